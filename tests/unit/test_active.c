/*
 * test_active.c — active regions inside an awake object (world.c "active regions", issue 7,
 * seed 000 §2.2): a block at rest is frozen node by node; a poke at one corner wakes a small
 * region and the displacement field agrees with the all-active solve; a later push elsewhere
 * wakes that region; the object still falls asleep as before.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "lattice.h"
#include "scene.h"

typedef struct blk {
    cs_world_t *w;
    cs_object_id id;
    int32_t *ijk;
    int n;
} blk;

/* An n³ block of 1 m (h = 1/n), bottom face held, corotational, damped, gravity on; active
 * regions on when active_steps > 0. */
static int make_block(blk *b, int n, int nz, int active_steps, bool gravity, int sleep_steps)
{
    char err[256];
    memset(b, 0, sizeof *b);
    cs_world_def wd = cs_world_def_default();
    wd.active_steps = active_steps;
    wd.sleep_steps = sleep_steps;
    wd.threads = 1; /* the results do not depend on it; a loaded machine stalls barriers */
    if (!gravity)
        wd.gravity[2] = 0;
    if (cs_world_create(&wd, &b->w, err, sizeof err) != CS_OK)
        return -1;
    int nc = n * n * nz;
    b->n = n;
    b->ijk = cs_box_cells(n, n, nz);
    cs_object_def d = cs_object_def_default();
    d.name = "block";
    d.cube_size = 1.0 / n;
    d.material.young = 1e5;
    d.material.damping[0] = 2.0;
    d.material.damping[1] = 0.01;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = b->ijk;
    d.n_cells = nc;
    cs_aabb fix = {{-1, -1, -1e-3 / n}, {2, 2, 1e-3 / n}};
    d.fixed = &fix;
    d.n_fixed = 1;
    if (cs_world_add_object(b->w, &d, &b->id, err, sizeof err) != CS_OK) {
        printf("    add: %s\n", err);
        return -1;
    }
    return 0;
}

static void free_block(blk *b)
{
    cs_world_destroy(b->w);
    free(b->ijk);
}

static const double *positions(const blk *b, int *n)
{
    const double *rest, *pos;
    cs_object_nodes(b->w, b->id, &rest, &pos, NULL, n);
    return pos;
}

/* The node whose rest position is nearest p. */
static int nearest_node(const blk *b, const double p[3])
{
    const double *rest, *pos;
    int n, best = 0;
    double bd = 1e300;
    cs_object_nodes(b->w, b->id, &rest, &pos, NULL, &n);
    for (int i = 0; i < n; i++) {
        const double d = pow(rest[3 * i] - p[0], 2) + pow(rest[3 * i + 1] - p[1], 2) +
                         pow(rest[3 * i + 2] - p[2], 2);
        if (d < bd) {
            bd = d;
            best = i;
        }
    }
    return best;
}

static bool asleep(const blk *b)
{
    cs_object_info info;
    cs_object_get_info(b->w, b->id, &info);
    return info.sleeping;
}

static double max_diff(const double *a, const double *b, int n)
{
    double m = 0;
    for (int i = 0; i < n; i++) {
        const double d[3] = {a[3 * i] - b[3 * i], a[3 * i + 1] - b[3 * i + 1],
                             a[3 * i + 2] - b[3 * i + 2]};
        const double l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (l > m)
            m = l;
    }
    return m;
}

/* Max over nodes of |(xa − a0) − (xf − f0)|: the two runs' displacements since a0, f0. */
static double resp_diff(const double *xa, const double *a0, const double *xf, const double *f0,
                        int n)
{
    double m = 0;
    for (int i = 0; i < n; i++) {
        double l = 0;
        for (int a = 0; a < 3; a++) {
            const double d = (xa[3 * i + a] - a0[3 * i + a]) - (xf[3 * i + a] - f0[3 * i + a]);
            l += d * d;
        }
        if (sqrt(l) > m)
            m = sqrt(l);
    }
    return m;
}

static int step_both(blk *A, blk *F)
{
    int ra = cs_world_step(A->w), rf = cs_world_step(F->w);
    return ra != CS_OK ? ra : rf;
}

/*
 * A 16×16×4 slab (1 m wide, bottom held) at rest (no gravity), active regions against the
 * all-active run, sleep off in
 * both: every node freezes; a 0.5 s poke at a top corner wakes a region (measured: at most
 * 24 %, on average 10 % of the cells over the 60 steps) and the displacement field follows the
 * full solve within 2 % of its largest displacement throughout (measured 0.31 %); after it the
 * region freezes again; a later push at the opposite corner wakes that region (0.50 %; at most
 * 38 %, on average 16 % of the cells) while the first corner stays where it was.
 */
TEST(active_poke_matches_full_solve_and_wakes_elsewhere)
{
    const int n = 16, nz = 4, ncell = n * n * nz;
    blk A, F;
    ENSURE(make_block(&A, n, nz, 10, false, 0) == 0);
    ENSURE(make_block(&F, n, nz, 0, false, 0) == 0);
    int nn;
    const double *xa = positions(&A, &nn), *xf = positions(&F, &nn);
    const size_t sz = sizeof(double) * 3 * (size_t)nn;
    double *a0 = malloc(sz), *f0 = malloc(sz);
    for (int s = 0; s < 12; s++)
        ENSURE(step_both(&A, &F) == CS_OK);
    const cs_step_stats *st = cs_world_last_stats(A.w);
    ENSURE_MSG(st->cells_stepped == 0 && st->cells_awake == ncell,
               "at rest: %d of %d cells active", st->cells_stepped, st->cells_awake);
    ENSURE(cs_world_last_stats(F.w)->cells_stepped == ncell);
    char err[256];
    const double top = (double)nz / n;
    const double c1[3] = {1, 1, top}, f1[3] = {-0.07, -0.035, -0.105};
    const double c2[3] = {0, 0, top}, f2[3] = {0.055, 0.09, -0.07};
    const int k1 = nearest_node(&A, c1);
    for (int poke = 0; poke < 2; poke++) {
        memcpy(a0, xa, sz);
        memcpy(f0, xf, sz);
        const double *c = poke ? c2 : c1, *f = poke ? f2 : f1;
        ENSURE(cs_world_apply_force(A.w, A.id, c, f, 0.5, err, sizeof err) == CS_OK);
        ENSURE(cs_world_apply_force(F.w, F.id, c, f, 0.5, err, sizeof err) == CS_OK);
        double worst = 0, dmax = 0, act_sum = 0;
        int act_max = 0;
        bool first_region_frozen = true;
        for (int s = 0; s < 60; s++) {
            ENSURE(step_both(&A, &F) == CS_OK);
            st = cs_world_last_stats(A.w);
            act_sum += st->cells_stepped;
            if (st->cells_stepped > act_max)
                act_max = st->cells_stepped;
            const double d = resp_diff(xa, a0, xf, f0, nn), m = max_diff(xf, f0, nn);
            if (d > worst)
                worst = d;
            if (m > dmax)
                dmax = m;
            /* the second push: the corner of the first stays where it was */
            if (poke == 1 && max_diff(xa + 3 * k1, a0 + 3 * k1, 1) != 0)
                first_region_frozen = false;
        }
        printf("    poke %d: displacement %.3g m, worst difference %.3g m (%.2f %%), active "
               "cells max %d mean %.0f of %d\n",
               poke + 1, dmax, worst, 100 * worst / dmax, act_max, act_sum / 60, ncell);
        ENSURE(dmax > 5e-5);
        ENSURE_MSG(worst < 0.02 * dmax, "difference %.3g of %.3g", worst, dmax);
        ENSURE_MSG(act_max < ncell / 2 && act_sum / 60 < 0.2 * ncell && act_sum > 0,
                   "active cells: up to %d, mean %.0f", act_max, act_sum / 60);
        if (poke == 1)
            ENSURE_MSG(first_region_frozen, "the first poke's corner moved");
        /* released: the active cells fall back to none */
        for (int s = 0; s < 90; s++)
            ENSURE(step_both(&A, &F) == CS_OK);
        st = cs_world_last_stats(A.w);
        ENSURE_MSG(st->cells_stepped == 0, "%d cells still active after the poke",
                   st->cells_stepped);
    }
    free(a0);
    free(f0);
    free_block(&A);
    free_block(&F);
}

/*
 * An 8³ block settling under gravity (sleep on, the defaults): with active regions it falls
 * asleep no later than the all-active run (+ active_steps), and where it rests agrees with the
 * all-active run's rest within 2 % of the sag; both are compared with the static equilibrium.
 */
TEST(active_settles_and_sleeps_as_before)
{
    const int n = 8;
    blk A, F;
    ENSURE(make_block(&A, n, n, 10, true, 30) == 0);
    ENSURE(make_block(&F, n, n, 0, true, 30) == 0);
    int nn, sa = -1, sf = -1;
    const double *xa = positions(&A, &nn), *xf = positions(&F, &nn);
    for (int s = 0; s < 1500 && (sa < 0 || sf < 0); s++) {
        ENSURE(step_both(&A, &F) == CS_OK);
        if (sa < 0 && asleep(&A))
            sa = s;
        if (sf < 0 && asleep(&F))
            sf = s;
    }
    const double *rest, *pos;
    cs_object_nodes(F.w, F.id, &rest, &pos, NULL, &nn);
    const double sag = max_diff(xf, rest, nn), d = max_diff(xa, xf, nn);
    /* the static equilibrium of the same block */
    blk S;
    ENSURE(make_block(&S, n, n, 0, true, 30) == 0);
    ENSURE(cs_world_solve_static(S.w) == CS_OK);
    const double *xs = positions(&S, &nn);
    printf("    asleep after %d (active) / %d (all) steps; sag %.4g m; active vs all %.3g m; "
           "from statics %.3g (active), %.3g (all)\n",
           sa, sf, sag, d, max_diff(xa, xs, nn), max_diff(xf, xs, nn));
    ENSURE(sa >= 0 && sf >= 0);
    ENSURE(sa <= sf + 10);
    ENSURE(sag > 0.01);
    ENSURE_MSG(d < 0.02 * sag, "rest differs by %.3g of a sag %.3g", d, sag);
    free_block(&S);
    free_block(&A);
    free_block(&F);
}

/* The scene's "active" object: read, defaults (off, 5e-4 m/s), refusals. */
TEST(active_scene_field)
{
    cs_scene s;
    char err[256];
    ENSURE(cs_scene_parse("{\"active\": {\"steps\": 12, \"speed\": 0.002}, \"objects\": []}", NULL,
                          &s, err, sizeof err) == 0);
    ENSURE(s.world.active_steps == 12);
    ENSURE_NEAR(s.world.active_speed, 0.002, 0);
    cs_scene_free(&s);
    ENSURE(cs_scene_parse("{\"objects\": []}", NULL, &s, err, sizeof err) == 0);
    ENSURE(s.world.active_steps == 0);
    ENSURE_NEAR(s.world.active_speed, 5e-4, 0);
    cs_scene_free(&s);
    ENSURE(cs_scene_parse("{\"active\": {\"speed\": 0}, \"objects\": []}", NULL, &s, err,
                          sizeof err) != 0);
    ENSURE_MSG(strstr(err, "active.speed") != NULL, "%s", err);
    ENSURE(cs_scene_parse("{\"active\": {\"step\": 3}, \"objects\": []}", NULL, &s, err,
                          sizeof err) != 0);
    ENSURE_MSG(strstr(err, "active.step") != NULL, "%s", err);
    cs_world_def wd = cs_world_def_default();
    wd.active_steps = 5;
    wd.active_speed = NAN;
    cs_world_t *w = NULL;
    ENSURE(cs_world_create(&wd, &w, err, sizeof err) == CS_ERR_INVALID && w == NULL);
}
