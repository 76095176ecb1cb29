/*
 * dlog.h — the daemon's log: one line per event on stderr, prefixed "cubesimd: ".
 *
 * Owns: nothing but its own small rate-limit table. Info lines are silenced by `quiet`;
 * warnings and errors never are, but a warning repeated under the same key is printed at most
 * CS_DLOG_BURST times per second and the rest are counted and summarised once ("N more ...").
 * Events that clients can repeat at will (an applied input) are info lines limited the same way.
 * Not library code: the daemon's adapters (main.c, bus.c) are the only users.
 */
#ifndef CS_DLOG_H
#define CS_DLOG_H

#include <stdbool.h>
#include <stdint.h>

#define CS_DLOG_BURST 5
#define CS_DLOG_KEYS 32

typedef struct cs_dlog_slot {
    char key[48];
    double window_start; /* monotonic seconds */
    int printed;         /* in this window */
    int64_t suppressed;  /* in this window */
    bool info;           /* the key's lines are events (cs_dlog_event), not warnings */
} cs_dlog_slot;

typedef struct cs_dlog {
    bool quiet;
    cs_dlog_slot slot[CS_DLOG_KEYS];
} cs_dlog;

/* Monotonic clock in seconds (for scheduling) and wall clock in microseconds since 1970. */
double cs_dlog_now(void);
int64_t cs_dlog_utime(void);

/* An event; silenced by quiet. */
void cs_dlog_info(cs_dlog *l, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* An event a client can repeat at will (an input applied): an info line (silenced by quiet),
 * rate-limited per key like a warning. */
void cs_dlog_event(cs_dlog *l, const char *key, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* A problem that does not stop the daemon, rate-limited per key (NULL key: never limited). */
void cs_dlog_warn(cs_dlog *l, const char *key, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* Make s one printable line in place: every control character (newline, ESC, ...) becomes
 * '?', so a client's object name cannot split a line or reach a terminal raw. Used for the
 * log's lines and the acks' messages. */
void cs_dlog_one_line(char *s);
/* Print the "N more ... suppressed" summaries of windows that have ended (call now and then). */
void cs_dlog_flush(cs_dlog *l);

#endif
