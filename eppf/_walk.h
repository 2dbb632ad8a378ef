/* AVX2 kernels of a batch of pairs, four pairs at a time: the f1-f3 bins
 * (``eppf_f123_batch_avx2``) and the f4 line walks (``eppf_f4_batch_avx2``).
 *
 * f1-f3: the same IEEE operations in the same order as _core.pyx's
 * ``_bin_f123`` (no FMA: the target is plain "avx2" and the build passes
 * -ffp-contract=off), so the bins are bit-identical.
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

/* 4 points (x, y, z) at rows r[0..3] of an (n, 3) array, as x, y, z vectors. */
__attribute__((target("avx2")))
static inline void eppf_load3x4(const double *a, const int32_t *r, __m256d *x, __m256d *y, __m256d *z)
{
    const __m256i keep3 = _mm256_set_epi64x(0, -1, -1, -1);
    __m256d p0 = _mm256_maskload_pd(a + 3 * (int64_t)r[0], keep3);  /* x0 y0 z0 0 */
    __m256d p1 = _mm256_maskload_pd(a + 3 * (int64_t)r[1], keep3);
    __m256d p2 = _mm256_maskload_pd(a + 3 * (int64_t)r[2], keep3);
    __m256d p3 = _mm256_maskload_pd(a + 3 * (int64_t)r[3], keep3);
    __m256d t0 = _mm256_unpacklo_pd(p0, p1);  /* x0 x1 z0 z1 */
    __m256d t1 = _mm256_unpackhi_pd(p0, p1);  /* y0 y1 0 0 */
    __m256d t2 = _mm256_unpacklo_pd(p2, p3);  /* x2 x3 z2 z3 */
    __m256d t3 = _mm256_unpackhi_pd(p2, p3);  /* y2 y3 0 0 */
    *x = _mm256_permute2f128_pd(t0, t2, 0x20);
    *y = _mm256_permute2f128_pd(t1, t3, 0x20);
    *z = _mm256_permute2f128_pd(t0, t2, 0x31);
}

/* B[t] = ((b1 * n2 + b2) * n3 + b3) * n4 for the pairs (ii[t], jj[t]), t < m,
 * exactly as _core.pyx's ``_bin_f123``; cos2 / cos3 hold the n2 - 1 / n3 - 1
 * inner bin edges on the cosine scale. */
__attribute__((target("avx2")))
static void eppf_f123_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const double *pts,
                                 const double *nrm, double scale, int n1, int n2, int n3, int n4,
                                 double f1_density, const double *cos2, const double *cos3, int32_t *B)
{
    int32_t ri[4], rj[4];
    int32_t out[4];
    const __m256d vscale = _mm256_set1_pd(scale), vdens = _mm256_set1_pd(f1_density);
    const __m256d top1 = _mm256_set1_pd((double)(n1 - 1)), one = _mm256_set1_pd(1.0);
    const __m256d sign = _mm256_set1_pd(-0.0);
    int t, l, k;
    for (t = 0; t < m; t += 4) {
        __m256d pix, piy, piz, pjx, pjy, pjz, nix, niy, niz, njx, njy, njz;
        __m256d dx, dy, dz, dist, inv, m1, m2, v;
        __m128i b1, b2, b3, b;
        for (l = 0; l < 4; l++) {  /* a partial last group repeats its last pair */
            int u = t + l < m ? t + l : m - 1;
            ri[l] = ii[u];
            rj[l] = jj[u];
        }
        eppf_load3x4(pts, ri, &pix, &piy, &piz);
        eppf_load3x4(pts, rj, &pjx, &pjy, &pjz);
        dx = _mm256_sub_pd(pjx, pix);
        dy = _mm256_sub_pd(pjy, piy);
        dz = _mm256_sub_pd(pjz, piz);
        dist = _mm256_sqrt_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                                            _mm256_mul_pd(dz, dz)));
        /* f1: min(v * density, n1 - 1) truncated (a NaN lands in the top bin). */
        v = _mm256_mul_pd(_mm256_mul_pd(dist, vscale), vdens);
        b1 = _mm256_cvttpd_epi32(_mm256_min_pd(v, top1));
        b2 = _mm_setzero_si128();
        b3 = _mm_setzero_si128();
        if (n2 > 1 || n3 > 1) {
            eppf_load3x4(nrm, ri, &nix, &niy, &niz);
            eppf_load3x4(nrm, rj, &njx, &njy, &njz);
        }
        if (n2 > 1) {
            inv = _mm256_div_pd(one, dist);
            m1 = _mm256_mul_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nix, dx), _mm256_mul_pd(niy, dy)),
                                             _mm256_mul_pd(niz, dz)), inv);
            m2 = _mm256_mul_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(njx, dx), _mm256_mul_pd(njy, dy)),
                                             _mm256_mul_pd(njz, dz)), inv);
            m1 = _mm256_min_pd(m2, m1);  /* m2 < m1 ? m2 : m1 */
            for (k = 0; k < n2 - 1; k++) {
                __m256d le = _mm256_cmp_pd(m1, _mm256_set1_pd(cos2[k]), _CMP_LE_OQ);
                b2 = _mm_add_epi32(b2, _mm256_cvtpd_epi32(_mm256_and_pd(le, one)));  /* 1 where m1 <= edge */
            }
        }
        if (n3 > 1) {
            v = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nix, njx), _mm256_mul_pd(niy, njy)),
                              _mm256_mul_pd(niz, njz));
            v = _mm256_andnot_pd(sign, v);
            for (k = 0; k < n3 - 1; k++) {
                __m256d le = _mm256_cmp_pd(v, _mm256_set1_pd(cos3[k]), _CMP_LE_OQ);
                b3 = _mm_add_epi32(b3, _mm256_cvtpd_epi32(_mm256_and_pd(le, one)));
            }
        }
        b = _mm_add_epi32(_mm_mullo_epi32(b1, _mm_set1_epi32(n2)), b2);
        b = _mm_add_epi32(_mm_mullo_epi32(b, _mm_set1_epi32(n3)), b3);
        b = _mm_mullo_epi32(b, _mm_set1_epi32(n4));
        _mm_storeu_si128((__m128i *)out, b);
        for (l = 0; l < 4 && t + l < m; l++)
            B[t + l] = out[l];
    }
}

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

static void eppf_f123_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const double *pts,
                                 const double *nrm, double scale, int n1, int n2, int n3, int n4,
                                 double f1_density, const double *cos2, const double *cos3, int32_t *B)
{
    (void)m; (void)ii; (void)jj; (void)pts; (void)nrm; (void)scale; (void)n1; (void)n2; (void)n3;
    (void)n4; (void)f1_density; (void)cos2; (void)cos3; (void)B;
}

static void eppf_f4_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const int32_t *vox,
                               const uint64_t *bits, int64_t g, const int32_t *thr, int n4,
                               const double *recip_packed, int32_t *B)
{
    (void)m; (void)ii; (void)jj; (void)vox; (void)bits; (void)g; (void)thr; (void)n4;
    (void)recip_packed; (void)B;
}

#endif

#endif /* EPPF_WALK_H */
