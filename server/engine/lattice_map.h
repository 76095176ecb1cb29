/*
 * lattice_map.h — an object's cells and nodes placed on the lattice of its cells' box, for
 * the products that read nodal vectors by whole lattice rows (fem_lattice.c in double,
 * mg_lattice.c in float).
 *
 * A node row along x is sx consecutive places (sx = lanes·nxb + lanes: the cells of a row in
 * nxb batches of `lanes`, the row's end node, padding), node rows y-fastest within a node
 * layer, layers along z. A product runs in two parts split at cell layer kmid (fixed by the
 * mesh: the layer that halves the cells), whatever the thread count.
 *
 * Owns: node, cell, gbase, grun, grest.
 */
#ifndef CS_LATTICE_MAP_H
#define CS_LATTICE_MAP_H

#include <stddef.h>
#include <stdint.h>

#include "cubemesh.h"

typedef struct cs_lattice_map {
    int nx, ny, nz; /* cells in the box */
    int lanes;      /* cells per batch */
    int nxb;        /* batches per cell row */
    int sx;         /* places per node row */
    size_t layer;   /* places per node layer: sx·(ny + 1) */
    size_t npos;    /* places: layer·(nz + 1) */
    int kmid;       /* the second part's first cell layer (nz: one part) */
    int32_t *node;  /* per place: its node, or -1 */
    int32_t *cell;  /* per batch (ib + nxb·(j + ny·k)) × lanes: the cell of each lane, or -1 */
    /* Per group of `lanes` places (place q in group q / lanes): the lanes whose node is
     * gbase + lane (grun: along a node row the mesh numbers nodes consecutively, but for a
     * swapped pair at the row's start; the last lane with a node decides gbase), and the
     * other lanes with a node (grest): the products read and write a run with whole vectors. */
    int32_t *gbase;
    uint16_t *grun, *grest;
} cs_lattice_map;

/* lanes: 8 or 16. Returns 1 with m built; 0 where the mesh does not take the lattice form (no cells, two
 * cells at one index, a node split in two or without a cell, or a box of more than 3 × (nodes + 4096)
 * places), m empty;
 * -1 on out of memory. */
int cs_lattice_map_build(cs_lattice_map *m, const cs_cubemesh *cm, int lanes);
void cs_lattice_map_free(cs_lattice_map *m);

#endif
