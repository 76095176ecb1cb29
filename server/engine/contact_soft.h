/*
 * contact_soft.h — how a deformable object answers contact impulses in the sequential-impulse
 * solve of rigid.c. Not part of the API.
 *
 * The contact solve runs after the deformable objects' own steps: an impulse J on a node of D
 * gives the node momentum J at once (D->v += J/m, so momentum is exact), and D's next
 * implicit Euler step, A v' = M v + dt f with A = (1 + dt α) M + (dt² + dt β) K, shares it
 * with the rest of D (a Newmark object pushed by a contact takes that step too: world.c). The solve must see that response, not a free point mass (a heavy body
 * would push the nodes aside and D's step would pull them back only after the solve: a loaded
 * stack went through a soft slab that way). The response is modelled in two parts that add:
 *
 *   local   A_ii⁻¹ J at the node, A_ii the node's 3×3 diagonal block of A (its stiffness
 *           against its neighbours held, elastic.h's diag_blocks);
 *   coarse  the object's rigid modes, which K does not resist: Φ (Φᵀ A Φ)⁻¹ Φᵀ J = a change
 *           of a common velocity V + Ω × (x − c) with the object's mass and inertia about its
 *           centre of mass c. Without it a free soft block seen by its diagonal blocks alone is
 *           ~40 times stiffer than it is: a drop on a rigid floor threw it ten times higher.
 *           An object held in place (removed dofs) has no coarse part; one lying on the ground
 *           keeps only the modes the ground leaves free (x, y translation, rotation about z),
 *           and while the ground's friction holds it, u0 keeps none of them and the rigid
 *           bodies' contacts see none (contact_soft.c).
 *
 * The velocity each node heads for without contacts, u0, is one two-level iteration of D's
 * next step from v (coarse, then block Jacobi on what is left): a node held up by its elastic
 * force is seen to stay, a falling object to fall. Neither part bounds the true response
 * A⁻¹: a load spread over many nodes meets less stiffness than the diagonal blocks say, and a
 * held slender object's bending is seen stiffer than it is (not measured).
 *
 * Explicit integrators (symplectic Euler, Verlet) and central differences: the free point
 * masses (1/m) and u0 = v, as their next step sees an impulse.
 *
 * Owns: the arrays of each cs_soft_resp (cs_soft_free).
 */
#ifndef CS_CONTACT_SOFT_H
#define CS_CONTACT_SOFT_H

#include <stdint.h>

#include "solver.h"
#include "world_internal.h"

typedef struct cs_soft_resp {
    cs_object *D;
    cs_object_id id;
    uint64_t step;      /* the step it was prepared for (valid through that step's substeps) */
    int n;              /* D's nodes */
    double *u;          /* 3n: u0 plus the local responses A_ii⁻¹ J of the impulses since */
    double *ainv;       /* 9n: A_ii⁻¹ row-major (when stiff) */
    double *scratch;    /* 9n */
    double *mass;       /* n: the mass A gives each node ((1 + dt α) m) */
    size_t cap_u, cap_a, cap_s, cap_m;
    bool stiff;         /* implicit Euler or Newmark, not every node held: local + coarse response */
    /* coarse: the rigid modes D may move in, c its centre of mass, minv the inverse mass on
     * each axis (0: a blocked translation), iinv the inverse inertia restricted to the free
     * rotations; V, W the coarse velocity the impulses gave so far */
    double c[3], minv[3], iinv[9], V[3], W[3];
    /* the coarse velocity D's next step adds to v's without contacts (forces, gravity): u0's
     * coarse correction (zero when not stiff or held) */
    double U0[3], W0[3];
    bool coarse;        /* D has free rigid modes (else the coarse terms are all zero) */
    /* the response as one two-level iteration on the impulses, like u0: the block-Jacobi
     * pass after the coarse one takes back A_ii⁻¹ mass_i of the coarse velocity at node i
     * (false: local and coarse responses added, the model of the rigid bodies' contacts). Set
     * by the deformable–deformable pass (rigid.c) after the rigid bodies' contacts. */
    bool two_level;
    /* the local part isotropic, (3 / tr A_ii) I instead of A_ii⁻¹, in u0 and the responses
     * alike (cs_soft_prepare's iso) */
    bool iso;
    /* a held object's residual of its next step at v (res, prepare_stiff's) */
    double *res0;
    size_t cap_res0;
    bool has_res0;
    /* a held object's modes (cs_soft_modes_*): nm ≤ 2 A-orthonormal e_m (3n each, from
     * modes), A e_m (from modes + 6n), the contacts' pattern g (at modes + 12n), and the
     * coordinates cm the impulses gave them so far */
    double *modes, cm[2], dt;
    size_t cap_modes;
    cs_cg_work cg;      /* the modes' solves (no warm start) */
    /* their answers, ψ then φ before they became modes, kept across steps as the next
     * solves' starting points while the object (raw_id) keeps its topology and nodes */
    double *raw;
    size_t cap_raw;
    cs_object_id raw_id;
    uint32_t raw_version;
    int raw_n;
    bool raw_valid[2];
    /* a small held object's exact response (cs_soft_exact_*): its contact nodes cn (n_cn),
     * each node's index in cn or -1 (slot, n), S = A⁻¹ on them (3×3 blocks row-major at
     * 9 (k n_cn + j): rows of node cn[k], columns of cn[j]), and A's factor (dense) */
    int32_t *cn, *slot;
    int n_cn, cap_cn;
    double *S, *dense;
    size_t cap_S, cap_dense;
    bool exact, exact_open;
    int nm;
    bool modes_open;
} cs_soft_resp;

/* Make r (whose arrays may be from an earlier use) D's response for step `step` of world
 * step dt: nothing is done if it already is (whatever iso asks). iso: the model of the
 * deformable–deformable contacts (rigid.c): an isotropic local part and the two-level
 * response from the start. ground_mu: the ground's friction coefficient (an object on the
 * ground that it holds has no coarse part). Returns 0 or -1 (out of memory). */
int cs_soft_prepare(cs_soft_resp *r, cs_object *D, double dt, uint64_t step, bool iso,
                    double ground_mu);
void cs_soft_free(cs_soft_resp *r);

/* A point of D given by k nodes and weights (Σ w = 1): its arm from the centre of mass. */
void cs_soft_arm(const cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                 double arm[3]);
/* Its velocity as the solve sees it. */
void cs_soft_velocity(const cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                      const double arm[3], double v[3]);
/* dᵀ W d: the velocity change along d of an impulse d on that point (W its compliance). */
double cs_soft_compliance(const cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                          const double arm[3], const double d[3], double local);
/* The local part of that compliance as if none of the point's nodes were held (every node
 * with mass counted): the scale a held point is judged against (rigid.c's soft_eff_mass). */
double cs_soft_unheld_compliance(const cs_soft_resp *r, const int32_t *nodes, const double *w,
                                 int k, const double d[3]);
/* An impulse J on D at that point: D->v and the solve's view of it change. */
void cs_soft_impulse(cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                     const double arm[3], const double J[3], double local);

/* r has no rigid modes (fixed nodes or pins) and answers by its blocks (stiff): held. */
bool cs_soft_is_held(const cs_soft_resp *r);

/*
 * A held object's modes: what carries its motion in place of the rigid modes it has not.
 * Its blocks alone are a poor model of its next step: far stiffer than it is when many of its
 * nodes are pushed together, and its u0 (one block-Jacobi iteration from v) far from the
 * step. Between two held pieces those errors gave energy at every exchange: two halves of a
 * held 4×2×2 beam (E 2 MPa, dt 1/60 s) cut lengthwise flew apart (0.28 m in 120 steps at
 * rest) and, pushed sideways for 0.5 s, rattled on at 0.2 m/s for as long as they were
 * watched; the fracture demo's beam, broken at its clamp into held cubes, was torn apart.
 * Making u0 exact alone was worse (a free piece resting on a held base fell through it):
 * u0 and the response are one model, and mixed, the contacts balance the wrong residual.
 * So both get the same coarse space, as a free object's rigid modes: ψ ≈ A⁻¹ res (the
 * object's step without contacts) and φ ≈ A⁻¹ g, g the pattern of its contact normals (its
 * answer to its contacts pushing together), each by conjugate gradients on A (preconditioned
 * by the step's multigrid hierarchy where it has one, else by the blocks) to 1e-2, made
 * A-orthonormal. Any vectors make a consistent model (u0 = v + M res, the response M J, M =
 * P + B (I − A P), P the Galerkin projection on the modes); the closer they are to A⁻¹ res
 * and A⁻¹ g, the closer the model is to the step (with ψ exact, u0 = v + ψ). The modes'
 * coordinates start at e_mᵀ res and move by e_mᵀ J with every impulse J; every node sees
 * them less what the block pass takes back (the two-level response of rigid.c's deformable
 * pass). Cost: two solves of the object's step per step it has a deformable contact with
 * another held object. begin: the pattern zeroed (1), 0 if r is not held, -1 out of memory;
 * add: the pattern gets d at that point (its free nodes); solve: the modes (0, or -1 out of
 * memory; a solve that fails leaves its mode out).
 */
/*
 * A small held object's exact response, in place of its modes: an object of at most 240 free
 * dofs has its step's operator A assembled (its products with unit vectors) and factored
 * (dense Cholesky); S = A⁻¹ on its contact nodes answers every impulse at every contact node
 * and u0 = v + A⁻¹ res. The pieces a clamp holds after a beam breaks at it are single cubes
 * and short rows: two modes and the blocks were not enough between them (a cluster of such
 * pieces in the fracture demo kept throwing each other), the exact answer is. begin: 1 if r
 * is held and small (its node list emptied), 0 if not (its modes answer), -1 out of memory;
 * add: the point's free nodes join the list; solve: S and u0 (0, or -1 out of memory; left
 * on the blocks if A is not positive definite).
 */
int cs_soft_exact_begin(cs_soft_resp *r);
int cs_soft_exact_add(cs_soft_resp *r, const int32_t *nodes, const double *w, int k);
int cs_soft_exact_solve(cs_soft_resp *r);
int cs_soft_modes_begin(cs_soft_resp *r);
void cs_soft_modes_add(cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                       const double d[3]);
int cs_soft_modes_solve(cs_soft_resp *r);

/* The rigid modes alone (zero without them): the compliance dᵀ (minv d + iinv (arm × d) × arm)
 * along d at arm, and the velocity they will have at arm in D's next step, that of D's
 * nodes' momentum now (D->v, with the impulses so far) plus what the step's forces add
 * (U0, W0). The bounce of two deformable objects (rigid.c's pair_restitution). */
double cs_soft_coarse_compliance(const cs_soft_resp *r, const double arm[3], const double d[3]);
void cs_soft_coarse_velocity(const cs_soft_resp *r, const double arm[3], double v[3]);

#endif
