"""petsc_c: a matrix's local rows read in place equal petsc4py's copy of them."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_mortar.petsc_c import local_blocks


def random_matrix(comm, kind: str, rows_per_rank: int = 7, seed: int = 3) -> PETSc.Mat:
    """A square matrix of ``kind`` with random entries in random columns of every rank."""
    size = rows_per_rank * comm.size
    matrix = PETSc.Mat().create(comm)
    matrix.setSizes(((rows_per_rank, size), (rows_per_rank, size)))
    matrix.setType(kind)
    matrix.setUp()
    matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    generator = np.random.default_rng(seed + comm.rank)
    first = matrix.getOwnershipRange()[0]
    for row in range(first, first + rows_per_rank - 1):  # (the last local row empty)
        columns = np.sort(generator.choice(size, size=min(size, 4), replace=False))
        matrix.setValues([row], columns.astype(PETSc.IntType), generator.normal(size=columns.size))
    matrix.assemble()
    return matrix


@pytest.mark.parallel
@pytest.mark.parametrize("kind", ["aij", "baij"])
def test_local_blocks_hold_the_rows_of_get_values_csr(kind):
    """Row by row, the blocks' (global column, value) entries are getValuesCSR's, and the
    values of an AIJ matrix are PETSc's own memory (another type's are a copy)."""
    comm = MPI.COMM_WORLD
    matrix = random_matrix(comm, kind)
    indptr, indices, values = matrix.getValuesCSR()
    with local_blocks(matrix) as blocks:
        assert len(blocks) == (1 if kind == "baij" or comm.size == 1 else 2)
        for row in range(indptr.size - 1):
            expected = dict(zip(indices[indptr[row]:indptr[row + 1]],
                                values[indptr[row]:indptr[row + 1]], strict=True))
            found = {}
            for block in blocks:
                part = slice(block.indptr[row], block.indptr[row + 1])
                found.update(zip(block.global_columns(part), block.values[part], strict=True))
            assert found == expected
        rows = blocks[0].rows(3)
        assert rows.indptr.size == 4 and rows.values.size == rows.indptr[-1]
    with local_blocks(matrix) as blocks:
        # the views are PETSc's memory: a value written through one is the matrix's
        block = blocks[0]
        row = int(np.searchsorted(block.indptr, 0, side="right")) - 1
        block.values[0] = 42.0
        column = block.global_columns(slice(0, 1))[0]
        original = values[indptr[row] + np.flatnonzero(indices[indptr[row]:indptr[row + 1]]
                                                      == column)[0]]
    indptr, indices, values = matrix.getValuesCSR()
    written = values[indptr[row] + np.flatnonzero(indices[indptr[row]:indptr[row + 1]]
                                                 == column)[0]]
    assert written == (42.0 if kind == "aij" else original)
    matrix.destroy()
