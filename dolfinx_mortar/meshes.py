"""Builders of the benchmark geometries: gmsh for the 2D ones (Hertz, patch test, ironing,
rings, tied blocks); structured boxes and extrusions for the 3D patch test and ironing.

Every geometry is built here from a few numbers, so no geometry file is needed: the
gmsh model lives on rank 0 only and :func:`compat.model_to_mesh` distributes it.

Bodies that touch are separate meshes inside one dolfinx mesh: their boundaries may
have nodes at the same coordinates but never share a node, a facet or a cell, which is
what a contact (or mortar tying) formulation expects. Each body is one cell tag; the
boundary pieces the solvers need are facet tags. ``markers`` maps their names to tag
values; ``contact_slave`` and ``contact_master`` are aliases of two of those names
(same value, not extra facets), so a solver can be written once for every benchmark.

``refinement`` halves the mesh size at the contact surfaces (and the coarsest size far
away) per level. Graded meshes keep a fixed growth rate of the element size with the
distance from the contact surfaces, so their fine layer thins with refinement and the
cell count grows by about 2 to 4 per level rather than by 4. Structured meshes
(``patch_test``, ``tied_blocks``) double the element count along every side.

Run ``python3 -m dolfinx_mortar.meshes NAME --output meshes/NAME.xdmf`` to export a
mesh with its tags for ParaView.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import operator
import pathlib
from collections.abc import Callable, Sequence
from typing import NamedTuple

import basix.ufl
import dolfinx
import dolfinx.io
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx_mortar import compat
from dolfinx_mortar.bodies import TaggedMesh, merge_meshes

CELL_TYPES = ("triangle", "quadrilateral")
"""Accepted values of every builder's ``cell_type``."""

HERTZ_CASES = ("A", "B", "C")
"""Accepted values of :func:`hertz`'s ``case``."""

HERTZ_SLAVES = ("cylinder", "block")
"""Accepted values of :func:`hertz`'s ``slave``: the upper cylinder or the lower body."""

GROWTH = 0.25
"""Increase of the element size per unit distance from a refined curve (graded meshes),
at refinement 0; level k uses GROWTH / 2**k, so that refining halves the element size
everywhere (a fixed growth rate would leave the elements at a given distance from the
contact unrefined, and errors would stall: Hertz p_max stayed 1 % off from level 1 to 4)."""

_HERTZ_RADIUS = 8.0
"""Radius at which :func:`hertz` builds its gmsh model, before scaling to the given radius."""

_HERTZ_HALF_WIDTH = {"A": 0.39, "B": 1.0, "C": 0.7}
"""Contact half-width a of the Hertz cases at radius 8 (it scales with sqrt(radius))."""


# ---------------------------------------------------------------------------------------
# Parameter checks. They run on every rank before gmsh starts, so a bad argument raises
# the same ValueError everywhere instead of leaving the other ranks waiting for a mesh.


def _check_refinement(refinement: int) -> int:
    try:
        value = operator.index(refinement)
    except TypeError:
        raise ValueError(f"refinement must be an integer, got {refinement!r}") from None
    if isinstance(refinement, bool) or value < 0:
        raise ValueError(f"refinement must be a non-negative integer, got {refinement!r}")
    return value


def _check_cell_type(cell_type: str) -> bool:
    if cell_type not in CELL_TYPES:
        raise ValueError(f"cell_type must be one of {CELL_TYPES}, got {cell_type!r}")
    return cell_type == "quadrilateral"


def _check_ratio(ratio: Sequence[int]) -> tuple[int, int]:
    try:
        values = tuple(ratio)
    except TypeError:
        raise ValueError(f"ratio must be a pair of integers >= 1, got {ratio!r}") from None
    if len(values) != 2:
        raise ValueError(f"ratio must be a pair of integers >= 1, got {ratio!r}")
    checked = []
    for value in values:
        try:
            number = operator.index(value)
        except TypeError:
            raise ValueError(f"ratio must be a pair of integers >= 1, got {ratio!r}") from None
        if isinstance(value, bool) or number < 1:
            raise ValueError(f"ratio must be a pair of integers >= 1, got {ratio!r}")
        checked.append(number)
    return checked[0], checked[1]


def _check_positive(name: str, value: float) -> float:
    number = float(value)
    if not math.isfinite(number) or number <= 0.0:
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    return number


# ---------------------------------------------------------------------------------------
# gmsh plumbing, used on rank 0 only.


class _Model:
    """The geometry of one builder, written with gmsh's built-in kernel.

    The built-in kernel keeps points at equal coordinates distinct (with
    ``Geometry.AutoCoherence`` off), which is how touching bodies stay separate meshes.
    """

    def __init__(self, gmsh) -> None:
        self.gmsh = gmsh
        self.geo = gmsh.model.geo
        self._refined: list[tuple[list[int], float, float]] = []
        self._transfinite: list[int] = []

    def point(self, x: float, y: float) -> int:
        return self.geo.addPoint(x, y, 0.0)

    def line(self, start: int, end: int, nodes: int | None = None) -> int:
        """A straight curve; ``nodes`` makes it transfinite with that many nodes."""
        tag = self.geo.addLine(start, end)
        if nodes is not None:
            self.geo.mesh.setTransfiniteCurve(tag, nodes)
        return tag

    def arc(self, start: int, centre: int, end: int) -> int:
        """The circular arc (less than half a circle) from ``start`` to ``end``."""
        return self.geo.addCircleArc(start, centre, end)

    def surface(
        self,
        curves: Sequence[int],
        transfinite: bool = False,
        holes: Sequence[Sequence[int]] = (),
    ) -> int:
        """The plane surface bounded by ``curves`` minus ``holes`` (curves in any order)."""
        loops = [self.geo.addCurveLoop(list(c), reorient=True) for c in (curves, *holes)]
        tag = self.geo.addPlaneSurface(loops)
        if transfinite:
            self.geo.mesh.setTransfiniteSurface(tag)
            self._transfinite.append(tag)
        return tag

    def refine_near(self, curves: Sequence[int], size: float, growth: float) -> None:
        """Ask for element size ``size`` on ``curves``, growing by ``growth`` per unit distance."""
        self._refined.append((list(curves), size, growth))

    def mesh(
        self,
        cells: dict[int, list[int]],
        facets: dict[int, list[int]],
        names: dict[int, str],
        h_max: float,
        quadrilateral: bool,
    ) -> None:
        """Synchronise, tag and mesh the model.

        Args:
            cells: Tag value to the surfaces of one body.
            facets: Tag value to the curves of one facet group.
            names: Tag value to name, for the physical groups (read by ParaView users).
            h_max: Largest element size anywhere.
            quadrilateral: Recombine into quadrilaterals.
        """
        gmsh = self.gmsh
        if quadrilateral:
            for surface in self._transfinite:
                self.geo.mesh.setRecombine(2, surface)
        self.geo.synchronize()
        for tag, surfaces in cells.items():
            gmsh.model.addPhysicalGroup(2, surfaces, tag, name=names[tag])
        for tag, curves in facets.items():
            gmsh.model.addPhysicalGroup(1, curves, tag, name=names[tag])

        field = gmsh.model.mesh.field
        thresholds = []
        for curves, size, growth in self._refined:
            distance = field.add("Distance")
            field.setNumbers(distance, "CurvesList", curves)
            length = sum(_curve_length(gmsh, c) for c in curves)
            field.setNumber(distance, "Sampling", max(20, math.ceil(4.0 * length / size)))
            threshold = field.add("Threshold")
            field.setNumber(threshold, "InField", distance)
            field.setNumber(threshold, "SizeMin", size)
            field.setNumber(threshold, "SizeMax", h_max)
            field.setNumber(threshold, "DistMin", 0.0)
            field.setNumber(threshold, "DistMax", max(h_max - size, 0.0) / growth)
            thresholds.append(threshold)
        if thresholds:
            smallest = field.add("Min")
            field.setNumbers(smallest, "FieldsList", thresholds)
            field.setAsBackgroundMesh(smallest)

        gmsh.option.setNumber("Mesh.MeshSizeMax", h_max)
        if quadrilateral:
            # Blossom leaves triangles; Frontal-Delaunay triangles, "simple full-quad"
            # recombination and smoothing give only quadrilaterals, with angles between
            # about 30 and 145 degrees on gmsh 4.13 and 4.15.
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 2)
            gmsh.option.setNumber("Mesh.Smoothing", 10)
        gmsh.model.mesh.generate(2)

        wanted = 3 if quadrilateral else 2
        types = set(gmsh.model.mesh.getElementTypes(2))
        if types != {wanted}:
            raise RuntimeError(
                f"gmsh produced element types {sorted(types)}, expected only type {wanted} "
                f"({'quadrilaterals' if quadrilateral else 'triangles'})"
            )


def _curve_length(gmsh, curve: int) -> float:
    """Arc length of a model curve, for the sampling density of distance fields."""
    low, high = gmsh.model.getParametrizationBounds(1, curve)
    samples = 64
    parameters = [low[0] + (high[0] - low[0]) * i / samples for i in range(samples + 1)]
    xyz = gmsh.model.getValue(1, curve, parameters)
    return sum(
        math.dist(xyz[3 * i : 3 * i + 2], xyz[3 * i + 3 : 3 * i + 5]) for i in range(samples)
    )


_OPTIONS = {
    "General.Terminal": 0,
    "Geometry.AutoCoherence": 0,
    "Mesh.ElementOrder": 1,
    "Mesh.Algorithm": 6,
    "Mesh.RecombineAll": 0,
    "Mesh.MeshSizeFromPoints": 0,
    "Mesh.MeshSizeFromCurvature": 0,
    "Mesh.MeshSizeExtendFromBoundary": 0,
}


def _build(
    comm: MPI.Comm,
    name: str,
    construct: Callable,
    gdim: int = 2,
    options: dict[str, float] | None = None,
) -> compat.MeshWithTags:
    """Run ``construct`` on rank 0 inside a fresh gmsh model and distribute the mesh.

    ``construct`` gets a :class:`_Model` in 2D and the ``gmsh`` module in 3D; ``options``
    (default the 2D builders') are set for the call. gmsh is initialised (quietly) for
    this call and finalised afterwards; if the caller already has gmsh running, a
    separate model is used and removed, and the options touched here are restored, so
    the caller's gmsh state is left as it was.
    """
    options = _OPTIONS if options is None else options
    model = None
    error: str | None = None
    own_session = False
    saved: dict[str, float] = {}
    gmsh = None
    if comm.rank == 0:
        import gmsh

        own_session = not gmsh.isInitialized()
        if own_session:
            gmsh.initialize(argv=["dolfinx_mortar"], readConfigFiles=False, interruptible=False)
            gmsh.option.setNumber("General.Terminal", 0)
        previous = None if own_session else gmsh.model.getCurrent()
        try:
            for option, value in options.items():
                saved[option] = gmsh.option.getNumber(option)
                gmsh.option.setNumber(option, value)
            for option in ("Mesh.MeshSizeMax", "Mesh.MeshSizeMin", "Mesh.RecombinationAlgorithm",
                           "Mesh.Smoothing"):
                saved[option] = gmsh.option.getNumber(option)
            gmsh.model.add(f"dolfinx_mortar_{name}")
            construct(_Model(gmsh) if gdim == 2 else gmsh)
            model = gmsh.model
        except Exception as exception:  # reported on every rank below
            error = f"{type(exception).__name__}: {exception}"

    def close() -> None:
        if comm.rank != 0:
            return
        if own_session:
            gmsh.finalize()
            return
        gmsh.model.remove()
        for option, value in saved.items():
            gmsh.option.setNumber(option, value)
        if previous:
            gmsh.model.setCurrent(previous)

    error = comm.bcast(error, root=0)
    if error is not None:
        close()
        raise RuntimeError(f"building the {name} mesh with gmsh failed: {error}")
    try:
        return compat.model_to_mesh(model, comm, 0, gdim=gdim)
    finally:
        close()


def _tagged(
    data: compat.MeshWithTags,
    markers: dict[str, int],
    aliases: dict[str, str],
    h_contact: float,
) -> TaggedMesh:
    every = dict(markers)
    for alias, target in aliases.items():
        every[alias] = markers[target]
    return TaggedMesh(data.mesh, data.cell_tags, data.facet_tags, every, h_contact)


def _numbered(cells: Sequence[str], facets: Sequence[str]) -> dict[str, int]:
    """Tag values: bodies from 1, facet groups from 11, so no value means two things."""
    values = {name: 1 + i for i, name in enumerate(cells)}
    values.update({name: 11 + i for i, name in enumerate(facets)})
    return values


def _names(markers: dict[str, int]) -> dict[int, str]:
    return {value: name for name, value in markers.items()}


# ---------------------------------------------------------------------------------------
# Builders.


def hertz_half_width(case: str, radius: float = 8.0) -> float:
    """Nominal contact half-width a of a Hertz case, which sets its refined zone.

    The values (0.39, 1.0, 0.7 at radius 8 for cases A, B, C) are those of the
    benchmark loads; a grows like sqrt(radius) at fixed load and moduli.

    Examples:
        >>> hertz_half_width("A"), hertz_half_width("B"), hertz_half_width("B", radius=32.0)
        (0.39, 1.0, 2.0)
    """
    if case not in HERTZ_CASES:
        raise ValueError(f"case must be one of {HERTZ_CASES}, got {case!r}")
    return _HERTZ_HALF_WIDTH[case] * math.sqrt(_check_positive("radius", radius) / 8.0)


class _HertzSizes(NamedTuple):
    """The lengths of :func:`hertz`'s model, in the units of R = 8 where it is meshed."""

    R: float
    x_zone: float
    h_contact: float
    h_arc: float
    h_max: float
    growth: float


def _hertz_sizes(case: str, level: int, radius: float, half_width: float | None):
    """(unit, sizes): the model is meshed at R = 8 and scaled by ``unit`` afterwards."""
    R = _check_positive("radius", radius)
    a = hertz_half_width(case, R)  # also checks case
    if half_width is not None:
        a = _check_positive("half_width", half_width)
    # gmsh's output is not similar under a change of units (absolute tolerances, rounding),
    # so the model is always built at R = 8 and the coordinates scaled afterwards; a/R is
    # rounded so that the same ratio in other units gives gmsh identical input
    unit = R / _HERTZ_RADIUS
    R = _HERTZ_RADIUS
    a = float(f"{a / unit:.12g}")
    scale = 0.5**level
    sizes = _HertzSizes(R=R, x_zone=min(3.0 * a, 0.5 * R), h_contact=a / 5.0 * scale,
                        h_arc=R / 8.0 * scale, h_max=R / 2.0 * scale, growth=GROWTH * scale)
    return unit, sizes


def _hertz_half_disk(m: _Model, sign: float, sizes: _HertzSizes) -> dict[str, list[int]]:
    """Half disk centred at (0, sign R) whose arc passes through the origin."""
    R, x_zone = sizes.R, sizes.x_zone
    y_zone = sign * (R - math.sqrt(R * R - x_zone * x_zone))
    centre = m.point(0.0, sign * R)
    left, right = m.point(-R, sign * R), m.point(R, sign * R)
    zone_left, zone_right = m.point(-x_zone, y_zone), m.point(x_zone, y_zone)
    origin = m.point(0.0, 0.0)
    arcs = [
        m.arc(left, centre, zone_left),
        m.arc(zone_left, centre, origin),
        m.arc(origin, centre, zone_right),
        m.arc(zone_right, centre, right),
    ]
    flats = [m.line(left, centre), m.line(centre, right)]
    symmetry = m.line(origin, centre)
    surfaces = [
        m.surface([arcs[0], arcs[1], symmetry, flats[0]]),
        m.surface([arcs[2], arcs[3], flats[1], symmetry]),
    ]
    m.refine_near(arcs[1:3], sizes.h_contact, sizes.growth)
    m.refine_near(arcs + flats, sizes.h_arc, sizes.growth)
    return {"surfaces": surfaces, "arc": arcs, "flat": flats, "symmetry": [symmetry]}


def _hertz_block(m: _Model, half_width: float, height: float,
                 sizes: _HertzSizes) -> dict[str, list[int]]:
    """The block [-half_width, half_width] x [-height, 0], split at x = 0."""
    x_zone = sizes.x_zone
    top = [m.point(x, 0.0) for x in (-half_width, -x_zone, 0.0, x_zone, half_width)]
    bottom = [m.point(x, -height) for x in (-half_width, 0.0, half_width)]
    top_lines = [m.line(p, q) for p, q in itertools.pairwise(top)]
    bottom_lines = [m.line(bottom[0], bottom[1]), m.line(bottom[1], bottom[2])]
    symmetry = m.line(top[2], bottom[1])
    sides = [m.line(bottom[0], top[0]), m.line(top[4], bottom[2])]
    surfaces = [
        m.surface([*top_lines[:2], symmetry, bottom_lines[0], sides[0]]),
        m.surface([*top_lines[2:], sides[1], bottom_lines[1], symmetry]),
    ]
    m.refine_near(top_lines[1:3], sizes.h_contact, sizes.growth)
    return {
        "surfaces": surfaces,
        "top": top_lines,
        "bottom": bottom_lines,
        "symmetry": [symmetry],
    }


def _hertz_model(m: _Model, case: str, slave: str, sizes: _HertzSizes,
                 markers: dict[str, int], quadrilateral: bool) -> None:
    """:func:`hertz`'s gmsh model on rank 0: the two bodies with their size fields, then
    the physical groups (which side is the slave decides which arc or top gets which tag)."""
    R = sizes.R
    upper = _hertz_half_disk(m, 1.0, sizes)
    if case == "C":
        lower = _hertz_half_disk(m, -1.0, sizes)
        lower_contact, support = lower["arc"], lower["flat"]
    else:
        size = (R, 0.5 * R) if case == "A" else (4.0 * R, 4.0 * R)
        lower = _hertz_block(m, *size, sizes)
        lower_contact, support = lower["top"], lower["bottom"]
    sides = [(upper["arc"], upper["symmetry"]), (lower_contact, lower["symmetry"])]
    if slave == "block":
        sides.reverse()
    (slave_contact, slave_symmetry), (master_contact, master_symmetry) = sides
    m.mesh(
        cells={markers["cylinder"]: upper["surfaces"], markers["block"]: lower["surfaces"]},
        facets={
            markers["contact_slave"]: slave_contact,
            markers["contact_master"]: master_contact,
            markers["load"]: upper["flat"],
            markers["support"]: support,
            markers["symmetry_slave"]: slave_symmetry,
            markers["symmetry_master"]: master_symmetry,
        },
        names=_names(markers),
        h_max=sizes.h_max,
        quadrilateral=quadrilateral,
    )


def hertz(
    case: str = "B",
    refinement: int = 0,
    radius: float = 8.0,
    cell_type: str = "triangle",
    comm: MPI.Comm = MPI.COMM_WORLD,
    half_width: float | None = None,
    slave: str = "cylinder",
) -> TaggedMesh:
    """Plane-strain Hertz contact: a half-cylinder pressed onto a block or a half-cylinder.

    The upper body is the lower half of the disk of radius R centred at (0, R): it
    touches y = 0 at the origin and carries the load on its flat face y = R.

    * case "A": on a plate [-R, R] x [-R/2, 0] standing for a near-rigid body (a = 0.39).
    * case "B": on an elastic block [-4R, 4R] x [-4R, 0], much larger than a = 1.
    * case "C": on the upper half of the disk of radius R centred at (0, -R), supported
      on its flat face y = -R (a = 0.7). The cell tag "cylinder" is the upper body and
      "block" the lower half-cylinder, so solvers treat all cases alike.

    Every body is split by the line x = 0 (tagged ``symmetry_slave`` in the slave's
    body, ``symmetry_master`` in the master's) so a solver can stop rigid horizontal
    motion there. With a = ``half_width`` (by default :func:`hertz_half_width`), the element
    size is h_contact = a/5 (0.078, 0.2, 0.14 for A, B, C at R = 8 by default) on both
    contact surfaces for |x| < min(3a, R/2), R/8 on the rest of the arcs and the flat
    faces of the cylinders, at most R/2 anywhere, and grows by GROWTH per unit distance;
    all (sizes and growth) divided by 2**refinement. Every length of the mesh is a
    multiple of R or a, and the model is meshed at R = 8 and then scaled, so scaling R
    and a by s scales the node coordinates by s (to rounding) with the same cells: pass
    the Hertz a of the actual load and moduli, and the same dimensionless problem gets
    the same mesh in any unit system.

    Args:
        case: "A", "B" or "C".
        refinement: Halves the sizes per level.
        radius: Cylinder radius R.
        cell_type: "triangle" or "quadrilateral" (recombined).
        comm: Communicator of the mesh.
        half_width: Contact half-width a that sizes the refined zone, e.g. the Hertz a
            of the load and moduli to be solved; None for :func:`hertz_half_width`
            (the benchmark loads).
        slave: "cylinder" (default) makes the upper cylinder's arc the slave surface,
            "block" the lower body's contact surface; the mesh is the same either way,
            only the tags "contact_*" and "symmetry_*" swap their facets.

    Returns:
        The mesh with cells "cylinder", "block" and facets "contact_slave" (the whole
        arc of the upper cylinder, or with ``slave="block"`` the top of the block or
        the arc of the lower cylinder), "contact_master" (the other of the two), "load"
        (y = R), "support" (bottom of the lower body), "symmetry_slave",
        "symmetry_master".
    """
    level = _check_refinement(refinement)
    quadrilateral = _check_cell_type(cell_type)
    if slave not in HERTZ_SLAVES:
        raise ValueError(f"slave must be one of {HERTZ_SLAVES}, got {slave!r}")
    unit, sizes = _hertz_sizes(case, level, radius, half_width)
    markers = _numbered(
        ["cylinder", "block"],
        ["contact_slave", "contact_master", "load", "support", "symmetry_slave", "symmetry_master"],
    )

    def construct(m: _Model) -> None:
        _hertz_model(m, case, slave, sizes, markers, quadrilateral)

    data = _build(comm, f"hertz_{case}", construct)
    if unit != 1.0:
        data.mesh.geometry.x[:] *= unit
    return _tagged(data, markers, {}, sizes.h_contact * unit)


def _patch_test_model(m: _Model, n_punch: int, n_foundation: int, n_height: int,
                      markers: dict[str, int], quadrilateral: bool) -> None:
    """:func:`patch_test`'s gmsh model on rank 0: the foundation's three transfinite
    blocks, the punch, their physical groups."""
    xs = (0.0, 4.0, 6.0, 8.0)
    counts = (2 * n_foundation, n_foundation, n_foundation)
    bottom = [m.point(x, 0.0) for x in xs]
    top = [m.point(x, 5.0) for x in xs]
    verticals = [m.line(b, t, n_height + 1) for b, t in zip(bottom, top, strict=True)]
    bottoms = [m.line(bottom[i], bottom[i + 1], counts[i] + 1) for i in range(3)]
    tops = [m.line(top[i], top[i + 1], counts[i] + 1) for i in range(3)]
    foundation = [
        m.surface([bottoms[i], verticals[i + 1], tops[i], verticals[i]], transfinite=True)
        for i in range(3)
    ]
    corners = [m.point(x, y) for x, y in ((4.0, 5.0), (6.0, 5.0), (6.0, 7.0), (4.0, 7.0))]
    punch_bottom = m.line(corners[0], corners[1], n_punch + 1)
    punch_right = m.line(corners[1], corners[2], n_punch + 1)
    punch_top = m.line(corners[2], corners[3], n_punch + 1)
    punch_left = m.line(corners[3], corners[0], n_punch + 1)
    punch = m.surface([punch_bottom, punch_right, punch_top, punch_left], transfinite=True)
    m.mesh(
        cells={markers["punch"]: [punch], markers["foundation"]: foundation},
        facets={
            markers["punch_contact"]: [punch_bottom],
            markers["foundation_contact"]: [tops[1]],
            markers["punch_top"]: [punch_top],
            markers["foundation_top_free"]: [tops[0], tops[2]],
            markers["foundation_bottom"]: bottoms,
        },
        names=_names(markers),
        h_max=8.0,
        quadrilateral=quadrilateral,
    )


def patch_test(
    ratio: Sequence[int] = (3, 2),
    slave: str = "top",
    refinement: int = 0,
    cell_type: str = "triangle",
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TaggedMesh:
    """Contact patch test: a punch [4, 6] x [5, 7] on a foundation [0, 8] x [0, 5].

    Both bodies are structured. Along the interface x in [4, 6], y = 5 the punch has
    n_punch = ratio[0] * 2**refinement elements and the foundation n_foundation =
    ratio[1] * 2**refinement, so non-matching interfaces are chosen exactly. Every other
    element is close to square: the foundation uses the interface spacing 2/n_foundation
    everywhere (2 n_foundation elements on [0, 4], n_foundation on [6, 8], about
    2.5 n_foundation in height; it has nodes at x = 4 and x = 6), the punch 2/n_punch.

    Args:
        ratio: (n_punch, n_foundation) at refinement 0, integers >= 1.
        slave: "top" makes the punch bottom the slave surface, "bottom" the foundation.
        refinement: Doubles the element counts per level.
        cell_type: "triangle" or "quadrilateral".
        comm: Communicator of the mesh.

    Returns:
        The mesh with cells "punch", "foundation" and facets "punch_contact",
        "foundation_contact", "punch_top", "foundation_top_free" (y = 5 outside [4, 6]),
        "foundation_bottom"; ``h_contact`` is the slave's element size.
    """
    n_punch, n_foundation = _check_ratio(ratio)
    level = _check_refinement(refinement)
    quadrilateral = _check_cell_type(cell_type)
    if slave not in ("top", "bottom"):
        raise ValueError(f"slave must be 'top' or 'bottom', got {slave!r}")
    n_punch *= 2**level
    n_foundation *= 2**level
    n_height = max(1, round(2.5 * n_foundation))
    markers = _numbered(
        ["punch", "foundation"],
        [
            "punch_contact",
            "foundation_contact",
            "punch_top",
            "foundation_top_free",
            "foundation_bottom",
        ],
    )
    if slave == "top":
        aliases = {"contact_slave": "punch_contact", "contact_master": "foundation_contact"}
        h_contact = 2.0 / n_punch
    else:
        aliases = {"contact_slave": "foundation_contact", "contact_master": "punch_contact"}
        h_contact = 2.0 / n_foundation

    def construct(m: _Model) -> None:
        _patch_test_model(m, n_punch, n_foundation, n_height, markers, quadrilateral)

    data = _build(comm, "patch_test", construct)
    return _tagged(data, markers, aliases, h_contact)


CELL_TYPES_3D = ("tetrahedron", "hexahedron")
"""Accepted values of :func:`patch_test_3d`'s ``cell_type``."""


def patch_test_3d(
    ratio: Sequence[int] = (3, 2),
    slave: str = "top",
    refinement: int = 0,
    cell_type: str = "hexahedron",
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TaggedMesh:
    """3D contact patch test: a punch [0, 1]^2 x [0.5, 1] stacked on a foundation
    [0, 1]^2 x [0, 0.5] (benchmarks.md, section 6).

    Both blocks are structured boxes (``dolfinx.mesh.create_box``; tetrahedra split
    each hexahedron into six) with the same footprint, so a uniform pressure on the
    punch top passes through the interface as a uniform state. Across the interface
    the punch has n_punch = ratio[0] * 2**refinement elements per side and the
    foundation n_foundation = ratio[1] * 2**refinement; each block has
    max(1, n // 2) elements through its height.

    Args:
        ratio: (n_punch, n_foundation) at refinement 0, integers >= 1.
        slave: "top" makes the punch bottom the slave surface, "bottom" the foundation top.
        refinement: Doubles the element counts per level.
        cell_type: "tetrahedron" or "hexahedron".
        comm: Communicator of the mesh.

    Returns:
        The mesh with cells "punch", "foundation" and facets "punch_contact",
        "punch_top", "foundation_contact", "foundation_bottom"; ``h_contact`` is the
        slave's element size.
    """
    n_punch, n_foundation = _check_ratio(ratio)
    level = _check_refinement(refinement)
    if cell_type not in CELL_TYPES_3D:
        raise ValueError(f"cell_type must be one of {CELL_TYPES_3D}, got {cell_type!r}")
    if slave not in ("top", "bottom"):
        raise ValueError(f"slave must be 'top' or 'bottom', got {slave!r}")
    n_punch *= 2**level
    n_foundation *= 2**level
    kind = getattr(dolfinx.mesh.CellType, cell_type)

    def box(z0: float, n: int) -> dolfinx.mesh.Mesh:
        return dolfinx.mesh.create_box(
            comm, [[0.0, 0.0, z0], [1.0, 1.0, z0 + 0.5]], [n, n, max(1, n // 2)], kind
        )

    tagged = merge_meshes(
        {
            "punch": (
                box(0.5, n_punch),
                {
                    "contact": lambda x: np.isclose(x[2], 0.5),
                    "top": lambda x: np.isclose(x[2], 1.0),
                },
            ),
            "foundation": (
                box(0.0, n_foundation),
                {
                    "contact": lambda x: np.isclose(x[2], 0.5),
                    "bottom": lambda x: np.isclose(x[2], 0.0),
                },
            ),
        },
        comm,
    )
    sides = ("punch_contact", "foundation_contact")
    if slave == "bottom":
        sides = sides[::-1]
    tagged.markers["contact_slave"] = tagged.markers[sides[0]]
    tagged.markers["contact_master"] = tagged.markers[sides[1]]
    tagged.h_contact = 1.0 / (n_punch if slave == "top" else n_foundation)
    return tagged


def ironing(
    refinement: int = 0,
    cell_type: str = "triangle",
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TaggedMesh:
    """Ironing: a die with a rounded bottom above an elastic block [0, 12] x [0, 4].

    The die spans x in [0.2, 1.4]; its bottom is a circular arc of radius 0.75 whose
    lowest point (0.8, 4.2) leaves an initial gap of 0.2, its side walls rise vertically
    from the arc's ends (y = 4.5) to its flat top at y = 5.4 (the die is 1.2 tall, as in
    Yastrebov's statement of the benchmark). Element sizes at
    refinement 0: 0.05 on the die arc (h_contact), 0.1 along the whole block top (the
    die slides along it), growing by GROWTH with distance up to 0.8; all (and the growth) divided by
    2**refinement.

    Args:
        refinement: Halves the sizes per level.
        cell_type: "triangle" or "quadrilateral".
        comm: Communicator of the mesh.

    Returns:
        The mesh with cells "die", "block" and facets "die_contact" (the arc),
        "block_contact" (y = 4), "die_top", "block_bottom"; contact_slave is the die arc.
    """
    level = _check_refinement(refinement)
    quadrilateral = _check_cell_type(cell_type)
    scale = 0.5**level
    h_die, h_block, h_max = 0.05 * scale, 0.1 * scale, 0.8 * scale
    markers = _numbered(
        ["die", "block"], ["die_contact", "block_contact", "die_top", "block_bottom"]
    )
    aliases = {"contact_slave": "die_contact", "contact_master": "block_contact"}
    radius, centre_x, lowest = 0.75, 0.8, 4.2
    centre_y = lowest + radius
    arc_end_y = centre_y - math.sqrt(radius**2 - 0.6**2)

    def construct(m: _Model) -> None:
        b = [m.point(x, y) for x, y in ((0.0, 0.0), (12.0, 0.0), (12.0, 4.0), (0.0, 4.0))]
        block_bottom, block_right = m.line(b[0], b[1]), m.line(b[1], b[2])
        block_top, block_left = m.line(b[2], b[3]), m.line(b[3], b[0])
        block = m.surface([block_bottom, block_right, block_top, block_left])
        m.refine_near([block_top], h_block, GROWTH * scale)

        centre = m.point(centre_x, centre_y)
        arc_left, bottom, arc_right = (
            m.point(centre_x - 0.6, arc_end_y),
            m.point(centre_x, lowest),
            m.point(centre_x + 0.6, arc_end_y),
        )
        top_y = lowest + 1.2
        top_left, top_right = m.point(centre_x - 0.6, top_y), m.point(centre_x + 0.6, top_y)
        arcs = [m.arc(arc_left, centre, bottom), m.arc(bottom, centre, arc_right)]
        walls = [m.line(arc_right, top_right), m.line(top_left, arc_left)]
        die_top = m.line(top_right, top_left)
        die = m.surface([*arcs, walls[0], die_top, walls[1]])
        m.refine_near(arcs, h_die, GROWTH * scale)
        m.mesh(
            cells={markers["die"]: [die], markers["block"]: [block]},
            facets={
                markers["die_contact"]: arcs,
                markers["block_contact"]: [block_top],
                markers["die_top"]: [die_top],
                markers["block_bottom"]: [block_bottom],
            },
            names=_names(markers),
            h_max=h_max,
            quadrilateral=quadrilateral,
        )

    data = _build(comm, "ironing", construct)
    return _tagged(data, markers, aliases, h_die)


def ironing_3d(
    refinement: int = 0,
    layers: int | None = None,
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TaggedMesh:
    """3D ironing: :func:`ironing`'s quadrilateral die and block extruded into hexahedra
    through the thickness z in [0, 1] (``layers`` cells, default the block-top element
    size 0.1 / 2**refinement).

    Returns:
        The mesh with cells "die", "block" and facets "die_contact" (the curved bottom),
        "die_top", "block_contact" (y = 4), "block_bottom" (y = 0) and "block_back"
        (z = 0); contact_slave is the die's curved bottom.
    """
    level = _check_refinement(refinement)
    if layers is None:
        layers = 10 * 2**level
    if isinstance(layers, bool) or operator.index(layers) < 1:
        raise ValueError(f"layers must be a positive integer, got {layers!r}")
    bodies = {"die": None, "block": None}
    if comm.rank == 0:
        plane = ironing(refinement, "quadrilateral", comm=MPI.COMM_SELF)
        x2 = plane.mesh.geometry.x[:, :2]
        cells2 = compat.geometry_dofmap(plane.mesh)
        for name in bodies:
            cells = cells2[plane.cell_tags.find(plane.markers[name])]
            nodes, local = np.unique(cells, return_inverse=True)
            bodies[name] = _extruded(x2[nodes], local.reshape(cells.shape), layers)
    radius, centre = 0.75, (0.8, 4.95)
    arc_top = centre[1] - math.sqrt(radius**2 - 0.6**2)
    groups = {
        "die": {
            "contact": lambda x: (np.abs(np.hypot(x[0] - centre[0], x[1] - centre[1]) - radius)
                                  < 1e-6) & (x[1] <= arc_top + 1e-9),
            "top": lambda x: np.isclose(x[1], 5.4),
        },
        "block": {
            "contact": lambda x: np.isclose(x[1], 4.0),
            "bottom": lambda x: np.isclose(x[1], 0.0),
            "back": lambda x: np.isclose(x[2], 0.0),
        },
    }
    element = basix.ufl.element("Lagrange", "hexahedron", 1, shape=(3,))
    meshes = {}
    for name, body in bodies.items():
        x, cells = body if comm.rank == 0 else (np.zeros((0, 3)), np.zeros((0, 8), np.int64))
        mesh = dolfinx.mesh.create_mesh(comm, cells=cells, x=x, e=ufl.Mesh(element))
        meshes[name] = (mesh, groups[name])
    tagged = merge_meshes(meshes, comm)
    tagged.markers["contact_slave"] = tagged.markers["die_contact"]
    tagged.markers["contact_master"] = tagged.markers["block_contact"]
    tagged.h_contact = 0.05 * 0.5**level
    return tagged


def _extruded(x2, quadrilaterals, layers: int):
    """Nodes (n (layers + 1), 3) and hexahedra (dolfinx vertex order) of quadrilaterals
    (dolfinx order) extruded through z in [0, 1]."""
    n = x2.shape[0]
    z = np.linspace(0.0, 1.0, layers + 1)
    x = np.column_stack([np.tile(x2, (layers + 1, 1)), np.repeat(z, n)])
    k = np.arange(layers)[:, None, None] * n
    hexahedra = np.concatenate([quadrilaterals[None] + k, quadrilaterals[None] + k + n], axis=2)
    return x, hexahedra.reshape(-1, 8).astype(np.int64)


def _ring(m: _Model, sign: float, r_in: float, r_out: float, gap: float, h_contact: float,
          h_max: float, growth: float) -> tuple[int, list[int], list[int]]:
    """:func:`rings`' ring centred at (0, sign c), c = r_out + gap / 2 (``sign`` also points
    away from the other ring): its surface, outer and inner arcs."""
    cy = sign * (r_out + 0.5 * gap)
    centre = m.point(0.0, cy)
    zone = math.radians(30.0)  # the refined arcs: within 30 degrees of the contact point

    def on_circle(radius: float, angle: float) -> int:
        return m.point(radius * math.sin(angle), cy - sign * radius * math.cos(angle))

    near = on_circle(r_out, 0.0)
    zone_a, zone_b = on_circle(r_out, zone), on_circle(r_out, -zone)
    far = on_circle(r_out, math.pi)
    outer = [
        m.arc(near, centre, zone_a),
        m.arc(zone_a, centre, far),
        m.arc(far, centre, zone_b),
        m.arc(zone_b, centre, near),
    ]
    inner_points = [on_circle(r_in, angle) for angle in (0.0, 0.5 * math.pi, math.pi)]
    inner_points.append(on_circle(r_in, -0.5 * math.pi))
    inner = [m.arc(inner_points[i], centre, inner_points[(i + 1) % 4]) for i in range(4)]
    surface = m.surface(outer, holes=[inner])
    m.refine_near([outer[0], outer[3]], h_contact, growth)
    m.refine_near(outer + inner, h_max, growth)
    return surface, outer, inner


def rings(
    refinement: int = 0,
    inner_radius: float = 0.8,
    outer_radius: float = 1.0,
    gap: float = 0.0,
    cell_type: str = "triangle",
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TaggedMesh:
    """Two equal rings (annuli) one above the other, touching at the origin when gap = 0.

    Centres (0, c) and (0, -c) with c = outer_radius + gap/2. With t = outer_radius -
    inner_radius, the element size is t/8 (h_contact) on the outer circles within 30
    degrees of the contact points, t/2 on the rest of the circles and at most t/2
    anywhere, growing by GROWTH with distance; all (and the growth) divided by 2**refinement.

    Args:
        refinement: Halves the sizes per level.
        inner_radius: Radius of the holes, > 0.
        outer_radius: Outer radius, > inner_radius.
        gap: Initial distance between the rings, >= 0.
        cell_type: "triangle" or "quadrilateral".
        comm: Communicator of the mesh.

    Returns:
        The mesh with cells "ring_top", "ring_bottom" and facets "ring_top_outer",
        "ring_bottom_outer", "ring_top_inner", "ring_bottom_inner"; contact_slave is the
        top ring's outer circle.
    """
    level = _check_refinement(refinement)
    quadrilateral = _check_cell_type(cell_type)
    r_in = _check_positive("inner_radius", inner_radius)
    r_out = _check_positive("outer_radius", outer_radius)
    if r_in >= r_out:
        raise ValueError(f"inner_radius {inner_radius} must be below outer_radius {outer_radius}")
    gap = float(gap)
    if not math.isfinite(gap) or gap < 0.0:
        raise ValueError(f"gap must be a non-negative number, got {gap!r}")
    scale = 0.5**level
    thickness = r_out - r_in
    h_contact, h_max = thickness / 8.0 * scale, thickness / 2.0 * scale
    markers = _numbered(
        ["ring_top", "ring_bottom"],
        ["ring_top_outer", "ring_bottom_outer", "ring_top_inner", "ring_bottom_inner"],
    )
    aliases = {"contact_slave": "ring_top_outer", "contact_master": "ring_bottom_outer"}

    def construct(m: _Model) -> None:
        sizes = (h_contact, h_max, GROWTH * scale)
        top, top_outer, top_inner = _ring(m, 1.0, r_in, r_out, gap, *sizes)
        bottom, bottom_outer, bottom_inner = _ring(m, -1.0, r_in, r_out, gap, *sizes)
        m.mesh(
            cells={markers["ring_top"]: [top], markers["ring_bottom"]: [bottom]},
            facets={
                markers["ring_top_outer"]: top_outer,
                markers["ring_bottom_outer"]: bottom_outer,
                markers["ring_top_inner"]: top_inner,
                markers["ring_bottom_inner"]: bottom_inner,
            },
            names=_names(markers),
            h_max=h_max,
            quadrilateral=quadrilateral,
        )

    data = _build(comm, "rings", construct)
    return _tagged(data, markers, aliases, h_contact)


def crushed_ring(refinement: int = 0, inner_radius: float = 0.7, outer_radius: float = 1.0,
                 cell_type: str = "triangle", comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """Half a ring (x >= 0, centre at the origin) between two plates that touch it at
    (0, +-outer_radius): ``demos/self_contact.py --case crush`` (the plane x = 0 a
    symmetry plane).

    The plates are [0, 1.6 R] x [R, 1.2 R] and its mirror; the ring's element size is
    its thickness over 6 (over 6 * 2**refinement), the plates' 0.1 R. The ring's mesh is
    mirror-symmetric about y = 0, as the crush is about the plane midway between the
    plates: where the closed walls fold, an asymmetric mesh bent them together near the
    fold, and a node there ended 0.026 facet lengths behind the other wall (1.8e-6 with
    the symmetric mesh, docs/benchmarks.md).

    Returns:
        Cells "ring", "plate_top", "plate_bottom"; facets "ring_outer_top" and
        "ring_outer_bottom" (the outer arc above and below y = 0), "ring_inner" (the
        whole inner arc: the self-contact surface), "plate_top_contact",
        "plate_bottom_contact", "plate_top_load" (the top plate's upper face),
        "plate_bottom_support", "symmetry" (every facet on x = 0).
    """
    level = _check_refinement(refinement)
    quadrilateral = _check_cell_type(cell_type)
    r_in = _check_positive("inner_radius", inner_radius)
    r_out = _check_positive("outer_radius", outer_radius)
    if r_in >= r_out:
        raise ValueError(f"inner_radius {inner_radius} must be below outer_radius {outer_radius}")
    h_ring = (r_out - r_in) / 6.0 * 0.5**level
    markers = _numbered(
        ["ring", "plate_top", "plate_bottom"],
        ["ring_outer_top", "ring_outer_bottom", "ring_inner", "plate_top_contact",
         "plate_bottom_contact", "plate_top_load", "plate_bottom_support", "symmetry"])

    def construct(m: _Model) -> None:
        centre = m.point(0.0, 0.0)
        top, right, bottom = m.point(0.0, r_out), m.point(r_out, 0.0), m.point(0.0, -r_out)
        inner_top, inner_right = m.point(0.0, r_in), m.point(r_in, 0.0)
        inner_bottom = m.point(0.0, -r_in)
        outer_top, outer_bottom = m.arc(top, centre, right), m.arc(right, centre, bottom)
        inner = [m.arc(inner_top, centre, inner_right), m.arc(inner_right, centre, inner_bottom)]
        cuts = [m.line(inner_top, top), m.line(bottom, inner_bottom)]
        # the halves above and below y = 0, the lower meshed as the upper's mirror image
        middle = m.line(inner_right, right)
        halves = [m.surface([outer_top, middle, inner[0], cuts[0]]),
                  m.surface([outer_bottom, cuts[1], inner[1], middle])]
        m.geo.synchronize()
        mirror = [1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
        m.gmsh.model.mesh.setPeriodic(2, [halves[1]], [halves[0]], mirror)
        plates, faces = {}, {}
        for name, sign in (("top", 1.0), ("bottom", -1.0)):
            near, far = sign * r_out, sign * 1.2 * r_out
            corners = [m.point(0.0, near), m.point(1.6 * r_out, near),
                       m.point(1.6 * r_out, far), m.point(0.0, far)]
            sides = [m.line(corners[i], corners[(i + 1) % 4]) for i in range(4)]
            plates[name] = m.surface(sides)
            faces[name] = sides
        m.refine_near([outer_top, outer_bottom, *inner], h_ring, GROWTH)
        m.refine_near([faces["top"][0], faces["bottom"][0]], 2.0 * h_ring, GROWTH)
        m.mesh(
            cells={markers["ring"]: halves, markers["plate_top"]: [plates["top"]],
                   markers["plate_bottom"]: [plates["bottom"]]},
            facets={markers["ring_outer_top"]: [outer_top],
                    markers["ring_outer_bottom"]: [outer_bottom],
                    markers["ring_inner"]: inner,
                    markers["plate_top_contact"]: [faces["top"][0]],
                    markers["plate_bottom_contact"]: [faces["bottom"][0]],
                    markers["plate_top_load"]: [faces["top"][2]],
                    markers["plate_bottom_support"]: [faces["bottom"][2]],
                    markers["symmetry"]: cuts + [faces["top"][3], faces["bottom"][3]]},
            names=_names(markers),
            h_max=0.1 * r_out,
            quadrilateral=quadrilateral,
        )

    data = _build(comm, "crushed_ring", construct)
    return _tagged(data, markers, {}, h_ring)


SLIT_TIP = 1.2
"""How far (in y, from y = 0) :func:`slit_block`'s slit reaches into the block [0, 2]^2."""


def slit_block(ratio: Sequence[int] = (5, 7), cell_type: str = "triangle",
               comm: MPI.Comm = MPI.COMM_WORLD) -> TaggedMesh:
    """One body with a slit: the self-contact patch test (``demos/self_contact.py``).

    The block [0, 2] x [0, 2] (3D: times [0, 1/2] in z) is cut along x = 1 from y = 0 to
    y = :data:`SLIT_TIP`; above the tip its halves are one mesh. The slit's left lip has
    ratio[0] elements along the slit, the right lip ratio[1] (non-matching unless equal);
    the part above the tip has max(ratio) // 2 + 1 rows, z (3D) max(1, min(ratio) // 2)
    layers. The four pieces are structured (triangles split each square by its rising
    diagonal, tetrahedra each cube into six around its main diagonal, so that the pieces
    join conformingly). Pressed from both sides (u_x = +d at x = 0, -d at x = 2), the
    lips meet along the whole slit and the stress is uniform: a uniform pressure
    across a slit whose two lips are one surface.

    Returns:
        Cells "block"; facets "slit" (both lips), "left" (x = 0), "right" (x = 2),
        "bottom" (y = 0) and in 3D "back" (z = 0); ``h_contact`` the finer lip's.
    """
    n_left, n_right = _check_ratio(ratio)
    if cell_type not in CELL_TYPES + CELL_TYPES_3D:
        raise ValueError(f"cell_type must be one of {CELL_TYPES + CELL_TYPES_3D}, "
                         f"got {cell_type!r}")
    gdim = 3 if cell_type in CELL_TYPES_3D else 2
    tip = SLIT_TIP
    rows_above = max(n_left, n_right) // 2 + 1
    layers = max(1, min(n_left, n_right) // 2)
    pieces = [((0.0, 1.0), (0.0, tip), (n_left, n_left), 0),
              ((1.0, 2.0), (0.0, tip), (n_right, n_right), 1),
              ((0.0, 1.0), (tip, 2.0), (n_left, rows_above), 0),
              ((1.0, 2.0), (tip, 2.0), (n_right, rows_above), 1)]
    x, cells = np.zeros((0, gdim)), []
    if comm.rank == 0:
        nodes = []
        for (x0, x1), (y0, y1), (nx, ny), side in pieces:
            axes = [np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)]
            if gdim == 3:
                axes.append(np.linspace(0.0, 0.5, layers + 1))
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, gdim)
            first = sum(n.shape[0] for n in nodes)
            cells.append(first + _structured_cells([a.size - 1 for a in axes], cell_type))
            nodes.append(np.column_stack([grid, np.full(grid.shape[0], side)]))
        everything = np.concatenate(nodes)
        x = everything[:, :gdim]
        on_slit = np.isclose(x[:, 0], 1.0) & (x[:, 1] < tip - 1e-9)
        key = np.column_stack([np.round(x * 1e9).astype(np.int64),
                               np.where(on_slit, everything[:, gdim], -1).astype(np.int64)])
        _, first, merged = np.unique(key, axis=0, return_index=True, return_inverse=True)
        x, cells = x[first], merged.reshape(-1)[np.concatenate(cells)]
    else:
        cells = np.zeros((0, 2**gdim if cell_type in ("quadrilateral", "hexahedron")
                          else gdim + 1), dtype=np.int64)
    domain = ufl.Mesh(basix.ufl.element("Lagrange", cell_type, 1, shape=(gdim,)))
    mesh = dolfinx.mesh.create_mesh(comm, cells=np.asarray(cells, dtype=np.int64), x=x,
                                    e=domain)
    markers = _numbered(["block"], ["slit", "left", "right", "bottom", "back"][:4 + (gdim == 3)])
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = dolfinx.mesh.exterior_facet_indices(mesh.topology)
    middle = dolfinx.mesh.compute_midpoints(mesh, tdim - 1, facets)
    where = {"slit": np.isclose(middle[:, 0], 1.0) & (middle[:, 1] < tip),
             "left": np.isclose(middle[:, 0], 0.0), "right": np.isclose(middle[:, 0], 2.0),
             "bottom": np.isclose(middle[:, 1], 0.0)}
    if gdim == 3:
        where["back"] = np.isclose(middle[:, 2], 0.0)
    values = np.zeros(facets.size, dtype=np.int32)
    for name, found in where.items():
        values[found] = markers[name]
    tagged = values > 0
    facet_tags = dolfinx.mesh.meshtags(mesh, tdim - 1, facets[tagged], values[tagged])
    num_cells = mesh.topology.index_map(tdim)
    all_cells = np.arange(num_cells.size_local + num_cells.num_ghosts, dtype=np.int32)
    cell_tags = dolfinx.mesh.meshtags(mesh, tdim, all_cells,
                                      np.full(all_cells.size, markers["block"], np.int32))
    return TaggedMesh(mesh, cell_tags, facet_tags, markers, tip / max(n_left, n_right))


def _structured_cells(counts: Sequence[int], cell_type: str) -> np.ndarray:
    """Cells of a structured grid of ``counts`` cells per axis (nodes numbered as
    ``np.meshgrid(..., indexing="ij")``), in dolfinx's vertex order; simplices split each
    square (cube) around its rising (main) diagonal, the same way everywhere."""
    shape = [c + 1 for c in counts]
    index = np.arange(np.prod(shape)).reshape(shape)
    corner = index[tuple(slice(0, c) for c in counts)].reshape(-1)
    strides = [index.strides[k] // index.itemsize for k in range(len(counts))]
    # vertex v of a square (cube): bit k of v steps along axis k (dolfinx's order)
    offsets = np.array([sum(strides[k] for k in range(len(counts)) if v >> k & 1)
                        for v in range(2 ** len(counts))])
    boxes = corner[:, None] + offsets[None, :]
    if cell_type in ("quadrilateral", "hexahedron"):
        return boxes
    top = 2 ** len(counts) - 1
    paths = [[0, 1 << a, (1 << a) | (1 << b), top]
             for a, b in itertools.permutations(range(3), 2)] if len(counts) == 3 \
        else [[0, 1, top], [0, 2, top]]
    return np.concatenate([boxes[:, path] for path in paths])


def tied_blocks(
    ratio: Sequence[int] = (3, 4),
    refinement: int = 0,
    cell_type: str = "triangle",
    comm: MPI.Comm = MPI.COMM_WORLD,
) -> TaggedMesh:
    """The unit square cut at y = 0.5 into two separately meshed structured blocks.

    The lower block [0, 1] x [0, 0.5] has n_lower = ratio[0] * 2**refinement elements
    along x, the upper block [0, 1] x [0.5, 1] n_upper = ratio[1] * 2**refinement; each
    has max(1, round(n/2)) elements along y, so elements are about square. It is the
    mesh of mortar tying tests: the solution of a problem on the whole square must be
    reproduced across the non-matching interface.

    Args:
        ratio: (n_lower, n_upper) at refinement 0, integers >= 1.
        refinement: Doubles the element counts per level.
        cell_type: "triangle" or "quadrilateral".
        comm: Communicator of the mesh.

    Returns:
        The mesh with cells "lower", "upper" and facets "lower_interface",
        "upper_interface", "boundary" (the whole outer boundary of the square);
        contact_slave is the upper interface (the finer one when ratio[1] > ratio[0]).
    """
    n_lower, n_upper = _check_ratio(ratio)
    level = _check_refinement(refinement)
    quadrilateral = _check_cell_type(cell_type)
    n_lower *= 2**level
    n_upper *= 2**level
    markers = _numbered(["lower", "upper"], ["lower_interface", "upper_interface", "boundary"])
    aliases = {"contact_slave": "upper_interface", "contact_master": "lower_interface"}

    def block(m: _Model, y0: float, n: int) -> tuple[int, int, int, list[int]]:
        n_y = max(1, round(0.5 * n))
        p = [m.point(x, y) for x, y in ((0.0, y0), (1.0, y0), (1.0, y0 + 0.5), (0.0, y0 + 0.5))]
        bottom, right = m.line(p[0], p[1], n + 1), m.line(p[1], p[2], n_y + 1)
        top, left = m.line(p[2], p[3], n + 1), m.line(p[3], p[0], n_y + 1)
        surface = m.surface([bottom, right, top, left], transfinite=True)
        return surface, bottom, top, [left, right]

    def construct(m: _Model) -> None:
        lower, lower_bottom, lower_top, lower_sides = block(m, 0.0, n_lower)
        upper, upper_bottom, upper_top, upper_sides = block(m, 0.5, n_upper)
        m.mesh(
            cells={markers["lower"]: [lower], markers["upper"]: [upper]},
            facets={
                markers["lower_interface"]: [lower_top],
                markers["upper_interface"]: [upper_bottom],
                markers["boundary"]: [lower_bottom, *lower_sides, upper_top, *upper_sides],
            },
            names=_names(markers),
            h_max=1.0,
            quadrilateral=quadrilateral,
        )

    data = _build(comm, "tied_blocks", construct)
    return _tagged(data, markers, aliases, 1.0 / n_upper)


BUILDERS: dict[str, Callable[..., TaggedMesh]] = {
    "hertz": hertz,
    "patch_test": patch_test,
    "patch_test_3d": patch_test_3d,
    "ironing": ironing,
    "ironing_3d": ironing_3d,
    "rings": rings,
    "tied_blocks": tied_blocks,
}
"""The builders by name, as the command line knows them."""


def write_xdmf(tagged: TaggedMesh, path: str | pathlib.Path) -> None:
    """Write the mesh and its cell and facet tags to one XDMF file (with its .h5).

    The markers and h_contact go to ``<path without suffix>.markers.json`` since XDMF
    keeps only the tag values.
    """
    path = pathlib.Path(path)
    mesh = tagged.mesh
    comm = mesh.comm
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
    comm.Barrier()
    mesh.name = "mesh"
    tagged.cell_tags.name = "cell_tags"
    tagged.facet_tags.name = "facet_tags"
    mesh.topology.create_connectivity(mesh.topology.dim - 1, mesh.topology.dim)
    with dolfinx.io.XDMFFile(comm, str(path), "w") as xdmf:
        xdmf.write_mesh(mesh)
        xdmf.write_meshtags(tagged.cell_tags, mesh.geometry)
        xdmf.write_meshtags(tagged.facet_tags, mesh.geometry)
    if comm.rank == 0:
        info = {"markers": tagged.markers, "h_contact": tagged.h_contact}
        path.with_suffix(".markers.json").write_text(json.dumps(info, indent=2) + "\n")


def _main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python3 -m dolfinx_mortar.meshes",
        description="Build a benchmark mesh and write it with its tags to XDMF (ParaView).",
    )
    parser.add_argument("name", choices=sorted(BUILDERS))
    parser.add_argument("--refinement", type=int, default=0)
    parser.add_argument(
        "--cell-type",
        choices=CELL_TYPES + CELL_TYPES_3D,
        help="default: triangle in 2D, hexahedron in 3D",
    )
    parser.add_argument("--case", default="B", choices=HERTZ_CASES, help="hertz only")
    parser.add_argument("--output", required=True, type=pathlib.Path, help="an .xdmf file")
    args = parser.parse_args(argv)
    options = {"refinement": args.refinement}
    if args.cell_type is not None:
        options["cell_type"] = args.cell_type
    if args.name == "hertz":
        options["case"] = args.case
    try:
        tagged = BUILDERS[args.name](**options)
    except ValueError as error:
        parser.error(str(error))
    write_xdmf(tagged, args.output)
    cells = tagged.mesh.topology.index_map(tagged.mesh.topology.dim).size_global
    if tagged.mesh.comm.rank == 0:
        print(f"{args.output}: {cells} cells, h_contact {tagged.h_contact:g}")
        print(json.dumps(tagged.markers))


if __name__ == "__main__":
    _main()
