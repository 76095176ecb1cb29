/*
 * dlog.c — the daemon's stderr log with per-key rate limiting (see dlog.h).
 * Each line is written with one fprintf so lines from one process never interleave.
 */
#include "dlog.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

double cs_dlog_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int64_t cs_dlog_utime(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

void cs_dlog_one_line(char *s)
{
    for (char *p = s; *p; p++)
        if ((unsigned char)*p < 0x20 || *p == 0x7f)
            *p = '?';
}

static void vline(const char *fmt, va_list ap)
{
    char buf[1024];
    vsnprintf(buf, sizeof buf, fmt, ap);
    cs_dlog_one_line(buf); /* one line per event, whatever the message held */
    fprintf(stderr, "cubesimd: %s\n", buf);
}

void cs_dlog_info(cs_dlog *l, const char *fmt, ...)
{
    if (l && l->quiet)
        return;
    va_list ap;
    va_start(ap, fmt);
    vline(fmt, ap);
    va_end(ap);
}

static void summarise(cs_dlog_slot *s)
{
    if (s->suppressed > 0)
        fprintf(stderr, "cubesimd: (%lld more '%s' %s suppressed)\n", (long long)s->suppressed,
                s->key, s->info ? "lines" : "warnings");
    s->suppressed = 0;
    s->printed = 0;
}

void cs_dlog_flush(cs_dlog *l)
{
    double now = cs_dlog_now();
    for (int i = 0; i < CS_DLOG_KEYS; i++) {
        cs_dlog_slot *s = &l->slot[i];
        if (s->key[0] && now - s->window_start >= 1.0 && (s->printed || s->suppressed)) {
            summarise(s);
            s->window_start = now;
        }
    }
}

static cs_dlog_slot *find_slot(cs_dlog *l, const char *key, double now)
{
    cs_dlog_slot *oldest = &l->slot[0];
    for (int i = 0; i < CS_DLOG_KEYS; i++) {
        cs_dlog_slot *s = &l->slot[i];
        if (s->key[0] && strncmp(s->key, key, sizeof s->key - 1) == 0)
            return s;
        if (!s->key[0]) {
            oldest = s;
            break;
        }
        if (s->window_start < oldest->window_start)
            oldest = s;
    }
    summarise(oldest);
    snprintf(oldest->key, sizeof oldest->key, "%s", key);
    oldest->window_start = now;
    return oldest;
}

/* Whether a line under key may be printed now (counted if not). */
static bool admit(cs_dlog *l, const char *key, bool info)
{
    double now = cs_dlog_now();
    cs_dlog_slot *s = find_slot(l, key, now);
    if (now - s->window_start >= 1.0) {
        summarise(s);
        s->window_start = now;
    }
    s->info = info;
    if (s->printed >= CS_DLOG_BURST) {
        s->suppressed++;
        return false;
    }
    s->printed++;
    return true;
}

void cs_dlog_event(cs_dlog *l, const char *key, const char *fmt, ...)
{
    if (l && (l->quiet || (key && !admit(l, key, true))))
        return;
    va_list ap;
    va_start(ap, fmt);
    vline(fmt, ap);
    va_end(ap);
}

void cs_dlog_warn(cs_dlog *l, const char *key, const char *fmt, ...)
{
    if (l && key && !admit(l, key, false))
        return;
    va_list ap;
    va_start(ap, fmt);
    vline(fmt, ap);
    va_end(ap);
}
