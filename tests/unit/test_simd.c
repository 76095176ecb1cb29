/*
 * test_simd.c — the element kernels' two vector widths (simd.h): the 512-bit forms (fem.c
 * modal_wide_body in double, mg.c wide_body in float) give the same bits as the 256-bit ones,
 * product by product (corotated and linear, uniform, scaled and graded cells, a partial last
 * batch, the force with its rest shape and energy, the implicit step's operator) and step by
 * step through a world; a world refuses a width it does not know. On a CPU without AVX-512
 * both widths are the portable or 256-bit code and the comparisons hold trivially (said so).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cells_ref.h"
#include "cubesim.h"
#include "fem.h"
#include "lattice.h"
#include "mg.h"
#include "simd.h"
#include "world_internal.h"

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX - 0.5;
}

static void note_width(void)
{
    if (!cs_simd_wide(512))
        printf("    (no AVX-512 here: both widths run the same code)\n");
}

/* cs_fem products with fem->wide false and true: the same bits. */
TEST(simd_fem_products_same_bits_both_widths)
{
    note_width();
    for (int corot = 0; corot < 2; corot++) {
        cs_cubemesh cm;
        /* 3100 cells: 387 whole batches of 8 and a partial one */
        ENSURE(cells_build(&cm, 0.05, cs_box_cells(31, 10, 10), 3100, 0) == 0);
        const int n = cm.n_nodes, nc = cm.n_cells;
        const size_t bytes = sizeof(double) * 3 * (size_t)n;
        double *x = malloc(bytes), *p = malloc(bytes), *m = malloc(sizeof(double) * n),
               *kf = malloc(sizeof(double) * 8 * nc), *y[2][3];
        ENSURE(x && p && m && kf);
        for (int w = 0; w < 2; w++)
            for (int k = 0; k < 3; k++)
                ENSURE((y[w][k] = malloc(bytes)) != NULL);
        unsigned seed = 5;
        for (int a = 0; a < n; a++) { /* bent about y and jiggled: every cell rotated */
            const double *X = cm.node_rest + 3 * a, th = 0.7 * X[2];
            x[3 * a] = X[0] * cos(th) + X[2] * sin(th) + 0.005 * urand(&seed);
            x[3 * a + 1] = X[1] + 0.005 * urand(&seed);
            x[3 * a + 2] = -X[0] * sin(th) + X[2] * cos(th);
            m[a] = 0.01 * (1.0 + urand(&seed));
        }
        for (int i = 0; i < 3 * n; i++)
            p[i] = urand(&seed);
        for (int c = 0; c < nc; c++) /* whole batches scaled, one batch in 9 with a graded cell */
            for (int g = 0; g < 8; g++)
                kf[8 * c + g] = (c / 8) % 9 == 4 && c % 8 == 3 ? 0.5 + 0.2 * g
                                                               : 1.0 + 0.25 * ((c / 8) % 3);
        double e[2];
        for (int w = 0; w < 2; w++) {
            cs_fem fem;
            ENSURE(cs_fem_init(&fem, &cm, 2e6, 0.3, corot, 2) == 0);
            fem.wide = cs_simd_wide(w ? 512 : 256);
            fem.kf = kf;
            cs_fem_update_rotations(&fem, x);
            cs_fem_apply_K(&fem, p, y[w][0]);
            cs_fem_elastic_force(&fem, x, y[w][1], &e[w]);
            cs_fem_apply_K_mass(&fem, 2.5e-5, 1.0, m, p, y[w][2]);
            cs_fem_free(&fem);
        }
        for (int k = 0; k < 3; k++)
            ENSURE_MSG(memcmp(y[0][k], y[1][k], bytes) == 0, "%s product %d differs",
                       corot ? "corotational" : "linear", k);
        ENSURE_MSG(e[0] == e[1], "energy %.17g against %.17g", e[0], e[1]);
        free(x);
        free(p);
        free(m);
        free(kf);
        for (int w = 0; w < 2; w++)
            for (int k = 0; k < 3; k++)
                free(y[w][k]);
        cs_cubemesh_free(&cm);
    }
}

/* The V-cycle's finest product (single precision) from a multigrid built on a fem of either
 * width: the same bits, on one and two threads. */
TEST(simd_vcycle_product_same_bits_both_widths)
{
    note_width();
    cs_cubemesh cm;
    /* 4896 cells, 306 batches of 16 */
    ENSURE(cells_build(&cm, 0.05, cs_box_cells(34, 12, 12), 4896, 0) == 0);
    const int n = cm.n_nodes, nc = cm.n_cells;
    double *x = malloc(sizeof(double) * 3 * n), *inv = malloc(sizeof(double) * 9 * n);
    float *pf = malloc(sizeof(float) * 3 * n), *y[2][2];
    uint8_t *mask = calloc(3 * (size_t)n, 1);
    ENSURE(x && inv && pf && mask);
    unsigned seed = 8;
    for (int a = 0; a < n; a++) {
        const double *X = cm.node_rest + 3 * a, th = 0.8 * X[2];
        x[3 * a] = X[0] * cos(th) + X[2] * sin(th);
        x[3 * a + 1] = X[1] + 0.005 * urand(&seed);
        x[3 * a + 2] = -X[0] * sin(th) + X[2] * cos(th);
        for (int k = 0; k < 9; k++)
            inv[9 * a + k] = k % 4 == 0;
    }
    for (int i = 0; i < 3 * n; i++)
        pf[i] = (float)urand(&seed);
    for (int t = 0; t < 2; t++)
        for (int w = 0; w < 2; w++) {
            ENSURE((y[t][w] = malloc(sizeof(float) * 3 * n)) != NULL);
            cs_fem fem;
            ENSURE(cs_fem_init(&fem, &cm, 1e5, 0.3, true, t + 1) == 0);
            fem.wide = cs_simd_wide(w ? 512 : 256);
            cs_fem_update_rotations(&fem, x);
            cs_mg *mg = cs_mg_build(&cm, &fem, 1);
            ENSURE(mg != NULL);
            double *s = cs_mg_cell_scale(mg), *dg = cs_mg_node_diag(mg);
            for (int c = 0; c < nc; c++)
                s[c] = 1.0 + 0.5 * (c % 3);
            for (int a = 0; a < n; a++)
                dg[a] = 1e3;
            ENSURE(cs_mg_setup(mg, &fem, NULL, NULL, inv, mask) == 0);
            cs_mg_apply_level(mg, 0, false, pf, y[t][w]);
            cs_mg_free(mg);
            cs_fem_free(&fem);
        }
    for (int t = 0; t < 2; t++)
        ENSURE_MSG(memcmp(y[t][0], y[t][1], sizeof(float) * 3 * n) == 0,
                   "threads %d: the widths differ", t + 1);
    ENSURE(memcmp(y[0][0], y[1][0], sizeof(float) * 3 * n) == 0);
    free(x);
    free(inv);
    free(pf);
    free(mask);
    for (int t = 0; t < 2; t++)
        for (int w = 0; w < 2; w++)
            free(y[t][w]);
    cs_cubemesh_free(&cm);
}

/* A 16 × 12 × 12 cantilever (2304 cells: products and V-cycles on two threads) stepped four
 * times with multigrid at simd_width 256 and 512: the same positions and velocities, bit for
 * bit; and a width the engine does not know refused by name. */
TEST(simd_world_steps_same_bits_both_widths)
{
    note_width();
    uint64_t hash[2];
    for (int w = 0; w < 2; w++) {
        char err[256];
        cs_world_def wd = cs_world_def_default();
        wd.threads = 2;
        wd.preconditioner = CS_PRECOND_MULTIGRID;
        wd.simd_width = w ? 512 : 256;
        cs_world_t *world;
        ENSURE(cs_world_create(&wd, &world, err, sizeof err) == CS_OK);
        int32_t *ijk = cs_box_cells(16, 12, 12);
        ENSURE(ijk != NULL);
        cs_object_def d = cs_object_def_default();
        d.name = "beam";
        d.model = CS_MODEL_COROTATIONAL;
        d.material.young = 1e6;
        d.material.density = 1000;
        d.cube_size = 0.05;
        d.geometry = CS_GEOMETRY_CELLS;
        d.cells_ijk = ijk;
        d.n_cells = 16 * 12 * 12;
        cs_aabb box = {{-1e-4, -1, -1}, {1e-4, 1e3, 1e3}};
        d.fixed = &box;
        d.n_fixed = 1;
        cs_object_id id;
        ENSURE(cs_world_add_object(world, &d, &id, err, sizeof err) == CS_OK);
        free(ijk);
        for (int s = 0; s < 4; s++)
            ENSURE(cs_world_step(world) == CS_OK);
        cs_object *o = cs_world_find_internal(world, id);
        ENSURE(o->fem.wide == cs_simd_wide(wd.simd_width));
        hash[w] = cs_object_state_hash(world, id);
        cs_world_destroy(world);
    }
    ENSURE(hash[0] == hash[1]);
    char err[256] = "";
    cs_world_def wd = cs_world_def_default();
    wd.simd_width = 128;
    cs_world_t *world = NULL;
    ENSURE(cs_world_create(&wd, &world, err, sizeof err) == CS_ERR_INVALID);
    ENSURE(world == NULL);
    ENSURE_MSG(strstr(err, "simd_width") != NULL, "error: %s", err);
}
