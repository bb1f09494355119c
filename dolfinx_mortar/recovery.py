"""The contact pressure and friction traction a user reads: the nodal multipliers recovered
on their patches.

The dual multiplier z_j of a slave node is its contact force divided by its area
(D_jj = int N_j). On unstructured meshes (gmsh tetrahedra above all) these nodal forces
scatter about the smooth pressure, node to node, the way nodal reactions and stresses of
linear elements do, and the scatter does not fall with the mesh size as fast as the
error of the pressure field: the largest nodal value of ever more nodes stays above the
peak pressure (docs/benchmarks.md, "Contact pressure: nodal multipliers and their
recovery"). As with stresses, the value to show is a recovered one (Zienkiewicz and
Zhu's patch recovery): at each active slave node, the linear function of the surface
coordinates that fits the multiplier field

    lambda_h = sum_k z_k N_k

best in L2 over the node's patch (its slave facets whose nodes are all active),

    min over p in P1:  int_patch (p - lambda_h)^2 dA,

evaluated at the node, and never below 0 (a contact pressure; a one-sided patch at a
symmetry plane extrapolates). A pressure that is linear on the patch is reproduced
exactly (so patch tests stay exact), the fit only averages what scatters. Nodes with no such facet
(a lone active node, the contact edge's outermost nodes) and inactive nodes keep z_j.
The forces (``contact_forces``) always come from the multipliers themselves.

The tangential multipliers of friction scatter the same way; their field is recovered
alike (``ContactProblem.tangential_traction``): in 2D as a scalar, in 3D as the vectors
y_j . tau_j component by component (the nodes' tangent frames differ), the fitted vector
made tangential again and expressed in the node's frame. Coulomb's law holds for the
multipliers node by node, not for the fit.

Parallel: each rank integrates its own slave facets; the small normal equations of
every node are summed on the node's owner (a ghosted vector, reverse scatter), so the
result does not depend on the partition beyond rounding.
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .mortar import MortarInterface

_QUADRILATERAL_GAUSS = (0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0))


def _facet_mass_matrices(x: np.ndarray) -> np.ndarray:
    """(facets, k, k) mass matrices int N_a N_b dA of facets with nodes x (facets, k, gdim):
    segments, triangles and bilinear quadrilaterals (cyclic node order)."""
    k = x.shape[1]
    if k == 2:
        length = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
        return length[:, None, None] / 6.0 * (np.ones((2, 2)) + np.eye(2))
    if k == 3:
        area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
        return area[:, None, None] / 12.0 * (np.ones((3, 3)) + np.eye(3))
    mass = np.zeros((x.shape[0], 4, 4))
    for s in _QUADRILATERAL_GAUSS:
        for t in _QUADRILATERAL_GAUSS:
            shape = np.array([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t])
            d_s = np.array([-(1 - t), 1 - t, t, -t])
            d_t = np.array([-(1 - s), -s, s, 1 - s])
            jacobian = np.linalg.norm(
                np.cross(np.einsum("a,fad->fd", d_s, x), np.einsum("a,fad->fd", d_t, x)), axis=1
            )
            mass += 0.25 * jacobian[:, None, None] * np.outer(shape, shape)
    return mass


def _area_normals(x: np.ndarray) -> np.ndarray:
    """(facets, gdim) outward normals of the facets, of length the facet's size (for a
    non-planar quadrilateral, of its diagonals' parallelogram)."""
    if x.shape[1] == 2:
        t = x[:, 1] - x[:, 0]
        return np.column_stack([t[:, 1], -t[:, 0]])
    if x.shape[1] == 3:
        return 0.5 * np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    return 0.5 * np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 1])


def _tangent_bases(normals: np.ndarray) -> np.ndarray:
    """(n, gdim - 1, gdim) orthonormal tangent vectors of the (nonzero) normals."""
    n = normals / np.linalg.norm(normals, axis=1)[:, None]
    if n.shape[1] == 2:
        return np.stack([n[:, 1], -n[:, 0]], axis=1)[:, None, :]
    helper = np.where(np.abs(n[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(n, t1)], axis=1)


def recovered_pressure(interface: MortarInterface, multipliers: PETSc.Vec,
                       active: np.ndarray) -> np.ndarray:
    """The recovered pressure at ``interface``'s owned slave nodes (rows of its multiplier
    vector), from the ghosted multiplier vector ``multipliers`` and the owned nodes'
    active flags; never below 0. Collective."""
    return recovered_scalar(interface, multipliers, active, lower=0.0)


def recovered_scalar(interface: MortarInterface, multipliers: PETSc.Vec, active: np.ndarray,
                     lower: float | None = None) -> np.ndarray:
    """A scalar nodal field recovered as the pressure is (a 2D tangential traction too):
    the fit at the owned active nodes (at least ``lower`` if given), the field's own value
    elsewhere. Collective."""
    result = multipliers.getArray(readonly=True).copy()
    fitted, value = _patch_fits(interface, interface.node_values(multipliers)[:, None], active)
    result[fitted] = value[:, 0] if lower is None else np.maximum(value[:, 0], lower)
    return result


def recovered_traction(interface: MortarInterface, traction: np.ndarray,
                       active: np.ndarray) -> np.ndarray:
    """The recovered tangential traction at ``interface``'s owned slave nodes: ``traction``
    (owned nodes, gdim), each node's tangential multipliers as a vector (y_j . tau_j),
    fitted component by component as the pressure is, then made tangential again (its
    component along the node's patch normal taken out; a fitted tangent field of a
    curved surface has one). Nodes not fitted keep their vector. Collective."""
    traction = np.asarray(traction, dtype=float)
    gdim = interface.gdim
    vector = interface.create_multiplier_vector()
    node_values = np.empty((interface.slave.num_nodes, gdim))
    for c in range(gdim):
        vector.getArray()[:] = traction[:, c]
        node_values[:, c] = interface.node_values(vector)
    vector.destroy()
    result = traction.copy()
    fitted, value = _patch_fits(interface, node_values, active, with_normals=True)
    value, normals = value[:, :gdim], value[:, gdim:]
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    value -= np.einsum("nc,nc->n", value, normals)[:, None] * normals
    result[fitted] = value
    return result


def _patch_fits(interface: MortarInterface, node_values: np.ndarray, active: np.ndarray,
                with_normals: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The linear fits of the fields ``node_values`` (slave node table, fields) over each
    owned active node's patch (module docstring), evaluated at the node: (which owned
    nodes were fitted (n,) bool, their values (fitted, fields)); with ``with_normals`` the
    patch's summed area normal follows each node's values. Collective."""
    slave = interface.slave
    gdim = interface.gdim
    m = gdim + 1
    fields = node_values.shape[1]

    flags = interface.create_multiplier_vector()
    flags.getArray()[:] = active
    node_active = interface.node_values(flags) > 0.5
    flags.destroy()

    facets = slave.facets
    used = np.all(node_active[facets], axis=1) if facets.size else np.zeros(0, dtype=bool)
    facets = facets[used]
    x = slave.reference_coordinates[facets]
    mass = _facet_mass_matrices(x)
    values_at = node_values[facets]  # (facets, k, fields)
    normals = _area_normals(x)

    width = m * m + m * fields + gdim
    local = np.zeros((slave.num_nodes, width))
    for a in range(facets.shape[1]):
        basis = np.concatenate([np.ones(x.shape[:2] + (1,)), x - x[:, [a]]], axis=2)
        weighted = np.einsum("fkl,fkp->flp", mass, basis)
        values = np.concatenate([
            np.einsum("flp,flq->fpq", weighted, basis).reshape(-1, m * m),
            np.einsum("flp,flr->fpr", weighted, values_at).reshape(-1, m * fields),
            normals,
        ], axis=1)
        np.add.at(local, facets[:, a], values)

    sums = _sum_on_owners(interface, local, width)
    owned = sums.reshape(-1, width)
    patch_normals = owned[:, width - gdim:]
    fitted = active & (np.linalg.norm(patch_normals, axis=1) > 0.0)
    empty = np.zeros((0, fields + (gdim if with_normals else 0)))
    if not fitted.any():
        return np.zeros(active.shape, dtype=bool), empty
    gram = owned[fitted, : m * m].reshape(-1, m, m)
    moments = owned[fitted, m * m: m * m + m * fields].reshape(-1, m, fields)
    tangents = _tangent_bases(patch_normals[fitted])
    projection = np.zeros((tangents.shape[0], gdim, m))
    projection[:, 0, 0] = 1.0
    projection[:, 1:, 1:] = tangents
    gram_t = np.einsum("nip,npq,njq->nij", projection, gram, projection)
    moments_t = np.einsum("nip,npr->nir", projection, moments)
    well_posed = np.linalg.cond(gram_t) < 1e12
    value = np.linalg.solve(gram_t[well_posed], moments_t[well_posed])[:, 0, :]
    rows = np.flatnonzero(fitted)[well_posed]
    if with_normals:
        value = np.concatenate([value, patch_normals[rows]], axis=1)
    result = np.zeros(active.shape, dtype=bool)
    result[rows] = True
    return result, value


def _sum_on_owners(interface: MortarInterface, local: np.ndarray, width: int) -> np.ndarray:
    """Sums of the per-node rows ``local`` (this rank's slave nodes) over the ranks, at the
    owned multipliers: (owned multipliers * width,)."""
    vector = PETSc.Vec().createGhost(
        interface._ghost_multipliers.astype(PETSc.IntType),
        size=(interface.num_owned_multipliers * width, interface.num_global_multipliers * width),
        bsize=width,
        comm=interface.comm,
    )
    offset = interface.multiplier_offset
    numbers = interface.node_multipliers
    is_owned = (numbers >= offset) & (numbers < offset + interface.num_owned_multipliers)
    position = np.empty(numbers.size, dtype=np.int64)
    position[is_owned] = numbers[is_owned] - offset
    position[~is_owned] = interface.num_owned_multipliers + np.searchsorted(
        interface._ghost_multipliers, numbers[~is_owned])
    with vector.localForm() as form:
        array = form.getArray()
        array[:] = 0.0
        blocks = array.reshape(-1, width)
        np.add.at(blocks, position, local)
    vector.ghostUpdate(addv=PETSc.InsertMode.ADD_VALUES, mode=PETSc.ScatterMode.REVERSE)
    result = vector.getArray(readonly=True).copy()
    vector.destroy()
    return result
