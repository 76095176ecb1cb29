/*
 * check.h — the unit-test harness: TEST(name) registers a test at load time; ENSURE and
 * ENSURE_NEAR record a failure with its file and line and leave the current function.
 * The runner (runner.c) prints one "PASS name" or "FAIL name: why" line per test and a last
 * line "N passed, N failed". `--quick` skips tests marked slow; an argument filters by name.
 */
#ifndef CS_CHECK_H
#define CS_CHECK_H

#include <math.h>
#include <stdio.h>

typedef void (*cs_test_fn)(void);
void cs_test_register(const char *name, cs_test_fn fn, int slow);
void cs_test_fail(const char *file, int line, const char *fmt, ...);
int cs_test_failed(void);

#define CS_TEST_(name, slow)                                                                   \
    static void name(void);                                                                    \
    __attribute__((constructor)) static void reg_##name(void)                                 \
    {                                                                                          \
        cs_test_register(#name, name, slow);                                                   \
    }                                                                                          \
    static void name(void)

#define TEST(name) CS_TEST_(name, 0)
#define SLOW_TEST(name) CS_TEST_(name, 1)

#define ENSURE(cond)                                                                           \
    do {                                                                                       \
        if (!(cond)) {                                                                         \
            cs_test_fail(__FILE__, __LINE__, "%s", #cond);                                     \
            return;                                                                            \
        }                                                                                      \
    } while (0)

#define ENSURE_MSG(cond, ...)                                                                  \
    do {                                                                                       \
        if (!(cond)) {                                                                         \
            cs_test_fail(__FILE__, __LINE__, __VA_ARGS__);                                     \
            return;                                                                            \
        }                                                                                      \
    } while (0)

#define ENSURE_NEAR(a, b, tol)                                                                 \
    do {                                                                                       \
        double a_ = (a), b_ = (b), t_ = (tol);                                                 \
        if (!(fabs(a_ - b_) <= t_)) {                                                          \
            cs_test_fail(__FILE__, __LINE__, "%s = %.9g, %s = %.9g, |diff| %.3g > %.3g", #a,   \
                         a_, #b, b_, fabs(a_ - b_), t_);                                       \
            return;                                                                            \
        }                                                                                      \
    } while (0)

#endif
