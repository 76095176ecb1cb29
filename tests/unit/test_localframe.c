/*
 * test_localframe.c — the local-frame B-spline model (seed 001 §3.2–3.4) and the
 * central-difference integrator (Eq. 20) against known answers: B-spline partition of unity
 * and identity reproduction, element null spaces, rigid motions of any size giving no force,
 * forces as the energy's gradient, cell classification and its survival of fracture, exact
 * tricubic skinning, a ν = 0 cantilever against Euler–Bernoulli/Timoshenko and its error
 * under refinement, energy of an undamped oscillation, and refusals.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "check.h"
#include "cubemesh.h"
#include "cubesim.h"
#include "elastic.h"
#include "localframe.h"
#include "surface.h"
#include "world_internal.h"
#include "lattice.h"

static int box_mesh(cs_cubemesh *cm, int nx, int ny, int nz, double h)
{
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    char err[128];
    const double origin[3] = {0.1, -0.2, 0.3};
    int rc = cs_cubemesh_build(cm, h, origin, ijk, nx * ny * nz, err, sizeof err);
    free(ijk);
    return rc;
}

/* Rotation matrix of angle th about unit axis u (Rodrigues). */
static void rotation(const double u0[3], double th, double Q[9])
{
    double n = sqrt(u0[0] * u0[0] + u0[1] * u0[1] + u0[2] * u0[2]);
    double u[3] = {u0[0] / n, u0[1] / n, u0[2] / n}, c = cos(th), s = sin(th);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            Q[3 * i + j] = (i == j ? c : 0) + (1 - c) * u[i] * u[j];
    Q[1] -= s * u[2];
    Q[2] += s * u[1];
    Q[3] += s * u[2];
    Q[5] -= s * u[0];
    Q[6] -= s * u[1];
    Q[7] += s * u[0];
}

/* ---------------------------------------------------------------- basis and elements */

TEST(lf_bspline_partition_of_unity_and_identity)
{
    for (int s = 0; s <= 20; s++) {
        const double t = s / 20.0;
        double b[4], db[4];
        cs_bspline_basis(t, b, db);
        double sum = 0, dsum = 0, lin = 0, dlin = 0;
        for (int k = 0; k < 4; k++) {
            ENSURE(b[k] >= 0);
            sum += b[k];
            dsum += db[k];
            lin += b[k] * (k - 1);  /* control points at the integers i−1..i+2 */
            dlin += db[k] * (k - 1);
        }
        ENSURE_NEAR(sum, 1.0, 1e-15);
        ENSURE_NEAR(dsum, 0.0, 1e-15);
        ENSURE_NEAR(lin, t, 1e-15);
        ENSURE_NEAR(dlin, 1.0, 1e-15);
    }
    /* C² across the knot: the basis of span i at t = 1 equals that of span i+1 at t = 0
     * shifted by one control point. */
    double b1[4], b0[4], d1[4], d0[4];
    cs_bspline_basis(1.0, b1, d1);
    cs_bspline_basis(0.0, b0, d0);
    for (int k = 1; k < 4; k++) {
        ENSURE_NEAR(b1[k], b0[k - 1], 1e-15);
        ENSURE_NEAR(d1[k], d0[k - 1], 1e-15);
    }
}

/* The classification: in a 5×5×5 box the 3×3×3 interior cells are B-spline elements. */
TEST(lf_classify_box_interior_cells)
{
    cs_cubemesh cm;
    ENSURE(box_mesh(&cm, 5, 5, 5, 0.1) == 0);
    ENSURE(cs_lf_classify(&cm) == 27);
    for (int c = 0; c < cm.n_cells; c++) {
        const int32_t *q = cm.cell_ijk + 3 * c;
        const bool interior = q[0] > 0 && q[0] < 4 && q[1] > 0 && q[1] < 4 && q[2] > 0 && q[2] < 4;
        ENSURE((cm.spline_nodes[64 * c] >= 0) == interior);
        if (!interior)
            continue;
        /* the 64 control points sit on the lattice i−1..i+2: the tricubic map at rest is the
         * identity (B-splines reproduce linear functions) */
        for (int a = 0; a < 64; a++) {
            const double *X = cm.node_rest + 3 * cm.spline_nodes[64 * c + a];
            const int off[3] = {a % 4 - 1, (a / 4) % 4 - 1, a / 16 - 1};
            for (int i = 0; i < 3; i++)
                ENSURE_NEAR(X[i], cm.origin[i] + cm.h * (q[i] + off[i]), 1e-12);
        }
        const double uvw[3] = {0.137, 0.5, 0.911};
        double bx[4], by[4], bz[4], p[3] = {0, 0, 0};
        cs_bspline_basis(uvw[0], bx, NULL);
        cs_bspline_basis(uvw[1], by, NULL);
        cs_bspline_basis(uvw[2], bz, NULL);
        for (int a = 0; a < 64; a++)
            for (int i = 0; i < 3; i++)
                p[i] += bx[a % 4] * by[(a / 4) % 4] * bz[a / 16] *
                        cm.node_rest[3 * cm.spline_nodes[64 * c + a] + i];
        for (int i = 0; i < 3; i++)
            ENSURE_NEAR(p[i], cm.origin[i] + cm.h * (q[i] + uvw[i]), 1e-12);
    }
    cs_cubemesh_free(&cm);
}

/* Element matrices: symmetric, total mass ρh³, and rigid motions in the null space. */
TEST(lf_element_matrices_symmetric_mass_and_null_space)
{
    cs_cubemesh cm;
    ENSURE(box_mesh(&cm, 3, 3, 3, 0.05) == 0);
    cs_lf lf;
    const double E = 1e5, nu = 0.3, rho = 800, h = 0.05;
    ENSURE(cs_lf_init(&lf, &cm, E, nu, rho, 1) == 0);
    ENSURE(lf.n_spline == 1);
    double kmax = 0, msum = 0, mlsum = 0;
    for (int i = 0; i < 192 * 192; i++)
        kmax = fmax(kmax, fabs(lf.Ks[i]));
    for (int i = 0; i < 192; i++)
        for (int j = 0; j < 192; j++)
            ENSURE_NEAR(lf.Ks[i * 192 + j], lf.Ks[j * 192 + i], 1e-12 * kmax);
    for (int i = 0; i < 64 * 64; i++)
        msum += lf.Ms[i];
    for (int i = 0; i < 64; i++)
        mlsum += lf.Ml[i];
    ENSURE_NEAR(msum, rho * h * h * h, 1e-12 * rho * h * h * h);
    /* the tensor-product form the mass product uses */
    for (int a = 0; a < 64; a++)
        for (int b = 0; b < 64; b++) {
            const double k = lf.m1scale * lf.m1[4 * (a % 4) + b % 4] *
                             lf.m1[4 * ((a / 4) % 4) + (b / 4) % 4] * lf.m1[4 * (a / 16) + b / 16];
            ENSURE_NEAR(lf.Ms[64 * a + b], k, 1e-12 * rho * h * h * h);
        }
    ENSURE_NEAR(mlsum, rho * h * h * h, 1e-12 * rho * h * h * h);
    /* translations and infinitesimal rotations about the cell centre */
    for (int mode = 0; mode < 6; mode++) {
        double u[192];
        for (int a = 0; a < 64; a++) {
            const double X[3] = {(a % 4 - 1.5) * h, ((a / 4) % 4 - 1.5) * h, (a / 16 - 1.5) * h};
            for (int i = 0; i < 3; i++)
                u[3 * a + i] = mode < 3 ? (i == mode) : 0.0;
            if (mode >= 3) {
                const int ax = mode - 3, i1 = (ax + 1) % 3, i2 = (ax + 2) % 3;
                u[3 * a + i1] = -X[i2];
                u[3 * a + i2] = X[i1];
            }
        }
        for (int i = 0; i < 192; i++) {
            double s = 0;
            for (int j = 0; j < 192; j++)
                s += lf.Ks[i * 192 + j] * u[j];
            ENSURE_NEAR(s, 0.0, 1e-10 * kmax * h);
        }
    }
    cs_lf_free(&lf);
    cs_cubemesh_free(&cm);
}

/* ---------------------------------------------------------------- local frames */

/* Rigid motions of any size (translation, rotations up to 179°) give no force and no energy,
 * in B-spline and linear elements alike: the local frames rotate with the body. */
TEST(lf_rigid_motions_give_no_force)
{
    cs_cubemesh cm;
    const double h = 0.1, E = 1e4;
    ENSURE(box_mesh(&cm, 5, 4, 4, h) == 0);
    cs_lf lf;
    ENSURE(cs_lf_init(&lf, &cm, E, 0.3, 1000, 1) == 0);
    ENSURE(lf.n_spline == 3 * 2 * 2);
    const int n = cm.n_nodes;
    double *x = malloc(sizeof(double) * 3 * n), *f = malloc(sizeof(double) * 3 * n);
    const double axes[4][3] = {{0, 0, 1}, {1, 0, 0}, {1, 2, -0.5}, {-0.3, 0.7, 0.2}};
    const double angles[5] = {0.0, 0.3, 1.5707963, 2.5, 3.12};
    /* force scale: what a 1 % strain would give at a node, E·h²·0.01 */
    const double fscale = E * h * h * 0.01;
    for (int ax = 0; ax < 4; ax++)
        for (int an = 0; an < 5; an++) {
            double Q[9];
            rotation(axes[ax], angles[an], Q);
            const double t[3] = {3.0, -1.0, 0.5};
            for (int i = 0; i < n; i++) {
                const double *X = cm.node_rest + 3 * i;
                for (int r = 0; r < 3; r++)
                    x[3 * i + r] = Q[3 * r] * X[0] + Q[3 * r + 1] * X[1] + Q[3 * r + 2] * X[2] + t[r];
            }
            cs_lf_reset(&lf);
            cs_lf_update(&lf, x);
            double e;
            cs_lf_force(&lf, x, f, &e);
            double fbig = 0;
            for (int d = 0; d < 3 * n; d++)
                fbig = fmax(fbig, fabs(f[d]));
            ENSURE_MSG(fbig < 1e-9 * fscale, "axis %d angle %g: |f| %g", ax, angles[an], fbig);
            ENSURE(e < 1e-20 * E * h * h * h);
            ENSURE(cs_lf_energy(&lf, x) < 1e-20 * E * h * h * h);
        }
    /* and a real deformation is resisted: a 1 % stretch along x gives forces of that scale */
    for (int i = 0; i < n; i++) {
        memcpy(x + 3 * i, cm.node_rest + 3 * i, 3 * sizeof(double));
        x[3 * i] *= 1.01;
    }
    cs_lf_update(&lf, x);
    cs_lf_force(&lf, x, f, NULL);
    double fbig = 0;
    for (int d = 0; d < 3 * n; d++)
        fbig = fmax(fbig, fabs(f[d]));
    ENSURE(fbig > 0.05 * fscale && fbig < 10 * fscale);
    free(x);
    free(f);
    cs_lf_free(&lf);
    cs_cubemesh_free(&cm);
}

/* The elastic force is the negative gradient of the energy: a central finite difference of
 * cs_lf_energy along a random direction matches −f·dir, at a rotated, deformed state. */
TEST(lf_force_is_energy_gradient)
{
    cs_cubemesh cm;
    const double h = 0.1;
    ENSURE(box_mesh(&cm, 4, 4, 4, h) == 0);
    cs_lf lf;
    ENSURE(cs_lf_init(&lf, &cm, 1e4, 0.25, 1000, 1) == 0);
    const int n = cm.n_nodes;
    double *x = malloc(sizeof(double) * 3 * n), *f = malloc(sizeof(double) * 3 * n),
           *dir = malloc(sizeof(double) * 3 * n), *xp = malloc(sizeof(double) * 3 * n);
    double Q[9];
    rotation((double[3]){0.2, 1, 0.4}, 0.9, Q);
    unsigned s = 12345;
    for (int i = 0; i < n; i++) {
        double X[3];
        for (int r = 0; r < 3; r++) {
            s = s * 1103515245u + 12345u;
            X[r] = cm.node_rest[3 * i + r] + 0.003 * ((s >> 8) % 1000 / 500.0 - 1.0);
            s = s * 1103515245u + 12345u;
            dir[3 * i + r] = (s >> 8) % 1000 / 500.0 - 1.0;
        }
        for (int r = 0; r < 3; r++)
            x[3 * i + r] = Q[3 * r] * X[0] + Q[3 * r + 1] * X[1] + Q[3 * r + 2] * X[2];
    }
    cs_lf_update(&lf, x);
    cs_lf_force(&lf, x, f, NULL);
    double fd = 0, an = 0;
    const double eps = 1e-6;
    for (int d = 0; d < 3 * n; d++)
        xp[d] = x[d] + eps * dir[d];
    double ep = cs_lf_energy(&lf, xp);
    for (int d = 0; d < 3 * n; d++)
        xp[d] = x[d] - eps * dir[d];
    double em = cs_lf_energy(&lf, xp);
    fd = (ep - em) / (2 * eps);
    for (int d = 0; d < 3 * n; d++)
        an -= f[d] * dir[d];
    /* the local-frame force omits the frame's own derivative (as corotational FEM does), an
     * error of the order of the strain (0.3 %) relative to the force */
    ENSURE_MSG(fabs(fd - an) < 0.02 * fabs(an), "dE %g vs -f.dir %g", fd, an);
    free(x);
    free(f);
    free(dir);
    free(xp);
    cs_lf_free(&lf);
    cs_cubemesh_free(&cm);
}

/* The stability bound is the exact largest element eigenvalue: for one free linear cell (the
 * whole object is one element) it matches a full eigen-decomposition. */
TEST(lf_stability_bound_matches_element_eigenvalue)
{
    const double E = 2e4, nu = 0.3, rho = 500, h = 0.07;
    double w2;
    ENSURE(cs_lf_omega2_bound(CS_MODEL_LINEAR, E, nu, rho, h, &w2) == 0);
    /* the same element through the FEM code: K of fem.c and the lumped mass ρh³/8 */
    double K[576];
    cs_cube_stiffness(E, nu, h, K);
    const double m = rho * h * h * h / 8;
    /* Jacobi eigenvalues of K/m */
    double A[576];
    for (int i = 0; i < 576; i++)
        A[i] = K[i] / m;
    const int nn = 24;
    for (int sweep = 0; sweep < 60; sweep++)
        for (int p = 0; p < nn; p++)
            for (int q = p + 1; q < nn; q++) {
                double apq = A[p * nn + q];
                if (fabs(apq) < 1e-300)
                    continue;
                double th = (A[q * nn + q] - A[p * nn + p]) / (2 * apq);
                double t = (th >= 0 ? 1 : -1) / (fabs(th) + sqrt(th * th + 1));
                double c = 1 / sqrt(t * t + 1), sn = t * c;
                for (int k = 0; k < nn; k++) {
                    double akp = A[k * nn + p], akq = A[k * nn + q];
                    A[k * nn + p] = c * akp - sn * akq;
                    A[k * nn + q] = sn * akp + c * akq;
                }
                for (int k = 0; k < nn; k++) {
                    double apk = A[p * nn + k], aqk = A[q * nn + k];
                    A[p * nn + k] = c * apk - sn * aqk;
                    A[q * nn + k] = sn * apk + c * aqk;
                }
            }
    double lmax = 0;
    for (int i = 0; i < nn; i++)
        lmax = fmax(lmax, A[i * nn + i]);
    ENSURE(w2 >= lmax);
    ENSURE_NEAR(w2, lmax, 2e-3 * lmax);
    /* localframe's consistent-mass bound is finite and of the expected E/(ρh²) scale */
    double w2lf;
    ENSURE(cs_lf_omega2_bound(CS_MODEL_LOCALFRAME, E, nu, rho, h, &w2lf) == 0);
    ENSURE(w2lf > 1.0 * E / (rho * h * h) && w2lf < 1e3 * E / (rho * h * h));
}

/* ---------------------------------------------------------------- through the world */

typedef struct lbeam {
    cs_world_t *w;
    cs_object_id id;
} lbeam;

/* A cantilever of nx×nz×nz cubes, fixed at x = 0, with a total tip force on x = nx·h. */
static int make_lbeam(lbeam *b, cs_world_def wd, cs_model model, cs_integrator integ,
                      cs_material mat, int nx, int nz, double h, const double *tip, char *err,
                      size_t errlen)
{
    memset(b, 0, sizeof *b);
    if (cs_world_create(&wd, &b->w, err, errlen) != CS_OK)
        return -1;
    int32_t *ijk = cs_box_cells(nx, nz, nz);
    cs_object_def d = cs_object_def_default();
    d.name = "beam";
    d.model = model;
    d.integrator = integ;
    d.material = mat;
    d.cube_size = h;
    d.cells_ijk = ijk;
    d.n_cells = nx * nz * nz;
    cs_aabb fix = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1e3, 1e3}};
    cs_load load = {{{nx * h - 1e-3 * h, -1, -1}, {nx * h + 1e-3 * h, 1e3, 1e3}}, {0, 0, 0}};
    d.fixed = &fix;
    d.n_fixed = 1;
    if (tip) {
        memcpy(load.force, tip, sizeof load.force);
        d.loads = &load;
        d.n_loads = 1;
    }
    int rc = cs_world_add_object(b->w, &d, &b->id, err, errlen);
    free(ijk);
    return rc;
}

static double tip_deflection(const lbeam *b, double L)
{
    const double *rest, *pos;
    int n, cnt = 0;
    double s = 0;
    cs_object_nodes(b->w, b->id, &rest, &pos, NULL, &n);
    for (int i = 0; i < n; i++)
        if (fabs(rest[3 * i] - L) < 1e-9) {
            s += pos[3 * i + 2] - rest[3 * i + 2];
            cnt++;
        }
    return -s / cnt;
}

static cs_world_def static_world(void)
{
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = 0;
    wd.cg_tolerance = 1e-10;
    wd.cg_max_iterations = 20000;
    wd.threads = 1;
    return wd;
}

/* Euler–Bernoulli: a tip load P gives δ = PL³/(3EI); Timoshenko adds PL/(κGA), κ = 5/6.
 * ν = 0 removes the Poisson effects, L/H = 10 makes the beam slender. */
TEST(lf_cantilever_tip_load_matches_euler_bernoulli)
{
    const double L = 1.0, H = 0.1, E = 1e6, P = 0.05;
    const int nz = 4, nx = 40;
    cs_material mat = cs_material_default();
    mat.young = E;
    mat.poisson = 0.0;
    lbeam b;
    char err[256];
    /* statics: the integrator does not matter (central differences would need dt < 3e-4 s) */
    ENSURE_MSG(make_lbeam(&b, static_world(), CS_MODEL_LOCALFRAME, CS_INTEGRATOR_IMPLICIT_EULER,
                          mat, nx, nz, H / nz, (double[3]){0, 0, -P}, err, sizeof err) == CS_OK,
               "%s", err);
    ENSURE(cs_world_solve_static(b.w) == CS_OK);
    const double d = tip_deflection(&b, L);
    const double I = H * H * H * H / 12.0, A = H * H, G = E / 2.0;
    const double eb = P * L * L * L / (3 * E * I), timo = eb + P * L / (5.0 / 6.0 * G * A);
    printf("    tip deflection %.6g m, Euler-Bernoulli %.6g (%+.2f%%), Timoshenko %.6g (%+.2f%%)\n",
           d, eb, 100 * (d - eb) / eb, timo, 100 * (d - timo) / timo);
    ENSURE_MSG(fabs(d - eb) < 0.03 * eb, "tip %g vs Euler-Bernoulli %g", d, eb);
    cs_world_destroy(b.w);
}

/* Pure bending, ν = 0: u = (−κxz', 0, κx²/2) (z' from the mid-plane) is the exact 3D solution
 * with the clamped end u(0) = 0 and the end traction σ_xx = −Eκz'. */
static int bending_beam(lbeam *b, cs_model model, double E, int nx, int nz, double H, double kappa,
                        char *err, size_t errlen)
{
    cs_world_def wd = static_world();
    memset(b, 0, sizeof *b);
    if (cs_world_create(&wd, &b->w, err, errlen) != CS_OK)
        return -1;
    const double h = H / nz;
    int32_t *ijk = cs_box_cells(nx, nz, nz);
    cs_material mat = cs_material_default();
    mat.young = E;
    mat.poisson = 0.0;
    cs_object_def d = cs_object_def_default();
    d.name = "beam";
    d.model = model;
    d.integrator = CS_INTEGRATOR_IMPLICIT_EULER;
    d.material = mat;
    d.cube_size = h;
    d.cells_ijk = ijk;
    d.n_cells = nx * nz * nz;
    cs_aabb fix = {{-1e-3 * h, -1, -1}, {1e-3 * h, 1e3, 1e3}};
    cs_load loads[64];
    for (int k = 0; k < nz; k++) {
        const double zc = (k + 0.5) * h - 0.5 * H;
        loads[k] = (cs_load){{{nx * h - 1e-3 * h, -1, k * h + 1e-3 * h},
                              {nx * h + 1e-3 * h, 1e3, (k + 1) * h - 1e-3 * h}},
                             {-E * kappa * zc * H * h, 0, 0}};
    }
    d.fixed = &fix;
    d.n_fixed = 1;
    d.loads = loads;
    d.n_loads = nz;
    int rc = cs_world_add_object(b->w, &d, &b->id, err, errlen);
    free(ijk);
    return rc;
}

/* Refinement: the tip deflection under pure bending against the exact 3D answer κL²/2. The
 * error falls as h² (observed order ≥ 1.8 from nz = 2 to 4): the B-spline cells reproduce the
 * quadratic field exactly, but the outer layer of linear hexahedra, which carries most of the
 * bending, is second-order accurate and sets the rate. */
TEST(lf_cantilever_refinement_error_falls_as_h_squared)
{
    const double L = 0.5, H = 0.1, E = 1e6, kappa = 0.008;
    const double exact = kappa * L * L / 2;
    const int nzs[3] = {2, 3, 4};
    double errs[3];
    for (int r = 0; r < 3; r++) {
        const int nz = nzs[r], nx = nz * 5;
        lbeam b;
        char err[256];
        ENSURE_MSG(bending_beam(&b, CS_MODEL_LOCALFRAME, E, nx, nz, H, kappa, err, sizeof err) ==
                       CS_OK, "%s", err);
        ENSURE(cs_world_solve_static(b.w) == CS_OK);
        const double d = -tip_deflection(&b, L);
        errs[r] = fabs(d - exact) / exact;
        printf("    nz %d (h = %.4g m): tip %.6g, exact %.6g, error %.2f%%\n", nz, H / nz, d, exact,
               100 * errs[r]);
        cs_world_destroy(b.w);
    }
    ENSURE(errs[1] < errs[0] && errs[2] < errs[1]);
    const double order = log(errs[0] / errs[2]) / log(2.0);
    printf("    observed order %.2f\n", order);
    ENSURE_MSG(order > 1.8, "order %g", order);
}

/* ---------------------------------------------------------------- central differences */

static cs_object *internal(const lbeam *b)
{
    return cs_world_find_internal(b->w, b->id);
}

/* ½ v̄ᵀ M v̄ + U(x) with the model's own mass (consistent for localframe). */
static double kinetic_m(cs_object *o, const double *v)
{
    const size_t n3 = 3 * (size_t)o->n;
    double *mv = calloc(n3, sizeof *mv), e = 0;
    cs_elastic_apply_M(o, v, mv, 1.0);
    for (size_t d = 0; d < n3; d++)
        e += 0.5 * v[d] * mv[d];
    free(mv);
    return e;
}

static void m_operator(void *ctx, const double *p, double *y)
{
    cs_object *o = ctx;
    memset(y, 0, 3 * (size_t)o->n * sizeof(double));
    cs_elastic_apply_M(o, p, y, 1.0);
}

/* The ω²max of the assembled object (rest frames) by power iteration on M⁻¹K, inner CG for
 * M; returns the largest Rayleigh quotient met, a lower bound of ω²max. */
static double assembled_omega2(cs_object *o, int iters)
{
    const int n3 = 3 * o->n;
    double *v = malloc(sizeof(double) * n3), *w = malloc(sizeof(double) * n3),
           *z = calloc(n3, sizeof(double)), *mv = malloc(sizeof(double) * n3);
    double *blk = calloc(9 * (size_t)o->n, sizeof(double));
    uint8_t *mask = calloc(n3, 1);
    const double *md = cs_elastic_mass_diag(o);
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            blk[9 * i + 4 * a] = 1.0 / md[i];
    cs_cg_work cg;
    cs_cg_work_init(&cg, n3);
    for (int d = 0; d < n3; d++)
        v[d] = sin(1.3 * d) + ((d / 3) % 2 ? 1 : -1);
    cs_elastic_reset(o);
    double lam = 0;
    for (int it = 0; it < iters; it++) {
        double nv = 0, num = 0, den = 0;
        for (int d = 0; d < n3; d++)
            nv += v[d] * v[d];
        nv = sqrt(nv);
        for (int d = 0; d < n3; d++)
            v[d] /= nv;
        cs_elastic_apply_K(o, v, w);
        m_operator(o, v, mv);
        for (int d = 0; d < n3; d++) {
            num += v[d] * w[d];
            den += v[d] * mv[d];
        }
        lam = fmax(lam, num / den);
        cs_pcg(&cg, m_operator, o, blk, mask, w, z, 1e-9, 2000, 1);
        memcpy(v, z, sizeof(double) * n3);
    }
    cs_cg_work_free(&cg);
    free(v);
    free(w);
    free(z);
    free(mv);
    free(blk);
    free(mask);
    return lam;
}

/* The stability limit against the assembled objects' largest frequency: never below it,
 * and not far above (a limit much too strict would refuse usable time steps). */
TEST(lf_stability_estimate_bounds_assembled_objects)
{
    const int shapes[2][3] = {{5, 5, 5}, {10, 3, 3}};
    const double nus[2] = {0.3, 0.45};
    for (int s = 0; s < 2; s++) {
        const int k = s;
            cs_world_def wd = static_world();
            wd.dt = 1e-4;
            cs_world_t *w;
            ENSURE(cs_world_create(&wd, &w, NULL, 0) == CS_OK);
            int32_t *ijk = cs_box_cells(shapes[s][0], shapes[s][1], shapes[s][2]);
            cs_object_def d = cs_object_def_default();
            d.name = "box";
            d.model = CS_MODEL_LOCALFRAME;
            d.material.young = 1.0;
            d.material.density = 1.0;
            d.material.poisson = nus[k];
            d.cube_size = 1.0;
            d.cells_ijk = ijk;
            d.n_cells = shapes[s][0] * shapes[s][1] * shapes[s][2];
            cs_object_id id;
            char err[256];
            ENSURE_MSG(cs_world_add_object(w, &d, &id, err, sizeof err) == CS_OK, "%s", err);
            double bound;
            ENSURE(cs_lf_omega2_bound(CS_MODEL_LOCALFRAME, 1, nus[k], 1, 1, &bound) == 0);
            const double got = assembled_omega2(cs_world_find_internal(w, id), 40);
            printf("    %dx%dx%d nu %.2f: assembled omega^2 >= %.4g, estimate %.4g (ratio %.2f)\n",
                   shapes[s][0], shapes[s][1], shapes[s][2], nus[k], got, bound, bound / got);
            ENSURE(got <= bound);
            ENSURE(bound < 1.6 * got);
            free(ijk);
            cs_world_destroy(w);
    }
}

/* A free-vibrating cantilever, undamped: central differences keep the energy
 * ½ v̄ᵀMv̄ + U (v̄ the mean of the half-step velocities around x) bounded with no drift; and
 * cs_object_energy measures kinetic energy with that consistent M. */
TEST(lf_central_difference_energy_bounded_no_drift)
{
    cs_material mat = cs_material_default();
    mat.young = 1e4;
    mat.poisson = 0.3;
    mat.density = 1000;
    double w2;
    ENSURE(cs_lf_omega2_bound(CS_MODEL_LOCALFRAME, mat.young, mat.poisson, mat.density, 0.1,
                              &w2) == 0);
    cs_world_def wd = static_world();
    /* the modified energy of central differences oscillates by O((ω·dt)²) in each mode: at
     * half the limit the pluck's high modes keep the spread within a few per cent */
    wd.dt = 0.5 * 2 / sqrt(w2);
    wd.cg_tolerance = 1e-10;
    wd.sleep_steps = 0;
    lbeam b;
    char err[256];
    ENSURE_MSG(make_lbeam(&b, wd, CS_MODEL_LOCALFRAME, CS_INTEGRATOR_CENTRAL_DIFFERENCE, mat, 6, 3, 0.1,
                          NULL, err, sizeof err) == CS_OK, "%s", err);
    cs_object_info info;
    cs_object_get_info(b.w, b.id, &info);
    ENSURE(info.integrator == CS_INTEGRATOR_CENTRAL_DIFFERENCE);
    cs_object *o = internal(&b);
    ENSURE(o->lf && o->lf->n_spline == 4);
    /* pluck the tip for 0.1 s */
    ENSURE(cs_world_apply_force(b.w, b.id, (double[3]){0.6, 0.15, 0.3}, (double[3]){0, 0, -2.0},
                                0.1, err, sizeof err) == CS_OK);
    const int n3 = 3 * o->n;
    double *vprev = malloc(sizeof(double) * n3), *vbar = malloc(sizeof(double) * n3);
    const int steps = (int)(3.0 / wd.dt); /* 3 s of simulated time */
    double emin = INFINITY, emax = 0, first = 0, last = 0;
    int nfirst = 0, nlast = 0, iters = 0, counted = 0;
    for (int s = 0; s < steps; s++) {
        memcpy(vprev, o->v, sizeof(double) * n3);
        const double u = cs_elastic_energy(o, o->x);
        ENSURE(cs_world_step(b.w) == CS_OK);
        iters += cs_world_last_stats(b.w)->cg_iterations;
        counted++;
        if (o->n_inputs > 0 || s < (int)(0.1 / wd.dt) + 2)
            continue;
        for (int d = 0; d < n3; d++)
            vbar[d] = 0.5 * (vprev[d] + o->v[d]);
        const double e = kinetic_m(o, vbar) + u;
        emin = fmin(emin, e);
        emax = fmax(emax, e);
        if (s < steps / 3) {
            first += e;
            nfirst++;
        } else if (s > 2 * steps / 3) {
            last += e;
            nlast++;
        }
    }
    first /= nfirst;
    last /= nlast;
    printf("    dt %.4g s, %d steps, energy %.6g..%.6g J (spread %.3f%%), drift %.4f%%, %.1f CG "
           "iterations per step\n",
           wd.dt, steps, emin, emax, 100 * (emax - emin) / emax, 100 * (last - first) / first,
           (double)iters / counted);
    ENSURE(emax > 0);
    /* cs_object_energy reports the kinetic energy with the mass the object moves with, the
     * consistent one here (it used the lumped one, which is not what this scheme conserves) */
    cs_energy ce;
    ENSURE(cs_object_energy(b.w, b.id, &ce) == CS_OK);
    const double km = kinetic_m(o, o->v);
    ENSURE_MSG(km > 0 && fabs(ce.kinetic - km) <= 1e-12 * km, "kinetic %g, consistent %g",
               ce.kinetic, km);
    ENSURE_MSG((emax - emin) < 0.03 * emax, "spread %g", (emax - emin) / emax);
    ENSURE_MSG(fabs(last - first) < 0.002 * first, "drift %g", (last - first) / first);
    free(vprev);
    free(vbar);
    cs_world_destroy(b.w);
}

/* Just below the limit the scheme stays bounded for every model; just above it the object is
 * refused with a one-line message naming the limit. */
TEST(lf_central_difference_limit_enforced)
{
    const cs_model models[3] = {CS_MODEL_LOCALFRAME, CS_MODEL_COROTATIONAL, CS_MODEL_LINEAR};
    for (int m = 0; m < 3; m++) {
        cs_material mat = cs_material_default();
        mat.young = 1e4;
        double w2;
        ENSURE(cs_lf_omega2_bound(models[m], mat.young, mat.poisson, mat.density, 0.1, &w2) == 0);
        const double limit = 2 / sqrt(w2);
        cs_world_def wd = static_world();
        wd.cg_tolerance = 1e-8;
        wd.sleep_steps = 0;
        wd.dt = 1.05 * limit;
        lbeam b;
        char err[256] = "";
        ENSURE(make_lbeam(&b, wd, models[m], CS_INTEGRATOR_CENTRAL_DIFFERENCE, mat, 4, 3, 0.1, NULL,
                          err, sizeof err) == CS_ERR_INVALID);
        ENSURE_MSG(strstr(err, "stability limit") && !strchr(err, '\n'), "%s", err);
        cs_world_destroy(b.w);
        /* the implicit integrator takes the same dt */
        ENSURE(make_lbeam(&b, wd, models[m], CS_INTEGRATOR_IMPLICIT_EULER, mat, 4, 3, 0.1, NULL, err,
                          sizeof err) == CS_OK);
        cs_world_destroy(b.w);
        wd.dt = 0.95 * limit;
        ENSURE_MSG(make_lbeam(&b, wd, models[m], CS_INTEGRATOR_CENTRAL_DIFFERENCE, mat, 4, 3, 0.1,
                              NULL, err, sizeof err) == CS_OK, "%s", err);
        /* a one-step kick at a corner excites the highest modes */
        ENSURE(cs_world_apply_force(b.w, b.id, (double[3]){0.4, 0.3, 0.3}, (double[3]){3, -2, 5}, 0,
                                    err, sizeof err) == CS_OK);
        ENSURE(cs_world_step(b.w) == CS_OK);
        cs_energy e0;
        cs_object_energy(b.w, b.id, &e0);
        double emax = 0;
        for (int s = 0; s < 600; s++) {
            ENSURE(cs_world_step(b.w) == CS_OK);
            cs_energy e;
            cs_object_energy(b.w, b.id, &e);
            emax = fmax(emax, e.kinetic + e.elastic);
        }
        ENSURE_MSG(emax < 3 * (e0.kinetic + e0.elastic), "%s: energy grew from %g to %g",
                   cs_model_name(models[m]), e0.kinetic + e0.elastic, emax);
        cs_world_destroy(b.w);
    }
}

TEST(lf_bad_parameters_refused)
{
    cs_material mat = cs_material_default();
    const double bad[3][2] = {{1000, 0.5}, {0, 0.3}, {-5, 0.3}};
    for (int k = 0; k < 3; k++) {
        mat.young = bad[k][0];
        mat.poisson = bad[k][1];
        lbeam b;
        char err[256] = "";
        ENSURE(make_lbeam(&b, static_world(), CS_MODEL_LOCALFRAME, CS_INTEGRATOR_DEFAULT, mat, 3, 3,
                          0.1, NULL, err, sizeof err) == CS_ERR_INVALID);
        ENSURE_MSG(strstr(err, k == 0 ? "poisson" : "young"), "%s", err);
        cs_world_destroy(b.w);
    }
}

/* Fracture: the localframe data follow node duplication (cells next to a cut become linear)
 * and the pieces step on; pieces at rest feel no force. */
TEST(lf_fracture_then_step)
{
    cs_world_def wd = static_world();
    wd.dt = 1.0 / 60;
    wd.cg_tolerance = 1e-8;
    cs_material mat = cs_material_default(); /* E = 1000 Pa: 1/60 s is below the limit */
    cs_world_t *w;
    ENSURE(cs_world_create(&wd, &w, NULL, 0) == CS_OK);
    int32_t *ijk = cs_box_cells(8, 4, 4);
    cs_object_def d = cs_object_def_default();
    d.name = "box";
    d.model = CS_MODEL_LOCALFRAME;
    d.material = mat;
    d.cube_size = 0.1;
    d.cells_ijk = ijk;
    d.n_cells = 8 * 4 * 4;
    d.fracture = true;
    cs_object_id id;
    char err[256];
    ENSURE_MSG(cs_world_add_object(w, &d, &id, err, sizeof err) == CS_OK, "%s", err);
    ENSURE(cs_world_find_internal(w, id)->lf->n_spline == 6 * 2 * 2);
    ENSURE_MSG(cs_world_fracture(w, id, (double[3]){0.4, 0.2, 0.2}, (double[3]){1, 0, 0}, 1.0, err,
                                 sizeof err) == CS_OK, "%s", err);
    cs_object_id ids[8];
    const int n = cs_world_object_ids(w, ids, 8);
    ENSURE(n == 2);
    int spline = 0;
    for (int i = 0; i < n; i++) {
        cs_object *o = cs_world_find_internal(w, ids[i]);
        ENSURE(o->lf && o->lf->n_cells == o->cm.n_cells && o->lf->n_nodes == o->n);
        spline += o->lf->n_spline;
    }
    /* two 4×4×4 halves: 2×2×2 interior cells each, the layers at the cut now boundary cells */
    ENSURE_MSG(spline == 2 * 2 * 2 * 2, "%d B-spline cells after the cut", spline);
    for (int s = 0; s < 20; s++)
        ENSURE(cs_world_step(w) == CS_OK);
    for (int i = 0; i < n; i++) {
        const double *rest, *pos;
        int nn;
        cs_object_nodes(w, ids[i], &rest, &pos, NULL, &nn);
        for (int k = 0; k < 3 * nn; k++)
            ENSURE_NEAR(pos[k], rest[k], 1e-9);
    }
    /* kick one piece: it moves and stays finite */
    ENSURE(cs_world_apply_force(w, ids[1], (double[3]){0.8, 0.2, 0.4}, (double[3]){0, 0, 0.05}, 0.1,
                                err, sizeof err) == CS_OK);
    for (int s = 0; s < 30; s++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_energy e;
    ENSURE(cs_object_energy(w, ids[1], &e) == CS_OK);
    ENSURE(e.kinetic > 0 && isfinite(e.kinetic) && isfinite(e.elastic));
    free(ijk);
    cs_world_destroy(w);
}

/* Skinning follows the tricubic map in B-spline cells: rest positions map to themselves
 * exactly, affine node motions are reproduced, and a general motion gives Σ B̃_a x_a. */
TEST(lf_skin_tricubic_exact_at_rest_and_affine)
{
    cs_cubemesh cm;
    ENSURE(box_mesh(&cm, 5, 5, 5, 0.1) == 0);
    ENSURE(cs_lf_classify(&cm) == 27);
    /* a closed tetrahedron inside the centre cell (2,2,2) and a triangle in a boundary cell */
    const double c0[3] = {cm.origin[0] + 0.2, cm.origin[1] + 0.2, cm.origin[2] + 0.2};
    double v[7][3] = {{0.013, 0.021, 0.017}, {0.087, 0.019, 0.031}, {0.041, 0.093, 0.022},
                      {0.047, 0.038, 0.081}, {-0.18, -0.17, -0.16}, {-0.12, -0.17, -0.16},
                      {-0.15, -0.12, -0.16}};
    for (int i = 0; i < 7; i++)
        for (int k = 0; k < 3; k++)
            v[i][k] += c0[k];
    const int32_t t[5][3] = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}, {4, 5, 6}};
    cs_surface s;
    char err[256];
    ENSURE_MSG(cs_surface_bind(&s, &cm, &v[0][0], 7, &t[0][0], 5, err, sizeof err) == 0, "%s", err);
    const int n = cm.n_nodes;
    double *x = malloc(sizeof(double) * 3 * n);
    memcpy(x, cm.node_rest, sizeof(double) * 3 * n);
    cs_surface_skin(&s, &cm, x, 1);
    for (int i = 0; i < 3 * 4; i++) /* the tetrahedron, in a B-spline cell: bit-exact */
        ENSURE(s.pos[i] == s.rest[i]);
    for (int i = 3 * 4; i < 3 * 7; i++) /* the trilinear cell: up to rounding */
        ENSURE_NEAR(s.pos[i], s.rest[i], 1e-15);
    /* affine: x = A X + b */
    const double A[9] = {1.1, 0.2, -0.05, 0.03, 0.9, 0.1, -0.1, 0.07, 1.2}, bb[3] = {0.3, -0.2, 1};
    for (int i = 0; i < n; i++) {
        const double *X = cm.node_rest + 3 * i;
        for (int r = 0; r < 3; r++)
            x[3 * i + r] = A[3 * r] * X[0] + A[3 * r + 1] * X[1] + A[3 * r + 2] * X[2] + bb[r];
    }
    cs_surface_skin(&s, &cm, x, 1);
    for (int i = 0; i < 7; i++)
        for (int r = 0; r < 3; r++)
            ENSURE_NEAR(s.pos[3 * i + r],
                        A[3 * r] * v[i][0] + A[3 * r + 1] * v[i][1] + A[3 * r + 2] * v[i][2] + bb[r],
                        1e-12);
    /* a general motion: the tetrahedron follows Σ B̃_a x_a of its cell, not the trilinear map */
    for (int i = 0; i < n; i++) {
        const double *X = cm.node_rest + 3 * i;
        x[3 * i] = X[0] + 0.3 * sin(7 * X[1]) * X[2];
        x[3 * i + 1] = X[1] + 0.2 * X[0] * X[0];
        x[3 * i + 2] = X[2] + 0.1 * cos(5 * X[0] + 3 * X[1]);
    }
    cs_surface_skin(&s, &cm, x, 1);
    const int32_t cell = s.vert_cell[0];
    ENSURE(cm.spline_nodes[64 * cell] >= 0);
    double bx[4], by[4], bz[4], p[3] = {0, 0, 0}, ptri[3] = {0, 0, 0};
    const double *uvw = s.vert_uvw;
    cs_bspline_basis(uvw[0], bx, NULL);
    cs_bspline_basis(uvw[1], by, NULL);
    cs_bspline_basis(uvw[2], bz, NULL);
    for (int a = 0; a < 64; a++)
        for (int r = 0; r < 3; r++)
            p[r] += bx[a % 4] * by[(a / 4) % 4] * bz[a / 16] * x[3 * cm.spline_nodes[64 * cell + a] + r];
    for (int k = 0; k < 8; k++) {
        const double wk = (CS_CORNER[k][0] ? uvw[0] : 1 - uvw[0]) *
                          (CS_CORNER[k][1] ? uvw[1] : 1 - uvw[1]) * (CS_CORNER[k][2] ? uvw[2] : 1 - uvw[2]);
        for (int r = 0; r < 3; r++)
            ptri[r] += wk * x[3 * cm.cell_nodes[8 * cell + k] + r];
    }
    double dtri = 0;
    for (int r = 0; r < 3; r++) {
        ENSURE_NEAR(s.pos[r], p[r], 1e-12);
        dtri += fabs(ptri[r] - p[r]);
    }
    ENSURE(dtri > 1e-6); /* the two maps really differ here */
    /* the boundary-cell triangle stays trilinear */
    ENSURE(cm.spline_nodes[64 * s.vert_cell[4]] < 0);
    free(x);
    cs_surface_free(&s);
    cs_cubemesh_free(&cm);
}

/* Element products write per-element slots and gather per node in a fixed order: the same
 * steps on 1 and 2 threads give bit-identical surfaces (288 cubes: above the threading
 * threshold). */
TEST(lf_results_independent_of_thread_count)
{
    uint64_t hash[2];
    for (int t = 0; t < 2; t++) {
        cs_world_def wd = static_world();
        wd.threads = t + 1;
        wd.dt = 1.0 / 60;
        wd.cg_tolerance = 1e-6;
        cs_material mat = cs_material_default();
        lbeam b;
        char err[256];
        ENSURE_MSG(make_lbeam(&b, wd, CS_MODEL_LOCALFRAME, CS_INTEGRATOR_CENTRAL_DIFFERENCE, mat, 8, 6, 0.1,
                              NULL, err, sizeof err) == CS_OK, "%s", err);
        ENSURE(cs_world_find_internal(b.w, b.id)->lf->threads == t + 1);
        ENSURE(cs_world_apply_force(b.w, b.id, (double[3]){0.8, 0.3, 0.6}, (double[3]){0, 1, -2},
                                    0.05, err, sizeof err) == CS_OK);
        for (int s = 0; s < 3; s++)
            ENSURE(cs_world_step(b.w) == CS_OK);
        hash[t] = cs_object_state_hash(b.w, b.id);
        cs_world_destroy(b.w);
    }
    ENSURE(hash[0] == hash[1]);
}

/* Central differences with everything the step honours: a damped localframe block dropped on
 * the ground settles on it, stops (Rayleigh damping), falls asleep; a drag wakes it and pulls
 * it up towards the target. */
TEST(lf_central_difference_ground_damping_sleep_drag)
{
    cs_world_def wd = cs_world_def_default();
    wd.has_ground = true;
    wd.threads = 1;
    wd.dt = 0.003; /* the limit is 0.0037 s for E = 1e5 Pa, ρ = 1000, h = 0.1 m */
    wd.ground_friction = 0; /* the sag formula below is for a bottom free to spread */
    cs_world_t *w;
    ENSURE(cs_world_create(&wd, &w, NULL, 0) == CS_OK);
    int32_t *ijk = cs_box_cells(3, 3, 3);
    cs_object_def d = cs_object_def_default();
    d.name = "block";
    d.model = CS_MODEL_LOCALFRAME;
    d.integrator = CS_INTEGRATOR_CENTRAL_DIFFERENCE; /* no longer the default (bench_wp) */
    d.material.young = 1e5;
    d.material.damping[0] = 6.0;
    d.cube_size = 0.1;
    d.cells_origin[2] = 0.05;
    d.cells_ijk = ijk;
    d.n_cells = 27;
    cs_object_id id;
    char err[256];
    ENSURE_MSG(cs_world_add_object(w, &d, &id, err, sizeof err) == CS_OK, "%s", err);
    cs_object_info info;
    cs_object_get_info(w, id, &info);
    ENSURE(info.integrator == CS_INTEGRATOR_CENTRAL_DIFFERENCE);
    int s = 0;
    for (; s < 2000 && !info.sleeping; s++) {
        ENSURE(cs_world_step(w) == CS_OK);
        cs_object_get_info(w, id, &info);
    }
    ENSURE_MSG(info.sleeping, "not asleep after %d steps", s);
    const double *rest, *pos;
    int n;
    cs_object_nodes(w, id, &rest, &pos, NULL, &n);
    double zmin = INFINITY, zmean = 0;
    for (int i = 0; i < n; i++) {
        zmin = fmin(zmin, pos[3 * i + 2]);
        zmean += pos[3 * i + 2] / n;
    }
    printf("    asleep after %d steps, lowest node z = %.2e m, mean z %.4f m\n", s, zmin, zmean);
    ENSURE(zmin >= -1e-12 && zmin < 1e-3); /* resting on the ground */
    /* a column under its own weight: u(z) = −ρg(Hz − z²/2)/E, whose mean is −ρgH²/3E */
    const double sag = 1000 * 9.81 * 0.09 / (3 * 1e5);
    ENSURE_MSG(fabs((0.15 - zmean) - sag) < 0.15 * sag, "mean sag %g vs %g", 0.15 - zmean, sag);
    /* a drag wakes it and lifts it */
    ENSURE(cs_world_drag(w, id, (double[3]){0.15, 0.15, 0.3}, (double[3]){0.15, 0.15, 0.6}, 2000.0,
                         0.5, err, sizeof err) == CS_OK);
    for (int k = 0; k < 100; k++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_object_get_info(w, id, &info);
    ENSURE(!info.sleeping);
    double zmean2 = 0;
    for (int i = 0; i < n; i++)
        zmean2 += pos[3 * i + 2] / n;
    ENSURE_MSG(zmean2 > zmean + 0.01, "mean z %g -> %g", zmean, zmean2);
    free(ijk);
    cs_world_destroy(w);
}

/* The largest difference between two objects' node positions (the same mesh), and the
 * largest displacement of the first. */
static void position_gap(const lbeam *a, const lbeam *b, double *gap, double *umax)
{
    const double *ra, *pa, *rb, *pb;
    int na, nb;
    cs_object_nodes(a->w, a->id, &ra, &pa, NULL, &na);
    cs_object_nodes(b->w, b->id, &rb, &pb, NULL, &nb);
    *gap = na == nb ? 0.0 : INFINITY;
    *umax = 0;
    for (int i = 0; na == nb && i < 3 * na; i++) {
        *gap = fmax(*gap, fabs(pa[i] - pb[i]));
        *umax = fmax(*umax, fabs(pa[i] - ra[i]));
    }
}

/* Session 46: the multigrid hierarchy, built from the FEM's cube operator, preconditions
 * localframe solves too (world.c wants_multigrid): a static cantilever and implicit Euler
 * steps reach the answers block Jacobi reaches, within what the tolerance leaves, in a
 * fraction of its CG iterations. Before, "multigrid" and "auto" gave localframe block Jacobi
 * (the same iterations as "jacobi": the iteration bounds below fail). 2.6 s in the -O3 build,
 * about 5 minutes under valgrind (`make valgrind` runs --quick, which leaves it out; it passed
 * under valgrind when written). */
SLOW_TEST(lf_multigrid_solves_agree_with_block_jacobi)
{
    cs_material mat = cs_material_default();
    mat.young = 1e6;
    mat.poisson = 0.3;
    mat.density = 1000;
    char err[256];
    /* statics: 40×4×4 cubes of 2.5 cm, 2 N down at the tip */
    lbeam s[2];
    int sits[2];
    for (int k = 0; k < 2; k++) {
        cs_world_def wd = static_world();
        wd.cg_tolerance = 1e-8;
        wd.preconditioner = k ? CS_PRECOND_MULTIGRID : CS_PRECOND_JACOBI;
        ENSURE_MSG(make_lbeam(&s[k], wd, CS_MODEL_LOCALFRAME, CS_INTEGRATOR_IMPLICIT_EULER, mat,
                              40, 4, 0.025, (double[3]){0, 0, -2.0}, err, sizeof err) == CS_OK,
                   "%s", err);
        ENSURE(cs_world_solve_static(s[k].w) == CS_OK);
        sits[k] = cs_world_last_stats(s[k].w)->cg_iterations;
    }
    double gap, umax;
    position_gap(&s[0], &s[1], &gap, &umax);
    printf("    static: CG iterations block Jacobi %d, multigrid %d; tip %.4f m, gap %.2e m\n",
           sits[0], sits[1], tip_deflection(&s[0], 1.0), gap);
    ENSURE(umax > 0.05);
    ENSURE_MSG(gap < 1e-6 * umax, "static answers %g m apart", gap);
    ENSURE_MSG(4 * sits[1] < sits[0], "multigrid %d against block Jacobi %d", sits[1], sits[0]);
    for (int k = 0; k < 2; k++)
        cs_world_destroy(s[k].w);
    /* implicit Euler: 24×4×4 cubes of 5 cm sagging under gravity for 20 steps */
    lbeam d[2];
    long dits[2] = {0, 0};
    for (int k = 0; k < 2; k++) {
        cs_world_def wd = cs_world_def_default();
        wd.cg_tolerance = 1e-10;
        wd.cg_max_iterations = 5000;
        wd.threads = 1;
        wd.preconditioner = k ? CS_PRECOND_MULTIGRID : CS_PRECOND_JACOBI;
        ENSURE_MSG(make_lbeam(&d[k], wd, CS_MODEL_LOCALFRAME, CS_INTEGRATOR_IMPLICIT_EULER, mat,
                              24, 4, 0.05, NULL, err, sizeof err) == CS_OK,
                   "%s", err);
        for (int t = 0; t < 20; t++) {
            ENSURE(cs_world_step(d[k].w) == CS_OK);
            dits[k] += cs_world_last_stats(d[k].w)->cg_iterations;
        }
    }
    position_gap(&d[0], &d[1], &gap, &umax);
    printf("    implicit Euler, 20 steps: CG iterations block Jacobi %ld, multigrid %ld; largest "
           "displacement %.4f m, gap %.2e m\n", dits[0], dits[1], umax, gap);
    ENSURE(umax > 0.05);
    ENSURE_MSG(gap < 1e-6 * umax, "dynamic answers %g m apart", gap);
    ENSURE_MSG(2 * dits[1] < dits[0], "multigrid %ld against block Jacobi %ld", dits[1], dits[0]);
    for (int k = 0; k < 2; k++)
        cs_world_destroy(d[k].w);
}

/* The mass factor (elastic.c): M·(M⁻¹ r) = r on a cantilever's consistent mass; central
 * differences preconditioned by it reach the same steps as block Jacobi (held dofs, a tip
 * pluck, 200 steps) in a quarter of the iterations or fewer; a density field drops it and
 * the next step builds it again. */
TEST(lf_central_difference_mass_factor)
{
    cs_material mat = cs_material_default();
    mat.young = 1e5;
    mat.poisson = 0.3;
    mat.density = 1000;
    double w2;
    ENSURE(cs_lf_omega2_bound(CS_MODEL_LOCALFRAME, mat.young, mat.poisson, mat.density, 0.05,
                              &w2) == 0);
    char err[256];
    lbeam b[2];
    long its[2] = {0, 0};
    for (int k = 0; k < 2; k++) {
        cs_world_def wd = static_world();
        wd.dt = 0.9 * 2 / sqrt(w2);
        wd.cg_tolerance = 1e-10;
        wd.sleep_steps = 0;
        wd.preconditioner = k ? CS_PRECOND_AUTO : CS_PRECOND_JACOBI;
        ENSURE_MSG(make_lbeam(&b[k], wd, CS_MODEL_LOCALFRAME, CS_INTEGRATOR_CENTRAL_DIFFERENCE,
                              mat, 12, 4, 0.05, NULL, err, sizeof err) == CS_OK, "%s", err);
        ENSURE(cs_world_apply_force(b[k].w, b[k].id, (double[3]){0.6, 0.1, 0.2},
                                    (double[3]){0.3, 0.5, -2.0}, 0.02, err, sizeof err) == CS_OK);
        for (int s = 0; s < 200; s++) {
            ENSURE(cs_world_step(b[k].w) == CS_OK);
            its[k] += cs_world_last_stats(b[k].w)->cg_iterations;
        }
    }
    cs_object *o = internal(&b[1]);
    ENSURE(o->mfac != NULL && internal(&b[0])->mfac == NULL);
    /* M (M⁻¹ r) = r */
    const int n3 = 3 * o->n;
    double *r = malloc(sizeof(double) * n3), *z = malloc(sizeof(double) * n3),
           *y = calloc((size_t)n3, sizeof(double));
    ENSURE(r && z && y);
    double rmax = 0, err_max = 0;
    for (int d = 0; d < n3; d++) {
        r[d] = sin(0.37 * d) + 0.5 * cos(1.3 * d);
        rmax = fmax(rmax, fabs(r[d]));
    }
    cs_elastic_mass_solve(o, 1.0, r, z);
    cs_elastic_apply_M(o, z, y, 1.0);
    for (int d = 0; d < n3; d++)
        err_max = fmax(err_max, fabs(y[d] - r[d]));
    ENSURE_MSG(err_max < 1e-10 * rmax, "M M^-1 r - r: %g", err_max);
    double gap, umax;
    position_gap(&b[0], &b[1], &gap, &umax);
    printf("    200 steps: CG iterations block Jacobi %ld, mass factor %ld; largest displacement "
           "%.3g m, gap %.2e m\n", its[0], its[1], umax, gap);
    ENSURE(umax > 1e-4);
    ENSURE_MSG(gap < 1e-7 * umax, "the steps %g m apart", gap);
    ENSURE_MSG(4 * its[1] < its[0], "mass factor %ld against block Jacobi %ld", its[1], its[0]);
    /* a density field changes the mass: the factor goes, the next step builds it again for
     * the new mass (M M⁻¹ r = r with it) */
    const cs_field_factors f = {.density = 3.0, .which = CS_FIELD_DENSITY};
    int touched = 0;
    ENSURE(cs_world_paint(b[1].w, b[1].id, (double[3]){0.3, 0.1, 0.1}, 0.12, &f, &touched, err,
                          sizeof err) == CS_OK);
    ENSURE(touched > 0 && o->mfac == NULL);
    ENSURE(cs_world_step(b[1].w) == CS_OK);
    ENSURE(o->mfac != NULL);
    cs_elastic_mass_solve(o, 1.0, r, z);
    memset(y, 0, sizeof(double) * n3);
    cs_elastic_apply_M(o, z, y, 1.0);
    err_max = 0;
    for (int d = 0; d < n3; d++)
        err_max = fmax(err_max, fabs(y[d] - r[d]));
    ENSURE_MSG(err_max < 1e-10 * rmax, "after painting: M M^-1 r - r: %g", err_max);
    free(r);
    free(z);
    free(y);
    for (int k = 0; k < 2; k++)
        cs_world_destroy(b[k].w);
}

/* A localframe object under central differences cut in two: each piece builds the factor of
 * its own mass (the pieces' nodes are one per lattice point), and their steps stay finite and
 * agree with block Jacobi's. */
TEST(lf_central_difference_mass_factor_after_fracture)
{
    cs_object_id ids[2][8];
    cs_world_t *w[2];
    for (int k = 0; k < 2; k++) {
        cs_world_def wd = static_world();
        wd.dt = 1.0 / 60;
        wd.cg_tolerance = 1e-10;
        wd.sleep_steps = 0;
        wd.preconditioner = k ? CS_PRECOND_AUTO : CS_PRECOND_JACOBI;
        ENSURE(cs_world_create(&wd, &w[k], NULL, 0) == CS_OK);
        int32_t *ijk = cs_box_cells(8, 4, 4);
        cs_object_def d = cs_object_def_default();
        d.name = "box";
        d.model = CS_MODEL_LOCALFRAME;
        d.integrator = CS_INTEGRATOR_CENTRAL_DIFFERENCE;
        d.material = cs_material_default(); /* E = 1000 Pa: 1/60 s is below the limit */
        d.cube_size = 0.1;
        d.cells_ijk = ijk;
        d.n_cells = 8 * 4 * 4;
        d.fracture = true;
        cs_object_id id;
        char err[256];
        ENSURE_MSG(cs_world_add_object(w[k], &d, &id, err, sizeof err) == CS_OK, "%s", err);
        free(ijk);
        ENSURE(cs_world_apply_force(w[k], id, (double[3]){0.75, 0.2, 0.3},
                                    (double[3]){0.5, 0.2, -5.0}, 0.1, err, sizeof err) == CS_OK);
        for (int s = 0; s < 3; s++)
            ENSURE(cs_world_step(w[k]) == CS_OK);
        ENSURE((cs_world_find_internal(w[k], id)->mfac != NULL) == (k == 1));
        ENSURE_MSG(cs_world_fracture(w[k], id, (double[3]){0.4, 0.2, 0.2}, (double[3]){1, 0, 0},
                                     1.0, err, sizeof err) == CS_OK, "%s", err);
        ENSURE(cs_world_object_ids(w[k], ids[k], 8) == 2);
        for (int s = 0; s < 20; s++)
            ENSURE(cs_world_step(w[k]) == CS_OK);
    }
    for (int i = 0; i < 2; i++) {
        cs_object *a = cs_world_find_internal(w[0], ids[0][i]),
                  *b = cs_world_find_internal(w[1], ids[1][i]);
        ENSURE(a->n == b->n && b->mfac != NULL && a->mfac == NULL);
        double gap = 0, umax = 0;
        for (int d = 0; d < 3 * a->n; d++) {
            ENSURE(isfinite(b->x[d]));
            gap = fmax(gap, fabs(a->x[d] - b->x[d]));
            umax = fmax(umax, fabs(b->x[d] - b->cm.node_rest[d]));
        }
        printf("    piece %d: %d nodes, largest displacement %.3g m, %.2e m from block Jacobi's\n", i,
               b->n, umax, gap);
        ENSURE(umax > 1e-4); /* the plucked piece swings, the other drifts off the crack */
        ENSURE_MSG(gap < 1e-7 * umax, "piece %d: %g m apart", i, gap);
    }
    for (int k = 0; k < 2; k++)
        cs_world_destroy(w[k]);
}
