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

#include "cubesim.h"
#include "mat3.h"

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
    R[0] = 1 - 2 * (y * y + z * z);
    R[1] = 2 * (x * y - w * z);
    R[2] = 2 * (x * z + w * y);
    R[3] = 2 * (x * y + w * z);
    R[4] = 1 - 2 * (x * x + z * z);
    R[5] = 2 * (y * z - w * x);
    R[6] = 2 * (x * z - w * y);
    R[7] = 2 * (y * z + w * x);
    R[8] = 1 - 2 * (x * x + y * y);
}

void cs_extract_rotation(const double A[9], double q[4], int max_iter)
{
    for (int it = 0; it < max_iter; it++) {
        double R[9], om[3] = {0, 0, 0}, den = 0;
        cs_quat_to_mat(q, R);
        for (int c = 0; c < 3; c++) {
            const double r[3] = {R[c], R[3 + c], R[6 + c]};
            const double a[3] = {A[c], A[3 + c], A[6 + c]};
            om[0] += r[1] * a[2] - r[2] * a[1];
            om[1] += r[2] * a[0] - r[0] * a[2];
            om[2] += r[0] * a[1] - r[1] * a[0];
            den += r[0] * a[0] + r[1] * a[1] + r[2] * a[2];
        }
        const double s = 1.0 / (fabs(den) + 1e-9);
        om[0] *= s;
        om[1] *= s;
        om[2] *= s;
        const double wn = sqrt(om[0] * om[0] + om[1] * om[1] + om[2] * om[2]);
        if (wn < 1e-12)
            break;
        /* The update quaternion exp(ω/2). For small steps (the warm-started case) the
         * first-order [1, ω/2], normalized below, avoids sin/cos; it rotates by
         * 2·atan(|ω|/2) instead of |ω|, which changes how fast the iteration converges, not
         * where: it stops where ω = 0. */
        double d[4];
        if (wn < 0.3) {
            d[0] = 1.0;
            d[1] = 0.5 * om[0];
            d[2] = 0.5 * om[1];
            d[3] = 0.5 * om[2];
        } else {
            const double half = 0.5 * wn, sh = sin(half) / wn;
            d[0] = cos(half);
            d[1] = om[0] * sh;
            d[2] = om[1] * sh;
            d[3] = om[2] * sh;
        }
        const double n[4] = {
            d[0] * q[0] - d[1] * q[1] - d[2] * q[2] - d[3] * q[3],
            d[0] * q[1] + d[1] * q[0] + d[2] * q[3] - d[3] * q[2],
            d[0] * q[2] - d[1] * q[3] + d[2] * q[0] + d[3] * q[1],
            d[0] * q[3] + d[1] * q[2] - d[2] * q[1] + d[3] * q[0],
        };
        const double nn = 1.0 / sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] + n[3] * n[3]);
        for (int i = 0; i < 4; i++)
            q[i] = n[i] * nn;
        if (wn < 1e-9)
            break;
    }
}

int cs_fem_relink(cs_fem *fem, const cs_cubemesh *cm)
{
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
    return 0;
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
    fem->fe = malloc((size_t)cm->n_cells * 24 * sizeof *fem->fe);
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

void cs_fem_update_rotations(cs_fem *fem, const double *x)
{
    if (!fem->corotational)
        return;
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int c = 0; c < fem->n_cells; c++) {
        if (fem->cell_active && !fem->cell_active[c])
            continue;
        double F[9];
        centre_gradient(fem, x, c, F);
        cs_extract_rotation(F, fem->q + 4 * c, 30);
        cs_quat_to_mat(fem->q + 4 * c, fem->R + 9 * c);
    }
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
__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4")))
static void modal_kernel_avx512(mlanes *restrict b, int rot, double rest, int energy)
{
    for (int h = 0; h < LANES; h += 4) {
        vd4 u[24], R[9], y[24], e, L, M;
        const double *x = b->x;
        for (int k = 0; k < 8; k++) {
            const int32_t *ix = b->ix[k] + h;
            const __m256d r0 = _mm256_maskz_loadu_pd(7, x + ix[0]);
            const __m256d r1 = _mm256_maskz_loadu_pd(7, x + ix[1]);
            const __m256d r2 = _mm256_maskz_loadu_pd(7, x + ix[2]);
            const __m256d r3 = _mm256_maskz_loadu_pd(7, x + ix[3]);
            const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1);
            const __m256d t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3);
            u[3 * k] = (vd4)_mm256_permute2f128_pd(t0, t2, 0x20);
            u[3 * k + 1] = (vd4)_mm256_permute2f128_pd(t1, t3, 0x20);
            u[3 * k + 2] = (vd4)_mm256_permute2f128_pd(t0, t2, 0x31);
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

/*
 * One batch of cells [c0, c0 + LANES) ∩ [0, n_cells): fe[24c..] = R_c K_c (R_cᵀ x − rest)
 * (Rb: the rotations of the batch's cells, 9 each from c0, NULL: none; fe NULL: not stored)
 * and, if e, the energies per lane (0 past the end). Uniform cells go through the modal
 * kernel together, graded ones point by point.
 */
static void batch_product(const cs_fem *fem, const double *kf, int c0, const double *Rb,
                          const double *x, double rest, double *fe, double e[LANES])
{
    const double c16 = fem->h / 16.0;
    double sink[24];
    mlanes B;
    int graded = 0, first = -1;
    int live = 0;
    B.x = x;
    B.R = Rb;
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
            B.out[l] = fe ? fe + 24 * (size_t)c : sink;
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
                        Rb ? Rb + 9 * l : NULL, x, rest, fe ? fe + 24 * (size_t)c : NULL,
                        e ? e + l : NULL);
        else if (e)
            e[l] = B.e[l];
    }
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

double cs_fem_energy(const cs_fem *fem, const double *x)
{
    double e_sum = 0;
    for (int c0 = 0; c0 < fem->n_cells; c0 += LANES) {
        double Rb[9 * LANES], e[LANES];
        for (int l = 0; fem->corotational && l < LANES && c0 + l < fem->n_cells; l++) {
            double F[9], q[4];
            centre_gradient(fem, x, c0 + l, F);
            memcpy(q, fem->q + 4 * (size_t)(c0 + l), sizeof q);
            cs_extract_rotation(F, q, 30);
            cs_quat_to_mat(q, Rb + 9 * l);
        }
        batch_product(fem, fem->kf, c0, fem->corotational ? Rb : NULL, x, fem->h, NULL, e);
        for (int l = 0; l < LANES; l++)
            e_sum += e[l];
    }
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

/* Node pass: out[n] = sign · Σ fe over the node's (cell, corner) slots, in a fixed order. */
static void gather(cs_fem *fem, double *out, double sign)
{
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int n = 0; n < fem->n_nodes; n++) {
        double s0 = 0, s1 = 0, s2 = 0;
        for (int a = fem->adj_start[n]; a < fem->adj_start[n + 1]; a++) {
            if (fem->cell_active && !fem->cell_active[fem->adj[a] >> 3])
                continue;
            const double *v = fem->fe + 3 * fem->adj[a];
            s0 += v[0];
            s1 += v[1];
            s2 += v[2];
        }
        out[3 * n] = sign * s0;
        out[3 * n + 1] = sign * s1;
        out[3 * n + 2] = sign * s2;
    }
}

void cs_fem_elastic_force(cs_fem *fem, const double *x, double *f, double *energy)
{
    double e_sum = 0;
    const int nb = n_batches(fem->n_cells);
#pragma omp parallel for num_threads(fem->threads) schedule(static) reduction(+ : e_sum)
    for (int b = 0; b < nb; b++) {
        const int c0 = b * LANES;
        if (!batch_active(fem, c0))
            continue;
        double e[LANES];
        batch_product(fem, fem->kf, c0, fem->corotational ? fem->R + 9 * (size_t)c0 : NULL, x,
                      fem->h, fem->fe, e);
        for (int l = 0; l < LANES; l++)
            e_sum += e[l];
    }
    gather(fem, f, -1.0);
    if (energy)
        *energy = e_sum;
}

void cs_fem_apply_K(cs_fem *fem, const double *p, double *y)
{
    cs_fem_apply_Kw(fem, fem->kf, p, y);
}

void cs_fem_apply_Kw(cs_fem *fem, const double *kf, const double *p, double *y)
{
    const int nb = n_batches(fem->n_cells);
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int b = 0; b < nb; b++) {
        const int c0 = b * LANES;
        if (!batch_active(fem, c0))
            continue;
        batch_product(fem, kf, c0, fem->corotational ? fem->R + 9 * (size_t)c0 : NULL, p, 0.0,
                      fem->fe, NULL);
    }
    gather(fem, y, 1.0);
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

void cs_fem_diag_blocks_w(cs_fem *fem, const double *kf, double *blocks)
{
    memset(blocks, 0, sizeof(double) * 9 * (size_t)fem->n_nodes);
    /* Serial: called once per step, 8·n_cells small products. */
    for (int c = 0; c < fem->n_cells; c++) {
        if (fem->cell_active && !fem->cell_active[c])
            continue;
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        bool uniform = true;
        for (int g = 1; kf && g < 8; g++)
            uniform = uniform && kf[8 * (size_t)c + g] == kf[8 * (size_t)c];
        for (int k = 0; k < 8; k++) {
            double Kk[9], T[9];
            const int at = (3 * k) * 24 + 3 * k;
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++) {
                    const int ij = at + 24 * i + j;
                    if (!kf || uniform) {
                        Kk[3 * i + j] = kf ? kf[8 * (size_t)c] * fem->K[ij] : fem->K[ij];
                        continue;
                    }
                    double s = 0;
                    for (int g = 0; g < 8; g++)
                        s += kf[8 * (size_t)c + g] * fem->Kg[576 * g + ij];
                    Kk[3 * i + j] = s;
                }
            /* T = R Kk, then blocks += T Rᵀ */
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    T[3 * i + j] = R[3 * i] * Kk[j] + R[3 * i + 1] * Kk[3 + j] +
                                   R[3 * i + 2] * Kk[6 + j];
            double *B = blocks + 9 * nd[k];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    B[3 * i + j] += T[3 * i] * R[3 * j] + T[3 * i + 1] * R[3 * j + 1] +
                                    T[3 * i + 2] * R[3 * j + 2];
        }
    }
}

static void cross3(const double a[3], const double b[3], double c[3])
{
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
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

void cs_fem_apply_tangent(cs_fem *fem, const double *p, double *y)
{
    const double inv4h = 1.0 / (4.0 * fem->h);
    const int nb = n_batches(fem->n_cells);
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int bt = 0; bt < nb; bt++) {
      const int c0 = bt * LANES;
      double qs[24 * LANES], kqs[24 * LANES], as[LANES][3], bs[LANES][3];
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
            cross3(SGN[k], qk, t);
            for (int i = 0; i < 3; i++)
                a[i] += inv4h * t[i];
            cross3(ku + 3 * k, qk, t);
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
        double *out = fem->fe + 24 * c;
        for (int k = 0; k < 8; k++) {
            double g1[3], g2[3], l3[3];
            cross3(w1, ku + 3 * k, g1);
            cross3(w2, SGN[k], g2);
            for (int i = 0; i < 3; i++)
                l3[i] = kq[3 * k + i] + 0.5 * (g1[i] + inv4h * g2[i]);
            for (int i = 0; i < 3; i++)
                out[3 * k + i] = R[3 * i] * l3[0] + R[3 * i + 1] * l3[1] + R[3 * i + 2] * l3[2];
        }
      }
    }
    gather(fem, y, 1.0);
}
