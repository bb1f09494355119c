"""One mesh of several bodies, merged from the user's own meshes or gmsh models.

:class:`~dolfinx_mortar.problem.ContactProblem` works on one dolfinx mesh that holds
every body, with these rules:

* one mesh: all bodies are cells of the same (distributed) dolfinx mesh;
* bodies share no nodes: touching bodies may have nodes at the same coordinates,
  but never the same node, facet or cell (a shared node would glue them together);
* one cell tag per body, so materials and loads can be assigned per body;
* contact facets lie on the boundary of their own body (facet tags).

:func:`merge_meshes` builds such a mesh from separate meshes, each with its own
facet groups, in serial and in parallel::

    import numpy as np
    from mpi4py import MPI
    from dolfinx.mesh import create_rectangle, CellType
    from dolfinx_mortar.bodies import merge_meshes

    comm = MPI.COMM_WORLD
    punch = create_rectangle(comm, [[-0.5, 1.0], [0.5, 1.5]], [6, 3], CellType.triangle)
    block = create_rectangle(comm, [[-1.0, 0.0], [1.0, 1.0]], [10, 5], CellType.triangle)
    tagged = merge_meshes({
        "punch": (punch, {"contact": lambda x: np.isclose(x[1], 1.0),
                          "top": lambda x: np.isclose(x[1], 1.5)}),
        "block": (block, {"contact": lambda x: np.isclose(x[1], 1.0),
                          "bottom": lambda x: np.isclose(x[1], 0.0)})})
    tagged.markers  # {"punch": 1, "block": 2, "punch_contact": 11, "punch_top": 12,
                    #  "block_contact": 13, "block_bottom": 14}

The merged mesh is built on rank 0 from the gathered bodies and distributed by
dolfinx (ghost mode none, like the gmsh builders of :mod:`dolfinx_mortar.meshes`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping

import basix
import basix.ufl
import dolfinx
import dolfinx.graph
import dolfinx.io
import dolfinx.mesh
import numpy as np
from mpi4py import MPI

from . import compat

FIRST_FACET_VALUE = 11
"""Facet tag values start here (or after the last body value with more than 10 bodies)."""

Locator = Callable[[np.ndarray], np.ndarray]



@dataclasses.dataclass
class TaggedMesh:
    """A mesh of several separate bodies with its cell and facet tags.

    Attributes:
        mesh: The distributed mesh of all bodies.
        cell_tags: One tag value per body.
        facet_tags: Tagged boundary pieces and internal symmetry lines.
        markers: Name to tag value, identical on every rank. ``contact_slave`` and
            ``contact_master`` repeat the value of the slave and master surfaces.
        h_contact: Nominal element size on the slave contact surface (the one the
            mortar integrals live on); nan if the builder does not define one.
    """

    mesh: dolfinx.mesh.Mesh
    cell_tags: dolfinx.mesh.MeshTags
    facet_tags: dolfinx.mesh.MeshTags
    markers: dict[str, int]
    h_contact: float = math.nan


class _Body:
    """One body on this rank: its mesh and its facet groups (name, owned facets)."""

    def __init__(self, name: str, mesh: dolfinx.mesh.Mesh, groups: list[tuple[str, np.ndarray]]):
        self.name = name
        self.mesh = mesh
        self.groups = groups


def merge_meshes(bodies: Mapping[str, object], comm: MPI.Comm | None = None) -> TaggedMesh:
    """Put several bodies, each meshed on its own, into one mesh with one cell tag per body.

    Collective on ``comm``: call it on every rank with the same bodies. All bodies must have
    the same cell type (e.g. all tetrahedra or all hexahedra: dolfinx meshes hold one cell
    type) and geometric dimension, with linear (P1/Q1) geometry.

    Args:
        bodies: body name -> body, in the order of the tag values. A body is
            a dolfinx Mesh (no facet groups); a tuple ``(mesh, facets)`` where
            ``facets`` is a dict group name -> locator (``x -> bool array`` over
            the points ``x`` of shape (3, n), as for
            ``dolfinx.mesh.locate_entities_boundary``: it selects boundary facets
            of that body whose vertices all satisfy it) or a facet MeshTags
            (groups named ``str(value)``, or by an optional third element,
            a dict name -> value); the ``(mesh, cell_tags, facet_tags)`` result of
            gmsh's ``model_to_mesh`` (a tuple or a ``MeshData``, by dolfinx version);
            or the ``gmsh.model`` module after meshing (the model on rank 0, as
            for ``model_to_mesh``, whose value on other ranks is ignored; groups
            are its physical facet groups, named by their physical names where
            given, else by their tag).
        comm: communicator of the merged mesh; default that of the first body
            given as a mesh (``MPI.COMM_WORLD`` if all are gmsh models). Input
            meshes must live on it.

    Returns:
        The merged mesh with cell tags 1, 2, ... per body in the given order and
        facet tags from 11 on (from n + 1 with n > 10 bodies), group by group in
        the given order; ``markers`` names them ``body`` and ``body_group``.

    Raises:
        ValueError: on every rank, for a body that is not one of the forms above,
            meshes of different cell types or geometric dimensions, non-linear
            geometry, a locator that selects no boundary facet, a facet in two
            groups of one body, or names that repeat.
    """
    if not isinstance(bodies, Mapping) or not bodies:
        raise ValueError(
            "merge_meshes needs a non-empty dict body name -> mesh or (mesh, facets), "
            f"got {type(bodies).__name__}"
        )
    for name in bodies:
        if not isinstance(name, str) or not name:
            raise ValueError(f"body names must be non-empty strings, got {name!r}")
    if comm is None:
        comm = next(
            (_mesh_of(value).comm for value in bodies.values() if _mesh_of(value) is not None),
            MPI.COMM_WORLD,
        )
    parsed = [_parse_body(name, value, comm) for name, value in bodies.items()]
    _check_compatible(parsed, comm)
    markers = _markers(parsed)
    mesh, cell_tags, facet_tags = _merge(parsed, markers, comm)
    return TaggedMesh(mesh, cell_tags, facet_tags, markers)


# ---------------------------------------------------------------------------------------
# Reading the bodies. Each check depends only on the arguments (the same on every rank)
# or is reduced over comm, so a bad body raises on every rank.


def _mesh_of(value) -> dolfinx.mesh.Mesh | None:
    if isinstance(value, dolfinx.mesh.Mesh):
        return value
    if isinstance(value, tuple) and value and isinstance(value[0], dolfinx.mesh.Mesh):
        return value[0]
    mesh_data = compat.gmsh_mesh_data(value)
    return mesh_data[0] if mesh_data is not None else None


def _is_gmsh_model(value) -> bool:
    return callable(getattr(value, "getPhysicalGroups", None)) and callable(
        getattr(value, "getDimension", None)
    )


def _parse_body(name: str, value, comm: MPI.Comm) -> _Body:
    # the model lives on rank 0: rank 0 decides, whatever the other ranks pass
    if comm.bcast(_is_gmsh_model(value) if comm.rank == 0 else None, root=0):
        return _gmsh_body(name, value, comm)
    if isinstance(value, dolfinx.mesh.Mesh):
        _check_comm(name, value, comm)
        return _Body(name, value, [])
    if isinstance(value, tuple) and len(value) in (2, 3):
        mesh, facets = value[0], value[1]
        if not isinstance(mesh, dolfinx.mesh.Mesh):
            raise ValueError(
                f"body {name!r}: the first element of the tuple must be a dolfinx Mesh, "
                f"got {type(mesh).__name__}"
            )
        _check_comm(name, mesh, comm)
        if len(value) == 3 and isinstance(value[2], dolfinx.mesh.MeshTags):
            # (mesh, cell_tags, facet_tags) of gmsh's model_to_mesh
            return _Body(name, mesh, _tag_groups(name, mesh, value[2], None, comm))
        names = value[2] if len(value) == 3 else None
        if names is not None and not isinstance(names, Mapping):
            raise ValueError(
                f"body {name!r}: the third element of the tuple must be a dict "
                f"name -> tag value, got {type(names).__name__}"
            )
        if isinstance(facets, dolfinx.mesh.MeshTags):
            return _Body(name, mesh, _tag_groups(name, mesh, facets, names, comm))
        if isinstance(facets, Mapping):
            if names is not None:
                raise ValueError(
                    f"body {name!r}: names (third element) apply to facet MeshTags, "
                    "not to a dict of locators"
                )
            return _Body(name, mesh, _locator_groups(name, mesh, facets, comm))
        raise ValueError(
            f"body {name!r}: facets must be a dict name -> locator or a facet MeshTags, "
            f"got {type(facets).__name__}"
        )
    mesh_data = compat.gmsh_mesh_data(value)
    if mesh_data is not None:
        mesh, facet_tags, groups = mesh_data
        _check_comm(name, mesh, comm)
        names = {group: int(tag) for group, (dim, tag) in groups.items()
                 if group and dim == mesh.topology.dim - 1}
        return _Body(name, mesh, _tag_groups(name, mesh, facet_tags, names, comm,
                                             partial_names=True))
    raise ValueError(
        f"body {name!r}: expected a dolfinx Mesh, a tuple (mesh, facets), the result of "
        f"model_to_mesh or a gmsh model, got {type(value).__name__}"
    )


def _check_comm(name: str, mesh: dolfinx.mesh.Mesh, comm: MPI.Comm) -> None:
    if MPI.Comm.Compare(mesh.comm, comm) not in (MPI.IDENT, MPI.CONGRUENT):
        raise ValueError(
            f"body {name!r}: its mesh lives on another communicator than comm "
            f"(sizes {mesh.comm.size} and {comm.size}); create the meshes on comm"
        )


def _owned_facets(mesh: dolfinx.mesh.Mesh, facets: np.ndarray) -> np.ndarray:
    fdim = mesh.topology.dim - 1
    mesh.topology.create_entities(fdim)
    num_owned = mesh.topology.index_map(fdim).size_local
    facets = np.asarray(facets, dtype=np.int32)
    return np.unique(facets[facets < num_owned])


def _locator_groups(
    name: str, mesh: dolfinx.mesh.Mesh, locators: Mapping[str, Locator], comm: MPI.Comm
) -> list[tuple[str, np.ndarray]]:
    fdim = mesh.topology.dim - 1
    groups = []
    for group, locator in locators.items():
        if not isinstance(group, str) or not group:
            raise ValueError(f"body {name!r}: facet group names must be non-empty strings, "
                             f"got {group!r}")
        if not callable(locator):
            raise ValueError(
                f"body {name!r}: facet group {group!r} must be a locator x -> bool array, "
                f"got {type(locator).__name__}"
            )
        facets = _owned_facets(mesh, dolfinx.mesh.locate_entities_boundary(mesh, fdim, locator))
        if comm.allreduce(facets.size, op=MPI.SUM) == 0:
            raise ValueError(
                f"body {name!r}: facet group {group!r} selects no boundary facet (a locator "
                "selects facets on the boundary of its body whose vertices all satisfy it; "
                "interior facets cannot be tagged this way)"
            )
        groups.append((group, facets))
    return groups


def _tag_groups(
    name: str,
    mesh: dolfinx.mesh.Mesh,
    tags: dolfinx.mesh.MeshTags,
    names: Mapping[str, int] | None,
    comm: MPI.Comm,
    partial_names: bool = False,
) -> list[tuple[str, np.ndarray]]:
    fdim = mesh.topology.dim - 1
    if tags.dim != fdim:
        raise ValueError(
            f"body {name!r}: the MeshTags have dimension {tags.dim}; facet tags "
            f"(dimension {fdim}) are needed"
        )
    present = np.unique(np.concatenate(comm.allgather(np.unique(tags.values))))
    label = {int(value): str(int(value)) for value in present}
    if names:
        for group, value in names.items():
            if not isinstance(group, str) or not group:
                raise ValueError(f"body {name!r}: facet group names must be non-empty strings, "
                                 f"got {group!r}")
            if int(value) not in label:
                if partial_names:
                    continue
                raise ValueError(
                    f"body {name!r}: facet group {group!r} (tag {value}) marks no facet "
                    f"(tags present: {present.tolist()})"
                )
            label[int(value)] = group
    return [
        (label[int(value)], _owned_facets(mesh, tags.indices[tags.values == value]))
        for value in present
    ]


def _gmsh_body(name: str, model, comm: MPI.Comm) -> _Body:
    names: dict[str, int] = {}
    gdim = 0
    if comm.rank == 0:
        gdim = int(model.getDimension())
        for dim, tag in model.getPhysicalGroups(dim=gdim - 1):
            group = model.getPhysicalName(dim, tag)
            if group:
                names[group] = int(tag)
    gdim, names = comm.bcast((gdim, names), root=0)
    if gdim < 1:
        raise ValueError(f"body {name!r}: the gmsh model holds no mesh on rank 0")
    mesh, _, facet_tags = compat.model_to_mesh(model, comm, 0, gdim)
    return _Body(name, mesh, _tag_groups(name, mesh, facet_tags, names, comm))


def _check_compatible(parsed: list[_Body], comm: MPI.Comm) -> None:
    first = parsed[0].mesh
    kind = (first.topology.cell_name(), first.geometry.dim)
    for body in parsed:
        mesh = body.mesh
        if compat.coordinate_element_degree(mesh) != 1:
            raise ValueError(
                f"body {body.name!r}: geometry of degree "
                f"{compat.coordinate_element_degree(mesh)} is not supported (linear meshes only)"
            )
        if (mesh.topology.cell_name(), mesh.geometry.dim) != kind:
            raise ValueError(
                f"body {body.name!r}: {mesh.topology.cell_name()} cells in dimension "
                f"{mesh.geometry.dim} with {kind[0]} cells in dimension {kind[1]} in body "
                f"{parsed[0].name!r}: mixed cell types or dimensions are not supported"
            )
        owned = np.concatenate([facets for _, facets in body.groups] or [np.empty(0, np.int32)])
        repeated = comm.allreduce(int(owned.size - np.unique(owned).size), op=MPI.SUM)
        if repeated:
            raise ValueError(
                f"body {body.name!r}: {repeated} facets belong to two facet groups; "
                "a facet carries one tag"
            )


def _markers(parsed: list[_Body]) -> dict[str, int]:
    first_facet = max(FIRST_FACET_VALUE, len(parsed) + 1)
    markers = {body.name: 1 + i for i, body in enumerate(parsed)}
    groups = [f"{body.name}_{group}" for body in parsed for group, _ in body.groups]
    for n, group in enumerate(groups):
        if group in markers:
            raise ValueError(
                f"the name {group!r} is used twice (body and facet group names are joined "
                "as body_group); rename a body or a group"
            )
        markers[group] = first_facet + n
    return markers


# ---------------------------------------------------------------------------------------
# Merging: gather every body to rank 0 in global node numbers, offset the node numbers
# body by body so no node is shared, and let dolfinx distribute the result.


def _gather_body(body: _Body, comm: MPI.Comm, gdim: int):
    """Rank 0: (coordinates, cells, facet vertex nodes per group) in this body's numbering."""
    mesh = body.mesh
    tdim = mesh.topology.dim
    node_map = mesh.geometry.index_map()
    num_owned_nodes = node_map.size_local
    x = mesh.geometry.x[:num_owned_nodes, :gdim]
    offset = node_map.local_range[0]
    num_cells = mesh.topology.index_map(tdim).size_local
    dofmap = compat.geometry_dofmap(mesh)[:num_cells]
    cells = node_map.local_to_global(dofmap.ravel()).reshape(dofmap.shape)
    facets = []
    for _, group in body.groups:
        if group.size == 0:  # dolfinx 0.9 divides by zero on no entities
            nodes = np.empty((0, _nodes_per_facet(mesh)), dtype=np.int32)
        else:
            nodes = dolfinx.mesh.entities_to_geometry(mesh, tdim - 1, group, False)
        facets.append(node_map.local_to_global(nodes.ravel()).reshape(nodes.shape))
    gathered = comm.gather((offset, x, cells, facets), root=0)
    if comm.rank != 0:
        return None
    coordinates = np.empty((node_map.size_global, gdim), dtype=np.float64)
    for start, block, _, _ in gathered:
        coordinates[start : start + block.shape[0]] = block
    all_cells = np.concatenate([c for _, _, c, _ in gathered]).astype(np.int64)
    all_facets = [
        np.concatenate([f[k] for _, _, _, f in gathered]).astype(np.int64)
        for k in range(len(body.groups))
    ]
    return coordinates, all_cells, all_facets


def _nodes_per_facet(mesh: dolfinx.mesh.Mesh) -> int:
    cell_type = getattr(basix.CellType, mesh.topology.cell_name())
    return len(basix.topology(cell_type)[mesh.topology.dim - 1][0])


def _merge(parsed: list[_Body], markers: dict[str, int], comm: MPI.Comm):
    first = parsed[0].mesh
    gdim = first.geometry.dim
    tdim = first.topology.dim
    nodes_per_cell = compat.geometry_dofmap(first).shape[1]
    nodes_per_facet = _nodes_per_facet(first)
    gathered = [_gather_body(body, comm, gdim) for body in parsed]
    if comm.rank == 0:
        x, cells, cell_values, facets, facet_values = [], [], [], [], []
        offset = 0
        for body, (coordinates, body_cells, body_facets) in zip(parsed, gathered, strict=True):
            x.append(coordinates)
            cells.append(body_cells + offset)
            cell_values.append(np.full(body_cells.shape[0], markers[body.name], dtype=np.int32))
            for (group, _), group_facets in zip(body.groups, body_facets, strict=True):
                facets.append(group_facets.reshape(-1, nodes_per_facet) + offset)
                value = markers[f"{body.name}_{group}"]
                facet_values.append(np.full(group_facets.shape[0], value, dtype=np.int32))
            offset += coordinates.shape[0]
        x_all = np.concatenate(x)
        cells_all = np.concatenate(cells)
        cell_values_all = np.concatenate(cell_values)
        facets_all = (np.concatenate(facets) if facets
                      else np.empty((0, nodes_per_facet), dtype=np.int64))
        facet_values_all = (np.concatenate(facet_values) if facet_values
                            else np.empty(0, dtype=np.int32))
    else:
        x_all = np.empty((0, gdim), dtype=np.float64)
        cells_all = np.empty((0, nodes_per_cell), dtype=np.int64)
        cell_values_all = np.empty(0, dtype=np.int32)
        facets_all = np.empty((0, nodes_per_facet), dtype=np.int64)
        facet_values_all = np.empty(0, dtype=np.int32)

    element = basix.ufl.element("Lagrange", first.topology.cell_name(), 1, shape=(gdim,))
    # keywords: 0.9 takes (comm, cells, x, e), 0.10 onwards (comm, cells, e, x)
    mesh = dolfinx.mesh.create_mesh(comm, cells=cells_all, x=x_all, e=element)
    cell_tags = _meshtags(mesh, tdim, cells_all, cell_values_all)
    cell_tags.name = "bodies"
    facet_tags = _meshtags(mesh, tdim - 1, facets_all, facet_values_all)
    facet_tags.name = "facets"
    return mesh, cell_tags, facet_tags


def _meshtags(mesh: dolfinx.mesh.Mesh, dim: int, entities: np.ndarray, values: np.ndarray):
    """MeshTags of entities given by their input node numbers (on any rank)."""
    local_entities, local_values = dolfinx.io.distribute_entity_data(
        mesh, dim, entities, values
    )
    mesh.topology.create_connectivity(dim, mesh.topology.dim)
    mesh.topology.create_connectivity(dim, 0)
    return dolfinx.mesh.meshtags_from_entities(
        mesh,
        dim,
        dolfinx.graph.adjacencylist(local_entities.astype(np.int32)),
        local_values.astype(np.int32, copy=False),
    )
