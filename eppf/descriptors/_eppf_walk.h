/* SIMD kernels of a batch of pairs for _eppf_fast.pyx, chosen at run time:
 *
 * - AVX2, four pairs at a time: the f1-f3 bins (``eppf_f123_batch_avx2``)
 *   and the f4 line walks (``eppf_f4_batch_avx2``);
 * - AVX-512 (F, BW, VL, DQ and VBMI), eight pairs at a time: the pair draws
 *   (``eppf_draw_batch_avx512``), the f1-f3 bins with the check for
 *   coinciding points (``eppf_f123_batch_avx512``) and two f4 walks: the
 *   grouped walk (``eppf_f4_batch_avx512``, level 2) and the skipping walk
 *   (``eppf_f4_dist_avx512``, level 3), which keeps every lane busy by
 *   refilling it from a queue and walks each line along its dominant axis,
 *   jumping over voxels proved empty by the cone ahead of them
 *   (``eppf_code_grid``): 1.3 gathers a pair instead of 3.0. The default is level 3 on AMD, 2 elsewhere
 *   (``eppf_walk_prefers_skips``).
 *
 * Gathers are used only for the walk's look-ups: AMD Zen 4 runs an
 * eight-element gather at about 13 cycles (0.65 ns an element measured on a
 * Zen 4 KVM guest, against about 0.4 ns a scalar load), so the AVX-512 code
 * reads the points and normals of f1-f3 with row loads and a transpose, and
 * the setup and the groups of the walks with scalar loads and in-register
 * table look-ups.
 *
 * f1-f3: the same IEEE operations in the same order as _eppf_fast.pyx's
 * ``_bin_f123`` (no FMA: the targets are plain "avx2" / AVX-512 and the build
 * passes -ffp-contract=off), so the bins are bit-identical. The draws are
 * splitmix64's, state seed + k gamma for the k-th draw, so eight lanes draw
 * exactly the pairs of eight successive scalar draws.
 *
 * The walks serve grids of at most 64 voxels a side, where a voxel
 * position fits the packed fixed-point form of _eppf_fast.pyx's ``_line_bin``:
 * x, y, z in three 21-bit lanes of one int64, 14 fraction bits each, so one
 * addition advances all three axes by a step. A walk here visits exactly
 * the voxels ``_line_bin`` visits (or proves them empty), and stops only once
 * the f4 bin is certain, so the bins are identical; only the order in which
 * pairs are walked changes (the grouped walks group pairs by line length so
 * that the lanes of a group need similar numbers of steps).
 *
 * Stopping rule, per pair: with ``occ`` the occupied voxels counted so far
 * (both end voxels included) and ``rem`` the inner voxels not yet looked at,
 * the bin is certain once occ >= hi (top bin) or occ + rem < lo (bottom bin),
 * or when rem == 0. Every empty voxel lowers occ + rem by one, so the next
 * ``occ + rem - lo + 1`` steps can be walked without a test: a phase walks
 * that many steps (at most rem) in every lane, then the rule is applied again.
 * Walking on past the point where a bin became certain (but never past the
 * line's end) cannot change that bin, which the AVX-512 walk uses to test
 * only every fourth step.
 *
 * The SIMD code is compiled with target attributes and chosen at run time
 * (``eppf_walk_has_avx2`` / ``eppf_walk_has_avx512``); other compilers and
 * CPUs use the scalar code of _eppf_fast.pyx. No floating point is involved in
 * the walks beyond the setup, which uses the same expressions as _eppf_fast.pyx.
 */
#ifndef EPPF_WALK_H
#define EPPF_WALK_H

#include <stdint.h>
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
/* Pairs per batch (the walks sort a batch by line length: a longer batch
   groups the lanes better, up to about this size). */
#define EPPF_WALK_BATCH 256
/* A walk's counters in one int64 for the AVX-512 walk: rem (inner voxels) in
   bits 0-20, the f4 thresholds lo from bit 21 and hi from bit 42 (all below
   2**21); ``lohi[T]`` holds lo and hi of T voxels in place (_eppf_fast.pyx). */
#define EPPF_META_LO 21
#define EPPF_META_HI 42
#define EPPF_META_MASK 0x1FFFFF
/* The lane state of ``eppf_f4_dist_avx512`` between calls for one object: per
   set of eight lanes (six sets), seven vectors of eight int64 and the mask
   of lanes in use. */
#define EPPF_LANES_WORDS 384
/* splitmix64's increment: the generator's state after k draws is seed + k * gamma. */
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

/* Whether the skipping AVX-512 walk (``eppf_f4_dist_avx512``) is the better of
   the two AVX-512 walks here: on AMD Zen 4 an eight-element gather costs about
   13 cycles, and the skipping walk's 1.3 gathers a pair (against 3.0) pay for
   its extra vector work; where gathers are cheaper (Intel) the grouped walk's
   lighter steps are expected to win. Both give the same counts. */
static int eppf_walk_prefers_skips(void)
{
    return eppf_cpu_has(EPPF_CPU_AMD);
}

static int eppf_walk_has_avx2(void)
{
    return eppf_cpu_has(EPPF_CPU_AVX2);
}

/* The rows of ``eppf_f123_batch_avx512``'s ``pn``: point k's x, y, z,
 * nx, ny, nz (and two unused doubles) at pn[8 k], so that one 64-byte load
 * reads a point and its normal. */
static void eppf_pack_rows(int64_t n, const double *pts, int64_t ps, const double *nrm, int64_t ns, double *pn)
{
    int64_t k;
    for (k = 0; k < n; k++) {
        double *r = pn + 8 * k;
        r[0] = pts[ps * k];
        r[1] = pts[ps * k + 1];
        r[2] = pts[ps * k + 2];
        r[3] = nrm[ns * k];
        r[4] = nrm[ns * k + 1];
        r[5] = nrm[ns * k + 2];
        r[6] = 0.0;
        r[7] = 0.0;
    }
}

#if EPPF_WALK_SIMD
/* The points and normals at rows r[0..7] of ``eppf_pack_rows``'s ``pn`` as six
 * vectors v[0..5] (x, y, z, nx, ny, nz): eight loads and a transpose. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_load6x8(const double *pn, const int32_t *r, __m512d *v)
{
    __m512d a[8], t[8], u[8];
    int k;
    for (k = 0; k < 8; k++)
        a[k] = _mm512_loadu_pd(pn + 8 * (int64_t)r[k]);
    for (k = 0; k < 4; k++) {
        t[2 * k] = _mm512_unpacklo_pd(a[2 * k], a[2 * k + 1]);      /* x01 z01 ny01 - */
        t[2 * k + 1] = _mm512_unpackhi_pd(a[2 * k], a[2 * k + 1]);  /* y01 nx01 nz01 - */
    }
    for (k = 0; k < 2; k++) {
        u[4 * k] = _mm512_shuffle_f64x2(t[4 * k], t[4 * k + 2], 0x44);          /* x01 z01 x23 z23 */
        u[4 * k + 1] = _mm512_shuffle_f64x2(t[4 * k], t[4 * k + 2], 0xEE);      /* ny01 - ny23 - */
        u[4 * k + 2] = _mm512_shuffle_f64x2(t[4 * k + 1], t[4 * k + 3], 0x44);  /* y01 nx01 y23 nx23 */
        u[4 * k + 3] = _mm512_shuffle_f64x2(t[4 * k + 1], t[4 * k + 3], 0xEE);  /* nz01 - nz23 - */
    }
    v[0] = _mm512_shuffle_f64x2(u[0], u[4], 0x88);
    v[2] = _mm512_shuffle_f64x2(u[0], u[4], 0xDD);
    v[1] = _mm512_shuffle_f64x2(u[2], u[6], 0x88);
    v[3] = _mm512_shuffle_f64x2(u[2], u[6], 0xDD);
    v[4] = _mm512_shuffle_f64x2(u[1], u[5], 0x88);
    v[5] = _mm512_shuffle_f64x2(u[3], u[7], 0x88);
}
#endif

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
 * exactly as _core.pyx's ``_bin_f123``; cos2 / cos3 hold the n2 - 1 / n3 - 1
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

/* The pairs with inner voxels (L > 1) in walk order, longest line first, into
   ``order``; returns their number. */
static int eppf_f4_order(int m, const int32_t *Ls, int *order)
{
    int count[65], start[65];
    int t, k, n_walk;
    for (k = 0; k < 65; k++)
        count[k] = 0;
    for (t = 0; t < m; t++)
        count[Ls[t]]++;
    {
        int s = 0;
        for (k = 64; k >= 2; k--) {
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

/* ``eppf_f123_batch_avx2`` eight pairs at a time (the same IEEE operations in
 * the same order, so the same bins), which also checks the pairs as
 * ``_draw_pair`` does: returns the first t whose two points coincide (all
 * three coordinates equal), or m when none does. B[t] is written for every t.
 * Where ``pn`` is not NULL, the points and normals are read from its rows
 * (``eppf_pack_rows``: the same values, one load a point). */
__attribute__((target(EPPF_AVX512_TARGET)))
static int eppf_f123_batch_avx512(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                                  const double *nrm, int64_t ns, double scale, int n1, int n2, int n3, int n4,
                                  double f1_density, const double *cos2, const double *cos3, int32_t *B,
                                  const double *pn)
{
    const __m512d vscale = _mm512_set1_pd(scale), vdens = _mm512_set1_pd(f1_density);
    const __m512d top1 = _mm512_set1_pd((double)(n1 - 1)), one = _mm512_set1_pd(1.0);
    const __m256i one32 = _mm256_set1_epi32(1);
    int32_t ri[8], rj[8];
    int t, k, l, bad = m;
    for (t = 0; t < m; t += 8) {
        const __mmask8 keep = m - t >= 8 ? (__mmask8)0xff : (__mmask8)((1u << (m - t)) - 1);
        const int32_t *vi = ii + t, *vj = jj + t;
        __m512d pix, piy, piz, pjx, pjy, pjz, dx, dy, dz, dist, v;
        __m256i b1, b2 = _mm256_setzero_si256(), b3 = _mm256_setzero_si256(), b;
        __mmask8 same;
        if (keep != 0xff) {  /* a partial last group repeats its last pair */
            for (l = 0; l < 8; l++) {
                ri[l] = ii[t + (l < m - t ? l : m - t - 1)];
                rj[l] = jj[t + (l < m - t ? l : m - t - 1)];
            }
            vi = ri;
            vj = rj;
        }
        __m512d vi6[6], vj6[6];
        if (pn) {
            eppf_load6x8(pn, vi, vi6);
            eppf_load6x8(pn, vj, vj6);
            pix = vi6[0], piy = vi6[1], piz = vi6[2], pjx = vj6[0], pjy = vj6[1], pjz = vj6[2];
        } else {
            eppf_load3x8(pts, ps, vi, &pix, &piy, &piz);
            eppf_load3x8(pts, ps, vj, &pjx, &pjy, &pjz);
        }
        same = keep & _mm512_cmp_pd_mask(pix, pjx, _CMP_EQ_OQ) & _mm512_cmp_pd_mask(piy, pjy, _CMP_EQ_OQ)
               & _mm512_cmp_pd_mask(piz, pjz, _CMP_EQ_OQ);
        if (same && bad == m)
            bad = t + __builtin_ctz(same);
        dx = _mm512_sub_pd(pjx, pix);
        dy = _mm512_sub_pd(pjy, piy);
        dz = _mm512_sub_pd(pjz, piz);
        dist = _mm512_sqrt_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy)),
                                            _mm512_mul_pd(dz, dz)));
        v = _mm512_mul_pd(_mm512_mul_pd(dist, vscale), vdens);
        b1 = _mm512_cvttpd_epi32(_mm512_max_pd(_mm512_min_pd(v, top1), _mm512_setzero_pd()));
        if (n2 > 1 || n3 > 1) {
            __m512d nix, niy, niz, njx, njy, njz;
            if (pn) {
                nix = vi6[3], niy = vi6[4], niz = vi6[5], njx = vj6[3], njy = vj6[4], njz = vj6[5];
            } else {
                eppf_load3x8(nrm, ns, vi, &nix, &niy, &niz);
                eppf_load3x8(nrm, ns, vj, &njx, &njy, &njz);
            }
            if (n2 > 1) {
                __m512d inv = _mm512_div_pd(one, dist), m1, m2;
                m1 = _mm512_mul_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(nix, dx), _mm512_mul_pd(niy, dy)),
                                                 _mm512_mul_pd(niz, dz)), inv);
                m2 = _mm512_mul_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(njx, dx), _mm512_mul_pd(njy, dy)),
                                                 _mm512_mul_pd(njz, dz)), inv);
                m1 = _mm512_min_pd(m2, m1);  /* m2 < m1 ? m2 : m1 */
                for (k = 0; k < n2 - 1; k++)
                    b2 = _mm256_mask_add_epi32(b2, _mm512_cmp_pd_mask(m1, _mm512_set1_pd(cos2[k]), _CMP_LE_OQ),
                                               b2, one32);
            }
            if (n3 > 1) {
                v = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(nix, njx), _mm512_mul_pd(niy, njy)),
                                  _mm512_mul_pd(niz, njz));
                v = _mm512_abs_pd(v);
                for (k = 0; k < n3 - 1; k++)
                    b3 = _mm256_mask_add_epi32(b3, _mm512_cmp_pd_mask(v, _mm512_set1_pd(cos3[k]), _CMP_LE_OQ),
                                               b3, one32);
            }
        }
        b = _mm256_add_epi32(_mm256_mullo_epi32(b1, _mm256_set1_epi32(n2)), b2);
        b = _mm256_add_epi32(_mm256_mullo_epi32(b, _mm256_set1_epi32(n3)), b3);
        b = _mm256_mullo_epi32(b, _mm256_set1_epi32(n4));
        _mm256_mask_storeu_epi32(B + t, keep, b);
    }
    return bad;
}

/* The walk setup of the eight pairs (i8[l], j8[l]), from ``pv``: each
 * point's voxel already in the packed walk's start form (lanes v S + S/2 + g,
 * see _eppf_fast.pyx's ``_fill_grid``). The packed difference of two such
 * words holds the three lane differences d S exactly (each below 2**20 in
 * size), recovered by sign-extending 21-bit fields. The same integer results
 * as ``eppf_f4_setup_avx2``: the increments' scale 2**14 / L is the same
 * correctly rounded division (the value of ``recip_packed[L]``), and
 * lo | hi of T = L + 1 voxels is ``lohi[T]``, looked up in registers:
 * ``tab`` holds lohi[1..63] at 1..63 and lohi[64] at 0 (T >= 3 on every
 * walked line). No gathers: on CPUs with slow ones (AMD Zen 4) eight loads
 * and in-register look-ups cost a fraction of them. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_setup8_avx512(const int32_t *i8, const int32_t *j8, const int64_t *pv, const __m512i *tab,
                                      __m512i *P, __m512i *INC, __m512i *Lout, __m512i *LOHI, __m512i *D)
{
    const __m512i one = _mm512_set1_epi64(1);
    const __m512i a = _mm512_set_epi64(pv[i8[7]], pv[i8[6]], pv[i8[5]], pv[i8[4]], pv[i8[3]], pv[i8[2]], pv[i8[1]],
                                       pv[i8[0]]);
    const __m512i b = _mm512_set_epi64(pv[j8[7]], pv[j8[6]], pv[j8[5]], pv[j8[4]], pv[j8[3]], pv[j8[2]], pv[j8[1]],
                                       pv[j8[0]]);
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

/* ``tab`` of ``eppf_setup8_avx512`` from lohi[0..64]. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline void eppf_lohi_tab_avx512(const int64_t *lohi, __m512i *tab)
{
    int k;
    for (k = 0; k < 8; k++)
        tab[k] = _mm512_loadu_si512(lohi + 8 * k);
    tab[0] = _mm512_mask_mov_epi64(tab[0], 1, _mm512_set1_epi64(lohi[64]));
}

/* ``eppf_f4_setup_avx2`` eight pairs at a time (``eppf_setup8_avx512``). */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_f4_setup_avx512(int m, const int32_t *ii, const int32_t *jj, const int64_t *pv,
                                 const int64_t *lohi, const double *recip_packed, int64_t *P, int64_t *INC,
                                 int32_t *Ls, int64_t *META)
{
    __m512i tab[8];
    int32_t ri[8], rj[8];
    int t, l;
    (void)recip_packed;
    eppf_lohi_tab_avx512(lohi, tab);
    for (t = 0; t < m; t += 8) {
        const __mmask8 keep = m - t >= 8 ? (__mmask8)0xff : (__mmask8)((1u << (m - t)) - 1);
        const int32_t *i8 = ii + t, *j8 = jj + t;
        __m512i p, inc, L, lh;
        if (keep != 0xff) {  /* a partial last group repeats its last pair */
            for (l = 0; l < 8; l++) {
                ri[l] = ii[t + (l < m - t ? l : m - t - 1)];
                rj[l] = jj[t + (l < m - t ? l : m - t - 1)];
            }
            i8 = ri;
            j8 = rj;
        }
        eppf_setup8_avx512(i8, j8, pv, tab, &p, &inc, &L, &lh, NULL);
        _mm512_mask_storeu_epi64(P + t, keep, p);
        _mm512_mask_storeu_epi64(INC + t, keep, inc);
        _mm256_mask_storeu_epi32(Ls + t, keep, _mm512_cvtepi64_epi32(L));
        /* rem = L - 1 (a wrapped field for lines of L <= 1, which are never walked) | lo | hi */
        _mm512_mask_storeu_epi64(META + t, keep, _mm512_add_epi64(
            lh, _mm512_and_si512(_mm512_sub_epi64(L, _mm512_set1_epi64(1)), _mm512_set1_epi64(EPPF_META_MASK))));
    }
}

/* The AVX-512 walk: eight lanes, the same stopping rule and bins as
 * ``eppf_f4_batch_avx2`` (same arguments). One step of a lane is a few
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

/* The cone grids behind the AVX-512 walk's skips. A line walked along its
 * dominant axis a, in the direction in which that coordinate grows, moves it
 * by exactly one voxel a step and every other coordinate by at most one, so
 * its j-th voxel after v lies in the cone of v: the 3^2 box of half side j in
 * the plane j voxels further along a. ``code`` holds three grids, one per
 * axis (x, y, z), at word 128 g a (EPPF_CODE_WORDS in all; rows of 2 words,
 * the first 2 g^2 of each grid written): for every voxel v, c = min(C, 3),
 * C the number of cone planes from v on (v's own first) with no occupied
 * voxel, i.e. C = 0 where v is occupied, else 1 + the smallest C of the 3^2
 * voxels of the next plane (planes past the grid's face count as empty).
 * c is bits 2 (z & 31) and 2 (z & 31) + 1 of word 128 g a + 2 row + (z >> 5).
 * The sets O_m of voxels with C < m: O_1 the occupied ones, O_{m+1} = O_1
 * or the voxels whose next plane's 3^2 box meets O_m (``eppf_cone_step``).
 * ``bits``: g^2 words, one per (x, y) row, z bits (none past z = g - 1);
 * ``work``: 4 g^2 words of scratch; 2 <= g <= 64. */
#define EPPF_CODE_WORDS (3 * 128 * 64)
/* ``out[x g + y]`` = ``in`` of rows y - 1, y and y + 1 of the same x (those
   inside the grid) or-ed: the y +- 1 part of a 3^2 box; 2 <= g <= 64. */
EPPF_AVX512_FN
static void eppf_rows_pm1(const uint64_t *in, uint64_t *out, int64_t g)
{
    int64_t x, y;
    for (x = 0; x < g; x++) {
        const uint64_t *t = in + x * g;
        uint64_t *u = out + x * g;
        u[0] = t[0] | t[1];
        for (y = 1; y < g - 1; y++)
            u[y] = t[y - 1] | t[y] | t[y + 1];
        u[g - 1] = t[g - 2] | t[g - 1];
    }
}

/* ``out`` = ``bits`` or the voxels whose next plane along ``axis`` meets
   ``o`` in its 3^2 box; a and b: g^2 words of scratch each. */
EPPF_AVX512_FN
static void eppf_cone_step(const uint64_t *bits, const uint64_t *o, uint64_t *out, uint64_t *a, uint64_t *b,
                           int64_t g, int axis)
{
    const uint64_t gm = g == 64 ? ~(uint64_t)0 : (((uint64_t)1 << g) - 1);
    int64_t x, y, r;
    if (axis == 2) {
        /* the 3^2 box in (x, y), then the next z (bit z + 1) */
        eppf_rows_pm1(o, b, g);
        for (y = 0; y < g; y++)
            out[y] = bits[y] | ((b[y] | b[g + y]) >> 1);
        for (x = 1; x < g - 1; x++)
            for (y = 0; y < g; y++)
                out[x * g + y] = bits[x * g + y] | ((b[(x - 1) * g + y] | b[x * g + y] | b[(x + 1) * g + y]) >> 1);
        for (y = 0; y < g; y++)
            out[(g - 1) * g + y] = bits[(g - 1) * g + y] | ((b[(g - 2) * g + y] | b[(g - 1) * g + y]) >> 1);
        return;
    }
    /* z +- 1 within the grid */
    for (r = 0; r < g * g; r++)
        a[r] = (o[r] | (o[r] << 1) | (o[r] >> 1)) & gm;
    if (axis == 0) {
        /* y +- 1, then the next x */
        eppf_rows_pm1(a, b, g);
        for (r = 0; r < (g - 1) * g; r++)
            out[r] = bits[r] | b[r + g];
        for (; r < g * g; r++)
            out[r] = bits[r];
    } else {
        /* x +- 1, then the next y */
        for (y = 0; y < g; y++)
            b[y] = a[y] | a[g + y];
        for (x = 1; x < g - 1; x++)
            for (y = 0; y < g; y++)
                b[x * g + y] = a[(x - 1) * g + y] | a[x * g + y] | a[(x + 1) * g + y];
        for (y = 0; y < g; y++)
            b[(g - 1) * g + y] = a[(g - 2) * g + y] | a[(g - 1) * g + y];
        for (x = 0; x < g; x++) {
            for (y = 0; y < g - 1; y++)
                out[x * g + y] = bits[x * g + y] | b[x * g + y + 1];
            out[x * g + g - 1] = bits[x * g + g - 1];
        }
    }
}

/* The low 32 bits of x spread to the even bits of the result. */
EPPF_AVX512_FN
static inline uint64_t eppf_spread32(uint64_t x)
{
    x &= 0xFFFFFFFFULL;
    x = (x | (x << 16)) & 0x0000FFFF0000FFFFULL;
    x = (x | (x << 8)) & 0x00FF00FF00FF00FFULL;
    x = (x | (x << 4)) & 0x0F0F0F0F0F0F0F0FULL;
    x = (x | (x << 2)) & 0x3333333333333333ULL;
    x = (x | (x << 1)) & 0x5555555555555555ULL;
    return x;
}

#if EPPF_WALK_SIMD
/* ``eppf_code_grid`` for g = 64, in registers: a slab (the 64 rows of one x)
   is eight vectors; y +- 1 by lane rotations across them, z +- 1 by shifts. */
#define EPPF_SLAB_LOAD(v, src)                                                                   \
    do {                                                                                         \
        int k_;                                                                                  \
        for (k_ = 0; k_ < 8; k_++)                                                               \
            (v)[k_] = _mm512_loadu_si512((src) + 8 * k_);                                        \
    } while (0)
__attribute__((target(EPPF_AVX512_TARGET)))
static inline __m512i eppf_ynext(const __m512i *v, int k)
{
    return _mm512_alignr_epi64(k < 7 ? v[k + 1] : _mm512_setzero_si512(), v[k], 1);
}
__attribute__((target(EPPF_AVX512_TARGET)))
static inline __m512i eppf_yprev(const __m512i *v, int k)
{
    return _mm512_alignr_epi64(v[k], k > 0 ? v[k - 1] : _mm512_setzero_si512(), 7);
}
__attribute__((target(EPPF_AVX512_TARGET)))
static inline __m512i eppf_zdil(__m512i w)
{
    return _mm512_ternarylogic_epi64(w, _mm512_slli_epi64(w, 1), _mm512_srli_epi64(w, 1), 0xFE);
}
/* out = bits | D_axis(o) for g = 64 (``eppf_cone_step``); a: 4096 words of scratch */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_cone_step64(const uint64_t *bits, const uint64_t *o, uint64_t *out, uint64_t *a, int axis)
{
    __m512i v[8];
    int x, k;
    if (axis == 0) {
        /* a slab's y +- 1 and z +- 1 box, then the slab before it */
        for (x = 0; x < 64; x++) {
            if (x < 63) {
                EPPF_SLAB_LOAD(v, o + (x + 1) * 64);
                for (k = 0; k < 8; k++)
                    v[k] = eppf_zdil(v[k]);
                for (k = 0; k < 8; k++) {
                    const __m512i r = _mm512_ternarylogic_epi64(v[k], eppf_yprev(v, k), eppf_ynext(v, k), 0xFE);
                    _mm512_storeu_si512(out + x * 64 + 8 * k, _mm512_or_si512(r, _mm512_loadu_si512(bits + x * 64 + 8 * k)));
                }
            } else {
                for (k = 0; k < 8; k++)
                    _mm512_storeu_si512(out + x * 64 + 8 * k, _mm512_loadu_si512(bits + x * 64 + 8 * k));
            }
        }
        return;
    }
    /* a = the slab's own box: z +- 1 (axis 1) or y +- 1 (axis 2) */
    for (x = 0; x < 64; x++) {
        EPPF_SLAB_LOAD(v, o + x * 64);
        for (k = 0; k < 8; k++)
            _mm512_storeu_si512(a + x * 64 + 8 * k, axis == 1 ? eppf_zdil(v[k])
                                : _mm512_ternarylogic_epi64(v[k], eppf_yprev(v, k), eppf_ynext(v, k), 0xFE));
    }
    /* x +- 1, then the next y (axis 1) or the next z (axis 2) */
    for (x = 0; x < 64; x++) {
        for (k = 0; k < 8; k++) {
            __m512i r = _mm512_loadu_si512(a + x * 64 + 8 * k);
            if (x > 0)
                r = _mm512_or_si512(r, _mm512_loadu_si512(a + (x - 1) * 64 + 8 * k));
            if (x < 63)
                r = _mm512_or_si512(r, _mm512_loadu_si512(a + (x + 1) * 64 + 8 * k));
            v[k] = r;
        }
        for (k = 0; k < 8; k++) {
            const __m512i r = axis == 1 ? eppf_ynext(v, k) : _mm512_srli_epi64(v[k], 1);
            _mm512_storeu_si512(out + x * 64 + 8 * k, _mm512_or_si512(r, _mm512_loadu_si512(bits + x * 64 + 8 * k)));
        }
    }
}
/* The code words of eight rows from their bit planes b0 (code bit 0) and
   b1 (code bit 1), z bits each: word 2 r + h holds z = 32 h + i at bits
   2 i (b0) and 2 i + 1 (b1). Bytes pairing a nibble of b0 with the same
   nibble of b1 (lo: the low nibbles of each byte, hi: the high ones), put in
   order by a byte permutation, and spread by one GF(2) affine map (bit i to
   2 i, bit 4 + i to 2 i + 1). */
__attribute__((target(EPPF_AVX512_TARGET ",gfni")))
static inline void eppf_code_rows8(__m512i b0, __m512i b1, uint64_t *out)
{
    const __m512i m4 = _mm512_set1_epi8(0x0F);
    const __m512i spread = _mm512_set1_epi64(0x0110022004400880LL);
    /* nibble bytes: lo = low nibbles (b0 | b1 << 4), hi = high nibbles (b0 >> 4 | b1 & 0xF0) */
    const __m512i lo = _mm512_ternarylogic_epi64(m4, b0, _mm512_slli_epi64(b1, 4), 0xCA);
    const __m512i hi = _mm512_ternarylogic_epi64(m4, _mm512_srli_epi64(b0, 4), b1, 0xCA);
    /* output byte 16 R + 2 k + e (row R, source byte k) from lo (e = 0) or hi (e = 1) byte 8 R + k */
    const __m512i i03 = _mm512_set_epi8(
        95, 31, 94, 30, 93, 29, 92, 28, 91, 27, 90, 26, 89, 25, 88, 24,
        87, 23, 86, 22, 85, 21, 84, 20, 83, 19, 82, 18, 81, 17, 80, 16,
        79, 15, 78, 14, 77, 13, 76, 12, 75, 11, 74, 10, 73, 9, 72, 8,
        71, 7, 70, 6, 69, 5, 68, 4, 67, 3, 66, 2, 65, 1, 64, 0);
    const __m512i i47 = _mm512_add_epi8(i03, _mm512_set1_epi8(32));
    _mm512_storeu_si512(out, _mm512_gf2p8affine_epi64_epi8(_mm512_permutex2var_epi8(lo, i03, hi), spread, 0));
    _mm512_storeu_si512(out + 8, _mm512_gf2p8affine_epi64_epi8(_mm512_permutex2var_epi8(lo, i47, hi), spread, 0));
}
__attribute__((target(EPPF_AVX512_TARGET ",gfni")))
static void eppf_code_grid64(const uint64_t *bits, uint64_t *work, uint64_t *code)
{
    uint64_t *o2 = work, *o3 = work + 4096, *a = work + 2 * 4096;
    int axis, r;
    for (axis = 0; axis < 3; axis++) {
        uint64_t *c = code + 128 * 64 * axis;
        eppf_cone_step64(bits, bits, o2, a, axis);
        eppf_cone_step64(bits, o2, o3, a, axis);
        for (r = 0; r < 4096; r += 8) {
            const __m512i b = _mm512_loadu_si512(bits + r), u2 = _mm512_loadu_si512(o2 + r);
            const __m512i u3 = _mm512_loadu_si512(o3 + r);
            const __m512i b0 = _mm512_ternarylogic_epi64(u2, b, u3, 0x75);  /* (u2 & ~b) | ~u3: c = 1 or 3 */
            const __m512i b1 = _mm512_ternarylogic_epi64(u2, u2, u2, 0x55); /* ~u2: c = 2 or 3 */
            eppf_code_rows8(b0, b1, c + 2 * r);
        }
    }
}
#undef EPPF_SLAB_LOAD
#endif

EPPF_AVX512_FN
static void eppf_code_grid(const uint64_t *bits, int64_t g, uint64_t *work, uint64_t *code)
{
    uint64_t *o2 = work, *o3 = work + g * g, *a = work + 2 * g * g, *b = work + 3 * g * g;
    int64_t r;
    int axis;
#if EPPF_WALK_SIMD
    if (g == 64 && eppf_cpu_has(EPPF_CPU_GFNI)) {  /* the same words, in registers */
        eppf_code_grid64(bits, work, code);
        return;
    }
#endif
    for (axis = 0; axis < 3; axis++) {
        uint64_t *c = code + 128 * g * axis;
        eppf_cone_step(bits, bits, o2, a, b, g, axis);
        eppf_cone_step(bits, o2, o3, a, b, g, axis);
        for (r = 0; r < g * g; r++) {
            const uint64_t b0 = (o2[r] & ~bits[r]) | ~o3[r];  /* c = 1 or 3 */
            const uint64_t b1 = ~o2[r];                       /* c = 2 or 3 */
            c[2 * r] = eppf_spread32(b0) | (eppf_spread32(b1) << 1);
            c[2 * r + 1] = eppf_spread32(b0 >> 32) | (eppf_spread32(b1 >> 32) << 1);
        }
    }
}
#if EPPF_WALK_SIMD
/* The f4 walks of a batch and their counts, AVX-512: three sets of eight
 * lanes, each lane refilled from a queue as soon as its line's bin is
 * certain, each step skipping the voxels the cone grids prove empty.
 *
 * The pairs (ii[t], jj[t]), t < m <= EPPF_WALK_BATCH, with f1-f3 bins B[t]
 * (already times n4): lines without inner voxels (L <= 1) are counted at
 * once; the others join a queue of (first inner voxel, increment,
 * rem | lo | hi, key) in batch order (setup of ``eppf_setup8_avx512``).
 * A line is walked along a dominant axis a (|delta_a| = L: its increment's
 * field is exactly +-2**14, so that coordinate moves by one voxel every
 * step), in the direction in which that coordinate grows: a line whose
 * delta_a is negative starts at its last inner voxel (first + (L - 2) INC)
 * and steps by -INC, which visits the same integer positions in reverse. a
 * sits in bits 62-63 of the position (above the x field, which never
 * reaches them), where the word index picks the cone grid of axis a.
 *
 * A step of a lane reads c = min(C, 3) at its voxel in the grid of its
 * axis (``eppf_code_grid``). c = 0: the voxel is occupied (occ + 1), one
 * step. c > 0: the voxel and the next c - 1 of the line are empty, since
 * the k-th voxel after this one lies in its cone k planes on (one plane a
 * step, the other coordinates at most one voxel a step): the lane advances
 * c steps at once (P += c INC, the same integer position as that many
 * single steps), occ unchanged.
 * Every voxel is thus still counted or proved empty in line order, and occ
 * and rem mean what they mean in the scalar walk. After two steps the
 * stopping rule of ``eppf_f4_batch_avx2`` applies, with one more case for
 * n4 = 3: the middle bin is certain once lo <= occ and occ + rem < hi.
 * Walking past the point where the bin became certain (never past the
 * line's end) cannot change it. A lane whose bin is certain or whose line has
 * ended adds one to counts[B + f4 bin] and takes the next queued line.
 *
 * Lines still being walked when the queue runs dry stay in ``lanes``
 * (EPPF_LANES_WORDS int64, all zero before an object's first call) for the
 * next call; ``drain`` walks them to their end (the object's last call,
 * m = 0). A histogram is a sum, so the order in which lines finish does not
 * change it: the counts are the scalar kernel's.
 */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_f4_dist_avx512(int m, const int32_t *ii, const int32_t *jj, const int32_t *B,
                                const int64_t *pv, const uint64_t *code, int64_t g, const int32_t *thr, int n4,
                                const int64_t *lohi, int64_t *lanes, int drain, int32_t *counts)
{
    int64_t QP[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    int64_t QI[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    int64_t QM[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    int64_t QK[EPPF_WALK_BATCH + 8] __attribute__((aligned(64)));
    /* finished lines: counts index (n4 <= 3), or key and occ (n4 > 3); at most 48 + m of them */
    int64_t OK[EPPF_WALK_BATCH + 64] __attribute__((aligned(64)));
    int64_t OO[EPPF_WALK_BATCH + 64] __attribute__((aligned(64)));
    const __m512i zero = _mm512_setzero_si512(), one = _mm512_set1_epi64(1), two = _mm512_set1_epi64(2);
    const __m512i fmask = _mm512_set1_epi64(EPPF_META_MASK), three = _mm512_set1_epi64(3);
    /* multishift fields: byte 0 <- bits 13.. (2 z and a fraction bit), byte 1 <- bit 19 (z >> 5),
       byte 2 <- bits 35.. (y), byte 3 <- bits 56.. (x and the axis a above it); kept: 2 (z & 31), 1, 6
       and 8 bits (x + 64 a) */
    const __m512i ctrl = _mm512_set1_epi64(((int64_t)EPPF_PK_XSHIFT << 24) | ((int64_t)EPPF_PK_YSHIFT << 16)
                                           | ((int64_t)(EPPF_PK_ZSHIFT + 5) << 8) | (EPPF_PK_ZSHIFT - 1));
    const __m512i mfield = _mm512_set1_epi64(0xFF3F013E);
    /* bytes (0, 1, 1, g): words z >> 5 and y + g (x + 64 a) (at most 16383); then (1, 2): the word
       index 2 (y + g x) + (z >> 5) + 128 g a, in the cone grid of axis a */
    const __m512i mul = _mm512_set1_epi64(((int64_t)g << 24) | (1 << 16) | (1 << 8));
    const __m512i w21 = _mm512_set1_epi64(0x00020001);
    /* steps a look-up advances by its code c (index bits 0-1; bit 2 is the next voxel's): max(c, 1) */
    const __m512i tsteps = _mm512_set_epi64(3, 2, 1, 1, 3, 2, 1, 1);
    const long long *cbase = (const long long *)code;
    const int wide = n4 > 3;
    __m512i pA, incA, remA, occA, pB, incB, remB, occB, pC, incC, remC, occC;
    __m512i pD, incD, remD, occD, pE, incE, remE, occE, pF, incF, remF, occF;
    __mmask8 actA, actB, actC, actD, actE, actF;
    __m512i tab[8];
    int32_t ri[8], rj[8];
    __m512i dd[3];
    int t, nq = 0, q = 0, nout = 0, i;

    /* The queue. */
    eppf_lohi_tab_avx512(lohi, tab);
    for (t = 0; t < m; t += 8) {
        const __mmask8 keep = m - t >= 8 ? (__mmask8)0xff : (__mmask8)((1u << (m - t)) - 1);
        const int32_t *i8 = ii + t, *j8 = jj + t;
        __m512i a, vinc, L, lh, vkey, meta;
        __mmask8 walk, few;
        if (keep != 0xff) {  /* a partial last group repeats its last pair */
            int l;
            for (l = 0; l < 8; l++) {
                ri[l] = ii[t + (l < m - t ? l : m - t - 1)];
                rj[l] = jj[t + (l < m - t ? l : m - t - 1)];
            }
            i8 = ri;
            j8 = rj;
        }
        eppf_setup8_avx512(i8, j8, pv, tab, &a, &vinc, &L, &lh, dd);
        {
            /* along the dominant axis (any of them on a tie: its coordinate moves by exactly one voxel a step,
               the increment's field being +-2**14), in the direction in which it grows: lines whose axis
               difference is negative are walked from their last inner voxel back (the same positions) */
            const __mmask8 onx = _mm512_cmpeq_epi64_mask(_mm512_abs_epi64(dd[0]), L);
            const __mmask8 ony = (__mmask8)~onx & _mm512_cmpeq_epi64_mask(_mm512_abs_epi64(dd[1]), L);
            const __mmask8 onz = (__mmask8)~(onx | ony);
            const __m512i dax = _mm512_mask_blend_epi64(onz, _mm512_mask_blend_epi64(ony, dd[0], dd[1]), dd[2]);
            const __mmask8 back = _mm512_cmplt_epi64_mask(dax, zero);
            const __m512i axis = _mm512_mask_blend_epi64(onz, _mm512_maskz_mov_epi64(ony, one), two);
            a = _mm512_mask_add_epi64(a, back, a, _mm512_mullo_epi64(_mm512_sub_epi64(L, two), vinc));
            vinc = _mm512_mask_sub_epi64(vinc, back, zero, vinc);
            a = _mm512_add_epi64(a, _mm512_slli_epi64(axis, 62));
        }
        walk = keep & _mm512_cmpgt_epi64_mask(L, one);
        few = keep & (__mmask8)~walk;
        vkey = _mm512_cvtepi32_epi64(_mm256_maskz_loadu_epi32(keep, B + t));
        if (wide)
            vkey = _mm512_add_epi64(vkey, _mm512_slli_epi64(L, 32));
        meta = _mm512_add_epi64(lh, _mm512_sub_epi64(L, one));  /* rem = L - 1 | lo | hi */
        _mm512_storeu_si512(QP + nq, _mm512_maskz_compress_epi64(walk, a));
        _mm512_storeu_si512(QI + nq, _mm512_maskz_compress_epi64(walk, vinc));
        _mm512_storeu_si512(QM + nq, _mm512_maskz_compress_epi64(walk, meta));
        _mm512_storeu_si512(QK + nq, _mm512_maskz_compress_epi64(walk, vkey));
        nq += __builtin_popcount(walk);
        if (few) {
            /* no inner voxel: occ = T = L + 1, every voxel occupied */
            int64_t Lf[8] __attribute__((aligned(64)));
            int l;
            _mm512_store_si512(Lf, L);
            for (l = 0; l < 8; l++) {
                if ((few >> l) & 1) {
                    const int32_t *th = thr + (Lf[l] + 1) * n4;
                    int bb = 0, j;
                    for (j = 1; j < n4; j++)
                        bb += (Lf[l] + 1) >= th[j];
                    counts[B[t + l] + bb]++;
                }
            }
        }
    }

/* Set S's lanes: position, increment, rem and occ in registers, lo, hi and
   key in ``lanes`` (read only when a lane may finish). */
#define EPPF_LOADL(S, o)                                                                          \
    do {                                                                                          \
        p##S = _mm512_loadu_si512(lanes + (o));                                                   \
        inc##S = _mm512_loadu_si512(lanes + (o) + 8);                                             \
        rem##S = _mm512_loadu_si512(lanes + (o) + 16);                                            \
        occ##S = _mm512_loadu_si512(lanes + (o) + 40);                                            \
        act##S = (__mmask8)lanes[(o) + 56];                                                       \
    } while (0)
#define EPPF_SAVEL(S, o)                                                                          \
    do {                                                                                          \
        _mm512_storeu_si512(lanes + (o), p##S);                                                   \
        _mm512_storeu_si512(lanes + (o) + 8, inc##S);                                             \
        _mm512_storeu_si512(lanes + (o) + 16, rem##S);                                            \
        _mm512_storeu_si512(lanes + (o) + 40, occ##S);                                            \
        lanes[(o) + 56] = act##S;                                                                 \
    } while (0)
/* The free lanes of set S take the next lines of the queue, in lane order. */
#define EPPF_REFILL(S, o)                                                                         \
    do {                                                                                          \
        __mmask8 fill_ = (__mmask8)~act##S;                                                       \
        if (nq - q < 8) {                                                                         \
            while (__builtin_popcount(fill_) > nq - q)                                            \
                fill_ &= (__mmask8)~(1u << (31 - __builtin_clz(fill_)));                          \
        }                                                                                         \
        {   /* (no branch: a free lane is as likely as not) */                                    \
            const __m512i mt_ = _mm512_maskz_expand_epi64(fill_, _mm512_loadu_si512(QM + q));     \
            p##S = _mm512_mask_expand_epi64(p##S, fill_, _mm512_loadu_si512(QP + q));             \
            inc##S = _mm512_mask_expand_epi64(inc##S, fill_, _mm512_loadu_si512(QI + q));         \
            rem##S = _mm512_mask_and_epi64(rem##S, fill_, mt_, fmask);                            \
            occ##S = _mm512_mask_mov_epi64(occ##S, fill_, two);                                   \
            _mm512_mask_storeu_epi64(lanes + (o) + 48, fill_,                                     \
                                     _mm512_maskz_expand_epi64(fill_, _mm512_loadu_si512(QK + q))); \
            _mm512_mask_storeu_epi64(lanes + (o) + 24, fill_,                                     \
                                     _mm512_and_si512(_mm512_srli_epi64(mt_, EPPF_META_LO), fmask)); \
            _mm512_mask_storeu_epi64(lanes + (o) + 32, fill_, _mm512_srli_epi64(mt_, EPPF_META_HI)); \
            act##S |= fill_;                                                                      \
            q += __builtin_popcount(fill_);                                                       \
        }                                                                                         \
    } while (0)
/* One step of set S: the lanes with voxels left (rem > 0) look up c and
   count an occupied voxel; every lane advances max(c, 1) voxels (a lane
   whose line ends within them has rem <= 0 after it and counts no more). A
   lane is looked up only while rem > 0 (masked gather), i.e. at a voxel of
   its line, whose word index is below 384 g <= EPPF_CODE_WORDS; lanes past
   their line (rem <= 0) drift to any position, never read. The fields of
   the word index come from one multishift, and so does the code: byte 0
   of t_ is the code's bit offset, so multishift(t_, word) puts c in bits
   0-1 (the next voxel's code above, ignored by the table of max(c, 1)). */
#define EPPF_STEPD(S)                                                                             \
    do {                                                                                          \
        const __mmask8 on_ = _mm512_cmpgt_epi64_mask(rem##S, zero);                              \
        const __m512i t_ = _mm512_and_si512(_mm512_multishift_epi64_epi8(ctrl, p##S), mfield);   \
        const __m512i wi_ = _mm512_madd_epi16(_mm512_maddubs_epi16(t_, mul), w21);               \
        __m512i c_ = _mm512_mask_i64gather_epi64(zero, on_, wi_, cbase, 8);                      \
        c_ = _mm512_multishift_epi64_epi8(t_, c_);                                                \
        occ##S = _mm512_mask_add_epi64(occ##S, _mm512_mask_testn_epi64_mask(on_, c_, three), occ##S, one); \
        c_ = _mm512_permutexvar_epi64(c_, tsteps);                                                \
        p##S = _mm512_add_epi64(p##S, _mm512_mullo_epi64(c_, inc##S));                            \
        rem##S = _mm512_sub_epi64(rem##S, c_);                                                    \
    } while (0)
/* The lanes of set S whose bin is certain (or whose line has ended) give
   their counts index (or key and occ) to the output and free their lane. */
#define EPPF_DONE(S, o)                                                                           \
    do {                                                                                          \
        const __m512i lo_ = _mm512_loadu_si512(lanes + (o) + 24), hi_ = _mm512_loadu_si512(lanes + (o) + 32); \
        const __m512i key_ = _mm512_loadu_si512(lanes + (o) + 48);                                \
        const __m512i end_ = _mm512_add_epi64(occ##S, rem##S);                                    \
        __mmask8 done_ = _mm512_cmple_epi64_mask(rem##S, zero) | _mm512_cmpge_epi64_mask(occ##S, hi_) \
                         | _mm512_cmplt_epi64_mask(end_, lo_);                                    \
        if (!wide)                                                                                \
            done_ |= _mm512_cmpge_epi64_mask(occ##S, lo_) & _mm512_cmplt_epi64_mask(end_, hi_);   \
        done_ &= act##S;                                                                          \
        if (wide) {                                                                               \
            _mm512_storeu_si512(OK + nout, _mm512_maskz_compress_epi64(done_, key_));             \
            _mm512_storeu_si512(OO + nout, _mm512_maskz_compress_epi64(done_, occ##S));           \
        } else {                                                                                  \
            /* the bin: how many of lo, hi (one and the same for n4 = 2) occ reaches */           \
            __m512i bb_ = _mm512_mask_add_epi64(key_, _mm512_cmpge_epi64_mask(occ##S, lo_), key_, one); \
            if (n4 == 3)                                                                          \
                bb_ = _mm512_mask_add_epi64(bb_, _mm512_cmpge_epi64_mask(occ##S, hi_), bb_, one); \
            _mm512_storeu_si512(OK + nout, _mm512_maskz_compress_epi64(done_, bb_));              \
        }                                                                                         \
        nout += __builtin_popcount(done_);                                                        \
        act##S &= (__mmask8)~done_;                                                               \
        rem##S = _mm512_mask_mov_epi64(rem##S, done_, zero);  /* a free lane looks nothing up */  \
    } while (0)

    EPPF_LOADL(A, 0);
    EPPF_LOADL(B, 64);
    EPPF_LOADL(C, 128);
    EPPF_LOADL(D, 192);
    EPPF_LOADL(E, 256);
    EPPF_LOADL(F, 320);
    for (;;) {
        EPPF_REFILL(A, 0);
        EPPF_REFILL(B, 64);
        EPPF_REFILL(C, 128);
        EPPF_REFILL(D, 192);
        EPPF_REFILL(E, 256);
        EPPF_REFILL(F, 320);
        if (drain ? (actA | actB | actC | actD | actE | actF) == 0
                  : (q >= nq && (actA & actB & actC & actD & actE & actF) != 0xff))
            break;
        EPPF_STEPD(A);
        EPPF_STEPD(B);
        EPPF_STEPD(C);
        EPPF_STEPD(D);
        EPPF_STEPD(E);
        EPPF_STEPD(F);
        EPPF_STEPD(A);
        EPPF_STEPD(B);
        EPPF_STEPD(C);
        EPPF_STEPD(D);
        EPPF_STEPD(E);
        EPPF_STEPD(F);
        EPPF_STEPD(A);
        EPPF_STEPD(B);
        EPPF_STEPD(C);
        EPPF_STEPD(D);
        EPPF_STEPD(E);
        EPPF_STEPD(F);
        EPPF_STEPD(A);
        EPPF_STEPD(B);
        EPPF_STEPD(C);
        EPPF_STEPD(D);
        EPPF_STEPD(E);
        EPPF_STEPD(F);
        EPPF_DONE(A, 0);
        EPPF_DONE(B, 64);
        EPPF_DONE(C, 128);
        EPPF_DONE(D, 192);
        EPPF_DONE(E, 256);
        EPPF_DONE(F, 320);
    }
    EPPF_SAVEL(A, 0);
    EPPF_SAVEL(B, 64);
    EPPF_SAVEL(C, 128);
    EPPF_SAVEL(D, 192);
    EPPF_SAVEL(E, 256);
    EPPF_SAVEL(F, 320);
#undef EPPF_LOADL
#undef EPPF_SAVEL
#undef EPPF_REFILL
#undef EPPF_STEPD
#undef EPPF_DONE

    if (!wide) {
        for (i = 0; i < nout; i++)
            counts[OK[i]]++;
    } else {
        for (i = 0; i < nout; i++) {
            const int32_t *th = thr + ((OK[i] >> 32) + 1) * n4;
            int bb = 0, j;
            for (j = 1; j < n4; j++)
                bb += OO[i] >= th[j];
            counts[(int32_t)(OK[i] & 0xFFFFFFFF) + bb]++;
        }
    }
}
#else
static void eppf_f4_dist_avx512(int m, const int32_t *ii, const int32_t *jj, const int32_t *B,
                                const int64_t *pv, const uint64_t *code, int64_t g, const int32_t *thr, int n4,
                                const int64_t *lohi, int64_t *lanes, int drain, int32_t *counts)
{
    (void)m; (void)ii; (void)jj; (void)B; (void)pv; (void)code; (void)g; (void)thr; (void)n4; (void)lohi;
    (void)lanes; (void)drain; (void)counts;
}
#endif

#endif /* EPPF_WALK_H */
