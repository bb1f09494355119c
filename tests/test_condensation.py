"""Static condensation of dual multipliers: the same solutions as the monolithic solve.

The condensed solve preconditions fgmres on the monolithic system, so the
Newton iterates must not change: condensed and uncondensed displacements and
pressures agree to 1e-9 (Newton stops at 1e-10). Where the condensation is
exact (penalty rows; Lagrange rows when T G is diagonal, as on the flat patch
test), the outer method needs one iteration per Newton step.
"""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from stress.common import gathered_displacement, hertz, patch_traction, relative_difference
from test_iterative_solver import rebuilt_inner_matrix

from dolfinx_mortar import ContactPair, ContactProblem, Material, internal_work, meshes

OPTIONS = {
    "semismooth": {"method": "lagrange"},
    "fixed-point": {"method": "lagrange", "active_set": "fixed-point"},
    "penalty": {"method": "penalty"},
    "augmented": {"method": "augmented"},
}


def solution(problem: ContactProblem, cell_tags) -> dict:
    """Nodal displacements sorted by (x, y, body) and each pair's pressure sorted by x.

    The mesh partition may differ between two builds, so the dof order does too;
    nodes of the two bodies at the same place are told apart by their cells' tag.
    """
    V = problem.V
    owned = V.dofmap.index_map.size_local
    num_cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    cell_tag = np.zeros(num_cells, dtype=np.int64)
    local = cell_tags.indices < num_cells
    cell_tag[cell_tags.indices[local]] = cell_tags.values[local]
    node_tag = np.zeros(owned + V.dofmap.index_map.num_ghosts, dtype=np.int64)
    node_tag[V.dofmap.list[:num_cells]] = cell_tag[:, None]
    body = np.concatenate(problem.comm.allgather(node_tag[:owned]))
    coordinates, displacement = gathered_displacement(problem.u)
    # dof coordinates are evaluated in some cell: equal only to rounding
    rounded = np.round(coordinates, 9)
    order = np.lexsort((body, rounded[:, 1], rounded[:, 0]))
    return {
        "displacement": displacement[order],
        "pressure": [problem.gathered_pressure(k)[1] for k in range(len(problem.interfaces))],
        "active": problem.num_active(),
    }


def assert_same_solution(condensed: dict, uncondensed: dict, tolerance=1e-9):
    assert condensed["active"] == uncondensed["active"]
    difference = relative_difference(condensed["displacement"], uncondensed["displacement"])
    assert difference <= tolerance
    for pressure, reference in zip(condensed["pressure"], uncondensed["pressure"], strict=True):
        assert pressure.size
        assert relative_difference(pressure, reference) <= tolerance


@pytest.mark.parallel
@pytest.mark.parametrize("name", sorted(OPTIONS))
@pytest.mark.parametrize("slave", ["top", "bottom"])
def test_condensed_patch_test_is_exact_in_one_outer_iteration(name, slave):
    solutions, reports = {}, {}
    for condensation in (False, True):
        setup = patch_traction(ratio=(3, 7), slave=slave, condensation=condensation,
                               **OPTIONS[name])
        setup.apply_load(1.0)
        reports[condensation] = setup.problem.solve()
        assert reports[condensation].converged
        solutions[condensation] = solution(setup.problem, setup.tagged.cell_tags)
        setup.destroy()
    assert_same_solution(solutions[True], solutions[False])
    if name != "penalty":
        pressure = solutions[True]["pressure"][0]
        assert np.max(np.abs(pressure - 10.0)) <= 1e-10 * 10.0
    # flat surfaces, full coverage: T G is diagonal and the condensation exact
    assert reports[True].linear_iterations == reports[True].iterations


@pytest.mark.parallel
@pytest.mark.timeout(600)
@pytest.mark.parametrize("name", ["semismooth", "fixed-point", "penalty"])
def test_condensed_hertz_equals_uncondensed(name):
    outcomes, solutions = {}, {}
    for condensation in (False, True):
        setup = hertz(refinement=0, condensation=condensation, **OPTIONS[name])
        outcomes[condensation] = setup.steps(2)
        assert outcomes[condensation].converged
        solutions[condensation] = solution(setup.problem, setup.tagged.cell_tags)
        if condensation:
            condenser = setup.problem._condenser
            set_ups = (condenser.rebuilds, condenser.reuses)
        setup.destroy()
    assert solutions[True]["active"] > 0
    assert outcomes[True].iterations == outcomes[False].iterations
    # sub-matrices and products are built again only when J's pattern changed
    assert set_ups[0] >= 1 and set_ups[1] > set_ups[0], set_ups
    assert_same_solution(solutions[True], solutions[False])
    records = outcomes[True].extra["records"]
    linear = sum(r.report.linear_iterations for r in records)
    newton = sum(r.report.iterations for r in records)
    if name == "penalty":
        assert linear == newton  # exact condensation
    else:
        assert newton <= linear <= 5 * newton


def two_pair_patch_test(condensation: bool, comm=MPI.COMM_WORLD):
    """The patch test with the punch's contact surface split at x = 5 into two pairs."""
    tagged = meshes.patch_test(ratio=(4, 7), slave="top", comm=comm)
    mesh, markers = tagged.mesh, tagged.markers
    tags = tagged.facet_tags
    values = tags.values.copy()
    slave = values == markers["contact_slave"]
    midpoints = dolfinx.mesh.compute_midpoints(mesh, 1, tags.indices[slave])
    right = max(markers.values()) + 1
    values[np.flatnonzero(slave)[midpoints[:, 0] > 5.0]] = right
    facet_tags = dolfinx.mesh.meshtags(mesh, 1, tags.indices, values)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags)
    traction = dolfinx.fem.Constant(mesh, np.array([0.0, -10.0]))
    F = internal_work(u, v, {0: Material(1000.0, 0.4, "linear")}) - ufl.inner(traction, v) * (
        ds(markers["punch_top"]) + ds(markers["foundation_top_free"]))
    strain_xx = 10.0 * 0.4 * 1.4 / 1000.0
    bottom = facet_tags.find(markers["foundation_bottom"])
    bcs = [dolfinx.fem.dirichletbc(np.float64(0.0),
                                   dolfinx.fem.locate_dofs_topological(V.sub(1), 1, bottom),
                                   V.sub(1))]
    mesh.topology.create_connectivity(0, 2)
    for corner in ((0.0, 0.0), (4.0, 7.0)):
        vertices = dolfinx.mesh.locate_entities(
            mesh, 0, lambda x, c=corner: np.isclose(x[0], c[0]) & np.isclose(x[1], c[1]))
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(0), 0, vertices)
        bcs.append(dolfinx.fem.dirichletbc(np.float64(strain_xx * corner[0]), dofs, V.sub(0)))
    pairs = [ContactPair(facet_tags, tag, markers["contact_master"], name=name)
             for tag, name in ((markers["contact_slave"], "left"), (right, "right"))]
    problem = ContactProblem(F, u, bcs, pairs, configuration="reference",
                             condensation=condensation)
    return problem, tagged.cell_tags


@pytest.mark.parallel
def test_condensation_with_two_pairs():
    solutions, reports = {}, {}
    for condensation in (False, True):
        problem, cell_tags = two_pair_patch_test(condensation)
        reports[condensation] = problem.solve()
        assert reports[condensation].converged
        solutions[condensation] = solution(problem, cell_tags)
        problem.destroy()
    assert_same_solution(solutions[True], solutions[False])
    for pressure in solutions[True]["pressure"]:
        assert np.max(np.abs(pressure - 10.0)) <= 1e-10 * 10.0
    report = reports[True]
    # two multipliers at x = 5: an approximate condensation there, still a few iterations
    assert report.linear_iterations <= 4 * report.iterations


@pytest.mark.parallel
def test_separated_bodies_condense_to_the_bulk_matrix():
    """No active node: K_c is the bulk matrix; one outer iteration per Newton step."""
    tagged = meshes.tied_blocks(ratio=(2, 3))
    mesh = tagged.mesh
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    F = internal_work(u, ufl.TestFunction(V), {0: Material(10.0, 0.3, "neo-hookean")})
    bcs = []
    for y, value in ((0.0, np.zeros(2)), (1.0, np.array([0.0, 0.3]))):
        facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x, y=y: np.isclose(x[1], y))
        dofs = dolfinx.fem.locate_dofs_topological(V, 1, facets)
        bcs.append(dolfinx.fem.dirichletbc(value, dofs, V))
    pair = ContactPair(
        tagged.facet_tags, tagged.markers["contact_slave"], tagged.markers["contact_master"]
    )
    problem = ContactProblem(F, u, bcs, [pair], search_margin=0.05, condensation=True)
    report = problem.solve()
    assert report.converged and report.active == 0
    assert report.linear_iterations == report.iterations
    problem.destroy()


@pytest.mark.parallel
def test_inner_solver_options_take_the_condensed_prefix():
    """An inexact inner solve (block Jacobi/ILU, 10 GMRES steps) only costs outer iterations."""
    inexact = {"condensed_ksp_type": "gmres", "condensed_pc_type": "bjacobi",
               "condensed_ksp_max_it": 10}
    setup = patch_traction(ratio=(3, 7), slave="bottom", condensation=True,
                           petsc_options=inexact)
    setup.apply_load(1.0)
    report = setup.problem.solve()
    inner = setup.problem._condenser.ksp
    assert inner.getPC().getType() == "bjacobi" and inner.getType() == "gmres"
    assert report.converged and report.linear_iterations > report.iterations
    pressure = setup.problem.gathered_pressure()[1]
    assert np.max(np.abs(pressure - 10.0)) <= 1e-10 * 10.0
    setup.destroy()


@pytest.mark.parallel
@pytest.mark.timeout(600)
@pytest.mark.parametrize("preconditioner", ["hypre", "gamg"])
def test_iterative_linear_solver_gives_the_direct_answer(preconditioner):
    """GMRES + AMG on the condensed system (BoomerAMG by default, GAMG with the rigid-body
    near-nullspace on request) preconditions the same Newton steps: the same iterations and
    the direct answer to 1e-8."""
    outcomes, solutions = {}, {}
    for linear_solver in ("direct", "iterative"):
        options = {"condensed_pc_type": "gamg"} if preconditioner == "gamg" else {}
        setup = hertz(refinement=0, linear_solver=linear_solver, petsc_options=options)
        outcomes[linear_solver] = setup.steps(2)
        assert outcomes[linear_solver].converged
        solutions[linear_solver] = solution(setup.problem, setup.tagged.cell_tags)
        if linear_solver == "iterative":
            inner = setup.problem._condenser.ksp
            assert inner.getType() == "gmres" and inner.getPC().getType() == preconditioner
            K_c = rebuilt_inner_matrix(setup.problem)
            assert K_c.getBlockSize() == 2
            assert len(K_c.getNearNullSpace().getVecs()) == 6  # 3 modes x 2 bodies
        setup.destroy()
    assert outcomes["iterative"].iterations == outcomes["direct"].iterations
    assert_same_solution(solutions["iterative"], solutions["direct"], tolerance=1e-8)


@pytest.mark.parallel
@pytest.mark.parametrize("cell", ["triangle", "tetrahedron"])
def test_rigid_body_modes_are_the_kernel_of_elasticity(cell):
    """The modes of each body are orthonormal and K m = 0 for the free elastic bodies."""
    from dolfinx.fem.petsc import assemble_matrix

    from dolfinx_mortar import merge_meshes
    from dolfinx_mortar.solvers import rigid_body_modes

    comm = MPI.COMM_WORLD
    if cell == "triangle":
        lower = dolfinx.mesh.create_rectangle(comm, [[0, 0], [1, 0.5]], [4, 2])
        upper = dolfinx.mesh.create_rectangle(comm, [[0.2, 0.5], [0.8, 1.0]], [3, 3])
    else:
        cube = dolfinx.mesh.create_box
        lower = cube(comm, [[0, 0, 0], [1, 1, 0.5]], [3, 3, 2])
        upper = cube(comm, [[0.2, 0.2, 0.5], [0.8, 0.8, 1.0]], [2, 2, 2])
    tagged = merge_meshes({"lower": lower, "upper": upper}, comm)
    gdim = tagged.mesh.geometry.dim
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (gdim,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    strain = ufl.sym(ufl.grad(u))
    stress = 2.0 * strain + ufl.tr(strain) * ufl.Identity(gdim)
    K = assemble_matrix(dolfinx.fem.form(ufl.inner(stress, ufl.sym(ufl.grad(v))) * ufl.dx))
    K.assemble()
    modes = rigid_body_modes(V)
    expected = 2 * (3 if gdim == 2 else 6)
    assert len(modes) == expected
    gram = np.array([[comm.allreduce(float(a @ b), op=MPI.SUM) for b in modes] for a in modes])
    assert np.abs(gram - np.eye(expected)).max() < 1e-12
    mode, product = K.createVecRight(), K.createVecLeft()
    scale = K.norm()
    for values in modes:
        mode.getArray()[:] = values
        K.mult(mode, product)
        assert product.norm() < 1e-12 * scale


def test_iterative_linear_solver_needs_dual_multipliers():
    with pytest.raises(ValueError, match="basis='dual'"):
        hertz(refinement=0, linear_solver="iterative", basis="standard")


@pytest.mark.parallel
@pytest.mark.timeout(600)
def test_condensation_without_kept_products_gives_the_same_newton_steps():
    """``condensed_keep_products: False`` (the low-memory set-up) frees every product
    after use and builds them again at each set-up: the preconditioner, and so every
    outer and Newton iteration and the solution, must be the kept-products one."""
    solutions, linear, kept = {}, {}, {}
    for keep in (True, False):
        setup = hertz(refinement=0, condensation=True,
                      petsc_options={"condensed_keep_products": keep})
        outcome = setup.steps(2)
        assert outcome.converged
        records = outcome.extra["records"]
        linear[keep] = [r.report.linear_iterations for r in records]
        solutions[keep] = solution(setup.problem, setup.tagged.cell_tags)
        condenser = setup.problem._condenser
        kept[keep] = (sorted(condenser._matrices) + sorted(condenser._products),
                      condenser.reuses)
        setup.destroy()
    assert linear[True] == linear[False]
    assert_same_solution(solutions[False], solutions[True], tolerance=1e-12)
    assert kept[True][1] > 0 and kept[False][1] == 0
    assert kept[False][0] == ["C", "G", "K_inner", "T", "E_q"]  # (A du is J's)


@pytest.mark.parametrize("chunk", [1, 5, 1 << 20])
def test_masked_copy_by_rows_equals_the_whole_masked_copy(monkeypatch, chunk):
    """K_c's values from A's kept entries, a block of rows at a time, are the whole
    masked copy ``target[target_mask] = source[source_mask]`` (rows whose masked entries
    match in number and order; empty rows and rows with nothing kept included)."""
    from dolfinx_mortar import inner_matrix

    monkeypatch.setattr(inner_matrix, "COPY_CHUNK", chunk)
    rng = np.random.default_rng(5)
    num_rows = 40
    source_lengths = rng.integers(0, 9, num_rows)
    kept_per_row = np.array([rng.integers(0, n + 1) for n in source_lengths])
    target_lengths = kept_per_row + rng.integers(0, 4, num_rows)
    def masks(lengths):
        return np.concatenate([rng.permutation(np.arange(n) < k)
                               for n, k in zip(lengths, kept_per_row, strict=True)])

    source_mask, target_mask = masks(source_lengths), masks(target_lengths)
    source_indptr = np.concatenate([[0], np.cumsum(source_lengths)]).astype(np.int32)
    target_indptr = np.concatenate([[0], np.cumsum(target_lengths)]).astype(np.int32)
    source = rng.standard_normal(source_indptr[-1])
    expected = np.full(target_indptr[-1], -1.0)
    expected[target_mask] = source[source_mask]
    target = np.full(target_indptr[-1], -1.0)
    inner_matrix.masked_copy_by_rows(target, target_indptr, target_mask, source,
                                     source_indptr, source_mask)
    np.testing.assert_array_equal(target, expected)


def test_row_reduce_counts_rows_with_empty_rows_anywhere():
    """Per-row sums and ORs over CSR rows equal a loop's, empty rows first, between and
    last included (an off-diagonal block's last rows are often empty)."""
    from dolfinx_mortar.inner_matrix import row_reduce

    rng = np.random.default_rng(11)
    for lengths in ([0, 3, 0, 0, 2, 0, 0], [4], [0, 0], [1, 0, 5]):
        indptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
        mask = rng.random(indptr[-1]) < 0.5
        rows = [mask[indptr[i]:indptr[i + 1]] for i in range(len(lengths))]
        np.testing.assert_array_equal(row_reduce(np.add, mask, indptr, np.int64),
                                      [row.sum() for row in rows])
        np.testing.assert_array_equal(row_reduce(np.logical_or, mask, indptr),
                                      [row.any() for row in rows])
