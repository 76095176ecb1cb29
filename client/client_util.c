/*
 * client_util.c — shared client plumbing (see client_util.h): header peeking by fingerprint,
 * per-channel sequence accounting, ids and clocks, and the strict LCM event-log indexer.
 */
#include "client_util.h"

#include <errno.h>
#include <stdbool.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "cubesim_ack_t.h"
#include "cubesim_delta_t.h"
#include "cubesim_pose_t.h"
#include "number.h"
#include "cubesim_snapshot_t.h"
#include "cubesim_status_t.h"
#include "cubesim_topology_t.h"

#define CS_LOG_SYNC 0xEDA1DA01u
#define CS_LOG_MAX_CHANNEL 1024

int64_t cs_now_utime(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

double cs_mono_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

char *cs_client_url(const char *url)
{
    if (!url || !*url)
        url = getenv("LCM_DEFAULT_URL");
    if (!url || !*url)
        url = "udpm://239.255.76.67:7667?ttl=0";
    size_t n = strlen(url);
    if (strncmp(url, "udpm://", 7) != 0 || strstr(url, "recv_buf_size=")) {
        char *c = malloc(n + 1);
        if (c)
            memcpy(c, url, n + 1);
        return c;
    }
    char extra[64];
    snprintf(extra, sizeof extra, "%crecv_buf_size=%d", strchr(url, '?') ? '&' : '?',
             CS_CLIENT_RECV_BUF);
    size_t m = strlen(extra);
    char *c = malloc(n + m + 1);
    if (!c)
        return NULL;
    memcpy(c, url, n);
    memcpy(c + n, extra, m + 1);
    return c;
}

int64_t cs_random_id(void)
{
    uint64_t r = 0;
    if (getrandom(&r, sizeof r, 0) != (ssize_t)sizeof r)
        r = (uint64_t)cs_now_utime() * 6364136223846793005ULL ^ (uint64_t)getpid();
    r &= 0x7fffffffffffffffULL;
    return r ? (int64_t)r : 1;
}

static int64_t be64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int i = 0; i < 8; i++)
        v = v << 8 | p[i];
    return (int64_t)v;
}

static int32_t be32(const uint8_t *p)
{
    return (int32_t)((uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3]);
}

int cs_msg_header(const void *data, int len, cubesim_header_t *h)
{
    if (!data || len < 8)
        return 0;
    int64_t fp = be64(data);
    if (fp != __cubesim_ack_t_get_hash() && fp != __cubesim_delta_t_get_hash() &&
        fp != __cubesim_snapshot_t_get_hash() && fp != __cubesim_status_t_get_hash() &&
        fp != __cubesim_topology_t_get_hash() && fp != __cubesim_pose_t_get_hash())
        return 0;
    if (__cubesim_header_t_decode_array(data, 8, len - 8, h, 1) < 0)
        return 0;
    return 1;
}

int cs_parse_double(const char *s, double *out)
{
    return cs_parse_decimal(s, out) == 0 ? 0 : -1;
}

int cs_parse_int(const char *s, long lo, long hi, long *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (!*s || *end || errno || v < lo || v > hi)
        return -1;
    *out = v;
    return 0;
}

/* Room for one more of n items of `size` bytes in *arr (capacity *cap, doubled from `first`);
 * 0, or -1 out of memory (*arr unchanged). */
static int grow(void **arr, int n, int *cap, size_t size, int first)
{
    if (n < *cap)
        return 0;
    const int c = *cap ? 2 * *cap : first;
    void *p = realloc(*arr, (size_t)c * size);
    if (!p)
        return -1;
    *arr = p;
    *cap = c;
    return 0;
}

int cs_seq_table_note(cs_seq_table *tab, const char *channel, const cubesim_header_t *h)
{
    cs_seq_track *t = NULL;
    for (int i = 0; i < tab->n; i++)
        if (!strcmp(tab->t[i].channel, channel))
            t = &tab->t[i];
    if (!t) {
        if (grow((void **)&tab->t, tab->n, &tab->cap, sizeof *tab->t, 8))
            return -1;
        t = &tab->t[tab->n];
        memset(t, 0, sizeof *t);
        t->channel = strdup(channel);
        if (!t->channel)
            return -1;
        tab->n++;
    }
    t->messages++;
    if (!h)
        return 0;
    bool known = false;
    for (int i = 0; i < tab->n_sessions && !known; i++)
        known = tab->sessions[i] == h->session_id;
    if (!known) {
        if (grow((void **)&tab->sessions, tab->n_sessions, &tab->cap_sessions,
                 sizeof *tab->sessions, 4))
            return -1;
        tab->sessions[tab->n_sessions++] = h->session_id;
    }
    if (!t->have) {
        t->have = 1;
    } else if (h->session_id != t->session_id) {
        t->restarts++;
    } else if (h->seq > t->last_seq) {
        t->lost += h->seq - t->last_seq - 1;
    } else {
        t->reordered++;
        return 0;
    }
    t->session_id = h->session_id;
    t->last_seq = h->seq;
    return 0;
}

int64_t cs_seq_table_restarts(const cs_seq_table *tab)
{
    return tab->n_sessions > 1 ? tab->n_sessions - 1 : 0;
}

void cs_seq_table_free(cs_seq_table *tab)
{
    for (int i = 0; i < tab->n; i++)
        free(tab->t[i].channel);
    free(tab->t);
    free(tab->sessions);
    memset(tab, 0, sizeof *tab);
}

void cs_log_close(cs_log *log)
{
    if (log->f)
        fclose(log->f);
    for (int i = 0; i < log->n_channels; i++)
        free(log->channels[i]);
    free(log->channels);
    free(log->ev);
    free(log->buf);
    memset(log, 0, sizeof *log);
}

static int channel_index(cs_log *log, const char *name)
{
    for (int i = 0; i < log->n_channels; i++)
        if (!strcmp(log->channels[i], name))
            return i;
    char **nc = realloc(log->channels, (size_t)(log->n_channels + 1) * sizeof *nc);
    if (!nc)
        return -1;
    log->channels = nc;
    if (!(nc[log->n_channels] = strdup(name)))
        return -1;
    return log->n_channels++;
}

int cs_log_open(const char *path, cs_log *log, char *err, size_t errlen)
{
    memset(log, 0, sizeof *log);
    log->f = fopen(path, "rb");
    if (!log->f) {
        snprintf(err, errlen, "%s: cannot open: %s", path, strerror(errno));
        return -1;
    }
    struct stat sb;
    if (fstat(fileno(log->f), &sb) || !S_ISREG(sb.st_mode)) {
        snprintf(err, errlen, "%s: not a regular file", path);
        goto fail;
    }
    int64_t size = sb.st_size, off = 0, cap = 0;
    if (size == 0) {
        snprintf(err, errlen, "%s: empty file, not an LCM event log", path);
        goto fail;
    }
    char chan[CS_LOG_MAX_CHANNEL + 1];
    while (off < size) {
        uint8_t h[28];
        if (size - off < 28) {
            snprintf(err, errlen, "%s: truncated: event %" PRId64 " header cut at byte %" PRId64,
                     path, log->n, off);
            goto fail;
        }
        if (fseeko(log->f, off, SEEK_SET) || fread(h, 1, 28, log->f) != 28) {
            snprintf(err, errlen, "%s: read error at byte %" PRId64, path, off);
            goto fail;
        }
        if ((uint32_t)be32(h) != CS_LOG_SYNC) {
            if (off == 0)
                snprintf(err, errlen, "%s: not an LCM event log (no sync word at byte 0)", path);
            else
                snprintf(err, errlen, "%s: corrupt: no sync word at byte %" PRId64
                         " (event %" PRId64 ")", path, off, log->n);
            goto fail;
        }
        int32_t chlen = be32(h + 20), dlen = be32(h + 24);
        if (chlen <= 0 || chlen > CS_LOG_MAX_CHANNEL || dlen < 0) {
            snprintf(err, errlen, "%s: corrupt: event %" PRId64 " at byte %" PRId64
                     " has channel length %d, data length %d", path, log->n, off, chlen, dlen);
            goto fail;
        }
        if (off + 28 + chlen + (int64_t)dlen > size) {
            snprintf(err, errlen, "%s: truncated: event %" PRId64 " at byte %" PRId64
                     " needs %" PRId64 " bytes, the file ends %" PRId64 " bytes later", path, log->n, off,
                     (int64_t)28 + chlen + dlen, size - off);
            goto fail;
        }
        if (fread(chan, 1, (size_t)chlen, log->f) != (size_t)chlen) {
            snprintf(err, errlen, "%s: read error at byte %" PRId64, path, off);
            goto fail;
        }
        chan[chlen] = 0;
        if (strlen(chan) != (size_t)chlen) {
            snprintf(err, errlen, "%s: corrupt: event %" PRId64 " channel name contains NUL",
                     path, log->n);
            goto fail;
        }
        if (log->n == cap) {
            cap = cap ? 2 * cap : 1024;
            cs_log_event *ne = realloc(log->ev, (size_t)cap * sizeof *ne);
            if (!ne) {
                snprintf(err, errlen, "%s: out of memory indexing", path);
                goto fail;
            }
            log->ev = ne;
        }
        int ci = channel_index(log, chan);
        if (ci < 0) {
            snprintf(err, errlen, "%s: out of memory indexing", path);
            goto fail;
        }
        log->ev[log->n++] = (cs_log_event){be64(h + 4), be64(h + 12), off + 28 + chlen, dlen, ci};
        off += 28 + chlen + (int64_t)dlen;
    }
    return 0;
fail:
    cs_log_close(log);
    return -1;
}

int cs_log_read(cs_log *log, int64_t i, const uint8_t **data, char *err, size_t errlen)
{
    const cs_log_event *e = &log->ev[i];
    if ((size_t)e->datalen + 1 > log->buf_cap) {
        size_t cap = (size_t)e->datalen + 1;
        uint8_t *nb = realloc(log->buf, cap);
        if (!nb) {
            snprintf(err, errlen, "out of memory reading event %" PRId64, i);
            return -1;
        }
        log->buf = nb;
        log->buf_cap = cap;
    }
    if (fseeko(log->f, e->data_offset, SEEK_SET) ||
        fread(log->buf, 1, (size_t)e->datalen, log->f) != (size_t)e->datalen) {
        snprintf(err, errlen, "read error at event %" PRId64, i);
        return -1;
    }
    *data = log->buf;
    return 0;
}
