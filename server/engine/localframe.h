/*
 * localframe.h — the local-frame B-spline model of seed 001 §3.2–3.4 on the cube mesh.
 *
 * Elements. A cell whose full 4×4×4 node neighbourhood exists (the cell and its 26
 * neighbouring cells exist and share their nodes: fracture's duplicated nodes break that) is
 * a tricubic B-spline element with 64 control nodes, the cube-mesh nodes of lattice points
 * i−1..i+2 per axis; a uniform cubic B-spline over those spans exactly the cell, and with
 * the rest positions as control points it is the identity (§3.4.1 "regular cells"). Every
 * other cell is a linear hexahedron (§3.4.2 "extraordinary cells"). Element stiffness K_e
 * (Eq. 5 with C of Eq. 6), mass M_e = ∫ρ ΓᵀΓ and the shape of the damping ∫γ ΓᵀΓ (§3.2.1)
 * come from 4-point Gauss quadrature per axis (64 points, Eq. 21): one matrix of each kind
 * per element type and material, shared by all elements.
 *
 * Local frames (§3.2.2). Each element measures its deformation in a moving frame u–v–w that
 * follows it (Figs. 4, 5): the frame vectors are the element's edge directions at its centre
 * (the columns of F = ∂x/∂X there), whose length changes are the edge-length changes
 * (stretch) and whose angle changes are the face-angle changes (shear). The frame's rotation
 * R is the one that splits each face-angle change evenly between the two edges, as Fig. 3
 * rotates both a and b about the node: that is the polar rotation (RᵀF symmetric). The R
 * operator of Eq. (3) is then d̂_e = Rᵀ(x_a − x_ref) − (X_a − X_ref) per element node a: the
 * nodal displacements due to stretching and shearing alone, in the element's frame. The
 * stiffness is never reassembled: f_e = −R K_e d̂_e, energy ½ d̂ᵀK_e d̂, and the implicit
 * operator is R K_e Rᵀ. Rigid motions of any size give d̂ = 0 exactly.
 *
 * Products are matrix-free and race-free like fem.c: each element writes its results to its
 * own slots, a node pass gathers them through a node → slot list in a fixed order.
 *
 * Owns: every array below. Writes cm->spline_nodes (owned by the cube mesh, see cubemesh.h).
 */
#ifndef CS_LOCALFRAME_H
#define CS_LOCALFRAME_H

#include <stdint.h>

#include "cubemesh.h"
#include "cubesim.h"

typedef struct cs_lf {
    int n_cells, n_nodes, n_spline;
    int threads;
    double h;
    double Kl[24 * 24], Ml[8 * 8]; /* linear hexahedron, corner order of cubemesh.h */
    double *Ks, *Ms;       /* tricubic: 192×192 and 64×64, node a = ix + 4·iy + 16·iz */
    double m1[16], m1scale; /* Ms = m1scale · m1⊗m1⊗m1 (1D Gram matrix of one span) */
    double m1h[32];        /* m1 of the span's lower and upper half (m1 = their sum) */
    double *Kso;           /* 8 × 192×192: Ks integrated over one octant of the cell */
    double *Kso_l;         /* 8 × (576 + 64): Kl and Ml over one octant, corner order */
    int32_t *off;          /* n_cells + 1: each cell's first slot in en */
    int32_t *en;           /* element nodes: 8 (corner order) or 64 (lattice order) per cell */
    double *R;             /* 9 per cell: the local frame's rotation, row-major */
    double *q;             /* 4 per cell: warm start of the rotation extraction */
    double *fe;            /* 3 per slot: scratch of the element pass */
    int32_t *adj_start;    /* n_nodes + 1 */
    int32_t *adj;          /* slots, grouped by node */
    double *mrow;          /* per node: row sum of the consistent mass (= ∫ρ N_a) */
    double *mdiag;         /* per node: diagonal entry of the consistent mass */
    /* Material fields (world_internal.h), borrowed, 8 per cell or NULL (= all 1). Each of the
     * 4×4×4 quadrature points takes the factor of the nearest of the cell's 8 Gauss points
     * (the one in its octant), so K_e = Σ_g f_g K_g and M_e = Σ_g ρ_g M_g with 8 octant
     * matrices per element type (Kso, Kso_l; the B-spline octant masses are products of
     * half-span Gram matrices): still no matrix per element. A cell whose 8 factors are
     * equal costs one product with K (or M) scaled; a graded one 8. cs_lf_set_fields points
     * them and recomputes mrow and mdiag. */
    const double *ky;      /* young factors */
    const double *km;      /* density factors */
} cs_lf;

/* Uniform cubic B-spline basis on one span, t in [0,1]: b[k] weighs control node i−1+k. */
void cs_bspline_basis(double t, double b[4], double db[4]);

/*
 * Classify cm's cells: cm->spline_nodes (64 per cell, lattice order; entry 0 is -1 for a
 * linear cell) is rebuilt. Returns the number of B-spline cells, or -1 on out of memory.
 */
int cs_lf_classify(cs_cubemesh *cm);

/* Element matrices for material (young, poisson, density) and cube size h. */
int cs_lf_init(cs_lf *lf, cs_cubemesh *cm, double young, double poisson, double density,
               int threads);
/* After fracture duplicated nodes: re-classify cells and rebuild the node lists. */
int cs_lf_relink(cs_lf *lf, cs_cubemesh *cm);
void cs_lf_free(cs_lf *lf);
void cs_lf_reset(cs_lf *lf);

void cs_lf_update(cs_lf *lf, const double *x);
void cs_lf_force(cs_lf *lf, const double *x, double *f, double *energy);
/* Energy at x with frames extracted afresh (reads only). */
double cs_lf_energy(const cs_lf *lf, const double *x);
void cs_lf_apply_K(cs_lf *lf, const double *p, double *y);
void cs_lf_diag_blocks(const cs_lf *lf, double *blocks);
/* The same with factors w (8 per cell, NULL = all 1) instead of ky (damping: K_d). */
void cs_lf_apply_Kw(cs_lf *lf, const double *w, const double *p, double *y);
void cs_lf_diag_blocks_w(const cs_lf *lf, const double *w, double *blocks);
/* y += coef · M p, M the consistent mass (with km); _w: with factors w instead (M_d). */
void cs_lf_apply_M(cs_lf *lf, const double *p, double *y, double coef);
void cs_lf_apply_Mw(cs_lf *lf, const double *w, const double *p, double *y, double coef);
/* Point ky, km at the object's fields (NULL = all 1) and recompute mrow, mdiag. */
void cs_lf_set_fields(cs_lf *lf, const double *young, const double *density);


/*
 * ω²max = λmax(M⁻¹K) of objects of this model, material and cube size, for the stability
 * limit dt < 2/ωmax of central differences. FEM models (lumped mass): the largest element
 * eigenvalue of the linear hexahedron, a rigorous bound (λmax of an assembly never exceeds
 * its elements'). localframe (consistent mass): the larger of that bound for its linear
 * hexahedra and 1.1 × the B-spline lattice maximum (cs_lf_lattice_max); an estimate, checked
 * against assembled objects in the tests. Returns 0, or -1 on out of memory.
 */
int cs_lf_omega2_bound(cs_model model, double young, double poisson, double density, double h,
                       double *omega2);

/*
 * λmax of the infinite uniform lattice of one element type (nb = 2 or 4 nodes per axis, K
 * 3n×3n and M n×n in lexicographic order): plane waves e^{iθ·X/h} turn K and M into a 3×3
 * Hermitian K̂(θ) and a scalar M̂(θ); θ is scanned over a grid of [0, π]³. -1 on out of memory.
 */
double cs_lf_lattice_max(const double *K, const double *M, int nb);

#endif
