"""The compiled 3D triangle kernel behind the contract: values at evaluation, gradients on demand.

The C kernel (``surface3.c`` through :mod:`.compiled`) integrates one triangle pair in a few
microseconds, values and gradients over the pair's 27 variables together. Kept for every
pair of an evaluation, the gradients would be the evaluation's memory (~1,700 numbers a
pair); so :func:`evaluate` keeps the values only (D, M, Dn, Mn, gaps, areas, valid, overlap)
and the coordinates of the contributing pairs, and :class:`CompiledGradients` runs the
kernel again on the pairs a consumer asks for (the stencils, a chunk at a time), hands
over their gradients and forgets them. The values and gradients are the same bits as the
first run's: the kernel is deterministic per pair.

Covered (:func:`covers`): triangle on triangle, segment-based, averaged normals (the
default 3D path), standard or dual basis, crosspoints, 1, 3 or 7 Gauss points per cell;
the covered dual basis runs it with the standard basis. Everything else stays with the
numpy kernel (:mod:`.surface3`).
"""

from __future__ import annotations

import numpy as np

from ..dual import RowSubsetDual
from . import compiled
from .contract import KernelOptions, PairGeometry, PairQuantities

EVALUATION_CHUNK = 2048
"""Candidate pairs per kernel call at evaluation (their discarded gradients live together)."""
GRADIENT_CHUNK = 2048
"""Pairs whose gradients a consumer gets at once (:attr:`CompiledGradients.chunk`)."""
_RULES = (1, 3, 7)
_VALUES = ("D", "M", "Dn", "Mn", "gap", "area")
_GRADIENTS = ("Dn_grad", "Mn_grad", "area_grad", "gap_grad", "D_grad", "M_grad")


def covers(geometry: PairGeometry, options: KernelOptions) -> bool:
    """Whether the compiled kernel integrates these pairs with these options."""
    return (options.integration == "segment" and options.normals == "averaged"
            and geometry.slave_normals is not None
            and geometry.slave_x.shape[1:] == (3, 3) and geometry.master_x.shape[1:] == (3, 3)
            and (options.num_gauss_points or 7) in _RULES)


class _Buffers:
    """The kernel's output arrays for up to ``size`` pairs, reused from call to call (fresh
    arrays of this size would be mapped and faulted in at every call)."""

    def __init__(self, size: int, scalar_gradients: bool):
        nv = compiled.NUM_VARIABLES
        self.size = size
        self.arrays = {
            "valid": np.zeros(size, dtype=np.uint8), "overlap": np.empty(size),
            "D": np.empty((size, 3, 3)), "M": np.empty((size, 3, 3)),
            "Dn": np.empty((size, 3, 3, 3)), "Mn": np.empty((size, 3, 3, 3)),
            "gap": np.empty((size, 3)), "area": np.empty((size, 3)),
            "Dn_grad": np.empty((size, 3, 3, 3, nv)), "Mn_grad": np.empty((size, 3, 3, 3, nv)),
            "gap_grad": np.empty((size, 3, nv)), "area_grad": np.empty((size, 3, nv)),
            "D_grad": np.empty((size, 3, 3, nv)) if scalar_gradients else None,
            "M_grad": np.empty((size, 3, 3, nv)) if scalar_gradients else None,
        }

    def run(self, slave_x, master_x, slave_normals, crosspoint, dual_basis: bool,
            rule: int) -> dict:
        """The kernel on up to ``size`` pairs (contiguous float64 (m, 3, 3) arrays;
        crosspoint (m, 3) uint8 or None); returns views of the first m rows."""
        m = slave_x.shape[0]
        out = {name: None if array is None else array[:m]
               for name, array in self.arrays.items()}
        if m == 0:
            return out
        module = compiled._get()
        ffi = module.ffi
        d = "double *"

        def pointer(array, ctype=d):
            return compiled._pointer(ffi, array, ctype)

        status = module.lib.surface3_triangles(
            m, pointer(slave_x), pointer(master_x), pointer(slave_normals),
            pointer(crosspoint, "unsigned char *"), compiled._NORMAL_FIELDS["averaged"],
            int(dual_basis), rule,
            pointer(out["valid"], "unsigned char *"), pointer(out["overlap"]),
            *(pointer(out[name]) for name in _VALUES),
            pointer(out["D_grad"]), pointer(out["M_grad"]),
            *(pointer(out[name]) for name in ("Dn_grad", "Mn_grad", "gap_grad", "area_grad")))
        if status != 0:
            raise RuntimeError(f"compiled 3D kernel failed (status {status}): a clip polygon "
                               "outgrew its slots or a bad rule")
        return out


def _contiguous(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float64)


class CompiledGradients:
    """The gradients of the contributing pairs of one compiled evaluation, made on demand
    (:class:`~.contract.GradientsOnDemand`): the kernel run again on the asked pairs'
    coordinates (kept for the contributing pairs only)."""

    chunk = GRADIENT_CHUNK

    def __init__(self, rows: np.ndarray, slave_x, master_x, slave_normals, crosspoint,
                 options: KernelOptions):
        self.rows = rows
        self.slave_x = _contiguous(slave_x[rows])
        self.master_x = _contiguous(master_x[rows])
        self.slave_normals = _contiguous(slave_normals[rows])
        self.crosspoint = None if crosspoint is None else np.ascontiguousarray(
            crosspoint[rows], dtype=np.uint8)
        self.dual_basis = options.basis == "dual"
        self.rule = options.num_gauss_points or 7
        self.scalar_gradients = options.scalar_gradients
        self._buffers: _Buffers | None = None

    def _names(self) -> tuple[str, ...]:
        return _GRADIENTS if self.scalar_gradients else _GRADIENTS[:4]

    def gradients(self, rows: np.ndarray) -> list[np.ndarray]:
        """As :meth:`~.contract.GradientsOnDemand.gradients`; for up to :attr:`chunk`
        contributing rows, views of the kernel's buffers, overwritten by the next call."""
        rows = np.asarray(rows)
        nv = compiled.NUM_VARIABLES
        shapes = {"Dn_grad": (3, 3, 3), "Mn_grad": (3, 3, 3), "area_grad": (3,),
                  "gap_grad": (3,), "D_grad": (3, 3), "M_grad": (3, 3)}
        kept = self.rows
        position = np.minimum(np.searchsorted(kept, rows), max(kept.size - 1, 0))
        found = kept[position] == rows if kept.size else np.zeros(rows.shape, dtype=bool)
        if self._buffers is None:
            self._buffers = _Buffers(self.chunk, self.scalar_gradients)
        buffers = self._buffers
        if found.all() and rows.size <= buffers.size:
            index = position
            cross = None if self.crosspoint is None else self.crosspoint[index]
            out = buffers.run(self.slave_x[index], self.master_x[index],
                              self.slave_normals[index], cross, self.dual_basis, self.rule)
            return [out[name] for name in self._names()]
        result = {name: np.zeros((rows.size,) + shapes[name] + (nv,))
                  for name in self._names()}
        asked = np.flatnonzero(found)
        for start in range(0, asked.size, buffers.size):
            part = asked[start:start + buffers.size]
            index = position[part]
            cross = None if self.crosspoint is None else self.crosspoint[index]
            out = buffers.run(self.slave_x[index], self.master_x[index],
                              self.slave_normals[index], cross, self.dual_basis, self.rule)
            for name in self._names():
                result[name][part] = out[name]
        return [result[name] for name in self._names()]


def _near(slave_x: np.ndarray, master_x: np.ndarray, slave_normals: np.ndarray) -> np.ndarray:
    """The candidates whose facets may overlap on the auxiliary plane: the others' projected
    bounding discs (centre the node mean, radius the farthest node) lie apart by a millionth
    of their radii, far more than the kernel's separation tolerance, so the kernel would
    find them separated. Spares the kernel most of a search's candidates."""
    s, m = slave_x.transpose(1, 2, 0), master_x.transpose(1, 2, 0)  # (node, xyz, pair)
    slave_centre, master_centre = (s[0] + s[1] + s[2]) / 3.0, (m[0] + m[1] + m[2]) / 3.0

    def radius(nodes, centre):
        return np.sqrt(np.maximum(np.maximum(((nodes[0] - centre) ** 2).sum(axis=0),
                                             ((nodes[1] - centre) ** 2).sum(axis=0)),
                                  ((nodes[2] - centre) ** 2).sum(axis=0)))

    normals = slave_normals.transpose(1, 2, 0)
    normal = normals[0] + normals[1] + normals[2]
    length2 = (normal**2).sum(axis=0)
    offset = master_centre - slave_centre
    along = (offset * normal).sum(axis=0)
    flat = np.where(length2 > 0.0, along**2 / np.where(length2 > 0.0, length2, 1.0), 0.0)
    in_plane2 = (offset**2).sum(axis=0) - flat
    reach = (radius(s, slave_centre) + radius(m, master_centre)) * (1.0 + 1e-6)
    return np.flatnonzero((in_plane2 <= reach**2) | ~(length2 > 0.0))


def evaluate(geometry: PairGeometry, options: KernelOptions,
             crosspoint: np.ndarray | None = None) -> PairQuantities:
    """The pairs' values by the compiled kernel (:func:`covers` must hold), their gradients
    on demand (``gradients_on_demand``; the outputs' ``grad`` also works, for every
    contributing pair at once)."""
    slave_x = _contiguous(geometry.slave_x)
    master_x = _contiguous(geometry.master_x)
    slave_normals = _contiguous(geometry.slave_normals)
    n = slave_x.shape[0]
    cross = None
    if crosspoint is not None:
        cross = np.ascontiguousarray(np.asarray(crosspoint, dtype=bool).reshape(n, 3),
                                     dtype=np.uint8)
    rule = options.num_gauss_points or 7
    dual_basis = options.basis == "dual"
    values = {name: np.zeros((n,) + shape) for name, shape in (
        ("D", (3, 3)), ("M", (3, 3)), ("Dn", (3, 3, 3)), ("Mn", (3, 3, 3)), ("gap", (3,)),
        ("area", (3,)))}
    valid = np.zeros(n, dtype=bool)
    overlap = np.zeros(n)
    near = _near(slave_x, master_x, slave_normals)
    buffers = _Buffers(min(EVALUATION_CHUNK, max(near.size, 1)), options.scalar_gradients)
    for start in range(0, near.size, buffers.size):
        part = near[start:start + buffers.size]
        out = buffers.run(slave_x[part], master_x[part], slave_normals[part],
                          None if cross is None else cross[part], dual_basis, rule)
        for name in _VALUES:
            values[name][part] = out[name]
        valid[part] = out["valid"].view(bool)
        overlap[part] = out["overlap"]
    del buffers
    rows = np.flatnonzero(valid)
    source = CompiledGradients(rows, slave_x, master_x, slave_normals, cross, options)
    names = ("Dn", "Mn", "area", "gap") + (("D", "M") if options.scalar_gradients else ())
    cached: list = []

    def all_gradients(index: int):
        def make():
            if not cached:
                cached.append([np.array(grad) for grad in source.gradients(rows)])
            return cached[0][index]
        return make

    duals = {name: RowSubsetDual(values[name], rows, all_gradients(i))
             for i, name in enumerate(names)}
    return PairQuantities(
        D=values["D"], M=values["M"], Dn=duals["Dn"], Mn=duals["Mn"], gap=duals["gap"],
        area=duals["area"], valid=valid, overlap=overlap,
        num_variables=compiled.NUM_VARIABLES, D_dual=duals.get("D"), M_dual=duals.get("M"),
        gradients_on_demand=source)
