/*
 * test_closing.c — seed 000 §3.2 closing surfaces (server/engine/closing.c): the ear cutter,
 * and the closing of one exposed face checked the way fracture uses it: split a closed surface
 * along a plane the §3.1 way, add the closing triangles (and their reverse for the other
 * side) and ask common/watertight.h whether each half is closed and consistently oriented.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "closing.h"
#include "cubemesh.h"
#include "surface.h"
#include "watertight.h"

/* ---------------------------------------------------------------- meshes made here */

typedef struct {
    double *v;
    int nv, cap_v;
    int32_t *t;
    int nt, cap_t;
} tmesh;

static void tm_free(tmesh *m)
{
    free(m->v);
    free(m->t);
    memset(m, 0, sizeof *m);
}

static int tm_vert(tmesh *m, double x, double y, double z)
{
    if (m->nv == m->cap_v) {
        m->cap_v = m->cap_v ? 2 * m->cap_v : 64;
        m->v = realloc(m->v, 3 * (size_t)m->cap_v * sizeof *m->v);
    }
    m->v[3 * m->nv] = x;
    m->v[3 * m->nv + 1] = y;
    m->v[3 * m->nv + 2] = z;
    return m->nv++;
}

static void tm_tri(tmesh *m, int a, int b, int c)
{
    if (m->nt == m->cap_t) {
        m->cap_t = m->cap_t ? 2 * m->cap_t : 64;
        m->t = realloc(m->t, 3 * (size_t)m->cap_t * sizeof *m->t);
    }
    m->t[3 * m->nt] = a;
    m->t[3 * m->nt + 1] = b;
    m->t[3 * m->nt + 2] = c;
    m->nt++;
}

/* Midpoint of edge (a,b) pushed to the unit sphere, made once per edge. */
static int ico_mid(tmesh *m, int32_t *keys, int *vals, int *nk, int a, int b)
{
    int lo = a < b ? a : b, hi = a < b ? b : a;
    for (int i = 0; i < *nk; i++)
        if (keys[2 * i] == lo && keys[2 * i + 1] == hi)
            return vals[i];
    double p[3];
    for (int k = 0; k < 3; k++)
        p[k] = 0.5 * (m->v[3 * a + k] + m->v[3 * b + k]);
    double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    /* keep points of the equator exactly on it */
    int v = tm_vert(m, p[0] / r, p[1] / r, p[2] == 0 ? 0 : p[2] / r);
    keys[2 * *nk] = lo;
    keys[2 * *nk + 1] = hi;
    vals[(*nk)++] = v;
    return v;
}

/* A unit icosphere with `levels` subdivisions, scaled by r and moved to c. Four icosahedron
 * vertices lie exactly on z = 0 (and so do the equator points made from them). */
static void icosphere(tmesh *m, int levels, double r, const double c[3])
{
    memset(m, 0, sizeof *m);
    const double g = (1.0 + sqrt(5.0)) / 2.0;
    const double base[12][3] = {{-1, g, 0}, {1, g, 0},   {-1, -g, 0}, {1, -g, 0},
                                {0, -1, g}, {0, 1, g},   {0, -1, -g}, {0, 1, -g},
                                {g, 0, -1}, {g, 0, 1},   {-g, 0, -1}, {-g, 0, 1}};
    static const int faces[20][3] = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                     {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                     {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                     {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
    for (int i = 0; i < 12; i++) {
        double n = sqrt(base[i][0] * base[i][0] + base[i][1] * base[i][1] + base[i][2] * base[i][2]);
        tm_vert(m, base[i][0] / n, base[i][1] / n, base[i][2] / n);
    }
    for (int i = 0; i < 20; i++)
        tm_tri(m, faces[i][0], faces[i][1], faces[i][2]);
    for (int l = 0; l < levels; l++) {
        int nt = m->nt;
        int32_t *old = malloc(3 * (size_t)nt * sizeof *old);
        memcpy(old, m->t, 3 * (size_t)nt * sizeof *old);
        int32_t *keys = malloc(6 * (size_t)nt * sizeof *keys);
        int *vals = malloc(3 * (size_t)nt * sizeof *vals), nk = 0;
        m->nt = 0;
        for (int i = 0; i < nt; i++) {
            int a = old[3 * i], b = old[3 * i + 1], cc = old[3 * i + 2];
            int ab = ico_mid(m, keys, vals, &nk, a, b), bc = ico_mid(m, keys, vals, &nk, b, cc),
                ca = ico_mid(m, keys, vals, &nk, cc, a);
            tm_tri(m, a, ab, ca);
            tm_tri(m, b, bc, ab);
            tm_tri(m, cc, ca, bc);
            tm_tri(m, ab, bc, ca);
        }
        free(old);
        free(keys);
        free(vals);
    }
    for (int i = 0; i < m->nv; i++)
        for (int k = 0; k < 3; k++)
            m->v[3 * i + k] = c[k] + r * m->v[3 * i + k];
}

/* A torus around the z axis (radii R, r), nu × nv quads; points with z = ±0 snapped to 0. */
static void torus(tmesh *m, double R, double r, int nu, int nv)
{
    memset(m, 0, sizeof *m);
    for (int i = 0; i < nu; i++)
        for (int j = 0; j < nv; j++) {
            double a = 2 * M_PI * i / nu, b = 2 * M_PI * j / nv;
            double z = r * sin(b);
            if (fabs(z) < 1e-12)
                z = 0;
            tm_vert(m, (R + r * cos(b)) * cos(a), (R + r * cos(b)) * sin(a), z);
        }
    for (int i = 0; i < nu; i++)
        for (int j = 0; j < nv; j++) {
            int a = i * nv + j, b = ((i + 1) % nu) * nv + j, c = ((i + 1) % nu) * nv + (j + 1) % nv,
                d = i * nv + (j + 1) % nv;
            tm_tri(m, a, b, c);
            tm_tri(m, a, c, d);
        }
}

/* ---------------------------------------------------------------- the fracture check */

typedef struct {
    int axis, c1_below;
    double plane, lo[3], hi[3];
} face_spec;

/* 1 if the triangle's centroid is on c1's side (strictly; on the plane counts as c2's). */
static uint8_t centroid_side(const tmesh *m, int t, const face_spec *fs)
{
    double c = 0;
    for (int k = 0; k < 3; k++)
        c += m->v[3 * m->t[3 * t + k] + fs->axis] / 3.0;
    double d = (c - fs->plane) * (fs->c1_below ? 1 : -1);
    return d < 0;
}

/*
 * Split m along the plane (triangles by centroid), close with the given closing triangles
 * (ids into m's vertices, plus corner vertices appended by the caller) and check both halves.
 * Returns 1 if both are closed, else 0 with the reason in msg.
 */
static int halves_closed(const tmesh *m, const uint8_t *side, const int32_t *cl, int ncl,
                         char *msg, size_t msglen)
{
    int nv = m->nv;
    uint8_t *use = calloc((size_t)nv, 1);
    int32_t *dup = malloc((size_t)nv * sizeof *dup);
    double *v2 = malloc(3 * (size_t)nv * 2 * sizeof *v2);
    int32_t *h1 = malloc(3 * (size_t)(m->nt + ncl) * sizeof *h1);
    int32_t *h2 = malloc(3 * (size_t)(m->nt + ncl) * sizeof *h2);
    memcpy(v2, m->v, 3 * (size_t)nv * sizeof *v2);
    for (int t = 0; t < m->nt; t++)
        for (int k = 0; k < 3; k++)
            use[m->t[3 * t + k]] |= side[t] ? 1 : 2;
    int nv2 = nv;
    for (int i = 0; i < nv; i++) {
        dup[i] = i;
        if (use[i] == 3) {
            memcpy(v2 + 3 * nv2, m->v + 3 * i, 3 * sizeof *v2);
            dup[i] = nv2++;
        }
    }
    int n1 = 0, n2 = 0;
    for (int t = 0; t < m->nt; t++) {
        if (side[t]) {
            memcpy(h1 + 3 * n1++, m->t + 3 * t, 3 * sizeof *h1);
        } else {
            for (int k = 0; k < 3; k++)
                h2[3 * n2 + k] = dup[m->t[3 * t + k]];
            n2++;
        }
    }
    for (int t = 0; t < ncl; t++) {
        memcpy(h1 + 3 * n1++, cl + 3 * t, 3 * sizeof *h1);
        for (int k = 0; k < 3; k++)
            h2[3 * n2 + k] = dup[cl[3 * t + 2 - k]];
        n2++;
    }
    char e1[200] = "", e2[200] = "";
    cs_watertight_report r1, r2;
    int ok1 = cs_watertight_check(v2, nv2, h1, n1, &r1, e1, sizeof e1);
    int ok2 = cs_watertight_check(v2, nv2, h2, n2, &r2, e2, sizeof e2);
    if (!ok1 || !ok2)
        snprintf(msg, msglen, "c1 half: %s (%d open, %d misoriented, %d non-manifold); "
                 "c2 half: %s (%d open, %d misoriented)", ok1 ? "closed" : e1,
                 r1.boundary_edges, r1.misoriented_edges, r1.nonmanifold_edges,
                 ok2 ? "closed" : e2, r2.boundary_edges, r2.misoriented_edges);
    free(use);
    free(dup);
    free(v2);
    free(h1);
    free(h2);
    return ok1 && ok2;
}

/* The face of fs with four corner vertices appended to m (at the corner positions). */
static cs_close_face make_face(tmesh *m, const face_spec *fs, int inside)
{
    cs_close_face f;
    memset(&f, 0, sizeof f);
    f.axis = fs->axis;
    f.c1_below = fs->c1_below;
    f.plane = fs->plane;
    memcpy(f.lo, fs->lo, sizeof f.lo);
    memcpy(f.hi, fs->hi, sizeof f.hi);
    int u = (fs->axis + 1) % 3, w = (fs->axis + 2) % 3;
    /* positive sense about n_f from the smallest corner: (u,w) order if n_f = +e_axis */
    int su[4] = {0, 1, 1, 0}, sw[4] = {0, 0, 1, 1};
    for (int k = 0; k < 4; k++) {
        int a = fs->c1_below ? su[k] : sw[k], b = fs->c1_below ? sw[k] : su[k];
        double p[3];
        p[fs->axis] = fs->plane;
        p[u] = a ? fs->hi[u] : fs->lo[u];
        p[w] = b ? fs->hi[w] : fs->lo[w];
        f.corner_vertex[k] = tm_vert(m, p[0], p[1], p[2]);
        f.corner_inside[k] = inside;
    }
    return f;
}

/* Area-weighted normal of the output, and whether its boundary edges form closed loops
 * (every vertex as often the start as the end of a boundary edge). */
static int output_shape(const tmesh *m, const int32_t *cl, int n, double nrm[3])
{
    nrm[0] = nrm[1] = nrm[2] = 0;
    for (int t = 0; t < n; t++) {
        const double *a = m->v + 3 * cl[3 * t], *b = m->v + 3 * cl[3 * t + 1],
                     *c = m->v + 3 * cl[3 * t + 2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        nrm[0] += 0.5 * (u[1] * w[2] - u[2] * w[1]);
        nrm[1] += 0.5 * (u[2] * w[0] - u[0] * w[2]);
        nrm[2] += 0.5 * (u[0] * w[1] - u[1] * w[0]);
    }
    int *bal = calloc((size_t)m->nv, sizeof *bal);
    for (int t = 0; t < n; t++)
        for (int k = 0; k < 3; k++) {
            int a = cl[3 * t + k], b = cl[3 * t + (k + 1) % 3], rev = 0, same = 0;
            for (int s = 0; s < n; s++)
                for (int j = 0; j < 3; j++) {
                    int c = cl[3 * s + j], d = cl[3 * s + (j + 1) % 3];
                    rev += c == b && d == a;
                    same += c == a && d == b;
                }
            if (rev == 0 && same == 1) {
                bal[a]++;
                bal[b]--;
            }
        }
    int ok = 1;
    for (int i = 0; i < m->nv; i++)
        ok &= bal[i] == 0;
    free(bal);
    return ok;
}

/* Close face fs of mesh m (all triangles as candidates, sides by centroid). Returns the
 * triangle count or -1; the closing goes to *cl (malloc'd). Corner vertices appended to m. */
static int close_mesh_face(tmesh *m, const face_spec *fs, int inside, int32_t **cl, char *err,
                           size_t errlen)
{
    int nt = m->nt;
    cs_close_face f = make_face(m, fs, inside);
    int32_t *cand = malloc((size_t)nt * sizeof *cand);
    uint8_t *side = malloc((size_t)nt);
    for (int t = 0; t < nt; t++) {
        cand[t] = t;
        side[t] = centroid_side(m, t, fs);
    }
    int cap = 4 * nt + 16;
    *cl = malloc(3 * (size_t)cap * sizeof **cl);
    int n = cs_close_face_triangles(&f, m->v, m->t, cand, nt, side, *cl, cap, err, errlen);
    free(cand);
    free(side);
    return n;
}

/* Close, then check the normal, the boundary loop and both halves. */
static int close_and_check(tmesh *m, const face_spec *fs, char *msg, size_t msglen)
{
    int nt = m->nt;
    int32_t *cl;
    char err[256] = "";
    int n = close_mesh_face(m, fs, 1, &cl, err, sizeof err);
    if (n <= 0) {
        snprintf(msg, msglen, "closing returned %d: %s", n, err);
        free(cl);
        return 0;
    }
    double nrm[3];
    int loop = output_shape(m, cl, n, nrm);
    double nf = fs->c1_below ? 1 : -1, len = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    int ok = 1;
    if (!loop) {
        snprintf(msg, msglen, "the boundary of the %d closing triangles is not closed", n);
        ok = 0;
    } else if (!(nrm[fs->axis] * nf > 0.99 * len)) {
        snprintf(msg, msglen, "area normal (%g %g %g) not along n_f", nrm[0], nrm[1], nrm[2]);
        ok = 0;
    } else {
        uint8_t *side = malloc((size_t)nt);
        int save = m->nt;
        m->nt = nt;
        for (int t = 0; t < nt; t++)
            side[t] = centroid_side(m, t, fs);
        ok = halves_closed(m, side, cl, n, msg, msglen);
        m->nt = save;
        free(side);
    }
    free(cl);
    return ok;
}

/* ---------------------------------------------------------------- ear cutting */

static double poly_area(const double *xy, int n)
{
    double a = 0;
    for (int i = 0; i < n; i++)
        a += xy[2 * i] * xy[2 * ((i + 1) % n) + 1] - xy[2 * i + 1] * xy[2 * ((i + 1) % n)];
    return 0.5 * a;
}

/* n-2 triangles, every index used, all counter-clockwise, areas summing to the polygon's;
 * *n_flat receives the number of zero-area triangles. */
static int earcut_ok(const double *xy, int n, int *n_flat, char *msg, size_t msglen)
{
    int32_t *t = malloc(3 * (size_t)n * sizeof *t);
    int nt = cs_earcut(xy, n, t);
    int ok = 1;
    double sum = 0;
    *n_flat = 0;
    if (nt != n - 2) {
        snprintf(msg, msglen, "%d triangles for %d points", nt, n);
        ok = 0;
    }
    for (int i = 0; ok && i < nt; i++) {
        for (int k = 0; k < 3; k++)
            if (t[3 * i + k] < 0 || t[3 * i + k] >= n) {
                snprintf(msg, msglen, "index %d out of range", t[3 * i + k]);
                ok = 0;
            }
        if (!ok)
            break;
        const double *a = xy + 2 * t[3 * i], *b = xy + 2 * t[3 * i + 1], *c = xy + 2 * t[3 * i + 2];
        double ar = 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
        if (ar < 0) {
            snprintf(msg, msglen, "triangle %d is clockwise (area %g)", i, ar);
            ok = 0;
        }
        *n_flat += ar == 0;
        sum += ar;
    }
    double pa = poly_area(xy, n);
    if (ok && fabs(sum - pa) > 1e-9 * fabs(pa)) {
        snprintf(msg, msglen, "triangle areas sum to %.12g, polygon %.12g", sum, pa);
        ok = 0;
    }
    free(t);
    return ok;
}

TEST(closing_earcut_convex_concave_collinear)
{
    char msg[200];
    int flat;
    /* convex: a regular 12-gon */
    double c12[24];
    for (int i = 0; i < 12; i++) {
        c12[2 * i] = cos(2 * M_PI * i / 12);
        c12[2 * i + 1] = sin(2 * M_PI * i / 12);
    }
    ENSURE_MSG(earcut_ok(c12, 12, &flat, msg, sizeof msg), "12-gon: %s", msg);
    ENSURE(flat == 0);
    /* concave: a star of 9 spikes, a comb, an L */
    double star[36];
    for (int i = 0; i < 18; i++) {
        double r = i % 2 ? 0.3 : 1.0;
        star[2 * i] = r * cos(2 * M_PI * i / 18);
        star[2 * i + 1] = r * sin(2 * M_PI * i / 18);
    }
    ENSURE_MSG(earcut_ok(star, 18, &flat, msg, sizeof msg), "star: %s", msg);
    ENSURE(flat == 0);
    double comb[] = {0, 0, 5, 0, 5, 3, 4, 3, 4, 1, 3, 1, 3, 3, 2, 3, 2, 1, 1, 1, 1, 3, 0, 3};
    ENSURE_MSG(earcut_ok(comb, 12, &flat, msg, sizeof msg), "comb: %s", msg);
    ENSURE(flat == 0);
    double ell[] = {0, 0, 2, 0, 2, 1, 1, 1, 1, 2, 0, 2};
    ENSURE_MSG(earcut_ok(ell, 6, &flat, msg, sizeof msg), "L: %s", msg);
    ENSURE(flat == 0);
    /* collinear points: a greedy cut can leave A,B,C,D flat here */
    double flatrun[] = {0, 0, 1, 0, 2, 0, 3, 0, 3, 1, 0, 1};
    ENSURE_MSG(earcut_ok(flatrun, 6, &flat, msg, sizeof msg), "run: %s", msg);
    ENSURE_MSG(flat == 0, "%d zero-area triangles", flat);
    /* a square with 5 points on every side, started mid-side */
    double sq[40];
    int n = 0;
    for (int s = 0; s < 4; s++)
        for (int i = 0; i < 5; i++) {
            double t = i / 5.0, x, y;
            switch (s) {
            case 0: x = t; y = 0; break;
            case 1: x = 1; y = t; break;
            case 2: x = 1 - t; y = 1; break;
            default: x = 0; y = 1 - t; break;
            }
            sq[2 * n] = x;
            sq[2 * n + 1] = y;
            n++;
        }
    double rot[40];
    for (int i = 0; i < 20; i++) {
        rot[2 * i] = sq[2 * ((i + 2) % 20)];
        rot[2 * i + 1] = sq[2 * ((i + 2) % 20) + 1];
    }
    ENSURE_MSG(earcut_ok(rot, 20, &flat, msg, sizeof msg), "square: %s", msg);
    ENSURE_MSG(flat == 0, "%d zero-area triangles", flat);
    /* collinear runs on a concave outline (a U with flat floors) */
    double u[] = {0, 0, 1, 0, 2, 0, 3, 0, 3, 3, 2, 3, 2, 2, 2, 1, 1, 1, 1, 2, 1, 3, 0, 3, 0, 2, 0, 1};
    ENSURE_MSG(earcut_ok(u, 14, &flat, msg, sizeof msg), "U: %s", msg);
    ENSURE_MSG(flat == 0, "%d zero-area triangles", flat);
    /* a triangle with points on all three sides (the reduced ring is one triangle) */
    double tr[] = {0, 0, 1, 0, 2, 0, 1.5, 1, 1, 2, 0.5, 1};
    ENSURE_MSG(earcut_ok(tr, 6, &flat, msg, sizeof msg), "triangle: %s", msg);
    ENSURE_MSG(flat == 0, "%d zero-area triangles", flat);
    /* unavoidable: repeated points still give n-2 triangles */
    double rep[] = {0, 0, 1, 0, 1, 0, 1, 1, 0, 1};
    ENSURE_MSG(earcut_ok(rep, 5, &flat, msg, sizeof msg), "repeated: %s", msg);
    int32_t t3[3];
    ENSURE(cs_earcut(c12, 2, t3) == -1);
    ENSURE(cs_earcut(NULL, 5, t3) == -1);
    ENSURE(cs_earcut(c12, 3, t3) == 1);
}

TEST(closing_earcut_random_star_polygons)
{
    uint64_t s = 12345;
    char msg[200];
    for (int it = 0; it < 300; it++) {
        int n = 3 + it % 40;
        double *xy = malloc(2 * (size_t)n * sizeof *xy);
        for (int i = 0; i < n; i++) {
            s = s * 6364136223846793005ULL + 1442695040888963407ULL;
            double r = 0.2 + (double)(s >> 11) / 9007199254740992.0;
            /* snap radii to a few values so that some points line up */
            if (it % 3 == 0)
                r = 0.5 + 0.25 * (double)((s >> 20) % 3);
            xy[2 * i] = r * cos(2 * M_PI * i / n);
            xy[2 * i + 1] = r * sin(2 * M_PI * i / n);
        }
        int flat;
        int ok = earcut_ok(xy, n, &flat, msg, sizeof msg);
        free(xy);
        ENSURE_MSG(ok, "polygon %d (%d points): %s", it, n, msg);
    }
}

/* ---------------------------------------------------------------- closing one face */

static void box12(tmesh *m, const double lo[3], const double hi[3])
{
    static const int bt[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6},
                                  {0, 1, 5}, {0, 5, 4}, {2, 6, 7}, {2, 7, 3},
                                  {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
    memset(m, 0, sizeof *m);
    for (int i = 0; i < 8; i++)
        tm_vert(m, (i & 1) ? hi[0] : lo[0], (i & 2) ? hi[1] : lo[1], (i & 4) ? hi[2] : lo[2]);
    for (int i = 0; i < 12; i++)
        tm_tri(m, bt[i][0], bt[i][1], bt[i][2]);
}

TEST(closing_face_inside_and_outside_a_box)
{
    char err[256];
    for (int axis = 0; axis < 3; axis++)
        for (int below = 0; below < 2; below++) {
            tmesh m;
            box12(&m, (double[3]){-1, -1, -1}, (double[3]){2, 2, 2});
            face_spec fs = {axis, below, 0.5, {0, 0, 0}, {1, 1, 1}};
            int32_t *cl;
            int n = close_mesh_face(&m, &fs, 1, &cl, err, sizeof err);
            int c0 = m.nv - 4;
            double nrm[3];
            int loop = n == 2 ? output_shape(&m, cl, n, nrm) : 0;
            int corners_only = 1;
            for (int i = 0; i < 3 * (n > 0 ? n : 0); i++)
                corners_only &= cl[i] >= c0;
            free(cl);
            /* outside: a box elsewhere, corners outside */
            tmesh o;
            box12(&o, (double[3]){5, 5, 5}, (double[3]){6, 6, 6});
            int n_out = close_mesh_face(&o, &fs, 0, &cl, err, sizeof err);
            free(cl);
            tm_free(&m);
            tm_free(&o);
            ENSURE_MSG(n == 2, "axis %d below %d: %d triangles (%s)", axis, below, n, err);
            ENSURE(corners_only && loop);
            /* unit square, normal along n_f */
            ENSURE_NEAR(nrm[axis], below ? 1.0 : -1.0, 1e-12);
            ENSURE(n_out == 0);
        }
}

TEST(closing_sphere_inside_one_face_closes_both_halves)
{
    char msg[400];
    /* generic planes, and z = 0 through four icosahedron vertices and the equator points */
    const double planes[] = {0.137, -0.41, 0.0, 0.52};
    for (int lev = 1; lev <= 3; lev++)
        for (int pi = 0; pi < 4; pi++)
            for (int axis = 0; axis < 3; axis++)
                for (int below = 0; below < 2; below++) {
                    tmesh m;
                    icosphere(&m, lev, 1.0, (double[3]){0, 0, 0});
                    if (axis != 2) /* move the special plane z = 0 onto this axis */
                        for (int i = 0; i < m.nv; i++) {
                            double t = m.v[3 * i + 2];
                            m.v[3 * i + 2] = m.v[3 * i + axis];
                            m.v[3 * i + axis] = t;
                        }
                    if (axis != 2) /* the swap mirrored the mesh: flip the triangles */
                        for (int t = 0; t < m.nt; t++) {
                            int32_t x = m.t[3 * t + 1];
                            m.t[3 * t + 1] = m.t[3 * t + 2];
                            m.t[3 * t + 2] = x;
                        }
                    face_spec fs = {axis, below, planes[pi], {-1.3, -1.2, -1.25},
                                    {1.4, 1.1, 1.3}};
                    int ok = close_and_check(&m, &fs, msg, sizeof msg);
                    tm_free(&m);
                    ENSURE_MSG(ok, "level %d plane %g axis %d below %d: %s", lev, planes[pi],
                               axis, below, msg);
                }
}

TEST(closing_torus_gives_holes_and_several_polygons)
{
    char msg[400];
    /* z-planes cut an annulus (outer polygon with a hole); x-planes two discs or one
     * figure with ... (|x| < R - r: two discs, else one) */
    const face_spec specs[] = {
        {2, 1, 0.0, {-2, -2, 0}, {2, 2, 0}},    {2, 0, 0.0, {-2, -2, 0}, {2, 2, 0}},
        {2, 1, 0.17, {-2, -2, 0}, {2, 2, 0}},   {2, 0, -0.23, {-2, -2, 0}, {2, 2, 0}},
        {0, 1, 0.0, {0, -2, -2}, {0, 2, 2}},    {0, 0, 0.3, {0, -2, -2}, {0, 2, 2}},
        {1, 1, 0.9, {-2, 0, -2}, {2, 0, 2}},    {1, 0, -1.05, {-2, 0, -2}, {2, 0, 2}},
    };
    for (int s = 0; s < (int)(sizeof specs / sizeof specs[0]); s++)
        for (int res = 0; res < 2; res++) {
            tmesh m;
            torus(&m, 1.0, 0.4, res ? 48 : 24, res ? 24 : 12);
            int ok = close_and_check(&m, &specs[s], msg, sizeof msg);
            tm_free(&m);
            ENSURE_MSG(ok, "spec %d res %d: %s", s, res, msg);
        }
}

/* The boundary surface of an nx×ny×nz block of unit cells, `sub` quads per cell face. */
static int block_surface(tmesh *m, int nx, int ny, int nz, int sub, char *err, size_t errlen)
{
    cs_cubemesh cm;
    int n = nx * ny * nz;
    int32_t *ijk = malloc(3 * (size_t)n * sizeof *ijk);
    for (int i = 0, c = 0; i < nx; i++)
        for (int j = 0; j < ny; j++)
            for (int k = 0; k < nz; k++, c++) {
                ijk[3 * c] = i;
                ijk[3 * c + 1] = j;
                ijk[3 * c + 2] = k;
            }
    int rc = cs_cubemesh_build(&cm, 1.0, (double[3]){0, 0, 0}, ijk, n, err, errlen);
    free(ijk);
    if (rc != 0)
        return -1;
    memset(m, 0, sizeof *m);
    rc = cs_surface_of_cells(&cm, sub, &m->v, &m->nv, &m->t, &m->nt, err, errlen);
    m->cap_v = m->nv;
    m->cap_t = m->nt;
    cs_cubemesh_free(&cm);
    return rc;
}

TEST(closing_box_with_vertices_on_the_plane)
{
    char err[256], msg[400];
    /* one big face around the whole cross-section: planes through vertex rows (z = 1, and
     * z = 1.5 when sub = 2) and between them */
    const double planes[] = {1.0, 1.5, 1.25, 2.0};
    for (int sub = 1; sub <= 3; sub++)
        for (int pi = 0; pi < 4; pi++)
            for (int axis = 0; axis < 3; axis++)
                for (int below = 0; below < 2; below++) {
                    tmesh m;
                    ENSURE_MSG(block_surface(&m, 3, 3, 3, sub, err, sizeof err) == 0, "%s", err);
                    face_spec fs = {axis, below, planes[pi], {-0.5, -0.5, -0.5},
                                    {3.5, 3.5, 3.5}};
                    int ok = close_and_check(&m, &fs, msg, sizeof msg);
                    tm_free(&m);
                    ENSURE_MSG(ok, "sub %d plane %g axis %d below %d: %s", sub, planes[pi],
                               axis, below, msg);
                }
}

/*
 * A flat crack across a box: a 3×3×3 block (sub = 1) split between layers z < 1 and z > 1,
 * all nine faces closed separately. Corner nodes on the box surface use the surface vertex
 * there (the box's own corner), the others one new vertex per lattice node. (With sub >= 2
 * the rim vertices between lattice points on the box's upper x and y sides stay open: those
 * sides lie on upper edge lines of faces, which count as outside, and the faces' corners
 * stand in for them.)
 */
TEST(closing_flat_crack_across_a_box)
{
    char err[256], msg[400];
    for (int below = 0; below < 2; below++) {
        tmesh m;
        ENSURE_MSG(block_surface(&m, 3, 3, 3, 1, err, sizeof err) == 0, "%s", err);
        int nt = m.nt;
        int32_t node_vert[4][4];
        for (int i = 0; i <= 3; i++)
            for (int j = 0; j <= 3; j++) {
                node_vert[i][j] = -1;
                for (int v = 0; v < m.nv; v++)
                    if (m.v[3 * v] == i && m.v[3 * v + 1] == j && m.v[3 * v + 2] == 1.0)
                        node_vert[i][j] = v;
                if (node_vert[i][j] < 0)
                    node_vert[i][j] = tm_vert(&m, i, j, 1.0);
            }
        int32_t *cand = malloc((size_t)nt * sizeof *cand);
        uint8_t *side = malloc((size_t)nt);
        face_spec fs0 = {2, below, 1.0, {0, 0, 0}, {0, 0, 0}};
        for (int t = 0; t < nt; t++) {
            cand[t] = t;
            side[t] = centroid_side(&m, t, &fs0);
        }
        int32_t *cl = malloc(3 * 64 * 9 * sizeof *cl);
        int ncl = 0, bad = 0;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                cs_close_face f;
                memset(&f, 0, sizeof f);
                f.axis = 2;
                f.c1_below = below;
                f.plane = 1.0;
                f.lo[0] = i;
                f.lo[1] = j;
                f.hi[0] = i + 1;
                f.hi[1] = j + 1;
                /* corners counter-clockwise about n_f from (lo, lo) */
                int ci[4] = {0, 1, 1, 0}, cj[4] = {0, 0, 1, 1};
                for (int k = 0; k < 4; k++) {
                    int a = below ? ci[k] : cj[k], b = below ? cj[k] : ci[k];
                    f.corner_vertex[k] = node_vert[i + a][j + b];
                    f.corner_inside[k] = 1;
                }
                f.boundary_rule = CS_CLOSE_BOUNDARY_SHARED;
                int n = cs_close_face_triangles(&f, m.v, m.t, cand, nt, side, cl + 3 * ncl, 64,
                                                err, sizeof err);
                if (n < 2 && !bad) {
                    bad = 1;
                    snprintf(msg, sizeof msg, "face (%d,%d) gave %d: %s", i, j, n, err);
                } else if (n > 0) {
                    ncl += n;
                }
            }
        int save = m.nt;
        m.nt = nt;
        int ok = bad || halves_closed(&m, side, cl, ncl, msg, sizeof msg);
        m.nt = save;
        free(cand);
        free(side);
        free(cl);
        tm_free(&m);
        ENSURE_MSG(!bad, "below %d: %s", below, msg);
        ENSURE_MSG(ok, "below %d: %s", below, msg);
    }
}

TEST(closing_rejects_garbage_cleanly)
{
    char err[256];
    tmesh m;
    icosphere(&m, 2, 1.0, (double[3]){0, 0, 0});
    face_spec fs = {2, 1, 0.1, {-2, -2, 0}, {2, 2, 0}};
    cs_close_face f = make_face(&m, &fs, 1);
    int nt = m.nt;
    int32_t *cand = malloc((size_t)nt * sizeof *cand);
    uint8_t *side = malloc((size_t)nt);
    int32_t out[3 * 400];
    for (int t = 0; t < nt; t++) {
        cand[t] = t;
        side[t] = centroid_side(&m, t, &fs);
    }
    int full = cs_close_face_triangles(&f, m.v, m.t, cand, nt, side, out, 400, err, sizeof err);
    err[0] = 0;
    int small = cs_close_face_triangles(&f, m.v, m.t, cand, nt, side, out, 3, err, sizeof err);
    int small_msg = err[0] != 0;
    /* no candidates: the whole face if its corners are inside, else nothing */
    int none_in = cs_close_face_triangles(&f, m.v, m.t, cand, 0, side, out, 400, err, sizeof err);
    int none_cap = cs_close_face_triangles(&f, m.v, m.t, cand, 0, side, out, 1, err, sizeof err);
    cs_close_face g = f;
    for (int k = 0; k < 4; k++)
        g.corner_inside[k] = k != 2;
    int none_out = cs_close_face_triangles(&g, m.v, m.t, cand, 0, side, out, 400, err, sizeof err);
    g = f;
    g.axis = 3;
    int bad_axis = cs_close_face_triangles(&g, m.v, m.t, cand, nt, side, out, 400, err, sizeof err);
    g = f;
    g.hi[0] = g.lo[0];
    int empty_sq = cs_close_face_triangles(&g, m.v, m.t, cand, nt, side, out, 400, err, sizeof err);
    int null_f = cs_close_face_triangles(NULL, m.v, m.t, cand, nt, side, out, 400, err, sizeof err);
    /* an open surface: drop one crossing triangle */
    int drop = -1;
    for (int t = 0; t < nt && drop < 0; t++) {
        int below = 0;
        for (int k = 0; k < 3; k++)
            below += m.v[3 * m.t[3 * t + k] + 2] < 0.1;
        if (below == 1 || below == 2)
            drop = t;
    }
    int32_t keep = cand[drop];
    cand[drop] = cand[nt - 1];
    int open = cs_close_face_triangles(&f, m.v, m.t, cand, nt - 1, side, out, 400, err, sizeof err);
    cand[drop] = keep;
    /* one crossing triangle turned over */
    int32_t sw = m.t[3 * drop + 1];
    m.t[3 * drop + 1] = m.t[3 * drop + 2];
    m.t[3 * drop + 2] = sw;
    err[0] = 0;
    int flipped = cs_close_face_triangles(&f, m.v, m.t, cand, nt, side, out, 400, err, sizeof err);
    int flipped_msg = err[0] != 0;
    /* the inside corners have no vertex */
    m.t[3 * drop + 2] = m.t[3 * drop + 1];
    m.t[3 * drop + 1] = sw;
    g = f;
    for (int k = 0; k < 4; k++)
        g.corner_vertex[k] = -1;
    int no_corner = cs_close_face_triangles(&g, m.v, m.t, cand, 0, side, out, 400, err, sizeof err);
    int sphere_no_corner =
        cs_close_face_triangles(&g, m.v, m.t, cand, nt, side, out, 400, err, sizeof err);
    free(cand);
    free(side);
    tm_free(&m);
    ENSURE_MSG(full > 3, "%d", full);
    ENSURE(small == -1 && small_msg);
    ENSURE(none_in == 2 && none_cap == -1 && none_out == 0);
    ENSURE(bad_axis == -1 && empty_sq == -1 && null_f == -1);
    ENSURE_MSG(open == -1, "open surface gave %d", open);
    ENSURE_MSG(flipped == -1 && flipped_msg, "flipped triangle gave %d", flipped);
    ENSURE(no_corner == -1);
    ENSURE(sphere_no_corner == full); /* corners outside the sphere are never used */
}

/* Random triangle soups: any answer, but no crash and nothing out of bounds (sanitizers). */
TEST(closing_survives_random_soup)
{
    uint64_t s = 99;
    char err[256];
    for (int it = 0; it < 400; it++) {
        tmesh m;
        memset(&m, 0, sizeof m);
        int nv = 4 + it % 20, nt = 1 + it % 30;
        for (int i = 0; i < nv; i++) {
            double p[3];
            for (int k = 0; k < 3; k++) {
                s = s * 6364136223846793005ULL + 1442695040888963407ULL;
                p[k] = (double)((s >> 33) % 9) * 0.25 - 1.0; /* many exact ties */
            }
            tm_vert(&m, p[0], p[1], p[2]);
        }
        for (int t = 0; t < nt; t++) {
            int v[3];
            for (int k = 0; k < 3; k++) {
                s = s * 6364136223846793005ULL + 1442695040888963407ULL;
                v[k] = (int)((s >> 33) % (uint64_t)nv);
            }
            tm_tri(&m, v[0], v[1], v[2]);
        }
        face_spec fs = {it % 3, it % 2, 0.0, {-0.5, -0.5, -0.5}, {0.5, 0.5, 0.5}};
        int32_t *cl;
        int n = close_mesh_face(&m, &fs, it % 4 != 0, &cl, err, sizeof err);
        free(cl);
        tm_free(&m);
        ENSURE(n >= -1);
    }
}

/*
 * The strong case: a sphere bigger than a cell, cracked along a lattice plane through all the
 * faces it covers, each face closed on its own. With the shared boundary rule the closings of
 * neighbouring faces meet and both halves are closed — also with vertices on the crack plane
 * (z = 0) and a vertex exactly on a lattice line (r = 2.9 puts one at x = 3). (Without the
 * offsets, r = 2.9 makes one closing triangle flat: two lattice corners and the sphere's top
 * point happen to lie on one line.)
 */
TEST(closing_sphere_across_many_faces_closes)
{
    const double radii[] = {0.7, 1.3, 2.2, 2.9};
    const double heights[] = {0.37, 0.0, -0.5};
    char err[256], msg[400];
    for (int lev = 2; lev <= 3; lev++)
        for (int ri = 0; ri < 4; ri++)
            for (int hi = 0; hi < 3; hi++)
                for (int below = 0; below < 2; below++) {
                    double r = radii[ri], cz = heights[hi];
                    tmesh m;
                    icosphere(&m, lev, r, (double[3]){0.1, 0.2, cz});
                    int nt = m.nt;
                    face_spec fs0 = {2, below, 0.0, {0, 0, 0}, {0, 0, 0}};
                    uint8_t *side = malloc((size_t)nt);
                    int32_t *cand = malloc((size_t)nt * sizeof *cand);
                    for (int t = 0; t < nt; t++) {
                        cand[t] = t;
                        side[t] = centroid_side(&m, t, &fs0);
                    }
                    /* corner vertices at the lattice nodes plus a small offset (§3.2's
                     * random delta vectors) */
                    int32_t nodev[10][10];
                    for (int i = 0; i < 10; i++)
                        for (int j = 0; j < 10; j++)
                            nodev[i][j] = tm_vert(&m, i - 5 + 0.013 * sin(7.0 * i + j),
                                                  j - 5 + 0.011 * cos(3.0 * i - 5.0 * j),
                                                  0.009 * sin(i + 11.0 * j));
                    int cap = 20000, ncl = 0, fail = 0;
                    int32_t *cl = malloc(3 * (size_t)cap * sizeof *cl);
                    for (int i = -5; i < 4 && !fail; i++)
                        for (int j = -5; j < 4 && !fail; j++) {
                            cs_close_face f;
                            memset(&f, 0, sizeof f);
                            f.axis = 2;
                            f.c1_below = below;
                            f.plane = 0;
                            f.lo[0] = i;
                            f.lo[1] = j;
                            f.hi[0] = i + 1;
                            f.hi[1] = j + 1;
                            f.boundary_rule = CS_CLOSE_BOUNDARY_SHARED;
                            int ci[4] = {0, 1, 1, 0}, cj[4] = {0, 0, 1, 1};
                            for (int k = 0; k < 4; k++) {
                                int a = i + (below ? ci[k] : cj[k]), b = j + (below ? cj[k] : ci[k]);
                                f.corner_vertex[k] = nodev[a + 5][b + 5];
                                double x = a - 0.1, y = b - 0.2;
                                f.corner_inside[k] = x * x + y * y + cz * cz < r * r;
                            }
                            int n = cs_close_face_triangles(&f, m.v, m.t, cand, nt, side,
                                                            cl + 3 * ncl, cap - ncl, err,
                                                            sizeof err);
                            if (n < 0) {
                                fail = 1;
                                snprintf(msg, sizeof msg, "face (%d,%d): %s", i, j, err);
                            } else {
                                ncl += n;
                            }
                        }
                    int crosses = 0;
                    for (int t = 0; t < nt; t++)
                        crosses |= side[t] ? 1 : 2;
                    int save = m.nt;
                    m.nt = nt;
                    int ok = fail || crosses != 3 || halves_closed(&m, side, cl, ncl, msg, sizeof msg);
                    m.nt = save;
                    free(side);
                    free(cand);
                    free(cl);
                    tm_free(&m);
                    ENSURE_MSG(!fail && ok, "level %d r %g z %g below %d: %s", lev, r, cz, below,
                               msg);
                }
}
