"""Compiled mortar kernels: C source compiled at first use through cffi, cached across processes.

As FFCx compiles dolfinx's form kernels: each C source next to this file (``surface3.c``, the
3D triangle kernel; ``line2.c``, the 2D kernel) is its own module, loaded with
:func:`load` (``load("line2")``). Its source, declarations, the compiler flags and the cffi and
Python versions are hashed into the module's name; the module is compiled once into a cache
directory and loaded from there by every later process. The cache directory is
``$DOLFINX_MORTAR_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/dolfinx_mortar``, else
``~/.cache/dolfinx_mortar``.

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

import fcntl
import hashlib
import importlib.machinery
import importlib.util
import logging
import os
import pathlib
import platform
import shutil
import sys
import tempfile
import time

import numpy as np

_LOG = logging.getLogger(__name__)
# -O3: 1.5x faster than -O2 on the 3D kernel (benchmarks/compiled_kernel.py), portable (no
# -march: the cache may be shared across machines); no FMA contraction, so that the values
# (and the clip decisions made on them) follow the numpy kernels' operation order
COMPILE_ARGS = ("-O3", "-ffp-contract=off", "-std=c99")
_CDEFS = {
    "surface3": """
int surface3_triangles(long n, const double *xs, const double *xm, const double *nn,
                       const unsigned char *crosspoint, int dual_basis, int rule,
                       unsigned char *valid, double *overlap,
                       double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                       double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                       double *garea);
""",
    "line2": """
void line2_screen(long n, const double *x, const unsigned char *has_neighbour, int normals,
                  int element, int num_points, const double *points, unsigned char *valid,
                  double *screened);
void line2_integrate(long num_rows, const long *rows, const double *x,
                     const unsigned char *has_neighbour, const unsigned char *crosspoint,
                     const unsigned char *on_master, int normals, int element, int num_points,
                     const double *points, const double *weights, const double *dual_basis,
                     unsigned char *contributes,
                     double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                     double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                     double *garea);
""",
}
KERNELS = tuple(_CDEFS)
NUM_VARIABLES = 27
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


def _source(kernel: str) -> str:
    if kernel not in _CDEFS:
        raise ValueError(f"unknown compiled kernel {kernel!r}; expected one of {KERNELS}")
    return pathlib.Path(__file__).with_name(kernel + ".c").read_text()


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
                        built = _compile(kernel, name, work, compile_args)
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
    """The compiled module of ``kernel`` (``surface3`` or ``line2``), built or loaded from the
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


def _pointer(ffi, array: np.ndarray | None, ctype: str):
    if array is None:
        return ffi.NULL
    return ffi.cast(ctype, ffi.from_buffer(array))


def pair_quantities_compiled(slave_x, master_x, slave_normals, *, basis: str = "standard",
                             crosspoint=None, num_gauss_points: int | None = None,
                             scalar_gradients: bool = False) -> dict:
    """Segment-based mortar integrals of triangle pairs with averaged normals, compiled.

    The same quantities as :func:`dolfinx_mortar.kernels.surface3.pair_quantities` with
    ``normals="averaged"``, ``integration="segment"``, for ns = nm = 3, as plain arrays
    (leading axis: the pair): values ``D``, ``M`` (n, 3, 3), ``Dn``, ``Mn`` (n, 3, 3, 3),
    ``gap``, ``area`` (n, 3), ``valid`` (n,) bool, ``overlap`` (n,); full gradients over
    the pair's 27 variables (slave xyz, master xyz, slave nodal normals) ``Dn_grad``,
    ``Mn_grad`` (n, 3, 3, 3, 27), ``gap_grad``, ``area_grad`` (n, 3, 27), and with
    ``scalar_gradients`` ``D_grad``, ``M_grad`` (n, 3, 3, 27). Zero where not valid.
    """
    if basis not in ("standard", "dual"):
        raise ValueError(f"unknown multiplier basis {basis!r}; expected standard or dual")
    rule = num_gauss_points or 7
    if rule not in (1, 3, 7):
        raise ValueError(f"3D segments take 1, 3 or 7 Gauss points per cell, got {rule}")
    slave_x = np.ascontiguousarray(slave_x, dtype=np.float64)
    master_x = np.ascontiguousarray(master_x, dtype=np.float64)
    slave_normals = np.ascontiguousarray(slave_normals, dtype=np.float64)
    n = slave_x.shape[0]
    for name, array in (("slave_x", slave_x), ("master_x", master_x),
                        ("slave_normals", slave_normals)):
        if array.shape != (n, 3, 3):
            raise ValueError(f"{name} must be (n, 3, 3) (triangles), got {array.shape}")
    cross = None
    if crosspoint is not None:
        cross = np.ascontiguousarray(np.asarray(crosspoint, dtype=bool).reshape(n, 3),
                                     dtype=np.uint8)
    nv = NUM_VARIABLES
    out = {
        "valid": np.zeros(n, dtype=np.uint8), "overlap": np.empty(n),
        "D": np.empty((n, 3, 3)), "M": np.empty((n, 3, 3)),
        "Dn": np.empty((n, 3, 3, 3)), "Mn": np.empty((n, 3, 3, 3)),
        "gap": np.empty((n, 3)), "area": np.empty((n, 3)),
        "Dn_grad": np.empty((n, 3, 3, 3, nv)), "Mn_grad": np.empty((n, 3, 3, 3, nv)),
        "gap_grad": np.empty((n, 3, nv)), "area_grad": np.empty((n, 3, nv)),
    }
    if scalar_gradients:
        out["D_grad"] = np.empty((n, 3, 3, nv))
        out["M_grad"] = np.empty((n, 3, 3, nv))
    if n == 0:
        out["valid"] = out["valid"].astype(bool)
        return out
    module = _get()
    ffi, lib = module.ffi, module.lib
    d = "double *"
    status = lib.surface3_triangles(
        n, _pointer(ffi, slave_x, d), _pointer(ffi, master_x, d),
        _pointer(ffi, slave_normals, d), _pointer(ffi, cross, "unsigned char *"),
        int(basis == "dual"), rule,
        _pointer(ffi, out["valid"], "unsigned char *"), _pointer(ffi, out["overlap"], d),
        *(_pointer(ffi, out[key], d) for key in ("D", "M", "Dn", "Mn", "gap", "area")),
        _pointer(ffi, out.get("D_grad"), d), _pointer(ffi, out.get("M_grad"), d),
        *(_pointer(ffi, out[key], d) for key in ("Dn_grad", "Mn_grad", "gap_grad",
                                                  "area_grad")))
    if status == -1:
        raise ValueError(f"bad rule {rule}")
    if status != 0:
        raise RuntimeError(f"pair {-2 - status}: clip polygon with more than 8 vertices")
    out["valid"] = out["valid"].astype(bool)
    return out


_LINE2_NORMALS = {"averaged": 0, "slave": 1, "master": 2}


def line2_pair_quantities_compiled(x, has_neighbour, *, normals: str = "averaged",
                                   integration: str = "segment", basis: str = "standard",
                                   num_gauss_points: int | None = None, crosspoint=None,
                                   slave_facet=None, scalar_gradients: bool = False) -> dict:
    """The 2D mortar integrals of every pair, compiled.

    The same quantities as :func:`dolfinx_mortar.kernels.line2.pair_quantities` (the same
    arguments: ``x`` (n, 6, 2) the nodes ``p, a, b, q, c, d``, ``has_neighbour`` (n, 2); the
    default Gauss points those of :class:`~dolfinx_mortar.kernels.line2.Line2Kernel`), as plain
    arrays: values ``D``, ``M`` (n, 2, 2), ``Dn``, ``Mn`` (n, 2, 2, 2), ``gap``, ``area``
    (n, 2), ``valid`` (n,) bool, ``overlap`` (n,), zero where not valid; ``rows``, the pairs
    that were integrated (the numpy kernel's ``rows``: outside them every output is zero), and
    the gradients over the 12 pair variables of those rows only (the others' are zero, and most
    candidate pairs do not overlap): ``Dn_grad``, ``Mn_grad`` (r, 2, 2, 2, 12), ``gap_grad``,
    ``area_grad`` (r, 2, 12), ``D_grad`` (r, 2, 2, 12) (the covered dual basis needs it), and
    with ``scalar_gradients`` ``M_grad`` (r, 2, 2, 12).
    """
    from . import line2
    from .contract import KernelOptions

    KernelOptions(normals=normals, integration=integration, basis=basis)  # (checks them)
    element = integration == "element"
    points, weights = line2.gauss_legendre(
        num_gauss_points or line2.DEFAULT_GAUSS_POINTS[integration])
    g = points.size
    x = np.ascontiguousarray(np.asarray(x, dtype=np.float64).reshape(-1, 12))
    n = x.shape[0]
    has = np.ascontiguousarray(np.asarray(has_neighbour, dtype=bool).reshape(n, 2),
                               dtype=np.uint8)
    cross = None
    if crosspoint is not None:
        cross = np.ascontiguousarray(np.asarray(crosspoint, dtype=bool).reshape(n, 2),
                                     dtype=np.uint8)
    module = load("line2")
    ffi, lib = module.ffi, module.lib
    d, u8 = "double *", "unsigned char *"
    normal_code = _LINE2_NORMALS[normals]

    valid = np.zeros(n, dtype=np.uint8)
    screened = np.empty((n, g) if element else n)
    if n:
        lib.line2_screen(n, _pointer(ffi, x, d), _pointer(ffi, has, u8), normal_code,
                         int(element), g, _pointer(ffi, points, d), _pointer(ffi, valid, u8),
                         _pointer(ffi, screened, d))
    valid = valid.astype(bool)
    on_master = None
    if element:
        facets = np.arange(n) if slave_facet is None else np.asarray(slave_facet).reshape(-1)
        on_master = line2._one_master_facet_per_point(screened, valid, facets)
        overlapping = on_master.any(axis=1)
        overlap = np.where(on_master, weights, 0.0).sum(axis=1)
        on_master = np.ascontiguousarray(on_master, dtype=np.uint8)
    else:
        overlapping = (screened > 0.0) & valid
    rows = np.flatnonzero(overlapping).astype(np.int64)
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
        dual = (np.ascontiguousarray(line2._DUAL_COEFFICIENTS, dtype=np.float64)
                if basis == "dual" else None)
        lib.line2_integrate(
            r, ffi.cast("long *", ffi.from_buffer(rows)), _pointer(ffi, x, d),
            _pointer(ffi, has, u8), _pointer(ffi, cross, u8), _pointer(ffi, on_master, u8),
            normal_code, int(element), g, _pointer(ffi, points, d), _pointer(ffi, weights, d),
            _pointer(ffi, dual, d), _pointer(ffi, contributes, u8),
            *(_pointer(ffi, out[key], d) for key in ("D", "M", "Dn", "Mn", "gap", "area")),
            _pointer(ffi, out["D_grad"], d), _pointer(ffi, out.get("M_grad"), d),
            *(_pointer(ffi, out[key], d) for key in ("Dn_grad", "Mn_grad", "gap_grad",
                                                      "area_grad")))
    if not element:
        parallel = rows[contributes == 0]
        valid[parallel] = False
        overlapping[parallel] = False
        overlap = np.where(overlapping, screened, 0.0)
    out["valid"] = valid & overlapping
    out["overlap"] = overlap
    return out
