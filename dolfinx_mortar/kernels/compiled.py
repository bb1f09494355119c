"""Compiled mortar kernels: C source compiled at first use through cffi, cached across processes.

As FFCx compiles dolfinx's form kernels: each C source next to this file (``surface3.c``, the
3D kernel, which includes its general pair path ``surface3_general.h`` twice, the
quadrilaterals' inverse maps ``surface3_bilinear.h`` and its stencil passes
``surface3_stencils.h``; ``line2.c``, the 2D kernel; ``pattern.c``, where the pairs'
dense blocks go in a sparse pattern; ``search.c``, the search's box overlaps) is its own
module, loaded with :func:`load` (``load("line2")``). Its source (local includes inlined),
declarations, the compiler flags and the cffi and Python versions are hashed into the module's
name; the module is compiled once into a cache directory and loaded from there by every later
process. The cache directory is ``$DOLFINX_MORTAR_CACHE_DIR`` if set, else
``$XDG_CACHE_HOME/dolfinx_mortar``, else ``~/.cache/dolfinx_mortar``.

Concurrent processes (MPI ranks starting on an empty cache) do not race: the first to take
an exclusive ``fcntl`` lock on ``<module>.lock`` compiles into a temporary directory inside
the cache and renames the extension module into place atomically; the others wait for the
lock (one per module; at most ``DOLFINX_MORTAR_COMPILE_TIMEOUT`` seconds, default 600, then a
RuntimeError naming the lock file) and find the module there. A reader never sees a
half-written file.

:func:`build_info` tells whether this process compiled a module (and how long it took) or
loaded it from the cache.

Why cffi and C rather than numba: Debian's python3-numba pins one Python minor version
(``python3 (<< 3.15), python3 (>= 3.14~)`` for 0.65), so it drops out of sid whenever sid moves
to the next Python before numba catches up; cffi (``Depends: python3:any``), the C compiler and
python3-dev are what FFCx already needs in both suites (python3-ffcx depends on python3-cffi).
Compiling needs setuptools on Python >= 3.12 (cffi's ``ffi.compile``): sid's python3-cffi
depends on it, trixie's does not (there it comes with python3-ffcx).
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import importlib.machinery
import importlib.util
import logging
import os
import pathlib
import platform
import re
import shutil
import sys
import tempfile
import time

import numpy as np

from . import line2_rules
from .contract import KernelOptions

_LOG = logging.getLogger(__name__)
# -O3: 1.5x faster than -O2 on the 3D kernel (benchmarks/compiled_kernel.py); no FMA
# contraction, so that the values (and the clip decisions made on them) follow the operation
# order of the tests' numpy oracle (tests/oracle), so that the two agree to rounding
PORTABLE_ARGS = ("-O3", "-ffp-contract=off", "-std=c99")


def _vector_args() -> tuple[str, ...]:
    """``-mavx2`` where this CPU has AVX2, else nothing.

    The dual numbers' derivative loops then run 4 doubles wide instead of 2. The bits do not
    change: every operation is the same IEEE addition or multiplication, none is contracted
    or reassociated (tests/test_compiled_cache_mpi.py compares the two builds). The flags are
    part of the module's name, so a cache shared by machines of both kinds holds one module
    for each and none runs where its instructions are missing."""
    if platform.machine() not in ("x86_64", "AMD64"):
        return ()
    try:
        cpuinfo = pathlib.Path("/proc/cpuinfo").read_text()
    except OSError:
        return ()
    return ("-mavx2",) if re.search(r"^flags\s*:.*\bavx2\b", cpuinfo, re.MULTILINE) else ()


COMPILE_ARGS = PORTABLE_ARGS + _vector_args()
_CDEFS = {
    "surface3": """
int surface3_triangles(long n, const double *xs, const double *xm, const double *nn,
                       const unsigned char *crosspoint, int normals, int dual_basis, int rule,
                       unsigned char *valid, double *overlap,
                       double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                       double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                       double *garea);
int surface3_pairs(long n, int ns, int nm, const double *xs, const double *xm, const double *nn,
                   const unsigned char *crosspoint, int normals, int dual_basis, int rule,
                   unsigned char *valid, double *overlap,
                   double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                   double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                   double *garea);
int surface3_element_scores(long n, int ns, int nm, const double *xs, const double *xm,
                            const double *nn, int normals, int q, const double *points,
                            double *score);
int surface3_element(long n, int ns, int nm, const double *xs, const double *xm, const double *nn,
                     const unsigned char *crosspoint, int normals, int dual_basis, int q,
                     const double *points, const double *point_weights,
                     const unsigned char *on_master, unsigned char *valid, double *overlap,
                     double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                     double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                     double *garea);
int gradients_combine(long num_rows, int nv, int size, const double *grad, int num_entries,
                      const int *term, const int *index, const long *weight_start,
                      const int *weight_step, const double *weights, double *out);
void stencil_columns(long num_rows, long row_stride, int num_terms, int nv, int direct, int ns,
                     int width3, const double *kernel, const double *J, double *out);
int gather_rows(long num_rows, int k, const double *table, long table_rows, const int *index,
                long index_stride, double *out);
""",
    "line2": """
int line2_gather(long n, const long *nodes, const double *node_x, long table_rows,
                 double *slave, double *master, double *neighbour);
void line2_screen(long n, const double *slave, const double *master, const double *neighbour,
                  const unsigned char *has_neighbour, int normals, int element,
                  int num_points, const double *points, unsigned char *valid,
                  double *screened);
void line2_integrate(long num_rows, const long *rows, const double *slave,
                     const double *master, const double *neighbour,
                     const unsigned char *has_neighbour, const unsigned char *crosspoint,
                     const unsigned char *on_master, int normals, int element, int num_points,
                     const double *points, const double *weights, const double *dual_basis,
                     unsigned char *contributes,
                     double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                     double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                     double *garea);
int line2_integrate_rows(long num_rows, const long *rows, const double *slave,
                         const double *master, const double *neighbour,
                         const unsigned char *has_neighbour, const unsigned char *crosspoint,
                         const unsigned char *on_master, int normals, int element,
                         int num_points, const double *points, const double *weights,
                         const double *dual_basis, unsigned char *contributes,
                         double *D, double *M, double *Dn, double *Mn, double *gap,
                         double *area, int kept, double *G);
int line2_combine(long num_rows, int kept, const double *G, int num_terms,
                  const int *term_start, const int *output, const long *weight_start,
                  const int *weight_step, const double *weights, double *out);
""",
    "pattern": """
int pattern_positions(long n, int nr, int nc, const int *rows, const int *cols,
                      const long *indptr, const int *indices, long num_rows, long num_cols,
                      int *out, int *starts, unsigned short *offsets);
void pattern_sum(long n, int nr, int br, int nc, int bc, const int *positions,
                 const int *starts, const unsigned short *offsets, long stride,
                 const double *values, long count, int group_major, double *sums);
int pattern_sum_part(long n, int nr, int br, int nc, int bc, const int *positions,
                     const int *starts, const unsigned short *offsets, long stride,
                     const long *which, int nk, const long *columns, const double *values,
                     long count, double *sums);
int pattern_union(long num_rows, long a_rows, int a_block, const long *a_indptr,
                  const int *a_indices, const long *b_indptr, const int *b_indices,
                  long *out_indptr, int *out_indices);
int pattern_blocks(long num_rows, int bs, const long *indptr, const int *indices,
                   long *block_indptr, int *block_first);
int pattern_of_groups(long n, int nr, int nc, const int *row_blocks, const int *col_blocks,
                      long num_row_blocks, long num_col_blocks, long *out_indptr,
                      int *out_indices);
""",
    "search": """
int search_boxes(long ns, long nm, int dim, const double *slave_lower,
                 const double *slave_upper, const double *master_lower,
                 const double *master_upper, double margin, long **pairs, long *num_pairs,
                 long *tested);
void search_free(long *pairs);
""",
}
KERNELS = tuple(_CDEFS)
NUM_VARIABLES = 27  # of a triangle pair; 3 (2 ns + nm) for ns slave and nm master nodes
LINE2_NUM_VARIABLES = 12

_modules: dict = {}
_infos: dict = {}


def cache_dir() -> pathlib.Path:
    """Where compiled modules are kept (see the module docstring)."""
    explicit = os.environ.get("DOLFINX_MORTAR_CACHE_DIR")
    if explicit:
        return pathlib.Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return pathlib.Path(base) / "dolfinx_mortar"


_LOCAL_INCLUDE = re.compile(r'^#include "([\w.]+)"$', re.MULTILINE)


def _source(kernel: str) -> str:
    """The kernel's C source with its local ``#include "x.h"`` files inlined, so that one
    string is both hashed and compiled."""
    if kernel not in _CDEFS:
        raise ValueError(f"unknown compiled kernel {kernel!r}; expected one of {KERNELS}")
    here = pathlib.Path(__file__).parent
    return _LOCAL_INCLUDE.sub(lambda match: (here / match.group(1)).read_text(),
                              (here / (kernel + ".c")).read_text())


def module_name(compile_args=COMPILE_ARGS, kernel: str = "surface3") -> str:
    """The module's name: a hash of everything its binary depends on."""
    import cffi

    key = "\n".join([_source(kernel), _CDEFS[kernel], " ".join(compile_args), cffi.__version__,
                     sys.version, importlib.machinery.EXTENSION_SUFFIXES[0],
                     platform.machine()])
    return f"_dolfinx_mortar_{kernel}_" + hashlib.sha256(key.encode()).hexdigest()[:24]


def _compile(kernel: str, name: str, directory: pathlib.Path, compile_args) -> pathlib.Path:
    """Compile the module into ``directory``; returns the extension file's path."""
    import cffi

    ffi = cffi.FFI()
    ffi.cdef(_CDEFS[kernel])
    ffi.set_source(name, _source(kernel), extra_compile_args=list(compile_args),
                   libraries=["m"])
    return pathlib.Path(ffi.compile(tmpdir=str(directory), verbose=False))


def _load(name: str, path: pathlib.Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _acquire(lock_file, timeout: float, path: pathlib.Path) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            fcntl.flock(lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"waited {timeout:.0f} s for another process compiling the mortar kernels "
                    f"(lock {path}); if no such process runs, remove the lock file") from None
            time.sleep(0.05)


def build(compile_args=COMPILE_ARGS, directory: pathlib.Path | None = None,
          kernel: str = "surface3"):
    """The compiled module (``.ffi``, ``.lib``) of ``kernel`` for ``compile_args``: loaded from
    the cache, compiled there first if absent. Returns (module, info)."""
    directory = pathlib.Path(directory) if directory is not None else cache_dir()
    name = module_name(compile_args, kernel)
    target = directory / (name + importlib.machinery.EXTENSION_SUFFIXES[0])
    start = time.perf_counter()
    info = {"name": name, "path": str(target), "compiled": False}
    if not target.exists():
        directory.mkdir(parents=True, exist_ok=True)
        timeout = float(os.environ.get("DOLFINX_MORTAR_COMPILE_TIMEOUT", "600"))
        lock_path = directory / (name + ".lock")
        with open(lock_path, "a") as lock_file:
            _acquire(lock_file, timeout, lock_path)
            try:
                if not target.exists():  # nobody built it while we waited
                    work = pathlib.Path(tempfile.mkdtemp(prefix=name + "-", dir=directory))
                    try:
                        try:
                            built = _compile(kernel, name, work, compile_args)
                        except Exception as error:  # cffi's, distutils' or the compiler's
                            raise RuntimeError(
                                f"could not compile the mortar kernels ({kernel}.c) into "
                                f"{directory}: {error}. They are the package's only kernels "
                                "and need what dolfinx's form compilation needs: cffi (with "
                                "setuptools on Python >= 3.12), a C compiler (cc, or $CC) and "
                                "the Python headers (python3-dev); install them, or point "
                                "$CC at a working compiler") from error
                        os.replace(built, target)  # atomic within one file system
                    finally:
                        shutil.rmtree(work, ignore_errors=True)
                    info["compiled"] = True
                    info["compile_seconds"] = time.perf_counter() - start
                    _LOG.info("compiled %s in %.2f s", target, info["compile_seconds"])
            finally:
                fcntl.flock(lock_file, fcntl.LOCK_UN)
    module = _load(name, target)
    info["seconds"] = time.perf_counter() - start
    return module, info


def load(kernel: str = "surface3"):
    """The compiled module of ``kernel`` (one of :data:`KERNELS`), built or loaded from the
    cache on this process's first use."""
    if kernel not in _modules:
        module, info = build(kernel=kernel)
        _infos[kernel] = info
        _modules[kernel] = module
    return _modules[kernel]


def _get():
    return load("surface3")


def build_info(kernel: str = "surface3") -> dict:
    """How this process got the module of ``kernel``: ``compiled`` (bool), ``seconds`` (compile
    or load), ``path``; empty before the first use."""
    return dict(_infos.get(kernel, {}))


def packed_weights(weights, num_rows: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The weights of a C combination pass (``line2_combine``, ``gradients_combine``): each a
    number or one per row, packed as (weight_start int64, weight_step int, values), weight e
    of row r being values[weight_start[e] + r * weight_step[e]]."""
    step = np.array([np.ndim(w) != 0 for w in weights], dtype=np.intc)
    lengths = np.where(step == 1, num_rows, 1)
    start = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    values = np.empty(int(lengths.sum()))
    for e, w in enumerate(weights):
        values[start[e]:start[e] + lengths[e]] = np.ravel(w)
    return start, step, values


def _pointer(ffi, array: np.ndarray | None, ctype: str):
    """``array`` as a C argument of type ``ctype`` (``"double *"``...): a cdata that holds
    the array alive, so that a temporary array given to a call outlives the call."""
    if array is None:
        return ffi.NULL
    if not ctype.endswith("*"):
        raise ValueError(f"a pointer type, got {ctype!r}")
    return ffi.from_buffer(ctype[:-1].strip() + "[]", array)


_NORMAL_FIELDS = {"averaged": 0, "slave": 1, "master": 2}
_A1, _B1, _A2, _B2 = 0.059715871789770, 0.470142064105115, 0.797426985353087, 0.101286507323456
_TRIANGLE_RULES = {  # barycentric points, weights summing to 1
    1: ([[1 / 3, 1 / 3, 1 / 3]], [1.0]),
    3: ([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]], [1 / 3] * 3),
    7: ([[1 / 3, 1 / 3, 1 / 3], [_A1, _B1, _B1], [_B1, _A1, _B1], [_B1, _B1, _A1],
         [_A2, _B2, _B2], [_B2, _A2, _B2], [_B2, _B2, _A2]],
        [0.225] + [0.132394152788506] * 3 + [0.125939180544827] * 3),
}


def _facet_rule(nodes: int, rule: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss points (q, 2) and weights on the slave reference facet of element-based
    integration: a triangle's symmetric rule (weights summing to 1/2); a
    quadrilateral's 1, 2 x 2 or 3 x 3 Gauss-Legendre rule (3 and 7 read as 4 and 9)."""
    if nodes == 3:
        if rule not in _TRIANGLE_RULES:
            raise ValueError(f"element-based triangles take 1, 3 or 7 Gauss points, got {rule}")
        bary, weights = _TRIANGLE_RULES[rule]
        return np.array(bary)[:, 1:].copy(), 0.5 * np.array(weights)
    per_direction = {1: 1, 3: 2, 4: 2, 7: 3, 9: 3}.get(rule)
    if per_direction is None:
        raise ValueError(f"element-based quadrilaterals take 1, 4 or 9 Gauss points, got {rule}")
    g, w = np.polynomial.legendre.leggauss(per_direction)
    return (np.array([[a, b] for a in g for b in g]),
            np.array([wa * wb for wa in w for wb in w]))


def points_on_master(score: np.ndarray, slave_facet: np.ndarray) -> np.ndarray:
    """(n, q) mask: each Gauss point of a slave facet goes to the pair (of that slave facet)
    whose master facet it lands on most centrally (the first such pair on ties); ``score``
    (n, q): how far outside its master facet each point lands, inf where it misses. The
    rule of both 3D kernels' element-based integration."""
    n, q = score.shape
    flat = score.ravel()
    key = np.repeat(np.asarray(slave_facet, dtype=np.int64) * q, q) + np.tile(np.arange(q), n)
    order = np.lexsort((flat, key))
    first = np.ones(order.size, dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    winner = np.zeros(order.size, dtype=bool)
    winner[order[first]] = True
    return (winner & np.isfinite(flat)).reshape(n, q)


def _checked_surface3_options(normals: str, basis: str, integration: str,
                              num_gauss_points: int | None) -> int:
    """The Gauss rule of 3D pair options, after refusing unknown ones."""
    if basis not in ("standard", "dual"):
        raise ValueError(f"unknown multiplier basis {basis!r}; expected standard or dual")
    if normals not in _NORMAL_FIELDS:
        raise ValueError(f"unknown normal field {normals!r}; expected one of "
                         f"{sorted(_NORMAL_FIELDS)}")
    if integration not in ("segment", "element"):
        raise ValueError(f"unknown integration {integration!r}; expected segment or element")
    rule = num_gauss_points or 7
    if integration == "segment" and rule not in (1, 3, 7):
        raise ValueError(f"3D segments take 1, 3 or 7 Gauss points per cell, got {rule}")
    return rule


def pair_quantities_compiled(slave_x, master_x, slave_normals, *, normals: str = "averaged",
                             basis: str = "standard", crosspoint=None,
                             num_gauss_points: int | None = None,
                             scalar_gradients: bool = False, pointwise: bool = False,
                             integration: str = "segment", slave_facet=None) -> dict:
    """Mortar integrals of triangle or quadrilateral pairs, compiled.

    The quantities of :class:`~dolfinx_mortar.kernels.Surface3Kernel` (and of the tests'
    numpy oracle, ``tests/oracle/surface3_numpy.py``) (``integration`` ``segment`` or
    ``element``; with ``element``, ``slave_facet`` (n,) says which pairs share a slave facet:
    each of its Gauss points goes to one of them), for ns, nm in {3, 4} slave and master
    nodes, as plain arrays
    (leading axis: the pair): values ``D`` (n, ns, ns), ``M`` (n, ns, nm), ``Dn``
    (n, ns, ns, 3), ``Mn`` (n, ns, nm, 3), ``gap``, ``area`` (n, ns), ``valid`` (n,) bool,
    ``overlap`` (n,); full gradients over the pair's nv = 3 (2 ns + nm) variables (slave xyz,
    master xyz, slave nodal normals) ``Dn_grad``, ``Mn_grad``, ``gap_grad``, ``area_grad``
    (the value's shape + (nv,)), and with ``scalar_gradients`` ``D_grad``, ``M_grad``. Zero
    where not valid.

    A triangle on a triangle takes the corner-value path (the oracle's ``_affine_integrals``)
    unless ``pointwise``; quadrilaterals are integrated at every Gauss point (the oracle's
    pointwise path).
    """
    rule = _checked_surface3_options(normals, basis, integration, num_gauss_points)
    slave_x = np.ascontiguousarray(slave_x, dtype=np.float64)
    master_x = np.ascontiguousarray(master_x, dtype=np.float64)
    slave_normals = np.ascontiguousarray(slave_normals, dtype=np.float64)
    if slave_x.ndim != 3 or master_x.ndim != 3:
        raise ValueError("slave_x and master_x must be (n, nodes, 3)")
    n, ns = slave_x.shape[:2]
    nm = master_x.shape[1]
    for name, array, nodes in (("slave_x", slave_x, ns), ("master_x", master_x, nm),
                               ("slave_normals", slave_normals, ns)):
        if array.shape != (n, nodes, 3) or nodes not in (3, 4):
            raise ValueError(f"{name} must be (n, 3 or 4, 3) (triangles or quadrilaterals) "
                             f"matching the pairs, got {array.shape}")
    cross = None
    if crosspoint is not None:
        cross = np.ascontiguousarray(np.asarray(crosspoint, dtype=bool).reshape(n, ns),
                                     dtype=np.uint8)
    nv = 3 * (2 * ns + nm)
    out = {
        "valid": np.zeros(n, dtype=np.uint8), "overlap": np.empty(n),
        "D": np.empty((n, ns, ns)), "M": np.empty((n, ns, nm)),
        "Dn": np.empty((n, ns, ns, 3)), "Mn": np.empty((n, ns, nm, 3)),
        "gap": np.empty((n, ns)), "area": np.empty((n, ns)),
        "Dn_grad": np.empty((n, ns, ns, 3, nv)), "Mn_grad": np.empty((n, ns, nm, 3, nv)),
        "gap_grad": np.empty((n, ns, nv)), "area_grad": np.empty((n, ns, nv)),
    }
    if scalar_gradients:
        out["D_grad"] = np.empty((n, ns, ns, nv))
        out["M_grad"] = np.empty((n, ns, nm, nv))
    if n == 0:
        out["valid"] = out["valid"].astype(bool)
        return out
    module = _get()
    ffi, lib = module.ffi, module.lib
    d = "double *"
    arrays = (
        _pointer(ffi, slave_x, d), _pointer(ffi, master_x, d), _pointer(ffi, slave_normals, d),
        _pointer(ffi, cross, "unsigned char *"))
    results = (
        _pointer(ffi, out["valid"], "unsigned char *"), _pointer(ffi, out["overlap"], d),
        *(_pointer(ffi, out[key], d) for key in ("D", "M", "Dn", "Mn", "gap", "area")),
        _pointer(ffi, out.get("D_grad"), d), _pointer(ffi, out.get("M_grad"), d),
        *(_pointer(ffi, out[key], d) for key in ("Dn_grad", "Mn_grad", "gap_grad",
                                                  "area_grad")))
    if integration == "element":
        points, point_weights = _facet_rule(ns, rule)
        q = points.shape[0]
        points = np.ascontiguousarray(points)
        score = np.empty((n, q))
        status = lib.surface3_element_scores(
            n, ns, nm, *arrays[:3], _NORMAL_FIELDS[normals], q, _pointer(ffi, points, d),
            _pointer(ffi, score, d))
        if status != 0:
            raise ValueError("bad element-based arguments")
        on_master = np.ascontiguousarray(points_on_master(
            score, np.arange(n) if slave_facet is None else np.asarray(slave_facet).reshape(-1)),
            dtype=np.uint8)
        status = lib.surface3_element(
            n, ns, nm, *arrays, _NORMAL_FIELDS[normals], int(basis == "dual"), q,
            _pointer(ffi, points, d), _pointer(ffi, np.ascontiguousarray(point_weights), d),
            _pointer(ffi, on_master, "unsigned char *"), *results)
    elif ns == 3 and nm == 3 and not pointwise:
        status = lib.surface3_triangles(n, *arrays, _NORMAL_FIELDS[normals],
                                        int(basis == "dual"), rule, *results)
    else:
        status = lib.surface3_pairs(n, ns, nm, *arrays, _NORMAL_FIELDS[normals],
                                    int(basis == "dual"), rule, *results)
    if status == -1:
        raise ValueError(f"bad rule {rule}")
    if status != 0:
        raise RuntimeError(f"pair {-2 - status}: clip polygon with more than 8 vertices")
    out["valid"] = out["valid"].astype(bool)
    return out


OFFSET_LIMIT = 65535
"""Rows of a pattern shorter than this let :func:`pattern_positions` give positions as
:class:`RowOffsets` (2 bytes an entry instead of 4)."""


@dataclasses.dataclass
class RowOffsets:
    """Positions (nr, nc, G) kept as each entry's place within its row: entry (i, j, g) is
    at ``starts[i, g] + offsets[i, j, g]`` (0 where the offset is 0: not in the pattern).
    A group's block repeats its rows' starts, so this holds 2 bytes an entry (and 4 a row)
    where :func:`pattern_positions`' int32 positions hold 4."""

    starts: np.ndarray
    """(nr, G) int32: the first index of each group's row in the pattern."""
    offsets: np.ndarray
    """(nr, nc, G) uint16: 1 + the entry's place within its row, 0 where it has none."""

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.offsets.shape

    def take(self, index: np.ndarray) -> RowOffsets:
        """The positions of the groups ``index``."""
        return RowOffsets(np.ascontiguousarray(np.take(self.starts, index, axis=1)),
                          np.ascontiguousarray(np.take(self.offsets, index, axis=2)))

    def put(self, mask: np.ndarray, other: RowOffsets) -> None:
        """Those of the groups ``mask`` replaced by ``other``'s."""
        self.starts[:, mask] = other.starts
        self.offsets[..., mask] = other.offsets

    def absolute(self) -> np.ndarray:
        """As :func:`pattern_positions`' int32 positions."""
        offsets = self.offsets.astype(np.int64)
        return np.where(offsets > 0, self.starts[:, None, :] + offsets, 0).astype(np.intc)



def take_groups(positions: np.ndarray | RowOffsets, index: np.ndarray):
    """The positions (either kind) of the groups ``index``."""
    if isinstance(positions, RowOffsets):
        return positions.take(index)
    return np.take(positions, index, axis=2)


def put_groups(positions: np.ndarray | RowOffsets, mask: np.ndarray, other) -> None:
    """The positions of the groups ``mask`` replaced by ``other`` (of the same kind)."""
    if isinstance(positions, RowOffsets):
        positions.put(mask, other)
    else:
        positions[..., mask] = other


def _bounds(positions: np.ndarray | RowOffsets, groups: slice) -> tuple[int, int]:
    """(smallest, largest) position of the groups ``groups`` (0, 0 for none)."""
    if isinstance(positions, RowOffsets):
        offsets, starts = positions.offsets[..., groups], positions.starts[:, groups]
        if not offsets.size:
            return 0, 0
        last = offsets.max(axis=1)
        present = np.where(last > 0, starts + last, 0)
        return int(min(0, starts.min())), int(present.max())
    part = positions[..., groups]
    return (int(part.min()), int(part.max())) if part.size else (0, 0)


def _check_positions(positions) -> tuple:
    """The C arguments (positions, starts, offsets) of int32 positions or RowOffsets."""
    if isinstance(positions, RowOffsets):
        if (positions.offsets.dtype != np.uint16 or positions.starts.dtype != np.intc
                or not positions.offsets.flags.c_contiguous
                or not positions.starts.flags.c_contiguous
                or positions.starts.shape != (positions.shape[0], positions.shape[2])):
            raise ValueError("RowOffsets must hold contiguous int32 starts (nr, G) and uint16 "
                             "offsets (nr, nc, G)")
        return None, positions.starts, positions.offsets
    if positions.dtype != np.intc or not positions.flags.c_contiguous:
        raise ValueError(f"positions {positions.dtype} {positions.shape} are not contiguous "
                         "int32")
    return positions, None, None


def pattern_positions(rows: np.ndarray, cols: np.ndarray, indptr: np.ndarray,
                      indices: np.ndarray, row_offsets: bool = False) -> np.ndarray | RowOffsets:
    """(nr, nc, n) int32 (the order of :func:`pattern_sum`'s positions): at (i, j, g), 1 +
    the index into ``indices`` of column ``cols[g, j]`` in row ``rows[g, i]`` of the CSR
    pattern (``indptr``, ``indices``, each row's columns sorted), 0 where the row has no such
    column; ``rows`` (n, nr) and ``cols`` (n, nc) name rows and columns of the pattern. With
    ``row_offsets`` the same as :class:`RowOffsets` where every row of the pattern is
    shorter than :data:`OFFSET_LIMIT`. In C, row by row: a row's positions put once into a
    marker of the columns and read there by every group that has the row (no index array of
    every entry)."""
    rows = np.ascontiguousarray(rows, dtype=np.intc)
    cols = np.ascontiguousarray(cols, dtype=np.intc)
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    indices = np.ascontiguousarray(indices, dtype=np.intc)
    if rows.ndim != 2 or cols.ndim != 2 or rows.shape[0] != cols.shape[0]:
        raise ValueError(f"rows {rows.shape} and cols {cols.shape} must be (n, nr), (n, nc)")
    if indices.size >= 2**31 - 1:
        raise ValueError("pattern_positions takes patterns of fewer than 2^31 entries")
    if rows.size and (rows.min() < 0 or rows.max() >= indptr.size - 1):
        raise IndexError("a group's row outside the pattern")
    shape = (rows.shape[1], cols.shape[1], rows.shape[0])
    compact = row_offsets and (indptr.size < 2 or int(np.diff(indptr).max()) < OFFSET_LIMIT)
    out, starts, offsets = None, None, None
    if compact:
        starts = np.zeros(shape[::2], dtype=np.intc)
        offsets = np.empty(shape, dtype=np.uint16)
    else:
        out = np.empty(shape, dtype=np.intc)
    if rows.size and cols.size:
        num_cols = int(max(indices.max(initial=-1), cols.max(initial=-1)) + 1)
        module = load("pattern")
        ffi = module.ffi
        status = module.lib.pattern_positions(
            rows.shape[0], rows.shape[1], cols.shape[1], _pointer(ffi, rows, "int *"),
            _pointer(ffi, cols, "int *"), _pointer(ffi, indptr, "long *"),
            _pointer(ffi, indices, "int *"), indptr.size - 1, num_cols,
            _pointer(ffi, out, "int *"), _pointer(ffi, starts, "int *"),
            _pointer(ffi, offsets, "unsigned short *"))
        if status != 0:
            raise MemoryError("pattern_positions: no memory for the rows' order")
    return RowOffsets(starts, offsets) if compact else out


def pattern_sum(positions: np.ndarray | RowOffsets, values: np.ndarray, count: int,
                sums: np.ndarray | None = None, start: int = 0,
                group_major: bool = False) -> np.ndarray:
    """sums[a, b, positions[i, j, start + g]] += values[i, a, j, b, g] for the int32
    ``positions`` (nr, nc, G) (or :class:`RowOffsets`) of G groups and ``values`` (nr, br, nc,
    bc, n) of the groups start .. start + n - 1; ``sums`` (br, bc, count + 1), zeros if None,
    is returned (slot 0 takes the dropped entries). Each sum takes its entries in the order
    (i, j, g), or with ``group_major`` (g, i, j), as np.bincount (np.add.at) over them in
    that order would."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    nr, br, nc, bc, n = values.shape
    absolute, starts, offsets = _check_positions(positions)
    if positions.shape[:2] != (nr, nc) or not 0 <= start <= positions.shape[2] - n:
        raise ValueError(f"positions {positions.shape} do not hold the groups {start} .. "
                         f"{start + n - 1} of values {values.shape}")
    if sums is None:
        sums = np.zeros((br, bc, count + 1))
    if sums.shape != (br, bc, count + 1) or sums.dtype != np.float64 or not sums.flags.c_contiguous:
        raise ValueError(f"sums must be contiguous float64 {(br, bc, count + 1)}")
    smallest, largest = _bounds(positions, slice(start, start + n))
    if smallest < 0 or largest > count:
        raise IndexError("a position outside the pattern")
    if values.size:
        module = load("pattern")
        ffi = module.ffi

        def from_start(array, ctype):  # (the group axis is the last: group start's entry)
            return ffi.NULL if array is None else ffi.cast(ctype, array.ctypes.data) + start

        module.lib.pattern_sum(n, nr, br, nc, bc, from_start(absolute, "int *"),
                               from_start(starts, "int *"),
                               from_start(offsets, "unsigned short *"), positions.shape[2],
                               _pointer(ffi, values, "double *"), count, int(group_major),
                               _pointer(ffi, sums, "double *"))
    return sums


def pattern_sum_part(positions: np.ndarray | RowOffsets, values: np.ndarray, count: int,
                     sums: np.ndarray, which: np.ndarray | None = None,
                     columns: np.ndarray | None = None) -> np.ndarray:
    """:func:`pattern_sum` of the values (nr, br, len(columns), bc, len(which)) of the groups
    ``which`` (None: all) on the block columns ``columns`` (None: all) of the int32
    ``positions`` (nr, nc, G) (or :class:`RowOffsets`), added to ``sums`` (br, bc, count +
    1) in pattern_sum's order, with no copy of the positions."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    nr, br, nk, bc, n = values.shape
    absolute, starts, offsets = _check_positions(positions)
    if positions.shape[0] != nr:
        raise ValueError(f"positions {positions.shape} do not hold the rows of values "
                         f"{values.shape}")
    if sums.shape != (br, bc, count + 1) or sums.dtype != np.float64 or not sums.flags.c_contiguous:
        raise ValueError(f"sums must be contiguous float64 {(br, bc, count + 1)}")
    index = [None if a is None else np.ascontiguousarray(a, dtype=np.int64)
             for a in (which, columns)]
    if (n != (positions.shape[2] if index[0] is None else index[0].size)
            or nk != (positions.shape[1] if index[1] is None else index[1].size)):
        raise ValueError(f"values {values.shape} are not those of the groups and columns given")
    if values.size:
        module = load("pattern")
        ffi = module.ffi
        status = module.lib.pattern_sum_part(
            n, nr, br, positions.shape[1], bc, _pointer(ffi, absolute, "int *"),
            _pointer(ffi, starts, "int *"), _pointer(ffi, offsets, "unsigned short *"),
            positions.shape[2], _pointer(ffi, index[0], "long *"), nk,
            _pointer(ffi, index[1], "long *"), _pointer(ffi, values, "double *"), count,
            _pointer(ffi, sums, "double *"))
        if status != 0:
            raise IndexError("a group or column outside the positions")
    return sums


def pattern_union(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray],
                  a_block: int = 1) -> tuple[np.ndarray, np.ndarray] | None:
    """The union (indptr int64, indices int32) of two CSR patterns (indptr, indices), each
    row's columns strictly increasing and below 2^31; None if a row is not (the caller
    merges another way). ``a`` may have fewer rows than ``b`` (the others empty) and be
    blocked (:func:`pattern_blocks`: ``a_block`` x ``a_block`` blocks, its indptr over block
    rows and its indices the blocks' first columns). One pass to count, one to fill."""
    (a_indptr, a_indices), (b_indptr, b_indices) = a, b
    a_rows = (a_indptr.size - 1) * a_block
    if a_rows > b_indptr.size - 1:
        raise ValueError(f"patterns of {a_rows} and {b_indptr.size - 1} rows")
    for indices, width in ((a_indices, a_block), (b_indices, 1)):
        if indices.size and (indices.min() < 0 or indices.max() + width >= 2**31):
            raise ValueError("pattern_union takes columns in [0, 2^31 - 1)")
    arrays = [np.ascontiguousarray(a_indptr, dtype=np.int64),
              np.ascontiguousarray(a_indices, dtype=np.intc),
              np.ascontiguousarray(b_indptr, dtype=np.int64),
              np.ascontiguousarray(b_indices, dtype=np.intc)]
    module = load("pattern")
    ffi = module.ffi
    pointers = [_pointer(ffi, array, ctype) for array, ctype in
                zip(arrays, ("long *", "int *", "long *", "int *"), strict=True)]
    indptr = np.empty(b_indptr.size, dtype=np.int64)
    num_rows = b_indptr.size - 1
    if module.lib.pattern_union(num_rows, a_rows, a_block, *pointers,
                                _pointer(ffi, indptr, "long *"), ffi.NULL) != 0:
        return None
    indices = np.empty(int(indptr[-1]), dtype=np.intc)
    module.lib.pattern_union(num_rows, a_rows, a_block, *pointers,
                             _pointer(ffi, indptr, "long *"), _pointer(ffi, indices, "int *"))
    return indptr, indices


def pattern_blocks(indptr: np.ndarray, indices: np.ndarray,
                   block: int) -> tuple[np.ndarray, np.ndarray] | None:
    """A CSR pattern (indptr, indices) as ``block`` x ``block`` blocks: the block rows' indptr
    (int64) and each block's first column (int32), a ``block``-th of the rows and a
    ``block``^2-th of the columns; None if the pattern is not made of whole blocks (or has
    a number of rows that is not a multiple of ``block``)."""
    num_rows = indptr.size - 1
    if block < 1 or num_rows % block:
        return None
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    indices = np.ascontiguousarray(indices, dtype=np.intc)
    block_indptr = np.empty(num_rows // block + 1, dtype=np.int64)
    block_first = np.empty(indices.size // block**2, dtype=np.intc)
    module = load("pattern")
    ffi = module.ffi
    if module.lib.pattern_blocks(num_rows, block, _pointer(ffi, indptr, "long *"),
                                 _pointer(ffi, indices, "int *"),
                                 _pointer(ffi, block_indptr, "long *"),
                                 _pointer(ffi, block_first, "int *")) != 0:
        return None
    return block_indptr, block_first


def pattern_of_groups(row_blocks: np.ndarray, col_blocks: np.ndarray, num_row_blocks: int,
                      num_col_blocks: int) -> tuple[np.ndarray, np.ndarray]:
    """The block pattern (indptr int64, indices int32; num_row_blocks + 1 rows, the last
    empty, each row's columns sorted) of groups of row and column blocks ((groups, nr) and
    (groups, nc) arrays; a block outside [0, count): none): block row r holds column c
    where some group has both. In C: the groups of each block row by a counting sort, their
    columns marked once a row."""
    if max(num_row_blocks, num_col_blocks) >= 2**31 - 1:
        raise ValueError("pattern_of_groups takes fewer than 2^31 - 1 blocks a side")
    rows = np.ascontiguousarray(row_blocks, dtype=np.intc)
    cols = np.ascontiguousarray(col_blocks, dtype=np.intc)
    if rows.ndim != 2 or cols.ndim != 2 or rows.shape[0] != cols.shape[0]:
        raise ValueError(f"groups of {rows.shape} row and {cols.shape} column blocks")
    module = load("pattern")
    ffi = module.ffi
    indptr = np.empty(num_row_blocks + 2, dtype=np.int64)
    arguments = (rows.shape[0], rows.shape[1], cols.shape[1], _pointer(ffi, rows, "int *"),
                 _pointer(ffi, cols, "int *"), num_row_blocks, num_col_blocks,
                 _pointer(ffi, indptr, "long *"))
    if module.lib.pattern_of_groups(*arguments, ffi.NULL) != 0:
        raise MemoryError("pattern_of_groups: out of memory")
    indices = np.empty(int(indptr[-1]), dtype=np.intc)
    if module.lib.pattern_of_groups(*arguments, _pointer(ffi, indices, "int *")) != 0:
        raise MemoryError("pattern_of_groups: out of memory")
    return indptr, indices


def search_boxes(slave_lower: np.ndarray, slave_upper: np.ndarray, master_lower: np.ndarray,
                 master_upper: np.ndarray, margin: float) -> tuple[np.ndarray, int]:
    """(pairs (n, 2) int64, box tests done): every (slave, master) pair of boxes (lower, upper:
    (num, dim) each) that overlap once each is grown by ``margin``, sorted by slave then
    master. A box with a corner that is not finite (the nodes of a diverged iterate) pairs
    with nothing. In C: per pair of size groups, the masters sorted by their cell of a grid
    as wide as two boxes of the groups, each slave tested against its cell and the
    neighbouring ones."""
    boxes = [np.ascontiguousarray(b, dtype=np.float64)
             for b in (slave_lower, slave_upper, master_lower, master_upper)]
    dim = boxes[0].shape[1]
    if (any(b.ndim != 2 or b.shape[1] != dim for b in boxes) or not 1 <= dim <= 3
            or boxes[0].shape != boxes[1].shape or boxes[2].shape != boxes[3].shape):
        raise ValueError("boxes must be (n, dim) lower and upper corners, dim 1-3")
    module = load("search")
    ffi, lib = module.ffi, module.lib
    pairs, count, tested = ffi.new("long **"), ffi.new("long *"), ffi.new("long *")
    status = lib.search_boxes(boxes[0].shape[0], boxes[2].shape[0], dim,
                              *(_pointer(ffi, b, "double *") for b in boxes), float(margin),
                              pairs, count, tested)
    if status != 0:
        raise MemoryError("search_boxes: out of memory")
    try:
        found = np.frombuffer(ffi.buffer(pairs[0], 16 * count[0]), dtype=np.int64).copy()
    finally:
        lib.search_free(pairs[0])
    return found.reshape(-1, 2), int(tested[0])


def line2_gather(nodes: np.ndarray, node_x: np.ndarray) -> tuple[np.ndarray, ...]:
    """(slave, master, neighbour), each (n, 2, 2): the positions in the node table ``node_x``
    (rows, 2) of the 2D pairs' stencil nodes ``nodes`` (n, 6: p, a, b, q, c, d; slave a b,
    master c d, neighbours p q), in one pass."""
    nodes = np.ascontiguousarray(nodes, dtype=np.int64)
    node_x = np.ascontiguousarray(node_x, dtype=np.float64)
    if nodes.ndim != 2 or nodes.shape[1] != 6 or node_x.ndim != 2 or node_x.shape[1] != 2:
        raise ValueError(f"nodes {nodes.shape} must be (n, 6), node_x {node_x.shape} (rows, 2)")
    out = tuple(np.empty((nodes.shape[0], 2, 2)) for _ in range(3))
    if nodes.size:
        module = load("line2")
        ffi = module.ffi
        status = module.lib.line2_gather(
            nodes.shape[0], _pointer(ffi, nodes, "long *"), _pointer(ffi, node_x, "double *"),
            node_x.shape[0], *(_pointer(ffi, o, "double *") for o in out))
        if status != 0:
            raise IndexError("a stencil node outside the node table")
    return out


_LINE2_NORMALS = {"averaged": 0, "slave": 1, "master": 2}


class Line2Screening:
    """The values-only pass of the compiled 2D kernel over every pair and what it decides:
    which pairs are integrated (``rows``), and element-based which Gauss points count
    (``on_master``). Holds the C arguments of the integration pass too."""

    def __init__(self, slave_x, master_x, neighbour_x, has_neighbour, *, normals: str,
                 integration: str, basis: str, num_gauss_points: int | None, crosspoint,
                 slave_facet):
        KernelOptions(normals=normals, integration=integration, basis=basis)  # (checks them)
        self.element = integration == "element"
        self.points, self.weights = line2_rules.gauss_legendre(
            num_gauss_points or line2_rules.DEFAULT_GAUSS_POINTS[integration])
        n = self.num_pairs = slave_x.shape[0]
        # (the C kernel gathers each pair's 12 variables from these: no copy of them all)
        self.coordinates = [np.ascontiguousarray(np.asarray(array, dtype=np.float64)
                                                 .reshape(n, 2, 2))
                            for array in (slave_x, master_x, neighbour_x)]
        self.has = np.ascontiguousarray(np.asarray(has_neighbour, dtype=bool).reshape(n, 2),
                                        dtype=np.uint8)
        self.cross = None
        if crosspoint is not None:
            self.cross = np.ascontiguousarray(np.asarray(crosspoint, dtype=bool).reshape(n, 2),
                                              dtype=np.uint8)
        self.normal_code = _LINE2_NORMALS[normals]
        self.dual = (np.ascontiguousarray(line2_rules.DUAL_COEFFICIENTS, dtype=np.float64)
                     if basis == "dual" else None)
        self.module = module = load("line2")
        ffi = module.ffi
        g = self.points.size
        valid = np.zeros(n, dtype=np.uint8)
        screened = np.empty((n, g) if self.element else n)
        if n:
            module.lib.line2_screen(
                n, *(_pointer(ffi, array, "double *") for array in self.coordinates),
                _pointer(ffi, self.has, "unsigned char *"),
                self.normal_code, int(self.element), g, _pointer(ffi, self.points, "double *"),
                _pointer(ffi, valid, "unsigned char *"), _pointer(ffi, screened, "double *"))
        self.valid = valid.astype(bool)
        self.screened = screened
        self.on_master = None
        if self.element:
            facets = np.arange(n) if slave_facet is None else np.asarray(slave_facet).reshape(-1)
            on_master = line2_rules.one_master_facet_per_point(screened, self.valid, facets)
            self.overlapping = on_master.any(axis=1)
            self.overlap = np.where(on_master, self.weights, 0.0).sum(axis=1)
            self.on_master = np.ascontiguousarray(on_master, dtype=np.uint8)
        else:
            self.overlapping = (screened > 0.0) & self.valid
        self.rows = np.flatnonzero(self.overlapping).astype(np.int64)

    def arguments(self) -> tuple:
        """The integration pass's arguments from ``rows`` to ``dual_basis`` (C pointers)."""
        ffi = self.module.ffi
        u8, d = "unsigned char *", "double *"
        return (self.rows.size, ffi.cast("long *", ffi.from_buffer(self.rows)),
                *(_pointer(ffi, array, d) for array in self.coordinates),
                _pointer(ffi, self.has, u8),
                _pointer(ffi, self.cross, u8), _pointer(ffi, self.on_master, u8),
                self.normal_code, int(self.element), self.points.size,
                _pointer(ffi, self.points, d), _pointer(ffi, self.weights, d),
                _pointer(ffi, self.dual, d))

    def finish(self, contributes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(valid, overlap) of every pair once the integrated ones said whether they
        contribute (segment-based: not where the master is parallel to the normal at a Gauss
        point)."""
        valid, overlapping = self.valid, self.overlapping
        if not self.element:
            parallel = self.rows[contributes == 0]
            valid[parallel] = False
            overlapping[parallel] = False
            self.overlap = np.where(overlapping, self.screened, 0.0)
        return valid & overlapping, self.overlap


def line2_pair_quantities_compiled(x, has_neighbour, *, normals: str = "averaged",
                                   integration: str = "segment", basis: str = "standard",
                                   num_gauss_points: int | None = None, crosspoint=None,
                                   slave_facet=None, scalar_gradients: bool = False) -> dict:
    """The 2D mortar integrals of every pair, compiled.

    The quantities of :func:`dolfinx_mortar.kernels.line2.pair_quantities` (the same
    arguments: ``x`` (n, 6, 2) the nodes ``p, a, b, q, c, d``, ``has_neighbour`` (n, 2); the
    default Gauss points those of :class:`~dolfinx_mortar.kernels.line2.Line2Kernel`), as plain
    arrays: values ``D``, ``M`` (n, 2, 2), ``Dn``, ``Mn`` (n, 2, 2, 2), ``gap``, ``area``
    (n, 2), ``valid`` (n,) bool, ``overlap`` (n,), zero where not valid; ``rows``, the pairs
    that were integrated (``PairQuantities.rows``: outside them every output is zero), and
    the gradients over the 12 pair variables of those rows only (the others' are zero, and most
    candidate pairs do not overlap): ``Dn_grad``, ``Mn_grad`` (r, 2, 2, 2, 12), ``gap_grad``,
    ``area_grad`` (r, 2, 12), ``D_grad`` (r, 2, 2, 12) (the covered dual basis needs it), and
    with ``scalar_gradients`` ``M_grad`` (r, 2, 2, 12).
    """
    x = np.asarray(x, dtype=np.float64).reshape(-1, 6, 2)
    screening = Line2Screening(x[:, 1:3], x[:, 4:6], x[:, [0, 3]], has_neighbour,
                               normals=normals, integration=integration,
                               basis=basis, num_gauss_points=num_gauss_points,
                               crosspoint=crosspoint, slave_facet=slave_facet)
    n, rows = screening.num_pairs, screening.rows
    r, nv = rows.size, LINE2_NUM_VARIABLES
    out = {
        "D": np.zeros((n, 2, 2)), "M": np.zeros((n, 2, 2)),
        "Dn": np.zeros((n, 2, 2, 2)), "Mn": np.zeros((n, 2, 2, 2)),
        "gap": np.zeros((n, 2)), "area": np.zeros((n, 2)), "rows": rows,
        "Dn_grad": np.empty((r, 2, 2, 2, nv)), "Mn_grad": np.empty((r, 2, 2, 2, nv)),
        "gap_grad": np.empty((r, 2, nv)), "area_grad": np.empty((r, 2, nv)),
        "D_grad": np.empty((r, 2, 2, nv)),
    }
    if scalar_gradients:
        out["M_grad"] = np.empty((r, 2, 2, nv))
    contributes = np.ones(r, dtype=np.uint8)
    if r:
        ffi = screening.module.ffi
        d = "double *"
        screening.module.lib.line2_integrate(
            *screening.arguments(), _pointer(ffi, contributes, "unsigned char *"),
            *(_pointer(ffi, out[key], d) for key in ("D", "M", "Dn", "Mn", "gap", "area")),
            _pointer(ffi, out["D_grad"], d), _pointer(ffi, out.get("M_grad"), d),
            *(_pointer(ffi, out[key], d) for key in ("Dn_grad", "Mn_grad", "gap_grad",
                                                      "area_grad")))
    out["valid"], out["overlap"] = screening.finish(contributes)
    return out
