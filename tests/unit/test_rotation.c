/*
 * test_rotation.c — the corotational rotation extraction (fem.c): Newton's steps near the
 * solution converge quadratically, the batched update gives bit for bit the single-cell
 * extraction (so the energy query sees the step's rotations), and both find the polar
 * rotation of the centre deformation gradient, for stretched, skewed, flat and inverted cells.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubemesh.h"
#include "fem.h"
#include "lattice.h"
#include "mat3.h"

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX;
}

/* Unit quaternion of the rotation by ang about axis. */
static void axis_quat(const double axis[3], double ang, double q[4])
{
    const double n = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    q[0] = cos(ang / 2);
    for (int a = 0; a < 3; a++)
        q[a + 1] = sin(ang / 2) * axis[a] / n;
}

static void quat_mul(const double a[4], const double b[4], double c[4])
{
    c[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    c[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
    c[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
    c[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
}

/* The polar rotation of A (det A > 0) by Higham's iteration X ← (X + X⁻ᵀ)/2. */
static void polar(const double A[9], double R[9])
{
    memcpy(R, A, 9 * sizeof *R);
    for (int it = 0; it < 60; it++) {
        double adj[9];
        const double det = cs_mat3_adjugate(R, adj);
        for (int i = 0; i < 3; i++) /* X⁻ᵀ = adjᵀ / det */
            for (int j = 0; j < 3; j++)
                R[3 * i + j] = 0.5 * (R[3 * i + j] + adj[3 * j + i] / det);
    }
}

/*
 * Warm-started within 0.2 rad of the answer, 6 steps reach the polar rotation to 1e-12: the
 * error squares at each step (Newton). Müller's step alone shrinks it 3× per step, which
 * would leave 0.2/3⁶ ≈ 3e-4.
 */
TEST(fem_rotation_extraction_newton_converges_fast)
{
    unsigned seed = 11;
    for (int trial = 0; trial < 300; trial++) {
        double axis[3], q_true[4], Rt[9], S[9] = {0}, A[9];
        for (int a = 0; a < 3; a++)
            axis[a] = urand(&seed) - 0.5;
        axis_quat(axis, 3.0 * urand(&seed), q_true);
        cs_quat_to_mat(q_true, Rt);
        /* a symmetric stretch: compressed to 0.5, stretched to 1.7, sheared */
        for (int a = 0; a < 3; a++)
            S[4 * a] = 0.5 + 1.2 * urand(&seed);
        S[1] = S[3] = 0.2 * (urand(&seed) - 0.5);
        S[2] = S[6] = 0.2 * (urand(&seed) - 0.5);
        S[5] = S[7] = 0.2 * (urand(&seed) - 0.5);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                A[3 * i + j] = Rt[3 * i] * S[j] + Rt[3 * i + 1] * S[3 + j] +
                               Rt[3 * i + 2] * S[6 + j];
        double Rp[9];
        polar(A, Rp); /* S need not be positive definite after the shear: the true answer */
        double dq[4], q[4], Rx[9];
        for (int a = 0; a < 3; a++)
            axis[a] = urand(&seed) - 0.5;
        axis_quat(axis, 0.2 * urand(&seed), dq);
        quat_mul(dq, q_true, q);
        cs_extract_rotation(A, q, 6);
        cs_quat_to_mat(q, Rx);
        double err = 0;
        for (int i = 0; i < 9; i++)
            err = fmax(err, fabs(Rx[i] - Rp[i]));
        ENSURE_MSG(err < 1e-12, "trial %d: error %g after 6 steps", trial, err);
    }
}

/*
 * From the identity, rotations close to a half turn (where H = tr(M)·I − sym(M) is indefinite
 * and tr M < 0: Müller's steps must carry the iteration until Newton's apply) are found to
 * 1e-9 within the 30 steps the engine allows, stretched or not.
 */
TEST(fem_rotation_extraction_near_half_turn)
{
    const double axes[4][3] = {{0, 0, 1}, {1, 0, 0}, {1, 2, -0.5}, {-0.3, 0.7, 0.2}};
    const double angles[4] = {2.5, 3.0, 3.12, 3.14};
    for (int ax = 0; ax < 4; ax++)
        for (int an = 0; an < 4; an++)
            for (int st = 0; st < 2; st++) {
                double qt[4], Rt[9], A[9], Rp[9], q[4] = {1, 0, 0, 0}, Rx[9];
                axis_quat(axes[ax], angles[an], qt);
                cs_quat_to_mat(qt, Rt);
                const double S[3] = {st ? 1.3 : 1.0, st ? 0.8 : 1.0, 1.0};
                for (int i = 0; i < 3; i++)
                    for (int j = 0; j < 3; j++)
                        A[3 * i + j] = Rt[3 * i + j] * S[j];
                polar(A, Rp);
                cs_extract_rotation(A, q, 30);
                cs_quat_to_mat(q, Rx);
                double err = 0;
                for (int i = 0; i < 9; i++)
                    err = fmax(err, fabs(Rx[i] - Rp[i]));
                ENSURE_MSG(err < 1e-9, "axis %d angle %g stretch %d: error %g", ax, angles[an],
                           st, err);
            }
}

/*
 * cs_fem_update_rotations (4 cells per SIMD lane group, a partial last group) gives bit for
 * bit what cs_extract_rotation gives cell by cell from the same warm start, for a block that
 * is turned by 2.5 rad (from the identity warm start: Müller's big steps with sin/cos) and
 * shaken by ±0.3 h (skewed cells), one cell flattened and one turned inside out; the non-inverted
 * cells' rotations are their polar rotations to 1e-9.
 */
TEST(fem_rotation_batched_update_matches_single_cell)
{
    int32_t *ijk = cs_box_cells(5, 3, 3); /* 45 cells: 11 groups of 4 and one of 1 */
    cs_cubemesh cm;
    char err[256];
    const double h = 0.1, origin[3] = {0, 0, 0};
    ENSURE(ijk && cs_cubemesh_build(&cm, h, origin, ijk, 45, err, sizeof err) == 0);
    free(ijk);
    cs_fem fem;
    ENSURE(cs_fem_init(&fem, &cm, 1e6, 0.3, true, 1) == 0);
    const int n = cm.n_nodes, nc = cm.n_cells;
    double *x = malloc(sizeof(double) * 3 * n);
    ENSURE(x);
    double qr[4], Rr[9];
    axis_quat((double[3]){0.3, -0.8, 0.5}, 2.5, qr);
    cs_quat_to_mat(qr, Rr);
    unsigned seed = 5;
    for (int i = 0; i < n; i++) {
        double p[3];
        for (int a = 0; a < 3; a++)
            p[a] = cm.node_rest[3 * i + a] + 0.3 * h * (2 * urand(&seed) - 1);
        for (int a = 0; a < 3; a++)
            x[3 * i + a] = Rr[3 * a] * p[0] + Rr[3 * a + 1] * p[1] + Rr[3 * a + 2] * p[2];
    }
    /* flatten cell 22 onto its first node's plane along the turned z */
    for (int k = 4; k < 8; k++)
        for (int a = 0; a < 3; a++)
            x[3 * cm.cell_nodes[8 * 22 + k] + a] =
                x[3 * cm.cell_nodes[8 * 22 + k - 4] + a] + 1e-6 * Rr[3 * a + 2];
    /* turn cell 30 (0,0,2: top layer) inside out: its top nodes mirrored through its bottom */
    for (int k = 4; k < 8; k++)
        for (int a = 0; a < 3; a++) {
            double *t = x + 3 * cm.cell_nodes[8 * 30 + k];
            t[a] = 2 * x[3 * cm.cell_nodes[8 * 30 + k - 4] + a] - t[a];
        }
    cs_fem_update_rotations(&fem, x);
    int inverted = 0, checked = 0;
    for (int c = 0; c < nc; c++) {
        /* F at the centre, the sums in centre_gradient's order */
        double F[9] = {0}, q[4] = {1, 0, 0, 0}, R[9];
        static const double SG[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                        {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
        for (int k = 0; k < 8; k++) {
            const double *p = x + 3 * cm.cell_nodes[8 * c + k];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    F[3 * i + j] += p[i] * SG[k][j];
        }
        for (int i = 0; i < 9; i++)
            F[i] /= 4.0 * h;
        cs_extract_rotation(F, q, 30);
        cs_quat_to_mat(q, R);
        ENSURE_MSG(memcmp(q, fem.q + 4 * c, sizeof q) == 0, "cell %d: q differs", c);
        ENSURE_MSG(memcmp(R, fem.R + 9 * c, sizeof R) == 0, "cell %d: R differs", c);
        const double det = F[0] * (F[4] * F[8] - F[5] * F[7]) -
                           F[1] * (F[3] * F[8] - F[5] * F[6]) +
                           F[2] * (F[3] * F[7] - F[4] * F[6]);
        if (det <= 0.05) {
            inverted += det < 0;
            continue;
        }
        double Rp[9];
        polar(F, Rp);
        for (int i = 0; i < 9; i++)
            ENSURE_NEAR(R[i], Rp[i], 1e-9);
        checked++;
    }
    ENSURE_MSG(inverted > 0 && checked > nc / 2, "%d inverted, %d checked of %d", inverted,
               checked, nc);
    free(x);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
}
