/*
 * elastic.c — dispatch from the integrators to the element model of each object.
 *
 * FEM (linear, corotational): fem.c. Mass-spring (mss, seed 004): mss.c, which borrows the
 * FEM record's node → cell adjacency (every model keeps o->fem, see elastic.h).
 */
#include "elastic.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "band.h"
#include "localframe.h"
#include "mat3.h"
#include "rigid.h"
#include "simd.h"

int cs_elastic_init(cs_object *o, int threads, int simd_width)
{
    /* Every model keeps the FEM record: fracture uses its adjacency and rotations. */
    if (cs_fem_init(&o->fem, &o->cm, o->mat.young, o->mat.poisson,
                    o->model != CS_MODEL_LINEAR, threads) != 0)
        return -1;
    o->fem.wide = cs_simd_wide(simd_width);
    /* the stiffness field (world_internal.h); NULL while uniform 1 */
    o->fem.kf = o->fld.has_young ? o->fld.young : NULL;
    if (o->model == CS_MODEL_LOCALFRAME) {
        o->lf = malloc(sizeof *o->lf);
        if (!o->lf || cs_lf_init(o->lf, &o->cm, o->mat.young, o->mat.poisson, o->mat.density,
                                 threads) != 0) {
            free(o->lf);
            o->lf = NULL;
            return -1;
        }
    }
    if (o->model == CS_MODEL_MSS &&
        cs_mss_init(&o->mss, &o->cm, &o->fem, o->mat.young, o->mat.poisson) != 0)
        return -1;
    /* fields already there (a piece made by fracture): the models follow them */
    return o->fld.young ? cs_elastic_fields_changed(o) : 0;
}

int cs_elastic_fields_changed(cs_object *o)
{
    const double *ky = o->fld.has_young ? o->fld.young : NULL;
    o->fem.kf = ky;
    o->lag.valid = false; /* the fields and masses the preconditioner was built from changed */
    cs_elastic_mass_factor_drop(o);
    o->lag.small_mg = false; /* and "auto" decides again for the new material */
    o->lag.hard_steps = 0;
    if (o->model == CS_MODEL_MSS)
        o->mss.ky = ky;
    if (o->lf) {
        /* mid-fracture (cells or nodes changed, relink to follow) only the pointers */
        if (o->lf->n_cells == o->cm.n_cells && o->lf->n_nodes == o->n)
            cs_lf_set_fields(o->lf, ky, o->fld.density);
        else
            o->lf->ky = ky, o->lf->km = o->fld.density;
    }
    if (o->rb)
        return cs_rigid_fields_changed(o);
    return 0;
}

void cs_elastic_apply_Kd(cs_object *o, const double *p, double *y)
{
    if (o->lf)
        cs_lf_apply_Kw(o->lf, o->fld.kd, p, y);
    else if (o->model == CS_MODEL_MSS)
        cs_mss_apply_Kw(&o->mss, o->fld.kd, p, y);
    else
        cs_fem_apply_Kw(&o->fem, o->fld.kd, p, y);
}

void cs_elastic_diag_blocks_d(cs_object *o, double *blocks)
{
    if (o->lf)
        cs_lf_diag_blocks_w(o->lf, o->fld.kd, blocks);
    else if (o->model == CS_MODEL_MSS)
        cs_mss_diag_blocks_w(&o->mss, o->fld.kd, blocks);
    else
        cs_fem_diag_blocks_w(&o->fem, o->fld.kd, blocks);
}

void cs_elastic_apply_Md(cs_object *o, const double *p, double *y, double coef)
{
    if (o->lf) {
        cs_lf_apply_Mw(o->lf, o->fld.dd, p, y, coef);
        return;
    }
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            y[3 * i + a] += coef * o->fld.md[i] * p[3 * i + a];
}

double cs_elastic_object_omega2(const cs_object *o, double omega2_plain, bool with_penalty)
{
    double r = o->cm.n_cells > 0 && o->fld.young && o->fld.density ? 0.0 : 1.0;
    const cs_fields *fl = &o->fld;
    if (fl->young && fl->density)
        for (int c = 0; c < o->cm.n_cells; c++) {
            const double *y = fl->young + 8 * (size_t)c, *d = fl->density + 8 * (size_t)c;
            double ymax = y[0], dmin = d[0];
            for (int g = 1; g < 8; g++) {
                ymax = fmax(ymax, y[g]);
                dmin = fmin(dmin, d[g]);
            }
            r = fmax(r, ymax / dmin);
        }
    double w2 = r * omega2_plain, pk = 0;
    if (with_penalty && o->penalty > 0 && o->pin)
        for (int i = 0; i < o->n; i++)
            if (o->pin[i] && o->m[i] > 0)
                pk = fmax(pk, o->penalty / o->m[i]);
    return w2 + pk;
}

void cs_elastic_free(cs_object *o)
{
    cs_elastic_mass_factor_drop(o);
    cs_fem_free(&o->fem);
    if (o->lf) {
        cs_lf_free(o->lf);
        free(o->lf);
        o->lf = NULL;
    }
    cs_mss_free(&o->mss);
}

int cs_elastic_relink(cs_object *o)
{
    cs_elastic_mass_factor_drop(o);
    o->fem.kf = o->fld.has_young ? o->fld.young : NULL;
    if (o->model == CS_MODEL_MSS)
        o->mss.ky = o->fem.kf;
    if (o->lf)
        o->lf->ky = o->fem.kf, o->lf->km = o->fld.density;
    if (cs_fem_relink(&o->fem, &o->cm) != 0)
        return -1;
    if (o->model == CS_MODEL_MSS)
        return cs_mss_relink(&o->mss, &o->cm, &o->fem);
    return o->lf ? cs_lf_relink(o->lf, &o->cm) : 0;
}

void cs_elastic_reset(cs_object *o)
{
    cs_fem_reset_rotations(&o->fem);
    if (o->lf)
        cs_lf_reset(o->lf);
    if (o->model == CS_MODEL_MSS)
        cs_mss_update(&o->mss, o->cm.node_rest);
}

void cs_elastic_update(cs_object *o, const double *x)
{
    if (o->lf)
        cs_lf_update(o->lf, x);
    else if (o->model == CS_MODEL_MSS)
        cs_mss_update(&o->mss, x);
    else
        cs_fem_update_rotations(&o->fem, x);
}

void cs_elastic_force(cs_object *o, const double *x, double *f, double *energy)
{
    if (o->lf)
        cs_lf_force(o->lf, x, f, energy);
    else if (o->model == CS_MODEL_MSS)
        cs_mss_force(&o->mss, x, f, energy);
    else
        cs_fem_elastic_force(&o->fem, x, f, energy);
}

double cs_elastic_energy(cs_object *o, const double *x)
{
    if (o->lf)
        return cs_lf_energy(o->lf, x);
    if (o->model == CS_MODEL_MSS)
        return cs_mss_energy(&o->mss, x);
    return cs_fem_energy(&o->fem, x);
}

void cs_elastic_apply_K(cs_object *o, const double *p, double *y)
{
    if (o->lf)
        cs_lf_apply_K(o->lf, p, y);
    else if (o->model == CS_MODEL_MSS)
        cs_mss_apply_K(&o->mss, p, y);
    else
        cs_fem_apply_K(&o->fem, p, y);
}

void cs_elastic_diag_blocks(cs_object *o, double *blocks)
{
    if (o->lf)
        cs_lf_diag_blocks(o->lf, blocks);
    else if (o->model == CS_MODEL_MSS)
        cs_mss_diag_blocks(&o->mss, blocks);
    else
        cs_fem_diag_blocks(&o->fem, blocks);
}

void cs_elastic_apply_M(cs_object *o, const double *p, double *y, double coef)
{
    if (o->lf) {
        cs_lf_apply_M(o->lf, p, y, coef);
        return;
    }
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            y[3 * i + a] += coef * o->m[i] * p[3 * i + a];
}

const double *cs_elastic_mass_diag(const cs_object *o)
{
    return o->lf ? o->lf->mdiag : o->m;
}

const double *cs_elastic_mass_rows(const cs_object *o)
{
    return o->lf ? o->lf->mrow : NULL;
}

int cs_elastic_prepare_tangent(cs_object *o, const double *x, bool exact)
{
    /* mss: the full spring Jacobian (transverse term included) is its Newton operator, and it
     * is what cs_mss_apply_K gives while `geometric` is set, from here to the release (every
     * update in between, trial points included, keeps the term); no separate tangent. */
    if (o->model == CS_MODEL_MSS) {
        if (!o->mss.geometric || o->mss.compressed != exact) {
            o->mss.geometric = true;
            o->mss.compressed = exact; /* mss.h */
            cs_mss_update(&o->mss, x);
        }
        return -1;
    }
    /* localframe: the warped stiffness R K Rᵀ is its Newton operator (K is never rebuilt). */
    if (o->model != CS_MODEL_COROTATIONAL)
        return -1;
    return cs_fem_prepare_tangent(&o->fem, x);
}

void cs_elastic_apply_tangent(cs_object *o, const double *p, double *y)
{
    cs_fem_apply_tangent(&o->fem, p, y);
}

bool cs_elastic_clamp_tangent(cs_object *o, const double *x)
{
    if (o->model != CS_MODEL_MSS || !o->mss.compressed)
        return false;
    o->mss.compressed = false;
    cs_mss_update(&o->mss, x);
    return true;
}

void cs_elastic_release_tangent(cs_object *o)
{
    if (o->model == CS_MODEL_MSS) /* the next update (every step begins with one) drops them */
        o->mss.geometric = o->mss.compressed = false;
    cs_fem_release_tangent(&o->fem);
}

int cs_elastic_threads(const cs_object *o)
{
    return o->lf ? o->lf->threads : o->fem.threads;
}

/* Largest eigenvalue of a symmetric 24×24 matrix by cyclic Jacobi rotations. */
static double sym_max_eigen(const double *K)
{
    double A[24 * 24];
    memcpy(A, K, sizeof A);
    for (int i = 0; i < 24; i++) /* symmetrize: the stored matrices are symmetric up to rounding */
        for (int j = i + 1; j < 24; j++)
            A[24 * i + j] = A[24 * j + i] = 0.5 * (A[24 * i + j] + A[24 * j + i]);
    for (int sweep = 0; sweep < 60; sweep++) {
        double off = 0, diag = 0;
        for (int i = 0; i < 24; i++) {
            diag += A[25 * i] * A[25 * i];
            for (int j = i + 1; j < 24; j++)
                off += A[24 * i + j] * A[24 * i + j];
        }
        if (off <= 1e-30 * diag)
            break;
        for (int p = 0; p < 24; p++)
            for (int q = p + 1; q < 24; q++) {
                const double apq = A[24 * p + q];
                if (!(fabs(apq) < 1e-300))
                    cs_jacobi_rotate(A, NULL, 24, p, q, apq);
            }
    }
    double mx = 0;
    for (int i = 0; i < 24; i++)
        mx = fmax(mx, A[25 * i]);
    return mx;
}

double cs_elastic_max_omega(cs_model model, const cs_material *mat, double h)
{
    double K[24 * 24];
    if (model == CS_MODEL_MSS)
        cs_mss_cube_stiffness(mat->young, mat->poisson, h, K);
    else
        cs_cube_stiffness(mat->young, mat->poisson, h, K);
    const double m_corner = mat->density * h * h * h / 8.0;
    return sqrt(sym_max_eigen(K) / m_corner);
}

double cs_elastic_critical_dt(cs_model model, const cs_material *mat, double h)
{
    const double w = cs_elastic_max_omega(model, mat, h);
    /* Explicit step with Rayleigh damping C = αM + βK on the old velocity: the recurrence of
     * a mode ω is stable iff ω²dt² + 2dt(α + βω²) ≤ 4 (Jury's test), largest at ω_max. */
    const double g = mat->damping[0] + mat->damping[1] * w * w;
    return (-g + sqrt(g * g + 4 * w * w)) / (w * w);
}

/* ---------------------------------------------------------------- the mass factor
 *
 * A localframe object's consistent mass couples two nodes only if they are control nodes of
 * one cell (a 4×4×4 neighbourhood of lattice points, or a linear cell's 2×2×2), so nodes
 * whose lattice points differ by 7 or more along some axis never share a column's support:
 * M is read column by column with one product per colour (i, j, k mod 7), 343 products at
 * most. Rows ordered lattice-lexicographically, the shortest axis fastest, so the band is
 * about three layers across the two shorter axes. Factored once (n·b² multiply-adds), each
 * solve is 2·n·b per component: on the 40 × 6 × 6 beam of the localframe bench 2 000 nodes
 * and a band of 150. */

typedef struct cs_mass_factor {
    cs_band L;
    int32_t *row; /* per node: its row */
    double *t;    /* 3 per node: a solve's right-hand side in row order */
    uint32_t version;
} cs_mass_factor;

#define MF_REACH 3       /* the largest lattice distance of two coupled nodes, per axis */
#define MF_MAX_BAND 4000000.0

void cs_elastic_mass_factor_drop(cs_object *o)
{
    if (o->mfac) {
        cs_band_free(&o->mfac->L);
        free(o->mfac->row);
        free(o->mfac->t);
        free(o->mfac);
        o->mfac = NULL;
    }
    o->mfac_failed = false;
}

/* qsort order of (key, node) pairs by key */
static int cmp_pairs(const void *p, const void *q)
{
    const int64_t a = *(const int64_t *)p, b = *(const int64_t *)q;
    return (a > b) - (a < b);
}

static int build_mass_factor(cs_object *o, cs_mass_factor *mf)
{
    const int n = o->n;
    const cs_cubemesh *cm = &o->cm;
    int rc = -1;
    int32_t *lat = malloc(sizeof(int32_t) * 3 * (size_t)n);
    int32_t *colour = malloc(sizeof(int32_t) * (size_t)n); /* (i, j, k) mod 7, one number */
    double *e = calloc(3 * (size_t)n, sizeof *e), *y = calloc(3 * (size_t)n, sizeof *y);
    cs_ijk_hash h;
    bool hash_ok = cs_ijk_hash_init(&h, n) == 0;
    mf->row = malloc(sizeof(int32_t) * (size_t)n);
    mf->t = malloc(sizeof(double) * 3 * (size_t)n);
    if (!lat || !colour || !e || !y || !hash_ok || !mf->row || !mf->t)
        goto out;
    int32_t lo[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
    for (int a = 0; a < n; a++)
        for (int k = 0; k < 3; k++) {
            const double t = (cm->node_rest[3 * a + k] - cm->origin[k]) / cm->h;
            lat[3 * a + k] = (int32_t)lround(t);
            lo[k] = lat[3 * a + k] < lo[k] ? lat[3 * a + k] : lo[k];
            hi[k] = lat[3 * a + k] > hi[k] ? lat[3 * a + k] : hi[k];
        }
    for (int a = 0; a < n; a++) {
        const int32_t *q = lat + 3 * a;
        if (cs_ijk_hash_get(&h, q[0], q[1], q[2]) >= 0 || cs_ijk_hash_put(&h, q[0], q[1], q[2], a))
            goto out; /* two nodes at one lattice point (a crack), or out of memory */
    }
    /* rows: the longest axis slowest, the shortest fastest */
    int ax[3] = {0, 1, 2};
    for (int i = 0; i < 3; i++)
        for (int j = i + 1; j < 3; j++)
            if (hi[ax[j]] - lo[ax[j]] > hi[ax[i]] - lo[ax[i]]) {
                const int t = ax[i];
                ax[i] = ax[j];
                ax[j] = t;
            }
    /* rows sorted by key = Σ (l − lo) · stride over the bounding box, slowest axis first */
    const int64_t ext[3] = {hi[ax[0]] - lo[ax[0]] + 1, hi[ax[1]] - lo[ax[1]] + 1,
                            hi[ax[2]] - lo[ax[2]] + 1};
    /* a full box's band is about MF_REACH layers of the two shorter axes: a body whose bounding
     * box gives more than the cap, filled or not, is not scanned (a sparse one could fit, but
     * the scan below costs 343 lookups a node) */
    if ((double)n * MF_REACH * (double)ext[1] * (double)ext[2] > 8 * MF_MAX_BAND)
        goto out;
    int64_t *kk = malloc(sizeof(int64_t) * 2 * (size_t)n); /* (key, node) pairs */
    if (!kk)
        goto out;
    for (int a = 0; a < n; a++) {
        const int32_t *q = lat + 3 * a;
        kk[2 * a] = ((q[ax[0]] - lo[ax[0]]) * ext[1] + (q[ax[1]] - lo[ax[1]])) * ext[2] +
                    (q[ax[2]] - lo[ax[2]]);
        kk[2 * a + 1] = a;
    }
    qsort(kk, (size_t)n, 2 * sizeof(int64_t), cmp_pairs); /* keys distinct: one node a point */
    for (int r = 0; r < n; r++)
        mf->row[kk[2 * r + 1]] = r;
    free(kk);
    /* the band: the farthest row among each node's lattice neighbours within reach */
    int b = 0;
    for (int a = 0; a < n; a++) {
        const int32_t *q = lat + 3 * a;
        for (int dz = -MF_REACH; dz <= MF_REACH; dz++)
            for (int dy = -MF_REACH; dy <= MF_REACH; dy++)
                for (int dx = -MF_REACH; dx <= MF_REACH; dx++) {
                    const int c = cs_ijk_hash_get(&h, q[0] + dx, q[1] + dy, q[2] + dz);
                    if (c >= 0 && mf->row[c] - mf->row[a] > b)
                        b = mf->row[c] - mf->row[a];
                }
    }
    if ((double)n * (b + 1) > MF_MAX_BAND || cs_band_init(&mf->L, n, b) != 0)
        goto out;
    /* columns by colour: e = 1 at the colour's nodes (x components), y = M e */
    const int S = 2 * MF_REACH + 1;
    for (int a = 0; a < n; a++) {
        const int32_t *q = lat + 3 * a;
        int m[3];
        for (int k = 0; k < 3; k++)
            m[k] = ((q[k] % S) + S) % S;
        colour[a] = m[0] + S * (m[1] + S * m[2]);
    }
    for (int col = 0; col < S * S * S; col++) {
        bool any = false;
        for (int a = 0; a < n; a++) {
            e[3 * a] = colour[a] == col;
            any |= colour[a] == col;
        }
        if (!any)
            continue;
        memset(y, 0, 3 * (size_t)n * sizeof *y);
        cs_elastic_apply_M(o, e, y, 1.0);
        for (int a = 0; a < n; a++) {
            if (e[3 * a] == 0)
                continue;
            const int32_t *q = lat + 3 * a;
            for (int dz = -MF_REACH; dz <= MF_REACH; dz++)
                for (int dy = -MF_REACH; dy <= MF_REACH; dy++)
                    for (int dx = -MF_REACH; dx <= MF_REACH; dx++) {
                        const int c = cs_ijk_hash_get(&h, q[0] + dx, q[1] + dy, q[2] + dz);
                        if (c >= 0 && mf->row[c] >= mf->row[a])
                            *cs_band_at(&mf->L, mf->row[c], mf->row[a]) = y[3 * c];
                    }
        }
    }
    if (cs_band_cholesky(&mf->L) != 0)
        goto out;
    mf->version = o->topology_version;
    rc = 0;
out:
    if (hash_ok)
        cs_ijk_hash_free(&h);
    free(lat);
    free(colour);
    free(e);
    free(y);
    if (rc != 0) {
        cs_band_free(&mf->L);
        free(mf->row);
        free(mf->t);
        mf->row = NULL;
        mf->t = NULL;
    }
    return rc;
}

int cs_elastic_mass_factor(cs_object *o)
{
    if (o->mfac && o->mfac->version == o->topology_version)
        return 0;
    if (o->mfac)
        cs_elastic_mass_factor_drop(o);
    if (!o->lf || o->mfac_failed)
        return -1;
    cs_mass_factor *mf = calloc(1, sizeof *mf);
    if (!mf || build_mass_factor(o, mf) != 0) {
        free(mf);
        o->mfac_failed = true;
        return -1;
    }
    o->mfac = mf;
    return 0;
}

void cs_elastic_mass_solve(const cs_object *o, double c, const double *r, double *z)
{
    const cs_mass_factor *mf = o->mfac;
    const int n = o->n;
    double *t = mf->t; /* rows in the factor's order, three components side by side */
    for (int a = 0; a < n; a++)
        for (int k = 0; k < 3; k++)
            t[3 * (size_t)mf->row[a] + k] = r[3 * (size_t)a + k];
    cs_band_solve3(&mf->L, t);
    for (int a = 0; a < n; a++)
        for (int k = 0; k < 3; k++)
            z[3 * (size_t)a + k] = c * t[3 * (size_t)mf->row[a] + k];
}
