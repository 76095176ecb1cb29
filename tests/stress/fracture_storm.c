/*
 * tests/stress/fracture_storm.c — cs_stress_fracture_storm: the fracture storm of issue 6
 * (stability suite, `make stress`). It drives the engine directly (no LCM).
 *
 *   cs_stress_fracture_storm [--fractures N] [--steps S] [--seed K] [--meshes DIR]
 *
 * Storm: a world with a 16×12×8 box of 12.5 mm cubes given as cells (corotational), the repository's icosphere (linear),
 * torus (mss) and star (localframe), voxelized at small cubes, no gravity. N times: a live
 * object picked with probability proportional to its cells, a random point (half of them within its nodes' bounding box, half at one of its
 * nodes, ±5 mm), a random unit normal, radius 0
 * (the object's own) → cs_world_fracture; every 10th fracture the world steps once (pieces
 * drift apart on a random push of at most 0.09 N). After every fracture every object's surface
 * is closed and consistently oriented (no degenerate triangle), the object cut and the new
 * pieces enclose a positive volume, and the volumes of all objects add up to their total
 * before that fracture within 1 % (a forced fracture moves no node; its closing surfaces
 * change the volume a little); after every step every surface is closed and oriented again
 * (see check_all for what may turn inside out in a step, and why).
 *
 * Load: a brittle cantilever (10×2×2 cubes of 0.02 m, E 50 kPa, strength 300 Pa, fracture on,
 * max 4 fractures per step) held at x = 0 over a ground, under gravity and a random 0.5–2 N
 * push on a random object every step, for S steps: it breaks again and again; after every
 * step with events every surface is closed and oriented and every new piece has a positive
 * volume.
 *
 * Every check prints one line; the last line is "fracture_storm: F fractures (E events), P
 * objects, peak RSS R kB, T s: ok" or "...: FAIL <why>"; exit status 0 ok, 1 a check failed,
 * 2 usage or setup.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cubesim.h"
#include "mesh.h"
#include "watertight.h"

#define MAX_OBJ 65536

static uint64_t rng_state;

static double urand(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) / 9007199254740992.0;
}

static long peak_rss_kb(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long kb = -1;
    if (!f)
        return -1;
    while (fgets(line, sizeof line, f))
        if (sscanf(line, "VmHWM: %ld", &kb) == 1)
            break;
    fclose(f);
    return kb;
}

typedef struct views {
    cs_object_id *ids;
    cs_piece_view *pv;
} views;

/*
 * Every object's surface closed and consistently oriented (cs_watertight_check: every edge
 * twice, in opposite directions, no degenerate triangle), and the volumes adding up to
 * `volume` within rel_tol (skipped if NAN; |volume| of each piece).
 *
 * The sign of a piece's volume is asserted only where the fracture made it: for the object
 * cut (`strict_id`, unless it was already inside out) and every object with an id ≥
 * `strict_from` (the new pieces; 0: none). Elsewhere an inside-out piece is counted in
 * *inverted, not failed: a step can turn a small piece inside out for reasons of its model
 * (test_stability.c: mss springs have zero energy in a mirror image, the linear model is not
 * rotation-invariant, and a violently kicked corotational/localframe cell passes through
 * inversion before it recovers). Slivers (pieces enclosing less than 1e-3 h³, made by cuts
 * grazing the surface) are exempt from the sign everywhere: sub-micron motion decides it.
 */
static int check_all(const cs_world_t *w, views *vw, double volume, double rel_tol, double *total,
                     int *n_objects, int *inverted, cs_object_id strict_id,
                     cs_object_id strict_from, char *why, size_t n)
{
    const int no = cs_world_object_ids(w, vw->ids, MAX_OBJ);
    if (no >= MAX_OBJ) {
        snprintf(why, n, "more than %d objects", MAX_OBJ);
        return 0;
    }
    int ni = 0;
    double sum = 0;
    for (int i = 0; i < no; i++) {
        const double *v;
        const int32_t *t;
        int nv, nt;
        cs_object_info info;
        if (cs_object_surface(w, vw->ids[i], &v, &nv, &t, &nt) != CS_OK ||
            cs_object_get_info(w, vw->ids[i], &info) != CS_OK) {
            snprintf(why, n, "object %u: no surface", (unsigned)vw->ids[i]);
            return 0;
        }
        cs_watertight_report rep;
        char e[256];
        if (!cs_watertight_check(v, nv, t, nt, &rep, e, sizeof e)) {
            const bool closed = rep.boundary_edges == 0 && rep.nonmanifold_edges == 0 &&
                                rep.misoriented_edges == 0 && rep.degenerate_triangles == 0;
            const double hh = info.cube_size * info.cube_size * info.cube_size;
            const bool sliver = fabs(rep.volume) < 1e-3 * hh;
            const bool strict = vw->ids[i] == strict_id ||
                                (strict_from != CS_NULL_OBJECT && vw->ids[i] >= strict_from);
            if (!closed || (strict && !sliver)) {
                snprintf(why, n, "object %u (%s, %s%s): %s", (unsigned)vw->ids[i], info.name,
                         cs_model_name(info.model), strict ? ", just made by a fracture" : "", e);
                return 0;
            }
            if (!sliver)
                ni++;
        }
        sum += fabs(rep.volume);
    }
    *n_objects = no;
    if (inverted)
        *inverted = ni;
    if (total)
        *total = sum;
    if (isfinite(volume) && fabs(sum - volume) > rel_tol * fabs(volume)) {
        snprintf(why, n, "volumes add up to %.9g m^3, want %.9g within %g", sum, volume, rel_tol);
        return 0;
    }
    return 1;
}

/* Is this object's surface inside out (negative enclosed volume)? */
static bool inside_out(const cs_world_t *w, cs_object_id id)
{
    const double *v;
    const int32_t *t;
    int nv, nt;
    if (cs_object_surface(w, id, &v, &nv, &t, &nt) != CS_OK)
        return false;
    return cs_mesh_volume(v, t, nt) <= 0;
}

static int add_mesh(cs_world_t *w, const char *dir, const char *file, const char *name,
                    cs_model model, double h, const double at[3], char *err, size_t errlen)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir, file);
    cs_mesh m;
    if (cs_mesh_load(path, &m, err, errlen) != 0)
        return -1;
    cs_mesh_transform(&m, 1.0, (double[3]){0, 0, 0}, at);
    cs_object_def d = cs_object_def_default();
    d.name = name;
    d.model = model;
    d.integrator = CS_INTEGRATOR_IMPLICIT_EULER;
    d.cube_size = h;
    d.material.young = 1e5;
    d.geometry = CS_GEOMETRY_MESH;
    d.mesh_vertices = m.v;
    d.n_mesh_vertices = m.nv;
    d.mesh_triangles = m.t;
    d.n_mesh_triangles = m.nt;
    const int rc = cs_world_add_object(w, &d, NULL, err, errlen);
    cs_mesh_free(&m);
    return rc == CS_OK ? 0 : -1;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv)
{
    int n_fract = 2000, n_steps = 600;
    bool trace = false; /* --trace: after every storm step, the fastest node's object */
    uint64_t seed = 1;
    const char *dir = "scenes/meshes";
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--fractures") && i + 1 < argc)
            n_fract = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--steps") && i + 1 < argc)
            n_steps = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--seed") && i + 1 < argc)
            seed = strtoull(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--meshes") && i + 1 < argc)
            dir = argv[++i];
        else if (!strcmp(argv[i], "--trace"))
            trace = true;
        else {
            fprintf(stderr, "usage: %s [--fractures N] [--steps S] [--seed K] [--meshes DIR] [--trace]\n",
                    argv[0]);
            return 2;
        }
    }
    rng_state = seed * 0x9E3779B97F4A7C15ULL + 12345;
    const double t0 = now_s();
    char err[512] = "", why[512] = "";
    views vw = {malloc(sizeof(cs_object_id) * MAX_OBJ), malloc(sizeof(cs_piece_view) * MAX_OBJ)};
    double max_dv = 0, end_volume = 0;
    int fail = 0, fractures = 0, events = 0, objects = 0, inverted = 0, max_inverted = 0;
    if (!vw.ids || !vw.pv) {
        fprintf(stderr, "out of memory\n");
        return 2;
    }

    /* ------------------------------------------------------------ 1. the storm */
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = 0;
    wd.threads = 1;
    wd.sleep_steps = 0;
    cs_world_t *w = NULL;
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK) {
        fprintf(stderr, "world: %s\n", err);
        return 2;
    }
    int32_t box_ijk[3 * 16 * 12 * 8];
    int nb = 0;
    for (int k = 0; k < 8; k++)
        for (int j = 0; j < 12; j++)
            for (int i = 0; i < 16; i++) {
                box_ijk[3 * nb] = i, box_ijk[3 * nb + 1] = j, box_ijk[3 * nb + 2] = k;
                nb++;
            }
    cs_object_def bd = cs_object_def_default();
    bd.name = "box";
    bd.cube_size = 0.0125;
    bd.cells_ijk = box_ijk;
    bd.n_cells = nb;
    bd.material.young = 1e5;
    if (cs_world_add_object(w, &bd, NULL, err, sizeof err) != CS_OK ||
        add_mesh(w, dir, "icosphere.obj", "icosphere", CS_MODEL_LINEAR, 0.025,
                 (double[3]){0.5, 0, 0}, err, sizeof err) ||
        add_mesh(w, dir, "torus.obj", "torus", CS_MODEL_MSS, 0.02, (double[3]){1.0, 0, 0}, err,
                 sizeof err) ||
        add_mesh(w, dir, "star.obj", "star", CS_MODEL_LOCALFRAME, 0.02, (double[3]){1.5, 0, 0},
                 err, sizeof err)) {
        fprintf(stderr, "setup: %s\n", err);
        return 2;
    }
    double volume = 0;
    if (!check_all(w, &vw, NAN, 0, &volume, &objects, &inverted, CS_NULL_OBJECT, 1, why, sizeof why)) {
        printf("FAIL storm-start: %s\n", why);
        return 1;
    }
    printf("     storm: 4 objects, %.6g m^3 of surface volume at the start\n", volume);
    int cuts_with_faces = 0;
    for (int f = 0; f < n_fract && !fail; f++) {
        /* an object picked with probability ∝ its cells: the big ones keep being cut */
        const int no = cs_world_object_ids(w, vw.ids, MAX_OBJ);
        int cells_total = 0;
        for (int k = 0; k < no; k++) {
            cs_object_info info;
            cs_object_get_info(w, vw.ids[k], &info);
            cells_total += info.n_cells;
        }
        int pick = (int)(urand() * cells_total), ko = 0;
        for (; ko < no - 1; ko++) {
            cs_object_info info;
            cs_object_get_info(w, vw.ids[ko], &info);
            if (pick < info.n_cells)
                break;
            pick -= info.n_cells;
        }
        const cs_object_id id = vw.ids[ko];
        const double *X, *x, *v;
        int n;
        cs_object_nodes(w, id, &X, &x, &v, &n);
        double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (int i = 0; i < n; i++)
            for (int a = 0; a < 3; a++) {
                lo[a] = fmin(lo[a], x[3 * i + a]);
                hi[a] = fmax(hi[a], x[3 * i + a]);
            }
        /* half the points anywhere in the bounding box, half at a node (inside the material:
         * those cut) */
        const int node = (int)(urand() * n) % n;
        const bool at_node = urand() < 0.5;
        double p[3], nrm[3], nn = 0;
        for (int a = 0; a < 3; a++) {
            p[a] = at_node ? x[3 * node + a] + 0.01 * (urand() - 0.5)
                           : lo[a] + urand() * (hi[a] - lo[a]);
            nrm[a] = urand() - 0.5;
            nn += nrm[a] * nrm[a];
        }
        if (nn < 1e-6)
            nrm[2] = 1;
        double before = 0;
        if (!check_all(w, &vw, NAN, 0, &before, &objects, &inverted, CS_NULL_OBJECT, 0, why, sizeof why)) {
            printf("FAIL storm-watertight: before fracture %d: %s\n", f, why);
            fail = 1;
            break;
        }
        const bool was_inside_out = inside_out(w, id);
        cs_object_id next_id = 0;
        for (int k = 0; k < objects; k++)
            next_id = vw.ids[k] >= next_id ? vw.ids[k] + 1 : next_id;
        const int rc = cs_world_fracture(w, id, p, nrm, 0, err, sizeof err);
        if (rc != CS_OK) {
            printf("FAIL storm-fracture: fracture %d of object %u: %s\n", f, (unsigned)id, err);
            fail = 1;
            break;
        }
        fractures++;
        max_inverted = max_inverted > inverted ? max_inverted : inverted;
        int ne;
        const cs_event *ev = cs_world_events(w, &ne);
        events += ne;
        for (int e = 0; e < ne; e++)
            if (ev[e].kind == CS_EVENT_FRACTURE && ev[e].faces_cut > 0)
                cuts_with_faces++;
        double tot;
        if (!check_all(w, &vw, before, 0.01, &tot, &objects, &inverted, was_inside_out ? CS_NULL_OBJECT : id, next_id, why, sizeof why)) {
            printf("FAIL storm-watertight: after fracture %d (object %u, point %.4f %.4f %.4f): %s\n",
                   f, (unsigned)id, p[0], p[1], p[2], why);
            fail = 1;
            break;
        }
        max_dv = fmax(max_dv, fabs(tot - before) / before);
        if (f % 10 == 9) {
            const cs_object_id pid = vw.ids[(int)(urand() * no) % no];
            cs_world_apply_force(w, pid, p,
                                 (double[3]){0.1 * (urand() - 0.5), 0.1 * (urand() - 0.5),
                                             0.1 * (urand() - 0.5)},
                                 0, err, sizeof err);
            const int src = cs_world_step(w);
            if (src != CS_OK && src != CS_ERR_NOT_CONVERGED) {
                printf("FAIL storm-step: after fracture %d: %s\n", f, cs_status_str(src));
                fail = 1;
            } else if (!check_all(w, &vw, NAN, 0, &tot, &objects, &inverted, CS_NULL_OBJECT, 0, why, sizeof why)) {
                printf("FAIL storm-watertight: after the step following fracture %d: %s\n", f, why);
                fail = 1;
            }
            if (trace) {
                const int nt = cs_world_object_ids(w, vw.ids, MAX_OBJ);
                double vmax = 0;
                cs_object_id fast = CS_NULL_OBJECT;
                for (int k = 0; k < nt; k++) {
                    const double *tv;
                    int tn;
                    cs_object_nodes(w, vw.ids[k], NULL, NULL, &tv, &tn);
                    for (int q = 0; q < 3 * tn; q++)
                        if (fabs(tv[q]) > vmax) {
                            vmax = fabs(tv[q]);
                            fast = vw.ids[k];
                        }
                }
                cs_object_info ti;
                if (fast != CS_NULL_OBJECT && cs_object_get_info(w, fast, &ti) == CS_OK)
                    printf("     trace: after fracture %d: fastest node %.3g m/s, object %u (%s, %s, "
                           "%d cells)\n", f, vmax, (unsigned)fast, ti.name, cs_model_name(ti.model),
                           ti.n_cells);
            }
        }
    }
    check_all(w, &vw, NAN, 0, &end_volume, &objects, &inverted, CS_NULL_OBJECT, 0, why, sizeof why);
    if (!fail)
        printf("     storm: largest volume change of one fracture %.3g %%; volume at the end %.6g "
               "m^3 (%+.3g %%: steps deform the pieces, and small linear pieces set spinning inflate, "
               "see stab_spin_tumbling_block)\n", 100 * max_dv, end_volume,
               100 * (end_volume / volume - 1));
    if (!fail)
        printf("PASS storm-watertight (%d forced fractures, %d cut faces, %d events, %d objects: "
               "every surface closed and oriented, each fracture keeps the volume within 1 %%; at most %d pieces inside out at "
               "once after steps, never one a fracture made)\n",
               fractures, cuts_with_faces, events, objects, max_inverted);
    cs_world_destroy(w);

    /* ------------------------------------------------------------ 2. a load breaks it */
    int load_events = 0, load_objects = 0;
    if (!fail) {
        wd = cs_world_def_default();
        wd.threads = 1;
        wd.has_ground = true;
        wd.ground_height = 0;
        wd.max_fractures = 4;
        if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK) {
            fprintf(stderr, "world: %s\n", err);
            return 2;
        }
        int32_t ijk[3 * 40];
        int nc = 0;
        for (int k = 0; k < 2; k++)
            for (int j = 0; j < 2; j++)
                for (int i = 0; i < 10; i++) {
                    ijk[3 * nc] = i, ijk[3 * nc + 1] = j, ijk[3 * nc + 2] = k;
                    nc++;
                }
        cs_object_def d = cs_object_def_default();
        d.name = "brittle";
        d.cube_size = 0.02;
        d.cells_ijk = ijk;
        d.n_cells = nc;
        d.cells_origin[2] = 0.1;
        d.material.young = 5e4;
        d.material.strength = 300;
        d.material.damping[0] = 0.5;
        d.fracture = true;
        const cs_aabb fix = {{-1e-4, -1, -1}, {1e-4, 1, 1}};
        d.fixed = &fix;
        d.n_fixed = 1;
        if (cs_world_add_object(w, &d, NULL, err, sizeof err) != CS_OK) {
            fprintf(stderr, "setup: %s\n", err);
            return 2;
        }
        for (int s = 0; s < n_steps && !fail; s++) {
            const int no = cs_world_object_ids(w, vw.ids, MAX_OBJ);
            const cs_object_id id = vw.ids[(int)(urand() * no) % no];
            const double *X, *x, *v;
            int n;
            cs_object_nodes(w, id, &X, &x, &v, &n);
            const int node = (int)(urand() * n) % n;
            const double mag = 0.5 + 1.5 * urand();
            double push[3] = {urand() - 0.5, urand() - 0.5, urand() - 0.5};
            const double dn = sqrt(push[0] * push[0] + push[1] * push[1] + push[2] * push[2]) + 1e-12;
            for (int a = 0; a < 3; a++)
                push[a] *= mag / dn;
            cs_world_apply_force(w, id, x + 3 * node, push, 0, err, sizeof err);
            cs_object_id next_id = 0;
            for (int k = 0; k < no; k++)
                next_id = vw.ids[k] >= next_id ? vw.ids[k] + 1 : next_id;
            const int rc = cs_world_step(w);
            if (rc != CS_OK && rc != CS_ERR_NOT_CONVERGED) {
                printf("FAIL load-step: step %d: %s\n", s, cs_status_str(rc));
                fail = 1;
                break;
            }
            int ne;
            cs_world_events(w, &ne);
            if (ne > 0) {
                load_events += ne;
                double tot;
                if (!check_all(w, &vw, NAN, 0, &tot, &load_objects, &inverted, CS_NULL_OBJECT, next_id, why, sizeof why)) {
                    printf("FAIL load-watertight: after step %d: %s\n", s, why);
                    fail = 1;
                }
            }
        }
        check_all(w, &vw, NAN, 0, NULL, &load_objects, &inverted, CS_NULL_OBJECT, 0, why, sizeof why);
        if (!fail && load_events < 10) {
            printf("FAIL load-breaks: only %d fracture events in %d steps (want >= 10: the load "
                   "must break it repeatedly)\n", load_events, n_steps);
            fail = 1;
        } else if (!fail) {
            printf("PASS load-watertight (%d steps, %d events, %d objects at the end: every "
                   "surface closed and oriented after every step with events)\n",
                   n_steps, load_events, load_objects);
        }
        cs_world_destroy(w);
    }
    free(vw.ids);
    free(vw.pv);
    printf("fracture_storm: %d fractures (%d events), %d objects, load %d events, peak RSS %ld kB, "
           "%.1f s: %s\n", fractures, events, objects, load_events, peak_rss_kb(), now_s() - t0,
           fail ? "FAIL" : "ok");
    return fail;
}
