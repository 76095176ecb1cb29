/*
 * fem.h — hexahedral finite elements on the cube mesh: seed 000 §2.2 and Appendix A.
 *
 * One 24×24 stiffness matrix K per material (all cubes share their geometry), computed by
 * 2×2×2 Gauss quadrature of the trilinear shape functions, which is exact for a cube.
 * Linear model: f = -K (x - X) per element. Corotational (warped stiffness): each element's
 * rotation R is the rotational part of the deformation gradient at its centre, and
 * f = -R K (Rᵀ x - X); the tangent used by the implicit solve is R K Rᵀ.
 *
 * Products are matrix-free and race-free: an element pass writes each cell's 24 results to its
 * own slot, a node pass gathers them through a node→(cell,corner) list in a fixed order, so
 * results are identical for any number of threads. The two passes run fused, chunk by chunk,
 * with the slots in a window per thread's segment of cells that stays in L2 (fem.c,
 * fused_pass). (Adding each cell straight into the output
 * by colours — the 8 lattice parities, or slabs of alternate layers — measured slower on a 32³
 * block: 42–49 ns per cube and product against 37 with the gather.) The element product does
 * not use K: it is modal (fem.c), a Walsh–Hadamard transform of the nodal values to the 7
 * deformation modes of the trilinear field, their stresses, and back (188 flops, 398 with the
 * rotations, instead of 1152 + 240), 8 cells per batch, one per SIMD lane (two 256-bit
 * halves; its arithmetic, modal_core.h, is shared with multigrid's single-precision V-cycle).
 * K stays for the diagonal blocks and multigrid's set-up. On CPUs with AVX-512, cs_fem_apply_K
 * and cs_fem_apply_K_mass of a mesh whose nodes sit one per lattice point (no fracture) and
 * whose box is not mostly empty run on the lattice instead (fem_lattice.c: the nodal vectors
 * as x, y, z arrays over the box, read and summed by whole rows, no slots and no node pass;
 * the same sums in another fixed order, also independent of the thread count).
 *
 * Material fields (world_internal.h, seed 001 §3.3): with kf set (8 factors per cell, one per
 * Gauss point), cell c's stiffness is K_e = Σ_g kf[8c+g]·K_g, K_g the shared unit matrix of
 * Gauss point g (Σ_g K_g = K). A cell whose 8 factors are equal costs one modal product
 * (scaled); a graded cell's product is taken point by point, Σ_g kf_g·B_gᵀ C B_g u (strain,
 * stress, nodal forces: about 2900 flops, 7 times a modal product). No matrix is stored per
 * element.
 *
 * Owns: R, q, fe, adj_start, adj, Kg, lat. Borrows: cell_nodes (from the object's cube mesh) and kf
 * (the object's young field).
 */
#ifndef CS_FEM_H
#define CS_FEM_H

#include <stdbool.h>
#include <stdint.h>
#include "cubemesh.h"

/* Objects with fewer cells than this are stepped on one thread (see cs_fem_init). */
#define CS_FEM_PARALLEL_CELLS 2048

/* The lattice form of the products (fem_lattice.c), built by cs_fem_relink where it applies. */
typedef struct cs_fem_lattice cs_fem_lattice;

typedef struct cs_fem {
    int n_cells, n_nodes;
    const int32_t *cell_nodes; /* 8 per cell, borrowed */
    double h;
    bool corotational;
    int threads;        /* worker threads for this object's products (1 when small) */
    bool wide;          /* 512-bit element kernels (simd.h; the same bits as 256-bit ones):
                         * cs_fem_init sets the CPU's default, callers may change it */
    double K[24 * 24];
    double *Kg;         /* 8 × 576: the unit matrix of each Gauss point (Σ_g = K) */
    double gq[8][8][3]; /* ∂N_k/∂x at Gauss point g: graded products as Σ_g B_gᵀ C B_g */
    double lambda, mu, detj;
    const double *kf;   /* 8 per cell: stiffness factor per Gauss point; NULL = all 1. Borrowed */
    /* Per cell: 0 = skipped by update_rotations, elastic_force, apply_K(w) and diag_blocks(_w)
     * (an inactive cell of an active region: its R, slot and blocks are left alone and the node
     * pass ignores it; elastic_force's energy then covers only what was computed); NULL = every
     * cell. Borrowed (world.c sets it only during a step). */
    const uint8_t *cell_active;
    double *R;          /* 9 per cell, row-major; identity for the linear model */
    double *q;          /* 4 per cell (w,x,y,z): warm start of the rotation extraction */
    double *fe;         /* 24 per cell: scratch of the element pass */
    int32_t *adj_start; /* n_nodes + 1 */
    int32_t *adj;       /* cell*8 + corner, grouped by node */
    double *tg;         /* 33 per cell while a static solve runs (see cs_fem_prepare_tangent) */
    /* The products' element and node passes run fused, chunk by chunk (fem.c, fused_pass): the
     * cells in batches of 8, split into `nseg` segments (one per thread); the node pass
     * follows the element pass through the nodes ordered by the batch of their last cell
     * (norder; nminb: the batch of the node's first cell; nfirst[b]: the first position whose
     * last batch is >= b), and the element pass's results live in a window of fe per segment
     * (bslot: a batch's slot of 8 × 24 doubles; fadj: where link a of adj reads them). Built by
     * cs_fem_relink. */
    int nseg;
    int32_t *norder, *nminb, *nfirst, *bslot;
    /* Row batches (fem.c, product_layout; only where cs_simd_wide_default, simd.h): a batch of 8
     * cells along x in one lattice row whose four node rows (one per (dy, dz)) are each 9
     * consecutive nodes; rowb[4b + r] = 3·(the first node of node row r), rowb[4b] = -1: not a
     * row batch. Its results are stored per node row (32 doubles from the slot's 32 r: 9 nodes'
     * (x, y, z)), each node's two results in the row added in the element pass. The node pass's
     * links (nstart: per node, its first; n_nodes + 1) in adj's order less those a row batch
     * added into another: fadj, where each reads its x component in fe, and fcell, its cell
     * (-1 − batch for a row batch's link: active if its batch is). */
    int32_t *rowb, *nstart, *fadj, *fcell;
    int n_row_batches;
    int span; /* the largest distance between a node's first and last batch */
    /* cs_fem_apply_K(w) and cs_fem_apply_K_mass on the lattice of the cells' box
     * (fem_lattice.c; NULL: the mesh is not one the lattice form takes). `lattice`: use it
     * (cs_fem_init sets true; false: fem.c's product, for comparisons). */
    cs_fem_lattice *lat;
    bool lattice;
} cs_fem;

int cs_fem_init(cs_fem *fem, const cs_cubemesh *cm, double young, double poisson,
                bool corotational, int threads);
void cs_fem_free(cs_fem *fem);
/* Rebuild the node→cell list after the cell/node links changed (fracture). */
int cs_fem_relink(cs_fem *fem, const cs_cubemesh *cm);

/* Per-element rotations from current positions x (3 per node). No-op for the linear model. */
void cs_fem_update_rotations(cs_fem *fem, const double *x);
/* Reset rotations to identity (reset / rest state). */
void cs_fem_reset_rotations(cs_fem *fem);

/*
 * Elastic forces f = -Σ R K (Rᵀ x - X) (3 per node, overwritten) and, if energy is non-NULL,
 * the elastic energy ½ Σ uᵀ K u with u = Rᵀ x - X in element-local coordinates.
 */
void cs_fem_elastic_force(cs_fem *fem, const double *x, double *f, double *energy);
/*
 * Elastic energy ½ Σ uᵀ K u at positions x, with each element's rotation extracted afresh
 * from x (warm-started from, but not written back to, the stored quaternions). Reads only:
 * asking for the energy never changes what the next step computes.
 */
double cs_fem_energy(const cs_fem *fem, const double *x);

/* y = Σ R K Rᵀ p over elements (3 per node, overwritten). */
void cs_fem_apply_K(cs_fem *fem, const double *p, double *y);
/* The same with the factors kf (8 per cell) instead of fem->kf (damping: K_d). */
void cs_fem_apply_Kw(cs_fem *fem, const double *kf, const double *p, double *y);
/* Diagonal blocks of that weighted K (9 per node, overwritten). */
void cs_fem_diag_blocks_w(cs_fem *fem, const double *kf, double *blocks);
/* The diagonal term of node i that cs_fem_precond_blocks adds:
 * d_i = mcoef·m[i] + (md ? cmcoef·md[i] : 0) + (pin[i] ? pk : 0). */
typedef struct cs_fem_node_terms {
    const double *m, *md; /* md may be NULL */
    const uint8_t *pin;
    double mcoef, cmcoef, pk;
} cs_fem_node_terms;
/* Block Jacobi in one node pass: blocks = (kcoef·B_i + d_i I)⁻¹ (cs_invert_block), B_i node
 * i's block of cs_fem_diag_blocks_w(fem, kf), bit for bit what those two passes give. */
void cs_fem_precond_blocks(cs_fem *fem, const double *kf, double kcoef, const cs_fem_node_terms *t,
                           double *blocks);
/* y = kcoef·K p + mcoef·m_i p_i (m: 1 per node), K as cs_fem_apply_K's: the implicit step's
 * operator without its damping field, penalty and springs, in one product (the mass term added
 * in the node pass as each row is written; bit for bit kcoef·y + (mcoef·m_i)·p_i on y from
 * cs_fem_apply_K, on any number of threads). */
void cs_fem_apply_K_mass(cs_fem *fem, double kcoef, double mcoef, const double *m,
                         const double *p, double *y);
/* The unit matrix of Gauss point g (0..7) of a cube: K = Σ_g Kg. */
void cs_cube_stiffness_gauss(double young, double poisson, double h, int g, double K[24 * 24]);
/*
 * Geometric stiffness for Newton's method on corotational statics. With F = R S at an
 * element's centre, dR = R[ω]× where ω = (tr(S)·I − S)⁻¹ axial(RᵀdF − dFᵀR); the force
 * f = −R K u then changes by −R (ω × (K u)_k) besides the warped term. prepare stores
 * (tr(S)I − S)⁻¹ and K u per element for positions x (rotations must be current);
 * apply_tangent computes y = (R K Rᵀ + G_sym) p, G_sym the symmetric part of that term.
 * Returns -1 on out of memory.
 */
int cs_fem_prepare_tangent(cs_fem *fem, const double *x);
void cs_fem_apply_tangent(cs_fem *fem, const double *p, double *y);
void cs_fem_release_tangent(cs_fem *fem);

/*
 * The element pass of a product on cells that share one cube stiffness K (as
 * cs_cube_stiffness builds it, any edge and material): fe[24c..24c+23] = s_c R_c K R_cᵀ x on
 * cell c's nodes, for c < n_cells (R: 9 per cell, s: 1 per cell). The modal kernel of
 * cs_fem_apply_K in double (multigrid's V-cycle runs its single-precision twin in mg.c, with
 * a coarse level's K(2h) = 2 K(h) in s).
 */
void cs_cube_cells_product(const double K[24 * 24], int n_cells, const int32_t *cell_nodes,
                           const double *R, const double *s, const double *x, double *fe,
                           int threads);
/* hλ and hμ of a cube stiffness K built by cs_cube_stiffness (K is linear in both). */
void cs_cube_lame_h(const double K[24 * 24], double *hl, double *hm);
/* fem_lattice.c: *lt = the lattice form for this mesh, or NULL where it does not apply
 * (returns -1 on out of memory); its product (false: not taken, the caller runs fem.c's):
 * y = sign·K p (+ (mcoef·m_n)·p_n per node when m is not NULL), K of the uniform material
 * (taken only for kf NULL: no stiffness factors). */
int cs_fem_lattice_build(const cs_fem *fem, const cs_cubemesh *cm, cs_fem_lattice **lt);
void cs_fem_lattice_free(cs_fem_lattice *lt);
bool cs_fem_lattice_product(cs_fem *fem, const double *kf, double sign, double mcoef,
                            const double *m, const double *p, double *y);
/* Floating-point operations of one cs_fem_apply_K on this mesh (the kernel as implemented). */
double cs_fem_product_flops(const cs_fem *fem);

/* The 3×3 diagonal blocks of Σ R K Rᵀ (9 per node, overwritten). */
void cs_fem_diag_blocks(cs_fem *fem, double *blocks);

/* Rotational part of a 3×3 matrix A (row-major) by the iterative method of Müller et al.
 * (2016), warm-started from unit quaternion q (w,x,y,z), which is updated; near the solution
 * its steps are Newton's (quadratic convergence, fem.c). Robust for inverted and degenerate A.
 * Gives bit for bit what cs_fem_update_rotations computes for the same A and warm start. */
void cs_extract_rotation(const double A[9], double q[4], int max_iter);
/* n extractions (A 9 per matrix, q 4 per warm start, updated), ROT_LANES side by side: each
 * q as cs_extract_rotation(A + 9i, q + 4i, max_iter) leaves it, bit for bit. */
void cs_extract_rotations(int n, const double *A, double *q, int max_iter);
void cs_quat_to_mat(const double q[4], double R[9]);

#endif
