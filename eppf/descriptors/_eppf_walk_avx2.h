/* Level 1 of _eppf_walk.h: AVX2, four pairs at a time, the AVX-512 levels'
 * approach at half their width and without gathers (slow on AVX2-only AMD
 * CPUs): the pair draws (``eppf_draw_batch_avx2``), one pass over a batch
 * for the coincidence check, the f1-f3 bins and the portable walk's setup,
 * reading ``eppf_pack_rows``' rows (``eppf_f123q_avx2``), and the portable
 * walk four lines to a vector (``eppf_port_walk_avx2``). */
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

/* The points, normals and voxels at rows r[0..3] of ``eppf_pack_rows``'s
 * ``pn`` (level 1's form: the voxel's x, y, z as int32): v[0..5] = x, y, z,
 * nx, ny, nz as vectors (the normals only where ``normals``), V[0] the
 * voxels' (x, y) and V[1] their (z, 0) as int32 pairs in 64-bit lanes. Each
 * vector is two 16-byte column pairs of two rows, put side by side, then
 * split by an unpack: no masked loads (slow on AMD CPUs), no gathers. */
__attribute__((target("avx2")))
static inline void eppf_load_rows4(const double *pn, const int32_t *r, int normals, __m256d *v, __m256i *V)
{
    const double *p0 = pn + 8 * (int64_t)r[0], *p1 = pn + 8 * (int64_t)r[1];
    const double *p2 = pn + 8 * (int64_t)r[2], *p3 = pn + 8 * (int64_t)r[3];
/* columns c and c + 1 of rows 0 and 2 (A) and of rows 1 and 3 (B) */
#define EPPF_COLS(c, lo, hi)                                                                       \
    do {                                                                                           \
        const __m256d A_ = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_load_pd(p0 + (c))), _mm_load_pd(p2 + (c)), 1); \
        const __m256d B_ = _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_load_pd(p1 + (c))), _mm_load_pd(p3 + (c)), 1); \
        lo = _mm256_unpacklo_pd(A_, B_);                                                           \
        hi = _mm256_unpackhi_pd(A_, B_);                                                           \
    } while (0)
    __m256d v6, v7;
    EPPF_COLS(0, v[0], v[1]);
    EPPF_COLS(2, v[2], v[3]);
    if (normals)
        EPPF_COLS(4, v[4], v[5]);
    EPPF_COLS(6, v6, v7);
#undef EPPF_COLS
    V[0] = _mm256_castpd_si256(v6);
    V[1] = _mm256_castpd_si256(v7);
}

/* ``eppf_load_rows4``'s V from ``vox`` ((n, 3) int32, read as 16 bytes a
 * point: room for 3 n + 1), for objects without rows. */
__attribute__((target("avx2")))
static inline void eppf_load_vox4(const int32_t *vox, const int32_t *r, __m256i *V)
{
    const __m128i q0 = _mm_loadu_si128((const __m128i *)(vox + 3 * (int64_t)r[0]));  /* x y z - */
    const __m128i q1 = _mm_loadu_si128((const __m128i *)(vox + 3 * (int64_t)r[1]));
    const __m128i q2 = _mm_loadu_si128((const __m128i *)(vox + 3 * (int64_t)r[2]));
    const __m128i q3 = _mm_loadu_si128((const __m128i *)(vox + 3 * (int64_t)r[3]));
    V[0] = _mm256_inserti128_si256(_mm256_castsi128_si256(_mm_unpacklo_epi64(q0, q1)), _mm_unpacklo_epi64(q2, q3), 1);
    V[1] = _mm256_and_si256(_mm256_inserti128_si256(_mm256_castsi128_si256(_mm_unpackhi_epi64(q0, q1)),
                                                    _mm_unpackhi_epi64(q2, q3), 1),
                            _mm256_set1_epi64x(0xFFFFFFFF));
}

/* x * c mod 2**64 for four uint64 lanes x and a constant c (c_lo, c_hi: its
   halves in every lane): AVX2 multiplies 32 by 32 bits only. */
__attribute__((target("avx2")))
static inline __m256i eppf_mul64_avx2(__m256i x, __m256i c_lo, __m256i c_hi)
{
    const __m256i cross = _mm256_add_epi64(_mm256_mul_epu32(_mm256_srli_epi64(x, 32), c_lo), _mm256_mul_epu32(x, c_hi));
    return _mm256_add_epi64(_mm256_mul_epu32(x, c_lo), _mm256_slli_epi64(cross, 32));
}

/* ``eppf_draw_batch_avx512`` four draws at a time: the candidate pairs of
 * the next m draws of splitmix64 from ``state``, exactly as _eppf_fast.pyx's
 * ``_draw_pair`` draws them but without its check for coinciding points
 * (``eppf_f123q_avx2`` does that check). out_i, out_j: room for m + 3 entries
 * (those past m are overwritten with other draws). */
__attribute__((target("avx2")))
static void eppf_draw_batch_avx2(int m, uint64_t state, uint32_t n, int32_t *out_i, int32_t *out_j)
{
    const __m256i step = _mm256_set1_epi64x((long long)(4 * EPPF_SM_GAMMA));
    const __m256i c1 = _mm256_set1_epi64x((long long)(0xBF58476D1CE4E5B9ULL & 0xFFFFFFFF));
    const __m256i c1h = _mm256_set1_epi64x((long long)(0xBF58476D1CE4E5B9ULL >> 32));
    const __m256i c2 = _mm256_set1_epi64x((long long)(0x94D049BB133111EBULL & 0xFFFFFFFF));
    const __m256i c2h = _mm256_set1_epi64x((long long)(0x94D049BB133111EBULL >> 32));
    const __m256i vn = _mm256_set1_epi64x(n), vn1 = _mm256_set1_epi64x(n - 1), one = _mm256_set1_epi64x(1);
    const __m256i low = _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6);  /* the low halves of the four lanes */
    __m256i st = _mm256_setr_epi64x((long long)(state + EPPF_SM_GAMMA), (long long)(state + 2 * EPPF_SM_GAMMA),
                                    (long long)(state + 3 * EPPF_SM_GAMMA), (long long)(state + 4 * EPPF_SM_GAMMA));
    int t;
    for (t = 0; t < m; t += 4) {
        __m256i z = st, i, j;
        z = eppf_mul64_avx2(_mm256_xor_si256(z, _mm256_srli_epi64(z, 30)), c1, c1h);
        z = eppf_mul64_avx2(_mm256_xor_si256(z, _mm256_srli_epi64(z, 27)), c2, c2h);
        z = _mm256_xor_si256(z, _mm256_srli_epi64(z, 31));
        i = _mm256_srli_epi64(_mm256_mul_epu32(_mm256_srli_epi64(z, 32), vn), 32);
        j = _mm256_srli_epi64(_mm256_mul_epu32(z, vn1), 32);
        /* j + 1 where j >= i (both below 2**32: a signed comparison is exact) */
        j = _mm256_add_epi64(j, _mm256_add_epi64(one, _mm256_cmpgt_epi64(i, j)));
        _mm_storeu_si128((__m128i *)(out_i + t), _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(i, low)));
        _mm_storeu_si128((__m128i *)(out_j + t), _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(j, low)));
        st = _mm256_add_epi64(st, step);
    }
}

/* The f1-f3 bins, times n4, of four pairs from their points p and normals n
 * (x, y, z vectors; the normals read only where n2 > 1 or n3 > 1), as
 * _eppf_fast.pyx's ``_bin_f123``: the same IEEE operations in the same order
 * (``eppf_bins123_8`` is this, eight pairs at a time), so the same bins. The
 * f2 and f3 bins are counts of edges reached, summed as 64-bit integers (a
 * comparison's all-ones lanes subtracted), b2 n3 + b3 formed there. */
__attribute__((target("avx2")))
static inline __m128i eppf_bins123_4(const __m256d *pi, const __m256d *ni, const __m256d *pj, const __m256d *nj,
                                     double scale, int n1, int n2, int n3, int n4, double f1_density,
                                     const double *cos2, const double *cos3)
{
    const __m256d dx = _mm256_sub_pd(pj[0], pi[0]), dy = _mm256_sub_pd(pj[1], pi[1]);
    const __m256d dz = _mm256_sub_pd(pj[2], pi[2]);
    const __m256d dist = _mm256_sqrt_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                                                      _mm256_mul_pd(dz, dz)));
    /* f1: max(min(v * density, n1 - 1), 0) truncated: clamped in floating
       point before the conversion, so a NaN or +inf lands in the top bin
       (min_pd returns its second operand when one is NaN) and a negative
       value in bin 0, as in _bin_f123. */
    const __m256d v1 = _mm256_mul_pd(_mm256_mul_pd(dist, _mm256_set1_pd(scale)), _mm256_set1_pd(f1_density));
    const __m128i b1 = _mm256_cvttpd_epi32(_mm256_max_pd(_mm256_min_pd(v1, _mm256_set1_pd((double)(n1 - 1))),
                                                         _mm256_setzero_pd()));
    __m256i b2 = _mm256_setzero_si256(), b3 = _mm256_setzero_si256();
    int k;
    if (n2 > 1) {
        const __m256d inv = _mm256_div_pd(_mm256_set1_pd(1.0), dist);
        __m256d m1 = _mm256_mul_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ni[0], dx), _mm256_mul_pd(ni[1], dy)),
                                                 _mm256_mul_pd(ni[2], dz)), inv);
        const __m256d m2 = _mm256_mul_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nj[0], dx),
                                                                     _mm256_mul_pd(nj[1], dy)),
                                                       _mm256_mul_pd(nj[2], dz)), inv);
        m1 = _mm256_min_pd(m2, m1);  /* m2 < m1 ? m2 : m1 */
        for (k = 0; k < n2 - 1; k++)  /* + 1 where m1 <= edge */
            b2 = _mm256_sub_epi64(b2, _mm256_castpd_si256(_mm256_cmp_pd(m1, _mm256_set1_pd(cos2[k]), _CMP_LE_OQ)));
    }
    if (n3 > 1) {
        const __m256d v3 = _mm256_andnot_pd(_mm256_set1_pd(-0.0),
                                            _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ni[0], nj[0]),
                                                                        _mm256_mul_pd(ni[1], nj[1])),
                                                          _mm256_mul_pd(ni[2], nj[2])));
        for (k = 0; k < n3 - 1; k++)
            b3 = _mm256_sub_epi64(b3, _mm256_castpd_si256(_mm256_cmp_pd(v3, _mm256_set1_pd(cos3[k]), _CMP_LE_OQ)));
    }
    {
        /* ((b1 n2 + b2) n3 + b3) n4 = (b1 (n2 n3) + (b2 n3 + b3)) n4 */
        const __m256i b23 = _mm256_add_epi64(_mm256_mul_epu32(b2, _mm256_set1_epi64x(n3)), b3);
        const __m128i low = _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(b23, _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6)));
        return _mm_mullo_epi32(_mm_add_epi32(_mm_mullo_epi32(b1, _mm_set1_epi32(n2 * n3)), low), _mm_set1_epi32(n4));
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

/* Level 1's pass over a batch of pairs (ii[t], jj[t]), t < m, four at a
 * time, for the draws of ``eppf_draw_batch_avx2``: finds the first t whose
 * two points coincide (returned; m when none does) and bins f1-f3
 * (``eppf_bins123_4``). Where QP is NULL it writes B[t] (the f1-f3 bin
 * times n4) for every t (B: room for m + 3); otherwise it sets up the f4
 * walks of the pairs before the first coinciding one as ``eppf_f123q_port``
 * does (the same lines, in the same order, *nq_out of them, into QP, QI,
 * QS: room for m + 4) and counts those without inner voxels; B is unused.
 * The setup reads each point's voxel as 16 bytes (its x, y, z and one int32
 * past them: ``vox`` must hold 3 n + 1) and transposes four of them; the
 * increments' scale 2**14 / L is the same correctly rounded division as
 * ``recip_packed[L]``, rounded to integers as llrint does; the first states
 * come by scalar loads. ii, jj: read in fours (room for m + 3). */
__attribute__((target("avx2,bmi,bmi2")))
static int eppf_f123q_avx2(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                           const double *nrm, int64_t ns, const int32_t *vox, int64_t g, double scale, int n1, int n2,
                           int n3, int n4, double f1_density, const double *cos2, const double *cos3,
                           const int64_t *states, const int32_t *thr, const double *pn, int32_t *B, int64_t *QP,
                           int64_t *QI, int64_t *QS, int *nq_out, int32_t *counts)
{
    const __m128i one = _mm_set1_epi32(1), two = _mm_set1_epi32(2), zero = _mm_setzero_si128();
    const __m256i half = _mm256_set1_epi64x(EPPF_PK_S / 2 + g);
    const __m256i even = _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6), odd = _mm256_setr_epi32(1, 3, 5, 7, 1, 3, 5, 7);
    const __m256d S = _mm256_set1_pd((double)EPPF_PK_S);
    const int normals = n2 > 1 || n3 > 1;
    int t, l, nq = 0, bad = m;
    for (t = 0; t < m && bad == m; t += 4) {
        int nv = m - t < 4 ? m - t : 4, same;
        int32_t ri[4], rj[4], Lv[4] __attribute__((aligned(16))), Bv[4] __attribute__((aligned(16))), few;
        __m256d a[6], b[6];
        __m256i Va[2], Vb[2];
        __m128i bins;
        if (nv == 4) {
            _mm_storeu_si128((__m128i *)ri, _mm_loadu_si128((const __m128i *)(ii + t)));
            _mm_storeu_si128((__m128i *)rj, _mm_loadu_si128((const __m128i *)(jj + t)));
        } else {
            for (l = 0; l < 4; l++) {  /* a partial last group repeats its last pair */
                const int u = l < nv ? t + l : m - 1;
                ri[l] = ii[u];
                rj[l] = jj[u];
            }
        }
        if (pn) {
            eppf_load_rows4(pn, ri, normals, a, Va);
            eppf_load_rows4(pn, rj, normals, b, Vb);
        } else {
            eppf_load3x4(pts, ps, ri, a, a + 1, a + 2);
            eppf_load3x4(pts, ps, rj, b, b + 1, b + 2);
            if (normals) {
                eppf_load3x4(nrm, ns, ri, a + 3, a + 4, a + 5);
                eppf_load3x4(nrm, ns, rj, b + 3, b + 4, b + 5);
            }
            if (QP) {
                eppf_load_vox4(vox, ri, Va);
                eppf_load_vox4(vox, rj, Vb);
            }
        }
        same = _mm256_movemask_pd(_mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(a[0], b[0], _CMP_EQ_OQ),
                                                              _mm256_cmp_pd(a[1], b[1], _CMP_EQ_OQ)),
                                                _mm256_cmp_pd(a[2], b[2], _CMP_EQ_OQ))) & ((1 << nv) - 1);
        if (same) {  /* the first pair whose points coincide ends the batch */
            bad = t + __builtin_ctz(same);
            nv = __builtin_ctz(same);
        }
        bins = eppf_bins123_4(a, a + 3, b, b + 3, scale, n1, n2, n3, n4, f1_density, cos2, cos3);
        if (!QP) {
            _mm_storeu_si128((__m128i *)(B + t), bins);
            continue;
        }
        {
            __m128i dx, dy, dz, adx, ady, adz, L, onx, ony, onz, da, walk;
            __m256i inc, p, back, st;
            {
                /* the voxels' differences as x, y, z vectors (int32) */
                const __m256i d01 = _mm256_sub_epi32(Vb[0], Va[0]), d23 = _mm256_sub_epi32(Vb[1], Va[1]);
                dx = _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(d01, even));
                dy = _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(d01, odd));
                dz = _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(d23, even));
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
                    _mm256_slli_epi64(_mm256_add_epi64(_mm256_slli_epi64(_mm256_and_si256(Va[0], _mm256_set1_epi64x(0xFFFFFFFF)),
                                                                         EPPF_PK_FRAC), half), EPPF_PK_XLANE),
                    _mm256_slli_epi64(_mm256_add_epi64(_mm256_slli_epi64(_mm256_srli_epi64(Va[0], 32), EPPF_PK_FRAC), half),
                                      EPPF_PK_YLANE)),
                _mm256_add_epi64(_mm256_slli_epi64(Va[1], EPPF_PK_FRAC), half));
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
                __m128i key = bins;
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
                few = ~w & ((1 << nv) - 1);
                if (few) {
                    _mm_store_si128((__m128i *)Bv, bins);
                    for (l = 0; few; l++, few >>= 1)
                        if (few & 1)  /* no inner voxel: occ = T = L + 1 */
                            counts[Bv[l] + eppf_f4_bin(thr, n4, Lv[l] + 1, Lv[l] + 1)]++;
                }
            }
        }
    }
    if (nq_out)
        *nq_out = nq;
    return bad;
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
    /* a position's row times two, ((p >> 56) << 7) + ((p >> 34) & 126), is ((p >> 49) & mx) + ((p >> 34) & my) */
    const __m256i mx = _mm256_set1_epi64x(0x7F80), my = _mm256_set1_epi64x(126);
    int nd = 0;
/* One step of the four lines of vector v (EPPF_PORT_STEP of _eppf_walk_port.h). The position's
   chain of operations is kept short (it bounds how fast a line goes): the row offsets leave the
   register by extraction, and the move, max(c, 1) inc = inc + (c >= 2) inc + (c == 3) inc, takes
   no multiply (lines whose bin is certain move on too; their state stays). */
#define EPPF_VSTEP(v)                                                                                  \
    do {                                                                                               \
        const __m256i r_ = _mm256_add_epi64(_mm256_and_si256(_mm256_srli_epi64(p##v, 49), mx),         \
                                            _mm256_and_si256(_mm256_srli_epi64(p##v, EPPF_PK_YSHIFT - 1), my)); \
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
        __m256i pA, incA, stA, pB, incB, stB, pC, incC, stC;
        /* the list's last vector is filled up with lines whose look-ups are valid (zero) and ignored */
        for (k = 0; k < 4; k++)
            QP[n + k] = QI[n + k] = QS[n + k] = 0;
        /* three vectors of lines at a time: with four, their twelve state vectors and the constants
           outgrew AVX2's 16 registers and spilled every step (3-5% slower on a Zen 2; two: no faster) */
        for (; t + 12 <= n; t += 12) {
            EPPF_VLOAD(A, t);
            EPPF_VLOAD(B, t + 4);
            EPPF_VLOAD(C, t + 8);
            for (k = 0; k < EPPF_PORT_STEPS; k++) {
                EPPF_VSTEP(A);
                EPPF_VSTEP(B);
                EPPF_VSTEP(C);
            }
            EPPF_VSORT(A, 4);
            EPPF_VSORT(B, 4);
            EPPF_VSORT(C, 4);
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

static void eppf_draw_batch_avx2(int m, uint64_t state, uint32_t n, int32_t *out_i, int32_t *out_j)
{
    (void)m; (void)state; (void)n; (void)out_i; (void)out_j;
}

static int eppf_f123q_avx2(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                           const double *nrm, int64_t ns, const int32_t *vox, int64_t g, double scale, int n1, int n2,
                           int n3, int n4, double f1_density, const double *cos2, const double *cos3,
                           const int64_t *states, const int32_t *thr, const double *pn, int32_t *B, int64_t *QP,
                           int64_t *QI, int64_t *QS, int *nq_out, int32_t *counts)
{
    (void)pn; (void)m; (void)ii; (void)jj; (void)pts; (void)ps; (void)nrm; (void)ns; (void)vox; (void)g; (void)scale; (void)n1;
    (void)n2; (void)n3; (void)n4; (void)f1_density; (void)cos2; (void)cos3; (void)states; (void)thr; (void)B;
    (void)QP; (void)QI; (void)QS; (void)counts;
    if (nq_out)
        *nq_out = 0;
    return 0;
}

#endif

#endif /* EPPF_WALK_AVX2_H */
