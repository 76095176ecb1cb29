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

#endif
