/*
 * strain_limit.h — the strain limit: no cube of a deformable object stretches past `limit`
 * times its edge, or is compressed below 1/limit of it, along any direction, or turns inside
 * out. Not part of the API.
 *
 * The elastic models are linear in the strain (corotational FEM, mss), and nothing in them
 * keeps a cube from inverting: a force far above what the material carries at one point, or a
 * contact impulse on a small piece of a violent fracture, can take a cube past any strain the
 * model means anything at, and the next steps push it on (README Known limitations). After each
 * step the limit checks every cell's corner Jacobians (the deformation gradient at its 8
 * corners, the extremes of a trilinear cube); a cell with a singular value outside
 * [1/limit, limit], or a negative one (inverted), is projected by shape matching (Müller et
 * al. 2005): its corners' rest offsets, stretched by its centre's stretch clamped to
 * [1/(0.9 limit), 0.9 limit] (inside the bounds, so that neighbours' projections do not push
 * it straight back out), turned and moved to fit its corners as they are (weights: the nodes'
 * masses; held and frozen nodes a thousand times more, and they do not move). The projections
 * go in cell by cell in cell order, forward then backward (Gauss–Seidel: the result does not
 * depend on the thread count), and the cells around each are checked again, up to
 * CS_STRAIN_SWEEPS sweeps; where a whole object is held at its bound the sweeps may end with
 * cells slightly outside it. Each moved node's velocity becomes the one that ends the step
 * where it now is, but no faster than before (the move takes back motion the step made and
 * gives none for a shape that was out of bounds before it); a cell without held corners keeps
 * its momentum while that cap is not reached.
 *
 * Every cube in bounds costs one pass over the cells (a bound from the cell's trilinear modes
 * settles nearly all; the exact singular values only where the bound is not enough), and an
 * object whose cubes stay within the bounds steps bit for bit as without the limit.
 */
#ifndef CS_STRAIN_LIMIT_H
#define CS_STRAIN_LIMIT_H

#include "world_internal.h"

#define CS_STRAIN_SWEEPS 64

/* Checks and limits o's cells (o->strain_limit > 1; 0 does nothing) after a step that moved x
 * over dt. Returns the number of cell projections made (0: every cell was within bounds), or
 * -1 if the object's scratch arrays cannot be allocated (nothing changed). Held dofs
 * (o->mask), penalty pins and frozen nodes (active regions) never move. */
int cs_strain_limit(cs_object *o, double dt);

/* The cells among n_cells (8 node indices each, positions x, edge h) turned inside out: a
 * corner where the deformation gradient's determinant is ≤ 0 (a trilinear cube's Jacobian
 * takes its extremes at the corners). *min_det (if non-NULL): the smallest corner
 * determinant of all cells (1 at rest, the volume ratio there). */
int cs_strain_inverted_cells(const double *x, const int32_t *cell_nodes, int n_cells, double h,
                             double *min_det);

/* The singular values of F (row-major, F[3i + j] = ∂x_i/∂X_j) in descending order, the
 * smallest negative when det F < 0. For tests. */
void cs_strain_singular_values(const double F[9], double s[3]);

#endif
