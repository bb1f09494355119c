"""CooMatrix.from_blocks against the plain triplet CooMatrix (sorted entries, PETSc insertion).

The block path builds its pattern by sparse products and, in serial, makes the PETSc
matrix around its own CSR arrays with the values summed straight into CSR order; the
triplet path sorts all entries and inserts them. Both must give the same pattern and
the same values, also after a second assembly of other groups into the same matrix.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_mortar.layout import CooMatrix


def _triplets(row_blocks, col_blocks, block_shape, values, groups):
    """(rows, cols, values) of the listed groups, in the (g, i, a, j, b) order."""
    br, bc = block_shape
    nr, nc = row_blocks.shape[1], col_blocks.shape[1]
    row_block = row_blocks[groups][:, :, None, None, None]
    col_block = col_blocks[groups][:, None, None, :, None]
    rows = np.where(row_block < 0, -1, row_block * br + np.arange(br)[:, None, None])
    cols = np.where(col_block < 0, -1, col_block * bc + np.arange(bc))
    shape = (groups.size, nr, br, nc, bc)
    return (np.broadcast_to(rows, shape).reshape(-1), np.broadcast_to(cols, shape).reshape(-1),
            np.moveaxis(values, -1, 0).reshape(-1))


def _csr(matrix):
    indptr, indices, values = matrix.getValuesCSR()
    return indptr.copy(), indices.copy(), values.copy()


@pytest.mark.parametrize("block_shape", [(1, 1), (1, 2), (2, 2), (3, 1)])
def test_blocks_equal_triplets(block_shape):
    """Same CSR structure and values (to rounding: the sums run in another order)."""
    comm = MPI.COMM_SELF
    rng = np.random.default_rng(7)
    num_groups, nr, nc = 400, 3, 5
    num_row_blocks, num_col_blocks = 60, 90
    row_blocks = rng.integers(0, num_row_blocks, (num_groups, nr))
    col_blocks = rng.integers(0, num_col_blocks, (num_groups, nc))
    row_blocks[rng.random(row_blocks.shape) < 0.1] = -1  # dropped rows and columns
    col_blocks[rng.random(col_blocks.shape) < 0.1] = -1
    br, bc = block_shape
    sizes = ((num_row_blocks * br,) * 2, (num_col_blocks * bc,) * 2)
    blocks = CooMatrix.from_blocks(comm, row_blocks, col_blocks, block_shape, *sizes)
    all_groups = np.arange(num_groups)
    rows, cols, _ = _triplets(row_blocks, col_blocks, block_shape,
                              np.zeros((nr, br, nc, bc, num_groups)), all_groups)
    triplets = CooMatrix(comm, rows, cols, *sizes)
    first = rng.choice(num_groups, 150, replace=False)
    second = np.sort(rng.choice(num_groups, 230, replace=False))
    # new groups, the same again, others partly known, none, the first again
    for subset in (first, first.copy(), second, np.zeros(0, dtype=np.int64), first):
        values = rng.standard_normal((nr, br, nc, bc, subset.size))
        full = np.zeros((nr, br, nc, bc, num_groups))
        full[..., subset] = values
        expected = _csr(triplets.assemble(np.moveaxis(full, -1, 0)))
        got = _csr(blocks.assemble_groups(values, subset))
        assert np.array_equal(got[0], expected[0])
        assert np.array_equal(got[1], expected[1])
        assert np.allclose(got[2], expected[2], rtol=1e-14, atol=1e-14)
        assert np.abs(expected[2]).max(initial=1.0) > 0.0
    full = rng.standard_normal((num_groups, nr, br, nc, bc))  # all groups, group axis first
    expected = _csr(triplets.assemble(full))
    got = _csr(blocks.assemble(full))
    assert np.array_equal(got[1], expected[1])
    assert np.allclose(got[2], expected[2], rtol=1e-14, atol=1e-14)
    assert blocks.mat.getSize() == (num_row_blocks * br, num_col_blocks * bc)
    blocks.destroy()
    triplets.destroy()


def test_blocks_without_groups():
    """No pair at all: an empty matrix of the right size, assembled."""
    comm = MPI.COMM_SELF
    empty = np.zeros((0, 2), dtype=np.int64)
    matrix = CooMatrix.from_blocks(comm, empty, np.zeros((0, 3), dtype=np.int64), (1, 2),
                                   (4, 4), (6, 6))
    mat = matrix.assemble_groups(np.zeros((2, 1, 3, 2, 0)), np.zeros(0, dtype=np.int64))
    assert mat.getSize() == (4, 6)
    indptr, indices, _ = mat.getValuesCSR()
    assert np.array_equal(indptr, np.zeros(5)) and indices.size == 0
    matrix.destroy()


@pytest.mark.parallel
def test_entries_reach_the_ranks_that_own_their_rows():
    """Each rank's entries, in rows of any rank (some ranks owning none), end up on the rank
    that owns the row: every entry once, none elsewhere."""
    from dolfinx_mortar.layout import _entries_to_owners

    comm = MPI.COMM_WORLD
    sizes = [7, 0, 5, 9][:comm.size] if comm.size > 1 else [7]
    num_owned = sizes[comm.rank]
    first = int(sum(sizes[:comm.rank]))
    rng = np.random.default_rng(11 + comm.rank)
    rows = rng.integers(0, sum(sizes), 40)
    cols = rng.integers(0, 1000, 40)
    got_rows, got_cols = _entries_to_owners(comm, first, rows, cols)
    assert np.all((got_rows >= first) & (got_rows < first + num_owned))
    everything = np.concatenate(comm.allgather(np.stack([rows, cols], axis=1)))
    expected = everything[(everything[:, 0] >= first) & (everything[:, 0] < first + num_owned)]
    got = np.stack([got_rows, got_cols], axis=1)
    assert sorted(map(tuple, got)) == sorted(map(tuple, expected))


def test_pattern_positions_equal_scipys_lookup():
    """The compiled lookup of blocks in a pattern equals scipy's fancy indexing of a pattern
    whose values are 1 + their positions: present entries, absent ones (0), an empty last row
    and a column no row has, rows with one entry and with many."""
    import scipy.sparse

    from dolfinx_mortar.kernels import compiled

    rng = np.random.default_rng(5)
    num_rows, num_cols = 40, 60
    dense = rng.random((num_rows, num_cols)) < 0.2
    dense[7] = False
    dense[8, :] = False
    dense[8, 3] = True
    dense[9, :] = True
    dense[:, num_cols - 1] = False
    pattern = scipy.sparse.csr_matrix(dense.astype(float))
    pattern.sort_indices()
    pattern.data = np.arange(1, pattern.nnz + 1, dtype=np.int32)
    rows = rng.integers(0, num_rows, (25, 4)).astype(np.int32)
    rows[0] = [7, 8, 9, num_rows - 1]
    cols = rng.integers(0, num_cols, (25, 9)).astype(np.int32)
    cols[0, :3] = [3, 0, num_cols - 1]
    shape = (25, 4, 9)
    expected = np.asarray(pattern[np.broadcast_to(rows[:, :, None], shape).reshape(-1),
                                  np.broadcast_to(cols[:, None, :], shape).reshape(-1)])
    got = compiled.pattern_positions(rows, cols, pattern.indptr, pattern.indices)
    np.testing.assert_array_equal(got, expected.reshape(shape).transpose(1, 2, 0))
    assert (got > 0).any() and (got == 0).any()
    assert got[1, 0, 0] == pattern.indptr[8] + 1 and got[0, :, 0].max() == 0
    with pytest.raises(IndexError):
        compiled.pattern_positions(rows + num_rows, cols, pattern.indptr, pattern.indices)


def test_row_offsets_hold_the_positions(monkeypatch):
    """Positions as row starts and uint16 offsets (``row_offsets=True``) are the int32 ones:
    present and absent entries, an empty row; the groups taken and put back as np.take and
    an assignment would; a pattern with a row of OFFSET_LIMIT entries or more gets int32
    positions; and the sums over either are the same bits (pattern_sum in both orders,
    pattern_sum_part on some groups and columns)."""
    import scipy.sparse

    from dolfinx_mortar.kernels import compiled

    rng = np.random.default_rng(15)
    num_rows, num_cols, n = 30, 80, 40
    dense = rng.random((num_rows, num_cols)) < 0.3
    dense[4] = False
    pattern = scipy.sparse.csr_matrix(dense.astype(float))
    pattern.sort_indices()
    rows = rng.integers(0, num_rows, (n, 3)).astype(np.int32)
    rows[0, 0] = 4
    cols = rng.integers(0, num_cols, (n, 7)).astype(np.int32)
    absolute = compiled.pattern_positions(rows, cols, pattern.indptr, pattern.indices)
    compact = compiled.pattern_positions(rows, cols, pattern.indptr, pattern.indices,
                                         row_offsets=True)
    assert isinstance(compact, compiled.RowOffsets) and compact.offsets.dtype == np.uint16
    assert (absolute > 0).any() and (absolute == 0).any()
    np.testing.assert_array_equal(compact.absolute(), absolute)
    index = rng.integers(0, n, 25)
    taken = compact.take(index)
    np.testing.assert_array_equal(taken.absolute(), np.take(absolute, index, axis=2))
    mask = rng.random(25) < 0.5
    other = compact.take(index[::-1][mask])
    taken.put(mask, other)
    expected = np.take(absolute, index, axis=2)
    expected[..., mask] = np.take(absolute, index[::-1][mask], axis=2)
    np.testing.assert_array_equal(taken.absolute(), expected)
    for kind in (compact, absolute):  # (CooMatrix's reuse of the last groups' positions)
        reused = compiled.take_groups(kind, index)
        compiled.put_groups(reused, mask, compiled.take_groups(kind, index[::-1][mask]))
        got = reused.absolute() if isinstance(reused, compiled.RowOffsets) else reused
        np.testing.assert_array_equal(got, expected)
    count = pattern.nnz
    for br, bc in ((1, 1), (2, 3)):
        values = rng.standard_normal((3, br, 7, bc, n))
        np.testing.assert_array_equal(compiled.pattern_sum(compact, values, count),
                                      compiled.pattern_sum(absolute, values, count))
        part = np.ascontiguousarray(values[..., 10:30])
        np.testing.assert_array_equal(
            compiled.pattern_sum(compact, part, count, start=10, group_major=True),
            compiled.pattern_sum(absolute, part, count, start=10, group_major=True))
        which, columns = rng.permutation(n)[:15], np.array([6, 0, 2])
        some = rng.standard_normal((3, br, 3, bc, 15))
        for chosen, on in ((which, columns), (None, None)):
            some_values = some if chosen is not None else values
            np.testing.assert_array_equal(
                compiled.pattern_sum_part(compact, some_values, count,
                                          np.zeros((br, bc, count + 1)), chosen, on),
                compiled.pattern_sum_part(absolute, some_values, count,
                                          np.zeros((br, bc, count + 1)), chosen, on))
    compact.offsets[0, 0, 0] = count + 1
    with pytest.raises(IndexError):
        compiled.pattern_sum(compact, values, count)
    monkeypatch.setattr(compiled, "OFFSET_LIMIT", int(np.diff(pattern.indptr).max()))
    fallback = compiled.pattern_positions(rows, cols, pattern.indptr, pattern.indices,
                                          row_offsets=True)
    assert isinstance(fallback, np.ndarray) and fallback.dtype == np.intc
    np.testing.assert_array_equal(fallback, absolute)


@pytest.mark.parametrize("block_shape", [(1, 1), (3, 2)])
def test_pattern_sum_adds_as_bincount_and_add_at(block_shape):
    """The compiled sum of the groups' values into the pattern gives np.bincount's bits (all
    groups at once, entries in (i, j, g) order) and np.add.at's (chunk by chunk, group by
    group), dropped entries in slot 0; a position outside the pattern is refused."""
    from dolfinx_mortar.kernels import compiled

    br, bc = block_shape
    rng = np.random.default_rng(9)
    nr, nc, n, count = 4, 5, 30, 50
    positions = rng.integers(0, count + 1, (nr, nc, n)).astype(np.intc)
    shape = (nr, br, nc, bc, n)
    values = rng.standard_normal(shape) * 10.0 ** rng.integers(-8, 8, shape)
    expected = np.zeros((br, bc, count + 1))
    for a in range(br):
        for b in range(bc):
            weights = np.ascontiguousarray(values[:, a, :, b, :]).reshape(-1)
            expected[a, b] = np.bincount(positions.reshape(-1), weights, minlength=count + 1)
    np.testing.assert_array_equal(compiled.pattern_sum(positions, values, count), expected)
    chunked = np.zeros((br, bc, count + 1))
    summed = np.zeros((br, bc, count + 1))
    for start in range(0, n, 7):
        stop = min(n, start + 7)
        part = np.ascontiguousarray(values[..., start:stop])
        where = positions[..., start:stop].transpose(2, 0, 1).reshape(-1)
        for a in range(br):
            for b in range(bc):
                np.add.at(chunked[a, b], where, part[:, a, :, b, :].transpose(2, 0, 1).reshape(-1))
        compiled.pattern_sum(positions, part, count, summed, start, group_major=True)
    np.testing.assert_array_equal(summed, chunked)
    assert not np.array_equal(chunked, expected)  # (the two orders round differently here)
    positions[0, 0, 0] = count + 1
    with pytest.raises(IndexError):
        compiled.pattern_sum(positions, values, count)


@pytest.mark.parametrize("block_shape", [(1, 1), (2, 3)])
def test_pattern_sum_of_a_part_equals_the_sum_of_its_copied_positions(block_shape):
    """Some groups on some block columns, their positions read in place: the bits of
    pattern_sum over a copy of those positions, added to what the sums held; a group or a
    column outside the positions is refused."""
    from dolfinx_mortar.kernels import compiled

    br, bc = block_shape
    rng = np.random.default_rng(10)
    nr, nc, groups, count = 4, 6, 40, 60
    positions = rng.integers(0, count + 1, (nr, nc, groups)).astype(np.intc)
    which = rng.permutation(groups)[:25]
    columns = np.array([5, 0, 3])
    values = rng.standard_normal((nr, br, columns.size, bc, which.size))
    start = rng.standard_normal((br, bc, count + 1))
    expected = compiled.pattern_sum(np.ascontiguousarray(positions[:, columns][..., which]),
                                    values, count, start.copy())
    got = compiled.pattern_sum_part(positions, values, count, start.copy(), which, columns)
    np.testing.assert_array_equal(got, expected)
    everything = rng.standard_normal((nr, br, nc, bc, groups))
    np.testing.assert_array_equal(
        compiled.pattern_sum_part(positions, everything, count, np.zeros((br, bc, count + 1))),
        compiled.pattern_sum(positions, everything, count))
    for bad_which, bad_columns in (([0, groups], columns[:1]), ([0, 1], [nc])):
        bad = np.zeros((nr, br, len(bad_columns), bc, 2))
        with pytest.raises(IndexError):
            compiled.pattern_sum_part(positions, bad, count, start.copy(), bad_which,
                                      bad_columns)


def test_pattern_of_groups_equals_the_product_of_the_incidences():
    """Block row r holds block column c where a group has both: the pattern is the product
    of the groups' row-block incidence (transposed) with their column-block incidence
    (scipy, sorted), with repeated blocks in a group, missing ones (-1 or the count) and a
    block no group has (an empty row), and an extra empty last row."""
    import scipy.sparse

    from dolfinx_mortar.kernels import compiled

    rng = np.random.default_rng(12)
    num_rows, num_cols, n = 40, 70, 90
    rows = rng.integers(0, num_rows, (n, 4))
    cols = rng.integers(0, num_cols, (n, 9))
    rows[rows == 5] = 6  # block row 5: in no group
    rows[::7, 1] = rows[::7, 0]  # a block twice in a group
    rows[::5, 2], cols[::3, 4], cols[::4, 0] = -1, -1, num_cols  # missing blocks

    def incidence(blocks, count):
        valid = (blocks >= 0) & (blocks < count)
        group = np.repeat(np.arange(n), blocks.shape[1]).reshape(blocks.shape)
        return scipy.sparse.csr_matrix((np.ones(int(valid.sum())), (group[valid], blocks[valid])),
                                       shape=(n, count + 1))

    expected = (incidence(rows, num_rows).T @ incidence(cols, num_cols)).tocsr()
    expected.sort_indices()
    indptr, indices = compiled.pattern_of_groups(rows, cols, num_rows, num_cols)
    assert indptr.tolist() == expected.indptr.tolist()
    assert indices.tolist() == expected.indices.tolist()
    assert indptr[6] == indptr[5] and indptr[-1] == indptr[-2] and indices.size > 0
    empty_indptr, empty_indices = compiled.pattern_of_groups(
        np.zeros((0, 4), dtype=int), np.zeros((0, 9), dtype=int), num_rows, num_cols)
    assert empty_indptr.tolist() == [0] * (num_rows + 2) and empty_indices.size == 0


def test_pattern_union_equals_the_sum_of_the_sparse_patterns():
    """The union of two CSR patterns (rows strictly increasing) is scipy's sum of the two
    as sparse matrices, empty rows and a pattern without entries included; a row that is
    not strictly increasing gives None (the caller merges through scipy)."""
    import scipy.sparse

    from dolfinx_mortar.kernels import compiled

    rng = np.random.default_rng(11)
    shape = (60, 200)
    a = scipy.sparse.random(*shape, density=0.05, random_state=rng, format="csr")
    b = scipy.sparse.random(*shape, density=0.02, random_state=rng, format="lil")
    b[7] = 0.0
    b = b.tocsr()
    assert b[7].nnz == 0 and a[7].nnz > 0
    for first, second in ((a, b), (b, a), (a, scipy.sparse.csr_matrix(shape))):
        for m in (first, second):
            m.sort_indices()
        expected = (abs(first) + abs(second)).tocsr()
        expected.sort_indices()
        indptr, indices = compiled.pattern_union((first.indptr, first.indices),
                                                 (second.indptr, second.indices))
        assert indptr.tolist() == expected.indptr.tolist()
        assert indices.tolist() == expected.indices.tolist()
    unsorted = a.indices.copy()
    row = int(np.argmax(np.diff(a.indptr)))
    start = a.indptr[row]
    unsorted[start], unsorted[start + 1] = unsorted[start + 1], unsorted[start]
    assert compiled.pattern_union((a.indptr, unsorted), (b.indptr, b.indices)) is None


@pytest.mark.parametrize("block", [2, 3])
def test_blocked_pattern_holds_the_same_entries(block):
    """A pattern of whole block x block blocks (as dolfinx makes a vector space's) is kept
    as its blocks' first columns (``pattern_blocks``): expanded (``layout._unblocked``) it is
    the pattern again, and its union with another pattern of more rows (``pattern_union``
    with ``a_block``) is the union of the expanded one; a pattern with one entry more or
    less, or with a block off the block grid, is no block pattern."""
    import scipy.sparse

    from dolfinx_mortar.kernels import compiled
    from dolfinx_mortar.layout import _unblocked

    rng = np.random.default_rng(3)
    nodes = scipy.sparse.random(20, 30, density=0.15, random_state=rng, format="lil")
    nodes[4] = 0.0  # (an empty block row)
    nodes = nodes.tocsr()
    nodes.sort_indices()
    scalar = scipy.sparse.kron(nodes, np.ones((block, block)), format="csr")
    scalar.sort_indices()
    indptr, indices = scalar.indptr.astype(np.int64), scalar.indices.astype(np.int32)
    blocks = compiled.pattern_blocks(indptr, indices, block)
    assert blocks is not None
    block_indptr, first = blocks
    assert block_indptr.tolist() == nodes.indptr.tolist()
    assert first.tolist() == (nodes.indices * block).tolist()
    expanded = _unblocked(block_indptr, first, block)
    assert expanded[0].tolist() == indptr.tolist()
    assert expanded[1].tolist() == indices.tolist()
    other = scipy.sparse.random(scalar.shape[0] + 5, scalar.shape[1], density=0.03,
                                random_state=rng, format="csr")
    other.sort_indices()
    padded = np.concatenate([indptr, np.full(5, indptr[-1])])
    expected = compiled.pattern_union((padded, indices), (other.indptr, other.indices))
    union = compiled.pattern_union((block_indptr, first), (other.indptr, other.indices), block)
    assert union[0].tolist() == expected[0].tolist()
    assert union[1].tolist() == expected[1].tolist()
    shifted = (first + 1).astype(np.int32)  # (blocks off the grid still union right)
    union = compiled.pattern_union((block_indptr, shifted), (other.indptr, other.indices), block)
    expected = compiled.pattern_union(
        (padded, _unblocked(block_indptr, shifted, block)[1]), (other.indptr, other.indices))
    assert union[1].tolist() == expected[1].tolist()
    assert compiled.pattern_blocks(indptr, indices + 1, block) is None
    row = int(np.argmax(np.diff(indptr)))
    fewer = np.delete(indices, indptr[row + 1] - 1)
    fewer_indptr = indptr.copy()
    fewer_indptr[row + 1:] -= 1
    assert compiled.pattern_blocks(fewer_indptr, fewer, block) is None
    assert compiled.pattern_blocks(indptr[:-1], indices[:indptr[-2]], block) is None


@pytest.mark.parallel
@pytest.mark.parametrize("chunk", [3, 1 << 20])
def test_block_layout_index_maps_each_global_index_to_its_owners_row(monkeypatch, chunk):
    """Global index g of field f, owned by rank r (field_offsets[r, f] <= g <
    field_offsets[r + 1, f]), sits at row offsets[r] + within_rank[r, f] + g -
    field_offsets[r, f]; -1 stays -1; in chunks smaller than the input too, and as int32."""
    from dolfinx_mortar import layout as layout_module

    monkeypatch.setattr(layout_module, "INDEX_CHUNK", chunk)
    comm = MPI.COMM_WORLD
    rank = comm.rank
    layout = layout_module.BlockLayout(comm, 5 + 2 * rank, [3 + rank, rank % 2])
    rng = np.random.default_rng(11)
    for field in range(3):
        total = int(layout.field_offsets[-1, field])
        index = rng.integers(-1, total, size=40).astype(np.int32)
        expected = np.full(index.size, -1, dtype=np.int64)
        for k, g in enumerate(index):
            if g < 0:
                continue
            owner = int(np.flatnonzero(layout.field_offsets[:-1, field] <= g)[-1])
            expected[k] = (layout.offsets[owner] + layout.within_rank[owner, field]
                           + g - layout.field_offsets[owner, field])
        np.testing.assert_array_equal(layout.index(field, index), expected)
        as_int32 = layout.index(field, index.reshape(5, 8), np.int32)
        assert as_int32.dtype == np.int32 and as_int32.shape == (5, 8)
        np.testing.assert_array_equal(as_int32.reshape(-1), expected)


@pytest.mark.parallel
@pytest.mark.parametrize("chunk", [3, 1 << 20])
def test_block_layout_u_global_inverts_u(monkeypatch, chunk):
    """Every global displacement dof comes back from its monolithic row, -1 stays -1, and
    a row of one layout reaches the same dof's row of another (the multiplier counts
    changed, as when a pair leaves the layout): the bulk pattern's remap."""
    from dolfinx_mortar import layout as layout_module

    monkeypatch.setattr(layout_module, "INDEX_CHUNK", chunk)
    comm = MPI.COMM_WORLD
    rank = comm.rank
    before = layout_module.BlockLayout(comm, 5 + 2 * rank, [3 + rank, rank % 2])
    after = layout_module.BlockLayout(comm, 5 + 2 * rank, [0, 2 + rank])
    dofs = np.r_[-1, np.arange(int(before.field_offsets[-1, 0]))]
    rows = before.u(dofs)
    assert np.unique(rows[1:]).size == dofs.size - 1  # (not the identity: rows skip z)
    if comm.size > 1:
        assert not np.array_equal(rows[1:], dofs[1:])
    back = before.u_global(rows.astype(np.int32).reshape(-1, 1), np.int32)
    assert back.dtype == np.int32 and back.shape == (dofs.size, 1)
    np.testing.assert_array_equal(back.reshape(-1), dofs)
    np.testing.assert_array_equal(after.u(before.u_global(rows)), after.u(dofs))
