/*
 * cubemesh.c — seed 000 §2.1: cells in a hash table on integer (x,y,z), shared corner nodes.
 */
#include "cubemesh.h"

#include <stdio.h>
#include <stdlib.h>

const int CS_CORNER[8][3] = {
    {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1},
};

#define CS_IJK_LIMIT (1 << 20)

static int64_t pack(int32_t i, int32_t j, int32_t k)
{
    return ((int64_t)(i + CS_IJK_LIMIT) << 42) | ((int64_t)(j + CS_IJK_LIMIT) << 21) |
           (int64_t)(k + CS_IJK_LIMIT);
}

static uint64_t mix(int64_t key)
{
    uint64_t x = (uint64_t)key;
    x ^= x >> 33;
    x *= 0xff51afd7ed558ccdULL;
    x ^= x >> 33;
    x *= 0xc4ceb9fe1a85ec53ULL;
    x ^= x >> 33;
    return x;
}

int cs_ijk_hash_init(cs_ijk_hash *h, int expected)
{
    int cap = 16;
    while (cap < 2 * expected + 16)
        cap *= 2;
    h->keys = malloc((size_t)cap * sizeof *h->keys);
    h->vals = malloc((size_t)cap * sizeof *h->vals);
    h->cap = cap;
    h->count = 0;
    if (!h->keys || !h->vals) {
        cs_ijk_hash_free(h);
        return -1;
    }
    for (int s = 0; s < cap; s++)
        h->keys[s] = CS_HASH_EMPTY;
    return 0;
}

void cs_ijk_hash_free(cs_ijk_hash *h)
{
    free(h->keys);
    free(h->vals);
    h->keys = NULL;
    h->vals = NULL;
    h->cap = h->count = 0;
}

static int slot_of(const cs_ijk_hash *h, int64_t key)
{
    uint64_t mask = (uint64_t)h->cap - 1;
    uint64_t s = mix(key) & mask;
    while (h->keys[s] != CS_HASH_EMPTY && h->keys[s] != key)
        s = (s + 1) & mask;
    return (int)s;
}

int32_t cs_ijk_hash_get(const cs_ijk_hash *h, int32_t i, int32_t j, int32_t k)
{
    if (!h->cap || i <= -CS_IJK_LIMIT || j <= -CS_IJK_LIMIT || k <= -CS_IJK_LIMIT ||
        i >= CS_IJK_LIMIT || j >= CS_IJK_LIMIT || k >= CS_IJK_LIMIT)
        return -1;
    int64_t key = pack(i, j, k);
    int s = slot_of(h, key);
    return h->keys[s] == key ? h->vals[s] : -1;
}

static int grow(cs_ijk_hash *h)
{
    cs_ijk_hash n;
    if (cs_ijk_hash_init(&n, h->cap) != 0)
        return -1;
    for (int s = 0; s < h->cap; s++) {
        if (h->keys[s] == CS_HASH_EMPTY)
            continue;
        int t = slot_of(&n, h->keys[s]);
        n.keys[t] = h->keys[s];
        n.vals[t] = h->vals[s];
        n.count++;
    }
    cs_ijk_hash_free(h);
    *h = n;
    return 0;
}

int cs_ijk_hash_put(cs_ijk_hash *h, int32_t i, int32_t j, int32_t k, int32_t v)
{
    if (2 * (h->count + 1) > h->cap && grow(h) != 0)
        return -1;
    int64_t key = pack(i, j, k);
    int s = slot_of(h, key);
    if (h->keys[s] == CS_HASH_EMPTY) {
        h->keys[s] = key;
        h->count++;
    }
    h->vals[s] = v;
    return 0;
}

void cs_cubemesh_free(cs_cubemesh *cm)
{
    free(cm->cell_ijk);
    free(cm->cell_nodes);
    free(cm->node_rest);
    free(cm->spline_nodes);
    cs_ijk_hash_free(&cm->cells);
    cm->cell_ijk = cm->cell_nodes = cm->spline_nodes = NULL;
    cm->node_rest = NULL;
    cm->n_cells = cm->n_nodes = 0;
}

int32_t cs_cubemesh_find(const cs_cubemesh *cm, int32_t i, int32_t j, int32_t k)
{
    return cs_ijk_hash_get(&cm->cells, i, j, k);
}

int cs_cubemesh_build(cs_cubemesh *cm, double h, const double origin[3], const int32_t *ijk,
                      int n, char *err, size_t errlen)
{
    cs_ijk_hash nodes = {0};
    *cm = (cs_cubemesh){.h = h, .origin = {origin[0], origin[1], origin[2]}};
    if (n <= 0) {
        snprintf(err, errlen, "cube mesh has no cells");
        return -1;
    }
    cm->cell_ijk = malloc((size_t)n * 3 * sizeof *cm->cell_ijk);
    cm->cell_nodes = malloc((size_t)n * 8 * sizeof *cm->cell_nodes);
    /* A node count bound: every cell brings at most 8 new nodes. */
    cm->node_rest = malloc((size_t)n * 8 * 3 * sizeof *cm->node_rest);
    if (!cm->cell_ijk || !cm->cell_nodes || !cm->node_rest ||
        cs_ijk_hash_init(&cm->cells, n) != 0 || cs_ijk_hash_init(&nodes, 2 * n) != 0)
        goto nomem;
    for (int c = 0; c < n; c++) {
        const int32_t *q = ijk + 3 * c;
        for (int a = 0; a < 3; a++) {
            if (q[a] <= -CS_IJK_LIMIT + 1 || q[a] >= CS_IJK_LIMIT - 1) {
                snprintf(err, errlen, "cell %d index %d out of range (|index| <= %d)", c, (int)q[a],
                     CS_IJK_LIMIT - 2);
                goto fail;
            }
        }
        if (cs_ijk_hash_get(&cm->cells, q[0], q[1], q[2]) >= 0) {
            snprintf(err, errlen, "cell (%d,%d,%d) listed twice", (int)q[0], (int)q[1], (int)q[2]);
            goto fail;
        }
        if (cs_ijk_hash_put(&cm->cells, q[0], q[1], q[2], c) != 0)
            goto nomem;
        cm->cell_ijk[3 * c] = q[0];
        cm->cell_ijk[3 * c + 1] = q[1];
        cm->cell_ijk[3 * c + 2] = q[2];
        for (int k = 0; k < 8; k++) {
            int32_t a = q[0] + CS_CORNER[k][0], b = q[1] + CS_CORNER[k][1],
                    d = q[2] + CS_CORNER[k][2];
            int32_t v = cs_ijk_hash_get(&nodes, a, b, d);
            if (v < 0) {
                v = cm->n_nodes++;
                if (cs_ijk_hash_put(&nodes, a, b, d, v) != 0)
                    goto nomem;
                cm->node_rest[3 * v] = origin[0] + h * a;
                cm->node_rest[3 * v + 1] = origin[1] + h * b;
                cm->node_rest[3 * v + 2] = origin[2] + h * d;
            }
            cm->cell_nodes[8 * c + k] = v;
        }
        cm->n_cells = c + 1;
    }
    cs_ijk_hash_free(&nodes);
    double *shrunk = realloc(cm->node_rest, (size_t)cm->n_nodes * 3 * sizeof *shrunk);
    if (shrunk)
        cm->node_rest = shrunk;
    return 0;
nomem:
    snprintf(err, errlen, "out of memory building a cube mesh of %d cells", n);
fail:
    cs_ijk_hash_free(&nodes);
    cs_cubemesh_free(cm);
    return -1;
}
