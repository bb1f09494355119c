"""Stress case 4: the unit system must not matter.

Lengths x 1e3 with moduli x 1e-6, and back (lengths x 1e-3, moduli x 1e6), must give
the same dimensionless result: pressure / E and displacement / length.

* Kernel level: kernels.pair_quantities (compiled) and the numpy oracle's
  (tests/oracle/line2_numpy.py) on coordinates scaled by s give D, M, Dn,
  Mn, area scaled by s and the weighted gap by s^2 (their coordinate derivatives
  by 1, 1 and s), to 1e-10 relative.
* ContactProblem: the patch test mesh (meshes.patch_test) with mesh.geometry.x
  scaled in place before the function space is created, E and the applied
  pressure scaled by the modulus factor; the same Newton iterations and the same
  pressure / E and u / length to 1e-10.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np
import pytest

from dolfinx_mortar import kernels

from . import common
from .common import all_pairs, record, record_outcome, relative_difference
from oracle import line2_numpy

SCALINGS = [(1e3, 1e-6), (1e-3, 1e6)]  # (length factor, modulus factor)
OPTIONS = list(
    itertools.product(kernels.NORMAL_OPTIONS, kernels.INTEGRATION_OPTIONS, kernels.BASIS_OPTIONS)
)


# ----------------------------------------------------------------------------------------
# kernel level


def curved_polylines(rng: np.random.Generator, num_slave: int, num_master: int):
    """A slave arc (below, nodes right to left) and a master arc (above, left to right)
    that cross each other slightly, with random spacings, then a random rigid motion;
    every (slave facet, master facet) pair in the kernels' layout."""
    slave_s = np.sort(rng.uniform(0.0, 2.0, num_slave - 1))
    slave_s = np.concatenate([[0.0], slave_s, [2.0]])[::-1]
    master_s = np.sort(rng.uniform(-0.3, 2.3, num_master - 1))
    master_s = np.concatenate([[-0.3], master_s, [2.3]])
    slave = np.stack([slave_s, -0.1 * (slave_s - 1.0) ** 2 + 0.01], axis=1)
    master = np.stack([master_s, 0.05 * (master_s - 1.0) ** 2 - 0.01], axis=1)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    shift = rng.uniform(-1.0, 1.0, 2)
    slave, master = slave @ rotation.T + shift, master @ rotation.T + shift
    x, has_neighbour, facets_s, _ = all_pairs(slave, master)
    return x, has_neighbour, facets_s


@pytest.mark.parametrize("implementation", ["compiled", "oracle"])
@pytest.mark.parametrize("scale", [1e3, 1e-3, 1e6, 1e-6])
@pytest.mark.parametrize("normals,integration,basis", OPTIONS)
def test_kernel_quantities_scale_with_length(normals, integration, basis, scale, implementation):
    pair_quantities = {"compiled": kernels.pair_quantities,
                       "oracle": line2_numpy.pair_quantities}[implementation]
    rng = np.random.default_rng(2024)
    x, has_neighbour, slave_facet = curved_polylines(rng, 7, 11)
    options = dict(normals=normals, integration=integration, basis=basis, slave_facet=slave_facet)
    reference = pair_quantities(x, has_neighbour, **options)
    scaled = pair_quantities(x * scale, has_neighbour, **options)
    assert reference.valid.sum() >= 10
    errors = {
        "D": relative_difference(scaled.D / scale, reference.D),
        "M": relative_difference(scaled.M / scale, reference.M),
        "Dn": relative_difference(scaled.Dn.value / scale, reference.Dn.value),
        "Mn": relative_difference(scaled.Mn.value / scale, reference.Mn.value),
        "area": relative_difference(scaled.area.value / scale, reference.area.value),
        "gap": relative_difference(scaled.gap.value / scale**2, reference.gap.value),
        "dDn": relative_difference(scaled.Dn.grad, reference.Dn.grad),
        "dMn": relative_difference(scaled.Mn.grad, reference.Mn.grad),
        "darea": relative_difference(scaled.area.grad, reference.area.grad),
        "dgap": relative_difference(scaled.gap.grad / scale, reference.gap.grad),
        "overlap": relative_difference(scaled.overlap, reference.overlap),
    }
    worst = max(errors.values())
    record(4, nan=not all(np.all(np.isfinite(getattr(scaled, n))) for n in ("D", "M")), error=worst)
    np.testing.assert_array_equal(scaled.valid, reference.valid)
    assert worst <= 1e-10, errors


# ----------------------------------------------------------------------------------------
# ContactProblem on the patch test

PROBLEMS = {
    # name: options of common.patch_traction
    "linear-uniform": {"material": "linear", "pressure_on": "all"},
    "neo-hookean-uniform": {"material": "neo-hookean", "pressure_on": "all"},
    # pressure on the punch only: a non-uniform contact pressure, nodes changing state
    "neo-hookean-punch": {"material": "neo-hookean", "pressure_on": "punch", "pressure": 40.0},
}

# Fixed defects these cases caught (docs/stress.md): the semismooth decision compared a
# pressure with c_n times a weighted gap of unit length^2, and the residual mixed force rows
# with Dirichlet rows of unit length under an absolute tolerance (now the decision uses
# g~/A and every row is a force).


@functools.cache
def dimensionless(name: str, length: float, modulus: float):
    setup = common.patch_traction(
        ratio=(3, 7), length_scale=length, modulus_scale=modulus, **PROBLEMS[name]
    )
    outcome = setup.steps(2)
    E = setup.info["E"]
    setup.destroy()
    return outcome, outcome.pressure / E, outcome.displacement / length


def check_units(name: str, scaling: tuple[float, float]):
    reference, p0, u0 = dimensionless(name, 1.0, 1.0)
    assert reference.converged and not reference.nan
    outcome, p, u = dimensionless(name, *scaling)
    errors = {"pressure/E": relative_difference(p, p0), "u/length": relative_difference(u, u0)}
    record_outcome(
        4,
        outcome,
        error=max(errors.values()),
        reference_iterations=reference.iterations,
        scaling=list(scaling),
    )
    assert outcome.converged and not outcome.nan
    assert outcome.iterations == reference.iterations, (outcome.iterations, reference.iterations)
    assert outcome.cutbacks == 0
    assert max(errors.values()) <= 1e-10, errors


def params(names, scalings):
    for name in names:
        for scaling in scalings:
            yield pytest.param(name, scaling, id=f"{name}-L{scaling[0]:g}-E{scaling[1]:g}")


@pytest.mark.parametrize("name,scaling", list(params(PROBLEMS, SCALINGS)))
def test_contact_problem_dimensionless(name, scaling):
    check_units(name, scaling)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,scaling", list(params(PROBLEMS, [(1e3, 1.0), (1e-3, 1.0), (1.0, 1e-6), (1.0, 1e6)]))
)
def test_contact_problem_dimensionless_separately(name, scaling):
    """Lengths alone and moduli alone: which of the two scalings breaks what."""
    check_units(name, scaling)
