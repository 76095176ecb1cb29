/*
 * tool_util.h — small helpers shared by the test-side LCM tools (tests/it/tools/bus.c,
 * tests/stress/probe.c).
 */
#ifndef CS_TOOL_UTIL_H
#define CS_TOOL_UTIL_H

#include <stdlib.h>
#include <time.h>

/* Monotonic seconds, for timeouts and pacing. */
static inline double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* "x,y,z" into v; 0, or -1 if it is not exactly three comma-separated numbers. */
static inline int parse3(const char *s, double v[3])
{
    char *end = NULL;
    for (int i = 0; i < 3; i++) {
        v[i] = strtod(s, &end);
        if (end == s)
            return -1;
        s = end;
        if (i < 2) {
            if (*s != ',')
                return -1;
            s++;
        }
    }
    return *s ? -1 : 0;
}

#endif
