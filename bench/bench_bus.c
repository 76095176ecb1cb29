/*
 * bench/bench_bus.c — the bus throughput benchmark's two halves (issue 7 part 3: deltas of a
 * 100 000-vertex surface at 60 Hz to two clients on one host, with no lost message).
 *
 *   bench_bus mesh FILE.obj [--vertices N] [--radius R]
 *       write a closed, outward-oriented UV sphere of at least N vertices (default 100000;
 *       400 segments around, as many rings as needed) centred at the origin, radius R
 *       (default 0.5 m). Prints "mesh vertices=V triangles=T".
 *   bench_bus sub [--lcm URL] [--duration S] [--wait S] [--queue N]
 *       a client that keeps the daemon's surfaces (common/surface_state: snapshot + every
 *       delta, as a viewer would) for S wall seconds after its first delta (default 30; it
 *       gives up after --wait S, default 20, without one), then prints one line:
 *         sub frames=F complete=C incomplete=I first_frame=A last_frame=B delta_msgs=M
 *             lost=L bytes=BYTES wall_s=W rate_hz=R lat_ms_p50=.. lat_ms_p99=.. lat_ms_max=..
 *             cpu_s=.. cpu_pct=.. hash_checked=K hash_bad=X snapshots=S stale=Z
 *             daemon_rtf=.. daemon_step_ms=..
 *       frames: physics frames of which at least one delta chunk arrived; complete: of which
 *       all n_chunks arrived; lost: gaps in CUBESIM_DELTA's header.seq (messages); latency:
 *       LCM's receive time of a frame's last chunk minus header.utime (when the daemon made
 *       the frame); cpu: this process (both LCM threads), getrusage; hash_checked: frames at
 *       which a CUBESIM_STATUS was sent and the client's copy, when that frame was complete,
 *       was compared with the status's state_hash (hash_bad: differed). With
 *       publish_epsilon = 0 a complete copy equals the daemon's floats bit for bit.
 * Exit status: 0 ok, 1 LCM failure or no delta arrived, 2 usage.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include <lcm/lcm.h>

#include "client/client_util.h"
#include "cubesim_delta_t.h"
#include "cubesim_snapshot_t.h"
#include "cubesim_status_t.h"
#include "surface_state.h"

static double mono_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double cpu_s(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return (double)ru.ru_utime.tv_sec + 1e-6 * (double)ru.ru_utime.tv_usec +
           (double)ru.ru_stime.tv_sec + 1e-6 * (double)ru.ru_stime.tv_usec;
}

static int usage(void)
{
    fputs("usage: bench_bus mesh FILE.obj [--vertices N] [--radius R]\n"
          "       bench_bus sub [--lcm URL] [--duration S] [--wait S] [--queue N]\n",
          stderr);
    return 2;
}

/* ---------------------------------------------------------------- mesh */

static int write_sphere(const char *path, long want, double r)
{
    const int seg = 400;
    int rings = (int)((want - 2 + seg - 1) / seg);
    if (rings < 2)
        rings = 2;
    FILE *f = fopen(path, "w");
    if (!f) {
        fprintf(stderr, "bench_bus: cannot write '%s'\n", path);
        return 1;
    }
    const double pi = acos(-1.0);
    fprintf(f, "# UV sphere: %d rings x %d segments, radius %g\n", rings, seg, r);
    fprintf(f, "v 0 0 %.9g\n", r); /* vertex 1: north pole */
    for (int i = 1; i <= rings; i++) {
        double th = pi * i / (rings + 1);
        for (int j = 0; j < seg; j++) {
            double ph = 2 * pi * j / seg;
            fprintf(f, "v %.9g %.9g %.9g\n", r * sin(th) * cos(ph), r * sin(th) * sin(ph),
                    r * cos(th));
        }
    }
    long south = 2 + (long)rings * seg;
    fprintf(f, "v 0 0 %.9g\n", -r);
    /* ring i (1-based), segment j -> OBJ index; counter-clockwise seen from outside:
     * around +z the segments run counter-clockwise, so (pole, j, j+1) faces out at the top. */
#define V(i, j) (2 + (long)((i) - 1) * seg + ((j) % seg))
    long nt = 0;
    for (int j = 0; j < seg; j++, nt++)
        fprintf(f, "f 1 %ld %ld\n", V(1, j), V(1, j + 1));
    for (int i = 1; i < rings; i++)
        for (int j = 0; j < seg; j++, nt += 2) {
            fprintf(f, "f %ld %ld %ld\n", V(i, j), V(i + 1, j), V(i + 1, j + 1));
            fprintf(f, "f %ld %ld %ld\n", V(i, j), V(i + 1, j + 1), V(i, j + 1));
        }
    for (int j = 0; j < seg; j++, nt++)
        fprintf(f, "f %ld %ld %ld\n", south, V(rings, j + 1), V(rings, j));
#undef V
    if (fclose(f) != 0) {
        fprintf(stderr, "bench_bus: cannot write '%s'\n", path);
        return 1;
    }
    printf("mesh vertices=%ld triangles=%ld\n", south, nt);
    return 0;
}

/* ---------------------------------------------------------------- subscriber */

#define HASH_RING 64

typedef struct sub {
    cs_surface_state ss;
    double t_first, t_end, duration;
    int started, done;
    /* the frame being received */
    int64_t cur_frame;
    int cur_chunks, cur_n_chunks;
    int64_t cur_bytes;    /* of the frame being received */
    int64_t frames, complete, incomplete, first_frame, last_frame, delta_msgs, bytes;
    int64_t last_complete_frame;
    double *lat;          /* ms per complete frame */
    int64_t n_lat, cap_lat;
    double t_first_frame, t_last_frame;
    /* statuses: (frame, hash of object 0) */
    int64_t st_frame[HASH_RING];
    uint64_t st_hash[HASH_RING];
    int32_t st_obj[HASH_RING];
    int n_st, hash_checked, hash_bad;
    int64_t snapshots, stale_seen, rejected;
    double rtf, step_ms;
} sub;

static void close_frame(sub *s)
{
    if (s->cur_frame < 0)
        return;
    if (s->cur_chunks == s->cur_n_chunks)
        s->complete++;
    else
        s->incomplete++;
    s->cur_frame = -1;
}

static void check_hash(sub *s, int64_t frame)
{
    for (int i = 0; i < s->n_st && i < HASH_RING; i++) {
        if (s->st_frame[i] != frame)
            continue;
        const cs_ss_object *o = cs_surface_state_find(&s->ss, s->st_obj[i]);
        if (!o || !s->ss.valid)
            continue;
        s->hash_checked++;
        if (cs_ss_object_hash(o) != s->st_hash[i])
            s->hash_bad++;
        s->st_frame[i] = -1;
    }
}

static void on_delta(const lcm_recv_buf_t *rb, const char *ch, const cubesim_delta_t *d,
                     void *u)
{
    sub *s = u;
    double now = mono_s();
    if (!s->started) {
        s->started = 1;
        s->t_first = now;
        s->t_end = now + s->duration;
    }
    if (s->done)
        return;
    if (now >= s->t_end) {
        s->done = 1;
        return;
    }
    s->delta_msgs++;
    s->bytes += rb->data_size;
    cs_ss_delta x = {
        .header = { d->header.session_id, d->header.epoch, d->header.frame, d->header.seq,
                    d->header.sim_time },
        .object_id = d->object_id, .topology_version = d->topology_version,
        .chunk = d->chunk, .n_chunks = d->n_chunks, .n_vertices_total = d->n_vertices_total,
        .n = d->n, .index = d->index, .n_coords = d->n_coords, .xyz = d->xyz };
    char err[256];
    int r = cs_surface_state_apply_delta(&s->ss, &x, err, sizeof err);
    if (r == CS_SS_REJECTED)
        s->rejected++;
    if (d->header.frame != s->cur_frame) {
        close_frame(s);
        s->cur_frame = d->header.frame;
        s->cur_chunks = 0;
        s->cur_bytes = 0;
        s->cur_n_chunks = d->n_chunks;
        if (s->frames == 0) {
            s->first_frame = d->header.frame;
            s->t_first_frame = now;
        }
        s->frames++;
        s->last_frame = d->header.frame;
        s->t_last_frame = now;
    }
    s->cur_chunks++;
    s->cur_bytes += rb->data_size;
    if (s->cur_chunks == s->cur_n_chunks) {
        if (s->n_lat == s->cap_lat) {
            int64_t cap = s->cap_lat ? 2 * s->cap_lat : 4096;
            double *l = realloc(s->lat, (size_t)cap * sizeof *l);
            if (l) {
                s->lat = l;
                s->cap_lat = cap;
            }
        }
        if (s->n_lat < s->cap_lat)
            s->lat[s->n_lat++] = 1e-3 * (double)(rb->recv_utime - d->header.utime);
        s->last_complete_frame = d->header.frame;
        if (r == CS_SS_APPLIED)
            check_hash(s, d->header.frame);
    }
    if (s->ss.stale)
        s->stale_seen = 1;
}

static void on_snapshot(const lcm_recv_buf_t *rb, const char *ch, const cubesim_snapshot_t *m,
                        void *u)
{
    sub *s = u;
    if (s->done)
        return;
    cs_ss_chunk c = {
        .header = { m->header.session_id, m->header.epoch, m->header.frame, m->header.seq,
                    m->header.sim_time },
        .snapshot_id = m->snapshot_id, .chunk = m->chunk, .n_chunks = m->n_chunks,
        .n_objects = m->n_objects, .object_id = m->object_id, .object_name = m->object_name,
        .model = m->model, .topology_version = m->topology_version,
        .n_vertices_total = m->n_vertices_total, .n_triangles_total = m->n_triangles_total,
        .vertex_offset = m->vertex_offset, .n_coords = m->n_coords, .xyz = m->xyz,
        .triangle_offset = m->triangle_offset, .n_indices = m->n_indices,
        .indices = m->indices };
    char err[256];
    if (cs_surface_state_apply_chunk(&s->ss, &c, err, sizeof err) == CS_SS_APPLIED)
        s->snapshots++;
}

static void on_status(const lcm_recv_buf_t *rb, const char *ch, const cubesim_status_t *m,
                      void *u)
{
    sub *s = u;
    if (s->done || m->n_objects < 1)
        return;
    s->rtf = m->real_time_factor;
    s->step_ms = m->step_ms_avg;
    int k = s->n_st % HASH_RING;
    s->st_frame[k] = m->header.frame;
    s->st_hash[k] = (uint64_t)m->state_hash[0];
    s->st_obj[k] = m->object_id[0];
    s->n_st++;
    /* the frame may already be complete here (a status can trail its deltas) */
    if (s->ss.valid && s->last_complete_frame == m->header.frame)
        check_hash(s, m->header.frame);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static int run_sub(const char *url, double duration, double wait, int queue)
{
    char *bus_url = cs_client_url(url); /* as cubesim-log: a 4 MiB receive buffer */
    lcm_t *lcm = bus_url ? lcm_create(bus_url) : NULL;
    if (!lcm) {
        fprintf(stderr, "bench_bus: cannot open the LCM bus at '%s'\n", bus_url ? bus_url : "(out of memory)");
        free(bus_url);
        return 1;
    }
    free(bus_url);
    sub s;
    memset(&s, 0, sizeof s);
    cs_surface_state_init(&s.ss);
    s.duration = duration;
    s.cur_frame = -1;
    s.last_complete_frame = -1;
    for (int i = 0; i < HASH_RING; i++)
        s.st_frame[i] = -1;
    cubesim_delta_t_subscription_t *sd = cubesim_delta_t_subscribe(lcm, "CUBESIM_DELTA", on_delta, &s);
    cubesim_snapshot_t_subscription_t *ss =
        cubesim_snapshot_t_subscribe(lcm, "CUBESIM_SNAPSHOT", on_snapshot, &s);
    cubesim_status_t_subscription_t *st =
        cubesim_status_t_subscribe(lcm, "CUBESIM_STATUS", on_status, &s);
    if (!sd || !ss || !st) {
        fprintf(stderr, "bench_bus: cannot subscribe\n");
        lcm_destroy(lcm);
        return 1;
    }
    cubesim_delta_t_subscription_set_queue_capacity(sd, queue);
    cubesim_snapshot_t_subscription_set_queue_capacity(ss, queue);
    double c0 = cpu_s(), t0 = mono_s();
    while (!s.done) {
        double now = mono_s();
        if (!s.started && now - t0 > wait)
            break;
        if (s.started && now >= s.t_end) {
            s.done = 1;
            break;
        }
        lcm_handle_timeout(lcm, 100);
    }
    double c1 = cpu_s(), t1 = mono_s();
    if (s.cur_frame >= 0 && s.cur_chunks < s.cur_n_chunks && s.done && s.frames > 1) {
        /* the window closed in the middle of this frame: it is not part of the count */
        s.frames--;
        s.delta_msgs -= s.cur_chunks;
        s.bytes -= s.cur_bytes;
        s.last_frame = s.cur_frame - 1;
        s.cur_frame = -1;
    }
    close_frame(&s);
    double p50 = 0, p99 = 0, pmax = 0;
    if (s.n_lat > 0) {
        qsort(s.lat, (size_t)s.n_lat, sizeof *s.lat, cmp_double);
        p50 = s.lat[s.n_lat / 2];
        p99 = s.lat[(int64_t)(0.99 * (double)(s.n_lat - 1))];
        pmax = s.lat[s.n_lat - 1];
    }
    double span = s.t_last_frame - s.t_first_frame;
    double wall = s.started ? t1 - s.t_first : t1 - t0;
    printf("sub frames=%lld complete=%lld incomplete=%lld first_frame=%lld last_frame=%lld "
           "delta_msgs=%lld lost=%lld bytes=%lld wall_s=%.3f rate_hz=%.2f lat_ms_p50=%.2f "
           "lat_ms_p99=%.2f lat_ms_max=%.2f cpu_s=%.3f cpu_pct=%.1f hash_checked=%d "
           "hash_bad=%d snapshots=%lld stale=%lld rejected=%lld daemon_rtf=%.3f "
           "daemon_step_ms=%.3f\n",
           (long long)s.frames, (long long)s.complete, (long long)s.incomplete,
           (long long)s.first_frame, (long long)s.last_frame, (long long)s.delta_msgs,
           (long long)s.ss.deltas_lost, (long long)s.bytes, wall,
           span > 0 ? (double)(s.frames - 1) / span : 0.0, p50, p99, pmax, c1 - c0,
           100.0 * (c1 - c0) / (t1 - t0), s.hash_checked, s.hash_bad, (long long)s.snapshots,
           (long long)s.stale_seen, (long long)s.rejected, s.rtf, s.step_ms);
    cubesim_delta_t_unsubscribe(lcm, sd);
    cubesim_snapshot_t_unsubscribe(lcm, ss);
    cubesim_status_t_unsubscribe(lcm, st);
    lcm_destroy(lcm);
    cs_surface_state_free(&s.ss);
    free(s.lat);
    return s.frames > 0 ? 0 : 1;
}

int main(int argc, char **argv)
{
    if (argc < 2)
        return usage();
    if (strcmp(argv[1], "mesh") == 0) {
        if (argc < 3)
            return usage();
        long n = 100000;
        double r = 0.5;
        for (int i = 3; i + 1 < argc; i += 2) {
            if (strcmp(argv[i], "--vertices") == 0)
                n = strtol(argv[i + 1], NULL, 10);
            else if (strcmp(argv[i], "--radius") == 0)
                r = strtod(argv[i + 1], NULL);
            else
                return usage();
        }
        if ((argc - 3) % 2 || n < 10 || n > 50000000 || !(r > 0))
            return usage();
        return write_sphere(argv[2], n, r);
    }
    if (strcmp(argv[1], "sub") == 0) {
        const char *url = NULL;
        double duration = 30, wait = 20;
        int queue = 100000;
        if ((argc - 2) % 2)
            return usage();
        for (int i = 2; i + 1 < argc; i += 2) {
            if (strcmp(argv[i], "--lcm") == 0)
                url = argv[i + 1];
            else if (strcmp(argv[i], "--duration") == 0)
                duration = strtod(argv[i + 1], NULL);
            else if (strcmp(argv[i], "--wait") == 0)
                wait = strtod(argv[i + 1], NULL);
            else if (strcmp(argv[i], "--queue") == 0)
                queue = atoi(argv[i + 1]);
            else
                return usage();
        }
        if (!(duration > 0) || !(wait > 0) || queue < 1)
            return usage();
        return run_sub(url, duration, wait, queue);
    }
    return usage();
}
