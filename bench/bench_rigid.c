/*
 * bench_rigid.c — a rigid scene stepped headless (no bus): wall time per step against the
 * step dt (real-time factor), the pieces made, and every piece checked closed.
 *
 *   bench_rigid [SCENE] [SECONDS]     default scenes/drop.json, 3 s
 *   bench_rigid --boxes N              2·N² boxes (8 cubes each) in two layers fall on the
 *                                      ground: ms per step while they fall and settle (first
 *                                      2 s) and once asleep (after 10 s)
 *   bench_rigid --slab N               N² boxes dropped on a held (never stepped) deformable
 *                                      slab of 16N×16N×2 cubes: ms per step (the bodies and
 *                                      their contacts) with the grid broad phase against the
 *                                      plain loop (every cell and node against every box);
 *                                      both find the same contacts
 *
 * Prints one line per simulated quarter second and a summary; exits 1 if a piece fails the
 * watertight checker or a step fails.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench_util.h"
#include "lattice.h"
#include "cubesim.h"
#include "scene.h"
#include "watertight.h"
#include "world_internal.h"

#define MAX_OBJECTS 4096

static int check_all(cs_world_t *w, double volume, double *vsum, char *why, size_t n)
{
    static cs_object_id ids[MAX_OBJECTS];
    static cs_piece_view pv[MAX_OBJECTS];
    int no = cs_world_object_ids(w, ids, MAX_OBJECTS);
    if (no > MAX_OBJECTS)
        no = MAX_OBJECTS;
    for (int i = 0; i < no; i++) {
        cs_object_surface(w, ids[i], &pv[i].v, &pv[i].nv, &pv[i].t, &pv[i].nt);
        cs_object_info info;
        cs_object_get_info(w, ids[i], &info);
        pv[i].name = info.name;
    }
    return cs_check_pieces(pv, no, volume, 0.05, vsum, why, n);
}

/* A world with the ground, default dt and gravity, one engine thread; NULL on failure. */
static cs_world_t *ground_world(void)
{
    cs_world_def wd = cs_world_def_default();
    wd.has_ground = true;
    wd.threads = 1;
    cs_world_t *w;
    char err[256];
    return cs_world_create(&wd, &w, err, sizeof err) == CS_OK ? w : NULL;
}

static int boxes(int n)
{
    cs_world_t *w = ground_world();
    char err[256];
    if (!w)
        return 1;
    int32_t *ijk = cs_box_cells(2, 2, 2);
    if (!ijk) {
        cs_world_destroy(w);
        return 1;
    }
    for (int a = 0; a < n; a++)
        for (int b = 0; b < n; b++)
            for (int l = 0; l < 2; l++) {
                char name[48];
                snprintf(name, sizeof name, "box%d.%d.%d", a, b, l);
                cs_object_def d = cs_object_def_default();
                d.name = name;
                d.model = CS_MODEL_RIGID;
                d.cube_size = 0.05;
                d.cells_ijk = ijk;
                d.n_cells = 8;
                d.cells_origin[0] = 0.15 * a + 0.01 * l;
                d.cells_origin[1] = 0.15 * b;
                d.cells_origin[2] = 0.05 + 0.3 * l;
                if (cs_world_add_object(w, &d, NULL, err, sizeof err) != CS_OK) {
                    fprintf(stderr, "bench_rigid: %s\n", err);
                    cs_world_destroy(w);
                    free(ijk);
                    return 1;
                }
            }
    double t0 = now_s();
    for (int i = 0; i < 120; i++)
        cs_world_step(w);
    const double falling = (now_s() - t0) / 120;
    for (int i = 0; i < 480; i++)
        cs_world_step(w);
    t0 = now_s();
    for (int i = 0; i < 120; i++)
        cs_world_step(w);
    const double asleep_ms = (now_s() - t0) / 120;
    static cs_object_id ids[MAX_OBJECTS];
    int no = cs_world_object_ids(w, ids, MAX_OBJECTS), asleep = 0;
    for (int i = 0; i < no && i < MAX_OBJECTS; i++) {
        cs_object_info info;
        cs_object_get_info(w, ids[i], &info);
        asleep += info.sleeping;
    }
    printf("%d boxes (%d cubes): falling and settling %.3f ms/step; after 10 s %.4f ms/step, "
           "%d asleep\n", no, 8 * no, 1e3 * falling, 1e3 * asleep_ms, asleep);
    cs_world_destroy(w);
    free(ijk);
    return 0;
}

/* One run of the slab scene: ms per step over steps 10–40 (boxes landing and resting), or -1. */
static double slab_run(int n, int min_bodies)
{
    cs_world_t *w = ground_world();
    char err[256];
    if (!w)
        return -1;
    w->broadphase_min_bodies = min_bodies;
    const int m = 16 * n, c = m * m * 2;
    int32_t *ijk = cs_box_cells(m, m, 2);
    if (!ijk) {
        cs_world_destroy(w);
        return -1;
    }
    cs_object_def d = cs_object_def_default();
    d.name = "slab";
    d.material.young = 1e6;
    d.material.damping[0] = 1;
    d.cube_size = 0.025;
    d.cells_ijk = ijk;
    d.n_cells = c;
    /* held everywhere: never stepped, so the step's cost is the bodies' and their contacts' */
    const cs_aabb all = {{-1, -1, -1}, {1e3, 1e3, 1e3}};
    d.fixed = &all;
    d.n_fixed = 1;
    int rc = cs_world_add_object(w, &d, NULL, err, sizeof err);
    free(ijk);
    int32_t *box = cs_box_cells(2, 2, 2);
    if (!box)
        rc = CS_ERR_NOMEM;
    for (int a = 0; a < n && rc == CS_OK; a++)
        for (int b = 0; b < n && rc == CS_OK; b++) {
            char name[32];
            snprintf(name, sizeof name, "box%d.%d", a, b);
            cs_object_def r = cs_object_def_default();
            r.name = name;
            r.model = CS_MODEL_RIGID;
            r.cube_size = 0.05;
            r.cells_ijk = box;
            r.n_cells = 8;
            r.cells_origin[0] = 0.4 * a + 0.15;
            r.cells_origin[1] = 0.4 * b + 0.15;
            r.cells_origin[2] = 0.06 + 0.002 * (a + b);
            rc = cs_world_add_object(w, &r, NULL, err, sizeof err);
        }
    free(box);
    if (rc != CS_OK) {
        fprintf(stderr, "bench_rigid: %s\n", err);
        cs_world_destroy(w);
        return -1;
    }
    for (int i = 0; i < 10; i++)
        cs_world_step(w);
    double total = 0;
    for (int i = 0; i < 30; i++) {
        const double t0 = now_s();
        cs_world_step(w);
        total += now_s() - t0;
    }
    cs_world_destroy(w);
    return 1e3 * total / 30;
}

static int slab(int n)
{
    double plain[3], grid[3];
    for (int k = 0; k < 3; k++) { /* interleaved, median of 3 */
        plain[k] = slab_run(n, 1 << 30);
        grid[k] = slab_run(n, 0);
        if (plain[k] < 0 || grid[k] < 0)
            return 1;
    }
    for (int k = 0; k < 3; k++)
        for (int j = k + 1; j < 3; j++) {
            if (plain[j] < plain[k]) { double t = plain[j]; plain[j] = plain[k]; plain[k] = t; }
            if (grid[j] < grid[k]) { double t = grid[j]; grid[j] = grid[k]; grid[k] = t; }
        }
    printf("%d boxes on a %dx%dx2 slab (%d cubes): %.2f ms/step with the plain loop, %.2f with "
           "the grid broad phase (x%.2f)\n", n * n, 16 * n, 16 * n, 512 * n * n, plain[1], grid[1],
           plain[1] / grid[1]);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc > 2 && !strcmp(argv[1], "--slab"))
        return slab(atoi(argv[2]));
    if (argc > 2 && !strcmp(argv[1], "--boxes"))
        return boxes(atoi(argv[2]));
    setvbuf(stdout, NULL, _IOLBF, 0);
    const char *path = argc > 1 ? argv[1] : "scenes/drop.json";
    const double seconds = argc > 2 ? atof(argv[2]) : 3.0;
    cs_scene sc;
    cs_world_t *w = NULL;
    char err[512];
    if (cs_scene_load(path, &sc, err, sizeof err) != 0 ||
        cs_scene_instantiate(&sc, &w, err, sizeof err) != 0) {
        fprintf(stderr, "bench_rigid: %s\n", err);
        return 1;
    }
    const double dt = cs_world_get_def(w)->dt;
    const int steps = (int)ceil(seconds / dt);
    cs_object_id ids[MAX_OBJECTS];
    int n0 = cs_world_object_ids(w, ids, MAX_OBJECTS), cells = 0;
    double volume = 0; /* enclosed by the surfaces: the checker's expected sum */
    for (int i = 0; i < n0; i++) {
        cs_object_info info;
        const double *v;
        const int32_t *t;
        int nv, nt;
        cs_object_get_info(w, ids[i], &info);
        cs_object_surface(w, ids[i], &v, &nv, &t, &nt);
        volume += cs_mesh_volume(v, t, nt);
        cells += info.n_cells;
    }
    printf("%s: %d objects, %d cubes, dt %.4f s, %d steps\n", path, n0, cells, dt, steps);
    double total = 0, worst = 0;
    cs_step_stats worst_st = {0};
    int fractures = 0, bad = 0, failed = 0;
    for (int s = 0; s < steps; s++) {
        const double t0 = now_s();
        int rc = cs_world_step(w);
        const double t = now_s() - t0;
        total += t;
        if (t > worst) {
            worst = t;
            worst_st = *cs_world_last_stats(w);
        }
        if (rc != CS_OK) {
            fprintf(stderr, "step %d: %s\n", s, cs_status_str(rc));
            failed = 1;
        }
        int ne;
        const cs_event *ev = cs_world_events(w, &ne);
        for (int e = 0; e < ne; e++)
            fractures += ev[e].kind == CS_EVENT_FRACTURE;
        char why[256] = "";
        double vsum = 0;
        if (ne > 0 && !check_all(w, volume, &vsum, why, sizeof why)) {
            printf("step %d: checker: %s\n", s, why);
            bad++;
        }
        if ((s + 1) % (int)ceil(0.25 / dt) == 0)
            printf("t %.2f s: %d objects, %d fracture events so far, step %.2f ms (worst %.2f)\n",
                   (s + 1) * dt, cs_world_object_ids(w, ids, MAX_OBJECTS), fractures, t * 1e3,
                   worst * 1e3);
    }
    char why[256] = "";
    double vsum = 0;
    const int ok = check_all(w, volume, &vsum, why, sizeof why);
    printf("summary: %d pieces, %d fracture events, mean step %.2f ms, worst %.2f ms, "
           "real-time factor %.1f (dt / mean step), pieces %s (volume %.4g of %.4g m^3)%s%s\n",
           cs_world_object_ids(w, ids, MAX_OBJECTS), fractures, 1e3 * total / steps,
           1e3 * worst, dt / (total / steps), ok ? "closed" : "NOT closed", vsum, volume,
           ok ? "" : ": ", why);
    printf("worst step: contacts %.2f ms, poses/sleep %.2f ms, impact solve + fracture %.2f ms "
           "(%d PCG iterations, residual %.1e)\n", worst_st.ms_solve, worst_st.ms_skin,
           worst_st.ms_post, worst_st.cg_iterations, worst_st.cg_residual);
    cs_world_destroy(w);
    cs_scene_free(&sc);
    return failed || bad || !ok;
}
