"""Shared pytest setup: garbage collection and rank synchronisation between tests.

dolfinx and petsc4py objects hold collective resources; collecting them at the
same point on every rank, and waiting for all ranks after each test, keeps a
failure on one rank from turning into a hang on another.
"""

from __future__ import annotations

import gc

import pytest
from mpi4py import MPI


@pytest.fixture(autouse=True)
def _collect_and_synchronise():
    # no automatic collection inside a test: it would run at a rank-dependent moment
    # and free dolfinx objects whose destructors are collective (a hang on sid, 2 ranks)
    gc.disable()
    try:
        yield
    finally:
        gc.enable()
    gc.collect()
    MPI.COMM_WORLD.Barrier()


@pytest.fixture
def comm():
    return MPI.COMM_WORLD
