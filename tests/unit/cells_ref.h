/*
 * cells_ref.h — a cube mesh from a list of lattice cells, in their order or shuffled: the
 * scrambled meshes of the product and layout tests (test_products.c, test_mg_layout.c).
 */
#ifndef CS_TEST_CELLS_REF_H
#define CS_TEST_CELLS_REF_H

#include <stdlib.h>

#include "cubemesh.h"

/* Builds cm with cube size h from the n cells ijk (3 per cell; freed here), first shuffled
 * (Fisher–Yates, rand_r from seed) unless seed is 0. Returns cs_cubemesh_build's code, -1 if
 * ijk is NULL. */
static inline int cells_build(cs_cubemesh *cm, double h, int32_t *ijk, int n, unsigned seed)
{
    if (!ijk)
        return -1;
    for (int c = n - 1; seed && c > 0; c--) {
        const int d = rand_r(&seed) % (c + 1);
        for (int a = 0; a < 3; a++) {
            const int32_t t = ijk[3 * c + a];
            ijk[3 * c + a] = ijk[3 * d + a];
            ijk[3 * d + a] = t;
        }
    }
    char err[128];
    const double origin[3] = {0, 0, 0};
    const int rc = cs_cubemesh_build(cm, h, origin, ijk, n, err, sizeof err);
    free(ijk);
    return rc;
}

#endif
