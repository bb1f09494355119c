"""The iterative linear solver's inner matrix: K_c's values without its stored zeros.

K_c keeps the pattern of every product (zeros included) so that its symbolic
parts are reused; algebraic multigrid carried those zeros into dense coarse
levels, so the inner solver is given only the nonzeros. That matrix must be K_c
exactly (the same preconditioner, cheaper), with the block size and the
rigid-body near-nullspace AMG needs.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from stress.common import hertz


@pytest.mark.parallel
@pytest.mark.timeout(300)
def test_inner_matrix_is_k_c_without_its_zeros():
    setup = hertz(refinement=0, linear_solver="iterative")
    outcome = setup.steps(2)
    assert outcome.converged
    condenser = setup.problem._condenser
    K_c = condenser._matrices["K_c"]
    inner = condenser.ksp.getOperators()[0]
    assert inner.handle != K_c.handle
    difference = K_c.copy()
    difference.axpy(-1.0, inner, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert difference.norm(PETSc.NormType.FROBENIUS) == 0.0
    assert inner.getBlockSize() == K_c.getBlockSize() == 2
    assert len(inner.getNearNullSpace().getVecs()) == 6  # 3 modes x 2 bodies
    indptr, indices, values = inner.getValuesCSR()
    first = inner.getOwnershipRange()[0]
    rows = first + np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    assert np.all((values != 0.0) | (indices == rows))
    stored = [MPI.COMM_WORLD.allreduce(matrix.getValuesCSR()[1].size, op=MPI.SUM)
              for matrix in (K_c, inner)]
    assert stored[1] < stored[0]
    setup.destroy()
