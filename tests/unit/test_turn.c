/*
 * test_turn.c — turning bodies under implicit Euler keep their shape: a free body's rigid
 * part turns along its rotation (world.c free_body_rotation), and a body the ground holds
 * while it turns gets a second Newton iteration of its step (relinearize_turn). Before
 * session 32 the step moved every node along the tangent of its circle and a turning body
 * stretched by (ω dt)²/2 per step, as long as it turned.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "check.h"
#include "demo_beam.h"
#include "cubesim.h"
#include "lattice.h"
#include "mat3.h"
#include "world_internal.h"

/* A world `wd` holding a 2×2×2 block of 0.1 m cubes of `model`, E young, ρ 1000, stiffness
 * damping beta, its lowest face z0 up, moving at vx and turning at wy about y through its
 * centre. NULL if it cannot be made. */
static cs_world_t *block_world(const cs_world_def *wd, cs_model model, double young,
                               double beta, double z0, double vx, double wy, cs_object **out)
{
    cs_world_t *w = NULL;
    if (cs_world_create(wd, &w, NULL, 0) != CS_OK)
        return NULL;
    int32_t *ijk = cs_box_cells(2, 2, 2);
    cs_object_def d = cs_object_def_default();
    d.name = "b";
    d.model = model;
    d.material.young = young;
    d.material.density = 1000;
    d.material.damping[1] = beta;
    d.cube_size = 0.1;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_origin[2] = z0;
    d.cells_ijk = ijk;
    d.n_cells = 8;
    cs_object_id id;
    char err[256];
    const int rc = cs_world_add_object(w, &d, &id, err, sizeof err);
    free(ijk);
    if (rc != CS_OK) {
        printf("    %s\n", err);
        cs_world_destroy(w);
        return NULL;
    }
    cs_object *o = w->objects[0];
    for (int j = 0; j < o->n; j++) {
        const double rx = o->x[3 * j] - 0.1, rz = o->x[3 * j + 2] - (z0 + 0.1);
        o->v[3 * j] = vx + wy * rz;
        o->v[3 * j + 2] = -wy * rx;
    }
    *out = o;
    return w;
}

/* The same under gravity, on the ground if ground, the scene's defaults, one thread. */
static cs_world_t *turning_block(cs_model model, double young, bool ground, double z0,
                                 double vx, double wy, cs_object **out)
{
    cs_world_def wd = cs_world_def_default();
    wd.has_ground = ground;
    wd.threads = 1;
    return block_world(&wd, model, young, 0, z0, vx, wy, out);
}

/* The largest relative change of length, from rest, of any two nodes of one cube. */
static double max_stretch(const cs_object *o)
{
    double s = 0;
    for (int c = 0; c < o->cm.n_cells; c++) {
        const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
        for (int a = 0; a < 8; a++)
            for (int b = a + 1; b < 8; b++) {
                double l2 = 0, L2 = 0;
                for (int k = 0; k < 3; k++) {
                    const double d = o->x[3 * nd[a] + k] - o->x[3 * nd[b] + k];
                    const double D = o->cm.node_rest[3 * nd[a] + k] - o->cm.node_rest[3 * nd[b] + k];
                    l2 += d * d;
                    L2 += D * D;
                }
                s = fmax(s, fabs(sqrt(l2 / L2) - 1));
            }
    }
    return s;
}

/* Momentum and angular momentum about the centre of mass. */
static void momenta(const cs_object *o, double P[3], double L[3])
{
    double M = 0, c[3] = {0, 0, 0};
    P[0] = P[1] = P[2] = L[0] = L[1] = L[2] = 0;
    for (int i = 0; i < o->n; i++) {
        M += o->m[i];
        for (int a = 0; a < 3; a++) {
            c[a] += o->m[i] * o->x[3 * i + a];
            P[a] += o->m[i] * o->v[3 * i + a];
        }
    }
    for (int a = 0; a < 3; a++)
        c[a] /= M;
    for (int i = 0; i < o->n; i++) {
        const double *x = o->x + 3 * i, *v = o->v + 3 * i, m = o->m[i];
        const double r[3] = {x[0] - c[0], x[1] - c[1], x[2] - c[2]};
        L[0] += m * (r[1] * v[2] - r[2] * v[1]);
        L[1] += m * (r[2] * v[0] - r[0] * v[2]);
        L[2] += m * (r[0] * v[1] - r[1] * v[0]);
    }
}

TEST(turn_spinning_stiff_block_keeps_its_shape)
{
    /* A 1e9 Pa block at 6 rad/s (ω dt = 0.1 at 60 Hz) and 1 m/s, 2 s of free fall. Before: the
     * step's tangents stretched it by 0.93 % for as long as it spun, holding 250 times its
     * kinetic energy of rotation as strain. Now its rigid part turns exactly and its stretch
     * is the centrifugal one, ρ ω² r²/E ≈ 1e-7; momentum gains exactly m g t, angular momentum
     * is kept (what the corotated solve of a strained body moves it by), and the warm start's
     * history turns with the body, so the solves stay cheap (about 2 CG iterations a step;
     * 6–28 with the history left as it was). */
    const cs_model models[3] = {CS_MODEL_COROTATIONAL, CS_MODEL_LOCALFRAME, CS_MODEL_MSS};
    for (int mi = 0; mi < 3; mi++) {
        cs_object *o = NULL;
        cs_world_t *w = turning_block(models[mi], 1e9, false, 100, 1, -6, &o);
        ENSURE(w);
        double P0[3], L0[3], P[3], L[3], mass = 0;
        momenta(o, P0, L0);
        for (int i = 0; i < o->n; i++)
            mass += o->m[i];
        const double g = w->def.gravity[2], dt = w->def.dt, l0 = hypot(L0[0], hypot(L0[1], L0[2]));
        double stretch = 0, dl = 0, dp = 0;
        long its = 0;
        for (int s = 1; s <= 120; s++) {
            ENSURE(cs_world_step(w) == CS_OK);
            its += cs_world_last_stats(w)->cg_iterations;
            stretch = fmax(stretch, max_stretch(o));
            momenta(o, P, L);
            dl = fmax(dl, hypot(L[0] - L0[0], hypot(L[1] - L0[1], L[2] - L0[2])) / l0);
            dp = fmax(dp, hypot(P[0] - P0[0], hypot(P[1] - P0[1], P[2] - P0[2] - mass * g * dt * s)) /
                              hypot(P0[0], P0[2]));
        }
        printf("    %-12s: stretch at most %.2e, |dP| %.1e, |dL| %.1e, %.2f CG iterations a step\n",
               cs_model_name(models[mi]), stretch, dp, dl, its / 120.0);
        ENSURE_MSG(stretch < 1e-6 && dp < 1e-12 && dl < 1e-5, "%s: stretch %g, dP %g, dL %g",
                   cs_model_name(models[mi]), stretch, dp, dl);
        ENSURE_MSG(its <= 3 * 120, "%s: %ld CG iterations in 120 steps", cs_model_name(models[mi]),
                   its);
        cs_world_destroy(w);
    }
}

/* The largest stretch of a free 2×2×2 block of 0.1 m cubes (E young, ρ 1000, β 0.01 s) spun
 * at w rad/s about y, after 3 s at step dt, no gravity, CG to 1e-8. */
static double spun_stretch(double young, double dt, double w_rate)
{
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    wd.dt = dt;
    wd.gravity[2] = 0;
    wd.cg_tolerance = 1e-8;
    cs_object *o = NULL;
    cs_world_t *w = block_world(&wd, CS_MODEL_COROTATIONAL, young, 0.01, 0, 0, w_rate, &o);
    if (!w)
        return NAN;
    for (int s = 0; s < (int)(3.0 / dt + 0.5); s++)
        if (cs_world_step(w) != CS_OK) {
            cs_world_destroy(w);
            return NAN;
        }
    const double st = max_stretch(o);
    cs_world_destroy(w);
    return st;
}

TEST(turn_spinning_soft_block_bulges_as_at_small_steps)
{
    /* A spinning body bulges until its stress gives every point its centripetal acceleration
     * (ρ ω² r²/E of its size): a physical answer that must not depend on the step. The turn
     * gives the rigid part its centripetal acceleration itself, so the solve feels the
     * centrifugal force in its place (turn_centrifugal). At 60 Hz against 1 kHz: 1.2152e-2
     * and 1.2152e-2 at 10 kPa, 1.2553e-3 and 1.2553e-3 at 100 kPa. The tangent steps before
     * gave 1.95e-2 and 9.0e-3 at 60 Hz (1.22e-2 and 1.35e-3 at 2 kHz, converging there);
     * without the centrifugal force the turn left the bodies rigid (1.9e-6). */
    const double youngs[2] = {1e4, 1e5};
    for (int k = 0; k < 2; k++) {
        const double s60 = spun_stretch(youngs[k], 1.0 / 60, 6), s1k = spun_stretch(youngs[k], 1e-3, 6);
        printf("    E %.0e at 6 rad/s: stretch %.4e at 60 Hz, %.4e at 1 kHz\n", youngs[k], s60, s1k);
        ENSURE_MSG(fabs(s60 - s1k) <= 0.02 * s1k && s1k > 0.1 * 1000 * 36 * 0.01 / youngs[k],
                   "E %g: %g at 60 Hz, %g at 1 kHz", youngs[k], s60, s1k);
    }
}

TEST(turn_block_rolling_on_its_edge_keeps_its_shape)
{
    /* Released 5 cm up at 2 m/s and 8 rad/s, a stiff block lands on an edge and rolls over it
     * onto its face. Pivoting on the edge the step's tangents stretched it 0.9 % (40 times its
     * energy as strain, thrown out sideways when its face landed: 0.3 m/s over Coulomb's
     * bound); the second Newton iteration keeps it to the strain of the impacts. */
    cs_object *o = NULL;
    cs_world_t *w = turning_block(CS_MODEL_COROTATIONAL, 1e9, true, 0.05, 2, 8, &o);
    ENSURE(w);
    double stretch = 0;
    int contact_steps = 0;
    for (int s = 0; s < 40; s++) {
        ENSURE(cs_world_step(w) == CS_OK);
        int held = 0;
        for (int i = 0; i < o->n; i++)
            held += o->contact[i] != CS_GROUND_FREE;
        contact_steps += held > 0;
        if (held > 0)
            stretch = fmax(stretch, max_stretch(o));
    }
    printf("    rolled: %d steps on the ground, stretch at most %.2e\n", contact_steps, stretch);
    ENSURE(contact_steps > 20);
    ENSURE_MSG(stretch < 1e-3, "stretched %g on the ground", stretch);
    cs_world_destroy(w);
}

/* The rigid part of velocities v on o's nodes: the centre of mass c, the mean velocity vc and
 * the spin ω = I⁻¹ L about c. */
static void rigid_part(const cs_object *o, const double *v, double c[3], double vc[3],
                       double om[3])
{
    double M = 0, L[3] = {0, 0, 0}, I[9] = {0};
    for (int a = 0; a < 3; a++)
        c[a] = vc[a] = 0;
    for (int i = 0; i < o->n; i++) {
        M += o->m[i];
        for (int a = 0; a < 3; a++) {
            c[a] += o->m[i] * o->x[3 * i + a];
            vc[a] += o->m[i] * v[3 * i + a];
        }
    }
    for (int a = 0; a < 3; a++) {
        c[a] /= M;
        vc[a] /= M;
    }
    for (int i = 0; i < o->n; i++) {
        const double r[3] = {o->x[3 * i] - c[0], o->x[3 * i + 1] - c[1], o->x[3 * i + 2] - c[2]};
        const double u[3] = {v[3 * i] - vc[0], v[3 * i + 1] - vc[1], v[3 * i + 2] - vc[2]};
        const double m = o->m[i], r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        L[0] += m * (r[1] * u[2] - r[2] * u[1]);
        L[1] += m * (r[2] * u[0] - r[0] * u[2]);
        L[2] += m * (r[0] * u[1] - r[1] * u[0]);
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                I[3 * a + b] += m * ((a == b ? r2 : 0.0) - r[a] * r[b]);
    }
    double Ia[9];
    const double det = cs_mat3_adjugate(I, Ia);
    for (int a = 0; a < 3; a++)
        om[a] = (Ia[3 * a] * L[0] + Ia[3 * a + 1] * L[1] + Ia[3 * a + 2] * L[2]) / det;
}

/* The rigid part's turn rate |ω| dt of o's velocities. */
static double turn_rate(const cs_object *o, double dt)
{
    double c[3], vc[3], om[3];
    rigid_part(o, o->v, c, vc, om);
    return dt * sqrt(om[0] * om[0] + om[1] * om[1] + om[2] * om[2]);
}

/* The smallest and largest corner Jacobian det(∂x/∂X) of o's cubes (1 at rest). */
static void corner_jacobians(const cs_object *o, double *jmin, double *jmax)
{
    for (int c = 0; c < o->cm.n_cells; c++) {
        const int32_t *q = o->cm.cell_nodes + 8 * (size_t)c;
        for (int k = 0; k < 8; k++) {
            double e[3][3];
            for (int a = 0; a < 3; a++) {
                int t[3] = {CS_CORNER[k][0], CS_CORNER[k][1], CS_CORNER[k][2]}, nb = -1;
                t[a] = 1 - t[a];
                for (int m = 0; m < 8; m++)
                    if (CS_CORNER[m][0] == t[0] && CS_CORNER[m][1] == t[1] && CS_CORNER[m][2] == t[2])
                        nb = m;
                for (int b = 0; b < 3; b++)
                    e[a][b] = (o->x[3 * q[nb] + b] - o->x[3 * q[k] + b]) * (CS_CORNER[k][a] ? -1 : 1);
            }
            const double det = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                               e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                               e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
            const double J = det / (o->cm.h * o->cm.h * o->cm.h);
            *jmin = fmin(*jmin, J);
            *jmax = fmax(*jmax, J);
        }
    }
}

/* A free piece of the fracture demo's beam material (E 2 MPa, ρ 100, damping 0.5 / 0.002,
 * 2.5 cm cubes), n_cells of the 2×2×2 block, spinning at `spin` rad/s about z through its
 * centre, every node's velocity shaken by up to `shake` m/s (seed: the shake has a mean and a
 * spin of its own); 120 steps at 60 Hz. Reports the
 * corner Jacobians' range over the run, the turn rate after the first step and the largest
 * after any, and the energies at the end. False if it cannot be made or a step fails. */
static bool shaken_spin(int n_cells, double spin, double shake, unsigned seed, double *jmin,
                        double *jmax, double *turn_first, double *turn_after, cs_energy *e)
{
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    cs_world_t *w = NULL;
    if (cs_world_create(&wd, &w, NULL, 0) != CS_OK)
        return false;
    int32_t *ijk = cs_box_cells(2, 2, 2);
    cs_object_def d = cs_object_def_default();
    d.name = "piece";
    demo_beam_material(&d);
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_origin[2] = 1;
    d.cells_ijk = ijk;
    d.n_cells = n_cells;
    cs_object_id id;
    const int rc = cs_world_add_object(w, &d, &id, NULL, 0);
    free(ijk);
    if (rc != CS_OK) {
        cs_world_destroy(w);
        return false;
    }
    cs_object *o = w->objects[0];
    double cx = 0, cy = 0;
    for (int j = 0; j < o->n; j++) {
        cx += o->x[3 * j] / o->n;
        cy += o->x[3 * j + 1] / o->n;
    }
    unsigned r = seed;
    for (int j = 0; j < o->n; j++) {
        for (int a = 0; a < 3; a++) {
            r = r * 1103515245u + 12345u;
            o->v[3 * j + a] = shake * ((double)(r >> 8) / (double)(1u << 24) * 2 - 1);
        }
        o->v[3 * j] -= spin * (o->x[3 * j + 1] - cy);
        o->v[3 * j + 1] += spin * (o->x[3 * j] - cx);
    }
    *jmin = 1;
    *jmax = 1;
    *turn_after = 0;
    bool ok = true;
    for (int s = 0; s < 120 && ok; s++) {
        ok = cs_world_step(w) == CS_OK;
        corner_jacobians(o, jmin, jmax);
        const double t = turn_rate(o, w->def.dt);
        if (s == 0)
            *turn_first = t;
        *turn_after = fmax(*turn_after, t);
    }
    ok = ok && cs_object_energy(w, id, e) == CS_OK;
    cs_world_destroy(w);
    return ok;
}

TEST(turn_violent_piece_spins_no_faster_than_a_step_resolves)
{
    /* A one-cube piece of the fracture demo's beam born spinning at hundreds of rad/s with its
     * nodes flying apart at metres a second (10.9 rad in one step in the demo). Left to its
     * tangent steps x + dt v1 (until session 35) it swelled to 33 times its volume at 300
     * rad/s and 131 times at 650 in its first steps, then the damping took the energy out.
     * Now the rigid part of a spin past CS_TURN_MAX (0.5 rad) a step is slowed to that rate,
     * not stopped, and the piece turns in its shape: corner Jacobians 1 ± 0.01, a turn rate of
     * 0.45–0.505 rad a step after the first step (the turned inertia moves it by under 1 %),
     * never more after, and no strain left at the end (2 s of free fall, no ground). */
    const double spins[2] = {300, 650};
    for (int k = 0; k < 2; k++)
        for (unsigned seed = 1; seed <= 2; seed++) {
            double jmin, jmax, first, turn;
            cs_energy e;
            ENSURE(shaken_spin(1, spins[k], 3.0, seed, &jmin, &jmax, &first, &turn, &e));
            printf("    %.0f rad/s, seed %u: Jacobians %.4f..%.4f, turn %.3f rad after the first "
                   "step, at most %.3f; after 2 s elastic %.2e J\n", spins[k], seed, jmin, jmax,
                   first, turn, e.elastic);
            ENSURE_MSG(jmin > 0.99 && jmax < 1.01, "%.0f rad/s seed %u: Jacobians %g..%g",
                       spins[k], seed, jmin, jmax);
            ENSURE_MSG(first >= 0.45 && turn <= 0.505,
                       "%.0f rad/s seed %u: turned %g rad in the first step, at most %g", spins[k],
                       seed, first, turn);
            ENSURE_MSG(isfinite(e.kinetic) && e.elastic < 1e-6, "%.0f rad/s seed %u: elastic %g J",
                       spins[k], seed, e.elastic);
        }
}

TEST(turn_shaken_spinning_block_keeps_its_shape)
{
    /* A 2×2×2 block of the same material spun at 25 rad/s about z with its nodes shaken by up
     * to 3 m/s: the shake adds a spin of its own about other axes, 0.53–0.90 rad a step in all
     * (seeds 1–4), past the bound. Left to its tangent steps (until session 35) the tumbling
     * block flew at 1.35–2.83 times its volume; slowed to the bound and turned, its corner
     * Jacobians stay within 1 ± 0.05 (5e-4 measured), the turn at most 0.505 rad a step. */
    for (unsigned seed = 1; seed <= 4; seed++) {
        double jmin, jmax, first, turn;
        cs_energy e;
        ENSURE(shaken_spin(8, 25, 3.0, seed, &jmin, &jmax, &first, &turn, &e));
        printf("    seed %u: Jacobians %.4f..%.4f, turn %.3f rad after the first step, at most "
               "%.3f\n", seed, jmin, jmax, first, turn);
        ENSURE_MSG(jmin > 0.95 && jmax < 1.05, "seed %u: Jacobians %g..%g", seed, jmin, jmax);
        ENSURE_MSG(turn <= 0.505, "seed %u: turned %g rad in a step", seed, turn);
    }
}
