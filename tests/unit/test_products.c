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
#include "cubemesh.h"
#include "fem.h"
#include "mg.h"

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX - 0.5;
}

/* An nx × ny × nz block of cubes of edge h, i fastest; scrambled: the cells in a random order. */
static int block(cs_cubemesh *cm, int nx, int ny, int nz, double h, bool scrambled)
{
    const int n = nx * ny * nz;
    int32_t *ijk = malloc(sizeof(int32_t) * 3 * (size_t)n);
    if (!ijk)
        return -1;
    for (int c = 0, k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++, c++) {
                ijk[3 * c] = i;
                ijk[3 * c + 1] = j;
                ijk[3 * c + 2] = k;
            }
    unsigned seed = 5;
    for (int c = n - 1; scrambled && c > 0; c--) {
        const int d = rand_r(&seed) % (c + 1);
        for (int a = 0; a < 3; a++) {
            const int32_t t = ijk[3 * c + a];
            ijk[3 * c + a] = ijk[3 * d + a];
            ijk[3 * d + a] = t;
        }
    }
    char err[128];
    const double origin[3] = {0, 0, 0};
    const int rc = cs_cubemesh_build(cm, h, origin, ijk, n, err, sizeof err);
    free(ijk);
    return rc;
}

/* y = Σ_c R_c K_c R_cᵀ p over the active cells with the dense 24×24 matrices (K_c = Σ_g kf_g
 * K_g, or K without kf). */
static void dense_apply(const cs_fem *fem, const double *kf, const uint8_t *act, const double *p,
                        double *y)
{
    memset(y, 0, sizeof(double) * 3 * fem->n_nodes);
    for (int c = 0; c < fem->n_cells; c++) {
        if (act && !act[c])
            continue;
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        double Ke[576], u[24], ku[24];
        for (int i = 0; i < 576; i++) {
            Ke[i] = kf ? 0.0 : fem->K[i];
            for (int g = 0; kf && g < 8; g++)
                Ke[i] += kf[8 * c + g] * fem->Kg[576 * g + i];
        }
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++) {
                const double *d = p + 3 * nd[k];
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
            }
        for (int i = 0; i < 24; i++) {
            ku[i] = 0;
            for (int j = 0; j < 24; j++)
                ku[i] += Ke[24 * i + j] * u[j];
        }
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++)
                y[3 * nd[k] + i] += R[3 * i] * ku[3 * k] + R[3 * i + 1] * ku[3 * k + 1] +
                                    R[3 * i + 2] * ku[3 * k + 2];
    }
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
            cs_mg_apply_level(mg, 0, false, pf, y[t]);
            if (t == 1) {
                cs_mg_apply_level(mg, 0, true, pf, y[2]);
                ENSURE_MSG(memcmp(y[1], y[2], sizeof(float) * 3 * n) == 0,
                           "the portable gathers give another product");
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
