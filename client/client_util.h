/*
 * client_util.h — what the cubesim clients share: the bus channel names, reading the header of
 * a raw daemon message without decoding the rest, ids, clocks, argument parsing helpers, and a
 * strict reader of LCM event logs (format of lcm/eventlog.h: per event a sync word 0xEDA1DA01,
 * event number, timestamp [µs], channel length, data length, channel, data; big-endian).
 *
 * The log reader indexes the whole file once, so that a foreign, corrupt or truncated log is
 * refused with one line before anything is replayed, and so that replay can seek and loop.
 * lcm_eventlog_read_next_event is not used for reading: it trusts lengths from the file.
 */
#ifndef CS_CLIENT_UTIL_H
#define CS_CLIENT_UTIL_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "cubesim_header_t.h"

#define CS_CH_SNAPSHOT "CUBESIM_SNAPSHOT"
#define CS_CH_DELTA "CUBESIM_DELTA"
#define CS_CH_POSE "CUBESIM_POSE"
#define CS_CH_TOPOLOGY "CUBESIM_TOPOLOGY"
#define CS_CH_STATUS "CUBESIM_STATUS"
#define CS_CH_ACK "CUBESIM_ACK"
#define CS_CH_FORCE "CUBESIM_FORCE"
#define CS_CH_COMMAND "CUBESIM_COMMAND"
#define CS_CH_PAINT "CUBESIM_PAINT"
#define CS_CH_PRESSURE "CUBESIM_PRESSURE"
#define CS_CH_CURVE "CUBESIM_CURVE"

/* Wall clock, microseconds since 1970; monotonic seconds. */
int64_t cs_now_utime(void);
double cs_mono_s(void);

/* A random non-zero 63-bit id (getrandom, falling back to time and pid). */
int64_t cs_random_id(void);

/* If `data` is a message of a type that carries header_t (ack, delta, pose, snapshot,
 * status, topology, by fingerprint), decode its header into *h and return 1; else 0. */
int cs_msg_header(const void *data, int len, cubesim_header_t *h);

/*
 * The URL a receiving client opens: `url`, else $LCM_DEFAULT_URL, else LCM's default
 * udpm://239.255.76.67:7667?ttl=0; a udpm URL without recv_buf_size gets
 * recv_buf_size=CS_CLIENT_RECV_BUF appended (the kernel caps it at net.core.rmem_max), so a
 * burst of 60 KB chunks — a 100 000-vertex surface is 1.6 MB per frame — fits in the socket
 * buffer (the kernel's default, 208 KiB, holds about 3 of them). Other URLs are kept as they
 * are. Returns a malloc'd string, NULL when out of memory.
 */
#define CS_CLIENT_RECV_BUF 4194304
char *cs_client_url(const char *url);

/* Parse a finite double / an int in [lo, hi]; 0 on success, -1 otherwise. */
int cs_parse_double(const char *s, double *out);
int cs_parse_int(const char *s, long lo, long hi, long *out);

/* Per-channel receive accounting from header.seq: messages, lost (gaps), restarts. */
typedef struct cs_seq_track {
    char *channel;
    int64_t messages;
    int64_t lost;
    int64_t restarts;      /* session_id changes after the first message */
    int64_t reordered;     /* seq not above the last one of the same session */
    int have;
    int64_t session_id;
    int64_t last_seq;
} cs_seq_track;

typedef struct cs_seq_table {
    cs_seq_track *t;
    int n, cap;
    int64_t *sessions; /* every session_id seen, on any channel */
    int n_sessions, cap_sessions;
} cs_seq_table;

/* Count one message on `channel` (h NULL: a message without our header). 0, or -1 on OOM. */
int cs_seq_table_note(cs_seq_table *tab, const char *channel, const cubesim_header_t *h);
/* Daemon restarts seen: distinct session ids over all channels, less one (each channel's
 * `restarts` counts the same restart again). */
int64_t cs_seq_table_restarts(const cs_seq_table *tab);
void cs_seq_table_free(cs_seq_table *tab);

/* One event of an indexed log. */
typedef struct cs_log_event {
    int64_t eventnum;
    int64_t timestamp;   /* µs */
    int64_t data_offset; /* file offset of the payload */
    int32_t datalen;
    int32_t channel;     /* index into cs_log.channels */
} cs_log_event;

typedef struct cs_log {
    FILE *f;
    cs_log_event *ev;
    int64_t n;
    char **channels;     /* distinct channel names, owned */
    int n_channels;
    uint8_t *buf;        /* payload buffer for cs_log_read */
    size_t buf_cap;
} cs_log;

/*
 * Open and index a log. Returns 0, or -1 with a one-line message: missing or unreadable file,
 * empty file, "not an LCM event log" (no sync word at byte 0), corrupt (bad sync word or
 * impossible lengths at byte N), truncated (the last event ends past the end of the file).
 */
int cs_log_open(const char *path, cs_log *log, char *err, size_t errlen);
void cs_log_close(cs_log *log);
/* Read event i's payload into log->buf (valid until the next call); -1 with err on I/O error. */
int cs_log_read(cs_log *log, int64_t i, const uint8_t **data, char *err, size_t errlen);

#endif
