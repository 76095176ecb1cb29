/*
 * tests/it/tools/mklog.c — cs_it_mklog: writes a hand-made cubesim log (an LCM event log) of a
 * fracture, so that cubesim-replay's rebuild and --verify can be tested on topology changes
 * before the engine makes real ones.
 *
 *   cs_it_mklog OUT.lcm MODE [--chunk-bytes B]
 *
 * The story, one daemon session, epoch 0, cube size h = 0.1 m:
 *   frame 0  snapshot: object 1 "bar", the 2x1x1 block of cells (0,0,0),(1,0,0) (12 vertices,
 *            20 triangles)
 *   frame 1  delta: every vertex of "bar" 1 mm up
 *   frame 2  topology: "bar" v1 -> v2 becomes the left cube (4 vertices swap-removed, the
 *            triangles of the right half removed, the others rewired, the closing face at
 *            x = h appended); new piece 2 "bar.1" (parent 1) is the right cube; then a delta
 *            moving both 1 mm up again
 *   frame 3  delta: "bar.1" 1 cm up (a rigid motion: volumes unchanged)
 *   frame 4  snapshot of both (what a client that went stale asks for)
 * MODE: good | badvolume (the piece is 20 % longer along x) | open (the piece lacks its
 * closing face) | gap (the second chunk of the split is left out of the log, as if lost:
 * chunks of 40 bytes unless --chunk-bytes says otherwise; header.seq shows the gap) |
 * lagged (the piece's vertices on the crack are sent 0.5 mm off the positions the client
 * holds for the left cube's, as copies naming their sources: topology_t.vnew_src) | nosrc
 * (the same without sources).
 * --chunk-bytes B splits every topology change into chunks of at most B payload bytes
 * (default: one chunk each), as the daemon does for large changes.
 * Exit 0, 2 on usage or write errors.
 */
#include <lcm/eventlog.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cubesim_delta_t.h"
#include "cubesim_snapshot_t.h"
#include "cubesim_topology_t.h"

#define H 0.1
#define SESSION 4242

typedef struct mesh {
    int nv, nt;
    double v[3 * 64];
    int32_t t[3 * 64];
    int32_t lattice[64]; /* lattice point id (ix + 3*(iy + 2*iz)) of each vertex */
} mesh;

typedef struct out {
    lcm_eventlog_t *log;
    int64_t n, utime, seq_snap, seq_delta, seq_topo;
    int drop_topo;  /* 1 + the index of the topology message to leave out; 0: none */
    int topo_index; /* topology messages made so far */
    int chunk_bytes;
    int32_t change_id;
} out;

static int lattice_index(mesh *m, int ix, int iy, int iz, double dz)
{
    int32_t id = ix + 3 * (iy + 2 * iz);
    for (int i = 0; i < m->nv; i++)
        if (m->lattice[i] == id)
            return i;
    m->lattice[m->nv] = id;
    m->v[3 * m->nv] = ix * H;
    m->v[3 * m->nv + 1] = iy * H;
    m->v[3 * m->nv + 2] = 0.5 + iz * H + dz;
    return m->nv++;
}

/* The boundary of cells ix in [x0, x1) (one row along x), outward counter-clockwise. */
static void cells_surface(mesh *m, int x0, int x1, double dz)
{
    /* Each face: axis, side, and the four corners in counter-clockwise order seen from
     * outside, as offsets from the cell's corner. */
    static const int face[6][4][3] = {
        {{0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}}, /* -x */
        {{1, 0, 0}, {1, 1, 0}, {1, 1, 1}, {1, 0, 1}}, /* +x */
        {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}}, /* -y */
        {{0, 1, 0}, {0, 1, 1}, {1, 1, 1}, {1, 1, 0}}, /* +y */
        {{0, 0, 0}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}}, /* -z */
        {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}}, /* +z */
    };
    for (int x = x0; x < x1; x++)
        for (int f = 0; f < 6; f++) {
            if ((f == 0 && x > x0) || (f == 1 && x < x1 - 1))
                continue; /* an inner face */
            int q[4];
            for (int k = 0; k < 4; k++)
                q[k] = lattice_index(m, x + face[f][k][0], face[f][k][1], face[f][k][2], dz);
            int32_t *t = m->t + 3 * m->nt;
            t[0] = q[0], t[1] = q[1], t[2] = q[2], t[3] = q[0], t[4] = q[2], t[5] = q[3];
            m->nt += 2;
        }
}

static int write_event(out *o, const char *channel, void *buf, int len)
{
    lcm_eventlog_event_t ev;
    ev.eventnum = o->n++;
    ev.timestamp = (o->utime += 1000);
    ev.channellen = (int32_t)strlen(channel);
    ev.datalen = len;
    ev.channel = (char *)channel;
    ev.data = buf;
    return lcm_eventlog_write_event(o->log, &ev);
}

static cubesim_header_t hdr(int64_t frame, int64_t *seq)
{
    cubesim_header_t h = {SESSION, 0, frame, (*seq)++, frame / 60.0, 0};
    return h;
}

static int put_snapshot(out *o, int32_t snap, int64_t frame, const mesh *const *objs,
                        const char *const *names, const int32_t *ids, const int32_t *vers, int n)
{
    for (int i = 0; i < n; i++) {
        float xyz[3 * 64];
        for (int k = 0; k < 3 * objs[i]->nv; k++)
            xyz[k] = (float)objs[i]->v[k];
        cubesim_snapshot_t s;
        memset(&s, 0, sizeof s);
        s.header = hdr(frame, &o->seq_snap);
        s.snapshot_id = snap;
        s.chunk = i;
        s.n_chunks = n;
        s.n_objects = n;
        s.object_id = ids[i];
        s.object_name = (char *)names[i];
        s.model = "corotational";
        s.topology_version = vers[i];
        s.n_vertices_total = objs[i]->nv;
        s.n_triangles_total = objs[i]->nt;
        s.n_coords = 3 * objs[i]->nv;
        s.xyz = xyz;
        s.n_indices = 3 * objs[i]->nt;
        s.indices = (int32_t *)objs[i]->t;
        uint8_t buf[8192];
        int len = cubesim_snapshot_t_encode(buf, 0, sizeof buf, &s);
        if (len < 0 || write_event(o, "CUBESIM_SNAPSHOT", buf, len))
            return -1;
    }
    return 0;
}

/* A delta sending every vertex of m (absolute positions). */
static int put_delta(out *o, int64_t frame, int32_t id, int32_t version, const mesh *m)
{
    int32_t idx[64];
    float xyz[3 * 64];
    for (int i = 0; i < m->nv; i++)
        idx[i] = i;
    for (int k = 0; k < 3 * m->nv; k++)
        xyz[k] = (float)m->v[k];
    cubesim_delta_t d = {hdr(frame, &o->seq_delta), id, version, 0, 1, m->nv, m->nv, idx,
                         3 * m->nv, xyz};
    uint8_t buf[8192];
    int len = cubesim_delta_t_encode(buf, 0, sizeof buf, &d);
    return len < 0 || write_event(o, "CUBESIM_DELTA", buf, len) ? -1 : 0;
}

/* One change as chunks: the five arrays end to end, at most chunk_bytes of items each. */
static int put_change(out *o, int64_t frame, cubesim_topology_t *m, const int32_t *vrm,
                      const float *vnew, const int32_t *trm, const int32_t *tsi,
                      const int32_t *tst, const int32_t *tnew)
{
    static const int bytes[5] = {4, 12, 4, 16, 12};
    int32_t total[5] = {m->total_vremove, m->total_vnew, m->total_tremove, m->total_tset,
                        m->total_tnew};
    int32_t start[64][5], cnt[64][5];
    int nch = 0, a = 0;
    int32_t pos = 0;
    int budget = o->chunk_bytes > 0 ? o->chunk_bytes : 1 << 20;
    while (a < 5 && total[a] == 0)
        a++;
    do {
        int left = budget;
        for (int k = 0; k < 5; k++) {
            start[nch][k] = k < a ? total[k] : (k == a ? pos : 0);
            cnt[nch][k] = 0;
        }
        while (a < 5) {
            int32_t take = total[a] - pos, fit = left / bytes[a];
            if (take > fit)
                take = fit;
            cnt[nch][a] += take;
            pos += take;
            left -= take * bytes[a];
            if (pos < total[a])
                break;
            a++;
            pos = 0;
            while (a < 5 && total[a] == 0)
                a++;
        }
        nch++;
    } while (a < 5 && nch < 64);
    int32_t *src = m->vnew_src; /* the whole change's sources, or NULL */
    m->change_id = ++o->change_id;
    m->n_chunks = nch;
    for (int c = 0; c < nch; c++) {
        m->header = hdr(frame, &o->seq_topo);
        m->chunk = c;
        m->vremove_offset = start[c][0];
        m->n_vremove = cnt[c][0];
        m->vremove = (int32_t *)vrm + start[c][0];
        m->vnew_offset = start[c][1];
        m->n_vnew_coords = 3 * cnt[c][1];
        m->vnew_xyz = (float *)vnew + 3 * start[c][1];
        m->n_vnew_src = src ? cnt[c][1] : 0;
        m->vnew_src = src ? src + start[c][1] : NULL;
        m->tremove_offset = start[c][2];
        m->n_tremove = cnt[c][2];
        m->tremove = (int32_t *)trm + start[c][2];
        m->tset_offset = start[c][3];
        m->n_tset = cnt[c][3];
        m->tset_index = (int32_t *)tsi + start[c][3];
        m->n_tset_indices = 3 * cnt[c][3];
        m->tset_tri = (int32_t *)tst + 3 * start[c][3];
        m->tnew_offset = start[c][4];
        m->n_tnew_indices = 3 * cnt[c][4];
        m->tnew = (int32_t *)tnew + 3 * start[c][4];
        if (o->drop_topo == ++o->topo_index)
            continue; /* lost on the way: its seq number is used, the log lacks it */
        uint8_t buf[16384];
        int len = cubesim_topology_t_encode(buf, 0, sizeof buf, m);
        if (len < 0 || write_event(o, "CUBESIM_TOPOLOGY", buf, len))
            return -1;
    }
    return 0;
}

static int same_tri(const int32_t *a, const int32_t *b)
{
    return a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
}

/*
 * The change taking `old` to `neu` (neu's vertices are a subset of old's lattice points;
 * none new): vertices not kept are swap-removed, old triangles not in neu removed, kept ones
 * that point at a moved vertex rewired, neu's other triangles appended.
 */
static int put_split(out *o, int64_t frame, int32_t id, const mesh *old, const mesh *neu,
                     mesh *fin)
{
    int32_t vrm[64], trm[64], tsi[64], tst[3 * 64], tnew[3 * 64];
    int nvr = 0, ntr = 0, nts = 0, ntn = 0;
    int32_t slot_of_old[64], old_at[64]; /* vertex slots during the swap-removes */
    for (int i = old->nv - 1; i >= 0; i--) {
        int kept = 0;
        for (int j = 0; j < neu->nv; j++)
            kept |= neu->lattice[j] == old->lattice[i];
        if (!kept)
            vrm[nvr++] = i;
    }
    for (int i = 0; i < old->nv; i++)
        old_at[i] = i;
    int nv = old->nv;
    for (int k = 0; k < nvr; k++) {
        old_at[vrm[k]] = old_at[nv - 1];
        nv--;
    }
    for (int i = 0; i < old->nv; i++)
        slot_of_old[i] = -1;
    for (int s = 0; s < nv; s++)
        slot_of_old[old_at[s]] = s;
    /* neu's triangles in old indices, and mapped to final slots */
    int32_t neu_old[3 * 64], neu_fin[3 * 64];
    for (int k = 0; k < 3 * neu->nt; k++) {
        int32_t lat = neu->lattice[neu->t[k]], oi = -1;
        for (int i = 0; i < old->nv; i++)
            if (old->lattice[i] == lat)
                oi = i;
        neu_old[k] = oi;
        neu_fin[k] = slot_of_old[oi];
    }
    uint8_t used[64] = {0};
    int keep_old[64];
    for (int i = old->nt - 1; i >= 0; i--) {
        keep_old[i] = -1;
        for (int j = 0; j < neu->nt; j++)
            if (same_tri(old->t + 3 * i, neu_old + 3 * j))
                keep_old[i] = j;
        if (keep_old[i] < 0)
            trm[ntr++] = i;
        else
            used[keep_old[i]] = 1;
    }
    int32_t tri_at[64]; /* old triangle in each slot during the swap-removes */
    for (int i = 0; i < old->nt; i++)
        tri_at[i] = i;
    int nt = old->nt;
    for (int k = 0; k < ntr; k++) {
        tri_at[trm[k]] = tri_at[nt - 1];
        nt--;
    }
    for (int s = 0; s < nt; s++) {
        const int32_t *ot = old->t + 3 * tri_at[s];
        int32_t want[3] = {slot_of_old[ot[0]], slot_of_old[ot[1]], slot_of_old[ot[2]]};
        if (!same_tri(ot, want)) {
            tsi[nts] = s;
            memcpy(tst + 3 * nts++, want, sizeof want);
        }
    }
    for (int j = 0; j < neu->nt; j++)
        if (!used[j])
            memcpy(tnew + 3 * ntn++, neu_fin + 3 * j, 3 * sizeof(int32_t));
    /* What a client holds afterwards, in its slot order (for the deltas that follow). */
    memset(fin, 0, sizeof *fin);
    fin->nv = nv;
    for (int s = 0; s < nv; s++) {
        memcpy(fin->v + 3 * s, old->v + 3 * old_at[s], 3 * sizeof(double));
        fin->lattice[s] = old->lattice[old_at[s]];
    }
    fin->nt = nt + ntn;
    for (int s = 0; s < nt; s++)
        for (int k = 0; k < 3; k++)
            fin->t[3 * s + k] = slot_of_old[old->t[3 * tri_at[s] + k]];
    memcpy(fin->t + 3 * nt, tnew, 3 * (size_t)ntn * sizeof(int32_t));
    cubesim_topology_t m;
    memset(&m, 0, sizeof m);
    m.object_id = id;
    m.name = "";
    m.model = "";
    m.from_version = 1;
    m.to_version = 2;
    m.n_vertices_total = nv;
    m.n_triangles_total = nt + ntn;
    m.total_vremove = nvr;
    m.total_tremove = ntr;
    m.total_tset = nts;
    m.total_tnew = ntn;
    return put_change(o, frame, &m, vrm, NULL, trm, tsi, tst, tnew);
}

static int put_piece(out *o, int64_t frame, int32_t id, int32_t parent, const char *name,
                     const mesh *p, const int32_t *src)
{
    float xyz[3 * 64];
    for (int k = 0; k < 3 * p->nv; k++)
        xyz[k] = (float)p->v[k];
    cubesim_topology_t m;
    memset(&m, 0, sizeof m);
    m.object_id = id;
    m.parent_id = parent;
    m.name = (char *)name;
    m.model = "corotational";
    m.from_version = 0;
    m.to_version = 1;
    m.n_vertices_total = p->nv;
    m.n_triangles_total = p->nt;
    m.total_vnew = p->nv;
    m.total_tnew = p->nt;
    m.vnew_src = (int32_t *)src; /* put_change slices it with vnew */
    return put_change(o, frame, &m, NULL, xyz, NULL, NULL, NULL, p->t);
}

static void lift(mesh *m, double dz)
{
    for (int i = 0; i < m->nv; i++)
        m->v[3 * i + 2] += dz;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: cs_it_mklog OUT.lcm good|badvolume|open|gap|lagged|nosrc "
                        "[--chunk-bytes B]\n");
        return 2;
    }
    const char *mode = argv[2];
    out o;
    memset(&o, 0, sizeof o);
    o.utime = 1700000000000000LL;
    for (int i = 3; i + 1 < argc; i += 2)
        if (!strcmp(argv[i], "--chunk-bytes"))
            o.chunk_bytes = atoi(argv[i + 1]);
    if (strcmp(mode, "good") && strcmp(mode, "badvolume") && strcmp(mode, "open") &&
        strcmp(mode, "gap") && strcmp(mode, "lagged") && strcmp(mode, "nosrc")) {
        fprintf(stderr, "cs_it_mklog: unknown mode '%s'\n", mode);
        return 2;
    }
    o.log = lcm_eventlog_create(argv[1], "w");
    if (!o.log) {
        fprintf(stderr, "cs_it_mklog: cannot write %s\n", argv[1]);
        return 2;
    }
    static mesh bar, left, piece, fin;
    cells_surface(&bar, 0, 2, 0);
    int rc = 0;
    const mesh *objs[2] = {&bar, NULL};
    const char *names[2] = {"bar", "bar.1"};
    int32_t ids[2] = {1, 2}, vers[2] = {1, 1};
    rc |= put_snapshot(&o, 1, 0, objs, names, ids, vers, 1);
    lift(&bar, 0.001);
    rc |= put_delta(&o, 1, 1, 1, &bar);

    /* frame 2: the fracture at x = h */
    lift(&bar, 0.001);
    memset(&left, 0, sizeof left);
    cells_surface(&left, 0, 1, 0.002);
    memset(&piece, 0, sizeof piece);
    cells_surface(&piece, 1, 2, 0.002);
    if (!strcmp(mode, "badvolume"))
        for (int i = 0; i < piece.nv; i++)
            if (piece.v[3 * i] > 1.5 * H)
                piece.v[3 * i] += 0.2 * H;
    if (!strcmp(mode, "open"))
        for (int j = 0; j < piece.nt; j++) /* drop the closing face (-x, at x = h): 2 triangles */
            if (piece.v[3 * piece.t[3 * j]] < 1.5 * H && piece.v[3 * piece.t[3 * j + 1]] < 1.5 * H &&
                piece.v[3 * piece.t[3 * j + 2]] < 1.5 * H) {
                memmove(piece.t + 3 * j, piece.t + 3 * j + 3,
                        (size_t)(piece.nt - j - 1) * 3 * sizeof(int32_t));
                piece.nt--;
                j--;
            }
    if (!strcmp(mode, "gap")) {
        o.drop_topo = 2; /* the second chunk of the split */
        if (!o.chunk_bytes)
            o.chunk_bytes = 40;
    }
    rc |= put_split(&o, 2, 1, &bar, &left, &fin);
    /* lagged, nosrc: the piece's vertices on the crack (x = h) are sent 0.5 mm further along
     * x than the client holds them (the daemon's positions of copies the client last got
     * within publish_epsilon); lagged names their sources (the left cube's vertices there),
     * nosrc does not */
    int32_t src[64], *srcp = NULL;
    const int lagged = !strcmp(mode, "lagged"), nosrc = !strcmp(mode, "nosrc");
    for (int i = 0; i < piece.nv; i++) {
        src[i] = -1;
        if ((lagged || nosrc) && piece.v[3 * i] < 1.5 * H)
            piece.v[3 * i] += 0.0005;
        for (int j = 0; j < fin.nv; j++)
            if (fin.lattice[j] == piece.lattice[i])
                src[i] = j;
    }
    if (lagged)
        srcp = src;
    rc |= put_piece(&o, 2, 2, 1, "bar.1", &piece, srcp);
    rc |= put_delta(&o, 2, 1, 2, &fin);

    lift(&piece, 0.01);
    rc |= put_delta(&o, 3, 2, 1, &piece);

    objs[0] = &fin;
    objs[1] = &piece;
    vers[0] = 2;
    rc |= put_snapshot(&o, 2, 4, objs, names, ids, vers, 2);
    lcm_eventlog_destroy(o.log);
    if (rc) {
        fprintf(stderr, "cs_it_mklog: writing %s failed\n", argv[1]);
        return 2;
    }
    return 0;
}
