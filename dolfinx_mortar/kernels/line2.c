/* The 2D mortar kernel in C: a linear slave facet a -> b on a linear master facet c -> d,
 * averaged, slave or master normals, segment- or element-based integration, standard or dual
 * multiplier basis, crosspoints (dolfinx_mortar/kernels/line2.py's module docstring describes
 * the method and the 12 pair variables p, a, b, q, c, d). "The numpy kernel" below is the
 * package's former vectorized kernel, now the tests' oracle, tests/oracle/line2_numpy.py.
 *
 * Two passes, as the numpy kernel:
 *  - line2_screen, values only, every pair: facing test, and segment-based the projections of
 *    c and d onto the slave facet (the overlap length), element-based the master parameter eta
 *    of each slave Gauss point (the caller gives each point to one master facet);
 *  - line2_integrate, the contributing pairs only: D, M, Dn, Mn, the areas and the gaps with
 *    their gradients over the 12 pair variables, per pair on the stack (see integrate).
 * Values follow the numpy kernel's operation order, so that the discrete decisions (facing,
 * projection found, parallel, overlap) are taken on the same bits.
 */
#include <math.h>
#include <string.h>

#define NV 12

static const double FACING_TOLERANCE = 1e-8;
static const double PARALLEL_TOLERANCE = 1e-10;

enum { AVERAGED = 0, SLAVE = 1, MASTER = 2 };

/* ---- values (screening) ---- */

static void unit_normal(double tx, double ty, double *n) {
    double inverse = 1.0 / sqrt(tx * tx + ty * ty);
    n[0] = ty * inverse;
    n[1] = -tx * inverse;
}

static void normal_values(const double *x, const unsigned char *has, int normals, double *na,
                          double *nb) {
    double n[2];
    if (normals == MASTER) {
        unit_normal(x[10] - x[8], x[11] - x[9], n);
        na[0] = nb[0] = -n[0];
        na[1] = nb[1] = -n[1];
        return;
    }
    unit_normal(x[4] - x[2], x[5] - x[3], n);
    if (normals == SLAVE) {
        na[0] = nb[0] = n[0];
        na[1] = nb[1] = n[1];
        return;
    }
    double va[2] = {n[0], n[1]}, vb[2] = {n[0], n[1]}, m[2];
    if (has[0]) {
        unit_normal(x[2] - x[0], x[3] - x[1], m);
        va[0] = n[0] + m[0];
        va[1] = n[1] + m[1];
    }
    if (has[1]) {
        unit_normal(x[6] - x[4], x[7] - x[5], m);
        vb[0] = n[0] + m[0];
        vb[1] = n[1] + m[1];
    }
    double inverse_a = 1.0 / sqrt(va[0] * va[0] + va[1] * va[1]);
    double inverse_b = 1.0 / sqrt(vb[0] * vb[0] + vb[1] * vb[1]);
    na[0] = va[0] * inverse_a; na[1] = va[1] * inverse_a;
    nb[0] = vb[0] * inverse_b; nb[1] = vb[1] * inverse_b;
}

static int facing(const double *x) {
    double tx = x[4] - x[2], ty = x[5] - x[3];
    double length = sqrt(tx * tx + ty * ty);
    double ux = x[10] - x[8], uy = x[11] - x[9];
    double master_length = sqrt(ux * ux + uy * uy);
    double cosine = (ty / length) * (uy / master_length) + (-tx / length) * (-ux / master_length);
    return cosine < -FACING_TOLERANCE;
}

/* xi where the normal line through x_s(xi) meets the point (px, py); returns whether found */
static int project_value(const double *s0, const double *s1, const double *n0, const double *n1,
                         double px, double py, double *xi) {
    double offx = s0[0] - px, offy = s0[1] - py;
    double c = offx * n0[1] - offy * n0[0];
    double b = (offx * n1[1] - offy * n1[0]) + (s1[0] * n0[1] - s1[1] * n0[0]);
    double a = s1[0] * n1[1] - s1[1] * n1[0];
    double discriminant = b * b - a * c * 4.0;
    int ok = discriminant >= 0.0;
    double root = sqrt(ok ? discriminant : 0.0);
    double sign = b >= 0.0 ? 1.0 : -1.0;
    double denominator = b + root * sign;
    double scale = sqrt(s1[0] * s1[0] + s1[1] * s1[1]) * sqrt(n0[0] * n0[0] + n0[1] * n0[1]);
    ok = ok && fabs(denominator) > PARALLEL_TOLERANCE * scale;
    double inverse = 1.0 / (ok ? denominator : 1.0);
    *xi = c * -2.0 * inverse;
    return ok;
}

static void segment_limits_value(double xi_c, double xi_d, double *low, double *high) {
    double lower = xi_c <= xi_d ? xi_c : xi_d;
    *low = -1.0 >= lower ? -1.0 : lower;
    double upper = xi_c >= xi_d ? xi_c : xi_d;
    *high = 1.0 <= upper ? 1.0 : upper;
}

/* the master parameter eta of the slave point xi; returns whether the master is parallel to
 * the normal there */
static int eta_value(const double *x, const double *na, const double *nb, double xi,
                     double *eta) {
    double N0 = (1.0 - xi) * 0.5, N1 = (xi + 1.0) * 0.5;
    double point[2] = {N0 * x[2] + N1 * x[4], N0 * x[3] + N1 * x[5]};
    double normal[2] = {N0 * na[0] + N1 * nb[0], N0 * na[1] + N1 * nb[1]};
    double m0[2] = {(x[8] + x[10]) * 0.5, (x[9] + x[11]) * 0.5};
    double m1[2] = {(x[10] - x[8]) * 0.5, (x[11] - x[9]) * 0.5};
    double cross = m1[0] * normal[1] - m1[1] * normal[0];
    int parallel = fabs(cross) <= PARALLEL_TOLERANCE * sqrt(m1[0] * m1[0] + m1[1] * m1[1]);
    double inverse = 1.0 / (parallel ? 1.0 : cross);
    double relative[2] = {m0[0] - point[0], m0[1] - point[1]};
    *eta = -(relative[0] * normal[1] - relative[1] * normal[0]) * inverse;
    return parallel;
}

/* the 12 variables p, a, b, q, c, d of pair p from the contract's arrays: slave and master
 * facet nodes (n, 2, 2) and the slave facets' neighbours p, q (n, 2, 2) */
static void gather(const double *slave, const double *master, const double *neighbour, long p,
                   double *x) {
    const double *s = slave + 4 * p, *m = master + 4 * p, *e = neighbour + 4 * p;
    x[0] = e[0]; x[1] = e[1]; x[2] = s[0]; x[3] = s[1];
    x[4] = s[2]; x[5] = s[3]; x[6] = e[2]; x[7] = e[3];
    x[8] = m[0]; x[9] = m[1]; x[10] = m[2]; x[11] = m[3];
}

/* The arrays gather reads, from the node table node_x (table_rows, 2) and the pairs' stencil
 * nodes (n, 6: p, a, b, q, c, d): slave (a, b), master (c, d), neighbour (p, q), each (n, 2, 2).
 * Returns -1 for a node outside the table. */
int line2_gather(long n, const long *nodes, const double *node_x, long table_rows,
                 double *slave, double *master, double *neighbour) {
    static const int slot[6] = {0, 0, 1, 1, 0, 1}, side[6] = {2, 0, 0, 2, 1, 1};
    for (long p = 0; p < n; ++p)
        for (int j = 0; j < 6; ++j) {
            const long i = nodes[6 * p + j];
            if (i < 0 || i >= table_rows) return -1;
            double *out = (side[j] == 0 ? slave : side[j] == 1 ? master : neighbour)
                          + 4 * p + 2 * slot[j];
            out[0] = node_x[2 * i];
            out[1] = node_x[2 * i + 1];
        }
    return 0;
}

/* whether the slave facet and neighbours of x (and has) are those of the last pair (then its
 * slave normals hold); if not, they become the last pair's */
static int same_slave(const double *x, const unsigned char *has, double *last,
                      unsigned char *last_has) {
    if (has[0] == last_has[0] && has[1] == last_has[1] && memcmp(x, last, 8 * sizeof(double)) == 0)
        return 1;
    memcpy(last, x, 8 * sizeof(double));
    last_has[0] = has[0];
    last_has[1] = has[1];
    return 0;
}

/* n pairs (slave, master, neighbour: see gather), has_neighbour (n, 2). Segment-based
 * (element == 0): valid (facing and both projections found) and screened[p] = high - low.
 * Element-based: valid (facing and no Gauss point where the master is parallel to the normal)
 * and screened (n, g) = eta. */
void line2_screen(long n, const double *slave, const double *master, const double *neighbour,
                  const unsigned char *has_neighbour, int normals,
                  int element, int num_points, const double *points, unsigned char *valid,
                  double *screened) {
    double na[2] = {0.0, 0.0}, nb[2] = {0.0, 0.0}, last[8];
    unsigned char last_has[2] = {2, 2};
    for (long p = 0; p < n; ++p) {
        double xp[NV];
        gather(slave, master, neighbour, p, xp);
        if (normals == MASTER || !same_slave(xp, has_neighbour + 2 * p, last, last_has))
            normal_values(xp, has_neighbour + 2 * p, normals, na, nb);
        int ok = facing(xp);
        if (!element) {
            double s0[2] = {(xp[2] + xp[4]) * 0.5, (xp[3] + xp[5]) * 0.5};
            double s1[2] = {(xp[4] - xp[2]) * 0.5, (xp[5] - xp[3]) * 0.5};
            double n0[2] = {(na[0] + nb[0]) * 0.5, (na[1] + nb[1]) * 0.5};
            double n1[2] = {(nb[0] - na[0]) * 0.5, (nb[1] - na[1]) * 0.5};
            double xi_c, xi_d, low, high;
            int ok_c = project_value(s0, s1, n0, n1, xp[8], xp[9], &xi_c);
            int ok_d = project_value(s0, s1, n0, n1, xp[10], xp[11], &xi_d);
            segment_limits_value(xi_c, xi_d, &low, &high);
            valid[p] = ok && ok_c && ok_d;
            screened[p] = high - low;
        } else {
            int parallel = 0;
            for (int g = 0; g < num_points; ++g)
                parallel |= eta_value(xp, na, nb, points[g], screened + (long)num_points * p + g);
            valid[p] = ok && !parallel;
        }
    }
}

/* ---- pair-level gradients (12 variables), as the numpy kernel writes them out ---- */

/* d n / d t of n = (t_y, -t_x)/|t| as the entries (00, 01, 10, 11) */
static void unit_normal_jacobian(const double *n, double tx, double ty, double inverse, double *J) {
    double ux = tx * inverse, uy = ty * inverse;
    J[0] = (-ux * n[0]) * inverse; J[1] = (1.0 - uy * n[0]) * inverse;
    J[2] = (-1.0 - ux * n[1]) * inverse; J[3] = (-uy * n[1]) * inverse;
}

/* d n / d v of n = v/|v| */
static void normalize_jacobian(const double *n, double inverse, double *J) {
    double off = (-n[0] * n[1]) * inverse;
    J[0] = (1.0 - n[0] * n[0]) * inverse; J[1] = off; J[2] = off; J[3] = (1.0 - n[1] * n[1]) * inverse;
}

static void matmul2(const double *A, const double *B, double *C) {
    C[0] = A[0] * B[0] + A[1] * B[2]; C[1] = A[0] * B[1] + A[1] * B[3];
    C[2] = A[2] * B[0] + A[3] * B[2]; C[3] = A[2] * B[1] + A[3] * B[3];
}

/* grad (2 x 12) += factor J on the two variables of node (0..5 = p, a, b, q, c, d) */
static void add_block(double grad[2][NV], int node, const double *J, double factor) {
    for (int row = 0; row < 2; ++row)
        for (int column = 0; column < 2; ++column)
            grad[row][2 * node + column] += J[2 * row + column] * factor;
}

static void unit_normal_with_inverse(double tx, double ty, double *n, double *inverse) {
    *inverse = 1.0 / sqrt(tx * tx + ty * ty);
    n[0] = ty * *inverse;
    n[1] = -tx * *inverse;
}

/* the nodal normals n_a, n_b (the values of normal_values) and their gradients */
static void normal_field(const double *x, const unsigned char *has, int normals, double *na,
                         double *nb, double grad_a[2][NV], double grad_b[2][NV]) {
    memset(grad_a, 0, 2 * NV * sizeof(double));
    memset(grad_b, 0, 2 * NV * sizeof(double));
    double n[2], inverse, J[4];
    if (normals == MASTER) {
        double tx = x[10] - x[8], ty = x[11] - x[9];
        unit_normal_with_inverse(tx, ty, n, &inverse);
        unit_normal_jacobian(n, tx, ty, inverse, J);
        na[0] = nb[0] = -n[0];
        na[1] = nb[1] = -n[1];
        add_block(grad_a, 4, J, 1.0);
        add_block(grad_a, 5, J, -1.0);
        memcpy(grad_b, grad_a, 2 * NV * sizeof(double));
        return;
    }
    double tx = x[4] - x[2], ty = x[5] - x[3], J_ab[4];
    unit_normal_with_inverse(tx, ty, n, &inverse);
    unit_normal_jacobian(n, tx, ty, inverse, J_ab);
    if (normals == SLAVE) {
        na[0] = nb[0] = n[0];
        na[1] = nb[1] = n[1];
        add_block(grad_a, 1, J_ab, -1.0);
        add_block(grad_a, 2, J_ab, 1.0);
        memcpy(grad_b, grad_a, 2 * NV * sizeof(double));
        return;
    }
    /* n_a = normalize(n(x_b - x_a) + n(x_a - x_p)), n_b = normalize(n(x_b - x_a) + n(x_q - x_b)),
     * an absent neighbour's term left out */
    double va[2] = {n[0], n[1]}, vb[2] = {n[0], n[1]}, m[2];
    double J_pa[4] = {0.0}, J_bq[4] = {0.0};
    if (has[0]) {
        double px = x[2] - x[0], py = x[3] - x[1];
        unit_normal_with_inverse(px, py, m, &inverse);
        unit_normal_jacobian(m, px, py, inverse, J_pa);
        va[0] = n[0] + m[0];
        va[1] = n[1] + m[1];
    }
    if (has[1]) {
        double qx = x[6] - x[4], qy = x[7] - x[5];
        unit_normal_with_inverse(qx, qy, m, &inverse);
        unit_normal_jacobian(m, qx, qy, inverse, J_bq);
        vb[0] = n[0] + m[0];
        vb[1] = n[1] + m[1];
    }
    double inverse_a = 1.0 / sqrt(va[0] * va[0] + va[1] * va[1]);
    double inverse_b = 1.0 / sqrt(vb[0] * vb[0] + vb[1] * vb[1]);
    na[0] = va[0] * inverse_a; na[1] = va[1] * inverse_a;
    nb[0] = vb[0] * inverse_b; nb[1] = vb[1] * inverse_b;
    double J_a[4], J_b[4], product[4], difference[4];
    normalize_jacobian(na, inverse_a, J_a);
    normalize_jacobian(nb, inverse_b, J_b);
    matmul2(J_a, J_pa, product);
    add_block(grad_a, 0, product, -1.0);
    for (int e = 0; e < 4; ++e) difference[e] = J_pa[e] - J_ab[e];
    matmul2(J_a, difference, product);
    add_block(grad_a, 1, product, 1.0);
    matmul2(J_a, J_ab, product);
    add_block(grad_a, 2, product, 1.0);
    matmul2(J_b, J_ab, product);
    add_block(grad_b, 1, product, -1.0);
    for (int e = 0; e < 4; ++e) difference[e] = J_ab[e] - J_bq[e];
    matmul2(J_b, difference, product);
    add_block(grad_b, 2, product, 1.0);
    matmul2(J_b, J_bq, product);
    add_block(grad_b, 3, product, 1.0);
}

/* the projection xi of master node point_node (4: c, 5: d) and its gradient: project_value's
 * xi = -2 c / (b + sign sqrt(b^2 - 4 a c)) differentiated in c, b, a, then in off = s0 - point,
 * s1, n0 = (n_a + n_b)/2 and n1 = (n_b - n_a)/2 */
static double projection(const double *x, const double *s0, const double *s1, const double *n0,
                         const double *n1, const double grad_a[2][NV], const double grad_b[2][NV],
                         int point_node, double *grad) {
    double offx = s0[0] - x[2 * point_node], offy = s0[1] - x[2 * point_node + 1];
    double c = offx * n0[1] - offy * n0[0];
    double b = (offx * n1[1] - offy * n1[0]) + (s1[0] * n0[1] - s1[1] * n0[0]);
    double a = s1[0] * n1[1] - s1[1] * n1[0];
    double discriminant = b * b - a * c * 4.0;
    double root = sqrt(discriminant >= 0.0 ? discriminant : 0.0);
    double sign = b >= 0.0 ? 1.0 : -1.0;
    double inverse = 1.0 / (b + root * sign);
    double xi = c * -2.0 * inverse;
    double sign_factor = root > 0.0 ? sign * 0.5 / root : 0.0;
    double alpha_c = inverse * (-2.0 + 4.0 * xi * sign_factor * a);
    double alpha_b = -inverse * xi * (1.0 + 2.0 * sign_factor * b);
    double alpha_a = 4.0 * inverse * xi * sign_factor * c;
    double g_off[2] = {alpha_c * n0[1] + alpha_b * n1[1], -(alpha_c * n0[0] + alpha_b * n1[0])};
    double g_s1[2] = {alpha_b * n0[1] + alpha_a * n1[1], -(alpha_b * n0[0] + alpha_a * n1[0])};
    double g_n0[2] = {-(alpha_c * offy + alpha_b * s1[1]), alpha_c * offx + alpha_b * s1[0]};
    double g_n1[2] = {-(alpha_b * offy + alpha_a * s1[1]), alpha_b * offx + alpha_a * s1[0]};
    double f_a0 = 0.5 * (g_n0[0] - g_n1[0]), f_a1 = 0.5 * (g_n0[1] - g_n1[1]);
    double f_b0 = 0.5 * (g_n0[0] + g_n1[0]), f_b1 = 0.5 * (g_n0[1] + g_n1[1]);
    for (int v = 0; v < NV; ++v)
        grad[v] = f_a0 * grad_a[0][v] + f_a1 * grad_a[1][v] + f_b0 * grad_b[0][v] + f_b1 * grad_b[1][v];
    for (int k = 0; k < 2; ++k) {
        grad[2 + k] += 0.5 * (g_off[k] - g_s1[k]);
        grad[4 + k] += 0.5 * (g_off[k] + g_s1[k]);
        grad[2 * point_node + k] -= g_off[k];
    }
    return xi;
}

typedef struct {
    double *D, *M, *Dn, *Mn, *gap, *area;          /* values, at the pair's index */
    double *gD, *gM, *gDn, *gMn, *ggap, *garea;    /* gradients, at the row's index */
    double *G;          /* or all gradients in one array (rows, kept, NV), at the row's index */
    int kept;           /* outputs in G: 24 (Dn, Mn, area, gap, D) or 28 (and M) */
} outputs_t;

/* the stencils' output numbering (Dn, Mn, area, gap, D, M) of the kernel's outputs below: the
 * kernel's output of each, -1 and -2 for the two gaps */
static const int STENCIL_OUTPUTS[28] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15,
                                        16, 17, -1, -2, 18, 19, 20, 21, 22, 23, 24, 25};

/* gradients grad (kernel outputs) and ggap into row r of G (zero if grad is NULL) */
static void put_row(const outputs_t *o, long r, const double (*grad)[NV],
                    const double (*ggap)[NV]) {
    double *row = o->G + (long)o->kept * NV * r;
    if (!grad) {
        memset(row, 0, (size_t)o->kept * NV * sizeof(double));
        return;
    }
    for (int out = 0; out < o->kept; ++out) {
        int source = STENCIL_OUTPUTS[out];
        memcpy(row + out * NV, source >= 0 ? grad[source] : ggap[-1 - source],
               NV * sizeof(double));
    }
}

/* the integrals of pair p (row r); returns 0 if a Gauss point sees the master parallel to the
 * normal (segment-based: the pair contributes nothing).
 *
 * As the numpy kernel: the gradients of a few pair-level quantities (nodal normals, segment
 * limits low and length, facet Jacobian J) over the 12 variables, written out; each output's
 * derivative gathered over the Gauss points as coefficients on those pair-level gradients (through xi, the weight and the normal) plus direct terms on a, b, c, d (through
 * the master parameter eta), and expanded once per output at the end.
 * Outputs o: Dn 0-7 (4 j + 2 k + c), Mn 8-15 (8 + 4 j + 2 l + c), area 16-17, D 18-21
 * (2 j + k), M 22-25 (2 j + l); the gaps are formed from Dn and Mn. */
#define NO 26
typedef struct {
    double na[2], nb[2], grad_na[2][NV], grad_nb[2][NV], x[8];
    unsigned char has[2];
} normal_cache_t;

static int integrate(const double *x, const unsigned char *has, const unsigned char *cross,
                     const unsigned char *on_master, int normals, int element, int num_points,
                     const double *points, const double *weights, const double *dual_basis,
                     const outputs_t *o, long p, long r, normal_cache_t *cache) {
    if (normals == MASTER || !same_slave(x, has, cache->x, cache->has))
        normal_field(x, has, normals, cache->na, cache->nb, cache->grad_na, cache->grad_nb);
    const double *nav = cache->na, *nbv = cache->nb;
    const double (*grad_na)[NV] = cache->grad_na, (*grad_nb)[NV] = cache->grad_nb;
    const double ax = x[2], ay = x[3], bx = x[4], by = x[5];
    const double s1[2] = {(bx - ax) * 0.5, (by - ay) * 0.5};
    const double n1[2] = {(nbv[0] - nav[0]) * 0.5, (nbv[1] - nav[1]) * 0.5};
    double jacobian = sqrt(s1[0] * s1[0] + s1[1] * s1[1]);
    double grad_jacobian[NV] = {0.0}, grad_low[NV] = {0.0}, grad_length[NV] = {0.0};
    for (int k = 0; k < 2; ++k) {
        grad_jacobian[2 + k] = -0.5 * s1[k] / jacobian;
        grad_jacobian[4 + k] = 0.5 * s1[k] / jacobian;
    }
    double low = 0.0, length = 0.0;
    if (!element) {
        const double s0[2] = {(ax + bx) * 0.5, (ay + by) * 0.5};
        const double n0[2] = {(nav[0] + nbv[0]) * 0.5, (nav[1] + nbv[1]) * 0.5};
        double grad_c[NV], grad_d[NV];
        double xi_c = projection(x, s0, s1, n0, n1, grad_na, grad_nb, 4, grad_c);
        double xi_d = projection(x, s0, s1, n0, n1, grad_na, grad_nb, 5, grad_d);
        /* low = max(-1, min(xi_c, xi_d)), high = min(1, max(xi_c, xi_d)) */
        int take_c_low = xi_c <= xi_d, take_c_high = xi_c >= xi_d;
        double lower = take_c_low ? xi_c : xi_d, upper = take_c_high ? xi_c : xi_d;
        int clip_low = -1.0 >= lower, clip_high = 1.0 <= upper;
        low = clip_low ? -1.0 : lower;
        length = (clip_high ? 1.0 : upper) - low;
        const double *g_low = take_c_low ? grad_c : grad_d, *g_high = take_c_high ? grad_c : grad_d;
        for (int v = 0; v < NV; ++v) {
            grad_low[v] = clip_low ? 0.0 : g_low[v];
            grad_length[v] = (clip_high ? 0.0 : g_high[v]) - grad_low[v];
        }
    }
    const double m0[2] = {(x[8] + x[10]) * 0.5, (x[9] + x[11]) * 0.5};
    const double m1[2] = {(x[10] - x[8]) * 0.5, (x[11] - x[9]) * 0.5};
    const double m1_length = sqrt(m1[0] * m1[0] + m1[1] * m1[1]);
    /* the multiplier basis Phi_j = B_j0 N0 + B_j1 N1 and its derivative in xi */
    double dphi[2];
    if (dual_basis) {
        for (int j = 0; j < 2; ++j) dphi[j] = -0.5 * dual_basis[2 * j] + 0.5 * dual_basis[2 * j + 1];
    } else {
        dphi[0] = -0.5; dphi[1] = 0.5;
    }
    int crossed = cross && (cross[0] || cross[1]);
    if (crossed) {
        double total = dphi[0] + dphi[1], d0 = dphi[0], d1 = dphi[1];
        dphi[0] = cross[0] ? 0.0 : (cross[1] ? total : d0);
        dphi[1] = cross[1] ? 0.0 : (cross[0] ? total : d1);
    }
    static const double dN[2] = {-0.5, 0.5};
    double value[NO] = {0.0}, c_low[NO] = {0.0}, c_length[NO] = {0.0};
    double Z[2][2][12] = {{{0.0}}}, ZM[2][12] = {{0.0}};  /* sum_g PN_jc (or w Phi_j) d eta */
    double NS[2][2][2] = {{{0.0}}}, NSm[2][2][2] = {{{0.0}}}; /* sum_g w Phi_j N_m N_k, Nm_l */
    for (int g = 0; g < num_points; ++g) {
        if (element && !on_master[g]) continue;
        double xi, weight, half = 0.0;
        if (!element) {
            double half_length = length * 0.5;
            half = points[g] + 1.0;
            xi = low + half_length * half;
            weight = (half_length * weights[g]) * jacobian;
        } else {
            xi = points[g];
            weight = weights[g] * jacobian;
        }
        double N[2] = {(1.0 - xi) * 0.5, (xi + 1.0) * 0.5};
        double point[2] = {N[0] * ax + N[1] * bx, N[0] * ay + N[1] * by};
        double normal[2] = {N[0] * nav[0] + N[1] * nbv[0], N[0] * nav[1] + N[1] * nbv[1]};
        double cross_m1 = m1[0] * normal[1] - m1[1] * normal[0];
        if (fabs(cross_m1) <= PARALLEL_TOLERANCE * m1_length) {
            if (!element) return 0;
            cross_m1 = 1.0;
        }
        double inverse = 1.0 / cross_m1;
        double relative[2] = {m0[0] - point[0], m0[1] - point[1]};
        double eta = -(relative[0] * normal[1] - relative[1] * normal[0]) * inverse;
        double Nm[2] = {(1.0 - eta) * 0.5, (eta + 1.0) * 0.5};
        double phi[2];
        if (dual_basis) {
            for (int j = 0; j < 2; ++j) phi[j] = N[0] * dual_basis[2 * j] + N[1] * dual_basis[2 * j + 1];
        } else {
            phi[0] = N[0]; phi[1] = N[1];
        }
        if (crossed) {
            double total = phi[0] + phi[1], p0 = phi[0], p1 = phi[1];
            phi[0] = cross[0] ? 0.0 : (cross[1] ? total : p0);
            phi[1] = cross[1] ? 0.0 : (cross[0] ? total : p1);
        }
        /* d eta / d (n_a, n_b, x_a, x_b, x_c, x_d) at this point, and d eta / d xi */
        double perp[2] = {-normal[1] * inverse, normal[0] * inverse};
        double rr[2] = {relative[0] + eta * m1[0], relative[1] + eta * m1[1]};
        double rperp[2] = {rr[1] * inverse, -rr[0] * inverse};
        double partial[12] = {N[0] * rperp[0], N[0] * rperp[1], N[1] * rperp[0], N[1] * rperp[1],
                              -N[0] * perp[0], -N[0] * perp[1], -N[1] * perp[0], -N[1] * perp[1],
                              Nm[0] * perp[0], Nm[0] * perp[1], Nm[1] * perp[0], Nm[1] * perp[1]};
        double eta_xi = -(perp[0] * s1[0] + perp[1] * s1[1]) + (rperp[0] * n1[0] + rperp[1] * n1[1]);
        double xi_length = 0.5 * half;
        for (int j = 0; j < 2; ++j) {
            double wphi = phi[j] * weight;
            double PN[2] = {wphi * normal[0], wphi * normal[1]};
            value[16 + j] += wphi;
            for (int e = 0; e < 12; ++e) {
                ZM[j][e] += wphi * partial[e];
                Z[j][0][e] += PN[0] * partial[e];
                Z[j][1][e] += PN[1] * partial[e];
            }
            for (int m = 0; m < 2; ++m) {
                double phi_N = wphi * N[m];
                for (int k = 0; k < 2; ++k) {
                    NS[j][k][m] += phi_N * N[k];
                    NSm[j][k][m] += phi_N * Nm[k];
                }
            }
            for (int k = 0; k < 2; ++k) {
                value[18 + 2 * j + k] += wphi * N[k];
                value[22 + 2 * j + k] += wphi * Nm[k];
                for (int c = 0; c < 2; ++c) {
                    value[4 * j + 2 * k + c] += PN[c] * N[k];
                    value[8 + 4 * j + 2 * k + c] += PN[c] * Nm[k];
                }
            }
            if (element) continue;
            /* d (point integrand) / d xi, gathered on low and length */
            double X_xi[NO] = {0.0};
            X_xi[16 + j] = weight * dphi[j];
            for (int k = 0; k < 2; ++k) {
                X_xi[18 + 2 * j + k] = weight * (dphi[j] * N[k] + phi[j] * dN[k]);
                X_xi[22 + 2 * j + k] = weight * (dphi[j] * Nm[k] + phi[j] * dN[k] * eta_xi);
            }
            for (int c = 0; c < 2; ++c) {
                double Q = weight * dphi[j] * normal[c] + wphi * n1[c];
                for (int k = 0; k < 2; ++k) {
                    X_xi[4 * j + 2 * k + c] = Q * N[k] + PN[c] * dN[k];
                    X_xi[8 + 4 * j + 2 * k + c] = Q * Nm[k] + PN[c] * dN[k] * eta_xi;
                }
            }
            for (int out = 0; out < NO; ++out) {
                c_low[out] += X_xi[out];
                c_length[out] += xi_length * X_xi[out];
            }
        }
    }
    /* every output is proportional to J, and (segment) through its weights to length */
    double inverse_jacobian = 1.0 / jacobian, inverse_length = element ? 0.0 : 1.0 / length;
    double c_normal[NO][4] = {{0.0}}, direct[NO][NV] = {{0.0}};  /* direct: on a, b, c, d */
    for (int j = 0; j < 2; ++j)
        for (int k = 0; k < 2; ++k) {
            for (int c = 0; c < 2; ++c) {
                int dn = 4 * j + 2 * k + c, mn = 8 + 4 * j + 2 * k + c;
                c_normal[dn][c] = NS[j][k][0];
                c_normal[dn][2 + c] = NS[j][k][1];
                for (int e = 0; e < 4; ++e) c_normal[mn][e] = dN[k] * Z[j][c][e];
                c_normal[mn][c] += NSm[j][k][0];
                c_normal[mn][2 + c] += NSm[j][k][1];
                for (int e = 0; e < 4; ++e) {
                    direct[mn][2 + e] = dN[k] * Z[j][c][4 + e];
                    direct[mn][8 + e] = dN[k] * Z[j][c][8 + e];
                }
            }
            int m = 22 + 2 * j + k;
            for (int e = 0; e < 4; ++e) c_normal[m][e] = dN[k] * ZM[j][e];
            for (int e = 0; e < 4; ++e) {
                direct[m][2 + e] = dN[k] * ZM[j][4 + e];
                direct[m][8 + e] = dN[k] * ZM[j][8 + e];
            }
        }
    const double *g_na0 = grad_na[0], *g_na1 = grad_na[1], *g_nb0 = grad_nb[0], *g_nb1 = grad_nb[1];
    /* M's gradients (the last 4 outputs) only where kept */
    int with_m = o->G ? o->kept == 28 : o->gM != NULL;
    double grad[NO][NV];
    /* one pass per output: the gradients of the Jacobian and of the normals are zero outside
     * the variables they depend on (a, b; the facet's nodes and neighbours), so adding them
     * over all 12 adds exact zeros there */
    for (int out = 0; out < (with_m ? NO : NO - 4); ++out) {
        double cl = c_low[out], cL = c_length[out] + value[out] * inverse_length;
        double cJ = value[out] * inverse_jacobian;
        const double *cn = c_normal[out], *d = direct[out];
        for (int v = 0; v < NV; ++v)
            grad[out][v] = cl * grad_low[v] + cL * grad_length[v] + cJ * grad_jacobian[v]
                           + (cn[0] * g_na0[v] + cn[1] * g_na1[v])
                           + (cn[2] * g_nb0[v] + cn[3] * g_nb1[v]) + d[v];
    }
    /* gap_j = sum_kc Mn_jkc x^m_kc - Dn_jkc x^s_kc */
    double gap[2], ggap[2][NV];
    for (int j = 0; j < 2; ++j) {
        double inner[2];
        for (int k = 0; k < 2; ++k) {
            double term[2];
            for (int c = 0; c < 2; ++c)
                term[c] = value[8 + 4 * j + 2 * k + c] * x[8 + 2 * k + c] - value[4 * j + 2 * k + c] * x[2 + 2 * k + c];
            inner[k] = term[0] + term[1];
        }
        gap[j] = inner[0] + inner[1];
        for (int v = 0; v < NV; ++v) {
            double s = 0.0;
            for (int kc = 0; kc < 4; ++kc)
                s += grad[8 + 4 * j + kc][v] * x[8 + kc] - grad[4 * j + kc][v] * x[2 + kc];
            ggap[j][v] = s;
        }
        for (int kc = 0; kc < 4; ++kc) {
            ggap[j][8 + kc] += value[8 + 4 * j + kc];
            ggap[j][2 + kc] -= value[4 * j + kc];
        }
    }
    memcpy(o->Dn + 8 * p, value, 8 * sizeof(double));
    memcpy(o->Mn + 8 * p, value + 8, 8 * sizeof(double));
    memcpy(o->area + 2 * p, value + 16, 2 * sizeof(double));
    memcpy(o->D + 4 * p, value + 18, 4 * sizeof(double));
    memcpy(o->M + 4 * p, value + 22, 4 * sizeof(double));
    memcpy(o->gap + 2 * p, gap, 2 * sizeof(double));
    if (o->G) {
        put_row(o, r, (const double (*)[NV])grad, (const double (*)[NV])ggap);
        return 1;
    }
    memcpy(o->gDn + 8 * NV * r, grad[0], 8 * NV * sizeof(double));
    memcpy(o->gMn + 8 * NV * r, grad[8], 8 * NV * sizeof(double));
    memcpy(o->garea + 2 * NV * r, grad[16], 2 * NV * sizeof(double));
    if (o->gD) memcpy(o->gD + 4 * NV * r, grad[18], 4 * NV * sizeof(double));
    if (o->gM) memcpy(o->gM + 4 * NV * r, grad[22], 4 * NV * sizeof(double));
    memcpy(o->ggap + 2 * NV * r, ggap[0], 2 * NV * sizeof(double));
    return 1;
}

/* The pairs rows[0 .. num_rows - 1] (coordinates as for line2_screen), has_neighbour (n, 2),
 * crosspoint (n, 2) or NULL; on_master (n, g), element-based only (which Gauss points count). dual_basis: the 2 x 2
 * coefficients A (Phi = A N) or NULL (standard basis). Values D, M (n, 2, 2), Dn, Mn
 * (n, 2, 2, 2), area, gap (n, 2) are written at the pair's index (the caller zeroes the
 * others), gradients (num_rows, ..., 12) at the row's; gD, gM may be NULL. contributes[r]:
 * segment-based, 0 where a Gauss point sees the master parallel to the normal (then the pair's
 * values and gradients are zero). */
void line2_integrate(long num_rows, const long *rows, const double *slave,
                     const double *master, const double *neighbour,
                     const unsigned char *has_neighbour, const unsigned char *crosspoint,
                     const unsigned char *on_master, int normals, int element, int num_points,
                     const double *points, const double *weights, const double *dual_basis,
                     unsigned char *contributes,
                     double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                     double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                     double *garea) {
    outputs_t o = {D, M, Dn, Mn, gap, area, gD, gM, gDn, gMn, ggap, garea, NULL, 0};
    normal_cache_t cache = {.has = {2, 2}};
    for (long r = 0; r < num_rows; ++r) {
        long p = rows[r];
        double x[NV];
        gather(slave, master, neighbour, p, x);
        contributes[r] = (unsigned char)integrate(
            x, has_neighbour + 2 * p, crosspoint ? crosspoint + 2 * p : NULL,
            on_master ? on_master + (long)num_points * p : NULL, normals, element, num_points,
            points, weights, dual_basis, &o, p, r, &cache);
        if (!contributes[r]) {
            memset(D + 4 * p, 0, 4 * sizeof(double)); memset(M + 4 * p, 0, 4 * sizeof(double));
            memset(Dn + 8 * p, 0, 8 * sizeof(double)); memset(Mn + 8 * p, 0, 8 * sizeof(double));
            memset(area + 2 * p, 0, 2 * sizeof(double)); memset(gap + 2 * p, 0, 2 * sizeof(double));
            if (gD) memset(gD + 4 * NV * r, 0, 4 * NV * sizeof(double));
            if (gM) memset(gM + 4 * NV * r, 0, 4 * NV * sizeof(double));
            memset(gDn + 8 * NV * r, 0, 8 * NV * sizeof(double));
            memset(gMn + 8 * NV * r, 0, 8 * NV * sizeof(double));
            memset(ggap + 2 * NV * r, 0, 2 * NV * sizeof(double));
            memset(garea + 2 * NV * r, 0, 2 * NV * sizeof(double));
        }
    }
}

static void zero_values(long p, double *D, double *M, double *Dn, double *Mn, double *gap,
                        double *area) {
    memset(D + 4 * p, 0, 4 * sizeof(double)); memset(M + 4 * p, 0, 4 * sizeof(double));
    memset(Dn + 8 * p, 0, 8 * sizeof(double)); memset(Mn + 8 * p, 0, 8 * sizeof(double));
    memset(area + 2 * p, 0, 2 * sizeof(double)); memset(gap + 2 * p, 0, 2 * sizeof(double));
}

/* line2_integrate with the values by rows, D (num_rows, 2, 2) ..., and the gradients of each row
 * together: G (num_rows, kept, 12), the outputs in the stencils' numbering (Dn 0-7, Mn 8-15,
 * area 16-17, gap 18-19, D 20-23, with kept 28 also M 24-27). Returns -1 for a bad kept. */
int line2_integrate_rows(long num_rows, const long *rows, const double *slave,
                         const double *master, const double *neighbour,
                         const unsigned char *has_neighbour, const unsigned char *crosspoint,
                         const unsigned char *on_master, int normals, int element,
                         int num_points, const double *points, const double *weights,
                         const double *dual_basis, unsigned char *contributes,
                         double *D, double *M, double *Dn, double *Mn, double *gap,
                         double *area, int kept, double *G) {
    if (kept != 24 && kept != 28) return -1;
    outputs_t o = {D, M, Dn, Mn, gap, area, NULL, NULL, NULL, NULL, NULL, NULL, G, kept};
    normal_cache_t cache = {.has = {2, 2}};
    for (long r = 0; r < num_rows; ++r) {
        long p = rows[r];
        double x[NV];
        gather(slave, master, neighbour, p, x);
        contributes[r] = (unsigned char)integrate(
            x, has_neighbour + 2 * p, crosspoint ? crosspoint + 2 * p : NULL,
            on_master ? on_master + (long)num_points * p : NULL, normals, element, num_points,
            points, weights, dual_basis, &o, r, r, &cache);
        if (!contributes[r]) {
            zero_values(r, D, M, Dn, Mn, gap, area);
            put_row(&o, r, NULL, NULL);
        }
    }
    return 0;
}

/* Linear combinations of the gradients G (num_rows, kept, 12) of line2_integrate_rows, in the
 * stencils' layout: out (num_terms, 12, num_rows), term t the sum over its entries e in
 * [term_start[t], term_start[t + 1]) of weight_e[r] * G[r, output[e], :], where weight_e[r] is
 * weights[weight_start[e] + r * weight_step[e]] (step 0: one number for every row). Returns -1
 * for an output outside G. */
int line2_combine(long num_rows, int kept, const double *G, int num_terms,
                  const int *term_start, const int *output, const long *weight_start,
                  const int *weight_step, const double *weights, double *out) {
    for (int e = 0; e < term_start[num_terms]; ++e)
        if (output[e] < 0 || output[e] >= kept) return -1;
    for (long r = 0; r < num_rows; ++r) {
        const double *row = G + (long)kept * NV * r;
        for (int t = 0; t < num_terms; ++t) {
            double sum[NV] = {0.0};
            for (int e = term_start[t]; e < term_start[t + 1]; ++e) {
                double w = weights[weight_start[e] + r * weight_step[e]];
                const double *g = row + output[e] * NV;
                for (int v = 0; v < NV; ++v) sum[v] += w * g[v];
            }
            double *column = out + (long)t * NV * num_rows + r;
            for (int v = 0; v < NV; ++v) column[(long)v * num_rows] = sum[v];
        }
    }
    return 0;
}
