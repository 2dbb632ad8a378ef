/* Level 1 of _eppf_walk.h: AVX2, four pairs at a time: the f1-f3 bins
 * (``eppf_f123_batch_avx2``) and the f4 line walks of a batch, grouped by
 * line length (``eppf_f4_batch_avx2``). */
#ifndef EPPF_WALK_AVX2_H
#define EPPF_WALK_AVX2_H

#include "_eppf_walk_common.h"
#include "_eppf_walk_port.h" /* the portable walk's layout and counts */

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

/* The lane lists of ``eppf_port_walk_avx2``'s compaction: entry k (k < 16)
 * holds, for the set lanes of the 4-bit mask k in order, the two 32-bit
 * halves of each lane, then the unset ones (whatever follows the last kept
 * lane is overwritten or ignored). */
#define EPPF_L4(a, b, c, d) 2 * (a), 2 * (a) + 1, 2 * (b), 2 * (b) + 1, 2 * (c), 2 * (c) + 1, 2 * (d), 2 * (d) + 1
static const int32_t eppf_compress4[16][8] __attribute__((aligned(32))) = {
    {EPPF_L4(0, 1, 2, 3)}, {EPPF_L4(0, 1, 2, 3)}, {EPPF_L4(1, 0, 2, 3)}, {EPPF_L4(0, 1, 2, 3)},
    {EPPF_L4(2, 0, 1, 3)}, {EPPF_L4(0, 2, 1, 3)}, {EPPF_L4(1, 2, 0, 3)}, {EPPF_L4(0, 1, 2, 3)},
    {EPPF_L4(3, 0, 1, 2)}, {EPPF_L4(0, 3, 1, 2)}, {EPPF_L4(1, 3, 0, 2)}, {EPPF_L4(0, 1, 3, 2)},
    {EPPF_L4(2, 3, 0, 1)}, {EPPF_L4(0, 2, 3, 1)}, {EPPF_L4(1, 2, 3, 0)}, {EPPF_L4(0, 1, 2, 3)}};
#undef EPPF_L4

/* ``eppf_port_setup`` (_eppf_walk_port.h) four pairs at a time, the same
 * lines in the same order: each point's voxel read as 16 bytes (its x, y, z
 * and one int32 past them: ``vox`` must hold 3 n + 1), four of them
 * transposed; the increments' scale 2**14 / L the same correctly rounded
 * division as ``recip_packed[L]``, rounded to integers as llrint does; the
 * first states by scalar loads. ii, jj, B: read in fours (room for m + 3
 * entries, those past m unused); QP, QI, QS: room for m + 4 lines. */
__attribute__((target("avx2,bmi,bmi2")))
static int eppf_port_setup_avx2(int m, const int32_t *ii, const int32_t *jj, const int32_t *vox, int64_t g,
                                const int32_t *B, const double *recip_packed, const int64_t *states,
                                const int32_t *thr, int n4, int64_t *QP, int64_t *QI, int64_t *QS, int32_t *counts)
{
    const __m128i one = _mm_set1_epi32(1), two = _mm_set1_epi32(2), zero = _mm_setzero_si128();
    const __m128i half = _mm_set1_epi32(EPPF_PK_S / 2 + (int32_t)g);
    const __m256d S = _mm256_set1_pd((double)EPPF_PK_S);
    int t, l, nq = 0;
    (void)recip_packed;
    for (t = 0; t < m; t += 4) {
        const int nv = m - t < 4 ? m - t : 4;
        int32_t ri[4], rj[4], Lv[4] __attribute__((aligned(16))), bad;
        __m128i a[4], b[4], ax, ay, az, dx, dy, dz, adx, ady, adz, L, onx, ony, onz, da, walk;
        __m256i inc, p, back, st;
        if (nv == 4) {
            const __m128i i4 = _mm_loadu_si128((const __m128i *)(ii + t)), j4 = _mm_loadu_si128((const __m128i *)(jj + t));
            _mm_storeu_si128((__m128i *)ri, _mm_add_epi32(i4, _mm_add_epi32(i4, i4)));
            _mm_storeu_si128((__m128i *)rj, _mm_add_epi32(j4, _mm_add_epi32(j4, j4)));
        } else {
            for (l = 0; l < 4; l++) {  /* a partial last group repeats its last pair */
                const int u = l < nv ? t + l : m - 1;
                ri[l] = 3 * ii[u];
                rj[l] = 3 * jj[u];
            }
        }
        for (l = 0; l < 4; l++) {
            a[l] = _mm_loadu_si128((const __m128i *)(vox + ri[l]));
            b[l] = _mm_loadu_si128((const __m128i *)(vox + rj[l]));
        }
        {
            /* x, y, z of the four points as three vectors */
            const __m128i a01 = _mm_unpacklo_epi32(a[0], a[1]), a23 = _mm_unpacklo_epi32(a[2], a[3]);
            const __m128i b01 = _mm_unpacklo_epi32(b[0], b[1]), b23 = _mm_unpacklo_epi32(b[2], b[3]);
            ax = _mm_unpacklo_epi64(a01, a23);
            ay = _mm_unpackhi_epi64(a01, a23);
            az = _mm_unpacklo_epi64(_mm_unpackhi_epi32(a[0], a[1]), _mm_unpackhi_epi32(a[2], a[3]));
            dx = _mm_sub_epi32(_mm_unpacklo_epi64(b01, b23), ax);
            dy = _mm_sub_epi32(_mm_unpackhi_epi64(b01, b23), ay);
            dz = _mm_sub_epi32(_mm_unpacklo_epi64(_mm_unpackhi_epi32(b[0], b[1]), _mm_unpackhi_epi32(b[2], b[3])), az);
        }
        adx = _mm_abs_epi32(dx);
        ady = _mm_abs_epi32(dy);
        adz = _mm_abs_epi32(dz);
        L = _mm_max_epi32(_mm_max_epi32(adx, ady), adz);
        _mm_store_si128((__m128i *)Lv, L);
        walk = _mm_cmpgt_epi32(L, one);
        {
            /* 2**14 / L as recip_packed[L] (L <= 1 lanes are not walked; max(L, 1) keeps them finite) */
            const __m256d q = _mm256_div_pd(S, _mm256_cvtepi32_pd(_mm_max_epi32(L, one)));
            const __m256i ix = _mm256_cvtepi32_epi64(_mm256_cvtpd_epi32(_mm256_mul_pd(_mm256_cvtepi32_pd(dx), q)));
            const __m256i iy = _mm256_cvtepi32_epi64(_mm256_cvtpd_epi32(_mm256_mul_pd(_mm256_cvtepi32_pd(dy), q)));
            const __m256i iz = _mm256_cvtepi32_epi64(_mm256_cvtpd_epi32(_mm256_mul_pd(_mm256_cvtepi32_pd(dz), q)));
            inc = _mm256_add_epi64(_mm256_add_epi64(_mm256_slli_epi64(ix, EPPF_PK_XLANE),
                                                    _mm256_slli_epi64(iy, EPPF_PK_YLANE)), iz);
        }
        /* the start v S + S/2 + g of each lane (below 2**21), then the first inner voxel */
        p = _mm256_add_epi64(
            _mm256_add_epi64(
                _mm256_slli_epi64(_mm256_cvtepu32_epi64(_mm_add_epi32(_mm_slli_epi32(ax, EPPF_PK_FRAC), half)),
                                  EPPF_PK_XLANE),
                _mm256_slli_epi64(_mm256_cvtepu32_epi64(_mm_add_epi32(_mm_slli_epi32(ay, EPPF_PK_FRAC), half)),
                                  EPPF_PK_YLANE)),
            _mm256_cvtepu32_epi64(_mm_add_epi32(_mm_slli_epi32(az, EPPF_PK_FRAC), half)));
        p = _mm256_add_epi64(p, inc);
        /* along the dominant axis (the first on a tie), in the direction in which it grows */
        onx = _mm_cmpeq_epi32(adx, L);
        ony = _mm_andnot_si128(onx, _mm_cmpeq_epi32(ady, L));
        onz = _mm_andnot_si128(_mm_or_si128(onx, ony), _mm_set1_epi32(-1));
        da = _mm_or_si128(_mm_or_si128(_mm_and_si128(onx, dx), _mm_and_si128(ony, dy)), _mm_and_si128(onz, dz));
        back = _mm256_cvtepi32_epi64(_mm_cmpgt_epi32(zero, da));
        {
            /* (L - 2) inc: L - 2 < 2**6 times the two halves of inc */
            const __m256i k = _mm256_cvtepu32_epi64(_mm_max_epi32(_mm_sub_epi32(L, two), zero));
            const __m256i kinc = _mm256_add_epi64(_mm256_mul_epu32(k, inc),
                                                  _mm256_slli_epi64(_mm256_mul_epu32(k, _mm256_srli_epi64(inc, 32)), 32));
            p = _mm256_add_epi64(p, _mm256_and_si256(kinc, back));
            inc = _mm256_sub_epi64(_mm256_xor_si256(inc, back), back);
        }
        p = _mm256_add_epi64(p, _mm256_slli_epi64(_mm256_cvtepu32_epi64(_mm_sub_epi32(
                                    _mm_and_si128(onz, two), ony)), 62));  /* axis: 2 (z), 1 (y: ony = -1) or 0 */
        {
            /* the first state of each line (its low 32 bits: bytes R, U, O, X), biased, and B (and L) above */
            const __m128i first = _mm_setr_epi32((int32_t)states[(Lv[0] & 63) + 1], (int32_t)states[(Lv[1] & 63) + 1],
                                                 (int32_t)states[(Lv[2] & 63) + 1], (int32_t)states[(Lv[3] & 63) + 1]);
            __m128i key = _mm_loadu_si128((const __m128i *)(B + t));
            if (n4 > 3)
                key = _mm_add_epi32(key, _mm_slli_epi32(L, 24));
            st = _mm256_or_si256(_mm256_cvtepu32_epi64(_mm_xor_si128(first, _mm_set1_epi32((int32_t)EPPF_PORT_BIAS))),
                                 _mm256_slli_epi64(_mm256_cvtepu32_epi64(key), 32));
        }
        {
            const int w = _mm_movemask_ps(_mm_castsi128_ps(walk)) & ((1 << nv) - 1);
            const __m256i k = _mm256_load_si256((const __m256i *)eppf_compress4[w]);
            _mm256_storeu_si256((__m256i *)(QP + nq), _mm256_permutevar8x32_epi32(p, k));
            _mm256_storeu_si256((__m256i *)(QI + nq), _mm256_permutevar8x32_epi32(inc, k));
            _mm256_storeu_si256((__m256i *)(QS + nq), _mm256_permutevar8x32_epi32(st, k));
            nq += __builtin_popcount(w);
            bad = ~w & ((1 << nv) - 1);
            for (l = 0; bad; l++, bad >>= 1)
                if (bad & 1)  /* no inner voxel: occ = T = L + 1 */
                    counts[B[t + l] + eppf_f4_bin(thr, n4, Lv[l] + 1, Lv[l] + 1)]++;
        }
    }
    return nq;
}


/* ``eppf_port_walk`` (_eppf_walk_port.h) four lines to a vector, two vectors
 * side by side: the same steps and states, so the same counts. The look-ups
 * are four 16-byte loads a vector (a row's two code words) put together by
 * two lane inserts and two unpacks, not gathers (slow on AMD CPUs); the
 * tables of what a step takes from the state and how far it moves are
 * looked up in registers (one 32-bit permutation each: the index c + 4 live
 * sits in each lane's low half, its high half is 0, whose entries are 0);
 * the lines that stay are packed to the front of the list by a permutation
 * from ``eppf_compress4``, the finished states likewise to ``done`` (room for
 * n + 4 states). QP, QI, QS: room for n + 4 lines. */
__attribute__((target("avx2,bmi,bmi2")))
static void eppf_port_walk_avx2(int n, int64_t *QP, int64_t *QI, int64_t *QS, const uint64_t *code,
                                const int32_t *thr, int n4, int64_t *done, int32_t *counts)
{
    const __m256i dtab = _mm256_setr_epi32(0, 0, 0, 0, (int32_t)EPPF_ST(1, 0, 1, 1), (int32_t)EPPF_ST(1, 1, 0, 0),
                                           (int32_t)EPPF_ST(2, 2, 0, 0), (int32_t)EPPF_ST(3, 3, 0, 0));
    const __m256i zero = _mm256_setzero_si256();
    const __m256i m63 = _mm256_set1_epi64x(63), one = _mm256_set1_epi64x(1), four = _mm256_set1_epi64x(4);
    const __m256i live = _mm256_set1_epi64x(EPPF_PORT_LIVE);
    int nd = 0;
/* One step of the four lines of vector v (EPPF_PORT_STEP of _eppf_walk_port.h). The position's
   chain of operations is kept short (it bounds how fast a line goes): the row offsets leave the
   register by extraction, and the move, max(c, 1) inc = inc + (c >= 2) inc + (c == 3) inc, takes
   no multiply (lines whose bin is certain move on too; their state stays). */
#define EPPF_VSTEP(v)                                                                                  \
    do {                                                                                               \
        const __m256i r_ = _mm256_add_epi64(_mm256_slli_epi64(_mm256_srli_epi64(p##v, 56), 7),         \
                                            _mm256_slli_epi64(_mm256_and_si256(_mm256_srli_epi64(p##v, EPPF_PK_YSHIFT), m63), 1)); \
        const __m128i rh_ = _mm256_extracti128_si256(r_, 1);                                           \
        const __m256i w_ = _mm256_inserti128_si256(                                                    \
            _mm256_castsi128_si256(_mm_loadu_si128((const __m128i *)(code + _mm256_extract_epi64(r_, 0)))), \
            _mm_loadu_si128((const __m128i *)(code + _mm_cvtsi128_si64(rh_))), 1);                      \
        const __m256i x_ = _mm256_inserti128_si256(                                                    \
            _mm256_castsi128_si256(_mm_loadu_si128((const __m128i *)(code + _mm256_extract_epi64(r_, 1)))), \
            _mm_loadu_si128((const __m128i *)(code + _mm_extract_epi64(rh_, 1))), 1);                   \
        const __m256i z_ = _mm256_and_si256(_mm256_srli_epi64(p##v, EPPF_PK_ZSHIFT), m63);             \
        const __m256i b0_ = _mm256_and_si256(_mm256_srlv_epi64(_mm256_unpacklo_epi64(w_, x_), z_), one); \
        const __m256i b1_ = _mm256_and_si256(_mm256_srlv_epi64(_mm256_unpackhi_epi64(w_, x_), z_), one); \
        const __m256i j_ = _mm256_or_si256(_mm256_add_epi64(b0_, _mm256_add_epi64(b1_, b1_)),         \
                                           _mm256_and_si256(_mm256_cmpeq_epi64(_mm256_and_si256(st##v, live), live), four)); \
        st##v = _mm256_sub_epi64(st##v, _mm256_permutevar8x32_epi32(dtab, j_));                        \
        p##v = _mm256_add_epi64(_mm256_add_epi64(p##v, inc##v),                                        \
                                _mm256_add_epi64(_mm256_and_si256(inc##v, _mm256_sub_epi64(zero, b1_)), \
                                                 _mm256_and_si256(inc##v, _mm256_sub_epi64(zero, _mm256_and_si256(b0_, b1_))))); \
    } while (0)
/* The lines of vector v (from t): those still uncertain (of the first nv) back to the list at keep, the others' states to done. */
#define EPPF_VSORT(v, nv)                                                                              \
    do {                                                                                               \
        const int on_ = _mm256_movemask_pd(_mm256_castsi256_pd(                                        \
                            _mm256_cmpeq_epi64(_mm256_and_si256(st##v, live), live))) & ((1 << (nv)) - 1); \
        const int off_ = ~on_ & ((1 << (nv)) - 1);                                                     \
        const __m256i k_ = _mm256_load_si256((const __m256i *)eppf_compress4[on_]);                     \
        _mm256_storeu_si256((__m256i *)(done + nd),                                                    \
                            _mm256_permutevar8x32_epi32(st##v, _mm256_load_si256((const __m256i *)eppf_compress4[off_]))); \
        nd += __builtin_popcount(off_);                                                                \
        _mm256_storeu_si256((__m256i *)(QP + keep), _mm256_permutevar8x32_epi32(p##v, k_));            \
        _mm256_storeu_si256((__m256i *)(QI + keep), _mm256_permutevar8x32_epi32(inc##v, k_));          \
        _mm256_storeu_si256((__m256i *)(QS + keep), _mm256_permutevar8x32_epi32(st##v, k_));           \
        keep += __builtin_popcount(on_);                                                               \
    } while (0)
#define EPPF_VLOAD(v, t)                                                                               \
    do {                                                                                               \
        p##v = _mm256_loadu_si256((const __m256i *)(QP + (t)));                                        \
        inc##v = _mm256_loadu_si256((const __m256i *)(QI + (t)));                                      \
        st##v = _mm256_loadu_si256((const __m256i *)(QS + (t)));                                       \
    } while (0)
    while (n > 0) {
        int t = 0, keep = 0, k;
        __m256i pA, incA, stA, pB, incB, stB, pC, incC, stC, pD, incD, stD;
        /* the list's last vector is filled up with lines whose look-ups are valid (zero) and ignored */
        for (k = 0; k < 4; k++)
            QP[n + k] = QI[n + k] = QS[n + k] = 0;
        for (; t + 16 <= n; t += 16) {
            EPPF_VLOAD(A, t);
            EPPF_VLOAD(B, t + 4);
            EPPF_VLOAD(C, t + 8);
            EPPF_VLOAD(D, t + 12);
            for (k = 0; k < EPPF_PORT_STEPS; k++) {
                EPPF_VSTEP(A);
                EPPF_VSTEP(B);
                EPPF_VSTEP(C);
                EPPF_VSTEP(D);
            }
            EPPF_VSORT(A, 4);
            EPPF_VSORT(B, 4);
            EPPF_VSORT(C, 4);
            EPPF_VSORT(D, 4);
        }
        for (; t < n; t += 4) {
            EPPF_VLOAD(A, t);
            for (k = 0; k < EPPF_PORT_STEPS; k++)
                EPPF_VSTEP(A);
            EPPF_VSORT(A, n - t < 4 ? n - t : 4);
        }
        n = keep;
    }
#undef EPPF_VSTEP
#undef EPPF_VSORT
#undef EPPF_VLOAD
    eppf_port_count_done(nd, done, thr, n4, counts);
}

#else

static void eppf_f123_batch_avx2(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                                 const double *nrm, int64_t ns, double scale, int n1, int n2, int n3, int n4,
                                 double f1_density, const double *cos2, const double *cos3, int32_t *B)
{
    (void)m; (void)ii; (void)jj; (void)pts; (void)ps; (void)nrm; (void)ns; (void)scale; (void)n1; (void)n2; (void)n3;
    (void)n4; (void)f1_density; (void)cos2; (void)cos3; (void)B;
}

#endif

#endif /* EPPF_WALK_AVX2_H */
