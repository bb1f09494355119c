"""glibc's malloc after PETSc's import, and after dolfinx_mortar.allocator set it back (which a
condensed solve's set-up does).

Each case runs in a fresh interpreter: whether freed memory goes back to the system is a
property of the process, set by the libraries it loaded and the order it loaded them.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import textwrap

import pytest

from dolfinx_mortar import allocator

# frees an array of 256 MiB and prints the resident set before, with and after it (MiB)
_PROBE = textwrap.dedent("""
    import json, sys
    {imports}
    import numpy as np
    def rss():
        for line in open("/proc/self/status"):
            if line.startswith("VmRSS"):
                return int(line.split()[1]) / 1024.0
    before = rss()
    block = np.ones(32 * 1024 * 1024)
    held = rss()
    del block
    print(json.dumps([before, held, rss()]))
""")


def _probe(imports: str, **environment) -> tuple[float, float, float]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    env.update(environment)
    result = subprocess.run([sys.executable, "-c", _PROBE.format(imports=imports)], env=env,
                            capture_output=True, text=True, check=True, timeout=300)
    return tuple(json.loads(result.stdout.strip().splitlines()[-1]))


needs_glibc = pytest.mark.skipif(
    platform.libc_ver()[0] != "glibc" or not os.path.exists("/proc/self/status"),
    reason="glibc's malloc, a Linux /proc")


@needs_glibc
def test_petsc_import_keeps_freed_memory():
    """The premise: after ``import petsc4py.PETSc`` a freed 256 MiB array stays resident
    (SuperLU_DIST's initializers turn mmap and trimming off). If this fails, Debian's
    PETSc no longer does it and the allocator module can go."""
    before, held, after = _probe("import petsc4py.PETSc")
    assert held - before > 200
    assert after - before > 200


_RELEASED = ("import petsc4py.PETSc\nfrom dolfinx_mortar import allocator\n"
             "allocator.release_freed_memory()")


@needs_glibc
def test_release_freed_memory_gives_it_back():
    """After :func:`allocator.release_freed_memory` the same array goes back when freed."""
    before, held, after = _probe(_RELEASED)
    assert held - before > 200
    assert after - before < 20


@needs_glibc
def test_importing_the_package_leaves_malloc_as_petsc_left_it():
    """Importing ``dolfinx_mortar.problem`` changes nothing (a direct solve keeps glibc's
    malloc as PETSc left it): the array stays."""
    before, held, after = _probe("import petsc4py.PETSc\nimport dolfinx_mortar.problem")
    assert after - before > 200


@needs_glibc
def test_malloc_tuned_by_the_user_is_left_alone():
    """With a ``MALLOC_*_`` variable set the user owns malloc: nothing is changed (so the
    array stays, as PETSc's import left it)."""
    before, held, after = _probe(_RELEASED, MALLOC_ARENA_MAX_="2")
    assert after - before > 200


@pytest.mark.parametrize("linear_solver", ["direct", "iterative"])
def test_the_condensed_solve_releases_freed_memory(monkeypatch, linear_solver):
    """Making a problem with a condensed (iterative) solve calls
    :func:`allocator.release_freed_memory`, before the bulk matrix is made (whose CSR copy
    then goes back when freed); a direct one does not (MUMPS's workspace would get fresh
    pages at every factorization)."""
    from stress.common import hertz

    from dolfinx_mortar import compat

    calls, made = [], []
    monkeypatch.setattr(allocator, "release_freed_memory", lambda: calls.append(len(made)))
    create_matrix = compat.create_matrix
    monkeypatch.setattr(compat, "create_matrix",
                        lambda *args: made.append(1) or create_matrix(*args))
    setup = hertz(refinement=0, linear_solver=linear_solver)
    assert made and calls == ([0] if linear_solver == "iterative" else [])
    setup.problem.destroy()


def test_user_tunes_malloc():
    assert not allocator.user_tunes_malloc({"PATH": "/bin", "MALLOC": "x"})
    assert allocator.user_tunes_malloc({"MALLOC_MMAP_THRESHOLD_": "131072"})
    assert allocator.user_tunes_malloc({"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=0"})
    assert not allocator.user_tunes_malloc({"GLIBC_TUNABLES": "glibc.pthread.rseq=0"})
