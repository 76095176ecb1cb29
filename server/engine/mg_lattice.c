/*
 * mg_lattice.c — the V-cycle's float passes on the lattice (mg_lattice.h).
 *
 * The same scheme as fem_lattice.c (read it first): the level's nodal vectors placed on the
 * lattice of its cells' box, node layer by node layer, as x, y, z arrays; a batch of 16 cells
 * along a row reads its corners with whole-vector loads and adds its results into the rows of
 * the sums, each node's pair of results in the row added by a lane shift; a node layer whose
 * cells are done goes back to the nodes through the node pass of mg.c's node_out (y = A x, the
 * residual, or a Chebyshev step on it). The node pass's per-node data are kept on the lattice
 * too (cs_mgl_set, every setup): D⁻¹, the diagonal term and the held dofs; the cells' scales
 * and quaternions per lattice batch. Two parts split at a fixed cell layer (the shared node
 * layer's pass after both), so results do not depend on the thread count; they differ from
 * mg.c's slots and node pass (the same sums in another order) in the last bits.
 *
 * Per lane the element arithmetic is mg.c's wide kernel (modal_core.h in float, R rebuilt from
 * the quaternions), each node's pass node_out's operations in the same order (no fused
 * multiply-adds there).
 */
#include "mg_lattice.h"

#include <stdlib.h>
#include <string.h>

#include <immintrin.h>

#include "lattice_map.h"
#include "mat3.h"
#include "rowbatch.h"

#define GL 16 /* cells per batch: floats per 512-bit vector */

struct cs_mgl {
    cs_lattice_map m;
    uint16_t *bmask; /* per batch: its lanes with a cell */
    float *lL, *lM;  /* per batch 16: the cells' s·hλ/16, s·hμ/16 (0 without a cell) */
    float *lQ;       /* per batch 4 × 16: their quaternions (w, x, y, z; identity without) */
    bool q_ok;       /* the last setup's quaternions hold the rotations */
    float *linv;     /* 9 × npos: D⁻¹ by columns (invf's order), per place */
    float *ldg;      /* npos: the diagonal term */
    uint8_t *lheld;  /* npos: held bits */
    cs_lattice_bufs b; /* the layers in turn (lattice_map.h), floats */
};

void cs_mgl_free(cs_mgl *g)
{
    if (!g)
        return;
    cs_lattice_map_free(&g->m);
    free(g->bmask);
    free(g->lL);
    free(g->lM);
    free(g->lQ);
    free(g->linv);
    free(g->ldg);
    free(g->lheld);
    cs_lattice_bufs_free(&g->b);
    free(g);
}

static float *alloc_floats(size_t n)
{
    return cs_lattice_zalloc(n * sizeof(float));
}

int cs_mgl_build(const cs_cubemesh *cm, cs_mgl **out)
{
    *out = NULL;
    cs_lattice_map map;
    const int rc = cs_lattice_map_build(&map, cm, GL);
    if (rc <= 0)
        return rc;
    cs_mgl *g = calloc(1, sizeof *g);
    if (!g) {
        cs_lattice_map_free(&map);
        return -1;
    }
    g->m = map;
    const size_t nb = (size_t)map.nxb * map.ny * map.nz;
    g->bmask = calloc(nb, sizeof *g->bmask);
    g->lL = alloc_floats(nb * GL);
    g->lM = alloc_floats(nb * GL);
    g->lQ = alloc_floats(nb * GL * 4);
    g->linv = alloc_floats(9 * map.npos);
    g->ldg = alloc_floats(map.npos);
    g->lheld = calloc(map.npos + GL, 1);
    if (!g->bmask || !g->lL || !g->lM || !g->lQ || !g->linv || !g->ldg || !g->lheld ||
        cs_lattice_bufs_alloc(&g->b, &map, sizeof(float))) {
        cs_mgl_free(g);
        return -1;
    }
    for (size_t b = 0; b < nb; b++)
        for (int l = 0; l < GL; l++) {
            if (map.cell[GL * b + l] >= 0)
                g->bmask[b] |= (uint16_t)(1u << l);
            g->lQ[4 * GL * b + l] = 1.0f; /* the identity where no cell */
        }
    *out = g;
    return 0;
}

void cs_mgl_set(cs_mgl *g, const float *bL, const float *bM, const float *bQ, bool q_ok,
                const float *invf, const float *dgf, const uint8_t *held, bool same, int threads)
{
    const cs_lattice_map *m = &g->m;
    const int64_t nb = (int64_t)m->nxb * m->ny * m->nz, np = (int64_t)m->npos;
    g->q_ok = q_ok;
#pragma omp parallel num_threads(threads)
    {
#pragma omp for schedule(static) nowait
        for (int64_t b = 0; b < nb; b++)
            for (int l = 0; l < GL; l++) {
                const int32_t c = m->cell[GL * b + l];
                if (c < 0)
                    continue;
                const size_t cb = (size_t)c / GL, cl = (size_t)c % GL;
                for (int j = 0; q_ok && j < 4; j++)
                    g->lQ[GL * (4 * b + j) + l] = bQ[GL * (4 * cb + j) + cl];
                if (!same) {
                    g->lL[GL * b + l] = bL[c];
                    g->lM[GL * b + l] = bM[c];
                }
            }
#pragma omp for schedule(static)
        for (int64_t q = 0; q < np; q++) {
            const int32_t n = m->node[q];
            if (n < 0)
                continue;
            for (int e = 0; e < 9; e++)
                g->linv[e * np + q] = invf[9 * (size_t)n + e];
            if (!same) {
                g->ldg[q] = dgf[n];
                g->lheld[q] = held[n];
            }
        }
    }
}

typedef float vf16 __attribute__((vector_size(64)));
#define MODAL_NAME lattice_core16
#define MODAL_V vf16
#define MODAL_S float
#include "modal_core.h"

/* Cell layer k (fem_lattice.c's cell_layer in float, 16 lanes). */
__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4"))) static void
cell_layer(const cs_mgl *g, int k, const float *restrict pl, const float *restrict ph,
           float *restrict yl, float *restrict yh, bool first)
{
    const cs_lattice_map *m = &g->m;
    const size_t layer = m->layer;
    const int sx = m->sx, nxb = m->nxb, ny = m->ny;
    for (int j = 0; j < ny; j++) {
        const size_t q0 = (size_t)j * sx;
        const float *irow[4] = {pl + q0, pl + q0 + sx, ph + q0, ph + q0 + sx};
        float *orow[4] = {yl + q0, yl + q0 + sx, yh + q0, yh + q0 + sx};
        const bool zero[4] = {j == 0 && first, first, j == 0, true};
        for (int r = 0; r < 4; r++)
            for (int c = 0; zero[r] && c < 3; c++)
                for (int x = 0; x < sx; x += GL)
                    _mm512_store_ps(orow[r] + c * layer + x, _mm512_setzero_ps());
        const size_t b0 = (size_t)nxb * (j + (size_t)ny * k);
        float carry[12][GL] __attribute__((aligned(64)));
        bool live = false;
        for (int ib = 0; ib < nxb; ib++) {
            const size_t b = b0 + ib;
            const __mmask16 mask = g->bmask[b];
            if (!mask || !live) {
                for (int r = 0; live && r < 4; r++)
                    for (int c = 0; c < 3; c++)
                        orow[r][c * layer + GL * ib] += carry[3 * r + c][GL - 1];
                for (int v = 0; v < 12; v++)
                    _mm512_store_ps(carry[v], _mm512_setzero_ps());
                live = mask != 0;
                if (!mask)
                    continue;
            }
            vf16 u[24], R[9], y[24], L, M, q[4];
            const size_t x0 = (size_t)GL * ib;
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 3; c++) {
                    const float *p = irow[r] + c * layer + x0;
                    u[3 * CS_ROW_K0[r] + c] = (vf16)_mm512_load_ps(p);
                    u[3 * CS_ROW_K1[r] + c] = (vf16)_mm512_loadu_ps(p + 1);
                }
            for (int j4 = 0; j4 < 4; j4++)
                q[j4] = (vf16)_mm512_load_ps(g->lQ + GL * (4 * b + j4));
            const vf16 w = q[0], qx = q[1], qy = q[2], qz = q[3];
            CS_QUAT_TO_MAT(w, qx, qy, qz, R);
            L = (vf16)_mm512_load_ps(g->lL + GL * b);
            M = (vf16)_mm512_load_ps(g->lM + GL * b);
            lattice_core16(u, R, 0.0f, &L, &M, NULL, y);
            if (mask != 0xffff)
                for (int v = 0; v < 24; v++)
                    y[v] = (vf16)_mm512_maskz_mov_ps(mask, (__m512)y[v]);
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 3; c++) {
                    const __m512 y1 = (__m512)y[3 * CS_ROW_K1[r] + c];
                    const __m512 sm = _mm512_add_ps(
                        (__m512)y[3 * CS_ROW_K0[r] + c],
                        _mm512_castsi512_ps(_mm512_alignr_epi32(_mm512_castps_si512(y1),
                                                                _mm512_load_si512(carry[3 * r + c]), 15)));
                    float *o = orow[r] + c * layer + x0;
                    _mm512_store_ps(o, _mm512_add_ps(_mm512_load_ps(o), sm));
                    _mm512_store_ps(carry[3 * r + c], y1);
                }
        }
        for (int r = 0; live && r < 4; r++)
            for (int c = 0; c < 3; c++)
                orow[r][c * layer + GL * nxb] += carry[3 * r + c][GL - 1];
    }
}

/* 16 places' 3-vectors of the node-ordered v as x, y, z vectors (0 where no node). */
__attribute__((target("arch=x86-64-v4"))) static inline __attribute__((always_inline)) void
group_in(const cs_lattice_map *m, size_t q, const float *restrict v, __m512 o[3])
{
    unsigned run, rest;
    uint64_t e;
    const int32_t base = cs_lattice_group(m, q, &run, &rest, &e);
    const int32_t *node = m->node + q;
    const float *s = (const float *)((uintptr_t)v + (uintptr_t)(12 * (int64_t)base));
    cs_xyz16_split(_mm512_maskz_loadu_ps((__mmask16)e, s),
                   _mm512_maskz_loadu_ps((__mmask16)(e >> 16), s + 16),
                   _mm512_maskz_loadu_ps((__mmask16)(e >> 32), s + 32), o);
    for (unsigned r = rest; r; r &= r - 1) {
        const int l = __builtin_ctz(r);
        const float *n = v + 3 * (size_t)node[l];
        for (int c = 0; c < 3; c++)
            o[c] = _mm512_mask_broadcastss_ps(o[c], (__mmask16)(1u << l), _mm_set_ss(n[c]));
    }
}

/* x, y, z vectors of 16 places (r) into the node-ordered dst (3 per node). */
__attribute__((target("arch=x86-64-v4"))) static inline __attribute__((always_inline)) void
group_out(const cs_lattice_map *m, size_t q, const __m512 r[3], float *restrict dst,
          double *restrict dd)
{
    unsigned run, rest;
    uint64_t e;
    const int32_t base = cs_lattice_group(m, q, &run, &rest, &e);
    const int32_t *node = m->node + q;
    __m512 o3[3];
    cs_xyz16_join(r, o3);
    float *o = (float *)((uintptr_t)dst + (uintptr_t)(12 * (int64_t)base));
    for (int v = 0; v < 3; v++)
        _mm512_mask_storeu_ps(o + 16 * v, (__mmask16)(e >> (16 * v)), o3[v]);
    if (dd) {
        double *od = (double *)((uintptr_t)dd + (uintptr_t)(24 * (int64_t)base));
        for (int v = 0; v < 3; v++) {
            _mm512_mask_storeu_pd(od + 16 * v, (__mmask8)(e >> (16 * v)),
                                  _mm512_cvtps_pd(_mm512_castps512_ps256(o3[v])));
            _mm512_mask_storeu_pd(od + 16 * v + 8, (__mmask8)(e >> (16 * v + 8)),
                                  _mm512_cvtps_pd(_mm512_extractf32x8_ps(o3[v], 1)));
        }
    }
    if (rest) {
        float t[3][GL];
        for (int c = 0; c < 3; c++)
            _mm512_storeu_ps(t[c], r[c]);
        for (unsigned u = rest; u; u &= u - 1) {
            const int l = __builtin_ctz(u);
            const size_t n = (size_t)node[l];
            for (int c = 0; c < 3; c++) {
                dst[3 * n + c] = t[c][l];
                if (dd)
                    dd[3 * n + c] = t[c][l];
            }
        }
    }
}

/* The pass's operands (cs_mgl_apply's). */
typedef struct mgl_op {
    int mode;
    float *x;
    const float *b;
    float *y;
    float c;
    double *out;
} mgl_op;

/* Node layer kn from its sums s1 (+ s2: the shared layer, the first part's then the second's)
 * through node_out's pass; xin: the layer's x on the lattice (NULL: read from o->x). */
__attribute__((target("arch=x86-64-v4"))) static void
layer_out(const cs_mgl *g, const mgl_op *o, int kn, const float *restrict s1,
          const float *restrict s2, const float *restrict xin)
{
    const size_t layer = g->m.layer, np = g->m.npos, q0 = (size_t)kn * layer;
    const __m512 cc = _mm512_set1_ps(o->c);
    for (size_t q = 0; q < layer; q += GL) {
        const size_t gq = (q0 + q) / GL;
        if (!(g->m.grun[gq] | g->m.grest[gq]))
            continue;
        __m512 xv[3], ax[3];
        if (xin)
            for (int c = 0; c < 3; c++)
                xv[c] = _mm512_load_ps(xin + c * layer + q);
        else
            group_in(&g->m, q0 + q, o->x, xv);
        const __m512 dg = _mm512_load_ps(g->ldg + q0 + q);
        for (int c = 0; c < 3; c++) {
            __m512 s = _mm512_load_ps(s1 + c * layer + q);
            if (s2)
                s = _mm512_add_ps(s, _mm512_load_ps(s2 + c * layer + q));
            ax[c] = _mm512_add_ps(s, _mm512_mul_ps(dg, xv[c]));
        }
        if (o->mode == CS_MGL_APPLY) {
            group_out(&g->m, q0 + q, ax, o->y, NULL);
            continue;
        }
        const __m512i h = _mm512_cvtepu8_epi32(_mm_loadu_si128((const __m128i *)(g->lheld + q0 + q)));
        __mmask16 fr[3];
        for (int c = 0; c < 3; c++)
            fr[c] = _mm512_testn_epi32_mask(h, _mm512_set1_epi32(1 << c));
        __m512 bv[3], r[3];
        group_in(&g->m, q0 + q, o->b, bv);
        for (int c = 0; c < 3; c++)
            r[c] = _mm512_maskz_sub_ps(fr[c], bv[c], ax[c]);
        if (o->mode == CS_MGL_RESID) {
            group_out(&g->m, q0 + q, r, o->y, NULL);
            continue;
        }
        const float *inv = g->linv + q0 + q;
        __m512 xn[3];
        for (int k = 0; k < 3; k++) {
            const __m512 z = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(_mm512_load_ps(inv + (size_t)k * np), r[0]),
                              _mm512_mul_ps(_mm512_load_ps(inv + (size_t)(3 + k) * np), r[1])),
                _mm512_mul_ps(_mm512_load_ps(inv + (size_t)(6 + k) * np), r[2]));
            const __m512 dj = _mm512_maskz_mul_ps(fr[k], cc, z);
            xn[k] = _mm512_maskz_add_ps(fr[k], xv[k], dj);
        }
        group_out(&g->m, q0 + q, xn, o->x, o->out);
    }
}

/* Node layer kn of v onto the lattice (dst: 3 × layer). */
__attribute__((target("arch=x86-64-v4"))) static void layer_in(const cs_mgl *g,
                                                                const float *restrict v, int kn,
                                                                float *restrict dst)
{
    const size_t layer = g->m.layer, q0 = (size_t)kn * layer;
    for (size_t q = 0; q < layer; q += GL) {
        __m512 o[3];
        group_in(&g->m, q0 + q, v, o);
        for (int c = 0; c < 3; c++)
            _mm512_store_ps(dst + c * layer + q, o[c]);
    }
}

/* The passes' steps for cs_lattice_run. */
typedef struct mgl_pass {
    const cs_mgl *g;
    mgl_op o;
} mgl_pass;

static void pass_in(void *ctx, int kn, void *dst)
{
    const mgl_pass *f = ctx;
    layer_in(f->g, f->o.x, kn, dst);
}

static void pass_cells(void *ctx, int k, const void *pl, const void *ph, void *yl, void *yh,
                       bool first)
{
    const mgl_pass *f = ctx;
    cell_layer(f->g, k, pl, ph, yl, yh, first);
}

static void pass_out(void *ctx, int kn, const void *s1, const void *s2, const void *pin)
{
    const mgl_pass *f = ctx;
    layer_out(f->g, &f->o, kn, s1, s2, pin);
}

bool cs_mgl_apply(cs_mgl *g, int threads, int mode, float *x, const float *b, float *y, float c,
                  double *out)
{
    if (!g || !g->q_ok || !__builtin_cpu_supports("x86-64-v4"))
        return false;
    mgl_pass f = {g, {mode, x, b, y, c, out}};
    const cs_lattice_pass pass = {&f, pass_in, pass_cells, pass_out};
    cs_lattice_run(&g->m, threads, &g->b, &pass);
    return true;
}
