/*
 * bench_wp.c — work-precision benchmark (issue 6 parts 1 and 3): run time against error for
 * every elastic model and each integrator that applies, sweeping the cube size, the time step
 * and the CG tolerance.
 *
 * Specimen: a ν = 0 cantilever, L = 1 m, square section H = 0.1 m (L/H = 10), E = 1e6 Pa,
 * ρ = 1000 kg/m³, nz = 1..4 cubes through the thickness (h = H/nz, 10·nz³ cubes), every node
 * of the face x = 0 held, loaded by its own weight along −z. One thread.
 *
 * Cases (error = |measured/reference − 1|, or a distance over the reference for vectors):
 *   static_small  tip deflection under g = 0.01 m/s² (δ ≈ 1.5 mm = L/670: small deflection).
 *                 Reference: Timoshenko beam theory (κ = 5/6, G = E/2 at ν = 0):
 *                   δ = qL⁴/(8EI) + qL²/(2κGA), q = ρgA.
 *                 Timoshenko rather than Euler–Bernoulli because at L/H = 10 the shear term is
 *                 0.8 % of the bending one, larger than the finest error targets; both are in
 *                 the CSV, and the converged fine-mesh FEM is printed beside them.
 *   freq          the same beam released from rest, undeformed, with g = 0.01 m/s²: the tip
 *                 oscillates about its static deflection in (mostly) the first bending mode.
 *                 Frequency from the zero crossings of u_tip − u_static (same model and mesh).
 *                 Reference: the Richardson extrapolation of corotational FEM on two meshes
 *                 (nz 3 and 4; 4 and 6 with --wide), Verlet at 0.5 × its stability limit; the
 *                 Euler–Bernoulli ω₁ = 1.875²·√(EI/(ρAL⁴)) is printed beside it (at L/H = 10,
 *                 shear and rotary inertia lower the true ω₁ by ~0.6 %, so EB is not the
 *                 reference below 1 %).
 *   amp           amplitude of that oscillation: √2 × RMS of u_tip − u_static over the first
 *                 and over the third period; the beam is undamped, so the exact first-mode
 *                 amplitude is constant and the error is the fraction lost (or gained) over two
 *                 periods: numerical damping (implicit Euler) or growth.
 *   static_large  tip displacement under g = 2.5 m/s²: the tip drops by about L/3 and the
 *                 section rotates ~30°. Reference: corotational FEM at the finest mesh
 *                 (difference to the next finest printed). Linear FEM cannot represent large
 *                 rotations and is expected to be wrong here (it overshoots and stretches).
 *
 * Sweeps: nz (cube size); for dynamics (nz 1..4), implicit Euler at dt = 1/30, 1/60, 1/120 s
 * (tolerance 1e-6) and at tolerances 1e-3, 1e-4 (dt = 1/60 s); central differences,
 * symplectic Euler and Verlet at 0.9 × their limit. Statics: nz 1, 2, 3, 4, 6 × tolerance
 * 1e-3, 1e-4, 1e-6 (the static solver uses max(tolerance, 1e-8)). --wide adds dt = 1/240 s,
 * tolerance 1e-8 and the explicit schemes at 0.5 × their limit.
 * Times: CPU seconds (CLOCK_PROCESS_CPUTIME_ID) and wall seconds, medians over --runs runs
 * for runs shorter than 1 s (a single run otherwise); dynamic runs are capped (--cap seconds
 * of CPU, default 8, 15 with --wide, 3 with --quick: recorded as "timeout").
 *
 * Usage: bench_wp [--quick | --wide] [--runs 3] [--cap S] [--out DIR] [--check]
 * Writes DIR/wp_static.csv, wp_dynamic.csv, wp_pareto.csv, wp_refs.txt and prints
 * the fastest setting per error target as Markdown. --check exits 1 unless the harness's
 * sanity checks hold (error falls as cubes shrink; analytic references agree with the fine
 * mesh); --quick runs a reduced sweep in well under a minute.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench_util.h"
#include "cubesim.h"
#include "elastic.h"
#include "localframe.h"
#include "lattice.h"

static const double L = 1.0, H = 0.1, E = 1e6, RHO = 1000, G_SMALL = 0.01, G_LARGE = 2.5;

static double cpu_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

typedef struct run {
    int rc;           /* 0 ok, 1 refused, 2 failed / diverged, 3 timeout */
    double cpu, wall; /* seconds */
    double tip[3];    /* static: mean tip displacement */
    double freq, amp; /* dynamic: ω [rad/s], A3/A1 */
    long iters;
    char msg[256];
} run;

static cs_world_t *beam(cs_model model, cs_integrator integ, int nz, double dt, double tol,
                        double g, cs_object_id *id, char *err, size_t errlen)
{
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = -g;
    wd.dt = dt;
    wd.threads = 1;
    wd.sleep_steps = 0;
    wd.cg_tolerance = tol;
    wd.cg_max_iterations = 20000;
    cs_world_t *w;
    if (cs_world_create(&wd, &w, err, errlen) != CS_OK)
        return NULL;
    const int nx = 10 * nz, n = nx * nz * nz;
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
    const cs_aabb fix = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1, 1}};
    d.fixed = &fix;
    d.n_fixed = 1;
    int rc = cs_world_add_object(w, &d, id, err, errlen);
    free(ijk);
    if (rc != CS_OK) {
        cs_world_destroy(w);
        return NULL;
    }
    return w;
}

/* Mean displacement of the nodes of the face x = L. */
static void tip_disp(cs_world_t *w, cs_object_id id, double u[3])
{
    const double *rest, *pos;
    int n, cnt = 0;
    u[0] = u[1] = u[2] = 0;
    cs_object_nodes(w, id, &rest, &pos, NULL, &n);
    for (int i = 0; i < n; i++)
        if (fabs(rest[3 * i] - L) < 1e-9) {
            for (int a = 0; a < 3; a++)
                u[a] += pos[3 * i + a] - rest[3 * i + a];
            cnt++;
        }
    for (int a = 0; a < 3; a++)
        u[a] /= cnt;
}

static void run_static(cs_model model, int nz, double tol, double g, run *r)
{
    memset(r, 0, sizeof *r);
    cs_object_id id;
    cs_world_t *w = beam(model, CS_INTEGRATOR_IMPLICIT_EULER, nz, 1.0 / 60, tol, g, &id, r->msg,
                         sizeof r->msg);
    if (!w) {
        r->rc = 1;
        return;
    }
    const double c0 = cpu_s(), w0 = now_s();
    const int rc = cs_world_solve_static(w);
    r->cpu = cpu_s() - c0;
    r->wall = now_s() - w0;
    r->iters = cs_world_last_stats(w)->cg_iterations;
    tip_disp(w, id, r->tip);
    if (rc != CS_OK) {
        r->rc = 2;
        snprintf(r->msg, sizeof r->msg, "static solve: %s", cs_status_str(rc));
    }
    cs_world_destroy(w);
}

/* √2 × RMS of u − c over [t0, t1] (samples u[k] at t = (k+1)·dt). */
static double amp_window(const double *u, double dt, double c, double t0, double t1)
{
    double s = 0;
    int n = 0;
    for (int k = (int)ceil(t0 / dt) - 1; (k + 1) * dt <= t1; k++) {
        if (k < 0)
            continue;
        s += (u[k] - c) * (u[k] - c);
        n++;
    }
    return n ? sqrt(2 * s / n) : NAN;
}

/* Release from rest (undeformed) under G_SMALL and measure ω and A3/A1 about `mean`. */
static void run_dynamic(cs_model model, cs_integrator integ, int nz, double dt, double tol,
                        double sim, double mean, double cap, run *r)
{
    memset(r, 0, sizeof *r);
    r->freq = r->amp = NAN;
    cs_object_id id;
    cs_world_t *w = beam(model, integ, nz, dt, tol, G_SMALL, &id, r->msg, sizeof r->msg);
    if (!w) {
        r->rc = 1;
        return;
    }
    const int steps = (int)ceil(sim / dt);
    double *u = malloc(sizeof *u * (size_t)steps);
    const double c0 = cpu_s(), w0 = now_s();
    int s;
    for (s = 0; s < steps; s++) {
        const int rc = cs_world_step(w);
        r->iters += cs_world_last_stats(w)->cg_iterations;
        double t[3];
        tip_disp(w, id, t);
        u[s] = t[2];
        if (rc != CS_OK || !isfinite(u[s]) || fabs(u[s]) > 1) {
            r->rc = 2;
            snprintf(r->msg, sizeof r->msg, "step %d: %s", s, rc != CS_OK ? cs_status_str(rc) : "diverged");
            break;
        }
        if ((s & 63) == 63 && cpu_s() - c0 > cap) {
            r->rc = 3;
            snprintf(r->msg, sizeof r->msg, "timeout after %d of %d steps", s + 1, steps);
            break;
        }
    }
    r->cpu = cpu_s() - c0;
    r->wall = now_s() - w0;
    if (r->rc == 0) {
        /* Zero crossings of u − mean, by linear interpolation. */
        double zc[64];
        int nzc = 0;
        for (int k = 1; k < steps && nzc < 64; k++) {
            const double a = u[k - 1] - mean, b = u[k] - mean;
            if ((a < 0) != (b < 0) && a != b)
                zc[nzc++] = (k + a / (a - b)) * dt;
        }
        if (nzc >= 3) {
            const int last = nzc - 1 - ((nzc - 1) % 2); /* whole periods: even index distance */
            r->freq = 2 * M_PI * (last / 2) / (zc[last] - zc[0]);
            if (nzc >= 7) {
                const double a1 = amp_window(u, dt, mean, zc[0], zc[2]);
                const double a3 = amp_window(u, dt, mean, zc[4], zc[6]);
                r->amp = a3 / a1;
            }
        }
        if (!isfinite(r->freq) || !isfinite(r->amp)) {
            r->rc = 2;
            snprintf(r->msg, sizeof r->msg, "%d zero crossings: too few for 3 periods (damped?)", nzc);
        }
    }
    free(u);
    cs_world_destroy(w);
}

static int cmp_run_cpu(const void *a, const void *b)
{
    const double x = ((const run *)a)->cpu, y = ((const run *)b)->cpu;
    return (x > y) - (x < y);
}

/* Repeat while runs are short (< 1 s CPU); keep the run of median CPU time and the median
 * wall time. */
#define REPEAT(R, RUNS, CALL)                                                                   \
    do {                                                                                        \
        run rr_[16];                                                                            \
        double wl_[16];                                                                         \
        int n_ = 0;                                                                             \
        for (; n_ < (RUNS) && n_ < 16; n_++) {                                                  \
            run *rp = &rr_[n_];                                                                  \
            CALL;                                                                               \
            wl_[n_] = rp->wall;                                                                  \
            if (rp->rc || rp->cpu > 1.0) {                                                        \
                n_++;                                                                           \
                break;                                                                          \
            }                                                                                   \
        }                                                                                       \
        qsort(rr_, (size_t)n_, sizeof rr_[0], cmp_run_cpu);                                     \
        (R) = rr_[n_ / 2];                                                                      \
        (R).wall = median(wl_, n_);                                                             \
    } while (0)

/* ---------------------------------------------------------------- results and targets */

typedef struct row {
    char kase[16], model[16], integ[24];
    int nz;
    double dt, tol, cpu, wall, err;
} row;

typedef struct table {
    row *r;
    int n, cap;
} table;

static void add_row(table *t, const char *kase, cs_model m, const char *integ, int nz, double dt,
                    double tol, const run *r, double err)
{
    if (t->n == t->cap) {
        t->cap = t->cap ? 2 * t->cap : 256;
        t->r = realloc(t->r, sizeof *t->r * (size_t)t->cap);
    }
    row *x = &t->r[t->n++];
    snprintf(x->kase, sizeof x->kase, "%s", kase);
    snprintf(x->model, sizeof x->model, "%s", cs_model_name(m));
    snprintf(x->integ, sizeof x->integ, "%s", integ);
    x->nz = nz;
    x->dt = dt;
    x->tol = tol;
    x->cpu = r->cpu;
    x->wall = r->wall;
    x->err = r->rc ? NAN : err;
}

static const cs_model MODELS[4] = {CS_MODEL_LINEAR, CS_MODEL_COROTATIONAL, CS_MODEL_MSS,
                                   CS_MODEL_LOCALFRAME};

static int cmp_row_cpu(const void *a, const void *b)
{
    const double x = ((const row *)a)->cpu, y = ((const row *)b)->cpu;
    return (x > y) - (x < y);
}

/* The Pareto front per case and model (each point faster than the next and less accurate):
 * the work-precision curves. */
static void write_pareto(table *t, FILE *f)
{
    static const char *cases[5] = {"static_small", "dyn", "freq", "amp", "static_large"};
    qsort(t->r, (size_t)t->n, sizeof *t->r, cmp_row_cpu);
    fprintf(f, "case,model,cpu_s,wall_s,err,integrator,nz,dt,tol\n");
    for (int c = 0; c < 5; c++)
        for (int m = 0; m < 4; m++) {
            double best = INFINITY;
            for (int i = 0; i < t->n; i++) {
                const row *x = &t->r[i];
                if (strcmp(x->kase, cases[c]) || strcmp(x->model, cs_model_name(MODELS[m])) ||
                    !(x->err < best * (1 - 1e-3)))
                    continue;
                best = x->err;
                fprintf(f, "%s,%s,%.6g,%.6g,%.6g,%s,%d,%.6g,%g\n", x->kase, x->model, x->cpu,
                        x->wall, fmax(x->err, 1e-6), x->integ, x->nz, x->dt, x->tol);
            }
            fprintf(f, "\n\n"); /* gnuplot data blocks */
        }
}

static void print_targets(const table *t, const char *kase)
{
    static const double targets[4] = {0.10, 0.03, 0.01, 0.003};
    printf("\n**%s** — fastest setting (CPU s) reaching each error target\n\n", kase);
    printf("| model | ≤ 10 %% | ≤ 3 %% | ≤ 1 %% | ≤ 0.3 %% |\n|---|---|---|---|---|\n");
    for (int m = 0; m < 4; m++) {
        const char *mn = cs_model_name(MODELS[m]);
        printf("| %s |", mn);
        for (int k = 0; k < 4; k++) {
            const row *best = NULL;
            for (int i = 0; i < t->n; i++) {
                const row *x = &t->r[i];
                if (strcmp(x->kase, kase) || strcmp(x->model, mn) || !(x->err <= targets[k]))
                    continue;
                if (!best || x->cpu < best->cpu)
                    best = x;
            }
            if (!best) {
                printf(" — |");
                continue;
            }
            char dts[32] = "", tols[32] = "";
            if (best->dt > 0)
                snprintf(dts, sizeof dts, ", dt %.3g", best->dt);
            if (best->tol > 0)
                snprintf(tols, sizeof tols, ", tol %.0e", best->tol);
            printf(" %.3g s: %s nz %d%s%s (%.2g %%) |", best->cpu, best->integ, best->nz, dts,
                   tols, 100 * best->err);
        }
        printf("\n");
    }
}

int main(int argc, char **argv)
{
    int quick = 0, runs = 3, check = 0, wide = 0;
    const char *out = "bench/results";
    double cap = -1;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--quick"))
            quick = 1;
        else if (!strcmp(argv[i], "--wide"))
            wide = 1;
        else if (!strcmp(argv[i], "--check"))
            check = 1;
        else if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--cap") && i + 1 < argc)
            cap = atof(argv[++i]);
        else if (!strcmp(argv[i], "--out") && i + 1 < argc)
            out = argv[++i];
        else {
            fprintf(stderr, "usage: bench_wp [--quick] [--check] [--wide] [--runs 3] [--cap S] [--out DIR]\n");
            return 2;
        }
    }
    if (runs < 1)
        runs = 1;
    if (cap < 0)
        cap = quick ? 3 : wide ? 15 : 8;
    if (quick)
        runs = 1;
    setvbuf(stdout, NULL, _IOLBF, 0);
    const int nzs_full[4] = {1, 2, 3, 4}, nzs_quick[2] = {1, 2};
    const int *nzs = quick ? nzs_quick : nzs_full, nn = quick ? 2 : 4;
    const double tols_full[4] = {1e-3, 1e-4, 1e-6, 1e-8}, tols_quick[2] = {1e-3, 1e-6};
    const double *tols = quick ? tols_quick : tols_full;
    const int ntol = quick ? 2 : wide ? 4 : 3;
    const double dts_full[4] = {1.0 / 30, 1.0 / 60, 1.0 / 120, 1.0 / 240},
                 dts_quick[2] = {1.0 / 30, 1.0 / 60};
    const double *dts = quick ? dts_quick : dts_full;
    const int ndt = quick ? 2 : wide ? 4 : 3;
    const double fr_full[2] = {0.9, 0.5}, fr_quick[1] = {0.9};
    const double *fracs = quick ? fr_quick : fr_full;
    const int nfr = quick || !wide ? 1 : 2;
    const int refs[2] = {quick ? 3 : 6, quick ? 4 : 8};
    const int nzs_static_full[5] = {1, 2, 3, 4, 6};
    const int *nzs_s = quick ? nzs_quick : nzs_static_full, nns = quick ? 2 : 5;
    int failed = 0;

    /* ------------------------------------------------ analytic references */
    const double A = H * H, I = H * H * H * H / 12, kappa = 5.0 / 6, Gs = E / 2;
    const double q = RHO * G_SMALL * A;
    const double d_eb = q * L * L * L * L / (8 * E * I), d_ti = d_eb + q * L * L / (2 * kappa * Gs * A);
    const double w_eb = 1.875104 * 1.875104 * sqrt(E * I / (RHO * A * L * L * L * L));
    char path[512];
    snprintf(path, sizeof path, "%s/wp_refs.txt", out);
    FILE *fr = fopen(path, "w");
    if (!fr) {
        fprintf(stderr, "bench_wp: cannot write %s\n", path);
        return 1;
    }
#define REF(...)                                                                                \
    do {                                                                                        \
        printf(__VA_ARGS__);                                                                    \
        fprintf(fr, __VA_ARGS__);                                                               \
    } while (0)
    REF("# bench_wp%s: nu = 0 cantilever L = %g m, H = %g m, E = %g Pa, rho = %g kg/m3, %d cores\n",
        quick ? " --quick" : "", L, H, E, RHO, 2);
    REF("static_small: Euler-Bernoulli tip %.6g m, Timoshenko %.6g m (shear adds %.2f %%)\n", d_eb,
        d_ti, 100 * (d_ti / d_eb - 1));
    REF("freq: Euler-Bernoulli omega1 = %.5g rad/s (T = %.4g s)\n", w_eb, 2 * M_PI / w_eb);

    /* Fine-mesh references: statics (small and large) and the frequency. Trilinear cubes
     * converge as h² in bending (checked: the two meshes' errors scale so), so each reference
     * is the Richardson extrapolation (n₂²u₂ − n₁²u₁)/(n₂² − n₁²) of the two finest meshes,
     * and how converged it is is said by the finer mesh's own distance to it. */
    /* The static references are solved to 1e-7 of the load: on the small load the residual's
     * round-off floor is about 3e-8 (asked for 1e-8, corotational Newton stalls there; the
     * engine now keeps that state, but it used to report not converged, which made this bench
     * exit 1). 1e-7 moves the tip by far less than the digits reported. */
    const double ref_tol = 1e-7;
    run rs[2], rl[2], rd[2];
    for (int k = 0; k < 2; k++) {
        run_static(CS_MODEL_COROTATIONAL, refs[k], ref_tol, G_SMALL, &rs[k]);
        run_static(CS_MODEL_COROTATIONAL, refs[k], ref_tol, G_LARGE, &rl[k]);
        failed |= rs[k].rc || rl[k].rc;
        REF("corotational nz %d (h = %.4g m): small tip %.6g m (%+.3f %% vs Timoshenko), "
            "large tip (%.5g, %.5g) m\n",
            refs[k], H / refs[k], -rs[k].tip[2], 100 * (-rs[k].tip[2] / d_ti - 1), rl[k].tip[0],
            rl[k].tip[2]);
    }
    const double n1 = refs[0] * refs[0], n2 = refs[1] * refs[1];
#define RICH(a, b) ((n2 * (b) - n1 * (a)) / (n2 - n1))
    const double small_x = -RICH(rs[0].tip[2], rs[1].tip[2]);
    REF("static_small: Richardson extrapolation of nz %d, %d: %.6g m, %+.3f %% from Timoshenko, "
        "%+.3f %% from Euler-Bernoulli (reference used: Timoshenko)\n",
        refs[0], refs[1], small_x, 100 * (small_x / d_ti - 1), 100 * (small_x / d_eb - 1));
    const double lt[3] = {RICH(rl[0].tip[0], rl[1].tip[0]), 0, RICH(rl[0].tip[2], rl[1].tip[2])};
    const double lref = hypot(lt[0], lt[2]);
    REF("static_large reference: corotational, Richardson of nz %d, %d: tip (%.5g, %.5g) m, "
        "|tip| %.5g m (tip drop %.3f L, slope ~%.0f deg); nz %d alone is %.3f %% from it, nz %d %.3f %%\n",
        refs[0], refs[1], lt[0], lt[2], lref, -lt[2] / L, atan(1.5 * -lt[2] / L) * 180 / M_PI,
        refs[1], 100 * hypot(rl[1].tip[0] - lt[0], rl[1].tip[2] - lt[2]) / lref, refs[0],
        100 * hypot(rl[0].tip[0] - lt[0], rl[0].tip[2] - lt[2]) / lref);
    const double T = 2 * M_PI / w_eb, sim = 3.8 * T;
    const int drefs[2] = {quick ? 2 : wide ? 4 : 3, quick ? 3 : wide ? 6 : 4};
    for (int k = 0; k < 2; k++) {
        const double dtc = cs_elastic_critical_dt(CS_MODEL_COROTATIONAL,
                                                  &(cs_material){.young = E, .poisson = 0,
                                                                 .density = RHO},
                                                  H / drefs[k]);
        run st;
        run_static(CS_MODEL_COROTATIONAL, drefs[k], ref_tol, G_SMALL, &st);
        run_dynamic(CS_MODEL_COROTATIONAL, CS_INTEGRATOR_VERLET, drefs[k], 0.5 * dtc, 1e-8, sim,
                    st.tip[2], 1e9, &rd[k]);
        failed |= rd[k].rc != 0;
        REF("corotational nz %d, Verlet dt %.3g s: omega1 %.6g rad/s (%+.3f %% vs EB), "
            "A3/A1 %.5f, %.1f s CPU\n",
            drefs[k], 0.5 * dtc, rd[k].freq, 100 * (rd[k].freq / w_eb - 1), rd[k].amp, rd[k].cpu);
    }
    const double dn1 = drefs[0] * drefs[0], dn2 = drefs[1] * drefs[1];
    const double w_x = (dn2 * rd[1].freq - dn1 * rd[0].freq) / (dn2 - dn1);
    REF("freq reference: Richardson of nz %d, %d: omega1 %.6g rad/s, %+.3f %% from Euler-Bernoulli "
        "(shear and rotary inertia at L/H = 10); nz %d alone is %+.3f %% from it\n",
        drefs[0], drefs[1], w_x, 100 * (w_x / w_eb - 1), drefs[1], 100 * (rd[1].freq / w_x - 1));
    const double w_ref = w_x;
    fclose(fr);

    /* ------------------------------------------------ sweeps */
    table t = {0};
    snprintf(path, sizeof path, "%s/wp_static.csv", out);
    FILE *fs = fopen(path, "w");
    snprintf(path, sizeof path, "%s/wp_dynamic.csv", out);
    FILE *fd = fopen(path, "w");
    if (!fs || !fd) {
        fprintf(stderr, "bench_wp: cannot write under %s\n", out);
        return 1;
    }
    fprintf(fs, "case,model,nz,cells,tol,cpu_s,wall_s,newton_cg_iters,tip_x,tip_z,err,err_eb,status\n");
    fprintf(fd, "model,integrator,nz,cells,dt,tol,cpu_s,wall_s,cg_iters,omega,err_freq,"
                "err_freq_eb,amp_ratio,err_amp,status\n");
    double stat_tip[4][8]; /* per model and nz: the static small tip, the mean for dynamics */
    double err_small_corot[8] = {0};
    for (int m = 0; m < 4; m++) {
        /* A static setting that took over cap/4 CPU seconds is not tried on finer meshes
         * (each finer mesh costs 4× or more): mss in large rotation needs 10⁵ CG iterations. */
        double last_cpu[8][2] = {{0}};
        for (int a = 0; a < nns; a++) {
            const int nz = nzs_s[a], cells = 10 * nz * nz * nz;
            stat_tip[m][a] = NAN;
            for (int b = 0; b < ntol; b++) {
                for (int big = 0; big < 2; big++) {
                    run r;
                    if (last_cpu[b][big] > cap / 4) {
                        fprintf(fs, "%s,%s,%d,%d,%g,nan,nan,0,nan,nan,nan,nan,skipped: %.1f s "
                                    "CPU at the previous size\n",
                                big ? "static_large" : "static_small", cs_model_name(MODELS[m]), nz,
                                cells, tols[b], last_cpu[b][big]);
                        continue;
                    }
                    REPEAT(r, runs, run_static(MODELS[m], nz, tols[b], big ? G_LARGE : G_SMALL, rp));
                    last_cpu[b][big] = r.cpu;
                    double err, err_eb = NAN;
                    if (big) {
                        err = hypot(r.tip[0] - lt[0], r.tip[2] - lt[2]) / lref;
                    } else {
                        err = fabs(-r.tip[2] / d_ti - 1);
                        err_eb = fabs(-r.tip[2] / d_eb - 1);
                        if (b == ntol - 1 || tols[b] == 1e-6) {
                            if (tols[b] == 1e-6)
                                stat_tip[m][a] = r.tip[2];
                            if (MODELS[m] == CS_MODEL_COROTATIONAL && tols[b] == 1e-6)
                                err_small_corot[a] = err;
                        }
                    }
                    const char *kase = big ? "static_large" : "static_small";
                    fprintf(fs, "%s,%s,%d,%d,%g,%.6g,%.6g,%ld,%.8g,%.8g,%.6g,%.6g,%s\n", kase,
                            cs_model_name(MODELS[m]), nz, cells, tols[b], r.cpu, r.wall, r.iters,
                            r.tip[0], r.tip[2], r.rc ? NAN : err, r.rc ? NAN : err_eb,
                            r.rc ? r.msg : "ok");
                    add_row(&t, kase, MODELS[m], "static", nz, 0, tols[b], &r, err);
                }
            }
            fflush(fs);
        }
    }
    fclose(fs);

    /* Dynamics. */
    for (int m = 0; m < 4; m++) {
        const cs_material mat = {.young = E, .poisson = 0, .density = RHO};
        for (int a = 0; a < nn; a++) {
            const int nz = nzs[a], cells = 10 * nz * nz * nz;
            const double h = H / nz, mean = stat_tip[m][a];
            if (!isfinite(mean))
                continue;
            /* (integrator, dt, tol) triples for this model and size. */
            struct cfg_t {
                cs_integrator in;
                double dt, tol;
            } cfg[32];
            int nc = 0;
            for (int k = 0; k < ndt; k++)
                cfg[nc++] = (struct cfg_t){CS_INTEGRATOR_IMPLICIT_EULER, dts[k], 1e-6};
            for (int k = 0; k < ndt && MODELS[m] != CS_MODEL_MSS; k++) /* refused for mss */
                cfg[nc++] = (struct cfg_t){CS_INTEGRATOR_NEWMARK, dts[k], 1e-6};
            for (int b = 0; b < ntol; b++)
                if (tols[b] != 1e-6)
                    cfg[nc++] = (struct cfg_t){CS_INTEGRATOR_IMPLICIT_EULER, 1.0 / 60, tols[b]};
            double w2 = 0;
            cs_lf_omega2_bound(MODELS[m], E, 0, RHO, h, &w2);
            const double dcd = 2 / sqrt(w2), dex = cs_elastic_critical_dt(MODELS[m], &mat, h);
            for (int k = 0; k < nfr; k++) {
                cfg[nc++] = (struct cfg_t){CS_INTEGRATOR_CENTRAL_DIFFERENCE, fracs[k] * dcd, 1e-6};
                cfg[nc++] = (struct cfg_t){CS_INTEGRATOR_SYMPLECTIC_EULER, fracs[k] * dex, 1e-6};
                cfg[nc++] = (struct cfg_t){CS_INTEGRATOR_VERLET, fracs[k] * dex, 1e-6};
            }
            for (int c = 0; c < nc; c++) {
                run r;
                REPEAT(r, runs, run_dynamic(MODELS[m], cfg[c].in, nz, cfg[c].dt, cfg[c].tol, sim,
                                            mean, cap, rp));
                const double ef = fabs(r.freq / w_ref - 1), ea = fabs(r.amp - 1);
                const int explicit_ = cfg[c].in == CS_INTEGRATOR_SYMPLECTIC_EULER ||
                                      cfg[c].in == CS_INTEGRATOR_VERLET;
                fprintf(fd, "%s,%s,%d,%d,%.6g,%g,%.6g,%.6g,%ld,%.8g,%.6g,%.6g,%.6g,%.6g,\"%s\"\n",
                        cs_model_name(MODELS[m]), cs_integrator_name(cfg[c].in), nz, cells,
                        cfg[c].dt, explicit_ ? NAN : cfg[c].tol, r.cpu, r.wall, r.iters, r.freq,
                        r.rc ? NAN : ef, r.rc ? NAN : fabs(r.freq / w_eb - 1), r.amp,
                        r.rc ? NAN : ea, r.rc ? r.msg : "ok");
                fflush(fd);
                add_row(&t, "freq", MODELS[m], cs_integrator_name(cfg[c].in), nz, cfg[c].dt,
                        explicit_ ? 0 : cfg[c].tol, &r, ef);
                add_row(&t, "dyn", MODELS[m], cs_integrator_name(cfg[c].in), nz, cfg[c].dt,
                        explicit_ ? 0 : cfg[c].tol, &r, fmax(ef, ea));
                add_row(&t, "amp", MODELS[m], cs_integrator_name(cfg[c].in), nz, cfg[c].dt,
                        explicit_ ? 0 : cfg[c].tol, &r, ea);
                fprintf(stderr, "  %s %s nz %d dt %.3g tol %g: %s, %.2f s CPU, freq err %.3g, amp %.4g\n",
                        cs_model_name(MODELS[m]), cs_integrator_name(cfg[c].in), nz, cfg[c].dt,
                        cfg[c].tol, r.rc ? r.msg : "ok", r.cpu, ef, r.amp);
            }
        }
    }
    fclose(fd);

    print_targets(&t, "static_small");
    print_targets(&t, "dyn");
    print_targets(&t, "freq");
    print_targets(&t, "static_large");
    printf("\n(amp alone is met by any undamped explicit scheme on any mesh, so it is not "
           "tabulated: see dyn, the larger of the frequency and amplitude errors, and "
           "wp_dynamic.csv.)\n");
    printf("\nstatic_large: linear FEM has no rotations; its error there is the model's, not "
           "the mesh's (expected wrong).\n");

    snprintf(path, sizeof path, "%s/wp_pareto.csv", out);
    FILE *fp = fopen(path, "w");
    if (fp) {
        write_pareto(&t, fp);
        fclose(fp);
    }

    if (check) {
        /* The harness's own sanity: the analytic static reference agrees with the finest
         * mesh within 2 %, the frequency reference with Euler–Bernoulli within 3 %, and the
         * corotational static error falls from nz 1 to nz 2. */
        int bad = 0;
        if (!(fabs(small_x / d_ti - 1) < 0.005)) {
            fprintf(stderr, "check: extrapolated mesh and Timoshenko differ by more than 0.5 %%\n");
            bad = 1;
        }
        if (!(fabs(w_x / w_eb - 1) < 0.03)) {
            fprintf(stderr, "check: extrapolated omega1 and Euler-Bernoulli differ by more than 3 %%\n");
            bad = 1;
        }
        if (!(err_small_corot[1] < err_small_corot[0])) {
            fprintf(stderr, "check: corotational error did not fall from nz %d to %d (%g, %g)\n",
                    nzs[0], nzs[1], err_small_corot[0], err_small_corot[1]);
            bad = 1;
        }
        if (!(lref > 0.25 * L && lref < 0.45 * L)) {
            fprintf(stderr, "check: large-rotation tip %g m is not about L/3\n", lref);
            bad = 1;
        }
        int dyn_ok = 0;
        for (int i = 0; i < t.n; i++)
            if (!strcmp(t.r[i].kase, "freq") && !strcmp(t.r[i].model, "corotational") &&
                t.r[i].nz == nzs[nn - 1] && t.r[i].err < 0.08)
                dyn_ok = 1;
        if (!dyn_ok) {
            fprintf(stderr, "check: no corotational run at nz %d within 8 %% of omega1\n", nzs[nn - 1]);
            bad = 1;
        }
        failed |= bad;
        fprintf(stderr, "check: %s\n", bad ? "FAILED" : "ok");
    }
    free(t.r);
    return failed ? 1 : 0;
}
