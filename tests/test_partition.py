"""A parallel run repeats itself: the same mesh on the same ranks is partitioned the same
way every time. PT-Scotch (dolfinx's partitioner) does so only with one thread; tools/run
sets SCOTCH_PTHREAD_NUMBER=1. With more threads the 3D patch test's mesh on 3 ranks came
out split ~250 different ways in 400 runs, and MUMPS' pivoting changed with it."""

from __future__ import annotations

import os

import pytest
from mpi4py import MPI

from dolfinx_mortar import meshes


@pytest.mark.parallel
def test_the_same_mesh_is_partitioned_the_same_way_every_time():
    comm = MPI.COMM_WORLD
    splits = set()
    for _ in range(6):
        tagged = meshes.patch_test_3d(ratio=(3, 7), slave="bottom", cell_type="tetrahedron",
                                      comm=comm)
        topology = tagged.mesh.topology
        splits.add(tuple(comm.allgather(topology.index_map(topology.dim).size_local)))
        del tagged, topology
    assert len(splits) == 1, (
        f"cells per rank differ between identical meshes: {sorted(splits)} "
        f"(SCOTCH_PTHREAD_NUMBER={os.environ.get('SCOTCH_PTHREAD_NUMBER')}; tools/run sets 1)")
