/*
 * tests/it/tools/bus.c — cs_it_bus: the integration tests' own minimal LCM client, so the
 * daemon's tests do not depend on the client programs. It sends well-formed, malformed and
 * foreign messages and prints what the daemon answers, one parseable line each.
 *
 *   cs_it_bus [--lcm URL] [--timeout S] force [--id N] [--name S] [--kind K] [--point x,y,z]
 *             [--force x,y,z] [--target x,y,z] [--stiffness K] [--duration S] [--cid N]
 *   cs_it_bus ... command NAME [--count N] [--arg S] [--cid N]
 *       publish, wait for the matching ack, print "ack ok=0|1 request=R message=M"
 *       (force --burst N: publish N forces back to back, command ids cid .. cid+N-1, wait for
 *       their acks, print "burst sent=N acked=A ok=K": every one must get its ack)
 *   cs_it_bus ... foreign CHANNEL            publish a cubesim.ack_t (a foreign type) there
 *   cs_it_bus ... truncated CHANNEL          publish half of an encoded force_t/command_t raw
 *   cs_it_bus ... badlength CHANNEL          ... whole, with its first string's length = -16
 *   cs_it_bus ... unterminated CHANNEL       ... whole, with that string's '\0' overwritten
 *       (these four take [--repeat N]: publish N times back to back)
 *   cs_it_bus ... status [--count N]         print the N-th status received (default 1):
 *       "status session=S epoch=E frame=F seq=Q paused=P objects=N" and per object
 *       "object id=I name=NAME hash=H sleeping=Z"
 *   cs_it_bus ... follow [K]                 keep object 0's surface from snapshot + deltas
 *       and compare it with each of the next K complete snapshots (key frames), printing
 *       "follow compared=K deltas=D max_error=E bad=B max_chunks=C vertices=V"
 *   cs_it_bus ... snapshot                   wait for one complete snapshot, print
 *       "snapshot id=I objects=N vertices=V triangles=T chunks=C"
 * Exit status: 0 ok, 2 usage, 3 timeout (nothing matching arrived), 1 LCM failure.
 */
#include <math.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <lcm/lcm.h>

#include "tool_util.h"
#include "cubesim_ack_t.h"
#include "cubesim_command_t.h"
#include "cubesim_delta_t.h"
#include "cubesim_force_t.h"
#include "cubesim_snapshot_t.h"
#include "cubesim_status_t.h"

typedef struct state {
    int64_t client_id, command_id;
    int got_ack;
    int burst, burst_acked, burst_ok; /* force --burst: acks of command ids id .. id+burst-1 */
    unsigned char *burst_seen;
    int status_left;
    int snap_id, snap_chunks, snap_seen, snap_objects, snap_v, snap_t, snap_done;
    unsigned char seen[4096];
    /* follow: one object's float copy, kept from snapshot + deltas */
    int f_have, f_nv, f_topo, f_snap_building, f_compared, f_want, f_deltas, f_bad, f_chunks;
    int32_t f_obj;
    float *f_xyz, *f_snap;
    double f_maxerr;
} state;

static void on_ack(const lcm_recv_buf_t *rb, const char *ch, const cubesim_ack_t *a, void *u)
{
    state *st = u;
    if (st->burst > 0) {
        const int64_t k = a->command_id - st->command_id;
        if (a->client_id == st->client_id && k >= 0 && k < st->burst && !st->burst_seen[k]) {
            st->burst_seen[k] = 1;
            st->burst_acked++;
            st->burst_ok += a->ok != 0;
        }
        return;
    }
    if (a->client_id != st->client_id || a->command_id != st->command_id)
        return;
    printf("ack ok=%d request=%s message=%s\n", a->ok, a->request, a->message);
    st->got_ack = 1;
}

static void on_status(const lcm_recv_buf_t *rb, const char *ch, const cubesim_status_t *s,
                      void *u)
{
    state *st = u;
    if (st->status_left <= 0 || --st->status_left > 0)
        return;
    printf("status session=%lld epoch=%d frame=%lld seq=%lld paused=%d objects=%d\n",
           (long long)s->header.session_id, s->header.epoch, (long long)s->header.frame,
           (long long)s->header.seq, s->paused, s->n_objects);
    for (int i = 0; i < s->n_objects; i++)
        printf("object id=%d name=%s hash=%016llx sleeping=%d\n", s->object_id[i],
               s->object_name[i], (unsigned long long)s->state_hash[i], s->sleeping[i]);
}

static void on_snapshot(const lcm_recv_buf_t *rb, const char *ch, const cubesim_snapshot_t *s,
                        void *u)
{
    state *st = u;
    if (st->snap_done)
        return;
    if (s->snapshot_id != st->snap_id) {
        if (s->chunk != 0)
            return; /* join at the start of a snapshot */
        memset(st->seen, 0, sizeof st->seen);
        st->snap_id = s->snapshot_id;
        st->snap_chunks = s->n_chunks;
        st->snap_seen = st->snap_v = st->snap_t = 0;
        st->snap_objects = s->n_objects;
    }
    if (s->chunk < 0 || s->chunk >= (int)sizeof st->seen || st->seen[s->chunk])
        return;
    st->seen[s->chunk] = 1;
    st->snap_seen++;
    st->snap_v += s->n_coords / 3;
    st->snap_t += s->n_indices / 3;
    if (st->snap_seen == st->snap_chunks) {
        printf("snapshot id=%d objects=%d vertices=%d triangles=%d chunks=%d\n", st->snap_id,
               st->snap_objects, st->snap_v, st->snap_t, st->snap_chunks);
        st->snap_done = 1;
    }
}

/*
 * follow: the first complete snapshot starts the copy (object 0 of it only); every later
 * complete snapshot (a key frame) is first compared with the copy built from deltas, then
 * adopted. With the daemon's FIFO ordering the copy must equal the snapshot up to the
 * publish_epsilon bound.
 */
static void f_on_snapshot(const lcm_recv_buf_t *rb, const char *ch, const cubesim_snapshot_t *s,
                          void *u)
{
    state *st = u;
    if (s->n_objects < 1 || (st->f_have && s->object_id != st->f_obj))
        return;
    if (s->snapshot_id != st->snap_id) {
        if (s->chunk != 0)
            return;
        memset(st->seen, 0, sizeof st->seen);
        st->snap_id = s->snapshot_id;
        st->snap_chunks = s->n_chunks;
        st->snap_seen = 0;
        st->snap_v = s->n_vertices_total;
        free(st->f_snap);
        st->f_snap = calloc((size_t)s->n_vertices_total * 3 + 3, sizeof(float));
        st->f_obj = s->object_id;
        st->f_topo = s->topology_version;
    }
    if (s->chunk < 0 || s->chunk >= (int)sizeof st->seen || st->seen[s->chunk] || !st->f_snap)
        return;
    st->seen[s->chunk] = 1;
    st->snap_seen++;
    if (s->n_coords > 0 && s->vertex_offset >= 0 &&
        s->vertex_offset * 3 + s->n_coords <= st->snap_v * 3)
        memcpy(st->f_snap + 3 * s->vertex_offset, s->xyz, (size_t)s->n_coords * sizeof(float));
    if (st->snap_seen != st->snap_chunks)
        return;
    if (st->f_have && st->f_nv == st->snap_v) {
        for (int i = 0; i < 3 * st->f_nv; i += 3) {
            double dx = st->f_xyz[i] - st->f_snap[i], dy = st->f_xyz[i + 1] - st->f_snap[i + 1],
                   dz = st->f_xyz[i + 2] - st->f_snap[i + 2];
            double e = sqrt(dx * dx + dy * dy + dz * dz);
            if (e > st->f_maxerr)
                st->f_maxerr = e;
        }
        st->f_compared++;
    } else if (st->f_have) {
        st->f_bad++;
    }
    if (s->n_chunks > st->f_chunks)
        st->f_chunks = s->n_chunks;
    free(st->f_xyz);
    st->f_xyz = st->f_snap;
    st->f_snap = NULL;
    st->f_nv = st->snap_v;
    st->f_have = 1;
    st->snap_id = -1;
}

static void f_on_delta(const lcm_recv_buf_t *rb, const char *ch, const cubesim_delta_t *d,
                       void *u)
{
    state *st = u;
    if (!st->f_have || d->object_id != st->f_obj)
        return;
    if (d->topology_version != st->f_topo || d->n_vertices_total != st->f_nv) {
        st->f_bad++;
        return;
    }
    for (int i = 0; i < d->n; i++) {
        if (d->index[i] < 0 || d->index[i] >= st->f_nv) {
            st->f_bad++;
            return;
        }
        memcpy(st->f_xyz + 3 * d->index[i], d->xyz + 3 * i, 3 * sizeof(float));
    }
    st->f_deltas++;
}

static int follow_done(const state *st) { return st->f_compared >= st->f_want; }

static int usage(void)
{
    fprintf(stderr, "usage: cs_it_bus [--lcm URL] [--timeout S] "
                    "force|command|foreign|truncated|status|snapshot ...\n");
    return 2;
}

/* Handle messages until done() or the deadline; returns 0 when done, 3 on timeout. */
static int wait_for(lcm_t *lcm, double timeout, int (*done)(const state *), const state *st)
{
    double end = now_s() + timeout;
    while (!done(st)) {
        double left = end - now_s();
        if (left <= 0)
            return 3;
        if (lcm_handle_timeout(lcm, (int)(left * 1000) + 1) < 0)
            return 1;
    }
    return 0;
}

static int ack_done(const state *st) { return st->got_ack; }
static int burst_done(const state *st) { return st->burst_acked >= st->burst; }
static int status_done(const state *st) { return st->status_left <= 0; }
static int snap_done(const state *st) { return st->snap_done; }

int main(int argc, char **argv)
{
    const char *url = NULL;
    double timeout = 5;
    int i = 1;
    for (; i < argc && strncmp(argv[i], "--", 2) == 0; i += 2) {
        if (i + 1 >= argc)
            return usage();
        if (strcmp(argv[i], "--lcm") == 0)
            url = argv[i + 1];
        else if (strcmp(argv[i], "--timeout") == 0)
            timeout = atof(argv[i + 1]);
        else
            return usage();
    }
    if (i >= argc)
        return usage();
    const char *verb = argv[i++];
    lcm_t *lcm = lcm_create(url);
    if (!lcm) {
        fprintf(stderr, "cs_it_bus: cannot open LCM\n");
        return 1;
    }
    state st;
    memset(&st, 0, sizeof st);
    st.client_id = getpid();
    st.command_id = 1;
    int rc = 0;

    if (strcmp(verb, "force") == 0 || strcmp(verb, "command") == 0) {
        cubesim_force_t f;
        memset(&f, 0, sizeof f);
        f.object_name = "";
        cubesim_command_t c;
        memset(&c, 0, sizeof c);
        c.command = strcmp(verb, "command") == 0 && i < argc ? argv[i++] : "";
        c.argument = "";
        c.count = 1;
        for (; i + 1 < argc; i += 2) {
            const char *k = argv[i], *v = argv[i + 1];
            int bad = 0;
            if (strcmp(k, "--id") == 0) f.object_id = atoi(v);
            else if (strcmp(k, "--name") == 0) f.object_name = (char *)v;
            else if (strcmp(k, "--kind") == 0) f.kind = (int8_t)atoi(v);
            else if (strcmp(k, "--point") == 0) bad = parse3(v, f.point);
            else if (strcmp(k, "--force") == 0) bad = parse3(v, f.force);
            else if (strcmp(k, "--target") == 0) bad = parse3(v, f.target);
            else if (strcmp(k, "--stiffness") == 0) f.stiffness = strtod(v, NULL);
            else if (strcmp(k, "--duration") == 0) f.duration = strtod(v, NULL);
            else if (strcmp(k, "--cid") == 0) st.command_id = atoll(v);
            else if (strcmp(k, "--count") == 0) c.count = atoi(v);
            else if (strcmp(k, "--arg") == 0) c.argument = (char *)v;
            else if (strcmp(k, "--burst") == 0) bad = (st.burst = atoi(v)) <= 0;
            else bad = 1;
            if (bad) {
                fprintf(stderr, "cs_it_bus: bad option %s %s\n", k, v);
                lcm_destroy(lcm);
                return 2;
            }
        }
        if (i < argc || (st.burst > 0 && verb[0] != 'f')) { /* --burst: forces only */
            lcm_destroy(lcm);
            return usage();
        }
        cubesim_ack_t_subscription_t *sub = cubesim_ack_t_subscribe(lcm, "CUBESIM_ACK", on_ack,
                                                                    &st);
        f.client_id = c.client_id = st.client_id;
        f.command_id = c.command_id = st.command_id;
        if (st.burst > 0 && verb[0] == 'f') {
            /* the acks of a burst come back as one: room for all of them in our queue */
            cubesim_ack_t_subscription_set_queue_capacity(sub, st.burst + 64);
            st.burst_seen = calloc((size_t)st.burst, 1);
            for (int k = 0; k < st.burst && !rc && st.burst_seen; k++) {
                f.command_id = st.command_id + k;
                rc = cubesim_force_t_publish(lcm, "CUBESIM_FORCE", &f) < 0;
            }
            if (!rc)
                rc = st.burst_seen ? wait_for(lcm, timeout, burst_done, &st) : 1;
            printf("burst sent=%d acked=%d ok=%d\n", st.burst, st.burst_acked, st.burst_ok);
            free(st.burst_seen);
            rc = rc == 3 ? 0 : rc; /* the count says what came back */
            cubesim_ack_t_unsubscribe(lcm, sub);
            lcm_destroy(lcm);
            return rc;
        }
        if (verb[0] == 'f')
            rc = cubesim_force_t_publish(lcm, "CUBESIM_FORCE", &f) < 0;
        else
            rc = cubesim_command_t_publish(lcm, "CUBESIM_COMMAND", &c) < 0;
        if (!rc)
            rc = wait_for(lcm, timeout, ack_done, &st);
        if (rc == 3)
            fprintf(stderr, "cs_it_bus: no ack for command %lld within %g s\n",
                    (long long)st.command_id, timeout);
        cubesim_ack_t_unsubscribe(lcm, sub);
    } else if ((strcmp(verb, "foreign") == 0 || strcmp(verb, "truncated") == 0 ||
                strcmp(verb, "badlength") == 0 || strcmp(verb, "unterminated") == 0) &&
               i < argc) {
        const char *ch = argv[i];
        int repeat = 1;
        if (i + 2 < argc && strcmp(argv[i + 1], "--repeat") == 0)
            repeat = atoi(argv[i + 2]);
        /* The first string's length prefix: force_t object_name, command_t command. */
        int str_at = strstr(ch, "COMMAND") ? 8 + 16 : 8 + 20;
        unsigned char buf[512];
        int n;
        if (verb[0] == 'f') {
            cubesim_ack_t a;
            memset(&a, 0, sizeof a);
            a.request = "foreign";
            a.message = "not for you";
            n = cubesim_ack_t_encode(buf, 0, sizeof buf, &a);
        } else if (strstr(ch, "COMMAND")) {
            cubesim_command_t c = {.client_id = 1, .command_id = 1, .command = "pause",
                                   .count = 1, .argument = "x"};
            n = cubesim_command_t_encode(buf, 0, sizeof buf, &c);
        } else {
            cubesim_force_t f;
            memset(&f, 0, sizeof f);
            f.object_name = "block";
            n = cubesim_force_t_encode(buf, 0, sizeof buf, &f);
        }
        if (n > 0 && verb[0] == 't')
            n /= 2;
        if (n > 0 && verb[0] == 'b') /* a length prefix of -16: lcm-gen would memcpy via NULL */
            buf[str_at] = buf[str_at + 1] = buf[str_at + 2] = 0xff, buf[str_at + 3] = 0xf0;
        if (n > 0 && verb[0] == 'u') { /* the string's '\0' overwritten */
            int len = (buf[str_at] << 24) | (buf[str_at + 1] << 16) | (buf[str_at + 2] << 8) |
                      buf[str_at + 3];
            buf[str_at + 4 + len - 1] = 'X';
        }
        for (int k = 0; k < repeat && !rc; k++)
            rc = n <= 0 || lcm_publish(lcm, ch, buf, (unsigned)n) < 0;
        if (!rc)
            printf("published %d bytes on %s (%d times)\n", n, ch, repeat);
    } else if (strcmp(verb, "status") == 0) {
        st.status_left = 1;
        if (i + 1 < argc && strcmp(argv[i], "--count") == 0)
            st.status_left = atoi(argv[i + 1]);
        cubesim_status_t_subscription_t *sub =
            cubesim_status_t_subscribe(lcm, "CUBESIM_STATUS", on_status, &st);
        rc = wait_for(lcm, timeout, status_done, &st);
        if (rc == 3)
            fprintf(stderr, "cs_it_bus: no status within %g s\n", timeout);
        cubesim_status_t_unsubscribe(lcm, sub);
    } else if (strcmp(verb, "follow") == 0) {
        st.f_want = i < argc ? atoi(argv[i]) : 3;
        st.snap_id = -1;
        cubesim_snapshot_t_subscription_t *s1 =
            cubesim_snapshot_t_subscribe(lcm, "CUBESIM_SNAPSHOT", f_on_snapshot, &st);
        cubesim_delta_t_subscription_t *s2 =
            cubesim_delta_t_subscribe(lcm, "CUBESIM_DELTA", f_on_delta, &st);
        cubesim_snapshot_t_subscription_set_queue_capacity(s1, 1000);
        cubesim_delta_t_subscription_set_queue_capacity(s2, 1000);
        rc = wait_for(lcm, timeout, follow_done, &st);
        printf("follow compared=%d deltas=%d max_error=%.9g bad=%d max_chunks=%d vertices=%d\n",
               st.f_compared, st.f_deltas, st.f_maxerr, st.f_bad, st.f_chunks, st.f_nv);
        cubesim_snapshot_t_unsubscribe(lcm, s1);
        cubesim_delta_t_unsubscribe(lcm, s2);
        free(st.f_xyz);
        free(st.f_snap);
    } else if (strcmp(verb, "snapshot") == 0) {
        cubesim_snapshot_t_subscription_t *sub =
            cubesim_snapshot_t_subscribe(lcm, "CUBESIM_SNAPSHOT", on_snapshot, &st);
        rc = wait_for(lcm, timeout, snap_done, &st);
        if (rc == 3)
            fprintf(stderr, "cs_it_bus: no complete snapshot within %g s\n", timeout);
        cubesim_snapshot_t_unsubscribe(lcm, sub);
    } else {
        rc = usage();
    }
    fflush(stdout);
    lcm_destroy(lcm);
    return rc;
}
