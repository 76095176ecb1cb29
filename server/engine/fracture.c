/*
 * fracture.c — fracture of the cube mesh and of the embedded surface (seed 000 §2.3, §3.1,
 * §3.2), and the topology changes (topo.h) that tell clients about it.
 *
 * One fracture event on an object, given a ± label per cell (cells of a neighbourhood on the
 * two sides of a splitting plane; unlabelled cells take no part):
 *   1. crack faces F: faces between a + and a − cell that are still joined; each is marked cut;
 *   2. cube mesh (§2.3): a stress fracture (or cs_world_fracture) follows the paper: every node
 *      of F is duplicated and the − cells there relinked to the duplicate, so the crack opens
 *      at once (at its rim the − cells tear from their unlabelled neighbours). A single cut
 *      face (cs_world_cut_face) duplicates a node only where the cut faces separate the cells
 *      around it, so cutting one face does exactly that;
 *   3. surface (§3.1): each triangle belongs to the cell its centroid lies in; two triangles
 *      sharing an edge are separated when their cells shared a node before and share none now;
 *      around each vertex the triangles are grouped by the edges that still join them, and
 *      every group beyond the first gets its own copy of the vertex, skinned to a cell of its
 *      own side. With partial closing (below) also where the cells share fewer nodes than
 *      before (a face or edge between them opened partially), except along a mesh edge that
 *      lies where they are still held (between two still-shared corners), and a corner vertex
 *      splits with its node: one per node copy;
 *   4. closing surface (§3.2, closing.c): per face that this event opened fully (its four nodes
 *      separated), the region of f inside the surface as triangles between surface vertices
 *      and corner vertices (a random offset per lattice point that never crosses the surface;
 *      a mesh vertex lying on the lattice point is used instead), t for c1 and its reverse t'
 *      for c2. Partial closing — in the cut path (cs_world_cut_face) on an object whose mesh
 *      lies in lattice planes (objects given as cells, voxel models, pieces without mesh
 *      triangles) — closes a face when it first opens at all (a corner node separated): a
 *      corner still shared by c1 and c2 gets one corner vertex used by t and t' (the pair is
 *      glued along it: a wedge-shaped cavity, closed, of volume 0 at rest), a separated one a
 *      vertex per node copy; when the face later opens further its pair exists already and its
 *      corner vertices split with their nodes. Elsewhere (meshes crossing faces, stress
 *      cracks) a face opened only partially waits, as before: there the mesh's slit across it
 *      does not end where the glued pair does (it ends wherever the triangles around the hinge
 *      still join), which was measured to leave more loops, not fewer;
 *   5. repair: the §3.2 rules for assigning surface vertices to nodes are heuristics and can
 *      leave the closing triangles not matching the fracture line exactly (seed 000 does not
 *      claim otherwise). With partial closing, glued pairs of two faces hinged on one lattice
 *      edge would give it four triangles: one end gets a vertex per cavity (split_glued), and
 *      such second vertices go back into their node's vertex once the hinge opens
 *      (merge_cavity_corners, only where no edge is then used twice one way). A face's pair
 *      t, t' that would make an edge used twice in one direction, or that is degenerate, is
 *      dropped; where boundary loops pass a vertex twice the vertex is split so that every
 *      loop is simple; every loop left is closed by a fan (or a single triangle), the fans of
 *      loops joined by an edge at rest around one apex point, so that their volumes cancel
 *      exactly at rest (close_loops). The surface is then closed and consistently oriented by
 *      construction; the event reports the fans. Where a face opens partially without partial
 *      closing, its rim is left to such fans, and when the face opens fully one of its pairs
 *      can meet a fan of the earlier opening and be dropped: the two sides' loops then differ
 *      (with an apex per loop that lost volume: up to 1.2 % in test_fracture_meshes' cut
 *      runs). The surface also separates here between cells that step 6 will put in
 *      different pieces (cells touching only along an edge or at a corner, which still share
 *      nodes), so that no piece is left with open loops to close on its own;
 *   6. pieces (§2.4): cells are grouped by shared nodes (face connectivity after step 2); the
 *      largest group stays the object, every other one becomes a new object with its own cube
 *      mesh, surface, state (positions, velocities, inputs) and id.
 * Steps 3–5 make one topology change (vertices and triangles appended, triangles rewired);
 * step 6 makes one more for the object (swap-removals) and one per new piece (from version 0).
 * The engine applies each change to its own arrays exactly as topo.c applies it for a client.
 *
 * All surface geometry decisions use rest positions, as §3.2 prescribes.
 */
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "closing.h"
#include "elastic.h"
#include "mat3.h"
#include "voxelize.h"
#include "rigid.h"
#include "world_internal.h"

/* ---------------------------------------------------------------- small helpers */

/* Grow *a (elements of `elem` bytes, capacity *cap) so that one more fits after n. */
static int vec_room(void *a, int *cap, int n, size_t elem)
{
    if (n < *cap)
        return 0;
    int c = *cap ? 2 * *cap : 64;
    void *g = realloc(*(void **)a, (size_t)c * elem);
    if (!g)
        return -1;
    *(void **)a = g;
    *cap = c;
    return 0;
}

typedef struct ivec {
    int32_t *a;
    int n, cap;
} ivec;

typedef struct dvec {
    double *a;
    int n, cap;
} dvec;

static int ivec_push(ivec *v, int32_t x)
{
    if (vec_room(&v->a, &v->cap, v->n, sizeof *v->a))
        return -1;
    v->a[v->n++] = x;
    return 0;
}

static int ivec_push3(ivec *v, int32_t a, int32_t b, int32_t c)
{
    return ivec_push(v, a) || ivec_push(v, b) || ivec_push(v, c) ? -1 : 0;
}

static int dvec_push(dvec *v, double x)
{
    if (vec_room(&v->a, &v->cap, v->n, sizeof *v->a))
        return -1;
    v->a[v->n++] = x;
    return 0;
}

static int uf_find(int32_t *p, int32_t x)
{
    while (p[x] != x) {
        p[x] = p[p[x]];
        x = p[x];
    }
    return x;
}

static void uf_union(int32_t *p, int32_t a, int32_t b)
{
    a = uf_find(p, a);
    b = uf_find(p, b);
    if (a != b)
        p[a < b ? b : a] = a < b ? a : b; /* the smaller index is the root: deterministic */
}

/* realloc to exactly n elements (at least one) */
static int resize(void *pp, size_t elem, size_t n)
{
    void **p = pp;
    void *g = realloc(*p, (n ? n : 1) * elem);
    if (!g)
        return -1;
    *p = g;
    return 0;
}

/* Corner index of lattice offset (x,y,z) in seed 000 App. A order. */
static const int CORNER_ID[2][2][2] = {{{0, 4}, {3, 7}}, {{1, 5}, {2, 6}}};

static int corner_id(int x, int y, int z)
{
    return CORNER_ID[x][y][z];
}

/* SplitMix64: the deterministic per-lattice-point random offsets of corner vertices. */
static uint64_t mix64(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

/* ---------------------------------------------------------------- stress (§2.3) */

/* Symmetric 3×3 eigen-decomposition by cyclic Jacobi rotations; returns the largest eigenvalue
 * and its unit eigenvector. */
static double max_eigen(const double S[9], double dir[3])
{
    double a[3][3], v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            a[i][j] = 0.5 * (S[3 * i + j] + S[3 * j + i]);
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = fabs(a[0][1]) + fabs(a[0][2]) + fabs(a[1][2]);
        double scale = fabs(a[0][0]) + fabs(a[1][1]) + fabs(a[2][2]);
        if (off <= 1e-15 * scale || off == 0)
            break;
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++) {
                if (a[p][q] == 0)
                    continue;
                double theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
                double t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1));
                double c = 1 / sqrt(t * t + 1), s = t * c;
                for (int k = 0; k < 3; k++) { /* A <- A J */
                    double akp = a[k][p], akq = a[k][q];
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < 3; k++) { /* A <- Jᵀ A */
                    double apk = a[p][k], aqk = a[q][k];
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for (int k = 0; k < 3; k++) {
                    double vkp = v[k][p], vkq = v[k][q];
                    v[k][p] = c * vkp - s * vkq;
                    v[k][q] = s * vkp + c * vkq;
                }
            }
    }
    int best = 0;
    for (int i = 1; i < 3; i++)
        if (a[i][i] > a[best][best])
            best = i;
    double n = sqrt(v[0][best] * v[0][best] + v[1][best] * v[1][best] + v[2][best] * v[2][best]);
    for (int k = 0; k < 3; k++)
        dir[k] = v[k][best] / n;
    return a[best][best];
}

/*
 * Stress of cell c in its rotated frame: the small strain of the element-local displacement
 * u = Rᵀ(x − x₀) − X at the cell centre (where ∂N_k/∂x = s_k/(4h), s_k = ±1), σ = λ tr(ε) I +
 * 2μ ε (symmetric to the bit: S_ij and S_ji are the same sums).
 */
static void cell_stress(const cs_object *o, int c, double S[9])
{
    /* the cell's stiffness: its mean Gauss-point factor of the young field */
    double kf = 0;
    for (int g = 0; g < 8; g++)
        kf += o->fld.young ? o->fld.young[8 * (size_t)c + g] / 8.0 : 1.0 / 8.0;
    const double h = o->cm.h, E = o->mat.young * kf, nu = o->mat.poisson;
    const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
    const double *R = o->fem.R + 9 * (size_t)c;
    const double *x0 = o->x + 3 * (size_t)nd[0];
    double G[9] = {0};
    for (int k = 0; k < 8; k++) {
        const double *p = o->x + 3 * (size_t)nd[k];
        const double d[3] = {p[0] - x0[0], p[1] - x0[1], p[2] - x0[2]};
        double u[3], g[3];
        for (int i = 0; i < 3; i++) {
            u[i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2] - h * CS_CORNER[k][i];
            g[i] = (2.0 * CS_CORNER[k][i] - 1.0) / (4.0 * h);
        }
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                G[3 * i + j] += u[i] * g[j];
    }
    const double tr = G[0] + G[4] + G[8];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            S[3 * i + j] = mu * (G[3 * i + j] + G[3 * j + i]) + (i == j ? lambda * tr : 0.0);
}

/* Largest principal stress of cell c (of cell_stress's S, by the Jacobi eigensolver) and its
 * direction in world space. */
static double cell_max_stress(const cs_object *o, int c, double dir[3])
{
    double S[9], dl[3];
    cell_stress(o, c, S);
    const double s = max_eigen(S, dl);
    const double *R = o->fem.R + 9 * (size_t)c;
    for (int i = 0; i < 3; i++)
        dir[i] = R[3 * i] * dl[0] + R[3 * i + 1] * dl[1] + R[3 * i + 2] * dl[2];
    return s;
}

int cs_object_principal_stress(const cs_world_t *w, cs_object_id id, double *sigma,
                               double *dir, int n)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return CS_ERR_UNKNOWN_OBJECT;
    if (!sigma || !dir || n < 0)
        return CS_ERR_INVALID;
    for (int c = 0; c < o->cm.n_cells && c < n; c++)
        sigma[c] = cell_max_stress(o, c, dir + 3 * (size_t)c);
    return CS_OK;
}

/* ---------------------------------------------------------------- events and changes */

void cs_fracture_clear_step(cs_world_t *w)
{
    w->n_events = 0;
    for (int i = 0; i < w->topo.n_blocks; i++)
        free(w->topo.blocks[i]);
    w->topo.n_blocks = 0;
    w->topo.n = 0;
}

void cs_world_fracture_free(cs_world_t *w)
{
    cs_fracture_clear_step(w);
    free(w->events);
    free(w->topo.items);
    free(w->topo.blocks);
}

const cs_event *cs_world_events(const cs_world_t *w, int *count)
{
    if (count)
        *count = w ? w->n_events : 0;
    return w ? w->events : NULL;
}

const cs_topo_change *cs_world_topology_changes(const cs_world_t *w, int *count)
{
    if (count)
        *count = w ? w->topo.n : 0;
    return w ? w->topo.items : NULL;
}

static int push_event(cs_world_t *w, const cs_event *e)
{
    if (w->n_events == w->cap_events) {
        int cap = w->cap_events ? 2 * w->cap_events : 8;
        cs_event *g = realloc(w->events, (size_t)cap * sizeof *g);
        if (!g)
            return -1;
        w->events = g;
        w->cap_events = cap;
    }
    w->events[w->n_events++] = *e;
    return 0;
}

/* Keep a copy of n bytes in the change list's arena; NULL on out of memory (or n == 0). */
static void *keep(cs_world_t *w, const void *src, size_t n)
{
    if (n == 0)
        return NULL;
    cs_topo_list *t = &w->topo;
    if (t->n_blocks == t->cap_blocks) {
        int cap = t->cap_blocks ? 2 * t->cap_blocks : 16;
        void **g = realloc(t->blocks, (size_t)cap * sizeof *g);
        if (!g)
            return NULL;
        t->blocks = g;
        t->cap_blocks = cap;
    }
    void *p = malloc(n);
    if (!p)
        return NULL;
    memcpy(p, src, n);
    t->blocks[t->n_blocks++] = p;
    return p;
}

/* Append a change whose arrays are copied into the arena. */
static int push_change(cs_world_t *w, const cs_topo_change *c)
{
    cs_topo_list *t = &w->topo;
    if (t->n == t->cap) {
        int cap = t->cap ? 2 * t->cap : 8;
        cs_topo_change *g = realloc(t->items, (size_t)cap * sizeof *g);
        if (!g)
            return -1;
        t->items = g;
        t->cap = cap;
    }
    cs_topo_change k = *c;
#define KEEP(field, count, elem)                                                               \
    do {                                                                                       \
        k.field = keep(w, c->field, (size_t)(count) * (elem));                                 \
        if ((count) > 0 && !k.field)                                                           \
            return -1;                                                                         \
    } while (0)
    KEEP(vremove, c->n_vremove, sizeof(int32_t));
    KEEP(vnew_xyz, c->n_vnew, 3 * sizeof(double));
    KEEP(tremove, c->n_tremove, sizeof(int32_t));
    KEEP(tset_index, c->n_tset, sizeof(int32_t));
    KEEP(tset_tri, c->n_tset, 3 * sizeof(int32_t));
    KEEP(tnew, c->n_tnew, 3 * sizeof(int32_t));
    if (c->vnew_src)
        KEEP(vnew_src, c->n_vnew, sizeof(int32_t));
#undef KEEP
    if (c->name) {
        k.name = keep(w, c->name, strlen(c->name) + 1);
        if (!k.name)
            return -1;
    }
    if (c->model) {
        k.model = keep(w, c->model, strlen(c->model) + 1);
        if (!k.model)
            return -1;
    }
    t->items[t->n++] = k;
    return 0;
}

/* ---------------------------------------------------------------- cube-mesh queries */

static bool cells_share_node(const cs_cubemesh *cm, int32_t a, int32_t b)
{
    if (a == b)
        return true;
    const int32_t *na = cm->cell_nodes + 8 * (size_t)a, *nb = cm->cell_nodes + 8 * (size_t)b;
    for (int i = 0; i < 8; i++)
        for (int j = 0; j < 8; j++)
            if (na[i] == nb[j])
                return true;
    return false;
}

/* Axis along which a and b are face neighbours (b = a + e_axis·dir), or -1. */
static int face_axis(const cs_cubemesh *cm, int32_t a, int32_t b, int *dir)
{
    const int32_t *p = cm->cell_ijk + 3 * (size_t)a, *q = cm->cell_ijk + 3 * (size_t)b;
    int axis = -1;
    for (int k = 0; k < 3; k++) {
        int d = q[k] - p[k];
        if (d == 0)
            continue;
        if ((d != 1 && d != -1) || axis >= 0)
            return -1;
        axis = k;
        *dir = d;
    }
    return axis;
}

/* The 4 corners of cell's face on side `hi` (0/1) of `axis`. */
static void face_corners(int axis, int hi, int out[4])
{
    int n = 0;
    for (int k = 0; k < 8; k++)
        if (CS_CORNER[k][axis] == hi)
            out[n++] = k;
}

/* Bit of cell's face on side dir (±1) of axis in cs_object.cell_cut. */
static uint8_t face_bit(int axis, int dir)
{
    return (uint8_t)(1u << (2 * axis + (dir > 0)));
}

/* Are a and b (face neighbours, b at +dir along axis) joined: not cut by an earlier fracture
 * and sharing all four nodes of their face? (A cut whose rim kept every node shared is an
 * inner slit: the nodes alone do not show it; at the rim of a stress crack the − cells tear
 * from their unlabelled neighbours without that face being cut.) */
static bool face_joined(const cs_object *o, int32_t a, int32_t b, int axis, int dir)
{
    const cs_cubemesh *cm = &o->cm;
    if (o->cell_cut && (o->cell_cut[a] & face_bit(axis, dir)))
        return false;
    int ca[4];
    face_corners(axis, dir > 0 ? 1 : 0, ca);
    for (int i = 0; i < 4; i++) {
        int off[3] = {CS_CORNER[ca[i]][0], CS_CORNER[ca[i]][1], CS_CORNER[ca[i]][2]};
        off[axis] = 1 - off[axis];
        if (cm->cell_nodes[8 * (size_t)a + ca[i]] !=
            cm->cell_nodes[8 * (size_t)b + corner_id(off[0], off[1], off[2])])
            return false;
    }
    return true;
}

/* ---------------------------------------------------------------- the crack */

typedef struct crack_face {
    int32_t c1, c2; /* c1: + side (keeps its nodes), c2: − side */
    int axis;
    int c1_below;   /* c1 lies below the face along axis */
} crack_face;

typedef struct pairkey {
    int32_t a, b;
} pairkey;

static int cmp_pair(const void *x, const void *y)
{
    const pairkey *p = x, *q = y;
    if (p->a != q->a)
        return p->a < q->a ? -1 : 1;
    return (p->b > q->b) - (p->b < q->b);
}

static bool in_pairs(const pairkey *s, int n, int32_t a, int32_t b)
{
    pairkey k = {a < b ? a : b, a < b ? b : a};
    return bsearch(&k, s, (size_t)n, sizeof k, cmp_pair) != NULL;
}

/* ---------------------------------------------------------------- edge counting */

/* Open-addressing map of directed edges (a,b) -> count. */
typedef struct edge_map {
    uint64_t *keys;
    int32_t *count;
    size_t cap; /* power of two */
} edge_map;

#define EDGE_EMPTY UINT64_MAX

static uint64_t edge_key(int32_t a, int32_t b)
{
    return ((uint64_t)(uint32_t)a << 32) | (uint32_t)b;
}

static int edge_map_init(edge_map *m, size_t expected)
{
    size_t cap = 64;
    while (cap < 2 * expected + 16)
        cap <<= 1;
    m->cap = cap;
    m->keys = malloc(cap * sizeof *m->keys);
    m->count = calloc(cap, sizeof *m->count);
    if (!m->keys || !m->count)
        return -1;
    memset(m->keys, 0xff, cap * sizeof *m->keys);
    return 0;
}

static void edge_map_free(edge_map *m)
{
    free(m->keys);
    free(m->count);
    memset(m, 0, sizeof *m);
}

static int32_t *edge_slot(edge_map *m, uint64_t k, bool insert)
{
    size_t i = (size_t)(mix64(k) & (m->cap - 1));
    for (;;) {
        if (m->keys[i] == k)
            return &m->count[i];
        if (m->keys[i] == EDGE_EMPTY) {
            if (!insert)
                return NULL;
            m->keys[i] = k;
            return &m->count[i];
        }
        i = (i + 1) & (m->cap - 1);
    }
}

static int32_t edge_get(edge_map *m, int32_t a, int32_t b)
{
    int32_t *s = edge_slot(m, edge_key(a, b), false);
    return s ? *s : 0;
}

static void edge_add(edge_map *m, int32_t a, int32_t b, int32_t d)
{
    *edge_slot(m, edge_key(a, b), true) += d;
}

static void tri_edges_add(edge_map *m, const int32_t *t, int32_t d)
{
    edge_add(m, t[0], t[1], d);
    edge_add(m, t[1], t[2], d);
    edge_add(m, t[2], t[0], d);
}

/* ---------------------------------------------------------------- surface editing state */

/*
 * The surface being edited: the engine's arrays plus room to append. New vertices are
 * appended with their binding; triangles rewired in place are flagged.
 */
typedef struct surf_edit {
    cs_object *o;
    /* this event closes partially opened faces too (fracture_event: the cut path on an object
     * whose mesh lies in lattice planes) */
    bool partial;
    /* per cell: the piece it will be in (split_pieces' rule, after the nodes split), so that
     * the surface separates between pieces in this event and its loops close together */
    int32_t *piece;
    int nv0, nt0;     /* counts before the event */
    dvec rest, pos;   /* appended vertices: 3 each */
    ivec vcell;       /* appended vertices: bound cell */
    ivec vsrc;        /* appended vertices: the vertex (< nv0) each is a copy of, or -1 */
    ivec jumped;      /* appended vertices: 1 for a copy that starts at its skinned position
                         away from its source's (sv_append_copy) */
    dvec uvw;         /* appended vertices: 3 each */
    ivec tnew;        /* appended triangles: 3 each */
    ivec tnew_cell;   /* cell of each appended triangle */
    uint8_t *rewired; /* per original triangle */
    /* From the surface split (NULL otherwise): the triangles before the event and, per
     * vertex < nv0, the triangles that held it then (CSR); they let the repair look only at
     * the triangles around the crack (see repair_region). */
    const int32_t *tris0;
    int32_t *vstart, *vtris;
} surf_edit;

static const double *sv_rest(const surf_edit *e, int32_t v)
{
    return v < e->nv0 ? e->o->surf.rest + 3 * (size_t)v : e->rest.a + 3 * (size_t)(v - e->nv0);
}


/* Skin a rest position p to `cell` at current node positions x: its local coordinates and
 * the position cs_surface_skin will give it (trilinear, or the B-spline map of a localframe
 * cell), bit for bit. */
static void skin_point(const cs_object *o, int32_t cell, const double p[3], double uvw[3],
                       double out[3])
{
    const cs_cubemesh *cm = &o->cm;
    const int32_t *ijk = cm->cell_ijk + 3 * (size_t)cell;
    for (int k = 0; k < 3; k++)
        uvw[k] = (p[k] - cm->origin[k]) / cm->h - ijk[k];
    cs_surface_skin_point(cm, o->x, cell, uvw, p, out);
}

/* Append a vertex at rest position p bound to `cell`; returns its index or -1. */
static int32_t sv_append(surf_edit *e, const double p[3], int32_t cell)
{
    double uvw[3], x[3];
    skin_point(e->o, cell, p, uvw, x);
    for (int k = 0; k < 3; k++)
        if (dvec_push(&e->rest, p[k]) || dvec_push(&e->pos, x[k]) || dvec_push(&e->uvw, uvw[k]))
            return -1;
    if (ivec_push(&e->vcell, cell) || ivec_push(&e->vsrc, -1) || ivec_push(&e->jumped, 0))
        return -1;
    return e->nv0 + e->vcell.n - 1;
}

/*
 * Append a copy of vertex v bound to `cell`, and where it starts. Where its cell puts it
 * (skinned) within JUMP_REL·h of where v is now, v's side and the copy's are still together:
 * the crack between them is the one this event opens (its node copies coincide; the two
 * cells' maps differ only by how far the deformation is from affine across it: measured up
 * to 0.014 h in test_fracture_meshes' pushed icosphere). The copy then starts exactly where
 * v is, so the surface does not jump at the fracture and the two sides' closing triangles
 * coincide at this instant too (a client checks a change's volume there, topo.h); the next
 * skin moves it with its side. Further away, v's side and the copy's were already apart: v
 * lies across a crack that opened earlier and is still held elsewhere (an open crack: a
 * piece hinged on a partially opened face, or a crack the elastic motion has opened), and
 * v's position says nothing about where the copy's side is now. The copy then starts where
 * its cell puts it, a jump at the fracture to its truthful position. (Starting it at v's
 * position there left it, the closing triangles and the fans over it on the wrong side of
 * the open crack until the next step: new pieces inside out at the instant of a fracture,
 * the fracture storm at seed 5.) vsrc names v either way.
 */
#define JUMP_REL 0.1

static int32_t sv_append_copy(surf_edit *e, int32_t v, int32_t cell)
{
    double p[3];
    memcpy(p, sv_rest(e, v), sizeof p);
    int32_t c = sv_append(e, p, cell);
    if (c < 0)
        return c;
    /* a copy of a copy made in this edit names the first one's source */
    e->vsrc.a[c - e->nv0] = v < e->nv0 ? v : e->vsrc.a[v - e->nv0];
    const double *xv = v < e->nv0 ? e->o->surf.pos + 3 * (size_t)v
                                   : e->pos.a + 3 * (size_t)(v - e->nv0);
    double *xc = e->pos.a + 3 * (size_t)(c - e->nv0), d2 = 0;
    for (int a = 0; a < 3; a++)
        d2 += (xc[a] - xv[a]) * (xc[a] - xv[a]);
    const double far = JUMP_REL * e->o->cm.h;
    if (d2 <= far * far)
        memcpy(xc, xv, 3 * sizeof(double));
    else
        e->jumped.a[c - e->nv0] = 1;
    return c;
}

static void surf_edit_free(surf_edit *e)
{
    free(e->rest.a);
    free(e->pos.a);
    free(e->vcell.a);
    free(e->vsrc.a);
    free(e->jumped.a);
    free(e->uvw.a);
    free(e->tnew.a);
    free(e->tnew_cell.a);
    free(e->rewired);
    free(e->piece);
    free(e->vstart);
    free(e->vtris);
}

/* ---------------------------------------------------------------- generalized winding number */

/* Is p inside the object's closed rest surface? (winding number of the surface at p > ½;
 * robust to the coincident reversed layers that closing surfaces make) */
static bool inside_surface(const surf_edit *e, const double p[3])
{
    const cs_surface *s = &e->o->surf;
    double total = 0;
    for (int t = 0; t < e->nt0; t++) {
        const int32_t *tri = s->tris + 3 * (size_t)t;
        double a[3], b[3], c[3];
        const double *ra = sv_rest(e, tri[0]), *rb = sv_rest(e, tri[1]), *rc = sv_rest(e, tri[2]);
        for (int k = 0; k < 3; k++) {
            a[k] = ra[k] - p[k];
            b[k] = rb[k] - p[k];
            c[k] = rc[k] - p[k];
        }
        double la = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        double lb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
        double lc = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        double det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                     a[2] * (b[0] * c[1] - b[1] * c[0]);
        double ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        double bc = b[0] * c[0] + b[1] * c[1] + b[2] * c[2];
        double ca = c[0] * a[0] + c[1] * a[1] + c[2] * a[2];
        double den = la * lb * lc + ab * lc + bc * la + ca * lb;
        total += 2 * atan2(det, den);
    }
    return total / (4 * M_PI) > 0.5;
}

/*
 * The same question answered locally: the parity of the surface triangles a ray from p meets,
 * the ray walked cell by cell through the lattice (the triangles of each cell it passes: seed
 * 000 Table 1) until it leaves the object's cells. A triangle meets the ray only inside a
 * cell whose list holds it, so no other triangle can count; the direction is generic (no
 * lattice plane, edge or mesh symmetry lies along it), so the ray does not graze an edge in
 * practice, and a closing pair t, t' (the same points, reversed) is met twice or not at all.
 * Costs the cells along one line instead of every triangle of the surface.
 */
static int cmp_i32(const void *x, const void *y)
{
    int32_t a = *(const int32_t *)x, b = *(const int32_t *)y;
    return (a > b) - (a < b);
}

static int inside_by_ray(const surf_edit *e, const double p[3], const int32_t hi[3],
                         bool *inside)
{
    const cs_object *o = e->o;
    const cs_cubemesh *cm = &o->cm;
    const cs_surface *s = &o->surf;
    static const double dir[3] = {0.7548776662466927, 0.5698402909980532, 0.3247179572447460};
    ivec seen = {0};
    int32_t c[3];
    double tmax[3], tdelta[3];
    for (int k = 0; k < 3; k++) {
        const double x = (p[k] - cm->origin[k]) / cm->h;
        c[k] = (int32_t)floor(x);
        tdelta[k] = cm->h / dir[k];
        tmax[k] = (c[k] + 1 - x) * cm->h / dir[k];
    }
    /* the direction's components are all positive: once past hi + 1 on any axis, no cell of
     * the object nor a neighbour of one lies ahead */
    while (c[0] <= hi[0] + 1 && c[1] <= hi[1] + 1 && c[2] <= hi[2] + 1) {
        /* a cell the object lacks (outside it, or now another piece's) may still hold a part
         * of a triangle listed by a neighbour: its neighbours' triangles are taken instead */
        const int32_t here = cs_cubemesh_find(cm, c[0], c[1], c[2]);
        const int r = here >= 0 ? 0 : 1;
        for (int dz = -r; dz <= r; dz++)
            for (int dy = -r; dy <= r; dy++)
                for (int dx = -r; dx <= r; dx++) {
                    int32_t cell = r ? cs_cubemesh_find(cm, c[0] + dx, c[1] + dy, c[2] + dz) : here;
                    for (int j = cell >= 0 ? s->cell_tri_start[cell] : 0;
                         cell >= 0 && j < s->cell_tri_start[cell + 1]; j++)
                        if (s->cell_tri_list[j] < e->nt0 && ivec_push(&seen, s->cell_tri_list[j])) {
                            free(seen.a);
                            return -1;
                        }
                }
        const int k = tmax[0] < tmax[1] ? (tmax[0] < tmax[2] ? 0 : 2) : (tmax[1] < tmax[2] ? 1 : 2);
        c[k]++;
        tmax[k] += tdelta[k];
    }
    if (seen.n > 1)
        qsort(seen.a, (size_t)seen.n, sizeof *seen.a, cmp_i32);
    int hits = 0;
    for (int i = 0; i < seen.n; i++) {
        if (i > 0 && seen.a[i] == seen.a[i - 1])
            continue;
        const int32_t *q = s->tris + 3 * (size_t)seen.a[i];
        const double *a = sv_rest(e, q[0]), *b = sv_rest(e, q[1]), *cc = sv_rest(e, q[2]);
        double e1[3], e2[3], pv[3], tv[3], qv[3];
        for (int k = 0; k < 3; k++) {
            e1[k] = b[k] - a[k];
            e2[k] = cc[k] - a[k];
            tv[k] = p[k] - a[k];
        }
        pv[0] = dir[1] * e2[2] - dir[2] * e2[1];
        pv[1] = dir[2] * e2[0] - dir[0] * e2[2];
        pv[2] = dir[0] * e2[1] - dir[1] * e2[0];
        const double det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2];
        if (det == 0)
            continue; /* parallel to the ray */
        const double u = (tv[0] * pv[0] + tv[1] * pv[1] + tv[2] * pv[2]) / det;
        if (u < 0 || u > 1)
            continue;
        qv[0] = tv[1] * e1[2] - tv[2] * e1[1];
        qv[1] = tv[2] * e1[0] - tv[0] * e1[2];
        qv[2] = tv[0] * e1[1] - tv[1] * e1[0];
        const double v = (dir[0] * qv[0] + dir[1] * qv[1] + dir[2] * qv[2]) / det;
        if (v < 0 || u + v > 1)
            continue;
        if ((e2[0] * qv[0] + e2[1] * qv[1] + e2[2] * qv[2]) / det > 0)
            hits++;
    }
    free(seen.a);
    *inside = hits & 1;
    return 0;
}

/* Rebuild the per-cell triangle lists (seed 000 Table 1) after the surface changed. */
static int rebuild_cell_lists(cs_surface *s, const cs_cubemesh *cm)
{
    return cs_surface_build_cell_lists(s, cm, 1e-9 * cm->h);
}

/* ---------------------------------------------------------------- vertex families */

/*
 * The copies of one surface vertex made by this event, each with the cells of the triangles
 * of its group (the side it belongs to). Used to pick, for a closing triangle of cell c, the
 * copy that lies on c's side.
 */
typedef struct families {
    ivec of_old;   /* per vertex < nv0: family or -1 (allocated lazily to nv0) */
    ivec of_new;   /* per appended vertex: family or -1 */
    ivec fstart;   /* per family: first member in mcopy */
    ivec mcopy;    /* members: vertex copy */
    ivec mcstart;  /* per member: first cell in mcells (one past the last member is next) */
    ivec mcells;   /* cells of each member's group */
} families;

static int32_t family_of(const families *f, int nv0, int32_t v)
{
    if (v < nv0)
        return f->of_old.a[v];
    int i = v - nv0;
    return i < f->of_new.n ? f->of_new.a[i] : -1;
}

/* The copy of v's family attached to cell c: a member whose group has c or a cell sharing a
 * node with c; else the member whose group's cells are nearest to c; v itself if no family. */
static int32_t copy_for_cell(const cs_object *o, const families *f, int nv0, int32_t v,
                             int32_t c)
{
    int32_t fam = family_of(f, nv0, v);
    if (fam < 0)
        return v;
    int m0 = f->fstart.a[fam], m1 = fam + 1 < f->fstart.n ? f->fstart.a[fam + 1] : f->mcopy.n;
    int32_t best = v;
    long bestd = -1;
    const int32_t *cc = o->cm.cell_ijk + 3 * (size_t)c;
    for (int m = m0; m < m1; m++) {
        int c0 = f->mcstart.a[m], c1 = m + 1 < f->mcstart.n ? f->mcstart.a[m + 1] : f->mcells.n;
        for (int k = c0; k < c1; k++) {
            int32_t g = f->mcells.a[k];
            if (g == c || cells_share_node(&o->cm, g, c))
                return f->mcopy.a[m];
            const int32_t *gc = o->cm.cell_ijk + 3 * (size_t)g;
            long d = labs((long)gc[0] - cc[0]) + labs((long)gc[1] - cc[1]) +
                     labs((long)gc[2] - cc[2]);
            if (bestd < 0 || d < bestd) {
                bestd = d;
                best = f->mcopy.a[m];
            }
        }
    }
    return best;
}

static void families_free(families *f)
{
    free(f->of_old.a);
    free(f->of_new.a);
    free(f->fstart.a);
    free(f->mcopy.a);
    free(f->mcstart.a);
    free(f->mcells.a);
}

/* ---------------------------------------------------------------- corner vertices */

/* Segment p→q against triangle (a,b,c): do they intersect? (Möller–Trumbore) */
static bool seg_tri(const double p[3], const double q[3], const double *a, const double *b,
                    const double *c)
{
    double d[3], e1[3], e2[3], s[3], pv[3], qv[3];
    for (int k = 0; k < 3; k++) {
        d[k] = q[k] - p[k];
        e1[k] = b[k] - a[k];
        e2[k] = c[k] - a[k];
        s[k] = p[k] - a[k];
    }
    pv[0] = d[1] * e2[2] - d[2] * e2[1];
    pv[1] = d[2] * e2[0] - d[0] * e2[2];
    pv[2] = d[0] * e2[1] - d[1] * e2[0];
    double det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2];
    if (fabs(det) < 1e-300)
        return false;
    double u = (s[0] * pv[0] + s[1] * pv[1] + s[2] * pv[2]) / det;
    if (u < -1e-12 || u > 1 + 1e-12)
        return false;
    qv[0] = s[1] * e1[2] - s[2] * e1[1];
    qv[1] = s[2] * e1[0] - s[0] * e1[2];
    qv[2] = s[0] * e1[1] - s[1] * e1[0];
    double v = (d[0] * qv[0] + d[1] * qv[1] + d[2] * qv[2]) / det;
    if (v < -1e-12 || u + v > 1 + 1e-12)
        return false;
    double t = (e2[0] * qv[0] + e2[1] * qv[1] + e2[2] * qv[2]) / det;
    return t >= -1e-12 && t <= 1 + 1e-12;
}

/*
 * The rest position of the corner vertex of `node` (seed 000 §3.2: corner nodes get their own
 * coordinates, the lattice point plus a random delta fixed per lattice point, chosen so that
 * it does not cross the surface).
 */
/* A vertex of the mesh's own triangles lying on node's lattice point (meshes made of
 * cube faces have them), or -1: the closing surface must end on it, not beside it. Where the
 * mesh was split there, the copy used by a triangle of a cell attached to `cell` (sharing a
 * node with it) is preferred; cell < 0 takes any. With `exact` (partially opened faces: the
 * cells of both sides may still share nodes), the copy used by a triangle of a cell that holds
 * this very node copy is preferred, and *exact says whether one was found. */
static int corner_at(const cs_cubemesh *cm, int32_t c, const double p[3]);

static int32_t surface_vertex_at(const surf_edit *e, int32_t node, int32_t cell, bool *exact)
{
    const cs_object *o = e->o;
    const cs_cubemesh *cm = &o->cm;
    const cs_surface *s = &o->surf;
    const double *p = cm->node_rest + 3 * (size_t)node;
    /* meshes come from files in float32: a vertex meant to lie on the lattice point is there
     * to float precision (2^-24 of its coordinates; a closing vertex beside it, 3e-9 m away at
     * 0.1 m, collapsed onto it on the bus): 4 times that rounding of the point's largest
     * coordinate, within cs_voxel_tolerance's bounds (1e-9 h to 1e-4 h) */
    const double pm = fmax(fabs(p[0]), fmax(fabs(p[1]), fabs(p[2])));
    const double tol = fmin(1e-4 * cm->h, fmax(1e-9 * cm->h, 0x1p-22 * pm));
    int32_t li[3], any = -1, near = -1;
    for (int k = 0; k < 3; k++)
        li[k] = (int32_t)llround((p[k] - cm->origin[k]) / cm->h);
    for (int dz = -1; dz <= 0; dz++)
        for (int dy = -1; dy <= 0; dy++)
            for (int dx = -1; dx <= 0; dx++) {
                int32_t c = cs_cubemesh_find(cm, li[0] + dx, li[1] + dy, li[2] + dz);
                if (c < 0)
                    continue;
                for (int k = s->cell_tri_start[c]; k < s->cell_tri_start[c + 1]; k++) {
                    int32_t t = s->cell_tri_list[k];
                    if (t >= e->nt0 || o->tri_kind[t] != 0)
                        continue;
                    for (int j = 0; j < 3; j++) {
                        int32_t v = s->tris[3 * (size_t)t + j];
                        const double *q = sv_rest(e, v);
                        if (fabs(q[0] - p[0]) > tol || fabs(q[1] - p[1]) > tol ||
                            fabs(q[2] - p[2]) > tol)
                            continue;
                        if (cell < 0)
                            return v;
                        /* the copy on node's side: held by a triangle of a cell that has this
                         * copy of the node (where a face opened partially, the cells of both
                         * sides still share nodes) */
                        const int32_t tc = s->tri_cell[t];
                        const int kc = corner_at(cm, tc, p);
                        if (exact && kc >= 0 && cm->cell_nodes[8 * (size_t)tc + kc] == node) {
                            *exact = true;
                            return v;
                        }
                        if (!exact && cells_share_node(cm, tc, cell))
                            return v;
                        if (near < 0 && cells_share_node(cm, tc, cell))
                            near = v;
                        if (any < 0)
                            any = v;
                    }
                }
            }
    return near >= 0 ? near : any;
}

static void corner_position(const cs_world_t *w, const surf_edit *e, int32_t node,
                            double out[3], int32_t *from)
{
    const cs_object *o = e->o;
    int32_t sv = surface_vertex_at(e, node, -1, NULL);
    if (from)
        *from = -1;
    if (sv >= 0) {
        memcpy(out, sv_rest(e, sv), 3 * sizeof(double));
        return;
    }
    if (o->corner_vertex[node] >= 0) {
        memcpy(out, sv_rest(e, o->corner_vertex[node]), 3 * sizeof(double));
        if (from)
            *from = o->corner_vertex[node];
        return;
    }
    const cs_cubemesh *cm = &o->cm;
    const double *p = cm->node_rest + 3 * (size_t)node;
    int64_t li[3];
    for (int k = 0; k < 3; k++)
        li[k] = llround((p[k] - cm->origin[k]) / cm->h);
    /* Another copy of the lattice point (a node split off this one) may have its corner
     * vertex already: the same position, so that the two sides of a crack close with mirror
     * images whose volumes cancel exactly (the offset below is shrunk against the triangles
     * the object holds now, which differ from event to event and between pieces). */
    for (int dz = -1; dz <= 0; dz++)
        for (int dy = -1; dy <= 0; dy++)
            for (int dx = -1; dx <= 0; dx++) {
                int32_t c = cs_cubemesh_find(cm, (int32_t)li[0] + dx, (int32_t)li[1] + dy,
                                             (int32_t)li[2] + dz);
                if (c < 0)
                    continue;
                int32_t nd = cm->cell_nodes[8 * (size_t)c + corner_id(-dx, -dy, -dz)];
                if (nd < o->n && o->corner_vertex[nd] >= 0) {
                    memcpy(out, sv_rest(e, o->corner_vertex[nd]), 3 * sizeof(double));
                    if (from)
                        *from = o->corner_vertex[nd];
                    return;
                }
            }
    uint64_t r = mix64(w->def.seed ^ mix64((uint64_t)li[0] * 73856093u ^
                                           (uint64_t)li[1] * 19349663u ^
                                           (uint64_t)li[2] * 83492791u));
    double d[3];
    for (int k = 0; k < 3; k++) {
        r = mix64(r);
        d[k] = 0.15 * cm->h * ((double)(r >> 11) / 9007199254740992.0 * 2.0 - 1.0);
    }
    /* shrink the offset until it crosses no surface triangle near the corner */
    const cs_surface *s = &o->surf;
    for (int tries = 0; tries < 5; tries++) {
        double q[3] = {p[0] + d[0], p[1] + d[1], p[2] + d[2]};
        bool crosses = false;
        for (int dz = -1; dz <= 0 && !crosses; dz++)
            for (int dy = -1; dy <= 0 && !crosses; dy++)
                for (int dx = -1; dx <= 0 && !crosses; dx++) {
                    int32_t c = cs_cubemesh_find(cm, (int32_t)li[0] + dx, (int32_t)li[1] + dy,
                                                 (int32_t)li[2] + dz);
                    if (c < 0)
                        continue;
                    for (int k = s->cell_tri_start[c]; k < s->cell_tri_start[c + 1]; k++) {
                        int32_t t = s->cell_tri_list[k];
                        /* the mesh's own triangles only: they never move at rest, so a
                         * lattice point gets the same offset in every event */
                        if (t >= e->nt0 || o->tri_kind[t] != 0)
                            continue;
                        const int32_t *tri = s->tris + 3 * (size_t)t;
                        if (seg_tri(p, q, sv_rest(e, tri[0]), sv_rest(e, tri[1]),
                                    sv_rest(e, tri[2]))) {
                            crosses = true;
                            break;
                        }
                    }
                }
        if (!crosses)
            break;
        for (int k = 0; k < 3; k++)
            d[k] = tries == 3 ? 0.0 : 0.5 * d[k];
    }
    for (int k = 0; k < 3; k++)
        out[k] = p[k] + d[k];
}

/* The corner vertex of `node`: the mesh's vertex on it if there is one (the copy on cell's
 * side), else made on first use and bound to `cell`. Returns its index or -1. */
static int32_t corner_vertex(cs_world_t *w, surf_edit *e, const families *fam, int32_t node,
                             int32_t cell)
{
    cs_object *o = e->o;
    /* a mesh vertex on the lattice point is looked up each time (never cached: the surface
     * split moves its copies between sides) */
    bool exact = false;
    int32_t sv = surface_vertex_at(e, node, cell, e->partial ? &exact : NULL);
    if (exact)
        return sv;
    /* a corner vertex made for a node: with partial pairs each node copy names its own
     * (split_surface) and the node given is the cell's own copy; otherwise the node's own
     * entry names one copy and the cell's side decides which, through its family */
    if (sv < 0 && o->corner_vertex[node] >= 0) {
        if (e->partial)
            return o->corner_vertex[node];
        sv = o->corner_vertex[node];
    }
    if (sv >= 0) {
        /* a family's first member is the original vertex, or the copy that replaced it */
        const int32_t f = family_of(fam, e->nv0, sv);
        const int32_t orig = f >= 0 ? fam->mcopy.a[fam->fstart.a[f]] : sv;
        return copy_for_cell(o, fam, e->nv0, orig, cell);
    }
    /* a new corner vertex: a copy of another copy's of the lattice point if there is one
     * (its mirror across the crack: the same position now, so that t and t' coincide) */
    double q[3];
    int32_t from;
    corner_position(w, e, node, q, &from);
    int32_t v = from >= 0 ? sv_append_copy(e, from, cell) : sv_append(e, q, cell);
    if (v < 0)
        return -1;
    o->corner_vertex[node] = v;
    return v;
}

/* ---------------------------------------------------------------- step 2: nodes (§2.3) */

/*
 * Duplicate the nodes that the crack faces separate. *split_nodes receives every node that was
 * split (the kept original and its copies); node_src[n] is the node each node came from.
 */
static int split_nodes(cs_object *o, const crack_face *F, int nF, const pairkey *fset,
                       const int8_t *label, bool paper, ivec *touched, ivec *newsrc_out)
{
    cs_cubemesh *cm = &o->cm;
    const int n0 = cm->n_nodes;
    uint8_t *seen = calloc((size_t)n0, 1);
    ivec cand = {0}, newsrc = {0};
    int rc = -1;
    if (!seen)
        return -1;
    for (int i = 0; i < nF; i++) {
        int cs[4];
        int dir = F[i].c1_below ? 1 : -1;
        face_corners(F[i].axis, dir > 0 ? 1 : 0, cs);
        for (int k = 0; k < 4; k++) {
            int32_t nd = cm->cell_nodes[8 * (size_t)F[i].c1 + cs[k]];
            if (!seen[nd]) {
                seen[nd] = 1;
                if (ivec_push(&cand, nd))
                    goto out;
            }
        }
    }
    for (int i = 0; i < cand.n; i++) {
        const int32_t nd = cand.a[i];
        int32_t cells[64], corner[64], parent[64] = {0};
        int m = 0;
        for (int a = o->fem.adj_start[nd]; a < o->fem.adj_start[nd + 1] && m < 64; a++) {
            cells[m] = o->fem.adj[a] / 8;
            corner[m] = o->fem.adj[a] % 8;
            parent[m] = m;
            m++;
        }
        if (m == 0)
            continue;
        for (int a = 0; a < m && !paper; a++)
            for (int b = a + 1; b < m; b++) {
                int dir;
                int axis = face_axis(cm, cells[a], cells[b], &dir);
                if (axis < 0 || in_pairs(fset, nF, cells[a], cells[b]))
                    continue;
                if (face_joined(o, cells[a], cells[b], axis, dir))
                    uf_union(parent, a, b);
            }
        if (paper) {
            /* §2.3 as written: every − cell at the node is relinked to one duplicate; + and
             * unlabelled cells keep it (at the rim the − cells tear from their unlabelled
             * neighbours there, so that the crack opens at once) */
            int minus = -1, rest = -1;
            for (int a = 0; a < m; a++) {
                int *first = label[cells[a]] < 0 ? &minus : &rest;
                if (*first < 0)
                    *first = a;
                parent[a] = *first;
            }
        }
        /* the group of a + cell keeps the node; the others (the minus side) get copies */
        int keep = -1;
        for (int a = 0; a < m && keep < 0; a++)
            if (label[cells[a]] > 0)
                keep = uf_find(parent, a);
        if (keep < 0)
            keep = uf_find(parent, 0);
        int32_t copy_of_root[64];
        for (int a = 0; a < m; a++)
            copy_of_root[a] = -1;
        bool split = false;
        for (int a = 0; a < m; a++) {
            int r = uf_find(parent, a);
            if (r == keep)
                continue;
            if (copy_of_root[r] < 0) {
                copy_of_root[r] = n0 + newsrc.n;
                if (ivec_push(&newsrc, nd) || ivec_push(touched, copy_of_root[r]))
                    goto out;
                split = true;
            }
            cm->cell_nodes[8 * (size_t)cells[a] + corner[a]] = copy_of_root[r];
        }
        if (split && ivec_push(touched, nd))
            goto out;
    }
    if (newsrc.n > 0) {
        const int n1 = n0 + newsrc.n;
        if (resize(&cm->node_rest, 3 * sizeof(double), (size_t)n1) ||
            resize(&o->x, 3 * sizeof(double), (size_t)n1) ||
            resize(&o->v, 3 * sizeof(double), (size_t)n1) ||
            resize(&o->mask, 3, (size_t)n1) || resize(&o->contact, 1, (size_t)n1) ||
            resize(&o->ground, 3 * sizeof(double), (size_t)n1) ||
            resize(&o->pin, 1, (size_t)n1) ||
            resize(&o->corner_vertex, sizeof(int32_t), (size_t)n1))
            goto out;
        for (int j = 0; j < newsrc.n; j++) {
            const int32_t s = newsrc.a[j], d = n0 + j;
            memcpy(cm->node_rest + 3 * (size_t)d, cm->node_rest + 3 * (size_t)s,
                   3 * sizeof(double));
            memcpy(o->x + 3 * (size_t)d, o->x + 3 * (size_t)s, 3 * sizeof(double));
            memcpy(o->v + 3 * (size_t)d, o->v + 3 * (size_t)s, 3 * sizeof(double));
            memcpy(o->mask + 3 * (size_t)d, o->mask + 3 * (size_t)s, 3);
            o->pin[d] = o->pin[s];
            o->contact[d] = o->contact[s];
            memcpy(o->ground + 3 * (size_t)d, o->ground + 3 * (size_t)s, 3 * sizeof(double));
            o->corner_vertex[d] = -1; /* assigned when the surface is split */
        }
        cm->n_nodes = n1;
    }
    rc = newsrc.n;
    *newsrc_out = newsrc;
    newsrc = (ivec){0};
out:
    free(seen);
    free(cand.a);
    free(newsrc.a);
    return rc;
}

/* After nodes changed: masses, constant forces (gravity plus the old nodes' load shares split
 * by mass) and every per-node work array at the new size. */
static int refresh_node_state(cs_world_t *w, cs_object *o, int n_old, const ivec *newsrc)
{
    const cs_cubemesh *cm = &o->cm;
    const int n1 = cm->n_nodes;
    const double *g = w->def.gravity;
    double *load = malloc((size_t)n_old * 3 * sizeof *load);
    double *m_old = malloc((size_t)n_old * sizeof *m_old);
    if (!load || !m_old) {
        free(load);
        free(m_old);
        return -1;
    }
    for (int i = 0; i < n_old; i++) {
        m_old[i] = o->m[i];
        for (int a = 0; a < 3; a++)
            load[3 * i + a] = o->f_const[3 * i + a] - o->m[i] * g[a];
    }
    if (resize(&o->m, sizeof(double), (size_t)n1) ||
        resize(&o->f_const, 3 * sizeof(double), (size_t)n1) ||
        resize(&o->f, 3 * sizeof(double), (size_t)n1) ||
        resize(&o->b, 3 * sizeof(double), (size_t)n1) ||
        resize(&o->v1, 3 * sizeof(double), (size_t)n1) ||
        resize(&o->blocks, 9 * sizeof(double), (size_t)n1) ||
        resize(&o->smask, 3, (size_t)n1)) {
        free(load);
        free(m_old);
        return -1;
    }
    /* the masses of the density field (world_internal.h) at the new node count */
    o->n = n1;
    if (cs_object_lump_mass(o) != 0) {
        free(load);
        free(m_old);
        return -1;
    }
    /* A split node's cells are shared out among its copies, so their masses add up to the
     * old node's: each copy takes the load share of its mass fraction. */
    for (int i = 0; i < n1; i++) {
        const int32_t src = i < n_old ? i : newsrc->a[i - n_old];
        const double share = m_old[src] > 0 ? o->m[i] / m_old[src] : 0.0;
        for (int a = 0; a < 3; a++)
            o->f_const[3 * i + a] = o->m[i] * g[a] + share * load[3 * src + a];
    }
    free(load);
    free(m_old);
    o->n = n1;
    o->n_fixed_nodes = 0;
    for (int i = 0; i < n1; i++)
        if ((o->mask[3 * i] && o->mask[3 * i + 1] && o->mask[3 * i + 2]) || o->pin[i])
            o->n_fixed_nodes++;
    cs_cg_work_free(&o->cg);
    if (cs_cg_work_init(&o->cg, 3 * n1) != 0 || cs_elastic_relink(o) != 0)
        return -1;
    o->elastic_energy_valid = false;
    return 0;
}

/* The cell of c's corner at the lattice point of node position p, or -1. */
static int corner_at(const cs_cubemesh *cm, int32_t c, const double p[3])
{
    int off[3];
    for (int k = 0; k < 3; k++) {
        long l = lround((p[k] - cm->origin[k]) / cm->h) - cm->cell_ijk[3 * (size_t)c + k];
        if (l < 0 || l > 1)
            return -1;
        off[k] = (int)l;
    }
    return corner_id(off[0], off[1], off[2]);
}

/* ---------------------------------------------------------------- step 3: surface (§3.1) */

/* Do cells a and b share a node in the links `cn` (8 per cell)? */
static bool cells_share_node_in(const int32_t *cn, int32_t a, int32_t b)
{
    const int32_t *na = cn + 8 * (size_t)a, *nb = cn + 8 * (size_t)b;
    for (int i = 0; i < 8; i++)
        for (int j = 0; j < 8; j++)
            if (na[i] == nb[j])
                return true;
    return false;
}

/* How many of a's eight node slots hold a node that b holds too. */
static int shared_nodes(const int32_t *a, const int32_t *b)
{
    int n = 0;
    for (int i = 0; i < 8; i++)
        for (int j = 0; j < 8; j++)
            if (a[i] == b[j]) {
                n++;
                break;
            }
    return n;
}

/* Is rest point p held between cells a and b: on their common face, edge or corner, where
 * every node of a with weight at p (the corners of the smallest part of a's boundary holding
 * p) is b's too? There the two cells' trilinear maps agree, so the surface stays whole. */
static bool held_point(const cs_cubemesh *cm, int32_t a, int32_t b, const double *p)
{
    const int32_t *ia = cm->cell_ijk + 3 * (size_t)a, *ib = cm->cell_ijk + 3 * (size_t)b;
    const double tol = 1e-9 * cm->h;
    int fix[3]; /* -1 free, else the corner offset (0/1) p lies on */
    for (int k = 0; k < 3; k++) {
        const double lo = cm->origin[k] + cm->h * (ia[k] > ib[k] ? ia[k] : ib[k]);
        const double hi = cm->origin[k] + cm->h * ((ia[k] < ib[k] ? ia[k] : ib[k]) + 1);
        if (p[k] < lo - tol || p[k] > hi + tol)
            return false; /* off the common part */
        const double x = (p[k] - cm->origin[k]) / cm->h - ia[k];
        fix[k] = fabs(x) <= 1e-9 ? 0 : fabs(x - 1) <= 1e-9 ? 1 : -1;
    }
    const int32_t *na = cm->cell_nodes + 8 * (size_t)a, *nb = cm->cell_nodes + 8 * (size_t)b;
    for (int c = 0; c < 8; c++) {
        if ((fix[0] >= 0 && CS_CORNER[c][0] != fix[0]) ||
            (fix[1] >= 0 && CS_CORNER[c][1] != fix[1]) ||
            (fix[2] >= 0 && CS_CORNER[c][2] != fix[2]))
            continue;
        bool shared = false;
        for (int j = 0; j < 8 && !shared; j++)
            shared = na[c] == nb[j];
        if (!shared)
            return false;
    }
    return true;
}

/* Are triangles t and u, in cells ct and cu, separated by this event along their common edge
 * (rest points p, q)? Their cells shared a node before and share fewer now: a node they shared
 * was split between them, so the cube mesh came apart between them there, fully (they share
 * none now) or partially (a face or edge still held at its other nodes: the surface separates
 * across it, and the closing pair of each face that opened, glued along its still-shared
 * corners, closes the slit) — except along an edge that lies where the cells are still held
 * (a mesh edge on the line between two still-shared corners). */
static bool tri_cut(const cs_object *o, const int32_t *cn0, int32_t ct, int32_t cu,
                    const double *p, const double *q, bool partial)
{
    if (ct == cu)
        return false;
    if (!partial) /* shared a node before, none now */
        return cells_share_node_in(cn0, ct, cu) && !cells_share_node(&o->cm, ct, cu);
    const int before = shared_nodes(cn0 + 8 * (size_t)ct, cn0 + 8 * (size_t)cu);
    if (before == 0)
        return false;
    const int32_t *cn = o->cm.cell_nodes;
    const int now = shared_nodes(cn + 8 * (size_t)ct, cn + 8 * (size_t)cu);
    return now == 0 ||
           (now < before && !(held_point(&o->cm, ct, cu, p) && held_point(&o->cm, ct, cu, q)));
}

static double dist2_cell(const cs_cubemesh *cm, int32_t c, const double p[3])
{
    double d = 0;
    for (int k = 0; k < 3; k++) {
        double x = cm->origin[k] + cm->h * (cm->cell_ijk[3 * (size_t)c + k] + 0.5) - p[k];
        d += x * x;
    }
    return d;
}

/* parent[c] (union-find over the cells): face neighbours still sharing a node of their face
 * joined (what split_pieces and piece_roots call one piece). */
static void union_face_neighbours(const cs_cubemesh *cm, int32_t *parent)
{
    const int nc = cm->n_cells;
    for (int c = 0; c < nc; c++)
        parent[c] = c;
    for (int c = 0; c < nc; c++) {
        const int32_t *q = cm->cell_ijk + 3 * (size_t)c;
        for (int axis = 0; axis < 3; axis++) {
            int32_t nb[3] = {q[0], q[1], q[2]};
            nb[axis]++;
            int32_t d = cs_cubemesh_find(cm, nb[0], nb[1], nb[2]);
            if (d >= 0 && cells_share_node(cm, c, d))
                uf_union(parent, c, d);
        }
    }
}

/* Per cell, the root of its piece as split_pieces will find it. NULL if out of memory. */
static int32_t *piece_roots(const cs_cubemesh *cm)
{
    const int nc = cm->n_cells;
    int32_t *parent = malloc((size_t)(nc ? nc : 1) * sizeof *parent);
    if (!parent)
        return NULL;
    union_face_neighbours(cm, parent);
    for (int c = 0; c < nc; c++)
        parent[c] = uf_find(parent, c);
    return parent;
}

/*
 * Split the surface along the crack: vertex groups by uncut edges, one copy per group beyond
 * the first, bound to a cell of the group's side (the first group too when it is not on the
 * vertex's side: the vertex is then left unused). Fills fam (vertex families) and marks
 * rewired triangles.
 */
static int split_surface(cs_object *o, surf_edit *e, const int32_t *cn0, const int32_t *tris0,
                         const uint8_t *affected_cell, const int32_t *corner_of, families *fam)
{
    cs_surface *s = &o->surf;
    const int nv = e->nv0, nt = e->nt0;
    int32_t *vstart = calloc((size_t)nv + 1, sizeof *vstart), *vtris = NULL;
    uint8_t *vdone = calloc((size_t)nv, 1);
    int rc = -1;
    if (!vstart || !vdone)
        goto out;
    fam->of_old.a = malloc((size_t)(nv ? nv : 1) * sizeof(int32_t));
    if (!fam->of_old.a)
        goto out;
    fam->of_old.n = fam->of_old.cap = nv;
    for (int i = 0; i < nv; i++)
        fam->of_old.a[i] = -1;
    for (int i = 0; i < 3 * nt; i++)
        vstart[tris0[i] + 1]++;
    for (int i = 0; i < nv; i++)
        vstart[i + 1] += vstart[i];
    vtris = malloc((size_t)(nt ? nt : 1) * 3 * sizeof *vtris);
    int32_t *fill = malloc((size_t)(nv ? nv : 1) * sizeof *fill);
    if (!vtris || !fill) {
        free(fill);
        goto out;
    }
    memcpy(fill, vstart, (size_t)nv * sizeof *fill);
    for (int t = 0; t < nt; t++)
        for (int k = 0; k < 3; k++)
            vtris[fill[tris0[3 * t + k]]++] = t;
    free(fill);

    for (int t0 = 0; t0 < nt; t0++) {
        if (!affected_cell[s->tri_cell[t0]])
            continue;
        for (int k0 = 0; k0 < 3; k0++) {
            const int32_t v = tris0[3 * t0 + k0];
            if (vdone[v])
                continue;
            vdone[v] = 1;
            const int m = vstart[v + 1] - vstart[v];
            const int32_t *T = vtris + vstart[v];
            int32_t pbuf[64], *parent = m <= 64 ? pbuf : malloc((size_t)m * sizeof *parent);
            if (!parent)
                goto out;
            /* A corner vertex (§3.2) made for a node, used only by closing triangles. Where
             * partially opened faces get their closing pairs (e->partial), it splits with its
             * node: one vertex per node copy (tn: the node copy of each triangle's cell);
             * every face that opened at all has its pair, glued at the corners its cells still
             * share, so around a lattice edge the pairs of the opened faces meet over the
             * corner vertices of the node copies between them (a partially opened face's t and
             * t' share the vertex of a shared corner and part at a separated one). Otherwise
             * it splits like any surface vertex: where the triangles' cells stop sharing a
             * node; splitting it per node copy there opened slits at a crack's rim (the node
             * split, the cells still sharing another node: a partially opened face without a
             * pair). Either way each copy of the node then names the vertex copy of its
             * cells' group. */
            /* corner_of: the node, or -2 - node for a second vertex of the node (a cavity of
             * its own, split_glued): grouped the same way, but the node keeps naming its own */
            const bool named = corner_of[v] >= 0;
            int32_t cnode = named ? corner_of[v] : corner_of[v] <= -2 ? -2 - corner_of[v] : -1;
            int32_t tn_buf[64], *tn = NULL;
            for (int a = 0; cnode >= 0 && a < m; a++)
                if (o->tri_kind[T[a]] == 0)
                    cnode = -1;
            if (cnode >= 0) {
                tn = m <= 64 ? tn_buf : malloc((size_t)m * sizeof *tn);
                if (!tn)
                    goto out_p;
                const double *p = o->cm.node_rest + 3 * (size_t)cnode;
                for (int a = 0; a < m; a++) {
                    const int32_t ct = s->tri_cell[T[a]];
                    const int k = corner_at(&o->cm, ct, p);
                    tn[a] = k >= 0 ? o->cm.cell_nodes[8 * (size_t)ct + k] : cnode;
                }
            }
            for (int a = 0; a < m; a++)
                parent[a] = a;
            for (int a = 0; a < m; a++)
                for (int b = a + 1; b < m; b++) {
                    if (cnode >= 0 && e->partial) {
                        if (tn[a] == tn[b])
                            uf_union(parent, a, b);
                        continue;
                    }
                    const int32_t *ta = tris0 + 3 * (size_t)T[a], *tb = tris0 + 3 * (size_t)T[b];
                    int32_t other = -1;
                    for (int i = 0; i < 3 && other < 0; i++)
                        for (int j = 0; j < 3; j++)
                            if (ta[i] != v && ta[i] == tb[j]) {
                                other = ta[i];
                                break;
                            }
                    const int32_t ca = s->tri_cell[T[a]], cb = s->tri_cell[T[b]];
                    if (other >= 0 && !tri_cut(o, cn0, ca, cb, s->rest + 3 * (size_t)v,
                                               s->rest + 3 * (size_t)other, e->partial) &&
                        (!e->piece || e->piece[ca] == e->piece[cb]))
                        uf_union(parent, a, b);
                }
            /* groups in order of their root; the group whose cells hold the vertex's binding
             * keeps the vertex */
            int n_groups = 0, keep = -1;
            int32_t roots[64];
            for (int a = 0; a < m; a++) {
                int r = uf_find(parent, a);
                bool known = false;
                for (int g = 0; g < n_groups; g++)
                    known |= roots[g] == r;
                if (!known && n_groups < 64)
                    roots[n_groups++] = r;
            }
            const int32_t vc = s->vert_cell[v];
            for (int g = 0; cnode >= 0 && g < n_groups && keep < 0; g++)
                for (int a = 0; a < m && keep < 0; a++)
                    if (uf_find(parent, a) == roots[g] && tn[a] == cnode)
                        keep = g;
            if (cnode >= 0 && keep < 0)
                keep = 0;
            for (int g = 0; g < n_groups && keep < 0; g++)
                for (int a = 0; a < m; a++)
                    if (uf_find(parent, a) == roots[g] && s->tri_cell[T[a]] == vc) {
                        keep = g;
                        break;
                    }
            for (int g = 0; g < n_groups && keep < 0; g++)
                for (int a = 0; a < m; a++)
                    if (uf_find(parent, a) == roots[g] &&
                        cells_share_node(&o->cm, s->tri_cell[T[a]], vc)) {
                        keep = g;
                        break;
                    }
            if (keep < 0)
                keep = 0;
            const int32_t famid = fam->fstart.n;
            if (ivec_push(&fam->fstart, fam->mcopy.n))
                goto out_p;
            fam->of_old.a[v] = famid;
            if (cnode >= 0 && named)
                o->corner_vertex[cnode] = -1; /* set again below for the node copy keeping v */
            for (int gi = 0; gi < n_groups; gi++) {
                /* keep first so that the family's first member is v (or its copy) */
                const int g = gi == 0 ? keep : (gi <= keep ? gi - 1 : gi);
                /* bound cell: v's own if its side, else the group's cell nearest to v */
                int32_t bind = -1;
                double bd = INFINITY;
                bool own = false;
                if (ivec_push(&fam->mcstart, fam->mcells.n))
                    goto out_p;
                for (int a = 0; a < m; a++) {
                    if (uf_find(parent, a) != roots[g])
                        continue;
                    int32_t c = s->tri_cell[T[a]];
                    if (ivec_push(&fam->mcells, c))
                        goto out_p;
                    if (cnode < 0 && (c == vc || (cells_share_node(&o->cm, c, vc) &&
                                                  (!e->piece || e->piece[c] == e->piece[vc]))))
                        own = true;
                    if (cnode >= 0 && c == vc)
                        own = true; /* a corner vertex stays bound to a cell of its node */
                    double d = dist2_cell(&o->cm, c, s->rest + 3 * (size_t)v);
                    if (d < bd) {
                        bd = d;
                        bind = c;
                    }
                }
                int32_t copy = v;
                /* A group not on v's side (no cell of it is v's cell or shares a node with
                 * it in the same piece) gets a copy of v bound to its side, skinned there;
                 * the first group too: v is then left unused, bound and placed as before.
                 * (Rebinding v in place moved a vertex the clients hold, which a topology
                 * change cannot say, or left it where its old side is until the next skin:
                 * across an open crack, or in another piece.) */
                if (gi > 0 || !own) {
                    copy = sv_append_copy(e, v, bind);
                    if (copy < 0)
                        goto out_p;
                    while (e->vcell.n > fam->of_new.n)
                        if (ivec_push(&fam->of_new, -1))
                            goto out_p;
                    fam->of_new.a[copy - nv] = famid;
                    for (int a = 0; a < m; a++) {
                        if (uf_find(parent, a) != roots[g])
                            continue;
                        int32_t *tri = s->tris + 3 * (size_t)T[a];
                        for (int k = 0; k < 3; k++)
                            if (tris0[3 * (size_t)T[a] + k] == v)
                                tri[k] = copy;
                        e->rewired[T[a]] = 1;
                    }
                }
                if (ivec_push(&fam->mcopy, copy))
                    goto out_p;
                for (int a = 0; cnode >= 0 && a < m; a++)
                    if (uf_find(parent, a) == roots[g] && (named || o->corner_vertex[tn[a]] < 0))
                        o->corner_vertex[tn[a]] = copy;
            }
            if (parent != pbuf)
                free(parent);
            if (tn != tn_buf)
                free(tn);
            continue;
        out_p:
            if (parent != pbuf)
                free(parent);
            if (tn != tn_buf)
                free(tn);
            goto out;
        }
    }
    rc = 0;
    e->tris0 = tris0;
    e->vstart = vstart;
    e->vtris = vtris;
    vstart = vtris = NULL;
out:
    free(vstart);
    free(vtris);
    free(vdone);
    return rc;
}

/* ---------------------------------------------------------------- step 4: closing (§3.2) */

/* The square of crack face f and its corner nodes on each side, corner k in the positive
 * sense about n_f (closing.h). */
static void face_setup(const cs_object *o, const crack_face *f, cs_close_face *cf,
                       int32_t node1[4], int32_t node2[4], double centre[3])
{
    const cs_cubemesh *cm = &o->cm;
    const int ax = f->axis, u = (ax + 1) % 3, v = (ax + 2) % 3;
    const int32_t *ijk = cm->cell_ijk + 3 * (size_t)f->c1;
    memset(cf, 0, sizeof *cf);
    cf->axis = ax;
    cf->c1_below = f->c1_below;
    /* the boundary-node rule that depends only on the triangle and f's edge line, so that the
     * closings of two opened faces sharing an edge meet (§3.2's own rule picks the vertex by
     * the other node in each face and leaves cracks across several faces open) */
    cf->boundary_rule = CS_CLOSE_BOUNDARY_SHARED;
    cf->plane = cm->origin[ax] + cm->h * (ijk[ax] + (f->c1_below ? 1 : 0));
    for (int k = 0; k < 3; k++) {
        cf->lo[k] = cm->origin[k] + cm->h * ijk[k];
        cf->hi[k] = cf->lo[k] + cm->h;
        centre[k] = cf->lo[k] + 0.5 * cm->h;
    }
    centre[ax] = cf->plane;
    /* (u,v) offsets of the corners in the positive sense about +e_ax, reversed about -e_ax */
    static const int pos_uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    static const int neg_uv[4][2] = {{0, 0}, {0, 1}, {1, 1}, {1, 0}};
    for (int k = 0; k < 4; k++) {
        const int *uv = f->c1_below ? pos_uv[k] : neg_uv[k];
        int off[3];
        off[ax] = f->c1_below ? 1 : 0;
        off[u] = uv[0];
        off[v] = uv[1];
        node1[k] = cm->cell_nodes[8 * (size_t)f->c1 + corner_id(off[0], off[1], off[2])];
        off[ax] = 1 - off[ax];
        node2[k] = cm->cell_nodes[8 * (size_t)f->c2 + corner_id(off[0], off[1], off[2])];
    }
}

/* Does triangle q lie in one of the planes through f's four edges (perpendicular to f)? Such
 * a triangle (the side of a box-shaped surface) touches f only along f's boundary and never
 * bounds the region of f inside the surface; left in, its crossings lie exactly on f's edge
 * lines, where a neighbouring closing triangle of an earlier fracture may stand in for its
 * other side. */
static bool on_side_plane(const cs_close_face *cf, const double *rest, const int32_t *q,
                          double tol)
{
    for (int a = 0; a < 3; a++) {
        if (a == cf->axis)
            continue;
        for (int side = 0; side < 2; side++) {
            const double x = side ? cf->hi[a] : cf->lo[a];
            if (fabs(rest[3 * (size_t)q[0] + a] - x) <= tol &&
                fabs(rest[3 * (size_t)q[1] + a] - x) <= tol &&
                fabs(rest[3 * (size_t)q[2] + a] - x) <= tol)
                return true;
        }
    }
    return false;
}

/* A patch: the closing triangles of one crack face for one side. */
typedef struct patch_list {
    ivec tri;    /* 3 per triangle */
    ivec cell;   /* per triangle */
    ivec group;  /* per triangle: the crack face; t and t' are kept or dropped together so
                    that the two sides stay mirror images */
} patch_list;

static int close_faces(cs_world_t *w, cs_object *o, surf_edit *e, const int32_t *tris0,
                       const crack_face *F, int nF, const int8_t *label, const families *fam,
                       patch_list *pl)
{
    const cs_surface *s = &o->surf;
    ivec cand = {0};
    uint8_t *side = NULL;
    int32_t *out = NULL;
    int cap_side = 0, rc = -1, n_groups = 0;
    /* the rest positions closing.c sees: the surface's, then the four corners of the face at
     * hand (ids nv0 .. nv0+3) */
    double *xr = malloc(((size_t)e->nv0 + 4) * 3 * sizeof *xr);
    if (!xr)
        return -1;
    /* the upper corner of the object's lattice box: rays (all going up) end beyond it */
    int32_t hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
    for (int c = 0; nF > 0 && c < o->cm.n_cells; c++)
        for (int k = 0; k < 3; k++)
            if (o->cm.cell_ijk[3 * (size_t)c + k] > hi[k])
                hi[k] = o->cm.cell_ijk[3 * (size_t)c + k];
    memcpy(xr, s->rest, (size_t)e->nv0 * 3 * sizeof *xr);
    for (int i = 0; i < nF; i++) {
        const crack_face *f = &F[i];
        cs_close_face cf;
        int32_t n1[4], n2[4];
        double centre[3];
        face_setup(o, f, &cf, n1, n2, centre);
        const bool partial = n1[0] == n2[0] || n1[1] == n2[1] || n1[2] == n2[2] || n1[3] == n2[3];
        for (int k = 0; k < 4; k++) {
            cf.corner_vertex[k] = e->nv0 + k;
            corner_position(w, e, n1[k], xr + 3 * ((size_t)e->nv0 + k), NULL);
        }
        /* §3.2 tests the triangles meeting c1; those meeting c2 are added so that both
         * triangles of every edge crossing f are seen even when rounding puts one of them
         * just outside c1 (triangles not crossing f are ignored) */
        int attempt = 0;
    retry:
        /* First the mesh's own triangles; if they leave an edge crossing f with one side only
         * (its other triangle is a closing triangle of an earlier fracture), all triangles. */
        cand.n = 0;
        for (int sd = 0; sd < 2; sd++) {
            const int32_t c = sd ? f->c2 : f->c1;
            for (int k = s->cell_tri_start[c]; k < s->cell_tri_start[c + 1]; k++) {
                int32_t t = s->cell_tri_list[k];
                bool dup = false;
                for (int j = 0; sd && j < cand.n && !dup; j++)
                    dup = cand.a[j] == t;
                if (t < e->nt0 && (attempt || o->tri_kind[t] == 0) && !dup &&
                    !on_side_plane(&cf, s->rest, tris0 + 3 * (size_t)t, 1e-9 * o->cm.h) &&
                    ivec_push(&cand, t))
                    goto out;
            }
        }
        if (cand.n > cap_side) {
            cap_side = cand.n;
            if (resize(&side, 1, (size_t)cap_side))
                goto out;
        }
        for (int k = 0; k < cand.n; k++) {
            int32_t ct = s->tri_cell[cand.a[k]];
            /* on c1's side: c1 itself, or attached to c1 and not to c2 (after the split);
             * where that does not decide, the side of f the cell lies on if f is still held
             * at a corner (both sides' cells share nodes there), else the plane's label */
            bool s1 = cells_share_node(&o->cm, ct, f->c1), s2 = cells_share_node(&o->cm, ct, f->c2);
            if (ct == f->c1 || ct == f->c2)
                side[k] = ct == f->c1;
            else if (s1 != s2)
                side[k] = s1;
            else if (partial) {
                const int32_t lt = o->cm.cell_ijk[3 * (size_t)ct + f->axis],
                              l1 = o->cm.cell_ijk[3 * (size_t)f->c1 + f->axis];
                side[k] = f->c1_below ? lt <= l1 : lt >= l1;
            }
            else
                side[k] = label[ct] == label[f->c1] && label[ct] != 0;
        }
        /* a cell no mesh triangle meets lies inside the surface (seed 000 §2.1) */
        bool inside = true;
        if (cand.n > 0 && inside_by_ray(e, centre, hi, &inside))
            goto out;
        for (int k = 0; k < 4; k++)
            cf.corner_inside[k] = inside;
        int cap = 8 * cand.n + 16;
        int32_t *grown = realloc(out, (size_t)cap * 3 * sizeof *out);
        if (!grown)
            goto out;
        out = grown;
        char why[160];
        int nt = cs_close_face_triangles(&cf, xr, tris0, cand.a, cand.n, side, out, cap,
                                         why, sizeof why);
        if (nt < 0 && attempt++ == 0)
            goto retry;
        /* The whole face (two triangles over its corners, in the positive sense): where t and
         * t' share corners (nodes still joined), the diagonal must not join two shared ones, or
         * t and t' would both use it in each direction. */
        if (nt == 2) {
            bool corners = true;
            for (int k = 0; k < 6; k++)
                corners &= out[k] >= e->nv0 && out[k] < e->nv0 + 4;
            if (corners) {
                const int d = n1[0] == n2[0] && n1[2] == n2[2] ? 1 : 0;
                const int32_t b = e->nv0;
                const int32_t q[6] = {b + d, b + d + 1, b + (d + 2) % 4,
                                      b + d, b + (d + 2) % 4, b + (d + 3) % 4};
                memcpy(out, q, sizeof q);
            }
        }
        if (nt < 0)
            continue; /* the repair closes what is left open */
        /* t for c1 and t' for c2 are kept or dropped together (one group per pair), so that
         * the two sides stay mirror images and their volumes cancel */
        for (int t = 0; t < nt; t++) {
            int32_t m[2][3];
            bool ok = true;
            for (int sd = 0; sd < 2 && ok; sd++) {
                const int32_t cell = sd == 0 ? f->c1 : f->c2;
                const int32_t *nodes = sd == 0 ? n1 : n2;
                for (int k = 0; k < 3 && ok; k++) {
                    int32_t id = out[3 * t + k];
                    if (id >= e->nv0 && id < e->nv0 + 4)
                        m[sd][k] = corner_vertex(w, e, fam, nodes[id - e->nv0], cell);
                    else if (id >= 0 && id < e->nv0)
                        m[sd][k] = copy_for_cell(o, fam, e->nv0, id, cell);
                    else
                        m[sd][k] = -1;
                    ok = m[sd][k] >= 0;
                }
                ok = ok && m[sd][0] != m[sd][1] && m[sd][1] != m[sd][2] && m[sd][0] != m[sd][2];
            }
            if (!ok)
                continue;
            /* t and t' over the same three vertices (a part of a partially opened face held at
             * every corner of it): they cancel, and would only give its edges two more uses */
            if (m[0][0] == m[1][0] && m[0][1] == m[1][1] && m[0][2] == m[1][2])
                continue;
            /* t for c1 as given (normal along n_f); t' for c2 reversed */
            if (ivec_push3(&pl->tri, m[0][0], m[0][1], m[0][2]) || ivec_push(&pl->cell, f->c1) ||
                ivec_push(&pl->group, n_groups) ||
                ivec_push3(&pl->tri, m[1][0], m[1][2], m[1][1]) || ivec_push(&pl->cell, f->c2) ||
                ivec_push(&pl->group, n_groups))
                goto out;
            n_groups++;
        }
    }
    rc = 0;
out:
    free(xr);
    free(cand.a);
    free(side);
    free(out);
    return rc;
}

/* ---------------------------------------------------------------- step 5: repair */

static bool tri_degenerate(const double *a, const double *b, const double *c)
{
    double e1[3], e2[3], x[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = b[k] - a[k];
        e2[k] = c[k] - a[k];
    }
    x[0] = e1[1] * e2[2] - e1[2] * e2[1];
    x[1] = e1[2] * e2[0] - e1[0] * e2[2];
    x[2] = e1[0] * e2[1] - e1[1] * e2[0];
    double l1 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2];
    double l2 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2];
    return x[0] * x[0] + x[1] * x[1] + x[2] * x[2] <= 1e-20 * l1 * l2;
}

static int cmp64(const void *x, const void *y)
{
    int64_t a = *(const int64_t *)x, b = *(const int64_t *)y;
    return (a > b) - (a < b);
}

/* Triangle i of the edit: an original (rewired) one or an appended one. */
static int32_t *edit_tri(surf_edit *e, ivec *tri, int i)
{
    return i < e->nt0 ? e->o->surf.tris + 3 * (size_t)i : tri->a + 3 * (size_t)(i - e->nt0);
}

static int32_t edit_tri_cell(const surf_edit *e, const ivec *cell, int i)
{
    return i < e->nt0 ? e->o->surf.tri_cell[i] : cell->a[i - e->nt0];
}

static bool is_boundary(edge_map *em, int32_t a, int32_t b)
{
    return edge_get(em, a, b) == 1 && edge_get(em, b, a) == 0;
}

/*
 * The part of the surface the repair looks at. Before the event the surface was closed, so an
 * edge can be open afterwards only if a triangle holding it changed: a rewired triangle (its
 * edges now or before) or an appended one. Their vertices are marked (vmark, per vertex
 * < nv0; every vertex appended by the event counts as marked), and the triangles to count
 * edges over are those holding a marked vertex (list: the original ones; the appended ones
 * always count), which the split's vertex → triangle lists give (a rewired triangle only
 * trades vertices for new copies, so an original vertex's triangles now are among its
 * triangles before). An edge is looked at only if both its ends are marked: then every
 * triangle holding it is counted. Without the split's lists (closing a piece's loops) the
 * region is the whole surface (vmark NULL, list NULL).
 */
typedef struct region {
    uint8_t *vmark;
    int32_t *list;
    int n_list;
} region;

static void region_free(region *rg)
{
    free(rg->vmark);
    free(rg->list);
    memset(rg, 0, sizeof *rg);
}

static bool marked(const region *rg, const surf_edit *e, int32_t v)
{
    return !rg->vmark || v >= e->nv0 || rg->vmark[v];
}

static bool open_edge(edge_map *em, const region *rg, const surf_edit *e, int32_t a, int32_t b)
{
    return marked(rg, e, a) && marked(rg, e, b) && is_boundary(em, a, b);
}

/* Triangles the region walks: its original ones, then every appended one. */
static int region_count(const region *rg, const surf_edit *e, const ivec *cell)
{
    return (rg->list ? rg->n_list : e->nt0) + cell->n;
}

static int region_tri(const region *rg, const surf_edit *e, int i)
{
    const int n0 = rg->list ? rg->n_list : e->nt0;
    return i < n0 ? (rg->list ? rg->list[i] : i) : e->nt0 + (i - n0);
}

static int repair_region(const surf_edit *e, const patch_list *pl, region *rg)
{
    memset(rg, 0, sizeof *rg);
    if (!e->vstart)
        return 0;
    const cs_surface *s = &e->o->surf;
    ivec vs = {0}, tl = {0};
    uint8_t *tmark = calloc((size_t)(e->nt0 ? e->nt0 : 1), 1);
    rg->vmark = calloc((size_t)(e->nv0 ? e->nv0 : 1), 1);
    if (!tmark || !rg->vmark)
        goto fail;
#define MARK(v)                                                                                \
    do {                                                                                       \
        int32_t v_ = (v);                                                                      \
        if (v_ < e->nv0 && !rg->vmark[v_]) {                                                   \
            rg->vmark[v_] = 1;                                                                 \
            if (ivec_push(&vs, v_))                                                            \
                goto fail;                                                                     \
        }                                                                                      \
    } while (0)
    for (int t = 0; t < e->nt0; t++)
        if (e->rewired[t])
            for (int k = 0; k < 3; k++) {
                MARK(e->tris0[3 * (size_t)t + k]);
                MARK(s->tris[3 * (size_t)t + k]);
            }
    for (int i = 0; i < pl->tri.n; i++)
        MARK(pl->tri.a[i]);
#undef MARK
    for (int i = 0; i < vs.n; i++) {
        const int32_t v = vs.a[i];
        for (int j = e->vstart[v]; j < e->vstart[v + 1]; j++) {
            const int32_t t = e->vtris[j];
            if (!tmark[t]) {
                tmark[t] = 1;
                if (ivec_push(&tl, t))
                    goto fail;
            }
        }
    }
    free(tmark);
    free(vs.a);
    rg->list = tl.a;
    rg->n_list = tl.n;
    if (!rg->list && !(rg->list = malloc(sizeof *rg->list)))
        goto fail_nolists;
    return 0;
fail:
    free(tmark);
    free(vs.a);
    free(tl.a);
fail_nolists:
    region_free(rg);
    return -1;
}

/*
 * Split boundary pinch vertices: where boundary loops pass a vertex more than once, the
 * triangles around it form separate fans joined only at that vertex. Each fan beyond the
 * first gets its own copy, so that every boundary loop is simple and its closure is fixed by
 * the loop alone (the two sides of a crack then close their twin loops identically).
 */
static int split_pinches(surf_edit *e, edge_map *em, const region *rg, ivec *tri,
                         const ivec *cell)
{
    for (int round = 0; round < 4; round++) {
        const int nt = region_count(rg, e, cell), nvt = e->nv0 + e->vcell.n;
        int32_t *outdeg = calloc((size_t)nvt, sizeof *outdeg);
        ivec pv = {0}, pt = {0};
        int pinches = 0, rc = -1;
        if (!outdeg)
            return -1;
        for (int i = 0; i < nt; i++) {
            const int32_t *q = edit_tri(e, tri, region_tri(rg, e, i));
            for (int k = 0; k < 3; k++)
                if (open_edge(em, rg, e, q[k], q[(k + 1) % 3]) && ++outdeg[q[k]] == 2)
                    pinches++;
        }
        if (pinches == 0) {
            free(outdeg);
            return 0;
        }
        for (int i = 0; i < nt; i++) {
            const int t = region_tri(rg, e, i);
            const int32_t *q = edit_tri(e, tri, t);
            for (int k = 0; k < 3; k++)
                if (outdeg[q[k]] >= 2 && (ivec_push(&pv, q[k]) || ivec_push(&pt, t)))
                    goto done;
        }
        /* group the incident triangles of each pinch vertex: pairs sorted by (vertex,
         * triangle) by insertion (pinches are few) */
        {
            for (int i = 1; i < pv.n; i++) {
                int32_t x = pv.a[i], y = pt.a[i];
                int j = i - 1;
                while (j >= 0 && (pv.a[j] > x || (pv.a[j] == x && pt.a[j] > y))) {
                    pv.a[j + 1] = pv.a[j];
                    pt.a[j + 1] = pt.a[j];
                    j--;
                }
                pv.a[j + 1] = x;
                pt.a[j + 1] = y;
            }
        }
        for (int i = 0; i < pv.n;) {
            int j = i;
            while (j < pv.n && pv.a[j] == pv.a[i])
                j++;
            const int32_t v = pv.a[i];
            const int m = j - i;
            int32_t *parent = malloc((size_t)m * sizeof *parent);
            if (!parent)
                goto done;
            for (int a = 0; a < m; a++)
                parent[a] = a;
            for (int a = 0; a < m; a++)
                for (int b = a + 1; b < m; b++) {
                    const int32_t *qa = edit_tri(e, tri, pt.a[i + a]);
                    const int32_t *qb = edit_tri(e, tri, pt.a[i + b]);
                    for (int x = 0; x < 3; x++)
                        for (int y = 0; y < 3; y++)
                            if (qa[x] != v && qa[x] == qb[y] && !open_edge(em, rg, e, v, qa[x]) &&
                                !open_edge(em, rg, e, qa[x], v))
                                uf_union(parent, a, b);
                }
            int32_t root0 = uf_find(parent, 0);
            int32_t roots[64], copies[64];
            int nr = 0;
            for (int a = 0; a < m; a++) {
                int32_t r = uf_find(parent, a);
                if (r == root0)
                    continue;
                int g = 0;
                while (g < nr && roots[g] != r)
                    g++;
                if (g == nr) {
                    if (nr == 64)
                        continue;
                    roots[nr] = r;
                    copies[nr] = sv_append_copy(e, v, edit_tri_cell(e, cell, pt.a[i + a]));
                    if (copies[nr++] < 0) {
                        free(parent);
                        goto done;
                    }
                }
                int32_t *q = edit_tri(e, tri, pt.a[i + a]);
                tri_edges_add(em, q, -1);
                for (int k = 0; k < 3; k++)
                    if (q[k] == v)
                        q[k] = copies[g];
                tri_edges_add(em, q, 1);
                if (pt.a[i + a] < e->nt0)
                    e->rewired[pt.a[i + a]] = 1;
            }
            free(parent);
            i = j;
        }
        rc = 0;
    done:
        free(outdeg);
        free(pv.a);
        free(pt.a);
        if (rc)
            return -1;
    }
    return 0;
}

/* vertex ids ordered by their rest positions (qsort_r, the edit as context) */
static int cmp_rest(const void *x, const void *y, void *ctx)
{
    const double *p = sv_rest(ctx, *(const int32_t *)x), *q = sv_rest(ctx, *(const int32_t *)y);
    for (int a = 0; a < 3; a++)
        if (p[a] != q[a])
            return p[a] < q[a] ? -1 : 1;
    return 0;
}

/*
 * Close the boundary loops of the edit's triangles (directed edges used once whose reverse is
 * unused; simple after split_pinches): a fan around a new vertex, or one triangle for a loop
 * of three joined to nothing but its mirror image; each closing triangle takes the cell of
 * the triangle across its boundary edge. Loops that share an edge at rest (in either
 * direction, through copies of its vertices) form a joined set, and every fan of a set has
 * its apex at one point (one new vertex per loop, all at that point). Why: at rest, the
 * loops' edges cancel over the whole event — the surface was closed before it, the split
 * only makes copies at the same rest points, and the closing pairs t, t' are mirror images —
 * so they cancel over each joined set (an edge is shared within its set), and cones from one
 * point over a set add up to the cone over nothing: the fans' volumes cancel exactly at rest
 * (and at the positions of the moment, where copies still coincide). The twin loops of the
 * two sides of a crack are the simplest such set; with an apex per loop at its own mean,
 * whatever the two sides' loops did not share (an out-and-back to a point, a mesh triangle
 * held by one side only, a loop running along both sides at a crack's rim) moved volume.
 * Appends to e (vertices) and tri/cell. Returns the number of fans, or -1.
 */

static int close_loops(cs_world_t *w, surf_edit *e, edge_map *em, const region *rg, ivec *tri,
                       ivec *cell, int32_t *n_loops)
{
    ivec bsrc = {0}, bdst = {0}, bcell = {0}, walk = {0}, walk_e = {0};
    ivec lstart = {0}, lv = {0}, lc = {0}; /* the loops: starts in lv, vertices, edge cells */
    int32_t *ord = NULL, *rid = NULL, *comp = NULL, *stamp = NULL;
    int64_t *ekey = NULL;
    double *capex = NULL; /* per joined set of loops: apex rest and current position */
    int fans = 0, rc = -1;
    *n_loops = 0;
    const int nt = region_count(rg, e, cell);
    for (int i = 0; i < nt; i++) {
        const int t = region_tri(rg, e, i);
        const int32_t *q = edit_tri(e, tri, t);
        for (int k = 0; k < 3; k++) {
            int32_t a = q[k], b = q[(k + 1) % 3];
            if (open_edge(em, rg, e, a, b) &&
                (ivec_push(&bsrc, a) || ivec_push(&bdst, b) ||
                 ivec_push(&bcell, edit_tri_cell(e, cell, t))))
                goto out;
        }
    }
    if (bsrc.n == 0) {
        rc = 0;
        goto out;
    }
    const int nb = bsrc.n;
    int64_t *key = malloc((size_t)nb * sizeof *key);
    uint8_t *used = calloc((size_t)nb, 1);
    if (!key || !used) {
        free(key);
        free(used);
        goto out;
    }
    for (int i = 0; i < nb; i++)
        key[i] = ((int64_t)bsrc.a[i] << 32) | (uint32_t)i;
    qsort(key, (size_t)nb, sizeof *key, cmp64);
    for (int s0 = 0; s0 < nb; s0++) {
        int start = (int)(key[s0] & 0xffffffff);
        if (used[start])
            continue;
        walk.n = walk_e.n = 0;
        int cur = start;
        bool ok = true;
        for (;;) {
            used[cur] = 1;
            if (ivec_push(&walk, bsrc.a[cur]) || ivec_push(&walk_e, cur))
                goto out2;
            int32_t next_v = bdst.a[cur];
            if (next_v == bsrc.a[start])
                break;
            int lo = 0, hi = nb;
            int64_t want = (int64_t)next_v << 32;
            while (lo < hi) {
                int mid = (lo + hi) / 2;
                if (key[mid] < want)
                    lo = mid + 1;
                else
                    hi = mid;
            }
            int found = -1;
            for (int j = lo; j < nb && (key[j] >> 32) == next_v; j++)
                if (!used[key[j] & 0xffffffff]) {
                    found = (int)(key[j] & 0xffffffff);
                    break;
                }
            if (found < 0) {
                ok = false;
                break;
            }
            cur = found;
        }
        const int k = walk.n;
        if (!ok || k < 3)
            continue; /* cannot happen for oriented triangles without pinches */
        /* kept: its vertices and the cell of each of its edges; closed below */
        if (ivec_push(&lstart, lv.n))
            goto out2;
        for (int j = 0; j < k; j++)
            if (ivec_push(&lv, walk.a[j]) || ivec_push(&lc, bcell.a[walk_e.a[j]]))
                goto out2;
    }
    const int nl = lstart.n;
    if (ivec_push(&lstart, lv.n))
        goto out2;
    /* Loops joined by an edge at rest (in either direction) close with one apex point: over
     * all loops of an event the edges cancel at rest (the surface before the event was
     * closed; the split only copies vertices; closing pairs t, t' are mirror images at rest),
     * so over each joined set they cancel too, and the cones from one point over them sum
     * to the cone over nothing: their volumes cancel exactly. Twin loops on the two sides of
     * a crack are the common case; an apex per loop at its own mean left the volume of
     * whatever the two sides' loops did not share. */
    const int nlv = lv.n;
    if (nl > 0) {
        ord = malloc((size_t)nlv * sizeof *ord);
        rid = malloc((size_t)nlv * sizeof *rid);
        comp = malloc((size_t)nl * sizeof *comp);
        ekey = malloc((size_t)(nlv ? nlv : 1) * sizeof *ekey);
        stamp = malloc((size_t)nlv * sizeof *stamp);
        capex = malloc((size_t)nl * 6 * sizeof *capex);
        if (!ord || !rid || !comp || !ekey || !stamp || !capex)
            goto out2;
        for (int i = 0; i < nlv; i++)
            ord[i] = lv.a[i];
        qsort_r(ord, (size_t)nlv, sizeof *ord, cmp_rest, (void *)e);
        /* rid: the rank of a loop vertex's rest point */
        for (int i = 0; i < nlv; i++) {
            int lo = 0, hi = nlv;
            while (lo < hi) { /* first entry of ord at lv.a[i]'s rest point */
                const int mid = (lo + hi) / 2;
                int32_t tmp = lv.a[i];
                if (cmp_rest(&ord[mid], &tmp, (void *)e) < 0)
                    lo = mid + 1;
                else
                    hi = mid;
            }
            rid[i] = lo;
        }
        for (int l = 0; l < nl; l++)
            comp[l] = l;
        int ne = 0;
        for (int l = 0; l < nl; l++) {
            const int st = lstart.a[l], k = lstart.a[l + 1] - st;
            for (int j = 0; j < k; j++) {
                int32_t ra = rid[st + j], rb = rid[st + (j + 1) % k];
                if (ra == rb)
                    continue;
                if (ra > rb) {
                    const int32_t t = ra;
                    ra = rb;
                    rb = t;
                }
                ekey[ne++] = (((int64_t)ra * nlv + rb) << 20) | l; /* nl < 2^20 below */
            }
        }
        if (nl < (1 << 20)) {
            qsort(ekey, (size_t)ne, sizeof *ekey, cmp64);
            for (int i = 1; i < ne; i++)
                if ((ekey[i] >> 20) == (ekey[i - 1] >> 20))
                    uf_union(comp, (int32_t)(ekey[i] & 0xfffff), (int32_t)(ekey[i - 1] & 0xfffff));
        }
        /* per joined set: the apex at the mean of its rest points (each once) plus a small
         * offset that depends only on that mean (so that it is not flat); it starts at the
         * same points' current mean plus the offset (the next skin moves it), one point for
         * the set, so that the fans cancel now too. If a copy in the set started away from
         * its source (sv_append_copy: across a crack that had opened before), that mean lies
         * between sides that are apart: each loop's apex then starts where its cell puts it
         * (skinned, on its own side) */
        for (int i = 0; i < nlv; i++)
            stamp[i] = -1;
        for (int l = 0; l < nl; l++) {
            if (uf_find(comp, l) != l)
                continue;
            double c[3] = {0, 0, 0}, x[3] = {0, 0, 0};
            int np = 0;
            bool jump = false;
            for (int m = 0; m < nl; m++) {
                if (uf_find(comp, m) != l)
                    continue;
                for (int i = lstart.a[m]; i < lstart.a[m + 1]; i++) {
                    if (stamp[rid[i]] == l)
                        continue;
                    stamp[rid[i]] = l;
                    const int32_t v = lv.a[i];
                    const double *px = v < e->nv0 ? e->o->surf.pos + 3 * (size_t)v
                                                  : e->pos.a + 3 * (size_t)(v - e->nv0);
                    jump |= v >= e->nv0 && e->jumped.a[v - e->nv0];
                    for (int a = 0; a < 3; a++) {
                        c[a] += sv_rest(e, v)[a];
                        x[a] += px[a];
                    }
                    np++;
                }
            }
            for (int a = 0; a < 3; a++) {
                c[a] /= np;
                x[a] /= np;
            }
            uint64_t r = w->def.seed;
            for (int a = 0; a < 3; a++)
                r = mix64(r ^ (uint64_t)llround(c[a] / e->o->cm.h * 1e6));
            for (int a = 0; a < 3; a++) {
                r = mix64(r);
                const double d = 1e-3 * e->o->cm.h * ((double)(r >> 11) / 9007199254740992.0 - 0.5);
                capex[6 * l + a] = c[a] + d;
                capex[6 * l + 3 + a] = jump ? NAN : x[a] + d;
            }
        }
    }
    for (int l = 0; l < nl; l++) {
        const int32_t *cyc = lv.a + lstart.a[l], *lcell = lc.a + lstart.a[l];
        const int k = lstart.a[l + 1] - lstart.a[l];
        const int root = uf_find(comp, l);
        (*n_loops)++;
        /* a triangle alone closes a loop of three that is joined to nothing but, at most, its
         * mirror image (closed the same way: they cancel) */
        int others = 0;
        bool threes = true;
        for (int m = 0; m < nl; m++)
            if (m != l && uf_find(comp, m) == root) {
                others++;
                threes &= lstart.a[m + 1] - lstart.a[m] == 3;
            }
        if (k == 3 && others <= 1 && threes &&
            !tri_degenerate(sv_rest(e, cyc[0]), sv_rest(e, cyc[2]), sv_rest(e, cyc[1]))) {
            if (ivec_push3(tri, cyc[0], cyc[2], cyc[1]) || ivec_push(cell, lcell[0]))
                goto out2;
            continue;
        }
        int32_t cv = sv_append(e, capex + 6 * root, lcell[0]);
        if (cv < 0)
            goto out2;
        if (!isnan(capex[6 * root + 3]))
            memcpy(e->pos.a + 3 * (size_t)(cv - e->nv0), capex + 6 * root + 3, 3 * sizeof(double));
        for (int j = 0; j < k; j++)
            if (ivec_push3(tri, cv, cyc[(j + 1) % k], cyc[j]) || ivec_push(cell, lcell[j]))
                goto out2;
        fans++;
    }
    rc = fans;
out2:
    free(key);
    free(used);
out:
    free(bsrc.a);
    free(bdst.a);
    free(bcell.a);
    free(walk.a);
    free(walk_e.a);
    free(lstart.a);
    free(lv.a);
    free(lc.a);
    free(ord);
    free(rid);
    free(comp);
    free(stamp);
    free(ekey);
    free(capex);
    return rc;
}

/* Append the edit's vertices and the given triangles to the object's surface; record the
 * change (rewired and appended) and bump the topology version. */
static int commit_edit(cs_world_t *w, cs_object *o, surf_edit *e, const ivec *tri,
                       const ivec *cell, bool record)
{
    cs_surface *s = &o->surf;
    const int nva = e->vcell.n, nta = cell->n;
    const int nv1 = e->nv0 + nva, nt1 = e->nt0 + nta;
    if (resize(&s->rest, 3 * sizeof(double), (size_t)nv1) ||
        resize(&s->pos, 3 * sizeof(double), (size_t)nv1) ||
        resize(&s->vert_uvw, 3 * sizeof(double), (size_t)nv1) ||
        resize(&s->vert_cell, sizeof(int32_t), (size_t)nv1) ||
        resize(&s->tris, 3 * sizeof(int32_t), (size_t)nt1) ||
        resize(&s->tri_cell, sizeof(int32_t), (size_t)nt1) || resize(&o->tri_kind, 1, (size_t)nt1))
        return -1;
    if (nva) {
        memcpy(s->rest + 3 * (size_t)e->nv0, e->rest.a, (size_t)nva * 3 * sizeof(double));
        memcpy(s->vert_uvw + 3 * (size_t)e->nv0, e->uvw.a, (size_t)nva * 3 * sizeof(double));
        memcpy(s->vert_cell + e->nv0, e->vcell.a, (size_t)nva * sizeof(int32_t));
    }
    if (nta) {
        memcpy(s->tris + 3 * (size_t)e->nt0, tri->a, (size_t)nta * 3 * sizeof(int32_t));
        memcpy(s->tri_cell + e->nt0, cell->a, (size_t)nta * sizeof(int32_t));
        memset(o->tri_kind + e->nt0, 1, (size_t)nta);
    }
    s->n_vertices = nv1;
    s->n_triangles = nt1;
    /* Only the new vertices get positions now, each skinned in its cell (sv_append). No
     * vertex the event found changes its binding or position (split_surface copies it
     * instead), so the recorded change is exactly what the engine holds. */
    if (nva)
        memcpy(s->pos + 3 * (size_t)e->nv0, e->pos.a, (size_t)nva * 3 * sizeof(double));
    if (!record)
        return cs_surface_extend_cell_lists(s, &o->cm, 1e-9 * o->cm.h, e->nt0);
    ivec tset_i = {0}, tset_t = {0};
    int rc = -1;
    for (int t = 0; t < e->nt0; t++)
        if (e->rewired[t] && (ivec_push(&tset_i, t) ||
                              ivec_push3(&tset_t, s->tris[3 * t], s->tris[3 * t + 1],
                                         s->tris[3 * t + 2])))
            goto out;
    cs_topo_change c = {
        .object_id = (int32_t)o->id, .from_version = o->topology_version,
        .to_version = o->topology_version + 1, .n_vertices_total = nv1,
        .n_triangles_total = nt1, .n_vnew = nva, .vnew_xyz = s->pos + 3 * (size_t)e->nv0,
        .n_tset = tset_i.n, .tset_index = tset_i.a, .tset_tri = tset_t.a, .n_tnew = nta,
        .tnew = s->tris + 3 * (size_t)e->nt0, .vnew_src = e->vsrc.a};
    if (push_change(w, &c))
        goto out;
    o->topology_version++;
    rc = cs_surface_extend_cell_lists(s, &o->cm, 1e-9 * o->cm.h, e->nt0);
out:
    free(tset_i.a);
    free(tset_t.a);
    return rc;
}

static bool any_rewired(const surf_edit *e)
{
    for (int t = 0; t < e->nt0; t++)
        if (e->rewired[t])
            return true;
    return false;
}

/*
 * Glued pairs that meet along one edge. A partially opened face's t and t' are glued along
 * the edges between its still-shared corners; where two such faces share a lattice edge with
 * both ends still shared (two wedge-shaped cavities hinged on one line), that edge would
 * carry four triangles. Each cavity is closed on its own, so the triangles are paired per
 * cavity (a closing triangle with the reversed closing triangle over the same points: its t'
 * partner) and one end of the edge is split: the triangles around it are grouped through
 * the edges at it (an edge of two triangles joins them, an edge of more joins the pairs), and
 * every group beyond the first gets its own copy of the vertex (the copies coincide: the
 * same rest point, bound to cells that share its node). Done only if every group then uses
 * each edge at most twice in opposite directions; otherwise the greedy acceptance below
 * drops what does not fit, as before.
 */
typedef struct star_tri {
    int idx;   /* region triangle (< nt0: original) or patch triangle (pl index + nt0) */
    int32_t *q;
    int32_t cell;
    bool closing;
} star_tri;

static const double *third_rest(const surf_edit *e, const int32_t *q, int32_t a, int32_t b)
{
    for (int k = 0; k < 3; k++)
        if (q[k] != a && q[k] != b)
            return sv_rest(e, q[k]);
    return NULL;
}

/* Is triangle x (holding directed edge a->b) the glued partner of y (holding b->a)? */
static bool glued_partner(const surf_edit *e, const star_tri *x, const star_tri *y, int32_t a,
                          int32_t b)
{
    if (!x->closing || !y->closing || x->cell == y->cell)
        return false;
    const double *p = third_rest(e, x->q, a, b), *r = third_rest(e, y->q, a, b);
    return p && r && p[0] == r[0] && p[1] == r[1] && p[2] == r[2];
}

static bool has_dir(const int32_t *q, int32_t a, int32_t b)
{
    for (int k = 0; k < 3; k++)
        if (q[k] == a && q[(k + 1) % 3] == b)
            return true;
    return false;
}

static bool holds(const int32_t *q, int32_t v)
{
    return q[0] == v || q[1] == v || q[2] == v;
}

/* Split vertex v's star into its cavity groups (see above). Returns 1 if split, 0 if not,
 * -1 on allocation failure. */
static int split_star(surf_edit *e, const region *rg, patch_list *pl, int32_t v)
{
    cs_object *o = e->o;
    const int n0 = rg->list ? rg->n_list : e->nt0;
    star_tri *st = NULL;
    int n = 0, cap = 0, rc = -1;
    int32_t *parent = NULL;
    for (int i = 0; i < n0 + pl->cell.n; i++) {
        const int t = i < n0 ? (rg->list ? rg->list[i] : i) : e->nt0 + (i - n0);
        int32_t *q = t < e->nt0 ? o->surf.tris + 3 * (size_t)t
                                : pl->tri.a + 3 * (size_t)(t - e->nt0);
        if (!holds(q, v))
            continue;
        if (vec_room(&st, &cap, n, sizeof *st))
            goto out;
        st[n++] = (star_tri){t, q, t < e->nt0 ? o->surf.tri_cell[t] : pl->cell.a[t - e->nt0],
                             t >= e->nt0 || o->tri_kind[t] != 0};
    }
    parent = malloc((size_t)(n ? n : 1) * sizeof *parent);
    if (!parent)
        goto out;
    for (int i = 0; i < n; i++)
        parent[i] = i;
    /* through each edge (v, w) */
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            const int32_t wv = st[i].q[k];
            if (wv == v)
                continue;
            int at = 0;
            for (int j = 0; j < n; j++)
                at += holds(st[j].q, wv);
            for (int j = i + 1; j < n; j++) {
                if (!holds(st[j].q, wv))
                    continue;
                if (at == 2) {
                    uf_union(parent, i, j);
                } else {
                    const bool iv = has_dir(st[i].q, v, wv), jv = has_dir(st[j].q, v, wv);
                    /* a cavity's two walls: a glued pair */
                    if (iv != jv && (iv ? glued_partner(e, &st[i], &st[j], v, wv)
                                        : glued_partner(e, &st[j], &st[i], wv, v)))
                        uf_union(parent, i, j);
                }
            }
        }
    /* valid only if every group uses each edge at v at most once per direction */
    int groups = 0;
    for (int i = 0; i < n; i++)
        if (uf_find(parent, i) == i)
            groups++;
    rc = 0;
    if (groups < 2)
        goto out;
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            const int32_t wv = st[i].q[k];
            if (wv == v)
                continue;
            int fw = 0, bw = 0;
            for (int j = 0; j < n; j++)
                if (uf_find(parent, j) == uf_find(parent, i) && holds(st[j].q, wv)) {
                    fw += has_dir(st[j].q, v, wv);
                    bw += has_dir(st[j].q, wv, v);
                }
            if (fw > 1 || bw > 1)
                goto out;
        }
    /* the group of the first triangle keeps v */
    const int keep = uf_find(parent, 0);
    for (int i = 0; i < n; i++) {
        const int r = uf_find(parent, i);
        if (r == keep || r != i)
            continue;
        const int32_t c = sv_append_copy(e, v, st[i].cell);
        if (c < 0) {
            rc = -1;
            goto out;
        }
        for (int j = 0; j < n; j++) {
            if (uf_find(parent, j) != r)
                continue;
            for (int k = 0; k < 3; k++)
                if (st[j].q[k] == v)
                    st[j].q[k] = c;
            if (st[j].idx < e->nt0)
                e->rewired[st[j].idx] = 1;
        }
    }
    rc = 1;
out:
    free(st);
    free(parent);
    return rc;
}

static int split_glued(surf_edit *e, const region *rg, patch_list *pl)
{
    const cs_surface *s = &e->o->surf;
    const int n0 = rg->list ? rg->n_list : e->nt0;
    edge_map em;
    if (pl->cell.n == 0)
        return 0;
    if (edge_map_init(&em, (size_t)3 * (n0 + pl->cell.n) + 64))
        return -1;
    for (int i = 0; i < n0; i++)
        tri_edges_add(&em, s->tris + 3 * (size_t)(rg->list ? rg->list[i] : i), 1);
    for (int i = 0; i < pl->cell.n; i++)
        tri_edges_add(&em, pl->tri.a + 3 * (size_t)i, 1);
    int rc = 0;
    for (int i = 0; i < n0 + pl->cell.n && rc == 0; i++) {
        const int t = i < n0 ? (rg->list ? rg->list[i] : i) : -1;
        if (t >= 0 && !e->rewired[t])
            continue;
        const int32_t *q = t >= 0 ? s->tris + 3 * (size_t)t : pl->tri.a + 3 * (size_t)(i - n0);
        for (int k = 0; k < 3 && rc == 0; k++) {
            const int32_t a = q[k], b = q[(k + 1) % 3];
            if (edge_get(&em, a, b) + edge_get(&em, b, a) <= 2)
                continue;
            /* split an end; the edge map follows by recounting (splits are rare) */
            int r = split_star(e, rg, pl, a);
            if (r == 0)
                r = split_star(e, rg, pl, b);
            if (r < 0) {
                rc = -1;
                break;
            }
            if (r > 0) {
                edge_map_free(&em);
                if (edge_map_init(&em, (size_t)3 * (n0 + pl->cell.n) + 64)) {
                    rc = -1;
                    break;
                }
                for (int j = 0; j < n0; j++)
                    tri_edges_add(&em, s->tris + 3 * (size_t)(rg->list ? rg->list[j] : j), 1);
                for (int j = 0; j < pl->cell.n; j++)
                    tri_edges_add(&em, pl->tri.a + 3 * (size_t)j, 1);
            }
        }
    }
    edge_map_free(&em);
    return rc;
}

/* Accept closing patches greedily (a patch group is dropped if it is degenerate or would use a
 * directed edge twice), then close what is left open. Commits the edit. */
static int repair_and_commit(cs_world_t *w, cs_object *o, surf_edit *e, patch_list *pl,
                             int *fans, int *closing, bool record)
{
    const cs_surface *s = &o->surf;
    edge_map em;
    region rg;
    ivec tri = {0}, cell = {0};
    int rc = -1;
    if (repair_region(e, pl, &rg))
        return -1;
    /* each pass renames vertices of original triangles: the region follows (the triangles
     * they flag rewired bring their vertices in) */
    if (e->partial && (split_glued(e, &rg, pl) || (region_free(&rg), repair_region(e, pl, &rg)))) {
        region_free(&rg);
        return -1;
    }
    const int n_orig = rg.list ? rg.n_list : e->nt0;
    if (edge_map_init(&em, (size_t)3 * (n_orig + pl->cell.n) + 64)) {
        region_free(&rg);
        return -1;
    }
    for (int i = 0; i < n_orig; i++)
        tri_edges_add(&em, s->tris + 3 * (size_t)(rg.list ? rg.list[i] : i), 1);
    for (int i = 0; i < pl->cell.n;) {
        int j = i;
        while (j < pl->cell.n && pl->group.a[j] == pl->group.a[i])
            j++;
        bool ok = true;
        for (int t = i; t < j && ok; t++) {
            const int32_t *q = pl->tri.a + 3 * (size_t)t;
            if (tri_degenerate(sv_rest(e, q[0]), sv_rest(e, q[1]), sv_rest(e, q[2])))
                ok = false;
        }
        for (int t = i; t < j; t++)
            tri_edges_add(&em, pl->tri.a + 3 * (size_t)t, 1);
        for (int t = i; t < j && ok; t++) {
            const int32_t *q = pl->tri.a + 3 * (size_t)t;
            for (int k = 0; k < 3; k++) {
                int32_t a = q[k], b = q[(k + 1) % 3];
                if (edge_get(&em, a, b) > 1 || edge_get(&em, a, b) + edge_get(&em, b, a) > 2) {
                    ok = false;
                }
            }
        }
        if (!ok) {
            for (int t = i; t < j; t++)
                tri_edges_add(&em, pl->tri.a + 3 * (size_t)t, -1);
        } else {
            for (int t = i; t < j; t++)
                if (ivec_push3(&tri, pl->tri.a[3 * t], pl->tri.a[3 * t + 1],
                               pl->tri.a[3 * t + 2]) ||
                    ivec_push(&cell, pl->cell.a[t]))
                    goto out;
        }
        i = j;
    }
    /* the loops left open: over the original (rewired) triangles and the accepted patches */
    {
        int32_t loops = 0;
        if (split_pinches(e, &em, &rg, &tri, &cell) != 0)
            goto out;
        int f = close_loops(w, e, &em, &rg, &tri, &cell, &loops);
        if (f < 0)
            goto out;
        *fans = f;
    }
    *closing = cell.n;
    if (cell.n == 0 && e->vcell.n == 0 && !record)
        rc = 0;
    else if (cell.n == 0 && e->vcell.n == 0 && !any_rewired(e))
        rc = 0; /* nothing changed: no change to record */
    else
        rc = commit_edit(w, o, e, &tri, &cell, record);
out:
    edge_map_free(&em);
    region_free(&rg);
    free(tri.a);
    free(cell.a);
    return rc;
}

/* ---------------------------------------------------------------- step 6: pieces */

/* A surface edit of an object with nothing pending (for closing loops only). */
static int surf_edit_begin(surf_edit *e, cs_object *o)
{
    memset(e, 0, sizeof *e);
    e->o = o;
    e->nv0 = o->surf.n_vertices;
    e->nt0 = o->surf.n_triangles;
    e->rewired = calloc((size_t)(e->nt0 ? e->nt0 : 1), 1);
    return e->rewired ? 0 : -1;
}

/* Close whatever boundary loops o's surface has (none, normally). */
static int close_open_loops(cs_world_t *w, cs_object *o, bool record, int *fans)
{
    surf_edit e;
    patch_list none = {0};
    int closing = 0;
    if (surf_edit_begin(&e, o))
        return -1;
    int rc = repair_and_commit(w, o, &e, &none, fans, &closing, record);
    surf_edit_free(&e);
    return rc;
}

/*
 * A new object holding cells `cells` (n of them, indices into o) with their nodes, state and
 * surface triangles (those whose centroid cell is among them). Its surface vertices start
 * where o's are; one bound to a cell of another piece (rare: the surface split binds the
 * copies it makes in their piece) is bound to a cell of this one and starts where that puts
 * it (a new object's vertices are all sent with the change that makes it). If vsrc is
 * not NULL it receives the o vertex each of the piece's vertices is (owned by the caller).
 */
static cs_object *make_piece(cs_world_t *w, const cs_object *o, const int32_t *cells, int nc,
                             const int32_t *cell_map, int32_t **vsrc)
{
    const cs_cubemesh *cm = &o->cm;
    const cs_surface *s = &o->surf;
    cs_object *p = calloc(1, sizeof *p);
    int32_t *nmap = malloc((size_t)o->n * sizeof *nmap);
    int32_t *vmap = malloc((size_t)(s->n_vertices ? s->n_vertices : 1) * sizeof *vmap);
    ivec tl = {0}, vl = {0}, nl = {0};
    if (!p || !nmap || !vmap)
        goto fail;
    for (int i = 0; i < o->n; i++)
        nmap[i] = -1;
    for (int i = 0; i < s->n_vertices; i++)
        vmap[i] = -1;
    p->model = o->model;
    p->kin = o->kin;
    p->contact_seen = true; /* its contacts with its kin are its born pairs' (rigid.c) */
    /* the kin o's box has been apart from, p's has been too (rigid.c soft_contacts) */
    if (o->n_apart > 0) {
        if (!(p->apart = malloc((size_t)o->n_apart * sizeof *p->apart)))
            goto fail;
        memcpy(p->apart, o->apart, (size_t)o->n_apart * sizeof *p->apart);
        p->n_apart = p->cap_apart = o->n_apart;
    }
    p->integrator = o->integrator;
    p->mat = o->mat;
    p->omega2_plain = o->omega2_plain;
    p->fracture = o->fracture;
    p->fracture_radius = o->fracture_radius;
    p->strain_limit = o->strain_limit;
    if (o->rb && !(p->rb = cs_rigid_clone(o->rb))) /* rigid: continues o's motion */
        goto fail;
    /* cube mesh */
    cs_cubemesh *pm = &p->cm;
    pm->h = cm->h;
    memcpy(pm->origin, cm->origin, sizeof pm->origin);
    pm->n_cells = nc;
    pm->cell_ijk = malloc((size_t)nc * 3 * sizeof(int32_t));
    pm->cell_nodes = malloc((size_t)nc * 8 * sizeof(int32_t));
    if (!pm->cell_ijk || !pm->cell_nodes || cs_ijk_hash_init(&pm->cells, nc) != 0)
        goto fail;
    if (o->cell_cut) {
        p->cell_cut = malloc((size_t)(nc ? nc : 1));
        if (!p->cell_cut)
            goto fail;
        for (int i = 0; i < nc; i++)
            p->cell_cut[i] = o->cell_cut[cells[i]];
    }
    if (o->cell_open) {
        p->cell_open = malloc((size_t)(nc ? nc : 1));
        if (!p->cell_open)
            goto fail;
        for (int i = 0; i < nc; i++)
            p->cell_open[i] = o->cell_open[cells[i]];
    }
    for (int i = 0; i < nc; i++) {
        const int32_t c = cells[i];
        memcpy(pm->cell_ijk + 3 * (size_t)i, cm->cell_ijk + 3 * (size_t)c, 3 * sizeof(int32_t));
        for (int k = 0; k < 8; k++) {
            int32_t nd = cm->cell_nodes[8 * (size_t)c + k];
            if (nmap[nd] < 0) {
                nmap[nd] = nl.n;
                if (ivec_push(&nl, nd))
                    goto fail;
            }
            pm->cell_nodes[8 * (size_t)i + k] = nmap[nd];
        }
        const int32_t *q = pm->cell_ijk + 3 * (size_t)i;
        if (cs_ijk_hash_put(&pm->cells, q[0], q[1], q[2], i) != 0)
            goto fail;
    }
    pm->n_nodes = p->n = nl.n;
    pm->node_rest = malloc((size_t)p->n * 3 * sizeof(double));
    p->corner_vertex = malloc((size_t)p->n * sizeof(int32_t));
    if (!pm->node_rest || !p->corner_vertex || cs_object_alloc_state(p) != 0)
        goto fail;
    for (int i = 0; i < p->n; i++) {
        const int32_t nd = nl.a[i];
        memcpy(pm->node_rest + 3 * (size_t)i, cm->node_rest + 3 * (size_t)nd, 3 * sizeof(double));
        memcpy(p->x + 3 * (size_t)i, o->x + 3 * (size_t)nd, 3 * sizeof(double));
        memcpy(p->v + 3 * (size_t)i, o->v + 3 * (size_t)nd, 3 * sizeof(double));
        memcpy(p->f_const + 3 * (size_t)i, o->f_const + 3 * (size_t)nd, 3 * sizeof(double));
        memcpy(p->mask + 3 * (size_t)i, o->mask + 3 * (size_t)nd, 3);
        p->pin[i] = o->pin[nd];
        p->m[i] = o->m[nd];
        p->contact[i] = o->contact[nd];
        memcpy(p->ground + 3 * (size_t)i, o->ground + 3 * (size_t)nd, 3 * sizeof(double));
        if ((p->mask[3 * i] && p->mask[3 * i + 1] && p->mask[3 * i + 2]) || p->pin[i])
            p->n_fixed_nodes++;
    }
    /* the material fields of its cells; masses from them (a node the piece shares with
     * another one only at an edge or corner keeps its own cells' share), gravity to match */
    p->penalty = o->penalty;
    if (cs_fields_alloc(p) != 0)
        goto fail;
    for (int i = 0; i < nc; i++) {
        const size_t a = 8 * (size_t)i, b = 8 * (size_t)cells[i];
        memcpy(p->fld.young + a, o->fld.young + b, 8 * sizeof(double));
        memcpy(p->fld.density + a, o->fld.density + b, 8 * sizeof(double));
        memcpy(p->fld.damping + a, o->fld.damping + b, 8 * sizeof(double));
    }
    if (cs_object_lump_mass(p) != 0)
        goto fail;
    for (int i = 0; i < p->n; i++) {
        const double dm = p->m[i] - o->m[nl.a[i]];
        for (int a = 0; a < 3; a++)
            p->f_const[3 * (size_t)i + a] += dm * w->def.gravity[a];
    }
    /* surface */
    for (int t = 0; t < s->n_triangles; t++) {
        if (cell_map[s->tri_cell[t]] < 0)
            continue;
        if (ivec_push(&tl, t))
            goto fail;
        for (int k = 0; k < 3; k++) {
            int32_t v = s->tris[3 * (size_t)t + k];
            if (vmap[v] < 0) {
                vmap[v] = vl.n;
                if (ivec_push(&vl, v))
                    goto fail;
            }
        }
    }
    cs_surface *ps = &p->surf;
    const int nv = vl.n, nt = tl.n;
    ps->n_vertices = nv;
    ps->n_triangles = nt;
    ps->rest = malloc((size_t)(nv ? nv : 1) * 3 * sizeof(double));
    ps->pos = malloc((size_t)(nv ? nv : 1) * 3 * sizeof(double));
    ps->vert_uvw = malloc((size_t)(nv ? nv : 1) * 3 * sizeof(double));
    ps->vert_cell = malloc((size_t)(nv ? nv : 1) * sizeof(int32_t));
    ps->tris = malloc((size_t)(nt ? nt : 1) * 3 * sizeof(int32_t));
    ps->tri_cell = malloc((size_t)(nt ? nt : 1) * sizeof(int32_t));
    p->tri_kind = malloc((size_t)(nt ? nt : 1));
    if (!ps->rest || !ps->pos || !ps->vert_uvw || !ps->vert_cell || !ps->tris || !ps->tri_cell ||
        !p->tri_kind)
        goto fail;
    for (int i = 0; i < nt; i++) {
        const int32_t t = tl.a[i];
        for (int k = 0; k < 3; k++)
            ps->tris[3 * i + k] = vmap[s->tris[3 * (size_t)t + k]];
        ps->tri_cell[i] = cell_map[s->tri_cell[t]];
        p->tri_kind[i] = o->tri_kind[t];
    }
    for (int i = 0; i < nv; i++) {
        const int32_t v = vl.a[i];
        memcpy(ps->rest + 3 * (size_t)i, s->rest + 3 * (size_t)v, 3 * sizeof(double));
        memcpy(ps->pos + 3 * (size_t)i, s->pos + 3 * (size_t)v, 3 * sizeof(double));
        memcpy(ps->vert_uvw + 3 * (size_t)i, s->vert_uvw + 3 * (size_t)v, 3 * sizeof(double));
        ps->vert_cell[i] = cell_map[s->vert_cell[v]];
    }
    for (int i = 0; i < p->n; i++) {
        int32_t cv = o->corner_vertex ? o->corner_vertex[nl.a[i]] : -1;
        p->corner_vertex[i] = cv >= 0 ? vmap[cv] : -1;
    }
    ps->cell_tri_start = NULL;
    ps->cell_tri_list = NULL;
    if (rebuild_cell_lists(ps, pm) != 0)
        goto fail;
    if (cs_elastic_init(p, w->threads, w->def.simd_width) != 0)
        goto fail;
    /* a vertex bound to a cell of another piece follows a cell of this one (skinned after
     * cs_elastic_init: a localframe piece's B-spline cells are known then) */
    for (int i = 0; i < nt; i++)
        for (int k = 0; k < 3; k++) {
            int32_t v = ps->tris[3 * i + k];
            if (ps->vert_cell[v] >= 0)
                continue;
            ps->vert_cell[v] = ps->tri_cell[i];
            skin_point(p, ps->tri_cell[i], ps->rest + 3 * (size_t)v, ps->vert_uvw + 3 * (size_t)v,
                       ps->pos + 3 * (size_t)v);
        }
    for (int i = 0; i < nc; i++) {
        memcpy(p->fem.R + 9 * (size_t)i, o->fem.R + 9 * (size_t)cells[i], 9 * sizeof(double));
        memcpy(p->fem.q + 4 * (size_t)i, o->fem.q + 4 * (size_t)cells[i], 4 * sizeof(double));
    }
    /* inputs acting on its cells move with it */
    for (int i = 0; i < o->n_inputs; i++)
        if (o->inputs[i].kind == CS_INPUT_PRESSURE) /* on every piece's surface */
            p->inputs[p->n_inputs++] = o->inputs[i];
        else if (cell_map[o->inputs[i].cell] >= 0) {
            p->inputs[p->n_inputs] = o->inputs[i];
            p->inputs[p->n_inputs++].cell = cell_map[o->inputs[i].cell];
        }
    free(nmap);
    free(vmap);
    free(tl.a);
    if (vsrc)
        *vsrc = vl.a;
    else
        free(vl.a);
    free(nl.a);
    return p;
fail:
    free(nmap);
    free(vmap);
    free(tl.a);
    free(vl.a);
    free(nl.a);
    cs_object_free_internal(p);
    return NULL;
}

/* A name not yet used in the world: "<base>.<k>". */
static char *piece_name(const cs_world_t *w, const char *base)
{
    size_t n = strlen(base) + 24;
    char *s = malloc(n);
    if (!s)
        return NULL;
    for (unsigned k = 1;; k++) {
        snprintf(s, n, "%.*s.%u", CS_MAX_NAME - 12, base, k);
        if (cs_world_find_object(w, s) == CS_NULL_OBJECT)
            return s;
    }
}

/* Make o hold only the cells with cell_map >= 0 (the kept component): its cube mesh, nodes
 * and state are rebuilt, its surface loses the other pieces' triangles and vertices by one
 * recorded change (swap-removals and rewired triangles). */
static int keep_cells(cs_world_t *w, cs_object *o, const int32_t *kept, int nk,
                      const int32_t *cell_map)
{
    cs_surface *s = &o->surf;
    const int nv = s->n_vertices, nt = s->n_triangles;
    cs_object *p = make_piece(w, o, kept, nk, cell_map, NULL);
    uint8_t *used = calloc((size_t)(nv ? nv : 1), 1);
    int32_t *vid = malloc((size_t)(nv ? nv : 1) * sizeof *vid);
    int32_t *newidx = malloc((size_t)(nv ? nv : 1) * sizeof *newidx);
    int32_t *tid = malloc((size_t)(nt ? nt : 1) * sizeof *tid);
    ivec vrem = {0}, trem = {0}, tsi = {0}, tst = {0};
    int rc = -1;
    if (!p || !used || !vid || !newidx || !tid)
        goto out;
    for (int t = 0; t < nt; t++)
        if (cell_map[s->tri_cell[t]] >= 0)
            for (int k = 0; k < 3; k++)
                used[s->tris[3 * (size_t)t + k]] = 1;
    for (int t = nt - 1; t >= 0; t--)
        if (cell_map[s->tri_cell[t]] < 0 && ivec_push(&trem, t))
            goto out;
    for (int v = nv - 1; v >= 0; v--)
        if (!used[v] && ivec_push(&vrem, v))
            goto out;
    cs_topo_change c = {.object_id = (int32_t)o->id, .from_version = o->topology_version,
                        .to_version = o->topology_version + 1,
                        .n_vertices_total = nv - vrem.n, .n_triangles_total = nt - trem.n,
                        .n_vremove = vrem.n, .vremove = vrem.a, .n_tremove = trem.n,
                        .tremove = trem.a};
    for (int v = 0; v < nv; v++) {
        vid[v] = v;
        newidx[v] = -1;
    }
    int nv1 = cs_topo_remove_vertices(&c, vid, sizeof *vid, nv);
    for (int i = 0; i < nv1; i++)
        newidx[vid[i]] = i;
    for (int t = 0; t < nt; t++)
        tid[t] = t;
    int nt1 = cs_topo_remove_triangles(&c, tid, sizeof *tid, nt);
    for (int j = 0; j < nt1; j++) {
        const int32_t *q = s->tris + 3 * (size_t)tid[j];
        int32_t r[3] = {newidx[q[0]], newidx[q[1]], newidx[q[2]]};
        if ((r[0] != q[0] || r[1] != q[1] || r[2] != q[2]) &&
            (ivec_push(&tsi, j) || ivec_push3(&tst, r[0], r[1], r[2])))
            goto out;
    }
    c.n_tset = tsi.n;
    c.tset_index = tsi.a;
    c.tset_tri = tst.a;
    /* the same change on the engine's own arrays */
    cs_topo_remove_vertices(&c, s->rest, 3 * sizeof(double), nv);
    cs_topo_remove_vertices(&c, s->pos, 3 * sizeof(double), nv);
    cs_topo_remove_vertices(&c, s->vert_uvw, 3 * sizeof(double), nv);
    cs_topo_remove_vertices(&c, s->vert_cell, sizeof(int32_t), nv);
    cs_topo_remove_triangles(&c, s->tri_cell, sizeof(int32_t), nt);
    cs_topo_remove_triangles(&c, o->tri_kind, 1, nt);
    cs_topo_apply_triangles(&c, s->tris, nt);
    s->n_vertices = nv1;
    s->n_triangles = nt1;
    for (int t = 0; t < nt1; t++)
        s->tri_cell[t] = cell_map[s->tri_cell[t]];
    for (int v = 0; v < nv1; v++)
        s->vert_cell[v] = cell_map[s->vert_cell[v]];
    for (int t = 0; t < nt1; t++)
        for (int k = 0; k < 3; k++) {
            int32_t v = s->tris[3 * (size_t)t + k];
            double x[3];
            if (s->vert_cell[v] < 0) {
                s->vert_cell[v] = s->tri_cell[t];
                skin_point(p, s->tri_cell[t], s->rest + 3 * (size_t)v,
                           s->vert_uvw + 3 * (size_t)v, x);
            }
        }
    /* corner vertices of the kept nodes, renumbered */
    for (int i = 0; i < nk; i++)
        for (int k = 0; k < 8; k++) {
            int32_t old = o->cm.cell_nodes[8 * (size_t)kept[i] + k];
            int32_t cv = o->corner_vertex ? o->corner_vertex[old] : -1;
            p->corner_vertex[p->cm.cell_nodes[8 * (size_t)i + k]] = cv >= 0 ? newidx[cv] : -1;
        }
    if (push_change(w, &c))
        goto out;
    o->topology_version++;
    /* o takes p's cube mesh, nodes, state and inputs; p takes o's old ones to free them */
    {
        cs_object tmp = *o;
        cs_surface surf_o = o->surf;
        uint8_t *kind_o = o->tri_kind;
        *o = *p;
        o->id = tmp.id;
        o->kin = tmp.kin;
        free(o->apart); /* p's copy of the same list */
        o->apart = tmp.apart;
        o->n_apart = tmp.n_apart;
        o->cap_apart = tmp.cap_apart;
        tmp.apart = NULL;
        o->name = tmp.name;
        o->topology_version = tmp.topology_version;
        o->surf = surf_o;
        o->tri_kind = kind_o;
        o->still_steps = 0;
        o->sleeping = false;
        o->elastic_energy_valid = false;
        tmp.name = NULL;
        tmp.surf = p->surf;
        tmp.tri_kind = p->tri_kind;
        *p = tmp;
    }
    if (rebuild_cell_lists(&o->surf, &o->cm) != 0)
        goto out;
    int fans = 0;
    rc = close_open_loops(w, o, true, &fans);
out:
    cs_object_free_internal(p);
    free(used);
    free(vid);
    free(newidx);
    free(tid);
    free(vrem.a);
    free(trem.a);
    free(tsi.a);
    free(tst.a);
    return rc;
}

/* Rest volume enclosed by o's surface. */
static double rest_volume(const cs_object *o)
{
    double v = 0;
    const cs_surface *s = &o->surf;
    for (int t = 0; t < s->n_triangles; t++) {
        const double *a = s->rest + 3 * (size_t)s->tris[3 * t],
                     *b = s->rest + 3 * (size_t)s->tris[3 * t + 1],
                     *c = s->rest + 3 * (size_t)s->tris[3 * t + 2];
        v += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
              a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0;
    }
    return v;
}

/*
 * The last resort for a piece whose surface encloses no positive volume (or none at all): the
 * boundary of its cubes, bound to them. Recorded as one change (everything removed, the new
 * surface appended) when `record`. Returns 1 if it replaced the surface, 0 if not needed, -1.
 */
static int ensure_positive_volume(cs_world_t *w, cs_object *o, bool record)
{
    const double h = o->cm.h;
    if (o->surf.n_triangles > 0 && rest_volume(o) > 1e-9 * h * h * h)
        return 0;
    const double v_old = o->surf.n_triangles > 0 ? rest_volume(o) : 0;
    double *v = NULL;
    int32_t *t = NULL;
    int nv = 0, nt = 0, rc = -1;
    char err[128];
    cs_surface ns;
    if (cs_surface_of_cells(&o->cm, 1, &v, &nv, &t, &nt, err, sizeof err) != 0)
        return -1;
    /* A single cube whose surface came out flat or inside-out held a sliver of the surface,
     * not a cube of material: its whole boundary would add up to h^3 to the pieces' volume
     * (measured: 13-15 % of a star cut down to single cubes, 2 % of a torus). It gets the
     * cube shrunk about its centre to the magnitude of the volume it had, at least 1e-3 h^3
     * so that no triangle is degenerate: the pieces' volume changes by
     * max(|v_old|, 1e-3 h^3) - v_old instead of h^3 - v_old. */
    if (o->cm.n_cells == 1 && nv > 0) {
        const double target = fmax(fabs(v_old), 1e-3 * h * h * h);
        const double sc = target < h * h * h ? cbrt(target / (h * h * h)) : 1.0;
        double mid[3];
        for (int k = 0; k < 3; k++)
            mid[k] = o->cm.origin[k] + h * (o->cm.cell_ijk[k] + 0.5);
        for (int i = 0; i < nv; i++)
            for (int k = 0; k < 3; k++)
                v[3 * (size_t)i + k] = mid[k] + sc * (v[3 * (size_t)i + k] - mid[k]);
    }
    if (cs_surface_bind(&ns, &o->cm, v, nv, t, nt, err, sizeof err) != 0) {
        free(v);
        free(t);
        return -1;
    }
    free(v);
    free(t);
    cs_surface_skin(&ns, &o->cm, o->x, 1);
    uint8_t *kind = malloc((size_t)(nt ? nt : 1));
    int32_t *vrem = malloc((size_t)(o->surf.n_vertices + 1) * sizeof *vrem);
    int32_t *trem = malloc((size_t)(o->surf.n_triangles + 1) * sizeof *trem);
    if (!kind || !vrem || !trem)
        goto out;
    memset(kind, 1, (size_t)nt);
    for (int i = 0; i < o->surf.n_vertices; i++)
        vrem[i] = o->surf.n_vertices - 1 - i;
    for (int i = 0; i < o->surf.n_triangles; i++)
        trem[i] = o->surf.n_triangles - 1 - i;
    if (record) {
        cs_topo_change c = {.object_id = (int32_t)o->id, .from_version = o->topology_version,
                            .to_version = o->topology_version + 1, .n_vertices_total = nv,
                            .n_triangles_total = nt, .n_vremove = o->surf.n_vertices,
                            .vremove = vrem, .n_vnew = nv, .vnew_xyz = ns.pos,
                            .n_tremove = o->surf.n_triangles, .tremove = trem, .n_tnew = nt,
                            .tnew = ns.tris};
        if (push_change(w, &c))
            goto out;
        o->topology_version++;
    }
    cs_surface_free(&o->surf);
    o->surf = ns;
    memset(&ns, 0, sizeof ns);
    free(o->tri_kind);
    o->tri_kind = kind;
    kind = NULL;
    for (int i = 0; o->corner_vertex && i < o->n; i++)
        o->corner_vertex[i] = -1;
    rc = 1;
out:
    cs_surface_free(&ns);
    free(kind);
    free(vrem);
    free(trem);
    return rc;
}

/* Does the centre of cell c lie inside o's closed rest surface (winding number > ½)? */
static bool cell_inside(const cs_object *o, int32_t c)
{
    surf_edit e = {.o = (cs_object *)o, .nv0 = o->surf.n_vertices, .nt0 = o->surf.n_triangles};
    double p[3];
    for (int k = 0; k < 3; k++)
        p[k] = o->cm.origin[k] + o->cm.h * (o->cm.cell_ijk[3 * (size_t)c + k] + 0.5);
    return inside_surface(&e, p);
}

/* Split o into face-connected pieces: the largest stays o, every other becomes a new object
 * announced by an event and a from-version-0 change. */
static int split_pieces(cs_world_t *w, cs_object *o, int *n_rebuilt, int *n_dropped)
{
    const cs_cubemesh *cm = &o->cm;
    const int nc = cm->n_cells;
    int32_t *parent = malloc((size_t)nc * sizeof *parent);
    int32_t *comp = malloc((size_t)nc * sizeof *comp);
    int32_t *count = calloc((size_t)nc, sizeof *count);
    int32_t *cmap = malloc((size_t)nc * sizeof *cmap);
    int32_t *list = malloc((size_t)nc * sizeof *list);
    int rc = -1;
    if (!parent || !comp || !count || !cmap || !list)
        goto out;
    /* face-connected: face neighbours still sharing a node of their face (cells that touch
     * only along an edge or at a corner become pieces of their own; each keeps a copy of the
     * nodes they shared) */
    union_face_neighbours(cm, parent);
    /* components numbered by their first cell */
    int ncomp = 0;
    int32_t *root_comp = malloc((size_t)nc * sizeof *root_comp);
    if (!root_comp)
        goto out;
    for (int i = 0; i < nc; i++)
        root_comp[i] = -1;
    for (int c = 0; c < nc; c++) {
        int r = uf_find(parent, c);
        if (root_comp[r] < 0)
            root_comp[r] = ncomp++;
        comp[c] = root_comp[r];
        count[comp[c]]++;
    }
    free(root_comp);
    if (ncomp <= 1) {
        rc = 0;
        goto out;
    }
    int keep = 0;
    for (int k = 1; k < ncomp; k++)
        if (count[k] > count[keep])
            keep = k;
    for (int k = 0; k < ncomp; k++) {
        if (k == keep)
            continue;
        int n = 0;
        for (int c = 0; c < nc; c++) {
            cmap[c] = comp[c] == k ? n : -1;
            if (comp[c] == k)
                list[n++] = c;
        }
        int32_t *vsrc = NULL;
        cs_object *p = make_piece(w, o, list, n, cmap, &vsrc);
        if (!p)
            goto out;
        if (p->surf.n_triangles == 0 && !cell_inside(o, list[0])) {
            free(vsrc);
            /* cubes outside the surface holding none of it: voxels that only grazed it
             * (seed 000 §2.1 keeps every cube the surface touches). No material, nothing to
             * show: dropped rather than made into an invisible object. (Cubes inside with no
             * surface left get the boundary of their cubes below.) */
            cs_object_free_internal(p);
            (*n_dropped)++;
            continue;
        }
        const int nv_piece = p->surf.n_vertices;
        p->name = piece_name(w, o->name);
        if (!p->name || cs_world_append_object(w, p) != 0) {
            free(vsrc);
            cs_object_free_internal(p);
            goto out;
        }
        int fans = 0, rebuilt;
        if (close_open_loops(w, p, false, &fans) != 0 ||
            (rebuilt = ensure_positive_volume(w, p, false)) < 0) {
            free(vsrc);
            goto out;
        }
        *n_rebuilt += rebuilt;
        p->topology_version = 1;
        /* sources: o's vertices, then whatever closing the piece's loops added (new points;
         * a rebuilt surface is all new) */
        int32_t *grown = rebuilt ? NULL : realloc(vsrc, (size_t)(p->surf.n_vertices + 1) *
                                                            sizeof *vsrc);
        if (!grown) {
            free(vsrc);
            vsrc = NULL;
        } else {
            vsrc = grown;
            for (int i = nv_piece; i < p->surf.n_vertices; i++)
                vsrc[i] = -1;
        }
        cs_topo_change ch = {.object_id = (int32_t)p->id, .parent_id = (int32_t)o->id,
                             .name = p->name, .model = cs_model_name(p->model),
                             .from_version = 0, .to_version = 1,
                             .n_vertices_total = p->surf.n_vertices,
                             .n_triangles_total = p->surf.n_triangles,
                             .n_vnew = p->surf.n_vertices, .vnew_xyz = p->surf.pos,
                             .n_tnew = p->surf.n_triangles, .tnew = p->surf.tris,
                             .vnew_src = vsrc};
        cs_event ev = {.kind = CS_EVENT_NEW_PIECE, .object = p->id, .parent = o->id,
                       .frame = w->frame};
        const int pushed = push_change(w, &ch);
        free(vsrc);
        if (pushed || push_event(w, &ev))
            goto out;
    }
    int n = 0;
    for (int c = 0; c < nc; c++) {
        cmap[c] = comp[c] == keep ? n : -1;
        if (comp[c] == keep)
            list[n++] = c;
    }
    rc = keep_cells(w, o, list, n, cmap);
    if (rc == 0) {
        int rebuilt = ensure_positive_volume(w, o, true);
        rc = rebuilt < 0 ? -1 : 0;
        *n_rebuilt += rebuilt > 0;
    }
out:
    free(parent);
    free(comp);
    free(count);
    free(cmap);
    free(list);
    return rc;
}

/* ---------------------------------------------------------------- one fracture event */

_Static_assert(sizeof(crack_face) == 4 * sizeof(int32_t), "crack_face is four int32");

/* Bit of a face in cs_object.cell_open (the same layout as cell_cut). */
static bool face_open(const cs_object *o, int32_t c, int axis, int dir)
{
    return o->cell_open && (o->cell_open[c] & face_bit(axis, dir));
}

/*
 * The faces of the affected cells that this event opened fully: not open before, and the two
 * cells now share none of the face's four nodes. These get closing surfaces (§3.2); c1 is the
 * cell on the plane's + side (or the lower one). A face whose rim nodes stay shared is still
 * held there: it opens (and is closed) in the event that separates its last node.
 */
static int opened_faces(cs_object *o, const int8_t *label, const uint8_t *affected, bool partial,
                        ivec *out)
{
    const cs_cubemesh *cm = &o->cm;
    if (!o->cell_open && !(o->cell_open = calloc((size_t)cm->n_cells, 1)))
        return -1;
    for (int c = 0; c < cm->n_cells; c++) {
        if (!affected[c])
            continue;
        const int32_t *q = cm->cell_ijk + 3 * (size_t)c;
        for (int axis = 0; axis < 3; axis++) {
            int32_t nb[3] = {q[0], q[1], q[2]};
            nb[axis]++;
            int32_t d = cs_cubemesh_find(cm, nb[0], nb[1], nb[2]);
            if (d < 0 || face_open(o, c, axis, 1))
                continue;
            int cs[4], n_shared = 0;
            face_corners(axis, 1, cs);
            for (int k = 0; k < 4; k++) {
                int32_t nc_ = cm->cell_nodes[8 * (size_t)c + cs[k]];
                for (int j = 0; j < 8; j++)
                    if (cm->cell_nodes[8 * (size_t)d + j] == nc_) {
                        n_shared++;
                        break;
                    }
            }
            if (n_shared == 4 || (n_shared > 0 && !partial))
                continue;
            o->cell_open[c] |= face_bit(axis, 1);
            o->cell_open[d] |= face_bit(axis, -1);
            /* c is below d: c1 = c unless d is on the + side */
            bool c_first = label[c] >= label[d];
            if (ivec_push(out, c_first ? c : d) || ivec_push(out, c_first ? d : c) ||
                ivec_push(out, axis) || ivec_push(out, c_first ? 1 : 0))
                return -1;
        }
    }
    return 0;
}

/* Does every triangle of the object's own mesh lie in a lattice plane (a surface made of cube
 * faces: objects given as cells, voxel models)? Then the mesh meets a face of the lattice only
 * along its edges. */
static bool mesh_on_lattice(const cs_object *o)
{
    const cs_surface *s = &o->surf;
    const cs_cubemesh *cm = &o->cm;
    for (int t = 0; t < s->n_triangles; t++) {
        if (o->tri_kind[t] != 0)
            continue;
        const int32_t *q = s->tris + 3 * (size_t)t;
        bool in_plane = false;
        for (int a = 0; a < 3 && !in_plane; a++) {
            const double x = s->rest[3 * (size_t)q[0] + a];
            const double l = (x - cm->origin[a]) / cm->h;
            in_plane = fabs(l - nearbyint(l)) <= 1e-9 && s->rest[3 * (size_t)q[1] + a] == x &&
                       s->rest[3 * (size_t)q[2] + a] == x;
        }
        if (!in_plane)
            return false;
    }
    return true;
}

/*
 * The second corner vertices of nodes (split_glued made them for cavities meeting at one
 * edge): used by closing triangles only, at the very rest point of the corner vertex a node at
 * that lattice point names. corner_of[v] = -2 - node for them (split_surface groups them by
 * node copy like the node's own).
 */
static int mark_cavity_corners(const cs_object *o, int32_t *corner_of)
{
    const cs_surface *s = &o->surf;
    const cs_cubemesh *cm = &o->cm;
    uint8_t *mesh_used = calloc((size_t)(s->n_vertices ? s->n_vertices : 1), 1);
    if (!mesh_used)
        return -1;
    for (int t = 0; t < s->n_triangles; t++)
        for (int k = 0; k < 3; k++)
            if (o->tri_kind[t] == 0)
                mesh_used[s->tris[3 * (size_t)t + k]] = 1;
            else if (!mesh_used[s->tris[3 * (size_t)t + k]])
                mesh_used[s->tris[3 * (size_t)t + k]] = 2;
    for (int v = 0; v < s->n_vertices; v++) {
        if (mesh_used[v] != 2 || corner_of[v] != -1)
            continue;
        const double *p = s->rest + 3 * (size_t)v;
        int32_t li[3];
        for (int k = 0; k < 3; k++)
            li[k] = (int32_t)llround((p[k] - cm->origin[k]) / cm->h);
        for (int d = 0; d < 8 && corner_of[v] == -1; d++) {
            const int dx = d & 1, dy = (d >> 1) & 1, dz = (d >> 2) & 1;
            const int32_t c = cs_cubemesh_find(cm, li[0] - dx, li[1] - dy, li[2] - dz);
            if (c < 0)
                continue;
            const int32_t nd = cm->cell_nodes[8 * (size_t)c + corner_id(dx, dy, dz)];
            const int32_t r = o->corner_vertex[nd];
            if (r >= 0 && r != v && r < s->n_vertices &&
                !memcmp(s->rest + 3 * (size_t)r, p, 3 * sizeof(double)))
                corner_of[v] = -2 - nd;
        }
    }
    free(mesh_used);
    return 0;
}

/* Vertex x of a triangle of cell ct as the surface split will leave it: a corner vertex (of a
 * node: corner_of) with the node copy ct holds now, another vertex as it is. */
static int64_t split_ident(const cs_object *o, const int32_t *corner_of, int32_t x, int32_t ct)
{
    const int32_t c = corner_of[x];
    if (c == -1)
        return (int64_t)x << 32;
    const double *p = o->cm.node_rest + 3 * (size_t)(c >= 0 ? c : -2 - c);
    const int k = corner_at(&o->cm, ct, p);
    return ((int64_t)x << 32) | (uint32_t)(k >= 0 ? o->cm.cell_nodes[8 * (size_t)ct + k] : -1);
}

/*
 * Second corner vertices are a state of the moment: two cavities hinged on one edge. Where the
 * cells around them changed (an affected cell holds one of its triangles), each goes back into
 * the vertex its node copy names (before the event), so that the surface split below sees one
 * vertex per node copy again; split_glued splits it anew where cavities still meet at an edge.
 * Every triangle of such a vertex is merged or none (the surface stays closed), in s->tris and
 * tris0 alike (the state the event starts from), and flagged rewired. A vertex is merged only where no edge at
 * the merged vertex is then used twice in one direction, counted as the surface split will
 * leave it; where that does not hold it stays (the repair closes what is left between the
 * two vertices with fans; see fracture_shuffled_box_cuts_keep_closing_pairs).
 */
static void merge_cavity_corners(cs_object *o, surf_edit *e, const int32_t *cn0, int32_t *tris0,
                                 const uint8_t *affected, const int32_t *corner_of)
{
    cs_surface *s = &o->surf;
    const cs_cubemesh *cm = &o->cm;
    for (int t = 0; t < e->nt0; t++) {
        if (!affected[s->tri_cell[t]] || o->tri_kind[t] == 0)
            continue;
        for (int k = 0; k < 3; k++) {
            const int32_t u = tris0[3 * (size_t)t + k];
            if (corner_of[u] > -2)
                continue;
            /* the node copy each of u's triangles had; all must name the same vertex */
            const double *p = cm->node_rest + 3 * (size_t)(-2 - corner_of[u]);
            int32_t into = -1;
            bool ok = true;
            for (int j = 0; j < e->nt0 && ok; j++) {
                const int32_t *q = tris0 + 3 * (size_t)j;
                if (q[0] != u && q[1] != u && q[2] != u)
                    continue;
                const int32_t ct = s->tri_cell[j];
                const int kc = corner_at(cm, ct, p);
                const int32_t r = kc >= 0 ? o->corner_vertex[cn0[8 * (size_t)ct + kc]] : -1;
                ok = r >= 0 && r != u && (into < 0 || r == into) &&
                     !memcmp(s->rest + 3 * (size_t)r, s->rest + 3 * (size_t)u, 3 * sizeof(double));
                into = r;
            }
            if (!ok || into < 0)
                continue;
            /* and only if no edge at the merged vertex is then used twice in one direction,
             * counted as the surface split will leave it: a corner vertex taken per node copy
             * of each triangle's cell (split_surface), other vertices as they are */
            int64_t ein[2 * 96], eout[2 * 96];
            int ni = 0, no = 0;
            for (int j = 0; j < e->nt0 && ok; j++) {
                const int32_t *q = tris0 + 3 * (size_t)j;
                for (int i = 0; i < 3 && ok; i++) {
                    if (q[i] != u && q[i] != into)
                        continue;
                    const int32_t ct = s->tri_cell[j];
                    const int64_t self = split_ident(o, corner_of, into, ct),
                                  nx = split_ident(o, corner_of, q[(i + 1) % 3] == u ? into : q[(i + 1) % 3], ct),
                                  pv = split_ident(o, corner_of, q[(i + 2) % 3] == u ? into : q[(i + 2) % 3], ct);
                    for (int x = 0; x < no && ok; x++)
                        ok = eout[2 * x] != self || eout[2 * x + 1] != nx;
                    for (int x = 0; x < ni && ok; x++)
                        ok = ein[2 * x] != self || ein[2 * x + 1] != pv;
                    ok = ok && no < 96 && ni < 96;
                    if (ok) {
                        eout[2 * no] = self;
                        eout[2 * no++ + 1] = nx;
                        ein[2 * ni] = self;
                        ein[2 * ni++ + 1] = pv;
                    }
                }
            }
            if (!ok)
                continue;
            for (int j = 0; j < e->nt0; j++)
                for (int i = 0; i < 3; i++)
                    if (tris0[3 * (size_t)j + i] == u) {
                        tris0[3 * (size_t)j + i] = s->tris[3 * (size_t)j + i] = into;
                        e->rewired[j] = 1;
                    }
        }
    }
}

/*
 * Separate the cells of o labelled +1 from those labelled -1 (seed 000 §2.3 and §3), make the
 * pieces, record changes and events. *cut receives the number of faces separated (0: nothing
 * was joined across the labels, nothing changed).
 */
static int fracture_event(cs_world_t *w, cs_object *o, const int8_t *label, bool paper,
                          int32_t centre, const double normal[3], double stress, int *cut)
{
    cs_cubemesh *cm = &o->cm;
    const int nc = cm->n_cells, n_old = o->n;
    ivec Fv = {0}, touched = {0}, newsrc = {0}, Ov = {0};
    crack_face *O = NULL;
    pairkey *fset = NULL;
    int32_t *cn0 = NULL, *tris0 = NULL, *corner_of = NULL;
    uint8_t *affected = NULL;
    surf_edit e = {0};
    families fam = {0};
    patch_list pl = {0};
    int rc = CS_ERR_NOMEM;
    *cut = 0;
    /* 1. crack faces */
    for (int c = 0; c < nc; c++) {
        if (label[c] <= 0)
            continue;
        const int32_t *q = cm->cell_ijk + 3 * (size_t)c;
        for (int axis = 0; axis < 3; axis++)
            for (int dir = -1; dir <= 1; dir += 2) {
                int32_t nb[3] = {q[0], q[1], q[2]};
                nb[axis] += dir;
                int32_t d = cs_cubemesh_find(cm, nb[0], nb[1], nb[2]);
                if (d < 0 || label[d] >= 0 || !face_joined(o, c, d, axis, dir))
                    continue;
                if (ivec_push(&Fv, c) || ivec_push(&Fv, d) || ivec_push(&Fv, axis) ||
                    ivec_push(&Fv, dir > 0))
                    goto out;
            }
    }
    const int nF = Fv.n / 4;
    if (nF == 0) {
        rc = CS_OK;
        goto out;
    }
    crack_face *F = (crack_face *)NULL;
    F = malloc((size_t)nF * sizeof *F);
    fset = malloc((size_t)nF * sizeof *fset);
    if (!F || !fset) {
        free(F);
        goto out;
    }
    for (int i = 0; i < nF; i++) {
        F[i] = (crack_face){Fv.a[4 * i], Fv.a[4 * i + 1], Fv.a[4 * i + 2], Fv.a[4 * i + 3]};
        fset[i] = (pairkey){F[i].c1 < F[i].c2 ? F[i].c1 : F[i].c2,
                            F[i].c1 < F[i].c2 ? F[i].c2 : F[i].c1};
    }
    qsort(fset, (size_t)nF, sizeof *fset, cmp_pair);
    if (!o->cell_cut && !(o->cell_cut = calloc((size_t)nc, 1)))
        goto out_f;
    for (int i = 0; i < nF; i++) {
        const int dir = F[i].c1_below ? 1 : -1;
        o->cell_cut[F[i].c1] |= face_bit(F[i].axis, dir);
        o->cell_cut[F[i].c2] |= face_bit(F[i].axis, -dir);
    }
    /* state before: cell links and triangles */
    cn0 = malloc((size_t)nc * 8 * sizeof *cn0);
    tris0 = malloc((size_t)(o->surf.n_triangles ? o->surf.n_triangles : 1) * 3 * sizeof *tris0);
    if (!cn0 || !tris0)
        goto out_f;
    memcpy(cn0, cm->cell_nodes, (size_t)nc * 8 * sizeof *cn0);
    memcpy(tris0, o->surf.tris, (size_t)o->surf.n_triangles * 3 * sizeof *tris0);
    if (!o->corner_vertex) {
        o->corner_vertex = malloc((size_t)o->n * sizeof *o->corner_vertex);
        if (!o->corner_vertex)
            goto out_f;
        for (int i = 0; i < o->n; i++)
            o->corner_vertex[i] = -1;
    }
    corner_of = malloc((size_t)(o->surf.n_vertices ? o->surf.n_vertices : 1) * sizeof *corner_of);
    if (!corner_of)
        goto out_f;
    for (int i = 0; i < o->surf.n_vertices; i++)
        corner_of[i] = -1;
    for (int i = 0; i < o->n; i++)
        if (o->corner_vertex[i] >= 0 && o->corner_vertex[i] < o->surf.n_vertices)
            corner_of[o->corner_vertex[i]] = i;
    const bool partial = !paper && mesh_on_lattice(o);
    if (partial && mark_cavity_corners(o, corner_of) != 0)
        goto out_f;
    /* 2. nodes */
    if (split_nodes(o, F, nF, fset, label, paper, &touched, &newsrc) < 0 ||
        refresh_node_state(w, o, n_old, &newsrc) != 0)
        goto out_f;
    /* 3. surface: the cells around split nodes; the faces they opened fully */
    affected = calloc((size_t)nc, 1);
    if (!affected)
        goto out_f;
    for (int i = 0; i < touched.n; i++) {
        int32_t nd = touched.a[i];
        for (int a = o->fem.adj_start[nd]; a < o->fem.adj_start[nd + 1]; a++)
            affected[o->fem.adj[a] / 8] = 1;
    }
    if (opened_faces(o, label, affected, partial, &Ov) != 0)
        goto out_f;
    const int nO = Ov.n / 4;
    O = (crack_face *)Ov.a; /* 4 int32 per face, laid out as crack_face */
    e.o = o;
    e.partial = partial;
    if (!(e.piece = piece_roots(cm)))
        goto out_f;
    e.nv0 = o->surf.n_vertices;
    e.nt0 = o->surf.n_triangles;
    e.rewired = calloc((size_t)(e.nt0 ? e.nt0 : 1), 1);
    if (!e.rewired)
        goto out_f;
    if (partial)
        merge_cavity_corners(o, &e, cn0, tris0, affected, corner_of);
    if (split_surface(o, &e, cn0, tris0, affected, corner_of, &fam) != 0)
        goto out_f;
    /* 4. closing surfaces, 5. repair */
    if (close_faces(w, o, &e, tris0, O, nO, label, &fam, &pl) != 0)
        goto out_f;
    int fans = 0, closing = 0;
    if (repair_and_commit(w, o, &e, &pl, &fans, &closing, true) != 0)
        goto out_f;
    cs_event ev = {.kind = CS_EVENT_FRACTURE, .object = o->id, .frame = w->frame,
                   .normal = {normal[0], normal[1], normal[2]}, .stress = stress,
                   .faces_cut = nF, .closing_triangles = closing, .fallback_loops = fans};
    {
        const int32_t *nd = cm->cell_nodes + 8 * (size_t)centre;
        for (int k = 0; k < 8; k++)
            for (int a = 0; a < 3; a++)
                ev.point[a] += o->x[3 * (size_t)nd[k] + a] / 8.0;
    }
    if (push_event(w, &ev))
        goto out_f;
    *cut = nF;
    o->sleeping = false;
    o->still_steps = 0;
    o->elastic_energy_valid = false;
    /* 6. pieces */
    int rebuilt = 0, dropped = 0;
    rc = split_pieces(w, o, &rebuilt, &dropped) == 0 ? CS_OK : CS_ERR_NOMEM;
    for (int i = w->n_events - 1; i >= 0; i--)
        if (w->events[i].kind == CS_EVENT_FRACTURE && w->events[i].object == o->id) {
            w->events[i].rebuilt_pieces = rebuilt;
            w->events[i].dropped_pieces = dropped;
            break;
        }
out_f:
    free(F);
out:
    free(Fv.a);
    free(Ov.a);
    free(touched.a);
    free(newsrc.a);
    free(fset);
    free(cn0);
    free(tris0);
    free(corner_of);
    free(affected);
    surf_edit_free(&e);
    families_free(&fam);
    free(pl.tri.a);
    free(pl.cell.a);
    free(pl.group.a);
    return rc;
}

/* ---------------------------------------------------------------- drivers */

/* Current centre of cell c. */
static void cell_centre(const cs_object *o, int32_t c, double p[3])
{
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
    p[0] = p[1] = p[2] = 0;
    for (int k = 0; k < 8; k++)
        for (int a = 0; a < 3; a++)
            p[a] += o->x[3 * (size_t)nd[k] + a] / 8.0;
}

/* §2.3: label the cells within `radius` of cell `centre` by the side of the plane through its
 * centre with normal n on which their centres lie (+ on the positive side and on the plane). */
static int8_t *plane_labels(const cs_object *o, int32_t centre, const double n[3], double radius,
                            bool centre_below)
{
    const int nc = o->cm.n_cells;
    int8_t *label = calloc((size_t)nc, 1);
    if (!label)
        return NULL;
    double c0[3];
    cell_centre(o, centre, c0);
    const double r2 = radius * radius;
    for (int c = 0; c < nc; c++) {
        double p[3];
        cell_centre(o, c, p);
        double d[3] = {p[0] - c0[0], p[1] - c0[1], p[2] - c0[2]};
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > r2)
            continue;
        const double dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
        label[c] = (centre_below ? dn > 0 : dn >= 0) ? 1 : -1;
    }
    return label;
}

static double effective_radius(const cs_object *o, double radius)
{
    double r = radius > 0 ? radius : o->fracture_radius;
    return fmax(r, 1.01 * o->cm.h); /* at least the face neighbours take part */
}

int cs_fracture_after_step(cs_world_t *w, cs_object *o)
{
    const int nc = o->cm.n_cells;
    if (nc < 2 || !(o->mat.strength < 1e299))
        return CS_OK;
    /* The common step breaks nothing: one stress pass, no allocation. After a fracture the
     * stresses are the same (duplicated nodes keep their positions), so the next most
     * stressed cube is found by the same pass, skipping the cubes already labelled. */
    uint8_t *done = NULL;
    int rc = CS_OK;
    const int n_objects = w->n_objects;
    /* The stress test reads the FEM rotations; models other than FEM do not keep them. */
    if (o->model != CS_MODEL_LINEAR && o->model != CS_MODEL_COROTATIONAL)
        cs_fem_update_rotations(&o->fem, o->x);
    for (int k = 0; k < w->def.max_fractures; k++) {
        int best = -1;
        double best_sig = 0, best_dir[3] = {0, 0, 0};
        /* the most stressed cube by the closed form of the largest eigenvalue
         * (cs_mat3_sym_max_eigen: a tenth of the scene's step time went to the Jacobi
         * eigensolver on every cube of the fracture demo); the eigensolver then gives the
         * chosen cube's stress and direction. (Cubes within 1e-8 of strength or of each
         * other may rank otherwise than by the eigensolver: the stresses are not that
         * exact.) */
        for (int c = 0; c < nc; c++) {
            if (done && done[c])
                continue;
            double S[9];
            cell_stress(o, c, S);
            if (!(cs_mat3_sym_max_eigen_bound(S) > o->mat.strength))
                continue; /* most cubes, most steps: no acos, no cos */
            const double sig = cs_mat3_sym_max_eigen(S);
            if (sig > o->mat.strength && (best < 0 || sig > best_sig)) {
                best = c;
                best_sig = sig;
            }
        }
        if (best < 0)
            break;
        best_sig = cell_max_stress(o, best, best_dir);
        if (!done && !(done = calloc((size_t)nc, 1))) {
            rc = CS_ERR_NOMEM;
            break;
        }
        int8_t *label = plane_labels(o, best, best_dir, effective_radius(o, 0), false);
        if (!label) {
            rc = CS_ERR_NOMEM;
            break;
        }
        for (int c = 0; c < nc; c++)
            if (label[c])
                done[c] = 1;
        int cut = 0;
        rc = fracture_event(w, o, label, true, best, best_dir, best_sig, &cut);
        free(label);
        if (rc == CS_OK && cut == 0 && w->n_objects == n_objects) {
            /* The plane through the cube's centre keeps the cube (and the cubes in its plane)
             * on the + side; where no joined neighbour lies on the - side (a cube against a
             * free or already cut face, such as a bar's end layer against its support) the
             * crack belongs on the cube's other side. */
            if (!(label = plane_labels(o, best, best_dir, effective_radius(o, 0), true))) {
                rc = CS_ERR_NOMEM;
                break;
            }
            rc = fracture_event(w, o, label, true, best, best_dir, best_sig, &cut);
            free(label);
        }
        if (rc != CS_OK || w->n_objects != n_objects || o->cm.n_cells != nc)
            break; /* pieces renumbered o's cells, or a grazing cube went (no piece is made
                    * of it, session 33: the star's next stress pass read past its cells):
                    * the rest waits for the next step */
    }
    free(done);
    return rc;
}

/* The cell whose centre is nearest p, or -1. Past about 1.3e154 m the squared distances
 * overflow for every cell (a client's fracture at x = 1e200 left none and crashed the daemon),
 * and then the distances themselves are compared; -1 only where even those overflow. */
static int nearest_cell(const cs_object *o, const double p[3])
{
    int best = -1;
    double bd = INFINITY;
    for (int pass = 0; pass < 2 && best < 0; pass++)
        for (int c = 0; c < o->cm.n_cells; c++) {
            double q[3];
            cell_centre(o, c, q);
            const double dx = q[0] - p[0], dy = q[1] - p[1], dz = q[2] - p[2];
            const double d = pass == 0 ? dx * dx + dy * dy + dz * dz : hypot(hypot(dx, dy), dz);
            if (d < bd) {
                bd = d;
                best = c;
            }
        }
    return best;
}

int cs_world_fracture(cs_world_t *w, cs_object_id id, const double point[3],
                      const double normal[3], double radius, char *err, size_t errlen)
{
    if (!w || !point || !normal)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "NULL argument");
    cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return cs_engine_fail(err, errlen, CS_ERR_UNKNOWN_OBJECT, "no object with id %u", (unsigned)id);
    double m = 0;
    for (int a = 0; a < 3; a++) {
        if (!isfinite(point[a]) || !isfinite(normal[a]))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID, "fracture point and normal must be finite");
        m = fmax(m, fabs(normal[a]));
    }
    if (!(m > 0))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "fracture normal must not be zero");
    if (!(radius >= 0 && isfinite(radius)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "fracture radius must be >= 0 m, got %g",
                    radius);
    /* The normal scaled by its largest component first: the squares of (1e300, 0, 0) overflow
     * and of (1e-200, 0, 0) underflow, and either left a zero or NaN normal. */
    const double u[3] = {normal[0] / m, normal[1] / m, normal[2] / m};
    const double un = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    const double n[3] = {u[0] / un, u[1] / un, u[2] / un};
    const int best = nearest_cell(o, point);
    if (best < 0)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "fracture point (%g, %g, %g) is too far from '%s' to find its "
                              "nearest cube", point[0], point[1], point[2], o->name);
    cs_fracture_clear_step(w);
    cs_rigid_drop_pending(w);
    int8_t *label = plane_labels(o, best, n, effective_radius(o, radius), false);
    if (!label)
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
    int cut = 0;
    int rc = fracture_event(w, o, label, true, best, n, 0.0, &cut);
    free(label);
    if (rc == CS_OK)
        rc = cs_rigid_sync(w); /* rigid pieces: their own mass properties */
    if (rc != CS_OK)
        return cs_engine_fail(err, errlen, rc, "fracture of '%s' failed: %s", o->name, cs_status_str(rc));
    return CS_OK;
}

int cs_world_cut_face(cs_world_t *w, cs_object_id id, const int32_t ijk[3], int axis,
                      char *err, size_t errlen)
{
    if (!w || !ijk)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "NULL argument");
    cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return cs_engine_fail(err, errlen, CS_ERR_UNKNOWN_OBJECT, "no object with id %u", (unsigned)id);
    if (axis < 0 || axis > 2)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "axis must be 0, 1 or 2, got %d", axis);
    int32_t a = cs_cubemesh_find(&o->cm, ijk[0], ijk[1], ijk[2]);
    int32_t nb[3] = {ijk[0], ijk[1], ijk[2]};
    nb[axis]++;
    int32_t b = cs_cubemesh_find(&o->cm, nb[0], nb[1], nb[2]);
    if (a < 0 || b < 0)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                    "object '%s' has no cells (%d,%d,%d) and its +%c neighbour", o->name,
                    ijk[0], ijk[1], ijk[2], "xyz"[axis]);
    if (!face_joined(o, a, b, axis, 1))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "the face after cell (%d,%d,%d) along %c is "
                    "already cut", ijk[0], ijk[1], ijk[2], "xyz"[axis]);
    cs_fracture_clear_step(w);
    cs_rigid_drop_pending(w);
    int8_t *label = calloc((size_t)o->cm.n_cells, 1);
    if (!label)
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
    label[a] = 1;
    label[b] = -1;
    double n[3] = {0, 0, 0};
    n[axis] = -1; /* from the + cell towards the − cell is +axis: the + side lies below */
    int cut = 0;
    int rc = fracture_event(w, o, label, false, a, n, 0.0, &cut);
    free(label);
    if (rc == CS_OK)
        rc = cs_rigid_sync(w);
    if (rc != CS_OK)
        return cs_engine_fail(err, errlen, rc, "cut of '%s' failed: %s", o->name, cs_status_str(rc));
    return CS_OK;
}
