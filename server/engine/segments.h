/*
 * segments.h — the second phase of a fused product pass, shared out among the threads.
 *
 * A fused pass (fem.c fused_pass, mg.c apply_path) gives each thread its segments of cell
 * batches; a node whose cells are all in one segment is finished by that segment's thread,
 * and a node whose cells straddle a segment boundary is finished after the barrier. Those
 * nodes' rows depend on nothing but their own inputs and the cells' stored results, so any
 * thread may compute any of them, with the same bits. Giving each segment's shared nodes to
 * its own thread left thread 0 (the first segment has none) waiting at the pass's end for
 * the others' (about 2.6 % of a 64³ finest-level product on two threads); here the position
 * ranges of all segments are laid end to end and cut into equal parts, one per thread.
 */
#ifndef CS_SEGMENTS_H
#define CS_SEGMENTS_H

#include <stdint.h>

/* Of a range of len positions that starts `before` positions into a sequence of `total`, the
 * part [*lo, *hi) (relative to the range; empty if *lo >= *hi) that falls in thread t's
 * equal share of the sequence among nt threads. */
static inline void cs_segment_share(int64_t before, int64_t len, int64_t total, int t, int nt,
                                    int64_t *lo, int64_t *hi)
{
    const int64_t a = total * t / nt, b = total * (t + 1) / nt;
    *lo = a > before ? a - before : 0;
    *hi = b < before + len ? b - before : len;
}

#endif
