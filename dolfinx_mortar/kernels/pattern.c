/* Where the dense blocks of groups go in a sparse pattern (layout.CooMatrix), compiled as its
 * own module (compiled.load("pattern")). */
#include <stdlib.h>

/* the order of the nc columns of a group, by value (insertion sort: nc is a stencil's width) */
static void sort_columns(int nc, const int *cols, int *order) {
    for (int j = 0; j < nc; ++j) {
        int k = j;
        while (k > 0 && cols[order[k - 1]] > cols[j]) {
            order[k] = order[k - 1];
            --k;
        }
        order[k] = j;
    }
}

/* out[g, i, j] = 1 + k where indices[k] == cols[g, j] within row rows[g, i] of the CSR pattern
 * (indptr, indices: each row's columns sorted), 0 where the row has no such column: n groups of
 * nr rows and nc columns. The group's columns are sorted once and each row is walked beside
 * them. Returns -1 if out of memory. */
int pattern_positions(long n, int nr, int nc, const int *rows, const int *cols,
                      const long *indptr, const int *indices, int *out) {
    int *order = malloc(sizeof(int) * (size_t)(nc > 0 ? nc : 1));
    if (!order) return -1;
    for (long g = 0; g < n; ++g) {
        const int *group_cols = cols + g * nc;
        sort_columns(nc, group_cols, order);
        for (int i = 0; i < nr; ++i) {
            int *row_out = out + (g * nr + i) * nc;
            long k = indptr[rows[g * nr + i]], stop = indptr[rows[g * nr + i] + 1];
            for (int s = 0; s < nc; ++s) {
                int j = order[s], column = group_cols[j];
                while (k < stop && indices[k] < column) ++k;
                row_out[j] = (k < stop && indices[k] == column) ? (int)(k + 1) : 0;
            }
        }
    }
    free(order);
    return 0;
}
