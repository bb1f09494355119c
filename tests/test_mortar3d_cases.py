"""3D mortar acceptance cases with hand-computed answers: two cubes sunk into each other,
and a slave surface whose boundary nodes are fixed (crosspoints)."""

from __future__ import annotations

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from test_mortar3d import GAP, interface, two_blocks

from dolfinx_mortar import merge_meshes
from dolfinx_mortar.layout import csr_to_coo, dirichlet_dofs

CELLS = ("tetrahedron", "hexahedron")
BASES = ("standard", "dual")
SHIFT = (0.3, 0.2)
DEPTH = 0.1
OVERLAP = (1.0 - SHIFT[0]) * (1.0 - SHIFT[1])  # 0.56


def penetrating_cubes(cell: str, n_lower: int, n_upper: int):
    """The unit cube and a unit cube shifted by SHIFT whose bottom is DEPTH below its top:
    the upper cube's bottom is the slave surface, the lower cube's top the master."""
    cell_type = getattr(dolfinx.mesh.CellType, cell)
    comm = MPI.COMM_SELF
    lower = dolfinx.mesh.create_box(comm, [[0, 0, 0], [1, 1, 1]], [n_lower, n_lower, 2], cell_type)
    bottom = 1.0 - DEPTH
    upper = dolfinx.mesh.create_box(
        comm, [[SHIFT[0], SHIFT[1], bottom], [1 + SHIFT[0], 1 + SHIFT[1], 1 + bottom]],
        [n_upper, n_upper, 2], cell_type)
    return merge_meshes({
        "lower": (lower, {"top": lambda x: np.isclose(x[2], 1.0)}),
        "upper": (upper, {"bottom": lambda x: np.isclose(x[2], bottom)}),
    }, comm)


def dense(matrix, shape) -> np.ndarray:
    rows, cols, values = csr_to_coo(matrix)
    result = np.zeros(shape)
    np.add.at(result, (rows, cols), values)
    return result


def row_sums(matrix) -> np.ndarray:
    vector = matrix.createVecLeft()
    matrix.getRowSum(vector)
    return vector.getArray().copy()


def nodal_areas(tagged) -> np.ndarray:
    """int_slave N_j per node (scalar P1 numbering = vector P1 block numbering)."""
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1))
    ds = ufl.Measure("ds", domain=tagged.mesh, subdomain_data=tagged.facet_tags)
    form = dolfinx.fem.form(ufl.TestFunction(V) * ds(tagged.markers["upper_bottom"]))
    return dolfinx.fem.petsc.assemble_vector(form).getArray().copy()


@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("basis", BASES)
def test_penetrating_cubes(cell, basis):
    """Flat slave sunk DEPTH through the master: sum D = sum M = 0.7 x 0.8, sum g~ =
    -DEPTH x 0.56, g~_j = -DEPTH x (D 1)_j at every node, and a node whose facets all lie
    over the master has (D 1)_j = int N_j, its whole nodal area."""
    tagged = penetrating_cubes(cell, 3, 4)
    mortar = interface(tagged, basis=basis)
    assert 2 * mortar.search_growth >= DEPTH  # the boxes grown by the default reach across
    D, M = mortar.mortar_matrices()
    assert abs(csr_to_coo(D)[2].sum() - OVERLAP) < 1e-13
    assert abs(csr_to_coo(M)[2].sum() - OVERLAP) < 1e-13
    gap = mortar.weighted_gap().getArray()
    assert abs(gap.sum() + DEPTH * OVERLAP) < 1e-13
    area = row_sums(D)
    assert np.abs(gap + DEPTH * area).max() < 1e-15

    slave = mortar.slave
    corners = slave.reference_coordinates[slave.facets]
    over_master = np.all(corners[:, :, :2] <= 1.0 + 1e-12, axis=(1, 2))
    covered = np.setdiff1d(np.arange(slave.num_nodes), slave.facets[~over_master])
    rows = mortar.node_multipliers[covered] - mortar.multiplier_offset
    assert covered.size >= 4
    assert np.abs(gap[rows] / area[rows] + DEPTH).max() < 1e-13
    whole = nodal_areas(tagged)[slave.node_global_blocks[covered]]
    assert np.abs(area[rows] - whole).max() < 1e-14
    assert np.all(whole > 0.0)


@pytest.mark.parametrize("cell", CELLS)
def test_penetration_deeper_than_the_boxes_growth(cell):
    """The same cubes with 12 slave cells across: the boxes' growth (half the default
    margin, a quarter of the mean slave edge) is below DEPTH / 2, so boxes grown by it
    alone do not overlap before any displacement (no sweep); the boxes' reach behind each
    facet pairs them."""
    tagged = penetrating_cubes(cell, 12, 12)
    mortar = interface(tagged)
    assert 2 * mortar.search_growth < DEPTH
    D, _ = mortar.mortar_matrices()
    total = csr_to_coo(D)[2].sum()
    assert abs(total - OVERLAP) < 1e-13


def fully_fixed_slave_blocks(tagged, V, sides) -> np.ndarray:
    """Blocks fixed in every component by a Dirichlet condition on the upper block's
    ``sides`` (as ContactProblem and MeshTying find them)."""
    mesh = tagged.mesh
    mesh.topology.create_connectivity(2, 3)
    outer = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    midpoints = dolfinx.mesh.compute_midpoints(mesh, 2, outer)
    on_side = np.zeros(outer.size, dtype=bool)
    for axis, value in sides:
        on_side |= np.isclose(midpoints[:, axis], value)
    on_side &= midpoints[:, 2] > 0.5 + GAP  # the upper block's sides only
    dofs = dolfinx.fem.locate_dofs_topological(V, 2, outer[on_side])
    bc = dolfinx.fem.dirichletbc(np.zeros(3), dofs, V)
    fixed = dirichlet_dofs([bc], V)
    bs = V.dofmap.index_map_bs
    blocks = np.unique(fixed // bs)
    return blocks[np.all([np.isin(blocks * bs + c, fixed) for c in range(bs)], axis=0)]


ALL_SIDES = ((0, 0.0), (0, 1.0), (1, 0.0), (1, 1.0))


@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("basis", BASES)
@pytest.mark.parametrize("sides", [ALL_SIDES, ((0, 0.0),)], ids=["all-sides", "one-side"])
def test_crosspoints(cell, basis, sides):
    """Slave nodes fixed on the upper block's sides carry no multiplier: their rows of D, M
    and g~ are empty, D on the other nodes is regular (dual: diagonal, positive), M x = D x
    for linear x, and sum D = sum M = 1, the interface area, less the facets whose nodes
    are all crosspoints (tetrahedral corners when all sides are fixed): they carry no
    multiplier and drop out."""
    tagged = two_blocks(cell, 3, 4, comm=MPI.COMM_SELF)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (3,)))
    crosspoints = fully_fixed_slave_blocks(tagged, V, sides)
    mortar = interface(tagged, basis=basis)
    mortar.set_crosspoints(crosspoints)
    mortar.update(None)

    slave_x = mortar.owned_multiplier_coordinates
    on_sides = np.zeros(slave_x.shape[0], dtype=bool)
    for axis, value in sides:
        on_sides |= np.isclose(slave_x[:, axis], value)
    cross_rows = mortar.owned_crosspoint_multipliers - mortar.multiplier_offset
    assert on_sides.any() and np.array_equal(np.flatnonzero(on_sides), np.sort(cross_rows))
    free_rows = np.flatnonzero(~on_sides)

    shape = (mortar.num_global_multipliers, mortar.num_global_blocks)
    D, M = mortar.mortar_matrices()
    D_dense, M_dense = dense(D, shape), dense(M, shape)
    gap = mortar.weighted_gap().getArray()
    assert np.all(D_dense[cross_rows] == 0.0)
    assert np.all(M_dense[cross_rows] == 0.0)
    assert np.all(gap[cross_rows] == 0.0)
    assert np.abs(gap - GAP * D_dense.sum(axis=1)).max() < 1e-15

    free = D_dense[np.ix_(free_rows, mortar.owned_multiplier_blocks[free_rows])]
    singular = np.linalg.svd(free, compute_uv=False)
    assert singular.min() / singular.max() > 1e-3
    if basis == "dual":
        assert np.abs(free - np.diag(np.diag(free))).max() < 1e-13
        assert np.all(np.diag(free) > 0.0)

    V_scalar = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1))
    for c in ((1.0, 0.0, 0.0), (0.3, 1.7, -0.4), (-2.0, 0.5, 4.0)):
        field = dolfinx.fem.Function(V_scalar)
        field.interpolate(lambda x, c=c: c[0] + c[1] * x[0] + c[2] * x[1])
        x = field.x.array
        assert np.abs(M_dense @ x - D_dense @ x)[free_rows].max() < 1e-12

    slave = mortar.slave
    lost = np.all(np.isin(slave.node_global_blocks[slave.facets], crosspoints), axis=1)
    total_D, total_M = D_dense.sum(), M_dense.sum()
    assert abs(total_D - total_M) < 1e-12
    # a facet whose nodes are all crosspoints carries no multiplier: it drops out
    corners = slave.reference_coordinates[slave.facets[lost]]  # cyclic: a fan from 0
    edges = corners[:, 1:] - corners[:, :1]
    lost_area = 0.5 * np.linalg.norm(np.cross(edges[:, :-1], edges[:, 1:]), axis=2).sum()
    assert abs(total_D - (1.0 - lost_area)) < 1e-12


@pytest.mark.parametrize("basis", BASES)
def test_reference_configuration_combines_only_the_gap_gradients(basis, monkeypatch):
    """Reference configuration: D, M, Dn, Mn and the areas are frozen (zero gradients), so
    their terms add nothing to a Jacobian and the kernel's gradients are never combined for
    them; the gap's gradient is B: -Dn on the slave nodes, +Mn on the master nodes."""
    from dolfinx_mortar import stencils

    mortar = interface(penetrating_cubes("tetrahedron", 3, 4), basis=basis,
                       configuration="reference")
    rows = mortar.contributing_pairs()
    q, stencil = mortar.quantities, mortar.stencil
    assert q.Dn.constant and q.Mn.constant and q.area.constant and not q.gap.constant
    combined = []
    original = stencils._add_combined
    monkeypatch.setattr(stencils, "_add_combined",
                        lambda result, grad, entries: combined.append(grad.shape[1])
                        or original(result, grad, entries))
    z = np.linspace(1.0, 2.0, rows.size)
    force = mortar.combined_gradients(rows, mortar.force_jacobian_terms(
        np.repeat(z[:, None], stencil.ns, axis=1)))
    assert combined == [] and not force.any()
    gap = mortar.combined_gradients(rows, [[(stencil.GAP + j, 1.0)] for j in range(stencil.ns)])
    assert len(combined) == 1
    Dn, Mn = q.Dn.value_of(rows), q.Mn.value_of(rows)  # (rows, j, k, c)
    slave = gap[:, :3 * stencil.ns].reshape(stencil.ns, stencil.ns, 3, rows.size)
    master = gap[:, 3 * stencil.ns:3 * (stencil.ns + stencil.nm)].reshape(
        stencil.ns, stencil.nm, 3, rows.size)
    assert np.array_equal(slave, -Dn.transpose(1, 2, 3, 0))
    assert np.array_equal(master, Mn.transpose(1, 2, 3, 0))


@pytest.mark.parametrize("basis", BASES)
def test_force_dofs_of_rows_are_those_of_the_pattern(basis):
    """The residual's force dofs of some pairs (made from their facet nodes) are the rows
    of the pattern's :attr:`pair_force_dofs` (made from the whole stencil's dofs)."""
    mortar = interface(penetrating_cubes("tetrahedron", 3, 4), basis=basis)
    rows = mortar.contributing_pairs()[::2]
    assert rows.size > 4
    expected = mortar.pair_force_dofs[rows]
    assert (expected >= 0).all()
    np.testing.assert_array_equal(mortar.pair_force_dofs_of(rows), expected)


@pytest.mark.parametrize("cell", CELLS)
def test_flat_surfaces_are_paired_within_one_margin(cell):
    """Two parallel flat surfaces ``gap`` apart (no sweep: the first search): each 3D box
    grows by half the margin, so they are paired (and every slave node covered, its
    nodal gap the distance) when the gap is below the margin and not at all above it."""
    from test_mortar3d import two_blocks

    margin = 0.05
    for gap, paired in ((0.9 * margin, True), (1.1 * margin, False)):
        mortar = interface(two_blocks(cell, 3, 4, comm=MPI.COMM_SELF, gap=gap),
                           search_margin=margin)
        assert mortar.search_growth == 0.5 * margin
        assert (mortar.statistics.pairs > 0) == paired
        if paired:
            D, _ = mortar.mortar_matrices()
            area = row_sums(D)
            gap_j = mortar.weighted_gap().getArray() / area
            assert abs(area.sum() - 1.0) < 1e-13
            assert np.abs(gap_j - gap).max() < 1e-13
