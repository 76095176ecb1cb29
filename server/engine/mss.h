/*
 * mss.h — the cubic mass-spring element of seed 004 §3.2 (Baudet et al., WSCG 2009).
 *
 * Per cube of edge h (the per-cube formulation: springs of neighbouring cubes on a shared
 * edge each contribute, so an interior edge carries four springs):
 *   12 edge springs          k   = E·h(4ν+1) / (8(1+ν))       rest length h
 *    4 inner-diagonal springs k_d = 3E·h / (8(1+ν))           rest length √3·h
 *   correction forces         F⊥_i = −F_i(4ν−1)/16 for an elongation force F_i along axis i
 *
 * The correction forces, read from §3.2 and checked against the paper's own Lagrangians
 * (2D: L = F η − 4F⊥(2δ) − …; the 3D analogue has 16 node–direction pairs moving by 2δ):
 *   - the element's axes are e_i = d_i/|d_i| with d_i = ¼ Σ_a s_i(a) x_a (the mean edge along
 *     i; s_i(a) = ±1 the side of corner a), so everything rotates with the element;
 *   - F_i is the elongation force of the faces normal to i: "the component of the sum of all
 *     applied forces to a face, in the direction of face normal vector". At equilibrium the
 *     forces applied to a face from outside balance the element's spring AND correction forces
 *     on it, so F = Fs − 4c(J − I)F with Fs_i = −½ Σ_a s_i(a) e_i·fs_a (spring forces only) and
 *     c = (1−4ν)/8; solved in closed form, F = A⁻¹ Fs, A = (1−4c)I + 4cJ (J = all ones);
 *   - each corner a gets 2F⊥ = c·F_i along ±e_j for both axes j ≠ i, outward for s_j(a) = +1:
 *     f_a += c Σ_i F_i Σ_{j≠i} s_j(a) e_j.
 * With this reading one cube under uniaxial stress has exactly Young's modulus E and Poisson
 * ratio ν; its nodal forces for the homogeneous normal strains equal the continuum's (bulk and
 * deviatoric parts both), and its energy for every homogeneous strain, shears included (the
 * diagonals give G exactly, §3.2 Eq. 2) — tests/unit/test_mss.c. The correction forces sum to zero and
 * have zero moment (Σ_a s_j(a) x_a ∥ e_j), vanish in any rigid placement, but are not the
 * gradient of a potential beyond first order.
 *
 * Energy: the springs' ½k(L−L0)² plus ε^T (A⁻¹ − I) P ε, ε_i = |d_i| − h, P the springs'
 * stiffness for axial stretches — the potential whose gradient is the linearized correction
 * force. Exact for small strains; it is what status messages report.
 *
 * Stiffness (cs_mss_apply_K): at the state of the last cs_mss_update, the springs' Jacobian
 * plus the correction's Jacobian with the axes frozen, symmetrized (it is symmetric at rest).
 * Matrix-free: per cell 178 numbers. The springs' Jacobian is k[n nᵀ + g (I − n nᵀ)], g =
 * max(0, 1 − L0/L): the transverse term clamped at zero so that compressed springs never make
 * it indefinite. Static Newton solves (`geometric`, cs_elastic_prepare_tangent) take it
 * unprojected and, first, unclamped too (`compressed`: g = 1 − L0/L, the springs' exact
 * Jacobian; the clamped one where CG finds that indefinite). Clamped alone, a bent slender
 * cantilever's tangent lacks the compressed half's negative transverse stiffness, and Newton
 * stalled at 0.1–0.7 of the loads (session 43's sweep: 1 m beams of 2.5 and 1.25 cm cubes
 * bent to half their length, 7–80 s then exit 1; converged in 0.6 s unclamped).
 * Implicit steps take k n nᵀ + Pᵀ k g (I − n nᵀ) P, P the orthogonal projection off the
 * cube's three infinitesimal rigid rotations ω × (x_a − c) (k n nᵀ has them in its null space
 * already): the analogue of corotational FEM's warped stiffness R K Rᵀ, whose null space holds
 * the rotations of the current state, so implicit Euler does not brake a rotating object (a
 * free tumbling block, 10 000 steps of 1/60 s: angular momentum kept to 9e-10 and energy to
 * 0.3 %; with the transverse term unprojected it lost 90 % and 99 %). The projected term must
 * stay: without it (session 12) the cubes' zero-energy modes (three per cube, not rigid, and
 * not stretching any spring to first order) had no stiffness in the implicit operator, so
 * implicit Euler integrated them explicitly and the correction forces, which are not a
 * potential's gradient, pumped them: an undamped block on frictionless ground, at rest after
 * 1 s, reached 1 m/s node speeds after 20 (test_mss). The diagonal blocks (the Jacobi
 * preconditioner) take the transverse term unprojected.
 *
 * Products are race-free like fem.c's: an element pass writes 24 numbers per cell, a node
 * pass gathers them through the node→(cell,corner) list.
 *
 * Owns: fe, st. Borrows: cell_nodes (the cube mesh), adj_start/adj (the object's cs_fem,
 * which every model keeps; cs_mss_relink re-borrows them after cs_fem_relink).
 */
#ifndef CS_MSS_H
#define CS_MSS_H

#include <stdbool.h>
#include <stdint.h>
#include "cubemesh.h"
#include "fem.h"

/*
 * The largest Poisson ratio the element is offered at (cs_world_add_object refuses more;
 * README "The mass-spring model"). Its correction forces grow as ν → 0.5: the face-force
 * balance A = (1−4c)I + 4cJ has the eigenvalue 1 + 8c = 2 − 4ν along (1,1,1), so A⁻¹ and
 * with it c·B (the correction's response, (1−4ν)/(8(1−2ν)) on a uniform stretch) grow as
 * 1/(1 − 2ν). At rest that is only the bulk stiffness the continuum has too (a cube's
 * dilation eigenvalue E·h/(2(1−2ν))), but the forces are not a potential's gradient beyond
 * first order, and their non-potential part grows with them: the implicit steps' symmetrized
 * tangent ("Stiffness" above) of a cube whose corners are moved at random by 2–20 % of h
 * turns indefinite from ν ≈ 0.445–0.455 on (2000 draws per ν; semi-definite in all of them
 * up to 0.44, and up to 0.4 at 50 %), and an implicit step with an indefinite tangent throws
 * the object. Measured (session 31, implicit Euler, dt 1/60 s): a 10×2×2 cantilever of 5 cm
 * cubes at E 1e6 Pa blew up (kinetic energy 1e5 J) from ν = 0.49; standing on the ground, a
 * 2×2×6 column of 0.1 m cubes at E 1e5 Pa gained 2.4 J and did not come to rest at 0.47 and
 * was thrown about with 1e19 J at 0.48, a 4×4×4 block at 3e4 Pa with 1e15 J at 0.48; at 0.45
 * and 0.46 they settled and slept without gaining energy (test_mss.c). Strains of order 1
 * (a 10×2×2 cantilever of 5 cm cubes at E 1e4 Pa hanging under its own weight) gain energy
 * from ν = 0.3 on, bounded (+0.4 J at 0.3, +32 J at 0.4, +186 J at 0.45 on 2.5 J), none up to
 * 0.25, where c = 0 and the element is its springs alone.
 */
#define CS_MSS_MAX_POISSON 0.45

#define CS_MSS_STATE 178 /* per cell: 16 springs × (n, g), 3 axes, K_s·S (3 × 24), r_a (24), I⁻¹ (9) */

typedef struct cs_mss {
    int n_cells, n_nodes;
    const int32_t *cell_nodes; /* 8 per cell, borrowed */
    const int32_t *adj_start, *adj; /* borrowed from the object's cs_fem */
    int threads;
    double h;
    double k_edge, k_diag; /* [N/m] */
    double c;              /* (1 − 4ν)/8: 2F⊥/F */
    double Ainv[9];        /* A⁻¹ of the face-force balance */
    double B[9];           /* (J − I)·A⁻¹: the correction's response to the face forces */
    double Mc[9];          /* (A⁻¹ − I)·P: the correction's quadratic energy */
    double *fe;            /* 24 per cell: scratch of the element pass */
    double *st;            /* CS_MSS_STATE per cell: the state of the last update */
    /* The stiffness field (world_internal.h), borrowed, 8 per cell or NULL (= all 1). A cube's
     * springs all take the mean ȳ_c of its cell's 8 Gauss-point factors (k = ȳ_c·k(E)): the
     * element's forces, energy and K are linear in its spring constants, so this scales the
     * whole element, correction forces included, and a uniform factor equals E·factor. */
    const double *ky;
    bool geometric; /* statics: the transverse spring term unprojected (the full Jacobian) */
    /* statics: compressed springs' transverse term too, negative (g = 1 − L0/L < 0): the
     * springs' exact Jacobian, which may be indefinite; read by cs_mss_update */
    bool compressed;
} cs_mss;

/* Spring constants of seed 004 §3.2 for a cube of edge h. */
double cs_mss_edge_constant(double young, double poisson, double h);
double cs_mss_diagonal_constant(double young, double poisson, double h);

/* Needs fem (initialized for the same mesh) for its adjacency. Returns 0, -1 on OOM. */
int cs_mss_init(cs_mss *m, const cs_cubemesh *cm, const cs_fem *fem, double young,
                double poisson);
void cs_mss_free(cs_mss *m);
/* After fracture changed the cell → node links and cs_fem_relink ran. */
int cs_mss_relink(cs_mss *m, const cs_cubemesh *cm, const cs_fem *fem);

/* Spring directions, axes and K_s·S at positions x, for apply_K / diag_blocks. */
void cs_mss_update(cs_mss *m, const double *x);
/* f = spring + correction forces at x (3 per node, overwritten); energy as above if non-NULL. */
void cs_mss_force(cs_mss *m, const double *x, double *f, double *energy);
/* The energy alone (reads only). */
double cs_mss_energy(const cs_mss *m, const double *x);
/* y = K p with K the symmetric stiffness of the last update. */
void cs_mss_apply_K(cs_mss *m, const double *p, double *y);
/* The 3×3 diagonal blocks of that K (9 per node, overwritten). */
void cs_mss_diag_blocks(cs_mss *m, double *blocks);
/* The same with factors w (8 per cell, NULL = all 1) instead of ky (damping: K_d). */
void cs_mss_apply_Kw(cs_mss *m, const double *w, const double *p, double *y);
void cs_mss_diag_blocks_w(cs_mss *m, const double *w, double *blocks);

/* The 24×24 stiffness of one cube at rest (what apply_K uses there); row-major. */
void cs_mss_cube_stiffness(double young, double poisson, double h, double K[24 * 24]);

#endif
