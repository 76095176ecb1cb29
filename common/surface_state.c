/*
 * surface_state.c — a client's copy of the daemon's surfaces, rebuilt from snapshot chunks and
 * deltas (DESIGN.md "Bus"; the protocol is lcmtypes/snapshot_t.lcm and delta_t.lcm).
 *
 * Owns the assembled objects and one half-built snapshot. Snapshot chunks are checked in full
 * (counts, offsets, finiteness, triangle indices) before anything is copied; every vertex and
 * triangle slot of an object must be filled exactly once for the snapshot to complete, so
 * overlapping or missing chunks can never pass as a complete surface. Topology changes are
 * assembled the same way (every item of each of the five arrays filled exactly once), checked
 * with cs_topo_check and applied with common/topo.c on copies, so a change is applied whole
 * or not at all.
 */
#include "surface_state.h"
#include "topo.h"
#include "watertight.h"

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

/* A topology change being assembled: its identity (from the first chunk), the five arrays
 * at full size, and a fill flag per item. */
struct cs_ss_tpending {
    int64_t session_id;
    int32_t epoch;
    int32_t change_id, n_chunks, n_got;
    uint8_t *got;            /* 1 per chunk */
    int64_t frame;
    double sim_time;
    int32_t object_id, parent_id, from_version, to_version, nv_total, nt_total;
    char *name, *model;
    int32_t total[5];        /* vremove, vnew, tremove, tset, tnew (items) */
    int32_t filled[5];
    uint8_t *fill[5];        /* 1 per item */
    int32_t *vremove, *tremove, *tset_index, *tset_tri, *tnew;
    float *vnew;
    int32_t *vsrc;           /* per new vertex: its source, -1 where no chunk named one */
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
    free(o->ref_xyz);
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

static void tpending_free(cs_ss_tpending *p)
{
    if (!p)
        return;
    free(p->got);
    free(p->name);
    free(p->model);
    for (int k = 0; k < 5; k++)
        free(p->fill[k]);
    free(p->vremove);
    free(p->tremove);
    free(p->tset_index);
    free(p->tset_tri);
    free(p->tnew);
    free(p->vnew);
    free(p->vsrc);
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
    tpending_free(st->tpending);
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
    tpending_free(st->tpending);
    st->tpending = NULL;
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
        /* Snapshots do not carry parents: keep what topology changes of this epoch said
         * (observe() already emptied the state if the session or epoch changed). */
        for (int j = 0; j < st->n_objects; j++)
            if (st->objects[j].id == objs[i].id)
                objs[i].parent_id = st->objects[j].parent_id;
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
        /* Perhaps a piece whose topology message was lost: ask for a snapshot. */
        snprintf(err, errlen, "delta for unknown object %" PRId32, d->object_id);
        st->stale = 1;
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

void cs_surface_state_note_pose_seq(cs_surface_state *st, const cs_ss_header *h)
{
    if (!st->have_pose_seq || h->session_id != st->pose_session) {
        st->have_pose_seq = 1;
        st->pose_session = h->session_id;
        st->last_pose_seq = h->seq;
        return;
    }
    if (h->seq > st->last_pose_seq + 1) {
        st->poses_lost += h->seq - st->last_pose_seq - 1;
        st->stale = 1;
    }
    if (h->seq > st->last_pose_seq)
        st->last_pose_seq = h->seq;
}

static void pose_matrix(const double q[4], double R[9])
{
    const double n = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    const double s = n > 0 ? 2.0 / n : 0.0;
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    R[0] = 1 - s * (y * y + z * z);
    R[1] = s * (x * y - w * z);
    R[2] = s * (x * z + w * y);
    R[3] = s * (x * y + w * z);
    R[4] = 1 - s * (x * x + z * z);
    R[5] = s * (y * z - w * x);
    R[6] = s * (x * z - w * y);
    R[7] = s * (y * z + w * x);
    R[8] = 1 - s * (x * x + y * y);
}

void cs_pose_transform(const float *ref, int nv, const double q_r[4], const double c_r[3],
                       const double q[4], const double c[3], float *out)
{
    double Rr[9], R[9], M[9];
    pose_matrix(q_r, Rr);
    pose_matrix(q, R);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            M[3 * i + j] = R[3 * i] * Rr[3 * j] + R[3 * i + 1] * Rr[3 * j + 1] +
                           R[3 * i + 2] * Rr[3 * j + 2];
    for (int v = 0; v < nv; v++) {
        const double d[3] = {(double)ref[3 * v] - c_r[0], (double)ref[3 * v + 1] - c_r[1],
                             (double)ref[3 * v + 2] - c_r[2]};
        for (int a = 0; a < 3; a++)
            out[3 * v + a] =
                (float)(c[a] + M[3 * a] * d[0] + M[3 * a + 1] * d[1] + M[3 * a + 2] * d[2]);
    }
}

int cs_surface_state_apply_pose(cs_surface_state *st, const cs_ss_pose *p, char *err,
                                size_t errlen)
{
    cs_surface_state_note_pose_seq(st, &p->header);
    if (observe(st, &p->header)) {
        snprintf(err, errlen, "pose of epoch %" PRId32 " is older than epoch %" PRId32,
                 p->header.epoch, st->epoch);
        return CS_SS_IGNORED;
    }
    if (!st->valid) {
        snprintf(err, errlen, "pose for object %" PRId32 " before any snapshot", p->object_id);
        return CS_SS_IGNORED;
    }
    if (p->header.frame < st->frame) {
        snprintf(err, errlen, "pose of frame %" PRId64 " is older than the state's frame %" PRId64,
                 p->header.frame, st->frame);
        return CS_SS_IGNORED;
    }
    cs_ss_object *o = find_mut(st, p->object_id);
    if (!o) {
        snprintf(err, errlen, "pose for unknown object %" PRId32, p->object_id);
        st->stale = 1;
        return CS_SS_REJECTED;
    }
    if (p->topology_version != o->topology_version) {
        snprintf(err, errlen, "pose for object %" PRId32 " topology version %" PRId32
                 ", the state has %" PRId32, p->object_id, p->topology_version,
                 o->topology_version);
        st->stale = 1;
        return CS_SS_IGNORED;
    }
    if (p->n_vertices_total != o->nv) {
        snprintf(err, errlen, "pose for object %" PRId32 " says %" PRId32
                 " vertices, the state has %d", p->object_id, p->n_vertices_total, o->nv);
        return CS_SS_REJECTED;
    }
    double qn = 0;
    int finite = 1;
    for (int a = 0; a < 4; a++) {
        qn += p->orientation[a] * p->orientation[a];
        finite = finite && isfinite(p->orientation[a]);
    }
    for (int a = 0; a < 3; a++)
        finite = finite && isfinite(p->position[a]);
    if (!finite || !(fabs(qn - 1) < 1e-6) || (p->reference != 0 && p->reference != 1)) {
        snprintf(err, errlen, "pose for object %" PRId32 ": not finite, not a unit quaternion "
                 "or a bad reference flag", p->object_id);
        return CS_SS_REJECTED;
    }
    if (p->reference) {
        float *r = realloc(o->ref_xyz, 3 * (size_t)(o->nv > 0 ? o->nv : 1) * sizeof *r);
        if (!r) {
            snprintf(err, errlen, "out of memory for the pose of object %" PRId32, p->object_id);
            return CS_SS_NOMEM;
        }
        o->ref_xyz = r;
        if (o->nv)
            memcpy(r, o->xyz, 3 * (size_t)o->nv * sizeof *r);
        memcpy(o->ref_q, p->orientation, sizeof o->ref_q);
        memcpy(o->ref_c, p->position, sizeof o->ref_c);
        o->has_ref = 1;
    } else {
        if (!o->has_ref) {
            snprintf(err, errlen, "pose for object %" PRId32 " without its reference pose",
                     p->object_id);
            st->stale = 1;
            return CS_SS_IGNORED;
        }
        cs_pose_transform(o->ref_xyz, o->nv, o->ref_q, o->ref_c, p->orientation, p->position,
                          o->xyz);
    }
    st->frame = p->header.frame;
    st->sim_time = p->header.sim_time;
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

/* ---------------------------------------------------------------- topology changes */

void cs_surface_state_note_topology_seq(cs_surface_state *st, const cs_ss_header *h)
{
    if (!st->have_topo_seq || h->session_id != st->topo_session) {
        st->have_topo_seq = 1;
        st->topo_session = h->session_id;
        st->last_topo_seq = h->seq;
        return;
    }
    if (h->seq > st->last_topo_seq + 1) {
        st->topology_lost += h->seq - st->last_topo_seq - 1;
        st->stale = 1;
    }
    if (h->seq > st->last_topo_seq)
        st->last_topo_seq = h->seq;
}

static void drop_tpending(cs_surface_state *st)
{
    tpending_free(st->tpending);
    st->tpending = NULL;
}

/* A slice [off, off + n) of an array of `total` items, with its data present if n > 0. */
static int slice_ok(int32_t off, int32_t n, int32_t total, const void *data)
{
    return n >= 0 && off >= 0 && (int64_t)off + n <= total && (n == 0 || data);
}

/* Every field of a topology chunk that can be checked on its own. */
static int check_topo_chunk(const cs_ss_topo *t, char *err, size_t errlen)
{
    const int32_t tot[5] = {t->total_vremove, t->total_vnew, t->total_tremove, t->total_tset,
                            t->total_tnew};
    if (t->n_chunks < 1 || t->n_chunks > CS_SS_MAX_CHUNKS || t->chunk < 0 ||
        t->chunk >= t->n_chunks) {
        snprintf(err, errlen, "topology change %" PRId32 ": chunk %" PRId32 " of %" PRId32
                 " out of range", t->change_id, t->chunk, t->n_chunks);
        return -1;
    }
    if (t->object_id <= 0 || t->parent_id < 0 || t->from_version < 0 ||
        t->to_version <= t->from_version) {
        snprintf(err, errlen, "topology change %" PRId32 ": object %" PRId32 ", parent %" PRId32
                 ", version %" PRId32 " -> %" PRId32 " impossible", t->change_id, t->object_id,
                 t->parent_id, t->from_version, t->to_version);
        return -1;
    }
    int bad = t->n_vertices_total < 0 || t->n_vertices_total > CS_SS_MAX_ELEMS / 3 ||
              t->n_triangles_total < 0 || t->n_triangles_total > CS_SS_MAX_ELEMS / 3;
    for (int k = 0; k < 5; k++)
        bad |= tot[k] < 0 || tot[k] > CS_SS_MAX_ELEMS / 3;
    if (bad) {
        snprintf(err, errlen, "topology change %" PRId32 " of object %" PRId32
                 ": a total is out of range", t->change_id, t->object_id);
        return -1;
    }
    if (t->from_version == 0 && (t->total_vremove || t->total_tremove || t->total_tset)) {
        snprintf(err, errlen, "topology change %" PRId32 ": new object %" PRId32
                 " removes or rewires items", t->change_id, t->object_id);
        return -1;
    }
    if (t->n_vnew_coords % 3 || t->n_tset_indices != 3 * (int64_t)t->n_tset ||
        t->n_tnew_indices % 3 ||
        !slice_ok(t->vremove_offset, t->n_vremove, tot[0], t->vremove) ||
        !slice_ok(t->vnew_offset, t->n_vnew_coords / 3, tot[1], t->vnew_xyz) ||
        !slice_ok(t->tremove_offset, t->n_tremove, tot[2], t->tremove) ||
        !slice_ok(t->tset_offset, t->n_tset, tot[3], t->tset_index) ||
        (t->n_tset && !t->tset_tri) ||
        !slice_ok(t->tnew_offset, t->n_tnew_indices / 3, tot[4], t->tnew) ||
        (t->n_vnew_src != 0 && t->n_vnew_src != t->n_vnew_coords / 3) ||
        (t->n_vnew_src && !t->vnew_src)) {
        snprintf(err, errlen, "topology change %" PRId32 " of object %" PRId32 ": chunk %" PRId32
                 " has a slice that does not fit the totals", t->change_id, t->object_id,
                 t->chunk);
        return -1;
    }
    char what[96];
    snprintf(what, sizeof what, "topology change %" PRId32 " of object %" PRId32, t->change_id,
             t->object_id);
    return check_floats(t->vnew_xyz, t->n_vnew_coords, err, errlen, what);
}

static cs_ss_tpending *tpending_new(const cs_ss_topo *t)
{
    cs_ss_tpending *p = calloc(1, sizeof *p);
    if (!p)
        return NULL;
    p->session_id = t->header.session_id;
    p->epoch = t->header.epoch;
    p->change_id = t->change_id;
    p->n_chunks = t->n_chunks;
    p->object_id = t->object_id;
    p->parent_id = t->parent_id;
    p->from_version = t->from_version;
    p->to_version = t->to_version;
    p->nv_total = t->n_vertices_total;
    p->nt_total = t->n_triangles_total;
    const int32_t tot[5] = {t->total_vremove, t->total_vnew, t->total_tremove, t->total_tset,
                            t->total_tnew};
    int ok = 1;
    for (int k = 0; k < 5; k++) {
        p->total[k] = tot[k];
        p->fill[k] = calloc((size_t)tot[k] + 1, 1);
        ok &= p->fill[k] != NULL;
    }
    p->got = calloc((size_t)t->n_chunks, 1);
    p->name = dup_str(t->name);
    p->model = dup_str(t->model);
    p->vremove = malloc((size_t)tot[0] * sizeof(int32_t) + 1);
    p->vnew = malloc(3 * (size_t)tot[1] * sizeof(float) + 1);
    p->vsrc = malloc((size_t)tot[1] * sizeof(int32_t) + 1);
    for (int32_t i = 0; p->vsrc && i < tot[1]; i++)
        p->vsrc[i] = -1;
    p->tremove = malloc((size_t)tot[2] * sizeof(int32_t) + 1);
    p->tset_index = malloc((size_t)tot[3] * sizeof(int32_t) + 1);
    p->tset_tri = malloc(3 * (size_t)tot[3] * sizeof(int32_t) + 1);
    p->tnew = malloc(3 * (size_t)tot[4] * sizeof(int32_t) + 1);
    if (!ok || !p->got || !p->name || !p->model || !p->vremove || !p->vnew || !p->vsrc ||
        !p->tremove ||
        !p->tset_index || !p->tset_tri || !p->tnew) {
        tpending_free(p);
        return NULL;
    }
    return p;
}

/* Does chunk t belong to the change p is assembling (same identity and totals)? */
static int tpending_agrees(const cs_ss_tpending *p, const cs_ss_topo *t)
{
    return p->n_chunks == t->n_chunks && p->object_id == t->object_id &&
           p->parent_id == t->parent_id && p->from_version == t->from_version &&
           p->to_version == t->to_version && p->nv_total == t->n_vertices_total &&
           p->nt_total == t->n_triangles_total && p->total[0] == t->total_vremove &&
           p->total[1] == t->total_vnew && p->total[2] == t->total_tremove &&
           p->total[3] == t->total_tset && p->total[4] == t->total_tnew &&
           !strcmp(p->name, t->name ? t->name : "") && !strcmp(p->model, t->model ? t->model : "");
}

/* Mark items [off, off+n) of array k filled; -1 if one already was. */
static int fill_items(cs_ss_tpending *p, int k, int32_t off, int32_t n)
{
    for (int32_t i = 0; i < n; i++)
        if (p->fill[k][off + i])
            return -1;
    if (n)
        memset(p->fill[k] + off, 1, (size_t)n);
    p->filled[k] += n;
    return 0;
}

static int store_chunk(cs_ss_tpending *p, const cs_ss_topo *t)
{
    if (fill_items(p, 0, t->vremove_offset, t->n_vremove) ||
        fill_items(p, 1, t->vnew_offset, t->n_vnew_coords / 3) ||
        fill_items(p, 2, t->tremove_offset, t->n_tremove) ||
        fill_items(p, 3, t->tset_offset, t->n_tset) ||
        fill_items(p, 4, t->tnew_offset, t->n_tnew_indices / 3))
        return -1;
    if (t->n_vremove)
        memcpy(p->vremove + t->vremove_offset, t->vremove, (size_t)t->n_vremove * 4);
    if (t->n_vnew_coords)
        memcpy(p->vnew + 3 * (size_t)t->vnew_offset, t->vnew_xyz, (size_t)t->n_vnew_coords * 4);
    if (t->n_vnew_src)
        memcpy(p->vsrc + t->vnew_offset, t->vnew_src, (size_t)t->n_vnew_src * 4);
    if (t->n_tremove)
        memcpy(p->tremove + t->tremove_offset, t->tremove, (size_t)t->n_tremove * 4);
    if (t->n_tset) {
        memcpy(p->tset_index + t->tset_offset, t->tset_index, (size_t)t->n_tset * 4);
        memcpy(p->tset_tri + 3 * (size_t)t->tset_offset, t->tset_tri, (size_t)t->n_tset * 12);
    }
    if (t->n_tnew_indices)
        memcpy(p->tnew + 3 * (size_t)t->tnew_offset, t->tnew, (size_t)t->n_tnew_indices * 4);
    return 0;
}

/* Apply the complete change p. Returns a cs_ss_result; the state changes only on APPLIED. */
static int apply_change(cs_surface_state *st, const cs_ss_tpending *p, char *err, size_t errlen)
{
    cs_ss_object *o = find_mut(st, p->object_id);
    if (p->from_version == 0 ? o != NULL : o == NULL) {
        if (o && o->topology_version >= p->to_version) {
            snprintf(err, errlen, "topology change %" PRId32 ": object %" PRId32
                     " is already held at version %" PRId32, p->change_id, p->object_id,
                     o->topology_version);
            return CS_SS_IGNORED;
        }
        snprintf(err, errlen, "topology change %" PRId32 ": object %" PRId32 " %s",
                 p->change_id, p->object_id,
                 o ? "is held already but the change creates it" : "is not held");
        st->stale = 1;
        return CS_SS_IGNORED;
    }
    if (o && o->topology_version != p->from_version) {
        if (o->topology_version >= p->to_version) {
            snprintf(err, errlen, "topology change %" PRId32 " of object %" PRId32
                     " is older than the held version %" PRId32, p->change_id, p->object_id,
                     o->topology_version);
            return CS_SS_IGNORED;
        }
        snprintf(err, errlen, "topology change %" PRId32 " of object %" PRId32 " is from version %"
                 PRId32 ", the state has %" PRId32 " (a change was missed)", p->change_id,
                 p->object_id, p->from_version, o->topology_version);
        st->stale = 1;
        return CS_SS_IGNORED;
    }
    int nv = o ? o->nv : 0, nt = o ? o->nt : 0;
    double *vnew = malloc(3 * (size_t)p->total[1] * sizeof *vnew + 1);
    if (!vnew) {
        snprintf(err, errlen, "out of memory applying topology change %" PRId32, p->change_id);
        return CS_SS_NOMEM;
    }
    for (size_t i = 0; i < 3 * (size_t)p->total[1]; i++)
        vnew[i] = p->vnew[i];
    cs_topo_change c = {.object_id = p->object_id, .parent_id = p->parent_id,
                        .name = p->name, .model = p->model,
                        .from_version = (uint32_t)p->from_version,
                        .to_version = (uint32_t)p->to_version, .n_vertices_total = p->nv_total,
                        .n_triangles_total = p->nt_total, .n_vremove = p->total[0],
                        .vremove = p->vremove, .n_vnew = p->total[1], .vnew_xyz = vnew,
                        .n_tremove = p->total[2], .tremove = p->tremove,
                        .n_tset = p->total[3], .tset_index = p->tset_index,
                        .tset_tri = p->tset_tri, .n_tnew = p->total[4], .tnew = p->tnew,
                        .vnew_src = p->vsrc};
    char why[200];
    if (cs_topo_check(&c, nv, nt, why, sizeof why)) {
        free(vnew);
        snprintf(err, errlen, "topology change %" PRId32 " of object %" PRId32 ": %s",
                 p->change_id, p->object_id, why);
        st->stale = 1;
        return CS_SS_REJECTED;
    }
    free(vnew);
    /* Work on copies so that a failed allocation changes nothing. */
    size_t vcap = (size_t)(nv > p->nv_total ? nv : p->nv_total);
    size_t tcap = (size_t)(nt > p->nt_total ? nt : p->nt_total);
    float *xyz = malloc(3 * vcap * sizeof *xyz + 1);
    int32_t *tris = malloc(3 * tcap * sizeof *tris + 1);
    char *name = NULL, *model = NULL;
    cs_ss_object *objs = NULL;
    if (!o) {
        name = dup_str(p->name);
        model = dup_str(p->model);
        objs = realloc(st->objects, (size_t)(st->n_objects + 1) * sizeof *objs);
        if (objs)
            st->objects = objs; /* same contents, one more slot: harmless if we stop here */
    }
    if (!xyz || !tris || (!o && (!name || !model || !objs))) {
        free(xyz);
        free(tris);
        free(name);
        free(model);
        snprintf(err, errlen, "out of memory applying topology change %" PRId32, p->change_id);
        return CS_SS_NOMEM;
    }
    if (nv)
        memcpy(xyz, o->xyz, 3 * (size_t)nv * sizeof *xyz);
    if (nt)
        memcpy(tris, o->tris, 3 * (size_t)nt * sizeof *tris);
    int nv1 = cs_topo_remove_vertices(&c, xyz, 3 * sizeof *xyz, nv);
    if (p->total[1])
        memcpy(xyz + 3 * (size_t)nv1, p->vnew, 3 * (size_t)p->total[1] * sizeof *xyz);
    cs_topo_apply_triangles(&c, tris, nt);
    double v_before = 0, v_after = 0;
    if (st->track_volume) {
        /* the volume after, at the positions before: survivors where they were, a copy at
         * its source's position (in o, or in the parent of a new piece), a new point at its
         * vnew_xyz */
        const cs_ss_object *from = o ? o : find_mut(st, p->parent_id);
        double *at = malloc(3 * vcap * sizeof *at + sizeof *at), *old = NULL;
        if (at && o && (old = malloc(3 * (size_t)nv * sizeof *old + sizeof *old)) == NULL) {
            free(at);
            at = NULL;
        }
        if (!at) {
            free(xyz);
            free(tris);
            free(name);
            free(model);
            snprintf(err, errlen, "out of memory applying topology change %" PRId32,
                     p->change_id);
            return CS_SS_NOMEM;
        }
        for (size_t i = 0; i < 3 * (size_t)nv; i++)
            at[i] = old[i] = o->xyz[i];
        if (o)
            v_before = cs_mesh_volume(old, o->tris, o->nt);
        int k1 = cs_topo_remove_vertices(&c, at, 3 * sizeof *at, nv);
        for (int32_t i = 0; i < p->total[1]; i++) {
            const int32_t sv = p->vsrc[i];
            for (int a = 0; a < 3; a++)
                at[3 * (size_t)(k1 + i) + a] = sv >= 0 && from && sv < from->nv
                                                   ? from->xyz[3 * (size_t)sv + a]
                                                   : p->vnew[3 * (size_t)i + a];
        }
        v_after = cs_mesh_volume(at, tris, p->nt_total);
        free(at);
        free(old);
    }
    if (!o) {
        o = &st->objects[st->n_objects++];
        memset(o, 0, sizeof *o);
        o->id = p->object_id;
        o->parent_id = p->parent_id;
        o->name = name;
        o->model = model;
    }
    free(o->xyz);
    free(o->tris);
    free(o->ref_xyz);
    o->ref_xyz = NULL;
    o->has_ref = 0; /* its vertices changed: the daemon sends a new reference pose */
    o->xyz = xyz;
    o->tris = tris;
    o->nv = p->nv_total;
    o->nt = p->nt_total;
    o->topology_version = p->to_version;
    if (st->track_volume) {
        o->topo_changed = 1;
        o->topo_dv += v_after - v_before;
    }
    st->frame = p->frame;
    st->sim_time = p->sim_time;
    st->topology_applied++;
    return CS_SS_APPLIED;
}

void cs_surface_state_clear_volume_ledger(cs_surface_state *st)
{
    for (int i = 0; i < st->n_objects; i++) {
        st->objects[i].topo_changed = 0;
        st->objects[i].topo_dv = 0;
    }
}

int cs_surface_state_apply_topology(cs_surface_state *st, const cs_ss_topo *t, char *err,
                                    size_t errlen)
{
    cs_surface_state_note_topology_seq(st, &t->header);
    if (check_topo_chunk(t, err, errlen)) {
        cs_ss_tpending *p = st->tpending;
        if (p && p->session_id == t->header.session_id && p->change_id == t->change_id)
            drop_tpending(st);
        st->stale = 1; /* whatever it was, a change may have been lost with it */
        return CS_SS_REJECTED;
    }
    if (observe(st, &t->header)) {
        snprintf(err, errlen, "topology change of epoch %" PRId32 " is older than epoch %" PRId32,
                 t->header.epoch, st->epoch);
        return CS_SS_IGNORED;
    }
    if (!st->valid) {
        snprintf(err, errlen, "topology change for object %" PRId32 " before any snapshot",
                 t->object_id);
        return CS_SS_IGNORED;
    }
    if (t->header.frame < st->frame) {
        snprintf(err, errlen, "topology change of frame %" PRId64 " is older than the state's "
                 "frame %" PRId64, t->header.frame, st->frame);
        return CS_SS_IGNORED;
    }
    cs_ss_tpending *p = st->tpending;
    if (p && (p->session_id != t->header.session_id || p->epoch != t->header.epoch ||
              p->change_id != t->change_id)) {
        /* Chunks of one change are sent back to back: another change means a chunk of this
         * one was lost. */
        st->topology_incomplete++;
        st->stale = 1;
        drop_tpending(st);
        p = NULL;
    }
    if (p && !tpending_agrees(p, t)) {
        snprintf(err, errlen, "topology change %" PRId32 ": chunk %" PRId32
                 " disagrees with an earlier chunk on the object, versions or totals",
                 t->change_id, t->chunk);
        drop_tpending(st);
        st->stale = 1;
        return CS_SS_REJECTED;
    }
    if (!p) {
        p = st->tpending = tpending_new(t);
        if (!p) {
            snprintf(err, errlen, "out of memory for topology change %" PRId32, t->change_id);
            st->stale = 1;
            return CS_SS_NOMEM;
        }
    }
    if (p->got[t->chunk]) {
        snprintf(err, errlen, "topology change %" PRId32 ": duplicate chunk %" PRId32,
                 t->change_id, t->chunk);
        return CS_SS_IGNORED;
    }
    if (store_chunk(p, t)) {
        snprintf(err, errlen, "topology change %" PRId32 ": chunk %" PRId32
                 " overlaps an earlier chunk", t->change_id, t->chunk);
        drop_tpending(st);
        st->stale = 1;
        return CS_SS_REJECTED;
    }
    p->got[t->chunk] = 1;
    if (p->n_got++ == 0 || t->header.frame > p->frame) {
        p->frame = t->header.frame;
        p->sim_time = t->header.sim_time;
    }
    if (p->n_got < p->n_chunks)
        return CS_SS_PENDING;
    for (int k = 0; k < 5; k++) {
        if (p->filled[k] != p->total[k]) {
            snprintf(err, errlen, "topology change %" PRId32 ": its %" PRId32 " chunks carry %"
                     PRId32 " of %" PRId32 " items of array %d", t->change_id, p->n_chunks,
                     p->filled[k], p->total[k], k);
            drop_tpending(st);
            st->stale = 1;
            return CS_SS_REJECTED;
        }
    }
    int r = apply_change(st, p, err, errlen);
    drop_tpending(st);
    if (r == CS_SS_NOMEM)
        st->stale = 1;
    return r;
}
