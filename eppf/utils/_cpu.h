/* The CPU features the SIMD kernels choose their code by, in one place.
 *
 * ``eppf_cpu_has(EPPF_CPU_AVX2 | EPPF_CPU_BMI2)`` is 1 when the CPU (and, for
 * AVX-512, the OS, which must save the zmm state: libgcc's check reads XCR0)
 * supports every feature named; 0 otherwise, and always 0 where the kernels
 * are built without SIMD (another compiler or architecture, or EPPF_NO_SIMD).
 * The kernels' headers (_eppf_walk.h, _esf_kernel.h, _normals_simd.h) build
 * their run-time checks from it, and their own SIMD switches from
 * EPPF_CPU_CHECKS, so the condition for compiling SIMD code lives only here.
 *
 * The environment variable EPPF_SIMD caps what the kernels may use, so that
 * one machine can run the code paths of others: "scalar" (the portable C
 * code, as on ARM64), "avx2" (no AVX-512) or "avx512" (everything, the same
 * as unset). eppf checks the value when it is imported (eppf/utils/_simd.py)
 * and refuses anything else; here an unknown value caps nothing.
 */
#ifndef EPPF_CPU_H
#define EPPF_CPU_H

#include <stdlib.h>
#include <string.h>

#if defined(__GNUC__) && defined(__x86_64__) && !defined(EPPF_NO_SIMD)
#define EPPF_CPU_CHECKS 1
#else
#define EPPF_CPU_CHECKS 0
#endif

enum {
    EPPF_CPU_AVX2 = 1 << 0,
    EPPF_CPU_BMI2 = 1 << 1,
    EPPF_CPU_POPCNT = 1 << 2,
    EPPF_CPU_AVX512F = 1 << 3,
    EPPF_CPU_AVX512BW = 1 << 4,
    EPPF_CPU_AVX512VL = 1 << 5,
    EPPF_CPU_AVX512DQ = 1 << 6,
    EPPF_CPU_AVX512VBMI = 1 << 7,
    EPPF_CPU_GFNI = 1 << 8,
    EPPF_CPU_AMD = 1 << 9 /* the vendor, not a feature: AMD's gathers are slow */
};

/* The flags EPPF_SIMD allows (all of them when it is unset or unknown). */
static int eppf_cpu_allowed(void)
{
    const char* cap = getenv("EPPF_SIMD");
    const int avx512 = EPPF_CPU_AVX512F | EPPF_CPU_AVX512BW | EPPF_CPU_AVX512VL | EPPF_CPU_AVX512DQ
        | EPPF_CPU_AVX512VBMI | EPPF_CPU_GFNI;
    if (cap == NULL) return ~0;
    if (strcmp(cap, "scalar") == 0) return EPPF_CPU_AMD;
    if (strcmp(cap, "avx2") == 0) return ~avx512;
    return ~0;
}

/* Every flag above that this CPU has and EPPF_SIMD allows. Worked out once:
 * the first call comes from the module's import (its default level), on the
 * importing thread, before any kernel thread reads the cached value; later
 * calls (one an object in some kernels) cost a load, not getenv. */
static int eppf_cpu_features(void)
{
    static int cached = -1;
    int f = 0;
    if (cached >= 0) return cached;
#if EPPF_CPU_CHECKS
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx2")) f |= EPPF_CPU_AVX2;
    if (__builtin_cpu_supports("bmi2")) f |= EPPF_CPU_BMI2;
    if (__builtin_cpu_supports("popcnt")) f |= EPPF_CPU_POPCNT;
    if (__builtin_cpu_supports("avx512f")) f |= EPPF_CPU_AVX512F;
    if (__builtin_cpu_supports("avx512bw")) f |= EPPF_CPU_AVX512BW;
    if (__builtin_cpu_supports("avx512vl")) f |= EPPF_CPU_AVX512VL;
    if (__builtin_cpu_supports("avx512dq")) f |= EPPF_CPU_AVX512DQ;
    if (__builtin_cpu_supports("avx512vbmi")) f |= EPPF_CPU_AVX512VBMI;
    if (__builtin_cpu_supports("gfni")) f |= EPPF_CPU_GFNI;
    if (__builtin_cpu_is("amd")) f |= EPPF_CPU_AMD;
#endif
    cached = f & eppf_cpu_allowed();
    return cached;
}

static int eppf_cpu_has(int wanted)
{
    return (eppf_cpu_features() & wanted) == wanted;
}

#endif /* EPPF_CPU_H */
