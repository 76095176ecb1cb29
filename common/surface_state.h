/*
 * surface_state.h — what a client holds of the daemon's world, rebuilt from the bus.
 *
 * Owns: per object its id, name, model, parent (for pieces), topology_version, float32 surface
 * positions and triangles (DESIGN.md "Bus"). Fed with decoded CUBESIM_SNAPSHOT chunks,
 * CUBESIM_TOPOLOGY chunks and CUBESIM_DELTA messages; it makes no LCM calls itself, so tests
 * drive it directly.
 *
 * Invariants
 * - `objects` is the last complete snapshot with every accepted delta applied on top; every
 *   triangle index is in [0, nv) and every coordinate is finite.
 * - A snapshot replaces the state only when all n_chunks chunks of one (session_id,
 *   snapshot_id) arrived, in any order; a chunk of a newer snapshot drops a half-built one.
 * - A delta is applied only to the same session, epoch, object and topology_version, and only
 *   whole: a delta with any bad field changes nothing.
 * - A topology change (lcmtypes/topology_t.lcm, common/topo.h) is applied only when all its
 *   chunks arrived, only to the same session and epoch, only to an object whose
 *   topology_version is its from_version (a new piece: to an id not yet held), only after
 *   cs_topo_check passed, and only whole. It bumps the object's topology_version to
 *   to_version; a new piece becomes a new object (appended, remembering its parent).
 * - A message of a new session or epoch invalidates the state (valid = 0, stale = 1) until the
 *   next complete snapshot of that session and epoch; a gap in header.seq on CUBESIM_DELTA or
 *   CUBESIM_TOPOLOGY, a topology change left incomplete, rejected or whose from_version does
 *   not follow the object's version marks it stale (the client should ask for a snapshot:
 *   deltas for a topology it does not hold are ignored until then). A stale state is still
 *   applied to.
 *
 * Every malformed input is rejected with CS_SS_REJECTED and a one-line message; nothing here
 * prints, aborts or trusts a count it did not check.
 */
#ifndef CS_SURFACE_STATE_H
#define CS_SURFACE_STATE_H

#include <stddef.h>
#include <stdint.h>

#include "mesh.h"

/* Results of the apply functions. */
typedef enum cs_ss_result {
    CS_SS_APPLIED = 0,    /* the message changed the state (or completed a snapshot) */
    CS_SS_PENDING = 1,    /* a snapshot chunk was stored; the snapshot is not complete yet */
    CS_SS_IGNORED = 2,    /* well formed but not applicable (old, other session, no state yet) */
    CS_SS_REJECTED = -1,  /* malformed: err says why; the state is unchanged */
    CS_SS_NOMEM = -2      /* out of memory; the state is unchanged */
} cs_ss_result;

/* The header fields every daemon -> client message carries (cubesim_header_t, flattened so
 * this file does not depend on lcm-gen output). */
typedef struct cs_ss_header {
    int64_t session_id;
    int32_t epoch;
    int64_t frame;
    int64_t seq;
    double sim_time;
} cs_ss_header;

/* One CUBESIM_SNAPSHOT chunk, borrowed views of the decoded message. */
typedef struct cs_ss_chunk {
    cs_ss_header header;
    int32_t snapshot_id, chunk, n_chunks, n_objects;
    int32_t object_id;
    const char *object_name, *model;
    int32_t topology_version, n_vertices_total, n_triangles_total;
    int32_t vertex_offset, n_coords;
    const float *xyz;
    int32_t triangle_offset, n_indices;
    const int32_t *indices;
} cs_ss_chunk;

/* One CUBESIM_DELTA message, borrowed views. */
typedef struct cs_ss_delta {
    cs_ss_header header;
    int32_t object_id, topology_version, chunk, n_chunks, n_vertices_total;
    int32_t n;
    const int32_t *index;
    int32_t n_coords;
    const float *xyz;
} cs_ss_delta;

/* One CUBESIM_TOPOLOGY message (a chunk of one topology change), borrowed views; the fields
 * mean what lcmtypes/topology_t.lcm says. */
typedef struct cs_ss_topo {
    cs_ss_header header;
    int32_t change_id, chunk, n_chunks;
    int32_t object_id, parent_id;
    const char *name, *model;
    int32_t from_version, to_version, n_vertices_total, n_triangles_total;
    int32_t total_vremove, total_vnew, total_tremove, total_tset, total_tnew;
    int32_t vremove_offset, n_vremove;
    const int32_t *vremove;
    int32_t vnew_offset, n_vnew_coords;
    const float *vnew_xyz;
    int32_t tremove_offset, n_tremove;
    const int32_t *tremove;
    int32_t tset_offset, n_tset;
    const int32_t *tset_index;
    int32_t n_tset_indices;
    const int32_t *tset_tri;
    int32_t tnew_offset, n_tnew_indices;
    const int32_t *tnew;
    int32_t n_vnew_src;      /* 0 (every new vertex a new point) or n_vnew_coords / 3 */
    const int32_t *vnew_src; /* the vertex each new one is a copy of, or -1 (topo.h) */
} cs_ss_topo;

typedef struct cs_ss_object {
    int32_t id;
    int32_t parent_id;       /* a piece: the object it broke off (from CUBESIM_TOPOLOGY; kept
                                across snapshots of the same epoch); else 0 */
    char *name;              /* owned */
    char *model;             /* owned */
    int32_t topology_version;
    int nv;
    float *xyz;              /* owned, 3 per vertex */
    int nt;
    int32_t *tris;           /* owned, 3 per triangle */
    /* rigid objects (CUBESIM_POSE): the copy and pose of the last reference pose; has_ref is
     * 0 until one arrives and again after a snapshot or topology change of the object */
    int has_ref;
    float *ref_xyz;          /* owned, 3 per vertex */
    double ref_q[4], ref_c[3];
    /* Volume ledger (kept when cs_surface_state.track_volume is set; cleared by
     * cs_surface_state_clear_volume_ledger): topo_dv is the sum, over the topology changes
     * applied to this object since (topo_changed: any), of the enclosed volume after the
     * change minus before, both at the positions before it (a copy at its source's
     * position, a new point at its vnew_xyz; a new piece counts its whole volume, its copies
     * at its parent's positions). Where the closing surfaces come in mirror pairs, the sum
     * over an object and its new pieces is 0 up to round-off. */
    int topo_changed;
    double topo_dv;
} cs_ss_object;

/* One CUBESIM_POSE message (lcmtypes/pose_t.lcm). */
typedef struct cs_ss_pose {
    cs_ss_header header;
    int32_t object_id, topology_version, n_vertices_total;
    int32_t reference;
    double position[3], orientation[4];
} cs_ss_pose;

typedef struct cs_ss_pending cs_ss_pending; /* a snapshot being assembled (private) */
typedef struct cs_ss_tpending cs_ss_tpending; /* a topology change being assembled (private) */

typedef struct cs_surface_state {
    int valid;               /* a complete snapshot of the current session/epoch is held */
    int stale;               /* the client should ask for a snapshot (loss, restart, reset) */
    int64_t session_id;      /* of the state (or of the last message seen when !valid) */
    int32_t epoch;
    int have_session;
    int64_t frame;           /* last frame applied */
    double sim_time;
    int32_t snapshot_id;     /* of the last complete snapshot */
    int n_objects;
    cs_ss_object *objects;   /* owned */

    /* CUBESIM_DELTA sequence tracking (per daemon session). */
    int have_delta_seq;
    int64_t delta_session;
    int64_t last_delta_seq;
    int64_t deltas_lost;     /* messages missing from header.seq gaps, all sessions */

    /* CUBESIM_POSE sequence tracking (per daemon session). */
    int have_pose_seq;
    int64_t pose_session;
    int64_t last_pose_seq;
    int64_t poses_lost;

    /* CUBESIM_TOPOLOGY sequence tracking and counts. */
    int have_topo_seq;
    int64_t topo_session;
    int64_t last_topo_seq;
    int64_t topology_lost;       /* messages missing from header.seq gaps, all sessions */
    int64_t topology_incomplete; /* changes dropped because a chunk never came */
    int64_t topology_applied;    /* changes applied, all sessions */
    int track_volume;            /* set by the caller: keep the objects' volume ledgers */

    cs_ss_pending *pending;  /* owned */
    cs_ss_tpending *tpending; /* owned */
} cs_surface_state;

/* An empty state (valid = 0). Nothing is allocated until messages arrive. */
void cs_surface_state_init(cs_surface_state *st);
/* Free everything and leave an empty state. */
void cs_surface_state_free(cs_surface_state *st);

/*
 * Store one snapshot chunk. Returns CS_SS_APPLIED when it completed a snapshot (the state is
 * replaced: valid = 1, stale = 0), CS_SS_PENDING when more chunks are needed, CS_SS_IGNORED
 * for a chunk of an older snapshot or epoch, CS_SS_REJECTED for a malformed chunk (counts that
 * disagree, offsets out of range, chunk >= n_chunks, non-finite coordinates, triangle indices
 * outside the object) — a rejected chunk also drops the half-built snapshot it belonged to.
 */
int cs_surface_state_apply_chunk(cs_surface_state *st, const cs_ss_chunk *c, char *err,
                                 size_t errlen);

/*
 * Apply one delta (absolute float32 positions). Tracks header.seq first: a gap marks the
 * state stale and adds to deltas_lost. Returns CS_SS_APPLIED, CS_SS_IGNORED (no valid state,
 * another session or epoch, a frame older than the state, or a topology_version other than
 * the object's — err then says which, and the state is marked stale), or CS_SS_REJECTED
 * (unknown object — also marked stale: it may be a piece whose topology change was lost —,
 * counts that disagree, index out of range, non-finite coordinate).
 */
/*
 * Apply one pose of a rigid object (lcmtypes/pose_t.lcm): with reference = 1 the object's
 * current copy and this pose become its reference; otherwise every vertex is set from the
 * reference by cs_pose_transform. Same session/epoch/object/version rules as a delta; a pose
 * without a reference is ignored (and marks the state stale). Tracks header.seq (gap: stale).
 */
int cs_surface_state_apply_pose(cs_surface_state *st, const cs_ss_pose *p, char *err,
                                size_t errlen);
void cs_surface_state_note_pose_seq(cs_surface_state *st, const cs_ss_header *h);
/* out = float(c + R(q) R(q_r)ᵀ (ref − c_r)) for nv vertices, in double: the daemon computes
 * its record of what it sent with this same function, so both stay identical. */
void cs_pose_transform(const float *ref, int nv, const double q_r[4], const double c_r[3],
                       const double q[4], const double c[3], float *out);

int cs_surface_state_apply_delta(cs_surface_state *st, const cs_ss_delta *d, char *err,
                                 size_t errlen);

/* Track header.seq of a CUBESIM_DELTA that the caller chooses not to apply (e.g. a replay
 * stopping at a frame) so that the gaps it would hide are not reported as loss. */
void cs_surface_state_note_delta_seq(cs_surface_state *st, const cs_ss_header *h);

/*
 * Store one topology chunk and, when it completes its change, apply the change. Tracks
 * header.seq of CUBESIM_TOPOLOGY first (a gap marks the state stale). Returns
 * CS_SS_APPLIED (a change was applied: objects changed or one was added), CS_SS_PENDING (more
 * chunks needed), CS_SS_IGNORED (no valid state, older epoch or frame, a change the object
 * already has, a duplicate chunk, or — stale set — a from_version that does not follow the
 * object's version or an object not held), CS_SS_REJECTED (malformed chunk, chunks that
 * disagree, or a change cs_topo_check refuses; the partial change is dropped, stale set), or
 * CS_SS_NOMEM. The state is unchanged unless CS_SS_APPLIED.
 */
int cs_surface_state_apply_topology(cs_surface_state *st, const cs_ss_topo *t, char *err,
                                    size_t errlen);

/* Track header.seq of a CUBESIM_TOPOLOGY message the caller chooses not to apply. */
void cs_surface_state_note_topology_seq(cs_surface_state *st, const cs_ss_header *h);

/* Zero every object's volume ledger (topo_changed, topo_dv). */
void cs_surface_state_clear_volume_ledger(cs_surface_state *st);

/* Object by id, or NULL. */
const cs_ss_object *cs_surface_state_find(const cs_surface_state *st, int32_t id);

/* FNV-1a 64 (offset 14695981039346656037, prime 1099511628211) over the bytes of the float32
 * array x0,y0,z0,x1,... in little-endian order: equals cs_object_state_hash of the engine when
 * the floats are the engine's positions rounded to float. */
uint64_t cs_surface_hash_floats(const float *xyz, int nv);
uint64_t cs_ss_object_hash(const cs_ss_object *o);

/*
 * The state as meshes for cs_mesh_export: one piece per object, in state order, named after
 * the object. *pieces and *names (and the strings, which are copies) are malloc'd; release
 * them with cs_surface_state_meshes_free. Returns 0, or -1 with err set (empty or no state,
 * out of memory).
 */
int cs_surface_state_to_meshes(const cs_surface_state *st, cs_mesh **pieces, char ***names,
                               int *n, char *err, size_t errlen);
void cs_surface_state_meshes_free(cs_mesh *pieces, char **names, int n);

/* One object's surface as doubles (3 per vertex), malloc'd; NULL on out of memory. */
double *cs_ss_object_vertices_double(const cs_ss_object *o);

#endif
