/*
 * surface_state.c — a client's copy of the daemon's surfaces, rebuilt from snapshot chunks and
 * deltas (DESIGN.md "Bus"; the protocol is lcmtypes/snapshot_t.lcm and delta_t.lcm).
 *
 * Owns the assembled objects and one half-built snapshot. Snapshot chunks are checked in full
 * (counts, offsets, finiteness, triangle indices) before anything is copied; every vertex and
 * triangle slot of an object must be filled exactly once for the snapshot to complete, so
 * overlapping or missing chunks can never pass as a complete surface.
 */
#include "surface_state.h"

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Bounds that no real message reaches; they keep a hostile count from sizing an allocation. */
#define CS_SS_MAX_CHUNKS (1 << 20)
#define CS_SS_MAX_ELEMS (1 << 27)

typedef struct cs_ss_pobj {
    cs_ss_object o;
    uint8_t *vfill, *tfill; /* 1 per vertex / triangle once a chunk filled it */
    int nv_filled, nt_filled;
} cs_ss_pobj;

struct cs_ss_pending {
    int64_t session_id;
    int32_t epoch;
    int32_t snapshot_id;
    int32_t n_chunks;
    int32_t n_objects;
    int n_got;
    uint8_t *got;       /* 1 per chunk */
    int64_t frame;
    double sim_time;
    int n_obj;
    cs_ss_pobj *obj;    /* capacity max(n_objects, 1) */
};

static char *dup_str(const char *s)
{
    if (!s)
        s = "";
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d)
        memcpy(d, s, n);
    return d;
}

static void object_free(cs_ss_object *o)
{
    free(o->name);
    free(o->model);
    free(o->xyz);
    free(o->tris);
    memset(o, 0, sizeof *o);
}

static void objects_free(cs_ss_object *objs, int n)
{
    for (int i = 0; i < n; i++)
        object_free(&objs[i]);
    free(objs);
}

static void pending_free(cs_ss_pending *p)
{
    if (!p)
        return;
    for (int i = 0; i < p->n_obj; i++) {
        object_free(&p->obj[i].o);
        free(p->obj[i].vfill);
        free(p->obj[i].tfill);
    }
    free(p->obj);
    free(p->got);
    free(p);
}

void cs_surface_state_init(cs_surface_state *st)
{
    memset(st, 0, sizeof *st);
}

void cs_surface_state_free(cs_surface_state *st)
{
    objects_free(st->objects, st->n_objects);
    pending_free(st->pending);
    cs_surface_state_init(st);
}

static void drop_pending(cs_surface_state *st)
{
    pending_free(st->pending);
    st->pending = NULL;
}

/* Forget the objects (a new session or epoch made them meaningless). */
static void invalidate(cs_surface_state *st)
{
    objects_free(st->objects, st->n_objects);
    st->objects = NULL;
    st->n_objects = 0;
    st->valid = 0;
    st->stale = 1;
    st->frame = 0;
    st->sim_time = 0;
    st->snapshot_id = -1;
}

/*
 * Relate a message's session and epoch to the state's. Returns 1 if the message is older
 * than the state (to be ignored), else 0 after invalidating the state for a new session or
 * a later epoch. A daemon's sessions have no order, so any other session counts as new.
 */
static int observe(cs_surface_state *st, const cs_ss_header *h)
{
    if (!st->have_session) {
        st->have_session = 1;
        st->session_id = h->session_id;
        st->epoch = h->epoch;
        st->snapshot_id = -1;
        return 0;
    }
    if (h->session_id != st->session_id) {
        invalidate(st);
        st->session_id = h->session_id;
        st->epoch = h->epoch;
        return 0;
    }
    if (h->epoch < st->epoch)
        return 1;
    if (h->epoch > st->epoch) {
        int32_t snap = st->snapshot_id;
        invalidate(st);
        st->snapshot_id = snap; /* snapshot ids run on across epochs of one session */
        st->epoch = h->epoch;
    }
    return 0;
}

static int check_floats(const float *x, int n, char *err, size_t errlen, const char *what)
{
    for (int i = 0; i < n; i++) {
        if (!isfinite(x[i])) {
            snprintf(err, errlen, "%s: coordinate %d is not finite", what, i);
            return -1;
        }
    }
    return 0;
}

/* Every field of a chunk that can be checked on its own. */
static int check_chunk(const cs_ss_chunk *c, char *err, size_t errlen)
{
    if (c->n_chunks < 1 || c->n_chunks > CS_SS_MAX_CHUNKS) {
        snprintf(err, errlen, "snapshot %" PRId32 ": n_chunks %" PRId32 " out of range",
                 c->snapshot_id, c->n_chunks);
        return -1;
    }
    if (c->chunk < 0 || c->chunk >= c->n_chunks) {
        snprintf(err, errlen, "snapshot %" PRId32 ": chunk %" PRId32 " not in [0, %" PRId32 ")",
                 c->snapshot_id, c->chunk, c->n_chunks);
        return -1;
    }
    if (c->n_objects < 0 || c->n_objects > c->n_chunks) {
        snprintf(err, errlen,
                 "snapshot %" PRId32 ": n_objects %" PRId32 " impossible with %" PRId32 " chunks",
                 c->snapshot_id, c->n_objects, c->n_chunks);
        return -1;
    }
    if (c->n_objects == 0) {
        if (c->n_chunks != 1 || c->n_coords != 0 || c->n_indices != 0) {
            snprintf(err, errlen, "snapshot %" PRId32 ": an empty world must be one empty chunk",
                     c->snapshot_id);
            return -1;
        }
        return 0;
    }
    if (c->n_vertices_total < 0 || c->n_vertices_total > CS_SS_MAX_ELEMS / 3 ||
        c->n_triangles_total < 0 || c->n_triangles_total > CS_SS_MAX_ELEMS / 3) {
        snprintf(err, errlen, "snapshot %" PRId32 " object %" PRId32 ": totals %" PRId32
                 " vertices, %" PRId32 " triangles out of range", c->snapshot_id, c->object_id,
                 c->n_vertices_total, c->n_triangles_total);
        return -1;
    }
    if (c->n_coords < 0 || c->n_coords % 3 || (c->n_coords && !c->xyz) || c->vertex_offset < 0 ||
        (int64_t)c->vertex_offset + c->n_coords / 3 > c->n_vertices_total) {
        snprintf(err, errlen, "snapshot %" PRId32 " object %" PRId32 ": vertices [%" PRId32
                 ", +%" PRId32 " coords) do not fit %" PRId32 " vertices", c->snapshot_id,
                 c->object_id, c->vertex_offset, c->n_coords, c->n_vertices_total);
        return -1;
    }
    if (c->n_indices < 0 || c->n_indices % 3 || (c->n_indices && !c->indices) ||
        c->triangle_offset < 0 ||
        (int64_t)c->triangle_offset + c->n_indices / 3 > c->n_triangles_total) {
        snprintf(err, errlen, "snapshot %" PRId32 " object %" PRId32 ": triangles [%" PRId32
                 ", +%" PRId32 " indices) do not fit %" PRId32 " triangles", c->snapshot_id,
                 c->object_id, c->triangle_offset, c->n_indices, c->n_triangles_total);
        return -1;
    }
    char what[96];
    snprintf(what, sizeof what, "snapshot %" PRId32 " object %" PRId32, c->snapshot_id,
             c->object_id);
    if (check_floats(c->xyz, c->n_coords, err, errlen, what))
        return -1;
    for (int i = 0; i < c->n_indices; i++) {
        if (c->indices[i] < 0 || c->indices[i] >= c->n_vertices_total) {
            snprintf(err, errlen, "%s: triangle index %" PRId32 " not in [0, %" PRId32 ")", what,
                     c->indices[i], c->n_vertices_total);
            return -1;
        }
    }
    return 0;
}

static cs_ss_pending *pending_new(const cs_ss_chunk *c)
{
    cs_ss_pending *p = calloc(1, sizeof *p);
    if (!p)
        return NULL;
    p->session_id = c->header.session_id;
    p->epoch = c->header.epoch;
    p->snapshot_id = c->snapshot_id;
    p->n_chunks = c->n_chunks;
    p->n_objects = c->n_objects;
    p->got = calloc((size_t)c->n_chunks, 1);
    p->obj = calloc((size_t)(c->n_objects > 0 ? c->n_objects : 1), sizeof *p->obj);
    if (!p->got || !p->obj) {
        pending_free(p);
        return NULL;
    }
    return p;
}

/* The pending object with this id, created from the chunk if new; NULL with err set. */
static cs_ss_pobj *pending_object(cs_ss_pending *p, const cs_ss_chunk *c, int *nomem, char *err,
                                  size_t errlen)
{
    for (int i = 0; i < p->n_obj; i++) {
        cs_ss_pobj *q = &p->obj[i];
        if (q->o.id != c->object_id)
            continue;
        if (q->o.nv != c->n_vertices_total || q->o.nt != c->n_triangles_total ||
            q->o.topology_version != c->topology_version ||
            strcmp(q->o.name, c->object_name ? c->object_name : "")) {
            snprintf(err, errlen, "snapshot %" PRId32 " object %" PRId32
                     ": chunk %" PRId32 " disagrees with an earlier chunk on name, version or totals",
                     c->snapshot_id, c->object_id, c->chunk);
            return NULL;
        }
        return q;
    }
    if (p->n_obj >= p->n_objects) {
        snprintf(err, errlen, "snapshot %" PRId32 ": more than n_objects = %" PRId32 " objects",
                 c->snapshot_id, p->n_objects);
        return NULL;
    }
    cs_ss_pobj *q = &p->obj[p->n_obj];
    memset(q, 0, sizeof *q);
    q->o.id = c->object_id;
    q->o.name = dup_str(c->object_name);
    q->o.model = dup_str(c->model);
    q->o.topology_version = c->topology_version;
    q->o.nv = c->n_vertices_total;
    q->o.nt = c->n_triangles_total;
    size_t nv = (size_t)c->n_vertices_total, nt = (size_t)c->n_triangles_total;
    q->o.xyz = malloc(3 * nv * sizeof(float) + 1);
    q->o.tris = malloc(3 * nt * sizeof(int32_t) + 1);
    q->vfill = calloc(nv + 1, 1);
    q->tfill = calloc(nt + 1, 1);
    p->n_obj++; /* counted now so that pending_free releases a partial object */
    if (!q->o.name || !q->o.model || !q->o.xyz || !q->o.tris || !q->vfill || !q->tfill) {
        *nomem = 1;
        snprintf(err, errlen, "out of memory assembling snapshot %" PRId32, c->snapshot_id);
        return NULL;
    }
    return q;
}

static int complete(cs_surface_state *st)
{
    cs_ss_pending *p = st->pending;
    cs_ss_object *objs = calloc((size_t)(p->n_obj > 0 ? p->n_obj : 1), sizeof *objs);
    if (!objs)
        return -1;
    for (int i = 0; i < p->n_obj; i++) {
        objs[i] = p->obj[i].o;
        memset(&p->obj[i].o, 0, sizeof p->obj[i].o);
    }
    objects_free(st->objects, st->n_objects);
    st->objects = objs;
    st->n_objects = p->n_obj;
    st->valid = 1;
    st->stale = 0;
    st->session_id = p->session_id;
    st->epoch = p->epoch;
    st->frame = p->frame;
    st->sim_time = p->sim_time;
    st->snapshot_id = p->snapshot_id;
    drop_pending(st);
    return 0;
}

int cs_surface_state_apply_chunk(cs_surface_state *st, const cs_ss_chunk *c, char *err,
                                 size_t errlen)
{
    if (check_chunk(c, err, errlen)) {
        cs_ss_pending *p = st->pending;
        if (p && p->session_id == c->header.session_id && p->snapshot_id == c->snapshot_id)
            drop_pending(st);
        return CS_SS_REJECTED;
    }
    if (observe(st, &c->header)) {
        snprintf(err, errlen, "snapshot %" PRId32 " of epoch %" PRId32 " is older than epoch %"
                 PRId32, c->snapshot_id, c->header.epoch, st->epoch);
        return CS_SS_IGNORED;
    }
    if (st->valid && c->snapshot_id <= st->snapshot_id) {
        snprintf(err, errlen, "snapshot %" PRId32 " is not newer than the state's %" PRId32,
                 c->snapshot_id, st->snapshot_id);
        return CS_SS_IGNORED;
    }
    cs_ss_pending *p = st->pending;
    if (p && (p->session_id != c->header.session_id || p->epoch != c->header.epoch ||
              p->snapshot_id != c->snapshot_id)) {
        if (p->session_id == c->header.session_id && c->snapshot_id < p->snapshot_id) {
            snprintf(err, errlen, "snapshot %" PRId32 " is older than the one being assembled",
                     c->snapshot_id);
            return CS_SS_IGNORED;
        }
        drop_pending(st);
        p = NULL;
    }
    if (p && (p->n_chunks != c->n_chunks || p->n_objects != c->n_objects)) {
        snprintf(err, errlen, "snapshot %" PRId32 ": chunk %" PRId32
                 " disagrees on n_chunks or n_objects", c->snapshot_id, c->chunk);
        drop_pending(st);
        return CS_SS_REJECTED;
    }
    if (!p) {
        p = st->pending = pending_new(c);
        if (!p) {
            snprintf(err, errlen, "out of memory for snapshot %" PRId32, c->snapshot_id);
            return CS_SS_NOMEM;
        }
    }
    if (p->got[c->chunk]) {
        snprintf(err, errlen, "snapshot %" PRId32 ": duplicate chunk %" PRId32, c->snapshot_id,
                 c->chunk);
        return CS_SS_IGNORED;
    }
    if (c->n_objects > 0) {
        int nomem = 0;
        cs_ss_pobj *q = pending_object(p, c, &nomem, err, errlen);
        if (!q) {
            drop_pending(st);
            return nomem ? CS_SS_NOMEM : CS_SS_REJECTED;
        }
        int v0 = c->vertex_offset, nvc = c->n_coords / 3;
        int t0 = c->triangle_offset, ntc = c->n_indices / 3;
        for (int i = 0; i < nvc; i++) {
            if (q->vfill[v0 + i]) {
                snprintf(err, errlen, "snapshot %" PRId32 " object %" PRId32
                         ": vertex %d sent twice", c->snapshot_id, c->object_id, v0 + i);
                drop_pending(st);
                return CS_SS_REJECTED;
            }
        }
        for (int i = 0; i < ntc; i++) {
            if (q->tfill[t0 + i]) {
                snprintf(err, errlen, "snapshot %" PRId32 " object %" PRId32
                         ": triangle %d sent twice", c->snapshot_id, c->object_id, t0 + i);
                drop_pending(st);
                return CS_SS_REJECTED;
            }
        }
        if (nvc) {
            memcpy(q->o.xyz + 3 * (size_t)v0, c->xyz, (size_t)c->n_coords * sizeof(float));
            memset(q->vfill + v0, 1, (size_t)nvc);
        }
        if (ntc) {
            memcpy(q->o.tris + 3 * (size_t)t0, c->indices, (size_t)c->n_indices * sizeof(int32_t));
            memset(q->tfill + t0, 1, (size_t)ntc);
        }
        q->nv_filled += nvc;
        q->nt_filled += ntc;
    }
    p->got[c->chunk] = 1;
    p->n_got++;
    if (c->header.frame > p->frame || p->n_got == 1) {
        p->frame = c->header.frame;
        p->sim_time = c->header.sim_time;
    }
    if (p->n_got < p->n_chunks)
        return CS_SS_PENDING;
    /* All chunks are here: every object must be present and completely filled. */
    if (p->n_obj != p->n_objects) {
        snprintf(err, errlen, "snapshot %" PRId32 ": %d objects in %" PRId32
                 " chunks, n_objects says %" PRId32, c->snapshot_id, p->n_obj, p->n_chunks,
                 p->n_objects);
        drop_pending(st);
        return CS_SS_REJECTED;
    }
    for (int i = 0; i < p->n_obj; i++) {
        const cs_ss_pobj *q = &p->obj[i];
        if (q->nv_filled != q->o.nv || q->nt_filled != q->o.nt) {
            snprintf(err, errlen, "snapshot %" PRId32 " object %" PRId32
                     ": chunks carry %d of %d vertices and %d of %d triangles", c->snapshot_id,
                     q->o.id, q->nv_filled, q->o.nv, q->nt_filled, q->o.nt);
            drop_pending(st);
            return CS_SS_REJECTED;
        }
    }
    if (complete(st)) {
        snprintf(err, errlen, "out of memory completing snapshot %" PRId32, c->snapshot_id);
        return CS_SS_NOMEM;
    }
    return CS_SS_APPLIED;
}

void cs_surface_state_note_delta_seq(cs_surface_state *st, const cs_ss_header *h)
{
    if (!st->have_delta_seq || h->session_id != st->delta_session) {
        st->have_delta_seq = 1;
        st->delta_session = h->session_id;
        st->last_delta_seq = h->seq;
        return;
    }
    if (h->seq > st->last_delta_seq + 1) {
        st->deltas_lost += h->seq - st->last_delta_seq - 1;
        st->stale = 1;
    }
    if (h->seq > st->last_delta_seq)
        st->last_delta_seq = h->seq;
}

static cs_ss_object *find_mut(cs_surface_state *st, int32_t id)
{
    for (int i = 0; i < st->n_objects; i++)
        if (st->objects[i].id == id)
            return &st->objects[i];
    return NULL;
}

const cs_ss_object *cs_surface_state_find(const cs_surface_state *st, int32_t id)
{
    return find_mut((cs_surface_state *)st, id);
}

int cs_surface_state_apply_delta(cs_surface_state *st, const cs_ss_delta *d, char *err,
                                 size_t errlen)
{
    cs_surface_state_note_delta_seq(st, &d->header);
    if (observe(st, &d->header)) {
        snprintf(err, errlen, "delta of epoch %" PRId32 " is older than epoch %" PRId32,
                 d->header.epoch, st->epoch);
        return CS_SS_IGNORED;
    }
    if (!st->valid) {
        snprintf(err, errlen, "delta for object %" PRId32 " before any snapshot", d->object_id);
        return CS_SS_IGNORED;
    }
    if (d->header.frame < st->frame) {
        snprintf(err, errlen, "delta of frame %" PRId64 " is older than the state's frame %" PRId64,
                 d->header.frame, st->frame);
        return CS_SS_IGNORED;
    }
    cs_ss_object *o = find_mut(st, d->object_id);
    if (!o) {
        snprintf(err, errlen, "delta for unknown object %" PRId32, d->object_id);
        return CS_SS_REJECTED;
    }
    if (d->topology_version != o->topology_version) {
        snprintf(err, errlen, "delta for object %" PRId32 " topology version %" PRId32
                 ", the state has %" PRId32, d->object_id, d->topology_version,
                 o->topology_version);
        st->stale = 1;
        return CS_SS_IGNORED;
    }
    if (d->n_vertices_total != o->nv) {
        snprintf(err, errlen, "delta for object %" PRId32 " says %" PRId32
                 " vertices, the state has %d", d->object_id, d->n_vertices_total, o->nv);
        return CS_SS_REJECTED;
    }
    if (d->n_chunks < 1 || d->chunk < 0 || d->chunk >= d->n_chunks) {
        snprintf(err, errlen, "delta for object %" PRId32 ": chunk %" PRId32 " not in [0, %" PRId32
                 ")", d->object_id, d->chunk, d->n_chunks);
        return CS_SS_REJECTED;
    }
    if (d->n < 0 || d->n > o->nv || (int64_t)d->n_coords != 3 * (int64_t)d->n ||
        (d->n && (!d->index || !d->xyz))) {
        snprintf(err, errlen, "delta for object %" PRId32 ": n = %" PRId32 " with n_coords = %" PRId32,
                 d->object_id, d->n, d->n_coords);
        return CS_SS_REJECTED;
    }
    for (int i = 0; i < d->n; i++) {
        if (d->index[i] < 0 || d->index[i] >= o->nv) {
            snprintf(err, errlen, "delta for object %" PRId32 ": vertex index %" PRId32
                     " not in [0, %d)", d->object_id, d->index[i], o->nv);
            return CS_SS_REJECTED;
        }
    }
    char what[64];
    snprintf(what, sizeof what, "delta for object %" PRId32, d->object_id);
    if (check_floats(d->xyz, d->n_coords, err, errlen, what))
        return CS_SS_REJECTED;
    for (int i = 0; i < d->n; i++)
        memcpy(o->xyz + 3 * (size_t)d->index[i], d->xyz + 3 * (size_t)i, 3 * sizeof(float));
    st->frame = d->header.frame;
    st->sim_time = d->header.sim_time;
    return CS_SS_APPLIED;
}

uint64_t cs_surface_hash_floats(const float *xyz, int nv)
{
    uint64_t h = 14695981039346656037ULL;
    for (size_t i = 0; i < 3 * (size_t)(nv > 0 ? nv : 0); i++) {
        uint32_t bits;
        memcpy(&bits, &xyz[i], sizeof bits);
        for (int b = 0; b < 4; b++) { /* little-endian byte order, whatever the host */
            h ^= (bits >> (8 * b)) & 0xffu;
            h *= 1099511628211ULL;
        }
    }
    return h;
}

uint64_t cs_ss_object_hash(const cs_ss_object *o)
{
    return cs_surface_hash_floats(o->xyz, o->nv);
}

double *cs_ss_object_vertices_double(const cs_ss_object *o)
{
    double *v = malloc(3 * (size_t)o->nv * sizeof(double) + 1);
    if (!v)
        return NULL;
    for (size_t i = 0; i < 3 * (size_t)o->nv; i++)
        v[i] = o->xyz[i];
    return v;
}

void cs_surface_state_meshes_free(cs_mesh *pieces, char **names, int n)
{
    for (int i = 0; i < n; i++) {
        if (pieces) {
            free(pieces[i].v);
            free(pieces[i].t);
        }
        if (names)
            free(names[i]);
    }
    free(pieces);
    free(names);
}

int cs_surface_state_to_meshes(const cs_surface_state *st, cs_mesh **pieces, char ***names,
                               int *n, char *err, size_t errlen)
{
    *pieces = NULL;
    *names = NULL;
    *n = 0;
    if (!st->valid) {
        snprintf(err, errlen, "no complete snapshot: no surface to export");
        return -1;
    }
    if (st->n_objects == 0) {
        snprintf(err, errlen, "the world is empty: no surface to export");
        return -1;
    }
    int k = st->n_objects;
    cs_mesh *p = calloc((size_t)k, sizeof *p);
    char **nm = calloc((size_t)k, sizeof *nm);
    if (!p || !nm) {
        free(p);
        free(nm);
        snprintf(err, errlen, "out of memory exporting %d objects", k);
        return -1;
    }
    for (int i = 0; i < k; i++) {
        const cs_ss_object *o = &st->objects[i];
        p[i].v = cs_ss_object_vertices_double(o);
        p[i].nv = o->nv;
        p[i].t = malloc(3 * (size_t)o->nt * sizeof(int32_t) + 1);
        p[i].nt = o->nt;
        nm[i] = dup_str(o->name);
        if (!p[i].v || !p[i].t || !nm[i]) {
            cs_surface_state_meshes_free(p, nm, k);
            snprintf(err, errlen, "out of memory exporting object '%s'", o->name);
            return -1;
        }
        if (o->nt)
            memcpy(p[i].t, o->tris, 3 * (size_t)o->nt * sizeof(int32_t));
    }
    *pieces = p;
    *names = nm;
    *n = k;
    return 0;
}
