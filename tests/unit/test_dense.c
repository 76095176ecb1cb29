/*
 * test_dense.c — the small dense kernels against known answers: the closed-form largest
 * eigenvalue of a symmetric 3×3 (the fracture pass ranks cubes by it) on matrices of known
 * spectrum, and the dense Cholesky's solves, its forward solve from a row on, and the
 * interleaved short dot product (a held object's exact contact response).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "band.h"
#include "check.h"
#include "mat3.h"
#include "solver.h"

/* A fixed-seed generator: the same matrices on every run. */
static double unit_rand(uint64_t *s)
{
    *s = *s * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double)(*s >> 11) / 9007199254740992.0; /* [0, 1) */
}

/* Q diag(l) Qᵀ for the rotation of the unit quaternion q (row-major). */
static void rotated_diagonal(const double q_in[4], const double l[3], double s[9])
{
    double n = sqrt(q_in[0] * q_in[0] + q_in[1] * q_in[1] + q_in[2] * q_in[2] + q_in[3] * q_in[3]);
    const double w = q_in[0] / n, x = q_in[1] / n, y = q_in[2] / n, z = q_in[3] / n;
    const double Q[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                         2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                         2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double t = 0;
            for (int k = 0; k < 3; k++)
                t += Q[3 * i + k] * l[k] * Q[3 * j + k];
            s[3 * i + j] = t;
        }
    for (int i = 0; i < 3; i++) /* symmetric to the bit, as the fracture pass's stresses are */
        for (int j = i + 1; j < 3; j++)
            s[3 * j + i] = s[3 * i + j];
}

TEST(dense_sym_max_eigen_matches_known_spectra)
{
    uint64_t seed = 7;
    double worst = 0;
    int exact_cases = 0;
    /* spectra: distinct, two equal (either pair), three equal, a zero matrix, signs mixed,
     * one eigenvalue far below the others, and scales from 1e-12 to 1e12 */
    const double fixed[][3] = {{3, 2, 1},      {5, 5, -1},   {-1, 4, 4},     {2, 2, 2},
                               {0, 0, 0},      {-3, -7, -5}, {1, 1e-9, -1},  {1e6, 1, 0},
                               {-2, -2, -2.5}, {0, 0, 1e-3}, {7, 7, 7 + 1e-7}, {3, 0, 0},
                               {-2, -5, -5}};
    for (int t = 0; t < 2000; t++) {
        double l[3];
        if (t < (int)(sizeof fixed / sizeof fixed[0]))
            memcpy(l, fixed[t], sizeof l);
        else
            for (int k = 0; k < 3; k++)
                l[k] = 2 * unit_rand(&seed) - 1;
        const double scale = pow(10.0, -12 + 24 * ((t * 37) % 25) / 24.0);
        for (int k = 0; k < 3; k++)
            l[k] *= scale;
        const double q[4] = {unit_rand(&seed) - 0.5, unit_rand(&seed) - 0.5,
                             unit_rand(&seed) - 0.5, unit_rand(&seed) - 0.5};
        double s[9];
        rotated_diagonal(q, l, s);
        const double lmax = fmax(l[0], fmax(l[1], l[2]));
        const double big = fmax(fabs(l[0]), fmax(fabs(l[1]), fabs(l[2])));
        /* the cubic's roots lose half the digits where the top two meet (acos near 0):
         * there 1e-8, elsewhere round-off (the fracture pass's ranking is as exact as
         * the stresses in it, and the stress an event reports is the eigensolver's) */
        const double lmid = l[0] + l[1] + l[2] - lmax - fmin(l[0], fmin(l[1], l[2]));
        const double tol = (lmax - lmid < 1e-6 * big ? 2e-8 : 1e-12) * big + 1e-300;
        const double err = fabs(cs_mat3_sym_max_eigen(s) - lmax);
        worst = fmax(worst, lmax - lmid < 1e-6 * big ? 0 : err / big);
        ENSURE_MSG(err <= tol, "spectrum %g %g %g: got %.17g", l[0], l[1], l[2],
                   cs_mat3_sym_max_eigen(s));
        /* the bound that spares the closed form: above it, at most twice as far from the
         * mean (the top two equal) */
        const double bnd = cs_mat3_sym_max_eigen_bound(s), mean = (l[0] + l[1] + l[2]) / 3;
        ENSURE_MSG(bnd >= cs_mat3_sym_max_eigen(s) && bnd >= lmax &&
                       bnd - mean <= 2.0 * (lmax - mean) + 1e-8 * big + 1e-300,
                   "spectrum %g %g %g: bound %.17g", l[0], l[1], l[2], bnd);
        if (fabs(l[1] - l[2]) <= 1e-15 * big && l[0] >= l[1]) /* the other two equal */
        {
            ENSURE_NEAR(bnd, lmax, 3e-9 * big + 1e-300); /* (its 1e-9 margin) */
            exact_cases++;
        }
    }
    printf("    distinct top eigenvalues: largest error %.2g of the largest |eigenvalue|\n", worst);
    ENSURE(exact_cases >= 3); /* uniaxial (two shapes) and hydrostatic were checked */
    /* a diagonal matrix as it is (no rotation's rounding) and one in a non-finite state */
    const double d[9] = {-4, 0, 0, 0, 9, 0, 0, 0, 1};
    ENSURE(cs_mat3_sym_max_eigen(d) == 9.0 || fabs(cs_mat3_sym_max_eigen(d) - 9.0) < 1e-14);
    const double bad[9] = {1, NAN, 0, NAN, 1, 0, 0, 0, 1};
    ENSURE(isnan(cs_mat3_sym_max_eigen(bad))); /* "> strength" is then false: no fracture */
    const double inf[9] = {INFINITY, 0, 0, 0, 1, 0, 0, 0, 1};
    ENSURE(!(cs_mat3_sym_max_eigen(inf) < 1e300));
}

TEST(dense_cholesky_solves_and_inverse_entries_by_forward_solves)
{
    enum { N = 41 };
    uint64_t seed = 11;
    static double B[N * N], A[N * N], L[N * N];
    for (int i = 0; i < N * N; i++)
        B[i] = unit_rand(&seed) - 0.5;
    for (int i = 0; i < N; i++) /* A = B Bᵀ + I: SPD, condition about 10² */
        for (int j = 0; j < N; j++) {
            double t = i == j ? 1.0 : 0.0;
            for (int k = 0; k < N; k++)
                t += B[i * N + k] * B[j * N + k];
            A[i * N + j] = t;
        }
    memcpy(L, A, sizeof L);
    ENSURE(cs_cholesky(L, N) == 0);
    /* L Lᵀ = A */
    for (int i = 0; i < N; i++)
        for (int j = 0; j <= i; j++) {
            double t = 0;
            for (int k = 0; k <= j; k++)
                t += L[i * N + k] * L[j * N + k];
            ENSURE_NEAR(t, A[i * N + j], 1e-12 * A[i * N + i]);
        }
    /* A x = b for a known x */
    double x[N], b[N];
    for (int i = 0; i < N; i++)
        x[i] = sin(1.0 + i);
    for (int i = 0; i < N; i++)
        b[i] = cs_dot_short(A + i * N, x, 0, N);
    cs_cholesky_solve(L, N, b);
    for (int i = 0; i < N; i++)
        ENSURE_NEAR(b[i], x[i], 1e-11);
    /* (A⁻¹)_pq = (L⁻¹e_p)·(L⁻¹e_q), the forward solves started at p and q */
    static double Y[N * N];
    for (int p = 0; p < N; p++) {
        double *y = Y + p * N;
        memset(y, 0, N * sizeof *y);
        y[p] = 1;
        cs_cholesky_forward(L, N, p, y);
        for (int i = 0; i < p; i++)
            ENSURE(y[i] == 0.0);
    }
    for (int q = 0; q < N; q += 5) {
        double col[N];
        memset(col, 0, sizeof col);
        col[q] = 1;
        cs_cholesky_solve(L, N, col); /* column q of A⁻¹ */
        for (int p = 0; p < N; p++) {
            const double s = cs_dot_short(Y + p * N, Y + q * N, p > q ? p : q, N);
            ENSURE_NEAR(s, col[p], 1e-12 * fabs(col[q]));
        }
    }
    /* not positive definite: refused */
    double M[4] = {1, 2, 2, 1};
    ENSURE(cs_cholesky(M, 2) == -1);
}

TEST(dense_short_dot_every_tail_length)
{
    double a[13], b[13];
    for (int i = 0; i < 13; i++) {
        a[i] = i + 1;
        b[i] = 2 * i - 5;
    }
    for (int lo = 0; lo < 5; lo++)
        for (int hi = lo; hi <= 13; hi++) {
            double ref = 0; /* integers: every order gives the same sum */
            for (int i = lo; i < hi; i++)
                ref += a[i] * b[i];
            ENSURE_MSG(cs_dot_short(a, b, lo, hi) == ref, "lo %d hi %d", lo, hi);
        }
}

/* The band Cholesky (band.h) against the dense one on a random SPD band matrix (diagonally
 * dominant, n = 157, half-bandwidth 9, three right-hand sides side by side); a matrix that is
 * not positive definite is refused. */
TEST(band_cholesky_matches_dense)
{
    const int n = 157, b = 9;
    cs_band m;
    ENSURE(cs_band_init(&m, n, b) == 0);
    double *D = calloc((size_t)n * n, sizeof *D), *x = malloc(sizeof(double) * 3 * n),
           *xd = malloc(sizeof(double) * n);
    ENSURE(D && x && xd);
    unsigned seed = 4;
    for (int i = 0; i < n; i++)
        for (int j = i - b > 0 ? i - b : 0; j < i; j++) {
            const double v = rand_r(&seed) / (double)RAND_MAX - 0.5;
            *cs_band_at(&m, i, j) = v;
            D[(size_t)n * i + j] = D[(size_t)n * j + i] = v;
        }
    for (int i = 0; i < n; i++) {
        double s = 1.0;
        for (int j = 0; j < n; j++)
            s += fabs(D[(size_t)n * i + j]);
        *cs_band_at(&m, i, i) = s;
        D[(size_t)n * i + i] = s;
    }
    for (int i = 0; i < 3 * n; i++)
        x[i] = sin(0.1 * i) + 0.3;
    ENSURE(cs_band_cholesky(&m) == 0);
    cs_band_solve3(&m, x);
    ENSURE(cs_cholesky(D, n) == 0);
    for (int k = 0; k < 3; k++) {
        for (int i = 0; i < n; i++)
            xd[i] = sin(0.1 * (3 * i + k)) + 0.3;
        cs_cholesky_solve(D, n, xd);
        for (int i = 0; i < n; i++)
            ENSURE_MSG(fabs(x[3 * i + k] - xd[i]) <= 1e-12 * (1 + fabs(xd[i])), "rhs %d row %d",
                       k, i);
    }
    /* indefinite: a negative pivot */
    memset(m.a, 0, sizeof(double) * (size_t)n * (b + 1));
    for (int i = 0; i < n; i++)
        *cs_band_at(&m, i, i) = i == 80 ? -1.0 : 2.0;
    ENSURE(cs_band_cholesky(&m) == -1);
    cs_band_free(&m);
    free(D);
    free(x);
    free(xd);
}
