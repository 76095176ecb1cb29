/*
 * bench_blocks.c — speed of the implicit corotational step against problem size.
 *
 * A 1 m corotational block of n³ cubes (h = 1/n), its bottom face held, sags under gravity at
 * dt = 1/60 s (E = 1e5 Pa, ν = 0.3, ρ = 1000 kg/m³, solver tolerance 1e-6: the scene
 * defaults). Same physics at every n, so the cost growth is the solver's. For each size and
 * thread count: the median over runs of steps per second, CG iterations per step and the
 * cost of each stage of a step. CSV to the file given with --csv; a Markdown table on stdout.
 *
 * --field (seed 001 §3.3 material fields): "cubes" makes the half x < 0.5 three times stiffer
 * (each cube's 8 Gauss-point factors equal: one product with K per cube), "gradient" a
 * stiffness rising linearly to 5× along x (every cube graded: 8 products with the per-Gauss-
 * point matrices); "none" (default) the plain material.
 *
 * Usage: bench_blocks [--sizes 8,16,32,48] [--runs 5] [--threads 1,2] [--csv FILE]
 *                     [--field none|cubes|gradient]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"
#include "cubesim.h"

typedef struct result {
    double steps_per_s, ms_step, cpu_ms_step, iters, ms_rot, ms_rhs, ms_solve, ms_post, ms_skin;
} result;

typedef enum { FIELD_NONE, FIELD_CUBES, FIELD_GRADIENT } field_kind;

static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static int run_once(int n, int threads, int steps, field_kind field, cs_preconditioner pc,
                    result *r)
{
    char err[256];
    cs_world_def wd = cs_world_def_default();
    wd.threads = threads;
    wd.preconditioner = pc;
    wd.sleep_steps = 0;
    cs_world_t *w;
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_blocks: %s\n", err);
        return -1;
    }
    int nc = n * n * n, c = 0;
    int32_t *ijk = malloc(sizeof(int32_t) * 3 * (size_t)nc);
    for (int k = 0; k < n; k++)
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                ijk[3 * c] = i;
                ijk[3 * c + 1] = j;
                ijk[3 * c + 2] = k;
                c++;
            }
    cs_object_def d = cs_object_def_default();
    d.name = "block";
    d.model = CS_MODEL_COROTATIONAL;
    d.material.young = 1e5;
    d.material.density = 1000;
    d.cube_size = 1.0 / n;
    d.cells_ijk = ijk;
    d.n_cells = nc;
    cs_aabb fix = {{-1, -1, -1e-6}, {2, 2, 1e-6}};
    d.fixed = &fix;
    d.n_fixed = 1;
    cs_field_region reg = {.factors = {.young = field == FIELD_CUBES ? 3.0 : 5.0,
                                       .which = CS_FIELD_YOUNG}};
    if (field == FIELD_CUBES) {
        reg.shape = CS_FIELD_BOX;
        reg.box = (cs_aabb){{-1, -1, -1}, {0.5, 2, 2}};
    } else {
        reg.shape = CS_FIELD_GRADIENT;
        reg.to[0] = 1.0;
    }
    if (field != FIELD_NONE) {
        d.fields = &reg;
        d.n_fields = 1;
    }
    cs_object_id id;
    if (cs_world_add_object(w, &d, &id, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_blocks: %s\n", err);
        free(ijk);
        cs_world_destroy(w);
        return -1;
    }
    cs_world_step(w); /* warm-up: first touch of every page */
    memset(r, 0, sizeof *r);
    double t0 = now_s(), c0 = cpu_s();
    for (int s = 0; s < steps; s++) {
        cs_world_step(w);
        const cs_step_stats *st = cs_world_last_stats(w);
        r->iters += st->cg_iterations;
        r->ms_rot += st->ms_rotations;
        r->ms_rhs += st->ms_rhs;
        r->ms_solve += st->ms_solve;
        r->ms_post += st->ms_post + st->ms_inputs;
        r->ms_skin += st->ms_skin;
    }
    double el = now_s() - t0;
    r->cpu_ms_step = 1e3 * (cpu_s() - c0) / steps;
    r->steps_per_s = steps / el;
    r->ms_step = 1e3 * el / steps;
    r->iters /= steps;
    r->ms_rot /= steps;
    r->ms_rhs /= steps;
    r->ms_solve /= steps;
    r->ms_post /= steps;
    r->ms_skin /= steps;
    free(ijk);
    cs_world_destroy(w);
    return 0;
}

int main(int argc, char **argv)
{
    int sizes[16] = {8, 16, 32, 48}, ns = 4, threads[8] = {1, 2}, nt = 2, runs = 5;
    const char *csv = NULL;
    field_kind field = FIELD_NONE;
    cs_preconditioner pcs[3] = {CS_PRECOND_JACOBI};
    int npc = 1;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--sizes") && i + 1 < argc)
            ns = parse_list(argv[++i], sizes, 16);
        else if (!strcmp(argv[i], "--threads") && i + 1 < argc)
            nt = parse_list(argv[++i], threads, 8);
        else if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--csv") && i + 1 < argc)
            csv = argv[++i];
        else if (!strcmp(argv[i], "--field") && i + 1 < argc && !strcmp(argv[i + 1], "none"))
            field = FIELD_NONE, i++;
        else if (!strcmp(argv[i], "--field") && i + 1 < argc && !strcmp(argv[i + 1], "cubes"))
            field = FIELD_CUBES, i++;
        else if (!strcmp(argv[i], "--field") && i + 1 < argc && !strcmp(argv[i + 1], "gradient"))
            field = FIELD_GRADIENT, i++;
        else if (!strcmp(argv[i], "--precond") && i + 1 < argc) {
            /* a comma-separated list of auto, jacobi, multigrid */
            char buf[64];
            snprintf(buf, sizeof buf, "%s", argv[++i]);
            npc = 0;
            for (char *tok = strtok(buf, ","); tok && npc < 3; tok = strtok(NULL, ","))
                if (cs_preconditioner_from_name(tok, &pcs[npc++]) != 0) {
                    fprintf(stderr, "bench_blocks: unknown preconditioner %s\n", tok);
                    return 2;
                }
            if (npc == 0)
                return 2;
        } else {
            fprintf(stderr, "usage: bench_blocks [--sizes 8,16,32,48] [--runs 5] "
                            "[--threads 1,2] [--csv FILE] [--field none|cubes|gradient] "
                            "[--precond jacobi,multigrid,auto]\n");
            return 2;
        }
    }
    if (runs < 1 || runs > 100)
        runs = 5;
    FILE *f = csv ? fopen(csv, "w") : NULL;
    if (csv && !f) {
        fprintf(stderr, "bench_blocks: cannot write %s\n", csv);
        return 2;
    }
    if (f)
        fprintf(f, "cubes,precond,threads,runs,steps_per_s,ms_per_step,cpu_ms_per_step,cg_iters_per_step,ms_rotations,"
                   "ms_rhs,ms_solve,ms_post,ms_skin\n");
    printf("| cubes | precond | threads | steps/s | ms/step | CPU ms/step | CG it/step | rotations | "
           "rhs+precond | CG solve | post | skin |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    static const char *const PCN[] = {"auto", "jacobi", "multigrid"};
    double prev_ms[3][8] = {{0}}, prev_cells = 0;
    for (int si = 0; si < ns; si++) {
        int n = sizes[si];
        long cells = (long)n * n * n;
        /* About two seconds of stepping per run at most, at least 3 steps. */
        int steps = cells <= 5000 ? 60 : cells <= 40000 ? 12 : 4;
        for (int pi = 0; pi < npc; pi++)
        for (int ti = 0; ti < nt; ti++) {
            result rs[100];
            double v[100];
            for (int r = 0; r < runs; r++)
                if (run_once(n, threads[ti], steps, field, pcs[pi], &rs[r]) != 0)
                    return 1;
            result m;
            double *fields[] = {&m.steps_per_s, &m.ms_step, &m.cpu_ms_step, &m.iters, &m.ms_rot,
                                &m.ms_rhs, &m.ms_solve, &m.ms_post, &m.ms_skin};
            for (int k = 0; k < 9; k++) {
                for (int r = 0; r < runs; r++)
                    v[r] = *(double *)((char *)&rs[r] + ((char *)fields[k] - (char *)&m));
                *fields[k] = median(v, runs);
            }
            printf("| %d³ = %ld | %s | %d | %.2f | %.2f | %.2f | %.1f | %.2f | %.2f | %.2f | %.2f | "
                   "%.2f |\n",
                   n, cells, PCN[pcs[pi]], threads[ti], m.steps_per_s, m.ms_step, m.cpu_ms_step,
                   m.iters, m.ms_rot, m.ms_rhs, m.ms_solve, m.ms_post, m.ms_skin);
            fflush(stdout);
            if (f)
                fprintf(f, "%ld,%s,%d,%d,%.4f,%.4f,%.4f,%.2f,%.4f,%.4f,%.4f,%.4f,%.4f\n", cells,
                        PCN[pcs[pi]], threads[ti], runs, m.steps_per_s, m.ms_step, m.cpu_ms_step,
                        m.iters, m.ms_rot, m.ms_rhs, m.ms_solve, m.ms_post, m.ms_skin);
            if (si > 0 && prev_ms[pi][ti] > 0)
                fprintf(stderr, "  %s, %d thread(s): cost grows as cubes^%.2f from %ld to %ld cubes\n",
                        PCN[pcs[pi]], threads[ti],
                        log(m.ms_step / prev_ms[pi][ti]) / log(cells / prev_cells),
                        (long)prev_cells, cells);
            prev_ms[pi][ti] = m.ms_step;
        }
        prev_cells = (double)cells;
    }
    if (f)
        fclose(f);
    return 0;
}
