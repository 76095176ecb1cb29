/*
 * test_tolerance.c — the default CG tolerance (1e-4 since issue 6 part 3; README "Defaults
 * (issue 6 part 3)", bench/bench_tol.c for the full evidence) against the laws and the tight
 * solves it must still honour: a thrown block's linear momentum (exactly conserved by implicit
 * Euler with an exact solve), its angular momentum against the integrator's own drift, and a
 * brittle cantilever's first fracture (same step, same cell as a 1e-10 solve).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "lattice.h"

static cs_world_t *make_world(double tol, double g, double dt)
{
    cs_world_def wd = cs_world_def_default();
    if (dt > 0)
        wd.dt = dt;
    if (tol > 0) {
        wd.cg_tolerance = tol;
        wd.cg_max_iterations = 100000;
    }
    wd.gravity[2] = -g;
    wd.threads = 1;
    wd.sleep_steps = 0;
    cs_world_t *w = NULL;
    if (cs_world_create(&wd, &w, NULL, 0) != CS_OK)
        return NULL;
    return w;
}

static int add_box(cs_world_t *w, int nx, int ny, int nz, double h, double z0, double young,
                   double strength, bool held, cs_object_id *id)
{
    const int n = nx * ny * nz;
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    if (!ijk)
        return CS_ERR_NOMEM;
    cs_object_def d = cs_object_def_default();
    d.name = "box";
    d.model = CS_MODEL_COROTATIONAL;
    d.integrator = CS_INTEGRATOR_IMPLICIT_EULER;
    d.material.young = young;
    d.material.poisson = 0.3;
    if (strength > 0) {
        d.material.strength = strength;
        d.fracture = true;
    }
    d.cube_size = h;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_origin[2] = z0;
    d.cells_ijk = ijk;
    d.n_cells = n;
    const cs_aabb fix = {{-1e-3 * h, -1e9, -1e9}, {1e-3 * h, 1e9, 1e9}};
    if (held) {
        d.fixed = &fix;
        d.n_fixed = 1;
    }
    const int rc = cs_world_add_object(w, &d, id, NULL, 0);
    free(ijk);
    return rc;
}

/* P = Σ m v and L = Σ m (x − c) × v with the lumped masses ρh³/8 per cell corner. */
static void momenta(cs_world_t *w, cs_object_id id, double h, double P[3], double L[3])
{
    const int32_t *cells;
    const double *x, *v;
    int nc, n;
    cs_object_cells(w, id, NULL, &cells, &nc);
    cs_object_nodes(w, id, NULL, &x, &v, &n);
    double *m = calloc((size_t)n, sizeof *m), c[3] = {0, 0, 0}, mt = 0;
    for (int k = 0; k < 8 * nc; k++)
        m[cells[k]] += 1000 * h * h * h / 8;
    for (int i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++)
            c[a] += m[i] * x[3 * i + a];
        mt += m[i];
    }
    for (int a = 0; a < 3; a++)
        c[a] /= mt, P[a] = L[a] = 0;
    for (int i = 0; i < n; i++) {
        const double *vi = v + 3 * i, d[3] = {x[3 * i] - c[0], x[3 * i + 1] - c[1], x[3 * i + 2] - c[2]};
        for (int a = 0; a < 3; a++)
            P[a] += m[i] * vi[a];
        L[0] += m[i] * (d[1] * vi[2] - d[2] * vi[1]);
        L[1] += m[i] * (d[2] * vi[0] - d[0] * vi[2]);
        L[2] += m[i] * (d[0] * vi[1] - d[1] * vi[0]);
    }
    free(m);
}

/* Thrown by a force at a corner for 0.25 s, then 600 free steps of dt: largest relative
 * drifts. */
static int tumble(double tol, double dt, double *dp, double *dl)
{
    cs_world_t *w = make_world(tol, 0, dt);
    cs_object_id id;
    if (!w || add_box(w, 4, 3, 2, 0.1, 1, 1e5, 0, false, &id) != CS_OK)
        return -1;
    const double corner[3] = {0.4, 0.3, 1.2}, F[3] = {30, -10, 20};
    if (cs_world_apply_force(w, id, corner, F, 0.25, NULL, 0) != CS_OK)
        return -1;
    for (int s = 0; s < (int)(0.25 / dt + 0.5); s++)
        if (cs_world_step(w) != CS_OK)
            return -1;
    double P0[3], L0[3], P[3], L[3];
    momenta(w, id, 0.1, P0, L0);
    *dp = *dl = 0;
    for (int s = 0; s < 600; s++) {
        if (cs_world_step(w) != CS_OK)
            return -1;
        momenta(w, id, 0.1, P, L);
        *dp = fmax(*dp, hypot(hypot(P[0] - P0[0], P[1] - P0[1]), P[2] - P0[2]) / hypot(hypot(P0[0], P0[1]), P0[2]));
        *dl = fmax(*dl, hypot(hypot(L[0] - L0[0], L[1] - L0[1]), L[2] - L0[2]) / hypot(hypot(L0[0], L0[1]), L0[2]));
    }
    cs_world_destroy(w);
    return 0;
}

TEST(tolerance_default_keeps_momentum_of_a_tumbling_block)
{
    ENSURE(cs_world_def_default().cg_tolerance <= 1e-4);
    ENSURE(cs_world_def_default().cg_relative_to == CS_CG_RELATIVE_STEP);
    /* dt 1/60 and 1/240 s: with the tolerance relative to ‖b‖ = ‖M v + dt f‖ (mostly momentum
     * at small dt) the warm-started solve stopped after 1.2 iterations a step at 1/240 and L
     * drifted 2.8 % (bench_tol, session 12); relative to the step's own ‖b − A v‖ it takes 3.2
     * and drifts 0.03 %, the integrator's own */
    const double dts[2] = {1.0 / 60, 1.0 / 240};
    for (int k = 0; k < 2; k++) {
        double dp, dl, dp_ref, dl_ref;
        ENSURE(tumble(0, dts[k], &dp, &dl) == 0);
        ENSURE(tumble(1e-10, dts[k], &dp_ref, &dl_ref) == 0);
        /* exact solve: P conserved to round-off; the default's residual may move it by 1.1e-5
         * (dt 1/60) and 4.5e-6 (1/240) here; 1e-3 lets it reach 1.4e-4 */
        ENSURE_MSG(dp_ref < 1e-8, "dt %g: reference P drift %g", dts[k], dp_ref);
        ENSURE_MSG(dp < 5e-5, "dt %g: P drift %g over 600 steps at the default tolerance",
                   dts[k], dp);
        /* L: the integrator's own drift is 0.075 % (1/60), 0.033 % (1/240); the default may
         * add at most 1.5× that (measured: 0.049 % and 0.030 %; 1e-3 gives 0.84 % at 1/60) */
        ENSURE_MSG(dl_ref < 1e-3 && dl < 1.5 * dl_ref, "dt %g: L drift %g against the exact solve's %g",
                   dts[k], dl, dl_ref);
    }
}

/* A 1 × 0.1 × 0.1 m cantilever released under gravity at 0.9 of its critical strength (about
 * 118 kPa at dt 1/60 s, bench_tol): frame and cell centre of its first fracture. */
static int first_fracture(double tol, int64_t *frame, double p[3])
{
    cs_world_t *w = make_world(tol, 9.81, 0);
    cs_object_id id;
    if (!w || add_box(w, 20, 2, 2, 0.05, 0, 1e6, 0.9 * 118460, true, &id) != CS_OK)
        return -1;
    *frame = -1;
    for (int s = 0; s < 90 && *frame < 0; s++) {
        if (cs_world_step(w) != CS_OK)
            return -1;
        int ne;
        const cs_event *ev = cs_world_events(w, &ne);
        for (int k = 0; k < ne; k++)
            if (ev[k].kind == CS_EVENT_FRACTURE && *frame < 0) {
                *frame = ev[k].frame;
                memcpy(p, ev[k].point, sizeof(double) * 3);
            }
    }
    cs_world_destroy(w);
    return 0;
}

TEST(tolerance_default_breaks_like_the_exact_solve)
{
    int64_t f, f_ref;
    double p[3], p_ref[3];
    ENSURE(first_fracture(0, &f, p) == 0);
    ENSURE(first_fracture(1e-10, &f_ref, p_ref) == 0);
    ENSURE_MSG(f_ref > 5, "the reference must break during the swing, not at once (frame %lld)", (long long)f_ref);
    ENSURE_MSG(f == f_ref, "first fracture at frame %lld, the exact solve at %lld", (long long)f, (long long)f_ref);
    /* the same cell, or its mirror image across the beam's plane y = 0.05 */
    ENSURE_NEAR(p[0], p_ref[0], 1e-3);
    ENSURE_NEAR(fabs(p[1] - 0.05), fabs(p_ref[1] - 0.05), 1e-3);
    ENSURE_NEAR(p[2], p_ref[2], 1e-3);
}
