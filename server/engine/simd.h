/*
 * simd.h — which vector width the element kernels use.
 *
 * The modal element products (fem.c in double, the V-cycle's in float, mg.c) have 256-bit and
 * 512-bit forms with the same arithmetic per lane, so the same bits either way; only the speed
 * differs, and it depends on the core. Zen 4 executes a 512-bit operation as two 256-bit halves,
 * and there the 512-bit forms measured slower (bench/HISTORY.md, sessions 12 and 46); Intel's
 * AVX-512 cores (and Zen 5) execute them at full width, where the 512-bit double product ran
 * 1.27× faster (session 47, an Intel Xeon). The default follows the vendor and family; a world
 * may set the width (cs_world_def.simd_width).
 */
#ifndef CS_SIMD_H
#define CS_SIMD_H

#include <stdbool.h>

#include <cpuid.h>

/* True when the CPU has AVX-512 (x86-64-v4) and executes 512-bit vectors at full width. */
static inline bool cs_simd_wide_default(void)
{
    if (!__builtin_cpu_supports("x86-64-v4"))
        return false;
    if (__builtin_cpu_is("intel"))
        return true;
    unsigned a, b, c, d;
    if (!__builtin_cpu_is("amd") || !__get_cpuid(1, &a, &b, &c, &d))
        return false;
    const unsigned family = ((a >> 8) & 0xf) == 0xf ? 0xf + ((a >> 20) & 0xff) : (a >> 8) & 0xf;
    return family >= 0x1a; /* Zen 5 on */
}

/* The width for a requested one: 512 or 256 bits, 0 = the CPU's default. 512 only with
 * AVX-512. */
static inline bool cs_simd_wide(int bits)
{
    if (bits == 256)
        return false;
    if (bits == 512)
        return __builtin_cpu_supports("x86-64-v4");
    return cs_simd_wide_default();
}

#endif
