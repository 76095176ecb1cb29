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
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>

typedef struct {
    int32_t lo, hi;
    int32_t forward; /* 1 if the triangle runs lo -> hi */
    int32_t tri;     /* the triangle (cs_mesh_orient_shells) */
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

/* 6 × the signed volume of the tetrahedron (o, pa, pb, pc). */
static double tet6(const double *o, const double *pa, const double *pb, const double *pc)
{
    const double a[3] = {pa[0] - o[0], pa[1] - o[1], pa[2] - o[2]};
    const double b[3] = {pb[0] - o[0], pb[1] - o[1], pb[2] - o[2]};
    const double c[3] = {pc[0] - o[0], pc[1] - o[1], pc[2] - o[2]};
    return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
           a[2] * (b[0] * c[1] - b[1] * c[0]);
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
    for (int i = 0; i < nt; i++)
        vol += tet6(o, v + 3 * t[3 * i], v + 3 * t[3 * i + 1], v + 3 * t[3 * i + 2]);
    return vol / 6.0;
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
    const double det = tet6(p, pa, pb, pc);
    const double den = la * lb * lc + (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) * lc +
                       (a[0] * c[0] + a[1] * c[1] + a[2] * c[2]) * lb +
                       (b[0] * c[0] + b[1] * c[1] + b[2] * c[2]) * la;
    return 2.0 * atan2(det, den) / (4.0 * M_PI);
}

/* What cs_mesh_orient_shells keeps per shell. */
typedef struct shell_info {
    double vol, lo[3], hi[3];
    int32_t start, count; /* its triangles in the shell-sorted order */
} shell_info;

static void centroid(const double *v, const int32_t *f, double p[3])
{
    for (int a = 0; a < 3; a++)
        p[a] = (v[3 * f[0] + a] + v[3 * f[1] + a] + v[3 * f[2] + a]) / 3.0;
}

static bool box_within(const shell_info *in, const shell_info *out)
{
    for (int a = 0; a < 3; a++)
        if (in->lo[a] < out->lo[a] || in->hi[a] > out->hi[a])
            return false;
    return true;
}

/* The winding number of shell j about p (solid angles summed over its triangles); *budget
 * counts the triangles. */
static double shell_winding(const double *v, const int32_t *t, const int32_t *order,
                            const shell_info *sj, const double *p, long *budget)
{
    double w = 0;
    for (int32_t k = sj->start; k < sj->start + sj->count; k++) {
        const int32_t *f = t + 3 * order[k];
        w += winding_of_triangle(p, v + 3 * f[0], v + 3 * f[1], v + 3 * f[2]);
    }
    *budget -= sj->count;
    return w;
}

int cs_mesh_orient_shells(const double *v, int nv, int32_t *t, int nt, int *n_shells)
{
    if (n_shells)
        *n_shells = nt > 0;
    if (nt <= 1 || nv <= 0)
        return 0;
    int32_t *up = malloc((size_t)nt * sizeof *up);
    edge_rec *e = malloc((size_t)nt * 3 * sizeof *e);
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
            e[3 * i + k] = (edge_rec){a < b ? a : b, a < b ? b : a, a < b, i};
        }
    qsort(e, (size_t)nt * 3, sizeof *e, cmp_edge);
    for (int i = 0; i + 1 < 3 * nt; i++)
        if (e[i].lo == e[i + 1].lo && e[i].hi == e[i + 1].hi) {
            const int32_t ra = root_of(up, e[i].tri), rb = root_of(up, e[i + 1].tri);
            if (ra != rb)
                up[ra < rb ? rb : ra] = ra < rb ? ra : rb;
        }
    free(e);
    /* shells numbered by their first triangle (a root is its set's lowest index) */
    int32_t *shell = malloc((size_t)nt * sizeof *shell), *order = malloc((size_t)nt * sizeof *order);
    shell_info *sh = calloc((size_t)nt, sizeof *sh);
    if (!shell || !order || !sh) {
        free(up);
        free(shell);
        free(order);
        free(sh);
        return -1;
    }
    int32_t ns = 0;
    for (int32_t i = 0; i < nt; i++) {
        const int32_t r = root_of(up, i);
        shell[i] = r == i ? ns++ : shell[r];
    }
    free(up);
    if (n_shells)
        *n_shells = ns;
    for (int32_t s = 0; s < ns; s++)
        for (int a = 0; a < 3; a++) {
            sh[s].lo[a] = INFINITY;
            sh[s].hi[a] = -INFINITY;
        }
    const double *o = v + 3 * t[0];
    for (int32_t i = 0; i < nt; i++) {
        shell_info *si = &sh[shell[i]];
        si->count++;
        si->vol += tet6(o, v + 3 * t[3 * i], v + 3 * t[3 * i + 1], v + 3 * t[3 * i + 2]);
        for (int k = 0; k < 3; k++)
            for (int d = 0; d < 3; d++) {
                si->lo[d] = fmin(si->lo[d], v[3 * t[3 * i + k] + d]);
                si->hi[d] = fmax(si->hi[d], v[3 * t[3 * i + k] + d]);
            }
    }
    bool any_inward = false;
    for (int32_t s = 0, at = 0; s < ns; s++) {
        sh[s].start = at;
        at += sh[s].count;
        sh[s].count = 0;
        any_inward |= sh[s].vol < 0;
    }
    for (int32_t i = 0; i < nt; i++)
        order[sh[shell[i]].start + sh[shell[i]].count++] = i;
    free(shell);
    unsigned char *turn = any_inward && ns > 1 ? calloc((size_t)ns, 1) : NULL;
    int turned = 0;
    /* triangles summed over and box tests, each about half a second at most; past either, the
     * shells not yet decided are left as they are */
    long budget = 20000000, boxes = 400000000;
    /* A shell of negative volume at even depth (inside no shell, or inside a cavity: 0 or 2
     * shells around it) is the outer wall of a part wound inside out as a whole; the part is
     * turned: that shell and every shell inside it (a cavity wall in it, wound outward, becomes
     * one again). A negative shell at odd depth is a cavity's wall; positive shells are left as
     * they are (an outward shell inside another is a second solid, winding number 2). "Inside":
     * its bounding box within the other's, and the other's winding number about a point of it
     * not 0 — a point tried at up to 8 of its triangles' centroids until every winding number
     * about it is near a whole number (a centroid on another shell's face gives ½). */
    for (int32_t s = 0; turn && s < ns && budget > 0 && boxes > 0; s++) {
        if (!(sh[s].vol < 0) || turn[s])
            continue;
        int depth = 0;
        for (int tries = 0; tries < 8 && budget > 0; tries++) {
            const int32_t k = sh[s].start + (int32_t)((int64_t)sh[s].count * tries / 8);
            double p[3];
            centroid(v, t + 3 * order[k], p);
            bool clean = true;
            depth = 0;
            for (int32_t j = 0; j < ns && budget > 0 && boxes > 0; j++) {
                boxes--; /* shells × shells of box tests in a file of many shells */
                if (j == s || !box_within(&sh[s], &sh[j]))
                    continue;
                const double w = shell_winding(v, t, order, &sh[j], p, &budget);
                clean &= fabs(w - round(w)) < 0.25;
                depth += fabs(w) >= 0.5;
            }
            if (clean)
                break;
        }
        if (budget <= 0 || boxes <= 0 || depth % 2)
            continue;
        turn[s] = 1;
        for (int32_t j = 0; j < ns && budget > 0 && boxes > 0; j++) {
            boxes--;
            if (j == s || turn[j] || !box_within(&sh[j], &sh[s]))
                continue;
            double p[3];
            centroid(v, t + 3 * order[sh[j].start], p);
            if (fabs(shell_winding(v, t, order, &sh[s], p, &budget)) >= 0.5)
                turn[j] = 1;
        }
    }
    for (int32_t s = 0; turn && s < ns; s++) {
        if (!turn[s])
            continue;
        turned++;
        for (int32_t k = sh[s].start; k < sh[s].start + sh[s].count; k++) {
            int32_t *f = t + 3 * order[k];
            const int32_t tmp = f[1];
            f[1] = f[2];
            f[2] = tmp;
        }
    }
    const int rc = (any_inward && ns > 1 && !turn) ? -1 : turned;
    free(turn);
    free(order);
    free(sh);
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
            e[ne++] = a < b ? (edge_rec){a, b, 1, i} : (edge_rec){b, a, 0, i};
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
