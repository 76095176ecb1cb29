/*
 * bench_localframe.c — accuracy and cost of the localframe model (seed 001) against
 * corotational FEM on the same cube meshes.
 *
 * Accuracy: a ν = 0 cantilever (L = 0.5 m, H = 0.1 m, nz cubes through the thickness,
 * 5·nz along it) under pure bending, whose exact 3D answer is known: the tip deflection
 * κL²/2 (u = (−κxz, 0, κx²/2) with the clamped end u(0) = 0). Static solves.
 * Cost: the static solve, and the wall time per simulated second of the loaded beam swinging
 * (E = 1e6 Pa, ρ = 1000 kg/m³): localframe with its central differences at 0.9 × its
 * stability limit and with implicit Euler at dt = 1/60 s (its lumped mass; since session 46
 * multigrid-preconditioned like FEM), corotational FEM with implicit Euler at dt = 1/60 s and
 * with central differences at 0.9 × its limit. One thread, CG tolerance 1e-6 (the scene default).
 *
 * Usage: bench_localframe [--sizes 2,3,4,6] [--runs 3] [--csv FILE]
 * Prints a Markdown table; the CSV has one row per (model, nz).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench_util.h"
#include "cubesim.h"
#include "localframe.h"
#include "lattice.h"

static const double L = 0.5, H = 0.1, E = 1e6, RHO = 1000, KAPPA = 0.008;

static cs_world_t *beam(cs_model model, cs_integrator integ, int nz, double dt, cs_object_id *id)
{
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = 0;
    wd.dt = dt;
    wd.threads = 1;
    wd.sleep_steps = 0;
    wd.cg_tolerance = 1e-6; /* the scene default (statics: no looser than 1e-8 anyway) */
    wd.cg_max_iterations = 20000;
    cs_world_t *w;
    char err[256];
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK)
        return NULL;
    const int nx = 5 * nz, n = nx * nz * nz;
    const double h = H / nz;
    int32_t *ijk = cs_box_cells(nx, nz, nz);
    cs_object_def d = cs_object_def_default();
    d.name = "beam";
    d.model = model;
    d.integrator = integ;
    d.material.young = E;
    d.material.poisson = 0.0;
    d.material.density = RHO;
    d.cube_size = h;
    d.cells_ijk = ijk;
    d.n_cells = n;
    cs_aabb fix = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1e3, 1e3}};
    cs_load loads[64];
    for (int k = 0; k < nz; k++) {
        const double zc = (k + 0.5) * h - 0.5 * H;
        loads[k] = (cs_load){{{nx * h - 1e-3 * h, -1, k * h + 1e-3 * h},
                              {nx * h + 1e-3 * h, 1e3, (k + 1) * h - 1e-3 * h}},
                             {-E * KAPPA * zc * H * h, 0, 0}};
    }
    d.fixed = &fix;
    d.n_fixed = 1;
    d.loads = loads;
    d.n_loads = nz;
    int rc = cs_world_add_object(w, &d, id, err, sizeof err);
    free(ijk);
    if (rc != CS_OK) {
        fprintf(stderr, "bench_localframe: %s\n", err);
        cs_world_destroy(w);
        return NULL;
    }
    return w;
}

static double tip_error(cs_world_t *w, cs_object_id id)
{
    const double *rest, *pos;
    int n, cnt = 0;
    double s = 0;
    cs_object_nodes(w, id, &rest, &pos, NULL, &n);
    for (int i = 0; i < n; i++)
        if (fabs(rest[3 * i] - L) < 1e-9) {
            s += pos[3 * i + 2] - rest[3 * i + 2];
            cnt++;
        }
    const double exact = KAPPA * L * L / 2;
    return (s / cnt - exact) / exact;
}

/* Wall seconds per simulated second, over `sim` simulated seconds (at least 5 steps). */
static double dynamic_cost(cs_model model, cs_integrator integ, int nz, double dt, double sim,
                           double *used_dt)
{
    cs_object_id id;
    cs_world_t *w = beam(model, integ, nz, dt, &id);
    if (!w)
        return NAN;
    int steps = (int)ceil(sim / dt);
    if (steps < 5)
        steps = 5;
    const double t0 = now_s();
    long iters = 0;
    for (int s = 0; s < steps; s++) {
        cs_world_step(w);
        iters += cs_world_last_stats(w)->cg_iterations;
    }
    const double t = now_s() - t0;
    fprintf(stderr, "  %s %s nz %d: %.1f CG iterations per step, %.3f ms per step\n",
            cs_model_name(model), cs_integrator_name(integ), nz, (double)iters / steps,
            1e3 * t / steps);
    cs_world_destroy(w);
    *used_dt = dt;
    return t / (steps * dt);
}

int main(int argc, char **argv)
{
    int sizes[16] = {2, 3, 4, 6}, ns = 4, runs = 3;
    const char *csv = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--sizes") && i + 1 < argc)
            ns = parse_list(argv[++i], sizes, 16);
        else if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--csv") && i + 1 < argc)
            csv = argv[++i];
        else {
            fprintf(stderr, "usage: bench_localframe [--sizes 2,3,4,6] [--runs 3] [--csv FILE]\n");
            return 2;
        }
    }
    if (runs < 1)
        runs = 1;
    FILE *f = csv ? fopen(csv, "w") : NULL;
    if (f)
        fprintf(f, "model,nz,cells,error_pct,static_ms,cd_dt,cd_s_per_s,ie_s_per_s\n");
    printf("| model | nz | cubes | tip error (pure bending) | static solve ms | central diff. dt | "
           "wall s per simulated s, central diff. | wall s per simulated s, implicit Euler 1/60 |\n");
    printf("|---|---|---|---|---|---|---|---|\n");
    const cs_model models[2] = {CS_MODEL_LOCALFRAME, CS_MODEL_COROTATIONAL};
    for (int si = 0; si < ns; si++)
        for (int m = 0; m < 2; m++) {
            const int nz = sizes[si];
            double err = NAN, ms[16];
            for (int r = 0; r < runs && r < 16; r++) {
                cs_object_id id;
                cs_world_t *w = beam(models[m], CS_INTEGRATOR_IMPLICIT_EULER, nz, 1.0 / 60, &id);
                ms[r] = NAN;
                if (!w)
                    continue;
                const double t0 = now_s();
                cs_world_solve_static(w);
                ms[r] = (now_s() - t0) * 1e3;
                err = tip_error(w, id);
                cs_world_destroy(w);
            }
            double w2, used = NAN;
            cs_lf_omega2_bound(models[m], E, 0.0, RHO, H / nz, &w2);
            const double cd_dt = 0.9 * 2 / sqrt(w2);
            const double cd = dynamic_cost(models[m], CS_INTEGRATOR_CENTRAL_DIFFERENCE, nz, cd_dt,
                                           0.05, &used);
            const double ie = dynamic_cost(models[m], CS_INTEGRATOR_IMPLICIT_EULER, nz, 1.0 / 60,
                                           0.5, &used);
            const double sms = median(ms, runs < 16 ? runs : 16);
            const int cells = 5 * nz * nz * nz;
            printf("| %s | %d | %d | %+.2f %% | %.1f | %.3g s | %.2f | %.2f |\n",
                   cs_model_name(models[m]), nz, cells, 100 * err, sms, cd_dt, cd, ie);
            if (f)
                fprintf(f, "%s,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g\n", cs_model_name(models[m]), nz,
                        cells, 100 * err, sms, cd_dt, cd, ie);
            fflush(stdout);
        }
    if (f)
        fclose(f);
    return 0;
}
