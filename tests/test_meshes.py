"""Known answers of the benchmark meshes: body areas, tag lengths, element counts, separation.

Areas and lengths are summed over owned entities and reduced over all ranks, so the
``parallel`` tests check that distributing the gmsh model loses or duplicates nothing.
"""

from __future__ import annotations

import math

import dolfinx
import dolfinx.mesh
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_mortar import compat, meshes

R = 8.0


def _owned(indices: np.ndarray, mesh: dolfinx.mesh.Mesh, dim: int) -> np.ndarray:
    return indices[indices < mesh.topology.index_map(dim).size_local]


def _cells(tagged: meshes.TaggedMesh, name: str) -> np.ndarray:
    mesh = tagged.mesh
    cells = tagged.cell_tags.find(tagged.markers[name])
    return _owned(cells, mesh, mesh.topology.dim)


def _facets(tagged: meshes.TaggedMesh, name: str) -> np.ndarray:
    mesh = tagged.mesh
    facets = tagged.facet_tags.find(tagged.markers[name])
    return _owned(facets, mesh, mesh.topology.dim - 1)


def _sum(comm: MPI.Comm, value: float) -> float:
    return comm.allreduce(value, op=MPI.SUM)


def area(tagged: meshes.TaggedMesh, name: str) -> float:
    """Area of a body from its vertex coordinates (P1 geometry)."""
    mesh = tagged.mesh
    x = mesh.geometry.x[:, :2]
    nodes = np.asarray(compat.geometry_dofmap(mesh))[_cells(tagged, name)]
    if mesh.topology.cell_type == dolfinx.mesh.CellType.quadrilateral:
        nodes = nodes[:, [0, 1, 3, 2]]  # dolfinx's tensor-product order to polygon order
    polygon = x[nodes]
    following = np.roll(polygon, -1, axis=1)
    cross = polygon[..., 0] * following[..., 1] - polygon[..., 1] * following[..., 0]
    return _sum(mesh.comm, float(np.abs(0.5 * cross.sum(axis=1)).sum()))


def facet_segments(tagged: meshes.TaggedMesh, name: str) -> np.ndarray:
    """(n, 2, 2) end points of the owned facets of a tag."""
    mesh = tagged.mesh
    facets = _facets(tagged, name)
    if len(facets) == 0:  # dolfinx 0.9's entities_to_geometry divides by zero here
        return np.empty((0, 2, 2))
    nodes = dolfinx.mesh.entities_to_geometry(mesh, mesh.topology.dim - 1, facets, False)
    return mesh.geometry.x[np.asarray(nodes)][..., :2].reshape(-1, 2, 2)


def length(tagged: meshes.TaggedMesh, name: str) -> float:
    segments = facet_segments(tagged, name)
    local = float(np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1).sum())
    return _sum(tagged.mesh.comm, local)


def count(tagged: meshes.TaggedMesh, name: str) -> int:
    return tagged.mesh.comm.allreduce(len(_facets(tagged, name)), op=MPI.SUM)


def num_cells(tagged: meshes.TaggedMesh) -> int:
    mesh = tagged.mesh
    return mesh.topology.index_map(mesh.topology.dim).size_global


def shared_nodes(tagged: meshes.TaggedMesh, first: str, second: str) -> tuple[int, int]:
    """Numbers of input geometry nodes and of topology vertices used by both bodies."""
    mesh = tagged.mesh
    tdim = mesh.topology.dim
    dofmap = np.asarray(compat.geometry_dofmap(mesh))
    cell_vertices = mesh.topology.connectivity(tdim, 0).array.reshape(len(dofmap), -1)
    vertex_map = mesh.topology.index_map(0)
    input_nodes = np.asarray(mesh.geometry.input_global_indices)

    def used(name: str) -> tuple[set[int], set[int]]:
        cells = tagged.cell_tags.find(tagged.markers[name])
        nodes = input_nodes[dofmap[cells].ravel()]
        vertices = cell_vertices[cells].ravel()
        vertices = vertex_map.local_to_global(vertices.astype(np.int32))
        nodes_all = set().union(*mesh.comm.allgather(set(nodes.tolist())))
        vertices_all = set().union(*mesh.comm.allgather(set(vertices.tolist())))
        return nodes_all, vertices_all

    nodes_a, vertices_a = used(first)
    nodes_b, vertices_b = used(second)
    return len(nodes_a & nodes_b), len(vertices_a & vertices_b)


def angle_range(tagged: meshes.TaggedMesh) -> tuple[float, float]:
    """Smallest and largest interior angle (degrees) over all cells of all ranks."""
    mesh = tagged.mesh
    nodes = np.asarray(compat.geometry_dofmap(mesh))
    if mesh.topology.cell_type == dolfinx.mesh.CellType.quadrilateral:
        nodes = nodes[:, [0, 1, 3, 2]]
    polygon = mesh.geometry.x[nodes][..., :2]
    incoming = polygon - np.roll(polygon, 1, axis=1)
    outgoing = np.roll(polygon, -1, axis=1) - polygon
    cross = incoming[..., 0] * outgoing[..., 1] - incoming[..., 1] * outgoing[..., 0]
    cross *= np.sign(cross.sum(axis=1))[:, None]  # counter-clockwise: convex corners > 0
    angles = np.degrees(np.arctan2(cross, -(incoming * outgoing).sum(axis=2)))
    smallest = mesh.comm.allreduce(angles.min(initial=180.0), op=MPI.MIN)
    largest = mesh.comm.allreduce(angles.max(initial=0.0), op=MPI.MAX)
    return smallest, largest


def half_disk_error(tagged: meshes.TaggedMesh, name: str) -> float:
    return 1.0 - area(tagged, name) / (0.5 * math.pi * R**2)


HERTZ_BLOCK = {"A": (2 * R, 0.5 * R), "B": (8 * R, 4 * R)}  # width, height


@pytest.mark.parallel
@pytest.mark.parametrize("case", ["A", "B", "C"])
def test_hertz_areas_lengths_and_convergence(case):
    coarse, fine = (meshes.hertz(case, refinement=r) for r in (0, 1))
    for tagged in (coarse, fine):
        assert tagged.mesh.topology.cell_type == dolfinx.mesh.CellType.triangle
        assert length(tagged, "load") == pytest.approx(2 * R, rel=1e-12)
        assert length(tagged, "symmetry_slave") == pytest.approx(R, rel=1e-12)
        if case == "C":
            assert length(tagged, "support") == pytest.approx(2 * R, rel=1e-12)
            assert length(tagged, "symmetry_master") == pytest.approx(R, rel=1e-12)
        else:
            width, height = HERTZ_BLOCK[case]
            assert area(tagged, "block") == pytest.approx(width * height, rel=1e-12)
            assert length(tagged, "contact_master") == pytest.approx(width, rel=1e-12)
            assert length(tagged, "support") == pytest.approx(width, rel=1e-12)
            assert length(tagged, "symmetry_master") == pytest.approx(height, rel=1e-12)

    # Polygons inscribed in the arcs: a little too small, converging like h^2.
    for body in ("cylinder", "block") if case == "C" else ("cylinder",):
        errors = [half_disk_error(t, body) for t in (coarse, fine)]
        assert 0 < errors[1] < 0.5 * errors[0] < 0.5e-2
    arcs = ["contact_slave", "contact_master"] if case == "C" else ["contact_slave"]
    for arc in arcs:
        errors = [1 - length(t, arc) / (math.pi * R) for t in (coarse, fine)]
        assert 0 < errors[1] < 0.5 * errors[0] < 0.5e-2


@pytest.mark.parallel
@pytest.mark.parametrize("cell_type", meshes.CELL_TYPES)
@pytest.mark.parametrize("case", ["A", "B", "C"])
def test_hertz_contact_zone_resolution(case, cell_type):
    """The contact surfaces have h_contact elements where the contact zone can reach."""
    a = meshes.hertz_half_width(case)
    sizes = {}
    for refinement in (0, 1):
        tagged = meshes.hertz(case, refinement=refinement, cell_type=cell_type)
        assert tagged.h_contact == pytest.approx(a / 5 / 2**refinement)
        for name in ("contact_slave", "contact_master"):
            segments = facet_segments(tagged, name)
            middle = np.abs(segments.mean(axis=1)[:, 0]) < 2.5 * a
            lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)[middle]
            comm = tagged.mesh.comm
            largest = comm.allreduce(lengths.max(initial=0.0), op=MPI.MAX)
            smallest = comm.allreduce(lengths.min(initial=np.inf), op=MPI.MIN)
            assert 0.6 * tagged.h_contact < smallest <= largest < 1.3 * tagged.h_contact
            assert comm.allreduce(len(lengths), op=MPI.SUM) >= 5 * 2.5 * 2**refinement
            sizes[refinement, name] = largest
    for name in ("contact_slave", "contact_master"):
        assert sizes[1, name] < 0.6 * sizes[0, name]


@pytest.mark.parametrize("case", ["B", "C"])
def test_hertz_slave_block_swaps_the_contact_and_symmetry_tags(case):
    """slave="block": the same mesh, with "contact_slave" on the lower body's surface
    and "symmetry_slave" on its symmetry line; the markers' values do not change."""
    cylinder, block = (meshes.hertz(case, slave=s, comm=MPI.COMM_SELF)
                       for s in ("cylinder", "block"))
    assert block.markers == cylinder.markers
    np.testing.assert_array_equal(cylinder.mesh.geometry.x, block.mesh.geometry.x)
    assert block.h_contact == cylinder.h_contact
    for role in ("contact", "symmetry"):
        slave, master = (cylinder.facet_tags.find(cylinder.markers[f"{role}_{side}"])
                         for side in ("slave", "master"))
        np.testing.assert_array_equal(block.facet_tags.find(block.markers[f"{role}_slave"]),
                                      master)
        np.testing.assert_array_equal(block.facet_tags.find(block.markers[f"{role}_master"]),
                                      slave)
    if case == "B":
        width, height = HERTZ_BLOCK[case]
        assert length(block, "contact_slave") == pytest.approx(width, rel=1e-12)
        assert length(block, "symmetry_slave") == pytest.approx(height, rel=1e-12)
        assert length(block, "symmetry_master") == pytest.approx(R, rel=1e-12)
        segments = facet_segments(block, "contact_slave")
        assert np.abs(segments[..., 1]).max() == 0.0


def test_hertz_cell_counts_stay_moderate():
    counts = [num_cells(meshes.hertz("B", refinement=r)) for r in (0, 1, 2)]
    assert counts[0] < counts[1] < counts[2] < 25_000


def test_hertz_radius_scales_the_geometry():
    tagged = meshes.hertz("C", radius=2.0)
    assert length(tagged, "load") == pytest.approx(4.0, rel=1e-12)
    assert area(tagged, "cylinder") == pytest.approx(2 * math.pi, rel=1e-2)
    assert tagged.h_contact == pytest.approx(0.7 * math.sqrt(2 / 8) / 5)


def test_hertz_half_width_sizes_the_refined_zone():
    """half_width replaces the benchmark's a: h_contact = a / 5 over |x| < 3a."""
    tagged = meshes.hertz("B", half_width=0.5, comm=MPI.COMM_SELF)
    assert tagged.h_contact == pytest.approx(0.1, rel=1e-12)
    segments = facet_segments(tagged, "contact_slave")
    middle = np.abs(segments.mean(axis=1)[:, 0]) < 1.25
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)[middle]
    assert 0.06 < lengths.min() <= lengths.max() < 0.13
    assert len(lengths) >= 20  # 2.5 a / h_contact = 12.5 on each side


@pytest.mark.parametrize("cell_type", meshes.CELL_TYPES)
@pytest.mark.parametrize("case", ["A", "B", "C"])
def test_hertz_mesh_scales_with_its_lengths(case, cell_type):
    """Radius and half-width times 1000: the same cells, coordinates times 1000 (to
    rounding), so a dimensionless problem does not depend on the unit of length."""
    a = 0.97 * meshes.hertz_half_width(case)
    small, large = (
        meshes.hertz(
            case, radius=8.0 * s, half_width=a * s, cell_type=cell_type, comm=MPI.COMM_SELF
        )
        for s in (1.0, 1e3)
    )
    assert large.h_contact == pytest.approx(1e3 * small.h_contact, rel=1e-12)
    cells = [np.asarray(compat.geometry_dofmap(t.mesh)) for t in (small, large)]
    np.testing.assert_array_equal(cells[0], cells[1])
    x_small, x_large = small.mesh.geometry.x, large.mesh.geometry.x
    assert np.abs(x_large - 1e3 * x_small).max() <= 1e-12 * 1e3 * np.abs(x_small).max()
    for name in ("contact_slave", "contact_master", "load", "support"):
        np.testing.assert_array_equal(
            small.facet_tags.find(small.markers[name]), large.facet_tags.find(large.markers[name])
        )


@pytest.mark.parallel
@pytest.mark.parametrize("ratio", [(3, 2), (1, 7)])
@pytest.mark.parametrize("refinement", [0, 1])
def test_patch_test_interface_counts_and_areas(ratio, refinement):
    tagged = meshes.patch_test(ratio=ratio, refinement=refinement)
    n_punch, n_foundation = (n * 2**refinement for n in ratio)
    assert count(tagged, "punch_contact") == n_punch
    assert count(tagged, "foundation_contact") == n_foundation
    assert area(tagged, "punch") == pytest.approx(4.0, rel=1e-12)
    assert area(tagged, "foundation") == pytest.approx(40.0, rel=1e-12)
    expected = {
        "punch_contact": 2.0,
        "foundation_contact": 2.0,
        "punch_top": 2.0,
        "foundation_top_free": 6.0,
        "foundation_bottom": 8.0,
    }
    for name, value in expected.items():
        assert length(tagged, name) == pytest.approx(value, rel=1e-12), name
    # Uniform spacing: the interface nodes are exactly at 4 + 2k/n on both sides.
    comm = tagged.mesh.comm
    for name, n in (("punch_contact", n_punch), ("foundation_contact", n_foundation)):
        segments = facet_segments(tagged, name)
        assert np.allclose(segments[..., 1], 5.0, atol=1e-14)
        xs = np.unique(np.concatenate(comm.allgather(segments[..., 0].ravel())).round(12))
        assert np.allclose(xs, np.linspace(4.0, 6.0, n + 1), atol=1e-12)
    # Foundation elements away from the punch are about square.
    cells = num_cells(tagged)
    square = 40.0 / (2.0 / n_foundation) ** 2 + 4.0 / (2.0 / n_punch) ** 2
    assert 0.8 * 2 * square < cells < 1.25 * 2 * square


@pytest.mark.parallel
def test_patch_test_slave_aliases():
    top = meshes.patch_test(ratio=(1, 7), slave="top")
    assert top.markers["contact_slave"] == top.markers["punch_contact"]
    assert top.markers["contact_master"] == top.markers["foundation_contact"]
    assert top.h_contact == pytest.approx(2.0)
    bottom = meshes.patch_test(ratio=(1, 7), slave="bottom")
    assert bottom.markers["contact_slave"] == bottom.markers["foundation_contact"]
    assert bottom.markers["contact_master"] == bottom.markers["punch_contact"]
    assert bottom.h_contact == pytest.approx(2.0 / 7)
    assert count(bottom, "contact_slave") == 7
    assert count(bottom, "contact_master") == 1
    values = set(np.unique(np.concatenate(bottom.mesh.comm.allgather(bottom.facet_tags.values))))
    assert len(values - {v for k, v in bottom.markers.items() if k.startswith("contact")}) == 3
    assert bottom.markers.keys() == top.markers.keys()


@pytest.mark.parallel
def test_ironing_geometry():
    radius, half_angle = 0.75, math.asin(0.6 / 0.75)
    segment = 0.5 * radius**2 * (2 * half_angle - math.sin(2 * half_angle))
    die_area = 1.2 * (5.4 - 4.5) + segment
    errors = []
    for refinement in (0, 1):
        tagged = meshes.ironing(refinement=refinement)
        assert tagged.h_contact == pytest.approx(0.05 / 2**refinement)
        assert area(tagged, "block") == pytest.approx(48.0, rel=1e-12)
        for name, value in {"block_contact": 12.0, "block_bottom": 12.0, "die_top": 1.2}.items():
            assert length(tagged, name) == pytest.approx(value, rel=1e-12), name
        arc = length(tagged, "die_contact")
        assert arc == pytest.approx(2 * half_angle * radius, rel=1e-3)
        errors.append(1 - area(tagged, "die") / die_area)
        segments = facet_segments(tagged, "die_contact")
        lowest = tagged.mesh.comm.allreduce(segments[..., 1].min(initial=np.inf), op=MPI.MIN)
        assert lowest == pytest.approx(4.2, abs=1e-12)
        block_top = facet_segments(tagged, "block_contact")
        sizes = np.linalg.norm(block_top[:, 1] - block_top[:, 0], axis=1)
        largest = tagged.mesh.comm.allreduce(sizes.max(initial=0.0), op=MPI.MAX)
        assert largest < 1.3 * 0.1 / 2**refinement
    assert 0 < errors[1] < 0.5 * errors[0] < 1e-2


@pytest.mark.parallel
def test_rings_geometry_and_gap():
    annulus = math.pi * (1.0**2 - 0.8**2)
    errors = {}
    for refinement in (0, 1):
        tagged = meshes.rings(refinement=refinement)
        assert tagged.h_contact == pytest.approx(0.2 / 8 / 2**refinement)
        for body in ("ring_top", "ring_bottom"):
            assert area(tagged, body) == pytest.approx(annulus, rel=1e-2)
        for name in ("ring_top_outer", "ring_bottom_outer"):
            errors[refinement, name] = 1 - length(tagged, name) / (2 * math.pi)
        for name in ("ring_top_inner", "ring_bottom_inner"):
            errors[refinement, name] = 1 - length(tagged, name) / (2 * math.pi * 0.8)
    # Area errors of the inscribed outer and inner polygons nearly cancel, so the
    # convergence is checked on the circle lengths.
    for key in [k for k in errors if k[0] == 0]:
        assert 0 < errors[1, key[1]] < 0.5 * errors[key] < 1e-2

    tagged = meshes.rings(gap=0.1, inner_radius=0.5, outer_radius=1.5)
    comm = tagged.mesh.comm
    top = facet_segments(tagged, "contact_slave")
    bottom = facet_segments(tagged, "contact_master")
    assert comm.allreduce(top[..., 1].min(initial=np.inf), op=MPI.MIN) == pytest.approx(0.05)
    assert comm.allreduce(bottom[..., 1].max(initial=-np.inf), op=MPI.MAX) == pytest.approx(-0.05)
    assert tagged.h_contact == pytest.approx(1.0 / 8)
    assert area(tagged, "ring_top") == pytest.approx(math.pi * (1.5**2 - 0.5**2), rel=1e-2)


@pytest.mark.parallel
@pytest.mark.parametrize("ratio, refinement", [((3, 4), 0), ((3, 4), 1), ((5, 2), 0)])
def test_tied_blocks(ratio, refinement):
    tagged = meshes.tied_blocks(ratio=ratio, refinement=refinement)
    n_lower, n_upper = (n * 2**refinement for n in ratio)
    assert count(tagged, "lower_interface") == n_lower
    assert count(tagged, "upper_interface") == n_upper
    assert tagged.markers["contact_slave"] == tagged.markers["upper_interface"]
    assert tagged.markers["contact_master"] == tagged.markers["lower_interface"]
    assert tagged.h_contact == pytest.approx(1.0 / n_upper)
    for body in ("lower", "upper"):
        assert area(tagged, body) == pytest.approx(0.5, rel=1e-12)
    assert length(tagged, "boundary") == pytest.approx(4.0, rel=1e-12)
    assert length(tagged, "lower_interface") == pytest.approx(1.0, rel=1e-12)
    assert length(tagged, "upper_interface") == pytest.approx(1.0, rel=1e-12)
    expected = 2 * (n_lower * max(1, round(n_lower / 2)) + n_upper * max(1, round(n_upper / 2)))
    assert num_cells(tagged) == expected


BODIES = {
    "hertz": ("cylinder", "block"),
    "patch_test": ("punch", "foundation"),
    "ironing": ("die", "block"),
    "rings": ("ring_top", "ring_bottom"),
    "tied_blocks": ("lower", "upper"),
}


def _build(name: str, **options) -> meshes.TaggedMesh:
    if name == "hertz":
        return meshes.hertz("C", **options)
    return meshes.BUILDERS[name](**options)


@pytest.mark.parallel
@pytest.mark.parametrize("name", sorted(BODIES))
def test_bodies_share_no_vertex(name):
    tagged = _build(name)
    first, second = BODIES[name]
    assert shared_nodes(tagged, first, second) == (0, 0)
    every_cell = np.concatenate([_cells(tagged, first), _cells(tagged, second)])
    local = tagged.mesh.topology.index_map(tagged.mesh.topology.dim).size_local
    assert np.array_equal(np.sort(every_cell), np.arange(local))
    assert tagged.markers["contact_slave"] != tagged.markers["contact_master"]


@pytest.mark.parallel
@pytest.mark.parametrize("name", sorted(BODIES))
def test_quadrilateral_variants(name):
    triangles = _build(name)
    quads = _build(name, cell_type="quadrilateral")
    assert quads.mesh.topology.cell_type == dolfinx.mesh.CellType.quadrilateral
    assert triangles.mesh.topology.cell_type == dolfinx.mesh.CellType.triangle
    smallest, largest = angle_range(quads)
    assert 25.0 < smallest and largest < 155.0
    smallest, largest = angle_range(triangles)
    assert 25.0 < smallest and largest < 125.0
    assert quads.markers == triangles.markers
    for body in BODIES[name]:
        assert area(quads, body) == pytest.approx(area(triangles, body), rel=1e-2)
    for tag in ("contact_slave", "contact_master"):
        assert length(quads, tag) == pytest.approx(length(triangles, tag), rel=1e-2)
    assert shared_nodes(quads, *BODIES[name]) == (0, 0)


def test_quadrilateral_structured_counts():
    tagged = meshes.patch_test(ratio=(1, 7), refinement=1, cell_type="quadrilateral")
    assert count(tagged, "punch_contact") == 2
    assert count(tagged, "foundation_contact") == 14
    assert num_cells(tagged) == 2 * 2 + (28 + 14 + 14) * 35


@pytest.mark.parametrize(
    "call",
    [
        lambda: meshes.hertz(refinement=-1),
        lambda: meshes.hertz(refinement=1.5),
        lambda: meshes.hertz(case="D"),
        lambda: meshes.hertz(radius=0.0),
        lambda: meshes.hertz(half_width=-1.0),
        lambda: meshes.hertz(half_width=float("nan")),
        lambda: meshes.hertz(cell_type="tetrahedron"),
        lambda: meshes.hertz(slave="master"),
        lambda: meshes.patch_test(ratio=(0, 2)),
        lambda: meshes.patch_test(ratio=(1, 2, 3)),
        lambda: meshes.patch_test(ratio=(1.5, 2)),
        lambda: meshes.patch_test(slave="left"),
        lambda: meshes.ironing(refinement=-2),
        lambda: meshes.ironing(cell_type="quad"),
        lambda: meshes.rings(inner_radius=1.0, outer_radius=1.0),
        lambda: meshes.rings(gap=-0.1),
        lambda: meshes.tied_blocks(ratio=(3, 0)),
        lambda: meshes.tied_blocks(refinement=-1),
    ],
)
def test_bad_parameters_raise_value_error(call):
    with pytest.raises(ValueError):
        call()


@pytest.mark.parallel
def test_repeated_calls_give_the_same_mesh():
    first, second = meshes.ironing(), meshes.ironing()
    assert num_cells(first) == num_cells(second)
    assert area(first, "die") == area(second, "die")


def test_running_gmsh_session_is_left_alone():
    gmsh = pytest.importorskip("gmsh")
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the gmsh session of the caller lives on one rank")
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("callers_model")
        gmsh.option.setNumber("Mesh.Algorithm", 5)
        tagged = meshes.tied_blocks()
        assert gmsh.isInitialized()
        assert gmsh.model.getCurrent() == "callers_model"
        assert gmsh.option.getNumber("Mesh.Algorithm") == 5
        assert area(tagged, "upper") == pytest.approx(0.5)
    finally:
        gmsh.finalize()


def test_command_line_writes_xdmf(tmp_path, capsys):
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("tmp_path differs between ranks")
    output = tmp_path / "out" / "rings.xdmf"
    meshes._main(
        ["rings", "--refinement", "0", "--cell-type", "quadrilateral", "--output", str(output)]
    )
    assert output.exists() and output.with_suffix(".h5").exists()
    assert '"contact_slave": 11' in output.with_suffix(".markers.json").read_text()
    assert "cells" in capsys.readouterr().out
    with dolfinx.io.XDMFFile(MPI.COMM_SELF, str(output), "r") as xdmf:
        mesh = xdmf.read_mesh(name="mesh")
        cell_tags = xdmf.read_meshtags(mesh, name="cell_tags")
    assert set(np.unique(cell_tags.values)) == {1, 2}
