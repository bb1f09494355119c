/* The general pair path of surface3.c, instantiated there twice: with the derivatives over the
 * pair's variables (DERIVATIVES 1: NX = 36 pair variables, NP = 16 plane coordinates) and for
 * the values only (DERIVATIVES 0: one derivative slot each, never touched by the arithmetic;
 * surface3.c renames every type and function of this file for that instance). The values'
 * operations are the same in both, so are their bits. */
#if DERIVATIVES
#define SEED(x, i) ((x).d[i] = 1.0)
#define NXD NX
#define NPD NP
#else
#define SEED(x, i) ((void)0)
#define NXD 0
#define NPD 0
#endif

typedef struct { double v, d[NX]; } dx;

static inline dx constx(double v) { dx r; memset(&r, 0, sizeof r); r.v = v; return r; }
static inline dx addx(dx a, dx b) { dx r; r.v = a.v + b.v; for (int i = 0; i < NXD; ++i) r.d[i] = a.d[i] + b.d[i]; return r; }
static inline dx subx(dx a, dx b) { dx r; r.v = a.v - b.v; for (int i = 0; i < NXD; ++i) r.d[i] = a.d[i] - b.d[i]; return r; }
static inline dx mulx(dx a, dx b) { dx r; r.v = a.v * b.v; for (int i = 0; i < NXD; ++i) r.d[i] = a.d[i] * b.v + b.d[i] * a.v; return r; }
static inline dx scalex(dx a, double s) { dx r; r.v = a.v * s; for (int i = 0; i < NXD; ++i) r.d[i] = a.d[i] * s; return r; }
static inline dx negx(dx a) { dx r; r.v = -a.v; for (int i = 0; i < NXD; ++i) r.d[i] = -a.d[i]; return r; }
static inline dx divx(dx a, dx b) {
    dx r; double inverse = 1.0 / b.v; r.v = a.v * inverse;
    for (int i = 0; i < NXD; ++i) r.d[i] = (a.d[i] - b.d[i] * r.v) * inverse;
    return r;
}
static inline dx sqrtx(dx a) {
    dx r; r.v = sqrt(a.v); double f = r.v > 0.0 ? 0.5 / r.v : 0.0;
    for (int i = 0; i < NXD; ++i) r.d[i] = a.d[i] * f;
    return r;
}
static inline void zerox(dx *r) { memset(r, 0, sizeof *r); }
/* r -= a * b */
static inline void subtract_productx(dx *r, const dx *a, const dx *b) {
    r->v = r->v - a->v * b->v;
    for (int i = 0; i < NXD; ++i) r->d[i] = r->d[i] - (a->d[i] * b->v + b->d[i] * a->v);
}
/* r += a * b */
static inline void accumulatex(dx *r, const dx *a, const dx *b) {
    r->v += a->v * b->v;
    for (int i = 0; i < NXD; ++i) r->d[i] += a->d[i] * b->v + b->d[i] * a->v;
}
static inline dx dotx(const dx *a, const dx *b) { return addx(addx(mulx(a[0], b[0]), mulx(a[1], b[1])), mulx(a[2], b[2])); }
static inline void crossx(const dx *a, const dx *b, dx *out) {
    out[0] = subx(mulx(a[1], b[2]), mulx(a[2], b[1]));
    out[1] = subx(mulx(a[2], b[0]), mulx(a[0], b[2]));
    out[2] = subx(mulx(a[0], b[1]), mulx(a[1], b[0]));
}
static inline void normalizex(const dx *v, dx *out) {
    dx length = sqrtx(dotx(v, v));
    for (int c = 0; c < 3; ++c) out[c] = divx(v[c], length);
}
static inline dx cross2x(const dx *a, const dx *b) { return subx(mulx(a[0], b[1]), mulx(a[1], b[0])); }

/* the same over the plane coordinates S, Mp only (NP local variables: S_ka at 2 k + a, Mp_la at
 * 2 ns + 2 l + a): everything in the plane depends on the pair's variables through them */
typedef struct { double v, d[NP]; } dp;

static inline dp constp(double v) { dp r; memset(&r, 0, sizeof r); r.v = v; return r; }
static inline dp addp(dp a, dp b) { dp r; r.v = a.v + b.v; for (int i = 0; i < NPD; ++i) r.d[i] = a.d[i] + b.d[i]; return r; }
static inline dp subp(dp a, dp b) { dp r; r.v = a.v - b.v; for (int i = 0; i < NPD; ++i) r.d[i] = a.d[i] - b.d[i]; return r; }
static inline dp mulp(dp a, dp b) { dp r; r.v = a.v * b.v; for (int i = 0; i < NPD; ++i) r.d[i] = a.d[i] * b.v + b.d[i] * a.v; return r; }
static inline dp scalep(dp a, double s) { dp r; r.v = a.v * s; for (int i = 0; i < NPD; ++i) r.d[i] = a.d[i] * s; return r; }
static inline dp negp(dp a) { dp r; r.v = -a.v; for (int i = 0; i < NPD; ++i) r.d[i] = -a.d[i]; return r; }
static inline dp divp(dp a, dp b) {
    dp r; double inverse = 1.0 / b.v; r.v = a.v * inverse;
    for (int i = 0; i < NPD; ++i) r.d[i] = (a.d[i] - b.d[i] * r.v) * inverse;
    return r;
}
/* r += a * b */
static inline void accumulatep(dp *r, const dp *a, const dp *b) {
    r->v += a->v * b->v;
    for (int i = 0; i < NPD; ++i) r->d[i] += a->d[i] * b->v + b->d[i] * a->v;
}
static inline dp cross2p(const dp *a, const dp *b) { return subp(mulp(a[0], b[1]), mulp(a[1], b[0])); }

static void shape_duals_p(const dp *xi, int nodes, dp *N) {
    if (nodes == 3) {
        N[0] = subp(subp(constp(1.0), xi[0]), xi[1]); N[1] = xi[0]; N[2] = xi[1];
        return;
    }
    for (int k = 0; k < 4; ++k) {
        dp u = addp(constp(1.0), scalep(xi[0], QUAD_SIGNS[k][0]));
        dp w = addp(constp(1.0), scalep(xi[1], QUAD_SIGNS[k][1]));
        N[k] = scalep(mulp(u, w), 0.25);
    }
}

/* xi with sum_k N_k(xi) C_k = P (plane coordinates), in closed form on values (map: the
 * quadrilateral's coefficients, unread for triangles) */
static void inverse_map_p(const dp (*C)[2], int nodes, const bilinear_t *map, const dp *P,
                          dp *xi) {
    double x[2];
    if (nodes == 3) {
        double A00 = C[1][0].v - C[0][0].v, A01 = C[2][0].v - C[0][0].v;
        double A10 = C[1][1].v - C[0][1].v, A11 = C[2][1].v - C[0][1].v;
        double det = A00 * A11 - A01 * A10;
        double o0 = P[0].v - C[0][0].v, o1 = P[1].v - C[0][1].v;
        x[0] = (A11 * o0 - A01 * o1) / det;
        x[1] = (A00 * o1 - A10 * o0) / det;
    } else {
        double point[2] = {P[0].v, P[1].v};
        bilinear_inverse(map, point, x);
    }
    /* the root's derivatives by the implicit function theorem: dxi = -J^-1 dF at xi,
     * F = sum_k N_k(xi) C_k - P */
    for (int a = 0; a < 2; ++a) xi[a] = constp(x[a]);
#if DERIVATIVES
    double N[4], dN[4][2], J[2][2];
    shape_values(x[0], x[1], nodes, N, dN);
    dp F[2];
    for (int c = 0; c < 2; ++c) {
        F[c] = negp(P[c]);
        for (int k = 0; k < nodes; ++k) F[c] = addp(F[c], scalep(C[k][c], N[k]));
        for (int d = 0; d < 2; ++d) {
            J[c][d] = 0.0;
            for (int k = 0; k < nodes; ++k) J[c][d] += C[k][c].v * dN[k][d];
        }
    }
    double det = J[0][0] * J[1][1] - J[0][1] * J[1][0];
    double I[2][2] = {{J[1][1] / det, -J[0][1] / det}, {-J[1][0] / det, J[0][0] / det}};
    for (int a = 0; a < 2; ++a)
        for (int i = 0; i < NP; ++i) xi[a].d[i] = -(I[a][0] * F[0].d[i] + I[a][1] * F[1].d[i]);
#endif
}

/* A (ns x ns) with Phi = A N biorthogonal on the whole slave facet: A = D_e M_e^-1, for
 * quadrilaterals from the 3 x 3 Gauss rule of the area element, dA = (dD_e - A dM_e) M_e^-1 */
static void dual_coefficients_x(const dx (*xs)[3], int ns, dx A[4][4]) {
    if (ns == 3) {
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k) A[j][k] = constx(j == k ? 3.0 : -1.0);
        return;
    }
    const double g[3] = {-0.7745966692414834, 0.0, 0.7745966692414834};
    const double w[3] = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
    dx mass[4][4], lumped[4];
    for (int j = 0; j < 4; ++j) {
        zerox(&lumped[j]);
        for (int k = 0; k < 4; ++k) zerox(&mass[j][k]);
    }
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
            double N[4], dN[4][2];
            shape_values(g[a], g[b], 4, N, dN);
            dx t1[3], t2[3], normal[3];
            for (int c = 0; c < 3; ++c) {
                zerox(&t1[c]); zerox(&t2[c]);
                for (int k = 0; k < 4; ++k) {
                    t1[c] = addx(t1[c], scalex(xs[k][c], dN[k][0]));
                    t2[c] = addx(t2[c], scalex(xs[k][c], dN[k][1]));
                }
            }
            crossx(t1, t2, normal);
            dx jw = scalex(sqrtx(dotx(normal, normal)), w[a] * w[b]);
            for (int j = 0; j < 4; ++j) {
                lumped[j] = addx(lumped[j], scalex(jw, N[j]));
                for (int k = 0; k < 4; ++k) mass[j][k] = addx(mass[j][k], scalex(jw, N[j] * N[k]));
            }
        }
    double Me[4][4], inverse[4][4], Av[4][4];
    for (int j = 0; j < 4; ++j)
        for (int k = 0; k < 4; ++k) Me[j][k] = mass[j][k].v;
    invert(4, Me, inverse);
    for (int j = 0; j < 4; ++j)
        for (int k = 0; k < 4; ++k) Av[j][k] = lumped[j].v * inverse[j][k];
    /* B = A dM_e (per variable), then dA = dD_e - B M_e^-1 */
    for (int j = 0; j < 4; ++j)
        for (int k = 0; k < 4; ++k) {
            A[j][k].v = Av[j][k];
            for (int s = 0; s < NX; ++s) A[j][k].d[s] = lumped[j].d[s] * inverse[j][k];
        }
    for (int i = 0; i < 4; ++i)
        for (int m = 0; m < 4; ++m) {
            double B[NX] = {0.0};
            for (int l = 0; l < 4; ++l)
                for (int s = 0; s < NX; ++s) B[s] += Av[i][l] * mass[l][m].d[s];
            for (int k = 0; k < 4; ++k)
                for (int s = 0; s < NX; ++s) A[i][k].d[s] -= B[s] * inverse[m][k];
        }
}

/* The pair's variables xs, xm as dual numbers and the normal field's nodal normals */
static void pair_variables_x(sizes_t z, const double *xsv, const double *xmv, const double *nnv,
                             int normals, dx xs[4][3], dx xm[4][3], dx node_normals[4][3]) {
    const int ns = z.ns, nm = z.nm;
    for (int k = 0; k < ns; ++k)
        for (int c = 0; c < 3; ++c) {
            xs[k][c] = constx(xsv[3 * k + c]); SEED(xs[k][c], 3 * k + c);
        }
    for (int k = 0; k < nm; ++k)
        for (int c = 0; c < 3; ++c) {
            xm[k][c] = constx(xmv[3 * k + c]); SEED(xm[k][c], 3 * ns + 3 * k + c);
        }
    /* the normal field's nodal normals */
    if (normals == 0) {
        for (int k = 0; k < ns; ++k)
            for (int c = 0; c < 3; ++c) {
                node_normals[k][c] = constx(nnv[3 * k + c]);
                SEED(node_normals[k][c], 3 * (ns + nm) + 3 * k + c);
            }
    } else if (normals == 1) {
        for (int i = 0; i < ns; ++i) {
            dx a[3], b[3], v[3];
            for (int c = 0; c < 3; ++c) {
                a[c] = subx(xs[(i + 1) % ns][c], xs[i][c]);
                b[c] = subx(xs[(i + ns - 1) % ns][c], xs[i][c]);
            }
            crossx(a, b, v);
            normalizex(v, node_normals[i]);
        }
    } else {
        dx a[3], b[3], v[3], unit[3];
        for (int c = 0; c < 3; ++c) {
            if (nm == 4) { a[c] = subx(xm[2][c], xm[0][c]); b[c] = subx(xm[3][c], xm[1][c]); }
            else { a[c] = subx(xm[1][c], xm[0][c]); b[c] = subx(xm[2][c], xm[0][c]); }
        }
        crossx(a, b, v);
        normalizex(v, unit);
        for (int i = 0; i < ns; ++i)
            for (int c = 0; c < 3; ++c) node_normals[i][c] = negx(unit[c]);
    }
}

typedef struct { dx D[4][4], M[4][4], Dn[4][4][3], Mn[4][4][3], area[4]; } integrals_t;

/* D, M, Dn, Mn, the areas and gap_j = sum_lc Mn_jlc xm_lc - sum_kc Dn_jkc xs_kc into pair p's
 * output slots */
static void write_outputs(const integrals_t *in, sizes_t z, long p, const dx (*xs)[3],
                          const dx (*xm)[3], const outputs_t *o) {
    const int ns = z.ns, nm = z.nm, nv = z.nv;
    for (int j = 0; j < ns; ++j) {
        dx gap;
        zerox(&gap);
        for (int l = 0; l < nm; ++l)
            for (int c = 0; c < 3; ++c) accumulatex(&gap, &in->Mn[j][l][c], &xm[l][c]);
        for (int k = 0; k < ns; ++k)
            for (int c = 0; c < 3; ++c) subtract_productx(&gap, &in->Dn[j][k][c], &xs[k][c]);
        o->gap[ns * p + j] = gap.v;
        if (DERIVATIVES && o->ggap) memcpy(o->ggap + (ns * p + j) * nv, gap.d, sizeof(double) * nv);
        o->area[ns * p + j] = in->area[j].v;
        if (DERIVATIVES && o->garea) memcpy(o->garea + (ns * p + j) * nv, in->area[j].d, sizeof(double) * nv);
        for (int k = 0; k < ns; ++k) {
            long e = (long)ns * ns * p + ns * j + k;
            o->D[e] = in->D[j][k].v;
            if (DERIVATIVES && o->gD) memcpy(o->gD + e * nv, in->D[j][k].d, sizeof(double) * nv);
            for (int c = 0; c < 3; ++c) {
                o->Dn[3 * e + c] = in->Dn[j][k][c].v;
                if (DERIVATIVES && o->gDn) memcpy(o->gDn + (3 * e + c) * nv, in->Dn[j][k][c].d, sizeof(double) * nv);
            }
        }
        for (int l = 0; l < nm; ++l) {
            long e = (long)ns * nm * p + nm * j + l;
            o->M[e] = in->M[j][l].v;
            if (DERIVATIVES && o->gM) memcpy(o->gM + e * nv, in->M[j][l].d, sizeof(double) * nv);
            for (int c = 0; c < 3; ++c) {
                o->Mn[3 * e + c] = in->Mn[j][l][c].v;
                if (DERIVATIVES && o->gMn) memcpy(o->gMn + (3 * e + c) * nv, in->Mn[j][l][c].d, sizeof(double) * nv);
            }
        }
    }
}

/* The pair's outputs (values and gradients over its nv variables): zero unless valid */
static int pair_general(long p, sizes_t z, const double *xsv, const double *xmv, const double *nnv,
                        const unsigned char *crosspoint, int normals, int dual_basis,
                        int q, const double (*bary)[3], const double *rule_weights,
                        const outputs_t *o, unsigned char *valid, double *overlap) {
    const int ns = z.ns, nm = z.nm;
    if (!passes_screening(z, xsv, xmv, nnv, normals)) return 0;
    dx xs[4][3], xm[4][3], node_normals[4][3];
    /* (their first rows set for the compiler, which cannot see that ns >= 3) */
    memset(xs[0], 0, sizeof xs[0]); memset(node_normals[0], 0, sizeof node_normals[0]);
    pair_variables_x(z, xsv, xmv, nnv, normals, xs, xm, node_normals);
    /* the auxiliary plane */
    dx x0[3], sum[3], n0[3], edge[3], wv[3], e[2][3];
    for (int c = 0; c < 3; ++c) {
        x0[c] = xs[0][c]; sum[c] = node_normals[0][c];
        for (int k = 1; k < ns; ++k) { x0[c] = addx(x0[c], xs[k][c]); sum[c] = addx(sum[c], node_normals[k][c]); }
        x0[c] = scalex(x0[c], 1.0 / ns);
        sum[c] = scalex(sum[c], 1.0 / ns);
    }
    normalizex(sum, n0);
    for (int c = 0; c < 3; ++c) edge[c] = subx(xs[1][c], xs[0][c]);
    dx along = dotx(edge, n0);
    for (int c = 0; c < 3; ++c) wv[c] = subx(edge[c], mulx(n0[c], along));
    normalizex(wv, e[0]);
    crossx(n0, e[0], e[1]);
    dx Sx[4][2], Mx[4][2];
    double S[4][2], Mp[4][2];
    for (int k = 0; k < ns; ++k) {
        dx offset[3];
        for (int c = 0; c < 3; ++c) offset[c] = subx(xs[k][c], x0[c]);
        for (int a = 0; a < 2; ++a) { Sx[k][a] = dotx(offset, e[a]); S[k][a] = Sx[k][a].v; }
    }
    for (int k = 0; k < nm; ++k) {
        dx offset[3];
        for (int c = 0; c < 3; ++c) offset[c] = subx(xm[k][c], x0[c]);
        for (int a = 0; a < 2; ++a) { Mx[k][a] = dotx(offset, e[a]); Mp[k][a] = Mx[k][a].v; }
    }
    /* (facing and separation: passes_screening, on the same values) */
    polygon_t poly;
    if (clip_k((const double (*)[2])S, ns, (const double (*)[2])Mp, nm, &poly) != 0) return -1;
    double slave_area = fabs(polygon_area_k((const double (*)[2])S, ns));
    double clip_area = padded_area(&poly);
    if (!(poly.count >= 3 && clip_area > AREA_TOLERANCE * slave_area)) return 0;
    valid[p] = 1;
    overlap[p] = clip_area / slave_area;
    const int V = poly.count;

    /* the plane coordinates as local variables */
    dp Sl[4][2], Ml[4][2];
    for (int k = 0; k < ns; ++k)
        for (int a = 0; a < 2; ++a) { Sl[k][a] = constp(S[k][a]); SEED(Sl[k][a], 2 * k + a); }
    for (int l = 0; l < nm; ++l)
        for (int a = 0; a < 2; ++a) { Ml[l][a] = constp(Mp[l][a]); SEED(Ml[l][a], 2 * ns + 2 * l + a); }
    /* the clip vertices from their labels, the centre */
    dp vertex[MAXV][2], centre[2];
    for (int k = 0; k < V; ++k) {
        int kind = poly.label[k][0], i = poly.label[k][1], j = poly.label[k][2];
        if (kind == 0) {
            vertex[k][0] = Sl[i][0]; vertex[k][1] = Sl[i][1];
        } else if (kind == 1) {
            int node = ((nm - 1 - j) % nm + nm) % nm;
            vertex[k][0] = Ml[node][0]; vertex[k][1] = Ml[node][1];
        } else {
            int es = ((nm - 2 - j) % nm + nm) % nm;
            const dp *a0 = Sl[i], *a1 = Sl[(i + 1) % ns], *b0 = Ml[es], *b1 = Ml[(es + 1) % nm];
            dp da[2] = {subp(a1[0], a0[0]), subp(a1[1], a0[1])};
            dp db[2] = {subp(b1[0], b0[0]), subp(b1[1], b0[1])};
            dp ba[2] = {subp(b0[0], a0[0]), subp(b0[1], a0[1])};
            dp denominator = cross2p(da, db), numerator = cross2p(ba, db);
            dp t = denominator.v != 0.0 ? divp(numerator, denominator) : numerator;
            vertex[k][0] = addp(a0[0], mulp(da[0], t));
            vertex[k][1] = addp(a0[1], mulp(da[1], t));
        }
    }
    double weight = 1.0 / V;
    for (int a = 0; a < 2; ++a) {
        centre[a] = scalep(vertex[0][a], weight);
        for (int k = 1; k < V; ++k) centre[a] = addp(centre[a], scalep(vertex[k][a], weight));
    }
    /* the integrals of products of N_a, N_k, N_i (slave) and Nm_l (master) over the clip
     * polygon, over the local variables: L_a = int N_a, I_ak, K_al = int N_a Nm_l, T_aki
     * (a <= k <= i), U_ail = int N_a N_i Nm_l (a <= i) */
    bilinear_t slave_map, master_map;
    if (ns == 4) bilinear_coefficients((const double (*)[2])S, &slave_map);
    if (nm == 4) bilinear_coefficients((const double (*)[2])Mp, &master_map);
    dp L[4], I[4][4], K[4][4], T[4][4][4], U[4][4][4];
    memset(L, 0, sizeof L); memset(I, 0, sizeof I); memset(K, 0, sizeof K);
    memset(T, 0, sizeof T); memset(U, 0, sizeof U);
    for (int cell = 0; cell < V; ++cell) {
        const dp *v0 = vertex[cell], *v1 = vertex[(cell + 1) % V];
        dp ea[2] = {subp(v0[0], centre[0]), subp(v0[1], centre[1])};
        dp eb[2] = {subp(v1[0], centre[0]), subp(v1[1], centre[1])};
        dp cell_area = scalep(cross2p(ea, eb), 0.5);
        for (int g = 0; g < q; ++g) {
            dp P[2], xi[2], eta[2], N[4], Nm[4], WN[4], WNN[4][4];
            for (int a = 0; a < 2; ++a)
                P[a] = addp(addp(scalep(centre[a], bary[g][0]), scalep(v0[a], bary[g][1])),
                            scalep(v1[a], bary[g][2]));
            dp W = scalep(cell_area, rule_weights[g]);
            inverse_map_p((const dp (*)[2])Sl, ns, &slave_map, P, xi);
            inverse_map_p((const dp (*)[2])Ml, nm, &master_map, P, eta);
            shape_duals_p(xi, ns, N);
            shape_duals_p(eta, nm, Nm);
            for (int a = 0; a < ns; ++a) {
                WN[a] = mulp(W, N[a]);
                L[a] = addp(L[a], WN[a]);
                for (int l = 0; l < nm; ++l) accumulatep(&K[a][l], &WN[a], &Nm[l]);
                for (int k = a; k < ns; ++k) {
                    WNN[a][k] = mulp(WN[a], N[k]);
                    I[a][k] = addp(I[a][k], WNN[a][k]);
                    for (int i = k; i < ns; ++i) accumulatep(&T[a][k][i], &WNN[a][k], &N[i]);
                    for (int l = 0; l < nm; ++l) accumulatep(&U[a][k][l], &WNN[a][k], &Nm[l]);
                }
            }
        }
    }
    /* chained to the pair's variables through the plane coordinates */
    dx Lx[4], Ix[4][4], Kx[4][4], Tx[4][4][4], Ux[4][4][4];
#if DERIVATIVES
    double chain[NP][NX];
    for (int k = 0; k < ns; ++k)
        for (int a = 0; a < 2; ++a) memcpy(chain[2 * k + a], Sx[k][a].d, sizeof(double) * NX);
    for (int l = 0; l < nm; ++l)
        for (int a = 0; a < 2; ++a) memcpy(chain[2 * ns + 2 * l + a], Mx[l][a].d, sizeof(double) * NX);
    const int nl = 2 * (ns + nm);
#define CHAIN(out, in) do { \
        (out).v = (in).v; \
        for (int v_ = 0; v_ < NX; ++v_) (out).d[v_] = 0.0; \
        for (int s_ = 0; s_ < nl; ++s_) { \
            double f_ = (in).d[s_]; \
            for (int v_ = 0; v_ < NX; ++v_) (out).d[v_] += f_ * chain[s_][v_]; \
        } \
    } while (0)
#else
#define CHAIN(out, in) ((out) = constx((in).v))
#endif
    for (int a = 0; a < ns; ++a) {
        CHAIN(Lx[a], L[a]);
        for (int l = 0; l < nm; ++l) CHAIN(Kx[a][l], K[a][l]);
        for (int k = a; k < ns; ++k) {
            CHAIN(Ix[a][k], I[a][k]);
            Ix[k][a] = Ix[a][k];
            for (int l = 0; l < nm; ++l) { CHAIN(Ux[a][k][l], U[a][k][l]); Ux[k][a][l] = Ux[a][k][l]; }
            for (int i = k; i < ns; ++i) {
                CHAIN(Tx[a][k][i], T[a][k][i]);
                Tx[a][i][k] = Tx[k][a][i] = Tx[k][i][a] = Tx[i][a][k] = Tx[i][k][a] = Tx[a][k][i];
            }
        }
    }
#undef CHAIN
    /* the multiplier basis Phi_j = sum_a A_ja N_a, a crosspoint's share given to the others */
    dx A[4][4];
    if (dual_basis) {
        dual_coefficients_x((const dx (*)[3])xs, ns, A);
    } else {
        for (int j = 0; j < ns; ++j)
            for (int a = 0; a < ns; ++a) A[j][a] = constx(j == a ? 1.0 : 0.0);
    }
    int cross[4], any_cross;
    double share = crosspoint_shares(ns, crosspoint, cross, &any_cross);
    if (any_cross) {
        for (int a = 0; a < ns; ++a) {
            dx shared = constx(0.0);
            for (int j = 0; j < ns; ++j) if (cross[j]) shared = addx(shared, A[j][a]);
            for (int j = 0; j < ns; ++j)
                A[j][a] = cross[j] ? constx(0.0) : addx(A[j][a], scalex(shared, share));
        }
    }
    const int identity = !dual_basis && !any_cross;
    /* D, M, the areas; Dn_jkc = sum_i n_ic G_jki, G_jki = sum_a A_ja T_aki; Mn likewise */
    integrals_t in;
    for (int j = 0; j < ns; ++j) {
        dx G[4][4], H[4][4];
        if (identity) {
            in.area[j] = Lx[j];
            for (int k = 0; k < ns; ++k) in.D[j][k] = Ix[j][k];
            for (int l = 0; l < nm; ++l) in.M[j][l] = Kx[j][l];
        } else {
            zerox(&in.area[j]);
            for (int k = 0; k < ns; ++k) zerox(&in.D[j][k]);
            for (int l = 0; l < nm; ++l) zerox(&in.M[j][l]);
            for (int a = 0; a < ns; ++a) {
                accumulatex(&in.area[j], &A[j][a], &Lx[a]);
                for (int k = 0; k < ns; ++k) accumulatex(&in.D[j][k], &A[j][a], &Ix[a][k]);
                for (int l = 0; l < nm; ++l) accumulatex(&in.M[j][l], &A[j][a], &Kx[a][l]);
            }
        }
        for (int k = 0; k < ns; ++k) {
            for (int i = 0; i < ns; ++i) {
                if (identity) {
                    G[k][i] = Tx[j][k][i];
                } else {
                    zerox(&G[k][i]);
                    for (int a = 0; a < ns; ++a) accumulatex(&G[k][i], &A[j][a], &Tx[a][k][i]);
                }
            }
        }
        for (int i = 0; i < ns; ++i)
            for (int l = 0; l < nm; ++l) {
                if (identity) {
                    H[i][l] = Ux[j][i][l];
                } else {
                    zerox(&H[i][l]);
                    for (int a = 0; a < ns; ++a) accumulatex(&H[i][l], &A[j][a], &Ux[a][i][l]);
                }
            }
        for (int c = 0; c < 3; ++c) {
            for (int k = 0; k < ns; ++k) {
                zerox(&in.Dn[j][k][c]);
                for (int i = 0; i < ns; ++i) accumulatex(&in.Dn[j][k][c], &node_normals[i][c], &G[k][i]);
            }
            for (int l = 0; l < nm; ++l) {
                zerox(&in.Mn[j][l][c]);
                for (int i = 0; i < ns; ++i) accumulatex(&in.Mn[j][l][c], &node_normals[i][c], &H[i][l]);
            }
        }
    }
    write_outputs(&in, z, p, (const dx (*)[3])xs, (const dx (*)[3])xm, o);
    return 1;
}
#undef SEED
#undef NXD
#undef NPD
