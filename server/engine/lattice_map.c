/*
 * lattice_map.c — see lattice_map.h.
 */
#include "lattice_map.h"

#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include <omp.h>

void cs_lattice_map_free(cs_lattice_map *m)
{
    free(m->node);
    free(m->cell);
    free(m->gbase);
    free(m->grun);
    free(m->grest);
    memset(m, 0, sizeof *m);
}

int cs_lattice_map_build(cs_lattice_map *m, const cs_cubemesh *cm, int lanes)
{
    memset(m, 0, sizeof *m);
    const int nc = cm->n_cells, nn = cm->n_nodes;
    if (nc == 0 || nn == 0 || lanes < 1 || lanes > 16)
        return 0;
    int32_t lo[3], hi[3];
    for (int a = 0; a < 3; a++)
        lo[a] = hi[a] = cm->cell_ijk[a];
    for (int c = 0; c < nc; c++)
        for (int a = 0; a < 3; a++) {
            const int32_t v = cm->cell_ijk[3 * (size_t)c + a];
            lo[a] = v < lo[a] ? v : lo[a];
            hi[a] = v > hi[a] ? v : hi[a];
        }
    const int64_t nx = (int64_t)hi[0] - lo[0] + 1, ny = (int64_t)hi[1] - lo[1] + 1,
                  nz = (int64_t)hi[2] - lo[2] + 1;
    const int64_t nxb = (nx + lanes - 1) / lanes, sx = lanes * nxb + lanes;
    /* each factor at most 2^21 + 17 (cubemesh.h: indices within ±2^20): no overflow */
    if (sx * (ny + 1) > INT32_MAX / 16)
        return 0;
    const int64_t npos = sx * (ny + 1) * (nz + 1), nb = nxb * ny * nz;
    if (npos > 3 * ((int64_t)nn + 4096) || npos > INT32_MAX / 16 || nb * lanes > INT32_MAX / 16)
        return 0; /* a sparse box */
    m->nx = (int)nx, m->ny = (int)ny, m->nz = (int)nz;
    m->lanes = lanes, m->nxb = (int)nxb, m->sx = (int)sx;
    m->layer = (size_t)(sx * (ny + 1));
    m->npos = (size_t)npos;
    m->node = malloc((size_t)npos * sizeof(int32_t));
    m->cell = malloc((size_t)(nb * lanes) * sizeof(int32_t));
    if (!m->node || !m->cell) {
        cs_lattice_map_free(m);
        return -1;
    }
    for (int64_t q = 0; q < npos; q++)
        m->node[q] = -1;
    for (int64_t s = 0; s < nb * lanes; s++)
        m->cell[s] = -1;
    uint8_t *put = calloc((size_t)nn, 1); /* nodes placed: each at one place only */
    if (!put) {
        cs_lattice_map_free(m);
        return -1;
    }
    bool ok = true;
    for (int c = 0; c < nc && ok; c++) {
        const int32_t *ijk = cm->cell_ijk + 3 * (size_t)c;
        const int64_t i = ijk[0] - lo[0], j = ijk[1] - lo[1], k = ijk[2] - lo[2];
        int32_t *slot = &m->cell[i + lanes * nxb * (j + ny * k)];
        ok = *slot < 0; /* two cells at one lattice index (a coarse level across a crack) */
        *slot = c;
        for (int kk = 0; kk < 8 && ok; kk++) {
            const int64_t q = (i + CS_CORNER[kk][0]) +
                              sx * ((j + CS_CORNER[kk][1]) + (ny + 1) * (k + CS_CORNER[kk][2]));
            const int32_t n = cm->cell_nodes[8 * (size_t)c + kk];
            if (n < 0 || n >= nn) {
                ok = false;
            } else if (m->node[q] < 0) {
                ok = !put[n]; /* not placed elsewhere already */
                put[n] = 1;
                m->node[q] = n;
            } else {
                ok = m->node[q] == n;
            }
        }
    }
    /* every node at one place: none split (fracture), none at two places, none without a
     * cell */
    int64_t placed = 0;
    for (int64_t q = 0; q < npos && ok; q++)
        placed += m->node[q] >= 0;
    free(put);
    if (!ok || placed != nn) {
        cs_lattice_map_free(m);
        return 0;
    }
    /* the groups' runs */
    const int64_t ng = npos / lanes;
    m->gbase = malloc((size_t)ng * sizeof(int32_t));
    m->grun = malloc((size_t)ng * sizeof(uint16_t));
    m->grest = malloc((size_t)ng * sizeof(uint16_t));
    if (!m->gbase || !m->grun || !m->grest) {
        cs_lattice_map_free(m);
        return -1;
    }
    for (int64_t g = 0; g < ng; g++) {
        const int32_t *nd = m->node + g * lanes;
        int last = -1;
        for (int l = 0; l < lanes; l++)
            last = nd[l] >= 0 ? l : last;
        const int32_t base = last >= 0 ? nd[last] - last : 0;
        unsigned run = 0, rest = 0;
        for (int l = 0; l < lanes; l++)
            if (nd[l] >= 0) {
                if (nd[l] == base + l)
                    run |= 1u << l;
                else
                    rest |= 1u << l;
            }
        m->gbase[g] = base;
        m->grun[g] = (uint16_t)run;
        m->grest[g] = (uint16_t)rest;
    }
    /* the part boundary: the cell layer that splits the cells most evenly */
    int64_t seen = 0, best = -1;
    m->kmid = m->nz;
    for (int64_t k = 0; k < nz; k++) {
        if (k > 0) {
            const int64_t d = 2 * seen > nc ? 2 * seen - nc : nc - 2 * seen;
            if (best < 0 || d < best) {
                best = d;
                m->kmid = (int)k;
            }
        }
        for (int64_t s = lanes * nxb * ny * k; s < lanes * nxb * ny * (k + 1); s++)
            seen += m->cell[s] >= 0;
    }
    return 1;
}

void *cs_lattice_zalloc(size_t n)
{
    const size_t bytes = (n + 63) / 64 * 64;
    void *p = aligned_alloc(64, bytes ? bytes : 64);
    if (p)
        memset(p, 0, bytes ? bytes : 64);
    return p;
}

void cs_lattice_bufs_free(cs_lattice_bufs *b)
{
    for (int a = 0; a < 2; a++)
        for (int c = 0; c < 2; c++) {
            free(b->ps[a][c]);
            free(b->ys[a][c]);
        }
    free(b->mid);
    free(b->seam);
    memset(b, 0, sizeof *b);
}

int cs_lattice_bufs_alloc(cs_lattice_bufs *b, const cs_lattice_map *m, size_t elem)
{
    const size_t n = 3 * m->layer * elem;
    bool got = true;
    for (int a = 0; a < 2; a++)
        for (int c = 0; c < 2; c++) {
            b->ps[a][c] = cs_lattice_zalloc(n);
            b->ys[a][c] = cs_lattice_zalloc(n);
            got = got && b->ps[a][c] && b->ys[a][c];
        }
    b->mid = cs_lattice_zalloc(n);
    b->seam = cs_lattice_zalloc(n);
    if (got && b->mid && b->seam)
        return 0;
    cs_lattice_bufs_free(b);
    return -1;
}

/* One part: cell layers [k0, k1); with two parts the first keeps node layer k1's sums in mid
 * and the second node layer k0's in seam, for after the barrier. */
static void run_part(cs_lattice_bufs *b, const cs_lattice_pass *p, int part, int k0, int k1,
                     bool split)
{
    void *const *ps = b->ps[part], *const *ys = b->ys[part];
    p->in(p->ctx, k0, ps[k0 & 1]);
    for (int k = k0; k < k1; k++) {
        p->in(p->ctx, k + 1, ps[(k + 1) & 1]);
        void *yl = split && part == 1 && k == k0 ? b->seam : ys[k & 1];
        void *yh = split && part == 0 && k + 1 == k1 ? b->mid : ys[(k + 1) & 1];
        p->cells(p->ctx, k, ps[k & 1], ps[(k + 1) & 1], yl, yh, k == k0);
        if (yl != b->seam)
            p->out(p->ctx, k, yl, NULL, ps[k & 1]);
    }
    if (!(split && part == 0))
        p->out(p->ctx, k1, ys[k1 & 1], NULL, ps[k1 & 1]);
}

void cs_lattice_run(const cs_lattice_map *m, int threads, cs_lattice_bufs *b,
                    const cs_lattice_pass *p)
{
    const bool split = m->kmid < m->nz;
#pragma omp parallel num_threads(split && threads > 1 ? 2 : 1) /* one per part */
    {
        const int nt = omp_get_num_threads(), t = omp_get_thread_num();
        for (int part = t; part < (split ? 2 : 1); part += nt)
            run_part(b, p, part, part ? m->kmid : 0, part ? m->nz : m->kmid, split);
        if (split) {
#pragma omp barrier
            if (t == nt - 1)
                p->out(p->ctx, m->kmid, b->mid, b->seam, NULL);
        }
    }
}
