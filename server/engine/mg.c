/*
 * mg.c — geometric multigrid preconditioner on the cube lattice (see mg.h).
 */
#include "mg.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <immintrin.h>
#include <omp.h>

#include "mat3.h"
#include "mg_lattice.h"
#include "rowbatch.h"
#include "segments.h"
#include "simd.h"

#define MG_NU 1           /* smoothing sweeps before and after the coarse correction */
#ifndef MG_CHEB
#define MG_CHEB 2         /* Chebyshev degree on the finest level (0: damped Jacobi, MG_NU sweeps) */
#endif
/* Session 17 (README "Cheaper cycles, measured"): degree 1 on the finest level (2 products per
 * cycle instead of 4) took 1.5–2× the CG iterations, a hybrid of degree 1 with the second
 * weight added to the coarse correction 1.2–1.7×, an additive two-level cycle (no finest
 * products) 3–4×; degree 1 breaks even at about 1.36×: none kept. */
/* ... and on the finest level of a nearly incompressible material, Poisson ratio ν ≥ MG_CHEB_NU
 * (λ ≥ 4μ): there degree 3 took 14–28 % fewer CG iterations per step than 2 (75×15×15 beam,
 * 32³ block; ν = 0.4, 0.45, 0.49), for about 20 % more instructions per iteration: the same
 * instructions per step, 6–12 % less CPU time (fewer passes over CG's double vectors). At
 * ν = 0.3 it saved 8–10 % of the iterations, which did not pay (README "Multigrid against
 * block Jacobi"). */
#ifndef MG_CHEB_NEAR_INCOMPRESSIBLE
#define MG_CHEB_NEAR_INCOMPRESSIBLE 3
#endif
#define MG_CHEB_NU 0.4
#ifndef MG_CHEB_COARSE
#define MG_CHEB_COARSE 3  /* ... and on the coarse levels (an eighth of the cost each) */
#endif
/* (Degree 2 on every coarse level, on level 1 only or on the thin levels only cost 2–18 % more
 * iterations somewhere on each of those rules: beams, ν = 0.45, 32³, a plate; session 17.) */
/* The smoothing polynomial's kind. 4 (default): Lottes' optimised fourth kind over [0, λ]
 * (cs_mg_smoother_steps), λ = MG_LAMBDA_SAFETY × the power estimate of λmax(D⁻¹A); |1 − t p|
 * stays below 1 up to 1.17 λ (degree 2) and 1.11 λ (degree 3), i.e. to 1.29× and 1.22× the
 * estimate (test_mg_smoother.c). Session 14: 5–13 % fewer CG iterations per step than kind 1
 * on the bench beams, blocks and ν = 0.3–0.49, for the same products per cycle (README
 * "Multigrid against block Jacobi"). 1: the first kind over [λ/MG_CHEB_RATIO, λ] (sessions
 * 11–13), at most 1 in modulus up to λ (1 + 1/ratio) = 1.375× the estimate; a wider interval
 * (ratio 6) took 5–10 % fewer iterations in the first steps from rest but 25–33 % more in
 * long warm-started runs: not kept. */
#ifndef MG_CHEB_KIND
#define MG_CHEB_KIND 4
#endif
_Static_assert(MG_CHEB_KIND != 4 ||
                   (MG_CHEB <= 3 && MG_CHEB_COARSE <= 3 && MG_CHEB_NEAR_INCOMPRESSIBLE <= 3),
               "the fourth-kind degrees above 3 leave under 1.1 λ of room (test_mg_smoother)");
#ifndef MG_CHEB_RATIO
#define MG_CHEB_RATIO 4.0
#endif
#ifndef MG_LAMBDA_SAFETY
#define MG_LAMBDA_SAFETY 1.1
#endif
/* W-cycle: a coarse level with at least this many nodes per cell is solved by two cycles
 * instead of one (cs_mg_build). Such a level is thin or small (a box: 1.1 nodes per cell at
 * 32³, 1.3 at 38×8×8, 1.6 at 19×4×4 or 32×32×2, 2 at 4³), its coarser levels are thinner
 * still, and coarse trilinear cubes a cell or two thick lock in bending: their correction is
 * poor for a stiff thin body's bending modes, and a second cycle recovers most of an exact
 * solve (README "Multigrid against block Jacobi"). A cycle on a thick level costs more and
 * helped less: one on 38×8×8 (level 1 of the 75×15×15 beam) took its iterations from 5.3 to
 * 4.9 for +19 % per V-cycle (48³). */
#define MG_W_NODES_PER_CELL 1.5
#define MG_COARSE_SWEEPS 8 /* Jacobi sweeps on a coarsest level too large for Cholesky */
#define MG_POWER_ITERS 10
#define MG_ROT_BATCH 16    /* coarse cells per batch of setup_coarse's rotation extraction */
#ifndef MG_CHUNK /* batches per chunk of apply_ex (1024 cells, 128 KiB of results) */
#define MG_CHUNK 64
#endif
#define MG_LANES 16        /* cells per batch of the element pass (one float SIMD lane each) */
#define VF_LANES 8         /* lanes per vector of the element pass's arithmetic */
enum { SIMD_256 = 1, SIMD_512 = 2 }; /* cs_mg.simd */
typedef float vf __attribute__((vector_size(4 * VF_LANES)));
#define MODAL_NAME modal_core_f
#define MODAL_V vf
#define MODAL_S float
#include "modal_core.h"
/* A level with fewer cells runs on one thread. 256 (the beam's 19×4×4 level on two threads
 * too) measured on the loaded machine of session 17: stiff beam 40 → 22 steps/s with
 * OMP_WAIT_POLICY=passive (more synchronisations, each a futex wake-up), 19.7 → 20.4 with the
 * default spinning (medians of 6 rounds; noise); idle in session 18: within the host's noise
 * (bench/HISTORY.md "Session 18: where the second thread waits"). */
#ifndef MG_PARALLEL_CELLS
#define MG_PARALLEL_CELLS CS_FEM_PARALLEL_CELLS
#endif
#define MG_LAMBDA_EVERY 64 /* re-estimate λmax(D⁻¹A) after this many setups */
/* Levels with at least this many cells run their passes on the lattice where they can
 * (mg_lattice.c); below, mg.c's slots and node pass. */
#ifndef MG_LATTICE_CELLS
#define MG_LATTICE_CELLS 256
#endif

typedef struct mg_tw {
    int32_t node;
    float w;
} mg_tw;

typedef struct mg_level {
    int n_cells, n_nodes, threads;
    const int32_t *cell_nodes, *cell_ijk, *adj_start, *adj; /* borrowed on level 0 */
    int32_t *own_nodes, *own_ijk, *own_adj_start, *own_adj;
    /* to the next coarser level (NULL on the coarsest) */
    int32_t *parent;                  /* per cell */
    int32_t *p_start, *p_node;        /* per node: prolongation row */
    double *p_w;
    int32_t *r_start, *r_node;        /* per coarse node: its fine nodes (Pᵀ) */
    double *r_w;
    /* the V-cycle's copies of both (transfer_layout): (node, weight in float) pairs, one
     * 8-byte stream per transfer instead of a 4- and an 8-byte one */
    mg_tw *p_tw, *r_tw;
    /* ... and the prolongation by coarse cells (transfer_layout; NULL: by p_tw): per coarse
     * cell C, the fine nodes whose row was made from C (their first cell's parent), each as
     * n | (position of n in C, 0..26) << 27; their rows are the cs_mg position tables' */
    int32_t *pc_start;                /* per coarse cell */
    uint32_t *pc_ent;
    int32_t *p_lone;                  /* the fine nodes with empty rows (no cell) */
    int n_lone;
    /* the restriction's pairs packed (transfer_layout; NULL: r_tw): fine node | e << 27 for
     * the weight 2^−e, e = 0..3 (the trilinear weights are 1, 1/2, 1/4, 1/8): 4 bytes each */
    uint32_t *r_pk;
    /* from the next finer level (level >= 1) */
    int32_t *ch_start, *ch;           /* children of each cell */
    int32_t *walk;                    /* the cells in the order of their first child */
    int32_t *nwalk;                   /* the nodes in the order of their first fine node */
    /* per solve */
    const double *R;                  /* 9 per cell (level 0: fem's) */
    const double *rq;                 /* 4 per cell: the unit quaternions R was made from */
    double *own_R, *q;                /* level >= 1 */
    double *s;                        /* per cell: stiffness multiplier */
    double *dg;                       /* per node: diagonal part */
    const double *inv;                /* 9 per node, inverted diagonal blocks */
    double *own_inv;
    const uint8_t *mask;
    uint8_t *own_mask;
    /* the V-cycle's single-precision copies (converted in cs_mg_setup) and scratch */
    float *dgf;                       /* per node: dg */
    float *invf;                      /* per node: D⁻¹ by columns (9, and one float of tail) */
    uint8_t *held;                    /* per node: its held dofs, bits 1, 2, 4 for x, y, z */
    float *x, *b, *t, *d;             /* 3 per node each */
    /* the element pass, in batches of MG_LANES cells (cell c: batch c / MG_LANES, lane
     * c % MG_LANES; lanes past the last cell repeat the batch's first cell with L = M = 0) */
    int n_batches;
    int32_t *bidx;                    /* per batch 8 × MG_LANES: 3·node of corner k per lane */
    /* ... or, where every batch's corners lie within 65536 floats of x (narrow_corners: any
     * box up to about 100 cells across a layer), as 16-bit offsets from a base per batch
     * (half the bytes; bidx is then NULL) */
    int32_t *bbase;                   /* per batch: the least 3·node of its corners */
    uint16_t *bidx16;                 /* per batch 8 × MG_LANES: 3·node − bbase */
    float *bR;                        /* per batch 9 × MG_LANES: R_c (cs_mg_setup) */
    /* ... and as unit quaternions (w, x, y, z), per batch 4 × MG_LANES (rotation_layout, per
     * setup): the element pass rebuilds R from them (16 bytes a cell to stream instead of
     * 36); bQ_ok false (R not a rotation to float precision somewhere): it reads bR */
    float *bQ;
    bool bQ_ok;
    float *bL, *bM;                   /* per batch MG_LANES: s_c·hλ/16, s_c·hμ/16 (cs_mg_setup) */
    /* The cells' products, 8 corners × (x, y, z, ·) per cell (32 floats), in a window per
     * segment of batches
     * (product_layout): a node's links are read back soon after they are written, and the
     * window stays in L2 instead of going out to memory. */
    float *fe;
    int32_t *bslot;                   /* per batch: its slot in fe */
    /* Row batches (product_layout): a batch of 16 cells along x in one lattice row whose four
     * node rows (one per (dy, dz)) are each 17 consecutive nodes; rowb[4b + r] = 3·(the first
     * node of node row r), rowb[4b] = -1: not a row batch. Its element pass reads each node row
     * with whole-vector loads and adds each node's two results in the row (the cell before it
     * at dx = 1 and the cell after at dx = 0) before storing them: fe holds per node row 17
     * nodes' (x, y, z) from the batch's slot + 64 r, the last one the row's end node. */
    int32_t *rowb;
    int n_row_batches;
    /* per link of the node pass (nstart: per node, its first; n_nodes + 1): its x component
     * in fe. The links of adj in adj's order, less those a row batch added into another. */
    int32_t *nstart;
    int32_t *fadj;
    int nseg;                         /* segments of batches: l->threads */
    int span;                         /* the most batches between a node's first and last cell */
    /* the node pass follows the element pass chunk by chunk (apply_ex): the nodes ordered by
     * the batch of their last cell (nodes without cells: batch 0), then by index */
    int32_t *norder;                  /* n_nodes */
    int32_t *nminb;                   /* per position in norder: the batch of its first cell */
    int32_t *nfirst;                  /* n_batches + 1: first position whose last batch >= b */
    double lam;
    float omega;
    int cheb_deg;                     /* Chebyshev degree of this level's smoother */
    /* cycles that solve this level's problem for the next finer one: 2 (W) on levels with at
     * least MG_W_NODES_PER_CELL nodes per cell (cs_mg_build), 1 elsewhere; gb, gx: the
     * second cycle's residual and correction (NULL with one cycle) */
    int cycles;
    float *gb, *gx;
    double cheb_c[CS_MG_CHEB_MAX];    /* fourth kind: the steps' weights × λ (cs_mg_smoother_steps) */
    /* the level's passes on the lattice of its cells' box (mg_lattice.c; NULL: not this
     * level: fewer than MG_LATTICE_CELLS cells, or not one node per lattice point) */
    cs_mgl *lat;
} mg_level;

struct cs_mg {
    int n_levels;
    mg_level *lv;
    uint32_t version;
    int fine_nodes, fine_cells;
    const int32_t *fine_links;
    double K[576];
    double hl, hm;     /* hλ, hμ of K (cs_cube_lame_h) */
    int simd;          /* the element pass: 0 portable, SIMD_256 or SIMD_512 (AVX-512) */
    double *dense;     /* coarsest: Cholesky factor (lower), NULL if swept */
    double *dense_x;   /* its right-hand side and solution in double */
    int dense_n;
    cs_matvec_fn A;
    void *ctx;
    /* the trilinear rows by a fine node's position t in its coarse cell (t0 + 3 t1 + 9 t2,
     * half-units): its nonzero weights' corners K, increasing, and the weights in float */
    uint8_t pos_n[27], pos_k[27][8];
    float pos_w[27][8];
    int setups;
    double key[3];
    /* What the last setup's level 0 was built from besides the rotations (its cell scales s,
     * node diagonal dg and held dofs; NULL before the first): a setup whose three are the same
     * (a lagged hierarchy rebuilt because the rotations turned) keeps every level's derived
     * copies of them (cs_mg_setup: coarse s, dg and held dofs, bL, bM, dgf, held). */
    double *prev_s, *prev_dg;
    uint8_t *prev_mask;
    bool prev_ok; /* they hold a whole setup's (a failed one clears it) */
    bool lattice; /* take the levels' lattice passes (cs_mg_set_lattice; true by default) */
};

static bool corner_blocks_ok(const double *K);

/* ------------------------------------------------------------------ building */

static int64_t floordiv2(int32_t v)
{
    return v >= 0 ? v / 2 : -((-v + 1) / 2);
}

/* Parent indices are within ±2^19 (cell indices within ±2^20, cubemesh.h): 21 bits each. */
static int64_t pack(int64_t i, int64_t j, int64_t k)
{
    const uint64_t o = 1u << 20, m = (1u << 21) - 1;
    return (int64_t)((((uint64_t)(i + o) & m) << 42) | (((uint64_t)(j + o) & m) << 21) |
                     ((uint64_t)(k + o) & m));
}

typedef struct keyed {
    int64_t key;
    int32_t idx;
} keyed;

static int cmp_keyed(const void *a, const void *b)
{
    const keyed *x = a, *y = b;
    if (x->key != y->key)
        return x->key < y->key ? -1 : 1;
    return (x->idx > y->idx) - (x->idx < y->idx);
}

static int uf_find(int32_t *p, int32_t a)
{
    while (p[a] != a) {
        p[a] = p[p[a]];
        a = p[a];
    }
    return a;
}

static void uf_union(int32_t *p, int32_t a, int32_t b)
{
    a = uf_find(p, a);
    b = uf_find(p, b);
    if (a != b) {
        if (a < b)
            p[b] = a;
        else
            p[a] = b;
    }
}

/* node → (cell·8 + corner), cells in increasing order */
static int build_adj(mg_level *l)
{
    l->own_adj_start = calloc((size_t)l->n_nodes + 1, sizeof(int32_t));
    l->own_adj = malloc((size_t)l->n_cells * 8 * sizeof(int32_t));
    int32_t *fill = malloc(((size_t)l->n_nodes + 1) * sizeof(int32_t));
    if (!l->own_adj_start || !l->own_adj || !fill) {
        free(fill);
        return -1;
    }
    for (int e = 0; e < 8 * l->n_cells; e++)
        l->own_adj_start[l->cell_nodes[e] + 1]++;
    for (int n = 0; n < l->n_nodes; n++)
        l->own_adj_start[n + 1] += l->own_adj_start[n];
    memcpy(fill, l->own_adj_start, (size_t)l->n_nodes * sizeof(int32_t));
    for (int e = 0; e < 8 * l->n_cells; e++)
        l->own_adj[fill[l->cell_nodes[e]]++] = e;
    free(fill);
    l->adj_start = l->own_adj_start;
    l->adj = l->own_adj;
    return 0;
}

/* Trilinear weight of coarse corner K for a fine node at half-units t (0..2 per axis). */
static double corner_weight(const int t[3], int K)
{
    double w = 1;
    for (int a = 0; a < 3; a++)
        w *= CS_CORNER[K][a] ? t[a] * 0.5 : 1.0 - t[a] * 0.5;
    return w;
}

/* Position of fine corner k of fine cell c inside its parent C, in half-units. */
static void half_units(const mg_level *f, const mg_level *c, int fc, int k, int C, int t[3])
{
    for (int a = 0; a < 3; a++)
        t[a] = f->cell_ijk[3 * fc + a] - 2 * c->cell_ijk[3 * C + a] + CS_CORNER[k][a];
}

/* Make level c from level f; c is zeroed. Returns 0, -1 on out of memory. */
static int coarsen(mg_level *f, mg_level *c)
{
    int rc = -1;
    const int nf = f->n_cells;
    keyed *ks = malloc((size_t)nf * sizeof *ks);
    int32_t *slot = NULL, *nid = NULL, *ufb = malloc((size_t)nf * sizeof(int32_t));
    f->parent = malloc((size_t)nf * sizeof(int32_t));
    c->own_ijk = malloc((size_t)nf * 3 * sizeof(int32_t));
    c->ch_start = malloc(((size_t)nf + 1) * sizeof(int32_t));
    c->ch = malloc((size_t)nf * sizeof(int32_t));
    if (!ks || !ufb || !f->parent || !c->own_ijk || !c->ch_start || !c->ch)
        goto out;
    for (int i = 0; i < nf; i++) {
        const int32_t *ijk = f->cell_ijk + 3 * i;
        ks[i].key = pack(floordiv2(ijk[0]), floordiv2(ijk[1]), floordiv2(ijk[2]));
        ks[i].idx = i;
    }
    qsort(ks, (size_t)nf, sizeof *ks, cmp_keyed);
    /* Coarse cells: one per connected group of the children of a lattice block. */
    int nc = 0, nch = 0;
    for (int g0 = 0; g0 < nf;) {
        int g1 = g0;
        while (g1 < nf && ks[g1].key == ks[g0].key)
            g1++;
        const int m = g1 - g0; /* 8 at most, more where split cells share an index */
        int32_t *uf = ufb + g0;
        for (int a = 0; a < m; a++)
            uf[a] = a;
        for (int a = 0; a < m; a++)
            for (int b = a + 1; b < m; b++) {
                const int32_t *na = f->cell_nodes + 8 * ks[g0 + a].idx;
                const int32_t *nb = f->cell_nodes + 8 * ks[g0 + b].idx;
                bool share = false;
                for (int x = 0; x < 8 && !share; x++)
                    for (int y = 0; y < 8 && !share; y++)
                        share = na[x] == nb[y];
                if (share)
                    uf_union(uf, a, b);
            }
        for (int a = 0; a < m; a++) {
            if (uf_find(uf, a) != a)
                continue;
            const int32_t *ijk = f->cell_ijk + 3 * ks[g0 + a].idx;
            for (int d = 0; d < 3; d++)
                c->own_ijk[3 * nc + d] = (int32_t)floordiv2(ijk[d]);
            c->ch_start[nc] = nch;
            for (int b = 0; b < m; b++)
                if (uf_find(uf, b) == a) {
                    c->ch[nch++] = ks[g0 + b].idx;
                    f->parent[ks[g0 + b].idx] = nc;
                }
            nc++;
        }
        g0 = g1;
    }
    c->ch_start[nc] = nch;
    c->n_cells = nc;
    c->cell_ijk = c->own_ijk;
    /* The coarse cells are numbered in key order (k fastest) and the fine ones are usually i
     * fastest: setup_coarse visits them by first child instead (a cell's children are
     * listed increasing), so that it reads the fine rotations forward. */
    c->walk = malloc((size_t)(nc ? nc : 1) * sizeof(int32_t));
    if (!c->walk)
        goto out;
    for (int fc = 0, w = 0; fc < nf; fc++)
        if (c->ch[c->ch_start[f->parent[fc]]] == fc)
            c->walk[w++] = f->parent[fc];
    /* Coarse corners: merge the slots a fine node joins at the same lattice point. */
    slot = malloc((size_t)nc * 8 * sizeof(int32_t));
    nid = malloc((size_t)nc * 8 * sizeof(int32_t));
    c->own_nodes = malloc((size_t)nc * 8 * sizeof(int32_t));
    if (!slot || !nid || !c->own_nodes)
        goto out;
    for (int i = 0; i < 8 * nc; i++)
        slot[i] = i;
    for (int n = 0; n < f->n_nodes; n++) {
        const int a0 = f->adj_start[n], a1 = f->adj_start[n + 1];
        if (a1 - a0 < 2)
            continue;
        const int fc0 = f->adj[a0] / 8, k0 = f->adj[a0] % 8, C0 = f->parent[fc0];
        int t0[3];
        half_units(f, c, fc0, k0, C0, t0);
        for (int a = a0 + 1; a < a1; a++) {
            const int fc = f->adj[a] / 8, C = f->parent[fc];
            if (C == C0)
                continue;
            for (int K = 0; K < 8; K++) {
                if (corner_weight(t0, K) == 0)
                    continue;
                int K2 = 0, ok = 1;
                for (int d = 0; d < 3; d++) {
                    const int off = c->cell_ijk[3 * C0 + d] + CS_CORNER[K][d] -
                                    c->cell_ijk[3 * C + d];
                    if (off < 0 || off > 1)
                        ok = 0;
                    else
                        K2 |= off << d;
                }
                if (!ok)
                    continue;
                /* corner index from the offset bits (x, y, z) */
                static const int BITS_TO_CORNER[8] = {0, 1, 3, 2, 4, 5, 7, 6};
                uf_union(slot, 8 * C0 + K, 8 * C + BITS_TO_CORNER[K2]);
            }
        }
    }
    int nn = 0;
    for (int i = 0; i < 8 * nc; i++)
        nid[i] = -1;
    for (int i = 0; i < 8 * nc; i++) {
        const int r = uf_find(slot, i);
        if (nid[r] < 0)
            nid[r] = nn++;
        c->own_nodes[i] = nid[r];
    }
    c->n_nodes = nn;
    c->cell_nodes = c->own_nodes;
    if (build_adj(c))
        goto out;
    /* Prolongation rows and their transpose. */
    f->p_start = malloc(((size_t)f->n_nodes + 1) * sizeof(int32_t));
    f->p_node = malloc((size_t)f->n_nodes * 8 * sizeof(int32_t));
    f->p_w = malloc((size_t)f->n_nodes * 8 * sizeof(double));
    f->r_start = calloc((size_t)nn + 1, sizeof(int32_t));
    if (!f->p_start || !f->p_node || !f->p_w || !f->r_start)
        goto out;
    int np = 0;
    for (int n = 0; n < f->n_nodes; n++) {
        f->p_start[n] = np;
        if (f->adj_start[n] == f->adj_start[n + 1])
            continue; /* an unused node */
        const int e = f->adj[f->adj_start[n]], fc = e / 8, C = f->parent[fc];
        int t[3];
        half_units(f, c, fc, e % 8, C, t);
        for (int K = 0; K < 8; K++) {
            const double w = corner_weight(t, K);
            if (w == 0)
                continue;
            f->p_node[np] = c->cell_nodes[8 * C + K];
            f->p_w[np++] = w;
            f->r_start[c->cell_nodes[8 * C + K] + 1]++;
        }
    }
    f->p_start[f->n_nodes] = np;
    for (int J = 0; J < nn; J++)
        f->r_start[J + 1] += f->r_start[J];
    f->r_node = malloc((size_t)(np > 0 ? np : 1) * sizeof(int32_t));
    f->r_w = malloc((size_t)(np > 0 ? np : 1) * sizeof(double));
    int32_t *fill = malloc(((size_t)nn + 1) * sizeof(int32_t));
    if (!f->r_node || !f->r_w || !fill) {
        free(fill);
        goto out;
    }
    memcpy(fill, f->r_start, (size_t)nn * sizeof(int32_t));
    for (int n = 0; n < f->n_nodes; n++)
        for (int a = f->p_start[n]; a < f->p_start[n + 1]; a++) {
            const int J = f->p_node[a];
            f->r_node[fill[J]] = n;
            f->r_w[fill[J]++] = f->p_w[a];
        }
    free(fill);
    /* setup_coarse's node pass visits the coarse nodes by their first fine node (their
     * r lists are increasing), as walk does the cells */
    c->nwalk = malloc((size_t)(nn ? nn : 1) * sizeof(int32_t));
    if (!c->nwalk)
        goto out;
    int nw = 0;
    for (int n = 0; n < f->n_nodes; n++)
        for (int a = f->p_start[n]; a < f->p_start[n + 1]; a++)
            if (f->r_node[f->r_start[f->p_node[a]]] == n)
                c->nwalk[nw++] = f->p_node[a];
    if (nw != nn) /* a node without fine nodes (none on cube lattices): in index order */
        for (int J = 0; J < nn; J++)
            c->nwalk[J] = J;
    rc = 0;
out:
    free(ks);
    free(ufb);
    free(slot);
    free(nid);
    return rc;
}

/* The segments of batches of a level: segment s is [seg_start(l, s), seg_start(l, s + 1)). */
static int seg_start(const mg_level *l, int s)
{
    return (int)((int64_t)l->n_batches * s / l->nseg);
}

/*
 * Where the element pass stores each batch (bslot) and where the node pass reads each link
 * (fadj). The node pass of a chunk reads back batches up to `span` batches old (span: the
 * largest distance between a node's first and last batch; about one layer of cells on a
 * box), so each segment keeps its first `span` batches (its nodes shared with the previous
 * segment read them after the barrier) and then cycles through a ring of span + MG_CHUNK
 * batches: on a box only about two layers of cells' results are ever live, and they stay
 * in L2 instead of being written to memory and read back from it (10.6 MB per product on
 * 48³). A segment shorter than that is stored whole. The layout depends on l->threads only,
 * and the values on nothing of it. Returns -1 on out of memory.
 */
static int product_layout(mg_level *l)
{
    l->nseg = l->threads;
    int span = 0;
    for (int n = 0; n < l->n_nodes; n++) {
        int lo = INT32_MAX, hi = -1;
        for (int a = l->adj_start[n]; a < l->adj_start[n + 1]; a++) {
            const int b = l->adj[a] / 8 / MG_LANES;
            lo = b < lo ? b : lo;
            hi = b > hi ? b : hi;
        }
        if (hi >= 0 && hi - lo > span)
            span = hi - lo;
    }
    l->span = span;
    const int64_t head = span, ring = (int64_t)span + MG_CHUNK;
    int64_t total = 0;
    for (int s = 0; s < l->nseg; s++) {
        const int b0 = seg_start(l, s), b1 = seg_start(l, s + 1);
        for (int b = b0; b < b1; b++) {
            const int64_t o = b - b0;
            l->bslot[b] = (int32_t)(total + (o < head ? o : head + (o - head) % ring));
        }
        total += b1 - b0 < head + ring ? b1 - b0 : head + ring;
    }
    l->fe = aligned_alloc(64, (size_t)(total ? total : 1) * 32 * MG_LANES * sizeof(float));
    free(l->rowb);
    free(l->nstart);
    l->rowb = malloc(((size_t)l->n_batches * 4 + 1) * sizeof(int32_t));
    l->nstart = malloc(((size_t)l->n_nodes + 1) * sizeof(int32_t));
    if (!l->fe || !l->rowb || !l->nstart)
        return -1;
    _Static_assert(MG_LANES == 16, "a row batch's layout: 17 nodes' 3 floats within 64");
    /* row batches only on the CPUs whose default is the 512-bit kernel (fem.c, product_layout) */
    l->n_row_batches =
        cs_row_batches(l->cell_nodes, l->n_cells, MG_LANES, cs_simd_wide_default(), l->rowb);
    int32_t m = 0;
    for (int n = 0; n < l->n_nodes; n++) {
        l->nstart[n] = m;
        for (int a = l->adj_start[n]; a < l->adj_start[n + 1]; a++) {
            const int c = l->adj[a] / 8, k = l->adj[a] % 8, b = c / MG_LANES, p = c % MG_LANES;
            if (l->rowb[4 * b] < 0) {
                l->fadj[m++] = 32 * (MG_LANES * l->bslot[b] + p) + 4 * k;
                continue;
            }
            /* in a row batch: corner k in node row CS_ROW_OF[k] (rowbatch.h) */
            const int off = cs_row_link(k, p, MG_LANES);
            if (off >= 0)
                l->fadj[m++] = 32 * MG_LANES * l->bslot[b] + 64 * CS_ROW_OF[k] + off;
        }
    }
    l->nstart[l->n_nodes] = m;
    return 0;
}

/*
 * The element pass's corner indices as 16-bit offsets from a base per batch (bbase, bidx16;
 * bidx freed), if every batch's fit: 16 bytes a cell less to stream (of 76: indices 32,
 * rotations 36, λ and μ 8), the same gathers. Otherwise bidx stays. Only where the pass
 * gathers with AVX-512 (batches_avx512: a scalar load per corner either way); the portable
 * pass's loads from 32-bit indices vectorise into AVX2 gathers, from 16-bit ones they did not
 * (valgrind: 1.6× its instructions). -1 on out of memory.
 */
static int narrow_corners(mg_level *l)
{
    if (!__builtin_cpu_supports("x86-64-v4"))
        return 0;
    const size_t per = 8 * MG_LANES;
    for (int b = 0; b < l->n_batches; b++) {
        int32_t lo = INT32_MAX, hi = INT32_MIN;
        for (size_t i = 0; i < per; i++) {
            const int32_t v = l->bidx[per * b + i];
            lo = v < lo ? v : lo;
            hi = v > hi ? v : hi;
        }
        if ((int64_t)hi - lo > UINT16_MAX)
            return 0;
    }
    const size_t nb = l->n_batches ? (size_t)l->n_batches : 1;
    l->bbase = malloc(nb * sizeof(int32_t));
    l->bidx16 = aligned_alloc(64, nb * per * sizeof(uint16_t));
    if (!l->bbase || !l->bidx16)
        return -1;
    for (int b = 0; b < l->n_batches; b++) {
        int32_t lo = INT32_MAX;
        for (size_t i = 0; i < per; i++)
            lo = l->bidx[per * b + i] < lo ? l->bidx[per * b + i] : lo;
        l->bbase[b] = lo;
        for (size_t i = 0; i < per; i++)
            l->bidx16[per * b + i] = (uint16_t)(l->bidx[per * b + i] - lo);
    }
    free(l->bidx);
    l->bidx = NULL;
    return 0;
}

/* corner_weight with CS_CORNER's offsets as compile-time constants (position_row folds them;
 * transfer_layout checks every row made from them against coarsen's) */
static inline __attribute__((always_inline)) double position_weight(const int t[3], int K)
{
    static const int CORNER[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                     {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    double w = 1;
    for (int a = 0; a < 3; a++)
        w *= CORNER[K][a] ? t[a] * 0.5 : 1.0 - t[a] * 0.5;
    return w;
}

/* The trilinear rows by position in the coarse cell (cs_mg pos_*): as coarsen makes them. */
static void position_rows(cs_mg *mg)
{
    for (int p = 0; p < 27; p++) {
        const int t[3] = {p % 3, p / 3 % 3, p / 9};
        int m = 0;
        for (int K = 0; K < 8; K++) {
            const double w = position_weight(t, K);
            if (w == 0)
                continue;
            mg->pos_k[p][m] = (uint8_t)K;
            mg->pos_w[p][m++] = (float)w;
        }
        mg->pos_n[p] = (uint8_t)m;
    }
}

/*
 * The V-cycle's copies of level f's transfer rows: (node, float weight) pairs (the weights
 * are the float the loops converted them to); the restriction's packed into 4 bytes (r_pk)
 * if every weight is 2^−e, e ≤ 3; and the prolongation by coarse cells (pc_start, pc_ent,
 * p_lone), used if every fine row is its position's row of its coarse cell's corners, weight
 * for weight: it streams 4 bytes per fine node instead of 8 per weight (3.4 per node on a
 * box) and reads each coarse cell's corners once. Either way the same sums in the same order;
 * where a check fails (or memory is short), the pairs stay (r_tw, p_tw). -1 on out of memory.
 */
static int transfer_layout(cs_mg *mg, int level)
{
    mg_level *f = &mg->lv[level];
    if (!f->p_start)
        return 0;
    const mg_level *c = &mg->lv[level + 1];
    const int np = f->p_start[f->n_nodes];
    f->p_tw = malloc((size_t)(np > 0 ? np : 1) * sizeof(mg_tw));
    f->r_tw = malloc((size_t)(np > 0 ? np : 1) * sizeof(mg_tw));
    if (!f->p_tw || !f->r_tw)
        return -1;
    for (int a = 0; a < np; a++) {
        f->p_tw[a] = (mg_tw){f->p_node[a], (float)f->p_w[a]};
        f->r_tw[a] = (mg_tw){f->r_node[a], (float)f->r_w[a]};
    }
    if (f->n_nodes >= 1 << 27)
        return 0;
    f->r_pk = malloc((size_t)(np > 0 ? np : 1) * sizeof(uint32_t));
    bool pk = f->r_pk != NULL;
    for (int a = 0; pk && a < np; a++) {
        int e = 0;
        while (e < 3 && f->r_tw[a].w != 1.0f / (float)(1 << e))
            e++;
        pk = f->r_tw[a].w == 1.0f / (float)(1 << e);
        f->r_pk[a] = (uint32_t)f->r_tw[a].node | (uint32_t)e << 27;
    }
    if (pk) {
        free(f->r_tw);
        f->r_tw = NULL;
    } else {
        free(f->r_pk);
        f->r_pk = NULL;
    }
    f->pc_start = calloc((size_t)c->n_cells + 1, sizeof(int32_t));
    f->pc_ent = malloc((size_t)(f->n_nodes ? f->n_nodes : 1) * sizeof(uint32_t));
    f->p_lone = malloc((size_t)(f->n_nodes ? f->n_nodes : 1) * sizeof(int32_t));
    int32_t *owner = malloc((size_t)(f->n_nodes ? f->n_nodes : 1) * sizeof(int32_t));
    uint8_t *pos = malloc((size_t)(f->n_nodes ? f->n_nodes : 1));
    bool ok = f->pc_start && f->pc_ent && f->p_lone && owner && pos;
    f->n_lone = 0;
    for (int n = 0; ok && n < f->n_nodes; n++) {
        owner[n] = -1;
        if (f->adj_start[n] == f->adj_start[n + 1]) {
            f->p_lone[f->n_lone++] = n;
            ok = f->p_start[n] == f->p_start[n + 1];
            continue;
        }
        const int e = f->adj[f->adj_start[n]], fc = e / 8, C = f->parent[fc];
        int t[3];
        half_units(f, c, fc, e % 8, C, t);
        const int p = t[0] + 3 * t[1] + 9 * t[2];
        /* the row as the position tables give it, or no fast path */
        ok = f->p_start[n + 1] - f->p_start[n] == mg->pos_n[p];
        for (int j = 0; ok && j < mg->pos_n[p]; j++)
            ok = f->p_tw[f->p_start[n] + j].node == c->cell_nodes[8 * C + mg->pos_k[p][j]] &&
                 f->p_tw[f->p_start[n] + j].w == mg->pos_w[p][j];
        owner[n] = C;
        pos[n] = (uint8_t)p;
        f->pc_start[C + 1]++;
    }
    if (ok) {
        for (int C = 0; C < c->n_cells; C++)
            f->pc_start[C + 1] += f->pc_start[C];
        int32_t *fill = malloc(((size_t)c->n_cells + 1) * sizeof(int32_t));
        ok = fill != NULL;
        if (ok) {
            memcpy(fill, f->pc_start, ((size_t)c->n_cells + 1) * sizeof(int32_t));
            for (int n = 0; n < f->n_nodes; n++)
                if (owner[n] >= 0)
                    f->pc_ent[fill[owner[n]]++] = (uint32_t)n | (uint32_t)pos[n] << 27;
        }
        free(fill);
    }
    free(owner);
    free(pos);
    if (ok) { /* the rows by position replace p_tw */
        free(f->p_tw);
        f->p_tw = NULL;
    } else { /* out of memory or another row: p_tw */
        free(f->pc_start);
        free(f->pc_ent);
        free(f->p_lone);
        f->pc_start = f->p_lone = NULL;
        f->pc_ent = NULL;
        f->n_lone = 0;
    }
    return 0;
}

/* The optimised fourth-kind polynomials' weights β (Lottes, "Optimal polynomial smoothers for
 * multigrid V-cycles", 2023, arXiv:2202.08830, Table 5), degrees 1–4. */
static const double opt4_beta[CS_MG_CHEB_MAX][CS_MG_CHEB_MAX] = {
    {1.12500000000000},
    {1.02387287570313, 1.26408905371085},
    {1.00842544782028, 1.08867839208730, 1.33753125909618},
    {1.00391310427285, 1.04035811188593, 1.14863498546254, 1.38268869241000},
};

void cs_mg_smoother_poly(int deg, double *e)
{
    /* the paper's recurrence on polynomials in λ (λ(D⁻¹A) over its estimate ρ = 1): z_1 =
     * 4/3 r_0, y_i = y_{i−1} + z_i, r_i = λ (1 − y_i), z_{i+1} = (2i−1)/(2i+3) z_i +
     * (8i+4)/(2i+3) r_i; the correction Σ β_i z_i, the error 1 − that (r_0 = λ) */
    double z[CS_MG_CHEB_MAX + 1] = {0}, y[CS_MG_CHEB_MAX + 1] = {0}, out[CS_MG_CHEB_MAX + 1] = {0};
    z[1] = 4.0 / 3.0;
    for (int i = 1; i <= deg; i++) {
        for (int j = 0; j <= deg; j++) {
            y[j] += z[j];
            out[j] += opt4_beta[deg - 1][i - 1] * z[j];
        }
        if (i == deg)
            break;
        const double a = (2.0 * i - 1) / (2.0 * i + 3), c = (8.0 * i + 4) / (2.0 * i + 3);
        for (int j = deg; j >= 1; j--) /* r_i = λ (1 − y_i) */
            z[j] = a * z[j] + c * ((j == 1 ? 1.0 : 0.0) - y[j - 1]);
        z[0] = a * z[0];
    }
    for (int j = 0; j <= deg; j++)
        e[j] = (j == 0 ? 1.0 : 0.0) - out[j];
}

static double poly_at(const double *e, int deg, double t)
{
    double v = 0;
    for (int j = deg; j >= 0; j--)
        v = v * t + e[j];
    return v;
}

int cs_mg_smoother_steps(int deg, double *c)
{
    if (deg < 1 || deg > CS_MG_CHEB_MAX)
        return -1;
    double e[CS_MG_CHEB_MAX + 1];
    cs_mg_smoother_poly(deg, e);
    /* its roots are real, simple and in (0, 1): bracket them on a grid, then bisect; the step
     * weights are their reciprocals, the mildest first */
    int found = 0;
    const int N = 4096;
    double t0 = 0, v0 = poly_at(e, deg, 0);
    for (int g = 1; g <= N && found < deg; g++) {
        const double t1 = (double)g / N, v1 = poly_at(e, deg, t1);
        if ((v0 > 0) != (v1 > 0)) {
            double lo = t0, hi = t1;
            for (int it = 0; it < 60; it++) {
                const double mid = 0.5 * (lo + hi);
                if ((poly_at(e, deg, mid) > 0) == (v0 > 0))
                    lo = mid;
                else
                    hi = mid;
            }
            c[deg - 1 - found++] = 2.0 / (lo + hi);
        }
        t0 = t1;
        v0 = v1;
    }
    return found == deg ? 0 : -1;
}

/* cheb_deg: the level's smoother degree */
static int alloc_level_state(mg_level *l, int level, int threads, int cheb_deg)
{
    const size_t n3 = 3 * (size_t)l->n_nodes, nc = l->n_cells ? (size_t)l->n_cells : 1;
    l->threads = threads > 1 && l->n_cells >= MG_PARALLEL_CELLS ? threads : 1;
    l->cheb_deg = cheb_deg;
    if (MG_CHEB_KIND == 4 && l->cheb_deg > 0 &&
        cs_mg_smoother_steps(l->cheb_deg, l->cheb_c) != 0)
        return -1;
    l->s = malloc(nc * sizeof(double));
    l->dg = malloc((size_t)(l->n_nodes ? l->n_nodes : 1) * sizeof(double));
    l->dgf = malloc((size_t)(l->n_nodes ? l->n_nodes : 1) * sizeof(float));
    l->invf = malloc((n3 * 3 + 1) * sizeof(float));
    l->held = malloc((size_t)(l->n_nodes ? l->n_nodes : 1));
    const size_t nb = (nc + MG_LANES - 1) / MG_LANES, vb = MG_LANES * sizeof(float);
    l->n_batches = (l->n_cells + MG_LANES - 1) / MG_LANES;
    l->bidx = aligned_alloc(64, nb * 8 * vb);
    l->bR = aligned_alloc(64, nb * 9 * vb);
    l->bQ = aligned_alloc(64, nb * 4 * vb);
    l->bL = aligned_alloc(64, nb * vb);
    l->bM = aligned_alloc(64, nb * vb);
    l->bslot = malloc(nb * sizeof(int32_t));
    l->fadj = malloc(nc * 8 * sizeof(int32_t));
    l->norder = malloc((size_t)(l->n_nodes ? l->n_nodes : 1) * sizeof(int32_t));
    l->nminb = malloc((size_t)(l->n_nodes ? l->n_nodes : 1) * sizeof(int32_t));
    l->nfirst = calloc(nb + 2, sizeof(int32_t));
    l->x = malloc((n3 ? n3 : 1) * sizeof(float));
    l->b = malloc((n3 ? n3 : 1) * sizeof(float));
    l->t = malloc((n3 ? n3 : 1) * sizeof(float));
    l->d = malloc((n3 ? n3 : 1) * sizeof(float));
    if (!l->d || !l->s || !l->dg || !l->dgf || !l->invf || !l->held || !l->bslot || !l->x || !l->b || !l->t ||
        !l->bidx || !l->bR || !l->bQ || !l->bL || !l->bM || !l->fadj || !l->norder || !l->nminb ||
        !l->nfirst)
        return -1;
    /* counting sort of the nodes by the batch of their last cell (adj: cells increasing) */
    for (int n = 0; n < l->n_nodes; n++) {
        const int a0 = l->adj_start[n], a1 = l->adj_start[n + 1];
        l->nfirst[(a1 > a0 ? l->adj[a1 - 1] / 8 / MG_LANES : 0) + 1]++;
    }
    for (int b = 0; b <= l->n_batches; b++)
        l->nfirst[b + 1] += l->nfirst[b];
    {
        int32_t *fill = malloc(((size_t)l->n_batches + 1) * sizeof(int32_t));
        if (!fill)
            return -1;
        memcpy(fill, l->nfirst, ((size_t)l->n_batches + 1) * sizeof(int32_t));
        for (int n = 0; n < l->n_nodes; n++) {
            const int a0 = l->adj_start[n], a1 = l->adj_start[n + 1];
            const int q = fill[a1 > a0 ? l->adj[a1 - 1] / 8 / MG_LANES : 0]++;
            l->norder[q] = n;
            l->nminb[q] = a1 > a0 ? l->adj[a0] / 8 / MG_LANES : 0;
        }
        free(fill);
    }
    for (int b = 0; b < l->n_batches; b++)
        for (int p = 0; p < MG_LANES; p++) {
            const int c = b * MG_LANES + p < l->n_cells ? b * MG_LANES + p : b * MG_LANES;
            for (int k = 0; k < 8; k++)
                l->bidx[(8 * b + k) * MG_LANES + p] = 3 * l->cell_nodes[8 * c + k];
        }
    if (product_layout(l) != 0 || narrow_corners(l) != 0)
        return -1;
    if (level == 0)
        return 0;
    l->own_R = malloc((size_t)l->n_cells * 9 * sizeof(double));
    l->q = malloc((size_t)l->n_cells * 4 * sizeof(double));
    l->own_inv = malloc(n3 * 3 * sizeof(double));
    l->own_mask = malloc(n3);
    if (!l->own_R || !l->q || !l->own_inv || !l->own_mask)
        return -1;
    for (int c = 0; c < l->n_cells; c++) {
        static const double I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
        memcpy(l->own_R + 9 * c, I, sizeof I);
        l->q[4 * c] = 1;
        l->q[4 * c + 1] = l->q[4 * c + 2] = l->q[4 * c + 3] = 0;
    }
    l->R = l->own_R;
    l->rq = l->q;
    l->inv = l->own_inv;
    l->mask = l->own_mask;
    return 0;
}

static void free_level(mg_level *l)
{
    cs_mgl_free(l->lat);
    free(l->own_nodes);
    free(l->own_ijk);
    free(l->own_adj_start);
    free(l->own_adj);
    free(l->parent);
    free(l->p_start);
    free(l->p_node);
    free(l->p_w);
    free(l->r_start);
    free(l->r_node);
    free(l->r_w);
    free(l->p_tw);
    free(l->r_tw);
    free(l->r_pk);
    free(l->pc_start);
    free(l->pc_ent);
    free(l->p_lone);
    free(l->bbase);
    free(l->bidx16);
    free(l->ch_start);
    free(l->ch);
    free(l->walk);
    free(l->nwalk);
    free(l->own_R);
    free(l->q);
    free(l->s);
    free(l->dg);
    free(l->own_inv);
    free(l->own_mask);
    free(l->bidx);
    free(l->bR);
    free(l->bQ);
    free(l->bL);
    free(l->bM);
    free(l->fadj);
    free(l->rowb);
    free(l->nstart);
    free(l->norder);
    free(l->nminb);
    free(l->nfirst);
    free(l->dgf);
    free(l->invf);
    free(l->held);
    free(l->fe);
    free(l->bslot);
    free(l->x);
    free(l->b);
    free(l->t);
    free(l->d);
    free(l->gb);
    free(l->gx);
}

void cs_mg_free(cs_mg *mg)
{
    if (!mg)
        return;
    for (int l = 0; l < mg->n_levels; l++)
        free_level(&mg->lv[l]);
    free(mg->lv);
    free(mg->dense);
    free(mg->dense_x);
    free(mg->prev_s);
    free(mg->prev_dg);
    free(mg->prev_mask);
    free(mg);
}

cs_mg *cs_mg_build(const cs_cubemesh *cm, const cs_fem *fem, uint32_t version)
{
    cs_mg *mg = calloc(1, sizeof *mg);
    if (!mg)
        return NULL;
    const int max_levels = 16;
    mg->lv = calloc(max_levels, sizeof *mg->lv);
    if (!mg->lv)
        goto fail;
    mg->version = version;
    mg->fine_nodes = cm->n_nodes;
    mg->fine_cells = cm->n_cells;
    mg->fine_links = cm->cell_nodes;
    memcpy(mg->K, fem->K, sizeof mg->K);
    cs_cube_lame_h(fem->K, &mg->hl, &mg->hm);
    if (!corner_blocks_ok(mg->K))
        goto fail;
    mg->simd = !__builtin_cpu_supports("x86-64-v4") ? 0 : fem->wide ? SIMD_512 : SIMD_256;
    mg_level *l0 = &mg->lv[0];
    l0->n_cells = cm->n_cells;
    l0->n_nodes = cm->n_nodes;
    l0->cell_nodes = cm->cell_nodes;
    l0->cell_ijk = cm->cell_ijk;
    l0->adj_start = fem->adj_start;
    l0->adj = fem->adj;
    mg->n_levels = 1;
    /* ν = λ / (2 (λ + μ)) from the model's hλ, hμ (a field scales both alike); "≥" up to
     * the rounding of K */
    const double nu = mg->hl / (2.0 * (mg->hl + mg->hm));
    const int deg0 = MG_CHEB && nu >= MG_CHEB_NU - 1e-9 ? MG_CHEB_NEAR_INCOMPRESSIBLE : MG_CHEB;
    if (alloc_level_state(l0, 0, fem->threads, deg0))
        goto fail;
    while (mg->n_levels < max_levels && mg->lv[mg->n_levels - 1].n_nodes > CS_MG_COARSEST_NODES) {
        mg_level *f = &mg->lv[mg->n_levels - 1], *c = &mg->lv[mg->n_levels];
        if (coarsen(f, c)) {
            mg->n_levels++; /* so that it is freed */
            goto fail;
        }
        mg->n_levels++;
        if (alloc_level_state(c, mg->n_levels - 1, fem->threads, MG_CHEB_COARSE))
            goto fail;
        if (c->n_nodes > 0.8 * f->n_nodes) {
            /* coarsening stalls: drop that level, the finer one is the coarsest */
            free_level(c);
            memset(c, 0, sizeof *c);
            mg->n_levels--;
            free(f->parent);
            free(f->p_start);
            free(f->p_node);
            free(f->p_w);
            free(f->r_start);
            free(f->r_node);
            free(f->r_w);
            f->parent = f->p_start = f->p_node = f->r_start = f->r_node = NULL;
            f->p_w = f->r_w = NULL;
            break;
        }
    }
    position_rows(mg);
    for (int l = 0; l < mg->n_levels; l++)
        if (transfer_layout(mg, l) != 0)
            goto fail;
    mg->lattice = true;
    for (int l = 0; l < mg->n_levels; l++) {
        mg_level *v = &mg->lv[l];
        if (v->n_cells < MG_LATTICE_CELLS)
            continue;
        cs_cubemesh view = {0};
        view.n_cells = v->n_cells;
        view.n_nodes = v->n_nodes;
        view.cell_ijk = (int32_t *)v->cell_ijk;
        view.cell_nodes = (int32_t *)v->cell_nodes;
        if (cs_mgl_build(&view, &v->lat) != 0)
            goto fail;
    }
    for (int l = 0; l < mg->n_levels; l++) {
        mg_level *c = &mg->lv[l];
        c->cycles = l > 0 && l < mg->n_levels - 1 &&
                            c->n_nodes >= MG_W_NODES_PER_CELL * c->n_cells
                        ? 2
                        : 1;
        if (c->cycles > 1) {
            const size_t n3 = 3 * (size_t)c->n_nodes + 1;
            c->gb = malloc(n3 * sizeof(float));
            c->gx = malloc(n3 * sizeof(float));
            if (!c->gb || !c->gx)
                goto fail;
        }
    }
    mg_level *last = &mg->lv[mg->n_levels - 1];
    if (mg->n_levels > 1 && last->n_nodes <= CS_MG_DENSE_NODES) {
        mg->dense_n = 3 * last->n_nodes;
        mg->dense = malloc((size_t)mg->dense_n * mg->dense_n * sizeof(double));
        mg->dense_x = malloc((size_t)mg->dense_n * sizeof(double));
        if (!mg->dense || !mg->dense_x)
            goto fail;
    }
    return mg;
fail:
    cs_mg_free(mg);
    return NULL;
}

bool cs_mg_matches(const cs_mg *mg, const cs_cubemesh *cm, const cs_fem *fem, uint32_t version)
{
    return mg && mg->version == version && mg->fine_nodes == cm->n_nodes &&
           mg->fine_cells == cm->n_cells && mg->fine_links == cm->cell_nodes &&
           mg->lv[0].adj == fem->adj && mg->lv[0].adj_start == fem->adj_start;
}

double cs_mg_rotation_drift(const cs_mg *mg, const double *R, const double *q)
{
    const mg_level *l = &mg->lv[0];
    double dmax = 0;
    if (l->bQ_ok) {
        /* from the quaternions (16 + 32 bytes a cell instead of 36 + 72): for unit a and b,
         * tr(R(a)ᵀ R(b)) = 4 (a·b)² − 1, so 3 − tr = 4 (1 − (a·b)²) (the float q's rounding
         * moves it by about 1e-7, as bR's did) */
#pragma omp parallel for num_threads(l->threads) schedule(static) reduction(max : dmax)
        for (int c = 0; c < l->n_cells; c++) {
            const int b = c / MG_LANES, p = c % MG_LANES;
            double t = 0;
            for (int j = 0; j < 4; j++)
                t += (double)l->bQ[(4 * b + j) * MG_LANES + p] * q[4 * (size_t)c + j];
            const double d = 4.0 * (1.0 - t * t);
            dmax = isfinite(d) ? (d > dmax ? d : dmax) : INFINITY;
        }
        return dmax;
    }
#pragma omp parallel for num_threads(l->threads) schedule(static) reduction(max : dmax)
    for (int c = 0; c < l->n_cells; c++) {
        const int b = c / MG_LANES, p = c % MG_LANES;
        double t = 0;
        for (int k = 0; k < 9; k++)
            t += (double)l->bR[(9 * b + k) * MG_LANES + p] * R[9 * (size_t)c + k];
        const double d = 3.0 - t;
        dmax = isfinite(d) ? (d > dmax ? d : dmax) : INFINITY;
    }
    return dmax;
}

bool cs_mg_held_matches(const cs_mg *mg, const uint8_t *mask)
{
    /* every step of a lagged hierarchy: on the level's threads (the answer an or) */
    const mg_level *l = &mg->lv[0];
    int differ = 0;
#pragma omp parallel for num_threads(l->threads) schedule(static) reduction(| : differ)
    for (int n = 0; n < l->n_nodes; n++) {
        const uint8_t h = (uint8_t)((mask[3 * n] ? 1 : 0) | (mask[3 * n + 1] ? 2 : 0) |
                                    (mask[3 * n + 2] ? 4 : 0));
        differ |= h != l->held[n];
    }
    return !differ;
}

int cs_mg_levels(const cs_mg *mg)
{
    return mg->n_levels;
}

int cs_mg_level_nodes(const cs_mg *mg, int level)
{
    return level >= 0 && level < mg->n_levels ? mg->lv[level].n_nodes : 0;
}

int cs_mg_level_cycles(const cs_mg *mg, int level)
{
    return level >= 0 && level < mg->n_levels ? mg->lv[level].cycles : 0;
}

int cs_mg_level_degree(const cs_mg *mg, int level)
{
    return level >= 0 && level < mg->n_levels ? mg->lv[level].cheb_deg : 0;
}

double *cs_mg_cell_scale(cs_mg *mg)
{
    return mg->lv[0].s;
}

double *cs_mg_node_diag(cs_mg *mg)
{
    return mg->lv[0].dg;
}

/* ------------------------------------------------------------------ products */

/* The element pass of half h (lanes 8h..8h+7) of batch b: fe = s R K Rᵀ x per lane, by the
 * modal kernel (fem.c, modal_core.h) in single precision, 8 lanes in 256-bit vectors (512-bit
 * vectors of 16 lanes with gathers measured slower on Zen 4, which splits them in two; the whole
 * batch in one 512-bit vector, wide_body, on the cores that do not, simd.h). */
typedef int vi8 __attribute__((vector_size(32)));
static inline __attribute__((always_inline)) void half_rest(const mg_level *l, int b, int h,
                                                            const vf u[24], float *yt)
{
    vf R[9], y[24], L, M;
    const size_t o = (size_t)b * MG_LANES + VF_LANES * h;
    if (l->bQ_ok) {
        /* R(q) (mat3.h), in float */
        vf q[4];
        for (int j = 0; j < 4; j++)
            memcpy(&q[j], l->bQ + 4 * MG_LANES * (size_t)b + MG_LANES * j + VF_LANES * h,
                   sizeof(vf));
        const vf w = q[0], qx = q[1], qy = q[2], qz = q[3];
        CS_QUAT_TO_MAT(w, qx, qy, qz, R);
    } else {
        for (int j = 0; j < 9; j++)
            memcpy(&R[j], l->bR + 9 * MG_LANES * (size_t)b + MG_LANES * j + VF_LANES * h,
                   sizeof(vf));
    }
    memcpy(&L, l->bL + o, sizeof L);
    memcpy(&M, l->bM + o, sizeof M);
    modal_core_f(u, R, 0.0f, &L, &M, NULL, y);
    if (yt) { /* a row batch's: component i of corner k of lane p at yt[16 (3k + i) + p] */
        for (int i = 0; i < 24; i++)
            memcpy(yt + MG_LANES * i + VF_LANES * h, &y[i], sizeof y[i]);
        return;
    }
    /* lane p's corner k at out + 32 p + 4 k as (x, y, z, z): the components transposed across
     * lanes in registers (lanes j and j + 4 per 256-bit vector), whole 16-byte stores */
    float *out = l->fe + 32 * ((size_t)MG_LANES * l->bslot[b] + VF_LANES * h);
    for (int k = 0; k < 8; k++) {
        const vf X = y[3 * k], Y = y[3 * k + 1], Z = y[3 * k + 2];
        const vf t0 = __builtin_shuffle(X, Y, (vi8){0, 8, 1, 9, 4, 12, 5, 13});
        const vf t1 = __builtin_shuffle(X, Y, (vi8){2, 10, 3, 11, 6, 14, 7, 15});
        const vf t2 = __builtin_shuffle(Z, (vi8){0, 0, 1, 1, 4, 4, 5, 5});
        const vf t3 = __builtin_shuffle(Z, (vi8){2, 2, 3, 3, 6, 6, 7, 7});
        vf r[4];
        r[0] = __builtin_shuffle(t0, t2, (vi8){0, 1, 8, 9, 4, 5, 12, 13});
        r[1] = __builtin_shuffle(t0, t2, (vi8){2, 3, 10, 11, 6, 7, 14, 15});
        r[2] = __builtin_shuffle(t1, t3, (vi8){0, 1, 8, 9, 4, 5, 12, 13});
        r[3] = __builtin_shuffle(t1, t3, (vi8){2, 3, 10, 11, 6, 7, 14, 15});
        for (int j = 0; j < 4; j++) {
            memcpy(out + 32 * j + 4 * k, (const char *)&r[j], 4 * sizeof(float));
            memcpy(out + 32 * (j + 4) + 4 * k, (const char *)&r[j] + 4 * sizeof(float),
                   4 * sizeof(float));
        }
    }
}

/* A row batch's results (yt as half_rest leaves them) into its rows in fe: node p of row r
 * gets corner CS_ROW_K0[r] of lane p plus corner CS_ROW_K1[r] of lane p − 1 (0 for p = 0), the row's
 * end node corner CS_ROW_K1[r] of lane 15 (row_wide: the same sums). */
static inline __attribute__((always_inline)) void row_store(const mg_level *l, int b,
                                                            const float *yt)
{
    float *out = l->fe + 32 * ((size_t)MG_LANES * l->bslot[b]);
    for (int r = 0; r < 4; r++)
        for (int i = 0; i < 3; i++) {
            const float *y0 = yt + MG_LANES * (3 * CS_ROW_K0[r] + i);
            const float *y1 = yt + MG_LANES * (3 * CS_ROW_K1[r] + i);
            out[64 * r + i] = y0[0] + 0.0f;
            for (int p = 1; p < MG_LANES; p++)
                out[64 * r + 3 * p + i] = y0[p] + y1[p - 1];
            out[64 * r + 48 + i] = y1[MG_LANES - 1];
        }
}

/* Corner k of lane p of half h of batch b: its 3·node index, as an offset from x_b (x moved
 * to the batch's base with 16-bit offsets, bidx16; x itself with 32-bit indices, bidx). */
static inline __attribute__((always_inline)) const float *batch_x(const mg_level *l,
                                                                  const float *x, int b,
                                                                  const bool narrow)
{
    return narrow ? x + l->bbase[b] : x;
}

static inline __attribute__((always_inline)) int32_t corner_at(const mg_level *l, int b, int h,
                                                              int k, int p, const bool narrow)
{
    const size_t i = 8 * MG_LANES * (size_t)b + VF_LANES * h + MG_LANES * k + p;
    return narrow ? l->bidx16[i] : l->bidx[i];
}

/* Inputs lane by lane (narrow: the layout, compile-time once inlined). */
static inline __attribute__((always_inline)) void
generic_body(const mg_level *l, const float *restrict x, int b0, int b1, const bool narrow)
{
    for (int b = b0; b < b1; b++) {
        float yt[24 * MG_LANES];
        const bool row = l->rowb[4 * b] >= 0;
        for (int h = 0; h < MG_LANES / VF_LANES; h++) {
            const float *xb = batch_x(l, x, b, narrow);
            vf u[24];
            for (int k = 0; k < 8; k++)
                for (int i = 0; i < 3; i++)
                    for (int p = 0; p < VF_LANES; p++)
                        u[3 * k + i][p] = xb[corner_at(l, b, h, k, p, narrow) + i];
            half_rest(l, b, h, u, row ? yt : NULL);
        }
        if (row)
            row_store(l, b, yt);
    }
}

__attribute__((optimize("fp-contract=fast"), target_clones("arch=x86-64-v3", "default")))
static void batches_generic(const mg_level *l, const float *restrict x, int b0, int b1)
{
    if (l->bidx16)
        generic_body(l, x, b0, b1, true);
    else
        generic_body(l, x, b0, b1, false);
}

/* Inputs with AVX-512VL: each corner's nodal 3-vectors by masked loads, transposed into x, y, z
 * across the lanes in registers (the same values as batches_generic). */
static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
avx512_body(const mg_level *l, const float *restrict x, int b0, int b1, const bool narrow)
{
    _Static_assert(VF_LANES == 8, "two 4-lane groups per 256-bit vector");
    for (int b = b0; b < b1; b++) {
        float yt[24 * MG_LANES];
        const bool row = l->rowb[4 * b] >= 0;
        for (int h = 0; h < MG_LANES / VF_LANES; h++) {
            const float *xb = batch_x(l, x, b, narrow);
            vf u[24];
            for (int k = 0; k < 8; k++) {
                __m256 r[4]; /* (x, y, z, 0) of lanes j | j + 4 */
                for (int j = 0; j < 4; j++)
                    r[j] = _mm256_insertf128_ps(
                        _mm256_castps128_ps256(
                            _mm_maskz_loadu_ps(7, xb + corner_at(l, b, h, k, j, narrow))),
                        _mm_maskz_loadu_ps(7, xb + corner_at(l, b, h, k, j + 4, narrow)), 1);
                const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]); /* x0 x1 y0 y1 | 4 5 */
                const __m256 t1 = _mm256_unpackhi_ps(r[0], r[1]); /* z0 z1 0 0 | 4 5 */
                const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]);
                const __m256 t3 = _mm256_unpackhi_ps(r[2], r[3]);
                u[3 * k] = (vf)_mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
                u[3 * k + 1] = (vf)_mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
                u[3 * k + 2] = (vf)_mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
            }
            half_rest(l, b, h, u, row ? yt : NULL);
        }
        if (row)
            row_store(l, b, yt);
    }
}

__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4")))
static void batches_avx512(const mg_level *l, const float *restrict x, int b0, int b1)
{
    if (l->bidx16)
        avx512_body(l, x, b0, b1, true);
    else
        avx512_body(l, x, b0, b1, false);
}

/* The whole batch of 16 lanes in one 512-bit vector (cs_mg.simd SIMD_512: CPUs that execute
 * 512-bit vectors at full width, simd.h): the same arithmetic per lane as half_rest, so the
 * same bits. A corner's inputs by four masked loads per group of four lanes (each shifted so
 * that its 3 floats land in its 128-bit quarter), then avx512_body's unpacks and shuffles
 * within the quarters; the results stored a quarter (a lane's corner) at a time. On the 2-core
 * Intel Xeon of session 47 a 64³ V-cycle's finest product went from 5.0 to 4.9 ms (one
 * thread): the float pass waits on its loads and stores more than on its arithmetic. Row
 * batches (session 48, product_layout: row_inputs, row_outputs, row_store) read whole node rows
 * and halve the node pass's loads where a block's rows allow: that product 1.28× (32³) and
 * 1.33× (64³) faster on that host (a prototype, in process), cs_mg_vcycle 64³ on two threads
 * 20.7 → 17.4 ms (the landed code against the one before, interleaved). */
typedef float vf16 __attribute__((vector_size(64)));
typedef int vi16 __attribute__((vector_size(64)));
#define MODAL_NAME modal_core_f16
#define MODAL_V vf16
#define MODAL_S float
#include "modal_core.h"

/* A row batch's inputs (row_store's layout): each node row's 16 nodes by three whole loads
 * deinterleaved into x, y, z (two two-source permutes each), its dx = 1 corners the same shifted
 * by one lane with the row's end node; the same values as the gathers. */
static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
row_inputs(const float *restrict x, const int32_t *rowb, vf16 u[24])
{
    for (int r = 0; r < 4; r++) {
        const float *p = x + rowb[r];
        __m512 v[3];
        cs_xyz16_split(_mm512_loadu_ps(p), _mm512_loadu_ps(p + 16), _mm512_loadu_ps(p + 32), v);
        for (int i = 0; i < 3; i++) {
            /* the end node's component i in lane 0 */
            const __m512i e = _mm512_castps_si512(_mm512_maskz_loadu_ps(1, p + 48 + i));
            u[3 * CS_ROW_K0[r] + i] = (vf16)v[i];
            u[3 * CS_ROW_K1[r] + i] =
                (vf16)_mm512_castsi512_ps(_mm512_alignr_epi32(e, _mm512_castps_si512(v[i]), 1));
        }
    }
}

/* A row batch's results into fe (row_store's sums): per node row, the dx = 1 corner shifted a
 * lane up and added to the dx = 0 one, interleaved into 48 floats by two permutes per vector;
 * the last lane's dx = 1 corner as the row's end node. */
static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
row_outputs(const vf16 y[24], float *out)
{
    const __m512i e0 = _mm512_setr_epi32(15, 31, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0);
    const __m512i e1 = _mm512_setr_epi32(0, 1, 31, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0);
    const __m512i zero = _mm512_setzero_si512();
    for (int r = 0; r < 4; r++) {
        __m512 S[3], o3[3];
        for (int i = 0; i < 3; i++) {
            const __m512i y1 = _mm512_castps_si512((__m512)y[3 * CS_ROW_K1[r] + i]);
            S[i] = _mm512_add_ps((__m512)y[3 * CS_ROW_K0[r] + i],
                                 _mm512_castsi512_ps(_mm512_alignr_epi32(y1, zero, 15)));
        }
        float *o = out + 64 * r;
        cs_xyz16_join(S, o3);
        for (int v = 0; v < 3; v++)
            _mm512_storeu_ps(o + 16 * v, o3[v]);
        const __m512 end = _mm512_permutex2var_ps(
            _mm512_permutex2var_ps((__m512)y[3 * CS_ROW_K1[r]], e0, (__m512)y[3 * CS_ROW_K1[r] + 1]), e1,
            (__m512)y[3 * CS_ROW_K1[r] + 2]);
        _mm512_mask_storeu_ps(o + 48, 0x7, end);
    }
}

static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
wide_body(const mg_level *l, const float *restrict x, int b0, int b1, const bool narrow)
{
    _Static_assert(MG_LANES == 16, "one 512-bit vector per batch");
    for (int b = b0; b < b1; b++) {
        const float *xb = batch_x(l, x, b, narrow);
        vf16 u[24];
        const bool row = l->rowb[4 * b] >= 0;
        if (row)
            row_inputs(x, l->rowb + 4 * b, u);
        else
        for (int k = 0; k < 8; k++) {
            __m512 r[4]; /* (x, y, z, 0) of lanes j | j + 4 | j + 8 | j + 12 */
            for (int j = 0; j < 4; j++) { /* quarter g from 4g floats before its node: the
                                           * masked-out lanes are never read */
                __m512 v = _mm512_maskz_loadu_ps(0x0007, xb + corner_at(l, b, 0, k, j, narrow));
                for (int g = 1; g < 4; g++)
                    v = _mm512_mask_loadu_ps(
                        v, (__mmask16)(0x7 << 4 * g),
                        (const void *)((uintptr_t)(xb + corner_at(l, b, 0, k, j + 4 * g, narrow)) -
                                       4 * g * sizeof(float)));
                r[j] = v;
            }
            const __m512 t0 = _mm512_unpacklo_ps(r[0], r[1]);
            const __m512 t1 = _mm512_unpackhi_ps(r[0], r[1]);
            const __m512 t2 = _mm512_unpacklo_ps(r[2], r[3]);
            const __m512 t3 = _mm512_unpackhi_ps(r[2], r[3]);
            u[3 * k] = (vf16)_mm512_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
            u[3 * k + 1] = (vf16)_mm512_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
            u[3 * k + 2] = (vf16)_mm512_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
        }
        vf16 R[9], y[24], L, M;
        const size_t o = (size_t)b * MG_LANES;
        if (l->bQ_ok) {
            vf16 q[4];
            for (int j = 0; j < 4; j++)
                memcpy(&q[j], l->bQ + 4 * MG_LANES * (size_t)b + MG_LANES * j, sizeof(vf16));
            const vf16 w = q[0], qx = q[1], qy = q[2], qz = q[3];
            CS_QUAT_TO_MAT(w, qx, qy, qz, R);
        } else {
            for (int j = 0; j < 9; j++)
                memcpy(&R[j], l->bR + 9 * MG_LANES * (size_t)b + MG_LANES * j, sizeof(vf16));
        }
        memcpy(&L, l->bL + o, sizeof L);
        memcpy(&M, l->bM + o, sizeof M);
        modal_core_f16(u, R, 0.0f, &L, &M, NULL, y);
        float *out = l->fe + 32 * ((size_t)MG_LANES * l->bslot[b]);
        if (row) {
            row_outputs(y, out);
            continue;
        }
        for (int k = 0; k < 8; k++) {
            const __m512 X = (__m512)y[3 * k], Y = (__m512)y[3 * k + 1], Z = (__m512)y[3 * k + 2];
            const __m512 t0 = _mm512_unpacklo_ps(X, Y), t1 = _mm512_unpackhi_ps(X, Y);
            const __m512 t2 = _mm512_unpacklo_ps(Z, Z), t3 = _mm512_unpackhi_ps(Z, Z);
            __m512 r[4];
            r[0] = _mm512_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
            r[1] = _mm512_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
            r[2] = _mm512_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
            r[3] = _mm512_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2));
            for (int j = 0; j < 4; j++) {
                _mm_storeu_ps(out + 32 * j + 4 * k, _mm512_castps512_ps128(r[j]));
                _mm_storeu_ps(out + 32 * (j + 4) + 4 * k, _mm512_extractf32x4_ps(r[j], 1));
                _mm_storeu_ps(out + 32 * (j + 8) + 4 * k, _mm512_extractf32x4_ps(r[j], 2));
                _mm_storeu_ps(out + 32 * (j + 12) + 4 * k, _mm512_extractf32x4_ps(r[j], 3));
            }
        }
    }
}

__attribute__((optimize("fp-contract=fast"), target("arch=x86-64-v4")))
static void batches_wide(const mg_level *l, const float *restrict x, int b0, int b1)
{
    if (l->bidx16)
        wide_body(l, x, b0, b1, true);
    else
        wide_body(l, x, b0, b1, false);
}

/* A Chebyshev step fused into a residual's node pass: d = a d + c D⁻¹ r (d = c D⁻¹ r if
 * first; d NULL: first, and d is not stored), x += d at free dofs, 0 at held ones
 * (cheb_update's arithmetic, node by node); with
 * out, the new x also converted to double into out (the V-cycle's last step: its result). */
typedef struct cheb_step {
    float *d, *x;
    float a, c;
    bool first;
    double *out;
} cheb_step;

/* The node pass's variants, compile-time in node_out: y = A x; y = b − A x (0 at held dofs);
 * that residual's Chebyshev step, the first (d = c D⁻¹ r) or a later one; and those two
 * writing x in double as well (cheb_step.out). */
enum { NP_APPLY, NP_RESID, NP_CHEB_FIRST, NP_CHEB, NP_CHEB_FIRST_OUT, NP_CHEB_OUT };

/* A node's 3-vector as (x, y, z, 0) and back: 8 + 4 bytes, never past the node's own dofs (the
 * vectors are 3 per node, and other threads write their neighbours' dofs). */
typedef float vf4 __attribute__((vector_size(16)));
typedef int32_t vi4 __attribute__((vector_size(16)));
static inline vf4 load3(const float *p)
{
    return (vf4)_mm_movelh_ps(_mm_loadl_pi(_mm_setzero_ps(), (const __m64 *)p),
                              _mm_load_ss(p + 2));
}

static inline void store3(float *p, vf4 v)
{
    _mm_storel_pi((__m64 *)p, (__m128)v);
    _mm_store_ss(p + 2, _mm_movehl_ps((__m128)v, (__m128)v));
}

/* The free dofs of node n (all bits set; lane 3 clear). */
static inline vf4 free_mask(const mg_level *l, int n)
{
    static const vi4 FREE[8] = {{-1, -1, -1, 0}, {0, -1, -1, 0}, {-1, 0, -1, 0}, {0, 0, -1, 0},
                                {-1, -1, 0, 0},  {0, -1, 0, 0},  {-1, 0, 0, 0},  {0, 0, 0, 0}};
    return (vf4)FREE[l->held[n] & 7];
}

/* D⁻¹ v at node n by its columns (16-byte loads: lane 3 is the next column's first entry, or
 * the tail), per component in the order of a row-major product: (m_k0 v0 + m_k1 v1) + m_k2 v2. */
static inline vf4 dinv(const mg_level *l, int n, vf4 v)
{
    const float *m = l->invf + 9 * (size_t)n;
    vf4 c0, c1, c2;
    memcpy(&c0, m, sizeof c0);
    memcpy(&c1, m + 3, sizeof c1);
    memcpy(&c2, m + 6, sizeof c2);
    const vf4 v0 = __builtin_shuffle(v, (vi4){0, 0, 0, 0});
    const vf4 v1 = __builtin_shuffle(v, (vi4){1, 1, 1, 1});
    const vf4 v2 = __builtin_shuffle(v, (vi4){2, 2, 2, 2});
    return c0 * v0 + c1 * v1 + c2 * v2;
}

static inline vf4 and4(vf4 v, vf4 m)
{
    return (vf4)((vi4)v & (vi4)m);
}

/* nl (a constant once inlined) links' (x, y, z, ·) loaded at once and summed in order */
static inline __attribute__((always_inline)) vf4 sum_links(const float *fe, const int32_t *fadj,
                                                          const int nl)
{
    vf4 v[8], s = {0, 0, 0, 0};
    for (int a = 0; a < nl; a++)
        memcpy(&v[a], fe + fadj[a], sizeof v[a]);
    for (int a = 0; a < nl; a++)
        s += v[a];
    return s;
}

/* Node n's row of y (see apply_path): its cells' products summed in the adj order; in the
 * Chebyshev variants, instead of storing it, the step on node n (its cells are all done: no
 * later cell of this pass reads its x). Component by component the same arithmetic in the
 * same order as scalar code, 4 lanes wide (lane 3 is discarded). */
static inline __attribute__((always_inline)) void node_out(const mg_level *l, int n,
                                                           const float *x, const float *b,
                                                           float *y, const cheb_step *cs,
                                                           const int mode)
{
    const int32_t *fadj = l->fadj + l->nstart[n];
    const int links = l->nstart[n + 1] - l->nstart[n];
    /* (x, y, z, ·) per link: one 16-byte load and add each, the same sums per component */
    vf4 s = {0, 0, 0, 0};
    const float *fe = __builtin_assume_aligned(l->fe, 16);
    if (links == 8) /* an interior node: its 8 links loaded at once, summed in the same order */
        s = sum_links(fe, fadj, 8);
    else if (links == 4) /* ... inside row batches (one link per node row) */
        s = sum_links(fe, fadj, 4);
    else {
        for (int a = 0; a < links; a++) {
            vf4 v;
            memcpy(&v, fe + fadj[a], sizeof v);
            s += v;
        }
    }
    const vf4 ax = s + l->dgf[n] * load3(x + 3 * n);
    if (mode == NP_APPLY) {
        store3(y + 3 * n, ax);
        return;
    }
    const vf4 fr = free_mask(l, n);
    const vf4 r = and4(load3(b + 3 * n) - ax, fr);
    if (mode == NP_RESID) {
        store3(y + 3 * n, r);
        return;
    }
    const vf4 z = dinv(l, n, r);
    const bool first = mode == NP_CHEB_FIRST || mode == NP_CHEB_FIRST_OUT;
    const vf4 dj = and4(first ? cs->c * z : cs->a * load3(cs->d + 3 * n) + cs->c * z, fr);
    if (cs->d)
        store3(cs->d + 3 * n, dj);
    const vf4 xn = and4(load3(cs->x + 3 * n) + dj, fr);
    store3(cs->x + 3 * n, xn);
    if (mode == NP_CHEB_FIRST_OUT || mode == NP_CHEB_OUT)
        for (int k = 0; k < 3; k++)
            cs->out[3 * (size_t)n + k] = xn[k];
}

/* One thread's share of apply_path (mode compile-time once inlined): its segments' element
 * and node passes chunk by chunk, then (after the barrier) the nodes they share with lower
 * segments. */
static inline __attribute__((always_inline)) void path_share(const mg_level *l, int simd,
                                                             const float *x, const float *b,
                                                             float *y, const cheb_step *csp,
                                                             const int mode)
{
    /* a private copy: the node pass's stores cannot change it (no reloads of d, x, a, c) */
    const cheb_step c = csp ? *csp : (cheb_step){NULL, NULL, 0.0f, 0.0f, false, NULL}, *cs = &c;
    const int nt = omp_get_num_threads(), t = omp_get_thread_num();
    for (int sg = t; sg < l->nseg; sg += nt) {
        const int b0 = seg_start(l, sg), b1 = seg_start(l, sg + 1);
        for (int j0 = b0; j0 < b1; j0 += MG_CHUNK) {
            const int j1 = j0 + MG_CHUNK < b1 ? j0 + MG_CHUNK : b1;
            if (simd == SIMD_512)
                batches_wide(l, x, j0, j1);
            else if (simd == SIMD_256)
                batches_avx512(l, x, j0, j1);
            else
                batches_generic(l, x, j0, j1);
            for (int q = l->nfirst[j0]; q < l->nfirst[j1]; q++)
                if (l->nminb[q] >= b0)
                    node_out(l, l->norder[q], x, b, y, cs, mode);
        }
    }
#pragma omp barrier
    /* a node shared with a lower segment has its last cell within span batches of the
     * segment's start: only those positions are scanned (none in the first segment), all
     * segments' together shared out equally among the threads (segments.h) */
    int64_t total = 0;
    for (int pass = 0; pass < 2; pass++) {
        int64_t before = 0;
        for (int sg = 1; sg < l->nseg; sg++) {
            const int b0 = seg_start(l, sg), b1 = seg_start(l, sg + 1);
            const int e = b0 + l->span < b1 ? b0 + l->span : b1;
            const int q0 = l->nfirst[b0], len = l->nfirst[e] - q0;
            if (pass == 1) {
                int64_t lo, hi;
                cs_segment_share(before, len, total, t, nt, &lo, &hi);
                for (int64_t q = q0 + lo; q < q0 + hi; q++)
                    if (l->nminb[q] < b0)
                        node_out(l, l->norder[q], x, b, y, cs, mode);
            }
            before += len;
        }
        total = before;
    }
}

/* path_share per variant, compiled for AVX2 as well where the CPU has it (3-operand VEX
 * forms: fewer register copies in the node pass; no FMA contraction, the same values). */
#define PATH_VARIANT(NAME, MODE)                                                               \
    __attribute__((noinline, target_clones("arch=x86-64-v3", "default"))) static void NAME(    \
        const mg_level *l, int simd, const float *x, const float *b, float *y,                 \
        const cheb_step *cs)                                                                   \
    {                                                                                          \
        path_share(l, simd, x, b, y, cs, MODE);                                                 \
    }
PATH_VARIANT(path_apply, NP_APPLY)
PATH_VARIANT(path_resid, NP_RESID)
PATH_VARIANT(path_cheb_first, NP_CHEB_FIRST)
PATH_VARIANT(path_cheb, NP_CHEB)
PATH_VARIANT(path_cheb_first_out, NP_CHEB_FIRST_OUT)
PATH_VARIANT(path_cheb_out, NP_CHEB_OUT)

/* y = Σ s R K Rᵀ x + dg x on any level (the finest too: rediscretized like the coarse ones);
 * with b, the residual y = b − (that) at free dofs and 0 at held ones, in the same pass; with
 * cs (and b), the Chebyshev step on that residual instead of y (cs->x is x). */
static void apply_path(const cs_mg *mg, int level, int simd, const float *x, const float *b,
                       float *y, const cheb_step *cs)
{
    const mg_level *l = &mg->lv[level];
    const int mode = !b    ? NP_APPLY
                     : !cs ? NP_RESID
                           : (cs->first ? NP_CHEB_FIRST : NP_CHEB) + (cs->out ? 2 : 0);
    if (l->n_batches == 0) {
        for (int n = 0; n < l->n_nodes; n++)
            node_out(l, n, x, b, y, cs, mode);
        return;
    }
    /* on the lattice (mg_lattice.c): the product, the residual and a first Chebyshev step
     * without d (the fourth kind's steps); not for the portable path (simd 0) */
    if (l->lat && simd && mg->lattice && (!cs || (cs->first && !cs->d))) {
        const int lm = !b ? CS_MGL_APPLY : !cs ? CS_MGL_RESID : CS_MGL_CHEB;
        if (cs_mgl_apply(l->lat, l->threads, lm, cs ? cs->x : (float *)x, b, y,
                         cs ? cs->c : 0.0f, cs ? cs->out : NULL))
            return;
    }
    /* Each segment (product_layout; one per thread when the team is complete): its batches
     * chunk by chunk, each chunk's element pass followed by the node pass of the nodes whose
     * cells are all done and all in the segment (their results still in cache); after the
     * barrier the nodes it shares with lower segments. One copy per variant. */
#pragma omp parallel num_threads(l->threads)
    switch (mode) {
    case NP_APPLY:
        path_apply(l, simd, x, b, y, cs);
        break;
    case NP_RESID:
        path_resid(l, simd, x, b, y, cs);
        break;
    case NP_CHEB_FIRST:
        path_cheb_first(l, simd, x, b, y, cs);
        break;
    case NP_CHEB:
        path_cheb(l, simd, x, b, y, cs);
        break;
    case NP_CHEB_FIRST_OUT:
        path_cheb_first_out(l, simd, x, b, y, cs);
        break;
    default:
        path_cheb_out(l, simd, x, b, y, cs);
        break;
    }
}

static void apply_ex(const cs_mg *mg, int level, const float *x, const float *b, float *y)
{
    apply_path(mg, level, mg->simd, x, b, y, NULL);
}

static void apply(const cs_mg *mg, int level, const float *x, float *y)
{
    apply_ex(mg, level, x, NULL, y);
}

void cs_mg_apply_level(const cs_mg *mg, int level, bool portable, const float *x, float *y)
{
    if (level >= 0 && level < mg->n_levels)
        apply_path(mg, level, portable ? 0 : mg->simd, x, NULL, y, NULL);
}

void cs_mg_residual_level(const cs_mg *mg, int level, const float *x, const float *b, float *y)
{
    if (level >= 0 && level < mg->n_levels)
        apply_path(mg, level, mg->simd, x, b, y, NULL);
}

void cs_mg_cheb_step_level(const cs_mg *mg, int level, const float *b, float *x, float *d,
                           float a, float c, bool first)
{
    if (level < 0 || level >= mg->n_levels)
        return;
    const cheb_step cs = {d, x, a, c, first, NULL};
    apply_path(mg, level, mg->simd, x, b, NULL, &cs);
}

void cs_mg_set_lattice(cs_mg *mg, bool on)
{
    mg->lattice = on;
}

int cs_mg_level_layout(const cs_mg *mg, int level)
{
    if (level < 0 || level >= mg->n_levels)
        return 0;
    const mg_level *l = &mg->lv[level];
    return (l->bidx16 ? CS_MG_NARROW_CORNERS : 0) | (l->bQ_ok ? CS_MG_QUAT_ROTATIONS : 0) |
           (l->pc_ent ? CS_MG_CELL_PROLONGATION : 0) | (l->r_pk ? CS_MG_PACKED_RESTRICTION : 0) |
           (l->n_row_batches ? CS_MG_ROW_BATCHES : 0) | (l->lat ? CS_MG_LATTICE : 0);
}

void cs_mg_level_smoother(const cs_mg *mg, int level, float *inv, uint8_t *mask)
{
    if (level < 0 || level >= mg->n_levels)
        return;
    const mg_level *l = &mg->lv[level];
    for (int n = 0; n < l->n_nodes; n++)
        for (int k = 0; k < 3; k++) {
            for (int j = 0; j < 3; j++)
                inv[9 * n + 3 * k + j] = l->invf[9 * n + 3 * j + k];
            mask[3 * n + k] = (uint8_t)(l->held[n] >> k & 1);
        }
}

/* x (+)= ω D⁻¹ r at free dofs; zero at held ones. */
static void jacobi(const mg_level *l, const float *r, float *x, float omega, bool add)
{
#pragma omp parallel for num_threads(l->threads) schedule(static)
    for (int i = 0; i < l->n_nodes; i++) {
        const vf4 s = omega * dinv(l, i, load3(r + 3 * i));
        store3(x + 3 * i, and4(add ? load3(x + 3 * i) + s : s, free_mask(l, i)));
    }
}

/* x += ω D⁻¹ (b − A x). */
static void smooth(const cs_mg *mg, int level, const float *b, float *x)
{
    mg_level *l = &mg->lv[level];
    /* masked: D⁻¹ acts on the free dofs only (Z D⁻¹ Z keeps the cycle symmetric) */
    apply_ex(mg, level, x, b, l->t);
    jacobi(l, l->t, x, l->omega, true);
}

/* d = a d + c D⁻¹ t (d = c D⁻¹ t if first), x += d (x = d if zero) at free dofs, 0 at held;
 * d NULL (first only): d not stored. */
static void cheb_update(const mg_level *l, const float *t, float *d, float *x, float a, float c,
                        bool first, bool zero)
{
#pragma omp parallel for num_threads(l->threads) schedule(static)
    for (int i = 0; i < l->n_nodes; i++) {
        const vf4 z = dinv(l, i, load3(t + 3 * i)), fr = free_mask(l, i);
        const vf4 dj = and4(first ? c * z : a * load3(d + 3 * i) + c * z, fr);
        if (d)
            store3(d + 3 * i, dj);
        store3(x + 3 * i, zero ? dj : and4(load3(x + 3 * i) + dj, fr));
    }
}

/* cheb_update's first step from x = 0 on a right-hand side still in double (the V-cycle's
 * input): each node's b converted to single precision, stored into t and used, in one pass. */
static void cheb_update_in(const mg_level *l, const double *in, float *t, float *d, float *x,
                           float c)
{
#pragma omp parallel for num_threads(l->threads) schedule(static)
    for (int i = 0; i < l->n_nodes; i++) {
        const double *v = in + 3 * (size_t)i;
        const vf4 tv = {(float)v[0], (float)v[1], (float)v[2], 0.0f};
        store3(t + 3 * i, tv);
        const vf4 z = dinv(l, i, tv), dj = and4(c * z, free_mask(l, i));
        if (d)
            store3(d + 3 * i, dj);
        store3(x + 3 * i, dj);
    }
}

/*
 * Chebyshev smoothing of the level's degree (MG_CHEB on the finest, MG_CHEB_COARSE below):
 * x += p(D⁻¹A) D⁻¹ (b − A x); from x = 0 if zero (one product less). Kind 4 (MG_CHEB_KIND):
 * Lottes' optimised fourth-kind polynomial on [0, λ], applied as its root factors, one
 * Richardson step x += (c_i/λ) D⁻¹ (b − A x) each (the factors commute; c_i ≥ 1, the mildest
 * first). Kind 1: the polynomial that minimises max |1 − λ p(λ)| over [λ/MG_CHEB_RATIO, λ],
 * by its three-term recurrence. Either way the same polynomial before and after the coarse
 * correction keeps the V-cycle symmetric, and |1 − λ p(λ)| < 1 on (0, λmax] keeps it positive
 * definite.
 */
static void cheb(const cs_mg *mg, int level, const float *b, float *x, bool zero,
                 const double *in, double *out)
{
    mg_level *l = &mg->lv[level];
    /* in (with zero): b is yet to be converted from it, by the first step (into l->b: the
     * V-cycle's finest right-hand side); out: the last step writes x in double there too */
    if (MG_CHEB_KIND == 4) {
        /* the polynomial as a product of its root factors: x += (c_i/λ) D⁻¹ (b − A x); each
         * step's d = (c_i/λ) D⁻¹ r is added to x and not kept (d NULL: not stored) */
        for (int k = 0; k < l->cheb_deg; k++) {
            const float c = (float)(l->cheb_c[k] / l->lam);
            if (k == 0 && zero && in) {
                cheb_update_in(l, in, l->b, NULL, x, c);
            } else if (k == 0 && zero) {
                cheb_update(l, b, NULL, x, 0.0f, c, true, true);
            } else {
                const cheb_step cs = {NULL, x, 0.0f, c, true,
                                      k == l->cheb_deg - 1 ? out : NULL};
                apply_path(mg, level, mg->simd, x, b, NULL, &cs);
            }
        }
        return;
    }
    const double lmax = l->lam, lmin = lmax / MG_CHEB_RATIO;
    const double theta = 0.5 * (lmax + lmin), delta = 0.5 * (lmax - lmin), sigma = theta / delta;
    double rho = 1.0 / sigma;
    if (zero && in) {
        cheb_update_in(l, in, l->b, l->d, x, (float)(1.0 / theta));
    } else if (zero) {
        cheb_update(l, b, l->d, x, 0.0f, (float)(1.0 / theta), true, true);
    } else {
        /* apply_ex into l->t, then cheb_update: fused */
        const cheb_step cs = {l->d, x, 0.0f, (float)(1.0 / theta), true,
                              l->cheb_deg == 1 ? out : NULL};
        apply_path(mg, level, mg->simd, x, b, NULL, &cs);
    }
    for (int k = 1; k < l->cheb_deg; k++) {
        const double rn = 1.0 / (2.0 * sigma - rho);
        const cheb_step cs = {l->d, x, (float)(rn * rho), (float)(2.0 * rn / delta), false,
                              k == l->cheb_deg - 1 ? out : NULL};
        apply_path(mg, level, mg->simd, x, b, NULL, &cs);
        rho = rn;
    }
}

/* ------------------------------------------------------------------ setup */

/* The 3×3 block (k, j) of s R K Rᵀ added to B (row stride ld). */
static void add_rotated_block(const double *K, const double *R, double s, int k, int j,
                              double *B, int ld)
{
    double Kb[9], T[9];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            Kb[3 * a + b] = K[(3 * k + a) * 24 + 3 * j + b];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            T[3 * a + b] = R[3 * a] * Kb[b] + R[3 * a + 1] * Kb[3 + b] + R[3 * a + 2] * Kb[6 + b];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            B[a * ld + b] += s * (T[3 * a] * R[3 * b] + T[3 * a + 1] * R[3 * b + 1] +
                                  T[3 * a + 2] * R[3 * b + 2]);
}

/* Level c's node diagonal dg (the restriction of f's) and held dofs (those of its fine nodes of
 * largest weight), node by node. */
static void restrict_diagonal(const mg_level *f, mg_level *c)
{
#pragma omp parallel for num_threads(c->threads) schedule(static)
    for (int p = 0; p < c->n_nodes; p++) {
        const int J = c->nwalk[p];
        double d = 0, wmax = 0;
        uint8_t held[3] = {0, 0, 0};
        for (int a = f->r_start[J]; a < f->r_start[J + 1]; a++) {
            d += f->r_w[a] * f->dg[f->r_node[a]];
            if (f->r_w[a] > wmax)
                wmax = f->r_w[a];
        }
        for (int a = f->r_start[J]; a < f->r_start[J + 1]; a++)
            if (f->r_w[a] >= wmax * (1 - 1e-9))
                for (int k = 0; k < 3; k++)
                    held[k] |= f->mask[3 * f->r_node[a] + k];
        c->dg[J] = d;
        for (int k = 0; k < 3; k++)
            c->own_mask[3 * J + k] = held[k] ? 1 : 0;
    }
}

/* Level l (>= 1) from level l−1: rotations, stiffness multipliers, D⁻¹, and the diagonal and
 * held dofs unless `same` (level 0's are the last setup's, and so are these). */
static void setup_coarse(cs_mg *mg, int level, bool corotational, bool same)
{
    mg_level *f = &mg->lv[level - 1], *c = &mg->lv[level];
    /* Cells by first child (walk: the fine rotations are read forward, not once per k row),
     * MG_ROT_BATCH at a time: the rotations of their summed child rotations extracted side
     * by side (cs_extract_rotations, each cs_extract_rotation's bit for bit). */
    const int nwb = (c->n_cells + MG_ROT_BATCH - 1) / MG_ROT_BATCH;
#pragma omp parallel for num_threads(c->threads) schedule(static)
    for (int wb = 0; wb < nwb; wb++) {
        double Ra[MG_ROT_BATCH][9] = {{0}}, q[MG_ROT_BATCH][4];
        const int p0 = wb * MG_ROT_BATCH;
        const int m = c->n_cells - p0 < MG_ROT_BATCH ? c->n_cells - p0 : MG_ROT_BATCH;
        for (int l = 0; l < m; l++) {
            const int C = c->walk[p0 + l];
            double sum = 0;
            for (int a = c->ch_start[C]; a < c->ch_start[C + 1]; a++) {
                const int fc = c->ch[a];
                sum += f->s[fc];
                if (corotational)
                    for (int i = 0; i < 9; i++)
                        Ra[l][i] += f->R[9 * fc + i];
            }
            c->s[C] = 2.0 * sum / 8.0;
            memcpy(q[l], c->q + 4 * C, sizeof q[l]);
        }
        if (!corotational)
            continue;
        cs_extract_rotations(m, &Ra[0][0], &q[0][0], 30);
        for (int l = 0; l < m; l++) {
            const int C = c->walk[p0 + l];
            memcpy(c->q + 4 * C, q[l], sizeof q[l]);
            cs_quat_to_mat(q[l], c->own_R + 9 * C);
        }
    }
    if (!same)
        restrict_diagonal(f, c);
    /* D⁻¹: node by node (the cells of a node in adj order, so any thread count gives the same
     * sums), each corner block by R K_kk Rᵀ = (K00 − K01) I + K01 (R σ)(R σ)ᵀ, σ the corner's
     * signs (2·CS_CORNER − 1): the cube's corner block is K00 on the diagonal and K01 σ_a σ_b
     * off it (cs_mg_build checks that on the model's K) */
    const double kd = mg->K[0] - mg->K[1], ko = mg->K[1];
    double sg[8][3]; /* σ as doubles (±1: the products are exact either way) */
    for (int k = 0; k < 8; k++)
        for (int i = 0; i < 3; i++)
            sg[k][i] = 2 * CS_CORNER[k][i] - 1;
#pragma omp parallel for num_threads(c->threads) schedule(static)
    for (int J = 0; J < c->n_nodes; J++) {
        double m[9] = {0};
        for (int a = c->adj_start[J]; a < c->adj_start[J + 1]; a++) {
            const int C = c->adj[a] / 8, k = c->adj[a] % 8;
            const double *R = c->R + 9 * C, sc = c->s[C];
            double v[3], p[3];
            for (int i = 0; i < 3; i++)
                v[i] = R[3 * i] * sg[k][0] + R[3 * i + 1] * sg[k][1] + R[3 * i + 2] * sg[k][2];
            /* sc·ko·v_i·v_j evaluates left to right: (sc·ko·v_i)·v_j, the p_i hoisted */
            const double sk = sc * ko, skd = sc * kd;
            for (int i = 0; i < 3; i++)
                p[i] = sk * v[i];
            for (int i = 0; i < 3; i++) {
                for (int j = 0; j < 3; j++)
                    m[3 * i + j] += p[i] * v[j];
                m[4 * i] += skd;
            }
        }
        for (int i = 0; i < 3; i++)
            m[4 * i] += c->dg[J];
        cs_mat3_invert_block(m);
        memcpy(c->own_inv + 9 * J, m, sizeof m);
    }
}

/* Does the model's K have the corner-block form setup_coarse's D⁻¹ assumes? */
static bool corner_blocks_ok(const double *K)
{
    const double kd = K[0] - K[1], ko = K[1], tol = 1e-12 * fabs(K[0]);
    for (int k = 0; k < 8; k++)
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) {
                const double want = (a == b ? kd : 0.0) + ko * (2 * CS_CORNER[k][a] - 1) *
                                                           (2 * CS_CORNER[k][b] - 1);
                if (fabs(K[(3 * k + a) * 24 + 3 * k + b] - want) > tol)
                    return false;
            }
    return true;
}

/* Dense Cholesky of the coarsest operator (held dofs: identity rows). */
static int setup_dense(cs_mg *mg)
{
    mg_level *l = &mg->lv[mg->n_levels - 1];
    const int n = mg->dense_n;
    double *M = mg->dense;
    memset(M, 0, (size_t)n * n * sizeof(double));
    for (int C = 0; C < l->n_cells; C++) {
        const int32_t *nd = l->cell_nodes + 8 * C;
        for (int k = 0; k < 8; k++)
            for (int j = 0; j < 8; j++)
                add_rotated_block(mg->K, l->R + 9 * C, l->s[C], k, j,
                                  M + (size_t)3 * nd[k] * n + 3 * nd[j], n);
    }
    double dmax = 0;
    for (int i = 0; i < n; i++) {
        M[(size_t)i * n + i] += l->dg[i / 3];
        if (M[(size_t)i * n + i] > dmax)
            dmax = M[(size_t)i * n + i];
    }
    if (!(dmax > 0) || !isfinite(dmax))
        dmax = 1;
    for (int i = 0; i < n; i++)
        if (l->mask[i])
            for (int j = 0; j < n; j++)
                M[(size_t)i * n + j] = M[(size_t)j * n + i] = i == j ? 1.0 : 0.0;
    /* in-place lower Cholesky */
    for (int j = 0; j < n; j++) {
        double *Rj = M + (size_t)j * n;
        double d = Rj[j];
        for (int k = 0; k < j; k++)
            d -= Rj[k] * Rj[k];
        if (!(d > 1e-13 * dmax))
            d = dmax; /* a (near) free mode of the coarsest level: damp it */
        d = sqrt(d);
        Rj[j] = d;
        for (int i = j + 1; i < n; i++) {
            double *Ri = M + (size_t)i * n;
            double s = Ri[j];
            for (int k = 0; k < j; k++)
                s -= Ri[k] * Rj[k];
            Ri[j] = s / d;
        }
    }
    for (int i = 0; i < n * n; i++)
        if (!isfinite(M[i]))
            return -1;
    return 0;
}

/* λmax(D⁻¹A) of a level by power iteration, the free dofs only. */
static double estimate_lambda(cs_mg *mg, int level)
{
    mg_level *l = &mg->lv[level];
    const int n3 = 3 * l->n_nodes;
    float *v = malloc((size_t)(n3 ? n3 : 1) * sizeof(float));
    float *w = malloc((size_t)(n3 ? n3 : 1) * sizeof(float));
    double lam = 2.0;
    if (!v || !w)
        goto out;
    uint64_t s = 0x9e3779b97f4a7c15ull;
    for (int d = 0; d < n3; d++) {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        v[d] = l->mask[d] ? 0.0f : (float)((double)(s >> 11) / 9007199254740992.0 - 0.5);
    }
    for (int it = 0; it < MG_POWER_ITERS; it++) {
        double nv = 0, nw = 0;
        for (int d = 0; d < n3; d++)
            nv += (double)v[d] * v[d];
        if (!(nv > 0))
            break;
        apply(mg, level, v, l->t);
        for (int d = 0; d < n3; d++)
            if (l->mask[d])
                l->t[d] = 0;
        jacobi(l, l->t, w, 1.0f, false);
        for (int d = 0; d < n3; d++)
            nw += (double)w[d] * w[d];
        lam = sqrt(nw / nv);
        const double sc = 1.0 / sqrt(nw > 0 ? nw : 1);
        for (int d = 0; d < n3; d++)
            v[d] = (float)(w[d] * sc);
    }
out:
    free(v);
    free(w);
    return isfinite(lam) && lam > 0 ? lam : 2.0;
}

/*
 * The element pass's rotations as float unit quaternions (bQ): the quaternions the cells' R
 * were made from (l->rq: fem's rotation extraction on level 0, setup_coarse's below; lanes
 * past the last cell: the identity). Used (bQ_ok) only if R(q) rebuilt in double from the
 * float q is every cell's R within 1e-6 per entry; otherwise the pass reads bR. Called at
 * the end of to_single, every setup.
 */
static void rotation_layout(mg_level *l)
{
    int bad = 0;
#pragma omp parallel for num_threads(l->threads) schedule(static) reduction(+ : bad)
    for (int b = 0; b < l->n_batches; b++)
        for (int p = 0; p < MG_LANES; p++) {
            const int c = b * MG_LANES + p;
            double qf[4] = {1, 0, 0, 0};
            if (c < l->n_cells) {
                for (int j = 0; j < 4; j++)
                    qf[j] = (float)l->rq[4 * (size_t)c + j];
                double Rq[9];
                CS_QUAT_TO_MAT(qf[0], qf[1], qf[2], qf[3], Rq); /* cs_quat_to_mat's, inline */
                for (int j = 0; j < 9; j++)
                    bad += !(fabs(Rq[j] - l->R[9 * (size_t)c + j]) <= 1e-6);
            }
            for (int j = 0; j < 4; j++)
                l->bQ[(4 * b + j) * MG_LANES + p] = (float)qf[j];
        }
    l->bQ_ok = bad == 0;
}

/* The single-precision copies the V-cycle reads: the rotations (bQ; bR only where the element
 * pass reads it, i.e. not bQ_ok) and D⁻¹ every setup, the scales, diagonal and held dofs unless
 * `same` (cs_mg_setup: what they are made from has not changed since the last setup). */
static void to_single(mg_level *l, double hl, double hm, bool same)
{
    rotation_layout(l);
    const bool rot = !l->bQ_ok;
    if (rot || !same) {
#pragma omp parallel for num_threads(l->threads) schedule(static)
        for (int b = 0; b < l->n_batches; b++)
            for (int p = 0; p < MG_LANES; p++) {
                const int c = b * MG_LANES + p;
                const bool live = c < l->n_cells;
                for (int k = 0; rot && k < 9; k++)
                    l->bR[(9 * b + k) * MG_LANES + p] =
                        live ? (float)l->R[9 * c + k] : k % 4 == 0;
                if (same)
                    continue;
                l->bL[b * MG_LANES + p] = live ? (float)(l->s[c] * hl / 16.0) : 0.0f;
                l->bM[b * MG_LANES + p] = live ? (float)(l->s[c] * hm / 16.0) : 0.0f;
            }
    }
#pragma omp parallel for num_threads(l->threads) schedule(static)
    for (int n = 0; n < l->n_nodes; n++) {
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++)
                l->invf[9 * n + 3 * j + k] = (float)l->inv[9 * n + 3 * k + j];
        if (same)
            continue;
        l->dgf[n] = (float)l->dg[n];
        l->held[n] = (uint8_t)((l->mask[3 * n] ? 1 : 0) | (l->mask[3 * n + 1] ? 2 : 0) |
                               (l->mask[3 * n + 2] ? 4 : 0));
    }
    l->invf[9 * (size_t)l->n_nodes] = 0.0f; /* the tail dinv's last column load reads */
    if (l->lat)
        cs_mgl_set(l->lat, l->bL, l->bM, l->bQ, l->bQ_ok, l->invf, l->dgf, l->held, same,
                   l->threads);
}

/* Whether level 0's s, dg and held dofs are the last whole setup's (mg->prev_*, remember_setup;
 * false before the first and when the copies could not be allocated). */
static bool same_as_last_setup(const cs_mg *mg)
{
    const mg_level *l = &mg->lv[0];
    return mg->prev_ok &&
           memcmp(mg->prev_s, l->s, (size_t)l->n_cells * sizeof(double)) == 0 &&
           memcmp(mg->prev_dg, l->dg, (size_t)l->n_nodes * sizeof(double)) == 0 &&
           memcmp(mg->prev_mask, l->mask, 3 * (size_t)l->n_nodes) == 0;
}

/* After a whole setup: what same_as_last_setup compares with (not kept if out of memory);
 * `same`: the copies hold these values already. */
static void remember_setup(cs_mg *mg, bool same)
{
    if (same) {
        mg->prev_ok = true;
        return;
    }
    const mg_level *l = &mg->lv[0];
    const size_t ns = (size_t)l->n_cells * sizeof(double), nd = (size_t)l->n_nodes * sizeof(double),
                 nm = 3 * (size_t)l->n_nodes;
    if (!mg->prev_s) {
        mg->prev_s = malloc(ns ? ns : 1);
        mg->prev_dg = malloc(nd ? nd : 1);
        mg->prev_mask = malloc(nm ? nm : 1);
    }
    if (!mg->prev_s || !mg->prev_dg || !mg->prev_mask)
        return;
    memcpy(mg->prev_s, l->s, ns);
    memcpy(mg->prev_dg, l->dg, nd);
    memcpy(mg->prev_mask, l->mask, nm);
    mg->prev_ok = true;
}

void cs_mg_setup_forget(cs_mg *mg)
{
    mg->prev_ok = false;
}

int cs_mg_setup(cs_mg *mg, const cs_fem *fem, cs_matvec_fn A, void *ctx, const double *inv0,
                const uint8_t *mask0)
{
    mg->A = A;
    mg->ctx = ctx;
    mg_level *l0 = &mg->lv[0];
    l0->R = fem->R;
    l0->rq = fem->q;
    l0->inv = inv0;
    l0->mask = mask0;
    /* a rebuild for the rotations alone keeps what the scales, diagonal and held dofs give */
    const bool same = same_as_last_setup(mg);
    mg->prev_ok = false; /* until this setup is whole */
    for (int l = 1; l < mg->n_levels; l++)
        setup_coarse(mg, l, fem->corotational, same);
    if (mg->dense && setup_dense(mg))
        return -1;
    for (int l = 0; l < mg->n_levels; l++)
        to_single(&mg->lv[l], mg->hl, mg->hm, same);
    remember_setup(mg, same);
    /* Smoothing weights: re-estimated when the operator's kind changes, and now and then. */
    const double key[3] = {l0->s[0], l0->dg[0], (double)mg->n_levels};
    if (mg->setups % MG_LAMBDA_EVERY == 0 || memcmp(key, mg->key, sizeof key) != 0) {
        memcpy(mg->key, key, sizeof key);
        for (int l = 0; l < mg->n_levels; l++) {
            mg->lv[l].lam = MG_LAMBDA_SAFETY * estimate_lambda(mg, l);
            mg->lv[l].omega = (float)(4.0 / (3.0 * mg->lv[l].lam));
        }
    }
    mg->setups++;
    return 0;
}

/* ------------------------------------------------------------------ the V-cycle */

static void coarsest(cs_mg *mg, const float *b, float *x)
{
    const int L = mg->n_levels - 1;
    mg_level *l = &mg->lv[L];
    if (!mg->dense) {
        jacobi(l, b, x, l->omega, false);
        for (int s = 1; s < MG_COARSE_SWEEPS; s++)
            smooth(mg, L, b, x);
        return;
    }
    const int n = mg->dense_n;
    const double *M = mg->dense;
    double *y = mg->dense_x;
    for (int i = 0; i < n; i++) {
        double s = l->mask[i] ? 0.0 : b[i];
        const double *Ri = M + (size_t)i * n;
        for (int k = 0; k < i; k++)
            s -= Ri[k] * y[k];
        y[i] = s / Ri[i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = y[i];
        for (int k = i + 1; k < n; k++)
            s -= M[(size_t)k * n + i] * y[k];
        y[i] = s / M[(size_t)i * n + i];
    }
    for (int i = 0; i < n; i++)
        x[i] = l->mask[i] ? 0.0f : (float)y[i];
}

/* l->b = in and out = l->x, for the paths that cannot fuse these conversions into a pass */
static void from_double(const mg_level *l, const double *in, float *b)
{
    const int n3 = 3 * l->n_nodes;
#pragma omp parallel for num_threads(l->threads) schedule(static)
    for (int d = 0; d < n3; d++)
        b[d] = (float)in[d];
}

static void to_double(const mg_level *l, const float *x, double *out)
{
    const int n3 = 3 * l->n_nodes;
#pragma omp parallel for num_threads(l->threads) schedule(static)
    for (int d = 0; d < n3; d++)
        out[d] = x[d];
}

/* xc = Pᵀ xf at the free dofs of level `level` + 1, 0 at its held ones (the residual's
 * restriction), by the packed pairs where the layout allows (transfer_layout). */
static void restrict_to(const cs_mg *mg, int level, const float *xf, float *xc)
{
    const mg_level *f = &mg->lv[level], *c = &mg->lv[level + 1];
#pragma omp parallel for num_threads(c->threads) schedule(static)
    for (int J = 0; J < c->n_nodes; J++) {
        /* (x, y, z, 0) vectors: per component the scalar sums in the same order */
        vf4 s = {0, 0, 0, 0};
        if (f->r_pk) {
            static const float W[4] = {1.0f, 0.5f, 0.25f, 0.125f};
            for (int a = f->r_start[J]; a < f->r_start[J + 1]; a++) {
                const uint32_t e = f->r_pk[a];
                s += W[e >> 27] * load3(xf + 3 * (size_t)(e & ((1u << 27) - 1)));
            }
        } else {
            for (int a = f->r_start[J]; a < f->r_start[J + 1]; a++)
                s += f->r_tw[a].w * load3(xf + 3 * f->r_tw[a].node);
        }
        store3(xc + 3 * J, and4(s, free_mask(c, J)));
    }
}

/* The prolongation row of position p (t0 + 3 t1 + 9 t2 in half-units, constant once inlined)
 * applied to its coarse cell's corner values: the nonzero trilinear weights in corner order,
 * in float, summed from 0 as the rows are (position_rows, coarsen). */
static inline __attribute__((always_inline)) vf4 position_row(const int p, const vf4 *xc)
{
    const int t[3] = {p % 3, p / 3 % 3, p / 9};
    vf4 s = {0, 0, 0, 0};
    for (int K = 0; K < 8; K++) {
        const float w = (float)position_weight(t, K);
        if (w != 0)
            s += w * xc[K];
    }
    return s;
}

/* x += P xc at free dofs of level `level` (held dofs keep their value, bit for bit: not
 * x + 0), by coarse cells where the layout allows (transfer_layout), else by rows. */
static void prolong_add(const cs_mg *mg, int level, const float *xc_in, float *x)
{
    const mg_level *f = &mg->lv[level], *c = &mg->lv[level + 1];
    if (f->pc_ent) {
        /* by coarse cells: each fine node once, from its coarse cell's corners (the same sums
         * in the same order as its row) */
#pragma omp parallel for num_threads(f->threads) schedule(static)
        for (int C = 0; C < c->n_cells; C++) {
            const int a0 = f->pc_start[C], a1 = f->pc_start[C + 1];
            if (a0 == a1)
                continue;
            vf4 xc[8];
            for (int K = 0; K < 8; K++)
                xc[K] = load3(xc_in + 3 * c->cell_nodes[8 * C + K]);
            for (int a = a0; a < a1; a++) {
                const int n = (int)(f->pc_ent[a] & ((1u << 27) - 1)), p = f->pc_ent[a] >> 27;
                vf4 s;
                switch (p) { /* the row of each position with its weights as constants */
#define PROW_CASE(P)                                                                           \
    case P:                                                                                    \
        s = position_row(P, xc);                                                               \
        break;
                    PROW_CASE(0) PROW_CASE(1) PROW_CASE(2) PROW_CASE(3) PROW_CASE(4)
                    PROW_CASE(5) PROW_CASE(6) PROW_CASE(7) PROW_CASE(8) PROW_CASE(9)
                    PROW_CASE(10) PROW_CASE(11) PROW_CASE(12) PROW_CASE(13) PROW_CASE(14)
                    PROW_CASE(15) PROW_CASE(16) PROW_CASE(17) PROW_CASE(18) PROW_CASE(19)
                    PROW_CASE(20) PROW_CASE(21) PROW_CASE(22) PROW_CASE(23) PROW_CASE(24)
                    PROW_CASE(25)
#undef PROW_CASE
                default:
                    s = position_row(26, xc);
                    break;
                }
                const vf4 fr = free_mask(f, n), xn = load3(x + 3 * n);
                store3(x + 3 * n, (vf4)(((vi4)(xn + s) & (vi4)fr) | ((vi4)xn & ~(vi4)fr)));
            }
        }
        for (int i = 0; i < f->n_lone; i++) { /* x + 0, as an empty row gives */
            const int n = f->p_lone[i];
            const vf4 fr = free_mask(f, n), xn = load3(x + 3 * n), s = {0, 0, 0, 0};
            store3(x + 3 * n, (vf4)(((vi4)(xn + s) & (vi4)fr) | ((vi4)xn & ~(vi4)fr)));
        }
    } else {
#pragma omp parallel for num_threads(f->threads) schedule(static)
        for (int n = 0; n < f->n_nodes; n++) {
            vf4 s = {0, 0, 0, 0};
            for (int a = f->p_start[n]; a < f->p_start[n + 1]; a++)
                s += f->p_tw[a].w * load3(xc_in + 3 * f->p_tw[a].node);
            /* held dofs keep their value (bit for bit: not x + 0) */
            const vf4 fr = free_mask(f, n), xn = load3(x + 3 * n);
            store3(x + 3 * n, (vf4)(((vi4)(xn + s) & (vi4)fr) | ((vi4)xn & ~(vi4)fr)));
        }
    }
}

/* The V-cycle from `level` down. On the finest level (cs_mg_vcycle) b is l->b, still to be
 * converted from in (double), and the result also goes to out in double: the first and the
 * last smoothing steps do that in their passes (a pass and a parallel region fewer each). */
static void vcycle(cs_mg *mg, int level, const float *b, float *x, const double *in,
                   double *out)
{
    mg_level *f = &mg->lv[level];
    if (level == mg->n_levels - 1 || !f->cheb_deg) {
        if (in)
            from_double(f, in, f->b);
        in = NULL;
    }
    if (level == mg->n_levels - 1) {
        coarsest(mg, b, x);
        if (out)
            to_double(f, x, out);
        return;
    }
    mg_level *c = &mg->lv[level + 1];
    if (f->cheb_deg) {
        cheb(mg, level, b, x, true, in, NULL);
    } else {
        jacobi(f, b, x, f->omega, false);
        for (int s = 1; s < MG_NU; s++)
            smooth(mg, level, b, x);
    }
    /* residual, restricted */
    apply_ex(mg, level, x, b, f->t);
    restrict_to(mg, level, f->t, c->b);
    vcycle(mg, level + 1, c->b, c->x, NULL, NULL);
    for (int g = 1; g < c->cycles; g++) {
        /* W: one more cycle on the level's residual, x_c += B_c (b_c − A_c x_c); with B_c
         * symmetric, the two together (2 B_c − B_c A_c B_c) are too */
        apply_ex(mg, level + 1, c->x, c->b, c->gb);
        vcycle(mg, level + 1, c->gb, c->gx, NULL, NULL);
#pragma omp parallel for num_threads(c->threads) schedule(static)
        for (int d = 0; d < 3 * c->n_nodes; d++)
            c->x[d] += c->gx[d]; /* 0 at held dofs */
    }
    prolong_add(mg, level, c->x, x);
    if (f->cheb_deg) {
        cheb(mg, level, b, x, false, NULL, out);
    } else {
        for (int s = 0; s < MG_NU; s++)
            smooth(mg, level, b, x);
        if (out)
            to_double(f, x, out);
    }
}

void cs_mg_vcycle(void *ctx, const double *r, double *z)
{
    cs_mg *mg = ctx;
    mg_level *l0 = &mg->lv[0];
    vcycle(mg, 0, l0->b, l0->x, r, z);
}

/* ------------------------------------------------------------------ transfers (for tests) */

void cs_mg_prolong(const cs_mg *mg, int level, const float *xc, float *xf)
{
    if (level < 0 || level + 1 >= mg->n_levels)
        return;
    const mg_level *f = &mg->lv[level];
    for (int n = 0; n < f->n_nodes; n++)
        for (int k = 0; k < 3; k++) {
            float s = 0;
            for (int a = f->p_start[n]; a < f->p_start[n + 1]; a++)
                s += (float)f->p_w[a] * xc[3 * f->p_node[a] + k];
            xf[3 * n + k] = s;
        }
}

void cs_mg_prolong_add_level(const cs_mg *mg, int level, const float *xc, float *xf)
{
    if (level >= 0 && level + 1 < mg->n_levels)
        prolong_add(mg, level, xc, xf);
}

void cs_mg_restrict_level(const cs_mg *mg, int level, const float *xf, float *xc)
{
    if (level >= 0 && level + 1 < mg->n_levels)
        restrict_to(mg, level, xf, xc);
}

void cs_mg_restrict(const cs_mg *mg, int level, const float *xf, float *xc)
{
    if (level < 0 || level + 1 >= mg->n_levels)
        return;
    const mg_level *f = &mg->lv[level], *c = &mg->lv[level + 1];
    for (int J = 0; J < c->n_nodes; J++)
        for (int k = 0; k < 3; k++) {
            float s = 0;
            for (int a = f->r_start[J]; a < f->r_start[J + 1]; a++)
                s += (float)f->r_w[a] * xf[3 * f->r_node[a] + k];
            xc[3 * J + k] = s;
        }
}
