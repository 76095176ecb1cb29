/*
 * test_fem_setup.c — what an implicit step prepares before its solve, against the plain
 * definitions: the diagonal blocks Σ_cells R K_kk Rᵀ (node pass, corner-block formula) equal
 * the blocks of the dense 24×24 matrices for plain, equal-factor and graded cells and with
 * inactive cells, identically on 1 and 2 threads; and block Jacobi in one pass
 * (cs_fem_precond_blocks) is those blocks scaled, shifted and inverted, bit for bit.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubemesh.h"
#include "fem.h"
#include "lattice.h"
#include "solver.h"

static double urand(unsigned *seed)
{
    return rand_r(seed) / (double)RAND_MAX;
}

/* The reference: per cell and corner Kk = Σ_g kf_g K_g[kk] (K without kf), R Kk Rᵀ summed. */
static void dense_blocks(const cs_fem *fem, const double *kf, const uint8_t *active,
                         double *blocks)
{
    memset(blocks, 0, sizeof(double) * 9 * (size_t)fem->n_nodes);
    for (int c = 0; c < fem->n_cells; c++) {
        if (active && !active[c])
            continue;
        const double *R = fem->R + 9 * c;
        for (int k = 0; k < 8; k++) {
            double Kk[9];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++) {
                    const int at = (3 * k + i) * 24 + 3 * k + j;
                    double s = 0;
                    for (int g = 0; g < 8; g++)
                        s += (kf ? kf[8 * c + g] : 1.0) * fem->Kg[576 * g + at];
                    Kk[3 * i + j] = s;
                }
            double *B = blocks + 9 * fem->cell_nodes[8 * c + k];
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    for (int a = 0; a < 3; a++)
                        for (int b = 0; b < 3; b++)
                            B[3 * i + j] += R[3 * i + a] * Kk[3 * a + b] * R[3 * j + b];
        }
    }
}

TEST(fem_diag_blocks_match_dense_blocks)
{
    const int nx = 16, ny = 12, nz = 11; /* 2112 cells: two threads really run */
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    cs_cubemesh cm;
    char err[256];
    const double origin[3] = {0, 0, 0};
    ENSURE(ijk && cs_cubemesh_build(&cm, 0.05, origin, ijk, nx * ny * nz, err, sizeof err) == 0);
    free(ijk);
    ENSURE(cm.n_cells >= CS_FEM_PARALLEL_CELLS);
    cs_fem f1, f2;
    ENSURE(cs_fem_init(&f1, &cm, 2e6, 0.3, true, 1) == 0);
    ENSURE(cs_fem_init(&f2, &cm, 2e6, 0.3, true, 2) == 0);
    ENSURE(f2.threads == 2);
    const int n = cm.n_nodes, nc = cm.n_cells;
    double *x = malloc(sizeof(double) * 3 * n), *kf = malloc(sizeof(double) * 8 * nc);
    double *b1 = malloc(sizeof(double) * 9 * n), *b2 = malloc(sizeof(double) * 9 * n),
           *ref = malloc(sizeof(double) * 9 * n), *p1 = malloc(sizeof(double) * 9 * n),
           *p2 = malloc(sizeof(double) * 9 * n), *m = malloc(sizeof(double) * n),
           *md = malloc(sizeof(double) * n);
    uint8_t *active = malloc((size_t)nc), *pin = malloc((size_t)n);
    ENSURE(x && kf && b1 && b2 && ref && p1 && p2 && m && md && active && pin);
    unsigned seed = 9;
    /* every cell rotated differently: a twist about z plus noise */
    for (int i = 0; i < n; i++) {
        const double *p = cm.node_rest + 3 * i, t = 1.5 * p[2];
        x[3 * i] = cos(t) * p[0] - sin(t) * p[1] + 0.01 * urand(&seed);
        x[3 * i + 1] = sin(t) * p[0] + cos(t) * p[1] + 0.01 * urand(&seed);
        x[3 * i + 2] = p[2] + 0.01 * urand(&seed);
    }
    cs_fem_update_rotations(&f1, x);
    cs_fem_update_rotations(&f2, x);
    /* factors: a third plain (1), a third equal per cell, a third graded */
    for (int c = 0; c < nc; c++) {
        const double e = 0.5 + 2 * urand(&seed);
        for (int g = 0; g < 8; g++)
            kf[8 * c + g] = c % 3 == 0 ? 1.0 : c % 3 == 1 ? e : 0.5 + 2 * urand(&seed);
        active[c] = c % 7 != 3;
    }
    for (int i = 0; i < n; i++) {
        m[i] = 0.1 + urand(&seed);
        md[i] = urand(&seed);
        pin[i] = i % 11 == 0;
    }
    for (int pass = 0; pass < 4; pass++) {
        const double *w = pass == 0 ? NULL : kf;
        const uint8_t *act = pass == 3 ? active : NULL;
        f1.cell_active = f2.cell_active = act;
        cs_fem_diag_blocks_w(&f1, w, b1);
        cs_fem_diag_blocks_w(&f2, w, b2);
        dense_blocks(&f1, w, act, ref);
        ENSURE_MSG(memcmp(b1, b2, sizeof(double) * 9 * n) == 0, "pass %d: 1 and 2 threads differ",
                   pass);
        double scale = 0, e = 0;
        for (int d = 0; d < 9 * n; d++)
            scale = fmax(scale, fabs(ref[d]));
        for (int d = 0; d < 9 * n; d++)
            e = fmax(e, fabs(b1[d] - ref[d]));
        ENSURE_MSG(e < 1e-13 * scale, "pass %d: error %g of %g", pass, e, scale);
        /* block Jacobi of kcoef·K + d_i (md only in passes 1 and 3) in one pass */
        const double kcoef = 3e-4;
        const cs_fem_node_terms t = {m, pass % 2 ? md : NULL, pin, 1.5, 0.25, 7.0};
        cs_fem_precond_blocks(&f1, w, kcoef, &t, p1);
        cs_fem_precond_blocks(&f2, w, kcoef, &t, p2);
        ENSURE_MSG(memcmp(p1, p2, sizeof(double) * 9 * n) == 0,
                   "pass %d: preconditioner, 1 and 2 threads differ", pass);
        double worst = 0;
        for (int i = 0; i < n; i++) {
            double *B = b1 + 9 * (size_t)i, A[9];
            const double d = t.mcoef * m[i] + (t.md ? t.cmcoef * md[i] : 0.0) + (pin[i] ? t.pk : 0.0);
            for (int k = 0; k < 9; k++)
                B[k] *= kcoef;
            for (int a = 0; a < 3; a++)
                B[4 * a] += d;
            cs_invert_block(B);
            ENSURE_MSG(memcmp(B, p1 + 9 * (size_t)i, sizeof(double) * 9) == 0,
                       "pass %d, node %d: not the blocks scaled, shifted and inverted", pass, i);
            /* against the dense blocks: (kcoef·ref + d I) P = I */
            for (int k = 0; k < 9; k++)
                A[k] = kcoef * ref[9 * (size_t)i + k] + (k % 4 == 0 ? d : 0.0);
            for (int r = 0; r < 3; r++)
                for (int c = 0; c < 3; c++) {
                    double sum = 0;
                    for (int k = 0; k < 3; k++)
                        sum += A[3 * r + k] * p1[9 * (size_t)i + 3 * k + c];
                    worst = fmax(worst, fabs(sum - (r == c)));
                }
        }
        ENSURE_MSG(worst < 1e-9, "pass %d: (kcoef K + d) P - I up to %g", pass, worst);
    }
    f1.cell_active = f2.cell_active = NULL;
    /* The plain case's blocks (8 nodes side by side, fem.c precond_blocks_plain) where the
     * inversion's sign and branch matter: negative definite blocks (kcoef and mcoef < 0: det and
     * the diagonal negative) and, with kcoef = 0 and some masses 0, zero blocks (the diagonal
     * fallback, 1 on the diagonal) among pure mass ones; 1 and 2 threads, bit for bit the blocks
     * scaled, shifted and inverted one by one. */
    uint8_t *all = malloc((size_t)n);
    ENSURE(all);
    for (int i = 0; i < n; i++) {
        md[i] = i % 5 == 0 ? 0.0 : m[i];
        all[i] = 1; /* every node pinned */
    }
    /* and singular blocks with a nonzero diagonal: d = −kcoef (α − β) leaves a corner node
     * (one cell) kcoef β v vᵀ, of rank 1 (the fallback's inverted diagonal) */
    const double kc = 3e-4, sing = -kc * (f1.K[0] - f1.K[1]);
    const struct {
        double kcoef;
        cs_fem_node_terms t;
    } edge[3] = {{-3e-4, {m, NULL, pin, -1.5, 0, -7.0}},
                 {0.0, {md, NULL, pin, 1.5, 0, 0.0}},
                 {kc, {m, NULL, all, 0.0, 0, sing}}};
    cs_fem_diag_blocks_w(&f1, NULL, ref);
    for (int pass = 0; pass < 3; pass++) {
        cs_fem_precond_blocks(&f1, NULL, edge[pass].kcoef, &edge[pass].t, p1);
        cs_fem_precond_blocks(&f2, NULL, edge[pass].kcoef, &edge[pass].t, p2);
        ENSURE_MSG(memcmp(p1, p2, sizeof(double) * 9 * n) == 0, "edge %d: 1 and 2 threads differ",
                   pass);
        int fallback = 0;
        for (int i = 0; i < n; i++) {
            const cs_fem_node_terms *t = &edge[pass].t;
            double B[9];
            const double d = t->mcoef * t->m[i] + (t->pin[i] ? t->pk : 0.0);
            for (int k = 0; k < 9; k++)
                B[k] = ref[9 * (size_t)i + k] * edge[pass].kcoef;
            for (int a = 0; a < 3; a++)
                B[4 * a] += d;
            fallback += d == 0.0 && pass == 1;
            cs_invert_block(B);
            fallback += pass == 2 && B[1] == 0 && B[2] == 0 && B[5] == 0 && B[0] != 1.0;
            ENSURE_MSG(memcmp(B, p1 + 9 * (size_t)i, sizeof B) == 0,
                       "edge %d, node %d: not the block scaled, shifted and inverted", pass, i);
        }
        ENSURE_MSG(pass == 0 || fallback > 0, "edge %d: no singular block", pass);
    }
    free(all);
    /* no factors (diag_node's plain loop) against factors all 1 (its general loop): f·β = β */
    for (int d = 0; d < 8 * nc; d++)
        kf[d] = 1.0;
    cs_fem_diag_blocks_w(&f1, NULL, b1);
    cs_fem_diag_blocks_w(&f1, kf, b2);
    ENSURE_MSG(memcmp(b1, b2, sizeof(double) * 9 * n) == 0, "plain and unit factors differ");
    free(x);
    free(kf);
    free(b1);
    free(b2);
    free(ref);
    free(p1);
    free(p2);
    free(m);
    free(md);
    free(pin);
    free(active);
    cs_fem_free(&f1);
    cs_fem_free(&f2);
    cs_cubemesh_free(&cm);
}
