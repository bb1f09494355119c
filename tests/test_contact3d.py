"""ContactProblem in 3D: patch tests, a curved punch (semismooth Newton, c_n, linear
solvers, serial = parallel), the exact Jacobian of the whole system, diagnostics."""

from __future__ import annotations

import re
import warnings

import dolfinx
import numpy as np
import pytest
import ufl
from contact_warnings import warns_on_rank_zero
from mpi4py import MPI
from test_contact import assert_taylor_second_order, demo

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    ContactWarning,
    Material,
    compat,
    internal_work,
    meshes,
    solve_load_steps,
)

CELLS = ("tetrahedron", "hexahedron")


def patch_test(*args, comm=MPI.COMM_SELF) -> dict:
    return demo("patch_test").main(["--dim", "3", *args], comm=comm)


def assert_exact(summary: dict, tolerance: float = 1e-10) -> None:
    assert summary["converged"]
    assert summary["max_pressure_deviation_rel"] <= tolerance, summary
    assert summary["max_multiplier_deviation_rel"] <= tolerance, summary
    assert summary["max_stress_deviation_rel"] <= tolerance, summary
    slave, master = np.array(summary["slave_force"]), np.array(summary["master_force"])
    # the master pushes the slave away from it: up on the punch, down on the foundation
    sign = 1.0 if summary["slave"] == "top" else -1.0
    expected = np.array([0.0, 0.0, sign * summary["total_force_expected"]])
    assert np.abs(slave - expected).max() <= tolerance * abs(expected[2])
    assert np.abs(slave + master).max() <= tolerance * abs(expected[2])


@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("ratio", ["1:1", "2:3", "3:7"])
@pytest.mark.parametrize("slave", ["top", "bottom"])
def test_patch_test_segment_lagrange_is_exact(cell, ratio, slave):
    """Uniform pressure 10 through non-matching tetrahedral and hexahedral interfaces, either
    slave side: contact pressure and sigma_zz uniform to rounding (measured <= 2e-13)."""
    summary = patch_test("--cell", cell, "--ratio", ratio, "--slave", slave)
    assert_exact(summary)
    assert summary["newton_iterations"] == 1


@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("moduli", [("1e5", "1e3"), ("1e3", "1e5")])
@pytest.mark.parametrize("slave", ["top", "bottom"])
@pytest.mark.parametrize("slave_side", ["auto", "given"])
def test_patch_test_is_exact_with_moduli_100_to_1(cell, moduli, slave, slave_side):
    """Punch and foundation 100 times stiffer than the other, either slave side: the state
    stays uniform (the bodies' lateral strains differ, the interface slides) and exact.
    A stiff slave is solved swapped with ``slave_side="auto"`` (one warning that says so;
    the forces keep the ContactPair's order, the pressure is at the other surface's
    nodes), and gets the set-up advice to swap with ``given``; a soft one gets neither.
    assert_exact checks the forces in the ContactPair's order (up on the punch)."""
    args = ("--cell", cell, "--ratio", "3:2", "--slave", slave,
            "--E-punch", moduli[0], "--E-foundation", moduli[1], "--slave-side", slave_side)
    stiff_slave = (slave == "top") == (float(moduli[0]) > float(moduli[1]))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        summary = patch_test(*args)
    messages = [str(w.message) for w in caught if issubclass(w.category, ContactWarning)]
    advice = [m for m in messages if "Swap the two tags" in m]
    swap = [m for m in messages if "solved with the two sides swapped" in m]
    assert len(advice) == (1 if stiff_slave and slave_side == "given" else 0), messages
    assert len(swap) == (1 if stiff_slave and slave_side == "auto" else 0), messages
    assert summary["swapped"] == (stiff_slave and slave_side == "auto")
    if stiff_slave:  # the estimate from the stiffness diagonals (non-matching 3:2 meshes)
        ratio = float(re.search(r"about ([0-9.e+]+) times stiffer", (advice + swap)[0]).group(1))
        assert 50.0 < ratio < 200.0, messages
    assert_exact(summary)


@pytest.mark.parallel
@pytest.mark.parametrize("cell", CELLS)
def test_patch_test_is_exact_in_parallel(cell):
    args = ("--cell", cell, "--ratio", "3:7", "--slave", "bottom")
    summary = patch_test(*args, comm=MPI.COMM_WORLD)
    assert summary["num_ranks"] == MPI.COMM_WORLD.size
    assert_exact(summary)


@pytest.mark.parametrize(
    "options",
    [
        ["--multipliers", "standard"],
        ["--method", "penalty"],
        ["--method", "augmented"],
        ["--normals", "slave"],
        ["--normals", "master"],
        ["--active-set", "fixed-point"],
        ["--linear-solver", "iterative"],
        ["--condensation"],
    ],
)
def test_patch_test_options_are_exact(options):
    summary = patch_test("--cell", "tetrahedron", "--ratio", "2:3", *options)
    assert_exact(summary)


@pytest.mark.parametrize("cell", CELLS)
def test_patch_test_element_based_is_not_exact(cell):
    """Element-based integration passes matching meshes only; its error is reported
    (measured 1.3e-3 to 2.8e-2 on these ratios)."""
    for ratio, slave in (("3:7", "top"), ("2:3", "bottom")):
        summary = patch_test("--cell", cell, "--ratio", ratio, "--slave", slave,
                             "--integration", "element")
        assert 1e-6 < summary["max_pressure_deviation_rel"] < 0.1
    assert_exact(patch_test("--cell", cell, "--ratio", "1:1", "--integration", "element"))


def test_patch_test_at_finite_strain_is_uniform():
    """Neo-Hookean: the Cauchy pressure is uniform to rounding (its value is 10 over the
    lateral stretch squared, not 10)."""
    summary = patch_test("--cell", "hexahedron", "--ratio", "3:7", "--material", "neo-hookean")
    assert summary["converged"]
    assert summary["pressure_nonuniformity_rel"] <= 1e-10
    assert 0.9 < summary["pressure_max"] / 10.0 < 1.0


def curved_punch(comm, cell: str = "hexahedron", ratio=(6, 5), curvature: float = 0.1,
                 material: str = "linear", slave: str = "top", length: float = 1.0,
                 modulus: float = 1.0, **options):
    """The 3D patch test's punch with a paraboloidal bottom z = 0.5 + curvature r^2 (r from
    the axis x = y = 1/2), its top clamped and driven down by ``apply_load(t)`` = 0.02 t,
    on the foundation clamped at its bottom: a circular contact zone that grows with t."""
    tagged = meshes.patch_test_3d(ratio=ratio, slave=slave, cell_type=cell, comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    punch = tagged.cell_tags.find(markers["punch"])
    nodes = np.unique(compat.geometry_dofmap(mesh)[punch])
    x = mesh.geometry.x
    r2 = (x[nodes, 0] - 0.5) ** 2 + (x[nodes, 1] - 0.5) ** 2
    x[nodes, 2] += curvature * r2 * (1.0 - x[nodes, 2]) / 0.5
    x *= length
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(1000.0 * modulus, 0.3, material)})
    drive = dolfinx.fem.Function(V)
    top = tagged.facet_tags.find(markers["punch_top"])
    bottom = tagged.facet_tags.find(markers["foundation_bottom"])
    bcs = [
        dolfinx.fem.dirichletbc(drive, dolfinx.fem.locate_dofs_topological(V, 2, top)),
        dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(V, 2, bottom), V),
    ]
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"],
                       name="punch")
    problem = ContactProblem(F, u, bcs, [pair], **options)

    def apply_load(t):
        drive.x.array.reshape(-1, 3)[:, 2] = -0.02 * length * t

    return problem, apply_load


def solve_curved_punch(comm=MPI.COMM_WORLD, steps: int = 2, **options) -> dict:
    problem, apply_load = curved_punch(comm, **options)
    records = solve_load_steps(problem, apply_load, steps)
    coordinates, pressure = problem.gathered_pressure()
    slave, master = problem.contact_forces()
    result = {
        "coordinates": coordinates,
        "pressure": pressure,
        "active": problem.num_active(),
        "iterations": [r.report.iterations for r in records],
        "residuals": [r.report.residuals for r in records],
        "slave_force": slave,
        "master_force": master,
        "c_n": problem.c_n,
    }
    problem.destroy()
    return result


@pytest.fixture(scope="module")
def curved_reference():
    return solve_curved_punch(MPI.COMM_SELF)


def test_curved_punch_semismooth_newton(curved_reference):
    """A contact zone of several elements, at most 8 semismooth iterations per step,
    quadratic at the end (linear material: one iteration once the set is right), the
    forces in balance, the pressure positive on the active nodes."""
    result = curved_reference
    assert 4 <= result["active"] < result["pressure"].size
    assert max(result["iterations"]) <= 8
    slave, master = result["slave_force"], result["master_force"]
    assert slave[2] > 0.1
    assert np.abs(slave + master).max() <= 1e-10 * slave[2]
    assert np.abs(slave[:2]).max() <= 1e-8 * slave[2]  # symmetric punch
    assert result["pressure"].min() >= -1e-10 * result["pressure"].max()


@pytest.mark.parametrize("factor", [1e-2, 1e2])
def test_curved_punch_does_not_depend_on_c_n(curved_reference, factor):
    other = solve_curved_punch(MPI.COMM_SELF, c_n=factor * curved_reference["c_n"])
    assert other["active"] == curved_reference["active"]
    scale = np.abs(curved_reference["pressure"]).max()
    assert np.abs(other["pressure"] - curved_reference["pressure"]).max() <= 1e-8 * scale


@pytest.mark.parametrize("material", ["linear", "neo-hookean"])
def test_curved_punch_is_unit_free(material):
    """Lengths x 1e3 and moduli x 1e-6: the same dimensionless pressure p / E at the same
    nodes x / L, the same active set and Newton iterations (every tolerance scales)."""
    options = {"cell": "tetrahedron", "ratio": (4, 3), "material": material}
    base = solve_curved_punch(MPI.COMM_SELF, **options)
    scaled = solve_curved_punch(MPI.COMM_SELF, length=1e3, modulus=1e-6, **options)
    assert scaled["active"] == base["active"] > 0
    assert scaled["iterations"] == base["iterations"]
    np.testing.assert_allclose(scaled["coordinates"] / 1e3, base["coordinates"], atol=1e-12)
    scale = np.abs(base["pressure"]).max()
    assert np.abs(scaled["pressure"] / 1e-6 - base["pressure"]).max() <= 1e-8 * scale


@pytest.mark.parametrize("preconditioner", ["hypre", "gamg"])
def test_curved_punch_iterative_solver_gives_the_direct_answer(curved_reference, preconditioner):
    options = {} if preconditioner == "hypre" else {"petsc_options": {"condensed_pc_type": "gamg"}}
    other = solve_curved_punch(MPI.COMM_SELF, linear_solver="iterative", **options)
    assert other["iterations"] == curved_reference["iterations"]
    scale = np.abs(curved_reference["pressure"]).max()
    assert np.abs(other["pressure"] - curved_reference["pressure"]).max() <= 1e-8 * scale


@pytest.mark.parallel
def test_curved_punch_serial_equals_parallel():
    serial = solve_curved_punch(MPI.COMM_SELF, cell="tetrahedron")
    parallel = solve_curved_punch(MPI.COMM_WORLD, cell="tetrahedron")
    assert parallel["active"] == serial["active"]
    assert parallel["iterations"] == serial["iterations"]
    np.testing.assert_allclose(parallel["coordinates"], serial["coordinates"], atol=1e-14)
    scale = np.abs(serial["pressure"]).max()
    assert np.abs(parallel["pressure"] - serial["pressure"]).max() <= 1e-8 * scale


def test_curved_punch_neo_hookean_converges_quadratically():
    """Once the active set has settled, r_{k+1}/r_0 <= 10 (r_k/r_0)^2 (measured on both
    steps: 0.039 -> 5.5e-6 -> 2.5e-12 after the set changed at the second iteration)."""
    result = solve_curved_punch(MPI.COMM_SELF, material="neo-hookean", cell="tetrahedron")
    assert max(result["iterations"]) <= 8
    for residuals in result["residuals"]:
        q = np.array(residuals) / residuals[0]
        # the tail after the last rise of the residual (the last change of the active set)
        rises = np.flatnonzero(np.diff(q) > 0)
        tail = slice(rises[-1] + 1 if rises.size else 0, None)
        q, r = q[tail], np.array(residuals)[tail]
        asymptotic = [(a, b) for a, b, rb in zip(q[:-1], q[1:], r[1:], strict=True)
                      if a < 0.1 and rb > 1e-11]
        assert asymptotic, residuals
        for a, b in asymptotic:
            assert b <= 10.0 * a**2, residuals


@pytest.mark.parallel
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("method", ["lagrange", "penalty"])
def test_contact_jacobian_taylor(normals, method):
    """The whole 3D contact system R(x) in a penetrating, sheared state (Neo-Hookean,
    current configuration; every slave node 0.04 deep, so no active set changes within
    the steps): |R(x + e h) - R(x) - e J h| = O(e^2)."""
    problem = penetrating_punch(curvature=0.0, normals=normals, method=method)
    assert_taylor_second_order(problem, seed=3)
    problem.destroy()


@pytest.mark.parametrize("multipliers", ["dual", "standard"])
def test_contact_blocks_skip_the_pairs_without_weight(monkeypatch, multipliers):
    """Pairs whose slave nodes are all inactive (zero multipliers, zero gap and area
    coefficients) add nothing through their gradients: the system makes none for them
    (``system._weighted_rows``), and the matrix equals the one made with every
    contributing pair's gradients (curved punch, Neo-Hookean, a contact zone smaller than
    the paired surface)."""
    from petsc4py import PETSc

    from dolfinx_mortar import system

    problem, apply_load = curved_punch(MPI.COMM_SELF, cell="tetrahedron", ratio=(4, 3),
                                       material="neo-hookean", basis=multipliers)
    solve_load_steps(problem, apply_load, 1)
    fractions = []
    weighted_rows = system._weighted_rows

    def recorded(terms, n):
        rows = weighted_rows(terms, n)
        fractions.append(rows.size / n)
        return rows

    monkeypatch.setattr(system, "_weighted_rows", recorded)
    skipping = problem.equations.assemble_system().copy()
    assert 0.0 < fractions[0] < 1.0, fractions
    monkeypatch.setattr(system, "_weighted_rows", lambda terms, n: np.arange(n))
    every = problem.equations.assemble_system()
    scale = every.norm(PETSc.NormType.INFINITY)
    skipping.axpy(-1.0, every)
    assert skipping.norm(PETSc.NormType.INFINITY) <= 1e-14 * scale
    skipping.destroy()
    problem.destroy()


def penetrating_punch(curvature: float, **options) -> ContactProblem:
    """curved_punch (tetrahedra 4:3, Neo-Hookean, current configuration) with the punch
    moved 0.04 into the foundation and sheared by 0.01 sin / cos waves plus 1e-3 noise,
    and random multipliers z in [0.5, 1.5]: a state for Taylor tests in which no active
    set changes within the steps."""
    problem, apply_load = curved_punch(MPI.COMM_WORLD, cell="tetrahedron", ratio=(4, 3),
                                       curvature=curvature, material="neo-hookean", **options)
    rng = np.random.default_rng(3 + problem.comm.rank)
    u = problem.u
    V = u.function_space
    shift = dolfinx.fem.Function(V)
    punch = dolfinx.mesh.locate_entities(V.mesh, 3, lambda x: x[2] >= 0.5 - 1e-12)
    shift.interpolate(lambda x: np.vstack([0.01 * np.sin(3 * x[1]), 0.01 * np.cos(2 * x[0]),
                                           -0.04 + 0.0 * x[2]]), punch)
    u.x.array[:] = shift.x.array + 1e-3 * rng.standard_normal(u.x.array.size)
    u.x.scatter_forward()
    apply_load(0.0)
    compat.set_bc_values(u, problem.bcs)
    for z in problem.multipliers:
        z.setArray(rng.uniform(0.5, 1.5, z.getLocalSize()))
    problem.equations.read_state(problem.x)
    return problem


@pytest.mark.parallel
def test_slave_surface_on_the_wrong_face_warns_in_3d():
    """The punch's top tagged as the slave looks away from the foundation: a warning at set-up
    that names the pair, and no silent pass-through."""
    comm = MPI.COMM_WORLD
    tagged = meshes.patch_test_3d(ratio=(3, 2), comm=comm)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(1000.0, 0.3, "linear")})
    markers = tagged.markers
    wrong = ContactPair(tagged.facet_tags, markers["punch_top"], markers["foundation_contact"],
                        name="punch")
    with warns_on_rank_zero(r"'punch'.*looks away from its master.*9 of 9"):
        ContactProblem(F, u, [], [wrong]).destroy()
    right = ContactPair(tagged.facet_tags, markers["punch_contact"],
                        markers["foundation_contact"], name="punch")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ContactWarning)
        ContactProblem(F, u, [], [right]).destroy()


@pytest.mark.parallel
def test_penetration_report_finds_nodes_behind_a_3d_surface():
    """Foundation nodes pushed 0.3 (> half a facet) into the punch are found and located;
    nodes beside the punch's footprint or only shallowly inside are not."""
    comm = MPI.COMM_WORLD
    problem, _ = curved_punch(comm, ratio=(3, 2), curvature=0.0)
    u = problem.u
    V = u.function_space
    cells = dolfinx.mesh.locate_entities(V.mesh, 3, lambda x: x[2] <= 0.5 + 1e-12)
    foundation = dolfinx.fem.locate_dofs_topological(V, 3, cells)
    x = V.tabulate_dof_coordinates()
    blocks = foundation[np.isclose(x[foundation, 2], 0.5)]
    centre = blocks[np.isclose(x[blocks, 0], 0.5) & np.isclose(x[blocks, 1], 0.5)]
    values = u.x.array.reshape(-1, 3)
    values[blocks, 2] = 0.05
    values[centre, 2] = 0.3
    u.x.scatter_forward()
    with warns_on_rank_zero(r"1 master node\(s\) ended the step behind the "
                      r"slave surface.*\(0.5, 0.5, 0.8"):
        reports = problem.check_penetration()
    assert reports[0].count == 1 and reports[0].side == "master"
    assert reports[0].depth == pytest.approx(0.3 / (1.0 / 3.0), rel=1e-12)
    problem.destroy()


@pytest.mark.parallel
@pytest.mark.timeout(600)
def test_ironing_3d_small_run_balances_and_gives_the_serial_answer():
    """The extruded die pressed 0.1 into the extruded block (two hexahedra through the
    thickness): every step converges, die and block forces balance, the die-top reaction
    equals the contact force, N ranks give the serial forces to 1e-8 (and the serial
    Newton iterations to one), and the serial steps end quadratically."""
    args = ["--dim", "3", "--layers", "2", "--steps", "40", "--end-time", "0.3"]
    serial = demo("ironing").main(list(args), comm=MPI.COMM_SELF)
    parallel = demo("ironing").main(list(args), comm=MPI.COMM_WORLD)
    for summary in (serial, parallel):
        assert summary["steps_completed"] == 6 and summary["end_time"] == pytest.approx(0.3)
        assert summary["max_newton_iterations"] <= 8
        assert summary["max_force_balance_rel"] <= 1e-8
        assert summary["max_reaction_mismatch_rel"] <= 1e-8
    last = (serial["history"][-1], parallel["history"][-1])
    assert -last[0]["block_force_y"] > 1e7
    for key in ("block_force_x", "block_force_y"):
        assert last[1][key] == pytest.approx(last[0][key], rel=1e-8, abs=1e-8 * 1e8)
    # the same Newton path but for rounding: PETSc sums off-process matrix and vector
    # contributions in the order the messages arrive, and one make-test run on 3 loaded
    # ranks (of about 10 runs) took 8 iterations instead of 7 in step 5 (same forces)
    assert len(parallel["newton_iterations"]) == len(serial["newton_iterations"])
    for a, b in zip(serial["newton_iterations"], parallel["newton_iterations"], strict=True):
        assert abs(a - b) <= 1, (serial["newton_iterations"], parallel["newton_iterations"])
    # quadratic at the end: the last drop above the rounding floor (1e-11 r_0) has
    # r_k+1/r_0 <= 10 (r_k/r_0)^2 (the active set may change in any earlier iteration)
    checked = 0
    for step in serial["history"]:
        q = np.array(step["residuals"]) / step["residuals"][0]
        drops = [(a, b) for a, b in zip(q[:-1], q[1:], strict=True) if a < 0.1 and b > 1e-11]
        if drops:
            a, b = drops[-1]
            assert b <= 10.0 * a**2, step["residuals"]
            checked += 1
    assert checked == 2, [h["residuals"] for h in serial["history"]]  # the steps in contact


@pytest.mark.parallel
def test_bad_3d_input_fails_on_every_rank_with_a_message():
    """Unknown options, a tag that marks nothing, a slave on the master's body, an iterative
    solver with standard multipliers, a quadratic space: a ValueError on every rank (the
    parallel run would hang if one rank went on)."""
    from dolfinx_mortar.surface import SurfaceError

    comm = MPI.COMM_WORLD
    tagged = meshes.patch_test_3d(ratio=(2, 3), comm=comm)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(1.0, 0.3, "linear")})
    markers = tagged.markers
    pair = ContactPair(tagged.facet_tags, markers["contact_slave"], markers["contact_master"])
    for key, value in (("method", "lagrangian"), ("integration", "nodal"), ("normals", "up"),
                       ("basis", "mortar"), ("linear_solver", "cg")):
        with pytest.raises(ValueError, match=f"unknown {key}"):
            ContactProblem(F, u, [], [pair], **{key: value})
    with pytest.raises(ValueError, match="needs dual multipliers, basis='dual'"):
        ContactProblem(F, u, [], [pair], basis="standard", linear_solver="iterative")
    with pytest.raises(SurfaceError, match="marks no facet"):
        ContactProblem(F, u, [], [ContactPair(tagged.facet_tags, 999, markers["contact_master"])])
    wrong = ContactPair(tagged.facet_tags, markers["foundation_bottom"],
                        markers["foundation_contact"])
    with pytest.raises(ValueError, match="wrong body"):
        ContactProblem(F, u, [], [wrong])
    quadratic = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 2, (3,)))
    w = dolfinx.fem.Function(quadratic)
    G = internal_work(w, ufl.TestFunction(quadratic), {0: Material(1.0, 0.3, "linear")})
    with pytest.raises(SurfaceError, match="degree|quadratic|P1|linear"):
        ContactProblem(G, w, [], [pair])
