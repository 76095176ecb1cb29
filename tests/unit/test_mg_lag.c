/*
 * test_mg_lag.c — the lagged multigrid preconditioner of the implicit step (world.c "the
 * lagged preconditioner", cs_pc_lag): the hierarchy is reused while nothing it was built from
 * changed, and rebuilt when the step's coefficients (dt, implicit Euler against Newmark), the
 * held dofs, the fields, the drag springs, the topology change, after statics or a reset, when
 * a cell has turned by more than the threshold, or after the step cap; a step solved with a
 * lagged hierarchy agrees with one solved with a fresh hierarchy to what the CG tolerance
 * allows; a fast-spinning object still converges every step; a lagged solve that misses the
 * iteration limit is redone with a fresh hierarchy and converges.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "lattice.h"
#include "world_internal.h"

typedef struct scene {
    cs_world_t *w;
    cs_object_id id;
    cs_object *o;
} scene;

/* Adds an nx×ny×nz corotational box of cubes of edge h and density rho to s->w (fixed at
 * x = 0 if fix; its lowest cells at z0) and finds its internal object. */
static int add_box(scene *s, int nx, int ny, int nz, double h, double young, double rho,
                   bool fix, cs_integrator integ, double z0)
{
    char err[256];
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    cs_object_def d = cs_object_def_default();
    d.name = "o";
    d.model = CS_MODEL_COROTATIONAL;
    d.integrator = integ;
    d.material.young = young;
    d.material.density = rho;
    d.cube_size = h;
    d.cells_ijk = ijk;
    d.n_cells = nx * ny * nz;
    d.cells_origin[2] = z0;
    cs_aabb box = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1e3, 1e3}};
    if (fix) {
        d.fixed = &box;
        d.n_fixed = 1;
    }
    const int rc = cs_world_add_object(s->w, &d, &s->id, err, sizeof err);
    free(ijk);
    if (rc != CS_OK) {
        printf("    add: %s\n", err);
        return -1;
    }
    s->o = cs_world_find_internal(s->w, s->id);
    return 0;
}

/* An nx×ny×nz corotational box of cubes of edge h (fixed at x = 0 if fix), multigrid
 * preconditioner, one thread, tolerance 1e-6 of ‖b‖. */
static int make_threads(scene *s, int nx, int ny, int nz, double h, double young, bool fix,
                        cs_integrator integ, bool gravity, int threads)
{
    memset(s, 0, sizeof *s);
    cs_world_def wd = cs_world_def_default();
    wd.threads = threads;
    wd.preconditioner = CS_PRECOND_MULTIGRID;
    wd.sleep_steps = 0;
    wd.cg_tolerance = 1e-6;
    wd.cg_relative_to = CS_CG_RELATIVE_RHS;
    if (!gravity)
        wd.gravity[0] = wd.gravity[1] = wd.gravity[2] = 0;
    if (cs_world_create(&wd, &s->w, NULL, 0) != CS_OK)
        return -1;
    return add_box(s, nx, ny, nz, h, young, 1000, fix, integ, 0);
}

static int make(scene *s, int nx, int ny, int nz, double h, double young, bool fix,
                cs_integrator integ, bool gravity)
{
    return make_threads(s, nx, ny, nz, h, young, fix, integ, gravity, 1);
}

/* Every node moving as a rigid rotation at omega (rad/s) about the centroid. */
static void spin(cs_object *o, const double om[3])
{
    double c[3] = {0, 0, 0};
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            c[a] += o->x[3 * i + a] / o->n;
    for (int i = 0; i < o->n; i++) {
        const double r[3] = {o->x[3 * i] - c[0], o->x[3 * i + 1] - c[1], o->x[3 * i + 2] - c[2]};
        o->v[3 * i] = om[1] * r[2] - om[2] * r[1];
        o->v[3 * i + 1] = om[2] * r[0] - om[0] * r[2];
        o->v[3 * i + 2] = om[0] * r[1] - om[1] * r[0];
    }
}

/* A force on a corner of the box, across it, for the whole run: it bends and turns the body
 * in every step. (A free body turning alone is solved by its velocity: its rigid part turns
 * exactly, world.c free_body_rotation, and gives a solve nothing to do.) */
static int push_corner(scene *s, double f)
{
    const double p[3] = {s->o->x[0], s->o->x[1], s->o->x[2]}, F[3] = {0, f, f};
    return cs_world_apply_force(s->w, s->id, p, F, 100.0, NULL, 0);
}

/* One step; returns how many builds it made (0: it reused the hierarchy). */
static long step_builds(scene *s, int *rc)
{
    const long b0 = s->o->lag.builds;
    *rc = cs_world_step(s->w);
    return s->o->lag.builds - b0;
}

/* A stiff cantilever barely moves: one build serves every step (until the cap), and the
 * rotation measure stays below the threshold in every reused step. */
TEST(mg_lag_reused_while_nothing_changes)
{
    scene s;
    ENSURE(make(&s, 16, 4, 4, 0.05, 1e8, true, CS_INTEGRATOR_IMPLICIT_EULER, true) == 0);
    int rc;
    ENSURE(step_builds(&s, &rc) == 1 && rc == CS_OK);
    const double lim = 2 * (1 - cos(s.w->pc_lag_angle));
    for (int k = 0; k < 20; k++) {
        ENSURE_MSG(step_builds(&s, &rc) == 0 && rc == CS_OK, "step %d built", k);
        ENSURE(s.o->lag.drift <= lim);
        ENSURE(cs_world_last_stats(s.w)->cg_residual <= 1e-6);
    }
    ENSURE(s.o->lag.reuses == 20 && s.o->lag.retries == 0);
    /* the cap: pc_lag_steps reuses, then a build */
    s.w->pc_lag_steps = 3;
    ENSURE(step_builds(&s, &rc) == 1); /* 20 reuses already: over the cap */
    for (int k = 0; k < 3; k++)
        ENSURE(step_builds(&s, &rc) == 0);
    ENSURE(step_builds(&s, &rc) == 1);
    /* pc_lag_angle 0: every step builds, as before the lag */
    s.w->pc_lag_angle = 0;
    for (int k = 0; k < 3; k++)
        ENSURE(step_builds(&s, &rc) == 1);
    cs_world_destroy(s.w);
}

/* Each trigger, one at a time, after a step that reused the hierarchy: the next step builds,
 * and the one after it reuses again. */
TEST(mg_lag_rebuilt_on_each_trigger)
{
    scene s;
    ENSURE(make(&s, 16, 4, 4, 0.05, 1e8, true, CS_INTEGRATOR_IMPLICIT_EULER, true) == 0);
    char err[256];
    int rc;
    ENSURE(step_builds(&s, &rc) == 1);
    ENSURE(step_builds(&s, &rc) == 0);
    /* dt: every coefficient of the operator changes */
    s.w->def.dt *= 0.5;
    ENSURE_MSG(step_builds(&s, &rc) == 1, "dt changed");
    ENSURE(step_builds(&s, &rc) == 0);
    /* held dofs: one more node held */
    s.o->mask[3 * (s.o->n - 1) + 1] = 1;
    ENSURE_MSG(step_builds(&s, &rc) == 1, "mask changed");
    ENSURE(step_builds(&s, &rc) == 0);
    /* a drag spring (the operator holds it) */
    const double grab[3] = {0.7, 0.1, 0.1}, target[3] = {0.7, 0.1, 0.12};
    ENSURE(cs_world_drag(s.w, s.id, grab, target, 50, 10, err, sizeof err) == CS_OK);
    ENSURE_MSG(step_builds(&s, &rc) == 1, "drag added");
    ENSURE(step_builds(&s, &rc) == 0);
    /* the stiffness field painted */
    const double c[3] = {0.4, 0.1, 0.1};
    cs_field_factors f = {.young = 3.0, .which = CS_FIELD_YOUNG};
    int touched = 0;
    ENSURE(cs_world_paint(s.w, s.id, c, 0.1, &f, &touched, err, sizeof err) == CS_OK);
    ENSURE(touched > 0);
    ENSURE_MSG(step_builds(&s, &rc) == 1, "paint");
    ENSURE(step_builds(&s, &rc) == 0);
    /* the topology: one face cut */
    const int32_t ijk[3] = {10, 1, 1};
    ENSURE(cs_world_cut_face(s.w, s.id, ijk, 0, err, sizeof err) == CS_OK);
    s.o = cs_world_find_internal(s.w, s.id);
    ENSURE_MSG(step_builds(&s, &rc) == 1, "cut");
    ENSURE(step_builds(&s, &rc) == 0);
    /* statics (overwrites the hierarchy with its own operator) */
    ENSURE(cs_world_solve_static(s.w) == CS_OK);
    ENSURE_MSG(step_builds(&s, &rc) == 1, "statics");
    ENSURE(step_builds(&s, &rc) == 0);
    /* reset */
    cs_world_reset(s.w);
    ENSURE_MSG(step_builds(&s, &rc) == 1, "reset");
    ENSURE(step_builds(&s, &rc) == 0);
    /* a rotation beyond the threshold: the whole body turned by 0.1 rad about z */
    cs_object *o = s.o;
    const double a = 0.1, ca = cos(a), sa = sin(a);
    for (int i = 0; i < o->n; i++) {
        const double x = o->x[3 * i], y = o->x[3 * i + 1];
        o->x[3 * i] = ca * x - sa * y;
        o->x[3 * i + 1] = sa * x + ca * y;
    }
    ENSURE_MSG(step_builds(&s, &rc) == 1, "rotation");
    ENSURE(step_builds(&s, &rc) == 0);
    ENSURE(s.o->lag.retries == 0);
    cs_world_destroy(s.w);
}

/* The held dofs' check runs on the object's threads (session 40): on a 2048-cell box on two
 * threads a newly held dof in either thread's half of the nodes is seen, and the hierarchy
 * rebuilt before the solve (a check that missed it would leave the lagged V-cycle moving the
 * held dof; its solve then fails and is retried with a fresh build: lag.retries). */
TEST(mg_lag_held_dofs_checked_on_two_threads)
{
    scene s;
    ENSURE(make_threads(&s, 32, 8, 8, 0.05, 1e8, true, CS_INTEGRATOR_IMPLICIT_EULER, true, 2) ==
           0);
    ENSURE(s.o->fem.threads == 2);
    int rc;
    ENSURE(step_builds(&s, &rc) == 1);
    ENSURE(step_builds(&s, &rc) == 0);
    const int nodes[2] = {s.o->n / 4, s.o->n - 1};
    for (int k = 0; k < 2; k++) {
        ENSURE(!s.o->mask[3 * nodes[k] + 2]);
        s.o->mask[3 * nodes[k] + 2] = 1;
        ENSURE_MSG(step_builds(&s, &rc) == 1 && rc == CS_OK, "node %d held", nodes[k]);
        /* built before the solve, not after a lagged solve that failed */
        ENSURE(s.o->lag.retries == 0);
        ENSURE(step_builds(&s, &rc) == 0);
    }
    cs_world_destroy(s.w);
}

/* Newmark after a rigid contact's push takes an implicit Euler step: other coefficients,
 * so a build, and the Newmark step after it builds again. */
TEST(mg_lag_rebuilt_when_the_integrator_switches)
{
    scene s;
    ENSURE(make(&s, 8, 8, 8, 0.05, 1e6, false, CS_INTEGRATOR_NEWMARK, false) == 0);
    const double om[3] = {0.1, 0, 0.2}; /* slowly turning, free: no step redone by the guard */
    spin(s.o, om);
    int rc;
    ENSURE(step_builds(&s, &rc) == 1);
    ENSURE(step_builds(&s, &rc) == 0);
    s.o->contact_pushed = true;
    ENSURE_MSG(step_builds(&s, &rc) == 1, "implicit Euler step");
    ENSURE_MSG(step_builds(&s, &rc) == 1, "Newmark again");
    ENSURE(step_builds(&s, &rc) == 0);
    cs_world_destroy(s.w);
}

/* A soft beam swinging down, stepped by two worlds in lockstep from the same state each step
 * (b's positions and velocities copied from a before each step): one lagging up to 0.2 rad,
 * one building every step. Each step's velocities agree to the solve's tolerance: within 1e-5 of the
 * step's velocity change (the CG tolerance is 1e-6 of ‖b‖). */
TEST(mg_lag_step_matches_fresh)
{
    scene a, b;
    ENSURE(make(&a, 20, 4, 4, 0.05, 1e5, true, CS_INTEGRATOR_IMPLICIT_EULER, true) == 0);
    ENSURE(make(&b, 20, 4, 4, 0.05, 1e5, true, CS_INTEGRATOR_IMPLICIT_EULER, true) == 0);
    a.w->pc_lag_angle = 0.2; /* four times the default: a staler hierarchy than ever used */
    b.w->pc_lag_angle = 0;
    const size_t n3 = 3 * (size_t)a.o->n;
    double *v0 = malloc(n3 * sizeof *v0);
    ENSURE(v0 != NULL);
    double worst = 0;
    for (int k = 0; k < 40; k++) {
        memcpy(b.o->x, a.o->x, n3 * sizeof(double));
        memcpy(b.o->v, a.o->v, n3 * sizeof(double));
        memcpy(v0, a.o->v, n3 * sizeof(double));
        ENSURE(cs_world_step(a.w) == CS_OK && cs_world_step(b.w) == CS_OK);
        ENSURE(cs_world_last_stats(a.w)->cg_residual <= 1e-6);
        double dd = 0, dv = 0;
        for (size_t d = 0; d < n3; d++) {
            dd += (a.o->v[d] - b.o->v[d]) * (a.o->v[d] - b.o->v[d]);
            dv += (b.o->v[d] - v0[d]) * (b.o->v[d] - v0[d]);
        }
        worst = fmax(worst, sqrt(dd / dv));
    }
    printf("    40 steps: %ld builds, %ld reuses; lagged against fresh: largest difference %.1e "
           "of the step's velocity change\n", a.o->lag.builds, a.o->lag.reuses, worst);
    ENSURE(a.o->lag.reuses >= 10 && b.o->lag.reuses == 0);
    ENSURE_MSG(worst < 1e-5, "lagged and fresh steps differ by %g", worst);
    free(v0);
    cs_world_destroy(a.w);
    cs_world_destroy(b.w);
}

/* A free block spinning at 8 rad/s (0.13 rad per step at 1/60 s, more than the threshold),
 * Newmark: every step rebuilds, converges, and the body keeps spinning (its angular velocity
 * within 1 % after 30 steps). At 1 rad/s the hierarchy is reused for a few steps between
 * builds, and every step converges too. */
TEST(mg_lag_fast_spin_converges)
{
    const double rates[2] = {8.0, 1.0};
    for (int r = 0; r < 2; r++) {
        scene s;
        ENSURE(make(&s, 8, 8, 8, 0.05, 1e6, false, CS_INTEGRATOR_NEWMARK, false) == 0);
        const double om[3] = {0, 0, rates[r]};
        spin(s.o, om);
        for (int k = 0; k < 30; k++) {
            ENSURE(cs_world_step(s.w) == CS_OK);
            ENSURE_MSG(cs_world_last_stats(s.w)->cg_residual <= 1e-6, "step %d: %g", k,
                       cs_world_last_stats(s.w)->cg_residual);
        }
        /* ω about z from a node's velocity relative to the centroid */
        cs_object *o = s.o;
        double c[3] = {0, 0, 0}, vc[3] = {0, 0, 0}, L = 0, I = 0;
        for (int i = 0; i < o->n; i++)
            for (int a = 0; a < 3; a++) {
                c[a] += o->x[3 * i + a] / o->n;
                vc[a] += o->v[3 * i + a] / o->n;
            }
        for (int i = 0; i < o->n; i++) {
            const double rx = o->x[3 * i] - c[0], ry = o->x[3 * i + 1] - c[1];
            L += rx * (o->v[3 * i + 1] - vc[1]) - ry * (o->v[3 * i] - vc[0]);
            I += rx * rx + ry * ry;
        }
        printf("    spin %.0f rad/s: %ld builds, %ld reuses, %ld retries in 30 steps (redone steps build too); "
               "ω after %.3f rad/s\n", rates[r], o->lag.builds, o->lag.reuses, o->lag.retries,
               L / I);
        ENSURE_MSG(fabs(L / I - rates[r]) < 0.01 * rates[r], "ω %g", L / I);
        if (r == 0)
            ENSURE(o->lag.reuses == 0);
        else
            ENSURE(o->lag.reuses > 0 && o->lag.builds > 1);
        cs_world_destroy(s.w);
    }
}

/* A lagged hierarchy far off (no threshold, no cap, a body turned by 1.5 rad) with an
 * iteration limit it cannot meet: the solve is redone with a fresh build and converges. */
TEST(mg_lag_retry_with_fresh_build)
{
    scene s;
    ENSURE(make(&s, 12, 6, 6, 0.05, 1e7, false, CS_INTEGRATOR_IMPLICIT_EULER, false) == 0);
    s.w->pc_lag_angle = 10; /* never by angle */
    s.w->pc_lag_steps = 1000000;
    s.w->pc_lag_cap = false; /* nor by iterations */
    const double om[3] = {0, 0, 3.0};
    spin(s.o, om);
    ENSURE(push_corner(&s, 20) == CS_OK);
    for (int k = 0; k < 30; k++) /* ≈ 1.5 rad turned since the build */
        ENSURE(cs_world_step(s.w) == CS_OK);
    ENSURE(s.o->lag.builds == 1);
    const int it_lag = cs_world_last_stats(s.w)->cg_iterations;
    /* the limit: the fresh hierarchy's count needs no more than that (measured: 3–5) */
    s.w->def.cg_max_iterations = 6;
    const long r0 = s.o->lag.retries;
    for (int k = 0; k < 3; k++) {
        ENSURE(cs_world_step(s.w) == CS_OK);
        ENSURE_MSG(cs_world_last_stats(s.w)->cg_residual <= 1e-6, "step %d: %g", k,
                   cs_world_last_stats(s.w)->cg_residual);
    }
    printf("    lagged by 1.5 rad: %d iterations; limit 6: %ld retries\n", it_lag,
           s.o->lag.retries - r0);
    ENSURE(it_lag > 6);
    ENSURE(s.o->lag.retries > r0);
    cs_world_destroy(s.w);
}

/* The same body lagged by 1.5 rad under the default iteration limit (500): the lagged solve
 * stops at twice the last fresh solve's iterations + 2 (at least 8) and goes on with a fresh
 * build, so the step costs fewer iterations than the lagged solve alone needs. */
TEST(mg_lag_capped_by_fresh_iterations)
{
    scene s;
    ENSURE(make(&s, 12, 6, 6, 0.05, 1e7, false, CS_INTEGRATOR_IMPLICIT_EULER, false) == 0);
    s.w->pc_lag_angle = 10;
    s.w->pc_lag_steps = 1000000;
    s.w->pc_lag_cap = false; /* until the lagged step */
    const double om[3] = {0, 0, 3.0};
    spin(s.o, om);
    ENSURE(push_corner(&s, 20) == CS_OK);
    for (int k = 0; k < 30; k++)
        ENSURE(cs_world_step(s.w) == CS_OK);
    ENSURE(s.o->lag.builds == 1 && s.o->lag.retries == 0);
    const int it_lag = cs_world_last_stats(s.w)->cg_iterations, fresh = s.o->lag.fresh_it;
    const int cap = 2 * fresh + 2 > 8 ? 2 * fresh + 2 : 8;
    ENSURE_MSG(it_lag > cap, "lagged %d, cap %d: the scene no longer tests the cap", it_lag,
               cap);
    s.w->pc_lag_cap = true;
    ENSURE(cs_world_step(s.w) == CS_OK);
    const int it = cs_world_last_stats(s.w)->cg_iterations;
    printf("    lagged by 1.5 rad: %d iterations alone; capped at %d (fresh %d): %d in all, "
           "%ld retries\n", it_lag, cap, fresh, it, s.o->lag.retries);
    ENSURE(s.o->lag.retries == 1 && s.o->lag.builds == 2);
    ENSURE_MSG(cs_world_last_stats(s.w)->cg_residual <= 1e-6, "%g",
               cs_world_last_stats(s.w)->cg_residual);
    ENSURE_MSG(it < it_lag, "%d iterations with the cap against %d without", it, it_lag);
    cs_world_destroy(s.w);
}

/* A box of nx×ny×nz cubes of edge h under preconditioner pc at the default tolerance, one
 * thread, held at x = 0 (fix) or resting above the ground, with density rho; steps it `steps`
 * times and sums the CG iterations of the second half in *its_after. */
static int auto_box(scene *s, int nx, int ny, int nz, double h, double young, double rho,
                    bool fix, cs_preconditioner pc, int steps, long *its_after)
{
    memset(s, 0, sizeof *s);
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    wd.preconditioner = pc;
    wd.sleep_steps = 0;
    wd.has_ground = !fix;
    if (cs_world_create(&wd, &s->w, NULL, 0) != CS_OK ||
        add_box(s, nx, ny, nz, h, young, rho, fix, CS_INTEGRATOR_IMPLICIT_EULER,
                fix ? 1.0 : 0.05) != 0)
        return -1;
    *its_after = 0;
    for (int k = 0; k < steps; k++) {
        if (cs_world_step(s->w) != CS_OK)
            return -1;
        if (k >= steps / 2)
            *its_after += cs_world_last_stats(s->w)->cg_iterations;
    }
    return 0;
}

/*
 * "auto" below CS_MG_AUTO_CELLS (session 42): block Jacobi, until its solves take more than
 * CS_MG_AUTO_JACOBI_IT iterations in CS_MG_AUTO_HARD_STEPS steps in a row; then multigrid
 * for good if three fixed nodes not on a line hold it (a free body's rigid motions are held by
 * its mass alone, which the float V-cycle loses when stiff, and a turning one rebuilds its
 * hierarchy every step).
 * A held 40×4×4 beam (E 1e7 and 1e13 Pa, 41–84 Jacobi iterations a step) takes multigrid and
 * needs under a fifth of the iterations, to the same state as Jacobi's within the
 * tolerance's reach; a soft 8³ block (6 a step) keeps Jacobi; a free 4³ block of (ω dt)² 3e7
 * landing on the ground keeps Jacobi although its landing solves take hundreds.
 */
TEST(mg_auto_takes_multigrid_where_jacobi_works_hard)
{
    struct {
        const char *what;
        int nx, ny, nz;
        double h, young, rho;
        bool fix, want_mg;
    } c[] = {
        {"held beam 40x4x4, E 1e7", 40, 4, 4, 0.025, 1e7, 1000, true, true},
        {"held beam 40x4x4, E 1e13", 40, 4, 4, 0.025, 1e13, 1000, true, true},
        {"held soft block 8^3, E 1e5", 8, 8, 8, 0.1, 1e5, 1000, true, false},
        {"free block 4^3 on the ground, (w dt)^2 3e7", 4, 4, 4, 0.1, 1000, 1e-5, false, false},
    };
    for (size_t k = 0; k < sizeof c / sizeof c[0]; k++) {
        scene a, j;
        long its_a, its_j;
        ENSURE(auto_box(&a, c[k].nx, c[k].ny, c[k].nz, c[k].h, c[k].young, c[k].rho, c[k].fix,
                        CS_PRECOND_AUTO, 40, &its_a) == 0);
        ENSURE(auto_box(&j, c[k].nx, c[k].ny, c[k].nz, c[k].h, c[k].young, c[k].rho, c[k].fix,
                        CS_PRECOND_JACOBI, 40, &its_j) == 0);
        /* the same state to what the tolerance allows: largest node difference against the
         * largest displacement */
        double diff = 0, umax = 0;
        for (int d = 0; d < 3 * a.o->n; d++) {
            diff = fmax(diff, fabs(a.o->x[d] - j.o->x[d]));
            umax = fmax(umax, fabs(j.o->x[d] - j.o->cm.node_rest[d]));
        }
        printf("    %s: %s, CG it/step %.1f (jacobi %.1f), state within %.2g of %.3g m\n",
               c[k].what, a.o->lag.small_mg ? "multigrid" : "jacobi", its_a / 20.0,
               its_j / 20.0, diff, umax);
        ENSURE_MSG(a.o->lag.small_mg == c[k].want_mg, "%s", c[k].what);
        ENSURE(!j.o->lag.small_mg);
        if (c[k].want_mg) {
            ENSURE(its_j > 20 * CS_MG_AUTO_JACOBI_IT && 5 * its_a < its_j);
            ENSURE_MSG(diff <= 1e-3 * umax, "%s: %g of %g", c[k].what, diff, umax);
        } else {
            ENSURE(its_a == its_j && diff == 0); /* Jacobi all along: the same bits */
            if (!c[k].fix) /* being free, not the iterations, kept it on Jacobi */
                ENSURE(its_j > 20 * CS_MG_AUTO_JACOBI_IT);
        }
        cs_world_destroy(a.w);
        cs_world_destroy(j.w);
    }
}

/*
 * The auto choice's life (session 42's review): a reset clears it, so a reset run repeats the
 * first one bit for bit; a change of the material fields clears it (decided again for the
 * new material); a Newmark step redone by implicit Euler counts once (it counted its
 * trapezoidal solve and the redo's: a held beam switched after one step).
 */
TEST(mg_auto_choice_cleared_by_reset_and_fields_counted_once_per_step)
{
    scene a;
    long its;
    ENSURE(auto_box(&a, 40, 4, 4, 0.025, 1e7, 1000, true, CS_PRECOND_AUTO, 20, &its) == 0);
    ENSURE(a.o->lag.small_mg);
    const size_t n3 = 3 * (size_t)a.o->n;
    double *x1 = malloc(n3 * sizeof *x1);
    ENSURE(x1 != NULL);
    memcpy(x1, a.o->x, n3 * sizeof *x1);
    cs_world_reset(a.w);
    ENSURE(!a.o->lag.small_mg && a.o->lag.hard_steps == 0);
    for (int k = 0; k < 20; k++)
        ENSURE(cs_world_step(a.w) == CS_OK);
    ENSURE(memcmp(x1, a.o->x, n3 * sizeof *x1) == 0);
    free(x1);
    const double centre[3] = {0.5, 0.05, 1.05};
    const cs_field_factors f = {.young = 2.0, .which = CS_FIELD_YOUNG};
    int touched = 0;
    ENSURE(cs_world_paint(a.w, a.id, centre, 0.1, &f, &touched, NULL, 0) == CS_OK && touched > 0);
    ENSURE(!a.o->lag.small_mg);
    cs_world_destroy(a.w);

    /* Newmark at dt 0.1 s on a soft held beam: steps redone by implicit Euler count once */
    scene n;
    memset(&n, 0, sizeof n);
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    wd.sleep_steps = 0;
    wd.dt = 0.1;
    ENSURE(cs_world_create(&wd, &n.w, NULL, 0) == CS_OK);
    ENSURE(add_box(&n, 12, 4, 4, 0.025, 1e5, 1000, true, CS_INTEGRATOR_NEWMARK, 1.0) == 0);
    int redone = 0, first = -1;
    for (int k = 0; k < 20 && !n.o->lag.small_mg; k++) {
        const int before = n.o->lag.hard_steps;
        ENSURE(cs_world_step(n.w) == CS_OK);
        const cs_step_stats *st = cs_world_last_stats(n.w);
        if (st->newmark_redone && st->cg_iterations > 2 * CS_MG_AUTO_JACOBI_IT) {
            if (first < 0)
                first = k;
            redone++;
            ENSURE_MSG(n.o->lag.hard_steps == before + 1 &&
                           (before + 1 >= CS_MG_AUTO_HARD_STEPS) == n.o->lag.small_mg,
                       "step %d: hard steps %d -> %d", k, before, n.o->lag.hard_steps);
        }
    }
    printf("    Newmark: %d redone steps of over %d CG iterations (first: step %d), %s\n",
           redone, 2 * CS_MG_AUTO_JACOBI_IT, first, n.o->lag.small_mg ? "multigrid" : "jacobi");
    ENSURE(redone > 0 && first == 0); /* the first step is one: counted once, not twice */
    cs_world_destroy(n.w);
}
