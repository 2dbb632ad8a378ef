/* Level 1 of _eppf_walk.h: AVX2, four pairs at a time: the f1-f3 bins
 * (``eppf_f123_batch_avx2``) and the f4 line walks of a batch, grouped by
 * line length (``eppf_f4_batch_avx2``). */
#ifndef EPPF_WALK_AVX2_H
#define EPPF_WALK_AVX2_H

#include "_eppf_walk_common.h"

#if EPPF_WALK_SIMD

/* 4 points (x, y, z) at rows r[0..3] of an array with rows of ``stride``
 * doubles, as x, y, z vectors. */
__attribute__((target("avx2")))
static inline void eppf_load3x4(const double *a, int64_t stride, const int32_t *r, __m256d *x, __m256d *y,
                                __m256d *z)
{
    const __m256i keep3 = _mm256_set_epi64x(0, -1, -1, -1);
    __m256d p0 = _mm256_maskload_pd(a + stride * r[0], keep3);  /* x0 y0 z0 0 */
    __m256d p1 = _mm256_maskload_pd(a + stride * r[1], keep3);
    __m256d p2 = _mm256_maskload_pd(a + stride * r[2], keep3);
    __m256d p3 = _mm256_maskload_pd(a + stride * r[3], keep3);
    __m256d t0 = _mm256_unpacklo_pd(p0, p1);  /* x0 x1 z0 z1 */
    __m256d t1 = _mm256_unpackhi_pd(p0, p1);  /* y0 y1 0 0 */
    __m256d t2 = _mm256_unpacklo_pd(p2, p3);  /* x2 x3 z2 z3 */
    __m256d t3 = _mm256_unpackhi_pd(p2, p3);  /* y2 y3 0 0 */
    *x = _mm256_permute2f128_pd(t0, t2, 0x20);
    *y = _mm256_permute2f128_pd(t1, t3, 0x20);
    *z = _mm256_permute2f128_pd(t0, t2, 0x31);
}

/* B[t] = ((b1 * n2 + b2) * n3 + b3) * n4 for the pairs (ii[t], jj[t]), t < m,
 * exactly as _eppf_fast.pyx's ``_bin_f123``; cos2 / cos3 hold the n2 - 1 / n3 - 1
 * inner bin edges on the cosine scale. */
__attribute__((target("avx2")))
static void eppf_f123_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                                 const double *nrm, int64_t ns, double scale, int n1, int n2, int n3, int n4,
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
        eppf_load3x4(pts, ps, ri, &pix, &piy, &piz);
        eppf_load3x4(pts, ps, rj, &pjx, &pjy, &pjz);
        dx = _mm256_sub_pd(pjx, pix);
        dy = _mm256_sub_pd(pjy, piy);
        dz = _mm256_sub_pd(pjz, piz);
        dist = _mm256_sqrt_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                                            _mm256_mul_pd(dz, dz)));
        /* f1: max(min(v * density, n1 - 1), 0) truncated: clamped in floating
           point before the conversion, so a NaN or +inf lands in the top bin
           (min_pd returns its second operand when one is NaN) and a negative
           value in bin 0, as in _bin_f123. */
        v = _mm256_mul_pd(_mm256_mul_pd(dist, vscale), vdens);
        b1 = _mm256_cvttpd_epi32(_mm256_max_pd(_mm256_min_pd(v, top1), _mm256_setzero_pd()));
        b2 = _mm_setzero_si128();
        b3 = _mm_setzero_si128();
        if (n2 > 1 || n3 > 1) {
            eppf_load3x4(nrm, ns, ri, &nix, &niy, &niz);
            eppf_load3x4(nrm, ns, rj, &njx, &njy, &njz);
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

/* The setup of the walks of pairs (ii[t], jj[t]), t < m <= EPPF_WALK_BATCH,
 * four pairs at a time in original order: line length L, the packed start P
 * (first inner voxel) and increment INC, the thresholds LO = thr[1] and
 * HI = thr[n4 - 1] of T = L + 1 voxels. vox: (n, 3) voxel coordinates;
 * thr[T * n4 + b] = ceil(b T / n4). */
__attribute__((target("avx2")))
static void eppf_f4_setup_avx2(int m, const int32_t *ii, const int32_t *jj, const int32_t *vox, int64_t g,
                               const int32_t *thr, int n4, int64_t *P, int64_t *INC, int32_t *Ls, int32_t *LO,
                               int32_t *HI)
{
    int32_t ri[EPPF_WALK_BATCH + 4] __attribute__((aligned(16)));
    int32_t rj[EPPF_WALK_BATCH + 4] __attribute__((aligned(16)));
    int t;

    /* Row offsets of the two points of each pair, padded to a multiple of 4
       with the first pair (its lanes are computed and ignored). */
    for (t = 0; t < m; t++) {
        ri[t] = 3 * ii[t];
        rj[t] = 3 * jj[t];
    }
    for (; t < ((m + 3) & ~3); t++) {
        ri[t] = ri[0];
        rj[t] = rj[0];
    }
    {
        const __m128i n4v = _mm_set1_epi32(n4), onev = _mm_set1_epi32(1), n4m1 = _mm_set1_epi32(n4 - 1);
        const __m256d S = _mm256_set1_pd((double)EPPF_PK_S);
        const __m256i off = _mm256_set1_epi64x(EPPF_PK_S / 2 + g);
        for (t = 0; t < m; t += 4) {
            __m128i ra = _mm_load_si128((const __m128i *)(ri + t)), rb = _mm_load_si128((const __m128i *)(rj + t));
            __m128i ax = _mm_i32gather_epi32(vox, ra, 4);
            __m128i ay = _mm_i32gather_epi32(vox + 1, ra, 4);
            __m128i az = _mm_i32gather_epi32(vox + 2, ra, 4);
            __m128i dx = _mm_sub_epi32(_mm_i32gather_epi32(vox, rb, 4), ax);
            __m128i dy = _mm_sub_epi32(_mm_i32gather_epi32(vox + 1, rb, 4), ay);
            __m128i dz = _mm_sub_epi32(_mm_i32gather_epi32(vox + 2, rb, 4), az);
            __m128i L = _mm_max_epi32(_mm_max_epi32(_mm_abs_epi32(dx), _mm_abs_epi32(dy)), _mm_abs_epi32(dz));
            __m128i row = _mm_mullo_epi32(_mm_add_epi32(L, onev), n4v);
            /* 2**14 / L, the same correctly rounded division as recip_packed[L]
               (L <= 1 lanes are never walked; max(L, 1) only keeps them finite) */
            __m256d q = _mm256_div_pd(S, _mm256_cvtepi32_pd(_mm_max_epi32(L, onev)));
            __m128i ix = _mm256_cvtpd_epi32(_mm256_mul_pd(_mm256_cvtepi32_pd(dx), q));  /* = llrint */
            __m128i iy = _mm256_cvtpd_epi32(_mm256_mul_pd(_mm256_cvtepi32_pd(dy), q));
            __m128i iz = _mm256_cvtpd_epi32(_mm256_mul_pd(_mm256_cvtepi32_pd(dz), q));
            __m256i inc = _mm256_add_epi64(_mm256_add_epi64(_mm256_slli_epi64(_mm256_cvtepi32_epi64(ix), 42),
                                                            _mm256_slli_epi64(_mm256_cvtepi32_epi64(iy), 21)),
                                           _mm256_cvtepi32_epi64(iz));
            __m256i p0 = _mm256_add_epi64(
                _mm256_add_epi64(_mm256_slli_epi64(_mm256_add_epi64(_mm256_slli_epi64(_mm256_cvtepi32_epi64(ax), EPPF_PK_FRAC), off), EPPF_PK_XLANE),
                                 _mm256_slli_epi64(_mm256_add_epi64(_mm256_slli_epi64(_mm256_cvtepi32_epi64(ay), EPPF_PK_FRAC), off), EPPF_PK_YLANE)),
                _mm256_add_epi64(_mm256_slli_epi64(_mm256_cvtepi32_epi64(az), EPPF_PK_FRAC), off));
            _mm256_store_si256((__m256i *)(P + t), _mm256_add_epi64(p0, inc));
            _mm256_store_si256((__m256i *)(INC + t), inc);
            _mm_store_si128((__m128i *)(Ls + t), L);
            _mm_store_si128((__m128i *)(LO + t), _mm_i32gather_epi32(thr + 1, row, 4));
            _mm_store_si128((__m128i *)(HI + t), _mm_i32gather_epi32(thr, _mm_add_epi32(row, n4m1), 4));
        }
    }
}

/* Add to ``B[t]`` the f4 bin of pair (ii[t], jj[t]) for t < m <= EPPF_WALK_BATCH.
 *
 * bits: the grid, one 64-bit word per (x, y) row (g <= 64). After the setup,
 * the walks take the pairs longest line first, in groups of four, so that
 * the lanes of a group need similar numbers of steps.
 */
__attribute__((target("avx2")))
static void eppf_f4_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const int32_t *vox,
                               const uint64_t *bits, int64_t g, const int32_t *thr, int n4,
                               const double *recip_packed, int32_t *B)
{
    int64_t P[EPPF_WALK_BATCH + 4] __attribute__((aligned(32)));
    int64_t INC[EPPF_WALK_BATCH + 4] __attribute__((aligned(32)));
    int32_t Ls[EPPF_WALK_BATCH + 4] __attribute__((aligned(16)));
    int32_t LO[EPPF_WALK_BATCH + 4] __attribute__((aligned(16)));
    int32_t HI[EPPF_WALK_BATCH + 4] __attribute__((aligned(16)));
    int order[EPPF_WALK_BATCH + 4];
    int k, n_walk;
    (void)recip_packed;

    eppf_f4_setup_avx2(m, ii, jj, vox, g, thr, n4, P, INC, Ls, LO, HI);
    /* Walk order: L descending; L <= 1 (no inner voxel, occ = L + 1) last, unwalked. */
    n_walk = eppf_f4_order(m, Ls, order);
    for (k = n_walk; k < n_walk + 4; k++)
        order[k] = -1;

    {
        const __m256i one = _mm256_set1_epi64x(1), two = _mm256_set1_epi64x(2), m63 = _mm256_set1_epi64x(63);
        const __m256i zero = _mm256_setzero_si256();
        const __m256i vg = _mm256_set1_epi64x(g);
        const long long *base = (const long long *)bits;
        int grp;
        for (grp = 0; grp < n_walk; grp += 4) {
            const int o0 = order[grp], o1 = order[grp + 1], o2 = order[grp + 2], o3 = order[grp + 3];
            /* Missing lanes of the last group: nothing to walk (rem = 0, occ = lo = hi = 0). */
            const int u1 = o1 >= 0 ? o1 : o0, u2 = o2 >= 0 ? o2 : o0, u3 = o3 >= 0 ? o3 : o0;
            const __m256i valid = _mm256_set_epi64x(o3 >= 0 ? -1 : 0, o2 >= 0 ? -1 : 0, o1 >= 0 ? -1 : 0, -1);
            __m256i p = _mm256_set_epi64x(P[u3], P[u2], P[u1], P[o0]);
            __m256i inc = _mm256_set_epi64x(INC[u3], INC[u2], INC[u1], INC[o0]);
            __m256i lo = _mm256_and_si256(valid, _mm256_set_epi64x(LO[u3], LO[u2], LO[u1], LO[o0]));
            __m256i hi = _mm256_and_si256(valid, _mm256_set_epi64x(HI[u3], HI[u2], HI[u1], HI[o0]));
            __m256i rem = _mm256_and_si256(valid, _mm256_set_epi64x(Ls[u3] - 1, Ls[u2] - 1, Ls[u1] - 1, Ls[o0] - 1));
            __m256i occ = _mm256_and_si256(valid, two);
            int64_t res[4] __attribute__((aligned(32)));
            int l;
            for (;;) {
                /* steps = occ < hi ? clamp(occ + rem - lo + 1, 0, rem) : 0 */
                __m256i need = _mm256_add_epi64(_mm256_sub_epi64(_mm256_add_epi64(occ, rem), lo), one);
                __m256i steps = _mm256_blendv_epi8(rem, need, _mm256_cmpgt_epi64(rem, need));
                __m256i live = _mm256_cmpgt_epi64(hi, occ);
                int64_t st[4] __attribute__((aligned(32))), nmax, nmin, s;
                steps = _mm256_and_si256(steps, _mm256_and_si256(live, _mm256_cmpgt_epi64(steps, zero)));
                _mm256_store_si256((__m256i *)st, steps);
                nmax = st[0];
                if (st[1] > nmax) nmax = st[1];
                if (st[2] > nmax) nmax = st[2];
                if (st[3] > nmax) nmax = st[3];
                if (nmax == 0)
                    break;
                rem = _mm256_sub_epi64(rem, steps);
                nmin = st[0];
                if (st[1] < nmin) nmin = st[1];
                if (st[2] < nmin) nmin = st[2];
                if (st[3] < nmin) nmin = st[3];
                /* Every lane position is a voxel of its line (or of a valid
                   pair for padding lanes), so the gathers need no mask: lanes
                   past their steps drop the word and stand still. */
                if (g == 64) {
                    for (s = 0; s < nmin; s++) {
                        __m256i row = _mm256_add_epi64(_mm256_slli_epi64(_mm256_srli_epi64(p, EPPF_PK_XSHIFT), 6),
                                                       _mm256_and_si256(_mm256_srli_epi64(p, EPPF_PK_YSHIFT), m63));
                        __m256i w = _mm256_i64gather_epi64(base, row, 8);
                        __m256i z = _mm256_and_si256(_mm256_srli_epi64(p, EPPF_PK_ZSHIFT), m63);
                        occ = _mm256_add_epi64(occ, _mm256_and_si256(_mm256_srlv_epi64(w, z), one));
                        p = _mm256_add_epi64(p, inc);
                    }
                    for (; s < nmax; s++) {
                        __m256i on = _mm256_cmpgt_epi64(steps, _mm256_set1_epi64x(s));
                        __m256i row = _mm256_add_epi64(_mm256_slli_epi64(_mm256_srli_epi64(p, EPPF_PK_XSHIFT), 6),
                                                       _mm256_and_si256(_mm256_srli_epi64(p, EPPF_PK_YSHIFT), m63));
                        __m256i w = _mm256_and_si256(_mm256_i64gather_epi64(base, row, 8), on);
                        __m256i z = _mm256_and_si256(_mm256_srli_epi64(p, EPPF_PK_ZSHIFT), m63);
                        occ = _mm256_add_epi64(occ, _mm256_and_si256(_mm256_srlv_epi64(w, z), one));
                        p = _mm256_add_epi64(p, _mm256_and_si256(inc, on));
                    }
                } else {
                    for (s = 0; s < nmax; s++) {
                        __m256i on = _mm256_cmpgt_epi64(steps, _mm256_set1_epi64x(s));
                        __m256i row = _mm256_add_epi64(_mm256_mul_epu32(_mm256_srli_epi64(p, EPPF_PK_XSHIFT), vg),
                                                       _mm256_and_si256(_mm256_srli_epi64(p, EPPF_PK_YSHIFT), m63));
                        __m256i w = _mm256_and_si256(_mm256_i64gather_epi64(base, row, 8), on);
                        __m256i z = _mm256_and_si256(_mm256_srli_epi64(p, EPPF_PK_ZSHIFT), m63);
                        occ = _mm256_add_epi64(occ, _mm256_and_si256(_mm256_srlv_epi64(w, z), one));
                        p = _mm256_add_epi64(p, _mm256_and_si256(inc, on));
                    }
                }
            }
            /* The bin: how many thresholds ceil(b T / n4), b = 1..n4-1, the count reaches. */
            if (n4 <= 3) {
                /* lo and hi are all the thresholds (one and the same for n4 = 2). */
                /* occ >= lo is 1 + (lo > occ ? -1 : 0) */
                __m256i b = _mm256_add_epi64(one, _mm256_cmpgt_epi64(lo, occ));
                if (n4 == 3)
                    b = _mm256_add_epi64(b, _mm256_add_epi64(one, _mm256_cmpgt_epi64(hi, occ)));
                _mm256_store_si256((__m256i *)res, b);
                B[o0] += (int32_t)res[0];
                if (o1 >= 0) B[o1] += (int32_t)res[1];
                if (o2 >= 0) B[o2] += (int32_t)res[2];
                if (o3 >= 0) B[o3] += (int32_t)res[3];
            } else {
                _mm256_store_si256((__m256i *)res, occ);
                for (l = 0; l < 4; l++) {
                    int o = order[grp + l], b = 0, j;
                    const int32_t *th;
                    if (o < 0)
                        break;
                    th = thr + (int64_t)(Ls[o] + 1) * n4;
                    for (j = 1; j < n4; j++)
                        b += res[l] >= th[j];
                    B[o] += b;
                }
            }
        }
    }
    /* Lines without inner voxels: occ = T = L + 1, all voxels occupied. */
    if (n_walk < m)
        eppf_f4_short_lines(m, Ls, thr, n4, B);
}

#else

static void eppf_f123_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                                 const double *nrm, int64_t ns, double scale, int n1, int n2, int n3, int n4,
                                 double f1_density, const double *cos2, const double *cos3, int32_t *B)
{
    (void)m; (void)ii; (void)jj; (void)pts; (void)ps; (void)nrm; (void)ns; (void)scale; (void)n1; (void)n2; (void)n3;
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

#endif /* EPPF_WALK_AVX2_H */
