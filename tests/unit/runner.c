/*
 * runner.c — runs every registered unit test; see check.h.
 */
#include "check.h"

#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define CS_MAX_TESTS 512

typedef struct {
    const char *name;
    cs_test_fn fn;
    int slow;
} cs_test_entry;

/* The registry is filled by constructors before main; the runner is a test program, not the
 * engine, so this static table is allowed state. */
static cs_test_entry tests[CS_MAX_TESTS];
static int n_tests;
static int current_failed;

void cs_test_register(const char *name, cs_test_fn fn, int slow)
{
    if (n_tests < CS_MAX_TESTS)
        tests[n_tests++] = (cs_test_entry){name, fn, slow};
}

void cs_test_fail(const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    current_failed = 1;
    printf("    %s:%d: ", file, line);
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
    printf("\n");
}

int cs_test_failed(void)
{
    return current_failed;
}

static int by_name(const void *a, const void *b)
{
    return strcmp(((const cs_test_entry *)a)->name, ((const cs_test_entry *)b)->name);
}

int main(int argc, char **argv)
{
    int quick = 0, list = 0, passed = 0, failed = 0;
    const char *filter = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--quick"))
            quick = 1;
        else if (!strcmp(argv[i], "--list"))
            list = 1;
        else
            filter = argv[i];
    }
    qsort(tests, (size_t)n_tests, sizeof tests[0], by_name);
    setvbuf(stdout, NULL, _IOLBF, 0);
    for (int i = 0; i < n_tests; i++) {
        if (filter && !strstr(tests[i].name, filter))
            continue;
        if (quick && tests[i].slow)
            continue;
        if (list) {
            printf("%s%s\n", tests[i].name, tests[i].slow ? " (slow)" : "");
            continue;
        }
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        current_failed = 0;
        tests[i].fn();
        clock_gettime(CLOCK_MONOTONIC, &t1);
        double ms = (t1.tv_sec - t0.tv_sec) * 1e3 + (t1.tv_nsec - t0.tv_nsec) / 1e6;
        if (current_failed) {
            printf("FAIL %s (%.0f ms)\n", tests[i].name, ms);
            failed++;
        } else {
            printf("PASS %s (%.0f ms)\n", tests[i].name, ms);
            passed++;
        }
    }
    if (!list)
        printf("unit: %d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
