"""glibc's malloc as PETSc's libraries leave it, and how we set it back.

Debian's SuperLU_DIST (which libpetsc links, 8.2 in trixie, 9.2 in sid) turns glibc's
mmap allocations and heap trimming off in two static initializers
(``mallopt(M_MMAP_MAX, 0)``, ``mallopt(M_TRIM_THRESHOLD, -1)``): once petsc4py is
imported, no freed memory goes back to the system. A contact solve makes and frees
large temporaries (the bulk pattern, the condensation's CSR copies, BoomerAMG's
hierarchy at each set-up); with mmap off the resident set only grows and its peak is the
sum of them. :func:`release_freed_memory` gives allocations of :data:`MMAP_THRESHOLD`
bytes and more their own mappings again (returned when freed) and trims the heap's top
above :data:`TRIM_THRESHOLD`; smaller allocations stay on the heap (docs/benchmarks.md,
"glibc's malloc under PETSc" and "mmap from 4 MiB").

It is called when a contact problem with a condensed (iterative) solve is made, before
its set-up's temporaries (the bulk matrix and its CSR copy, freed before the first
solve); its set-ups make more of them at every new pattern. Not for the direct path:
MUMPS allocates its workspace anew at each factorization, which then gets fresh zeroed
pages every time instead of the heap's reused ones, for no lower peak
(docs/benchmarks.md, "Blocks for the overlapping pairs only; the direct path's malloc").
"""

from __future__ import annotations

import ctypes
import os
import platform

MMAP_THRESHOLD = 4 * 1024 * 1024
"""Allocations of at least this many bytes are mapped on their own. Below glibc's largest
dynamic threshold (32 MiB): BoomerAMG's coarser levels and the set-up's mid-sized
temporaries, made anew at every set-up in other sizes, otherwise stayed on the heap as
holes the next ones did not fit; small enough arrays (the kernels' per-chunk work) stay
on the heap and pay no page faults."""

TRIM_THRESHOLD = 2 * MMAP_THRESHOLD
"""Free memory at the heap's top beyond this many bytes goes back to the system."""

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_MMAP_MAX = -1, -3, -4
_GLIBC_MMAP_MAX = 65536


def user_tunes_malloc(environ=os.environ) -> bool:
    """Whether the environment sets glibc's malloc parameters (``MALLOC_*_`` variables or
    ``glibc.malloc`` tunables): then they are the user's to keep."""
    return ("glibc.malloc" in environ.get("GLIBC_TUNABLES", "")
            or any(name.startswith("MALLOC_") and name.endswith("_") for name in environ))


def release_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds (:data:`MMAP_THRESHOLD`,
    :data:`TRIM_THRESHOLD`) unless the user tunes malloc; whether it did. Per process,
    idempotent; nothing on other C libraries."""
    if platform.libc_ver()[0] != "glibc" or user_tunes_malloc():
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # pragma: no cover
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all(mallopt(parameter, value) == 1 for parameter, value in (
        (_M_MMAP_THRESHOLD, MMAP_THRESHOLD), (_M_TRIM_THRESHOLD, TRIM_THRESHOLD),
        (_M_MMAP_MAX, _GLIBC_MMAP_MAX)))
