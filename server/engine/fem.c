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

/* y = K x for one element (24-vectors): the hot kernel of every product. Compiled twice,
 * for AVX2+FMA and for baseline x86-64, and picked at load time, so the binary runs on any
 * x86-64 and uses the wider units where they exist. */
__attribute__((target_clones("arch=x86-64-v3", "default"))) static void
kmul(const double *restrict K, const double *restrict x, double *restrict y)
{
    /* K is symmetric: y = Σ_j x_j K[j,:], so the 24 sums stay in vector registers. */
    double acc[24] = {0};
    for (int j = 0; j < 24; j++) {
        const double xj = x[j], *row = K + 24 * j;
        for (int i = 0; i < 24; i++)
            acc[i] += xj * row[i];
    }
    for (int i = 0; i < 24; i++)
        y[i] = acc[i];
}

static void graded_kmul(const cs_fem *fem, const double *f, const double *restrict x,
                        double *restrict y);

/* y = K_e x for cell c with the Gauss-point factors kf (8 per cell; NULL: all 1). */
static void cell_kmul(const cs_fem *fem, const double *kf, int c, const double *restrict x,
                      double *restrict y)
{
    if (!kf) {
        kmul(fem->K, x, y);
        return;
    }
    const double *f = kf + 8 * (size_t)c;
    if (f[0] == f[1] && f[0] == f[2] && f[0] == f[3] && f[0] == f[4] && f[0] == f[5] &&
        f[0] == f[6] && f[0] == f[7]) {
        kmul(fem->K, x, y);
        if (f[0] != 1.0)
            for (int i = 0; i < 24; i++)
                y[i] *= f[0];
        return;
    }
    graded_kmul(fem, f, x, y);
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

double cs_fem_energy(const cs_fem *fem, const double *x)
{
    double e_sum = 0;
    for (int c = 0; c < fem->n_cells; c++) {
        const int32_t *nd = fem->cell_nodes + 8 * c;
        double R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
        if (fem->corotational) {
            double F[9], q[4];
            centre_gradient(fem, x, c, F);
            memcpy(q, fem->q + 4 * c, sizeof q);
            cs_extract_rotation(F, q, 30);
            cs_quat_to_mat(q, R);
        }
        const double *x0 = x + 3 * nd[0];
        double u[24], ku[24], e = 0;
        for (int k = 0; k < 8; k++) {
            const double *p = x + 3 * nd[k];
            const double d[3] = {p[0] - x0[0], p[1] - x0[1], p[2] - x0[2]};
            for (int i = 0; i < 3; i++)
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2] -
                               fem->h * CS_CORNER[k][i];
        }
        cell_kmul(fem, fem->kf, c, u, ku);
        for (int i = 0; i < 24; i++)
            e += u[i] * ku[i];
        e_sum += 0.5 * e;
    }
    return e_sum;
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
    const double h = fem->h;
    double e_sum = 0;
#pragma omp parallel for num_threads(fem->threads) schedule(static) reduction(+ : e_sum)
    for (int c = 0; c < fem->n_cells; c++) {
        if (fem->cell_active && !fem->cell_active[c])
            continue;
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        const double *x0 = x + 3 * nd[0];
        double u[24], ku[24];
        for (int k = 0; k < 8; k++) {
            const double *p = x + 3 * nd[k];
            const double d[3] = {p[0] - x0[0], p[1] - x0[1], p[2] - x0[2]};
            for (int i = 0; i < 3; i++)
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2] -
                               h * CS_CORNER[k][i];
        }
        cell_kmul(fem, fem->kf, c, u, ku);
        double *out = fem->fe + 24 * c;
        double e = 0;
        for (int k = 0; k < 8; k++) {
            const double *l = ku + 3 * k;
            for (int i = 0; i < 3; i++)
                out[3 * k + i] = R[3 * i] * l[0] + R[3 * i + 1] * l[1] + R[3 * i + 2] * l[2];
            e += u[3 * k] * l[0] + u[3 * k + 1] * l[1] + u[3 * k + 2] * l[2];
        }
        e_sum += 0.5 * e;
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
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int c = 0; c < fem->n_cells; c++) {
        if (fem->cell_active && !fem->cell_active[c])
            continue;
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        double u[24], ku[24];
        for (int k = 0; k < 8; k++) {
            const double *d = p + 3 * nd[k];
            for (int i = 0; i < 3; i++)
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
        }
        cell_kmul(fem, kf, c, u, ku);
        double *out = fem->fe + 24 * c;
        for (int k = 0; k < 8; k++) {
            const double *l = ku + 3 * k;
            for (int i = 0; i < 3; i++)
                out[3 * k + i] = R[3 * i] * l[0] + R[3 * i + 1] * l[1] + R[3 * i + 2] * l[2];
        }
    }
    gather(fem, y, 1.0);
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
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int c = 0; c < fem->n_cells; c++) {
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        double *G = fem->tg + 33 * c, *ku = G + 9;
        double F[9] = {0}, S[9], u[24];
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
        cell_kmul(fem, fem->kf, c, u, ku);
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
#pragma omp parallel for num_threads(fem->threads) schedule(static)
    for (int c = 0; c < fem->n_cells; c++) {
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        const double *G = fem->tg + 33 * c, *ku = G + 9;
        double q[24], kq[24], a[3] = {0, 0, 0}, b[3] = {0, 0, 0};
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
        cell_kmul(fem, fem->kf, c, q, kq);
        double w1[3], w2[3];
        for (int i = 0; i < 3; i++) {
            w1[i] = G[3 * i] * a[0] + G[3 * i + 1] * a[1] + G[3 * i + 2] * a[2];
            w2[i] = G[3 * i] * b[0] + G[3 * i + 1] * b[1] + G[3 * i + 2] * b[2];
        }
        double *out = fem->fe + 24 * c;
        for (int k = 0; k < 8; k++) {
            double g1[3], g2[3], l[3];
            cross3(w1, ku + 3 * k, g1);
            cross3(w2, SGN[k], g2);
            for (int i = 0; i < 3; i++)
                l[i] = kq[3 * k + i] + 0.5 * (g1[i] + inv4h * g2[i]);
            for (int i = 0; i < 3; i++)
                out[3 * k + i] = R[3 * i] * l[0] + R[3 * i + 1] * l[1] + R[3 * i + 2] * l[2];
        }
    }
    gather(fem, y, 1.0);
}
