/*
 * test_lattice.c — the lattice form of the double products (fem_lattice.c): cs_fem_apply_K
 * and cs_fem_apply_K_mass with the nodal vectors as x, y, z arrays over the cells' box, on
 * blocks whose rows end in a partial batch, with the cells and nodes scrambled (rotations
 * gathered, nodes placed one by one), with holes (lanes and whole batches without a cell),
 * one layer thick (one part) and linear: equal to the dense product and to fem.c's, the same
 * bits on one and two threads, the mass term as the unfused operator's, a NaN input confined
 * to its cells; meshes the lattice form must not take (a node split in two, a sparse box).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cells_ref.h"
#include "check.h"
#include "cubemesh.h"
#include "dense_ref.h"
#include "fem.h"
#include "lattice.h"
#include "mg.h"

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX - 0.5;
}

/* The test meshes: 0 a 29 × 7 × 6 block (rows of 3 whole batches and a partial one), 1 the
 * same scrambled, 2 a 37 × 6 × 5 block with holes (single cells, and cells 16–31 of some rows:
 * whole batches without a cell), 3 a 40 × 8 × 1 slab (one layer: one part), 4 a 32 × 4 × 3
 * block (rows of whole batches of 8 and of 16: the last lane's dx = 1 corner is the row's end
 * node). Each has at least MG_LATTICE_CELLS (mg.c) cells. */
static const int DIMS[5][3] = {{29, 7, 6}, {29, 7, 6}, {37, 6, 5}, {40, 8, 1}, {32, 4, 3}};

static int test_mesh(cs_cubemesh *cm, int which)
{
    const int(*dims)[3] = DIMS;
    const int nx = dims[which][0], ny = dims[which][1], nz = dims[which][2];
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    if (!ijk)
        return -1;
    int n = 0;
    for (int c = 0; c < nx * ny * nz; c++) {
        const int32_t *q = ijk + 3 * c;
        if (which == 2 && ((q[0] * 7 + q[1] * 13 + q[2] * 29) % 9 == 4 ||
                           (q[0] >= 16 && q[0] < 32 && (q[1] + q[2]) % 3 == 1)))
            continue;
        memmove(ijk + 3 * n++, q, 3 * sizeof(int32_t));
    }
    return cells_build(cm, 0.05, ijk, n, which == 1 ? 7 : 0);
}

/* Whether node a is a corner of cell c. */
static bool has_node(const cs_cubemesh *cm, int c, int a)
{
    for (int k = 0; k < 8; k++)
        if (cm->cell_nodes[8 * c + k] == a)
            return true;
    return false;
}

/* The node inside the box (not on its faces; a one-layer box: any z) with the fewest cells:
 * on mesh 2 one next to holes, whose cell-less lanes read it too. */
static int fewest_cells_inside(const cs_cubemesh *cm, const int d[3])
{
    int bad = -1, fewest = 9;
    for (int a = 0; a < cm->n_nodes; a++) {
        int inside = 1, cells = 0;
        for (int i = 0; i < 3; i++) {
            const long l = lround(cm->node_rest[3 * a + i] / cm->h);
            inside &= d[i] == 1 || (l > 0 && l < d[i]);
        }
        for (int c = 0; inside && c < cm->n_cells; c++)
            cells += has_node(cm, c, a);
        if (inside && cells < fewest) {
            fewest = cells;
            bad = a;
        }
    }
    return bad;
}

TEST(fem_lattice_product_matches_dense_fem_and_threads)
{
    const bool v4 = __builtin_cpu_supports("x86-64-v4");
    for (int which = 0; which < 6; which++) {
        const bool linear = which == 5; /* on mesh 0 */
        cs_cubemesh cm;
        ENSURE(test_mesh(&cm, linear ? 0 : which) == 0);
        cs_fem f[2];
        ENSURE(cs_fem_init(&f[0], &cm, 3e6, 0.3, !linear, 1) == 0);
        ENSURE(cs_fem_init(&f[1], &cm, 3e6, 0.3, !linear, 2) == 0);
        f[1].threads = 2; /* small meshes run on one thread unless told */
        ENSURE_MSG(f[0].lat && f[1].lat, "mesh %d: no lattice form", which);
        const int n = cm.n_nodes;
        const size_t bytes = sizeof(double) * 3 * n;
        double *x = malloc(bytes), *p = malloc(bytes), *ref = malloc(bytes), *yf = malloc(bytes),
               *y[2] = {malloc(bytes), malloc(bytes)}, *m = malloc(sizeof(double) * n);
        unsigned seed = 40 + which;
        for (int a = 0; a < n; a++) { /* bent about y and jiggled: every cell turned apart */
            const double *X = cm.node_rest + 3 * a, th = 0.8 * X[2] + 0.3 * X[0];
            x[3 * a] = X[0] * cos(th) + X[2] * sin(th) + 0.1 * cm.h * urand(&seed);
            x[3 * a + 1] = X[1] + 0.1 * cm.h * urand(&seed);
            x[3 * a + 2] = -X[0] * sin(th) + X[2] * cos(th);
            m[a] = 1.0 + urand(&seed);
        }
        for (int i = 0; i < 3 * n; i++)
            p[i] = urand(&seed);
        for (int t = 0; t < 2; t++)
            cs_fem_update_rotations(&f[t], x);
        dense_apply(&f[0], NULL, NULL, p, ref);
        double big = 0;
        for (int i = 0; i < 3 * n; i++)
            big = fmax(big, fabs(ref[i]));
        /* the lattice form is taken where the CPU has AVX-512 */
        ENSURE(cs_fem_lattice_product(&f[0], NULL, 1.0, 0.0, NULL, p, y[0]) == v4);
        f[0].lattice = false;
        cs_fem_apply_K(&f[0], p, yf); /* fem.c's product */
        f[0].lattice = true;
        for (int t = 0; t < 2; t++) {
            cs_fem_apply_K(&f[t], p, y[t]);
            for (int i = 0; i < 3 * n; i++) {
                ENSURE_MSG(fabs(y[t][i] - ref[i]) <= 1e-13 * big, "mesh %d threads %d dof %d",
                           which, t + 1, i);
                ENSURE_MSG(fabs(y[t][i] - yf[i]) <= 1e-13 * big, "mesh %d: fem.c dof %d", which, i);
            }
        }
        ENSURE_MSG(memcmp(y[0], y[1], bytes) == 0, "mesh %d: threads differ", which);
        /* the step's operator: the unfused one's bits */
        const double kc = 2.5e-4, mc = 1.7;
        for (int i = 0; i < n; i++)
            for (int a = 0; a < 3; a++)
                yf[3 * i + a] = kc * y[0][3 * i + a] + mc * m[i] * p[3 * i + a];
        for (int t = 0; t < 2; t++) {
            cs_fem_apply_K_mass(&f[t], kc, mc, m, p, y[t]);
            ENSURE_MSG(memcmp(y[t], yf, bytes) == 0, "mesh %d threads %d: K + mass", which, t + 1);
        }
        /* a NaN at one node reaches only the nodes of its own cells */
        const int bad = fewest_cells_inside(&cm, DIMS[linear ? 0 : which]);
        ENSURE(bad >= 0);
        memcpy(ref, y[0], bytes);
        cs_fem_apply_K(&f[1], p, ref);
        p[3 * bad + 1] = NAN;
        cs_fem_apply_K(&f[1], p, y[1]);
        for (int a = 0; a < n; a++) {
            bool near = false;
            for (int c = 0; c < cm.n_cells && !near; c++)
                near = has_node(&cm, c, a) && has_node(&cm, c, bad);
            for (int i = 0; !near && i < 3; i++)
                ENSURE_MSG(y[1][3 * a + i] == ref[3 * a + i], "mesh %d: NaN reached node %d",
                           which, a);
        }
        free(x);
        free(p);
        free(ref);
        free(yf);
        free(y[0]);
        free(y[1]);
        free(m);
        cs_fem_free(&f[0]);
        cs_fem_free(&f[1]);
        cs_cubemesh_free(&cm);
    }
}

TEST(fem_lattice_form_refuses_split_twin_and_doubled_nodes_and_sparse_boxes)
{
    cs_cubemesh cm;
    ENSURE(test_mesh(&cm, 0) == 0);
    cs_fem fem;
    ENSURE(cs_fem_init(&fem, &cm, 3e6, 0.3, true, 1) == 0);
    ENSURE(fem.lat);
    /* one corner of one cell made a node of its own (as fracture splits them) */
    int32_t *keep = cm.cell_nodes, *split = malloc(sizeof(int32_t) * 8 * cm.n_cells);
    memcpy(split, keep, sizeof(int32_t) * 8 * cm.n_cells);
    split[8 * 100 + 6] = cm.n_nodes;
    cm.cell_nodes = split;
    cm.n_nodes++;
    cs_fem_lattice *lt = fem.lat; /* not NULL: the build must clear it */
    ENSURE(cs_fem_lattice_build(&fem, &cm, &lt) == 0);
    ENSURE(lt == NULL);
    cm.cell_nodes = keep;
    cm.n_nodes--;
    free(split);
    /* two cells at one lattice index (as a coarse level across a crack can have), here cell 1
     * made a copy of cell 0: every node still placed, but one cell would be lost */
    int32_t *ijk0 = cm.cell_ijk, *twin = malloc(sizeof(int32_t) * 3 * cm.n_cells),
            *tn = malloc(sizeof(int32_t) * 8 * cm.n_cells);
    memcpy(twin, ijk0, sizeof(int32_t) * 3 * cm.n_cells);
    memcpy(tn, keep, sizeof(int32_t) * 8 * cm.n_cells);
    memcpy(twin + 3, twin, 3 * sizeof(int32_t));
    memcpy(tn + 8, tn, 8 * sizeof(int32_t));
    cm.cell_ijk = twin;
    cm.cell_nodes = tn;
    lt = fem.lat;
    ENSURE(cs_fem_lattice_build(&fem, &cm, &lt) == 0);
    ENSURE(lt == NULL);
    cm.cell_ijk = ijk0;
    cm.cell_nodes = keep;
    free(twin);
    free(tn);
    /* a node at two places and one without a cell: cell 0's corner 0 (the block's corner,
     * no other cell's) made its corner 6; every place still holds one node */
    tn = malloc(sizeof(int32_t) * 8 * cm.n_cells);
    memcpy(tn, keep, sizeof(int32_t) * 8 * cm.n_cells);
    tn[0] = tn[6];
    cm.cell_nodes = tn;
    lt = fem.lat;
    ENSURE(cs_fem_lattice_build(&fem, &cm, &lt) == 0);
    ENSURE(lt == NULL);
    cm.cell_nodes = keep;
    free(tn);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
    /* a diagonal line of 40 cells: its box would be 40³ */
    int32_t *ijk = malloc(sizeof(int32_t) * 3 * 40);
    for (int c = 0; c < 40; c++)
        ijk[3 * c] = ijk[3 * c + 1] = ijk[3 * c + 2] = c;
    ENSURE(cells_build(&cm, 0.05, ijk, 40, 0) == 0);
    ENSURE(cs_fem_init(&fem, &cm, 3e6, 0.3, true, 1) == 0);
    ENSURE(fem.lat == NULL);
    double *p = calloc(3 * (size_t)cm.n_nodes, sizeof(double)), *y = malloc(sizeof(double) * 3 * cm.n_nodes);
    ENSURE(!cs_fem_lattice_product(&fem, NULL, 1.0, 0.0, NULL, p, y));
    free(p);
    free(y);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
}

/* ------------------------------------------------------------------ the V-cycle's passes */

/* The V-cycle's level-0 passes on the lattice (mg_lattice.c) against mg.c's slots and node
 * pass (cs_mg_set_lattice false) on the test meshes and on a holey, scrambled 41 × 9 × 7 block
 * (rows of two batches of 16 and a partial one; two threads): y = A x, the residual (exactly 0
 * at held dofs), a Chebyshev step (held dofs exactly 0) and whole V-cycles (whose last step
 * also writes x in double) within float rounding; on the large block the same bits on one and
 * two threads. */
static int mg_case(int which, int threads, float *keep, double *keepz, size_t *nkeep)
{
    cs_cubemesh cm;
    int32_t *ijk = NULL;
    int n = 0;
    if (which < 5) {
        if (test_mesh(&cm, which) != 0)
            return -1;
    } else {
        ijk = cs_box_cells(41, 9, 7);
        for (int c = 0; c < 41 * 9 * 7; c++) {
            const int32_t *q = ijk + 3 * c;
            if ((q[0] * 5 + q[1] * 11 + q[2] * 23) % 13 == 6)
                continue;
            memmove(ijk + 3 * n++, q, 3 * sizeof(int32_t));
        }
        if (cells_build(&cm, 0.04, ijk, n, 3) != 0)
            return -1;
    }
    cs_fem fem;
    if (cs_fem_init(&fem, &cm, 2e6, 0.3, true, threads) != 0) {
        cs_cubemesh_free(&cm);
        return -1;
    }
    const int nn = cm.n_nodes, nc = cm.n_cells;
    double *x = malloc(sizeof(double) * 3 * nn), *inv = malloc(sizeof(double) * 9 * nn),
           *r = malloc(sizeof(double) * 3 * nn), *z[2] = {malloc(sizeof(double) * 3 * nn),
                                                          malloc(sizeof(double) * 3 * nn)};
    float *xf = malloc(sizeof(float) * 3 * nn), *bf = malloc(sizeof(float) * 3 * nn),
          *y[2][3] = {{NULL}};
    uint8_t *mask = calloc(3 * (size_t)nn, 1);
    unsigned seed = 77 + which;
    for (int a = 0; a < nn; a++) {
        const double *X = cm.node_rest + 3 * a, th = 0.9 * X[2] + 0.2 * X[1];
        x[3 * a] = X[0] * cos(th) + X[2] * sin(th) + 0.05 * cm.h * urand(&seed);
        x[3 * a + 1] = X[1] + 0.05 * cm.h * urand(&seed);
        x[3 * a + 2] = -X[0] * sin(th) + X[2] * cos(th);
    }
    cs_fem_update_rotations(&fem, x);
    cs_mg *mg = cs_mg_build(&cm, &fem, 1);
    int bad = mg ? 0 : -1;
    if (mg) {
        double *s = cs_mg_cell_scale(mg), *dg = cs_mg_node_diag(mg);
        for (int c = 0; c < nc; c++)
            s[c] = exp(2.0 * (urand(&seed) + 0.5));
        for (int a = 0; a < nn; a++) {
            dg[a] = 40.0 * (1.0 + urand(&seed));
            const double o = 1e-5 * urand(&seed);
            for (int j = 0; j < 9; j++)
                inv[9 * a + j] = j % 4 == 0 ? 1e-3 * (1.0 + 0.3 * urand(&seed)) : o;
            for (int i = 0; i < 3; i++) /* every held pattern */
                mask[3 * a + i] = (a % 9 < 8 && (a % 9) >> i & 1) || a % 23 == 0;
        }
        for (int d = 0; d < 3 * nn; d++) {
            xf[d] = (float)urand(&seed);
            bf[d] = (float)urand(&seed);
            r[d] = urand(&seed);
        }
        bad = cs_mg_setup(mg, &fem, NULL, NULL, inv, mask) != 0;
        bad += !(cs_mg_level_layout(mg, 0) & CS_MG_LATTICE);
        const float c = 0.37f;
        for (int on = 1; on >= 0 && !bad; on--) {
            cs_mg_set_lattice(mg, on);
            for (int k = 0; k < 3; k++)
                y[on][k] = malloc(sizeof(float) * 3 * nn);
            cs_mg_apply_level(mg, 0, false, xf, y[on][0]);
            cs_mg_residual_level(mg, 0, xf, bf, y[on][1]);
            memcpy(y[on][2], xf, sizeof(float) * 3 * nn);
            cs_mg_cheb_step_level(mg, 0, bf, y[on][2], NULL, 0.0f, c, true);
            cs_mg_vcycle(mg, r, z[on]);
        }
        cs_mg_set_lattice(mg, true);
        for (int k = 0; k < 3 && !bad; k++) {
            float big = 0;
            for (int d = 0; d < 3 * nn; d++)
                big = fmaxf(big, fabsf(y[0][k][d]));
            for (int d = 0; d < 3 * nn; d++) {
                bad += !(fabsf(y[1][k][d] - y[0][k][d]) <= 4e-6f * big);
                if (k > 0 && mask[d])
                    bad += y[1][k][d] != 0.0f;
            }
        }
        double zb = 0;
        for (int d = 0; d < 3 * nn && !bad; d++)
            zb = fmax(zb, fabs(z[0][d]));
        for (int d = 0; d < 3 * nn && !bad; d++)
            bad += !(fabs(z[1][d] - z[0][d]) <= 1e-4 * zb) || (mask[d] && z[1][d] != 0.0);
        if (which == 2 && !bad) {
            /* a NaN at one node reaches only the nodes of its own cells */
            const int nan_at = fewest_cells_inside(&cm, DIMS[2]);
            xf[3 * nan_at] = NAN;
            cs_mg_apply_level(mg, 0, false, xf, y[0][0]);
            for (int a = 0; a < nn; a++) {
                bool near = false;
                for (int cc = 0; cc < nc && !near; cc++)
                    near = has_node(&cm, cc, a) && has_node(&cm, cc, nan_at);
                for (int i = 0; !near && i < 3; i++)
                    bad += !isfinite(y[0][0][3 * a + i]);
            }
        }
        if (keep && !bad) {
            for (int k = 0; k < 3; k++)
                memcpy(keep + 3 * (size_t)nn * k, y[1][k], sizeof(float) * 3 * nn);
            memcpy(keepz, z[1], sizeof(double) * 3 * nn);
            *nkeep = 3 * (size_t)nn;
        }
    }
    for (int on = 0; on < 2; on++)
        for (int k = 0; k < 3; k++)
            free(y[on][k]);
    cs_mg_free(mg);
    free(x);
    free(inv);
    free(r);
    free(z[0]);
    free(z[1]);
    free(xf);
    free(bf);
    free(mask);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
    return bad;
}

TEST(mg_lattice_passes_match_slots_and_threads)
{
    for (int which = 0; which < 5; which++)
        ENSURE_MSG(mg_case(which, 1, NULL, NULL, NULL) == 0, "mesh %d", which);
    const size_t cap = 3 * 42 * 10 * 8;
    float *keep[2] = {malloc(sizeof(float) * 3 * cap), malloc(sizeof(float) * 3 * cap)};
    double *kz[2] = {malloc(sizeof(double) * cap), malloc(sizeof(double) * cap)};
    size_t nk[2] = {0, 0};
    for (int t = 0; t < 2; t++)
        ENSURE_MSG(mg_case(5, t + 1, keep[t], kz[t], &nk[t]) == 0, "large block, %d threads",
                   t + 1);
    ENSURE(nk[0] == nk[1] && nk[0] > 0);
    ENSURE_MSG(memcmp(keep[0], keep[1], sizeof(float) * 3 * nk[0]) == 0,
               "the passes differ between 1 and 2 threads");
    ENSURE_MSG(memcmp(kz[0], kz[1], sizeof(double) * nk[0]) == 0,
               "the V-cycle differs between 1 and 2 threads");
    for (int t = 0; t < 2; t++) {
        free(keep[t]);
        free(kz[t]);
    }
}
