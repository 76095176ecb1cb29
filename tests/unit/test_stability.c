/*
 * test_stability.c — the numerical-stability suite of issue 6 (fast part; the fracture storm
 * is tests/stress/fracture_storm.c in `make stress`). Every test states its pass criterion
 * next to it; the README's "Stability" section lists them with the measured figures (printed
 * here as indented lines).
 *
 *   stab_spin_*            a free tumbling block, 10 000 steps, every model × integrator
 *   stab_implicit_any_dt   implicit Euler from dt 1e-4 to 0.1 s, every model (and rigid)
 *   stab_explicit_limit_*  measured explicit stability limit against the engine's refusal
 *   stab_material_range_*  ν 0..0.49, E 1e2..1e9: statics against beam theory, dynamics finite
 *   stab_crushed_block_*   a block flattened, inverted or jittered, and released
 *   stab_extreme_inputs_*  1e12 N, NaN, inf, tiny/huge dt, absurd drags: refused, state kept
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "elastic.h"
#include "localframe.h"
#include "rigid.h"
#include "world_internal.h"
#include "lattice.h"

/* ---------------------------------------------------------------- helpers */

typedef struct blk {
    cs_world_t *w;
    cs_object_id id;
    int32_t *ijk;
} blk;

static cs_world_def free_world(double dt)
{
    cs_world_def wd = cs_world_def_default();
    wd.dt = dt;
    wd.gravity[0] = wd.gravity[1] = wd.gravity[2] = 0;
    wd.cg_tolerance = 1e-10;
    wd.cg_max_iterations = 5000;
    wd.sleep_steps = 0;
    wd.threads = 1;
    return wd;
}

/* nx×ny×nz cubes of edge h at the origin; held at x = 0 if `fixed`. 0 or -1 (err set). */
static int make_blk(blk *b, const cs_world_def *wd, cs_model model, cs_integrator integ,
                    cs_material mat, int nx, int ny, int nz, double h, bool fixed, char *err,
                    size_t errlen)
{
    memset(b, 0, sizeof *b);
    if (cs_world_create(wd, &b->w, err, errlen) != CS_OK)
        return -1;
    const int n = nx * ny * nz;
    b->ijk = cs_box_cells(nx, ny, nz);
    if (!b->ijk)
        return -1;
    cs_object_def d = cs_object_def_default();
    d.name = "blk";
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

static void free_blk(blk *b)
{
    cs_world_destroy(b->w);
    free(b->ijk);
    memset(b, 0, sizeof *b);
}

static double energy_of(const blk *b)
{
    cs_energy e;
    if (cs_object_energy(b->w, b->id, &e) != CS_OK)
        return NAN;
    return e.kinetic + e.elastic + e.gravity;
}

static bool all_finite(const blk *b)
{
    const double *X, *x, *v;
    int n;
    if (cs_object_nodes(b->w, b->id, &X, &x, &v, &n) != CS_OK)
        return false;
    for (int i = 0; i < 3 * n; i++)
        if (!isfinite(x[i]) || !isfinite(v[i]))
            return false;
    return true;
}

/* Angular momentum about the centre of mass [kg m²/s]. */
static void angular_momentum(const blk *b, double L[3])
{
    cs_object *o = cs_world_find_internal(b->w, b->id);
    L[0] = L[1] = L[2] = 0;
    if (o->model == CS_MODEL_RIGID) {
        cs_rigid_state s;
        cs_object_rigid_state(b->w, b->id, &s);
        memcpy(L, s.angular_momentum, sizeof s.angular_momentum);
        return;
    }
    double c[3] = {0, 0, 0}, p[3] = {0, 0, 0}, m = 0;
    for (int i = 0; i < o->n; i++) {
        m += o->m[i];
        for (int a = 0; a < 3; a++) {
            c[a] += o->m[i] * o->x[3 * i + a];
            p[a] += o->m[i] * o->v[3 * i + a];
        }
    }
    for (int a = 0; a < 3; a++)
        c[a] /= m;
    for (int i = 0; i < o->n; i++) {
        const double r[3] = {o->x[3 * i] - c[0], o->x[3 * i + 1] - c[1], o->x[3 * i + 2] - c[2]};
        const double *v = o->v + 3 * i;
        L[0] += o->m[i] * (r[1] * v[2] - r[2] * v[1]);
        L[1] += o->m[i] * (r[2] * v[0] - r[0] * v[2]);
        L[2] += o->m[i] * (r[0] * v[1] - r[1] * v[0]);
    }
}

static double norm3(const double a[3])
{
    return sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
}

/* Start the block spinning rigidly with angular velocity om about its centre of mass. */
static void spin(blk *b, const double om[3])
{
    cs_object *o = cs_world_find_internal(b->w, b->id);
    if (o->model == CS_MODEL_RIGID) {
        memcpy(o->rb->w, om, 3 * sizeof(double));
        return;
    }
    double c[3] = {0, 0, 0}, m = 0;
    for (int i = 0; i < o->n; i++) {
        m += o->m[i];
        for (int a = 0; a < 3; a++)
            c[a] += o->m[i] * o->x[3 * i + a];
    }
    for (int i = 0; i < o->n; i++) {
        const double r[3] = {o->x[3 * i] - c[0] / m, o->x[3 * i + 1] - c[1] / m,
                             o->x[3 * i + 2] - c[2] / m};
        o->v[3 * i] = om[1] * r[2] - om[2] * r[1];
        o->v[3 * i + 1] = om[2] * r[0] - om[0] * r[2];
        o->v[3 * i + 2] = om[0] * r[1] - om[1] * r[0];
    }
}

/* Small pseudo-random displacements of every free node (every mode excited). */
static void shake(blk *b, double amp, uint64_t seed)
{
    cs_object *o = cs_world_find_internal(b->w, b->id);
    uint64_t r = seed * 0x9E3779B97F4A7C15ULL + 1;
    for (int d = 0; d < 3 * o->n; d++) {
        r ^= r << 13, r ^= r >> 7, r ^= r << 17;
        if (!o->mask[d])
            o->x[d] += amp * ((double)(r % 2001) / 1000.0 - 1.0);
    }
    o->elastic_energy_valid = false;
}

static const cs_model MODELS[4] = {CS_MODEL_LINEAR, CS_MODEL_COROTATIONAL, CS_MODEL_MSS,
                                   CS_MODEL_LOCALFRAME};
static const cs_integrator INTEGS[4] = {CS_INTEGRATOR_IMPLICIT_EULER,
                                        CS_INTEGRATOR_SYMPLECTIC_EULER, CS_INTEGRATOR_VERLET,
                                        CS_INTEGRATOR_CENTRAL_DIFFERENCE};

/* The largest dt (1/60 s halved until accepted) the engine takes for this combination. */
static double accepted_dt(cs_model model, cs_integrator integ, cs_material mat, double h,
                          double start)
{
    char err[512];
    for (double dt = start; dt > 1e-7; dt *= 0.5) {
        cs_world_def wd = free_world(dt);
        blk b;
        const int rc = make_blk(&b, &wd, model, integ, mat, 1, 1, 1, h, false, err, sizeof err);
        free_blk(&b);
        if (rc == 0)
            return dt;
    }
    return 0;
}

/* ---------------------------------------------------------------- 1. free tumbling block */

typedef struct spin_result {
    double dt, e0, radius, emax_rel, egain_step_rel, efinal_rel, l_rel;
    bool finite;
} spin_result;

static int run_spin(cs_model model, cs_integrator integ, int steps, spin_result *res, char *err,
                    size_t errlen)
{
    cs_material mat = cs_material_default();
    mat.young = 1e5;
    const double h = 0.1;
    res->dt = integ == CS_INTEGRATOR_IMPLICIT_EULER || model == CS_MODEL_RIGID
                  ? 1.0 / 60
                  : 0.5 * accepted_dt(model, integ, mat, h, 1.0 / 60);
    cs_world_def wd = free_world(res->dt);
    blk b;
    if (make_blk(&b, &wd, model, integ, mat, 3, 2, 1, h, false, err, errlen) != 0) {
        free_blk(&b);
        return -1;
    }
    /* about the intermediate principal axis (y) with a small perturbation: it flips over
     * (the tennis-racket instability), so the motion is a full 3-D tumble */
    spin(&b, (double[3]){0.05, 2.0, 0.05});
    double L0[3], L[3];
    angular_momentum(&b, L0);
    const double e0 = energy_of(&b);
    double prev = e0, emax = e0, gain = 0, dl = 0;
    res->finite = true;
    for (int s = 0; s < steps; s++) {
        if (cs_world_step(b.w) != CS_OK || !all_finite(&b)) {
            res->finite = false;
            break;
        }
        const double e = energy_of(&b);
        emax = fmax(emax, e);
        gain = fmax(gain, e - prev);
        prev = e;
        angular_momentum(&b, L);
        const double d[3] = {L[0] - L0[0], L[1] - L0[1], L[2] - L0[2]};
        dl = fmax(dl, norm3(d));
    }
    {
        cs_object *o = cs_world_find_internal(b.w, b.id);
        double mx = 0, c[3] = {0, 0, 0};
        for (int i = 0; i < o->n; i++)
            for (int a = 0; a < 3; a++)
                c[a] += o->x[3 * i + a] / o->n;
        for (int i = 0; i < o->n; i++)
            mx = fmax(mx, sqrt(pow(o->x[3 * i] - c[0], 2) + pow(o->x[3 * i + 1] - c[1], 2) +
                               pow(o->x[3 * i + 2] - c[2], 2)));
        res->radius = mx;
    }
    res->e0 = e0;
    res->emax_rel = emax / e0 - 1;
    res->egain_step_rel = gain / e0;
    res->efinal_rel = prev / e0;
    res->l_rel = dl / norm3(L0);
    free_blk(&b);
    return 0;
}

/* 10 000 steps; under the sanitizers (`make test` runs the unit tests only there, ~10× slower)
 * 2 500, so the suite stays within its time budget: the criteria are the same, checked over
 * 10 000 steps by `build/bin/cs_unit_tests stab_spin` in the -O3 build. */
#if defined(__SANITIZE_ADDRESS__)
#define SPIN_STEPS 2500
#else
#define SPIN_STEPS 10000
#endif

/*
 * A free, undamped 3×2×1 block (h 0.1 m, E 100 kPa, ρ 1000) spun at 2 rad/s about its
 * intermediate axis (it tumbles over) for 10 000 steps, every model × integrator the engine
 * accepts (explicit ones at half their accepted dt). Criteria:
 *   - every step succeeds, positions and velocities finite;
 *   - implicit Euler (corotational, localframe, mss): the free body's rigid part turns along
 *     its rotation and its solve feels the centrifugal force (world.c free_body_rotation,
 *     session 32): E ≤ E0 (1 + 1e-4) (measured: it never rises) and |L − L0| ≤ 1e-2 |L0|
 *     (9.8e-4: the corotated operator's torque on the strained body). Before, the
 *     linearised step moved each node along the tangent of its circle, a radius grew by
 *     ~(ω dt)²/2 per step before the elastic force pulled it back, and the bound was
 *     E ≤ E0 (1 + 5 (ω dt)²) (measured 1 + 3.2e-3, settling at 1 + 4.7e-4, spinning on a
 *     little stretched) and |L − L0| ≤ 1e-2 |L0| (9.7e-4); turning by ω at the step's start
 *     instead of at its midpoint pumped this tumble to 1.55 E0. The linear model keeps that
 *     bound (mss lost 90 % of L and 99 % of its energy while its implicit Jacobian kept the
 *     springs' transverse term, now used by statics only);
 *   - symplectic Euler, Verlet, central differences: E ≤ E0 (1 + 1e-3) and |L − L0| ≤ 1e-4 |L0|
 *     (symplectic schemes with internal, rotation-invariant forces conserve L up to round-off
 *     and the rotation extraction's tolerance; measured ≤ 1.2e-5, mss 5e-15), except
 *     localframe + central differences: E ≤ 1.1 E0 and |L − L0| ≤ 0.2 |L0| (measured 6.6 % and
 *     14 %: a documented limit of that combination at half its accepted dt);
 *   - the linear model: a rigid velocity field is a zero-energy mode of the linear stiffness,
 *     so the nodes fly off along their tangents and the block inflates without any force
 *     (E and L stay exact): asserted as the documented limit (final radius > 1 m); every
 *     other model keeps its size (radius < 0.25 m, rest 0.187 m);
 *   - rigid: |L − L0| ≤ 1e-9 |L0| (round-off).
 */
SLOW_TEST(stab_spin_tumbling_block)
{
    char err[512];
    for (int mi = 0; mi < 5; mi++)
        for (int ii = 0; ii < 4; ii++) {
            const cs_model model = mi < 4 ? MODELS[mi] : CS_MODEL_RIGID;
            if (model == CS_MODEL_RIGID && ii > 0)
                continue;
            const cs_integrator integ = INTEGS[ii];
            spin_result r;
            ENSURE_MSG(run_spin(model, integ, SPIN_STEPS, &r, err, sizeof err) == 0, "%s %s: %s",
                       cs_model_name(model), cs_integrator_name(integ), err);
            printf("    spin %s %s dt %.3g: E0 %.4g J, max E/E0-1 %.3g, max step gain %.3g E0, "
                   "final E/E0 %.4g, max |L-L0|/|L0| %.3g\n",
                   cs_model_name(model), model == CS_MODEL_RIGID ? "rigid" : cs_integrator_name(integ),
                   r.dt, r.e0, r.emax_rel, r.egain_step_rel, r.efinal_rel, r.l_rel);
            printf("      largest node distance from the centre of mass at the end %.3g m "
                   "(rest 0.187 m)\n", r.radius);
            ENSURE_MSG(r.finite, "%s %s: a step failed or went non-finite", cs_model_name(model),
                       cs_integrator_name(integ));
            const char *mn = cs_model_name(model), *in = cs_integrator_name(integ);
            if (model == CS_MODEL_RIGID) {
                ENSURE_MSG(r.emax_rel <= 1e-9 && r.l_rel <= 1e-9, "rigid: E %g, L %g", r.emax_rel,
                           r.l_rel);
            } else if (integ == CS_INTEGRATOR_IMPLICIT_EULER && model == CS_MODEL_LINEAR) {
                /* the linear model is not rotation-invariant: it inflates (asserted below) */
                const double wdt = 2.0 * r.dt;
                ENSURE_MSG(r.emax_rel <= 5 * wdt * wdt, "%s %s: E rose to (1 + %g) E0 > 1 + 5 (w dt)^2",
                           mn, in, r.emax_rel);
            } else if (integ == CS_INTEGRATOR_IMPLICIT_EULER) {
                /* The free body's rigid part turns along its rotation and its solve feels the
                 * centrifugal force (world.c free_body_rotation, turn_centrifugal): the energy
                 * never rises (measured max E/E0 − 1 = 0; 1.4e-5 without the centrifugal
                 * force). Before session 32 the linearised step moved each node along the
                 * tangent of its circle, a radius grew by (ω dt)²/2 per step before the
                 * elastic force pulled it back, and E rose by 3.2e-3; turning by ω itself
                 * instead of the midpoint's rotation pumped this tumble to +55 %. L: the
                 * corotated operator of a strained body exerts a torque (it bulges as it
                 * spins), measured 9.8e-4 (3e-14 when the turn left it rigid). */
                ENSURE_MSG(r.emax_rel <= 1e-4, "%s %s: E rose to (1 + %g) E0", mn, in,
                           r.emax_rel);
                ENSURE_MSG(r.l_rel <= 1e-2, "%s %s: |L - L0| = %g |L0|", mn, in, r.l_rel);
            } else {
                const bool lf_cd = model == CS_MODEL_LOCALFRAME &&
                                   integ == CS_INTEGRATOR_CENTRAL_DIFFERENCE;
                ENSURE_MSG(r.emax_rel <= (lf_cd ? 0.1 : 1e-3), "%s %s: E rose to (1 + %g) E0", mn,
                           in, r.emax_rel);
                ENSURE_MSG(r.l_rel <= (lf_cd ? 0.2 : 1e-4), "%s %s: |L - L0| = %g |L0|", mn, in,
                           r.l_rel);
            }
            if (model == CS_MODEL_LINEAR) /* documents the limit: a linear block inflates */
                ENSURE_MSG(r.radius > 1.0, "linear %s: radius %g", in, r.radius);
            else
                ENSURE_MSG(r.radius < 0.25, "%s %s: radius %g", mn, in, r.radius);
        }
}

/* ---------------------------------------------------------------- 3. explicit stability limit */

/* The limit the engine refuses above (world.c: cs_elastic_critical_dt for symplectic Euler
 * and Verlet; for central differences 2/ω_max: cs_lf_omega2_bound for localframe, the
 * model's cube eigenvalue bound cs_elastic_max_omega otherwise). */
static double engine_limit(cs_model model, cs_integrator integ, const cs_material *mat, double h)
{
    if (integ == CS_INTEGRATOR_CENTRAL_DIFFERENCE) {
        /* localframe: its B-spline bound; the others: their own cube's eigenvalue bound */
        if (model != CS_MODEL_LOCALFRAME)
            return 2.0 / cs_elastic_max_omega(model, mat, h);
        double w2;
        if (cs_lf_omega2_bound(model, mat->young, mat->poisson, mat->density, h, &w2) != 0)
            return NAN;
        return 2.0 / sqrt(w2);
    }
    return cs_elastic_critical_dt(model, mat, h);
}

/* Does a shaken free 3×3×3 block blow up at this dt? (The object is made at an accepted dt
 * and the world's dt raised afterwards, past the add-time check.) Blown up: a step diverges
 * or the energy exceeds 1e6 times its starting value within 1000 steps (below the limit the
 * energy of the fastest mode swings by at most ~1/(1 − (ωdt/2)²), far less). */
static int blows_up(cs_model model, cs_integrator integ, const cs_material *mat, double h,
                    double dt, double safe_dt)
{
    char err[512];
    cs_world_def wd = free_world(safe_dt);
    blk b;
    if (make_blk(&b, &wd, model, integ, *mat, 3, 3, 3, h, false, err, sizeof err) != 0) {
        free_blk(&b);
        return -1;
    }
    b.w->def.dt = dt;
    shake(&b, 1e-4 * h, 7);
    const double e0 = energy_of(&b);
    int up = 0;
    for (int s = 0; s < 1000 && !up; s++) {
        if (cs_world_step(b.w) != CS_OK || !(energy_of(&b) < 1e6 * e0))
            up = 1;
    }
    free_blk(&b);
    return up;
}

/*
 * For every model with symplectic Euler, Verlet and central differences: bisect dt (to 1 %)
 * between the engine's limit and a dt that blows up. Criteria: the engine's limit is safe
 * (the block does not blow up at it: measured ≥ engine) and not absurdly conservative
 * (measured ≤ 3 × engine). The ratios are printed (README, Stability).
 */
SLOW_TEST(stab_explicit_limit_against_engine_estimate)
{
    cs_material mat = cs_material_default();
    mat.young = 1e5;
    const double h = 0.1;
    for (int mi = 0; mi < 4; mi++)
        for (int ii = 1; ii < 4; ii++) {
            const cs_model model = MODELS[mi];
            const cs_integrator integ = INTEGS[ii];
            const double lim = engine_limit(model, integ, &mat, h);
            ENSURE(isfinite(lim) && lim > 0);
            const int at_lim = blows_up(model, integ, &mat, h, lim, 0.5 * lim);
            if (at_lim < 0) {
                printf("    limit %s %s: refused by the engine\n", cs_model_name(model),
                       cs_integrator_name(integ));
                continue;
            }
            double lo = lim, hi = 1.25 * lim;
            while (hi < 16 * lim && blows_up(model, integ, &mat, h, hi, 0.5 * lim) == 0)
                lo = hi, hi *= 2;
            while (hi - lo > 1e-2 * lo) {
                const double mid = 0.5 * (lo + hi);
                if (blows_up(model, integ, &mat, h, mid, 0.5 * lim))
                    hi = mid;
                else
                    lo = mid;
            }
            printf("    limit %s %s: engine %.4g s, measured %.4g s, ratio %.3f%s\n",
                   cs_model_name(model), cs_integrator_name(integ), lim, lo, lo / lim,
                   at_lim ? " (UNSAFE: blows up at the engine's limit)" : "");
            ENSURE_MSG(!at_lim, "%s %s blows up at the engine's limit %g s", cs_model_name(model),
                       cs_integrator_name(integ), lim);
            ENSURE_MSG(lo <= 3 * lim, "%s %s: engine limit %g s is over 3x conservative (%g s)",
                       cs_model_name(model), cs_integrator_name(integ), lim, lo);
        }
}

/* ---------------------------------------------------------------- 2. implicit steps of any size */

/*
 * A 6×2×2 cantilever (h 0.05 m, E 100 kPa, ν 0.3, ρ 1000, undamped, gravity on) held at x = 0
 * and started with every free node moving at 1 m/s downwards, stepped by implicit Euler at
 * dt = 1e-4, 1e-3, 1e-2, 0.1 s (max(100, min(1000, 0.3 s/dt)) steps) for every deformable
 * model; and a free rigid block tumbling at 2 rad/s at the same steps. Criteria: every step
 * succeeds and stays finite; no node leaves a 1 m ball around its rest position; the total
 * energy (kinetic + elastic + gravity: no other force works on it) never exceeds its initial
 * value E0 (1e-9 relative) for dt ≤ 0.01 s, for the linear model and for rigid bodies at every
 * dt, and ends below E0. Documented limit: at dt 0.1 s the corotational, localframe and mss
 * models rise once (measured +104 %, +104 %, +48 % in the first step: its strain increment
 * v·dt/h is 2, and one linearised solve lands where the nonlinear energy exceeds the linear
 * one), asserted below 3 E0, then decay (final E < E0 asserted). Central differences at dt above their limit are refused with the limit in
 * the message (asserted here for dt = 0.1 s).
 */
TEST(stab_implicit_any_dt)
{
    const double dts[4] = {1e-4, 1e-3, 1e-2, 0.1};
    cs_material mat = cs_material_default();
    mat.young = 1e5;
    char err[512];
    for (int mi = 0; mi < 5; mi++)
        for (int di = 0; di < 4; di++) {
            const cs_model model = mi < 4 ? MODELS[mi] : CS_MODEL_RIGID;
            const double dt = dts[di];
            cs_world_def wd = free_world(dt);
            if (model != CS_MODEL_RIGID)
                wd.gravity[2] = -9.81;
            blk b;
            ENSURE_MSG(make_blk(&b, &wd, model,
                                model == CS_MODEL_RIGID ? CS_INTEGRATOR_DEFAULT
                                                        : CS_INTEGRATOR_IMPLICIT_EULER,
                                mat, 6, 2, 2, 0.05, model != CS_MODEL_RIGID, err, sizeof err) == 0,
                       "%s dt %g: %s", cs_model_name(model), dt, err);
            cs_object *o = cs_world_find_internal(b.w, b.id);
            if (model == CS_MODEL_RIGID)
                spin(&b, (double[3]){0.05, 2.0, 0.05});
            else
                for (int i = 0; i < o->n; i++)
                    if (!o->mask[3 * i + 2])
                        o->v[3 * i + 2] = -1.0;
            const double e0 = energy_of(&b);
            const int steps = (int)fmax(100, fmin(1000, 0.3 / dt));
            double emax = e0, dmax = 0;
            int s = 0;
            bool ok = true;
            for (; s < steps && ok; s++) {
                ok = cs_world_step(b.w) == CS_OK && all_finite(&b);
                emax = fmax(emax, energy_of(&b));
            }
            const double *X, *x, *v;
            int n;
            cs_object_nodes(b.w, b.id, &X, &x, &v, &n);
            for (int i = 0; i < 3 * n; i++)
                dmax = fmax(dmax, fabs(x[i] - X[i]));
            printf("    implicit %s dt %g: %d steps, E0 %.4g J, max (E - E0)/|E0| %.3g, final E %.4g J, "
                   "max |x - X| %.3g m\n", cs_model_name(model), dt, s, e0, (emax - e0) / fabs(e0),
                   energy_of(&b), dmax);
            const double efinal = energy_of(&b);
            free_blk(&b);
            ENSURE_MSG(ok, "%s dt %g: step %d failed or non-finite", cs_model_name(model), dt, s);
            ENSURE_MSG(dmax < 1.0 || model == CS_MODEL_RIGID, "%s dt %g: a node moved %g m",
                       cs_model_name(model), dt, dmax);
            /* the linearised step is exact for the linear model; for the nonlinear ones a step
             * whose strain increment v dt / h is O(1) (here 2 at dt 0.1 s) lands where their
             * energy exceeds the linear one: the documented limit is a one-off rise below 3 E0
             * that then decays (final E < E0) */
            const double bound = model == CS_MODEL_LINEAR || model == CS_MODEL_RIGID || dt < 0.05
                                     ? 1e-9 : 2.0;
            ENSURE_MSG(emax <= e0 + bound * fabs(e0), "%s dt %g: energy rose from %g to %g J",
                       cs_model_name(model), dt, e0, emax);
            ENSURE_MSG(efinal <= e0 * (1 + 1e-9), "%s dt %g: final energy %g J > E0 %g J",
                       cs_model_name(model), dt, efinal, e0);
        }
    /* central differences above their limit: refused, the limit named */
    for (int mi = 0; mi < 4; mi++) {
        cs_world_def wd = free_world(0.1);
        blk b;
        err[0] = 0;
        const int rc = make_blk(&b, &wd, MODELS[mi], CS_INTEGRATOR_CENTRAL_DIFFERENCE, mat, 6, 2, 2,
                                0.05, true, err, sizeof err);
        free_blk(&b);
        ENSURE_MSG(rc != 0 && strstr(err, "stability limit"), "%s central_difference at 0.1 s: %s",
                   cs_model_name(MODELS[mi]), err);
    }
}

/* ---------------------------------------------------------------- 6. extreme inputs */

/*
 * Criteria: every absurd input is refused with CS_ERR_INVALID and a one-line message naming
 * the problem, and the state hash is unchanged by the refusals; the largest accepted inputs
 * (a force just below max_force, a 1e6 s duration at a small dt, a drag of absurd stiffness)
 * are survived: every step returns CS_OK or CS_ERR_DIVERGED (undone, inputs dropped) and the
 * nodes stay finite.
 */
TEST(stab_extreme_inputs_refused_state_kept)
{
    char err[512];
    /* world definitions */
    const double bad_dt[6] = {0, -1, NAN, INFINITY, 2.0, 1e-300};
    for (int i = 0; i < 6; i++) {
        cs_world_def wd = cs_world_def_default();
        wd.dt = bad_dt[i];
        cs_world_t *w = (cs_world_t *)1;
        err[0] = 0;
        ENSURE_MSG(cs_world_create(&wd, &w, err, sizeof err) == CS_ERR_INVALID && !w &&
                       strstr(err, "dt") && !strchr(err, '\n'),
                   "dt %g: accepted or bad message '%s'", bad_dt[i], err);
    }
    cs_world_def wd = free_world(1.0 / 60);
    wd.gravity[2] = -9.81;
    blk b;
    ENSURE(make_blk(&b, &wd, CS_MODEL_COROTATIONAL, CS_INTEGRATOR_IMPLICIT_EULER,
                    cs_material_default(), 3, 2, 2, 0.1, true, err, sizeof err) == 0);
    for (int s = 0; s < 5; s++)
        ENSURE(cs_world_step(b.w) == CS_OK);
    const uint64_t h0 = cs_object_state_hash(b.w, b.id);
    const double p[3] = {0.25, 0.1, 0.1}, far[3] = {0.25, 0.1, 10.0};
    const double nan3[3] = {NAN, 0, 0}, inf3[3] = {0, INFINITY, 0}, big[3] = {0, 0, 1e12};
    struct {
        int rc;
        const char *want;
    } r[32];
    int n = 0;
#define TRY(call, w_)                                                                          \
    do {                                                                                       \
        err[0] = 0;                                                                            \
        r[n].rc = (call);                                                                      \
        r[n].want = w_;                                                                        \
        ENSURE_MSG(r[n].rc == CS_ERR_INVALID && strstr(err, w_) && !strchr(err, '\n'),         \
                   "%s: rc %d, message '%s' (want '%s')", #call, r[n].rc, err, w_);            \
        n++;                                                                                   \
    } while (0)
    TRY(cs_world_apply_force(b.w, b.id, p, big, 0, err, sizeof err), "max_force");
    TRY(cs_world_apply_force(b.w, b.id, p, nan3, 0, err, sizeof err), "not finite");
    TRY(cs_world_apply_force(b.w, b.id, p, inf3, 0, err, sizeof err), "not finite");
    TRY(cs_world_apply_force(b.w, b.id, nan3, p, 0, err, sizeof err), "not finite");
    TRY(cs_world_apply_force(b.w, b.id, p, p, NAN, err, sizeof err), "duration");
    TRY(cs_world_apply_force(b.w, b.id, p, p, INFINITY, err, sizeof err), "duration");
    TRY(cs_world_apply_force(b.w, b.id, p, p, -1, err, sizeof err), "duration");
    TRY(cs_world_drag(b.w, b.id, p, far, 1e300, 1, err, sizeof err), "max_force");
    TRY(cs_world_drag(b.w, b.id, p, far, INFINITY, 1, err, sizeof err), "stiffness");
    TRY(cs_world_drag(b.w, b.id, p, far, NAN, 1, err, sizeof err), "stiffness");
    TRY(cs_world_drag(b.w, b.id, p, far, -1, 1, err, sizeof err), "stiffness");
    TRY(cs_world_drag(b.w, b.id, p, nan3, 10, 1, err, sizeof err), "not finite");
    TRY(cs_world_pressure(b.w, b.id, NAN, 1, err, sizeof err), "finite");
    TRY(cs_world_pressure(b.w, b.id, 1e300, 1, err, sizeof err), "max_force");
    const double curve[6] = {0.25, 0.1, 0.1, NAN, 0, 0};
    TRY(cs_world_drag_curve(b.w, b.id, curve, 2, 10, 1, err, sizeof err), "finite");
    TRY(cs_world_fracture(b.w, b.id, nan3, (double[3]){0, 0, 1}, 0, err, sizeof err), "finite");
    TRY(cs_world_fracture(b.w, b.id, p, (double[3]){0, 0, 0}, 0, err, sizeof err), "normal");
    const cs_field_factors ff = {.young = 1e30, .which = CS_FIELD_YOUNG};
    TRY(cs_world_paint(b.w, b.id, p, 0.1, &ff, NULL, err, sizeof err), "young");
#undef TRY
    ENSURE_MSG(cs_object_state_hash(b.w, b.id) == h0, "the refusals changed the state");
    free_blk(&b);

    /* the largest accepted inputs, implicit and explicit */
    for (int ii = 0; ii < 3; ii++) {
        const cs_integrator integ = ii == 0 ? CS_INTEGRATOR_IMPLICIT_EULER
                                    : ii == 1 ? CS_INTEGRATOR_SYMPLECTIC_EULER
                                              : CS_INTEGRATOR_CENTRAL_DIFFERENCE;
        wd = free_world(ii ? 1e-4 : 1.0 / 60);
        wd.gravity[2] = -9.81;
        ENSURE_MSG(make_blk(&b, &wd, CS_MODEL_COROTATIONAL, integ, cs_material_default(), 3, 2, 2,
                            0.1, true, err, sizeof err) == 0, "%s", err);
        ENSURE(cs_world_apply_force(b.w, b.id, p, (double[3]){0, 1, 0}, 1e6, err, sizeof err) ==
               CS_OK);
        const cs_object *o = cs_world_find_internal(b.w, b.id);
        ENSURE_MSG(o->inputs[o->n_inputs - 1].steps_left > 0,
                   "a 1e6 s force at dt %g lasts %d steps", wd.dt, o->inputs[o->n_inputs - 1].steps_left);
        double k = 1e9; /* 1e8 N at 0.1 m */
        int rc = cs_world_drag(b.w, b.id, p, (double[3]){0.25, 0.1, 0.2}, k, 1, err, sizeof err);
        if (integ == CS_INTEGRATOR_SYMPLECTIC_EULER) {
            /* explicit: refused, the limit named; the largest accepted one must be stable */
            ENSURE_MSG(rc == CS_ERR_INVALID && strstr(err, "explicit stability limit"), "%s", err);
            while (rc != CS_OK && k > 1)
                rc = cs_world_drag(b.w, b.id, p, (double[3]){0.25, 0.1, 0.2}, k *= 0.7, 1, err,
                                   sizeof err);
        }
        ENSURE_MSG(rc == CS_OK, "%s", err);
        const int release = (int)ceil(1.0 / wd.dt) + 1;
        double e_rel = 0, e_max = 0;
        int diverged = 0, other = 0;
        for (int s = 0; s < release + 200; s++) {
            if (s == 0)
                ENSURE(cs_world_apply_force(b.w, b.id, p, (double[3]){0, 0, 0.999e9}, 0, err,
                                            sizeof err) == CS_OK);
            const int rcs = cs_world_step(b.w);
            diverged += rcs == CS_ERR_DIVERGED;
            other += rcs != CS_OK && rcs != CS_ERR_DIVERGED;
            if (s == release)
                e_rel = energy_of(&b);
            if (s > release)
                e_max = fmax(e_max, energy_of(&b));
        }
        const double *X, *x, *v;
        int nn;
        cs_object_nodes(b.w, b.id, &X, &x, &v, &nn);
        double dmax = 0;
        for (int i = 0; i < 3 * nn; i++)
            dmax = fmax(dmax, fabs(x[i] - X[i]));
        printf("    extreme accepted inputs, %s: a 0.999e9 N kick and a %.3g N/m drag for 1 s: "
               "%d steps diverged (undone); energy after the drag %.3g J, then at most %.3g J; "
               "max |x - X| %.3g m\n", cs_integrator_name(integ), k, diverged, e_rel, e_max, dmax);
        const bool fin = all_finite(&b);
        free_blk(&b);
        ENSURE_MSG(fin && other == 0, "%s: finite %d, %d failed steps", cs_integrator_name(integ),
                   fin, other);
        ENSURE_MSG(e_max <= 1.01 * fabs(e_rel) + 1e-6, "%s: energy grew after the inputs ended",
                   cs_integrator_name(integ));
    }
}

/* ---------------------------------------------------------------- 4. material range */

/* Tip deflection of an 8×2×2 cantilever (h 0.05: L 0.4, 0.1 × 0.1 section) held at x = 0 under
 * a total tip force F on its x = L end face, against Timoshenko's
 * δ = F L³/(3EI) + F L/(κ G A), κ = 5/6. Returns the ratio FEM/theory, or NAN. */
static double cantilever_ratio(cs_model model, double young, double poisson, char *err,
                               size_t errlen)
{
    const double L = 0.4, t = 0.1, I = t * t * t * t / 12, A = t * t;
    const double G = young / (2 * (1 + poisson));
    const double F = 3 * young * I * 1e-3 * L / (L * L * L); /* δ_EB = L/1000 */
    const double ref = F * L * L * L / (3 * young * I) + F * L / (5.0 / 6.0 * G * A);
    cs_world_def wd = free_world(1.0 / 60);
    wd.cg_tolerance = 1e-12;
    wd.cg_max_iterations = 20000;
    cs_world_t *w;
    if (cs_world_create(&wd, &w, err, errlen) != CS_OK)
        return NAN;
    int32_t ijk[3 * 32];
    int c = 0;
    for (int k = 0; k < 2; k++)
        for (int j = 0; j < 2; j++)
            for (int i = 0; i < 8; i++) {
                ijk[3 * c] = i, ijk[3 * c + 1] = j, ijk[3 * c + 2] = k;
                c++;
            }
    cs_object_def d = cs_object_def_default();
    d.name = "beam";
    d.model = model;
    d.integrator = CS_INTEGRATOR_IMPLICIT_EULER; /* statics: any that accepts the dt */
    d.material.young = young;
    d.material.poisson = poisson;
    d.cube_size = 0.05;
    d.cells_ijk = ijk;
    d.n_cells = c;
    const cs_aabb fix = {{-1e-4, -1, -1}, {1e-4, 1, 1}};
    const cs_load load = {{{L - 1e-3, -1, -1}, {L + 1e-3, 1, 1}}, {0, 0, -F}};
    d.fixed = &fix;
    d.n_fixed = 1;
    d.loads = &load;
    d.n_loads = 1;
    cs_object_id id;
    double ratio = NAN;
    if (cs_world_add_object(w, &d, &id, err, errlen) == CS_OK && cs_world_solve_static(w) == CS_OK) {
        const double *X, *x, *v;
        int n;
        cs_object_nodes(w, id, &X, &x, &v, &n);
        double s = 0;
        int m = 0;
        for (int i = 0; i < n; i++)
            if (X[3 * i] > L - 1e-6) {
                s += x[3 * i + 2] - X[3 * i + 2];
                m++;
            }
        ratio = -s / m / ref;
    } else if (!err[0]) {
        snprintf(err, errlen, "static solve failed");
    }
    cs_world_destroy(w);
    return ratio;
}

/*
 * Statics: the cantilever above for every model, ν ∈ {0, 0.25, 0.4, 0.45, 0.49} and
 * E ∈ {1e2, 1e5, 1e9} Pa (the load scales with E: a small deflection, L/1000). Criteria: the
 * result does not depend on E (relative spread ≤ 1e-6: the solve is scale-free); the tip
 * deflection is within a factor 2 of Timoshenko's for ν ≤ 0.45 (two trilinear cubes
 * through the thickness lock in shear: measured ratios printed). ν = 0.49 is reported, and
 * only required positive and finite: linear hexahedra lock volumetrically as ν → 0.5; mss
 * refuses it (above CS_MSS_MAX_POISSON, mss.h), with the limit in its message.
 */
TEST(stab_material_range_statics)
{
    const double nus[5] = {0, 0.25, 0.4, 0.45, 0.49}, Es[3] = {1e2, 1e5, 1e9};
    char err[512];
    for (int mi = 0; mi < 4; mi++)
        for (int ni = 0; ni < 5; ni++) {
            double r[3];
            if (MODELS[mi] == CS_MODEL_MSS && nus[ni] > CS_MSS_MAX_POISSON) {
                err[0] = 0; /* refused (mss.h) */
                ENSURE(!isfinite(cantilever_ratio(MODELS[mi], Es[0], nus[ni], err, sizeof err)));
                ENSURE_MSG(strstr(err, "'mss' takes poisson up to 0.45"), "%s", err);
                continue;
            }
            for (int ei = 0; ei < 3; ei++) {
                err[0] = 0;
                r[ei] = cantilever_ratio(MODELS[mi], Es[ei], nus[ni], err, sizeof err);
                ENSURE_MSG(isfinite(r[ei]) && r[ei] > 0, "%s nu %g E %g: %s",
                           cs_model_name(MODELS[mi]), nus[ni], Es[ei], err);
            }
            printf("    static %s nu %.2f: tip deflection / Timoshenko %.4f (E 1e2), %.4f (1e5), "
                   "%.4f (1e9)\n", cs_model_name(MODELS[mi]), nus[ni], r[0], r[1], r[2]);
            for (int ei = 1; ei < 3; ei++)
                ENSURE_MSG(fabs(r[ei] - r[0]) <= 1e-6 * r[0], "%s nu %g: depends on E: %g vs %g",
                           cs_model_name(MODELS[mi]), nus[ni], r[ei], r[0]);
            if (nus[ni] <= 0.45)
                ENSURE_MSG(r[0] > 0.5 && r[0] < 2, "%s nu %g: ratio %g", cs_model_name(MODELS[mi]),
                           nus[ni], r[0]);
        }
}

/*
 * Dynamics over the same range: a 4×2×2 cantilever (h 0.05) held at x = 0 under gravity,
 * implicit Euler at dt 1/60 s with the default solver settings (tolerance 1e-4 since issue 6, 500
 * iterations), 120 steps, every model, E ∈ {1e2, 1e5, 1e9} Pa, ν ∈ {0, 0.49} (mss: 0.45).
 * Criteria: every step returns CS_OK (or CS_ERR_NOT_CONVERGED, counted and printed: the state stays finite);
 * nodes finite; the total energy (kinetic + elastic + gravity) never exceeds its start by more
 * than 1e-6 |E0| + 1 µJ (gravity is the only load and is conservative). At E = 1e2 Pa the beam
 * hangs (its own weight stresses it 20 times E: strains of order 1–10), and the linear model
 * sags by ~20 m (nonsense, but finite and without energy gain). Documented limit: at
 * E = 1e2 Pa and ν = 0.49 the nonlinear models (corotational, localframe) gain energy
 * under implicit Euler — a single linearised solve per step with nearly incompressible cubes
 * at strains of order 1 (measured after 120 steps: +5.8 J, +5.8 J on E0 = 0.98 J;
 * localframe +12 J after 1000); asserted below 10 |E0| and finite, never NaN. mss refuses
 * ν = 0.49 since session 31 (CS_MSS_MAX_POISSON, mss.h; it gained +3.7 J here) and runs at
 * its limit, 0.45, instead (no energy gain).
 */
TEST(stab_material_range_dynamics)
{
    const double nus[2] = {0, 0.49}, Es[3] = {1e2, 1e5, 1e9};
    char err[512];
    for (int mi = 0; mi < 4; mi++)
        for (int ni = 0; ni < 2; ni++)
            for (int ei = 0; ei < 3; ei++) {
                cs_world_def wd = cs_world_def_default();
                wd.sleep_steps = 0;
                wd.threads = 1;
                cs_material mat = cs_material_default();
                mat.young = Es[ei];
                mat.poisson = nus[ni];
                blk b;
                if (MODELS[mi] == CS_MODEL_MSS && nus[ni] > CS_MSS_MAX_POISSON) {
                    /* refused (mss.h); run at its limit instead */
                    const int refused = make_blk(&b, &wd, MODELS[mi], CS_INTEGRATOR_IMPLICIT_EULER,
                                                 mat, 4, 2, 2, 0.05, true, err, sizeof err);
                    free_blk(&b);
                    ENSURE(refused != 0);
                    ENSURE_MSG(strstr(err, "'mss' takes poisson up to 0.45"), "%s", err);
                    mat.poisson = CS_MSS_MAX_POISSON;
                }
                ENSURE_MSG(make_blk(&b, &wd, MODELS[mi], CS_INTEGRATOR_IMPLICIT_EULER, mat, 4, 2, 2,
                                    0.05, true, err, sizeof err) == 0, "%s", err);
                const double e0 = energy_of(&b);
                double emax = e0;
                int nc = 0, bad = 0;
                for (int s = 0; s < 120; s++) {
                    const int rc = cs_world_step(b.w);
                    nc += rc == CS_ERR_NOT_CONVERGED;
                    bad += rc != CS_OK && rc != CS_ERR_NOT_CONVERGED;
                    emax = fmax(emax, energy_of(&b));
                }
                const double *X, *x, *v;
                int n;
                cs_object_nodes(b.w, b.id, &X, &x, &v, &n);
                double tip = 0;
                for (int i = 0; i < n; i++)
                    tip = fmin(tip, x[3 * i + 2] - X[3 * i + 2]);
                const bool fin = all_finite(&b);
                free_blk(&b);
                printf("    dynamic %s E %g nu %.2f: lowest node moved %.3g m, max (E - E0) %.3g J "
                       "(E0 %.4g J), %d of 120 steps not converged\n", cs_model_name(MODELS[mi]),
                       Es[ei], mat.poisson, tip, emax - e0, e0, nc);
                ENSURE_MSG(fin && bad == 0, "%s E %g nu %g: finite %d, %d failed steps",
                           cs_model_name(MODELS[mi]), Es[ei], nus[ni], fin, bad);
                /* documented limit: see the comment above the test */
                const bool limit =
                    MODELS[mi] != CS_MODEL_LINEAR && Es[ei] < 1e3 && mat.poisson > 0.45;
                ENSURE_MSG(emax <= (limit ? 10 * fabs(e0) : e0 + 1e-6 * fabs(e0) + 1e-6),
                           "%s E %g nu %g: energy rose by %g J",
                           cs_model_name(MODELS[mi]), Es[ei], nus[ni], emax - e0);
            }
}

/* ---------------------------------------------------------------- 5. crushed and released */

/* Smallest corner Jacobian determinant of any cell, over h³ (1 at rest, ≤ 0 inverted), and
 * the largest relative change of a cell edge's length. */
static void cell_quality(const blk *b, double *min_det, double *max_edge)
{
    const double *X, *x, *v;
    const int32_t *ijk, *nodes;
    int n, nc;
    cs_object_nodes(b->w, b->id, &X, &x, &v, &n);
    cs_object_cells(b->w, b->id, &ijk, &nodes, &nc);
    const cs_object *o = cs_world_find_internal(b->w, b->id);
    const double h = o->cm.h;
    *min_det = INFINITY;
    *max_edge = 0;
    for (int c = 0; c < nc; c++) {
        const int32_t *nd = nodes + 8 * c;
        for (int a = 0; a < 8; a++) {
            /* the three corners adjacent to a, each along +axis or −axis */
            double e[3][3];
            for (int ax = 0; ax < 3; ax++) {
                int bc = -1;
                for (int q = 0; q < 8; q++) {
                    int diff = 0;
                    for (int k = 0; k < 3; k++)
                        diff += CS_CORNER[q][k] != CS_CORNER[a][k];
                    if (diff == 1 && CS_CORNER[q][ax] != CS_CORNER[a][ax])
                        bc = q;
                }
                const double sg = CS_CORNER[bc][ax] > CS_CORNER[a][ax] ? 1 : -1;
                for (int k = 0; k < 3; k++)
                    e[ax][k] = sg * (x[3 * nd[bc] + k] - x[3 * nd[a] + k]);
                const double len = sqrt(e[ax][0] * e[ax][0] + e[ax][1] * e[ax][1] + e[ax][2] * e[ax][2]);
                *max_edge = fmax(*max_edge, fabs(len / h - 1));
            }
            const double det = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                               e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                               e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
            *min_det = fmin(*min_det, det / (h * h * h));
        }
    }
}

/*
 * A free 3×3×3 block (h 0.1, E 10 kPa, ν 0.3, Rayleigh α 1/s, no gravity) crushed flat (every
 * node projected onto its mid plane z = 0.15: every cell of zero volume), turned inside out
 * (z → 0.3 − z: every cell inverted) or flattened and jittered by ±0.02 m (cells flat,
 * inverted and skewed in a mix), at rest, then released for 600 implicit Euler steps of
 * 1/60 s, for every model. Criteria: every step succeeds, nodes finite; the total energy never
 * exceeds the crushed state's; at the end every corner Jacobian of every cell is positive
 * (> 0.9 h³: the elements recovered) and every cell edge within 5 % of h, the kinetic energy
 * below 1e-6 of the crushed state's energy. The corotational rotation extraction (fem.c,
 * cs_extract_rotation) works on quaternions, so it returns a proper rotation for a reflected
 * cell too, and linear, corotational and localframe recover exactly (measured: det 1, edges
 * to 1e-13). Documented limit of mss: its energy depends on spring lengths only, so a mirror
 * image of a cell has zero energy — the flattened block comes back inside out (det −1,
 * edges exact; the inverted one stays inverted at zero energy), and the flattened one
 * gains energy once (measured 4.2 E0): for mss |det| > 0.9 and E ≤ 10 E0 are asserted.
 */
TEST(stab_crushed_block_recovers)
{
    char err[512];
    for (int mi = 0; mi < 4; mi++)
        for (int inv = 0; inv < 3; inv++) {
            static const char *const how[3] = {"flat", "inverted", "flat+jitter"};
            cs_material mat = cs_material_default();
            mat.young = 1e4;
            mat.damping[0] = 1.0;
            cs_world_def wd = free_world(1.0 / 60);
            wd.cg_tolerance = 1e-8;
            blk b;
            ENSURE_MSG(make_blk(&b, &wd, MODELS[mi], CS_INTEGRATOR_IMPLICIT_EULER, mat, 3, 3, 3,
                                0.1, false, err, sizeof err) == 0, "%s", err);
            cs_object *o = cs_world_find_internal(b.w, b.id);
            for (int i = 0; i < o->n; i++)
                o->x[3 * i + 2] = inv == 1 ? 0.3 - o->x[3 * i + 2] : 0.15;
            o->elastic_energy_valid = false;
            if (inv == 2) /* ±0.02 m in every direction: cells flat, inverted and skewed */
                shake(&b, 0.02, 11);
            const double e0 = energy_of(&b);
            double emax = e0;
            bool ok = true;
            for (int s = 0; s < 600 && ok; s++) {
                ok = cs_world_step(b.w) == CS_OK && all_finite(&b);
                emax = fmax(emax, energy_of(&b));
            }
            double det, edge;
            cell_quality(&b, &det, &edge);
            cs_energy e;
            cs_object_energy(b.w, b.id, &e);
            free_blk(&b);
            printf("    crushed %s %s: E0 %.4g J, max E/E0 %.4f, final kinetic %.3g J, elastic "
                   "%.3g J, min corner det %.4f h^3, max edge change %.3g\n",
                   cs_model_name(MODELS[mi]), how[inv], e0, emax / e0,
                   e.kinetic, e.elastic, det, edge);
            ENSURE_MSG(ok, "%s: a step failed or went non-finite", cs_model_name(MODELS[mi]));
            const bool mss = MODELS[mi] == CS_MODEL_MSS;
            ENSURE_MSG(emax <= e0 * (mss ? 10 : 1 + 1e-9), "%s: energy rose to %g E0",
                       cs_model_name(MODELS[mi]), emax / e0);
            if (mss) /* documented limit: springs cannot tell a cell from its mirror image */
                det = fabs(det);
            ENSURE_MSG(det > 0.9 && edge < 0.05 && e.kinetic < 1e-6 * e0 + 1e-12,
                       "%s %s: not recovered: det %g, edge %g, kinetic %g J",
                       cs_model_name(MODELS[mi]), how[inv], det, edge, e.kinetic);
        }
}

/* ---------------------------------------------------------------- 7. a drag that swings a small piece */

/* Centre of mass (lumped node masses) of b's object. */
static void centre_of_mass(const blk *b, double c[3])
{
    const cs_object *o = cs_world_find_internal(b->w, b->id);
    double m = 0;
    c[0] = c[1] = c[2] = 0;
    for (int i = 0; i < o->n; i++) {
        m += o->m[i];
        for (int a = 0; a < 3; a++)
            c[a] += o->m[i] * o->x[3 * (size_t)i + a];
    }
    for (int a = 0; a < 3; a++)
        c[a] /= m;
}

/*
 * A drag that swings a free body about its centre of mass faster than a step can follow
 * (world.c, centre_fast_springs). The fracture demo's case alone: a 20 N/m drag on a corner
 * of a free one-cube piece of 1.6 g (2.5 cm, E = 2 MPa, ρ = 100 kg/m³), its target 0.7 m
 * away. Before, each step turned the cube by 4–14 rad along its tangents: cells at 200–2000
 * times their volume, nodes at 160 m/s. Now the spring pulls at the centre of mass: over 2 s
 * every cell keeps its shape (corner Jacobians within 10 % of h³, edges within 10 %), and
 * the cube comes to rest with its centre at the target. A 0.4 m beam of the same material
 * pulled at an end corner by a soft spring swings slowly enough to be followed (ω_p dt about
 * 0.2): its spring stays at the corner, which leads the beam's centre.
 */
TEST(stab_drag_swinging_a_small_piece_pulls_it_whole)
{
    char err[256];
    cs_world_def wd = free_world(1.0 / 60);
    cs_material mat = cs_material_default();
    mat.young = 2e6;
    mat.poisson = 0.3;
    mat.density = 100;
    blk b;
    ENSURE_MSG(make_blk(&b, &wd, CS_MODEL_COROTATIONAL, CS_INTEGRATOR_IMPLICIT_EULER, mat, 1, 1,
                        1, 0.025, false, err, sizeof err) == 0, "%s", err);
    const double grab[3] = {0, 0, 0}, target[3] = {0, 0, 0.7};
    ENSURE(cs_world_drag(b.w, b.id, grab, target, 20, 3, err, sizeof err) == CS_OK);
    double worst_det = INFINITY, worst_edge = 0;
    for (int s = 0; s < 120; s++) {
        ENSURE(cs_world_step(b.w) == CS_OK);
        double det, edge;
        cell_quality(&b, &det, &edge);
        worst_det = fmin(worst_det, det);
        worst_edge = fmax(worst_edge, edge);
    }
    const cs_object *o = cs_world_find_internal(b.w, b.id);
    const bool centred = o->n_inputs == 1 && o->inputs[0].centred;
    double c[3], vmax = 0;
    centre_of_mass(&b, c);
    for (int i = 0; i < 3 * o->n; i++)
        vmax = fmax(vmax, fabs(o->v[i]));
    const double miss = sqrt(c[0] * c[0] + c[1] * c[1] + (c[2] - 0.7) * (c[2] - 0.7));
    printf("    one cube: least corner Jacobian %.4f h^3, largest edge change %.4f; centre "
           "%.2g m from the target, %.2g m/s\n", worst_det, worst_edge, miss, vmax);
    free_blk(&b);
    ENSURE(centred);
    ENSURE(worst_det > 0.9 && worst_edge < 0.1);
    ENSURE(miss < 1e-3 && vmax < 1e-2);

    /* the beam: pulled sideways at its end corner (x = 0.4 m) */
    ENSURE_MSG(make_blk(&b, &wd, CS_MODEL_COROTATIONAL, CS_INTEGRATOR_IMPLICIT_EULER, mat, 16, 4,
                        4, 0.025, false, err, sizeof err) == 0, "%s", err);
    double c0[3];
    centre_of_mass(&b, c0);
    const double end[3] = {0.4, 0, 0}, side[3] = {0.4, 0.3, 0};
    ENSURE(cs_world_drag(b.w, b.id, end, side, 2, 3, err, sizeof err) == CS_OK);
    for (int s = 0; s < 20; s++)
        ENSURE(cs_world_step(b.w) == CS_OK);
    o = cs_world_find_internal(b.w, b.id);
    const bool beam_centred = o->n_inputs == 1 && o->inputs[0].centred;
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)o->inputs[0].cell;
    double g = 0; /* the grabbed point's sideways move */
    for (int k = 0; k < 8; k++)
        g += o->inputs[0].w[k] * o->x[3 * (size_t)nd[k] + 1];
    centre_of_mass(&b, c);
    printf("    beam: grabbed corner moved %.3g m sideways, the centre %.3g m\n", g, c[1] - c0[1]);
    free_blk(&b);
    ENSURE(!beam_centred);
    ENSURE(g > 2 * (c[1] - c0[1]) && c[1] - c0[1] > 0);
}
