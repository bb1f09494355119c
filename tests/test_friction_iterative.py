"""Friction in the condensed and iterative linear solvers (issue 26, item 1).

The tangential rows are condensed with the normal ones, node by node
(:mod:`dolfinx_mortar.condensation`); the condensed solve preconditions fgmres on the
whole [u | z | y] system, so the Newton iterates must be the direct solver's: the same
Newton iterations, displacements, pressures, tangential tractions and stick/slip states
to 1e-8. The outer iterations per Newton iteration are bounded by what was measured
(at most 4.8 on these problems, inner rtol 1e-3, outer 1e-12): a preconditioner that
did not hold the tangential rows needs far more (or fails).
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from test_contact3d import curved_punch
from test_friction import load_demo

from dolfinx_mortar import Coulomb, Tresca, solve_load_steps

PATCH = load_demo("friction_patch")
OUTER_PER_NEWTON = 7
"""Largest mean fgmres iterations per Newton iteration of a load step allowed (measured:
4.0 on the patch tests, at most 4.8 on the sheared punch, serial and 2 ranks)."""


def snapshot(problem) -> dict:
    """This rank's displacement, pressures, tangential tractions and states."""
    state = problem.friction_state()
    return {"u": problem.u.x.array.copy(), "dofs": problem.V.tabulate_dof_coordinates(),
            "pressure": state["pressure"].copy(), "traction": np.array(state["traction"]),
            "sticking": state["sticking"].copy(), "slipping": state["slipping"].copy()}


def assert_same_iterates(runs: dict, tolerance: float = 1e-8) -> None:
    """Every run's steps against the direct solver's: Newton iterations, and per step
    the snapshot to ``tolerance`` of its largest value (states exactly)."""
    comm = MPI.COMM_WORLD
    reference = runs["direct"]
    for name, run in runs.items():
        assert run["iterations"] == reference["iterations"], name
        for step, (mine, theirs) in enumerate(zip(run["snapshots"], reference["snapshots"],
                                                  strict=True)):
            np.testing.assert_array_equal(mine["dofs"], theirs["dofs"])  # the same partition
            for key in ("sticking", "slipping"):
                np.testing.assert_array_equal(mine[key], theirs[key], err_msg=f"{name} {key}")
            for key in ("u", "pressure", "traction"):
                scale = comm.allreduce(float(np.max(np.abs(theirs[key]), initial=0.0)),
                                       op=MPI.MAX)
                difference = comm.allreduce(float(np.max(np.abs(mine[key] - theirs[key]),
                                                         initial=0.0)), op=MPI.MAX)
                assert difference <= tolerance * scale, (name, step, key, difference, scale)


def run(build, steps: int = 1, apply_load=None) -> dict:
    """Solve ``build()``'s problem in ``steps`` load steps (or one solve): per step the
    Newton and fgmres iterations and the snapshot."""
    problem = build()
    snapshots, iterations, outer = [], [], []
    if apply_load is None:
        report = problem.solve()
        assert report.converged, report
        reports = [report]
        snapshots.append(snapshot(problem))
    else:
        load = apply_load(problem)
        records = solve_load_steps(problem, load, steps,
                                   on_step=lambda step: snapshots.append(snapshot(problem)),
                                   end=2.0)
        assert all(r.cutbacks == 0 for r in records)
        reports = [r.report for r in records]
    iterations = [r.iterations for r in reports]
    outer = [r.linear_iterations for r in reports]
    result = {"iterations": iterations, "outer": outer, "snapshots": snapshots,
              "solver": problem.linear_solver, "condensation": problem.condensation}
    problem.destroy()
    return result


SOLVERS = {"direct": {"linear_solver": "direct"},
           "condensed": {"linear_solver": "direct", "condensation": True},
           "iterative": {"linear_solver": "iterative"}}


def compare_solvers(build, **kwargs) -> dict:
    runs = {name: run(lambda options=options: build(**options), **kwargs)
            for name, options in SOLVERS.items()}
    assert runs["iterative"]["solver"] == "iterative" and runs["iterative"]["condensation"]
    assert runs["condensed"]["condensation"] and not runs["direct"]["condensation"]
    assert_same_iterates(runs)
    for name in ("condensed", "iterative"):
        for newton, outer in zip(runs[name]["iterations"], runs[name]["outer"], strict=True):
            assert outer <= OUTER_PER_NEWTON * newton, (name, runs[name])
    return runs


@pytest.mark.parallel
@pytest.mark.parametrize("shear_ratio", [0.6, 2.0])
def test_friction_patch_2d_iterative_is_direct(shear_ratio):
    """2D friction patch test (demos/friction_patch.py, 3:7): sticking (R = 0.6) and
    slipping (R = 2: each slipping node's tangential row eliminated through its diagonal,
    its tilted normal force condensed); exact with the condensed direct solve (one outer
    iteration a Newton step)."""
    limit = 0.2 * PATCH.PRESSURE
    shear = min(shear_ratio, 1.0) * limit
    runs = compare_solvers(lambda **options: PATCH.sheared_blocks(
        (3, 7), "upper", Coulomb(0.2), shear_ratio * limit / PATCH.SHEAR_MODULUS, shear,
        **options))
    assert runs["condensed"]["outer"] == runs["condensed"]["iterations"]
    state = runs["direct"]["snapshots"][-1]
    flag = "slipping" if shear_ratio > 1.0 else "sticking"
    assert MPI.COMM_WORLD.allreduce(int(state[flag].sum()), op=MPI.SUM) == 8


@pytest.mark.parallel
@pytest.mark.parametrize("law", ["coulomb-stick", "coulomb-slip", "tresca", "penalty"])
def test_friction_patch_3d_iterative_is_direct(law):
    """3D friction patch test (tetrahedra, 3:7): stick (two tangential constraint rows
    per node, condensed along the node's frame), slip (the disc projection's 2 x 2 block),
    Tresca slip and penalty slip (every row eliminated through its diagonal: the
    condensed direct solve is exact, one outer iteration a Newton step)."""
    limit = 0.2 * PATCH.PRESSURE
    ratio = 0.5 if law == "coulomb-stick" else 2.0
    friction = Tresca(limit) if law == "tresca" else Coulomb(0.2)
    options = {"method": "penalty", "penalty": 1e5} if law == "penalty" else {}
    runs = compare_solvers(lambda **more: PATCH.sheared_blocks_3d(
        (3, 7), "upper", friction, ratio * limit / PATCH.SHEAR_MODULUS,
        min(ratio, 1.0) * limit, **options, **more))
    if law == "penalty":
        assert runs["condensed"]["outer"] == runs["condensed"]["iterations"]


def sheared_punch(friction, **options):
    """The curved punch of test_friction3d (hexahedra): pressed 0.02 (t <= 1), then its
    top moved along x: a stick centre in a slip rim at t = 1.5."""
    problem, press = curved_punch(MPI.COMM_WORLD, cell="hexahedron", ratio=(6, 5),
                                  curvature=0.1, friction=friction, **options)

    def apply_load(problem):
        drive = problem.bcs[0].g.x.array.reshape(-1, 3)

        def load(t):
            press(min(t, 1.0))
            drive[:, 0] = 0.02 * max(t - 1.0, 0.0)
        return load

    return problem, apply_load


@pytest.mark.parallel
@pytest.mark.timeout(600)
def test_sheared_punch_with_stick_and_slip_iterative_is_direct():
    """3D frictional contact with sticking and slipping nodes at once (the sheared curved
    punch, Coulomb mu = 0.3, 4 steps to t = 2): the condensed and the iterative solves
    take the direct solver's Newton iterates, step by step."""
    built = {}

    def build(**options):
        problem, built["load"] = sheared_punch(Coulomb(0.3), **options)
        return problem

    runs = compare_solvers(build, steps=4, apply_load=lambda p: built["load"](p))
    states = runs["direct"]["snapshots"][2]
    comm = MPI.COMM_WORLD
    assert comm.allreduce(int(states["sticking"].sum()), op=MPI.SUM) > 0
    assert comm.allreduce(int(states["slipping"].sum()), op=MPI.SUM) > 0


def test_friction_is_accepted_by_every_linear_solver():
    """The refusal is gone: friction runs with condensation and the iterative solver, and
    ``auto`` picks the iterative solver for friction by the frictionless rule."""
    from dolfinx_mortar.solvers import AUTO_ITERATIVE_MIN_DOFS, automatic_linear_solver

    assert automatic_linear_solver(3, AUTO_ITERATIVE_MIN_DOFS, "dual", True) == "iterative"
    assert automatic_linear_solver(3, AUTO_ITERATIVE_MIN_DOFS - 1, "dual", True) == "direct"
    assert automatic_linear_solver(2, 100 * AUTO_ITERATIVE_MIN_DOFS, "dual", True) == "direct"
    assert automatic_linear_solver(3, AUTO_ITERATIVE_MIN_DOFS, "standard", True) == "direct"
    with pytest.raises(ValueError, match="basis='dual'"):
        PATCH.sheared_blocks_3d((3, 7), "upper", Coulomb(0.2), 0.0, 0.0,
                                linear_solver="iterative", basis="standard")


def test_low_memory_condensation_gives_the_same_outer_iterations():
    """``condensed_keep_products: False`` (every product built anew at each set-up) with
    friction: the same preconditioner, so the same outer and Newton iterations and answer,
    and only what ``apply`` needs is kept (the turns, P^-1 and S P^-1 among it)."""
    limit = 0.2 * PATCH.PRESSURE
    runs, kept = {}, {}
    for keep in (True, False):
        problem = PATCH.sheared_blocks_3d(
            (3, 7), "upper", Coulomb(0.2), 2.0 * limit / PATCH.SHEAR_MODULUS, limit,
            linear_solver="iterative", petsc_options={"condensed_keep_products": keep,
                                                      "snes_rtol": 1e-12, "snes_atol": 0.0})
        report = problem.solve()
        assert report.converged
        runs[keep] = (report.iterations, report.linear_iterations, snapshot(problem))
        kept[keep] = sorted(problem._condenser._matrices) + sorted(problem._condenser._products)
        problem.destroy()
    assert runs[True][:2] == runs[False][:2]
    np.testing.assert_allclose(runs[False][2]["u"], runs[True][2]["u"], rtol=0, atol=1e-14)
    assert kept[False] == ["C", "G", "P_inv", "R_U_t", "R_V", "S_P_inv", "T", "E_q"]


@pytest.mark.parallel
@pytest.mark.timeout(600)
def test_frictional_hertz_sphere_iterative_is_direct():
    """demos/hertz_sphere.py --mu 0.3 (quarter model: slave nodes on the symmetry planes
    hold the tangent directions along them, y^a = 0 rows eliminated whole or per
    component), 2 load steps: the iterative solve takes the direct solver's Newton
    iterations and multipliers (to 1e-8 of the largest) and balances the load."""
    argv = ["--elements-per-radius", "2", "--refinement", "1", "--steps", "2", "--mu", "0.3"]
    hertz = load_demo("hertz_sphere")
    summaries = {solver: hertz.main(argv + ["--linear-solver", solver], comm=MPI.COMM_WORLD)
                 for solver in ("direct", "iterative")}
    direct, iterative = summaries["direct"], summaries["iterative"]
    assert iterative["linear_solver"] == "iterative"
    assert iterative["newton_iterations"] == direct["newton_iterations"]
    reference = np.array(direct["pressure_profile"]["multiplier"])
    np.testing.assert_allclose(iterative["pressure_profile"]["multiplier"], reference,
                               rtol=0, atol=1e-8 * reference.max())
    assert iterative["total_force"] == pytest.approx(iterative["load"], rel=1e-10)
    for newton, outer in zip(iterative["newton_iterations"], iterative["krylov_iterations"],
                             strict=True):
        assert outer <= OUTER_PER_NEWTON * newton


def test_elimination_ratio_trades_outer_iterations_only():
    """``condensed_elimination_ratio`` (an option under the solver's prefix): eliminating a
    rotated multiplier is exact and condensing a tangential one is not, so with an exact
    inner solve (LU) the outer iterations fall as the ratio falls, to one per Newton
    iteration when every nonzero singular value above 1e-3 of its node's largest is
    eliminated, while the Newton iterates stay the direct solver's (demos/hertz_sphere.py
    --mu 0.3 at refinement 0: 16, 12 and 8 outer iterations for 8 Newton iterations at
    ratios 0.1, 0.03 and 0.001; 23 at 0.5)."""
    from petsc4py import PETSc

    from dolfinx_mortar.condensation import ELIMINATION_RATIO

    hertz = load_demo("hertz_sphere")
    argv = ["--refinement", "0", "--mu", "0.3"]
    direct = hertz.main(argv + ["--linear-solver", "direct"])
    options = PETSc.Options()
    exact_inner = {"dolfinx_mortar_condensed_ksp_type": "preonly",
                   "dolfinx_mortar_condensed_pc_type": "lu",
                   "dolfinx_mortar_condensed_pc_factor_mat_solver_type": "mumps"}
    outer = {}
    for ratio in (0.5, ELIMINATION_RATIO, 1e-3):
        settings = dict(exact_inner, dolfinx_mortar_condensed_elimination_ratio=ratio)
        for key, value in settings.items():
            options[key] = value
        try:
            summary = hertz.main(argv + ["--linear-solver", "iterative"])
        finally:
            for key in settings:
                options.delValue(key)
        assert summary["newton_iterations"] == direct["newton_iterations"], ratio
        reference = np.array(direct["pressure_profile"]["multiplier"])
        np.testing.assert_allclose(summary["pressure_profile"]["multiplier"], reference,
                                   rtol=0, atol=1e-8 * reference.max())
        outer[ratio] = sum(summary["krylov_iterations"])
    newton = sum(direct["newton_iterations"])
    assert outer[0.5] > outer[ELIMINATION_RATIO] > outer[1e-3] == newton, outer


@pytest.mark.parallel
def test_outer_solve_stops_at_a_fraction_of_the_newton_tolerance():
    """``ksp_newton_fraction``: the outer fgmres also stops where its residual is 1e-2 of
    the Newton tolerance (solvers.NewtonLinearTolerance). Coulomb friction converges over
    several Newton iterations, whose last steps then need fewer digits: fewer outer
    iterations (demos/hertz_sphere.py --mu 0.3 at refinement 0, serial: 35 -> 31), the same
    Newton iterations and multipliers to 1e-8, the last residual still under the Newton
    tolerance. Off (0), every step is solved to 1e-12 of its own residual."""
    from petsc4py import PETSc

    from dolfinx_mortar.solvers import KSP_NEWTON_FRACTION

    hertz = load_demo("hertz_sphere")
    argv = ["--refinement", "0", "--mu", "0.3", "--linear-solver", "iterative"]
    options = PETSc.Options()
    summaries = {}
    for fraction in (0.0, KSP_NEWTON_FRACTION):
        options["dolfinx_mortar_ksp_newton_fraction"] = fraction
        try:
            summaries[fraction] = hertz.main(argv, comm=MPI.COMM_WORLD)
        finally:
            options.delValue("dolfinx_mortar_ksp_newton_fraction")
    off, on = summaries[0.0], summaries[KSP_NEWTON_FRACTION]
    assert on["newton_iterations"] == off["newton_iterations"]
    reference = np.array(off["pressure_profile"]["multiplier"])
    np.testing.assert_allclose(on["pressure_profile"]["multiplier"], reference,
                               rtol=0, atol=1e-8 * reference.max())
    assert sum(on["krylov_iterations"]) < sum(off["krylov_iterations"])
    for residuals in on["residuals_per_step"]:
        assert residuals[-1] <= 1e-10 * residuals[0]


def test_newton_linear_tolerance_is_a_fraction_of_the_newton_tolerance():
    """The update sets the KSP's atol to fraction * max(snes atol, snes rtol ||r_0||),
    never below the KSP's own atol, and leaves its rtol."""
    from petsc4py import PETSc

    from dolfinx_mortar.solvers import NewtonLinearTolerance

    snes = PETSc.SNES().create(MPI.COMM_SELF)
    try:
        snes.setTolerances(rtol=1e-10, atol=1e-20)
        snes.getKSP().setTolerances(rtol=1e-12, atol=1e-50)
        monitored = []
        update = NewtonLinearTolerance(monitored, 1e-2, 1e-50)
        update(snes, 0)  # no norm yet: the snes atol
        assert snes.getKSP().getTolerances()[:2] == (1e-12, pytest.approx(1e-22, rel=1e-15))
        monitored.append(3.0)
        update(snes, 1)
        assert snes.getKSP().getTolerances()[1] == pytest.approx(3e-12, rel=1e-15)
        snes.setTolerances(atol=1e-9)
        update(snes, 2)
        assert snes.getKSP().getTolerances()[1] == pytest.approx(1e-11, rel=1e-15)
        update = NewtonLinearTolerance(monitored, 1e-2, 1e-6)
        update(snes, 3)
        assert snes.getKSP().getTolerances()[1] == 1e-6
    finally:
        snes.destroy()
