"""ContactProblem: patch tests, parameter independence, convergence, exact Jacobian, errors."""

from __future__ import annotations

import importlib.util
import pathlib

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    LoadSteppingError,
    Material,
    compat,
    internal_work,
    meshes,
    solve_load_steps,
)
from dolfinx_mortar.surface import SurfaceError

DEMOS = pathlib.Path(__file__).parents[1] / "demos"


def demo(name: str):
    spec = importlib.util.spec_from_file_location(f"demo_{name}", DEMOS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parallel
@pytest.mark.parametrize("refinement", ["0", "1"])
@pytest.mark.parametrize("ratio", ["1:1", "2:3", "3:7", "1:7"])
@pytest.mark.parametrize("slave", ["top", "bottom"])
def test_patch_test_segment_lagrange_is_exact(ratio, slave, refinement):
    summary = demo("patch_test").main(
        ["--ratio", ratio, "--slave", slave, "--refinement", refinement]
    )
    assert summary["converged"]
    assert summary["max_pressure_deviation_rel"] <= 1e-10
    assert summary["max_multiplier_deviation_rel"] <= 1e-10
    assert summary["max_stress_deviation_rel"] <= 1e-10
    forces = np.array(summary["slave_force"]) + np.array(summary["master_force"])
    assert np.linalg.norm(forces) <= 1e-10 * summary["total_force_expected"]


@pytest.mark.parallel
@pytest.mark.parametrize(
    "options",
    [
        ["--multipliers", "standard"],
        ["--normals", "slave"],
        ["--normals", "master"],
        ["--active-set", "fixed-point"],
        ["--method", "augmented"],
        ["--cell-type", "quadrilateral"],
    ],
)
def test_patch_test_options_are_exact(options):
    summary = demo("patch_test").main(["--ratio", "3:7", *options])
    assert summary["max_pressure_deviation_rel"] <= 1e-10
    assert summary["max_multiplier_deviation_rel"] <= 1e-10


@pytest.mark.parallel
@pytest.mark.parametrize("moduli", [("1e5", "1e3"), ("1e3", "1e5")])
@pytest.mark.parametrize("slave", ["top", "bottom"])
@pytest.mark.parametrize("cell", ["triangle", "quadrilateral"])
def test_patch_test_is_exact_with_moduli_100_to_1(moduli, slave, cell):
    """Punch and foundation 100 times stiffer than the other, either slave side, triangles
    and quadrilaterals: the state stays uniform (the bodies' lateral strains differ, the
    interface slides) and exact, the multipliers and the recovered pressure alike."""
    summary = demo("patch_test").main(["--ratio", "3:7", "--slave", slave, "--cell-type", cell,
                                       "--E-punch", moduli[0], "--E-foundation", moduli[1]])
    assert summary["converged"]
    assert summary["max_pressure_deviation_rel"] <= 1e-10
    assert summary["max_multiplier_deviation_rel"] <= 1e-10
    assert summary["max_stress_deviation_rel"] <= 1e-10


@pytest.mark.parametrize("gauss_points", [2, 4, 8])
def test_patch_test_element_based_is_not_exact(gauss_points):
    """Element-based integration is close but never exact; the deviation is reported."""
    summary = demo("patch_test").main(
        ["--ratio", "3:7", "--integration", "element", "--gauss-points", str(gauss_points)]
    )
    assert 1e-6 < summary["max_pressure_deviation_rel"] < 0.1


@pytest.mark.parametrize("factor", [0.1, 1.0, 10.0])
def test_patch_test_penalty_gives_uniform_pressure_and_penetration(factor):
    lagrange = demo("patch_test").main(["--ratio", "3:7"])
    penalty = lagrange["penalty_used"] * factor
    summary = demo("patch_test").main(
        ["--ratio", "3:7", "--method", "penalty", "--penalty", str(penalty)]
    )
    # a uniform pressure needs a uniform penetration p / eps: the pressure is exact
    assert summary["max_pressure_deviation_rel"] <= 1e-10


def hertz(args, comm=MPI.COMM_WORLD):
    return demo("hertz").main(["--refinement", "0", "--steps", "2", *args], comm=comm)


def test_hertz_matches_theory_and_converges():
    """Case B at the demo's default (refinement 2): p_max within 2 % of p0, the half-width
    within one slave element, the force equal to the load; cases A and C within 3 % on
    p0; the L2 pressure error falls at a least-squares rate >= 0.8 over refinements 0-3
    (Hertz's sqrt edge allows at most about 1 for P1 multipliers)."""
    rows = [hertz(["--refinement", str(r)], comm=MPI.COMM_SELF) for r in range(4)]
    default = rows[2]
    assert abs(default["p_max_error_rel"]) <= 0.02
    assert default["a_error_in_elements"] <= 1.0
    assert default["total_force_error_rel"] <= 1e-8
    h = np.array([r["h_contact"] for r in rows])
    error = np.array([r["l2_pressure_error_rel"] for r in rows])
    assert np.polyfit(np.log(h), np.log(error), 1)[0] >= 0.8, error
    for case in ("A", "C"):
        summary = hertz(["--case", case, "--refinement", "2"], comm=MPI.COMM_SELF)
        assert abs(summary["p_max_error_rel"]) <= 0.03, case


def test_hertz_block_as_slave():
    """--slave block: the slave nodes are the block's top (y = 0), the cylinder's arc is
    the master, and what the demo reports is as right as with the cylinder as slave at
    refinement 0 (measured: p_max +0.12 % and +0.08 %, L2 error 5.1 % and 6.4 %): the
    force on the cylinder equals the load, p_max is within 1 % of p0, the half-width
    within one element, and the default normals are the block's for either choice."""
    R = 8.0
    for slave, normals in (("cylinder", "master"), ("block", "slave")):
        summary = hertz(["--slave", slave], comm=MPI.COMM_SELF)
        assert summary["slave"] == slave
        assert summary["normals"] == normals
        assert summary["total_force"] == pytest.approx(summary["load"], rel=1e-10)
        assert summary["force_balance"] <= 1e-10
        assert abs(summary["p_max_error_rel"]) <= 0.01, slave
        assert summary["a_error_in_elements"] <= 1.0, slave
        assert summary["l2_pressure_error_rel"] <= 0.07, slave
        x = np.array(summary["pressure_profile"]["x"])
        y = np.array(summary["pressure_profile"]["y"])
        on_arc = R - np.sqrt(R * R - x * x)
        surface, other = (on_arc, 0.0 * x) if slave == "cylinder" else (0.0 * x, on_arc)
        np.testing.assert_allclose(y, surface, rtol=0.0, atol=1e-12 * R)
        assert np.abs(y - other).max() > 0.1 * summary["h_contact"]


def test_soft_slave_on_a_10000_times_stiffer_master_converges():
    """The block as slave, the cylinder 1e4 times stiffer (E* as in case B): the residual's
    rounding floor follows the stiff master's rows, and so must the Newton tolerance (it
    followed the soft slave's: every step stalled at the floor, cut back six times and
    failed). Measured: 5 Newton iterations, p_max +0.56 %."""
    summary = demo("hertz").main(["--refinement", "2", "--steps", "1", "--slave", "block",
                                  "--E-cylinder", "1000100", "--E-block", "100.01"],
                                 comm=MPI.COMM_SELF)
    assert summary["cutbacks"] == 0
    assert summary["newton_iterations"] == [5]
    assert abs(summary["p_max_error_rel"]) < 0.01
    assert summary["total_force"] == pytest.approx(summary["load"], rel=1e-8)


@pytest.mark.parametrize("material", ["linear", "neo-hookean"])
def test_hertz_solution_does_not_depend_on_search_margin(material):
    """A margin of 1/50 of the default (far below the initial gaps at the edge of the
    zone): pairs are searched again as the gap closes, for the small-strain
    (reference-configuration) integrals as for the finite-strain ones."""
    args = ["--refinement", "1", "--material", material]
    reference = hertz(args, comm=MPI.COMM_SELF)
    margin = 2.0 * reference["h_contact"] / 50.0
    other = hertz([*args, "--search-margin", str(margin)], comm=MPI.COMM_SELF)
    done = [s["contact_statistics"]["cylinder-block"]["searches_done"] for s in (reference, other)]
    assert done[1] > done[0]
    assert other["active_nodes"] == reference["active_nodes"]
    assert other["p_max"] == pytest.approx(reference["p_max"], rel=1e-8)
    assert other["a_contact"] == pytest.approx(reference["a_contact"], rel=1e-8)


def test_semismooth_solution_does_not_depend_on_c_n():
    """c_n from 1e-2 to 1e2 times the default (four decades): the same solution."""
    reference = hertz([])
    scale = reference["c_n"]
    for factor in (1e-2, 1e-1, 10.0, 1e2):
        other = hertz(["--c-n", str(scale * factor)])
        assert other["p_max"] == pytest.approx(reference["p_max"], rel=1e-8)
        assert other["a_contact"] == pytest.approx(reference["a_contact"], rel=1e-8)
        assert other["l2_pressure_error"] == pytest.approx(reference["l2_pressure_error"], rel=1e-8)


def test_penalty_converges_to_lagrange_and_augmented_reaches_it():
    reference = hertz([])
    scale = reference["penalty_used"]
    errors = []
    for factor in (1.0, 10.0, 100.0, 1000.0):
        penalty = hertz(["--method", "penalty", "--penalty", str(scale * factor)])
        errors.append(abs(penalty["p_max"] - reference["p_max"]) / reference["p_max"])
    assert all(b < a for a, b in zip(errors, errors[1:], strict=False))
    assert errors[-1] < 1e-2 * errors[0]
    augmented = hertz(["--method", "augmented", "--penalty", str(10 * scale)])
    assert augmented["p_max"] == pytest.approx(reference["p_max"], rel=1e-6)


def test_semismooth_newton_converges_quadratically():
    """Once the active set has settled, r_{k+1}/r_0 <= 10 (r_k/r_0)^2 (Neo-Hookean Hertz;
    the linear material converges in one step once the set is right)."""
    summary = demo("hertz").main(["--refinement", "2", "--steps", "2", "--material", "neo-hookean"])
    assert max(summary["newton_iterations"]) <= 8
    for residuals in summary["residuals_per_step"]:
        r = np.array(residuals)
        q = r / r[0]
        # pairs past the active-set search and above the rounding floor (~1e-12 here)
        asymptotic = [
            (a, b) for a, b, rb in zip(q[:-1], q[1:], r[1:], strict=True) if a < 0.1 and rb > 1e-11
        ]
        assert asymptotic, residuals
        for a, b in asymptotic:
            assert b <= 10.0 * a**2, residuals


def penetrating_blocks(normals: str, method: str = "lagrange", material: str = "neo-hookean"):
    tagged = meshes.tied_blocks(ratio=(3, 5), refinement=0)
    mesh = tagged.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    v = ufl.TestFunction(V)
    F = internal_work(u, v, {0: Material(10.0, 0.3, material)})
    bottom = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[1], 0.0))
    top = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[1], 1.0))
    bcs = [
        dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, b), V)
        for b in (bottom, top)
    ]
    pair = ContactPair(
        tagged.facet_tags, tagged.markers["contact_slave"], tagged.markers["contact_master"]
    )
    problem = ContactProblem(F, u, bcs, [pair], normals=normals, method=method)
    rng = np.random.default_rng(7)
    u.x.array[:] = 0.01 * rng.standard_normal(u.x.array.size)
    upper = tagged.cell_tags.find(tagged.markers["upper"])
    lower = tagged.cell_tags.find(tagged.markers["lower"])
    shift = dolfinx.fem.Function(V)
    shift.interpolate(lambda x: np.vstack([0.0 * x[0], -0.02 + 0.0 * x[0]]), upper)
    shift.interpolate(lambda x: np.vstack([0.0 * x[0], 0.02 + 0.0 * x[0]]), lower)
    u.x.array[:] += shift.x.array
    # a state that satisfies the boundary conditions, as every Newton iterate after the first
    compat.set_bc_values(u, bcs)
    for z in problem.multipliers:
        z.setArray(rng.uniform(0.5, 1.5, z.getLocalSize()))
    problem.equations.read_state(problem.x)
    return problem


@pytest.mark.parallel
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("method", ["lagrange", "penalty"])
def test_contact_jacobian_taylor(normals, method):
    """Residual R(x) of the whole contact system: |R(x+eh) - R(x) - e J h| = O(e^2)."""
    problem = penetrating_blocks(normals, method)
    assert_taylor_second_order(problem, seed=11)


def assert_taylor_second_order(problem: ContactProblem, seed: int) -> None:
    """|R(x + e h) - R(x) - e J h| = O(e^2) at the problem's state x, for a random
    direction h that leaves the Dirichlet dofs alone, with the active set unchanged
    within the steps (checked on every rank together, so that no rank is left waiting)."""
    snes = problem.snes
    x0 = problem.x.copy()
    r0 = problem.b.duplicate()
    problem.equations.residual(snes, x0, r0)
    active = [a.copy() for a in problem.active]
    assert problem.num_active() > 0
    J = problem.equations.assemble_system()
    h = random_direction(problem, x0, seed=seed)
    Jh = h.duplicate()
    J.mult(h, Jh)
    remainders = []
    steps = 1e-4 * 0.5 ** np.arange(5)
    for eps in steps:
        x = x0.copy()
        x.axpy(eps, h)
        r = r0.duplicate()
        problem.equations.residual(snes, x, r)
        same = all(np.array_equal(a, b) for a, b in zip(active, problem.active, strict=True))
        assert problem.comm.allreduce(same, op=MPI.LAND)
        r.axpy(-1.0, r0)
        r.axpy(-eps, Jh)
        remainders.append(r.norm())
    slope = np.polyfit(np.log(steps), np.log(remainders), 1)[0]
    assert slope == pytest.approx(2.0, abs=0.1), remainders


def random_direction(problem: ContactProblem, x0, seed: int):
    """A random [u, z] direction (per-rank seed), zero at the Dirichlet dofs."""
    rng = np.random.default_rng(seed + problem.comm.rank)
    d = x0.duplicate()
    d.setArray(rng.standard_normal(d.getLocalSize()))
    d.getArray()[
        np.isin(np.arange(*d.getOwnershipRange()), problem.layout.u(problem._fixed_dofs))
    ] = 0.0
    return d


class _ProblemBuilt(Exception):
    def __init__(self, problem):
        self.problem = problem


def built_problem(demo_name: str, argv: list[str]) -> ContactProblem:
    """The demo's ContactProblem as its main builds it, before any solve."""
    module = demo(demo_name)

    class Capture(module.ContactProblem):
        def solve(self):
            raise _ProblemBuilt(self)

    module.ContactProblem = Capture
    with pytest.raises(_ProblemBuilt) as built:
        module.main(argv)
    return built.value.problem


@pytest.mark.parallel
def test_patch_test_jacobian_is_exact_in_the_reference_configuration():
    """Linear material, frozen mortar integrals: R is linear in (u, z) for a fixed active set,
    so central differences equal J d to rounding, Dirichlet rows and multiplier rows included.

    (One Newton step from u = 0 leaves 9.5e-10 of 66.6 with MUMPS; that is the
    factorization's rounding, eps ||J|| ||dx|| ~ 3e-9, not the Jacobian.)
    """
    problem = built_problem("patch_test", ["--ratio", "3:7", "--slave", "bottom",
                                           "--refinement", "1"])
    snes = problem.snes
    x0 = problem.x.copy()
    r0 = problem.b.duplicate()
    problem.equations.residual(snes, x0, r0)
    assert problem.interfaces[0].configuration == "reference"
    # u = 0, z = 0: every covered node is a tie; keep that active set at the perturbed states
    active = [a.copy() for a in problem.active]
    assert all(a.all() for a in active) and problem.num_active() > 0
    problem.equations.decide_active = lambda k: active[k]
    J = problem.equations.assemble_system()
    d = random_direction(problem, x0, seed=5)
    Jd = d.duplicate()
    J.mult(d, Jd)
    for eps in (1e-3, 1e-4):
        plus, minus = r0.duplicate(), r0.duplicate()
        for sign, r in ((1.0, plus), (-1.0, minus)):
            x = x0.copy()
            x.axpy(sign * eps, d)
            problem.equations.residual(snes, x, r)
        plus.axpy(-1.0, minus)
        plus.scale(1.0 / (2.0 * eps))
        plus.axpy(-1.0, Jd)
        assert plus.norm() <= 1e-12 * Jd.norm(), (eps, plus.norm(), Jd.norm())
    problem.destroy()


@pytest.mark.parallel
def test_bad_options_and_inputs():
    tagged = meshes.patch_test(ratio=(2, 3))
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(1.0, 0.3, "linear")})
    markers = tagged.markers
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"])
    for key, value in (
        ("method", "lagrangian"),
        ("integration", "nodal"),
        ("normals", "up"),
        ("active_set", "smooth"),
        ("basis", "mortar"),
    ):
        with pytest.raises(ValueError, match=f"unknown {key}"):
            ContactProblem(F, u, [], [pair], **{key: value})
    with pytest.raises(ValueError, match="fixed-point"):
        ContactProblem(F, u, [], [pair], method="penalty", active_set="fixed-point")
    with pytest.raises(ValueError, match="c_n must be positive"):
        ContactProblem(F, u, [], [pair], c_n=-1.0)
    with pytest.raises(ValueError, match="condensation=True needs dual multipliers, basis='dual'"):
        ContactProblem(F, u, [], [pair], basis="standard", condensation=True)
    with pytest.raises(SurfaceError, match="marks no facet"):
        ContactProblem(F, u, [], [ContactPair(tagged.facet_tags, 999, markers["contact_master"])])
    # a slave surface on the master's body: both tags on the foundation
    wrong = ContactPair(
        tagged.facet_tags, markers["foundation_top_free"], markers["foundation_contact"]
    )
    with pytest.raises(ValueError, match="wrong body"):
        ContactProblem(F, u, [], [wrong])
    with pytest.raises(ValueError, match="at least one"):
        ContactProblem(F, u, [], [])


@pytest.mark.parallel
def test_load_stepping_gives_up_with_a_clear_error():
    """A load no Newton solve can follow (SNES limited to one iteration) fails cleanly."""
    tagged = meshes.patch_test(ratio=(2, 3))
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    traction = dolfinx.fem.Constant(mesh, np.zeros(2))
    F = internal_work(u, v, {0: Material(1000.0, 0.4, "neo-hookean")}) - ufl.inner(
        traction, v
    ) * ds(markers["punch_top"])
    bottom = tagged.facet_tags.find(markers["foundation_bottom"])
    bcs = [
        dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, bottom), V)
    ]
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"])
    problem = ContactProblem(F, u, bcs, [pair], petsc_options={"snes_max_it": 1})

    def apply_load(t):
        traction.value[:] = (3.0e3 * t, -1.0e4 * t)

    with pytest.raises(LoadSteppingError, match="after 2 cut-backs"):
        solve_load_steps(problem, apply_load, 1, max_cutbacks=2)
    problem.destroy()


def test_load_stepping_grows_back_onto_the_nominal_grid_after_a_cut_back():
    """A solver that fails on load jumps above 0.15: 4 nominal steps of 0.25 are cut to
    0.125, and every later step first halves, then grows back onto the grid, so each
    t = k / 4 is reached exactly and no step is smaller than needed."""
    from dolfinx_mortar import SolveReport

    class JumpLimitedProblem:
        comm = MPI.COMM_WORLD

        def __init__(self):
            self.accepted, self.load = 0.0, 0.0

        def save_state(self):
            return self.accepted

        def restore_state(self, state):
            self.accepted = state

        def solve(self):
            converged = self.load - self.accepted <= 0.15 + 1e-12
            if converged:
                self.accepted = self.load
            return SolveReport(converged=converged, reason=2 if converged else -5,
                               iterations=3, residuals=[1.0], active=0)

    problem = JumpLimitedProblem()
    records = solve_load_steps(problem, lambda t: setattr(problem, "load", t), 4)
    loads = [r.load for r in records]
    assert loads == pytest.approx([0.125 * k for k in range(1, 9)], abs=1e-14)
    assert [r.cutbacks for r in records] == [1, 0, 1, 0, 1, 0, 1, 0]


@pytest.mark.parallel
def test_separated_bodies_have_no_active_node_and_a_regular_system():
    """Bodies far apart: no pairs, no active node, Newton converges (identity z-rows)."""
    tagged = meshes.tied_blocks(ratio=(2, 3))
    mesh = tagged.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(10.0, 0.3, "neo-hookean")})
    outer = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[1], 0.0))
    bcs = [
        dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, outer), V)
    ]
    pair = ContactPair(
        tagged.facet_tags, tagged.markers["contact_slave"], tagged.markers["contact_master"]
    )
    top_dofs = dolfinx.fem.locate_dofs_topological(
        V, 1, dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[1], 1.0))
    )
    bcs.append(dolfinx.fem.dirichletbc(np.array([0.0, 0.3]), top_dofs, V))
    problem = ContactProblem(F, u, bcs, [pair], search_margin=0.05)
    report = problem.solve()
    assert report.converged
    assert report.active == 0
    assert problem.statistics()[f"{pair.slave}-{pair.master}"]["pairs"] == 0
    problem.destroy()


def _patch_test_with_load(argv: list[str]):
    """The patch test demo's problem before its solve, and its traction Constant."""
    module = demo("patch_test")

    class Capture(module.ContactProblem):
        def __init__(self, F, *args, **kwargs):
            super().__init__(F, *args, **kwargs)
            (self.traction,) = [c for c in F.constants() if c.value.shape == (2,)]

        def solve(self):
            raise _ProblemBuilt(self)

    module.ContactProblem = Capture
    with pytest.raises(_ProblemBuilt) as built:
        module.main(argv)
    problem = built.value.problem
    problem.solve = ContactProblem.solve.__get__(problem)
    return problem, problem.traction


@pytest.mark.parallel
def test_extrapolating_predictor_is_exact_for_a_solution_linear_in_the_load():
    """The patch test (linear material, reference configuration, every slave node active)
    has u and z affine in the load: from the third step on (the first two converged states
    are the first to extrapolate from) the guess is the solution, so its residual is the
    previous steps' solver tolerance, and Newton stops at its one forced step; without
    the predictor each step starts one load increment off. Both end at the same state."""
    problem, traction = _patch_test_with_load(["--ratio", "2:3", "--refinement", "1"])
    full = traction.value.copy()
    start = problem.save_state()

    def apply_load(t):
        traction.value[:] = t * full

    references = []
    predict = problem.predict

    def recording_predict(*args):
        predict(*args)
        references.append(problem._reference_norm)

    problem.predict = recording_predict
    initial, final = {}, {}
    for predictor in ("none", "extrapolate"):
        problem.restore_state(start)
        records = solve_load_steps(problem, apply_load, 4, predictor=predictor,
                                   check_penetration=False)
        initial[predictor] = [r.report.residuals[0] for r in records]
        final[predictor] = problem.save_state()
        assert problem.num_active() > 0 and all(r.report.converged for r in records)
    none, extrapolated = initial["none"], initial["extrapolate"]
    # the same load increment in every step after the first: the same initial residual
    assert none[2:] == pytest.approx([none[1]] * 2, rel=1e-6)
    assert extrapolated[:2] == pytest.approx(none[:2], rel=1e-12)
    assert max(extrapolated[2:]) <= 1e-8 * none[1], (none, extrapolated)
    assert [r.iterations for r in records][2:] == [1, 1]
    # the predicted steps stop relative to where an unpredicted step starts
    assert references == pytest.approx(none[2:], rel=1e-10)
    comm = problem.comm
    for key in ("u", "z"):
        a, b = (np.concatenate([np.ravel(final[p][key])]) for p in ("none", "extrapolate"))
        scale = comm.allreduce(np.abs(a).max(initial=0.0), op=MPI.MAX)
        difference = comm.allreduce(np.abs(a - b).max(initial=0.0), op=MPI.MAX)
        assert scale > 0.0 and difference <= 1e-9 * scale, (key, difference, scale)
    with pytest.raises(ValueError, match="predictor must be one of"):
        solve_load_steps(problem, apply_load, 1, predictor="quadratic")
    problem.destroy()
