/*
 * rowbatch.h — the row batches of the element passes (fem.c and mg.c, product_layout).
 *
 * In a block whose cells are in lattice order, the nodes of a lattice row are numbered
 * consecutively (inside the block each cell creates one node). A batch of `lanes` cells
 * along one row whose four node rows r = (dy, dz) = (0, 0), (1, 0), (0, 1), (1, 1) are each
 * consecutive is a row batch: its pass reads each node row with whole-vector loads and adds
 * each node's two results in the row (the cell before it at dx = 1, the cell after it at
 * dx = 0) before storing them, lanes + 1 nodes per row (the last one the row's end node,
 * added to by the next batch's first lane). fem.c's double pass has 8 lanes, mg.c's float
 * pass 16.
 */
#ifndef CS_ROWBATCH_H
#define CS_ROWBATCH_H

#include <stdbool.h>
#include <stdint.h>

#include <immintrin.h>

#include "cubemesh.h"

/* Node row r's corners at dx = 0 and dx = 1 (CS_CORNER), and each corner's node row. */
static const int CS_ROW_K0[4] = {0, 3, 4, 7}, CS_ROW_K1[4] = {1, 2, 5, 6};
static const int CS_ROW_OF[8] = {0, 0, 1, 1, 2, 2, 3, 3};

/* Marks the row batches among the whole batches of `lanes` cells: rowb[4b + r] = 3·(the first
 * node of node row r) and rowb[4b] = -1 where batch b is not one (every batch when !rows: the
 * CPU's kernel does not take them). Returns how many are. */
static inline int cs_row_batches(const int32_t *cell_nodes, int n_cells, int lanes, bool rows,
                                 int32_t *rowb)
{
    const int nb = (n_cells + lanes - 1) / lanes;
    int count = 0;
    for (int b = 0; b < nb; b++) {
        const int c0 = b * lanes;
        bool row = rows && c0 + lanes <= n_cells;
        for (int r = 0; r < 4 && row; r++) {
            const int32_t base = 3 * cell_nodes[8 * c0 + CS_ROW_K0[r]];
            for (int l = 0; l < lanes && row; l++)
                row = 3 * cell_nodes[8 * (c0 + l) + CS_ROW_K0[r]] == base + 3 * l &&
                      3 * cell_nodes[8 * (c0 + l) + CS_ROW_K1[r]] == base + 3 * l + 3;
            rowb[4 * b + r] = base;
        }
        rowb[4 * b] = row ? rowb[4 * b] : -1;
        count += row;
    }
    return count;
}

/* Where corner k of lane l of a row batch is stored within its node row (in values, 3 per
 * node): at dx = 0 its own node's place; at dx = 1 it is the next lane's dx = 0 node, added
 * there (-1: no link of its own), except for the last lane's, the row's end node. */
static inline int cs_row_link(int k, int l, int lanes)
{
    return CS_CORNER[k][0] ? (l + 1 < lanes ? -1 : 3 * lanes) : 3 * l;
}

/* 8 nodes' interleaved (x, y, z) in three vectors (A: doubles 0–7, B: 8–15, C: 16–23) →
 * v[0] = their x, v[1] their y, v[2] their z: two two-source permutes each. */
static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
cs_xyz8_split(__m512d A, __m512d B, __m512d C, __m512d v[3])
{
    const __m512i lo[3] = {_mm512_setr_epi64(0, 3, 6, 9, 12, 15, 0, 0),
                           _mm512_setr_epi64(1, 4, 7, 10, 13, 0, 0, 0),
                           _mm512_setr_epi64(2, 5, 8, 11, 14, 0, 0, 0)};
    const __m512i hi[3] = {_mm512_setr_epi64(0, 1, 2, 3, 4, 5, 10, 13),
                           _mm512_setr_epi64(0, 1, 2, 3, 4, 8, 11, 14),
                           _mm512_setr_epi64(0, 1, 2, 3, 4, 9, 12, 15)};
    for (int i = 0; i < 3; i++)
        v[i] = _mm512_permutex2var_pd(_mm512_permutex2var_pd(A, lo[i], B), hi[i], C);
}

/* The inverse: x, y, z of 8 nodes (v) → their interleaved 24 doubles in o[0..2]. */
static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
cs_xyz8_join(const __m512d v[3], __m512d o[3])
{
    const __m512i ia[3] = {_mm512_setr_epi64(0, 8, 0, 1, 9, 0, 2, 10),
                           _mm512_setr_epi64(0, 3, 11, 0, 4, 12, 0, 5),
                           _mm512_setr_epi64(13, 0, 6, 14, 0, 7, 15, 0)};
    const __m512i ib[3] = {_mm512_setr_epi64(0, 1, 8, 3, 4, 9, 6, 7),
                           _mm512_setr_epi64(10, 1, 2, 11, 4, 5, 12, 7),
                           _mm512_setr_epi64(0, 13, 2, 3, 14, 5, 6, 15)};
    for (int i = 0; i < 3; i++)
        o[i] = _mm512_permutex2var_pd(_mm512_permutex2var_pd(v[0], ia[i], v[1]), ib[i], v[2]);
}

/* The same for 16 nodes in float: (x, y, z) interleaved in A (floats 0–15), B, C → v. */
static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
cs_xyz16_split(__m512 A, __m512 B, __m512 C, __m512 v[3])
{
    const __m512i lo[3] = {
        _mm512_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 0, 0, 0, 0, 0),
        _mm512_setr_epi32(1, 4, 7, 10, 13, 16, 19, 22, 25, 28, 31, 0, 0, 0, 0, 0),
        _mm512_setr_epi32(2, 5, 8, 11, 14, 17, 20, 23, 26, 29, 0, 0, 0, 0, 0, 0)};
    const __m512i hi[3] = {
        _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 17, 20, 23, 26, 29),
        _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 18, 21, 24, 27, 30),
        _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 19, 22, 25, 28, 31)};
    for (int i = 0; i < 3; i++)
        v[i] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(A, lo[i], B), hi[i], C);
}

static inline __attribute__((always_inline, target("arch=x86-64-v4"))) void
cs_xyz16_join(const __m512 v[3], __m512 o[3])
{
    const __m512i ia[3] = {
        _mm512_setr_epi32(0, 16, 0, 1, 17, 0, 2, 18, 0, 3, 19, 0, 4, 20, 0, 5),
        _mm512_setr_epi32(21, 0, 6, 22, 0, 7, 23, 0, 8, 24, 0, 9, 25, 0, 10, 26),
        _mm512_setr_epi32(0, 11, 27, 0, 12, 28, 0, 13, 29, 0, 14, 30, 0, 15, 31, 0)};
    const __m512i ib[3] = {
        _mm512_setr_epi32(0, 1, 16, 3, 4, 17, 6, 7, 18, 9, 10, 19, 12, 13, 20, 15),
        _mm512_setr_epi32(0, 21, 2, 3, 22, 5, 6, 23, 8, 9, 24, 11, 12, 25, 14, 15),
        _mm512_setr_epi32(26, 1, 2, 27, 4, 5, 28, 7, 8, 29, 10, 11, 30, 13, 14, 31)};
    for (int i = 0; i < 3; i++)
        o[i] = _mm512_permutex2var_ps(_mm512_permutex2var_ps(v[0], ia[i], v[1]), ib[i], v[2]);
}

#endif
