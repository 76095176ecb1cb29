/*
 * mg.h — geometric multigrid on the cube lattice, used as the CG preconditioner of the FEM
 * solves (issue 7). One V-cycle per CG iteration.
 *
 * Hierarchy: 2×2×2 cells of a level become one cell of the next (lattice index floor(ijk/2)).
 * The mesh need not be a box and may be cut: the children of one lattice block that share no
 * node (a crack runs between them) make separate coarse cells at the same index, and coarse
 * corners are merged only where a fine node joins them. A fine node is interpolated
 * trilinearly from the corners of the coarse cell of any cell that references it (the merge
 * makes those rows equal), so P respects duplicated (split) nodes.
 *
 * Operators are rediscretized, matrix-free, on every level including the finest: a cell of
 * edge h has s·R K Rᵀ with K the element matrix of the unit cube scaled by the level (a coarse
 * cell of edge 2h has 2·K(h), K ∝ h), s the mean of its children's stiffness factors over 8 (a
 * partly filled block is proportionally softer; on the finest level the caller's per-cell
 * multiplier, the mean of the cell's Gauss-point factors), R the cell's rotation (finest:
 * fem's; coarse: the polar part of the sum of its children's), plus the diagonal part of the
 * fine operator (lumped mass, penalty springs, drag springs lumped by rows) restricted by Pᵀ.
 * The finest level's block-Jacobi inverse is the true operator's. The V-cycle never calls the
 * true operator: it is a fixed map built from these, so its cost does not depend on how the
 * element model computes its product (graded fields, damping fields). A coarse dof is held
 * when the fine node with the largest weight on it is held there; held dofs are zero in every
 * correction.
 *
 * Precision: the V-cycle runs in single precision (rotations, factors, D⁻¹ and vectors are
 * converted in cs_mg_setup; the coarsest Cholesky solve is double), which halves its memory
 * traffic and doubles its SIMD width. Its element products are fem.c's modal kernel
 * (modal_core.h) in float, 16 cells per batch (rotations and λ, μ laid out per batch at set-up),
 * 8 lanes per 256-bit vector; each level's element pass and node pass run chunk by chunk
 * (64 batches), so a chunk's products are summed while still in cache. CG stays in double with the true operator, so the
 * stopping rule and the solution's accuracy are unchanged; B is symmetric only up to float
 * rounding, which cs_pcg_ex's flexible (Polak–Ribière) β absorbs.
 *
 * Smoother: Chebyshev polynomials of the fourth kind (Lottes' optimised weights) in D⁻¹A over
 * [0, λ], λ = 1.1× a power-iteration estimate of λmax(D⁻¹A), of degree 2 on the finest level
 * (3 if the material's Poisson ratio is 0.4 or more) and 3 on the coarse ones (an eighth of
 * the cost each, fewer iterations), before (from zero: one product less) and after the coarse
 * correction with the same polynomial, so the V-cycle B is symmetric; it is positive definite
 * because the polynomial's error factor stays below 1 in modulus up to 1.17 λ (degree 2) and
 * 1.11 λ (degree 3), and the coarsest level is solved exactly (dense Cholesky) or, if
 * coarsening stalls above CS_MG_DENSE_NODES nodes, by a fixed number of damped Jacobi sweeps
 * (ω = 4/(3λ), a symmetric polynomial). A coarse level with at least 1.5 nodes per cell (thin
 * or small: where coarse cubes lock in bending) is solved by two cycles instead of one (a
 * W-cycle below it; two cycles of a symmetric B are 2B − BAB, symmetric too). Products run on
 * the object's threads in fixed-order element and node passes (or, where the CPU has AVX-512,
 * on the lattice of a level's box: mg_lattice.c, CS_MG_LATTICE below), so the result is
 * independent of the thread count.
 *
 * Owns: every array of every coarse level, each level's lattice form and the scratch vectors.
 * Borrows: the finest level's
 * cell links and lattice indices (the object's cube mesh), its adjacency and rotations (fem).
 */
#ifndef CS_MG_H
#define CS_MG_H

#include <stdbool.h>
#include <stdint.h>

#include "cubemesh.h"
#include "fem.h"
#include "solver.h"

#define CS_MG_COARSEST_NODES 32 /* coarsen while a level has more nodes */
#define CS_MG_DENSE_NODES 400   /* exact solve on the coarsest level up to this many nodes */

typedef struct cs_mg cs_mg;

/* Build the hierarchy for the mesh of fem (cm gives the lattice indices). NULL on out of
 * memory. `version` identifies the topology (cs_mg_matches). */
cs_mg *cs_mg_build(const cs_cubemesh *cm, const cs_fem *fem, uint32_t version);
void cs_mg_free(cs_mg *mg);
/* Built for this mesh (same version, node and cell counts and cell links)? */
bool cs_mg_matches(const cs_mg *mg, const cs_cubemesh *cm, const cs_fem *fem, uint32_t version);
int cs_mg_levels(const cs_mg *mg);
int cs_mg_level_nodes(const cs_mg *mg, int level);
/* Cycles that solve level `level`'s problem per visit from the next finer level: 1, or 2
 * where the level is thin (W-cycle below it); 1 on level 0 and the coarsest. */
int cs_mg_level_cycles(const cs_mg *mg, int level);
/* The Chebyshev degree of level `level`'s smoother: 2 on the finest (3 for a Poisson ratio of
 * 0.4 or more), 3 on the coarse levels; 0 for a level that does not exist. */
int cs_mg_level_degree(const cs_mg *mg, int level);

/* Per-fine-cell stiffness multipliers (K_e = scale·R K Rᵀ approximately) and per-fine-node
 * diagonal part of the operator, filled by the caller before cs_mg_setup. */
double *cs_mg_cell_scale(cs_mg *mg);
double *cs_mg_node_diag(cs_mg *mg);

/*
 * Prepare a solve: A(ctx) is the fine operator (kept for reference; the V-cycle uses its own
 * rediscretization, see above), inv0 its inverted 3×3 diagonal blocks, mask0 the held dofs of
 * this solve; rotations are read from fem. Returns 0, or -1 if a non-finite value appeared.
 */
int cs_mg_setup(cs_mg *mg, const cs_fem *fem, cs_matvec_fn A, void *ctx, const double *inv0,
                const uint8_t *mask0);
/* The next cs_mg_setup derives every level's scales, diagonal and held dofs again, as if they
 * had changed (a setup keeps them when level 0's are the last setup's: mg.c,
 * same_as_last_setup; for tests that compare the two). */
void cs_mg_setup_forget(cs_mg *mg);

/* z = B r, one V-cycle (a cs_precond_fn; ctx is the cs_mg). */
void cs_mg_vcycle(void *ctx, const double *r, double *z);

/* The smoother: Chebyshev polynomials of the fourth kind with Lottes' optimised weights, of
 * degree 2 on the finest level (3 at ν ≥ 0.4) and 3 on the coarse ones, over [0, λ]
 * (λ = 1.1 × the power estimate of λmax(D⁻¹A)). cs_mg_smoother_poly: the error polynomial
 * e(t) = 1 − t p(t) in t = λ(D⁻¹A)/λ, coefficients e[0..deg]; cs_mg_smoother_steps: the
 * weights c_i (the reciprocals of its roots, mildest first) of the product form
 * e(t) = Π (1 − c_i t) the V-cycle applies as x += (c_i/λ) D⁻¹ (b − A x); −1 if deg is not
 * 1..CS_MG_CHEB_MAX. */
#define CS_MG_CHEB_MAX 4
void cs_mg_smoother_poly(int deg, double *e);
int cs_mg_smoother_steps(int deg, double *c);

/* y = A x with level `level`'s operator in the V-cycle's single precision (level 0: Σ_c s_c
 * R_c K R_cᵀ x + dg x over the finest cells, as cs_mg_setup left them), x and y 3 per node of
 * the level; portable: with the gathers of CPUs without AVX-512 even where it is present. For
 * tests: the V-cycle's own products. */
void cs_mg_apply_level(const cs_mg *mg, int level, bool portable, const float *x, float *y);

/* For tests, the V-cycle's other node-pass variants on level `level` (vectors 3 per node of
 * the level): y = b − A x at free dofs and 0 at held ones (the residual it restricts); and the
 * Chebyshev step fused into that residual's pass, d = a d + c D⁻¹ r (d = c D⁻¹ r if first) and
 * x += d at free dofs, both 0 at held ones. cs_mg_level_smoother gives what they read: the
 * level's D⁻¹ blocks in single precision (9 per node, row-major) and its held dofs (3 per node). */
void cs_mg_residual_level(const cs_mg *mg, int level, const float *x, const float *b, float *y);
void cs_mg_cheb_step_level(const cs_mg *mg, int level, const float *b, float *x, float *d,
                           float a, float c, bool first);
void cs_mg_level_smoother(const cs_mg *mg, int level, float *inv, uint8_t *mask);

/* For tests, which compact layouts level `level`'s element pass reads (set by cs_mg_build and
 * each cs_mg_setup): CS_MG_NARROW_CORNERS, its corner indices as 16-bit offsets from a base
 * per batch of cells (else 32-bit indices: a CPU without AVX-512, or a batch whose corners
 * span more than 65536 floats of x); CS_MG_QUAT_ROTATIONS, its rotations as float quaternions rebuilt into R in the pass
 * (else the 3×3 matrices: some cell's R not a rotation to float precision). */
#define CS_MG_NARROW_CORNERS 1
#define CS_MG_QUAT_ROTATIONS 2
/* CS_MG_CELL_PROLONGATION: its prolongation from the next coarser level runs by coarse cells
 * (each fine node's row read as its position's row of its coarse cell's corners: the same
 * sums in the same order as by rows; else by its (node, weight) rows). */
#define CS_MG_CELL_PROLONGATION 4
/* CS_MG_PACKED_RESTRICTION: its restriction to the next coarser level reads (fine node,
 * weight) pairs packed into 4 bytes (the weight 2^−e as e in the top bits; else 8-byte pairs). */
#define CS_MG_PACKED_RESTRICTION 8
/* CS_MG_ROW_BATCHES: some of its batches are row batches (16 cells along x whose four node rows
 * are numbered consecutively: a lattice-ordered block's inside), read by whole-vector loads of
 * those rows and each node's two results in a row added in the pass (the same sums on every
 * path). Only on CPUs whose default is the 512-bit kernel (simd.h, cs_simd_wide_default). */
#define CS_MG_ROW_BATCHES 16
/* CS_MG_LATTICE: its passes (product, residual, fourth-kind Chebyshev step) run on the lattice
 * of its cells' box where the CPU has AVX-512 (mg_lattice.c: nodal vectors read and summed by
 * whole lattice rows; the same sums as the slots and node pass in another fixed order). */
#define CS_MG_LATTICE 32
int cs_mg_level_layout(const cs_mg *mg, int level);
/* Whether the levels' lattice passes are taken (true after cs_mg_build; false: the slots and
 * node pass, for comparisons). */
void cs_mg_set_lattice(cs_mg *mg, bool on);

/* The transfers between level `level` and the next coarser one, without masks (for tests):
 * xf = P xc (prolongation, trilinear) and xc = Pᵀ xf (restriction); nothing on the coarsest. */
void cs_mg_prolong(const cs_mg *mg, int level, const float *xc, float *xf);
void cs_mg_restrict(const cs_mg *mg, int level, const float *xf, float *xc);
/* The V-cycle's own prolongation (for tests): xf += P xc at the free dofs of level `level`
 * as the last cs_mg_setup left them; held dofs keep their value. */
void cs_mg_prolong_add_level(const cs_mg *mg, int level, const float *xc, float *xf);
/* The V-cycle's own restriction (for tests): xc = Pᵀ xf at the free dofs of level `level` + 1,
 * 0 at its held ones. */
void cs_mg_restrict_level(const cs_mg *mg, int level, const float *xf, float *xc);

/* Against the finest level's copies made by the last cs_mg_setup (what a lagged hierarchy was
 * built from, world.c): the max over cells of 3 − tr(R_builtᵀ R) = 2(1 − cos θ), θ the angle
 * a cell has turned by since (+inf if not finite), from the cells' unit quaternions q (4 per
 * cell; R where the level keeps its rotations as matrices); and whether mask (3 per node)
 * holds the same dofs. */
double cs_mg_rotation_drift(const cs_mg *mg, const double *R, const double *q);
bool cs_mg_held_matches(const cs_mg *mg, const uint8_t *mask);

#endif
