/*
 * fem_lattice.c — cs_fem_apply_K and cs_fem_apply_K_mass on a lattice: the nodal vectors as
 * three arrays (x, y, z) over the box of the object's cells, read and summed by whole rows.
 *
 * fem.c's product reads each cell's 8 corners from the interleaved (x, y, z) nodal vectors and
 * transposes them into the SIMD lanes, and writes each cell's 24 results to a slot that a node
 * pass gathers: most of its time goes to those loads, transposes, stores and gathers, not to
 * the arithmetic (README, "The element product against the peak"). Here the object's nodes are
 * placed on the lattice of its bounding box, a row of nodes along x at consecutive places of
 * three component arrays (ps): a batch of 8 cells along a row reads each of its 8 corners'
 * components as one vector load (the dx = 1 corners the same row one place on), with no
 * transpose, and adds its results into the rows of the sums (ys) as whole vectors, each node's
 * two results in the row first added in registers (the dx = 1 corner of cell i − 1 and the
 * dx = 0 corner of cell i: a lane shift). No slots, no node pass. The nodal vectors go onto
 * the lattice and back node layer by node layer: before a cell layer, the node layer above it
 * is placed (loads and permutes where consecutive places hold consecutive nodes, as along a
 * row of a block; one by one elsewhere); after it, the node layer below it is complete and
 * goes back to the nodes with the operator's mass term. Two node layers of inputs and of sums
 * are live per part (225 kB of each on 64³), so they stay in L2.
 *
 * Per lane the arithmetic is fem.c's wide kernel (modal_core.h, rotations rebuilt from the
 * quaternions fem->q), so every cell's 24 results are the same bits; the sums per node are
 * in a fixed order: cell rows by layer (z) then row (y), each adding its pair of results to
 * the node, from zero. The cell layers are split into two parts at a fixed layer (the one
 * that halves the work), whatever the thread count: the second part's sums on the shared
 * node layer are kept apart and added to the first's at the end. So results do not depend on
 * the number of threads; they differ from fem.c's (a different order of the same sums) in the
 * last bits.
 *
 * Taken (cs_fem_lattice_product) on CPUs with AVX-512 (in 512-bit vectors whatever fem->wide
 * says: measured only on Intel's full-width cores; results do not depend on it), for products of the uniform material
 * (fem->kf NULL), without an active region, on meshes whose nodes are each one lattice point
 * (none split by fracture, none without a cell) and whose box holds at most 3 × (nodes + 4096)
 * lattice places; anything else runs fem.c's product.
 */
#include "fem.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <immintrin.h>

#include "lattice_map.h"
#include "mat3.h"
#include "rowbatch.h"

#define LLANES 8 /* cells per batch: doubles per 512-bit vector */

struct cs_fem_lattice {
    cs_lattice_map m; /* places, batches of 8 cells, the two parts (lattice_map.h) */
    uint8_t *bmask; /* per batch (ib + nxb·(j + ny·k)): its lanes with a cell */
    int32_t *bq;    /* per batch: 4·(its first cell) if its 8 cells are consecutive, else -1 */
    int32_t *qix;   /* 8 per batch: 4·cell per lane (0 where none) */
    cs_lattice_bufs b; /* the layers in turn (lattice_map.h), doubles */
};

void cs_fem_lattice_free(cs_fem_lattice *lt)
{
    if (!lt)
        return;
    free(lt->bmask);
    free(lt->bq);
    free(lt->qix);
    cs_lattice_map_free(&lt->m);
    cs_lattice_bufs_free(&lt->b);
    free(lt);
}

int cs_fem_lattice_build(const cs_fem *fem, const cs_cubemesh *cm, cs_fem_lattice **out)
{
    (void)fem;
    *out = NULL;
    cs_lattice_map map;
    const int rc = cs_lattice_map_build(&map, cm, LLANES);
    if (rc <= 0)
        return rc;
    cs_fem_lattice *lt = calloc(1, sizeof *lt);
    if (!lt) {
        cs_lattice_map_free(&map);
        return -1;
    }
    lt->m = map;
    const size_t nb = (size_t)map.nxb * map.ny * map.nz;
    lt->bmask = calloc(nb, 1);
    lt->bq = malloc(nb * sizeof(int32_t));
    lt->qix = calloc(nb * LLANES, sizeof(int32_t));
    if (!lt->bmask || !lt->bq || !lt->qix || cs_lattice_bufs_alloc(&lt->b, &map, sizeof(double))) {
        cs_fem_lattice_free(lt);
        return -1;
    }
    for (size_t b = 0; b < nb; b++) {
        const int32_t *cl = map.cell + LLANES * b;
        bool run = cl[0] >= 0;
        for (int l = 0; l < LLANES; l++) {
            if (cl[l] >= 0) {
                lt->bmask[b] |= (uint8_t)(1u << l);
                lt->qix[LLANES * b + l] = 4 * cl[l];
            }
            run = run && cl[l] == cl[0] + l;
        }
        lt->bq[b] = run ? 4 * cl[0] : -1;
    }
    *out = lt;
    return 0;
}

typedef double vd8 __attribute__((vector_size(64)));
#define MODAL_NAME lattice_core8
#define MODAL_V vd8
#define MODAL_S double
#include "modal_core.h"

/* Cell layer k: each cell row's batches read the four node rows around it from the input
 * layers (pl: node layer k, ph: k + 1; 3 × layer each) and add into those of the sums (yl,
 * yh). A node row is zeroed just before the first cell row of the part that adds to it
 * (first: k is the part's first layer). */
__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4"))) static void
cell_layer(const cs_fem *fem, const cs_fem_lattice *lt, int k, const double *restrict pl,
           const double *restrict ph, double *restrict yl, double *restrict yh, bool first,
           int rot)
{
    const double c16 = fem->h / 16.0;
    const __m512d Lc = _mm512_set1_pd(c16 * fem->lambda * 1.0),
                  Mc = _mm512_set1_pd(c16 * fem->mu * 1.0);
    const size_t layer = lt->m.layer;
    const int sx = lt->m.sx, nxb = lt->m.nxb, ny = lt->m.ny;
    const double *restrict Q = fem->q;
    const __m512i wx = _mm512_setr_epi64(0, 4, 8, 12, 1, 5, 9, 13);
    const __m512i yz = _mm512_setr_epi64(2, 6, 10, 14, 3, 7, 11, 15);
    for (int j = 0; j < ny; j++) {
        const size_t q0 = (size_t)j * sx;
        const double *irow[4] = {pl + q0, pl + q0 + sx, ph + q0, ph + q0 + sx};
        double *orow[4] = {yl + q0, yl + q0 + sx, yh + q0, yh + q0 + sx};
        /* zero the node rows this cell row is the first to reach */
        const bool zero[4] = {j == 0 && first, first, j == 0, true};
        for (int r = 0; r < 4; r++)
            for (int c = 0; zero[r] && c < 3; c++)
                for (int x = 0; x < sx; x += LLANES)
                    _mm512_store_pd(orow[r] + c * layer + x, _mm512_setzero_pd());
        const size_t b0 = (size_t)nxb * (j + (size_t)ny * k);
        /* each node row's last results at dx = 1 (lane 7: the next batch's first node's), in
         * memory: kept in registers they would hold 12 of 32 through the kernel */
        double carry[12][LLANES] __attribute__((aligned(64)));
        bool live = false;
        for (int ib = 0; ib < nxb; ib++) {
            const size_t b = b0 + ib;
            const __mmask8 mask = lt->bmask[b];
            if (!mask || !live) {
                /* the last batch's dx = 1 corner of its last lane: the next node's */
                for (int r = 0; live && r < 4; r++)
                    for (int c = 0; c < 3; c++)
                        orow[r][c * layer + LLANES * ib] += carry[3 * r + c][LLANES - 1];
                for (int v = 0; v < 12; v++)
                    _mm512_store_pd(carry[v], _mm512_setzero_pd());
                live = mask != 0;
                if (!mask)
                    continue;
            }
            vd8 u[24], R[9], y[24];
            const size_t x0 = (size_t)LLANES * ib;
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 3; c++) {
                    const double *p = irow[r] + c * layer + x0;
                    u[3 * CS_ROW_K0[r] + c] = (vd8)_mm512_load_pd(p);
                    u[3 * CS_ROW_K1[r] + c] = (vd8)_mm512_loadu_pd(p + 1);
                }
            if (rot) {
                __m512d w, x1, y1, z1;
                if (lt->bq[b] >= 0) {
                    /* 8 consecutive cells' (w, x, y, z), regrouped by component */
                    const double *Qp = Q + lt->bq[b];
                    const __m512d A = _mm512_loadu_pd(Qp), B = _mm512_loadu_pd(Qp + 8),
                                  C = _mm512_loadu_pd(Qp + 16), D = _mm512_loadu_pd(Qp + 24);
                    const __m512d p0 = _mm512_permutex2var_pd(A, wx, B),
                                  p1 = _mm512_permutex2var_pd(A, yz, B);
                    const __m512d p2 = _mm512_permutex2var_pd(C, wx, D),
                                  p3 = _mm512_permutex2var_pd(C, yz, D);
                    w = _mm512_shuffle_f64x2(p0, p2, 0x44);
                    x1 = _mm512_shuffle_f64x2(p0, p2, 0xEE);
                    y1 = _mm512_shuffle_f64x2(p1, p3, 0x44);
                    z1 = _mm512_shuffle_f64x2(p1, p3, 0xEE);
                } else {
                    const __m256i ix = _mm256_loadu_si256((const __m256i *)(lt->qix + LLANES * b));
                    w = _mm512_i32gather_pd(ix, Q, 8);
                    x1 = _mm512_i32gather_pd(ix, Q + 1, 8);
                    y1 = _mm512_i32gather_pd(ix, Q + 2, 8);
                    z1 = _mm512_i32gather_pd(ix, Q + 3, 8);
                }
                const vd8 W = (vd8)w, X = (vd8)x1, Y = (vd8)y1, Z = (vd8)z1;
                CS_QUAT_TO_MAT(W, X, Y, Z, R);
            }
            const vd8 L = (vd8)_mm512_maskz_mov_pd(mask, Lc), M = (vd8)_mm512_maskz_mov_pd(mask, Mc);
            lattice_core8(u, rot ? R : NULL, 0.0, &L, &M, NULL, y);
            if (mask != 0xff) /* a lane without a cell adds nothing (even for a NaN input) */
                for (int v = 0; v < 24; v++)
                    y[v] = (vd8)_mm512_maskz_mov_pd(mask, (__m512d)y[v]);
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 3; c++) {
                    const __m512d y1 = (__m512d)y[3 * CS_ROW_K1[r] + c];
                    const __m512d sm = _mm512_add_pd(
                        (__m512d)y[3 * CS_ROW_K0[r] + c],
                        _mm512_castsi512_pd(_mm512_alignr_epi64(
                            _mm512_castpd_si512(y1), _mm512_load_si512(carry[3 * r + c]), 7)));
                    double *o = orow[r] + c * layer + x0;
                    _mm512_store_pd(o, _mm512_add_pd(_mm512_load_pd(o), sm));
                    _mm512_store_pd(carry[3 * r + c], y1);
                }
        }
        for (int r = 0; live && r < 4; r++)
            for (int c = 0; c < 3; c++)
                orow[r][c * layer + LLANES * nxb] += carry[3 * r + c][LLANES - 1];
    }
}

/* 8 places' nodal vectors (cs_lattice_group's run and rest) as x, y, z vectors (0 where no node). */
__attribute__((target("arch=x86-64-v4"))) static inline __attribute__((always_inline)) void
group_in(const cs_lattice_map *m, size_t q, const double *restrict p, __m512d v[3])
{
    unsigned run, rest;
    uint64_t e;
    const int32_t base = cs_lattice_group(m, q, &run, &rest, &e);
    const int32_t *node = m->node + q;
    /* masked loads: lanes outside the run are neither read nor faulted */
    const double *s = (const double *)((uintptr_t)p + (uintptr_t)(24 * (int64_t)base));
    cs_xyz8_split(_mm512_maskz_loadu_pd((__mmask8)e, s),
                  _mm512_maskz_loadu_pd((__mmask8)(e >> 8), s + 8),
                  _mm512_maskz_loadu_pd((__mmask8)(e >> 16), s + 16), v);
    for (unsigned r = rest; r; r &= r - 1) {
        const int l = __builtin_ctz(r);
        const double *n = p + 3 * (size_t)node[l];
        for (int c = 0; c < 3; c++)
            v[c] = _mm512_mask_broadcastsd_pd(v[c], (__mmask8)(1u << l), _mm_set_sd(n[c]));
    }
}

/* Node layer kn of the input p onto the lattice (dst: 3 × layer; places without a node 0). */
__attribute__((target("arch=x86-64-v4"))) static void layer_in(const cs_fem_lattice *lt,
                                                                const double *restrict p, int kn,
                                                                double *restrict dst)
{
    const size_t layer = lt->m.layer, q0 = (size_t)kn * layer;
    for (size_t q = 0; q < layer; q += LLANES) {
        __m512d v[3];
        group_in(&lt->m, q0 + q, p, v);
        for (int c = 0; c < 3; c++)
            _mm512_store_pd(dst + c * layer + q, v[c]);
    }
}

/* The operator's terms on the product (lattice_product's). */
typedef struct lat_out {
    const double *p, *m;
    double *y;
    double sign, mcoef;
} lat_out;

/* Node layer kn's sums back to its nodes: y = sign·Σ (+ (mcoef·m_n)·p_n with m), Σ = s1
 * (+ s2: the shared layer, the first part's sum then the second's); pin: the layer's input on
 * the lattice (NULL: read from p). */
__attribute__((target("arch=x86-64-v4"))) static void
layer_out(const cs_fem_lattice *lt, const lat_out *o, int kn, const double *restrict s1,
          const double *restrict s2, const double *restrict pin)
{
    const size_t layer = lt->m.layer, q0 = (size_t)kn * layer;
    const int32_t *node = lt->m.node + q0;
    const __m512d sg = _mm512_set1_pd(o->sign), mc = _mm512_set1_pd(o->mcoef);
    const double *restrict m = o->m;
    double *restrict y = o->y;
    for (size_t q = 0; q < layer; q += LLANES) {
        unsigned run, rest;
        uint64_t e;
        const int32_t base = cs_lattice_group(&lt->m, q0 + q, &run, &rest, &e);
        if (!(run | rest))
            continue;
        __m512d r[3], mm = _mm512_setzero_pd(), P[3];
        if (m) {
            mm = _mm512_maskz_loadu_pd((__mmask8)run, (const void *)((uintptr_t)m + (uintptr_t)(8 * (int64_t)base)));
            for (unsigned t = rest; t; t &= t - 1) {
                const int l = __builtin_ctz(t);
                mm = _mm512_mask_broadcastsd_pd(mm, (__mmask8)(1u << l), _mm_set_sd(m[node[q + l]]));
            }
            mm = _mm512_mul_pd(mc, mm);
            if (pin)
                for (int c = 0; c < 3; c++)
                    P[c] = _mm512_load_pd(pin + c * layer + q);
            else
                group_in(&lt->m, q0 + q, o->p, P);
        }
        for (int c = 0; c < 3; c++) {
            __m512d s = _mm512_load_pd(s1 + c * layer + q);
            if (s2)
                s = _mm512_add_pd(s, _mm512_load_pd(s2 + c * layer + q));
            r[c] = _mm512_mul_pd(sg, s);
            if (m)
                r[c] = _mm512_add_pd(r[c], _mm512_mul_pd(mm, P[c]));
        }
        double *out = (double *)((uintptr_t)y + (uintptr_t)(24 * (int64_t)base));
        __m512d o3[3];
        cs_xyz8_join(r, o3);
        for (int v = 0; v < 3; v++)
            _mm512_mask_storeu_pd(out + 8 * v, (__mmask8)(e >> (8 * v)), o3[v]);
        if (rest) {
            double t[3][LLANES];
            for (int c = 0; c < 3; c++)
                _mm512_storeu_pd(t[c], r[c]);
            for (unsigned u = rest; u; u &= u - 1) {
                const int l = __builtin_ctz(u);
                double *v = y + 3 * (size_t)node[q + l];
                for (int c = 0; c < 3; c++)
                    v[c] = t[c][l];
            }
        }
    }
}

/* The product's steps for cs_lattice_run. */
typedef struct fem_pass {
    const cs_fem *fem;
    const cs_fem_lattice *lt;
    lat_out o;
    int rot;
} fem_pass;

static void pass_in(void *ctx, int kn, void *dst)
{
    const fem_pass *f = ctx;
    layer_in(f->lt, f->o.p, kn, dst);
}

static void pass_cells(void *ctx, int k, const void *pl, const void *ph, void *yl, void *yh,
                       bool first)
{
    const fem_pass *f = ctx;
    cell_layer(f->fem, f->lt, k, pl, ph, yl, yh, first, f->rot);
}

static void pass_out(void *ctx, int kn, const void *s1, const void *s2, const void *pin)
{
    const fem_pass *f = ctx;
    layer_out(f->lt, &f->o, kn, s1, s2, pin);
}

bool cs_fem_lattice_product(cs_fem *fem, const double *kf, double sign, double mcoef,
                            const double *m, const double *p, double *y)
{
    cs_fem_lattice *lt = fem->lat;
    if (!lt || !fem->lattice || kf || fem->cell_active ||
        !__builtin_cpu_supports("x86-64-v4"))
        return false;
    fem_pass f = {fem, lt, {p, m, y, sign, mcoef}, fem->corotational};
    const cs_lattice_pass pass = {&f, pass_in, pass_cells, pass_out};
    cs_lattice_run(&lt->m, fem->threads, &lt->b, &pass);
    return true;
}
