/*
 * watertight.c — closedness and orientation of a triangle surface (implements watertight.h).
 *
 * Every directed edge (a,b) of every triangle is listed under its undirected key (min,max) and
 * the list is sorted (O(n log n), no hash table to size): a run of one is a boundary edge, a run
 * of three or more a non-manifold edge, a run of two with the same direction a misoriented one.
 * The volume is the divergence-theorem sum of signed tetrahedra (origin, a, b, c). This is the
 * invariant seed 000 §2.3/§3.1 fracture must keep: every piece a closed, oriented surface.
 */
#include "watertight.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

typedef struct {
    int32_t lo, hi;
    int32_t forward; /* 1 if the triangle runs lo -> hi */
} edge_rec;

static int cmp_edge(const void *pa, const void *pb)
{
    const edge_rec *a = pa, *b = pb;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    return (a->forward > b->forward) - (a->forward < b->forward);
}

double cs_mesh_volume(const double *v, const int32_t *t, int nt)
{
    /* Tetrahedra from a point of the mesh, not from the origin: for a closed surface the sum is
     * the same, but far from the origin the origin's terms cancel to round-off of |x|³ (a
     * 6 cm mesh placed 10 km out came out "inside out", an outside review found). */
    if (nt <= 0)
        return 0.0;
    const double *o = v + 3 * t[0];
    double vol = 0.0;
    for (int i = 0; i < nt; i++) {
        const double *pa = v + 3 * t[3 * i], *pb = v + 3 * t[3 * i + 1], *pc = v + 3 * t[3 * i + 2];
        const double a[3] = {pa[0] - o[0], pa[1] - o[1], pa[2] - o[2]};
        const double b[3] = {pb[0] - o[0], pb[1] - o[1], pb[2] - o[2]};
        const double c[3] = {pc[0] - o[0], pc[1] - o[1], pc[2] - o[2]};
        vol += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
               a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    return vol / 6.0;
}

/* edge key with the triangle that uses it (cs_mesh_orient_shells) */
typedef struct {
    int32_t lo, hi, tri;
} edge_tri;

static int cmp_edge_tri(const void *pa, const void *pb)
{
    const edge_tri *a = pa, *b = pb;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    return (a->tri > b->tri) - (a->tri < b->tri);
}

static int32_t root_of(int32_t *up, int32_t i)
{
    while (up[i] != i) {
        up[i] = up[up[i]];
        i = up[i];
    }
    return i;
}

/* The solid angle of triangle (a, b, c) seen from p, over 4π (Van Oosterom and Strackee). */
static double winding_of_triangle(const double *p, const double *pa, const double *pb,
                                  const double *pc)
{
    const double a[3] = {pa[0] - p[0], pa[1] - p[1], pa[2] - p[2]};
    const double b[3] = {pb[0] - p[0], pb[1] - p[1], pb[2] - p[2]};
    const double c[3] = {pc[0] - p[0], pc[1] - p[1], pc[2] - p[2]};
    const double la = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    const double lb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    const double lc = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    const double det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                       a[2] * (b[0] * c[1] - b[1] * c[0]);
    const double den = la * lb * lc + (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) * lc +
                       (a[0] * c[0] + a[1] * c[1] + a[2] * c[2]) * lb +
                       (b[0] * c[0] + b[1] * c[1] + b[2] * c[2]) * la;
    return 2.0 * atan2(det, den) / (4.0 * M_PI);
}

int cs_mesh_orient_shells(const double *v, int nv, int32_t *t, int nt, int *n_shells)
{
    if (n_shells)
        *n_shells = nt > 0;
    if (nt <= 1 || nv <= 0)
        return 0;
    int32_t *up = malloc((size_t)nt * sizeof *up);
    edge_tri *e = malloc((size_t)nt * 3 * sizeof *e);
    if (!up || !e) {
        free(up);
        free(e);
        return -1;
    }
    for (int32_t i = 0; i < nt; i++)
        up[i] = i;
    for (int32_t i = 0; i < nt; i++)
        for (int k = 0; k < 3; k++) {
            const int32_t a = t[3 * i + k], b = t[3 * i + (k + 1) % 3];
            e[3 * i + k] = (edge_tri){a < b ? a : b, a < b ? b : a, i};
        }
    qsort(e, (size_t)nt * 3, sizeof *e, cmp_edge_tri);
    for (int i = 0; i + 1 < 3 * nt; i++)
        if (e[i].lo == e[i + 1].lo && e[i].hi == e[i + 1].hi) {
            const int32_t ra = root_of(up, e[i].tri), rb = root_of(up, e[i + 1].tri);
            if (ra != rb)
                up[ra < rb ? rb : ra] = ra < rb ? ra : rb;
        }
    free(e);
    /* shells numbered by their first triangle; their signed volumes from one common point */
    int32_t *shell = malloc((size_t)nt * sizeof *shell), ns = 0;
    int32_t *first = malloc((size_t)nt * sizeof *first);
    double *vol = calloc((size_t)nt, sizeof *vol);
    if (!shell || !first || !vol) {
        free(up);
        free(shell);
        free(first);
        free(vol);
        return -1;
    }
    for (int32_t i = 0; i < nt; i++) {
        const int32_t r = root_of(up, i);
        if (r == i) {
            first[ns] = i;
            shell[i] = ns++;
        } else {
            shell[i] = shell[r]; /* r < i: numbered already */
        }
    }
    free(up);
    if (n_shells)
        *n_shells = ns;
    const double *o = v + 3 * t[0];
    for (int32_t i = 0; i < nt; i++) {
        const double *pa = v + 3 * t[3 * i], *pb = v + 3 * t[3 * i + 1], *pc = v + 3 * t[3 * i + 2];
        const double a[3] = {pa[0] - o[0], pa[1] - o[1], pa[2] - o[2]};
        const double b[3] = {pb[0] - o[0], pb[1] - o[1], pb[2] - o[2]};
        const double c[3] = {pc[0] - o[0], pc[1] - o[1], pc[2] - o[2]};
        vol[shell[i]] += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                         a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    /* each inward shell: the winding number of the other shells at its first triangle's
     * centroid (they do not pass through it: the surface is manifold) */
    unsigned char *turn = calloc((size_t)ns, 1);
    int turned = 0;
    for (int32_t s = 0; turn && ns > 1 && s < ns; s++) {
        if (!(vol[s] < 0))
            continue;
        const int32_t *f = t + 3 * first[s];
        double p[3], w = 0;
        for (int a = 0; a < 3; a++)
            p[a] = (v[3 * f[0] + a] + v[3 * f[1] + a] + v[3 * f[2] + a]) / 3.0;
        for (int32_t i = 0; i < nt; i++)
            if (shell[i] != s)
                w += winding_of_triangle(p, v + 3 * t[3 * i], v + 3 * t[3 * i + 1],
                                         v + 3 * t[3 * i + 2]);
        if (w < 0.5) {
            turn[s] = 1;
            turned++;
        }
    }
    for (int32_t i = 0; turned > 0 && i < nt; i++)
        if (turn[shell[i]]) {
            const int32_t tmp = t[3 * i + 1];
            t[3 * i + 1] = t[3 * i + 2];
            t[3 * i + 2] = tmp;
        }
    const int rc = turn ? turned : -1;
    free(turn);
    free(shell);
    free(first);
    free(vol);
    return rc;
}

static int fail(char *err, size_t errlen, const char *msg)
{
    if (err && errlen)
        snprintf(err, errlen, "%s", msg);
    return 0;
}

int cs_watertight_check(const double *v, int nv, const int32_t *t, int nt,
                        cs_watertight_report *rep, char *err, size_t errlen)
{
    cs_watertight_report r = {0};
    char msg[160];
    if (rep)
        *rep = r;
    if (nt <= 0)
        return fail(err, errlen, "no triangles: the surface is empty");
    for (int i = 0; i < 3 * nt; i++)
        if (t[i] < 0 || t[i] >= nv) {
            snprintf(msg, sizeof msg, "triangle %d has vertex index %d out of range [0,%d)",
                     i / 3, (int)t[i], nv);
            return fail(err, errlen, msg);
        }
    edge_rec *e = malloc((size_t)nt * 3 * sizeof *e);
    if (!e)
        return fail(err, errlen, "out of memory checking the surface");
    int ne = 0;
    for (int i = 0; i < nt; i++) {
        const int32_t *tri = t + 3 * i;
        if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) {
            r.degenerate_triangles++;
        } else {
            const double *a = v + 3 * tri[0], *b = v + 3 * tri[1], *c = v + 3 * tri[2];
            double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                           u[0] * w[1] - u[1] * w[0]};
            double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
            double uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
            double ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
            /* zero area relative to the edge lengths (sin of the angle below ~1e-12) */
            if (!(nn > 1e-24 * uu * ww))
                r.degenerate_triangles++;
        }
        for (int k = 0; k < 3; k++) {
            int32_t a = tri[k], b = tri[(k + 1) % 3];
            if (a == b)
                continue;
            e[ne++] = a < b ? (edge_rec){a, b, 1} : (edge_rec){b, a, 0};
        }
    }
    qsort(e, (size_t)ne, sizeof *e, cmp_edge);
    for (int i = 0; i < ne;) {
        int j = i + 1;
        while (j < ne && e[j].lo == e[i].lo && e[j].hi == e[i].hi)
            j++;
        int run = j - i;
        if (run == 1)
            r.boundary_edges++;
        else if (run > 2)
            r.nonmanifold_edges++;
        else if (e[i].forward == e[i + 1].forward)
            r.misoriented_edges++;
        i = j;
    }
    free(e);
    r.volume = cs_mesh_volume(v, t, nt);
    if (rep)
        *rep = r;
    if (r.boundary_edges) {
        snprintf(msg, sizeof msg, "%d boundary edges: the surface is open", r.boundary_edges);
        return fail(err, errlen, msg);
    }
    if (r.nonmanifold_edges) {
        snprintf(msg, sizeof msg, "%d edges shared by three or more triangles: not manifold",
                 r.nonmanifold_edges);
        return fail(err, errlen, msg);
    }
    if (r.misoriented_edges) {
        snprintf(msg, sizeof msg,
                 "%d edges used twice in the same direction: inconsistent orientation",
                 r.misoriented_edges);
        return fail(err, errlen, msg);
    }
    if (r.degenerate_triangles) {
        snprintf(msg, sizeof msg, "%d degenerate triangles (repeated vertex or zero area)",
                 r.degenerate_triangles);
        return fail(err, errlen, msg);
    }
    if (!(r.volume > 0.0)) {
        snprintf(msg, sizeof msg, "enclosed volume %.6g is not positive: the surface is inside out",
                 r.volume);
        return fail(err, errlen, msg);
    }
    return 1;
}

int cs_check_pieces(const cs_piece_view *pieces, int n, double expected_volume,
                    double rel_tol, double *total_volume, char *err, size_t errlen)
{
    double total = 0;
    int ok = 1;
    for (int i = 0; i < n && ok; i++) {
        const cs_piece_view *p = &pieces[i];
        char why[200];
        cs_watertight_report rep;
        if (!cs_watertight_check(p->v, p->nv, p->t, p->nt, &rep, why, sizeof why)) {
            if (err && errlen)
                snprintf(err, errlen, "piece %d (%s): %s", i, p->name ? p->name : "unnamed",
                         why);
            ok = 0;
        }
        total += rep.volume;
    }
    if (total_volume)
        *total_volume = total;
    if (ok && isfinite(expected_volume) &&
        fabs(total - expected_volume) > rel_tol * fabs(expected_volume)) {
        if (err && errlen)
            snprintf(err, errlen, "pieces enclose %.9g m^3 in all, expected %.9g m^3 (relative "
                     "error %.3g > %.3g)", total, expected_volume,
                     fabs(total - expected_volume) / fabs(expected_volume), rel_tol);
        ok = 0;
    }
    return ok;
}
