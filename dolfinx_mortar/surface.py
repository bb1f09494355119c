"""Contact surfaces extracted from dolfinx facet tags: facets, nodes, dofs, owners.

A :class:`ContactSurface` is this rank's share of one tagged boundary: the
facets it owns, oriented so that their normal points out of their body, and
the nodes of those facets with the displacement dofs that move them. Nodes
are identified across ranks by their global dof block (a P1 vector space has
one block per vertex), which is independent of how a rank numbers them.
"""

from __future__ import annotations

import dataclasses

import dolfinx
import numpy as np
from mpi4py import MPI

from . import compat


class SurfaceError(ValueError):
    """A contact surface cannot be built from the given tags or space."""


@dataclasses.dataclass
class ContactSurface:
    """This rank's owned facets of one contact surface.

    Attributes:
        name: for messages (``"slave"``, ``"master"``, a tag name).
        marker: the facet tag value.
        facets: (num_facets, k) local node indices. 2D (k = 2): start -> end
            so that (t_y, -t_x), t = end - start, points out of the body. 3D
            (k = 3 triangles, 4 quadrilaterals): cyclic around the facet,
            counter-clockwise seen from outside, so that
            (x_1 - x_0) x (x_{k-1} - x_0) points out of the body.
        facet_entities: (num_facets,) dolfinx facet indices on this rank.
        node_blocks: (num_nodes,) local dof block of each node in ``V``.
        node_global_blocks: (num_nodes,) global dof block (the node's identity).
        node_owned: (num_nodes,) whether this rank owns the node's dofs.
        reference_coordinates: (num_nodes, gdim) undeformed coordinates.
        cells: (num_facets,) the cell of each facet (for body checks).
        block_size: the displacement space's block size (gdim), for :meth:`node_dofs`.
    """

    name: str
    marker: int
    facets: np.ndarray
    facet_entities: np.ndarray
    node_blocks: np.ndarray
    node_global_blocks: np.ndarray
    node_owned: np.ndarray
    reference_coordinates: np.ndarray
    cells: np.ndarray
    block_size: int = 2

    @property
    def num_facets(self) -> int:
        """Facets this rank owns."""
        return self.facets.shape[0]

    @property
    def num_nodes(self) -> int:
        """Nodes of this rank's facets (owned or not)."""
        return self.node_blocks.shape[0]

    @property
    def gdim(self) -> int:
        """Geometric dimension, 2 or 3."""
        return self.reference_coordinates.shape[1]

    @property
    def nodes_per_facet(self) -> int:
        """2 (segments), 3 (triangles) or 4 (quadrilaterals)."""
        return self.facets.shape[1]

    def edge_lengths(self) -> np.ndarray:
        """The lengths of this rank's undeformed facet edges: every edge of every facet (a
        2D facet is its one edge; an edge between two facets counts for each)."""
        corners = self.reference_coordinates[self.facets]
        if corners.shape[1] == 2:
            return np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
        return np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2).ravel()

    def node_dofs(self) -> np.ndarray:
        """(num_nodes, gdim) global PETSc indices of the displacement dofs."""
        return self.node_global_blocks[:, None] * self.block_size + np.arange(self.block_size)

    def current_coordinates(self, u: dolfinx.fem.Function | None,
                            origin: np.ndarray | None = None) -> np.ndarray:
        """x = X + u at the surface nodes (ghost values of ``u`` must be up to date), or
        (X - origin) + u: relative to a point near the surface, a small u is not rounded
        to the size of X."""
        X = self.reference_coordinates if origin is None else self.reference_coordinates - origin
        if u is None:
            return X.copy() if origin is None else X
        values = u.x.array.reshape(-1, self.block_size)
        return X + values[self.node_blocks, : self.gdim]

    def bounding_box_centre(self, comm: MPI.Intracomm) -> np.ndarray:
        """The centre of the undeformed surface's bounding box over all ranks (collective;
        the same on every rank; zero for a surface with no node)."""
        X = self.reference_coordinates
        lower = np.full(self.gdim, np.inf) if X.shape[0] == 0 else X.min(axis=0)
        upper = np.full(self.gdim, -np.inf) if X.shape[0] == 0 else X.max(axis=0)
        lower, upper = np.ascontiguousarray(lower, dtype=np.float64), upper.astype(np.float64)
        comm.Allreduce(MPI.IN_PLACE, lower, op=MPI.MIN)
        comm.Allreduce(MPI.IN_PLACE, upper, op=MPI.MAX)
        if not np.all(np.isfinite(lower) & np.isfinite(upper)):
            return np.zeros(self.gdim)
        return 0.5 * (lower + upper)


CELL_TYPES = {2: ("triangle", "quadrilateral"), 3: ("tetrahedron", "hexahedron")}


def check_space(V: dolfinx.fem.FunctionSpace) -> None:
    """Raise a clear error for a space the mortar method does not support."""
    mesh = V.mesh
    tdim = mesh.topology.dim
    gdim = mesh.geometry.dim
    if tdim not in CELL_TYPES:
        raise SurfaceError(f"contact needs a 2D or 3D mesh; got topological dimension {tdim}")
    if gdim != tdim:
        raise NotImplementedError(
            f"a {tdim}D mesh in {gdim}D space (a surface or plate) is not supported; "
            "contact needs a mesh of the dimension of its space")
    cell_name = mesh.topology.cell_name()
    if cell_name not in CELL_TYPES[tdim]:
        raise SurfaceError(
            f"unsupported cell type {cell_name!r}; use {' or '.join(CELL_TYPES[tdim])} "
            "(prisms, pyramids and mixed meshes are not supported)")
    if compat.coordinate_element_degree(mesh) != 1:
        raise SurfaceError("only meshes with linear (P1/Q1) geometry are supported")
    block_size = V.dofmap.index_map_bs
    if block_size != gdim:
        raise SurfaceError(
            f"the displacement must be a vector space with {gdim} components; "
            f"got block size {block_size}"
        )
    if not compat.is_linear_lagrange(V):
        raise SurfaceError("the displacement space must be linear Lagrange (P1 or Q1)")


def _tagged_facets(mesh: dolfinx.mesh.Mesh, facet_tags: dolfinx.mesh.MeshTags, marker: int,
                   name: str) -> tuple[np.ndarray, np.ndarray]:
    """(facets, cells): this rank's owned facets tagged ``marker``, sorted, and the one
    cell of each; raises if no rank has any or if one of them is an interior facet."""
    comm = mesh.comm
    tdim = mesh.topology.dim
    fdim = tdim - 1
    if facet_tags.dim != fdim:
        raise SurfaceError(f"{name}: meshtags of dimension {facet_tags.dim} are not facet tags")
    mesh.topology.create_connectivity(fdim, tdim)
    mesh.topology.create_connectivity(tdim, fdim)
    facet_map = mesh.topology.index_map(fdim)

    tagged = facet_tags.indices[facet_tags.values == marker]
    facets = np.sort(tagged[tagged < facet_map.size_local]).astype(np.int32)
    if comm.allreduce(facets.size, op=MPI.SUM) == 0:
        present = np.unique(np.concatenate(comm.allgather(np.unique(facet_tags.values))))
        raise SurfaceError(
            f"{name}: facet tag {marker} marks no facet on any rank "
            f"(tags present: {present.tolist()})"
        )

    f_to_c = mesh.topology.connectivity(fdim, tdim)
    num_cells = np.diff(f_to_c.offsets)[facets]
    interior = comm.allreduce(int(np.count_nonzero(num_cells != 1)), op=MPI.SUM)
    if interior:
        raise SurfaceError(
            f"{name}: {interior} facets with tag {marker} are interior facets; "
            "a contact surface must lie on the boundary of its own body, and two bodies "
            "in one mesh must not share nodes (build the mesh from one mesh per body "
            "with dolfinx_mortar.bodies.merge_meshes)"
        )
    return facets, f_to_c.array[f_to_c.offsets[facets]]


def _outward_facet_nodes(V: dolfinx.fem.FunctionSpace, facets: np.ndarray,
                         cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dof blocks, geometry nodes) of each facet's nodes, (num_facets, k) each, in the
    order of :attr:`ContactSurface.facets`: cyclic, and reversed where the facet's normal
    would point into its cell."""
    mesh = V.mesh
    fdim = mesh.topology.dim - 1
    c_to_f = mesh.topology.connectivity(fdim + 1, fdim)
    facets_per_cell = c_to_f.offsets[1] - c_to_f.offsets[0]
    cell_facets = c_to_f.array.reshape(-1, facets_per_cell)[cells]
    local_facet = np.argmax(cell_facets == facets[:, None], axis=1)

    layout = V.dofmap.dof_layout
    closure = np.array(
        [layout.entity_closure_dofs(fdim, i) for i in range(facets_per_cell)], dtype=np.int32
    )
    cell_dofs = V.dofmap.list[cells]
    facet_blocks = np.take_along_axis(cell_dofs, closure[local_facet], axis=1)

    geometry_dofmap = compat.geometry_dofmap(mesh)
    facet_geometry = np.take_along_axis(geometry_dofmap[cells], closure[local_facet], axis=1)
    if facet_geometry.shape[1] == 4:
        # dolfinx numbers quadrilateral vertices as a tensor product: make them cyclic
        facet_blocks = facet_blocks[:, [0, 1, 3, 2]]
        facet_geometry = facet_geometry[:, [0, 1, 3, 2]]
    gdim = mesh.geometry.dim
    X = mesh.geometry.x[:, :gdim]
    corners = X[facet_geometry]
    cell_midpoints = X[geometry_dofmap[cells]].mean(axis=1)
    if gdim == 2:
        tangent = corners[:, 1] - corners[:, 0]
        outward = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    elif corners.shape[1] == 4:
        outward = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    else:
        outward = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flip = np.einsum("ij,ij->i", outward, corners.mean(axis=1) - cell_midpoints) < 0.0
    facet_blocks[flip] = facet_blocks[flip, ::-1]
    facet_geometry[flip] = facet_geometry[flip, ::-1]
    return facet_blocks, facet_geometry


def extract_surface(
    V: dolfinx.fem.FunctionSpace,
    facet_tags: dolfinx.mesh.MeshTags,
    marker: int,
    name: str = "surface",
) -> ContactSurface:
    """Build this rank's part of the contact surface tagged ``marker``.

    Collective: every rank of the mesh's communicator must call it.

    Args:
        V: The displacement space (vector P1 or Q1 on a linear mesh).
        facet_tags: Facet tags of ``V``'s mesh.
        marker: The tag value of the surface.
        name: Names the surface in error messages.

    Raises:
        SurfaceError: the tag is absent or empty on every rank, a tagged facet
            is not on the boundary, or the space is not supported.
    """
    check_space(V)
    facets, cells = _tagged_facets(V.mesh, facet_tags, marker, name)
    facet_blocks, facet_geometry = _outward_facet_nodes(V, facets, cells)
    node_blocks, inverse = np.unique(facet_blocks.ravel(), return_inverse=True)
    node_facets = inverse.reshape(facet_blocks.shape).astype(np.int32)
    geometry_of_node = np.empty(node_blocks.size, dtype=np.int64)
    geometry_of_node[inverse] = facet_geometry.ravel()
    dof_map = V.dofmap.index_map
    X = V.mesh.geometry.x[:, : V.mesh.geometry.dim]
    return ContactSurface(
        name=name,
        marker=int(marker),
        facets=node_facets,
        facet_entities=facets,
        node_blocks=node_blocks.astype(np.int32),
        node_global_blocks=dof_map.local_to_global(node_blocks.astype(np.int32)).astype(np.int64),
        node_owned=node_blocks < dof_map.size_local,
        reference_coordinates=X[geometry_of_node].copy(),
        cells=cells.astype(np.int32),
        block_size=V.dofmap.index_map_bs,
    )


def check_disjoint(slave: ContactSurface, master: ContactSurface, comm: MPI.Intracomm) -> None:
    """The same facet may not be both slave and master."""
    shared = np.intersect1d(slave.facet_entities, master.facet_entities).size
    if comm.allreduce(shared, op=MPI.SUM):
        raise SurfaceError(
            f"{comm.allreduce(shared, op=MPI.SUM)} facets are tagged both slave "
            f"({slave.marker}) and master ({master.marker})"
        )


def body_labels(mesh: dolfinx.mesh.Mesh) -> np.ndarray:
    """A body number for each local cell: cells joined through vertices share it.

    Components are found on each rank (scipy), then joined across ranks
    through the shared vertices with a small union-find that every rank does
    on the gathered links. The numbers are the same on every rank count up
    to renaming; only equality between them is meaningful.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    comm = mesh.comm
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    vertex_map = mesh.topology.index_map(0)
    num_vertices = vertex_map.size_local + vertex_map.num_ghosts
    cell_vertices = mesh.topology.connectivity(tdim, 0)
    vertices_per_cell = cell_vertices.offsets[1] - cell_vertices.offsets[0]
    cells = cell_vertices.array.reshape(-1, vertices_per_cell)
    rows = np.repeat(cells[:, 0], vertices_per_cell - 1)
    cols = cells[:, 1:].reshape(-1)
    graph = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(num_vertices, num_vertices))
    count, local = connected_components(graph, directed=False)
    offset = comm.exscan(count) or 0
    label = local.astype(np.int64) + offset
    links = np.zeros((0, 2), dtype=np.int64)
    if comm.size > 1:
        shared = dolfinx.la.vector(vertex_map, 1)
        shared.array[: vertex_map.size_local] = label[: vertex_map.size_local]
        shared.scatter_forward()
        ghost_labels = shared.array[vertex_map.size_local : num_vertices].astype(np.int64)
        links = np.unique(np.column_stack([label[vertex_map.size_local :], ghost_labels]), axis=0)
    links = np.vstack(comm.allgather(links)) if comm.size > 1 else links
    parent = np.arange(comm.allreduce(count, op=MPI.SUM), dtype=np.int64)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in links:
        root_a, root_b = find(int(a)), find(int(b))
        if root_a != root_b:
            parent[max(root_a, root_b)] = min(root_a, root_b)
    roots = np.array([find(i) for i in range(parent.size)], dtype=np.int64)
    return roots[label[cells[:, 0]]]
