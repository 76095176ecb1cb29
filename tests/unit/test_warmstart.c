/*
 * test_warmstart.c — the warm start of sequences of solves (solver.h cs_cg_guess): the history
 * arms only when the state is exactly where the last recorded step ended (reset, sleep and a
 * re-initialised work after fracture start afresh); a warm-started solve reaches the same
 * solution to the tolerance, keeps held dofs at their initial value, and needs no more
 * iterations than a cold one on a smoothly changing system; implicit steps record and forget
 * the history as they should.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "solver.h"
#include "world_internal.h"

/* A 1-D chain: y = (m I + k L) x per coordinate, L the path Laplacian (SPD for m > 0). */
typedef struct chain {
    int n;
    double m, k;
} chain;

static void chain_apply(void *ctx, const double *x, double *y)
{
    const chain *c = ctx;
    for (int i = 0; i < c->n; i++) {
        double s = c->m * x[i];
        if (i > 0)
            s += c->k * (x[i] - x[i - 1]);
        if (i + 1 < c->n)
            s += c->k * (x[i] - x[i + 1]);
        y[i] = s;
    }
}

TEST(warmstart_history_rules)
{
    cs_cg_work w;
    ENSURE(cs_cg_work_init(&w, 6) == 0);
    double v0[6] = {1, 2, 3, 4, 5, 6}, v1[6] = {2, 3, 4, 5, 6, 7}, x[6];
    ENSURE(cs_cg_guess(&w, v0, x) == 0); /* no history yet */
    ENSURE(memcmp(x, v0, sizeof x) == 0);
    cs_cg_record(&w, v1);
    ENSURE(cs_cg_guess(&w, v1, x) == 1); /* continuous: armed with d = v1 − v0 */
    ENSURE(memcmp(x, v1, sizeof x) == 0);
    for (int i = 0; i < 6; i++)
        ENSURE(w.dirs[0][i] == 1.0);
    /* a state changed between steps (one bit of one component) does not match */
    cs_cg_record(&w, v1);
    double v2[6];
    memcpy(v2, v1, sizeof v2);
    v2[3] = nextafter(v2[3], 10);
    ENSURE(cs_cg_guess(&w, v2, x) == 0);
    ENSURE(!w.dir_ready);
    /* no record after a step (it fell asleep): nothing armed */
    ENSURE(cs_cg_guess(&w, v2, x) == 0);
    /* forget (reset) */
    cs_cg_record(&w, v1);
    cs_cg_forget(&w);
    ENSURE(cs_cg_guess(&w, v1, x) == 0);
    /* a re-initialised work (fracture) has no history */
    cs_cg_record(&w, v1);
    cs_cg_work_free(&w);
    ENSURE(cs_cg_work_init(&w, 6) == 0);
    ENSURE(cs_cg_guess(&w, v1, x) == 0);
    /* an armed direction is used by one solve only */
    cs_cg_record(&w, v1);
    ENSURE(cs_cg_guess(&w, v1, x) == 1);
    chain c = {6, 1.0, 3.0};
    uint8_t mask[6] = {0};
    double b[6] = {1, 0, 0, 0, 0, 1}, inv[6 * 9] = {0};
    for (int i = 0; i < 2; i++)
        inv[9 * i] = inv[9 * i + 4] = inv[9 * i + 8] = 1.0 / 7.0;
    cs_pcg(&w, chain_apply, &c, inv, mask, b, x, 1e-10, 100, 1);
    ENSURE(!w.dir_ready);
    cs_cg_work_free(&w);
}

/*
 * A sequence of solves A x_k = b_k with smoothly moving b_k (a travelling load), held dofs at
 * both ends with non-zero values: warm (cs_cg_guess / cs_cg_record) and cold (x = previous
 * solution) reach the tolerance, agree to it, keep the held values, and warm needs fewer
 * iterations in total.
 */
TEST(warmstart_same_solution_fewer_iterations)
{
    const int nodes = 200, n = 3 * nodes;
    chain c = {n, 1.0, 50.0};
    cs_cg_work ww, wc;
    ENSURE(cs_cg_work_init(&ww, n) == 0 && cs_cg_work_init(&wc, n) == 0);
    double *inv = calloc(9 * (size_t)nodes, sizeof(double));
    double *b = malloc(sizeof(double) * n), *xw = calloc((size_t)n, sizeof(double));
    double *xc = calloc((size_t)n, sizeof(double)), *vw = calloc((size_t)n, sizeof(double));
    double *r = malloc(sizeof(double) * n);
    uint8_t *mask = calloc((size_t)n, 1);
    ENSURE(inv && b && xw && xc && vw && r && mask);
    for (int i = 0; i < nodes; i++)
        for (int a = 0; a < 3; a++)
            inv[9 * i + 4 * a] = 1.0 / (c.m + 2 * c.k);
    mask[0] = mask[n - 1] = 1;
    int it_warm = 0, it_cold = 0;
    const double tol = 1e-6;
    for (int k = 0; k < 30; k++) {
        for (int i = 0; i < n; i++)
            b[i] = sin(0.02 * i + 0.1 * k) + 0.5 * cos(0.05 * i - 0.07 * k);
        /* warm: the guess from vw (the last solution), then record the new one */
        cs_cg_guess(&ww, vw, xw);
        xw[0] = 0.25;
        xw[n - 1] = -0.5;
        cs_cg_result rw = cs_pcg(&ww, chain_apply, &c, inv, mask, b, xw, tol, 1000, 1);
        memcpy(vw, xw, sizeof(double) * n);
        cs_cg_record(&ww, vw);
        /* cold: from the last solution */
        xc[0] = 0.25;
        xc[n - 1] = -0.5;
        cs_cg_result rc = cs_pcg(&wc, chain_apply, &c, inv, mask, b, xc, tol, 1000, 1);
        ENSURE(rw.converged && rc.converged);
        it_warm += rw.iterations;
        it_cold += rc.iterations;
        ENSURE(xw[0] == 0.25 && xw[n - 1] == -0.5);
        /* the true residual of the warm solution meets the stopping rule */
        chain_apply(&c, xw, r);
        double rr = 0, bb = 0, dd = 0, xx = 0;
        for (int i = 1; i < n - 1; i++) {
            rr += (b[i] - r[i]) * (b[i] - r[i]);
            bb += b[i] * b[i];
            dd += (xw[i] - xc[i]) * (xw[i] - xc[i]);
            xx += xc[i] * xc[i];
        }
        ENSURE_MSG(sqrt(rr) <= 1.001 * tol * sqrt(bb), "step %d: residual %.3g", k,
                   sqrt(rr / bb));
        /* both solutions within the tolerance of the exact one: agree to a few tol */
        ENSURE_MSG(sqrt(dd) <= 1e-5 * sqrt(xx), "step %d: differ by %.3g", k, sqrt(dd / xx));
    }
    ENSURE_MSG(it_warm < it_cold, "warm %d, cold %d iterations", it_warm, it_cold);
    cs_cg_work_free(&ww);
    cs_cg_work_free(&wc);
    free(inv);
    free(b);
    free(xw);
    free(xc);
    free(vw);
    free(r);
    free(mask);
}

/*
 * The warm start's subspace (CS_CG_DIRS directions): solutions that move along a fixed
 * three-dimensional family, x_k = Σ f_i(k) u_i (a quadratic, a sine and a linear drift in k),
 * change each step by a vector of span{u_i}. Once three consecutive changes are in the history,
 * the Galerkin step over them finds the next solution exactly (to the round-off of their
 * nearly parallel directions, 1e-8 here), so a solve to 1e-7 needs no CG iteration; a line
 * search along the last change alone (one direction) still needs several.
 * The solutions match the exact ones either way.
 */
/* Solves along the family of the test below with the warm start's subspace limited to
 * `dirs` directions: CG iterations summed over the solves after the fourth. */
static int family_iterations(int dirs, double tol)
{
    const int nodes = 100, n = 3 * nodes;
    chain c = {n, 1.0, 30.0};
    cs_cg_work w;
    if (cs_cg_work_init(&w, n) != 0)
        return -1;
    w.max_dirs = dirs;
    double *inv = calloc(9 * (size_t)nodes, sizeof(double)), *u = malloc(sizeof(double) * 3 * n);
    double *xs = malloc(sizeof(double) * n), *b = malloc(sizeof(double) * n);
    double *x = calloc((size_t)n, sizeof(double)), *v = calloc((size_t)n, sizeof(double));
    uint8_t *mask = calloc((size_t)n, 1);
    int late = 0;
    if (!inv || !u || !xs || !b || !x || !v || !mask)
        late = -1;
    for (int i = 0; late == 0 && i < nodes; i++)
        for (int a = 0; a < 3; a++)
            inv[9 * i + 4 * a] = 1.0 / (c.m + 2 * c.k);
    for (int i = 0; late == 0 && i < n; i++) {
        u[i] = sin(0.05 * i);
        u[n + i] = cos(0.13 * i) * (i % 7);
        u[2 * n + i] = 1.0 + 0.01 * i;
    }
    for (int k = 1; late >= 0 && k <= 12; k++) {
        const double f[3] = {0.1 * k * k, sin(0.3 * k), 0.5 * k};
        for (int i = 0; i < n; i++)
            xs[i] = f[0] * u[i] + f[1] * u[n + i] + f[2] * u[2 * n + i];
        chain_apply(&c, xs, b);
        cs_cg_guess(&w, v, x);
        const cs_cg_result r = cs_pcg(&w, chain_apply, &c, inv, mask, b, x, tol, 1000, 1);
        double e = 0, s = 0;
        for (int i = 0; i < n; i++) {
            e += (x[i] - xs[i]) * (x[i] - xs[i]);
            s += xs[i] * xs[i];
        }
        if (!r.converged || !(sqrt(e / s) < 1e3 * tol))
            late = -1;
        else if (k >= 5) /* three changes armed from here on */
            late += r.iterations;
        memcpy(v, x, sizeof(double) * n);
        cs_cg_record(&w, v);
    }
    cs_cg_work_free(&w);
    free(inv);
    free(u);
    free(xs);
    free(b);
    free(x);
    free(v);
    free(mask);
    return late;
}

/*
 * The warm start's subspace: solutions that move along a fixed three-dimensional family,
 * x_k = Σ f_i(k) u_i (a quadratic, a sine and a linear drift in k), change each step by a
 * vector of span{u_i}. With three or more of the last changes in the history the Galerkin
 * step over them lands on the next solution up to the previous solves' errors (the tolerance)
 * and the round-off of nearly parallel directions; the line search along the last change
 * alone (one direction) cannot. Each solve still reaches its tolerance and the exact solution.
 */
TEST(warmstart_subspace_reproduces_a_low_dimensional_motion)
{
    const int one = family_iterations(1, 1e-8), two = family_iterations(2, 1e-8);
    const int three = family_iterations(3, 1e-8), all = family_iterations(CS_CG_DIRS, 1e-8);
    printf("    CG iterations in the 8 solves after the 4th: 1 direction %d, 2: %d, 3: %d, "
           "%d: %d\n", one, two, three, CS_CG_DIRS, all);
    ENSURE(one > 0 && two > 0 && three >= 0 && all >= 0);
    ENSURE(3 * three < one && 3 * all < one);
    ENSURE(three <= two && all <= three);
}

/* Implicit steps record their end state; a reset, and falling asleep, forget it. */
TEST(warmstart_implicit_steps_reset_sleep)
{
    char err[256];
    cs_world_def wd = cs_world_def_default();
    wd.sleep_steps = 3;
    wd.sleep_speed = 1e3; /* falls asleep after three steps */
    cs_world_t *w;
    ENSURE(cs_world_create(&wd, &w, err, sizeof err) == CS_OK);
    int32_t ijk[3 * 8];
    for (int c = 0; c < 8; c++) {
        ijk[3 * c] = c & 1;
        ijk[3 * c + 1] = (c >> 1) & 1;
        ijk[3 * c + 2] = c >> 2;
    }
    cs_object_def d = cs_object_def_default();
    d.name = "o";
    d.model = CS_MODEL_COROTATIONAL;
    d.cube_size = 0.1;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = 8;
    cs_object_id id;
    ENSURE(cs_world_add_object(w, &d, &id, err, sizeof err) == CS_OK);
    cs_object *o = w->objects[0];
    ENSURE(o->integrator == CS_INTEGRATOR_IMPLICIT_EULER);
    ENSURE(cs_world_step(w) == CS_OK);
    ENSURE(o->cg.hist_valid);
    ENSURE(memcmp(o->cg.hist_end, o->v, sizeof(double) * 3 * o->n) == 0);
    ENSURE(cs_world_step(w) == CS_OK); /* armed by the first step's record */
    ENSURE(o->cg.hist_valid);
    cs_world_reset(w);
    ENSURE(!o->cg.hist_valid);
    for (int s = 0; s < 3; s++)
        ENSURE(cs_world_step(w) == CS_OK);
    ENSURE(o->sleeping);
    ENSURE(!o->cg.hist_valid);
    cs_world_destroy(w);
}

/* ------------------------------------- what the warm start's cost rests on (session 16) */

/* The chain with a product counter; its stiffness may change between solves. */
typedef struct counted {
    chain c;
    int products;
} counted;

static void counted_apply(void *ctx, const double *x, double *y)
{
    counted *k = ctx;
    k->products++;
    chain_apply(&k->c, x, y);
}

/* ‖x − xs‖²_A (e, y scratch): the A-norm² of an error. */
static double anorm2(chain *c, const double *x, const double *xs, double *e, double *y)
{
    for (int i = 0; i < c->n; i++)
        e[i] = x[i] - xs[i];
    chain_apply(c, e, y);
    double s = 0;
    for (int i = 0; i < c->n; i++)
        s += e[i] * y[i];
    return s;
}

/*
 * CG's residual stays b − A x through the warm start's update (r −= A D α) and the
 * iterations: after each warm-started solve of a moving load with held dofs, r0 − r_end equals
 * A (x_end − x0) to 1e-10 of its norm (r0 = b − A x0 at the guess, computed here), and r_end is
 * 0 at held dofs. This identity would give the product of the newest direction for free (the
 * solve's own change), but under that solve's operator: the corotated operator of the next
 * step differs (README "Warm start of implicit steps": reusing such products did not pay).
 */
TEST(warmstart_residual_identity)
{
    const int nodes = 60, n = 3 * nodes;
    counted k = {{n, 1.0, 40.0}, 0};
    cs_cg_work w;
    ENSURE(cs_cg_work_init(&w, n) == 0);
    double *inv = calloc(9 * (size_t)nodes, sizeof(double)), *b = malloc(sizeof(double) * n);
    double *x = calloc((size_t)n, sizeof(double)), *v = calloc((size_t)n, sizeof(double));
    double *x0 = malloc(sizeof(double) * n), *r0 = malloc(sizeof(double) * n);
    double *y = malloc(sizeof(double) * n);
    uint8_t *mask = calloc((size_t)n, 1);
    ENSURE(inv && b && x && v && x0 && r0 && y && mask);
    for (int i = 0; i < nodes; i++)
        for (int a = 0; a < 3; a++)
            inv[9 * i + 4 * a] = 1.0 / (k.c.m + 2 * k.c.k);
    mask[0] = mask[1] = 1;
    int armed = 0;
    for (int s = 0; s < 8; s++) {
        for (int i = 0; i < n; i++)
            b[i] = sin(0.03 * i + 0.2 * s) + 0.1 * s;
        armed += cs_cg_guess(&w, v, x) == 1;
        x[0] = 0.5;
        x[1] = -0.25;
        memcpy(x0, x, sizeof(double) * n);
        chain_apply(&k.c, x0, y);
        for (int i = 0; i < n; i++)
            r0[i] = mask[i] ? 0.0 : b[i] - y[i];
        const cs_cg_result r = cs_pcg(&w, counted_apply, &k, inv, mask, b, x, 1e-9, 500, 1);
        ENSURE(r.converged && r.iterations > 0);
        for (int i = 0; i < n; i++)
            y[i] = x[i] - x0[i];
        double *ay = x0; /* x0 no longer needed */
        chain_apply(&k.c, y, ay);
        double dd = 0, qq = 0;
        for (int i = 0; i < n; i++) {
            if (mask[i]) {
                ENSURE(w.r[i] == 0.0 && y[i] == 0.0);
                continue;
            }
            const double q = r0[i] - w.r[i];
            dd += (ay[i] - q) * (ay[i] - q);
            qq += ay[i] * ay[i];
        }
        ENSURE_MSG(sqrt(dd) <= 1e-10 * sqrt(qq), "solve %d: |A e − (r0 − r_end)| / |A e| %.3g", s,
                   sqrt(dd / qq));
        memcpy(v, x, sizeof(double) * n);
        cs_cg_record(&w, v);
    }
    ENSURE(armed == 7);
    cs_cg_work_free(&w);
    free(inv);
    free(b);
    free(x);
    free(v);
    free(x0);
    free(r0);
    free(y);
    free(mask);
}

/*
 * The warm start itself (a solve with max_iter 0 stops right after it), on an operator that
 * changes between solves (the chain's stiffness × 1.02, and × 3, per solve) with a held dof:
 * it costs one product per armed direction and one for the start residual; CG's r after it is
 * b − A x to rounding (1e-13 of ‖b‖ + ‖A x0‖ + ‖A (x − x0)‖ at × 1.02, 1e-11 at × 3, below;
 * the stopping test is honest); it never increases the A-norm error
 * against x = v, and it is at least as good as the best step along the newest direction alone
 * (the Galerkin step over a span that contains it), to 1e-9 of the start's error.
 */
TEST(warmstart_galerkin_start_exact_and_never_worse)
{
    const int nodes = 80, n = 3 * nodes;
    const double factors[2] = {1.02, 3.0};
    /* the update r −= Σ α_k A d_k rounds on the scale of Σ |α_k| |A d_k|, which nearly
     * parallel directions with cancelling coefficients raise above |A (x − x0)| */
    const double rtol[2] = {1e-13, 1e-11};
    for (int fi = 0; fi < 2; fi++) {
        counted k = {{n, 1.0, 30.0}, 0};
        cs_cg_work w, wx;
        ENSURE(cs_cg_work_init(&w, n) == 0 && cs_cg_work_init(&wx, n) == 0);
        double *inv = calloc(9 * (size_t)nodes, sizeof(double));
        double *b = malloc(sizeof(double) * n), *x = calloc((size_t)n, sizeof(double));
        double *v = calloc((size_t)n, sizeof(double)), *xs = calloc((size_t)n, sizeof(double));
        double *e = malloc(sizeof(double) * n), *y = malloc(sizeof(double) * n);
        double *x0 = malloc(sizeof(double) * n), *xl = malloc(sizeof(double) * n);
        uint8_t *mask = calloc((size_t)n, 1);
        ENSURE(inv && b && x && v && xs && e && y && x0 && xl && mask);
        for (int i = 0; i < nodes; i++)
            for (int a = 0; a < 3; a++)
                inv[9 * i + 4 * a] = 1.0 / (k.c.m + 2 * k.c.k);
        mask[n - 1] = 1;
        int full = 0;
        double worst = 0;
        for (int s = 0; s < 10; s++) {
            for (int i = 0; i < n; i++)
                b[i] = sin(0.04 * i) * (1 + 0.3 * s) + cos(0.11 * i) * sin(0.5 * s);
            const int armed = cs_cg_guess(&w, v, x);
            ENSURE(armed == (s > 0));
            x[n - 1] = 0.125;
            memcpy(x0, x, sizeof(double) * n);
            /* the exact solution (cold, to 1e-13) */
            memcpy(xs, x0, sizeof(double) * n);
            ENSURE(cs_pcg(&wx, chain_apply, &k.c, inv, mask, b, xs, 1e-13, 4000, 1).converged);
            const double e0 = anorm2(&k.c, x0, xs, e, y);
            const int nd = armed ? w.ndirs : 0, p0 = k.products;
            cs_pcg(&w, counted_apply, &k, inv, mask, b, x, 1e-13, 0, 1);
            ENSURE_MSG(k.products - p0 == 1 + nd, "solve %d: %d products, %d directions", s,
                       k.products - p0, nd);
            full += nd == CS_CG_DIRS;
            ENSURE(x[n - 1] == 0.125);
            /* CG's r is b − A x, to the rounding of its terms: the scale |b| + |A x0| +
             * |A (x − x0)| (the last is the warm start's update, large when the operator
             * stiffens × 3 per solve) */
            for (int i = 0; i < n; i++)
                e[i] = x[i] - x0[i];
            chain_apply(&k.c, e, y);
            double sc = 0;
            for (int i = 0; i < n - 1; i++)
                sc += y[i] * y[i];
            chain_apply(&k.c, x0, y);
            double bb = 0, yy = 0;
            for (int i = 0; i < n - 1; i++) {
                bb += b[i] * b[i];
                yy += y[i] * y[i];
            }
            sc = sqrt(sc) + sqrt(bb) + sqrt(yy);
            chain_apply(&k.c, x, y);
            double dr = 0;
            for (int i = 0; i < n - 1; i++)
                dr += (b[i] - y[i] - w.r[i]) * (b[i] - y[i] - w.r[i]);
            ENSURE_MSG(sqrt(dr) <= rtol[fi] * sc, "solve %d: |r − (b − A x)| / scale %.3g", s,
                       sqrt(dr) / sc);
            worst = fmax(worst, sqrt(dr) / sc);
            const double e1 = anorm2(&k.c, x, xs, e, y);
            ENSURE_MSG(e1 <= e0 * (1 + 1e-12), "solve %d: A-norm² error %.3g > %.3g", s, e1, e0);
            if (nd > 0) {
                /* the best step along d_1 alone (masked): x0 + t d, t = dᵀ(b − A x0) / dᵀA d */
                const double *d = w.dirs[0];
                chain_apply(&k.c, x0, y);
                double dr0 = 0;
                for (int i = 0; i < n; i++)
                    dr0 += mask[i] ? 0.0 : d[i] * (b[i] - y[i]);
                chain_apply(&k.c, d, y);
                double dad = 0;
                for (int i = 0; i < n; i++)
                    dad += d[i] * y[i];
                ENSURE(dad > 0);
                for (int i = 0; i < n; i++)
                    xl[i] = x0[i] + dr0 / dad * d[i];
                const double el = anorm2(&k.c, xl, xs, e, y);
                ENSURE_MSG(e1 <= el + 1e-9 * e0, "solve %d: subspace %.3g, line %.3g (of %.3g)",
                           s, e1, el, e0);
            }
            /* finish the solve and record the step's end */
            ENSURE(cs_pcg(&w, chain_apply, &k.c, inv, mask, b, x, 1e-12, 4000, 1).converged);
            memcpy(v, x, sizeof(double) * n);
            cs_cg_record(&w, v);
            k.c.k *= factors[fi]; /* the next solve's operator */
        }
        ENSURE(full >= 5);
        printf("    stiffness × %g per solve: |r − (b − A x)| / (|b| + |A x0| + |A (x − x0)|) "
               "after the warm start ≤ %.2g\n", factors[fi], worst);
        cs_cg_work_free(&w);
        cs_cg_work_free(&wx);
        free(inv);
        free(b);
        free(x);
        free(v);
        free(xs);
        free(e);
        free(y);
        free(x0);
        free(xl);
        free(mask);
    }
}

/* The warm start's sums (cs_cg_gram_block): for every count of directions 1..5, each sum
 * equals the same terms added in dof order from 0 by plain scalar code, bit for bit (the
 * five-direction case goes through vectors across the sums; a reordered sum would differ in
 * its last bits on these values, which span 16 decades and both signs). */
TEST(warmstart_gram_sums_bit_for_bit)
{
    enum { N = 1000, NV = CS_CG_DIRS + 1 };
    double *buf = malloc(sizeof(double) * N * (2 * NV + 1));
    ENSURE(buf);
    const double *D[NV], *Q[NV];
    uint64_t s = 88172645463325252ull;
    for (size_t i = 0; i < (size_t)N * (2 * NV + 1); i++) {
        s ^= s << 13, s ^= s >> 7, s ^= s << 17; /* xorshift64 */
        const double u = (double)(s >> 11) / 9007199254740992.0;
        buf[i] = (u - 0.5) * pow(10.0, (double)(s % 17) - 8.0);
    }
    for (int a = 0; a < NV; a++) {
        D[a] = buf + (size_t)a * N;
        Q[a] = buf + (size_t)(NV + a) * N;
    }
    const double *r = buf + (size_t)2 * NV * N;
    int reordered = 0;
    for (int nv = 1; nv <= NV; nv++) {
        const int lo = 7, hi = N - 3, ne = nv * (nv + 1);
        double got[NV * (NV + 1)], want[NV * (NV + 1)];
        cs_cg_gram_block(D, Q, r, nv, lo, hi, got);
        for (int a = 0; a < nv; a++) {
            for (int c = 0; c < nv; c++) {
                double t = 0;
                for (int i = lo; i < hi; i++)
                    t += D[a][i] * Q[c][i];
                want[a * nv + c] = t;
            }
            double t = 0;
            for (int i = lo; i < hi; i++)
                t += D[a][i] * r[i];
            want[nv * nv + a] = t;
        }
        for (int e = 0; e < ne; e++)
            ENSURE_MSG(memcmp(&got[e], &want[e], sizeof(double)) == 0,
                       "nv %d, sum %d: %.17g against %.17g", nv, e, got[e], want[e]);
        /* the check can fail: the same terms summed backwards differ somewhere */
        if (nv == NV)
            for (int e = 0; e < nv * nv && !reordered; e++) {
                double t = 0;
                for (int i = hi - 1; i >= lo; i--)
                    t += D[e / nv][i] * Q[e % nv][i];
                reordered = memcmp(&t, &want[e], sizeof(double)) != 0;
            }
    }
    ENSURE_MSG(reordered, "summing backwards gave the same bits: the check cannot tell");
    printf("    1..%d directions over %d dofs: every sum bit for bit\n", NV, N - 10);
    free(buf);
}
