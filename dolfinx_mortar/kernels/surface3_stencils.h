/* The plain passes around the kernel, included at the end of surface3.c, no dual numbers: the
 * pairs' coordinates gathered from the node tables, and the stencils' passes over the
 * gradients a consumer asks for (stencils.py). */

/* out (num_rows, k, 3) = table[index[r * index_stride + j]] (the rows of a node table named by
 * k indices a pair, int32). Returns -1 for an index outside the table's table_rows rows. */
int gather_rows(long num_rows, int k, const double *table, long table_rows, const int *index,
                long index_stride, double *out) {
    for (long r = 0; r < num_rows; ++r)
        for (int j = 0; j < k; ++j) {
            const long i = index[r * index_stride + j];
            if (i < 0 || i >= table_rows) return -1;
            double *o = out + 3 * (r * k + j);
            const double *t = table + 3 * i;
            o[0] = t[0]; o[1] = t[1]; o[2] = t[2];
        }
    return 0;
}

/* ======================================================================================
 * The consumers' linear combinations of output gradients (stencils.PairStencil._row_gradients):
 * out (num_terms, num_rows, nv) += weight_e[r] * grad[r, index[e], :] for each entry e into
 * term[e], entries in order; grad (num_rows, size, nv); weight_e[r] is
 * weights[weight_start[e] + r * weight_step[e]] (step 0: one number for every row). One pass
 * over the rows, so that a row's gradients are read once for all terms. Returns -1 for an
 * index outside the outputs.
 * ====================================================================================== */
int gradients_combine(long num_rows, int nv, int size, const double *grad, int num_entries,
                      const int *term, const int *index, const long *weight_start,
                      const int *weight_step, const double *weights, double *out) {
    for (int e = 0; e < num_entries; ++e)
        if (index[e] < 0 || index[e] >= size) return -1;
    for (long r = 0; r < num_rows; ++r) {
        const double *row = grad + (long)size * nv * r;
        for (int e = 0; e < num_entries; ++e) {
            const double w = weights[weight_start[e] + r * weight_step[e]];
            const double *g = row + (long)index[e] * nv;
            double *o = out + ((long)term[e] * num_rows + r) * nv;
            for (int v = 0; v < nv; ++v) o[v] += g[v] * w;
        }
    }
    return 0;
}

/* The stencil's columns of combined gradients (stencils.Surface3Stencil.combined_gradients):
 * kernel (num_terms, num_rows, nv) over the kernel's variables, whose first `direct` are the
 * facet nodes' coordinates and the next 3 ns the slave nodal normals; J (num_rows, ns, 3,
 * width3) d n_j[c] / d x over the normal's star, or NULL (no chain: those columns are zero).
 * out (t, column, r) at out[(t cols + column) row_stride + r], cols = direct + ns width3:
 * written a tile of rows at a time, so that each column's writes are contiguous. */
#define COLUMN_TILE 64
void stencil_columns(long num_rows, long row_stride, int num_terms, int nv, int direct, int ns,
                     int width3, const double *kernel, const double *J, double *out) {
    const int cols = direct + ns * width3;
    for (long r0 = 0; r0 < num_rows; r0 += COLUMN_TILE) {
        const long r1 = r0 + COLUMN_TILE < num_rows ? r0 + COLUMN_TILE : num_rows;
        for (int t = 0; t < num_terms; ++t) {
            const double *k = kernel + (long)t * num_rows * nv;
            double *o = out + (long)t * cols * row_stride;
            for (int v = 0; v < direct; ++v) {
                double *column = o + (long)v * row_stride;
                for (long r = r0; r < r1; ++r) column[r] = k[r * nv + v];
            }
            for (int j = 0; j < ns; ++j)
                for (int s = 0; s < width3; ++s) {
                    double *column = o + (long)(direct + j * width3 + s) * row_stride;
                    if (!J) {
                        for (long r = r0; r < r1; ++r) column[r] = 0.0;
                        continue;
                    }
                    for (long r = r0; r < r1; ++r) {
                        const double *kr = k + r * nv + direct + 3 * j;
                        const double *Jr = J + (r * ns + j) * 3 * width3 + s;
                        column[r] = (kr[0] * Jr[0] + kr[1] * Jr[width3]) + kr[2] * Jr[2 * width3];
                    }
                }
        }
    }
}
