/*
 * test_threads.c — the solver's and the V-cycle's fused passes (wave 7, "threads"): results
 * do not depend on the thread count, bit for bit, on sizes where the passes really split
 * (vectors of several CS_DOT_BLOCK blocks; a block whose first two multigrid levels run on
 * two threads). cs_cg_guess's threaded pass arms and disarms as the one-thread pass does
 * (also when the one differing value is in the second thread's half); warm-started solves
 * reach the tolerance (checked against b − A x computed here) with the same iterations and
 * bits on 1 and 2 threads; the V-cycle, whose input conversion to single precision is fused
 * into the first smoothing step and whose output conversion into the last, rounds its input
 * to float once (V(r) = V(float(r)) bit for bit), returns float values, keeps held dofs at
 * zero, is exactly homogeneous (V(2r) = 2 V(r)) and bit-identical on 1 and 2 threads.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "fem.h"
#include "lattice.h"
#include "mg.h"
#include "mk_op.h"
#include "solver.h"
#include "world_internal.h"

static double urand(uint64_t *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return (double)(*s >> 11) / 9007199254740992.0 - 0.5;
}

/* ---------------------------------------------------------------- warm start history */

TEST(threads_cg_guess_matches_one_thread)
{
    const int n = 3 * 6000; /* 5 dot blocks: the pass splits */
    cs_cg_work w[2];
    double *v = malloc(sizeof(double) * n), *x[2];
    ENSURE(v != NULL);
    for (int t = 0; t < 2; t++) {
        ENSURE(cs_cg_work_init(&w[t], n) == 0);
        w[t].threads = t + 1;
        x[t] = malloc(sizeof(double) * n);
        ENSURE(x[t] != NULL);
    }
    uint64_t seed = 7;
    for (int i = 0; i < n; i++)
        v[i] = urand(&seed);
    /* step k starts from v_k; a recorded end equal to the next start arms the history, an end
     * that differs in one value (the last: the second thread's half) does not */
    const int expect[6] = {0, 1, 1, 0, 1, 1};
    for (int k = 0; k < 6; k++) {
        int rc[2];
        for (int t = 0; t < 2; t++)
            rc[t] = cs_cg_guess(&w[t], v, x[t]);
        ENSURE_MSG(rc[0] == expect[k] && rc[1] == expect[k], "step %d: armed %d / %d, want %d",
                   k, rc[0], rc[1], expect[k]);
        ENSURE(memcmp(x[0], x[1], sizeof(double) * n) == 0);
        ENSURE(memcmp(x[0], v, sizeof(double) * n) == 0); /* the guess is v itself */
        ENSURE(w[0].ndirs == w[1].ndirs);
        for (int j = 0; j < w[0].ndirs; j++)
            ENSURE(memcmp(w[0].dirs[j], w[1].dirs[j], sizeof(double) * n) == 0);
        for (int i = 0; i < n; i++) /* the next step's start */
            v[i] += 0.01 * sin(0.001 * i + k);
        if (k == 2)
            v[n - 1] += 1e-3; /* the next start differs from this end in one value */
        for (int t = 0; t < 2; t++) {
            double *end = malloc(sizeof(double) * n);
            ENSURE(end != NULL);
            memcpy(end, v, sizeof(double) * n);
            if (k == 2)
                end[n - 1] -= 1e-3;
            cs_cg_record(&w[t], end);
            free(end);
        }
    }
    for (int t = 0; t < 2; t++) {
        cs_cg_work_free(&w[t]);
        free(x[t]);
    }
    free(v);
}

/* ---------------------------------------------------------------- warm-started solves */

/* y = (m I + k L) x per coordinate (L the path Laplacian over the nodes, 3 dofs each), with a
 * parallel loop so that the operator itself also runs on the solve's threads. */
typedef struct chain {
    int n, threads;
    double m, k;
} chain;

static void chain_apply(void *ctx, const double *x, double *y)
{
    const chain *c = ctx;
#pragma omp parallel for num_threads(c->threads) schedule(static)
    for (int i = 0; i < c->n; i++) {
        double s = c->m * x[i];
        if (i >= 3)
            s += c->k * (x[i] - x[i - 3]);
        if (i + 3 < c->n)
            s += c->k * (x[i] - x[i + 3]);
        y[i] = s;
    }
}

TEST(threads_warm_started_solves_bit_identical)
{
    const int n = 3 * 7000;
    double *b = malloc(sizeof(double) * n), *inv = malloc(sizeof(double) * 9 * (n / 3));
    double *v[2], *x[2], *ax = malloc(sizeof(double) * n);
    uint8_t *mask = malloc(n);
    ENSURE(b && inv && ax && mask);
    for (int i = 0; i < n; i++)
        mask[i] = i < 6 || i % 997 == 0; /* two held nodes and scattered held dofs */
    for (int t = 0; t < 2; t++) {
        v[t] = calloc(n, sizeof(double));
        x[t] = malloc(sizeof(double) * n);
        ENSURE(v[t] && x[t]);
    }
    cs_cg_work w[2];
    chain c[2];
    for (int t = 0; t < 2; t++) {
        ENSURE(cs_cg_work_init(&w[t], n) == 0);
        w[t].threads = t + 1;
        c[t] = (chain){n, t + 1, 1.0, 40.0};
    }
    for (int i = 0; i < n / 3; i++) { /* block Jacobi: the operator's diagonal, inverted */
        memset(inv + 9 * i, 0, 9 * sizeof(double));
        const double dg = 1.0 + 40.0 * ((i > 0) + (i + 1 < n / 3));
        for (int a = 0; a < 3; a++)
            inv[9 * i + 4 * a] = 1.0 / dg;
    }
    const double tol = 1e-8;
    for (int step = 0; step < 6; step++) {
        for (int i = 0; i < n; i++) /* a slowly moving load */
            b[i] = sin(0.002 * i + 0.3 * step) + 0.1 * (i % 3);
        cs_cg_result r[2];
        for (int t = 0; t < 2; t++) {
            cs_cg_guess(&w[t], v[t], x[t]);
            for (int i = 0; i < n; i++)
                if (mask[i])
                    x[t][i] = 0.0;
            r[t] = cs_pcg(&w[t], chain_apply, &c[t], inv, mask, b, x[t], tol, 2000, t + 1);
            memcpy(v[t], x[t], sizeof(double) * n);
            cs_cg_record(&w[t], v[t]);
        }
        ENSURE(r[0].converged && r[1].converged);
        ENSURE_MSG(r[0].iterations == r[1].iterations && r[0].relres == r[1].relres,
                   "step %d: %d / %d iterations", step, r[0].iterations, r[1].iterations);
        ENSURE(memcmp(x[0], x[1], sizeof(double) * n) == 0);
        /* the tolerance, measured here: ‖b − A x‖ ≤ tol ‖b‖ over the free dofs */
        chain_apply(&c[0], x[0], ax);
        double rr = 0, bb = 0;
        for (int i = 0; i < n; i++)
            if (!mask[i]) {
                rr += (b[i] - ax[i]) * (b[i] - ax[i]);
                bb += b[i] * b[i];
            }
        ENSURE_MSG(sqrt(rr) <= 1.01 * tol * sqrt(bb), "step %d: ‖r‖/‖b‖ = %.3g", step,
                   sqrt(rr / bb));
        for (int i = 0; i < n; i++)
            if (mask[i])
                ENSURE(x[0][i] == 0.0);
        if (step >= 2)
            printf("    step %d: %d iterations (warm-started)\n", step, r[0].iterations);
    }
    for (int t = 0; t < 2; t++) {
        cs_cg_work_free(&w[t]);
        free(v[t]);
        free(x[t]);
    }
    free(b);
    free(inv);
    free(ax);
    free(mask);
}

/* ---------------------------------------------------------------- the V-cycle */

/* The V-cycle of a 42×20×20 cantilever (16800 cubes: levels 0 and 1 at 2048 cubes or more run
 * on the world's threads) applied to r, 2r and float(r) into z[0..2]. 0 on success. */
static int vcycles(int threads, double *z[3], int *n3_out, uint8_t **mask_out, int *lv1_nodes,
                   double **x_out)
{
    char err[256];
    cs_world_def wd = cs_world_def_default();
    wd.threads = threads;
    cs_world_t *w;
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK)
        return -1;
    const int nx = 42, ny = 20, nz = 20;
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    cs_object_def d = cs_object_def_default();
    d.name = "beam";
    d.model = CS_MODEL_COROTATIONAL;
    d.material.young = 1e6;
    d.material.density = 1000;
    d.cube_size = 0.05;
    d.cells_ijk = ijk;
    d.n_cells = nx * ny * nz;
    cs_aabb box = {{-1e-4, -1, -1}, {1e-4, 1e3, 1e3}};
    d.fixed = &box;
    d.n_fixed = 1;
    cs_object_id id;
    int rc = ijk ? cs_world_add_object(w, &d, &id, err, sizeof err) : -1;
    free(ijk);
    cs_mg *mg = NULL;
    double *inv = NULL, *r = NULL;
    uint8_t *mask = NULL;
    if (rc != CS_OK)
        goto out;
    rc = -1;
    for (int s = 0; s < 3; s++) /* a bent state: rotations differ from cell to cell */
        if (cs_world_step(w) != CS_OK)
            goto out;
    cs_object *o = cs_world_find_internal(w, id);
    const int n3 = 3 * o->n;
    *x_out = malloc(sizeof(double) * n3); /* the stepped positions (the fem's fused passes) */
    if (!*x_out)
        goto out;
    memcpy(*x_out, o->x, sizeof(double) * n3);
    mk_opctx c = {o, 1.0 / 3600};
    inv = malloc(sizeof(double) * 9 * o->n);
    r = malloc(sizeof(double) * n3);
    mask = malloc(n3);
    mg = cs_mg_build(&o->cm, &o->fem, o->topology_version);
    if (!inv || !r || !mask || !mg || cs_mg_levels(mg) < 3)
        goto out;
    *lv1_nodes = cs_mg_level_nodes(mg, 1);
    mk_op_inv_diag(&c, inv);
    uint64_t seed = 99;
    for (int q = 0; q < n3; q++) /* the held dofs and 5 % more */
        mask[q] = o->mask[q] || urand(&seed) > 0.45;
    double *s = cs_mg_cell_scale(mg), *dg = cs_mg_node_diag(mg);
    for (int e = 0; e < o->cm.n_cells; e++)
        s[e] = c.kc;
    for (int i = 0; i < o->n; i++)
        dg[i] = o->m[i];
    if (cs_mg_setup(mg, &o->fem, mk_op, &c, inv, mask) != 0)
        goto out;
    for (int q = 0; q < n3; q++)
        r[q] = mask[q] ? 0.0 : urand(&seed) * (1.0 + 1e-3 * q); /* not floats */
    for (int k = 0; k < 3; k++)
        z[k] = malloc(sizeof(double) * n3);
    if (!z[0] || !z[1] || !z[2])
        goto out;
    cs_mg_vcycle(mg, r, z[0]);
    for (int q = 0; q < n3; q++)
        r[q] *= 2;
    cs_mg_vcycle(mg, r, z[1]);
    for (int q = 0; q < n3; q++)
        r[q] = (float)(r[q] / 2);
    cs_mg_vcycle(mg, r, z[2]);
    *n3_out = n3;
    *mask_out = mask;
    mask = NULL;
    rc = 0;
out:
    cs_mg_free(mg);
    free(inv);
    free(r);
    free(mask);
    cs_world_destroy(w);
    return rc;
}

/* Slow only under valgrind (about 3 minutes there; 0.2 s in the -O3 build): `make valgrind`
 * (--quick) leaves it out; it passed under valgrind when written. */
SLOW_TEST(threads_vcycle_fused_conversions)
{
    /* 3 threads too (oversubscribed here): three segments per pass, two boundaries' shared
     * nodes cut among three threads (segments.h) */
    enum { T = 3 };
    double *z[T][3] = {{NULL}}, *x[T] = {NULL};
    uint8_t *mask[T] = {NULL};
    int n3[T] = {0}, lv1[T];
    for (int t = 0; t < T; t++)
        ENSURE_MSG(vcycles(t + 1, z[t], &n3[t], &mask[t], &lv1[t], &x[t]) == 0,
                   "%d threads: set-up", t + 1);
    ENSURE(n3[0] == n3[1] && n3[0] == n3[2] && n3[0] > 0);
    const int n = n3[0];
    long bad_float = 0, bad_held = 0, bad_scale = 0, bad_round = 0;
    for (int q = 0; q < n; q++) {
        const double v = z[0][0][q];
        bad_float += v != (double)(float)v;
        bad_held += mask[0][q] && v != 0.0;
        bad_scale += z[0][1][q] != 2 * v;
        bad_round += z[0][2][q] != v;
    }
    printf("    %d dofs, level 1 %d nodes: non-float %ld, held %ld, V(2r) != 2V(r) %ld, "
           "V(float(r)) != V(r) %ld\n", n, lv1[0], bad_float, bad_held, bad_scale, bad_round);
    ENSURE(bad_float == 0 && bad_held == 0 && bad_scale == 0 && bad_round == 0);
    long nonzero = 0;
    for (int q = 0; q < n; q++)
        nonzero += z[0][0][q] != 0;
    ENSURE(nonzero > n / 2);
    for (int t = 1; t < T; t++) {
        ENSURE_MSG(memcmp(x[0], x[t], sizeof(double) * n) == 0,
                   "the stepped positions differ between 1 and %d threads", t + 1);
        for (int k = 0; k < 3; k++)
            ENSURE_MSG(memcmp(z[0][k], z[t][k], sizeof(double) * n) == 0,
                       "V-cycle %d differs between 1 and %d threads", k, t + 1);
    }
    for (int t = 0; t < T; t++) {
        for (int k = 0; k < 3; k++)
            free(z[t][k]);
        free(mask[t]);
        free(x[t]);
    }
}
