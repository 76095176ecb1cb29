/*
 * world_internal.h — the engine's private object and world records, shared by world.c (the
 * step, inputs, reading) and fracture.c (seed 000 §2.3, §3.1–3.2). Not part of the API.
 *
 * Owns (through cs_object): the cube mesh, the bound surface, the FEM (and localframe) data and every
 * per-node array; (through cs_world) every object, and the events and topology changes of
 * the last mutating call.
 */
#ifndef CS_WORLD_INTERNAL_H
#define CS_WORLD_INTERNAL_H

#include "cubesim.h"
#include "cubemesh.h"
#include "fem.h"
#include "mss.h"
#include "solver.h"
#include "surface.h"

#define CS_MAX_INPUTS 1024
#define CS_MAX_NAME 255
#define CS_MIN_DT 1e-6 /* [s]: the smallest world dt accepted */

/*
 * Scales an object must keep for double arithmetic to work (cs_world_add_object; README
 * "Limits that protect the daemon"). Squares and products of momenta, forces and energies
 * summed over up to 2^24 cubes must stay far inside double's 1e±308: a node's mass ρh³/8, a
 * cube's stiffness E·h and (rigid bodies, whose inertia is inverted through its determinant)
 * a cube's moment of inertia ρh⁵/6 lie in [CS_MIN_SCALE, CS_MAX_SCALE] in SI units. Nothing
 * physical comes near (an electron is 1e-30 kg, the observable universe 1e53 kg); density
 * 1e-300 (node mass 1e-304 kg: every squared momentum underflows to 0 and CG divides 0 by 0)
 * and cube_size 1e300 or 1e-300 (h³ overflows to inf or underflows to 0) do not.
 */
#define CS_MIN_SCALE 1e-80
#define CS_MAX_SCALE 1e80
/*
 * An implicit step solves (M + dt²K) v = b: where a node's mass m is below the round-off of
 * dt²·k (ω²dt² = dt²k/m above 1/ε = 4.5e15) it is lost, and with it gravity, momentum and
 * the ground's reactions (measured, session 31: blocks of 1 to 64 cubes landing on the ground
 * were thrown 10 m to 1e9 m from (ω_max·dt)² = 1e15 on, none below 7e14). Refused above
 * this, a step of 1e7 periods of the stiffest cube mode; steel at 1 mm cubes and dt 1/60 s is
 * at 7e10, diamond at 0.1 mm at 6e13.
 */
#define CS_MAX_OMEGA_DT2 1e14
/*
 * A scene load that gives a node more than the speed of light in one step (dt·|f|/m) is
 * refused: nothing the engine computes means anything there, and 1e100–1e200 N loads on a
 * 2 kg block gave NaN (the ground friction's |v|² overflowed) or slid it 1e94 m sideways on
 * round-off.
 */
#define CS_MAX_STEP_SPEED 299792458.0 /* [m/s] */

/*
 * Inputs. FORCE: a constant force at a material point. DRAG: a spring (stiffness) from the
 * material point to `target`. CURVE: one segment of a drag along a polyline (seed 001 §4.1):
 * after `delay` steps the target moves from `target` to `target1` in `steps_total` steps
 * (reaching target1 on its last step); a polyline is one CURVE input per segment sharing the
 * material point. PRESSURE: a normal traction `pressure` [Pa] on every surface triangle
 * (outward positive: inflate), spread to the triangle's vertices and from each vertex to its
 * cell's corners by its skinning weights; `cell` is unused (-1) and the input belongs to every
 * piece the object breaks into. An input acts while delay == 0 and steps_left > 0.
 */
typedef enum {
    CS_INPUT_FORCE = 0,
    CS_INPUT_DRAG = 1,
    CS_INPUT_CURVE = 2,
    CS_INPUT_PRESSURE = 3
} cs_input_kind;

typedef struct cs_input {
    cs_input_kind kind;
    int32_t cell;
    double w[8];          /* trilinear weight of each corner of `cell` */
    double force[3];      /* CS_INPUT_FORCE */
    double target[3];     /* CS_INPUT_DRAG, CS_INPUT_CURVE (segment start) */
    double target1[3];    /* CS_INPUT_CURVE: segment end */
    double stiffness;     /* DRAG, CURVE [N/m] */
    double pressure;      /* CS_INPUT_PRESSURE [Pa] */
    int steps_left;
    int steps_total;      /* CURVE: steps of the segment */
    int delay;            /* steps before the input starts acting */
    bool centred;         /* DRAG, CURVE: moved to its body's centre of mass (world.c,
                             centre_fast_springs) */
} cs_input;

/* Springs (DRAG, CURVE) enter the implicit operator; FORCE and PRESSURE are loads. */
static inline bool cs_input_is_spring(const cs_input *in)
{
    return in->kind == CS_INPUT_DRAG || in->kind == CS_INPUT_CURVE;
}

/*
 * Material fields (seed 001 §3.3), the representation every element model honours.
 *
 * Each cell carries three factors at each of its 8 Gauss points (the 2×2×2 rule: point g at
 * ξ = (2·CS_CORNER[g] − 1)/√3 in the cell's [−1,1]³, i.e. rest position
 * origin + h·(ijk + ½ + (CS_CORNER[g] − ½)/√3)):
 *   young[8c+g]    factor on mat.young     (> 0)
 *   density[8c+g]  factor on mat.density   (> 0)
 *   damping[8c+g]  factor on both Rayleigh coefficients mat.damping (>= 0)
 * A model samples them at its own quadrature points (a per-cube model may use the mean of a
 * cell's 8). FEM: K_e = Σ_g young_g·K_g with 8 shared unit per-Gauss-point matrices K_g
 * (fem.h), never a matrix per element. Lumped mass (cs_object_lump_mass): node k of cell c gets
 * Σ_g ρ·density_g·N_k(ξ_g)·h³/8 (the row sum of the consistent mass; ρh³/8 when uniform).
 * Damping: C = α·M_d + β·K_d with M_d lumped like M from density·damping and
 * K_d = Σ_g young_g·damping_g·K_g; while every damping factor is 1 (has_damping false) that is
 * the plain α M + β K and the integrators use M and K. Every model honours the fields
 * through elastic.h (cs_elastic_fields_changed after any change; K_d, M_d products): mss uses
 * each cell's mean factor, localframe the nearest Gauss point's at each of its quadrature
 * points (8 octant matrices), rigid bodies integrate the density at the Gauss points. Every
 * array is always allocated (all 1 for a plain object); fracture copies them with the cells.
 */
typedef struct cs_fields {
    double *young, *density, *damping; /* 8 per cell */
    double *kd;       /* 8 per cell: young·damping (valid when has_damping) */
    double *dd;       /* 8 per cell: density·damping (valid when has_damping) */
    double *md;       /* per node: the lumped α-damping mass (valid when has_damping) */
    double *tmp;      /* 9 per node: scratch of the damping products (when has_damping) */
    bool has_damping; /* some damping factor differs from 1 */
    bool has_young;   /* some young factor differs from 1 (else the models may ignore it) */
} cs_fields;

/*
 * The lagged preconditioner of the implicit step (world.c "the lagged preconditioner"): the
 * multigrid hierarchy built for one step is reused by the next ones while what it was built
 * from has not changed (the key below) and no cell has turned by more than the world's
 * pc_lag_angle since (against the hierarchy's own copies of the held dofs and rotations,
 * cs_mg_held_matches, cs_mg_rotation_drift). Zeroed with the object (calloc); owns nothing.
 */
typedef struct cs_pc_lag {
    bool valid;            /* the hierarchy o->mg holds is the one this key describes */
    int steps;             /* later steps that reused it since it was built */
    double coef[7];        /* mcoef, kcoef, cmcoef, ckcoef, pcoef, penalty, dcoef */
    const double *kf;      /* fem.kf at the build (NULL: uniform) */
    bool has_damping;
    uint64_t springs;      /* hash of the drag springs in the operator (pc_lag_springs) */
    /* counters (tests, measurements): builds of the implicit step, steps that reused one,
     * lagged solves that missed the tolerance and were redone with a fresh build */
    long builds, reuses, retries;
    int fresh_it;          /* CG iterations of the last round-0 solve on a fresh build */
    /* "auto" below CS_MG_AUTO_CELLS: implicit steps in a row whose block-Jacobi solves took
     * more than CS_MG_AUTO_JACOBI_IT iterations; at CS_MG_AUTO_HARD_STEPS the object takes
     * multigrid (small_mg) until a reset or a change of its material fields */
    int hard_steps;
    bool small_mg;
    double drift;          /* the last step's max over cells of 3 − tr(R_builtᵀ R) */
} cs_pc_lag;

/* Defaults of the lag rule (cs_world pc_lag_angle, pc_lag_steps): rebuild when a cell has
 * turned by more than this many radians since the build, or after this many reuses. 0.05 rad:
 * measured on beams of E = 1e5 to 1e8, a swinging soft cantilever, tumbling blocks (README
 * "The lagged multigrid hierarchy"): iterations rise from 0.02 rad at E = 1e8, from 0.05 at
 * 1e7, from 0.1 at 1e5; 0.05 saves the most in sum and loses nowhere. */
#define CS_PC_LAG_ANGLE 0.05
#define CS_PC_LAG_STEPS 50

/* One kin's born pairs seen from an object (cs_object.born): ref[i] is node i's reference depth
 * [m] behind the kin's born faces (≤ 0); nodes from n on (made since) have 0. */
typedef struct cs_born_ref {
    cs_object_id other;
    int n;
    float *ref;
} cs_born_ref;

/* A node's ground contact (cs_object.contact). In implicit solves a sticking node's tangential
 * velocity is held at 0 and a sliding node feels μ fn against its motion, both inside the
 * solve (world.c, constrain_ground and ground_reactions). */
enum {
    CS_GROUND_FREE = 0,     /* not in contact */
    CS_GROUND_SLIDE = 1,    /* normal velocity held; Coulomb friction μ fn in b */
    CS_GROUND_RELEASED = 2, /* the ground would have had to pull: free for the next step */
    CS_GROUND_STICK = 3     /* normal and tangential velocity held */
};

/* Whether a node's contact state (cs_object.contact) has it on the ground this step. */
static inline bool cs_ground_contact(uint8_t c)
{
    return c == CS_GROUND_SLIDE || c == CS_GROUND_STICK;
}

typedef struct cs_object {
    cs_object_id id;
    char *name;
    cs_model model;
    cs_integrator integrator; /* resolved: never CS_INTEGRATOR_DEFAULT */
    cs_material mat;
    bool fracture;
    double fracture_radius;  /* [m], > 0 */
    uint8_t *cell_cut;       /* per cell: bit 2·axis + (side > 0) set where a fracture cut
                                that face; NULL until the first fracture */
    uint8_t *cell_open;      /* per cell, the same bits: faces whose four nodes are separated
                                (their closing surfaces exist); NULL until then */
    uint8_t *tri_kind;       /* per surface triangle: 0 from the mesh, 1 made by fracture */
    int32_t *corner_vertex;  /* per node: the surface vertex made for it as a closing-surface
                                corner (seed 000 §3.2), or -1; NULL until the first fracture */
    cs_cubemesh cm;
    cs_surface surf;
    cs_fem fem;
    struct cs_lf *lf;      /* localframe model data (localframe.h); NULL for other models */
    cs_mss mss;            /* CS_MODEL_MSS only (seed 004) */
    int n;                 /* nodes */
    double *x, *v, *m;     /* 3, 3, 1 per node */
    double *f_const;       /* gravity + scene loads, 3 per node */
    double *f, *b, *v1, *blocks;
    uint8_t *mask;         /* per dof: held */
    uint8_t *smask;        /* per dof: held or in ground contact during this step's solve */
    uint8_t *contact;      /* per node, CS_GROUND_*: the ground contact this step */
    double *ground;        /* per node: the ground's friction force on it while it slides,
                              as in b (x, y) [N], and the normal force of its last contact [N] */
    int n_fixed_nodes;     /* held nodes (removed dofs or penalty springs) */
    /* Constraints (seed 001 §4.2): with penalty == 0 held nodes' dofs are removed (mask);
     * with penalty > 0 they stay free and a spring of that stiffness [N/m] per node pulls
     * each towards its rest position (pin[node] = 1, mask 0). */
    double penalty;
    uint8_t *pin;          /* per node: held by a penalty spring */
    double strain_limit;   /* strain_limit.h; 0 = none */
    uint8_t *sl_flag;      /* strain_limit.c scratch: per cell, 2 per cell; cells they hold */
    int32_t *sl_list;
    size_t sl_cap_cells;
    /* An integrator honours them through world.c: gather_forces adds k_p (X − x) at pinned
     * nodes, and an implicit operator adds pcoef·k_p on their diagonal (step_operator and
     * build_preconditioner do; central differences' cd_operator too, with 2dt²). An explicit
     * integrator must keep dt below 2·sqrt(m/k_p): cs_object_check_stability refuses it. */
    cs_fields fld;
    double omega2_plain;   /* ω²max of the plain material (fields and penalty not included),
                              for the stability and precision limits; 0 for rigid bodies */
    double mass;
    cs_cg_work cg;
    struct cs_mg *mg;      /* multigrid hierarchy (mg.h), built on first use; NULL otherwise */
    cs_input inputs[CS_MAX_INPUTS];
    int n_inputs;
    int still_steps;
    /* a deformable–deformable contact pass (rigid.c) has seen the object since it was added
     * or reset; if not, cs_world_step runs one before its first step (cs_rigid_prestep).
     * Fracture pieces start with it set: their born pairs take their first contacts after a
     * step (born_contacts). */
    bool contact_seen;
    bool contact_pushed; /* a rigid contact pushed its nodes in the last solve: a Newmark
                            object's next step is implicit Euler's, whose response the contact
                            solve modelled (contact_soft.h) */
    bool sleeping;
    bool static_unstable; /* the last static solve's equilibrium has negative stiffness */
    /* The velocity the step in which it fell asleep started from (world.c, wake_velocity): at
     * rest, what the contacts' impulses left on its nodes, the load of what rests on it. The
     * first step after it wakes (wake_armed) starts from it if no contact reached the object
     * while it slept and it still has n_wake nodes. wake_saved: this step made the copy. */
    double *v_wake;
    int n_wake;
    bool wake_saved, wake_armed;
    /* Deformable–deformable contacts (rigid.c soft_contacts) between pieces of one fractured
     * object: kin is the id of the object all of them came from (its own id otherwise); a
     * piece is born touching its kin across the crack, so a pair of kin takes no contacts
     * until their boxes have once been apart; apart lists the kin this object's box has been
     * apart from (owned, n_apart of cap_apart). */
    cs_object_id kin;
    cs_object_id *apart;
    int n_apart, cap_apart;
    /* Until then they take contacts only between their born pairs (rigid.c born_contacts):
     * this object's nodes at a lattice point that is a corner of a kin's cells, against those
     * cells. born lists, per kin not yet apart, the reference depth each node had behind the
     * kin's faces when the pair was first seen (≤ 0; the overlap the crack was born with,
     * moved back by a step) and has come out to since: only depth beyond it is pushed out.
     * Owned (cs_rigid_free), n_born of cap_born; a piece made by a fracture starts with none. */
    struct cs_born_ref *born;
    int n_born, cap_born;
    /* Active regions (world.c "active regions", seed 000 §2.2): NULL/0 until first used.
     * A frozen node is held where it is with v = 0 outside the solve; a cell whose 8 nodes are
     * frozen is inactive and skipped by the element passes (fem.cell_active during a step). */
    uint8_t *frozen;        /* per node */
    uint8_t *cell_active;   /* per cell: some node not frozen */
    uint8_t *cell_flip;     /* per cell: scratch, cells changing state */
    int32_t *calm;          /* per node: steps in a row it met the freezing criterion */
    double *f_skip;         /* 3 per node: elastic force of the inactive cells (constant while
                               they are: their nodes do not move) */
    int act_nodes, act_cells;  /* sizes the arrays were made for */
    int n_frozen, n_active_cells;
    bool act_wake_all;      /* set by anything that changes the object outside a step (paint,
                               reset, statics): every node wakes before the next step */
    uint32_t topology_version;
    /* elastic energy of the current positions, valid until they change (status messages
     * ask for it several times a second; recomputing means a rotation per element) */
    double elastic_energy;
    bool elastic_energy_valid;
    /* operator coefficients of the current solve */
    double mcoef, kcoef, dcoef;
    double pcoef;          /* on the penalty springs (dt² in a step, 1 in statics) */
    double cmcoef, ckcoef; /* on α·M_d and β·K_d when fld.has_damping (then mcoef = 1 and
                              kcoef carries only the dt² of K) */
    /* CS_MODEL_RIGID: pose, velocities and mass properties (rigid.h); NULL otherwise */
    struct cs_rigid *rb;
    cs_pc_lag lag;         /* the implicit step's lagged multigrid preconditioner */
    /* localframe: the Cholesky factor of its scalar consistent mass, the preconditioner of
     * its central-difference steps (elastic.c cs_elastic_mass_factor); NULL until built, after
     * a change of the mass (fields, fracture) or when it could not be built (mfac_failed) */
    struct cs_mass_factor *mfac;
    bool mfac_failed;
} cs_object;

/* The topology changes of one mutating call: their arrays live in one arena. */
typedef struct cs_topo_list {
    cs_topo_change *items;
    int n, cap;
    void **blocks;          /* owned allocations the items point into */
    int n_blocks, cap_blocks;
} cs_topo_list;

struct cs_world {
    cs_world_def def;
    int threads;
    cs_object **objects;
    int n_objects, cap_objects;
    cs_object_id next_id;
    double time;
    int64_t frame;
    cs_step_stats stats;
    cs_event *events;
    int n_events, cap_events;
    cs_topo_list topo;
    struct cs_rigid_world *rigid; /* rigid.c's per-step scratch; NULL until a rigid step */
    /* rigid.c: a deformable object that at least this many rigid bodies' boxes overlap gets
     * its cells and nodes filed in a grid for the contact search (CS_BROADPHASE_BODIES; the
     * tests set 0 and INT_MAX to compare both paths) */
    int broadphase_min_bodies;
    /* rigid.c: deformable objects' pairs (soft_contacts, wake_near_movers) all tested, as
     * before their broad phase (false; the tests set it to compare both) */
    bool object_pairs_all;
    /* The lagged preconditioner's rule (cs_pc_lag): rebuild when a cell turned by more than
     * pc_lag_angle [rad] since the build (0: every step, as before the lag) or after
     * pc_lag_steps steps; CS_PC_LAG_ANGLE and CS_PC_LAG_STEPS unless a test sets them. */
    double pc_lag_angle;
    int pc_lag_steps;
    /* a lagged solve stops at twice the last fresh one's iterations + 2 (at least 8) and
     * goes on with a fresh build (true unless a test clears it) */
    bool pc_lag_cap;
    /* cs_world_set_cancel's function and its argument (NULL: statics never stop early) */
    bool (*cancel)(void *ctx);
    void *cancel_ctx;
};

#define CS_BROADPHASE_BODIES 4

/* Defined in world.c and fields.c, used by fracture.c and each other. */
/* Write the message to err (if any) and return code: the engine's runtime-error idiom. */
int cs_engine_fail(char *err, size_t errlen, int code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
cs_object *cs_world_find_internal(const cs_world_t *w, cs_object_id id);
/* The clients' inputs that o's next step applies (those not waiting for their start): f +=
 * their forces at o->x (point forces, drag and curve springs, pressure); y += coef · the drag
 * and curve springs' stiffness times p (the implicit operators' term); blocks (9 per node)
 * += its diagonal, coef · k w_k² per corner. */
void cs_object_add_input_forces(cs_object *o, double *f);
void cs_object_add_spring_operator(const cs_object *o, double coef, const double *p, double *y);
void cs_object_add_spring_blocks(const cs_object *o, double coef, double *blocks);
int cs_world_append_object(cs_world_t *w, cs_object *o);
/* An implicit object's nodes on or below the ground plane that no step has constrained yet (it
 * was just added or reset): marked sticking or sliding as the next step's ground constraint
 * will mark them, so that a contact pass before that step (cs_rigid_prestep) sees the object
 * supported. */
void cs_world_ground_predict(const cs_world_t *w, cs_object *o);
void cs_object_free_internal(cs_object *o);
int cs_object_alloc_state(cs_object *o);
/* Allocate o->fld for o->cm.n_cells cells, every factor 1. Returns -1 on out of memory. */
int cs_fields_alloc(cs_object *o);
void cs_fields_free(cs_fields *f);
/* Check design region i (message names "fields[i]"); CS_OK or CS_ERR_INVALID. */
int cs_fields_check_region(const cs_field_region *r, int i, char *err, size_t errlen);
/* Multiply the fields by every region, evaluated at each Gauss point's rest position. */
void cs_fields_apply_regions(cs_object *o, const cs_field_region *r, int n);
/* Lumped masses o->m and o->mass from the density field, and M_d, K_d (fld.md reallocated
 * to o->n nodes) from the damping field; has_young, has_damping and the FEM's o->fem.kf
 * (NULL while every young factor is 1) follow the fields. f_const is left alone. Returns -1 on out of
 * memory. */
int cs_object_lump_mass(cs_object *o);
/* The object's explicit or central-difference stability with its current fields and penalty
 * springs at world step dt (elastic.h: cs_elastic_object_critical_dt): CS_OK, or
 * CS_ERR_INVALID with a message saying what is unstable (`what`: "" or a prefix such as
 * "paint: "). Implicit Euler and rigid objects always pass. */
int cs_object_check_stability(const cs_object *o, double dt, const char *what, char *err,
                              size_t errlen);

/* Defined in fracture.c, used by world.c. */
void cs_fracture_clear_step(cs_world_t *w);
void cs_world_fracture_free(cs_world_t *w);
/* Stress test and fracture of one object after its step (fracture enabled only). */
int cs_fracture_after_step(cs_world_t *w, cs_object *o);

#endif


