/*
 * localframe.c — seed 001 §3.2 (dynamic representation, local frames), §3.3 (quadrature) and
 * §3.4 (regular cells as tricubic B-spline elements, the others as linear hexahedra).
 *
 * What the paper says and what we derived (its text is garbled or informal in places):
 *  - Eq. (5)–(15): K_i = ∫ Bᵀ C B dV over the element with the 64 tricubic basis functions.
 *    Eqs. (12)–(13) carry a factor 2 because they differentiate ∫ εᵀCε without the ½ of the
 *    strain energy; we use the energy ½ ∫ εᵀCε, so K = ∫ BᵀCB exactly as Eq. (5). Eq. (15)
 *    writes K as block-diagonal in x, y, z, which drops the coupling blocks K_y^x, ... that
 *    Eq. (14) itself keeps; we keep them (without them the element has no Poisson effect and
 *    is not rotation-consistent). C is Eq. (6) with engineering shear strains, which is the
 *    isotropic λ, μ form used below.
 *  - The R operator (§3.2.2, Fig. 3) is described only in words: "the i-th row of Rd" sums
 *    signed edge-length changes and the vectors a'−a, b'−b that undo the face-angle changes.
 *    That sum is not a displacement field on which K_i = ∫BᵀCB acts consistently (a
 *    stretched element would get forces proportional to a Laplacian of its displacement),
 *    so we derive R_i from what the paper wants of it: d̂_i are "the relative nodal
 *    displacements due to stretching and shearing" measured in the element's moving frame
 *    u–v–w (Figs. 4, 5), invariant under rigid motion. The frame is spanned by the element's
 *    edge directions at its centre (the columns of F = ∂x/∂X); their length changes are the
 *    edge-length changes and their angle changes the face-angle changes. Fig. 3 removes a
 *    face-angle change by rotating *both* edges a and b about the node, i.e. splits it
 *    evenly between them: the frame rotation with that property is the polar rotation R of
 *    F (RᵀF symmetric), and d̂ = Rᵀ(x − x_ref) − (X − X_ref). Its linearization is exactly
 *    the small-strain ε (diagonal: edge stretches, off-diagonal: half the angle changes).
 *  - §3.2.1 mass and damping: M_i = ∫μ ΓᵀΓ, D_i = ∫γ ΓᵀΓ; the engine's damping is Rayleigh
 *    (α M + β K), whose mass part is this D_i with γ = α μ (world.c uses it).
 *  - §3.3: four Gauss points per axis, exact here: the integrands are polynomials of degree
 *    at most 6 per axis.
 */
#include "localframe.h"

#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "fem.h"
#include "solver.h"

/* Gauss–Legendre, 4 points on [0,1]. */
static void gauss4(double xg[4], double wg[4])
{
    const double a = sqrt(3.0 / 7.0 - 2.0 / 7.0 * sqrt(6.0 / 5.0));
    const double b = sqrt(3.0 / 7.0 + 2.0 / 7.0 * sqrt(6.0 / 5.0));
    const double wa = (18.0 + sqrt(30.0)) / 36.0, wb = (18.0 - sqrt(30.0)) / 36.0;
    const double x[4] = {-b, -a, a, b}, w[4] = {wb, wa, wa, wb};
    for (int i = 0; i < 4; i++) {
        xg[i] = 0.5 * (1.0 + x[i]);
        wg[i] = 0.5 * w[i];
    }
}

void cs_bspline_basis(double t, double b[4], double db[4])
{
    const double s = 1.0 - t, t2 = t * t, t3 = t2 * t;
    b[0] = s * s * s / 6.0;
    b[1] = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0;
    b[2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0;
    b[3] = t3 / 6.0;
    if (db) {
        db[0] = -0.5 * s * s;
        db[1] = 0.5 * (3.0 * t2 - 4.0 * t);
        db[2] = 0.5 * (-3.0 * t2 + 2.0 * t + 1.0);
        db[3] = 0.5 * t2;
    }
}

static void axis_basis(int nb, double t, double *N, double *dN)
{
    if (nb == 2) {
        N[0] = 1.0 - t;
        N[1] = t;
        dN[0] = -1.0;
        dN[1] = 1.0;
    } else {
        cs_bspline_basis(t, N, dN);
    }
}

/*
 * K (3n×3n) and M (n×n) of one element with nb basis functions per axis (2: trilinear,
 * 4: tricubic B-spline), nodes in lexicographic order a = ix + nb·iy + nb²·iz.
 */
static void element_matrices_oct(int nb, int oct, double lambda, double mu, double rho, double h,
                                 double *K, double *M)
{
    const int n = nb * nb * nb, n3 = 3 * n;
    double xg[4], wg[4];
    gauss4(xg, wg);
    memset(K, 0, sizeof(double) * (size_t)n3 * n3);
    memset(M, 0, sizeof(double) * (size_t)n * n);
    double N[64], g[64][3];
    for (int gz = 0; gz < 4; gz++)
        for (int gy = 0; gy < 4; gy++)
            for (int gx = 0; gx < 4; gx++) {
                /* oct ≥ 0: only the points of that octant (the 2×2×2 Gauss point g = oct of
                 * the fields nearest to them) */
                if (oct >= 0 && ((gx >= 2) != CS_CORNER[oct][0] || (gy >= 2) != CS_CORNER[oct][1] ||
                                 (gz >= 2) != CS_CORNER[oct][2]))
                    continue;
                const double w = wg[gx] * wg[gy] * wg[gz] * h * h * h;
                double Nx[4], Ny[4], Nz[4], dx[4], dy[4], dz[4];
                axis_basis(nb, xg[gx], Nx, dx);
                axis_basis(nb, xg[gy], Ny, dy);
                axis_basis(nb, xg[gz], Nz, dz);
                for (int iz = 0, a = 0; iz < nb; iz++)
                    for (int iy = 0; iy < nb; iy++)
                        for (int ix = 0; ix < nb; ix++, a++) {
                            N[a] = Nx[ix] * Ny[iy] * Nz[iz];
                            g[a][0] = dx[ix] * Ny[iy] * Nz[iz] / h;
                            g[a][1] = Nx[ix] * dy[iy] * Nz[iz] / h;
                            g[a][2] = Nx[ix] * Ny[iy] * dz[iz] / h;
                        }
                for (int a = 0; a < n; a++)
                    for (int b = 0; b < n; b++) {
                        M[a * n + b] += rho * w * N[a] * N[b];
                        const double dot = g[a][0] * g[b][0] + g[a][1] * g[b][1] + g[a][2] * g[b][2];
                        for (int i = 0; i < 3; i++)
                            for (int j = 0; j < 3; j++)
                                K[(size_t)(3 * a + i) * n3 + 3 * b + j] +=
                                    w * (lambda * g[a][i] * g[b][j] + mu * g[a][j] * g[b][i] +
                                         (i == j ? mu * dot : 0.0));
                    }
            }
}

static void element_matrices(int nb, double lambda, double mu, double rho, double h, double *K,
                             double *M)
{
    element_matrices_oct(nb, -1, lambda, mu, rho, h, K, M);
}

/* Lexicographic index of corner k of a linear element. */
static int corner_lex(int k)
{
    return CS_CORNER[k][0] + 2 * CS_CORNER[k][1] + 4 * CS_CORNER[k][2];
}

/* The linear element in corner order. */
static void linear_matrices_oct(int oct, double lambda, double mu, double rho, double h,
                                double Kl[576], double Ml[64])
{
    double K[576], M[64];
    element_matrices_oct(2, oct, lambda, mu, rho, h, K, M);
    for (int k = 0; k < 8; k++)
        for (int l = 0; l < 8; l++) {
            const int a = corner_lex(k), b = corner_lex(l);
            Ml[8 * k + l] = M[8 * a + b];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    Kl[(3 * k + i) * 24 + 3 * l + j] = K[(3 * a + i) * 24 + 3 * b + j];
        }
}

static void linear_matrices(double lambda, double mu, double rho, double h, double Kl[576],
                            double Ml[64])
{
    linear_matrices_oct(-1, lambda, mu, rho, h, Kl, Ml);
}

static void lame(double young, double poisson, double *lambda, double *mu)
{
    *lambda = young * poisson / ((1 + poisson) * (1 - 2 * poisson));
    *mu = young / (2 * (1 + poisson));
}

/* ---------------------------------------------------------------- classification */

int cs_lf_classify(cs_cubemesh *cm)
{
    free(cm->spline_nodes);
    cm->spline_nodes = malloc((size_t)(cm->n_cells ? cm->n_cells : 1) * 64 * sizeof(int32_t));
    if (!cm->spline_nodes)
        return -1;
    int count = 0;
    for (int c = 0; c < cm->n_cells; c++) {
        int32_t *t = cm->spline_nodes + 64 * (size_t)c;
        for (int a = 0; a < 64; a++)
            t[a] = -1;
        const int32_t *q = cm->cell_ijk + 3 * (size_t)c;
        bool ok = true;
        for (int dz = -1; dz <= 1 && ok; dz++)
            for (int dy = -1; dy <= 1 && ok; dy++)
                for (int dx = -1; dx <= 1 && ok; dx++) {
                    const int32_t nb = cs_cubemesh_find(cm, q[0] + dx, q[1] + dy, q[2] + dz);
                    if (nb < 0) {
                        ok = false;
                        break;
                    }
                    for (int k = 0; k < 8; k++) {
                        const int a = (dx + 1 + CS_CORNER[k][0]) + 4 * (dy + 1 + CS_CORNER[k][1]) +
                                      16 * (dz + 1 + CS_CORNER[k][2]);
                        const int32_t node = cm->cell_nodes[8 * (size_t)nb + k];
                        if (t[a] < 0)
                            t[a] = node;
                        else if (t[a] != node)
                            ok = false; /* neighbours do not share this node: cut */
                    }
                }
        if (ok)
            count++;
        else
            t[0] = -1;
    }
    return count;
}

/* ---------------------------------------------------------------- lifetime */

void cs_lf_free(cs_lf *lf)
{
    if (!lf)
        return;
    free(lf->Ks);
    free(lf->Ms);
    free(lf->Kso);
    free(lf->Kso_l);
    free(lf->off);
    free(lf->en);
    free(lf->R);
    free(lf->q);
    free(lf->fe);
    free(lf->adj_start);
    free(lf->adj);
    free(lf->mrow);
    free(lf->mdiag);
    memset(lf, 0, sizeof *lf);
}

void cs_lf_reset(cs_lf *lf)
{
    static const double I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    for (int c = 0; c < lf->n_cells; c++) {
        memcpy(lf->R + 9 * (size_t)c, I, sizeof I);
        double *q = lf->q + 4 * (size_t)c;
        q[0] = 1;
        q[1] = q[2] = q[3] = 0;
    }
}

/* Whether cell c's 8 factors in w are equal (w NULL: all 1); *u their value. */
static bool uniform_factor(const double *w, int c, double *u)
{
    if (!w) {
        *u = 1.0;
        return true;
    }
    const double *f = w + 8 * (size_t)c;
    *u = f[0];
    for (int g = 1; g < 8; g++)
        if (f[g] != f[0])
            return false;
    return true;
}

/* Octant g's stiffness (K of an n-node element over that eighth of the cell). */
static const double *octant_K(const cs_lf *lf, int n, int g)
{
    return n == 64 ? lf->Kso + (size_t)g * 192 * 192 : lf->Kso_l + (size_t)g * 640;
}

/* Octant g's 1-D half-span Gram matrix along axis a. */
static const double *octant_m1(const cs_lf *lf, int g, int a)
{
    return lf->m1h + 16 * CS_CORNER[g][a];
}

/* Consistent-mass row sums and diagonal (with the density factors km). */
static void mass_rows(cs_lf *lf)
{
    memset(lf->mrow, 0, (size_t)lf->n_nodes * sizeof(double));
    memset(lf->mdiag, 0, (size_t)lf->n_nodes * sizeof(double));
    for (int c = 0; c < lf->n_cells; c++) {
        const int n = lf->off[c + 1] - lf->off[c];
        const double *M = n == 64 ? lf->Ms : lf->Ml;
        const int32_t *nd = lf->en + lf->off[c];
        double sc;
        if (uniform_factor(lf->km, c, &sc)) {
            for (int a = 0; a < n; a++) {
                double r = 0;
                for (int b = 0; b < n; b++)
                    r += M[a * n + b];
                lf->mrow[nd[a]] += sc * r;
                lf->mdiag[nd[a]] += sc * M[a * n + a];
            }
            continue;
        }
        const double *f = lf->km + 8 * (size_t)c;
        for (int g = 0; g < 8; g++) {
            if (n == 64) { /* m1scale · m1h_x ⊗ m1h_y ⊗ m1h_z */
                double rs[3][4], dg[3][4];
                for (int ax = 0; ax < 3; ax++) {
                    const double *m = octant_m1(lf, g, ax);
                    for (int i = 0; i < 4; i++) {
                        rs[ax][i] = m[4 * i] + m[4 * i + 1] + m[4 * i + 2] + m[4 * i + 3];
                        dg[ax][i] = m[5 * i];
                    }
                }
                for (int a = 0; a < 64; a++) {
                    const int ix = a % 4, iy = (a / 4) % 4, iz = a / 16;
                    lf->mrow[nd[a]] += f[g] * lf->m1scale * rs[0][ix] * rs[1][iy] * rs[2][iz];
                    lf->mdiag[nd[a]] += f[g] * lf->m1scale * dg[0][ix] * dg[1][iy] * dg[2][iz];
                }
            } else {
                const double *Mg = lf->Kso_l + (size_t)g * 640 + 576;
                for (int a = 0; a < 8; a++) {
                    double r = 0;
                    for (int b = 0; b < 8; b++)
                        r += Mg[8 * a + b];
                    lf->mrow[nd[a]] += f[g] * r;
                    lf->mdiag[nd[a]] += f[g] * Mg[9 * a];
                }
            }
        }
    }
}

void cs_lf_set_fields(cs_lf *lf, const double *young, const double *density)
{
    lf->ky = young;
    lf->km = density;
    if (lf->mrow && lf->mdiag && lf->off)
        mass_rows(lf);
}

int cs_lf_relink(cs_lf *lf, cs_cubemesh *cm)
{
    const int ns = cs_lf_classify(cm);
    if (ns < 0)
        return -1;
    const bool same_cells = lf->R && lf->n_cells == cm->n_cells;
    free(lf->off);
    free(lf->en);
    free(lf->fe);
    free(lf->adj_start);
    free(lf->adj);
    free(lf->mrow);
    free(lf->mdiag);
    lf->off = NULL;
    lf->en = NULL;
    lf->fe = NULL;
    lf->adj_start = lf->adj = NULL;
    lf->mrow = lf->mdiag = NULL;
    lf->n_spline = ns;
    lf->n_nodes = cm->n_nodes;
    if (!same_cells) {
        free(lf->R);
        free(lf->q);
        lf->n_cells = cm->n_cells;
        lf->R = malloc((size_t)(lf->n_cells ? lf->n_cells : 1) * 9 * sizeof(double));
        lf->q = malloc((size_t)(lf->n_cells ? lf->n_cells : 1) * 4 * sizeof(double));
        if (!lf->R || !lf->q)
            return -1;
        cs_lf_reset(lf);
    }
    const int nc = lf->n_cells;
    const size_t slots = (size_t)ns * 64 + (size_t)(nc - ns) * 8;
    lf->off = malloc(((size_t)nc + 1) * sizeof(int32_t));
    lf->en = malloc((slots ? slots : 1) * sizeof(int32_t));
    lf->fe = malloc((slots ? slots : 1) * 3 * sizeof(double));
    lf->adj_start = calloc((size_t)lf->n_nodes + 1, sizeof(int32_t));
    lf->adj = malloc((slots ? slots : 1) * sizeof(int32_t));
    lf->mrow = calloc((size_t)(lf->n_nodes ? lf->n_nodes : 1), sizeof(double));
    lf->mdiag = calloc((size_t)(lf->n_nodes ? lf->n_nodes : 1), sizeof(double));
    if (!lf->off || !lf->en || !lf->fe || !lf->adj_start || !lf->adj || !lf->mrow || !lf->mdiag)
        return -1;
    size_t s = 0;
    for (int c = 0; c < nc; c++) {
        lf->off[c] = (int32_t)s;
        const int32_t *sn = cm->spline_nodes + 64 * (size_t)c;
        if (sn[0] >= 0) {
            memcpy(lf->en + s, sn, 64 * sizeof(int32_t));
            s += 64;
        } else {
            memcpy(lf->en + s, cm->cell_nodes + 8 * (size_t)c, 8 * sizeof(int32_t));
            s += 8;
        }
    }
    lf->off[nc] = (int32_t)s;
    for (size_t e = 0; e < slots; e++)
        lf->adj_start[lf->en[e] + 1]++;
    for (int n = 0; n < lf->n_nodes; n++)
        lf->adj_start[n + 1] += lf->adj_start[n];
    int32_t *fill = malloc((size_t)(lf->n_nodes ? lf->n_nodes : 1) * sizeof *fill);
    if (!fill)
        return -1;
    memcpy(fill, lf->adj_start, (size_t)lf->n_nodes * sizeof *fill);
    for (size_t e = 0; e < slots; e++)
        lf->adj[fill[lf->en[e]]++] = (int32_t)e;
    free(fill);
    mass_rows(lf);
    return 0;
}

int cs_lf_init(cs_lf *lf, cs_cubemesh *cm, double young, double poisson, double density,
               int threads)
{
    memset(lf, 0, sizeof *lf);
    lf->h = cm->h;
    lf->threads = threads > 1 && cm->n_cells >= CS_FEM_PARALLEL_CELLS / 8 ? threads : 1;
    double lambda, mu;
    lame(young, poisson, &lambda, &mu);
    linear_matrices(lambda, mu, density, cm->h, lf->Kl, lf->Ml);
    lf->Ks = malloc(192 * 192 * sizeof(double));
    lf->Ms = malloc(64 * 64 * sizeof(double));
    if (!lf->Ks || !lf->Ms) {
        cs_lf_free(lf);
        return -1;
    }
    element_matrices(4, lambda, mu, density, cm->h, lf->Ks, lf->Ms);
    /* the octant matrices of graded cells (fields): 8 of each, no mass kept for the B-spline
     * one (its octant masses are products of half-span Gram matrices, m1h) */
    lf->Kso = malloc(8 * 192 * 192 * sizeof(double));
    lf->Kso_l = malloc(8 * (576 + 64) * sizeof(double));
    double *Mtmp = malloc(64 * 64 * sizeof(double));
    if (!lf->Kso || !lf->Kso_l || !Mtmp) {
        free(Mtmp);
        cs_lf_free(lf);
        return -1;
    }
    for (int g = 0; g < 8; g++) {
        element_matrices_oct(4, g, lambda, mu, density, cm->h, lf->Kso + (size_t)g * 192 * 192,
                             Mtmp);
        linear_matrices_oct(g, lambda, mu, density, cm->h, lf->Kso_l + (size_t)g * 640,
                            lf->Kso_l + (size_t)g * 640 + 576);
    }
    free(Mtmp);
    double xg[4], wg[4];
    gauss4(xg, wg);
    memset(lf->m1, 0, sizeof lf->m1);
    memset(lf->m1h, 0, sizeof lf->m1h);
    for (int g = 0; g < 4; g++) {
        double b[4], db[4];
        cs_bspline_basis(xg[g], b, db);
        for (int i = 0; i < 4; i++)
            for (int j = 0; j < 4; j++) {
                lf->m1[4 * i + j] += wg[g] * b[i] * b[j];
                lf->m1h[16 * (g >= 2) + 4 * i + j] += wg[g] * b[i] * b[j];
            }
    }
    lf->m1scale = density * cm->h * cm->h * cm->h;
    if (cs_lf_relink(lf, cm) != 0) {
        cs_lf_free(lf);
        return -1;
    }
    return 0;
}

/* ---------------------------------------------------------------- per-element kernels */

/* y = K x for one element, n = 24 or 192 (K symmetric: y = Σ_j x_j K[j,:]). */
__attribute__((target_clones("arch=x86-64-v3", "default"))) static void
kmul(const double *restrict K, const double *restrict x, double *restrict y, int n)
{
    double acc[192];
    for (int i = 0; i < n; i++)
        acc[i] = 0.0;
    for (int j = 0; j < n; j++) {
        const double xj = x[j], *row = K + (size_t)n * j;
        for (int i = 0; i < n; i++)
            acc[i] += xj * row[i];
    }
    for (int i = 0; i < n; i++)
        y[i] = acc[i];
}

/* Rest offset of element node a from the element's reference node, in units of h. */
static void rest_offset(int n, int a, int o[3])
{
    if (n == 64) {
        o[0] = a % 4 - 1;
        o[1] = (a / 4) % 4 - 1;
        o[2] = a / 16 - 1;
    } else {
        o[0] = CS_CORNER[a][0];
        o[1] = CS_CORNER[a][1];
        o[2] = CS_CORNER[a][2];
    }
}

/* The element's reference node: the cell's corner 0 (lattice (1,1,1) of a B-spline cell). */
static int ref_node(int n)
{
    return n == 64 ? 21 : 0;
}

/* F = ∂x/∂X at the cell centre: the edge directions of the moving frame. */
static void centre_frame(int n, const int32_t *nd, const double *x, double h, double F[9])
{
    memset(F, 0, 9 * sizeof *F);
    const double *x0 = x + 3 * (size_t)nd[ref_node(n)];
    if (n == 64) {
        double b[4], db[4];
        cs_bspline_basis(0.5, b, db);
        for (int a = 0; a < 64; a++) {
            const int ix = a % 4, iy = (a / 4) % 4, iz = a / 16;
            const double g[3] = {db[ix] * b[iy] * b[iz] / h, b[ix] * db[iy] * b[iz] / h,
                                 b[ix] * b[iy] * db[iz] / h};
            const double *p = x + 3 * (size_t)nd[a];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    F[3 * i + j] += (p[i] - x0[i]) * g[j];
        }
    } else {
        for (int k = 0; k < 8; k++) {
            const double *p = x + 3 * (size_t)nd[k];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    F[3 * i + j] += (p[i] - x0[i]) * (2 * CS_CORNER[k][j] - 1) / (4.0 * h);
        }
    }
}

void cs_lf_update(cs_lf *lf, const double *x)
{
#pragma omp parallel for num_threads(lf->threads) schedule(static)
    for (int c = 0; c < lf->n_cells; c++) {
        const int n = lf->off[c + 1] - lf->off[c];
        double F[9];
        centre_frame(n, lf->en + lf->off[c], x, lf->h, F);
        cs_extract_rotation(F, lf->q + 4 * (size_t)c, 30);
        cs_quat_to_mat(lf->q + 4 * (size_t)c, lf->R + 9 * (size_t)c);
    }
}

/* d̂ = Rᵀ(x_a − x_ref) − (X_a − X_ref): the R operator of one element. */
static void local_displacements(int n, const int32_t *nd, const double *x, const double *R,
                                double h, double *u)
{
    const double *x0 = x + 3 * (size_t)nd[ref_node(n)];
    for (int a = 0; a < n; a++) {
        const double *p = x + 3 * (size_t)nd[a];
        const double d[3] = {p[0] - x0[0], p[1] - x0[1], p[2] - x0[2]};
        int o[3];
        rest_offset(n, a, o);
        for (int i = 0; i < 3; i++)
            u[3 * a + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2] - h * o[i];
    }
}

/* out = R l per node (l in the element frame). */
static void rotate_out(int n, const double *R, const double *l, double *out)
{
    for (int a = 0; a < n; a++)
        for (int i = 0; i < 3; i++)
            out[3 * a + i] =
                R[3 * i] * l[3 * a] + R[3 * i + 1] * l[3 * a + 1] + R[3 * i + 2] * l[3 * a + 2];
}

/* Node pass: out[n] (= or +=) coef · Σ fe over the node's slots, in a fixed order. */
static void gather(cs_lf *lf, double *out, double coef, bool add)
{
#pragma omp parallel for num_threads(lf->threads) schedule(static)
    for (int n = 0; n < lf->n_nodes; n++) {
        double s0 = 0, s1 = 0, s2 = 0;
        for (int a = lf->adj_start[n]; a < lf->adj_start[n + 1]; a++) {
            const double *v = lf->fe + 3 * (size_t)lf->adj[a];
            s0 += v[0];
            s1 += v[1];
            s2 += v[2];
        }
        double *o = out + 3 * (size_t)n;
        if (add) {
            o[0] += coef * s0;
            o[1] += coef * s1;
            o[2] += coef * s2;
        } else {
            o[0] = coef * s0;
            o[1] = coef * s1;
            o[2] = coef * s2;
        }
    }
}

static const double *stiffness_of(const cs_lf *lf, int n)
{
    return n == 64 ? lf->Ks : lf->Kl;
}

/* ku = K_e u for cell c (n nodes) with the factors w: s·K when its 8 are equal, else
 * Σ_g w_g K_g over the octant matrices. */
static void cell_stiffness(const cs_lf *lf, const double *w, int c, int n, const double *u,
                           double *ku)
{
    double s;
    const int n3 = 3 * n;
    if (uniform_factor(w, c, &s)) {
        kmul(stiffness_of(lf, n), u, ku, n3);
        if (s != 1.0)
            for (int i = 0; i < n3; i++)
                ku[i] *= s;
        return;
    }
    const double *f = w + 8 * (size_t)c;
    double t[192];
    memset(ku, 0, (size_t)n3 * sizeof *ku);
    for (int g = 0; g < 8; g++) {
        if (f[g] == 0)
            continue;
        kmul(octant_K(lf, n, g), u, t, n3);
        for (int i = 0; i < n3; i++)
            ku[i] += f[g] * t[i];
    }
}

void cs_lf_force(cs_lf *lf, const double *x, double *f, double *energy)
{
    double e_sum = 0;
#pragma omp parallel for num_threads(lf->threads) schedule(static) reduction(+ : e_sum)
    for (int c = 0; c < lf->n_cells; c++) {
        const int n = lf->off[c + 1] - lf->off[c];
        const double *R = lf->R + 9 * (size_t)c;
        double u[192], ku[192];
        local_displacements(n, lf->en + lf->off[c], x, R, lf->h, u);
        cell_stiffness(lf, lf->ky, c, n, u, ku);
        double e = 0;
        for (int i = 0; i < 3 * n; i++)
            e += u[i] * ku[i];
        e_sum += 0.5 * e;
        rotate_out(n, R, ku, lf->fe + 3 * (size_t)lf->off[c]);
    }
    gather(lf, f, -1.0, false);
    if (energy)
        *energy = e_sum;
}

double cs_lf_energy(const cs_lf *lf, const double *x)
{
    double e_sum = 0;
    for (int c = 0; c < lf->n_cells; c++) {
        const int n = lf->off[c + 1] - lf->off[c];
        const int32_t *nd = lf->en + lf->off[c];
        double F[9], q[4], R[9], u[192], ku[192];
        centre_frame(n, nd, x, lf->h, F);
        memcpy(q, lf->q + 4 * (size_t)c, sizeof q);
        cs_extract_rotation(F, q, 30);
        cs_quat_to_mat(q, R);
        local_displacements(n, nd, x, R, lf->h, u);
        cell_stiffness(lf, lf->ky, c, n, u, ku);
        double e = 0;
        for (int i = 0; i < 3 * n; i++)
            e += u[i] * ku[i];
        e_sum += 0.5 * e;
    }
    return e_sum;
}

void cs_lf_apply_K(cs_lf *lf, const double *p, double *y)
{
    cs_lf_apply_Kw(lf, lf->ky, p, y);
}

void cs_lf_apply_Kw(cs_lf *lf, const double *w, const double *p, double *y)
{
#pragma omp parallel for num_threads(lf->threads) schedule(static)
    for (int c = 0; c < lf->n_cells; c++) {
        const int n = lf->off[c + 1] - lf->off[c];
        const int32_t *nd = lf->en + lf->off[c];
        const double *R = lf->R + 9 * (size_t)c;
        double u[192], ku[192];
        for (int a = 0; a < n; a++) {
            const double *d = p + 3 * (size_t)nd[a];
            for (int i = 0; i < 3; i++)
                u[3 * a + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
        }
        cell_stiffness(lf, w, c, n, u, ku);
        rotate_out(n, R, ku, lf->fe + 3 * (size_t)lf->off[c]);
    }
    gather(lf, y, 1.0, false);
}

void cs_lf_diag_blocks(const cs_lf *lf, double *blocks)
{
    cs_lf_diag_blocks_w(lf, lf->ky, blocks);
}

void cs_lf_diag_blocks_w(const cs_lf *lf, const double *w, double *blocks)
{
    memset(blocks, 0, sizeof(double) * 9 * (size_t)lf->n_nodes);
    for (int c = 0; c < lf->n_cells; c++) {
        const int n = lf->off[c + 1] - lf->off[c], n3 = 3 * n;
        const int32_t *nd = lf->en + lf->off[c];
        const double *R = lf->R + 9 * (size_t)c, *K = stiffness_of(lf, n);
        double sc;
        const bool uni = uniform_factor(w, c, &sc);
        const double *f = w ? w + 8 * (size_t)c : NULL;
        for (int a = 0; a < n; a++) {
            double Ka[9], T[9];
            /* K_aa (s·K, or Σ_g f_g K_g for a graded cell); T = R K_aa, block += T Rᵀ */
            for (int k = 0; k < 3; k++)
                for (int j = 0; j < 3; j++) {
                    const size_t e = (size_t)(3 * a + k) * n3 + 3 * a + j;
                    double v = 0;
                    if (uni)
                        v = sc * K[e];
                    else
                        for (int g = 0; g < 8; g++)
                            v += f[g] * octant_K(lf, n, g)[e];
                    Ka[3 * k + j] = v;
                }
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    T[3 * i + j] = R[3 * i] * Ka[j] + R[3 * i + 1] * Ka[3 + j] +
                                   R[3 * i + 2] * Ka[6 + j];
            double *B = blocks + 9 * (size_t)nd[a];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    B[3 * i + j] += T[3 * i] * R[3 * j] + T[3 * i + 1] * R[3 * j + 1] +
                                    T[3 * i + 2] * R[3 * j + 2];
        }
    }
}

void cs_lf_apply_M(cs_lf *lf, const double *p, double *y, double coef)
{
    cs_lf_apply_Mw(lf, lf->km, p, y, coef);
}

/* B (192) = (mx ⊗ my ⊗ mz) A (192): three 4×4 passes, one per axis (sum factorization). */
static void kron3_apply(const double *const m[3], const double *A0, double *B)
{
    double A[192];
    memcpy(A, A0, sizeof A);
    for (int ax = 0, stride = 1; ax < 3; ax++, stride *= 4) {
        const double *src = ax == 1 ? B : A;
        double *dst = ax == 1 ? A : B;
        for (int a = 0; a < 64; a++) {
            const int i = (a / stride) % 4, base = a - i * stride;
            double s0 = 0, s1 = 0, s2 = 0;
            for (int j = 0; j < 4; j++) {
                const double mm = m[ax][4 * i + j], *q = src + 3 * (base + j * stride);
                s0 += mm * q[0];
                s1 += mm * q[1];
                s2 += mm * q[2];
            }
            dst[3 * a] = s0;
            dst[3 * a + 1] = s1;
            dst[3 * a + 2] = s2;
        }
    }
}

void cs_lf_apply_Mw(cs_lf *lf, const double *w, const double *p, double *y, double coef)
{
#pragma omp parallel for num_threads(lf->threads) schedule(static)
    for (int c = 0; c < lf->n_cells; c++) {
        const int n = lf->off[c + 1] - lf->off[c];
        const int32_t *nd = lf->en + lf->off[c];
        double *out = lf->fe + 3 * (size_t)lf->off[c];
        double sc;
        const bool uni = uniform_factor(w, c, &sc);
        const double *f = w ? w + 8 * (size_t)c : NULL;
        if (n == 64) {
            /* Ms = ρh³ m⊗m⊗m (m the 4×4 Gram matrix of the cubic B-splines on one span):
             * three 4×4 passes instead of 64×64; a graded cell sums its 8 octants, each
             * ρh³ f_g m_x⊗m_y⊗m_z with the half-span Gram matrices of its sides. */
            double A[192], B[192];
            for (int a = 0; a < 64; a++)
                memcpy(A + 3 * a, p + 3 * (size_t)nd[a], 3 * sizeof(double));
            if (uni) {
                const double *const m[3] = {lf->m1, lf->m1, lf->m1};
                kron3_apply(m, A, B);
                for (int k = 0; k < 192; k++)
                    out[k] = lf->m1scale * sc * B[k];
                continue;
            }
            memset(out, 0, 192 * sizeof *out);
            for (int g = 0; g < 8; g++) {
                if (f[g] == 0)
                    continue;
                const double *const m[3] = {octant_m1(lf, g, 0), octant_m1(lf, g, 1),
                                            octant_m1(lf, g, 2)};
                kron3_apply(m, A, B);
                for (int k = 0; k < 192; k++)
                    out[k] += lf->m1scale * f[g] * B[k];
            }
            continue;
        }
        for (int a = 0; a < n; a++) {
            double s0 = 0, s1 = 0, s2 = 0;
            for (int b = 0; b < n; b++) {
                double m = 0;
                if (uni)
                    m = sc * lf->Ml[a * n + b];
                else
                    for (int g = 0; g < 8; g++)
                        m += f[g] * lf->Kso_l[(size_t)g * 640 + 576 + a * n + b];
                const double *q = p + 3 * (size_t)nd[b];
                s0 += m * q[0];
                s1 += m * q[1];
                s2 += m * q[2];
            }
            out[3 * a] = s0;
            out[3 * a + 1] = s1;
            out[3 * a + 2] = s2;
        }
    }
    gather(lf, y, coef, true);
}

/* ---------------------------------------------------------------- stability bound */

/* λmax of L⁻¹ K L⁻ᵀ (L⊗I₃ the Cholesky factor of M⊗I₃) by power iteration. */
static double generalized_max(const double *K, double *L, int n)
{
    const int n3 = 3 * n;
    double v[192], w[192], z[192], lam = 0;
    for (int d = 0; d < n3; d++)
        v[d] = ((d / 3) % 2 ? 1.0 : -1.0) + 0.3 * sin(1.7 * d + 0.4);
    for (int it = 0; it < 1500; it++) {
        double nv = 0;
        for (int d = 0; d < n3; d++)
            nv += v[d] * v[d];
        nv = sqrt(nv);
        for (int d = 0; d < n3; d++)
            v[d] /= nv;
        /* z = L⁻ᵀ v (per component), w = K z, v' = L⁻¹ w */
        for (int c = 0; c < 3; c++)
            for (int i = n - 1; i >= 0; i--) {
                double s = v[3 * i + c];
                for (int k = i + 1; k < n; k++)
                    s -= L[k * n + i] * z[3 * k + c];
                z[3 * i + c] = s / L[i * n + i];
            }
        kmul(K, z, w, n3);
        double next[192];
        for (int c = 0; c < 3; c++)
            for (int i = 0; i < n; i++) {
                double s = w[3 * i + c];
                for (int k = 0; k < i; k++)
                    s -= L[i * n + k] * next[3 * k + c];
                next[3 * i + c] = s / L[i * n + i];
            }
        double rq = 0;
        for (int d = 0; d < n3; d++)
            rq += v[d] * next[d];
        if (rq > lam)
            lam = rq;
        memcpy(v, next, sizeof(double) * n3);
    }
    return lam;
}

/* Largest eigenvalue of a symmetric n×n matrix (n <= 6) by cyclic Jacobi (destroys A). */
static double sym_max_eigenvalue(double *A, int n)
{
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = 0, diag = 0;
        for (int p = 0; p < n; p++) {
            diag += A[p * n + p] * A[p * n + p];
            for (int q = p + 1; q < n; q++)
                off += A[p * n + q] * A[p * n + q];
        }
        if (off <= 1e-30 * diag)
            break;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++) {
                const double apq = A[p * n + q];
                if (apq == 0)
                    continue;
                const double th = (A[q * n + q] - A[p * n + p]) / (2 * apq);
                const double t = (th >= 0 ? 1 : -1) / (fabs(th) + sqrt(th * th + 1));
                const double c = 1 / sqrt(t * t + 1), sn = t * c;
                for (int k = 0; k < n; k++) {
                    const double akp = A[k * n + p], akq = A[k * n + q];
                    A[k * n + p] = c * akp - sn * akq;
                    A[k * n + q] = sn * akp + c * akq;
                }
                for (int k = 0; k < n; k++) {
                    const double apk = A[p * n + k], aqk = A[q * n + k];
                    A[p * n + k] = c * apk - sn * aqk;
                    A[q * n + k] = sn * apk + c * aqk;
                }
            }
    }
    double m = A[0];
    for (int i = 1; i < n; i++)
        m = fmax(m, A[i * n + i]);
    return m;
}

/*
 * λmax of the infinite uniform lattice of one element type (nb nodes per axis, K 3n×3n and
 * M n×n in lexicographic order): a plane wave e^{iθ·X/h} turns K and M into a 3×3 Hermitian
 * K̂(θ) = Σ_ab K_ab e^{iθ·(b−a)} and a scalar M̂(θ); scan θ over a grid of [0, π]³.
 */
double cs_lf_lattice_max(const double *K, const double *M, int nb)
{
    const int n = nb * nb * nb, n3 = 3 * n, span = 2 * nb - 1;
    const int no = span * span * span;
    double *Ko = calloc((size_t)no * 9, sizeof *Ko), *Mo = calloc((size_t)no, sizeof *Mo);
    if (!Ko || !Mo) {
        free(Ko);
        free(Mo);
        return -1;
    }
    for (int a = 0; a < n; a++)
        for (int b = 0; b < n; b++) {
            const int d[3] = {b % nb - a % nb, (b / nb) % nb - (a / nb) % nb, b / (nb * nb) - a / (nb * nb)};
            const int o = (d[0] + nb - 1) + span * ((d[1] + nb - 1) + span * (d[2] + nb - 1));
            Mo[o] += M[a * n + b];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    Ko[9 * o + 3 * i + j] += K[(size_t)(3 * a + i) * n3 + 3 * b + j];
        }
    const int G = 8;
    double best = 0;
    for (int gz = 0; gz <= G; gz++)
        for (int gy = 0; gy <= G; gy++)
            for (int gx = 0; gx <= G; gx++) {
                const double th[3] = {M_PI * gx / G, M_PI * gy / G, M_PI * gz / G};
                double re[9] = {0}, im[9] = {0}, m = 0;
                for (int o = 0; o < no; o++) {
                    const int d[3] = {o % span - (nb - 1), (o / span) % span - (nb - 1),
                                      o / (span * span) - (nb - 1)};
                    const double ph = th[0] * d[0] + th[1] * d[1] + th[2] * d[2];
                    const double c = cos(ph), s = sin(ph);
                    m += Mo[o] * c;
                    for (int k = 0; k < 9; k++) {
                        re[k] += Ko[9 * o + k] * c;
                        im[k] += Ko[9 * o + k] * s;
                    }
                }
                /* [[Re, −Im], [Im, Re]]: the real form of the Hermitian 3×3 */
                double A[36];
                for (int i = 0; i < 3; i++)
                    for (int j = 0; j < 3; j++) {
                        A[6 * i + j] = A[6 * (i + 3) + j + 3] = re[3 * i + j];
                        A[6 * i + j + 3] = -im[3 * i + j];
                        A[6 * (i + 3) + j] = im[3 * i + j];
                    }
                if (m > 0)
                    best = fmax(best, sym_max_eigenvalue(A, 6) / m);
            }
    free(Ko);
    free(Mo);
    return best;
}

int cs_lf_omega2_bound(cs_model model, double young, double poisson, double density, double h,
                       double *omega2)
{
    double lambda, mu;
    lame(young, poisson, &lambda, &mu);
    double Kl[576], Ml[64];
    linear_matrices(lambda, mu, density, h, Kl, Ml);
    if (model != CS_MODEL_LOCALFRAME) {
        /* the engine's lumped mass: ρh³/8 at each corner */
        memset(Ml, 0, sizeof Ml);
        for (int k = 0; k < 8; k++)
            Ml[9 * k] = density * h * h * h / 8.0;
    }
    if (cs_cholesky(Ml, 8) != 0)
        return -1;
    /* Power iteration approaches λmax from below; the 0.1 % margin covers what it has not
     * reached (test_localframe.c checks it against a full eigen-decomposition). */
    double best = 1.001 * generalized_max(Kl, Ml, 8);
    if (model == CS_MODEL_LOCALFRAME) {
        /* The element bound is useless for B-spline elements: one cell's 64×64 consistent mass
         * is nearly singular (B₀ = (1−t)³/6 barely enters the cell), so it overestimates ω²
         * twentyfold. The B-spline cells' own frequencies are those of the infinite lattice
         * (plane waves); the margin covers the modes where they meet the linear cells
         * (test_localframe.c compares with power iteration on assembled objects). */
        double *Ks = malloc(192 * 192 * sizeof *Ks), *Ms = malloc(64 * 64 * sizeof *Ms);
        double s = -1;
        if (Ks && Ms) {
            element_matrices(4, lambda, mu, density, h, Ks, Ms);
            s = cs_lf_lattice_max(Ks, Ms, 4);
        }
        free(Ks);
        free(Ms);
        if (s < 0)
            return -1;
        if (1.1 * s > best)
            best = 1.1 * s;
    }
    *omega2 = best;
    return 0;
}
