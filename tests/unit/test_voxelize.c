/*
 * test_voxelize.c — seed 000 §3.3 edge subdivision, the triangle/box SAT, §2.1 voxelization,
 * and the embedded surface (server/engine/voxelize.c, surface.c): binding, skinning, the
 * boundary surface of a cell set.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "check.h"
#include "cubemesh.h"
#include "cubesim.h"
#include "mesh.h"
#include "surface.h"
#include "voxelize.h"
#include "watertight.h"

#ifndef CS_SOURCE_DIR
#define CS_SOURCE_DIR "."
#endif

static const char *vox_mesh_path(char *buf, size_t n, const char *name)
{
    const char *root = getenv("CS_SOURCE_DIR");
    snprintf(buf, n, "%s/scenes/meshes/%s", root && *root ? root : CS_SOURCE_DIR, name);
    return buf;
}

/* An axis-aligned box mesh [lo, lo+size], 8 vertices, 12 outward triangles (malloc'd). */
static void box_mesh(cs_mesh *m, const double lo[3], const double size[3])
{
    static const int32_t bt[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6},
                                      {0, 1, 5}, {0, 5, 4}, {2, 6, 7}, {2, 7, 3},
                                      {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
    m->nv = 8;
    m->nt = 12;
    m->v = malloc(24 * sizeof *m->v);
    m->t = malloc(36 * sizeof *m->t);
    for (int i = 0; i < 8; i++)
        for (int k = 0; k < 3; k++)
            m->v[3 * i + k] = lo[k] + ((i >> k) & 1) * size[k];
    memcpy(m->t, bt, sizeof bt);
}

static double max_edge(const cs_mesh *m)
{
    double worst = 0;
    for (int t = 0; t < m->nt; t++)
        for (int k = 0; k < 3; k++) {
            const double *a = m->v + 3 * m->t[3 * t + k], *b = m->v + 3 * m->t[3 * t + (k + 1) % 3];
            double d = sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                            (a[2] - b[2]) * (a[2] - b[2]));
            worst = d > worst ? d : worst;
        }
    return worst;
}

/* The icosphere of scenes/meshes, subdivided to edges <= len and pushed onto the sphere. */
static int fine_sphere(cs_mesh *m, double radius, double len)
{
    char p[512], err[256];
    if (cs_mesh_load(vox_mesh_path(p, sizeof p, "icosphere.obj"), m, err, sizeof err) != 0)
        return -1;
    /* pushing midpoints outwards lengthens edges by up to ~1/cos: leave some margin */
    if (cs_subdivide_edges(&m->v, &m->nv, &m->t, &m->nt, 0.9 * len * 0.1 / radius, err,
                           sizeof err) != 0) {
        cs_mesh_free(m);
        return -1;
    }
    for (int i = 0; i < m->nv; i++) {
        double *q = m->v + 3 * i;
        double r = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
        for (int k = 0; k < 3; k++)
            q[k] *= radius / r;
    }
    return 0;
}

/* ---------------------------------------------------------------- subdivision */

TEST(subdivide_bounds_edges_keeps_closed_and_volume)
{
    char p[512], err[256];
    const double lens[] = {0.05, 0.013, 0.004};
    for (int l = 0; l < 3; l++) {
        cs_mesh m;
        ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "icosphere.obj"), &m, err, sizeof err) ==
               0);
        double v0 = cs_mesh_volume(m.v, m.t, m.nt);
        int nt0 = m.nt;
        int rc = cs_subdivide_edges(&m.v, &m.nv, &m.t, &m.nt, lens[l], err, sizeof err);
        double worst = max_edge(&m);
        double v1 = cs_mesh_volume(m.v, m.t, m.nt);
        int closed = cs_watertight_check(m.v, m.nv, m.t, m.nt, NULL, err, sizeof err);
        int nv = m.nv, nt = m.nt;
        cs_mesh_free(&m);
        ENSURE_MSG(rc == 0, "%s", err);
        ENSURE_MSG(worst <= lens[l], "longest edge %g > %g", worst, lens[l]);
        ENSURE_MSG(closed, "after subdivision to %g: %s", lens[l], err);
        ENSURE_NEAR(v1, v0, 1e-15);
        /* Euler: a closed genus-0 surface has V - E + F = 2, E = 3F/2 */
        ENSURE(nv - 3 * nt / 2 + nt == 2);
        ENSURE(l == 0 || nt > nt0);
    }
    /* an open mesh stays open with the same boundary length, and nothing short is touched */
    cs_mesh o;
    ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "open_sphere.obj"), &o, err, sizeof err) == 0);
    int nt_before = o.nt;
    ENSURE(cs_subdivide_edges(&o.v, &o.nv, &o.t, &o.nt, 1.0, err, sizeof err) == 0);
    ENSURE(o.nt == nt_before);
    ENSURE(cs_subdivide_edges(&o.v, &o.nv, &o.t, &o.nt, 0.01, err, sizeof err) == 0);
    cs_watertight_report rep;
    cs_watertight_check(o.v, o.nv, o.t, o.nt, &rep, err, sizeof err);
    double worst = max_edge(&o);
    cs_mesh_free(&o);
    ENSURE(worst <= 0.01);
    ENSURE(rep.misoriented_edges == 0 && rep.nonmanifold_edges == 0);
    ENSURE(rep.boundary_edges > 6); /* the hole's rim is split too */
    ENSURE(cs_subdivide_edges(&o.v, &o.nv, &o.t, &o.nt, 0.0, err, sizeof err) == -1);
}

TEST(subdivide_100k_triangles_quickly)
{
    /* a unit box with 12 long triangles; edges <= 1/64 gives well over 100k triangles */
    cs_mesh m;
    char err[256];
    box_mesh(&m, (double[3]){0, 0, 0}, (double[3]){1, 1, 1});
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    int rc = cs_subdivide_edges(&m.v, &m.nv, &m.t, &m.nt, 1.0 / 64, err, sizeof err);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    double s = (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec);
    double worst = max_edge(&m);
    int closed = cs_watertight_check(m.v, m.nv, m.t, m.nt, NULL, err, sizeof err);
    double vol = cs_mesh_volume(m.v, m.t, m.nt);
    int nt = m.nt;
    cs_mesh_free(&m);
    ENSURE(rc == 0);
    ENSURE_MSG(nt >= 100000, "only %d triangles", nt);
    ENSURE(worst <= 1.0 / 64);
    ENSURE_MSG(closed, "%s", err);
    ENSURE_NEAR(vol, 1.0, 1e-12);
    /* generous: about 0.1 s in the release build, slower under sanitizers */
    ENSURE_MSG(s < 5.0, "%d triangles took %.2f s", nt, s);
}

/* ---------------------------------------------------------------- SAT */

static uint64_t rng_state = 0x9e3779b97f4a7c15ULL;
static double urand(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) / 9007199254740992.0;
}

/* Independent exact reference: clip the triangle by the six slabs (Sutherland–Hodgman). */
static int clip_overlap(const double c[3], const double hlf[3], const double *a, const double *b,
                        const double *cc)
{
    double poly[16][3], tmp[16][3];
    int n = 3;
    memcpy(poly[0], a, sizeof poly[0]);
    memcpy(poly[1], b, sizeof poly[0]);
    memcpy(poly[2], cc, sizeof poly[0]);
    for (int ax = 0; ax < 3; ax++)
        for (int side = -1; side <= 1; side += 2) {
            double bound = c[ax] + side * hlf[ax];
            int m = 0;
            for (int i = 0; i < n; i++) {
                const double *p = poly[i], *q = poly[(i + 1) % n];
                double dp = side * (p[ax] - bound), dq = side * (q[ax] - bound); /* <= 0 inside */
                if (dp <= 0)
                    memcpy(tmp[m++], p, sizeof tmp[0]);
                if ((dp < 0 && dq > 0) || (dp > 0 && dq < 0)) {
                    double s = dp / (dp - dq);
                    for (int k = 0; k < 3; k++)
                        tmp[m][k] = p[k] + s * (q[k] - p[k]);
                    tmp[m][ax] = bound;
                    m++;
                }
            }
            n = m;
            memcpy(poly, tmp, (size_t)m * sizeof tmp[0]);
            if (n == 0)
                return 0;
        }
    return 1;
}

TEST(sat_matches_clipping_and_sampling)
{
    int checked = 0, hits = 0;
    for (int it = 0; it < 200000; it++) {
        double c[3], hf[3], v[3][3];
        for (int k = 0; k < 3; k++) {
            c[k] = urand() - 0.5;
            hf[k] = 0.05 + 0.3 * urand();
        }
        double scale = it % 3 == 0 ? 0.3 : 1.0;
        for (int q = 0; q < 3; q++)
            for (int k = 0; k < 3; k++)
                v[q][k] = scale * (2 * urand() - 1);
        if (it % 5 == 0) /* put a vertex exactly on a box face plane */
            v[it % 3][it % 2] = c[it % 2] + hf[it % 2];
        if (it % 7 == 0) /* a degenerate (collinear) triangle */
            for (int k = 0; k < 3; k++)
                v[2][k] = 0.5 * (v[0][k] + v[1][k]);
        int clip = clip_overlap(c, hf, v[0], v[1], v[2]);
        double big[3], small[3];
        for (int k = 0; k < 3; k++) {
            big[k] = hf[k] * (1 + 1e-9);
            small[k] = hf[k] * (1 - 1e-9);
        }
        if (clip) {
            ENSURE_MSG(cs_tri_box_overlap(c, big, v[0], v[1], v[2]),
                       "iteration %d: SAT misses: c %.17g %.17g %.17g h %.17g %.17g %.17g "
                       "a %.17g %.17g %.17g b %.17g %.17g %.17g c %.17g %.17g %.17g",
                       it, c[0], c[1], c[2], hf[0], hf[1], hf[2], v[0][0], v[0][1], v[0][2],
                       v[1][0], v[1][1], v[1][2], v[2][0], v[2][1], v[2][2]);
            hits++;
        } else {
            ENSURE_MSG(!cs_tri_box_overlap(c, small, v[0], v[1], v[2]),
                       "iteration %d: SAT overlaps", it);
        }
        /* sampling: a sample point of the triangle inside the box means overlap */
        if (it % 20 == 0) {
            for (int s = 0; s < 400; s++) {
                double r1 = urand(), r2 = urand();
                if (r1 + r2 > 1)
                    r1 = 1 - r1, r2 = 1 - r2;
                int inside = 1;
                for (int k = 0; k < 3; k++) {
                    double x = v[0][k] + r1 * (v[1][k] - v[0][k]) + r2 * (v[2][k] - v[0][k]);
                    inside &= fabs(x - c[k]) < small[k];
                }
                if (inside) {
                    ENSURE_MSG(cs_tri_box_overlap(c, hf, v[0], v[1], v[2]),
                               "iteration %d: sample inside but SAT says apart", it);
                    break;
                }
            }
        }
        checked++;
    }
    ENSURE(hits > 10000 && checked - hits > 10000);
    /* touching exactly on a face counts as overlap for the closed test */
    ENSURE(cs_tri_box_overlap((double[3]){0, 0, 0}, (double[3]){1, 1, 1}, (double[3]){1, -5, -5},
                              (double[3]){1, 5, -5}, (double[3]){1, 0, 5}));
    ENSURE(!cs_tri_box_overlap((double[3]){0, 0, 0}, (double[3]){1, 1, 1},
                               (double[3]){1.000001, -5, -5}, (double[3]){1.000001, 5, -5},
                               (double[3]){1.000001, 0, 5}));
    /* a big triangle around a small box, no vertex inside: only the plane axis decides */
    ENSURE(cs_tri_box_overlap((double[3]){0, 0, 0}, (double[3]){0.1, 0.1, 0.1},
                              (double[3]){-10, -10, 0.05}, (double[3]){10, -10, 0.05},
                              (double[3]){0, 10, 0.05}));
    ENSURE(!cs_tri_box_overlap((double[3]){0, 0, 0}, (double[3]){0.1, 0.1, 0.1},
                               (double[3]){-10, -10, 0.15}, (double[3]){10, -10, 0.15},
                               (double[3]){0, 10, 0.15}));
}

/* ---------------------------------------------------------------- voxelization */

static int vox(const cs_mesh *m, double h, double origin[3], int32_t **ijk, int *n, char *err,
               size_t errlen)
{
    return cs_voxelize(m->v, m->nv, m->t, m->nt, h, origin, ijk, n, err, errlen);
}

TEST(voxelize_lattice_aligned_box_exact_count)
{
    char err[256];
    double origin[3];
    int32_t *ijk;
    int n;
    const double h = 0.025;
    const double offsets[3][3] = {{0, 0, 0}, {0.3, -1.7, 2.25}, {-0.0125, 0.1, 0.0375}};
    for (int o = 0; o < 3; o++) {
        cs_mesh m;
        box_mesh(&m, offsets[o], (double[3]){4 * h, 4 * h, 4 * h});
        int rc = vox(&m, h, origin, &ijk, &n, err, sizeof err);
        ENSURE_MSG(rc == 0, "%s", err);
        free(ijk);
        ENSURE_MSG(n == 64, "box 4h at offset %d: %d cells", o, n);
        /* vertices on every lattice line of the faces change nothing */
        ENSURE(cs_subdivide_edges(&m.v, &m.nv, &m.t, &m.nt, h, err, sizeof err) == 0);
        rc = vox(&m, h, origin, &ijk, &n, err, sizeof err);
        cs_mesh_free(&m);
        ENSURE_MSG(rc == 0, "%s", err);
        free(ijk);
        ENSURE_MSG(n == 64, "subdivided box 4h at offset %d: %d cells", o, n);
    }
    /* the same box read from a file: float32 coordinates (0.1f = 0.100000001) still give 64 */
    {
        char path[] = "/tmp/cs_test_box_XXXXXX.obj";
        int fd = mkstemps(path, 4);
        ENSURE(fd >= 0);
        FILE *f = fdopen(fd, "w");
        fprintf(f, "v 0.2 0.3 0.1\nv 0.3 0.3 0.1\nv 0.2 0.4 0.1\nv 0.3 0.4 0.1\n"
                   "v 0.2 0.3 0.2\nv 0.3 0.3 0.2\nv 0.2 0.4 0.2\nv 0.3 0.4 0.2\n"
                   "f 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\n"
                   "f 3 7 8\nf 3 8 4\nf 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\n");
        fclose(f);
        cs_mesh fm;
        int rc = cs_mesh_load(path, &fm, err, sizeof err);
        unlink(path);
        ENSURE_MSG(rc == 0, "%s", err);
        rc = vox(&fm, h, origin, &ijk, &n, err, sizeof err);
        cs_mesh_free(&fm);
        ENSURE_MSG(rc == 0, "%s", err);
        free(ijk);
        ENSURE_MSG(n == 64, "float32 box: %d cells", n);
    }
    /* 4h x 2h x 3h -> 24 cells; 4.5h per side -> 5^3 */
    cs_mesh m;
    box_mesh(&m, (double[3]){0.1, 0.2, 0.3}, (double[3]){4 * h, 2 * h, 3 * h});
    ENSURE(vox(&m, h, origin, &ijk, &n, err, sizeof err) == 0);
    cs_mesh_free(&m);
    free(ijk);
    ENSURE(n == 24);
    box_mesh(&m, (double[3]){0, 0, 0}, (double[3]){4.5 * h, 4.5 * h, 4.5 * h});
    ENSURE(vox(&m, h, origin, &ijk, &n, err, sizeof err) == 0);
    cs_mesh_free(&m);
    free(ijk);
    ENSURE(n == 125);
    /* a flat box thinner than a cell is kept as one layer */
    box_mesh(&m, (double[3]){0, 0, 0}, (double[3]){4 * h, 4 * h, 0.1 * h});
    ENSURE(vox(&m, h, origin, &ijk, &n, err, sizeof err) == 0);
    cs_mesh_free(&m);
    free(ijk);
    ENSURE(n == 16);
}

/* Every point within 1e-9 h of some kept cell? */
static int covered(const cs_cubemesh *cm, const double *p)
{
    double l[3];
    for (int k = 0; k < 3; k++)
        l[k] = (p[k] - cm->origin[k]) / cm->h;
    for (int a = -1; a <= 1; a++)
        for (int b = -1; b <= 1; b++)
            for (int c = -1; c <= 1; c++) {
                int i = (int)floor(l[0]) + a, j = (int)floor(l[1]) + b, k = (int)floor(l[2]) + c;
                if (cs_cubemesh_find(cm, i, j, k) < 0)
                    continue;
                if (l[0] >= i - 1e-9 && l[0] <= i + 1 + 1e-9 && l[1] >= j - 1e-9 &&
                    l[1] <= j + 1 + 1e-9 && l[2] >= k - 1e-9 && l[2] <= k + 1 + 1e-9)
                    return 1;
            }
    return 0;
}

SLOW_TEST(voxelize_sphere_volume_converges)
{
    const double r = 0.1, exact = 4.0 / 3.0 * M_PI * r * r * r;
    cs_mesh m;
    ENSURE(fine_sphere(&m, r, 0.004) == 0);
    const double hs[4] = {0.04, 0.02, 0.01, 0.005};
    double e[4];
    char err[256];
    for (int q = 0; q < 4; q++) {
        double origin[3];
        int32_t *ijk;
        int n;
        if (vox(&m, hs[q], origin, &ijk, &n, err, sizeof err) != 0) {
            cs_mesh_free(&m);
            ENSURE_MSG(0, "%s", err);
        }
        cs_cubemesh cm;
        int rc = cs_cubemesh_build(&cm, hs[q], origin, ijk, n, err, sizeof err);
        free(ijk);
        if (rc != 0) {
            cs_mesh_free(&m);
            ENSURE_MSG(0, "%s", err);
        }
        int all = 1;
        for (int i = 0; i < m.nv && all; i++)
            all = covered(&cm, m.v + 3 * i);
        cs_cubemesh_free(&cm);
        if (!all) {
            cs_mesh_free(&m);
            ENSURE_MSG(0, "h = %g: a surface vertex lies in no cell", hs[q]);
        }
        e[q] = n * hs[q] * hs[q] * hs[q] - exact;
        if (e[q] <= 0) {
            cs_mesh_free(&m);
            ENSURE_MSG(0, "h = %g: the cells (%g) do not cover the sphere (%g)", hs[q],
                       n * hs[q] * hs[q] * hs[q], exact);
        }
    }
    cs_mesh_free(&m);
    /* the kept set overshoots by about a layer of half cells: error ~ area * h */
    for (int q = 1; q < 4; q++) {
        double ratio = e[q - 1] / e[q];
        ENSURE_MSG(ratio > 1.4 && ratio < 3.0, "h %g -> %g: error %g -> %g (ratio %.2f)",
                   hs[q - 1], hs[q], e[q - 1], e[q], ratio);
    }
    ENSURE_MSG(e[3] / exact < 0.2, "relative error %.3f at h = 0.005", e[3] / exact);
    if (getenv("CS_VERBOSE"))
        printf("    sphere r = 0.1: relative volume error %.4f %.4f %.4f %.4f at h = 0.04 ... 0.005\n",
               e[0] / exact, e[1] / exact, e[2] / exact, e[3] / exact);
}

TEST(voxelize_torus_has_a_hole)
{
    char p[512], err[256];
    cs_mesh m;
    ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "torus.obj"), &m, err, sizeof err) == 0);
    double origin[3];
    int32_t *ijk;
    int n;
    const double h = 0.01;
    int rc = vox(&m, h, origin, &ijk, &n, err, sizeof err);
    cs_mesh_free(&m);
    ENSURE_MSG(rc == 0, "%s", err);
    cs_cubemesh cm;
    rc = cs_cubemesh_build(&cm, h, origin, ijk, n, err, sizeof err);
    free(ijk);
    ENSURE_MSG(rc == 0, "%s", err);
    /* the hole has radius R - r = 0.06: no cell within 0.04 of the axis at z = 0 */
    int in_hole = 0, on_ring = 0;
    for (int c = 0; c < cm.n_cells; c++) {
        double x = origin[0] + (cm.cell_ijk[3 * c] + 0.5) * h;
        double y = origin[1] + (cm.cell_ijk[3 * c + 1] + 0.5) * h;
        double d = sqrt(x * x + y * y);
        in_hole += d < 0.04;
        on_ring += fabs(d - 0.1) < 0.005;
    }
    int centre = cs_cubemesh_find(&cm, (int)floor((0 - origin[0]) / h),
                                  (int)floor((0 - origin[1]) / h), (int)floor((0 - origin[2]) / h));
    double vol = cm.n_cells * h * h * h;
    cs_cubemesh_free(&cm);
    ENSURE(centre < 0);
    ENSURE(in_hole == 0);
    ENSURE(on_ring > 0);
    /* torus volume 2 pi^2 R r^2 = 3.158e-3; the cells cover it with a shell of ~h/2 */
    ENSURE(vol > 2 * M_PI * M_PI * 0.1 * 0.04 * 0.04);
    ENSURE(vol < 2.0 * 2 * M_PI * M_PI * 0.1 * 0.04 * 0.04);
}

TEST(voxelize_refuses_open_and_absurd)
{
    char p[512], err[256];
    cs_mesh m;
    ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "open_sphere.obj"), &m, err, sizeof err) == 0);
    double origin[3];
    int32_t *ijk = (int32_t *)&m; /* must be reset */
    int n = 7;
    int rc = vox(&m, 0.01, origin, &ijk, &n, err, sizeof err);
    ENSURE(rc == -1);
    ENSURE(ijk == NULL && n == 0);
    ENSURE_MSG(!strcmp(err, "mesh is not closed: 6 boundary edges"), "%s", err);
    cs_mesh_free(&m);

    ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "icosphere.obj"), &m, err, sizeof err) == 0);
    rc = vox(&m, 1e-5, origin, &ijk, &n, err, sizeof err);
    ENSURE(rc == -1);
    ENSURE_MSG(strstr(err, "h = 1e-05") && strstr(err, "cells"), "%s", err);
    rc = vox(&m, 0.0, origin, &ijk, &n, err, sizeof err);
    ENSURE(rc == -1);
    rc = vox(&m, NAN, origin, &ijk, &n, err, sizeof err);
    ENSURE(rc == -1);
    /* a cube larger than the mesh: one cell */
    rc = vox(&m, 1.0, origin, &ijk, &n, err, sizeof err);
    cs_mesh_free(&m);
    ENSURE_MSG(rc == 0, "%s", err);
    free(ijk);
    ENSURE(n == 1);
}

TEST(voxelize_nonmanifold_closed_mesh)
{
    /* two 0.05 cubes sharing an edge: closed, not manifold, well defined as a solid */
    char p[512], err[256];
    cs_mesh m;
    ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "nonmanifold.obj"), &m, err, sizeof err) == 0);
    double origin[3];
    int32_t *ijk;
    int n;
    int rc = vox(&m, 0.0125, origin, &ijk, &n, err, sizeof err);
    cs_mesh_free(&m);
    ENSURE_MSG(rc == 0, "%s", err);
    free(ijk);
    ENSURE_MSG(n == 128, "%d cells", n);
}

/* What the engine refuses at cs_world_add_object (cs_mesh_surface_check): a closed surface it
 * cannot fracture or skin — not manifold, mixed orientation, inside out — each with one line
 * naming the problem; the good surface passes. */
TEST(mesh_surface_check_names_the_problem)
{
    char p[512], err[256];
    cs_mesh m;
    ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "icosphere.obj"), &m, err, sizeof err) == 0);
    ENSURE_MSG(cs_mesh_surface_check(m.v, m.nv, m.t, m.nt, err, sizeof err) == 0, "%s", err);
    /* every triangle reversed: inside out */
    for (int t = 0; t < m.nt; t++) {
        int32_t a = m.t[3 * t + 1];
        m.t[3 * t + 1] = m.t[3 * t + 2];
        m.t[3 * t + 2] = a;
    }
    ENSURE(cs_mesh_surface_check(m.v, m.nv, m.t, m.nt, err, sizeof err) == -1);
    ENSURE_MSG(strstr(err, "inside out") && !strchr(err, '\n'), "%s", err);
    /* the first triangle turned back alone: its three edges now run the same way twice */
    int32_t a = m.t[1];
    m.t[1] = m.t[2];
    m.t[2] = a;
    ENSURE(cs_mesh_surface_check(m.v, m.nv, m.t, m.nt, err, sizeof err) == -1);
    ENSURE_MSG(strstr(err, "not consistently oriented: 3 edges"), "%s", err);
    /* a triangle with a repeated vertex */
    m.t[1] = m.t[0];
    ENSURE(cs_mesh_surface_check(m.v, m.nv, m.t, m.nt, err, sizeof err) == -1);
    ENSURE_MSG(strstr(err, "repeated vertex"), "%s", err);
    cs_mesh_free(&m);
    ENSURE(cs_mesh_load(vox_mesh_path(p, sizeof p, "nonmanifold.obj"), &m, err, sizeof err) == 0);
    ENSURE(cs_mesh_surface_check(m.v, m.nv, m.t, m.nt, err, sizeof err) == -1);
    ENSURE_MSG(strstr(err, "not manifold"), "%s", err);
    /* and the engine refuses it at add time with that message, the world unchanged */
    cs_world_def wd = cs_world_def_default();
    cs_world_t *w = NULL;
    ENSURE(cs_world_create(&wd, &w, err, sizeof err) == CS_OK);
    cs_object_def od = cs_object_def_default();
    od.name = "two cubes";
    od.cube_size = 0.0125;
    od.geometry = CS_GEOMETRY_MESH;
    od.mesh_vertices = m.v;
    od.n_mesh_vertices = m.nv;
    od.mesh_triangles = m.t;
    od.n_mesh_triangles = m.nt;
    cs_object_id id;
    int rc = cs_world_add_object(w, &od, &id, err, sizeof err);
    cs_mesh_free(&m);
    ENSURE(rc == CS_ERR_GEOMETRY);
    ENSURE_MSG(strstr(err, "not manifold"), "%s", err);
    ENSURE(cs_world_object_ids(w, NULL, 0) == 0);
    cs_world_destroy(w);
}

/* ---------------------------------------------------------------- surface binding */

TEST(surface_bind_and_skin)
{
    cs_mesh m;
    ENSURE(fine_sphere(&m, 0.1, 0.01) == 0);
    char err[256];
    double origin[3];
    int32_t *ijk;
    int n;
    const double h = 0.02;
    ENSURE(vox(&m, h, origin, &ijk, &n, err, sizeof err) == 0);
    cs_cubemesh cm;
    int rc = cs_cubemesh_build(&cm, h, origin, ijk, n, err, sizeof err);
    free(ijk);
    ENSURE_MSG(rc == 0, "%s", err);
    cs_surface s;
    rc = cs_surface_bind(&s, &cm, m.v, m.nv, m.t, m.nt, err, sizeof err);
    if (rc != 0) {
        cs_cubemesh_free(&cm);
        cs_mesh_free(&m);
        ENSURE_MSG(0, "%s", err);
    }
    int bad = 0;
    for (int i = 0; i < s.n_vertices; i++) {
        bad += s.vert_cell[i] < 0 || s.vert_cell[i] >= cm.n_cells;
        for (int k = 0; k < 3; k++)
            bad += !(s.vert_uvw[3 * i + k] >= 0 && s.vert_uvw[3 * i + k] <= 1);
    }
    /* every triangle is listed in the cell its centroid is in, and lists are sorted */
    for (int t = 0; t < s.n_triangles; t++) {
        int c = s.tri_cell[t], found = 0;
        for (int q = s.cell_tri_start[c]; q < s.cell_tri_start[c + 1]; q++)
            found |= s.cell_tri_list[q] == t;
        bad += !found;
    }
    for (int c = 0; c < cm.n_cells; c++)
        for (int q = s.cell_tri_start[c] + 1; q < s.cell_tri_start[c + 1]; q++)
            bad += s.cell_tri_list[q] <= s.cell_tri_list[q - 1];
    /* at rest: skinning gives back the rest positions */
    memset(s.pos, 0, (size_t)s.n_vertices * 3 * sizeof *s.pos);
    cs_surface_skin(&s, &cm, cm.node_rest, 1);
    double err_rest = 0;
    for (int i = 0; i < 3 * s.n_vertices; i++)
        err_rest = fmax(err_rest, fabs(s.pos[i] - m.v[i]));
    /* an affine node map x -> A x + b is reproduced exactly by trilinear interpolation */
    const double A[3][3] = {{1.2, 0.3, -0.1}, {-0.2, 0.9, 0.4}, {0.05, -0.3, 1.1}};
    const double b[3] = {0.5, -1.0, 2.0};
    double *np = malloc((size_t)cm.n_nodes * 3 * sizeof *np);
    for (int i = 0; i < cm.n_nodes; i++)
        for (int r = 0; r < 3; r++)
            np[3 * i + r] = A[r][0] * cm.node_rest[3 * i] + A[r][1] * cm.node_rest[3 * i + 1] +
                            A[r][2] * cm.node_rest[3 * i + 2] + b[r];
    cs_surface_skin(&s, &cm, np, 1);
    double err_aff = 0;
    for (int i = 0; i < s.n_vertices; i++)
        for (int r = 0; r < 3; r++) {
            const double *x = m.v + 3 * i;
            double want = A[r][0] * x[0] + A[r][1] * x[1] + A[r][2] * x[2] + b[r];
            err_aff = fmax(err_aff, fabs(s.pos[3 * i + r] - want));
        }
    free(np);
    cs_surface_free(&s);
    ENSURE(s.rest == NULL && s.n_vertices == 0);
    /* a vertex outside every cell is refused */
    double far[9] = {5, 5, 5, 5.1, 5, 5, 5, 5.1, 5};
    int32_t ft[3] = {0, 1, 2};
    rc = cs_surface_bind(&s, &cm, far, 3, ft, 1, err, sizeof err);
    cs_cubemesh_free(&cm);
    cs_mesh_free(&m);
    ENSURE(rc == -1);
    ENSURE_MSG(strstr(err, "vertex 0") && strstr(err, "no cube"), "%s", err);
    ENSURE(bad == 0);
    ENSURE_MSG(err_rest <= 1e-12, "rest error %g", err_rest);
    ENSURE_MSG(err_aff <= 1e-12, "affine error %g", err_aff);
}

TEST(surface_bind_on_cell_boundaries)
{
    /* a lattice-aligned box: every vertex lies on cell boundaries, the top ones on the outer
     * faces, where only the lower cell exists */
    const double h = 0.025;
    cs_mesh m;
    char err[256];
    box_mesh(&m, (double[3]){0.1, 0.1, 0.1}, (double[3]){2 * h, 3 * h, 4 * h});
    ENSURE(cs_subdivide_edges(&m.v, &m.nv, &m.t, &m.nt, 0.5 * h, err, sizeof err) == 0);
    double origin[3];
    int32_t *ijk;
    int n;
    ENSURE(vox(&m, h, origin, &ijk, &n, err, sizeof err) == 0);
    ENSURE(n == 24);
    cs_cubemesh cm;
    int rc = cs_cubemesh_build(&cm, h, origin, ijk, n, err, sizeof err);
    free(ijk);
    ENSURE(rc == 0);
    cs_surface s;
    rc = cs_surface_bind(&s, &cm, m.v, m.nv, m.t, m.nt, err, sizeof err);
    if (rc == 0) {
        cs_surface_skin(&s, &cm, cm.node_rest, 1);
        double e = 0;
        for (int i = 0; i < 3 * m.nv; i++)
            e = fmax(e, fabs(s.pos[i] - m.v[i]));
        cs_surface_free(&s);
        if (e > 1e-12)
            rc = 2;
    }
    cs_cubemesh_free(&cm);
    cs_mesh_free(&m);
    ENSURE_MSG(rc == 0, "rc %d: %s", rc, err);
}

TEST(surface_of_cells_is_closed_with_the_right_volume)
{
    const double h = 0.1;
    /* an L of 3 cells plus a 2x2x2 block elsewhere with a notch: all manifold */
    int32_t cells[][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 5, 5}, {6, 5, 5}, {5, 6, 5},
                          {6, 6, 5}, {5, 5, 6}, {6, 5, 6}, {5, 6, 6}};
    int n = (int)(sizeof cells / sizeof cells[0]);
    cs_cubemesh cm;
    char err[256];
    ENSURE(cs_cubemesh_build(&cm, h, (double[3]){-0.3, 0.2, 1.0}, &cells[0][0], n, err,
                             sizeof err) == 0);
    for (int sub = 1; sub <= 3; sub++) {
        double *v;
        int32_t *t;
        int nv, nt;
        int rc = cs_surface_of_cells(&cm, sub, &v, &nv, &t, &nt, err, sizeof err);
        if (rc != 0) {
            cs_cubemesh_free(&cm);
            ENSURE_MSG(0, "%s", err);
        }
        cs_watertight_report rep;
        int ok = cs_watertight_check(v, nv, t, nt, &rep, err, sizeof err);
        double longest = 0;
        for (int i = 0; i < nt; i++)
            for (int k = 0; k < 3; k++) {
                const double *a = v + 3 * t[3 * i + k], *b = v + 3 * t[3 * i + (k + 1) % 3];
                longest = fmax(longest, sqrt((a[0] - b[0]) * (a[0] - b[0]) +
                                             (a[1] - b[1]) * (a[1] - b[1]) +
                                             (a[2] - b[2]) * (a[2] - b[2])));
            }
        free(v);
        free(t);
        if (!ok) {
            cs_cubemesh_free(&cm);
            ENSURE_MSG(0, "sub %d: %s", sub, err);
        }
        ENSURE_NEAR(rep.volume, n * h * h * h, 1e-14);
        /* L: 14 exposed faces, notched block: 24 - 3 + 3 = 24 faces */
        ENSURE_MSG(nt == (14 + 24) * 2 * sub * sub, "sub %d: %d triangles", sub, nt);
        ENSURE_NEAR(longest, sqrt(2.0) * h / sub, 1e-12);
    }
    cs_cubemesh_free(&cm);
}

/* ---------------------------------------------------------------- cavities */

/* Append to m (malloc'd or zeroed) the box [lo, lo+size]: outward, or inward (a cavity's
 * wall, its triangles reversed). */
static void add_box(cs_mesh *m, const double lo[3], const double size[3], int inward)
{
    cs_mesh b;
    box_mesh(&b, lo, size);
    m->v = realloc(m->v, (size_t)(m->nv + 8) * 3 * sizeof *m->v);
    m->t = realloc(m->t, (size_t)(m->nt + 12) * 3 * sizeof *m->t);
    memcpy(m->v + 3 * m->nv, b.v, 24 * sizeof *b.v);
    for (int t = 0; t < 12; t++)
        for (int c = 0; c < 3; c++)
            m->t[3 * (m->nt + t) + c] = m->nv + b.t[3 * t + (inward ? 2 - c : c)];
    m->nv += 8;
    m->nt += 12;
    cs_mesh_free(&b);
}

/* Append the sphere of radius r about c (fine_sphere with edges <= len), inward or not. */
static int add_sphere(cs_mesh *m, const double c[3], double r, double len, int inward)
{
    cs_mesh s;
    if (fine_sphere(&s, r, len) != 0)
        return -1;
    m->v = realloc(m->v, (size_t)(m->nv + s.nv) * 3 * sizeof *m->v);
    m->t = realloc(m->t, (size_t)(m->nt + s.nt) * 3 * sizeof *m->t);
    for (int i = 0; i < s.nv; i++)
        for (int k = 0; k < 3; k++)
            m->v[3 * (m->nv + i) + k] = c[k] + s.v[3 * i + k];
    for (int t = 0; t < s.nt; t++)
        for (int k = 0; k < 3; k++)
            m->t[3 * (m->nt + t) + k] = m->nv + s.t[3 * t + (inward ? 2 - k : k)];
    m->nv += s.nv;
    m->nt += s.nt;
    cs_mesh_free(&s);
    return 0;
}

/* Is cell (i, j, k) in the list? */
static int has_cell(const int32_t *ijk, int n, int i, int j, int k)
{
    for (int c = 0; c < n; c++)
        if (ijk[3 * c] == i && ijk[3 * c + 1] == j && ijk[3 * c + 2] == k)
            return 1;
    return 0;
}

/* Voxelize m at h: the cell count (-1 on error), and the subdivided mesh gives the same. */
static int vox_count(const cs_mesh *m, double h, int32_t **ijk_out, char *err, size_t errlen)
{
    double origin[3];
    int32_t *ijk;
    int n;
    if (vox(m, h, origin, &ijk, &n, err, errlen) != 0)
        return -1;
    if (ijk_out)
        *ijk_out = ijk;
    else
        free(ijk);
    return n;
}

/*
 * A closed inner shell wound inward is a cavity (seed 000 §2.1 keeps the cubes inside the
 * surface; the inside of a hollow body does not hold its cavity): an 8h box with a 4h cavity
 * at 2h..6h keeps 512 - 64 cells. Lattice-aligned, the walls lie on lattice planes and no
 * cell is overlapped: the cavity is only told apart by the inside test. With the edges
 * subdivided to h (vertices on every lattice line: rays through edges and vertices), at three
 * offsets, and read through a float32 OBJ, the count is the same; so it is with the whole
 * mesh turned inside out (a winding number of -1 is inside too).
 */
TEST(voxelize_cavity_lattice_aligned)
{
    char err[256];
    const double h = 0.025;
    const double offsets[3][3] = {{0, 0, 0}, {0.3, -1.7, 2.25}, {-0.0125, 0.1, 0.0375}};
    for (int o = 0; o < 3; o++) {
        for (int flip = 0; flip < 2; flip++) {
            cs_mesh m = {0};
            double in[3];
            for (int k = 0; k < 3; k++)
                in[k] = offsets[o][k] + 2 * h;
            add_box(&m, offsets[o], (double[3]){8 * h, 8 * h, 8 * h}, flip);
            add_box(&m, in, (double[3]){4 * h, 4 * h, 4 * h}, !flip);
            int32_t *ijk = NULL;
            int n = vox_count(&m, h, &ijk, err, sizeof err);
            if (n < 0)
                cs_mesh_free(&m);
            ENSURE_MSG(n >= 0, "%s", err);
            int hollow = 0, walls = 0;
            for (int k = 0; k < 8; k++)
                for (int j = 0; j < 8; j++)
                    for (int i = 0; i < 8; i++) {
                        int cav = i >= 2 && i < 6 && j >= 2 && j < 6 && k >= 2 && k < 6;
                        int got = has_cell(ijk, n, i, j, k);
                        hollow += cav && got;
                        walls += !cav && got;
                    }
            free(ijk);
            if (n != 448 || hollow || walls != 448)
                cs_mesh_free(&m);
            ENSURE_MSG(n == 448 && hollow == 0 && walls == 448,
                       "offset %d%s: %d cells, %d in the cavity, %d of the 448 walls", o,
                       flip ? " inside out" : "", n, hollow, walls);
            int rc = cs_subdivide_edges(&m.v, &m.nv, &m.t, &m.nt, h, err, sizeof err);
            n = rc == 0 ? vox_count(&m, h, NULL, err, sizeof err) : -1;
            cs_mesh_free(&m);
            ENSURE_MSG(n == 448, "subdivided, offset %d%s: %d cells (%s)", o,
                       flip ? " inside out" : "", n, n < 0 ? err : "");
        }
    }
    /* float32 coordinates from a file */
    char path[] = "/tmp/cs_test_cavity_XXXXXX.obj";
    int fd = mkstemps(path, 4);
    ENSURE(fd >= 0);
    FILE *f = fdopen(fd, "w");
    for (int s = 0; s < 2; s++) {
        const double lo = s ? 0.15 : 0.1, size = s ? 0.1 : 0.2; /* h = 0.025: 8h and 4h */
        for (int i = 0; i < 8; i++)
            fprintf(f, "v %.9g %.9g %.9g\n", lo + (i & 1) * size, lo + (i >> 1 & 1) * size,
                    lo + (i >> 2 & 1) * size);
    }
    static const int bt[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                                  {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
    for (int s = 0; s < 2; s++)
        for (int t = 0; t < 12; t++)
            fprintf(f, "f %d %d %d\n", 8 * s + bt[t][0] + 1, 8 * s + bt[t][s ? 2 : 1] + 1,
                    8 * s + bt[t][s ? 1 : 2] + 1);
    fclose(f);
    cs_mesh fm;
    int rc = cs_mesh_load(path, &fm, err, sizeof err);
    unlink(path);
    ENSURE_MSG(rc == 0, "%s", err);
    int n = vox_count(&fm, h, NULL, err, sizeof err);
    cs_mesh_free(&fm);
    ENSURE_MSG(n == 448, "float32 hollow box: %d cells (%s)", n, n < 0 ? err : "");
}

/*
 * Which unreached regions are solid, by the winding number: a cavity not on the lattice (the
 * cubes its wall crosses are kept, the 2x2x2 wholly inside it are not), a solid box inside a
 * cavity (nested shells: kept), two hollow boxes side by side (several outer shells), two
 * overlapping outward boxes (winding number 2 where they overlap: solid, as the flood always
 * had it), and an inner shell with one triangle turned (not an oriented surface: the parity
 * of the crossings decides, and the cavity stays empty).
 */
TEST(voxelize_cavity_nested_and_several_shells)
{
    char err[256];
    const double h = 0.025;
    const double o[3] = {0.1, 0.2, 0.3};
    cs_mesh m = {0};
    int32_t *ijk = NULL;
    /* cavity 2.5h..5.5h: cells 2 and 5 hold its wall, 3 and 4 are empty */
    add_box(&m, o, (double[3]){8 * h, 8 * h, 8 * h}, 0);
    add_box(&m, (double[3]){o[0] + 2.5 * h, o[1] + 2.5 * h, o[2] + 2.5 * h},
            (double[3]){3 * h, 3 * h, 3 * h}, 1);
    int n = vox_count(&m, h, &ijk, err, sizeof err);
    int hollow = 0;
    for (int c = 0; c < n; c++) {
        int in = 1;
        for (int k = 0; k < 3; k++)
            in &= ijk[3 * c + k] == 3 || ijk[3 * c + k] == 4;
        hollow += in;
    }
    free(ijk);
    cs_mesh_free(&m);
    ENSURE_MSG(n == 512 - 8 && hollow == 0, "unaligned cavity: %d cells, %d inside it (%s)", n,
               hollow, n < 0 ? err : "");

    /* 12h box, cavity 2h..10h, solid 4h..8h inside: 1728 - 512 + 64 */
    memset(&m, 0, sizeof m);
    add_box(&m, o, (double[3]){12 * h, 12 * h, 12 * h}, 0);
    add_box(&m, (double[3]){o[0] + 2 * h, o[1] + 2 * h, o[2] + 2 * h},
            (double[3]){8 * h, 8 * h, 8 * h}, 1);
    add_box(&m, (double[3]){o[0] + 4 * h, o[1] + 4 * h, o[2] + 4 * h},
            (double[3]){4 * h, 4 * h, 4 * h}, 0);
    n = vox_count(&m, h, &ijk, err, sizeof err);
    int core = 0;
    for (int c = 0; c < n; c++) {
        int in = 1;
        for (int k = 0; k < 3; k++)
            in &= ijk[3 * c + k] >= 4 && ijk[3 * c + k] < 8;
        core += in;
    }
    free(ijk);
    cs_mesh_free(&m);
    ENSURE_MSG(n == 1728 - 512 + 64 && core == 64, "nested: %d cells, %d of the core's 64", n,
               core);

    /* two hollow boxes 2h apart along x: 2 x 448 */
    memset(&m, 0, sizeof m);
    for (int b = 0; b < 2; b++) {
        double lo[3] = {o[0] + 10 * h * b, o[1], o[2]};
        add_box(&m, lo, (double[3]){8 * h, 8 * h, 8 * h}, 0);
        add_box(&m, (double[3]){lo[0] + 2 * h, lo[1] + 2 * h, lo[2] + 2 * h},
                (double[3]){4 * h, 4 * h, 4 * h}, 1);
    }
    n = vox_count(&m, h, NULL, err, sizeof err);
    cs_mesh_free(&m);
    ENSURE_MSG(n == 2 * 448, "two hollow boxes: %d cells", n);

    /* overlapping 4h boxes, offset 2h on every axis: 64 + 64 - 8 */
    memset(&m, 0, sizeof m);
    add_box(&m, o, (double[3]){4 * h, 4 * h, 4 * h}, 0);
    add_box(&m, (double[3]){o[0] + 2 * h, o[1] + 2 * h, o[2] + 2 * h},
            (double[3]){4 * h, 4 * h, 4 * h}, 0);
    n = vox_count(&m, h, NULL, err, sizeof err);
    cs_mesh_free(&m);
    ENSURE_MSG(n == 120, "overlapping boxes: %d cells", n);

    /* the 8h/4h hollow box with one triangle of the cavity turned back */
    memset(&m, 0, sizeof m);
    add_box(&m, o, (double[3]){8 * h, 8 * h, 8 * h}, 0);
    add_box(&m, (double[3]){o[0] + 2 * h, o[1] + 2 * h, o[2] + 2 * h},
            (double[3]){4 * h, 4 * h, 4 * h}, 1);
    int32_t tmp = m.t[3 * 12 + 1];
    m.t[3 * 12 + 1] = m.t[3 * 12 + 2];
    m.t[3 * 12 + 2] = tmp;
    n = vox_count(&m, h, NULL, err, sizeof err);
    cs_mesh_free(&m);
    ENSURE_MSG(n == 448, "misoriented cavity: %d cells", n);
}

/*
 * A hollow ball (sphere r = 0.1 outward, r = 0.06 inward) with a solid ball r = 0.03 in its
 * cavity, not on the lattice: every cell whose cube lies wholly inside the cavity and outside
 * the core is gone, every cell whose centre lies in the shell or the core (by more than the
 * chord error) is there, and the kept volume converges to the solid's.
 */
TEST(voxelize_hollow_ball_with_a_core)
{
    const double c[3] = {0.013, -0.007, 0.021};
    const double r_out = 0.1, r_in = 0.06, r_core = 0.03, len = 0.005;
    cs_mesh m = {0};
    ENSURE(add_sphere(&m, c, r_out, len, 0) == 0 && add_sphere(&m, c, r_in, len, 1) == 0 &&
           add_sphere(&m, c, r_core, len, 0) == 0);
    char err[256];
    const double hs[2] = {0.01, 0.005};
    const double exact =
        4.0 / 3.0 * M_PI * (r_out * r_out * r_out - r_in * r_in * r_in + r_core * r_core * r_core);
    for (int q = 0; q < 2; q++) {
        const double h = hs[q];
        double origin[3];
        int32_t *ijk;
        int n;
        if (vox(&m, h, origin, &ijk, &n, err, sizeof err) != 0) {
            cs_mesh_free(&m);
            ENSURE_MSG(0, "%s", err);
        }
        /* chord error of edges <= len on radius r: len^2 / (8 r) < 1e-4 */
        const double slack = 1e-4, half_diag = 0.5 * sqrt(3.0) * h;
        int in_cavity = 0, missing = 0, kept_cav = 0;
        int32_t lo[3], hi[3];
        for (int k = 0; k < 3; k++) {
            lo[k] = (int32_t)floor((c[k] - r_out - origin[k]) / h) - 1;
            hi[k] = (int32_t)floor((c[k] + r_out - origin[k]) / h) + 1;
        }
        /* mark the kept cells in a dense box */
        int dx = hi[0] - lo[0] + 1, dy = hi[1] - lo[1] + 1, dz = hi[2] - lo[2] + 1;
        uint8_t *kept = calloc((size_t)dx * dy * dz, 1);
        for (int e = 0; e < n; e++)
            kept[((size_t)(ijk[3 * e + 2] - lo[2]) * dy + (ijk[3 * e + 1] - lo[1])) * dx +
                 (ijk[3 * e] - lo[0])] = 1;
        free(ijk);
        for (int k = lo[2]; k <= hi[2]; k++)
            for (int j = lo[1]; j <= hi[1]; j++)
                for (int i = lo[0]; i <= hi[0]; i++) {
                    double p[3] = {origin[0] + (i + 0.5) * h, origin[1] + (j + 0.5) * h,
                                   origin[2] + (k + 0.5) * h};
                    double d = sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                                    (p[2] - c[2]) * (p[2] - c[2]));
                    int got = kept[((size_t)(k - lo[2]) * dy + (j - lo[1])) * dx + (i - lo[0])];
                    int cavity = d + half_diag < r_in - slack && d - half_diag > r_core + slack;
                    int solid = (d > r_in + slack && d < r_out - slack) || d < r_core - slack;
                    in_cavity += cavity;
                    kept_cav += cavity && got;
                    missing += solid && !got;
                }
        free(kept);
        const double rel = (n * h * h * h - exact) / exact;
        if (kept_cav || missing || in_cavity < 50 || !(rel > 0 && rel < 0.5))
            cs_mesh_free(&m);
        ENSURE_MSG(kept_cav == 0 && missing == 0 && in_cavity >= 50,
                   "h = %g: %d of %d cavity cells kept, %d solid cells missing", h, kept_cav,
                   in_cavity, missing);
        /* the kept volume overshoots by about half a layer of cells on each of 3 surfaces */
        ENSURE_MSG(rel > 0 && rel < 0.5, "h = %g: volume %g against %g", h, n * h * h * h, exact);
    }
    cs_mesh_free(&m);
}

/*
 * Through the world API: the review's hollow cube (cavity.obj: a 1 m cube with an inward
 * 0.5 m cube at its centre) at h = 0.05 holds 8000 - 1000 cells, and its mass is the hollow
 * body's, for a rigid body and a corotational FEM object; the published surface holds both
 * shells (closed, oriented, volume 1 - 0.125), and it falls freely as a solid does.
 */
TEST(voxelize_cavity_mass_through_the_world)
{
    const double h = 0.05, rho = 1000;
    cs_mesh m = {0};
    add_box(&m, (double[3]){0, 0, 0}, (double[3]){1, 1, 1}, 0);
    add_box(&m, (double[3]){0.25, 0.25, 0.25}, (double[3]){0.5, 0.5, 0.5}, 1);
    char err[256];
    for (int model = 0; model < 2; model++) {
        cs_world_def wd = cs_world_def_default();
        wd.gravity[0] = wd.gravity[1] = 0;
        wd.gravity[2] = -9.81;
        wd.threads = 1;
        cs_world_t *w = NULL;
        ENSURE(cs_world_create(&wd, &w, err, sizeof err) == CS_OK);
        cs_object_def od = cs_object_def_default();
        od.name = "hollow";
        od.model = model ? CS_MODEL_COROTATIONAL : CS_MODEL_RIGID;
        od.material.density = rho;
        od.cube_size = h;
        od.geometry = CS_GEOMETRY_MESH;
        od.mesh_vertices = m.v;
        od.n_mesh_vertices = m.nv;
        od.mesh_triangles = m.t;
        od.n_mesh_triangles = m.nt;
        cs_object_id id;
        int rc = cs_world_add_object(w, &od, &id, err, sizeof err);
        if (rc != CS_OK) {
            cs_world_destroy(w);
            cs_mesh_free(&m);
            ENSURE_MSG(0, "%s", err);
        }
        cs_object_info info;
        cs_object_get_info(w, id, &info);
        const double *v;
        const int32_t *t;
        int nv, nt;
        cs_object_surface(w, id, &v, &nv, &t, &nt);
        cs_watertight_report rep;
        int closed = cs_watertight_check(v, nv, t, nt, &rep, err, sizeof err);
        /* it steps: 10 steps of free fall move every node by g dt^2 n(n+1)/2 */
        double fall = 0;
        int bad_steps = 0;
        for (int s = 0; s < 10; s++)
            bad_steps += cs_world_step(w) != CS_OK;
        const double *rest, *pos;
        int nn;
        cs_object_nodes(w, id, &rest, &pos, NULL, &nn);
        for (int i = 0; i < nn; i++)
            fall = fmax(fall, fabs(rest[3 * i + 2] - pos[3 * i + 2] - 9.81 * wd.dt * wd.dt * 55));
        cs_world_destroy(w);
        if (info.n_cells != 7000 || !closed)
            cs_mesh_free(&m);
        ENSURE_MSG(info.n_cells == 7000, "model %d: %d cells", model, info.n_cells);
        ENSURE_NEAR(info.volume, 0.875, 1e-12);
        ENSURE_NEAR(info.mass, rho * 0.875, 1e-9 * rho);
        ENSURE_MSG(closed, "%s", err);
        ENSURE_NEAR(rep.volume, 0.875, 1e-12);
        /* the FEM object's steps are solved to the CG tolerance (1e-4 relative) */
        const double want = 9.81 * wd.dt * wd.dt * 55;
        ENSURE_MSG(bad_steps == 0 && fall < (model ? 1e-4 * want : 1e-12),
                   "model %d: %d failed steps, fall off by %g of %g", model, bad_steps, fall,
                   want);
    }
    cs_mesh_free(&m);
}

/* A mesh fills at most 2^22 cubes (as a scene's boxes and cell sets: about 7 GB in the
 * daemon); a 1 m cube at h = 1/170 (4 913 000 cubes) was voxelized whole before, and the
 * world built from it would have taken 8 GB. */
TEST(voxelize_refuses_more_cubes_than_the_daemon_holds)
{
    cs_mesh m;
    box_mesh(&m, (double[3]){0, 0, 0}, (double[3]){1, 1, 1});
    int32_t *ijk = NULL;
    int n = 0;
    double origin[3];
    char err[256] = "";
    ENSURE(cs_voxelize(m.v, m.nv, m.t, m.nt, 1.0 / 170, origin, &ijk, &n, err, sizeof err) != 0);
    ENSURE_MSG(strstr(err, "4913000 cubes") && strstr(err, "4194304"), "%s", err);
    ENSURE(!ijk);
    ENSURE(cs_voxelize(m.v, m.nv, m.t, m.nt, 1.0 / 160, origin, &ijk, &n, err, sizeof err) == 0);
    ENSURE_MSG(n == 160 * 160 * 160, "%d cubes", n);
    free(ijk);
    cs_mesh_free(&m);
}
