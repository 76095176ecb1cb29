/*
 * rigid.c — rigid bodies, their contacts and impact fracture (seed 000 §2.4, after Müller et
 * al.: every face-connected set of cubes of a rigid object is one rigid body).
 *
 * Time integration, per step of dt (semi-implicit), in substeps so that no body moves more
 * than its cube edge in one (at most MAX_SUBSTEPS):
 *   1. v += dt (F/m), ω += dt I⁻¹ τ for gravity, scene loads and client forces (acting at
 *      their material point); drags and curves are implicit springs on the point's effective
 *      mass (stable at any stiffness); a pressure has no net effect on a closed rigid body.
 *   2. sleeping bodies that a moving body's box reaches wake (they take part in this step).
 *   3. contacts: speculative (generated while the gap is below the distance the bodies can
 *      close in one step), solved by sequential impulses (projected Gauss–Seidel on the
 *      accumulated normal impulse ≥ 0 and Coulomb friction |jt| ≤ μ jn per tangent, warm
 *      started from the same contacts of the last step), with restitution above an approach
 *      speed of 2|g|dt and Baumgarte push-out beyond a slop.
 *   4. c += dt v; the rotation by the Lie–Poisson implicit midpoint rule: in body axes
 *      I (ω1 − ω0) + dt ω½ × I ω½ = 0 (ω½ = (ω0+ω1)/2, solved by Newton), then
 *      R1 = R0 cay(dt [ω½]), the Cayley rotation (quaternion (1, dt ω½/2) normalised). Both
 *      quadratic invariants of free rotation, |L| and ½ ωᵀIω, are conserved exactly by the
 *      midpoint rule, and the Cayley update makes R1 L1 = R0 L0, so the world angular
 *      momentum of a free body is conserved to rounding, tumbling about any axis.
 *      Nodes x = c + R (X − C), velocities v + ω × (x − c), surface skinned; bodies resting
 *      on each other (contact islands) fall asleep together.
 *   5. impact fracture (below).
 *
 * Collision detection: an AABB per body (grown by its speculative margin), sort-and-sweep on
 * x over bodies; for an overlapping pair, the cubes of the smaller body near the other are
 * looked up in the other's lattice (its hash), so only cube pairs within reach are tested.
 * A cube pair: libccd's MPR tells whether the two oriented boxes (grown by the margin) meet;
 * the normal and depth come from the separating-axis test over the 15 box axes (exact for
 * boxes; libccd's EPA stalls on the coplanar faces resting cubes always have, MPR's direction
 * follows the line between the centres), snapped to a face normal of either cube when within
 * ~14° of one; the contact points are the corners of either cube that lie against the other
 * (libccd's MPR point when none does, edge–edge). Normals that would push through a face
 * shared with a neighbouring cube of the same body are dropped. The ground is a plane against
 * the nodes. Deformable objects take part in the same solve (two-way): their nodes inside a
 * rigid body's cubes (out through the exposed face they came in by) and the rigid nodes inside
 * or just outside their deformed cells (against the cell's nearest exposed face, the face
 * point weighted bilinearly over its corners) are contacts whose other side is those nodes.
 * An impulse J gives those nodes momentum J at once; the solve sees them answer as they will
 * in their object's next implicit step (their diagonal stiffness blocks plus the object's
 * rigid modes, contact_soft.h), not as free point masses.
 *
 * Deformable objects against each other (soft_contacts), once per step after the bodies: a
 * node of one in (or just outside) a deformed cell of the other against that cell's nearest
 * exposed face, both sides answering as above; only pairs whose boxes overlap, found by a
 * broad phase (broadphase.h, a hierarchical grid: n log n in the objects, where testing every
 * pair made a step with 8 000 objects take 0.7–2 s) and taken in the order of their indices.
 *
 * Impact fracture: when the contact force (impulse/dt) on a body with fracture enabled exceeds
 * strength·h² and twice its weight, the body's cube mesh is solved statically (linear FEM,
 * inertia relief: the contact loads minus the rigid acceleration they cause, K + εM for the
 * rigid modes) and fracture.c splits it where the stress exceeds the strength; the pieces
 * become rigid bodies moving with the parent's velocity field.
 */
#include "rigid.h"

#include <ccd/ccd.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "broadphase.h"
#include "contact_soft.h"
#include "elastic.h"
#include "mat3.h"

#define PGS_ITERATIONS 60
/* The friction rows' view of a deformable side's local response, as a multiple of the model's
 * A_ii⁻¹ (contact_soft.h). That model is the inverse of the node's diagonal block, a lower
 * bound of the true response (A⁻¹)_ii, which at a block's corner or edge is several times
 * larger; a bilateral friction row solved against a model ρ times too stiff overshoots by
 * (ρ − 1) of the slip each step, and in alternating steps grows once ρ > 2: a rigid box resting
 * on a soft block (E 1e5 Pa) set the block's top corners swinging at 0.05 m/s, its friction
 * impulses changing sign every step. Seen at twice its size (stable to ρ < 4; below ρ = 2 the
 * slip is taken out over several steps instead of one) the corners stay below 3e-5 m/s. The
 * normal rows keep the model: there a softer view lets a box sink in (0.03 h deeper at 2×). */
#define FRICTION_LOCAL 2.0
#define BAUMGARTE 0.2
/* (Against deformable objects too. The whole depth per substep was needed while the solve saw
 * their nodes as free masses: they took most of the push-out and their own step pulled them
 * back. Seen with their stiffness (contact_soft.h) 0.2 rests boxes as deep as 1.0 did, and a
 * soft block dropped on a rigid floor rebounds 0.107 m from 1 m, against 0.141 m with 1.0;
 * restitution 0.3 says 0.09.) */
#define MAX_SUBSTEPS 8
/* The impact stress solve (a stress test, not a trajectory): its relative residual, and at
 * most this many PCG iterations, ~10 ms for the drop demo's 1300 nodes. The local stress
 * under the contacts converges in a few dozen iterations; the global bending of a body with
 * partial cracks takes ~300 (it made a 40 ms frame), and is what the cap leaves rough. */
#define IMPACT_CG_TOL 1e-3
#define IMPACT_CG_MAX 100
#define MAX_SPEED 1e3 /* m/s: beyond it a body's velocity is taken as diverged */

typedef struct contact {
    int a, b;            /* body indices; b < 0: the ground */
    double p[3], n[3];   /* point, normal from b towards a */
    double sep;          /* gap along n (negative: penetration) */
    double ra[3], rb[3];
    double t1[3], t2[3];
    double kn, kt1, kt2; /* effective masses */
    double target;       /* lowest normal relative velocity allowed */
    double jn, jt1, jt2;
    double mu;
    double bounce;       /* restitution taken at this contact this substep, or −1 */
    int32_t node_a, node_b; /* node of each body the point is, or -1 */
    int32_t cell_a, cell_b; /* cube of each body it touches, or -1 */
    int64_t key;         /* for removing duplicates within a body pair */
    /* against a deformable object D (then b < 0): the face point is Σ dw[k] x[dn[k]] */
    cs_object *D;
    int32_t dn[4];
    double dw[4];
    cs_soft_resp *S;     /* D's response to impulses (contact_soft.h) */
    double rd[3];        /* the face point's arm from D's centre of mass */
} contact;

/* A contact's accumulated impulse, kept for the next step (warm start). */
typedef struct kept_impulse {
    cs_object_id lo, hi; /* the two object ids in order; the ground is CS_NULL_OBJECT */
    int64_t key;
    double n[3];         /* normal towards lo */
    double J[3];         /* normal + friction impulse on lo, world */
} kept_impulse;

typedef struct cs_rigid_world {
    double dt;        /* of the current substep */
    kept_impulse *kept;
    int n_kept, cap_kept;
    cs_object **body;
    int n_body, cap_body;
    int *order;
    int *island;      /* union-find over bodies joined by contacts (sleep together) */
    int *island_still;
    int *bounce_c;    /* per body: its bouncing contact with the least gap, −1 none, −2 barred */
    uint8_t *dyn;
    contact *c;
    int nc, cap_c;
    struct dgrid *grid; /* broad phase against a deformable object (deformable_grid) */
    cs_soft_resp **soft; /* per deformable object in contact (soft_prepare) */
    int n_soft, cap_soft;
    int *soft_map;      /* soft's index + 1 by object id (soft_find), 0 empty; cap_map slots */
    int cap_map;
    uint64_t step;      /* cs_rigid_step calls so far */
    cs_soft_resp *cur;  /* the object's whose contacts are being made */
    struct soft_contact *sc; /* deformable against deformable (soft_contacts) */
    int nsc, cap_sc;
    double *sbox;       /* soft_contacts: 7 per object, its box and fastest node's speed */
    int cap_sbox;
    /* their broad phase (soft_candidates, wake_near_movers): each object's box grown by its
     * reach (6 per object), object indices by kin (kord), the pairs found (cand, 2 each) */
    cs_bp bp;
    double *gbox;
    int *kord;
    int cap_gbox;
    int32_t *cand;
    int n_cand, cap_cand;
    /* the last soft_contacts pass's impulses are still on the node velocities of rw->sc's
     * objects (cs_rigid_drop_pending): until the step after frame pending_frame; each
     * object's topology version then (sc_version, 2 per contact) */
    bool pending;
    int64_t pending_frame;
    uint32_t *sc_version;
    int cap_sc_version;
} cs_rigid_world;

/* cs_world carries the pointer: world_internal.h. */

static double now_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

/* ---------------------------------------------------------------- small vector algebra */

static void quat_mul(const double a[4], const double b[4], double r[4])
{
    double t[4] = {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
                   a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
                   a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
                   a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
    memcpy(r, t, sizeof t);
}

static bool finite_n(const double *a, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(a[i]))
            return false;
    return true;
}

/* R I_body⁻¹ Rᵀ */
static void update_inertia(cs_rigid *rb)
{
    double T[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s = 0;
            for (int k = 0; k < 3; k++)
                s += rb->R[3 * i + k] * rb->I_body_inv[3 * k + j];
            T[3 * i + j] = s;
        }
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s = 0;
            for (int k = 0; k < 3; k++)
                s += T[3 * i + k] * rb->R[3 * j + k];
            rb->I_inv_world[3 * i + j] = s;
        }
}

/* Δω of an impulse J at arm r: I⁻¹ (r × J). */
static void apply_impulse(cs_rigid *rb, const double r[3], const double J[3], double sign)
{
    double rxj[3], dw[3];
    cs_vec3_cross(r, J, rxj);
    cs_mat3_vec(rb->I_inv_world, rxj, dw);
    for (int a = 0; a < 3; a++) {
        rb->v[a] += sign * rb->inv_mass * J[a];
        rb->w[a] += sign * dw[a];
    }
}

/* ---------------------------------------------------------------- mass properties and pose */

static int mass_properties(cs_object *o, cs_rigid *rb)
{
    const cs_cubemesh *cm = &o->cm;
    const double h = cm->h, mc = o->mat.density * h * h * h;
    /* The density field (world_internal.h) read as the trilinear function through each cell's
     * 8 Gauss-point factors: the 2×2×2 Gauss rule integrates its mass, first and second
     * moments exactly (degree ≤ 3 per axis), so each cube is 8 point masses m_g = ρ d_g h³/8
     * at its Gauss points; a uniform cube gives exactly m h²/6 about its centre. */
    const double *dn = o->fld.density;
    const double gq = 0.5 / sqrt(3.0);
    double M = 0, C[3] = {0, 0, 0};
    for (int c = 0; c < cm->n_cells; c++)
        for (int g = 0; g < 8; g++) {
            const double mg = mc / 8.0 * (dn ? dn[8 * (size_t)c + g] : 1.0);
            M += mg;
            for (int a = 0; a < 3; a++)
                C[a] += mg * (cm->origin[a] + h * (cm->cell_ijk[3 * (size_t)c + a] + 0.5 +
                                                   (CS_CORNER[g][a] ? gq : -gq)));
        }
    if (!(M > 0))
        return -1;
    for (int a = 0; a < 3; a++)
        C[a] /= M;
    double I[9] = {0};
    for (int c = 0; c < cm->n_cells; c++)
        for (int g = 0; g < 8; g++) {
            const double mg = mc / 8.0 * (dn ? dn[8 * (size_t)c + g] : 1.0);
            double d[3];
            for (int a = 0; a < 3; a++)
                d[a] = cm->origin[a] +
                       h * (cm->cell_ijk[3 * (size_t)c + a] + 0.5 + (CS_CORNER[g][a] ? gq : -gq)) -
                       C[a];
            const double dd = cs_vec3_dot(d, d);
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                    I[3 * i + j] += mg * ((i == j) * dd - d[i] * d[j]);
        }
    rb->mass = M;
    rb->n_cells = cm->n_cells;
    for (int a = 0; a < 3; a++) {
        rb->ijk_lo[a] = INT32_MAX;
        rb->ijk_hi[a] = INT32_MIN;
    }
    for (int c = 0; c < cm->n_cells; c++)
        for (int a = 0; a < 3; a++) {
            const int32_t v = cm->cell_ijk[3 * (size_t)c + a];
            rb->ijk_lo[a] = v < rb->ijk_lo[a] ? v : rb->ijk_lo[a];
            rb->ijk_hi[a] = v > rb->ijk_hi[a] ? v : rb->ijk_hi[a];
        }
    rb->n_nodes = o->n;
    rb->inv_mass = 1.0 / rb->mass;
    memcpy(rb->com_rest, C, sizeof C);
    memcpy(rb->I_body, I, sizeof I);
    double adj[9];
    const double det = cs_mat3_adjugate(I, adj);
    if (!(det > 0))
        return -1;
    for (int k = 0; k < 9; k++)
        rb->I_body_inv[k] = adj[k] / det;
    rb->radius = 0;
    for (int i = 0; i < o->n; i++) {
        double d[3];
        for (int a = 0; a < 3; a++)
            d[a] = cm->node_rest[3 * (size_t)i + a] - C[a];
        rb->radius = fmax(rb->radius, cs_vec3_norm(d));
    }
    return 0;
}

static void node_aabb(cs_object *o, double margin)
{
    cs_rigid *rb = o->rb;
    for (int a = 0; a < 3; a++) {
        rb->aabb_min[a] = INFINITY;
        rb->aabb_max[a] = -INFINITY;
    }
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++) {
            const double x = o->x[3 * (size_t)i + a];
            rb->aabb_min[a] = fmin(rb->aabb_min[a], x);
            rb->aabb_max[a] = fmax(rb->aabb_max[a], x);
        }
    for (int a = 0; a < 3; a++) {
        rb->aabb_min[a] -= margin;
        rb->aabb_max[a] += margin;
    }
}

/* Nodes (and their velocities) from the pose; the surface skinned. O(nodes + vertices). */
static void place_nodes(cs_object *o)
{
    cs_rigid *rb = o->rb;
    for (int i = 0; i < o->n; i++) {
        double d[3], r[3], wr[3];
        for (int a = 0; a < 3; a++)
            d[a] = o->cm.node_rest[3 * (size_t)i + a] - rb->com_rest[a];
        cs_mat3_vec(rb->R, d, r);
        cs_vec3_cross(rb->w, r, wr);
        for (int a = 0; a < 3; a++) {
            o->x[3 * (size_t)i + a] = rb->c[a] + r[a];
            o->v[3 * (size_t)i + a] = rb->v[a] + wr[a];
        }
    }
    cs_surface_skin(&o->surf, &o->cm, o->x, 1);
    o->elastic_energy_valid = false;
}

int cs_rigid_init(cs_object *o)
{
    cs_rigid *rb = calloc(1, sizeof *rb);
    if (!rb || mass_properties(o, rb) != 0) {
        free(rb);
        return -1;
    }
    free(o->rb);
    o->rb = rb;
    cs_rigid_reset(o);
    return 0;
}

void cs_rigid_reset(cs_object *o)
{
    cs_rigid *rb = o->rb;
    rb->q[0] = 1;
    rb->q[1] = rb->q[2] = rb->q[3] = 0;
    cs_quat_to_mat(rb->q, rb->R);
    memcpy(rb->c, rb->com_rest, sizeof rb->c);
    memset(rb->v, 0, sizeof rb->v);
    memset(rb->w, 0, sizeof rb->w);
    rb->impact_force = 0;
    update_inertia(rb);
    place_nodes(o);
    node_aabb(o, 0);
}

int cs_rigid_refit(cs_object *o, const double q[4], const double c0[3], const double C0[3],
                   const double v0[3], const double w0[3])
{
    cs_rigid *rb = calloc(1, sizeof *rb);
    if (!rb || mass_properties(o, rb) != 0) {
        free(rb);
        return -1;
    }
    memcpy(rb->q, q, sizeof rb->q);
    cs_quat_to_mat(rb->q, rb->R);
    double d[3], r[3], wr[3];
    for (int a = 0; a < 3; a++)
        d[a] = rb->com_rest[a] - C0[a];
    cs_mat3_vec(rb->R, d, r);
    cs_vec3_cross(w0, r, wr);
    for (int a = 0; a < 3; a++) {
        rb->c[a] = c0[a] + r[a];
        rb->v[a] = v0[a] + wr[a];
        rb->w[a] = w0[a];
    }
    update_inertia(rb);
    rb->has_loads = o->rb && o->rb->has_loads;
    free(o->rb);
    o->rb = rb;
    place_nodes(o);
    node_aabb(o, 0);
    return 0;
}

cs_rigid *cs_rigid_clone(const cs_rigid *rb)
{
    cs_rigid *c = malloc(sizeof *c);
    if (c)
        *c = *rb;
    return c;
}

int cs_rigid_sync(cs_world_t *w)
{
    for (int i = 0; i < w->n_objects; i++) {
        cs_object *o = w->objects[i];
        const cs_rigid *rb = o->rb;
        if (!rb || (rb->n_cells == o->cm.n_cells && rb->n_nodes == o->n))
            continue;
        double q[4], c0[3], C0[3], v0[3], w0[3];
        memcpy(q, rb->q, sizeof q);
        memcpy(c0, rb->c, sizeof c0);
        memcpy(C0, rb->com_rest, sizeof C0);
        memcpy(v0, rb->v, sizeof v0);
        memcpy(w0, rb->w, sizeof w0);
        if (cs_rigid_refit(o, q, c0, C0, v0, w0) != 0)
            return CS_ERR_NOMEM;
    }
    return CS_OK;
}

int cs_rigid_fields_changed(cs_object *o)
{
    const cs_rigid *rb = o->rb;
    if (!rb || rb->n_cells != o->cm.n_cells || rb->n_nodes != o->n)
        return 0; /* not built yet, or mid-fracture: cs_rigid_sync refits */
    double q[4], c0[3], C0[3], v0[3], w0[3];
    memcpy(q, rb->q, sizeof q);
    memcpy(c0, rb->c, sizeof c0);
    memcpy(C0, rb->com_rest, sizeof C0);
    memcpy(v0, rb->v, sizeof v0);
    memcpy(w0, rb->w, sizeof w0);
    return cs_rigid_refit(o, q, c0, C0, v0, w0);
}

void cs_rigid_free(cs_object *o)
{
    free(o->rb);
    o->rb = NULL;
    for (int i = 0; i < o->n_born; i++)
        free(o->born[i].ref);
    free(o->born);
    o->born = NULL;
    o->n_born = o->cap_born = 0;
}

double cs_rigid_kinetic_energy(const cs_object *o)
{
    const cs_rigid *rb = o->rb;
    double wb[3], Iw[3];
    cs_mat3_t_vec(rb->R, rb->w, wb);
    cs_mat3_vec(rb->I_body, wb, Iw);
    return 0.5 * rb->mass * cs_vec3_dot(rb->v, rb->v) + 0.5 * cs_vec3_dot(wb, Iw);
}

/* ---------------------------------------------------------------- broad phase: deformable */

/*
 * A deformable object's cells (by the box of their current corners) or nodes, filed in the
 * buckets of a uniform grid of edge 2h over the object's box (a counting sort): a rigid
 * body's box then finds the cells or nodes it may touch in time that grows with them, not
 * with the object. The plain loop (every cell or node against every body's box) is kept for
 * objects that few bodies overlap (w->broadphase_min_bodies), where building the grid costs
 * more than it saves. Candidates are visited in ascending order, so both produce the same
 * contacts in the same order.
 */
typedef struct dgrid {
    double lo[3], g;
    int32_t dim[3];
    int32_t *start;  /* per bucket (linear index), its first entry in item; n_buckets + 1 */
    int32_t *item;   /* the cells or nodes, bucket by bucket, ascending within each */
    int32_t *range;  /* scratch: 6 per item, its bucket ranges */
    int32_t *stamp, cur; /* per item: the query that last took it */
    int32_t *cand;   /* the last query's items, ascending */
    int n_cand;
    size_t cap_start, cap_item, cap_items;
} dgrid;

static void grid_free(dgrid *gr)
{
    if (!gr)
        return;
    free(gr->start);
    free(gr->item);
    free(gr->range);
    free(gr->stamp);
    free(gr->cand);
    free(gr);
}

static int cmp_i32(const void *x, const void *y)
{
    const int32_t a = *(const int32_t *)x, b = *(const int32_t *)y;
    return (a > b) - (a < b);
}

/* The bucket index of coordinate v along axis a, clamped to the grid. */
static int32_t bucket_at(const dgrid *gr, double v, int a)
{
    const double f = floor((v - gr->lo[a]) / gr->g);
    return f < 0 ? 0 : f >= gr->dim[a] ? gr->dim[a] - 1 : (int32_t)f;
}

static int grow_i32(int32_t **p, size_t *cap, size_t n)
{
    if (n <= *cap)
        return 0;
    int32_t *g = realloc(*p, n * sizeof *g);
    if (!g)
        return -1;
    *p = g;
    *cap = n;
    return 0;
}

/* File D's cells (cells) or nodes in rw->grid over D's box [lo, hi] (bodies_over's), by
 * counting sort (linear in the items and buckets; the buckets are at most 8 per item).
 * Returns 0 or -1 (out of memory). */
static int grid_build(cs_rigid_world *rw, const cs_object *D, bool cells, const double lo[3],
                      const double hi[3])
{
    if (!rw->grid && !(rw->grid = calloc(1, sizeof *rw->grid)))
        return -1;
    dgrid *gr = rw->grid;
    const int n_items = cells ? D->cm.n_cells : D->n;
    memcpy(gr->lo, lo, sizeof gr->lo);
    /* buckets of 2h, coarser if a stretched object would need more than 8 per item */
    gr->g = 2.0 * D->cm.h;
    double nb;
    for (;;) {
        nb = 1;
        for (int a = 0; a < 3; a++)
            nb *= floor((hi[a] - gr->lo[a]) / gr->g) + 1;
        if (nb <= 8.0 * n_items + 64)
            break;
        gr->g *= 2;
    }
    for (int a = 0; a < 3; a++)
        gr->dim[a] = (int32_t)(floor((hi[a] - gr->lo[a]) / gr->g) + 1);
    const size_t n_buckets = (size_t)nb;
    size_t items = 0;
    if (grow_i32(&gr->range, &gr->cap_items, 6 * (size_t)n_items) ||
        grow_i32(&gr->start, &gr->cap_start, n_buckets + 1))
        return -1;
    memset(gr->start, 0, (n_buckets + 1) * sizeof *gr->start);
    for (int32_t it = 0; it < n_items; it++) {
        double blo[3], bhi[3];
        if (cells) {
            const int32_t *cn = D->cm.cell_nodes + 8 * (size_t)it;
            for (int a = 0; a < 3; a++)
                blo[a] = bhi[a] = D->x[3 * (size_t)cn[0] + a];
            for (int k = 1; k < 8; k++)
                for (int a = 0; a < 3; a++) {
                    const double v = D->x[3 * (size_t)cn[k] + a];
                    blo[a] = v < blo[a] ? v : blo[a];
                    bhi[a] = v > bhi[a] ? v : bhi[a];
                }
        } else {
            for (int a = 0; a < 3; a++)
                blo[a] = bhi[a] = D->x[3 * (size_t)it + a];
        }
        int32_t *r = gr->range + 6 * (size_t)it;
        for (int a = 0; a < 3; a++) {
            r[a] = bucket_at(gr, blo[a], a);
            r[3 + a] = bucket_at(gr, bhi[a], a);
        }
        for (int32_t i = r[0]; i <= r[3]; i++)
            for (int32_t j = r[1]; j <= r[4]; j++)
                for (int32_t k = r[2]; k <= r[5]; k++) {
                    gr->start[((size_t)i * gr->dim[1] + j) * gr->dim[2] + k + 1]++;
                    items++;
                }
    }
    for (size_t q = 0; q < n_buckets; q++)
        gr->start[q + 1] += gr->start[q];
    if (grow_i32(&gr->item, &gr->cap_item, items ? items : 1))
        return -1;
    for (int32_t it = 0; it < n_items; it++) { /* items ascending within each bucket */
        const int32_t *r = gr->range + 6 * (size_t)it;
        for (int32_t i = r[0]; i <= r[3]; i++)
            for (int32_t j = r[1]; j <= r[4]; j++)
                for (int32_t k = r[2]; k <= r[5]; k++)
                    gr->item[gr->start[((size_t)i * gr->dim[1] + j) * gr->dim[2] + k]++] = it;
    }
    for (size_t q = n_buckets; q > 0; q--) /* the fill moved each start to the next one's */
        gr->start[q] = gr->start[q - 1];
    gr->start[0] = 0;
    int32_t *st = realloc(gr->stamp, (size_t)(n_items ? n_items : 1) * sizeof *st);
    if (st)
        gr->stamp = st;
    int32_t *cd = realloc(gr->cand, (size_t)(n_items ? n_items : 1) * sizeof *cd);
    if (cd)
        gr->cand = cd;
    if (!st || !cd)
        return -1;
    memset(gr->stamp, 0, (size_t)n_items * sizeof *gr->stamp);
    gr->cur = 0;
    return 0;
}

/* The items filed in buckets that the box [qlo, qhi] overlaps, ascending, in gr->cand. */
static void grid_query(dgrid *gr, const double qlo[3], const double qhi[3])
{
    gr->n_cand = 0;
    for (int a = 0; a < 3; a++)
        if (qhi[a] < gr->lo[a] || qlo[a] > gr->lo[a] + gr->g * gr->dim[a])
            return;
    gr->cur++;
    int32_t r0[3], r1[3];
    for (int a = 0; a < 3; a++) {
        r0[a] = bucket_at(gr, qlo[a], a);
        r1[a] = bucket_at(gr, qhi[a], a);
    }
    for (int32_t i = r0[0]; i <= r1[0]; i++)
        for (int32_t j = r0[1]; j <= r1[1]; j++)
            for (int32_t k = r0[2]; k <= r1[2]; k++) {
                const size_t q = ((size_t)i * gr->dim[1] + j) * gr->dim[2] + k;
                for (int32_t e = gr->start[q]; e < gr->start[q + 1]; e++) {
                    const int32_t it = gr->item[e];
                    if (gr->stamp[it] != gr->cur) {
                        gr->stamp[it] = gr->cur;
                        gr->cand[gr->n_cand++] = it;
                    }
                }
            }
    /* ascending; a node's query takes a few dozen at most: by insertion (qsort's merge sort
     * was an eighth of the deformable contacts' time in the fracture storm) */
    if (gr->n_cand > 32) {
        qsort(gr->cand, (size_t)gr->n_cand, sizeof *gr->cand, cmp_i32);
        return;
    }
    for (int a = 1; a < gr->n_cand; a++) {
        const int32_t v = gr->cand[a];
        int b = a;
        for (; b > 0 && gr->cand[b - 1] > v; b--)
            gr->cand[b] = gr->cand[b - 1];
        gr->cand[b] = v;
    }
}

static double body_margin(const cs_object *o, double dt);

/* How many bodies' boxes (grown by grow, or by each body's own margin if grow < 0) overlap
 * D's current box, which it writes to lo, hi; bodies at rest do not count against a sleeping
 * D. */
static int bodies_over(const cs_rigid_world *rw, const cs_object *D, double grow, double lo[3],
                       double hi[3])
{
    for (int a = 0; a < 3; a++) {
        lo[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    for (int i = 0; i < D->n; i++)
        for (int a = 0; a < 3; a++) {
            const double v = D->x[3 * (size_t)i + a];
            lo[a] = v < lo[a] ? v : lo[a];
            hi[a] = v > hi[a] ? v : hi[a];
        }
    int n = 0;
    for (int b = 0; b < rw->n_body; b++) {
        const cs_rigid *rb = rw->body[b]->rb;
        if (!rw->dyn[b] && D->sleeping)
            continue;
        const double m = grow >= 0 ? grow : body_margin(rw->body[b], rw->dt);
        n += lo[0] <= rb->aabb_max[0] + m && hi[0] >= rb->aabb_min[0] - m &&
             lo[1] <= rb->aabb_max[1] + m && hi[1] >= rb->aabb_min[1] - m &&
             lo[2] <= rb->aabb_max[2] + m && hi[2] >= rb->aabb_min[2] - m;
    }
    return n;
}

void cs_rigid_world_free(cs_world_t *w)
{
    cs_rigid_world *rw = w->rigid;
    if (!rw)
        return;
    free(rw->body);
    free(rw->order);
    free(rw->island);
    free(rw->island_still);
    free(rw->bounce_c);
    free(rw->dyn);
    free(rw->c);
    free(rw->kept);
    grid_free(rw->grid);
    for (int i = 0; i < rw->n_soft; i++) {
        cs_soft_free(rw->soft[i]);
        free(rw->soft[i]);
    }
    free(rw->soft);
    free(rw->soft_map);
    free(rw->sc);
    free(rw->sc_version);
    free(rw->sbox);
    free(rw->gbox);
    free(rw->kord);
    free(rw->cand);
    cs_bp_free(&rw->bp);
    free(rw);
    w->rigid = NULL;
}

/* ---------------------------------------------------------------- integration */

/*
 * Free rotation over dt by the Lie–Poisson implicit midpoint rule (see the top of the file).
 */
static void rotate(cs_rigid *rb, double dt)
{
    const double *I = rb->I_body;
    double w0[3], wm[3];
    cs_mat3_t_vec(rb->R, rb->w, w0);
    memcpy(wm, w0, sizeof wm);
    for (int it = 0; it < 20; it++) {
        /* G(ωm) = 2 I (ωm − ω0) + dt ωm × I ωm */
        double Iw[3], d[3], G[3], c[3];
        cs_mat3_vec(I, wm, Iw);
        for (int a = 0; a < 3; a++)
            d[a] = wm[a] - w0[a];
        cs_mat3_vec(I, d, G);
        cs_vec3_cross(wm, Iw, c);
        for (int a = 0; a < 3; a++)
            G[a] = 2 * G[a] + dt * c[a];
        /* J = 2 I + dt ([ωm]× I − [I ωm]×) */
        double J[9];
        const double W[9] = {0, -wm[2], wm[1], wm[2], 0, -wm[0], -wm[1], wm[0], 0};
        const double L[9] = {0, -Iw[2], Iw[1], Iw[2], 0, -Iw[0], -Iw[1], Iw[0], 0};
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                double s = 0;
                for (int k = 0; k < 3; k++)
                    s += W[3 * i + k] * I[3 * k + j];
                J[3 * i + j] = 2 * I[3 * i + j] + dt * (s - L[3 * i + j]);
            }
        double adj[9], step[3];
        const double det = cs_mat3_adjugate(J, adj);
        if (det == 0 || !isfinite(det))
            break;
        cs_mat3_vec(adj, G, step);
        double sn = 0, wn = 0;
        for (int a = 0; a < 3; a++) {
            wm[a] -= step[a] / det;
            sn += (step[a] / det) * (step[a] / det);
            wn += wm[a] * wm[a];
        }
        if (sn <= 1e-30 * (wn + 1e-300))
            break;
    }
    double w1[3];
    for (int a = 0; a < 3; a++)
        w1[a] = 2 * wm[a] - w0[a];
    const double dq[4] = {1, 0.5 * dt * wm[0], 0.5 * dt * wm[1], 0.5 * dt * wm[2]};
    double q[4];
    quat_mul(rb->q, dq, q);
    const double qn = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int a = 0; a < 4; a++)
        rb->q[a] = q[a] / qn;
    cs_quat_to_mat(rb->q, rb->R);
    cs_mat3_vec(rb->R, w1, rb->w);
    update_inertia(rb);
}

/* The 3×3 matrix K with Δv(point) = K J for an impulse J at arm r. */
static void point_mass_matrix(const cs_rigid *rb, const double r[3], double K[9])
{
    for (int j = 0; j < 3; j++) {
        double e[3] = {0, 0, 0}, rxe[3], t[3], col[3];
        e[j] = 1;
        cs_vec3_cross(r, e, rxe);
        cs_mat3_vec(rb->I_inv_world, rxe, t);
        cs_vec3_cross(t, r, col);
        for (int i = 0; i < 3; i++)
            K[3 * i + j] = rb->inv_mass * e[i] + col[i];
    }
}

/* Gravity and client inputs: velocities of a dynamic body. */
static void apply_inputs(const cs_world_t *w, cs_object *o)
{
    cs_rigid *rb = o->rb;
    const double dt = w->rigid->dt;
    if (!rb->has_loads) {
        for (int a = 0; a < 3; a++)
            rb->v[a] += dt * w->def.gravity[a];
    } else {
        /* gravity and the scene's constant loads, as the nodes carry them (f_const) */
        double F[3] = {0, 0, 0}, tau[3] = {0, 0, 0};
        for (int i = 0; i < o->n; i++) {
            double r[3], t[3];
            for (int a = 0; a < 3; a++)
                r[a] = o->x[3 * (size_t)i + a] - rb->c[a];
            cs_vec3_cross(r, o->f_const + 3 * (size_t)i, t);
            for (int a = 0; a < 3; a++) {
                F[a] += o->f_const[3 * (size_t)i + a];
                tau[a] += t[a];
            }
        }
        double dw[3];
        cs_mat3_vec(rb->I_inv_world, tau, dw);
        for (int a = 0; a < 3; a++) {
            rb->v[a] += dt * F[a] * rb->inv_mass;
            rb->w[a] += dt * dw[a];
        }
    }
    for (int i = 0; i < o->n_inputs; i++) {
        const cs_input *in = &o->inputs[i];
        /* a uniform pressure on a closed surface has no net force or torque on a rigid body */
        if (in->delay > 0 || in->kind == CS_INPUT_PRESSURE || in->cell < 0)
            continue;
        const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)in->cell;
        double p[3] = {0, 0, 0}, r[3];
        for (int k = 0; k < 8; k++)
            for (int a = 0; a < 3; a++)
                p[a] += in->w[k] * o->x[3 * (size_t)nd[k] + a];
        for (int a = 0; a < 3; a++)
            r[a] = p[a] - rb->c[a];
        double J[3];
        if (in->kind == CS_INPUT_FORCE) {
            for (int a = 0; a < 3; a++)
                J[a] = dt * in->force[a];
        } else {
            /* implicit spring on the point: (1 + dt² k K) J = dt k (e − dt v_p) */
            double K[9], A[9], adj[9], vp[3], wr[3], rhs[3];
            point_mass_matrix(rb, r, K);
            cs_vec3_cross(rb->w, r, wr);
            /* the target: fixed (drag) or moving along its segment (curve) */
            double tg[3];
            const double sc = in->kind == CS_INPUT_CURVE && in->steps_total > 0
                                  ? (double)(in->steps_total - in->steps_left + 1) / in->steps_total
                                  : 0.0;
            for (int a = 0; a < 3; a++)
                tg[a] = in->target[a] +
                        (in->kind == CS_INPUT_CURVE ? sc * (in->target1[a] - in->target[a]) : 0.0);
            for (int a = 0; a < 3; a++) {
                vp[a] = rb->v[a] + wr[a];
                rhs[a] = dt * in->stiffness * (tg[a] - p[a] - dt * vp[a]);
            }
            for (int k = 0; k < 9; k++)
                A[k] = dt * dt * in->stiffness * K[k] + (k % 4 == 0);
            const double det = cs_mat3_adjugate(A, adj);
            cs_mat3_vec(adj, rhs, J);
            for (int a = 0; a < 3; a++)
                J[a] /= det;
        }
        apply_impulse(rb, r, J, 1.0);
    }
}

/* As world.c's expire_inputs: a delayed input counts its delay down first. */
static void expire(cs_object *o)
{
    int j = 0;
    for (int i = 0; i < o->n_inputs; i++) {
        cs_input *in = &o->inputs[i];
        if (in->delay > 0 ? (in->delay--, true) : --in->steps_left > 0)
            o->inputs[j++] = *in;
    }
    o->n_inputs = j;
}

/* ---------------------------------------------------------------- contacts */

/* p (n of *cap elements of elem bytes in use) with room for one more: p itself while there is,
 * else reallocated to twice *cap (first, when empty), *cap updated. NULL when out of memory
 * (p is then still valid). */
static void *room_for_one(void *p, int n, int *cap, size_t elem, int first)
{
    if (n < *cap)
        return p;
    const int c = *cap ? 2 * *cap : first;
    void *g = realloc(p, (size_t)c * elem);
    if (g)
        *cap = c;
    return g;
}

static contact *new_contact(cs_rigid_world *rw)
{
    contact *g = room_for_one(rw->c, rw->nc, &rw->cap_c, sizeof *g, 256);
    if (!g)
        return NULL;
    rw->c = g;
    contact *c = &rw->c[rw->nc++];
    memset(c, 0, sizeof *c);
    c->node_a = c->node_b = c->cell_a = c->cell_b = -1;
    return c;
}

/* The distance a body can move towards anything in one step, plus a small persistence
 * margin so resting contacts stay in the set. */
static double body_margin(const cs_object *o, double dt)
{
    const cs_rigid *rb = o->rb;
    return dt * (cs_vec3_norm(rb->v) + cs_vec3_norm(rb->w) * rb->radius) +
           0.05 * o->cm.h;
}

static int ground_contacts(cs_world_t *w, cs_rigid_world *rw, int ia)
{
    cs_object *o = rw->body[ia];
    const double g = w->def.ground_height, dt = w->rigid->dt;
    const double margin = body_margin(o, dt);
    if (o->rb->aabb_min[2] > g + margin)
        return 0;
    for (int i = 0; i < o->n; i++) {
        const double *x = o->x + 3 * (size_t)i;
        if (x[2] - g >= margin)
            continue;
        contact *c = new_contact(rw);
        if (!c)
            return -1;
        c->a = ia;
        c->b = -1;
        memcpy(c->p, x, sizeof c->p);
        c->n[2] = 1;
        c->sep = x[2] - g;
        c->node_a = i;
        c->key = i;
    }
    return 0;
}

/* An oriented cube for libccd: centre, axes (the body's R columns), half edge. */
typedef struct obox {
    double c[3];
    const double *R;
    double half;
} obox;

static void obox_support(const void *obj, const ccd_vec3_t *dir, ccd_vec3_t *out)
{
    const obox *b = obj;
    double d[3] = {dir->v[0], dir->v[1], dir->v[2]}, l[3];
    cs_mat3_t_vec(b->R, d, l);
    for (int a = 0; a < 3; a++)
        l[a] = l[a] >= 0 ? b->half : -b->half;
    double r[3];
    cs_mat3_vec(b->R, l, r);
    for (int a = 0; a < 3; a++)
        out->v[a] = b->c[a] + r[a];
}

static void obox_center(const void *obj, ccd_vec3_t *out)
{
    const obox *b = obj;
    for (int a = 0; a < 3; a++)
        out->v[a] = b->c[a];
}

static void cell_centre_world(const cs_object *o, int32_t c, double p[3])
{
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
    p[0] = p[1] = p[2] = 0;
    for (int k = 0; k < 8; k++)
        for (int a = 0; a < 3; a++)
            p[a] += o->x[3 * (size_t)nd[k] + a] / 8.0;
}

/* Whether the face of cell c that a world direction d leaves through is shared with a
 * neighbouring cell of the same object (then a push along d would be through the body). */
static bool internal_direction(const cs_object *o, int32_t c, const double d[3])
{
    double l[3];
    cs_mat3_t_vec(o->rb->R, d, l);
    int ax = 0;
    for (int a = 1; a < 3; a++)
        if (fabs(l[a]) > fabs(l[ax]))
            ax = a;
    if (fabs(l[ax]) < 0.9)
        return false;
    const int32_t *q = o->cm.cell_ijk + 3 * (size_t)c;
    int32_t nb[3] = {q[0], q[1], q[2]};
    nb[ax] += l[ax] > 0 ? 1 : -1;
    return cs_cubemesh_find(&o->cm, nb[0], nb[1], nb[2]) >= 0;
}

/* Is world point p inside cube `box` grown by g? */
static bool in_obox(const obox *b, const double p[3], double g)
{
    double d[3] = {p[0] - b->c[0], p[1] - b->c[1], p[2] - b->c[2]}, l[3];
    cs_mat3_t_vec(b->R, d, l);
    return fabs(l[0]) <= b->half + g && fabs(l[1]) <= b->half + g && fabs(l[2]) <= b->half + g;
}

/* Contacts between cube ca of body ia and cube cb of body ib (normal towards ia). */
static int cube_pair(cs_rigid_world *rw, int ia, int32_t ca, int ib, int32_t cb, double margin)
{
    const cs_object *A = rw->body[ia], *B = rw->body[ib];
    obox ba = {.R = A->rb->R, .half = 0.5 * A->cm.h + 0.5 * margin};
    obox bbx = {.R = B->rb->R, .half = 0.5 * B->cm.h + 0.5 * margin};
    cell_centre_world(A, ca, ba.c);
    cell_centre_world(B, cb, bbx.c);
    double n[3], depth;
    ccd_t ccd;
    CCD_INIT(&ccd);
    ccd.support1 = obox_support;
    ccd.support2 = obox_support;
    ccd.center1 = obox_center;
    ccd.center2 = obox_center;
    ccd.max_iterations = 100;
    ccd.mpr_tolerance = 1e-9 * (A->cm.h + B->cm.h);
    /* Pieces of one broken body keep its orientation: parallel cubes need no GJK/MPR */
    double par = 0;
    for (int k = 0; k < 9; k++)
        par = fmax(par, fabs(A->rb->R[k] - B->rb->R[k]));
    if (par >= 1e-9 && !ccdMPRIntersect(&bbx, &ba, &ccd))
        return 0;
    /* The separating-axis test over the 15 axes of two boxes gives the exact minimum
     * translation (libccd's EPA is that too in principle, but stalls on the touching,
     * coplanar faces that resting cubes always have; MPR's direction is too rough). */
    {
        double d[3], axes[15][3];
        int na = 0;
        for (int a = 0; a < 3; a++)
            d[a] = ba.c[a] - bbx.c[a];
        for (int s2 = 0; s2 < 2; s2++)
            for (int k = 0; k < 3; k++) {
                const double *R = s2 ? A->rb->R : B->rb->R;
                axes[na][0] = R[k];
                axes[na][1] = R[3 + k];
                axes[na][2] = R[6 + k];
                na++;
            }
        if (par >= 1e-9)
            for (int i = 0; i < 3; i++)
                for (int j = 3; j < 6; j++) {
                    double c[3];
                    cs_vec3_cross(axes[i], axes[j], c);
                    const double l = cs_vec3_norm(c);
                    if (l < 1e-6)
                        continue;
                    for (int a = 0; a < 3; a++)
                        axes[na][a] = c[a] / l;
                    na++;
                }
        depth = INFINITY;
        int best = -1;
        for (int k = 0; k < na; k++) {
            double ra = 0, rb = 0;
            for (int j = 0; j < 3; j++) {
                ra += ba.half * fabs(cs_vec3_dot(axes[3 + j], axes[k]));
                rb += bbx.half * fabs(cs_vec3_dot(axes[j], axes[k]));
            }
            const double ov = ra + rb - fabs(cs_vec3_dot(d, axes[k]));
            if (ov < 0)
                return 0;
            /* face axes win ties against edge axes (1e-9 of h) */
            if (ov < depth - (k >= 6 ? 1e-9 * (A->cm.h + B->cm.h) : 0)) {
                depth = ov;
                best = k;
            }
        }
        const double sg = cs_vec3_dot(d, axes[best]) >= 0 ? 1 : -1;
        for (int a = 0; a < 3; a++)
            n[a] = sg * axes[best][a];
    }
    /* Face contacts: the normal of the face (of either cube) it is within ~14° of, so that
     * every cube pair of one face-to-face contact pushes along the same direction; the penetration
     * direction varies with the overlap of each pair and makes stacks creep. */
    {
        double best = 0, u[3] = {0, 0, 0};
        for (int s = 0; s < 2; s++)
            for (int ax = 0; ax < 3; ax++) {
                const double *R = s ? B->rb->R : A->rb->R;
                const double col[3] = {R[ax], R[3 + ax], R[6 + ax]};
                const double d = cs_vec3_dot(col, n);
                if (fabs(d) > best) {
                    best = fabs(d);
                    for (int a = 0; a < 3; a++)
                        u[a] = d > 0 ? col[a] : -col[a];
                }
            }
        if (best > 0.97)
            memcpy(n, u, sizeof u);
    }
    const double minus_n[3] = {-n[0], -n[1], -n[2]};
    if (internal_direction(B, cb, n) || internal_direction(A, ca, minus_n))
        return 0;
    /* extents along n of the true (ungrown) cubes */
    const int32_t *na = A->cm.cell_nodes + 8 * (size_t)ca, *nb = B->cm.cell_nodes + 8 * (size_t)cb;
    double minA = INFINITY, maxB = -INFINITY;
    for (int k = 0; k < 8; k++) {
        minA = fmin(minA, cs_vec3_dot(A->x + 3 * (size_t)na[k], n));
        maxB = fmax(maxB, cs_vec3_dot(B->x + 3 * (size_t)nb[k], n));
    }
    if (minA - maxB >= margin)
        return 0; /* apart along the (snapped) normal */
    ba.half = 0.5 * A->cm.h;
    bbx.half = 0.5 * B->cm.h;
    const double tol = 1e-6 * (A->cm.h + B->cm.h);
    int made = 0;
    for (int side = 0; side < 2; side++)
        for (int k = 0; k < 8; k++) {
            const int32_t node = side == 0 ? na[k] : nb[k];
            const double *p = (side == 0 ? A->x : B->x) + 3 * (size_t)node;
            const double sep = side == 0 ? cs_vec3_dot(p, n) - maxB : minA - cs_vec3_dot(p, n);
            if (sep >= margin || !in_obox(side == 0 ? &bbx : &ba, p, fabs(sep) + tol))
                continue;
            /* only points on the facing side: a corner of A near B's face, not behind it */
            if (side == 0 && cs_vec3_dot(p, n) > minA + fmax(margin, 0.25 * A->cm.h))
                continue;
            if (side == 1 && cs_vec3_dot(p, n) < maxB - fmax(margin, 0.25 * B->cm.h))
                continue;
            contact *c = new_contact(rw);
            if (!c)
                return -1;
            c->a = ia;
            c->b = ib;
            memcpy(c->p, p, sizeof c->p);
            memcpy(c->n, n, sizeof c->n);
            c->sep = sep;
            c->cell_a = ca;
            c->cell_b = cb;
            if (side == 0)
                c->node_a = node;
            else
                c->node_b = node;
            /* the same key whichever body ends up as a: the node and whose it is */
            c->key = 2 * (int64_t)node + ((side == 0) == (A->id < B->id));
            made++;
        }
    if (made == 0) {
        /* edge against edge: libccd's contact point */
        ccd_real_t cdepth;
        ccd_vec3_t dir, pos;
        if (ccdMPRPenetration(&bbx, &ba, &ccd, &cdepth, &dir, &pos) != 0)
            return 0;
        contact *c = new_contact(rw);
        if (!c)
            return -1;
        c->a = ia;
        c->b = ib;
        for (int a = 0; a < 3; a++)
            c->p[a] = pos.v[a];
        memcpy(c->n, n, sizeof c->n);
        c->sep = minA - maxB;
        c->cell_a = ca;
        c->cell_b = cb;
        c->key = -1 - ((int64_t)ca << 31 | (int64_t)cb); /* never a duplicate */
    }
    return 0;
}

static int cmp_contact(const void *x, const void *y)
{
    const contact *a = x, *b = y;
    if (a->key != b->key)
        return a->key < b->key ? -1 : 1;
    return a->sep < b->sep ? -1 : a->sep > b->sep;
}

/* Contacts between bodies ia and ib, whose grown AABBs overlap. */
static int body_pair(const cs_world_t *w, cs_rigid_world *rw, int ia, int ib)
{
    /* look up the cubes of the body with fewer cells in the other's lattice */
    if (rw->body[ia]->cm.n_cells > rw->body[ib]->cm.n_cells) {
        int t = ia;
        ia = ib;
        ib = t;
    }
    const cs_object *A = rw->body[ia], *B = rw->body[ib];
    const double margin = body_margin(A, w->rigid->dt) + body_margin(B, w->rigid->dt);
    const double hA = A->cm.h, hB = B->cm.h;
    const double reach = 0.5 * sqrt(3.0) * (hA + hB) + margin;
    const int start = rw->nc;
    for (int32_t ca = 0; ca < A->cm.n_cells; ca++) {
        double xa[3], d[3], X[3];
        cell_centre_world(A, ca, xa);
        bool out = false;
        for (int a = 0; a < 3; a++)
            if (xa[a] < B->rb->aabb_min[a] - reach || xa[a] > B->rb->aabb_max[a] + reach)
                out = true;
        if (out)
            continue;
        for (int a = 0; a < 3; a++)
            d[a] = xa[a] - B->rb->c[a];
        cs_mat3_t_vec(B->rb->R, d, X);
        double u[3];
        for (int a = 0; a < 3; a++)
            u[a] = (X[a] + B->rb->com_rest[a] - B->cm.origin[a]) / hB - 0.5;
        const double rc = reach / hB;
        int lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            /* clamped to B's cells (a body thrown at absurd speed has a margin of
             * kilometres: its box of lattice points would not end, nor fit an int) */
            lo[a] = (int)ceil(fmax(u[a] - rc, B->rb->ijk_lo[a] - 1.0));
            hi[a] = (int)floor(fmin(u[a] + rc, B->rb->ijk_hi[a] + 1.0));
        }
        for (int i = lo[0]; i <= hi[0]; i++)
            for (int j = lo[1]; j <= hi[1]; j++)
                for (int k = lo[2]; k <= hi[2]; k++) {
                    const double e[3] = {i - u[0], j - u[1], k - u[2]};
                    if (cs_vec3_dot(e, e) > rc * rc)
                        continue;
                    int32_t cb = cs_cubemesh_find(&B->cm, i, j, k);
                    if (cb >= 0 && cube_pair(rw, ia, ca, ib, cb, margin) != 0)
                        return -1;
                }
    }
    /* one contact per node of either body (the deepest), however many cube pairs found it */
    if (rw->nc - start > 1)
        qsort(rw->c + start, (size_t)(rw->nc - start), sizeof *rw->c, cmp_contact);
    int k = start;
    for (int i = start; i < rw->nc; i++)
        if (i == start || rw->c[i].key < 0 || rw->c[i].key != rw->c[k - 1].key)
            rw->c[k++] = rw->c[i];
    rw->nc = k;
    return 0;
}

static const cs_rigid *body_rb(const cs_rigid_world *rw, int i)
{
    return i >= 0 ? rw->body[i]->rb : NULL;
}

static void tangents(const double n[3], double t1[3], double t2[3])
{
    double a[3] = {0, 0, 0};
    a[fabs(n[0]) < 0.57 ? 0 : (fabs(n[1]) < 0.57 ? 1 : 2)] = 1;
    cs_vec3_cross(n, a, t1);
    const double l = cs_vec3_norm(t1);
    for (int k = 0; k < 3; k++)
        t1[k] /= l;
    cs_vec3_cross(n, t1, t2);
}

static double eff_mass(const cs_rigid_world *rw, const contact *c, const double d[3], double local)
{
    double k = 0;
    for (int s = 0; s < 2; s++) {
        const int i = s ? c->b : c->a;
        if (i < 0 || !rw->dyn[i])
            continue;
        const cs_rigid *rb = body_rb(rw, i);
        double rxd[3], t[3];
        cs_vec3_cross(s ? c->rb : c->ra, d, rxd);
        cs_mat3_vec(rb->I_inv_world, rxd, t);
        k += rb->inv_mass + cs_vec3_dot(rxd, t);
    }
    if (c->D)
        k += cs_soft_compliance(c->S, c->dn, c->dw, 4, c->rd, d, local);
    return k > 0 ? 1.0 / k : 0.0;
}

/* Relative velocity of a over b at the contact (before this step's forces if pre). */
static void rel_velocity_at(const cs_rigid_world *rw, const contact *c, double v[3], bool pre)
{
    v[0] = v[1] = v[2] = 0;
    for (int s = 0; s < 2; s++) {
        const int i = s ? c->b : c->a;
        if (i < 0)
            continue;
        const cs_rigid *rb = body_rb(rw, i);
        const double *bv = pre ? rb->v_pre : rb->v, *bw = pre ? rb->w_pre : rb->w;
        double wr[3];
        cs_vec3_cross(bw, s ? c->rb : c->ra, wr);
        for (int a = 0; a < 3; a++)
            v[a] += (s ? -1 : 1) * (bv[a] + wr[a]);
    }
    if (c->D) {
        double vd[3];
        cs_soft_velocity(c->S, c->dn, c->dw, 4, c->rd, vd);
        for (int a = 0; a < 3; a++)
            v[a] -= vd[a];
    }
}

static void rel_velocity(const cs_rigid_world *rw, const contact *c, double v[3])
{
    rel_velocity_at(rw, c, v, false);
}

static void contact_impulse(cs_rigid_world *rw, const contact *c, const double J[3], double local)
{
    if (rw->dyn[c->a])
        apply_impulse(rw->body[c->a]->rb, c->ra, J, 1.0);
    if (c->b >= 0 && rw->dyn[c->b])
        apply_impulse(rw->body[c->b]->rb, c->rb, J, -1.0);
    if (c->D) { /* −J on the deformable side */
        const double mJ[3] = {-J[0], -J[1], -J[2]};
        cs_soft_impulse(c->S, c->dn, c->dw, 4, c->rd, mJ, local);
    }
}

static void prepare_contacts(const cs_world_t *w, cs_rigid_world *rw)
{
    const double dt = w->rigid->dt;
    const double gn = cs_vec3_norm(w->def.gravity);
    const double v_bounce = 2 * gn * dt + 1e-3;
    for (int i = 0; i < rw->nc; i++) {
        contact *c = &rw->c[i];
        const cs_object *A = rw->body[c->a], *B = c->b >= 0 ? rw->body[c->b] : NULL;
        for (int a = 0; a < 3; a++) {
            c->ra[a] = c->p[a] - A->rb->c[a];
            c->rb[a] = B ? c->p[a] - B->rb->c[a] : 0;
        }
        if (c->D)
            cs_soft_arm(c->S, c->dn, c->dw, 4, c->rd);
        tangents(c->n, c->t1, c->t2);
        c->kn = eff_mass(rw, c, c->n, 1.0);
        c->kt1 = eff_mass(rw, c, c->t1, FRICTION_LOCAL);
        c->kt2 = eff_mass(rw, c, c->t2, FRICTION_LOCAL);
        double vr[3];
        rel_velocity(rw, c, vr);
        const double vn0 = cs_vec3_dot(vr, c->n);
        rel_velocity_at(rw, c, vr, true);
        const double vn_pre = cs_vec3_dot(vr, c->n);
        const double slop = 0.01 * A->cm.h;
        c->target = c->sep > 0 ? -c->sep / dt
                               : BAUMGARTE * fmin(fmax(0, -c->sep - slop), 0.1 * A->cm.h) / dt;
        const double e = B ? fmax(A->mat.restitution, B->mat.restitution) : A->mat.restitution;
        /* restitution reverses the approach speed before this step's forces, so that a
         * bounce retraces the fall (symplectic Euler is time-symmetric that way) */
        c->bounce = -1;
        if (vn_pre < -v_bounce && vn0 * dt < -c->sep) {
            c->target = fmax(c->target, -e * vn_pre);
            c->bounce = e;
        }
        c->mu = B ? sqrt(A->mat.friction * B->mat.friction)
                  : sqrt(A->mat.friction * (c->D ? c->D->mat.friction : w->def.ground_friction));
        c->jn = c->jt1 = c->jt2 = 0;
    }
}

static int cmp_kept(const void *x, const void *y)
{
    const kept_impulse *a = x, *b = y;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    return a->key < b->key ? -1 : a->key > b->key;
}

/* The contact's identity across steps; *sign is +1 if a is lo, else −1. */
static kept_impulse contact_id(const cs_rigid_world *rw, const contact *c, double *sign)
{
    const cs_object_id a = rw->body[c->a]->id,
                       b = c->b >= 0 ? rw->body[c->b]->id : (c->D ? c->D->id : CS_NULL_OBJECT);
    *sign = a < b ? 1.0 : -1.0;
    return (kept_impulse){.lo = a < b ? a : b, .hi = a < b ? b : a, .key = c->key};
}

/* Start from last step's impulses of the same contacts (same bodies, same node, normal
 * within ~8°): resting stacks then need few iterations and do not creep. */
static void warm_start(cs_rigid_world *rw)
{
    for (int i = 0; i < rw->nc && rw->n_kept > 0; i++) {
        contact *c = &rw->c[i];
        if (c->key < 0)
            continue;
        double sg;
        kept_impulse k = contact_id(rw, c, &sg);
        const kept_impulse *f = bsearch(&k, rw->kept, (size_t)rw->n_kept, sizeof k, cmp_kept);
        if (!f || sg * cs_vec3_dot(f->n, c->n) < 0.99)
            continue;
        c->jn = fmax(0, sg * cs_vec3_dot(f->J, c->n));
        const double lim = c->mu * c->jn;
        c->jt1 = fmin(lim, fmax(-lim, sg * cs_vec3_dot(f->J, c->t1)));
        c->jt2 = fmin(lim, fmax(-lim, sg * cs_vec3_dot(f->J, c->t2)));
        double J[3], T[3];
        for (int a = 0; a < 3; a++) {
            J[a] = c->jn * c->n[a];
            T[a] = c->jt1 * c->t1[a] + c->jt2 * c->t2[a];
        }
        contact_impulse(rw, c, J, 1.0);
        contact_impulse(rw, c, T, FRICTION_LOCAL);
    }
}

static int keep_impulses(cs_rigid_world *rw)
{
    if (rw->nc > rw->cap_kept) {
        kept_impulse *g = realloc(rw->kept, (size_t)rw->nc * sizeof *g);
        if (!g)
            return -1;
        rw->kept = g;
        rw->cap_kept = rw->nc;
    }
    int n = 0;
    for (int i = 0; i < rw->nc; i++) {
        const contact *c = &rw->c[i];
        if (c->key < 0)
            continue;
        double sg;
        kept_impulse k = contact_id(rw, c, &sg);
        for (int a = 0; a < 3; a++) {
            k.n[a] = sg * c->n[a];
            k.J[a] = sg * (c->jn * c->n[a] + c->jt1 * c->t1[a] + c->jt2 * c->t2[a]);
        }
        rw->kept[n++] = k;
    }
    if (n > 1)
        qsort(rw->kept, (size_t)n, sizeof *rw->kept, cmp_kept);
    rw->n_kept = n;
    return 0;
}

static void solve_contacts(cs_rigid_world *rw)
{
    for (int it = 0; it < PGS_ITERATIONS; it++)
        for (int i = 0; i < rw->nc; i++) {
            contact *c = &rw->c[i];
            if (c->kn == 0)
                continue;
            double vr[3];
            rel_velocity(rw, c, vr);
            double dj = (c->target - cs_vec3_dot(vr, c->n)) * c->kn;
            double jn = fmax(0, c->jn + dj);
            dj = jn - c->jn;
            c->jn = jn;
            double J[3];
            for (int a = 0; a < 3; a++)
                J[a] = dj * c->n[a];
            contact_impulse(rw, c, J, 1.0);
            /* friction, each tangent clamped to μ jn */
            rel_velocity(rw, c, vr);
            const double lim = c->mu * c->jn;
            double *jt[2] = {&c->jt1, &c->jt2};
            const double *t[2] = {c->t1, c->t2}, kt[2] = {c->kt1, c->kt2};
            for (int s = 0; s < 2; s++) {
                double d = -cs_vec3_dot(vr, t[s]) * kt[s];
                double nj = fmin(lim, fmax(-lim, *jt[s] + d));
                d = nj - *jt[s];
                *jt[s] = nj;
                for (int a = 0; a < 3; a++)
                    J[a] = d * t[s][a];
                contact_impulse(rw, c, J, FRICTION_LOCAL);
            }
        }
}

/*
 * Time of impact of a bounce within the substep. A body that bounces off something that does
 * not move (the ground, a sleeping or fixed body) while still in flight (every contact of
 * it has a gap) would turn at the gap, up to one substep's travel above the surface: its
 * velocity is reversed at the start of the substep. It is moved by −(1+e)·gap along the
 * normal, which puts it where the exact motion at its approach speed, reaching the surface
 * at gap/|v| into the substep and leaving at e|v|, would be at the end: the reflection of
 * the free motion in the surface; its rebound speed gains gravity's work over that drop.
 * The contact with the least gap decides, so no other
 * contact point is moved through the surface by it.
 */
static void bounce_positions(const cs_world_t *w, cs_rigid_world *rw)
{
    const double dt = rw->dt;
    for (int i = 0; i < rw->n_body; i++)
        rw->bounce_c[i] = -1;
    for (int i = 0; i < rw->nc; i++) {
        const contact *c = &rw->c[i];
        if (!rw->dyn[c->a])
            continue;
        int *bc = &rw->bounce_c[c->a];
        if (c->sep <= 0 || c->D || (c->b >= 0 && rw->dyn[c->b])) {
            /* touching, or against a moving body: no correction for either side */
            *bc = -2;
            if (c->b >= 0)
                rw->bounce_c[c->b] = -2;
            continue;
        }
        if (*bc == -2)
            continue;
        if (*bc == -1 || c->sep < rw->c[*bc].sep)
            *bc = i;
    }
    for (int i = 0; i < rw->n_body; i++) {
        const int k = rw->bounce_c[i];
        if (k < 0 || !rw->dyn[i] || rw->c[k].bounce < 0 || rw->c[k].jn <= 0)
            continue;
        const contact *c = &rw->c[k];
        cs_rigid *rb = rw->body[i]->rb;
        const double d = (1 + c->bounce) * c->sep, gn = -cs_vec3_dot(w->def.gravity, c->n);
        /* gravity's work over the extra drop d goes into the rebound: symplectic Euler
         * keeps ½v² + g z − ½ g dt v exactly in flight, so keep it across the shift too
         * (the position update that follows moves by dt v, so the shift makes up for the
         * velocity change) */
        const double vn = cs_vec3_dot(rb->v, c->n);
        const double disc = 0.25 * gn * gn * dt * dt + vn * vn - gn * dt * vn + 2 * gn * d;
        const double vn1 = vn > 0 && disc >= 0 ? 0.5 * gn * dt + sqrt(disc) : vn;
        for (int a = 0; a < 3; a++) {
            rb->c[a] -= (d + dt * (vn1 - vn)) * c->n[a];
            rb->v[a] += (vn1 - vn) * c->n[a];
        }
    }
}

static uint32_t id_hash(cs_object_id id)
{
    return id * 2654435761u;
}

/* File rw->soft[i] in rw->soft_map under its object's id. */
static void soft_map_put(cs_rigid_world *rw, int i)
{
    const uint32_t mask = (uint32_t)rw->cap_map - 1;
    uint32_t h = id_hash(rw->soft[i]->id) & mask;
    while (rw->soft_map[h])
        h = (h + 1) & mask;
    rw->soft_map[h] = i + 1;
}

/* rw->soft_map refiled with cap slots (a power of two, > rw->n_soft). */
static int soft_map_build(cs_rigid_world *rw, int cap)
{
    if (cap != rw->cap_map) {
        int *m = realloc(rw->soft_map, (size_t)cap * sizeof *m);
        if (!m)
            return -1;
        rw->soft_map = m;
        rw->cap_map = cap;
    }
    memset(rw->soft_map, 0, (size_t)cap * sizeof *rw->soft_map);
    for (int i = 0; i < rw->n_soft; i++)
        soft_map_put(rw, i);
    return 0;
}

/* The record of object id in rw->soft, NULL if none. */
static cs_soft_resp *soft_find(const cs_rigid_world *rw, cs_object_id id)
{
    const uint32_t mask = (uint32_t)rw->cap_map - 1;
    for (uint32_t h = id_hash(id) & mask; rw->cap_map > 0 && rw->soft_map[h];
         h = (h + 1) & mask)
        if (rw->soft[rw->soft_map[h] - 1]->id == id)
            return rw->soft[rw->soft_map[h] - 1];
    return NULL;
}

/* D's response to this step's impulses (contact_soft.h), made on the first contact search
 * of the step that reaches D and kept through the step's substeps, into rw->cur for the
 * contacts about to be made. Returns 0 or -1 (out of memory). */
static int soft_prepare(const cs_world_t *w, cs_rigid_world *rw, cs_object *D, bool iso)
{
    /* (found through a hash on the id: a search of the list made a step with thousands of
     * objects in contact quadratic in their number) */
    cs_soft_resp *r = soft_find(rw, D->id);
    if (!r) {
        if (2 * (rw->n_soft + 1) > rw->cap_map &&
            soft_map_build(rw, rw->cap_map ? 2 * rw->cap_map : 16) != 0)
            return -1;
        cs_soft_resp **g = room_for_one(rw->soft, rw->n_soft, &rw->cap_soft, sizeof *g, 4);
        if (!g)
            return -1;
        rw->soft = g;
        if (!(r = calloc(1, sizeof *r)))
            return -1;
        r->id = D->id; /* (cs_soft_prepare sets it too; the map files it under it now) */
        rw->soft[rw->n_soft++] = r;
        soft_map_put(rw, rw->n_soft - 1);
    }
    if (cs_soft_prepare(r, D, w->def.dt, rw->step, iso, w->def.ground_friction) != 0)
        return -1;
    rw->cur = r;
    return 0;
}

/*
 * Nodes of deformable objects inside a rigid body's cubes: pushed out through the nearest
 * exposed face of the cube they are in, their velocity into the body removed by an impulse
 * whose opposite acts on the body (friction limited by μ times it).
 */
/* One node i of deformable D against rigid body b: a contact if it lies in one of b's cubes. */
static int node_body(cs_world_t *w, cs_rigid_world *rw, cs_object *D, int b, int i)
{
    const double dt = w->rigid->dt;
    cs_object *B = rw->body[b];
    cs_rigid *rb = B->rb;
    const double h = B->cm.h;
    const double *x = D->x + 3 * (size_t)i, *v = rw->cur->u + 3 * (size_t)i;
    if (D->mask[3 * (size_t)i] || x[0] < rb->aabb_min[0] || x[0] > rb->aabb_max[0] ||
        x[1] < rb->aabb_min[1] || x[1] > rb->aabb_max[1] ||
        x[2] < rb->aabb_min[2] || x[2] > rb->aabb_max[2])
        return 0;
    double dl[3], X[3], u[3];
    int32_t ijk[3];
    for (int a = 0; a < 3; a++)
        dl[a] = x[a] - rb->c[a];
    cs_mat3_t_vec(rb->R, dl, X);
    for (int a = 0; a < 3; a++) {
        u[a] = (X[a] + rb->com_rest[a] - B->cm.origin[a]) / h;
        ijk[a] = (int32_t)floor(u[a]);
    }
    /* a node on a face of the body (up to rounding) belongs to it too */
    int32_t cell = cs_cubemesh_find(&B->cm, ijk[0], ijk[1], ijk[2]);
    for (int a = 0; a < 3 && cell < 0; a++) {
        const double f = u[a] - ijk[a];
        const int step = f < 1e-7 ? -1 : (f > 1 - 1e-7 ? 1 : 0);
        if (!step)
            continue;
        ijk[a] += step;
        cell = cs_cubemesh_find(&B->cm, ijk[0], ijk[1], ijk[2]);
        if (cell < 0)
            ijk[a] -= step;
    }
    if (cell < 0)
        return 0;
    /* the exposed face it is nearest to, counting the distance it moved in
     * (relative to the body) in the last step: a node the body overtook is
     * pushed back out the way it came, not through a nearer side */
    double vrel_l[3], rr[3], wrr[3], vv[3];
    for (int a = 0; a < 3; a++)
        rr[a] = x[a] - rb->c[a];
    cs_vec3_cross(rb->w, rr, wrr);
    for (int a = 0; a < 3; a++)
        vv[a] = v[a] - rb->v[a] - wrr[a];
    cs_mat3_t_vec(rb->R, vv, vrel_l);
    double best = INFINITY, score_best = INFINITY;
    int bax = -1, bdir = 0;
    for (int ax = 0; ax < 3; ax++)
        for (int dir = -1; dir <= 1; dir += 2) {
            int32_t nb[3] = {ijk[0], ijk[1], ijk[2]};
            nb[ax] += dir;
            if (cs_cubemesh_find(&B->cm, nb[0], nb[1], nb[2]) >= 0)
                continue;
            const double f = u[ax] - ijk[ax];
            const double dist = (dir > 0 ? 1 - f : f) * h;
            if (dist < 1e-7 * h)
                continue; /* on that face's plane: not in through it */
            const double score = dist + 2 * dt * dir * vrel_l[ax];
            if (score < score_best) {
                score_best = score;
                best = dist;
                bax = ax;
                bdir = dir;
            }
        }
    if (bax < 0)
        return 0;
    double nl[3] = {0, 0, 0}, n[3];
    nl[bax] = bdir;
    cs_mat3_vec(rb->R, nl, n);
    contact *c = new_contact(rw);
    if (!c)
        return -1;
    c->a = b;
    c->b = -1;
    c->D = D;
    c->S = rw->cur;
    memcpy(c->p, x, sizeof c->p);
    for (int a = 0; a < 3; a++)
        c->n[a] = -n[a]; /* from the node towards the body */
    c->sep = -best;
    c->cell_a = cell;
    c->key = ((int64_t)1 << 60) + ((int64_t)i * 3 + bax) * 2 + (bdir > 0);
    c->dn[0] = c->dn[1] = c->dn[2] = c->dn[3] = i;
    c->dw[0] = 1;
    return 0;
}

static int deformable_contacts(cs_world_t *w, cs_rigid_world *rw, int n_objects)
{
    for (int d = 0; d < n_objects; d++) {
        cs_object *D = w->objects[d];
        if (D->model == CS_MODEL_RIGID || D->n == 0)
            continue;
        double lo[3], hi[3];
        const int over = bodies_over(rw, D, 0.0, lo, hi);
        if (over == 0)
            continue;
        if (soft_prepare(w, rw, D, false) != 0)
            return -1;
        const bool grid = over >= w->broadphase_min_bodies;
        if (grid && grid_build(rw, D, false, lo, hi) != 0)
            return -1;
        for (int b = 0; b < rw->n_body; b++) {
            if (!rw->dyn[b] && D->sleeping)
                continue; /* both at rest */
            if (!grid) {
                for (int i = 0; i < D->n; i++)
                    if (node_body(w, rw, D, b, i) != 0)
                        return -1;
                continue;
            }
            const cs_rigid *rb = rw->body[b]->rb;
            grid_query(rw->grid, rb->aabb_min, rb->aabb_max);
            for (int e = 0; e < rw->grid->n_cand; e++)
                if (node_body(w, rw, D, b, rw->grid->cand[e]) != 0)
                    return -1;
        }
    }
    return 0;
}

/* The local coordinates u ∈ [0,1]³ of p in the (deformed) hexahedron with corners x[k]
 * (CS_CORNER order), by Newton on the trilinear map. False if it does not converge or p is
 * outside (by more than tol). */
static bool hex_local(const double x[8][3], const double p[3], double u[3], double tol)
{
    u[0] = u[1] = u[2] = 0.5;
    for (int it = 0; it < 8; it++) {
        double r[3] = {-p[0], -p[1], -p[2]}, J[9] = {0};
        for (int k = 0; k < 8; k++) {
            double f[3], df[3];
            for (int a = 0; a < 3; a++) {
                f[a] = CS_CORNER[k][a] ? u[a] : 1 - u[a];
                df[a] = CS_CORNER[k][a] ? 1 : -1;
            }
            const double N = f[0] * f[1] * f[2];
            const double dN[3] = {df[0] * f[1] * f[2], f[0] * df[1] * f[2], f[0] * f[1] * df[2]};
            for (int a = 0; a < 3; a++) {
                r[a] += N * x[k][a];
                for (int b = 0; b < 3; b++)
                    J[3 * a + b] += x[k][a] * dN[b];
            }
        }
        double Ja[9], du[3];
        const double det = cs_mat3_adjugate(J, Ja);
        if (!(fabs(det) > 0))
            return false;
        cs_mat3_vec(Ja, r, du);
        double m = 0;
        for (int a = 0; a < 3; a++) {
            u[a] -= du[a] / det;
            m = fmax(m, fabs(du[a] / det));
            if (!(fabs(u[a] - 0.5) < 2))
                return false;
        }
        if (m < 1e-10)
            break;
    }
    for (int a = 0; a < 3; a++)
        if (u[a] < -tol || u[a] > 1 + tol)
            return false;
    return true;
}

/* How far outside a face, in the cell's own coordinates, a surface point is still taken as on
 * the face's plane when the face faces the same way as the point's surface (point_in_cell) */
#define COPLANAR 0.05

/* A point against a deformable cell: the face it is pushed out through, its gap and the face
 * point's nodes and bilinear weights. */
typedef struct cell_face {
    double n[3];    /* outward normal of the face (the cell's mean edge across it) */
    double sep;     /* the point's gap to the face along n (negative inside) */
    int32_t dn[4];
    double dw[4];
    int face;       /* 2·axis + (side > 0) */
} cell_face;

/* Point p inside D's deformed cell (corners X, CS_CORNER order; inverse trilinear map), or
 * within `margin` outside it across one face only: true with the nearest exposed face of the
 * cell (in the cell's own coordinates) in *cf. False if p is elsewhere or no face of the
 * cell that it could leave by is exposed. pn (or NULL): the outward normal of the surface p
 * is on (a deformable node of another object); only faces that face it (normals within
 * ~70° of opposite) are taken, so a node on a block lying on another is pushed up, not out
 * through the side face whose plane it happens to lie in. */
static bool point_in_cell(const cs_object *D, int32_t cell, const double X[8][3],
                          const double p[3], const double *pn, double margin, double tol,
                          cell_face *cf)
{
    const int32_t *cn = D->cm.cell_nodes + 8 * (size_t)cell;
    const int32_t *ijk = D->cm.cell_ijk + 3 * (size_t)cell;
    double u[3];
    if (!hex_local(X, p, u, tol))
        return false;
    /* the cell's mean edges: with pn, the faces' directions */
    double E[3][3] = {{0}};
    for (int ax = 0; pn && ax < 3; ax++)
        for (int k = 0; k < 8; k++) {
            const double sg = CS_CORNER[k][ax] ? 0.25 : -0.25;
            for (int a = 0; a < 3; a++)
                E[ax][a] += sg * X[k][a];
        }
    /* outside the cell (within the margin) across one of its faces only:
     * a speculative contact with that face if it is exposed. A surface point just outside
     * a face that faces the same way as its surface (pn) is on that face's plane, not
     * approaching it: two blocks stacked with flush sides, each one's edge nodes in the
     * other's side planes. It is taken as on the face (u clamped) and meets the cell's other
     * faces. Before, such a node was outside or inside by a fraction of a millimetre as the
     * blocks deformed: outside, it had no contact at all and sank into the other block
     * (18–24 mm under an overhanging block, 10–20 mm at a crack), then met it deep inside
     * and was pushed out at the Baumgarte limit, and the stack rattled. */
    int n_out = 0, oax = -1;
    for (int a = 0; a < 3; a++) {
        if (!(u[a] < 0 || u[a] > 1))
            continue;
        const int dir = u[a] > 1 ? 1 : -1;
        const double side = dir > 0 ? 1 : 0;
        if (pn && fabs(u[a] - side) < COPLANAR &&
            dir * cs_vec3_dot(E[a], pn) > 0.3 * cs_vec3_norm(E[a])) {
            u[a] = side;
            continue;
        }
        n_out++;
        oax = a;
    }
    if (n_out > 1)
        return false;
    /* the nearest exposed face (in the cell's own coordinates); f < 0 outside */
    int bax = -1, bdir = 0;
    double bf = INFINITY;
    for (int ax = 0; ax < 3; ax++)
        for (int dir = -1; dir <= 1; dir += 2) {
            if (n_out && (ax != oax || (dir > 0) != (u[ax] > 1)))
                continue;
            if (pn && dir * cs_vec3_dot(E[ax], pn) > -0.3 * cs_vec3_norm(E[ax]))
                continue;
            int32_t nb[3] = {ijk[0], ijk[1], ijk[2]};
            nb[ax] += dir;
            if (cs_cubemesh_find(&D->cm, nb[0], nb[1], nb[2]) >= 0)
                continue;
            const double f = dir > 0 ? 1 - u[ax] : u[ax];
            if (f < bf) {
                bf = f;
                bax = ax;
                bdir = dir;
            }
        }
    if (bax < 0)
        return false;
    /* e: the cell's mean edge along bax; the face normal is e's direction
     * (sheared cells: close enough, the gap is measured along it) */
    double e[3] = {0, 0, 0};
    for (int k = 0; k < 8; k++) {
        const double sg = CS_CORNER[k][bax] ? 0.25 : -0.25;
        for (int a = 0; a < 3; a++)
            e[a] += sg * X[k][a];
    }
    const double el = cs_vec3_norm(e);
    if (!(el > 0) || -bf * el >= margin)
        return false;
    for (int a = 0; a < 3; a++)
        cf->n[a] = bdir * e[a] / el;
    cf->sep = -bf * el;
    cf->face = 2 * bax + (bdir > 0);
    const int a1 = (bax + 1) % 3, a2 = (bax + 2) % 3;
    int j = 0;
    for (int k = 0; k < 8 && j < 4; k++) {
        if (CS_CORNER[k][bax] != (bdir > 0))
            continue;
        const double u1 = fmin(1, fmax(0, u[a1])), u2 = fmin(1, fmax(0, u[a2]));
        cf->dn[j] = cn[k];
        cf->dw[j] = (CS_CORNER[k][a1] ? u1 : 1 - u1) * (CS_CORNER[k][a2] ? u2 : 1 - u2);
        j++;
    }
    return true;
}

/*
 * Rigid nodes (the corners of its cubes) against the cells of deformable objects: a rigid
 * corner or edge pressing into a deformable face between its nodes, which deformable_contacts
 * (nodes against cubes) does not see. The node is located in a deformed cell (inverse
 * trilinear map of its 8 current corners), or within the body's speculative margin outside
 * it across one face; the contact is the nearest exposed face of the cell (in the cell's own
 * coordinates), the normal the cell's mean edge across it, the gap the node's distance to it
 * along that edge (negative inside). The other side of the contact is the face point under
 * the node, Σ wk x_k over the face's 4 corners with their bilinear weights: it takes part in
 * the sequential-impulse solve with the bodies' contacts (effective mass from Σ wk² times each
 * corner's compliance, contact_soft.h; an impulse −wk J on corner k), so the body and the
 * deformable object exchange momentum
 * two-way, with friction, warm starting and speculative approach like any contact. Fills
 * rw->c; returns 0 or -1 (out of memory).
 */
static int cell_body(cs_world_t *w, cs_rigid_world *rw, cs_object *D, int b, int32_t cell,
                     double margin, double tol)
{
    cs_object *B = rw->body[b];
    const cs_rigid *rb = B->rb;
    (void)w;
    const int32_t *cn = D->cm.cell_nodes + 8 * (size_t)cell;
    double X[8][3], lo[3] = {INFINITY, INFINITY, INFINITY};
    double hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int k = 0; k < 8; k++)
        for (int a = 0; a < 3; a++) { /* (not fmin/fmax: libm calls, 40 % of this loop) */
            X[k][a] = D->x[3 * (size_t)cn[k] + a];
            lo[a] = X[k][a] - margin < lo[a] ? X[k][a] - margin : lo[a];
            hi[a] = X[k][a] + margin > hi[a] ? X[k][a] + margin : hi[a];
        }
    if (lo[0] > rb->aabb_max[0] || hi[0] < rb->aabb_min[0] || lo[1] > rb->aabb_max[1] ||
        hi[1] < rb->aabb_min[1] || lo[2] > rb->aabb_max[2] || hi[2] < rb->aabb_min[2])
        return 0;
    for (int i = 0; i < B->n; i++) {
        const double *p = B->x + 3 * (size_t)i;
        if (p[0] < lo[0] || p[0] > hi[0] || p[1] < lo[1] || p[1] > hi[1] ||
            p[2] < lo[2] || p[2] > hi[2])
            continue;
        cell_face cf;
        if (!point_in_cell(D, cell, X, p, NULL, margin, tol, &cf))
            continue;
        contact *c = new_contact(rw);
        if (!c)
            return -1;
        c->a = b;
        c->b = -1;
        c->D = D;
        c->S = rw->cur;
        memcpy(c->p, p, sizeof c->p);
        memcpy(c->n, cf.n, sizeof c->n);
        c->sep = cf.sep;
        c->node_a = i;
        c->key = ((int64_t)cell * 6 + cf.face) * B->n + i;
        memcpy(c->dn, cf.dn, sizeof c->dn);
        memcpy(c->dw, cf.dw, sizeof c->dw);
    }
    return 0;
}

static int cell_contacts(cs_world_t *w, cs_rigid_world *rw, int n_objects)
{
    const double dt = w->rigid->dt;
    for (int d = 0; d < n_objects; d++) {
        cs_object *D = w->objects[d];
        if (D->model == CS_MODEL_RIGID || D->n == 0 || D->cm.n_cells == 0)
            continue;
        double lo[3], hi[3];
        const int over = bodies_over(rw, D, -1.0, lo, hi);
        if (over == 0)
            continue;
        if (soft_prepare(w, rw, D, false) != 0)
            return -1;
        const bool grid = over >= w->broadphase_min_bodies;
        if (grid && grid_build(rw, D, true, lo, hi) != 0)
            return -1;
        for (int b = 0; b < rw->n_body; b++) {
            cs_object *B = rw->body[b];
            const cs_rigid *rb = B->rb;
            if (!rw->dyn[b] && D->sleeping)
                continue; /* both at rest: nothing to do until one moves */
            /* speculative: nodes within the distance the body can close in a substep */
            const double margin = body_margin(B, dt), tol = fmin(0.5, margin / D->cm.h);
            if (!grid) {
                for (int32_t cell = 0; cell < D->cm.n_cells; cell++)
                    if (cell_body(w, rw, D, b, cell, margin, tol) != 0)
                        return -1;
                continue;
            }
            const double qlo[3] = {rb->aabb_min[0] - margin, rb->aabb_min[1] - margin,
                                   rb->aabb_min[2] - margin};
            const double qhi[3] = {rb->aabb_max[0] + margin, rb->aabb_max[1] + margin,
                                   rb->aabb_max[2] + margin};
            grid_query(rw->grid, qlo, qhi);
            for (int e = 0; e < rw->grid->n_cand; e++)
                if (cell_body(w, rw, D, b, rw->grid->cand[e], margin, tol) != 0)
                    return -1;
        }
    }
    return 0;
}

/* After the solve: the deformable objects contacts pushed are awake; their energies and
 * surfaces follow the velocities and positions they now have. A push from a moving body, or
 * one that woke D, starts D's count of still steps afresh; a body at rest (asleep) lying on
 * an awake D does not, so D falls asleep under it once its own nodes are still (finish_step)
 * and the pair is then skipped until something moves. */
static void cell_contacts_done(cs_rigid_world *rw)
{
    const cs_object *last = NULL; /* contacts come grouped by object: skin each once a group */
    for (int i = 0; i < rw->nc; i++) {
        const contact *c = &rw->c[i];
        cs_object *D = c->D;
        if (D && c->jn > 0) {
            D->elastic_energy_valid = false;
            if (D->sleeping || rw->dyn[c->a])
                D->still_steps = 0;
            D->sleeping = false;
            D->contact_pushed = true;
            if (D != last)
                cs_surface_skin(&D->surf, &D->cm, D->x, 1);
            last = D;
        }
    }
}

/* ---------------------------------------------------------------- deformable against deformable */

/*
 * A node of deformable object A inside (or within the speculative margin outside) a deformed
 * cell of deformable object B, pushed out through the cell's nearest exposed face like a rigid
 * corner (point_in_cell): the face point Σ wk x_k of B's face against A's node. Both sides
 * answer as their objects' next implicit steps will (contact_soft.h); an impulse J on A's
 * node is −wk J on B's corner k, so momentum is exchanged exactly.
 */
typedef struct soft_contact {
    cs_soft_resp *SA, *SB;
    int32_t node;       /* of A */
    int32_t bn[4];      /* B's face corners and their weights */
    double bw[4];
    double n[3];        /* B's outward face normal: from B towards A */
    double sep, hB;
    double ra[3], rb[3];
    double t1[3], t2[3];
    double kn, kt1, kt2, target, jn, jt1, jt2, mu;
    double e;           /* restitution: the larger of the two materials' */
    double vimp;        /* < 0: the node's approach now, at an impact (pair_restitution) */
    double vapp;        /* in a pair's first contact: the pair's approach on their rigid
                         * modes (pair_approach) */
} soft_contact;

static const double ONE[1] = {1.0};

static void soft_rel_velocity(const soft_contact *c, double v[3])
{
    double va[3], vb[3];
    cs_soft_velocity(c->SA, &c->node, ONE, 1, c->ra, va);
    cs_soft_velocity(c->SB, c->bn, c->bw, 4, c->rb, vb);
    for (int a = 0; a < 3; a++)
        v[a] = va[a] - vb[a];
}

/*
 * The effective mass of contact c along d: 1 / (the two points' compliances), or 0 (the
 * contact takes no impulse) where both points are held: each point's compliance under
 * SOFT_HELD_FRACTION of what it would be with none of its nodes held, i.e. the point lies
 * within about 1 % of held nodes (its free nodes' weights under ~1e-2). Pieces of an object
 * held across their crack have such contacts from birth: a held node on the other piece's held
 * corner, the face point's weights on its free corners round-off (1e-15 … 1e-47). Their
 * compliance was the round-off's square, the effective mass 1e28–1e64 kg, and the impulse
 * the round-off asked for, given to the free corners by their round-off weights, threw them
 * at hundreds of m/s (in the fracture demo, the beam's pieces at its clamp and the star's at
 * its held top). Nothing is lost by dropping them: what moves such a point is its free
 * nodes, through a lever of their weights, and a push there would have to move them 1/w as
 * far; the held nodes hold it.
 */
#define SOFT_HELD_FRACTION 1e-4

static double soft_eff_mass(const soft_contact *c, const double d[3])
{
    const double ka = cs_soft_compliance(c->SA, &c->node, ONE, 1, c->ra, d, 1.0),
                 kb = cs_soft_compliance(c->SB, c->bn, c->bw, 4, c->rb, d, 1.0);
    if (c->SA->D->n_fixed_nodes > 0 && c->SB->D->n_fixed_nodes > 0 && /* (else none is held) */
        ka < SOFT_HELD_FRACTION * cs_soft_unheld_compliance(c->SA, &c->node, ONE, 1, d) &&
        kb < SOFT_HELD_FRACTION * cs_soft_unheld_compliance(c->SB, c->bn, c->bw, 4, d))
        return 0.0;
    const double k = ka + kb;
    return k > 0 ? 1.0 / k : 0.0;
}

static void soft_impulse(soft_contact *c, const double J[3])
{
    const double mJ[3] = {-J[0], -J[1], -J[2]};
    cs_soft_impulse(c->SA, &c->node, ONE, 1, c->ra, J, 1.0);
    cs_soft_impulse(c->SB, c->bn, c->bw, 4, c->rb, mJ, 1.0);
}

/* The normal relative velocity the two sides have now (D->v: after their steps). */
static double soft_now_normal(const soft_contact *c)
{
    const cs_object *A = c->SA->D, *B = c->SB->D;
    double v[3];
    for (int a = 0; a < 3; a++) {
        v[a] = A->v[3 * (size_t)c->node + a];
        for (int k = 0; k < 4; k++)
            v[a] -= c->bw[k] * B->v[3 * (size_t)c->bn[k] + a];
    }
    return cs_vec3_dot(v, c->n);
}

/* Room in rw->sbox for n objects' boxes (7 doubles each). */
static int sbox_room(cs_rigid_world *rw, int n)
{
    if (n <= rw->cap_sbox)
        return 0;
    double *g = realloc(rw->sbox, (size_t)n * 7 * sizeof *g);
    if (!g)
        return -1;
    rw->sbox = g;
    rw->cap_sbox = n;
    return 0;
}

/* D's box (of its nodes) and its fastest node's speed. */
static void object_box(const cs_object *D, double lo[3], double hi[3], double *vmax)
{
    double v2 = 0;
    for (int a = 0; a < 3; a++) {
        lo[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    for (int i = 0; i < D->n; i++) {
        const double *x = D->x + 3 * (size_t)i, *v = D->v + 3 * (size_t)i;
        for (int a = 0; a < 3; a++) {
            lo[a] = x[a] < lo[a] ? x[a] : lo[a];
            hi[a] = x[a] > hi[a] ? x[a] : hi[a];
        }
        const double s = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        v2 = s > v2 ? s : v2;
    }
    *vmax = sqrt(v2);
}

/* The outward normal of A's surface at node i (the sum of the directions of the exposed faces
 * of its cells that it is a corner of, each the cell's current mean edge across it); false for
 * a node inside A (or where they cancel). */
static bool node_normal(const cs_object *A, int i, double n[3])
{
    n[0] = n[1] = n[2] = 0;
    for (int32_t e = A->fem.adj_start[i]; e < A->fem.adj_start[i + 1]; e++) {
        const int32_t c = A->fem.adj[e] >> 3, k = A->fem.adj[e] & 7;
        const int32_t *ijk = A->cm.cell_ijk + 3 * (size_t)c, *cn = A->cm.cell_nodes + 8 * (size_t)c;
        for (int ax = 0; ax < 3; ax++) {
            const int dir = CS_CORNER[k][ax] ? 1 : -1;
            int32_t nb[3] = {ijk[0], ijk[1], ijk[2]};
            nb[ax] += dir;
            if (cs_cubemesh_find(&A->cm, nb[0], nb[1], nb[2]) >= 0)
                continue;
            double d[3] = {0, 0, 0};
            for (int q = 0; q < 8; q++) {
                const double sg = CS_CORNER[q][ax] ? 0.25 : -0.25;
                for (int a = 0; a < 3; a++)
                    d[a] += sg * A->x[3 * (size_t)cn[q] + a];
            }
            const double l = cs_vec3_norm(d);
            for (int a = 0; l > 0 && a < 3; a++)
                n[a] += dir * d[a] / l;
        }
    }
    const double l = cs_vec3_norm(n);
    if (!(l > 1e-6))
        return false;
    for (int a = 0; a < 3; a++)
        n[a] /= l;
    return true;
}

/* Append a deformable contact of node i of A behind best's face of B, at separation sep
 * (e = the larger restitution, until prepared). NULL when out of memory. */
static soft_contact *add_soft_contact(cs_rigid_world *rw, const cs_object *A, const cs_object *B,
                                      cs_soft_resp *SA, cs_soft_resp *SB, int i,
                                      const cell_face *best, double sep)
{
    soft_contact *g = room_for_one(rw->sc, rw->nsc, &rw->cap_sc, sizeof *g, 256);
    if (!g)
        return NULL;
    rw->sc = g;
    soft_contact *c = &rw->sc[rw->nsc++];
    memset(c, 0, sizeof *c);
    c->SA = SA;
    c->SB = SB;
    c->node = i;
    memcpy(c->bn, best->dn, sizeof c->bn);
    memcpy(c->bw, best->dw, sizeof c->bw);
    memcpy(c->n, best->n, sizeof c->n);
    c->sep = sep;
    c->hB = B->cm.h;
    c->mu = sqrt(A->mat.friction * B->mat.friction);
    c->e = fmax(A->mat.restitution, B->mat.restitution);
    return c;
}

/* The nodes of A in the overlap [olo, ohi] against B's cells (filed in rw->grid over B's box
 * [blo, bhi]): at most one contact per node, with the face it is least deep behind. */
static int soft_nodes_in_cells(cs_rigid_world *rw, cs_object *A, cs_object *B,
                               cs_soft_resp *SA, cs_soft_resp *SB, const double olo[3],
                               const double ohi[3], const double blo[3], const double bhi[3],
                               double margin)
{
    if (grid_build(rw, B, true, blo, bhi) != 0)
        return -1;
    const double tol = fmin(0.5, margin / B->cm.h);
    for (int i = 0; i < A->n; i++) {
        const double *p = A->x + 3 * (size_t)i;
        if (p[0] < olo[0] || p[0] > ohi[0] || p[1] < olo[1] || p[1] > ohi[1] || p[2] < olo[2] ||
            p[2] > ohi[2])
            continue;
        const double qlo[3] = {p[0] - margin, p[1] - margin, p[2] - margin};
        const double qhi[3] = {p[0] + margin, p[1] + margin, p[2] + margin};
        grid_query(rw->grid, qlo, qhi);
        double pn[3];
        int surface = -1; /* node_normal's answer, asked once a cell is near */
        cell_face best = {.sep = -INFINITY};
        for (int e = 0; e < rw->grid->n_cand; e++) {
            const int32_t cell = rw->grid->cand[e];
            const int32_t *cn = B->cm.cell_nodes + 8 * (size_t)cell;
            double X[8][3];
            bool near = true;
            for (int a = 0; a < 3 && near; a++) {
                double l = INFINITY, h = -INFINITY;
                for (int k = 0; k < 8; k++) {
                    X[k][a] = B->x[3 * (size_t)cn[k] + a];
                    l = X[k][a] < l ? X[k][a] : l;
                    h = X[k][a] > h ? X[k][a] : h;
                }
                near = p[a] >= l - margin && p[a] <= h + margin;
            }
            if (!near)
                continue;
            if (surface < 0)
                surface = node_normal(A, i, pn);
            cell_face cf;
            if (point_in_cell(B, cell, X, p, surface ? pn : NULL, margin, tol, &cf) &&
                cf.sep > best.sep)
                best = cf;
        }
        /* a node more than half a cell behind the face did not get there by a step's
         * approach (the speculative reach is half a cell): objects that met inside each
         * other (a tumbling linear-model piece grows) are not pushed apart from within, which
         * crushed and inverted small pieces in the fracture storm */
        if (best.sep == -INFINITY || best.sep < -0.5 * B->cm.h)
            continue;
        if (!add_soft_contact(rw, A, B, SA, SB, i, &best, best.sep))
            return -1;
    }
    return 0;
}

/* Whether o's box has been apart from kin id's (o->apart). */
static int kin_apart(const cs_object *o, cs_object_id id)
{
    for (int i = 0; i < o->n_apart; i++)
        if (o->apart[i] == id)
            return 1;
    return 0;
}

static int kin_add(cs_object *o, cs_object_id id)
{
    cs_object_id *g = room_for_one(o->apart, o->n_apart, &o->cap_apart, sizeof *g, 4);
    if (!g)
        return -1;
    o->apart = g;
    o->apart[o->n_apart++] = id;
    return 0;
}

/* o's record of kin id's born pairs (NULL if none). */
static cs_born_ref *born_find(cs_object *o, cs_object_id id)
{
    for (int i = 0; i < o->n_born; i++)
        if (o->born[i].other == id)
            return &o->born[i];
    return NULL;
}

/* Drop o's record of kin id (their boxes came apart: the whole search takes over). */
static void born_drop(cs_object *o, cs_object_id id)
{
    cs_born_ref *r = born_find(o, id);
    if (!r)
        return;
    free(r->ref);
    *r = o->born[--o->n_born];
}

/* A new record of kin id for o, all references 0; NULL when out of memory. */
static cs_born_ref *born_new(cs_object *o, cs_object_id id)
{
    cs_born_ref *g = room_for_one(o->born, o->n_born, &o->cap_born, sizeof *g, 4);
    if (!g)
        return NULL;
    o->born = g;
    float *ref = calloc((size_t)(o->n ? o->n : 1), sizeof *ref);
    if (!ref)
        return NULL;
    cs_born_ref *r = &o->born[o->n_born++];
    *r = (cs_born_ref){.other = id, .n = o->n, .ref = ref};
    return r;
}

/*
 * The born pairs of kin A and B whose boxes have not been apart: each node of A (in the
 * overlap [olo, ohi]) at a lattice point that is a corner of B's cells (kin share their
 * parent's lattice), against those cells only (point_in_cell: the nearest exposed face that
 * faces it). Contacts are taken against a reference depth instead of the face: the first
 * time the pair is seen (A's record of B is made), each such node's depth moved back by a
 * step of its relative motion (sep − dt·vn: where it was before the step that followed the
 * split; a piece split between steps has since moved by one), or 0 if it is outside; after
 * that the reference follows the node out towards 0 and never back in. A piece falling into
 * its sibling from the crack is stopped at the crack; an overlap the pieces were born with
 * (an earlier crack between their parents had opened inwards, no contact stopping it) is
 * left as it is: pushing it out from within crushed and inverted small pieces in the
 * fracture storm. Resting contact only: a node approaching the face faster than v_rest (an
 * impact by restitution's measure) takes none (stopping a small piece's flight into its
 * large sibling kicked nodes at 8–116 m/s in the storm). Contacts go to rw->sc with SA and
 * SB. Returns 0 or -1.
 */
static int born_contacts(cs_rigid_world *rw, double dt, double v_rest, cs_object *A, cs_object *B,
                         cs_soft_resp *SA, cs_soft_resp *SB, const double olo[3],
                         const double ohi[3], double margin)
{
    cs_born_ref *R = born_find(A, B->id);
    const bool first = R == NULL;
    if (first && !(R = born_new(A, B->id)))
        return -1;
    if (R->n < A->n) { /* nodes A made since (a crack opened inside it): reference 0 */
        float *g = realloc(R->ref, (size_t)A->n * sizeof *g);
        if (!g)
            return -1;
        memset(g + R->n, 0, (size_t)(A->n - R->n) * sizeof *g);
        R->ref = g;
        R->n = A->n;
    }
    const double tol = fmin(0.5, margin / B->cm.h);
    for (int i = 0; i < A->n; i++) {
        const double *p = A->x + 3 * (size_t)i;
        if (p[0] < olo[0] || p[0] > ohi[0] || p[1] < olo[1] || p[1] > ohi[1] || p[2] < olo[2] ||
            p[2] > ohi[2] || A->fem.adj_start[i] == A->fem.adj_start[i + 1])
            continue;
        /* node i's lattice point, from the first of its cells */
        const int32_t e0 = A->fem.adj[A->fem.adj_start[i]];
        const int32_t *cijk = A->cm.cell_ijk + 3 * (size_t)(e0 >> 3);
        int32_t L[3];
        for (int a = 0; a < 3; a++)
            L[a] = cijk[a] + CS_CORNER[e0 & 7][a];
        double pn[3];
        int surface = -1;
        cell_face best = {.sep = -INFINITY};
        for (int q = 0; q < 8; q++) {
            const int32_t cell = cs_cubemesh_find(&B->cm, L[0] - CS_CORNER[q][0],
                                                  L[1] - CS_CORNER[q][1], L[2] - CS_CORNER[q][2]);
            if (cell < 0)
                continue;
            const int32_t *cn = B->cm.cell_nodes + 8 * (size_t)cell;
            double X[8][3];
            for (int k = 0; k < 8; k++)
                for (int a = 0; a < 3; a++)
                    X[k][a] = B->x[3 * (size_t)cn[k] + a];
            if (surface < 0)
                surface = node_normal(A, i, pn);
            cell_face cf;
            if (point_in_cell(B, cell, X, p, surface ? pn : NULL, margin, tol, &cf) &&
                cf.sep > best.sep)
                best = cf;
        }
        if (best.sep == -INFINITY)
            continue;
        /* the relative normal velocity of the node and the face point now */
        double v[3];
        for (int a = 0; a < 3; a++) {
            v[a] = A->v[3 * (size_t)i + a];
            for (int k = 0; k < 4; k++)
                v[a] -= best.dw[k] * B->v[3 * (size_t)best.dn[k] + a];
        }
        if (first)
            R->ref[i] = (float)fmin(0, best.sep - dt * cs_vec3_dot(v, best.n));
        else
            R->ref[i] = (float)fmin(0, fmax(R->ref[i], best.sep));
        if (best.sep < -0.5 * B->cm.h) /* as soft_nodes_in_cells: met inside, left there */
            continue;
        if (cs_vec3_dot(v, best.n) < -v_rest)
            continue; /* an impact, not pieces resting on each other */
        /* its restitution never applies: v_rest */
        if (!add_soft_contact(rw, A, B, SA, SB, i, &best, best.sep - R->ref[i]))
            return -1;
    }
    return 0;
}

void cs_rigid_drop_pending(cs_world_t *w)
{
    cs_rigid_world *rw = w->rigid;
    if (!rw || !rw->pending)
        return;
    rw->pending = false;
    if (w->frame != rw->pending_frame + 1)
        return; /* a step has shared them out */
    for (int k = 0; k < rw->nsc; k++) {
        const soft_contact *c = &rw->sc[k];
        cs_object *A = cs_world_find_internal(w, c->SA->id);
        cs_object *B = cs_world_find_internal(w, c->SB->id);
        if (!A || !B || A->topology_version != rw->sc_version[2 * k] ||
            B->topology_version != rw->sc_version[2 * k + 1] || c->node >= A->n)
            continue; /* removed or remade since: its nodes are others */
        double J[3];
        for (int a = 0; a < 3; a++)
            J[a] = c->jn * c->n[a] + c->jt1 * c->t1[a] + c->jt2 * c->t2[a];
        const size_t i = (size_t)c->node;
        if (!A->mask[3 * i] && A->m[i] > 0)
            for (int a = 0; a < 3; a++)
                A->v[3 * i + a] -= J[a] / A->m[i];
        for (int q = 0; q < 4; q++) {
            const size_t j = (size_t)c->bn[q];
            if (j < (size_t)B->n && !B->mask[3 * j] && B->m[j] > 0)
                for (int a = 0; a < 3; a++)
                    B->v[3 * j + a] += c->bw[q] * J[a] / B->m[j];
        }
    }
}

/*
 * Restitution between two implicit deformable objects, on the pair's rigid modes. Restitution
 * on the nodes (their approach reversed by e in the step of the impact, as with an explicit
 * object) gave the centres almost no bounce: the impulse that reverses a node's approach is
 * mostly taken by the node's local compliance, and the implicit step then spends that local
 * motion. Two soft blocks (E 1e5 Pa) meeting head-on at ±0.5 and ±1 m/s with e = 0.3 parted at
 * 0.05 m/s, and only because contact nodes missed at their flush edges were pushed back out;
 * with those found they stuck together. Now, in the step of an impact, after the contacts'
 * impulses, the pair's rigid modes get the normal impulse that makes them part at e times the
 * speed they approached at (pair_approach, before the impulses), as two rigid bodies with
 * Newton's restitution, shared over the impact's contacts by their impulses; never one that
 * pulls them together (what the contacts gave may part them faster already). The centres then
 * part at 0.293, 0.600 and 1.200 m/s for 1, 2 and 4 m/s of approach.
 */
/* The end of the run of contacts from k0 between the pair of k0's objects. */
static int pair_end(const cs_rigid_world *rw, int k0)
{
    const cs_soft_resp *P = rw->sc[k0].SA, *Q = rw->sc[k0].SB;
    int k1 = k0;
    while (k1 < rw->nsc && ((rw->sc[k1].SA == P && rw->sc[k1].SB == Q) ||
                            (rw->sc[k1].SA == Q && rw->sc[k1].SB == P)))
        k1++;
    return k1;
}

/* The pair's impact (its contacts k0..k1 with vimp < 0): the mean normal n (from Q = the other
 * object towards P = sc[k0].SA), the mean arms on each side, and the normal velocity of P's
 * rigid modes relative to Q's there (> 0 apart). False without an impact. */
static bool pair_impact(const cs_rigid_world *rw, int k0, int k1, double n[3], double rp[3],
                        double rq[3], double *vn)
{
    const cs_soft_resp *P = rw->sc[k0].SA, *Q = rw->sc[k0].SB;
    int m = 0;
    for (int a = 0; a < 3; a++)
        n[a] = rp[a] = rq[a] = 0;
    for (int k = k0; k < k1; k++) {
        const soft_contact *c = &rw->sc[k];
        if (!(c->vimp < 0))
            continue;
        const bool same = c->SA == P;
        for (int a = 0; a < 3; a++) {
            n[a] += (same ? 1 : -1) * c->n[a];
            rp[a] += (same ? c->ra : c->rb)[a];
            rq[a] += (same ? c->rb : c->ra)[a];
        }
        m++;
    }
    const double l = cs_vec3_norm(n);
    if (m == 0 || !(l > 0))
        return false;
    double vp[3], vq[3];
    for (int a = 0; a < 3; a++) {
        n[a] /= l;
        rp[a] /= m;
        rq[a] /= m;
    }
    cs_soft_coarse_velocity(P, rp, vp);
    cs_soft_coarse_velocity(Q, rq, vq);
    *vn = 0;
    for (int a = 0; a < 3; a++)
        *vn += (vp[a] - vq[a]) * n[a];
    return true;
}

/* Whether r's rigid modes translate freely along n (not held there: on the ground, a vertical
 * n; pinned or fixed, any; an explicit object has none). */
static bool free_along(const cs_soft_resp *r, const double n[3])
{
    const double m = fmax(r->minv[0], fmax(r->minv[1], r->minv[2]));
    return r->coarse && m > 0 &&
           r->minv[0] * n[0] * n[0] + r->minv[1] * n[1] * n[1] + r->minv[2] * n[2] * n[2] >=
               0.5 * m;
}

/* Before the contacts' impulses: each pair's approach at its impact, into the vapp of its
 * first contact (> 0 approaching), when both objects are free along it; else restitution on
 * the nodes, the impact's targets. */
static void pair_approach(cs_rigid_world *rw)
{
    for (int k0 = 0, k1; k0 < rw->nsc; k0 = k1) {
        k1 = pair_end(rw, k0);
        double n[3], rp[3], rq[3], vn;
        if (pair_impact(rw, k0, k1, n, rp, rq, &vn) && free_along(rw->sc[k0].SA, n) &&
            free_along(rw->sc[k0].SB, n)) {
            rw->sc[k0].vapp = -vn;
            continue;
        }
        for (int k = k0; k < k1; k++) { /* restitution on the nodes */
            soft_contact *c = &rw->sc[k];
            if (c->vimp < 0)
                c->target = fmax(c->target, -c->e * c->vimp);
            c->vimp = 0;
        }
    }
}

/* After them: the restitution impulse of each pair that approached faster than v_bounce. */
static void pair_restitution(cs_rigid_world *rw, double v_bounce)
{
    for (int k0 = 0, k1; k0 < rw->nsc; k0 = k1) {
        k1 = pair_end(rw, k0);
        const cs_soft_resp *P = rw->sc[k0].SA, *Q = rw->sc[k0].SB;
        double n[3], rp[3], rq[3], vsep;
        const double v0 = rw->sc[k0].vapp;
        if (!(v0 > v_bounce) || !pair_impact(rw, k0, k1, n, rp, rq, &vsep))
            continue;
        const double e = rw->sc[k0].e; /* (one pair of materials) */
        double sj = 0;
        for (int k = k0; k < k1; k++)
            if (rw->sc[k].vimp < 0)
                sj += rw->sc[k].jn;
        const double w =
            cs_soft_coarse_compliance(P, rp, n) + cs_soft_coarse_compliance(Q, rq, n);
        const double Jr = w > 0 ? (e * v0 - vsep) / w : 0;
        if (!(Jr > 0))
            continue;
        double sd = 0;
        for (int k = k0; k < k1; k++) {
            const soft_contact *c = &rw->sc[k];
            if (c->vimp < 0)
                sd += (sj > 0 ? c->jn : 1.0) * fabs(cs_vec3_dot(c->n, n));
        }
        for (int k = k0; k < k1 && sd > 0; k++) {
            soft_contact *c = &rw->sc[k];
            if (!(c->vimp < 0))
                continue;
            const double x = Jr * (sj > 0 ? c->jn : 1.0) / sd;
            double J[3];
            for (int a = 0; a < 3; a++)
                J[a] = x * c->n[a];
            soft_impulse(c, J);
            c->jn += x;
        }
    }
}

/* Whether soft_contacts looks at o at all. */
static bool soft_takes_part(const cs_object *o)
{
    return o->model != CS_MODEL_RIGID && o->n > 0 && o->cm.n_cells > 0;
}

/*
 * Objects i < j of soft_contacts (their boxes and speeds in rw->sbox): their contacts, if their
 * boxes, grown by the distance they can close in a step, overlap and they are not both asleep;
 * the record of kin whose boxes are apart. Nothing happens for any other pair
 * (soft_candidates relies on it). Returns 0, or -1 when out of memory.
 */
static int soft_pair(cs_world_t *w, cs_rigid_world *rw, int i, int j, double v_rest)
{
    const double dt = w->def.dt;
    cs_object *A = w->objects[i], *B = w->objects[j];
    if (!soft_takes_part(A) || !soft_takes_part(B) || (A->sleeping && B->sleeping))
        return 0;
    const double *alo = rw->sbox + 7 * i, *ahi = alo + 3, va = alo[6];
    const double *blo = rw->sbox + 7 * j, *bhi = blo + 3, vb = blo[6];
    const double margin = dt * (va + vb) + 0.05 * fmin(A->cm.h, B->cm.h);
    double olo[3], ohi[3];
    bool over = true;
    for (int a = 0; a < 3; a++) {
        olo[a] = fmax(alo[a], blo[a]) - margin;
        ohi[a] = fmin(ahi[a], bhi[a]) + margin;
        over = over && olo[a] <= ohi[a];
    }
    bool born = false; /* kin never apart: only their born pairs */
    if (A->kin == B->kin) {
        /* pieces of one object: born touching across their crack (each crack node on the
         * other's cell face), so they take the whole search only once their boxes have been
         * apart; until then their born pairs (born_contacts) */
        const int ka = kin_apart(A, B->id), kb = kin_apart(B, A->id);
        if (!over) {
            if ((!ka && kin_add(A, B->id) != 0) || (!kb && kin_add(B, A->id) != 0))
                return -1;
            born_drop(A, B->id);
            born_drop(B, A->id);
            return 0;
        }
        if (!ka && !kb) { /* (a piece inherits its parent's list, not its kin) */
            /* mass-spring pieces take none: a contact impulse turned a small one inside out
             * (its cube has zero energy in its mirror image) */
            if (A->model == CS_MODEL_MSS || B->model == CS_MODEL_MSS)
                return 0;
            born = true;
        }
    }
    if (!over)
        return 0;
    if (soft_prepare(w, rw, A, true) != 0)
        return -1;
    cs_soft_resp *SA = rw->cur;
    if (soft_prepare(w, rw, B, true) != 0)
        return -1;
    cs_soft_resp *SB = rw->cur;
    SA->two_level = SB->two_level = true;
    if (born) {
        if (born_contacts(rw, dt, v_rest, A, B, SA, SB, olo, ohi, margin) != 0 ||
            born_contacts(rw, dt, v_rest, B, A, SB, SA, olo, ohi, margin) != 0)
            return -1;
    } else if (soft_nodes_in_cells(rw, A, B, SA, SB, olo, ohi, blo, bhi, margin) != 0 ||
               soft_nodes_in_cells(rw, B, A, SB, SA, olo, ohi, alo, ahi, margin) != 0) {
        return -1;
    }
    return 0;
}

/* Append pair (i, j) to rw->cand. */
static int push_cand(cs_rigid_world *rw, int i, int j)
{
    return cs_pair_push(&rw->cand, &rw->n_cand, &rw->cap_cand, i, j);
}

/* Orders object indices by kin, then index (soft_candidates). */
static int cmp_kin(const void *x, const void *y, void *ctx)
{
    const cs_world_t *w = ctx;
    const int a = *(const int *)x, b = *(const int *)y;
    const cs_object_id ka = w->objects[a]->kin, kb = w->objects[b]->kin;
    if (ka != kb)
        return ka < kb ? -1 : 1;
    return (a > b) - (a < b);
}

/* Room in rw->gbox and rw->kord for n objects. */
static int gbox_room(cs_rigid_world *rw, int n)
{
    if (n <= rw->cap_gbox)
        return 0;
    double *g = realloc(rw->gbox, (size_t)n * 6 * sizeof *g);
    if (g)
        rw->gbox = g;
    int *k = g ? realloc(rw->kord, (size_t)n * sizeof *k) : NULL;
    if (!k)
        return -1;
    rw->kord = k;
    rw->cap_gbox = n;
    return 0;
}

/*
 * Box i of rw->sbox grown by grow on every side into rw->gbox (for the broad phase), with
 * room for the rounding of the tests it stands for: 1e-9 of its coordinates' size, far above
 * the few units in the last place those tests' sums can differ by. False (and a NaN box) if
 * the grown box is not finite.
 */
static bool grown_box(cs_rigid_world *rw, int i, double grow)
{
    const double *s = rw->sbox + 7 * i;
    double *g = rw->gbox + 6 * i;
    for (int a = 0; a < 3; a++) {
        const double slack = 1e-9 * (fabs(s[a]) + fabs(s[3 + a]) + grow);
        g[a] = s[a] - grow - slack;
        g[3 + a] = s[3 + a] + grow + slack;
        if (!isfinite(g[a]) || !isfinite(g[3 + a])) {
            g[0] = NAN;
            return false;
        }
    }
    return true;
}

/*
 * The pairs i < j soft_pair has anything to do for, into rw->cand in (i, j) order, the order
 * all pairs were taken in before (their impulses are applied in turn, so the order is part of
 * the result): those whose boxes may overlap, found by the broad phase (broadphase.h) on each
 * object's box grown by 2 dt v + 0.1 h (soft_pair's test grows both boxes by
 * dt (va + vb) + 0.05 min(ha, hb), so the sum of the two growths covers it); every pair of
 * an object whose box or speed is not finite (soft_pair's own test decides those); and the
 * pairs of kin that soft_pair records as apart or whose born pairs it drops, when their boxes
 * are apart (each kin, a fracture's pieces, with each other: as many as before). Returns 0,
 * or -1 when out of memory.
 */
static int soft_candidates(cs_world_t *w, cs_rigid_world *rw)
{
    const int n = w->n_objects;
    const double dt = w->def.dt;
    rw->n_cand = 0;
    if (gbox_room(rw, n) != 0)
        return -1;
    int n_part = 0;
    for (int i = 0; i < n; i++) {
        const cs_object *o = w->objects[i];
        if (!soft_takes_part(o)) {
            rw->gbox[6 * i] = NAN;
            continue;
        }
        rw->kord[n_part++] = i;
        if (grown_box(rw, i, 2 * dt * rw->sbox[7 * i + 6] + 0.1 * o->cm.h))
            continue;
        for (int j = 0; j < n; j++) /* not finite */
            if (j != i && soft_takes_part(w->objects[j]) && push_cand(rw, i, j) != 0)
                return -1;
    }
    if (cs_bp_find(&rw->bp, rw->gbox, 6, n) != 0)
        return -1;
    for (int k = 0; k < rw->bp.n_pairs; k++)
        if (push_cand(rw, rw->bp.pairs[2 * k], rw->bp.pairs[2 * k + 1]) != 0)
            return -1;
    if (n_part > 0)
        qsort_r(rw->kord, (size_t)n_part, sizeof *rw->kord, cmp_kin, w);
    for (int g0 = 0, g1; g0 < n_part; g0 = g1) {
        const cs_object_id kin = w->objects[rw->kord[g0]]->kin;
        for (g1 = g0 + 1; g1 < n_part && w->objects[rw->kord[g1]]->kin == kin; g1++)
            ;
        for (int p = g0; p < g1; p++)
            for (int q = p + 1; q < g1; q++) {
                cs_object *A = w->objects[rw->kord[p]], *B = w->objects[rw->kord[q]];
                if (A->sleeping && B->sleeping)
                    continue;
                if ((!kin_apart(A, B->id) || !kin_apart(B, A->id) || born_find(A, B->id) ||
                     born_find(B, A->id)) &&
                    push_cand(rw, rw->kord[p], rw->kord[q]) != 0)
                    return -1;
            }
    }
    if (rw->n_cand > 0) /* (cand is NULL until the first pair: qsort's pointer must not be) */
        qsort(rw->cand, (size_t)rw->n_cand, 2 * sizeof *rw->cand, cs_pair_cmp);
    int m = 0;
    for (int k = 0; k < rw->n_cand; k++) {
        if (m > 0 && rw->cand[2 * k] == rw->cand[2 * m - 2] &&
            rw->cand[2 * k + 1] == rw->cand[2 * m - 1])
            continue;
        rw->cand[2 * m] = rw->cand[2 * k];
        rw->cand[2 * m + 1] = rw->cand[2 * k + 1];
        m++;
    }
    rw->n_cand = m;
    return 0;
}

/*
 * Contacts between deformable objects, once per step after the rigid bodies' (the same
 * sequential impulses, their own solve): only pairs whose boxes, grown by the distance they can
 * close in a step, overlap, and not both asleep (soft_pair, for the pairs soft_candidates
 * finds, in (i, j) order); each object's nodes in the overlap against the other's cells.
 * Returns CS_OK or CS_ERR_NOMEM.
 */
static int soft_contacts(cs_world_t *w, cs_rigid_world *rw, cs_step_stats *st)
{
    const double t0 = now_ms();
    const double dt = w->def.dt;
    /* the approach that is an impact, not resting contact (restitution's threshold below) */
    const double v_rest = 2 * cs_vec3_norm(w->def.gravity) * dt + 1e-3;
    rw->nsc = 0;
    rw->pending = false;
    int soft = 0;
    for (int i = 0; i < w->n_objects; i++) {
        soft += w->objects[i]->model != CS_MODEL_RIGID;
        w->objects[i]->contact_seen = true;
    }
    if (soft < 2)
        return CS_OK;
    if (sbox_room(rw, w->n_objects) != 0)
        return CS_ERR_NOMEM;
    for (int i = 0; i < w->n_objects; i++) {
        const cs_object *o = w->objects[i];
        if (o->model != CS_MODEL_RIGID && o->n > 0)
            object_box(o, rw->sbox + 7 * i, rw->sbox + 7 * i + 3, rw->sbox + 7 * i + 6);
    }
    if (w->object_pairs_all) { /* (tests: every pair, as before the broad phase) */
        for (int i = 0; i < w->n_objects; i++)
            for (int j = i + 1; j < w->n_objects; j++)
                if (soft_pair(w, rw, i, j, v_rest) != 0)
                    return CS_ERR_NOMEM;
    } else {
        if (soft_candidates(w, rw) != 0)
            return CS_ERR_NOMEM;
        for (int k = 0; k < rw->n_cand; k++)
            if (soft_pair(w, rw, rw->cand[2 * k], rw->cand[2 * k + 1], v_rest) != 0)
                return CS_ERR_NOMEM;
    }
    if (rw->nsc == 0)
        return CS_OK;
    /* held objects against held objects: their modes or, when small, their exact response
     * (contact_soft.h). (A held object under a free one keeps its blocks: the free one's
     * rigid modes carry the exchange, and the modes' two solves a step made a soft block
     * resting on a held slab 1.7-3.3x dearer.) An object answering exactly answers every
     * contact it has by S, so every contact's nodes join its list, its contacts with free
     * objects too: the exact response ignores an impulse on a node not in the list, and until
     * session 36 a small held piece touching a held sibling and a free block dropped the
     * block's impulses on its side (no momentum, no compliance: the block rested on a rigid
     * piece, which never felt its weight; test contact_born_exact_piece_feels_a_block_on_it). */
    for (int k = 0; k < rw->nsc; k++) {
        soft_contact *c = &rw->sc[k];
        if (cs_soft_is_held(c->SA) && cs_soft_is_held(c->SB) &&
            (cs_soft_exact_begin(c->SA) < 0 || cs_soft_exact_begin(c->SB) < 0))
            return CS_ERR_NOMEM;
    }
    for (int k = 0; k < rw->nsc; k++) {
        soft_contact *c = &rw->sc[k];
        if ((c->SA->exact_open && cs_soft_exact_add(c->SA, &c->node, ONE, 1) != 0) ||
            (c->SB->exact_open && cs_soft_exact_add(c->SB, c->bn, c->bw, 4) != 0))
            return CS_ERR_NOMEM;
        const bool xa = c->SA->exact_open || c->SA->exact, xb = c->SB->exact_open || c->SB->exact;
        if (!cs_soft_is_held(c->SA) || !cs_soft_is_held(c->SB))
            continue;
        const double mn[3] = {-c->n[0], -c->n[1], -c->n[2]};
        const int ra = xa ? 0 : cs_soft_modes_begin(c->SA), rb = xb ? 0 : cs_soft_modes_begin(c->SB);
        if (ra < 0 || rb < 0)
            return CS_ERR_NOMEM;
        if (ra)
            cs_soft_modes_add(c->SA, &c->node, ONE, 1, c->n);
        if (rb)
            cs_soft_modes_add(c->SB, c->bn, c->bw, 4, mn);
    }
    for (int k = 0; k < rw->nsc; k++)
        if (cs_soft_exact_solve(rw->sc[k].SA) != 0 || cs_soft_exact_solve(rw->sc[k].SB) != 0 ||
            cs_soft_modes_solve(rw->sc[k].SA) != 0 || cs_soft_modes_solve(rw->sc[k].SB) != 0)
            return CS_ERR_NOMEM;
    /* prepare: arms, tangents, effective masses, target normal velocities */
    const double v_bounce = v_rest;
    for (int k = 0; k < rw->nsc; k++) {
        soft_contact *c = &rw->sc[k];
        cs_soft_arm(c->SA, &c->node, ONE, 1, c->ra);
        cs_soft_arm(c->SB, c->bn, c->bw, 4, c->rb);
        tangents(c->n, c->t1, c->t2);
        c->kn = soft_eff_mass(c, c->n);
        c->kt1 = soft_eff_mass(c, c->t1);
        c->kt2 = soft_eff_mass(c, c->t2);
        double vr[3];
        soft_rel_velocity(c, vr);
        const double vn0 = cs_vec3_dot(vr, c->n), slop = 0.01 * c->hB;
        c->target = c->sep > 0 ? -c->sep / dt
                               : BAUMGARTE * fmin(fmax(0, -c->sep - slop), 0.1 * c->hB) / dt;
        /* an impact is judged on the approach the objects have now (their velocities after
         * their steps), not the predicted one: a compressed block's nodes springing up in
         * the prediction under a block resting on it are no impact. Between two implicit
         * objects free along it the bounce is the pair's (pair_restitution); otherwise
         * restitution reverses the node's approach (pair_approach). */
        const double vn_now = soft_now_normal(c);
        if (vn_now < -v_bounce && vn0 * dt < -c->sep)
            c->vimp = vn_now; /* (pair_approach turns it into a target or the pair's) */
    }
    pair_approach(rw);
    for (int it = 0; it < PGS_ITERATIONS; it++)
        for (int k = 0; k < rw->nsc; k++) {
            soft_contact *c = &rw->sc[k];
            if (c->kn == 0)
                continue;
            double vr[3], J[3];
            soft_rel_velocity(c, vr);
            double dj = (c->target - cs_vec3_dot(vr, c->n)) * c->kn;
            const double jn = fmax(0, c->jn + dj);
            dj = jn - c->jn;
            c->jn = jn;
            for (int a = 0; a < 3; a++)
                J[a] = dj * c->n[a];
            soft_impulse(c, J);
            soft_rel_velocity(c, vr);
            const double lim = c->mu * c->jn;
            double *jt[2] = {&c->jt1, &c->jt2};
            const double *t[2] = {c->t1, c->t2}, kt[2] = {c->kt1, c->kt2};
            for (int s = 0; s < 2; s++) {
                double d = -cs_vec3_dot(vr, t[s]) * kt[s];
                const double nj = fmin(lim, fmax(-lim, *jt[s] + d));
                d = nj - *jt[s];
                *jt[s] = nj;
                for (int a = 0; a < 3; a++)
                    J[a] = d * t[s][a];
                soft_impulse(c, J);
            }
        }
    pair_restitution(rw, v_bounce);
    /* left on the node velocities until the next step shares them out */
    if (rw->cap_sc_version < 2 * rw->nsc) {
        uint32_t *g = realloc(rw->sc_version, (size_t)rw->nsc * 2 * sizeof *g);
        if (!g)
            return CS_ERR_NOMEM;
        rw->sc_version = g;
        rw->cap_sc_version = 2 * rw->nsc;
    }
    for (int k = 0; k < rw->nsc; k++) {
        rw->sc_version[2 * k] = rw->sc[k].SA->D->topology_version;
        rw->sc_version[2 * k + 1] = rw->sc[k].SB->D->topology_version;
    }
    rw->pending = true;
    rw->pending_frame = w->frame;
    /* the objects pushed wake; their energies follow the velocities they now have.
     * Newmark objects with a contact, pushing or not, take their next step by implicit Euler:
     * the step the solve modelled (a speculative contact that did not push trusts that
     * prediction; Newmark's own step after an impact went 13 mm into the other block) */
    for (int k = 0; k < rw->nsc; k++) {
        const soft_contact *c = &rw->sc[k];
        cs_object *o[2] = {c->SA->D, c->SB->D};
        for (int s = 0; s < 2; s++) {
            o[s]->contact_pushed = true;
            if (c->jn <= 0)
                continue;
            if (o[s]->sleeping) {
                o[s]->sleeping = false;
                o[s]->still_steps = 0;
            }
            o[s]->elastic_energy_valid = false;
        }
    }
    /* Objects pressing on each other sleep together: each takes the fewest still steps of
     * the objects its pushing contacts join it to (relaxed over the contacts until no count
     * changes), so they reach sleep_steps in the same step or not at all, and one that moves
     * restarts the count of all. (Every push restarted both counts, so soft objects resting
     * on each other never slept; one asleep alone would have left the other's contacts
     * against a body that is not stepped.) */
    for (bool changed = true; changed;) {
        changed = false;
        for (int k = 0; k < rw->nsc; k++) {
            const soft_contact *c = &rw->sc[k];
            cs_object *a = c->SA->D, *b = c->SB->D;
            if (c->jn <= 0 || a->still_steps == b->still_steps)
                continue;
            a->still_steps = b->still_steps =
                a->still_steps < b->still_steps ? a->still_steps : b->still_steps;
            changed = true;
        }
    }
    st->ms_solve += now_ms() - t0;
    return CS_OK;
}

/* ---------------------------------------------------------------- impact fracture */

typedef struct relief_ctx {
    cs_object *o;
    double eps;
} relief_ctx;

static void relief_operator(void *ctx, const double *p, double *y)
{
    relief_ctx *r = ctx;
    cs_fem_apply_K(&r->o->fem, p, y);
    for (int i = 0; i < r->o->n; i++)
        for (int a = 0; a < 3; a++)
            y[3 * i + a] += r->eps * r->o->m[i] * p[3 * i + a];
}

/* Add world force F at contact point p to the node loads f of body o (the node itself, or
 * the corners of cell by trilinear weights of p in it). */
static void add_load(const cs_object *o, double *f, int32_t node, int32_t cell, const double p[3],
                     const double F[3])
{
    if (node >= 0) {
        for (int a = 0; a < 3; a++)
            f[3 * (size_t)node + a] += F[a];
        return;
    }
    if (cell < 0)
        return;
    const cs_rigid *rb = o->rb;
    double d[3], X[3], u[3];
    for (int a = 0; a < 3; a++)
        d[a] = p[a] - rb->c[a];
    cs_mat3_t_vec(rb->R, d, X);
    for (int a = 0; a < 3; a++) {
        u[a] = (X[a] + rb->com_rest[a] - o->cm.origin[a]) / o->cm.h - o->cm.cell_ijk[3 * (size_t)cell + a];
        u[a] = fmin(1, fmax(0, u[a]));
    }
    for (int k = 0; k < 8; k++) {
        const double wk = (CS_CORNER[k][0] ? u[0] : 1 - u[0]) * (CS_CORNER[k][1] ? u[1] : 1 - u[1]) *
                          (CS_CORNER[k][2] ? u[2] : 1 - u[2]);
        const int32_t nd = o->cm.cell_nodes[8 * (size_t)cell + k];
        for (int a = 0; a < 3; a++)
            f[3 * (size_t)nd + a] += wk * F[a];
    }
}

/*
 * Static deformation of body bi under this step's contact forces (inertia relief), then the
 * stress test and fracture of fracture.c; pieces become rigid bodies. Returns CS_OK or an
 * error.
 */
static int impact_fracture(cs_world_t *w, cs_rigid_world *rw, int bi, cs_step_stats *st)
{
    cs_object *o = rw->body[bi];
    cs_rigid *rb = o->rb;
    const int n = o->n;
    const size_t n3 = 3 * (size_t)n;
    const double dt = w->rigid->dt;
    double *f = o->f, *u = o->v1;
    memset(f, 0, n3 * sizeof *f);
    for (int i = 0; i < rw->nc; i++) {
        const contact *c = &rw->c[i];
        if (c->a != bi && c->b != bi)
            continue;
        double F[3];
        for (int a = 0; a < 3; a++)
            F[a] = (c->jn * c->n[a] + c->jt1 * c->t1[a] + c->jt2 * c->t2[a]) / dt *
                   (c->a == bi ? 1 : -1);
        if (c->a == bi)
            add_load(o, f, c->node_a, c->cell_a, c->p, F);
        else
            add_load(o, f, c->node_b, c->cell_b, c->p, F);
    }
    /* body axes; minus the rigid acceleration the loads cause (inertia relief) */
    double Ft[3] = {0, 0, 0}, tau[3] = {0, 0, 0};
    for (int i = 0; i < n; i++) {
        double fb[3], d[3], t[3];
        cs_mat3_t_vec(rb->R, f + 3 * (size_t)i, fb);
        memcpy(f + 3 * (size_t)i, fb, sizeof fb);
        for (int a = 0; a < 3; a++)
            d[a] = o->cm.node_rest[3 * (size_t)i + a] - rb->com_rest[a];
        cs_vec3_cross(d, fb, t);
        for (int a = 0; a < 3; a++) {
            Ft[a] += fb[a];
            tau[a] += t[a];
        }
    }
    /* with the lumped node masses (their sum is the mass, their centre the centre of mass,
     * but their inertia is not the cubes'), so that the loads balance exactly */
    double Il[9] = {0}, Il_adj[9], acc[3], alpha[3];
    for (int i = 0; i < n; i++) {
        double d[3];
        for (int a = 0; a < 3; a++)
            d[a] = o->cm.node_rest[3 * (size_t)i + a] - rb->com_rest[a];
        const double dd = cs_vec3_dot(d, d);
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 3; c++)
                Il[3 * r + c] += o->m[i] * ((r == c) * dd - d[r] * d[c]);
    }
    const double il_det = cs_mat3_adjugate(Il, Il_adj);
    cs_mat3_vec(Il_adj, tau, alpha);
    for (int a = 0; a < 3; a++) {
        alpha[a] /= il_det;
        acc[a] = Ft[a] * rb->inv_mass;
    }
    for (int i = 0; i < n; i++) {
        double d[3], axd[3];
        for (int a = 0; a < 3; a++)
            d[a] = o->cm.node_rest[3 * (size_t)i + a] - rb->com_rest[a];
        cs_vec3_cross(alpha, d, axd);
        for (int a = 0; a < 3; a++)
            f[3 * (size_t)i + a] -= o->m[i] * (acc[a] + axd[a]);
    }
    /* (K + εM) u = f, linear (rest rotations); ε makes the rigid modes definite */
    cs_fem_reset_rotations(&o->fem);
    cs_fem_diag_blocks(&o->fem, o->blocks);
    double kd = 0, md = 0;
    for (int i = 0; i < n; i++) {
        kd += o->blocks[9 * (size_t)i] + o->blocks[9 * (size_t)i + 4] + o->blocks[9 * (size_t)i + 8];
        md += 3 * o->m[i];
    }
    relief_ctx ctx = {.o = o, .eps = 1e-6 * kd / md};
    for (int i = 0; i < n; i++)
        for (int a = 0; a < 3; a++)
            o->blocks[9 * (size_t)i + 4 * a] += ctx.eps * o->m[i];
    cs_invert_blocks(o->blocks, n);
    memset(u, 0, n3 * sizeof *u);
    const cs_cg_result cg =
        cs_pcg(&o->cg, relief_operator, &ctx, o->blocks, o->mask, f, u,
               fmax(w->def.cg_tolerance, IMPACT_CG_TOL), IMPACT_CG_MAX, cs_elastic_threads(o));
    st->cg_iterations += cg.iterations;
    st->cg_residual = fmax(st->cg_residual, cg.relres);
    if (!finite_n(u, (int)n3)) {
        place_nodes(o);
        return CS_OK;
    }
    /* remove what is left of the rigid modes (mass-weighted translation and rotation) */
    {
        double t[3] = {0, 0, 0}, L[3] = {0, 0, 0}, wv[3];
        for (int i = 0; i < n; i++) {
            double d[3], dxu[3];
            for (int a = 0; a < 3; a++) {
                d[a] = o->cm.node_rest[3 * (size_t)i + a] - rb->com_rest[a];
                t[a] += o->m[i] * u[3 * (size_t)i + a] * rb->inv_mass;
            }
            cs_vec3_cross(d, u + 3 * (size_t)i, dxu);
            for (int a = 0; a < 3; a++)
                L[a] += o->m[i] * dxu[a];
        }
        cs_mat3_vec(Il_adj, L, wv);
        for (int i = 0; i < n; i++) {
            double d[3], wxd[3];
            for (int a = 0; a < 3; a++)
                d[a] = o->cm.node_rest[3 * (size_t)i + a] - rb->com_rest[a];
            cs_vec3_cross(wv, d, wxd);
            for (int a = 0; a < 3; a++)
                u[3 * (size_t)i + a] -= t[a] + wxd[a] / il_det;
        }
    }
    for (int i = 0; i < n; i++) {
        double d[3], r[3];
        for (int a = 0; a < 3; a++)
            d[a] = o->cm.node_rest[3 * (size_t)i + a] - rb->com_rest[a] + u[3 * (size_t)i + a];
        cs_mat3_vec(rb->R, d, r);
        for (int a = 0; a < 3; a++)
            o->x[3 * (size_t)i + a] = rb->c[a] + r[a];
    }
    /* the pose and motion before the split: every piece continues it */
    double q[4], c0[3], C0[3], v0[3], w0[3];
    memcpy(q, rb->q, sizeof q);
    memcpy(c0, rb->c, sizeof c0);
    memcpy(C0, rb->com_rest, sizeof C0);
    memcpy(v0, rb->v, sizeof v0);
    memcpy(w0, rb->w, sizeof w0);
    int rc = cs_fracture_after_step(w, o);
    /* o's nodes may have been duplicated and its cells reduced; pieces carry a copy of its
     * pose (make_piece): every part gets its mass properties and continues the motion. o is
     * refitted even if nothing changed, to undo the static deformation. */
    if (cs_rigid_refit(o, q, c0, C0, v0, w0) != 0 || cs_rigid_sync(w) != CS_OK)
        return CS_ERR_NOMEM;
    return rc;
}

/* ---------------------------------------------------------------- the step */

static int cmp_aabb_x(const void *x, const void *y, void *ctx)
{
    const cs_rigid_world *rw = ctx;
    const double a = rw->body[*(const int *)x]->rb->aabb_min[0];
    const double b = rw->body[*(const int *)y]->rb->aabb_min[0];
    return a < b ? -1 : a > b;
}

static int island_find(int *p, int x)
{
    while (p[x] != x) {
        p[x] = p[p[x]];
        x = p[x];
    }
    return x;
}

static int gather_bodies(cs_world_t *w, cs_rigid_world *rw)
{
    rw->n_body = 0;
    rw->nc = 0;
    for (int i = 0; i < w->n_objects; i++) {
        cs_object *o = w->objects[i];
        if (o->model != CS_MODEL_RIGID || !o->rb)
            continue;
        if (rw->n_body == rw->cap_body) {
            int cap = rw->cap_body ? 2 * rw->cap_body : 16;
            cs_object **b = realloc(rw->body, (size_t)cap * sizeof *b);
            int *ord = b ? realloc(rw->order, (size_t)cap * sizeof *ord) : NULL;
            if (b)
                rw->body = b;
            if (ord)
                rw->order = ord;
            uint8_t *dy = ord ? realloc(rw->dyn, (size_t)cap) : NULL;
            if (dy)
                rw->dyn = dy;
            int *isl = dy ? realloc(rw->island, (size_t)cap * sizeof *isl) : NULL;
            if (isl)
                rw->island = isl;
            int *ist = isl ? realloc(rw->island_still, (size_t)cap * sizeof *ist) : NULL;
            if (ist)
                rw->island_still = ist;
            int *bc = ist ? realloc(rw->bounce_c, (size_t)cap * sizeof *bc) : NULL;
            if (!bc)
                return -1;
            rw->bounce_c = bc;
            rw->cap_body = cap;
        }
        rw->body[rw->n_body++] = o;
    }
    return 0;
}

/* One substep of rw->dt for every rigid body; `last` ends the frame (sleep, inputs). */
static int substep(cs_world_t *w, cs_rigid_world *rw, bool last, cs_step_stats *st)
{
    const double t0 = now_ms();
    if (gather_bodies(w, rw) != 0)
        return CS_ERR_NOMEM;
    if (rw->n_body == 0)
        return CS_OK;
    const int n_objects = w->n_objects;
    const double dt = rw->dt;
    int rc = CS_OK;
    /* 1. forces */
    for (int i = 0; i < rw->n_body; i++) {
        cs_object *o = rw->body[i];
        cs_rigid *rb = o->rb;
        rw->dyn[i] = !o->sleeping && o->n_fixed_nodes == 0;
        rb->impact_force = 0;
        memcpy(rb->v_pre, rb->v, sizeof rb->v);
        memcpy(rb->w_pre, rb->w, sizeof rb->w);
        if (!rw->dyn[i])
            continue;
        apply_inputs(w, o);
        node_aabb(o, body_margin(o, dt));
    }
    /* 2. sort-and-sweep over the bodies' boxes. A sleeping body that a moving one may reach
     * this step wakes now, so that the collision exchanges momentum with it (were it fixed
     * for this step, the mover would bounce off it as off a wall). Moving: faster than
     * twice the sleep speed before this step's forces, or under an input (a box pushed from
     * rest with a sleeping box on it was held by that box as by a wall: it never moved). */
    for (int i = 0; i < rw->n_body; i++)
        rw->order[i] = i;
    if (rw->n_body > 1)
        qsort_r(rw->order, (size_t)rw->n_body, sizeof *rw->order, cmp_aabb_x, rw);
    for (int s = 0; s < rw->n_body; s++) {
        const int ia = rw->order[s];
        for (int t = s + 1; t < rw->n_body; t++) {
            const int ib = rw->order[t];
            const cs_rigid *a = rw->body[ia]->rb, *b = rw->body[ib]->rb;
            if (b->aabb_min[0] > a->aabb_max[0])
                break;
            if (rw->dyn[ia] == rw->dyn[ib] || b->aabb_min[1] > a->aabb_max[1] ||
                b->aabb_max[1] < a->aabb_min[1] || b->aabb_min[2] > a->aabb_max[2] ||
                b->aabb_max[2] < a->aabb_min[2])
                continue;
            const int mv = rw->dyn[ia] ? ia : ib, sl = rw->dyn[ia] ? ib : ia;
            const cs_rigid *m = rw->body[mv]->rb;
            cs_object *o = rw->body[sl];
            if (!o->sleeping || o->n_fixed_nodes > 0 ||
                (rw->body[mv]->n_inputs == 0 &&
                 cs_vec3_norm(m->v_pre) + cs_vec3_norm(m->w_pre) * m->radius <=
                     2 * w->def.sleep_speed))
                continue;
            o->sleeping = false;
            o->still_steps = 0;
            rw->dyn[sl] = 1;
            apply_inputs(w, o);
            node_aabb(o, body_margin(o, dt));
        }
    }
    /* 3. contacts: ground, then the overlapping pairs */
    for (int i = 0; i < rw->n_body && w->def.has_ground; i++)
        if (rw->dyn[i] && ground_contacts(w, rw, i) != 0)
            return CS_ERR_NOMEM;
    for (int s = 0; s < rw->n_body; s++) {
        const int ia = rw->order[s];
        const cs_rigid *a = rw->body[ia]->rb;
        for (int t = s + 1; t < rw->n_body; t++) {
            const int ib = rw->order[t];
            const cs_rigid *b = rw->body[ib]->rb;
            if (b->aabb_min[0] > a->aabb_max[0])
                break;
            if ((!rw->dyn[ia] && !rw->dyn[ib]) || b->aabb_min[1] > a->aabb_max[1] ||
                b->aabb_max[1] < a->aabb_min[1] || b->aabb_min[2] > a->aabb_max[2] ||
                b->aabb_max[2] < a->aabb_min[2])
                continue;
            if (body_pair(w, rw, ia, ib) != 0)
                return CS_ERR_NOMEM;
        }
    }
    if (cell_contacts(w, rw, n_objects) != 0 || deformable_contacts(w, rw, n_objects) != 0)
        return CS_ERR_NOMEM;
    /* contacts whose normal must point towards a dynamic body: swap so that a is dynamic */
    for (int i = 0; i < rw->nc; i++) {
        contact *c = &rw->c[i];
        if (c->b >= 0 && !rw->dyn[c->a]) {
            int t = c->a;
            c->a = c->b;
            c->b = t;
            int32_t tn = c->node_a, tc = c->cell_a;
            c->node_a = c->node_b;
            c->cell_a = c->cell_b;
            c->node_b = tn;
            c->cell_b = tc;
            for (int a = 0; a < 3; a++)
                c->n[a] = -c->n[a];
        }
    }
    const double t1 = now_ms();
    prepare_contacts(w, rw);
    warm_start(rw);
    solve_contacts(rw);
    if (keep_impulses(rw) != 0)
        return CS_ERR_NOMEM;
    for (int i = 0; i < rw->nc; i++) {
        const contact *c = &rw->c[i];
        const double J = sqrt(c->jn * c->jn + c->jt1 * c->jt1 + c->jt2 * c->jt2) / dt;
        rw->body[c->a]->rb->impact_force += J;
        if (c->b >= 0)
            rw->body[c->b]->rb->impact_force += J;
    }
    bounce_positions(w, rw);
    cell_contacts_done(rw);
    const double t2 = now_ms();
    /* 4. poses, nodes, sleep */
    for (int i = 0; i < rw->n_body; i++) {
        cs_object *o = rw->body[i];
        cs_rigid *rb = o->rb;
        if (!rw->dyn[i]) {
            if (last)
                expire(o);
            continue;
        }
        if (!finite_n(rb->v, 3) || !finite_n(rb->w, 3) ||
            cs_vec3_norm(rb->v) > MAX_SPEED ||
            cs_vec3_norm(rb->w) * rb->radius > MAX_SPEED) {
            memset(rb->v, 0, sizeof rb->v);
            memset(rb->w, 0, sizeof rb->w);
            o->n_inputs = 0;
            place_nodes(o);
            rc = CS_ERR_DIVERGED;
            continue;
        }
        for (int a = 0; a < 3; a++)
            rb->c[a] += dt * rb->v[a];
        rotate(rb, dt);
        place_nodes(o);
        node_aabb(o, 0);
        if (!last)
            continue;
        expire(o);
        const double speed = cs_vec3_norm(rb->v) + cs_vec3_norm(rb->w) * rb->radius;
        if (w->def.sleep_steps > 0 && o->n_inputs == 0 && speed < w->def.sleep_speed) {
            o->still_steps++;
        } else {
            o->still_steps = 0;
        }
        st->objects_stepped++;
    }
    /* sleep by islands: bodies resting on each other fall asleep together (one alone would
     * drop its support from the solve and start the others creeping) */
    for (int i = 0; i < rw->n_body; i++) {
        rw->island[i] = i;
        rw->island_still[i] = 1 << 30;
    }
    for (int i = 0; i < rw->nc; i++) {
        const contact *c = &rw->c[i];
        if (c->b >= 0 && rw->dyn[c->a] && rw->dyn[c->b])
            rw->island[island_find(rw->island, c->a)] = island_find(rw->island, c->b);
    }
    for (int i = 0; i < rw->n_body; i++)
        if (rw->dyn[i]) {
            int r = island_find(rw->island, i);
            if (rw->body[i]->still_steps < rw->island_still[r])
                rw->island_still[r] = rw->body[i]->still_steps;
        }
    for (int i = 0; i < rw->n_body && w->def.sleep_steps > 0 && last; i++) {
        cs_object *o = rw->body[i];
        if (!rw->dyn[i] || rw->island_still[island_find(rw->island, i)] < w->def.sleep_steps)
            continue;
        o->sleeping = true;
        memset(o->rb->v, 0, sizeof o->rb->v);
        memset(o->rb->w, 0, sizeof o->rb->w);
        memset(o->v, 0, (size_t)o->n * 3 * sizeof(double));
    }
    const double t3 = now_ms();
    /* 5. impact fracture */
    const double gn = cs_vec3_norm(w->def.gravity);
    const int n_body = rw->n_body;
    for (int i = 0; i < n_body; i++) {
        cs_object *o = rw->body[i];
        const double h = o->cm.h;
        if (!o->fracture || o->cm.n_cells < 2 || !(o->mat.strength < 1e299) ||
            o->rb->impact_force <= fmax(o->mat.strength * h * h, 2 * o->rb->mass * gn))
            continue;
        int r = impact_fracture(w, rw, i, st);
        if (r != CS_OK && rc == CS_OK)
            rc = r;
    }
    const double t4 = now_ms();
    st->ms_inputs += t1 - t0;
    st->ms_solve += t2 - t1;
    st->ms_post += t4 - t3;
    st->ms_skin += t3 - t2;
    return rc;
}

/* Sleeping object s wakes if mover m may reach it (wake_near_movers; their boxes and speeds
 * in rw->sbox, the speed −1 for an object taking no part, 0 for a sleeping one). */
static void wake_pair(cs_world_t *w, cs_rigid_world *rw, int m, int s)
{
    const double dt = w->def.dt;
    const cs_object *M = w->objects[m];
    const double *mb = rw->sbox + 7 * m;
    if (mb[6] <= 0)
        return;
    cs_object *S = w->objects[s];
    const double *sb = rw->sbox + 7 * s;
    if (!S->sleeping || sb[6] < 0 || S->n_fixed_nodes == S->n ||
        (M->model == CS_MODEL_RIGID && S->model == CS_MODEL_RIGID))
        return;
    const double g = dt * mb[6] + 0.05 * fmin(M->cm.h, S->cm.h);
    bool near = true;
    for (int a = 0; a < 3; a++)
        near = near && mb[a] - g <= sb[3 + a] && mb[3 + a] + g >= sb[a];
    if (!near)
        return;
    S->sleeping = false;
    S->still_steps = 0;
}

/*
 * A sleeping object that a moving neighbour may leave or reach wakes, when one of the two is
 * deformable (rigid pairs: substep's sort-and-sweep). Contacts only wake what they push, so a
 * box asleep on a soft block that was then dragged away stayed in the air, and so did a soft
 * block asleep on anything that moved out from under it. Moving: a node faster than twice the
 * sleep speed; near: the two boxes of nodes, the mover's grown by how far it goes in the step
 * and 5 % of the smaller cube edge, overlap (wake_pair, for the pairs the broad phase finds).
 * Run after the deformable objects' steps, whose velocities are then their motion (after the
 * contact solve they also hold its impulses).
 */
static int wake_near_movers(cs_world_t *w, cs_rigid_world *rw)
{
    const double v_wake = 2 * w->def.sleep_speed, dt = w->def.dt;
    int asleep = 0, moving = 0;
    for (int i = 0; i < w->n_objects; i++)
        asleep += w->objects[i]->sleeping;
    if (asleep == 0 || asleep == w->n_objects)
        return CS_OK;
    if (sbox_room(rw, w->n_objects) != 0)
        return CS_ERR_NOMEM;
    for (int i = 0; i < w->n_objects; i++) {
        const cs_object *o = w->objects[i];
        double *b = rw->sbox + 7 * i;
        if (o->n == 0) {
            b[6] = -1; /* not taking part */
            continue;
        }
        object_box(o, b, b + 3, b + 6);
        if (o->sleeping)
            b[6] = 0;
        else if (o->n_fixed_nodes == o->n || b[6] <= v_wake)
            b[6] = -1;
        else
            moving++;
    }
    if (moving == 0)
        return CS_OK;
    if (w->object_pairs_all) { /* (tests: every pair, as before the broad phase) */
        for (int m = 0; m < w->n_objects; m++)
            for (int s = 0; s < w->n_objects; s++)
                wake_pair(w, rw, m, s);
        return CS_OK;
    }
    /* the broad phase on the movers' boxes grown by the most wake_pair grows them, and the
     * sleepers' as they are (which of them wake does not depend on the order) */
    if (gbox_room(rw, w->n_objects) != 0)
        return CS_ERR_NOMEM;
    rw->n_cand = 0;
    for (int i = 0; i < w->n_objects; i++) {
        const cs_object *o = w->objects[i];
        const double *b = rw->sbox + 7 * i;
        const bool mover = !(b[6] <= 0);
        if (!mover && !(o->sleeping && b[6] >= 0 && o->n_fixed_nodes != o->n)) {
            rw->gbox[6 * i] = NAN;
            continue;
        }
        if (grown_box(rw, i, mover ? dt * b[6] + 0.05 * o->cm.h : 0))
            continue;
        for (int j = 0; j < w->n_objects; j++) /* not finite: wake_pair decides */
            if (j != i && push_cand(rw, i, j) != 0)
                return CS_ERR_NOMEM;
    }
    if (cs_bp_find(&rw->bp, rw->gbox, 6, w->n_objects) != 0)
        return CS_ERR_NOMEM;
    for (int k = 0; k < rw->bp.n_pairs; k++)
        if (push_cand(rw, rw->bp.pairs[2 * k], rw->bp.pairs[2 * k + 1]) != 0)
            return CS_ERR_NOMEM;
    for (int k = 0; k < rw->n_cand; k++) {
        wake_pair(w, rw, rw->cand[2 * k], rw->cand[2 * k + 1]);
        wake_pair(w, rw, rw->cand[2 * k + 1], rw->cand[2 * k]);
    }
    return CS_OK;
}

int cs_rigid_prestep(cs_world_t *w, cs_step_stats *st)
{
    int soft = 0;
    bool unseen = false;
    for (int i = 0; i < w->n_objects; i++) {
        const cs_object *o = w->objects[i];
        if (o->model == CS_MODEL_RIGID || o->n == 0 || o->cm.n_cells == 0)
            continue;
        soft++;
        unseen = unseen || !o->contact_seen;
    }
    if (soft < 2) {
        /* nothing to touch yet: seen as it is */
        for (int i = 0; i < w->n_objects; i++)
            w->objects[i]->contact_seen = true;
        return CS_OK;
    }
    if (!unseen)
        return CS_OK;
    if (!w->rigid && !(w->rigid = calloc(1, sizeof *w->rigid)))
        return CS_ERR_NOMEM;
    w->rigid->step++; /* the responses prepared by the last pass saw other velocities */
    for (int i = 0; i < w->n_objects; i++)
        if (!w->objects[i]->contact_seen && w->objects[i]->model != CS_MODEL_RIGID)
            cs_world_ground_predict(w, w->objects[i]);
    return soft_contacts(w, w->rigid, st);
}

/*
 * The frame is split into substeps so that no body moves more than its cube edge in one (at
 * most MAX_SUBSTEPS): contacts are speculative, so nothing passes through anything at any
 * speed; a bounce off a still surface is moved to its time of impact within the substep
 * (bounce_positions).
 */
int cs_rigid_step(cs_world_t *w, cs_step_stats *st)
{
    if (!w->rigid) {
        /* rigid bodies, or two deformable objects that may touch (soft_contacts) */
        int rigid = 0, soft = 0;
        for (int i = 0; i < w->n_objects; i++) {
            rigid += w->objects[i]->model == CS_MODEL_RIGID;
            soft += w->objects[i]->model != CS_MODEL_RIGID;
        }
        if (rigid == 0 && soft < 2)
            return CS_OK;
        if (!(w->rigid = calloc(1, sizeof *w->rigid)))
            return CS_ERR_NOMEM;
    }
    cs_rigid_world *rw = w->rigid;
    rw->step++; /* soft_resp records of earlier steps are stale */
    /* and those of objects no contact reached last step are dropped (removed objects, pieces
     * that broke off: their memory does not pile up) */
    int kept_soft = 0;
    for (int i = 0; i < rw->n_soft; i++) {
        if (rw->soft[i]->step + 1 >= rw->step) {
            rw->soft[kept_soft++] = rw->soft[i];
            continue;
        }
        cs_soft_free(rw->soft[i]);
        free(rw->soft[i]);
    }
    rw->n_soft = kept_soft;
    if (rw->cap_map > 0 && soft_map_build(rw, rw->cap_map) != 0)
        return CS_ERR_NOMEM;
    if (cs_rigid_sync(w) != CS_OK || wake_near_movers(w, rw) != CS_OK)
        return CS_ERR_NOMEM;
    const double dt = w->def.dt, gn = cs_vec3_norm(w->def.gravity);
    int n_sub = 1;
    for (int i = 0; i < w->n_objects; i++) {
        const cs_object *o = w->objects[i];
        if (o->model != CS_MODEL_RIGID || !o->rb || o->sleeping)
            continue;
        const cs_rigid *rb = o->rb;
        double travel = dt * (cs_vec3_norm(rb->v) + gn * dt +
                              cs_vec3_norm(rb->w) * rb->radius);
        for (int k = 0; k < o->n_inputs; k++)
            if (o->inputs[k].kind == CS_INPUT_FORCE)
                travel += dt * dt * cs_vec3_norm(o->inputs[k].force) *
                          rb->inv_mass;
        const double s = ceil(travel / o->cm.h - 1e-9);
        if (s > n_sub)
            n_sub = s > MAX_SUBSTEPS ? MAX_SUBSTEPS : (int)s;
    }
    rw->dt = dt / n_sub;
    int rc = CS_OK;
    for (int k = 0; k < n_sub; k++) {
        int r = substep(w, rw, k == n_sub - 1, st);
        if (r != CS_OK && rc == CS_OK)
            rc = r;
        if (r == CS_ERR_NOMEM)
            break;
    }
    if (rc != CS_ERR_NOMEM) {
        const int r = soft_contacts(w, rw, st);
        if (r != CS_OK && rc == CS_OK)
            rc = r;
    }
    return rc;
}
