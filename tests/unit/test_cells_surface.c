/*
 * test_cells_surface.c — the boundary of a cell set (cs_surface_of_cells) is a closed manifold
 * whatever the cells: cells that touch only along an edge or at a corner keep their own
 * boundaries (the edge used twice, not four times; one fan per vertex copy).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubemesh.h"
#include "cubesim.h"
#include "scene.h"
#include "surface.h"
#include "watertight.h"

/* Closed, oriented, of volume n h^3, every vertex's triangles one fan (a manifold): why on
 * failure. */
static int cells_surface_ok(const int32_t *ijk, int n, int sub, int *nv_out, char *why,
                            size_t whylen)
{
    const double h = 0.25;
    cs_cubemesh cm;
    char err[160];
    if (cs_cubemesh_build(&cm, h, (double[3]){0.1, -0.2, 0.3}, ijk, n, err, sizeof err) != 0) {
        snprintf(why, whylen, "cubemesh: %s", err);
        return 0;
    }
    double *v = NULL;
    int32_t *t = NULL;
    int nv = 0, nt = 0, ok = 0;
    if (cs_surface_of_cells(&cm, sub, &v, &nv, &t, &nt, err, sizeof err) != 0) {
        snprintf(why, whylen, "surface: %s", err);
        goto out;
    }
    cs_watertight_report rep;
    if (!cs_watertight_check(v, nv, t, nt, &rep, err, sizeof err)) {
        snprintf(why, whylen, "%s", err);
        goto out;
    }
    if (fabs(rep.volume - n * h * h * h) > 1e-12) {
        snprintf(why, whylen, "volume %.17g, cells %g", rep.volume, n * h * h * h);
        goto out;
    }
    /* one fan per vertex: around each vertex, the triangles' edges (opposite the vertex)
     * chain into one cycle, so degree (triangle count) equals the edges walked from any one */
    int *deg = calloc((size_t)nv, sizeof *deg);
    if (!deg)
        goto out;
    for (int i = 0; i < 3 * nt; i++)
        deg[t[i]]++;
    int bad = -1;
    for (int vert = 0; vert < nv && bad < 0; vert++) {
        /* walk: from a triangle at vert, go to the triangle across the edge (vert, next) */
        int start = -1;
        for (int i = 0; i < nt && start < 0; i++)
            for (int k = 0; k < 3; k++)
                if (t[3 * i + k] == vert)
                    start = i;
        int tri = start, steps = 0;
        do {
            int k = 0;
            while (t[3 * tri + k] != vert)
                k++;
            const int nxt = t[3 * tri + (k + 1) % 3];
            /* the triangle with the directed edge (nxt, vert) */
            int found = -1;
            for (int i = 0; i < nt && found < 0; i++)
                for (int m = 0; m < 3; m++)
                    if (t[3 * i + m] == nxt && t[3 * i + (m + 1) % 3] == vert)
                        found = i;
            tri = found;
            steps++;
        } while (tri >= 0 && tri != start && steps <= deg[vert]);
        if (tri != start || steps != deg[vert])
            bad = vert;
    }
    free(deg);
    if (bad >= 0) {
        snprintf(why, whylen, "vertex %d: its triangles are not one fan", bad);
        goto out;
    }
    *nv_out = nv;
    ok = 1;
out:
    free(v);
    free(t);
    cs_cubemesh_free(&cm);
    return ok;
}

TEST(cells_touching_along_an_edge_or_corner_keep_their_own_boundaries)
{
    char why[256];
    int nv = 0;
    const int32_t edge[] = {0, 0, 0, 1, 1, 0};
    ENSURE_MSG(cells_surface_ok(edge, 2, 1, &nv, why, sizeof why), "edge: %s", why);
    ENSURE_MSG(nv == 16, "edge: %d vertices (two cubes: 16)", nv);
    const int32_t corner[] = {0, 0, 0, 1, 1, 1};
    ENSURE_MSG(cells_surface_ok(corner, 2, 1, &nv, why, sizeof why), "corner: %s", why);
    ENSURE_MSG(nv == 16, "corner: %d vertices (two cubes: 16)", nv);
    ENSURE_MSG(cells_surface_ok(edge, 2, 3, &nv, why, sizeof why), "edge, sub 3: %s", why);
    ENSURE_MSG(nv == 2 * (6 * 4 + 12 * 2 + 8), "edge, sub 3: %d vertices", nv);
    /* a manifold set is welded as before: 2x1x1 cells, 12 vertices */
    const int32_t pair[] = {0, 0, 0, 1, 0, 0};
    ENSURE_MSG(cells_surface_ok(pair, 2, 1, &nv, why, sizeof why), "pair: %s", why);
    ENSURE_MSG(nv == 12, "pair: %d vertices", nv);
}

TEST(cells_surface_of_random_sets_is_a_closed_manifold)
{
    unsigned seed = 12345;
    char why[256];
    for (int trial = 0; trial < 120; trial++) {
        int32_t ijk[3 * 64];
        int n = 0;
        const unsigned fill = 30 + (unsigned)(trial % 5) * 10; /* 30-70 % of a 4x4x4 block */
        for (int i = 0; i < 4; i++)
            for (int j = 0; j < 4; j++)
                for (int k = 0; k < 4; k++) {
                    seed = seed * 1103515245u + 12345u;
                    if ((seed >> 16) % 100 < fill) {
                        ijk[3 * n] = i, ijk[3 * n + 1] = j, ijk[3 * n + 2] = k;
                        n++;
                    }
                }
        if (n == 0)
            continue;
        int nv;
        const int sub = 1 + trial % 2;
        ENSURE_MSG(cells_surface_ok(ijk, n, sub, &nv, why, sizeof why), "trial %d (%d cells, sub %d): %s",
                   trial, n, sub, why);
    }
}

/* The scene of the outside review: two cells along an edge load, step and stay closed. */
TEST(cells_along_an_edge_scene_has_a_closed_surface)
{
    const char *json = "{\"solver\":{\"threads\":1},\"ground\":{},\"objects\":[{\"name\":\"a\","
                       "\"cells\":{\"origin\":[0,0,0.5],\"ijk\":[[0,0,0],[1,1,0]]}}]}";
    cs_scene s;
    char err[512];
    ENSURE_MSG(cs_scene_parse(json, NULL, &s, err, sizeof err) == 0, "%s", err);
    cs_world_t *w = NULL;
    const int rc = cs_scene_instantiate(&s, &w, err, sizeof err);
    cs_scene_free(&s);
    ENSURE_MSG(rc == 0, "%s", err);
    for (int i = 0; i < 30; i++)
        ENSURE(cs_world_step(w) == CS_OK);
    const double *v;
    const int32_t *t;
    int nv, nt;
    ENSURE(cs_object_surface(w, cs_world_find_object(w, "a"), &v, &nv, &t, &nt) == CS_OK);
    cs_watertight_report rep;
    const int ok = cs_watertight_check(v, nv, t, nt, &rep, err, sizeof err);
    cs_world_destroy(w);
    ENSURE_MSG(ok, "%s", err);
    ENSURE_MSG(nv == 16 && rep.nonmanifold_edges == 0, "%d vertices", nv);
}
