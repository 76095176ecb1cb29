/*
 * elastic.h — the element models behind one interface (DESIGN.md "Element models").
 *
 * Every object has a cube mesh, a lumped mass and an element model. The integrators in
 * world.c see the model only through these functions, so a model is added by giving each
 * of them a case. The FEM record (o->fem) exists for every model: fracture reads its
 * node → cell adjacency and its rotations (cs_fem_update_rotations) for the stress test.
 *
 *   update        per-step state that depends on the positions (rotations, local frames);
 *                 called before force / apply_K / diag_blocks of a step
 *   force         f = internal elastic force at x (overwrites f); energy if non-NULL
 *   apply_K       y = K p: the stiffness the implicit integrators use (for corotational
 *                 FEM the warped R K Rᵀ of the last update)
 *   diag_blocks   the 3×3 diagonal blocks of that K, 9 per node (preconditioner)
 *   tangent       the Newton operator of static solves; models without a better one use K
 *   apply_M       y += c·M p with the model's mass matrix: the lumped o->m for FEM, the
 *                 consistent (B-spline) mass for localframe (central differences use it)
 *   mass_diag     its diagonal, one per node (preconditioner)
 *   mass_rows     its row sums (= ∫ρN_a, the consistent nodal share of gravity), or NULL
 *                 when the mass is o->m itself
 */
#ifndef CS_ELASTIC_H
#define CS_ELASTIC_H

#include "world_internal.h"

int cs_elastic_init(cs_object *o, int threads);
void cs_elastic_free(cs_object *o);
/* After fracture changed o->cm's cell → node links (nodes were duplicated). */
int cs_elastic_relink(cs_object *o);
void cs_elastic_reset(cs_object *o);

void cs_elastic_update(cs_object *o, const double *x);
void cs_elastic_force(cs_object *o, const double *x, double *f, double *energy);
double cs_elastic_energy(cs_object *o, const double *x);
void cs_elastic_apply_K(cs_object *o, const double *p, double *y);
void cs_elastic_diag_blocks(cs_object *o, double *blocks);

void cs_elastic_apply_M(cs_object *o, const double *p, double *y, double coef);
const double *cs_elastic_mass_diag(const cs_object *o);
const double *cs_elastic_mass_rows(const cs_object *o);

/* Static solves: returns 0 when a tangent better than K is ready for apply_tangent. */
int cs_elastic_prepare_tangent(cs_object *o, const double *x);
void cs_elastic_apply_tangent(cs_object *o, const double *p, double *y);
void cs_elastic_release_tangent(cs_object *o);

/* Worker threads the model's products use for this object. */
int cs_elastic_threads(const cs_object *o);

#endif
