"""Monolithic numbering of displacements and multipliers in one PETSc system, and the
preallocated matrices assembled in it.

Rank r owns a contiguous range of rows: first its displacement dofs, then its
multipliers. MUMPS needs one AIJ matrix, so the saddle-point systems of
mesh tying and Lagrange-multiplier contact are assembled in this numbering;
:class:`BlockLayout` translates global displacement and multiplier indices (as
dolfinx and :class:`~dolfinx_mortar.mortar.MortarInterface` number them)
into it, keeping negative indices negative (PETSc ignores those).

:class:`CooMatrix` is a PETSc matrix of a fixed pattern assembled from
triplets or from dense blocks per group (a mortar pair), preallocated once;
:class:`MonolithicMatrix` is the [u, z] system matrix: the bulk block assembled
in place, the mortar blocks and a diagonal added; :class:`BlockIncidence` holds
the block patterns that several matrices share.
"""

from __future__ import annotations

import functools
import typing

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

INDEX_CHUNK = 1 << 20
"""Indices :meth:`BlockLayout.index` maps at a time."""


class BlockLayout:
    """Rows [u | z_1 | z_2 | ...] per rank: displacements, then each multiplier field.

    Args:
        comm: communicator.
        num_owned_u: displacement dofs this rank owns (dolfinx numbering is
            contiguous by rank, so global u index = rank offset + local).
        num_owned_z: multipliers this rank owns, one count per multiplier
            field (each field's global numbering is contiguous by rank too).

    Collective (the counts of every rank are gathered).

    Examples:
        One rank with 4 displacement dofs and 2 multipliers: the multipliers follow
        the displacements, and a negative index stays negative.

        >>> layout = BlockLayout(MPI.COMM_SELF, 4, 2)
        >>> layout.u([0, 3, -1])
        array([ 0,  3, -1])
        >>> layout.z([0, 1])
        array([4, 5])
        >>> layout.owned_u, layout.owned_z, layout.num_global
        (slice(0, 4, None), slice(4, 6, None), 6)
        >>> BlockLayout(MPI.COMM_SELF, 4, [2, 3]).z([0, 1], field=2)
        array([6, 7])
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
        first_z = int(self.within_rank[rank, 1]) if self.num_fields > 1 else self.num_owned
        self.owned_z = slice(first_z, self.num_owned)

    def owned(self, field: int) -> slice:
        """This rank's rows of ``field`` within its owned block."""
        start = int(self.within_rank[self.comm.rank, field])
        return slice(start, start + int(self.counts[self.comm.rank, field]))

    def index(self, field: int, index: np.ndarray, dtype=np.int64) -> np.ndarray:
        """Monolithic index of global indices of ``field`` (negative stays -1), as
        ``dtype``. Mapped a chunk at a time: a bulk pattern's column indices (some 10^7 a
        rank) would otherwise take several int64 temporaries of their size."""
        index = np.asarray(index)
        if index.dtype.kind not in "iu":
            index = index.astype(np.int64)
        mapped = np.empty(index.shape, dtype=dtype)
        source, target = index.reshape(-1), mapped.reshape(-1)
        starts = self.field_offsets[:, field]
        # per owning rank: monolithic = global + shift
        shifts = self.offsets[:-1] + self.within_rank[:, field] - starts[:-1]
        for begin in range(0, source.size, INDEX_CHUNK):
            part = source[begin:begin + INDEX_CHUNK].astype(np.int64)
            if self.comm.size == 1:
                mono = part + shifts[0]
            else:
                owner = np.searchsorted(starts, part, side="right") - 1
                np.clip(owner, 0, self.comm.size - 1, out=owner)
                mono = part + shifts[owner]
            mono[part < 0] = -1
            target[begin:begin + INDEX_CHUNK] = mono
        return mapped

    def u(self, index: np.ndarray, dtype=np.int64) -> np.ndarray:
        """Monolithic index of global displacement dofs."""
        return self.index(0, index, dtype)

    def u_global(self, index: np.ndarray, dtype=np.int64) -> np.ndarray:
        """Global displacement dof of monolithic displacement indices (the inverse of
        :meth:`u`; negative stays -1), a chunk at a time as :meth:`index`."""
        index = np.asarray(index)
        result = np.empty(index.shape, dtype=dtype)
        source, target = index.reshape(-1), result.reshape(-1)
        shifts = self.field_offsets[:-1, 0] - self.offsets[:-1] - self.within_rank[:, 0]
        for begin in range(0, source.size, INDEX_CHUNK):
            part = source[begin:begin + INDEX_CHUNK].astype(np.int64)
            owner = np.searchsorted(self.offsets, part, side="right") - 1
            np.clip(owner, 0, self.comm.size - 1, out=owner)
            dof = part + shifts[owner]
            dof[part < 0] = -1
            target[begin:begin + INDEX_CHUNK] = dof
        return result

    def z(self, index: np.ndarray, field: int = 1) -> np.ndarray:
        """Monolithic index of global multipliers of a multiplier field (default the first)."""
        return self.index(field, index)

    def create_vector(self) -> PETSc.Vec:
        """A zero vector of this layout (collective)."""
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


def _block_csr_columns(block_cols: np.ndarray, block_starts: np.ndarray,
                       block_lengths: np.ndarray, br: int, bc: int) -> tuple[np.ndarray, list]:
    """(CSR column indices, row starts) of a pattern of dense br x bc blocks.

    ``block_cols`` are the global block columns of the block rows in CSR order, block
    row r holding ``block_lengths[r]`` of them from ``block_starts[r]``. Row (r, a) of
    the matrix holds the columns c * bc + b of the blocks c of block row r. With br > 1
    the row starts list, for each a, the CSR slot (in units of bc) of row a of every
    block: block p of block row r is slot p + (br - 1) start(r) + a length(r); with
    br == 1 the rows' runs of block columns follow each other and the list is empty.
    """
    if br == 1:
        return _interleave(block_cols, bc), []
    num_blocks = block_cols.size
    starts = (br - 1) * block_starts
    block_numbers = np.arange(num_blocks, dtype=np.int64)
    row_starts = [block_numbers + np.repeat(starts + a * block_lengths, block_lengths)
                  for a in range(br)]
    slot_blocks = np.empty(br * num_blocks, dtype=np.int64)
    for start in row_starts:
        slot_blocks[start] = block_numbers
    return _interleave(block_cols[slot_blocks], bc), row_starts


class CooMatrix:
    """A parallel AIJ matrix assembled from (row, col, value) triplets.

    The pattern is given once; :meth:`assemble` may then be called any number
    of times with new values in the same order. Duplicates are summed,
    entries with a negative row or column are dropped, rows owned by another
    rank are sent to it by PETSc. The matrix is preallocated exactly (from
    the pattern in CSR form when this rank owns all its rows, else PETSc's
    preallocator) and refuses new nonzeros, so assembly never allocates.
    (petsc4py 3.22 has no MatSetValuesCOO; this is its equivalent.)

    :meth:`from_blocks` builds the same matrix for a pattern made of dense
    blocks, one per group (a mortar pair), without sorting the entries, and
    :meth:`assemble_groups` assembles the values of a few groups only (the
    others are zero): most candidate pairs of a contact search never overlap.
    In serial, a matrix of :meth:`from_blocks` is made at its first assembly
    around its own CSR arrays (``createAIJWithArrays``, no copy): the values
    are summed straight into PETSc's storage, with no preallocation and no
    insertion.
    """

    def __init__(self, comm: MPI.Intracomm, rows, cols, row_sizes, col_sizes):
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        cols = np.asarray(cols, dtype=np.int64).reshape(-1)
        self.num_entries = rows.size
        self._blocks = None
        self._serial = None
        self._keep = np.flatnonzero((rows >= 0) & (cols >= 0))
        rows, cols = rows[self._keep], cols[self._keep]
        order = self._sorting_order(rows, cols)
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
        self._create(comm, row_sizes, col_sizes)

    @staticmethod
    def _sorting_order(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """The stable order by (row, col): one adaptive sort of a combined key when it fits."""
        if rows.size == 0:
            return np.zeros(0, dtype=np.int64)
        width = int(cols.max()) + 1
        if int(rows.max()) < (2**62) // width:
            return np.argsort(rows * width + cols, kind="stable")
        return np.lexsort((cols, rows))

    @classmethod
    def from_blocks(cls, comm: MPI.Intracomm, row_blocks, col_blocks, block_shape,
                    row_sizes, col_sizes, create: bool = True) -> CooMatrix:
        """The matrix of ``CooMatrix(comm, rows, cols, ...)`` for a pattern of dense blocks.

        Group g has the entries (row_blocks[g, i] * br + a, col_blocks[g, j] * bc + b)
        for a < br, b < bc, in the order (g, i, a, j, b); a negative block
        drops its rows or columns (``row_blocks`` and ``col_blocks`` may be
        :class:`BlockIncidence` objects shared with other matrices). The block
        pattern is a sparse product of the groups' row- and column-block
        incidences (no sort of the entries); where a group's blocks go is
        looked up when the group is first assembled. With ``create=False`` no
        PETSc matrix is made: the object is only the pattern (``pattern_csr``)
        and the summation of values for :meth:`add_groups` into another matrix.
        """
        self = cls.__new__(cls)
        row_side = row_blocks if isinstance(row_blocks, BlockIncidence) else BlockIncidence(
            row_blocks)
        col_side = col_blocks if isinstance(col_blocks, BlockIncidence) else BlockIncidence(
            col_blocks)
        num_groups, rows_per_group = row_side.local.shape
        cols_per_group = col_side.local.shape[1]
        br, bc = (int(b) for b in block_shape)
        self.num_entries = num_groups * rows_per_group * br * cols_per_group * bc
        self._block_shape = (rows_per_group, br, cols_per_group, bc)
        row_numbers, col_numbers = row_side.numbers, col_side.numbers
        from .kernels import compiled

        block_indptr, block_indices = compiled.pattern_of_groups(
            row_side.local, col_side.local, row_side.count, col_side.count)
        per_row = np.diff(block_indptr)
        present = np.flatnonzero(per_row)
        num_blocks = block_indices.size
        if num_blocks >= 2**31 - 1:
            raise ValueError(f"a block pattern of {num_blocks} blocks on one rank (at most "
                             "2^31 - 2: their positions are int32)")
        global_rows = present if row_numbers is None else row_numbers[present]
        global_cols = block_indices if col_numbers is None else col_numbers[block_indices]
        # the CSR form (rows sorted, each row's columns sorted), for the preallocation:
        # row (r, a) holds the columns c * bc + b of the blocks c of block row r
        self._rowmap = _interleave(global_rows, br)
        row_lengths = np.repeat(per_row[present] * bc, br)
        indptr = np.zeros(row_lengths.size + 1, dtype=np.int64)
        np.cumsum(row_lengths, out=indptr[1:])
        self._indptr = indptr.astype(PETSc.IntType)
        self._indices, row_starts = _block_csr_columns(global_cols, block_indptr[present],
                                                       per_row[present], br, bc)
        self._num_unique = num_blocks * br * bc
        self._blocks = {
            "indptr": block_indptr, "indices": block_indices, "rows": row_side.local,
            "cols": col_side.local, "count": num_blocks, "num_groups": num_groups, "last": None,
        }
        self.mat = None
        self._serial = None
        if create and comm.size == 1:
            # serial: the matrix is made around its values at the first assembly
            # (no preallocation, no insertion), see _set_serial
            self._serial = self._serial_layout(row_sizes, col_sizes, row_starts)
            self._serial["comm"] = comm
            return self
        # the values are kept as (a, block, b): then row (r, a) is one contiguous
        # run, and the rows go to PETSc grouped by a
        self._ijv = (
            np.concatenate([a * num_blocks * bc + block_indptr[present] * bc for a in range(br)]
                           + [[br * num_blocks * bc]]).astype(PETSc.IntType),
            self._indices if br == 1 else np.tile(_interleave(global_cols, bc), br),
            np.concatenate([global_rows * br + a for a in range(br)]).astype(PETSc.IntType),
        )
        if not create:
            return self
        self._create(comm, row_sizes, col_sizes)
        del self._indptr, self._indices  # the preallocation was their only use
        return self

    def _serial_layout(self, row_sizes, col_sizes, row_starts) -> dict:
        """What a serial matrix of :meth:`from_blocks` needs: its full CSR structure and,
        for blocks of several rows, where each block's row a starts in the CSR values
        (in units of bc)."""
        num_rows = int(row_sizes[0] if isinstance(row_sizes, (tuple, list)) else row_sizes)
        counts = np.zeros(num_rows, dtype=PETSc.IntType)
        counts[self._rowmap] = np.diff(self._indptr)
        indptr = np.zeros(num_rows + 1, dtype=PETSc.IntType)
        np.cumsum(counts, out=indptr[1:])
        del self._indptr
        return {"sizes": (row_sizes, col_sizes), "indptr": indptr,
                "indices": np.ascontiguousarray(self._indices, dtype=PETSc.IntType),
                "row_starts": row_starts, "values": None}

    def pattern_csr(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rowmap, indptr, indices): the global rows of the pattern and their sorted columns."""
        if self._serial is not None:
            raise TypeError("pattern_csr is for matrices built with create=False")
        return self._rowmap, self._indptr, self._indices

    def _create(self, comm: MPI.Intracomm, row_sizes, col_sizes) -> None:
        self.mat = PETSc.Mat().create(comm=comm)
        self.mat.setType(PETSc.Mat.Type.AIJ)
        self.mat.setSizes((row_sizes, col_sizes))
        num_local = int(row_sizes[0] if isinstance(row_sizes, (tuple, list)) else row_sizes)
        first = comm.exscan(max(num_local, 0)) or 0
        local = num_local >= 0 and bool(
            np.all((self._rowmap >= first) & (self._rowmap < first + num_local)))
        if comm.allreduce(local, op=MPI.LAND):
            # this rank owns all its rows: the pattern is the preallocation
            counts = np.zeros(num_local, dtype=PETSc.IntType)
            counts[self._rowmap - first] = np.diff(self._indptr)
            indptr = np.zeros(num_local + 1, dtype=PETSc.IntType)
            np.cumsum(counts, out=indptr[1:])
            self.mat.setPreallocationCSR((indptr, self._indices))
        else:
            preallocator = PETSc.Mat().create(comm=comm)
            preallocator.setType(PETSc.Mat.Type.PREALLOCATOR)
            preallocator.setSizes((row_sizes, col_sizes))
            preallocator.setUp()
            preallocator.setValuesIJV(self._indptr, self._indices, np.zeros(self._num_unique),
                                      addv=PETSc.InsertMode.INSERT_VALUES, rowmap=self._rowmap)
            preallocator.assemble()
            preallocator.preallocatorPreallocate(self.mat, fill=True)
            preallocator.destroy()
        self.mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        self.mat.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)

    def _set(self, summed: np.ndarray, ijv=None) -> PETSc.Mat:
        indptr, indices, rowmap = ijv or (self._indptr, self._indices, self._rowmap)
        self.mat.zeroEntries()
        self.mat.setValuesIJV(indptr, indices, summed, addv=PETSc.InsertMode.ADD_VALUES,
                              rowmap=rowmap)
        self.mat.assemble()
        return self.mat

    def assemble(self, values) -> PETSc.Mat:
        """Replace the matrix values by the summed ``values`` (same order as the pattern)."""
        values = np.asarray(values, dtype=PETSc.ScalarType).reshape(-1)
        if values.size != self.num_entries:
            raise ValueError(f"expected {self.num_entries} values, got {values.size}")
        if self._blocks is not None:
            num_groups = self._blocks["num_groups"]
            grouped = values.reshape((num_groups,) + self._block_shape)
            return self.assemble_groups(np.moveaxis(grouped, 0, -1), np.arange(num_groups))
        summed = np.bincount(self._slot, weights=values[self._keep], minlength=self._num_unique)
        return self._set(summed)

    def assemble_groups(self, values, groups, chunk: int | None = None) -> PETSc.Mat:
        """Replace the matrix values by those of the listed groups (all others are zero).

        Only for a matrix built by :meth:`from_blocks`. ``values`` has the
        shape (nr, br, nc, bc, len(groups)) (or any shape with those
        entries in that order): the group axis last. Or it is a function
        ``values(start, stop)`` giving the values of ``groups[start:stop]``,
        called ``chunk`` groups at a time (so that the values of all groups
        never exist at once); those sums do not depend on ``chunk`` (each
        group's entries are added after the last group's; an array's
        entries are added entry by entry over the groups: the same sums, other
        rounding).
        """
        if self._serial is not None:
            return self._set_serial(values, groups, chunk)
        return self._set(self._summed_groups(values, groups, chunk), self._ijv)

    def _set_serial(self, values, groups, chunk=None) -> PETSc.Mat:
        """The summed values written straight into the CSR values of the serial matrix,
        which is made around them (zero copy) at the first assembly."""
        serial = self._serial
        first = serial["values"] is None
        if first:
            serial["values"] = np.empty(serial["indices"].size, dtype=PETSc.ScalarType)
        self._summed_groups(values, groups, chunk, out=serial["values"],
                            row_starts=serial["row_starts"])
        if first:
            row_sizes, col_sizes = serial["sizes"]
            self.mat = PETSc.Mat().createAIJWithArrays(
                (row_sizes, col_sizes), (serial["indptr"], serial["indices"], serial["values"]),
                comm=serial["comm"])
            self.mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
            self.mat.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
        # (assembly ends a change of the values: PETSc drops what it derived from them)
        self.mat.assemble()
        return self.mat

    def add_groups(self, matrix: PETSc.Mat, groups, parts) -> None:
        """Add values of the listed groups to ``matrix`` (not assembled; its pattern has ours).

        ``parts``: (values, which, columns) each, the values (nr, br, len(columns), bc,
        len(which)) of the groups ``groups[which]`` on their block columns ``columns``
        (None: all groups, all columns). A pair's block is mostly zero where its slave nodes
        carry no multiplier, gap or area weight: only the columns that are not are given for
        those (one lookup of the positions of all ``groups``, kept across calls). ``values``
        may be :class:`ChunkedValues`: then no part's values are held whole."""
        groups = np.asarray(groups, dtype=np.int64).reshape(-1)
        if groups.size == 0:
            return
        indptr, indices, rowmap = self._ijv
        matrix.setValuesIJV(indptr, indices, self._summed_parts(groups, parts),
                            addv=PETSc.InsertMode.ADD_VALUES, rowmap=rowmap)

    def _summed_parts(self, groups: np.ndarray, parts) -> np.ndarray:
        """The parts' values (:meth:`add_groups`) summed into the pattern, in the order of
        ``_ijv``: part after part, each in the order of :meth:`_summed_groups`."""
        from .kernels import compiled

        nr, br, nc, bc = self._block_shape
        count = self._blocks["count"]
        position = self._positions(groups)
        sums = np.zeros((br, bc, count + 1))
        chunks = []
        for values, which, columns in parts:
            if not isinstance(values, ChunkedValues):
                chunks.append((values, which, columns))
                continue
            n = groups.size if which is None else len(which)
            step = max(int(values.chunk or n), 1)
            for start in range(0, n, step):
                stop = min(n, start + step)
                part = np.arange(start, stop) if which is None else np.asarray(which)[start:stop]
                chunks.append((functools.partial(values, start, stop), part, columns))
        for values, which, columns in chunks:
            if callable(values):
                values = values()  # (one chunk's values, summed and dropped before the next)
            n = groups.size if which is None else len(which)
            nk = nc if columns is None else len(columns)
            values = np.asarray(values, dtype=PETSc.ScalarType)
            if values.size != nr * br * nk * bc * n:
                raise ValueError(f"expected {nr * br * nk * bc * n} values, got {values.size}")
            values = values.reshape(nr, br, nk, bc, n)
            compiled.pattern_sum_part(position, values, count, sums, which, columns)
        return self._in_order(sums)

    def _summed_groups(self, values, groups, chunk=None, out=None, row_starts=()) -> np.ndarray:
        """The groups' values summed into the pattern, in the order of ``_ijv``, or with
        ``row_starts`` (serial CSR, see :meth:`_serial_layout`) in CSR order into ``out``.
        The entries are added group by group (``values`` as in :meth:`assemble_groups`)."""
        if self._blocks is None:
            raise TypeError("assemble_groups needs a matrix built by CooMatrix.from_blocks")
        groups = np.asarray(groups, dtype=np.int64).reshape(-1)
        nr, br, nc, bc = self._block_shape
        count = self._blocks["count"]
        position = self._positions(groups)  # (nr, nc, groups)
        sums = np.zeros((br, bc, count + 1))
        from .kernels import compiled

        if not callable(values):
            # all at once, entry (i, a, j, b) of every group after the other
            values = np.asarray(values, dtype=PETSc.ScalarType)
            expected = nr * br * nc * bc * groups.size
            if values.size != expected:
                raise ValueError(f"expected {expected} values, got {values.size}")
            values = values.reshape(nr, br, nc, bc, groups.size)
            compiled.pattern_sum(position, values, count, sums)
            chunk, values = None, None
        step = max(int(chunk or groups.size), 1)
        for start in range(0, groups.size if values is not None else 0, step):
            # chunk by chunk, group by group: the sums do not depend on the chunk size
            stop = min(groups.size, start + step)
            part = np.asarray(values(start, stop), dtype=PETSc.ScalarType)
            expected = nr * br * nc * bc * (stop - start)
            if part.size != expected:
                raise ValueError(f"expected {expected} values, got {part.size}")
            part = part.reshape(nr, br, nc, bc, stop - start)
            compiled.pattern_sum(position, part, count, sums, start, group_major=True)
            del part
        return self._in_order(sums, out, row_starts)

    def _in_order(self, sums: np.ndarray, out=None, row_starts=()) -> np.ndarray:
        """The sums (br, bc, count + 1) over the block pattern (slot 0: dropped entries) as
        the values of ``_ijv`` (or with ``row_starts``, in serial CSR order into ``out``)."""
        br, bc, count = sums.shape[0], sums.shape[1], sums.shape[2] - 1
        summed = np.empty(br * count * bc) if out is None else out
        by_block = summed.reshape(br * count, bc)
        for a in range(br):
            for b in range(bc):
                if len(row_starts):
                    by_block[row_starts[a], b] = sums[a, b, 1:]
                else:
                    by_block[a * count:(a + 1) * count, b] = sums[a, b, 1:]
        return summed

    def _positions(self, groups: np.ndarray):
        """(nr, nc, len(groups)) 1 + positions of the groups' blocks; 0 for dropped ones
        (as :class:`~dolfinx_mortar.kernels.compiled.RowOffsets` where the pattern's rows
        allow: half the memory, which is most of the pairs' share on the ranks that hold
        the contact).

        The answer for the last ``groups`` is kept, in the order of the values'
        entries (contiguous: no copy of an index of every entry at each assembly): a
        Newton iteration assembles the same pairs again, or almost the same (only the
        groups that were not in the last call are looked up).
        """
        from .kernels import compiled

        blocks = self._blocks
        last = blocks["last"]
        if last is None:
            result = self._lookup(groups)
        elif np.array_equal(last[0], groups):
            return last[1]
        else:
            where = np.full(blocks["num_groups"], -1, dtype=np.int64)
            where[last[0]] = np.arange(last[0].size)
            index = where[groups]
            known = index >= 0
            if known.any():
                result = compiled.take_groups(last[1], np.where(known, index, 0))
                if not known.all():
                    compiled.put_groups(result, ~known, self._lookup(groups[~known]))
            else:
                result = self._lookup(groups)
        blocks["last"] = (groups.copy(), result)
        return result

    def _lookup(self, groups: np.ndarray):
        """(nr, nc, len(groups)) 1 + positions of the groups' blocks, found in the pattern
        (RowOffsets, or int32 where a row is too long for them)."""
        from .kernels import compiled

        blocks = self._blocks
        rows, cols = blocks["rows"][groups], blocks["cols"][groups]
        return compiled.pattern_positions(rows, cols, blocks["indptr"], blocks["indices"],
                                          row_offsets=True)

    def release_pattern(self) -> None:
        """Drop what only further assemblies need (the block pattern, the groups'
        positions, the insertion indices); the PETSc matrix stays valid. For a pattern
        that will not be assembled again (a new search makes new ones)."""
        self._blocks = None
        self._ijv = None

    def destroy(self) -> None:
        """Free the PETSc matrix (collective); the object cannot assemble afterwards."""
        if self.mat is not None:
            self.mat.destroy()
            self.mat = None


class ChunkedValues:
    """A part's values for :meth:`CooMatrix.add_groups` made on demand: ``values(start,
    stop)`` gives those of ``which[start:stop]``, asked for ``chunk`` groups at a time (all
    at once if None), so that only one chunk's values are alive at a time."""

    def __init__(self, values: typing.Callable[[int, int], np.ndarray], chunk: int | None):
        self.values = values
        self.chunk = chunk

    def __call__(self, start: int, stop: int) -> np.ndarray:
        return self.values(start, stop)


class MonolithicMatrix:
    """The system matrix of a layout: a bulk block assembled in place, dense blocks, a diagonal.

    The bulk bilinear form is assembled straight into this matrix through
    its local-to-global map, which sends the local displacement dofs
    (owned and ghost, unrolled) to their monolithic rows (MatSetValuesLocal,
    as dolfinx assembles the blocks of a block matrix): no copy of the bulk
    matrix. The dense blocks (one group per mortar pair, by global index,
    rows of other ranks allowed) and a diagonal of owned rows are added to
    it. The pattern is the union of the three, preallocated exactly and
    fixed (new nonzeros are an error); another group pattern needs another
    MonolithicMatrix.

    Args:
        comm: communicator.
        sizes: (owned, global) rows and columns.
        local_to_global: monolithic index of each local displacement dof.
        bulk_pattern: (indptr, indices) of the bulk block's owned rows in
            monolithic columns; they are the first rows of this rank. Or (indptr,
            indices, block): as ``block`` x ``block`` blocks
            (:func:`~dolfinx_mortar.kernels.compiled.pattern_blocks`), the indices each
            block's first column.
        group_rows, group_cols: (groups, nr) and (groups, nc) monolithic
            indices of each group's dense block; negative ones are dropped.
        diagonal_rows: owned monolithic rows that get a diagonal entry.
        point_entries: (rows, cols) of further single entries in owned rows
            (node-local couplings, e.g. a tangential multiplier row on its
            node's normal multiplier); their values follow the diagonal's.
    """

    def __init__(self, comm: MPI.Intracomm, sizes, local_to_global, bulk_pattern,
                 group_rows, group_cols, diagonal_rows, point_entries=None):
        import scipy.sparse

        num_owned, num_global = (int(n) for n in sizes)
        first = comm.exscan(num_owned) or 0
        self.groups = CooMatrix.from_blocks(comm, group_rows, group_cols, (1, 1), sizes, sizes,
                                            create=False)
        group_rowmap, group_indptr, group_indices = self.groups.pattern_csr()
        self.diagonal_rows = np.asarray(diagonal_rows, dtype=PETSc.IntType)
        self._entry_rows, self._entry_cols = self.diagonal_rows, self.diagonal_rows
        if point_entries is not None:
            self._entry_rows = np.concatenate(
                [self.diagonal_rows, np.asarray(point_entries[0], dtype=PETSc.IntType)])
            self._entry_cols = np.concatenate(
                [self.diagonal_rows, np.asarray(point_entries[1], dtype=PETSc.IntType)])
        bulk_indptr, bulk_indices = bulk_pattern[:2]
        block = bulk_pattern[2] if len(bulk_pattern) > 2 else 1
        self.mat = PETSc.Mat().create(comm=comm)
        self.mat.setType(PETSc.Mat.Type.AIJ)
        self.mat.setSizes((sizes, sizes))
        # the pattern of this rank's rows, the others' entries in them received
        rows = np.concatenate([np.repeat(group_rowmap.astype(np.int64), np.diff(group_indptr)),
                               self._entry_rows.astype(np.int64)])
        cols = np.concatenate([group_indices.astype(np.int64), self._entry_cols.astype(np.int64)])
        rows, cols = _entries_to_owners(comm, first, rows, cols)
        shape = (num_owned, max(num_global, 1))
        extra = scipy.sparse.coo_matrix((np.ones(rows.size), (rows - first, cols)),
                                        shape=shape).tocsr()
        extra.sum_duplicates()
        from .kernels import compiled

        # the bulk rows merged with the few entries of the pairs and multipliers in one pass
        # (no sum of the whole pattern as sparse matrices: 12 bytes an entry more, each time)
        pattern = compiled.pattern_union((bulk_indptr, bulk_indices),
                                         (extra.indptr, extra.indices), block)
        if pattern is None:  # (a bulk row not sorted)
            bulk_ptr, bulk_indices = _unblocked(bulk_indptr, bulk_indices, block)
            bulk_ptr = np.concatenate([bulk_ptr, np.full(num_owned + 1 - bulk_ptr.size,
                                                         bulk_ptr[-1])])
            bulk = scipy.sparse.csr_matrix((np.ones(bulk_indices.size), bulk_indices, bulk_ptr),
                                           shape=shape)
            merged = (bulk + extra).tocsr()
            merged.sum_duplicates()
            pattern = merged.indptr, merged.indices
        self.mat.setPreallocationCSR((pattern[0].astype(PETSc.IntType),
                                      pattern[1].astype(PETSc.IntType)))
        self.mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        self.mat.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
        lgmap = PETSc.LGMap().create(np.asarray(local_to_global, dtype=PETSc.IntType), comm=comm)
        self.mat.setLGMap(lgmap, lgmap)
        lgmap.destroy()

    def _add_diagonal(self, matrix: PETSc.Mat, values: np.ndarray, mode) -> None:
        """The diagonal values, then those of the point entries (one per entry)."""
        if self._entry_rows.size:
            matrix.setValuesIJV(np.arange(self._entry_rows.size + 1, dtype=PETSc.IntType),
                                self._entry_cols, values, addv=mode, rowmap=self._entry_rows)

    def add(self, groups, parts, diagonal_values) -> None:
        """Add the listed groups' blocks, given in ``parts`` as for
        :meth:`CooMatrix.add_groups` (values (nr, len(columns), len(which)) each), and the
        diagonal values (followed by the point entries' values, if any).

        The caller zeroes the matrix, adds the bulk form through the
        local-to-global map (:func:`compat.add_matrix_local`) and assembles.
        """
        self.groups.add_groups(self.mat, groups, parts)
        self._add_diagonal(self.mat, np.asarray(diagonal_values, dtype=PETSc.ScalarType),
                           PETSc.InsertMode.ADD_VALUES)

    def destroy(self) -> None:
        """Free the PETSc matrix (collective)."""
        self.mat.destroy()


def _unblocked(indptr: np.ndarray, indices: np.ndarray,
               block: int) -> tuple[np.ndarray, np.ndarray]:
    """A pattern of ``block`` x ``block`` blocks (block rows' indptr, blocks' first columns)
    as a plain CSR pattern."""
    if block == 1:
        return indptr, indices
    expanded = (np.asarray(indices)[:, None] + np.arange(block)).reshape(-1)
    lengths = np.repeat(np.diff(indptr) * block, block)  # each block row's rows alike
    scalar_indptr = np.concatenate([[0], np.cumsum(lengths)])
    starts = np.repeat(np.asarray(indptr[:-1]) * block, block)
    within = np.arange(scalar_indptr[-1]) - np.repeat(scalar_indptr[:-1], lengths)
    return scalar_indptr, expanded[np.repeat(starts, lengths) + within]


def _entries_to_owners(comm: MPI.Intracomm, first: int, rows: np.ndarray,
                       cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The entries (global rows, cols) in this rank's rows: its own and those the other
    ranks have there, sent to it (one exchange of counts, one of entries), so that every
    rank preallocates its rows exactly from a CSR pattern."""
    if comm.size == 1:
        return rows, cols
    starts = np.asarray(comm.allgather(first), dtype=np.int64)
    owner = np.searchsorted(starts, rows, side="right") - 1
    mine = owner == comm.rank
    order = np.flatnonzero(~mine)
    order = order[np.argsort(owner[order], kind="stable")]
    send_counts = np.bincount(owner[order], minlength=comm.size).astype(np.int64)
    receive_counts = np.empty(comm.size, dtype=np.int64)
    comm.Alltoall(send_counts, receive_counts)
    outgoing = np.ascontiguousarray(np.stack([rows[order], cols[order]], axis=1))
    incoming = np.empty((int(receive_counts.sum()), 2), dtype=np.int64)
    send_starts = np.concatenate([[0], np.cumsum(send_counts)[:-1]])
    receive_starts = np.concatenate([[0], np.cumsum(receive_counts)[:-1]])
    comm.Alltoallv([outgoing, (2 * send_counts, 2 * send_starts), MPI.INT64_T],
                   [incoming, (2 * receive_counts, 2 * receive_starts), MPI.INT64_T])
    return (np.concatenate([rows[mine], incoming[:, 0]]),
            np.concatenate([cols[mine], incoming[:, 1]]))


def _interleave(blocks: np.ndarray, size: int) -> np.ndarray:
    """(blocks * size + i for i < size), flattened block by block, as PETSc integers."""
    blocks = blocks.astype(PETSc.IntType, copy=False)
    if size == 1:
        return blocks
    result = np.empty((blocks.size, size), dtype=PETSc.IntType)
    for i in range(size):  # (a broadcast over a short last axis is slow in numpy)
        result[:, i] = blocks * size + i
    return result.reshape(-1)


class BlockIncidence:
    """The row (or column) blocks of the groups of a block pattern, (groups, n), -1 where a
    group has none, in a compact numbering shared by the matrices that have the same blocks
    (:meth:`CooMatrix.from_blocks` takes this or the array).

    ``local`` numbers the blocks among ``count`` (``numbers``: the global block of each,
    None if the global numbering is used); a missing block is ``count``, a block that no
    group has (the pattern gets an empty last row, and a lookup there finds nothing).
    """

    def __init__(self, blocks):
        blocks = np.asarray(blocks, dtype=np.int64)
        self.numbers, local, self.count = _compact_numbering(blocks)
        index = np.int32 if self.count < 2**31 - 1 else np.int64
        self.local = np.where(local < 0, self.count, local).astype(index, copy=False)


def _compact_numbering(blocks: np.ndarray):
    """(numbers, local, count): the block numbers used, each block's index among them
    (-1 stays -1) and how many. ``numbers`` is None when the global numbering itself
    is used (it is not much larger than the data)."""
    largest = int(blocks.max()) if blocks.size else -1
    if largest < 16 * blocks.size + 4096:
        return None, blocks, largest + 1
    valid = blocks >= 0
    numbers, inverse = np.unique(blocks[valid], return_inverse=True)
    local = np.full(blocks.shape, -1, dtype=np.int64)
    local[valid] = inverse.reshape(-1)
    return numbers, local, numbers.size
