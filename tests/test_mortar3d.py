"""MortarInterface in 3D: flat-interface identities, gaps, derivatives, serial = parallel."""

from __future__ import annotations

import dolfinx
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_mortar import MortarInterface, merge_meshes
from dolfinx_mortar.layout import csr_to_coo

CELLS = ("tetrahedron", "hexahedron")
GAP = 1e-3


def two_blocks(cell: str, n_lower: int, n_upper: int, comm=MPI.COMM_WORLD, gap: float = GAP,
               rotate_lower: float = 0.0):
    """A block [0, 1]^2 x [0, 0.5] and, ``gap`` above it, a block [0, 1]^2 x [0.5 + gap, 1];
    the upper block's bottom is the slave surface, the lower block's top the master.

    With ``rotate_lower`` (radians) the lower block is [-0.5, 1.5]^2 x [0, 0.5] turned by that
    angle about the vertical axis through (0.5, 0.5): its top still covers the whole slave."""
    cell_type = getattr(dolfinx.mesh.CellType, cell)
    a, b = (-0.5, 1.5) if rotate_lower else (0.0, 1.0)
    lower = dolfinx.mesh.create_box(comm, [[a, a, 0], [b, b, 0.5]], [n_lower, n_lower, 2],
                                    cell_type)
    if rotate_lower:
        x = lower.geometry.x
        cos, sin = np.cos(rotate_lower), np.sin(rotate_lower)
        dx, dy = x[:, 0] - 0.5, x[:, 1] - 0.5
        x[:, 0], x[:, 1] = 0.5 + cos * dx - sin * dy, 0.5 + sin * dx + cos * dy
    upper = dolfinx.mesh.create_box(comm, [[0, 0, 0.5 + gap], [1, 1, 1]], [n_upper, n_upper, 2],
                                    cell_type)
    tagged = merge_meshes({
        "lower": (lower, {"top": lambda x: np.isclose(x[2], 0.5)}),
        "upper": (upper, {"bottom": lambda x: np.isclose(x[2], 0.5 + gap)}),
    }, comm)
    return tagged


def interface(tagged, u=None, **options) -> MortarInterface:
    V = u.function_space if u is not None else dolfinx.fem.functionspace(
        tagged.mesh, ("Lagrange", 1, (3,)))
    mortar = MortarInterface(V, tagged.facet_tags, tagged.markers["upper_bottom"],
                             tagged.markers["lower_top"], **options)
    mortar.update(u)
    return mortar


def bent_displacement(tagged, amplitude=0.02):
    """A smooth displacement, different in each body, that bends the interface."""
    V = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1, (3,)))
    u = dolfinx.fem.Function(V)
    upper = tagged.cell_tags.find(tagged.markers["upper"])
    lower = tagged.cell_tags.find(tagged.markers["lower"])
    u.interpolate(lambda x: np.vstack([
        amplitude * np.sin(7 * x[0] + 1), amplitude * np.cos(5 * x[1]),
        amplitude * np.sin(3 * x[0] + 2 * x[1])]), upper)
    u.interpolate(lambda x: np.vstack([
        -amplitude * np.sin(3 * x[1]), 0.5 * amplitude * np.cos(4 * x[0]),
        -0.5 * amplitude * np.cos(4 * x[0] + 2 * x[1]) - 0.01]), lower)
    u.x.scatter_forward()
    return u


def node_keys(V) -> dict[int, tuple]:
    """Global dof block -> its rounded coordinates (no two nodes coincide here), all ranks."""
    index_map = V.dofmap.index_map
    num = index_map.size_local + index_map.num_ghosts
    blocks = index_map.local_to_global(np.arange(num, dtype=np.int32))
    x = V.tabulate_dof_coordinates()[:num]
    local = {int(b): tuple(np.round(p, 9)) for b, p in zip(blocks, x, strict=True)}
    return {k: v for part in V.mesh.comm.allgather(local) for k, v in part.items()}


def keyed_entries(matrix, row_key, col_key) -> dict:
    rows, cols, values = csr_to_coo(matrix)
    local = [(row_key(r), col_key(c), v) for r, c, v in zip(rows, cols, values, strict=True)]
    result: dict = {}
    for part in matrix.comm.tompi4py().allgather(local):
        for r, c, v in part:
            result[(r, c)] = result.get((r, c), 0.0) + v
    return result


def multiplier_keys(mortar, keys) -> dict:
    owned = {int(mortar.multiplier_offset + i): keys[int(b)]
             for i, b in enumerate(mortar.owned_multiplier_blocks)}
    return {k: v for part in mortar.comm.allgather(owned) for k, v in part.items()}


def assert_flat_identities(tagged, basis):
    """M x = D x for linear fields (in z up to the gap), sum of D = sum of M = interface area 1,
    row sums of D and M agree, weighted gap = gap x nodal area; dual D diagonal."""
    mortar = interface(tagged, basis=basis)
    D, M = mortar.mortar_matrices()
    comm = tagged.mesh.comm
    V_scalar = dolfinx.fem.functionspace(tagged.mesh, ("Lagrange", 1))
    row_D, row_M = D.createVecLeft(), D.createVecLeft()
    D.getRowSum(row_D)
    M.getRowSum(row_M)
    assert row_D.min()[1] > 0.0  # every slave node lies on the interface
    for c in ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0),
              (0.0, 0.0, 0.0, 1.0), (0.3, 1.7, -0.4, 0.0), (-2.0, 0.5, 4.0, 1.5)):
        field = dolfinx.fem.Function(V_scalar)
        field.interpolate(lambda x, c=c: c[0] + c[1] * x[0] + c[2] * x[1] + c[3] * x[2])
        slave_side, master_side = D.createVecLeft(), D.createVecLeft()
        D.mult(field.x.petsc_vec, slave_side)
        M.mult(field.x.petsc_vec, master_side)
        master_side.axpy(-1.0, slave_side)
        master_side.axpy(c[3] * GAP, row_D)  # the master surface lies GAP below the slave
        scale = slave_side.norm(PETSc.NormType.INFINITY)
        assert master_side.norm(PETSc.NormType.INFINITY) < 1e-12 * scale, c
    total_D = comm.allreduce(csr_to_coo(D)[2].sum(), op=MPI.SUM)
    total_M = comm.allreduce(csr_to_coo(M)[2].sum(), op=MPI.SUM)
    assert total_D == pytest.approx(1.0, abs=1e-12)
    assert total_M == pytest.approx(1.0, abs=1e-12)
    gap = mortar.weighted_gap()
    expected = row_D.copy()
    expected.scale(GAP)
    expected.axpy(-1.0, gap)
    assert expected.norm(PETSc.NormType.INFINITY) < 1e-14
    row_M.axpy(-1.0, row_D)
    assert row_M.norm(PETSc.NormType.INFINITY) < 1e-13
    if basis == "dual":
        rows, cols, values = csr_to_coo(D)
        blocks = mortar.owned_multiplier_blocks
        diagonal = blocks[rows - mortar.multiplier_offset] == cols
        assert np.all(np.abs(values[~diagonal]) < 1e-13)


@pytest.mark.parallel
@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("ratio", [(2, 3), (1, 5), (3, 2), (5, 1)])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_flat_interface_identities(cell, ratio, basis):
    """Non-matching grids up to 1:5 and 5:1 keep the flat-interface identities."""
    assert_flat_identities(two_blocks(cell, 2 * ratio[0], 2 * ratio[1]), basis)


@pytest.mark.parallel
@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_flat_interface_identities_rotated_master(cell, basis):
    """A master grid turned 30 degrees against the slave grid (no edge of one parallel to an
    edge of the other) keeps the flat-interface identities."""
    angle = np.pi / 6
    tagged = two_blocks(cell, 5, 4, rotate_lower=angle)
    corner = 0.5 + np.array([np.cos(angle) - np.sin(angle), np.sin(angle) + np.cos(angle)])
    turned = np.any(np.all(np.isclose(tagged.mesh.geometry.x[:, :2], corner), axis=1))
    assert tagged.mesh.comm.allreduce(turned, op=MPI.LOR)  # the merged mesh kept the rotation
    assert_flat_identities(tagged, basis)


@pytest.mark.parallel
@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize("normals", ["averaged", "slave", "master"])
@pytest.mark.parametrize("integration", ["segment"])
def test_serial_equals_parallel(cell, normals, integration):
    """D, M, gaps, the gap Jacobian and the force Jacobian on N ranks equal one rank's."""
    results = []
    for comm in (MPI.COMM_SELF, MPI.COMM_WORLD):
        tagged = two_blocks(cell, 3, 4, comm=comm)
        u = bent_displacement(tagged)
        mortar = interface(tagged, u, normals=normals, integration=integration)
        keys = node_keys(u.function_space)
        z_keys = multiplier_keys(mortar, keys)
        z = mortar.create_multiplier_vector()
        owned = mortar.owned_multiplier_coordinates
        z.getArray()[:] = 1.0 + owned[:, 0] + 2.0 * owned[:, 1] ** 2
        z.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        D, M = mortar.mortar_matrices()
        G = mortar.gap_jacobian()
        K = mortar.force_jacobian(z)
        gap = mortar.weighted_gap()
        gaps = {z_keys[int(mortar.multiplier_offset + i)]: v for i, v in enumerate(gap.getArray())}
        dof_key = lambda c, k=keys: (k[int(c) // 3], int(c) % 3)  # noqa: E731
        results.append({
            "D": keyed_entries(D, z_keys.get, keys.get),
            "M": keyed_entries(M, z_keys.get, keys.get),
            "G": keyed_entries(G, z_keys.get, dof_key),
            "K": keyed_entries(K, dof_key, dof_key),
            "gap": {k: v for part in comm.allgather(gaps) for k, v in part.items()},
        })
    serial, parallel = results
    for name in ("D", "M", "G", "K", "gap"):
        nonzero = {k for k, v in serial[name].items() if abs(v) > 1e-15}
        assert nonzero <= parallel[name].keys(), name
        scale = max(abs(v) for v in serial[name].values())
        difference = max(abs(serial[name][k] - parallel[name].get(k, 0.0)) for k in serial[name])
        assert difference <= 1e-12 * max(scale, 1.0), (name, difference)
    assert max(abs(v) for v in serial["gap"].values()) > 1e-5


@pytest.mark.parametrize("cell", CELLS)
@pytest.mark.parametrize(("normals", "integration"), [
    ("averaged", "segment"), ("slave", "segment"), ("master", "segment"),
    ("averaged", "element")])
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_contact_residual_taylor(cell, normals, integration, basis):
    """r(u) = [-B(u)^T z, g~(u)] at fixed z: |r(u + h du) - r(u) - h J du| falls as h^2
    (element-based: no Gauss point changes master facet within the steps)."""
    tagged = two_blocks(cell, 3, 4, comm=MPI.COMM_SELF)
    u = bent_displacement(tagged)
    mortar = interface(tagged, u, normals=normals, basis=basis, integration=integration)
    z = mortar.create_multiplier_vector()
    rng = np.random.default_rng(5)
    z.getArray()[:] = rng.uniform(0.5, 1.5, z.getLocalSize())
    z.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    V = u.function_space
    du = dolfinx.fem.Function(V)
    du.x.array[:] = rng.uniform(-1.0, 1.0, du.x.array.size) * 1e-3

    def residual(w):
        mortar.update(w)
        force = dolfinx.fem.Function(V)
        mortar.contact_force(z, force.x.petsc_vec)
        return np.concatenate([force.x.petsc_vec.getArray().copy(),
                               mortar.weighted_gap().getArray().copy()])

    r0 = residual(u)
    mortar.update(u)
    K = mortar.force_jacobian(z)
    G = mortar.gap_jacobian()
    direction = du.x.petsc_vec
    Kdu, Gdu = K.createVecLeft(), G.createVecLeft()
    K.mult(direction, Kdu)
    G.mult(direction, Gdu)
    Jdu = np.concatenate([Kdu.getArray(), Gdu.getArray()])
    assert np.linalg.norm(Jdu) > 1e-6
    steps = np.array([0.25, 0.125, 0.0625, 0.03125])
    remainders = []
    for h in steps:
        w = dolfinx.fem.Function(V)
        w.x.array[:] = u.x.array + h * du.x.array
        remainders.append(np.linalg.norm(residual(w) - r0 - h * Jdu))
    slopes = np.diff(np.log(remainders)) / np.diff(np.log(steps))
    assert np.all(np.abs(slopes - 2.0) < 0.1), (slopes, remainders)


@pytest.mark.parallel
@pytest.mark.parametrize("basis", ["standard", "dual"])
def test_a_new_search_takes_over_the_slave_surface_stars(basis):
    """The averaged normals' stars are topology of the slave surface: a new search keeps them
    (the same object), and the weighted gaps and the gap Jacobian are those of an interface
    that searched once; stars of other facets are not taken for these."""
    from dolfinx_mortar.stencils import SlaveSurfaceStars

    tagged = two_blocks("hexahedron", 3, 4)
    u = bent_displacement(tagged)
    searched_again = interface(tagged, u, basis=basis)

    def surface(mortar):
        return mortar.stencil.slave_surface

    kept = surface(searched_again)
    assert kept is not None
    u.x.array[:] *= 1.5
    searched_again.reuse.invalidate()
    searched_again.update(u)
    assert surface(searched_again) is kept
    fresh = interface(tagged, u, basis=basis)
    assert surface(fresh) is not kept
    np.testing.assert_array_equal(surface(fresh).stars.star, kept.stars.star)
    np.testing.assert_allclose(searched_again.weighted_gap().array, fresh.weighted_gap().array,
                               rtol=0, atol=1e-15)
    G_again, G_fresh = searched_again.gap_jacobian(), fresh.gap_jacobian()
    difference = G_again.copy()
    difference.axpy(-1.0, G_fresh)
    assert difference.norm() <= 1e-14 * G_fresh.norm()
    difference.destroy()
    node_blocks = np.arange(8)
    square = np.array([[0, 1, 2, 3]])
    stars = SlaveSurfaceStars(node_blocks, square)
    assert stars.describes(node_blocks, square.copy())
    assert not stars.describes(node_blocks, np.array([[0, 1, 2, 4]]))
    assert not stars.describes(node_blocks[::-1].copy(), square)
    for mortar in (searched_again, fresh):
        mortar.destroy()
