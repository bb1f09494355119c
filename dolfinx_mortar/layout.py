"""Monolithic numbering of displacements and multipliers in one PETSc system.

Rank r owns a contiguous range of rows: first its displacement dofs, then its
multipliers. MUMPS needs one AIJ matrix, so the saddle-point systems of
mesh tying and Lagrange-multiplier contact are assembled in this numbering;
the maps below translate global displacement and multiplier indices (as
dolfinx and :class:`~dolfinx_mortar.mortar.MortarInterface` number them)
into it, keeping negative indices negative (PETSc ignores those).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


class BlockLayout:
    """Rows [u | z_1 | z_2 | ...] per rank: displacements, then each multiplier field.

    Args:
        comm: communicator.
        num_owned_u: displacement dofs this rank owns (dolfinx numbering is
            contiguous by rank, so global u index = rank offset + local).
        num_owned_z: multipliers this rank owns, one count per multiplier
            field (each field's global numbering is contiguous by rank too).
    """

    def __init__(self, comm: MPI.Intracomm, num_owned_u: int, num_owned_z: int | list[int]):
        self.comm = comm
        counts = [int(num_owned_u)] + ([int(num_owned_z)] if np.isscalar(num_owned_z)
                                       else [int(n) for n in num_owned_z])
        sizes = np.array(comm.allgather(counts), dtype=np.int64).reshape(comm.size, len(counts))
        self.counts = sizes  # (ranks, fields)
        self.field_offsets = np.vstack([np.zeros((1, sizes.shape[1]), dtype=np.int64),
                                        np.cumsum(sizes, axis=0)])  # global start per rank
        self.within_rank = np.hstack([np.zeros((comm.size, 1), dtype=np.int64),
                                      np.cumsum(sizes, axis=1)[:, :-1]])
        self.offsets = np.concatenate([[0], np.cumsum(sizes.sum(axis=1))])
        rank = comm.rank
        self.num_owned = int(sizes[rank].sum())
        self.num_global = int(self.offsets[-1])
        self.num_fields = sizes.shape[1]
        self.num_u = sizes[:, 0]
        self.owned_u = self.owned(0)
        self.owned_z = slice(int(self.within_rank[rank, 1]) if self.num_fields > 1 else self.num_owned,
                             self.num_owned)

    def owned(self, field: int) -> slice:
        """This rank's rows of ``field`` within its owned block."""
        start = int(self.within_rank[self.comm.rank, field])
        return slice(start, start + int(self.counts[self.comm.rank, field]))

    def index(self, field: int, index: np.ndarray) -> np.ndarray:
        """Monolithic index of global indices of ``field`` (negative stays -1)."""
        index = np.asarray(index, dtype=np.int64)
        starts = self.field_offsets[:, field]
        owner = np.clip(np.searchsorted(starts, index, side="right") - 1, 0, self.comm.size - 1)
        mono = index - starts[owner] + self.offsets[owner] + self.within_rank[owner, field]
        return np.where(index >= 0, mono, -1)

    def u(self, index: np.ndarray) -> np.ndarray:
        """Monolithic index of global displacement dofs."""
        return self.index(0, index)

    def z(self, index: np.ndarray, field: int = 1) -> np.ndarray:
        """Monolithic index of global multipliers of a multiplier field (default the first)."""
        return self.index(field, index)

    def create_vector(self) -> PETSc.Vec:
        vector = PETSc.Vec().createMPI((self.num_owned, self.num_global), comm=self.comm)
        vector.zeroEntries()
        return vector

    def create_matrix(self, rows: np.ndarray, cols: np.ndarray) -> CooMatrix:
        """A square matrix in this layout, preallocated for the pattern (rows, cols)."""
        sizes = (self.num_owned, self.num_global)
        return CooMatrix(self.comm, rows, cols, sizes, sizes)


def csr_to_coo(matrix: PETSc.Mat) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global (rows, cols, values) of this rank's rows of an assembled AIJ matrix."""
    indptr, indices, values = matrix.getValuesCSR()
    first = matrix.getOwnershipRange()[0]
    rows = first + np.repeat(np.arange(indptr.size - 1, dtype=np.int64), np.diff(indptr))
    return rows, indices.astype(np.int64), values


def dirichlet_dofs(bcs, V) -> np.ndarray:
    """Global displacement dofs (unrolled) fixed by the Dirichlet conditions, owned here."""
    index_map = V.dofmap.index_map
    block_size = V.dofmap.index_map_bs
    fixed = []
    for bc in bcs:
        local, num_owned = bc.dof_indices()
        local = np.asarray(local[:num_owned], dtype=np.int64)
        blocks = index_map.local_to_global((local // block_size).astype(np.int32))
        fixed.append(blocks * block_size + local % block_size)
    if not fixed:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate(fixed))


class CooMatrix:
    """A parallel AIJ matrix assembled from (row, col, value) triplets.

    The pattern is given once; :meth:`assemble` may then be called any number
    of times with new values in the same order. Duplicates are summed,
    entries with a negative row or column are dropped, rows owned by another
    rank are sent to it by PETSc. The matrix is preallocated exactly (PETSc's
    preallocator) and refuses new nonzeros, so assembly never allocates.
    (petsc4py 3.22 has no MatSetValuesCOO; this is its equivalent.)
    """

    def __init__(self, comm: MPI.Intracomm, rows, cols, row_sizes, col_sizes):
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        cols = np.asarray(cols, dtype=np.int64).reshape(-1)
        self.num_entries = rows.size
        self._keep = np.flatnonzero((rows >= 0) & (cols >= 0))
        rows, cols = rows[self._keep], cols[self._keep]
        order = np.lexsort((cols, rows))
        rows, cols = rows[order], cols[order]
        first = np.ones(rows.size, dtype=bool)
        first[1:] = (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])
        unique_id = np.cumsum(first) - 1
        self._slot = np.empty(rows.size, dtype=np.int64)
        self._slot[order] = unique_id
        self._num_unique = int(first.sum())
        unique_rows, unique_cols = rows[first], cols[first]
        self._rowmap, counts = np.unique(unique_rows, return_counts=True)
        self._rowmap = self._rowmap.astype(PETSc.IntType)
        self._indptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
        self._indices = unique_cols.astype(PETSc.IntType)

        preallocator = PETSc.Mat().create(comm=comm)
        preallocator.setType(PETSc.Mat.Type.PREALLOCATOR)
        preallocator.setSizes((row_sizes, col_sizes))
        preallocator.setUp()
        preallocator.setValuesIJV(self._indptr, self._indices, np.zeros(self._num_unique),
                                  addv=PETSc.InsertMode.INSERT_VALUES, rowmap=self._rowmap)
        preallocator.assemble()
        self.mat = PETSc.Mat().create(comm=comm)
        self.mat.setType(PETSc.Mat.Type.AIJ)
        self.mat.setSizes((row_sizes, col_sizes))
        preallocator.preallocatorPreallocate(self.mat, fill=True)
        preallocator.destroy()
        self.mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        self.mat.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)

    def assemble(self, values) -> PETSc.Mat:
        """Replace the matrix values by the summed ``values`` (same order as the pattern)."""
        values = np.asarray(values, dtype=PETSc.ScalarType).reshape(-1)
        if values.size != self.num_entries:
            raise ValueError(f"expected {self.num_entries} values, got {values.size}")
        summed = np.bincount(self._slot, weights=values[self._keep], minlength=self._num_unique)
        self.mat.zeroEntries()
        self.mat.setValuesIJV(self._indptr, self._indices, summed,
                              addv=PETSc.InsertMode.ADD_VALUES, rowmap=self._rowmap)
        self.mat.assemble()
        return self.mat

    def destroy(self) -> None:
        self.mat.destroy()
