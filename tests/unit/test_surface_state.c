/*
 * test_surface_state.c — the client's surface state (common/surface_state.c): snapshot chunk
 * assembly in any order, deltas, version and session rules, loss detection from header.seq,
 * rejection of malformed input, and the FNV-1a state hash against a hand computation.
 */
#include "check.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "surface_state.h"

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
