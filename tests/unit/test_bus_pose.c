/*
 * test_bus_pose.c — what the daemon's bus (server/bus.c) publishes for a moving rigid object:
 * CUBESIM_POSE at every publish frame, and vertex deltas only for vertices that moved in the
 * body frame (README "CUBESIM_POSE"). Frames are queued with cs_bus_queue_deltas as the
 * daemon's loop does, sent through LCM's file:// provider into an event log, counted and fed
 * to common/surface_state as a client would.
 *
 * Before the fix, a pose moved the daemon's record of what it sent to the pose applied to its
 * float32 reference copy, and the deltas then compared those floats with the engine's doubles:
 * at publish_epsilon 0 every vertex of a falling box went again in every frame (42 of 42 per
 * frame beside its pose), and so did every vertex of a box 500 m from the origin at the default
 * 1e-6 (a float32 step there is 3e-5 m). A vertex that did move in the body frame was resent in
 * every frame, each pose undoing it on the clients.
 */
#include "check.h"

#include <lcm/eventlog.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "cubesim.h"
#include "cubesim_delta_t.h"
#include "cubesim_pose_t.h"
#include "cubesim_snapshot_t.h"
#include "server/bus.h"
#include "surface_state.h"

#define MAX_FRAMES 64

/* A world (no ground; gravity as given) with one rigid box of 4×2×2 cubes of 0.05 m at `at`. */
static cs_world_t *box_world(const double at[3], double gz, cs_object_id *id)
{
    static const int32_t ijk[48] = {0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0, 0, 1, 0, 1, 1, 0,
                                    2, 1, 0, 3, 1, 0, 0, 0, 1, 1, 0, 1, 2, 0, 1, 3, 0, 1,
                                    0, 1, 1, 1, 1, 1, 2, 1, 1, 3, 1, 1};
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = gz;
    wd.threads = 1;
    cs_world_t *w = NULL;
    char err[256];
    if (cs_world_create(&wd, &w, err, sizeof err))
        return NULL;
    cs_object_def d = cs_object_def_default();
    d.name = "box";
    d.model = CS_MODEL_RIGID;
    d.cube_size = 0.05;
    d.geometry = CS_GEOMETRY_CELLS;
    memcpy(d.cells_origin, at, sizeof d.cells_origin);
    d.cells_ijk = ijk;
    d.n_cells = 16;
    if (cs_world_add_object(w, &d, id, err, sizeof err)) {
        fprintf(stderr, "box_world: %s\n", err);
        cs_world_destroy(w);
        return NULL;
    }
    /* set it turning: a push off its centre for one step */
    const double p[3] = {at[0] + 0.2, at[1], at[2] + 0.1}, F[3] = {0, 40, 20};
    if (cs_world_apply_force(w, *id, p, F, 0, err, sizeof err)) {
        cs_world_destroy(w);
        return NULL;
    }
    return w;
}

/* What the log holds, frame by frame (frames 1 … MAX_FRAMES − 1). */
typedef struct tally {
    int snapshots, poses, refs, deltas_lost, rejected;
    int vertices[MAX_FRAMES]; /* delta vertices in the frame */
    int pose[MAX_FRAMES], ref[MAX_FRAMES];
} tally;

/* Feed the whole log to st (a client), counting. */
static void read_log(const char *path, cs_surface_state *st, tally *n)
{
    memset(n, 0, sizeof *n);
    lcm_eventlog_t *log = lcm_eventlog_create(path, "r");
    if (!log)
        return;
    lcm_eventlog_event_t *ev;
    char err[256];
    while ((ev = lcm_eventlog_read_next_event(log)) != NULL) {
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
        } else if (!strcmp(ev->channel, CS_CH_DELTA)) {
            cubesim_delta_t d;
            if (cubesim_delta_t_decode(ev->data, 0, ev->datalen, &d) >= 0) {
                const int64_t f = d.header.frame;
                if (f > 0 && f < MAX_FRAMES)
                    n->vertices[f] += d.n;
                cs_ss_delta c = {{d.header.session_id, d.header.epoch, d.header.frame,
                                  d.header.seq, d.header.sim_time},
                                 d.object_id, d.topology_version, d.chunk, d.n_chunks,
                                 d.n_vertices_total, d.n, d.index, d.n_coords, d.xyz};
                n->rejected += cs_surface_state_apply_delta(st, &c, err, sizeof err) !=
                               CS_SS_APPLIED;
                cubesim_delta_t_decode_cleanup(&d);
            }
        } else if (!strcmp(ev->channel, CS_CH_POSE)) {
            cubesim_pose_t p;
            if (cubesim_pose_t_decode(ev->data, 0, ev->datalen, &p) >= 0) {
                const int64_t f = p.header.frame;
                n->poses++;
                n->refs += p.reference;
                if (f > 0 && f < MAX_FRAMES) {
                    n->pose[f]++;
                    n->ref[f] += p.reference;
                }
                cs_ss_pose c = {{p.header.session_id, p.header.epoch, p.header.frame,
                                 p.header.seq, p.header.sim_time},
                                p.object_id, p.topology_version, p.n_vertices_total,
                                p.reference, {p.position[0], p.position[1], p.position[2]},
                                {p.orientation[0], p.orientation[1], p.orientation[2],
                                 p.orientation[3]}};
                n->rejected += cs_surface_state_apply_pose(st, &c, err, sizeof err) !=
                               CS_SS_APPLIED;
                cubesim_pose_t_decode_cleanup(&p);
            }
        }
        lcm_eventlog_free_event(ev);
    }
    n->deltas_lost = (int)st->deltas_lost;
    lcm_eventlog_destroy(log);
}

/* Send everything queued (the file provider has no pacing to respect). */
static void flush(cs_bus_t *b)
{
    double t = 1e6;
    while (cs_bus_pump(b, t, NULL) > 0)
        t += 1.0;
}

/* A bus writing to a fresh log at path (64 chars). */
static cs_bus_t *log_bus(char *path, cs_dlog *dl)
{
    static int serial;
    char url[128];
    snprintf(path, 64, "/tmp/cs_unit_pose_%d_%d.lcm", (int)getpid(), serial++);
    snprintf(url, sizeof url, "file://%s?mode=w", path);
    memset(dl, 0, sizeof *dl);
    dl->quiet = true;
    cs_bus_t *b = NULL;
    char err[256];
    return cs_bus_create(url, dl, &b, err, sizeof err) == 0 ? b : NULL;
}

/* The largest coordinate magnitude of object id's surface, and its vertex count. */
static double surface_max_abs(const cs_world_t *w, cs_object_id id, int *nv)
{
    const double *v;
    const int32_t *t;
    int nt;
    cs_object_surface(w, id, &v, nv, &t, &nt);
    double m = 0;
    for (int i = 0; i < 3 * *nv; i++)
        m = fmax(m, fabs(v[i]));
    return m;
}

/* The largest distance between the client's copy of object id and the engine's surface, and
 * the largest coordinate magnitude of that surface. */
static double client_error(const cs_surface_state *st, const cs_world_t *w, cs_object_id id,
                           double *max_x)
{
    const cs_ss_object *o = cs_surface_state_find(st, (int32_t)id);
    const double *v;
    const int32_t *t;
    int nv, nt;
    cs_object_surface(w, id, &v, &nv, &t, &nt);
    if (!o || o->nv != nv)
        return INFINITY;
    double e = 0;
    for (int i = 0; i < nv; i++) {
        double d2 = 0;
        for (int k = 0; k < 3; k++) {
            const double d = (double)o->xyz[3 * i + k] - v[3 * i + k];
            d2 += d * d;
            *max_x = fmax(*max_x, fabs(v[3 * i + k]));
        }
        e = fmax(e, sqrt(d2));
    }
    return e;
}

/*
 * A box set turning at `at`, falling under gz, published for `frames` frames at eps after a
 * snapshot at frame 0 (one step per frame). Into n, and the client's final error against the
 * engine's surface and the largest coordinate seen (reference or final) into err, max_x.
 */
static int run_box(const double at[3], double gz, double eps, int frames, tally *n,
                   double *err, double *max_x, int *nv)
{
    cs_object_id id;
    cs_world_t *w = box_world(at, gz, &id);
    cs_dlog dl;
    char path[64];
    cs_bus_t *b = log_bus(path, &dl);
    if (!w || !b) {
        cs_world_destroy(w);
        cs_bus_destroy(b);
        return -1;
    }
    cs_bus_set_context(b, 0, 0, 0);
    int rc = cs_bus_queue_snapshot(b, w, false) > 0 ? 0 : -1;
    *max_x = 0;
    for (int f = 1; f <= frames && rc == 0; f++) {
        rc = cs_world_step(w) == CS_OK ? 0 : -1;
        cs_bus_set_context(b, 0, cs_world_frame(w), cs_world_time(w));
        if (rc == 0 && cs_bus_queue_deltas(b, w, eps) < 0)
            rc = -1;
        if (f == 1) /* the reference copy's frame */
            *max_x = surface_max_abs(w, id, nv);
        flush(b);
    }
    cs_bus_destroy(b);
    cs_surface_state st;
    cs_surface_state_init(&st);
    read_log(path, &st, n);
    unlink(path);
    *err = client_error(&st, w, id, max_x);
    cs_surface_state_free(&st);
    cs_world_destroy(w);
    return rc;
}

/* After its reference frame, a moving rigid box costs one pose per frame and no vertex; the
 * client's copy stays within the bound README "CUBESIM_POSE" states (publish_epsilon plus
 * float32 rounding of the reference copy and of the pose's result: √3·2⁻²³ (|x_r| + |x|)). */
static void check_poses_only(const char *what, const double at[3], double gz, double eps)
{
    enum { FRAMES = 30 };
    tally n;
    double err, max_x;
    int nv = 0;
    ENSURE_MSG(run_box(at, gz, eps, FRAMES, &n, &err, &max_x, &nv) == 0, "%s: the run failed",
               what);
    int later = 0, frames_posed = 0;
    for (int f = 2; f <= FRAMES; f++) {
        later += n.vertices[f];
        frames_posed += n.pose[f] == 1 && n.ref[f] == 0;
    }
    const double bound = eps + 2 * sqrt(3.0) * 0x1p-23 * max_x;
    printf("    %s: frame 1: %d of %d vertices and %d reference pose; frames 2-%d: %d poses, "
           "%d vertices; client off by %.3g m (bound %.3g)\n",
           what, n.vertices[1], nv, n.ref[1], FRAMES, frames_posed, later, err, bound);
    ENSURE_MSG(n.snapshots == 1 && n.rejected == 0 && n.deltas_lost == 0,
               "%s: %d snapshots, %d messages refused, %d lost", what, n.snapshots, n.rejected,
               n.deltas_lost);
    ENSURE_MSG(nv > 0 && n.vertices[1] == nv && n.ref[1] == 1, "%s: frame 1 sent %d of %d "
               "vertices, %d reference poses", what, n.vertices[1], nv, n.ref[1]);
    ENSURE_MSG(frames_posed == FRAMES - 1, "%s: %d of %d frames with one plain pose", what,
               frames_posed, FRAMES - 1);
    ENSURE_MSG(later == 0, "%s: %d vertices sent in frames 2-%d (each moved only as a rigid "
               "body)", what, later, FRAMES);
    ENSURE_MSG(err <= bound, "%s: the client's copy is %.3g m off, bound %.3g", what, err,
               bound);
}

TEST(bus_rigid_poses_at_epsilon_zero_send_no_vertices)
{
    check_poses_only("falling at publish_epsilon 0", (double[3]){0.3, 0.1, 2.0}, -9.81, 0.0);
}

TEST(bus_rigid_poses_far_from_the_origin_send_no_vertices)
{
    check_poses_only("500 m out at publish_epsilon 1e-6", (double[3]){500.0, -20.0, 3.0}, 0,
                     1e-6);
}

/* A vertex that moves in the body frame (here by hand, 1 mm) is sent once, with a new
 * reference pose after it; the next frames carry poses only, and the client keeps it. */
TEST(bus_rigid_vertex_moved_in_its_body_frame_sent_once)
{
    const double at[3] = {0.3, 0.1, 2.0};
    cs_object_id id;
    cs_world_t *w = box_world(at, 0, &id);
    cs_dlog dl;
    char path[64];
    cs_bus_t *b = log_bus(path, &dl);
    ENSURE(w && b);
    cs_bus_set_context(b, 0, 0, 0);
    ENSURE(cs_bus_queue_snapshot(b, w, false) > 0);
    for (int f = 1; f <= 3; f++) {
        ENSURE(cs_world_step(w) == CS_OK);
        cs_bus_set_context(b, 0, f, f / 60.0);
        ENSURE(cs_bus_queue_deltas(b, w, 1e-6) >= 0);
        flush(b);
    }
    /* the engine's surface, vertex 5 moved 1 mm (a step would skin it back: frames 4-6 only
     * publish) */
    const double *v;
    const int32_t *t;
    int nv0, nt;
    ENSURE(cs_object_surface(w, id, &v, &nv0, &t, &nt) == CS_OK && nv0 > 5);
    ((double *)v)[3 * 5 + 2] += 1e-3; /* (the engine's own array, written behind its back) */
    for (int f = 4; f <= 6; f++) {
        cs_bus_set_context(b, 0, f, f / 60.0);
        ENSURE(cs_bus_queue_deltas(b, w, 1e-6) >= 0);
        flush(b);
    }
    cs_bus_destroy(b);
    cs_surface_state st;
    cs_surface_state_init(&st);
    tally n;
    read_log(path, &st, &n);
    unlink(path);
    int nv;
    double max_x = surface_max_abs(w, id, &nv);
    const double err = client_error(&st, w, id, &max_x);
    printf("    frames 4/5/6: %d/%d/%d vertices, %d/%d/%d reference poses; client off by %.3g m\n",
           n.vertices[4], n.vertices[5], n.vertices[6], n.ref[4], n.ref[5], n.ref[6], err);
    cs_surface_state_free(&st);
    cs_world_destroy(w);
    ENSURE(n.rejected == 0 && n.deltas_lost == 0);
    ENSURE_MSG(n.vertices[4] == 1 && n.ref[4] == 1 && n.pose[4] == 2,
               "frame 4: %d vertices, %d poses (%d reference)", n.vertices[4], n.pose[4],
               n.ref[4]);
    ENSURE_MSG(n.vertices[5] == 0 && n.vertices[6] == 0 && n.ref[5] == 0 && n.ref[6] == 0,
               "frames 5, 6: %d, %d vertices (sent again after each pose undid it)",
               n.vertices[5], n.vertices[6]);
    ENSURE_MSG(err <= 1e-6 + 2 * sqrt(3.0) * 0x1p-23 * max_x, "the client's copy is %.3g m off",
               err);
}
