/*
 * test_broadphase.c — the broad phase of the deformable objects' contacts (broadphase.h, used
 * by rigid.c soft_contacts and wake_near_movers).
 *
 * broadphase_*: cs_bp_find gives exactly the pairs, in the same order, that testing every pair
 * gives, on random boxes made to hit the cases a grid can get wrong: boxes that only touch (on
 * a face, an edge, a corner: integer coordinates, so touching is exact), nested and identical
 * boxes, points and flat boxes, sizes over five decades (several grid levels), boxes far out,
 * grown by margins from speeds as soft_contacts grows them, and boxes that take part in
 * nothing (NaN, infinite, lo > hi).
 *
 * soft_pairs_*: a world of deformable objects stepped twice, once with every pair of objects
 * tested (w->object_pairs_all, as before the broad phase) and once with the broad phase: the
 * two runs stay bit-identical (node positions and velocities, sleep), through blocks raining
 * onto blocks asleep on the ground (they wake: wake_near_movers) and a block broken into
 * pieces (kin: their born pairs, and their record of having been apart).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "broadphase.h"
#include "check.h"
#include "cubesim.h"
#include "lattice.h"
#include "world_internal.h"

static uint64_t rng = 0x9e3779b97f4a7c15ull;

static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) / 9007199254740992.0;
}

static int irand(int n)
{
    return (int)(urand() * n);
}

/* Every pair (i < j) of valid boxes that overlap, in (i, j) order: the reference. */
static int brute_pairs(const double *b, int n, int32_t *out)
{
    int m = 0;
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n; j++) {
            const double *p = b + 6 * i, *q = b + 6 * j;
            bool ok = true;
            for (int k = 0; k < 3; k++)
                ok = ok && isfinite(p[k]) && isfinite(p[3 + k]) && isfinite(q[k]) &&
                     isfinite(q[3 + k]) && p[k] <= p[3 + k] && q[k] <= q[3 + k] &&
                     p[k] <= q[3 + k] && q[k] <= p[3 + k];
            if (ok) {
                out[2 * m] = i;
                out[2 * m + 1] = j;
                m++;
            }
        }
    return m;
}

/* One random box of the mix (see the file's comment) into b[0..5]; earlier boxes b0[0..i). */
static void random_box(double *b, const double *b0, int i, double scale)
{
    const int kind = irand(10);
    double c[3], e[3];
    for (int k = 0; k < 3; k++) {
        c[k] = scale * (urand() - 0.5);
        e[k] = scale * 0.02 * urand();
    }
    switch (kind) {
    case 0: /* on the integer lattice, unit sizes: neighbours touch exactly */
    case 1:
        for (int k = 0; k < 3; k++) {
            b[k] = floor(c[k] / (scale * 0.02));
            b[3 + k] = b[k] + 1 + irand(2);
        }
        return;
    case 2: /* a copy of an earlier box, or one nested in it */
        if (i > 0) {
            const double *o = b0 + 6 * irand(i);
            const bool nest = irand(2);
            for (int k = 0; k < 3; k++) {
                const double w = o[3 + k] - o[k];
                b[k] = nest && isfinite(w) ? o[k] + 0.25 * w : o[k];
                b[3 + k] = nest && isfinite(w) ? o[3 + k] - 0.25 * w : o[3 + k];
            }
            return;
        }
        break;
    case 3: /* a point, or flat on one axis */
        for (int k = 0; k < 3; k++)
            b[k] = b[3 + k] = c[k];
        if (irand(2))
            for (int k = 0; k < 2; k++)
                b[3 + k] += e[k];
        return;
    case 4: /* large: up to half the scene */
        for (int k = 0; k < 3; k++) {
            b[k] = c[k];
            b[3 + k] = c[k] + scale * 0.5 * urand();
        }
        return;
    case 5: /* tiny */
        for (int k = 0; k < 3; k++) {
            b[k] = c[k];
            b[3 + k] = c[k] + e[k] * 1e-3;
        }
        return;
    case 6: /* takes part in nothing */
        for (int k = 0; k < 3; k++) {
            b[k] = c[k];
            b[3 + k] = c[k] + e[k];
        }
        b[irand(6)] = irand(3) == 0 ? NAN : irand(2) ? INFINITY : -INFINITY;
        if (irand(3) == 0) { /* or lo > hi */
            b[0] = c[0] + 1;
            b[3] = c[0];
        }
        return;
    default:
        break;
    }
    for (int k = 0; k < 3; k++) { /* ordinary */
        b[k] = c[k];
        b[3 + k] = c[k] + e[k];
    }
}

/* cs_bp_find against brute_pairs on n boxes; the message names the first difference. */
static bool same_as_brute(cs_bp *bp, const double *b, int n, char *why, size_t len)
{
    int32_t *ref = malloc((size_t)(n > 1 ? n * (n - 1) : 1) * sizeof *ref);
    if (!ref) {
        snprintf(why, len, "out of memory");
        return false;
    }
    const int m = brute_pairs(b, n, ref);
    bool ok = cs_bp_find(bp, b, 6, n) == 0;
    if (!ok)
        snprintf(why, len, "cs_bp_find failed");
    else if (bp->n_pairs != m)
        snprintf(why, len, "%d pairs, every pair's test gives %d", bp->n_pairs, m), ok = false;
    for (int k = 0; ok && k < m; k++)
        if (bp->pairs[2 * k] != ref[2 * k] || bp->pairs[2 * k + 1] != ref[2 * k + 1]) {
            snprintf(why, len, "pair %d is (%d, %d), should be (%d, %d)", k, bp->pairs[2 * k],
                     bp->pairs[2 * k + 1], ref[2 * k], ref[2 * k + 1]);
            ok = false;
        }
    free(ref);
    return ok;
}

TEST(broadphase_finds_every_overlapping_pair_once_in_order)
{
    static const int sizes[] = {0, 1, 2, 3, 16, 17, 40, 300, 2500};
    static const double scales[] = {1.0, 1e-6, 1e6};
    cs_bp bp = {0};
    char why[160];
    long total = 0;
    for (int si = 0; si < (int)(sizeof sizes / sizeof *sizes); si++)
        for (int sc = 0; sc < 3; sc++)
            for (int rep = 0; rep < 3; rep++) {
                const int n = sizes[si];
                double *b = malloc((size_t)(n ? n : 1) * 6 * sizeof *b);
                ENSURE(b);
                const double off = rep == 2 ? 1e4 * scales[sc] : 0; /* far from the origin */
                for (int i = 0; i < n; i++) {
                    random_box(b + 6 * i, b, i, scales[sc]);
                    for (int k = 0; k < 6; k++)
                        b[6 * i + k] += off;
                }
                const bool ok = same_as_brute(&bp, b, n, why, sizeof why);
                total += bp.n_pairs;
                free(b);
                if (!ok)
                    cs_bp_free(&bp);
                ENSURE_MSG(ok, "%d boxes, scale %g, run %d: %s", n, scales[sc], rep, why);
            }
    printf("    %ld overlapping pairs found, each as testing every pair finds it\n", total);
    cs_bp_free(&bp);
}

/* Boxes all alike (every one in one cell), all one point, and all taking part in nothing. */
TEST(broadphase_degenerate_sets)
{
    enum { N = 200 };
    static double b[6 * N];
    cs_bp bp = {0};
    char why[160];
    for (int i = 0; i < N; i++)
        for (int k = 0; k < 3; k++) {
            b[6 * i + k] = 1.0;
            b[6 * i + 3 + k] = 2.0;
        }
    ENSURE_MSG(same_as_brute(&bp, b, N, why, sizeof why), "identical boxes: %s", why);
    ENSURE(bp.n_pairs == N * (N - 1) / 2);
    for (int i = 0; i < N; i++)
        for (int k = 0; k < 3; k++)
            b[6 * i + 3 + k] = 1.0;
    ENSURE_MSG(same_as_brute(&bp, b, N, why, sizeof why), "one point: %s", why);
    ENSURE(bp.n_pairs == N * (N - 1) / 2);
    for (int i = 0; i < N; i++) /* a row of points 1 apart along x, and unit boxes touching */
        for (int k = 0; k < 3; k++) {
            b[6 * i + k] = k == 0 ? i : 0;
            b[6 * i + 3 + k] = k == 0 ? i + (i % 2) : 0;
        }
    ENSURE_MSG(same_as_brute(&bp, b, N, why, sizeof why), "a row: %s", why);
    for (int i = 0; i < N; i++)
        b[6 * i] = NAN;
    ENSURE_MSG(same_as_brute(&bp, b, N, why, sizeof why), "all NaN: %s", why);
    ENSURE(bp.n_pairs == 0);
    cs_bp_free(&bp);
}

/*
 * Boxes of nodes moving at random speeds, grown as soft_contacts grows them for the broad
 * phase (rigid.c soft_candidates: 2 dt v + 0.1 h and 1e-9 of the coordinates' size): every
 * pair soft_pair's own test (rigid.c, the boxes' overlap grown by dt (va + vb) +
 * 0.05 min(ha, hb) on each side) takes is among the pairs found, and those are exactly the
 * pairs whose grown boxes overlap.
 */
TEST(broadphase_covers_soft_contacts_margins)
{
    enum { N = 1500 };
    const double dt = 1.0 / 60;
    double *raw = malloc(N * 7 * sizeof *raw), *g = malloc(N * 6 * sizeof *g), *h = malloc(N * sizeof *h);
    int32_t *ref = malloc((size_t)N * (N - 1) * sizeof *ref);
    ENSURE(raw && g && h && ref);
    cs_bp bp = {0};
    char why[160];
    long needed = 0, found = 0;
    for (int i = 0; i < N; i++) {
        h[i] = irand(4) == 0 ? 0.01 : 0.1;
        const double side = h[i] * (1 + irand(3));
        for (int k = 0; k < 3; k++) {
            raw[7 * i + k] = 3.0 * urand() + (irand(5) == 0 ? 100 : 0);
            raw[7 * i + 3 + k] = raw[7 * i + k] + side;
        }
        raw[7 * i + 6] = irand(3) == 0 ? 0 : 10 * urand() * urand(); /* fastest node [m/s] */
        const double grow = 2 * dt * raw[7 * i + 6] + 0.1 * h[i];
        for (int k = 0; k < 3; k++) {
            const double slack = 1e-9 * (fabs(raw[7 * i + k]) + fabs(raw[7 * i + 3 + k]) + grow);
            g[6 * i + k] = raw[7 * i + k] - grow - slack;
            g[6 * i + 3 + k] = raw[7 * i + 3 + k] + grow + slack;
        }
    }
    bool ok = same_as_brute(&bp, g, N, why, sizeof why);
    for (int i = 0; ok && i < N; i++)
        for (int j = i + 1; ok && j < N; j++) {
            const double *a = raw + 7 * i, *b = raw + 7 * j;
            const double margin = dt * (a[6] + b[6]) + 0.05 * fmin(h[i], h[j]);
            bool over = true;
            for (int k = 0; k < 3; k++)
                over = over && fmax(a[k], b[k]) - margin <= fmin(a[3 + k], b[3 + k]) + margin;
            if (!over)
                continue;
            needed++;
            bool in = false; /* binary search of (i, j) in the sorted answer */
            for (int lo = 0, hi = bp.n_pairs; lo < hi && !in;) {
                const int mid = (lo + hi) / 2;
                const int32_t *p = bp.pairs + 2 * mid;
                if (p[0] == i && p[1] == j)
                    in = true;
                else if (p[0] < i || (p[0] == i && p[1] < j))
                    lo = mid + 1;
                else
                    hi = mid;
            }
            found += in;
            if (!in)
                snprintf(why, sizeof why, "pair (%d, %d) overlaps in soft_pair's test, not found",
                         i, j), ok = false;
        }
    printf("    %ld pairs in soft_pair's test, all among the %d found on the grown boxes\n",
           needed, bp.n_pairs);
    free(raw);
    free(g);
    free(h);
    free(ref);
    cs_bp_free(&bp);
    ENSURE_MSG(ok, "%s", why);
    ENSURE(needed > 100 && found == needed);
}

/* ------------------------------------------------------------------ the engine, both ways */

static cs_object_id add_block(cs_world_t *w, const char *name, int nx, int ny, int nz,
                              const double at[3], cs_model model, bool fracture)
{
    int32_t *ijk = cs_box_cells(nx, ny, nz);
    if (!ijk)
        return CS_NULL_OBJECT;
    cs_object_def d = cs_object_def_default();
    d.name = name;
    d.model = model;
    d.material.young = 1e5;
    d.material.damping[0] = 1;
    d.fracture = fracture;
    d.cube_size = 0.1;
    d.geometry = CS_GEOMETRY_CELLS;
    memcpy(d.cells_origin, at, sizeof d.cells_origin);
    d.cells_ijk = ijk;
    d.n_cells = nx * ny * nz;
    cs_object_id id = CS_NULL_OBJECT;
    char err[256];
    if (cs_world_add_object(w, &d, &id, err, sizeof err) != CS_OK) {
        fprintf(stderr, "add_block %s: %s\n", name, err);
        id = CS_NULL_OBJECT;
    }
    free(ijk);
    return id;
}

/*
 * The scene: a 3×3 grid of 2×2×2 blocks (E 1e5 Pa) on the ground (corotational, linear, mss by turns,
 * placed at random within 5 cm) and two more layers of them 0.6 m and 1.2 m up, which fall on
 * the first; sleep speed 0.3 m/s so that the blocks below sleep before the ones above land.
 * And a 4×2×2 block beside them broken into three pieces before the first step (kin born
 * touching); the test pushes them apart and back (their record of having been apart).
 */
static cs_world_t *rain_world(bool all_pairs, cs_object_id pieces[8], int *n_pieces)
{
    cs_world_def wd = cs_world_def_default();
    wd.has_ground = true;
    wd.threads = 1;
    wd.sleep_speed = 0.3;
    wd.sleep_steps = 10;
    cs_world_t *w = NULL;
    char err[256];
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK)
        return NULL;
    w->object_pairs_all = all_pairs;
    rng = 12345;
    for (int k = 0; k < 27; k++) {
        char name[16];
        snprintf(name, sizeof name, "b%d", k);
        const double at[3] = {(k % 3) * 0.35 + 0.05 * urand(), (k / 3 % 3) * 0.35 + 0.05 * urand(),
                              (k / 9) * 0.6};
        const cs_model m = k % 3 == 0 ? CS_MODEL_COROTATIONAL
                           : k % 3 == 1 ? CS_MODEL_LINEAR
                                        : CS_MODEL_MSS;
        if (add_block(w, name, 2, 2, 2, at, m, false) == CS_NULL_OBJECT) {
            cs_world_destroy(w);
            return NULL;
        }
    }
    const cs_object_id id = add_block(w, "breaks", 4, 2, 2, (double[3]){1.6, 0, 0},
                                      CS_MODEL_COROTATIONAL, false);
    const double n[3] = {1, 0, 0}, cut[2] = {1.85, 1.75};
    for (int c = 0; c < 2 && id != CS_NULL_OBJECT; c++) {
        cs_object_id at = CS_NULL_OBJECT; /* the piece holding the cut's cell */
        for (int k = 0; k < w->n_objects; k++) {
            const cs_object *o = w->objects[k];
            double lo = INFINITY, hi = -INFINITY;
            for (int i = 0; i < o->n; i++) {
                lo = fmin(lo, o->x[3 * i]);
                hi = fmax(hi, o->x[3 * i]);
            }
            if (o->kin == id && lo < cut[c] && hi > cut[c])
                at = o->id;
        }
        const double p[3] = {cut[c], 0.05, 0.05};
        if (at == CS_NULL_OBJECT || cs_world_fracture(w, at, p, n, 1.0, err, sizeof err) != CS_OK) {
            fprintf(stderr, "rain_world: cut %d: %s\n", c, at ? err : "no piece there");
            cs_world_destroy(w);
            return NULL;
        }
    }
    *n_pieces = 0;
    for (int k = 0; k < w->n_objects; k++)
        if (w->objects[k]->kin == id)
            pieces[(*n_pieces)++] = w->objects[k]->id;
    return w;
}

/* Whether a and b hold the same objects in the same state, bit for bit. */
static bool same_state(const cs_world_t *a, const cs_world_t *b, char *why, size_t len)
{
    if (a->n_objects != b->n_objects) {
        snprintf(why, len, "%d objects against %d", a->n_objects, b->n_objects);
        return false;
    }
    for (int i = 0; i < a->n_objects; i++) {
        const cs_object *p = a->objects[i], *q = b->objects[i];
        if (p->id != q->id || p->n != q->n || p->sleeping != q->sleeping ||
            memcmp(p->x, q->x, 3 * (size_t)p->n * sizeof *p->x) != 0 ||
            memcmp(p->v, q->v, 3 * (size_t)p->n * sizeof *p->v) != 0) {
            snprintf(why, len, "object %d (id %u) differs", i, (unsigned)p->id);
            return false;
        }
    }
    return true;
}

TEST(soft_pairs_broad_phase_steps_as_every_pair)
{
    cs_object_id pa[8], pb[8];
    int na = 0, nb = 0;
    cs_world_t *W[2] = {rain_world(true, pa, &na), rain_world(false, pb, &nb)};
    ENSURE_MSG(W[0] && W[1], "the scene could not be made");
    ENSURE_MSG(na == 3 && nb == 3, "%d pieces", na);
    char why[160], err[256];
    bool same = true;
    int max_asleep = 0, woke = 0, prev = 0, s = 0;
    for (; s < 180 && same; s++) {
        for (int k = 0; k < 2; k++) {
            /* the outer pieces pushed apart along x (3 N for 0.2 s), then back */
            const double f = s == 40 ? 3 : s == 110 ? -3 : 0;
            for (int q = 0; f != 0 && q < 3; q++) {
                const cs_object *o = cs_world_find_internal(W[k], pa[q]);
                double c = 0;
                for (int i = 0; i < o->n; i++)
                    c += o->x[3 * i] / o->n;
                const double side = c < 1.7 ? -1 : c > 1.8 ? 1 : 0;
                const double at[3] = {c, 0.1, 0.1}, F[3] = {side * f, 0, 0};
                if (side != 0)
                    ENSURE_MSG(cs_world_apply_force(W[k], pa[q], at, F, 0.2, err, sizeof err) ==
                                   CS_OK, "%s", err);
            }
            ENSURE(cs_world_step(W[k]) == CS_OK);
        }
        same = same_state(W[0], W[1], why, sizeof why);
        int asleep = 0;
        for (int i = 0; i < W[1]->n_objects; i++)
            asleep += W[1]->objects[i]->sleeping;
        max_asleep = asleep > max_asleep ? asleep : max_asleep;
        woke += asleep < prev;
        prev = asleep;
    }
    /* the scene did what it is for: blocks slept and woke, blocks rest on blocks, the pieces
     * came apart */
    int stacked = 0, apart = 0;
    for (int i = 0; i < W[1]->n_objects; i++) {
        const cs_object *o = W[1]->objects[i];
        double zmin = INFINITY;
        for (int k = 0; k < o->n; k++)
            zmin = fmin(zmin, o->x[3 * k + 2]);
        stacked += zmin > 0.15;
        apart += o->kin == W[1]->objects[W[1]->n_objects - 1]->kin && o->n_apart > 0;
    }
    printf("    %d steps bit-identical: up to %d objects asleep, %d steps woke some, %d blocks "
           "resting on blocks, %d pieces recorded apart from their kin\n",
           s, max_asleep, woke, stacked, apart);
    cs_world_destroy(W[0]);
    cs_world_destroy(W[1]);
    ENSURE_MSG(same, "step %d: %s", s, why);
    ENSURE(max_asleep >= 9 && woke > 0 && stacked >= 4 && apart >= 2);
}
