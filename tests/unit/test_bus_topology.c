/*
 * test_bus_topology.c — the daemon's side of CUBESIM_TOPOLOGY (server/bus.c) without the
 * engine's fracture: a change made by hand against a real object's surface is queued, sent
 * through LCM's file:// provider into an event log, decoded like a client decodes it and fed
 * to common/surface_state after the snapshot: the client ends with exactly the arrays
 * common/topo.c gives. Large changes are chunked under 64 KiB; a change the last-sent copy
 * cannot follow is not sent and a snapshot goes out instead.
 */
#include "check.h"

#include <lcm/eventlog.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cubesim.h"
#include "cubesim_snapshot_t.h"
#include "cubesim_topology_t.h"
#include "server/bus.h"
#include "surface_state.h"

/* A world with one 2x1x1 block of cells; its surface as the engine made it. */
static cs_world_t *block_world(void)
{
    static const int32_t ijk[6] = {0, 0, 0, 1, 0, 0};
    cs_world_def wd = cs_world_def_default();
    cs_world_t *w = NULL;
    char err[256];
    if (cs_world_create(&wd, &w, err, sizeof err))
        return NULL;
    cs_object_def d = cs_object_def_default();
    d.name = "block";
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = 2;
    cs_object_id id;
    if (cs_world_add_object(w, &d, &id, err, sizeof err)) {
        cs_world_destroy(w);
        return NULL;
    }
    return w;
}

/* Send everything queued (the file provider has no pacing to respect). */
static void flush(cs_bus_t *b)
{
    double t = 1e6;
    while (cs_bus_pump(b, t, NULL) > 0)
        t += 1.0;
}

typedef struct counts {
    int snapshots, topology, max_len, applied, rejected;
    int src_items;         /* vnew_src items received, all changes */
    int32_t *src77;        /* if not NULL: the sources received for object 77, by item */
} counts;

/* Feed every snapshot and topology message of the log to st. */
static void read_log(const char *path, cs_surface_state *st, counts *n)
{
    int32_t *src77 = n->src77;
    memset(n, 0, sizeof *n);
    n->src77 = src77;
    lcm_eventlog_t *log = lcm_eventlog_create(path, "r");
    if (!log)
        return;
    lcm_eventlog_event_t *ev;
    char err[256];
    while ((ev = lcm_eventlog_read_next_event(log)) != NULL) {
        if (ev->datalen > n->max_len)
            n->max_len = ev->datalen;
        if (!strcmp(ev->channel, CS_CH_SNAPSHOT)) {
            cubesim_snapshot_t s;
            if (cubesim_snapshot_t_decode(ev->data, 0, ev->datalen, &s) >= 0) {
                n->snapshots++;
                cs_ss_chunk c = {{s.header.session_id, s.header.epoch, s.header.frame,
                                  s.header.seq, s.header.sim_time},
                                 s.snapshot_id, s.chunk, s.n_chunks, s.n_objects, s.object_id,
                                 s.object_name, s.model, s.topology_version, s.n_vertices_total,
                                 s.n_triangles_total, s.vertex_offset, s.n_coords, s.xyz,
                                 s.triangle_offset, s.n_indices, s.indices};
                cs_surface_state_apply_chunk(st, &c, err, sizeof err);
                cubesim_snapshot_t_decode_cleanup(&s);
            }
        } else if (!strcmp(ev->channel, CS_CH_TOPOLOGY)) {
            cubesim_topology_t m;
            if (cubesim_topology_t_decode(ev->data, 0, ev->datalen, &m) >= 0) {
                n->topology++;
                cs_ss_topo t = {{m.header.session_id, m.header.epoch, m.header.frame,
                                 m.header.seq, m.header.sim_time},
                                m.change_id, m.chunk, m.n_chunks, m.object_id, m.parent_id,
                                m.name, m.model, m.from_version, m.to_version,
                                m.n_vertices_total, m.n_triangles_total, m.total_vremove,
                                m.total_vnew, m.total_tremove, m.total_tset, m.total_tnew,
                                m.vremove_offset, m.n_vremove, m.vremove, m.vnew_offset,
                                m.n_vnew_coords, m.vnew_xyz, m.tremove_offset, m.n_tremove,
                                m.tremove, m.tset_offset, m.n_tset, m.tset_index,
                                m.n_tset_indices, m.tset_tri, m.tnew_offset, m.n_tnew_indices,
                                m.tnew, m.n_vnew_src, m.vnew_src};
                n->src_items += m.n_vnew_src;
                for (int i = 0; n->src77 && m.object_id == 77 && i < m.n_vnew_src; i++)
                    n->src77[m.vnew_offset + i] = m.vnew_src[i];
                int r = cs_surface_state_apply_topology(st, &t, err, sizeof err);
                n->applied += r == CS_SS_APPLIED;
                n->rejected += r == CS_SS_REJECTED;
                cubesim_topology_t_decode_cleanup(&m);
            }
        }
        lcm_eventlog_free_event(ev);
    }
    lcm_eventlog_destroy(log);
}

TEST(bus_topology_reaches_clients_exactly)
{
    char path[64], url[96];
    snprintf(path, sizeof path, "/tmp/cs_unit_bus_%d.lcm", (int)getpid());
    snprintf(url, sizeof url, "file://%s?mode=w", path);
    cs_world_t *w = block_world();
    ENSURE(w);
    cs_dlog dl;
    memset(&dl, 0, sizeof dl);
    dl.quiet = true;
    cs_bus_t *b = NULL;
    char err[256];
    ENSURE_MSG(cs_bus_create(url, &dl, &b, err, sizeof err) == 0, "%s", err);
    cs_object_id id = cs_world_find_object(w, "block");
    const double *v;
    const int32_t *t;
    int nv, nt;
    cs_object_surface(w, id, &v, &nv, &t, &nt);
    cs_object_info info;
    cs_object_get_info(w, id, &info);
    ENSURE(cs_bus_queue_snapshot(b, w, false) > 0);

    /* 1. split: remove the last two vertices and the first triangle, rewire one, add two */
    int32_t vrm[2] = {nv - 1, nv - 2}, trm[1] = {0}, tsi[1] = {1}, tst[3] = {0, 1, nv - 2};
    double vnew[6] = {0.5, 0.5, 0.5, 0.25, 0.75, 0.125};
    int32_t tnew[6] = {0, nv - 1, 2, 3, 1, nv - 2};
    cs_topo_change ch[3];
    memset(ch, 0, sizeof ch);
    int32_t src0[2] = {3, -1}; /* a copy of vertex 3 and a new point */
    ch[0] = (cs_topo_change){(int32_t)id, 0, NULL, NULL, info.topology_version,
                             info.topology_version + 1, nv, nt + 1, 2, vrm, 2, vnew, 1, trm,
                             1, tsi, tst, 2, tnew, src0};
    /* 2. a big new piece: 9000 vertices and triangles, several chunks */
    int big = 9000;
    double *pv = malloc(3 * (size_t)big * sizeof *pv);
    int32_t *pt = malloc(3 * (size_t)big * sizeof *pt);
    int32_t *ps = malloc((size_t)big * sizeof *ps), *got = malloc((size_t)big * sizeof *got);
    ENSURE(pv && pt && ps && got);
    for (int i = 0; i < big; i++) {
        pv[3 * i] = i * 1e-3;
        pv[3 * i + 1] = (i % 7) * 1e-2;
        pv[3 * i + 2] = 0.5;
        pt[3 * i] = i;
        pt[3 * i + 1] = (i + 1) % big;
        pt[3 * i + 2] = (i + 2) % big;
        ps[i] = i % 3 ? i % nv : -1; /* copies of the parent's vertices and new points */
        got[i] = -7;
    }
    ch[1] = (cs_topo_change){77, (int32_t)id, "block.1", "corotational", 0, 1, big, big,
                             0, NULL, big, pv, 0, NULL, 0, NULL, NULL, big, pt, ps};
    /* 3. a change the mirror cannot follow (from a version never sent) */
    ch[2] = ch[0];
    ch[2].from_version = info.topology_version + 5;
    ch[2].to_version = info.topology_version + 6;
    int q = cs_bus_queue_topology(b, w, ch, 2);
    ENSURE_MSG(q >= 3, "queued %d messages", q);
    flush(b);
    cs_bus_destroy(b);

    cs_surface_state st;
    cs_surface_state_init(&st);
    counts n = {.src77 = got};
    read_log(path, &st, &n);
    unlink(path);
    ENSURE_MSG(n.topology == q && n.applied == 2 && n.rejected == 0 && n.snapshots >= 1,
               "%d topology messages, %d applied, %d rejected", n.topology, n.applied, n.rejected);
    /* every source arrives with its vertex, across the piece's chunks */
    ENSURE_MSG(n.src_items == 2 + big, "%d sources received", n.src_items);
    ENSURE(!memcmp(got, ps, (size_t)big * sizeof *ps));
    free(ps);
    free(got);
    ENSURE_MSG(n.max_len < 65536, "a message of %d bytes", n.max_len);
    /* The client's block: common/topo.c applied to the engine's surface rounded to float. */
    float *want_v = malloc(3 * (size_t)(nv + 2) * sizeof *want_v);
    int32_t *want_t = malloc(3 * (size_t)(nt + 2) * sizeof *want_t);
    ENSURE(want_v && want_t);
    for (int i = 0; i < 3 * nv; i++)
        want_v[i] = (float)v[i];
    int k = cs_topo_remove_vertices(&ch[0], want_v, 3 * sizeof(float), nv);
    for (int i = 0; i < 6; i++)
        want_v[3 * k + i] = (float)vnew[i];
    memcpy(want_t, t, 3 * (size_t)nt * sizeof *want_t);
    int kt = cs_topo_apply_triangles(&ch[0], want_t, nt);
    const cs_ss_object *o = cs_surface_state_find(&st, (int32_t)id);
    ENSURE(o && o->nv == nv && o->nt == kt && o->topology_version == (int32_t)ch[0].to_version);
    ENSURE(!memcmp(o->xyz, want_v, 3 * (size_t)nv * sizeof(float)));
    ENSURE(!memcmp(o->tris, want_t, 3 * (size_t)kt * sizeof(int32_t)));
    const cs_ss_object *p = cs_surface_state_find(&st, 77);
    ENSURE(p && p->nv == big && p->nt == big && p->parent_id == (int32_t)id &&
           !strcmp(p->name, "block.1") && !memcmp(p->tris, pt, 3 * (size_t)big * sizeof *pt));
    ENSURE(p->xyz[3 * (big - 1)] == (float)pv[3 * (big - 1)]);
    free(want_v);
    free(want_t);
    cs_surface_state_free(&st);

    /* A change the last-sent copy cannot follow is not sent: a snapshot goes out instead. */
    ENSURE(cs_bus_create(url, &dl, &b, err, sizeof err) == 0);
    ENSURE(cs_bus_queue_snapshot(b, w, false) > 0);
    ENSURE(cs_bus_queue_topology(b, w, ch + 2, 1) == 0);
    flush(b);
    cs_bus_destroy(b);
    cs_surface_state_init(&st);
    read_log(path, &st, &n);
    unlink(path);
    ENSURE(n.topology == 0 && n.snapshots == 2);
    cs_surface_state_free(&st);
    free(pv);
    free(pt);
    cs_world_destroy(w);
}
