/*
 * surface.h — the surface mesh embedded in a cube mesh (seed 000 §3, §3.3).
 *
 * Every surface vertex is skinned: it remembers the cell it lies in and its local coordinates
 * (u,v,w) in [0,1]^3 there, and its deformed position is the trilinear interpolation of that
 * cell's eight nodes. Every triangle is assigned to the cell its centroid lies in (the rule the
 * fracture issue relies on), and each cell lists the triangles that intersect it (seed 000
 * Table 1), stored as CSR arrays.
 *
 * Owns: every array below.
 */
#ifndef CS_SURFACE_H
#define CS_SURFACE_H

#include <stddef.h>
#include <stdint.h>
#include "cubemesh.h"

typedef struct cs_surface {
    int n_vertices;
    double *rest;          /* 3 per vertex: rest (undeformed) position */
    double *pos;           /* 3 per vertex: current (skinned) position */
    int n_triangles;
    int32_t *tris;         /* 3 per triangle, counter-clockwise seen from outside */
    int32_t *vert_cell;    /* cell each vertex is skinned to */
    double *vert_uvw;      /* 3 per vertex: local coordinates in that cell, each in [0,1]
                              up to the binding tolerance / h (not clamped: exact at rest) */
    int32_t *tri_cell;     /* cell containing each triangle's centroid */
    int32_t *cell_tri_start; /* n_cells + 1 offsets into cell_tri_list */
    int32_t *cell_tri_list;  /* triangles intersecting each cell (seed 000 Table 1) */
} cs_surface;

/*
 * Bind a surface (vertices and triangles copied) to a cube mesh: skin weights, centroid cells,
 * per-cell triangle lists. Fails (-1, message in err) if a vertex or centroid lies in no cell
 * of cm (within cs_voxel_tolerance of voxelize.h), or on out of memory.
 */
int cs_surface_bind(cs_surface *s, const cs_cubemesh *cm, const double *verts, int nv,
                    const int32_t *tris, int nt, char *err, size_t errlen);
void cs_surface_free(cs_surface *s);

/*
 * (Re)build the per-cell triangle lists (seed 000 Table 1) from s->rest, s->tris and
 * s->tri_cell: every cell whose cube, grown by tol [m], a triangle meets lists it, and the
 * cell of its centroid always does. Replaces the old lists. Returns 0, or -1 (out of memory,
 * lists unchanged).
 */
int cs_surface_build_cell_lists(cs_surface *s, const cs_cubemesh *cm, double tol);
/* The same after triangles [first, n_triangles) were appended to a surface whose lists are
 * current for triangles [0, first) and the same cells (their rest geometry unchanged): only the
 * appended ones are tested. first <= 0 or no lists: a full build. */
int cs_surface_extend_cell_lists(cs_surface *s, const cs_cubemesh *cm, double tol, int first);

/* Recompute s->pos from node positions (3 per node) by trilinear interpolation, or by the
 * tricubic B-spline map in cells that have one (cm->spline_nodes, localframe objects), on up
 * to `threads` threads (each vertex on its own: the same bits on any count). */
void cs_surface_skin(cs_surface *s, const cs_cubemesh *cm, const double *node_pos, int threads);
/* The position cs_surface_skin gives a vertex at rest point `rest` with local coordinates
 * `uvw` in `cell` (bit for bit the same arithmetic): for vertices made between skins (fracture). */
void cs_surface_skin_point(const cs_cubemesh *cm, const double *node_pos, int32_t cell,
                           const double uvw[3], const double rest[3], double out[3]);

/*
 * The boundary of a cell set as a closed triangle surface: every cell face not shared with
 * another cell, split into two triangles, subdivided into `sub`×`sub` quads (sub >= 1),
 * vertices welded where that keeps the surface manifold: cells meeting only along an edge or at
 * a corner keep their own vertex copies there (and, where no copy separates an edge's two
 * cells, a vertex per cell at the edge's midpoint). Outputs are malloc'd; the caller frees them.
 */
int cs_surface_of_cells(const cs_cubemesh *cm, int sub, double **verts, int *nv,
                        int32_t **tris, int *nt, char *err, size_t errlen);

#endif
