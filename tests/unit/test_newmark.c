/*
 * test_newmark.c — Newmark's average acceleration (`"integrator": "newmark"`, the trapezoidal
 * rule, linearized like implicit Euler) against what the method is known to do: a linear
 * undamped object keeps its energy (the trapezoidal rule conserves a quadratic energy
 * exactly), the error falls with dt² (second order; implicit Euler's with dt), and a free
 * tumbling corotational block keeps its momenta.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "lattice.h"
#include "world_internal.h"

typedef struct run {
    cs_world_t *w;
    cs_object_id id;
} run;

/* nx×ny×nz cubes of h = 0.1 m (E 1e5 Pa, ν 0.3, ρ 1000), held at x = 0 if `held`. */
static int make_e(run *r, cs_model m, cs_integrator integ, double dt, double g, int nx, int ny,
                  int nz, bool held, double young)
{
    cs_world_def wd = cs_world_def_default();
    wd.dt = dt;
    wd.gravity[2] = -g;
    wd.cg_tolerance = 1e-11;
    wd.cg_max_iterations = 20000;
    wd.sleep_steps = 0;
    wd.threads = 1;
    if (cs_world_create(&wd, &r->w, NULL, 0) != CS_OK)
        return -1;
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    cs_object_def d = cs_object_def_default();
    d.name = "beam";
    d.model = m;
    d.integrator = integ;
    d.material.young = young;
    d.material.poisson = 0.3;
    d.material.density = 1000;
    d.cube_size = 0.1;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = nx * ny * nz;
    const cs_aabb fix = {{-1e-4, -1, -1}, {1e-4, 1, 1}};
    if (held) {
        d.fixed = &fix;
        d.n_fixed = 1;
    }
    char err[256];
    const int rc = cs_world_add_object(r->w, &d, &r->id, err, sizeof err);
    free(ijk);
    if (rc != CS_OK)
        fprintf(stderr, "    add: %s\n", err);
    return rc == CS_OK ? 0 : -1;
}

static int make(run *r, cs_model m, cs_integrator integ, double dt, double g, int nx, int ny,
                int nz, bool held)
{
    return make_e(r, m, integ, dt, g, nx, ny, nz, held, 1e5);
}

static double total_energy(const run *r)
{
    cs_energy e;
    cs_object_energy(r->w, r->id, &e);
    return e.kinetic + e.elastic;
}

/* A 6×2×2 cantilever (no gravity) kicked sideways at its tip for 0.1 s, then free for 600
 * steps of 1/60 s: the largest relative change of kinetic + elastic energy after the kick. */
static double free_vibration(cs_model m, cs_integrator integ, double *e_end)
{
    run r;
    if (make(&r, m, integ, 1.0 / 60, 0, 6, 2, 2, true) != 0)
        return -1;
    const double tip[3] = {0.6, 0.2, 0.2}, F[3] = {0, 2, 3};
    cs_world_apply_force(r.w, r.id, tip, F, 0.1, NULL, 0);
    for (int s = 0; s < 6; s++)
        cs_world_step(r.w);
    const double e0 = total_energy(&r);
    double worst = 0;
    for (int s = 0; s < 600; s++) {
        if (cs_world_step(r.w) != CS_OK)
            return -1;
        worst = fmax(worst, fabs(total_energy(&r) - e0) / e0);
    }
    *e_end = total_energy(&r) / e0;
    cs_world_destroy(r.w);
    return worst;
}

TEST(newmark_keeps_the_energy_of_a_linear_vibration)
{
    double end_nm, end_ie;
    const double d_nm = free_vibration(CS_MODEL_LINEAR, CS_INTEGRATOR_NEWMARK, &end_nm);
    const double d_ie = free_vibration(CS_MODEL_LINEAR, CS_INTEGRATOR_IMPLICIT_EULER, &end_ie);
    printf("    linear cantilever, 600 free steps of 1/60 s: Newmark max |ΔE|/E0 %.2e; implicit "
           "Euler ends at %.3f E0\n", d_nm, end_ie);
    ENSURE(d_nm >= 0 && d_ie >= 0);
    /* exact for the trapezoidal rule on a linear system, up to the solve (1e-11) */
    ENSURE_MSG(d_nm < 1e-7, "Newmark energy drift %g", d_nm);
    /* what the test can tell: implicit Euler damps this vibration away */
    ENSURE_MSG(end_ie < 0.5, "implicit Euler kept %g of the energy", end_ie);
}

/* A 6×2×2 corotational cantilever (E 2e6 Pa) released from rest under gravity: its tip's
 * mean z displacement at the 40 times k·0.4/40 s (steps a multiple of 40). */
#define SAMPLES 40
static int tip_path(cs_integrator integ, int steps, double *z)
{
    run r;
    if (make_e(&r, CS_MODEL_COROTATIONAL, integ, 0.4 / steps, 9.81, 6, 2, 2, true, 2e6) != 0)
        return -1;
    const double *rest, *x;
    int n;
    cs_object_nodes(r.w, r.id, &rest, NULL, NULL, &n);
    for (int s = 1; s <= steps; s++) {
        if (cs_world_step(r.w) != CS_OK)
            return -1;
        if (s % (steps / SAMPLES))
            continue;
        cs_object_nodes(r.w, r.id, &rest, &x, NULL, &n);
        double zs = 0;
        int cnt = 0;
        for (int i = 0; i < n; i++)
            if (fabs(rest[3 * i] - 0.6) < 1e-9) {
                zs += x[3 * i + 2] - rest[3 * i + 2];
                cnt++;
            }
        z[s / (steps / SAMPLES) - 1] = zs / cnt;
    }
    cs_world_destroy(r.w);
    return 0;
}

static double path_error(const double *z, const double *ref)
{
    double e = 0;
    for (int k = 0; k < SAMPLES; k++)
        e = fmax(e, fabs(z[k] - ref[k]));
    return e;
}

TEST(newmark_error_falls_with_dt_squared)
{
    double ref[SAMPLES], z[SAMPLES], e_nm[3], e_ie[3], amp = 0;
    ENSURE(tip_path(CS_INTEGRATOR_NEWMARK, 40 * 128, ref) == 0);
    for (int k = 0; k < SAMPLES; k++)
        amp = fmax(amp, fabs(ref[k]));
    const int steps[3] = {40 * 2, 40 * 4, 40 * 8};
    for (int k = 0; k < 3; k++) {
        ENSURE(tip_path(CS_INTEGRATOR_NEWMARK, steps[k], z) == 0);
        e_nm[k] = path_error(z, ref);
        ENSURE(tip_path(CS_INTEGRATOR_IMPLICIT_EULER, steps[k], z) == 0);
        e_ie[k] = path_error(z, ref);
    }
    printf("    tip path over 0.4 s (amplitude %.2e m); largest errors at dt 1/200, 1/400, 1/800: "
           "Newmark %.2e %.2e %.2e, implicit Euler %.2e %.2e %.2e\n", amp, e_nm[0], e_nm[1],
           e_nm[2], e_ie[0], e_ie[1], e_ie[2]);
    ENSURE(amp > 1e-3);
    /* halving dt: Newmark's error falls 3.0× and 3.3× (second order: 4, reached once dt also
     * resolves the beam's higher modes, which the sudden load excites and Newmark keeps
     * ringing), implicit Euler's 1.7× and 1.8× (first order: 2) */
    for (int k = 0; k < 2; k++) {
        ENSURE_MSG(e_nm[k] / e_nm[k + 1] > 2.8, "Newmark: error ratio %g at halving dt",
                   e_nm[k] / e_nm[k + 1]);
        ENSURE_MSG(e_ie[k] / e_ie[k + 1] < 2.1, "implicit Euler: error ratio %g (first order)",
                   e_ie[k] / e_ie[k + 1]);
    }
    ENSURE_MSG(e_nm[2] < 0.1 * e_ie[2], "Newmark %g against implicit Euler %g at dt 1/800",
               e_nm[2], e_ie[2]);
}

/* A free 3×2×1 block thrown spinning (no gravity), 3000 steps of 1/60 s (50 s): kinetic +
 * elastic energy stays within 1 % for corotational FEM and localframe (implicit Euler loses
 * most of it: stab_spin), and linear momentum is kept. */
TEST(newmark_tumbling_block_keeps_its_energy)
{
    const cs_model models[3] = {CS_MODEL_COROTATIONAL, CS_MODEL_LOCALFRAME, CS_MODEL_LINEAR};
    for (int m = 0; m < 3; m++) {
        run r;
        ENSURE(make(&r, models[m], CS_INTEGRATOR_NEWMARK, 1.0 / 60, 0, 3, 2, 1, false) == 0);
        const double corner[3] = {0.3, 0.2, 0.1}, F[3] = {15, -5, 10};
        cs_world_apply_force(r.w, r.id, corner, F, 0.25, NULL, 0);
        for (int s = 0; s < 15; s++)
            ENSURE(cs_world_step(r.w) == CS_OK);
        const double e0 = total_energy(&r);
        double worst = 0, p0[3] = {0, 0, 0}, dp = 0;
        for (int s = 0; s <= 3000; s++) {
            if (s > 0)
                ENSURE(cs_world_step(r.w) == CS_OK);
            worst = fmax(worst, fabs(total_energy(&r) - e0) / e0);
            const double *v;
            int n;
            cs_object_nodes(r.w, r.id, NULL, NULL, &v, &n);
            double p[3] = {0, 0, 0}; /* every node of a 3×2×1 block is a corner of 1, 2 or 4
                                      * cubes: Σ (cells at node) v is the momentum over ρh³/8 */
            const int32_t *cells;
            int nc;
            cs_object_cells(r.w, r.id, NULL, &cells, &nc);
            for (int k = 0; k < 8 * nc; k++)
                for (int a = 0; a < 3; a++)
                    p[a] += v[3 * cells[k] + a];
            if (s == 0)
                memcpy(p0, p, sizeof p);
            dp = fmax(dp, hypot(hypot(p[0] - p0[0], p[1] - p0[1]), p[2] - p0[2]) /
                              hypot(hypot(p0[0], p0[1]), p0[2]));
        }
        printf("    %s tumbling, Newmark, 3000 steps of 1/60 s: max |ΔE|/E0 %.2e, |ΔP|/|P0| %.1e\n",
               cs_model_name(models[m]), worst, dp);
        cs_world_destroy(r.w);
        /* linear: not rotation invariant, but still a linear system: energy exact */
        ENSURE_MSG(worst < (models[m] == CS_MODEL_LINEAR ? 1e-7 : 1e-2), "%s: energy drift %g",
                   cs_model_name(models[m]), worst);
        ENSURE_MSG(dp < 1e-8, "%s: momentum drift %g", cs_model_name(models[m]), dp);
    }
}

/* stab_implicit_any_dt's case for Newmark: a 6×2×2 cantilever (h 0.05 m, E 1e5 Pa) under
 * gravity, every free node started at 1 m/s down, dt from 1e-4 to 0.1 s, for 0.3 s (at least
 * 100 steps): finite, every node within 1 m of rest, and the total energy (kinetic, elastic,
 * gravity) kept — exactly for the linear model (up to the solve), within the bound below for
 * the corotational ones. Without the energy guard the corotational beam at 0.1 s grew to
 * 1.2e4 E0 and 1.5 m. */
TEST(newmark_any_dt_keeps_energy_bounded)
{
    const double dts[4] = {1e-4, 1e-3, 1e-2, 0.1};
    const cs_model models[3] = {CS_MODEL_LINEAR, CS_MODEL_COROTATIONAL, CS_MODEL_LOCALFRAME};
    for (int m = 0; m < 3; m++)
        for (int k = 0; k < 4; k++) {
            cs_world_def wd = cs_world_def_default();
            wd.dt = dts[k];
            wd.cg_tolerance = 1e-11;
            wd.cg_max_iterations = 20000;
            wd.sleep_steps = 0;
            wd.threads = 1;
            cs_world_t *w;
            ENSURE(cs_world_create(&wd, &w, NULL, 0) == CS_OK);
            int32_t *ijk = cs_box_cells(6, 2, 2);
            cs_object_def d = cs_object_def_default();
            d.name = "beam";
            d.model = models[m];
            d.integrator = CS_INTEGRATOR_NEWMARK;
            d.material.young = 1e5;
            d.cube_size = 0.05;
            d.geometry = CS_GEOMETRY_CELLS;
            d.cells_ijk = ijk;
            d.n_cells = 24;
            const cs_aabb fix = {{-1e-4, -1, -1}, {1e-4, 1, 1}};
            d.fixed = &fix;
            d.n_fixed = 1;
            cs_object_id id;
            ENSURE(cs_world_add_object(w, &d, &id, NULL, 0) == CS_OK);
            free(ijk);
            const double *rest, *x, *v;
            int n;
            cs_object *o = cs_world_find_internal(w, id);
            for (int i = 0; i < o->n; i++)
                if (!o->mask[3 * i + 2])
                    o->v[3 * i + 2] = -1.0;
            cs_energy e;
            cs_object_energy(w, id, &e);
            const double e0 = e.kinetic + e.elastic + e.gravity;
            const int steps = (int)fmax(100, fmin(1000, 0.3 / dts[k]));
            double emax = e0, dmax = 0;
            bool ok = true;
            for (int s = 0; s < steps && ok; s++) {
                ok = cs_world_step(w) == CS_OK;
                cs_object_energy(w, id, &e);
                ok = ok && isfinite(e.kinetic + e.elastic);
                emax = fmax(emax, e.kinetic + e.elastic + e.gravity);
            }
            cs_object_nodes(w, id, &rest, &x, &v, &n);
            for (int i = 0; i < 3 * n; i++)
                dmax = fmax(dmax, fabs(x[i] - rest[i]));
            printf("    newmark %s dt %g: max (E − E0)/|E0| %.3g, max |x − X| %.3g m\n",
                   cs_model_name(models[m]), dts[k], (emax - e0) / fabs(e0), dmax);
            cs_world_destroy(w);
            ENSURE_MSG(ok, "%s dt %g: a step failed or went non-finite", cs_model_name(models[m]),
                       dts[k]);
            ENSURE_MSG(dmax < 1.0, "%s dt %g: a node moved %g m", cs_model_name(models[m]), dts[k],
                       dmax);
            /* nonlinear: within 2 % up to dt 0.01 s (measured 1.2 %); at 0.1 s the strain
             * increment v dt / h is 2 and the energy guard hands the step to implicit Euler,
             * whose documented one-off rise (+104 %, stab_implicit_any_dt) is the bound */
            const double bound = models[m] == CS_MODEL_LINEAR ? 1e-7 : dts[k] < 0.05 ? 0.02 : 2.0;
            ENSURE_MSG(emax <= e0 + bound * fabs(e0), "%s dt %g: energy rose from %g to %g J",
                       cs_model_name(models[m]), dts[k], e0, emax);
        }
}

TEST(newmark_is_named_in_scenes_and_refused_for_mss)
{
    cs_integrator i;
    ENSURE(cs_integrator_from_name("newmark", &i) == 0 && i == CS_INTEGRATOR_NEWMARK);
    ENSURE(strcmp(cs_integrator_name(CS_INTEGRATOR_NEWMARK), "newmark") == 0);
    cs_world_def wd = cs_world_def_default();
    cs_world_t *w;
    ENSURE(cs_world_create(&wd, &w, NULL, 0) == CS_OK);
    int32_t *ijk = cs_box_cells(2, 1, 1);
    cs_object_def d = cs_object_def_default();
    d.name = "m";
    d.model = CS_MODEL_MSS;
    d.integrator = CS_INTEGRATOR_NEWMARK;
    d.cube_size = 0.1;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = 2;
    char err[256] = "";
    cs_object_id id;
    const int rc = cs_world_add_object(w, &d, &id, err, sizeof err);
    free(ijk);
    cs_world_destroy(w);
    ENSURE(rc == CS_ERR_INVALID);
    ENSURE_MSG(strstr(err, "'newmark' is not offered for model 'mss'") && !strchr(err, '\n'),
               "message: %s", err);
}

/* Newmark from rest: an impulse at the tip of a resting cantilever (no gravity) must be
 * integrated by the trapezoidal rule, not handed to implicit Euler by the energy guard. The
 * guard's slack was a fraction of the start energy, 0 at rest: every corotational and
 * localframe first step, and linear ones on round-off, were redone (an outside review found
 * the impulse response's modal amplitudes 3–28 % low). Every step of 60 keeps Newmark, and
 * the linear beam's energy after the impulse stays within 1e-8. */
TEST(newmark_from_rest_is_not_redone)
{
    const cs_model models[3] = {CS_MODEL_LINEAR, CS_MODEL_COROTATIONAL, CS_MODEL_LOCALFRAME};
    for (int k = 0; k < 3; k++) {
        run r;
        ENSURE(make(&r, models[k], CS_INTEGRATOR_NEWMARK, 1.0 / 60, 0, 6, 2, 2, true) == 0);
        const double tip[3] = {0.6, 0.2, 0.2}, F[3] = {0, 0.5, 1};
        ENSURE(cs_world_apply_force(r.w, r.id, tip, F, 0, NULL, 0) == CS_OK);
        int redone = 0;
        double e1 = 0, drift = 0;
        for (int s = 0; s < 60; s++) {
            ENSURE(cs_world_step(r.w) == CS_OK);
            redone += cs_world_last_stats(r.w)->newmark_redone;
            if (s == 0)
                e1 = total_energy(&r);
            else
                drift = fmax(drift, fabs(total_energy(&r) - e1) / e1);
        }
        printf("    model %d: %d steps redone by implicit Euler, energy drift after the impulse %.2e\n",
               (int)models[k], redone, drift);
        ENSURE_MSG(redone == 0, "model %d: %d steps redone", (int)models[k], redone);
        if (models[k] == CS_MODEL_LINEAR)
            ENSURE_MSG(drift < 1e-8, "linear: energy drift %g", drift);
        cs_world_destroy(r.w);
    }
}
