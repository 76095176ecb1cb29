/*
 * bench_active.c — what active regions (world.c "active regions", scene "active") save.
 *
 * A 1 m corotational block of n³ cubes (bottom face held, no gravity, E = 1e5 Pa, ν = 0.3,
 * ρ = 1000 kg/m³, damping [2, 0.01], dt = 1/60, solver tolerance 1e-6) at rest: with active
 * regions every node freezes within active_steps steps. Then a force pokes the top corner
 * (1, 1, 1) for `steps` steps; the same is run with active regions off. Reported per run: CPU
 * time per poked step (CLOCK_PROCESS_CPUTIME_ID: the machine may be loaded), CG iterations per
 * step, mean and largest fraction of cells in the element passes, and the largest difference
 * of the active run's nodes from the all-active run's over the poke, against the largest
 * displacement. The poke's size sets the active fraction (the region is where nodes move
 * faster than active.speed).
 *
 * --from S: time and count only the poke's steps S.. (the region has stopped growing).
 *
 * Usage: bench_active [--n 32] [--force 0.05] [--steps 20] [--from 0] [--threads 1]
 *                     [--speed 5e-4]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cubesim.h"
#include "lattice.h"

static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

typedef struct run {
    cs_world_t *w;
    cs_object_id id;
    double cpu, iters, act_mean, act_max;
} run;

static int make(run *r, int n, int threads, int active_steps, double speed)
{
    char err[256];
    memset(r, 0, sizeof *r);
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = 0;
    wd.threads = threads;
    wd.sleep_steps = 0;
    wd.active_steps = active_steps;
    wd.active_speed = speed;
    if (cs_world_create(&wd, &r->w, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_active: %s\n", err);
        return -1;
    }
    const int nc = n * n * n;
    int32_t *ijk = cs_box_cells(n, n, n);
    cs_object_def d = cs_object_def_default();
    d.name = "block";
    d.cube_size = 1.0 / n;
    d.material.young = 1e5;
    d.material.damping[0] = 2.0;
    d.material.damping[1] = 0.01;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = nc;
    cs_aabb fix = {{-1, -1, -1e-3 / n}, {2, 2, 1e-3 / n}};
    d.fixed = &fix;
    d.n_fixed = 1;
    const int rc = cs_world_add_object(r->w, &d, &r->id, err, sizeof err);
    free(ijk);
    if (rc != CS_OK) {
        fprintf(stderr, "bench_active: %s\n", err);
        return -1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    int n = 32, steps = 20, threads = 1, from = 0;
    double force = 0.05, speed = 5e-4;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--n"))
            n = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--force"))
            force = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--steps"))
            steps = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--threads"))
            threads = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--from"))
            from = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--speed"))
            speed = atof(argv[i + 1]);
        else {
            fprintf(stderr, "usage: bench_active [--n N] [--force F] [--steps S] [--threads T] "
                            "[--speed V]\n");
            return 2;
        }
    }
    run R[2];
    if (make(&R[0], n, threads, 10, speed) || make(&R[1], n, threads, 0, speed))
        return 1;
    for (int k = 0; k < 2; k++)
        for (int s = 0; s < 12; s++)
            cs_world_step(R[k].w);
    const double corner[3] = {1, 1, 1}, f[3] = {-force, -0.5 * force, -1.5 * force};
    char err[256];
    for (int k = 0; k < 2; k++)
        if (cs_world_apply_force(R[k].w, R[k].id, corner, f, 1.0, err, sizeof err) != CS_OK) {
            fprintf(stderr, "bench_active: %s\n", err);
            return 1;
        }
    int nn;
    const double *rest, *xa, *xf;
    cs_object_nodes(R[0].w, R[0].id, &rest, &xa, NULL, &nn);
    cs_object_nodes(R[1].w, R[1].id, &rest, &xf, NULL, &nn);
    double worst = 0, dmax = 0;
    for (int s = 0; s < steps; s++) {
        for (int k = 0; k < 2; k++) {
            const double t0 = cpu_s();
            if (cs_world_step(R[k].w) != CS_OK) {
                fprintf(stderr, "bench_active: step failed\n");
                return 1;
            }
            const double t1 = cpu_s();
            const cs_step_stats *st = cs_world_last_stats(R[k].w);
            const double a = (double)st->cells_stepped / st->cells_awake;
            if (getenv("BENCH_ACTIVE_TRACE"))
                printf("  step %d run %d: active %.3f it %d cpu %.1f ms\n", s, k, a,
                       st->cg_iterations, 1e3 * (t1 - t0));
            if (s < from)
                continue;
            R[k].cpu += t1 - t0;
            R[k].iters += st->cg_iterations;
            R[k].act_mean += a / (steps - from);
            if (a > R[k].act_max)
                R[k].act_max = a;
        }
        for (int i = 0; i < nn; i++) {
            double d = 0, m = 0;
            for (int a = 0; a < 3; a++) {
                d += pow(xa[3 * i + a] - xf[3 * i + a], 2);
                m += pow(xf[3 * i + a] - rest[3 * i + a], 2);
            }
            worst = fmax(worst, sqrt(d));
            dmax = fmax(dmax, sqrt(m));
        }
    }
    printf("| run | cells active (mean / max) | CPU ms per step | CG iterations per step |\n");
    printf("|---|---|---|---|\n");
    const char *name[2] = {"active regions", "all active"};
    for (int k = 0; k < 2; k++)
        printf("| %s | %.1f %% / %.1f %% | %.1f | %.1f |\n", name[k], 100 * R[k].act_mean,
               100 * R[k].act_max, 1e3 * R[k].cpu / (steps - from), R[k].iters / (steps - from));
    printf("\n%d³ cubes, poke %.3g N, steps %d to %d of it, %d thread(s): active costs %.1f %% "
           "of all active; largest difference %.3g m = %.3f %% of the largest displacement %.3g "
           "m\n",
           n, force * sqrt(1 + 0.25 + 2.25), from, steps, threads, 100 * R[0].cpu / R[1].cpu, worst,
           100 * worst / dmax, dmax);
    for (int k = 0; k < 2; k++)
        cs_world_destroy(R[k].w);
    return 0;
}
