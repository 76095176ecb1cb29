/*
 * test_fem.c — the element matrix, corotation and the solver against known answers:
 * seed 000 Appendix A closed-form constants, rigid-body null space, the patch test, rotation
 * extraction, and rigidly rotated corotational blocks.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubemesh.h"
#include "cubesim.h"
#include "fem.h"
#include "solver.h"

/* Cyclic Jacobi eigenvalues of a symmetric n×n matrix (destroys A). */
static void sym_eigenvalues(double *A, int n, double *ev)
{
    for (int sweep = 0; sweep < 100; sweep++) {
        double off = 0;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++)
                off += A[p * n + q] * A[p * n + q];
        if (off < 1e-30)
            break;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++) {
                double apq = A[p * n + q];
                if (fabs(apq) < 1e-300)
                    continue;
                double theta = (A[q * n + q] - A[p * n + p]) / (2 * apq);
                double t = (theta >= 0 ? 1 : -1) / (fabs(theta) + sqrt(theta * theta + 1));
                double c = 1 / sqrt(t * t + 1), s = t * c;
                for (int k = 0; k < n; k++) {
                    double akp = A[k * n + p], akq = A[k * n + q];
                    A[k * n + p] = c * akp - s * akq;
                    A[k * n + q] = s * akp + c * akq;
                }
                for (int k = 0; k < n; k++) {
                    double apk = A[p * n + k], aqk = A[q * n + k];
                    A[p * n + k] = c * apk - s * aqk;
                    A[q * n + k] = s * apk + c * aqk;
                }
            }
    }
    for (int i = 0; i < n; i++)
        ev[i] = A[i * n + i];
}

TEST(fem_stiffness_symmetric_six_zero_modes)
{
    double K[576], A[576], ev[24];
    cs_cube_stiffness(1e6, 0.3, 0.05, K);
    double maxabs = 0;
    for (int i = 0; i < 576; i++)
        maxabs = fmax(maxabs, fabs(K[i]));
    for (int i = 0; i < 24; i++)
        for (int j = 0; j < 24; j++)
            ENSURE_NEAR(K[i * 24 + j], K[j * 24 + i], 1e-12 * maxabs);
    memcpy(A, K, sizeof A);
    sym_eigenvalues(A, 24, ev);
    int zeros = 0, negative = 0;
    double evmax = 0;
    for (int i = 0; i < 24; i++)
        evmax = fmax(evmax, fabs(ev[i]));
    for (int i = 0; i < 24; i++) {
        if (fabs(ev[i]) < 1e-10 * evmax)
            zeros++;
        else if (ev[i] < 0)
            negative++;
    }
    ENSURE_MSG(zeros == 6, "%d zero eigenvalues, expected 6 (rigid modes)", zeros);
    ENSURE(negative == 0);
    /* Full 2×2×2 integration: no spurious hourglass modes, so the smallest non-zero
     * eigenvalue is well away from zero. */
}

/* Seed 000 Appendix A: a = hE(1-ν)/((1+ν)(1-2ν)), b = hEν/((1+ν)(1-2ν)), c = hE/(2(1+ν)). */
TEST(fem_stiffness_matches_appendix_a)
{
    const double E = 2.5e5, nu = 0.27, h = 0.04;
    double K[576];
    cs_cube_stiffness(E, nu, h, K);
    const double a = h * E * (1 - nu) / ((1 + nu) * (1 - 2 * nu));
    const double b = h * E * nu / ((1 + nu) * (1 - 2 * nu));
    const double c = h * E / (2 * (1 + nu));
    const double tol = 1e-12 * a;
#define KB(i, j, r, s) K[(3 * (i) + (r)) * 24 + 3 * (j) + (s)]
    /* Node blocks K_ii: d on the diagonal, ±(b+c)/12 off it. */
    for (int i = 0; i < 8; i++)
        for (int r = 0; r < 3; r++)
            for (int s = 0; s < 3; s++) {
                if (r == s)
                    ENSURE_NEAR(KB(i, i, r, s), (a + 2 * c) / 9, tol);
                else
                    ENSURE_NEAR(fabs(KB(i, i, r, s)), (b + c) / 12, tol);
            }
    /* Edge blocks (x edge 0-1): along-edge entry (c-a)/9, across (a-c)/18. */
    ENSURE_NEAR(KB(0, 1, 0, 0), (-a + c) / 9, tol);
    ENSURE_NEAR(KB(0, 1, 1, 1), (a - c) / 18, tol);
    ENSURE_NEAR(KB(0, 1, 2, 2), (a - c) / 18, tol);
    ENSURE_NEAR(fabs(KB(0, 1, 0, 1)), fabs(b - c) / 12, tol);
    ENSURE_NEAR(fabs(KB(0, 1, 1, 2)), (b + c) / 24, tol);
    /* z edge 0-4 */
    ENSURE_NEAR(KB(0, 4, 2, 2), (-a + c) / 9, tol);
    ENSURE_NEAR(KB(0, 4, 0, 0), (a - c) / 18, tol);
    /* Face diagonal 0-2 (in the xy plane): in-plane (-2a-c)/36, normal (a-4c)/36. */
    ENSURE_NEAR(KB(0, 2, 0, 0), (-2 * a - c) / 36, tol);
    ENSURE_NEAR(KB(0, 2, 1, 1), (-2 * a - c) / 36, tol);
    ENSURE_NEAR(KB(0, 2, 2, 2), (a - 4 * c) / 36, tol);
    ENSURE_NEAR(fabs(KB(0, 2, 0, 1)), (b + c) / 12, tol);
    ENSURE_NEAR(fabs(KB(0, 2, 0, 2)), fabs(b - c) / 24, tol);
    /* Cube diagonal 0-6: (-a-2c)/36 on the diagonal, ±(b+c)/24 off it. */
    for (int r = 0; r < 3; r++)
        for (int s = 0; s < 3; s++) {
            if (r == s)
                ENSURE_NEAR(KB(0, 6, r, s), (-a - 2 * c) / 36, tol);
            else
                ENSURE_NEAR(fabs(KB(0, 6, r, s)), (b + c) / 24, tol);
        }
#undef KB
}

static int build_block(cs_cubemesh *cm, int nx, int ny, int nz, double h)
{
    int n = nx * ny * nz;
    int32_t *ijk = malloc((size_t)n * 3 * sizeof *ijk);
    int c = 0;
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++) {
                ijk[3 * c] = i;
                ijk[3 * c + 1] = j;
                ijk[3 * c + 2] = k;
                c++;
            }
    char err[256];
    double origin[3] = {0.1, -0.2, 0.3};
    int rc = cs_cubemesh_build(cm, h, origin, ijk, n, err, sizeof err);
    free(ijk);
    return rc;
}

static void affine(const double A[9], const double t[3], const double *X, double *x, int n)
{
    for (int i = 0; i < n; i++)
        for (int a = 0; a < 3; a++)
            x[3 * i + a] = t[a] + A[3 * a] * X[3 * i] + A[3 * a + 1] * X[3 * i + 1] +
                           A[3 * a + 2] * X[3 * i + 2];
}

static bool interior(const cs_cubemesh *cm, int node, int nx, int ny, int nz)
{
    const double *p = cm->node_rest + 3 * node;
    int q[3] = {(int)lround((p[0] - cm->origin[0]) / cm->h),
                (int)lround((p[1] - cm->origin[1]) / cm->h),
                (int)lround((p[2] - cm->origin[2]) / cm->h)};
    return q[0] > 0 && q[0] < nx && q[1] > 0 && q[1] < ny && q[2] > 0 && q[2] < nz;
}

/* Patch test: a linear displacement field is reproduced exactly — interior nodes feel no
 * force under it, and solving for the interior with the boundary prescribed recovers it. */
typedef struct {
    cs_fem *fem;
} k_ctx;
static void k_op(void *ctx, const double *p, double *y)
{
    cs_fem_apply_K(((k_ctx *)ctx)->fem, p, y);
}

TEST(fem_patch_test)
{
    cs_cubemesh cm;
    const int nx = 4, ny = 3, nz = 3;
    ENSURE(build_block(&cm, nx, ny, nz, 0.05) == 0);
    cs_fem fem;
    ENSURE(cs_fem_init(&fem, &cm, 1e5, 0.3, false, 2) == 0);
    const int n = cm.n_nodes;
    double *x = malloc(sizeof(double) * 3 * n), *f = malloc(sizeof(double) * 3 * n);
    double *b = calloc(3 * (size_t)n, sizeof(double)), *blk = malloc(sizeof(double) * 9 * n);
    double *u = malloc(sizeof(double) * 3 * n), *uex = malloc(sizeof(double) * 3 * n);
    uint8_t *mask = calloc(3 * (size_t)n, 1);
    const double A[9] = {1.01, 0.003, -0.002, 0.004, 0.995, 0.001, -0.003, 0.002, 1.02};
    const double t[3] = {0.01, -0.02, 0.005};
    affine(A, t, cm.node_rest, x, n);
    cs_fem_elastic_force(&fem, x, f, NULL);
    double fmax_int = 0, fmax_all = 0;
    for (int i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) {
            fmax_all = fmax(fmax_all, fabs(f[3 * i + a]));
            if (interior(&cm, i, nx, ny, nz))
                fmax_int = fmax(fmax_int, fabs(f[3 * i + a]));
        }
    ENSURE(fmax_all > 0);
    ENSURE_MSG(fmax_int < 1e-10 * fmax_all, "interior force %g vs boundary %g", fmax_int, fmax_all);

    /* Solve K u = 0 on the interior with the boundary displacement held. */
    for (int i = 0; i < 3 * n; i++)
        uex[i] = x[i] - cm.node_rest[i];
    for (int i = 0; i < n; i++) {
        bool in = interior(&cm, i, nx, ny, nz);
        for (int a = 0; a < 3; a++) {
            mask[3 * i + a] = !in;
            u[3 * i + a] = in ? 0.0 : uex[3 * i + a];
        }
    }
    /* b = 0 on the free dofs; K u = 0 there with u fixed elsewhere means solving
     * K_ff u_f = -K_fb u_b: write it as b = -K u0, then solve for the correction. */
    cs_fem_apply_K(&fem, u, b);
    for (int i = 0; i < 3 * n; i++)
        b[i] = -b[i];
    double *du = calloc(3 * (size_t)n, sizeof(double));
    cs_fem_diag_blocks(&fem, blk);
    cs_invert_blocks(blk, n);
    cs_cg_work w;
    ENSURE(cs_cg_work_init(&w, 3 * n) == 0);
    k_ctx ctx = {&fem};
    cs_cg_result r = cs_pcg(&w, k_op, &ctx, blk, mask, b, du, 1e-13, 1000, 2);
    ENSURE(r.converged);
    double err = 0, scale = 0;
    for (int i = 0; i < 3 * n; i++) {
        err = fmax(err, fabs(u[i] + du[i] - uex[i]));
        scale = fmax(scale, fabs(uex[i]));
    }
    ENSURE_MSG(err < 1e-9 * scale, "patch test error %g (scale %g)", err, scale);
    cs_cg_work_free(&w);
    free(du);
    free(x);
    free(f);
    free(b);
    free(blk);
    free(u);
    free(uex);
    free(mask);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
}

static void rot_axis_angle(const double axis[3], double ang, double R[9])
{
    double n = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    double q[4] = {cos(ang / 2), sin(ang / 2) * axis[0] / n, sin(ang / 2) * axis[1] / n,
                   sin(ang / 2) * axis[2] / n};
    cs_quat_to_mat(q, R);
}

TEST(fem_rotation_extraction_recovers_rotation)
{
    unsigned seed = 7;
    for (int trial = 0; trial < 200; trial++) {
        double axis[3], R[9], S[9] = {0}, A[9];
        for (int a = 0; a < 3; a++)
            axis[a] = (rand_r(&seed) / (double)RAND_MAX) - 0.5;
        double ang = 3.0 * (rand_r(&seed) / (double)RAND_MAX);
        rot_axis_angle(axis, ang, R);
        /* symmetric positive stretch */
        for (int a = 0; a < 3; a++)
            S[4 * a] = 0.6 + rand_r(&seed) / (double)RAND_MAX;
        S[1] = S[3] = 0.1;
        S[5] = S[7] = -0.05;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                A[3 * i + j] = R[3 * i] * S[j] + R[3 * i + 1] * S[3 + j] + R[3 * i + 2] * S[6 + j];
        double q[4] = {1, 0, 0, 0}, Rx[9];
        cs_extract_rotation(A, q, 100);
        cs_quat_to_mat(q, Rx);
        for (int i = 0; i < 9; i++)
            ENSURE_NEAR(Rx[i], R[i], 1e-7);
    }
}

TEST(fem_corotational_rigid_rotation_feels_no_force)
{
    cs_cubemesh cm;
    ENSURE(build_block(&cm, 3, 2, 4, 0.1) == 0);
    cs_fem cor, lin;
    ENSURE(cs_fem_init(&cor, &cm, 1e6, 0.35, true, 2) == 0);
    ENSURE(cs_fem_init(&lin, &cm, 1e6, 0.35, false, 2) == 0);
    const int n = cm.n_nodes;
    double *x = malloc(sizeof(double) * 3 * n), *f = malloc(sizeof(double) * 3 * n);
    const double axes[3][3] = {{1, 2, 3}, {0, 0, 1}, {-1, 0.5, 0.2}};
    const double angles[3] = {0.7, M_PI / 2, 2.9};
    for (int t = 0; t < 3; t++) {
        double R[9], e_cor = 1, e_lin = 0;
        rot_axis_angle(axes[t], angles[t], R);
        const double tr[3] = {1.5, -3.0, 0.25};
        affine(R, tr, cm.node_rest, x, n);
        cs_fem_update_rotations(&cor, x);
        cs_fem_elastic_force(&cor, x, f, &e_cor);
        double fm = 0;
        for (int i = 0; i < 3 * n; i++)
            fm = fmax(fm, fabs(f[i]));
        /* Force scale of a 1 % strain: E h² · 0.01 */
        const double scale = 1e6 * 0.01 * 0.01;
        ENSURE_MSG(fm < 1e-9 * scale, "rotation %d: corotational force %g", t, fm);
        ENSURE_NEAR(e_cor, 0.0, 1e-12);
        /* The linear model does not have this property: it is what corotation is for. */
        cs_fem_elastic_force(&lin, x, f, &e_lin);
        ENSURE(e_lin > 1.0);
    }
    free(x);
    free(f);
    cs_fem_free(&cor);
    cs_fem_free(&lin);
    cs_cubemesh_free(&cm);
}

/* Stretched and rotated: corotated forces equal the rotated linear forces of the stretch. */
TEST(fem_corotational_force_is_rotated_linear_force)
{
    cs_cubemesh cm;
    ENSURE(build_block(&cm, 2, 2, 2, 0.1) == 0);
    cs_fem cor, lin;
    ENSURE(cs_fem_init(&cor, &cm, 1e6, 0.3, true, 1) == 0);
    ENSURE(cs_fem_init(&lin, &cm, 1e6, 0.3, false, 1) == 0);
    const int n = cm.n_nodes;
    double *xs = malloc(sizeof(double) * 3 * n), *xr = malloc(sizeof(double) * 3 * n);
    double *fs = malloc(sizeof(double) * 3 * n), *fr = malloc(sizeof(double) * 3 * n);
    const double S[9] = {1.02, 0, 0, 0, 0.99, 0, 0, 0, 1.01}, t0[3] = {0, 0, 0};
    affine(S, t0, cm.node_rest, xs, n);
    double R[9];
    rot_axis_angle((double[3]){0.3, -1, 0.4}, 1.1, R);
    affine(R, t0, xs, xr, n);
    cs_fem_elastic_force(&lin, xs, fs, NULL);
    cs_fem_update_rotations(&cor, xr);
    cs_fem_elastic_force(&cor, xr, fr, NULL);
    double fm = 0;
    for (int i = 0; i < 3 * n; i++)
        fm = fmax(fm, fabs(fs[i]));
    for (int i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) {
            double rf = R[3 * a] * fs[3 * i] + R[3 * a + 1] * fs[3 * i + 1] +
                        R[3 * a + 2] * fs[3 * i + 2];
            ENSURE_NEAR(fr[3 * i + a], rf, 1e-8 * fm);
        }
    free(xs);
    free(xr);
    free(fs);
    free(fr);
    cs_fem_free(&cor);
    cs_fem_free(&lin);
    cs_cubemesh_free(&cm);
}

TEST(fem_products_independent_of_thread_count)
{
    cs_cubemesh cm;
    ENSURE(build_block(&cm, 16, 12, 11, 0.1) == 0);
    ENSURE(cm.n_cells >= CS_FEM_PARALLEL_CELLS); /* so that two threads really run */
    cs_fem f1, f2;
    ENSURE(cs_fem_init(&f1, &cm, 1e6, 0.3, true, 1) == 0);
    ENSURE(cs_fem_init(&f2, &cm, 1e6, 0.3, true, 2) == 0);
    ENSURE(f2.threads == 2);
    const int n = cm.n_nodes;
    double *x = malloc(sizeof(double) * 3 * n), *a = malloc(sizeof(double) * 3 * n),
           *b = malloc(sizeof(double) * 3 * n);
    unsigned seed = 3;
    for (int i = 0; i < 3 * n; i++)
        x[i] = cm.node_rest[i] + 0.01 * (rand_r(&seed) / (double)RAND_MAX - 0.5);
    cs_fem_update_rotations(&f1, x);
    cs_fem_update_rotations(&f2, x);
    cs_fem_elastic_force(&f1, x, a, NULL);
    cs_fem_elastic_force(&f2, x, b, NULL);
    ENSURE(memcmp(a, b, sizeof(double) * 3 * n) == 0);
    cs_fem_apply_K(&f1, x, a);
    cs_fem_apply_K(&f2, x, b);
    ENSURE(memcmp(a, b, sizeof(double) * 3 * n) == 0);
    /* the energy (Newmark's guard, status messages): summed in fixed blocks, in order */
    const double e1 = cs_fem_energy(&f1, x), e2 = cs_fem_energy(&f2, x);
    ENSURE(e1 > 0 && memcmp(&e1, &e2, sizeof e1) == 0);
    free(x);
    free(a);
    free(b);
    cs_fem_free(&f1);
    cs_fem_free(&f2);
    cs_cubemesh_free(&cm);
}

/* ------------------------------------------------------------------ the modal element kernel */

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX - 0.5;
}

/* y = Σ_c R_c K_c R_cᵀ p with the dense 24×24 matrices: K_c = f K (uniform factors) or
 * Σ_g kf_g K_g (graded), R_c = fem->R. */
static void dense_apply(const cs_fem *fem, const double *kf, const double *p, double *y)
{
    memset(y, 0, sizeof(double) * 3 * fem->n_nodes);
    for (int c = 0; c < fem->n_cells; c++) {
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        double Ke[576], u[24], ku[24];
        for (int i = 0; i < 576; i++) {
            if (!kf) {
                Ke[i] = fem->K[i];
                continue;
            }
            Ke[i] = 0;
            for (int g = 0; g < 8; g++)
                Ke[i] += kf[8 * c + g] * fem->Kg[576 * g + i];
        }
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++) {
                const double *d = p + 3 * nd[k];
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
            }
        for (int i = 0; i < 24; i++) {
            ku[i] = 0;
            for (int j = 0; j < 24; j++)
                ku[i] += Ke[24 * i + j] * u[j];
        }
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++)
                y[3 * nd[k] + i] += R[3 * i] * ku[3 * k] + R[3 * i + 1] * ku[3 * k + 1] +
                                    R[3 * i + 2] * ku[3 * k + 2];
    }
}

static double max_abs(const double *v, int n)
{
    double m = 0;
    for (int i = 0; i < n; i++)
        m = fmax(m, fabs(v[i]));
    return m;
}

/* The modal (Walsh–Hadamard) product equals the dense K product to roundoff, for several
 * edges and materials, linear and rotated, plain, with equal factors per cell and graded. */
TEST(fem_modal_product_matches_dense_K)
{
    const double hs[3] = {0.1, 1.0, 0.0137}, Es[3] = {1e6, 3.5e4, 2e9},
                 nus[3] = {0.3, 0.0, 0.49};
    unsigned seed = 11;
    for (int t = 0; t < 3; t++)
        for (int corot = 0; corot < 2; corot++)
            for (int field = 0; field < 3; field++) {
                cs_cubemesh cm;
                ENSURE(build_block(&cm, 3, 3, 1 + t, hs[t]) == 0); /* 9, 18, 27 cells */
                cs_fem fem;
                ENSURE(cs_fem_init(&fem, &cm, Es[t], nus[t], corot, 1) == 0);
                const int n = cm.n_nodes;
                double *x = malloc(sizeof(double) * 3 * n), *p = malloc(sizeof(double) * 3 * n),
                       *a = malloc(sizeof(double) * 3 * n), *b = malloc(sizeof(double) * 3 * n),
                       *kf = malloc(sizeof(double) * 8 * cm.n_cells);
                for (int i = 0; i < 3 * n; i++) {
                    x[i] = cm.node_rest[i] + 0.3 * hs[t] * urand(&seed);
                    p[i] = urand(&seed);
                }
                for (int c = 0; c < cm.n_cells; c++)
                    for (int g = 0; g < 8; g++)
                        /* field 1: equal per cell; field 2: every third cell graded */
                        kf[8 * c + g] = field == 1 || c % 3 ? 0.5 + c % 4 : 0.2 + 0.3 * g;
                fem.kf = field ? kf : NULL;
                cs_fem_update_rotations(&fem, x);
                cs_fem_apply_K(&fem, p, a);
                dense_apply(&fem, fem.kf, p, b);
                const double m = max_abs(b, 3 * n);
                for (int i = 0; i < 3 * n; i++)
                    ENSURE_MSG(fabs(a[i] - b[i]) <= 1e-13 * m,
                               "h %g corot %d field %d dof %d: %.17g vs %.17g", hs[t], corot,
                               field, i, a[i], b[i]);
                if (field == 0) {
                    const double per = corot ? 398.0 : 188.0;
                    ENSURE_NEAR(cs_fem_product_flops(&fem),
                                cm.n_cells * (per + 24.0) + 3.0 * n, 1e-9);
                }
                free(x);
                free(p);
                free(a);
                free(b);
                free(kf);
                cs_fem_free(&fem);
                cs_cubemesh_free(&cm);
            }
}

/* Forces and energies agree: the linear model's force is minus the gradient of its energy
 * (central differences), with and without graded factors; the energy returned with the force
 * equals cs_fem_energy, also for rotated cells; and the tangent's warped part (no stress) is
 * the dense R K Rᵀ. */
TEST(fem_modal_force_energy_consistent)
{
    unsigned seed = 5;
    for (int field = 0; field < 2; field++)
        for (int corot = 0; corot < 2; corot++) {
            cs_cubemesh cm;
            ENSURE(build_block(&cm, 3, 2, 2, 0.2) == 0); /* 12 cells: 3 full batches */
            cs_fem fem;
            ENSURE(cs_fem_init(&fem, &cm, 1e5, 0.35, corot, 1) == 0);
            const int n = cm.n_nodes;
            double *x = malloc(sizeof(double) * 3 * n), *f = malloc(sizeof(double) * 3 * n),
                   *kf = malloc(sizeof(double) * 8 * cm.n_cells);
            for (int i = 0; i < 3 * n; i++)
                x[i] = cm.node_rest[i] + 0.02 * urand(&seed);
            for (int c = 0; c < cm.n_cells; c++)
                for (int g = 0; g < 8; g++)
                    kf[8 * c + g] = c % 2 ? 2.0 : 1.0 + 0.1 * g;
            fem.kf = field ? kf : NULL;
            cs_fem_update_rotations(&fem, x);
            double e;
            cs_fem_elastic_force(&fem, x, f, &e);
            ENSURE(e > 0);
            /* rotated: cs_fem_energy re-extracts R (converged to ~1e-9) */
            ENSURE_NEAR(e, cs_fem_energy(&fem, x), (corot ? 1e-9 : 1e-13) * e);
            if (!corot) {
                const double fm = max_abs(f, 3 * n), d = 1e-6;
                for (int i = 0; i < 3 * n; i++) {
                    const double xi = x[i];
                    x[i] = xi + d;
                    const double ep = cs_fem_energy(&fem, x);
                    x[i] = xi - d;
                    const double em = cs_fem_energy(&fem, x);
                    x[i] = xi;
                    ENSURE_NEAR(f[i], -(ep - em) / (2 * d), 1e-6 * fm);
                }
            } else {
                /* at rest shape, rotated: no stress, so the tangent is R K Rᵀ */
                double R[9], *p = malloc(sizeof(double) * 3 * n),
                             *a = malloc(sizeof(double) * 3 * n),
                             *b = malloc(sizeof(double) * 3 * n);
                rot_axis_angle((double[3]){1, 2, -0.5}, 0.7, R);
                affine(R, (double[3]){0.1, 0, 0.3}, cm.node_rest, x, n);
                for (int i = 0; i < 3 * n; i++)
                    p[i] = urand(&seed);
                cs_fem_update_rotations(&fem, x);
                ENSURE(cs_fem_prepare_tangent(&fem, x) == 0);
                cs_fem_apply_tangent(&fem, p, a);
                cs_fem_release_tangent(&fem);
                dense_apply(&fem, fem.kf, p, b);
                const double m = max_abs(b, 3 * n);
                for (int i = 0; i < 3 * n; i++)
                    ENSURE_NEAR(a[i], b[i], 1e-9 * m);
                free(p);
                free(a);
                free(b);
            }
            free(x);
            free(f);
            free(kf);
            cs_fem_free(&fem);
            cs_cubemesh_free(&cm);
        }
}

/* Multigrid's coarse-level kernel: cs_cube_lame_h recovers hλ, hμ from K, and
 * cs_cube_cells_product equals s R K Rᵀ with the dense K(2h) = 2 K(h). */
TEST(fem_cells_product_matches_dense)
{
    cs_cubemesh cm;
    ENSURE(build_block(&cm, 3, 2, 1, 0.4) == 0); /* 6 cells: a partial batch */
    cs_fem fem;
    ENSURE(cs_fem_init(&fem, &cm, 2e5, 0.25, true, 1) == 0);
    double hl, hm;
    cs_cube_lame_h(fem.K, &hl, &hm);
    ENSURE_NEAR(hl, 0.4 * fem.lambda, 1e-13 * fem.lambda);
    ENSURE_NEAR(hm, 0.4 * fem.mu, 1e-13 * fem.mu);
    const int n = cm.n_nodes;
    unsigned seed = 7;
    double *x = malloc(sizeof(double) * 3 * n), *p = malloc(sizeof(double) * 3 * n),
           *b = malloc(sizeof(double) * 3 * n), *fe = malloc(sizeof(double) * 24 * cm.n_cells),
           *s = malloc(sizeof(double) * cm.n_cells), K2[576];
    for (int i = 0; i < 3 * n; i++) {
        x[i] = cm.node_rest[i] + 0.1 * urand(&seed);
        p[i] = urand(&seed);
    }
    cs_fem_update_rotations(&fem, x);
    for (int c = 0; c < cm.n_cells; c++)
        s[c] = 1.0 + c;
    cs_cube_stiffness(2e5, 0.25, 0.8, K2);
    cs_cube_cells_product(fem.K, cm.n_cells, cm.cell_nodes, fem.R, s, p, fe, 1);
    for (int c = 0; c < cm.n_cells; c++) {
        /* the dense product of this one cell with K(2h) = 2 K(h): s_c/2 · R K(2h) Rᵀ p */
        const int32_t *nd = cm.cell_nodes + 8 * c;
        const double *R = fem.R + 9 * c;
        double u[24], ku[24];
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++) {
                const double *d = p + 3 * nd[k];
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
            }
        for (int i = 0; i < 24; i++) {
            ku[i] = 0;
            for (int j = 0; j < 24; j++)
                ku[i] += 0.5 * s[c] * K2[24 * i + j] * u[j];
        }
        double m = 0;
        for (int i = 0; i < 24; i++)
            m = fmax(m, fabs(ku[i]));
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++)
                ENSURE_NEAR(fe[24 * c + 3 * k + i],
                            R[3 * i] * ku[3 * k] + R[3 * i + 1] * ku[3 * k + 1] +
                                R[3 * i + 2] * ku[3 * k + 2],
                            1e-13 * m);
    }
    free(x);
    free(p);
    free(b);
    free(fe);
    free(s);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
}
