/*
 * world.c — the engine's face (cubesim.h): worlds, objects, inputs and the step.
 *
 * One step, per object that is awake and not fully fixed (seed 000 §2.2, DESIGN.md):
 *   inputs → rotations (corotational only) → right-hand side → block-Jacobi PCG on
 *   (1+dt·α)M + (dt·β+dt²)K_R [+ dt²·drag springs] for the new velocities (implicit Euler,
 *   warm-started from the old ones) → positions → ground → skin the surface → sleep test.
 * Explicit objects (symplectic Euler, velocity Verlet): inputs → forces → kick/drift → ground
 * projection with Coulomb friction → skin → sleep test; cs_world_add_object refuses a dt above
 * their stability limit (elastic.h: cs_elastic_critical_dt).
 * A step that produces non-finite values is undone and reported (CS_ERR_DIVERGED).
 *
 * Owns: every object and everything an object holds. Objects are kept in creation order in
 * an array of pointers; ids count up from 1 and are never reused.
 */
#include "cubesim.h"

#include <math.h>
#include <omp.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "elastic.h"
#include "localframe.h"
#include "mat3.h"
#include "mg.h"
#include "rigid.h"
#include "strain_limit.h"
#include "voxelize.h"
#include "world_internal.h"

/* ---------------------------------------------------------------- small helpers */

int cs_engine_fail(char *err, size_t errlen, int code, const char *fmt, ...)
{
    if (err && errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, errlen, fmt, ap);
        va_end(ap);
    }
    return code;
}

/* The stage clock of cs_step_stats: wall time; with -DCS_STAGE_CPU the process's CPU time (all
 * threads' together), for A/B comparisons of stages on a machine shared with other work. */
static double now_ms(void)
{
    struct timespec t;
#ifdef CS_STAGE_CPU
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
#else
    clock_gettime(CLOCK_MONOTONIC, &t);
#endif
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static bool finite3(const double v[3])
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

/* |v| without overflow for any finite v (cs_vec3_norm's squares overflow past 1.3e154): what the
 * refusals of inputs check and quote, so that a 1e300 N force reads "1e+300 N", not "inf N". */
static double length3(const double v[3])
{
    return hypot(hypot(v[0], v[1]), v[2]);
}

const char *cs_status_str(int status)
{
    switch (status) {
    case CS_OK: return "ok";
    case CS_ERR_INVALID: return "invalid argument";
    case CS_ERR_UNKNOWN_OBJECT: return "unknown object";
    case CS_ERR_NOMEM: return "out of memory";
    case CS_ERR_GEOMETRY: return "bad geometry";
    case CS_ERR_NOT_CONVERGED: return "not converged";
    case CS_ERR_DIVERGED: return "diverged";
    case CS_ERR_CANCELLED: return "stopped before it converged";
    default: return "unknown status";
    }
}

static const char *const MODEL_NAMES[] = {"linear", "corotational", "mss", "localframe", "rigid"};

int cs_model_from_name(const char *name, cs_model *out)
{
    for (int i = 0; i < 5; i++)
        if (name && !strcmp(name, MODEL_NAMES[i])) {
            *out = (cs_model)i;
            return 0;
        }
    return -1;
}

static const char *const PRECOND_NAMES[] = {"auto", "jacobi", "multigrid"};

int cs_cg_relative_from_name(const char *name, cs_cg_relative *out)
{
    static const char *const names[] = {"step", "rhs"};
    for (int i = 0; i < 2; i++)
        if (name && strcmp(name, names[i]) == 0) {
            *out = (cs_cg_relative)i;
            return 0;
        }
    return -1;
}

int cs_preconditioner_from_name(const char *name, cs_preconditioner *out)
{
    for (int i = 0; i < 3; i++)
        if (name && strcmp(name, PRECOND_NAMES[i]) == 0) {
            *out = (cs_preconditioner)i;
            return 0;
        }
    return -1;
}

static const char *const INTEGRATOR_NAMES[] = {"default", "implicit_euler", "symplectic_euler",
                                               "verlet", "central_difference", "newmark"};

int cs_integrator_from_name(const char *name, cs_integrator *out)
{
    for (int i = 0; name && i < (int)(sizeof INTEGRATOR_NAMES / sizeof *INTEGRATOR_NAMES); i++)
        if (strcmp(name, INTEGRATOR_NAMES[i]) == 0) {
            *out = (cs_integrator)i;
            return 0;
        }
    return -1;
}

const char *cs_integrator_name(cs_integrator i)
{
    if ((int)i < 0 || (int)i >= (int)(sizeof INTEGRATOR_NAMES / sizeof *INTEGRATOR_NAMES))
        return "unknown";
    return INTEGRATOR_NAMES[i];
}

/* The integrator an object uses when its definition asks for the default. */
/* Implicit Euler for every model: bench_wp (README "Work-precision") finds it the fastest way
 * to a given error for every model at interactive time steps, and for localframe 4-10× faster
 * than its central differences (whose consistent-mass solve runs at a dt 40-60× smaller). */
static cs_integrator default_integrator(cs_model m)
{
    (void)m;
    return CS_INTEGRATOR_IMPLICIT_EULER;
}

const char *cs_model_name(cs_model m)
{
    return (unsigned)m < 5 ? MODEL_NAMES[m] : "unknown";
}

/* ---------------------------------------------------------------- defaults */

cs_material cs_material_default(void)
{
    return (cs_material){.young = 1000.0, .poisson = 0.3, .density = 1000.0,
                         .damping = {0.0, 0.0}, .strength = 1e300,
                         .restitution = 0.3, .friction = 0.5};
}

cs_object_def cs_object_def_default(void)
{
    return (cs_object_def){.name = NULL, .model = CS_MODEL_COROTATIONAL,
                           .material = cs_material_default(), .cube_size = 0.1,
                           .geometry = CS_GEOMETRY_CELLS};
}

cs_world_def cs_world_def_default(void)
{
    return (cs_world_def){.dt = 1.0 / 60.0, .gravity = {0, 0, -9.81}, .has_ground = false,
                          .ground_height = 0.0, .ground_friction = 0.5, .cg_tolerance = 1e-4,
                          .cg_max_iterations = 500, .threads = 0, .sleep_speed = 5e-4,
                          .sleep_steps = 30, .active_steps = 0, .active_speed = 5e-4,
                          .max_force = 1e9, .max_fractures = 4,
                          .seed = 1};
}

/* ---------------------------------------------------------------- world lifetime */

int cs_world_create(const cs_world_def *def, cs_world_t **out, char *err, size_t errlen)
{
    *out = NULL;
    if (!def)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "world definition is NULL");
    /* Below 1 µs a step is pointless and durations (seconds/dt steps) overflow int. */
    if (!(def->dt >= CS_MIN_DT && def->dt <= 1.0))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "dt must be in [%g, 1] s, got %g",
                              CS_MIN_DT, def->dt);
    if (!finite3(def->gravity) || cs_vec3_norm(def->gravity) > 1e4)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "gravity must be finite and below 1e4 m/s^2");
    if (!isfinite(def->ground_height))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "ground height must be finite");
    if (!(def->ground_friction >= 0 && def->ground_friction <= 100))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "ground friction must be in [0, 100]");
    if (!(def->cg_tolerance > 0 && def->cg_tolerance < 1))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "solver tolerance must be in (0, 1), got %g",
                    def->cg_tolerance);
    if ((int)def->preconditioner < 0 || (int)def->preconditioner > CS_PRECOND_MULTIGRID)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "preconditioner: unknown value %d",
                              (int)def->preconditioner);
    if ((int)def->cg_relative_to < 0 || (int)def->cg_relative_to > CS_CG_RELATIVE_RHS)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "solver relative_to: unknown value %d",
                              (int)def->cg_relative_to);
    if (def->cg_max_iterations < 1 || def->cg_max_iterations > 1000000)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "solver max_iterations must be in [1, 1e6]");
    if (def->threads < 0 || def->threads > 256)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "threads must be in [0, 256]");
    if (def->simd_width != 0 && def->simd_width != 256 && def->simd_width != 512)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "simd_width must be 0, 256 or 512");
    if (!(def->sleep_speed >= 0 && isfinite(def->sleep_speed)) || def->sleep_steps < 0)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "sleep speed and steps must be >= 0");
    if (def->active_steps < 0 ||
        (def->active_steps > 0 && !(def->active_speed > 0 && isfinite(def->active_speed))))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "active steps must be >= 0 and active speed positive and finite");
    if (!(def->max_force > 0 && isfinite(def->max_force)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "max_force must be positive and finite");
    if (def->max_fractures < 1 || def->max_fractures > 1000000)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "max_fractures must be in [1, 1e6]");
    cs_world_t *w = calloc(1, sizeof *w);
    if (!w)
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory creating a world");
    w->def = *def;
    w->threads = def->threads > 0 ? def->threads : omp_get_num_procs();
    if (w->threads < 1)
        w->threads = 1;
    w->next_id = 1;
    w->broadphase_min_bodies = CS_BROADPHASE_BODIES;
    w->pc_lag_angle = CS_PC_LAG_ANGLE;
    w->pc_lag_steps = CS_PC_LAG_STEPS;
    w->pc_lag_cap = true;
    *out = w;
    return CS_OK;
}

void cs_object_free_internal(cs_object *o)
{
    if (!o)
        return;
    free(o->name);
    free(o->apart);
    free(o->corner_vertex);
    free(o->tri_kind);
    free(o->cell_cut);
    free(o->cell_open);
    cs_cubemesh_free(&o->cm);
    cs_surface_free(&o->surf);
    cs_elastic_free(o);
    cs_rigid_free(o);
    free(o->x);
    free(o->v);
    free(o->m);
    free(o->f_const);
    free(o->f);
    free(o->b);
    free(o->v1);
    free(o->blocks);
    free(o->mask);
    free(o->smask);
    free(o->contact);
    free(o->ground);
    free(o->v_wake);
    free(o->pin);
    free(o->sl_flag);
    free(o->sl_list);
    free(o->frozen);
    free(o->cell_active);
    free(o->cell_flip);
    free(o->calm);
    free(o->f_skip);
    cs_fields_free(&o->fld);
    cs_cg_work_free(&o->cg);
    cs_mg_free(o->mg);
    free(o);
}

void cs_world_destroy(cs_world_t *w)
{
    if (!w)
        return;
    for (int i = 0; i < w->n_objects; i++)
        cs_object_free_internal(w->objects[i]);
    free(w->objects);
    cs_world_fracture_free(w);
    cs_rigid_world_free(w);
    free(w);
}

cs_object *cs_world_find_internal(const cs_world_t *w, cs_object_id id)
{
    if (!w || id == CS_NULL_OBJECT)
        return NULL;
    /* objects are kept in increasing id order (ids grow as objects are added, removal keeps
     * the order, a fracture's rebuilt object keeps its id): binary search, so that walking
     * every object by id (the bus does, each publish) is not quadratic in a world of
     * thousands of them */
    int lo = 0, hi = w->n_objects - 1;
    while (lo <= hi) {
        const int mid = lo + (hi - lo) / 2;
        const cs_object_id m = w->objects[mid]->id;
        if (m == id)
            return w->objects[mid];
        if (m < id)
            lo = mid + 1;
        else
            hi = mid - 1;
    }
    for (int i = 0; i < w->n_objects; i++) /* a miss: also in case the order did not hold */
        if (w->objects[i]->id == id)
            return w->objects[i];
    return NULL;
}

/* ---------------------------------------------------------------- adding objects */

static int check_material(const cs_material *m, char *err, size_t errlen)
{
    if (!(m->young > 0 && isfinite(m->young)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "material young must be > 0 Pa, got %g",
                    m->young);
    if (!(m->poisson >= 0 && m->poisson < 0.5))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "material poisson must be in [0, 0.5), got %g",
                    m->poisson);
    if (!(m->density > 0 && isfinite(m->density)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "material density must be > 0, got %g",
                    m->density);
    if (!(m->damping[0] >= 0 && isfinite(m->damping[0]) && m->damping[1] >= 0 &&
          isfinite(m->damping[1])))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "material damping must be finite and >= 0");
    if (!(m->strength > 0))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "material strength must be > 0");
    if (!(m->restitution >= 0 && m->restitution <= 1))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "material restitution must be in [0, 1], got %g", m->restitution);
    if (!(m->friction >= 0 && m->friction <= 100))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "material friction must be in [0, 100], got %g", m->friction);
    return CS_OK;
}

/*
 * The scales double arithmetic must hold (world_internal.h CS_MIN_SCALE): a node's mass, a
 * cube's stiffness and, for a rigid body, a cube's moment of inertia. Each is a product of
 * fields inside their own ranges, so each can still overflow, underflow or lose every digit
 * of its squares: density 1e-300 or cube_size 1e±300 ran to NaN (or to nothing at all) with
 * exit status 0.
 */
static int check_scales(const cs_object_def *def, char *err, size_t errlen)
{
    const cs_material *m = &def->material;
    const double h = def->cube_size, node_mass = m->density * h * h * h / 8;
    if (!(node_mass >= CS_MIN_SCALE && node_mass <= CS_MAX_SCALE))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "density %g kg/m^3 and cube_size %g m give nodes of %g kg "
                              "(density*cube_size^3/8), outside [%g, %g] kg where double "
                              "arithmetic holds the step's momenta and energies",
                              m->density, h, node_mass, CS_MIN_SCALE, CS_MAX_SCALE);
    const double k = m->young * h;
    if (def->model != CS_MODEL_RIGID && !(k >= CS_MIN_SCALE && k <= CS_MAX_SCALE))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "young %g Pa and cube_size %g m give cubes of stiffness %g N/m "
                              "(young*cube_size), outside [%g, %g] N/m where double arithmetic "
                              "holds the elastic forces",
                              m->young, h, k, CS_MIN_SCALE, CS_MAX_SCALE);
    const double inertia = node_mass * 8 * h * h / 6;
    if (def->model == CS_MODEL_RIGID && !(inertia >= CS_MIN_SCALE && inertia <= CS_MAX_SCALE))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "density %g kg/m^3 and cube_size %g m give a rigid cube a moment of "
                              "inertia of %g kg m^2 (density*cube_size^5/6), outside [%g, %g] "
                              "where its inverse can be computed",
                              m->density, h, inertia, CS_MIN_SCALE, CS_MAX_SCALE);
    return CS_OK;
}

static bool in_box(const cs_aabb *b, const double p[3])
{
    return p[0] >= b->min[0] && p[0] <= b->max[0] && p[1] >= b->min[1] && p[1] <= b->max[1] &&
           p[2] >= b->min[2] && p[2] <= b->max[2];
}

/* Faces of a cell: axis, side, and the corners on that face in counter-clockwise order. */
static const int FACE_CORNERS[6][4] = {
    {0, 3, 7, 4}, {1, 2, 6, 5}, {0, 4, 5, 1}, {3, 7, 6, 2}, {0, 1, 2, 3}, {4, 5, 6, 7},
};

/* DESIGN.md: a load's total force is spread over the exposed faces whose centres lie in its
 * box, a quarter of each face's share to each of its corners. A load that alone gives one of
 * its nodes more than CS_MAX_STEP_SPEED in one step of dt (its share over the node's mass) is
 * refused. Needs the masses (cs_object_lump_mass); o->f is scratch here. */
static int apply_loads(cs_object *o, const cs_object_def *def, double dt, char *err,
                       size_t errlen)
{
    const cs_cubemesh *cm = &o->cm;
    double *share = o->f; /* this load's force per node, for the speed check */
    memset(share, 0, (size_t)o->n * 3 * sizeof *share);
    for (int l = 0; l < def->n_loads; l++) {
        const cs_load *ld = &def->loads[l];
        if (!finite3(ld->force) || !finite3(ld->box.min) || !finite3(ld->box.max))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID, "loads[%d]: values must be finite", l);
        int count = 0;
        for (int pass = 0; pass < 2; pass++) {
            for (int c = 0; c < cm->n_cells; c++) {
                const int32_t *q = cm->cell_ijk + 3 * c;
                for (int f = 0; f < 6; f++) {
                    int axis = f / 2, side = f % 2;
                    int32_t nb[3] = {q[0], q[1], q[2]};
                    nb[axis] += side ? 1 : -1;
                    if (cs_cubemesh_find(cm, nb[0], nb[1], nb[2]) >= 0)
                        continue;
                    double centre[3];
                    for (int a = 0; a < 3; a++)
                        centre[a] = cm->origin[a] + cm->h * (q[a] + 0.5);
                    centre[axis] += (side ? 0.5 : -0.5) * cm->h;
                    if (!in_box(&ld->box, centre))
                        continue;
                    if (pass == 0) {
                        count++;
                        continue;
                    }
                    for (int k = 0; k < 4; k++) {
                        int32_t node = cm->cell_nodes[8 * c + FACE_CORNERS[f][k]];
                        for (int a = 0; a < 3; a++) {
                            o->f_const[3 * node + a] += ld->force[a] / (4.0 * count);
                            share[3 * node + a] += ld->force[a] / (4.0 * count);
                        }
                    }
                }
            }
            if (pass == 0 && count == 0)
                return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                            "loads[%d]: no exposed cube face centre lies in its box", l);
        }
        double worst = 0;
        int at = -1;
        for (int i = 0; i < o->n; i++) {
            const double *q = share + 3 * (size_t)i;
            const double dv = dt * hypot(hypot(q[0], q[1]), q[2]) / o->m[i];
            if (!(dv <= worst)) { /* NaN or inf too */
                worst = dv;
                at = i;
            }
        }
        memset(share, 0, (size_t)o->n * 3 * sizeof *share);
        if (at >= 0 && !(worst <= CS_MAX_STEP_SPEED))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                                  "loads[%d]: the force (%g, %g, %g) N gives the node at (%g, "
                                  "%g, %g) (%g kg) %g m/s in one step of %g s, beyond the speed "
                                  "of light (%g m/s), where no step means anything",
                                  l, ld->force[0], ld->force[1], ld->force[2],
                                  cm->node_rest[3 * (size_t)at],
                                  cm->node_rest[3 * (size_t)at + 1],
                                  cm->node_rest[3 * (size_t)at + 2], o->m[at], worst, dt,
                                  CS_MAX_STEP_SPEED);
    }
    return CS_OK;
}

static int build_geometry(cs_object *o, const cs_object_def *def, char *err, size_t errlen)
{
    const double h = def->cube_size;
    if (def->geometry == CS_GEOMETRY_CELLS) {
        if (!def->cells_ijk || def->n_cells <= 0)
            return cs_engine_fail(err, errlen, CS_ERR_INVALID, "cells: no cells given");
        if (!finite3(def->cells_origin))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID, "cells: origin must be finite");
        if (cs_cubemesh_build(&o->cm, h, def->cells_origin, def->cells_ijk, def->n_cells, err,
                              errlen) != 0)
            return CS_ERR_INVALID;
        double *v = NULL;
        int32_t *t = NULL;
        int nv = 0, nt = 0;
        if (cs_surface_of_cells(&o->cm, 1, &v, &nv, &t, &nt, err, errlen) != 0)
            return CS_ERR_GEOMETRY;
        int rc = cs_surface_bind(&o->surf, &o->cm, v, nv, t, nt, err, errlen);
        free(v);
        free(t);
        return rc == 0 ? CS_OK : CS_ERR_GEOMETRY;
    }
    if (def->geometry != CS_GEOMETRY_MESH)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "unknown geometry kind %d", (int)def->geometry);
    if (!def->mesh_vertices || !def->mesh_triangles || def->n_mesh_vertices < 4 ||
        def->n_mesh_triangles < 4)
        return cs_engine_fail(err, errlen, CS_ERR_GEOMETRY, "mesh: fewer than 4 vertices or triangles");
    for (int i = 0; i < 3 * def->n_mesh_vertices; i++)
        if (!isfinite(def->mesh_vertices[i]))
            return cs_engine_fail(err, errlen, CS_ERR_GEOMETRY, "mesh: vertex %d is not finite", i / 3);
    for (int i = 0; i < 3 * def->n_mesh_triangles; i++)
        if (def->mesh_triangles[i] < 0 || def->mesh_triangles[i] >= def->n_mesh_vertices)
            return cs_engine_fail(err, errlen, CS_ERR_GEOMETRY, "mesh: triangle %d has a bad index", i / 3);
    /* The surface's orientation drives the closing surfaces (seed 000 Eq. 1) and its edges
     * the surface split (§3.1): refuse what they cannot work with. */
    if (cs_mesh_surface_check(def->mesh_vertices, def->n_mesh_vertices, def->mesh_triangles,
                              def->n_mesh_triangles, err, errlen) != 0)
        return CS_ERR_GEOMETRY;
    /* Seed 000 §3.3 on a private copy: no surface edge longer than h. */
    int nv = def->n_mesh_vertices, nt = def->n_mesh_triangles;
    double *v = malloc((size_t)nv * 3 * sizeof *v);
    int32_t *t = malloc((size_t)nt * 3 * sizeof *t);
    int32_t *ijk = NULL;
    int n_cells = 0, rc = CS_ERR_GEOMETRY;
    double origin[3];
    if (!v || !t) {
        rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory copying the mesh");
        goto out;
    }
    memcpy(v, def->mesh_vertices, (size_t)nv * 3 * sizeof *v);
    memcpy(t, def->mesh_triangles, (size_t)nt * 3 * sizeof *t);
    if (cs_subdivide_edges(&v, &nv, &t, &nt, h, err, errlen) != 0)
        goto out;
    if (cs_voxelize(v, nv, t, nt, h, origin, &ijk, &n_cells, err, errlen) != 0)
        goto out;
    if (cs_cubemesh_build(&o->cm, h, origin, ijk, n_cells, err, errlen) != 0)
        goto out;
    if (cs_surface_bind(&o->surf, &o->cm, v, nv, t, nt, err, errlen) != 0)
        goto out;
    rc = CS_OK;
out:
    free(v);
    free(t);
    free(ijk);
    return rc;
}

int cs_object_alloc_state(cs_object *o)
{
    size_t n3 = (size_t)o->n * 3;
    o->x = malloc(n3 * sizeof(double));
    o->v = calloc(n3, sizeof(double));
    o->m = calloc((size_t)o->n, sizeof(double));
    o->f_const = calloc(n3, sizeof(double));
    o->f = malloc(n3 * sizeof(double));
    o->b = malloc(n3 * sizeof(double));
    o->v1 = malloc(n3 * sizeof(double));
    o->blocks = malloc(n3 * 3 * sizeof(double));
    o->mask = calloc(n3, 1);
    o->smask = calloc(n3, 1);
    o->contact = calloc((size_t)o->n, 1);
    o->ground = calloc(n3 ? n3 : 1, sizeof(double));
    o->pin = calloc((size_t)(o->n ? o->n : 1), 1);
    if (!o->x || !o->v || !o->m || !o->f_const || !o->f || !o->b || !o->v1 || !o->blocks ||
        !o->mask || !o->smask || !o->contact || !o->ground || !o->pin || cs_cg_work_init(&o->cg, (int)n3) != 0)
        return -1;
    return 0;
}

/*
 * Central differences (seed 001 Eq. 20) are conditionally stable: with Rayleigh damping
 * centred as in Eq. (19), a mode of frequency ω is stable iff ω·dt < 2, whatever the
 * damping. ω is bounded by the largest element eigenvalue (cs_lf_omega2_bound).
 */
/* ω²max of central differences for the plain material: localframe's B-spline bound, else the
 * element eigenvalue bound of the model's own cube (mss springs are not the FEM cube). */
static int cd_omega2(const cs_object_def *def, double *omega2)
{
    const cs_material *m = &def->material;
    if (def->model == CS_MODEL_LOCALFRAME)
        return cs_lf_omega2_bound(def->model, m->young, m->poisson, m->density, def->cube_size,
                                  omega2);
    const double wm = cs_elastic_max_omega(def->model, m, def->cube_size);
    *omega2 = wm * wm;
    return 0;
}

static int check_central_difference(const cs_world_t *w, const cs_object_def *def, char *err,
                                    size_t errlen)
{
    const cs_material *m = &def->material;
    double omega2;
    if (cd_omega2(def, &omega2) != 0)
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
    const double limit = 2.0 / sqrt(omega2);
    if (w->def.dt > limit)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "dt %.4g s is above the central_difference stability limit %.4g s "
                              "for '%s' (E %g Pa, density %g, cube_size %g m): lower dt or use "
                              "implicit_euler",
                              w->def.dt, limit, def->name, m->young, m->density, def->cube_size);
    return CS_OK;
}

/*
 * The limits above for the plain material, applied to the object as it is: its stiffness and
 * density fields raise ω²max by at most max_cells(young_max/density_min) and its penalty
 * springs by max k_p/m_i (cs_elastic_object_omega2). Explicit steps (Jury's test with the
 * damping field's largest factor on α and β): ω²dt² + 2dt(α + βω_K²)·d_max ≤ 4. Central
 * differences take the penalty springs implicitly (like drags), so only the fields count
 * there: ω dt < 2.
 */
int cs_object_check_stability(const cs_object *o, double dt, const char *what, char *err,
                              size_t errlen)
{
    const bool expl = o->integrator == CS_INTEGRATOR_SYMPLECTIC_EULER ||
                      o->integrator == CS_INTEGRATOR_VERLET;
    if (o->model == CS_MODEL_RIGID || o->omega2_plain <= 0)
        return CS_OK;
    const double wk2 = cs_elastic_object_omega2(o, o->omega2_plain, false);
    if (!expl && o->integrator != CS_INTEGRATOR_CENTRAL_DIFFERENCE) {
        /* implicit steps: the masses must survive the round-off of dt²K (CS_MAX_OMEGA_DT2) */
        if (!(wk2 * dt * dt <= CS_MAX_OMEGA_DT2))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                                  "%s'%s' is too stiff for its mass at dt %g s: (omega_max*dt)^2 "
                                  "= %.3g is above %g, where its nodes' mass is lost in the "
                                  "round-off of the stiffness (young %g Pa, density %g kg/m^3, "
                                  "cube_size %g m%s): raise density or cube_size, or lower "
                                  "young or dt",
                                  what, o->name, dt, wk2 * dt * dt, CS_MAX_OMEGA_DT2,
                                  o->mat.young, o->mat.density, o->cm.h,
                                  wk2 > o->omega2_plain * (1 + 1e-12) ? ", with its fields" : "");
        return CS_OK;
    }
    if (!expl) {
        const double limit = 2.0 / sqrt(wk2);
        if (dt > limit)
            return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                                  "%sdt %.4g s is above the central_difference stability limit "
                                  "%.4g s of '%s' with its stiffness/density fields (omega_max "
                                  "%g rad/s): lower dt, soften or lighten less, or use "
                                  "implicit_euler",
                                  what, dt, limit, o->name, sqrt(wk2));
        return CS_OK;
    }
    const double w2 = cs_elastic_object_omega2(o, o->omega2_plain, true);
    double dmax = 1.0;
    if (o->fld.has_damping) {
        dmax = 0;
        for (size_t i = 0; i < 8 * (size_t)o->cm.n_cells; i++)
            dmax = fmax(dmax, o->fld.damping[i]);
    }
    const double g = dmax * (o->mat.damping[0] + o->mat.damping[1] * wk2);
    const double limit = (-g + sqrt(g * g + 4 * w2)) / w2;
    if (dt > limit) {
        const bool pen = w2 > wk2 * (1 + 1e-12);
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "%sintegrator '%s' is unstable for object '%s': dt %g s exceeds "
                              "the explicit stability limit %g s with its material fields%s "
                              "(omega_max %g rad/s); use dt <= %g s%s, or implicit_euler",
                              what, cs_integrator_name(o->integrator), o->name, dt, limit,
                              pen ? " and penalty springs" : "", sqrt(w2), limit,
                              pen ? ", a softer penalty_stiffness" : "");
    }
    return CS_OK;
}

int cs_world_add_object(cs_world_t *w, const cs_object_def *def, cs_object_id *id, char *err,
                        size_t errlen)
{
    if (id)
        *id = CS_NULL_OBJECT;
    if (!w || !def)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "world or object definition is NULL");
    if (!def->name || !def->name[0] || strlen(def->name) > CS_MAX_NAME)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "object name must have 1 to %d characters",
                    CS_MAX_NAME);
    if (cs_world_find_object(w, def->name) != CS_NULL_OBJECT)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "object name '%s' is already used", def->name);
    if (def->model != CS_MODEL_LINEAR && def->model != CS_MODEL_COROTATIONAL &&
        def->model != CS_MODEL_LOCALFRAME && def->model != CS_MODEL_MSS &&
        def->model != CS_MODEL_RIGID)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "model '%s' is not implemented yet",
                    cs_model_name(def->model));
    const cs_integrator integ = def->integrator == CS_INTEGRATOR_DEFAULT
                                    ? default_integrator(def->model) : def->integrator;
    const bool explicit_integ =
        integ == CS_INTEGRATOR_SYMPLECTIC_EULER || integ == CS_INTEGRATOR_VERLET;
    if (integ != CS_INTEGRATOR_IMPLICIT_EULER && integ != CS_INTEGRATOR_CENTRAL_DIFFERENCE &&
        integ != CS_INTEGRATOR_NEWMARK && !explicit_integ)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "integrator '%s' is not implemented yet", cs_integrator_name(integ));
    if (integ == CS_INTEGRATOR_NEWMARK && def->model == CS_MODEL_MSS)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "integrator 'newmark' is not offered for model 'mss': its "
                              "correction forces are not conservative and the midpoint rule "
                              "pumps energy into a spinning mss block; use implicit_euler, "
                              "symplectic_euler or verlet");
    if (!(def->cube_size > 0 && isfinite(def->cube_size)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "cube_size must be > 0 m, got %g",
                    def->cube_size);
    int rc = check_material(&def->material, err, errlen);
    if (rc)
        return rc;
    if (def->model == CS_MODEL_MSS && def->material.poisson > CS_MSS_MAX_POISSON)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "model 'mss' takes poisson up to %g, got %g: its correction forces "
                              "grow as 1/(1 - 2 poisson) and are not a potential's gradient, so "
                              "near incompressibility its implicit steps gain energy and blow up "
                              "(use corotational or linear)",
                              CS_MSS_MAX_POISSON, def->material.poisson);
    rc = check_scales(def, err, errlen);
    if (rc)
        return rc;
    if (explicit_integ) {
        /* An explicit step above the stability limit blows up within a few steps: refuse it
         * here, with the limit, rather than report divergence later. */
        const double dtc = cs_elastic_critical_dt(def->model, &def->material, def->cube_size);
        if (w->def.dt > dtc)
            return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                        "integrator '%s' is unstable for object '%s': world dt %g s exceeds the "
                        "explicit stability limit %g s (2/omega_max, damping included; "
                        "omega_max %g rad/s); use dt <= %g s, larger cubes, or implicit_euler",
                        cs_integrator_name(integ), def->name, w->def.dt, dtc,
                        cs_elastic_max_omega(def->model, &def->material, def->cube_size), dtc);
    }
    if (integ == CS_INTEGRATOR_CENTRAL_DIFFERENCE) {
        rc = check_central_difference(w, def, err, errlen);
        if (rc)
            return rc;
    }
    if (!(def->fracture_radius >= 0 && isfinite(def->fracture_radius)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "fracture_radius must be >= 0 m, got %g",
                    def->fracture_radius);
    for (int i = 0; i < def->n_fixed; i++)
        if (!finite3(def->fixed[i].min) || !finite3(def->fixed[i].max))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID, "fixed[%d]: values must be finite", i);
    if (def->n_fields < 0 || (def->n_fields > 0 && !def->fields))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "fields: bad count or NULL array");
    for (int i = 0; i < def->n_fields; i++)
        if ((rc = cs_fields_check_region(&def->fields[i], i, err, errlen)) != CS_OK)
            return rc;
    if (def->constraints != CS_CONSTRAINT_REMOVE && def->constraints != CS_CONSTRAINT_PENALTY)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "constraints: unknown mode %d",
                              (int)def->constraints);
    if (!(def->penalty_stiffness >= 0 && def->penalty_stiffness <= 1e15))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "penalty_stiffness must be in [0, 1e15] N/m, got %g",
                              def->penalty_stiffness);
    if (!(def->strain_limit == 0 || (def->strain_limit >= CS_STRAIN_LIMIT_MIN &&
                                     def->strain_limit <= CS_STRAIN_LIMIT_MAX)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "strain_limit must be 0 (none) or in [%g, %g], got %g",
                              CS_STRAIN_LIMIT_MIN, CS_STRAIN_LIMIT_MAX, def->strain_limit);

    cs_object *o = calloc(1, sizeof *o);
    if (!o)
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
    o->name = strdup(def->name);
    o->model = def->model;
    o->integrator = integ;
    o->mat = def->material;
    o->fracture = def->fracture;
    o->strain_limit = def->strain_limit;
    o->penalty = def->constraints != CS_CONSTRAINT_PENALTY ? 0.0
                 : def->penalty_stiffness > 0 ? def->penalty_stiffness
                 : 1e4 * def->material.young * def->cube_size;
    o->topology_version = 1; /* 0 means "no such object yet" in a topology change */
    o->fracture_radius = def->fracture_radius > 0 ? def->fracture_radius : 1.5 * def->cube_size;
    if (!o->name) {
        rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
        goto fail;
    }
    rc = build_geometry(o, def, err, errlen);
    if (rc)
        goto fail;
    o->n = o->cm.n_nodes;
    if (cs_object_alloc_state(o) != 0 ||
        cs_elastic_init(o, w->threads, w->def.simd_width) != 0) {
        rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory for %d nodes", o->n);
        goto fail;
    }
    memcpy(o->x, o->cm.node_rest, (size_t)o->n * 3 * sizeof(double));
    o->tri_kind = calloc((size_t)(o->surf.n_triangles ? o->surf.n_triangles : 1), 1);
    if (!o->tri_kind) {
        rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
        goto fail;
    }
    /* Material fields (all 1, then the design regions), then the lumped mass that follows
     * the density field (ρh³/8 to each corner when uniform); gravity on every node's mass. */
    if (cs_fields_alloc(o) != 0) {
        rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory for the material fields");
        goto fail;
    }
    cs_fields_apply_regions(o, def->fields, def->n_fields);
    if (cs_object_lump_mass(o) != 0) {
        rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
        goto fail;
    }
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            o->f_const[3 * i + a] = o->m[i] * w->def.gravity[a];
    rc = apply_loads(o, def, w->def.dt, err, errlen);
    if (rc)
        goto fail;
    for (int i = 0; i < o->n; i++)
        for (int b = 0; b < def->n_fixed; b++)
            if (in_box(&def->fixed[b], o->cm.node_rest + 3 * i)) {
                if (def->constraints == CS_CONSTRAINT_PENALTY)
                    o->pin[i] = 1;
                else
                    o->mask[3 * i] = o->mask[3 * i + 1] = o->mask[3 * i + 2] = 1;
                o->n_fixed_nodes++;
                break;
            }
    /* a fixed box that holds no node is a mistake the user cannot see (a plane at x = 0.3
     * misses nodes at 0.30000000000000004): refused, as a load box that holds nothing is */
    for (int b = 0; b < def->n_fixed; b++) {
        bool any = false;
        for (int i = 0; i < o->n && !any; i++)
            any = in_box(&def->fixed[b], o->cm.node_rest + 3 * i);
        if (!any) {
            const cs_aabb *f = &def->fixed[b];
            rc = cs_engine_fail(err, errlen, CS_ERR_INVALID,
                                "fixed[%d] (%g %g %g to %g %g %g) holds no node of the object "
                                "(grow it by a fraction of the cube size around the nodes)",
                                b, f->min[0], f->min[1], f->min[2], f->max[0], f->max[1],
                                f->max[2]);
            goto fail;
        }
    }
    /* the stability limits (and the implicit steps' precision limit) with the scene's fields
     * and penalty springs */
    if (integ == CS_INTEGRATOR_CENTRAL_DIFFERENCE) {
        if (cd_omega2(def, &o->omega2_plain) != 0) {
            rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
            goto fail;
        }
    } else if (def->model != CS_MODEL_RIGID) {
        const double wm = cs_elastic_max_omega(def->model, &def->material, def->cube_size);
        o->omega2_plain = wm * wm;
    }
    rc = cs_object_check_stability(o, w->def.dt, "", err, errlen);
    if (rc)
        goto fail;
    cs_surface_skin(&o->surf, &o->cm, o->x, 1);
    if (o->model == CS_MODEL_RIGID) {
        if (cs_rigid_init(o) != 0) {
            rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
            goto fail;
        }
        o->rb->has_loads = def->n_loads > 0;
    }
    if (cs_world_append_object(w, o) != 0) {
        rc = cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
        goto fail;
    }
    if (id)
        *id = o->id;
    return CS_OK;
fail:
    cs_object_free_internal(o);
    return rc;
}

/* Give o the next id and append it; returns 0, or -1 (out of memory; o untouched). */
int cs_world_append_object(cs_world_t *w, cs_object *o)
{
    if (w->n_objects == w->cap_objects) {
        int cap = w->cap_objects ? 2 * w->cap_objects : 8;
        cs_object **grown = realloc(w->objects, (size_t)cap * sizeof *grown);
        if (!grown)
            return -1;
        w->objects = grown;
        w->cap_objects = cap;
    }
    o->id = w->next_id++;
    if (!o->kin)
        o->kin = o->id;
    w->objects[w->n_objects++] = o;
    return 0;
}

int cs_world_remove_object(cs_world_t *w, cs_object_id id)
{
    for (int i = 0; w && i < w->n_objects; i++)
        if (w->objects[i]->id == id) {
            cs_object_free_internal(w->objects[i]);
            memmove(w->objects + i, w->objects + i + 1,
                    (size_t)(w->n_objects - i - 1) * sizeof *w->objects);
            w->n_objects--;
            return CS_OK;
        }
    return CS_ERR_UNKNOWN_OBJECT;
}

int cs_world_object_ids(const cs_world_t *w, cs_object_id *ids, int max)
{
    for (int i = 0; i < w->n_objects && i < max; i++)
        ids[i] = w->objects[i]->id;
    return w->n_objects;
}

cs_object_id cs_world_find_object(const cs_world_t *w, const char *name)
{
    for (int i = 0; w && name && i < w->n_objects; i++)
        if (!strcmp(w->objects[i]->name, name))
            return w->objects[i]->id;
    return CS_NULL_OBJECT;
}

/* ---------------------------------------------------------------- inputs */

/* The material point nearest to p: the nearest current surface vertex, with its cell and
 * trilinear weights. */
static void nearest_material_point(const cs_object *o, const double p[3], int32_t *cell,
                                   double wts[8])
{
    /* squared distances; past about 1.3e154 m they overflow for every vertex, and then the
     * distances themselves are compared (a point that far off still finds its nearest) */
    int best = -1;
    double bd = INFINITY;
    for (int pass = 0; pass < 2 && best < 0; pass++)
        for (int i = 0; i < o->surf.n_vertices; i++) {
            const double *q = o->surf.pos + 3 * i;
            const double dx = q[0] - p[0], dy = q[1] - p[1], dz = q[2] - p[2];
            const double d = pass == 0 ? dx * dx + dy * dy + dz * dz : hypot(hypot(dx, dy), dz);
            if (d < bd) {
                bd = d;
                best = i;
            }
        }
    best = best < 0 ? 0 : best;
    *cell = o->surf.vert_cell[best];
    const double *u = o->surf.vert_uvw + 3 * best;
    for (int k = 0; k < 8; k++)
        wts[k] = (CS_CORNER[k][0] ? u[0] : 1 - u[0]) * (CS_CORNER[k][1] ? u[1] : 1 - u[1]) *
                 (CS_CORNER[k][2] ? u[2] : 1 - u[2]);
}


/* Steps an input of `seconds` lasts: at least 1, at most 1e9 (1e6 s at dt 1e-6 s would be
 * 1e12: the cast to int must not overflow, and 1e9 steps outlast any session). */
static int duration_steps(double seconds, double dt)
{
    const double steps = ceil(seconds / dt - 1e-9);
    return steps < 1 ? 1 : steps > 1e9 ? 1000000000 : (int)steps;
}

/*
 * A drag spring is integrated explicitly by symplectic Euler and Verlet (the other integrators
 * take it into their implicit operator). It adds k·w wᵀ on the grabbed cell's corners, whose
 * largest frequency against the lumped masses is at most k Σ w_i²/m_i; with the elastic bound
 * ω_el the step stays stable while (ω_el² + k Σ w_i²/m_i) dt² ≤ (ω_el dt_c)² (dt_c the
 * object's explicit limit, damping included). A stiffer spring blew the object up to ~1e250 m
 * without a non-finite value to report (test_stability.c): refuse it with the bound instead.
 */
static int check_explicit_spring(const cs_world_t *w, const cs_object *o, const cs_input *in,
                                 char *err, size_t errlen)
{
    if (o->model == CS_MODEL_RIGID || (o->integrator != CS_INTEGRATOR_SYMPLECTIC_EULER &&
                                       o->integrator != CS_INTEGRATOR_VERLET))
        return CS_OK;
    double s = 0;
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)in->cell;
    for (int k = 0; k < 8; k++)
        if (o->m[nd[k]] > 0)
            s += in->w[k] * in->w[k] / o->m[nd[k]];
    const double we = cs_elastic_max_omega(o->model, &o->mat, o->cm.h);
    const double wc = we * cs_elastic_critical_dt(o->model, &o->mat, o->cm.h) / w->def.dt;
    const double kmax = s > 0 ? (wc * wc - we * we) / s : INFINITY;
    if (in->stiffness > kmax)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "drag stiffness %g N/m is above the explicit stability limit %.4g N/m "
                              "of '%s' at dt %g s (%s): lower it, lower dt or use implicit_euler",
                              in->stiffness, kmax, o->name, w->def.dt,
                              cs_integrator_name(o->integrator));
    return CS_OK;
}

static int add_input(cs_world_t *w, cs_object_id id, cs_input *in, const double point[3],
                     double seconds, char *err, size_t errlen)
{
    cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return cs_engine_fail(err, errlen, CS_ERR_UNKNOWN_OBJECT, "no object with id %u", (unsigned)id);
    if (!finite3(point))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "point is not finite");
    if (!(seconds >= 0 && seconds <= 1e6))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "duration must be in [0, 1e6] s, got %g",
                    seconds);
    if (o->n_inputs == CS_MAX_INPUTS)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "object '%s' already has %d active inputs",
                    o->name, CS_MAX_INPUTS);
    nearest_material_point(o, point, &in->cell, in->w);
    if (cs_input_is_spring(in)) {
        const int rc = check_explicit_spring(w, o, in, err, errlen);
        if (rc)
            return rc;
    }
    in->steps_left = duration_steps(seconds, w->def.dt);
    o->inputs[o->n_inputs++] = *in;
    o->sleeping = false;
    o->still_steps = 0;
    return CS_OK;
}

int cs_world_apply_force(cs_world_t *w, cs_object_id id, const double point[3],
                         const double force[3], double seconds, char *err, size_t errlen)
{
    if (!w || !point || !force)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "NULL argument");
    if (!finite3(force))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "force is not finite");
    if (length3(force) > w->def.max_force)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "force of %g N exceeds max_force %g N",
                    length3(force), w->def.max_force);
    cs_input in = {.kind = CS_INPUT_FORCE, .force = {force[0], force[1], force[2]}};
    return add_input(w, id, &in, point, seconds, err, errlen);
}

int cs_world_drag(cs_world_t *w, cs_object_id id, const double grab[3], const double target[3],
                  double stiffness, double seconds, char *err, size_t errlen)
{
    if (!w || !grab || !target)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "NULL argument");
    if (!finite3(target))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "drag target is not finite");
    if (!(stiffness > 0 && isfinite(stiffness)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "drag stiffness must be > 0 N/m, got %g",
                    stiffness);
    /* The largest force the spring could exert over the object's extent must stay sane. */
    cs_object *o = cs_world_find_internal(w, id);
    if (o) {
        double d = length3((double[3]){target[0] - grab[0], target[1] - grab[1],
                                       target[2] - grab[2]});
        if (stiffness * d > w->def.max_force)
            return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                        "drag force of %g N (stiffness x distance) exceeds max_force %g N",
                        stiffness * d, w->def.max_force);
    }
    cs_input in = {.kind = CS_INPUT_DRAG, .target = {target[0], target[1], target[2]},
                   .stiffness = stiffness};
    return add_input(w, id, &in, grab, seconds, err, errlen);
}

int cs_world_drag_curve(cs_world_t *w, cs_object_id id, const double *points, int n,
                        double stiffness, double seconds, char *err, size_t errlen)
{
    if (!w || !points)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "NULL argument");
    if (n < 2 || n > CS_MAX_CURVE_POINTS)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "curve must have 2 to %d points, got %d", CS_MAX_CURVE_POINTS, n);
    for (int i = 0; i < n; i++)
        if (!finite3(points + 3 * i))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID, "curve point %d is not finite", i);
    if (!(stiffness > 0 && isfinite(stiffness)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "drag stiffness must be > 0 N/m, got %g", stiffness);
    if (!(seconds > 0 && seconds <= 1e6))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "curve duration must be in (0, 1e6] s, got %g", seconds);
    cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return cs_engine_fail(err, errlen, CS_ERR_UNKNOWN_OBJECT, "no object with id %u",
                              (unsigned)id);
    double len[CS_MAX_CURVE_POINTS], total = 0, dmax = 0;
    len[0] = 0;
    for (int i = 1; i < n; i++) {
        const double *a = points + 3 * (i - 1), *b = points + 3 * i;
        total += length3((double[3]){b[0] - a[0], b[1] - a[1], b[2] - a[2]});
        len[i] = total;
    }
    if (!(total > 0))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "curve has zero length");
    cs_input in = {.kind = CS_INPUT_CURVE, .stiffness = stiffness};
    nearest_material_point(o, points, &in.cell, in.w);
    int rc = check_explicit_spring(w, o, &in, err, errlen);
    if (rc)
        return rc;
    const int32_t *nd = o->cm.cell_nodes + 8 * in.cell;
    double grab[3] = {0, 0, 0};
    for (int k = 0; k < 8; k++)
        for (int a = 0; a < 3; a++)
            grab[a] += in.w[k] * o->x[3 * nd[k] + a];
    for (int i = 0; i < n; i++) {
        const double *q = points + 3 * i;
        dmax = fmax(dmax, length3((double[3]){q[0] - grab[0], q[1] - grab[1], q[2] - grab[2]}));
    }
    if (stiffness * dmax > w->def.max_force)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "curve drag force of %g N (stiffness x distance) exceeds max_force "
                              "%g N", stiffness * dmax, w->def.max_force);
    /* Step j (1..S) has the target at arc length total·j/S: segment i covers the steps
     * (S·len[i]/total, S·len[i+1]/total], rounded; segments that get no step are skipped. */
    double sd = ceil(seconds / w->def.dt - 1e-9);
    const int S = sd < 1 ? 1 : sd > 1e9 ? 1000000000 : (int)sd;
    int segs = 0;
    for (int i = 0; i + 1 < n; i++)
        if (llround(S * len[i + 1] / total) > llround(S * len[i] / total))
            segs++;
    if (o->n_inputs + segs > CS_MAX_INPUTS)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "object '%s' has room for %d more inputs, the curve needs %d",
                              o->name, CS_MAX_INPUTS - o->n_inputs, segs);
    for (int i = 0; i + 1 < n; i++) {
        const int s0 = (int)llround(S * len[i] / total), s1 = (int)llround(S * len[i + 1] / total);
        if (s1 <= s0)
            continue;
        in.delay = s0;
        in.steps_total = in.steps_left = s1 - s0;
        memcpy(in.target, points + 3 * i, sizeof in.target);
        memcpy(in.target1, points + 3 * (i + 1), sizeof in.target1);
        o->inputs[o->n_inputs++] = in;
    }
    o->sleeping = false;
    o->still_steps = 0;
    return CS_OK;
}

/* Area-weighted outward normal sum of the current surface and its area. */
static double surface_area(const cs_object *o)
{
    double area = 0;
    for (int t = 0; t < o->surf.n_triangles; t++) {
        const int32_t *q = o->surf.tris + 3 * (size_t)t;
        const double *a = o->surf.pos + 3 * (size_t)q[0], *b = o->surf.pos + 3 * (size_t)q[1],
                     *c = o->surf.pos + 3 * (size_t)q[2];
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                             u[0] * v[1] - u[1] * v[0]};
        area += 0.5 * cs_vec3_norm(n);
    }
    return area;
}

int cs_world_pressure(cs_world_t *w, cs_object_id id, double pressure, double seconds,
                      char *err, size_t errlen)
{
    if (!w)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "NULL argument");
    if (!isfinite(pressure))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "pressure is not finite");
    if (!(seconds >= 0 && seconds <= 1e6))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "duration must be in [0, 1e6] s, got %g", seconds);
    cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return cs_engine_fail(err, errlen, CS_ERR_UNKNOWN_OBJECT, "no object with id %u",
                              (unsigned)id);
    const double area = surface_area(o);
    if (fabs(pressure) * area > w->def.max_force)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "pressure force of %g N (|pressure| x area %g m^2) exceeds "
                              "max_force %g N", fabs(pressure) * area, area, w->def.max_force);
    if (o->n_inputs == CS_MAX_INPUTS)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "object '%s' already has %d active inputs", o->name, CS_MAX_INPUTS);
    cs_input in = {.kind = CS_INPUT_PRESSURE, .cell = -1, .pressure = pressure,
                   .steps_left = duration_steps(seconds, w->def.dt)};
    o->inputs[o->n_inputs++] = in;
    o->sleeping = false;
    o->still_steps = 0;
    return CS_OK;
}

/* The target of a spring input at its current step. */
static void spring_target(const cs_input *in, double t[3])
{
    if (in->kind != CS_INPUT_CURVE) {
        memcpy(t, in->target, 3 * sizeof *t);
        return;
    }
    const double s = (double)(in->steps_total - in->steps_left + 1) / in->steps_total;
    for (int a = 0; a < 3; a++)
        t[a] = in->target[a] + s * (in->target1[a] - in->target[a]);
}

/* Pressure: p·(area-weighted outward normal) of each triangle, a third to each vertex, and
 * from the vertex to its cell's corners by its skinning weights. */
static void add_pressure(cs_object *o, double pressure, double *f)
{
    const cs_surface *sf = &o->surf;
    for (int t = 0; t < sf->n_triangles; t++) {
        const int32_t *q = sf->tris + 3 * (size_t)t;
        const double *a = sf->pos + 3 * (size_t)q[0], *b = sf->pos + 3 * (size_t)q[1],
                     *c = sf->pos + 3 * (size_t)q[2];
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        /* ½ u × v is the area vector; a third of p times it to each vertex */
        const double F[3] = {pressure / 6.0 * (u[1] * v[2] - u[2] * v[1]),
                             pressure / 6.0 * (u[2] * v[0] - u[0] * v[2]),
                             pressure / 6.0 * (u[0] * v[1] - u[1] * v[0])};
        for (int j = 0; j < 3; j++) {
            const int32_t vx = q[j], cell = sf->vert_cell[vx];
            const double *uvw = sf->vert_uvw + 3 * (size_t)vx;
            const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)cell;
            for (int k = 0; k < 8; k++) {
                const double wk = (CS_CORNER[k][0] ? uvw[0] : 1 - uvw[0]) *
                                  (CS_CORNER[k][1] ? uvw[1] : 1 - uvw[1]) *
                                  (CS_CORNER[k][2] ? uvw[2] : 1 - uvw[2]);
                for (int e = 0; e < 3; e++)
                    f[3 * (size_t)nd[k] + e] += wk * F[e];
            }
        }
    }
}

/* f += k_p (X − x) at every penalty-held node (seed 001 §4.2); returns ½ k_p Σ |x − X|². */
static double add_penalty_force(const cs_object *o, const double *x, double *f)
{
    double e = 0;
    if (o->penalty <= 0)
        return 0;
    for (int i = 0; i < o->n; i++) {
        if (!o->pin[i])
            continue;
        for (int a = 0; a < 3; a++) {
            const double d = x[3 * i + a] - o->cm.node_rest[3 * i + a];
            f[3 * i + a] -= o->penalty * d;
            e += 0.5 * o->penalty * d * d;
        }
    }
    return e;
}

/* y += coef · k_p p at every penalty-held node. */
static void add_penalty_operator(const cs_object *o, double coef, const double *p, double *y)
{
    if (o->penalty <= 0 || coef == 0)
        return;
    for (int i = 0; i < o->n; i++)
        if (o->pin[i])
            for (int a = 0; a < 3; a++)
                y[3 * i + a] += coef * o->penalty * p[3 * i + a];
}

void cs_object_add_input_forces(cs_object *o, double *f)
{
    for (int i = 0; i < o->n_inputs; i++) {
        const cs_input *in = &o->inputs[i];
        if (in->delay > 0)
            continue;
        if (in->kind == CS_INPUT_PRESSURE) {
            add_pressure(o, in->pressure, f);
            continue;
        }
        const int32_t *nd = o->cm.cell_nodes + 8 * in->cell;
        double F[3] = {in->force[0], in->force[1], in->force[2]};
        if (cs_input_is_spring(in)) {
            double p[3] = {0, 0, 0}, t[3];
            spring_target(in, t);
            for (int k = 0; k < 8; k++)
                for (int a = 0; a < 3; a++)
                    p[a] += in->w[k] * o->x[3 * nd[k] + a];
            for (int a = 0; a < 3; a++)
                F[a] = in->stiffness * (t[a] - p[a]);
        }
        for (int k = 0; k < 8; k++)
            for (int a = 0; a < 3; a++)
                f[3 * nd[k] + a] += in->w[k] * F[a];
    }
}

/* f = f_const + point forces + drag and curve springs + pressure at the current positions
 * (+ the penalty springs of held nodes if `penalty`). */
static void gather_forces_ex(cs_object *o, bool penalty)
{
    memcpy(o->f, o->f_const, (size_t)o->n * 3 * sizeof(double));
    if (penalty)
        add_penalty_force(o, o->x, o->f);
    cs_object_add_input_forces(o, o->f);
}

static void gather_forces(cs_object *o)
{
    gather_forces_ex(o, true);
}

static void expire_inputs(cs_object *o)
{
    int j = 0;
    for (int i = 0; i < o->n_inputs; i++) {
        cs_input *in = &o->inputs[i];
        if (in->delay > 0 ? (in->delay--, true) : --in->steps_left > 0)
            o->inputs[j++] = *in;
    }
    o->n_inputs = j;
}

/* ---------------------------------------------------------------- the implicit step */

/* The drag springs (drags and curve drags not waiting for their start) of the implicit
 * operators: y += coef·Σ k w (w·p) over each spring's cube corners. */
void cs_object_add_spring_operator(const cs_object *o, double coef, const double *p, double *y)
{
    if (coef == 0)
        return;
    for (int i = 0; i < o->n_inputs; i++) {
        const cs_input *in = &o->inputs[i];
        if (!cs_input_is_spring(in) || in->delay > 0)
            continue;
        const int32_t *nd = o->cm.cell_nodes + 8 * in->cell;
        double sum[3] = {0, 0, 0};
        for (int k = 0; k < 8; k++)
            for (int a = 0; a < 3; a++)
                sum[a] += in->w[k] * p[3 * nd[k] + a];
        for (int k = 0; k < 8; k++)
            for (int a = 0; a < 3; a++)
                y[3 * nd[k] + a] += coef * in->stiffness * in->w[k] * sum[a];
    }
}

/* Their diagonal, added to the preconditioner's blocks: coef·k w_k² per corner. */
void cs_object_add_spring_blocks(const cs_object *o, double coef, double *blocks)
{
    for (int i = 0; coef != 0 && i < o->n_inputs; i++) {
        const cs_input *in = &o->inputs[i];
        if (!cs_input_is_spring(in) || in->delay > 0)
            continue;
        for (int k = 0; k < 8; k++)
            for (int a = 0; a < 3; a++)
                blocks[9 * o->cm.cell_nodes[8 * in->cell + k] + 4 * a] +=
                    coef * in->stiffness * in->w[k] * in->w[k];
    }
}

/* The operator below with K p already computed (kp; kp may be y): y = kcoef·kp + the rest. */
static void step_operator_kp(cs_object *o, const double *p, const double *kp, double *y)
{
    const double mc = o->mcoef, kc = o->kcoef;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            y[3 * i + a] = kc * kp[3 * i + a] + mc * o->m[i] * p[3 * i + a];
    if (o->fld.has_damping && (o->cmcoef != 0 || o->ckcoef != 0)) {
        /* the damping field: + dt·α M_d p + dt·β K_d p */
        double *t = o->fld.tmp;
        if (o->ckcoef != 0) {
            cs_elastic_apply_Kd(o, p, t);
            for (int d = 0; d < 3 * o->n; d++)
                y[d] += o->ckcoef * t[d];
        }
        for (int i = 0; i < o->n; i++)
            for (int a = 0; a < 3; a++)
                y[3 * i + a] += o->cmcoef * o->fld.md[i] * p[3 * i + a];
    }
    add_penalty_operator(o, o->pcoef, p, y);
    cs_object_add_spring_operator(o, o->dcoef, p, y);
}

/* y = mcoef·M p + kcoef·K_R p + dcoef·Σ drags k w (w·p): the implicit Euler operator. With
 * the FEM models (cs_elastic_apply_K's fem path) and no damping field in it, the mass term
 * is added by the product's node pass as it writes each row (cs_fem_apply_K_mass: the same
 * bits as step_operator_kp's pass over y, which it saves); the penalty and springs, on a few
 * nodes, after it as there. */
static void step_operator(void *ctx, const double *p, double *y)
{
    cs_object *o = ctx;
    if (!o->lf && o->model != CS_MODEL_MSS &&
        !(o->fld.has_damping && (o->cmcoef != 0 || o->ckcoef != 0))) {
        cs_fem_apply_K_mass(&o->fem, o->kcoef, o->mcoef, o->m, p, y);
        add_penalty_operator(o, o->pcoef, p, y);
        cs_object_add_spring_operator(o, o->dcoef, p, y);
        return;
    }
    cs_elastic_apply_K(o, p, y);
    step_operator_kp(o, p, y, y);
}

/* The Newton operator of corotational statics: warped stiffness plus geometric stiffness. */
static void tangent_operator(void *ctx, const double *p, double *y)
{
    cs_object *o = ctx;
    cs_elastic_apply_tangent(o, p, y);
    add_penalty_operator(o, o->pcoef, p, y);
}

/* Whether the operator has drag or curve springs in it (add_spring_operator's terms). */
static bool springs_in_operator(const cs_object *o)
{
    for (int i = 0; o->dcoef != 0 && i < o->n_inputs; i++)
        if (cs_input_is_spring(&o->inputs[i]) && o->inputs[i].delay <= 0)
            return true;
    return false;
}

/* Block-Jacobi preconditioner of the current operator, inverted. One parallel pass over the
 * nodes scales the elastic blocks, adds the diagonal terms and inverts (drag springs, which
 * touch a few nodes, are added before the inversion in a pass of their own). */
static void build_preconditioner(cs_object *o)
{
    const bool damp = o->fld.has_damping && o->ckcoef != 0;
    const bool springs = springs_in_operator(o);
    if (!damp && !springs && !o->lf && o->model != CS_MODEL_MSS) {
        /* FEM (cs_elastic_diag_blocks' dispatch): the blocks, their terms and the inversion
         * in one node pass, the same operations as below */
        const cs_fem_node_terms t = {o->m, o->fld.has_damping ? o->fld.md : NULL, o->pin,
                                     o->mcoef, o->cmcoef, o->pcoef * o->penalty};
        cs_fem_precond_blocks(&o->fem, o->fem.kf, o->kcoef, &t, o->blocks);
        return;
    }
    cs_elastic_diag_blocks(o, o->blocks);
    if (damp) /* + dt·β diag(K_d) */
        cs_elastic_diag_blocks_d(o, o->fld.tmp);
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
    for (int i = 0; i < o->n; i++) {
        double *B = o->blocks + 9 * (size_t)i;
        for (int k = 0; k < 9; k++)
            B[k] *= o->kcoef;
        for (int a = 0; a < 3; a++)
            B[4 * a] += o->mcoef * o->m[i] +
                        (o->fld.has_damping ? o->cmcoef * o->fld.md[i] : 0.0) +
                        (o->pin[i] ? o->pcoef * o->penalty : 0.0);
        if (damp)
            for (int k = 0; k < 9; k++)
                B[k] += o->ckcoef * o->fld.tmp[9 * (size_t)i + k];
        if (!springs)
            cs_invert_block(B);
    }
    if (springs) {
        cs_object_add_spring_blocks(o, o->dcoef, o->blocks);
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
        for (int i = 0; i < o->n; i++)
            cs_invert_block(o->blocks + 9 * (size_t)i);
    }
}

/* Whether this object's solves use the multigrid preconditioner (cs_preconditioner); with
 * `any_size`, whether they may (auto below CS_MG_AUTO_CELLS too: statics). The hierarchy is
 * built from the FEM's cube operator (mg.h), and serves localframe objects as well: its
 * V-cycle is a preconditioner only, CG solves the model's own operator (B-spline cells and
 * all) to the same tolerance. Session 46: a 40×4×4 localframe cantilever's static solve 819
 * → 79 CG iterations, a 40×8×8 localframe beam's implicit steps 3× faster, the answers within
 * the tolerance of block Jacobi's. Not mss: its springs' operator is not the FEM's. */
static bool wants_multigrid(const cs_world_t *w, const cs_object *o, bool any_size)
{
    if (o->model != CS_MODEL_LINEAR && o->model != CS_MODEL_COROTATIONAL &&
        o->model != CS_MODEL_LOCALFRAME)
        return false;
    if (w->def.preconditioner == CS_PRECOND_JACOBI)
        return false;
    if (w->def.preconditioner == CS_PRECOND_MULTIGRID)
        return true;
    return any_size || o->cm.n_cells >= CS_MG_AUTO_CELLS || o->lag.small_mg;
}

/* Whether "auto" gives o block Jacobi by its size alone (below CS_MG_AUTO_CELLS cubes, not
 * switched by auto_small_mg): the objects whose choice auto_small_mg and statics' retry make. */
static bool auto_jacobi_by_size(const cs_world_t *w, const cs_object *o)
{
    return w->def.preconditioner == CS_PRECOND_AUTO && wants_multigrid(w, o, true) &&
           !wants_multigrid(w, o, false);
}

static bool node_fixed(const cs_object *o, int i)
{
    const uint8_t *m = o->mask + 3 * (size_t)i;
    return m[0] && m[1] && m[2];
}

/* Whether the scene holds the object's rigid motions: three nodes not on one line held in
 * every dof (fixed), at their rest positions. Penalty pins do not count: a pin of 1e-3 N/m
 * holds nothing the float V-cycle can see. */
static bool held_rigidly(const cs_object *o)
{
    const double *X = o->cm.node_rest;
    int a = 0, b = -1;
    while (a < o->n && !node_fixed(o, a))
        a++;
    double best = 0;
    for (int i = a + 1; i < o->n; i++) { /* the fixed node farthest from a */
        const double u[3] = {X[3 * i] - X[3 * a], X[3 * i + 1] - X[3 * a + 1],
                             X[3 * i + 2] - X[3 * a + 2]};
        const double d2 = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
        if (node_fixed(o, i) && d2 > best)
            best = d2, b = i;
    }
    if (b < 0)
        return false;
    const double v[3] = {X[3 * b] - X[3 * a], X[3 * b + 1] - X[3 * a + 1],
                         X[3 * b + 2] - X[3 * a + 2]};
    for (int i = a + 1; i < o->n; i++) { /* one off the line a–b by more than 1e-6 |ab| */
        const double u[3] = {X[3 * i] - X[3 * a], X[3 * i + 1] - X[3 * a + 1],
                             X[3 * i + 2] - X[3 * a + 2]};
        const double c[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                             u[0] * v[1] - u[1] * v[0]};
        if (node_fixed(o, i) && c[0] * c[0] + c[1] * c[1] + c[2] * c[2] > 1e-12 * best * best)
            return true;
    }
    return false;
}

/*
 * "auto" on an object below CS_MG_AUTO_CELLS cubes: after an implicit step solved by block
 * Jacobi in `iterations`. Multigrid breaks even with Jacobi on blocks of 1000–1700 cubes of a
 * soft material (E 1e5 Pa), where Jacobi takes 6–10 iterations a step; but the iterations grow
 * with the object's slenderness and stiffness, and multigrid's do not: at the default
 * tolerance (one thread, session 42) a 40×4×4 beam of 2.5 cm cubes took 41–84 Jacobi
 * iterations a step (E 1e5–1e11 Pa) and ran 1.7–4.4× faster with multigrid, a 20×20×2 plate
 * 49–98 (2.3–2.6× faster), an 8³ block of stiff material 30–44 (1.5–2.5×). Where Jacobi took
 * 19–21 the two were within 10–30 % either way, below 7 Jacobi was up to 35 % faster. So an
 * object whose Jacobi solves take more than CS_MG_AUTO_JACOBI_IT iterations in
 * CS_MG_AUTO_HARD_STEPS steps in a row (one impulse does not decide it) takes multigrid from
 * its next step on, until a reset or a change of its material (no back and forth). Iteration counts do not depend on the
 * thread count, so neither does the choice. Only for a body the scene holds rigidly
 * (held_rigidly): held beams and blocks ran 2× faster with multigrid up to (ω dt)² = 4.5e12.
 * A free body's rigid motions are held by its mass alone, which the single-precision V-cycle
 * loses once dt²K outweighs it by float's resolution (a 4³ block at (ω dt)² 3e11 on the ground
 * ended with 4e4 J of elastic energy under multigrid where Jacobi left 1e-12 J; free blocks
 * dropped on the ground were 2–4× slower with it from 3e6), and a free body that turns
 * rebuilds its hierarchy whenever a cell has turned 0.05 rad.
 */
static void auto_small_mg(const cs_world_t *w, cs_object *o, int iterations)
{
    if (!auto_jacobi_by_size(w, o))
        return;
    if (iterations <= CS_MG_AUTO_JACOBI_IT) {
        o->lag.hard_steps = 0;
        return;
    }
    if (!held_rigidly(o))
        return;
    if (++o->lag.hard_steps >= CS_MG_AUTO_HARD_STEPS)
        o->lag.small_mg = true;
}

/* The FEM record's rotations, which the hierarchy turns its cubes by: a localframe object's own
 * frames (the polar rotations its operator uses, cs_lf_update), which the FEM record does not
 * follow by itself (cs_elastic_update updates the model's own); FEM objects' are theirs. */
static void mg_frames(cs_object *o)
{
    if (!o->lf)
        return;
    const size_t nc = (size_t)o->cm.n_cells;
    if (o->lf->n_cells == o->cm.n_cells) {
        memcpy(o->fem.q, o->lf->q, nc * 4 * sizeof(double));
        memcpy(o->fem.R, o->lf->R, nc * 9 * sizeof(double));
    } else {
        cs_fem_update_rotations(&o->fem, o->x); /* mid-fracture: from the positions */
    }
}

/*
 * Prepare the multigrid hierarchy for operator A (step_operator's terms with the current
 * coefficients; build_preconditioner has run) and held dofs mask. Returns false when block
 * Jacobi is to be used (not wanted, or out of memory: Jacobi still solves). any_size: as
 * wants_multigrid's.
 */
static bool setup_multigrid_ex(const cs_world_t *w, cs_object *o, cs_matvec_fn A,
                               const uint8_t *mask, bool any_size)
{
    o->lag.valid = false; /* whatever the lag recorded is overwritten (pc_lag_record) */
    if (!wants_multigrid(w, o, any_size))
        return false;
    mg_frames(o);
    if (!cs_mg_matches(o->mg, &o->cm, &o->fem, o->topology_version)) {
        cs_mg_free(o->mg);
        o->mg = cs_mg_build(&o->cm, &o->fem, o->topology_version);
        if (!o->mg)
            return false;
    }
    double *s = cs_mg_cell_scale(o->mg), *dg = cs_mg_node_diag(o->mg);
    const double *kf = o->fem.kf, *kd = o->fld.has_damping ? o->fld.kd : NULL;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
    for (int c = 0; c < o->cm.n_cells; c++) {
        double a = 0, d = 0;
        for (int g = 0; g < 8; g++) {
            a += kf ? kf[8 * (size_t)c + g] : 1.0;
            d += kd ? kd[8 * (size_t)c + g] : 0.0;
        }
        s[c] = o->kcoef * a / 8 + (kd ? o->ckcoef * d / 8 : 0.0);
    }
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
    for (int i = 0; i < o->n; i++)
        dg[i] = o->mcoef * o->m[i] + (o->fld.has_damping ? o->cmcoef * o->fld.md[i] : 0.0) +
                (o->pin[i] ? o->pcoef * o->penalty : 0.0);
    for (int i = 0; o->dcoef != 0 && i < o->n_inputs; i++) {
        const cs_input *in = &o->inputs[i];
        if (!cs_input_is_spring(in) || in->delay > 0)
            continue;
        /* the spring k w wᵀ lumped by rows (Σ w = 1) */
        for (int k = 0; k < 8; k++)
            dg[o->cm.cell_nodes[8 * in->cell + k]] += o->dcoef * in->stiffness * in->w[k];
    }
    return cs_mg_setup(o->mg, &o->fem, A, o, o->blocks, mask) == 0;
}

static bool setup_multigrid(const cs_world_t *w, cs_object *o, cs_matvec_fn A,
                            const uint8_t *mask)
{
    return setup_multigrid_ex(w, o, A, mask, false);
}

/*
 * The lagged preconditioner. The implicit step's multigrid hierarchy (and the fine level's
 * block-Jacobi inverse it copies) is a preconditioner only: PCG solves the true operator to
 * the same tolerance whatever it is, so it is reused from step to step while it still fits
 * (production codes lag their preconditioners the same way). The V-cycle reads nothing but
 * its own copies (cs_mg_setup's single-precision rotations, factors, D⁻¹ and held dofs of
 * every level), so a reused hierarchy is consistently the operator of its build step. It is
 * rebuilt when anything it was built from changed: the topology (cs_mg_matches), any operator
 * coefficient (dt, Newmark against implicit Euler, penalty), the stiffness or damping field
 * and the masses (cs_elastic_fields_changed clears valid), the drag springs, the held dofs of
 * the solve (constraints, ground contacts, frozen nodes), a statics solve, a reset; and when
 * some cell's rotation has turned by more than w->pc_lag_angle since the build (measured as
 * 3 − tr(R_builtᵀ R) = 2(1 − cos θ), one pass over the cells), or after w->pc_lag_steps
 * steps. A lagged solve that misses the tolerance within the iteration limit (or within
 * twice the last fresh solve's iterations + 2, at least 8) is continued from where it
 * stopped with a fresh build. Block Jacobi alone (small objects) is rebuilt every
 * step as before: its set-up is cheap next to its iterations, and o->blocks is shared scratch
 * (the impact solve and central differences write it).
 */

/* A hash of the drag springs the operator holds (cell, weights, stiffness), FNV-1a. */
static uint64_t pc_lag_springs(const cs_object *o)
{
    uint64_t h = 14695981039346656037ull; /* FNV-1a 64 offset basis */
    for (int i = 0; i < o->n_inputs; i++) {
        const cs_input *in = &o->inputs[i];
        if (!cs_input_is_spring(in) || in->delay > 0)
            continue;
        unsigned char buf[sizeof in->cell + sizeof in->w + sizeof in->stiffness];
        memcpy(buf, &in->cell, sizeof in->cell);
        memcpy(buf + sizeof in->cell, in->w, sizeof in->w);
        memcpy(buf + sizeof in->cell + sizeof in->w, &in->stiffness, sizeof in->stiffness);
        for (size_t k = 0; k < sizeof buf; k++)
            h = (h ^ buf[k]) * 1099511628211ull;
    }
    return h;
}

static void pc_lag_coefs(const cs_object *o, double c[7])
{
    c[0] = o->mcoef;
    c[1] = o->kcoef;
    c[2] = o->cmcoef;
    c[3] = o->ckcoef;
    c[4] = o->pcoef;
    c[5] = o->penalty;
    c[6] = o->dcoef;
}

/* Can this step's solve on step_operator with held dofs mask reuse the last build? */
static bool pc_lag_reusable(const cs_world_t *w, cs_object *o, const uint8_t *mask)
{
    cs_pc_lag *L = &o->lag;
    if (!L->valid || !(w->pc_lag_angle > 0) || L->steps >= w->pc_lag_steps)
        return false;
    if (!wants_multigrid(w, o, false) ||
        !cs_mg_matches(o->mg, &o->cm, &o->fem, o->topology_version))
        return false;
    if (L->kf != o->fem.kf || L->has_damping != o->fld.has_damping)
        return false;
    double c[7];
    pc_lag_coefs(o, c);
    if (memcmp(c, L->coef, sizeof c) != 0 || L->springs != pc_lag_springs(o))
        return false;
    /* the build's held dofs and rotations: the hierarchy's own copies (cs_mg_setup) */
    if (!cs_mg_held_matches(o->mg, mask))
        return false;
    mg_frames(o);
    L->drift = o->fem.corotational ? cs_mg_rotation_drift(o->mg, o->fem.R, o->fem.q) : 0.0;
    return L->drift <= 2.0 * (1.0 - cos(w->pc_lag_angle));
}

/* After setup_multigrid built the hierarchy for step_operator: the key (the held dofs and
 * rotations it was built from are the hierarchy's own copies). */
static void pc_lag_record(const cs_world_t *w, cs_object *o)
{
    cs_pc_lag *L = &o->lag;
    L->valid = false;
    L->builds++;
    if (!(w->pc_lag_angle > 0))
        return; /* no lag: nothing to keep */
    pc_lag_coefs(o, L->coef);
    L->kf = o->fem.kf;
    L->has_damping = o->fld.has_damping;
    L->springs = pc_lag_springs(o);
    L->steps = 0;
    L->drift = 0;
    L->valid = true;
}

/* CG on A x = b with multigrid (if use_mg, after setup_multigrid) or block Jacobi. */
static cs_cg_result solve(const cs_world_t *w, cs_object *o, bool use_mg, cs_matvec_fn A,
                          const uint8_t *mask, const double *b, double *x, double tol,
                          int max_iter)
{
    if (use_mg)
        return cs_pcg_ex(&o->cg, A, o, cs_mg_vcycle, o->mg, mask, b, x, tol, max_iter,
                         cs_elastic_threads(o));
    return cs_pcg(&o->cg, A, o, o->blocks, mask, b, x, tol, max_iter, cs_elastic_threads(o));
}

/* The tangential speed above which a node arriving on the ground slides rather than sticks:
 * what friction under its own weight stops in a step, μ |g| dt (constrain_ground). */
static double slide_speed(const cs_world_t *w)
{
    const double *gv = w->def.gravity;
    return w->def.ground_friction * sqrt(gv[0] * gv[0] + gv[1] * gv[1] + gv[2] * gv[2]) *
           w->def.dt;
}

void cs_world_ground_predict(const cs_world_t *w, cs_object *o)
{
    if (!w->def.has_ground || !o->contact ||
        (o->integrator != CS_INTEGRATOR_IMPLICIT_EULER && o->integrator != CS_INTEGRATOR_NEWMARK))
        return;
    const double g = w->def.ground_height, eps = 1e-9 * (1 + fabs(g)), vs = slide_speed(w);
    for (int i = 0; i < o->n; i++) {
        const double *v = o->v + 3 * i;
        if (o->contact[i] != CS_GROUND_FREE || o->mask[3 * i + 2] || o->x[3 * i + 2] > g + eps)
            continue;
        o->contact[i] = sqrt(v[0] * v[0] + v[1] * v[1]) > vs ? CS_GROUND_SLIDE : CS_GROUND_STICK;
    }
}

/*
 * Ground contact (seed 000 has no contact model; this is Baraff–Witkin style filtered CG).
 * A node on or below the plane at the start of a step has its normal velocity constrained
 * inside the solve (to 0, or to what lifts it back onto the plane), so the implicit system
 * sees the support. Coulomb friction is in the solve too: a sticking node's tangential
 * velocity is held at 0 as well, and a sliding node feels μ fn against its tangential
 * velocity as a force in b (fn: its last normal force). After the solve the reaction
 * s·f_c = (A v1 − b) (s: b's factor on forces) tells whether the ground pushed (fn = f_c,z)
 * or would have to pull (release the node for the next step), whether a sticking node needs
 * more than μ fn to stay (it slides) and whether friction turned a sliding node back (it
 * sticks); ground_reactions re-poses the solve when that changes. A projection after the
 * step catches nodes that reached the plane during it.
 *
 * (Friction applied after the solve, node by node, as up to μ fn dt / m_i off each contact
 * node's velocity, could not hold a stiff body: its bottom nodes stopped and the nodes above
 * pulled them on, so a stiff block slid down slopes well inside the friction cone.)
 */
static int constrain_ground(const cs_world_t *w, cs_object *o, double s)
{
    const size_t n3 = (size_t)o->n * 3;
    memcpy(o->smask, o->mask, n3);
    if (!w->def.has_ground)
        return 0;
    const double g = w->def.ground_height, dt = w->def.dt, eps = 1e-9 * (1 + fabs(g));
    const double mu = w->def.ground_friction, vs = slide_speed(w);
    int count = 0;
    for (int i = 0; i < o->n; i++) {
        const double z = o->x[3 * i + 2];
        const uint8_t prev = o->contact[i];
        double *gr = o->ground + 3 * i;
        if (o->mask[3 * i + 2] || z > g + eps || prev == CS_GROUND_RELEASED) {
            o->contact[i] = CS_GROUND_FREE;
            gr[0] = gr[1] = 0;
            if (prev == CS_GROUND_FREE)
                gr[2] = 0; /* a step out of contact: its normal force is forgotten */
            continue;
        }
        o->smask[3 * i + 2] = 1;
        o->v1[3 * i + 2] = (g - z) / dt > 0 ? (g - z) / dt : 0.0;
        count++;
        /* A node that slid goes on sliding, at μ fn against its tangential velocity (or, if
         * that is zero, where its friction last pointed), and so does one that arrives, or was
         * pushed, faster than friction under its own weight stops it in a step (μ |g| dt);
         * any other sticks. fn is the node's last normal force (0 if it had none: no friction
         * until the solve has found one). */
        const double *v = o->v + 3 * i;
        const double vt = sqrt(v[0] * v[0] + v[1] * v[1]), fm = sqrt(gr[0] * gr[0] + gr[1] * gr[1]);
        const double F = mu * gr[2];
        if ((prev == CS_GROUND_SLIDE && (vt > 0 || fm > 0)) || vt > vs) {
            o->contact[i] = CS_GROUND_SLIDE;
            gr[0] = vt > 0 ? -F * v[0] / vt : F * gr[0] / fm;
            gr[1] = vt > 0 ? -F * v[1] / vt : F * gr[1] / fm;
            o->b[3 * i] += s * gr[0];
            o->b[3 * i + 1] += s * gr[1];
            continue;
        }
        o->contact[i] = CS_GROUND_STICK;
        gr[0] = gr[1] = 0;
        for (int a = 0; a < 2; a++) {
            o->smask[3 * i + a] = 1;
            if (!o->mask[3 * i + a])
                o->v1[3 * i + a] = 0.0;
        }
    }
    return count;
}

/*
 * After a solve with `contacts` ground contacts (A the solve's operator, s b's factor on
 * forces): the reactions. A node the ground would have to pull is released; the others keep
 * their normal force. A sticking node that needs more than μ fn slides, with μ fn along its
 * reaction; a sliding node whose velocity friction turned back sticks, and one whose friction
 * (posed from the last normal force) is not μ fn (to 1 %) is set to it. With resolve, those
 * changes are made to b, smask and v1 for another solve of this step (a released node loses
 * its friction and tangential hold in it) and the count of changes is returned; without, they
 * hold from the next step on (a node turned back stops here, as friction would have stopped
 * it) and 0 is returned. Before session 28 (two re-solves, a released node's friction kept,
 * friction at the last normal force) a stiff block landing tilted broke Coulomb's bound by
 * 1–2 m/s in a step or was thrown (2e11 Pa, kilometres).
 */
/* A contact node's friction in b (b, gr: its rows) from gr to nf, held dofs of the object
 * excepted (s: b's factor on forces). */
static void repose_friction(const cs_object *o, int i, double s, const double nf[2], double *b,
                            double *gr)
{
    for (int a = 0; a < 2; a++) {
        if (o->mask[3 * i + a])
            continue;
        b[a] += s * (nf[a] - gr[a]);
        gr[a] = nf[a];
    }
}

#define CS_GROUND_NET_FLOOR 0.25 /* friction scale's floor: ground_reactions */

static int ground_reactions(const cs_world_t *w, cs_object *o, int contacts, cs_matvec_fn A,
                            double s, bool resolve)
{
    if (!w->def.has_ground || contacts == 0)
        return 0;
    const double mu = w->def.ground_friction;
    double *av = o->cg.q; /* scratch: the solve is done */
    A(o, o->v1, av);
    /* What the ground pushes with (contacts) and what the released nodes it still holds down
     * pull with (held through the step, ground_reactions below): the net is the normal force
     * the object gets, and friction is bounded by μ times it, each node's share scaled by
     * net / push. μ times the pushing nodes' force alone let a block that landed on its face
     * while its other edge lifted stop dead: pull and push a couple of 24 times its weight,
     * and the push's friction took 1.55 m/s in a step where Coulomb allows 0.47. The scale
     * is at least CS_GROUND_NET_FLOOR: where push and pull nearly cancel their difference is
     * not known to better than a fraction of them (a block with (ω dt)² = 2.8e13, whose
     * couples are 1000 times its weight, slid on without friction at 0 and went unstable). */
    double push = 0, pull = 0;
    for (int i = 0; i < o->n; i++) {
        const uint8_t c = o->contact[i];
        const double fz = (av[3 * i + 2] - o->b[3 * i + 2]) / s;
        if ((c == CS_GROUND_SLIDE || c == CS_GROUND_STICK) && fz > 0)
            push += fz;
        else if (c == CS_GROUND_RELEASED && o->smask[3 * i + 2] && !o->mask[3 * i + 2] && fz < 0)
            pull -= fz;
    }
    const double net = push > 0 && pull > 0 ? fmax(push - pull, CS_GROUND_NET_FLOOR * push) / push : 1.0;
    int changes = 0;
    for (int i = 0; i < o->n; i++) {
        const uint8_t c = o->contact[i];
        if (c != CS_GROUND_SLIDE && c != CS_GROUND_STICK)
            continue;
        double *gr = o->ground + 3 * i, *v = o->v1 + 3 * i, *b = o->b + 3 * i;
        const double *ax = av + 3 * i;
        const double fn = (ax[2] - b[2]) / s, fnf = net * fn; /* fnf: its share for friction */
        if (!(fn >= 0)) {
            o->contact[i] = CS_GROUND_RELEASED; /* the ground would have to pull */
            gr[2] = 0;
            if (resolve && (gr[0] != 0 || gr[1] != 0 || c == CS_GROUND_STICK)) {
                /* no friction where the ground would pull: its friction out of b, its
                 * tangential dofs free in this step's next solve. (Its normal stays held to
                 * the step's end: freed, a stiff block's node could end the step below the
                 * plane, where the projection moves it alone; a dropped tower of 7e10 Pa
                 * blocks blew apart.) */
                repose_friction(o, i, s, (const double[2]){0, 0}, b, gr);
                for (int a = 0; a < 2; a++)
                    if (!o->mask[3 * i + a])
                        o->smask[3 * i + a] = 0;
                gr[0] = gr[1] = 0;
                changes++;
            }
            continue;
        }
        gr[2] = fn;
        double nf[2] = {0, 0};
        uint8_t nc;
        const double fm = sqrt(gr[0] * gr[0] + gr[1] * gr[1]);
        if (c == CS_GROUND_SLIDE && resolve && fm > 0 && fabs(fm - mu * fnf) > 0.01 * mu * fnf &&
            !(v[0] * gr[0] + v[1] * gr[1] > 0)) {
            /* its friction, posed from the last step's normal force, is not μ times this
             * step's (after an impact, many times above it): to it */
            repose_friction(o, i, s, (const double[2]){gr[0] * mu * fnf / fm, gr[1] * mu * fnf / fm},
                            b, gr);
            changes++;
            continue;
        }
        if (c == CS_GROUND_STICK) {
            /* the ground's tangential force holding it (held dofs of the object excepted) */
            double ft[2];
            for (int a = 0; a < 2; a++)
                ft[a] = o->mask[3 * i + a] ? 0.0 : (ax[a] - b[a]) / s;
            const double t = sqrt(ft[0] * ft[0] + ft[1] * ft[1]);
            if (t <= mu * fnf)
                continue;
            nc = CS_GROUND_SLIDE;
            nf[0] = t > 0 ? mu * fnf * ft[0] / t : 0.0;
            nf[1] = t > 0 ? mu * fnf * ft[1] / t : 0.0;
        } else if (v[0] * gr[0] + v[1] * gr[1] > 0) {
            nc = CS_GROUND_STICK; /* friction turned it back */
        } else {
            continue;
        }
        o->contact[i] = nc;
        if (!resolve) {
            /* from the next step on (constrain_ground); a node turned back stops now */
            if (nc == CS_GROUND_STICK) {
                v[0] = o->mask[3 * i] ? v[0] : 0.0;
                v[1] = o->mask[3 * i + 1] ? v[1] : 0.0;
            } else {
                gr[0] = nf[0];
                gr[1] = nf[1];
            }
            continue;
        }
        changes++;
        repose_friction(o, i, s, nf, b, gr);
        for (int a = 0; a < 2; a++) {
            if (o->mask[3 * i + a])
                continue;
            o->smask[3 * i + a] = nc == CS_GROUND_STICK;
            if (nc == CS_GROUND_STICK)
                v[a] = 0.0;
        }
    }
    return changes;
}

/* Solves of one step that may follow a change of ground contacts (ground_reactions): 2 until
 * session 28; a landing stiff block's contacts can take 5 to settle. Steps without contact
 * changes pay nothing. */
#define CS_GROUND_RESOLVES 8

/* Coulomb friction for a contact node whose downward velocity dvn the ground just removed:
 * up to μ·dvn off the tangential velocity. */
static void ground_friction(const cs_world_t *w, cs_object *o, int i, double dvn)
{
    double *v = o->v + 3 * i;
    const double vt = sqrt(v[0] * v[0] + v[1] * v[1]), mu = w->def.ground_friction;
    const double sc = vt > mu * dvn ? (vt - mu * dvn) / vt : 0.0;
    if (!o->mask[3 * i])
        v[0] *= sc;
    if (!o->mask[3 * i + 1])
        v[1] *= sc;
}

/* Nodes that went below the plane during a step are put back on it, their downward velocity
 * taken out with its Coulomb friction (ground_friction); returns how many nodes it moved. */
static int ground_project(const cs_world_t *w, cs_object *o)
{
    if (!w->def.has_ground)
        return 0;
    const double g = w->def.ground_height;
    int moved = 0;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static) reduction(+ : moved)
    for (int i = 0; i < o->n; i++) {
        double *x = o->x + 3 * i, *v = o->v + 3 * i;
        if (x[2] >= g || o->mask[3 * i + 2])
            continue;
        x[2] = g;
        const double dvn = v[2] < 0 ? -v[2] : 0.0;
        v[2] += dvn;
        ground_friction(w, o, i, dvn);
        moved++;
    }
    return moved;
}

/* Whether node i, free of the ground, ends the step below the plane (by more than eps); *z:
 * its height at the step's start. (A node released on the plane last step is free, may
 * return.) */
static inline bool ground_arriving(const cs_world_t *w, const cs_object *o, int i, bool trap,
                                   double eps, double *z)
{
    const size_t d = 3 * (size_t)i + 2;
    if (o->smask[d] || o->contact[i] != CS_GROUND_FREE)
        return false;
    const double dt = w->def.dt;
    *z = o->x[d];
    const double z1 = trap ? *z + 0.5 * dt * (o->v[d] + o->v1[d]) : *z + dt * o->v1[d];
    return z1 < w->def.ground_height - eps;
}

/*
 * Nodes that reach the ground during the step. constrain_ground holds the nodes on or below
 * the plane at the step's start; a node above it whose solved velocity takes it below by the
 * step's end (x + dt v1, or Newmark's x + dt (v + v1)/2) was left to ground_project, which
 * moved it up alone after the step: the momentum it brought never reached the rest of the
 * object, whose other nodes kept their speed. A 0.1 m cube of 1e6 Pa dropped 0.5 m took 21 J
 * of strain from a 5.2 J fall under implicit Euler (damped away in a few steps) and 140 J under
 * Newmark (kept). Such nodes are held at the velocity that puts them on the plane at the step's
 * end, without friction this step (no normal force is known yet), and the step is solved again;
 * ground_reactions then lets go of the ones the ground would have to pull. Returns how many.
 */
static int ground_arrivals(const cs_world_t *w, cs_object *o, bool trap)
{
    /* within constrain_ground's eps of the plane the projection's move is round-off */
    const double g = w->def.ground_height, dt = w->def.dt, eps = 1e-9 * (1 + fabs(g));
    /* Only the lowest layer of them at once: a small stiff block that falls through its own
     * height in a step has every node's free flight end below the plane, and holding them
     * all there flattened it (a 2 mm steel block dropped 1 mm took 1e3 J); with the lowest
     * held the solve stops the others, and those still arriving are held in the next round.
     * (The second pass runs only when the first found one.) The lowest is a minimum, the
     * same on any thread count. */
    const int nt = cs_elastic_threads(o);
    double zlow = INFINITY;
    int found = 0;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(min : zlow) reduction(+ : found)
    for (int i = 0; i < o->n; i++) {
        double z;
        if (ground_arriving(w, o, i, trap, eps, &z)) {
            zlow = z < zlow ? z : zlow;
            found++;
        }
    }
    if (found == 0)
        return 0;
    const double zcut = zlow + 0.5 * o->cm.h;
    int count = 0;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : count)
    for (int i = 0; i < o->n; i++) {
        double z;
        if (!ground_arriving(w, o, i, trap, eps, &z) || !(z < zcut))
            continue;
        const size_t d = 3 * (size_t)i + 2;
        o->smask[d] = 1;
        o->v1[d] = (g - z) / dt;
        o->contact[i] = CS_GROUND_SLIDE;
        o->ground[3 * (size_t)i] = o->ground[3 * (size_t)i + 1] = o->ground[d] = 0;
        count++;
    }
    return count;
}

/* The O(n) passes of a step around its solves (the checks, the ground's, the positions' and
 * the skin) on the object's threads (cs_elastic_threads: 1 below CS_FEM_PARALLEL_CELLS).
 * Each node's values are computed on their own, so the same bits on any thread count; the
 * reductions are a count, a minimum, a maximum or an or. */
static bool all_finite(const double *a, size_t n, int threads)
{
    int bad = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(| : bad)
    for (size_t i = 0; i < n; i++)
        bad |= !isfinite(a[i]);
    return !bad;
}

/* Node i's position and velocity finite, and its kinetic energy too: a finite speed above
 * 1e154 m/s squares to infinity (7e155 N on a 2-cube block, its ground contacts held inside
 * the step: no NaN, but no energy, momentum or next step either). A NaN or infinite velocity
 * makes m v² so (masses are positive), a NaN or infinite position the sum of its coordinates
 * (as does a sum past 1e308: absurd anyway). Until session 40 the sums ran over the whole
 * object; node by node the test needs no order of summation, so it runs on any thread count
 * with the same answer (it differs only where a sum of finite terms passed 1e308). */
static inline bool node_finite(const cs_object *o, int i)
{
    const double *v = o->v + 3 * (size_t)i, *x = o->x + 3 * (size_t)i;
    return isfinite(o->m[i] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])) &&
           isfinite(x[0] + x[1] + x[2]);
}

static bool state_finite(const cs_object *o)
{
    int bad = 0;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static) reduction(| : bad)
    for (int i = 0; i < o->n; i++)
        bad |= !node_finite(o, i);
    return !bad;
}

/* The implicit Euler operator (M + dt C + dt² K [+ dt² springs]) with Rayleigh damping
 * C = α M + β K, or α M_d + β K_d where a damping field is painted; Newmark's (trap) is
 * M + dt/2 C + dt²/4 K [+ dt²/4 springs]. */
static void set_implicit_coefs(cs_object *o, double dt, bool trap)
{
    const double c = trap ? dt / 2 : dt, k = trap ? dt * dt / 4 : dt * dt;
    if (o->fld.has_damping) {
        o->mcoef = 1;
        o->kcoef = k;
        o->cmcoef = c * o->mat.damping[0];
        o->ckcoef = c * o->mat.damping[1];
    } else {
        o->mcoef = 1 + c * o->mat.damping[0];
        o->kcoef = c * o->mat.damping[1] + k;
        o->cmcoef = o->ckcoef = 0;
    }
    o->dcoef = k;
    o->pcoef = k;
}

/*
 * The end of every integrator's step, after positions and velocities: inputs expire, the
 * surface follows the nodes, and an object whose fastest node stayed slower than sleep_speed
 * for sleep_steps steps in a row (with no input) falls asleep. Returns the ms spent skinning.
 */
static double finish_step(const cs_world_t *w, cs_object *o)
{
    const size_t n3 = (size_t)o->n * 3;
    double vmax2 = 0;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static) reduction(max : vmax2)
    for (size_t d = 0; d < n3; d += 3) {
        double s = o->v[d] * o->v[d] + o->v[d + 1] * o->v[d + 1] + o->v[d + 2] * o->v[d + 2];
        if (s > vmax2)
            vmax2 = s;
    }
    expire_inputs(o);
    const double t0 = now_ms();
    cs_surface_skin(&o->surf, &o->cm, o->x, cs_elastic_threads(o));
    const double ms = now_ms() - t0;
    if (w->def.sleep_steps > 0 && o->n_inputs == 0 && sqrt(vmax2) < w->def.sleep_speed) {
        if (++o->still_steps >= w->def.sleep_steps) {
            o->sleeping = true;
            o->wake_armed = o->wake_saved;
            memset(o->v, 0, n3 * sizeof(double));
        }
    } else {
        o->still_steps = 0;
    }
    return ms;
}

static void add_solve_stats(cs_step_stats *st, cs_cg_result r)
{
    st->cg_iterations += r.iterations;
    if (r.relres > st->cg_residual)
        st->cg_residual = r.relres;
    if (!r.converged)
        st->converged = false;
}

#define FREE_ROTATION_ITERS 4 /* fixed-point iterations of the midpoint rotation */
/* A step resolves a turn of at most CS_TURN_MAX rad. A free body spinning faster (a one-cube
 * piece born of a violent fracture in the fracture demo turned by 10.9 rad in its first step)
 * has the rigid part of its spin slowed to that rate, the rest of its velocity kept: what
 * rigid-body engines do with an angular velocity past their limit. Left to x + dt v1, as until
 * session 35, such a body stretched along every circle: a one-cube piece at 300 rad/s (5 rad a
 * step at 60 Hz) swelled to 33 times its volume in its first steps, and a block spun at
 * 25 rad/s whose nodes also shook (a tumble of 0.53–0.9 rad a step in all) flew at up to 2.8
 * times its volume. The relinearized step of a body the ground holds (relinearize_turn)
 * keeps the bound as it was: past it, nothing.
 * Where a free body's deformation moves a node by more than CS_TURN_MAX_DEFORM of its radius
 * of gyration in the step, the turned nodes' inertia is no guide to its new spin (turning
 * that piece with ω' = I'⁻¹ L blew it up: where its nodes went had 6600 times the start's
 * inertia); its velocities turn with it instead (each node's relative speed kept: momentum
 * and kinetic energy exact, angular momentum turned with the body). The bound is on |I⁻¹L| dt;
 * the step turns by the midpoint spin, which for a body unlike on its axes can differ a little. */
#define CS_TURN_MAX 0.5
#define CS_TURN_MAX_DEFORM 0.1

/* The factor that slows a spin of th rad a step to CS_TURN_MAX (1 within it). */
static double turn_scale(double th)
{
    return th > CS_TURN_MAX ? CS_TURN_MAX / th : 1.0;
}

/* R = exp(s [ω]×): the unit quaternion of that turn through cs_quat_to_mat (as rigid.c turns
 * its bodies); the identity for s|ω| = 0. */
static void rotation_exp(const double om[3], double s, double R[9])
{
    const double wn = sqrt(om[0] * om[0] + om[1] * om[1] + om[2] * om[2]), th = s * wn;
    const double k = th > 0 ? sin(0.5 * th) / wn : 0.0;
    const double q[4] = {th > 0 ? cos(0.5 * th) : 1.0, k * om[0], k * om[1], k * om[2]};
    cs_quat_to_mat(q, R);
}

/* om = R I⁻¹ Rᵀ L, I⁻¹ = Ia / det: the angular velocity of momentum L once the body (inertia
 * I) has turned by R. */
static void rotated_inverse_inertia(const double R[9], const double Ia[9], double det,
                                    const double L[3], double om[3])
{
    double RtL[3], IRtL[3];
    for (int a = 0; a < 3; a++)
        RtL[a] = R[a] * L[0] + R[3 + a] * L[1] + R[6 + a] * L[2];
    for (int a = 0; a < 3; a++)
        IRtL[a] = (Ia[3 * a] * RtL[0] + Ia[3 * a + 1] * RtL[1] + Ia[3 * a + 2] * RtL[2]) / det;
    for (int a = 0; a < 3; a++)
        om[a] = R[3 * a] * IRtL[0] + R[3 * a + 1] * IRtL[1] + R[3 * a + 2] * IRtL[2];
}

/* The rigid part of velocity field v on the nodes at o->x: the centre of mass c, its velocity
 * vc, the angular momentum L about c, the inertia I about c (its adjugate Ia and determinant
 * det: I⁻¹ = Ia / det) and ω = I⁻¹ L. */
typedef struct rigid_fit {
    double mass, c[3], vc[3], L[3], I[9], Ia[9], det, om[3];
} rigid_fit;

/* False if it cannot be had (no mass, a singular or non-finite inertia). */
static bool fit_rigid(const cs_object *o, const double *v, rigid_fit *f)
{
    memset(f, 0, sizeof *f);
    for (int i = 0; i < o->n; i++) {
        f->mass += o->m[i];
        for (int a = 0; a < 3; a++) {
            f->c[a] += o->m[i] * o->x[3 * (size_t)i + a];
            f->vc[a] += o->m[i] * v[3 * (size_t)i + a];
        }
    }
    if (!(f->mass > 0))
        return false;
    for (int a = 0; a < 3; a++) {
        f->c[a] /= f->mass;
        f->vc[a] /= f->mass;
    }
    for (int i = 0; i < o->n; i++) {
        const double *xi = o->x + 3 * (size_t)i, *vi = v + 3 * (size_t)i, m = o->m[i];
        const double r[3] = {xi[0] - f->c[0], xi[1] - f->c[1], xi[2] - f->c[2]};
        const double u[3] = {vi[0] - f->vc[0], vi[1] - f->vc[1], vi[2] - f->vc[2]};
        f->L[0] += m * (r[1] * u[2] - r[2] * u[1]);
        f->L[1] += m * (r[2] * u[0] - r[0] * u[2]);
        f->L[2] += m * (r[0] * u[1] - r[1] * u[0]);
        const double r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                f->I[3 * a + b] += m * ((a == b ? r2 : 0.0) - r[a] * r[b]);
    }
    f->det = cs_mat3_adjugate(f->I, f->Ia);
    if (!(f->det > 0) || !isfinite(f->det))
        return false;
    for (int a = 0; a < 3; a++)
        f->om[a] = (f->Ia[3 * a] * f->L[0] + f->Ia[3 * a + 1] * f->L[1] +
                    f->Ia[3 * a + 2] * f->L[2]) / f->det;
    return isfinite(f->om[0] + f->om[1] + f->om[2]);
}

/* The angle |ω| dt the rigid part of v turns by in a step (0 if it cannot be had). */
static double rigid_turn(const cs_object *o, const double *v, double dt)
{
    rigid_fit f;
    if (!fit_rigid(o, v, &f))
        return 0;
    return dt * sqrt(f.om[0] * f.om[0] + f.om[1] * f.om[1] + f.om[2] * f.om[2]);
}

/* Whether the object's model is invariant under rotation (a turn of its rigid part costs it
 * nothing): what free_body_rotation and relinearize_turn are for. */
static bool turns_freely(const cs_object *o)
{
    return o->model == CS_MODEL_COROTATIONAL || o->model == CS_MODEL_LOCALFRAME ||
           o->model == CS_MODEL_MSS;
}

/* Whether the scene holds the object: a held dof (fixed nodes) or a penalty pin. */
static bool held_by_scene(const cs_object *o)
{
    for (size_t d = 0; d < (size_t)o->n * 3; d++)
        if (o->mask[d])
            return true;
    for (int i = 0; o->pin && i < o->n; i++)
        if (o->pin[i])
            return true;
    return false;
}

/* Whether nothing holds the object in this step's solve: no held, ground-contact or frozen
 * dof (smask), no penalty pin and no drag or curve spring in its operator (a 400 N/m drag on
 * a one-cube piece of 1.6 g spun it tens of turns a second and the turn blew it up: the
 * spring's implicit pull is posed for the tangent step). */
static bool held_by_nothing(const cs_object *o)
{
    if (springs_in_operator(o))
        return false;
    for (size_t d = 0; d < (size_t)o->n * 3; d++)
        if (o->smask[d])
            return false;
    return !held_by_scene(o);
}

/*
 * The centrifugal force of a free body's turn, added to its step's right-hand side (sign +1)
 * or taken out again (−1) as s·dt·f_cf. free_body_rotation turns the rigid part of the
 * solved velocity after the solve, which gives every node its centripetal acceleration
 * −ω × (ω × r) without a force; in the body's turning frame that is the centrifugal force
 * f_i = −m_i ω × (ω × r_i), and the solve must feel it for the body to stretch as much as
 * its stiffness lets it: a 1 kPa jelly spun at 6 rad/s bulges by ρ ω² r²/E, 36 % of its
 * radius, a steel-stiff one by 1e-7 (without it every free body spun as if rigid). Its
 * torque about c, the part Euler's equations give the rigid motion (which the turn handles),
 * is taken out: f_i −= m_i α × r_i with I α = Σ r_i × f_i, so the force moves neither the
 * centre nor the angular momentum. ω from the state the step starts from (x, v), so the same
 * force is added and taken out. False (b unchanged) if it cannot be had.
 */
static bool turn_centrifugal(const cs_world_t *w, cs_object *o, double sign)
{
    rigid_fit f;
    if (!fit_rigid(o, o->v, &f))
        return false;
    const double dt = w->def.dt, s = sign * dt;
    const double th = dt * sqrt(f.om[0] * f.om[0] + f.om[1] * f.om[1] + f.om[2] * f.om[2]);
    if (!(th >= 1e-9))
        return false;
    /* a spin past CS_TURN_MAX rad a step turns at that rate (free_body_rotation) */
    const double k = turn_scale(th);
    const double om[3] = {k * f.om[0], k * f.om[1], k * f.om[2]};
    const double w2 = om[0] * om[0] + om[1] * om[1] + om[2] * om[2];
    /* the torque of −m ω × (ω × r) = m (ω² r − (ω·r) ω) about c, then α = I⁻¹ τ */
    double tau[3] = {0, 0, 0}, al[3] = {0, 0, 0};
    for (int pass = 0; pass < 2; pass++) {
        if (pass == 1)
            for (int a = 0; a < 3; a++)
                al[a] = (f.Ia[3 * a] * tau[0] + f.Ia[3 * a + 1] * tau[1] +
                         f.Ia[3 * a + 2] * tau[2]) / f.det;
        for (int i = 0; i < o->n; i++) {
            const double *xi = o->x + 3 * (size_t)i, m = o->m[i];
            const double r[3] = {xi[0] - f.c[0], xi[1] - f.c[1], xi[2] - f.c[2]};
            const double wr = om[0] * r[0] + om[1] * r[1] + om[2] * r[2];
            double fc[3];
            for (int a = 0; a < 3; a++)
                fc[a] = m * (w2 * r[a] - wr * om[a]);
            if (pass == 0) {
                tau[0] += r[1] * fc[2] - r[2] * fc[1];
                tau[1] += r[2] * fc[0] - r[0] * fc[2];
                tau[2] += r[0] * fc[1] - r[1] * fc[0];
                continue;
            }
            const double ar[3] = {al[1] * r[2] - al[2] * r[1], al[2] * r[0] - al[0] * r[2],
                                  al[0] * r[1] - al[1] * r[0]};
            for (int a = 0; a < 3; a++)
                o->b[3 * (size_t)i + a] += s * (fc[a] - m * ar[a]);
        }
    }
    return true;
}

/*
 * A second Newton iteration of the implicit Euler step, for a body the ground holds at some
 * dofs (nothing held by the scene) whose rigid part turns by at least CS_NEWTON_TURN in the
 * step: the first solve was linearized at the step's start, where a turn costs nothing, so
 * x + dt v1 left the body stretched by about (ω dt)²/2 — a block pivoting on an edge at 8
 * rad/s (60 Hz) gained 0.9 % of strain in a few steps and threw it out horizontally when its
 * face landed. Linearized again at x1 = x + dt v1 (its rotations, K₁ and force there), the
 * step's equation M (u − v) = dt (f_ext + f(x + dt u) − C u) becomes
 * (M + dt C + dt² K₁) u = b + dt (f(x1) − f(x)) + dt² K₁ v1, b the first solve's right-hand
 * side (its ground impulses included); the caller solves that again with the same held dofs,
 * so the ground's reactions and friction are posed for it. Returns true if b and the
 * operator were changed (false: not such a step, or out of memory).
 */
#define CS_NEWTON_TURN 0.02 /* rad per step: a stretch of 2e-4 */
static bool relinearize_turn(const cs_world_t *w, cs_object *o)
{
    if (!turns_freely(o) || held_by_nothing(o) || held_by_scene(o))
        return false;
    const size_t n3 = (size_t)o->n * 3;
    const double dt = w->def.dt, th = rigid_turn(o, o->v1, dt);
    if (!(th >= CS_NEWTON_TURN) || th > CS_TURN_MAX)
        return false;
    double *fx = malloc(n3 * sizeof *fx), *f1 = malloc(n3 * sizeof *f1),
           *x1 = malloc(n3 * sizeof *x1);
    if (!fx || !f1 || !x1) {
        free(fx);
        free(f1);
        free(x1);
        return false;
    }
    cs_elastic_force(o, o->x, fx, NULL); /* at the start's rotations, as b's */
    for (size_t d = 0; d < n3; d++)
        x1[d] = o->x[d] + dt * o->v1[d];
    cs_elastic_update(o, x1);
    cs_elastic_force(o, x1, f1, NULL);
    cs_elastic_apply_K(o, o->v1, x1); /* K₁ v1 (x1 no longer needed) */
    for (size_t d = 0; d < n3; d++)
        o->b[d] += dt * (f1[d] - fx[d]) + dt * dt * x1[d];
    free(fx);
    free(f1);
    free(x1);
    build_preconditioner(o);
    return true;
}

/* A velocity field u turned with a free body (free_body_rotation's R): u = ū + R (u − ū), ū
 * its mass-weighted mean. What the warm start's history gets (cs_cg_map_history), so that the
 * changes the next guess searches are the solves' own, not the turn's. */
typedef struct turn_ctx {
    const cs_object *o;
    const double *R;
    double mass; /* Σ m_i */
} turn_ctx;

static void turn_velocities(void *ctx, double *u)
{
    const turn_ctx *t = ctx;
    const cs_object *o = t->o;
    const double *R = t->R;
    double uc[3] = {0, 0, 0};
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            uc[a] += o->m[i] * u[3 * (size_t)i + a];
    for (int a = 0; a < 3; a++)
        uc[a] /= t->mass;
    for (int i = 0; i < o->n; i++) {
        double *ui = u + 3 * (size_t)i;
        const double q[3] = {ui[0] - uc[0], ui[1] - uc[1], ui[2] - uc[2]};
        for (int a = 0; a < 3; a++)
            ui[a] = uc[a] + R[3 * a] * q[0] + R[3 * a + 1] * q[1] + R[3 * a + 2] * q[2];
    }
}

/*
 * The rigid part of a free body's implicit Euler step, moved along its rotation instead of
 * its tangents. x1 = x + dt v1 moves every node along the tangent of its circle, which
 * stretches a spinning body by (ω dt)²/2 per step: the step's operator, linearized at the
 * start's rotations, sees an infinitesimal rotation as free and cannot pull that back, so a
 * body spinning at ω dt = 0.1 (6 rad/s at 60 Hz) flew 0.5–0.9 % inflated for as long as it
 * spun, whatever its stiffness — a steel-stiff 0.2 m block carried 250 times its kinetic
 * energy as strain and gave some back when it landed (README Known limitations, session 31).
 * Here, for a body nothing holds in the step (no held, ground-contact, arrival or frozen dof,
 * no penalty pin) of a rotation-invariant model (corotational, localframe, mss; a linear
 * object must inflate under rotation, that is the model), v1 is split about the centre of
 * mass c into its mean vc, the rotation ω = I⁻¹L of its angular momentum L (I the nodes'
 * inertia about c) and the rest, d = v1 − vc − ω × r (r = x − c; d carries neither momentum):
 * x1 = c + dt vc + r1, r1 = R r + dt d, R the turn of the step (below), and the velocity the
 * body leaves with is v1 = vc + ω' × r1 + R d, its deformation turned with it and
 * ω' = I₁⁻¹ (L − Σ m r1 × R d) (I₁ the inertia of the r1), so that momentum and angular
 * momentum are kept to round-off. The turn gives each node its centripetal acceleration
 * without a force: the solve felt the centrifugal force instead (turn_centrifugal). A spin
 * past CS_TURN_MAX rad a step is first slowed to it (ω → ω CS_TURN_MAX / (|ω| dt), in v1); a
 * deformation step past CS_TURN_MAX_DEFORM turns the velocities with the body, v1 = vc +
 * R (v1 − vc), instead of spinning at ω'. A body that turns by less than 1e-9 rad in the step
 * is left to x + dt v1 (at rest, sliding), and so is one a node of which would end below the
 * ground (with its spin slowed, if it was). Writes x1 into x_out and v1 in place, the turn into
 * R and Σ m_i into mass; false if the step is not such a body's (v1 unchanged but for that
 * slowing). Fixed order (one thread): the result does not depend on the thread count.
 */
static bool free_body_rotation(const cs_world_t *w, cs_object *o, double *x_out, double R[9],
                               double *mass)
{
    rigid_fit f;
    if (!turns_freely(o) || !held_by_nothing(o) || !fit_rigid(o, o->v1, &f))
        return false;
    *mass = f.mass;
    const double dt = w->def.dt, *x = o->x, *c = f.c, *vc = f.vc, *L = f.L, *Ia = f.Ia;
    const double det = f.det, *om = f.om;
    double *v = o->v1;
    const double th = dt * sqrt(om[0] * om[0] + om[1] * om[1] + om[2] * om[2]);
    if (!(th >= 1e-9))
        return false;
    if (th > CS_TURN_MAX) {
        /* a spin the step cannot resolve: its rigid part slowed to CS_TURN_MAX rad a step */
        const double k = 1 - turn_scale(th);
        for (int i = 0; i < o->n; i++) {
            const double *xi = x + 3 * (size_t)i;
            const double r[3] = {xi[0] - c[0], xi[1] - c[1], xi[2] - c[2]};
            v[3 * (size_t)i] -= k * (om[1] * r[2] - om[2] * r[1]);
            v[3 * (size_t)i + 1] -= k * (om[2] * r[0] - om[0] * r[2]);
            v[3 * (size_t)i + 2] -= k * (om[0] * r[1] - om[1] * r[0]);
        }
        if (!fit_rigid(o, v, &f))
            return false;
    }
    /* R = exp(dt [ωm]×), ωm the rotation at the step's midpoint orientation Rh = exp(dt/2
     * [ωm]×): ωm = Rh I⁻¹ Rhᵀ L, by fixed-point iteration from ω (time-reversible: a tumbling
     * body's energy stays bounded; turning by ω itself pumped the intermediate-axis tumble of
     * stab_spin_tumbling_block by 55 % over 10 000 steps) */
    double Rh[9], om1[3] = {0, 0, 0}, om_m[3] = {om[0], om[1], om[2]};
    for (int it = 0; it < FREE_ROTATION_ITERS; it++) {
        rotation_exp(om_m, 0.5 * dt, Rh);
        rotated_inverse_inertia(Rh, Ia, det, L, om_m);
    }
    rotation_exp(om_m, dt, R);
    /* two passes: the positions, refused if one would end below the ground (where x + dt v1
     * did not: ground_arrivals held every node that did, and a held node ends this function
     * above), with their inertia I' about the new centre and the angular momentum Ld of the
     * turned deformation velocities; then the velocities, ω' = I'⁻¹ (L − Ld), which keeps the
     * momentum and the angular momentum exactly (what the nodes carry is what the solve left);
     * or, past the deformation bound, turned with the body, which keeps the momentum and the
     * kinetic energy exactly but turns L with R (not kept for a tumbling body) */
    double I1[9] = {0}, Ld[3] = {0, 0, 0}, d2max = 0;
    for (int pass = 0; pass < 2; pass++) {
        if (pass == 1) {
            /* Σ m r² = tr(I)/2; a deformation step past CS_TURN_MAX_DEFORM of the radius of
             * gyration, or a degenerate I': the velocities turned with the body, as the warm
             * start's history is (turn_velocities) */
            const double rg2 = 0.5 * (f.I[0] + f.I[4] + f.I[8]) / f.mass;
            double Ia1[9];
            const double det1 = cs_mat3_adjugate(I1, Ia1);
            if (!(d2max <= CS_TURN_MAX_DEFORM * CS_TURN_MAX_DEFORM * rg2) || !(det1 > 0) ||
                !isfinite(det1)) {
                turn_velocities(&(turn_ctx){o, R, f.mass}, v);
                return true;
            }
            const double Lr[3] = {L[0] - Ld[0], L[1] - Ld[1], L[2] - Ld[2]};
            for (int a = 0; a < 3; a++)
                om1[a] = (Ia1[3 * a] * Lr[0] + Ia1[3 * a + 1] * Lr[1] + Ia1[3 * a + 2] * Lr[2]) /
                         det1;
        }
        for (int i = 0; i < o->n; i++) {
            const double *xi = x + 3 * (size_t)i;
            double *vi = v + 3 * (size_t)i;
            const double r[3] = {xi[0] - c[0], xi[1] - c[1], xi[2] - c[2]};
            const double d[3] = {vi[0] - vc[0] - (om[1] * r[2] - om[2] * r[1]),
                                 vi[1] - vc[1] - (om[2] * r[0] - om[0] * r[2]),
                                 vi[2] - vc[2] - (om[0] * r[1] - om[1] * r[0])};
            double Rr[3], Rd[3];
            for (int a = 0; a < 3; a++) {
                Rr[a] = R[3 * a] * r[0] + R[3 * a + 1] * r[1] + R[3 * a + 2] * r[2];
                Rd[a] = R[3 * a] * d[0] + R[3 * a + 1] * d[1] + R[3 * a + 2] * d[2];
            }
            /* the node's place about the new centre c + dt vc */
            const double r1[3] = {Rr[0] + dt * d[0], Rr[1] + dt * d[1], Rr[2] + dt * d[2]};
            if (pass == 0) {
                d2max = fmax(d2max, dt * dt * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
                double *xo = x_out + 3 * (size_t)i;
                for (int a = 0; a < 3; a++)
                    xo[a] = c[a] + dt * vc[a] + r1[a];
                if (w->def.has_ground && xo[2] < w->def.ground_height)
                    return false;
                const double m = o->m[i], q2 = r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2];
                for (int a = 0; a < 3; a++)
                    for (int b = 0; b < 3; b++)
                        I1[3 * a + b] += m * ((a == b ? q2 : 0.0) - r1[a] * r1[b]);
                Ld[0] += m * (r1[1] * Rd[2] - r1[2] * Rd[1]);
                Ld[1] += m * (r1[2] * Rd[0] - r1[0] * Rd[2]);
                Ld[2] += m * (r1[0] * Rd[1] - r1[1] * Rd[0]);
                continue;
            }
            const double wr[3] = {om1[1] * r1[2] - om1[2] * r1[1],
                                  om1[2] * r1[0] - om1[0] * r1[2],
                                  om1[0] * r1[1] - om1[1] * r1[0]};
            for (int a = 0; a < 3; a++)
                vi[a] = vc[a] + wr[a] + Rd[a];
        }
    }
    return true;
}

/* The end of a step that solved for the new velocities v1 (implicit Euler, Newmark, central
 * differences): positions (x += dt v1, or x_end when the step computed them: Newmark), ground
 * projection, finish_step, and the stage times t[0..4] (inputs, rotations, right-hand side,
 * solve) and solve statistics into st. el_end, if finite, is the elastic energy at x_end,
 * kept as the object's cached energy unless the ground projection moved a node.
 *
 * Returns CS_ERR_DIVERGED, with the positions as they were, when the new state is not finite
 * although v1 was: x + dt·v1 can overflow, and the ground's friction squares the tangential
 * speed (7e155 N on a block resting on the ground: NaN from a finite v1,
 * world_nonfinite_state_after_the_solve_is_undone). Such a state used to be kept, and NaN
 * speeds then passed the sleep test: the object could sleep, never stepped again, and the
 * run end with exit status 0. (o->b, the right-hand side, is scratch by now.) */
static int end_solved_step(const cs_world_t *w, cs_object *o, cs_step_stats *st,
                           const double t[5], cs_cg_result r, const double *x_end, double el_end)
{
    const size_t n3 = (size_t)o->n * 3;
    const double dt = w->def.dt;
    /* one pass: the old positions kept, the new state written and checked (node_finite); the
     * ground's projection may change it again, and then it is checked again */
    int bad = 0;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static) reduction(| : bad)
    for (int i = 0; i < o->n; i++) {
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * (size_t)i + a;
            const double v1 = o->v1[d];
            o->b[d] = o->x[d];
            o->x[d] = x_end ? x_end[d] : o->x[d] + dt * v1;
            o->v[d] = v1;
        }
        bad |= !node_finite(o, i);
    }
    const int limited = !bad ? cs_strain_limit(o, dt) : 0;
    if (limited < 0) {
        memcpy(o->x, o->b, n3 * sizeof(double));
        return CS_ERR_NOMEM;
    }
    const int moved = ground_project(w, o) + limited;
    if (bad || (moved > 0 && !state_finite(o))) {
        memcpy(o->x, o->b, n3 * sizeof(double));
        o->elastic_energy_valid = false;
        return CS_ERR_DIVERGED;
    }
    o->elastic_energy = el_end;
    o->elastic_energy_valid = x_end && isfinite(el_end) && moved == 0;
    const double t5 = now_ms();
    st->ms_skin += finish_step(w, o);
    st->ms_inputs += t[1] - t[0];
    st->ms_rotations += t[2] - t[1];
    st->ms_rhs += t[3] - t[2];
    st->ms_solve += t[4] - t[3];
    st->ms_post += t5 - t[4];
    add_solve_stats(st, r);
    st->objects_stepped++;
    return CS_OK;
}

/* ---------------------------------------------------------------- active regions */

/*
 * Active regions (issue 7; seed 000 §2.2: "only a subset of vertices and cube elements are
 * passed to the solver"). For linear and corotational FEM objects stepped by implicit Euler
 * (not fracturing ones), when active_steps > 0. s = active_speed.
 *
 * Freezing. After each solve, a node that took part in it is calm when |v_i| < s and its net
 * force f_i satisfies |f_i|·dt/m_i < s/16, where dt·f_i = (A v1)_i − m_i v_i (A the implicit
 * operator, v the velocity before the step): at a free dof (A v1)_i = b_i, so this is
 * dt·(elastic + gravity + loads + inputs + penalty springs) at the start of the step; at a
 * dof in ground contact it adds the ground's impulse. Held dofs do not count, nor do nodes an
 * input acts on. A node calm for active_steps steps in a row is frozen: v_i = 0, it stays
 * where it is, and every solve holds its three dofs like a held node's (the masked CG). A cell
 * whose 8 nodes are frozen is inactive: the element passes skip it (fem.cell_active) and the
 * statistics count it out. That is exact for the held problem: an inactive cell couples
 * frozen dofs only, whose rows the masked CG never reads.
 *
 * Waking (before the next step). A frozen node wakes when
 *   - held still, it needed a force: after the solve its reaction r_i = b_i + dt·f_skip_i −
 *     (A v1)_i (the impulse that kept it at rest through the step: elastic force of all its
 *     cells, loads, and the pull of moving neighbours through the implicit operator) has
 *     |r_i|/m_i ≥ s/8 (an eighth of s as the speed it would gain in one step if let go); a
 *     downward r_z on the ground is the ground's and does not count. Such nodes are woken
 *     and the step is solved again (warm start), up to CS_ACTIVE_MAX_RESOLVES times;
 *   - a node of one of its active cells moved faster than s in the step;
 *   - an input acts on its cube (a pressure: every node);
 *   - its velocity is not 0 (pushed outside the step: a rigid contact);
 *   - act_wake_all (reset, statics, paint) or the mesh changed size: all nodes wake.
 * f_skip is the elastic force of the inactive cells, updated when cells change state (their
 * nodes do not move while they are inactive), so r_i is a frozen node's whole residual.
 *
 * So a frozen node is held within m_i·s/(8 dt) of force balance with everything around it,
 * with a factor 2 of hysteresis between freezing and waking. The factor 1/8 and the re-solves
 * are measured choices (bench_active, README "Active regions"): the difference from the
 * all-active solve fell from 5 % to 1.3 % of a poke's displacement going from 1/2 to 1/8. The object as a whole still falls
 * asleep by sleep.speed and sleep.steps as before (frozen nodes have v = 0).
 */
#define CS_ACTIVE_MAX_RESOLVES 4 /* extra solves per step for nodes their reactions woke */
#ifndef CS_ACTIVE_WAKE
#define CS_ACTIVE_WAKE 0.125     /* a reaction wakes at |r|/m >= this · active_speed */
#endif

static bool active_wanted(const cs_world_t *w, const cs_object *o)
{
    return w->def.active_steps > 0 && !o->fracture && o->integrator == CS_INTEGRATOR_IMPLICIT_EULER &&
           (o->model == CS_MODEL_LINEAR || o->model == CS_MODEL_COROTATIONAL);
}

/* Every node awake, every cell active, no inactive force. */
static void active_reset(cs_object *o)
{
    memset(o->frozen, 0, (size_t)o->n);
    memset(o->calm, 0, (size_t)o->n * sizeof *o->calm);
    memset(o->f_skip, 0, (size_t)o->n * 3 * sizeof *o->f_skip);
    memset(o->cell_active, 1, (size_t)o->cm.n_cells);
    o->n_frozen = 0;
    o->n_active_cells = o->cm.n_cells;
    o->act_wake_all = false;
}

/* The arrays for the current mesh (all awake when new); false on out of memory. */
static bool active_alloc(cs_object *o)
{
    if (o->frozen && o->act_nodes == o->n && o->act_cells == o->cm.n_cells)
        return true;
    free(o->frozen);
    free(o->cell_active);
    free(o->cell_flip);
    free(o->calm);
    free(o->f_skip);
    o->frozen = malloc((size_t)o->n);
    o->calm = malloc((size_t)o->n * sizeof *o->calm);
    o->f_skip = malloc((size_t)o->n * 3 * sizeof *o->f_skip);
    o->cell_active = malloc((size_t)o->cm.n_cells);
    o->cell_flip = malloc((size_t)o->cm.n_cells);
    if (!o->frozen || !o->calm || !o->f_skip || !o->cell_active || !o->cell_flip) {
        free(o->frozen);
        free(o->cell_active);
        free(o->cell_flip);
        free(o->calm);
        free(o->f_skip);
        o->frozen = o->cell_active = o->cell_flip = NULL;
        o->calm = NULL;
        o->f_skip = NULL;
        o->act_nodes = o->act_cells = 0;
        o->n_frozen = 0;
        return false;
    }
    o->act_nodes = o->n;
    o->act_cells = o->cm.n_cells;
    active_reset(o);
    return true;
}

static void active_wake(cs_object *o, int32_t i)
{
    if (o->frozen[i]) {
        o->frozen[i] = 0;
        o->n_frozen--;
    }
    o->calm[i] = 0;
}

/* f_skip += sign · (elastic force of the cells selected in o->cell_flip) at the current x. */
static void active_cells_force(cs_object *o, double sign)
{
    double *t = o->cg.z; /* scratch outside the solve */
    o->fem.cell_active = o->cell_flip;
    cs_fem_update_rotations(&o->fem, o->x);
    cs_fem_elastic_force(&o->fem, o->x, t, NULL);
    o->fem.cell_active = NULL;
    for (size_t d = 0; d < 3 * (size_t)o->n; d++)
        o->f_skip[d] += sign * t[d];
}

/* Cells follow the frozen flags; f_skip follows the cells that change state. */
static void active_refresh(cs_object *o)
{
    const int nc = o->cm.n_cells;
    int on = 0, off = 0, act = 0;
    for (int c = 0; c < nc; c++) {
        const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
        uint8_t a = 0;
        for (int k = 0; k < 8 && !a; k++)
            a = !o->frozen[nd[k]];
        act += a;
        on += a && !o->cell_active[c];
        off += !a && o->cell_active[c];
    }
    if (on > 0) {
        for (int c = 0; c < nc; c++) {
            const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
            uint8_t a = 0;
            for (int k = 0; k < 8 && !a; k++)
                a = !o->frozen[nd[k]];
            o->cell_flip[c] = a && !o->cell_active[c];
        }
        active_cells_force(o, -1.0);
    }
    for (int c = 0; c < nc; c++) {
        const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
        uint8_t a = 0;
        for (int k = 0; k < 8 && !a; k++)
            a = !o->frozen[nd[k]];
        o->cell_flip[c] = !a && o->cell_active[c];
        o->cell_active[c] = a;
    }
    if (off > 0)
        active_cells_force(o, 1.0);
    if (act == nc) /* none inactive: drop what rounding left */
        memset(o->f_skip, 0, (size_t)o->n * 3 * sizeof *o->f_skip);
    o->n_active_cells = act;
}

/* Before a step: wake what inputs and outside pushes reach, then the cells and f_skip. */
static void active_begin(const cs_world_t *w, cs_object *o)
{
    o->fem.cell_active = NULL;
    if (!active_wanted(w, o) || !active_alloc(o))
        return;
    if (o->act_wake_all)
        active_reset(o);
    if (o->n_frozen == 0 && o->n_active_cells == o->cm.n_cells)
        return;
    for (int i = 0; i < o->n_inputs && o->n_frozen > 0; i++) {
        const cs_input *in = &o->inputs[i];
        if (in->delay > 0)
            continue;
        if (in->kind == CS_INPUT_PRESSURE) {
            for (int j = 0; j < o->n; j++)
                active_wake(o, j);
            continue;
        }
        for (int k = 0; k < 8; k++)
            active_wake(o, o->cm.cell_nodes[8 * (size_t)in->cell + k]);
    }
    for (int i = 0; i < o->n && o->n_frozen > 0; i++)
        if (o->frozen[i] &&
            (o->v[3 * i] != 0 || o->v[3 * i + 1] != 0 || o->v[3 * i + 2] != 0))
            active_wake(o, i);
    active_refresh(o);
    if (o->n_active_cells < o->cm.n_cells)
        o->fem.cell_active = o->cell_active;
}

/* Into the solve: frozen nodes' dofs held at v = 0, the others as constrain_ground left them
 * (held, z in ground contact, and x, y too if sticking). */
static void active_hold(cs_object *o)
{
    if (!o->frozen)
        return;
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * (size_t)i + a;
            const uint8_t c = o->contact[i];
            o->smask[d] = o->mask[d] || (a == 2 && c == CS_GROUND_SLIDE) ||
                          c == CS_GROUND_STICK || o->frozen[i];
            if (o->frozen[i])
                o->v1[d] = 0;
        }
}

/* After the solve (before the ground's friction changes v1): av = A v1 where needed. */
static bool active_needs_av(const cs_world_t *w, const cs_object *o, int contacts)
{
    return active_wanted(w, o) && o->frozen && (o->n_frozen > 0 || contacts > 0);
}

/* Wake frozen nodes by their reaction (av = A v1, or NULL when there is none to test);
 * returns how many woke. */
static int active_reactions(const cs_world_t *w, cs_object *o, const double *av)
{
    if (!av || o->n_frozen == 0)
        return 0;
    const int before = o->n_frozen;
    const double dt = w->def.dt, s = w->def.active_speed;
    const double g = w->def.ground_height, eps = 1e-9 * (1 + fabs(g));
    for (int i = 0; i < o->n; i++) {
        if (!o->frozen[i])
            continue;
        double r[3];
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * (size_t)i + a;
            r[a] = o->mask[d] ? 0.0 : o->b[d] + dt * o->f_skip[d] - av[d];
        }
        if (w->def.has_ground && o->x[3 * i + 2] <= g + eps && r[2] < 0)
            r[2] = 0;
        if (cs_vec3_norm(r) >= CS_ACTIVE_WAKE * s * o->m[i])
            active_wake(o, i);
    }
    return before - o->n_frozen;
}

/* After the step's velocities v1 (before they become v): the neighbours of fast nodes wake,
 * calm nodes count, and those calm long enough freeze. */
static void active_end(const cs_world_t *w, cs_object *o, const double *av)
{
    if (!active_wanted(w, o) || !o->frozen)
        return;
    const double s = w->def.active_speed;
    const int nc = o->cm.n_cells;
    /* nodes an input acts on do not freeze (calm −1 here, 0 after the count below) */
    for (int i = 0; i < o->n_inputs; i++) {
        const cs_input *in = &o->inputs[i];
        if (in->delay > 0)
            continue;
        for (int j = 0; in->kind == CS_INPUT_PRESSURE && j < o->n; j++)
            o->calm[j] = -1;
        for (int k = 0; in->kind != CS_INPUT_PRESSURE && k < 8; k++)
            o->calm[o->cm.cell_nodes[8 * (size_t)in->cell + k]] = -1;
    }
    /* a node faster than s wakes the frozen nodes of its cells */
    for (int c = 0; c < nc && o->n_frozen > 0; c++) {
        if (!o->cell_active[c])
            continue;
        const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
        bool fast = false;
        for (int k = 0; k < 8 && !fast; k++)
            fast = cs_vec3_norm(o->v1 + 3 * (size_t)nd[k]) >= s;
        if (fast)
            for (int k = 0; k < 8; k++)
                if (o->frozen[nd[k]])
                    active_wake(o, nd[k]);
    }
    for (int i = 0; i < o->n; i++) {
        if (o->frozen[i])
            continue;
        bool calm = cs_vec3_norm(o->v1 + 3 * (size_t)i) < s;
        double f[3] = {0, 0, 0};
        for (int a = 0; a < 3 && calm; a++) {
            const size_t d = 3 * (size_t)i + a;
            if (o->mask[d])
                continue;
            f[a] = (o->smask[d] && av ? av[d] : o->b[d]) - o->m[i] * o->v[d];
        }
        calm = calm && cs_vec3_norm(f) < 0.5 * CS_ACTIVE_WAKE * s * o->m[i];
        if (!calm) {
            o->calm[i] = 0;
            continue;
        }
        if (++o->calm[i] >= w->def.active_steps) {
            o->frozen[i] = 1;
            o->n_frozen++;
            for (int a = 0; a < 3; a++)
                o->v1[3 * (size_t)i + a] = 0;
        }
    }
}

/*
 * Implicit Euler (seed 000 §2.2): one linear solve per step for the new velocities. With trap,
 * Newmark's average acceleration instead (β = 1/4, γ = 1/2: the trapezoidal rule, which for
 * forces linear in x is the implicit midpoint rule): x1 = x + dt (v + v1)/2 and
 *     M (v1 − v) = dt [f_el(x_m) + f(x) − C (v + v1)/2 − S (x1 − x)/2],  x_m = (x + x1)/2,
 * S the drag and penalty springs. The elastic force is linearized about the predicted
 * midpoint x̃ = x + dt v/2, where the element rotations are taken: x_m − x̃ = dt (v1 − v)/4,
 * f_el(x_m) ≈ f_el(x̃) − K̃ dt (v1 − v)/4. With A = M + dt/2 C + dt²/4 (K̃ + S):
 *     A v1 = 2 M v − A v + dt (f + f_el(x̃)) + dt²/2 K̃ v.
 * For a linear model this is the trapezoidal rule exactly (a linear undamped object keeps its
 * energy); for the corotational ones, rotations at x rather than x̃ pump energy into a
 * tumbling body (+4 %/s at 1/60 s, measured).
 */
static double kinetic_energy(const cs_object *o, const double *v)
{
    double e = 0;
    for (int i = 0; i < o->n; i++) {
        const double *u = v + 3 * i;
        e += 0.5 * o->m[i] * (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    }
    return e;
}

/* Newmark's energy guard: the relative rise of kinetic + elastic energy over a step, beyond
 * the work of the external forces, at which the step is redone by implicit Euler. */
#define CS_NEWMARK_GUARD 1e-2

/*
 * A free object's momentum as its step's equations give it (implicit Euler and Newmark). With
 * no dof held (fixed, on the ground, frozen), no pins and no springs, the rows of the
 * operator sum to a_i = mcoef m_i (+ cmcoef md_i): the stiffness and K_d annihilate
 * translations and are symmetric. So Σ_i a_i v1_i = Σ_i b_i exactly, whatever the stiffness,
 * while CG stops at a residual relative to ‖b‖ (or to the step's start), and for a stiff,
 * strained object b is mostly the elastic forces' dt f_el, many times its momentum and the
 * impulse of gravity: a steel block (2e11 Pa) set turning by a contact took 0–1 iterations per
 * step with the whole of gravity's impulse in the residual, and flew on in a straight line, up
 * and away. The translation the solve left out is added to every node (K 1 = 0: no elastic
 * force changes). Sums in node order: the same on any thread count.
 */
static void momentum_exact(const cs_object *o, const double *b, double *v1)
{
    const size_t n3 = (size_t)o->n * 3;
    if (o->n == 0 || memchr(o->smask, 1, n3))
        return;
    if (springs_in_operator(o))
        return;
    for (int i = 0; o->penalty > 0 && o->pcoef != 0 && i < o->n; i++)
        if (o->pin[i])
            return;
    const bool fld = o->fld.has_damping && o->cmcoef != 0;
    double r[3] = {0, 0, 0}, asum = 0;
    for (int i = 0; i < o->n; i++) {
        const double a = o->mcoef * o->m[i] + (fld ? o->cmcoef * o->fld.md[i] : 0.0);
        asum += a;
        for (int k = 0; k < 3; k++)
            r[k] += b[3 * (size_t)i + k] - a * v1[3 * (size_t)i + k];
    }
    if (!(asum > 0))
        return;
    for (int i = 0; i < o->n; i++)
        for (int k = 0; k < 3; k++)
            v1[3 * (size_t)i + k] += r[k] / asum;
}

/*
 * The stopping reference's cap for an implicit step with ground contacts: ‖M v + dt f‖ over
 * the free dofs, the step's momentum and external impulse (cs_cg_work.stop_cap). The ground's
 * reactions are read off the residual (ground_reactions): the normal force that decides
 * release and sets the next step's friction. A stiff, strained object's b and its step
 * residual are mostly dt f_el, and a fraction of that left those reactions wrong by many
 * times the object's weight (friction of 500 N per node on a 1 kg block after a landing).
 * Relative to the momentum and weight, the reactions are what they are.
 */
static double contact_cap(const cs_object *o, double dt)
{
    double s = 0;
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * (size_t)i + a;
            if (!o->smask[d]) {
                const double t = o->m[i] * o->v[d] + dt * o->f[d];
                s += t * t;
            }
        }
    return sqrt(s);
}

static int step_implicit(cs_world_t *w, cs_object *o, cs_step_stats *st, bool trap)
{
    /* Newmark: a step after a rigid contact pushed the object is implicit Euler's (the
     * contact solve modelled that step's response, and it damps the contact's jolt) */
    if (trap && o->contact_pushed)
        trap = false;
    o->contact_pushed = false;
    const double dt = w->def.dt;
    const size_t n3 = (size_t)o->n * 3;
    double t0 = now_ms();
    active_begin(w, o);
    gather_forces(o);
    double e_start = 0;
    if (trap) {
        if (!o->elastic_energy_valid) {
            o->elastic_energy = cs_elastic_energy(o, o->x);
            o->elastic_energy_valid = true;
        }
        e_start = kinetic_energy(o, o->v) + o->elastic_energy;
    }
    double t1 = now_ms();
    /* Newmark: the elastic state and force at the predicted midpoint x̃ = x + dt v/2 */
    const double *xe = o->x;
    if (trap) {
        double *xt = o->cg.zo; /* scratch until the solve */
        for (size_t d = 0; d < n3; d++)
            xt[d] = o->x[d] + 0.5 * dt * o->v[d];
        xe = xt;
    }
    cs_elastic_update(o, xe);
    double t2 = now_ms();
    /* b = M v + dt (f + f_el(x)); the solve is for v1 (implicit Euler, Rayleigh damping). */
    cs_elastic_force(o, xe, o->b, NULL);
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++) {
            size_t d = 3 * (size_t)i + a;
            o->b[d] = o->m[i] * o->v[d] + dt * (o->f[d] + o->b[d]);
        }
    set_implicit_coefs(o, dt, trap);
    if (trap) {
        double *av = o->cg.q, *kv = o->cg.z; /* scratch until the solve */
        cs_elastic_apply_K(o, o->v, kv);
        step_operator_kp(o, o->v, kv, av);
        const double c = 0.5 * dt * dt;
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
        for (int i = 0; i < o->n; i++)
            for (int a = 0; a < 3; a++) {
                const size_t d = 3 * (size_t)i + a;
                o->b[d] += o->m[i] * o->v[d] - av[d] + c * kv[d];
            }
    }
    /* (the preconditioner: built, or reused, in the solve loop below) */
    /* Initial guess: v, improved inside the solve along the last step's change (cs_cg_guess);
     * held dofs 0, ground contacts their lift (constrain_ground). */
    o->cg.threads = cs_elastic_threads(o); /* cs_cg_guess's and cs_cg_record's passes */
    cs_cg_guess(&o->cg, o->v, o->v1);
#pragma omp parallel for num_threads(cs_elastic_threads(o)) schedule(static)
    for (size_t d = 0; d < n3; d++)
        if (o->mask[d])
            o->v1[d] = 0.0;
    int contacts = constrain_ground(w, o, dt);
    o->cg.stop_cap = contacts > 0 ? contact_cap(o, dt) : 0.0;
    active_hold(o);
    /* a free body's turn: the centrifugal force its solve must feel (turn_centrifugal; out
     * again if a node reaches the ground in the step, which then does not turn) */
    bool centrifugal = !trap && turns_freely(o) && held_by_nothing(o) &&
                       turn_centrifugal(w, o, 1.0);
    double t3 = now_ms(), t4 = t3, *av = NULL;
    int ground_rounds = 0;
    bool landed = false; /* Newmark: a node reached the ground in this step */
    bool relinearized = false; /* relinearize_turn has run */
    cs_cg_result r = {0, 0, 1, 0, 0};
    /* The tolerance is relative to ‖b − A v1‖ at the guess above (w->def.cg_relative_to):
     * the Δv form's right-hand side; a re-solve of this step keeps that reference. */
    o->cg.stop = w->def.cg_relative_to == CS_CG_RELATIVE_STEP ? CS_CG_STOP_START : CS_CG_STOP_RHS;
    /* With frozen nodes: solve, and while the reactions wake some, solve again with them free
     * (warm start), so the step ends with every frozen node near balance. Likewise while
     * ground contacts change between sticking and sliding (up to CS_GROUND_RESOLVES times). */
    for (int round = 0;; round++) {
        /* round 0: the last steps' hierarchy if it still fits (pc_lag_reusable), else a
         * fresh one; a re-solve (woken nodes) always builds (before the loop's end) */
        bool use_mg, lagged = false;
        if (round == 0 && pc_lag_reusable(w, o, o->smask)) {
            use_mg = lagged = true;
        } else {
            if (round == 0)
                build_preconditioner(o);
            use_mg = setup_multigrid(w, o, step_operator, o->smask);
            if (use_mg && round == 0)
                pc_lag_record(w, o);
        }
        if (round == 0)
            t3 = now_ms();
        /* A lagged solve may take at most twice the last fresh one's iterations (+ 2, and
         * no fewer than 8): past that a build (about half an iteration) is the cheaper way
         * on, and the retry below continues from where it stopped. */
        int max_it = w->def.cg_max_iterations;
        if (lagged && w->pc_lag_cap && max_it > 2 * o->lag.fresh_it + 2 && max_it > 8)
            max_it = 2 * o->lag.fresh_it + 2 > 8 ? 2 * o->lag.fresh_it + 2 : 8;
        cs_cg_result rr = solve(w, o, use_mg, step_operator, o->smask, o->b, o->v1,
                                w->def.cg_tolerance, max_it);
        if (lagged) {
            o->lag.steps++;
            o->lag.reuses++;
        } else if (use_mg && round == 0) {
            o->lag.fresh_it = rr.iterations;
        }
        /* whether v1 is finite, tested once per solve: a lagged solve's test (which decides
         * the retry) serves the check after it unless the retry solves again */
        bool tested = lagged, finite = !lagged || all_finite(o->v1, n3, cs_elastic_threads(o));
        if (lagged && (!rr.converged || !finite)) {
            /* The lagged hierarchy did not get there: build a fresh one and go on from where
             * the solve stopped (from v at the free dofs if it blew up; the held ones keep
             * their values, which CG does not change), with the same stopping reference. */
            o->lag.retries++;
            r.iterations += rr.iterations;
            if (o->cg.stop == CS_CG_STOP_START) {
                o->cg.stop = CS_CG_STOP_GIVEN;
                o->cg.stop_ref = rr.ref;
            }
            if (!finite)
                for (size_t d = 0; d < n3; d++)
                    if (!o->smask[d])
                        o->v1[d] = o->v[d];
            build_preconditioner(o);
            use_mg = setup_multigrid(w, o, step_operator, o->smask);
            if (use_mg)
                pc_lag_record(w, o);
            rr = solve(w, o, use_mg, step_operator, o->smask, o->b, o->v1, w->def.cg_tolerance,
                       w->def.cg_max_iterations);
            tested = false;
        }
        if (!tested)
            finite = all_finite(o->v1, n3, cs_elastic_threads(o));
        r.iterations += rr.iterations;
        r.relres = rr.relres;
        r.converged = rr.converged;
        if (o->cg.stop == CS_CG_STOP_START) {
            o->cg.stop = CS_CG_STOP_GIVEN;
            o->cg.stop_ref = rr.ref;
        }
        t4 = now_ms();
        /* A right-hand side whose norm overflows stops CG before its first iteration with the
         * guess and "converged" (inf <= inf): relres is then NaN, and the step diverged. */
        if (!finite || !isfinite(rr.relres)) {
            o->fem.cell_active = NULL;
            o->cg.stop = CS_CG_STOP_RHS;
            o->cg.stop_cap = 0;
            return CS_ERR_DIVERGED;
        }
        const bool again = ground_rounds < CS_GROUND_RESOLVES;
        if (ground_reactions(w, o, contacts, step_operator, dt, again) > 0) {
            ground_rounds++;
            active_hold(o); /* frozen nodes stay held */
            continue;
        }
        if (again && w->def.has_ground) {
            const int arrived = ground_arrivals(w, o, trap);
            if (arrived > 0 && trap) {
                /* Newmark: a landing step is implicit Euler's (below), as after a rigid
                 * contact's push (holding the arrivals inside the trapezoidal step slowed a
                 * stiff block sliding down a slope by 4 % against Coulomb's law) */
                landed = true;
                break;
            }
            if (arrived > 0) {
                if (centrifugal)
                    centrifugal = !turn_centrifugal(w, o, -1.0);
                if (contacts == 0)
                    o->cg.stop_cap = contact_cap(o, dt);
                contacts += arrived;
                ground_rounds++;
                active_hold(o);
                continue;
            }
        }
        if (!trap && !relinearized && relinearize_turn(w, o)) {
            relinearized = true; /* once: not a round of the ground's */
            continue;
        }
        if (!active_needs_av(w, o, contacts))
            break;
        av = o->cg.z; /* scratch: the solve is done (ground_reactions uses cg.q) */
        step_operator(o, o->v1, av);
        if (active_reactions(w, o, av) == 0 || round == CS_ACTIVE_MAX_RESOLVES)
            break;
        /* b's elastic part at each node is (active cells now) + f_skip: move the woken
         * cells from one to the other, then the operator's blocks and the held dofs */
        for (size_t d = 0; d < n3; d++)
            o->b[d] += dt * o->f_skip[d];
        active_refresh(o);
        for (size_t d = 0; d < n3; d++)
            o->b[d] -= dt * o->f_skip[d];
        o->fem.cell_active = o->n_active_cells < o->cm.n_cells ? o->cell_active : NULL;
        build_preconditioner(o);
        active_hold(o);
    }
    o->cg.stop = CS_CG_STOP_RHS; /* the other solves on this work (statics, impacts) */
    o->cg.stop_cap = 0;
    momentum_exact(o, o->b, o->v1);
    active_end(w, o, av);
    o->fem.cell_active = NULL;
    double el_end = NAN;
    if (trap) {
        /* The guard: without damping nothing takes out what a poorly linearized step puts in
         * (a strain increment v dt / h of order 1 in a nonlinear model: the 6×2×2 beam of
         * stab_implicit_any_dt at dt 0.1 s grew 1e4-fold). A step whose kinetic + elastic
         * energy rises by more than CS_NEWMARK_GUARD of it beyond the external forces' work
         * f·(x1 − x) is redone by implicit Euler, which dissipates. The slack is that fraction
         * of the larger of the start energy and the work: from rest the start energy is 0, and
         * a slack of it alone sent every corotational first step (and half the linear ones, on
         * round-off) to implicit Euler, which cost an impulse's response 3–28 % of its modal
         * amplitudes (an outside review against its own trapezoidal integration). */
        bool redo = landed;
        if (!redo) {
            double *x1 = o->cg.zo, work = 0;
            for (size_t d = 0; d < n3; d++) {
                x1[d] = o->x[d] +
                        (o->smask[d] ? dt * o->v1[d] : 0.5 * dt * (o->v[d] + o->v1[d]));
                work += o->f[d] * (x1[d] - o->x[d]);
            }
            el_end = cs_elastic_energy(o, x1);
            const double e_end = kinetic_energy(o, o->v1) + el_end;
            redo = !(e_end <=
                     e_start + work + CS_NEWMARK_GUARD * fmax(e_start, fabs(work)) + 1e-300);
        }
        if (redo) {
            add_solve_stats(st, r);
            st->newmark_redone++;
            return step_implicit(w, o, st, false);
        }
    }
    /* once per step: a Newmark step redone by implicit Euler counts as the redo's solve */
    auto_small_mg(w, o, r.iterations);
    /* implicit Euler: a free body's rigid part along its rotation (o->cg.zo: scratch) */
    double Rt[9], mass = 0;
    const bool turned = !trap && free_body_rotation(w, o, o->cg.zo, Rt, &mass);
    if (turned) {
        turn_ctx tc = {o, Rt, mass};
        cs_cg_map_history(&o->cg, turn_velocities, &tc);
    }
    if (end_solved_step(w, o, st, (const double[5]){t0, t1, t2, t3, t4}, r,
                        trap || turned ? o->cg.zo : NULL, el_end) != CS_OK)
        return CS_ERR_DIVERGED;
    if (!o->sleeping)
        cs_cg_record(&o->cg, o->v);
    return CS_OK;
}

/* ---------------------------------------------------------------- central differences */

/*
 * y = mcoef·M p + kcoef·K_R p + dcoef·Σ drags k w (w·p), M the model's mass (consistent for
 * localframe, lumped otherwise): the operator of the central-difference step.
 */
static void cd_operator(void *ctx, const double *p, double *y)
{
    cs_object *o = ctx;
    const double kc = o->kcoef;
    if (kc != 0) {
        cs_elastic_apply_K(o, p, y);
        for (size_t d = 0; d < 3 * (size_t)o->n; d++)
            y[d] *= kc;
    } else {
        memset(y, 0, 3 * (size_t)o->n * sizeof(double)); /* no stiffness damping: M alone */
    }
    cs_elastic_apply_M(o, p, y, o->mcoef);
    if (o->fld.has_damping) {
        /* the damping field: cmcoef·α-part M_d p + ckcoef·K_d p */
        if (o->ckcoef != 0) {
            double *t = o->fld.tmp;
            cs_elastic_apply_Kd(o, p, t);
            for (size_t d = 0; d < 3 * (size_t)o->n; d++)
                y[d] += o->ckcoef * t[d];
        }
        if (o->cmcoef != 0)
            cs_elastic_apply_Md(o, p, y, o->cmcoef);
    }
    add_penalty_operator(o, o->pcoef, p, y);
    cs_object_add_spring_operator(o, o->dcoef, p, y);
}

static void cd_preconditioner(cs_object *o)
{
    const double *md = cs_elastic_mass_diag(o);
    if (o->kcoef != 0)
        cs_elastic_diag_blocks(o, o->blocks);
    else
        memset(o->blocks, 0, 9 * (size_t)o->n * sizeof(double));
    for (int i = 0; i < o->n; i++) {
        double *B = o->blocks + 9 * i;
        for (int k = 0; k < 9; k++)
            B[k] *= o->kcoef;
        for (int a = 0; a < 3; a++)
            B[4 * a] += o->mcoef * md[i] +
                        (o->fld.has_damping ? o->cmcoef * o->fld.md[i] : 0.0) +
                        (o->pin[i] ? o->pcoef * o->penalty : 0.0);
    }
    if (o->fld.has_damping && o->ckcoef != 0) {
        cs_elastic_diag_blocks_d(o, o->fld.tmp);
        for (size_t d = 0; d < 9 * (size_t)o->n; d++)
            o->blocks[d] += o->ckcoef * o->fld.tmp[d];
    }
    cs_object_add_spring_blocks(o, o->dcoef, o->blocks);
    cs_invert_blocks(o->blocks, o->n);
}

/* z = (mcoef·M)⁻¹ r by the mass factor, 0 at the solve's held dofs: the preconditioner of a
 * localframe object's central-difference solves, whose operator is mostly its consistent
 * mass (on the localframe bench's 1080-cube beam: 95 block-Jacobi iterations a step, the
 * B-spline mass having a constant diagonal and a condition number near 18.5³). Symmetric
 * positive definite on the free dofs (the restriction of M⁻¹ to them). */
static void cd_mass_precond(void *ctx, const double *r, double *z)
{
    const cs_object *o = ctx;
    cs_elastic_mass_solve(o, 1.0 / o->mcoef, r, z);
    for (size_t d = 0; d < 3 * (size_t)o->n; d++)
        if (o->smask[d])
            z[d] = 0;
}

/*
 * Central differences, seed 001 Eq. (20): (2M + dt D) p⁺ = 2dt²(f − K_R p) + 4M p −
 * (2M − dt D) p⁻, D = αM + βK_R (Rayleigh; the mass part is §3.2.1's ∫γΓᵀΓ with γ = αρ),
 * "K_R p" the model's elastic force at p (local frames: it is −R K d̂). Written for the
 * increment p⁺ − p = dt·v1 (o->v holds (p − p⁻)/dt, so no extra state survives fracture
 * or reset):
 *   ((2 + dtα) M + dtβ K_R + 2dt²·drags) v1 = 2dt (f + f_el(p)) + ((2 − dtα) M − dtβ K_R) v,
 * solved by PCG warm-started from v. Drag and penalty springs are taken at p⁺ (implicitly)
 * so that a stiff one cannot break the stability limit checked at add time (ω·dt < 2). With a
 * damping field D = α M_d + β K_d (cmcoef, ckcoef; the model's M_d and K_d, elastic.h). Ground
 * contact holds a touching node's normal velocity in the solve, as in implicit Euler.
 */
static int step_central_difference(cs_world_t *w, cs_object *o, cs_step_stats *st)
{
    const double dt = w->def.dt, al = o->mat.damping[0], be = o->mat.damping[1];
    const size_t n3 = (size_t)o->n * 3;
    double t0 = now_ms();
    gather_forces(o);
    /* Gravity with the model's consistent nodal masses where they differ from o->m. */
    const double *mrow = cs_elastic_mass_rows(o);
    if (mrow)
        for (int i = 0; i < o->n; i++)
            for (int a = 0; a < 3; a++)
                o->f[3 * i + a] += (mrow[i] - o->m[i]) * w->def.gravity[a];
    double t1 = now_ms();
    cs_elastic_update(o, o->x);
    double t2 = now_ms();
    /* b = ((2 − dtα) M − dtβ K_R) v + 2dt (f + f_el); with a damping field
     * (2M − dt(α M_d + β K_d)) v. The penalty springs, like drags, only on the left. */
    const bool dfield = o->fld.has_damping;
    o->mcoef = dfield ? 2.0 : 2.0 - dt * al;
    o->kcoef = dfield ? 0.0 : -dt * be;
    o->cmcoef = dfield ? -dt * al : 0.0;
    o->ckcoef = dfield ? -dt * be : 0.0;
    o->dcoef = 0;
    o->pcoef = 0;
    cd_operator(o, o->v, o->b);
    cs_elastic_force(o, o->x, o->v1, NULL);
    /* Warm start: the step with the row-sum lumped mass, v + dt·(f + f_el)/m_row. It is the
     * exact answer for a lumped mass without damping and drags; with the consistent B-spline
     * mass CG only corrects the difference, which cuts its iterations several-fold. */
    const double *mr = mrow ? mrow : o->m;
    for (size_t d = 0; d < n3; d++) {
        const double F = o->f[d] + o->v1[d];
        o->b[d] += 2.0 * dt * F;
        o->v1[d] = o->mask[d] ? 0.0 : o->v[d] + dt * F / mr[d / 3];
    }
    o->mcoef = dfield ? 2.0 : 2.0 + dt * al;
    o->kcoef = dfield ? 0.0 : dt * be;
    o->cmcoef = dfield ? dt * al : 0.0;
    o->ckcoef = dfield ? dt * be : 0.0;
    o->dcoef = 2.0 * dt * dt;
    o->pcoef = 2.0 * dt * dt; /* penalty springs at p⁺: no limit on k_p */
    /* a localframe object's consistent mass: its factor (unless Jacobi is asked for) */
    const bool mfac = o->lf && w->def.preconditioner != CS_PRECOND_JACOBI &&
                      cs_elastic_mass_factor(o) == 0;
    if (!mfac)
        cd_preconditioner(o);
    /* forces enter b as 2dt·f: the held rows' residual is the ground's reaction, 2dt·f_c */
    int contacts = constrain_ground(w, o, 2.0 * dt);
    double t3 = now_ms();
    cs_cg_result r = {0, 0, 1, 0, 0};
    for (int round = 0;; round++) {
        const cs_cg_result rr =
            mfac ? cs_pcg_ex(&o->cg, cd_operator, o, cd_mass_precond, o, o->smask, o->b, o->v1,
                             w->def.cg_tolerance, w->def.cg_max_iterations,
                             cs_elastic_threads(o))
                 : cs_pcg(&o->cg, cd_operator, o, o->blocks, o->smask, o->b, o->v1,
                          w->def.cg_tolerance, w->def.cg_max_iterations, cs_elastic_threads(o));
        r.iterations += rr.iterations;
        r.relres = rr.relres;
        r.converged = rr.converged;
        /* see step_implicit */
        if (!all_finite(o->v1, n3, cs_elastic_threads(o)) || !isfinite(rr.relres))
            return CS_ERR_DIVERGED;
        if (ground_reactions(w, o, contacts, cd_operator, 2.0 * dt,
                             round < CS_GROUND_RESOLVES) == 0)
            break;
    }
    double t4 = now_ms();
    return end_solved_step(w, o, st, (const double[5]){t0, t1, t2, t3, t4}, r, NULL, NAN);
}

/* ---------------------------------------------------------------- explicit steps */

/*
 * ftot = inputs (gather_forces, at the current o->x, penalty springs included) + elastic force
 * at o->x − β K v (β K_d v with a damping field); the mass-proportional damping α M v (α M_d v)
 * is applied with the acceleration.
 */
static void explicit_force(cs_object *o, const double *v, double *ftot)
{
    gather_forces(o);
    cs_elastic_update(o, o->x);
    cs_elastic_force(o, o->x, ftot, NULL);
    const size_t n3 = (size_t)o->n * 3;
    if (o->mat.damping[1] > 0) {
        double *kv = o->cg.z; /* scratch: no solve in an explicit step */
        if (o->fld.has_damping)
            cs_elastic_apply_Kd(o, v, kv); /* the damping field: β K_d v */
        else
            cs_elastic_apply_K(o, v, kv);
        for (size_t d = 0; d < n3; d++)
            ftot[d] -= o->mat.damping[1] * kv[d];
    }
    for (size_t d = 0; d < n3; d++)
        ftot[d] += o->f[d];
}

/* v += s·dt·(M⁻¹ftot − α M⁻¹M_d v) on free dofs; held dofs keep zero velocity. */
static void explicit_kick(cs_object *o, const double *ftot, double sdt)
{
    const double alpha = o->mat.damping[0];
    for (int i = 0; i < o->n; i++) {
        /* α M_d v: per node α·md_i/m_i where a damping field is painted */
        const double al = o->fld.has_damping ? alpha * o->fld.md[i] / o->m[i] : alpha;
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * (size_t)i + a;
            o->v[d] = o->mask[d] ? 0.0 : o->v[d] + sdt * (ftot[d] / o->m[i] - al * o->v[d]);
        }
    }
}

static void explicit_drift(cs_object *o, double dt)
{
    for (size_t d = 0; d < (size_t)o->n * 3; d++)
        if (!o->mask[d])
            o->x[d] += dt * o->v[d];
}

/*
 * Ground for explicit steps, in two passes. After the drift (positions): a node below the
 * plane is put back on it and marked in contact. After the last kick (velocities): a contact
 * node moving down is stopped. Each pass removes a downward velocity Δv_n, the impulse per unit
 * mass the ground gave, and Coulomb friction takes up to μ·Δv_n off the tangential velocity (a
 * resting node loses g·dt per step, so it feels μmg). Verlet's second force evaluation sees the
 * projected positions, so a block at rest on the ground has zero velocity, not −g·dt/2.
 */
static void ground_explicit(const cs_world_t *w, cs_object *o, bool positions)
{
    if (!w->def.has_ground)
        return;
    const double g = w->def.ground_height;
    for (int i = 0; i < o->n; i++) {
        double *x = o->x + 3 * i, *v = o->v + 3 * i;
        if (positions) {
            o->contact[i] = CS_GROUND_FREE;
            if (x[2] >= g || o->mask[3 * i + 2])
                continue;
            o->contact[i] = CS_GROUND_SLIDE;
            x[2] = g;
        } else if (o->contact[i] == CS_GROUND_FREE) {
            continue;
        }
        const double dvn = v[2] < 0 ? -v[2] : 0.0;
        v[2] += dvn;
        ground_friction(w, o, i, dvn);
    }
}

/*
 * Symplectic Euler (v ← v + dt M⁻¹f(x, v); x ← x + dt v) or velocity Verlet (half kick with
 * f(x_n), drift, half kick with f(x_{n+1}) — two force evaluations per step, so that inputs
 * and fracture need no force carried between steps). Damping uses the velocity at the start
 * of each kick. Stable for dt below cs_elastic_critical_dt (checked when the object is added).
 * A step that produces non-finite values is undone.
 */
static int step_explicit(cs_world_t *w, cs_object *o, cs_step_stats *st, bool verlet)
{
    const double dt = w->def.dt;
    const size_t n3 = (size_t)o->n * 3;
    double *ftot = o->cg.r; /* scratch */
    double t0 = now_ms();
    memcpy(o->v1, o->x, n3 * sizeof(double)); /* kept to undo a diverged step */
    memcpy(o->b, o->v, n3 * sizeof(double));
    explicit_force(o, o->v, ftot);
    double t1 = now_ms();
    if (verlet) {
        explicit_kick(o, ftot, 0.5 * dt);
        explicit_drift(o, dt);
        ground_explicit(w, o, true);
        explicit_force(o, o->v, ftot);
        explicit_kick(o, ftot, 0.5 * dt);
    } else {
        explicit_kick(o, ftot, dt);
        explicit_drift(o, dt);
        ground_explicit(w, o, true);
    }
    ground_explicit(w, o, false);
    double t2 = now_ms();
    o->elastic_energy_valid = false;
    if (!state_finite(o)) {
        memcpy(o->x, o->v1, n3 * sizeof(double));
        memcpy(o->v, o->b, n3 * sizeof(double));
        return CS_ERR_DIVERGED;
    }
    st->ms_skin += finish_step(w, o);
    st->ms_rhs += t1 - t0;
    st->ms_solve += t2 - t1;
    st->objects_stepped++;
    return CS_OK;
}

/*
 * Sleep keeps the load of what rests on an object. Contact impulses reach a deformable object
 * as velocities its next step shares out (rigid.c), and once both sides sleep there are none:
 * the step after it woke (a box asleep on a soft block, the block then pulled) saw no box, the
 * ground held the block by its own weight alone, and it slipped a step early (the box then
 * landed 0.9 m from where it does when nothing sleeps). So a step that may end in sleep keeps
 * the velocity it started from, and the first step after waking starts from it, unless
 * contacts gave the object impulses while it slept (an awake rigid body on it still does):
 * those carry the load already.
 */
static void wake_velocity(const cs_world_t *w, cs_object *o)
{
    const size_t n3 = (size_t)o->n * 3;
    if (o->wake_armed && o->n_wake == o->n) {
        size_t d = 0;
        while (d < n3 && o->v[d] == 0)
            d++;
        if (d == n3)
            memcpy(o->v, o->v_wake, n3 * sizeof(double));
    }
    o->wake_armed = o->wake_saved = false;
    if (w->def.sleep_steps <= 0 || o->still_steps + 1 < w->def.sleep_steps)
        return;
    if (o->n_wake != o->n) {
        double *g = realloc(o->v_wake, (n3 ? n3 : 1) * sizeof *g);
        if (!g)
            return; /* it wakes without that load, as it did before */
        o->v_wake = g;
        o->n_wake = o->n;
    }
    memcpy(o->v_wake, o->v, n3 * sizeof(double));
    o->wake_saved = true;
}

/*
 * A drag or curve spring that swings its body about the centre of mass faster than a step
 * can follow acts there instead. A spring of stiffness k pulling a point g of a free body
 * towards t exerts F = k |t − g| with lever r = |g − c| (c the centre of mass): the body
 * swings about its alignment with the pull like a pendulum, at ω_p = √(F r / I), I its least
 * moment of inertia about an axis across r (the axes it can swing about), and settles (in
 * the limit of a fast swing) with the pull through c. Past ω_p dt = CS_DRAG_SWING_MAX the
 * swing is over within a fraction of a step, and a step linearized about its start turns
 * the body by ω_p dt along its tangents instead: the fracture demo's 20 N/m drag on a
 * one-cube piece of 1.6 g it had just broken off, 0.7 m from the target (ω_p dt = 21),
 * turned it by 4–14 rad a step and stretched it to 200–2000 times its volume at 160 m/s
 * (turning it exactly is not for a sprung body: held_by_nothing). So the spring is moved,
 * for the rest of its life, to the centre of the cube nearest c (weights 1/8: the centre of
 * mass itself for a single cube), where it pulls the body along without the swing; it keeps
 * its stiffness and target. (The body then keeps its orientation instead of hanging from
 * the grabbed point.) A body the scene holds swings about its supports, not c, and keeps its
 * springs where they are; so does a rigid body (it turns exactly: rigid.c). Whatever the
 * body's shape: a long beam pulled at its end swings about its cross axes (I = M L²/12),
 * not its long one, and a 0.4 m beam of 0.36 kg under the same drag has ω_p dt = 0.4.
 */
#define CS_DRAG_SWING_MAX 2.0
static void centre_fast_springs(const cs_world_t *w, cs_object *o)
{
    bool any = false;
    for (int i = 0; i < o->n_inputs && !any; i++)
        any = cs_input_is_spring(&o->inputs[i]) && o->inputs[i].delay <= 0 &&
              !o->inputs[i].centred;
    rigid_fit f; /* the centre of mass and the inertia about it */
    if (!any || o->model == CS_MODEL_RIGID || held_by_scene(o) || !fit_rigid(o, o->v, &f))
        return;
    const double *c = f.c, *I = f.I, dt = w->def.dt;
    for (int i = 0; i < o->n_inputs; i++) {
        cs_input *in = &o->inputs[i];
        if (!cs_input_is_spring(in) || in->delay > 0 || in->centred)
            continue;
        const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)in->cell;
        double g[3] = {0, 0, 0}, t[3];
        spring_target(in, t);
        for (int k = 0; k < 8; k++)
            for (int a = 0; a < 3; a++)
                g[a] += in->w[k] * o->x[3 * (size_t)nd[k] + a];
        const double F = in->stiffness * sqrt((t[0] - g[0]) * (t[0] - g[0]) +
                                              (t[1] - g[1]) * (t[1] - g[1]) +
                                              (t[2] - g[2]) * (t[2] - g[2]));
        double u[3] = {g[0] - c[0], g[1] - c[1], g[2] - c[2]};
        const double r = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        if (!(r > 0) || !(F > 0))
            continue; /* pulled at its centre of mass: no swing */
        for (int a = 0; a < 3; a++)
            u[a] /= r;
        /* the least moment of inertia about an axis across u: I on the plane normal to u
         * (e1, e2 an orthonormal basis of it), its smaller eigenvalue */
        const int ax = fabs(u[0]) < fabs(u[1]) ? (fabs(u[0]) < fabs(u[2]) ? 0 : 2)
                                               : (fabs(u[1]) < fabs(u[2]) ? 1 : 2);
        double e1[3] = {0, 0, 0}, e2[3];
        e1[ax] = 1;
        const double ue = u[ax];
        for (int a = 0; a < 3; a++)
            e1[a] -= ue * u[a];
        const double n1 = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
        for (int a = 0; a < 3; a++)
            e1[a] /= n1;
        e2[0] = u[1] * e1[2] - u[2] * e1[1];
        e2[1] = u[2] * e1[0] - u[0] * e1[2];
        e2[2] = u[0] * e1[1] - u[1] * e1[0];
        double i11 = 0, i12 = 0, i22 = 0;
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) {
                i11 += e1[a] * I[3 * a + b] * e1[b];
                i12 += e1[a] * I[3 * a + b] * e2[b];
                i22 += e2[a] * I[3 * a + b] * e2[b];
            }
        const double iperp = 0.5 * (i11 + i22) - sqrt(0.25 * (i11 - i22) * (i11 - i22) + i12 * i12);
        if (!(iperp > 0) ||
            !(F * r * dt * dt > CS_DRAG_SWING_MAX * CS_DRAG_SWING_MAX * iperp))
            continue;
        int best = in->cell;
        double bd = INFINITY;
        for (int q = 0; q < o->cm.n_cells; q++) {
            const int32_t *cn = o->cm.cell_nodes + 8 * (size_t)q;
            double p[3] = {0, 0, 0};
            for (int k = 0; k < 8; k++)
                for (int a = 0; a < 3; a++)
                    p[a] += 0.125 * o->x[3 * (size_t)cn[k] + a];
            const double d = (p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                             (p[2] - c[2]) * (p[2] - c[2]);
            if (d < bd) {
                bd = d;
                best = q;
            }
        }
        in->cell = best;
        for (int k = 0; k < 8; k++)
            in->w[k] = 0.125;
        in->centred = true;
    }
}

static int step_object(cs_world_t *w, cs_object *o, cs_step_stats *st)
{
    wake_velocity(w, o);
    centre_fast_springs(w, o);
    switch (o->integrator) {
    case CS_INTEGRATOR_IMPLICIT_EULER:
        return step_implicit(w, o, st, false);
    case CS_INTEGRATOR_NEWMARK:
        return step_implicit(w, o, st, true);
    case CS_INTEGRATOR_CENTRAL_DIFFERENCE:
        return step_central_difference(w, o, st);
    case CS_INTEGRATOR_SYMPLECTIC_EULER:
        return step_explicit(w, o, st, false);
    case CS_INTEGRATOR_VERLET:
        return step_explicit(w, o, st, true);
    default: /* refused when the object was added */
        return CS_ERR_INVALID;
    }
}

static bool needs_step(const cs_object *o)
{
    return !o->sleeping && o->n_fixed_nodes < o->n;
}

int cs_world_step(cs_world_t *w)
{
    if (!w)
        return CS_ERR_INVALID;
    cs_step_stats st = {.converged = true};
    double t0 = now_ms();
    int rc = CS_OK;
    cs_fracture_clear_step(w);
    rc = cs_rigid_prestep(w, &st);
    const int n_before = w->n_objects; /* pieces made in this step start stepping next step */
    for (int i = 0; i < n_before; i++) {
        cs_object *o = w->objects[i];
        if (o->model == CS_MODEL_RIGID)
            continue; /* all rigid bodies step together below */
        if (!needs_step(o)) {
            expire_inputs(o);
            continue;
        }
        /* Keep the old state so a diverged step can be undone. b and v1 are scratch. */
        int r = step_object(w, o, &st);
        st.cells_awake += o->cm.n_cells;
        st.cells_stepped += active_wanted(w, o) && o->frozen ? o->n_active_cells : o->cm.n_cells;
        if (r != CS_OK) {
            /* Non-finite velocities: drop the inputs and bring the object to rest in place. */
            memset(o->v, 0, (size_t)o->n * 3 * sizeof(double));
            o->n_inputs = 0;
            rc = r;
            continue;
        }
        if (o->fracture) {
            r = cs_fracture_after_step(w, o);
            if (r != CS_OK && rc == CS_OK)
                rc = r;
        }
    }
    int r = cs_rigid_step(w, &st);
    if (r != CS_OK && rc == CS_OK)
        rc = r;
    w->time += w->def.dt;
    w->frame++;
    st.ms_total = now_ms() - t0;
    w->stats = st;
    return rc;
}

/* ---------------------------------------------------------------- static equilibrium */

static double masked_norm(cs_object *o, const double *r)
{
    double s = 0;
    for (int d = 0; d < 3 * o->n; d++)
        if (!o->mask[d])
            s += r[d] * r[d];
    return sqrt(s);
}

/* residual = f_ext·load + f_el(x), zero at held dofs; returns its norm. If pot is non-NULL
 * it receives the total potential energy ½ Σ uᵀK u − load·f·x. */
static double static_residual(cs_object *o, double load, double *res, double *pot)
{
    double e = 0, work = 0;
    cs_elastic_update(o, o->x);
    cs_elastic_force(o, o->x, res, pot ? &e : NULL);
    const double ep = add_penalty_force(o, o->x, res); /* the supports, not scaled by load */
    for (int d = 0; d < 3 * o->n; d++) {
        res[d] = o->mask[d] ? 0.0 : res[d] + load * o->f[d];
        work += load * o->f[d] * (o->x[d] - o->cm.node_rest[d]);
    }
    if (pot)
        *pot = e + ep - work;
    return masked_norm(o, res);
}

/* The centre of the object's rest bounding box (the frame statics solve in). */
static void rest_centre(const cs_object *o, double c[3])
{
    for (int a = 0; a < 3; a++) {
        double lo = INFINITY, hi = -INFINITY;
        for (int i = 0; i < o->n; i++) {
            lo = fmin(lo, o->cm.node_rest[3 * i + a]);
            hi = fmax(hi, o->cm.node_rest[3 * i + a]);
        }
        c[a] = o->n > 0 ? 0.5 * (lo + hi) : 0.0;
    }
}

/* x and the rest positions moved by −c (sign −1) or back (+1; the rest positions from
 * rest_save, bit for bit). */
static void shift_frame(cs_object *o, const double c[3], double sign, const double *rest_save)
{
    for (int d = 0; d < 3 * o->n; d++) {
        o->x[d] += sign * c[d % 3];
        o->cm.node_rest[d] = sign > 0 ? rest_save[d] : o->cm.node_rest[d] - c[d % 3];
    }
}

static int solve_static_in_frame(cs_world_t *w, cs_object *o, cs_step_stats *st, double fnorm,
                                 bool mg_first, bool mss_exact, double *relres);

/* solve_static_in_frame again from x0 (the state before the first attempt), another way. */
static int resolve_static(cs_world_t *w, cs_object *o, const double *x0, cs_step_stats *st,
                          double fnorm, bool mg_first, bool mss_exact, double *relres)
{
    memcpy(o->x, x0, (size_t)o->n * 3 * sizeof(double));
    cs_elastic_update(o, o->x);
    return solve_static_in_frame(w, o, st, fnorm, mg_first, mss_exact, relres);
}

/*
 * One Newton solve of statics, A dx = res to ctol. With mg_first, preconditioner "auto" takes
 * multigrid for linear and corotational objects of any size, not from CS_MG_AUTO_CELLS cubes
 * as in dynamics: statics have no mass term, and the stiffness alone is as ill-conditioned as
 * the object is slender (the condition number grows as (L/h)² and, near incompressibility, as
 * 1/(1 − 2ν)). Block-Jacobi CG took 434–886 iterations a Newton solve on a 40×4×4
 * corotational cantilever at ν = 0.49 where multigrid takes 3–10. Without mg_first (the
 * retry of solve_static_object), as before session 42: the object's own choice, and where
 * block Jacobi does not converge in its iterations, on from there with multigrid (the outside
 * review's 40×4×4 linear beam at ν = 0.4999 needed more than the 2000 Jacobi is given).
 * "jacobi" asked for is block Jacobi. At most cap iterations a solve where cap > 0 (else
 * 4 × max_iterations). Adds the iterations to st.
 */
static cs_cg_result static_solve(cs_world_t *w, cs_object *o, cs_matvec_fn A, double *res,
                                 double *dx, double ctol, cs_step_stats *st, bool mg_first,
                                 int cap)
{
    const int max_it = cap > 0 && cap < w->def.cg_max_iterations * 4
                           ? cap : w->def.cg_max_iterations * 4;
    const bool use_mg = setup_multigrid_ex(w, o, A, o->mask, mg_first);
    cs_cg_result r = solve(w, o, use_mg, A, o->mask, res, dx, ctol, max_it);
    st->cg_iterations += r.iterations;
    if (!r.converged && !use_mg && all_finite(dx, 3 * (size_t)o->n, cs_elastic_threads(o)) &&
        setup_multigrid_ex(w, o, A, o->mask, true)) {
        const int done = r.iterations;
        r = solve(w, o, true, A, o->mask, res, dx, ctol, max_it);
        st->cg_iterations += r.iterations;
        r.iterations += done;
    }
    return r;
}

/*
 * Whether o's static equilibrium (x, solved in its frame) is unstable: its tangent stiffness
 * (the geometric one for corotational objects, the full spring Jacobian for mss) has a
 * direction of negative curvature. A straight column loaded past its buckling load is in
 * equilibrium, and the load stepping reaches that state along the symmetric path and reports
 * it as converged (session 43's sweep: a clamped-free block at 0.25–0.30 E·A, buckling near
 * 0.17). Probed by CG on the tangent from a fixed pseudo-random right-hand side: its pivots
 * pᵀA p are those of the Lanczos matrix, whose smallest Ritz value soon approaches a negative
 * eigenvalue, which then gives a negative pivot (with the preconditioner, the inertia is the
 * same). Measured: a negative pivot within 0–4 iterations wherever the sweep's columns were
 * past buckling, where positive definite tangents take 9–22 iterations to 1e-6; so 1e-3 and
 * at most 30 iterations (6–12 more CG iterations a converged solve). Linear and localframe
 * objects' operators are positive definite and are not probed.
 */
static bool probe_unstable(cs_world_t *w, cs_object *o, cs_step_stats *st, bool mg_first)
{
    if (o->model != CS_MODEL_COROTATIONAL && o->model != CS_MODEL_MSS)
        return false;
    const int n3 = 3 * o->n;
    double *rhs = o->b, *dx = o->v1;
    for (int d = 0; d < n3; d++) {
        const uint32_t hsh = (uint32_t)(d + 1) * 2654435761u;
        rhs[d] = o->mask[d] ? 0.0 : (double)(hsh >> 8) / 16777216.0 - 0.5;
        dx[d] = 0;
    }
    /* mss: the clamped Jacobian, as before session 45: the exact one has negative curvature
     * along the cubes' zero-energy modes under any compression (a 0.2 m block at 1 %), which
     * the dynamics' tangent does not have either */
    const bool geometric = cs_elastic_prepare_tangent(o, o->x, false) == 0;
    build_preconditioner(o);
    const cs_cg_result r = static_solve(w, o, geometric ? tangent_operator : step_operator, rhs,
                                        dx, 1e-3, st, mg_first, 30);
    cs_elastic_release_tangent(o);
    return r.indefinite;
}

/*
 * Static equilibrium of one object: Newton iterations with the corotated (warped) tangent
 * R K Rᵀ, a backtracking line search on the residual norm, and adaptive load stepping for
 * large rotations; linear objects take one solve, to the tolerance (and a second where
 * round-off left the first short of it).
 *
 * Solved in a frame centred on the object's rest bounding box: the internal forces come from
 * differences of nearby positions, and positions stored far from the origin (10 m, 1000 m)
 * carry only ulp(|x|) of them, which for a stiff object lies above the loads' 1e-8 (a steel
 * beam 10 m out stalled at 8e-6 of its loads, 1000 m out it took no load step at all). The
 * shift is exact where positions and centre are within a factor 2 of each other (Sterbenz),
 * so the displacements x − X are unchanged by it.
 */
static int solve_static_object(cs_world_t *w, cs_object *o, cs_step_stats *st)
{
    const int n3 = 3 * o->n;
    gather_forces_ex(o, false); /* the penalty springs are in static_residual */
    const double fnorm = masked_norm(o, o->f);
    o->static_unstable = false;
    memset(o->v, 0, (size_t)n3 * sizeof(double));
    if (fnorm == 0)
        return CS_OK;
    double c[3];
    rest_centre(o, c);
    double *rest_save = malloc((size_t)n3 * sizeof(double));
    if (!rest_save)
        return CS_ERR_NOMEM;
    memcpy(rest_save, o->cm.node_rest, (size_t)n3 * sizeof(double));
    shift_frame(o, c, -1.0, NULL);
    double *x0 = malloc((size_t)n3 * sizeof(double)), relres = 0;
    if (!x0) {
        shift_frame(o, c, 1.0, rest_save);
        free(rest_save);
        return CS_ERR_NOMEM;
    }
    memcpy(x0, o->x, (size_t)n3 * sizeof(double));
    o->cg.cancel = w->cancel;
    o->cg.cancel_ctx = w->cancel_ctx;
    int rc = solve_static_in_frame(w, o, st, fnorm, true, true, &relres);
    /* Multigrid first is not always the way: on soft slender beams bent far (a 40×2×2
     * corotational cantilever of E 1e4 Pa, ν 0.45, found by session 42's review) the
     * multigrid-preconditioned Newton steps stall at 2e-3 of the loads while block Jacobi's
     * converge (2463 CG iterations). Where "auto" would have given a small object Jacobi
     * before session 42 and the search failed, it is redone that way from the start (from
     * where multigrid stopped, Jacobi's load search failed too). */
    if (rc == CS_ERR_NOT_CONVERGED && auto_jacobi_by_size(w, o))
        rc = resolve_static(w, o, x0, st, fnorm, false, true, &relres);
    /* mss: Newton on the springs' exact Jacobian (mss.h) converged where the clamped one
     * stalled on slender beams bent far, but not everywhere the clamped one did (session 45,
     * session 43's sweep: a 1 m beam of 5 cm cubes at ν 0.45 bent to half its length: 0.8 s
     * clamped, exit 1 exact); where it fails, the clamped Newton from the start. */
    if (rc == CS_ERR_NOT_CONVERGED && o->model == CS_MODEL_MSS)
        rc = resolve_static(w, o, x0, st, fnorm, true, false, &relres);
    o->static_unstable = rc == CS_OK && probe_unstable(w, o, st, true);
    o->cg.cancel = NULL;
    o->cg.cancel_ctx = NULL;
    free(x0);
    st->cg_residual = fmax(st->cg_residual, relres);
    if (rc != CS_OK)
        st->converged = false;
    st->objects_stepped++;
    shift_frame(o, c, 1.0, rest_save);
    free(rest_save);
    cs_elastic_update(o, o->x);
    cs_surface_skin(&o->surf, &o->cm, o->x, cs_elastic_threads(o));
    return rc;
}

/*
 * The round-off floor of static_residual at the current positions: x is stored to half an
 * ulp(|x|), and the internal forces computed from it carry the stiffness (and the supports'
 * springs) times that error, which for a stiff object under a light load lies above the loads'
 * 1e-8 (an outside check: a 10 cm steel bar under gravity stalls at 1.4e-6 of its loads, a
 * 1 m bar of 1 GPa under 1e-3 g at about 1e-4), whatever the displacements' own accuracy.
 * Estimated as ‖(K + P) δ‖ over the free dofs with δ = ±ulp(x)/2, signs from a hash of the
 * dof (deterministic); delta and out are scratch vectors of 3n. The operator's coefficients
 * must be statics' (kcoef 1, pcoef 1, no mass, no drags).
 */
static double static_floor(cs_object *o, double *delta, double *out)
{
    for (int d = 0; d < 3 * o->n; d++) {
        const double a = fabs(o->x[d]), ulp = nextafter(a, INFINITY) - a;
        const uint32_t hsh = (uint32_t)d * 2654435761u;
        delta[d] = o->mask[d] ? 0.0 : (hsh >> 31) ? 0.5 * ulp : -0.5 * ulp; /* held: exact */
    }
    step_operator(o, delta, out);
    return masked_norm(o, out);
}

void cs_world_set_cancel(cs_world_t *w, bool (*cancel)(void *ctx), void *ctx)
{
    if (!w)
        return;
    w->cancel = cancel;
    w->cancel_ctx = ctx;
}

static int imax(int a, int b)
{
    return a > b ? a : b;
}

static bool static_cancelled(const cs_world_t *w)
{
    return w->cancel && w->cancel(w->cancel_ctx);
}

/* Newton steps without a new best residual before a load level counts as stalled. */
#define STATIC_STALL 6

static int solve_static_in_frame(cs_world_t *w, cs_object *o, cs_step_stats *st, double fnorm,
                                 bool mg_first, bool mss_exact, double *relres)
{
    const int n3 = 3 * o->n;
    const bool linear = o->model == CS_MODEL_LINEAR;
    /* Internal forces are much larger than the loads in stiff or slender objects and are
     * summed in floating point, so the residual cannot fall much below 1e-9 of the loads:
     * the static tolerance is the solver tolerance, but no tighter than 1e-8. */
    const double tol = fmax(w->def.cg_tolerance, 1e-8) * fnorm;
    /* A partial load level only has to bring the next one within Newton's reach: it ends at
     * a residual of level_tol of its own loads (0.1 at the default tolerance, 1e-3 of them at
     * 1e-6). Relative to the level's loads, not the full ones: a bound of 1e3·tol·‖f‖ took
     * every level below 1e3·tol as reached at the rest state, and at tolerance 1e-3 (the
     * advice for mass-spring objects) that was every level: only the full load was ever
     * solved, and where it failed the answer was the rest state (an L bracket at ν 0.49: 7 s
     * and exit 1 at 1e-3, 0.1 s converged at 1e-4). */
    const double level_tol = fmin(1e3 * fmax(w->def.cg_tolerance, 1e-8), 0.1);
    double *res = o->b, *dx = o->v1;
    double *x_save = malloc((size_t)n3 * sizeof(double));
    if (!x_save)
        return CS_ERR_NOMEM;
    o->mcoef = 0;
    o->kcoef = 1;
    o->dcoef = 0;
    o->cmcoef = o->ckcoef = 0;
    o->pcoef = 1;
    double load = 0, dl = 1;
    int rc = CS_OK, geo_cap = 0; /* geometric solves' cap: 0 until one has converged */
    while (load < 1) {
        double target = load + dl > 1 ? 1 : load + dl;
        memcpy(x_save, o->x, (size_t)n3 * sizeof(double));
        double pot, rn = static_residual(o, target, res, &pot), rn_best = INFINITY;
        int since_best = 0;
        /* No tighter than the residual's round-off floor (static_floor, 4× for its spread):
         * below it Newton only stirs the last bits and then stalls, and the load search that
         * followed gave back a smaller load's state, or the rest state (exit 1). Only after a
         * step: a load below the floor still moves the object (the floor is the stiffest
         * modes', the load the softest's: a steel cantilever under 1e-5 g was "converged" at
         * rest), and a nonlinear one only once Newton has stopped halving its residual (its
         * inexact steps would pass the floor long before they converge, where penalty
         * supports raise it). */
        const double floor4 = 4.0 * static_floor(o, dx, o->cg.q);
        double rn_last = INFINITY; /* the residual before the last step */
        bool ok = false, solved = true, stopped = false;
        for (int it = 0; it < 60 && isfinite(rn); it++) {
            if (static_cancelled(w)) {
                stopped = true;
                break;
            }
            const double ltol = target < 1 ? level_tol * target * fnorm : tol;
            const bool at_floor = it > 0 && rn <= floor4 && (linear || rn > 0.5 * rn_last);
            if (rn <= ltol || at_floor) {
                ok = true;
                break;
            }
            build_preconditioner(o);
            memset(dx, 0, (size_t)n3 * sizeof(double));
            /* Inexact Newton: the tangent itself is approximate (its geometric part is
             * symmetrized), so solving it beyond 1e-3 is wasted; near the target a looser
             * solve suffices. A linear object's tangent is exact: one solve to the target
             * (the tolerance asked for, even below the floor: the displacements the solve
             * adds are exact to its tolerance where the residual of their sum cannot show it). */
            double ctol = linear ? fmin(0.1, 0.5 * ltol / rn)
                                 : fmin(0.1, fmax(1e-3, 0.5 * ltol / rn));
            /* Newton with the geometric stiffness where it is positive definite; where CG
             * meets a direction of negative curvature (compression, near buckling), the
             * warped stiffness alone, which always is. */
            /* A geometric solve that stagnates (CG on the symmetrized tangent of a stiff
             * beam's first stretched state crept to 3e-3 in 2000 iterations where 1e-3 was
             * asked; the warped stiffness then took 8) stops at 10 times the iterations its
             * converged solves took, and where it got within 0.1 of its right-hand side its
             * step is taken as it is: an inexact Newton step, checked by the line search. */
            cs_cg_result r = {0, 1, 0, 0, 0};
            bool geometric = cs_elastic_prepare_tangent(o, o->x, mss_exact) == 0;
            bool stagnated = false;
            if (geometric) {
                r = static_solve(w, o, tangent_operator, res, dx, ctol, st, mg_first, geo_cap);
                if (r.converged)
                    geo_cap = imax(geo_cap, imax(50, 10 * r.iterations));
                else
                    stagnated = geo_cap > 0 && r.iterations >= geo_cap && r.relres <= 0.1;
            }
            if (!geometric || (!r.converged && !stagnated)) {
                /* mss: K is the springs' exact Jacobian here (cs_elastic_prepare_tangent,
                 * unless mss_exact is off), capped like the geometric tangent. Where CG meets
                 * negative curvature (compressed springs), the iterate it has reached is the
                 * step (truncated Newton–CG: a descent direction of the quadratic model, the
                 * line search below checks it); where it meets it at once or does not
                 * converge, the clamped Jacobian (mss.h), positive semi-definite. */
                const bool exact = o->model == CS_MODEL_MSS && mss_exact;
                memset(dx, 0, (size_t)n3 * sizeof(double));
                r = static_solve(w, o, step_operator, res, dx, ctol, st, mg_first,
                                 exact ? geo_cap : 0);
                if (exact && r.converged)
                    geo_cap = imax(geo_cap, imax(50, 10 * r.iterations));
                if (!r.converged && !(exact && r.indefinite && r.iterations > 0) &&
                    cs_elastic_clamp_tangent(o, o->x)) {
                    build_preconditioner(o);
                    memset(dx, 0, (size_t)n3 * sizeof(double));
                    r = static_solve(w, o, step_operator, res, dx, ctol, st, mg_first, 0);
                }
            }
            solved = r.converged;
            if (static_cancelled(w)) { /* the solve may have stopped short for it */
                stopped = true;
                break;
            }
            if (!all_finite(dx, (size_t)n3, cs_elastic_threads(o)))
                break;
            /* Backtracking (Armijo) on the total potential energy, the natural merit function
             * of this conservative problem: the residual norm alone rejects good steps, as
             * the first linear step of a slender beam leaves O(θ²) axial stretch. A step
             * that lowers the residual is accepted too, since the corotated forces are only
             * approximately the gradient of that energy. */
            double slope = 0, pot1 = 0;
            for (int d = 0; d < n3; d++)
                slope -= res[d] * dx[d]; /* dΠ/ds at s = 0, negative for a descent step */
            double s = 1.0, rn_new = INFINITY;
            for (int ls = 0; ls < 12; ls++) {
                for (int d = 0; d < n3; d++)
                    o->x[d] += s * dx[d];
                rn_new = static_residual(o, target, o->cg.q, &pot1);
                if (isfinite(rn_new) && (pot1 <= pot + 1e-4 * s * slope || rn_new < rn))
                    break;
                for (int d = 0; d < n3; d++)
                    o->x[d] -= s * dx[d];
                s *= 0.5;
                rn_new = INFINITY;
            }
            if (!isfinite(rn_new))
                break; /* no acceptable step: give up at this load level */
            /* The accepted trial point's residual (and rotations) are already computed. */
            memcpy(res, o->cg.q, (size_t)n3 * sizeof(double));
            rn_last = rn;
            rn = rn_new;
            pot = pot1;
            /* Stalled (retry with a smaller load increment) when the residual has not gone
             * 0.1 % below its best since the level's first step (which may raise it 100-fold
             * from the rest state's) for STATIC_STALL steps. Not when it rose once: the line
             * search takes steps that lower the energy, and on a slender beam bent far
             * (large rotations) the residual then swings up and down by 2–4× from one step to
             * the next while the energy falls steadily and the best residual every 2–4 steps:
             * a 40×4×4 cantilever bent to 0.35 m converges in 28 Newton steps at its full
             * load, where "above the last one after 8 steps" halved the load 8 times and
             * took 88. */
            if (rn < 0.999 * rn_best) {
                rn_best = rn;
                since_best = 0;
            } else if (++since_best >= STATIC_STALL) {
                break;
            }
            /* A linear object's tangent is exact: a solve that converges ends the level, and
             * one that does not is only restarted by the next Newton step. Three such
             * restarts are the end (the residual creeps down by a few per cent each: with
             * the rule above alone, "jacobi" at ν = 0.4999 ran 60 restarts, 120 000 CG
             * iterations, before it failed). */
            if (linear && !solved && it >= 2)
                break;
        }
        /* At the full load, a Newton that stalls (or finds no acceptable step) below 1e-6 of
         * the loads has met the round-off floor of the internal forces, which for a lightly
         * loaded slender object lies above the 1e-8 asked for (3e-8 for a 10:1 cantilever
         * under 1e-3 g): keep that state rather than fall back to the last load level. */
        if (stopped) { /* back to the last level reached */
            memcpy(o->x, x_save, (size_t)n3 * sizeof(double));
            cs_elastic_update(o, o->x);
            rc = CS_ERR_CANCELLED;
            break;
        }
        if (!ok && target == 1 && isfinite(rn) && rn <= 1e-6 * fnorm)
            ok = true;
        if (ok) {
            load = target;
            dl = fmin(1.0, dl * 2);
        } else {
            memcpy(o->x, x_save, (size_t)n3 * sizeof(double));
            cs_elastic_update(o, o->x);
            dl *= 0.5;
            /* A smaller load level does not make a linear solve converge (its conditioning
             * does not depend on the load, and a linear object's tangent is exact): where the
             * last one did not, stop here rather than search down to 1e-4 of the load. */
            if (dl < 1e-4 || (linear && !solved)) {
                rc = CS_ERR_NOT_CONVERGED;
                break;
            }
        }
    }
    /* the residual reported is the full load's: at a failed first level the state is the
     * rest state, whose residual at load 0 (1e-11 of nothing) read as nearly converged */
    *relres = static_residual(o, rc == CS_OK ? load : 1.0, res, NULL) / fnorm;
    free(x_save);
    cs_elastic_release_tangent(o);
    o->elastic_energy_valid = false;
    return rc;
}

int cs_world_solve_static(cs_world_t *w)
{
    if (!w)
        return CS_ERR_INVALID;
    cs_step_stats st = {.converged = true};
    double t0 = now_ms();
    int rc = CS_OK;
    cs_fracture_clear_step(w);
    for (int i = 0; i < w->n_objects; i++) {
        cs_object *o = w->objects[i];
        if (o->n_fixed_nodes == 0 || o->n_fixed_nodes == o->n || o->model == CS_MODEL_RIGID)
            continue; /* no equilibrium without supports; nothing to do when all held */
        if (static_cancelled(w)) {
            rc = CS_ERR_CANCELLED;
            break;
        }
        int r = solve_static_object(w, o, &st);
        if (r != CS_OK)
            rc = r;
        o->sleeping = false;
        o->wake_armed = false;
        o->still_steps = 0;
        o->act_wake_all = true;
    }
    st.ms_total = st.ms_solve = now_ms() - t0;
    w->stats = st;
    return rc;
}

/* ---------------------------------------------------------------- reset and reading */

void cs_world_reset(cs_world_t *w)
{
    if (!w)
        return;
    cs_fracture_clear_step(w);
    for (int i = 0; i < w->n_objects; i++) {
        cs_object *o = w->objects[i];
        memcpy(o->x, o->cm.node_rest, (size_t)o->n * 3 * sizeof(double));
        memset(o->v, 0, (size_t)o->n * 3 * sizeof(double));
        o->n_inputs = 0;
        o->sleeping = false;
        o->wake_armed = false;
        o->still_steps = 0;
        o->act_wake_all = true;
        o->lag.valid = false;
        o->lag.small_mg = false; /* "auto" decides again: a reset run repeats the first */
        o->lag.hard_steps = 0;
        memset(o->contact, 0, (size_t)o->n);
        memset(o->ground, 0, (size_t)o->n * 3 * sizeof(double));
        o->elastic_energy_valid = false;
        o->contact_seen = false;
        cs_cg_forget(&o->cg);
        cs_elastic_reset(o);
        cs_surface_skin(&o->surf, &o->cm, o->x, 1);
        if (o->rb)
            cs_rigid_reset(o);
    }
    w->time = 0;
    w->frame = 0;
    memset(&w->stats, 0, sizeof w->stats);
}

double cs_world_time(const cs_world_t *w)
{
    return w->time;
}

int64_t cs_world_frame(const cs_world_t *w)
{
    return w->frame;
}

const cs_world_def *cs_world_get_def(const cs_world_t *w)
{
    return &w->def;
}

const cs_step_stats *cs_world_last_stats(const cs_world_t *w)
{
    return &w->stats;
}

int cs_object_get_info(const cs_world_t *w, cs_object_id id, cs_object_info *info)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o || !info)
        return CS_ERR_UNKNOWN_OBJECT;
    *info = (cs_object_info){
        .name = o->name, .model = o->model, .integrator = o->integrator, .material = o->mat, .cube_size = o->cm.h,
        .origin = {o->cm.origin[0], o->cm.origin[1], o->cm.origin[2]},
        .n_cells = o->cm.n_cells, .n_nodes = o->n, .n_fixed_nodes = o->n_fixed_nodes,
        .n_surface_vertices = o->surf.n_vertices, .n_surface_triangles = o->surf.n_triangles,
        .topology_version = o->topology_version, .sleeping = o->sleeping,
        .fracture = o->fracture, .volume = o->cm.n_cells * o->cm.h * o->cm.h * o->cm.h,
        .mass = o->mass};
    return CS_OK;
}

int cs_object_static_unstable(const cs_world_t *w, cs_object_id id, bool *unstable)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o || !unstable)
        return CS_ERR_UNKNOWN_OBJECT;
    *unstable = o->static_unstable;
    return CS_OK;
}

int cs_object_inverted_cells(const cs_world_t *w, cs_object_id id, int *count, double *min_det)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return CS_ERR_UNKNOWN_OBJECT;
    const int k = cs_strain_inverted_cells(o->x, o->cm.cell_nodes, o->cm.n_cells, o->cm.h,
                                           min_det);
    if (count)
        *count = k;
    return CS_OK;
}

int cs_object_nodes(const cs_world_t *w, cs_object_id id, const double **rest,
                    const double **pos, const double **vel, int *n)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return CS_ERR_UNKNOWN_OBJECT;
    if (rest)
        *rest = o->cm.node_rest;
    if (pos)
        *pos = o->x;
    if (vel)
        *vel = o->v;
    if (n)
        *n = o->n;
    return CS_OK;
}

int cs_object_cells(const cs_world_t *w, cs_object_id id, const int32_t **ijk,
                    const int32_t **nodes, int *n)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return CS_ERR_UNKNOWN_OBJECT;
    if (ijk)
        *ijk = o->cm.cell_ijk;
    if (nodes)
        *nodes = o->cm.cell_nodes;
    if (n)
        *n = o->cm.n_cells;
    return CS_OK;
}

int cs_object_surface(const cs_world_t *w, cs_object_id id, const double **vertices, int *nv,
                      const int32_t **triangles, int *nt)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return CS_ERR_UNKNOWN_OBJECT;
    if (vertices)
        *vertices = o->surf.pos;
    if (nv)
        *nv = o->surf.n_vertices;
    if (triangles)
        *triangles = o->surf.tris;
    if (nt)
        *nt = o->surf.n_triangles;
    return CS_OK;
}

uint64_t cs_object_state_hash(const cs_world_t *w, cs_object_id id)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return 0;
    uint64_t hsh = 14695981039346656037ULL;
    for (int i = 0; i < 3 * o->surf.n_vertices; i++) {
        float f = (float)o->surf.pos[i];
        unsigned char b[sizeof f];
        memcpy(b, &f, sizeof f);
        for (size_t k = 0; k < sizeof f; k++) {
            hsh ^= b[k];
            hsh *= 1099511628211ULL;
        }
    }
    return hsh;
}

int cs_object_energy(const cs_world_t *w, cs_object_id id, cs_energy *e)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o || !e)
        return CS_ERR_UNKNOWN_OBJECT;
    cs_object *mo = (cs_object *)o; /* the cache is not part of the observable state */
    /* localframe under central differences moves with its consistent (B-spline) mass: the
     * energy it conserves is ½ vᵀM v with that M, and gravity acts on its rows (the lumped
     * measure swung by 70–120 % after an impulse, an outside review found) */
    const double *mrow = cs_elastic_mass_rows(o);
    const bool consistent = mrow && o->integrator == CS_INTEGRATOR_CENTRAL_DIFFERENCE;
    const double *mg = consistent ? mrow : o->m;
    double ek = -1, eg = 0;
    double *mv = consistent ? calloc((size_t)o->n * 3, sizeof *mv) : NULL;
    if (mv) {
        cs_elastic_apply_M(mo, o->v, mv, 1.0);
        ek = 0;
        for (int d = 0; d < 3 * o->n; d++)
            ek += 0.5 * o->v[d] * mv[d];
        free(mv);
    }
    if (ek < 0)
        ek = kinetic_energy(o, o->v); /* lumped (or out of memory for the product) */
    for (int i = 0; i < o->n; i++) {
        const double *x = o->x + 3 * i;
        eg -= mg[i] * (w->def.gravity[0] * x[0] + w->def.gravity[1] * x[1] +
                       w->def.gravity[2] * x[2]);
    }
    if (o->rb) {
        ek = cs_rigid_kinetic_energy(o);
        mo->elastic_energy = 0;
        mo->elastic_energy_valid = true;
    }
    if (!mo->elastic_energy_valid) {
        mo->elastic_energy = cs_elastic_energy(mo, o->x);
        mo->elastic_energy_valid = true;
    }
    const double ee = o->elastic_energy;
    *e = (cs_energy){.kinetic = ek, .elastic = ee, .gravity = eg};
    return CS_OK;
}

int cs_object_rigid_state(const cs_world_t *w, cs_object_id id, cs_rigid_state *s)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o || !s)
        return CS_ERR_UNKNOWN_OBJECT;
    if (!o->rb)
        return CS_ERR_INVALID;
    const cs_rigid *rb = o->rb;
    *s = (cs_rigid_state){.mass = rb->mass};
    memcpy(s->position, rb->c, sizeof s->position);
    memcpy(s->orientation, rb->q, sizeof s->orientation);
    memcpy(s->com_rest, rb->com_rest, sizeof s->com_rest);
    memcpy(s->velocity, rb->v, sizeof s->velocity);
    memcpy(s->angular_velocity, rb->w, sizeof s->angular_velocity);
    /* I = R I_body Rᵀ */
    double T[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            T[3 * i + j] = 0;
            for (int k = 0; k < 3; k++)
                T[3 * i + j] += rb->R[3 * i + k] * rb->I_body[3 * k + j];
        }
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++)
                s->inertia[3 * i + j] += T[3 * i + k] * rb->R[3 * j + k];
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            s->angular_momentum[i] += s->inertia[3 * i + k] * rb->w[k];
    return CS_OK;
}
