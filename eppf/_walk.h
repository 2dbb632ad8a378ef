/* f4 line walks of a batch of pairs, four pairs at a time in AVX2 lanes.
 *
 * Used by _core.pyx for grids of at most 64 voxels a side, where a voxel
 * position fits the packed fixed-point form of _core.pyx's ``_line_bin``:
 * x, y, z in three 21-bit lanes of one int64, 14 fraction bits each, so one
 * addition advances all three axes by a step. The walk here visits exactly
 * the voxels ``_line_bin`` visits, and stops only once the f4 bin is certain,
 * so the bins are identical; only the order in which pairs are walked
 * changes (pairs are grouped by line length so that the four lanes of a group
 * need similar numbers of steps).
 *
 * Stopping rule, per pair: with ``occ`` the occupied voxels counted so far
 * (both end voxels included) and ``rem`` the inner voxels not yet looked at,
 * the bin is certain once occ >= hi (top bin) or occ + rem < lo (bottom bin),
 * or when rem == 0. Every empty voxel lowers occ + rem by one, so the next
 * ``occ + rem - lo + 1`` steps can be walked without a test: a phase walks
 * that many steps (at most rem) in every lane, then the rule is applied again.
 *
 * The AVX2 code is compiled with a target attribute and chosen at run time
 * (``eppf_walk_has_avx2``); other compilers and CPUs use the scalar walk of
 * _core.pyx. No floating point is involved beyond the setup, which uses the
 * same expressions as _core.pyx.
 */
#ifndef EPPF_WALK_H
#define EPPF_WALK_H

#include <stdint.h>
#include <math.h>

#if defined(__GNUC__) && defined(__x86_64__) && !defined(EPPF_NO_SIMD)
#define EPPF_WALK_SIMD 1
#include <immintrin.h>
#else
#define EPPF_WALK_SIMD 0
#endif

#define EPPF_PK_S (1 << 14)
#define EPPF_PK_X ((int64_t)1 << 42)
#define EPPF_PK_Y ((int64_t)1 << 21)
#define EPPF_WALK_BATCH 64

static int eppf_walk_has_avx2(void)
{
#if EPPF_WALK_SIMD
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") != 0;
#else
    return 0;
#endif
}

#if EPPF_WALK_SIMD

/* Add to ``B[t]`` the f4 bin of pair (ii[t], jj[t]) for t < m (m <= 64).
 *
 * vox: (n, 3) voxel coordinates; bits: the grid, one 64-bit word per (x, y)
 * row (g <= 64); thr[T * n4 + b] = ceil(b T / n4); recip_packed[L] = 2**14 / L.
 */
__attribute__((target("avx2")))
static void eppf_f4_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const int32_t *vox,
                               const uint64_t *bits, int64_t g, const int32_t *thr, int n4,
                               const double *recip_packed, int32_t *B)
{
    int64_t P[EPPF_WALK_BATCH + 4], INC[EPPF_WALK_BATCH + 4];
    int64_t OCC[EPPF_WALK_BATCH + 4], REM[EPPF_WALK_BATCH + 4];
    int64_t LO[EPPF_WALK_BATCH + 4], HI[EPPF_WALK_BATCH + 4];
    int32_t Ls[EPPF_WALK_BATCH];
    int order[EPPF_WALK_BATCH + 4];
    int count[65];
    int t, k, n_walk = 0;

    for (k = 0; k < 65; k++)
        count[k] = 0;
    /* Setup (same expressions as _line_bin), and a count of line lengths. */
    for (t = 0; t < m; t++) {
        const int32_t *va = vox + 3 * (int64_t)ii[t], *vb = vox + 3 * (int64_t)jj[t];
        int64_t dx = vb[0] - va[0], dy = vb[1] - va[1], dz = vb[2] - va[2];
        int64_t L = dx >= 0 ? dx : -dx, a;
        a = dy >= 0 ? dy : -dy;
        if (a > L) L = a;
        a = dz >= 0 ? dz : -dz;
        if (a > L) L = a;
        Ls[t] = (int32_t)L;
        count[L]++;
    }
    /* Pairs with L <= 1 have no inner voxel: occ = L + 1 exactly. The others
       are walked, longest lines first, grouped by length. */
    {
        int start[65], s = 0;
        for (k = 64; k >= 2; k--) {
            start[k] = s;
            s += count[k];
        }
        n_walk = s;
        for (t = 0; t < m; t++) {
            int L = Ls[t];
            if (L > 1)
                order[start[L]++] = t;
        }
    }
    for (k = 0; k < n_walk; k++) {
        t = order[k];
        {
            const int32_t *va = vox + 3 * (int64_t)ii[t], *vb = vox + 3 * (int64_t)jj[t];
            int64_t dx = vb[0] - va[0], dy = vb[1] - va[1], dz = vb[2] - va[2];
            int64_t L = Ls[t];
            const int32_t *th = thr + (L + 1) * n4;
            double q = recip_packed[L];
            int64_t ix = llrint(dx * q), iy = llrint(dy * q), iz = llrint(dz * q);
            int64_t inc = ix * EPPF_PK_X + iy * EPPF_PK_Y + iz;
            int64_t p = ((va[0] * EPPF_PK_S + EPPF_PK_S / 2 + g) * EPPF_PK_X
                         + (va[1] * EPPF_PK_S + EPPF_PK_S / 2 + g) * EPPF_PK_Y
                         + va[2] * EPPF_PK_S + EPPF_PK_S / 2 + g);
            P[k] = p + inc;
            INC[k] = inc;
            OCC[k] = 2;
            REM[k] = L - 1;
            LO[k] = th[1];
            HI[k] = th[n4 - 1];
        }
    }
    /* Pad the last group with lanes that have nothing to walk. */
    for (k = n_walk; k < n_walk + 4; k++) {
        P[k] = 0;
        INC[k] = 0;
        OCC[k] = 0;
        REM[k] = 0;
        LO[k] = 0;
        HI[k] = 0;
    }

    {
        const __m256i one = _mm256_set1_epi64x(1), m63 = _mm256_set1_epi64x(63);
        const __m256i zero = _mm256_setzero_si256();
        const __m256i vg = _mm256_set1_epi64x(g);
        const long long *base = (const long long *)bits;
        int grp;
        for (grp = 0; grp < n_walk; grp += 4) {
            __m256i p = _mm256_loadu_si256((const __m256i *)(P + grp));
            __m256i inc = _mm256_loadu_si256((const __m256i *)(INC + grp));
            __m256i occ = _mm256_loadu_si256((const __m256i *)(OCC + grp));
            __m256i rem = _mm256_loadu_si256((const __m256i *)(REM + grp));
            __m256i lo = _mm256_loadu_si256((const __m256i *)(LO + grp));
            __m256i hi = _mm256_loadu_si256((const __m256i *)(HI + grp));
            for (;;) {
                /* steps = occ < hi ? clamp(occ + rem - lo + 1, 0, rem) : 0 */
                __m256i need = _mm256_add_epi64(_mm256_sub_epi64(_mm256_add_epi64(occ, rem), lo), one);
                __m256i steps = _mm256_blendv_epi8(rem, need, _mm256_cmpgt_epi64(rem, need));
                __m256i live = _mm256_cmpgt_epi64(hi, occ);
                int64_t st[4], nmax, s;
                steps = _mm256_and_si256(steps, _mm256_and_si256(live, _mm256_cmpgt_epi64(steps, zero)));
                _mm256_storeu_si256((__m256i *)st, steps);
                nmax = st[0];
                if (st[1] > nmax) nmax = st[1];
                if (st[2] > nmax) nmax = st[2];
                if (st[3] > nmax) nmax = st[3];
                if (nmax == 0)
                    break;
                rem = _mm256_sub_epi64(rem, steps);
                if (g == 64) {
                    for (s = 0; s < nmax; s++) {
                        __m256i on = _mm256_cmpgt_epi64(steps, _mm256_set1_epi64x(s));
                        __m256i row = _mm256_add_epi64(_mm256_slli_epi64(_mm256_srli_epi64(p, 56), 6),
                                                       _mm256_and_si256(_mm256_srli_epi64(p, 35), m63));
                        __m256i w = _mm256_mask_i64gather_epi64(zero, base, row, on, 8);
                        __m256i z = _mm256_and_si256(_mm256_srli_epi64(p, 14), m63);
                        occ = _mm256_add_epi64(occ, _mm256_and_si256(_mm256_srlv_epi64(w, z), one));
                        p = _mm256_add_epi64(p, _mm256_and_si256(inc, on));
                    }
                } else {
                    for (s = 0; s < nmax; s++) {
                        __m256i on = _mm256_cmpgt_epi64(steps, _mm256_set1_epi64x(s));
                        __m256i row = _mm256_add_epi64(_mm256_mul_epu32(_mm256_srli_epi64(p, 56), vg),
                                                       _mm256_and_si256(_mm256_srli_epi64(p, 35), m63));
                        __m256i w = _mm256_mask_i64gather_epi64(zero, base, row, on, 8);
                        __m256i z = _mm256_and_si256(_mm256_srli_epi64(p, 14), m63);
                        occ = _mm256_add_epi64(occ, _mm256_and_si256(_mm256_srlv_epi64(w, z), one));
                        p = _mm256_add_epi64(p, _mm256_and_si256(inc, on));
                    }
                }
            }
            _mm256_storeu_si256((__m256i *)(OCC + grp), occ);
        }
    }

    /* Bins: the thresholds the count reaches. */
    for (k = 0; k < n_walk; k++) {
        int64_t L, o = OCC[k];
        const int32_t *th;
        int b = 0, j;
        t = order[k];
        L = Ls[t];
        th = thr + (L + 1) * n4;
        for (j = 1; j < n4; j++)
            b += o >= th[j];
        B[t] += b;
    }
    for (t = 0; t < m; t++) {
        int64_t L = Ls[t];
        if (L <= 1) {
            const int32_t *th = thr + (L + 1) * n4;
            int b = 0, j;
            for (j = 1; j < n4; j++)
                b += (L + 1) >= th[j];
            B[t] += b;
        }
    }
}

#else

static void eppf_f4_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const int32_t *vox,
                               const uint64_t *bits, int64_t g, const int32_t *thr, int n4,
                               const double *recip_packed, int32_t *B)
{
    (void)m; (void)ii; (void)jj; (void)vox; (void)bits; (void)g; (void)thr; (void)n4;
    (void)recip_packed; (void)B;
}

#endif

#endif /* EPPF_WALK_H */
