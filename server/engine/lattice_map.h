/*
 * lattice_map.h — an object's cells and nodes placed on the lattice of its cells' box, for
 * the products that read nodal vectors by whole lattice rows (fem_lattice.c in double,
 * mg_lattice.c in float).
 *
 * A node row along x is sx consecutive places (sx = lanes·nxb + lanes: the cells of a row in
 * nxb batches of `lanes`, the row's end node, padding), node rows y-fastest within a node
 * layer, layers along z. A product runs in two parts split at cell layer kmid (fixed by the
 * mesh: the layer that halves the cells), whatever the thread count (cs_lattice_run).
 *
 * Owns: node, cell, gbase, grun, grest (cs_lattice_map); ps, ys, mid, seam (cs_lattice_bufs).
 */
#ifndef CS_LATTICE_MAP_H
#define CS_LATTICE_MAP_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include <immintrin.h>

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

/* Group q / m->lanes of places: its run's base (the node of lane 0 of the run), the run's
 * lanes and the other lanes with a node, and in *e the mask of the run's (x, y, z)
 * components from 3·base (3 bits per lane). */
__attribute__((target("arch=x86-64-v4"))) static inline __attribute__((always_inline)) int32_t
cs_lattice_group(const cs_lattice_map *m, size_t q, unsigned *run, unsigned *rest, uint64_t *e)
{
    const size_t g = q / (size_t)m->lanes;
    *run = m->grun[g];
    *rest = m->grest[g];
    *e = _pdep_u64(*run, 0x249249249249ull) * 7u;
    return m->gbase[g];
}

/* n bytes 64-byte aligned and zeroed (whole cache lines), or NULL. */
void *cs_lattice_zalloc(size_t n);

/* A product's lattice buffers: per part two node layers of its input (ps) and of its sums
 * (ys), node layer kn in slot kn & 1, each 3 × layer elements (x, y, z arrays); the shared
 * node layer kmid's sums of the first part (mid) and of the second (seam). */
typedef struct cs_lattice_bufs {
    void *ps[2][2], *ys[2][2], *mid, *seam;
} cs_lattice_bufs;
/* Elements of `elem` bytes (8: double, 4: float). Returns 0, or -1 on out of memory (b is then
 * empty). */
int cs_lattice_bufs_alloc(cs_lattice_bufs *b, const cs_lattice_map *m, size_t elem);
void cs_lattice_bufs_free(cs_lattice_bufs *b);

/* A product's three steps, each on one layer (ctx: the product's own state). */
typedef struct cs_lattice_pass {
    void *ctx;
    /* node layer kn of the product's input onto the lattice (dst: 3 × layer) */
    void (*in)(void *ctx, int kn, void *dst);
    /* cell layer k: reads the node layers k (pl) and k + 1 (ph), adds into their sums (yl,
     * yh), zeroing a sum row before its part first adds to it (first: k is the part's first
     * cell layer) */
    void (*cells)(void *ctx, int k, const void *pl, const void *ph, void *yl, void *yh,
                  bool first);
    /* node layer kn back to the nodes from its sums s1 (+ s2, the shared layer: the first
     * part's then the second's); pin: its input on the lattice (NULL: the nodes') */
    void (*out)(void *ctx, int kn, const void *s1, const void *s2, const void *pin);
} cs_lattice_pass;

/* The whole product: each part (cell layers [0, kmid) and [kmid, nz)) node layer by node
 * layer — the input of layer k + 1 placed, cell layer k, node layer k (then complete) back —
 * on one thread each (threads > 1), the shared node layer kmid back after both. The steps'
 * order on each layer, and so the result, does not depend on threads. */
void cs_lattice_run(const cs_lattice_map *m, int threads, cs_lattice_bufs *b,
                    const cs_lattice_pass *p);

#endif
