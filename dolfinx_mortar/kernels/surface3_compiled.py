"""The compiled 3D kernel behind the contract: values at evaluation, gradients on demand.

The C kernel (``surface3.c`` through :mod:`.compiled`) integrates one pair in a few
microseconds, values and gradients over the pair's 3 (2 ns + nm) variables together. Kept for
every pair of a large evaluation, the gradients would be its memory (~1,700 numbers a triangle
pair, ~4,900 a quadrilateral pair); so :func:`evaluate` keeps the values (D, M, Dn, Mn, gaps,
areas, valid, overlap), the coordinates of the contributing pairs, and their gradients only
while these fit in :data:`KEPT_GRADIENTS_BYTES`; above it :class:`CompiledGradients` runs the
kernel again on the pairs a consumer asks for (the stencils, a chunk at a time), hands over
their gradients and forgets them. The values and gradients are the same bits as the first
run's: the kernel is deterministic per pair.

Segment-based pairs are evaluated for their values only: the kernel screens a pair on plain
values (most of a search's candidates do not overlap) and computes dual parts only for the
gradients asked for (the triangle kernel skips them, the general one carries no derivatives
in its dual numbers); the contributing pairs' gradients are then made in a second pass if
they are kept. Element-based pairs make their gradients with their values, in chunks, and
keep them while they fit.

Covered (:func:`covers`): triangle and quadrilateral slave and master facets (a triangle on
a triangle by the C corner-value path, as the tests' numpy oracle's ``_affine_integrals``; the
others at every Gauss point), segment- or element-based integration, the averaged, slave or
master normal field, the standard or the dual basis, crosspoints, the Gauss rules of
:func:`.compiled._facet_rule` (element) and 1, 3 or 7 points per cell (segment); for anything
else :class:`~.surface3.Surface3Kernel` raises. The covered dual basis runs it with the
standard basis.

Element-based integration gives each Gauss point of a slave facet to one of its pairs (the
master facet it lands on most centrally, :func:`.compiled.points_on_master`): decided once, at
evaluation, from the C kernel's scores, and kept for the contributing pairs, so that the
gradients made again later are those of the same assignment as the values.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..dual import RowSubsetDual
from . import compiled
from .contract import IndexedPairGeometry, KernelOptions, PairGeometry, PairQuantities

EVALUATION_CHUNK = 2048
"""Candidate triangle pairs per kernel call at an element-based evaluation (their gradients
live together); fewer quadrilateral pairs, as many gradient numbers
(:func:`_pairs_per_call`)."""
VALUES_CHUNK = 65536
"""Candidate pairs per kernel call at a segment-based evaluation (values only: ~0.6 kB a
triangle pair in the buffers, of which the contributing pairs' are kept)."""
GRADIENT_CHUNK = 2048
"""Triangle pairs whose gradients a consumer gets at once (:attr:`CompiledGradients.chunk`)."""
KEPT_GRADIENTS_BYTES = 128 * 2**20
"""The contributing pairs' gradients are kept from the evaluation while they fit in this
many bytes (a small interface then never runs the kernel again); above it, made again."""
_SEGMENT_RULES = (1, 3, 7)
_ELEMENT_RULES = {3: (1, 3, 7), 4: (1, 3, 4, 7, 9)}
_VALUES = ("D", "M", "Dn", "Mn", "gap", "area")
_GRADIENTS = ("Dn_grad", "Mn_grad", "area_grad", "gap_grad", "D_grad", "M_grad")


def covers(geometry: PairGeometry, options: KernelOptions) -> bool:
    """Whether the compiled kernel integrates these pairs with these options: every 3D pair
    of triangles or quadrilaterals with a Gauss rule the kernel takes."""
    none = geometry.part(slice(0, 0))  # the shapes, nothing gathered
    slave_x, master_x = none.slave_x, none.master_x
    if slave_x.ndim != 3 or master_x.ndim != 3 or slave_x.shape[2] != 3:
        return False
    ns, nm = slave_x.shape[1], master_x.shape[1]
    if ns not in (3, 4) or nm not in (3, 4) or master_x.shape[2] != 3:
        return False
    if none.slave_normals is not None and none.slave_normals.shape != slave_x.shape:
        return False
    rule = options.num_gauss_points or 7
    if options.integration == "element":
        return rule in _ELEMENT_RULES[ns]
    return rule in _SEGMENT_RULES


def _pairs_per_call(chunk: int, num_variables: int) -> int:
    """Pairs of ``num_variables`` variables with as many gradient numbers as ``chunk``
    triangle pairs (the gradients grow with the square of the variables)."""
    return max(1, chunk * compiled.NUM_VARIABLES**2 // num_variables**2)


@dataclasses.dataclass(frozen=True)
class _Call:
    """What the C kernel is called with besides the pairs: the facets' nodes, the options,
    and for element-based integration the slave facet's Gauss points and weights."""

    ns: int
    nm: int
    normals: int
    dual_basis: bool
    rule: int
    scalar_gradients: bool
    points: np.ndarray | None = None
    point_weights: np.ndarray | None = None

    @classmethod
    def of(cls, ns: int, nm: int, options: KernelOptions) -> _Call:
        rule = options.num_gauss_points or 7
        points = weights = None
        if options.integration == "element":
            points, weights = (np.ascontiguousarray(a) for a in compiled._facet_rule(ns, rule))
        return cls(ns, nm, compiled._NORMAL_FIELDS[options.normals], options.basis == "dual",
                   rule, options.scalar_gradients, points, weights)

    @property
    def element(self) -> bool:
        return self.points is not None

    @property
    def values_only(self) -> bool:
        """Whether the kernel can make the values without any gradient (segment-based
        pairs: the triangle kernel skips its dual parts, the general one carries no
        derivatives in its dual numbers)."""
        return not self.element

    @property
    def some_gradients(self) -> bool:
        """Whether the kernel can skip some or all gradients (segment-based triangle
        pairs)."""
        return not self.element and self.ns == 3 and self.nm == 3

    @property
    def num_variables(self) -> int:
        return 3 * (2 * self.ns + self.nm)

    @property
    def gradient_names(self) -> tuple[str, ...]:
        return _GRADIENTS if self.scalar_gradients else _GRADIENTS[:4]

    @property
    def gradient_bytes(self) -> int:
        """The bytes of one pair's gradients."""
        shapes = self.shapes()
        return 8 * sum(int(np.prod(shapes[name])) for name in self.gradient_names)

    def shapes(self) -> dict[str, tuple]:
        """The per-pair shapes of the values and of the gradients kept."""
        ns, nm, nv = self.ns, self.nm, self.num_variables
        values = {"D": (ns, ns), "M": (ns, nm), "Dn": (ns, ns, 3), "Mn": (ns, nm, 3),
                  "gap": (ns,), "area": (ns,)}
        grads = {name + "_grad": values[name] + (nv,) for name in ("Dn", "Mn", "area", "gap")}
        if self.scalar_gradients:
            grads.update(D_grad=values["D"] + (nv,), M_grad=values["M"] + (nv,))
        return {**values, **grads}


class _Buffers:
    """The kernel's output arrays for up to ``size`` pairs, reused from call to call (fresh
    arrays of this size would be mapped and faulted in at every call)."""

    def __init__(self, size: int, call: _Call):
        self.size = size
        self.call = call
        self.arrays = {"valid": np.zeros(size, dtype=np.uint8), "overlap": np.empty(size)}
        self.arrays.update({name: np.empty((size,) + shape)
                            for name, shape in call.shapes().items()})

    def run(self, slave_x, master_x, slave_normals, crosspoint, on_master=None,
            gradients: tuple[str, ...] | None = None) -> dict:
        """The kernel on up to ``size`` pairs (as :func:`_run`); returns views of the first m
        rows of the buffers."""
        m = slave_x.shape[0]
        out = {name: array[:m] for name, array in self.arrays.items()}
        _run(self.call, slave_x, master_x, slave_normals, crosspoint, on_master, out,
             gradients)
        return out


def _run(call: _Call, slave_x, master_x, slave_normals, crosspoint, on_master, out: dict,
         gradients: tuple[str, ...] | None = None) -> None:
    """The kernel on m pairs (contiguous float64 (m, ns or nm, 3) arrays; crosspoint (m, ns)
    uint8 or None; element-based: on_master (m, q) uint8, the Gauss points given to each
    pair), written into ``out``: contiguous arrays of m rows, ``valid`` (uint8), ``overlap``,
    the values and the gradients made. ``gradients``: the names of the gradients to make
    (None: all the call keeps; fewer only for :attr:`_Call.some_gradients` calls, none for
    :attr:`_Call.values_only` calls, whose
    ``out`` then needs no others); the others are neither made nor written."""
    m = slave_x.shape[0]
    if m == 0:
        return
    module = compiled._get()
    ffi, lib = module.ffi, module.lib

    def pointer(array, ctype="double *"):
        return compiled._pointer(ffi, array, ctype)

    pairs = (pointer(slave_x), pointer(master_x), pointer(slave_normals),
             pointer(crosspoint, "unsigned char *"))
    grads = out
    if gradients is not None:
        if not (call.some_gradients or (call.values_only and not gradients)):
            raise ValueError("only segment-based triangle pairs make some gradients only, "
                             "only segment-based pairs none")
        grads = {name: out[name] for name in gradients}
    results = (pointer(out["valid"], "unsigned char *"), pointer(out["overlap"]),
               *(pointer(out[name]) for name in _VALUES),
               pointer(grads.get("D_grad")), pointer(grads.get("M_grad")),
               *(pointer(grads.get(name)) for name in ("Dn_grad", "Mn_grad", "gap_grad",
                                                       "area_grad")))
    if call.element:
        status = lib.surface3_element(
            m, call.ns, call.nm, *pairs, call.normals, int(call.dual_basis),
            call.points.shape[0], pointer(call.points), pointer(call.point_weights),
            pointer(on_master, "unsigned char *"), *results)
    elif call.ns == 3 and call.nm == 3:
        status = lib.surface3_triangles(m, *pairs, call.normals, int(call.dual_basis),
                                        call.rule, *results)
    else:
        status = lib.surface3_pairs(m, call.ns, call.nm, *pairs, call.normals,
                                    int(call.dual_basis), call.rule, *results)
    if status != 0:
        raise RuntimeError(f"compiled 3D kernel failed (status {status}): a clip polygon "
                           "outgrew its slots or a bad rule")


def _contiguous(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float64)


class CompiledGradients:
    """The gradients of the contributing pairs of one compiled evaluation
    (:class:`~.contract.GradientsOnDemand`): ``kept`` from the evaluation, or else made
    again by the kernel on the asked pairs' coordinates (kept for the contributing pairs
    only, with their Gauss points when element-based)."""

    chunk = GRADIENT_CHUNK
    """Triangle pairs asked for at once; quadrilateral pairs fewer, as many numbers."""

    def __init__(self, rows: np.ndarray, call: _Call, slave_x, master_x, slave_normals,
                 crosspoint, on_master, kept: dict[str, np.ndarray] | None = None):
        """``slave_x``, ``master_x``, ``slave_normals``: those of the pairs ``rows``;
        ``crosspoint``, ``on_master``: of every pair (or None)."""
        self.rows = rows
        self.kept = kept
        self.call = call
        self.slave_x, self.master_x, self.slave_normals = slave_x, master_x, slave_normals
        self.crosspoint = None if crosspoint is None else np.ascontiguousarray(crosspoint[rows])
        self.on_master = None if on_master is None else np.ascontiguousarray(on_master[rows])
        self.chunk = _pairs_per_call(type(self).chunk, call.num_variables)
        self._buffers: _Buffers | None = None
        self._keep_when_asked = False

    def keep(self, now: bool = True) -> None:
        """Make the gradients of every contributing pair and keep them: now, or (``now``
        False) when they are first asked for (the reference configuration never asks:
        its integrals are frozen)."""
        self._keep_when_asked = not now
        if not now:
            return
        names = self._names()
        # one call into arrays of every pair, which are then kept (no copy out of buffers)
        out = _Buffers(self.rows.size, self.call).run(
            self.slave_x, self.master_x, self.slave_normals, self.crosspoint, self.on_master,
            gradients=names if self.call.some_gradients else None)
        self.kept = {name: out[name] for name in names}
        self._buffers = None

    def _names(self) -> tuple[str, ...]:
        return self.call.gradient_names

    def _run(self, index: np.ndarray, names: tuple[str, ...]) -> dict:
        """The kernel on the kept pairs ``index`` (at most a buffer of them), making the
        gradients ``names``."""
        def kept(array):
            return None if array is None else array[index]

        some = names if self.call.some_gradients else None
        return self._buffers.run(self.slave_x[index], self.master_x[index],
                                 self.slave_normals[index], kept(self.crosspoint),
                                 kept(self.on_master), gradients=some)

    def gradients(self, rows: np.ndarray, outputs=None) -> list[np.ndarray | None]:
        """As :meth:`~.contract.GradientsOnDemand.gradients`; for up to :attr:`chunk`
        contributing rows, views of the kernel's buffers, overwritten by the next call."""
        names = self._names()
        if outputs is not None:
            asked = {names[i] for i in outputs}
            names = tuple(name for name in names if name in asked)
        return [result if name in names else None
                for name, result in zip(self._names(), self._made(rows, names), strict=True)]

    def _made(self, rows: np.ndarray, names: tuple[str, ...]) -> list[np.ndarray | None]:
        """The gradients ``names`` of ``rows`` in the order of :meth:`_names` (None for the
        others): copied from the kept ones, or made by the kernel."""
        if self._keep_when_asked:
            self.keep()
        rows = np.asarray(rows)
        kept = self.rows
        position = np.minimum(np.searchsorted(kept, rows), max(kept.size - 1, 0))
        found = kept[position] == rows if kept.size else np.zeros(rows.shape, dtype=bool)
        result: dict[str, np.ndarray] = {}
        if self.kept is not None:
            for name in names:
                grad = self.kept[name]
                result[name] = np.zeros((rows.size,) + grad.shape[1:])
                result[name][found] = grad[position[found]]
            return [result.get(name) for name in self._names()]
        if self._buffers is None:
            self._buffers = _Buffers(self.chunk, self.call)
        size = self._buffers.size
        if found.all() and rows.size <= size:
            out = self._run(position, names)
            return [out[name] if name in names else None for name in self._names()]
        shapes = self.call.shapes()
        result = {name: np.zeros((rows.size,) + shapes[name]) for name in names}
        asked = np.flatnonzero(found)
        for start in range(0, asked.size, size):
            part = asked[start:start + size]
            out = self._run(position[part], names)
            for name in names:
                result[name][part] = out[name]
        return [result.get(name) for name in self._names()]


class _KeptGradients:
    """The contributing pairs' gradients of an evaluation whose kernel makes them with the
    values (element-based pairs), copied out of the kernel's buffers chunk by
    chunk (in the order of the candidates, that of the rows) while they fit in
    :data:`KEPT_GRADIENTS_BYTES`; given up, and then made again on demand, above it."""

    def __init__(self, call: _Call):
        self.names = call.gradient_names
        self.pair_bytes = call.gradient_bytes
        self.parts: dict[str, list[np.ndarray]] | None = {name: [] for name in self.names}
        self.count = 0

    def add(self, out: dict) -> None:
        if self.parts is None:
            return
        valid = out["valid"].view(bool)
        self.count += int(valid.sum())
        if self.count * self.pair_bytes > KEPT_GRADIENTS_BYTES:
            self.parts = None
            return
        for name in self.names:
            self.parts[name].append(out[name][valid])

    def arrays(self) -> dict[str, np.ndarray] | None:
        if self.parts is None or not self.parts[self.names[0]]:
            return None
        return {name: np.concatenate(parts) for name, parts in self.parts.items()}


def _points_on_master(call: _Call, n: int, arrays,
                      slave_facet: np.ndarray | None) -> np.ndarray:
    """(n, q) uint8: the Gauss points each pair gets (element-based), from the C kernel's
    scores of every pair, in chunks (``arrays(index)``: the pairs' coordinates)."""
    q = call.points.shape[0]
    score = np.empty((n, q))
    module = compiled._get()
    ffi, lib = module.ffi, module.lib
    d = "double *"
    for start in range(0, n, EVALUATION_CHUNK):
        part = slice(start, min(n, start + EVALUATION_CHUNK))
        coordinates = arrays(part)  # (held here: the pointers do not keep them)
        status = lib.surface3_element_scores(
            part.stop - start, call.ns, call.nm, *(compiled._pointer(ffi, array, d)
                                                   for array in coordinates),
            call.normals, q, compiled._pointer(ffi, call.points, d),
            compiled._pointer(ffi, score[part], d))
        if status != 0:
            raise RuntimeError(f"compiled 3D element scores failed (status {status})")
    facets = np.arange(n) if slave_facet is None else np.asarray(slave_facet).reshape(-1)
    return np.ascontiguousarray(compiled.points_on_master(score, facets), dtype=np.uint8)


def _gathered(geometry: IndexedPairGeometry, part):
    """slave_x, master_x and slave_normals (zeros if none) of the pairs ``part`` (a slice or
    indices) gathered by
    C from the node tables (as :meth:`~.contract.IndexedPairGeometry.part`, without numpy's
    fancy indexing); None for tables C does not read (not float64 rows of 3, indices not
    int32 with contiguous columns)."""
    ffi, lib = (module := compiled._get()).ffi, module.lib
    tables = [(geometry.node_x, geometry.slave_nodes), (geometry.node_x, geometry.master_nodes)]
    if geometry.normals is not None:
        tables.append((geometry.normals, geometry.normal_rows))
    result = []
    for table, index in tables:
        index = index[part]
        if (table.dtype != np.float64 or table.ndim != 2 or table.shape[1] != 3
                or not table.flags.c_contiguous or index.dtype != np.int32 or index.ndim != 2
                or index.strides[1] != 4 or index.strides[0] % 4):
            return None
        out = np.empty(index.shape + (3,))
        if index.shape[0]:
            status = lib.gather_rows(
                index.shape[0], index.shape[1], compiled._pointer(ffi, table, "double *"),
                table.shape[0], ffi.cast("int *", index.ctypes.data), index.strides[0] // 4,
                compiled._pointer(ffi, out, "double *"))
            if status != 0:
                raise IndexError("a pair's node index outside its node table")
        result.append(out)
    if geometry.normals is None:
        result.append(np.zeros_like(result[0]))
    return tuple(result)


class _Screened:
    """What an evaluation keeps of its candidates: every candidate's ``valid`` and
    ``overlap``, the contributing ones' values (appended a chunk at a time, in the
    candidates' order)."""

    def __init__(self, n: int, call: _Call):
        self.valid = np.zeros(n, dtype=np.uint8)
        self.overlap = np.zeros(n)
        self.shapes = call.shapes()
        self._parts: dict[str, list[np.ndarray]] = {name: [] for name in _VALUES}

    def keep(self, out: dict) -> None:
        contributing = np.flatnonzero(out["valid"])
        for name in _VALUES:
            self._parts[name].append(np.take(out[name], contributing, axis=0))

    def take_values(self) -> dict[str, np.ndarray]:
        """The kept values, joined one output at a time, each output's chunks let go as it is
        joined (so the join holds one output twice, not all of them; a second call has
        none)."""
        joined = {}
        for name in _VALUES:
            parts, self._parts[name] = self._parts[name], []
            joined[name] = (np.concatenate(parts) if parts
                            else np.zeros((0,) + self.shapes[name]))
            del parts
        return joined


def _screen_values_only(call: _Call, n: int, arrays, cross) -> _Screened:
    """Every candidate screened on plain values, a chunk at a time into the same buffers;
    the contributing pairs' values kept (their gradients are made afterwards, or on
    demand)."""
    screened = _Screened(n, call)
    size = min(VALUES_CHUNK, max(n, 1))
    buffers = {name: np.empty((size,) + screened.shapes[name]) for name in _VALUES}
    for start in range(0, n, size):
        part = slice(start, min(n, start + size))
        out = {"valid": screened.valid[part], "overlap": screened.overlap[part],
               **{name: buffer[:part.stop - start] for name, buffer in buffers.items()}}
        _run(call, *arrays(part), None if cross is None else cross[part], None, out,
             gradients=())
        screened.keep(out)
    return screened


def _screen_element_based(call: _Call, n: int, arrays, cross, slave_facet):
    """The candidates given Gauss points, with their gradients (kept while they fit):
    (:class:`_Screened`, the Gauss points of each pair, the gradients kept or None)."""
    screened = _Screened(n, call)
    on_master = _points_on_master(call, n, arrays, slave_facet)
    candidates = np.flatnonzero(on_master.any(axis=1))
    size = _pairs_per_call(EVALUATION_CHUNK, call.num_variables)
    buffers = _Buffers(min(size, max(candidates.size, 1)), call)
    keeping = _KeptGradients(call)
    for start in range(0, candidates.size, buffers.size):
        part = candidates[start:start + buffers.size]
        out = buffers.run(*arrays(part), None if cross is None else cross[part], on_master[part])
        screened.valid[part] = out["valid"]
        screened.overlap[part] = out["overlap"]
        screened.keep(out)
        keeping.add(out)
    return screened, on_master, keeping.arrays()


def evaluate(geometry: PairGeometry, options: KernelOptions,
             crosspoint: np.ndarray | None = None,
             slave_facet: np.ndarray | None = None) -> PairQuantities:
    """The pairs' values by the compiled kernel (:func:`covers` must hold), their gradients
    on demand (``gradients_on_demand``; the outputs' ``grad`` also works, for every
    contributing pair at once). ``slave_facet``: as :meth:`~.contract.MortarKernel.evaluate`
    (element-based integration). The coordinates are gathered a chunk of pairs at a time
    (:meth:`~.contract.IndexedPairGeometry.part`)."""
    n = geometry.num_pairs
    none = geometry.part(slice(0, 0))
    ns, nm = none.slave_x.shape[1], none.master_x.shape[1]

    def arrays(index) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """slave_x, master_x, slave_normals (zeros if none) of the pairs ``index``,
        contiguous."""
        if isinstance(geometry, IndexedPairGeometry):
            gathered = _gathered(geometry, index)
            if gathered is not None:
                return gathered
        part = geometry.part(index)
        slave_x = _contiguous(part.slave_x)
        normals = part.slave_normals
        return (slave_x, _contiguous(part.master_x),
                np.zeros_like(slave_x) if normals is None else _contiguous(normals))

    call = _Call.of(ns, nm, options)
    cross = None
    if crosspoint is not None:
        cross = np.ascontiguousarray(np.asarray(crosspoint, dtype=bool).reshape(n, ns),
                                     dtype=np.uint8)
    on_master = kept = None
    if call.values_only:
        screened = _screen_values_only(call, n, arrays, cross)
    else:
        screened, on_master, kept = _screen_element_based(call, n, arrays, cross, slave_facet)
    values = screened.take_values()
    valid = screened.valid.view(bool)
    rows = np.flatnonzero(valid)
    source = CompiledGradients(rows, call, *arrays(rows), cross, on_master, kept)
    if call.values_only and rows.size * call.gradient_bytes <= KEPT_GRADIENTS_BYTES:
        source.keep(now=False)
    names = ("Dn", "Mn", "area", "gap") + (("D", "M") if options.scalar_gradients else ())
    cached: list = []

    def all_gradients(index: int):
        def make():
            if not cached:
                cached.append([np.array(grad) for grad in source.gradients(rows)])
            return cached[0][index]
        return make

    duals = {name: RowSubsetDual(values[name], rows, all_gradients(i), n)
             for i, name in enumerate(names)}
    return PairQuantities(
        D_rows=values["D"], M_rows=values["M"], Dn=duals["Dn"], Mn=duals["Mn"],
        gap=duals["gap"], area=duals["area"], valid=valid, overlap=screened.overlap,
        num_variables=call.num_variables, D_dual=duals.get("D"), M_dual=duals.get("M"),
        gradients_on_demand=source)
