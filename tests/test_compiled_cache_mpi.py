"""MPI ranks that start on an empty kernel cache at the same moment: one compiles, the others
wait for its lock and load the same module (kernels/compiled.py).

Run serially too (one rank: it compiles). Each kernel is built under extra compiler flags
that no other test uses, so the module's name is new to the processes and the cache
directory is empty: the ranks meet the first-use compilation, as a user's first ``mpirun``
does. It is built from the portable flags (no ``-mavx2``), so on a machine with AVX2 the
same build also shows that the default module's vector instructions change no bit.
"""

from __future__ import annotations

import pathlib
import tempfile

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_mortar.kernels import compiled

FRESH_FLAGS = ("-DDOLFINX_MORTAR_CACHE_TEST",)


def shared_empty_directory(comm) -> pathlib.Path:
    """A new directory every rank sees (rank 0 makes it under the system's temporary folder,
    which the ranks of one machine share)."""
    path = tempfile.mkdtemp(prefix="dolfinx_mortar_cache_") if comm.rank == 0 else None
    return pathlib.Path(comm.bcast(path, root=0))


def triangle_pair_overlap(module) -> float:
    """The overlap (a share of the slave facet's area) of a unit right triangle with its copy
    shifted by (1/4, 1/4): a right triangle with legs 1/2, a quarter of the slave."""
    slave = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    master = slave[:, ::-1] + np.array([0.25, 0.25, -0.01])  # facing the slave
    normals = np.tile([0.0, 0.0, 1.0], (1, 3, 1))
    ffi = module.ffi
    valid, overlap = np.zeros(1, dtype=np.uint8), np.zeros(1)
    values = [np.zeros(shape) for shape in ((1, 3, 3), (1, 3, 3), (1, 3, 3, 3), (1, 3, 3, 3),
                                             (1, 3), (1, 3))]
    gradients = [np.zeros((1,) + shape + (compiled.NUM_VARIABLES,))
                 for shape in ((3, 3, 3), (3, 3, 3), (3,), (3,))]

    def pointer(array, ctype="double *"):
        return compiled._pointer(ffi, array, ctype)

    status = module.lib.surface3_triangles(
        1, pointer(slave), pointer(master), pointer(normals), ffi.NULL, 0, 0, 7,
        pointer(valid, "unsigned char *"), pointer(overlap), *(pointer(v) for v in values),
        ffi.NULL, ffi.NULL, *(pointer(g) for g in gradients))
    assert status == 0 and valid[0]
    return float(overlap[0])


def assert_same_bits_as_the_default_module(module) -> None:
    """Triangle and quadrilateral pairs, every output and gradient, through ``module`` and
    through the default one (``compiled.COMPILE_ARGS``): equal bit for bit."""
    from test_compiled_surface3 import random_facets

    from dolfinx_mortar.kernels import KernelOptions
    from dolfinx_mortar.kernels import surface3_compiled as glue

    default = compiled.load("surface3")
    for ns, nm in ((3, 3), (4, 4), (3, 4)):
        slave, master, normals, _ = random_facets(200, ns, nm, seed=ns + nm, noise=0.04)
        call = glue._Call.of(ns, nm, KernelOptions())
        runs = []
        for candidate in (module, default):
            compiled._modules["surface3"] = candidate
            try:
                out = glue._Buffers(200, call).run(slave, master, normals, None)
            finally:
                compiled._modules["surface3"] = default
            runs.append(out)
        assert runs[0]["valid"].sum() > 50
        for name in runs[0]:
            assert np.array_equal(runs[0][name], runs[1][name]), (ns, nm, name)


@pytest.mark.parallel
@pytest.mark.parametrize("kernel", compiled.KERNELS)
def test_ranks_starting_on_an_empty_cache_compile_once(kernel):
    comm = MPI.COMM_WORLD
    directory = shared_empty_directory(comm)
    flags = tuple(compiled.PORTABLE_ARGS) + FRESH_FLAGS
    comm.Barrier()
    try:
        module, info = compiled.build(flags, directory=directory, kernel=kernel)
        names = comm.allgather(info["name"])
        assert comm.allreduce(int(info["compiled"]), op=MPI.SUM) == 1
        assert len(set(names)) == 1
        comm.Barrier()
        built = sorted(p.name for p in directory.iterdir() if not p.name.endswith(".lock"))
        assert built == [pathlib.Path(info["path"]).name]  # no build folder left
        if kernel == "surface3":
            overlap = triangle_pair_overlap(module)
            assert overlap == pytest.approx(0.25, rel=1e-14)
            assert len(set(comm.allgather(overlap))) == 1
            assert_same_bits_as_the_default_module(module)
    finally:
        comm.Barrier()
        if comm.rank == 0:
            import shutil

            shutil.rmtree(directory, ignore_errors=True)
