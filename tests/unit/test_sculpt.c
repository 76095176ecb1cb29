/*
 * test_sculpt.c — material fields, sculpting inputs and constraint modes (seed 001 §3.3, §4)
 * against known answers: axial bars with painted bands (1-D, exact for ν = 0), a graded bar
 * against the closed form ∫ F/(E(x)A) dx, uniform fields against the plain material, mass
 * painting against the lumped mass and a free fall, pressure against the bulk modulus, curve
 * drags against the curve, penalty supports against removed ones, and refusal of bad input.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubemesh.h"
#include "cubesim.h"
#include "fem.h"
#include "scene.h"

typedef struct bar {
    cs_world_t *w;
    cs_object_id id;
    int32_t *ijk;
} bar;

typedef struct bar_opts {
    cs_model model;
    cs_material mat;
    int nx, ny, nz;
    double h;
    bool fixed;             /* the face x = 0 held */
    double tip[3];          /* total force on the face x = nx·h */
    const cs_field_region *fields;
    int n_fields;
    cs_constraint_mode constraints;
    double penalty;
    cs_world_def wd;
} bar_opts;

static cs_world_def quiet(void)
{
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = 0;
    wd.cg_tolerance = 1e-10;
    wd.cg_max_iterations = 5000;
    wd.threads = 1;
    wd.sleep_steps = 0;
    return wd;
}

static bar_opts opts_default(void)
{
    bar_opts o = {.model = CS_MODEL_LINEAR, .mat = cs_material_default(), .nx = 8, .ny = 1,
                  .nz = 1, .h = 0.1, .fixed = true, .wd = quiet()};
    o.mat.young = 1e5;
    o.mat.poisson = 0.0;
    return o;
}

static int make_bar(bar *b, const bar_opts *op)
{
    char err[256];
    memset(b, 0, sizeof *b);
    if (cs_world_create(&op->wd, &b->w, err, sizeof err) != CS_OK) {
        printf("    world: %s\n", err);
        return -1;
    }
    const int n = op->nx * op->ny * op->nz;
    b->ijk = malloc(sizeof(int32_t) * 3 * (size_t)n);
    int c = 0;
    for (int k = 0; k < op->nz; k++)
        for (int j = 0; j < op->ny; j++)
            for (int i = 0; i < op->nx; i++) {
                b->ijk[3 * c] = i;
                b->ijk[3 * c + 1] = j;
                b->ijk[3 * c + 2] = k;
                c++;
            }
    cs_object_def d = cs_object_def_default();
    d.name = "bar";
    d.model = op->model;
    d.material = op->mat;
    d.cube_size = op->h;
    d.cells_ijk = b->ijk;
    d.n_cells = n;
    d.fields = op->fields;
    d.n_fields = op->n_fields;
    d.constraints = op->constraints;
    d.penalty_stiffness = op->penalty;
    const double h = op->h;
    cs_aabb fix = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1e3, 1e3}};
    cs_load load = {{{op->nx * h - 1e-3 * h, -1, -1}, {op->nx * h + 1e-3 * h, 1e3, 1e3}},
                    {op->tip[0], op->tip[1], op->tip[2]}};
    if (op->fixed) {
        d.fixed = &fix;
        d.n_fixed = 1;
    }
    if (op->tip[0] != 0 || op->tip[1] != 0 || op->tip[2] != 0) {
        d.loads = &load;
        d.n_loads = 1;
    }
    if (cs_world_add_object(b->w, &d, &b->id, err, sizeof err) != CS_OK) {
        printf("    add: %s\n", err);
        return -1;
    }
    return 0;
}

static void free_bar(bar *b)
{
    cs_world_destroy(b->w);
    free(b->ijk);
}

/* Mean x displacement of the nodes on the plane x = xp. */
static double ux_at(const bar *b, double xp)
{
    const double *rest, *pos;
    int n, cnt = 0;
    double s = 0;
    cs_object_nodes(b->w, b->id, &rest, &pos, NULL, &n);
    for (int i = 0; i < n; i++)
        if (fabs(rest[3 * i] - xp) < 1e-9) {
            s += pos[3 * i] - rest[3 * i];
            cnt++;
        }
    return s / cnt;
}

/* A band of cells [i0, i1) of a bar one cell thick painted with stiffness factor f: the
 * strain is F/(E A) outside and F/(f E A) inside (ν = 0: the 1-D answer is exact). */
TEST(sculpt_paint_stiff_band_changes_strain_there_only)
{
    bar_opts op = opts_default();
    const double F = 2.0, E = op.mat.young, h = op.h, A = h * h, f = 4.0;
    op.tip[0] = F;
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    /* Gauss points of cells 3 and 4 (x in [0.3, 0.5]) are within 0.1 of x = 0.4 on the axis
     * (their distance from it across the section is 0.041); those of cells 2 and 5 are not. */
    const int i0 = 3, i1 = 5;
    cs_field_factors ff = {.young = f, .which = CS_FIELD_YOUNG};
    int touched = 0;
    char err[256] = "";
    ENSURE(cs_world_paint(b.w, b.id, (double[3]){0.4, 0.05, 0.05}, 0.1, &ff, &touched, err,
                          sizeof err) == CS_OK);
    ENSURE_MSG(touched == 8 * (i1 - i0), "painted %d Gauss points, want %d", touched,
               8 * (i1 - i0));
    ENSURE(cs_world_solve_static(b.w) == CS_OK);
    const double eps = F / (E * A);
    double worst = 0;
    for (int i = 0; i < op.nx; i++) {
        const double strain = (ux_at(&b, (i + 1) * h) - ux_at(&b, i * h)) / h;
        const double want = (i >= i0 && i < i1) ? eps / f : eps;
        worst = fmax(worst, fabs(strain - want) / eps);
    }
    printf("    largest strain error %.2g of F/(EA)\n", worst);
    ENSURE_MSG(worst < 1e-6, "strain differs from the 1-D answer by %g of F/(EA)", worst);
    /* left of the band the displacement is the unpainted one */
    ENSURE_NEAR(ux_at(&b, 2 * h), eps * 2 * h, 1e-6 * eps * h);
    free_bar(&b);
}

/* The same band as a design region of the scene (a box) gives the same answer. */
TEST(sculpt_design_box_region_equals_painted_band)
{
    bar_opts op = opts_default();
    const double F = 2.0, E = op.mat.young, h = op.h, A = h * h;
    op.tip[0] = F;
    cs_field_region r = {.shape = CS_FIELD_BOX,
                         .box = {{0.3 - 1e-9, -1, -1}, {0.5 + 1e-9, 1, 1}},
                         .factors = {.young = 4.0, .which = CS_FIELD_YOUNG}};
    op.fields = &r;
    op.n_fields = 1;
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    ENSURE(cs_world_solve_static(b.w) == CS_OK);
    const double eps = F / (E * A);
    const double tip = eps * (0.8 - 0.2 + 0.2 / 4.0);
    ENSURE_NEAR(ux_at(&b, 0.8), tip, 1e-6 * tip);
    free_bar(&b);
}

/* A linear gradient E(x) = E₀(1 + (f−1)x/L): u(L) = F L ln f / (A E₀ (f−1)). The Gauss-point
 * sampling integrates each cell's stiffness exactly, so the error is the midpoint rule's:
 * second order, checked by halving h. */
TEST(sculpt_gradient_field_converges_to_closed_form)
{
    const double F = 1.0, L = 0.8, fac = 5.0;
    double errs[2];
    for (int r = 0; r < 2; r++) {
        bar_opts op = opts_default();
        op.nx = 8 << r;
        op.h = L / op.nx;
        op.ny = op.nz = 1;
        op.tip[0] = F;
        cs_field_region g = {.shape = CS_FIELD_GRADIENT, .from = {0, 0, 0}, .to = {L, 0, 0},
                             .factors = {.young = fac, .which = CS_FIELD_YOUNG}};
        op.fields = &g;
        op.n_fields = 1;
        bar b;
        ENSURE(make_bar(&b, &op) == 0);
        ENSURE(cs_world_solve_static(b.w) == CS_OK);
        const double A = op.h * op.h, E0 = op.mat.young;
        const double exact = F * L * log(fac) / (A * E0 * (fac - 1));
        errs[r] = fabs(ux_at(&b, L) - exact) / exact;
        free_bar(&b);
    }
    printf("    relative tip error %.3g (h), %.3g (h/2), ratio %.2f\n", errs[0], errs[1],
           errs[0] / errs[1]);
    ENSURE_MSG(errs[0] < 0.01, "error %g at 8 cells", errs[0]);
    ENSURE_MSG(errs[0] / errs[1] > 3.5, "error fell by %g, want about 4", errs[0] / errs[1]);
}

static bool same_state(const bar *a, const bar *b, double rel)
{
    const double *pa, *pb, *va, *vb;
    int na, nb;
    cs_object_nodes(a->w, a->id, NULL, &pa, &va, &na);
    cs_object_nodes(b->w, b->id, NULL, &pb, &vb, &nb);
    if (na != nb)
        return false;
    for (int i = 0; i < 3 * na; i++) {
        const double tp = rel * (1 + fabs(pa[i])), tv = rel * (1 + fabs(va[i]));
        if (fabs(pa[i] - pb[i]) > tp || fabs(va[i] - vb[i]) > tv)
            return false;
    }
    return true;
}

/* A field of ones is the plain material bit for bit; a uniform factor c equals the material
 * with E·c (ρ·c, damping·c) up to round-off; painted damping 0 equals an undamped material. */
TEST(sculpt_uniform_fields_equal_plain_material)
{
    bar_opts op = opts_default();
    op.model = CS_MODEL_COROTATIONAL;
    op.nx = 6;
    op.ny = op.nz = 2;
    op.tip[2] = -3.0;
    op.mat.damping[0] = 0.5;
    op.mat.damping[1] = 0.01;
    op.wd.gravity[2] = -9.81;
    bar plain, ones, scaled, ref, undamped, zero;
    ENSURE(make_bar(&plain, &op) == 0);
    cs_field_region all = {.shape = CS_FIELD_BOX, .box = {{-1, -1, -1}, {9, 9, 9}},
                           .factors = {.young = 1, .density = 1, .damping = 1,
                                       .which = CS_FIELD_YOUNG | CS_FIELD_DENSITY |
                                                CS_FIELD_DAMPING}};
    op.fields = &all;
    op.n_fields = 1;
    ENSURE(make_bar(&ones, &op) == 0);
    all.factors = (cs_field_factors){.young = 2.5, .density = 1.5, .damping = 3,
                                     .which = CS_FIELD_YOUNG | CS_FIELD_DENSITY |
                                              CS_FIELD_DAMPING};
    ENSURE(make_bar(&scaled, &op) == 0);
    bar_opts op2 = op;
    op2.fields = NULL;
    op2.n_fields = 0;
    op2.mat.young *= 2.5;
    op2.mat.density *= 1.5;
    op2.mat.damping[0] *= 3;
    op2.mat.damping[1] *= 3;
    ENSURE(make_bar(&ref, &op2) == 0);
    op2 = op;
    op2.fields = NULL;
    op2.n_fields = 0;
    op2.mat.damping[0] = op2.mat.damping[1] = 0;
    ENSURE(make_bar(&undamped, &op2) == 0);
    op2.mat = op.mat;
    ENSURE(make_bar(&zero, &op2) == 0);
    char err[256];
    ENSURE(cs_world_paint(zero.w, zero.id, (double[3]){0.3, 0.1, 0.1}, 5.0,
                          &(cs_field_factors){.damping = 0, .which = CS_FIELD_DAMPING}, NULL,
                          err, sizeof err) == CS_OK);
    for (int s = 0; s < 40; s++) {
        ENSURE(cs_world_step(plain.w) == CS_OK);
        ENSURE(cs_world_step(ones.w) == CS_OK);
        ENSURE(cs_world_step(scaled.w) == CS_OK);
        ENSURE(cs_world_step(ref.w) == CS_OK);
        ENSURE(cs_world_step(undamped.w) == CS_OK);
        ENSURE(cs_world_step(zero.w) == CS_OK);
    }
    ENSURE_MSG(same_state(&plain, &ones, 0.0), "a field of ones changed the result");
    ENSURE_MSG(same_state(&zero, &undamped, 0.0), "damping painted 0 is not undamped");
    ENSURE_MSG(same_state(&scaled, &ref, 1e-9), "uniform factors differ from the scaled material");
    ENSURE_MSG(!same_state(&plain, &undamped, 1e-6), "the test load did not move the bar");
    free_bar(&plain);
    free_bar(&ones);
    free_bar(&scaled);
    free_bar(&ref);
    free_bar(&undamped);
    free_bar(&zero);
}

/* Mass painting: the mass grows by (f−1)ρh³/8 per painted Gauss point, and gravity follows
 * it: a free bar at rest falls with g at every node after one step (implicit Euler:
 * (M + dt²K) v = dt M g has the solution v = g dt exactly when the load is M g). */
TEST(sculpt_mass_paint_changes_mass_and_gravity_consistently)
{
    bar_opts op = opts_default();
    op.fixed = false;
    op.nx = 4;
    op.ny = op.nz = 2;
    op.wd.gravity[2] = -9.81;
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    cs_object_info info;
    cs_object_get_info(b.w, b.id, &info);
    const double m0 = info.mass, h = op.h, rho = op.mat.density;
    ENSURE_NEAR(m0, rho * 16 * h * h * h, 1e-12 * m0);
    int touched = 0;
    char err[256];
    ENSURE(cs_world_paint(b.w, b.id, (double[3]){0.05, 0.05, 0.05}, 0.12,
                          &(cs_field_factors){.density = 3, .which = CS_FIELD_DENSITY},
                          &touched, err, sizeof err) == CS_OK);
    ENSURE(touched > 0 && touched < 8 * 16);
    cs_object_get_info(b.w, b.id, &info);
    const double want = m0 + touched * (3 - 1) * rho * h * h * h / 8;
    printf("    %d Gauss points painted: mass %.6g kg (want %.6g)\n", touched, info.mass, want);
    ENSURE_NEAR(info.mass, want, 1e-12 * want);
    ENSURE(cs_world_step(b.w) == CS_OK);
    const double *v;
    int n;
    cs_object_nodes(b.w, b.id, NULL, NULL, &v, &n);
    const double dt = op.wd.dt;
    for (int i = 0; i < n; i++) {
        ENSURE_NEAR(v[3 * i + 2], -9.81 * dt, 1e-8);
        ENSURE_NEAR(v[3 * i], 0.0, 1e-8);
    }
    free_bar(&b);
}

/* Volume enclosed by the object's surface (divergence theorem) and its centroid of nodes. */
static double enclosed_volume(const cs_world_t *w, cs_object_id id)
{
    const double *v;
    const int32_t *t;
    int nv, nt;
    cs_object_surface(w, id, &v, &nv, &t, &nt);
    double vol = 0;
    for (int i = 0; i < nt; i++) {
        const double *a = v + 3 * t[3 * i], *b = v + 3 * t[3 * i + 1], *c = v + 3 * t[3 * i + 2];
        vol += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0;
    }
    return vol;
}

/* Inflate and deflate a free 3×3×3 block: the volume change tends to p/K (K the bulk modulus,
 * uniform hydrostatic stress), the centre stays, and the block swells alike along each axis. */
TEST(sculpt_pressure_inflates_and_deflates_symmetrically)
{
    for (int sign = -1; sign <= 1; sign += 2) {
        bar_opts op = opts_default();
        op.fixed = false;
        op.nx = op.ny = op.nz = 3;
        op.mat.young = 1e4;
        op.mat.poisson = 0.3;
        op.mat.density = 100;
        op.mat.damping[0] = 40;
        op.wd.dt = 0.01;
        bar b;
        ENSURE(make_bar(&b, &op) == 0);
        const double V0 = enclosed_volume(b.w, b.id);
        ENSURE_NEAR(V0, 0.027, 1e-12);
        const double p = sign * 50.0, K = op.mat.young / (3 * (1 - 2 * op.mat.poisson));
        char err[256];
        ENSURE(cs_world_pressure(b.w, b.id, p, 4.0, err, sizeof err) == CS_OK);
        for (int s = 0; s < 400; s++)
            ENSURE(cs_world_step(b.w) == CS_OK);
        const double dv = (enclosed_volume(b.w, b.id) - V0) / V0;
        const double *rest, *pos;
        int n;
        cs_object_nodes(b.w, b.id, &rest, &pos, NULL, &n);
        double c[3] = {0, 0, 0}, lo[3] = {1e9, 1e9, 1e9}, hi[3] = {-1e9, -1e9, -1e9};
        for (int i = 0; i < n; i++)
            for (int a = 0; a < 3; a++) {
                c[a] += pos[3 * i + a] / n;
                lo[a] = fmin(lo[a], pos[3 * i + a]);
                hi[a] = fmax(hi[a], pos[3 * i + a]);
            }
        printf("    p = %+g Pa: dV/V = %.5g, p/K = %.5g; extents %.6f %.6f %.6f\n", p, dv,
               p / K, hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
        ENSURE_MSG(sign * dv > 0, "pressure %g changed the volume by %g", p, dv);
        ENSURE_NEAR(dv, p / K, 0.1 * fabs(p / K));
        for (int a = 0; a < 3; a++) {
            ENSURE_NEAR(c[a], 0.15, 1e-9);
            ENSURE_NEAR(hi[a] - lo[a], hi[0] - lo[0], 1e-3 * fabs(hi[0] - lo[0] - 0.3));
        }
        free_bar(&b);
    }
}

/* Drag a block's corner along an L-shaped curve: the corner follows the moving target with a
 * small lag and ends at the curve's end. */
TEST(sculpt_curve_drag_follows_the_curve)
{
    bar_opts op = opts_default();
    op.fixed = false;
    op.nx = op.ny = op.nz = 2;
    op.mat.young = 1e5;
    op.mat.poisson = 0.3;
    op.mat.density = 100;
    op.mat.damping[0] = 5;
    op.wd.dt = 0.01;
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    const double pts[9] = {0, 0, 0, 0.5, 0, 0, 0.5, 0.5, 0};
    char err[256];
    const double k = 2000, T = 2.0;
    ENSURE(cs_world_drag_curve(b.w, b.id, pts, 3, k, T, err, sizeof err) == CS_OK);
    const double *rest, *pos;
    int n, node = -1;
    cs_object_nodes(b.w, b.id, &rest, &pos, NULL, &n);
    for (int i = 0; i < n; i++)
        if (rest[3 * i] == 0 && rest[3 * i + 1] == 0 && rest[3 * i + 2] == 0)
            node = i;
    ENSURE(node >= 0);
    const int S = (int)llround(T / op.wd.dt);
    double worst = 0;
    for (int s = 1; s <= S; s++) {
        ENSURE(cs_world_step(b.w) == CS_OK);
        cs_object_nodes(b.w, b.id, NULL, &pos, NULL, NULL);
        const double *x = pos + 3 * node;
        /* distance from the polyline */
        const double d1 = fabs(x[1]) + fmax(0, x[0] - 0.5) + fmax(0, -x[0]);
        const double d2 = fabs(x[0] - 0.5) + fmax(0, x[1] - 0.5) + fmax(0, -x[1]);
        worst = fmax(worst, fmin(d1, d2) + fabs(x[2]));
    }
    cs_object_nodes(b.w, b.id, NULL, &pos, NULL, NULL);
    const double *x = pos + 3 * node;
    const double end = hypot(x[0] - 0.5, x[1] - 0.5);
    printf("    largest distance from the curve %.4f m, distance from its end %.4f m\n", worst,
           end);
    ENSURE_MSG(worst < 0.03, "left the curve by %g m", worst);
    ENSURE_MSG(end < 0.03, "ended %g m from the curve's end", end);
    free_bar(&b);
}

/* Penalty supports against removed ones: a cantilever under a tip load, static. With the
 * automatic stiffness k = 1e4·E·h a held node moves |reaction|/k; here every held node stays
 * within 1e-3 of the tip deflection and the displacement field agrees to 1e-3 of it. */
TEST(sculpt_penalty_constraints_agree_with_removal)
{
    bar_opts op = opts_default();
    op.nx = 8;
    op.ny = op.nz = 2;
    op.tip[2] = -1.0;
    bar rem, pen;
    ENSURE(make_bar(&rem, &op) == 0);
    op.constraints = CS_CONSTRAINT_PENALTY;
    ENSURE(make_bar(&pen, &op) == 0);
    ENSURE(cs_world_solve_static(rem.w) == CS_OK);
    ENSURE(cs_world_solve_static(pen.w) == CS_OK);
    const double *rest, *pr, *pp;
    int n;
    cs_object_nodes(rem.w, rem.id, &rest, &pr, NULL, &n);
    cs_object_nodes(pen.w, pen.id, NULL, &pp, NULL, NULL);
    double tip = 0, diff = 0, held = 0;
    for (int i = 0; i < 3 * n; i++) {
        tip = fmax(tip, fabs(pr[i] - rest[i]));
        diff = fmax(diff, fabs(pr[i] - pp[i]));
        if (rest[i - i % 3] < 1e-9)
            held = fmax(held, fabs(pp[i] - rest[i]));
    }
    printf("    tip %.4g m; penalty vs removal %.3g of it; held nodes moved %.3g of it\n", tip,
           diff / tip, held / tip);
    ENSURE(tip > 1e-3);
    ENSURE_MSG(held > 0 && held < 1e-3 * tip, "held nodes moved %g of the tip", held / tip);
    ENSURE_MSG(diff < 1e-3 * tip, "fields differ by %g of the tip", diff / tip);
    /* and in a dynamic run under gravity */
    free_bar(&rem);
    free_bar(&pen);
    op.tip[2] = 0;
    op.wd.gravity[2] = -9.81;
    op.mat.damping[0] = 2;
    op.constraints = CS_CONSTRAINT_REMOVE;
    ENSURE(make_bar(&rem, &op) == 0);
    op.constraints = CS_CONSTRAINT_PENALTY;
    ENSURE(make_bar(&pen, &op) == 0);
    for (int s = 0; s < 60; s++) {
        ENSURE(cs_world_step(rem.w) == CS_OK);
        ENSURE(cs_world_step(pen.w) == CS_OK);
    }
    cs_object_nodes(rem.w, rem.id, &rest, &pr, NULL, &n);
    cs_object_nodes(pen.w, pen.id, NULL, &pp, NULL, NULL);
    tip = diff = 0;
    for (int i = 0; i < 3 * n; i++) {
        tip = fmax(tip, fabs(pr[i] - rest[i]));
        diff = fmax(diff, fabs(pr[i] - pp[i]));
    }
    printf("    dynamic: deflection %.4g m, penalty vs removal %.3g of it\n", tip, diff / tip);
    ENSURE_MSG(diff < 1e-3 * tip, "dynamic fields differ by %g of the deflection", diff / tip);
    free_bar(&rem);
    free_bar(&pen);
}

/* Fracture carries the per-cell fields into the pieces, and their masses follow them. */
TEST(sculpt_fracture_carries_fields_into_pieces)
{
    bar_opts op = opts_default();
    op.fixed = false;
    op.nx = 6;
    op.ny = op.nz = 2;
    cs_field_region r = {.shape = CS_FIELD_BOX, .box = {{-1, -1, -1}, {0.3, 1, 1}},
                         .factors = {.young = 3, .density = 2,
                                     .which = CS_FIELD_YOUNG | CS_FIELD_DENSITY}};
    op.fields = &r;
    op.n_fields = 1;
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    char err[256];
    for (int j = 0; j < 2; j++)
        for (int k = 0; k < 2; k++)
            ENSURE_MSG(cs_world_cut_face(b.w, b.id, (int32_t[3]){2, j, k}, 0, err,
                                         sizeof err) == CS_OK, "%s", err);
    cs_object_id ids[8];
    const int no = cs_world_object_ids(b.w, ids, 8);
    ENSURE_MSG(no == 2, "%d objects after the cut", no);
    const double h = op.h, rho = op.mat.density;
    for (int k = 0; k < no; k++) {
        const double *yf, *df, *rest;
        int nc, n;
        cs_object_fields(b.w, ids[k], &yf, &df, NULL, &nc);
        cs_object_nodes(b.w, ids[k], &rest, NULL, NULL, &n);
        double xmax = -1;
        for (int i = 0; i < n; i++)
            xmax = fmax(xmax, rest[3 * i]);
        const bool is_left = xmax < 0.3 + 1e-9;
        for (int i = 0; i < 8 * nc; i++) {
            ENSURE_NEAR(yf[i], is_left ? 3.0 : 1.0, 0);
            ENSURE_NEAR(df[i], is_left ? 2.0 : 1.0, 0);
        }
        cs_object_info info;
        cs_object_get_info(b.w, ids[k], &info);
        const double want = (is_left ? 2.0 : 1.0) * rho * nc * h * h * h;
        ENSURE_NEAR(info.mass, want, 1e-12 * want);
        ENSURE(nc == 12);
    }
    free_bar(&b);
}

TEST(sculpt_refuses_bad_input_with_clear_messages)
{
    bar_opts op = opts_default();
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    char err[256];
    const double c[3] = {0.1, 0.05, 0.05};
    cs_field_factors ok = {.young = 2, .which = CS_FIELD_YOUNG};
#define REFUSED(call, code, word)                                                              \
    do {                                                                                       \
        err[0] = 0;                                                                            \
        int rc_ = (call);                                                                      \
        ENSURE_MSG(rc_ == (code), "%s returned %d", #call, rc_);                               \
        ENSURE_MSG(strstr(err, word) != NULL, "message '%s' lacks '%s'", err, word);           \
    } while (0)
    REFUSED(cs_world_paint(b.w, b.id, (double[3]){NAN, 0, 0}, 0.1, &ok, NULL, err, sizeof err),
            CS_ERR_INVALID, "centre");
    REFUSED(cs_world_paint(b.w, b.id, c, 0.0, &ok, NULL, err, sizeof err), CS_ERR_INVALID,
            "radius");
    REFUSED(cs_world_paint(b.w, b.id, c, NAN, &ok, NULL, err, sizeof err), CS_ERR_INVALID,
            "radius");
    REFUSED(cs_world_paint(b.w, b.id, c, 0.1,
                           &(cs_field_factors){.young = -1, .which = CS_FIELD_YOUNG}, NULL, err,
                           sizeof err),
            CS_ERR_INVALID, "young factor");
    REFUSED(cs_world_paint(b.w, b.id, c, 0.1,
                           &(cs_field_factors){.density = NAN, .which = CS_FIELD_DENSITY}, NULL,
                           err, sizeof err),
            CS_ERR_INVALID, "density factor");
    REFUSED(cs_world_paint(b.w, b.id, c, 0.1,
                           &(cs_field_factors){.damping = -0.5, .which = CS_FIELD_DAMPING}, NULL,
                           err, sizeof err),
            CS_ERR_INVALID, "damping factor");
    REFUSED(cs_world_paint(b.w, b.id, c, 0.1, &(cs_field_factors){.young = 2}, NULL, err,
                           sizeof err),
            CS_ERR_INVALID, "at least one");
    REFUSED(cs_world_paint(b.w, 99, c, 0.1, &ok, NULL, err, sizeof err), CS_ERR_UNKNOWN_OBJECT,
            "no object");
    REFUSED(cs_world_pressure(b.w, b.id, NAN, 1, err, sizeof err), CS_ERR_INVALID, "pressure");
    REFUSED(cs_world_pressure(b.w, b.id, 1e12, 1, err, sizeof err), CS_ERR_INVALID, "max_force");
    REFUSED(cs_world_pressure(b.w, b.id, 1, -1, err, sizeof err), CS_ERR_INVALID, "duration");
    REFUSED(cs_world_pressure(b.w, 99, 1, 1, err, sizeof err), CS_ERR_UNKNOWN_OBJECT,
            "no object");
    const double pts[6] = {0, 0, 0, 1, 0, 0};
    REFUSED(cs_world_drag_curve(b.w, b.id, pts, 1, 10, 1, err, sizeof err), CS_ERR_INVALID,
            "2 to");
    REFUSED(cs_world_drag_curve(b.w, b.id, (double[6]){0, 0, 0, NAN, 0, 0}, 2, 10, 1, err,
                                sizeof err),
            CS_ERR_INVALID, "point 1");
    REFUSED(cs_world_drag_curve(b.w, b.id, (double[6]){0, 0, 0, 0, 0, 0}, 2, 10, 1, err,
                                sizeof err),
            CS_ERR_INVALID, "zero length");
    REFUSED(cs_world_drag_curve(b.w, b.id, pts, 2, -10, 1, err, sizeof err), CS_ERR_INVALID,
            "stiffness");
    REFUSED(cs_world_drag_curve(b.w, b.id, pts, 2, 10, 0, err, sizeof err), CS_ERR_INVALID,
            "duration");
    REFUSED(cs_world_drag_curve(b.w, 99, pts, 2, 10, 1, err, sizeof err), CS_ERR_UNKNOWN_OBJECT,
            "no object");
    /* nothing refused changed the object */
    cs_object_info info;
    cs_object_get_info(b.w, b.id, &info);
    ENSURE_NEAR(info.mass, op.mat.density * 8 * 1e-3, 1e-12);
    const double *yf;
    int nc;
    cs_object_fields(b.w, b.id, &yf, NULL, NULL, &nc);
    for (int i = 0; i < 8 * nc; i++)
        ENSURE(yf[i] == 1.0);
    /* definitions */
    free_bar(&b);
    cs_field_region bad = {.shape = CS_FIELD_SPHERE, .centre = {0, 0, 0}, .radius = 0,
                           .factors = ok};
    op.fields = &bad;
    op.n_fields = 1;
    ENSURE(make_bar(&b, &op) != 0);
    cs_world_destroy(b.w);
    free(b.ijk);
    bad.radius = 1;
    bad.factors.young = 0;
    ENSURE(make_bar(&b, &op) != 0);
    cs_world_destroy(b.w);
    free(b.ijk);
    op.fields = NULL;
    op.n_fields = 0;
    op.constraints = CS_CONSTRAINT_PENALTY;
    op.penalty = -1;
    ENSURE(make_bar(&b, &op) != 0);
    cs_world_destroy(b.w);
    free(b.ijk);
#undef REFUSED
}

/* The scene's design fields and constraint mode reach the engine; bad ones are named. */
TEST(sculpt_scene_fields_and_constraints)
{
    const char *json =
        "{\"gravity\": [0, 0, 0], \"objects\": [{\"name\": \"b\", \"cube_size\": 0.1,"
        " \"material\": {\"young\": 1e5, \"poisson\": 0.0},"
        " \"box\": {\"min\": [0, 0, 0], \"size\": [0.4, 0.1, 0.1]},"
        " \"constraints\": \"penalty\", \"penalty_stiffness\": 1e7,"
        " \"fixed\": [{\"min\": [-0.01, -1, -1], \"max\": [0.01, 1, 1]}],"
        " \"fields\": [{\"shape\": \"box\", \"min\": [0, -1, -1], \"max\": [0.2, 1, 1],"
        "               \"young\": 2, \"density\": 3},"
        "              {\"shape\": \"sphere\", \"centre\": [0.35, 0.05, 0.05], \"radius\": 0.01,"
        "               \"damping\": 0},"
        "              {\"shape\": \"gradient\", \"from\": [0, 0, 0], \"to\": [0.4, 0, 0],"
        "               \"young\": 1},"
        "              {\"shape\": \"radial\", \"centre\": [9, 9, 9], \"radius\": 1,"
        "               \"young\": 5}]}]}";
    cs_scene s;
    char err[256];
    ENSURE_MSG(cs_scene_parse(json, NULL, &s, err, sizeof err) == 0, "%s", err);
    ENSURE(s.n_objects == 1 && s.objects[0].n_fields == 4);
    ENSURE(s.objects[0].constraints == CS_CONSTRAINT_PENALTY);
    ENSURE(s.objects[0].penalty_stiffness == 1e7);
    cs_world_t *w = NULL;
    ENSURE_MSG(cs_scene_instantiate(&s, &w, err, sizeof err) == 0, "%s", err);
    cs_object_id id = cs_world_find_object(w, "b");
    const double *yf, *df;
    int nc;
    cs_object_fields(w, id, &yf, &df, NULL, &nc);
    ENSURE(nc == 4);
    const int32_t *ijk;
    cs_object_cells(w, id, &ijk, NULL, NULL);
    for (int c = 0; c < nc; c++)
        for (int g = 0; g < 8; g++) {
            ENSURE_NEAR(yf[8 * c + g], ijk[3 * c] < 2 ? 2.0 : 1.0, 0);
            ENSURE_NEAR(df[8 * c + g], ijk[3 * c] < 2 ? 3.0 : 1.0, 0);
        }
    cs_object_info info;
    cs_object_get_info(w, id, &info);
    ENSURE_NEAR(info.mass, 1000 * (2 * 3 + 2) * 1e-3, 1e-9);
    ENSURE(info.n_fixed_nodes == 4);
    cs_world_destroy(w);
    cs_scene_free(&s);

    static const struct {
        const char *field, *word;
    } bad[] = {
        {"\"fields\": [{\"shape\": \"cone\", \"young\": 2}]", "unknown shape"},
        {"\"fields\": [{\"shape\": \"sphere\", \"centre\": [0,0,0], \"radius\": 0, \"young\": 2}]",
         "radius"},
        {"\"fields\": [{\"shape\": \"sphere\", \"centre\": [0,0,0], \"radius\": 1}]",
         "at least one factor"},
        {"\"fields\": [{\"shape\": \"box\", \"min\": [0,0,0], \"max\": [1,1,1], \"young\": -1}]",
         "young"},
        {"\"fields\": [{\"shape\": \"box\", \"centre\": [0,0,0], \"min\": [0,0,0], \"max\": [1,1,1],"
         " \"young\": 2}]", "does not apply"},
        {"\"constraints\": \"glue\"", "unknown mode"},
        {"\"penalty_stiffness\": 5", "only applies"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char text[1024];
        snprintf(text, sizeof text,
                 "{\"objects\": [{\"name\": \"b\", \"box\": {\"min\": [0,0,0], \"size\": [0.1,0.1,0.1]},"
                 " %s}]}", bad[i].field);
        err[0] = 0;
        ENSURE_MSG(cs_scene_parse(text, NULL, &s, err, sizeof err) != 0, "accepted %s",
                   bad[i].field);
        ENSURE_MSG(strstr(err, bad[i].word) && strstr(err, "objects[0]"),
                   "message '%s' lacks '%s'", err, bad[i].word);
    }
}

/* A bar hanging along +x (gravity +x, ν = 0, one cube thick) with a tip load and 2 cubes
 * painted 3× denser: N(x) = F + gA∫ₓᴸρ, u(L) = ∫₀ᴸ N/(EA). Lumped gravity on linear elements
 * is nodally exact here, so the painted masses and the kept tip load must give it exactly. */
TEST(sculpt_mass_paint_static_hanging_bar_matches_1d)
{
    bar_opts op = opts_default();
    const double F = 2.0, g = 9.81, h = op.h, A = h * h, E = op.mat.young;
    const double rho = op.mat.density;
    op.tip[0] = F;
    op.wd.gravity[0] = g;
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    char err[256];
    int touched = 0;
    ENSURE(cs_world_paint(b.w, b.id, (double[3]){0.4, 0.05, 0.05}, 0.1,
                          &(cs_field_factors){.density = 3, .which = CS_FIELD_DENSITY},
                          &touched, err, sizeof err) == CS_OK);
    ENSURE(touched == 16);
    ENSURE(cs_world_solve_static(b.w) == CS_OK);
    /* N at the node planes, from the tip inwards; u(L) = Σ_cells h (N_i + N_{i+1}) / 2 / EA */
    double N[9], u = 0;
    N[op.nx] = F;
    for (int i = op.nx - 1; i >= 0; i--)
        N[i] = N[i + 1] + g * A * h * rho * ((i == 3 || i == 4) ? 3.0 : 1.0);
    for (int i = 0; i < op.nx; i++)
        u += h * (N[i] + N[i + 1]) / 2 / (E * A);
    printf("    tip %.9g m, 1-D %.9g m\n", ux_at(&b, 0.8), u);
    ENSURE_NEAR(ux_at(&b, 0.8), u, 1e-6 * u);
    free_bar(&b);
}

/* Penalty supports go with their nodes into the pieces of a fracture. */
TEST(sculpt_penalty_supports_survive_fracture)
{
    bar_opts op = opts_default();
    op.nx = 6;
    op.ny = op.nz = 2;
    op.constraints = CS_CONSTRAINT_PENALTY;
    op.wd.gravity[2] = -9.81;
    bar b;
    ENSURE(make_bar(&b, &op) == 0);
    cs_object_info info;
    cs_object_get_info(b.w, b.id, &info);
    ENSURE(info.n_fixed_nodes == 9);
    char err[256];
    for (int j = 0; j < 2; j++)
        for (int k = 0; k < 2; k++)
            ENSURE_MSG(cs_world_cut_face(b.w, b.id, (int32_t[3]){3, j, k}, 0, err,
                                         sizeof err) == CS_OK, "%s", err);
    cs_object_id ids[4];
    ENSURE(cs_world_object_ids(b.w, ids, 4) == 2);
    cs_object_get_info(b.w, ids[0], &info);
    ENSURE_MSG(info.n_fixed_nodes == 9, "the held piece has %d held nodes", info.n_fixed_nodes);
    cs_object_get_info(b.w, ids[1], &info);
    ENSURE(info.n_fixed_nodes == 0);
    /* the held piece stays up (its supports hold), the free one falls */
    for (int s = 0; s < 30; s++)
        ENSURE(cs_world_step(b.w) == CS_OK);
    const double *rest, *pos;
    int n;
    cs_object_nodes(b.w, ids[0], &rest, &pos, NULL, &n);
    double held = 0;
    for (int i = 0; i < n; i++)
        if (rest[3 * i] < 1e-9)
            held = fmax(held, fabs(pos[3 * i + 2] - rest[3 * i + 2]));
    cs_object_nodes(b.w, ids[1], &rest, &pos, NULL, &n);
    const double fall = rest[2] - pos[2];
    printf("    held nodes moved %.3g m, the free piece fell %.3g m\n", held, fall);
    ENSURE(held < 1e-4);
    ENSURE(fall > 0.05);
    free_bar(&b);
}

/* A graded cube's product (point by point, B_gᵀ C B_g) is the matrix Σ_g f_g K_g built from
 * the per-Gauss-point matrices, column by column, and its diagonal blocks are that matrix's. */
TEST(sculpt_graded_element_equals_weighted_gauss_matrices)
{
    const double E = 3e4, nu = 0.3, h = 0.2;
    cs_cubemesh cm;
    memset(&cm, 0, sizeof cm);
    char err[128];
    ENSURE(cs_cubemesh_build(&cm, h, (double[3]){0, 0, 0}, (int32_t[3]){0, 0, 0}, 1, err,
                             sizeof err) == 0);
    cs_fem fem;
    ENSURE(cs_fem_init(&fem, &cm, E, nu, true, 1) == 0);
    const double f[8] = {1.0, 2.5, 0.3, 4.0, 1.7, 0.9, 3.3, 0.01};
    fem.kf = f;
    double want[576] = {0}, Kg[576];
    for (int g = 0; g < 8; g++) {
        cs_cube_stiffness_gauss(E, nu, h, g, Kg);
        for (int i = 0; i < 576; i++)
            want[i] += f[g] * Kg[i];
    }
    double scale = 0;
    for (int i = 0; i < 576; i++)
        scale = fmax(scale, fabs(want[i]));
    /* columns through the product (rotations are the identity) */
    double p[24], y[24], worst = 0;
    for (int j = 0; j < 24; j++) {
        memset(p, 0, sizeof p);
        p[j] = 1;
        cs_fem_apply_K(&fem, p, y);
        for (int i = 0; i < 24; i++) {
            const int node_i = i / 3, node_j = j / 3;
            /* the mesh numbers nodes its own way: map through the cell's corner list */
            int ci = -1, cj = -1;
            for (int k = 0; k < 8; k++) {
                if (cm.cell_nodes[k] == node_i)
                    ci = k;
                if (cm.cell_nodes[k] == node_j)
                    cj = k;
            }
            worst = fmax(worst, fabs(y[i] - want[(3 * ci + i % 3) * 24 + 3 * cj + j % 3]));
        }
    }
    ENSURE_MSG(worst <= 1e-12 * scale, "product differs from sum f_g K_g by %g (scale %g)",
               worst, scale);
    double blocks[72];
    cs_fem_diag_blocks(&fem, blocks);
    worst = 0;
    for (int n = 0; n < 8; n++) {
        int c = -1;
        for (int k = 0; k < 8; k++)
            if (cm.cell_nodes[k] == n)
                c = k;
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                worst = fmax(worst, fabs(blocks[9 * n + 3 * a + b] -
                                         want[(3 * c + a) * 24 + 3 * c + b]));
    }
    ENSURE_MSG(worst <= 1e-12 * scale, "diagonal blocks differ by %g", worst);
    cs_fem_free(&fem);
    cs_cubemesh_free(&cm);
}
