/* Where the dense blocks of groups go in a sparse pattern (layout.CooMatrix), compiled as its
 * own module (compiled.load("pattern")). */
#include <stdlib.h>

/* out[i, j, g] = 1 + k where indices[k] == cols[g, j] within row rows[g, i] of the CSR pattern
 * (indptr, indices) of num_rows rows and columns below num_cols, 0 where the row has no such
 * column (or the column is outside [0, num_cols)): n groups of nr rows and nc columns (out in
 * the order of the groups' values, pattern_sum's). With offsets (out NULL) the same as
 * starts[i, g] = indptr[rows[g, i]] and offsets[i, j, g] = out[i, j, g] - starts[i, g] (0
 * where out is 0; every row shorter than 65535). Row by row: the row's positions are
 * scattered into a marker of its columns once and read by every group that has the row
 * (groups share rows: a slave node's force rows are in every pair of its facets). Returns -1
 * if out of memory. */
int pattern_positions(long n, int nr, int nc, const int *rows, const int *cols,
                      const long *indptr, const int *indices, long num_rows, long num_cols,
                      int *out, int *starts, unsigned short *offsets) {
    const long entries = n * nr;
    long *start = calloc((size_t)num_rows + 1, sizeof(long));
    long *order = malloc(sizeof(long) * (size_t)(entries > 0 ? entries : 1));
    int *marker = calloc((size_t)(num_cols > 0 ? num_cols : 1), sizeof(int));
    if (!start || !order || !marker) {
        free(start);
        free(order);
        free(marker);
        return -1;
    }
    for (long e = 0; e < entries; ++e) ++start[rows[e] + 1];
    for (long r = 0; r < num_rows; ++r) start[r + 1] += start[r];
    for (long e = 0; e < entries; ++e) order[start[rows[e]]++] = e;
    for (long r = num_rows; r > 0; --r) start[r] = start[r - 1];
    start[0] = 0;
    for (long r = 0; r < num_rows; ++r) {
        if (start[r] == start[r + 1]) continue;
        for (long k = indptr[r]; k < indptr[r + 1]; ++k) marker[indices[k]] = (int)(k + 1);
        for (long p = start[r]; p < start[r + 1]; ++p) {
            const long g = order[p] / nr, i = order[p] % nr;
            const int *group_cols = cols + g * nc;
            if (offsets) {
                unsigned short *row_offsets = offsets + i * nc * n + g;
                starts[i * n + g] = (int)indptr[r];
                for (int j = 0; j < nc; ++j) {
                    const int column = group_cols[j];
                    const int found = (column >= 0 && column < num_cols) ? marker[column] : 0;
                    row_offsets[j * n] = (unsigned short)(found ? found - indptr[r] : 0);
                }
                continue;
            }
            int *row_out = out + i * nc * n + g;
            for (int j = 0; j < nc; ++j) {
                const int column = group_cols[j];
                row_out[j * n] = (column >= 0 && column < num_cols) ? marker[column] : 0;
            }
        }
        for (long k = indptr[r]; k < indptr[r + 1]; ++k) marker[indices[k]] = 0;
    }
    free(start);
    free(order);
    free(marker);
    return 0;
}

/* sums[a, b, positions[i, j, g]] += values[i, a, j, b, g] over n groups of nr x br rows and
 * nc x bc columns, positions[i, j, g] at (i nc + j) stride + g (0: a dropped entry, summed
 * into the unread slot 0), or with offsets (positions NULL) the position
 * starts[i stride + g] + offsets[(i nc + j) stride + g] (0 where the offset is 0); sums is
 * (br, bc, count + 1). Each sum takes its entries in the order (i, j, g), or with
 * group_major (g, i, j): that of np.bincount over the entries in either order. */
void pattern_sum(long n, int nr, int br, int nc, int bc, const int *positions,
                 const int *starts, const unsigned short *offsets, long stride,
                 const double *values, long count, int group_major, double *sums) {
    const long slot = count + 1;
    if (group_major) {
        for (long g = 0; g < n; ++g)
            for (int i = 0; i < nr; ++i)
                for (int a = 0; a < br; ++a)
                    for (int j = 0; j < nc; ++j) {
                        const long at = ((long)i * nc + j) * stride + g;
                        long where;
                        if (offsets)
                            where = offsets[at] ? (long)starts[(long)i * stride + g] + offsets[at]
                                                : 0;
                        else
                            where = positions[at];
                        for (int b = 0; b < bc; ++b)
                            sums[((long)a * bc + b) * slot + where] +=
                                values[((((long)i * br + a) * nc + j) * bc + b) * n + g];
                    }
        return;
    }
    for (int i = 0; i < nr; ++i)
        for (int a = 0; a < br; ++a)
            for (int j = 0; j < nc; ++j) {
                const long at = ((long)i * nc + j) * stride;
                for (int b = 0; b < bc; ++b) {
                    const double *v = values + ((((long)i * br + a) * nc + j) * bc + b) * n;
                    double *s = sums + ((long)a * bc + b) * slot;
                    if (offsets) {
                        const unsigned short *o = offsets + at;
                        const int *first = starts + (long)i * stride;
                        for (long g = 0; g < n; ++g) s[o[g] ? first[g] + o[g] : 0] += v[g];
                    } else {
                        const int *where = positions + at;
                        for (long g = 0; g < n; ++g) s[where[g]] += v[g];
                    }
                }
            }
}

/* pattern_sum over a part of the groups' blocks, without a copy of their positions: values
 * (nr, br, nk, bc, n) of the groups which[0 .. n - 1] (NULL: 0 .. n - 1) on the block columns
 * columns[0 .. nk - 1] (NULL: 0 .. nk - 1) of positions (nr, nc, stride), or of starts and
 * offsets as pattern_sum's. The order of the additions is pattern_sum's (i, j, g). Returns
 * -1 for a group or column outside positions. */
int pattern_sum_part(long n, int nr, int br, int nc, int bc, const int *positions,
                     const int *starts, const unsigned short *offsets, long stride,
                     const long *which, int nk, const long *columns, const double *values,
                     long count, double *sums) {
    const long slot = count + 1;
    for (long g = 0; which && g < n; ++g)
        if (which[g] < 0 || which[g] >= stride) return -1;
    for (int k = 0; columns && k < nk; ++k)
        if (columns[k] < 0 || columns[k] >= nc) return -1;
    for (int i = 0; i < nr; ++i)
        for (int a = 0; a < br; ++a)
            for (int k = 0; k < nk; ++k) {
                const long j = columns ? columns[k] : k;
                const long at = ((long)i * nc + j) * stride;
                const int *first = offsets ? starts + (long)i * stride : NULL;
                for (int b = 0; b < bc; ++b) {
                    const double *v = values + ((((long)i * br + a) * nk + k) * bc + b) * n;
                    double *s = sums + ((long)a * bc + b) * slot;
                    if (offsets) {
                        const unsigned short *o = offsets + at;
                        for (long g = 0; g < n; ++g) {
                            const long e = which ? which[g] : g;
                            s[o[e] ? first[e] + o[e] : 0] += v[g];
                        }
                    } else {
                        const int *where = positions + at;
                        if (which)
                            for (long g = 0; g < n; ++g) s[where[which[g]]] += v[g];
                        else
                            for (long g = 0; g < n; ++g) s[where[g]] += v[g];
                    }
                }
            }
    return 0;
}

/* The union of two CSR patterns of num_rows rows (each row's columns strictly increasing):
 * with out_indices NULL, out_indptr (num_rows + 1) gets the union's row starts; else the
 * union's columns go to out_indices (out_indptr as the first call made it). Pattern a has
 * rows in [0, a_rows) only and is blocked: a_indptr (a_rows / a_block + 1) over its block
 * rows, a_indices the first column of each a_block x a_block block (a_block 1: a plain CSR
 * pattern). Returns -1 if a row of either pattern is not strictly increasing. */
int pattern_union(long num_rows, long a_rows, int a_block, const long *a_indptr,
                  const int *a_indices, const long *b_indptr, const int *b_indices,
                  long *out_indptr, int *out_indices) {
    if (!out_indices) out_indptr[0] = 0;
    for (long r = 0; r < num_rows; ++r) {
        /* a's columns run over its block entries e, each a_block columns d = 0, 1, ... */
        long e = 0, e_stop = 0;
        if (r < a_rows) {
            e = a_indptr[r / a_block];
            e_stop = a_indptr[r / a_block + 1];
        }
        int d = 0;
        long j = b_indptr[r], b_stop = b_indptr[r + 1];
        long k = out_indptr[r];
        for (long p = e + 1; p < e_stop; ++p)
            if ((long)a_indices[p] < (long)a_indices[p - 1] + a_block) return -1;
        for (long p = j + 1; p < b_stop; ++p)
            if (b_indices[p] <= b_indices[p - 1]) return -1;
        while (e < e_stop || j < b_stop) {
            int column;
            int a_column = e < e_stop ? a_indices[e] + d : 0;
            int take_a = 0, take_b = 0;
            if (j == b_stop || (e < e_stop && a_column < b_indices[j])) {
                take_a = 1;
            } else if (e == e_stop || b_indices[j] < a_column) {
                take_b = 1;
            } else {
                take_a = take_b = 1;
            }
            column = take_a ? a_column : b_indices[j];
            if (take_a && ++d == a_block) {
                d = 0;
                ++e;
            }
            if (take_b) ++j;
            if (out_indices) out_indices[k] = column;
            ++k;
        }
        if (!out_indices) out_indptr[r + 1] = k;
    }
    return 0;
}

/* A CSR pattern of num_rows rows (a multiple of bs) as bs x bs blocks: block_indptr
 * (num_rows / bs + 1) and the first column of each block (block_first, as many as the
 * pattern has entries / bs^2). Returns -1 if the pattern is not made of whole blocks (the
 * rows of a block row alike, each a run of whole blocks, their first columns multiples of
 * bs). */
int pattern_blocks(long num_rows, int bs, const long *indptr, const int *indices,
                   long *block_indptr, int *block_first) {
    block_indptr[0] = 0;
    for (long b = 0; b < num_rows / bs; ++b) {
        long first = indptr[b * bs], length = indptr[b * bs + 1] - first;
        if (length % bs) return -1;
        long blocks = length / bs;
        block_indptr[b + 1] = block_indptr[b] + blocks;
        for (int c = 0; c < bs; ++c) {
            long start = indptr[b * bs + c];
            if (indptr[b * bs + c + 1] - start != length) return -1;
            for (long e = 0; e < blocks; ++e) {
                int column = indices[first + e * bs];
                if (column % bs) return -1;
                for (int d = 0; d < bs; ++d)
                    if (indices[start + e * bs + d] != column + d) return -1;
                if (c == 0) block_first[block_indptr[b] + e] = column;
            }
        }
    }
    return 0;
}

static int compare_int(const void *a, const void *b) {
    int x = *(const int *)a, y = *(const int *)b;
    return (x > y) - (x < y);
}

/* The block pattern of n groups of nr row blocks and nc column blocks (row_blocks,
 * col_blocks; a value outside [0, num_row_blocks) or [0, num_col_blocks): none): block row r
 * holds block column c if a group has both. The pattern has num_row_blocks + 1 rows, the last
 * empty. With out_indices NULL, out_indptr (num_row_blocks + 2) gets the row starts; else
 * each row's columns go to out_indices, sorted. Returns -1 if out of memory. */
int pattern_of_groups(long n, int nr, int nc, const int *row_blocks, const int *col_blocks,
                      long num_row_blocks, long num_col_blocks, long *out_indptr,
                      int *out_indices) {
    long *start = calloc((size_t)num_row_blocks + 1, sizeof(long));
    long *marker = malloc(sizeof(long) * (size_t)(num_col_blocks > 0 ? num_col_blocks : 1));
    if (!start || !marker) {
        free(start);
        free(marker);
        return -1;
    }
    for (long e = 0; e < n * nr; ++e)
        if (row_blocks[e] >= 0 && row_blocks[e] < num_row_blocks) ++start[row_blocks[e] + 1];
    for (long r = 0; r < num_row_blocks; ++r) start[r + 1] += start[r];
    long total = start[num_row_blocks];
    long *groups = malloc(sizeof(long) * (size_t)(total > 0 ? total : 1));
    long *cursor = malloc(sizeof(long) * (size_t)(num_row_blocks > 0 ? num_row_blocks : 1));
    if (!groups || !cursor) {
        free(start);
        free(marker);
        free(groups);
        free(cursor);
        return -1;
    }
    for (long r = 0; r < num_row_blocks; ++r) cursor[r] = start[r];
    for (long e = 0; e < n * nr; ++e)
        if (row_blocks[e] >= 0 && row_blocks[e] < num_row_blocks)
            groups[cursor[row_blocks[e]]++] = e / nr;
    for (long c = 0; c < num_col_blocks; ++c) marker[c] = -1;
    if (!out_indices) out_indptr[0] = 0;
    for (long r = 0; r < num_row_blocks; ++r) {
        long k = out_indptr[r];
        for (long p = start[r]; p < start[r + 1]; ++p) {
            const int *cols = col_blocks + groups[p] * nc;
            for (int j = 0; j < nc; ++j) {
                int c = cols[j];
                if (c < 0 || c >= num_col_blocks || marker[c] == r) continue;
                marker[c] = r;
                if (out_indices) out_indices[k] = c;
                ++k;
            }
        }
        if (out_indices)
            qsort(out_indices + out_indptr[r], (size_t)(k - out_indptr[r]), sizeof(int),
                  compare_int);
        else
            out_indptr[r + 1] = k;
    }
    if (!out_indices) out_indptr[num_row_blocks + 1] = out_indptr[num_row_blocks];
    free(start);
    free(marker);
    free(groups);
    free(cursor);
    return 0;
}
