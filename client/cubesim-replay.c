/*
 * cubesim-replay — play back a cubesim log, or rebuild its surfaces (DESIGN.md "Bus",
 * "Contracts": a log of the daemon's stream is enough to rebuild every frame's surface).
 *
 *   cubesim-replay LOG [--speed X] [--loop] [--start S] [--channels REGEX] [--lcm URL]
 *                      [--paused] [--quiet]
 *   cubesim-replay LOG --export FILE [--frame N]
 *   cubesim-replay LOG --verify [--topology-tol R] [--volume-tol R]
 *
 * Playback republishes every event whose channel matches REGEX (anchored, POSIX extended;
 * default: all) with the log's timing divided by X (0: as fast as possible), from S seconds
 * after the first event. When stdin is a terminal or a pipe it takes single-key commands:
 * p pause/resume, s publish one message (while paused), q quit; SIGINT/SIGTERM quit too.
 *
 * Rebuild reads only CUBESIM_SNAPSHOT, CUBESIM_TOPOLOGY, CUBESIM_DELTA and CUBESIM_POSE (rigid
 * objects) and feeds common/surface_state: the surfaces at frame N are the last complete
 * snapshot of the last session/epoch with frame <= N plus every topology change, pose and delta
 * of frame <= N after it.
 * --verify checks, after each frame that changed the surfaces, every object as a piece with
 * cs_check_pieces (closed, oriented, non-degenerate, positive volume); in a frame where a
 * topology change (fracture) was applied, the changes must keep the volume of the objects
 * that descend from one original object at the same positions: each change is measured
 * before and after at the positions before it (a new vertex that is a copy at its source's
 * position, topology_t.vnew_src), so elastic motion does not enter and the closing surfaces'
 * mirror pairs cancel to round-off (--topology-tol, default CS_VERIFY_TOPOLOGY_TOL). With
 * --volume-tol R, it also compares their volume with the previous checked frame's, within R
 * (that includes the elastic motion of a frame).
 *
 * Exit: 0 ok; 1 verify failures, export failure or frame not in the log; 2 usage error or a
 * log that is unreadable, foreign, corrupt, truncated or holds no complete snapshot.
 */
#include <errno.h>
#include <inttypes.h>
#include <limits.h>
#include <math.h>
#include <lcm/lcm.h>
#include <poll.h>
#include <regex.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include "client_util.h"
#include "cubesim_delta_t.h"
#include "cubesim_pose_t.h"
#include "cubesim_snapshot_t.h"
#include "cubesim_topology_t.h"
#include "mesh.h"
#include "surface_state.h"
#include "watertight.h"

/*
 * Relative tolerance on the volume that the topology changes of one frame move, over an
 * original object and its pieces, measured at unchanged positions (see --verify). Where §3.2
 * closes a crack, the closing triangles come in mirror pairs over copies (vnew_src) and new
 * points sent at the same float32 position, and the sum cancels to round-off (measured:
 * 5e-16 in tests/it/daemon_fracture.sh, 2e-16 in clients_topology.sh, which pass
 * --topology-tol 1e-9). Where the engine falls back (a fan over a loop without a twin on the
 * other side, a piece given the boundary of its cubes; README "Fracture"), a change moves
 * real volume: up to 6.8e-4 of the object's in scenes/fracture.json. The default leaves room
 * for that; elastic motion, which the frame-to-frame check (--volume-tol) had to allow for
 * (up to 2 % per step), does not enter.
 */
#define CS_VERIFY_TOPOLOGY_TOL 5e-3 /* default of --topology-tol */

static volatile sig_atomic_t stop_flag;

static void on_signal(int sig)
{
    stop_flag = sig;
}

typedef struct replay_opts {
    const char *log_path, *url, *regex, *export_path;
    double speed, start;
    int loop, paused, verify, quiet;
    int64_t frame; /* -1: last */
    double volume_tol; /* relative, >= 0; < 0: no frame-to-frame check */
    double topology_tol; /* relative, >= 0 */
} replay_opts;

static void usage(FILE *f)
{
    fprintf(f,
            "usage: cubesim-replay LOG [--speed X] [--loop] [--start S] [--channels REGEX]\n"
            "                          [--lcm URL] [--paused] [--quiet]\n"
            "       cubesim-replay LOG --export FILE [--frame N]\n"
            "       cubesim-replay LOG --verify [--topology-tol R] [--volume-tol R]\n"
            "keys while playing (stdin a terminal or pipe): p pause/resume, s step, q quit\n");
}

/* ------------------------------------------------------------------ rebuild */

typedef struct rebuild {
    cs_surface_state st;
    int64_t frame_limit;       /* apply only messages with frame <= this (-1: all) */
    int64_t bad_messages;      /* undecodable or rejected */
    char first_bad[300];
    int64_t last_frame_seen;   /* highest frame of the final session/epoch in the log */
    int64_t last_session;
    int32_t last_epoch;
    int have_last;
} rebuild;

static void note_bad(rebuild *rb, int64_t i, const char *what)
{
    if (!rb->bad_messages++)
        snprintf(rb->first_bad, sizeof rb->first_bad, "event %" PRId64 ": %.200s", i, what);
}

static void note_frame(rebuild *rb, const cubesim_header_t *h)
{
    if (!rb->have_last || h->session_id != rb->last_session || h->epoch != rb->last_epoch) {
        rb->have_last = 1;
        rb->last_session = h->session_id;
        rb->last_epoch = h->epoch;
        rb->last_frame_seen = h->frame;
    } else if (h->frame > rb->last_frame_seen) {
        rb->last_frame_seen = h->frame;
    }
}

static cs_ss_header ss_header(const cubesim_header_t *h)
{
    cs_ss_header s = {h->session_id, h->epoch, h->frame, h->seq, h->sim_time};
    return s;
}

/* Feed event i to the state. Returns 1 if the state changed, 0 if not, -1 on read error. */
static int rebuild_event(rebuild *rb, cs_log *log, int64_t i, char *err, size_t errlen)
{
    const char *ch = log->channels[log->ev[i].channel];
    int is_snap = !strcmp(ch, CS_CH_SNAPSHOT), is_delta = !strcmp(ch, CS_CH_DELTA);
    int is_topo = !strcmp(ch, CS_CH_TOPOLOGY), is_pose = !strcmp(ch, CS_CH_POSE);
    if (!is_snap && !is_delta && !is_topo && !is_pose)
        return 0;
    const uint8_t *data;
    if (cs_log_read(log, i, &data, err, errlen))
        return -1;
    char msg[300];
    int changed = 0;
    if (is_snap) {
        cubesim_snapshot_t s;
        if (cubesim_snapshot_t_decode(data, 0, log->ev[i].datalen, &s) < 0) {
            note_bad(rb, i, "CUBESIM_SNAPSHOT message of another type (fingerprint mismatch)");
            return 0;
        }
        note_frame(rb, &s.header);
        if (rb->frame_limit < 0 || s.header.frame <= rb->frame_limit) {
            cs_ss_chunk c = {ss_header(&s.header), s.snapshot_id, s.chunk, s.n_chunks,
                             s.n_objects, s.object_id, s.object_name, s.model,
                             s.topology_version, s.n_vertices_total, s.n_triangles_total,
                             s.vertex_offset, s.n_coords, s.xyz, s.triangle_offset,
                             s.n_indices, s.indices};
            int r = cs_surface_state_apply_chunk(&rb->st, &c, msg, sizeof msg);
            if (r == CS_SS_REJECTED || r == CS_SS_NOMEM)
                note_bad(rb, i, msg);
            changed = r == CS_SS_APPLIED;
        }
        cubesim_snapshot_t_decode_cleanup(&s);
    } else if (is_pose) {
        cubesim_pose_t m;
        if (cubesim_pose_t_decode(data, 0, log->ev[i].datalen, &m) < 0) {
            note_bad(rb, i, "CUBESIM_POSE message of another type (fingerprint mismatch)");
            return 0;
        }
        note_frame(rb, &m.header);
        cs_ss_pose p = {ss_header(&m.header), m.object_id, m.topology_version,
                        m.n_vertices_total, m.reference,
                        {m.position[0], m.position[1], m.position[2]},
                        {m.orientation[0], m.orientation[1], m.orientation[2], m.orientation[3]}};
        if (rb->frame_limit < 0 || m.header.frame <= rb->frame_limit) {
            int r = cs_surface_state_apply_pose(&rb->st, &p, msg, sizeof msg);
            if (r == CS_SS_REJECTED || r == CS_SS_NOMEM)
                note_bad(rb, i, msg);
            changed = r == CS_SS_APPLIED;
        } else {
            cs_surface_state_note_pose_seq(&rb->st, &p.header);
        }
        cubesim_pose_t_decode_cleanup(&m);
    } else if (is_topo) {
        cubesim_topology_t m;
        if (cubesim_topology_t_decode(data, 0, log->ev[i].datalen, &m) < 0) {
            note_bad(rb, i, "CUBESIM_TOPOLOGY message of another type (fingerprint mismatch)");
            return 0;
        }
        note_frame(rb, &m.header);
        cs_ss_topo t = {ss_header(&m.header), m.change_id, m.chunk, m.n_chunks, m.object_id,
                        m.parent_id, m.name, m.model, m.from_version, m.to_version,
                        m.n_vertices_total, m.n_triangles_total, m.total_vremove, m.total_vnew,
                        m.total_tremove, m.total_tset, m.total_tnew, m.vremove_offset,
                        m.n_vremove, m.vremove, m.vnew_offset, m.n_vnew_coords, m.vnew_xyz,
                        m.tremove_offset, m.n_tremove, m.tremove, m.tset_offset, m.n_tset,
                        m.tset_index, m.n_tset_indices, m.tset_tri, m.tnew_offset,
                        m.n_tnew_indices, m.tnew, m.n_vnew_src, m.vnew_src};
        if (rb->frame_limit < 0 || m.header.frame <= rb->frame_limit) {
            int r = cs_surface_state_apply_topology(&rb->st, &t, msg, sizeof msg);
            if (r == CS_SS_REJECTED || r == CS_SS_NOMEM)
                note_bad(rb, i, msg);
            changed = r == CS_SS_APPLIED;
        } else {
            cs_surface_state_note_topology_seq(&rb->st, &t.header);
        }
        cubesim_topology_t_decode_cleanup(&m);
    } else {
        cubesim_delta_t d;
        if (cubesim_delta_t_decode(data, 0, log->ev[i].datalen, &d) < 0) {
            note_bad(rb, i, "CUBESIM_DELTA message of another type (fingerprint mismatch)");
            return 0;
        }
        note_frame(rb, &d.header);
        cs_ss_delta c = {ss_header(&d.header), d.object_id, d.topology_version, d.chunk,
                         d.n_chunks, d.n_vertices_total, d.n, d.index, d.n_coords, d.xyz};
        if (rb->frame_limit < 0 || d.header.frame <= rb->frame_limit) {
            int r = cs_surface_state_apply_delta(&rb->st, &c, msg, sizeof msg);
            if (r == CS_SS_REJECTED)
                note_bad(rb, i, msg);
            changed = r == CS_SS_APPLIED;
        } else {
            cs_surface_state_note_delta_seq(&rb->st, &c.header);
        }
        cubesim_delta_t_decode_cleanup(&d);
    }
    return changed;
}

/* Is the next state-changing event of another frame (or is there none)? */
static int frame_ends_at(cs_log *log, int64_t i, int64_t frame, char *err, size_t errlen)
{
    for (int64_t j = i + 1; j < log->n; j++) {
        const char *ch = log->channels[log->ev[j].channel];
        if (strcmp(ch, CS_CH_SNAPSHOT) && strcmp(ch, CS_CH_DELTA) && strcmp(ch, CS_CH_TOPOLOGY) &&
            strcmp(ch, CS_CH_POSE))
            continue;
        const uint8_t *data;
        if (cs_log_read(log, j, &data, err, errlen))
            return 1;
        cubesim_header_t h;
        if (!cs_msg_header(data, log->ev[j].datalen, &h))
            continue;
        return h.frame != frame;
    }
    return 1;
}

/* What --verify remembers of the previous checked frame: per object its id, topology
 * version and enclosed volume. */
typedef struct verify_ctx {
    int64_t session_id;
    int32_t epoch;
    int64_t topology_applied;  /* st.topology_applied at that frame */
    int n, cap;
    int32_t *id, *version;
    double *volume;
    int have;
} verify_ctx;

static void verify_ctx_free(verify_ctx *v)
{
    free(v->id);
    free(v->version);
    free(v->volume);
    memset(v, 0, sizeof *v);
}

/* The original object a piece descends from: its parent chain within the state. */
static int32_t root_of(const cs_surface_state *st, const cs_ss_object *o)
{
    int32_t id = o->id;
    for (int guard = 0; o && o->parent_id > 0 && guard <= st->n_objects; guard++) {
        const cs_ss_object *p = cs_surface_state_find(st, o->parent_id);
        if (!p)
            return o->parent_id;
        id = p->id;
        o = p;
    }
    return id;
}

static int prev_index(const verify_ctx *v, int32_t id)
{
    for (int i = 0; i < v->n; i++)
        if (v->id[i] == id)
            return i;
    return -1;
}

/*
 * Check one frame: the objects descending from one original object (their parent chains; an
 * object without a parent is its own original) go to cs_check_pieces together, each a piece
 * that must be closed, oriented, non-degenerate and of positive volume. If topology changes
 * were applied to them since the last check, the volume they moved at unchanged positions
 * (the objects' ledgers, surface_state.h) must be within `topo_tol` of the volume they held
 * before, relative; *worst receives the largest such ratio seen. With vol_tol >= 0
 * (--volume-tol), if a change was applied since the previous checked frame (same session and
 * epoch), their total volume must also equal that frame's total of the same objects within
 * vol_tol. Clears the ledgers. Prints one line if the frame fails. Returns 1 if it failed, 0
 * if not, -1 out of memory.
 */
static int verify_frame(cs_surface_state *st, verify_ctx *v, double vol_tol, double topo_tol,
                        double *worst)
{
    int n = st->n_objects, nprob = 0;
    char first[512] = "";
    double *vol = calloc((size_t)n + 1, sizeof *vol);
    int32_t *root = calloc((size_t)n + 1, sizeof *root);
    uint8_t *done = calloc((size_t)n + 1, 1);
    cs_piece_view *pv = calloc((size_t)n + 1, sizeof *pv);
    double **verts = calloc((size_t)n + 1, sizeof *verts);
    int rc = -1;
    if (!vol || !root || !done || !pv || !verts)
        goto out;
    for (int k = 0; k < n; k++) {
        const cs_ss_object *o = &st->objects[k];
        if (!(verts[k] = cs_ss_object_vertices_double(o)))
            goto out;
        root[k] = root_of(st, o);
        vol[k] = cs_mesh_volume(verts[k], o->tris, o->nt);
    }
    int fractured = vol_tol >= 0 && v->have && v->session_id == st->session_id &&
                    v->epoch == st->epoch && st->topology_applied > v->topology_applied;
    for (int k = 0; k < n; k++) {
        if (done[k])
            continue;
        double before = 0, dv = 0, now = 0;
        int np = 0, changed = 0, in_prev = 0, topo = 0;
        for (int j = k; j < n; j++) {
            if (root[j] != root[k])
                continue;
            const cs_ss_object *o = &st->objects[j];
            done[j] = 1;
            pv[np++] = (cs_piece_view){o->name, verts[j], o->nv, o->tris, o->nt};
            now += vol[j];
            if (o->topo_changed) {
                topo = 1;
                dv += o->topo_dv;
            }
            int p = prev_index(v, o->id);
            if (p < 0 || v->version[p] != o->topology_version)
                changed = 1;
            if (p >= 0) {
                before += v->volume[p];
                in_prev = 1;
            }
        }
        double expected = fractured && changed && in_prev ? before : NAN;
        char err[400] = "";
        int ok = cs_check_pieces(pv, np, expected, vol_tol, NULL, err, sizeof err);
        if (ok && topo) {
            /* relative to what they held before the changes (at the positions then; a
             * delta applied after a change in the same frame moves `now` a little) */
            const double v0 = now - dv, rel = fabs(dv) / fmax(fabs(v0), 1e-300);
            if (rel > *worst)
                *worst = rel;
            if (!(rel <= topo_tol)) {
                ok = 0;
                snprintf(err, sizeof err, "topology changes moved %.9g m^3 at unchanged "
                         "positions: the pieces hold %.9g m^3, expected %.9g m^3 (relative "
                         "error %.3g > %g)", dv, v0 + dv, v0, rel, topo_tol);
            }
        }
        if (!ok && !nprob++) {
            const cs_ss_object *r = cs_surface_state_find(st, root[k]);
            snprintf(first, sizeof first, "object %" PRId32 " '%s'%s: %s", root[k],
                     r ? r->name : "?", np > 1 ? " and its pieces" : "", err);
        }
    }
    /* Remember this frame. */
    if (n > v->cap) {
        int32_t *a = realloc(v->id, (size_t)n * sizeof *a);
        if (a)
            v->id = a;
        int32_t *b = realloc(v->version, (size_t)n * sizeof *b);
        if (b)
            v->version = b;
        double *c = realloc(v->volume, (size_t)n * sizeof *c);
        if (c)
            v->volume = c;
        if (!a || !b || !c)
            goto out;
        v->cap = n;
    }
    for (int k = 0; k < n; k++) {
        v->id[k] = st->objects[k].id;
        v->version[k] = st->objects[k].topology_version;
        v->volume[k] = vol[k];
    }
    cs_surface_state_clear_volume_ledger(st);
    v->n = n;
    v->have = 1;
    v->session_id = st->session_id;
    v->epoch = st->epoch;
    v->topology_applied = st->topology_applied;
    if (nprob)
        printf("frame %" PRId64 ": %s%s\n", st->frame, first,
               nprob > 1 ? " (and more problems in this frame)" : "");
    rc = nprob ? 1 : 0;
out:
    if (rc < 0)
        fprintf(stderr, "cubesim-replay: out of memory\n");
    for (int k = 0; verts && k < n; k++)
        free(verts[k]);
    free(verts);
    free(pv);
    free(done);
    free(root);
    free(vol);
    return rc;
}

static int run_rebuild(const replay_opts *o, cs_log *log)
{
    rebuild rb;
    memset(&rb, 0, sizeof rb);
    cs_surface_state_init(&rb.st);
    rb.frame_limit = o->verify ? -1 : o->frame;
    char err[512];
    int64_t frames_checked = 0, failures = 0, snapshots = 0;
    verify_ctx vc;
    memset(&vc, 0, sizeof vc);
    rb.st.track_volume = o->verify;
    double worst = 0;
    int dirty = 0;
    int status = 0;
    for (int64_t i = 0; i < log->n; i++) {
        int r = rebuild_event(&rb, log, i, err, sizeof err);
        if (r < 0) {
            fprintf(stderr, "cubesim-replay: %s: %s\n", o->log_path, err);
            status = 2;
            goto out;
        }
        if (r > 0 && !strcmp(log->channels[log->ev[i].channel], CS_CH_SNAPSHOT))
            snapshots++;
        /* A frame is checked once its last message went by, if any of its messages changed
         * the surfaces (the last one may have been ignored). */
        if (r > 0)
            dirty = 1;
        if (o->verify && rb.st.valid && dirty &&
            frame_ends_at(log, i, rb.st.frame, err, sizeof err)) {
            dirty = 0;
            frames_checked++;
            int vr = verify_frame(&rb.st, &vc, o->volume_tol, o->topology_tol, &worst);
            if (vr < 0) {
                status = 2;
                goto out;
            }
            failures += vr;
        }
    }
    if (rb.bad_messages)
        fprintf(stderr, "cubesim-replay: warning: %" PRId64 " bad messages skipped (first: %s)\n",
                rb.bad_messages, rb.first_bad);
    if (!rb.st.valid) {
        if (!rb.have_last)
            fprintf(stderr, "cubesim-replay: %s: no cubesim snapshot or delta in the log "
                            "(%" PRId64 " events on %d channels)\n", o->log_path, log->n,
                    log->n_channels);
        else
            fprintf(stderr, "cubesim-replay: %s: no complete snapshot%s in the log: cannot rebuild "
                            "the surfaces\n", o->log_path,
                    o->frame >= 0 ? " at or before that frame" : "");
        status = 2;
        goto out;
    }
    if (rb.st.stale)
        fprintf(stderr, "cubesim-replay: warning: the surfaces went stale after the last snapshot "
                        "(messages lost, or a delta or topology change for a topology not held; "
                        "lost in the whole log: %" PRId64 " deltas, %" PRId64 " topology messages, "
                        "%" PRId64 " incomplete topology changes): they may lag the daemon's\n",
                rb.st.deltas_lost, rb.st.topology_lost, rb.st.topology_incomplete);
    if (o->verify) {
        char ftf[64] = "";
        if (o->volume_tol >= 0)
            snprintf(ftf, sizeof ftf, "; frame to frame: tolerance %g", o->volume_tol);
        printf("verify: %" PRId64 " frames checked, %" PRId64 " failed (%" PRId64
               " topology changes applied; volume across them at unchanged positions: largest "
               "relative change %.3g, tolerance %g%s)\n", frames_checked, failures,
               rb.st.topology_applied, worst, o->topology_tol, ftf);
        status = failures ? 1 : 0;
        goto out;
    }
    if (o->frame >= 0 && o->frame > rb.last_frame_seen) {
        fprintf(stderr, "cubesim-replay: %s: frame %" PRId64 " is not in the log (its last "
                        "frame is %" PRId64 ")\n", o->log_path, o->frame, rb.last_frame_seen);
        status = 1;
        goto out;
    }
    cs_mesh *pieces;
    char **names;
    int n;
    if (cs_surface_state_to_meshes(&rb.st, &pieces, &names, &n, err, sizeof err)) {
        fprintf(stderr, "cubesim-replay: %s\n", err);
        status = 1;
        goto out;
    }
    if (cs_mesh_export(o->export_path, pieces, (const char *const *)names, n, err, sizeof err)) {
        fprintf(stderr, "cubesim-replay: %s\n", err);
        status = 1;
    } else if (!o->quiet) {
        printf("exported frame %" PRId64 " (t = %.6g s, epoch %" PRId32 ", %d objects) to %s\n",
               rb.st.frame, rb.st.sim_time, rb.st.epoch, n, o->export_path);
        for (int k = 0; k < rb.st.n_objects; k++)
            printf("  object %" PRId32 " '%s': %d vertices, %d triangles, hash %016" PRIx64 "\n",
                   rb.st.objects[k].id, rb.st.objects[k].name, rb.st.objects[k].nv,
                   rb.st.objects[k].nt, cs_ss_object_hash(&rb.st.objects[k]));
    }
    cs_surface_state_meshes_free(pieces, names, n);
out:
    verify_ctx_free(&vc);
    cs_surface_state_free(&rb.st);
    return status;
}

/* ------------------------------------------------------------------ playback */

static struct termios saved_tio;
static int tio_saved;

static void restore_tty(void)
{
    if (tio_saved)
        tcsetattr(STDIN_FILENO, TCSANOW, &saved_tio);
    tio_saved = 0;
}

/* Single keys from a terminal; a pipe is read as it comes. Returns 1 if stdin is usable. */
static int setup_stdin(void)
{
    struct stat sb;
    if (isatty(STDIN_FILENO)) {
        if (tcgetattr(STDIN_FILENO, &saved_tio) == 0) {
            struct termios t = saved_tio;
            t.c_lflag &= (tcflag_t) ~(ICANON | ECHO);
            t.c_cc[VMIN] = 1;
            t.c_cc[VTIME] = 0;
            if (tcsetattr(STDIN_FILENO, TCSANOW, &t) == 0) {
                tio_saved = 1;
                atexit(restore_tty);
            }
        }
        return 1;
    }
    return fstat(STDIN_FILENO, &sb) == 0 && S_ISFIFO(sb.st_mode);
}

static double event_s(const cs_log *log, int64_t i)
{
    return (double)(log->ev[i].timestamp - log->ev[0].timestamp) * 1e-6;
}

static int run_playback(const replay_opts *o, cs_log *log)
{
    regex_t re;
    int have_re = 0;
    if (o->regex) {
        size_t len = strlen(o->regex) + 8;
        char *anch = malloc(len);
        if (!anch) {
            fprintf(stderr, "cubesim-replay: out of memory\n");
            return 2;
        }
        snprintf(anch, len, "^(%s)$", o->regex);
        int rc = regcomp(&re, anch, REG_EXTENDED | REG_NOSUB);
        free(anch);
        if (rc) {
            fprintf(stderr, "cubesim-replay: --channels: '%s' is not a valid regex\n", o->regex);
            return 2;
        }
        have_re = 1;
    }
    /* Which channels play, decided once per channel. */
    uint8_t *plays = calloc((size_t)log->n_channels + 1, 1);
    if (!plays) {
        if (have_re)
            regfree(&re);
        return 2;
    }
    for (int c = 0; c < log->n_channels; c++)
        plays[c] = !have_re || regexec(&re, log->channels[c], 0, NULL, 0) == 0;
    if (have_re)
        regfree(&re);

    int64_t first = 0;
    while (first < log->n && (event_s(log, first) < o->start || !plays[log->ev[first].channel]))
        first++;
    if (first >= log->n) {
        fprintf(stderr, "cubesim-replay: %s: no events to play%s\n", o->log_path,
                o->start > 0 ? " after --start" : " on the chosen channels");
        free(plays);
        return 1;
    }

    lcm_t *lcm = lcm_create(o->url);
    if (!lcm) {
        fprintf(stderr, "cubesim-replay: cannot open the bus %s\n", o->url ? o->url : "(LCM default)");
        free(plays);
        return 2;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    int keys = setup_stdin();
    int paused = o->paused, step_one = 0, status = 0;
    int64_t i = first, published = 0, loops = 0;
    double anchor_wall = cs_mono_s(), anchor_log = event_s(log, i);
    char err[512];
    if (paused && !o->quiet)
        fprintf(stderr, "paused at event %" PRId64 " (t = %.3f s): p resume, s step, q quit\n", i,
                event_s(log, i));

    while (!stop_flag) {
        if (i >= log->n) {
            if (!o->loop)
                break;
            loops++;
            i = first;
            anchor_wall = cs_mono_s();
            anchor_log = event_s(log, i);
        }
        if (!plays[log->ev[i].channel]) {
            i++;
            continue;
        }
        double wait_ms = -1; /* paused: until a key */
        if (!paused) {
            double due = o->speed > 0 ? anchor_wall + (event_s(log, i) - anchor_log) / o->speed
                                      : 0;
            double now = cs_mono_s();
            if (o->speed > 0 && event_s(log, i) < anchor_log) { /* time went backwards */
                anchor_wall = now;
                anchor_log = event_s(log, i);
                due = now;
            }
            wait_ms = due > now ? (due - now) * 1000 : 0;
        }
        if (paused && step_one) {
            wait_ms = 0;
        } else if (wait_ms != 0 || keys) {
            struct pollfd pfd = {STDIN_FILENO, POLLIN, 0};
            int ms = wait_ms < 0 ? 200 : (int)(wait_ms < 200 ? wait_ms : 200);
            int r = poll(&pfd, keys ? 1 : 0, ms);
            if (r > 0 && (pfd.revents & (POLLIN | POLLHUP))) {
                char buf[64];
                ssize_t got = read(STDIN_FILENO, buf, sizeof buf);
                if (got <= 0) {
                    keys = 0; /* EOF: no more commands, keep playing */
                    if (paused && !o->quiet)
                        fprintf(stderr, "stdin closed while paused: q or SIGINT to quit\n");
                }
                for (ssize_t k = 0; k < got; k++) {
                    if (buf[k] == 'q') {
                        stop_flag = 1;
                    } else if (buf[k] == 'p') {
                        paused = !paused;
                        if (!paused) {
                            anchor_wall = cs_mono_s();
                            anchor_log = event_s(log, i < log->n ? i : first);
                        }
                        if (!o->quiet)
                            fprintf(stderr, "%s at event %" PRId64 " (t = %.3f s)\n",
                                    paused ? "paused" : "resumed", i,
                                    event_s(log, i < log->n ? i : first));
                    } else if (buf[k] == 's' && paused) {
                        step_one++;
                    }
                }
                continue;
            }
            if (paused || wait_ms > 200)
                continue;
            if (wait_ms > 0 && cs_mono_s() < anchor_wall + (event_s(log, i) - anchor_log) / o->speed)
                continue;
        }
        if (stop_flag)
            break;
        const uint8_t *data;
        if (cs_log_read(log, i, &data, err, sizeof err)) {
            fprintf(stderr, "cubesim-replay: %s: %s\n", o->log_path, err);
            status = 2;
            break;
        }
        if (lcm_publish(lcm, log->channels[log->ev[i].channel], data,
                        (unsigned)log->ev[i].datalen) != 0) {
            fprintf(stderr, "cubesim-replay: publishing event %" PRId64 " failed\n", i);
            status = 2;
            break;
        }
        published++;
        if (paused && step_one) {
            step_one--;
            if (!o->quiet)
                fprintf(stderr, "stepped: event %" PRId64 " on %s (t = %.3f s)\n", i,
                        log->channels[log->ev[i].channel], event_s(log, i));
        }
        i++;
    }
    restore_tty();
    if (!o->quiet)
        printf("cubesim-replay: published %" PRId64 " messages%s\n", published,
               loops ? " (looped)" : "");
    lcm_destroy(lcm);
    free(plays);
    return status;
}

int main(int argc, char **argv)
{
    replay_opts o = {0};
    o.speed = 1.0;
    o.frame = -1;
    o.volume_tol = -1;
    o.topology_tol = CS_VERIFY_TOPOLOGY_TOL;
    int have_frame = 0, have_tol = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        int has_val = i + 1 < argc;
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(a, "--speed") && has_val) {
            if (cs_parse_double(argv[++i], &o.speed) || o.speed < 0) {
                fprintf(stderr, "cubesim-replay: --speed: '%s' is not a number >= 0\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(a, "--start") && has_val) {
            if (cs_parse_double(argv[++i], &o.start) || o.start < 0) {
                fprintf(stderr, "cubesim-replay: --start: '%s' is not a time >= 0\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(a, "--frame") && has_val) {
            long f;
            if (cs_parse_int(argv[++i], 0, LONG_MAX, &f)) {
                fprintf(stderr, "cubesim-replay: --frame: '%s' is not a frame number >= 0\n",
                        argv[i]);
                return 2;
            }
            o.frame = f;
            have_frame = 1;
        } else if (!strcmp(a, "--volume-tol") && has_val) {
            if (cs_parse_double(argv[++i], &o.volume_tol) || o.volume_tol < 0) {
                fprintf(stderr, "cubesim-replay: --volume-tol: '%s' is not a number >= 0\n",
                        argv[i]);
                return 2;
            }
            have_tol = 1;
        } else if (!strcmp(a, "--topology-tol") && has_val) {
            if (cs_parse_double(argv[++i], &o.topology_tol) || o.topology_tol < 0) {
                fprintf(stderr, "cubesim-replay: --topology-tol: '%s' is not a number >= 0\n",
                        argv[i]);
                return 2;
            }
            have_tol = 1;
        } else if (!strcmp(a, "--channels") && has_val) {
            o.regex = argv[++i];
        } else if (!strcmp(a, "--lcm") && has_val) {
            o.url = argv[++i];
        } else if (!strcmp(a, "--export") && has_val) {
            o.export_path = argv[++i];
        } else if (!strcmp(a, "--loop")) {
            o.loop = 1;
        } else if (!strcmp(a, "--paused")) {
            o.paused = 1;
        } else if (!strcmp(a, "--verify")) {
            o.verify = 1;
        } else if (!strcmp(a, "--quiet")) {
            o.quiet = 1;
        } else if (a[0] == '-' && a[1] == '-') {
            fprintf(stderr, "cubesim-replay: unknown option or missing value: %s\n", a);
            return 2;
        } else if (!o.log_path) {
            o.log_path = a;
        } else {
            fprintf(stderr, "cubesim-replay: unexpected argument '%s'\n", a);
            return 2;
        }
    }
    if (!o.log_path) {
        usage(stderr);
        return 2;
    }
    if (o.export_path && o.verify) {
        fprintf(stderr, "cubesim-replay: --export and --verify are separate modes\n");
        return 2;
    }
    if (have_tol && !o.verify) {
        fprintf(stderr, "cubesim-replay: --volume-tol and --topology-tol go with --verify\n");
        return 2;
    }
    if (have_frame && !o.export_path) {
        fprintf(stderr, "cubesim-replay: --frame goes with --export\n");
        return 2;
    }
    cs_log log;
    char err[512];
    if (cs_log_open(o.log_path, &log, err, sizeof err)) {
        fprintf(stderr, "cubesim-replay: %s\n", err);
        return 2;
    }
    int status = (o.export_path || o.verify) ? run_rebuild(&o, &log) : run_playback(&o, &log);
    cs_log_close(&log);
    return status;
}
