/*
 * cubesim.h — the one public header of the cubesim engine.
 *
 * The engine owns worlds of deformable objects, each a surface mesh embedded in a mesh of
 * equal cubes (seed 000). It has no knowledge of LCM, files or scenes: the daemon, the tests
 * and the benchmarks are adapters around this API.
 *
 * Conventions
 * - Worlds and objects are made from definition structs; cs_*_def_default() gives the documented
 *   defaults. `create` validates every field and reports the first bad one by name.
 * - Objects are named by ids (cs_object_id). Ids are never reused within a world; a stale or
 *   unknown id is the error CS_ERR_UNKNOWN_OBJECT, never a crash.
 * - Runtime errors are negative return codes (cs_status) plus, where a function takes one, a
 *   caller-owned message buffer `err` of `errlen` bytes that receives one line naming the
 *   problem. The engine never prints and never aborts on bad input.
 * - SI units throughout: metres, seconds, kilograms, newtons, pascals.
 * - Pointers returned by read functions stay valid until the next call that mutates the world
 *   (step, solve, reset, add/remove object, destroy).
 * - A world is not thread-safe; the engine may use worker threads inside a step only, and its
 *   results do not depend on their number.
 */
#ifndef CUBESIM_H
#define CUBESIM_H

#include <stddef.h>
#include <stdint.h>
#include <stdbool.h>

#include "topo.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum cs_status {
    CS_OK = 0,
    CS_ERR_INVALID = -1,        /* a definition or argument is out of range or not finite */
    CS_ERR_UNKNOWN_OBJECT = -2, /* no object with that id (or name) in this world */
    CS_ERR_NOMEM = -3,          /* an allocation failed; the world is unchanged */
    CS_ERR_GEOMETRY = -4,       /* a mesh cannot be voxelized (open, empty, degenerate) */
    CS_ERR_NOT_CONVERGED = -5,  /* a solve hit its iteration limit; state is still finite */
    CS_ERR_DIVERGED = -6,       /* a step produced non-finite values; the step was undone */
    CS_ERR_CANCELLED = -7       /* a static solve stopped by cs_world_set_cancel's function */
} cs_status;

/* Human-readable name of a status code ("ok", "invalid argument", ...). Never NULL. */
const char *cs_status_str(int status);

typedef uint32_t cs_object_id; /* 0 is never a valid id */
#define CS_NULL_OBJECT ((cs_object_id)0)

typedef enum cs_model {
    CS_MODEL_LINEAR = 0,       /* small-strain hexahedral FEM (seed 000 App. A) */
    CS_MODEL_COROTATIONAL = 1, /* the same with per-element rotation (seed 000 §2.2) */
    CS_MODEL_MSS = 2,          /* cubic mass-spring element with correction forces (seed 004) */
    CS_MODEL_LOCALFRAME = 3,   /* local-frame B-spline model (seed 001 §3.2–3.4) */
    CS_MODEL_RIGID = 4         /* rigid cube sets (seed 000 §2.4): rigid.c */
} cs_model;

/* Parse "linear", "corotational", ...; returns 0 and sets *out, or -1 for an unknown name. */
int cs_model_from_name(const char *name, cs_model *out);
const char *cs_model_name(cs_model m);

typedef enum cs_integrator {
    CS_INTEGRATOR_DEFAULT = 0,           /* implicit Euler for every model (README
                                            "Work-precision": the evidence) */
    CS_INTEGRATOR_IMPLICIT_EULER = 1,    /* seed 000: (M + dt C + dt² K) v1 = M v + dt f, CG */
    CS_INTEGRATOR_SYMPLECTIC_EULER = 2,  /* explicit: v += dt M⁻¹f(x, v), x += dt v (seed 004) */
    CS_INTEGRATOR_VERLET = 3,            /* explicit velocity Verlet (seed 004); both explicit
                                            ones need dt below a limit checked at add time */
    CS_INTEGRATOR_CENTRAL_DIFFERENCE = 4, /* seed 001 Eq. (20), solved by CG; conditionally
                                            stable: dt above the limit is refused */
    CS_INTEGRATOR_NEWMARK = 5            /* Newmark's average acceleration (trapezoidal rule,
                                            β = 1/4, γ = 1/2), linearized like implicit Euler:
                                            (M + dt/2 C + dt²/4 K) v1 = 2 M v + dt f − A v,
                                            x1 = x + dt (v + v1)/2; second order, no numerical
                                            damping, unconditionally stable for linear models */
} cs_integrator;

/* "default", "implicit_euler", "symplectic_euler", "verlet", "central_difference", "newmark". */
int cs_integrator_from_name(const char *name, cs_integrator *out);
const char *cs_integrator_name(cs_integrator i);

typedef struct cs_material {
    double young;         /* Young's modulus E [Pa], > 0; default 1000 */
    double poisson;       /* Poisson ratio ν, in [0, 0.5); default 0.3 */
    double density;       /* ρ [kg/m³], > 0; default 1000 */
    double damping[2];    /* Rayleigh [α (1/s, on mass), β (s, on stiffness)], >= 0; default 0,0 */
    double strength;      /* tensile strength [Pa], > 0 (fracture only); default 1e300 (never) */
    double restitution;   /* of rigid contacts, in [0, 1]; the larger of the two bodies'; 0.3 */
    double friction;      /* Coulomb coefficient of rigid contacts, in [0, 100]; the geometric
                             mean of the two (the ground: with ground_friction); default 0.5 */
} cs_material;

cs_material cs_material_default(void);

typedef struct cs_aabb {
    double min[3], max[3];
} cs_aabb;

/* A total force spread over the exposed cube faces whose centres lie in `box` (DESIGN.md). */
typedef struct cs_load {
    cs_aabb box;
    double force[3]; /* [N] */
} cs_load;

/* ---------------------------------------------------------------- material fields (seed 001 §3.3) */

/* Which factors a cs_field_factors sets (bits). */
#define CS_FIELD_YOUNG 1u
#define CS_FIELD_DENSITY 2u
#define CS_FIELD_DAMPING 4u

/* Factors on the object's material: young and density in [1e-6, 1e6], damping (on both
 * Rayleigh coefficients) in [0, 1e6]; only those whose bit is in `which` apply. */
typedef struct cs_field_factors {
    double young, density, damping;
    unsigned which; /* CS_FIELD_* bits, at least one */
} cs_field_factors;

typedef enum cs_field_shape {
    CS_FIELD_SPHERE = 0,   /* factor f inside the ball (centre, radius), 1 outside */
    CS_FIELD_BOX = 1,      /* factor f inside box, 1 outside */
    CS_FIELD_GRADIENT = 2, /* 1 at `from`, f at `to`, linear along from→to, constant beyond */
    CS_FIELD_RADIAL = 3    /* 1 + (f − 1)·(1 − (r/radius)²)² within radius of centre, 1 beyond */
} cs_field_shape;

/* A design region of an object's material fields, evaluated at every Gauss point's rest
 * position; regions multiply the fields in order (start: all 1). */
typedef struct cs_field_region {
    cs_field_shape shape;
    double centre[3], radius; /* SPHERE, RADIAL; radius > 0 */
    cs_aabb box;              /* BOX */
    double from[3], to[3];    /* GRADIENT; distinct */
    cs_field_factors factors;
} cs_field_region;

/* How held ("fixed") nodes are held (seed 001 §4.2). */
typedef enum cs_constraint_mode {
    CS_CONSTRAINT_REMOVE = 0, /* their degrees of freedom are removed from the solve */
    CS_CONSTRAINT_PENALTY = 1 /* a spring per node pulls each to its rest position */
} cs_constraint_mode;

typedef enum cs_geometry_kind {
    CS_GEOMETRY_MESH = 0,  /* a closed triangle surface, voxelized (seed 000 §2.1) */
    CS_GEOMETRY_CELLS = 1  /* explicit cells; the surface is their boundary */
} cs_geometry_kind;

typedef struct cs_object_def {
    const char *name;        /* copied; must be non-empty and unique in the world */
    cs_model model;          /* default CS_MODEL_COROTATIONAL */
    cs_integrator integrator;/* default CS_INTEGRATOR_DEFAULT (the model's own) */
    cs_material material;    /* default cs_material_default() */
    double cube_size;        /* h [m], > 0; default 0.1 */
    bool fracture;           /* default false */
    double fracture_radius;  /* cells whose centre lies within this distance [m] of an
                                overstressed cell's centre are labelled by the splitting
                                plane (seed 000 §2.3); >= 0; 0 = 1.5·cube_size (default) */

    cs_geometry_kind geometry;
    /* CS_GEOMETRY_MESH: world-space surface (already scaled/placed), borrowed during create. */
    const double *mesh_vertices;  /* 3 per vertex */
    int n_mesh_vertices;
    const int32_t *mesh_triangles; /* 3 per triangle, counter-clockwise seen from outside */
    int n_mesh_triangles;
    /* CS_GEOMETRY_CELLS: cell (i,j,k) spans origin + h·[i,i+1]×[j,j+1]×[k,k+1]. Borrowed. */
    double cells_origin[3];
    const int32_t *cells_ijk; /* 3 per cell, no duplicates */
    int n_cells;

    const cs_aabb *fixed;     /* boxes; every cube-mesh vertex inside one is held. Borrowed. */
    int n_fixed;
    const cs_load *loads;     /* constant loads. Borrowed. */
    int n_loads;
    const cs_field_region *fields; /* material design regions, applied in order. Borrowed. */
    int n_fields;
    cs_constraint_mode constraints;/* default CS_CONSTRAINT_REMOVE */
    double penalty_stiffness; /* [N/m] per held node, >= 0 (PENALTY only); 0: automatic,
                                 1e4·E·h (a held node then yields |reaction|/(1e4·E·h)) */
    double strain_limit;      /* corotational and mss: after each step no cube is stretched
                                 past this factor of its edge, or compressed below its inverse,
                                 along any direction, nor inverted (strain_limit.h); 0 = none
                                 (default), else in [CS_STRAIN_LIMIT_MIN, CS_STRAIN_LIMIT_MAX] */
} cs_object_def;
#define CS_STRAIN_LIMIT_MIN 1.1
#define CS_STRAIN_LIMIT_MAX 1000.0

cs_object_def cs_object_def_default(void);

/* The CG preconditioner of the FEM solves (implicit Euler, statics). */
typedef enum cs_preconditioner {
    CS_PRECOND_AUTO = 0,      /* multigrid for linear, corotational and localframe objects of at least
                                 CS_MG_AUTO_CELLS cells, in statics, and for smaller ones once
                                 block Jacobi has taken more than CS_MG_AUTO_JACOBI_IT
                                 iterations in CS_MG_AUTO_HARD_STEPS implicit steps in a row
                                 (until a reset or a change of its fields), if it is held by
                                 three fixed nodes not on a line; block Jacobi otherwise */
    CS_PRECOND_JACOBI = 1,    /* 3×3 block Jacobi */
    CS_PRECOND_MULTIGRID = 2  /* a geometric multigrid V-cycle per iteration (built from the
                                 FEM's cubes: linear, corotational and localframe; mss keeps
                                 block Jacobi) */
} cs_preconditioner;
#define CS_MG_AUTO_CELLS 2048
#define CS_MG_AUTO_JACOBI_IT 25
#define CS_MG_AUTO_HARD_STEPS 2

/* Cubes a scene's boxes and cell sets may hold together, and a mesh may fill (the scene
 * parser and the voxelizer refuse more): a deformable cube costs the daemon about 1.7 kB, so
 * this is about 7 GB. */
#define CS_MAX_SCENE_CUBES (1 << 22)

/* Parse "auto", "jacobi", "multigrid"; returns 0 and sets *out, or -1. */
int cs_preconditioner_from_name(const char *name, cs_preconditioner *out);

/* What the CG tolerance of an implicit Euler step is relative to. */
typedef enum cs_cg_relative {
    CS_CG_RELATIVE_STEP = 0, /* ‖b − A v‖: the Δv form of the step (what the step changes) */
    CS_CG_RELATIVE_RHS = 1   /* ‖b‖ = ‖M v + dt f‖ (before session 13; mostly momentum at
                                small dt) */
} cs_cg_relative;

/* Parse "step", "rhs"; returns 0 and sets *out, or -1. */
int cs_cg_relative_from_name(const char *name, cs_cg_relative *out);

typedef struct cs_world_def {
    double dt;               /* time step [s], in [1e-6, 1]; default 1/60 */
    double gravity[3];       /* [m/s²]; default (0, 0, -9.81) */
    bool has_ground;         /* default false */
    double ground_height;    /* the plane z = ground_height, solid below; default 0 */
    double ground_friction;  /* Coulomb coefficient at the ground, >= 0; default 0.5 */
    double cg_tolerance;     /* relative residual of every solve, in (0, 1); 1e-4 (README "Defaults (issue 6 part 3)": the evidence); relative to ‖b‖ except in implicit Euler steps (cg_relative_to) */
    cs_cg_relative cg_relative_to; /* implicit Euler steps: default CS_CG_RELATIVE_STEP */
    int cg_max_iterations;   /* >= 1; default 500 */
    cs_preconditioner preconditioner; /* default CS_PRECOND_AUTO */
    int threads;             /* worker threads inside a step, >= 0; 0 = all cores; default 0 */
    int simd_width;          /* element kernels' vectors [bits]: 256, 512 (with AVX-512) or 0 = by
                              * the CPU (server/engine/simd.h); the same results either way;
                              * default 0 */
    double sleep_speed;      /* an object whose fastest node is slower than this [m/s] ... */
    int sleep_steps;         /* ... for this many steps in a row sleeps; 0 = never; default 30 */
    /* Active regions inside awake objects (linear/corotational FEM, implicit Euler, not
     * fracturing; seed 000 §2.2; world.c "active regions"): a node slower than active_speed
     * [m/s] whose net force f (elastic + loads + gravity + ground) has |f|·dt/m <
     * active_speed/16 for active_steps steps in a row is frozen (held, v = 0) and leaves the
     * solve; cells of frozen nodes only are skipped. It wakes when holding it takes a force
     * with |f|·dt/m >= active_speed/8 (the step is then solved again), a node of one of its
     * cells moves faster than active_speed, or an input acts on its cube. Default off. */
    int active_steps;        /* 0 = off; default 0 */
    double active_speed;     /* [m/s], > 0 when on; default 5e-4 */
    double max_force;        /* |force| above this [N] is refused; default 1e9 */
    int max_fractures;       /* fracture events per object per step, >= 1; default 4 */
    uint64_t seed;           /* of the random corner offsets of closing surfaces; default 1 */
} cs_world_def;

cs_world_def cs_world_def_default(void);

typedef struct cs_world cs_world_t;

/* Create an empty world. On error *out is NULL and err names the bad field. */
int cs_world_create(const cs_world_def *def, cs_world_t **out, char *err, size_t errlen);
void cs_world_destroy(cs_world_t *w); /* NULL is fine */

/* Voxelize and add an object; on error the world is unchanged. Objects with an explicit
 * integrator are refused (CS_ERR_INVALID, the limit in err) when the world's dt exceeds their
 * stability limit 2/ω_max (smaller with damping; ω_max bounded per cube at rest). */
int cs_world_add_object(cs_world_t *w, const cs_object_def *def, cs_object_id *id,
                        char *err, size_t errlen);
int cs_world_remove_object(cs_world_t *w, cs_object_id id);

/* Ids of the live objects in creation order; returns the count, writes at most `max`. */
int cs_world_object_ids(const cs_world_t *w, cs_object_id *ids, int max);
/* Id of the object named `name`, or CS_NULL_OBJECT. */
cs_object_id cs_world_find_object(const cs_world_t *w, const char *name);

/*
 * A point force: `force` [N] acts for `seconds` of simulated time (0: exactly one step) at the
 * material point currently nearest to `point` (world space): the object's surface vertex
 * nearest to it, the force spread to the eight corners of that vertex's cube by its trilinear
 * weights (a point between vertices goes to one of them). Refused (CS_ERR_INVALID, message in err) if anything is not
 * finite, |force| > max_force or seconds < 0.
 */
int cs_world_apply_force(cs_world_t *w, cs_object_id id, const double point[3],
                         const double force[3], double seconds, char *err, size_t errlen);
/*
 * A drag: the material point nearest to `grab` is pulled towards `target` by a spring of
 * `stiffness` [N/m] for `seconds` of simulated time. Same refusals as apply_force.
 */
int cs_world_drag(cs_world_t *w, cs_object_id id, const double grab[3], const double target[3],
                  double stiffness, double seconds, char *err, size_t errlen);

/*
 * A drag along a curve (seed 001 §4.1): the material point nearest to points[0] is pulled by a
 * spring of `stiffness` [N/m] towards a target that moves along the polyline points (n of
 * them, 3 doubles each, 2 <= n <= CS_MAX_CURVE_POINTS) at constant speed, reaching its end
 * after `seconds` (> 0) of simulated time; then the input ends. Refused if anything is not
 * finite, the curve has zero length, or stiffness × (largest distance from the grabbed point
 * to the curve) exceeds max_force.
 */
#define CS_MAX_CURVE_POINTS 64
int cs_world_drag_curve(cs_world_t *w, cs_object_id id, const double *points, int n,
                        double stiffness, double seconds, char *err, size_t errlen);
/*
 * Inflate (pressure > 0) or deflate (< 0): a normal traction of `pressure` [Pa] on every
 * triangle of the object's surface, outward positive, following the current shape, for
 * `seconds` (0: one step). Refused if not finite or |pressure| × surface area > max_force.
 */
int cs_world_pressure(cs_world_t *w, cs_object_id id, double pressure, double seconds,
                      char *err, size_t errlen);
/*
 * Paint the material fields: every Gauss point whose current position lies within `radius`
 * (> 0) [m] of `centre` gets the factors in f (those in f->which; set, not multiplied).
 * Masses and the gravity load follow the density at once (velocities are kept). Returns CS_OK with *touched (if
 * non-NULL) the number of Gauss points painted (0 is not an error), or an error naming the
 * bad argument.
 */
int cs_world_paint(cs_world_t *w, cs_object_id id, const double centre[3], double radius,
                   const cs_field_factors *f, int *touched, char *err, size_t errlen);
/* The fields of an object: 8 factors per cell each (Gauss point order as CS_CORNER), n cells.
 * Valid until the next mutating call. */
int cs_object_fields(const cs_world_t *w, cs_object_id id, const double **young,
                     const double **density, const double **damping, int *n);

/* Advance one dt: inputs, each object's integrator (implicit Euler or central differences),
 * ground, skinning, sleep. */
int cs_world_step(cs_world_t *w);
/*
 * Static equilibrium under gravity, loads and held forces, from the current state. For
 * corotational objects this is the geometrically nonlinear equilibrium (load stepping and
 * Newton iterations with the corotated tangent). Velocities are zeroed.
 */
int cs_world_solve_static(cs_world_t *w);
/*
 * A function cs_world_solve_static asks, between its Newton steps and its CG iterations,
 * whether to stop (a daemon's SIGTERM: a large static solve runs for minutes). When it says
 * yes the solve returns CS_ERR_CANCELLED with each object at its last load level reached
 * (the rest state if none) and the objects after it untouched. NULL (the default): never.
 * The function is called from the solving thread only.
 */
void cs_world_set_cancel(cs_world_t *w, bool (*cancel)(void *ctx), void *ctx);
/* Every object back to its rest shape, at rest; time and inputs cleared. Painted material
 * fields are kept (they are the material, not the state), and so is fracture: an object that
 * broke stays broken and its pieces stay objects, each back at its own rest shape (the engine
 * keeps no copy of the unbroken definitions; the daemon's `reset` rebuilds the world from its
 * scene when anything fractured or was painted). */
void cs_world_reset(cs_world_t *w);

double cs_world_time(const cs_world_t *w);
int64_t cs_world_frame(const cs_world_t *w);
const cs_world_def *cs_world_get_def(const cs_world_t *w);

typedef struct cs_object_info {
    const char *name;
    cs_model model;
    cs_integrator integrator; /* never DEFAULT: the one in use */
    cs_material material;
    double cube_size;
    double origin[3];         /* world position of lattice index (0,0,0) */
    int n_cells, n_nodes, n_fixed_nodes;
    int n_surface_vertices, n_surface_triangles;
    uint32_t topology_version; /* bumped whenever the surface's triangles change */
    bool sleeping;
    bool fracture;
    double volume;            /* n_cells·h³ */
    double mass;
} cs_object_info;

int cs_object_get_info(const cs_world_t *w, cs_object_id id, cs_object_info *info);

/* How many of the object's cubes are turned inside out now: a corner where the deformation
 * gradient's determinant is ≤ 0 (a load beyond what the model represents there: the elastic
 * models are linear in the strain and nothing in a static solve stops a cube from inverting).
 * *min_det (if non-NULL): the smallest corner determinant (1 at rest: the local volume ratio). */
int cs_object_inverted_cells(const cs_world_t *w, cs_object_id id, int *count, double *min_det);

/* Whether the object's equilibrium from the last cs_world_solve_static is unstable: converged,
 * but its tangent stiffness has a direction of negative curvature (a column loaded past its
 * buckling load, held straight by symmetry; corotational and mss objects are probed, the
 * other models' operators are positive definite). false before any static solve. */
int cs_object_static_unstable(const cs_world_t *w, cs_object_id id, bool *unstable);

/* Cube-mesh nodes: rest and current positions, 3 doubles each; n nodes. */
int cs_object_nodes(const cs_world_t *w, cs_object_id id, const double **rest,
                    const double **pos, const double **vel, int *n);
/* Cells: 3 int32 lattice indices and 8 node indices each (seed 000 App. A corner order). */
int cs_object_cells(const cs_world_t *w, cs_object_id id, const int32_t **ijk,
                    const int32_t **nodes, int *n);
/* The embedded surface: current vertex positions (3 doubles each) and triangles. */
int cs_object_surface(const cs_world_t *w, cs_object_id id, const double **vertices, int *nv,
                      const int32_t **triangles, int *nt);
/* 64-bit FNV-1a hash of the surface vertex positions rounded to float: clients compare it. */
uint64_t cs_object_state_hash(const cs_world_t *w, cs_object_id id);

/* Kinetic and gravity energy with the mass the object moves with: the lumped one, or the
 * consistent B-spline mass for localframe under central differences. */
typedef struct cs_energy {
    double kinetic, elastic, gravity; /* [J]; gravity potential relative to z = 0 */
} cs_energy;
int cs_object_energy(const cs_world_t *w, cs_object_id id, cs_energy *e);

/* Cost and convergence of the last step or static solve, summed over objects. */
typedef struct cs_step_stats {
    double ms_total;
    double ms_inputs, ms_rotations, ms_rhs, ms_solve, ms_post, ms_skin; /* by stage */
    int cg_iterations;      /* total over objects (sum of Newton iterations for static) */
    double cg_residual;     /* largest final relative residual over objects */
    int objects_stepped;    /* objects awake and not fully fixed */
    int cells_stepped;      /* cells of the stepped objects that went through the element
                               passes (inactive cells of active regions not counted) */
    int cells_awake;        /* every cell of the stepped objects */
    bool converged;
    int newmark_redone;     /* Newmark steps whose energy rose and were redone by implicit
                               Euler (the energy guard, README "Newmark") */
} cs_step_stats;
const cs_step_stats *cs_world_last_stats(const cs_world_t *w);

/* ---------------------------------------------------------------- rigid bodies (seed 000 §2.4) */

typedef struct cs_rigid_state {
    double position[3];         /* centre of mass, world [m] */
    double orientation[4];      /* unit quaternion (w, x, y, z): rest frame → world */
    double com_rest[3];         /* centre of mass in the rest frame: x = position + R (X − com_rest) */
    double velocity[3];         /* of the centre of mass [m/s] */
    double angular_velocity[3]; /* world axes [rad/s] */
    double mass;                /* [kg] */
    double inertia[9];          /* about the centre of mass, world axes, row-major [kg m²] */
    double angular_momentum[3]; /* I ω about the centre of mass [kg m²/s] */
} cs_rigid_state;

/* The pose and motion of a rigid object; CS_ERR_INVALID if its model is not rigid. */
int cs_object_rigid_state(const cs_world_t *w, cs_object_id id, cs_rigid_state *s);

/* ---------------------------------------------------------------- fracture (seed 000 §2.3, §3) */

typedef enum cs_event_kind {
    CS_EVENT_FRACTURE = 1,  /* an object was split along a plane (cells separated) */
    CS_EVENT_NEW_PIECE = 2  /* a face-connected part became an object of its own */
} cs_event_kind;

typedef struct cs_event {
    cs_event_kind kind;
    cs_object_id object;  /* FRACTURE: the object that broke; NEW_PIECE: the new piece */
    cs_object_id parent;  /* NEW_PIECE: the object it broke off; else CS_NULL_OBJECT */
    int64_t frame;        /* the frame (step count) in which it happened */
    double point[3];      /* FRACTURE: centre of the overstressed cell, world space [m] */
    double normal[3];     /* FRACTURE: normal of the splitting plane (the stress direction) */
    double stress;        /* FRACTURE: largest principal tensile stress [Pa]; 0 when forced */
    int faces_cut;        /* FRACTURE: cube faces separated */
    int closing_triangles;/* FRACTURE: triangles added to close the surfaces */
    int fallback_loops;   /* FRACTURE: boundary loops the §3.2 polygons left open, closed by
                             a fan around a new vertex instead (0 when §3.2 closed all) */
    int rebuilt_pieces;   /* FRACTURE: pieces whose surface enclosed no positive volume after
                             that (closing patches rejected around them) and were rebuilt: a
                             single cube as its cube shrunk about its centre to the volume its
                             surface had (at least 1e-3 h³), a larger piece as the boundary of
                             its cubes; 0 normally */
    int dropped_pieces;   /* FRACTURE: pieces of cubes holding no surface triangle (voxels
                             that only grazed the surface: no material) that were discarded */
} cs_event;

/* Events of the last step or forced fracture, in order; *count set. Valid until the next
 * mutating call. */
const cs_event *cs_world_events(const cs_world_t *w, int *count);

/*
 * Surface topology changes of the last step or forced fracture, in the order they were made
 * (topo.h): per event, the split of the object, each new piece (from_version 0), then the
 * object losing the pieces' cells. Positions in vnew_xyz are current; vnew_src names the
 * vertex each new one is a copy of (and sits exactly at), -1 for a new point. Valid until the
 * next mutating call.
 */
const cs_topo_change *cs_world_topology_changes(const cs_world_t *w, int *count);

/*
 * Force a fracture as if the cell nearest to `point` were overstressed in direction `normal`:
 * cells within `radius` [m] (0: the object's fracture_radius; never less than the face
 * neighbours) are labelled by the plane through that cell's current centre, and the + and −
 * cells are separated (seed 000 §2.3: every node between them duplicated). New pieces become
 * objects. Works whether or not the object has fracture enabled. Returns CS_OK (also when no
 * face was left to cut), or an error with err set; events and changes as after a step.
 */
int cs_world_fracture(cs_world_t *w, cs_object_id id, const double point[3],
                      const double normal[3], double radius, char *err, size_t errlen);

/* Cut exactly one face: the one between cell (i,j,k) and its neighbour at +1 along `axis`
 * (both must exist in this object and still be joined there). Nodes are duplicated only where
 * the cut faces separate the cells around them, so the face opens (and its closing surface
 * appears) once the cuts around it free all four of its nodes. Returns CS_OK or an error. */
int cs_world_cut_face(cs_world_t *w, cs_object_id id, const int32_t ijk[3], int axis,
                      char *err, size_t errlen);

/* Largest principal stress of every cell at the current positions (corotated small strain,
 * σ = C ε at the cell centre): value [Pa] and unit direction, 1 and 3 per cell; n cells. */
int cs_object_principal_stress(const cs_world_t *w, cs_object_id id, double *sigma,
                               double *dir, int n);

/* The 24×24 element stiffness matrix of a cube (row-major, seed 000 App. A corner order). */
void cs_cube_stiffness(double young, double poisson, double h, double K[24 * 24]);

#ifdef __cplusplus
}
#endif
#endif
