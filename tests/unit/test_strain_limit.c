/*
 * test_strain_limit.c — the strain limit (server/engine/strain_limit.h, the objects'
 * "strain_limit"): its singular values against matrices built from known ones, a crushed and
 * inverted block turned back out in one step, a point force far above what a soft beam carries
 * kept near the bounds at every step (without the limit the same beam goes far past them), held
 * nodes never moved, nothing changed below the limit, results independent of the thread count,
 * and the scene field and its refusals.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "common/lattice.h"
#include "common/scene.h"
#include "cubesim.h"
#include "strain_limit.h"
#include "world_internal.h"

/* R = rotation about the unit axis u by angle a, row-major */
static void rot(const double u[3], double a, double R[9])
{
    const double c = cos(a), s = sin(a), t = 1 - c;
    R[0] = t * u[0] * u[0] + c;
    R[1] = t * u[0] * u[1] - s * u[2];
    R[2] = t * u[0] * u[2] + s * u[1];
    R[3] = t * u[0] * u[1] + s * u[2];
    R[4] = t * u[1] * u[1] + c;
    R[5] = t * u[1] * u[2] - s * u[0];
    R[6] = t * u[0] * u[2] - s * u[1];
    R[7] = t * u[1] * u[2] + s * u[0];
    R[8] = t * u[2] * u[2] + c;
}

/* F = U diag(d) Vᵀ */
static void compose(const double U[9], const double d[3], const double V[9], double F[9])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s = 0;
            for (int k = 0; k < 3; k++)
                s += U[3 * i + k] * d[k] * V[3 * j + k];
            F[3 * i + j] = s;
        }
}

TEST(strain_limit_singular_values_are_exact)
{
    const double u1[3] = {0.48, 0.6, 0.64}, u2[3] = {-0.8, 0.0, 0.6};
    double U[9], V[9];
    rot(u1, 0.9, U);
    rot(u2, -2.3, V);
    const double cases[][3] = {{2, 0.5, 3}, {1, 1, -0.5}, {4, 1e-3, 1e-3}, {0.7, 0, 2},
                               {1, 1, 1},   {5, 0, 0},    {0.2, 0.3, -0.25}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        double F[9], s[3];
        compose(U, cases[c], V, F);
        cs_strain_singular_values(F, s);
        /* expected: |d| descending, the smallest signed by det F */
        double a[3] = {fabs(cases[c][0]), fabs(cases[c][1]), fabs(cases[c][2])};
        for (int i = 0; i < 2; i++)
            for (int j = i + 1; j < 3; j++)
                if (a[j] > a[i]) {
                    const double t = a[i];
                    a[i] = a[j];
                    a[j] = t;
                }
        const double det = cases[c][0] * cases[c][1] * cases[c][2];
        if (det < 0)
            a[2] = -a[2];
        for (int k = 0; k < 3; k++)
            ENSURE_MSG(fabs(s[k] - a[k]) <= 1e-12 * a[0],
                       "case %zu: singular value %d is %.17g, expected %.17g", c, k, s[k], a[k]);
    }
}

typedef struct {
    cs_world_t *w;
    cs_object_id id;
    int32_t *ijk;
} sl_obj;

static int make_obj(sl_obj *b, int nx, int ny, int nz, double h, double young, bool fixed,
                    double limit, double gravity, int threads, char *err, size_t errlen)
{
    memset(b, 0, sizeof *b);
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = gravity;
    wd.sleep_steps = 0;
    wd.threads = threads;
    if (cs_world_create(&wd, &b->w, err, errlen) != CS_OK)
        return -1;
    b->ijk = cs_box_cells(nx, ny, nz);
    cs_object_def d = cs_object_def_default();
    d.name = "b";
    d.material.young = young;
    d.material.poisson = 0.3;
    d.material.damping[0] = 1.0;
    d.cube_size = h;
    d.cells_ijk = b->ijk;
    d.n_cells = nx * ny * nz;
    d.strain_limit = limit;
    cs_aabb fix = {{-1e-3 * h, -1e3, -1e3}, {1e-3 * h, 1e3, 1e3}};
    if (fixed) {
        d.fixed = &fix;
        d.n_fixed = 1;
    }
    return b->ijk && cs_world_add_object(b->w, &d, &b->id, err, errlen) == CS_OK ? 0 : -1;
}

static void free_obj(sl_obj *b)
{
    cs_world_destroy(b->w);
    free(b->ijk);
}

/* The smallest (signed) and largest singular values over every corner Jacobian of o. */
static void corner_range(const cs_object *o, double *lo, double *hi)
{
    *lo = INFINITY;
    *hi = -INFINITY;
    const double h = o->cm.h;
    for (int c = 0; c < o->cm.n_cells; c++) {
        const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
        for (int k = 0; k < 8; k++) {
            double E[9];
            for (int a = 0; a < 3; a++) {
                int t[3] = {CS_CORNER[k][0], CS_CORNER[k][1], CS_CORNER[k][2]};
                t[a] ^= 1;
                int q = 0;
                while (CS_CORNER[q][0] != t[0] || CS_CORNER[q][1] != t[1] ||
                       CS_CORNER[q][2] != t[2])
                    q++;
                const double sg = CS_CORNER[k][a] ? -1.0 / h : 1.0 / h;
                for (int r = 0; r < 3; r++)
                    E[3 * r + a] = sg * (o->x[3 * (size_t)nd[q] + r] - o->x[3 * (size_t)nd[k] + r]);
            }
            double s[3];
            cs_strain_singular_values(E, s);
            *lo = fmin(*lo, s[2]);
            *hi = fmax(*hi, s[0]);
        }
    }
}

/* A free 3×3×3 block (h 0.1, E 10 kPa, no gravity) turned inside out (z → 0.3 − z: every cell
 * inverted, as stab_crushed_block_recovers does) and released: with the limit 3 every corner
 * is within [1/3, 3] after the first step; without it the first step leaves cells inverted. */
TEST(strain_limit_turns_a_crushed_block_back_out)
{
    char err[256];
    for (int lim = 0; lim < 2; lim++) {
        sl_obj b;
        ENSURE_MSG(make_obj(&b, 3, 3, 3, 0.1, 1e4, false, lim ? 3.0 : 0.0, 0, 1, err,
                            sizeof err) == 0, "%s", err);
        cs_object *o = cs_world_find_internal(b.w, b.id);
        for (int i = 0; i < o->n; i++)
            o->x[3 * i + 2] = 0.3 - o->x[3 * i + 2];
        double lo, hi;
        corner_range(o, &lo, &hi);
        ENSURE_MSG(lo < 0, "the block is not inverted (%g)", lo);
        const int rc = cs_world_step(b.w);
        corner_range(o, &lo, &hi);
        double p[3] = {0, 0, 0};
        for (int i = 0; i < o->n; i++)
            for (int a = 0; a < 3; a++)
                p[a] += o->m[i] * o->v[3 * i + a];
        printf("    inverted block, limit %s: first step rc %d, corner singular values %.4g .. "
               "%.4g, momentum %.2g %.2g %.2g\n", lim ? "3" : "none", rc, lo, hi, p[0], p[1], p[2]);
        free_obj(&b);
        ENSURE(rc == CS_OK);
        if (lim) {
            ENSURE_MSG(lo >= (1 - 1e-6) / 3 && hi <= 3 * (1 + 1e-6),
                       "limited: corners %g .. %g", lo, hi);
        } else {
            ENSURE_MSG(lo < 0, "unlimited: the first step already turned the block out (%g)", lo);
        }
    }
}

/* A soft corotational beam (16×4×4 cubes of 2.5 cm, E 1e5 Pa: E·h² = 62.5 N) held at x = 0,
 * pulled at its free end by 1 kN for 0.5 s, then released for 1 s. Without the limit its
 * cubes stretch to 95 times their edge and turn inside out (measured −6 .. 94.6). With the
 * limit 3 the pull keeps the whole beam at its bound, where the projections of neighbouring
 * cubes undo each other and 64 sweeps do not settle every cube (measured −0.025 .. 3.75):
 * asserted, every corner's singular values within [−0.1, 4] at every step (the bound, not
 * exactly), the held nodes never moved, every step succeeded. */
TEST(strain_limit_holds_a_point_force_far_above_the_material_near_its_bounds)
{
    char err[256];
    double worst[2][2];
    for (int lim = 0; lim < 2; lim++) {
        sl_obj b;
        ENSURE_MSG(make_obj(&b, 16, 4, 4, 0.025, 1e5, true, lim ? 3.0 : 0.0, -9.81, 1, err,
                            sizeof err) == 0, "%s", err);
        const double p[3] = {0.4, 0.05, 0.1}, f[3] = {2e2, -6e2, 8e2};
        ENSURE_MSG(cs_world_apply_force(b.w, b.id, p, f, 0.5, err, sizeof err) == CS_OK, "%s",
                   err);
        cs_object *o = cs_world_find_internal(b.w, b.id);
        double lo = INFINITY, hi = -INFINITY, held_moved = 0;
        int bad = 0;
        for (int s = 0; s < 90; s++) {
            bad += cs_world_step(b.w) != CS_OK;
            double l, hgh;
            corner_range(o, &l, &hgh);
            lo = fmin(lo, l);
            hi = fmax(hi, hgh);
            for (int i = 0; i < o->n; i++)
                if (o->mask[3 * i])
                    for (int a = 0; a < 3; a++)
                        held_moved = fmax(held_moved,
                                          fabs(o->x[3 * i + a] - o->cm.node_rest[3 * i + a]));
        }
        printf("    1 kN on a soft beam, limit %s: corner singular values %.4g .. %.4g over "
               "90 steps, %d failed steps, held nodes moved %.3g m\n",
               lim ? "3" : "none", lo, hi, bad, held_moved);
        worst[lim][0] = lo;
        worst[lim][1] = hi;
        free_obj(&b);
        ENSURE_MSG(held_moved == 0, "held nodes moved %g m", held_moved);
        if (lim)
            ENSURE(bad == 0);
    }
    ENSURE_MSG(worst[0][0] < -1 || worst[0][1] > 10,
               "the unlimited beam stayed near the bounds (%g .. %g): the test shows nothing",
               worst[0][0], worst[0][1]);
    ENSURE_MSG(worst[1][0] >= -0.1 && worst[1][1] <= 4, "limited beam: corners %g .. %g",
               worst[1][0], worst[1][1]);
}

/* Below the limit nothing changes: a cantilever sagging under its weight and swinging steps
 * bit for bit as without a limit. */
TEST(strain_limit_changes_nothing_below_it)
{
    char err[256];
    uint64_t hash[2];
    for (int lim = 0; lim < 2; lim++) {
        sl_obj b;
        ENSURE_MSG(make_obj(&b, 12, 3, 3, 0.05, 1e6, true, lim ? 1.5 : 0.0, -9.81, 1, err,
                            sizeof err) == 0, "%s", err);
        for (int s = 0; s < 60; s++)
            ENSURE(cs_world_step(b.w) == CS_OK);
        cs_object *o = cs_world_find_internal(b.w, b.id);
        double lo, hi;
        corner_range(o, &lo, &hi);
        hash[lim] = cs_object_state_hash(b.w, b.id);
        free_obj(&b);
        ENSURE_MSG(lo > 1 / 1.5 && hi < 1.5, "the sag reached the limit 1.5 (%g .. %g)", lo, hi);
    }
    ENSURE_MSG(hash[0] == hash[1], "a limit that was never reached changed the state");
}

/* The check runs on both threads, the projections in cell order: the same bits either way. */
TEST(strain_limit_results_independent_of_thread_count)
{
    char err[256];
    uint64_t hash[2];
    for (int t = 0; t < 2; t++) {
        sl_obj b;
        ENSURE_MSG(make_obj(&b, 32, 8, 8, 0.025, 1e5, true, 2.0, -9.81, t + 1, err,
                            sizeof err) == 0, "%s", err);
        const double p[3] = {0.8, 0.1, 0.2}, f[3] = {0, -5e4, 5e4};
        ENSURE(cs_world_apply_force(b.w, b.id, p, f, 0.2, err, sizeof err) == CS_OK);
        for (int s = 0; s < 8; s++)
            ENSURE(cs_world_step(b.w) == CS_OK);
        hash[t] = cs_object_state_hash(b.w, b.id);
        cs_object *o = cs_world_find_internal(b.w, b.id);
        double lo, hi;
        corner_range(o, &lo, &hi);
        free_obj(&b);
        ENSURE_MSG(hi >= 2 * (1 - 1e-9), "the force did not reach the limit (%g): nothing shown",
                   hi);
    }
    ENSURE_MSG(hash[0] == hash[1], "one and two threads differ");
}

TEST(strain_limit_in_scenes_and_refused_out_of_range)
{
    char err[512] = "", text[512];
    const char *fmt = "{ \"objects\": [ { \"name\": \"a\", \"strain_limit\": %s,"
                      " \"box\": { \"min\": [0, 0, 0], \"size\": [0.2, 0.1, 0.1] } } ] }";
    cs_scene s;
    snprintf(text, sizeof text, fmt, "2.5");
    ENSURE_MSG(cs_scene_parse(text, NULL, &s, err, sizeof err) == 0, "%s", err);
    ENSURE(s.objects[0].strain_limit == 2.5);
    cs_scene_free(&s);
    snprintf(text, sizeof text, fmt, "0");
    ENSURE_MSG(cs_scene_parse(text, NULL, &s, err, sizeof err) == 0, "%s", err);
    ENSURE(s.objects[0].strain_limit == 0);
    cs_scene_free(&s);
    const char *bad[] = {"1.05", "-1", "2000", "\"3\"", "true"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(text, sizeof text, fmt, bad[i]);
        err[0] = 0;
        ENSURE_MSG(cs_scene_parse(text, NULL, &s, err, sizeof err) == -1, "%s accepted", bad[i]);
        ENSURE_MSG(strstr(err, "objects[0].strain_limit") && !strchr(err, '\n'), "%s: %s",
                   bad[i], err);
    }
    /* the engine refuses it too, and keeps nothing */
    cs_world_def wd = cs_world_def_default();
    cs_world_t *w;
    ENSURE(cs_world_create(&wd, &w, err, sizeof err) == CS_OK);
    int32_t *ijk = cs_box_cells(2, 1, 1);
    cs_object_def d = cs_object_def_default();
    d.name = "a";
    d.cells_ijk = ijk;
    d.n_cells = 2;
    d.strain_limit = 0.5;
    cs_object_id id;
    const int rc = cs_world_add_object(w, &d, &id, err, sizeof err);
    const int n = cs_world_object_ids(w, NULL, 0);
    free(ijk);
    cs_world_destroy(w);
    ENSURE(rc == CS_ERR_INVALID);
    ENSURE_MSG(strstr(err, "strain_limit must be 0 (none) or in [1.1, 1000], got 0.5"), "%s",
               err);
    ENSURE(n == 0);
}
