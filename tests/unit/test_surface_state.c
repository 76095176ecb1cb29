/*
 * test_surface_state.c — the client's surface state (common/surface_state.c): snapshot chunk
 * assembly in any order, deltas, version and session rules, loss detection from header.seq,
 * rejection of malformed input, and the FNV-1a state hash against a hand computation.
 */
#include "check.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "surface_state.h"
#include "watertight.h"

/* A unit tetrahedron: 4 vertices, 4 outward triangles. */
static const float tet_xyz[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
static const int32_t tet_tris[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};

static cs_ss_header hdr(int64_t session, int32_t epoch, int64_t frame, int64_t seq)
{
    cs_ss_header h = {session, epoch, frame, seq, frame / 60.0};
    return h;
}

/* Chunk `k` of a snapshot of one tetrahedron (id 7) split into 3 chunks: vertices 0-1 with
 * triangles 0-1, vertices 2-3 with triangles 2-3, and an empty chunk. */
static cs_ss_chunk tet_chunk(int k, int64_t session, int32_t snap)
{
    cs_ss_chunk c = {0};
    c.header = hdr(session, 0, 10, snap);
    c.snapshot_id = snap;
    c.chunk = k;
    c.n_chunks = 3;
    c.n_objects = 1;
    c.object_id = 7;
    c.object_name = "tet";
    c.model = "corotational";
    c.topology_version = 1;
    c.n_vertices_total = 4;
    c.n_triangles_total = 4;
    if (k < 2) {
        c.vertex_offset = 2 * k;
        c.n_coords = 6;
        c.xyz = tet_xyz + 6 * k;
        c.triangle_offset = 2 * k;
        c.n_indices = 6;
        c.indices = tet_tris + 6 * k;
    }
    return c;
}

static int load_tet(cs_surface_state *st, int64_t session, int32_t snap)
{
    char err[256];
    cs_ss_chunk zero = {0}; /* n_chunks 0: malformed, must change nothing */
    if (cs_surface_state_apply_chunk(st, &zero, err, sizeof err) != CS_SS_REJECTED)
        return -100;
    int r = 0;
    for (int k = 2; k >= 0; k--) {
        cs_ss_chunk c = tet_chunk(k, session, snap);
        r = cs_surface_state_apply_chunk(st, &c, err, sizeof err);
    }
    return r;
}

TEST(surface_state_chunks_any_order)
{
    static const int orders[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    for (int o = 0; o < 6; o++) {
        cs_surface_state st;
        cs_surface_state_init(&st);
        char err[256];
        for (int i = 0; i < 3; i++) {
            cs_ss_chunk c = tet_chunk(orders[o][i], 42, 1);
            int r = cs_surface_state_apply_chunk(&st, &c, err, sizeof err);
            ENSURE_MSG(r == (i < 2 ? CS_SS_PENDING : CS_SS_APPLIED), "order %d step %d: %d %s", o,
                       i, r, err);
            ENSURE(st.valid == (i == 2));
        }
        ENSURE(st.n_objects == 1);
        const cs_ss_object *t = cs_surface_state_find(&st, 7);
        ENSURE(t && t->nv == 4 && t->nt == 4);
        ENSURE(!strcmp(t->name, "tet") && !strcmp(t->model, "corotational"));
        ENSURE(!memcmp(t->xyz, tet_xyz, sizeof tet_xyz));
        ENSURE(!memcmp(t->tris, tet_tris, sizeof tet_tris));
        ENSURE(st.frame == 10 && st.session_id == 42 && st.snapshot_id == 1);
        cs_surface_state_free(&st);
    }
}

TEST(surface_state_empty_chunk_is_rejected_not_stored)
{
    /* load_tet above feeds an all-zero chunk before each real one: n_chunks 0 is malformed and
     * must neither crash nor disturb the assembly. */
    cs_surface_state st;
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 5, 1) == CS_SS_APPLIED);
    ENSURE(st.valid && st.n_objects == 1);
    cs_surface_state_free(&st);
}

TEST(surface_state_delta_applies)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256];
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    int32_t idx[2] = {3, 1};
    float xyz[6] = {0, 0, 2, 1.5f, 0, 0};
    cs_ss_delta d = {hdr(42, 0, 11, 100), 7, 1, 0, 1, 4, 2, idx, 6, xyz};
    ENSURE_MSG(cs_surface_state_apply_delta(&st, &d, err, sizeof err) == CS_SS_APPLIED, "%s", err);
    const cs_ss_object *t = cs_surface_state_find(&st, 7);
    ENSURE(t->xyz[11] == 2.0f && t->xyz[3] == 1.5f && t->xyz[0] == 0.0f && t->xyz[7] == 1.0f);
    ENSURE(st.frame == 11 && !st.stale);
    /* An older frame is ignored. */
    float back[6] = {9, 9, 9, 9, 9, 9};
    cs_ss_delta old = {hdr(42, 0, 5, 101), 7, 1, 0, 1, 4, 2, idx, 6, back};
    ENSURE(cs_surface_state_apply_delta(&st, &old, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(t->xyz[11] == 2.0f);
    cs_surface_state_free(&st);
}

TEST(surface_state_delta_version_session_epoch)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256];
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    int32_t idx[1] = {0};
    float xyz[3] = {5, 5, 5};
    cs_ss_delta d = {hdr(42, 0, 11, 1), 7, 2 /* wrong version */, 0, 1, 4, 1, idx, 3, xyz};
    ENSURE(cs_surface_state_apply_delta(&st, &d, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(strstr(err, "topology version"));
    ENSURE(st.objects[0].xyz[0] == 0.0f && st.stale);
    cs_surface_state_free(&st);

    /* A new epoch invalidates the state; the delta of that epoch is not applied. */
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    cs_ss_delta e = {hdr(42, 1, 1, 1), 7, 1, 0, 1, 4, 1, idx, 3, xyz};
    ENSURE(cs_surface_state_apply_delta(&st, &e, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(!st.valid && st.stale && st.n_objects == 0 && st.epoch == 1);
    /* A chunk of the old epoch is now ignored; a snapshot of the new epoch restores it. */
    cs_ss_chunk old = tet_chunk(0, 42, 2);
    ENSURE(cs_surface_state_apply_chunk(&st, &old, err, sizeof err) == CS_SS_IGNORED);
    for (int k = 0; k < 3; k++) {
        cs_ss_chunk c = tet_chunk(k, 42, 3);
        c.header.epoch = 1;
        cs_surface_state_apply_chunk(&st, &c, err, sizeof err);
    }
    ENSURE(st.valid && !st.stale && st.epoch == 1);
    cs_surface_state_free(&st);

    /* Another session (daemon restart) invalidates too. */
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    cs_ss_delta s = {hdr(43, 0, 20, 1), 7, 1, 0, 1, 4, 1, idx, 3, xyz};
    ENSURE(cs_surface_state_apply_delta(&st, &s, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(!st.valid && st.stale && st.session_id == 43);
    cs_surface_state_free(&st);
}

TEST(surface_state_seq_gap_marks_stale)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256];
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    int32_t idx[1] = {2};
    float xyz[3] = {0, 3, 0};
    cs_ss_delta d = {hdr(42, 0, 11, 7), 7, 1, 0, 1, 4, 1, idx, 3, xyz};
    ENSURE(cs_surface_state_apply_delta(&st, &d, err, sizeof err) == CS_SS_APPLIED);
    d.header = hdr(42, 0, 12, 8);
    ENSURE(cs_surface_state_apply_delta(&st, &d, err, sizeof err) == CS_SS_APPLIED);
    ENSURE(!st.stale && st.deltas_lost == 0);
    d.header = hdr(42, 0, 15, 11); /* 9 and 10 lost */
    ENSURE(cs_surface_state_apply_delta(&st, &d, err, sizeof err) == CS_SS_APPLIED);
    ENSURE(st.stale && st.deltas_lost == 2);
    /* The next complete snapshot clears it. */
    for (int k = 0; k < 3; k++) {
        cs_ss_chunk c = tet_chunk(k, 42, 2);
        c.header.frame = 16;
        cs_surface_state_apply_chunk(&st, &c, err, sizeof err);
    }
    ENSURE(st.valid && !st.stale && st.frame == 16);
    cs_surface_state_free(&st);
}

TEST(surface_state_bad_chunks_rejected)
{
    char err[256];
    float nan_xyz[6] = {0, 0, 0, NAN, 0, 0};
    int32_t bad_tris[6] = {0, 1, 4, 0, 1, 2};
    for (int which = 0; which < 9; which++) {
        cs_surface_state st;
        cs_surface_state_init(&st);
        cs_ss_chunk c = tet_chunk(0, 1, 1);
        switch (which) {
        case 0: c.chunk = 3; break;                    /* chunk >= n_chunks */
        case 1: c.chunk = -1; break;
        case 2: c.n_coords = 5; break;                 /* not a multiple of 3 */
        case 3: c.xyz = nan_xyz; break;                /* NaN */
        case 4: c.indices = bad_tris; break;           /* index 4 of 4 vertices */
        case 5: c.vertex_offset = 3; break;            /* 2 vertices from 3 overflow 4 */
        case 6: c.n_vertices_total = -1; break;
        case 7: c.n_objects = 4; break;                /* more objects than chunks */
        case 8: c.n_chunks = 0; break;
        }
        err[0] = 0;
        ENSURE_MSG(cs_surface_state_apply_chunk(&st, &c, err, sizeof err) == CS_SS_REJECTED,
                   "case %d accepted", which);
        ENSURE_MSG(strlen(err) > 10, "case %d: no message", which);
        ENSURE(!st.valid && !st.pending);
        cs_surface_state_free(&st);
    }
    /* Chunks that disagree with each other: overlap, and totals that change. */
    cs_surface_state st;
    cs_surface_state_init(&st);
    cs_ss_chunk a = tet_chunk(0, 1, 1), b = tet_chunk(1, 1, 1);
    b.vertex_offset = 1; /* vertex 1 twice */
    ENSURE(cs_surface_state_apply_chunk(&st, &a, err, sizeof err) == CS_SS_PENDING);
    ENSURE(cs_surface_state_apply_chunk(&st, &b, err, sizeof err) == CS_SS_REJECTED);
    ENSURE(strstr(err, "twice"));
    b = tet_chunk(1, 1, 2);
    b.n_triangles_total = 5;
    a = tet_chunk(0, 1, 2);
    ENSURE(cs_surface_state_apply_chunk(&st, &a, err, sizeof err) == CS_SS_PENDING);
    ENSURE(cs_surface_state_apply_chunk(&st, &b, err, sizeof err) == CS_SS_REJECTED);
    ENSURE(!st.valid);
    /* All chunks arrive but an object's vertices are missing. */
    a = tet_chunk(0, 1, 3);
    b = tet_chunk(1, 1, 3);
    cs_ss_chunk e = tet_chunk(2, 1, 3);
    b.n_coords = 3;
    ENSURE(cs_surface_state_apply_chunk(&st, &a, err, sizeof err) == CS_SS_PENDING);
    ENSURE(cs_surface_state_apply_chunk(&st, &b, err, sizeof err) == CS_SS_PENDING);
    ENSURE(cs_surface_state_apply_chunk(&st, &e, err, sizeof err) == CS_SS_REJECTED);
    ENSURE(strstr(err, "3 of 4 vertices"));
    ENSURE(!st.valid);
    cs_surface_state_free(&st);
}

TEST(surface_state_bad_deltas_rejected)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256];
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    int32_t idx_ok[2] = {0, 1}, idx_bad[2] = {0, 4}, idx_neg[2] = {-1, 0};
    float ok[6] = {1, 1, 1, 2, 2, 2}, nan6[6] = {1, 1, 1, 2, INFINITY, 2};
    cs_ss_delta cases[6] = {
        {hdr(42, 0, 11, 1), 8, 1, 0, 1, 4, 2, idx_ok, 6, ok},   /* unknown object */
        {hdr(42, 0, 11, 2), 7, 1, 0, 1, 5, 2, idx_ok, 6, ok},   /* wrong vertex total */
        {hdr(42, 0, 11, 3), 7, 1, 0, 1, 4, 2, idx_bad, 6, ok},  /* index out of range */
        {hdr(42, 0, 11, 4), 7, 1, 0, 1, 4, 2, idx_neg, 6, ok},  /* negative index */
        {hdr(42, 0, 11, 5), 7, 1, 0, 1, 4, 2, idx_ok, 5, ok},   /* n_coords != 3n */
        {hdr(42, 0, 11, 6), 7, 1, 0, 1, 4, 2, idx_ok, 6, nan6}, /* not finite */
    };
    for (int i = 0; i < 6; i++) {
        err[0] = 0;
        ENSURE_MSG(cs_surface_state_apply_delta(&st, &cases[i], err, sizeof err) ==
                       CS_SS_REJECTED, "case %d accepted", i);
        ENSURE(strlen(err) > 10);
    }
    /* Nothing changed, not even vertex 0 of the half-valid NaN case. */
    ENSURE(!memcmp(st.objects[0].xyz, tet_xyz, sizeof tet_xyz));
    cs_surface_state_free(&st);
}

TEST(surface_state_hash_is_fnv1a_of_floats)
{
    /* FNV-1a 64 of the empty input is the offset basis. */
    ENSURE(cs_surface_hash_floats(NULL, 0) == 14695981039346656037ULL);
    /* One vertex (1, 0, -2): the float bytes little-endian are 00 00 80 3f, 00 00 00 00,
     * 00 00 00 c0; hash them byte by byte here, independently of the library's loop. */
    const uint8_t bytes[12] = {0x00, 0x00, 0x80, 0x3f, 0, 0, 0, 0, 0x00, 0x00, 0x00, 0xc0};
    uint64_t h = 14695981039346656037ULL;
    for (int i = 0; i < 12; i++) {
        h ^= bytes[i];
        h *= 1099511628211ULL;
    }
    float v[3] = {1.0f, 0.0f, -2.0f};
    ENSURE(cs_surface_hash_floats(v, 1) == h);
    /* Known answer of FNV-1a 64 for the single byte 'a' (0x61): 0xaf63dc4c8601ec8c. The
     * float whose little-endian bytes begin with 0x61 cannot isolate one byte, so check the
     * algorithm constants through that published vector directly. */
    uint64_t a = (14695981039346656037ULL ^ 0x61) * 1099511628211ULL;
    ENSURE(a == 0xaf63dc4c8601ec8cULL);
    /* A changed coordinate changes the hash. */
    v[2] = -2.0000002f;
    ENSURE(cs_surface_hash_floats(v, 1) != h);
}

TEST(surface_state_to_meshes)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256];
    cs_mesh *pieces;
    char **names;
    int n;
    ENSURE(cs_surface_state_to_meshes(&st, &pieces, &names, &n, err, sizeof err) == -1);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    ENSURE(cs_surface_state_to_meshes(&st, &pieces, &names, &n, err, sizeof err) == 0);
    ENSURE(n == 1 && pieces[0].nv == 4 && pieces[0].nt == 4 && !strcmp(names[0], "tet"));
    int same = pieces[0].v[3] == 1.0 && pieces[0].v[11] == 1.0 && pieces[0].t[2] == 1;
    cs_surface_state_meshes_free(pieces, names, n);
    ENSURE(same);
    cs_surface_state_free(&st);
}

/* ---------------------------------------------------------------- topology changes */

/* The change of test_topo.c's topo_five_steps_in_order on the tetrahedron (id 7, version
 * 1 -> 2), as float32 chunks. Split in two: chunk 0 carries the vertex steps, chunk 1 the
 * triangle steps; n_chunks 1 carries all. */
static const int32_t tv_rm[1] = {1};
static const float tv_new[6] = {0.5f, 0.5f, 0.5f, 0.25f, 0.25f, 0.25f};
static const int32_t tt_rm[2] = {3, 0};
static const int32_t tt_set_i[1] = {1};
static const int32_t tt_set_t[3] = {0, 4, 3};
static const int32_t tt_new[3] = {3, 4, 2};

static cs_ss_topo tet_topo(int k, int n_chunks, int64_t seq, int32_t change_id)
{
    cs_ss_topo t;
    memset(&t, 0, sizeof t);
    t.header = hdr(42, 0, 12, seq);
    t.change_id = change_id;
    t.chunk = k;
    t.n_chunks = n_chunks;
    t.object_id = 7;
    t.name = "";
    t.model = "";
    t.from_version = 1;
    t.to_version = 2;
    t.n_vertices_total = 5;
    t.n_triangles_total = 3;
    t.total_vremove = 1;
    t.total_vnew = 2;
    t.total_tremove = 2;
    t.total_tset = 1;
    t.total_tnew = 1;
    t.vnew_offset = 2;
    t.tremove_offset = 2;
    t.tset_offset = 1;
    t.tnew_offset = 1;
    if (k == 0) { /* vertex steps */
        t.vremove_offset = 0;
        t.n_vremove = 1;
        t.vremove = tv_rm;
        t.vnew_offset = 0;
        t.n_vnew_coords = 6;
        t.vnew_xyz = tv_new;
    }
    if (k == n_chunks - 1) { /* triangle steps */
        t.tremove_offset = 0;
        t.n_tremove = 2;
        t.tremove = tt_rm;
        t.tset_offset = 0;
        t.n_tset = 1;
        t.tset_index = tt_set_i;
        t.n_tset_indices = 3;
        t.tset_tri = tt_set_t;
        t.tnew_offset = 0;
        t.n_tnew_indices = 3;
        t.tnew = tt_new;
    }
    return t;
}

/* A new piece (id 9, broken off 7): a tetrahedron of its own. */
static cs_ss_topo piece_topo(int64_t seq, int32_t change_id)
{
    static const float pv[12] = {2, 0, 0, 3, 0, 0, 2, 1, 0, 2, 0, 1};
    cs_ss_topo t;
    memset(&t, 0, sizeof t);
    t.header = hdr(42, 0, 12, seq);
    t.change_id = change_id;
    t.n_chunks = 1;
    t.object_id = 9;
    t.parent_id = 7;
    t.name = "tet.1";
    t.model = "corotational";
    t.to_version = 1;
    t.n_vertices_total = 4;
    t.n_triangles_total = 4;
    t.total_vnew = 4;
    t.total_tnew = 4;
    t.n_vnew_coords = 12;
    t.vnew_xyz = pv;
    t.n_tnew_indices = 12;
    t.tnew = tet_tris;
    return t;
}

static int tris_in_range(const cs_surface_state *st)
{
    for (int i = 0; i < st->n_objects; i++)
        for (int k = 0; k < 3 * st->objects[i].nt; k++)
            if (st->objects[i].tris[k] < 0 || st->objects[i].tris[k] >= st->objects[i].nv)
                return 0;
    return 1;
}

TEST(surface_state_topology_chunks_in_order_then_deltas)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256] = "";
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    cs_ss_topo a = tet_topo(0, 2, 1, 1), b = tet_topo(1, 2, 2, 1);
    ENSURE_MSG(cs_surface_state_apply_topology(&st, &a, err, sizeof err) == CS_SS_PENDING, "%s", err);
    ENSURE(st.objects[0].topology_version == 1 && st.objects[0].nv == 4); /* not yet */
    ENSURE_MSG(cs_surface_state_apply_topology(&st, &b, err, sizeof err) == CS_SS_APPLIED, "%s", err);
    const cs_ss_object *o = cs_surface_state_find(&st, 7);
    ENSURE(o->topology_version == 2 && o->nv == 5 && o->nt == 3);
    /* vertex 3 moved into slot 1, new vertices at 3 and 4 */
    ENSURE(o->xyz[3] == 0.0f && o->xyz[5] == 1.0f && o->xyz[9] == 0.5f && o->xyz[12] == 0.25f);
    static const int32_t want[9] = {0, 3, 2, 0, 4, 3, 3, 4, 2};
    ENSURE(memcmp(o->tris, want, sizeof want) == 0);
    ENSURE(!st.stale && st.topology_applied == 1 && st.frame == 12);
    /* A delta for the new version applies; one for the old version is ignored. */
    int32_t idx[1] = {4};
    float xyz[3] = {0.3f, 0.3f, 0.3f};
    cs_ss_delta d = {hdr(42, 0, 13, 1), 7, 2, 0, 1, 5, 1, idx, 3, xyz};
    ENSURE_MSG(cs_surface_state_apply_delta(&st, &d, err, sizeof err) == CS_SS_APPLIED, "%s", err);
    ENSURE(o->xyz[12] == 0.3f);
    cs_ss_delta old = {hdr(42, 0, 14, 2), 7, 1, 0, 1, 4, 1, idx, 3, xyz};
    ENSURE(cs_surface_state_apply_delta(&st, &old, err, sizeof err) == CS_SS_IGNORED);
    /* The same change again (e.g. replayed) is ignored without going stale. */
    cs_ss_topo again = tet_topo(0, 1, 3, 2);
    again.header.frame = 14;
    ENSURE(cs_surface_state_apply_topology(&st, &again, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(o->nv == 5);
    cs_surface_state_free(&st);

    /* Chunks in reverse order assemble the same. */
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    ENSURE(cs_surface_state_apply_topology(&st, &b, err, sizeof err) == CS_SS_PENDING);
    b.header.seq = 1;
    a.header.seq = 2;
    ENSURE(cs_surface_state_apply_topology(&st, &a, err, sizeof err) == CS_SS_APPLIED);
    ENSURE(memcmp(cs_surface_state_find(&st, 7)->tris, want, sizeof want) == 0);
    cs_surface_state_free(&st);
}

TEST(surface_state_topology_missing_chunk_goes_stale)
{
    cs_surface_state st;
    char err[256] = "";
    /* (a) the seq gap tells at once */
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    cs_ss_topo p0 = piece_topo(5, 1);
    ENSURE(cs_surface_state_apply_topology(&st, &p0, err, sizeof err) == CS_SS_APPLIED);
    ENSURE(!st.stale);
    cs_ss_topo b = tet_topo(1, 2, 7, 2); /* seq 6 (chunk 0) lost */
    ENSURE(cs_surface_state_apply_topology(&st, &b, err, sizeof err) == CS_SS_PENDING);
    ENSURE(st.stale && st.topology_lost == 1);
    ENSURE(st.objects[0].topology_version == 1);
    /* the following delta is for version 2: ignored, the surface is left as it was */
    int32_t idx[1] = {4};
    float xyz[3] = {1, 1, 1};
    cs_ss_delta d = {hdr(42, 0, 13, 1), 7, 2, 0, 1, 5, 1, idx, 3, xyz};
    ENSURE(cs_surface_state_apply_delta(&st, &d, err, sizeof err) == CS_SS_IGNORED);
    /* (b) the next change's chunk shows the first never completed, even without seq */
    cs_ss_topo p1 = piece_topo(8, 3);
    p1.object_id = 10;
    ENSURE(cs_surface_state_apply_topology(&st, &p1, err, sizeof err) == CS_SS_APPLIED);
    ENSURE(st.topology_incomplete == 1 && st.n_objects == 3);
    /* a snapshot (what the client asks for) brings it back: valid, not stale, parents kept */
    for (int k = 0; k < 3; k++) {
        cs_ss_chunk c = tet_chunk(k, 42, 2);
        c.header.frame = 20;
        c.topology_version = 2; /* pretend the daemon's object is at version 2 */
        cs_surface_state_apply_chunk(&st, &c, err, sizeof err);
    }
    ENSURE(st.valid && !st.stale && st.n_objects == 1);
    cs_surface_state_free(&st);
}

TEST(surface_state_topology_wrong_version)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256] = "";
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    /* from_version 3 does not follow version 1: a change was missed */
    cs_ss_topo t = tet_topo(0, 1, 1, 1);
    t.from_version = 3;
    t.to_version = 4;
    ENSURE(cs_surface_state_apply_topology(&st, &t, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(st.stale && strstr(err, "missed"));
    ENSURE(st.objects[0].nv == 4 && st.objects[0].topology_version == 1);
    /* an unknown object: stale too */
    cs_surface_state_free(&st);
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    t = tet_topo(0, 1, 1, 1);
    t.object_id = 99;
    ENSURE(cs_surface_state_apply_topology(&st, &t, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(st.stale);
    /* before any snapshot: ignored; of an older epoch: ignored */
    cs_surface_state_free(&st);
    cs_surface_state_init(&st);
    t = tet_topo(0, 1, 1, 1);
    ENSURE(cs_surface_state_apply_topology(&st, &t, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(!st.valid);
    cs_surface_state_free(&st);
}

TEST(surface_state_topology_new_piece)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256] = "";
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    cs_ss_topo t = tet_topo(0, 1, 1, 1), p = piece_topo(2, 2);
    ENSURE(cs_surface_state_apply_topology(&st, &t, err, sizeof err) == CS_SS_APPLIED);
    ENSURE_MSG(cs_surface_state_apply_topology(&st, &p, err, sizeof err) == CS_SS_APPLIED, "%s", err);
    ENSURE(st.n_objects == 2);
    const cs_ss_object *o = cs_surface_state_find(&st, 9);
    ENSURE(o && o->parent_id == 7 && !strcmp(o->name, "tet.1") &&
           !strcmp(o->model, "corotational") && o->topology_version == 1 && o->nv == 4 &&
           o->nt == 4 && o->xyz[0] == 2.0f && memcmp(o->tris, tet_tris, sizeof tet_tris) == 0);
    /* the piece exports as a mesh of its own */
    cs_mesh *pieces;
    char **names;
    int n;
    ENSURE(cs_surface_state_to_meshes(&st, &pieces, &names, &n, err, sizeof err) == 0);
    ENSURE(n == 2 && !strcmp(names[1], "tet.1"));
    cs_surface_state_meshes_free(pieces, names, n);
    /* the same piece again is ignored; a snapshot that lists it keeps its parent */
    p.header.seq = 3;
    p.change_id = 3;
    ENSURE(cs_surface_state_apply_topology(&st, &p, err, sizeof err) == CS_SS_IGNORED);
    cs_ss_chunk c0 = tet_chunk(0, 42, 5), c1 = tet_chunk(1, 42, 5);
    cs_ss_chunk c2 = {0};
    c2 = c0;
    c2.chunk = 2;
    c2.object_id = 9;
    c2.object_name = "tet.1";
    c2.vertex_offset = 0;
    c2.n_coords = 12;
    c2.xyz = tet_xyz;
    c2.triangle_offset = 0;
    c2.n_indices = 12;
    c2.indices = tet_tris;
    c0.n_objects = c1.n_objects = c2.n_objects = 2;
    c0.header.frame = c1.header.frame = c2.header.frame = 30;
    cs_surface_state_apply_chunk(&st, &c0, err, sizeof err);
    cs_surface_state_apply_chunk(&st, &c1, err, sizeof err);
    ENSURE_MSG(cs_surface_state_apply_chunk(&st, &c2, err, sizeof err) == CS_SS_APPLIED, "%s", err);
    o = cs_surface_state_find(&st, 9);
    ENSURE(o && o->parent_id == 7 && st.n_objects == 2);
    cs_surface_state_free(&st);
}

TEST(surface_state_topology_rejects_bad_changes)
{
    char err[256];
    static const float nan_v[6] = {0, 0, 0, NAN, 0, 0};
    static const int32_t asc[2] = {0, 3}, out_t[3] = {0, 1, 9};
    for (int which = 0; which < 14; which++) {
        cs_surface_state st;
        cs_surface_state_init(&st);
        ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
        cs_ss_topo t = tet_topo(0, 1, 1, 1);
        switch (which) {
        case 0: t.n_chunks = 0; break;
        case 1: t.chunk = 1; break;
        case 2: t.to_version = 1; break;                     /* not after from_version */
        case 3: t.total_vnew = -1; break;
        case 4: t.n_vnew_coords = 5; break;
        case 5: t.vnew_xyz = nan_v; break;                   /* NaN position */
        case 6: t.n_tset_indices = 6; break;                 /* not 3 x n_tset */
        case 7: t.vremove_offset = 1; break;                 /* slice beyond the total */
        case 8: t.tremove = asc; break;                      /* not descending */
        case 9: t.n_vertices_total = 6; break;               /* totals mismatch */
        case 10: t.tnew = out_t; break;                      /* index out of range */
        case 11: t.vremove = NULL; break;                    /* missing data */
        case 12: t.object_id = 0; break;
        case 13: t.total_vremove = 2; break;                 /* a chunk never carries item 1 */
        }
        memset(err, 0, sizeof err);
        int r = cs_surface_state_apply_topology(&st, &t, err, sizeof err);
        ENSURE_MSG(r == CS_SS_REJECTED, "case %d: %d (%s)", which, r, err);
        ENSURE_MSG(err[0] && !strchr(err, '\n'), "case %d: message '%s'", which, err);
        ENSURE(st.stale && st.objects[0].nv == 4 && st.objects[0].topology_version == 1);
        ENSURE(memcmp(st.objects[0].tris, tet_tris, sizeof tet_tris) == 0);
        cs_surface_state_free(&st);
    }
    /* chunks that disagree or overlap drop the partial change */
    cs_surface_state st;
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    cs_ss_topo a = tet_topo(0, 2, 1, 1), b = tet_topo(1, 2, 2, 1);
    b.to_version = 3;
    ENSURE(cs_surface_state_apply_topology(&st, &a, err, sizeof err) == CS_SS_PENDING);
    ENSURE(cs_surface_state_apply_topology(&st, &b, err, sizeof err) == CS_SS_REJECTED);
    b = tet_topo(1, 2, 3, 1);
    ENSURE(cs_surface_state_apply_topology(&st, &b, err, sizeof err) == CS_SS_PENDING);
    a = tet_topo(0, 2, 4, 1);
    a.tremove_offset = 0; /* chunk 0 carries the triangles chunk 1 already carried */
    a.n_tremove = 2;
    a.tremove = tt_rm;
    ENSURE(cs_surface_state_apply_topology(&st, &a, err, sizeof err) == CS_SS_REJECTED);
    ENSURE(strstr(err, "overlaps") && st.objects[0].nv == 4);
    cs_surface_state_free(&st);
}

static uint32_t fuzz_rnd(uint64_t *r)
{
    *r ^= *r << 13;
    *r ^= *r >> 7;
    *r ^= *r << 17;
    return (uint32_t)(*r >> 11);
}

/* Copy n items of `from` (NULL: none) into a buffer of 256 ints that any fuzzed count fits. */
static const int32_t *fuzz_ints(int32_t *buf, const int32_t *from, int n)
{
    memset(buf, 0, 256 * sizeof *buf);
    if (from && n > 0)
        memcpy(buf, from, (size_t)n * sizeof *buf);
    return buf;
}

/* Random fields, random array contents, truncated (chunk-losing) sequences: never a crash or
 * a leak (ASan in make test), the state's invariant holds after every message. */
TEST(surface_state_topology_fuzz)
{
    uint64_t r = 88172645463325252ULL;
    static int32_t ib[5][256];
    static float fb[256];
    char err[256];
    for (int iter = 0; iter < 3000; iter++) {
        cs_surface_state st;
        cs_surface_state_init(&st);
        ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
        for (int m = 0; m < 6; m++) {
            cs_ss_topo t = (fuzz_rnd(&r) & 1)
                               ? tet_topo((int)(fuzz_rnd(&r) % 2), 1 + (int)(fuzz_rnd(&r) % 2), m,
                                          1 + (int32_t)(fuzz_rnd(&r) % 3))
                               : piece_topo(m, 1 + (int32_t)(fuzz_rnd(&r) % 3));
            t.vremove = fuzz_ints(ib[0], t.vremove, t.n_vremove);
            t.tremove = fuzz_ints(ib[1], t.tremove, t.n_tremove);
            t.tset_index = fuzz_ints(ib[2], t.tset_index, t.n_tset);
            t.tset_tri = fuzz_ints(ib[3], t.tset_tri, t.n_tset_indices);
            t.tnew = fuzz_ints(ib[4], t.tnew, t.n_tnew_indices);
            memset(fb, 0, sizeof fb);
            if (t.n_vnew_coords > 0)
                memcpy(fb, t.vnew_xyz, (size_t)t.n_vnew_coords * sizeof *fb);
            t.vnew_xyz = fb;
            int32_t *fields[] = {&t.chunk, &t.n_chunks, &t.from_version, &t.to_version,
                                 &t.n_vertices_total, &t.n_triangles_total, &t.total_vremove,
                                 &t.total_vnew, &t.total_tremove, &t.total_tset, &t.total_tnew,
                                 &t.vremove_offset, &t.n_vremove, &t.vnew_offset,
                                 &t.n_vnew_coords, &t.tremove_offset, &t.n_tremove,
                                 &t.tset_offset, &t.n_tset, &t.n_tset_indices, &t.tnew_offset,
                                 &t.n_tnew_indices, &t.object_id, &t.parent_id};
            int nf = (int)(sizeof fields / sizeof fields[0]);
            for (int k = (int)(fuzz_rnd(&r) % 4); k > 0; k--) /* counts stay <= 40 */
                *fields[fuzz_rnd(&r) % (uint32_t)nf] = (int32_t)(fuzz_rnd(&r) % 44) - 3;
            for (int k = (int)(fuzz_rnd(&r) % 3); k > 0; k--) {
                ib[fuzz_rnd(&r) % 5][fuzz_rnd(&r) % 8] = (int32_t)(fuzz_rnd(&r) % 12) - 2;
                fb[fuzz_rnd(&r) % 12] = (fuzz_rnd(&r) % 4) ? (float)(fuzz_rnd(&r) % 100) : NAN;
            }
            if (fuzz_rnd(&r) % 8 == 0)
                continue; /* a lost message */
            int res = cs_surface_state_apply_topology(&st, &t, err, sizeof err);
            ENSURE(res >= CS_SS_NOMEM && res <= CS_SS_IGNORED);
            ENSURE_MSG(tris_in_range(&st), "iteration %d message %d broke the invariant", iter, m);
        }
        cs_surface_state_free(&st);
    }
}

/* CUBESIM_POSE (rigid objects): a reference pose, then poses move the copy rigidly. */
TEST(surface_state_pose_moves_rigidly)
{
    cs_surface_state st;
    cs_surface_state_init(&st);
    char err[256];
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    /* a pose before any reference is ignored and marks the state stale */
    cs_ss_pose p = {hdr(42, 0, 11, 1), 7, 1, 4, 0, {1, 2, 3}, {1, 0, 0, 0}};
    ENSURE(cs_surface_state_apply_pose(&st, &p, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(st.stale);
    st.stale = 0;
    /* the reference: the copy as it is, at centre (0.25, 0.25, 0.25), unrotated */
    cs_ss_pose r = {hdr(42, 0, 11, 2), 7, 1, 4, 1, {0.25, 0.25, 0.25}, {1, 0, 0, 0}};
    ENSURE_MSG(cs_surface_state_apply_pose(&st, &r, err, sizeof err) == CS_SS_APPLIED, "%s", err);
    const cs_ss_object *t = cs_surface_state_find(&st, 7);
    ENSURE(!memcmp(t->xyz, tet_xyz, sizeof tet_xyz));
    /* 90° about z and moved to (1, 1, 1): x' = c + Rz (x − c_r) */
    const double h = sqrt(0.5);
    cs_ss_pose m = {hdr(42, 0, 12, 3), 7, 1, 4, 0, {1, 1, 1}, {h, 0, 0, h}};
    ENSURE_MSG(cs_surface_state_apply_pose(&st, &m, err, sizeof err) == CS_SS_APPLIED, "%s", err);
    for (int v = 0; v < 4; v++) {
        const double d[3] = {tet_xyz[3 * v] - 0.25, tet_xyz[3 * v + 1] - 0.25,
                             tet_xyz[3 * v + 2] - 0.25};
        ENSURE_NEAR(t->xyz[3 * v], 1 - d[1], 1e-6);
        ENSURE_NEAR(t->xyz[3 * v + 1], 1 + d[0], 1e-6);
        ENSURE_NEAR(t->xyz[3 * v + 2], 1 + d[2], 1e-6);
    }
    /* poses are taken from the reference, not chained: back to the reference pose, exactly */
    cs_ss_pose back = {hdr(42, 0, 13, 4), 7, 1, 4, 0, {0.25, 0.25, 0.25}, {1, 0, 0, 0}};
    ENSURE(cs_surface_state_apply_pose(&st, &back, err, sizeof err) == CS_SS_APPLIED);
    ENSURE(!memcmp(t->xyz, tet_xyz, sizeof tet_xyz));
    /* malformed poses change nothing */
    cs_ss_pose bad[4] = {
        {hdr(42, 0, 14, 5), 7, 1, 4, 0, {NAN, 0, 0}, {1, 0, 0, 0}},
        {hdr(42, 0, 14, 6), 7, 1, 4, 0, {0, 0, 0}, {2, 0, 0, 0}},
        {hdr(42, 0, 14, 7), 7, 1, 5, 0, {0, 0, 0}, {1, 0, 0, 0}},
        {hdr(42, 0, 14, 8), 7, 1, 4, 3, {0, 0, 0}, {1, 0, 0, 0}},
    };
    for (int i = 0; i < 4; i++) {
        ENSURE_MSG(cs_surface_state_apply_pose(&st, &bad[i], err, sizeof err) == CS_SS_REJECTED,
                   "bad pose %d accepted", i);
        ENSURE(!memcmp(t->xyz, tet_xyz, sizeof tet_xyz));
    }
    /* another topology version: ignored, stale */
    cs_ss_pose other = {hdr(42, 0, 15, 9), 7, 2, 4, 0, {1, 1, 1}, {1, 0, 0, 0}};
    ENSURE(cs_surface_state_apply_pose(&st, &other, err, sizeof err) == CS_SS_IGNORED);
    ENSURE(st.stale);
    /* a gap in the pose sequence marks loss */
    st.stale = 0;
    cs_ss_pose gap = {hdr(42, 0, 16, 20), 7, 1, 4, 0, {0.25, 0.25, 0.25}, {1, 0, 0, 0}};
    ENSURE(cs_surface_state_apply_pose(&st, &gap, err, sizeof err) == CS_SS_APPLIED);
    ENSURE(st.stale && st.poses_lost == 10);
    /* a new snapshot drops the reference */
    ENSURE(load_tet(&st, 42, 2) == CS_SS_APPLIED);
    cs_ss_pose after = {hdr(42, 0, 17, 21), 7, 1, 4, 0, {1, 1, 1}, {1, 0, 0, 0}};
    ENSURE(cs_surface_state_apply_pose(&st, &after, err, sizeof err) == CS_SS_IGNORED);
    cs_surface_state_free(&st);
}

/*
 * The volume ledger (track_volume): a new piece whose vertices name the tetrahedron's as
 * their sources counts its volume at the tetrahedron's positions, not at the positions it
 * was sent with (a client's copy of the parent may lag the daemon's); without sources, at the
 * positions sent. A change to an existing object counts after minus before. A source count
 * that is neither 0 nor the chunk's vertex count is refused.
 */
TEST(surface_state_volume_ledger_uses_sources)
{
    /* the piece: the unit tetrahedron stretched to twice its length along x (volume 1/3) */
    static const float stretched[12] = {0, 0, 0, 2, 0, 0, 0, 1, 0, 0, 0, 1};
    static const int32_t src[4] = {0, 1, 2, 3};
    char err[256];
    for (int with_src = 0; with_src < 2; with_src++) {
        cs_surface_state st;
        cs_surface_state_init(&st);
        st.track_volume = 1;
        ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
        cs_ss_topo t = piece_topo(1, 1);
        t.vnew_xyz = stretched;
        if (with_src) {
            t.n_vnew_src = 4;
            t.vnew_src = src;
        }
        ENSURE_MSG(cs_surface_state_apply_topology(&st, &t, err, sizeof err) == CS_SS_APPLIED,
                   "%s", err);
        const cs_ss_object *p = cs_surface_state_find(&st, 9);
        ENSURE(p && p->topo_changed && p->xyz[3] == 2.0f); /* shown where it was sent */
        ENSURE_NEAR(p->topo_dv, with_src ? 1.0 / 6 : 1.0 / 3, 1e-15);
        const cs_ss_object *o = cs_surface_state_find(&st, 7);
        ENSURE(o && !o->topo_changed && o->topo_dv == 0);
        /* the tetrahedron's own change (test_topo's five steps): after minus before */
        cs_ss_topo c = tet_topo(0, 1, 2, 2);
        ENSURE_MSG(cs_surface_state_apply_topology(&st, &c, err, sizeof err) == CS_SS_APPLIED,
                   "%s", err);
        o = cs_surface_state_find(&st, 7);
        double *v = cs_ss_object_vertices_double(o);
        ENSURE(v);
        double after = cs_mesh_volume(v, o->tris, o->nt);
        free(v);
        ENSURE(o->topo_changed);
        ENSURE_NEAR(o->topo_dv, after - 1.0 / 6, 1e-15);
        cs_surface_state_clear_volume_ledger(&st);
        ENSURE(!st.objects[0].topo_changed && st.objects[0].topo_dv == 0 &&
               !st.objects[1].topo_changed && st.objects[1].topo_dv == 0);
        cs_surface_state_free(&st);
    }
    /* a source count that does not match the chunk's vertices */
    cs_surface_state st;
    cs_surface_state_init(&st);
    ENSURE(load_tet(&st, 42, 1) == CS_SS_APPLIED);
    cs_ss_topo t = piece_topo(1, 1);
    t.n_vnew_src = 3;
    t.vnew_src = src;
    ENSURE(cs_surface_state_apply_topology(&st, &t, err, sizeof err) == CS_SS_REJECTED);
    ENSURE(cs_surface_state_find(&st, 9) == NULL);
    /* a source out of range for an existing object (cs_topo_check) */
    cs_ss_topo c = tet_topo(0, 1, 2, 2);
    static const int32_t bad[2] = {4, -1}; /* the tetrahedron has vertices 0..3 */
    c.n_vnew_src = 2;
    c.vnew_src = bad;
    ENSURE(cs_surface_state_apply_topology(&st, &c, err, sizeof err) == CS_SS_REJECTED);
    ENSURE(strstr(err, "copy of vertex 4"));
    cs_surface_state_free(&st);
}
