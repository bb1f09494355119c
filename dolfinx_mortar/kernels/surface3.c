/* The 3D mortar kernel in C (dolfinx_mortar/kernels/surface3.py's module docstring describes the
 * method). "numpy" below is the package's former vectorized kernel, now the tests' oracle,
 * tests/oracle/surface3_numpy.py, whose module docstring gives the method in detail. Three
 * entry points:
 *
 * surface3_triangles: segment-based integration of a triangle slave facet on a triangle master
 * facet, any normal field (numpy's corner-value path, _affine_integrals):
 *  1. the normal field's nodal normals, the auxiliary plane (x0, n0, e1, e2) and the slave
 *     and master nodes in plane coordinates S, Mp, on plain values in numpy's operation order
 *     so that the clip topology is decided on the same bits;
 *  2. screening on values: facing test, separation test, Sutherland-Hodgman clip with vertex
 *     labels, the clip area against the area tolerance; for a pair that passes and whose
 *     gradients are asked for, the plane's derivatives over the pair's 27 variables (slave
 *     xyz, master xyz, slave nodal normals) in forward-mode dual numbers;
 *  3. the clip vertices recomputed from their labels, the fan cells around the vertex mean,
 *     both (affine) inverse maps at the centre and the vertices, in dual numbers over the 12
 *     plane coordinates (local variables);
 *  4. the 28 integrals int N_a N_k N_i (slave, symmetric) and int N_a N_i Nm_l over the clip
 *     polygon as the Gauss rule's sum (a fixed trilinear form T in the corner values of each
 *     fan cell, every factor being affine on a cell); their local gradients from what
 *     multiplies each corner value and each cell area (values), contracted once per point;
 *  5. the local gradients chained to the 27 variables; D, M, Dn, Mn, the areas and the gaps
 *     as linear combinations of the 28 integrals (the multiplier basis Phi_j = sum_a A_ja N_a
 *     and the normal field n = sum_i N_i n_i), the nodal normals' direct contributions added
 *     (through their own gradients unless they are the variables).
 *
 * surface3_pairs: segment-based integration of any triangle or quadrilateral facets, any
 * normal field (numpy's pointwise path): the same screening, then every Gauss point of every
 * fan cell in dual numbers over the pair's 3 (2 ns + nm) variables (surface3_general.h; its
 * values-only instance when no gradient is asked for), a quadrilateral's inverse map in closed
 * form (surface3_bilinear.h).
 *
 * surface3_element_scores, surface3_element: element-based integration (the slave facet's
 * Gauss points projected onto the master facet; which pair gets a point is decided between the
 * two calls, over the pairs of one slave facet).
 *
 * gradients_combine, stencil_columns (surface3_stencils.h): what the stencils do with the
 * gradients a consumer asks for (stencils.py): the consumer's linear combinations of outputs,
 * then the columns of the pair's stencil (the nodal normals chained through their stars), one
 * pass over the rows each.
 *
 * Per pair, every work array is on the stack.
 */
#include <math.h>
#include <string.h>

#define NL 12 /* local variables: S (3 x 2) then Mp (3 x 2) */
#define NV 27 /* the pair's variables */
#define MAXV 8
#define SLOTS 10
#define NI 28 /* integrals: 10 slave triples, 18 mixed */

static const double FACING_TOLERANCE = 1e-8;
static const double AREA_TOLERANCE = 1e-14;
static const double ON_LINE = 1e-10;

/* ---- dual numbers over the 27 pair variables (the auxiliary plane) ---- */
typedef struct { double v, d[NV]; } d27;

static inline d27 add27(d27 a, d27 b) { d27 r; r.v = a.v + b.v; for (int i = 0; i < NV; ++i) r.d[i] = a.d[i] + b.d[i]; return r; }
static inline d27 sub27(d27 a, d27 b) { d27 r; r.v = a.v - b.v; for (int i = 0; i < NV; ++i) r.d[i] = a.d[i] - b.d[i]; return r; }
static inline d27 mul27(d27 a, d27 b) { d27 r; r.v = a.v * b.v; for (int i = 0; i < NV; ++i) r.d[i] = a.d[i] * b.v + b.d[i] * a.v; return r; }
static inline d27 scale27(d27 a, double s) { d27 r; r.v = a.v * s; for (int i = 0; i < NV; ++i) r.d[i] = a.d[i] * s; return r; }
static inline d27 div27(d27 a, d27 b) {
    d27 r; double inverse = 1.0 / b.v; r.v = a.v * inverse;
    for (int i = 0; i < NV; ++i) r.d[i] = (a.d[i] - b.d[i] * r.v) * inverse;
    return r;
}
static inline d27 sqrt27(d27 a) {
    d27 r; r.v = sqrt(a.v); double f = r.v > 0.0 ? 0.5 / r.v : 0.0;
    for (int i = 0; i < NV; ++i) r.d[i] = a.d[i] * f;
    return r;
}
static inline d27 dot27(const d27 *a, const d27 *b) { return add27(add27(mul27(a[0], b[0]), mul27(a[1], b[1])), mul27(a[2], b[2])); }
static inline void normalize27(const d27 *v, d27 *out) {
    d27 length = sqrt27(dot27(v, v));
    for (int c = 0; c < 3; ++c) out[c] = div27(v[c], length);
}

/* ---- dual numbers over the 12 plane coordinates ---- */
typedef struct { double v, d[NL]; } dl;

static inline dl addl(dl a, dl b) { dl r; r.v = a.v + b.v; for (int i = 0; i < NL; ++i) r.d[i] = a.d[i] + b.d[i]; return r; }
static inline dl subl(dl a, dl b) { dl r; r.v = a.v - b.v; for (int i = 0; i < NL; ++i) r.d[i] = a.d[i] - b.d[i]; return r; }
static inline dl mull(dl a, dl b) { dl r; r.v = a.v * b.v; for (int i = 0; i < NL; ++i) r.d[i] = a.d[i] * b.v + b.d[i] * a.v; return r; }
static inline dl scalel(dl a, double s) { dl r; r.v = a.v * s; for (int i = 0; i < NL; ++i) r.d[i] = a.d[i] * s; return r; }
static inline dl divl(dl a, dl b) {
    dl r; double inverse = 1.0 / b.v; r.v = a.v * inverse;
    for (int i = 0; i < NL; ++i) r.d[i] = (a.d[i] - b.d[i] * r.v) * inverse;
    return r;
}
static inline dl cross2l(const dl *a, const dl *b) { return subl(mull(a[0], b[1]), mull(a[1], b[0])); }

/* ---- quadrature: T_abd = sum_g w_g b_ga b_gb b_gd ---- */
static int rule_tensor(int rule, double T[3][3][3]) {
    double bary[7][3], weight[7];
    int q;
    if (rule == 1) {
        q = 1; bary[0][0] = bary[0][1] = bary[0][2] = 1.0 / 3.0; weight[0] = 1.0;
    } else if (rule == 3) {
        q = 3;
        for (int g = 0; g < 3; ++g) {
            for (int a = 0; a < 3; ++a) bary[g][a] = (a == g) ? 2.0 / 3.0 : 1.0 / 6.0;
            weight[g] = 1.0 / 3.0;
        }
    } else if (rule == 7) {
        const double a1 = 0.059715871789770, b1 = 0.470142064105115;
        const double a2 = 0.797426985353087, b2 = 0.101286507323456;
        q = 7;
        bary[0][0] = bary[0][1] = bary[0][2] = 1.0 / 3.0; weight[0] = 0.225;
        for (int g = 0; g < 3; ++g) {
            for (int a = 0; a < 3; ++a) {
                bary[1 + g][a] = (a == g) ? a1 : b1;
                bary[4 + g][a] = (a == g) ? a2 : b2;
            }
            weight[1 + g] = 0.132394152788506;
            weight[4 + g] = 0.125939180544827;
        }
    } else {
        return -1;
    }
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            for (int d = 0; d < 3; ++d) {
                double s = 0.0;
                for (int g = 0; g < q; ++g) s += weight[g] * bary[g][a] * bary[g][b] * bary[g][d];
                T[a][b][d] = s;
            }
    return 0;
}

/* ---- screening (values, numpy's operation order) ---- */
static double polygon_area3(const double P[3][2]) {
    double t0 = P[0][0] * P[1][1] - P[1][0] * P[0][1];
    double t1 = P[1][0] * P[2][1] - P[2][0] * P[1][1];
    double t2 = P[2][0] * P[0][1] - P[0][0] * P[2][1];
    return 0.5 * ((t0 + t1) + t2);
}

static int separated(const double S[3][2], const double Mp[3][2]) {
    double size = 0.0;
    for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 2; ++c) {
            if (fabs(S[k][c]) > size) size = fabs(S[k][c]);
            if (fabs(Mp[k][c]) > size) size = fabs(Mp[k][c]);
        }
    for (int pass = 0; pass < 2; ++pass) {
        const double (*polygon)[2] = pass == 0 ? S : Mp;
        const double (*other)[2] = pass == 0 ? Mp : S;
        double area = polygon_area3(polygon);
        double orientation = area > 0.0 ? 1.0 : (area < 0.0 ? -1.0 : 0.0);
        for (int i = 0; i < 3; ++i) {
            const double *start = polygon[i], *end = polygon[(i + 1) % 3];
            double d0 = (end[0] - start[0]) * orientation, d1 = (end[1] - start[1]) * orientation;
            double largest = -INFINITY;
            for (int m = 0; m < 3; ++m) {
                double side = d0 * (other[m][1] - start[1]) - d1 * (other[m][0] - start[0]);
                if (side > largest) largest = side;
            }
            double gap = 1e-8 * size * hypot(d0, d1);
            if (largest < -gap) return 1;
        }
    }
    return 0;
}

typedef struct { double pos[SLOTS][2]; int label[SLOTS][3]; int edge[SLOTS][2]; int count; } polygon_t;

static void emit(polygon_t *p, const double *position, const int *label, const int *edge) {
    if (p->count < SLOTS) {
        p->pos[p->count][0] = position[0]; p->pos[p->count][1] = position[1];
        for (int c = 0; c < 3; ++c) p->label[p->count][c] = label[c];
        p->edge[p->count][0] = edge[0]; p->edge[p->count][1] = edge[1];
    }
    p->count++;
}

/* Sutherland-Hodgman: the slave polygon (ns nodes) clipped by the reversed (counter-
 * clockwise) master polygon (nm); labels (kind, i, j): 0 slave node i, 1 master node j,
 * 2 slave edge i x master edge j (reversed numbering). A vertex within ON_LINE of a clip
 * line (in lengths of that edge) lies on it: kept as itself, no crossing on an edge from
 * it (numpy's _clip). Returns -1 if a polygon outgrew its slots. */
static int clip_k(const double (*S)[2], int ns, const double (*Mp)[2], int nm, polygon_t *out) {
    double Mr[4][2];
    for (int j = 0; j < nm; ++j) { Mr[j][0] = Mp[nm - 1 - j][0]; Mr[j][1] = Mp[nm - 1 - j][1]; }
    polygon_t a, b;
    polygon_t *cur = &a, *next = &b;
    memset(cur, 0, sizeof(polygon_t));
    for (int i = 0; i < ns; ++i) {
        cur->pos[i][0] = S[i][0]; cur->pos[i][1] = S[i][1];
        cur->label[i][1] = i; cur->edge[i][1] = i;
    }
    cur->count = ns;
    for (int j = 0; j < nm; ++j) {
        const double *start = Mr[j], *end = Mr[(j + 1) % nm];
        double dir0 = end[0] - start[0], dir1 = end[1] - start[1];
        double tolerance = ON_LINE * (dir0 * dir0 + dir1 * dir1);
        memset(next, 0, sizeof(polygon_t));
        int count = cur->count < SLOTS ? cur->count : SLOTS;
        double side[SLOTS];
        for (int k = 0; k < count; ++k)
            side[k] = dir0 * (cur->pos[k][1] - start[1]) - dir1 * (cur->pos[k][0] - start[0]);
        for (int k = 0; k < count; ++k) {
            int following = (k + 1) % cur->count, after = (k + 2) % cur->count;
            if (following >= SLOTS || after >= SLOTS) return -1;
            const double *p = cur->pos[k], *q = cur->pos[following];
            double s_cur = side[k], s_next = side[following];
            int out_cur = s_cur < -tolerance, out_next = s_next < -tolerance;
            int in_cur = s_cur > tolerance, in_next = s_next > tolerance;
            double denominator = (s_cur - s_next == 0.0) ? 1.0 : s_cur - s_next;
            double t = s_cur / denominator;
            double crossing[2] = {p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])};
            const int *edge = cur->edge[k];
            int crossing_label[3];
            if (edge[0] == 0) {
                crossing_label[0] = 2; crossing_label[1] = edge[1]; crossing_label[2] = j;
            } else {
                crossing_label[0] = 1; crossing_label[1] = 0;
                crossing_label[2] = ((edge[1] + 1) % nm == j) ? j : (j + 1) % nm;
            }
            int along_clip[2] = {1, j};
            /* a kept vertex on the line before one outside: its new edge runs along the line */
            int leaves = !out_next && !in_next && side[after] < -tolerance;
            if (out_cur && in_next) emit(next, crossing, crossing_label, edge);
            if (!out_next) emit(next, q, cur->label[following], leaves ? along_clip : cur->edge[following]);
            if (in_cur && out_next) emit(next, crossing, crossing_label, along_clip);
        }
        polygon_t *swap = cur; cur = next; next = swap;
    }
    *out = *cur;
    if (out->count > MAXV) out->count = MAXV;
    return 0;
}

/* 0.5 sum_k (x_k y_k+1 - x_k+1 y_k) over 8 slots (zero beyond count), numpy's pairwise sum */
static double padded_area(const polygon_t *p) {
    double term[MAXV] = {0.0};
    for (int k = 0; k < MAXV; ++k) {
        if (k < p->count) {
            int f = (k + 1) % p->count;
            term[k] = p->pos[k][0] * p->pos[f][1] - p->pos[f][0] * p->pos[k][1];
        } else {
            term[k] = 0.0;
        }
    }
    return 0.5 * (((term[0] + term[1]) + (term[2] + term[3])) + ((term[4] + term[5]) + (term[6] + term[7])));
}

/* ---- the integrals' index tables ---- */
/* made per call (no mutable static state: calls from several threads do not race) */
typedef struct {
    int triple[NI][3];         /* functions (0-2 slave N, 3-5 master Nm) of each integral */
    int slave_index[3][3][3];  /* int N_a N_k N_i -> integral */
    int mixed_index[3][3][3];  /* int N_a N_i Nm_l -> integral ([a][i][l]) */
    int pair_index[6][6];      /* unordered function pair -> sigma slot (-1: not needed) */
} tables_t;

static void make_tables(tables_t *tb) {
    int o = 0;
    for (int a = 0; a < 3; ++a)
        for (int k = a; k < 3; ++k)
            for (int i = k; i < 3; ++i) {
                tb->triple[o][0] = a; tb->triple[o][1] = k; tb->triple[o][2] = i;
                int idx[3] = {a, k, i};
                for (int p = 0; p < 3; ++p)
                    for (int q = 0; q < 3; ++q)
                        for (int r = 0; r < 3; ++r)
                            if (p != q && q != r && p != r)
                                tb->slave_index[idx[p]][idx[q]][idx[r]] = o;
                tb->slave_index[a][k][i] = tb->slave_index[a][i][k] = tb->slave_index[k][a][i] = o;
                tb->slave_index[k][i][a] = tb->slave_index[i][a][k] = tb->slave_index[i][k][a] = o;
                ++o;
            }
    for (int a = 0; a < 3; ++a)
        for (int i = a; i < 3; ++i)
            for (int l = 0; l < 3; ++l) {
                tb->triple[o][0] = a; tb->triple[o][1] = i; tb->triple[o][2] = 3 + l;
                tb->mixed_index[a][i][l] = tb->mixed_index[i][a][l] = o;
                ++o;
            }
    int s = 0;
    for (int u = 0; u < 6; ++u)
        for (int v = 0; v < 6; ++v) tb->pair_index[u][v] = -1;
    for (int u = 0; u < 6; ++u)
        for (int v = u; v < 6; ++v)
            if (u < 3) { tb->pair_index[u][v] = tb->pair_index[v][u] = s++; }
}
#define NPAIRS 15

/* ---- one pair ---- */
typedef struct {
    double *D, *M, *Dn, *Mn, *gap, *area;
    double *gD, *gM, *gDn, *gMn, *ggap, *garea;
} outputs_t;

/* The auxiliary plane: S[i][a] = (xs_i - x0) . e_a and Mp[l][a] = (xm_l - x0) . e_a (values, in
 * numpy's operation order), n0, and what the chain rule needs: e_a, de_a over the 27 variables,
 * the offsets xs_i - x0 and xm_l - x0. */
typedef struct {
    double S[3][2], Mp[3][2], n0[3], e[2][3], de[2][3][NV], os[3][3], om[3][3];
    double field[3][3], dfield[3][3][NV]; /* the normal field's nodal normals */
    int unit_field;                       /* they are the variables 18-26 (averaged) */
} plane_t;

static inline void cross27(const d27 *a, const d27 *b, d27 *out) {
    out[0] = sub27(mul27(a[1], b[2]), mul27(a[2], b[1]));
    out[1] = sub27(mul27(a[2], b[0]), mul27(a[0], b[2]));
    out[2] = sub27(mul27(a[0], b[1]), mul27(a[1], b[0]));
}

static inline void cross3(const double *a, const double *b, double *out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static inline void normalize3(const double *v, double *out) {
    double inverse = 1.0 / sqrt((v[0] * v[0] + v[1] * v[1]) + v[2] * v[2]);
    for (int c = 0; c < 3; ++c) out[c] = v[c] * inverse;
}

/* The auxiliary plane's values: the values of plane_derivatives' dual numbers, operation for
 * operation (the screening of a pair that does not overlap needs nothing more).
 * normals 0 averaged (the nodal normals), 1 slave (the slave facet's corner normals), 2 master
 * (minus the master facet's unit normal at every slave node) */
static void plane_values(const double *xs, const double *xm, const double *nn, int normals,
                         plane_t *pl) {
    double N[3][3];
    if (normals == 0) {
        memcpy(N, nn, sizeof N);
    } else if (normals == 1) {
        for (int i = 0; i < 3; ++i) {
            double a[3], b[3], v[3];
            for (int c = 0; c < 3; ++c) {
                a[c] = xs[3 * ((i + 1) % 3) + c] - xs[3 * i + c];
                b[c] = xs[3 * ((i + 2) % 3) + c] - xs[3 * i + c];
            }
            cross3(a, b, v);
            normalize3(v, N[i]);
        }
    } else {
        double a[3], b[3], v[3], unit[3];
        for (int c = 0; c < 3; ++c) { a[c] = xm[3 + c] - xm[c]; b[c] = xm[6 + c] - xm[c]; }
        cross3(a, b, v);
        normalize3(v, unit);
        for (int i = 0; i < 3; ++i)
            for (int c = 0; c < 3; ++c) N[i][c] = unit[c] * -1.0;
    }
    pl->unit_field = normals == 0;
    memcpy(pl->field, N, sizeof N);
    double x0[3], v[3], n0[3], edge[3], w[3];
    for (int c = 0; c < 3; ++c) {
        x0[c] = ((xs[c] + xs[3 + c]) + xs[6 + c]) * (1.0 / 3.0);
        v[c] = ((N[0][c] + N[1][c]) + N[2][c]) * (1.0 / 3.0);
    }
    normalize3(v, n0);
    for (int c = 0; c < 3; ++c) edge[c] = xs[3 + c] - xs[c];
    double along = (edge[0] * n0[0] + edge[1] * n0[1]) + edge[2] * n0[2];
    for (int c = 0; c < 3; ++c) w[c] = edge[c] - n0[c] * along;
    normalize3(w, pl->e[0]);
    const double *e0 = pl->e[0];
    pl->e[1][0] = n0[1] * e0[2] - n0[2] * e0[1];
    pl->e[1][1] = n0[2] * e0[0] - n0[0] * e0[2];
    pl->e[1][2] = n0[0] * e0[1] - n0[1] * e0[0];
    for (int c = 0; c < 3; ++c) pl->n0[c] = n0[c];
    for (int k = 0; k < 3; ++k) {
        for (int c = 0; c < 3; ++c) { pl->os[k][c] = xs[3 * k + c] - x0[c]; pl->om[k][c] = xm[3 * k + c] - x0[c]; }
        for (int a = 0; a < 2; ++a) {
            const double *ea = pl->e[a];
            pl->S[k][a] = (pl->os[k][0] * ea[0] + pl->os[k][1] * ea[1]) + pl->os[k][2] * ea[2];
            pl->Mp[k][a] = (pl->om[k][0] * ea[0] + pl->om[k][1] * ea[1]) + pl->om[k][2] * ea[2];
        }
    }
}

/* The derivatives of the auxiliary plane over the 27 variables (de, dfield), for the pairs that
 * overlap when gradients are asked for. */
static void plane_derivatives(const double *xs, const double *xm, const double *nn, int normals,
                              plane_t *pl) {
    d27 N[3][3], X[3][3], Y[3][3];
    memset(N, 0, sizeof N); memset(X, 0, sizeof X); memset(Y, 0, sizeof Y);
    for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) {
            X[k][c].v = xs[3 * k + c]; X[k][c].d[3 * k + c] = 1.0;
            Y[k][c].v = xm[3 * k + c]; Y[k][c].d[9 + 3 * k + c] = 1.0;
        }
    if (normals == 0) {
        for (int k = 0; k < 3; ++k)
            for (int c = 0; c < 3; ++c) { N[k][c].v = nn[3 * k + c]; N[k][c].d[18 + 3 * k + c] = 1.0; }
    } else if (normals == 1) {
        for (int i = 0; i < 3; ++i) {
            d27 a[3], b[3], v[3];
            for (int c = 0; c < 3; ++c) {
                a[c] = sub27(X[(i + 1) % 3][c], X[i][c]);
                b[c] = sub27(X[(i + 2) % 3][c], X[i][c]);
            }
            cross27(a, b, v);
            normalize27(v, N[i]);
        }
    } else {
        d27 a[3], b[3], v[3], unit[3];
        for (int c = 0; c < 3; ++c) { a[c] = sub27(Y[1][c], Y[0][c]); b[c] = sub27(Y[2][c], Y[0][c]); }
        cross27(a, b, v);
        normalize27(v, unit);
        for (int i = 0; i < 3; ++i)
            for (int c = 0; c < 3; ++c) N[i][c] = scale27(unit[c], -1.0);
    }
    for (int i = 0; i < 3; ++i)
        for (int c = 0; c < 3; ++c) memcpy(pl->dfield[i][c], N[i][c].d, sizeof(double) * NV);
    d27 v[3], n0[3], edge[3], w[3], e[2][3];
    for (int c = 0; c < 3; ++c) v[c] = scale27(add27(add27(N[0][c], N[1][c]), N[2][c]), 1.0 / 3.0);
    normalize27(v, n0);
    for (int c = 0; c < 3; ++c) edge[c] = sub27(X[1][c], X[0][c]);
    d27 along = dot27(edge, n0);
    for (int c = 0; c < 3; ++c) w[c] = sub27(edge[c], mul27(n0[c], along));
    normalize27(w, e[0]);
    e[1][0] = sub27(mul27(n0[1], e[0][2]), mul27(n0[2], e[0][1]));
    e[1][1] = sub27(mul27(n0[2], e[0][0]), mul27(n0[0], e[0][2]));
    e[1][2] = sub27(mul27(n0[0], e[0][1]), mul27(n0[1], e[0][0]));
    for (int a = 0; a < 2; ++a)
        for (int c = 0; c < 3; ++c) memcpy(pl->de[a][c], e[a][c].d, sizeof(double) * NV);
}

/* out (27) = q (12, over S then Mp) chained to the pair's variables:
 * dS_ia = e_a . (dxs_i - dx0) + (xs_i - x0) . de_a, dMp_la = e_a . (dxm_l - dx0) + (xm_l - x0) . de_a */
static void chain(const plane_t *pl, const double *q, double *out) {
    double total[2] = {0.0, 0.0}, r[2][3] = {{0.0}};
    for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 2; ++a) {
            double qs = q[2 * k + a], qm = q[6 + 2 * k + a];
            total[a] += qs + qm;
            for (int c = 0; c < 3; ++c) r[a][c] += qs * pl->os[k][c] + qm * pl->om[k][c];
        }
    for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) {
            double xs_part = 0.0, xm_part = 0.0;
            for (int a = 0; a < 2; ++a) {
                xs_part += (q[2 * k + a] - total[a] * (1.0 / 3.0)) * pl->e[a][c];
                xm_part += q[6 + 2 * k + a] * pl->e[a][c];
            }
            out[3 * k + c] = xs_part;
            out[9 + 3 * k + c] = xm_part;
            out[18 + 3 * k + c] = 0.0;
        }
    for (int a = 0; a < 2; ++a)
        for (int c = 0; c < 3; ++c) {
            double rc = r[a][c];
            const double *de = pl->de[a][c];
            for (int v = 0; v < NV; ++v) out[v] += rc * de[v];
        }
}

/* N(p) of a triangle (corners C, local slots base + 2k + r) at the points P: values and
 * gradients over the local variables, dxi = A^-1 (dp - sum_k N_k dC_k) */
static void inverse_map(const double C[3][2], int base, const dl (*P)[2], int np,
                        double N[][3], double dN[][3][NL]) {
    double A00 = C[1][0] - C[0][0], A01 = C[2][0] - C[0][0];
    double A10 = C[1][1] - C[0][1], A11 = C[2][1] - C[0][1];
    double det = A00 * A11 - A01 * A10;
    double I00 = A11 / det, I01 = -A01 / det, I10 = -A10 / det, I11 = A00 / det;
    for (int p = 0; p < np; ++p) {
        double o0 = P[p][0].v - C[0][0], o1 = P[p][1].v - C[0][1];
        double xi0 = I00 * o0 + I01 * o1, xi1 = I10 * o0 + I11 * o1;
        double Nk[3] = {1.0 - xi0 - xi1, xi0, xi1};
        for (int k = 0; k < 3; ++k) N[p][k] = Nk[k];
        if (!dN) continue;
        double rhs[2][NL];
        for (int r = 0; r < 2; ++r) {
            for (int s = 0; s < NL; ++s) rhs[r][s] = P[p][r].d[s];
            for (int k = 0; k < 3; ++k) rhs[r][base + 2 * k + r] -= Nk[k];
        }
        for (int s = 0; s < NL; ++s) {
            double d0 = I00 * rhs[0][s] + I01 * rhs[1][s];
            double d1 = I10 * rhs[0][s] + I11 * rhs[1][s];
            dN[p][0][s] = -d0 - d1; dN[p][1][s] = d0; dN[p][2][s] = d1;
        }
    }
}

static void zero_pair(const outputs_t *o, long p) {
    memset(o->D + 9 * p, 0, 9 * sizeof(double)); memset(o->M + 9 * p, 0, 9 * sizeof(double));
    memset(o->Dn + 27 * p, 0, 27 * sizeof(double)); memset(o->Mn + 27 * p, 0, 27 * sizeof(double));
    memset(o->gap + 3 * p, 0, 3 * sizeof(double)); memset(o->area + 3 * p, 0, 3 * sizeof(double));
    if (o->gDn) memset(o->gDn + 27 * NV * p, 0, 27 * NV * sizeof(double));
    if (o->gMn) memset(o->gMn + 27 * NV * p, 0, 27 * NV * sizeof(double));
    if (o->ggap) memset(o->ggap + 3 * NV * p, 0, 3 * NV * sizeof(double));
    if (o->garea) memset(o->garea + 3 * NV * p, 0, 3 * NV * sizeof(double));
    if (o->gD) memset(o->gD + 9 * NV * p, 0, 9 * NV * sizeof(double));
    if (o->gM) memset(o->gM + 9 * NV * p, 0, 9 * NV * sizeof(double));
}

static int pair(long p, const double *xs, const double *xm, const double *nn, int normals,
                const unsigned char *crosspoint, int dual_basis, const double T[3][3][3],
                const tables_t *tb, const outputs_t *o, unsigned char *valid, double *overlap) {
    plane_t pl;
    plane_values(xs, xm, nn, normals, &pl);
    const double (*S)[2] = (const double (*)[2])pl.S, (*Mp)[2] = (const double (*)[2])pl.Mp;
    const double *n0 = pl.n0;
    /* facing: n0 . (master unit normal) < -tol */
    double u[3], w[3], mn[3];
    for (int c = 0; c < 3; ++c) { u[c] = xm[3 + c] - xm[c]; w[c] = xm[6 + c] - xm[c]; }
    mn[0] = u[1] * w[2] - u[2] * w[1]; mn[1] = u[2] * w[0] - u[0] * w[2]; mn[2] = u[0] * w[1] - u[1] * w[0];
    double length = sqrt((mn[0] * mn[0] + mn[1] * mn[1]) + mn[2] * mn[2]);
    for (int c = 0; c < 3; ++c) mn[c] = mn[c] / length;
    if (!(((n0[0] * mn[0] + n0[1] * mn[1]) + n0[2] * mn[2]) < -FACING_TOLERANCE)) return 0;
    if (separated(S, Mp)) return 0;
    polygon_t poly;
    if (clip_k(S, 3, Mp, 3, &poly) != 0) return -1;
    double slave_area = fabs(polygon_area3(S));
    double clip_area = padded_area(&poly);
    if (!(poly.count >= 3 && clip_area > AREA_TOLERANCE * slave_area)) return 0;
    valid[p] = 1;
    overlap[p] = clip_area / slave_area;
    const int V = poly.count, np = V + 1;
    /* the gradients asked for (none: the values only) */
    const int grads = o->gDn || o->gMn || o->ggap || o->garea || o->gD || o->gM;
    if (grads) plane_derivatives(xs, xm, nn, normals, &pl);

    /* clip vertices over the local variables, recomputed from the labels */
    dl Sl[3][2], Ml[3][2];
    for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 2; ++a) {
            memset(&Sl[k][a], 0, sizeof(dl)); memset(&Ml[k][a], 0, sizeof(dl));
            Sl[k][a].v = S[k][a]; Sl[k][a].d[2 * k + a] = 1.0;
            Ml[k][a].v = Mp[k][a]; Ml[k][a].d[6 + 2 * k + a] = 1.0;
        }
    dl P[MAXV + 1][2]; /* 0: centre, 1..V: vertices */
    for (int k = 0; k < V; ++k) {
        int kind = poly.label[k][0], i = poly.label[k][1], j = poly.label[k][2];
        if (kind == 0) {
            P[1 + k][0] = Sl[i][0]; P[1 + k][1] = Sl[i][1];
        } else if (kind == 1) {
            int node = (3 - 1 - j + 3) % 3;
            P[1 + k][0] = Ml[node][0]; P[1 + k][1] = Ml[node][1];
        } else {
            int e = ((3 - 2 - j) % 3 + 3) % 3;
            const dl *a0 = Sl[i], *a1 = Sl[(i + 1) % 3], *b0 = Ml[e], *b1 = Ml[(e + 1) % 3];
            dl da[2] = {subl(a1[0], a0[0]), subl(a1[1], a0[1])};
            dl db[2] = {subl(b1[0], b0[0]), subl(b1[1], b0[1])};
            dl ba[2] = {subl(b0[0], a0[0]), subl(b0[1], a0[1])};
            dl denominator = cross2l(da, db);
            dl numerator = cross2l(ba, db);
            dl t;
            if (denominator.v != 0.0) {
                t = divl(numerator, denominator);
            } else {
                t = numerator;
            }
            P[1 + k][0] = addl(a0[0], mull(da[0], t));
            P[1 + k][1] = addl(a0[1], mull(da[1], t));
        }
    }
    double weight = 1.0 / V;
    for (int a = 0; a < 2; ++a) {
        P[0][a] = scalel(P[1][a], weight);
        for (int k = 1; k < V; ++k) P[0][a] = addl(P[0][a], scalel(P[1 + k][a], weight));
    }
    dl W[MAXV];
    for (int c = 0; c < V; ++c) {
        const dl *v0 = P[1 + c], *v1 = P[1 + (c + 1) % V];
        dl ea[2] = {subl(v0[0], P[0][0]), subl(v0[1], P[0][1])};
        dl eb[2] = {subl(v1[0], P[0][0]), subl(v1[1], P[0][1])};
        W[c] = scalel(cross2l(ea, eb), 0.5);
    }
    /* the six functions (slave N_0..2, master Nm_0..2) at the points */
    double F[6][MAXV + 1], dF[6][MAXV + 1][NL];
    {
        double Nv[MAXV + 1][3], dNv[MAXV + 1][3][NL];
        inverse_map(S, 0, (const dl (*)[2])P, np, Nv, grads ? dNv : NULL);
        for (int q = 0; q < np; ++q)
            for (int k = 0; k < 3; ++k) {
                F[k][q] = Nv[q][k];
                if (grads) memcpy(dF[k][q], dNv[q][k], sizeof(double) * NL);
            }
        inverse_map(Mp, 6, (const dl (*)[2])P, np, Nv, grads ? dNv : NULL);
        for (int q = 0; q < np; ++q)
            for (int k = 0; k < 3; ++k) {
                F[3 + k][q] = Nv[q][k];
                if (grads) memcpy(dF[3 + k][q], dNv[q][k], sizeof(double) * NL);
            }
    }
    /* the integrals: values, what multiplies each cell area and each point value */
    double I[NI], coefW[NI][MAXV], coef[NI][3][MAXV + 1];
    memset(I, 0, sizeof I);
    if (grads) memset(coef, 0, sizeof coef);
    for (int c = 0; c < V; ++c) {
        int corner[3] = {0, 1 + c, 1 + (c + 1) % V};
        double f[6][3], Tf[6][3][3], sigma[NPAIRS][3];
        for (int u = 0; u < 6; ++u)
            for (int r = 0; r < 3; ++r) f[u][r] = F[u][corner[r]];
        /* sigma_uv[r] = f_u . T_r f_v, T_r f_v once per v */
        for (int v = 0; v < 6; ++v)
            for (int r = 0; r < 3; ++r)
                for (int q = 0; q < 3; ++q)
                    Tf[v][r][q] = (T[r][q][0] * f[v][0] + T[r][q][1] * f[v][1]) + T[r][q][2] * f[v][2];
        for (int u = 0; u < 3; ++u)
            for (int v = u; v < 6; ++v) {
                int s = tb->pair_index[u][v];
                for (int r = 0; r < 3; ++r)
                    sigma[s][r] = (f[u][0] * Tf[v][r][0] + f[u][1] * Tf[v][r][1]) + f[u][2] * Tf[v][r][2];
            }
        double wc = W[c].v;
        for (int o = 0; o < NI; ++o) {
            int u1 = tb->triple[o][0], u2 = tb->triple[o][1], u3 = tb->triple[o][2];
            const double *s23 = sigma[tb->pair_index[u2][u3]], *s13 = sigma[tb->pair_index[u1][u3]],
                         *s12 = sigma[tb->pair_index[u1][u2]];
            double tau = (f[u1][0] * s23[0] + f[u1][1] * s23[1]) + f[u1][2] * s23[2];
            I[o] += wc * tau;
            coefW[o][c] = tau;
            if (!grads) continue;
            for (int r = 0; r < 3; ++r) {
                coef[o][0][corner[r]] += wc * s23[r];
                coef[o][1][corner[r]] += wc * s13[r];
                coef[o][2][corner[r]] += wc * s12[r];
            }
        }
    }
    /* local gradients of the integrals */
    double dI[NI][NL];
    for (int o = 0; o < NI && grads; ++o) {
        double g[NL] = {0};
        for (int c = 0; c < V; ++c)
            for (int s = 0; s < NL; ++s) g[s] += coefW[o][c] * W[c].d[s];
        for (int slot = 0; slot < 3; ++slot) {
            int u = tb->triple[o][slot];
            for (int q = 0; q < np; ++q) {
                double k = coef[o][slot][q];
                for (int s = 0; s < NL; ++s) g[s] += k * dF[u][q][s];
            }
        }
        memcpy(dI[o], g, sizeof g);
    }
    /* the multiplier basis Phi_j = sum_a A_ja N_a */
    double A[3][3];
    for (int j = 0; j < 3; ++j)
        for (int a = 0; a < 3; ++a) A[j][a] = dual_basis ? (j == a ? 3.0 : -1.0) : (j == a ? 1.0 : 0.0);
    if (crosspoint && (crosspoint[0] || crosspoint[1] || crosspoint[2])) {
        int others = 0;
        double shared[3] = {0.0, 0.0, 0.0};
        for (int j = 0; j < 3; ++j) {
            if (crosspoint[j]) for (int a = 0; a < 3; ++a) shared[a] += A[j][a];
            else ++others;
        }
        double share = others > 0 ? 1.0 / others : 0.0;
        for (int j = 0; j < 3; ++j)
            for (int a = 0; a < 3; ++a) A[j][a] = crosspoint[j] ? 0.0 : A[j][a] + shared[a] * share;
    }
    /* J_jki = int Phi_j N_k N_i, K_jli = int Phi_j Nm_l N_i, values and local gradients */
    double J[3][3][3], K[3][3][3], dJ[3][3][3][NL], dK[3][3][3][NL];
    for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k)
            for (int i = 0; i < 3; ++i) {
                double js = 0.0, ks = 0.0, gj[NL] = {0}, gk[NL] = {0};
                for (int a = 0; a < 3; ++a) {
                    double c = A[j][a];
                    if (c == 0.0) continue;
                    int os = tb->slave_index[a][k][i], om = tb->mixed_index[a][i][k];
                    js += c * I[os]; ks += c * I[om];
                    if (grads)
                        for (int s = 0; s < NL; ++s) { gj[s] += c * dI[os][s]; gk[s] += c * dI[om][s]; }
                }
                J[j][k][i] = js; K[j][k][i] = ks;
                if (grads) { memcpy(dJ[j][k][i], gj, sizeof gj); memcpy(dK[j][k][i], gk, sizeof gk); }
            }
    /* the outputs: values, local gradients chained, the nodal normals' direct terms */
    double *D = o->D + 9 * p, *M = o->M + 9 * p, *Dn = o->Dn + 27 * p, *Mn = o->Mn + 27 * p;
    double *gap = o->gap + 3 * p, *area = o->area + 3 * p;
    if (!grads) { /* the values of the loop below, in its order */
        for (int j = 0; j < 3; ++j) {
            double area_j = 0.0, gap_m = 0.0, gap_s = 0.0;
            for (int k = 0; k < 3; ++k) {
                double d = 0.0, m = 0.0;
                for (int i = 0; i < 3; ++i) { d += J[j][k][i]; m += K[j][k][i]; }
                D[3 * j + k] = d; M[3 * j + k] = m;
                area_j += d;
                for (int c = 0; c < 3; ++c) {
                    int e = (3 * j + k) * 3 + c;
                    double dn = 0.0, mnv = 0.0;
                    for (int i = 0; i < 3; ++i) { dn += pl.field[i][c] * J[j][k][i]; mnv += pl.field[i][c] * K[j][k][i]; }
                    Dn[e] = dn; Mn[e] = mnv;
                    gap_m += mnv * xm[3 * k + c]; gap_s += dn * xs[3 * k + c];
                }
            }
            area[j] = area_j;
            gap[j] = gap_m - gap_s;
        }
        return 1;
    }
    double *gDn = o->gDn ? o->gDn + 27 * NV * p : NULL, *gMn = o->gMn ? o->gMn + 27 * NV * p : NULL;
    double *ggap = o->ggap ? o->ggap + 3 * NV * p : NULL;
    double *garea = o->garea ? o->garea + 3 * NV * p : NULL;
    for (int j = 0; j < 3; ++j) {
        double area_j = 0.0, la[NL] = {0}, lgap[NL] = {0};
        double gap_m = 0.0, gap_s = 0.0, gap_normals[3][3] = {{0.0}};
        for (int k = 0; k < 3; ++k) {
            double d = 0.0, m = 0.0, ld[NL] = {0}, lm[NL] = {0};
            for (int i = 0; i < 3; ++i) {
                d += J[j][k][i]; m += K[j][k][i];
                for (int s = 0; s < NL; ++s) { ld[s] += dJ[j][k][i][s]; lm[s] += dK[j][k][i][s]; }
            }
            D[3 * j + k] = d; M[3 * j + k] = m;
            area_j += d;
            for (int s = 0; s < NL; ++s) la[s] += ld[s];
            if (o->gD) chain(&pl, ld, o->gD + (9 * p + 3 * j + k) * NV);
            if (o->gM) chain(&pl, lm, o->gM + (9 * p + 3 * j + k) * NV);
            for (int c = 0; c < 3; ++c) {
                int e = (3 * j + k) * 3 + c;
                double dn = 0.0, mnv = 0.0, ldn[NL] = {0}, lmn[NL] = {0};
                for (int i = 0; i < 3; ++i) {
                    double ni = pl.field[i][c];
                    dn += ni * J[j][k][i]; mnv += ni * K[j][k][i];
                    for (int s = 0; s < NL; ++s) { ldn[s] += ni * dJ[j][k][i][s]; lmn[s] += ni * dK[j][k][i][s]; }
                    /* d gap_j / d n_i[c] = sum_l xm_lc K_jli - sum_k xs_kc J_jki */
                    gap_normals[i][c] += xm[3 * k + c] * K[j][k][i] - xs[3 * k + c] * J[j][k][i];
                }
                Dn[e] = dn; Mn[e] = mnv;
                double xmc = xm[3 * k + c], xsc = xs[3 * k + c];
                gap_m += mnv * xmc; gap_s += dn * xsc;
                for (int s = 0; s < NL; ++s) lgap[s] += lmn[s] * xmc - ldn[s] * xsc;
                if (gDn) chain(&pl, ldn, gDn + e * NV);
                if (gMn) chain(&pl, lmn, gMn + e * NV);
                for (int i = 0; i < 3; ++i) {
                    if (pl.unit_field) {
                        if (gDn) gDn[e * NV + 18 + 3 * i + c] += J[j][k][i];
                        if (gMn) gMn[e * NV + 18 + 3 * i + c] += K[j][k][i];
                    } else {
                        const double *dn_i = pl.dfield[i][c];
                        for (int v = 0; v < NV; ++v) {
                            if (gDn) gDn[e * NV + v] += J[j][k][i] * dn_i[v];
                            if (gMn) gMn[e * NV + v] += K[j][k][i] * dn_i[v];
                        }
                    }
                }
            }
        }
        area[j] = area_j;
        if (garea) chain(&pl, la, garea + j * NV);
        gap[j] = gap_m - gap_s;
        if (!ggap) continue;
        double *g = ggap + j * NV;
        chain(&pl, lgap, g);
        for (int k = 0; k < 3; ++k)
            for (int c = 0; c < 3; ++c) {
                int e = (3 * j + k) * 3 + c;
                g[3 * k + c] -= Dn[e];
                g[9 + 3 * k + c] += Mn[e];
                if (pl.unit_field) {
                    g[18 + 3 * k + c] += gap_normals[k][c];
                } else {
                    for (int v = 0; v < NV; ++v) g[v] += gap_normals[k][c] * pl.dfield[k][c][v];
                }
            }
    }
    return 1;
}

/* n pairs: xs, xm, nn (n, 3, 3); crosspoint (n, 3) or NULL; rule 1, 3 or 7; outputs as
 * surface3.pair_quantities (gradients (..., 27)); any of the six gradients may be NULL (not
 * made: a consumer that needs a few of them; none, the values only, for an evaluation whose
 * gradients are made again on demand).
 * Returns 0, or -1 for a bad rule, or -2 - p if pair p's clip polygon outgrew its slots. */
int surface3_triangles(long n, const double *xs, const double *xm, const double *nn,
                       const unsigned char *crosspoint, int normals, int dual_basis, int rule,
                       unsigned char *valid, double *overlap,
                       double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                       double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                       double *garea) {
    double T[3][3][3];
    if (rule_tensor(rule, T) != 0) return -1;
    tables_t tables;
    make_tables(&tables);
    outputs_t o = {D, M, Dn, Mn, gap, area, gD, gM, gDn, gMn, ggap, garea};
    for (long p = 0; p < n; ++p) {
        valid[p] = 0;
        overlap[p] = 0.0;
        int status = pair(p, xs + 9 * p, xm + 9 * p, nn + 9 * p, normals,
                          crosspoint ? crosspoint + 3 * p : NULL, dual_basis, T, &tables, &o, valid, overlap);
        if (status < 0) return -2 - (int)p;
        if (status == 0) zero_pair(&o, p);
    }
    return 0;
}

/* ======================================================================================
 * The general pointwise path: triangle or quadrilateral slave and master facets, any normal
 * field, standard or dual basis, crosspoints (surface3.py's _polygon_integrals with
 * pointwise=True). Everything is in forward-mode dual numbers over the pair's variables
 * (3 (2 ns + nm) <= 36 of them: slave xyz, master xyz, slave nodal normals): the clip cells,
 * the Gauss points, both inverse maps (Newton for quadrilaterals, then one Newton step in dual
 * arithmetic at the converged point) and the integrands. The screening (facing, separation,
 * clip, area) is on values in numpy's operation order, as for triangles. The dual-number part
 * is surface3_general.h, compiled twice: with the derivatives, and for the values only (one
 * unused derivative slot: a values-only call moves 16-byte numbers, not 296-byte ones).
 * ====================================================================================== */
/* the reference facets: triangles (0,0), (1,0), (0,1); quadrilaterals (-1,-1), (1,-1), (1,1), (-1,1) */
static const double QUAD_SIGNS[4][2] = {{-1.0, -1.0}, {1.0, -1.0}, {1.0, 1.0}, {-1.0, 1.0}};

static void shape_values(double r, double s, int nodes, double *N, double dN[][2]) {
    if (nodes == 3) {
        N[0] = 1.0 - r - s; N[1] = r; N[2] = s;
        if (dN) { dN[0][0] = -1.0; dN[0][1] = -1.0; dN[1][0] = 1.0; dN[1][1] = 0.0; dN[2][0] = 0.0; dN[2][1] = 1.0; }
        return;
    }
    for (int k = 0; k < 4; ++k) {
        double a = QUAD_SIGNS[k][0], b = QUAD_SIGNS[k][1];
        N[k] = (1.0 + r * a) * (1.0 + s * b) * 0.25;
        if (dN) { dN[k][0] = a * (1.0 + s * b) * 0.25; dN[k][1] = b * (1.0 + r * a) * 0.25; }
    }
}

#include "surface3_bilinear.h"

/* 4 x 4 (or 3 x 3) inverse by Gauss-Jordan elimination with partial pivoting */
static void invert(int n, const double A[4][4], double out[4][4]) {
    double a[4][8];
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < 2 * n; ++j) a[i][j] = j < n ? A[i][j] : (j - n == i ? 1.0 : 0.0);
    for (int col = 0; col < n; ++col) {
        int pivot = col;
        for (int i = col + 1; i < n; ++i)
            if (fabs(a[i][col]) > fabs(a[pivot][col])) pivot = i;
        if (pivot != col)
            for (int j = 0; j < 2 * n; ++j) { double t = a[col][j]; a[col][j] = a[pivot][j]; a[pivot][j] = t; }
        double inverse = 1.0 / a[col][col];
        for (int j = 0; j < 2 * n; ++j) a[col][j] *= inverse;
        for (int i = 0; i < n; ++i) {
            if (i == col) continue;
            double f = a[i][col];
            if (f != 0.0)
                for (int j = 0; j < 2 * n; ++j) a[i][j] -= f * a[col][j];
        }
    }
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) out[i][j] = a[i][n + j];
}

static double polygon_area_k(const double (*P)[2], int k) {
    double total = 0.0;
    for (int i = 0; i < k; ++i) {
        int f = (i + 1) % k;
        double t = P[i][0] * P[f][1] - P[f][0] * P[i][1];
        total = i == 0 ? t : total + t;
    }
    return 0.5 * total;
}

static int separated_k(const double (*S)[2], int ns, const double (*Mp)[2], int nm) {
    double size = 0.0;
    for (int k = 0; k < ns; ++k)
        for (int c = 0; c < 2; ++c) if (fabs(S[k][c]) > size) size = fabs(S[k][c]);
    for (int k = 0; k < nm; ++k)
        for (int c = 0; c < 2; ++c) if (fabs(Mp[k][c]) > size) size = fabs(Mp[k][c]);
    for (int pass = 0; pass < 2; ++pass) {
        const double (*polygon)[2] = pass == 0 ? S : Mp;
        const double (*other)[2] = pass == 0 ? Mp : S;
        int k = pass == 0 ? ns : nm, ko = pass == 0 ? nm : ns;
        double area = polygon_area_k(polygon, k);
        double orientation = area > 0.0 ? 1.0 : (area < 0.0 ? -1.0 : 0.0);
        for (int i = 0; i < k; ++i) {
            const double *start = polygon[i], *end = polygon[(i + 1) % k];
            double d0 = (end[0] - start[0]) * orientation, d1 = (end[1] - start[1]) * orientation;
            double largest = -INFINITY;
            for (int m = 0; m < ko; ++m) {
                double side = d0 * (other[m][1] - start[1]) - d1 * (other[m][0] - start[0]);
                if (side > largest) largest = side;
            }
            double gap = 1e-8 * size * hypot(d0, d1);
            if (largest < -gap) return 1;
        }
    }
    return 0;
}

typedef struct { int ns, nm, nv; } sizes_t;

/* the crosspoint flags; returns the share of a crosspoint's function each other node gets */
static double crosspoint_shares(int ns, const unsigned char *crosspoint, int *cross, int *any) {
    int others = 0;
    *any = 0;
    for (int j = 0; j < ns; ++j) {
        cross[j] = crosspoint ? crosspoint[j] != 0 : 0;
        others += !cross[j];
        *any |= cross[j];
    }
    return others > 0 ? 1.0 / others : 0.0;
}

/* The facing and separation tests of pair_general on plain values, with the operations (and
 * so the bits) of the values of its dual numbers: 0 if they reject the pair, before any dual
 * number is made. */
static int passes_screening(sizes_t z, const double *xsv, const double *xmv, const double *nnv,
                            int normals) {
    const int ns = z.ns, nm = z.nm;
    const double (*xs)[3] = (const double (*)[3])xsv, (*xm)[3] = (const double (*)[3])xmv;
    double node_normals[4][3] = {{0.0}};
    if (normals == 0) {
        memcpy(node_normals, nnv, sizeof(double) * 3 * ns);
    } else if (normals == 1) {
        for (int i = 0; i < ns; ++i) {
            double a[3], b[3], v[3];
            for (int c = 0; c < 3; ++c) {
                a[c] = xs[(i + 1) % ns][c] - xs[i][c];
                b[c] = xs[(i + ns - 1) % ns][c] - xs[i][c];
            }
            cross3(a, b, v);
            normalize3(v, node_normals[i]);
        }
    } else {
        double a[3], b[3], v[3], unit[3];
        for (int c = 0; c < 3; ++c) {
            if (nm == 4) { a[c] = xm[2][c] - xm[0][c]; b[c] = xm[3][c] - xm[1][c]; }
            else { a[c] = xm[1][c] - xm[0][c]; b[c] = xm[2][c] - xm[0][c]; }
        }
        cross3(a, b, v);
        normalize3(v, unit);
        for (int i = 0; i < ns; ++i)
            for (int c = 0; c < 3; ++c) node_normals[i][c] = -unit[c];
    }
    double x0[3], sum[3], n0[3], edge[3], wv[3], e[2][3];
    for (int c = 0; c < 3; ++c) {
        x0[c] = xs[0][c]; sum[c] = node_normals[0][c];
        for (int k = 1; k < ns; ++k) { x0[c] = x0[c] + xs[k][c]; sum[c] = sum[c] + node_normals[k][c]; }
        x0[c] = x0[c] * (1.0 / ns);
        sum[c] = sum[c] * (1.0 / ns);
    }
    normalize3(sum, n0);
    for (int c = 0; c < 3; ++c) edge[c] = xs[1][c] - xs[0][c];
    double along = (edge[0] * n0[0] + edge[1] * n0[1]) + edge[2] * n0[2];
    for (int c = 0; c < 3; ++c) wv[c] = edge[c] - n0[c] * along;
    normalize3(wv, e[0]);
    cross3(n0, e[0], e[1]);
    double u[3], w[3], mn[3];
    for (int c = 0; c < 3; ++c) {
        if (nm == 4) { u[c] = xmv[6 + c] - xmv[c]; w[c] = xmv[9 + c] - xmv[3 + c]; }
        else { u[c] = xmv[3 + c] - xmv[c]; w[c] = xmv[6 + c] - xmv[c]; }
    }
    mn[0] = u[1] * w[2] - u[2] * w[1]; mn[1] = u[2] * w[0] - u[0] * w[2]; mn[2] = u[0] * w[1] - u[1] * w[0];
    double length = sqrt((mn[0] * mn[0] + mn[1] * mn[1]) + mn[2] * mn[2]);
    for (int c = 0; c < 3; ++c) mn[c] = mn[c] / length;
    if (!(((n0[0] * mn[0] + n0[1] * mn[1]) + n0[2] * mn[2]) < -FACING_TOLERANCE)) return 0;
    double S[4][2], Mp[4][2];
    for (int k = 0; k < ns; ++k)
        for (int a = 0; a < 2; ++a) {
            double o0 = xs[k][0] - x0[0], o1 = xs[k][1] - x0[1], o2 = xs[k][2] - x0[2];
            S[k][a] = (o0 * e[a][0] + o1 * e[a][1]) + o2 * e[a][2];
        }
    for (int k = 0; k < nm; ++k)
        for (int a = 0; a < 2; ++a) {
            double o0 = xm[k][0] - x0[0], o1 = xm[k][1] - x0[1], o2 = xm[k][2] - x0[2];
            Mp[k][a] = (o0 * e[a][0] + o1 * e[a][1]) + o2 * e[a][2];
        }
    return !separated_k((const double (*)[2])S, ns, (const double (*)[2])Mp, nm);
}

/* the general pair path (surface3_general.h), values only: the same source over one unused
 * derivative slot, its names suffixed */
#define DERIVATIVES 0
#define NX 1
#define NP 1
#define dx dx_values
#define constx constx_values
#define addx addx_values
#define subx subx_values
#define mulx mulx_values
#define scalex scalex_values
#define negx negx_values
#define divx divx_values
#define sqrtx sqrtx_values
#define accumulatex accumulatex_values
#define subtract_productx subtract_productx_values
#define zerox zerox_values
#define dotx dotx_values
#define crossx crossx_values
#define normalizex normalizex_values
#define cross2x cross2x_values
#define dp dp_values
#define constp constp_values
#define addp addp_values
#define subp subp_values
#define mulp mulp_values
#define scalep scalep_values
#define negp negp_values
#define divp divp_values
#define accumulatep accumulatep_values
#define cross2p cross2p_values
#define shape_duals_p shape_duals_p_values
#define inverse_map_p inverse_map_p_values
#define dual_coefficients_x dual_coefficients_x_values
#define pair_variables_x pair_variables_x_values
#define integrals_t integrals_t_values
#define write_outputs write_outputs_values
#define pair_general pair_general_values
#include "surface3_general.h"
#undef dx
#undef constx
#undef addx
#undef subx
#undef mulx
#undef scalex
#undef negx
#undef divx
#undef sqrtx
#undef accumulatex
#undef subtract_productx
#undef zerox
#undef dotx
#undef crossx
#undef normalizex
#undef cross2x
#undef dp
#undef constp
#undef addp
#undef subp
#undef mulp
#undef scalep
#undef negp
#undef divp
#undef accumulatep
#undef cross2p
#undef shape_duals_p
#undef inverse_map_p
#undef dual_coefficients_x
#undef pair_variables_x
#undef integrals_t
#undef write_outputs
#undef pair_general
#undef DERIVATIVES
#undef NX
#undef NP

/* ... and with the derivatives over the pair's 3 (2 ns + nm) <= 36 variables and the 16 plane
 * coordinates */
#define DERIVATIVES 1
#define NX 36
#define NP 16
#include "surface3_general.h"

static void shape_duals(const dx *xi, int nodes, dx *N) {
    if (nodes == 3) {
        N[0] = subx(subx(constx(1.0), xi[0]), xi[1]); N[1] = xi[0]; N[2] = xi[1];
        return;
    }
    for (int k = 0; k < 4; ++k) {
        dx u = addx(constx(1.0), scalex(xi[0], QUAD_SIGNS[k][0]));
        dx w = addx(constx(1.0), scalex(xi[1], QUAD_SIGNS[k][1]));
        N[k] = scalex(mulx(u, w), 0.25);
    }
}

static void multiplier_basis(int ns, int dual_basis, const dx A[4][4], const dx *N, dx *Phi) {
    for (int j = 0; j < ns; ++j) {
        if (dual_basis) {
            Phi[j] = mulx(N[0], A[j][0]);
            for (int k = 1; k < ns; ++k) Phi[j] = addx(Phi[j], mulx(N[k], A[j][k]));
        } else {
            Phi[j] = N[j];
        }
    }
}

/* One Gauss point of weight W: D += W Phi_j N_k, M += W Phi_j Nm_l, Dn, Mn times the normal
 * field n = sum_j N_j n_j, area += W Phi_j; a crosspoint's Phi shared by the other nodes */
static void accumulate_point(integrals_t *in, int ns, int nm, dx W, dx *Phi, const dx *N,
                             const dx *Nm, const dx (*node_normals)[3], const int *cross,
                             int any_cross, double share) {
    dx normal[3];
    if (any_cross) {
        dx shared = constx(0.0);
        for (int j = 0; j < ns; ++j) if (cross[j]) shared = addx(shared, Phi[j]);
        for (int j = 0; j < ns; ++j)
            Phi[j] = cross[j] ? constx(0.0) : addx(Phi[j], scalex(shared, share));
    }
    for (int c = 0; c < 3; ++c) {
        normal[c] = mulx(node_normals[0][c], N[0]);
        for (int j = 1; j < ns; ++j) normal[c] = addx(normal[c], mulx(node_normals[j][c], N[j]));
    }
    for (int j = 0; j < ns; ++j) {
        if (cross[j]) continue;
        dx Q = mulx(W, Phi[j]);
        in->area[j] = addx(in->area[j], Q);
        for (int k = 0; k < ns; ++k) {
            dx QN = mulx(Q, N[k]);
            in->D[j][k] = addx(in->D[j][k], QN);
            for (int c = 0; c < 3; ++c) accumulatex(&in->Dn[j][k][c], &QN, &normal[c]);
        }
        for (int l = 0; l < nm; ++l) {
            dx QN = mulx(Q, Nm[l]);
            in->M[j][l] = addx(in->M[j][l], QN);
            for (int c = 0; c < 3; ++c) accumulatex(&in->Mn[j][l][c], &QN, &normal[c]);
        }
    }
}

static void zero_pair_general(const outputs_t *o, sizes_t z, long p) {
    const long ss = z.ns * z.ns, sm = z.ns * z.nm, nv = z.nv;
    memset(o->D + ss * p, 0, ss * sizeof(double)); memset(o->M + sm * p, 0, sm * sizeof(double));
    memset(o->Dn + 3 * ss * p, 0, 3 * ss * sizeof(double));
    memset(o->Mn + 3 * sm * p, 0, 3 * sm * sizeof(double));
    memset(o->gap + z.ns * p, 0, z.ns * sizeof(double));
    memset(o->area + z.ns * p, 0, z.ns * sizeof(double));
    if (o->gDn) memset(o->gDn + 3 * ss * nv * p, 0, 3 * ss * nv * sizeof(double));
    if (o->gMn) memset(o->gMn + 3 * sm * nv * p, 0, 3 * sm * nv * sizeof(double));
    if (o->ggap) memset(o->ggap + z.ns * nv * p, 0, z.ns * nv * sizeof(double));
    if (o->garea) memset(o->garea + z.ns * nv * p, 0, z.ns * nv * sizeof(double));
    if (o->gD) memset(o->gD + ss * nv * p, 0, ss * nv * sizeof(double));
    if (o->gM) memset(o->gM + sm * nv * p, 0, sm * nv * sizeof(double));
}

/* n pairs of ns-node slave and nm-node master facets (3 or 4 each): xs (n, ns, 3), xm (n, nm,
 * 3), nn (n, ns, 3); crosspoint (n, ns) or NULL; normals 0 averaged, 1 slave, 2 master; rule
 * 1, 3 or 7; outputs as surface3.pair_quantities (gradients (..., 3 (2 ns + nm))); gD, gM may
 * be NULL. Returns 0, -1 for bad arguments, or -2 - p if pair p's clip polygon outgrew its
 * slots. */
int surface3_pairs(long n, int ns, int nm, const double *xs, const double *xm, const double *nn,
                   const unsigned char *crosspoint, int normals, int dual_basis, int rule,
                   unsigned char *valid, double *overlap,
                   double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                   double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                   double *garea) {
    if ((ns != 3 && ns != 4) || (nm != 3 && nm != 4) || normals < 0 || normals > 2) return -1;
    double bary[7][3], weights[7];
    int q;
    if (rule == 1) {
        q = 1; bary[0][0] = bary[0][1] = bary[0][2] = 1.0 / 3.0; weights[0] = 1.0;
    } else if (rule == 3) {
        q = 3;
        for (int g = 0; g < 3; ++g) {
            for (int a = 0; a < 3; ++a) bary[g][a] = (a == g) ? 2.0 / 3.0 : 1.0 / 6.0;
            weights[g] = 1.0 / 3.0;
        }
    } else if (rule == 7) {
        const double a1 = 0.059715871789770, b1 = 0.470142064105115;
        const double a2 = 0.797426985353087, b2 = 0.101286507323456;
        q = 7;
        bary[0][0] = bary[0][1] = bary[0][2] = 1.0 / 3.0; weights[0] = 0.225;
        for (int g = 0; g < 3; ++g) {
            for (int a = 0; a < 3; ++a) {
                bary[1 + g][a] = (a == g) ? a1 : b1;
                bary[4 + g][a] = (a == g) ? a2 : b2;
            }
            weights[1 + g] = 0.132394152788506;
            weights[4 + g] = 0.125939180544827;
        }
    } else {
        return -1;
    }
    sizes_t z = {ns, nm, 3 * (2 * ns + nm)};
    outputs_t o = {D, M, Dn, Mn, gap, area, gD, gM, gDn, gMn, ggap, garea};
    const int values_only = !gD && !gM && !gDn && !gMn && !ggap && !garea;
    if (!values_only && (!gDn || !gMn || !ggap || !garea)) return -1;
    int (*integrate)(long, sizes_t, const double *, const double *, const double *,
                     const unsigned char *, int, int, int, const double (*)[3], const double *,
                     const outputs_t *, unsigned char *, double *) =
        values_only ? pair_general_values : pair_general;
    int status = 0;
    for (long p = 0; p < n && status >= 0; ++p) {
        valid[p] = 0;
        overlap[p] = 0.0;
        status = integrate(p, z, xs + 3 * ns * p, xm + 3 * nm * p, nn + 3 * ns * p,
                           crosspoint ? crosspoint + ns * p : NULL, normals, dual_basis,
                           q, (const double (*)[3])bary, weights, &o, valid, overlap);
        if (status < 0) status = -2 - (int)p;
        else if (status == 0) zero_pair_general(&o, z, p);
    }
    return status < 0 ? status : 0;
}

/* ======================================================================================
 * Element-based integration (surface3.py's _element_points_on_master and
 * _integrate_element): the slave facet's Gauss points projected along the normal field onto
 * the master facet (Newton on values, then one step in dual arithmetic at the root).
 * ====================================================================================== */

/* (eta, alpha) with sum_l Nm_l(eta) xm_l = point + alpha direction */
static void project_onto_master(const dx (*xm)[3], int nm, const dx *point, const dx *direction,
                                dx *eta) {
    double u[3] = {nm == 3 ? 1.0 / 3.0 : 0.0, nm == 3 ? 1.0 / 3.0 : 0.0, 0.0};
    double N[4], dN[4][2], J[4][4], inverse[4][4];
    const int iterations = nm == 3 ? 1 : 30;
    for (int pass = 0; pass <= iterations; ++pass) {
        shape_values(u[0], u[1], nm, N, dN);
        for (int c = 0; c < 3; ++c) {
            for (int d = 0; d < 2; ++d) {
                J[c][d] = 0.0;
                for (int l = 0; l < nm; ++l) J[c][d] += dN[l][d] * xm[l][c].v;
            }
            J[c][2] = -direction[c].v;
        }
        double det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1])
                     - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0])
                     + J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
        if (!(fabs(det) > 1e-300))
            for (int c = 0; c < 3; ++c)
                for (int d = 0; d < 3; ++d) J[c][d] = c == d ? 1.0 : 0.0;
        invert(3, (const double (*)[4])J, inverse);
        if (pass == iterations) break;
        double residual[3], step[3];
        for (int c = 0; c < 3; ++c) {
            residual[c] = -point[c].v - u[2] * direction[c].v;
            for (int l = 0; l < nm; ++l) residual[c] += N[l] * xm[l][c].v;
        }
        int converged = 1;
        for (int a = 0; a < 3; ++a) {
            step[a] = (inverse[a][0] * residual[0] + inverse[a][1] * residual[1]) + inverse[a][2] * residual[2];
        }
        for (int a = 0; a < 3; ++a) {
            u[a] -= step[a];
            converged &= fabs(step[a]) < 1e-15 * (1.0 + fabs(u[a]));
        }
        if (converged) {
            shape_values(u[0], u[1], nm, N, dN);
            for (int c = 0; c < 3; ++c) {
                for (int d = 0; d < 2; ++d) {
                    J[c][d] = 0.0;
                    for (int l = 0; l < nm; ++l) J[c][d] += dN[l][d] * xm[l][c].v;
                }
                J[c][2] = -direction[c].v;
            }
            double det2 = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1])
                          - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0])
                          + J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
            if (!(fabs(det2) > 1e-300))
                for (int c = 0; c < 3; ++c)
                    for (int d = 0; d < 3; ++d) J[c][d] = c == d ? 1.0 : 0.0;
            invert(3, (const double (*)[4])J, inverse);
            break;
        }
    }
    /* F = sum_l Nm_l xm_l - point - alpha direction; (eta, alpha) = u - J^-1 F */
    dx F[3];
    for (int c = 0; c < 3; ++c) {
        F[c] = subx(negx(point[c]), scalex(direction[c], u[2]));
        for (int l = 0; l < nm; ++l) F[c] = addx(F[c], scalex(xm[l][c], N[l]));
    }
    for (int a = 0; a < 2; ++a)
        eta[a] = subx(constx(u[a]), addx(addx(scalex(F[0], inverse[a][0]), scalex(F[1], inverse[a][1])),
                                          scalex(F[2], inverse[a][2])));
}

/* the slave facet's point (Gauss point on its reference facet) and the normal field there */
static void slave_point(const dx (*xs)[3], const dx (*node_normals)[3], int ns, const double *N,
                        dx *point, dx *direction) {
    for (int c = 0; c < 3; ++c) {
        point[c] = scalex(xs[0][c], N[0]);
        direction[c] = scalex(node_normals[0][c], N[0]);
        for (int k = 1; k < ns; ++k) {
            point[c] = addx(point[c], scalex(xs[k][c], N[k]));
            direction[c] = addx(direction[c], scalex(node_normals[k][c], N[k]));
        }
    }
}

/* score (n, q): how far each Gauss point (points (q, 2) on the slave reference facet) lands
 * outside the master facet (<= 1e-12: on it; smaller: more central), +inf where it does not
 * land on it or the facets do not face each other */
int surface3_element_scores(long n, int ns, int nm, const double *xs, const double *xm,
                            const double *nn, int normals, int q, const double *points,
                            double *score) {
    if ((ns != 3 && ns != 4) || (nm != 3 && nm != 4) || normals < 0 || normals > 2 || q > 9) return -1;
    sizes_t z = {ns, nm, 3 * (2 * ns + nm)};
    for (long p = 0; p < n; ++p) {
        dx vxs[4][3], vxm[4][3], node_normals[4][3];
        pair_variables_x(z, xs + 3 * ns * p, xm + 3 * nm * p, nn + 3 * ns * p, normals, vxs, vxm,
                         node_normals);
        const double *xmv = xm + 3 * nm * p;
        double n0[3], u[3], w[3], mn[3];
        for (int c = 0; c < 3; ++c) {
            n0[c] = node_normals[0][c].v;
            for (int k = 1; k < ns; ++k) n0[c] += node_normals[k][c].v;
            if (nm == 4) { u[c] = xmv[6 + c] - xmv[c]; w[c] = xmv[9 + c] - xmv[3 + c]; }
            else { u[c] = xmv[3 + c] - xmv[c]; w[c] = xmv[6 + c] - xmv[c]; }
        }
        mn[0] = u[1] * w[2] - u[2] * w[1]; mn[1] = u[2] * w[0] - u[0] * w[2]; mn[2] = u[0] * w[1] - u[1] * w[0];
        double length = sqrt((mn[0] * mn[0] + mn[1] * mn[1]) + mn[2] * mn[2]);
        for (int c = 0; c < 3; ++c) mn[c] = mn[c] / length;
        double n0_length = sqrt((n0[0] * n0[0] + n0[1] * n0[1]) + n0[2] * n0[2]);
        int facing = ((n0[0] * mn[0] + n0[1] * mn[1]) + n0[2] * mn[2]) < -FACING_TOLERANCE * n0_length;
        for (int g = 0; g < q; ++g) {
            double N[4];
            dx point[3], direction[3], eta[2];
            shape_values(points[2 * g], points[2 * g + 1], ns, N, NULL);
            slave_point((const dx (*)[3])vxs, (const dx (*)[3])node_normals, ns, N, point, direction);
            project_onto_master((const dx (*)[3])vxm, nm, point, direction, eta);
            double e0 = eta[0].v, e1 = eta[1].v, outside;
            if (nm == 3) {
                outside = -e0 > -e1 ? -e0 : -e1;
                if (e0 + e1 - 1.0 > outside) outside = e0 + e1 - 1.0;
            } else {
                outside = (fabs(e0) > fabs(e1) ? fabs(e0) : fabs(e1)) - 1.0;
            }
            int finite = isfinite(e0) && isfinite(e1);
            score[q * p + g] = (facing && finite && outside <= 1e-12) ? outside : INFINITY;
        }
    }
    return 0;
}

/* The pairs' outputs from the Gauss points given to them (on_master (n, q)): W = |x_xi x x_eta|
 * w_g at the slave points, the master functions at the projected points; valid where any
 * point is given, overlap = the given points' share of the facet's area */
int surface3_element(long n, int ns, int nm, const double *xs, const double *xm, const double *nn,
                     const unsigned char *crosspoint, int normals, int dual_basis, int q,
                     const double *points, const double *point_weights,
                     const unsigned char *on_master, unsigned char *valid, double *overlap,
                     double *D, double *M, double *Dn, double *Mn, double *gap, double *area,
                     double *gD, double *gM, double *gDn, double *gMn, double *ggap,
                     double *garea) {
    if ((ns != 3 && ns != 4) || (nm != 3 && nm != 4) || normals < 0 || normals > 2 || q > 9) return -1;
    sizes_t z = {ns, nm, 3 * (2 * ns + nm)};
    outputs_t o = {D, M, Dn, Mn, gap, area, gD, gM, gDn, gMn, ggap, garea};
    for (long p = 0; p < n; ++p) {
        valid[p] = 0;
        overlap[p] = 0.0;
        int any = 0;
        for (int g = 0; g < q; ++g) any |= on_master[q * p + g] != 0;
        if (!any) {
            zero_pair_general(&o, z, p);
            continue;
        }
        dx vxs[4][3], vxm[4][3], node_normals[4][3];
        pair_variables_x(z, xs + 3 * ns * p, xm + 3 * nm * p, nn + 3 * ns * p, normals, vxs, vxm,
                         node_normals);
        dx A[4][4];
        if (dual_basis) dual_coefficients_x((const dx (*)[3])vxs, ns, A);
        int cross[4], any_cross;
        double share = crosspoint_shares(ns, crosspoint ? crosspoint + ns * p : NULL, cross, &any_cross);
        integrals_t in;
        memset(&in, 0, sizeof in);
        double given = 0.0, total = 0.0;
        for (int g = 0; g < q; ++g) {
            double Nv[4], dN[4][2];
            shape_values(points[2 * g], points[2 * g + 1], ns, Nv, dN);
            dx t1[3], t2[3], normal[3];
            for (int c = 0; c < 3; ++c) {
                t1[c] = scalex(vxs[0][c], dN[0][0]); t2[c] = scalex(vxs[0][c], dN[0][1]);
                for (int k = 1; k < ns; ++k) {
                    t1[c] = addx(t1[c], scalex(vxs[k][c], dN[k][0]));
                    t2[c] = addx(t2[c], scalex(vxs[k][c], dN[k][1]));
                }
            }
            crossx(t1, t2, normal);
            dx jacobian = sqrtx(dotx(normal, normal));
            total += jacobian.v * point_weights[g];
            if (!on_master[q * p + g]) continue;
            given += jacobian.v * point_weights[g];
            dx point[3], direction[3], eta[2], N[4], Nm[4], Phi[4];
            slave_point((const dx (*)[3])vxs, (const dx (*)[3])node_normals, ns, Nv, point, direction);
            project_onto_master((const dx (*)[3])vxm, nm, point, direction, eta);
            for (int k = 0; k < ns; ++k) N[k] = constx(Nv[k]);
            shape_duals(eta, nm, Nm);
            multiplier_basis(ns, dual_basis, A, N, Phi);
            accumulate_point(&in, ns, nm, scalex(jacobian, point_weights[g]), Phi, N, Nm,
                             (const dx (*)[3])node_normals, cross, any_cross, share);
        }
        write_outputs(&in, z, p, (const dx (*)[3])vxs, (const dx (*)[3])vxm, &o);
        valid[p] = 1;
        overlap[p] = given / total;
    }
    return 0;
}

#include "surface3_stencils.h"
