/*
 * broadphase.h — the pairs of overlapping axis-aligned boxes among n, without testing every
 * pair: a hierarchical uniform grid (each box filed in the level whose cells are at least its
 * size, so it covers at most two cells per axis there), so the cost grows as n log n (the sort
 * of the filed cells) for boxes that are spread out, whatever their sizes.
 *
 * Exact: the answer is the same set of pairs a test of every pair gives, in the same order.
 * A pair is reported once, in the first cell both boxes cover.
 *
 * Owns: cs_bp holds its scratch and the answer, reused from call to call (a steady caller
 * allocates nothing); cs_bp_free releases them. Not thread-safe per cs_bp.
 */
#ifndef CS_BROADPHASE_H
#define CS_BROADPHASE_H

#include <stddef.h>
#include <stdint.h>

typedef struct cs_bp_cell cs_bp_cell;   /* private */
typedef struct cs_bp_entry cs_bp_entry; /* private */

typedef struct cs_bp {
    /* the answer of the last cs_bp_find: n_pairs pairs (i, j), i < j, box indices, sorted by
     * i then j; pairs[2k], pairs[2k + 1] */
    int32_t *pairs;
    int n_pairs, cap_pairs;
    /* scratch */
    cs_bp_cell *cell; /* per box */
    double *ext;      /* per box */
    int cap_box;
    cs_bp_entry *ent;
    size_t cap_ent;
} cs_bp;

/*
 * The pairs (i, j), i < j < n, of boxes whose closed boxes overlap: for every axis k,
 * lo_i[k] <= hi_j[k] and lo_j[k] <= hi_i[k], where box i is box[i·stride + 0..2] (lo) and
 * box[i·stride + 3..5] (hi). A box with a coordinate that is not finite, or lo > hi on an axis,
 * takes part in no pair (a caller marks boxes that are not to take part with NaN). Into
 * bp->pairs, sorted by (i, j). Returns 0, or -1 when out of memory (bp->n_pairs is then 0).
 */
int cs_bp_find(cs_bp *bp, const double *box, size_t stride, int n);

/* A growing list of pairs (i, j), 2 int32 each, stored as (min, max): append one (the array
 * doubles from 256 pairs). Returns 0, or -1 when out of memory (the list unchanged). */
int cs_pair_push(int32_t **pairs, int *n, int *cap, int32_t i, int32_t j);
/* qsort order of such pairs: by the first index, then the second. */
int cs_pair_cmp(const void *x, const void *y);

/* Frees bp's arrays (not bp); it may be used again after. */
void cs_bp_free(cs_bp *bp);

#endif
