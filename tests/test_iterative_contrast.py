"""The iterative linear solver on bodies of contrasting stiffness (issue 25, item 4).

Two spheres (demos/hertz_sphere.py, refinement 0), one 100 times stiffer than the
other, either one the slave. With the stiff slave, the condensed matrix's master rows
used to hold the slave's normal stiffness as couplings far above their own diagonal,
and BoomerAMG did not converge on them: fgmres stopped at its limit or on the inner
solve's breakdown at every cut-back. The condensation now takes the slave normal
displacements out of those rows (:mod:`dolfinx_mortar.condensation`): the iterative
solve converges in a few outer iterations per Newton iteration and gives the direct
solver's Newton iterations and answer.
"""

from __future__ import annotations

import numpy as np
import pytest
from stress.common import relative_difference
from test_hertz_sphere import hertz_sphere

from dolfinx_mortar.diagnostics import ContactWarning

# the upper sphere 100 times stiffer; the load that keeps the equal-modulus Hertz
# radius (E* doubles, so the mesh, sized by that radius, is the equal-modulus one)
CONTRAST = ["--case", "sphere", "--refinement", "0", "--steps", "2", "--material", "linear",
            "--normals", "averaged", "--E1", "20000", "--E2", "200", "--load", "0.29703",
            "--slave-side", "given"]


@pytest.mark.timeout(300)
@pytest.mark.parametrize("slave", ["sphere", "block"])
def test_iterative_solver_converges_under_contrast_with_the_direct_answer(slave):
    """The stiff upper sphere as slave (kept: ``given``) also gets the set-up advice to
    swap."""
    results = {}
    for solver in ("direct", "iterative"):
        args = CONTRAST + ["--slave", slave, "--linear-solver", solver]
        if slave == "sphere":
            with pytest.warns(ContactWarning, match="Swap the two tags"):
                results[solver] = hertz_sphere(args)
        else:
            results[solver] = hertz_sphere(args)
    iterative, direct = results["iterative"], results["direct"]
    assert iterative["linear_solver"] == "iterative"
    assert iterative["cutbacks"] == direct["cutbacks"] == 0
    assert iterative["newton_iterations"] == direct["newton_iterations"]
    outer_per_newton = (np.sum(iterative["krylov_iterations"])
                        / np.sum(iterative["newton_iterations"]))
    assert outer_per_newton <= 8.0
    profile, reference = iterative["pressure_profile"], direct["pressure_profile"]
    assert np.array_equal(profile["r"], reference["r"])
    assert relative_difference(profile["pressure"], reference["pressure"]) <= 1e-8
    assert iterative["total_force"] == pytest.approx(direct["total_force"], rel=1e-10)
