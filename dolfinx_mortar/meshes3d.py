"""Builders of the 3D Hertz geometries: quarter models of a sphere on a block or a sphere.

Like :mod:`dolfinx_mortar.meshes`, touching bodies are separate meshes of one dolfinx
mesh (no shared node), each body one cell tag, the boundary pieces facet tags,
``contact_slave`` and ``contact_master`` aliases of two of them.
:func:`hertz_sphere` meshes the balls with tetrahedra: the gmsh model lives on rank 0
only and :func:`compat.model_to_mesh` distributes it; it is built with gmsh's
OpenCASCADE kernel, which keeps separately created volumes apart (no fragmenting).
:func:`hertz_sphere_hexahedral` builds structured hexahedral columns from graded
tensor-product grids (:func:`graded_nodes`, no gmsh) and merges them with
:func:`dolfinx_mortar.bodies.merge_meshes`.
"""

from __future__ import annotations

import math

import dolfinx.mesh
import numpy as np
from mpi4py import MPI

from dolfinx_mortar import compat, meshes
from dolfinx_mortar.bodies import merge_meshes
from dolfinx_mortar.meshes import TaggedMesh, _check_positive, _check_refinement

HERTZ_SPHERE_CASES = ("block", "sphere")
CELL_TYPES_3D = ("tetrahedron", "hexahedron")
"""Accepted values of :func:`hertz_sphere`'s ``case``."""

ELEMENTS_PER_RADIUS = 4
"""n0: the element size within the refined zone is a / (n0 2**refinement) (a the contact
radius), about n0 slave facets across the contact radius at refinement 0."""

GROWTH_3D = 0.5
"""Increase of the element size per unit distance beyond the refined zone, at refinement
0; level k uses GROWTH_3D / 2**k so that refining halves the element size everywhere."""

CAP_RADIUS = 0.5
"""Radius (over R) of the spherical caps that are the contact surfaces of the balls; the
rest of a ball's curved surface is the facet group "free" (no contact search there)."""

_OPTIONS = {
    "General.Terminal": 0,
    "Mesh.ElementOrder": 1,
    "Mesh.Algorithm": 6,
    "Mesh.Algorithm3D": 1,
    "Mesh.RecombineAll": 0,
    "Mesh.MeshSizeFromPoints": 0,
    "Mesh.MeshSizeFromCurvature": 0,
    "Mesh.MeshSizeExtendFromBoundary": 0,
    "Mesh.Optimize": 1,
}

_OCC_TOLERANCE = 1e-6
"""Absolute tolerance of the face classification: OCC pads bounding boxes."""


def _build_3d(comm: MPI.Comm, name: str, construct) -> compat.MeshWithTags:
    """``construct(gmsh)`` on rank 0 and the distributed volume mesh (:func:`meshes._build`)."""
    return meshes._build(comm, name, construct, gdim=3, options=_OPTIONS)


def _hertz_arguments(case, slave, refinement, elements_per_radius, radius, contact_radius,
                     block_size) -> tuple[int, int, float, float, float]:
    """Checked (level, n0, R, a / R, L / R) of the Hertz sphere builders."""
    if case not in HERTZ_SPHERE_CASES:
        raise ValueError(f"case must be one of {HERTZ_SPHERE_CASES}, got {case!r}")
    if slave not in ("sphere", "block"):
        raise ValueError(f"slave must be 'sphere' or 'block', got {slave!r}")
    level = _check_refinement(refinement)
    n0 = _check_refinement(elements_per_radius)
    if n0 < 1:
        raise ValueError(f"elements_per_radius must be >= 1, got {elements_per_radius!r}")
    unit = _check_positive("radius", radius)
    a = float(f"{_check_positive('contact_radius', contact_radius) / unit:.12g}")
    L = float(f"{_check_positive('block_size', block_size):.12g}")
    if not 1.5 * a < CAP_RADIUS:
        raise ValueError(f"contact_radius must be below {CAP_RADIUS / 1.5:.4g} R = "
                         f"{CAP_RADIUS / 1.5 * unit:.6g}, got {contact_radius!r}")
    return level, n0, unit, a, L


def _quarter_half_ball(occ, sign: float, cap: float, x0: float = 0.0) -> list[int]:
    """The quarter (x >= 0, y >= 0; with ``x0 = -1`` the half y >= 0) of the half ball of
    radius 1 centred at (0, 0, sign) on the side of z = 0, as two conforming volumes: the
    cap of radius CAP_RADIUS (height ``cap``) and the rest."""
    pieces = []
    for low, high in ((0.0, cap), (cap, 1.0)):
        ball = occ.addSphere(0.0, 0.0, sign, 1.0)
        z0 = low if sign > 0 else -high
        box = occ.addBox(x0, 0.0, z0, 1.0 - x0, 1.0, high - low)
        result, _ = occ.intersect([(3, ball)], [(3, box)])
        assert len(result) == 1, result
        pieces.append(result[0])
    result, _ = occ.fragment([pieces[0]], [pieces[1]])
    assert len(result) == 2, result
    return [tag for _, tag in result]


def _sphere_physical_groups(gmsh, upper: list[int], lower: list[int], names: list[str],
                            markers: dict[str, int], half: bool = False) -> None:
    """:func:`hertz_sphere`'s physical groups: each boundary face of the two bodies sorted
    by its bounding box and type (plane or not), checked against the expected count (no
    x = 0 plane in the ``half`` model)."""
    groups: dict[str, list[int]] = {name: [] for name in [*names[2:], "free"]}
    tol = _OCC_TOLERANCE
    for body, volumes in (("sphere", upper), ("block", lower)):
        boundary = gmsh.model.getBoundary([(3, v) for v in volumes], oriented=False)
        for _, face in boundary:
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, face)
            kind = gmsh.model.getType(2, face)
            if x1 - x0 < tol and abs(x0) < tol:
                groups["symmetry_x"].append(face)
            elif y1 - y0 < tol and abs(y0) < tol:
                groups["symmetry_y"].append(face)
            elif kind != "Plane":
                if min(abs(z0), abs(z1)) > tol:
                    groups["free"].append(face)
                else:
                    groups["sphere_surface" if body == "sphere" else "block_top"].append(face)
            elif body == "sphere":
                groups["load"].append(face)
            elif z1 - z0 < tol and abs(z1) < tol:
                groups["block_top"].append(face)
            elif z1 - z0 < tol:
                groups["support"].append(face)
    free = groups.pop("free")
    expected = {"sphere_surface": 1, "block_top": 1, "load": 1, "support": 1,
                "symmetry_x": 0 if half else len(upper) + len(lower),
                "symmetry_y": len(upper) + len(lower)}
    found = {name: len(faces) for name, faces in groups.items()}
    if found != expected:
        raise RuntimeError(f"unexpected faces of the model: {found}")
    gmsh.model.addPhysicalGroup(3, upper, markers["sphere"], name="sphere")
    gmsh.model.addPhysicalGroup(3, lower, markers["block"], name="block")
    if free:
        gmsh.model.addPhysicalGroup(2, free, markers["free"], name="free")
    for name, faces in groups.items():
        if faces:
            gmsh.model.addPhysicalGroup(2, faces, markers[name], name=name)


def _restricted(gmsh, size_field: int, volumes: list[int]) -> int:
    """A gmsh field equal to ``size_field`` in ``volumes`` and on their boundaries (faces,
    curves, points), and not elsewhere."""
    field = gmsh.model.mesh.field
    restricted = field.add("Restrict")
    field.setNumber(restricted, "InField", size_field)
    field.setNumbers(restricted, "VolumesList", volumes)
    entities = [(3, v) for v in volumes]
    for dim, key in ((2, "SurfacesList"), (1, "CurvesList"), (0, "PointsList")):
        entities = gmsh.model.getBoundary(entities, combined=False, oriented=False)
        entities = sorted({e for e in entities if e[0] == dim})
        field.setNumbers(restricted, key, [tag for _, tag in entities])
    return restricted


def _sphere_size_field(gmsh, upper: list[int], lower: list[int], h_contact: float,
                       h_max: float, zone: float, growth: float, ratio: float) -> None:
    """:func:`hertz_sphere`'s background size field: h_contact within ``zone`` of the
    contact point, growing by ``growth`` up to h_max beyond, ``ratio`` times that in the
    lower body (and the largest size of both there)."""
    tol = _OCC_TOLERANCE
    origins = [tag for _, tag in gmsh.model.getEntitiesInBoundingBox(
        -tol, -tol, -tol, tol, tol, tol, dim=0)]
    field = gmsh.model.mesh.field
    distance = field.add("Distance")
    field.setNumbers(distance, "PointsList", origins)

    def sizes(factor: float, volumes: list[int]) -> int:
        """The graded sizes times ``factor``, restricted to ``volumes`` and their
        boundaries."""
        threshold = field.add("Threshold")
        field.setNumber(threshold, "InField", distance)
        field.setNumber(threshold, "SizeMin", factor * h_contact)
        field.setNumber(threshold, "SizeMax", factor * h_max)
        field.setNumber(threshold, "DistMin", zone)
        field.setNumber(threshold, "DistMax",
                        zone + factor * max(h_max - h_contact, 0.0) / growth)
        return _restricted(gmsh, threshold, volumes)

    smallest = field.add("Min")
    field.setNumbers(smallest, "FieldsList", [sizes(1.0, upper), sizes(ratio, lower)])
    field.setAsBackgroundMesh(smallest)
    gmsh.option.setNumber("Mesh.MeshSizeMax", max(1.0, ratio) * h_max)
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)


def _sphere_model(gmsh, case: str, L: float, cap: float, names: list[str],
                  markers: dict[str, int], sizes: tuple[float, float, float, float],
                  ratio: float, half: bool = False) -> None:
    """:func:`hertz_sphere`'s gmsh model on rank 0: the two bodies (OCC), their physical
    groups, the size field (``sizes``: h_contact, h_max, the zone, the growth) and the
    tetrahedra."""
    occ = gmsh.model.occ
    x0 = -1.0 if half else 0.0
    upper = _quarter_half_ball(occ, 1.0, cap, x0)
    if case == "block":
        lower = [occ.addBox(x0 * L, 0.0, -L, (1.0 - x0) * L, L, L)]
    else:
        lower = _quarter_half_ball(occ, -1.0, cap, x0)
    occ.synchronize()
    _sphere_physical_groups(gmsh, upper, lower, names, markers, half)
    _sphere_size_field(gmsh, upper, lower, *sizes, ratio)
    gmsh.model.mesh.generate(3)
    types = set(gmsh.model.mesh.getElementTypes(3))
    if types != {4}:
        raise RuntimeError(f"gmsh produced element types {sorted(types)}, expected "
                           "only type 4 (tetrahedra)")


def hertz_sphere(
    case: str = "block",
    refinement: int = 0,
    radius: float = 1.0,
    contact_radius: float = 0.1,
    block_size: float = 1.0,
    slave: str = "sphere",
    elements_per_radius: int = ELEMENTS_PER_RADIUS,
    comm: MPI.Comm = MPI.COMM_WORLD,
    lower_size_ratio: float = 1.0,
    half: bool = False,
) -> TaggedMesh:
    """Quarter model (x >= 0, y >= 0) of a sphere pressed onto a block or onto a sphere;
    with ``half`` the half model y >= 0 (x in [-R, R], the block's x in [-L, L]), for
    loads that are not symmetric about x = 0 (a tangential force along x).

    The upper body is the lower half of the ball of radius R centred at (0, 0, R), cut to
    x, y >= 0: it touches z = 0 at the origin and carries the load on its flat face z = R.

    * case "block": on the block [0, L] x [0, L] x [-L, 0], L = ``block_size`` R.
    * case "sphere": on the mirror image, the upper half of the ball centred at
      (0, 0, -R), supported on its flat face z = -R. Its cell tag is "block" too, so
      solvers treat both cases alike.

    With a = ``contact_radius`` (pass the Hertz a of the actual load and moduli) the
    tetrahedra have size h_contact = a / (n0 2**refinement), n0 = ``elements_per_radius``,
    within the distance 1.5 a of the origin, growing linearly by
    GROWTH_3D / 2**refinement per unit distance beyond, up to h_max = R / (4 2**refinement).
    Every length is a multiple of R or a and the model is meshed at R = 1 and scaled, so
    the same dimensionless problem gets the same mesh in any unit system. The lower body's
    sizes are ``lower_size_ratio`` times these (non-matching contact meshes of a chosen
    size ratio; its largest size h_max times the ratio too).

    Args:
        case: "block" or "sphere".
        refinement: Halves the sizes per level.
        radius: Sphere radius R.
        contact_radius: Contact radius a that sizes the refined zone, below R/3 (the
            contact surfaces are the caps of radius CAP_RADIUS R = R/2).
        block_size: L / R of case "block".
        slave: "sphere" (the upper body's curved surface is the slave, default) or
            "block" (the lower body's contact surface is).
        elements_per_radius: n0.
        comm: Communicator of the mesh.
        lower_size_ratio: The lower body's element sizes over the upper body's, > 0.
        half: The half model y >= 0 (no "symmetry_x" facets) instead of the quarter.

    Returns:
        The mesh with cells "sphere", "block" and facets "sphere_surface" (the upper
        ball's cap x^2 + y^2 <= (R/2)^2), "block_top" (z = 0 of the block, or the lower
        ball's cap), "load" (z = R), "support" (z = -L or z = -R), "symmetry_x" (x = 0 of
        both bodies), "symmetry_y" (y = 0 of both bodies), "free" (the rest of the balls'
        curved surfaces); the aliases "contact_slave", "contact_master"; ``h_contact``
        is the nominal element size of the contact zone.
    """
    level, n0, unit, a, L = _hertz_arguments(case, slave, refinement, elements_per_radius,
                                             radius, contact_radius, block_size)
    ratio = _check_positive("lower_size_ratio", lower_size_ratio)
    cap = 1.0 - math.sqrt(1.0 - CAP_RADIUS**2)
    scale = 0.5**level
    h_contact = a / n0 * scale
    h_max = 0.25 * scale
    zone = 1.5 * a
    growth = GROWTH_3D * scale
    names = ["sphere", "block", "sphere_surface", "block_top", "load", "support",
             "symmetry_x", "symmetry_y", "free"]
    markers = {name: 1 + i if i < 2 else 9 + i for i, name in enumerate(names)}

    def construct(gmsh) -> None:
        _sphere_model(gmsh, case, L, cap, names, markers, (h_contact, h_max, zone, growth),
                      ratio, half)

    data = _build_3d(comm, f"hertz_sphere_{case}{'_half' if half else ''}", construct)
    if unit != 1.0:
        data.mesh.geometry.x[:] *= unit
    every = _with_contact_aliases({name: markers[name] for name in names}, slave)
    return TaggedMesh(data.mesh, data.cell_tags, data.facet_tags, every, h_contact * unit)


HEXAHEDRAL_GROWTH = 1.5
"""Size ratio of neighbouring cells beyond the refined zone of :func:`hertz_sphere_hexahedral`
(the same at every refinement, so that a level adds only a few graded cells)."""


def graded_nodes(length: float, h_fine: float, zone: float, ratio: float, h_max: float):
    """Node coordinates on [0, length]: cells of size ``h_fine`` up to ``zone``, then growing by
    ``ratio`` per cell up to ``h_max``; the graded part is shrunk to end at ``length``.

    Examples:
        Cells of 0.1 up to 0.3, then 0.2 and 0.4 (the largest allowed) scaled to end at 1:

        >>> graded_nodes(1.0, 0.1, 0.3, 2.0, 0.4)
        array([0.  , 0.1 , 0.2 , 0.3 , 0.44, 0.72, 1.  ])
    """
    n_fine = max(1, math.ceil(zone / h_fine - 1e-9))
    nodes = [i * h_fine for i in range(n_fine + 1)]
    h = h_fine
    while nodes[-1] < length:
        h = min(h * ratio, h_max)
        nodes.append(nodes[-1] + h)
    nodes = np.array(nodes)
    start = nodes[n_fine]
    if start >= length:
        return nodes[: n_fine + 1] * (length / start)
    nodes[n_fine:] = start + (nodes[n_fine:] - start) * (length - start) / (nodes[-1] - start)
    return nodes


def _with_contact_aliases(markers: dict[str, int], slave: str) -> dict[str, int]:
    """``markers`` with "contact_slave" and "contact_master", the sphere's cap and the
    block's top in the order ``slave`` ("sphere" or "block") says."""
    sides = ("sphere_surface", "block_top") if slave == "sphere" else ("block_top",
                                                                       "sphere_surface")
    markers["contact_slave"] = markers[sides[0]]
    markers["contact_master"] = markers[sides[1]]
    return markers


def _mapped_box(comm: MPI.Comm, x_nodes, y_nodes, z_nodes, place) -> dolfinx.mesh.Mesh:
    """create_box on the unit cube with the given node counts, its nodes moved to
    place(x, y, depth) of the node coordinates along each axis."""
    counts = [x_nodes.size - 1, y_nodes.size - 1, z_nodes.size - 1]
    box = dolfinx.mesh.create_box(comm, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], counts,
                                  dolfinx.mesh.CellType.hexahedron)
    x = box.geometry.x
    index = [np.rint(x[:, i] * counts[i]).astype(np.int64) for i in range(3)]
    x[:] = place(x_nodes[index[0]], y_nodes[index[1]], z_nodes[index[2]])
    return box


def _regrouped_facet_tags(merged: TaggedMesh, groups: dict[str, list[str]],
                          markers: dict[str, int]) -> dolfinx.mesh.MeshTags:
    """The facet tags of ``merged`` with the tags of each group's parts (names of
    ``merged.markers``) replaced by the group's marker, -1 for facets in no group."""
    old = merged.facet_tags
    values = np.full(old.values.shape, -1, dtype=np.int32)
    for name, parts in groups.items():
        for part in parts:
            values[old.values == merged.markers[part]] = markers[name]
    return dolfinx.mesh.meshtags(merged.mesh, 2, old.indices, values)


def hertz_sphere_hexahedral(
    case: str = "block",
    refinement: int = 0,
    radius: float = 1.0,
    contact_radius: float = 0.1,
    block_size: float = 1.0,
    slave: str = "sphere",
    elements_per_radius: int = ELEMENTS_PER_RADIUS,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TaggedMesh:
    """Structured hexahedral quarter model of :func:`hertz_sphere`'s problem.

    The upper body is the column [0, R/2]^2 whose bottom face is the sphere's surface
    z = R - sqrt(R^2 - x^2 - y^2) (the cap of radius R/2 around the contact point, as
    the tetrahedral model's contact surface) and whose top face z = R carries the load;
    case "block": the block [0, L]^2 x [-L, 0]; case "sphere": the column mirrored in
    z = 0. Each is a tensor-product grid: cells of size a / (n0 2**refinement) within
    1.5 a of the contact point along each axis (the depth measured from the curved face),
    growing by HEXAHEDRAL_GROWTH per cell beyond, up to R / 4. Hertz theory sees only the
    curvature at the contact and the bodies' elasticity; the column differs from the
    ball away from the contact zone. Same groups and aliases as :func:`hertz_sphere`.
    """
    level, n0, unit, a, L = _hertz_arguments(case, slave, refinement, elements_per_radius,
                                             radius, contact_radius, block_size)
    h_contact = a / n0 * 0.5**level
    h_max = 0.25

    def axis(length: float):
        return graded_nodes(length, h_contact, 1.5 * a, HEXAHEDRAL_GROWTH, h_max)

    def surface(x, y):
        return 1.0 - np.sqrt(1.0 - x**2 - y**2)

    def column(sign: float):
        """The column on the side sign of z = 0; depth 0 on its curved face."""
        nodes = axis(CAP_RADIUS)

        def place(x, y, depth):
            s = surface(x, y)
            return np.column_stack([x, y, sign * (s + depth * (1.0 - s))])

        return _mapped_box(comm, nodes, nodes, axis(1.0), place)

    tol = 1e-9
    on_plane = {
        "symmetry_x": lambda x: np.abs(x[0]) < tol,
        "symmetry_y": lambda x: np.abs(x[1]) < tol,
    }
    upper = (column(1.0), {
        "surface": lambda x: np.abs(x[2] - surface(x[0], x[1])) < tol,
        "load": lambda x: np.abs(x[2] - 1.0) < tol, **on_plane})
    if case == "block":
        nodes = axis(L)
        lower_mesh = _mapped_box(comm, nodes, nodes, axis(L),
                                 lambda x, y, depth: np.column_stack([x, y, -depth]))
        lower = (lower_mesh, {"surface": lambda x: np.abs(x[2]) < tol,
                              "support": lambda x: np.abs(x[2] + L) < tol, **on_plane})
    else:
        lower = (column(-1.0), {
            "surface": lambda x: np.abs(x[2] + surface(x[0], x[1])) < tol,
            "support": lambda x: np.abs(x[2] + 1.0) < tol, **on_plane})
    merged = merge_meshes({"sphere": upper, "block": lower}, comm)
    # one tag per group across both bodies, named as hertz_sphere names them
    groups = {"sphere_surface": ["sphere_surface"], "block_top": ["block_surface"],
              "load": ["sphere_load"], "support": ["block_support"],
              "symmetry_x": ["sphere_symmetry_x", "block_symmetry_x"],
              "symmetry_y": ["sphere_symmetry_y", "block_symmetry_y"]}
    names = ["sphere", "block", *groups]
    markers = {name: 1 + i if i < 2 else 9 + i for i, name in enumerate(names)}
    facet_tags = _regrouped_facet_tags(merged, groups, markers)
    if unit != 1.0:
        merged.mesh.geometry.x[:] *= unit
    markers = _with_contact_aliases(markers, slave)
    return TaggedMesh(merged.mesh, merged.cell_tags, facet_tags, markers, h_contact * unit)


def _tube_groups(gmsh, ring: list[int], plates: dict[str, int], length: float,
                 r_in: float, markers: dict[str, int]) -> None:
    """:func:`crushed_tube`'s physical groups: each boundary face of the ring (its two
    halves as one body: the face y = 0 between them is inside) and of the plates sorted by
    its bounding box, checked against the expected count."""
    tol = _OCC_TOLERANCE
    groups: dict[str, list[int]] = {name: [] for name in markers if markers[name] > 10}
    free: list[int] = []
    bodies = [("ring", ring)] + [(f"plate_{name}", [v]) for name, v in plates.items()]
    for body, volumes in bodies:
        boundary = gmsh.model.getBoundary([(3, v) for v in volumes], combined=True,
                                          oriented=False)
        for _, face in boundary:
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, face)
            if x1 - x0 < tol and abs(x0) < tol:
                groups["symmetry"].append(face)
            elif z1 - z0 < tol and (abs(z0) < tol or abs(z0 - length) < tol):
                groups["ends"].append(face)
            elif body == "ring":
                side = "top" if y0 > -tol else "bottom"
                groups["ring_inner" if x1 < r_in + tol else f"ring_outer_{side}"].append(face)
            elif y1 - y0 < tol:
                near = min(abs(y0), abs(y1)) < 1.1  # the face at |y| = R, else 1.2 R
                far = "load" if body == "plate_top" else "support"
                groups[f"{body}_contact" if near else f"{body}_{far}"].append(face)
            else:
                free.append(face)  # the plates' far ends x = 1.6 R
    expected = {"ring_outer_top": 1, "ring_outer_bottom": 1, "ring_inner": 2,
                "plate_top_contact": 1, "plate_bottom_contact": 1, "plate_top_load": 1,
                "plate_bottom_support": 1, "symmetry": 4, "ends": 8}
    found = {name: len(faces) for name, faces in groups.items()}
    if found != expected or len(free) != 2:
        raise RuntimeError(f"unexpected faces of the tube model: {found}, {len(free)} free")
    gmsh.model.addPhysicalGroup(3, ring, markers["ring"], name="ring")
    for name, volume in plates.items():
        gmsh.model.addPhysicalGroup(3, [volume], markers[f"plate_{name}"], name=f"plate_{name}")
    for name, faces in groups.items():
        gmsh.model.addPhysicalGroup(2, faces, markers[name], name=name)


def crushed_tube(refinement: int = 0, inner_radius: float = 0.7, outer_radius: float = 1.0,
                 length: float | None = None, comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """A slice of half a tube (x >= 0, axis z) between two plates that touch it at
    (0, +-outer_radius, z): ``demos/self_contact.py --dim 3 --case crush``, the 3D twin of
    :func:`meshes.crushed_ring` (the plane x = 0 a symmetry plane; the ends z = 0 and
    z = ``length`` are to be held in z, so that the slice behaves as a long tube's).

    The slice is ``length`` long (default: the wall thickness); the plates are
    [0, 1.6 R] x [R, 1.2 R] x [0, length] and its mirror in y = 0. The ring is two
    volumes, its halves above and below y = 0, meshed conformingly (so that its outer
    surface splits at y = 0 into the two plates' slave surfaces). Its cross-section is
    meshed with triangles of size h_ring = thickness / 4 (over 2**refinement) and swept
    along z in layers of about h_ring, each prism cut into tetrahedra: every layer the
    same, as the solution of a slice held at its ends does not vary along z (free
    tetrahedra made the fold where the inner walls close wave along z, and left a node
    there 0.11 facet lengths behind the other wall instead of 0.0072, docs/benchmarks.md).
    The plates are free tetrahedra of size 2 h_ring.

    Returns:
        Cells "ring", "plate_top", "plate_bottom"; facets "ring_outer_top",
        "ring_outer_bottom" (the outer cylinder above and below y = 0), "ring_inner" (the
        whole inner cylinder: the self-contact surface), "plate_top_contact",
        "plate_bottom_contact", "plate_top_load" (the top plate's upper face),
        "plate_bottom_support", "symmetry" (every face on x = 0), "ends" (every face on
        z = 0 or z = length); ``h_contact`` = h_ring.
    """
    level = _check_refinement(refinement)
    r_in = _check_positive("inner_radius", inner_radius)
    r_out = _check_positive("outer_radius", outer_radius)
    if r_in >= r_out:
        raise ValueError(f"inner_radius {inner_radius} must be below outer_radius {outer_radius}")
    thickness = r_out - r_in
    L = thickness if length is None else _check_positive("length", length)
    h_ring = thickness / 4.0 * 0.5**level
    names_cells = ["ring", "plate_top", "plate_bottom"]
    names_facets = ["ring_outer_top", "ring_outer_bottom", "ring_inner", "plate_top_contact",
                    "plate_bottom_contact", "plate_top_load", "plate_bottom_support",
                    "symmetry", "ends"]
    markers = meshes._numbered(names_cells, names_facets)

    def construct(gmsh) -> None:
        occ = gmsh.model.occ
        halves = []
        for y0 in (0.0, -2.0 * r_out):  # the cross-section's halves above and below y = 0
            outer = occ.addDisk(0.0, 0.0, 0.0, r_out, r_out)
            hole = occ.addDisk(0.0, 0.0, 0.0, r_in, r_in)
            annulus, _ = occ.cut([(2, outer)], [(2, hole)])
            quarter = occ.addRectangle(0.0, y0, 0.0, 2.0 * r_out, 2.0 * r_out)
            result, _ = occ.intersect(annulus, [(2, quarter)])
            assert len(result) == 1, result
            halves.append(result[0])
        result, _ = occ.fragment([halves[0]], [halves[1]])
        assert len(result) == 2, result

        def extruded(surfaces, size):
            """The volumes swept by ``surfaces`` along z in layers of about ``size``: the
            cross-section's mesh repeated, each prism cut into tetrahedra."""
            layers = max(1, round(L / size))
            swept = occ.extrude(surfaces, 0.0, 0.0, L, numElements=[layers], recombine=False)
            return [tag for dim, tag in swept if dim == 3]

        ring = extruded(result, h_ring)
        plates = {"top": occ.addBox(0.0, r_out, 0.0, 1.6 * r_out, 0.2 * r_out, L),
                  "bottom": occ.addBox(0.0, -1.2 * r_out, 0.0, 1.6 * r_out, 0.2 * r_out, L)}
        occ.synchronize()
        _tube_groups(gmsh, ring, plates, L, r_in, markers)
        field = gmsh.model.mesh.field
        sizes = []
        for size, volumes in ((h_ring, ring), (2.0 * h_ring, list(plates.values()))):
            constant = field.add("MathEval")
            field.setString(constant, "F", f"{size!r}")
            sizes.append(_restricted(gmsh, constant, volumes))
        smallest = field.add("Min")
        field.setNumbers(smallest, "FieldsList", sizes)
        field.setAsBackgroundMesh(smallest)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 2.0 * h_ring)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
        gmsh.model.mesh.generate(3)
        types = set(gmsh.model.mesh.getElementTypes(3))
        if types != {4}:
            raise RuntimeError(f"gmsh produced element types {sorted(types)}, expected "
                               "only type 4 (tetrahedra)")

    data = _build_3d(comm, "crushed_tube", construct)
    return TaggedMesh(data.mesh, data.cell_tags, data.facet_tags, markers, h_ring)
