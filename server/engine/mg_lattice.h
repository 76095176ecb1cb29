/*
 * mg_lattice.h — the V-cycle's float product on the lattice of a level's cells (mg_lattice.c):
 * the passes of mg.c's apply_path (y = A x; the residual; a fourth-kind Chebyshev step on it)
 * with the nodal vectors read and summed by whole lattice rows, 16 cells per batch, as
 * fem_lattice.c does for the double product.
 */
#ifndef CS_MG_LATTICE_H
#define CS_MG_LATTICE_H

#include <stdbool.h>
#include <stdint.h>

#include "cubemesh.h"

typedef struct cs_mgl cs_mgl;

/* The lattice form of a level with these cells (n_cells, cell_ijk, cell_nodes and n_nodes of
 * cm are read): 0 with *g NULL where it does not apply (lattice_map.h), -1 on out of memory. */
int cs_mgl_build(const cs_cubemesh *cm, cs_mgl **g);
void cs_mgl_free(cs_mgl *g);

/* Per setup, from the level's single-precision copies (mg.c, to_single): bL, bM (16 per batch
 * of 16 cells in cell order), bQ (the unit quaternions, 4 × 16 per batch; q_ok false: R is not
 * read from them, and the lattice form is not taken until a setup where it is); invf (9 per
 * node, D⁻¹ by columns), dgf, held (bits 1, 2, 4: x, y, z held). `same`: bL, bM, dgf and held
 * are the last setup's. */
void cs_mgl_set(cs_mgl *g, const float *bL, const float *bM, const float *bQ, bool q_ok,
                const float *invf, const float *dgf, const uint8_t *held, bool same,
                int threads);

enum { CS_MGL_APPLY, CS_MGL_RESID, CS_MGL_CHEB };
/* APPLY: y = Σ s R K Rᵀ x + dg x; RESID: y = b − that at free dofs, 0 at held ones; CHEB:
 * x += c D⁻¹ (that residual) at free dofs, 0 at held ones, and if out is not NULL x also in
 * double there (the node pass of mg.c's node_out, the same operations per node). False: not
 * taken (no AVX-512, or no setup with q_ok yet). */
bool cs_mgl_apply(cs_mgl *g, int threads, int mode, float *x, const float *b, float *y, float c,
                  double *out);

#endif
