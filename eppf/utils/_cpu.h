/* The CPU features the SIMD kernels choose their code by, in one place.
 *
 * ``eppf_cpu_has(EPPF_CPU_AVX2 | EPPF_CPU_BMI2)`` is 1 when the CPU (and, for
 * AVX-512, the OS, which must save the zmm state: libgcc's check reads XCR0)
 * supports every feature named; 0 otherwise, and always 0 where the kernels
 * are built without SIMD (another compiler or architecture, or EPPF_NO_SIMD).
 * The kernels' headers (_eppf_walk.h, _esf_kernel.h, _normals_simd.h) build
 * their run-time checks from it, and their own SIMD switches from
 * EPPF_CPU_CHECKS, so the condition for compiling SIMD code lives only here.
 */
#ifndef EPPF_CPU_H
#define EPPF_CPU_H

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

/* Every flag above that this CPU has. */
static int eppf_cpu_features(void)
{
    int f = 0;
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
    return f;
}

static int eppf_cpu_has(int wanted)
{
    return (eppf_cpu_features() & wanted) == wanted;
}

#endif /* EPPF_CPU_H */
