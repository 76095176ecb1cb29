/*
 * mesh_io.c — triangle surface import and export through assimp's C API (implements mesh.h;
 * the input side of seed 000 §2.1: "an arbitrary surface mesh" becomes one indexed triangle list).
 *
 * Import: assimp pre-transforms (node transforms baked in) and splits primitive types; we then
 * merge every mesh of the scene with faces, cut polygons into triangles (triangulate_face), weld
 * vertices with bit-identical positions across meshes (sort, O(n log n): STL shares none), drop
 * points, lines, triangles with a repeated index or exactly zero area, and vertices no triangle
 * uses. Every coordinate is checked with isfinite. Assimp stores float32 (ai_real), so that is
 * the precision of any file it reads. OFF is read here instead (load_off, in double precision:
 * assimp's reader drops faces of more than 9 corners), then cut, welded and cleaned the same way.
 * All of that runs in a forked child under a memory cap and a time limit (see "the guarded
 * import" below); the parent only reads the result from a pipe.
 *
 * Export: a scene built by hand (one aiMesh and one child node per piece, one empty material),
 * handed to aiExportScene and freed here — it was never assimp's, so aiReleaseImport must not
 * see it. The exporter id follows the extension. Normals: assimp's OBJ and STL exporters make
 * their own when a mesh has none (OBJ smooth vertex normals, STL face normals), and both run
 * on our shared vertices as if each belonged to one triangle: a vertex kept the normal of the
 * last face written through it (on a box, two of every three corner normals pointed along the
 * wrong axis, and STL wrote wrong face normals). For those formats each triangle gets its own
 * three corners carrying its geometric normal (flat shading, what STL holds and what glTF
 * viewers must compute when normals are absent); OBJ still writes every position once (the
 * exporter welds equal positions) and every distinct normal once, so its faces stay joined.
 * The other formats get shared vertices and no normals, as a viewer then computes them.
 */
#include "mesh.h"

#include <assimp/cexport.h>
#include <assimp/cimport.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

void cs_mesh_free(cs_mesh *m)
{
    if (!m)
        return;
    free(m->v);
    free(m->t);
    m->v = NULL;
    m->t = NULL;
    m->nv = m->nt = 0;
}

const char *cs_msg_text(const char *s, char *buf, size_t n, int path)
{
    static const char cut[] = "\xe2\x80\xa6"; /* U+2026 (...), where the text was cut */
    if (!buf || n == 0)
        return "";
    if (!s)
        s = "(null)";
    const size_t len = strlen(s);
    size_t from = 0, to = len, k = 0;
    if (len > n - 1 && n > sizeof cut) {
        if (path) {
            /* keep the end: as many bytes as fit behind the mark, from a character's first
             * byte, and from a '/' if one comes soon (whole folder names, not a piece) */
            from = len - (n - sizeof cut);
            while (from < len && ((unsigned char)s[from] & 0xc0) == 0x80)
                from++;
            const char *slash = memchr(s + from, '/', len - from);
            if (slash && slash - (s + from) <= 40)
                from = (size_t)(slash - s);
            memcpy(buf, cut, sizeof cut - 1);
            k = sizeof cut - 1;
        } else {
            /* keep the start, up to a character's first byte, the mark after it */
            to = n - sizeof cut;
            while (to > 0 && ((unsigned char)s[to] & 0xc0) == 0x80)
                to--;
        }
    }
    for (size_t i = from; i < to && k < n - 1; i++)
        buf[k++] = ((unsigned char)s[i] < 0x20 || s[i] == 0x7f) ? '?' : s[i];
    if (to < len) {
        memcpy(buf + k, cut, sizeof cut - 1);
        k += sizeof cut - 1;
    }
    buf[k] = '\0';
    return buf;
}

const char *cs_msg_path(const char *s, char *buf, size_t n)
{
    return cs_msg_text(s, buf, n, 1);
}

typedef struct {
    const double *v;
    int32_t idx;
} weld_key;

static int cmp_pos(const void *pa, const void *pb)
{
    const weld_key *a = pa, *b = pb;
    for (int k = 0; k < 3; k++) {
        double x = a->v[3 * a->idx + k], y = b->v[3 * b->idx + k];
        if (x < y)
            return -1;
        if (x > y)
            return 1;
    }
    return (a->idx > b->idx) - (a->idx < b->idx);
}

/*
 * Weld identical positions, drop degenerate triangles, compact unused vertices. In place on
 * m (arrays may shrink but are not reallocated). Returns 0 or -1 on out of memory.
 */
static int weld_and_clean(cs_mesh *m)
{
    int nv = m->nv;
    weld_key *keys = malloc((size_t)(nv ? nv : 1) * sizeof *keys);
    int32_t *remap = malloc((size_t)(nv ? nv : 1) * sizeof *remap);
    int32_t *used = malloc((size_t)(nv ? nv : 1) * sizeof *used);
    if (!keys || !remap || !used) {
        free(keys);
        free(remap);
        free(used);
        return -1;
    }
    for (int i = 0; i < nv; i++)
        keys[i] = (weld_key){m->v, i};
    qsort(keys, (size_t)nv, sizeof *keys, cmp_pos);
    /* remap every vertex to the first (lowest index) of its equal-position run */
    for (int i = 0; i < nv;) {
        int j = i + 1;
        while (j < nv && m->v[3 * keys[j].idx] == m->v[3 * keys[i].idx] &&
               m->v[3 * keys[j].idx + 1] == m->v[3 * keys[i].idx + 1] &&
               m->v[3 * keys[j].idx + 2] == m->v[3 * keys[i].idx + 2])
            j++;
        for (int k = i; k < j; k++)
            remap[keys[k].idx] = keys[i].idx;
        i = j;
    }
    free(keys);
    /* keep non-degenerate triangles */
    int nt = 0;
    for (int t = 0; t < m->nt; t++) {
        int32_t a = remap[m->t[3 * t]], b = remap[m->t[3 * t + 1]], c = remap[m->t[3 * t + 2]];
        if (a == b || b == c || a == c)
            continue;
        const double *pa = m->v + 3 * a, *pb = m->v + 3 * b, *pc = m->v + 3 * c;
        double u[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
        double w[3] = {pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]};
        double n0 = u[1] * w[2] - u[2] * w[1], n1 = u[2] * w[0] - u[0] * w[2],
               n2 = u[0] * w[1] - u[1] * w[0];
        if (n0 == 0.0 && n1 == 0.0 && n2 == 0.0)
            continue;
        m->t[3 * nt] = a;
        m->t[3 * nt + 1] = b;
        m->t[3 * nt + 2] = c;
        nt++;
    }
    m->nt = nt;
    /* compact: new index of each used vertex, in original order */
    for (int i = 0; i < nv; i++)
        used[i] = -1;
    for (int k = 0; k < 3 * nt; k++)
        used[m->t[k]] = 0;
    int n = 0;
    for (int i = 0; i < nv; i++) {
        if (used[i] < 0)
            continue;
        used[i] = n;
        memmove(m->v + 3 * n, m->v + 3 * i, 3 * sizeof(double));
        n++;
    }
    for (int k = 0; k < 3 * nt; k++)
        m->t[k] = used[m->t[k]];
    m->nv = n;
    free(remap);
    free(used);
    return 0;
}

/*
 * The triangles of polygon face idx[0..k) (k >= 4) over positions v, appended to t (3 per
 * triangle, the face's winding kept); returns their count (k − 2). Ear clipping in the plane
 * that drops the largest component of the face's Newell normal: a concave face (an L- or
 * T-shaped cap) comes out as its own area, where assimp's triangulation overlapped triangles
 * and the surface was then refused with a wrong reason (an outside check: "vertex … lies in no
 * cube", "6 boundary edges"). A vertex is an ear when it turns with the face and no other
 * vertex of what is left lies in or on its triangle; where no ear is left (a self-intersecting
 * or degenerate face) the rest is a fan. rest: scratch of k ints. budget: containment tests
 * left for the file (each face's cost is up to corners² × reflex corners, and a crafted file
 * must not keep the importer busy to its time limit); once spent, faces are fans.
 */
static int triangulate_face(const double *v, const int32_t *idx, int k, int32_t *t, int *rest,
                            long *budget)
{
    double nrm[3] = {0, 0, 0};
    for (int i = 0; i < k; i++) {
        const double *p = v + 3 * idx[i], *q = v + 3 * idx[(i + 1) % k];
        nrm[0] += (p[1] - q[1]) * (p[2] + q[2]);
        nrm[1] += (p[2] - q[2]) * (p[0] + q[0]);
        nrm[2] += (p[0] - q[0]) * (p[1] + q[1]);
    }
    const int ax = fabs(nrm[0]) > fabs(nrm[1]) ? (fabs(nrm[0]) > fabs(nrm[2]) ? 0 : 2)
                                               : (fabs(nrm[1]) > fabs(nrm[2]) ? 1 : 2);
    const int u = (ax + 1) % 3, w = (ax + 2) % 3; /* (u, w, ax) right-handed */
    const double sg = nrm[ax] < 0 ? -1.0 : 1.0;
    int n = k, nt = 0;
    for (int i = 0; i < k; i++)
        rest[i] = idx[i];
#define FX(i) (v[3 * rest[i] + u])
#define FY(i) (v[3 * rest[i] + w])
#define TURN(a, b, c) (sg * ((FX(b) - FX(a)) * (FY(c) - FY(b)) - (FY(b) - FY(a)) * (FX(c) - FX(b))))
    /* From the second corner, and after each ear from the corner that followed it: a convex
     * face becomes the fan from its first corner, as assimp cut it (a quad along its diagonal
     * 0–2 unless that lies outside it; the other diagonal of the duck's non-planar quads is an
     * edge of its neighbours), each ear found at once. */
    int start = 1, reflex = 0; /* corners that turn against the face (or not at all) */
    for (int i = 0; i < n; i++)
        reflex += !(TURN((i + n - 1) % n, i, (i + 1) % n) > 0);
    while (n > 3 && reflex > 0 && *budget > 0) { /* none left: the fan below is the rest */
        int ear = -1;
        for (int q = 0; q < n && ear < 0; q++) {
            const int i = (start + q) % n, a = (i + n - 1) % n, c = (i + 1) % n;
            if (!(TURN(a, i, c) > 0))
                continue;
            const double ax2 = FX(a), ay = FY(a), bx = FX(i), by = FY(i), cx = FX(c), cy = FY(c);
            int inside = 0;
            for (int j = 0; j < n && !inside; j++) {
                if (j == a || j == i || j == c)
                    continue;
                --*budget;
                /* in a simple polygon only a reflex (or straight) corner can lie in an ear */
                if (TURN((j + n - 1) % n, j, (j + 1) % n) > 0)
                    continue;
                const double px = FX(j), py = FY(j);
                if ((px == ax2 && py == ay) || (px == bx && py == by) || (px == cx && py == cy))
                    continue; /* a repeated position of a corner */
                const double d1 = sg * ((bx - ax2) * (py - ay) - (by - ay) * (px - ax2));
                const double d2 = sg * ((cx - bx) * (py - by) - (cy - by) * (px - bx));
                const double d3 = sg * ((ax2 - cx) * (py - cy) - (ay - cy) * (px - cx));
                inside = d1 >= 0 && d2 >= 0 && d3 >= 0;
            }
            if (!inside)
                ear = i;
        }
        if (ear < 0)
            break;
        const int a = (ear + n - 1) % n, c = (ear + 1) % n;
        t[3 * nt] = rest[a];
        t[3 * nt + 1] = rest[ear];
        t[3 * nt + 2] = rest[c];
        nt++;
        reflex -= !(TURN((a + n - 1) % n, a, ear) > 0) + !(TURN(ear, c, (c + 1) % n) > 0);
        memmove(rest + ear, rest + ear + 1, (size_t)(n - ear - 1) * sizeof *rest);
        n--;
        start = ear % n;
        const int a1 = ear > 0 ? ear - 1 : n - 1, c1 = ear % n; /* a and c, renumbered */
        reflex += !(TURN((a1 + n - 1) % n, a1, c1) > 0) + !(TURN(a1, c1, (c1 + 1) % n) > 0);
    }
#undef TURN
#undef FX
#undef FY
    for (int i = 1; i + 1 < n; i++) { /* the last triangle, or the fan of what is left */
        t[3 * nt] = rest[0];
        t[3 * nt + 1] = rest[i];
        t[3 * nt + 2] = rest[i + 1];
        nt++;
    }
    return nt;
}

/* The triangles of face idx[0..k) (k >= 3) appended to t: a triangle as it is, a polygon by
 * triangulate_face. Returns their count. */
static int face_triangles(const double *v, const int32_t *idx, int k, int32_t *t, int *rest,
                          long *budget)
{
    if (k == 3) {
        memcpy(t, idx, 3 * sizeof *idx);
        return 1;
    }
    return triangulate_face(v, idx, k, t, rest, budget);
}

/* ---------------------------------------------------------------- OFF, read here */

/*
 * OFF (Geomview's object file format) is read here, not by assimp: assimp's reader drops every
 * face of more than 9 corners without a word (a 12-sided prism arrived without its two caps and
 * was refused as "24 boundary edges: the surface is open"), replaces an index past the last
 * vertex by the last vertex, and reads coordinates as floats. The format: an optional keyword
 * [ST][C][N][4][n]OFF (n: the coordinate count follows; 4: a homogeneous w after the
 * coordinates), the vertex, face and edge counts, one vertex per line (x y z, then whatever
 * normals, colours or texture coordinates the keyword announces, ignored here), one face per
 * line (its corner count, the corners' indices from 0, then an optional colour, ignored);
 * '#' starts a comment. Binary OFF is refused. Positions are read in double precision.
 */
typedef struct off_reader {
    const char *p, *end; /* the unread text */
    int line;            /* of the text at p, from 1 */
} off_reader;

/* A blank between OFF's words (a space, a tab, a carriage return, a form or vertical feed). */
static int off_blank(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}

/* The next line that holds anything but blanks and a comment: [*b, *e) without the comment.
 * Returns 0 at the end of the text. */
static int off_line(off_reader *r, const char **b, const char **e)
{
    while (r->p < r->end) {
        const char *s = r->p, *nl = memchr(s, '\n', (size_t)(r->end - s));
        const char *stop = nl ? nl : r->end, *hash = memchr(s, '#', (size_t)(stop - s));
        r->p = nl ? nl + 1 : r->end;
        r->line++;
        const char *t = hash ? hash : stop;
        while (s < t && off_blank(*s))
            s++;
        if (s < t) {
            *b = s;
            *e = t;
            return 1;
        }
    }
    return 0;
}

/* The next blank-separated word of [*b, e): [*b, returned end); NULL if none is left. */
static const char *off_word(const char **b, const char *e)
{
    const char *s = *b;
    while (s < e && off_blank(*s))
        s++;
    *b = s;
    while (s < e && !off_blank(*s))
        s++;
    return s > *b ? s : NULL;
}

/* A number word [b, we) as a double (strtod's syntax, the whole word: OFF writers use C's
 * forms, ".5" and "1." among them, which cs_parse_decimal's JSON syntax refuses); 0 or -1.
 * NaN and inf words parse and are refused by the caller's isfinite. */
static int off_number(const char *b, const char *we, double *x)
{
    char buf[64];
    const size_t n = (size_t)(we - b);
    if (n >= sizeof buf)
        return -1;
    memcpy(buf, b, n);
    buf[n] = '\0';
    char *stop;
    *x = strtod(buf, &stop);
    return *stop == '\0' ? 0 : -1;
}

/* A count or index word [b, we): digits only, below 2^31; 0 or -1. */
static int off_count(const char *b, const char *we, long *k)
{
    long v = 0;
    if (b == we)
        return -1;
    for (const char *s = b; s < we; s++) {
        if (*s < '0' || *s > '9' || v > (INT32_MAX - 9) / 10)
            return -1;
        v = 10 * v + (*s - '0');
    }
    *k = v;
    return 0;
}

/* The next word of the header (across lines), into [*wb, returned end); NULL at the end. */
static const char *off_header_word(off_reader *r, const char **lb, const char **le, const char **wb)
{
    for (;;) {
        if (*lb < *le) {
            const char *we = off_word(lb, *le);
            if (we) {
                *wb = *lb;
                *lb = we;
                return we;
            }
        }
        if (!off_line(r, lb, le))
            return NULL;
    }
}

static int load_off(const char *path, const char *shown, off_t size, cs_mesh *out, char *err,
                    size_t errlen)
{
    char *text = NULL;
    int32_t *poly = NULL;
    int *rest = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, errlen, "mesh '%s': %s", shown, strerror(errno));
        return -1;
    }
    text = malloc((size_t)size + 1);
    if (!text) {
        fclose(f);
        snprintf(err, errlen, "mesh '%s': out of memory", shown);
        return -1;
    }
    const size_t got = fread(text, 1, (size_t)size, f);
    fclose(f);
    if (got != (size_t)size) {
        snprintf(err, errlen, "mesh '%s': read %zu of its %lld bytes", shown, got, (long long)size);
        goto fail;
    }
    if (memchr(text, '\0', got)) {
        snprintf(err, errlen, "mesh '%s': OFF: a zero byte in the text (binary OFF is not read)",
                 shown);
        goto fail;
    }
    off_reader r = {text, text + got, 0};
    const char *lb = text, *le = text, *wb, *we;
    /* the keyword: [ST][C][N][4][n]OFF, or none (the counts come first) */
    int homogeneous = 0, dimension = 3, has_dim = 0;
    if (!(we = off_header_word(&r, &lb, &le, &wb))) {
        snprintf(err, errlen, "mesh '%s': OFF: no header (only blanks and comments)", shown);
        goto fail;
    }
    const size_t wl = (size_t)(we - wb);
    if (wl >= 3 && !memcmp(we - 3, "OFF", 3)) {
        const char *k = wb, *kend = we - 3;
        if (kend - k >= 2 && !memcmp(k, "ST", 2))
            k += 2;
        if (k < kend && *k == 'C')
            k++;
        if (k < kend && *k == 'N')
            k++;
        if (k < kend && *k == '4')
            homogeneous = 1, k++;
        if (k < kend && *k == 'n')
            has_dim = 1, k++;
        if (k != kend) {
            snprintf(err, errlen, "mesh '%s': OFF: line %d: unknown keyword '%.*s'", shown, r.line,
                     (int)(wl < 40 ? wl : 40), wb);
            goto fail;
        }
        if (!(we = off_header_word(&r, &lb, &le, &wb)))
            goto short_header;
        if ((size_t)(we - wb) == 6 && !memcmp(wb, "BINARY", 6)) {
            snprintf(err, errlen, "mesh '%s': OFF: binary OFF is not read (write it as text)",
                     shown);
            goto fail;
        }
        if (has_dim) {
            long d;
            if (off_count(wb, we, &d) != 0) {
                snprintf(err, errlen, "mesh '%s': OFF: line %d: the dimension is not a count",
                         shown, r.line);
                goto fail;
            }
            dimension = (int)d;
            if (!(we = off_header_word(&r, &lb, &le, &wb)))
                goto short_header;
        }
    }
    if (dimension != 3) {
        snprintf(err, errlen, "mesh '%s': OFF: %d coordinates per vertex (only 3 are read)", shown,
                 dimension);
        goto fail;
    }
    /* the vertex and face counts; the edge count, which writers often leave out, is not
     * used (whatever follows the face count on its line is skipped) */
    long counts[2];
    for (int c = 0; c < 2; c++) {
        if (c > 0 && !(we = off_header_word(&r, &lb, &le, &wb)))
            goto short_header;
        if (off_count(wb, we, &counts[c]) != 0) {
            snprintf(err, errlen, "mesh '%s': OFF: line %d: the %s count '%.*s' is not a count "
                     "below 2^31", shown, r.line, c == 0 ? "vertex" : "face",
                     (int)((we - wb) < 40 ? (we - wb) : 40), wb);
            goto fail;
        }
    }
    const long nv = counts[0], nf = counts[1];
    /* a vertex line takes at least 6 bytes ("0 0 0\n"), a face line 8 ("3 0 1 2\n"): a
     * header claiming far more is refused before anything is allocated for it (a file cut
     * short is found below, with the line it ends at) */
    if (nv > (long)(got / 4) + 64 || nf > (long)(got / 4) + 64 || nv > INT32_MAX / 3) {
        snprintf(err, errlen, "mesh '%s': OFF: the header claims %ld vertices and %ld faces, more "
                 "than its %zu bytes can hold", shown, nv, nf, got);
        goto fail;
    }
    if (nv < 3 || nf < 1) {
        snprintf(err, errlen, "mesh '%s': OFF: %ld vertices and %ld faces: no triangles", shown,
                 nv, nf);
        goto fail;
    }
    out->v = malloc((size_t)nv * 3 * sizeof(double));
    long tcap = nf * 2 + 16;
    out->t = malloc((size_t)tcap * 3 * sizeof(int32_t));
    if (!out->v || !out->t)
        goto nomem;
    /* the vertices: a line each, from the line after the counts' */
    const int ncoord = homogeneous ? 4 : 3;
    for (long i = 0; i < nv; i++) {
        if (!off_line(&r, &lb, &le)) {
            snprintf(err, errlen, "mesh '%s': OFF: the header claims %ld vertices, the file ends "
                     "after %ld", shown, nv, i);
            goto fail;
        }
        double x[4];
        for (int c = 0; c < ncoord; c++) {
            if (!(we = off_word(&lb, le)) || off_number(lb, we, &x[c]) != 0) {
                snprintf(err, errlen, "mesh '%s': OFF: line %d: vertex %ld needs %d numbers",
                         shown, r.line, i, ncoord);
                goto fail;
            }
            lb = we;
        }
        for (int c = 0; c < 3; c++) {
            const double v = homogeneous ? x[c] / x[3] : x[c];
            if (!isfinite(v)) {
                snprintf(err, errlen, "mesh '%s': OFF: line %d: vertex %ld is not finite", shown,
                         r.line, i);
                goto fail;
            }
            out->v[3 * i + c] = v;
        }
    }
    /* the faces: a line each; corners past 3 cut by triangulate_face, 1 or 2 corners (points,
     * lines) have no area and are skipped */
    long nt = 0, kcap = 0, budget = 100000000;
    for (long fi = 0; fi < nf; fi++) {
        if (!off_line(&r, &lb, &le)) {
            snprintf(err, errlen, "mesh '%s': OFF: the header claims %ld faces, the file ends "
                     "after %ld", shown, nf, fi);
            goto fail;
        }
        long k;
        if (!(we = off_word(&lb, le)) || off_count(lb, we, &k) != 0) {
            snprintf(err, errlen, "mesh '%s': OFF: line %d: face %ld does not start with its "
                     "corner count", shown, r.line, fi);
            goto fail;
        }
        lb = we;
        if (k > (le - lb) / 2 + 1) {
            snprintf(err, errlen, "mesh '%s': OFF: line %d: face %ld claims %ld corners, more "
                     "than its line holds", shown, r.line, fi, k);
            goto fail;
        }
        if (k > kcap) {
            kcap = k;
            free(poly);
            free(rest);
            poly = malloc((size_t)kcap * sizeof *poly);
            rest = malloc((size_t)kcap * sizeof *rest);
            if (!poly || !rest)
                goto nomem;
        }
        for (long c = 0; c < k; c++) {
            long idx;
            if (!(we = off_word(&lb, le)) || off_count(lb, we, &idx) != 0) {
                snprintf(err, errlen, "mesh '%s': OFF: line %d: face %ld needs %ld vertex "
                         "indices", shown, r.line, fi, k);
                goto fail;
            }
            if (idx >= nv) {
                snprintf(err, errlen, "mesh '%s': OFF: line %d: face %ld has vertex index %ld, "
                         "past the %ld vertices", shown, r.line, fi, idx, nv);
                goto fail;
            }
            lb = we;
            poly[c] = (int32_t)idx;
        }
        if (k < 3)
            continue;
        if (nt + k - 2 > INT32_MAX / 3) {
            snprintf(err, errlen, "mesh '%s': OFF: too many triangles", shown);
            goto fail;
        }
        if (nt + k - 2 > tcap) {
            tcap = 2 * tcap + k; /* below 2^32 by the check above */
            int32_t *t = realloc(out->t, (size_t)tcap * 3 * sizeof *t);
            if (!t)
                goto nomem;
            out->t = t;
        }
        nt += face_triangles(out->v, poly, (int)k, out->t + 3 * nt, rest, &budget);
    }
    free(text);
    free(poly);
    free(rest);
    out->nv = (int)nv;
    out->nt = (int)nt;
    return 0;
short_header:
    snprintf(err, errlen, "mesh '%s': OFF: the header ends before its vertex and face counts",
             shown);
    goto fail;
nomem:
    snprintf(err, errlen, "mesh '%s': out of memory", shown);
fail:
    free(text);
    free(poly);
    free(rest);
    cs_mesh_free(out);
    return -1;
}

/* Does path end in ".off" (any case)? */
static int is_off_path(const char *path)
{
    const size_t n = strlen(path);
    return n >= 4 && !strcasecmp(path + n - 4, ".off");
}

/* Weld and clean a loaded triangle list (weld_and_clean); 0, or -1 with out freed. */
static int finish_mesh(cs_mesh *out, const char *shown, char *err, size_t errlen)
{
    if (weld_and_clean(out) != 0) {
        cs_mesh_free(out);
        snprintf(err, errlen, "mesh '%s': out of memory", shown);
        return -1;
    }
    if (out->nt == 0) {
        cs_mesh_free(out);
        snprintf(err, errlen, "mesh '%s': no triangles (all degenerate)", shown);
        return -1;
    }
    return 0;
}

/* The import itself (in the child process of cs_mesh_load). */
static int load_direct(const char *path, cs_mesh *out, char *err, size_t errlen)
{
    char shown[CS_MSG_PATH + 1]; /* path as messages show it */
    cs_msg_path(path, shown, sizeof shown);
    memset(out, 0, sizeof *out);
    struct stat st;
    if (stat(path, &st) != 0) {
        if (errno == ENOENT)
            snprintf(err, errlen, "mesh '%s': no such file", shown);
        else
            snprintf(err, errlen, "mesh '%s': %s", shown, strerror(errno));
        return -1;
    }
    if (!S_ISREG(st.st_mode)) {
        snprintf(err, errlen, "mesh '%s': not a regular file", shown);
        return -1;
    }
    if (st.st_size == 0) {
        snprintf(err, errlen, "mesh '%s': empty file", shown);
        return -1;
    }
    if (is_off_path(path)) {
        if (load_off(path, shown, st.st_size, out, err, errlen) != 0)
            return -1;
        return finish_mesh(out, shown, err, errlen);
    }
    const struct aiScene *sc =
        aiImportFile(path, aiProcess_PreTransformVertices | aiProcess_SortByPType |
                               aiProcess_ValidateDataStructure);
    if (!sc) {
        const char *why = aiGetErrorString();
        snprintf(err, errlen, "mesh '%s': assimp: %s", shown, why && *why ? why : "unreadable");
        /* assimp messages may end in a newline; keep the message one line */
        for (char *p = err; *p; p++)
            if (*p == '\n' || *p == '\r')
                *p = ' ';
        return -1;
    }
    /* faces of 3 or more corners (polygons triangulated here: triangulate_face) */
    const unsigned faces = aiPrimitiveType_TRIANGLE | aiPrimitiveType_POLYGON;
    size_t nv = 0, nt = 0, kmax = 0;
    for (unsigned i = 0; i < sc->mNumMeshes; i++) {
        const struct aiMesh *am = sc->mMeshes[i];
        if (!(am->mPrimitiveTypes & faces))
            continue;
        nv += am->mNumVertices;
        for (unsigned f = 0; f < am->mNumFaces; f++) {
            const size_t k = am->mFaces[f].mNumIndices;
            nt += k >= 3 ? k - 2 : 0;
            kmax = k > kmax ? k : kmax;
        }
    }
    if (nt == 0) {
        aiReleaseImport(sc);
        snprintf(err, errlen, "mesh '%s': no triangles", shown);
        return -1;
    }
    if (nv > INT32_MAX / 3 || nt > INT32_MAX / 3) {
        aiReleaseImport(sc);
        snprintf(err, errlen, "mesh '%s': too large (%zu vertices, %zu triangles)", shown, nv, nt);
        return -1;
    }
    out->v = malloc(nv * 3 * sizeof(double));
    out->t = malloc(nt * 3 * sizeof(int32_t));
    int *rest = malloc((kmax + 1) * sizeof *rest);
    int32_t *poly = malloc((kmax + 1) * sizeof *poly);
    if (!out->v || !out->t || !rest || !poly) {
        aiReleaseImport(sc);
        free(rest);
        free(poly);
        cs_mesh_free(out);
        snprintf(err, errlen, "mesh '%s': out of memory", shown);
        return -1;
    }
    int vbase = 0, tcount = 0;
    long budget = 100000000; /* triangulate_face's corner tests for the file: about 0.5 s */
    for (unsigned i = 0; i < sc->mNumMeshes; i++) {
        const struct aiMesh *am = sc->mMeshes[i];
        if (!(am->mPrimitiveTypes & faces))
            continue;
        for (unsigned k = 0; k < am->mNumVertices; k++) {
            double x = am->mVertices[k].x, y = am->mVertices[k].y, z = am->mVertices[k].z;
            if (!isfinite(x) || !isfinite(y) || !isfinite(z)) {
                /* assimp's numbering (after its own processing), not the file's lines; it
                 * reads floats, so a coordinate past 3.4e38 arrives as inf */
                snprintf(err, errlen, "mesh '%s': a vertex is not finite (NaN, inf, or beyond "
                         "float's 3.4e38; assimp's vertex %u of its mesh %u)", shown, k, i);
                goto fail;
            }
            out->v[3 * (vbase + (int)k)] = x;
            out->v[3 * (vbase + (int)k) + 1] = y;
            out->v[3 * (vbase + (int)k) + 2] = z;
        }
        for (unsigned f = 0; f < am->mNumFaces; f++) {
            const struct aiFace *fc = &am->mFaces[f];
            const int k = (int)fc->mNumIndices;
            if (k < 3)
                continue;
            for (int c = 0; c < k; c++) {
                if (fc->mIndices[c] >= am->mNumVertices) {
                    snprintf(err, errlen, "mesh '%s': face %u of mesh %u has a bad index", shown,
                             f, i);
                    goto fail;
                }
                poly[c] = vbase + (int32_t)fc->mIndices[c];
            }
            tcount += face_triangles(out->v, poly, k, out->t + 3 * (size_t)tcount, rest,
                                     &budget);
        }
        vbase += (int)am->mNumVertices;
    }
    free(rest);
    free(poly);
    aiReleaseImport(sc);
    out->nv = vbase;
    out->nt = tcount;
    return finish_mesh(out, shown, err, errlen);
fail:
    aiReleaseImport(sc);
    free(rest);
    free(poly);
    cs_mesh_free(out);
    return -1;
}

/* ---------------------------------------------------------------- the guarded import */

/* Importers are large parsers of untrusted files: a crafted header can make one allocate
 * terabytes (assimp's own test file invalid/OutOfMemory.off claims 353 535 235 358 vertices)
 * or crash. cs_mesh_load therefore runs the import in a child process under a memory cap and
 * a time limit and takes the result through a pipe; whatever the child does, the caller gets
 * a mesh or a one-line error. */
#define IMPORT_SECONDS 120

static int write_all(int fd, const void *buf, size_t n)
{
    const char *p = buf;
    while (n > 0) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

/* Read n bytes before the deadline (CLOCK_MONOTONIC seconds); 0, or -1 (EOF, error), -2 (late). */
static int read_all(int fd, void *buf, size_t n, double deadline)
{
    char *p = buf;
    while (n > 0) {
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        double left = deadline - (ts.tv_sec + 1e-9 * ts.tv_nsec);
        if (left <= 0)
            return -2;
        struct pollfd pf = {fd, POLLIN, 0};
        int r = poll(&pf, 1, (int)(left * 1000) + 1);
        if (r < 0 && errno == EINTR)
            continue;
        if (r < 0)
            return -1;
        if (r == 0)
            continue;
        ssize_t got = read(fd, p, n);
        if (got < 0 && errno == EINTR)
            continue;
        if (got <= 0)
            return -1;
        p += got;
        n -= (size_t)got;
    }
    return 0;
}

/* The child: cap the address space at what the process has mapped now plus half the machine's
 * RAM (what it has now counts: under AddressSanitizer that is terabytes of reserved shadow),
 * import, send {status, nv, nt, v, t} or {status, message}. */
static void import_child(const char *path, int fd)
{
    long page = sysconf(_SC_PAGESIZE), phys = sysconf(_SC_PHYS_PAGES);
    unsigned long now_pages = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    if (f) {
        if (fscanf(f, "%lu", &now_pages) != 1)
            now_pages = 0;
        fclose(f);
    }
    if (page > 0 && phys > 0) {
        rlim_t cap = (rlim_t)now_pages * (rlim_t)page + (rlim_t)phys * (rlim_t)page / 2;
        struct rlimit rl = {cap, cap};
        setrlimit(RLIMIT_AS, &rl);
    }
    char err[1024] = "";
    cs_mesh m;
    int32_t hdr[3] = {0, 0, 0};
    if (load_direct(path, &m, err, sizeof err) != 0) {
        hdr[0] = -1;
        hdr[1] = (int32_t)strlen(err);
        if (write_all(fd, hdr, sizeof hdr) == 0)
            (void)write_all(fd, err, (size_t)hdr[1]);
        return;
    }
    hdr[1] = m.nv;
    hdr[2] = m.nt;
    if (write_all(fd, hdr, sizeof hdr) == 0 &&
        write_all(fd, m.v, (size_t)m.nv * 3 * sizeof *m.v) == 0)
        (void)write_all(fd, m.t, (size_t)m.nt * 3 * sizeof *m.t);
    cs_mesh_free(&m);
}

int cs_mesh_load(const char *path, cs_mesh *out, char *err, size_t errlen)
{
    char shown[CS_MSG_PATH + 1]; /* path as messages show it */
    cs_msg_path(path, shown, sizeof shown);
    memset(out, 0, sizeof *out);
    int fds[2];
    if (pipe(fds) != 0) {
        snprintf(err, errlen, "mesh '%s': cannot start the importer: %s", shown, strerror(errno));
        return -1;
    }
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0) {
        close(fds[0]);
        close(fds[1]);
        snprintf(err, errlen, "mesh '%s': cannot start the importer: %s", shown, strerror(errno));
        return -1;
    }
    if (pid == 0) {
        close(fds[0]);
        signal(SIGPIPE, SIG_DFL);
        alarm(IMPORT_SECONDS + 5);
        import_child(path, fds[1]);
        close(fds[1]);
        _exit(0);
    }
    close(fds[1]);
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    const double deadline = ts.tv_sec + 1e-9 * ts.tv_nsec + IMPORT_SECONDS;
    int32_t hdr[3];
    int rc = read_all(fds[0], hdr, sizeof hdr, deadline);
    if (rc == 0 && hdr[0] != 0) {
        char msg[1024];
        int n = hdr[1] >= 0 && hdr[1] < (int32_t)sizeof msg ? hdr[1] : 0;
        rc = read_all(fds[0], msg, (size_t)n, deadline);
        msg[rc == 0 ? n : 0] = '\0';
        snprintf(err, errlen, "%s", rc == 0 && n ? msg : "mesh: the importer failed");
        rc = 1; /* reported */
    } else if (rc == 0) {
        if (hdr[1] < 0 || hdr[2] <= 0 || hdr[1] > INT32_MAX / 3 || hdr[2] > INT32_MAX / 3)
            rc = -1;
        else {
            out->v = malloc((size_t)hdr[1] * 3 * sizeof *out->v + 1);
            out->t = malloc((size_t)hdr[2] * 3 * sizeof *out->t);
            if (!out->v || !out->t) {
                cs_mesh_free(out);
                snprintf(err, errlen, "mesh '%s': out of memory", shown);
                rc = 1;
            } else {
                out->nv = hdr[1];
                out->nt = hdr[2];
                rc = read_all(fds[0], out->v, (size_t)out->nv * 3 * sizeof *out->v, deadline);
                if (rc == 0)
                    rc = read_all(fds[0], out->t, (size_t)out->nt * 3 * sizeof *out->t,
                                  deadline);
            }
        }
    }
    close(fds[0]);
    if (rc == -2)
        kill(pid, SIGKILL);
    int status = 0;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR)
        ;
    if (rc == 0)
        return 0;
    cs_mesh_free(out);
    if (rc == -2)
        snprintf(err, errlen, "mesh '%s': the importer took longer than %d s and was stopped",
                 shown, IMPORT_SECONDS);
    else if (rc == -1 && WIFSIGNALED(status))
        snprintf(err, errlen, "mesh '%s': the importer died (%s) reading this file", shown,
                 strsignal(WTERMSIG(status)));
    else if (rc == -1)
        snprintf(err, errlen, "mesh '%s': the importer ended without a result", shown);
    return -1;
}

void cs_mesh_transform(cs_mesh *m, double scale, const double rotation_deg[3],
                       const double position[3])
{
    const double d2r = 3.14159265358979323846 / 180.0;
    double cx = 1, sx = 0, cy = 1, sy = 0, cz = 1, sz = 0;
    if (rotation_deg) {
        cx = cos(rotation_deg[0] * d2r), sx = sin(rotation_deg[0] * d2r);
        cy = cos(rotation_deg[1] * d2r), sy = sin(rotation_deg[1] * d2r);
        cz = cos(rotation_deg[2] * d2r), sz = sin(rotation_deg[2] * d2r);
    }
    /* R = Rz * Ry * Rx: rotate about x first, then y, then z (fixed axes). */
    const double r[3][3] = {
        {cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx},
        {sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx},
        {-sy, cy * sx, cy * cx},
    };
    for (int i = 0; i < m->nv; i++) {
        double *p = m->v + 3 * i;
        double q[3] = {scale * p[0], scale * p[1], scale * p[2]};
        for (int k = 0; k < 3; k++)
            p[k] = r[k][0] * q[0] + r[k][1] * q[1] + r[k][2] * q[2] +
                   (position ? position[k] : 0.0);
    }
}

/* Does assimp have an exporter with this id? */
static int have_exporter(const char *want)
{
    int found = 0;
    for (size_t k = 0; k < aiGetExportFormatCount() && !found; k++) {
        const struct aiExportFormatDesc *d = aiGetExportFormatDescription(k);
        if (!d)
            continue;
        found = d->id && !strcmp(d->id, want);
        aiReleaseExportFormatDescription(d); /* frees the strings too: copy before */
    }
    return found;
}

/* Exporter id for a file name, from its extension, copied into id (0), or -1 if none. */
static int format_for(const char *path, char *id, size_t idlen)
{
    const char *dot = strrchr(path, '.');
    const char *slash = strrchr(path, '/');
    if (!dot || (slash && dot < slash) || !dot[1])
        return -1;
    const char *ext = dot + 1;
    /* Where several exporters share an extension, pick the one a user expects: OBJ without a
     * side .mtl file, binary STL, glTF 2. */
    static const char *const prefer[][2] = {
        {"obj", "objnomtl"}, {"stl", "stlb"}, {"gltf", "gltf2"}, {"glb", "glb2"},
    };
    for (size_t i = 0; i < sizeof prefer / sizeof prefer[0]; i++)
        if (!strcasecmp(ext, prefer[i][0]) && have_exporter(prefer[i][1])) {
            snprintf(id, idlen, "%s", prefer[i][1]);
            return 0;
        }
    int found = 0;
    for (size_t k = 0; k < aiGetExportFormatCount() && !found; k++) {
        const struct aiExportFormatDesc *d = aiGetExportFormatDescription(k);
        if (!d)
            continue;
        if (d->id && d->fileExtension && !strcasecmp(d->fileExtension, ext)) {
            snprintf(id, idlen, "%s", d->id);
            found = 1;
        }
        aiReleaseExportFormatDescription(d);
    }
    return found ? 0 : -1;
}

static void set_name(struct aiString *s, const char *name)
{
    size_t n = strlen(name);
    if (n >= MAXLEN)
        n = MAXLEN - 1;
    memcpy(s->data, name, n);
    s->data[n] = '\0';
    s->length = (ai_uint32)n;
}

static void free_scene(struct aiScene *sc)
{
    if (!sc)
        return;
    if (sc->mMeshes) {
        for (unsigned i = 0; i < sc->mNumMeshes; i++) {
            struct aiMesh *am = sc->mMeshes[i];
            if (!am)
                continue;
            if (am->mFaces)
                for (unsigned f = 0; f < am->mNumFaces; f++)
                    free(am->mFaces[f].mIndices);
            free(am->mFaces);
            free(am->mVertices);
            free(am->mNormals);
            free(am);
        }
        free(sc->mMeshes);
    }
    if (sc->mMaterials) {
        for (unsigned i = 0; i < sc->mNumMaterials; i++)
            free(sc->mMaterials[i]);
        free(sc->mMaterials);
    }
    struct aiNode *root = sc->mRootNode;
    if (root) {
        if (root->mChildren) {
            for (unsigned i = 0; i < root->mNumChildren; i++) {
                if (!root->mChildren[i])
                    continue;
                free(root->mChildren[i]->mMeshes);
                free(root->mChildren[i]);
            }
            free(root->mChildren);
        }
        free(root);
    }
    free(sc);
}

/* Exporters that write normals and make their own when a mesh has none (see the top). */
static int writes_normals(const char *fmt)
{
    return !strcmp(fmt, "obj") || !strcmp(fmt, "objnomtl") || !strcmp(fmt, "stl") ||
           !strcmp(fmt, "stlb");
}

/* The unit normal of triangle f of pc (counter-clockwise seen from its front), or 0 if it has
 * no area. */
static struct aiVector3D face_normal(const cs_mesh *pc, int f)
{
    const double *a = pc->v + 3 * (size_t)pc->t[3 * f], *b = pc->v + 3 * (size_t)pc->t[3 * f + 1],
                 *c = pc->v + 3 * (size_t)pc->t[3 * f + 2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]},
                 w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                   u[0] * w[1] - u[1] * w[0]};
    const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    struct aiVector3D r = {0, 0, 0};
    if (len > 0 && isfinite(len)) {
        r.x = (ai_real)(n[0] / len);
        r.y = (ai_real)(n[1] / len);
        r.z = (ai_real)(n[2] / len);
    }
    return r;
}

static void identity(struct aiMatrix4x4 *m)
{
    memset(m, 0, sizeof *m);
    m->a1 = m->b2 = m->c3 = m->d4 = 1;
}

int cs_mesh_export_format(const char *path)
{
    char fmt[64];
    return path && format_for(path, fmt, sizeof fmt) == 0 ? 0 : -1;
}

int cs_mesh_export(const char *path, const cs_mesh *pieces, const char *const *names, int n,
                   char *err, size_t errlen)
{
    char shown[CS_MSG_PATH + 1]; /* path as messages show it */
    cs_msg_path(path, shown, sizeof shown);
    if (n <= 0) {
        snprintf(err, errlen, "export '%s': nothing to write", shown);
        return -1;
    }
    char fmt[64];
    if (format_for(path, fmt, sizeof fmt) != 0) {
        const char *dot = strrchr(shown, '.');
        snprintf(err, errlen, "export '%s': no assimp exporter for extension '%s'", shown,
                 dot ? dot : "(none)");
        return -1;
    }
    const int flat = writes_normals(fmt);
    for (int p = 0; p < n; p++) {
        if (pieces[p].nv > INT32_MAX / 3 || pieces[p].nt > INT32_MAX / 3) {
            snprintf(err, errlen, "export '%s': piece %d is too large", shown, p);
            return -1;
        }
        for (int k = 0; k < 3 * pieces[p].nv; k++)
            if (!isfinite(pieces[p].v[k])) {
                snprintf(err, errlen, "export '%s': piece %d has a non-finite vertex", shown, p);
                return -1;
            }
        for (int k = 0; k < 3 * pieces[p].nt; k++)
            if (pieces[p].t[k] < 0 || pieces[p].t[k] >= pieces[p].nv) {
                snprintf(err, errlen, "export '%s': piece %d has a bad vertex index", shown, p);
                return -1;
            }
    }
    struct aiScene *sc = calloc(1, sizeof *sc);
    if (!sc)
        goto oom;
    sc->mMeshes = calloc((size_t)n, sizeof *sc->mMeshes);
    sc->mMaterials = calloc(1, sizeof *sc->mMaterials);
    sc->mRootNode = calloc(1, sizeof *sc->mRootNode);
    if (!sc->mMeshes || !sc->mMaterials || !sc->mRootNode)
        goto oom;
    sc->mNumMeshes = (unsigned)n;
    sc->mMaterials[0] = calloc(1, sizeof *sc->mMaterials[0]);
    if (!sc->mMaterials[0])
        goto oom;
    sc->mNumMaterials = 1;
    struct aiNode *root = sc->mRootNode;
    set_name(&root->mName, "cubesim");
    identity(&root->mTransformation);
    root->mChildren = calloc((size_t)n, sizeof *root->mChildren);
    if (!root->mChildren)
        goto oom;
    root->mNumChildren = (unsigned)n;
    for (int p = 0; p < n; p++) {
        const cs_mesh *pc = &pieces[p];
        char fallback[32];
        snprintf(fallback, sizeof fallback, "piece%d", p);
        const char *name = names && names[p] && names[p][0] ? names[p] : fallback;
        struct aiMesh *am = calloc(1, sizeof *am);
        sc->mMeshes[p] = am;
        if (!am)
            goto oom;
        am->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
        am->mMaterialIndex = 0;
        set_name(&am->mName, name);
        /* flat: three corners of its own per triangle, carrying its normal */
        const size_t nverts = flat ? 3 * (size_t)pc->nt : (size_t)pc->nv;
        am->mVertices = calloc(nverts ? nverts : 1, sizeof *am->mVertices);
        am->mNormals = flat ? calloc(nverts ? nverts : 1, sizeof *am->mNormals) : NULL;
        am->mFaces = calloc((size_t)(pc->nt ? pc->nt : 1), sizeof *am->mFaces);
        if (!am->mVertices || !am->mFaces || (flat && !am->mNormals))
            goto oom;
        am->mNumVertices = (unsigned)nverts;
        for (size_t i = 0; !flat && i < nverts; i++) {
            am->mVertices[i].x = (ai_real)pc->v[3 * i];
            am->mVertices[i].y = (ai_real)pc->v[3 * i + 1];
            am->mVertices[i].z = (ai_real)pc->v[3 * i + 2];
        }
        am->mNumFaces = (unsigned)pc->nt;
        for (int f = 0; f < pc->nt; f++) {
            am->mFaces[f].mIndices = malloc(3 * sizeof(unsigned));
            if (!am->mFaces[f].mIndices)
                goto oom;
            am->mFaces[f].mNumIndices = 3;
            const struct aiVector3D nrm = flat ? face_normal(pc, f) : (struct aiVector3D){0, 0, 0};
            for (int c = 0; c < 3; c++) {
                const int32_t v = pc->t[3 * f + c];
                if (!flat) {
                    am->mFaces[f].mIndices[c] = (unsigned)v;
                    continue;
                }
                const size_t corner = 3 * (size_t)f + (size_t)c;
                am->mVertices[corner].x = (ai_real)pc->v[3 * (size_t)v];
                am->mVertices[corner].y = (ai_real)pc->v[3 * (size_t)v + 1];
                am->mVertices[corner].z = (ai_real)pc->v[3 * (size_t)v + 2];
                am->mNormals[corner] = nrm;
                am->mFaces[f].mIndices[c] = (unsigned)corner;
            }
        }
        struct aiNode *node = calloc(1, sizeof *node);
        root->mChildren[p] = node;
        if (!node)
            goto oom;
        set_name(&node->mName, name);
        identity(&node->mTransformation);
        node->mParent = root;
        node->mMeshes = malloc(sizeof(unsigned));
        if (!node->mMeshes)
            goto oom;
        node->mMeshes[0] = (unsigned)p;
        node->mNumMeshes = 1;
    }
    aiReturn rc = aiExportScene(sc, fmt, path, 0);
    free_scene(sc);
    if (rc != aiReturn_SUCCESS) {
        const char *why = aiGetErrorString();
        snprintf(err, errlen, "export '%s': assimp (%s): %s", shown, fmt,
                 why && *why ? why : "failed");
        for (char *q = err; *q; q++)
            if (*q == '\n' || *q == '\r')
                *q = ' ';
        return -1;
    }
    return 0;
oom:
    free_scene(sc);
    snprintf(err, errlen, "export '%s': out of memory", shown);
    return -1;
}
