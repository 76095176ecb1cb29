/*
 * solver.c — seed 000 §2.2 / Appendix A: matrix-free PCG with block-Jacobi preconditioning.
 */
#include "solver.h"

#include "mat3.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define CS_DOT_BLOCK 4096

/* The threads of cs_cg_guess's and cs_cg_record's passes (w->threads; 0: one). */
static int cg_threads(const cs_cg_work *w)
{
    return w->threads > 1 ? w->threads : 1;
}

int cs_cg_work_init(cs_cg_work *w, int n)
{
    memset(w, 0, sizeof *w);
    w->n = n;
    size_t sz = (size_t)n * sizeof(double);
    w->r = malloc(sz);
    w->z = malloc(sz);
    w->p = malloc(sz);
    w->q = malloc(sz);
    w->zo = malloc(sz);
    w->partial = malloc(2 * ((size_t)n / CS_DOT_BLOCK + 1) * sizeof(double));
    if (!w->r || !w->z || !w->p || !w->q || !w->zo || !w->partial) {
        cs_cg_work_free(w);
        return -1;
    }
    return 0;
}

static void free_history(cs_cg_work *w)
{
    free(w->hist_prev);
    free(w->hist_end);
    free(w->gpartial);
    w->hist_prev = w->hist_end = w->gpartial = NULL;
    for (int k = 0; k < CS_CG_DIRS; k++) {
        free(w->dirs[k]);
        free(w->adirs[k]);
        w->dirs[k] = w->adirs[k] = NULL;
    }
}

void cs_cg_work_free(cs_cg_work *w)
{
    free(w->r);
    free(w->z);
    free(w->p);
    free(w->q);
    free(w->zo);
    free(w->partial);
    free_history(w);
    memset(w, 0, sizeof *w);
}

int cs_cg_guess(cs_cg_work *w, const double *v, double *x)
{
    const size_t n = (size_t)w->n, sz = (n ? n : 1) * sizeof(double);
    w->dir_ready = false;
    if (!w->hist_prev) {
        w->hist_prev = malloc(sz);
        w->hist_end = malloc(sz);
        const size_t nb = n / CS_DOT_BLOCK + 1, ne = (CS_CG_DIRS + 1) * (CS_CG_DIRS + 2);
        w->gpartial = malloc(nb * ne * sizeof(double));
        bool ok = w->hist_prev && w->hist_end && w->gpartial;
        for (int k = 0; k < CS_CG_DIRS; k++) {
            w->dirs[k] = malloc(sz);
            w->adirs[k] = malloc(sz);
            ok = ok && w->dirs[k] && w->adirs[k];
        }
        w->hist_valid = false;
        w->ndirs = 0;
        if (!ok) {
            free_history(w);
            memcpy(x, v, n * sizeof(double));
            return -1;
        }
    }
    /* the oldest direction's slot takes the new one */
    double *d = w->dirs[CS_CG_DIRS - 1];
    for (int k = CS_CG_DIRS - 1; k > 0; k--)
        w->dirs[k] = w->dirs[k - 1];
    w->dirs[0] = d;
    /* One pass (w->threads): x = v, d = v − v_prev (used only if v is bit for bit where the
     * last step ended) and v_prev = v. */
    bool same = w->hist_valid;
    double *hp = w->hist_prev;
    const double *he = w->hist_end;
    const bool check = same;
    int differ = 0;
#pragma omp parallel for num_threads(cg_threads(w)) schedule(static) reduction(| : differ) \
    if (n >= CS_DOT_BLOCK)
    for (size_t i = 0; i < n; i++) {
        const double vi = v[i];
        differ |= check && memcmp(&vi, &he[i], sizeof vi) != 0;
        x[i] = vi;
        d[i] = vi - hp[i];
        hp[i] = vi;
    }
    same = same && !differ;
    const int m = w->max_dirs >= 1 && w->max_dirs < CS_CG_DIRS ? w->max_dirs : CS_CG_DIRS;
    w->ndirs = same ? (w->ndirs < m ? w->ndirs + 1 : m) : 0;
    w->dir_ready = same;
    w->hist_valid = false;
    return w->dir_ready ? 1 : 0;
}

void cs_cg_record(cs_cg_work *w, const double *v_end)
{
    if (!w->hist_end)
        return;
    double *he = w->hist_end;
    const int n = w->n;
#pragma omp parallel for num_threads(cg_threads(w)) schedule(static) if (n >= CS_DOT_BLOCK)
    for (int i = 0; i < n; i++)
        he[i] = v_end[i];
    w->hist_valid = true;
}

void cs_cg_map_history(cs_cg_work *w, void (*map)(void *ctx, double *u), void *ctx)
{
    if (!w->hist_prev)
        return;
    map(ctx, w->hist_prev);
    for (int k = 0; k < w->ndirs && k < CS_CG_DIRS; k++)
        map(ctx, w->dirs[k]);
}

void cs_cg_forget(cs_cg_work *w)
{
    w->hist_valid = w->dir_ready = false;
}

double cs_dot_short(const double *a, const double *b, int lo, int hi)
{
    /* four sums side by side: one chain of dependent additions waits for the adder at every
     * element. (CG's own reductions keep their single chains: in four, the fracture scene's
     * cs_dot went from 10 to 2.8 % of its time, but the changed round-off tipped a soft tower
     * dropped 2 cm onto itself, contact_soft_tower_of_three_stands, from standing to falling
     * in the sanitizer build: session 34, README Known limitations.) */
    double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    int i = lo;
    for (; i + 4 <= hi; i += 4) {
        s0 += a[i] * b[i];
        s1 += a[i + 1] * b[i + 1];
        s2 += a[i + 2] * b[i + 2];
        s3 += a[i + 3] * b[i + 3];
    }
    for (; i < hi; i++)
        s0 += a[i] * b[i];
    return (s0 + s1) + (s2 + s3);
}

int cs_cholesky(double *M, int n)
{
    for (int j = 0; j < n; j++) {
        const double *Mj = M + (size_t)j * n;
        const double d = Mj[j] - cs_dot_short(Mj, Mj, 0, j);
        if (!(d > 0))
            return -1;
        M[(size_t)j * n + j] = sqrt(d);
        for (int i = j + 1; i < n; i++) {
            double *Mi = M + (size_t)i * n;
            Mi[j] = (Mi[j] - cs_dot_short(Mi, Mj, 0, j)) / Mj[j];
        }
    }
    return 0;
}

void cs_cholesky_forward(const double *L, int n, int from, double *x)
{
    for (int i = from; i < n; i++) {
        const double *Li = L + (size_t)i * n;
        x[i] = (x[i] - cs_dot_short(Li, x, from, i)) / Li[i];
    }
}

void cs_cholesky_solve(const double *L, int n, double *x)
{
    cs_cholesky_forward(L, n, 0, x);
    /* Lᵀ x = y by rows of L: x_i once its row's later terms are out, then row i's part
     * taken from every earlier entry (reading L along its rows, not down its columns) */
    for (int i = n - 1; i >= 0; i--) {
        const double *Li = L + (size_t)i * n;
        const double xi = x[i] / Li[i];
        x[i] = xi;
        for (int k = 0; k < i; k++)
            x[k] -= Li[k] * xi;
    }
}

void cs_invert_block(double m[9])
{
    cs_mat3_invert_block(m);
}

void cs_invert_blocks(double *blocks, int n_nodes)
{
    for (int i = 0; i < n_nodes; i++)
        cs_invert_block(blocks + 9 * (size_t)i);
}

double cs_dot(cs_cg_work *w, const double *a, const double *b, int n, int threads)
{
    int nb = (n + CS_DOT_BLOCK - 1) / CS_DOT_BLOCK;
#pragma omp parallel for num_threads(threads) schedule(static) if (nb > 1)
    for (int k = 0; k < nb; k++) {
        int lo = k * CS_DOT_BLOCK, hi = lo + CS_DOT_BLOCK < n ? lo + CS_DOT_BLOCK : n;
        double s = 0;
        for (int i = lo; i < hi; i++)
            s += a[i] * b[i];
        w->partial[k] = s;
    }
    double s = 0;
    for (int k = 0; k < nb; k++)
        s += w->partial[k];
    return s;
}

static void precondition(const double *inv, const uint8_t *mask, const double *r, double *z,
                         int n_nodes, int threads)
{
#pragma omp parallel for num_threads(threads) schedule(static)
    for (int i = 0; i < n_nodes; i++) {
        const double *m = inv + 9 * i;
        const double *v = r + 3 * i;
        for (int a = 0; a < 3; a++) {
            double s = m[3 * a] * v[0] + m[3 * a + 1] * v[1] + m[3 * a + 2] * v[2];
            z[3 * i + a] = mask[3 * i + a] ? 0.0 : s;
        }
    }
}

typedef struct jacobi_ctx {
    const double *inv;
    const uint8_t *mask;
    int n_nodes, threads;
} jacobi_ctx;

static void jacobi_apply(void *ctx, const double *r, double *z)
{
    const jacobi_ctx *j = ctx;
    precondition(j->inv, j->mask, r, z, j->n_nodes, j->threads);
}

/* One element of the x/r update: x_i += α dx, r_i −= α dq at a free dof (r_i = 0 at a held
 * one); returns r_i². Shared by update_xr and warm_subspace so both do the same arithmetic. */
static inline double update_xr_at(const uint8_t *mask, int i, double alpha, double dx, double dq,
                                  double *x, double *r)
{
    x[i] += alpha * dx;
    const double ri = mask[i] ? 0.0 : r[i] - alpha * dq;
    r[i] = ri;
    return ri * ri;
}

/* x += α p and r = r − α q at free dofs (0 at held ones), returning ‖r‖² summed in the fixed
 * blocks of cs_dot: one pass instead of two. */
static double update_xr(cs_cg_work *w, const uint8_t *mask, double alpha, const double *p,
                        const double *q, double *x, double *r, int n, int threads)
{
    const int nb = (n + CS_DOT_BLOCK - 1) / CS_DOT_BLOCK;
#pragma omp parallel for num_threads(threads) schedule(static) if (nb > 1)
    for (int k = 0; k < nb; k++) {
        const int lo = k * CS_DOT_BLOCK, hi = lo + CS_DOT_BLOCK < n ? lo + CS_DOT_BLOCK : n;
        double s = 0;
        for (int i = lo; i < hi; i++)
            s += update_xr_at(mask, i, alpha, p[i], q[i], x, r);
        w->partial[k] = s;
    }
    double s = 0;
    for (int k = 0; k < nb; k++)
        s += w->partial[k];
    return s;
}

/* The solve's first pass, after q = A x: r = b − q at free dofs (0 at held ones), returning
 * ‖r‖² and *bb = Σ b_i² over the free dofs, each summed in the fixed blocks of cs_dot, and
 * *held0 = whether x is 0 at every held dof (then x is its own free part and q its product:
 * the warm start's first direction). */
static double start_residual(cs_cg_work *w, const uint8_t *mask, const double *b,
                             const double *q, const double *x, double *r, int n, int threads,
                             double *bb, bool *held0)
{
    const int nb = (n + CS_DOT_BLOCK - 1) / CS_DOT_BLOCK;
    double *pr = w->partial, *pb = w->partial + nb;
    int nz = 0;
#pragma omp parallel for num_threads(threads) schedule(static) if (nb > 1) reduction(| : nz)
    for (int k = 0; k < nb; k++) {
        const int lo = k * CS_DOT_BLOCK, hi = lo + CS_DOT_BLOCK < n ? lo + CS_DOT_BLOCK : n;
        double sr = 0, sb = 0;
        for (int i = lo; i < hi; i++) {
            const double bi = mask[i] ? 0.0 : b[i];
            const double ri = mask[i] ? 0.0 : b[i] - q[i];
            nz |= mask[i] && x[i] != 0.0;
            r[i] = ri;
            sb += bi * bi;
            sr += ri * ri;
        }
        pr[k] = sr;
        pb[k] = sb;
    }
    double sr = 0, sb = 0;
    for (int k = 0; k < nb; k++) {
        sr += pr[k];
        sb += pb[k];
    }
    *bb = sb;
    *held0 = !nz;
    return sr;
}

/* p = z and rᵀz (fixed blocks), one pass. */
static double copy_dot(cs_cg_work *w, const double *r, const double *z, double *p, int n,
                       int threads)
{
    const int nb = (n + CS_DOT_BLOCK - 1) / CS_DOT_BLOCK;
#pragma omp parallel for num_threads(threads) schedule(static) if (nb > 1)
    for (int k = 0; k < nb; k++) {
        const int lo = k * CS_DOT_BLOCK, hi = lo + CS_DOT_BLOCK < n ? lo + CS_DOT_BLOCK : n;
        double s = 0;
        for (int i = lo; i < hi; i++) {
            p[i] = z[i];
            s += r[i] * z[i];
        }
        w->partial[k] = s;
    }
    double s = 0;
    for (int k = 0; k < nb; k++)
        s += w->partial[k];
    return s;
}

/* rᵀz and rᵀzo in one pass (fixed blocks). */
static void dot2(cs_cg_work *w, const double *r, const double *z, const double *zo, int n,
                 int threads, double *rz, double *rzo)
{
    const int nb = (n + CS_DOT_BLOCK - 1) / CS_DOT_BLOCK;
    double *pa = w->partial, *pb = w->partial + nb;
#pragma omp parallel for num_threads(threads) schedule(static) if (nb > 1)
    for (int k = 0; k < nb; k++) {
        const int lo = k * CS_DOT_BLOCK, hi = lo + CS_DOT_BLOCK < n ? lo + CS_DOT_BLOCK : n;
        double a = 0, b = 0;
        for (int i = lo; i < hi; i++) {
            a += r[i] * z[i];
            b += r[i] * zo[i];
        }
        pa[k] = a;
        pb[k] = b;
    }
    double a = 0, b = 0;
    for (int k = 0; k < nb; k++) {
        a += pa[k];
        b += pb[k];
    }
    *rz = a;
    *rzo = b;
}

/* Block [lo, hi) of the warm start's sums: out[a nv + c] = Σ_i D_a[i] Q_c[i] and
 * out[nv nv + a] = Σ_i D_a[i] r[i], each summed in i order from 0. */
static void gram_block_any(const double *const *D, const double *const *Q, const double *r,
                           int nv, int lo, int hi, double *out)
{
    double acc[(CS_CG_DIRS + 1) * (CS_CG_DIRS + 2)] = {0};
    for (int i = lo; i < hi; i++)
        for (int a = 0; a < nv; a++) {
            const double da = D[a][i];
            acc[nv * nv + a] += da * r[i];
            for (int c = 0; c < nv; c++)
                acc[a * nv + c] += da * Q[c][i];
        }
    memcpy(out, acc, (size_t)(nv * (nv + 1)) * sizeof(double));
}

/* The same for the usual count, the guess and four directions (nv = 5), its 30 sums held in
 * vectors across the sums (row a: Q_0..Q_3 in one 4-double vector, Q_4 and r in a 2-double
 * one): per i, each row adds D_a[i] times (Q_0[i], .., Q_4[i], r[i]). Each sum gets the same
 * terms in the same order as gram_block_any's (a product, then an addition: no contraction in
 * ISO C), so the same bits; GCC vectorized the scalar loop across i instead, with in-order
 * reductions by shuffles that cost twice as much. */
#if CS_CG_DIRS == 4
typedef double gv4 __attribute__((vector_size(32)));
typedef double gv2 __attribute__((vector_size(16)));
__attribute__((target_clones("arch=x86-64-v3", "default"))) static void
gram_block(const double *const *D, const double *const *Q, const double *r, int lo, int hi,
           double *out)
{
    const double *restrict d0 = D[0], *restrict d1 = D[1], *restrict d2 = D[2],
                           *restrict d3 = D[3], *restrict d4 = D[4];
    const double *restrict q0 = Q[0], *restrict q1 = Q[1], *restrict q2 = Q[2],
                           *restrict q3 = Q[3], *restrict q4 = Q[4];
    gv4 A0 = {0}, A1 = {0}, A2 = {0}, A3 = {0}, A4 = {0};
    gv2 B0 = {0}, B1 = {0}, B2 = {0}, B3 = {0}, B4 = {0};
    for (int i = lo; i < hi; i++) {
        const gv4 qa = {q0[i], q1[i], q2[i], q3[i]};
        const gv2 qb = {q4[i], r[i]};
        A0 += d0[i] * qa;
        B0 += d0[i] * qb;
        A1 += d1[i] * qa;
        B1 += d1[i] * qb;
        A2 += d2[i] * qa;
        B2 += d2[i] * qb;
        A3 += d3[i] * qa;
        B3 += d3[i] * qb;
        A4 += d4[i] * qa;
        B4 += d4[i] * qb;
    }
    const gv4 A[5] = {A0, A1, A2, A3, A4};
    const gv2 B[5] = {B0, B1, B2, B3, B4};
    for (int a = 0; a < 5; a++) {
        for (int c = 0; c < 4; c++)
            out[5 * a + c] = A[a][c];
        out[5 * a + 4] = B[a][0];
        out[25 + a] = B[a][1];
    }
}
#endif

void cs_cg_gram_block(const double *const *D, const double *const *Q, const double *r, int nv,
                      int lo, int hi, double *out)
{
#if CS_CG_DIRS == 4
    if (nv == 5) {
        gram_block(D, Q, r, lo, hi, out);
        return;
    }
#endif
    gram_block_any(D, Q, r, nv, lo, hi, out);
}

/*
 * The warm start's Galerkin step: x += D α with D the nd directions of the last steps
 * (cs_cg_guess; masked here), preceded by x0 when given (the guess itself, 0 at the held
 * dofs, with its product q0 = A x0: then x may also be scaled, and x0 + span of the changes
 * is inside the span searched), α minimising the A-norm of the error over their span, i.e.
 * (Dᵀ A D) α = Dᵀ r, and r −= A D α. The small system in fixed blocks (bit-identical on any
 * thread count), factored by Cholesky over the directions, x0 and then the newest first,
 * that are independent of those taken before to 1e-10 (a dependent one is skipped: x0 = 0
 * from rest, an old change). Returns ‖r‖ after (rnorm if no step).
 */
static double warm_subspace(cs_cg_work *w, cs_matvec_fn A, void *ctx, const uint8_t *mask,
                            int nd, const double *x0, const double *q0, double *x, double *r,
                            double rnorm, int threads)
{
    if (nd > CS_CG_DIRS)
        nd = CS_CG_DIRS;
    const int n = w->n, nb = (n + CS_DOT_BLOCK - 1) / CS_DOT_BLOCK;
    /* the directions: x0 (the guess itself, its product q0 known) first when given, then
     * the last steps' changes, newest first */
    const double *D[CS_CG_DIRS + 1], *Q[CS_CG_DIRS + 1];
    int nv = 0;
    if (x0) {
        D[nv] = x0;
        Q[nv++] = q0;
    }
#pragma omp parallel for num_threads(threads) schedule(static)
    for (int i = 0; i < n; i++)
        if (mask[i])
            for (int k = 0; k < nd; k++)
                w->dirs[k][i] = 0.0;
    for (int k = 0; k < nd; k++) {
        A(ctx, w->dirs[k], w->adirs[k]);
        D[nv] = w->dirs[k];
        Q[nv++] = w->adirs[k];
    }
    const int ne = nv * (nv + 1);
    /* G = Dᵀ Q (nv × nv) and g = Dᵀ r, one pass (the usual nv = 5 by gram_block: the same
     * sums in the same order) */
#pragma omp parallel for num_threads(threads) schedule(static) if (nb > 1)
    for (int k = 0; k < nb; k++) {
        const int lo = k * CS_DOT_BLOCK, hi = lo + CS_DOT_BLOCK < n ? lo + CS_DOT_BLOCK : n;
        cs_cg_gram_block(D, Q, r, nv, lo, hi, w->gpartial + (size_t)k * ne);
    }
    double G[(CS_CG_DIRS + 1) * (CS_CG_DIRS + 2)] = {0};
    double L[(CS_CG_DIRS + 1) * (CS_CG_DIRS + 1)] = {0};
    for (int k = 0; k < nb; k++)
        for (int e = 0; e < ne; e++)
            G[e] += w->gpartial[(size_t)k * ne + e];
    const double *g = G + nv * nv;
    /* Cholesky of the symmetrised G over the directions, in order, that are independent of
     * the ones taken before them to 1e-10 (a dependent one is skipped) */
    int take[CS_CG_DIRS + 1], m = 0;
    for (int i = 0; i < nv; i++) {
        double *Li = L + m * nv; /* row m of the factor, if direction i is taken */
        bool ok = isfinite(g[i]);
        for (int jj = 0; jj < m && ok; jj++) {
            const int j = take[jj];
            double s = 0.5 * (G[i * nv + j] + G[j * nv + i]);
            for (int k = 0; k < jj; k++)
                s -= Li[k] * L[jj * nv + k];
            Li[jj] = s / L[jj * nv + jj];
        }
        double s = G[i * nv + i];
        for (int k = 0; k < m && ok; k++)
            s -= Li[k] * Li[k];
        if (ok && s > 1e-10 * G[i * nv + i] && isfinite(s)) {
            Li[m] = sqrt(s);
            take[m++] = i;
        } else {
            for (int k = 0; k <= m; k++)
                Li[k] = 0.0;
        }
    }
    if (m == 0)
        return rnorm;
    double al[CS_CG_DIRS + 1];
    for (int i = 0; i < m; i++) {
        double s = g[take[i]];
        for (int k = 0; k < i; k++)
            s -= L[i * nv + k] * al[k];
        al[i] = s / L[i * nv + i];
    }
    for (int i = m - 1; i >= 0; i--) {
        double s = al[i];
        for (int k = i + 1; k < m; k++)
            s -= L[k * nv + i] * al[k];
        al[i] = s / L[i * nv + i];
    }
    const double *Dt[CS_CG_DIRS + 1], *Qt[CS_CG_DIRS + 1];
    for (int a = 0; a < m; a++) {
        Dt[a] = D[take[a]];
        Qt[a] = Q[take[a]];
    }
    /* x += D α and r −= Q α at free dofs (0 at held ones), ‖r‖² in the fixed blocks: one
     * pass (update_xr_at with α = 1 on dx = (D α)_i, dq = (Q α)_i; 1·v is v exactly). x0 may
     * be x itself: (D α)_i is read before x_i changes. */
#pragma omp parallel for num_threads(threads) schedule(static) if (nb > 1)
    for (int k = 0; k < nb; k++) {
        const int lo = k * CS_DOT_BLOCK, hi = lo + CS_DOT_BLOCK < n ? lo + CS_DOT_BLOCK : n;
        double s = 0;
        for (int i = lo; i < hi; i++) {
            double dx = 0, dq = 0;
            for (int a = 0; a < m; a++) {
                dx += al[a] * Dt[a][i];
                dq += al[a] * Qt[a][i];
            }
            s += update_xr_at(mask, i, 1.0, dx, dq, x, r);
        }
        w->partial[k] = s;
    }
    double s = 0;
    for (int k = 0; k < nb; k++)
        s += w->partial[k];
    return sqrt(s);
}

static cs_cg_result pcg(cs_cg_work *w, cs_matvec_fn A, void *ctx, cs_precond_fn B, void *bctx,
                        const uint8_t *mask, const double *b, double *x, double tol,
                        int max_iter, int threads, bool flexible);


cs_cg_result cs_pcg(cs_cg_work *w, cs_matvec_fn A, void *ctx, const double *inv_blocks,
                    const uint8_t *mask, const double *b, double *x, double tol, int max_iter,
                    int threads)
{
    jacobi_ctx j = {inv_blocks, mask, w->n / 3, threads};
    return pcg(w, A, ctx, jacobi_apply, &j, mask, b, x, tol, max_iter, threads, false);
}

cs_cg_result cs_pcg_ex(cs_cg_work *w, cs_matvec_fn A, void *ctx, cs_precond_fn B, void *bctx,
                       const uint8_t *mask, const double *b, double *x, double tol, int max_iter,
                       int threads)
{
    return pcg(w, A, ctx, B, bctx, mask, b, x, tol, max_iter, threads, true);
}

static cs_cg_result pcg(cs_cg_work *w, cs_matvec_fn A, void *ctx, cs_precond_fn B, void *bctx,
                        const uint8_t *mask, const double *b, double *x, double tol,
                        int max_iter, int threads, bool flexible)
{
    const int n = w->n;
    double *r = w->r, *z = w->z, *p = w->p, *q = w->q, *zo = w->zo;
    cs_cg_result res = {0, 0, 0, 0, 0};
    const int nd = w->dir_ready ? w->ndirs : 0; /* armed by cs_cg_guess for this solve only */
    w->dir_ready = false;

    /* r = b - A x; ‖r‖ and ‖b‖ over the free dofs in the same pass. */
    A(ctx, x, q);
    double bb;
    bool held0;
    double rnorm = sqrt(start_residual(w, mask, b, q, x, r, n, threads, &bb, &held0));
    const double bnorm = sqrt(bb);
    if (bnorm == 0.0) {
        /* b = 0: x = 0 on the free dofs is the solution. */
        for (int i = 0; i < n; i++)
            if (!mask[i])
                x[i] = 0.0;
        res.converged = 1;
        return res;
    }
    double ref = bnorm;
    if (w->stop == CS_CG_STOP_START)
        ref = fmin(rnorm, bnorm);
    else if (w->stop == CS_CG_STOP_GIVEN)
        ref = w->stop_ref;
    const bool capped = w->stop != CS_CG_STOP_GIVEN && w->stop_cap > 0 && w->stop_cap < ref;
    if (capped)
        ref = w->stop_cap;
    double stop = tol * ref;
    if ((w->stop != CS_CG_STOP_RHS || capped) && !(stop >= 1e-12 * bnorm))
        stop = 1e-12 * bnorm; /* also a NaN reference */
    res.ref = stop / tol;
    if (nd > 0 && rnorm > stop) { /* warm start (cs_cg_guess) */
        /* x itself joins the span when it is 0 at the held dofs: q = A x is then its
         * product, so the Galerkin step may also scale the guess, at no product */
        rnorm = warm_subspace(w, A, ctx, mask, nd, held0 ? x : NULL, q, x, r, rnorm, threads);
    }
    B(bctx, r, z);
    double rz = copy_dot(w, r, z, p, n, threads);
    int it = 0;
    /* p and z are zero at held dofs (B's contract), so pᵀq needs no masking of q and
     * update_xr keeps r zero there. */
    while (rnorm > stop && it < max_iter && isfinite(rnorm)) {
        if (w->cancel && w->cancel(w->cancel_ctx))
            break;
        A(ctx, p, q);
        const double pq = cs_dot(w, p, q, n, threads);
        if (!(pq > 0)) {
            res.indefinite = pq <= 0; /* not positive definite along p (NaN: breakdown) */
            break; /* stop with what we have */
        }
        it++;
        rnorm = sqrt(update_xr(w, mask, rz / pq, p, q, x, r, n, threads));
        if (rnorm <= stop)
            break;
        double rz_new, beta;
        if (flexible) {
            /* Polak–Ribière: β = rᵀ(z − z_old)/rz_old, robust to a preconditioner that is
             * symmetric only up to rounding (the single-precision V-cycle, mg.h) */
            double *t = zo;
            zo = z;
            z = t;
            B(bctx, r, z);
            double rzo;
            dot2(w, r, z, zo, n, threads, &rz_new, &rzo);
            beta = (rz_new - rzo) / rz;
        } else {
            B(bctx, r, z);
            rz_new = cs_dot(w, r, z, n, threads);
            beta = rz_new / rz;
        }
        rz = rz_new;
#pragma omp parallel for num_threads(threads) schedule(static)
        for (int i = 0; i < n; i++)
            p[i] = z[i] + beta * p[i];
    }
    res.iterations = it;
    res.relres = rnorm / res.ref;
    res.converged = rnorm <= stop;
    return res;
}
