/* SIMD distance scan and k-th selection of the normals kernel's fast
 * neighbor search (_normals_fast.pyx's ``_knn_near`` and ``_knn_block``),
 * chosen at run time:
 *
 * - AVX-512 (F): eight grid-order points at a time;
 * - AVX2: four at a time, the survivors packed with a permutation table;
 * - portable (any CPU, the "scalar" level): two at a time in GCC/clang
 *   vector registers (SSE2, NEON), plain loops with other compilers.
 *
 * the covariance of a neighborhood (``eppf_nrm_covariance``: the order of
 * operations the lanes of _normals_lanes.h follow, and the kernel's own
 * code where the compiler has no vector extensions), and, included once per
 * level, the covariances and eigenvectors of eight neighborhoods at a time
 * (_normals_lanes.h).
 *
 * ``eppf_nrm_scan_*`` offers the points at grid-order positions [b, e) to
 * the candidate list: for each, in ascending position, the squared distance
 * ``d2 = (dx * dx + dy * dy) + dz * dz`` with ``d = point - query`` is
 * computed, and the points with ``d2 <= guess`` are appended to ``cand_d2``
 * and ``cand_pos`` from index ``m``; the new count is returned. These are the
 * IEEE operations, in the order, of the scalar loop in _normals_fast.pyx (no
 * FMA: the targets name no FMA and the build passes -ffp-contract=off), so
 * the list is the same bit for bit. The coordinates come in structure-of-
 * arrays form (``sx``, ``sy``, ``sz``, one double per point).
 *
 * Whole vectors are stored at ``cand_d2 + m`` and ``cand_pos + m`` (only the
 * first popcount lanes count), so both arrays need EPPF_NRM_SLACK entries
 * beyond the largest count; the loads past ``e`` are masked (AVX-512) or left
 * to a scalar tail (AVX2), so nothing beyond [b, e) is read.
 *
 * The selection is _normals_fast.pyx's histogram code at the portable level.
 */
#ifndef EPPF_NORMALS_SIMD_H
#define EPPF_NORMALS_SIMD_H

#include <stdint.h>

#include "../utils/_cpu.h"

/* Entries written past the count by one vector store. */
#define EPPF_NRM_SLACK 8
/* Buckets of the fast path's selection by squared distance. */
#define EPPF_NRM_BUCKETS 32

/* The covariance of the k points of ``spts`` (x, y, z per point) at the
 * grid-order positions ``kpos``: the mean (mx, my, mz) = (sum of the points
 * in the order of ``kpos``) / k, then, in that order, the sums of
 * x * x, x * y, x * z, y * y, y * z and z * z over (x, y, z) = point - mean,
 * written row-major to ``cov`` (nine entries, symmetric). Each sum is
 * accumulated alone, term after term, with the IEEE operations of the plain
 * loop, so computing two sums side by side in one vector register (GCC and
 * clang vector extensions: SSE2 on x86-64, NEON on ARM64) gives the same
 * bits on every CPU. */
#if defined(__GNUC__)
typedef double eppf_nrm_v2d __attribute__((vector_size(16)));

static inline void eppf_nrm_covariance(const double *spts, const int64_t *kpos, int64_t k, double *cov)
{
    eppf_nrm_v2d mxy = {0.0, 0.0}, xy, sxx_xy = {0.0, 0.0}, sxz_yy = {0.0, 0.0}, syz_zz = {0.0, 0.0};
    double mz = 0.0, z, dk = (double)k;
    int64_t i;
    for (i = 0; i < k; i++) {
        const double *pt = spts + 3 * kpos[i];
        xy = (eppf_nrm_v2d){pt[0], pt[1]};
        mxy += xy;
        mz += pt[2];
    }
    mxy /= (eppf_nrm_v2d){dk, dk};
    mz /= dk;
    for (i = 0; i < k; i++) {
        const double *pt = spts + 3 * kpos[i];
        xy = (eppf_nrm_v2d){pt[0], pt[1]} - mxy;
        z = pt[2] - mz;
        sxx_xy += (eppf_nrm_v2d){xy[0], xy[0]} * xy;
        sxz_yy += (eppf_nrm_v2d){xy[0], xy[1]} * (eppf_nrm_v2d){z, xy[1]};
        syz_zz += (eppf_nrm_v2d){xy[1], z} * (eppf_nrm_v2d){z, z};
    }
    cov[0] = sxx_xy[0];
    cov[1] = cov[3] = sxx_xy[1];
    cov[2] = cov[6] = sxz_yy[0];
    cov[4] = sxz_yy[1];
    cov[5] = cov[7] = syz_zz[0];
    cov[8] = syz_zz[1];
}

/* Normals of eight neighborhoods at once, one per vector lane, in
 * _normals_lanes.h (included once per SIMD level): the covariances
 * (``eppf_nrm_cov8_*``) and the eigenvector of the smallest eigenvalue
 * (``eppf_nrm_eig8_*``), each the scalar code's operations lane for lane. */
#define EPPF_NRM_LANES 8
/* Below this ratio of (lambda_mid - lambda_min) to (lambda_max - lambda_min)
 * the closed-form eigenvector is replaced by Jacobi's. */
#define EPPF_NRM_GAP_RATIO 1e-3

#if defined(__GNUC__)
#define EPPF_NRM_EIG_VEC 1
typedef double eppf_nrm_v4d __attribute__((vector_size(32)));
typedef double eppf_nrm_v8d __attribute__((vector_size(64)));
typedef long long eppf_nrm_v2l __attribute__((vector_size(16)));
typedef long long eppf_nrm_v4l __attribute__((vector_size(32)));
typedef long long eppf_nrm_v8l __attribute__((vector_size(64)));

/* The portable level's (baseline vector code of the target: SSE2, NEON). */
#define EPPF_NRM_L_NAME(f) f##_portable
#define EPPF_NRM_L_ATTR
#define EPPF_NRM_L_VT eppf_nrm_v2d
#define EPPF_NRM_L_VL eppf_nrm_v2l
#define EPPF_NRM_L_W 2
#include "_normals_lanes.h"
#else
#define EPPF_NRM_EIG_VEC 0
/* never called: the kernel solves lane by lane without EPPF_NRM_EIG_VEC */
static unsigned eppf_nrm_eig8_portable(const double *c, double *out)
{
    (void)c; (void)out;
    return 0;
}

static void eppf_nrm_cov8_portable(const double *nb, int64_t k, double *c)
{
    (void)nb; (void)k; (void)c;
}
#endif

/* The portable distance scan (every CPU; the scalar loop's operations),
 * two points per vector register: eppf_nrm_scan_avx2's contract, writing
 * only the entries it counts plus one (cand_d2 and cand_pos need one entry
 * of slack). */
static inline int64_t eppf_nrm_scan_portable(const double *sx, const double *sy, const double *sz, int64_t b,
                                             int64_t e, double qx, double qy, double qz, double guess,
                                             double *cand_d2, int64_t *cand_pos, int64_t m)
{
    const eppf_nrm_v2d vqx = {qx, qx}, vqy = {qy, qy}, vqz = {qz, qz};
    eppf_nrm_v2d dx, dy, dz, d2;
    int64_t p = b;
    for (; p + 2 <= e; p += 2) {
        dx = (eppf_nrm_v2d){sx[p], sx[p + 1]} - vqx;
        dy = (eppf_nrm_v2d){sy[p], sy[p + 1]} - vqy;
        dz = (eppf_nrm_v2d){sz[p], sz[p + 1]} - vqz;
        d2 = (dx * dx + dy * dy) + dz * dz;
        cand_d2[m] = d2[0];
        cand_pos[m] = p;
        m += d2[0] <= guess;
        cand_d2[m] = d2[1];
        cand_pos[m] = p + 1;
        m += d2[1] <= guess;
    }
    if (p < e) {
        double ex = sx[p] - qx, ey = sy[p] - qy, ez = sz[p] - qz, ed2 = (ex * ex + ey * ey) + ez * ez;
        cand_d2[m] = ed2;
        cand_pos[m] = p;
        m += ed2 <= guess;
    }
    return m;
}
#else
static inline void eppf_nrm_covariance(const double *spts, const int64_t *kpos, int64_t k, double *cov)
{
    double mx = 0.0, my = 0.0, mz = 0.0, x, y, z, dk = (double)k;
    int64_t i;
    for (i = 0; i < 9; i++)
        cov[i] = 0.0;
    for (i = 0; i < k; i++) {
        mx += spts[3 * kpos[i]];
        my += spts[3 * kpos[i] + 1];
        mz += spts[3 * kpos[i] + 2];
    }
    mx /= dk;
    my /= dk;
    mz /= dk;
    for (i = 0; i < k; i++) {
        x = spts[3 * kpos[i]] - mx;
        y = spts[3 * kpos[i] + 1] - my;
        z = spts[3 * kpos[i] + 2] - mz;
        cov[0] += x * x;
        cov[1] += x * y;
        cov[2] += x * z;
        cov[4] += y * y;
        cov[5] += y * z;
        cov[8] += z * z;
    }
    cov[3] = cov[1];
    cov[6] = cov[2];
    cov[7] = cov[5];
}

static inline int64_t eppf_nrm_scan_portable(const double *sx, const double *sy, const double *sz, int64_t b,
                                             int64_t e, double qx, double qy, double qz, double guess,
                                             double *cand_d2, int64_t *cand_pos, int64_t m)
{
    int64_t p;
    for (p = b; p < e; p++) {
        double dx = sx[p] - qx, dy = sy[p] - qy, dz = sz[p] - qz, d2 = (dx * dx + dy * dy) + dz * dz;
        cand_d2[m] = d2;
        cand_pos[m] = p;
        m += d2 <= guess;
    }
    return m;
}
#endif

#if EPPF_CPU_CHECKS  /* (gcc or clang on x86-64, EPPF_NO_SIMD not defined: _cpu.h) */
#define EPPF_NRM_SIMD 1
#include <immintrin.h>
#else
#define EPPF_NRM_SIMD 0
#endif

/* AVX-512 F (with the OS saving the zmm state: libgcc's cpu check reads XCR0). */
static int eppf_nrm_has_avx512(void)
{
    return eppf_cpu_has(EPPF_CPU_AVX2 | EPPF_CPU_AVX512F | EPPF_CPU_POPCNT);
}

static int eppf_nrm_has_avx2(void)
{
    return eppf_cpu_has(EPPF_CPU_AVX2 | EPPF_CPU_POPCNT);
}

#if EPPF_NRM_SIMD

/* The SIMD selections' bisection for the k-th's bucket over [lo, hi] (``count_mid``:
 * the number of candidates in the buckets up to mid); leaves the bucket in ``bk`` and
 * the count of the buckets below it in ``below`` (0 to begin with), kept from the
 * pass that moved lo last instead of counted by one more pass. */
#define EPPF_NRM_BISECT(count_mid)                 \
    do {                                           \
        while (lo < hi) {                          \
            int64_t mid = (lo + hi) / 2, c_;       \
            c_ = (count_mid);                      \
            if (c_ >= k) {                         \
                hi = mid;                          \
            } else {                               \
                lo = mid + 1;                      \
                below = c_;                        \
            }                                      \
        }                                          \
        bk = lo;                                   \
    } while (0)

/* The candidate of rank ``need - 1`` by (d2, index) among the n_in >= need
 * candidates ``sel`` (in ascending index) of the k-th's bucket: the SIMD
 * selections' last step, as in the scalar code of _normals_fast.pyx. */
static inline int64_t eppf_nrm_rank_in_bucket(const double *cand_d2, const int64_t *sel, int64_t n_in,
                                              int64_t need)
{
    int64_t i, j, rank, kth_i = sel[0];
    double di;
    for (i = 0; i < n_in; i++) {
        di = cand_d2[sel[i]];
        rank = 0;
        for (j = 0; j < i; j++)
            rank += cand_d2[sel[j]] <= di;
        for (j = i + 1; j < n_in; j++)
            rank += cand_d2[sel[j]] < di;
        if (rank == need - 1)
            kth_i = sel[i];
    }
    return kth_i;
}

__attribute__((target("avx2,avx512f,popcnt")))
static int64_t eppf_nrm_scan_avx512(const double *sx, const double *sy, const double *sz, int64_t b, int64_t e,
                                    double qx, double qy, double qz, double guess, double *cand_d2,
                                    int64_t *cand_pos, int64_t m)
{
    const __m512d vqx = _mm512_set1_pd(qx), vqy = _mm512_set1_pd(qy), vqz = _mm512_set1_pd(qz);
    const __m512d vg = _mm512_set1_pd(guess);
    const __m512i step = _mm512_set1_epi64(8);
    __m512i pos = _mm512_add_epi64(_mm512_set1_epi64(b), _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0));
    int64_t p = b;
    for (; p < e; p += 8) {
        int64_t left = e - p;
        __mmask8 live = left >= 8 ? (__mmask8)0xFF : (__mmask8)((1u << left) - 1u);
        __m512d dx = _mm512_sub_pd(_mm512_maskz_loadu_pd(live, sx + p), vqx);
        __m512d dy = _mm512_sub_pd(_mm512_maskz_loadu_pd(live, sy + p), vqy);
        __m512d dz = _mm512_sub_pd(_mm512_maskz_loadu_pd(live, sz + p), vqz);
        __m512d d2 = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy)),
                                   _mm512_mul_pd(dz, dz));
        __mmask8 keep = _mm512_mask_cmp_pd_mask(live, d2, vg, _CMP_LE_OQ);
        /* register compress, then a whole-vector store (the memory form is slow on some CPUs) */
        _mm512_storeu_pd(cand_d2 + m, _mm512_maskz_compress_pd(keep, d2));
        _mm512_storeu_si512((void *)(cand_pos + m), _mm512_maskz_compress_epi64(keep, pos));
        m += _mm_popcnt_u32((unsigned)keep);
        pos = _mm512_add_epi64(pos, step);
    }
    return m;
}

/* Candidates [0, m) with x = d2 * to_bucket below ``t`` (t = b + 1: the buckets up to b), eight at a time. */
__attribute__((target("avx2,avx512f,popcnt")))
static inline int64_t eppf_nrm_count_below(const double *cand_d2, int64_t m, __m512d vscale, double t)
{
    const __m512d vt = _mm512_set1_pd(t);
    int64_t i, count = 0;
    for (i = 0; i < m; i += 8) {
        int64_t left = m - i;
        __mmask8 live = left >= 8 ? (__mmask8)0xFF : (__mmask8)((1u << left) - 1u);
        __m512d x = _mm512_mul_pd(_mm512_maskz_loadu_pd(live, cand_d2 + i), vscale);
        count += _mm_popcnt_u32((unsigned)_mm512_mask_cmp_pd_mask(live, x, vt, _CMP_LT_OQ));
    }
    return count;
}

/* The fast path's selection (_normals_fast.pyx's ``_knn_block`` after the
 * scan), eight candidates at a time: among the m >= k candidates (cand_d2,
 * cand_pos, in ascending position), the k-th smallest by (d2, index) is found
 * and the positions of the k smallest are written to ``kpos`` in ascending
 * position; the k-th's index is returned. Buckets are those of the scalar
 * code, ``min(floor(d2 * to_bucket), EPPF_NRM_BUCKETS - 1)``, with
 * bucket(x) < b exactly when x < b; the bucket of the k-th is found by
 * bisection over bucket counts instead of a histogram, and ranked inside as
 * there. The k-th is unique, so the list is that of the scalar code whatever
 * the method. ``sel`` needs m + EPPF_NRM_SLACK entries, ``kpos`` k +
 * EPPF_NRM_SLACK. */
__attribute__((target("avx2,avx512f,popcnt")))
static int64_t eppf_nrm_select_avx512(const double *cand_d2, const int64_t *cand_pos, int64_t m, int64_t k,
                                      double to_bucket, int64_t *sel, int64_t *kpos)
{
    const __m512d vscale = _mm512_set1_pd(to_bucket);
    const __m512i iota = _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0);
    int64_t lo = 0, hi = EPPF_NRM_BUCKETS - 1, bk, below = 0, need, n_in = 0, i, j, kth_i;
    double kth;
    /* the smallest bucket bk whose count with those below reaches k (the top bucket holds the rest),
     * and that count without bk's (``below``, kept for lo: 0 for lo = 0) */
    EPPF_NRM_BISECT(eppf_nrm_count_below(cand_d2, m, vscale, (double)(mid + 1)));
    need = k - below;
    {
        const __m512d vlo = _mm512_set1_pd((double)bk), vhi = _mm512_set1_pd((double)(bk + 1));
        for (i = 0; i < m; i += 8) {
            int64_t left = m - i;
            __mmask8 live = left >= 8 ? (__mmask8)0xFF : (__mmask8)((1u << left) - 1u);
            __m512d x = _mm512_mul_pd(_mm512_maskz_loadu_pd(live, cand_d2 + i), vscale);
            __mmask8 in = live;
            if (bk > 0) /* not below bk: NaN (never counted below) joins the top bucket, as in the scalar code */
                in &= _mm512_mask_cmp_pd_mask(live, x, vlo, _CMP_NLT_UQ);
            if (bk < EPPF_NRM_BUCKETS - 1)
                in &= _mm512_mask_cmp_pd_mask(live, x, vhi, _CMP_LT_OQ);
            _mm512_storeu_si512((void *)(sel + n_in),
                                _mm512_maskz_compress_epi64(in, _mm512_add_epi64(_mm512_set1_epi64(i), iota)));
            n_in += _mm_popcnt_u32((unsigned)in);
        }
    }
    kth_i = eppf_nrm_rank_in_bucket(cand_d2, sel, n_in, need);
    kth = cand_d2[kth_i];
    /* everything up to the k-th in (d2, index) order, in position order */
    {
        const __m512d vk = _mm512_set1_pd(kth);
        const __m512i vki = _mm512_set1_epi64(kth_i);
        j = 0;
        for (i = 0; i < m; i += 8) {
            int64_t left = m - i;
            __mmask8 live = left >= 8 ? (__mmask8)0xFF : (__mmask8)((1u << left) - 1u);
            __m512d d2 = _mm512_maskz_loadu_pd(live, cand_d2 + i);
            __m512i idx = _mm512_add_epi64(_mm512_set1_epi64(i), iota);
            __mmask8 keep = _mm512_mask_cmp_pd_mask(live, d2, vk, _CMP_LT_OQ)
                            | (_mm512_mask_cmp_pd_mask(live, d2, vk, _CMP_EQ_OQ)
                               & _mm512_cmp_epi64_mask(idx, vki, _MM_CMPINT_LE));
            _mm512_storeu_si512((void *)(kpos + j),
                                _mm512_maskz_compress_epi64(keep, _mm512_maskz_loadu_epi64(live, cand_pos + i)));
            j += _mm_popcnt_u32((unsigned)keep);
        }
    }
    return kth_i;
}

/* The lane solvers (_normals_lanes.h) in AVX-512 registers. */
#define EPPF_NRM_L_NAME(f) f##_avx512
#define EPPF_NRM_L_ATTR __attribute__((target("avx2,avx512f,popcnt")))
#define EPPF_NRM_L_VT eppf_nrm_v8d
#define EPPF_NRM_L_VL eppf_nrm_v8l
#define EPPF_NRM_L_W 8
#include "_normals_lanes.h"

/* Lane permutations (as eight 32-bit indices) that move the lanes of a 4-bit mask to the front. */
static const int32_t eppf_nrm_pack4[16][8] = {
    {0, 1, 2, 3, 4, 5, 6, 7}, {0, 1, 2, 3, 4, 5, 6, 7}, {2, 3, 0, 1, 4, 5, 6, 7}, {0, 1, 2, 3, 4, 5, 6, 7},
    {4, 5, 0, 1, 2, 3, 6, 7}, {0, 1, 4, 5, 2, 3, 6, 7}, {2, 3, 4, 5, 0, 1, 6, 7}, {0, 1, 2, 3, 4, 5, 6, 7},
    {6, 7, 0, 1, 2, 3, 4, 5}, {0, 1, 6, 7, 2, 3, 4, 5}, {2, 3, 6, 7, 0, 1, 4, 5}, {0, 1, 2, 3, 6, 7, 4, 5},
    {4, 5, 6, 7, 0, 1, 2, 3}, {0, 1, 4, 5, 6, 7, 2, 3}, {2, 3, 4, 5, 6, 7, 0, 1}, {0, 1, 2, 3, 4, 5, 6, 7},
};

/* The lane solvers (_normals_lanes.h) in AVX2 registers. */
#define EPPF_NRM_L_NAME(f) f##_avx2
#define EPPF_NRM_L_ATTR __attribute__((target("avx2,popcnt")))
#define EPPF_NRM_L_VT eppf_nrm_v4d
#define EPPF_NRM_L_VL eppf_nrm_v4l
#define EPPF_NRM_L_W 4
#include "_normals_lanes.h"

__attribute__((target("avx2,popcnt")))
static int64_t eppf_nrm_scan_avx2(const double *sx, const double *sy, const double *sz, int64_t b, int64_t e,
                                  double qx, double qy, double qz, double guess, double *cand_d2,
                                  int64_t *cand_pos, int64_t m)
{
    const __m256d vqx = _mm256_set1_pd(qx), vqy = _mm256_set1_pd(qy), vqz = _mm256_set1_pd(qz);
    const __m256d vg = _mm256_set1_pd(guess);
    const __m256i step = _mm256_set1_epi64x(4);
    __m256i pos = _mm256_add_epi64(_mm256_set1_epi64x(b), _mm256_set_epi64x(3, 2, 1, 0));
    int64_t p = b;
    for (; p + 4 <= e; p += 4) {
        __m256d dx = _mm256_sub_pd(_mm256_loadu_pd(sx + p), vqx);
        __m256d dy = _mm256_sub_pd(_mm256_loadu_pd(sy + p), vqy);
        __m256d dz = _mm256_sub_pd(_mm256_loadu_pd(sz + p), vqz);
        __m256d d2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                                   _mm256_mul_pd(dz, dz));
        int keep = _mm256_movemask_pd(_mm256_cmp_pd(d2, vg, _CMP_LE_OQ));
        __m256i perm = _mm256_loadu_si256((const __m256i *)eppf_nrm_pack4[keep]);
        _mm256_storeu_pd(cand_d2 + m, _mm256_castsi256_pd(
            _mm256_permutevar8x32_epi32(_mm256_castpd_si256(d2), perm)));
        _mm256_storeu_si256((__m256i *)(cand_pos + m), _mm256_permutevar8x32_epi32(pos, perm));
        m += _mm_popcnt_u32((unsigned)keep);
        pos = _mm256_add_epi64(pos, step);
    }
    for (; p < e; p++) {
        double dx = sx[p] - qx, dy = sy[p] - qy, dz = sz[p] - qz;
        double d2 = dx * dx + dy * dy + dz * dz;
        cand_d2[m] = d2;
        cand_pos[m] = p;
        m += d2 <= guess;
    }
    return m;
}

/* Candidates [0, m) with x = d2 * scale below ``t``, four at a time (as eppf_nrm_count_below). */
__attribute__((target("avx2,popcnt")))
static inline int64_t eppf_nrm_count_below_avx2(const double *cand_d2, int64_t m, double scale, double t)
{
    const __m256d vscale = _mm256_set1_pd(scale), vt = _mm256_set1_pd(t);
    __m256i acc = _mm256_setzero_si256(); /* minus the count per lane (a true compare is -1) */
    int64_t i = 0, count;
    for (; i + 4 <= m; i += 4) {
        __m256d x = _mm256_mul_pd(_mm256_loadu_pd(cand_d2 + i), vscale);
        acc = _mm256_add_epi64(acc, _mm256_castpd_si256(_mm256_cmp_pd(x, vt, _CMP_LT_OQ)));
    }
    {
        __m128i s = _mm_add_epi64(_mm256_castsi256_si128(acc), _mm256_extracti128_si256(acc, 1));
        count = -(_mm_cvtsi128_si64(s) + _mm_extract_epi64(s, 1));
    }
    for (; i < m; i++)
        count += cand_d2[i] * scale < t;
    return count;
}

/* eppf_nrm_select_avx512's selection four candidates at a time, the
 * survivors packed with eppf_nrm_pack4 (same buckets, same bisection, same
 * ranking: the same k-th and list). ``sel`` needs m + EPPF_NRM_SLACK entries,
 * ``kpos`` k + EPPF_NRM_SLACK. */
__attribute__((target("avx2,popcnt")))
static int64_t eppf_nrm_select_avx2(const double *cand_d2, const int64_t *cand_pos, int64_t m, int64_t k,
                                    double to_bucket, int64_t *sel, int64_t *kpos)
{
    const __m256d vscale = _mm256_set1_pd(to_bucket);
    const __m256i iota = _mm256_set_epi64x(3, 2, 1, 0), four = _mm256_set1_epi64x(4);
    int64_t lo = 0, hi = EPPF_NRM_BUCKETS - 1, bk, below = 0, need, n_in = 0, i, j, kth_i;
    double kth;
    EPPF_NRM_BISECT(eppf_nrm_count_below_avx2(cand_d2, m, to_bucket, (double)(mid + 1)));
    need = k - below;
    {
        const double flo = (double)bk, fhi = (double)(bk + 1);
        const __m256d vlo = _mm256_set1_pd(flo), vhi = _mm256_set1_pd(fhi);
        const int test_lo = bk > 0, test_hi = bk < EPPF_NRM_BUCKETS - 1;
        __m256i idx = iota;
        for (i = 0; i + 4 <= m; i += 4) {
            __m256d x = _mm256_mul_pd(_mm256_loadu_pd(cand_d2 + i), vscale);
            __m256d in = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
            int mask;
            if (test_lo) /* not below bk: NaN joins the top bucket, as in the scalar code */
                in = _mm256_cmp_pd(x, vlo, _CMP_NLT_UQ);
            if (test_hi)
                in = _mm256_and_pd(in, _mm256_cmp_pd(x, vhi, _CMP_LT_OQ));
            mask = _mm256_movemask_pd(in);
            _mm256_storeu_si256((__m256i *)(sel + n_in), _mm256_permutevar8x32_epi32(
                idx, _mm256_loadu_si256((const __m256i *)eppf_nrm_pack4[mask])));
            n_in += _mm_popcnt_u32((unsigned)mask);
            idx = _mm256_add_epi64(idx, four);
        }
        for (; i < m; i++) {
            double x = cand_d2[i] * to_bucket;
            sel[n_in] = i;
            n_in += (!test_lo || !(x < flo)) && (!test_hi || x < fhi);
        }
    }
    kth_i = eppf_nrm_rank_in_bucket(cand_d2, sel, n_in, need);
    kth = cand_d2[kth_i];
    /* everything up to the k-th in (d2, index) order, in position order */
    {
        const __m256d vk = _mm256_set1_pd(kth);
        const __m256i vki = _mm256_set1_epi64x(kth_i);
        __m256i idx = iota;
        j = 0;
        for (i = 0; i + 4 <= m; i += 4) {
            __m256d d2 = _mm256_loadu_pd(cand_d2 + i);
            __m256d after = _mm256_castsi256_pd(_mm256_cmpgt_epi64(idx, vki));
            __m256d keep = _mm256_or_pd(_mm256_cmp_pd(d2, vk, _CMP_LT_OQ),
                                        _mm256_andnot_pd(after, _mm256_cmp_pd(d2, vk, _CMP_EQ_OQ)));
            int mask = _mm256_movemask_pd(keep);
            _mm256_storeu_si256((__m256i *)(kpos + j), _mm256_permutevar8x32_epi32(
                _mm256_loadu_si256((const __m256i *)(cand_pos + i)),
                _mm256_loadu_si256((const __m256i *)eppf_nrm_pack4[mask])));
            j += _mm_popcnt_u32((unsigned)mask);
            idx = _mm256_add_epi64(idx, four);
        }
        for (; i < m; i++) {
            double d2 = cand_d2[i];
            kpos[j] = cand_pos[i];
            j += (d2 < kth) | ((d2 == kth) & (i <= kth_i));
        }
    }
    return kth_i;
}

#else

static unsigned eppf_nrm_eig8_avx512(const double *c, double *out)
{
    (void)c; (void)out;
    return 0; /* never called: eppf_nrm_has_avx512() is 0 */
}

static unsigned eppf_nrm_eig8_avx2(const double *c, double *out)
{
    (void)c; (void)out;
    return 0; /* never called: eppf_nrm_has_avx2() is 0 */
}

static void eppf_nrm_cov8_avx512(const double *nb, int64_t k, double *c)
{
    (void)nb; (void)k; (void)c; /* never called: eppf_nrm_has_avx512() is 0 */
}

static void eppf_nrm_cov8_avx2(const double *nb, int64_t k, double *c)
{
    (void)nb; (void)k; (void)c; /* never called: eppf_nrm_has_avx2() is 0 */
}

static int64_t eppf_nrm_scan_avx512(const double *sx, const double *sy, const double *sz, int64_t b, int64_t e,
                                    double qx, double qy, double qz, double guess, double *cand_d2,
                                    int64_t *cand_pos, int64_t m)
{
    (void)sx; (void)sy; (void)sz; (void)b; (void)e; (void)qx; (void)qy; (void)qz; (void)guess;
    (void)cand_d2; (void)cand_pos;
    return m; /* never called: eppf_nrm_has_avx512() is 0 */
}

static int64_t eppf_nrm_select_avx512(const double *cand_d2, const int64_t *cand_pos, int64_t m, int64_t k,
                                      double to_bucket, int64_t *sel, int64_t *kpos)
{
    (void)cand_d2; (void)cand_pos; (void)m; (void)k; (void)to_bucket; (void)sel; (void)kpos;
    return 0; /* never called: eppf_nrm_has_avx512() is 0 */
}

static int64_t eppf_nrm_scan_avx2(const double *sx, const double *sy, const double *sz, int64_t b, int64_t e,
                                  double qx, double qy, double qz, double guess, double *cand_d2,
                                  int64_t *cand_pos, int64_t m)
{
    (void)sx; (void)sy; (void)sz; (void)b; (void)e; (void)qx; (void)qy; (void)qz; (void)guess;
    (void)cand_d2; (void)cand_pos;
    return m; /* never called: eppf_nrm_has_avx2() is 0 */
}

static int64_t eppf_nrm_select_avx2(const double *cand_d2, const int64_t *cand_pos, int64_t m, int64_t k,
                                    double to_bucket, int64_t *sel, int64_t *kpos)
{
    (void)cand_d2; (void)cand_pos; (void)m; (void)k; (void)to_bucket; (void)sel; (void)kpos;
    return 0; /* never called: eppf_nrm_has_avx2() is 0 */
}

#endif
#endif
