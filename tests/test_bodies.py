"""merge_meshes: one mesh of several bodies from the user's own meshes."""

from __future__ import annotations

import dolfinx
import dolfinx.fem
import numpy as np
import pytest
import ufl
from dolfinx.mesh import CellType, create_rectangle
from mpi4py import MPI

from dolfinx_mortar import (
    ContactPair,
    ContactProblem,
    Material,
    compat,
    internal_work,
    merge_meshes,
)
from dolfinx_mortar.surface import SurfaceError, extract_surface

PUNCH = [[-0.5, 1.0], [0.5, 1.5]]
BLOCK = [[-1.0, 0.0], [1.0, 1.0]]


def at_y(value: float):
    return lambda x: np.isclose(x[1], value)


def punch_on_block(comm: MPI.Comm, cell_type: CellType = CellType.triangle):
    punch = create_rectangle(comm, PUNCH, [6, 3], cell_type)
    block = create_rectangle(comm, BLOCK, [10, 5], cell_type)
    return merge_meshes(
        {
            "punch": (punch, {"contact": at_y(1.0), "top": at_y(1.5)}),
            "block": (block, {"contact": at_y(1.0), "bottom": at_y(0.0)}),
        },
        comm=comm,
    )


def integral(mesh, form) -> float:
    value = dolfinx.fem.assemble_scalar(dolfinx.fem.form(form))
    return mesh.comm.allreduce(value, op=MPI.SUM)


def node_bodies(tagged) -> dict[int, set[int]]:
    """Global geometry node -> cell tags of the cells using it (gathered on every rank)."""
    mesh = tagged.mesh
    tdim = mesh.topology.dim
    num_cells = mesh.topology.index_map(tdim).size_local
    dofmap = compat.geometry_dofmap(mesh)[:num_cells]
    nodes = mesh.geometry.index_map().local_to_global(dofmap.ravel()).reshape(dofmap.shape)
    tag = np.zeros(num_cells, dtype=np.int32)
    owned = tagged.cell_tags.indices < num_cells
    tag[tagged.cell_tags.indices[owned]] = tagged.cell_tags.values[owned]
    pairs = np.column_stack([nodes.ravel(), np.repeat(tag, nodes.shape[1])])
    result: dict[int, set[int]] = {}
    for node, body in np.concatenate(mesh.comm.allgather(pairs)):
        result.setdefault(int(node), set()).add(int(body))
    return result


@pytest.mark.parallel
@pytest.mark.parametrize("cell_type", [CellType.triangle, CellType.quadrilateral])
def test_two_rectangles_areas_lengths_and_no_shared_node(cell_type):
    comm = MPI.COMM_WORLD
    tagged = punch_on_block(comm, cell_type)
    mesh, markers = tagged.mesh, tagged.markers
    assert markers == {"punch": 1, "block": 2, "punch_contact": 11, "punch_top": 12,
                       "block_contact": 13, "block_bottom": 14}
    assert np.isnan(tagged.h_contact)
    cells_per_rectangle = 2 if cell_type == CellType.triangle else 1
    assert mesh.topology.index_map(2).size_global == cells_per_rectangle * (6 * 3 + 10 * 5)
    one = dolfinx.fem.Constant(mesh, 1.0)
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=tagged.cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    assert integral(mesh, one * dx(1)) == pytest.approx(0.5, rel=1e-12)
    assert integral(mesh, one * dx(2)) == pytest.approx(2.0, rel=1e-12)
    lengths = {"punch_contact": 1.0, "punch_top": 1.0, "block_contact": 2.0, "block_bottom": 2.0}
    for name, length in lengths.items():
        assert integral(mesh, one * ds(markers[name])) == pytest.approx(length, rel=1e-12)
    bodies = node_bodies(tagged)
    assert all(len(tags) == 1 for tags in bodies.values())
    assert len(bodies) == 7 * 4 + 11 * 6
    assert mesh.geometry.index_map().size_global == 7 * 4 + 11 * 6


def solve_punch(comm: MPI.Comm) -> tuple[np.ndarray, np.ndarray]:
    """Punch pressed 0.01 into the block (punch top prescribed, block bottom fixed)."""
    tagged = punch_on_block(comm)
    mesh, markers, facet_tags = tagged.mesh, tagged.markers, tagged.facet_tags
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    u = dolfinx.fem.Function(V)
    material = Material(1000.0, 0.3, "linear")
    F = internal_work(u, ufl.TestFunction(V), {1: material, 2: material}, tagged.cell_tags)
    bcs = [
        dolfinx.fem.dirichletbc(
            np.array(value),
            dolfinx.fem.locate_dofs_topological(V, 1, facet_tags.find(markers[name])),
            V,
        )
        for name, value in (("punch_top", [0.0, -0.01]), ("block_bottom", [0.0, 0.0]))
    ]
    pair = ContactPair(facet_tags, markers["punch_contact"], markers["block_contact"])
    problem = ContactProblem(F, u, bcs, [pair], configuration="reference")
    report = problem.solve()
    assert report.converged
    forces = problem.contact_forces()
    problem.destroy()
    return forces


@pytest.mark.parallel
def test_punch_on_block_balance_and_same_answer_on_one_rank():
    slave, master = solve_punch(MPI.COMM_WORLD)
    assert slave[1] > 1.0  # the block pushes the punch up
    assert np.linalg.norm(slave + master) <= 1e-9 * np.linalg.norm(slave)
    serial, _ = solve_punch(MPI.COMM_SELF)
    assert np.linalg.norm(slave - serial) <= 1e-8 * np.linalg.norm(serial)


@pytest.mark.parallel
def test_facet_meshtags_with_and_without_names():
    comm = MPI.COMM_WORLD
    punch = create_rectangle(comm, PUNCH, [2, 2], CellType.triangle)
    block = create_rectangle(comm, BLOCK, [2, 2], CellType.triangle)
    tags = {}
    for name, mesh, y in (("punch", punch, 1.0), ("block", block, 0.0)):
        mesh.topology.create_entities(1)
        bottom = dolfinx.mesh.locate_entities_boundary(mesh, 1, at_y(y))
        side = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda x: np.isclose(x[0], 0.5))
        facets = np.concatenate([bottom, side]).astype(np.int32)
        values = np.concatenate([np.full(bottom.size, 3), np.full(side.size, 7)]).astype(np.int32)
        order = np.argsort(facets)
        tags[name] = dolfinx.mesh.meshtags(mesh, 1, facets[order], values[order])
    # x = 0.5 is the punch's right side but inside the block: the block has no facet tagged 7
    tagged = merge_meshes({"punch": (punch, tags["punch"], {"right": 7}),
                           "block": (block, tags["block"])})
    assert tagged.markers == {"punch": 1, "block": 2, "punch_3": 11, "punch_right": 12,
                              "block_3": 13}
    one = dolfinx.fem.Constant(tagged.mesh, 1.0)
    ds = ufl.Measure("ds", domain=tagged.mesh, subdomain_data=tagged.facet_tags)
    for value, length in ((11, 1.0), (12, 0.5), (13, 2.0)):
        assert integral(tagged.mesh, one * ds(value)) == pytest.approx(length, rel=1e-12)
    with pytest.raises(ValueError, match="facet group 'left' \\(tag 9\\) marks no facet"):
        merge_meshes({"punch": (punch, tags["punch"], {"left": 9})})


@pytest.mark.parallel
def test_gmsh_model_and_model_to_mesh_result():
    gmsh = pytest.importorskip("gmsh")
    comm = MPI.COMM_WORLD
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        if comm.rank == 0:
            gmsh.model.add("square")
            square = gmsh.model.occ.addRectangle(0.0, 2.0, 0.0, 1.0, 1.0)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(2, [square], 1)
            lines = gmsh.model.getBoundary([(2, square)], oriented=False)
            bottom = [tag for dim, tag in lines
                      if np.isclose(gmsh.model.occ.getCenterOfMass(dim, tag)[1], 2.0)]
            gmsh.model.addPhysicalGroup(1, bottom, 5, name="bottom")
            gmsh.model.addPhysicalGroup(1, [t for _, t in lines if t not in bottom], 6)
            gmsh.option.setNumber("Mesh.CharacteristicLengthMax", 0.25)
            gmsh.model.mesh.generate(2)
        block = compat.model_to_mesh(gmsh.model, comm, 0, 2)
        # dolfinx's own result: a tuple in 0.9, MeshData (with physical names) from 0.10
        raw = compat._gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=2)
        # the model is read on rank 0 only: the other ranks may pass anything
        square = gmsh.model if comm.rank == 0 else None
        tagged = merge_meshes({"square": square, "block": block, "raw": raw})
    finally:
        gmsh.finalize()
    raw_bottom = "raw_bottom" if compat.DOLFINX_VERSION >= (0, 10) else "raw_5"
    assert tagged.markers == {"square": 1, "block": 2, "raw": 3, "square_bottom": 11,
                              "square_6": 12, "block_5": 13, "block_6": 14, raw_bottom: 15,
                              "raw_6": 16}
    mesh = tagged.mesh
    one = dolfinx.fem.Constant(mesh, 1.0)
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=tagged.cell_tags)
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tagged.facet_tags)
    assert integral(mesh, one * dx(1)) == pytest.approx(1.0, rel=1e-12)
    assert integral(mesh, one * dx(2)) == pytest.approx(1.0, rel=1e-12)
    assert integral(mesh, one * dx(3)) == pytest.approx(1.0, rel=1e-12)
    for value, length in ((11, 1.0), (12, 3.0), (13, 1.0), (14, 3.0), (15, 1.0), (16, 3.0)):
        assert integral(mesh, one * ds(value)) == pytest.approx(length, rel=1e-12)
    assert all(len(tags) == 1 for tags in node_bodies(tagged).values())


@pytest.mark.parallel
def test_interior_facets_error_names_the_helper():
    """A rectangle tagged along an inner line: the error says bodies must not share nodes."""
    comm = MPI.COMM_WORLD
    mesh = create_rectangle(comm, [[0.0, 0.0], [1.0, 2.0]], [2, 4], CellType.triangle)
    mesh.topology.create_entities(1)
    inner = dolfinx.mesh.locate_entities(mesh, 1, at_y(1.0))
    tags = dolfinx.mesh.meshtags(mesh, 1, inner, np.full(inner.size, 1, dtype=np.int32))
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    with pytest.raises(SurfaceError, match="must not share nodes.*merge_meshes"):
        extract_surface(V, tags, 1, "slave")
    with pytest.raises(ValueError, match="facet group 'inner' selects no boundary facet"):
        merge_meshes({"rectangle": (mesh, {"inner": at_y(1.0)})})


def p2_triangle(comm: MPI.Comm) -> dolfinx.mesh.Mesh:
    import basix.ufl

    element = basix.ufl.element("Lagrange", "triangle", 2, shape=(2,))
    x = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0.5], [0, 0.5], [0.5, 0]], dtype=np.float64)
    cells = np.arange(6, dtype=np.int64).reshape(1, 6)
    if comm.rank != 0:
        x, cells = x[:0], cells[:0]
    return dolfinx.mesh.create_mesh(comm, cells=cells, x=x, e=element)


@pytest.mark.parallel
def test_bad_inputs_raise_clear_errors():
    comm = MPI.COMM_WORLD
    tri = create_rectangle(comm, PUNCH, [2, 1], CellType.triangle)
    quad = create_rectangle(comm, BLOCK, [2, 1], CellType.quadrilateral)
    bottom = at_y(1.0)
    cases = [
        ([tri], "non-empty dict"),
        ({}, "non-empty dict"),
        ({"a": 3}, "body 'a': expected a dolfinx Mesh"),
        ({"a": (3, {})}, "body 'a': the first element of the tuple must be a dolfinx Mesh"),
        ({"a": (tri, [bottom])}, "body 'a': facets must be a dict"),
        ({"a": (tri, {"b": 1.0})}, "facet group 'b' must be a locator"),
        ({"punch": (tri, {"contact": at_y(0.0)})},
         "body 'punch': facet group 'contact' selects no boundary facet"),
        ({"a": (tri, {"x": bottom, "y": lambda x: x[1] < 1.2})},
         "body 'a': 2 facets belong to two facet groups"),
        ({"a_b": tri, "a": (tri, {"b": bottom})}, "the name 'a_b' is used twice"),
        ({"a": tri, "b": quad}, "mixed cell types or dimensions are not supported"),
        ({"a": tri, "b": p2_triangle(comm)}, "degree 2 is not supported"),
    ]
    for bodies, message in cases:
        with pytest.raises(ValueError, match=message):
            merge_meshes(bodies)
    if comm.size > 1:
        alone = create_rectangle(MPI.COMM_SELF, BLOCK, [2, 1], CellType.triangle)
        with pytest.raises(ValueError, match="another communicator"):
            merge_meshes({"a": tri, "b": alone}, comm=comm)
