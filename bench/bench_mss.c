/*
 * bench_mss.c — seed 004 §4's two studies of the mass-spring model (mss), against FEM.
 *
 * Cantilever (Fig. 5): a 400×100×100 mm beam, E = 1000 Pa, ν = 0.3, held at x = 0, bending
 * under its own weight (g = 9.81 m/s² along −z). The paper gives "a mass of 0.0125 Kg.m⁻³",
 * read here as the density ρ = 0.0125 kg/m³ (tip deflection ≈ 0.5 mm, small strain); --rho
 * changes it (3.125 reads 0.0125 kg as the beam's mass: ≈ 0.12 m, large rotation). Static
 * equilibrium of mss at 4×1×1, 8×2×2, 12×3×3 and 16×4×4 cubes; reference: corotational FEM on
 * a finer lattice (--ref cubes across the 100 mm, default 12, so that every mss node is a
 * reference node); the reference is also solved at ref/2 to say how converged it is. Error:
 * the largest distance between an mss node and the same point of the reference, over the
 * reference's largest displacement (the paper's "maximum error ... about 45 % at 4×1×1,
 * about 5 % at 16×4×4"). The FEM of the same coarse cubes is listed beside mss.
 *
 * L-shaped shear (Fig. 6): a 4×4×4 m L (the 4 m base leg 2 m high, the 2 m wide upright leg
 * on its x < 2 m half), E = 1000 Pa, ν = 0.3, no weight, held at its base z = 0, a shear
 * force along +x spread over the top face of the upright leg (z = 4 m). The paper's 0.3 GN
 * would strain a 1 kPa solid 10⁴-fold; the load here (1 N) keeps strains small (the error of
 * linear models is independent of the load's size). Resolutions of 1 to 4 cubes per 2 m,
 * reference: corotational FEM at --lref cubes per 2 m (default 12), checked against lref/2.
 *
 * Usage: bench_mss [--ref 12] [--lref 12] [--rho 0.0125] [--csv-cantilever FILE] [--csv-lshape FILE]
 * Markdown tables on stdout.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench_util.h"
#include "cubesim.h"
#include "lattice.h"

typedef struct solved {
    int nx, ny, nz;      /* lattice extent in cubes */
    double h;
    double *u;           /* displacement at lattice node (i,j,k), NAN where no node */
    double umax;         /* largest nodal displacement */
    double tip;          /* mean −u_z over the nodes at x = max (cantilever) */
    int iterations;
    double seconds;
} solved;

static double *lattice_at(solved *s, int i, int j, int k)
{
    return s->u + 3 * ((size_t)(k * (s->ny + 1) + j) * (s->nx + 1) + i);
}

/* Solve the static problem for the cells in ijk (lattice nx×ny×nz of edge h) and sample the
 * displacement at every lattice node. */
static int solve(cs_model model, double rho, const double g[3], const int32_t *ijk, int n,
                 int nx, int ny, int nz, double h, const cs_aabb *fix, const cs_load *load,
                 solved *out)
{
    char err[512];
    cs_world_def wd = cs_world_def_default();
    memcpy(wd.gravity, g, sizeof wd.gravity);
    /* Equilibrium to 1e-7 of the loads: far below the errors measured, and above the floor
     * that round-off in the internal forces of a fine, lightly loaded beam sets (a tighter
     * tolerance stalls there and load stepping retries for ever). */
    wd.cg_tolerance = 1e-7;
    wd.cg_max_iterations = 200000;
    wd.threads = 2;
    cs_world_t *w;
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_mss: %s\n", err);
        return -1;
    }
    cs_object_def d = cs_object_def_default();
    d.name = "specimen";
    d.model = model;
    d.material.young = 1000;
    d.material.poisson = 0.3;
    d.material.density = rho;
    d.cube_size = h;
    d.cells_ijk = ijk;
    d.n_cells = n;
    d.fixed = fix;
    d.n_fixed = 1;
    if (load) {
        d.loads = load;
        d.n_loads = 1;
    }
    cs_object_id id;
    if (cs_world_add_object(w, &d, &id, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_mss: %s\n", err);
        cs_world_destroy(w);
        return -1;
    }
    double t0 = now_s();
    int rc = cs_world_solve_static(w);
    out->seconds = now_s() - t0;
    out->iterations = cs_world_last_stats(w)->cg_iterations;
    if (rc != CS_OK)
        fprintf(stderr, "bench_mss: %s static solve with h = %g: %s (residual %g)\n",
                cs_model_name(model), h, cs_status_str(rc), cs_world_last_stats(w)->cg_residual);
    out->nx = nx;
    out->ny = ny;
    out->nz = nz;
    out->h = h;
    const size_t nn = (size_t)(nx + 1) * (ny + 1) * (nz + 1);
    out->u = malloc(3 * nn * sizeof *out->u);
    for (size_t i = 0; i < 3 * nn; i++)
        out->u[i] = NAN;
    const double *rest, *pos;
    int nnodes;
    cs_object_nodes(w, id, &rest, &pos, NULL, &nnodes);
    out->umax = 0;
    double tip = 0;
    int ntip = 0;
    for (int i = 0; i < nnodes; i++) {
        const int li = (int)lround(rest[3 * i] / h), lj = (int)lround(rest[3 * i + 1] / h),
                  lk = (int)lround(rest[3 * i + 2] / h);
        double *u = lattice_at(out, li, lj, lk);
        double m = 0;
        for (int a = 0; a < 3; a++) {
            u[a] = pos[3 * i + a] - rest[3 * i + a];
            m += u[a] * u[a];
        }
        out->umax = fmax(out->umax, sqrt(m));
        if (li == nx) {
            tip -= u[2];
            ntip++;
        }
    }
    out->tip = ntip ? tip / ntip : NAN;
    cs_world_destroy(w);
    return rc == CS_OK ? 0 : 1;
}

/* Largest |u_coarse − u_ref| over the coarse lattice's nodes, relative to ref's largest. */
static double max_error(solved *coarse, solved *ref)
{
    const int r = (int)lround(coarse->h / ref->h);
    double e = 0;
    for (int k = 0; k <= coarse->nz; k++)
        for (int j = 0; j <= coarse->ny; j++)
            for (int i = 0; i <= coarse->nx; i++) {
                const double *a = lattice_at(coarse, i, j, k);
                if (isnan(a[0]))
                    continue;
                const double *b = lattice_at(ref, r * i, r * j, r * k);
                const double d = sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                                      (a[2] - b[2]) * (a[2] - b[2]));
                e = fmax(e, d);
            }
    return e / ref->umax;
}

/* ---------------------------------------------------------------- geometry */

static int32_t *box_cells(int nx, int ny, int nz, int *n)
{
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    *n = nx * ny * nz;
    return ijk;
}

/* The L with r cubes per 2 m: the 4r×2r×r... base leg (x < 4, z < 2) and the upright leg
 * (x < 2, 2 ≤ z < 4), 4 m deep along y. */
static int32_t *l_cells(int r, int *n)
{
    int32_t *ijk = malloc(sizeof(int32_t) * 3 * (size_t)(8 * r * r * r));
    int c = 0;
    for (int k = 0; k < 2 * r; k++)
        for (int j = 0; j < 2 * r; j++)
            for (int i = 0; i < 2 * r; i++) {
                if (k >= r && i >= r)
                    continue;
                ijk[3 * c] = i;
                ijk[3 * c + 1] = j;
                ijk[3 * c + 2] = k;
                c++;
            }
    *n = c;
    return ijk;
}

static int cantilever_case(cs_model model, double rho, int m, solved *out)
{
    const double H = 0.1, h = H / m;
    int n;
    int32_t *ijk = box_cells(4 * m, m, m, &n);
    const cs_aabb fix = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1, 1}};
    const double g[3] = {0, 0, -9.81};
    int rc = solve(model, rho, g, ijk, n, 4 * m, m, m, h, &fix, NULL, out);
    free(ijk);
    return rc;
}

static int lshape_case(cs_model model, int r, double force, solved *out)
{
    const double h = 2.0 / r;
    int n;
    int32_t *ijk = l_cells(r, &n);
    const cs_aabb fix = {{-1, -1, -1e-3 * h}, {5, 5, 1e-3 * h}};
    const cs_load load = {{{-1, -1, 4 - 1e-3 * h}, {2 + 1e-3 * h, 5, 4 + 1e-3 * h}}, {force, 0, 0}};
    const double g[3] = {0, 0, 0};
    int rc = solve(model, 1.0, g, ijk, n, 2 * r, 2 * r, 2 * r, h, &fix, &load, out);
    free(ijk);
    return rc;
}

int main(int argc, char **argv)
{
    int ref = 12, lref = 12;
    double rho = 0.0125;
    const char *csv_c = NULL, *csv_l = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--ref") && i + 1 < argc)
            ref = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--lref") && i + 1 < argc)
            lref = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--rho") && i + 1 < argc)
            rho = atof(argv[++i]);
        else if (!strcmp(argv[i], "--csv-cantilever") && i + 1 < argc)
            csv_c = argv[++i];
        else if (!strcmp(argv[i], "--csv-lshape") && i + 1 < argc)
            csv_l = argv[++i];
        else {
            fprintf(stderr, "usage: bench_mss [--ref 12] [--lref 12] [--rho 0.0125] [--csv-cantilever FILE] "
                            "[--csv-lshape FILE]\n");
            return 2;
        }
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (ref < 2 || ref % 2 || lref < 2 || lref % 2) {
        fprintf(stderr, "bench_mss: --ref must be even (and a multiple of 12 for every "
                        "resolution: resolutions that do not divide it are skipped)\n");
        return 2;
    }
    int failed = 0;
    const int res[4] = {1, 2, 3, 4};

    /* ------------------------------------------------ cantilever */
    solved R = {0}, Rh = {0};
    failed |= cantilever_case(CS_MODEL_COROTATIONAL, rho, ref, &R) < 0;
    failed |= cantilever_case(CS_MODEL_COROTATIONAL, rho, ref / 2, &Rh) < 0;
    if (failed)
        return 1;
    const double L = 0.4, H = 0.1, I = H * H * H * H / 12, q = rho * H * H * 9.81;
    const double eb = q * L * L * L * L / (8 * 1000 * I);
    printf("### Cantilever (seed 004 §4, Fig. 5): 400×100×100 mm, E = 1000 Pa, ν = 0.3, "
           "ρ = %g kg/m³, own weight\n\n", rho);
    printf("Reference: corotational FEM, %d×%d×%d cubes (h = %.2f mm), tip deflection %.4g mm "
           "(%d CG iterations, %.1f s); at %d×%d×%d cubes the reference itself differs by %.2f %% "
           "(max nodal, at the common nodes). Euler–Bernoulli (ν = 0 theory) %.4g mm.\n\n",
           4 * ref, ref, ref, 100.0 / ref, 1e3 * R.tip, R.iterations, R.seconds, 2 * ref, ref / 2,
           ref / 2, 100 * max_error(&Rh, &R), 1e3 * eb);
    printf("| cubes | h [mm] | mss tip [mm] | mss max nodal error | FEM tip [mm] | FEM max nodal error | paper (mss) |\n");
    printf("|---|---|---|---|---|---|---|\n");
    FILE *fc = csv_c ? fopen(csv_c, "w") : NULL;
    if (fc)
        fprintf(fc, "resolution,cubes,h_mm,rho,mss_tip_mm,mss_max_err,fem_tip_mm,fem_max_err,"
                    "ref_tip_mm,ref_cubes_across,ref_self_err\n");
    for (int t = 0; t < 4; t++) {
        const int m = res[t];
        if (ref % m)
            continue;
        solved S = {0}, F = {0};
        int r1 = cantilever_case(CS_MODEL_MSS, rho, m, &S);
        int r2 = cantilever_case(CS_MODEL_COROTATIONAL, rho, m, &F);
        if (r1 < 0 || r2 < 0)
            return 1;
        failed |= r1 | r2;
        const double es = max_error(&S, &R), ef = max_error(&F, &R);
        const char *paper = m == 1 ? "≈ 45 %" : m == 4 ? "≈ 5 %" : "—";
        printf("| %d×%d×%d | %.1f | %.4g | %.1f %%%s | %.4g | %.1f %%%s | %s |\n", 4 * m, m, m,
               100.0 / m, 1e3 * S.tip, 100 * es, r1 ? " (not converged)" : "", 1e3 * F.tip,
               100 * ef, r2 ? " (not converged)" : "", paper);
        if (fc)
            fprintf(fc, "%dx%dx%d,%d,%.4f,%g,%.6g,%.5f,%.6g,%.5f,%.6g,%d,%.5f\n", 4 * m, m, m,
                    4 * m * m * m, 100.0 / m, rho, 1e3 * S.tip, es, 1e3 * F.tip, ef, 1e3 * R.tip,
                    ref, max_error(&Rh, &R));
        free(S.u);
        free(F.u);
    }
    if (fc)
        fclose(fc);
    free(R.u);
    free(Rh.u);

    /* ------------------------------------------------ L shape */
    const double force = 1.0; /* [N]: max displacement ≈ 1 % of the size at E = 1 kPa */
    solved LR = {0}, LRh = {0};
    if (lshape_case(CS_MODEL_COROTATIONAL, lref, force, &LR) < 0 ||
        lshape_case(CS_MODEL_COROTATIONAL, lref / 2, force, &LRh) < 0)
        return 1;
    printf("\n### L-shaped shear (seed 004 §4, Fig. 6): 4×4×4 m L, E = 1000 Pa, ν = 0.3, no "
           "weight, base held, %g N along +x on the upright's top face\n\n", force);
    printf("Reference: corotational FEM, %d cubes per 2 m (h = %.0f mm), largest displacement "
           "%.4g mm (%d CG iterations, %.1f s); at %d cubes per 2 m the reference differs by "
           "%.2f %%.\n\n", lref, 2000.0 / lref, 1e3 * LR.umax, LR.iterations, LR.seconds, lref / 2,
           100 * max_error(&LRh, &LR));
    printf("| cubes per 2 m | h [mm] | mss largest displacement [mm] | mss max nodal error | FEM max nodal error |\n");
    printf("|---|---|---|---|---|\n");
    FILE *fl = csv_l ? fopen(csv_l, "w") : NULL;
    if (fl)
        fprintf(fl, "per_2m,h_mm,mss_umax_mm,mss_max_err,fem_umax_mm,fem_max_err,ref_umax_mm,"
                    "ref_per_2m,ref_self_err\n");
    for (int t = 0; t < 4; t++) {
        const int r = res[t];
        if (lref % r)
            continue;
        solved S = {0}, F = {0};
        int r1 = lshape_case(CS_MODEL_MSS, r, force, &S);
        int r2 = lshape_case(CS_MODEL_COROTATIONAL, r, force, &F);
        if (r1 < 0 || r2 < 0)
            return 1;
        failed |= r1 | r2;
        const double es = max_error(&S, &LR), ef = max_error(&F, &LR);
        printf("| %d | %.0f | %.4g | %.1f %%%s | %.1f %%%s |\n", r, 2000.0 / r, 1e3 * S.umax,
               100 * es, r1 ? " (not converged)" : "", 100 * ef, r2 ? " (not converged)" : "");
        if (fl)
            fprintf(fl, "%d,%.1f,%.6g,%.5f,%.6g,%.5f,%.6g,%d,%.5f\n", r, 2000.0 / r, 1e3 * S.umax,
                    es, 1e3 * F.umax, ef, 1e3 * LR.umax, lref, max_error(&LRh, &LR));
        free(S.u);
        free(F.u);
    }
    if (fl)
        fclose(fl);
    free(LR.u);
    free(LRh.u);
    return failed ? 1 : 0;
}
