/*
 * voxelize.h — seed 000 §2.1 mesh generation and §3.3 surface preprocessing.
 */
#ifndef CS_VOXELIZE_H
#define CS_VOXELIZE_H

#include <stddef.h>
#include <stdint.h>

/*
 * Seed 000 §3.3: subdivide triangles until no edge is longer than max_len, in O(n log n), by
 * the sorted edge-triple list of the paper (new vertex at each long edge's midpoint; both
 * triangles sharing the edge are split, so a closed surface stays closed and consistently
 * oriented). *verts / *tris are realloc'd in place (they must be malloc'd). Returns 0 or -1
 * (out of memory, message in err).
 */
int cs_subdivide_edges(double **verts, int *nv, int32_t **tris, int *nt, double max_len,
                       char *err, size_t errlen);

/*
 * What fracture and skinning need of an object's surface (the daemon's scene loader checks
 * the same with common/watertight.c): every edge used by exactly two triangles in opposite
 * directions, no triangle with a repeated vertex, and a positive enclosed volume. Returns 0,
 * or -1 with one line naming the first problem found ("mesh is not manifold: ...", "mesh is
 * inside out: ..."), or out of memory.
 */
int cs_mesh_surface_check(const double *verts, int nv, const int32_t *tris, int nt, char *err,
                          size_t errlen);

/*
 * Seed 000 §2.1: cut the mesh's axis-aligned bounding box into cubes of edge h and keep every
 * cube that intersects a triangle (exact separating-axis test) or lies inside the closed
 * surface: where its winding number is not 0 (a cavity, inside a closed inner shell wound
 * inward, is outside; a mesh whose shells are not all consistently wound: an odd number of
 * crossings). The mesh must be closed (see common/watertight.h); an open one is refused with
 * CS_ERR_GEOMETRY-style -1 and a message. Outputs a malloc'd list of (i,j,k) and the lattice
 * origin (the bounding box's min corner).
 */
int cs_voxelize(const double *verts, int nv, const int32_t *tris, int nt, double h,
                double origin[3], int32_t **ijk, int *n_cells, char *err, size_t errlen);

/*
 * The geometric tolerance (a length) of voxelization and surface binding for a mesh: points
 * and surfaces within it of a cell boundary count as on it. max(1e-9·h, 2^-20·M), M the largest
 * |coordinate| of verts, capped at 1e-4·h: meshes come from files in float32, so a surface
 * meant to lie on a lattice plane is only there to float precision.
 */
double cs_voxel_tolerance(double h, const double *verts, int nv);

/* Exact triangle/axis-aligned-box overlap (separating axis theorem). */
int cs_tri_box_overlap(const double center[3], const double half[3], const double a[3],
                       const double b[3], const double c[3]);

#endif
