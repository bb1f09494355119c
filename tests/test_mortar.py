"""MortarInterface on dolfinx meshes: identities, gaps, derivatives, serial = parallel."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_mortar import MortarInterface, compat, meshes, search
from dolfinx_mortar.layout import csr_to_coo
from dolfinx_mortar.surface import SurfaceError


def node_identity(V) -> dict[int, int]:
    """Global dof block -> gmsh input node index, for every block on any rank."""
    mesh = V.mesh
    input_index = mesh.geometry.input_global_indices
    geometry = compat.geometry_dofmap(mesh)
    blocks = V.dofmap.list
    local_blocks = blocks.reshape(-1)
    local_input = np.asarray(input_index)[geometry.reshape(-1)]
    global_blocks = V.dofmap.index_map.local_to_global(local_blocks.astype(np.int32))
    pairs = np.unique(np.column_stack([global_blocks, local_input]), axis=0)
    everything = np.unique(np.vstack(mesh.comm.allgather(pairs)), axis=0)
    return dict(zip(everything[:, 0].tolist(), everything[:, 1].tolist(), strict=True))


def keyed_entries(matrix, row_key, col_key) -> dict:
    rows, cols, values = csr_to_coo(matrix)
    local = [(row_key(r), col_key(c), v) for r, c, v in zip(rows, cols, values, strict=True)]
    gathered = [entry for part in matrix.comm.tompi4py().allgather(local) for entry in part]
    result: dict = {}
    for r, c, v in gathered:
        result[(r, c)] = result.get((r, c), 0.0) + v
    return result


def interface(tagged, u=None, **options) -> MortarInterface:
    V = (
        u.function_space
        if u is not None
        else dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    )
    mortar = MortarInterface(
        V,
        tagged.facet_tags,
        tagged.markers["contact_slave"],
        tagged.markers["contact_master"],
        **options,
    )
    mortar.update(u)
    return mortar


def perturbed_displacement(tagged, amplitude=0.02, seed=3):
    """A smooth displacement, different in each body, that bends the interface."""
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    upper = tagged.cell_tags.find(tagged.markers["upper"])
    lower = tagged.cell_tags.find(tagged.markers["lower"])
    u.interpolate(
        lambda x: np.vstack([amplitude * np.sin(7 * x[0] + 1), amplitude * np.cos(5 * x[0])]), upper
    )
    u.interpolate(
        lambda x: np.vstack(
            [-amplitude * np.sin(3 * x[0]), -0.5 * amplitude * np.cos(4 * x[0] + 2) - 0.01]
        ),
        lower,
    )
    u.x.scatter_forward()
    return u


@pytest.mark.parallel
@pytest.mark.parametrize("ratio", [(1, 1), (3, 4), (3, 7), (1, 7), (7, 2)])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_flat_interface_identities(ratio, basis):
    tagged = meshes.tied_blocks(ratio=ratio, refinement=0)
    mortar = interface(tagged, basis=basis)
    D, M = mortar.mortar_matrices()
    comm = tagged.mesh.comm
    V_scalar = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1))
    for coefficients in ((1.0, 0.0, 0.0), (0.3, 1.7, 0.0), (-2.0, 0.5, 4.0)):
        field = dolfinx.fem.Function(V_scalar)
        field.interpolate(lambda x, c=coefficients: c[0] + c[1] * x[0] + c[2] * x[1])
        slave_side, master_side = D.createVecLeft(), D.createVecLeft()
        D.mult(field.x.petsc_vec, slave_side)
        M.mult(field.x.petsc_vec, master_side)
        master_side.axpy(-1.0, slave_side)
        assert master_side.norm(0) < 1e-13 * max(1.0, slave_side.norm(0))
    total_D = comm.allreduce(csr_to_coo(D)[2].sum(), op=MPI.SUM)
    total_M = comm.allreduce(csr_to_coo(M)[2].sum(), op=MPI.SUM)
    assert total_D == pytest.approx(1.0, abs=1e-13)
    assert total_M == pytest.approx(1.0, abs=1e-13)
    gap = mortar.weighted_gap()
    assert gap.norm(0) < 1e-14


@pytest.mark.parallel
def test_row_sums_and_dual_biorthogonality():
    tagged = meshes.tied_blocks(ratio=(3, 7), refinement=0)
    standard = interface(tagged, basis="standard")
    dual = interface(tagged, basis="dual")
    for mortar in (standard, dual):
        D, M = mortar.mortar_matrices()
        row_D, row_M = D.createVecLeft(), D.createVecLeft()
        D.getRowSum(row_D)
        M.getRowSum(row_M)
        row_M.axpy(-1.0, row_D)
        assert row_M.norm(0) < 1e-14
    D, _ = dual.mortar_matrices()
    rows, cols, values = csr_to_coo(D)
    blocks = dual.owned_multiplier_blocks
    diagonal = blocks[rows - dual.multiplier_offset] == cols
    assert np.all(np.abs(values[~diagonal]) < 1e-14)


@pytest.mark.parallel
@pytest.mark.parametrize("integration", ["segment", "element"])
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
def test_serial_equals_parallel(integration, normals):
    """D, M, gaps and gap Jacobian on N ranks equal those of one rank to 1e-12."""
    results = []
    for comm in (MPI.COMM_SELF, MPI.COMM_WORLD):
        tagged = meshes.tied_blocks(ratio=(3, 7), refinement=1, comm=comm)
        u = perturbed_displacement(tagged)
        mortar = interface(tagged, u, integration=integration, normals=normals)
        identity = node_identity(u.function_space)
        multiplier_key = {
            int(m): identity[int(b)]
            for m, b in zip(
                mortar.multiplier_offset + np.arange(mortar.num_owned_multipliers),
                mortar.owned_multiplier_blocks,
                strict=True,
            )
        }
        multiplier_key = {k: v for part in comm.allgather(multiplier_key) for k, v in part.items()}
        D, M = mortar.mortar_matrices()
        G = mortar.gap_jacobian()
        gap = mortar.weighted_gap()
        owned_gap = {
            multiplier_key[int(mortar.multiplier_offset + i)]: v
            for i, v in enumerate(gap.getArray())
        }
        owned_gap = {k: v for part in comm.allgather(owned_gap) for k, v in part.items()}
        results.append(
            {
                "D": keyed_entries(D, multiplier_key.get, identity.get),
                "M": keyed_entries(M, multiplier_key.get, identity.get),
                "G": keyed_entries(
                    G, multiplier_key.get, lambda c, ids=identity: (ids[int(c) // 2], int(c) % 2)
                ),
                "gap": owned_gap,
            }
        )
    serial, parallel = results
    for name in ("D", "M", "G", "gap"):
        assert serial[name].keys() == parallel[name].keys(), name
        difference = max(abs(serial[name][k] - parallel[name][k]) for k in serial[name])
        assert difference < 1e-12, (name, difference)
    assert max(abs(v) for v in serial["gap"].values()) > 1e-4


def test_penetrating_blocks_weighted_gap():
    """Lower block moved up by 0.01 rigidly: g~_j = -0.01 * int Phi_j."""
    tagged = meshes.tied_blocks(ratio=(2, 5), refinement=0)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    u.interpolate(
        lambda x: np.vstack([0.0 * x[0], 0.01 + 0.0 * x[0]]),
        tagged.cell_tags.find(tagged.markers["lower"]),
    )
    u.x.scatter_forward()
    for basis in ("standard", "dual"):
        mortar = interface(tagged, u, basis=basis)
        D, _ = mortar.mortar_matrices()
        row_sum = D.createVecLeft()
        D.getRowSum(row_sum)
        gap = mortar.weighted_gap()
        assert np.allclose(gap.getArray(), -0.01 * row_sum.getArray(), atol=1e-15, rtol=1e-12)


@pytest.mark.parallel
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("offset", [0.0, 1024.0, 1e4 / 3])
def test_weighted_gap_of_a_small_penetration_far_from_the_origin(dim, offset):
    """Lower body moved up by 1e-7 on a flat interface, the whole mesh translated by
    ``offset``: g~_j = -1e-7 * int Phi_j to 1e-12. Formed from x = X + u, each gap would carry
    the rounding of X, eps |X| / 1e-7 = 1e-9 of it at |X| = 0.5 and 2e-6 at |X| = 1024: the
    interface's coordinates are taken from a point on it."""
    if dim == 2:
        tagged = meshes.tied_blocks(ratio=(2, 5), refinement=0)
        slave, master = tagged.markers["contact_slave"], tagged.markers["contact_master"]
    else:
        from test_mortar3d import two_blocks

        tagged = two_blocks("tetrahedron", 3, 4, gap=0.0)
        slave, master = tagged.markers["upper_bottom"], tagged.markers["lower_top"]
    tagged.mesh.geometry.x[:, :dim] += offset
    depth = 1e-7
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (dim,)))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.vstack([0.0 * x[0]] * (dim - 1) + [depth + 0.0 * x[0]]),
                  tagged.cell_tags.find(tagged.markers["lower"]))
    u.x.scatter_forward()
    mortar = MortarInterface(V, tagged.facet_tags, slave, master)
    mortar.update(u)
    D, _ = mortar.mortar_matrices()
    row_sum = D.createVecLeft()
    D.getRowSum(row_sum)
    gap = mortar.weighted_gap()
    assert mortar.comm.allreduce(row_sum.getArray().size) == mortar.num_global_multipliers
    assert mortar.comm.allreduce(np.abs(row_sum.getArray()).sum()) > 0.5
    assert np.allclose(gap.getArray(), -depth * row_sum.getArray(), atol=0.0, rtol=1e-12)
    mortar.destroy()


@pytest.mark.parallel
@pytest.mark.parametrize("first_at_rest", [True, False])
def test_pushed_through_by_more_than_the_margin(first_at_rest):
    """Lower block moved up rigidly by five search margins in one update (from rest, or
    in the very first update): the swept search still pairs the facets, and
    g~_j = -depth * int Phi_j as for a shallow penetration, on any number of ranks."""
    tagged = meshes.tied_blocks(ratio=(2, 5), refinement=0)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    margin = 0.01
    depth = 5 * margin
    mortar = MortarInterface(V, tagged.facet_tags, tagged.markers["contact_slave"],
                             tagged.markers["contact_master"], search_margin=margin)
    if first_at_rest:
        mortar.update(dolfinx.fem.Function(V))
        assert mortar.comm.allreduce(mortar.statistics.pairs) > 0
    u = dolfinx.fem.Function(V)
    u.interpolate(
        lambda x: np.vstack([0.0 * x[0], depth + 0.0 * x[0]]),
        tagged.cell_tags.find(tagged.markers["lower"]),
    )
    u.x.scatter_forward()
    mortar.update(u)
    assert mortar.reuse.searches_done == (2 if first_at_rest else 1)
    D, _ = mortar.mortar_matrices()
    row_sum = D.createVecLeft()
    D.getRowSum(row_sum)
    gap = mortar.weighted_gap()
    assert mortar.comm.allreduce(row_sum.getArray().size) == mortar.num_global_multipliers
    assert row_sum.sum() == pytest.approx(1.0, rel=1e-12)  # the whole interface is covered
    assert np.allclose(gap.getArray(), -depth * row_sum.getArray(), atol=1e-15, rtol=1e-12)
    # the boxes at the new positions alone are too far apart: no pair at all
    slave_x = mortar.slave.current_coordinates(u)
    master_x = mortar.master.current_coordinates(u)
    unswept = search.candidate_pairs(slave_x, mortar.slave.facets, master_x, mortar.master.facets,
                                     margin)
    assert unswept.shape == (0, 2)


def test_bad_input():
    tagged = meshes.tied_blocks(ratio=(2, 3), refinement=0)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    slave, master = tagged.markers["contact_slave"], tagged.markers["contact_master"]
    with pytest.raises(SurfaceError, match="marks no facet"):
        MortarInterface(V, tagged.facet_tags, 999, master)
    itself = MortarInterface(V, tagged.facet_tags, slave, slave)  # self-contact (issue 29)
    assert itself.self_contact and itself.master is itself.slave
    itself.destroy()
    with pytest.raises(ValueError, match="unknown normals"):
        MortarInterface(V, tagged.facet_tags, slave, master, normals="sideways")
    with pytest.raises(ValueError, match="unknown integration"):
        MortarInterface(V, tagged.facet_tags, slave, master, integration="nodal")
    scalar = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1))
    with pytest.raises(SurfaceError, match="vector space"):
        MortarInterface(scalar, tagged.facet_tags, slave, master)
    quadratic = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 2, (2,)))
    with pytest.raises(SurfaceError, match="linear Lagrange"):
        MortarInterface(quadratic, tagged.facet_tags, slave, master)
    mesh3d = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2)
    V3 = dolfinx.fem.functionspace(mesh3d, ("Lagrange", 1, (3,)))
    tags3 = dolfinx.mesh.meshtags(
        mesh3d, 2, np.zeros(0, dtype=np.int32), np.zeros(0, dtype=np.int32)
    )
    with pytest.raises(SurfaceError, match="marks no facet"):
        MortarInterface(V3, tags3, 1, 2)
    prisms = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 1, 1, 1, dolfinx.mesh.CellType.prism)
    V_prism = dolfinx.fem.functionspace(prisms, ("Lagrange", 1, (3,)))
    with pytest.raises(SurfaceError, match="prisms"):
        MortarInterface(V_prism, tags3, 1, 2)


def test_force_dofs_of_rows_are_those_of_the_pattern():
    """2D: the residual's force dofs of some pairs are the rows of :attr:`pair_force_dofs`."""
    tagged = meshes.tied_blocks(ratio=(2, 5), refinement=1)
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (2,)))
    mortar = MortarInterface(V, tagged.facet_tags, tagged.markers["contact_slave"],
                             tagged.markers["contact_master"])
    mortar.update(dolfinx.fem.Function(V))
    rows = mortar.contributing_pairs()[1::2]
    assert rows.size > 2
    np.testing.assert_array_equal(mortar.pair_force_dofs_of(rows), mortar.pair_force_dofs[rows])
