/*
 * test_products.c — the fused element and node passes of the products (fem.c in double, the
 * V-cycle's finest level in mg.c in single precision) on blocks large enough that every
 * segment cycles through its window of results (fem.c product_layout, mg.c product_layout),
 * with a partial last batch, graded cells, inactive cells and a scrambled cell order (a node's
 * cells far apart: the window then holds the whole segment): equal to the dense product, and
 * bit-identical on one and two threads.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cells_ref.h"
#include "cubemesh.h"
#include "dense_ref.h"
#include "fem.h"
#include "lattice.h"
#include "mg.h"
#include "simd.h"
#include "solver.h"

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX - 0.5;
}

/* An nx × ny × nz block of cubes of edge h, i fastest; scrambled: the cells in a random order. */
static int block(cs_cubemesh *cm, int nx, int ny, int nz, double h, bool scrambled)
{
    return cells_build(cm, h, cs_box_cells(nx, ny, nz), nx * ny * nz, scrambled ? 5 : 0);
}

/* Positions of a block bent about y and jiggled: every cell rotated differently. */
static void bent(const cs_cubemesh *cm, double *x, unsigned *seed)
{
    for (int a = 0; a < cm->n_nodes; a++) {
        const double *X = cm->node_rest + 3 * a, th = 0.7 * X[2];
        x[3 * a] = X[0] * cos(th) + X[2] * sin(th) + 0.1 * cm->h * urand(seed);
        x[3 * a + 1] = X[1] + 0.1 * cm->h * urand(seed);
        x[3 * a + 2] = -X[0] * sin(th) + X[2] * cos(th);
    }
}

TEST(fem_fused_products_match_dense_and_threads)
{
    for (int scrambled = 0; scrambled < 2; scrambled++) {
        cs_cubemesh cm;
        /* 3100 cells: 387 whole batches of 8 and a partial one; a layer is 310 cells, so a
         * segment (388 or 194 batches) cycles through its window of about 2 × 40 + 64 */
        ENSURE(block(&cm, 31, 10, 10, 0.05, scrambled) == 0);
        cs_fem f[2];
        ENSURE(cs_fem_init(&f[0], &cm, 2e6, 0.3, true, 1) == 0);
        ENSURE(cs_fem_init(&f[1], &cm, 2e6, 0.3, true, 2) == 0);
        ENSURE(f[1].threads == 2);
        const int n = cm.n_nodes, nc = cm.n_cells;
        double *x = malloc(sizeof(double) * 3 * n), *p = malloc(sizeof(double) * 3 * n),
               *y[2] = {malloc(sizeof(double) * 3 * n), malloc(sizeof(double) * 3 * n)},
               *ref = malloc(sizeof(double) * 3 * n), *kf = malloc(sizeof(double) * 8 * nc);
        uint8_t *act = malloc((size_t)nc);
        unsigned seed = 21;
        bent(&cm, x, &seed);
        for (int i = 0; i < 3 * n; i++)
            p[i] = urand(&seed);
        for (int c = 0; c < nc; c++) {
            act[c] = c % 7 != 3 && (c / 50) % 4 != 1; /* whole inactive batches too */
            for (int g = 0; g < 8; g++) /* every fifth cell graded, the others uniform */
                kf[8 * c + g] = c % 5 == 0 ? 0.5 + 0.2 * g : 1.0 + 0.25 * (c % 3);
        }
        for (int t = 0; t < 2; t++) {
            f[t].kf = kf;
            cs_fem_update_rotations(&f[t], x);
        }
        /* apply_K: dense, and the same bits on both thread counts */
        dense_apply(&f[0], kf, NULL, p, ref);
        double m = 0;
        for (int i = 0; i < 3 * n; i++)
            m = fmax(m, fabs(ref[i]));
        for (int t = 0; t < 2; t++) {
            cs_fem_apply_K(&f[t], p, y[t]);
            for (int i = 0; i < 3 * n; i++)
                ENSURE_MSG(fabs(y[t][i] - ref[i]) <= 1e-13 * m, "scrambled %d threads %d dof %d",
                           scrambled, t + 1, i);
        }
        ENSURE(memcmp(y[0], y[1], sizeof(double) * 3 * n) == 0);
        /* elastic force and energy; the static tangent */
        double e[2];
        for (int t = 0; t < 2; t++)
            cs_fem_elastic_force(&f[t], x, y[t], &e[t]);
        ENSURE(memcmp(y[0], y[1], sizeof(double) * 3 * n) == 0);
        ENSURE_NEAR(e[1], e[0], 1e-12 * fabs(e[0]));
        ENSURE_NEAR(e[0], cs_fem_energy(&f[0], x), 1e-10 * fabs(e[0]));
        for (int t = 0; t < 2; t++) {
            ENSURE(cs_fem_prepare_tangent(&f[t], x) == 0);
            cs_fem_apply_tangent(&f[t], p, y[t]);
            cs_fem_release_tangent(&f[t]);
        }
        ENSURE(memcmp(y[0], y[1], sizeof(double) * 3 * n) == 0);
        /* an active region: inactive cells (and batches with none active) left out */
        dense_apply(&f[0], kf, act, p, ref);
        for (int t = 0; t < 2; t++) {
            f[t].cell_active = act;
            cs_fem_apply_K(&f[t], p, y[t]);
            f[t].cell_active = NULL;
            for (int i = 0; i < 3 * n; i++)
                ENSURE_MSG(fabs(y[t][i] - ref[i]) <= 1e-13 * m,
                           "active: scrambled %d threads %d dof %d", scrambled, t + 1, i);
        }
        ENSURE(memcmp(y[0], y[1], sizeof(double) * 3 * n) == 0);
        free(x);
        free(p);
        free(y[0]);
        free(y[1]);
        free(ref);
        free(kf);
        free(act);
        cs_fem_free(&f[0]);
        cs_fem_free(&f[1]);
        cs_cubemesh_free(&cm);
    }
}

/* The V-cycle's finest product (single precision, s = 1, no diagonal) against the double
 * product on a block whose segments cycle through their windows on two threads, in both cell
 * orders: within float rounding of the largest term, and the same bits on one and two threads
 * and with either way of gathering the inputs. */
TEST(mg_fine_product_windowed_matches_fem)
{
    for (int scrambled = 0; scrambled < 2; scrambled++) {
        cs_cubemesh cm;
        /* 4896 cells, 306 batches of 16; a layer is 408 cells: windows of about 26 + 90 */
        ENSURE(block(&cm, 34, 12, 12, 0.05, scrambled) == 0);
        const int n = cm.n_nodes, nc = cm.n_cells;
        double *x = malloc(sizeof(double) * 3 * n), *pd = malloc(sizeof(double) * 3 * n),
               *ref = malloc(sizeof(double) * 3 * n), *inv = malloc(sizeof(double) * 9 * n);
        float *pf = malloc(sizeof(float) * 3 * n), *y[3];
        uint8_t *mask = calloc(3 * (size_t)n, 1);
        for (int t = 0; t < 3; t++)
            y[t] = malloc(sizeof(float) * 3 * n);
        unsigned seed = 8;
        bent(&cm, x, &seed);
        for (int i = 0; i < 3 * n; i++) {
            pf[i] = (float)urand(&seed);
            pd[i] = pf[i];
        }
        for (int a = 0; a < n; a++)
            for (int k = 0; k < 9; k++)
                inv[9 * a + k] = k % 4 == 0;
        for (int t = 0; t < 2; t++) {
            cs_fem fem;
            ENSURE(cs_fem_init(&fem, &cm, 1e5, 0.3, true, t + 1) == 0);
            cs_fem_update_rotations(&fem, x);
            if (t == 0)
                cs_fem_apply_K(&fem, pd, ref);
            cs_mg *mg = cs_mg_build(&cm, &fem, 1);
            ENSURE(mg != NULL);
            double *s = cs_mg_cell_scale(mg), *dg = cs_mg_node_diag(mg);
            for (int c = 0; c < nc; c++)
                s[c] = 1.0;
            for (int a = 0; a < n; a++)
                dg[a] = 0.0;
            ENSURE(cs_mg_setup(mg, &fem, NULL, NULL, inv, mask) == 0);
            cs_mg_apply_level(mg, 0, false, pf, y[t]); /* on the lattice where taken */
            if (t == 1) { /* the slots and node pass: the same bits both ways */
                float *ys = malloc(sizeof(float) * 3 * n);
                cs_mg_set_lattice(mg, false);
                cs_mg_apply_level(mg, 0, false, pf, ys);
                cs_mg_apply_level(mg, 0, true, pf, y[2]);
                cs_mg_set_lattice(mg, true);
                ENSURE_MSG(memcmp(ys, y[2], sizeof(float) * 3 * n) == 0,
                           "the portable gathers give another product");
                free(ys);
            }
            cs_mg_free(mg);
            cs_fem_free(&fem);
        }
        double m = 0, err = 0;
        for (int i = 0; i < 3 * n; i++)
            m = fmax(m, fabs(ref[i]));
        for (int i = 0; i < 3 * n; i++)
            err = fmax(err, fabs(y[0][i] - ref[i]));
        printf("    %s: max error %.3g of the largest term\n", scrambled ? "scrambled" : "box",
               err / m);
        ENSURE(err <= 2e-6 * m);
        ENSURE_MSG(memcmp(y[0], y[1], sizeof(float) * 3 * n) == 0,
                   "the product differs between 1 and 2 threads");
        free(x);
        free(pd);
        free(ref);
        free(inv);
        free(pf);
        free(mask);
        for (int t = 0; t < 3; t++)
            free(y[t]);
        cs_cubemesh_free(&cm);
    }
}

/* An irregular mesh: an nx × ny × nz block with holes (every cell whose ijk hash hits 1 in 6
 * removed, so many nodes have 1–7 cells), in a scrambled order. */
static int holey_block(cs_cubemesh *cm, int nx, int ny, int nz, double h)
{
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    if (!ijk)
        return -1;
    int n = 0;
    for (int c = 0; c < nx * ny * nz; c++) {
        const int32_t *q = ijk + 3 * c;
        if ((q[0] * 7 + q[1] * 13 + q[2] * 29) % 6 == 5 && q[0] > 0 && q[0] < nx - 1)
            continue;
        memmove(ijk + 3 * n++, q, 3 * sizeof(int32_t));
    }
    return cells_build(cm, h, ijk, n, 9);
}

/* The implicit step's operator both ways (world.c step_operator): fused = cs_fem_apply_K_mass,
 * unfused = cs_fem_apply_K then y = kc·y + mc·m_i·p_i in a pass of its own. */
typedef struct km_ctx {
    cs_fem *fem;
    const double *m;
    double kc, mc;
} km_ctx;

static void km_fused(void *ctx, const double *p, double *y)
{
    km_ctx *c = ctx;
    cs_fem_apply_K_mass(c->fem, c->kc, c->mc, c->m, p, y);
}

static void km_unfused(void *ctx, const double *p, double *y)
{
    km_ctx *c = ctx;
    cs_fem_apply_K(c->fem, p, y);
    for (int i = 0; i < c->fem->n_nodes; i++)
        for (int a = 0; a < 3; a++)
            y[3 * i + a] = c->kc * y[3 * i + a] + c->mc * c->m[i] * p[3 * i + a];
}

/* cs_fem_apply_K_mass (the mass term added in the node pass) on an irregular, graded,
 * corotated mesh, whole and with inactive cells: the same bits as the unfused operator on one
 * and two threads, kc·(dense K p) + mc·M p to rounding; and a block-Jacobi CG solve with held
 * dofs on it takes the same iterations to the same bits, holds the held dofs, and its answer
 * meets the tolerance against the dense operator. */
TEST(fem_products_K_mass_match_unfused_operator)
{
    cs_cubemesh cm;
    ENSURE(holey_block(&cm, 30, 11, 10, 0.04) == 0);
    cs_fem f[2];
    ENSURE(cs_fem_init(&f[0], &cm, 1e8, 0.3, true, 1) == 0);
    ENSURE(cs_fem_init(&f[1], &cm, 1e8, 0.3, true, 2) == 0);
    ENSURE(f[1].threads == 2);
    const int n = cm.n_nodes, nc = cm.n_cells, nd = 3 * n;
    int partial = 0;
    for (int i = 0; i < n; i++)
        partial += f[0].adj_start[i + 1] - f[0].adj_start[i] < 8;
    ENSURE(partial > n / 3); /* irregular: many nodes with fewer than 8 cells */
    const size_t bytes = sizeof(double) * (size_t)nd;
    double *x = malloc(bytes), *p = malloc(bytes), *ref = malloc(bytes), *b = malloc(bytes),
           *ya[2] = {malloc(bytes), malloc(bytes)}, *yb[2] = {malloc(bytes), malloc(bytes)},
           *m = malloc(sizeof(double) * n), *kf = malloc(sizeof(double) * 8 * nc),
           *blocks = malloc(sizeof(double) * 9 * n);
    uint8_t *act = malloc((size_t)nc), *mask = malloc((size_t)nd);
    ENSURE(x && p && ref && b && ya[0] && ya[1] && yb[0] && yb[1] && m && kf && blocks && act &&
           mask);
    unsigned seed = 33;
    bent(&cm, x, &seed);
    for (int i = 0; i < nd; i++)
        p[i] = urand(&seed);
    for (int i = 0; i < n; i++)
        m[i] = 0.01 * (1.0 + urand(&seed)); /* positive, every node different */
    for (int c = 0; c < nc; c++) {
        act[c] = c % 9 != 4;
        for (int g = 0; g < 8; g++) /* graded: every third cell point by point, others scaled */
            kf[8 * c + g] = c % 3 == 0 ? 0.3 + 0.3 * g : 1.0 + 0.5 * (c % 4);
    }
    for (int t = 0; t < 2; t++) {
        f[t].kf = kf;
        cs_fem_update_rotations(&f[t], x);
    }
    const double kc = 2.5e-5, mc = 1.0;
    for (int pass = 0; pass < 2; pass++) { /* whole; an active region */
        const uint8_t *a = pass ? act : NULL;
        dense_apply(&f[0], kf, a, p, ref);
        double big = 0;
        for (int i = 0; i < nd; i++) {
            ref[i] = kc * ref[i] + mc * m[i / 3] * p[i];
            big = fmax(big, fabs(ref[i]));
        }
        for (int t = 0; t < 2; t++) {
            f[t].cell_active = a;
            km_ctx c = {&f[t], m, kc, mc};
            km_fused(&c, p, ya[t]);
            km_unfused(&c, p, yb[t]);
            f[t].cell_active = NULL;
            ENSURE_MSG(memcmp(ya[t], yb[t], bytes) == 0, "pass %d threads %d", pass, t + 1);
            for (int i = 0; i < nd; i++)
                ENSURE_MSG(fabs(ya[t][i] - ref[i]) <= 1e-13 * big, "pass %d threads %d dof %d",
                           pass, t + 1, i);
        }
        ENSURE(memcmp(ya[0], ya[1], bytes) == 0);
    }
    /* CG with held dofs: the nodes of the x = 0 face all held, 1 in 7 of the others' dofs */
    for (int i = 0; i < nd; i++)
        mask[i] = cm.node_rest[3 * (i / 3)] < 1e-9 || i % 7 == 2;
    cs_fem_diag_blocks(&f[0], blocks);
    for (int i = 0; i < n; i++) {
        for (int k = 0; k < 9; k++)
            blocks[9 * i + k] *= kc;
        for (int k = 0; k < 3; k++)
            blocks[9 * i + 4 * k] += mc * m[i];
    }
    cs_invert_blocks(blocks, n);
    for (int i = 0; i < nd; i++)
        b[i] = mask[i] ? 0.0 : urand(&seed) * 0.01;
    cs_cg_work w;
    ENSURE(cs_cg_work_init(&w, nd) == 0);
    cs_cg_result r[2][2];
    const double tol = 1e-8;
    for (int t = 0; t < 2; t++) {
        km_ctx c = {&f[t], m, kc, mc};
        for (int i = 0; i < nd; i++)
            ya[t][i] = yb[t][i] = mask[i] ? x[i] : 0.0; /* held dofs keep a value */
        r[t][0] = cs_pcg(&w, km_fused, &c, blocks, mask, b, ya[t], tol, 2000, t + 1);
        r[t][1] = cs_pcg(&w, km_unfused, &c, blocks, mask, b, yb[t], tol, 2000, t + 1);
        ENSURE_MSG(r[t][0].converged && r[t][1].converged, "threads %d", t + 1);
        ENSURE(r[t][0].iterations == r[t][1].iterations && r[t][0].iterations > 10);
        ENSURE_MSG(memcmp(ya[t], yb[t], bytes) == 0, "CG threads %d", t + 1);
        for (int i = 0; i < nd; i++)
            ENSURE(!mask[i] || ya[t][i] == x[i]);
    }
    /* the answer against the dense operator: the free rows' residual (the held dofs' values
     * moved to the right-hand side) within the tolerance, with room for the products' rounding */
    dense_apply(&f[0], kf, NULL, ya[0], ref);
    double rr = 0, bb = 0;
    for (int i = 0; i < nd; i++)
        if (!mask[i]) {
            const double res = b[i] - (kc * ref[i] + mc * m[i / 3] * ya[0][i]);
            rr += res * res;
            bb += b[i] * b[i];
        }
    ENSURE_MSG(sqrt(rr) <= 1.01 * tol * sqrt(bb), "relres %g", sqrt(rr / bb));
    cs_cg_work_free(&w);
    free(x);
    free(p);
    free(ref);
    free(b);
    for (int t = 0; t < 2; t++) {
        free(ya[t]);
        free(yb[t]);
    }
    free(m);
    free(kf);
    free(blocks);
    free(act);
    free(mask);
    cs_fem_free(&f[0]);
    cs_fem_free(&f[1]);
    cs_cubemesh_free(&cm);
}

/* The node of cm at lattice point (i, j, k) for every node of ref: the same block numbered
 * otherwise (nodes at multiples of h from the origin). */
static int *node_map(const cs_cubemesh *ref, const cs_cubemesh *cm, int nx, int ny)
{
    const int n = ref->n_nodes;
    int *at = malloc(sizeof(int) * (size_t)(nx + 1) * (ny + 1) * (n / ((nx + 1) * (ny + 1)) + 2));
    int *map = malloc(sizeof(int) * (size_t)n);
    if (!at || !map) {
        free(at);
        free(map);
        return NULL;
    }
    for (int pass = 0; pass < 2; pass++) {
        const cs_cubemesh *m = pass ? ref : cm;
        for (int a = 0; a < n; a++) {
            const double *X = m->node_rest + 3 * a;
            const int i = (int)lround(X[0] / m->h), j = (int)lround(X[1] / m->h),
                      k = (int)lround(X[2] / m->h), key = i + (nx + 1) * (j + (ny + 1) * k);
            if (pass)
                map[a] = at[key];
            else
                at[key] = a;
        }
    }
    free(at);
    return map;
}

/* Row batches (fem.c, product_layout: 8 cells along a lattice row whose node rows are numbered
 * consecutively, read by rows and each node's two results in a row added in the element pass)
 * against the same block scrambled, which has none: the products, the elastic force and energy,
 * the static tangent and the product with the mass term agree node for node to rounding, with
 * uniform cells (the whole-row kernel where the cores run 512-bit vectors), with graded ones
 * (their lanes stored first) and in an active region (inactive lanes add nothing). */
TEST(fem_row_batches_match_scrambled_block)
{
    const int nx = 32, ny = 6, nz = 5;
    cs_cubemesh cm[2];
    ENSURE(block(&cm[0], nx, ny, nz, 0.05, false) == 0);
    ENSURE(block(&cm[1], nx, ny, nz, 0.05, true) == 0);
    const int n = cm[0].n_nodes, nc = cm[0].n_cells;
    int *map = node_map(&cm[0], &cm[1], nx, ny);
    int *cmap = malloc(sizeof(int) * nc); /* cell of cm[1] at cell c of cm[0] */
    ENSURE(map && cmap);
    {
        int *at = malloc(sizeof(int) * nc);
        ENSURE(at);
        for (int pass = 0; pass < 2; pass++)
            for (int c = 0; c < nc; c++) {
                const int32_t *q = cm[pass ? 0 : 1].cell_ijk + 3 * c;
                const int key = q[0] + nx * (q[1] + ny * q[2]);
                if (pass)
                    cmap[c] = at[key];
                else
                    at[key] = c;
            }
        free(at);
    }
    double *x[2], *p[2], *y[2], *kf[2];
    uint8_t *act[2];
    for (int s = 0; s < 2; s++) {
        x[s] = malloc(sizeof(double) * 3 * n);
        p[s] = malloc(sizeof(double) * 3 * n);
        y[s] = malloc(sizeof(double) * 3 * n);
        kf[s] = malloc(sizeof(double) * 8 * nc);
        act[s] = malloc((size_t)nc);
        ENSURE(x[s] && p[s] && y[s] && kf[s] && act[s]);
    }
    unsigned seed = 5;
    bent(&cm[0], x[0], &seed);
    for (int i = 0; i < 3 * n; i++)
        p[0][i] = urand(&seed);
    for (int a = 0; a < n; a++)
        for (int i = 0; i < 3; i++) {
            x[1][3 * map[a] + i] = x[0][3 * a + i];
            p[1][3 * map[a] + i] = p[0][3 * a + i];
        }
    double *m = malloc(sizeof(double) * n), *m1 = malloc(sizeof(double) * n);
    ENSURE(m && m1);
    for (int a = 0; a < n; a++)
        m1[map[a]] = m[a] = 0.1 + 0.01 * (a % 7);
    for (int graded = 0; graded < 2; graded++)
        for (int threads = 1; threads <= 2; threads++) {
            cs_fem f[2];
            for (int s = 0; s < 2; s++)
                ENSURE(cs_fem_init(&f[s], &cm[s], 2e6, 0.3, true, threads) == 0);
            /* row batches where the CPU runs the 512-bit kernels at full width */
            ENSURE_MSG((cs_simd_wide_default() ? f[0].n_row_batches >= nc / 8 / 4
                                               : f[0].n_row_batches == 0) &&
                           f[1].n_row_batches == 0,
                       "row batches: %d in lattice order, %d scrambled", f[0].n_row_batches,
                       f[1].n_row_batches);
            for (int c = 0; c < nc; c++) {
                act[0][c] = c % 13 != 4 && (c / 64) % 3 != 1;
                act[1][cmap[c]] = act[0][c];
                for (int g = 0; g < 8; g++) { /* graded: every ninth cell */
                    kf[0][8 * c + g] = graded && c % 9 == 0 ? 0.5 + 0.2 * g : 1.0 + 0.25 * (c % 3);
                    kf[1][8 * cmap[c] + g] = kf[0][8 * c + g];
                }
            }
            double e[2], big = 0;
            for (int s = 0; s < 2; s++) {
                f[s].kf = kf[s];
                cs_fem_update_rotations(&f[s], x[s]);
            }
            /* compare y[0] with y[1] node for node, relative to the largest entry */
#define ROWS_AGREE(what)                                                                        \
    do {                                                                                        \
        big = 0;                                                                                \
        for (int i = 0; i < 3 * n; i++)                                                         \
            big = fmax(big, fabs(y[0][i]));                                                     \
        double worst = 0;                                                                       \
        for (int a = 0; a < n; a++)                                                             \
            for (int i = 0; i < 3; i++)                                                         \
                worst = fmax(worst, fabs(y[0][3 * a + i] - y[1][3 * map[a] + i]));              \
        ENSURE_MSG(big > 0 && worst <= 1e-13 * big, "%s (graded %d, %d threads): %.3g of %.3g", \
                   what, graded, threads, worst, big);                                          \
    } while (0)
            for (int s = 0; s < 2; s++)
                cs_fem_apply_K(&f[s], p[s], y[s]);
            ROWS_AGREE("apply_K");
            for (int s = 0; s < 2; s++)
                cs_fem_elastic_force(&f[s], x[s], y[s], &e[s]);
            ROWS_AGREE("elastic force");
            ENSURE_NEAR(e[0], e[1], 1e-12 * fabs(e[0]));
            for (int s = 0; s < 2; s++)
                cs_fem_apply_K_mass(&f[s], 0.3, 2.0, s ? m1 : m, p[s], y[s]);
            ROWS_AGREE("apply_K_mass");
            for (int s = 0; s < 2; s++) {
                ENSURE(cs_fem_prepare_tangent(&f[s], x[s]) == 0);
                cs_fem_apply_tangent(&f[s], p[s], y[s]);
                cs_fem_release_tangent(&f[s]);
            }
            ROWS_AGREE("tangent");
            for (int s = 0; s < 2; s++) {
                f[s].cell_active = act[s];
                cs_fem_apply_K(&f[s], p[s], y[s]);
                f[s].cell_active = NULL;
            }
            ROWS_AGREE("active region");
#undef ROWS_AGREE
            for (int s = 0; s < 2; s++)
                cs_fem_free(&f[s]);
        }
    for (int s = 0; s < 2; s++) {
        free(x[s]);
        free(p[s]);
        free(y[s]);
        free(kf[s]);
        free(act[s]);
        cs_cubemesh_free(&cm[s]);
    }
    free(m);
    free(m1);
    free(map);
    free(cmap);
}
