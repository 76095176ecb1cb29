/*
 * lattice.h — the cell indices of an nx × ny × nz box of cubes (i fastest, then j, then k),
 * the cs_object_def.cells of every box the tests and benchmarks build. Header-only.
 */
#ifndef CS_LATTICE_H
#define CS_LATTICE_H

#include <stdint.h>
#include <stdlib.h>

/* 3 per cell, malloc'd (the caller frees it); NULL on out of memory. */
static inline int32_t *cs_box_cells(int nx, int ny, int nz)
{
    int32_t *ijk = malloc(sizeof *ijk * 3 * (size_t)nx * (size_t)ny * (size_t)nz);
    if (!ijk)
        return NULL;
    size_t c = 0;
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++, c++) {
                ijk[3 * c] = i;
                ijk[3 * c + 1] = j;
                ijk[3 * c + 2] = k;
            }
    return ijk;
}

#endif
