"""K_c, the condensed solve's inner matrix, filled from the Newton matrix J in place.

:class:`~dolfinx_mortar.condensation.CondensedPreconditioner` never copies the
displacement block A = J[u, u]: its rows are J's first local rows (the layout puts each
rank's displacements first), read in PETSc's own arrays (:mod:`~dolfinx_mortar.petsc_c`:
J's diagonal and off-diagonal blocks), and :class:`DisplacementBlock` renumbers J's
columns to A's. K_c equals A away from the contact and the condensed products' rows near
it; :class:`InnerMatrix` merges the two into one CSR matrix without their stored zeros
(J's pattern holds entries that are zero at this state: Dirichlet columns, inactive
nodes), which algebraic multigrid would otherwise carry into its coarse levels. Its
layout is kept (which source each entry comes from, a byte an entry) while J's pattern,
the products' and the zeros hold.
"""

from __future__ import annotations

import contextlib
import typing

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .petsc_c import CsrBlock, local_blocks, preallocate_hypre

COPY_CHUNK = 1 << 20
"""Entries :func:`masked_copy_by_rows` copies at a time (about)."""

FROM_K_ROWS = 0
"""The source code of K_c's entries taken from the condensed rows (A's blocks: 1, 2)."""


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

    @contextlib.contextmanager
    def blocks(self, J: PETSc.Mat) -> typing.Iterator[list[CsrBlock]]:
        """J's displacement rows as CSR blocks of views into J (columns in J's numbering),
        valid inside the block."""
        with local_blocks(J) as blocks:
            yield [block.rows(self.num_u) for block in blocks]


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
        self._a_part: list[dict] | None = None
        self._segments: list[tuple] = []

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
        k_csr = K_rows.getValuesCSR()
        k_values = k_csr[2]
        with A.blocks(J) as a_blocks:
            a_parts = self._a_part
            a_moved = a_parts is not None and any(
                bool(np.any(block.values[part["dropped"]] != 0.0))
                for block, part in zip(a_blocks, a_parts, strict=True))
            layout = self._layout
            fresh = self.comm.allreduce(
                layout is None or a_moved
                or bool(np.any(k_values[layout["k_dropped"]] != 0.0)), op=MPI.LOR)
            if fresh:
                if a_parts is None or a_moved:
                    outside = np.ones(A.num_u, dtype=bool)
                    outside[rows] = False
                    diagonal = A.j_first + np.arange(A.num_u, dtype=np.int64)
                    a_parts = self._a_part = [_kept_entries(block, diagonal, outside)
                                              for block in a_blocks]
                    self._segments = _row_segments(a_blocks, a_parts, A.j_first)
                layout = self._layout = self._merged_layout(A, rows, self._segments,
                                                            a_blocks, k_csr)
            values = np.empty(layout["source"].size)
            for code, (which, kept, _) in enumerate(self._segments, 1):
                block = a_blocks[which]
                masked_copy_by_rows(values, layout["indptr"], layout["source"], block.values,
                                    block.indptr, kept, code)
        values[layout["source"] == FROM_K_ROWS] = k_values[layout["k_kept"]]
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
        """The CSR rows as a hypre matrix, preallocated exactly
        (:func:`~dolfinx_mortar.petsc_c.preallocate_hypre`)."""
        matrix = PETSc.Mat().create(self.comm)
        matrix.setSizes((A.sizes, A.sizes), bsize=self.block_size)
        matrix.setType(PETSc.Mat.Type.HYPRE)
        inside = (indices >= A.first) & (indices < A.first + A.num_u)
        lengths = np.diff(indptr)
        diagonal = row_reduce(np.add, inside, indptr, PETSc.IntType)
        del inside
        # every row set once, whole: hypre writes into its matrix, no auxiliary copy
        matrix.setOption(PETSc.Mat.Option.SORTED_FULL, True)
        preallocate_hypre(matrix, diagonal, lengths - diagonal)
        matrix.setValuesCSR(indptr, indices, values)
        matrix.assemble()
        return matrix

    @staticmethod
    def _merged_layout(A: DisplacementBlock, rows: np.ndarray, segments: list[tuple],
                       a_blocks: list[CsrBlock], k_csr: tuple) -> dict:
        """The CSR pattern of A's kept entries (``segments``, :func:`_row_segments`) with
        those of K_rows (``k_csr``) in the ``rows`` near the contact, and the source of each
        entry (:data:`FROM_K_ROWS`, or the segment's number from 1): a row from A holds its
        segments in turn, so its columns stay in order."""
        k_part = _kept_entries(CsrBlock(*k_csr, columns=None), A.first + rows)
        counts = np.zeros((A.num_u, len(segments) + 1), dtype=np.int64)
        for code, (_, _, segment_counts) in enumerate(segments, 1):
            counts[:, code] = segment_counts
        counts[rows, FROM_K_ROWS] = k_part["counts"]
        indptr = np.zeros(A.num_u + 1, dtype=PETSc.IntType)
        np.cumsum(counts.sum(axis=1), out=indptr[1:])
        codes = np.broadcast_to(np.arange(counts.shape[1], dtype=np.uint8), counts.shape)
        source = np.repeat(codes.reshape(-1), counts.reshape(-1))
        del counts, codes
        indices = np.empty(source.size, dtype=PETSc.IntType)
        for code, (which, kept, _) in enumerate(segments, 1):
            block = a_blocks[which]
            masked_copy_by_rows(indices, indptr, source, block.indices, block.indptr, kept,
                                code, transform=lambda local, columns=block.columns:
                                A.column[columns[local]])
        if np.any(indices[source != FROM_K_ROWS] < 0):
            raise RuntimeError("a displacement row away from the contact has a multiplier "
                               "column")
        indices[source == FROM_K_ROWS] = k_csr[1][k_part["kept"]]
        return {"indptr": indptr, "indices": indices, "source": source,
                "k_kept": k_part["kept"], "k_dropped": k_part["dropped"]}


def _row_segments(blocks: list[CsrBlock], parts: list[dict], first_column: int
                  ) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The kept entries of A's blocks as segments of each row in column order: (block,
    mask over its entries, count per row). One block: itself; an MPIAIJ matrix's two
    (:func:`~dolfinx_mortar.petsc_c.local_blocks`): the off-diagonal block's columns
    before this rank's (``first_column`` on), the diagonal block's, the off-diagonal's
    after. (PETSc's AIJ constructor wants each row's columns in order.)"""
    if len(blocks) == 1:
        return [(0, parts[0]["kept"], parts[0]["counts"])]
    off = blocks[1]
    before = np.zeros(off.indices.size, dtype=bool)
    for start in range(0, off.indices.size, COPY_CHUNK):
        chunk = slice(start, start + COPY_CHUNK)
        before[chunk] = off.columns[off.indices[chunk]] < first_column
    left, right = parts[1]["kept"] & before, parts[1]["kept"] & ~before
    return [(1, left, _row_counts(left, off.indptr)),
            (0, parts[0]["kept"], parts[0]["counts"]),
            (1, right, _row_counts(right, off.indptr))]


def _row_counts(mask: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """The entries of ``mask`` in each CSR row."""
    return row_reduce(np.add, mask, indptr, np.int64)


def row_reduce(ufunc: np.ufunc, entries: np.ndarray, indptr: np.ndarray,
               dtype=None) -> np.ndarray:
    """``ufunc`` over each CSR row's ``entries`` (its identity in an empty row)."""
    lengths = np.diff(indptr)
    result = np.full(lengths.size, ufunc.identity, dtype=dtype or entries.dtype)
    nonempty = lengths > 0
    # (reduceat over the nonempty rows' starts only: an empty row's start is the next
    # row's, or the end of the entries)
    if np.any(nonempty):
        result[nonempty] = ufunc.reduceat(entries, indptr[:-1][nonempty], dtype=dtype)
    return result


def _kept_entries(block: CsrBlock, diagonal: np.ndarray, taken: np.ndarray | None = None
                  ) -> dict:
    """Of a block's entries, those in the rows ``taken`` (a mask over its rows; None: all)
    that are nonzero or diagonal (row i's diagonal column, in the block's ``columns``
    numbering or, without them, in its indices', is ``diagonal[i]``): as a mask over the
    entries, the positions of the dropped ones, and the kept entries per row."""
    indptr, indices, values = block.indptr, block.indices, block.values
    lengths = np.diff(indptr)
    kept = values != 0.0
    num_rows = lengths.size
    step = max(1, num_rows * COPY_CHUNK // max(int(indptr[-1]), 1))
    for first in range(0, num_rows, step):
        last = min(num_rows, first + step)
        e0, e1 = indptr[first], indptr[last]
        columns = indices[e0:e1] if block.columns is None else block.columns[indices[e0:e1]]
        kept[e0:e1] |= columns == np.repeat(diagonal[first:last], lengths[first:last])
    if taken is not None:
        in_rows = np.repeat(taken, lengths)
        dropped = np.flatnonzero(in_rows & ~kept)
        kept &= in_rows
        del in_rows
    else:
        dropped = np.flatnonzero(~kept)
    return {"kept": kept, "dropped": dropped, "counts": _row_counts(kept, indptr)}


def masked_copy_by_rows(target: np.ndarray, target_indptr: np.ndarray,
                        target_source: np.ndarray, source: np.ndarray,
                        source_indptr: np.ndarray, source_mask: np.ndarray,
                        code: int | bool = True,
                        transform: typing.Callable[[np.ndarray], np.ndarray] | None = None
                        ) -> None:
    """``target[target_source == code] = transform(source[source_mask])`` for two CSR
    arrays of the same rows whose selected entries match row by row, in order; a block of
    rows at a time, so that no temporary has the size of either (A's kept values would
    take 8 bytes an entry of K_c at the set-up's peak)."""
    num_rows = target_indptr.size - 1
    step = max(1, num_rows * COPY_CHUNK // max(int(source_indptr[-1]), 1))
    for first in range(0, num_rows, step):
        last = min(num_rows, first + step)
        t0, t1 = target_indptr[first], target_indptr[last]
        s0, s1 = source_indptr[first], source_indptr[last]
        taken = source[s0:s1][source_mask[s0:s1]]
        target[t0:t1][target_source[t0:t1] == code] = (
            taken if transform is None else transform(taken))
