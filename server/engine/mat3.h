/*
 * mat3.h — the few 3×3 matrix helpers the engine shares (row-major double[9]).
 */
#ifndef CS_MAT3_H
#define CS_MAT3_H

#include <math.h>

/* The small 3-vector helpers, one copy for the engine. Each result is formed in a temporary
 * before it is stored, so the output may be one of the inputs. */
static inline double cs_vec3_dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* sqrt of the squares' sum: overflows past 1.3e154 (world.c's length3 does not) */
static inline double cs_vec3_norm(const double v[3])
{
    return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

static inline void cs_vec3_cross(const double a[3], const double b[3], double c[3])
{
    const double r0 = a[1] * b[2] - a[2] * b[1], r1 = a[2] * b[0] - a[0] * b[2],
                 r2 = a[0] * b[1] - a[1] * b[0];
    c[0] = r0;
    c[1] = r1;
    c[2] = r2;
}

/* r = M v */
static inline void cs_mat3_vec(const double M[9], const double v[3], double r[3])
{
    const double r0 = M[0] * v[0] + M[1] * v[1] + M[2] * v[2],
                 r1 = M[3] * v[0] + M[4] * v[1] + M[5] * v[2],
                 r2 = M[6] * v[0] + M[7] * v[1] + M[8] * v[2];
    r[0] = r0;
    r[1] = r1;
    r[2] = r2;
}

/* r = Mᵀ v */
static inline void cs_mat3_t_vec(const double M[9], const double v[3], double r[3])
{
    const double r0 = M[0] * v[0] + M[3] * v[1] + M[6] * v[2],
                 r1 = M[1] * v[0] + M[4] * v[1] + M[7] * v[2],
                 r2 = M[2] * v[0] + M[5] * v[1] + M[8] * v[2];
    r[0] = r0;
    r[1] = r1;
    r[2] = r2;
}

/* Adjugate (transposed cofactors) of m into c; returns det(m). m⁻¹ = c / det. */
static inline double cs_mat3_adjugate(const double m[9], double c[9])
{
    c[0] = m[4] * m[8] - m[5] * m[7];
    c[1] = m[2] * m[7] - m[1] * m[8];
    c[2] = m[1] * m[5] - m[2] * m[4];
    c[3] = m[5] * m[6] - m[3] * m[8];
    c[4] = m[0] * m[8] - m[2] * m[6];
    c[5] = m[2] * m[3] - m[0] * m[5];
    c[6] = m[3] * m[7] - m[4] * m[6];
    c[7] = m[1] * m[6] - m[0] * m[7];
    c[8] = m[0] * m[4] - m[1] * m[3];
    return m[0] * c[0] + m[1] * c[3] + m[2] * c[6];
}

/* m = m⁻¹ in place by the adjugate; a (near) singular m (|det| ≤ 1e-12 of its diagonal's scale
 * cubed) becomes its diagonal's inverse (1 where an entry is 0). cs_invert_block (solver.h),
 * inline for the node passes that invert a block each (block Jacobi, the V-cycle's D⁻¹). */
static inline void cs_mat3_invert_block(double m[9])
{
    double c[9];
    const double det = cs_mat3_adjugate(m, c);
    const double scale = fabs(m[0]) + fabs(m[4]) + fabs(m[8]);
    if (fabs(det) > 1e-12 * scale * scale * scale && det != 0) {
        const double id = 1.0 / det;
        for (int k = 0; k < 9; k++)
            m[k] = c[k] * id;
    } else {
        const double d[3] = {m[0], m[4], m[8]};
        for (int k = 0; k < 9; k++)
            m[k] = 0.0;
        for (int k = 0; k < 3; k++)
            m[4 * k] = d[k] != 0 ? 1.0 / d[k] : 1.0;
    }
}

/* The mean m = tr(s)/3 of the symmetric s's eigenvalues and their spread
 * p = √(‖s − m I‖²_F / 6) (returned): s = m I + p B with B's eigenvalues in [−2, 2]. */
static inline double cs_mat3_sym_spread(const double s[9], double *m)
{
    *m = (s[0] + s[4] + s[8]) / 3.0;
    const double d0 = s[0] - *m, d1 = s[4] - *m, d2 = s[8] - *m;
    return sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * (s[1] * s[1] + s[2] * s[2] + s[5] * s[5])) /
                6.0);
}

/* An upper bound of the largest eigenvalue of the symmetric s without a transcendental:
 * m + 2p (cs_mat3_sym_spread), Samuelson's inequality on the eigenvalues, exact when the
 * other two are equal (uniaxial, hydrostatic), at most twice λmax − m (when the top two are
 * equal); plus 1e-9 of the scale so that it also bounds cs_mat3_sym_max_eigen's. */
static inline double cs_mat3_sym_max_eigen_bound(const double s[9])
{
    double m;
    const double p = cs_mat3_sym_spread(s, &m);
    return m + 2.0 * p + 1e-9 * (fabs(m) + 2.0 * p);
}

/* The largest eigenvalue of the symmetric s in closed form: the trigonometric solution of its
 * characteristic cubic (s = m I + p B, λmax = m + 2p cos(acos(det B / 2) / 3)).
 * A few flops, one acos and one cos, against a Jacobi eigensolver's sweeps: the fracture
 * pass ranks every cube with it. Accurate to round-off of the largest |eigenvalue| where the
 * two largest eigenvalues are apart, to about 1e-8 of it where they meet (the cubic's double
 * root; test_dense.c). NaN if s is not finite. */
static inline double cs_mat3_sym_max_eigen(const double s[9])
{
    double m;
    const double p = cs_mat3_sym_spread(s, &m);
    if (!(p > 0))
        return p == 0 ? m : NAN; /* hydrostatic, or not finite */
    const double b0 = (s[0] - m) / p, b1 = s[1] / p, b2 = s[2] / p, b4 = (s[4] - m) / p,
                 b5 = s[5] / p, b8 = (s[8] - m) / p;
    double r = 0.5 * (b0 * (b4 * b8 - b5 * b5) - b1 * (b1 * b8 - b5 * b2) +
                      b2 * (b1 * b5 - b4 * b2));
    r = r < -1.0 ? -1.0 : r > 1.0 ? 1.0 : r;
    return m + 2.0 * p * cos(acos(r) / 3.0);
}

/* R(q) for a unit quaternion q = (w, x, y, z), row-major, for any arithmetic type (double,
 * or a vector of them: one lane per quaternion). The one spelling of the map that
 * cs_quat_to_mat, the rotation extraction's lanes, the double product's kernel and the
 * V-cycle's float element pass all use, so they agree in every bit their types allow. */
#define CS_QUAT_TO_MAT(w, x, y, z, R)                                                          \
    do {                                                                                       \
        (R)[0] = 1 - 2 * ((y) * (y) + (z) * (z));                                              \
        (R)[1] = 2 * ((x) * (y) - (w) * (z));                                                  \
        (R)[2] = 2 * ((x) * (z) + (w) * (y));                                                  \
        (R)[3] = 2 * ((x) * (y) + (w) * (z));                                                  \
        (R)[4] = 1 - 2 * ((x) * (x) + (z) * (z));                                              \
        (R)[5] = 2 * ((y) * (z) - (w) * (x));                                                  \
        (R)[6] = 2 * ((x) * (z) - (w) * (y));                                                  \
        (R)[7] = 2 * ((y) * (z) + (w) * (x));                                                  \
        (R)[8] = 1 - 2 * ((x) * (x) + (y) * (y));                                              \
    } while (0)

/* One cyclic Jacobi rotation of the symmetric n×n row-major a (and of the eigenvector
 * columns v, if not NULL) that zeroes a[p][q], given apq = a[p][q] ≠ 0: a ← Jᵀ a J, v ← v J.
 * What the engine's Jacobi eigensolvers (strain_limit.c's 3×3, elastic.c's 24×24 stability
 * bound) do per pair. */
static inline void cs_jacobi_rotate(double *a, double *v, int n, int p, int q, double apq)
{
    const double th = (a[n * q + q] - a[n * p + p]) / (2 * apq);
    const double t = (th >= 0 ? 1.0 : -1.0) / (fabs(th) + sqrt(th * th + 1));
    const double c = 1 / sqrt(t * t + 1), s = t * c;
    for (int k = 0; k < n; k++) { /* a J */
        const double akp = a[n * k + p], akq = a[n * k + q];
        a[n * k + p] = c * akp - s * akq;
        a[n * k + q] = s * akp + c * akq;
    }
    for (int k = 0; k < n; k++) { /* Jᵀ (a J) */
        const double apk = a[n * p + k], aqk = a[n * q + k];
        a[n * p + k] = c * apk - s * aqk;
        a[n * q + k] = s * apk + c * aqk;
    }
    for (int k = 0; v && k < n; k++) {
        const double vkp = v[n * k + p], vkq = v[n * k + q];
        v[n * k + p] = c * vkp - s * vkq;
        v[n * k + q] = s * vkp + c * vkq;
    }
}

#endif
