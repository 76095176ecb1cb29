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

int cs_elastic_init(cs_object *o, int threads, int simd_width);
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
/* The factor of the scalar mass (M = m ⊗ I₃, a localframe's consistent mass) for z = M⁻¹ r:
 * built on first use (o->mfac), 0 when it exists; -1 when the object has no consistent mass,
 * its nodes are not one per lattice point (mid-fracture duplicates), it is too large (the band
 * over 4e6 entries: 32 MB) or M is not positive definite. cs_elastic_mass_solve: z = c·M⁻¹ r
 * per component (r, z 3 per node; may alias). cs_elastic_mass_factor_drop: forget it (the mass
 * changed). */
int cs_elastic_mass_factor(cs_object *o);
void cs_elastic_mass_solve(const cs_object *o, double c, const double *r, double *z);
void cs_elastic_mass_factor_drop(cs_object *o);
const double *cs_elastic_mass_diag(const cs_object *o);
const double *cs_elastic_mass_rows(const cs_object *o);

/* Static solves: returns 0 when a tangent better than K is ready for apply_tangent. For mss
 * (returns -1) K itself becomes the springs' Jacobian, with exact its compressed springs'
 * transverse term too (else clamped at zero: mss.h). */
int cs_elastic_prepare_tangent(cs_object *o, const double *x, bool exact);
void cs_elastic_apply_tangent(cs_object *o, const double *p, double *y);
/* mss: K with compressed springs' transverse term clamped at zero (positive semi-definite
 * springs), updated at x; true if that changed K (false for other models, or already
 * clamped). Until the next cs_elastic_prepare_tangent. */
bool cs_elastic_clamp_tangent(cs_object *o, const double *x);
void cs_elastic_release_tangent(cs_object *o);

/*
 * Explicit integration (symplectic Euler, velocity Verlet): an upper bound of ω_max, the
 * largest eigenfrequency of M⁻¹K, for a model at rest on cubes of edge h with the lumped mass
 * ρh³/8 per corner — the largest eigenvalue of one cube's M_e⁻¹K_e, which bounds the assembled
 * one (element eigenvalue theorem) for any mesh and after any fracture. The critical step is
 * 2/ω_max, smaller with damping (see elastic.c).
 */
double cs_elastic_max_omega(cs_model model, const cs_material *mat, double h);
double cs_elastic_critical_dt(cs_model model, const cs_material *mat, double h);

/*
 * Material fields (world_internal.h). cs_elastic_fields_changed: after o->fld changed (called
 * by cs_object_lump_mass): each model's borrowed factor pointers and field-dependent data
 * (localframe's consistent mass rows, a rigid body's mass properties) follow. Returns -1 on
 * out of memory. The damping operators of C = α M_d + β K_d:
 *   apply_Kd      y = K_d p (factors young·damping), at the state of the last update
 *   diag_blocks_d its 3×3 diagonal blocks
 *   apply_Md      y += c·M_d p: lumped fld.md, or localframe's consistent mass with the
 *                 factors density·damping
 * Valid when o->fld.has_damping.
 */
int cs_elastic_fields_changed(cs_object *o);
void cs_elastic_apply_Kd(cs_object *o, const double *p, double *y);
void cs_elastic_diag_blocks_d(cs_object *o, double *blocks);
void cs_elastic_apply_Md(cs_object *o, const double *p, double *y, double coef);

/*
 * The stability limit of one object with its fields and penalty springs: the plain model's
 * ω²max (ω2_plain, for the object's material at rest) times the largest over cells of
 * max_g young_g / min_g density_g (K_e ≤ ȳ_max K and M_e ≥ ρ̄_min M in the Loewner order, so
 * each element eigenvalue grows at most by that ratio), plus max over penalty-held nodes of
 * k_p/m_i (Weyl: λmax(M⁻¹(K + P)) ≤ λmax(M⁻¹K) + λmax(M⁻¹P)). Returns that ω²max bound.
 */
double cs_elastic_object_omega2(const cs_object *o, double omega2_plain, bool with_penalty);

/* Worker threads the model's products use for this object. */
int cs_elastic_threads(const cs_object *o);

#endif
