/*
 * mss.c — seed 004 §3.2: the cubic mass-spring element with correction forces (see mss.h for
 * the reading of the paper and the derivation of what is computed here).
 */
#include "mss.h"

#include "mat3.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* s_i(a): the side (±1) of corner a along axis i, in the corner order of cubemesh.h. */
static const double SGN[8][3] = {
    {-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
    {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1},
};

/* 12 edges (4 per axis) then the 4 inner diagonals, as corner pairs. */
static const int SPRING[16][2] = {
    {0, 1}, {3, 2}, {4, 5}, {7, 6}, /* x */
    {0, 3}, {1, 2}, {4, 7}, {5, 6}, /* y */
    {0, 4}, {1, 5}, {2, 6}, {3, 7}, /* z */
    {0, 6}, {1, 7}, {2, 4}, {3, 5}, /* inner diagonals */
};

/* Offsets into a cell's state: per spring (n, g), the axes, K_s·S, the corners relative to
 * their centroid r_a and the inverse of Σ_a (|r_a|² I − r_a r_aᵀ) (implicit steps: the
 * projection of the transverse term, below). */
#define ST_AXES 64
#define ST_KSS 73
#define ST_R 145
#define ST_IINV 169

double cs_mss_edge_constant(double young, double poisson, double h)
{
    return young * h * (4 * poisson + 1) / (8 * (1 + poisson));
}

double cs_mss_diagonal_constant(double young, double poisson, double h)
{
    return 3 * young * h / (8 * (1 + poisson));
}

static void mat3_mul(const double a[9], const double b[9], double c[9])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            c[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
}

static void set_coefficients(cs_mss *m, double young, double poisson, double h)
{
    m->h = h;
    m->k_edge = cs_mss_edge_constant(young, poisson, h);
    m->k_diag = cs_mss_diagonal_constant(young, poisson, h);
    const double c = (1 - 4 * poisson) / 8;
    m->c = c;
    /* A = (1−4c)I + 4cJ; A⁻¹ = [I − 4c/(1+8c)·J]/(1−4c) (1−4c = (1+4ν)/2 > 0, 1+8c = 2−4ν > 0). */
    double J_I[9], P[9];
    const double t = 4 * c / (1 + 8 * c);
    /* P: the springs' force pattern for the axial stretch patterns, K_s S_i = a S_i + b Σ_{j≠i} S_j */
    const double a = 2 * m->k_edge + 2 * m->k_diag / 3, b = 2 * m->k_diag / 3;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            m->Ainv[3 * i + j] = ((i == j ? 1.0 : 0.0) - t) / (1 - 4 * c);
            J_I[3 * i + j] = i == j ? 0.0 : 1.0;
            P[3 * i + j] = i == j ? a : b;
        }
    mat3_mul(J_I, m->Ainv, m->B);
    double AmI[9];
    for (int i = 0; i < 9; i++)
        AmI[i] = m->Ainv[i] - (i % 4 == 0 ? 1.0 : 0.0);
    mat3_mul(AmI, P, m->Mc);
}

/* ---------------------------------------------------------------- element kernels */

static void rest_length(const cs_mss *m, int s, double *L0, double *k)
{
    *L0 = s < 12 ? m->h : sqrt(3.0) * m->h;
    *k = s < 12 ? m->k_edge : m->k_diag;
}

/* The element's axes e_i and their lengths |d_i|, d_i = ¼ Σ_a s_i(a) x_a. */
static void element_axes(const double *pos, double e[9], double len[3])
{
    for (int i = 0; i < 3; i++) {
        double d[3] = {0, 0, 0};
        for (int a = 0; a < 8; a++)
            for (int k = 0; k < 3; k++)
                d[k] += 0.25 * SGN[a][i] * pos[3 * a + k];
        len[i] = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        const double inv = len[i] > 0 ? 1.0 / len[i] : 0.0;
        for (int k = 0; k < 3; k++)
            e[3 * i + k] = d[k] * inv;
    }
}

/* Σ_a s_i(a) e_i·v_a for each axis i. */
static void project_axes(const double e[9], const double *v, double out[3])
{
    for (int i = 0; i < 3; i++) {
        double s = 0;
        for (int a = 0; a < 8; a++)
            s += SGN[a][i] * (e[3 * i] * v[3 * a] + e[3 * i + 1] * v[3 * a + 1] +
                              e[3 * i + 2] * v[3 * a + 2]);
        out[i] = s;
    }
}

/* f (24) = spring + correction forces of one cube at corner positions pos (24); returns the
 * energy (see mss.h). */
static double element_force(const cs_mss *m, const double *pos, double *f)
{
    double energy = 0;
    memset(f, 0, 24 * sizeof *f);
    for (int s = 0; s < 16; s++) {
        const int a = SPRING[s][0], b = SPRING[s][1];
        double d[3], L0, k;
        rest_length(m, s, &L0, &k);
        for (int i = 0; i < 3; i++)
            d[i] = pos[3 * b + i] - pos[3 * a + i];
        const double L = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (!(L > 0))
            continue;
        const double fs = k * (L - L0) / L;
        for (int i = 0; i < 3; i++) {
            f[3 * a + i] += fs * d[i];
            f[3 * b + i] -= fs * d[i];
        }
        energy += 0.5 * k * (L - L0) * (L - L0);
    }
    double e[9], len[3], Fs[3], F[3];
    element_axes(pos, e, len);
    project_axes(e, f, Fs);
    for (int i = 0; i < 3; i++)
        Fs[i] *= -0.5;
    for (int i = 0; i < 3; i++)
        F[i] = m->Ainv[3 * i] * Fs[0] + m->Ainv[3 * i + 1] * Fs[1] + m->Ainv[3 * i + 2] * Fs[2];
    /* f_a += c Σ_j s_j(a) e_j (Σ_{i≠j} F_i) */
    const double Ft = F[0] + F[1] + F[2];
    for (int a = 0; a < 8; a++)
        for (int j = 0; j < 3; j++) {
            const double w = m->c * SGN[a][j] * (Ft - F[j]);
            for (int k = 0; k < 3; k++)
                f[3 * a + k] += w * e[3 * j + k];
        }
    double eps[3] = {len[0] - m->h, len[1] - m->h, len[2] - m->h};
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            energy += eps[i] * m->Mc[3 * i + j] * eps[j];
    return energy;
}

/* p (24) with the cube's infinitesimal rigid rotation removed: p_a − α × r_a, α = I⁻¹ Σ_a
 * r_a × p_a (the orthogonal projection off the three rotation modes ω × r_a; translations are
 * kept, and the spring terms ignore them). */
static void project_rotation(const double *st, const double *p, double *out)
{
    const double *r = st + ST_R, *Ii = st + ST_IINV;
    double l[3] = {0, 0, 0}, al[3];
    for (int a = 0; a < 8; a++) {
        const double *ra = r + 3 * a, *pa = p + 3 * a;
        l[0] += ra[1] * pa[2] - ra[2] * pa[1];
        l[1] += ra[2] * pa[0] - ra[0] * pa[2];
        l[2] += ra[0] * pa[1] - ra[1] * pa[0];
    }
    for (int i = 0; i < 3; i++)
        al[i] = Ii[3 * i] * l[0] + Ii[3 * i + 1] * l[1] + Ii[3 * i + 2] * l[2];
    for (int a = 0; a < 8; a++) {
        const double *ra = r + 3 * a;
        out[3 * a] = p[3 * a] - (al[1] * ra[2] - al[2] * ra[1]);
        out[3 * a + 1] = p[3 * a + 1] - (al[2] * ra[0] - al[0] * ra[2]);
        out[3 * a + 2] = p[3 * a + 2] - (al[0] * ra[1] - al[1] * ra[0]);
    }
}

/* y (24) = K_s p (24) with the springs' Jacobian stored in st: the axial part k n nᵀ plus the
 * transverse part k g (I − n nᵀ), g = max(0, 1 − L0/L) (1 − L0/L with `compressed`).
 * Statics (`geometric`) take it as it is; implicit steps take Pᵀ (transverse) P with P the
 * projection off the cube's rigid rotation (project_rotation), see mss.h. */
static void spring_apply(const cs_mss *m, const double *st, const double *p, double *y)
{
    double pp[24], yt[24];
    const bool project = !m->geometric;
    if (project)
        project_rotation(st, p, pp);
    const double *pt = project ? pp : p;
    double *yo = project ? yt : y;
    memset(y, 0, 24 * sizeof *y);
    if (project)
        memset(yt, 0, sizeof yt);
    for (int s = 0; s < 16; s++) {
        const int a = SPRING[s][0], b = SPRING[s][1];
        const double *n = st + 4 * s, g = st[4 * s + 3];
        const double k = s < 12 ? m->k_edge : m->k_diag;
        const double r[3] = {p[3 * a] - p[3 * b], p[3 * a + 1] - p[3 * b + 1],
                             p[3 * a + 2] - p[3 * b + 2]};
        const double nr = n[0] * r[0] + n[1] * r[1] + n[2] * r[2];
        for (int i = 0; i < 3; i++) {
            const double t = k * nr * n[i];
            y[3 * a + i] += t;
            y[3 * b + i] -= t;
        }
        if (g == 0)
            continue;
        const double q[3] = {pt[3 * a] - pt[3 * b], pt[3 * a + 1] - pt[3 * b + 1],
                             pt[3 * a + 2] - pt[3 * b + 2]};
        const double nq = n[0] * q[0] + n[1] * q[1] + n[2] * q[2];
        for (int i = 0; i < 3; i++) {
            const double t = k * g * (q[i] - nq * n[i]);
            yo[3 * a + i] += t;
            yo[3 * b + i] -= t;
        }
    }
    if (project) {
        project_rotation(st, yt, pp);
        for (int i = 0; i < 24; i++)
            y[i] += pp[i];
    }
}

/* r_a = x_a − centroid and the inverse of Σ_a (|r_a|² I − r_a r_aᵀ) into st (zero inverse for
 * a collapsed cube: no projection there). */
static void rotation_frame(const double *pos, double *st)
{
    double c[3] = {0, 0, 0}, J[9] = {0};
    for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++)
            c[k] += pos[3 * a + k] / 8;
    double *r = st + ST_R;
    for (int a = 0; a < 8; a++) {
        double *ra = r + 3 * a;
        for (int k = 0; k < 3; k++)
            ra[k] = pos[3 * a + k] - c[k];
        const double rr = ra[0] * ra[0] + ra[1] * ra[1] + ra[2] * ra[2];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                J[3 * i + j] += (i == j ? rr : 0.0) - ra[i] * ra[j];
    }
    double *Ii = st + ST_IINV;
    const double det = cs_mat3_adjugate(J, Ii);
    const double tr = J[0] + J[4] + J[8];
    if (!(fabs(det) > 1e-12 * tr * tr * tr)) {
        memset(Ii, 0, 9 * sizeof *Ii);
        return;
    }
    for (int i = 0; i < 9; i++)
        Ii[i] /= det;
}

static void element_state(const cs_mss *m, const double *pos, double *st)
{
    for (int s = 0; s < 16; s++) {
        const int a = SPRING[s][0], b = SPRING[s][1];
        double d[3], L0, k;
        rest_length(m, s, &L0, &k);
        for (int i = 0; i < 3; i++)
            d[i] = pos[3 * b + i] - pos[3 * a + i];
        const double L = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        const double inv = L > 0 ? 1.0 / L : 0.0;
        for (int i = 0; i < 3; i++)
            st[4 * s + i] = d[i] * inv;
        st[4 * s + 3] = L > L0 || (m->compressed && L > 0) ? 1 - L0 / L : 0.0;
    }
    rotation_frame(pos, st);
    double len[3];
    element_axes(pos, st + ST_AXES, len);
    const double *e = st + ST_AXES;
    for (int mm = 0; mm < 3; mm++) {
        double S[24];
        for (int a = 0; a < 8; a++)
            for (int k = 0; k < 3; k++)
                S[3 * a + k] = SGN[a][mm] * e[3 * mm + k];
        spring_apply(m, st, S, st + ST_KSS + 24 * mm);
    }
}

/* y = K_s p − (c/4)[S B Sᵀ K_s p + (K_s S) B Sᵀ p]: springs plus the symmetrized correction. */
static void element_apply(const cs_mss *m, const double *st, const double *p, double *y)
{
    spring_apply(m, st, p, y);
    const double *e = st + ST_AXES, *kss = st + ST_KSS;
    double sy[3], sp[3], w1[3], w2[3];
    project_axes(e, y, sy);
    project_axes(e, p, sp);
    for (int i = 0; i < 3; i++) {
        w1[i] = -0.25 * m->c * (m->B[3 * i] * sy[0] + m->B[3 * i + 1] * sy[1] + m->B[3 * i + 2] * sy[2]);
        w2[i] = -0.25 * m->c * (m->B[3 * i] * sp[0] + m->B[3 * i + 1] * sp[1] + m->B[3 * i + 2] * sp[2]);
    }
    for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++) {
            double v = 0;
            for (int i = 0; i < 3; i++)
                v += w1[i] * SGN[a][i] * e[3 * i + k] + w2[i] * kss[24 * i + 3 * a + k];
            y[3 * a + k] += v;
        }
}

/* Mean of cell c's 8 factors in f (1 when f is NULL). */
static double cell_factor(const double *f, int c)
{
    if (!f)
        return 1.0;
    const double *g = f + 8 * (size_t)c;
    return (g[0] + g[1] + g[2] + g[3] + g[4] + g[5] + g[6] + g[7]) / 8.0;
}

static void gather_corners(const cs_mss *m, const double *x, int c, double *pos)
{
    const int32_t *nd = m->cell_nodes + 8 * (size_t)c;
    for (int a = 0; a < 8; a++)
        memcpy(pos + 3 * a, x + 3 * (size_t)nd[a], 3 * sizeof *pos);
}

/* Node pass: out[n] = sign · Σ fe over the node's (cell, corner) slots, in a fixed order. */
static void gather(cs_mss *m, double *out, double sign)
{
#pragma omp parallel for num_threads(m->threads) schedule(static)
    for (int n = 0; n < m->n_nodes; n++) {
        double s0 = 0, s1 = 0, s2 = 0;
        for (int a = m->adj_start[n]; a < m->adj_start[n + 1]; a++) {
            const double *v = m->fe + 3 * m->adj[a];
            s0 += v[0];
            s1 += v[1];
            s2 += v[2];
        }
        out[3 * n] = sign * s0;
        out[3 * n + 1] = sign * s1;
        out[3 * n + 2] = sign * s2;
    }
}

/* ---------------------------------------------------------------- lifetime */

int cs_mss_relink(cs_mss *m, const cs_cubemesh *cm, const cs_fem *fem)
{
    free(m->fe);
    free(m->st);
    m->n_cells = cm->n_cells;
    m->n_nodes = cm->n_nodes;
    m->cell_nodes = cm->cell_nodes;
    m->adj_start = fem->adj_start;
    m->adj = fem->adj;
    m->threads = fem->threads;
    const size_t nc = cm->n_cells > 0 ? (size_t)cm->n_cells : 1;
    m->fe = malloc(nc * 24 * sizeof *m->fe);
    m->st = malloc(nc * CS_MSS_STATE * sizeof *m->st);
    if (!m->fe || !m->st)
        return -1;
    cs_mss_update(m, cm->node_rest);
    return 0;
}

int cs_mss_init(cs_mss *m, const cs_cubemesh *cm, const cs_fem *fem, double young,
                double poisson)
{
    memset(m, 0, sizeof *m);
    set_coefficients(m, young, poisson, cm->h);
    if (cs_mss_relink(m, cm, fem) != 0) {
        cs_mss_free(m);
        return -1;
    }
    return 0;
}

void cs_mss_free(cs_mss *m)
{
    free(m->fe);
    free(m->st);
    memset(m, 0, sizeof *m);
}

/* ---------------------------------------------------------------- products */

void cs_mss_update(cs_mss *m, const double *x)
{
#pragma omp parallel for num_threads(m->threads) schedule(static)
    for (int c = 0; c < m->n_cells; c++) {
        double pos[24];
        gather_corners(m, x, c, pos);
        element_state(m, pos, m->st + CS_MSS_STATE * (size_t)c);
    }
}

void cs_mss_force(cs_mss *m, const double *x, double *f, double *energy)
{
    double e_sum = 0;
#pragma omp parallel for num_threads(m->threads) schedule(static) reduction(+ : e_sum)
    for (int c = 0; c < m->n_cells; c++) {
        double pos[24];
        gather_corners(m, x, c, pos);
        double *fe = m->fe + 24 * (size_t)c;
        const double e = element_force(m, pos, fe);
        if (m->ky) {
            const double sc = cell_factor(m->ky, c);
            for (int k = 0; k < 24; k++)
                fe[k] *= sc;
            e_sum += sc * e;
        } else {
            e_sum += e;
        }
    }
    gather(m, f, 1.0);
    if (energy)
        *energy = e_sum;
}

double cs_mss_energy(const cs_mss *m, const double *x)
{
    double e_sum = 0;
    for (int c = 0; c < m->n_cells; c++) {
        double pos[24], f[24];
        gather_corners(m, x, c, pos);
        e_sum += cell_factor(m->ky, c) * element_force(m, pos, f);
    }
    return e_sum;
}

void cs_mss_apply_K(cs_mss *m, const double *p, double *y)
{
    cs_mss_apply_Kw(m, m->ky, p, y);
}

void cs_mss_apply_Kw(cs_mss *m, const double *w, const double *p, double *y)
{
#pragma omp parallel for num_threads(m->threads) schedule(static)
    for (int c = 0; c < m->n_cells; c++) {
        double q[24];
        double *fe = m->fe + 24 * (size_t)c;
        gather_corners(m, p, c, q);
        element_apply(m, m->st + CS_MSS_STATE * (size_t)c, q, fe);
        if (w) {
            const double sc = cell_factor(w, c);
            for (int k = 0; k < 24; k++)
                fe[k] *= sc;
        }
    }
    gather(m, y, 1.0);
}

void cs_mss_diag_blocks(cs_mss *m, double *blocks)
{
    cs_mss_diag_blocks_w(m, m->ky, blocks);
}

void cs_mss_diag_blocks_w(cs_mss *m, const double *w, double *blocks)
{
    memset(blocks, 0, sizeof(double) * 9 * (size_t)m->n_nodes);
    for (int c = 0; c < m->n_cells; c++) {
        const int32_t *nd = m->cell_nodes + 8 * (size_t)c;
        const double *st = m->st + CS_MSS_STATE * (size_t)c, sc = cell_factor(w, c);
        for (int s = 0; s < 16; s++) {
            const double *n = st + 4 * s, g = st[4 * s + 3];
            const double k = sc * (s < 12 ? m->k_edge : m->k_diag);
            for (int e = 0; e < 2; e++) {
                double *B = blocks + 9 * (size_t)nd[SPRING[s][e]];
                for (int i = 0; i < 3; i++)
                    for (int j = 0; j < 3; j++)
                        B[3 * i + j] += k * ((1 - g) * n[i] * n[j] + (i == j ? g : 0.0));
            }
        }
        /* correction: −(c/2) Σ_{ij} S_i(a) B_ij (K_s S_j)(a)ᵀ, symmetrized */
        const double *e = st + ST_AXES, *kss = st + ST_KSS;
        for (int a = 0; a < 8; a++) {
            double X[9] = {0};
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++) {
                    const double wij = -0.5 * sc * m->c * m->B[3 * i + j] * SGN[a][i];
                    for (int r = 0; r < 3; r++)
                        for (int q = 0; q < 3; q++)
                            X[3 * r + q] += wij * e[3 * i + r] * kss[24 * j + 3 * a + q];
                }
            double *B = blocks + 9 * (size_t)nd[a];
            for (int r = 0; r < 3; r++)
                for (int q = 0; q < 3; q++)
                    B[3 * r + q] += 0.5 * (X[3 * r + q] + X[3 * q + r]);
        }
    }
}

void cs_mss_cube_stiffness(double young, double poisson, double h, double K[24 * 24])
{
    cs_mss m;
    memset(&m, 0, sizeof m);
    set_coefficients(&m, young, poisson, h);
    double pos[24], st[CS_MSS_STATE];
    for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++)
            pos[3 * a + k] = h * (SGN[a][k] + 1) / 2;
    element_state(&m, pos, st);
    for (int j = 0; j < 24; j++) {
        double p[24] = {0}, y[24];
        p[j] = 1;
        element_apply(&m, st, p, y);
        for (int i = 0; i < 24; i++)
            K[24 * i + j] = y[i];
    }
}
