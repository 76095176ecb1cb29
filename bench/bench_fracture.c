/*
 * bench_fracture.c — the cost of one fracture event against the number of surface triangles.
 *
 * A sphere of radius 0.1 m made by subdividing a tetrahedron L times and projecting onto the
 * sphere (4·4^L triangles: 1k, 4k, 16k, 64k, 256k for L = 4…8), voxelized at one fixed cube
 * size (default h = 0.02 m, about 700 cubes at every L), so that only the surface grows.
 * Two measurements per mesh, each the median over --runs fresh worlds:
 *  - fracture: one cs_world_fracture through the sphere's centre cell (normal along x, the
 *    default radius): stress-free split of the cells near the plane, surface splitting,
 *    closing surfaces, connected pieces, topology changes;
 *  - step: one cs_world_step of the same sphere with fracture enabled, its bottom held and a
 *    load pulling its top up hard enough that its first step overstresses it (strength 1 Pa),
 *    against the same step with the strength at its default (nothing breaks): the difference
 *    is what fracture adds to a loaded step (stress test, fracture, closing surface). The step
 *    is reported only if it fractured (events > 0).
 * The surface triangle count on the x axis is the engine's (after edge subdivision to h,
 * which adds triangles on the coarse meshes). CSV to --csv, a Markdown table on stdout, the
 * log-log growth exponent (least squares over the sizes that worked) on stderr.
 *
 * Until the engine's fracture exists (cs_world_fracture returns an error), the error is
 * printed, the column is "nan" and the run goes on.
 *
 * Usage: bench_fracture [--levels 4,5,6,7,8] [--runs 5] [--h 0.02] [--csv FILE]
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench_util.h"
#include "cubesim.h"

/* ---------------------------------------------------------------- the sphere */

typedef struct sphere {
    double *v;
    int nv, cap_v;
    int32_t *t;
    int nt;
} sphere;

/* Edge midpoint cache: open addressing on the (min, max) vertex pair. */
typedef struct edge_map {
    int64_t *key;
    int32_t *val;
    int cap;
} edge_map;

static int32_t midpoint(sphere *s, edge_map *m, int32_t a, int32_t b, double r)
{
    int64_t k = a < b ? ((int64_t)a << 32) | b : ((int64_t)b << 32) | a;
    uint64_t h = (uint64_t)k * 0x9E3779B97F4A7C15ull;
    int i = (int)(h >> 33) & (m->cap - 1);
    while (m->key[i] >= 0) {
        if (m->key[i] == k)
            return m->val[i];
        i = (i + 1) & (m->cap - 1);
    }
    double p[3], n = 0;
    for (int c = 0; c < 3; c++) {
        p[c] = 0.5 * (s->v[3 * a + c] + s->v[3 * b + c]);
        n += p[c] * p[c];
    }
    n = sqrt(n);
    for (int c = 0; c < 3; c++)
        s->v[3 * s->nv + c] = r * p[c] / n;
    m->key[i] = k;
    m->val[i] = s->nv;
    return s->nv++;
}

/* A tetrahedron subdivided `levels` times, every vertex on the sphere of radius r: 4·4^L
 * triangles, counter-clockwise seen from outside. Returns 0 or -1 (out of memory). */
static int make_sphere(sphere *s, int levels, double r)
{
    const double k = r / sqrt(3.0);
    const double v0[4][3] = {{k, k, k}, {k, -k, -k}, {-k, k, -k}, {-k, -k, k}};
    const int32_t t0[4][3] = {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}};
    long nt_final = 4L << (2 * levels);
    long nv_final = nt_final / 2 + 2;
    memset(s, 0, sizeof *s);
    s->v = malloc(sizeof *s->v * 3 * (size_t)nv_final);
    s->t = malloc(sizeof *s->t * 3 * (size_t)nt_final);
    int32_t *tmp = malloc(sizeof *tmp * 3 * (size_t)nt_final);
    if (!s->v || !s->t || !tmp) {
        free(tmp);
        return -1;
    }
    memcpy(s->v, v0, sizeof v0);
    memcpy(s->t, t0, sizeof t0);
    s->nv = 4;
    s->nt = 4;
    for (int l = 0; l < levels; l++) {
        edge_map m;
        m.cap = 16;
        while (m.cap < 4 * s->nt)
            m.cap *= 2;
        m.key = malloc(sizeof *m.key * (size_t)m.cap);
        m.val = malloc(sizeof *m.val * (size_t)m.cap);
        if (!m.key || !m.val) {
            free(m.key);
            free(m.val);
            free(tmp);
            return -1;
        }
        for (int i = 0; i < m.cap; i++)
            m.key[i] = -1;
        int n = 0;
        for (int i = 0; i < s->nt; i++) {
            int32_t a = s->t[3 * i], b = s->t[3 * i + 1], c = s->t[3 * i + 2];
            int32_t ab = midpoint(s, &m, a, b, r), bc = midpoint(s, &m, b, c, r),
                    ca = midpoint(s, &m, c, a, r);
            int32_t q[12] = {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca};
            memcpy(tmp + 3 * n, q, sizeof q);
            n += 4;
        }
        memcpy(s->t, tmp, sizeof *tmp * 3 * (size_t)n);
        s->nt = n;
        free(m.key);
        free(m.val);
    }
    free(tmp);
    return 0;
}

/* ---------------------------------------------------------------- one run */

typedef struct result {
    double ms_fracture, ms_step_fracture, ms_step_plain;
    int surface_triangles, cells, events, closing_triangles;
} result;

/* A world with the sphere; `strength` and loads only for the step measurement. */
static cs_world_t *make_world(const sphere *s, double h, int loaded, double strength,
                              cs_object_id *id)
{
    char err[256];
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    wd.sleep_steps = 0;
    if (!loaded)
        wd.gravity[2] = 0;
    cs_world_t *w;
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_fracture: world: %s\n", err);
        return NULL;
    }
    cs_object_def d = cs_object_def_default();
    d.name = "sphere";
    d.cube_size = h;
    d.fracture = true;
    d.material.young = 1e5;
    d.material.strength = strength;
    d.geometry = CS_GEOMETRY_MESH;
    d.mesh_vertices = s->v;
    d.n_mesh_vertices = s->nv;
    d.mesh_triangles = s->t;
    d.n_mesh_triangles = s->nt;
    /* held below z = -0.06, pulled up by 200 N on the exposed faces above z = 0.06 */
    cs_aabb fix = {{-1, -1, -1}, {1, 1, -0.06}};
    cs_load load = {{{-1, -1, 0.06}, {1, 1, 1}}, {0, 0, 200}};
    if (loaded) {
        d.fixed = &fix;
        d.n_fixed = 1;
        d.loads = &load;
        d.n_loads = 1;
    }
    if (cs_world_add_object(w, &d, id, err, sizeof err) != CS_OK) {
        fprintf(stderr, "bench_fracture: add: %s\n", err);
        cs_world_destroy(w);
        return NULL;
    }
    return w;
}

static int run_once(const sphere *s, double h, result *r, int report_errors)
{
    char err[256];
    cs_object_id id;
    memset(r, 0, sizeof *r);
    r->ms_fracture = r->ms_step_fracture = r->ms_step_plain = NAN;

    /* 1. a forced fracture through the centre cell */
    cs_world_t *w = make_world(s, h, 0, 1e300, &id);
    if (!w)
        return -1;
    cs_object_info info;
    cs_object_get_info(w, id, &info);
    r->surface_triangles = info.n_surface_triangles;
    r->cells = info.n_cells;
    const double centre[3] = {1e-4, 2e-4, 3e-4}, normal[3] = {1, 0, 0};
    err[0] = 0;
    double t0 = now_s();
    int rc = cs_world_fracture(w, id, centre, normal, 0, err, sizeof err);
    double el = now_s() - t0;
    if (rc == CS_OK) {
        r->ms_fracture = 1e3 * el;
        int n;
        const cs_event *ev = cs_world_events(w, &n);
        for (int i = 0; i < n; i++)
            if (ev[i].kind == CS_EVENT_FRACTURE)
                r->closing_triangles += ev[i].closing_triangles;
    } else if (report_errors) {
        fprintf(stderr, "bench_fracture: cs_world_fracture (%d triangles): %s: %s\n",
                s->nt, cs_status_str(rc), err);
    }
    cs_world_destroy(w);

    /* 2. one loaded step, breaking (strength 1 Pa) and not (default strength) */
    for (int breaking = 0; breaking < 2; breaking++) {
        w = make_world(s, h, 1, breaking ? 1.0 : cs_material_default().strength, &id);
        if (!w)
            return -1;
        t0 = now_s();
        rc = cs_world_step(w);
        el = now_s() - t0;
        int n = 0;
        cs_world_events(w, &n);
        if (breaking) {
            r->events = n;
            if (rc == CS_OK && n > 0)
                r->ms_step_fracture = 1e3 * el;
            else if (report_errors)
                fprintf(stderr, "bench_fracture: loaded step (%d triangles): %s, %d events: "
                        "no fracture to time\n", s->nt, cs_status_str(rc), n);
        } else if (rc == CS_OK || rc == CS_ERR_NOT_CONVERGED) {
            r->ms_step_plain = 1e3 * el;
        }
        cs_world_destroy(w);
    }
    return 0;
}

/* Least-squares slope of log(y) against log(x) over finite, positive points; NAN if < 2. */
static double loglog_slope(const double *x, const double *y, int n)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int m = 0;
    for (int i = 0; i < n; i++)
        if (isfinite(y[i]) && y[i] > 0 && x[i] > 0) {
            double a = log(x[i]), b = log(y[i]);
            sx += a, sy += b, sxx += a * a, sxy += a * b;
            m++;
        }
    if (m < 2 || sxx * m - sx * sx <= 0)
        return NAN;
    return (m * sxy - sx * sy) / (m * sxx - sx * sx);
}

int main(int argc, char **argv)
{
    int levels[8] = {4, 5, 6, 7, 8}, nl = 5, runs = 5;
    double h = 0.02;
    const char *csv = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--levels") && i + 1 < argc)
            nl = parse_list(argv[++i], levels, 8);
        else if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--h") && i + 1 < argc)
            h = atof(argv[++i]);
        else if (!strcmp(argv[i], "--csv") && i + 1 < argc)
            csv = argv[++i];
        else {
            fprintf(stderr, "usage: bench_fracture [--levels 4,5,6,7,8] [--runs 5] [--h 0.02] "
                            "[--csv FILE]\n");
            return 2;
        }
    }
    if (runs < 1 || runs > 100)
        runs = 5;
    if (!(h > 0.002 && h < 0.2)) {
        fprintf(stderr, "bench_fracture: --h must be in (0.002, 0.2) m\n");
        return 2;
    }
    FILE *f = csv ? fopen(csv, "w") : NULL;
    if (csv && !f) {
        fprintf(stderr, "bench_fracture: cannot write %s\n", csv);
        return 2;
    }
    if (f)
        fprintf(f, "mesh_triangles,surface_triangles,cells,runs,ms_fracture,ms_step_fracture,"
                   "ms_step_plain,fracture_events,closing_triangles\n");
    printf("| mesh triangles | surface triangles | cubes | fracture call ms | loaded step ms "
           "(breaking) | loaded step ms (intact) | events | closing triangles |\n"
           "|---|---|---|---|---|---|---|---|\n");
    double xs[8], ys[8], ysf[8];
    for (int li = 0; li < nl; li++) {
        if (levels[li] < 0 || levels[li] > 9) {
            fprintf(stderr, "bench_fracture: level %d out of [0, 9]\n", levels[li]);
            return 2;
        }
        sphere s;
        if (make_sphere(&s, levels[li], 0.1) != 0) {
            fprintf(stderr, "bench_fracture: out of memory\n");
            return 1;
        }
        result rs[100];
        double a[100], b[100], c[100];
        int ok = 1;
        for (int r = 0; r < runs && ok; r++)
            ok = run_once(&s, h, &rs[r], r == 0) == 0;
        if (!ok) {
            free(s.v);
            free(s.t);
            return 1;
        }
        for (int r = 0; r < runs; r++) {
            a[r] = rs[r].ms_fracture;
            b[r] = rs[r].ms_step_fracture;
            c[r] = rs[r].ms_step_plain;
        }
        double mf = median(a, runs), ms = median(b, runs), mp = median(c, runs);
        printf("| %d | %d | %d | %.3f | %.3f | %.3f | %d | %d |\n", s.nt,
               rs[0].surface_triangles, rs[0].cells, mf, ms, mp, rs[0].events,
               rs[0].closing_triangles);
        if (f)
            fprintf(f, "%d,%d,%d,%d,%.6g,%.6g,%.6g,%d,%d\n", s.nt, rs[0].surface_triangles,
                    rs[0].cells, runs, mf, ms, mp, rs[0].events, rs[0].closing_triangles);
        xs[li] = rs[0].surface_triangles;
        ys[li] = mf;
        ysf[li] = isfinite(ms) && isfinite(mp) ? ms - mp : NAN;
        free(s.v);
        free(s.t);
    }
    if (f)
        fclose(f);
    double e1 = loglog_slope(xs, ys, nl), e2 = loglog_slope(xs, ysf, nl);
    if (isfinite(e1))
        fprintf(stderr, "  fracture call: cost grows as triangles^%.2f (log-log least squares, "
                        "%.0f to %.0f triangles)\n", e1, xs[0], xs[nl - 1]);
    else
        fprintf(stderr, "  fracture call: no growth exponent (fewer than two sizes fractured)\n");
    if (isfinite(e2))
        fprintf(stderr, "  fracture within a loaded step (breaking - intact): grows as "
                        "triangles^%.2f\n", e2);
    else
        fprintf(stderr, "  fracture within a loaded step: no growth exponent (fewer than two "
                        "sizes fractured under load)\n");
    return 0;
}
