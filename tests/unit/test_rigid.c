/*
 * test_rigid.c — rigid bodies (seed 000 §2.4) through the public API, against known answers:
 * the inertia of a box, conservation of momentum, angular momentum and energy in free
 * tumbling about the intermediate axis, an elastic bounce, a settling stack that sleeps, no
 * tunnelling at speed, refusal of bad input, rigid against deformable, and an impact that
 * breaks a brittle body into closed pieces that keep the momentum; and the ground's Coulomb
 * friction on blocks of every model against the rigid body's and Coulomb's answers.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "scene.h"
#include "watertight.h"
#include "world_internal.h"
#include "lattice.h"
#include "contact_probe.h"

/* A box of nx×ny×nz cubes of edge h with its lower corner at `at`. */
static cs_object_id add_box_i(cs_world_t *w, const char *name, int nx, int ny, int nz,
                              double h, const double at[3], cs_material mat, bool fracture,
                              cs_model model, cs_integrator integ, const cs_aabb *fixed, char *err)
{
    int n = nx * ny * nz;
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    cs_object_def d = cs_object_def_default();
    d.name = name;
    d.model = model;
    d.integrator = integ;
    d.material = mat;
    d.cube_size = h;
    d.fracture = fracture;
    d.geometry = CS_GEOMETRY_CELLS;
    memcpy(d.cells_origin, at, sizeof d.cells_origin);
    d.cells_ijk = ijk;
    d.n_cells = n;
    d.fixed = fixed;
    d.n_fixed = fixed ? 1 : 0;
    cs_object_id id = CS_NULL_OBJECT;
    if (cs_world_add_object(w, &d, &id, err, 256) != CS_OK)
        id = CS_NULL_OBJECT;
    free(ijk);
    return id;
}

static cs_object_id add_box(cs_world_t *w, const char *name, int nx, int ny, int nz, double h,
                            const double at[3], cs_material mat, bool fracture, cs_model model,
                            const cs_aabb *fixed, char *err)
{
    return add_box_i(w, name, nx, ny, nz, h, at, mat, fracture, model, CS_INTEGRATOR_DEFAULT,
                     fixed, err);
}

static cs_world_t *world(bool gravity, bool ground)
{
    cs_world_def wd = cs_world_def_default();
    if (!gravity)
        wd.gravity[2] = 0;
    wd.has_ground = ground;
    wd.threads = 1;
    cs_world_t *w = NULL;
    char err[256];
    return cs_world_create(&wd, &w, err, sizeof err) == CS_OK ? w : NULL;
}

static void world_set_broadphase(cs_world_t *w, int min_bodies)
{
    if (w)
        w->broadphase_min_bodies = min_bodies;
}

static double norm3(const double v[3])
{
    return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

/* Give a cube of edge h velocity v without spin: half the impulse at each of two opposite
 * corners (their torques cancel). */
static int kick(cs_world_t *w, cs_object_id id, double h, const double v[3])
{
    cs_rigid_state s;
    cs_object_rigid_state(w, id, &s);
    const double dt = cs_world_get_def(w)->dt;
    double F[3] = {0.5 * s.mass * v[0] / dt, 0.5 * s.mass * v[1] / dt, 0.5 * s.mass * v[2] / dt};
    char err[256];
    int rc = 0;
    for (int sgn = -1; sgn <= 1; sgn += 2) {
        double p[3];
        for (int a = 0; a < 3; a++)
            p[a] = s.position[a] + sgn * 0.5 * h;
        rc |= cs_world_apply_force(w, id, p, F, 0, err, sizeof err);
    }
    return rc;
}

TEST(rigid_inertia_of_a_box)
{
    cs_world_t *w = world(false, false);
    char err[256] = "";
    const double h = 0.1, at[3] = {1, 2, 3};
    cs_material m = cs_material_default(); /* ρ = 1000: 1 kg per cube */
    cs_object_id id = add_box(w, "b", 3, 2, 1, h, at, m, false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    cs_rigid_state s;
    ENSURE(cs_object_rigid_state(w, id, &s) == CS_OK);
    const double M = 6.0, a = 0.3, b = 0.2, c = 0.1;
    ENSURE_NEAR(s.mass, M, 1e-12);
    ENSURE_NEAR(s.position[0], 1.15, 1e-12);
    ENSURE_NEAR(s.position[1], 2.10, 1e-12);
    ENSURE_NEAR(s.position[2], 3.05, 1e-12);
    ENSURE_NEAR(s.inertia[0], M * (b * b + c * c) / 12, 1e-12);
    ENSURE_NEAR(s.inertia[4], M * (a * a + c * c) / 12, 1e-12);
    ENSURE_NEAR(s.inertia[8], M * (a * a + b * b) / 12, 1e-12);
    ENSURE_NEAR(s.inertia[1], 0, 1e-12);
    ENSURE_NEAR(s.inertia[5], 0, 1e-12);
    /* an L of three cubes: products of inertia from the parallel-axis sums */
    const int32_t L[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    cs_object_def d = cs_object_def_default();
    d.name = "L";
    d.model = CS_MODEL_RIGID;
    d.cube_size = 1;
    d.material.density = 1;
    d.cells_ijk = L;
    d.n_cells = 3;
    cs_object_id l = CS_NULL_OBJECT;
    ENSURE_MSG(cs_world_add_object(w, &d, &l, err, sizeof err) == CS_OK, "%s", err);
    ENSURE(cs_object_rigid_state(w, l, &s) == CS_OK);
    /* centres (.5,.5), (1.5,.5), (.5,1.5); COM (5/6, 5/6); Ixy = −Σ m dx dy */
    double ixy = 0, izz = 0;
    const double cx[3] = {0.5, 1.5, 0.5}, cy[3] = {0.5, 0.5, 1.5};
    for (int i = 0; i < 3; i++) {
        const double dx = cx[i] - 5.0 / 6, dy = cy[i] - 5.0 / 6;
        ixy -= dx * dy;
        izz += 1.0 / 6 + dx * dx + dy * dy;
    }
    ENSURE_NEAR(s.inertia[1], ixy, 1e-12);
    ENSURE_NEAR(s.inertia[8], izz, 1e-12);
    ENSURE_NEAR(s.position[0], 5.0 / 6, 1e-12);
    cs_world_destroy(w);
}

TEST(rigid_free_tumbling_conserves_momentum_and_energy)
{
    cs_world_t *w = world(false, false);
    char err[256] = "";
    const double at[3] = {0, 0, 0};
    cs_object_id id = add_box(w, "t", 3, 2, 1, 0.1, at, cs_material_default(), false,
                              CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    /* a torque mostly about y (the intermediate axis: Ix < Iy < Iz) for one step, and a push */
    const double top[3] = {0.1, 0.1, 0.1}, bottom[3] = {0.2, 0.1, 0.0}, side[3] = {0.3, 0.2, 0.05};
    ENSURE(cs_world_apply_force(w, id, top, (double[3]){600, 0, 0}, 0, err, sizeof err) == CS_OK);
    ENSURE(cs_world_apply_force(w, id, bottom, (double[3]){-600, 0, 0}, 0, err, sizeof err) ==
           CS_OK);
    ENSURE(cs_world_apply_force(w, id, side, (double[3]){0, 0, 300}, 0, err, sizeof err) == CS_OK);
    ENSURE(cs_world_step(w) == CS_OK);
    cs_rigid_state s0, s;
    cs_energy e0, e;
    ENSURE(cs_object_rigid_state(w, id, &s0) == CS_OK);
    ENSURE(cs_object_energy(w, id, &e0) == CS_OK);
    const double L0 = norm3(s0.angular_momentum);
    ENSURE_MSG(norm3(s0.angular_velocity) > 1, "spin %g rad/s", norm3(s0.angular_velocity));
    double max_dL = 0, max_dE = 0;
    for (int i = 0; i < 10000; i++) {
        ENSURE(cs_world_step(w) == CS_OK);
        ENSURE(cs_object_rigid_state(w, id, &s) == CS_OK);
        ENSURE(cs_object_energy(w, id, &e) == CS_OK);
        double d[3] = {s.angular_momentum[0] - s0.angular_momentum[0],
                       s.angular_momentum[1] - s0.angular_momentum[1],
                       s.angular_momentum[2] - s0.angular_momentum[2]};
        max_dL = fmax(max_dL, norm3(d) / L0);
        max_dE = fmax(max_dE, fabs(e.kinetic - e0.kinetic) / e0.kinetic);
    }
    printf("    tumbling 10000 steps: max |ΔL|/|L| = %.2e, max |ΔE|/E = %.2e\n", max_dL, max_dE);
    ENSURE_MSG(max_dL < 1e-10, "angular momentum drift %.3g", max_dL);
    ENSURE_MSG(max_dE < 1e-10, "energy drift %.3g", max_dE);
    /* linear momentum: the centre moves uniformly */
    const double t = 10000 * cs_world_get_def(w)->dt;
    for (int a = 0; a < 3; a++) {
        ENSURE_NEAR(s.velocity[a], s0.velocity[a], 1e-12);
        ENSURE_NEAR(s.position[a], s0.position[a] + t * s0.velocity[a], 1e-9);
    }
    ENSURE(fabs(s0.velocity[2]) > 0.1);
    /* the quaternion stays unit */
    double qn = 0;
    for (int a = 0; a < 4; a++)
        qn += s.orientation[a] * s.orientation[a];
    ENSURE_NEAR(qn, 1, 1e-12);
    cs_world_destroy(w);
}

/* Largest distance from the pose-transformed rest nodes to the reported nodes. */
static double node_pose_error(cs_world_t *w, cs_object_id id)
{
    cs_rigid_state s;
    const double *rest, *pos;
    int n;
    cs_object_rigid_state(w, id, &s);
    cs_object_nodes(w, id, &rest, &pos, NULL, &n);
    const double qw = s.orientation[0], x = s.orientation[1], y = s.orientation[2],
                 z = s.orientation[3];
    const double R[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - qw * z), 2 * (x * z + qw * y),
                         2 * (x * y + qw * z), 1 - 2 * (x * x + z * z), 2 * (y * z - qw * x),
                         2 * (x * z - qw * y), 2 * (y * z + qw * x), 1 - 2 * (x * x + y * y)};
    double err = 0;
    for (int i = 0; i < n; i++) {
        double d[3];
        for (int a = 0; a < 3; a++)
            d[a] = rest[3 * i + a] - s.com_rest[a];
        for (int a = 0; a < 3; a++) {
            double p = s.position[a] + R[3 * a] * d[0] + R[3 * a + 1] * d[1] + R[3 * a + 2] * d[2];
            err = fmax(err, fabs(p - pos[3 * i + a]));
        }
    }
    return err;
}

TEST(rigid_nodes_follow_the_pose)
{
    cs_world_t *w = world(true, false);
    char err[256] = "";
    cs_object_id id = add_box(w, "p", 2, 3, 1, 0.1, (double[3]){0, 0, 0},
                              cs_material_default(), false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    ENSURE(cs_world_apply_force(w, id, (double[3]){0, 0, 0.1}, (double[3]){50, 20, 0}, 0, err,
                                sizeof err) == CS_OK);
    for (int i = 0; i < 50; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    ENSURE(node_pose_error(w, id) < 1e-12);
    /* the surface was skinned: its vertex count is the box's, its hash moved */
    const double *v;
    int nv;
    ENSURE(cs_object_surface(w, id, &v, &nv, NULL, NULL) == CS_OK && nv > 0);
    ENSURE(v[2] < -1.0); /* fallen for 50/60 s */
    cs_world_reset(w);
    ENSURE(node_pose_error(w, id) < 1e-15);
    cs_world_destroy(w);
}

TEST(rigid_elastic_bounce_keeps_energy)
{
    cs_world_t *w = world(true, true);
    char err[256] = "";
    cs_material m = cs_material_default();
    m.restitution = 1;
    m.friction = 0;
    cs_object_id id = add_box(w, "ball", 2, 2, 2, 0.1, (double[3]){0, 0, 0.9}, m, false,
                              CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    const double dt = cs_world_get_def(w)->dt;
    cs_energy e;
    cs_object_energy(w, id, &e);
    const double E0 = e.kinetic + e.gravity;
    /* symplectic Euler's energy oscillates by ~m g |v| dt within a flight; at the apexes
     * (v ≈ 0) it is the energy of the flight: compare those. Where a bounce turns: from the
     * frames before (z0, v0 < 0) and after (z1, v1 > 0) it, moving at v0 until the time of
     * impact τ and at v1 after, z0 + v0 τ = z1 − v1 (dt − τ); the turning height is z0 + v0 τ
     * (0 for a bounce at the surface, up to |v0| dt = 7 cm for one taken where it was found). */
    double zmin = 1e9, maxdev = 0, prev_vz = 0, prev_z = 0.9, turn_max = 0;
    int bounces = 0, apexes = 0;
    cs_rigid_state s;
    for (int i = 0; i < 300; i++) {
        ENSURE(cs_world_step(w) == CS_OK);
        cs_object_rigid_state(w, id, &s);
        cs_object_energy(w, id, &e);
        const double z = s.position[2] - 0.1;
        zmin = fmin(zmin, z);
        if (s.velocity[2] > 0 && prev_vz < 0) {
            bounces++;
            const double v0 = prev_vz, v1 = s.velocity[2];
            const double tau = (z - v1 * dt - prev_z) / (v0 - v1);
            turn_max = fmax(turn_max, fabs(prev_z + v0 * tau));
        }
        if (s.velocity[2] <= 0 && prev_vz > 0) {
            apexes++;
            maxdev = fmax(maxdev, fabs(e.kinetic + e.gravity - E0) / E0);
        }
        prev_vz = s.velocity[2];
        prev_z = z;
    }
    printf("    elastic bounce: %d bounces in 5 s, lowest bottom %.4f m, turning %.2e m from "
           "the ground at worst, apex energy within %.2e of the drop's\n",
           bounces, zmin, turn_max, maxdev);
    ENSURE_MSG(bounces >= 2 && apexes >= 2, "%d bounces, %d apexes", bounces, apexes);
    ENSURE_MSG(zmin > -0.005, "sank %.4f m into the ground", -zmin);
    ENSURE_MSG(turn_max < 1e-3, "a bounce turned %.4f m from the ground", turn_max);
    ENSURE_MSG(maxdev < 0.01, "apex energy deviated by %.3g", maxdev);
    /* no spin from a flat landing */
    ENSURE(norm3(s.angular_velocity) < 1e-6);
    cs_world_destroy(w);
}

TEST(rigid_stack_settles_and_sleeps)
{
    cs_world_t *w = world(true, true);
    char err[256] = "";
    cs_material m = cs_material_default();
    m.restitution = 0;
    const int N = 4;
    cs_object_id id[4];
    for (int k = 0; k < N; k++) {
        char name[16];
        snprintf(name, sizeof name, "box%d", k);
        /* 2×2×2 cubes of 0.1 m, 2 mm gaps, a little off-centre */
        id[k] = add_box(w, name, 2, 2, 2, 0.1, (double[3]){0.01 * k, -0.005 * k, 0.002 + 0.202 * k},
                        m, false, CS_MODEL_RIGID, NULL, err);
        ENSURE_MSG(id[k] != CS_NULL_OBJECT, "%s", err);
    }
    cs_rigid_state s;
    int steps = 0;
    bool all_asleep = false;
    for (; steps < 1200 && !all_asleep; steps++) {
        ENSURE(cs_world_step(w) == CS_OK);
        all_asleep = true;
        for (int k = 0; k < N; k++) {
            cs_object_info info;
            cs_object_get_info(w, id[k], &info);
            all_asleep = all_asleep && info.sleeping;
        }
    }
    ENSURE_MSG(all_asleep, "not all asleep after %d steps", steps);
    double p0[4][3];
    for (int k = 0; k < N; k++) {
        cs_object_rigid_state(w, id[k], &s);
        memcpy(p0[k], s.position, sizeof p0[k]);
        /* resting where they should: on each other, not sunk, not tilted */
        ENSURE_MSG(fabs(s.position[2] - (0.1 + 0.2 * k)) < 0.004, "box %d at z = %.4f", k,
                   s.position[2]);
        ENSURE_NEAR(s.position[0], 0.1 + 0.01 * k, 0.002);
        ENSURE_NEAR(s.position[1], 0.1 - 0.005 * k, 0.002);
        ENSURE(fabs(s.orientation[0]) > 1 - 1e-4);
    }
    printf("    4-box stack asleep after %d steps (%.2f s)\n", steps, steps / 60.0);
    for (int i = 0; i < 600; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    for (int k = 0; k < N; k++) {
        cs_object_rigid_state(w, id[k], &s);
        double d[3] = {s.position[0] - p0[k][0], s.position[1] - p0[k][1], s.position[2] - p0[k][2]};
        ENSURE_MSG(norm3(d) < 1e-6, "box %d drifted %.3g m", k, norm3(d));
    }
    /* a touch wakes the top box; it settles again */
    ENSURE(cs_world_apply_force(w, id[N - 1], (double[3]){0.13, 0.09, 0.8}, (double[3]){0, 0, -5}, 0,
                                err, sizeof err) == CS_OK);
    ENSURE(cs_world_step(w) == CS_OK);
    cs_object_info info;
    cs_object_get_info(w, id[N - 1], &info);
    ENSURE(!info.sleeping);
    cs_world_destroy(w);
}

TEST(rigid_no_tunnelling)
{
    cs_world_t *w = world(false, true);
    char err[256] = "";
    /* a fixed rigid wall 5 cm thick and a 5 cm cube thrown at it at 40 m/s: 0.67 m a step */
    const double h = 0.05;
    cs_aabb all = {{-10, -10, -10}, {10, 10, 10}};
    cs_object_id wall = add_box(w, "wall", 1, 20, 20, h, (double[3]){1.0, -0.5, 0}, cs_material_default(),
                                false, CS_MODEL_RIGID, &all, err);
    ENSURE_MSG(wall != CS_NULL_OBJECT, "%s", err);
    cs_object_id bullet = add_box(w, "bullet", 1, 1, 1, h, (double[3]){-1.0, 0, 0.3},
                                  cs_material_default(), false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(bullet != CS_NULL_OBJECT, "%s", err);
    /* and one thrown down at the ground at 60 m/s */
    cs_object_id drop = add_box(w, "drop", 1, 1, 1, h, (double[3]){-3.0, 0, 5},
                                cs_material_default(), false, CS_MODEL_RIGID, NULL, err);
    ENSURE(kick(w, bullet, h, (double[3]){40, 0, 0}) == CS_OK);
    ENSURE(kick(w, drop, h, (double[3]){0, 0, -60}) == CS_OK);
    cs_rigid_state s, d;
    double maxx = -1e9, minz = 1e9;
    for (int i = 0; i < 120; i++) {
        ENSURE(cs_world_step(w) == CS_OK);
        cs_object_rigid_state(w, bullet, &s);
        cs_object_rigid_state(w, drop, &d);
        maxx = fmax(maxx, s.position[0]);
        minz = fmin(minz, d.position[2]);
    }
    printf("    40 m/s into a wall: front reached x = %.4f (wall at 1.0); 60 m/s down: bottom "
           "at z = %.4f\n", maxx + 0.5 * h, minz - 0.5 * h);
    ENSURE_MSG(maxx + 0.5 * h < 1.0 + 0.01 * h + 1e-9, "bullet reached x = %.4f", maxx + 0.5 * h);
    ENSURE(s.velocity[0] <= 0);
    ENSURE_MSG(minz - 0.5 * h > -0.01 * h - 1e-9, "drop reached z = %.4f", minz - 0.5 * h);
    cs_world_destroy(w);
}

TEST(rigid_refuses_bad_input)
{
    cs_world_t *w = world(true, true);
    char err[256] = "";
    cs_material m = cs_material_default();
    m.restitution = 1.5;
    ENSURE(add_box(w, "bad", 1, 1, 1, 0.1, (double[3]){0, 0, 1}, m, false, CS_MODEL_RIGID, NULL,
                   err) == CS_NULL_OBJECT);
    ENSURE_MSG(strstr(err, "restitution"), "%s", err);
    m = cs_material_default();
    m.friction = NAN;
    ENSURE(add_box(w, "bad", 1, 1, 1, 0.1, (double[3]){0, 0, 1}, m, false, CS_MODEL_RIGID, NULL,
                   err) == CS_NULL_OBJECT);
    ENSURE_MSG(strstr(err, "friction"), "%s", err);
    cs_object_id id = add_box(w, "ok", 2, 1, 1, 0.1, (double[3]){0, 0, 1}, cs_material_default(),
                              false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    for (int i = 0; i < 5; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_rigid_state s0, s1;
    cs_object_rigid_state(w, id, &s0);
    const uint64_t h0 = cs_object_state_hash(w, id);
    const double p[3] = {0.1, 0.05, 1.05};
    ENSURE(cs_world_apply_force(w, id, p, (double[3]){NAN, 0, 0}, 0, err, sizeof err) ==
           CS_ERR_INVALID);
    ENSURE(cs_world_apply_force(w, id, p, (double[3]){0, INFINITY, 0}, 0, err, sizeof err) ==
           CS_ERR_INVALID);
    ENSURE(cs_world_apply_force(w, id, p, (double[3]){1e12, 0, 0}, 0, err, sizeof err) ==
           CS_ERR_INVALID);
    ENSURE(cs_world_apply_force(w, id, (double[3]){NAN, 0, 0}, (double[3]){1, 0, 0}, 0, err,
                                sizeof err) == CS_ERR_INVALID);
    ENSURE(cs_world_drag(w, id, p, (double[3]){0, 0, NAN}, 10, 0, err, sizeof err) == CS_ERR_INVALID);
    ENSURE(cs_world_drag(w, id, p, (double[3]){0, 0, 1e9}, 10, 0, err, sizeof err) == CS_ERR_INVALID);
    ENSURE(cs_world_drag(w, id, p, p, -1, 0, err, sizeof err) == CS_ERR_INVALID);
    cs_object_rigid_state(w, id, &s1);
    ENSURE(memcmp(&s0, &s1, sizeof s0) == 0);
    ENSURE(cs_object_state_hash(w, id) == h0);
    ENSURE(cs_object_rigid_state(w, 999, &s1) == CS_ERR_UNKNOWN_OBJECT);
    /* a strong drag is integrated implicitly: stiff springs stay bounded */
    ENSURE(cs_world_drag(w, id, p, (double[3]){0.1, 0.05, 2.0}, 1e6, 1.0, err, sizeof err) ==
           CS_OK);
    for (int i = 0; i < 60; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_object_rigid_state(w, id, &s1);
    ENSURE_MSG(fabs(s1.position[2] - 2.0) < 0.1 && norm3(s1.velocity) < 5,
               "dragged body at z = %.3f, speed %.3f", s1.position[2], norm3(s1.velocity));
    cs_world_destroy(w);
}

/* A soft block (4×4×2 cubes of 0.1 m, E 1e5 Pa, mass damping 1/s) resting on the ground and
 * a rigid box (3×3×1 cubes of 0.1 m over x, y in [0.05, 0.35]: nine block nodes under it, as
 * contact is deformable nodes against rigid cubes and the box's corners against the block's
 * cells) dropped on it from 0.2 m above. Returns false (err) if either is refused. */
static bool box_on_soft_block(cs_world_t *w, cs_object_id *block, cs_object_id *box, char *err)
{
    cs_material soft = cs_material_default();
    soft.young = 1e5;
    soft.damping[0] = 1;
    *block = add_box(w, "soft", 4, 4, 2, 0.1, (double[3]){0, 0, 0}, soft, false,
                     CS_MODEL_COROTATIONAL, NULL, err);
    *box = add_box(w, "rigid", 3, 3, 1, 0.1, (double[3]){0.05, 0.05, 0.4}, cs_material_default(),
                   false, CS_MODEL_RIGID, NULL, err);
    return *block != CS_NULL_OBJECT && *box != CS_NULL_OBJECT;
}

TEST(rigid_against_deformable)
{
    cs_world_t *w = world(true, true);
    char err[256] = "";
    cs_object_id block, box;
    ENSURE_MSG(box_on_soft_block(w, &block, &box, err), "%s", err);
    cs_rigid_state s;
    double zmin = 1e9;
    int asleep_at = -1, block_asleep_at = -1;
    for (int i = 0; i < 300; i++) {
        ENSURE(cs_world_step(w) == CS_OK);
        cs_object_rigid_state(w, box, &s);
        zmin = fmin(zmin, s.position[2] - 0.05);
        cs_object_info info;
        cs_object_get_info(w, box, &info);
        if (info.sleeping && asleep_at < 0)
            asleep_at = i;
        cs_object_get_info(w, block, &info);
        if (info.sleeping && block_asleep_at < 0)
            block_asleep_at = i;
    }
    const double *x;
    int n;
    cs_object_nodes(w, block, NULL, &x, NULL, &n);
    /* the block's top nodes under the box */
    double top = -1e9;
    for (int i = 0; i < n; i++)
        if (x[3 * i] > 0.06 && x[3 * i] < 0.34 && x[3 * i + 1] > 0.06 && x[3 * i + 1] < 0.34)
            top = fmax(top, x[3 * i + 2]);
    const double bottom = s.position[2] - 0.05;
    printf("    rigid box on a soft block: box bottom %.4f m (lowest %.4f), block top under it "
           "%.4f m (rest 0.2): %.3f h inside, asleep after %d steps (the block after %d)\n",
           bottom, zmin, top, (top - bottom) / 0.1, asleep_at, block_asleep_at);
    /* it rests on the block, not on the ground, pressing it down a little; the box's corners
     * take part in the contact solve against the block's faces (two-way), so the block's
     * nodes stay within 0.05 h of the box's bottom (they were up to h/8 inside when only the
     * block's nodes were pushed out), and the box falls asleep */
    ENSURE_MSG(bottom > 0.15 && zmin > 0.1, "box sank to %.4f (lowest %.4f)", bottom, zmin);
    ENSURE_MSG(top - bottom < 0.05 * 0.1, "block nodes %.4f m inside the box", top - bottom);
    ENSURE_MSG(asleep_at >= 0, "the box did not fall asleep (v %.3g %.3g %.3g w %.3g %.3g %.3g)", s.velocity[0], s.velocity[1], s.velocity[2], s.angular_velocity[0], s.angular_velocity[1], s.angular_velocity[2]);
    ENSURE(fabs(s.velocity[2]) < 0.05);
    /* a box at rest on the block does not keep the block awake: once the block's own nodes are
     * still it sleeps too (it never did: the resting contact reset its count every step) */
    ENSURE_MSG(block_asleep_at >= 0, "the block under the sleeping box never fell asleep");
    cs_world_destroy(w);
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The same box resting on the same soft block with sleeping off: the block's fastest node, step
 * by step. The box's corners press on the block's top face cells at face points shared by four
 * nodes, among them the block's top corners; friction there was solved against a local response
 * model stiffer than the corner nodes are, and alternated in sign every step, growing until the
 * top corners swung at 0.05 m/s. At rest the block's nodes are still (median of the fastest node
 * over steps 100–300; a rare single-step kick is not what this measures). */
TEST(rigid_box_on_soft_block_without_friction_chatter)
{
    cs_world_t *w = world(true, true);
    ENSURE(w != NULL);
    w->def.sleep_steps = 0;
    char err[256] = "";
    cs_object_id block, box;
    ENSURE_MSG(box_on_soft_block(w, &block, &box, err), "%s", err);
    double vmax[200], *prev = NULL;
    for (int i = 0; i < 301; i++) {
        ENSURE(cs_world_step(w) == CS_OK);
        const double *x;
        int n;
        cs_object_nodes(w, block, NULL, &x, NULL, &n);
        if (!prev) {
            prev = malloc(3 * (size_t)n * sizeof *prev);
            ENSURE(prev != NULL);
        } else if (i > 100) {
            /* how far the nodes moved in the step (their velocities between steps hold the
             * contact impulses the next step shares out, not motion) */
            double m = 0;
            for (int k = 0; k < 3 * n; k += 3) {
                const double d[3] = {x[k] - prev[k], x[k + 1] - prev[k + 1], x[k + 2] - prev[k + 2]};
                m = fmax(m, norm3(d) / w->def.dt);
            }
            vmax[i - 101] = m;
        }
        memcpy(prev, x, 3 * (size_t)n * sizeof *prev);
    }
    free(prev);
    qsort(vmax, 200, sizeof vmax[0], cmp_double);
    cs_rigid_state s;
    cs_object_rigid_state(w, box, &s);
    printf("    box on a soft block, no sleeping: the block's fastest node over steps 100-300: "
           "median %.2e m/s (from how far they moved), 90th percentile %.2e, max %.2e; box bottom %.4f m\n",
           vmax[100], vmax[180], vmax[199], s.position[2] - 0.05);
    ENSURE_MSG(vmax[100] < 1e-3, "the block's nodes swing at %.3g m/s (median)", vmax[100]);
    ENSURE(s.position[2] - 0.05 > 0.15);
    cs_world_destroy(w);
}

TEST(rigid_impact_breaks_into_closed_pieces)
{
    cs_world_t *w = world(true, true);
    char err[256] = "";
    cs_material m = cs_material_default();
    m.young = 1e6;
    m.strength = 2e3;
    m.restitution = 0.1;
    const double h = 0.05;
    cs_object_id id = add_box(w, "brittle", 8, 2, 2, h, (double[3]){0, 0, 1.0}, m, true,
                              CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    /* tilted: lands on one end */
    ENSURE(cs_world_apply_force(w, id, (double[3]){0.4, 0.05, 1.1}, (double[3]){0, 0, 30}, 0, err,
                                sizeof err) == CS_OK);
    cs_object_info info;
    cs_object_get_info(w, id, &info);
    const double volume = info.volume, mass0 = info.mass;
    int broke_at = -1;
    double p_before[3] = {0, 0, 0};
    for (int i = 0; i < 120 && broke_at < 0; i++) {
        cs_rigid_state s;
        cs_object_rigid_state(w, id, &s);
        ENSURE(cs_world_step(w) == CS_OK);
        int ne = 0;
        const cs_event *ev = cs_world_events(w, &ne);
        (void)ev;
        if (cs_world_object_ids(w, NULL, 0) > 1) {
            broke_at = i;
            /* the impact's static solve is bounded (one body broke: at most 100 PCG
             * iterations; the step's deformable objects: none) and did its work */
            const cs_step_stats *st = cs_world_last_stats(w);
            printf("    impact solve: %d PCG iterations, residual %.1e\n", st->cg_iterations,
                   st->cg_residual);
            ENSURE_MSG(st->cg_iterations > 0 && st->cg_iterations <= 100, "%d iterations",
                       st->cg_iterations);
            for (int a = 0; a < 3; a++)
                p_before[a] = s.mass * s.velocity[a];
        }
    }
    ENSURE_MSG(broke_at >= 0, "nothing broke");
    cs_object_id ids[256];
    const int no = cs_world_object_ids(w, ids, 256);
    printf("    brittle bar broke at step %d into %d pieces\n", broke_at, no);
    cs_piece_view pv[256];
    double mass = 0, p[3] = {0, 0, 0};
    for (int i = 0; i < no; i++) {
        cs_object_surface(w, ids[i], &pv[i].v, &pv[i].nv, &pv[i].t, &pv[i].nt);
        pv[i].name = NULL;
        cs_rigid_state s;
        ENSURE(cs_object_rigid_state(w, ids[i], &s) == CS_OK);
        ENSURE(node_pose_error(w, ids[i]) < 1e-9);
        mass += s.mass;
        for (int a = 0; a < 3; a++)
            p[a] += s.mass * s.velocity[a];
    }
    char why[256] = "";
    ENSURE_MSG(cs_check_pieces(pv, no, volume, 1e-6, NULL, why, sizeof why), "%s", why);
    ENSURE_NEAR(mass, mass0, 1e-9 * mass0);
    (void)p_before;
    /* the pieces fly on: a few more steps without error, everything finite */
    for (int i = 0; i < 60; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_world_destroy(w);
}

/* Σ m v and Σ (I ω + m c × v) (about the origin) over every object. */
static void world_momentum(cs_world_t *w, double p[3], double L[3], double *mass)
{
    cs_object_id ids[256];
    const int no = cs_world_object_ids(w, ids, 256);
    p[0] = p[1] = p[2] = L[0] = L[1] = L[2] = *mass = 0;
    for (int i = 0; i < no; i++) {
        cs_rigid_state s;
        if (cs_object_rigid_state(w, ids[i], &s) != CS_OK)
            continue;
        const double *c = s.position, *v = s.velocity;
        const double cxv[3] = {c[1] * v[2] - c[2] * v[1], c[2] * v[0] - c[0] * v[2],
                               c[0] * v[1] - c[1] * v[0]};
        *mass += s.mass;
        for (int a = 0; a < 3; a++) {
            p[a] += s.mass * v[a];
            L[a] += s.angular_momentum[a] + s.mass * cxv[a];
        }
    }
}

TEST(rigid_pieces_inherit_momentum)
{
    cs_world_t *w = world(false, false);
    char err[256] = "";
    cs_object_id id = add_box(w, "spinner", 6, 2, 2, 0.05, (double[3]){0, 0, 0},
                              cs_material_default(), false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    ENSURE(cs_world_apply_force(w, id, (double[3]){0.3, 0.1, 0.1}, (double[3]){0, 30, 5}, 0, err,
                                sizeof err) == CS_OK);
    ENSURE(cs_world_apply_force(w, id, (double[3]){0, 0, 0}, (double[3]){3, -10, 0}, 0, err,
                                sizeof err) == CS_OK);
    for (int i = 0; i < 10; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    double p0[3], L0[3], m0, p1[3], L1[3], m1;
    world_momentum(w, p0, L0, &m0);
    cs_rigid_state s;
    ENSURE(cs_object_rigid_state(w, id, &s) == CS_OK);
    ENSURE(norm3(s.angular_velocity) > 0.5);
    /* through the middle, across the whole bar */
    ENSURE_MSG(cs_world_fracture(w, id, s.position, (double[3]){1, 0, 0}, 1.0, err, sizeof err) ==
                   CS_OK, "%s", err);
    const int no = cs_world_object_ids(w, NULL, 0);
    ENSURE_MSG(no >= 2, "%d objects after the fracture", no);
    world_momentum(w, p1, L1, &m1);
    ENSURE_NEAR(m1, m0, 1e-12 * m0);
    for (int a = 0; a < 3; a++) {
        ENSURE_NEAR(p1[a], p0[a], 1e-12 * (norm3(p0) + 1));
        ENSURE_NEAR(L1[a], L0[a], 1e-12 * (norm3(L0) + 1));
    }
    cs_object_id ids[16];
    const int n = cs_world_object_ids(w, ids, 16);
    for (int i = 0; i < n; i++)
        ENSURE(node_pose_error(w, ids[i]) < 1e-12);
    /* the pieces fly on, touching each other: contacts are equal and opposite impulses */
    for (int i = 0; i < 120; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    world_momentum(w, p1, L1, &m1);
    printf("    %d pieces: momentum kept to %.1e, angular momentum to %.1e after 2 s\n", n,
           fmax(fabs(p1[0] - p0[0]), fmax(fabs(p1[1] - p0[1]), fabs(p1[2] - p0[2]))),
           fmax(fabs(L1[0] - L0[0]), fmax(fabs(L1[1] - L0[1]), fabs(L1[2] - L0[2]))));
    for (int a = 0; a < 3; a++) {
        ENSURE_NEAR(p1[a], p0[a], 1e-9 * (norm3(p0) + 1));
        ENSURE_NEAR(L1[a], L0[a], 1e-9 * (norm3(L0) + 1));
    }
    cs_world_destroy(w);
}

TEST(rigid_scene_materials)
{
    const char *ok = "{\"materials\": {\"stone\": {\"restitution\": 0.7, \"friction\": 0.9}},"
                     " \"objects\": [{\"name\": \"s\", \"model\": \"rigid\", \"material\": \"stone\","
                     " \"box\": {\"min\": [0, 0, 0], \"size\": [0.2, 0.1, 0.1]}}]}";
    cs_scene sc;
    char err[256] = "";
    ENSURE_MSG(cs_scene_parse(ok, ".", &sc, err, sizeof err) == 0, "%s", err);
    ENSURE(sc.n_objects == 1 && sc.objects[0].model == CS_MODEL_RIGID);
    ENSURE_NEAR(sc.objects[0].material.restitution, 0.7, 0);
    ENSURE_NEAR(sc.objects[0].material.friction, 0.9, 0);
    cs_world_t *w = NULL;
    ENSURE_MSG(cs_scene_instantiate(&sc, &w, err, sizeof err) == 0, "%s", err);
    cs_world_destroy(w);
    cs_scene_free(&sc);
    const char *bad = "{\"materials\": {\"stone\": {\"restitution\": 1.5}}, \"objects\": []}";
    ENSURE(cs_scene_parse(bad, ".", &sc, err, sizeof err) != 0);
    ENSURE_MSG(strstr(err, "restitution"), "%s", err);
    const char *bad2 = "{\"materials\": {\"stone\": {\"friction\": -1}}, \"objects\": []}";
    ENSURE(cs_scene_parse(bad2, ".", &sc, err, sizeof err) != 0);
    ENSURE_MSG(strstr(err, "friction"), "%s", err);
}

TEST(rigid_scene_loads_push_and_turn)
{
    cs_world_t *w = world(false, false);
    char err[256] = "";
    /* a 4×1×1 bar with a constant load of 2 N (+y) on its x = 0.4 end face: a = F/m, and a
     * torque 0.2 m · 2 N about z through the centre */
    const int32_t ijk[12] = {0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0};
    cs_load load = {.box = {{0.39, -1, -1}, {0.41, 1, 1}}, .force = {0, 2, 0}};
    cs_object_def d = cs_object_def_default();
    d.name = "bar";
    d.model = CS_MODEL_RIGID;
    d.cells_ijk = ijk;
    d.n_cells = 4;
    d.loads = &load;
    d.n_loads = 1;
    cs_object_id id;
    ENSURE_MSG(cs_world_add_object(w, &d, &id, err, sizeof err) == CS_OK, "%s", err);
    ENSURE(cs_world_step(w) == CS_OK);
    cs_rigid_state s;
    cs_object_rigid_state(w, id, &s);
    const double dt = cs_world_get_def(w)->dt, m = 4, Izz = m * (0.16 + 0.01) / 12;
    ENSURE_NEAR(s.velocity[1], 2 / m * dt, 1e-12);
    ENSURE_NEAR(s.angular_velocity[2], 0.2 * 2 / Izz * dt, 1e-9);
    cs_world_destroy(w);
}

TEST(rigid_pressure_has_no_net_effect)
{
    /* a uniform pressure on a closed surface: no net force or torque on a rigid body */
    cs_world_t *w = world(false, false);
    char err[256] = "";
    cs_object_id id = add_box(w, "p", 2, 2, 1, 0.1, (double[3]){0, 0, 0}, cs_material_default(),
                              false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(id != CS_NULL_OBJECT, "%s", err);
    ENSURE_MSG(cs_world_pressure(w, id, 500, 0.5, err, sizeof err) == CS_OK, "%s", err);
    for (int i = 0; i < 40; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_rigid_state s;
    cs_object_rigid_state(w, id, &s);
    ENSURE(norm3(s.velocity) == 0 && norm3(s.angular_velocity) == 0);
    ENSURE(node_pose_error(w, id) < 1e-15);
    cs_world_destroy(w);
}

TEST(rigid_sleeping_body_takes_momentum)
{
    /* a box sliding on frictionless ground into a sleeping box of the same mass: the
     * sleeper wakes before the collision is solved, so momentum passes on (inelastic: both
     * go on at half the speed) instead of the mover bouncing off a momentarily fixed wall */
    cs_world_t *w = world(true, true);
    char err[256] = "";
    cs_material m = cs_material_default();
    m.friction = 0;
    m.restitution = 0;
    cs_object_id a = add_box(w, "a", 2, 2, 2, 0.1, (double[3]){0, 0, 0}, m, false,
                             CS_MODEL_RIGID, NULL, err);
    cs_object_id b = add_box(w, "b", 2, 2, 2, 0.1, (double[3]){0.99, 0, 0}, m, false,
                             CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(a != CS_NULL_OBJECT && b != CS_NULL_OBJECT, "%s", err);
    cs_object_info info;
    for (int i = 0; i < 120; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_object_get_info(w, b, &info);
    ENSURE_MSG(info.sleeping, "the target box should be asleep");
    /* 2 m/s along +x: half the impulse at each of two corners level with the centre */
    const double dt = cs_world_get_def(w)->dt, F = 8 * 2.0 / dt / 2;
    ENSURE(cs_world_apply_force(w, a, (double[3]){0, 0, 0.1}, (double[3]){F, 0, 0}, 0, err,
                                sizeof err) == CS_OK);
    ENSURE(cs_world_apply_force(w, a, (double[3]){0, 0.2, 0.1}, (double[3]){F, 0, 0}, 0, err,
                                sizeof err) == CS_OK);
    ENSURE(cs_world_step(w) == CS_OK);
    cs_rigid_state sa, sb;
    cs_object_rigid_state(w, a, &sa);
    const double p0 = sa.mass * sa.velocity[0];
    ENSURE_NEAR(sa.velocity[0], 2.0, 1e-6);
    for (int i = 0; i < 60; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_object_rigid_state(w, a, &sa);
    cs_object_rigid_state(w, b, &sb);
    const double p1 = sa.mass * sa.velocity[0] + sb.mass * sb.velocity[0];
    printf("    after the hit: v_a = %.4f, v_b = %.4f m/s (momentum %.6f of %.6f)\n",
           sa.velocity[0], sb.velocity[0], p1, p0);
    ENSURE_NEAR(p1, p0, 1e-3 * p0);
    ENSURE_NEAR(sb.velocity[0], 1.0, 0.05);
    ENSURE_NEAR(sa.velocity[0], 1.0, 0.05);
    cs_world_destroy(w);
}

/* A rigid cube smaller than the deformable block's cells, dropped on the middle of a cell's
 * top face: no block node lies under it, so only its own corners inside the block's cells
 * can hold it (before those were tested it fell through to the ground). It must rest on the
 * face, its corners at most 0.05·h (block cells) below the face under them, push the block
 * down (the equal and opposite impulse), and fall asleep. */
TEST(rigid_corner_on_deformable_face)
{
    cs_world_t *w = world(true, true);
    char err[256] = "";
    const double H = 0.1, hr = 0.05;
    cs_material soft = cs_material_default();
    soft.young = 1e5;
    soft.damping[0] = 1;
    cs_object_id block = add_box(w, "soft", 4, 4, 2, H, (double[3]){0, 0, 0}, soft, false,
                                 CS_MODEL_COROTATIONAL, NULL, err);
    ENSURE_MSG(block != CS_NULL_OBJECT, "%s", err);
    cs_material hard = cs_material_default();
    hard.density = 4000;
    cs_object_id box = add_box(w, "pebble", 1, 1, 1, hr, (double[3]){0.125, 0.125, 0.3}, hard,
                               false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(box != CS_NULL_OBJECT, "%s", err);
    cs_rigid_state s;
    double zmin = 1e9, pen = 0, top_min = 1e9, far_top = 0;
    bool asleep = false;
    int steps = 0;
    for (; steps < 600 && !asleep; steps++) {
        ENSURE(cs_world_step(w) == CS_OK);
        cs_object_rigid_state(w, box, &s);
        const double bottom = s.position[2] - 0.5 * hr;
        zmin = fmin(zmin, bottom);
        /* the block's top face under the pebble: bilinear in the top nodes of its cell */
        const double *x;
        int n;
        cs_object_nodes(w, block, NULL, &x, NULL, &n);
        double top = 0, far = 0;
        int nt = 0, nf = 0;
        for (int i = 0; i < n; i++)
            if (x[3 * i + 2] > 0.15 && x[3 * i] > 0.05 && x[3 * i] < 0.25 && x[3 * i + 1] > 0.05 &&
                x[3 * i + 1] < 0.25) {
                top += x[3 * i + 2];
                nt++;
            } else if (x[3 * i + 2] > 0.15 && x[3 * i] > 0.25 && x[3 * i + 1] > 0.25) {
                far += x[3 * i + 2]; /* the top nodes of the cells away from it */
                nf++;
            }
        far_top = far / nf;
        ENSURE_MSG(nt == 4, "step %d: %d top nodes, pebble at %g %g %g", steps, nt, s.position[0], s.position[1], s.position[2]);
        top /= nt;
        top_min = fmin(top_min, top);
        pen = top - bottom; /* at the end */
        cs_object_info info;
        cs_object_get_info(w, box, &info);
        asleep = info.sleeping;
    }
    printf("    rigid pebble (h/2) on a soft cell face: bottom %.4f m (lowest %.4f), at rest "
           "%.2e m = %.3f h below the face, face down to %.4f (%.4f elsewhere), asleep after "
           "%d steps\n", s.position[2] - 0.5 * hr, zmin, pen, pen / H, top_min, far_top, steps);
    ENSURE_MSG(zmin > 0.15, "the pebble went into the block to %.4f", zmin);
    ENSURE_MSG(pen < 0.05 * H, "pebble %.4f m inside the face", pen);
    /* the pebble's weight is on the block: the face under it is lower than the others */
    ENSURE_MSG(top_min < far_top - 2e-4, "the block was not pushed (top %.6f, elsewhere %.6f)",
               top_min, far_top);
    ENSURE_MSG(asleep, "pebble still awake after %d steps", steps);
    cs_world_destroy(w);
}

/* The broad phase of rigid–deformable contacts (rigid.c, grid_build): a soft slab on the
 * ground under nine boxes dropped from 5 to 45 mm, 90 steps. The grid path
 * (every deformable object filed in buckets) and the plain loop (every cell and node against
 * every body) must give the same contacts in the same order: every node and pose equal to the
 * last bit. And the boxes rest on the slab, not in it or on the ground. */
static int slab_and_boxes(int min_bodies, double *out, int cap, int *n_out, double *lowest)
{
    cs_world_t *w = world(true, true);
    world_set_broadphase(w, min_bodies);
    char err[256] = "";
    cs_material soft = cs_material_default();
    soft.young = 2e5;
    soft.damping[0] = 1;
    cs_object_id slab = add_box(w, "slab", 12, 12, 2, 0.05, (double[3]){0, 0, 0}, soft, false,
                                CS_MODEL_COROTATIONAL, NULL, err);
    if (slab == CS_NULL_OBJECT)
        return -1;
    cs_object_id ids[9];
    for (int b = 0; b < 9; b++) {
        char name[16];
        snprintf(name, sizeof name, "box%d", b);
        const double at[3] = {0.04 + 0.2 * (b % 3), 0.06 + 0.19 * (b / 3), 0.105 + 0.005 * b};
        ids[b] = add_box(w, name, 2, 2, 2, 0.04, at, cs_material_default(), false,
                         CS_MODEL_RIGID, NULL, err);
        if (ids[b] == CS_NULL_OBJECT)
            return -1;
    }
    for (int i = 0; i < 90; i++)
        if (cs_world_step(w) != CS_OK)
            return -1;
    int n = 0;
    const double *x;
    int nn;
    cs_object_nodes(w, slab, NULL, &x, NULL, &nn);
    for (int i = 0; i < 3 * nn && n < cap; i++)
        out[n++] = x[i];
    *lowest = 1e9;
    for (int b = 0; b < 9; b++) {
        cs_object_nodes(w, ids[b], NULL, &x, NULL, &nn);
        for (int i = 0; i < nn; i++) {
            for (int a = 0; a < 3 && n < cap; a++)
                out[n++] = x[3 * i + a];
            *lowest = fmin(*lowest, x[3 * i + 2]);
        }
    }
    *n_out = n;
    cs_world_destroy(w);
    return 0;
}

TEST(rigid_deformable_broad_phase_equals_plain_loop)
{
    enum { CAP = 20000 };
    double *a = malloc(CAP * sizeof *a), *b = malloc(CAP * sizeof *b), low_a, low_b;
    int na = 0, nb = 0;
    ENSURE(a && b);
    ENSURE(slab_and_boxes(1 << 30, a, CAP, &na, &low_a) == 0);
    ENSURE(slab_and_boxes(0, b, CAP, &nb, &low_b) == 0);
    ENSURE(na == nb && na > 1000);
    int differ = 0;
    for (int i = 0; i < na; i++)
        differ += a[i] != b[i];
    printf("    slab under 9 boxes, 90 steps: %d of %d coordinates differ between the "
           "grid and the plain loop; lowest box node %.4f m (slab top 0.1)\n", differ, na, low_b);
    ENSURE_MSG(differ == 0, "%d coordinates differ", differ);
    /* resting on the slab (top at 0.1 m, pressed in a little), not through it */
    ENSURE_MSG(low_b > 0.1 - 0.01 && low_b < 0.1 + 0.005, "lowest box node at %.4f m", low_b);
    free(a);
    free(b);
}

/* An object asleep on another that is then dragged away, for each pairing of rigid and soft
 * (corotational, E 1e5 Pa, mass damping 1/s): the lower one 4×4×2 cubes of 0.1 m on the ground,
 * the upper 2×2×2 dropped on it from 0.05 m, half a cube in from its edges. Once both sleep, 600 N pulls the lower one along x
 * for 0.5 s (it slides ~3 m); 150 steps later the upper one should lie on the ground. Until
 * session 22 only contacts woke a sleeper, and only where they pushed: an object whose support
 * left stayed asleep in the air; soft objects resting on each other never slept (every push
 * restarted both counts); and a rigid box pushed with a sleeping rigid box on it did not move
 * (the sleeper held it as a wall). Woken, the pair should move as it does when nothing sleeps:
 * the lower one as far, and the upper one, while it rides (RIDE_STEPS into the pull), where
 * it does then; until session 24 the step after waking lost the load of what rested on the
 * lower one (world.c, wake_velocity), a box on a soft block was 5 cm behind by then and landed
 * 0.9 m away. Where it lands after tumbling off is not compared: runs that differ by their
 * settling alone (0.2 mm) land up to 0.2 m apart. sleep_at: steps until both slept (−1: not
 * within 400). */
#define RIDE_STEPS 20
typedef struct pulled_result {
    int sleep_at;
    double low_z, centre[2], lower_dx, ride[2];
} pulled_result;

/* The upper object's mean node (x, y). */
static void upper_centre(const cs_world_t *w, cs_object_id up, double c[2])
{
    const double *x;
    int n;
    cs_object_nodes(w, up, NULL, &x, NULL, &n);
    c[0] = c[1] = 0;
    for (int i = 0; i < n; i++) {
        c[0] += x[3 * i] / n;
        c[1] += x[3 * i + 1] / n;
    }
}

static bool support_pulled(bool lower_rigid, bool upper_rigid, bool sleep, pulled_result *r)
{
    cs_world_t *w = world(true, true);
    if (!w)
        return false;
    if (!sleep)
        w->def.sleep_steps = 0;
    char err[256] = "";
    cs_material soft = cs_material_default();
    soft.young = 1e5;
    soft.damping[0] = 1;
    const cs_material rigid = cs_material_default();
    const cs_object_id low =
        add_box(w, "lower", 4, 4, 2, 0.1, (double[3]){0, 0, 0}, lower_rigid ? rigid : soft,
                false, lower_rigid ? CS_MODEL_RIGID : CS_MODEL_COROTATIONAL, NULL, err);
    const cs_object_id up =
        add_box(w, "upper", 2, 2, 2, 0.1, (double[3]){0.05, 0.05, 0.25}, upper_rigid ? rigid : soft,
                false, upper_rigid ? CS_MODEL_RIGID : CS_MODEL_COROTATIONAL, NULL, err);
    bool ok = low != CS_NULL_OBJECT && up != CS_NULL_OBJECT;
    r->sleep_at = -1;
    for (int i = 0; i < 400 && ok && r->sleep_at < 0; i++) {
        ok = cs_world_step(w) == CS_OK;
        cs_object_info a, b;
        cs_object_get_info(w, low, &a);
        cs_object_get_info(w, up, &b);
        if (a.sleeping && b.sleeping)
            r->sleep_at = i + 1;
        if (!sleep && i == 199)
            break; /* the same state, give or take its settling */
    }
    const double *x;
    int n;
    cs_object_nodes(w, low, NULL, &x, NULL, &n);
    const double x0 = x[0];
    ok = ok && cs_world_apply_force(w, low, (double[3]){0.2, 0.2, 0.1}, (double[3]){600, 0, 0},
                                    0.5, err, sizeof err) == CS_OK;
    for (int i = 0; i < 150 && ok; i++) {
        ok = cs_world_step(w) == CS_OK;
        if (i == RIDE_STEPS - 1)
            upper_centre(w, up, r->ride);
    }
    cs_object_nodes(w, low, NULL, &x, NULL, &n);
    r->lower_dx = x[0] - x0;
    cs_object_nodes(w, up, NULL, &x, NULL, &n);
    r->low_z = INFINITY;
    for (int i = 0; i < n; i++)
        r->low_z = fmin(r->low_z, x[3 * i + 2]);
    upper_centre(w, up, r->centre);
    cs_world_destroy(w);
    return ok;
}

TEST(rigid_sleeper_wakes_when_its_support_is_pulled_away)
{
    for (int k = 0; k < 4; k++) {
        const bool lower_rigid = k & 1, upper_rigid = k & 2;
        pulled_result r, ref;
        ENSURE(support_pulled(lower_rigid, upper_rigid, true, &r));
        ENSURE(support_pulled(lower_rigid, upper_rigid, false, &ref));
        const double ride = hypot(r.ride[0] - ref.ride[0], r.ride[1] - ref.ride[1]);
        printf("    %s on %s: both asleep after %d steps; pulled away %.3f m (never sleeping "
               "%.3f m); the upper one after %d steps at (%.4f, %.4f) m (%.4f, %.4f), ends with "
               "its lowest node at z = %.4f m, centre (%.3f, %.3f) m (%.4f m, (%.3f, %.3f) m)\n",
               upper_rigid ? "rigid" : "soft", lower_rigid ? "rigid" : "soft", r.sleep_at,
               r.lower_dx, ref.lower_dx, RIDE_STEPS, r.ride[0], r.ride[1], ref.ride[0],
               ref.ride[1], r.low_z, r.centre[0], r.centre[1], ref.low_z, ref.centre[0],
               ref.centre[1]);
        ENSURE_MSG(r.sleep_at > 0, "the pair did not fall asleep within 400 steps");
        ENSURE_MSG(r.lower_dx > 1, "the lower object moved only %.3f m", r.lower_dx);
        ENSURE_MSG(fabs(r.lower_dx / ref.lower_dx - 1) < 0.02,
                   "the lower object moved %.3f m, %.3f m when nothing sleeps", r.lower_dx,
                   ref.lower_dx);
        ENSURE_MSG(ride < 0.01, "riding, the upper object is %.4f m from where it is when "
                   "nothing sleeps", ride);
        /* it fell to the ground, as it does when nothing sleeps */
        ENSURE_MSG(r.low_z < 0.01, "the upper object stayed at z = %.4f m", r.low_z);
        ENSURE(ref.low_z < 0.01);
    }
}

/* A rigid box (3×3×1 cubes of 0.1 m, μ 0.5) resting on a soft block (4×4×2, E 1e5 Pa, μ 0.5)
 * on the ground, on a slope: gravity tilted by θ about y, sleeping off. Returns how fast the
 * box moved down the slope relative to the block over steps 120–600 [m/s] and how far over
 * the whole run [m]. */
static bool box_on_sloped_block(double theta_deg, double *creep, double *moved)
{
    cs_world_t *w = world(true, true);
    if (!w)
        return false;
    const double th = theta_deg * M_PI / 180;
    w->def.sleep_steps = 0;
    w->def.gravity[0] = 9.81 * sin(th);
    w->def.gravity[2] = -9.81 * cos(th);
    char err[256] = "";
    cs_material soft = cs_material_default();
    soft.young = 1e5;
    soft.damping[0] = 1;
    const cs_object_id low = add_box(w, "block", 4, 4, 2, 0.1, (double[3]){0, 0, 0}, soft,
                                     false, CS_MODEL_COROTATIONAL, NULL, err);
    const cs_object_id up = add_box(w, "box", 3, 3, 1, 0.1, (double[3]){0.05, 0.05, 0.205},
                                    cs_material_default(), false, CS_MODEL_RIGID, NULL, err);
    bool ok = low != CS_NULL_OBJECT && up != CS_NULL_OBJECT;
    double rel0 = 0, rel120 = 0, rel = 0;
    for (int i = 0; i <= 600 && ok; i++) {
        const double *x[2];
        int n[2];
        cs_object_nodes(w, low, NULL, &x[0], NULL, &n[0]);
        cs_object_nodes(w, up, NULL, &x[1], NULL, &n[1]);
        double cx[2] = {0, 0};
        for (int k = 0; k < 2; k++)
            for (int j = 0; j < n[k]; j++)
                cx[k] += x[k][3 * j] / n[k];
        rel = cx[1] - cx[0];
        if (i == 0)
            rel0 = rel;
        if (i == 120)
            rel120 = rel;
        if (i < 600)
            ok = cs_world_step(w) == CS_OK;
    }
    *creep = (rel - rel120) / (480 * w->def.dt);
    *moved = rel - rel0;
    cs_world_destroy(w);
    return ok;
}

TEST(rigid_box_holds_on_sloped_soft_block)
{
    /* tan 3° = 0.05 and tan 10° = 0.18 are well inside μ = 0.5: the box should not slide. The
     * contact solve saw the block's top heading down the slope with the whole block (its free
     * coarse modes), while the ground's friction held the block: the box slid at 1.2 cm/s on
     * 3° and off the block on 10°. What is left comes from the friction rows' doubled local
     * response (FRICTION_LOCAL, README Known limitations). */
    const double th[2] = {3, 10}, lim[2] = {4e-3, 1.5e-2};
    for (int k = 0; k < 2; k++) {
        double creep, moved;
        ENSURE(box_on_sloped_block(th[k], &creep, &moved));
        printf("    rigid box on a soft block on a %.0f° slope (μ 0.5): creeps %.2e m/s over "
               "steps 120-600, %.4f m in 10 s\n", th[k], creep, moved);
        ENSURE_MSG(creep < lim[k], "the box slides at %.3g m/s", creep);
        ENSURE_MSG(moved < 0.1, "the box slid %.3f m", moved);
    }
}

/*
 * A 3×3×3 block of 0.1 m cubes (model, E, integrator, world dt) on the ground under gravity
 * tilted by θ about y, after 0.5 s of settling: with v0 > 0, every node (a rigid body: its
 * centre) is given v0 along x and the block's centre travels `dist` in `secs`; a[0], a[1] are
 * its mean velocity along x at secs/2 and at the end. Sleeping off. False if it cannot be built.
 */
static bool block_on_slope(cs_model model, double young, double beta, cs_integrator integ,
                           double dt, double theta_deg, double v0, double secs, double *dist,
                           double a[2])
{
    cs_world_t *w = world(true, true);
    if (!w)
        return false;
    const double th = theta_deg * M_PI / 180;
    w->def.dt = dt;
    w->def.sleep_steps = 0;
    w->def.gravity[0] = 9.81 * sin(th);
    w->def.gravity[2] = -9.81 * cos(th);
    cs_material m = cs_material_default();
    m.young = young;
    m.damping[1] = beta;
    char err[256] = "";
    const cs_object_id id = add_box_i(w, "block", 3, 3, 3, 0.1, (double[3]){0, 0, 0}, m, false,
                                      model, integ, NULL, err);
    bool ok = id != CS_NULL_OBJECT;
    const int settle = (int)lround(0.5 / dt), steps = (int)lround(secs / dt);
    for (int i = 0; i < settle && ok; i++)
        ok = cs_world_step(w) == CS_OK;
    if (ok && v0 > 0) {
        if (model == CS_MODEL_RIGID) {
            ok = kick(w, id, 0.3, (double[3]){v0, 0, 0}) == 0;
        } else {
            cs_object *o = w->objects[0];
            for (int j = 0; j < o->n; j++)
                o->v[3 * j] += v0;
        }
    }
    double x0 = 0;
    for (int i = 0; i <= steps && ok; i++) {
        const double *x, *v;
        int n;
        cs_object_nodes(w, id, NULL, &x, &v, &n);
        double c = 0, cv = 0;
        for (int j = 0; j < n; j++) {
            c += x[3 * j] / n;
            cv += v[3 * j] / n;
        }
        if (i == 0)
            x0 = c;
        if (i == steps / 2)
            a[0] = cv;
        if (i == steps) {
            a[1] = cv;
            *dist = c - x0;
        } else {
            ok = cs_world_step(w) == CS_OK;
        }
    }
    cs_world_destroy(w);
    return ok;
}

/* A 2×2×2 block of 0.1 m cubes (corotational, implicit Euler) released 5 cm above the ground
 * moving at vx and turning at wy about y: per step, the largest excess of the centre's
 * horizontal velocity change over Coulomb's bound μ (Δv_z + g dt)⁺ (the step's friction
 * impulse is at most μ times its normal impulse), the centre's y drift (the scene is
 * symmetric in y) and its speed and height at the end. */
/* The kinetic energy and the gravity's potential energy (above z = 0) of o's nodes. */
static double kinetic_potential(const cs_object *o, double g)
{
    double e = 0;
    for (int i = 0; i < o->n; i++) {
        const double *v = o->v + 3 * i;
        e += o->m[i] * (0.5 * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) + g * o->x[3 * i + 2]);
    }
    return e;
}

/* A 2×2×2 corotational block of 0.1 m cubes released 5 cm above the ground, moving at vx and
 * turning at wy about y; over 3 s: by how much its centre's horizontal velocity change in a
 * step broke Coulomb's bound μ (Δv_z + g dt)⁺ at most, its largest y drift, its largest
 * kinetic + potential energy over the start's (egain), and its speed and height at the end. */
static bool landing(double young, double rho, double vx, double wy, double *excess, double *ydrift,
                    double *egain, double *vend, double *zend)
{
    cs_world_t *w = world(true, true);
    if (!w)
        return false;
    cs_material m = cs_material_default();
    m.young = young;
    m.density = rho;
    char err[256] = "";
    const cs_object_id id = add_box_i(w, "block", 2, 2, 2, 0.1, (double[3]){0, 0, 0.05}, m,
                                      false, CS_MODEL_COROTATIONAL, CS_INTEGRATOR_DEFAULT, NULL,
                                      err);
    bool ok = id != CS_NULL_OBJECT;
    if (ok) {
        cs_object *o = w->objects[0];
        for (int j = 0; j < o->n; j++) {
            const double rx = o->x[3 * j] - 0.1, rz = o->x[3 * j + 2] - 0.15;
            o->v[3 * j] = vx + wy * rz;
            o->v[3 * j + 2] = -wy * rx;
        }
    }
    const double dt = w->def.dt, g = 9.81, mu = w->def.ground_friction;
    double pv[3] = {0, 0, 0}, e0 = 0;
    *excess = *ydrift = *egain = 0;
    for (int s = 0; s <= 180 && ok; s++) {
        const cs_object *o = w->objects[0];
        double c[3], cv[3];
        mass_mean(o, o->x, c);
        mass_mean(o, o->v, cv);
        if (s > 0) {
            const double dh = hypot(cv[0] - pv[0], cv[1] - pv[1]);
            const double bound = mu * fmax(cv[2] - pv[2] + g * dt, 0.0);
            *excess = fmax(*excess, dh - bound);
        }
        *ydrift = fmax(*ydrift, fabs(c[1] - 0.1));
        const double e = kinetic_potential(o, g);
        if (s == 0)
            e0 = e;
        *egain = fmax(*egain, e / e0);
        memcpy(pv, cv, sizeof pv);
        if (s == 180) {
            *vend = sqrt(cv[0] * cv[0] + cv[1] * cv[1] + cv[2] * cv[2]);
            *zend = c[2];
        } else {
            ok = cs_world_step(w) == CS_OK;
        }
    }
    cs_world_destroy(w);
    return ok;
}

TEST(ground_landing_stiff_blocks_are_not_thrown)
{
    /* Until session 28 a stiff block landing tilted broke Coulomb's bound by 1.1-2.2 m/s in
     * a step (stopping dead) or was thrown: its ground reactions came from a residual
     * relative to dt f_el (many times its weight), a node leaving the ground kept its
     * friction through the landing step, and friction stayed at the last step's μ fn. 2e11
     * Pa blocks were thrown kilometres. What is left (README Known limitations): a node
     * leaving the ground is still held down through its landing step, so some landings break
     * the bound, by up to 2-3 m/s. Which ones is chaotic: a change of the solve within
     * its tolerance (the warm start's span, session 29) moves single landings between 0 and
     * 1.07 m/s over. So the test lands 40 blocks (E 1e5-2e11 Pa, ρ 1000 and 7800 kg/m³, four
     * spins) and bounds how many break the bound by more than 0.2 m/s (a quarter) and their
     * energy (not thrown). Measured in scratch runs released 4, 5 and 6 cm up (150 steps;
     * over 0.2 m/s / worst): 77edff0 28 of 40 / 1.5e9 m/s at 5 cm; 9996ccc 12, 10, 11 / 1.66,
     * 1.10, 3.00; session 29 6, 6, 7 / 1.07, 1.94, 2.19; session 30's main 10, 6, 7 / 1.00,
     * 0.68, 2.19; session 31 (nodes reaching the ground during a step held in its solve,
     * world.c ground_arrivals) 3, 0, 0 / 0.30, 0.19, 0.13, and here 1 of 40, energy at most
     * 1.0545 of the start's (was 10 of 40 allowed, 25 % gain). Session 32: friction bounded by
     * μ times the net normal force (ground_reactions: the push of the nodes the ground holds
     * up less the pull of the released ones it still holds down; their couple, 24 times a
     * block's weight, had let the push's friction stop a block landing on its face dead,
     * 1.09 m/s over): 0, 0, 0 / 0.002, 0.056, 0.001 m/s, and with the turning bodies' steps
     * of that session 0 of 40, worst 0.015 m/s, energy at most 1.0000 here. */
    const double young[] = {1e5, 1e7, 1e9, 1e10, 2e11}, rho[] = {1000, 7800};
    const double spin[][2] = {{0.5, 3}, {2, 8}, {1, -6}, {0, 5}};
    int over = 0, n = 0;
    double worst = 0, gain = 0;
    for (int e = 0; e < 5; e++)
        for (int r = 0; r < 2; r++)
            for (int k = 0; k < 4; k++) {
                double excess = 0, ydrift = 0, egain = 0, vend = 0, zend = 0;
                ENSURE(landing(young[e], rho[r], spin[k][0], spin[k][1], &excess, &ydrift,
                               &egain, &vend, &zend));
                gain = fmax(gain, egain);
                n++;
                over += excess > 0.2;
                worst = fmax(worst, excess);
                if (excess > 0.2 || egain > 1)
                    printf("    E %.0e ρ %4.0f, %.1f m/s, %+.0f rad/s: over the bound by "
                           "%.4f m/s, energy at most %.4f of the start's\n",
                           young[e], rho[r], spin[k][0], spin[k][1], excess, egain);
                ENSURE_MSG(ydrift < 0.01, "E %.0e ρ %.0f: drifted %.3g m across a symmetric "
                           "landing", young[e], rho[r], ydrift);
                /* resting on its face after 3 s (the 1e5 Pa blocks, jellies, may still
                 * wobble: 7 mm/s at 7800 kg/m³) */
                ENSURE_MSG(young[e] < 1e7 || (vend < 1e-3 && fabs(zend - 0.1) < 1e-3),
                           "E %.0e ρ %.0f: still moving (%.3g m/s, %.4f m up)", young[e],
                           rho[r], vend, zend);
            }
    printf("    %d of %d landings over Coulomb's bound by more than 0.2 m/s; worst %.3f m/s; "
           "kinetic + potential energy at most %.4f of the start's\n",
           over, n, worst, gain);
    ENSURE_MSG(over <= 1 && worst <= 0.1, "%d of %d landings broke Coulomb's bound by more "
               "than 0.2 m/s, worst %.3f m/s", over, n, worst);
    /* thrown (77edff0: 6.8 m/s, kilometres) is many times the start's energy; landings of
     * spinning stiff blocks gained up to 10 % (session 29), 5.5 % in session 31: the strain
     * their spin's tangent steps stored in flight (250 times their kinetic energy at 1e9 Pa),
     * given back on landing; none since session 32's turn (world.c free_body_rotation) */
    ENSURE_MSG(gain <= 1.001, "a landing gained energy: %.4f of the start's", gain);
}

TEST(ground_friction_is_coulomb_for_every_model)
{
    /* μ = 0.5 (the ground's default). On 20° (tan 0.36 < μ) a block stays; on 35° it slides
     * at g (sin θ − μ cos θ) = 1.609 m/s²; pushed to 2 m/s on level ground it stops after
     * v0²/(2 μ g) = 0.408 m (implicit Euler's steps: Σ dt (v0 − k μ g dt) = 0.391 m at 1/60 s).
     * Friction applied after the solve, node by node, let stiff blocks slide on 20°, at up to
     * 4 m/s² on 35° and 0.64–2.2 m when pushed. The central-difference block has stiffness
     * damping: undamped it keeps vibrating on the ground and walks down 20° (30 mm in 2 s). */
    const struct {
        cs_model model;
        double young, beta, dt;
        cs_integrator integ;
    } c[] = {
        {CS_MODEL_RIGID, 1e5, 0, 1.0 / 60, CS_INTEGRATOR_DEFAULT},
        {CS_MODEL_COROTATIONAL, 1e5, 0, 1.0 / 60, CS_INTEGRATOR_DEFAULT},
        {CS_MODEL_COROTATIONAL, 1e7, 0, 1.0 / 60, CS_INTEGRATOR_DEFAULT},
        {CS_MODEL_COROTATIONAL, 1e10, 0, 1.0 / 60, CS_INTEGRATOR_DEFAULT},
        {CS_MODEL_LINEAR, 1e7, 0, 1.0 / 60, CS_INTEGRATOR_DEFAULT},
        {CS_MODEL_MSS, 1e7, 0, 1.0 / 60, CS_INTEGRATOR_DEFAULT},
        {CS_MODEL_LOCALFRAME, 1e7, 0, 1.0 / 60, CS_INTEGRATOR_DEFAULT},
        {CS_MODEL_COROTATIONAL, 1e8, 0, 1.0 / 60, CS_INTEGRATOR_NEWMARK},
        {CS_MODEL_LOCALFRAME, 1e5, 1e-3, 0.002, CS_INTEGRATOR_CENTRAL_DIFFERENCE},
    };
    const double g = 9.81, mu = 0.5, th = 35 * M_PI / 180;
    const double acc = g * (sin(th) - mu * cos(th));
    for (size_t k = 0; k < sizeof c / sizeof c[0]; k++) {
        double hold, slide, stop, a20[2], a35[2], a0[2];
        ENSURE(block_on_slope(c[k].model, c[k].young, c[k].beta, c[k].integ, c[k].dt, 20, 0, 2, &hold, a20));
        ENSURE(block_on_slope(c[k].model, c[k].young, c[k].beta, c[k].integ, c[k].dt, 35, 0, 2, &slide, a35));
        ENSURE(block_on_slope(c[k].model, c[k].young, c[k].beta, c[k].integ, c[k].dt, 0, 2, 1, &stop, a0));
        /* implicit Euler's stopping distance at this dt; the others' (x moves by the mean of
         * the step's velocities) is the continuous one, but for the last step */
        double v = 2, want = 0;
        while (v > 0) {
            v -= mu * g * c[k].dt;
            want += v > 0 ? v * c[k].dt : 0;
        }
        if (c[k].integ != CS_INTEGRATOR_DEFAULT)
            want = 2 * 2 / (2 * mu * g);
        const double got = (a35[1] - a35[0]) / 1.0;
        printf("    %-12s E %.0e %-18s: 20°: moved %.2e m; 35°: %.3f m/s² (%.3f); "
               "pushed: stops after %.4f m (%.4f)\n",
               cs_model_name(c[k].model), c[k].young, cs_integrator_name(c[k].integ), hold,
               got, acc, stop, want);
        ENSURE_MSG(fabs(hold) < 2e-3, "slid %.3g m on 20°", hold);
        ENSURE_MSG(fabs(got / acc - 1) < 0.03, "%.3f m/s² down 35° (Coulomb: %.3f)", got, acc);
        /* central differences (a vibrating, lightly damped block) stop 4.5 % short: not
         * traced (README Known limitations) */
        const double tol = c[k].integ == CS_INTEGRATOR_CENTRAL_DIFFERENCE ? 0.06 : 0.03;
        ENSURE_MSG(fabs(stop / want - 1) < tol, "stopped after %.4f m (%.4f)", stop, want);
    }
}

/* The largest accepted force (max_force) on a 1 kg cube next to another body: the step
 * diverges (past 1 km/s), is undone, the cube is left at rest where it was (gravity acts in
 * the step's later substeps), and the step ends.
 * Before the body-pair search was clamped to the other body's lattice, the contact margin of
 * the thrown cube (its speed times the substep, hundreds of metres) made that search run for
 * days: the daemon hung. */
TEST(rigid_absurd_force_next_to_a_body_diverges_and_returns)
{
    cs_world_t *w = world(true, true);
    char err[256] = "";
    const double h = 0.1;
    cs_object_id a = add_box(w, "a", 1, 1, 1, h, (double[3]){0, 0, 0}, cs_material_default(),
                             false, CS_MODEL_RIGID, NULL, err);
    cs_object_id b = add_box(w, "b", 2, 1, 1, h, (double[3]){0.12, 0, 0}, cs_material_default(),
                             false, CS_MODEL_RIGID, NULL, err);
    ENSURE_MSG(a != CS_NULL_OBJECT && b != CS_NULL_OBJECT, "%s", err);
    ENSURE(cs_world_step(w) == CS_OK);
    cs_rigid_state s0, s1;
    cs_object_rigid_state(w, a, &s0);
    const double F[3] = {0.999 * cs_world_get_def(w)->max_force, 0, 0};
    ENSURE(cs_world_apply_force(w, a, s0.position, F, 0, err, sizeof err) == CS_OK);
    ENSURE(cs_world_step(w) == CS_ERR_DIVERGED);
    cs_object_rigid_state(w, a, &s1);
    ENSURE(norm3(s1.velocity) < 1 && norm3(s1.angular_velocity) < 1); /* gravity in later substeps */
    for (int k = 0; k < 3; k++)
        ENSURE(isfinite(s1.position[k]) && fabs(s1.position[k] - s0.position[k]) < 1.0);
    /* and it steps on */
    for (int i = 0; i < 10; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    cs_world_destroy(w);
}
