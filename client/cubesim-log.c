/*
 * cubesim-log — record the cubesim bus to a standard LCM event log (lcm/eventlog.h), readable
 * by lcm-logplayer and cubesim-replay, and report what was lost (DESIGN.md "Bus").
 *
 *   cubesim-log FILE [--lcm URL] [--channels REGEX] [--duration S] [--passive] [--quiet]
 *
 * Records every channel matching REGEX (default "CUBESIM_.*", LCM's anchored regex) with the
 * receive time as the event timestamp. Unless --passive, it asks the daemon for a snapshot at
 * start (so a late logger's file can rebuild the surfaces without waiting for a key frame)
 * and again, at most once a second, after it detects lost deltas or topology changes (a
 * lost CUBESIM_TOPOLOGY message leaves every later delta of that object unusable until the
 * next snapshot) or a daemon restart.
 * On SIGINT, SIGTERM or after --duration it prints per channel: messages, messages lost
 * (gaps in header.seq), daemon restarts (session_id changes). Exit 0, 2 on usage/file/bus error.
 */
#include <inttypes.h>
#include <lcm/eventlog.h>
#include <lcm/lcm.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client_util.h"
#include "cubesim_command_t.h"

static volatile sig_atomic_t stop_flag;

static void on_signal(int sig)
{
    stop_flag = sig;
}

typedef struct logger {
    lcm_eventlog_t *log;
    int64_t nevents;
    int64_t bytes;
    int write_failed;
    cs_seq_table seq;
    int want_snapshot;   /* a delta/topology loss or restart was seen since the last request */
} logger;

static void on_message(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    logger *lg = user;
    lcm_eventlog_event_t ev;
    ev.eventnum = lg->nevents;
    ev.timestamp = rbuf->recv_utime;
    ev.channellen = (int32_t)strlen(channel);
    ev.datalen = (int32_t)rbuf->data_size;
    ev.channel = (char *)channel;
    ev.data = rbuf->data;
    if (lcm_eventlog_write_event(lg->log, &ev) != 0) {
        lg->write_failed = 1;
        return;
    }
    lg->nevents++;
    lg->bytes += ev.datalen;
    cubesim_header_t h;
    int has = cs_msg_header(rbuf->data, (int)rbuf->data_size, &h);
    int64_t lost0 = 0, restarts0 = 0;
    for (int i = 0; i < lg->seq.n; i++)
        if (!strcmp(lg->seq.t[i].channel, channel)) {
            lost0 = lg->seq.t[i].lost;
            restarts0 = lg->seq.t[i].restarts;
        }
    cs_seq_table_note(&lg->seq, channel, has ? &h : NULL);
    for (int i = 0; i < lg->seq.n; i++)
        if (!strcmp(lg->seq.t[i].channel, channel) &&
            (((!strcmp(channel, CS_CH_DELTA) || !strcmp(channel, CS_CH_TOPOLOGY) ||
               !strcmp(channel, CS_CH_POSE)) &&
              lg->seq.t[i].lost > lost0) ||
             lg->seq.t[i].restarts > restarts0))
            lg->want_snapshot = 1;
}

static void request_snapshot(lcm_t *lcm, int64_t client_id, int64_t *command_id)
{
    cubesim_command_t c;
    memset(&c, 0, sizeof c);
    c.client_id = client_id;
    c.command_id = ++*command_id;
    c.command = "snapshot";
    c.argument = "";
    cubesim_command_t_publish(lcm, CS_CH_COMMAND, &c);
}

static void usage(FILE *f)
{
    fprintf(f, "usage: cubesim-log FILE [--lcm URL] [--channels REGEX] [--duration S] "
               "[--passive] [--quiet]\n");
}

int main(int argc, char **argv)
{
    const char *path = NULL, *url = NULL, *regex = "CUBESIM_.*";
    double duration = -1;
    int passive = 0, quiet = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(a, "--lcm") && i + 1 < argc) {
            url = argv[++i];
        } else if (!strcmp(a, "--channels") && i + 1 < argc) {
            regex = argv[++i];
        } else if (!strcmp(a, "--duration") && i + 1 < argc) {
            if (cs_parse_double(argv[++i], &duration) || duration <= 0) {
                fprintf(stderr, "cubesim-log: --duration: '%s' is not a time > 0\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(a, "--passive")) {
            passive = 1;
        } else if (!strcmp(a, "--quiet")) {
            quiet = 1;
        } else if (a[0] == '-' && a[1] == '-') {
            fprintf(stderr, "cubesim-log: unknown option or missing value: %s\n", a);
            return 2;
        } else if (!path) {
            path = a;
        } else {
            fprintf(stderr, "cubesim-log: unexpected argument '%s'\n", a);
            return 2;
        }
    }
    if (!path) {
        usage(stderr);
        return 2;
    }
    logger lg;
    memset(&lg, 0, sizeof lg);
    lg.log = lcm_eventlog_create(path, "w");
    if (!lg.log) {
        fprintf(stderr, "cubesim-log: %s: cannot create the log file\n", path);
        return 2;
    }
    char *bus_url = cs_client_url(url); /* with a 4 MiB receive buffer */
    lcm_t *lcm = bus_url ? lcm_create(bus_url) : NULL;
    if (!lcm) {
        fprintf(stderr, "cubesim-log: cannot open the bus %s\n", bus_url ? bus_url : "(out of memory)");
        free(bus_url);
        lcm_eventlog_destroy(lg.log);
        return 2;
    }
    free(bus_url);
    lcm_subscription_t *sub = lcm_subscribe(lcm, regex, on_message, &lg);
    if (!sub) {
        fprintf(stderr, "cubesim-log: cannot subscribe to '%s'\n", regex);
        lcm_destroy(lcm);
        lcm_eventlog_destroy(lg.log);
        return 2;
    }
    /* A logger must not drop what it could keep: snapshot bursts exceed the default 30. */
    lcm_subscription_set_queue_capacity(sub, 100000);

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    int64_t client_id = cs_random_id(), command_id = 0;
    double t0 = cs_mono_s(), last_request = -1e9;
    if (!passive) {
        request_snapshot(lcm, client_id, &command_id);
        last_request = t0;
    }
    int fd = lcm_get_fileno(lcm);
    int status = 0;
    while (!stop_flag && !lg.write_failed) {
        double now = cs_mono_s();
        if (duration > 0 && now - t0 >= duration)
            break;
        if (!passive && lg.want_snapshot && now - last_request >= 1.0) {
            request_snapshot(lcm, client_id, &command_id);
            lg.want_snapshot = 0;
            last_request = now;
        }
        int ms = 100;
        if (duration > 0 && (t0 + duration - now) * 1000 < ms)
            ms = (int)((t0 + duration - now) * 1000) + 1;
        struct pollfd pfd = {fd, POLLIN, 0};
        int r = poll(&pfd, 1, ms);
        if (r > 0 && (pfd.revents & POLLIN)) {
            if (lcm_handle(lcm) != 0) {
                fprintf(stderr, "cubesim-log: the bus failed\n");
                status = 2;
                break;
            }
        }
    }
    if (lg.write_failed) {
        fprintf(stderr, "cubesim-log: %s: write failed (disk full?)\n", path);
        status = 2;
    }
    double secs = cs_mono_s() - t0;
    lcm_unsubscribe(lcm, sub);
    lcm_destroy(lcm);
    lcm_eventlog_destroy(lg.log);

    int64_t lost = 0, restarts = cs_seq_table_restarts(&lg.seq);
    for (int i = 0; i < lg.seq.n; i++)
        lost += lg.seq.t[i].lost;
    if (!quiet) {
        printf("cubesim-log: %s: %" PRId64 " messages, %" PRId64 " bytes in %.1f s\n", path,
               lg.nevents, lg.bytes, secs);
        for (int i = 0; i < lg.seq.n; i++) {
            const cs_seq_track *t = &lg.seq.t[i];
            if (t->have)
                printf("  %-20s %8" PRId64 " messages %6" PRId64 " lost %3" PRId64
                       " restarts%s\n", t->channel, t->messages, t->lost, t->restarts,
                       t->reordered ? " (some out of order)" : "");
            else
                printf("  %-20s %8" PRId64 " messages (no sequence numbers)\n", t->channel,
                       t->messages);
        }
        printf("lost %" PRId64 " messages, %" PRId64 " daemon restarts\n", lost, restarts);
    }
    cs_seq_table_free(&lg.seq);
    return status;
}
