/* Level 2 of _eppf_walk.h, and the AVX-512 parts level 3 shares: AVX-512 (F,
 * BW, VL, DQ and VBMI), eight pairs at a time: the pair draws
 * (``eppf_draw_batch_avx512``), the voxel grid (``eppf_fill_grid_avx512``),
 * the f1-f3 bins with the check for coinciding points
 * (``eppf_f123_batch_avx512``), the walk setup of eight lines
 * (``eppf_line8_avx512``) and the grouped f4 walk (``eppf_f4_batch_avx512``). */
#ifndef EPPF_WALK_AVX512_H
#define EPPF_WALK_AVX512_H

#include "_eppf_walk_common.h"

/* A walk's counters in one int64 for the AVX-512 walk: rem (inner voxels) in
   bits 0-20, the f4 thresholds lo from bit 21 and hi from bit 42 (all below
   2**21); ``lohi[T]`` holds lo and hi of T voxels in place (_eppf_fast.pyx). */
#define EPPF_META_LO 21
#define EPPF_META_HI 42
#define EPPF_META_MASK 0x1FFFFF

#if EPPF_WALK_SIMD
/* The points, normals and packed voxels at rows r[0..7] of
 * ``eppf_pack_rows``'s ``pn`` as seven vectors v[0..6] (x, y, z, nx, ny, nz,
 * pv): sixteen half-row loads, two rows to a vector, and a transpose within
 * the 256-bit halves (on Zen 4, which runs a 512-bit vector as two halves,
 * cheaper than crossing them twice: 1% of the level-3 kernel). v[6] costs
 * one shuffle, dropped by the compiler where it is not used. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_load7x8(const double *pn, const int32_t *r, __m512d *v)
{
    /* A[k]: the first halves (x, y, z, nx) of rows pick[k][0] and pick[k][1]; H[k] the second
       halves (ny, nz, pv, -) */
    __m512d A[4], H[4], t[4], h[4];
    static const int pick[4][2] = {{0, 2}, {1, 3}, {4, 6}, {5, 7}};
    int k;
    for (k = 0; k < 4; k++) {
        const double *p0 = pn + 8 * (int64_t)r[pick[k][0]], *p1 = pn + 8 * (int64_t)r[pick[k][1]];
        A[k] = _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_loadu_pd(p0)), _mm256_loadu_pd(p1), 1);
        H[k] = _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_loadu_pd(p0 + 4)), _mm256_loadu_pd(p1 + 4), 1);
    }
    t[0] = _mm512_unpacklo_pd(A[0], A[1]);  /* x01 z01 | x23 z23 */
    t[1] = _mm512_unpackhi_pd(A[0], A[1]);  /* y01 nx01 | y23 nx23 */
    t[2] = _mm512_unpacklo_pd(A[2], A[3]);
    t[3] = _mm512_unpackhi_pd(A[2], A[3]);
    h[0] = _mm512_unpacklo_pd(H[0], H[1]);  /* ny01 pv01 | ny23 pv23 */
    h[1] = _mm512_unpackhi_pd(H[0], H[1]);  /* nz01 - | nz23 - */
    h[2] = _mm512_unpacklo_pd(H[2], H[3]);
    h[3] = _mm512_unpackhi_pd(H[2], H[3]);
    v[0] = _mm512_shuffle_f64x2(t[0], t[2], 0x88);
    v[2] = _mm512_shuffle_f64x2(t[0], t[2], 0xDD);
    v[1] = _mm512_shuffle_f64x2(t[1], t[3], 0x88);
    v[3] = _mm512_shuffle_f64x2(t[1], t[3], 0xDD);
    v[4] = _mm512_shuffle_f64x2(h[0], h[2], 0x88);
    v[6] = _mm512_shuffle_f64x2(h[0], h[2], 0xDD);
    v[5] = _mm512_shuffle_f64x2(h[1], h[3], 0x88);
}

/* The candidate pairs of the next m draws of splitmix64 from ``state``, eight
 * draws at a time, exactly as _eppf_fast.pyx's ``_draw_pair`` draws them but
 * without its check for coinciding points (``eppf_f123_batch_avx512`` does
 * that check): i = (r_hi n) >> 32, j = (r_lo (n - 1)) >> 32, plus one where
 * j >= i. */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_draw_batch_avx512(int m, uint64_t state, uint32_t n, int32_t *out_i, int32_t *out_j)
{
    const __m512i step = _mm512_set1_epi64((long long)(8 * EPPF_SM_GAMMA));
    const __m512i c1 = _mm512_set1_epi64((long long)0xBF58476D1CE4E5B9ULL);
    const __m512i c2 = _mm512_set1_epi64((long long)0x94D049BB133111EBULL);
    const __m512i vn = _mm512_set1_epi64(n), vn1 = _mm512_set1_epi64(n - 1), one = _mm512_set1_epi64(1);
    __m512i st = _mm512_add_epi64(
        _mm512_set1_epi64((long long)state),
        _mm512_mullo_epi64(_mm512_set_epi64(8, 7, 6, 5, 4, 3, 2, 1), _mm512_set1_epi64((long long)EPPF_SM_GAMMA)));
    int t;
    for (t = 0; t < m; t += 8) {
        const __mmask8 keep = m - t >= 8 ? (__mmask8)0xff : (__mmask8)((1u << (m - t)) - 1);
        __m512i z = st, i, j;
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 30)), c1);
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 27)), c2);
        z = _mm512_xor_si512(z, _mm512_srli_epi64(z, 31));
        i = _mm512_srli_epi64(_mm512_mul_epu32(_mm512_srli_epi64(z, 32), vn), 32);
        j = _mm512_srli_epi64(_mm512_mul_epu32(z, vn1), 32);
        j = _mm512_mask_add_epi64(j, _mm512_cmpge_epu64_mask(j, i), j, one);
        _mm256_mask_storeu_epi32(out_i + t, keep, _mm512_cvtepi64_epi32(i));
        _mm256_mask_storeu_epi32(out_j + t, keep, _mm512_cvtepi64_epi32(j));
        st = _mm512_add_epi64(st, step);
    }
}

/* The points (x, y, z) at rows r[0..7] of an array with rows of ``stride``
 * doubles, as x, y, z vectors: eight masked row loads and a transpose (on
 * CPUs with slow gathers, such as AMD Zen 4, much cheaper than three
 * gathers; the values, and so the bins, are the same). */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_load3x8(const double *a, int64_t stride, const int32_t *r, __m512d *x, __m512d *y,
                                __m512d *z)
{
    const __m512i pick_xy = _mm512_set_epi64(13, 9, 5, 1, 12, 8, 4, 0);   /* x0 x1 x2 x3 y0 y1 y2 y3 */
    const __m512i pick_z = _mm512_set_epi64(15, 11, 7, 3, 14, 10, 6, 2);  /* z0 z1 z2 z3 ... */
    __m512d a0, a1, a2, a3, u0, u1, v0, v1;
#define EPPF_ROW(k) _mm256_maskz_loadu_pd(0x7, a + stride * r[k])
    a0 = _mm512_insertf64x4(_mm512_castpd256_pd512(EPPF_ROW(0)), EPPF_ROW(1), 1);  /* x0 y0 z0 0 x1 y1 z1 0 */
    a1 = _mm512_insertf64x4(_mm512_castpd256_pd512(EPPF_ROW(2)), EPPF_ROW(3), 1);
    a2 = _mm512_insertf64x4(_mm512_castpd256_pd512(EPPF_ROW(4)), EPPF_ROW(5), 1);
    a3 = _mm512_insertf64x4(_mm512_castpd256_pd512(EPPF_ROW(6)), EPPF_ROW(7), 1);
#undef EPPF_ROW
    u0 = _mm512_permutex2var_pd(a0, pick_xy, a1);
    u1 = _mm512_permutex2var_pd(a2, pick_xy, a3);
    v0 = _mm512_permutex2var_pd(a0, pick_z, a1);
    v1 = _mm512_permutex2var_pd(a2, pick_z, a3);
    *x = _mm512_shuffle_f64x2(u0, u1, 0x44);
    *y = _mm512_shuffle_f64x2(u0, u1, 0xEE);
    *z = _mm512_shuffle_f64x2(v0, v1, 0x44);
}

/* The pairs of a group of eight at t of (ii, jj), m - t of them real
 * (``keep``): a partial last group repeats its last pair, in ri and rj. */
static inline __mmask8 eppf_group8(int m, int t, const int32_t *ii, const int32_t *jj, int32_t *ri, int32_t *rj,
                                   const int32_t **vi, const int32_t **vj)
{
    int l;
    *vi = ii + t;
    *vj = jj + t;
    if (m - t >= 8)
        return (__mmask8)0xff;
    for (l = 0; l < 8; l++) {
        ri[l] = ii[t + (l < m - t ? l : m - t - 1)];
        rj[l] = jj[t + (l < m - t ? l : m - t - 1)];
    }
    *vi = ri;
    *vj = rj;
    return (__mmask8)((1u << (m - t)) - 1);
}

/* _eppf_fast.pyx's ``_fill_grid`` with ``pv`` for g <= 64 (one word a row),
 * eight points at a time (a partial last group repeats its last point,
 * ``eppf_group8``): the bounding box, each point's voxel (the same IEEE
 * operations and clamping, so the same voxels) as its packed start word
 * ``pv``, and the occupied voxels in ``bits`` (g^2 words). The box's minima
 * and maxima are taken lane by lane, then across the lanes, each step the
 * scalar loop's comparison (x < lo takes x, so a NaN is never taken and a
 * NaN first point stays), so they are the scalar loop's values up to the
 * sign of a zero extreme, which gives the same voxels. ``vox`` is not
 * written (the AVX-512 kernels read ``pv``); 1 <= n, 2 <= g <= 64. */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_fill_grid_avx512(const double *pts, int64_t ps, int64_t n, int64_t g, uint64_t *bits, int64_t *pv)
{
    static const int32_t seq[8] = {0, 1, 2, 3, 4, 5, 6, 7};
    const int32_t gi = (int32_t)g;
    int32_t ri[8], rj[8];
    const int32_t *rows = seq, *unused;
    double lo[3], hi[3], side, inv, acc[8];
    __m512d mn[3], mx[3], x[3];
    int64_t i, a;
    int k;
    for (a = 0; a < 3; a++) {
        mn[a] = mx[a] = _mm512_set1_pd(pts[a]);
    }
    for (i = 0; i < n; i += 8) {
        if (n - i < 8)
            eppf_group8((int)(n - i), 0, seq, seq, ri, rj, &rows, &unused);
        eppf_load3x8(pts + ps * i, ps, rows, x, x + 1, x + 2);
        for (a = 0; a < 3; a++) {
            mn[a] = _mm512_min_pd(x[a], mn[a]);  /* x < mn ? x : mn */
            mx[a] = _mm512_max_pd(x[a], mx[a]);  /* x > mx ? x : mx */
        }
    }
    for (a = 0; a < 3; a++) {
        _mm512_storeu_pd(acc, mn[a]);
        lo[a] = acc[0];
        for (k = 1; k < 8; k++)
            if (acc[k] < lo[a])
                lo[a] = acc[k];
        _mm512_storeu_pd(acc, mx[a]);
        hi[a] = acc[0];
        for (k = 1; k < 8; k++)
            if (acc[k] > hi[a])
                hi[a] = acc[k];
    }
    side = hi[0] - lo[0];
    if (hi[1] - lo[1] > side)
        side = hi[1] - lo[1];
    if (hi[2] - lo[2] > side)
        side = hi[2] - lo[2];
    inv = (double)g / side;
    memset(bits, 0, (size_t)(g * g) * sizeof(uint64_t));
    {
        const __m512d vinv = _mm512_set1_pd(inv), zero = _mm512_setzero_pd(), top = _mm512_set1_pd((double)(g - 1));
        const __m512i half = _mm512_set1_epi64(EPPF_PK_S / 2 + g);
        rows = seq;
        for (i = 0; i < n; i += 8) {
            const int m8 = n - i < 8 ? (int)(n - i) : 8;
            const __mmask8 keep = m8 < 8 ? eppf_group8(m8, 0, seq, seq, ri, rj, &rows, &unused) : (__mmask8)0xff;
            int32_t vx[8], vy[8], vz[8];
            __m512i w[3];
            eppf_load3x8(pts + ps * i, ps, rows, x, x + 1, x + 2);
            for (a = 0; a < 3; a++) {
                /* max first: NaN and t <= 0 give 0; then t >= g - 1 gives g - 1 */
                const __m512d t = _mm512_mul_pd(_mm512_sub_pd(x[a], _mm512_set1_pd(lo[a])), vinv);
                const __m256i v = _mm512_cvttpd_epi32(_mm512_min_pd(_mm512_max_pd(t, zero), top));
                _mm256_storeu_si256((__m256i *)(a == 0 ? vx : a == 1 ? vy : vz), v);
                w[a] = _mm512_add_epi64(_mm512_slli_epi64(_mm512_cvtepi32_epi64(v), EPPF_PK_FRAC), half);
            }
            _mm512_mask_storeu_epi64(pv + i, keep,
                                     _mm512_add_epi64(_mm512_add_epi64(_mm512_slli_epi64(w[0], EPPF_PK_XLANE),
                                                                       _mm512_slli_epi64(w[1], EPPF_PK_YLANE)),
                                                      w[2]));
            for (k = 0; k < 8; k++)  /* (a repeated last point sets its bit again) */
                bits[vx[k] * gi + vy[k]] |= (uint64_t)1 << vz[k];
        }
    }
}

/* The f1-f3 bins, times n4, of eight pairs from their points p and normals
 * n (x, y, z vectors): ``eppf_bins123_4``'s (and _eppf_fast.pyx's
 * ``_bin_f123``'s) IEEE operations in the same order, so the same bins. The normals are read only where n2 > 1 or
 * n3 > 1. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline __m256i eppf_bins123_8(const __m512d *pi, const __m512d *ni, const __m512d *pj, const __m512d *nj,
                                     double scale, int n1, int n2, int n3, int n4, double f1_density,
                                     const double *cos2, const double *cos3)
{
    const __m512d vscale = _mm512_set1_pd(scale), vdens = _mm512_set1_pd(f1_density);
    const __m512d top1 = _mm512_set1_pd((double)(n1 - 1)), one = _mm512_set1_pd(1.0);
    const __m256i one32 = _mm256_set1_epi32(1);
    const __m512d dx = _mm512_sub_pd(pj[0], pi[0]), dy = _mm512_sub_pd(pj[1], pi[1]);
    const __m512d dz = _mm512_sub_pd(pj[2], pi[2]);
    const __m512d dist = _mm512_sqrt_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy)),
                                                      _mm512_mul_pd(dz, dz)));
    __m512d v = _mm512_mul_pd(_mm512_mul_pd(dist, vscale), vdens);
    __m256i b1, b2 = _mm256_setzero_si256(), b3 = _mm256_setzero_si256(), b;
    int k;
    b1 = _mm512_cvttpd_epi32(_mm512_max_pd(_mm512_min_pd(v, top1), _mm512_setzero_pd()));
    if (n2 > 1) {
        __m512d inv = _mm512_div_pd(one, dist), m1, m2;
        m1 = _mm512_mul_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(ni[0], dx), _mm512_mul_pd(ni[1], dy)),
                                         _mm512_mul_pd(ni[2], dz)), inv);
        m2 = _mm512_mul_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(nj[0], dx), _mm512_mul_pd(nj[1], dy)),
                                         _mm512_mul_pd(nj[2], dz)), inv);
        m1 = _mm512_min_pd(m2, m1);  /* m2 < m1 ? m2 : m1 */
        for (k = 0; k < n2 - 1; k++)
            b2 = _mm256_mask_add_epi32(b2, _mm512_cmp_pd_mask(m1, _mm512_set1_pd(cos2[k]), _CMP_LE_OQ), b2, one32);
    }
    if (n3 > 1) {
        v = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(ni[0], nj[0]), _mm512_mul_pd(ni[1], nj[1])),
                          _mm512_mul_pd(ni[2], nj[2]));
        v = _mm512_abs_pd(v);
        for (k = 0; k < n3 - 1; k++)
            b3 = _mm256_mask_add_epi32(b3, _mm512_cmp_pd_mask(v, _mm512_set1_pd(cos3[k]), _CMP_LE_OQ), b3, one32);
    }
    b = _mm256_add_epi32(_mm256_mullo_epi32(b1, _mm256_set1_epi32(n2)), b2);
    b = _mm256_add_epi32(_mm256_mullo_epi32(b, _mm256_set1_epi32(n3)), b3);
    return _mm256_mullo_epi32(b, _mm256_set1_epi32(n4));
}

/* The lanes whose points pi and pj (x, y, z vectors) coincide: all three coordinates equal. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline __mmask8 eppf_same8(const __m512d *pi, const __m512d *pj)
{
    return _mm512_cmp_pd_mask(pi[0], pj[0], _CMP_EQ_OQ) & _mm512_cmp_pd_mask(pi[1], pj[1], _CMP_EQ_OQ)
           & _mm512_cmp_pd_mask(pi[2], pj[2], _CMP_EQ_OQ);
}

/* The f1-f3 bins, times n4, of the pairs (ii[t], jj[t]), t < m, eight at a
 * time (``eppf_bins123_8``), which also checks the pairs as ``_draw_pair`` does: returns the first t whose two
 * points coincide, or m when none does. B[t] is written for every t. Where
 * ``pn`` is not NULL, the points and normals are read from its rows
 * (``eppf_pack_rows``: the same values, one load a point). */
__attribute__((target(EPPF_AVX512_TARGET)))
static int eppf_f123_batch_avx512(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                                  const double *nrm, int64_t ns, double scale, int n1, int n2, int n3, int n4,
                                  double f1_density, const double *cos2, const double *cos3, int32_t *B,
                                  const double *pn)
{
    int32_t ri[8], rj[8];
    int t, bad = m;
    for (t = 0; t < m; t += 8) {
        const int32_t *vi, *vj;
        const __mmask8 keep = eppf_group8(m, t, ii, jj, ri, rj, &vi, &vj);
        __m512d a[7], b[7];
        __mmask8 same;
        if (pn) {
            eppf_load7x8(pn, vi, a);
            eppf_load7x8(pn, vj, b);
        } else {
            eppf_load3x8(pts, ps, vi, a, a + 1, a + 2);
            eppf_load3x8(pts, ps, vj, b, b + 1, b + 2);
            if (n2 > 1 || n3 > 1) {
                eppf_load3x8(nrm, ns, vi, a + 3, a + 4, a + 5);
                eppf_load3x8(nrm, ns, vj, b + 3, b + 4, b + 5);
            } else {
                a[3] = a[4] = a[5] = b[3] = b[4] = b[5] = _mm512_setzero_pd();
            }
        }
        same = keep & eppf_same8(a, b);
        if (same && bad == m)
            bad = t + __builtin_ctz(same);
        _mm256_mask_storeu_epi32(B + t, keep, eppf_bins123_8(a, a + 3, b, b + 3, scale, n1, n2, n3, n4, f1_density,
                                                             cos2, cos3));
    }
    return bad;
}

/* The walk setup of eight lines from voxel a[l] to voxel b[l], each already
 * in the packed walk's start form (lanes v S + S/2 + g, see _eppf_fast.pyx's
 * ``_fill_grid``): the first inner position P, the increment INC, L and the
 * entry ``tab[(L + 1) & 63]``; D (unless NULL) the differences dx, dy, dz
 * in voxels. The packed difference of two such
 * words holds the three lane differences d S exactly (each below 2**20 in
 * size), recovered by sign-extending 21-bit fields. The same integer results
 * as _eppf_fast.pyx's ``_line_bin``: the increments' scale 2**14 / L is the same
 * correctly rounded division (the value of ``recip_packed[L]``), and
 * lo | hi of T = L + 1 voxels is ``lohi[T]``, looked up in registers:
 * ``tab`` holds lohi[1..63] at 1..63 and lohi[64] at 0 (T >= 3 on every
 * walked line). No gathers: on CPUs with slow ones (AMD Zen 4) eight loads
 * and in-register look-ups cost a fraction of them. Any 65-entry table in
 * place of lohi works the same way (the skipping walk's lane states). */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_line8_avx512(__m512i a, __m512i b, const __m512i *tab, __m512i *P, __m512i *INC,
                                     __m512i *Lout, __m512i *LOHI, __m512i *D)
{
    const __m512i one = _mm512_set1_epi64(1);
    const __m512i d = _mm512_sub_epi64(b, a);
    const __m512i dzs = _mm512_srai_epi64(_mm512_slli_epi64(d, 43), 43);
    const __m512i d1 = _mm512_srai_epi64(_mm512_sub_epi64(d, dzs), EPPF_PK_YLANE);
    const __m512i dys = _mm512_srai_epi64(_mm512_slli_epi64(d1, 43), 43);
    const __m512i dxs = _mm512_srai_epi64(_mm512_sub_epi64(d1, dys), EPPF_PK_YLANE);
    const __m512i dx = _mm512_srai_epi64(dxs, EPPF_PK_FRAC), dy = _mm512_srai_epi64(dys, EPPF_PK_FRAC);
    const __m512i dz = _mm512_srai_epi64(dzs, EPPF_PK_FRAC);
    const __m512i L = _mm512_max_epi64(_mm512_max_epi64(_mm512_abs_epi64(dx), _mm512_abs_epi64(dy)),
                                       _mm512_abs_epi64(dz));
    /* L <= 1 lanes are never walked; max(L, 1) only keeps them finite */
    const __m512d q = _mm512_div_pd(_mm512_set1_pd((double)EPPF_PK_S), _mm512_cvtepi64_pd(_mm512_max_epi64(L, one)));
    const __m512i ix = _mm512_cvtpd_epi64(_mm512_mul_pd(_mm512_cvtepi64_pd(dx), q));  /* = llrint */
    const __m512i iy = _mm512_cvtpd_epi64(_mm512_mul_pd(_mm512_cvtepi64_pd(dy), q));
    const __m512i iz = _mm512_cvtpd_epi64(_mm512_mul_pd(_mm512_cvtepi64_pd(dz), q));
    const __m512i inc = _mm512_add_epi64(_mm512_add_epi64(_mm512_slli_epi64(ix, EPPF_PK_XLANE),
                                                          _mm512_slli_epi64(iy, EPPF_PK_YLANE)), iz);
    /* tab[(L + 1) & 63]: bits 0-3 pick within 16 entries, bits 4 and 5 which 16 */
    const __m512i k = _mm512_add_epi64(L, one);
    const __mmask8 b4 = _mm512_test_epi64_mask(k, _mm512_set1_epi64(16));
    const __mmask8 b5 = _mm512_test_epi64_mask(k, _mm512_set1_epi64(32));
    const __m512i r01 = _mm512_mask_blend_epi64(b4, _mm512_permutex2var_epi64(tab[0], k, tab[1]),
                                                _mm512_permutex2var_epi64(tab[2], k, tab[3]));
    const __m512i r23 = _mm512_mask_blend_epi64(b4, _mm512_permutex2var_epi64(tab[4], k, tab[5]),
                                                _mm512_permutex2var_epi64(tab[6], k, tab[7]));
    *P = _mm512_add_epi64(a, inc);
    *INC = inc;
    *Lout = L;
    *LOHI = _mm512_mask_blend_epi64(b5, r01, r23);
    if (D) {
        D[0] = dx;
        D[1] = dy;
        D[2] = dz;
    }
}

/* ``eppf_line8_avx512`` of the pairs (i8[l], j8[l]), their voxels read from pv. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_setup8_avx512(const int32_t *i8, const int32_t *j8, const int64_t *pv, const __m512i *tab,
                                      __m512i *P, __m512i *INC, __m512i *Lout, __m512i *LOHI)
{
    const __m512i a = _mm512_set_epi64(pv[i8[7]], pv[i8[6]], pv[i8[5]], pv[i8[4]], pv[i8[3]], pv[i8[2]], pv[i8[1]],
                                       pv[i8[0]]);
    const __m512i b = _mm512_set_epi64(pv[j8[7]], pv[j8[6]], pv[j8[5]], pv[j8[4]], pv[j8[3]], pv[j8[2]], pv[j8[1]],
                                       pv[j8[0]]);
    eppf_line8_avx512(a, b, tab, P, INC, Lout, LOHI, NULL);
}

/* ``tab`` of ``eppf_setup8_avx512`` from lohi[0..64]. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_lohi_tab_avx512(const int64_t *lohi, __m512i *tab)
{
    int k;
    for (k = 0; k < 8; k++)
        tab[k] = _mm512_loadu_si512(lohi + 8 * k);
    tab[0] = _mm512_mask_mov_epi64(tab[0], 1, _mm512_set1_epi64(lohi[64]));
}

/* The walk setup of the pairs (ii[t], jj[t]), t < m, eight at a time
   (``eppf_setup8_avx512``): P, INC, L and the counters (META) of each line. */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_f4_setup_avx512(int m, const int32_t *ii, const int32_t *jj, const int64_t *pv,
                                 const int64_t *lohi, const double *recip_packed, int64_t *P, int64_t *INC,
                                 int32_t *Ls, int64_t *META)
{
    __m512i tab[8];
    int32_t ri[8], rj[8];
    int t;
    (void)recip_packed;
    eppf_lohi_tab_avx512(lohi, tab);
    for (t = 0; t < m; t += 8) {
        const int32_t *i8, *j8;
        const __mmask8 keep = eppf_group8(m, t, ii, jj, ri, rj, &i8, &j8);
        __m512i p, inc, L, lh;
        eppf_setup8_avx512(i8, j8, pv, tab, &p, &inc, &L, &lh);
        _mm512_mask_storeu_epi64(P + t, keep, p);
        _mm512_mask_storeu_epi64(INC + t, keep, inc);
        _mm256_mask_storeu_epi32(Ls + t, keep, _mm512_cvtepi64_epi32(L));
        /* rem = L - 1 (a wrapped field for lines of L <= 1, which are never walked) | lo | hi */
        _mm512_mask_storeu_epi64(META + t, keep, _mm512_add_epi64(
            lh, _mm512_and_si512(_mm512_sub_epi64(L, _mm512_set1_epi64(1)), _mm512_set1_epi64(EPPF_META_MASK))));
    }
}

/* The grouped AVX-512 walk (level 2): eight lanes, the stopping rule of
 * _eppf_walk.h's header and ``_line_bin``'s bins, added to B. One step of a lane is a few
 * byte operations on the packed position: VBMI's multishift copies the integer
 * parts of y, x, z to bytes 0, 1, 2 of the lane, a multiply-add of bytes 0
 * and 1 by (1, g) gives the row x g + y, byte 2 the bit; lanes past their steps
 * are masked out of the gather and stand still. */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_f4_batch_avx512(int m, const int32_t *ii, const int32_t *jj, const int64_t *pv,
                                 const uint64_t *bits, int64_t g, const int32_t *thr, int n4,
                                 const int64_t *lohi, const double *recip_packed, int32_t *B)
{
    int64_t P[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    int64_t INC[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    int32_t Ls[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    int64_t META[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    int order[EPPF_WALK_BATCH + 16];
    int k, n_walk, n_pad, grp;
    const __m512i one = _mm512_set1_epi64(1), two = _mm512_set1_epi64(2), zero = _mm512_setzero_si512();
    const __m512i three = _mm512_set1_epi64(3), four = _mm512_set1_epi64(4);
    /* multishift control: byte 0 <- bits 35.. (y), byte 1 <- bits 56.. (x), byte 2 <- bits 14.. (z) */
    const __m512i ctrl = _mm512_set1_epi64(((int64_t)EPPF_PK_ZSHIFT << 16) | ((int64_t)EPPF_PK_XSHIFT << 8)
                                           | EPPF_PK_YSHIFT);
    const __m512i m6 = _mm512_set1_epi64(0x3f3f3f);
    const __m512i mul = _mm512_set1_epi64((g << 8) | 1);  /* bytes (1, g): y + g x, at most 4095 */
    const long long *base = (const long long *)bits;
    (void)recip_packed;

    eppf_f4_setup_avx512(m, ii, jj, pv, lohi, recip_packed, P, INC, Ls, META);
    n_walk = eppf_f4_order(m, Ls, order);
    /* Padding lanes of the last group: a valid pair's position, masked out. */
    n_pad = (n_walk + 15) & ~15;
    for (k = n_walk; k < n_pad; k++)
        order[k] = order[0];

#define EPPF_STEP512(MASKED, p, inc, occ, on)                                                     \
    do {                                                                                          \
        __m512i t_ = _mm512_and_si512(_mm512_multishift_epi64_epi8(ctrl, p), m6);                \
        __m512i row_ = _mm512_maddubs_epi16(t_, mul);                                             \
        __m512i bit_ = _mm512_sllv_epi64(one, _mm512_srli_epi64(t_, 16));                        \
        __m512i w_;                                                                               \
        __mmask8 hit_;                                                                            \
        if (MASKED) {                                                                             \
            w_ = _mm512_mask_i64gather_epi64(zero, on, row_, base, 8);                            \
            p = _mm512_mask_add_epi64(p, on, p, inc);                                             \
        } else {                                                                                  \
            w_ = _mm512_i64gather_epi64(row_, base, 8);                                           \
            p = _mm512_add_epi64(p, inc);                                                         \
        }                                                                                         \
        hit_ = _mm512_test_epi64_mask(w_, bit_);                                                  \
        occ = _mm512_mask_add_epi64(occ, hit_, occ, one);                                         \
    } while (0)

/* A[order[G + l]], l < 8, as a vector: eight loads (cheaper than a gather on
   CPUs with slow gathers, such as AMD Zen 4). */
#define EPPF_PICK8(A, G)                                                                          \
    _mm512_set_epi64((A)[order[(G) + 7]], (A)[order[(G) + 6]], (A)[order[(G) + 5]], (A)[order[(G) + 4]], \
                     (A)[order[(G) + 3]], (A)[order[(G) + 2]], (A)[order[(G) + 1]], (A)[order[(G) + 0]])

/* The lanes of the group at walk position G: nothing to walk in padding lanes
   (rem = 0, occ = lo = hi = 0); then the shortest quiet stretch of the
   group: every lane is still undecided for its first
   clamp(occ + rem - lo + 1, 0, rem) steps (0 once occ >= hi). */
#define EPPF_GROUP512(G, valid, p, inc, lo, hi, rem, occ, quiet)                                  \
    do {                                                                                          \
        __m512i need_, steps_;                                                                    \
        __mmask8 live_;                                                                           \
        valid = n_walk - (G) >= 8 ? (__mmask8)0xff                                                \
                : n_walk <= (G) ? (__mmask8)0 : (__mmask8)((1u << (n_walk - (G))) - 1);           \
        p = EPPF_PICK8(P, G);                                                                     \
        inc = _mm512_maskz_mov_epi64(valid, EPPF_PICK8(INC, G));                                  \
        rem = _mm512_maskz_mov_epi64(valid, EPPF_PICK8(META, G));                                 \
        lo = _mm512_and_si512(_mm512_srli_epi64(rem, EPPF_META_LO), _mm512_set1_epi64(EPPF_META_MASK)); \
        hi = _mm512_srli_epi64(rem, EPPF_META_HI);                                                \
        rem = _mm512_and_si512(rem, _mm512_set1_epi64(EPPF_META_MASK));                           \
        occ = _mm512_maskz_mov_epi64(valid, two);                                                 \
        need_ = _mm512_add_epi64(_mm512_sub_epi64(_mm512_add_epi64(occ, rem), lo), one);          \
        steps_ = _mm512_min_epi64(rem, need_);                                                    \
        live_ = _mm512_cmpgt_epi64_mask(hi, occ) & _mm512_cmpgt_epi64_mask(steps_, zero);         \
        quiet = live_ == 0xff ? _mm512_reduce_min_epi64(steps_) : 0;                              \
        rem = _mm512_sub_epi64(rem, _mm512_set1_epi64(quiet));                                    \
    } while (0)

/* Four steps in the lanes ``live`` (still undecided: occ < hi,
   occ + rem >= lo, rem > 0), never past a line's last inner voxel. A lane
   decided within the four walks on: counting more voxels of its own line
   cannot change a certain bin (occ only grows, and stays below lo when
   even all the rest could not lift it there). */
#define EPPF_LIVE512(occ, rem, lo, hi)                                                            \
    (_mm512_cmpgt_epi64_mask(hi, occ) & _mm512_cmpgt_epi64_mask(rem, zero)                        \
     & _mm512_cmpge_epi64_mask(_mm512_add_epi64(occ, rem), lo))
#define EPPF_FOUR512(live, p, inc, occ, rem)                                                      \
    do {                                                                                          \
        __mmask8 on_ = live;                                                                      \
        EPPF_STEP512(1, p, inc, occ, on_);                                                        \
        on_ = live & _mm512_cmpgt_epi64_mask(rem, one);                                           \
        EPPF_STEP512(1, p, inc, occ, on_);                                                        \
        on_ = live & _mm512_cmpgt_epi64_mask(rem, two);                                           \
        EPPF_STEP512(1, p, inc, occ, on_);                                                        \
        on_ = live & _mm512_cmpgt_epi64_mask(rem, three);                                         \
        EPPF_STEP512(1, p, inc, occ, on_);                                                        \
        rem = _mm512_mask_sub_epi64(rem, live, rem, _mm512_min_epi64(rem, four));                 \
    } while (0)

/* Add the bins of the group at walk position G to B. */
#define EPPF_BINS512(G, occ, lo, hi)                                                              \
    do {                                                                                          \
        int64_t res_[8] __attribute__((aligned(64)));                                             \
        int l_;                                                                                   \
        if (n4 <= 3) {                                                                            \
            /* lo and hi are all the thresholds (one and the same for n4 = 2) */                  \
            __m512i b_ = _mm512_maskz_mov_epi64(_mm512_cmpge_epi64_mask(occ, lo), one);           \
            if (n4 == 3)                                                                          \
                b_ = _mm512_mask_add_epi64(b_, _mm512_cmpge_epi64_mask(occ, hi), b_, one);        \
            _mm512_store_si512(res_, b_);                                                         \
            for (l_ = 0; l_ < 8 && (G) + l_ < n_walk; l_++)                                       \
                B[order[(G) + l_]] += (int32_t)res_[l_];                                          \
        } else {                                                                                  \
            _mm512_store_si512(res_, occ);                                                        \
            for (l_ = 0; l_ < 8 && (G) + l_ < n_walk; l_++) {                                     \
                int o_ = order[(G) + l_], b_ = 0, j_;                                             \
                const int32_t *th_ = thr + (int64_t)(Ls[o_] + 1) * n4;                           \
                for (j_ = 1; j_ < n4; j_++)                                                       \
                    b_ += res_[l_] >= th_[j_];                                                    \
                B[o_] += b_;                                                                      \
            }                                                                                     \
        }                                                                                         \
    } while (0)

    /* Two groups at a time, so that the latency of one group's gathers
       before its next test hides behind the other group's steps. */
    for (grp = 0; grp < n_walk; grp += 16) {
        __m512i pa, inca, loa, hia, rema, occa, pb, incb, lob, hib, remb, occb;
        __mmask8 va, vb;
        int64_t qa, qb, s, q;
        EPPF_GROUP512(grp, va, pa, inca, loa, hia, rema, occa, qa);
        EPPF_GROUP512(grp + 8, vb, pb, incb, lob, hib, remb, occb, qb);
        q = qa < qb ? qa : qb;
        for (s = 0; s < q; s++) {
            EPPF_STEP512(0, pa, inca, occa, va);
            EPPF_STEP512(0, pb, incb, occb, vb);
        }
        for (; s < qa; s++)
            EPPF_STEP512(0, pa, inca, occa, va);
        for (; s < qb; s++)
            EPPF_STEP512(0, pb, incb, occb, vb);
        for (;;) {
            const __mmask8 la = EPPF_LIVE512(occa, rema, loa, hia), lb = EPPF_LIVE512(occb, remb, lob, hib);
            if (!(la | lb))
                break;
            if (la)
                EPPF_FOUR512(la, pa, inca, occa, rema);
            if (lb)
                EPPF_FOUR512(lb, pb, incb, occb, remb);
        }
        EPPF_BINS512(grp, occa, loa, hia);
        if (grp + 8 < n_walk)
            EPPF_BINS512(grp + 8, occb, lob, hib);
    }
#undef EPPF_STEP512
#undef EPPF_GROUP512
#undef EPPF_PICK8
#undef EPPF_LIVE512
#undef EPPF_FOUR512
#undef EPPF_BINS512
    if (n_walk < m)
        eppf_f4_short_lines(m, Ls, thr, n4, B);
}

#else

static void eppf_f4_batch_avx512(int m, const int32_t *ii, const int32_t *jj, const int64_t *pv,
                                 const uint64_t *bits, int64_t g, const int32_t *thr, int n4,
                                 const int64_t *lohi, const double *recip_packed, int32_t *B)
{
    (void)m; (void)ii; (void)jj; (void)pv; (void)bits; (void)g; (void)thr; (void)n4; (void)lohi;
    (void)recip_packed; (void)B;
}

static void eppf_draw_batch_avx512(int m, uint64_t state, uint32_t n, int32_t *out_i, int32_t *out_j)
{
    (void)m; (void)state; (void)n; (void)out_i; (void)out_j;
}

static void eppf_fill_grid_avx512(const double *pts, int64_t ps, int64_t n, int64_t g, uint64_t *bits, int64_t *pv)
{
    (void)pts; (void)ps; (void)n; (void)g; (void)bits; (void)pv;
}

static int eppf_f123_batch_avx512(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                                  const double *nrm, int64_t ns, double scale, int n1, int n2, int n3, int n4,
                                  double f1_density, const double *cos2, const double *cos3, int32_t *B,
                                  const double *pn)
{
    (void)m; (void)ii; (void)jj; (void)pts; (void)ps; (void)nrm; (void)ns; (void)scale; (void)n1; (void)n2; (void)n3;
    (void)n4; (void)f1_density; (void)cos2; (void)cos3; (void)B; (void)pn;
    return 0;
}

#endif

#endif /* EPPF_WALK_AVX512_H */
