"""Failures and silent wrong answers turned into messages (dolfinx_mortar.diagnostics).

A punch driven into a block with its slave surface tagged on the face that looks
away from the block must not pass through silently; a load that inverts elements
must end in a message that says so; every PETSc reason gets its name and words.
"""

from __future__ import annotations

import warnings

import dolfinx
import numpy as np
import pytest
import ufl
from contact_warnings import warns_on_rank_zero
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    ContactWarning,
    LoadSteppingError,
    Material,
    SolveReport,
    diagnostics,
    internal_work,
    meshes,
    solve_load_steps,
)


def punch(comm, slave_face: str, material: str = "neo-hookean"):
    """The patch test's punch [4, 6] x [5, 7], its sides driven down, on the foundation.

    ``slave_face``: "bottom" (right: it faces the foundation) or "top" (wrong: it
    looks away from the foundation's top, the master)."""
    tagged = meshes.patch_test(ratio=(3, 2), comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(1000.0, 0.3, material)})
    sides = dolfinx.mesh.locate_entities_boundary(
        mesh, 1, lambda x: (np.isclose(x[0], 4.0) | np.isclose(x[0], 6.0)) & (x[1] > 5.5))
    bottom = tagged.facet_tags.find(markers["foundation_bottom"])
    drive = dolfinx.fem.Function(V)
    bcs = [
        dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, bottom), V),
        dolfinx.fem.dirichletbc(drive, dolfinx.fem.locate_dofs_topological(V, 1, sides)),
    ]
    slave = markers["punch_contact" if slave_face == "bottom" else "punch_top"]
    pair = ContactPair(tagged.facet_tags, slave, markers["foundation_contact"], name="punch")

    def apply_load(depth):
        def set_depth(t):
            drive.x.array.reshape(-1, 2)[:, 1] = -depth * t
        return set_depth

    return F, u, bcs, pair, apply_load


@pytest.mark.parallel
def test_slave_surface_tagged_on_the_wrong_face_warns_at_setup_and_after_steps(comm, caplog):
    """One warning per cause, shown once by rank 0: the wrong face at set-up, the nodes
    behind the slave after the first step; the second step's penetration goes to the log."""
    F, u, bcs, pair, apply_load = punch(comm, "top")
    with warns_on_rank_zero(r"contact pair 'punch'.*looks away from its master"
                            r".*3 of 3 slave facets.*wrong face") as caught:
        problem = ContactProblem(F, u, bcs, [pair])
    assert len(caught) == (1 if comm.rank == 0 else 0)
    with caplog.at_level("INFO", logger="dolfinx_mortar"):
        with warns_on_rank_zero(r"'punch'.*3 master node\(s\) ended the step behind "
                                r"the slave surface.*wrong face") as caught:
            solve_load_steps(problem, apply_load(1.0), 2)
    assert len(caught) == (1 if comm.rank == 0 else 0)
    again = [r for r in caplog.records if r.getMessage().startswith("again: ")]
    assert len(again) == (1 if comm.rank == 0 else 0)
    slave_force, _ = problem.contact_forces()
    assert problem.num_active() == 0 and np.all(slave_force == 0.0)  # what went unnoticed
    problem.destroy()


@pytest.mark.parallel
def test_the_right_face_gives_no_warning_and_a_contact_force(comm):
    F, u, bcs, pair, apply_load = punch(comm, "bottom")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ContactWarning)
        problem = ContactProblem(F, u, bcs, [pair])
        solve_load_steps(problem, apply_load(0.1), 2)
    slave_force, master_force = problem.contact_forces()
    assert slave_force[1] > 10.0
    assert np.allclose(slave_force, -master_force, rtol=1e-9, atol=1e-9 * abs(slave_force[1]))
    assert all(r.count == 0 for r in problem.check_penetration())
    problem.destroy()


def test_an_inverting_load_ends_in_a_message_that_says_inverted(comm):
    """Pressing the punch 4.5 deep into a foundation 5 tall: elements under its corners
    invert; the cut-backs stop at min_increment and the error names the inversion."""
    F, u, bcs, pair, apply_load = punch(comm, "bottom")
    problem = ContactProblem(F, u, bcs, [pair])
    with pytest.raises(LoadSteppingError, match=r"(?s)no convergence from t = .*inverted") as info:
        solve_load_steps(problem, apply_load(4.5), 2)
    error = info.value
    message = str(error)
    assert "The last converged step ended at t = " in message
    assert 0.0 < error.last_converged < error.failed < 1.0
    assert f"{error.last_converged:.6g}" in message
    assert "min_increment" in message
    problem.destroy()


def test_cut_backs_stop_at_min_increment_with_the_times_in_the_message():
    """A solver that cannot pass t = 0.3: the increments halve until min_increment."""

    class Wall:
        comm = MPI.COMM_WORLD

        def __init__(self):
            self.load = self.accepted = 0.0

        def save_state(self):
            return self.accepted

        def restore_state(self, state):
            self.accepted = state

        def solve(self):
            converged = self.load <= 0.3
            if converged:
                self.accepted = self.load
            return SolveReport(converged=converged, reason=2 if converged else -6,
                               iterations=4, residuals=[1.0], active=0)

    wall = Wall()
    with pytest.raises(LoadSteppingError, match=r"no convergence from t = 0\.29\d+ to 0\.30\d+ "
                       r"with "
                       r"the increment down to .* min_increment = 0\.001.*DIVERGED_LINE_SEARCH "
                       r"\(the line search failed\)") as info:
        solve_load_steps(wall, lambda t: setattr(wall, "load", t), 4, max_cutbacks=50,
                         min_increment=1e-3)
    assert 0.3 - 4e-3 < info.value.last_converged <= 0.3 < info.value.failed < 0.3 + 4e-3


def test_every_snes_reason_has_a_name_and_words():
    reasons = PETSc.SNES.ConvergedReason
    for name in dir(reasons):
        if name.startswith(("CONVERGED", "DIVERGED")) and name != "CONVERGED_ITERATING":
            text = diagnostics.describe_snes_reason(getattr(reasons, name))
            assert text.startswith(f"{getattr(reasons, name)} {name} (")
            assert "no description" not in text
    assert "UZAWA" in diagnostics.describe_snes_reason(diagnostics.UZAWA_NOT_SETTLED)


def test_a_singular_factorization_is_described():
    matrix = PETSc.Mat().createAIJ((3, 3), nnz=1, comm=MPI.COMM_SELF)
    for i, value in enumerate([1.0, 0.0, 1.0]):
        matrix.setValue(i, i, value)
    matrix.assemble()
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    ksp.setOperators(matrix)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.setErrorIfNotConverged(False)
    b, x = matrix.createVecs()
    b.set(1.0)
    ksp.solve(b, x)
    text = diagnostics.describe_ksp_failure(ksp)
    for words in ("DIVERGED_PCSETUP_FAILED", "FACTOR_NUMERIC_ZEROPIVOT", "zero or tiny pivot"):
        assert words in text
    ksp.destroy()
    matrix.destroy()
    b.destroy()
    x.destroy()


def test_a_factorization_out_of_working_space_is_described_as_such():
    """A saddle-point matrix (its zero block delays pivots) factorized by MUMPS with no
    margin on the estimated working space (ICNTL(14) = 0, strict pivoting): INFOG(1) = -9,
    named as such, not as a singular system."""
    n, m = 400, 200
    rng = np.random.default_rng(1)
    B = np.zeros((m, n))
    for i in range(m):
        B[i, rng.choice(n, 4, replace=False)] = rng.uniform(-1.0, 1.0, 4)
    K = np.block([[np.diag(rng.uniform(1.0, 2.0, n)), B.T], [B, np.zeros((m, m))]])
    rows, cols = np.nonzero(K)
    matrix = PETSc.Mat().createAIJ(K.shape, nnz=np.bincount(rows).astype(PETSc.IntType),
                                   comm=MPI.COMM_SELF)
    for r, c in zip(rows, cols, strict=True):
        matrix.setValue(r, c, K[r, c])
    matrix.assemble()
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    ksp.setOperators(matrix)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    pc.setFactorSetUpSolverType()
    pc.getFactorMatrix().setMumpsIcntl(14, 0)
    pc.getFactorMatrix().setMumpsCntl(1, 1.0)
    ksp.setErrorIfNotConverged(False)
    b, x = matrix.createVecs()
    b.set(1.0)
    ksp.solve(b, x)
    assert pc.getFactorMatrix().getMumpsInfog(1) == -9
    text = diagnostics.describe_ksp_failure(ksp)
    assert "FACTOR_OUTMEMORY" in text and "mat_mumps_icntl_14" in text
    assert "pivot: a singular system" not in text
    for obj in (ksp, matrix, b, x):
        obj.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize(
    "cell_type", ["triangle", "quadrilateral", "tetrahedron", "hexahedron"])
def test_inversion_check_counts_and_locates_the_inverted_cells(comm, cell_type):
    """u = -2 y e_y maps y -> -y: every cell is inverted (det F = -1); u = 0 leaves
    det F = 1; squashing x < 0.25 to det F = 0.5 locates the worst; a shear keeps det F = 1."""
    kind = getattr(dolfinx.mesh.CellType, cell_type)
    if cell_type in ("triangle", "quadrilateral"):
        mesh = dolfinx.mesh.create_unit_square(comm, 4, 4, kind)
    else:
        mesh = dolfinx.mesh.create_unit_cube(comm, 4, 4, 4, kind)
    gdim = mesh.geometry.dim
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (gdim,)))
    check = diagnostics.InversionCheck(V)
    u = dolfinx.fem.Function(V)
    assert check(u.x.array).count == 0
    assert check.worst(u.x.array)[0] == pytest.approx(1.0, rel=1e-12)

    def field(component):
        return lambda x: np.stack([component(x) if i == 1 else np.zeros_like(x[0])
                                   for i in range(gdim)])

    u.interpolate(field(lambda x: -2.0 * x[1]))
    num_cells = mesh.topology.index_map(gdim).size_global
    inversion = check(u.x.array)
    assert inversion.count == num_cells
    assert "inverted element" in inversion.describe()
    u.interpolate(lambda x: np.stack([-0.5 * np.minimum(x[0], 0.25)]
                                     + [np.zeros_like(x[0])] * (gdim - 1)))
    ratio, where = check.worst(u.x.array)
    assert check(u.x.array).count == 0
    assert ratio == pytest.approx(0.5, rel=1e-12) and where[0] < 0.25
    u.interpolate(field(lambda x: 3.0 * x[0]))  # a shear: det F = 1 everywhere
    assert check.worst(u.x.array)[0] == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parallel
@pytest.mark.parametrize("slave_face", ["contact", "top"])
def test_user_punch_from_two_rectangles_pressed_and_slid(comm, slave_face):
    """The scene of the user's report: a Neo-Hookean punch on a wider block, both from
    create_rectangle, pressed 0.05 and slid 0.1 by its top. Tagged right, it presses on
    the block with balanced forces and no warning; with the slave tagged on the punch's
    top (it looks away from the block) the user is told at set-up and after every step."""
    from dolfinx_mortar import merge_meshes

    punch = dolfinx.mesh.create_rectangle(comm, [[-0.5, 1.0], [0.5, 1.5]], [6, 3])
    block = dolfinx.mesh.create_rectangle(comm, [[-1.0, 0.0], [1.0, 1.0]], [12, 6])
    tagged = merge_meshes({
        "punch": (punch, {"contact": lambda x: np.isclose(x[1], 1.0),
                          "top": lambda x: np.isclose(x[1], 1.5)}),
        "block": (block, {"contact": lambda x: np.isclose(x[1], 1.0),
                          "bottom": lambda x: np.isclose(x[1], 0.0)})})
    mesh, markers = tagged.mesh, tagged.markers
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(100.0, 0.3, "neo-hookean")})
    top = dolfinx.fem.Function(V)
    facets = tagged.facet_tags
    bcs = [dolfinx.fem.dirichletbc(top, dolfinx.fem.locate_dofs_topological(
               V, 1, facets.find(markers["punch_top"]))),
           dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(
               V, 1, facets.find(markers["block_bottom"])), V)]
    pair = ContactPair(facets, markers[f"punch_{slave_face}"], markers["block_contact"],
                       name="punch-block")

    def apply_load(t):  # press to 0.05 in the first half, then slide by 0.1
        top.x.array.reshape(-1, 2)[:] = (0.2 * max(t - 0.5, 0.0), -0.1 * min(t, 0.5))

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ContactWarning)
        problem = ContactProblem(F, u, bcs, [pair])
        solve_load_steps(problem, apply_load, 4)
    messages = [str(w.message) for w in caught if issubclass(w.category, ContactWarning)]
    slave_force, master_force = problem.contact_forces()
    if slave_face == "contact":
        assert messages == []
        assert slave_force[1] > 1.0 and problem.num_active() > 0
        assert np.linalg.norm(slave_force + master_force) <= 1e-9 * np.linalg.norm(slave_force)
    else:
        assert len(messages) == (2 if comm.rank == 0 else 0)  # set-up, the first step
        if comm.rank == 0:
            assert "looks away from its master" in messages[0] and "wrong face" in messages[0]
            assert "ended the step behind the slave surface" in messages[1]
        assert problem.num_active() == 0
    problem.destroy()
