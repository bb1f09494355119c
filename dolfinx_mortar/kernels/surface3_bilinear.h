/* The inverse of a bilinear quadrilateral's map in its plane, for surface3.c (after its
 * QUAD_SIGNS and shape_values): in closed form, Newton where the closed form's root is not a
 * point of the facet. */

/* x with sum_k N_k(x) C_k = P on a bilinear quadrilateral: Newton from x until a step is below
 * 1e-7, which leaves an error of order 1e-14 that the caller's last Newton step squares */
static void bilinear_root(const double (*C)[2], const double *P, double *x) {
    double N[4], dN[4][2], J[2][2];
    for (int iteration = 0; iteration < 20; ++iteration) {
        shape_values(x[0], x[1], 4, N, dN);
        double residual[2];
        for (int c = 0; c < 2; ++c) {
            residual[c] = -P[c];
            for (int k = 0; k < 4; ++k) residual[c] += N[k] * C[k][c];
            for (int d = 0; d < 2; ++d) {
                J[c][d] = 0.0;
                for (int k = 0; k < 4; ++k) J[c][d] += C[k][c] * dN[k][d];
            }
        }
        double det = J[0][0] * J[1][1] - J[0][1] * J[1][0];
        double step0 = (J[1][1] * residual[0] - J[0][1] * residual[1]) / det;
        double step1 = (J[0][0] * residual[1] - J[1][0] * residual[0]) / det;
        x[0] -= step0; x[1] -= step1;
        if (fabs(step0) < 1e-7 && fabs(step1) < 1e-7) break;
    }
}

/* a bilinear quadrilateral's map sum_k N_k(x) C_k = a + b x0 + c x1 + d x0 x1 */
typedef struct { double corners[4][2], a[2], b[2], c[2], d[2]; } bilinear_t;

static void bilinear_coefficients(const double (*C)[2], bilinear_t *f) {
    for (int e = 0; e < 2; ++e) f->a[e] = f->b[e] = f->c[e] = f->d[e] = 0.0;
    for (int k = 0; k < 4; ++k) {
        double s = QUAD_SIGNS[k][0], t = QUAD_SIGNS[k][1];
        for (int e = 0; e < 2; ++e) {
            f->corners[k][e] = C[k][e];
            f->a[e] += 0.25 * C[k][e]; f->b[e] += 0.25 * s * C[k][e];
            f->c[e] += 0.25 * t * C[k][e]; f->d[e] += 0.25 * s * t * C[k][e];
        }
    }
}

/* x with a + b x0 + c x1 + d x0 x1 = P in closed form: with q = P - a, x0 is the root of
 * (b x d) x0^2 + (b x c - q x d) x0 - q x c = 0 that tends to the parallelogram's as b x d -> 0
 * (in the form that does not cancel), x1 = (q - b x0) . v / v . v along v = c + d x0. Newton
 * from the centre where that root is not a point of the facet. */
static void bilinear_inverse(const bilinear_t *f, const double *P, double *x) {
    const double *b = f->b, *c = f->c, *d = f->d;
    double q[2] = {P[0] - f->a[0], P[1] - f->a[1]};
    double A = b[0] * d[1] - b[1] * d[0];
    double B = (b[0] * c[1] - b[1] * c[0]) - (q[0] * d[1] - q[1] * d[0]);
    double K = -(q[0] * c[1] - q[1] * c[0]);
    double discriminant = B * B - 4.0 * A * K;
    double denominator = -B - copysign(sqrt(discriminant > 0.0 ? discriminant : 0.0), B);
    x[0] = 2.0 * K / denominator;
    double v[2] = {c[0] + d[0] * x[0], c[1] + d[1] * x[0]};
    double r[2] = {q[0] - b[0] * x[0], q[1] - b[1] * x[0]};
    x[1] = (r[0] * v[0] + r[1] * v[1]) / (v[0] * v[0] + v[1] * v[1]);
    if (!(fabs(x[0]) <= 1.5 && fabs(x[1]) <= 1.5)) {
        x[0] = x[1] = 0.0;
        bilinear_root((const double (*)[2])f->corners, P, x);
    }
}
