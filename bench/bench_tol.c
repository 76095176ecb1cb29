/*
 * bench_tol.c — the CG tolerance beyond smooth bending (issue 6 part 3). The work-precision
 * sweep (bench_wp) found tolerance 1e-3 as accurate as 1e-6 on a bending cantilever; the
 * tolerance is world-wide, so this measures what it does to the rest of the engine, against a
 * tight-tolerance reference (1e-10, the same model, mesh and dt) or a conservation law:
 *
 *   rest     a 0.4 m block (4³ cubes, E = 1e5 Pa, ν = 0) set on the ground under gravity,
 *            600 steps: the sag of its centre of mass against the reference's (and the 1D
 *            column value ρgH²/(3E) printed beside), the horizontal drift of the centre of
 *            mass, its jitter (standard deviation of its height over the last 300 steps) and
 *            the step at which it falls asleep.
 *   tumble   a free 0.4×0.3×0.2 m block (E = 1e5 Pa, ν = 0.3, no gravity, no ground) thrown
 *            by a force at a corner for 0.25 s, then 600 steps free: the largest drift of its
 *            linear momentum Σ m v and of its angular momentum about the centre of mass,
 *            relative to their values when the force ended. Implicit Euler keeps P exactly
 *            with an exact solve (the reference shows the floor); L drifts by the integrator.
 *   drag     a 0.6×0.2×0.2 m cantilever (E = 1e6 Pa, held at x = 0, gravity) whose free top
 *            corner is pulled 0.1 m up by a drag spring (500 N/m) for all 600 steps, and
 *            (curve) along a polyline up and sideways (cubesim drag / curve) over 0.8 of
 *            them: the largest distance of the grabbed node from the reference's over the
 *            run, over the 0.1 m pulled.
 *   fracture a ν = 0.3, E = 1e6 Pa cantilever 1 × 0.1 × 0.1 m (nz = 2, 80 cubes) released
 *            under gravity, fracture on: the strength s_c at which it just breaks within
 *            1.5 s is bisected with the reference tolerance; at 0.7·s_c (stress crossing
 *            steeply) and 0.99·s_c (crossing near the peak) the first fracture's step and
 *            cell are compared with the reference's.
 *   drop     a 0.3 m block (3³ cubes, E = 1e5 Pa, ν = 0.3) dropped from 0.5 m onto the ground:
 *            the largest difference of its centre-of-mass height from the reference's over
 *            the run (over the 0.5 m drop), the rebound (highest centre of mass after the
 *            deepest compression, above where it ends) and when it falls asleep.
 *
 * Every case: implicit Euler, dt 1/60 and 1/240 s, models linear, corotational, mss and
 * localframe, tolerances 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8; one engine thread; CPU seconds
 * (CLOCK_PROCESS_CPUTIME_ID) of the stepping, median of --runs runs.
 * Also (the stability bullet of the work-precision section): mss with central differences at
 * 0.9× the engine's own stated limit on the bench_wp cantilever, nz = 1 and 2, 3.8 periods.
 *
 * --relative-to rhs measures the implicit steps' residual against ‖b‖ as before session 13
 * (the engine's default is the step's ‖b − A v‖; cubesim.h cs_cg_relative).
 *
 * Usage: bench_tol [--runs 3] [--csv FILE] [--quick] [--relative-to step|rhs]
 *        (Markdown tables on stdout)
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench_util.h"
#include "cubesim.h"
#include "lattice.h"

#define NTOL 6
#define STEPS 600
static const double TOLS[NTOL] = {1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8};
static const double REF_TOL = 1e-10;
static const cs_model MODELS[4] = {CS_MODEL_LINEAR, CS_MODEL_COROTATIONAL, CS_MODEL_MSS,
                                   CS_MODEL_LOCALFRAME};

static double cpu_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

/* set once from the command line (--relative-to), before any world is made */
static cs_cg_relative relative_to = CS_CG_RELATIVE_STEP;

static cs_world_t *world(double dt, double tol, double g, bool ground)
{
    cs_world_def wd = cs_world_def_default();
    wd.cg_relative_to = relative_to;
    wd.dt = dt;
    wd.cg_tolerance = tol;
    wd.cg_max_iterations = tol < 1e-9 ? 100000 : 500; /* the reference must converge */
    wd.threads = 1;
    wd.gravity[2] = -g;
    wd.has_ground = ground;
    wd.sleep_steps = 0; /* the cases apply the engine's sleep test themselves (would_sleep) */
    char err[256];
    cs_world_t *w;
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_tol: %s\n", err);
        exit(2);
    }
    return w;
}

typedef struct blk {
    int nx, ny, nz;
    double h, origin[3], young, poisson, strength;
    bool fix_x0, fracture;
} blk;

static cs_object_id add_block(cs_world_t *w, cs_model m, const blk *b)
{
    const int n = b->nx * b->ny * b->nz;
    int32_t *ijk = cs_box_cells(b->nx, b->ny, b->nz);
    cs_object_def d = cs_object_def_default();
    d.name = "block";
    d.model = m;
    d.integrator = CS_INTEGRATOR_IMPLICIT_EULER;
    d.material.young = b->young;
    d.material.poisson = b->poisson;
    d.material.density = 1000;
    if (b->strength > 0)
        d.material.strength = b->strength;
    d.fracture = b->fracture;
    d.cube_size = b->h;
    d.geometry = CS_GEOMETRY_CELLS;
    memcpy(d.cells_origin, b->origin, sizeof d.cells_origin);
    d.cells_ijk = ijk;
    d.n_cells = n;
    const cs_aabb fix = {{b->origin[0] - 1e-3 * b->h, -1e9, -1e9}, {b->origin[0] + 1e-3 * b->h, 1e9, 1e9}};
    if (b->fix_x0) {
        d.fixed = &fix;
        d.n_fixed = 1;
    }
    cs_object_id id;
    char err[256];
    const int rc = cs_world_add_object(w, &d, &id, err, sizeof err);
    free(ijk);
    if (rc != CS_OK) {
        fprintf(stderr, "bench_tol: add: %s\n", err);
        exit(2);
    }
    return id;
}

/* Lumped nodal masses ρh³/8 per cell corner (the masses implicit Euler uses). */
static double *node_masses(cs_world_t *w, cs_object_id id, double rho, double h)
{
    const int32_t *ijk, *nodes;
    int nc, nn;
    const double *rest;
    cs_object_cells(w, id, &ijk, &nodes, &nc);
    cs_object_nodes(w, id, &rest, NULL, NULL, &nn);
    double *m = calloc((size_t)nn, sizeof *m);
    for (int c = 0; c < nc; c++)
        for (int k = 0; k < 8; k++)
            m[nodes[8 * c + k]] += rho * h * h * h / 8;
    return m;
}

static void com(cs_world_t *w, cs_object_id id, const double *m, double c[3])
{
    const double *pos;
    int n;
    cs_object_nodes(w, id, NULL, &pos, NULL, &n);
    double mt = 0;
    c[0] = c[1] = c[2] = 0;
    for (int i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++)
            c[a] += m[i] * pos[3 * i + a];
        mt += m[i];
    }
    for (int a = 0; a < 3; a++)
        c[a] /= mt;
}

static int nearest_node(cs_world_t *w, cs_object_id id, const double p[3])
{
    const double *rest;
    int n, best = 0;
    double bd = INFINITY;
    cs_object_nodes(w, id, &rest, NULL, NULL, &n);
    for (int i = 0; i < n; i++) {
        const double d = hypot(hypot(rest[3 * i] - p[0], rest[3 * i + 1] - p[1]), rest[3 * i + 2] - p[2]);
        if (d < bd) {
            bd = d;
            best = i;
        }
    }
    return best;
}

/* The engine's sleep test with its defaults (fastest node slower than 5e-4 m/s for 30 steps
 * in a row), applied without stopping the object so that its jitter stays measurable: the
 * step at which it would fall asleep (first time), or keeps *sleep_step at -1. */
static void would_sleep(cs_world_t *w, cs_object_id id, int s, int *still, int *sleep_step)
{
    const cs_world_def def = cs_world_def_default();
    const double *vel;
    int n;
    cs_object_nodes(w, id, NULL, NULL, &vel, &n);
    double v2 = 0;
    for (int i = 0; i < 3 * n; i += 3)
        v2 = fmax(v2, vel[i] * vel[i] + vel[i + 1] * vel[i + 1] + vel[i + 2] * vel[i + 2]);
    *still = sqrt(v2) < def.sleep_speed ? *still + 1 : 0;
    if (*still >= def.sleep_steps && *sleep_step < 0)
        *sleep_step = s + 1;
}

static bool step_ok(cs_world_t *w, long *iters)
{
    const int rc = cs_world_step(w);
    *iters += cs_world_last_stats(w)->cg_iterations;
    return rc == CS_OK || rc == CS_ERR_NOT_CONVERGED;
}

/* One run of a case: its metrics, a trajectory (3 doubles per step) to compare with the
 * reference's, CPU seconds and CG iterations. */
typedef struct res {
    double e[4];   /* case-specific metrics (see each case) */
    double *traj;  /* STEPS × 3 */
    double cpu;
    long iters;
    int sleep_step;
    bool failed;
} res;

/* rest: e = {sag [m], |drift xy| [m], jitter [m]} */
static void case_rest(cs_model m, double dt, double tol, res *r)
{
    cs_world_t *w = world(dt, tol, 9.81, true);
    const blk b = {4, 4, 4, 0.1, {0, 0, 0}, 1e5, 0.0, 0, false, false};
    const cs_object_id id = add_block(w, m, &b);
    double *ms = node_masses(w, id, 1000, b.h), c0[3], c[3];
    com(w, id, ms, c0);
    double zs[STEPS];
    int still = 0;
    r->sleep_step = -1;
    const double t0 = cpu_s();
    for (int s = 0; s < STEPS; s++) {
        if (!step_ok(w, &r->iters))
            r->failed = true;
        com(w, id, ms, c);
        zs[s] = c[2];
        memcpy(r->traj + 3 * s, c, sizeof c);
        would_sleep(w, id, s, &still, &r->sleep_step);
    }
    r->cpu = cpu_s() - t0;
    r->e[0] = c0[2] - c[2];
    r->e[1] = hypot(c[0] - c0[0], c[1] - c0[1]);
    double mean = 0, var = 0;
    for (int s = STEPS / 2; s < STEPS; s++)
        mean += zs[s] / (STEPS / 2);
    for (int s = STEPS / 2; s < STEPS; s++)
        var += (zs[s] - mean) * (zs[s] - mean) / (STEPS / 2);
    r->e[2] = sqrt(var);
    free(ms);
    cs_world_destroy(w);
}

static void momenta(cs_world_t *w, cs_object_id id, const double *m, double P[3], double Lm[3])
{
    const double *pos, *vel;
    int n;
    cs_object_nodes(w, id, NULL, &pos, &vel, &n);
    double c[3];
    com(w, id, m, c);
    for (int a = 0; a < 3; a++)
        P[a] = Lm[a] = 0;
    for (int i = 0; i < n; i++) {
        const double *x = pos + 3 * i, *v = vel + 3 * i, d[3] = {x[0] - c[0], x[1] - c[1], x[2] - c[2]};
        for (int a = 0; a < 3; a++)
            P[a] += m[i] * v[a];
        Lm[0] += m[i] * (d[1] * v[2] - d[2] * v[1]);
        Lm[1] += m[i] * (d[2] * v[0] - d[0] * v[2]);
        Lm[2] += m[i] * (d[0] * v[1] - d[1] * v[0]);
    }
}

/* tumble: e = {max |P − P0|/|P0|, max |L − L0|/|L0|} */
static void case_tumble(cs_model m, double dt, double tol, res *r)
{
    cs_world_t *w = world(dt, tol, 0, false);
    const blk b = {4, 3, 2, 0.1, {0, 0, 1}, 1e5, 0.3, 0, false, false};
    const cs_object_id id = add_block(w, m, &b);
    double *ms = node_masses(w, id, 1000, b.h);
    char err[256];
    const double corner[3] = {0.4, 0.3, 1.2}, F[3] = {30, -10, 20};
    cs_world_apply_force(w, id, corner, F, 0.25, err, sizeof err);
    const double t0 = cpu_s();
    int s = 0;
    for (; s * dt < 0.25 - 1e-9; s++)
        step_ok(w, &r->iters);
    double P0[3], L0[3], P[3], Lm[3];
    momenta(w, id, ms, P0, L0);
    r->e[0] = r->e[1] = 0;
    for (int k = 0; k < STEPS; k++) {
        if (!step_ok(w, &r->iters))
            r->failed = true;
        momenta(w, id, ms, P, Lm);
        double dp = 0, dl = 0;
        for (int a = 0; a < 3; a++) {
            dp += (P[a] - P0[a]) * (P[a] - P0[a]);
            dl += (Lm[a] - L0[a]) * (Lm[a] - L0[a]);
        }
        r->e[0] = fmax(r->e[0], sqrt(dp) / sqrt(P0[0] * P0[0] + P0[1] * P0[1] + P0[2] * P0[2]));
        r->e[1] = fmax(r->e[1], sqrt(dl) / sqrt(L0[0] * L0[0] + L0[1] * L0[1] + L0[2] * L0[2]));
        double c[3];
        com(w, id, ms, c);
        memcpy(r->traj + 3 * k, c, sizeof c);
    }
    r->cpu = cpu_s() - t0;
    free(ms);
    cs_world_destroy(w);
}

/* drag (curve = 0: straight, 1: along a polyline): the grabbed node's trajectory. */
static void case_drag(cs_model m, double dt, double tol, int curve, res *r)
{
    cs_world_t *w = world(dt, tol, 9.81, false);
    const blk b = {6, 2, 2, 0.1, {0, 0, 0.5}, 1e6, 0.3, 0, true, false};
    const cs_object_id id = add_block(w, m, &b);
    const double grab[3] = {0.6, 0.2, 0.7};
    const int node = nearest_node(w, id, grab);
    char err[256];
    int rc;
    if (!curve) {
        const double target[3] = {0.6, 0.2, 0.8};
        rc = cs_world_drag(w, id, grab, target, 500, 2 * STEPS * dt, err, sizeof err);
    } else {
        const double pts[9] = {0.6, 0.2, 0.7, 0.6, 0.2, 0.8, 0.6, 0.3, 0.8};
        rc = cs_world_drag_curve(w, id, pts, 3, 500, 0.8 * STEPS * dt, err, sizeof err);
    }
    if (rc != CS_OK) {
        fprintf(stderr, "bench_tol: drag: %s\n", err);
        exit(2);
    }
    const double t0 = cpu_s();
    for (int s = 0; s < STEPS; s++) {
        if (!step_ok(w, &r->iters))
            r->failed = true;
        const double *pos;
        int n;
        cs_object_nodes(w, id, NULL, &pos, NULL, &n);
        memcpy(r->traj + 3 * s, pos + 3 * node, 3 * sizeof(double));
    }
    r->cpu = cpu_s() - t0;
    cs_world_destroy(w);
}

/* fracture: e = {first fracture frame (-1: none), point x, y, z} within 1.5 s. */
static void case_fracture(cs_model m, double dt, double tol, double strength, res *r)
{
    cs_world_t *w = world(dt, tol, 9.81, false);
    const blk b = {20, 2, 2, 0.05, {0, 0, 0}, 1e6, 0.3, strength, true, true};
    const cs_object_id id = add_block(w, m, &b);
    const int steps = (int)ceil(1.5 / dt);
    r->e[0] = -1;
    r->e[1] = r->e[2] = r->e[3] = NAN;
    const double t0 = cpu_s();
    for (int s = 0; s < steps; s++) {
        if (!step_ok(w, &r->iters))
            r->failed = true;
        int ne;
        const cs_event *ev = cs_world_events(w, &ne);
        for (int k = 0; k < ne; k++)
            if (ev[k].kind == CS_EVENT_FRACTURE && ev[k].object == id) {
                r->e[0] = (double)ev[k].frame;
                memcpy(r->e + 1, ev[k].point, 3 * sizeof(double));
                break;
            }
        if (r->e[0] >= 0)
            break;
    }
    r->cpu = cpu_s() - t0;
    cs_world_destroy(w);
}

/* drop: e = {rebound [m], lowest centre of mass [m], lowest node [m]}; traj = the centre of mass. */
static void case_drop(cs_model m, double dt, double tol, res *r)
{
    cs_world_t *w = world(dt, tol, 9.81, true);
    const blk b = {3, 3, 3, 0.1, {0, 0, 0.5}, 1e5, 0.3, 0, false, false};
    const cs_object_id id = add_block(w, m, &b);
    double *ms = node_masses(w, id, 1000, b.h), c[3];
    double zc[STEPS], zlow = INFINITY;
    int still = 0;
    r->sleep_step = -1;
    const double t0 = cpu_s();
    for (int s = 0; s < STEPS; s++) {
        if (!step_ok(w, &r->iters))
            r->failed = true;
        com(w, id, ms, c);
        zc[s] = c[2];
        memcpy(r->traj + 3 * s, c, sizeof c);
        const double *pos;
        int n;
        cs_object_nodes(w, id, NULL, &pos, NULL, &n);
        for (int i = 0; i < n; i++)
            zlow = fmin(zlow, pos[3 * i + 2]);
        would_sleep(w, id, s, &still, &r->sleep_step);
    }
    r->cpu = cpu_s() - t0;
    /* deepest compression within 0.5 s of the impact (t ≈ 0.32 s), then the highest after it */
    int kmin = 0;
    const int kend = (int)fmin(STEPS, ceil(0.9 / dt));
    for (int s = 1; s < kend; s++)
        if (zc[s] < zc[kmin])
            kmin = s;
    double zmax = zc[kmin];
    for (int s = kmin; s < STEPS; s++)
        zmax = fmax(zmax, zc[s]);
    r->e[0] = zmax - zc[STEPS - 1];
    r->e[1] = zc[kmin];
    r->e[2] = zlow;
    free(ms);
    cs_world_destroy(w);
}

enum { C_REST, C_TUMBLE, C_DRAG, C_CURVE, C_FRAC_STEEP, C_FRAC_PEAK, C_DROP, NCASE };
static const char *CASE_NAME[NCASE] = {"rest", "tumble", "drag", "curve", "fracture_0.7", "fracture_0.99", "drop"};

static void run_case(int c, cs_model m, double dt, double tol, double strength, res *r)
{
    double *traj = r->traj;
    memset(r, 0, sizeof *r);
    r->traj = traj;
    memset(r->traj, 0, sizeof(double) * 3 * STEPS);
    switch (c) {
    case C_REST: case_rest(m, dt, tol, r); break;
    case C_TUMBLE: case_tumble(m, dt, tol, r); break;
    case C_DRAG: case_drag(m, dt, tol, 0, r); break;
    case C_CURVE: case_drag(m, dt, tol, 1, r); break;
    case C_FRAC_STEEP:
    case C_FRAC_PEAK: case_fracture(m, dt, tol, strength, r); break;
    default: case_drop(m, dt, tol, r); break;
    }
}

static double traj_diff(const res *a, const res *ref)
{
    double d = 0;
    for (int s = 0; s < STEPS; s++) {
        const double *p = a->traj + 3 * s, *q = ref->traj + 3 * s;
        d = fmax(d, sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2])));
    }
    return d;
}

/* The headline error of a run against the reference run (relative; see the header). */
static double headline(int c, const res *r, const res *ref)
{
    switch (c) {
    case C_REST: return fabs(r->e[0] - ref->e[0]) / fabs(ref->e[0]);
    case C_TUMBLE: return r->e[0];
    case C_DRAG:
    case C_CURVE: return traj_diff(r, ref) / 0.1;
    case C_FRAC_STEEP:
    case C_FRAC_PEAK: return fabs(r->e[0] - ref->e[0]);
    default: return traj_diff(r, ref) / 0.5;
    }
}

/* Critical strength: the largest at which the reference breaks within 1.5 s (log bisection). */
static double critical_strength(cs_model m, double dt, res *tmp)
{
    double lo = 1e4, hi = 3e6; /* breaks at lo, not at hi */
    for (int it = 0; it < 16; it++) {
        const double mid = sqrt(lo * hi);
        run_case(C_FRAC_STEEP, m, dt, REF_TOL, mid, tmp);
        if (tmp->e[0] >= 0)
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

/* mss, central differences at 0.9× the engine's own limit on the bench_wp cantilever. */
static void explicit_limit_check(void)
{
    printf("\n**mss, central differences at 0.9 × the engine's stated limit** (bench_wp cantilever, E = 1e6 Pa, ν = 0, g = 0.01 m/s², 3.8 periods of 1.96 s)\n\n");
    printf("| nz | engine limit [s] | dt [s] | steps | result | max |tip z| [m] |\n|---|---|---|---|---|---|\n");
    for (int nz = 1; nz <= 2; nz++) {
        char err[512];
        double limit = NAN;
        for (int pass = 0; pass < 2; pass++) {
            cs_world_def wd = cs_world_def_default();
            wd.dt = pass == 0 ? 0.5 : 0.9 * limit;
            wd.threads = 1;
            wd.sleep_steps = 0;
            wd.gravity[2] = -0.01;
            cs_world_t *w;
            cs_world_create(&wd, &w, err, sizeof err);
            const int nx = 10 * nz, n = nx * nz * nz;
            const double h = 0.1 / nz;
            int32_t *ijk = cs_box_cells(nx, nz, nz);
            cs_object_def d = cs_object_def_default();
            d.name = "beam";
            d.model = CS_MODEL_MSS;
            d.integrator = CS_INTEGRATOR_CENTRAL_DIFFERENCE;
            d.material.young = 1e6;
            d.material.poisson = 0;
            d.cube_size = h;
            d.geometry = CS_GEOMETRY_CELLS;
            d.cells_ijk = ijk;
            d.n_cells = n;
            const cs_aabb fix = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1, 1}};
            d.fixed = &fix;
            d.n_fixed = 1;
            cs_object_id id;
            const int rc = cs_world_add_object(w, &d, &id, err, sizeof err);
            free(ijk);
            if (pass == 0) {
                const char *p = strstr(err, "limit ");
                limit = p ? atof(p + 6) : NAN;
                cs_world_destroy(w);
                if (rc == CS_OK || !isfinite(limit)) {
                    printf("| %d | ? | — | — | could not read the limit (%s) | — |\n", nz, rc == CS_OK ? "accepted" : err);
                    break;
                }
                continue;
            }
            if (rc != CS_OK) {
                printf("| %d | %.4g | %.4g | 0 | refused: %s | — |\n", nz, limit, wd.dt, err);
                cs_world_destroy(w);
                break;
            }
            const int steps = (int)ceil(3.8 * 1.96 / wd.dt);
            double zmax = 0;
            int s, bad = 0;
            for (s = 0; s < steps && !bad; s++) {
                const int src = cs_world_step(w);
                const double *rest, *pos;
                int nn;
                cs_object_nodes(w, id, &rest, &pos, NULL, &nn);
                for (int i = 0; i < nn; i++)
                    if (fabs(rest[3 * i] - 1.0) < 1e-9)
                        zmax = fmax(zmax, fabs(pos[3 * i + 2] - rest[3 * i + 2]));
                if (src != CS_OK || !isfinite(zmax) || zmax > 1)
                    bad = 1;
            }
            printf("| %d | %.4g | %.4g | %d | %s | %.3g |\n", nz, limit, wd.dt, s,
                   bad ? "diverged" : "stable", zmax);
            cs_world_destroy(w);
        }
    }
}

int main(int argc, char **argv)
{
    int runs = 3, quick = 0;
    const char *csv = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--csv") && i + 1 < argc)
            csv = argv[++i];
        else if (!strcmp(argv[i], "--quick"))
            quick = 1;
        else if (!strcmp(argv[i], "--relative-to") && i + 1 < argc &&
                 cs_cg_relative_from_name(argv[i + 1], &relative_to) == 0)
            i++;
        else {
            fprintf(stderr, "usage: bench_tol [--runs 3] [--csv FILE] [--quick] [--relative-to step|rhs]\n");
            return 2;
        }
    }
    if (runs < 1)
        runs = 1;
    FILE *f = csv ? fopen(csv, "w") : NULL;
    if (csv && !f) {
        perror(csv);
        return 2;
    }
    if (f)
        fprintf(f, "case,model,dt,tol,cpu_s,cpu_runs,cg_iterations,error,m0,m1,m2,m3,sleep_step,failed\n");
    const double dts[2] = {1.0 / 60, 1.0 / 240};
    const int nm = quick ? 2 : 4, ndt = quick ? 1 : 2;
    /* per case and tolerance: worst headline error over models and dts, CPU summed over them */
    static double worst[NCASE][NTOL], cpu_sum[NCASE][NTOL], worst_l[NTOL], worst_l_ref = 0, worst_p_ref = 0;
    static long it_sum[NCASE][NTOL];
    static int sleep_mis[NCASE][NTOL], frac_cell_mis[NCASE][NTOL], fails[NCASE][NTOL];
    res ref = {.traj = malloc(sizeof(double) * 3 * STEPS)}, r = {.traj = malloc(sizeof(double) * 3 * STEPS)};
    double cpus[16];
    fprintf(stderr, "bench_tol: reference tolerance %g; %d runs per setting (CPU median)\n", REF_TOL, runs);
    for (int mi = 0; mi < nm; mi++)
        for (int di = 0; di < ndt; di++) {
            const cs_model m = MODELS[mi];
            const double dt = dts[di];
            const double sc = critical_strength(m, dt, &r);
            fprintf(stderr, "%s dt 1/%.0f: critical strength %.6g Pa\n", cs_model_name(m), 1 / dt, sc);
            for (int c = 0; c < NCASE; c++) {
                const double strength = c == C_FRAC_STEEP ? 0.7 * sc : c == C_FRAC_PEAK ? 0.99 * sc : 0;
                run_case(c, m, dt, REF_TOL, strength, &ref);
                fprintf(stderr, "%s %s dt 1/%.0f ref: %g %g %g %g sleep %d cpu %.3g s, %ld it\n", CASE_NAME[c],
                        cs_model_name(m), 1 / dt, ref.e[0], ref.e[1], ref.e[2], ref.e[3], ref.sleep_step, ref.cpu,
                        ref.iters);
                if (f)
                    fprintf(f, "%s,%s,%.6g,%g,%.6g,1,%ld,0,%.6g,%.6g,%.6g,%.6g,%d,%d\n", CASE_NAME[c],
                            cs_model_name(m), dt, REF_TOL, ref.cpu, ref.iters, ref.e[0], ref.e[1], ref.e[2],
                            ref.e[3], ref.sleep_step, ref.failed);
                for (int t = 0; t < NTOL; t++) {
                    for (int k = 0; k < runs; k++) {
                        run_case(c, m, dt, TOLS[t], strength, &r);
                        cpus[k] = r.cpu;
                    }
                    const double cpu = median(cpus, runs), err = headline(c, &r, &ref);
                    worst[c][t] = fmax(worst[c][t], err);
                    if (c == C_TUMBLE) {
                        worst_l[t] = fmax(worst_l[t], r.e[1]);
                        worst_l_ref = fmax(worst_l_ref, ref.e[1]);
                        worst_p_ref = fmax(worst_p_ref, ref.e[0]);
                    }
                    cpu_sum[c][t] += cpu;
                    it_sum[c][t] += r.iters;
                    if (r.sleep_step >= 0 ? ref.sleep_step < 0 || abs(r.sleep_step - ref.sleep_step) > 30
                                          : ref.sleep_step >= 0)
                        sleep_mis[c][t]++;
                    if ((c == C_FRAC_STEEP || c == C_FRAC_PEAK) && ref.e[0] >= 0 &&
                        !(r.e[0] >= 0 && hypot(hypot(r.e[1] - ref.e[1], fabs(r.e[2] - 0.05) - fabs(ref.e[2] - 0.05)),
                                              r.e[3] - ref.e[3]) < 0.01))
                        frac_cell_mis[c][t]++;
                    fails[c][t] += r.failed;
                    fprintf(stderr, "%s %s dt 1/%.0f tol %g: err %.3g (%g %g %g %g) sleep %d cpu %.3g s, %ld it%s\n",
                            CASE_NAME[c], cs_model_name(m), 1 / dt, TOLS[t], err, r.e[0], r.e[1], r.e[2], r.e[3],
                            r.sleep_step, cpu, r.iters, r.failed ? " FAILED" : "");
                    if (f)
                        fprintf(f, "%s,%s,%.6g,%g,%.6g,%d,%ld,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%d\n", CASE_NAME[c],
                                cs_model_name(m), dt, TOLS[t], cpu, runs, r.iters, err, r.e[0], r.e[1], r.e[2],
                                r.e[3], r.sleep_step, r.failed);
                }
            }
        }
    if (f)
        fclose(f);
    free(ref.traj);
    free(r.traj);
    printf("**CG tolerance across the engine** (implicit Euler; worst error over %d models × %d time steps "
           "against the same setting at tolerance %g; CPU: seconds summed over them, median of %d runs, "
           "in brackets relative to 1e-6; implicit steps' residual relative to %s)\n\n",
           nm, ndt, REF_TOL, runs,
           relative_to == CS_CG_RELATIVE_STEP ? "the step's ‖b − A v‖" : "‖b‖");
    printf("| tolerance |");
    for (int c = 0; c < NCASE; c++)
        printf(" %s |", CASE_NAME[c]);
    printf("\n|---|");
    for (int c = 0; c < NCASE; c++)
        printf("---|");
    printf("\n");
    for (int t = 0; t < NTOL; t++) {
        printf("| %g |", TOLS[t]);
        for (int c = 0; c < NCASE; c++) {
            if (c == C_FRAC_STEEP || c == C_FRAC_PEAK)
                printf(" Δstep ≤ %.0f%s", worst[c][t], frac_cell_mis[c][t] ? " (other cell)" : "");
            else if (c == C_TUMBLE)
                printf(" P %.2g, L %.2g", worst[c][t], worst_l[t]);
            else
                printf(" %.2g", worst[c][t]);
            if (sleep_mis[c][t] && (c == C_REST || c == C_DROP))
                printf(", sleep differs ×%d", sleep_mis[c][t]);
            if (fails[c][t])
                printf(", %d failed", fails[c][t]);
            printf("; %.3g s (%.2f) |", cpu_sum[c][t], cpu_sum[c][t] / cpu_sum[c][4]);
        }
        printf("\n");
    }
    printf("\nErrors: rest — |sag − sag_ref|/sag_ref; tumble — max |P − P₀|/|P₀| and max |L − L₀|/|L₀| (the reference's own: P %.1g, L %.2g); "
           "drag, curve — max distance of the grabbed node from the reference's over 0.1 m; fracture — |first fracture "
           "step − reference's| (other cell: a different cell or none); drop — max |z_com − z_com,ref| over 0.5 m. "
           "\"sleep differs\": the engine's sleep test (5e-4 m/s for 30 steps) first held more than 30 steps from when the reference's did (or for only one of them).\n",
           worst_p_ref, worst_l_ref);
    explicit_limit_check();
    return 0;
}
