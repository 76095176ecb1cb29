/*
 * number.h — the one syntax for numbers typed by people and clients (command-line flags, the
 * fracture command's argument): a decimal number as JSON writes it, an optional sign, digits
 * with an optional point (".5" and "5." too), an optional exponent. strtod alone also takes
 * hexadecimal ("0x10" read as 16), "inf", "nan" and leading blanks. Header-only (shared by the
 * daemon and the clients).
 */
#ifndef CS_NUMBER_H
#define CS_NUMBER_H

#include <ctype.h>
#include <math.h>
#include <stdlib.h>

/* *out = s read as a decimal number. Returns 0, -1 if s is not one (syntax), -2 if it is one
 * too large for a double (1e400). A value too small (1e-400) reads as 0 or subnormal. */
static inline int cs_parse_decimal(const char *s, double *out)
{
    const char *p = s;
    if (*p == '+' || *p == '-')
        p++;
    int digits = 0;
    while (isdigit((unsigned char)*p))
        p++, digits++;
    if (*p == '.')
        for (p++; isdigit((unsigned char)*p); p++)
            digits++;
    if (digits == 0)
        return -1;
    if (*p == 'e' || *p == 'E') {
        p++;
        if (*p == '+' || *p == '-')
            p++;
        if (!isdigit((unsigned char)*p))
            return -1;
        while (isdigit((unsigned char)*p))
            p++;
    }
    if (*p)
        return -1;
    char *end = NULL;
    const double v = strtod(s, &end);
    if (end != p) /* strtod read another syntax (a locale with a decimal comma) */
        return -1;
    if (!isfinite(v))
        return -2;
    *out = v;
    return 0;
}

#endif
