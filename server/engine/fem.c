/*
 * fem.c — seed 000 §2.2 (warped stiffness / corotation) and Appendix A (cube stiffness).
 *
 * The element matrix is computed, not transcribed: Appendix A's sub-matrices are garbled in
 * our copy of the paper, so K comes from 2×2×2 Gauss quadrature of the trilinear shape
 * functions (exact for a cube); tests/unit/test_fem.c checks it against the closed-form
 * constants that survived (a, b, c and the diagonal-block entries).
 */
#include "fem.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <immintrin.h>
#include <omp.h>

#include "cubesim.h"
#include "mat3.h"
#include "rowbatch.h"
#include "segments.h"
#include "simd.h"
#include "solver.h"

/* Sign pattern (2·corner − 1) of each corner: the gradient directions of the shape functions. */
static const double SGN[8][3] = {
    {-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
    {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1},
};

/* K += the Gauss point gp term of the cube's stiffness. */
static void gauss_term(double young, double poisson, double h, int gp, double K[24 * 24])
{
    const double lambda = young * poisson / ((1 + poisson) * (1 - 2 * poisson));
    const double mu = young / (2 * (1 + poisson));
    const double g = 1.0 / sqrt(3.0);
    const double detj = h * h * h / 8.0;
    {
        const double xi[3] = {SGN[gp][0] * g, SGN[gp][1] * g, SGN[gp][2] * g};
        double grad[8][3];
        for (int k = 0; k < 8; k++) {
            double f[3];
            for (int a = 0; a < 3; a++)
                f[a] = 1 + SGN[k][a] * xi[a];
            /* dφ/dx = (2/h)·∂φ/∂ξ, φ = ⅛ Π (1 + s ξ) */
            grad[k][0] = SGN[k][0] * f[1] * f[2] / 8.0 * (2.0 / h);
            grad[k][1] = SGN[k][1] * f[0] * f[2] / 8.0 * (2.0 / h);
            grad[k][2] = SGN[k][2] * f[0] * f[1] / 8.0 * (2.0 / h);
        }
        for (int a = 0; a < 8; a++)
            for (int b = 0; b < 8; b++) {
                const double dot = grad[a][0] * grad[b][0] + grad[a][1] * grad[b][1] +
                                   grad[a][2] * grad[b][2];
                for (int i = 0; i < 3; i++)
                    for (int j = 0; j < 3; j++) {
                        double v = lambda * grad[a][i] * grad[b][j] +
                                   mu * grad[a][j] * grad[b][i] + (i == j ? mu * dot : 0.0);
                        K[(3 * a + i) * 24 + 3 * b + j] += v * detj;
                    }
            }
    }
}

void cs_cube_stiffness(double young, double poisson, double h, double K[24 * 24])
{
    memset(K, 0, sizeof(double) * 576);
    for (int gp = 0; gp < 8; gp++)
        gauss_term(young, poisson, h, gp, K);
}

void cs_cube_stiffness_gauss(double young, double poisson, double h, int g, double K[24 * 24])
{
    memset(K, 0, sizeof(double) * 576);
    gauss_term(young, poisson, h, g, K);
}

void cs_quat_to_mat(const double q[4], double R[9])
{
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    CS_QUAT_TO_MAT(w, x, y, z, R);
}

/* ------------------------------------------------------------------ rotation extraction
 *
 * Müller et al. (2016): the rotation R(q) of A is where ω = Σ_c r_c × a_c (r_c, a_c the
 * columns of R and A) vanishes, i.e. where M = A Rᵀ is symmetric; their iteration rotates q by
 * ω / |tr M| (left-multiplied: world frame) until it does. Near the solution that step is 2/3
 * of the way (M ≈ I: ω = 2θ, tr M = 3), so the error shrinks only 3× per iteration and a
 * warm-started cell took 12–15 iterations to stop at |ω| < 1e-9. Linearizing ω(R) instead: a
 * world-frame turn by θ changes M to M(I − [θ]×), and ω by −H θ with H = tr(M)·I − sym(M), so
 * θ = H⁻¹ ω is Newton's step (the Hessian of tr(RᵀA) on the rotations; it is positive definite
 * exactly near its maximum, where the polar rotation lies). We take the Newton step while H is
 * clearly positive definite and the step is small (< 0.3 rad), Müller's step otherwise: far
 * from the solution (big rotations from a stale warm start, flat or inverted cells with a
 * singular H) the iteration is Müller's, robust as before, and near it the error squares at
 * each step. Stopping: before a step, at |ω| < 1e-12 (converged); after a Müller step of
 * |ω| < 1e-9 (as before); after a Newton step of |ω| < 1e-6 (the error left is of order
 * |ω|², far below what the old rule left, about |ω|/2 = 5e-10). On the 32³ block sagging
 * under gravity a step's extraction now takes 2 iterations per cell (15 before), and the
 * rotations are within 1e-12 of the polar rotation (5e-10 before).
 *
 * The same code runs for 1 cell (cs_extract_rotation) or ROT_LANES cells side by side
 * (cs_fem_update_rotations), one per SIMD lane: every lane does the same operations on its own
 * data, and a lane that has stopped keeps its q, so a cell's rotation does not depend on its
 * lane, its batch or the thread count, and the energy's extraction (cs_fem_energy, one cell
 * at a time) gives bit for bit the rotations of the step.
 */
#define ROT_LANES 4
typedef double rv __attribute__((vector_size(8 * ROT_LANES)));
typedef long long rm __attribute__((vector_size(8 * ROT_LANES))); /* lane masks: 0 or -1 */

#define ROT_NEWTON_MAX2 0.09  /* Newton steps up to 0.3 rad (the first-order update's range) */
#define ROT_NEWTON_STOP2 1e-12 /* stop after a Newton step below 1e-6 */
#define ROT_MULLER_STOP2 1e-18 /* stop after a Müller step below 1e-9 */
#define ROT_DONE2 1e-24        /* converged: no step below 1e-12 */

/* per lane: m ? a : b (a macro: functions passing 32-byte vectors trip -Wpsabi) */
#define rsel(m, a, b) ((rv)(((rm)(a) & (m)) | ((rm)(b) & ~(m))))

static inline bool rany(rm m)
{
    for (int l = 0; l < ROT_LANES; l++)
        if (m[l])
            return true;
    return false;
}

/* R = R(q) for unit quaternions q = (w, x, y, z), row-major, per lane. */
static inline __attribute__((always_inline)) void rot_quat_mat(const rv q[4], rv R[9])
{
    const rv w = q[0], x = q[1], y = q[2], z = q[3];
    CS_QUAT_TO_MAT(w, x, y, z, R);
}

/*
 * The extraction for the lanes in `live` (others untouched): A[j] is entry j of each lane's
 * matrix, q its warm start, updated. At most max_iter steps per lane.
 */
static inline __attribute__((always_inline)) void rot_extract(const rv A[9], rv q[4], rm live,
                                                               int max_iter)
{
    rm run = live;
    for (int it = 0; it < max_iter && rany(run); it++) {
        rv R[9], M[9];
        rot_quat_mat(q, R);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                M[3 * i + j] = A[3 * i] * R[3 * j] + A[3 * i + 1] * R[3 * j + 1] +
                               A[3 * i + 2] * R[3 * j + 2];
        const rv g0 = M[7] - M[5], g1 = M[2] - M[6], g2 = M[3] - M[1];
        const rv tr = M[0] + M[4] + M[8];
        /* Newton: H = tr·I − sym(M), θ = H⁻¹ ω by the adjugate */
        const rv h00 = M[4] + M[8], h11 = M[0] + M[8], h22 = M[0] + M[4];
        const rv h01 = -0.5 * (M[1] + M[3]), h02 = -0.5 * (M[2] + M[6]),
                 h12 = -0.5 * (M[5] + M[7]);
        const rv c00 = h11 * h22 - h12 * h12, c11 = h00 * h22 - h02 * h02,
                 c22 = h00 * h11 - h01 * h01;
        const rv c01 = h02 * h12 - h01 * h22, c02 = h01 * h12 - h02 * h11,
                 c12 = h01 * h02 - h00 * h12;
        const rv det = h00 * c00 + h01 * c01 + h02 * c02;
        const rv sc = rsel((rm)(h00 < 0), -h00, h00) + rsel((rm)(h11 < 0), -h11, h11) +
                      rsel((rm)(h22 < 0), -h22, h22);
        /* clearly positive definite: leading minors > 0, det above 1e-6 of its scale (the
         * scale is positive: far from the solution tr M can be negative) */
        const rm pd = (rm)(h00 > 0) & (rm)(c22 > 0) & (rm)(det > 1e-6 * sc * sc * sc);
        const rv idet = 1.0 / rsel(pd, det, (rv){0} + 1.0);
        const rv n0 = (c00 * g0 + c01 * g1 + c02 * g2) * idet,
                 n1 = (c01 * g0 + c11 * g1 + c12 * g2) * idet,
                 n2 = (c02 * g0 + c12 * g1 + c22 * g2) * idet;
        const rv nn2 = n0 * n0 + n1 * n1 + n2 * n2;
        const rm newton = pd & (rm)(nn2 < ROT_NEWTON_MAX2);
        /* Müller: ω / (|tr M| + 1e-9) */
        const rv ms = 1.0 / (rsel((rm)(tr < 0), -tr, tr) + 1e-9);
        const rv o0 = rsel(newton, n0, g0 * ms), o1 = rsel(newton, n1, g1 * ms),
                 o2 = rsel(newton, n2, g2 * ms);
        const rv wn2 = o0 * o0 + o1 * o1 + o2 * o2;
        run &= (rm)(wn2 >= ROT_DONE2);
        /* The update quaternion exp(ω/2): first order [1, ω/2] below 0.3 rad (normalized
         * below; it rotates by 2·atan(|ω|/2) instead of |ω|, which changes how fast the
         * iteration converges, not where), sin and cos above (Müller steps only). */
        rv d0 = (rv){0} + 1.0, d1 = 0.5 * o0, d2 = 0.5 * o1, d3 = 0.5 * o2;
        const rm big = run & (rm)(wn2 >= ROT_NEWTON_MAX2);
        if (rany(big))
            for (int l = 0; l < ROT_LANES; l++) {
                if (!big[l])
                    continue;
                const double wn = sqrt(wn2[l]), half = 0.5 * wn, sh = sin(half) / wn;
                d0[l] = cos(half);
                d1[l] = o0[l] * sh;
                d2[l] = o1[l] * sh;
                d3[l] = o2[l] * sh;
            }
        const rv p0 = d0 * q[0] - d1 * q[1] - d2 * q[2] - d3 * q[3],
                 p1 = d0 * q[1] + d1 * q[0] + d2 * q[3] - d3 * q[2],
                 p2 = d0 * q[2] - d1 * q[3] + d2 * q[0] + d3 * q[1],
                 p3 = d0 * q[3] + d1 * q[2] - d2 * q[1] + d3 * q[0];
        rv pn = p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3;
        for (int l = 0; l < ROT_LANES; l++)
            pn[l] = 1.0 / sqrt(run[l] ? pn[l] : 1.0);
        q[0] = rsel(run, p0 * pn, q[0]);
        q[1] = rsel(run, p1 * pn, q[1]);
        q[2] = rsel(run, p2 * pn, q[2]);
        q[3] = rsel(run, p3 * pn, q[3]);
        run &= (newton & (rm)(wn2 >= ROT_NEWTON_STOP2)) |
               (~newton & (rm)(wn2 >= ROT_MULLER_STOP2));
    }
}

__attribute__((optimize("no-math-errno"), target_clones("arch=x86-64-v4", "arch=x86-64-v3",
                                                          "default"))) void
cs_extract_rotation(const double A[9], double q[4], int max_iter)
{
    rv Av[9], qv[4];
    for (int j = 0; j < 9; j++)
        Av[j] = (rv){0} + A[j];
    for (int j = 0; j < 4; j++)
        qv[j] = (rv){0} + q[j];
    rot_extract(Av, qv, (rm){-1}, max_iter);
    for (int j = 0; j < 4; j++)
        q[j] = qv[j][0];
}

/* Lanes run the same operations on their own data and a stopped lane keeps its q, so each
 * matrix's result is cs_extract_rotation's bit for bit, whatever its lane. */
__attribute__((optimize("no-math-errno"), target_clones("arch=x86-64-v4", "arch=x86-64-v3",
                                                          "default"))) void
cs_extract_rotations(int n, const double *A, double *q, int max_iter)
{
    for (int c0 = 0; c0 < n; c0 += ROT_LANES) {
        double a[9][ROT_LANES], b[4][ROT_LANES];
        rv Av[9], qv[4];
        rm live = {0};
        for (int l = 0; l < ROT_LANES; l++) {
            const int c = c0 + l < n ? c0 + l : c0; /* a lane past n repeats the first */
            live[l] = c0 + l < n ? -1 : 0;
            for (int j = 0; j < 9; j++)
                a[j][l] = A[9 * (size_t)c + j];
            for (int j = 0; j < 4; j++)
                b[j][l] = q[4 * (size_t)c + j];
        }
        memcpy(Av, a, sizeof Av);
        memcpy(qv, b, sizeof qv);
        rot_extract(Av, qv, live, max_iter);
        memcpy(b, qv, sizeof b);
        for (int l = 0; l < ROT_LANES && c0 + l < n; l++)
            for (int j = 0; j < 4; j++)
                q[4 * (size_t)(c0 + l) + j] = b[j][l];
    }
}

static int product_layout(cs_fem *fem);

int cs_fem_relink(cs_fem *fem, const cs_cubemesh *cm)
{
    /* the old lattice form first: whatever fails below, no product reads a stale map */
    cs_fem_lattice_free(fem->lat);
    fem->lat = NULL;
    free(fem->adj_start);
    free(fem->adj);
    fem->n_cells = cm->n_cells;
    fem->n_nodes = cm->n_nodes;
    fem->cell_nodes = cm->cell_nodes;
    fem->adj_start = calloc((size_t)cm->n_nodes + 1, sizeof *fem->adj_start);
    fem->adj = malloc((size_t)cm->n_cells * 8 * sizeof *fem->adj);
    if (!fem->adj_start || !fem->adj)
        return -1;
    for (int e = 0; e < 8 * cm->n_cells; e++)
        fem->adj_start[cm->cell_nodes[e] + 1]++;
    for (int n = 0; n < cm->n_nodes; n++)
        fem->adj_start[n + 1] += fem->adj_start[n];
    int32_t *fill = malloc((size_t)cm->n_nodes * sizeof *fill);
    if (!fill)
        return -1;
    memcpy(fill, fem->adj_start, (size_t)cm->n_nodes * sizeof *fill);
    /* Cells in increasing order: the gather order is fixed by the mesh, not by threads. */
    for (int e = 0; e < 8 * cm->n_cells; e++)
        fem->adj[fill[cm->cell_nodes[e]]++] = e;
    free(fill);
    if (product_layout(fem) != 0)
        return -1;
    return cs_fem_lattice_build(fem, cm, &fem->lat);
}

int cs_fem_init(cs_fem *fem, const cs_cubemesh *cm, double young, double poisson,
                bool corotational, int threads)
{
    memset(fem, 0, sizeof *fem);
    fem->h = cm->h;
    fem->corotational = corotational;
    /* Below CS_FEM_PARALLEL_CELLS an object's products take microseconds, less than a
     * thread barrier costs when the other core is busy (a descheduled worker stalls each
     * barrier for a scheduler timeslice): small objects run on one thread. */
    fem->threads = threads > 1 && cm->n_cells >= CS_FEM_PARALLEL_CELLS ? threads : 1;
    fem->wide = cs_simd_wide_default();
    fem->lattice = true;
    cs_cube_stiffness(young, poisson, cm->h, fem->K);
    fem->lambda = young * poisson / ((1 + poisson) * (1 - 2 * poisson));
    fem->mu = young / (2 * (1 + poisson));
    fem->detj = cm->h * cm->h * cm->h / 8.0;
    for (int g = 0; g < 8; g++)
        for (int k = 0; k < 8; k++) {
            double fa[3];
            for (int a = 0; a < 3; a++)
                fa[a] = 1 + SGN[k][a] * SGN[g][a] / sqrt(3.0);
            fem->gq[g][k][0] = SGN[k][0] * fa[1] * fa[2] / 8.0 * (2.0 / cm->h);
            fem->gq[g][k][1] = SGN[k][1] * fa[0] * fa[2] / 8.0 * (2.0 / cm->h);
            fem->gq[g][k][2] = SGN[k][2] * fa[0] * fa[1] / 8.0 * (2.0 / cm->h);
        }
    fem->Kg = malloc(8 * 576 * sizeof *fem->Kg);
    if (fem->Kg)
        for (int g = 0; g < 8; g++)
            cs_cube_stiffness_gauss(young, poisson, cm->h, g, fem->Kg + 576 * g);
    fem->R = malloc((size_t)cm->n_cells * 9 * sizeof *fem->R);
    fem->q = malloc((size_t)cm->n_cells * 4 * sizeof *fem->q);
    /* whole batches of 8: product_layout's slots */
    fem->fe = malloc(((size_t)cm->n_cells + 7) / 8 * 8 * 24 * sizeof *fem->fe);
    if (!fem->Kg || !fem->R || !fem->q || !fem->fe || cs_fem_relink(fem, cm) != 0) {
        cs_fem_free(fem);
        return -1;
    }
    cs_fem_reset_rotations(fem);
    return 0;
}

void cs_fem_free(cs_fem *fem)
{
    free(fem->R);
    free(fem->q);
    free(fem->fe);
    free(fem->adj_start);
    free(fem->adj);
    free(fem->tg);
    free(fem->Kg);
    free(fem->norder);
    free(fem->nminb);
    free(fem->nfirst);
    free(fem->bslot);
    free(fem->fadj);
    free(fem->fcell);
    free(fem->rowb);
    free(fem->nstart);
    cs_fem_lattice_free(fem->lat);
    memset(fem, 0, sizeof *fem);
}

void cs_fem_reset_rotations(cs_fem *fem)
{
    for (int c = 0; c < fem->n_cells; c++) {
        static const double I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
        memcpy(fem->R + 9 * c, I, sizeof I);
        fem->q[4 * c] = 1;
        fem->q[4 * c + 1] = fem->q[4 * c + 2] = fem->q[4 * c + 3] = 0;
    }
}

/* The deformation gradient at a cell's centre: F = (1/4h) Σ_k x_k s_kᵀ. */
static void centre_gradient(const cs_fem *fem, const double *x, int c, double F[9])
{
    const int32_t *nd = fem->cell_nodes + 8 * c;
    memset(F, 0, 9 * sizeof *F);
    for (int k = 0; k < 8; k++) {
        const double *p = x + 3 * nd[k];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                F[3 * i + j] += p[i] * SGN[k][j];
    }
    for (int i = 0; i < 9; i++)
        F[i] /= 4.0 * fem->h;
}

/* Cells [c0, c0 + ROT_LANES) ∩ [0, n_cells), active ones only: F at the centre (the same sums
 * as centre_gradient), the extraction warm-started from q, R = R(q). */
__attribute__((optimize("no-math-errno"), target_clones("arch=x86-64-v4", "arch=x86-64-v3",
                                                          "default"))) static void
rotations_batch(cs_fem *fem, const double *x, int c0)
{
    rv A[9], q[4];
    rm live = {0};
    int first = -1;
    for (int l = 0; l < ROT_LANES; l++) {
        const int c = c0 + l;
        if (c < fem->n_cells && (!fem->cell_active || fem->cell_active[c])) {
            live[l] = -1;
            if (first < 0)
                first = l;
        }
    }
    if (first < 0)
        return;
    const int32_t *nd[ROT_LANES];
    for (int l = 0; l < ROT_LANES; l++)
        nd[l] = fem->cell_nodes + 8 * (size_t)(c0 + (live[l] ? l : first));
    for (int j = 0; j < 9; j++)
        A[j] = (rv){0};
    for (int k = 0; k < 8; k++)
        for (int i = 0; i < 3; i++) {
            rv p;
            for (int l = 0; l < ROT_LANES; l++)
                p[l] = x[3 * (size_t)nd[l][k] + i];
            for (int j = 0; j < 3; j++)
                A[3 * i + j] += p * SGN[k][j];
        }
    for (int j = 0; j < 9; j++)
        A[j] /= 4.0 * fem->h;
    for (int j = 0; j < 4; j++)
        for (int l = 0; l < ROT_LANES; l++)
            q[j][l] = fem->q[4 * (size_t)(c0 + (live[l] ? l : first)) + j];
    rot_extract(A, q, live, 30);
    rv R[9];
    rot_quat_mat(q, R);
    for (int l = 0; l < ROT_LANES; l++) {
        if (!live[l])
            continue;
        double *qc = fem->q + 4 * (size_t)(c0 + l), *Rc = fem->R + 9 * (size_t)(c0 + l);
        for (int j = 0; j < 4; j++)
            qc[j] = q[j][l];
        for (int j = 0; j < 9; j++)
            Rc[j] = R[j][l];
    }
}

void cs_fem_update_rotations(cs_fem *fem, const double *x)
{
    if (!fem->corotational)
        return;
    const int nb = (fem->n_cells + ROT_LANES - 1) / ROT_LANES;
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int b = 0; b < nb; b++)
        rotations_batch(fem, x, b * ROT_LANES);
}

static void graded_kmul(const cs_fem *fem, const double *f, const double *restrict x,
                        double *restrict y);

/* ------------------------------------------------------------------ modal element product
 *
 * The cube's element product without its 24×24 matrix. On the reference cube ξ ∈ [-1,1]³
 * (x = centre + h/2·ξ) a trilinear field is u_i = Σ_m a_im φ_m, φ = {1, ξ, η, ζ, ξη, ηζ, ζξ,
 * ξηζ}, and the nodal values map to the modes by a Walsh–Hadamard transform: â_m = Σ_k
 * φ_m(s_k) u_k = 8 a_m (s_k the corner's signs; 23 additions per component). The gradient is
 * (2/h)(G0 + ξ Gξ + η Gη + ζ Gζ + ηζ B_ξ + ζξ B_η + ξη B_ζ) with G0[i] = (a_i1, a_i2, a_i3),
 * Gξ[i] = (0, a_i4, a_i6), Gη[i] = (a_i4, 0, a_i5), Gζ[i] = (a_i6, a_i5, 0) and B the columns
 * of a_i7. The monomials are orthogonal on the cube (∫1 = 8, ∫ξ² = 8/3, ∫ξ²η² = 8/9) and the
 * energy density W(G) = ½[λ tr(G)² + μ (G:G + G:Gᵀ)] is quadratic, so with (h/2)³(2/h)²·8 = 4h
 *   E = 4h [W(G0) + (W(Gξ) + W(Gη) + W(Gζ))/3 + (λ + 4μ)/18 · Σ_i a_i7²],
 * which is exactly what 2×2×2 Gauss quadrature integrates (the integrand has degree ≤ 2 per
 * variable). K u = ∂E/∂u = Hᵀ ∂E/∂â: the mode gradients ĝ = ∂E/∂â from σ(G) = λ tr(G) I +
 * μ (G + Gᵀ) (scale h/16 for G0, h/48 for the linear modes, h/144 for a_7), then the transposed
 * transform back to the nodes. About 400 flops per rotated cell instead of 1152 + 240.
 *
 * A rotation acts on components and the transform on nodes, so they commute: corotational
 * cells rotate the 7 non-constant mode vectors instead of the 8 nodes. The rest shape
 * −h·CS_CORNER only has the modes â_{i,1+i} = −4h (the translation mode is never used).
 *
 * Cells go through in batches of LANES (8), computed as two halves of 4, one cell per SIMD
 * lane (256-bit vectors): every lane does the same operations, so a cell's result does not
 * depend on its lane or on the thread count. The arithmetic is modal_core.h's (shared with
 * multigrid's single-precision V-cycle). Measured on the 2-core Zen 4 (AVX-512), ns per cube
 * of a whole cs_fem_apply_K (node pass included) on a 12³ block in cache, 1 thread, best of
 * 30 × 30 calls (CPU time, loaded machine): 35.2 with 4 lanes per call and element by element
 * loads (wave 3), 32 with 8 lanes in 512-bit vectors and gathers (Zen 4 splits 512-bit
 * operations in two and its gathers are slow), 29.4 with the batch in two 256-bit halves and
 * the corner indices laid out per batch (ix below), 25.0 with AVX-512VL's masked loads and
 * stores of the nodal 3-vectors transposed in registers (modal_kernel_avx512).
 *
 * Row batches (session 48; fem.h, rowb): 8 cells along a lattice row whose node rows are
 * numbered consecutively are read with whole loads per node row and store each node's two
 * results in the row already added (row_inputs, row_outputs, row_store), so the node pass reads
 * 4 slots for such a node instead of 8: cs_fem_apply_K on 32³ 0.76 → 0.67 ms on the Xeon of
 * sessions 47–48 (one thread, medians of 5 interleaved rounds).
 */
#define LANES 8

/* One batch: where each lane's cell reads its nodal vectors and writes its results. A lane
 * without a cell repeats another lane's inputs with lam = mu = 0 and writes to scratch. */
typedef struct mlanes {
    const double *x;          /* nodal vectors, 3 per node (global frame when rotated) */
    int32_t ix[8][LANES];     /* x + ix[k][l]: corner k of lane l's cell */
    const double *R;          /* row-major rotations (rotated products only): lane l's at */
    int32_t rix[LANES];       /* R + rix[l] */
    double lam[LANES];        /* (h/16)·λ·factor per lane */
    double mu[LANES];         /* (h/16)·μ·factor */
    double *out[LANES];       /* 24 per lane: K u per node (global frame when rotated) */
    double e[LANES];          /* out (with energy): ½ uᵀ K u in the local frame */
    /* A plain batch (AVX-512 path only; cn not NULL): 8 cells, each with its own inputs and
     * outputs, rotations (if any) contiguous from R (rix unused), corner k of lane l at
     * x + 3·cn[8l + k] (ix unused), results contiguous from ob (out unused): read and written
     * with whole-vector loads and stores transposed in registers. */
    const int32_t *cn;
    double *ob;
    /* A plain batch's rotations as unit quaternions (w, x, y, z) contiguous from Q (NULL: R
     * is read): the kernel rebuilds R from them, 32 bytes a cell to stream instead of 72. */
    const double *Q;
    bool wide; /* a plain batch in one 512-bit vector (modal_wide_body) */
    /* A row batch (fem.h, rowb) read and written by rows (modal_wide_body only; NULL: not):
     * its 4 rows' first 3·node, and ob its slot */
    const int32_t *row;
} mlanes;

typedef double vd4 __attribute__((vector_size(32)));
#define MODAL_NAME modal_core4
#define MODAL_V vd4
#define MODAL_S double
#include "modal_core.h" /* MODAL_FLOPS_CORE, MODAL_FLOPS_ROT */

/* y = R K (Rᵀ u − rest) per lane (rot: R given; rest: subtract the rest shape of edge rest);
 * energy: e = ½ (Rᵀu − rest)ᵀ K (Rᵀu − rest). */
__attribute__((optimize("fp-contract=fast"), target_clones("arch=x86-64-v3", "default")))
static void modal_kernel_any(mlanes *restrict b, int rot, double rest, int energy)
{
    for (int h = 0; h < LANES; h += 4) {
        vd4 u[24], R[9], y[24], e, L, M;
        const double *x = b->x;
        for (int k = 0; k < 8; k++) {
            const int32_t *ix = b->ix[k] + h;
            for (int i = 0; i < 3; i++)
                u[3 * k + i] = (vd4){x[ix[0] + i], x[ix[1] + i], x[ix[2] + i], x[ix[3] + i]};
        }
        if (rot) {
            const int32_t *rix = b->rix + h;
            for (int j = 0; j < 9; j++)
                R[j] = (vd4){b->R[rix[0] + j], b->R[rix[1] + j], b->R[rix[2] + j],
                             b->R[rix[3] + j]};
        }
        memcpy(&L, b->lam + h, sizeof L);
        memcpy(&M, b->mu + h, sizeof M);
        modal_core4(u, rot ? R : NULL, rest, &L, &M, energy ? &e : NULL, y);
        if (energy)
            memcpy(b->e + h, &e, sizeof e);
        for (int k = 0; k < 24; k++)
            for (int l = 0; l < 4; l++)
                b->out[h + l][k] = y[k][l];
    }
}

/* The same with AVX-512VL: each corner's 4 nodal vectors by masked 3-double loads transposed
 * into x, y, z across the lanes, and back the same way into masked 3-double stores (fewer
 * instructions than element by element; 256-bit vectors with 32 registers: 512-bit vectors of
 * 8 lanes measured slower on this Zen 4, which splits them in two). */
/* a b c d (4 vectors) → their transpose, in place */
#define TRANSPOSE4(a, b, c, d)                                                                \
    do {                                                                                     \
        const __m256d t0_ = _mm256_unpacklo_pd(a, b), t1_ = _mm256_unpackhi_pd(a, b);      \
        const __m256d t2_ = _mm256_unpacklo_pd(c, d), t3_ = _mm256_unpackhi_pd(c, d);      \
        a = _mm256_permute2f128_pd(t0_, t2_, 0x20);                                          \
        b = _mm256_permute2f128_pd(t1_, t3_, 0x20);                                          \
        c = _mm256_permute2f128_pd(t0_, t2_, 0x31);                                          \
        d = _mm256_permute2f128_pd(t1_, t3_, 0x31);                                          \
    } while (0)

__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4"))) static inline
    __attribute__((always_inline)) void
modal_avx512_body(mlanes *restrict b, int rot, double rest, int energy, const int plain)
{
    for (int h = 0; h < LANES; h += 4) {
        vd4 u[24], R[9], y[24], e, L, M;
        const double *x = b->x;
#pragma GCC unroll 8
        for (int k = 0; k < 8; k++) {
            int32_t q[4];
            for (int l = 0; l < 4; l++)
                q[l] = plain ? 3 * b->cn[8 * (h + l) + k] : b->ix[k][h + l];
            const __m256d r0 = _mm256_maskz_loadu_pd(7, x + q[0]);
            const __m256d r1 = _mm256_maskz_loadu_pd(7, x + q[1]);
            const __m256d r2 = _mm256_maskz_loadu_pd(7, x + q[2]);
            const __m256d r3 = _mm256_maskz_loadu_pd(7, x + q[3]);
            const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1);
            const __m256d t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3);
            u[3 * k] = (vd4)_mm256_permute2f128_pd(t0, t2, 0x20);
            u[3 * k + 1] = (vd4)_mm256_permute2f128_pd(t1, t3, 0x20);
            u[3 * k + 2] = (vd4)_mm256_permute2f128_pd(t0, t2, 0x31);
        }
        if (rot && plain && b->Q) {
            /* 4 cells' quaternions by one 4 × 4 transpose, then R(q) as cs_quat_to_mat */
            const double *Qp = b->Q + 4 * h;
            __m256d qw = _mm256_loadu_pd(Qp), qx = _mm256_loadu_pd(Qp + 4),
                    qy = _mm256_loadu_pd(Qp + 8), qz = _mm256_loadu_pd(Qp + 12);
            TRANSPOSE4(qw, qx, qy, qz);
            const vd4 w = (vd4)qw, x1 = (vd4)qx, y1 = (vd4)qy, z1 = (vd4)qz;
            CS_QUAT_TO_MAT(w, x1, y1, z1, R);
        } else if (rot && plain) {
            /* 4 cells' 9 entries: entries 0–3 and 4–7 by two 4 × 4 transposes */
            const double *Rp = b->R + 9 * h;
            __m256d a0 = _mm256_loadu_pd(Rp), a1 = _mm256_loadu_pd(Rp + 9),
                    a2 = _mm256_loadu_pd(Rp + 18), a3 = _mm256_loadu_pd(Rp + 27);
            __m256d c0 = _mm256_loadu_pd(Rp + 4), c1 = _mm256_loadu_pd(Rp + 13),
                    c2 = _mm256_loadu_pd(Rp + 22), c3 = _mm256_loadu_pd(Rp + 31);
            TRANSPOSE4(a0, a1, a2, a3);
            TRANSPOSE4(c0, c1, c2, c3);
            R[0] = (vd4)a0, R[1] = (vd4)a1, R[2] = (vd4)a2, R[3] = (vd4)a3;
            R[4] = (vd4)c0, R[5] = (vd4)c1, R[6] = (vd4)c2, R[7] = (vd4)c3;
            R[8] = (vd4){Rp[8], Rp[17], Rp[26], Rp[35]};
        } else if (rot) {
            const int32_t *rix = b->rix + h;
            for (int j = 0; j < 9; j++)
                R[j] = (vd4){b->R[rix[0] + j], b->R[rix[1] + j], b->R[rix[2] + j],
                             b->R[rix[3] + j]};
        }
        memcpy(&L, b->lam + h, sizeof L);
        memcpy(&M, b->mu + h, sizeof M);
        modal_core4(u, rot ? R : NULL, rest, &L, &M, energy ? &e : NULL, y);
        if (energy)
            memcpy(b->e + h, &e, sizeof e);
        if (plain) {
            /* lane l's 24 results are contiguous: 6 transposes of 4 × 4, whole stores */
            double *o = b->ob + 24 * h;
            for (int m = 0; m < 6; m++) {
                __m256d a = (__m256d)y[4 * m], bb = (__m256d)y[4 * m + 1],
                        c = (__m256d)y[4 * m + 2], d = (__m256d)y[4 * m + 3];
                TRANSPOSE4(a, bb, c, d);
                _mm256_storeu_pd(o + 4 * m, a);
                _mm256_storeu_pd(o + 24 + 4 * m, bb);
                _mm256_storeu_pd(o + 48 + 4 * m, c);
                _mm256_storeu_pd(o + 72 + 4 * m, d);
            }
            continue;
        }
        for (int k = 0; k < 8; k++) {
            const __m256d X = (__m256d)y[3 * k], Y = (__m256d)y[3 * k + 1],
                          Z = (__m256d)y[3 * k + 2];
            /* (x_l, y_l, z_l, ·) per lane */
            const __m256d a0 = _mm256_unpacklo_pd(X, Y), a1 = _mm256_unpackhi_pd(X, Y);
            const __m256d z0 = _mm256_unpacklo_pd(Z, Z), z1 = _mm256_unpackhi_pd(Z, Z);
            _mm256_mask_storeu_pd(b->out[h] + 3 * k, 7, _mm256_permute2f128_pd(a0, z0, 0x20));
            _mm256_mask_storeu_pd(b->out[h + 1] + 3 * k, 7, _mm256_permute2f128_pd(a1, z1, 0x20));
            _mm256_mask_storeu_pd(b->out[h + 2] + 3 * k, 7, _mm256_permute2f128_pd(a0, z0, 0x31));
            _mm256_mask_storeu_pd(b->out[h + 3] + 3 * k, 7, _mm256_permute2f128_pd(a1, z1, 0x31));
        }
    }
}

/* A plain batch's 8 lanes in one 512-bit vector (mlanes.wide: CPUs that execute 512-bit
 * vectors at full width, simd.h), rotations (if rot) from the quaternions Q: the same
 * arithmetic per lane as modal_avx512_body, so the same bits. The inputs: two masked loads per
 * pair of lanes (the second shifted, so that its 3 doubles land in the upper half), then two
 * unpacks and three two-source permutes per corner for 8 lanes (the 256-bit body: 14 shuffles);
 * the results: three 8 × 8 transposes (72 shuffles for 24 whole stores; 96 for 48 there). On
 * the 2-core Intel Xeon of session 47, cs_fem_apply_K on 32³ (one thread, fast mode, 7 rounds)
 * 1.01–1.04 → 0.78–0.83 ms. */
typedef double vd8 __attribute__((vector_size(64)));
#define MODAL_NAME modal_core8
#define MODAL_V vd8
#define MODAL_S double
#include "modal_core.h"

/* A row batch's inputs (fem.h, rowb): each node row's 8 nodes by three whole loads
 * deinterleaved into x, y, z (two two-source permutes each), its dx = 1 corners the same shifted
 * by one lane with the row's end node; the same values as the corner loads. */
__attribute__((target("arch=x86-64-v4"))) static inline __attribute__((always_inline)) void
row_inputs(const double *restrict x, const int32_t *row, vd8 u[24])
{
    for (int r = 0; r < 4; r++) {
        const double *p = x + row[r];
        __m512d v[3];
        cs_xyz8_split(_mm512_loadu_pd(p), _mm512_loadu_pd(p + 8), _mm512_loadu_pd(p + 16), v);
        for (int i = 0; i < 3; i++) {
            /* the end node's component i in lane 0 */
            const __m512i e = _mm512_castpd_si512(_mm512_maskz_loadu_pd(1, p + 24 + i));
            u[3 * CS_ROW_K0[r] + i] = (vd8)v[i];
            u[3 * CS_ROW_K1[r] + i] =
                (vd8)_mm512_castsi512_pd(_mm512_alignr_epi64(e, _mm512_castpd_si512(v[i]), 1));
        }
    }
}

/* A row batch's results into its slot (row_store's sums): per node row, the dx = 1 corner
 * shifted a lane up and added to the dx = 0 one, interleaved into 24 doubles by two permutes
 * per vector; the last lane's dx = 1 corner as the row's end node. */
__attribute__((target("arch=x86-64-v4"))) static inline __attribute__((always_inline)) void
row_outputs(const vd8 y[24], double *out)
{
    const __m512i e0 = _mm512_setr_epi64(7, 15, 0, 0, 0, 0, 0, 0);
    const __m512i e1 = _mm512_setr_epi64(0, 1, 15, 0, 0, 0, 0, 0);
    const __m512i zero = _mm512_setzero_si512();
    for (int r = 0; r < 4; r++) {
        __m512d S[3], o3[3];
        for (int i = 0; i < 3; i++) {
            const __m512i y1 = _mm512_castpd_si512((__m512d)y[3 * CS_ROW_K1[r] + i]);
            S[i] = _mm512_add_pd((__m512d)y[3 * CS_ROW_K0[r] + i],
                                 _mm512_castsi512_pd(_mm512_alignr_epi64(y1, zero, 7)));
        }
        double *o = out + 32 * r;
        cs_xyz8_join(S, o3);
        for (int v = 0; v < 3; v++)
            _mm512_storeu_pd(o + 8 * v, o3[v]);
        const __m512d end = _mm512_permutex2var_pd(
            _mm512_permutex2var_pd((__m512d)y[3 * CS_ROW_K1[r]], e0, (__m512d)y[3 * CS_ROW_K1[r] + 1]),
            e1, (__m512d)y[3 * CS_ROW_K1[r] + 2]);
        _mm512_mask_storeu_pd(o + 24, 0x7, end);
    }
}

__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4"))) static inline
    __attribute__((always_inline)) void
modal_wide_body(mlanes *restrict b, int rot, double rest, int energy)
{
    vd8 u[24], R[9], y[24], e, L, M;
    const double *x = b->x;
    const __m512i lo = _mm512_setr_epi64(0, 1, 8, 9, 4, 5, 12, 13);
    const __m512i hi = _mm512_setr_epi64(2, 3, 10, 11, 6, 7, 14, 15);
    if (b->row)
        row_inputs(x, b->row, u);
    else
#pragma GCC unroll 8
    for (int k = 0; k < 8; k++) {
        __m512d r[4]; /* (x, y, z, 0) of lanes j | j + 4 */
        for (int j = 0; j < 4; j++) /* the second load from 4 doubles before its node: its
                                     * masked-out lanes are never read (fault suppression) */
            r[j] = _mm512_mask_loadu_pd(
                _mm512_maskz_loadu_pd(0x07, x + 3 * b->cn[8 * j + k]), 0x70,
                (const void *)((uintptr_t)(x + 3 * b->cn[8 * (j + 4) + k]) - 4 * sizeof(double)));
        const __m512d t0 = _mm512_unpacklo_pd(r[0], r[1]), t1 = _mm512_unpackhi_pd(r[0], r[1]);
        const __m512d t2 = _mm512_unpacklo_pd(r[2], r[3]), t3 = _mm512_unpackhi_pd(r[2], r[3]);
        u[3 * k] = (vd8)_mm512_permutex2var_pd(t0, lo, t2);
        u[3 * k + 1] = (vd8)_mm512_permutex2var_pd(t1, lo, t3);
        u[3 * k + 2] = (vd8)_mm512_permutex2var_pd(t0, hi, t2);
    }
    if (rot) {
        /* 8 cells' (w, x, y, z): two cells per vector, regrouped by component */
        const double *Qp = b->Q;
        const __m512d A = _mm512_loadu_pd(Qp), B = _mm512_loadu_pd(Qp + 8),
                      C = _mm512_loadu_pd(Qp + 16), D = _mm512_loadu_pd(Qp + 24);
        const __m512i wx = _mm512_setr_epi64(0, 4, 8, 12, 1, 5, 9, 13);
        const __m512i yz = _mm512_setr_epi64(2, 6, 10, 14, 3, 7, 11, 15);
        const __m512d p0 = _mm512_permutex2var_pd(A, wx, B), p1 = _mm512_permutex2var_pd(A, yz, B);
        const __m512d p2 = _mm512_permutex2var_pd(C, wx, D), p3 = _mm512_permutex2var_pd(C, yz, D);
        const vd8 w = (vd8)_mm512_shuffle_f64x2(p0, p2, 0x44),
                  x1 = (vd8)_mm512_shuffle_f64x2(p0, p2, 0xEE),
                  y1 = (vd8)_mm512_shuffle_f64x2(p1, p3, 0x44),
                  z1 = (vd8)_mm512_shuffle_f64x2(p1, p3, 0xEE);
        CS_QUAT_TO_MAT(w, x1, y1, z1, R);
    }
    memcpy(&L, b->lam, sizeof L);
    memcpy(&M, b->mu, sizeof M);
    modal_core8(u, rot ? R : NULL, rest, &L, &M, energy ? &e : NULL, y);
    if (energy)
        memcpy(b->e, &e, sizeof e);
    if (b->row) {
        row_outputs(y, b->ob);
        return;
    }
    /* lane l's 24 results contiguous at ob + 24 l: three 8 × 8 transposes, whole stores */
    double *o = b->ob;
    for (int m = 0; m < 3; m++) {
        __m512d v[8], t[8];
        for (int i = 0; i < 8; i++)
            v[i] = (__m512d)y[8 * m + i];
        for (int i = 0; i < 8; i += 2) {
            t[i] = _mm512_unpacklo_pd(v[i], v[i + 1]);
            t[i + 1] = _mm512_unpackhi_pd(v[i], v[i + 1]);
        }
        /* t0 = (a0 b0 | a2 b2 | a4 b4 | a6 b6), t1 = (a1 b1 | a3 b3 | ...) (a = v0, b = v1) */
        for (int i = 0; i < 8; i += 4)
            for (int j = 0; j < 2; j++) {
                v[i + j] = _mm512_shuffle_f64x2(t[i + j], t[i + j + 2], 0x88);     /* 0 2 | 0 2 */
                v[i + j + 2] = _mm512_shuffle_f64x2(t[i + j], t[i + j + 2], 0xDD); /* 1 3 | 1 3 */
            }
        /* v0 = (a0 b0 | a4 b4 | c0 d0 | c4 d4), v1 = (a1 b1 | a5 b5 | c1 d1 | c5 d5),
         * v2 = (a2 b2 | a6 b6 | c2 d2 | c6 d6), v3 = (a3 b3 | a7 b7 | c3 d3 | c7 d7); the same
         * for e..h in v4..v7 */
        for (int j = 0; j < 4; j++) {
            t[j] = _mm512_shuffle_f64x2(v[j], v[j + 4], 0x88);     /* lane j: a b c d e f g h */
            t[j + 4] = _mm512_shuffle_f64x2(v[j], v[j + 4], 0xDD); /* lane j + 4 */
        }
        for (int l = 0; l < 8; l++)
            _mm512_storeu_pd(o + 24 * l + 8 * m, t[l]);
    }
}

/* The same with AVX-512VL: each corner's 4 nodal vectors by masked 3-double loads transposed
 * into x, y, z across the lanes, and back the same way into masked 3-double stores (fewer
 * instructions than element by element; 256-bit vectors with 32 registers: 512-bit vectors of
 * 8 lanes with gathers measured slower on Zen 4, which splits them in two; modal_wide_body for
 * the cores that do not, simd.h). A plain batch (cn) reads
 * its corner indices from the cells' node lists, its rotations and writes its results with
 * whole vectors transposed in registers (no per-batch tables). A product's plain batch (rotated,
 * no rest shape, no energy: cs_fem_apply_K's) gets its own instance with those flags constant
 * and the corner loop unrolled, so the 24 nodal vectors stay in registers instead of a stack
 * array and no flag is tested per half (32³ product 0.77 → 0.70 ms, bit for bit the same).
 * The products and forces of the fem's own rotations (force_batch, kw_batch) read them as
 * its quaternions (fem->q, Q) and rebuild R in registers: 32 bytes a cell from memory instead
 * of 72, the 64³ product 7–9 % faster on one and two threads, 32³ (in cache) even. That R may
 * differ from fem->R in the last bit (the kernel's contractions), but every product and force
 * of a plain batch uses the same one, so the operator and the forces agree. */
__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4")))
static void modal_kernel_avx512(mlanes *restrict b, int rot, double rest, int energy)
{
    if (b->cn && b->wide && rot && b->Q && rest == 0 && !energy)
        modal_wide_body(b, 1, 0.0, 0); /* a product's batch: the flags constant */
    else if (b->cn && b->wide && (!rot || b->Q))
        modal_wide_body(b, rot, rest, energy);
    else if (b->cn && rot && rest == 0 && !energy)
        modal_avx512_body(b, 1, 0.0, 0, 1); /* a product's batch: the flags constant */
    else if (b->cn)
        modal_avx512_body(b, rot, rest, energy, 1);
    else
        modal_avx512_body(b, rot, rest, energy, 0);
}

static void modal_kernel(mlanes *restrict b, int rot, double rest, int energy)
{
    if (__builtin_cpu_supports("x86-64-v4"))
        modal_kernel_avx512(b, rot, rest, energy);
    else
        modal_kernel_any(b, rot, rest, energy);
}

/* A graded cell: y_k = Σ_g f_g·detJ·σ_g ∇N_k(ξ_g), σ_g = λ tr(H) I + μ (H + Hᵀ),
 * H = Σ_k x_k ⊗ ∇N_k(ξ_g): the same sum as Σ_g f_g K_g x, without 24×24 products. */
__attribute__((target_clones("arch=x86-64-v3", "default"))) static void
graded_kmul(const cs_fem *fem, const double *f, const double *restrict x, double *restrict y)
{
    for (int i = 0; i < 24; i++)
        y[i] = 0;
    for (int g = 0; g < 8; g++) {
        const double(*G)[3] = fem->gq[g];
        double H[9] = {0};
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    H[3 * i + j] += x[3 * k + i] * G[k][j];
        const double s = f[g] * fem->detj, ltr = fem->lambda * (H[0] + H[4] + H[8]);
        double S[9];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                S[3 * i + j] = s * ((i == j ? ltr : 0.0) + fem->mu * (H[3 * i + j] + H[3 * j + i]));
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++)
                y[3 * k + i] += S[3 * i] * G[k][0] + S[3 * i + 1] * G[k][1] + S[3 * i + 2] * G[k][2];
    }
}

/* Cell c's stiffness factor if its 8 Gauss-point factors are equal (kf NULL: 1); false for a
 * graded cell. */
static bool uniform_factor(const double *kf, int c, double *f)
{
    if (!kf) {
        *f = 1.0;
        return true;
    }
    const double *g = kf + 8 * (size_t)c;
    *f = g[0];
    return g[0] == g[1] && g[0] == g[2] && g[0] == g[3] && g[0] == g[4] && g[0] == g[5] &&
           g[0] == g[6] && g[0] == g[7];
}

/* A graded cell point by point: out = R K_e (Rᵀ (x − x_0) − rest·corner) (R NULL: identity)
 * and, if e, ½ uᵀ K_e u. With rest = 0 x is a displacement-like vector: no x_0 shift. */
static void graded_cell(const cs_fem *fem, const double *f, const int32_t *nd, const double *R,
                        const double *x, double rest, double *out, double *e)
{
    static const double I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    if (!R)
        R = I;
    const double *x0 = x + 3 * nd[0];
    double u[24], ku[24];
    for (int k = 0; k < 8; k++) {
        const double *p = x + 3 * nd[k];
        double d[3] = {p[0], p[1], p[2]};
        if (rest != 0.0)
            for (int i = 0; i < 3; i++)
                d[i] -= x0[i];
        for (int i = 0; i < 3; i++)
            u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2] -
                           rest * CS_CORNER[k][i];
    }
    graded_kmul(fem, f, u, ku);
    double en = 0;
    for (int k = 0; k < 8; k++) {
        const double *l = ku + 3 * k;
        for (int i = 0; out && i < 3; i++)
            out[3 * k + i] = R[3 * i] * l[0] + R[3 * i + 1] * l[1] + R[3 * i + 2] * l[2];
        en += u[3 * k] * l[0] + u[3 * k + 1] * l[1] + u[3 * k + 2] * l[2];
    }
    if (e)
        *e = 0.5 * en;
}

/* A row batch's results from lanes (t: 24 per lane, as a batch's fb) into its rows in fb (fem.h,
 * rowb): node l of row r gets corner CS_ROW_K0[r] of lane l plus corner CS_ROW_K1[r] of lane l − 1 (0
 * for l = 0), the row's end node corner CS_ROW_K1[r] of lane 7 (modal_wide_body's row_outputs: the
 * same sums); the lanes of inactive cells (an active region) give 0. */
static void row_store(const cs_fem *fem, int c0, double *t, double *fb)
{
    if (fem->cell_active)
        for (int l = 0; l < LANES; l++)
            if (!fem->cell_active[c0 + l])
                memset(t + 24 * l, 0, 24 * sizeof(double));
    for (int r = 0; r < 4; r++)
        for (int i = 0; i < 3; i++) {
            const int k0 = 3 * CS_ROW_K0[r] + i, k1 = 3 * CS_ROW_K1[r] + i;
            fb[32 * r + i] = t[k0] + 0.0;
            for (int l = 1; l < LANES; l++)
                fb[32 * r + 3 * l + i] = t[24 * l + k0] + t[24 * (l - 1) + k1];
            fb[32 * r + 24 + i] = t[24 * (LANES - 1) + k1];
        }
}

/*
 * One batch of cells [c0, c0 + LANES) ∩ [0, n_cells): fb[24l..] = R_c K_c (R_cᵀ x − rest) for
 * cell c = c0 + l (Rb: the rotations of the batch's cells, 9 each from c0, NULL: none; fb: the
 * batch's 24 × LANES results, NULL: not stored)
 * and, if e, the energies per lane (0 past the end). Uniform cells go through the modal
 * kernel together, graded ones point by point.
 */
static void batch_product(const cs_fem *fem, const double *kf, int c0, const double *Rb,
                          const double *Qb, const double *x, double rest, double *fb,
                          double e[LANES])
{
    const double c16 = fem->h / 16.0;
    double sink[24];
    mlanes B;
    int graded = 0, first = -1;
    int live = 0;
    B.x = x;
    B.R = Rb;
    B.Q = Rb ? Qb : NULL;
    B.cn = NULL;
    B.row = NULL;
    B.wide = fem->wide;
    /* a row batch's lanes into t first (row_store), unless the wide kernel writes its rows */
    const bool row = fb && fem->rowb[4 * (c0 / LANES)] >= 0;
    double t[24 * LANES];
    double *const dst = row ? t : fb;
    if (fb && c0 + LANES <= fem->n_cells && __builtin_cpu_supports("x86-64-v4")) {
        /* a plain batch if every cell is uniform */
        int l = 0;
        for (double f; l < LANES && uniform_factor(kf, c0 + l, &f); l++) {
            B.lam[l] = c16 * fem->lambda * f;
            B.mu[l] = c16 * fem->mu * f;
        }
        if (l == LANES) {
            B.cn = fem->cell_nodes + 8 * (size_t)c0;
            if (row && B.wide && (!Rb || B.Q) && !fem->cell_active)
                B.row = fem->rowb + 4 * (c0 / LANES);
            B.ob = B.row ? fb : dst;
            modal_kernel(&B, Rb != NULL, rest, e != NULL);
            if (row && !B.row)
                row_store(fem, c0, t, fb);
            for (int k = 0; e && k < LANES; k++)
                e[k] = B.e[k];
            return;
        }
    }
    for (int l = 0; l < LANES; l++) {
        const int c = c0 + l;
        double f;
        if (e)
            e[l] = 0;
        if (c < fem->n_cells && uniform_factor(kf, c, &f)) {
            const int32_t *nd = fem->cell_nodes + 8 * (size_t)c;
            for (int k = 0; k < 8; k++)
                B.ix[k][l] = 3 * nd[k];
            B.rix[l] = 9 * l;
            B.lam[l] = c16 * fem->lambda * f;
            B.mu[l] = c16 * fem->mu * f;
            B.out[l] = fb ? dst + 24 * l : sink;
            if (first < 0)
                first = l;
            live |= 1 << l;
        } else if (c < fem->n_cells) {
            graded |= 1 << l;
        }
    }
    if (first >= 0) {
        for (int l = 0; l < LANES; l++)
            if (!(live & (1 << l))) {
                for (int k = 0; k < 8; k++)
                    B.ix[k][l] = B.ix[k][first];
                B.rix[l] = B.rix[first];
                B.lam[l] = B.mu[l] = 0;
                B.out[l] = sink;
            }
        modal_kernel(&B, Rb != NULL, rest, e != NULL);
    }
    for (int l = 0; l < LANES && c0 + l < fem->n_cells; l++) {
        const int c = c0 + l;
        if (graded & (1 << l))
            graded_cell(fem, kf + 8 * (size_t)c, fem->cell_nodes + 8 * (size_t)c,
                        Rb ? Rb + 9 * l : NULL, x, rest, fb ? dst + 24 * l : NULL,
                        e ? e + l : NULL);
        else if (e)
            e[l] = B.e[l];
    }
    if (row)
        row_store(fem, c0, t, fb);
}

static int n_batches(int n_cells)
{
    return (n_cells + LANES - 1) / LANES;
}

/* ku = K_c u for local 24-vectors of the batch's cells from c0 (us, kus: 24 per lane). */
static void batch_local(const cs_fem *fem, const double *kf, int c0, const double *us,
                        double *kus)
{
    /* node k of lane l sits at us + 24 l + 3 k */
    const double c16 = fem->h / 16.0;
    double sink[24];
    mlanes B;
    int graded = 0, live = 0;
    B.x = us;
    B.R = NULL;
    B.cn = NULL;
    B.row = NULL;
    B.Q = NULL;
    for (int l = 0; l < LANES; l++) {
        const int c = c0 + l;
        double f;
        for (int k = 0; k < 8; k++)
            B.ix[k][l] = 24 * l + 3 * k;
        B.rix[l] = 0;
        B.out[l] = kus + 24 * l;
        if (c < fem->n_cells && uniform_factor(kf, c, &f)) {
            B.lam[l] = c16 * fem->lambda * f;
            B.mu[l] = c16 * fem->mu * f;
            live++;
        } else {
            /* graded or past the end: computed below, or not at all */
            for (int k = 0; k < 8; k++)
                B.ix[k][l] = 3 * k;
            B.lam[l] = B.mu[l] = 0;
            B.out[l] = sink;
            if (c < fem->n_cells)
                graded |= 1 << l;
        }
    }
    if (live)
        modal_kernel(&B, 0, 0.0, 0);
    for (int l = 0; l < LANES && c0 + l < fem->n_cells; l++)
        if (graded & (1 << l))
            graded_kmul(fem, kf + 8 * (size_t)(c0 + l), us + 24 * l, kus + 24 * l);
}

void cs_cube_lame_h(const double K[24 * 24], double *hl, double *hm)
{
    /* K_00 = h(λ + 4μ)/9 and K_01 = h(λ + μ)/12 (corner 0, x and y) */
    *hl = 16.0 * K[1] - 3.0 * K[0];
    *hm = 3.0 * K[0] - 4.0 * K[1];
}

void cs_cube_cells_product(const double K[24 * 24], int n_cells, const int32_t *cell_nodes,
                           const double *R, const double *s, const double *x, double *fe,
                           int threads)
{
    double hl, hm;
    cs_cube_lame_h(K, &hl, &hm);
    const int nb = n_batches(n_cells);
#pragma omp parallel for num_threads(threads) schedule(static)
    for (int b = 0; b < nb; b++) {
        double sink[24];
        mlanes B;
        B.x = x;
        B.R = R + 9 * (size_t)b * LANES;
        B.cn = NULL;
    B.row = NULL;
        B.Q = NULL;
        for (int l = 0; l < LANES; l++) {
            const int c = b * LANES + l, cc = c < n_cells ? c : b * LANES;
            const double sc = c < n_cells ? s[c] / 16.0 : 0.0;
            for (int k = 0; k < 8; k++)
                B.ix[k][l] = 3 * cell_nodes[8 * (size_t)cc + k];
            B.rix[l] = 9 * (cc - b * LANES);
            B.lam[l] = hl * sc;
            B.mu[l] = hm * sc;
            B.out[l] = c < n_cells ? fe + 24 * (size_t)c : sink;
        }
        modal_kernel(&B, 1, 0.0, 0);
    }
}

/* Energy batches per block of the parallel sum: blocks are summed in order, so the result does
 * not depend on the thread count. */
#define ENERGY_BLOCK 64

/* The energy of batches [b0, b1): exact rotations at x (not the cached ones), then the batch
 * product's energies. */
static double energy_batches(const cs_fem *fem, const double *x, int b0, int b1)
{
    double s = 0;
    for (int b = b0; b < b1; b++) {
        const int c0 = b * LANES;
        double Rb[9 * LANES], e[LANES];
        for (int l = 0; fem->corotational && l < LANES && c0 + l < fem->n_cells; l++) {
            double F[9], q[4];
            centre_gradient(fem, x, c0 + l, F);
            memcpy(q, fem->q + 4 * (size_t)(c0 + l), sizeof q);
            cs_extract_rotation(F, q, 30);
            cs_quat_to_mat(q, Rb + 9 * l);
        }
        batch_product(fem, fem->kf, c0, fem->corotational ? Rb : NULL, NULL, x, fem->h, NULL, e);
        for (int l = 0; l < LANES; l++)
            s += e[l];
    }
    return s;
}

double cs_fem_energy(const cs_fem *fem, const double *x)
{
    const int nb = (fem->n_cells + LANES - 1) / LANES;
    const int nblk = (nb + ENERGY_BLOCK - 1) / ENERGY_BLOCK;
    double stack[16], *part = nblk <= 16 ? stack : malloc(sizeof(double) * (size_t)nblk);
    double e_sum = 0;
    if (!part) { /* out of memory: the same blocks in the same order, on this thread */
        for (int k = 0; k < nblk; k++)
            e_sum += energy_batches(fem, x, k * ENERGY_BLOCK, (nb < (k + 1) * ENERGY_BLOCK ? nb : (k + 1) * ENERGY_BLOCK));
        return e_sum;
    }
#pragma omp parallel for num_threads(fem->threads) schedule(static) if (nblk > 1 && fem->threads > 1)
    for (int k = 0; k < nblk; k++)
        part[k] = energy_batches(fem, x, k * ENERGY_BLOCK, (nb < (k + 1) * ENERGY_BLOCK ? nb : (k + 1) * ENERGY_BLOCK));
    for (int k = 0; k < nblk; k++)
        e_sum += part[k];
    if (part != stack)
        free(part);
    return e_sum;
}

/* Whether the batch of cells from c0 holds an active one (cell_active; NULL: all are). The
 * other cells of a batch are computed too: harmless, the node pass ignores inactive cells. */
static bool batch_active(const cs_fem *fem, int c0)
{
    if (!fem->cell_active)
        return true;
    for (int l = 0; l < LANES && c0 + l < fem->n_cells; l++)
        if (fem->cell_active[c0 + l])
            return true;
    return false;
}

/* Whether the node pass reads link v of fcell (fem.h): its cell's, or a row batch's whole. */
static inline bool link_active(const cs_fem *fem, int32_t v)
{
    return v >= 0 ? fem->cell_active[v] != 0 : batch_active(fem, (-1 - v) * LANES);
}

/* Where the fused passes keep the element pass's results (the fields after tg in fem.h): the
 * nodes ordered by the batch of their last cell, each segment's batches in a window of fe.
 * A chunk's node pass reads results back up to `span` batches old (the largest distance
 * between a node's first and last batch: about one layer of cells on a box), so a segment
 * keeps its first `span` batches (the nodes it shares with the previous segment read them
 * after the barrier) and then cycles through a ring of span + FEM_CHUNK batches; a shorter
 * segment is stored whole. On a 32³ block that is about 2 × 200 KB of results live instead
 * of 6.3 MB written to memory and read back. The layout depends on fem->threads only, the
 * values on nothing of it. Returns -1 on out of memory. */
#define FEM_CHUNK 64 /* batches per chunk of a fused pass (512 cells, 96 KiB of results) */

static int seg_start(const cs_fem *fem, int nb, int s)
{
    return (int)((int64_t)nb * s / fem->nseg);
}

static int product_layout(cs_fem *fem)
{
    free(fem->norder);
    free(fem->nminb);
    free(fem->nfirst);
    free(fem->bslot);
    free(fem->fadj);
    free(fem->fcell);
    free(fem->rowb);
    free(fem->nstart);
    const int nb = n_batches(fem->n_cells), nn = fem->n_nodes;
    const size_t nn1 = nn ? (size_t)nn : 1;
    fem->nseg = fem->threads > 1 ? fem->threads : 1;
    fem->norder = malloc(nn1 * sizeof(int32_t));
    fem->nminb = malloc(nn1 * sizeof(int32_t));
    fem->nfirst = calloc((size_t)nb + 2, sizeof(int32_t));
    fem->bslot = malloc(((size_t)nb + 1) * sizeof(int32_t));
    fem->fadj = malloc(((size_t)fem->n_cells * 8 + 1) * sizeof(int32_t));
    fem->fcell = malloc(((size_t)fem->n_cells * 8 + 1) * sizeof(int32_t));
    fem->rowb = malloc(((size_t)nb * 4 + 1) * sizeof(int32_t));
    fem->nstart = malloc((nn1 + 1) * sizeof(int32_t));
    int32_t *fill = malloc(((size_t)nb + 1) * sizeof(int32_t));
    if (!fem->norder || !fem->nminb || !fem->nfirst || !fem->bslot || !fem->fadj || !fem->fcell ||
        !fem->rowb || !fem->nstart || !fill) {
        free(fill);
        return -1;
    }
    const int32_t *as = fem->adj_start, *adj = fem->adj;
    /* counting sort of the nodes by the batch of their last cell (adj: cells increasing);
     * nodes without cells with batch 0 */
    int span = 0;
    for (int n = 0; n < nn; n++) {
        const int a0 = as[n], a1 = as[n + 1];
        const int lo = a1 > a0 ? adj[a0] / 8 / LANES : 0, hi = a1 > a0 ? adj[a1 - 1] / 8 / LANES : 0;
        fem->nfirst[hi + 1]++;
        span = hi - lo > span ? hi - lo : span;
    }
    for (int b = 0; b <= nb; b++)
        fem->nfirst[b + 1] += fem->nfirst[b];
    memcpy(fill, fem->nfirst, ((size_t)nb + 1) * sizeof(int32_t));
    for (int n = 0; n < nn; n++) {
        const int a0 = as[n], a1 = as[n + 1];
        const int q = fill[a1 > a0 ? adj[a1 - 1] / 8 / LANES : 0]++;
        fem->norder[q] = n;
        fem->nminb[q] = a1 > a0 ? adj[a0] / 8 / LANES : 0;
    }
    free(fill);
    fem->span = span;
    const int64_t head = span, ring = (int64_t)span + FEM_CHUNK;
    int64_t total = 0;
    for (int sg = 0; sg < fem->nseg; sg++) {
        const int b0 = seg_start(fem, nb, sg), b1 = seg_start(fem, nb, sg + 1);
        for (int b = b0; b < b1; b++) {
            const int64_t o = b - b0;
            fem->bslot[b] = (int32_t)(total + (o < head ? o : head + (o - head) % ring));
        }
        total += b1 - b0 < head + ring ? b1 - b0 : head + ring;
    }
    /* row batches only where the wide kernel reads and writes them: elsewhere the lanes would
     * be added by rows in C (row_store), 10 % slower for the product than the 256-bit kernel's
     * own stores (--simd 256 on the Xeon of session 48) */
    fem->n_row_batches =
        cs_row_batches(fem->cell_nodes, fem->n_cells, LANES, cs_simd_wide_default(), fem->rowb);
    int32_t m = 0;
    for (int n = 0; n < nn; n++) {
        fem->nstart[n] = m;
        for (int a = as[n]; a < as[n + 1]; a++) {
            const int c = adj[a] / 8, k = adj[a] % 8, b = c / LANES, l = c % LANES;
            if (fem->rowb[4 * b] < 0) {
                fem->fcell[m] = c;
                fem->fadj[m++] = 24 * (LANES * fem->bslot[b] + l) + 3 * k;
                continue;
            }
            /* in a row batch: corner k in node row CS_ROW_OF[k] (rowbatch.h) */
            const int off = cs_row_link(k, l, LANES);
            if (off >= 0) {
                fem->fcell[m] = -1 - b;
                fem->fadj[m++] = 24 * LANES * fem->bslot[b] + 32 * CS_ROW_OF[k] + off;
            }
        }
    }
    fem->nstart[nn] = m;
    return 0;
}

/* What a product's node pass adds to each node's row besides sign · Σ (fused_pass's na):
 * mcoef·m[n]·p[n] (3 per node), the mass term of the implicit step's operator. NULL: none. */
typedef struct node_add {
    const double *m, *p;
    double mcoef;
} node_add;

/* Node n's row: out[n] = sign · Σ of its (cell, corner) results, in the node→cell list's order
 * (increasing cells, whatever the thread count), + mcoef·m[n]·p[n] with na (the product
 * mcoef·m[n] first, then by p: the rounding of the separate pass it replaces). A node with all
 * 8 cells (every interior node of a block) sums them unrolled, in the same order: its 8 slots
 * are loaded at once instead of one per trip of a loop whose length varies from node to node
 * (measured 20–30 % faster on 32³–64³ blocks). */
/* nl (a constant once inlined) links' 3-vectors loaded at once and summed in order */
static inline __attribute__((always_inline)) void sum_links(const double *restrict fe,
                                                           const int32_t *restrict f, const int nl,
                                                           double *s0, double *s1, double *s2)
{
    const double *v[8];
    for (int k = 0; k < nl; k++)
        v[k] = fe + f[k];
    for (int k = 0; k < nl; k++) {
        *s0 += v[k][0];
        *s1 += v[k][1];
        *s2 += v[k][2];
    }
}

static inline __attribute__((always_inline)) void
node_sum(const cs_fem *fem, int n, double *restrict out, double sign, const double *restrict m,
         const double *restrict p, double mcoef)
{
    const int32_t *restrict fadj = fem->fadj;
    const double *restrict fe = fem->fe;
    const uint8_t *act = fem->cell_active;
    const int a0 = fem->nstart[n], a1 = fem->nstart[n + 1];
    double s0 = 0, s1 = 0, s2 = 0;
    if (a1 - a0 == 8 && !act) { /* a block's inside */
        sum_links(fe, fadj + a0, 8, &s0, &s1, &s2);
    } else if (a1 - a0 == 4 && !act) { /* inside row batches */
        sum_links(fe, fadj + a0, 4, &s0, &s1, &s2);
    } else {
        for (int a = a0; a < a1; a++) {
            if (act && !link_active(fem, fem->fcell[a]))
                continue;
            const double *v = fe + fadj[a];
            s0 += v[0];
            s1 += v[1];
            s2 += v[2];
        }
    }
    double *o = out + 3 * (size_t)n;
    if (m) {
        const double mm = mcoef * m[n], *pn = p + 3 * (size_t)n;
        o[0] = sign * s0 + mm * pn[0];
        o[1] = sign * s1 + mm * pn[1];
        o[2] = sign * s2 + mm * pn[2];
    } else {
        o[0] = sign * s0;
        o[1] = sign * s1;
        o[2] = sign * s2;
    }
}

/* The node pass over positions [q0, q1) of norder: the nodes whose first batch is >= b0
 * (after = 0: their cells are all in this segment) or < b0 (after = 1: shared with a lower
 * segment, after the barrier). With na, a loop of its own with its terms in locals. */
static void node_range_any(const cs_fem *fem, int q0, int q1, int b0, int after, double *out,
                           double sign, const node_add *na)
{
    if (na) {
        const double *restrict m = na->m, *restrict p = na->p;
        const double mcoef = na->mcoef;
        for (int q = q0; q < q1; q++)
            if ((fem->nminb[q] < b0) == after)
                node_sum(fem, fem->norder[q], out, sign, m, p, mcoef);
        return;
    }
    for (int q = q0; q < q1; q++)
        if ((fem->nminb[q] < b0) == after)
            node_sum(fem, fem->norder[q], out, sign, NULL, NULL, 0.0);
}

/* The same with AVX-512VL: a node sums its corner results as masked 3-double vectors (one
 * load and one add per link instead of two of each), the same terms in the same order from the
 * same zero, so bit for bit node_sum's (an interior node's 8 unrolled); one masked store (with
 * the mass term: the same products and sum as node_sum's, no fused multiply-add). No call in
 * the loop: with node_sum's scalar branch inlined or called, GCC kept fadj in a vector register
 * and moved it back before every link. One instance per value of `mass` (a constant). */
__attribute__((target("arch=x86-64-v4"))) static inline __attribute__((always_inline)) void
node_range_avx512_body(const cs_fem *fem, int q0, int q1, int b0, int after, double *out,
                       double sign, const node_add *na, const int mass)
{
    const int32_t *restrict fadj = fem->fadj, *restrict as = fem->nstart;
    const int32_t *restrict norder = fem->norder, *restrict nminb = fem->nminb;
    const int32_t *restrict fcell = fem->fcell;
    const uint8_t *act = fem->cell_active;
    const double *restrict fe = fem->fe;
    const double *restrict m = mass ? na->m : NULL, *restrict p = mass ? na->p : NULL;
    const double mcoef = mass ? na->mcoef : 0.0;
    const __m256d sg = _mm256_set1_pd(sign);
    for (int q = q0; q < q1; q++) {
        if ((nminb[q] < b0) != after)
            continue;
        const int n = norder[q], a0 = as[n], a1 = as[n + 1];
        __m256d s = _mm256_setzero_pd();
        if (a1 - a0 == 8 && !act) {
            for (int k = 0; k < 8; k++)
                s = _mm256_add_pd(s, _mm256_maskz_loadu_pd(7, fe + fadj[a0 + k]));
        } else if (a1 - a0 == 4 && !act) { /* inside row batches */
            for (int k = 0; k < 4; k++)
                s = _mm256_add_pd(s, _mm256_maskz_loadu_pd(7, fe + fadj[a0 + k]));
        } else {
            for (int a = a0; a < a1; a++)
                if (!act || link_active(fem, fcell[a]))
                    s = _mm256_add_pd(s, _mm256_maskz_loadu_pd(7, fe + fadj[a]));
        }
        __m256d r = _mm256_mul_pd(sg, s);
        if (mass)
            r = _mm256_add_pd(r, _mm256_mul_pd(_mm256_set1_pd(mcoef * m[n]),
                                               _mm256_maskz_loadu_pd(7, p + 3 * (size_t)n)));
        _mm256_mask_storeu_pd(out + 3 * (size_t)n, 7, r);
    }
}

__attribute__((target("arch=x86-64-v4"))) static void
node_range_avx512(const cs_fem *fem, int q0, int q1, int b0, int after, double *out, double sign)
{
    node_range_avx512_body(fem, q0, q1, b0, after, out, sign, NULL, 0);
}

__attribute__((target("arch=x86-64-v4"))) static void
node_range_avx512_mass(const cs_fem *fem, int q0, int q1, int b0, int after, double *out,
                       double sign, const node_add *na)
{
    node_range_avx512_body(fem, q0, q1, b0, after, out, sign, na, 1);
}

static void node_range(const cs_fem *fem, int q0, int q1, int b0, int after, double *out,
                       double sign, const node_add *na)
{
    if (__builtin_cpu_supports("x86-64-v4")) {
        if (na)
            node_range_avx512_mass(fem, q0, q1, b0, after, out, sign, na);
        else
            node_range_avx512(fem, q0, q1, b0, after, out, sign);
    } else {
        node_range_any(fem, q0, q1, b0, after, out, sign, na);
    }
}

/* The element pass of batch b: its results into fb (24 × LANES), its energy added to *e. */
typedef void (*batch_fn)(cs_fem *fem, int b, double *fb, const void *ctx, double *e);

/*
 * A product's element pass (fn on every batch) fused with its node pass (out = sign · Σ):
 * each segment's batches chunk by chunk, each chunk's element pass followed by the node pass
 * of the nodes whose cells are all done and all in the segment (their results still in
 * cache); after the barrier the nodes it shares with lower segments. Every node's sum has the
 * same terms in the same order for any thread count; na (may be NULL): a term per node added
 * as the row is written (node_sum). Returns the sum of the batches' energies.
 */
static double fused_pass(cs_fem *fem, batch_fn fn, const void *ctx, double *out, double sign,
                         const node_add *na)
{
    const int nb = n_batches(fem->n_cells);
    double e_sum = 0;
#pragma omp parallel num_threads(fem->threads) reduction(+ : e_sum)
    {
        const int nt = omp_get_num_threads(), t = omp_get_thread_num();
        for (int sg = t; sg < fem->nseg; sg += nt) {
            const int b0 = seg_start(fem, nb, sg), b1 = seg_start(fem, nb, sg + 1);
            for (int j0 = b0; j0 < b1; j0 += FEM_CHUNK) {
                const int j1 = j0 + FEM_CHUNK < b1 ? j0 + FEM_CHUNK : b1;
                for (int b = j0; b < j1; b++)
                    fn(fem, b, fem->fe + 24 * LANES * (size_t)fem->bslot[b], ctx, &e_sum);
                node_range(fem, fem->nfirst[j0], fem->nfirst[j1], b0, 0, out, sign, na);
            }
        }
        /* nodes without cells (sorted to batch 0): when there are no batches at all */
        if (nb == 0 && t == 0)
            for (int q = 0; q < fem->n_nodes; q++)
                node_sum(fem, fem->norder[q], out, sign, na ? na->m : NULL,
                         na ? na->p : NULL, na ? na->mcoef : 0.0);
#pragma omp barrier
        /* a node whose first batch is below b0 has its last within span of it; all
         * segments' such positions shared out equally among the threads (segments.h) */
        int64_t total = 0;
        for (int pass = 0; pass < 2; pass++) {
            int64_t before = 0;
            for (int sg = 0; sg < fem->nseg; sg++) {
                const int b0 = seg_start(fem, nb, sg), b1 = seg_start(fem, nb, sg + 1);
                const int bs = b0 + fem->span + 1 < b1 ? b0 + fem->span + 1 : b1;
                if (b0 == 0)
                    continue;
                const int q0 = fem->nfirst[b0], len = fem->nfirst[bs] - q0;
                if (pass == 1) {
                    int64_t lo, hi;
                    cs_segment_share(before, len, total, t, nt, &lo, &hi);
                    if (lo < hi)
                        node_range(fem, q0 + (int)lo, q0 + (int)hi, b0, 1, out, sign, na);
                }
                before += len;
            }
            total = before;
        }
    }
    return e_sum;
}

typedef struct force_ctx {
    const double *x;
} force_ctx;

static void force_batch(cs_fem *fem, int b, double *fb, const void *ctx, double *e_sum)
{
    const int c0 = b * LANES;
    if (!batch_active(fem, c0))
        return;
    const force_ctx *fc = ctx;
    double e[LANES];
    batch_product(fem, fem->kf, c0, fem->corotational ? fem->R + 9 * (size_t)c0 : NULL,
                  fem->corotational ? fem->q + 4 * (size_t)c0 : NULL, fc->x,
                  fem->h, fb, e);
    for (int l = 0; l < LANES; l++)
        *e_sum += e[l];
}

void cs_fem_elastic_force(cs_fem *fem, const double *x, double *f, double *energy)
{
    const force_ctx fc = {x};
    const double e_sum = fused_pass(fem, force_batch, &fc, f, -1.0, NULL);
    if (energy)
        *energy = e_sum;
}

void cs_fem_apply_K(cs_fem *fem, const double *p, double *y)
{
    cs_fem_apply_Kw(fem, fem->kf, p, y);
}

typedef struct kw_ctx {
    const double *kf, *p;
} kw_ctx;

static void kw_batch(cs_fem *fem, int b, double *fb, const void *ctx, double *e_sum)
{
    (void)e_sum;
    const int c0 = b * LANES;
    if (!batch_active(fem, c0))
        return;
    const kw_ctx *kc = ctx;
    batch_product(fem, kc->kf, c0, fem->corotational ? fem->R + 9 * (size_t)c0 : NULL,
                  fem->corotational ? fem->q + 4 * (size_t)c0 : NULL, kc->p,
                  0.0, fb, NULL);
}

void cs_fem_apply_Kw(cs_fem *fem, const double *kf, const double *p, double *y)
{
    if (cs_fem_lattice_product(fem, kf, 1.0, 0.0, NULL, p, y))
        return;
    const kw_ctx kc = {kf, p};
    fused_pass(fem, kw_batch, &kc, y, 1.0, NULL);
}

void cs_fem_apply_K_mass(cs_fem *fem, double kcoef, double mcoef, const double *m,
                         const double *p, double *y)
{
    if (cs_fem_lattice_product(fem, fem->kf, kcoef, mcoef, m, p, y))
        return;
    const kw_ctx kc = {fem->kf, p};
    const node_add na = {m, p, mcoef};
    fused_pass(fem, kw_batch, &kc, y, kcoef, &na);
}

double cs_fem_product_flops(const cs_fem *fem)
{
    /* Useful operations, a multiply-add counted as two: uniform cells the modal kernel
     * (MODAL_FLOPS_*), graded cells graded_kmul (8 Gauss points × (144 gradient + 40 stress +
     * 144 forces)) and their 2 × 8 × 15 rotations; then the node pass (3 additions per
     * (node, cell) link and 3 products by the sign per node). Lanes without a cell are not
     * counted. */
    const double graded = 8.0 * (144.0 + 40.0 + 144.0) + 240.0;
    const double uniform = MODAL_FLOPS_CORE + (fem->corotational ? MODAL_FLOPS_ROT : 0.0);
    double flops = 0;
    for (int c = 0; c < fem->n_cells; c++) {
        double f;
        flops += uniform_factor(fem->kf, c, &f) ? uniform : graded;
    }
    return flops + 3.0 * 8.0 * fem->n_cells + 3.0 * fem->n_nodes;
}

void cs_fem_diag_blocks(cs_fem *fem, double *blocks)
{
    cs_fem_diag_blocks_w(fem, fem->kf, blocks);
}

/*
 * A corner's 3×3 diagonal block of the cube's K is K_kk = (α − β) I + β s sᵀ (s the corner's
 * signs: every diagonal entry α, off-diagonal ones β s_i s_j, by the cube's symmetries; α =
 * h(λ + 4μ)/9, β = h(λ + μ)/12), so R K_kk Rᵀ = (α − β) I + β (R s)(R s)ᵀ: 15 flops a corner
 * instead of two 3×3 products (54 multiply-adds). Graded cells (8 different Gauss-point factors)
 * sum the corner blocks of the per-point matrices and rotate them as before.
 *
 * A node pass (each node sums over its cells in the node→cell list's order, increasing cells;
 * uniform cells into the 6 entries of a symmetric block, graded ones into a full block added
 * at the end): no two threads write one block, and the sums do not depend on the thread
 * count. Each cell's factor is looked up once (into the scratch fe) instead of per corner.
 */
/* Each cell's factor (NaN: graded) into the element pass's scratch fe (kf not NULL), read
 * once per cell by diag_node instead of 8 times (once per corner). */
static const double *cell_factors(cs_fem *fem, const double *kf)
{
    double *fc = fem->fe;
    if (kf) {
#pragma omp parallel for num_threads(fem->threads) schedule(static)
        for (int c = 0; c < fem->n_cells; c++) {
            double f;
            fc[c] = uniform_factor(kf, c, &f) ? f : NAN;
        }
    }
    return fc;
}

/* Node n's diagonal block of Σ R K_w Rᵀ into B (9, overwritten); fc from cell_factors. */
static inline __attribute__((always_inline)) void diag_node(const cs_fem *fem, const double *kf,
                                                            const double *fc, int n, double *B)
{
    const double alpha = fem->K[0], beta = fem->K[1], ab = alpha - beta;
    static const double I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    const int32_t *restrict as = fem->adj_start, *restrict adj = fem->adj;
    const uint8_t *act = fem->cell_active;
    const double *Rs = fem->corotational ? fem->R : NULL;
    if (!kf && !act && Rs) {
        /* every cell rotated, factor 1 (f·β = β, f·(α − β) = α − β exactly): the loop below
         * without its lookups and its graded branch, whose 9 sums crowd the registers */
        double b00 = 0, b01 = 0, b02 = 0, b11 = 0, b12 = 0, b22 = 0;
        for (int a = as[n]; a < as[n + 1]; a++) {
            const int k = adj[a] & 7;
            const double *R = Rs + 9 * (size_t)(adj[a] >> 3);
            const double s0 = SGN[k][0], s1 = SGN[k][1], s2 = SGN[k][2];
            const double v0 = R[0] * s0 + R[1] * s1 + R[2] * s2;
            const double v1 = R[3] * s0 + R[4] * s1 + R[5] * s2;
            const double v2 = R[6] * s0 + R[7] * s1 + R[8] * s2;
            const double t0 = beta * v0, t1 = beta * v1, t2 = beta * v2;
            b00 += t0 * v0 + ab;
            b01 += t0 * v1;
            b02 += t0 * v2;
            b11 += t1 * v1 + ab;
            b12 += t1 * v2;
            b22 += t2 * v2 + ab;
        }
        B[0] = b00;
        B[1] = B[3] = b01;
        B[2] = B[6] = b02;
        B[4] = b11;
        B[5] = B[7] = b12;
        B[8] = b22;
        return;
    }
    /* the symmetric part of the uniform cells' sum in 6 entries, graded cells in G */
    double b00 = 0, b01 = 0, b02 = 0, b11 = 0, b12 = 0, b22 = 0, G[9] = {0};
    bool graded = false;
    for (int a = as[n]; a < as[n + 1]; a++) {
        const int c = adj[a] >> 3, k = adj[a] & 7;
        if (act && !act[c])
            continue;
        const double *R = Rs ? Rs + 9 * (size_t)c : I;
        const double f = kf ? fc[c] : 1.0;
        if (!isnan(f)) {
            const double s0 = SGN[k][0], s1 = SGN[k][1], s2 = SGN[k][2];
            const double v0 = R[0] * s0 + R[1] * s1 + R[2] * s2;
            const double v1 = R[3] * s0 + R[4] * s1 + R[5] * s2;
            const double v2 = R[6] * s0 + R[7] * s1 + R[8] * s2;
            const double fb = f * beta, fd = f * ab;
            const double t0 = fb * v0, t1 = fb * v1, t2 = fb * v2;
            b00 += t0 * v0 + fd;
            b01 += t0 * v1;
            b02 += t0 * v2;
            b11 += t1 * v1 + fd;
            b12 += t1 * v2;
            b22 += t2 * v2 + fd;
            continue;
        }
        graded = true;
        double Kk[9], T[9];
        const int at = (3 * k) * 24 + 3 * k;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                double sum = 0;
                for (int g = 0; g < 8; g++)
                    sum += kf[8 * (size_t)c + g] * fem->Kg[576 * g + at + 24 * i + j];
                Kk[3 * i + j] = sum;
            }
        /* T = R Kk, then B += T Rᵀ */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                T[3 * i + j] = R[3 * i] * Kk[j] + R[3 * i + 1] * Kk[3 + j] +
                               R[3 * i + 2] * Kk[6 + j];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                G[3 * i + j] += T[3 * i] * R[3 * j] + T[3 * i + 1] * R[3 * j + 1] +
                                T[3 * i + 2] * R[3 * j + 2];
    }
    B[0] = b00;
    B[1] = B[3] = b01;
    B[2] = B[6] = b02;
    B[4] = b11;
    B[5] = B[7] = b12;
    B[8] = b22;
    if (graded)
        for (int i = 0; i < 9; i++)
            B[i] += G[i];
}

void cs_fem_diag_blocks_w(cs_fem *fem, const double *kf, double *blocks)
{
    const double *fc = cell_factors(fem, kf);
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int n = 0; n < fem->n_nodes; n++)
        diag_node(fem, kf, fc, n, blocks + 9 * (size_t)n);
}

/*
 * cs_fem_precond_blocks' plain case (every cell rotated, factor 1, no active region: diag_node's
 * first branch) with AVX-512, 8 nodes [n0, n0 + 8) ∩ [0, n_nodes) side by side, one per lane:
 * each lane sums its cells in adj order with diag_node's operations (its cells' rotations
 * gathered; a corner sign ±1 times an entry is the entry or its negative, as in the scalar
 * product), then scales, shifts and inverts with the operations of the loop below and of
 * cs_mat3_invert_block (its branch per lane), without fused multiply-adds: every block is the
 * scalar one's bit for bit (test_fem_setup). The scalar code inverts a block after another,
 * each a chain of dependent operations (about 37 ns a node on two threads of the Xeon of
 * sessions 47-49, 0.7 ms for the 75×15×15 beam: every rebuild of a lagged hierarchy).
 */
__attribute__((target("arch=x86-64-v4"))) static void
precond_blocks_avx512(const cs_fem *fem, double kcoef, const cs_fem_node_terms *t, int n0,
                      double *blocks)
{
    const int lanes = fem->n_nodes - n0 < 8 ? fem->n_nodes - n0 : 8;
    const __mmask8 in = (__mmask8)((1u << lanes) - 1);
    const __m256i first = _mm256_maskz_loadu_epi32(in, fem->adj_start + n0);
    const __m256i cnt =
        _mm256_sub_epi32(_mm256_maskz_loadu_epi32(in, fem->adj_start + n0 + 1), first);
    int most = 0; /* the most cells of a lane's node */
    for (int l = 0; l < lanes; l++) {
        const int c = fem->adj_start[n0 + l + 1] - fem->adj_start[n0 + l];
        most = c > most ? c : most;
    }
    const __m512d beta = _mm512_set1_pd(fem->K[1]), ab = _mm512_set1_pd(fem->K[0] - fem->K[1]);
    const __m512d sx = _mm512_setr_pd(SGN[0][0], SGN[1][0], SGN[2][0], SGN[3][0], SGN[4][0],
                                      SGN[5][0], SGN[6][0], SGN[7][0]),
                  sy = _mm512_setr_pd(SGN[0][1], SGN[1][1], SGN[2][1], SGN[3][1], SGN[4][1],
                                      SGN[5][1], SGN[6][1], SGN[7][1]),
                  sz = _mm512_setr_pd(SGN[0][2], SGN[1][2], SGN[2][2], SGN[3][2], SGN[4][2],
                                      SGN[5][2], SGN[6][2], SGN[7][2]);
    __m512d b00 = _mm512_setzero_pd(), b01 = b00, b02 = b00, b11 = b00, b12 = b00, b22 = b00;
    for (int a = 0; a < most; a++) {
        const __mmask8 live = _mm256_mask_cmpgt_epi32_mask(in, cnt, _mm256_set1_epi32(a));
        const __m256i e = _mm256_mmask_i32gather_epi32(
            _mm256_setzero_si256(), live, _mm256_add_epi32(first, _mm256_set1_epi32(a)), fem->adj,
            4);
        const __m512i k = _mm512_cvtepi32_epi64(_mm256_and_si256(e, _mm256_set1_epi32(7)));
        const __m256i base = _mm256_mullo_epi32(_mm256_srli_epi32(e, 3), _mm256_set1_epi32(9));
        __m512d R[9];
        for (int j = 0; j < 9; j++)
            R[j] = _mm512_mask_i32gather_pd(
                _mm512_setzero_pd(), live, _mm256_add_epi32(base, _mm256_set1_epi32(j)), fem->R, 8);
        const __m512d s0 = _mm512_permutexvar_pd(k, sx), s1 = _mm512_permutexvar_pd(k, sy),
                      s2 = _mm512_permutexvar_pd(k, sz);
        const __m512d v0 =
            _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(R[0], s0), _mm512_mul_pd(R[1], s1)),
                          _mm512_mul_pd(R[2], s2));
        const __m512d v1 =
            _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(R[3], s0), _mm512_mul_pd(R[4], s1)),
                          _mm512_mul_pd(R[5], s2));
        const __m512d v2 =
            _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(R[6], s0), _mm512_mul_pd(R[7], s1)),
                          _mm512_mul_pd(R[8], s2));
        const __m512d t0 = _mm512_mul_pd(beta, v0), t1 = _mm512_mul_pd(beta, v1),
                      t2 = _mm512_mul_pd(beta, v2);
        b00 = _mm512_mask_add_pd(b00, live, b00, _mm512_add_pd(_mm512_mul_pd(t0, v0), ab));
        b01 = _mm512_mask_add_pd(b01, live, b01, _mm512_mul_pd(t0, v1));
        b02 = _mm512_mask_add_pd(b02, live, b02, _mm512_mul_pd(t0, v2));
        b11 = _mm512_mask_add_pd(b11, live, b11, _mm512_add_pd(_mm512_mul_pd(t1, v1), ab));
        b12 = _mm512_mask_add_pd(b12, live, b12, _mm512_mul_pd(t1, v2));
        b22 = _mm512_mask_add_pd(b22, live, b22, _mm512_add_pd(_mm512_mul_pd(t2, v2), ab));
    }
    double dd[8] = {0};
    for (int l = 0; l < lanes; l++) {
        const int n = n0 + l;
        dd[l] =
            t->mcoef * t->m[n] + (t->md ? t->cmcoef * t->md[n] : 0.0) + (t->pin[n] ? t->pk : 0.0);
    }
    const __m512d d = _mm512_loadu_pd(dd), kc = _mm512_set1_pd(kcoef);
    __m512d m[9];
    m[0] = _mm512_add_pd(_mm512_mul_pd(b00, kc), d);
    m[1] = m[3] = _mm512_mul_pd(b01, kc);
    m[2] = m[6] = _mm512_mul_pd(b02, kc);
    m[4] = _mm512_add_pd(_mm512_mul_pd(b11, kc), d);
    m[5] = m[7] = _mm512_mul_pd(b12, kc);
    m[8] = _mm512_add_pd(_mm512_mul_pd(b22, kc), d);
#define PB_DIFF(a, b, c, e) _mm512_sub_pd(_mm512_mul_pd(m[a], m[b]), _mm512_mul_pd(m[c], m[e]))
    __m512d c[9];
    c[0] = PB_DIFF(4, 8, 5, 7);
    c[1] = PB_DIFF(2, 7, 1, 8);
    c[2] = PB_DIFF(1, 5, 2, 4);
    c[3] = PB_DIFF(5, 6, 3, 8);
    c[4] = PB_DIFF(0, 8, 2, 6);
    c[5] = PB_DIFF(2, 3, 0, 5);
    c[6] = PB_DIFF(3, 7, 4, 6);
    c[7] = PB_DIFF(1, 6, 0, 7);
    c[8] = PB_DIFF(0, 4, 1, 3);
#undef PB_DIFF
    const __m512d det =
        _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(m[0], c[0]), _mm512_mul_pd(m[1], c[3])),
                      _mm512_mul_pd(m[2], c[6]));
    const __m512d scale =
        _mm512_add_pd(_mm512_add_pd(_mm512_abs_pd(m[0]), _mm512_abs_pd(m[4])), _mm512_abs_pd(m[8]));
    const __m512d thr =
        _mm512_mul_pd(_mm512_mul_pd(_mm512_mul_pd(_mm512_set1_pd(1e-12), scale), scale), scale);
    const __mmask8 ok = _mm512_cmp_pd_mask(_mm512_abs_pd(det), thr, _CMP_GT_OQ) &
                        _mm512_cmp_pd_mask(det, _mm512_setzero_pd(), _CMP_NEQ_UQ);
    const __m512d one = _mm512_set1_pd(1.0);
    const __m512d id = _mm512_div_pd(one, _mm512_mask_blend_pd(ok, one, det));
    __m512d out[9];
    for (int j = 0; j < 9; j++)
        out[j] = _mm512_maskz_mul_pd(ok, c[j], id);
    for (int j = 0; j < 3; j++) { /* the fallback's diagonal: 1/d, or 1 where d = 0 */
        const __mmask8 nz = _mm512_cmp_pd_mask(m[4 * j], _mm512_setzero_pd(), _CMP_NEQ_UQ);
        const __m512d inv = _mm512_mask_div_pd(one, nz, one, m[4 * j]);
        out[4 * j] = _mm512_mask_blend_pd(ok, inv, out[4 * j]);
    }
    double buf[9][8];
    for (int j = 0; j < 9; j++)
        _mm512_storeu_pd(buf[j], out[j]);
    for (int l = 0; l < lanes; l++)
        for (int j = 0; j < 9; j++)
            blocks[9 * (size_t)(n0 + l) + j] = buf[j][l];
}

void cs_fem_precond_blocks(cs_fem *fem, const double *kf, double kcoef, const cs_fem_node_terms *t,
                           double *blocks)
{
    if (!kf && !fem->cell_active && fem->corotational && __builtin_cpu_supports("x86-64-v4") &&
        (size_t)9 * fem->n_cells < (size_t)INT32_MAX) {
        const int ng = (fem->n_nodes + 7) / 8;
#pragma omp parallel for num_threads(fem->threads) schedule(static)
        for (int g = 0; g < ng; g++)
            precond_blocks_avx512(fem, kcoef, t, 8 * g, blocks);
        return;
    }
    const double *fc = cell_factors(fem, kf);
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int n = 0; n < fem->n_nodes; n++) {
        double *B = blocks + 9 * (size_t)n;
        diag_node(fem, kf, fc, n, B);
        for (int k = 0; k < 9; k++)
            B[k] *= kcoef;
        const double d =
            t->mcoef * t->m[n] + (t->md ? t->cmcoef * t->md[n] : 0.0) + (t->pin[n] ? t->pk : 0.0);
        for (int a = 0; a < 3; a++)
            B[4 * a] += d;
        cs_mat3_invert_block(B);
    }
}

int cs_fem_prepare_tangent(cs_fem *fem, const double *x)
{
    if (!fem->tg) {
        fem->tg = malloc((size_t)fem->n_cells * 33 * sizeof *fem->tg);
        if (!fem->tg)
            return -1;
    }
    const double h = fem->h, inv4h = 1.0 / (4.0 * h);
    const int nb = n_batches(fem->n_cells);
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int bt = 0; bt < nb; bt++) {
      const int c0 = bt * LANES;
      double us[24 * LANES], kus[24 * LANES];
      for (int l = 0; l < LANES; l++) {
        const int c = c0 + l;
        if (c >= fem->n_cells)
            break;
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        double *G = fem->tg + 33 * c;
        double F[9] = {0}, S[9], *u = us + 24 * l;
        const double *x0 = x + 3 * nd[0];
        for (int k = 0; k < 8; k++) {
            const double *p = x + 3 * nd[k];
            const double d[3] = {p[0] - x0[0], p[1] - x0[1], p[2] - x0[2]};
            for (int i = 0; i < 3; i++) {
                for (int j = 0; j < 3; j++)
                    F[3 * i + j] += p[i] * SGN[k][j] * inv4h;
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2] -
                               h * CS_CORNER[k][i];
            }
        }
        /* S = Rᵀ F, then A = tr(S)·I − S (symmetrized), G = A⁻¹ */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                S[3 * i + j] = R[i] * F[j] + R[3 + i] * F[3 + j] + R[6 + i] * F[6 + j];
        const double tr = S[0] + S[4] + S[8];
        double A[9];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                A[3 * i + j] = (i == j ? tr : 0.0) - 0.5 * (S[3 * i + j] + S[3 * j + i]);
        double cf[9];
        const double det = cs_mat3_adjugate(A, cf);
        /* Near-inverted or degenerate elements (tr S − s_i → 0) get no geometric term. */
        if (det > 0.05)
            for (int i = 0; i < 9; i++)
                G[i] = cf[i] / det;
        else
            memset(G, 0, 9 * sizeof *G);
      }
      batch_local(fem, fem->kf, c0, us, kus);
      for (int l = 0; l < LANES && c0 + l < fem->n_cells; l++)
          memcpy(fem->tg + 33 * (size_t)(c0 + l) + 9, kus + 24 * l, 24 * sizeof *kus);
    }
    return 0;
}

void cs_fem_release_tangent(cs_fem *fem)
{
    free(fem->tg);
    fem->tg = NULL;
}

typedef struct tangent_ctx {
    const double *p;
} tangent_ctx;

static void tangent_batch(cs_fem *fem, int bt, double *fb, const void *ctx, double *e_sum)
{
      (void)e_sum;
      const double *p = ((const tangent_ctx *)ctx)->p;
      const double inv4h = 1.0 / (4.0 * fem->h);
      const int c0 = bt * LANES;
      double qs[24 * LANES], kqs[24 * LANES], as[LANES][3], bs[LANES][3], lanes[24 * LANES];
      const bool row = fem->rowb[4 * bt] >= 0;
      for (int l = 0; l < LANES && c0 + l < fem->n_cells; l++) {
        const int c = c0 + l;
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        const double *ku = fem->tg + 33 * c + 9;
        double *q = qs + 24 * l, *a = as[l], *b = bs[l];
        a[0] = a[1] = a[2] = b[0] = b[1] = b[2] = 0;
        for (int k = 0; k < 8; k++) {
            const double *d = p + 3 * nd[k];
            double *qk = q + 3 * k, t[3];
            for (int i = 0; i < 3; i++)
                qk[i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
            cs_vec3_cross(SGN[k], qk, t);
            for (int i = 0; i < 3; i++)
                a[i] += inv4h * t[i];
            cs_vec3_cross(ku + 3 * k, qk, t);
            for (int i = 0; i < 3; i++)
                b[i] += t[i];
        }
      }
      batch_local(fem, fem->kf, c0, qs, kqs);
      for (int l = 0; l < LANES && c0 + l < fem->n_cells; l++) {
        const int c = c0 + l;
        const double *R = fem->R + 9 * c;
        const double *G = fem->tg + 33 * c, *ku = G + 9, *kq = kqs + 24 * l;
        const double *a = as[l], *b = bs[l];
        double w1[3], w2[3];
        for (int i = 0; i < 3; i++) {
            w1[i] = G[3 * i] * a[0] + G[3 * i + 1] * a[1] + G[3 * i + 2] * a[2];
            w2[i] = G[3 * i] * b[0] + G[3 * i + 1] * b[1] + G[3 * i + 2] * b[2];
        }
        double *out = (row ? lanes : fb) + 24 * l;
        for (int k = 0; k < 8; k++) {
            double g1[3], g2[3], l3[3];
            cs_vec3_cross(w1, ku + 3 * k, g1);
            cs_vec3_cross(w2, SGN[k], g2);
            for (int i = 0; i < 3; i++)
                l3[i] = kq[3 * k + i] + 0.5 * (g1[i] + inv4h * g2[i]);
            for (int i = 0; i < 3; i++)
                out[3 * k + i] = R[3 * i] * l3[0] + R[3 * i + 1] * l3[1] + R[3 * i + 2] * l3[2];
        }
      }
      if (row)
          row_store(fem, c0, lanes, fb);
}

void cs_fem_apply_tangent(cs_fem *fem, const double *p, double *y)
{
    const tangent_ctx tc = {p};
    fused_pass(fem, tangent_batch, &tc, y, 1.0, NULL);
}
