/* The parts of _eppf_walk.h that every level shares: the packed line walk's
 * layout, the batch size, the CPU checks behind the choice of level and the
 * order and bins of a batch's walks (levels 1 and 2). */
#ifndef EPPF_WALK_COMMON_H
#define EPPF_WALK_COMMON_H

#include <stdint.h>
#include <string.h>
#include <math.h>

#include "../utils/_cpu.h"

#if EPPF_CPU_CHECKS  /* (gcc or clang on x86-64, EPPF_NO_SIMD not defined: _cpu.h) */
#define EPPF_WALK_SIMD 1
#include <immintrin.h>
#else
#define EPPF_WALK_SIMD 0
#endif

/* The packed line walk's layout, defined here once and read by _eppf_fast.pyx:
 * three lanes of 21 bits (x from bit 42, y from bit 21, z from bit 0), each a
 * voxel coordinate with EPPF_PK_FRAC fraction bits; the integer part of a
 * lane is found at EPPF_PK_{X,Y,Z}SHIFT. */
#define EPPF_PK_FRAC 14
#define EPPF_PK_YLANE 21
#define EPPF_PK_XLANE 42
#define EPPF_PK_ZSHIFT EPPF_PK_FRAC
#define EPPF_PK_YSHIFT (EPPF_PK_YLANE + EPPF_PK_FRAC)
#define EPPF_PK_XSHIFT (EPPF_PK_XLANE + EPPF_PK_FRAC)
#define EPPF_PK_S (1 << EPPF_PK_FRAC)
#define EPPF_PK_X ((int64_t)1 << EPPF_PK_XLANE)
#define EPPF_PK_Y ((int64_t)1 << EPPF_PK_YLANE)
/* The largest grid the packed walks serve: one 64-bit word of z bits per (x, y)
   row, and voxel coordinates that fit the 21-bit lanes. */
#define EPPF_WALK_MAX_GRID 64
/* Pairs per batch (the walks sort a batch by line length: a longer batch
   groups the lanes better, up to about this size). */
#define EPPF_WALK_BATCH 256
/* splitmix64's increment: the generator's state after k draws is seed + k * gamma
   (the SIMD draws take four or eight successive draws side by side). */
#define EPPF_SM_GAMMA 0x9E3779B97F4A7C15ULL

#define EPPF_AVX512_TARGET "avx2,avx512f,avx512bw,avx512vl,avx512dq,avx512vbmi"
/* Plain C compiled for AVX-512 where the SIMD kernels are built (it serves only them). */
#if EPPF_WALK_SIMD
#define EPPF_AVX512_FN __attribute__((target(EPPF_AVX512_TARGET)))
#else
#define EPPF_AVX512_FN
#endif

/* AVX-512 F, BW, VL, DQ and VBMI (with the OS saving the zmm state: libgcc's
   cpu check reads XCR0). */
static int eppf_walk_has_avx512(void)
{
    return eppf_cpu_has(EPPF_CPU_AVX2 | EPPF_CPU_AVX512F | EPPF_CPU_AVX512BW | EPPF_CPU_AVX512VL | EPPF_CPU_AVX512DQ
                        | EPPF_CPU_AVX512VBMI);
}

/* Whether the skipping AVX-512 walk (``eppf_f4_walkq_avx512``) is the better of
   the two AVX-512 walks here: on AMD Zen 4 an eight-element gather costs about
   13 cycles, and the skipping walk's 1.3 look-ups a pair (by scalar loads,
   against 3.0 gathers) pay for its extra vector work; where gathers are
   cheaper (Intel) the grouped walk's lighter steps are expected to win. Both
   give the same counts. */
static int eppf_walk_prefers_skips(void)
{
    return eppf_cpu_has(EPPF_CPU_AMD);
}

/* AVX2, and BMI2 (level 1's build of the portable walk uses its shifts). */
static int eppf_walk_has_avx2(void)
{
    return eppf_cpu_has(EPPF_CPU_AVX2 | EPPF_CPU_BMI2);
}

/* The f4 bin of occ occupied voxels on a line of T voxels: how many of the
   thresholds thr[T n4 + b], b = 1..n4-1, occ reaches. */
static inline int eppf_f4_bin(const int32_t *thr, int n4, int64_t T, int64_t occ)
{
    const int32_t *th = thr + T * n4;
    int b = 0, j;
    for (j = 1; j < n4; j++)
        b += occ >= th[j];
    return b;
}

/* The rows of ``eppf_f123_batch_avx512``'s, ``eppf_f123q_avx2``'s and
 * ``eppf_f123q_port``'s ``pn``: point k's x, y, z, nx, ny, nz at pn[8 k], then 16 bytes of its
 * voxel: at levels 2 and 3 its packed voxel pv[k] (the bits of the int64 in
 * a double's place) and an unused double; at levels 0 and 1 (pv NULL) its voxel's
 * x, y, z (``vox``, (n, 3) int32) and an int32 0; zeros where both are NULL.
 * So one 64-byte row holds a point, its normal and its voxel. */
static void eppf_pack_rows(int64_t n, const double *pts, int64_t ps, const double *nrm, int64_t ns,
                           const int64_t *pv, const int32_t *vox, double *pn)
{
    int64_t k;
    for (k = 0; k < n; k++) {
        double *r = pn + 8 * k;
        int32_t v[4] = {0, 0, 0, 0};
        r[0] = pts[ps * k];
        r[1] = pts[ps * k + 1];
        r[2] = pts[ps * k + 2];
        r[3] = nrm[ns * k];
        r[4] = nrm[ns * k + 1];
        r[5] = nrm[ns * k + 2];
        if (pv) {
            memcpy(v, pv + k, sizeof pv[k]);
        } else if (vox) {
            v[0] = vox[3 * k];
            v[1] = vox[3 * k + 1];
            v[2] = vox[3 * k + 2];
        }
        memcpy(r + 6, v, sizeof v);
    }
}

/* The skipping walks' lane state (``eppf_f4_walkq_avx512``, the portable
   ``eppf_port_walk``): four signed bytes R, U, O, X. */
#define EPPF_ST(r, u, o, x) ((int64_t)(((uint64_t)(uint8_t)(r)) | ((uint64_t)(uint8_t)(u) << 8)       \
                                       | ((uint64_t)(uint8_t)(o) << 16) | ((uint64_t)(uint8_t)(x) << 24)))
/* st[T] = the state of a line of T voxels before its first step, T = 1..64
   (0 for T > g + 1, past ``thr``'s rows [T, b], T = 0..g + 1, and for T = 0). */
static void eppf_walk_states(const int32_t *thr, int n4, int64_t g, int64_t *st)
{
    int T;
    for (T = 0; T <= EPPF_WALK_MAX_GRID; T++) {
        st[T] = 0;
        if (T >= 1 && T <= g + 1) {
            const int lo = thr[T * n4 + 1], hi = thr[T * n4 + n4 - 1];
            st[T] = EPPF_ST(T - 3, T - lo, hi - 3, lo - 3);
        }
    }
}

/* The words of one axis's cone grid (one half of it at level 3): 64 rows (x)
   of 64 words (y), whatever g. */
#define EPPF_CODE_AXIS_WORDS 4096

#if EPPF_WALK_SIMD
/* The pairs with inner voxels (L > 1) in walk order, longest line first, into
   ``order``; returns their number. */
static int eppf_f4_order(int m, const int32_t *Ls, int *order)
{
    int count[EPPF_WALK_MAX_GRID + 1], start[EPPF_WALK_MAX_GRID + 1];
    int t, k, n_walk;
    for (k = 0; k <= EPPF_WALK_MAX_GRID; k++)
        count[k] = 0;
    for (t = 0; t < m; t++)
        count[Ls[t]]++;
    {
        int s = 0;
        for (k = EPPF_WALK_MAX_GRID; k >= 2; k--) {
            start[k] = s;
            s += count[k];
        }
        n_walk = s;
    }
    for (t = 0; t < m; t++) {
        int L = Ls[t];
        if (L > 1)
            order[start[L]++] = t;
    }
    return n_walk;
}

/* f4 bins of the lines without inner voxels (L <= 1): occ = T = L + 1, all voxels occupied. */
static void eppf_f4_short_lines(int m, const int32_t *Ls, const int32_t *thr, int n4, int32_t *B)
{
    int t;
    for (t = 0; t < m; t++)
        if (Ls[t] <= 1)
            B[t] += eppf_f4_bin(thr, n4, Ls[t] + 1, Ls[t] + 1);
}
#endif

#endif /* EPPF_WALK_COMMON_H */
