/*
 * closing.c — the closing surface of one exposed cube face (seed 000 §3.2). Implements
 * closing.h.
 *
 * Everything happens in a 2-d frame (x, y) on f chosen so that (x, y, n_f) is right-handed:
 * "positive sense about n_f" is then counter-clockwise, corner k of closing.h is corner k of
 * the frame's square, and a 2-d counter-clockwise triangle has its normal along n_f.
 *
 * Steps: (1) every candidate triangle with vertices on both sides of the plane gives a segment
 * between the crossing points of its two crossing edges, directed by Eq. (1); (2) the segment
 * is clipped to f's square: an end strictly inside is an edge node, a clipped end a boundary
 * node; (3) the two edge nodes made by one mesh edge are joined head → tail; (4) boundary
 * nodes and the corners that lie inside are walked counter-clockwise, each node without an
 * outgoing edge joined to the next; (5) cycles are extracted, nodes get surface vertices,
 * each triangle's two nodes are moved a third of the way towards each other, runs of one
 * vertex are merged; (6) positive cycles are outer polygons, negative ones holes (bridged into
 * the smallest outer polygon around them), and each is ear-cut.
 *
 * Degeneracies, by symbolic perturbation (closing.h): a vertex on the plane lies just on c2's
 * side, so a crossing point there is that vertex exactly, displaced by ε'·off towards the c1
 * end of its edge (off is kept: it is the geometry of a cycle that collapsed to one point; the
 * zero-length segment of a triangle whose lone vertex is on — or rounds onto — the plane is
 * directed by the limit of P2 - P1). The lattice lines through f's edges are moved by -ε
 * (ε' << ε), so f's square is [lo, hi) and neighbouring faces tile the plane; of the two
 * axes the smaller world axis's ε dominates, which decides clips through a corner; boundary
 * nodes at one position are ordered by where the moved line meets their segments. Crossing
 * points are computed from the edge's endpoints in index order, so the two triangles of an
 * edge agree bit for bit; inside-the-square is decided on the points themselves, never on
 * rounded clip parameters.
 *
 * Where the §3.2 heuristics leave freedom we take the choice that keeps the result closed:
 * a merged node of a vertex lying on the plane sits at the vertex itself; the ear cutter is
 * steered away from diagonals that repeat a mesh edge and from triangles whose surface
 * vertices are in a line (taken only if nothing else is left); boundary nodes follow
 * f->boundary_rule (closing.h).
 *
 * Ear cutting: vertices lying strictly between their neighbours on a straight line are taken
 * out first, the rest is ear-cut, and each taken-out run is fanned back into the one triangle
 * on its polygon edge — so no zero-area triangle appears where a proper triangulation exists
 * (a greedy ear-cut with collinear points can be left with a flat remainder). Ears are tried
 * in the order: convex and empty, zero area, convex, any — the cut always completes with n-2
 * triangles, so the output is a disk bounded by the polygon even for bad (self-touching)
 * input. Holes are bridged from their rightmost vertex to a visible outer vertex.
 *
 * All scratch memory is malloc'd and freed within the call.
 */
#include "closing.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- small helpers */

static void set_err(char *err, size_t errlen, const char *fmt, ...)
{
    if (!err || errlen == 0)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, errlen, fmt, ap);
    va_end(ap);
}

static double orient2(const double *a, const double *b, const double *c)
{
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

static int same_pt(const double *a, const double *b)
{
    return a[0] == b[0] && a[1] == b[1];
}

/* b lies strictly between a and c on the segment ac */
static int strictly_between(const double *a, const double *b, const double *c)
{
    if (orient2(a, b, c) != 0)
        return 0;
    return (b[0] - a[0]) * (c[0] - b[0]) + (b[1] - a[1]) * (c[1] - b[1]) > 0;
}

/* p in the closed triangle abc (abc counter-clockwise) */
static int in_tri(const double *a, const double *b, const double *c, const double *p)
{
    return orient2(a, b, p) >= 0 && orient2(b, c, p) >= 0 && orient2(c, a, p) >= 0;
}

/* ---------------------------------------------------------------- ear cutting */

/* Ear test at level 0: convex and no other live vertex (other than ones coincident with the
 * ear's corners, such as the two copies of a bridge end) in the closed triangle. */
static int ear_empty(const double *xy, const int *prv, const int *nxt, int b)
{
    int a = prv[b], c = nxt[b];
    const double *pa = xy + 2 * a, *pb = xy + 2 * b, *pc = xy + 2 * c;
    for (int p = nxt[c]; p != a; p = nxt[p]) {
        const double *pp = xy + 2 * p;
        if (same_pt(pp, pa) || same_pt(pp, pb) || same_pt(pp, pc))
            continue;
        if (in_tri(pa, pb, pc, pp))
            return 0;
    }
    return 1;
}

/* Optional vetoes (the closing keeps away from mesh edges and from triangles whose surface
 * vertices are in a line); NULL: none. Vetoed ears are only taken when nothing else is left. */
typedef struct {
    int (*diag)(const void *ctx, int a, int c);
    int (*tri)(const void *ctx, int a, int b, int c);
    const void *ctx;
} ear_veto;

typedef struct {
    const ear_veto *veto;
    const int *knext;   /* successor of a kept vertex on the reduced ring */
    const char *gone;   /* taken out (strictly between its neighbours on a line) */
    int n;
} ear_rules;

/* Would ear (a,b,c) be vetoed: its diagonal, itself, or the fan that will bring back the
 * taken-out vertices of one of its polygon edges? */
static int ear_vetoed(const ear_rules *er, int a, int b, int c)
{
    const ear_veto *v = er->veto;
    if (v->diag(v->ctx, a, c))
        return 1;
    int fan = 0;
    const int e[2][3] = {{a, b, c}, {b, c, a}};
    for (int k = 0; k < 2; k++) {
        int u = e[k][0], w = e[k][1], x = e[k][2];
        if (er->knext[u] != w || !er->gone[(u + 1) % er->n])
            continue;
        fan = 1;
        int prev = u;
        for (int i = (u + 1) % er->n; i != w; i = (i + 1) % er->n) {
            if (v->diag(v->ctx, x, i) || v->tri(v->ctx, prev, i, x))
                return 1;
            prev = i;
        }
        if (v->tri(v->ctx, prev, w, x))
            return 1;
    }
    return fan ? 0 : v->tri(v->ctx, a, b, c);
}

static int ear_ok(const double *xy, const int *prv, const int *nxt, int b, int level,
                  const ear_rules *er)
{
    double o = orient2(xy + 2 * prv[b], xy + 2 * b, xy + 2 * nxt[b]);
    switch (level) {
    case 0:
        return o > 0 && !ear_vetoed(er, prv[b], b, nxt[b]) && ear_empty(xy, prv, nxt, b);
    case 1:
        return o > 0 && ear_empty(xy, prv, nxt, b);
    case 2:
        return o == 0;
    case 3:
        return o > 0;
    default:
        return 1;
    }
}

/* Ear-cut the live ring through `start` (m vertices); writes m-2 triangles to out. */
static int cut_ring(const double *xy, int *prv, int *nxt, int start, int m, int32_t *out,
                    const ear_rules *er)
{
    int nt = 0, cur = start;
    while (m > 3) {
        int cut = -1;
        for (int level = er->veto ? 0 : 1; level < 5 && cut < 0; level++) {
            int b = cur;
            for (int k = 0; k < m; k++, b = nxt[b])
                if (ear_ok(xy, prv, nxt, b, level, er)) {
                    cut = b;
                    break;
                }
        }
        if (cut < 0)
            cut = cur; /* unreachable: the last level accepts any vertex */
        int a = prv[cut], c = nxt[cut];
        out[3 * nt] = a;
        out[3 * nt + 1] = cut;
        out[3 * nt + 2] = c;
        nt++;
        nxt[a] = c;
        prv[c] = a;
        m--;
        /* go on past the new diagonal: cutting at c next would fan out of a */
        cur = nxt[c];
    }
    out[3 * nt] = prv[cur];
    out[3 * nt + 1] = cur;
    out[3 * nt + 2] = nxt[cur];
    return nt + 1;
}

static int earcut_veto(const double *xy, int n, int32_t *out, const ear_veto *veto)
{
    if (!xy || !out || n < 3)
        return -1;
    int *prv = malloc((size_t)n * sizeof *prv), *nxt = malloc((size_t)n * sizeof *nxt);
    char *gone = calloc((size_t)n, 1);
    int *stack = malloc(2 * (size_t)n * sizeof *stack); /* n, +1 per removal */
    int *edge_tri = malloc((size_t)n * sizeof *edge_tri);
    int rc = -1;
    if (!prv || !nxt || !gone || !stack || !edge_tri)
        goto done;
    for (int i = 0; i < n; i++) {
        prv[i] = (i + n - 1) % n;
        nxt[i] = (i + 1) % n;
    }
    /* take out vertices lying strictly inside the segment of their neighbours */
    int m = n, sp = 0;
    for (int i = n - 1; i >= 0; i--)
        stack[sp++] = i;
    while (sp > 0 && m > 3) {
        int b = stack[--sp];
        if (gone[b] || !strictly_between(xy + 2 * prv[b], xy + 2 * b, xy + 2 * nxt[b]))
            continue;
        gone[b] = 1;
        nxt[prv[b]] = nxt[b];
        prv[nxt[b]] = prv[b];
        m--;
        stack[sp++] = prv[b];
        stack[sp++] = nxt[b];
    }
    int start = 0;
    while (gone[start])
        start++;
    if (m == 3 && n > 3 && orient2(xy + 2 * prv[start], xy + 2 * start, xy + 2 * nxt[start]) == 0) {
        /* everything is on one line: no proper triangulation exists */
        for (int i = 0; i < n; i++) {
            prv[i] = (i + n - 1) % n;
            nxt[i] = (i + 1) % n;
            gone[i] = 0;
        }
        m = n;
        start = 0;
    }
    /* the kept ring's successor, before cutting changes nxt */
    int *knext = stack; /* reuse: the stack is empty or no longer needed */
    for (int i = 0; i < n; i++)
        knext[i] = gone[i] ? -1 : nxt[i];
    ear_rules er = {veto, knext, gone, n};
    int w = cut_ring(xy, prv, nxt, start, m, out, &er);
    if (m == n) {
        rc = w;
        goto done;
    }
    /* fan each taken-out run back in from the vertex opposite its polygon edge; a triangle
     * may carry runs on several edges, so the split triangles are examined again */
    for (int i = 0; i < n; i++)
        edge_tri[i] = 0; /* 1 once the run after kept vertex i is back */
    for (int t = 0; t < w;) {
        int split = 0;
        for (int k = 0; k < 3 && !split; k++) {
            int u = out[3 * t + k], v = out[3 * t + (k + 1) % 3], c = out[3 * t + (k + 2) % 3];
            if (gone[u] || knext[u] != v || edge_tri[u] || !gone[(u + 1) % n])
                continue;
            edge_tri[u] = 1;
            int prev = (u + 1) % n;
            out[3 * t] = u;
            out[3 * t + 1] = prev;
            out[3 * t + 2] = c;
            for (int i = (prev + 1) % n; i != v; i = (i + 1) % n) {
                out[3 * w] = prev;
                out[3 * w + 1] = i;
                out[3 * w + 2] = c;
                w++;
                prev = i;
            }
            out[3 * w] = prev;
            out[3 * w + 1] = v;
            out[3 * w + 2] = c;
            w++;
            split = 1;
        }
        if (!split)
            t++;
    }
    rc = w;
done:
    free(prv);
    free(nxt);
    free(gone);
    free(stack);
    free(edge_tri);
    return rc;
}

int cs_earcut(const double *xy, int n, int32_t *out)
{
    return earcut_veto(xy, n, out, NULL);
}

/* ---------------------------------------------------------------- the face frame */

typedef struct {
    int wx, wy, wa;       /* world axes of the frame's x and y, and f's axis */
    double sgn;           /* n_f = sgn·e_wa */
    double plane;
    double lo[2], hi[2];  /* f's square in frame coordinates */
    int rank[2];          /* perturbation rank of the frame axes' edge lines (0 dominant) */
} frame;

/* Signed distance along n_f: < 0 on c1's side; a vertex on the plane (0) is on c2's side. */
static double side_dist(const frame *fr, const double *p)
{
    return (p[fr->wa] - fr->plane) * fr->sgn;
}

/* The crossing point of mesh edge (i, j) with the plane, in frame coordinates, computed from
 * the endpoints in index order; off is the symbolic displacement direction when the point is
 * the vertex on the plane (zero otherwise). */
static void crossing_point(const frame *fr, const double *rest, int32_t i, int32_t j,
                           double pt[2], double off[2])
{
    if (i > j) {
        int32_t s = i;
        i = j;
        j = s;
    }
    const double *a = rest + 3 * (size_t)i, *b = rest + 3 * (size_t)j;
    double da = side_dist(fr, a), db = side_dist(fr, b);
    const int ax[2] = {fr->wx, fr->wy};
    off[0] = off[1] = 0;
    if (da == 0 || db == 0) {
        const double *on = da == 0 ? a : b, *other = da == 0 ? b : a;
        double dd = fabs(da == 0 ? db : da);
        for (int k = 0; k < 2; k++) {
            pt[k] = on[ax[k]];
            off[k] = (other[ax[k]] - on[ax[k]]) / dd;
        }
        return;
    }
    double lam = da / (da - db);
    for (int k = 0; k < 2; k++)
        pt[k] = a[ax[k]] + lam * (b[ax[k]] - a[ax[k]]);
}

/* In f's square with the lattice lines moved by -ε: [lo, hi) in both axes. */
static int in_square(const frame *fr, const double *p)
{
    return p[0] >= fr->lo[0] && p[0] < fr->hi[0] && p[1] >= fr->lo[1] && p[1] < fr->hi[1];
}

/* ---------------------------------------------------------------- nodes */

enum { NODE_EDGE, NODE_BOUND, NODE_CORNER };

typedef struct {
    double p[2];      /* position on f */
    double q[2];      /* after the one-third move */
    double off[2];    /* symbolic displacement by ε' (see crossing_point) */
    double soff[2];   /* symbolic displacement by ε (the moved lattice lines): boundary
                         nodes and corners; zero for edge nodes */
    double along;     /* boundary nodes: coordinate along the walk on their edge of f */
    double slope;     /* boundary nodes: order among nodes at one position */
    int kind;
    int head;         /* 1: the triangle's segment ends here (no outgoing segment edge) */
    int cand;         /* candidate index of the triangle; -1 for corners */
    int other;        /* the other node of the same triangle; -1 for corners */
    int bedge;        /* boundary nodes: edge of f (0..3); corners: corner index */
    int32_t e[2];     /* edge nodes: the mesh edge, smaller index first */
    int32_t tri_v[3]; /* the triangle's vertices (edge and boundary nodes) */
    int32_t lxy[3];   /* its lone vertex L and the other ends X, Y of its crossing edges */
    int32_t vert;     /* assigned surface vertex */
    int out;          /* next node on its polygon, -1 if none yet */
} node;

/* Clip parameter with its symbolic part: lam + c[0]·ε_0 + c[1]·ε_1, ε_0 >> ε_1. */
typedef struct {
    double lam, c[2];
    int edge;         /* edge of f whose line gives it, -1 for a segment end */
} clip_t;

static int clip_less(const clip_t *a, const clip_t *b)
{
    if (a->lam != b->lam)
        return a->lam < b->lam;
    if (a->c[0] != b->c[0])
        return a->c[0] < b->c[0];
    return a->c[1] < b->c[1];
}

/* Walk tangent and inward normal of edge k of f (frame): bottom, right, top, left. */
static const double EDGE_T[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
static const double EDGE_N[4][2] = {{0, 1}, {-1, 0}, {0, -1}, {1, 0}};

/* Edge of f for frame axis j at its low (hi = 0) or high bound. */
static int edge_of(int j, int hi)
{
    return j == 0 ? (hi ? 1 : 3) : (hi ? 2 : 0);
}

/* The point where segment s→e meets the line of edge k, computed from the end nearer to the
 * line so that an end on the line is reproduced exactly. */
static void line_point(const frame *fr, const double *s, const double *e, int k, double out[2])
{
    int j = (k == 1 || k == 3) ? 0 : 1, o = 1 - j;
    double bound = (k == 0 || k == 3) ? fr->lo[j] : fr->hi[j];
    const double *near = fabs(bound - s[j]) <= fabs(e[j] - bound) ? s : e;
    double d[2] = {e[0] - s[0], e[1] - s[1]};
    out[j] = bound;
    out[o] = near[o] + (bound - near[j]) * d[o] / d[j];
    if (out[o] < fr->lo[o])
        out[o] = fr->lo[o];
    if (out[o] > fr->hi[o])
        out[o] = fr->hi[o];
}

static double along_edge(const double *p, int k)
{
    return EDGE_T[k][0] * p[0] + EDGE_T[k][1] * p[1];
}

/*
 * Clip the directed segment s→e to the square shrunk by the symbolic ε. Returns 0 if nothing
 * is left, else 1 with *ce / *cl the entering and leaving parameters (edge -1: the end itself).
 */
static int clip_segment(const frame *fr, const double *s, const double *e, clip_t *ce,
                        clip_t *cl)
{
    *ce = (clip_t){0, {0, 0}, -1};
    *cl = (clip_t){1, {0, 0}, -1};
    double d[2] = {e[0] - s[0], e[1] - s[1]};
    int s_in = in_square(fr, s), e_in = in_square(fr, e);
    for (int j = 0; j < 2; j++)
        for (int hi = 0; hi < 2; hi++) {
            double bound = hi ? fr->hi[j] : fr->lo[j];
            /* violated: beyond the line moved by -ε (so a point on a lo line is inside, a
             * point on a hi line outside) */
            int s_bad = hi ? s[j] >= bound : s[j] < bound;
            int e_bad = hi ? e[j] >= bound : e[j] < bound;
            if (s_bad && e_bad)
                return 0;
            if (!s_bad && !e_bad)
                continue;
            /* λ = (bound - ε - s)/d: the symbolic part is -1/d */
            clip_t c = {(bound - s[j]) / d[j], {0, 0}, edge_of(j, hi)};
            c.c[fr->rank[j]] = -1.0 / d[j];
            if (s_bad) {
                if (clip_less(ce, &c))
                    *ce = c;
            } else {
                if (clip_less(&c, cl))
                    *cl = c;
            }
        }
    if (s_in && e_in)
        return 1;
    /* ends inside are decided on the points themselves; only two clipped ends can miss */
    if (!s_in && !e_in && !clip_less(ce, cl))
        return 0;
    if (!s_in && ce->edge < 0)
        return 0; /* unreachable: an outside end violates some line */
    if (!e_in && cl->edge < 0)
        return 0;
    return 1;
}

static void fill_boundary(const frame *fr, node *nd, const double *s, const double *e,
                          int edge, int entering)
{
    line_point(fr, s, e, edge, nd->p);
    nd->kind = NODE_BOUND;
    nd->bedge = edge;
    nd->along = along_edge(nd->p, edge);
    /* where the shrunk line meets the segment, relative to p: the inward direction */
    double din[2] = {entering ? e[0] - s[0] : s[0] - e[0], entering ? e[1] - s[1] : s[1] - e[1]};
    double dn = EDGE_N[edge][0] * din[0] + EDGE_N[edge][1] * din[1];
    double dt = EDGE_T[edge][0] * din[0] + EDGE_T[edge][1] * din[1];
    /* the line moves by -ε along its axis: outwards for a lo edge (0, 3), inwards for hi */
    nd->slope = dn > 0 ? (edge == 0 || edge == 3 ? -dt / dn : dt / dn) : 0;
    /* s + λ(e - s) on the line moved by -ε along axis j: p - ε (e - s)/(e - s)_j */
    int j = (edge == 1 || edge == 3) ? 0 : 1;
    double d[2] = {e[0] - s[0], e[1] - s[1]};
    nd->soff[0] = -d[0] / d[j];
    nd->soff[1] = -d[1] / d[j];
}

/* Walk order of boundary nodes and corners (corners first on their edge). */
typedef struct {
    int edge;
    int corner;       /* 1 for a corner */
    double along, slope;
    int head;
    int id;
} walk_key;

static int walk_cmp(const void *pa, const void *pb)
{
    const walk_key *a = pa, *b = pb;
    if (a->edge != b->edge)
        return a->edge < b->edge ? -1 : 1;
    if (a->corner != b->corner)
        return a->corner ? -1 : 1;
    if (a->along != b->along)
        return a->along < b->along ? -1 : 1;
    if (a->slope != b->slope)
        return a->slope < b->slope ? -1 : 1;
    if (a->head != b->head) /* a fold: close it at once */
        return a->head ? -1 : 1;
    return a->id < b->id ? -1 : a->id > b->id;
}

typedef struct {
    int32_t a, b;
    int id;
} edge_key;

static int edge_cmp(const void *pa, const void *pb)
{
    const edge_key *a = pa, *b = pb;
    if (a->a != b->a)
        return a->a < b->a ? -1 : 1;
    if (a->b != b->b)
        return a->b < b->b ? -1 : 1;
    return a->id < b->id ? -1 : a->id > b->id;
}

/* ---------------------------------------------------------------- polygons */

/* Even-odd test of point p against ring. */
static int ring_contains(const double *xy, const int *ring, int n, const double *p)
{
    int in = 0;
    for (int i = 0, j = n - 1; i < n; j = i++) {
        const double *a = xy + 2 * ring[i], *b = xy + 2 * ring[j];
        if ((a[1] > p[1]) != (b[1] > p[1]) &&
            p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0])
            in = !in;
    }
    return in;
}

/*
 * Splice hole (h, nh points, clockwise) into ring (n points, capacity for n + nh + 2) through
 * a bridge from the hole's rightmost point to a visible ring point. Returns the new length.
 */
static int bridge_hole(const double *xy, int *ring, int n, const int *h, int nh)
{
    int hi = 0;
    for (int i = 1; i < nh; i++) {
        const double *a = xy + 2 * h[i], *b = xy + 2 * h[hi];
        if (a[0] > b[0] || (a[0] == b[0] && a[1] < b[1]))
            hi = i;
    }
    const double *hp = xy + 2 * h[hi];
    /* nearest crossing of the ray +x from hp with a ring edge */
    int best = -1;
    double bx = INFINITY;
    for (int i = 0; i < n; i++) {
        const double *a = xy + 2 * ring[i], *b = xy + 2 * ring[(i + 1) % n];
        if ((a[1] > hp[1]) == (b[1] > hp[1]) && !(a[1] == hp[1] || b[1] == hp[1]))
            continue;
        double x;
        if (a[1] == b[1])
            x = a[0] < b[0] ? a[0] : b[0];
        else
            x = a[0] + (hp[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
        if (x < hp[0] || x >= bx)
            continue;
        bx = x;
        /* the end of that edge further along +x */
        best = a[0] >= b[0] ? i : (i + 1) % n;
    }
    if (best < 0) {
        /* no crossing (the hole is not inside): the nearest ring point keeps things going */
        double bd = INFINITY;
        for (int i = 0; i < n; i++) {
            const double *a = xy + 2 * ring[i];
            double dd = (a[0] - hp[0]) * (a[0] - hp[0]) + (a[1] - hp[1]) * (a[1] - hp[1]);
            if (dd < bd) {
                bd = dd;
                best = i;
            }
        }
    } else {
        /* a ring point inside the triangle (hp, crossing, best) would hide best: take the
         * one at the smallest angle to the ray instead */
        double ip[2] = {bx, hp[1]};
        const double *m = xy + 2 * ring[best];
        double tri_a = orient2(hp, ip, m);
        double best_tan = INFINITY, best_d = INFINITY;
        int alt = -1;
        for (int i = 0; i < n; i++) {
            const double *p = xy + 2 * ring[i];
            if (i == best || p[0] < hp[0] || same_pt(p, m))
                continue;
            int in = tri_a > 0 ? in_tri(hp, ip, m, p) : tri_a < 0 ? in_tri(hp, m, ip, p) : 0;
            if (!in)
                continue;
            double dx = p[0] - hp[0], dy = fabs(p[1] - hp[1]);
            double tn = dx > 0 ? dy / dx : INFINITY;
            double dd = dx * dx + dy * dy;
            if (tn < best_tan || (tn == best_tan && dd < best_d)) {
                best_tan = tn;
                best_d = dd;
                alt = i;
            }
        }
        if (alt >= 0)
            best = alt;
    }
    /* ring[0..best], h[hi..], h[..hi], h[hi], ring[best], ring[best+1..] */
    int add = nh + 2;
    memmove(ring + best + 1 + add, ring + best + 1, (size_t)(n - best - 1) * sizeof *ring);
    int w = best + 1;
    for (int k = 0; k <= nh; k++)
        ring[w++] = h[(hi + k) % nh];
    ring[w++] = ring[best];
    return n + add;
}

/* ---------------------------------------------------------------- the closing */

/* Closing diagonals must not repeat a mesh edge (it would get four triangles), and closing
 * triangles should not have their surface vertices in a line. */
typedef struct {
    const node *nd;
    const int *ring;      /* slot -> node */
    const double *rest;
    const int64_t *edges; /* sorted mesh edges of the candidates, (min << 32) | max */
    int n_edges;
} veto_ctx;

static int cmp_i64(const void *pa, const void *pb)
{
    int64_t a = *(const int64_t *)pa, b = *(const int64_t *)pb;
    return (a > b) - (a < b);
}

static int mesh_edge_veto(const void *ctx, int a, int c)
{
    const veto_ctx *vc = ctx;
    int64_t x = vc->nd[vc->ring[a]].vert, y = vc->nd[vc->ring[c]].vert;
    int64_t key = x < y ? (x << 32) | y : (y << 32) | x;
    return bsearch(&key, vc->edges, (size_t)vc->n_edges, sizeof key, cmp_i64) != NULL;
}

static int flat_tri_veto(const void *ctx, int a, int b, int c)
{
    const veto_ctx *vc = ctx;
    int32_t x = vc->nd[vc->ring[a]].vert, y = vc->nd[vc->ring[b]].vert,
            z = vc->nd[vc->ring[c]].vert;
    if (x == y || y == z || x == z)
        return 1;
    const double *p = vc->rest + 3 * (size_t)x, *q = vc->rest + 3 * (size_t)y,
                 *r = vc->rest + 3 * (size_t)z;
    double u[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]};
    double w[3] = {r[0] - p[0], r[1] - p[1], r[2] - p[2]};
    double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                   u[0] * w[1] - u[1] * w[0]};
    double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    double uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
    double ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    return !(nn > 1e-20 * uu * ww);
}

/* §3.2 rule for a node made by mesh edge (a, b): c1's triangle takes the end off c1's side,
 * the other side's triangle the end on it. */
static int32_t edge_rule(const frame *fr, const double *rest, int32_t a, int32_t b, int c1)
{
    int a_c1 = side_dist(fr, rest + 3 * (size_t)a) < 0;
    return (c1 != 0) == a_c1 ? b : a;
}

/* Corner k of f as node slot i; returns i, or -1 if the caller named no vertex for it. */
static int add_corner(const cs_close_face *f, const frame *fr, node *nd, int i, int k)
{
    if (f->corner_vertex[k] < 0)
        return -1;
    node *x = nd + i;
    memset(x, 0, sizeof *x);
    x->kind = NODE_CORNER;
    x->bedge = k;
    x->cand = -1;
    x->other = -1;
    x->out = -1;
    x->vert = f->corner_vertex[k];
    x->p[0] = (k == 1 || k == 2) ? fr->hi[0] : fr->lo[0];
    x->p[1] = (k >= 2) ? fr->hi[1] : fr->lo[1];
    x->soff[0] = x->soff[1] = -1;
    return i;
}

/* Every node must have one outgoing and one incoming edge; the cycles go to order, cycle c
 * being order[start[c] .. start[c+1]). Returns 0, or -1 if the graph is not a set of cycles. */
static int extract_cycles(node *nd, int nn, int *indeg, int *order, int *start, int *n_cyc)
{
    memset(indeg, 0, (size_t)nn * sizeof *indeg);
    for (int i = 0; i < nn; i++) {
        if (nd[i].out < 0 || nd[i].out >= nn)
            return -1;
        indeg[nd[i].out]++;
    }
    for (int i = 0; i < nn; i++)
        if (indeg[i] != 1)
            return -1;
    int w = 0, c = 0;
    for (int i = 0; i < nn; i++) {
        if (indeg[i] == 0)
            continue; /* visited */
        start[c++] = w;
        for (int j = i; indeg[j] != 0; j = nd[j].out) {
            indeg[j] = 0;
            order[w++] = j;
        }
    }
    start[c] = w;
    *n_cyc = c;
    return 0;
}

/* Layout of a node: 0 its position, 1 its ε' offset, 2 its ε offset. */
static const double *node_xy(const node *x, int layout)
{
    return layout == 0 ? x->p : layout == 1 ? x->off : x->soff;
}

static double node_ring_area(const node *nd, const int *cy, int n, int layout)
{
    double a = 0;
    for (int i = 0; i < n; i++) {
        const double *p = node_xy(nd + cy[i], layout);
        const double *q = node_xy(nd + cy[(i + 1) % n], layout);
        a += p[0] * q[1] - p[1] * q[0];
    }
    return 0.5 * a;
}


int cs_close_face_triangles(const cs_close_face *f, const double *rest, const int32_t *tris,
                            const int32_t *cand, int n_cand, const uint8_t *c1_side,
                            int32_t *out, int cap, char *err, size_t errlen)
{
    if (err && errlen)
        err[0] = '\0';
    if (!f || f->axis < 0 || f->axis > 2 || n_cand < 0 || cap < 0 || (cap > 0 && !out) ||
        (n_cand > 0 && (!rest || !tris || !cand || !c1_side))) {
        set_err(err, errlen, "closing: invalid arguments");
        return -1;
    }
    frame fr;
    fr.wa = f->axis;
    int u = (f->axis + 1) % 3, v = (f->axis + 2) % 3;
    fr.wx = f->c1_below ? u : v;
    fr.wy = f->c1_below ? v : u;
    fr.sgn = f->c1_below ? 1.0 : -1.0;
    fr.plane = f->plane;
    fr.lo[0] = f->lo[fr.wx];
    fr.hi[0] = f->hi[fr.wx];
    fr.lo[1] = f->lo[fr.wy];
    fr.hi[1] = f->hi[fr.wy];
    fr.rank[0] = fr.wx < fr.wy ? 0 : 1;
    fr.rank[1] = 1 - fr.rank[0];
    if (!isfinite(fr.plane) || !(fr.lo[0] < fr.hi[0]) || !(fr.lo[1] < fr.hi[1]) ||
        !isfinite(fr.lo[0] + fr.hi[0] + fr.lo[1] + fr.hi[1])) {
        set_err(err, errlen, "closing: face square is empty or not finite");
        return -1;
    }

    int rc = -1, nn = 0;
    size_t max_nodes = 2 * (size_t)n_cand + 4;
    node *nd = calloc(max_nodes, sizeof *nd);
    int *order = malloc((max_nodes + 1) * sizeof *order);
    int *cyc_start = malloc((max_nodes + 1) * sizeof *cyc_start);
    int *indeg = calloc(max_nodes, sizeof *indeg);
    walk_key *wk = malloc(max_nodes * sizeof *wk);
    edge_key *ek = malloc(max_nodes * sizeof *ek);
    double *qxy = malloc(2 * max_nodes * sizeof *qxy);
    int *ring = malloc((3 * max_nodes + 8) * sizeof *ring);
    int *pol = malloc((max_nodes + 1) * sizeof *pol);  /* merged polygons, concatenated */
    int *pol_start = malloc((max_nodes + 1) * sizeof *pol_start);
    double *pol_area = malloc((max_nodes + 1) * sizeof *pol_area);
    int *pol_owner = malloc((max_nodes + 1) * sizeof *pol_owner);
    double *sxy = malloc(2 * (3 * max_nodes + 8) * sizeof *sxy);
    int32_t *stri = malloc(3 * (3 * max_nodes + 8) * sizeof *stri);
    int64_t *medges = malloc((3 * (size_t)n_cand + 1) * sizeof *medges);
    if (!nd || !order || !cyc_start || !indeg || !wk || !ek || !qxy || !ring || !pol ||
        !pol_start || !pol_area || !pol_owner || !sxy || !stri || !medges) {
        set_err(err, errlen, "closing: out of memory");
        goto done;
    }

    /* (1)-(2) segments of the crossing triangles, clipped to f */
    for (int ci = 0; ci < n_cand; ci++) {
        if (cand[ci] < 0) {
            set_err(err, errlen, "closing: negative candidate index");
            goto done;
        }
        const int32_t *t = tris + 3 * (size_t)cand[ci];
        if (t[0] < 0 || t[1] < 0 || t[2] < 0) {
            set_err(err, errlen, "closing: negative vertex index in triangle %d", cand[ci]);
            goto done;
        }
        int below[3];
        for (int k = 0; k < 3; k++)
            below[k] = side_dist(&fr, rest + 3 * (size_t)t[k]) < 0;
        int nb = below[0] + below[1] + below[2];
        if (nb == 0 || nb == 3)
            continue;
        int l = 0; /* the lone vertex */
        for (int k = 0; k < 3; k++)
            if ((nb == 1) == below[k])
                l = k;
        int32_t L = t[l], X = t[(l + 1) % 3], Y = t[(l + 2) % 3];
        double p1[2], p2[2], o1[2], o2[2];
        crossing_point(&fr, rest, L, X, p1, o1);
        crossing_point(&fr, rest, L, Y, p2, o2);
        double D[2] = {p2[0] - p1[0], p2[1] - p1[1]};
        int zero_len = D[0] == 0 && D[1] == 0;
        if (zero_len) {
            /* both points are L (on the plane, or rounded onto it): the direction of
             * P2 - P1 = d_L [(Y - L)/(d_L - d_Y) - (X - L)/(d_L - d_X)] */
            const double *pl = rest + 3 * (size_t)L, *px = rest + 3 * (size_t)X,
                         *py = rest + 3 * (size_t)Y;
            double dl = side_dist(&fr, pl);
            double gx = dl - side_dist(&fr, px), gy = dl - side_dist(&fr, py);
            /* d_L = 0 stands for +ε' (c2's side); a c1-side L (d_L < 0) flips the sign */
            double sg = nb == 1 ? -1.0 : 1.0;
            D[0] = sg * ((py[fr.wx] - pl[fr.wx]) / gy - (px[fr.wx] - pl[fr.wx]) / gx);
            D[1] = sg * ((py[fr.wy] - pl[fr.wy]) / gy - (px[fr.wy] - pl[fr.wy]) / gx);
        }
        const double *a = rest + 3 * (size_t)t[0], *b = rest + 3 * (size_t)t[1],
                     *c = rest + 3 * (size_t)t[2];
        double e1[3], e2[3], nt[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = b[k] - a[k];
            e2[k] = c[k] - a[k];
        }
        nt[0] = e1[1] * e2[2] - e1[2] * e2[1];
        nt[1] = e1[2] * e2[0] - e1[0] * e2[2];
        nt[2] = e1[0] * e2[1] - e1[1] * e2[0];
        /* Eq. (1) in the frame: [n_t × D]·n_f = n_t,x D_y − n_t,y D_x */
        double s = nt[fr.wx] * D[1] - nt[fr.wy] * D[0];
        if (s == 0) {
            set_err(err, errlen, "closing: triangle %d crosses f with no direction",
                    cand[ci]);
            goto done;
        }
        /* tail → head */
        const double *ps = s > 0 ? p1 : p2, *pe = s > 0 ? p2 : p1;
        const double *os = s > 0 ? o1 : o2, *oe = s > 0 ? o2 : o1;
        int32_t es = s > 0 ? X : Y, ee = s > 0 ? Y : X;
        clip_t ce, cl;
        if (zero_len) {
            if (!in_square(&fr, p1))
                continue;
            ce = (clip_t){0, {0, 0}, -1};
            cl = (clip_t){1, {0, 0}, -1};
        } else if (!clip_segment(&fr, ps, pe, &ce, &cl)) {
            continue;
        }
        node *ns = nd + nn, *ne = nd + nn + 1;
        for (int k = 0; k < 2; k++) {
            node *x = k ? ne : ns;
            x->cand = ci;
            x->other = nn + 1 - k;
            x->head = k;
            x->out = -1;
            x->vert = -1;
            memcpy(x->tri_v, t, sizeof x->tri_v);
            x->lxy[0] = L;
            x->lxy[1] = X;
            x->lxy[2] = Y;
            const clip_t *cc = k ? &cl : &ce;
            if (cc->edge < 0) {
                int32_t ev = k ? ee : es;
                x->kind = NODE_EDGE;
                memcpy(x->p, k ? pe : ps, sizeof x->p);
                memcpy(x->off, k ? oe : os, sizeof x->off);
                x->e[0] = L < ev ? L : ev;
                x->e[1] = L < ev ? ev : L;
            } else {
                fill_boundary(&fr, x, ps, pe, cc->edge, !k);
            }
        }
        ns->out = nn + 1;
        nn += 2;
    }
    int n_seg_nodes = nn;

    /* (3) the two nodes of one mesh edge: head → tail */
    int ne_ = 0;
    for (int i = 0; i < nn; i++)
        if (nd[i].kind == NODE_EDGE)
            ek[ne_++] = (edge_key){nd[i].e[0], nd[i].e[1], i};
    qsort(ek, (size_t)ne_, sizeof *ek, edge_cmp);
    for (int i = 0; i < ne_;) {
        int j = i;
        while (j < ne_ && ek[j].a == ek[i].a && ek[j].b == ek[i].b)
            j++;
        if (j - i != 2 || nd[ek[i].id].head == nd[ek[i + 1].id].head) {
            set_err(err, errlen,
                    "closing: mesh edge (%d,%d) crosses f with %d node(s) of %s orientation",
                    (int)ek[i].a, (int)ek[i].b, j - i, j - i == 2 ? "the same" : "unpaired");
            goto done;
        }
        int h = nd[ek[i].id].head ? ek[i].id : ek[i + 1].id;
        int tl = nd[ek[i].id].head ? ek[i + 1].id : ek[i].id;
        nd[h].out = tl;
        i = j;
    }

    /* (4) the walk along f's boundary */
    int nw = 0, n_bound = 0;
    for (int i = 0; i < nn; i++)
        if (nd[i].kind == NODE_BOUND) {
            wk[nw++] = (walk_key){nd[i].bedge, 0, nd[i].along, nd[i].slope, nd[i].head, i};
            n_bound++;
        }
    int corners_in = 0; /* for the no-boundary-node case */
    if (n_bound > 0) {
        for (int k = 0; k < 4; k++)
            wk[nw++] = (walk_key){k, 1, 0, 0, 0, -1 - k};
        qsort(wk, (size_t)nw, sizeof *wk, walk_cmp);
        /* the state before the walk starts: after the last boundary node */
        int inside = 0;
        for (int i = nw - 1; i >= 0; i--)
            if (wk[i].id >= 0) {
                inside = wk[i].head;
                break;
            }
        int n_walk = 0;
        for (int i = 0; i < nw; i++) {
            int id = wk[i].id;
            if (id < 0) {
                if (!inside)
                    continue;
                id = add_corner(f, &fr, nd, nn, -1 - id);
                if (id < 0) {
                    set_err(err, errlen, "closing: corner %d is inside but has no vertex",
                            -1 - wk[i].id);
                    goto done;
                }
                nn++;
            } else if (nd[id].head == inside) {
                set_err(err, errlen, "closing: boundary crossings of f do not alternate");
                goto done;
            } else {
                inside = nd[id].head;
            }
            order[n_walk++] = id;
        }
        for (int i = 0; i < n_walk; i++)
            if (nd[order[i]].out < 0)
                nd[order[i]].out = order[(i + 1) % n_walk];
    }

    /* (5) cycles */
    int n_cyc = 0;
    if (extract_cycles(nd, nn, indeg, order, cyc_start, &n_cyc) != 0) {
        set_err(err, errlen, "closing: the crossings of f do not form closed polygons");
        goto done;
    }
    if (n_bound == 0) {
        /* f's boundary is all inside or all outside: the outermost crossing polygon says
         * which (clockwise: a hole, so the boundary is inside); with none, corner_inside */
        int best = -1, best_c = -1;
        for (int c = 0; c < n_cyc; c++) {
            int len = cyc_start[c + 1] - cyc_start[c];
            double ar = node_ring_area(nd, order + cyc_start[c], len, 0);
            if (ar == 0)
                continue;
            for (int i = cyc_start[c]; i < cyc_start[c + 1]; i++) {
                const double *pp = nd[order[i]].p;
                if (best < 0 || pp[0] < nd[best].p[0] ||
                    (pp[0] == nd[best].p[0] && pp[1] < nd[best].p[1])) {
                    best = order[i];
                    best_c = c;
                }
            }
        }
        if (best_c >= 0) {
            int len = cyc_start[best_c + 1] - cyc_start[best_c];
            corners_in = node_ring_area(nd, order + cyc_start[best_c], len, 0) < 0;
        } else {
            corners_in = f->corner_inside[0] && f->corner_inside[1] && f->corner_inside[2] &&
                         f->corner_inside[3];
        }
        if (corners_in) {
            for (int k = 0; k < 4; k++) {
                if (add_corner(f, &fr, nd, nn + k, k) < 0) {
                    set_err(err, errlen, "closing: corner %d is inside but has no vertex", k);
                    goto done;
                }
                order[cyc_start[n_cyc] + k] = nn + k;
            }
            for (int k = 0; k < 4; k++)
                nd[nn + k].out = nn + (k + 1) % 4;
            nn += 4;
            n_cyc++;
            cyc_start[n_cyc] = cyc_start[n_cyc - 1] + 4;
        }
    }

    /* vertices (§3.2 rules), then the one-third move */
    for (int i = 0; i < n_seg_nodes; i++) {
        node *x = nd + i;
        if (x->kind == NODE_EDGE) {
            x->vert = edge_rule(&fr, rest, x->e[0], x->e[1], c1_side[x->cand]);
        } else if (f->boundary_rule == CS_CLOSE_BOUNDARY_SHARED) {
            /* the vertex the edge rule gives the crossing edge whose point lies on the
             * upper side of f's edge line: the face on the other side of that line sees the
             * same triangle, the same line and the same points, and agrees */
            int j = (x->bedge == 1 || x->bedge == 3) ? 0 : 1;
            double line = (x->bedge == 1 || x->bedge == 2) ? fr.hi[j] : fr.lo[j];
            double pa[2], pb[2], oo[2];
            crossing_point(&fr, rest, x->lxy[0], x->lxy[1], pa, oo);
            crossing_point(&fr, rest, x->lxy[0], x->lxy[2], pb, oo);
            int use_b = pb[j] >= line && !(pa[j] >= line);
            x->vert = edge_rule(&fr, rest, x->lxy[0], x->lxy[use_b ? 2 : 1], c1_side[x->cand]);
        } else {
            const node *o = nd + x->other;
            if (o->kind == NODE_EDGE) {
                for (int k = 0; k < 3; k++)
                    if (x->tri_v[k] != o->e[0] && x->tri_v[k] != o->e[1])
                        x->vert = x->tri_v[k];
            } else {
                double bd = INFINITY;
                for (int k = 0; k < 3; k++) {
                    const double *pv = rest + 3 * (size_t)x->tri_v[k];
                    double dx = pv[fr.wx] - x->p[0], dy = pv[fr.wy] - x->p[1],
                           dz = pv[fr.wa] - fr.plane;
                    double dd = dx * dx + dy * dy + dz * dz;
                    if (dd < bd || (dd == bd && x->tri_v[k] < x->vert)) {
                        bd = dd;
                        x->vert = x->tri_v[k];
                    }
                }
            }
        }
    }
    for (int i = 0; i < nn; i++) {
        node *x = nd + i;
        memcpy(x->q, x->p, sizeof x->q);
        if (x->kind != NODE_CORNER) {
            const node *o = nd + x->other;
            x->q[0] += (o->p[0] - x->p[0]) / 3.0;
            x->q[1] += (o->p[1] - x->p[1]) / 3.0;
        }
    }

    /* merge runs of one vertex; classify; bridge holes; ear-cut */
    int n_pol = 0, n_pol_nodes = 0;
    for (int c = 0; c < n_cyc; c++) {
        int s0 = cyc_start[c], len = cyc_start[c + 1] - s0;
        int *cy = order + s0;
        /* a cycle collapsed to one point (a vertex touching the plane, maybe on f's edge
         * line) is laid out by its symbolic offsets: by ε if it reaches f's boundary (ε'
         * << ε puts its edge nodes all at the point), else by ε' */
        int use_off = 1, layout = 0;
        for (int i = 1; i < len && use_off; i++)
            use_off = same_pt(nd[cy[i]].p, nd[cy[0]].p);
        if (use_off) {
            layout = 1;
            for (int i = 0; i < len; i++)
                if (nd[cy[i]].kind != NODE_EDGE)
                    layout = 2;
        }
        double ar = node_ring_area(nd, cy, len, layout);
        if (ar == 0)
            continue;
        /* start at a vertex change so that no run wraps around */
        int st = -1;
        for (int i = 0; i < len && st < 0; i++)
            if (nd[cy[i]].vert != nd[cy[(i + len - 1) % len]].vert)
                st = i;
        if (st < 0)
            continue; /* one vertex only */
        pol_start[n_pol] = n_pol_nodes;
        for (int i = 0; i < len;) {
            int j = i;
            while (j < len && nd[cy[(st + j) % len]].vert == nd[cy[(st + i) % len]].vert)
                j++;
            int keep = cy[(st + i + (j - i - 1) / 2) % len];
            pol[n_pol_nodes] = keep;
            const double *src = use_off ? node_xy(nd + keep, layout) : nd[keep].q;
            qxy[2 * keep] = src[0];
            qxy[2 * keep + 1] = src[1];
            if (!use_off && nd[keep].kind != NODE_CORNER) {
                /* a vertex on the plane is its own node position: surface vertices in a line
                 * then stay in a line, and the ear cutter avoids them */
                const double *pv = rest + 3 * (size_t)nd[keep].vert;
                if (side_dist(&fr, pv) == 0) {
                    qxy[2 * keep] = pv[fr.wx];
                    qxy[2 * keep + 1] = pv[fr.wy];
                }
            }
            n_pol_nodes++;
            i = j;
        }
        int plen = n_pol_nodes - pol_start[n_pol];
        if (plen < 3) {
            n_pol_nodes = pol_start[n_pol];
            continue;
        }
        pol_area[n_pol] = ar;
        n_pol++;
    }
    pol_start[n_pol] = n_pol_nodes;
    for (int i = 0; i < n_pol; i++) {
        pol_owner[i] = -1;
        if (pol_area[i] > 0)
            continue;
        /* a hole belongs to the smallest outer polygon around it */
        const double *pp = qxy + 2 * pol[pol_start[i]];
        double best = INFINITY;
        for (int j = 0; j < n_pol; j++)
            if (pol_area[j] > 0 && pol_area[j] < best &&
                ring_contains(qxy, pol + pol_start[j], pol_start[j + 1] - pol_start[j], pp)) {
                best = pol_area[j];
                pol_owner[i] = j;
            }
        if (pol_owner[i] < 0) {
            set_err(err, errlen, "closing: a hole of f's polygons lies in no outer polygon");
            goto done;
        }
    }
    int n_medges = 0;
    for (int ci = 0; ci < n_cand; ci++)
        for (int k = 0; k < 3; k++) {
            int64_t x = tris[3 * (size_t)cand[ci] + k], y = tris[3 * (size_t)cand[ci] + (k + 1) % 3];
            medges[n_medges++] = x < y ? (x << 32) | y : (y << 32) | x;
        }
    qsort(medges, (size_t)n_medges, sizeof *medges, cmp_i64);
    int n_out = 0;
    for (int i = 0; i < n_pol; i++) {
        if (pol_area[i] < 0)
            continue;
        int n = pol_start[i + 1] - pol_start[i];
        memcpy(ring, pol + pol_start[i], (size_t)n * sizeof *ring);
        /* holes by decreasing rightmost x, so that later bridges see earlier ones */
        for (;;) {
            int hb = -1;
            double hx = -INFINITY;
            for (int j = 0; j < n_pol; j++) {
                if (pol_owner[j] != i)
                    continue;
                for (int k = pol_start[j]; k < pol_start[j + 1]; k++)
                    if (qxy[2 * pol[k]] > hx || hb < 0) {
                        hx = qxy[2 * pol[k]];
                        hb = j;
                    }
            }
            if (hb < 0)
                break;
            n = bridge_hole(qxy, ring, n, pol + pol_start[hb], pol_start[hb + 1] - pol_start[hb]);
            pol_owner[hb] = -2;
        }
        for (int k = 0; k < n; k++) {
            sxy[2 * k] = qxy[2 * ring[k]];
            sxy[2 * k + 1] = qxy[2 * ring[k] + 1];
        }
        veto_ctx vctx = {nd, ring, rest, medges, n_medges};
        ear_veto ev = {mesh_edge_veto, flat_tri_veto, &vctx};
        int nt = earcut_veto(sxy, n, stri, &ev);
        if (nt < 0) {
            set_err(err, errlen, "closing: out of memory");
            goto done;
        }
        for (int t = 0; t < nt; t++) {
            int32_t a = nd[ring[stri[3 * t]]].vert, b = nd[ring[stri[3 * t + 1]]].vert,
                    c = nd[ring[stri[3 * t + 2]]].vert;
            if (a == b || b == c || a == c)
                continue;
            if (n_out >= cap) {
                set_err(err, errlen, "closing: more than %d triangles", cap);
                goto done;
            }
            out[3 * n_out] = a;
            out[3 * n_out + 1] = b;
            out[3 * n_out + 2] = c;
            n_out++;
        }
    }
    rc = n_out;
done:
    free(nd);
    free(order);
    free(cyc_start);
    free(indeg);
    free(wk);
    free(ek);
    free(qxy);
    free(ring);
    free(pol);
    free(pol_start);
    free(pol_area);
    free(pol_owner);
    free(sxy);
    free(stri);
    free(medges);
    return rc;
}
