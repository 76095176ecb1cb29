/*
 * cubemesh.h — the cube mesh of seed 000 §2.1 (Tables 1 and 2).
 *
 * A set of equal cubes of edge h on an integer lattice anchored at `origin`. Cells live in an
 * open-addressing hash table keyed by their integer (i,j,k), so the cell at a lattice index is
 * found in O(1). Each cell links the eight nodes at its corners; nodes are shared between cells
 * (a node is created the first time a cell needs a corner at that lattice point). Fracture
 * (a later issue) may duplicate nodes, so cells hold node indices rather than deriving them.
 *
 * Corner order (seed 000 Appendix A, Fig. 11): 0 (-,-,-), 1 (+,-,-), 2 (+,+,-), 3 (-,+,-),
 * 4 (-,-,+), 5 (+,-,+), 6 (+,+,+), 7 (-,+,+).
 *
 * Owns: every array below. Invariant: cell c's corner k has rest position
 * origin + h·(ijk[c] + CS_CORNER[k]).
 */
#ifndef CS_CUBEMESH_H
#define CS_CUBEMESH_H

#include <stddef.h>
#include <stdint.h>

extern const int CS_CORNER[8][3]; /* lattice offset of each corner (constant table) */

typedef struct cs_ijk_hash {
    int64_t *keys;  /* packed (i,j,k); CS_HASH_EMPTY where free */
    int32_t *vals;
    int cap;        /* a power of two */
    int count;
} cs_ijk_hash;

#define CS_HASH_EMPTY INT64_MIN

int cs_ijk_hash_init(cs_ijk_hash *h, int expected);
void cs_ijk_hash_free(cs_ijk_hash *h);
/* Value at (i,j,k) or -1. */
int32_t cs_ijk_hash_get(const cs_ijk_hash *h, int32_t i, int32_t j, int32_t k);
/* Insert or overwrite; returns 0, or -1 if out of memory. */
int cs_ijk_hash_put(cs_ijk_hash *h, int32_t i, int32_t j, int32_t k, int32_t v);

typedef struct cs_cubemesh {
    double h;
    double origin[3];
    int n_cells;
    int32_t *cell_ijk;    /* 3 per cell */
    int32_t *cell_nodes;  /* 8 per cell, corner order above */
    int n_nodes;
    double *node_rest;    /* 3 per node */
    cs_ijk_hash cells;    /* (i,j,k) -> cell index */
    int32_t *spline_nodes; /* NULL, or 64 per cell: the control nodes of the tricubic B-spline
                              map of cells whose full 4×4×4 node neighbourhood exists (lattice
                              order ix + 4·iy + 16·iz from the cell's lattice point − 1; entry 0
                              is -1 on other cells). Built by the localframe model
                              (cs_lf_classify); skinning follows it (surface.c). */
} cs_cubemesh;

/*
 * Build from a list of distinct cells. Lattice indices must fit in ±2^20. Returns 0, or -1 on
 * out of memory / duplicate cell / index out of range (message in err).
 */
int cs_cubemesh_build(cs_cubemesh *cm, double h, const double origin[3], const int32_t *ijk,
                      int n, char *err, size_t errlen);
void cs_cubemesh_free(cs_cubemesh *cm);
/* Index of the cell at (i,j,k), or -1. */
int32_t cs_cubemesh_find(const cs_cubemesh *cm, int32_t i, int32_t j, int32_t k);

#endif
