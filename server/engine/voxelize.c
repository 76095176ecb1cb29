/*
 * voxelize.c — seed 000 §3.3 surface preprocessing (edge subdivision) and §2.1 mesh generation
 * (which cubes of the bounding-box lattice to keep). Implements voxelize.h.
 *
 * Subdivision follows §3.3 literally: a lexicographically sorted list of triples (v1, v2, t),
 * v1 > v2, one per edge of each triangle, traversed once. A long edge gets its midpoint as a new
 * vertex v3 (the largest index so far), every triangle on it is split in two, the new edges
 * (which all contain v3) are appended in sorted order — the list stays sorted — and the
 * untouched edges that changed owner are found by binary search. Edges before the cursor are
 * all short, so when the cursor reaches the end no edge is longer than max_len.
 *
 * Voxelization, and the rule for surfaces lying on cell boundaries: a triangle "overlaps" a
 * cell only if it meets the cell shrunk by tol = cs_voxel_tolerance() on every side (exact
 * separating-axis test; tol is ~1e-6·h for float32 input, at least 1e-9·h). So a face lying exactly on a lattice plane marks no cell, and a lattice-aligned box of
 * 4h gives exactly 4×4×4 cells. Inside cells are found by flood-filling the outside from a
 * one-cell padded border through the 6-neighbour faces; a face is closed to the flood if a
 * triangle lies within tol of it (a flat box test), which is how surfaces lying on
 * lattice planes still wall the inside off. What the flood did not reach falls into connected
 * components (joined through the same open faces), and each is classified by the winding
 * number of the surface about its first cell's centre (seed_windings: signed crossings of a
 * ray, exact and consistent on edges and vertices): a component the surface does not wind
 * around (0) is a cavity — the inside of a closed inner shell wound inward — and is emptied
 * like the outside. So a hollow body keeps its cavity empty, a solid inside the cavity
 * (winding 1 again) is kept, and overlapping outward parts (2) stay solid. A closed surface
 * that is not an oriented cycle (triangles of a shell wound both ways) has no winding
 * number; the parity of the crossings decides for it. Kept = overlapped cells + the unreached
 * components the surface winds around. Every surface point then lies in a kept cell up to tol
 * (across a triangle the winding number changes, so one side of a wall on a lattice plane is
 * kept).
 */
#include "voxelize.h"

#include "cubesim.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>


#define CS_VOX_MAX_CELLS 2e7
#define CS_VOX_MAX_KEPT CS_MAX_SCENE_CUBES /* cubes a mesh may fill */
#define CS_SUBDIV_MAX_TRIS 50000000

/* ---------------------------------------------------------------- subdivision (§3.3) */

typedef struct {
    int32_t a, b, t; /* a > b */
} triple;

static int cmp_i64(const void *pa, const void *pb)
{
    int64_t a = *(const int64_t *)pa, b = *(const int64_t *)pb;
    return (a > b) - (a < b);
}

static int cmp_u64(const void *pa, const void *pb)
{
    uint64_t a = *(const uint64_t *)pa, b = *(const uint64_t *)pb;
    return (a > b) - (a < b);
}

static int cmp_triple(const void *pa, const void *pb)
{
    const triple *x = pa, *y = pb;
    if (x->a != y->a)
        return x->a < y->a ? -1 : 1;
    if (x->b != y->b)
        return x->b < y->b ? -1 : 1;
    return (x->t > y->t) - (x->t < y->t);
}

static triple mk_triple(int32_t p, int32_t q, int32_t t)
{
    return p > q ? (triple){p, q, t} : (triple){q, p, t};
}

/* First index of (a,b) in the sorted prefix [0,n), or -1. */
static int find_edge(const triple *L, int n, int32_t a, int32_t b)
{
    int lo = 0, hi = n;
    while (lo < hi) {
        int mid = lo + (hi - lo) / 2;
        if (L[mid].a < a || (L[mid].a == a && L[mid].b < b))
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < n && L[lo].a == a && L[lo].b == b ? lo : -1;
}

static int grow(void **p, int *cap, int need, size_t elem)
{
    if (need <= *cap)
        return 0;
    int c = *cap ? *cap : 64;
    while (c < need) {
        if (c > INT32_MAX / 2)
            return -1;
        c *= 2;
    }
    void *q = realloc(*p, (size_t)c * elem);
    if (!q)
        return -1;
    *p = q;
    *cap = c;
    return 0;
}

int cs_subdivide_edges(double **verts, int *nv, int32_t **tris, int *nt, double max_len,
                       char *err, size_t errlen)
{
    if (!(max_len > 0.0) || !isfinite(max_len)) {
        snprintf(err, errlen, "subdivision: edge length limit %g is not a positive number",
                 max_len);
        return -1;
    }
    double *v = *verts;
    int32_t *t = *tris;
    int n_v = *nv, n_t = *nt, cap_v = *nv, cap_t = *nt, n_l = 0, cap_l = 0;
    triple *L = NULL;
    triple *fresh = NULL;
    int cap_fresh = 0;
    int rc = -1;
    const double lim2 = max_len * max_len;

    for (int i = 0; i < 3 * n_t; i++)
        if (t[i] < 0 || t[i] >= n_v) {
            snprintf(err, errlen, "subdivision: triangle %d has a bad vertex index", i / 3);
            return -1;
        }
    if (grow((void **)&L, &cap_l, 3 * n_t + 16, sizeof *L) != 0)
        goto oom;
    for (int i = 0; i < n_t; i++)
        for (int k = 0; k < 3; k++) {
            int32_t p = t[3 * i + k], q = t[3 * i + (k + 1) % 3];
            if (p != q)
                L[n_l++] = mk_triple(p, q, i);
        }
    qsort(L, (size_t)n_l, sizeof *L, cmp_triple);

    for (int i = 0; i < n_l;) {
        int32_t a = L[i].a, b = L[i].b;
        int j = i + 1;
        while (j < n_l && L[j].a == a && L[j].b == b)
            j++;
        const double *pa = v + 3 * a, *pb = v + 3 * b;
        double d[3] = {pa[0] - pb[0], pa[1] - pb[1], pa[2] - pb[2]};
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= lim2) {
            i = j;
            continue;
        }
        int group = j - i;
        if (n_t + group > CS_SUBDIV_MAX_TRIS) {
            snprintf(err, errlen,
                     "subdivision: more than %d triangles needed for edges of at most %g",
                     CS_SUBDIV_MAX_TRIS, max_len);
            goto fail;
        }
        if (grow((void **)&v, &cap_v, n_v + 1, 3 * sizeof *v) != 0 ||
            grow((void **)&t, &cap_t, n_t + group, 3 * sizeof *t) != 0 ||
            grow((void **)&fresh, &cap_fresh, 4 * group, sizeof *fresh) != 0)
            goto oom;
        int32_t m = n_v++;
        for (int k = 0; k < 3; k++)
            v[3 * m + k] = 0.5 * (v[3 * a + k] + v[3 * b + k]);
        int nf = 0;
        for (int g = i; g < j; g++) {
            int32_t tk = L[g].t, tn = n_t++;
            int32_t *tri = t + 3 * tk;
            /* rotate so that the edge is tri[0] -> tri[1] in the triangle's own direction */
            int s = 0;
            while (s < 3 && !((tri[s] == a || tri[s] == b) &&
                              (tri[(s + 1) % 3] == a || tri[(s + 1) % 3] == b)))
                s++;
            if (s == 3) { /* cannot happen: the list always names the edge's triangles */
                snprintf(err, errlen, "subdivision: internal error (edge list out of date)");
                goto fail;
            }
            int32_t x = tri[s], y = tri[(s + 1) % 3], o = tri[(s + 2) % 3];
            tri[0] = x, tri[1] = m, tri[2] = o;                        /* t_k  = (x, m, o) */
            t[3 * tn] = m, t[3 * tn + 1] = y, t[3 * tn + 2] = o;       /* t_new = (m, y, o) */
            /* (y,o) now belongs to t_new: its entries are sorted by edge, not by t, so
             * search the edge and scan its short run */
            int32_t ya = y > o ? y : o, yb = y > o ? o : y;
            int e = find_edge(L, n_l, ya, yb);
            for (; e >= 0 && e < n_l && L[e].a == ya && L[e].b == yb; e++)
                if (L[e].t == tk) {
                    L[e].t = tn;
                    break;
                }
            fresh[nf++] = (triple){m, x, tk};
            fresh[nf++] = (triple){m, o, tk};
            fresh[nf++] = (triple){m, y, tn};
            fresh[nf++] = (triple){m, o, tn};
        }
        qsort(fresh, (size_t)nf, sizeof *fresh, cmp_triple);
        if (grow((void **)&L, &cap_l, n_l + nf, sizeof *L) != 0)
            goto oom;
        memcpy(L + n_l, fresh, (size_t)nf * sizeof *fresh); /* m is the largest index: sorted */
        n_l += nf;
        i = j; /* the split edge no longer exists */
    }
    rc = 0;
    goto done;
oom:
    snprintf(err, errlen, "subdivision: out of memory");
fail:
done:
    free(L);
    free(fresh);
    *verts = v;
    *tris = t;
    *nv = n_v;
    *nt = n_t;
    return rc;
}

/* ---------------------------------------------------------------- triangle/box SAT */

/* Is [min,max] of the projections disjoint from [-r, r]? */
static int separated(double p0, double p1, double p2, double r)
{
    double lo = p0, hi = p0;
    if (p1 < lo) lo = p1;
    if (p1 > hi) hi = p1;
    if (p2 < lo) lo = p2;
    if (p2 > hi) hi = p2;
    return lo > r || hi < -r;
}

int cs_tri_box_overlap(const double center[3], const double half[3], const double a[3],
                       const double b[3], const double c[3])
{
    double v[3][3];
    for (int k = 0; k < 3; k++) {
        v[0][k] = a[k] - center[k];
        v[1][k] = b[k] - center[k];
        v[2][k] = c[k] - center[k];
    }
    /* 3 box face normals */
    for (int k = 0; k < 3; k++)
        if (separated(v[0][k], v[1][k], v[2][k], half[k]))
            return 0;
    double e[3][3];
    for (int k = 0; k < 3; k++) {
        e[0][k] = v[1][k] - v[0][k];
        e[1][k] = v[2][k] - v[1][k];
        e[2][k] = v[0][k] - v[2][k];
    }
    /* 9 axes: box axis u_k × triangle edge e_i */
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) {
            int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
            /* axis = u_k × e_i: component k1 = -e[k2], component k2 = e[k1] */
            double ax[3] = {0, 0, 0};
            ax[k1] = -e[i][k2];
            ax[k2] = e[i][k1];
            double r = half[k1] * fabs(ax[k1]) + half[k2] * fabs(ax[k2]);
            double p[3];
            for (int q = 0; q < 3; q++)
                p[q] = ax[k1] * v[q][k1] + ax[k2] * v[q][k2];
            if (separated(p[0], p[1], p[2], r))
                return 0;
        }
    /* the triangle's plane */
    double n[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1], e[0][2] * e[1][0] - e[0][0] * e[1][2],
                   e[0][0] * e[1][1] - e[0][1] * e[1][0]};
    /* For a (nearly) collinear triangle the computed normal is rounding noise pointing
     * anywhere: skip this axis; the 12 above are then exact for the segment it is. */
    double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    double l0 = e[0][0] * e[0][0] + e[0][1] * e[0][1] + e[0][2] * e[0][2];
    double l1 = e[1][0] * e[1][0] + e[1][1] * e[1][1] + e[1][2] * e[1][2];
    if (!(nn > 1e-20 * l0 * l1))
        return 1;
    double r = half[0] * fabs(n[0]) + half[1] * fabs(n[1]) + half[2] * fabs(n[2]);
    double d = n[0] * v[0][0] + n[1] * v[0][1] + n[2] * v[0][2];
    if (fabs(d) > r)
        return 0;
    return 1;
}

/* ---------------------------------------------------------------- voxelization (§2.1) */

double cs_voxel_tolerance(double h, const double *verts, int nv)
{
    double m = 0.0;
    for (int i = 0; i < 3 * nv; i++)
        if (fabs(verts[i]) > m)
            m = fabs(verts[i]);
    double tol = m * 0x1p-20;
    if (!(tol >= 1e-9 * h))
        tol = 1e-9 * h;
    if (tol > 1e-4 * h)
        tol = 1e-4 * h;
    return tol;
}

/* How a triangle list closes, or -1 on out of memory: *odd counts the edges used by an odd
 * number of triangles (a closed surface, manifold or not, uses every edge an even number of
 * times), *unbalanced the edges not used as often in one direction as in the other (a closed
 * surface whose triangles are all wound the same way, outward or inward, has none: it is an
 * oriented cycle and has a winding number). Counted here rather than with common/watertight.c
 * so the engine library does not link against common. */
static int edge_census(const int32_t *tris, int nt, int *odd, int *unbalanced)
{
    /* (lo, hi) in the high bits, the direction in the lowest; indices are >= 0 (checked) */
    uint64_t *e = malloc((size_t)(nt ? nt : 1) * 3 * sizeof *e);
    if (!e)
        return -1;
    int ne = 0;
    for (int t = 0; t < nt; t++)
        for (int k = 0; k < 3; k++) {
            uint64_t a = (uint32_t)tris[3 * t + k], b = (uint32_t)tris[3 * t + (k + 1) % 3];
            if (a != b)
                e[ne++] = a < b ? a << 33 | b << 1 : b << 33 | a << 1 | 1;
        }
    qsort(e, (size_t)ne, sizeof *e, cmp_u64);
    *odd = *unbalanced = 0;
    for (int i = 0; i < ne;) {
        int j = i, up = 0;
        for (; j < ne && e[j] >> 1 == e[i] >> 1; j++)
            up += (int)(e[j] & 1);
        *odd += (j - i) % 2; /* odd use: a boundary modulo 2 (1, or a fin on 2) */
        *unbalanced += 2 * up != j - i;
        i = j;
    }
    free(e);
    return 0;
}

int cs_mesh_surface_check(const double *verts, int nv, const int32_t *tris, int nt, char *err,
                          size_t errlen)
{
    /* directed edges keyed (lo, hi) with the direction in the lowest bit */
    int64_t *e = malloc((size_t)(nt ? nt : 1) * 3 * sizeof *e);
    if (!e) {
        snprintf(err, errlen, "out of memory checking the mesh");
        return -1;
    }
    int ne = 0, repeated = 0;
    for (int t = 0; t < nt; t++) {
        const int32_t *tr = tris + 3 * (size_t)t;
        if (tr[0] == tr[1] || tr[1] == tr[2] || tr[0] == tr[2]) {
            repeated++;
            continue;
        }
        for (int k = 0; k < 3; k++) {
            int64_t a = tr[k], b = tr[(k + 1) % 3];
            e[ne++] = a < b ? (a << 33) | (b << 1) : (b << 33) | (a << 1) | 1;
        }
    }
    qsort(e, (size_t)ne, sizeof *e, cmp_i64);
    int open = 0, fins = 0, same = 0;
    for (int i = 0; i < ne;) {
        int j = i + 1;
        while (j < ne && e[j] >> 1 == e[i] >> 1)
            j++;
        if (j - i == 1)
            open++;
        else if (j - i > 2)
            fins++;
        else if ((e[i] & 1) == (e[i + 1] & 1))
            same++;
        i = j;
    }
    free(e);
    if (repeated) {
        snprintf(err, errlen, "mesh has %d triangles with a repeated vertex", repeated);
        return -1;
    }
    if (open) {
        snprintf(err, errlen, "mesh is not closed: %d boundary edges", open);
        return -1;
    }
    if (fins) {
        snprintf(err, errlen, "mesh is not manifold: %d edges shared by three or more triangles",
                 fins);
        return -1;
    }
    if (same) {
        snprintf(err, errlen, "mesh is not consistently oriented: %d edges used twice in the same "
                 "direction", same);
        return -1;
    }
    /* signed volume about the first vertex (divergence theorem) */
    double vol = 0;
    const double *o = verts;
    for (int t = 0; t < nt; t++) {
        const double *a = verts + 3 * (size_t)tris[3 * t], *b = verts + 3 * (size_t)tris[3 * t + 1],
                     *c = verts + 3 * (size_t)tris[3 * t + 2];
        const double u[3] = {a[0] - o[0], a[1] - o[1], a[2] - o[2]};
        const double v[3] = {b[0] - o[0], b[1] - o[1], b[2] - o[2]};
        const double w[3] = {c[0] - o[0], c[1] - o[1], c[2] - o[2]};
        vol += u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
               u[2] * (v[0] * w[1] - v[1] * w[0]);
    }
    vol /= 6.0;
    if (!(vol > 0.0)) {
        snprintf(err, errlen, "mesh is inside out: it encloses %.6g m^3 (its triangles must wind "
                 "counter-clockwise seen from outside)", vol);
        return -1;
    }
    (void)nv;
    return 0;
}

enum { F_SURF = 1, F_BLOCK_X = 2, F_BLOCK_Y = 4, F_BLOCK_Z = 8, F_OUT = 16, F_SEEN = 32 };

/* The padded cell grid of one voxelization: cell (i, j, k), each index in [-1, n], at
 * vg_at(G, i, j, k); the flood's work list grows on demand. */
typedef struct {
    uint8_t *g;
    int n[3];
    size_t px, py;
    size_t *stack;
    size_t cap;
} vgrid;

static size_t vg_at(const vgrid *G, int i, int j, int k)
{
    return ((size_t)(k + 1) * G->py + (size_t)(j + 1)) * G->px + (size_t)(i + 1);
}

/* Set mark on seed and on every cell reachable from it through faces no triangle closes
 * (F_BLOCK_*) into cells with none of the bits of stop (which holds mark): the cells that can
 * be joined without crossing the surface. 0, or -1 on out of memory. */
static int vg_flood(vgrid *G, size_t seed, uint8_t mark, uint8_t stop)
{
    static const int nb[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0},
                                 {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    size_t top = 0;
    G->g[seed] |= mark;
    G->stack[top++] = seed;
    while (top) {
        size_t s = G->stack[--top];
        int i = (int)(s % G->px) - 1, j = (int)((s / G->px) % G->py) - 1,
            k = (int)(s / (G->px * G->py)) - 1;
        for (int q = 0; q < 6; q++) {
            int a = i + nb[q][0], b = j + nb[q][1], c = k + nb[q][2];
            if (a < -1 || b < -1 || c < -1 || a > G->n[0] || b > G->n[1] || c > G->n[2])
                continue;
            size_t ns = vg_at(G, a, b, c);
            if (G->g[ns] & stop)
                continue;
            int ax = q / 2;
            size_t owner = (q % 2 == 0) ? s : ns; /* the lower of the two cells owns the face */
            if (G->g[owner] & (F_BLOCK_X << ax))
                continue;
            if (top == G->cap) {
                size_t *grown = realloc(G->stack, 2 * G->cap * sizeof *grown);
                if (!grown)
                    return -1;
                G->stack = grown;
                G->cap *= 2;
            }
            G->g[ns] |= mark;
            G->stack[top++] = ns;
        }
    }
    return 0;
}

/* One connected set of cells the outside flood did not reach (no triangle in them, none on
 * the faces joining them), named by its first cell in scan order (k, then j, then i). */
typedef struct {
    int i, j, k;
    size_t at;     /* its grid index */
    int winding;   /* signed crossings of the ray from its centre towards +x */
    int crossings; /* all crossings of that ray */
} vseed;

/* Orientation of p against the directed edge a->b in the (u, v) plane, exact (integers below
 * 2^29: products below 2^58), ties broken by simulation of simplicity with p moved to
 * p + (eps, eps^2): o(a,b,p') = o(a,b,p) - eps (b_v - a_v) + eps^2 (b_u - a_u). So it is
 * antisymmetric in a, b, never 0 unless a = b, and the signs of all edges are those of one
 * real point: every crossing of a closed surface by the ray is counted once. */
static int orient_sos(const int64_t *a, const int64_t *b, const int64_t *p, int64_t *o)
{
    *o = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
    if (*o)
        return *o > 0 ? 1 : -1;
    if (b[1] != a[1])
        return a[1] > b[1] ? 1 : -1;
    if (b[0] != a[0])
        return b[0] > a[0] ? 1 : -1;
    return 0;
}

/*
 * Winding number (signed crossings) and crossing count of the ray from each seed's cell centre
 * towards +x, over all triangles at once. The triangles' (y, z) are rounded to a lattice of
 * q = h / 2^S (cell centres lie on it) and the crossing tests run on those integers exactly;
 * x stays as it is. That moves the surface by at most q/sqrt(2) < h/2 - tol, and a seed's
 * centre is at least h/2 - tol from every triangle (its cell overlaps none), so neither the
 * winding number at the centre nor the side of the centre a crossing lies on can change.
 * seeds are sorted by (k, j) (scan order). -1 on out of memory.
 */
static int seed_windings(const double *verts, int nv, const int32_t *tris, int nt, double h,
                         const double origin[3], const int n[3], vseed *seeds, int ns)
{
    int nmax = n[1] > n[2] ? n[1] : n[2], S = 20;
    while (S > 1 && ((int64_t)nmax + 2) << S > (int64_t)1 << 29)
        S--;
    int64_t *qv = malloc((size_t)nv * 2 * sizeof *qv);
    if (!qv)
        return -1;
    const double scale = ldexp(1.0, S) / h;
    for (int v = 0; v < nv; v++)
        for (int a = 0; a < 2; a++)
            qv[2 * v + a] = llround((verts[3 * v + 1 + a] - origin[1 + a]) * scale);
    const int64_t half = (int64_t)1 << (S - 1); /* centre of row j: (2j + 1) half */
    for (int t = 0; t < nt; t++) {
        const int32_t *tr = tris + 3 * (size_t)t;
        const int64_t *A = qv + 2 * tr[0], *B = qv + 2 * tr[1], *C = qv + 2 * tr[2];
        int r0[2], r1[2];
        for (int a = 0; a < 2; a++) {
            int64_t lo = A[a], hi = A[a];
            lo = B[a] < lo ? B[a] : lo, hi = B[a] > hi ? B[a] : hi;
            lo = C[a] < lo ? C[a] : lo, hi = C[a] > hi ? C[a] : hi;
            /* rows whose centre (2r + 1) half lies in [lo, hi] */
            int64_t f = lo / half + (lo % half > 0); /* ceil(lo / half), lo >= 0 */
            r0[a] = (int)(f / 2);                      /* 2 r0 + 1 >= f */
            r1[a] = (int)((hi / half - 1) >= 0 ? (hi / half - 1) / 2 : -1);
            if (r0[a] < 0)
                r0[a] = 0;
            if (r1[a] > n[1 + a] - 1)
                r1[a] = n[1 + a] - 1;
        }
        if (r0[0] > r1[0] || r0[1] > r1[1])
            continue;
        const double xa = verts[3 * tr[0]] - origin[0], xb = verts[3 * tr[1]] - origin[0],
                     xc = verts[3 * tr[2]] - origin[0];
        for (int k = r0[1]; k <= r1[1]; k++)
            for (int j = r0[0]; j <= r1[0]; j++) {
                /* first seed of row (j, k) */
                int lo = 0, hi = ns;
                while (lo < hi) {
                    int mid = lo + (hi - lo) / 2;
                    if (seeds[mid].k < k || (seeds[mid].k == k && seeds[mid].j < j))
                        lo = mid + 1;
                    else
                        hi = mid;
                }
                if (lo == ns || seeds[lo].k != k || seeds[lo].j != j)
                    continue;
                const int64_t P[2] = {(2 * (int64_t)j + 1) * half, (2 * (int64_t)k + 1) * half};
                int64_t oab, obc, oca;
                int sab = orient_sos(A, B, P, &oab), sbc = orient_sos(B, C, P, &obc),
                    sca = orient_sos(C, A, P, &oca);
                if (sab == 0 || sab != sbc || sab != sca)
                    continue; /* the ray misses this triangle */
                /* where it crosses: barycentric weights of P, all of one sign, sum != 0 */
                const double wa = (double)obc, wb = (double)oca, wc = (double)oab;
                const double x = (wa * xa + wb * xb + wc * xc) / (wa + wb + wc);
                for (int s = lo; s < ns && seeds[s].k == k && seeds[s].j == j; s++)
                    if (x > (seeds[s].i + 0.5) * h) {
                        /* counter-clockwise in (y, z): the normal points towards +x */
                        seeds[s].winding += sab;
                        seeds[s].crossings++;
                    }
            }
    }
    free(qv);
    return 0;
}

int cs_voxelize(const double *verts, int nv, const int32_t *tris, int nt, double h,
                double origin[3], int32_t **ijk, int *n_cells, char *err, size_t errlen)
{
    *ijk = NULL;
    *n_cells = 0;
    if (!(h > 0.0) || !isfinite(h)) {
        snprintf(err, errlen, "voxelize: cube size h = %g is not a positive number", h);
        return -1;
    }
    if (nv <= 0 || nt <= 0) {
        snprintf(err, errlen, "voxelize: the mesh has no triangles");
        return -1;
    }
    for (int i = 0; i < 3 * nv; i++)
        if (!isfinite(verts[i])) {
            snprintf(err, errlen, "voxelize: vertex %d is not finite", i / 3);
            return -1;
        }
    for (int i = 0; i < 3 * nt; i++)
        if (tris[i] < 0 || tris[i] >= nv) {
            snprintf(err, errlen, "voxelize: triangle %d has a bad vertex index", i / 3);
            return -1;
        }
    int boundary = 0, unbalanced = 0;
    if (edge_census(tris, nt, &boundary, &unbalanced) != 0) {
        snprintf(err, errlen, "voxelize: out of memory");
        return -1;
    }
    if (boundary > 0) {
        snprintf(err, errlen, "mesh is not closed: %d boundary edges", boundary);
        return -1;
    }
    /* Non-manifold, misoriented or inside-out closed meshes are still well defined here (see
     * the winding rule below). Only an open surface is refused. */
    double lo[3], hi[3];
    for (int k = 0; k < 3; k++)
        lo[k] = hi[k] = verts[k];
    for (int i = 1; i < nv; i++)
        for (int k = 0; k < 3; k++) {
            if (verts[3 * i + k] < lo[k]) lo[k] = verts[3 * i + k];
            if (verts[3 * i + k] > hi[k]) hi[k] = verts[3 * i + k];
        }
    const double tol = cs_voxel_tolerance(h, verts, nv), tol_h = tol / h;
    int n[3];
    double total = 1.0;
    for (int k = 0; k < 3; k++) {
        double cells = ceil((hi[k] - lo[k]) / h - tol_h);
        if (cells < 1)
            cells = 1;
        total *= cells + 2;
        if (cells > 1e7 || total > CS_VOX_MAX_CELLS) {
            snprintf(err, errlen,
                     "voxelize: cube size h = %g m on a %.3g x %.3g x %.3g m mesh would need "
                     "more than %.0f cells (limit %.0f)",
                     h, hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], CS_VOX_MAX_CELLS,
                     CS_VOX_MAX_CELLS);
            return -1;
        }
        n[k] = (int)cells;
        origin[k] = lo[k];
    }
    /* padded grid: index (i+1, j+1, k+1) for cell (i,j,k), i in [-1, n] */
    const int px = n[0] + 2, py = n[1] + 2, pz = n[2] + 2;
    const size_t total_cells = (size_t)px * py * pz;
    uint8_t *g = calloc(total_cells, 1);
    if (!g) {
        snprintf(err, errlen, "voxelize: out of memory for %zu cells", total_cells);
        return -1;
    }
#define GI(i, j, k) (((size_t)((k) + 1) * py + (size_t)((j) + 1)) * px + (size_t)((i) + 1))
    const double shrink = 0.5 * h - tol;
    const double half_cell[3] = {shrink, shrink, shrink};
    for (int t = 0; t < nt; t++) {
        double p[3][3], tlo[3], thi[3];
        for (int c = 0; c < 3; c++)
            for (int k = 0; k < 3; k++)
                p[c][k] = verts[3 * tris[3 * t + c] + k] - origin[k];
        int r0[3], r1[3];
        for (int k = 0; k < 3; k++) {
            tlo[k] = fmin(p[0][k], fmin(p[1][k], p[2][k]));
            thi[k] = fmax(p[0][k], fmax(p[1][k], p[2][k]));
            r0[k] = (int)floor(tlo[k] / h - 2 * tol_h) - 1;
            r1[k] = (int)floor(thi[k] / h + 2 * tol_h) + 1;
            if (r0[k] < -1) r0[k] = -1;
            if (r1[k] > n[k]) r1[k] = n[k];
        }
        for (int k = r0[2]; k <= r1[2]; k++)
            for (int j = r0[1]; j <= r1[1]; j++)
                for (int i = r0[0]; i <= r1[0]; i++) {
                    double ctr[3] = {(i + 0.5) * h, (j + 0.5) * h, (k + 0.5) * h};
                    uint8_t *cell = &g[GI(i, j, k)];
                    if (!(*cell & F_SURF) && cs_tri_box_overlap(ctr, half_cell, p[0], p[1], p[2]))
                        *cell |= F_SURF;
                    /* the three faces on the + side of this cell, as flat boxes */
                    for (int ax = 0; ax < 3; ax++) {
                        uint8_t bit = (uint8_t)(F_BLOCK_X << ax);
                        if (*cell & bit)
                            continue;
                        if ((ax == 0 && i >= n[0]) || (ax == 1 && j >= n[1]) ||
                            (ax == 2 && k >= n[2]))
                            continue;
                        double fc[3] = {ctr[0], ctr[1], ctr[2]};
                        double fh[3] = {shrink, shrink, shrink};
                        fc[ax] += 0.5 * h;
                        fh[ax] = tol;
                        if (cs_tri_box_overlap(fc, fh, p[0], p[1], p[2]))
                            *cell |= bit;
                    }
                }
    }
    vgrid G = {g, {n[0], n[1], n[2]}, (size_t)px, (size_t)py, malloc(1024 * sizeof(size_t)),
               1024};
    vseed *seeds = NULL;
    int n_seeds = 0, cap_seeds = 0;
    if (!G.stack)
        goto oom;
    /* the outside: flooded from the padding corner through open faces of non-surface cells */
    if (vg_flood(&G, GI(-1, -1, -1), F_OUT, F_OUT | F_SURF) != 0)
        goto oom;
    /* What it did not reach falls into components (each flooded once, named by its first
     * cell); a component is solid if the surface winds around it, else a cavity. */
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                const size_t at = GI(i, j, k);
                if (g[at] & (F_OUT | F_SURF | F_SEEN))
                    continue;
                if (grow((void **)&seeds, &cap_seeds, n_seeds + 1, sizeof *seeds) != 0 ||
                    vg_flood(&G, at, F_SEEN, F_SEEN | F_OUT | F_SURF) != 0)
                    goto oom;
                seeds[n_seeds++] = (vseed){i, j, k, at, 0, 0};
            }
    if (n_seeds > 0) {
        if (seed_windings(verts, nv, tris, nt, h, origin, n, seeds, n_seeds) != 0)
            goto oom;
        for (int s = 0; s < n_seeds; s++) {
            /* an oriented surface: inside where its winding number is not 0 (nested shells,
             * overlapping parts, a whole mesh inside out); one whose triangles are not all
             * wound alike has only a parity */
            const int inside = unbalanced ? seeds[s].crossings % 2 : seeds[s].winding != 0;
            if (!inside && vg_flood(&G, seeds[s].at, F_OUT, F_OUT | F_SURF) != 0)
                goto oom;
        }
    }
    free(seeds);
    free(G.stack);
    int count = 0;
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++)
                count += !(g[GI(i, j, k)] & F_OUT);
    if (count > CS_VOX_MAX_KEPT) {
        free(g);
        snprintf(err, errlen,
                 "voxelize: cube size h = %g m fills the mesh with %d cubes; at most %d (about "
                 "7 GB in the daemon): choose a larger cube_size",
                 h, count, CS_VOX_MAX_KEPT);
        return -1;
    }
    int32_t *out = malloc((size_t)(count ? count : 1) * 3 * sizeof *out);
    if (!out) {
        free(g);
        snprintf(err, errlen, "voxelize: out of memory");
        return -1;
    }
    int m = 0;
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++)
                if (!(g[GI(i, j, k)] & F_OUT)) {
                    out[3 * m] = i, out[3 * m + 1] = j, out[3 * m + 2] = k;
                    m++;
                }
#undef GI
    free(g);
    if (count == 0) {
        free(out);
        double vlo[3] = {INFINITY, INFINITY, INFINITY}, vhi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (int i = 0; i < nv; i++)
            for (int a = 0; a < 3; a++) {
                vlo[a] = fmin(vlo[a], verts[3 * i + a]);
                vhi[a] = fmax(vhi[a], verts[3 * i + a]);
            }
        /* (a mesh far smaller than a cube: its triangles are below the exact test's
         * resolution there) */
        snprintf(err, errlen, "voxelize: no cube of %g m kept for a mesh of %.3g x %.3g x %.3g m: "
                 "choose a cube_size nearer its size (or scale it)", h, vhi[0] - vlo[0],
                 vhi[1] - vlo[1], vhi[2] - vlo[2]);
        return -1;
    }
    *ijk = out;
    *n_cells = count;
    return 0;
oom:
    free(seeds);
    free(G.stack);
    free(g);
    snprintf(err, errlen, "voxelize: out of memory");
    return -1;
}
