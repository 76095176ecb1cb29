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

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX - 0.5;
}

/* The test meshes: 0 a 29 × 7 × 6 block (rows of 3 whole batches and a partial one), 1 the
 * same scrambled, 2 a 37 × 6 × 5 block with holes (single cells, and cells 8–15 of some rows:
 * whole batches without a cell), 3 a 21 × 5 × 1 slab (one layer: one part), 4 a 16 × 4 × 3
 * block (rows of whole batches: the last lane's dx = 1 corner is the row's end node). */
static const int DIMS[5][3] = {{29, 7, 6}, {29, 7, 6}, {37, 6, 5}, {21, 5, 1}, {16, 4, 3}};

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
                           (q[0] >= 8 && q[0] < 16 && (q[1] + q[2]) % 3 == 1)))
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
        ENSURE(cs_fem_lattice_product(&f[0], 1.0, 0.0, NULL, p, y[0]) == v4);
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
        /* a NaN at one node reaches only the nodes of its own cells: the node inside the box
         * with the fewest cells (on mesh 2 one next to holes, whose lanes read it too) */
        const int *d = DIMS[linear ? 0 : which];
        int bad = -1, fewest = 9;
        for (int a = 0; a < n; a++) {
            int inside = 1, cells = 0;
            for (int i = 0; i < 3; i++) {
                const long l = lround(cm.node_rest[3 * a + i] / cm.h);
                inside &= d[i] == 1 || (l > 0 && l < d[i]);
            }
            for (int c = 0; inside && c < cm.n_cells; c++)
                cells += has_node(&cm, c, a);
            if (inside && cells < fewest) {
                fewest = cells;
                bad = a;
            }
        }
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

TEST(fem_lattice_form_refuses_split_nodes_and_sparse_boxes)
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
    ENSURE(!cs_fem_lattice_product(&fem, 1.0, 0.0, NULL, p, y));
    free(p);
    free(y);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
}
