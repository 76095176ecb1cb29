/*
 * test_mss.c — the mass-spring element of seed 004 (mss.c) and the explicit integrators
 * (world.c) against known answers: the paper's spring constants; no force in rigid motions
 * (element and object); one cube's stiffness equals the continuum's for every homogeneous
 * strain (what the constants and correction forces were derived for); refinement towards a
 * FEM reference; a ν = 0 cantilever against Euler–Bernoulli; energy of symplectic Euler,
 * Verlet and implicit Euler on undamped oscillations; the explicit stability limit; bad
 * parameters; fracture; scene files.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "elastic.h"
#include "mss.h"
#include "scene.h"
#include "world_internal.h"

/* ---------------------------------------------------------------- helpers */

typedef struct box {
    cs_world_t *w;
    cs_object_id id;
    int32_t *ijk;
} box;

/* nx×ny×nz cubes of edge h from the origin; fixed at x = 0 if asked. */
static int make_box(box *b, cs_world_def wd, cs_model model, cs_integrator integ,
                    cs_material mat, int nx, int ny, int nz, double h, bool fixed, char *err,
                    size_t errlen)
{
    memset(b, 0, sizeof *b);
    if (cs_world_create(&wd, &b->w, err, errlen) != CS_OK)
        return -1;
    const int n = nx * ny * nz;
    b->ijk = malloc(sizeof(int32_t) * 3 * (size_t)n);
    int c = 0;
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++) {
                b->ijk[3 * c] = i;
                b->ijk[3 * c + 1] = j;
                b->ijk[3 * c + 2] = k;
                c++;
            }
    cs_object_def d = cs_object_def_default();
    d.name = "box";
    d.model = model;
    d.integrator = integ;
    d.material = mat;
    d.cube_size = h;
    d.cells_ijk = b->ijk;
    d.n_cells = n;
    cs_aabb fix = {{-1e-3 * h, -1e3, -1e3}, {1e-3 * h, 1e3, 1e3}};
    if (fixed) {
        d.fixed = &fix;
        d.n_fixed = 1;
    }
    return cs_world_add_object(b->w, &d, &b->id, err, errlen) == CS_OK ? 0 : -1;
}

static void free_box(box *b)
{
    cs_world_destroy(b->w);
    free(b->ijk);
}

static cs_world_def quiet_world(double gz)
{
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = gz;
    wd.cg_tolerance = 1e-10;
    wd.cg_max_iterations = 20000;
    wd.sleep_steps = 0;
    return wd;
}

/* Rest positions of one cube's corners (cubemesh.h order). */
static void cube_corners(double h, double pos[24])
{
    for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++)
            pos[3 * a + k] = h * CS_CORNER[a][k];
}

static void matvec24(const double *K, const double *u, double *y)
{
    for (int i = 0; i < 24; i++) {
        double s = 0;
        for (int j = 0; j < 24; j++)
            s += K[24 * i + j] * u[j];
        y[i] = s;
    }
}

/* ---------------------------------------------------------------- element */

TEST(mss_spring_constants_match_seed_formulas)
{
    const double E = 1000, nu = 0.3, h = 0.1;
    ENSURE_NEAR(cs_mss_edge_constant(E, nu, h), E * h * (4 * nu + 1) / (8 * (1 + nu)), 1e-12);
    ENSURE_NEAR(cs_mss_edge_constant(E, nu, h), 100.0 * 2.2 / 10.4, 1e-12);
    ENSURE_NEAR(cs_mss_diagonal_constant(E, nu, h), 300.0 / 10.4, 1e-12);
    /* At ν = 1/4 the correction vanishes (F⊥ ∝ 4ν − 1): the stiffness matrix is the bare
     * springs'. Corner 0 is joined to corner 1 by one x edge only, corner 7 to corner 1 by
     * the diagonal (−1, 1, 1)/√3. */
    double K[576];
    const double k = cs_mss_edge_constant(E, 0.25, h), kd = cs_mss_diagonal_constant(E, 0.25, h);
    cs_mss_cube_stiffness(E, 0.25, h, K);
    ENSURE_NEAR(K[24 * 0 + 3], -k, 1e-12 * k);
    ENSURE_NEAR(K[24 * 21 + 3], -kd / 3, 1e-12 * k);
    ENSURE_NEAR(K[24 * 22 + 3], kd / 3, 1e-12 * k);
    /* x-x entry of corner 0: its x edge, plus its diagonal's n_x² = 1/3 (edges across x add
     * nothing at rest) */
    ENSURE_NEAR(K[0], k + kd / 3, 1e-12 * k);
}

/* The paper fixes k, k_d and F⊥ so that a cube stretched along an axis shows E and ν and a
 * sheared cube G. Read as in mss.h, this makes one cube's nodal forces equal to the continuum's
 * (= the FEM cube's) for the three homogeneous normal strains, and its energy equal for the
 * shears too (the diagonals also push a sheared cube's corners along the third axis, in the
 * pattern s_x s_y s_z that a homogeneous strain does not excite: no energy, no equal forces). */
TEST(mss_cube_stiffness_equals_continuum_for_homogeneous_strain)
{
    const double E = 1000, h = 0.1;
    const double nus[3] = {0.0, 0.3, 0.45};
    for (int t = 0; t < 3; t++) {
        double Km[576], Kf[576];
        cs_mss_cube_stiffness(E, nus[t], h, Km);
        cs_cube_stiffness(E, nus[t], h, Kf);
        for (int mode = 0; mode < 6; mode++) {
            double eps[9] = {0};
            const int I[6] = {0, 1, 2, 0, 0, 1}, J[6] = {0, 1, 2, 1, 2, 2};
            eps[3 * I[mode] + J[mode]] = eps[3 * J[mode] + I[mode]] = 1e-3;
            double pos[24], u[24], ym[24], yf[24];
            cube_corners(h, pos);
            for (int a = 0; a < 8; a++)
                for (int i = 0; i < 3; i++)
                    u[3 * a + i] = eps[3 * i] * pos[3 * a] + eps[3 * i + 1] * pos[3 * a + 1] +
                                   eps[3 * i + 2] * pos[3 * a + 2];
            matvec24(Km, u, ym);
            matvec24(Kf, u, yf);
            double scale = 0, diff = 0, em = 0, ef = 0;
            for (int i = 0; i < 24; i++) {
                scale = fmax(scale, fabs(yf[i]));
                diff = fmax(diff, fabs(ym[i] - yf[i]));
                em += 0.5 * u[i] * ym[i];
                ef += 0.5 * u[i] * yf[i];
            }
            ENSURE_MSG(ef > 0 && fabs(em - ef) < 1e-12 * ef, "nu %g mode %d: energy %g vs FEM %g",
                       nus[t], mode, em, ef);
            if (mode < 3)
                ENSURE_MSG(scale > 0 && diff < 1e-10 * scale,
                           "nu %g normal strain %d: |K_mss u - K_fem u| %g of %g", nus[t], mode,
                           diff, scale);
        }
    }
}

/* Uniaxial stress on one free cube, solved on the element matrix: E and ν come out. */
TEST(mss_cube_shows_young_and_poisson_under_uniaxial_stress)
{
    const double E = 1000, nu = 0.3, h = 0.1, F = 1e-3;
    box b;
    char err[256];
    cs_material mat = cs_material_default();
    mat.young = E;
    mat.poisson = nu;
    cs_world_def wd = quiet_world(0);
    ENSURE_MSG(make_box(&b, wd, CS_MODEL_MSS, CS_INTEGRATOR_DEFAULT, mat, 1, 1, 1, h, false, err,
                        sizeof err) == 0, "%s", err);
    /* Hold the face x = 0 only along x (and one corner fully, one more along y and z, so
     * nothing rigid is left), pull the face x = h with F. */
    cs_object *o = cs_world_find_internal(b.w, b.id);
    for (int i = 0; i < o->n; i++) {
        const double *X = o->cm.node_rest + 3 * i;
        if (X[0] < 1e-9) {
            o->mask[3 * i] = 1;
            if (X[1] < 1e-9 && X[2] < 1e-9)
                o->mask[3 * i + 1] = o->mask[3 * i + 2] = 1;
            if (X[1] < 1e-9 && X[2] > 1e-9)
                o->mask[3 * i + 1] = 1;
            if (X[1] > 1e-9 && X[2] < 1e-9)
                o->mask[3 * i + 2] = 1;
        } else {
            o->f_const[3 * i] = F / 4;
        }
    }
    o->n_fixed_nodes = 1;
    ENSURE(cs_world_solve_static(b.w) == CS_OK);
    double ux = 0, uy = 0;
    for (int i = 0; i < o->n; i++) {
        const double *X = o->cm.node_rest + 3 * i, *x = o->x + 3 * i;
        if (X[0] > 1e-9)
            ux += (x[0] - X[0]) / 4;
        if (X[1] > 1e-9)
            uy += (x[1] - X[1]) / 4;
    }
    const double stress = F / (h * h), strain = ux / h;
    ENSURE_NEAR(stress / strain, E, 1e-4 * E);
    ENSURE_NEAR(-uy / ux, nu, 1e-4);
    free_box(&b);
}

/* Rigid placements give no force: element level (one cube, any rotation) and object level
 * (a 3×2×2 block through the model interface, and a block in free fall). */
TEST(mss_rigid_motions_produce_no_force)
{
    const double E = 1000, h = 0.1;
    box b;
    char err[256];
    cs_material mat = cs_material_default();
    mat.young = E;
    ENSURE_MSG(make_box(&b, quiet_world(0), CS_MODEL_MSS, CS_INTEGRATOR_DEFAULT, mat, 3, 2, 2, h,
                        false, err, sizeof err) == 0, "%s", err);
    cs_object *o = cs_world_find_internal(b.w, b.id);
    const double k = cs_mss_edge_constant(E, 0.3, h);
    /* rotation by 2.1 rad about (1, 2, 3)/√14, then a translation */
    double ax[3] = {1 / sqrt(14.0), 2 / sqrt(14.0), 3 / sqrt(14.0)}, th = 2.1;
    const double c = cos(th), s = sin(th), C = 1 - c;
    const double Q[9] = {c + ax[0] * ax[0] * C, ax[0] * ax[1] * C - ax[2] * s, ax[0] * ax[2] * C + ax[1] * s,
                         ax[1] * ax[0] * C + ax[2] * s, c + ax[1] * ax[1] * C, ax[1] * ax[2] * C - ax[0] * s,
                         ax[2] * ax[0] * C - ax[1] * s, ax[2] * ax[1] * C + ax[0] * s, c + ax[2] * ax[2] * C};
    double *x = malloc(sizeof(double) * 3 * o->n), *f = malloc(sizeof(double) * 3 * o->n);
    for (int i = 0; i < o->n; i++) {
        const double *X = o->cm.node_rest + 3 * i;
        for (int a = 0; a < 3; a++)
            x[3 * i + a] = Q[3 * a] * X[0] + Q[3 * a + 1] * X[1] + Q[3 * a + 2] * X[2] + 5.0 - a;
    }
    double energy = -1;
    cs_elastic_force(o, x, f, &energy);
    double fbig = 0;
    for (int d = 0; d < 3 * o->n; d++)
        fbig = fmax(fbig, fabs(f[d]));
    const bool ok = fbig < 1e-12 * k * h && fabs(energy) < 1e-20 * k * h * h;
    /* K at the rest state annihilates the six infinitesimal rigid motions */
    cs_elastic_update(o, o->cm.node_rest);
    double kmax = 0;
    for (int r = 0; r < 6; r++) {
        for (int i = 0; i < o->n; i++) {
            const double *X = o->cm.node_rest + 3 * i;
            double v[3] = {0, 0, 0};
            if (r < 3)
                v[r] = 1;
            else { /* e_{r-3} × X */
                const int a0 = r - 3, a1 = (a0 + 1) % 3, a2 = (a0 + 2) % 3;
                v[a2] = X[a1];
                v[a1] = -X[a2];
            }
            memcpy(x + 3 * i, v, sizeof v);
        }
        cs_elastic_apply_K(o, x, f);
        for (int d = 0; d < 3 * o->n; d++)
            kmax = fmax(kmax, fabs(f[d]));
    }
    free(x);
    free(f);
    ENSURE_MSG(ok, "rigid placement: max force %g N, energy %g J", fbig, energy);
    ENSURE_MSG(kmax < 1e-12 * k, "K times a rigid motion: %g", kmax);
    free_box(&b);

    /* Free fall under gravity, Verlet and implicit Euler: no deformation appears. */
    for (int t = 0; t < 2; t++) {
        cs_world_def wd = quiet_world(-9.81);
        wd.dt = 1e-3;
        ENSURE_MSG(make_box(&b, wd, CS_MODEL_MSS, t ? CS_INTEGRATOR_IMPLICIT_EULER : CS_INTEGRATOR_VERLET,
                            mat, 3, 2, 2, h, false, err, sizeof err) == 0, "%s", err);
        for (int i = 0; i < 100; i++)
            ENSURE(cs_world_step(b.w) == CS_OK);
        cs_energy e;
        ENSURE(cs_object_energy(b.w, b.id, &e) == CS_OK);
        const double *rest, *pos;
        int n;
        cs_object_nodes(b.w, b.id, &rest, &pos, NULL, &n);
        const double drop = pos[2] - rest[2];
        double dev = 0;
        for (int i = 0; i < n; i++)
            for (int a = 0; a < 3; a++)
                dev = fmax(dev, fabs(pos[3 * i + a] - rest[3 * i + a] - (a == 2 ? drop : 0.0)));
        ENSURE_MSG(drop < -0.04 && dev < 1e-9 && e.elastic < 1e-15,
                   "free fall %d: drop %g, shape deviation %g, elastic energy %g", t, drop, dev,
                   e.elastic);
        free_box(&b);
    }
}

/* The force is minus the gradient of the energy for small strains, and K its Jacobian:
 * finite differences on a randomly perturbed 2×2×1 block. */
TEST(mss_force_and_stiffness_are_consistent)
{
    box b;
    char err[256];
    cs_material mat = cs_material_default();
    const double h = 0.1;
    ENSURE_MSG(make_box(&b, quiet_world(0), CS_MODEL_MSS, CS_INTEGRATOR_DEFAULT, mat, 2, 2, 1, h,
                        false, err, sizeof err) == 0, "%s", err);
    cs_object *o = cs_world_find_internal(b.w, b.id);
    const int n3 = 3 * o->n;
    double *x = malloc(sizeof(double) * n3), *f0 = malloc(sizeof(double) * n3),
           *f1 = malloc(sizeof(double) * n3), *p = malloc(sizeof(double) * n3),
           *kp = malloc(sizeof(double) * n3);
    uint64_t r = 88172645463325252ULL;
    for (int d = 0; d < n3; d++) {
        r ^= r << 13, r ^= r >> 7, r ^= r << 17;
        x[d] = o->cm.node_rest[d] + 1e-4 * h * ((double)(r % 2001) / 1000.0 - 1.0);
        r ^= r << 13, r ^= r >> 7, r ^= r << 17;
        p[d] = (double)(r % 2001) / 1000.0 - 1.0;
    }
    /* K p against (f(x − εp) − f(x + εp))/2ε */
    const double eps = 1e-7 * h;
    cs_elastic_update(o, x);
    cs_elastic_apply_K(o, p, kp);
    for (int d = 0; d < n3; d++)
        x[d] += eps * p[d];
    cs_elastic_force(o, x, f1, NULL);
    for (int d = 0; d < n3; d++)
        x[d] -= 2 * eps * p[d];
    cs_elastic_force(o, x, f0, NULL);
    double diff = 0, scale = 0;
    for (int d = 0; d < n3; d++) {
        const double fd = (f0[d] - f1[d]) / (2 * eps);
        diff = fmax(diff, fabs(fd - kp[d]));
        scale = fmax(scale, fabs(kp[d]));
    }
    /* energy: dE along p against −f·p */
    for (int d = 0; d < n3; d++)
        x[d] += eps * p[d];
    cs_elastic_force(o, x, f0, NULL);
    double fp = 0;
    for (int d = 0; d < n3; d++) {
        fp += f0[d] * p[d];
        x[d] += eps * p[d];
    }
    const double e1 = cs_elastic_energy(o, x);
    for (int d = 0; d < n3; d++)
        x[d] -= 2 * eps * p[d];
    const double e0 = cs_elastic_energy(o, x);
    const double de = (e1 - e0) / (2 * eps);
    free(x);
    free(f0);
    free(f1);
    free(p);
    free(kp);
    free_box(&b);
    ENSURE_MSG(diff < 1e-3 * scale, "K p vs finite differences: %g of %g", diff, scale);
    ENSURE_MSG(fabs(de + fp) < 1e-3 * fabs(fp) + 1e-12, "dE/ds %g vs -f.p %g", de, -fp);
}
