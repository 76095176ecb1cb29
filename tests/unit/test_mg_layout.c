/*
 * test_mg_layout.c — the V-cycle's compact element-pass layouts (mg.c: corner indices as
 * 16-bit offsets from a base per batch, rotations as float quaternions rebuilt in the pass,
 * transfer rows as (node, float weight) pairs) against references that do not use them: the
 * finest product against Σ s R K Rᵀ x + dg x in double with the mesh's own R, on meshes that
 * take each layout and each fallback (a scrambled cell order whose batches span more than
 * 16-bit offsets reach; a cell whose R is not a rotation), with graded stiffness scales and
 * held dofs (the residual pass: 0 there); every level bit-identical with the portable gathers
 * and on one and two threads; and the V-cycle's prolongation by coarse cells against P's rows
 * and its packed restriction against Pᵀ's rows on every level, bit for bit (held dofs
 * unchanged, and 0 at the coarse held ones).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cells_ref.h"
#include "cubemesh.h"
#include "fem.h"
#include "lattice.h"
#include "mg.h"
#include "simd.h"

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX - 0.5;
}

/* An nx × ny × nz block with every `hole`-th cell left out (0: none; a cut, irregular mesh),
 * in lattice order or scrambled. */
static int block(cs_cubemesh *cm, int nx, int ny, int nz, int hole, bool scrambled)
{
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    if (!ijk)
        return -1;
    int n = 0;
    for (int c = 0; c < nx * ny * nz; c++)
        if (!hole || c % hole != hole / 2) {
            memmove(ijk + 3 * n, ijk + 3 * c, 3 * sizeof(int32_t));
            n++;
        }
    return cells_build(cm, 0.05, ijk, n, scrambled ? 11 : 0);
}

typedef struct lay_case {
    int nx, ny, nz, hole;
    bool scrambled, skew; /* skew: one cell's R a non-rotation (the matrix path) */
    int want0;            /* cs_mg_level_layout of level 0 */
} lay_case;

/* One case on `threads` threads: returns the number of failed checks (-1: could not run);
 * y gets the level-0 product, ylev the products of every level (concatenated) for the
 * comparison across thread counts. */
static long run_case(lay_case k, int threads, float *y, float *ylev, size_t *nlev, int *layout0,
                     double *err0)
{
    cs_cubemesh cm;
    if (block(&cm, k.nx, k.ny, k.nz, k.hole, k.scrambled) != 0)
        return -1;
    cs_fem fem;
    if (cs_fem_init(&fem, &cm, 2e6, 0.3, true, threads) != 0) {
        cs_cubemesh_free(&cm);
        return -1;
    }
    const int n = cm.n_nodes, nc = cm.n_cells;
    double *x = malloc(sizeof(double) * 3 * n), *inv = malloc(sizeof(double) * 9 * n),
           *ref = calloc(3 * (size_t)n, sizeof(double));
    float *xf = malloc(sizeof(float) * 3 * n), *bf = malloc(sizeof(float) * 3 * n),
          *yp = malloc(sizeof(float) * 3 * n), *r = malloc(sizeof(float) * 3 * n);
    uint8_t *mask = calloc(3 * (size_t)n, 1);
    cs_mg *mg = NULL;
    long bad = -1;
    unsigned seed = 3;
    if (!x || !inv || !ref || !xf || !bf || !yp || !r || !mask)
        goto out;
    for (int a = 0; a < n; a++) { /* bent about y and jiggled: every cell turned differently */
        const double *X = cm.node_rest + 3 * a, th = 0.9 * X[2];
        x[3 * a] = X[0] * cos(th) + X[2] * sin(th) + 0.01 * urand(&seed);
        x[3 * a + 1] = X[1] + 0.01 * urand(&seed);
        x[3 * a + 2] = -X[0] * sin(th) + X[2] * cos(th);
    }
    cs_fem_update_rotations(&fem, x);
    if (k.skew) /* not a rotation: R scaled by 1.01 */
        for (int j = 0; j < 9; j++)
            fem.R[9 * (nc / 2) + j] *= 1.01;
    mg = cs_mg_build(&cm, &fem, 1);
    if (!mg)
        goto out;
    double *s = cs_mg_cell_scale(mg), *dg = cs_mg_node_diag(mg);
    for (int c = 0; c < nc; c++) /* graded: scales over two decades */
        s[c] = exp(4.6 * (urand(&seed) + 0.5));
    for (int a = 0; a < n; a++) {
        dg[a] = 50.0 * (1.0 + urand(&seed));
        for (int j = 0; j < 9; j++)
            inv[9 * a + j] = j % 4 == 0 ? 1e-3 : 0.0;
        for (int i = 0; i < 3; i++) /* held: every held pattern, and whole nodes */
            mask[3 * a + i] = (a % 11 < 8 && (a % 11) >> i & 1) || a % 17 == 0;
    }
    for (int d = 0; d < 3 * n; d++) {
        xf[d] = (float)urand(&seed);
        bf[d] = (float)urand(&seed);
    }
    if (cs_mg_setup(mg, &fem, NULL, NULL, inv, mask) != 0)
        goto out;
    bad = 0;
    *layout0 = cs_mg_level_layout(mg, 0);
    /* level 0 against the double reference with fem's R */
    cs_mg_apply_level(mg, 0, false, xf, y); /* on the lattice where taken */
    /* the slots and node pass: the same bits with AVX-512 and the portable gathers */
    cs_mg_set_lattice(mg, false);
    cs_mg_apply_level(mg, 0, false, xf, r);
    cs_mg_apply_level(mg, 0, true, xf, yp);
    cs_mg_set_lattice(mg, true);
    bad += memcmp(r, yp, sizeof(float) * 3 * n) != 0;
    double big = 0, worst = 0;
    for (int c = 0; c < nc; c++) {
        const int32_t *nd = cm.cell_nodes + 8 * c;
        const double *R = fem.R + 9 * c;
        double u[24], ku[24];
        for (int q = 0; q < 8; q++)
            for (int i = 0; i < 3; i++) {
                const float *d = xf + 3 * nd[q];
                u[3 * q + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
            }
        for (int i = 0; i < 24; i++) {
            ku[i] = 0;
            for (int j = 0; j < 24; j++)
                ku[i] += s[c] * fem.K[24 * i + j] * u[j];
        }
        for (int q = 0; q < 8; q++)
            for (int i = 0; i < 3; i++) {
                const double v = R[3 * i] * ku[3 * q] + R[3 * i + 1] * ku[3 * q + 1] +
                                 R[3 * i + 2] * ku[3 * q + 2];
                ref[3 * nd[q] + i] += v;
                big = fmax(big, fabs(v));
            }
    }
    for (int a = 0; a < n; a++)
        for (int i = 0; i < 3; i++) {
            const int d = 3 * a + i;
            ref[d] += dg[a] * xf[d];
            big = fmax(big, fabs(dg[a] * xf[d]));
        }
    for (int d = 0; d < 3 * n; d++)
        worst = fmax(worst, fabs(y[d] - ref[d]));
    *err0 = worst / big;
    bad += !(*err0 < 2e-6);
    /* the residual pass: b − A x at free dofs, exactly 0 at held ones */
    cs_mg_residual_level(mg, 0, xf, bf, r);
    for (int d = 0; d < 3 * n; d++)
        bad += mask[d] ? r[d] != 0.0f : !(fabs(r[d] - (bf[d] - ref[d])) <= 2e-6 * big + 1e-6);
    /* every level: the portable gathers give the same bits; the transfers match the
     * reference loops (double weights converted as the V-cycle does) */
    *nlev = 0;
    for (int L = 0; L < cs_mg_levels(mg); L++) {
        const int m3 = 3 * cs_mg_level_nodes(mg, L);
        float *xl = malloc(sizeof(float) * m3), *pl = malloc(sizeof(float) * m3);
        if (!xl || !pl) {
            free(xl);
            free(pl);
            bad = -1;
            goto out;
        }
        for (int d = 0; d < m3; d++)
            xl[d] = (float)urand(&seed);
        cs_mg_apply_level(mg, L, false, xl, ylev + *nlev); /* on the lattice where taken */
        /* the slots and node pass: the same bits both ways, and within float rounding of
         * the lattice's (the same sums in another order) */
        cs_mg_set_lattice(mg, false);
        cs_mg_apply_level(mg, L, true, xl, pl);
        float *sl = malloc(sizeof(float) * m3);
        if (!sl) {
            free(xl);
            free(pl);
            bad = -1;
            goto out;
        }
        cs_mg_apply_level(mg, L, false, xl, sl);
        cs_mg_set_lattice(mg, true);
        bad += memcmp(sl, pl, sizeof(float) * m3) != 0;
        float lbig = 0;
        for (int d = 0; d < m3; d++)
            lbig = fmaxf(lbig, fabsf(sl[d]));
        for (int d = 0; d < m3; d++)
            bad += !(fabsf(ylev[*nlev + d] - sl[d]) <= 4e-6f * lbig);
        free(sl);
        *nlev += (size_t)m3;
        if (L + 1 < cs_mg_levels(mg)) {
            /* the V-cycle's prolongation (by coarse cells) against P's rows: x + P xc at
             * free dofs, x at held ones, bit for bit */
            const int c3 = 3 * cs_mg_level_nodes(mg, L + 1);
            float *xc = malloc(sizeof(float) * c3), *pf = malloc(sizeof(float) * m3),
                  *linv = malloc(sizeof(float) * 3 * m3);
            uint8_t *held = malloc(m3);
            if (xc && pf && linv && held) {
                for (int d = 0; d < c3; d++)
                    xc[d] = (float)urand(&seed);
                cs_mg_prolong(mg, L, xc, pf);
                cs_mg_level_smoother(mg, L, linv, held);
                memcpy(pl, xl, sizeof(float) * m3);
                cs_mg_prolong_add_level(mg, L, xc, pl);
                for (int d = 0; d < m3; d++) {
                    const float want = held[d] ? xl[d] : xl[d] + pf[d];
                    bad += memcmp(&want, pl + d, sizeof want) != 0;
                }
                bad += !(cs_mg_level_layout(mg, L) & CS_MG_CELL_PROLONGATION);
                /* ... and its restriction against the rows: Pᵀ x at the coarse free dofs */
                float *rc = malloc(sizeof(float) * c3), *rr = malloc(sizeof(float) * c3),
                      *cinv = malloc(sizeof(float) * 3 * c3);
                uint8_t *cheld = malloc(c3);
                if (rc && rr && cinv && cheld) {
                    cs_mg_restrict(mg, L, xl, rr);
                    cs_mg_restrict_level(mg, L, xl, rc);
                    cs_mg_level_smoother(mg, L + 1, cinv, cheld);
                    for (int d = 0; d < c3; d++) {
                        const float want = cheld[d] ? 0.0f : rr[d];
                        bad += memcmp(&want, rc + d, sizeof want) != 0;
                    }
                    bad += !(cs_mg_level_layout(mg, L) & CS_MG_PACKED_RESTRICTION);
                } else {
                    bad = -1;
                }
                free(rc);
                free(rr);
                free(cinv);
                free(cheld);
            } else {
                bad = -1;
            }
            free(xc);
            free(pf);
            free(linv);
            free(held);
        }
        free(xl);
        free(pl);
        if (bad < 0)
            goto out;
    }
out:
    cs_mg_free(mg);
    free(x);
    free(inv);
    free(ref);
    free(xf);
    free(bf);
    free(yp);
    free(r);
    free(mask);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
    return bad;
}

TEST(mg_compact_layouts_match_reference)
{
    const lay_case cases[] = {
        /* a cut block in lattice order, 2300 cells (two threads' segments): both layouts */
        {20, 12, 10, 7, false, false,
         CS_MG_NARROW_CORNERS | CS_MG_QUAT_ROTATIONS | CS_MG_CELL_PROLONGATION |
             CS_MG_PACKED_RESTRICTION | CS_MG_LATTICE},
        /* scrambled: a batch's corners span the whole x (> 65536 floats): 32-bit indices */
        {30, 28, 28, 0, true, false,
         CS_MG_QUAT_ROTATIONS | CS_MG_CELL_PROLONGATION | CS_MG_PACKED_RESTRICTION |
             CS_MG_LATTICE},
        /* one cell's R not a rotation: the matrices */
        {20, 12, 10, 7, false, true,
         CS_MG_NARROW_CORNERS | CS_MG_CELL_PROLONGATION | CS_MG_PACKED_RESTRICTION |
             CS_MG_LATTICE},
        /* a whole block in lattice order, rows of two batches: row batches inside (not on
         * the first row and layer, whose nodes the cells number as they come) */
        {32, 7, 6, 0, false, false,
         CS_MG_NARROW_CORNERS | CS_MG_QUAT_ROTATIONS | CS_MG_CELL_PROLONGATION |
             CS_MG_PACKED_RESTRICTION | CS_MG_ROW_BATCHES | CS_MG_LATTICE},
        /* rows of 24 cells: batches across rows, some of them row batches */
        {24, 9, 5, 0, false, false,
         CS_MG_NARROW_CORNERS | CS_MG_QUAT_ROTATIONS | CS_MG_CELL_PROLONGATION |
             CS_MG_PACKED_RESTRICTION | CS_MG_ROW_BATCHES | CS_MG_LATTICE},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        const lay_case k = cases[c];
        const size_t cap = 3 * (size_t)(k.nx + 1) * (k.ny + 1) * (k.nz + 1);
        float *y[2], *yl[2];
        size_t nl[2] = {0, 0};
        int lay[2] = {-1, -1};
        double e[2] = {0, 0};
        for (int t = 0; t < 2; t++) {
            y[t] = malloc(sizeof(float) * cap);
            yl[t] = malloc(sizeof(float) * 2 * cap); /* the levels: under 8/7 of the finest */
            ENSURE(y[t] && yl[t]);
            const long bad = run_case(k, t + 1, y[t], yl[t], &nl[t], &lay[t], &e[t]);
            ENSURE_MSG(bad == 0, "case %zu, %d threads: %ld failed checks", c, t + 1, bad);
        }
        printf("    case %zu: layout %d, max error %.3g of the largest term\n", c, lay[0], e[0]);
        /* 16-bit corners only where the element pass gathers with AVX-512 */
        const int want = (__builtin_cpu_supports("x86-64-v4")
                              ? k.want0
                              : k.want0 & ~CS_MG_NARROW_CORNERS) &
                         ~(cs_simd_wide_default() ? 0 : CS_MG_ROW_BATCHES);
        ENSURE_MSG(lay[0] == want && lay[1] == want, "case %zu: layout %d, %d", c, lay[0],
                   lay[1]);
        ENSURE(nl[0] == nl[1]);
        ENSURE_MSG(memcmp(yl[0], yl[1], sizeof(float) * nl[0]) == 0,
                   "case %zu: the products differ between 1 and 2 threads", c);
        for (int t = 0; t < 2; t++) {
            free(y[t]);
            free(yl[t]);
        }
    }
}

/* Every level's setup outputs as the V-cycle reads them: its product and residual on a fixed
 * x and b, its smoother's D⁻¹ and held dofs; appended to out (NULL: counted only). */
static size_t level_outputs(const cs_mg *mg, float *out)
{
    size_t at = 0;
    for (int lv = 0; lv < cs_mg_levels(mg); lv++) {
        const int n = cs_mg_level_nodes(mg, lv);
        float *x = malloc(sizeof(float) * (3 * (size_t)n + 1)),
              *b = malloc(sizeof(float) * (3 * (size_t)n + 1));
        uint8_t *mask = malloc(3 * (size_t)n + 1);
        if (!x || !b || !mask) {
            free(x);
            free(b);
            free(mask);
            return 0;
        }
        unsigned seed = 5 + (unsigned)lv;
        for (int d = 0; d < 3 * n; d++) {
            x[d] = (float)urand(&seed);
            b[d] = (float)urand(&seed);
        }
        if (out) {
            cs_mg_apply_level(mg, lv, false, x, out + at);
            cs_mg_residual_level(mg, lv, x, b, out + at + 3 * (size_t)n);
            cs_mg_level_smoother(mg, lv, out + at + 6 * (size_t)n, mask);
            for (int d = 0; d < 3 * n; d++)
                out[at + 15 * (size_t)n + d] = mask[d];
        }
        at += 18 * (size_t)n;
        free(x);
        free(b);
        free(mask);
    }
    return at;
}

/* Bent about y by th·z (and jiggled): every cell turned differently. */
static void bend(const cs_cubemesh *cm, double th, unsigned seed, double *x)
{
    for (int a = 0; a < cm->n_nodes; a++) {
        const double *X = cm->node_rest + 3 * a, t = th * X[2];
        x[3 * a] = X[0] * cos(t) + X[2] * sin(t) + 0.01 * urand(&seed);
        x[3 * a + 1] = X[1] + 0.01 * urand(&seed);
        x[3 * a + 2] = -X[0] * sin(t) + X[2] * cos(t);
    }
}

/*
 * A setup whose scales, diagonal and held dofs are the last setup's (a lagged hierarchy
 * rebuilt because its cells turned) keeps what those give on every level and converts only
 * the rotations and D⁻¹ (mg.c, same_as_last_setup): through a sequence of setups (the cells
 * turned; held dofs changed; the diagonal changed; a cell's R not a rotation, its matrices
 * converted too) every level's product, residual, D⁻¹ and held dofs are those of the same
 * hierarchy set up alongside with everything derived again (cs_mg_setup_forget: the coarse
 * rotations are warm-started from the last setup's, so the twin has the same history), bit
 * for bit. The rotation drift against the hierarchy is 0 for the rotations it was set up with
 * and 2(1 − cos θ) for a uniform turn by θ.
 */
TEST(mg_setup_for_turned_cells_matches_a_whole_one)
{
    cs_cubemesh cm;
    ENSURE(block(&cm, 24, 9, 5, 0, false) == 0);
    cs_fem fem;
    ENSURE(cs_fem_init(&fem, &cm, 2e6, 0.3, true, 2) == 0);
    const int n = cm.n_nodes, nc = cm.n_cells;
    double *x = malloc(sizeof(double) * 3 * n), *inv = malloc(sizeof(double) * 9 * n);
    uint8_t *mask = calloc(3 * (size_t)n, 1);
    ENSURE(x && inv && mask);
    cs_mg *mg = cs_mg_build(&cm, &fem, 1), *twin = cs_mg_build(&cm, &fem, 1);
    ENSURE(mg && twin);
    const size_t len = level_outputs(mg, NULL);
    float *got = malloc(sizeof(float) * len), *want = malloc(sizeof(float) * len);
    ENSURE(len > 0 && got && want);
    double *s = cs_mg_cell_scale(mg), *dg = cs_mg_node_diag(mg);
    unsigned seed = 7;
    for (int c = 0; c < nc; c++)
        s[c] = exp(2.0 * (urand(&seed) + 0.5));
    for (int a = 0; a < n; a++) {
        dg[a] = 50.0 * (1.0 + urand(&seed));
        for (int j = 0; j < 9; j++)
            inv[9 * a + j] = j % 4 == 0 ? 1e-3 * (1.5 + urand(&seed)) : 0.0;
        mask[3 * a + 2] = a % 13 == 0;
    }
    bend(&cm, 0.4, 3, x);
    cs_fem_update_rotations(&fem, x);
    for (int step = 0; step < 5; step++) {
        /* 1: the cells turned (bent further); 2: held dofs changed; 3: the diagonal; 4: a
         * cell's R not a rotation */
        if (step == 1) {
            bend(&cm, 0.9, 4, x);
            cs_fem_update_rotations(&fem, x);
        } else if (step == 2) {
            for (int a = 0; a < n; a++)
                mask[3 * a] = a % 7 == 0;
        } else if (step == 3) {
            for (int a = 0; a < n; a += 5)
                dg[a] *= 1.5;
        } else if (step == 4) {
            for (int j = 0; j < 9; j++)
                fem.R[9 * (nc / 2) + j] *= 1.01;
        }
        ENSURE(cs_mg_setup(mg, &fem, NULL, NULL, inv, mask) == 0);
        memcpy(cs_mg_cell_scale(twin), s, sizeof(double) * nc);
        memcpy(cs_mg_node_diag(twin), dg, sizeof(double) * n);
        cs_mg_setup_forget(twin);
        ENSURE(cs_mg_setup(twin, &fem, NULL, NULL, inv, mask) == 0);
        ENSURE(level_outputs(mg, got) == len && level_outputs(twin, want) == len);
        ENSURE_MSG(memcmp(got, want, sizeof(float) * len) == 0,
                   "step %d: the set-up differs from a whole one", step);
        ENSURE_MSG((cs_mg_level_layout(mg, 0) & CS_MG_QUAT_ROTATIONS) ==
                       (step < 4 ? CS_MG_QUAT_ROTATIONS : 0),
                   "step %d: layout %d", step, cs_mg_level_layout(mg, 0));
        if (step == 0) {
            ENSURE(cs_mg_rotation_drift(mg, fem.R, fem.q) <= 1e-6);
            /* the whole body turned by 0.1 rad about z: every cell's drift 2(1 − cos 0.1),
             * to the float copies' rounding (about 1e-7 a quaternion entry) */
            double *xt = malloc(sizeof(double) * 3 * n);
            ENSURE(xt);
            for (int a = 0; a < n; a++) {
                xt[3 * a] = cos(0.1) * x[3 * a] - sin(0.1) * x[3 * a + 1];
                xt[3 * a + 1] = sin(0.1) * x[3 * a] + cos(0.1) * x[3 * a + 1];
                xt[3 * a + 2] = x[3 * a + 2];
            }
            cs_fem_update_rotations(&fem, xt);
            const double dr = cs_mg_rotation_drift(mg, fem.R, fem.q), w = 2 * (1 - cos(0.1));
            ENSURE_MSG(fabs(dr - w) < 2e-6, "drift %.9g, want %.9g", dr, w);
            free(xt);
        }
    }
    cs_mg_free(mg);
    cs_mg_free(twin);
    free(got);
    free(want);
    free(x);
    free(inv);
    free(mask);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
}
