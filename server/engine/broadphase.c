/*
 * broadphase.c — overlapping box pairs by a hierarchical uniform grid (broadphase.h).
 *
 * Level L has cubic cells of edge c_L = c_0 2^L from the corner of the boxes' common bounds,
 * c_0 the median of the boxes' largest extents (no smaller than 2^-18 of the bounds, so that a
 * cell index fits in 19 bits). A box is filed in the cells it covers at the lowest level whose
 * cells are at least its largest extent: two per axis at most (three if rounding says so).
 * The cell index of a coordinate x at level L, floor((x − corner) / c_L), never decreases as x
 * grows, so two boxes that overlap cover a common cell on every axis of any level: the cell
 * whose index on each axis is the larger of their lowest ones. A pair is reported there only:
 * two boxes of one level by the run of entries filed in that cell; a box and one of a higher
 * level by the lower one looking up its own cells of that level. Each candidate is then tested
 * on the boxes themselves, so the answer is exactly the pairs that overlap.
 *
 * Cost: the sort of the filed entries (at most 8 per box, normally) and, per box, the boxes
 * filed with it in a cell, plus a few binary searches for each higher level that holds boxes.
 * Boxes much smaller than the median crowd a cell only where they crowd space.
 */
#include "broadphase.h"

#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#define BP_BRUTE 16    /* at most this many boxes: every pair is tested */
#define BP_BITS 19     /* bits of a cell index per axis */
#define BP_SPAN 18     /* the bounds are at most 2^BP_SPAN cells of level 0 */
#define BP_LEVELS (BP_SPAN + 1)

/* A box as filed: its level and its range of cells there. */
struct cs_bp_cell {
    int level;
    int32_t lo[3], hi[3];
};

/* One cell a box covers: key = level, then the cell's indices (BP_BITS bits each). */
struct cs_bp_entry {
    uint64_t key;
    int32_t box;
};

static const double *box_at(const double *box, size_t stride, int i)
{
    return box + (size_t)i * stride;
}

static bool valid(const double *b)
{
    for (int k = 0; k < 3; k++)
        if (!isfinite(b[k]) || !isfinite(b[3 + k]) || b[k] > b[3 + k])
            return false;
    return true;
}

static bool overlap(const double *a, const double *b)
{
    for (int k = 0; k < 3; k++)
        if (!(a[k] <= b[3 + k] && b[k] <= a[3 + k]))
            return false;
    return true;
}

static uint64_t cell_key(int level, const int32_t c[3])
{
    return (uint64_t)level << (3 * BP_BITS) | (uint64_t)c[0] << (2 * BP_BITS) |
           (uint64_t)c[1] << BP_BITS | (uint64_t)c[2];
}

int cs_pair_push(int32_t **pairs, int *n, int *cap, int32_t i, int32_t j)
{
    if (*n == *cap) {
        const int c = *cap ? 2 * *cap : 256;
        int32_t *g = realloc(*pairs, (size_t)c * 2 * sizeof *g);
        if (!g)
            return -1;
        *pairs = g;
        *cap = c;
    }
    (*pairs)[2 * *n] = i < j ? i : j;
    (*pairs)[2 * *n + 1] = i < j ? j : i;
    (*n)++;
    return 0;
}

static int push_pair(cs_bp *bp, int32_t i, int32_t j)
{
    return cs_pair_push(&bp->pairs, &bp->n_pairs, &bp->cap_pairs, i, j);
}

static int cmp_double(const void *x, const void *y)
{
    const double a = *(const double *)x, b = *(const double *)y;
    return a < b ? -1 : a > b;
}

static int cmp_entry(const void *x, const void *y)
{
    const cs_bp_entry *a = x, *b = y;
    if (a->key != b->key)
        return a->key < b->key ? -1 : 1;
    return (a->box > b->box) - (a->box < b->box);
}

int cs_pair_cmp(const void *x, const void *y)
{
    const int32_t *a = x, *b = y;
    if (a[0] != b[0])
        return (a[0] > b[0]) - (a[0] < b[0]);
    return (a[1] > b[1]) - (a[1] < b[1]);
}

/* The first entry at or after key in ent[0..n) (sorted), n if none. */
static size_t lower_bound(const cs_bp_entry *ent, size_t n, uint64_t key)
{
    size_t lo = 0, hi = n;
    while (lo < hi) {
        const size_t mid = lo + (hi - lo) / 2;
        if (ent[mid].key < key)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* Every pair of valid boxes, tested (already in (i, j) order). */
static int brute(cs_bp *bp, const double *box, size_t stride, int n)
{
    for (int i = 0; i < n; i++) {
        const double *a = box_at(box, stride, i);
        if (!valid(a))
            continue;
        for (int j = i + 1; j < n; j++) {
            const double *b = box_at(box, stride, j);
            if (valid(b) && overlap(a, b) && push_pair(bp, i, j) != 0)
                return -1;
        }
    }
    return 0;
}

/* The cells [lo, hi] that box b covers at the level of cell size c. */
static void cell_range(const double *b, const double corner[3], double c, int32_t lo[3],
                       int32_t hi[3])
{
    for (int k = 0; k < 3; k++) {
        lo[k] = (int32_t)floor((b[k] - corner[k]) / c);
        hi[k] = (int32_t)floor((b[3 + k] - corner[k]) / c);
    }
}

static int find(cs_bp *bp, const double *box, size_t stride, int n)
{
    int nv = 0;
    double corner[3] = {INFINITY, INFINITY, INFINITY}, top[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < n; i++) {
        const double *b = box_at(box, stride, i);
        if (!valid(b))
            continue;
        nv++;
        for (int k = 0; k < 3; k++) {
            corner[k] = fmin(corner[k], b[k]);
            top[k] = fmax(top[k], b[3 + k]);
        }
    }
    if (nv < 2)
        return 0;
    double span = 0;
    for (int k = 0; k < 3; k++)
        span = fmax(span, top[k] - corner[k]);
    if (nv <= BP_BRUTE || !isfinite(span))
        return brute(bp, box, stride, n); /* (bounds beyond the doubles: nothing to grid) */

    if (n > bp->cap_box) {
        double *e = realloc(bp->ext, (size_t)n * sizeof *e);
        cs_bp_cell *c = e ? realloc(bp->cell, (size_t)n * sizeof *c) : NULL;
        if (e)
            bp->ext = e;
        if (!c)
            return -1;
        bp->cell = c;
        bp->cap_box = n;
    }
    int m = 0;
    for (int i = 0; i < n; i++) {
        const double *b = box_at(box, stride, i);
        if (valid(b))
            bp->ext[m++] = fmax(fmax(b[3] - b[0], b[4] - b[1]), b[5] - b[2]);
    }
    qsort(bp->ext, (size_t)m, sizeof *bp->ext, cmp_double);
    double c0 = fmax(bp->ext[m / 2], ldexp(span, -BP_SPAN));
    if (!(c0 > 0))
        c0 = span > 0 ? span : 1.0; /* every box one point (or the bounds are subnormal) */

    /* file every box at its level */
    size_t n_ent = 0;
    unsigned levels = 0;
    for (int i = 0; i < n; i++) {
        const double *b = box_at(box, stride, i);
        cs_bp_cell *f = &bp->cell[i];
        f->level = -1;
        if (!valid(b))
            continue;
        const double e = fmax(fmax(b[3] - b[0], b[4] - b[1]), b[5] - b[2]);
        int L = 0;
        while (L < BP_SPAN && e > ldexp(c0, L))
            L++;
        f->level = L;
        levels |= 1u << L;
        cell_range(b, corner, ldexp(c0, L), f->lo, f->hi);
        n_ent += (size_t)(f->hi[0] - f->lo[0] + 1) * (size_t)(f->hi[1] - f->lo[1] + 1) *
                 (size_t)(f->hi[2] - f->lo[2] + 1);
    }
    if (n_ent > bp->cap_ent) {
        cs_bp_entry *g = realloc(bp->ent, n_ent * sizeof *g);
        if (!g)
            return -1;
        bp->ent = g;
        bp->cap_ent = n_ent;
    }
    size_t k = 0;
    for (int i = 0; i < n; i++) {
        const cs_bp_cell *f = &bp->cell[i];
        if (f->level < 0)
            continue;
        int32_t c[3];
        for (c[0] = f->lo[0]; c[0] <= f->hi[0]; c[0]++)
            for (c[1] = f->lo[1]; c[1] <= f->hi[1]; c[1]++)
                for (c[2] = f->lo[2]; c[2] <= f->hi[2]; c[2]++)
                    bp->ent[k++] = (cs_bp_entry){cell_key(f->level, c), i};
    }
    qsort(bp->ent, n_ent, sizeof *bp->ent, cmp_entry);

    /* boxes of one level, in the first cell both cover */
    for (size_t r0 = 0, r1; r0 < n_ent; r0 = r1) {
        for (r1 = r0 + 1; r1 < n_ent && bp->ent[r1].key == bp->ent[r0].key; r1++)
            ;
        const uint64_t mask = ((uint64_t)1 << BP_BITS) - 1, key = bp->ent[r0].key;
        const int32_t here[3] = {(int32_t)(key >> (2 * BP_BITS) & mask),
                                 (int32_t)(key >> BP_BITS & mask), (int32_t)(key & mask)};
        for (size_t p = r0; p < r1; p++) {
            const int32_t a = bp->ent[p].box;
            const cs_bp_cell *fa = &bp->cell[a];
            for (size_t q = p + 1; q < r1; q++) {
                const int32_t b = bp->ent[q].box;
                const cs_bp_cell *fb = &bp->cell[b];
                bool first = true;
                for (int ax = 0; ax < 3; ax++)
                    first = first && (fa->lo[ax] > fb->lo[ax] ? fa->lo[ax] : fb->lo[ax]) == here[ax];
                if (first && overlap(box_at(box, stride, a), box_at(box, stride, b)) &&
                    push_pair(bp, a, b) != 0)
                    return -1;
            }
        }
    }

    /* a box and those of higher levels, in the first cell both cover there */
    for (int i = 0; i < n; i++) {
        const cs_bp_cell *fa = &bp->cell[i];
        if (fa->level < 0)
            continue;
        const double *a = box_at(box, stride, i);
        for (int L = fa->level + 1; L < BP_LEVELS; L++) {
            if (!(levels >> L & 1u))
                continue;
            int32_t lo[3], hi[3], c[3];
            cell_range(a, corner, ldexp(c0, L), lo, hi);
            for (c[0] = lo[0]; c[0] <= hi[0]; c[0]++)
                for (c[1] = lo[1]; c[1] <= hi[1]; c[1]++)
                    for (c[2] = lo[2]; c[2] <= hi[2]; c[2]++) {
                        const uint64_t key = cell_key(L, c);
                        for (size_t q = lower_bound(bp->ent, n_ent, key);
                             q < n_ent && bp->ent[q].key == key; q++) {
                            const int32_t b = bp->ent[q].box;
                            const cs_bp_cell *fb = &bp->cell[b];
                            bool first = true;
                            for (int ax = 0; ax < 3; ax++)
                                first = first && (lo[ax] > fb->lo[ax] ? lo[ax] : fb->lo[ax]) == c[ax];
                            if (first && overlap(a, box_at(box, stride, b)) &&
                                push_pair(bp, i, b) != 0)
                                return -1;
                        }
                    }
        }
    }
    if (bp->n_pairs > 0) /* (pairs is NULL until the first one) */
        qsort(bp->pairs, (size_t)bp->n_pairs, 2 * sizeof *bp->pairs, cs_pair_cmp);
    return 0;
}

int cs_bp_find(cs_bp *bp, const double *box, size_t stride, int n)
{
    bp->n_pairs = 0;
    if (find(bp, box, stride, n) != 0) {
        bp->n_pairs = 0;
        return -1;
    }
    return 0;
}

void cs_bp_free(cs_bp *bp)
{
    free(bp->pairs);
    free(bp->cell);
    free(bp->ent);
    free(bp->ext);
    *bp = (cs_bp){0};
}
