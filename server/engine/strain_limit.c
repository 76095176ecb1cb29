/*
 * strain_limit.c — see strain_limit.h.
 *
 * A cell's trilinear map in its own coordinates ξ ∈ [−1, 1]³ (ξ = 2(X − X_c)/h, corner k at
 * s_k = 2·CS_CORNER[k] − 1) is x(ξ) = a₀ + Σ_j a_j ξ_j + b₀ ξ₀ξ₁ + b₁ ξ₁ξ₂ + b₂ ξ₂ξ₀ + c ξ₀ξ₁ξ₂,
 * each coefficient (1/8) Σ_k (its sign product at s_k) x_k. Its gradient at corner s has the
 * columns (2/h)(a_j + b_j s_{j+1} + b_{j−1} s_{j−1} + c s_{j+1} s_{j−1}): the centre's
 * F = (2/h)[a₀ a₁ a₂] plus a part of column norm at most p_j = (2/h)(|b_j| + |b_{j−1}| + |c|).
 * With η = |p| every corner's singular values lie within [σ_min(F) − η, σ_max(F) + η], and
 * σ_max(F) ≤ |F| (Frobenius), σ_min(F) = det F / (σ_max σ_mid) ≥ 2 det F / |F|². A cell whose
 * bounds lie inside [1/limit, limit] needs nothing more; at rest the margin is 1/3 − 1/limit
 * below and limit − √3 above.
 */
#include "strain_limit.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "elastic.h"
#include "mat3.h"

#define HELD_WEIGHT 1000.0 /* a held corner's weight in the fit, against its mass */
#define SLACK 1e-9         /* relative: a cell just projected onto a bound is in bounds */
#define TARGET 0.9         /* a cell out of bounds is projected into [smin / TARGET, smax · TARGET] */

/* Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations, the eigenvalues in
 * descending order: a = Σ_k l_k v_k v_kᵀ, v_k orthonormal and v₂ = v₀ × v₁. */
static void sym_eigen3(const double a_in[9], double l[3], double v[3][3])
{
    double a[9], V[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    memcpy(a, a_in, sizeof a);
    for (int sweep = 0; sweep < 32; sweep++) {
        const double off = a[1] * a[1] + a[2] * a[2] + a[5] * a[5];
        const double diag = a[0] * a[0] + a[4] * a[4] + a[8] * a[8];
        if (!(off > 1e-32 * diag))
            break;
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++) {
                const double apq = a[3 * p + q];
                if (apq != 0)
                    cs_jacobi_rotate(a, V, 3, p, q, apq);
            }
    }
    int o[3] = {0, 1, 2};
    for (int i = 0; i < 2; i++)
        for (int j = i + 1; j < 3; j++)
            if (a[4 * o[j]] > a[4 * o[i]]) {
                const int t = o[i];
                o[i] = o[j];
                o[j] = t;
            }
    for (int k = 0; k < 3; k++) {
        l[k] = a[4 * o[k]];
        for (int i = 0; i < 3; i++)
            v[k][i] = V[3 * i + o[k]];
    }
    cs_vec3_cross(v[0], v[1], v[2]);
}

/* A unit vector orthogonal to the unit vector u. */
static void any_orthogonal(const double u[3], double w[3])
{
    const double e[3] = {fabs(u[0]) < 0.6 ? 1.0 : 0.0, fabs(u[0]) < 0.6 ? 0.0 : 1.0, 0.0};
    cs_vec3_cross(u, e, w);
    const double n = cs_vec3_norm(w);
    for (int i = 0; i < 3; i++)
        w[i] /= n;
}

/* The proper orthonormal u_k with A v_k = s_k u_k for the orthonormal right-handed v_k (AᵀA's
 * eigenvectors, descending): u₀, u₁ from A v₀, A v₁ (completed where A is degenerate), u₂ =
 * u₀ × u₁; s01 = |A v₀|, |A v₁| (to round-off of s₀, where √λ would lose half the digits of
 * a small one); returns u₂ · A v₂, the third singular value with the sign of det A. */
static double left_vectors(const double A[9], double v[3][3], double u[3][3], double s01[2])
{
    double av[3][3];
    for (int k = 0; k < 3; k++)
        for (int i = 0; i < 3; i++)
            av[k][i] = A[3 * i] * v[k][0] + A[3 * i + 1] * v[k][1] + A[3 * i + 2] * v[k][2];
    const double n0 = cs_vec3_norm(av[0]);
    s01[0] = n0;
    s01[1] = cs_vec3_norm(av[1]);
    if (!(n0 > 0 && isfinite(n0))) {
        memcpy(u, v, 9 * sizeof(double));
        return 0;
    }
    for (int i = 0; i < 3; i++)
        u[0][i] = av[0][i] / n0;
    const double d = cs_vec3_dot(av[1], u[0]);
    for (int i = 0; i < 3; i++)
        u[1][i] = av[1][i] - d * u[0][i];
    const double n1 = cs_vec3_norm(u[1]);
    if (n1 > 1e-12 * n0)
        for (int i = 0; i < 3; i++)
            u[1][i] /= n1;
    else
        any_orthogonal(u[0], u[1]);
    cs_vec3_cross(u[0], u[1], u[2]);
    return cs_vec3_dot(u[2], av[2]);
}

/* F = Σ_k s_k u_k v_kᵀ: the singular values descending (s₂ with the sign of det F) and the
 * proper orthonormal u_k, v_k, from the eigenvectors of FᵀF (left_vectors). */
static void svd3(const double F[9], double s[3], double u[3][3], double v[3][3])
{
    double C[9], l[3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            C[3 * i + j] = F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j];
    sym_eigen3(C, l, v);
    s[2] = left_vectors(F, v, u, s);
}

void cs_strain_singular_values(const double F[9], double s[3])
{
    double u[3][3], v[3][3];
    svd3(F, s, u, v);
}

/* Whether some singular value of E lies outside [smin, smax] (a negative one does). */
static bool stretch_out(const double E[9], double smin, double smax)
{
    const double n2 = cs_vec3_dot(E, E) + cs_vec3_dot(E + 3, E + 3) + cs_vec3_dot(E + 6, E + 6);
    const double det = E[0] * (E[4] * E[8] - E[5] * E[7]) - E[1] * (E[3] * E[8] - E[5] * E[6]) +
                       E[2] * (E[3] * E[7] - E[4] * E[6]);
    if (n2 <= smax * smax && det >= 0.5 * smin * n2)
        return false;
    double s[3];
    cs_strain_singular_values(E, s);
    return !(s[0] <= smax * (1 + SLACK) && s[2] >= smin * (1 - SLACK));
}

/* The cell's modes: a[j] (linear), b[j] (ξ_j ξ_{j+1}), c (ξ₀ξ₁ξ₂), 3 components each. */
static void cell_modes(const double *x, const int32_t *nd, double a[3][3], double b[3][3],
                       double c[3])
{
    memset(a, 0, 9 * sizeof(double));
    memset(b, 0, 9 * sizeof(double));
    c[0] = c[1] = c[2] = 0;
    for (int k = 0; k < 8; k++) {
        const double s0 = 2 * CS_CORNER[k][0] - 1, s1 = 2 * CS_CORNER[k][1] - 1,
                     s2 = 2 * CS_CORNER[k][2] - 1;
        const double *xk = x + 3 * (size_t)nd[k];
        for (int r = 0; r < 3; r++) {
            const double q = 0.125 * xk[r];
            a[0][r] += s0 * q;
            a[1][r] += s1 * q;
            a[2][r] += s2 * q;
            b[0][r] += s0 * s1 * q;
            b[1][r] += s1 * s2 * q;
            b[2][r] += s2 * s0 * q;
            c[r] += s0 * s1 * s2 * q;
        }
    }
}

/* The deformation gradient at corner k of a cell with modes a, b, c (cell_modes), g = 2/h. */
static void corner_jacobian(const double a[3][3], const double b[3][3], const double c[3],
                            double g, int k, double E[9])
{
    const double s[3] = {2 * CS_CORNER[k][0] - 1, 2 * CS_CORNER[k][1] - 1,
                         2 * CS_CORNER[k][2] - 1};
    for (int j = 0; j < 3; j++) {
        const int j1 = (j + 1) % 3, jm = (j + 2) % 3;
        for (int r = 0; r < 3; r++)
            E[3 * r + j] = g * (a[j][r] + b[j][r] * s[j1] + b[jm][r] * s[jm] +
                                c[r] * s[j1] * s[jm]);
    }
}

static double det3(const double F[9])
{
    return F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
           F[2] * (F[3] * F[7] - F[4] * F[6]);
}

/* Whether the cell has a corner (or its centre) outside the bounds. */
static bool cell_out(const double *x, const int32_t *nd, double h, double smin, double smax)
{
    double a[3][3], b[3][3], c[3];
    cell_modes(x, nd, a, b, c);
    const double g = 2 / h;
    double F[9];
    for (int r = 0; r < 3; r++)
        for (int j = 0; j < 3; j++)
            F[3 * r + j] = g * a[j][r];
    /* L1 norms: each bounds the Euclidean one, without a square root */
    const double nb0 = fabs(b[0][0]) + fabs(b[0][1]) + fabs(b[0][2]),
                 nb1 = fabs(b[1][0]) + fabs(b[1][1]) + fabs(b[1][2]),
                 nb2 = fabs(b[2][0]) + fabs(b[2][1]) + fabs(b[2][2]),
                 nc = fabs(c[0]) + fabs(c[1]) + fabs(c[2]);
    const double p0 = nb0 + nb2 + nc, p1 = nb1 + nb0 + nc, p2 = nb2 + nb1 + nc;
    const double eta = g * sqrt(p0 * p0 + p1 * p1 + p2 * p2);
    const double n2 = cs_vec3_dot(F, F) + cs_vec3_dot(F + 3, F + 3) + cs_vec3_dot(F + 6, F + 6);
    const double det = det3(F);
    if (sqrt(n2) + eta <= smax && det > 0 && 2 * det / n2 - eta >= smin)
        return false; /* every corner within bounds (the usual case) */
    if (stretch_out(F, smin, smax))
        return true;
    for (int k = 0; k < 8; k++) {
        double E[9];
        corner_jacobian(a, b, c, g, k, E);
        if (stretch_out(E, smin, smax))
            return true;
    }
    return false;
}

int cs_strain_inverted_cells(const double *x, const int32_t *cell_nodes, int n_cells, double h,
                             double *min_det)
{
    int count = 0;
    double lo = INFINITY;
    const double g = 2 / h;
    for (int c = 0; c < n_cells; c++) {
        double a[3][3], b[3][3], m[3], cell_lo = INFINITY;
        cell_modes(x, cell_nodes + 8 * (size_t)c, a, b, m);
        for (int k = 0; k < 8; k++) {
            double E[9];
            corner_jacobian(a, b, m, g, k, E);
            cell_lo = fmin(cell_lo, det3(E));
        }
        if (!(cell_lo > 0))
            count++;
        lo = fmin(lo, cell_lo);
    }
    if (min_det)
        *min_det = n_cells > 0 ? lo : 1.0;
    return count;
}

static bool node_held(const cs_object *o, size_t i)
{
    return o->mask[3 * i] || o->mask[3 * i + 1] || o->mask[3 * i + 2] || o->pin[i] ||
           (o->frozen && o->frozen[i]);
}

/* Moves the cell's free corners onto the shape within [smin, smax] that best fits it. */
static void project_cell(cs_object *o, int c, double smin, double smax, double dt)
{
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
    const double h = o->cm.h;
    double a[3][3], b[3][3], cc[3];
    cell_modes(o->x, nd, a, b, cc);
    /* the centre's stretch, clamped, in the material frame: S = Σ_k s_k v_k v_kᵀ */
    double F[9], v[3][3], u[3][3], s[3];
    for (int r = 0; r < 3; r++)
        for (int j = 0; j < 3; j++)
            F[3 * r + j] = (2 / h) * a[j][r];
    svd3(F, s, u, v);
    for (int k = 0; k < 3; k++)
        s[k] = fmin(fmax(s[k], smin), smax);
    double S[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            S[3 * i + j] = s[0] * v[0][i] * v[0][j] + s[1] * v[1][i] * v[1][j] +
                           s[2] * v[2][i] * v[2][j];
    /* the target offsets P_k = S dX_k, fitted to the corners by a rotation and a shift */
    double P[8][3], w[8], pw[3] = {0, 0, 0}, xw[3] = {0, 0, 0}, sw = 0;
    bool held[8];
    for (int k = 0; k < 8; k++) {
        const size_t i = (size_t)nd[k];
        double dX[3];
        for (int j = 0; j < 3; j++)
            dX[j] = 0.5 * h * (2 * CS_CORNER[k][j] - 1);
        for (int r = 0; r < 3; r++)
            P[k][r] = cs_vec3_dot(S + 3 * r, dX);
        held[k] = node_held(o, i);
        w[k] = (o->m[i] > 0 ? o->m[i] : 1.0) * (held[k] ? HELD_WEIGHT : 1.0);
        sw += w[k];
        for (int r = 0; r < 3; r++) {
            pw[r] += w[k] * P[k][r];
            xw[r] += w[k] * o->x[3 * i + r];
        }
    }
    for (int r = 0; r < 3; r++) {
        pw[r] /= sw;
        xw[r] /= sw;
    }
    double A[9] = {0};
    for (int k = 0; k < 8; k++) {
        const size_t i = (size_t)nd[k];
        for (int r = 0; r < 3; r++)
            for (int q = 0; q < 3; q++)
                A[3 * r + q] += w[k] * (o->x[3 * i + r] - xw[r]) * (P[k][q] - pw[q]);
    }
    /* R = polar(A) = Σ u_k v_kᵀ, proper */
    double sa[3];
    svd3(A, sa, u, v);
    double R[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            R[3 * i + j] = u[0][i] * v[0][j] + u[1][i] * v[1][j] + u[2][i] * v[2][j];
    for (int k = 0; k < 8; k++) {
        if (held[k])
            continue;
        const size_t i = (size_t)nd[k];
        double d[3], vn[3];
        for (int r = 0; r < 3; r++)
            d[r] = P[k][r] - pw[r];
        double *xi = o->x + 3 * i, *vi = o->v + 3 * i;
        for (int r = 0; r < 3; r++) {
            const double dx = xw[r] + cs_vec3_dot(R + 3 * r, d) - xi[r];
            xi[r] += dx;
            vn[r] = vi[r] + dx / dt;
        }
        /* the velocity that ends the step where the node now is, no faster than before: the
         * move takes back motion the step made, and gives none for a shape that was out of
         * bounds before it */
        const double v2 = cs_vec3_dot(vi, vi), n2 = cs_vec3_dot(vn, vn);
        const double f = n2 > v2 ? sqrt(v2 / n2) : 1.0;
        for (int r = 0; r < 3; r++)
            vi[r] = f * vn[r];
    }
}

static int cmp_i32(const void *a, const void *b)
{
    const int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
    return (x > y) - (x < y);
}

static int scratch(cs_object *o)
{
    const size_t nc = (size_t)o->cm.n_cells;
    if (nc > o->sl_cap_cells) {
        uint8_t *f = realloc(o->sl_flag, nc);
        if (f)
            o->sl_flag = f;
        int32_t *l = realloc(o->sl_list, 2 * nc * sizeof *l); /* a sweep's cells, then its candidates */
        if (l)
            o->sl_list = l;
        if (!f || !l)
            return -1;
        o->sl_cap_cells = nc;
    }
    return 0;
}

int cs_strain_limit(cs_object *o, double dt)
{
    const double smax = o->strain_limit;
    if (!(smax > 1) || (o->model != CS_MODEL_COROTATIONAL && o->model != CS_MODEL_MSS) ||
        o->cm.n_cells == 0)
        return 0;
    const double smin = 1 / smax, h = o->cm.h;
    const int n_cells = o->cm.n_cells;
    if (scratch(o) != 0)
        return -1;
    uint8_t *flag = o->sl_flag;
    int32_t *list = o->sl_list;
    const uint8_t *active = o->frozen ? o->cell_active : NULL;
    const int32_t *cn = o->cm.cell_nodes;
    const double *x = o->x;
    int count = 0;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static) reduction(+ : count)
    for (int c = 0; c < n_cells; c++) {
        flag[c] = (!active || active[c]) && cell_out(x, cn + 8 * (size_t)c, h, smin, smax);
        count += flag[c];
    }
    if (count == 0)
        return 0;
    int n = 0;
    for (int c = 0; c < n_cells; c++)
        if (flag[c]) {
            list[n++] = c;
            flag[c] = 0;
        }
    int total = 0;
    for (int sweep = 0; sweep < CS_STRAIN_SWEEPS && n > 0; sweep++) {
        /* the cells out of bounds, in cell order, forward then backward */
        for (int j = 0; j < n; j++)
            project_cell(o, list[sweep % 2 ? n - 1 - j : j], smin / TARGET, smax * TARGET, dt);
        total += n;
        /* check again the cells that share a lattice neighbourhood with a projected one (the
         * only ones a move can reach) */
        int m = 0;
        for (int j = 0; j < n; j++) {
            const int32_t *q = o->cm.cell_ijk + 3 * (size_t)list[j];
            for (int dk = -1; dk <= 1; dk++)
                for (int dj = -1; dj <= 1; dj++)
                    for (int di = -1; di <= 1; di++) {
                        const int32_t c = cs_ijk_hash_get(&o->cm.cells, q[0] + di, q[1] + dj,
                                                          q[2] + dk);
                        if (c >= 0 && !flag[c]) {
                            flag[c] = 1;
                            list[n + m++] = c; /* after the current list: n + m <= n_cells */
                        }
                    }
        }
        int k = 0;
        for (int j = 0; j < m; j++) {
            const int32_t c = list[n + j];
            flag[c] = 0;
            if ((!active || active[c]) && cell_out(o->x, cn + 8 * (size_t)c, h, smin, smax))
                list[k++] = c;
        }
        qsort(list, (size_t)k, sizeof *list, cmp_i32);
        n = k;
    }
    return total;
}
