/*
 * rigid.h — rigid bodies (seed 000 §2.4): objects of model CS_MODEL_RIGID and the pieces they
 * break into. Not part of the API.
 *
 * A rigid object keeps its cube mesh, nodes and surface like every object; its motion is the
 * pose (centre of mass c, unit quaternion q: rest frame → world) and the velocities (v, ω in
 * world axes). After every step its nodes are placed at x = c + R (X − C) and given the rigid
 * velocity field v + ω × (x − c), so readers, energies, the state hash and skinning are the
 * same as for deformable objects.
 *
 * All rigid objects of a world step together (cs_rigid_step): gravity and client inputs,
 * contacts (ground, rigid–rigid through libccd between cubes, two-way against deformable
 * objects: their nodes in rigid cubes, rigid nodes in their deformed cells) solved by
 * sequential impulses, then the pose update, sleeping and impact fracture.
 *
 * Owns: cs_rigid (through cs_object.rb) and cs_rigid_world (through cs_world.rigid).
 */
#ifndef CS_RIGID_H
#define CS_RIGID_H

#include "world_internal.h"

typedef struct cs_rigid {
    double mass, inv_mass;
    double com_rest[3];            /* C: centre of mass in the rest (lattice) frame */
    double I_body[9], I_body_inv[9]; /* inertia about C, rest-frame axes */
    double radius;                 /* max |X − C| over the nodes */
    int32_t ijk_lo[3], ijk_hi[3];  /* the cells' lattice bounds (the contact search's box) */
    double q[4];                   /* orientation, w x y z */
    double R[9];                   /* its matrix, row-major */
    double c[3];                   /* centre of mass, world */
    double v[3], w[3];             /* linear and angular velocity, world */
    double v_pre[3], w_pre[3];     /* the same before this step's forces (restitution) */
    double I_inv_world[9];         /* R I_body⁻¹ Rᵀ of the current pose */
    double aabb_min[3], aabb_max[3]; /* of the nodes, grown by the speculative margin */
    double impact_force;           /* Σ |contact impulse| / dt of the last step [N] */
    int n_cells, n_nodes;          /* of the object these were computed for */
    bool has_loads;                /* scene loads: forces from the nodes' f_const, else M g */
} cs_rigid;

/* Mass properties from o's cells (each a solid box of the material's density times the density
 * field: exact for the field trilinear in each cell through its Gauss-point factors) and the pose
 * at rest (R = I, c = C), at rest. Returns 0 or -1 (out of memory). */
int cs_rigid_init(cs_object *o);
/* Mass properties from o's (new) cells; the pose follows the rotation q and the rigid motion
 * (c0, C0, v0, w0) of the body o was part of: c = c0 + R (C − C0), v = v0 + w0 × (c − c0),
 * ω = w0. Replaces o->rb. Returns 0 or -1. */
int cs_rigid_refit(cs_object *o, const double q[4], const double c0[3], const double C0[3],
                   const double v0[3], const double w0[3]);
/* Frees what rigid.c keeps in o: its rigid body and its born-pair records (o->born). */
void cs_rigid_free(cs_object *o);
/* After the density field changed (painting): mass, centre of mass and inertia again, the
 * body keeping its pose of the old centre and its velocities (cs_rigid_refit). 0 or -1. */
int cs_rigid_fields_changed(cs_object *o);
/* A copy (for a piece made by fracture: it starts from its parent's pose and motion until
 * cs_rigid_sync fits it to its own cells). NULL if out of memory. */
cs_rigid *cs_rigid_clone(const cs_rigid *rb);
/* Refit every rigid object whose cells or nodes changed since its mass properties were
 * computed (fracture), continuing the motion it had. Returns CS_OK or CS_ERR_NOMEM. */
int cs_rigid_sync(cs_world_t *w);
/* Before a fracture between steps (cs_world_fracture, cs_world_cut_face): take back the
 * impulses the last deformable–deformable pass left on node velocities for the next step to
 * share out, if no step has shared them since. A fracture would hand a node's impulse, meant
 * for its whole object, to whichever piece gets the node (a single cube then flew off at up to
 * 271 m/s in the fracture storm); the next pass makes the contacts of the new pieces. */
void cs_rigid_drop_pending(cs_world_t *w);
/* Back to the rest pose, at rest. */
void cs_rigid_reset(cs_object *o);
/* Kinetic energy ½ m v² + ½ ωᵀ I ω. */
double cs_rigid_kinetic_energy(const cs_object *o);

/* Step every rigid object of w by one dt (with its contacts against deformable objects), then
 * the contacts between deformable objects (the deformable objects have stepped already).
 * Adds timings and counts to st. Returns CS_OK or the first error. */
int cs_rigid_step(cs_world_t *w, cs_step_stats *st);
/* Before the deformable objects step: the deformable–deformable contact pass that ends every
 * step (for the next one), if an object that may touch another has not been through one since
 * it was added or reset (contact_seen). Without it, objects placed touching or a few
 * millimetres apart stepped once without contact and started g dt² into each other (2.7 mm at
 * 60 Hz), of which the push-out left the slop, 1 % of a cube. Returns CS_OK or CS_ERR_NOMEM. */
int cs_rigid_prestep(cs_world_t *w, cs_step_stats *st);
void cs_rigid_world_free(cs_world_t *w);

#endif
