"""K_c, the condensed solve's inner matrix, filled from the Newton matrix J in place.

:class:`~dolfinx_mortar.condensation.CondensedPreconditioner` never copies the
displacement block A = J[u, u]: its rows are J's first local rows (the layout puts each
rank's displacements first) and :class:`DisplacementBlock` renumbers J's columns to A's.
K_c equals A away from the contact and the condensed products' rows near it;
:class:`InnerMatrix` merges the two into one CSR matrix without their stored zeros (J's
pattern holds entries that are zero at this state: Dirichlet columns, inactive nodes),
which algebraic multigrid would otherwise carry into its coarse levels. Its layout is
kept as masks (a byte an entry) while J's pattern, the products' and the zeros hold, so
that a Newton iteration on the same active set only copies values.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

COPY_CHUNK = 1 << 20
"""Entries :func:`masked_copy_by_rows` copies at a time (about)."""


class DisplacementBlock:
    """A = J[u, u] as J's first ``num_u`` local rows: ``column`` maps J's global columns to
    A's (-1 at the multipliers'); ``first`` and ``sizes`` are this rank's first row and
    (local, global) sizes in A's numbering, ``j_first`` its first row in J's. Collective.

    Args:
        comm: communicator.
        J: the monolithic matrix (its row ownership).
        u_rows: this rank's monolithic rows of the displacements (must be its first rows).
    """

    def __init__(self, comm: MPI.Intracomm, J: PETSc.Mat, u_rows: np.ndarray):
        first = J.getOwnershipRange()[0]
        num_u = len(u_rows)
        if not np.array_equal(u_rows, first + np.arange(num_u)):
            raise ValueError("the condensation needs each rank's displacement rows first")
        counts = np.array(comm.allgather(num_u), dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)])
        ranges = J.getOwnershipRanges()
        column = np.full(J.getSize()[1], -1, dtype=PETSc.IntType)
        for rank, count in enumerate(counts):
            column[ranges[rank]:ranges[rank] + count] = np.arange(
                starts[rank], starts[rank + 1], dtype=PETSc.IntType)
        self.num_u = num_u
        self.column = column
        self.j_first = first
        self.first = int(starts[comm.rank])
        self.sizes = (num_u, int(starts[-1]))

    def csr(self, J: PETSc.Mat) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """J's CSR arrays of the displacement rows (views; columns in J's numbering)."""
        indptr, indices, values = J.getValuesCSR()
        end = indptr[self.num_u]
        return indptr[: self.num_u + 1], indices[:end], values[:end]


class InnerMatrix:
    """K_c without its stored zeros (the diagonal kept): A's rows, with the condensed rows
    ``K_rows`` in the rows near the contact.

    For hypre's BoomerAMG it is made a hypre matrix (``MATHYPRE``) at once: given an AIJ
    matrix, PETSc's hypre preconditioner converts it into hypre's own and keeps both, the
    copy with an AIJ delegate and its COO maps, and the conversion's temporaries come on
    top at the set-up's peak (docs/benchmarks.md); the inner Krylov method multiplies with
    hypre's matrix as well as with an AIJ.

    Args:
        comm: communicator.
        block_size: the displacement block size (the matrix's, for AMG's nodal coarsening).
    """

    def __init__(self, comm: MPI.Intracomm, block_size: int):
        self.comm = comm
        self.block_size = block_size
        self._layout: dict | None = None
        self._a_part: dict | None = None

    def forget_layout(self) -> None:
        """The next fill builds the merged layout anew (the products' patterns changed)."""
        self._layout = None

    def reset(self) -> None:
        """The next fill builds everything anew (J's pattern changed)."""
        self._layout = self._a_part = None

    def fill(self, J: PETSc.Mat, A: DisplacementBlock, rows: np.ndarray, K_rows: PETSc.Mat,
             existing: PETSc.Mat | None, matrix_type: str = "aij") -> PETSc.Mat:
        """K_c from J's displacement rows and ``K_rows`` (the local ``rows`` near the
        contact, in order): a new matrix of ``matrix_type`` (``aij`` or ``hypre``) or, while
        the layout holds (J's pattern, the products' patterns and the zeros), new values of
        ``existing`` if there is one. Collective."""
        a_csr, k_csr = A.csr(J), K_rows.getValuesCSR()
        a_indptr, a_values, k_values = a_csr[0], a_csr[2], k_csr[2]
        a_part = self._a_part
        a_moved = a_part is not None and bool(np.any(a_values[a_part["dropped"]] != 0.0))
        layout = self._layout
        fresh = self.comm.allreduce(
            layout is None or a_moved
            or bool(np.any(k_values[layout["k_dropped"]] != 0.0)), op=MPI.LOR)
        if fresh:
            if a_part is None or a_moved:
                outside = np.ones(A.num_u, dtype=bool)
                outside[rows] = False
                a_part = self._a_part = _kept_entries(a_csr, A.j_first, np.arange(A.num_u),
                                                      outside)
            layout = self._layout = self._merged_layout(A, rows, a_part, a_csr[1], k_csr)
        del a_csr  # (its column indices: 4 bytes an entry of A)
        from_a = layout["from_a"]
        values = np.empty(from_a.size)
        masked_copy_by_rows(values, layout["indptr"], from_a, a_values, a_indptr,
                            a_part["kept"])
        del a_values
        values[~from_a] = k_values[layout["k_kept"]]
        if existing is not None and not fresh:
            existing.setValuesCSR(layout["indptr"], layout["indices"], values)
            existing.assemble()
            return existing
        if matrix_type == "hypre":
            return self._hypre_matrix(A, layout["indptr"], layout["indices"], values)
        matrix = PETSc.Mat().createAIJ(size=(A.sizes, A.sizes), bsize=self.block_size,
                                       csr=(layout["indptr"], layout["indices"], values),
                                       comm=self.comm)
        matrix.assemble()
        return matrix

    def _hypre_matrix(self, A: DisplacementBlock, indptr: np.ndarray, indices: np.ndarray,
                      values: np.ndarray) -> PETSc.Mat:
        """The CSR rows as a hypre matrix, preallocated exactly."""
        matrix = PETSc.Mat().create(self.comm)
        matrix.setSizes((A.sizes, A.sizes), bsize=self.block_size)
        matrix.setType(PETSc.Mat.Type.HYPRE)
        inside = (indices >= A.first) & (indices < A.first + A.num_u)
        lengths = np.diff(indptr)
        diagonal = np.zeros(lengths.size, dtype=PETSc.IntType)
        if inside.size:
            diagonal[:] = np.add.reduceat(inside, np.minimum(indptr[:-1], inside.size - 1))
            diagonal[lengths == 0] = 0
        del inside
        matrix.setPreallocationNNZ((diagonal, (lengths - diagonal).astype(PETSc.IntType)))
        matrix.setValuesCSR(indptr, indices, values)
        matrix.assemble()
        return matrix

    @staticmethod
    def _merged_layout(A: DisplacementBlock, rows: np.ndarray, a_part: dict,
                       a_indices: np.ndarray, k_csr: tuple) -> dict:
        """The CSR pattern of A's kept entries (J's column indices ``a_indices``) with those
        of K_rows (``k_csr``) in the ``rows`` near the contact, and which entries come from
        A (each row comes whole from one of them, in order)."""
        k_part = _kept_entries(k_csr, A.first, rows)
        counts = a_part["counts"].copy()
        counts[rows] = k_part["counts"]
        outside = np.ones(A.num_u, dtype=bool)
        outside[rows] = False
        indptr = np.zeros(A.num_u + 1, dtype=PETSc.IntType)
        np.cumsum(counts, out=indptr[1:])
        from_a = np.repeat(outside, counts)
        indices = np.empty(from_a.size, dtype=PETSc.IntType)
        indices[from_a] = A.column[a_indices[a_part["kept"]]]
        if np.any(indices[from_a] < 0):
            raise RuntimeError("a displacement row away from the contact has a multiplier "
                               "column")
        indices[~from_a] = k_csr[1][k_part["kept"]]
        return {"indptr": indptr, "indices": indices, "from_a": from_a,
                "k_kept": k_part["kept"], "k_dropped": k_part["dropped"]}


def _kept_entries(csr: tuple, first: int, row_of_local: np.ndarray,
                  taken: np.ndarray | None = None) -> dict:
    """Of a matrix's local CSR entries (its local rows the displacement rows
    ``row_of_local``, numbered from ``first``), those in the rows ``taken`` (a mask over
    the local rows; None: all) that are nonzero or diagonal: as a mask over the entries,
    the positions of the dropped ones, and the kept entries per local row."""
    indptr, indices, values = csr
    lengths = np.diff(indptr)
    diagonal = indices == np.repeat((row_of_local + first).astype(indices.dtype), lengths)
    kept = (values != 0.0) | diagonal
    del diagonal
    if taken is not None:
        in_rows = np.repeat(taken, lengths)
        dropped = np.flatnonzero(in_rows & ~kept)
        kept &= in_rows
        del in_rows
    else:
        dropped = np.flatnonzero(~kept)
    starts = np.minimum(indptr[:-1], max(kept.size - 1, 0))
    counts = (np.add.reduceat(kept, starts, dtype=np.int64) if kept.size
              else np.zeros(lengths.size, dtype=np.int64))
    counts[lengths == 0] = 0
    return {"kept": kept, "dropped": dropped, "counts": counts}


def masked_copy_by_rows(target: np.ndarray, target_indptr: np.ndarray,
                        target_mask: np.ndarray, source: np.ndarray,
                        source_indptr: np.ndarray, source_mask: np.ndarray) -> None:
    """``target[target_mask] = source[source_mask]`` for two CSR value arrays of the same
    rows whose masked entries match row by row, in order; a block of rows at a time, so
    that no temporary has the size of either (A's kept values would take 8 bytes an
    entry of K_c at the set-up's peak)."""
    num_rows = target_indptr.size - 1
    step = max(1, num_rows * COPY_CHUNK // max(int(source_indptr[-1]), 1))
    for first in range(0, num_rows, step):
        last = min(num_rows, first + step)
        t0, t1 = target_indptr[first], target_indptr[last]
        s0, s1 = source_indptr[first], source_indptr[last]
        target[t0:t1][target_mask[t0:t1]] = source[s0:s1][source_mask[s0:s1]]
