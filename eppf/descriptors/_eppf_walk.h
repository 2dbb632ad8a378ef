/* SIMD kernels of a batch of pairs for _eppf_fast.pyx, chosen at run time:
 *
 * - AVX2, four pairs at a time: the f1-f3 bins (``eppf_f123_batch_avx2``)
 *   and the f4 line walks (``eppf_f4_batch_avx2``);
 * - AVX-512 (F, BW, VL, DQ and VBMI), eight pairs at a time: the pair draws
 *   (``eppf_draw_batch_avx512``), the f1-f3 bins with the check for
 *   coinciding points (``eppf_f123_batch_avx512``) and two f4 walks: the
 *   grouped walk (``eppf_f4_batch_avx512``, level 2) and the skipping walk
 *   (``eppf_f123q_avx512`` and ``eppf_f4_walkq_avx512``, level 3), which
 *   keeps every lane busy by refilling it from a queue and walks each line
 *   along its dominant axis, jumping over voxels proved empty by the cone
 *   ahead of them (``eppf_code_grid``): 1.3 look-ups of eight lanes a pair
 *   instead of 3.0. The default is level 3 on AMD, 2 elsewhere
 *   (``eppf_walk_prefers_skips``).
 *
 * Gathers are used only for the grouped walk's look-ups: AMD Zen 4 runs an
 * eight-element gather at about 13 cycles (0.65 ns an element measured on a
 * Zen 4 KVM guest, against about 0.4 ns a scalar load), so the AVX-512 code
 * reads the points, normals and voxels of f1-f3 and the walk setup with row
 * loads and a transpose, the skipping walk's look-ups with scalar loads, and
 * its tables by in-register look-ups.
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
/* Pairs per batch (the walks sort a batch by line length: a longer batch
   groups the lanes better, up to about this size). */
#define EPPF_WALK_BATCH 256
/* Pairs per batch of the skipping walk (level 3), which needs no sorting:
   fewer, longer calls (its lanes carry over between them). */
#define EPPF_QUEUE_BATCH 1024
/* A walk's counters in one int64 for the AVX-512 walk: rem (inner voxels) in
   bits 0-20, the f4 thresholds lo from bit 21 and hi from bit 42 (all below
   2**21); ``lohi[T]`` holds lo and hi of T voxels in place (_eppf_fast.pyx). */
#define EPPF_META_LO 21
#define EPPF_META_HI 42
#define EPPF_META_MASK 0x1FFFFF
/* The lane state of ``eppf_f4_walkq_avx512`` between calls for one object: per
   set of eight lanes (six sets, 64 words each), three vectors of eight int64
   (words 0-23) and the mask of lanes in use (word 56). */
#define EPPF_LANES_WORDS 384
/* The skipping walk's lane state (``eppf_f4_walkq_avx512``): four signed
   bytes R, U, O, X. */
#define EPPF_ST(r, u, o, x) ((int64_t)(((uint64_t)(uint8_t)(r)) | ((uint64_t)(uint8_t)(u) << 8)       \
                                       | ((uint64_t)(uint8_t)(o) << 16) | ((uint64_t)(uint8_t)(x) << 24)))
/* st[T] = the state of a line of T voxels before its first step, T = 1..64
   (0 for T > g + 1, past ``thr``'s rows [T, b], T = 0..g + 1, and for T = 0). */
static void eppf_walk_states(const int32_t *thr, int n4, int64_t g, int64_t *st)
{
    int T;
    for (T = 0; T <= 64; T++) {
        st[T] = 0;
        if (T >= 1 && T <= g + 1) {
            const int lo = thr[T * n4 + 1], hi = thr[T * n4 + n4 - 1];
            st[T] = EPPF_ST(T - 3, T - lo, hi - 3, lo - 3);
        }
    }
}
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

static int eppf_walk_has_avx2(void)
{
    return eppf_cpu_has(EPPF_CPU_AVX2);
}

/* The rows of ``eppf_f123_batch_avx512``'s ``pn``: point k's x, y, z,
 * nx, ny, nz, its packed voxel pv[k] (the bits of the int64 in a double's
 * place; 0 where pv is NULL) and an unused double at pn[8 k], so that one
 * 64-byte load reads a point, its normal and its voxel. */
static void eppf_pack_rows(int64_t n, const double *pts, int64_t ps, const double *nrm, int64_t ns,
                           const int64_t *pv, double *pn)
{
    int64_t k;
    for (k = 0; k < n; k++) {
        double *r = pn + 8 * k;
        const int64_t v = pv ? pv[k] : 0;
        r[0] = pts[ps * k];
        r[1] = pts[ps * k + 1];
        r[2] = pts[ps * k + 2];
        r[3] = nrm[ns * k];
        r[4] = nrm[ns * k + 1];
        r[5] = nrm[ns * k + 2];
        memcpy(r + 6, &v, sizeof v);
        r[7] = 0.0;
    }
}

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

/* f4 bins of the lines without inner voxels (L <= 1): occ = T = L + 1, all voxels occupied. */
static void eppf_f4_short_lines(int m, const int32_t *Ls, const int32_t *thr, int n4, int32_t *B)
{
    int t;
    for (t = 0; t < m; t++)
        if (Ls[t] <= 1)
            B[t] += eppf_f4_bin(thr, n4, Ls[t] + 1, Ls[t] + 1);
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
 * n (x, y, z vectors): ``eppf_f123_batch_avx2``'s IEEE operations in the
 * same order, so the same bins. The normals are read only where n2 > 1 or
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

/* ``eppf_f123_batch_avx2`` eight pairs at a time (``eppf_bins123_8``), which
 * also checks the pairs as ``_draw_pair`` does: returns the first t whose two
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
 * as ``eppf_f4_setup_avx2``: the increments' scale 2**14 / L is the same
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

/* ``eppf_f4_setup_avx2`` eight pairs at a time (``eppf_setup8_avx512``). */
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

/* The cone grids behind the AVX-512 walk's skips. A line walked along its
 * dominant axis a, in the direction in which that coordinate grows, moves it
 * by exactly one voxel a step and every other coordinate by at most one, so
 * its j-th voxel after v lies in the cone of v: the 3^2 box of half side j in
 * the plane j voxels further along a. ``code`` holds three grids, one per
 * axis (x, y, z): for every voxel v, c = min(C, 3), C the number of cone
 * planes from v on (v's own first) with no occupied voxel, i.e. C = 0 where
 * v is occupied, else 1 + the smallest C of the 3^2 voxels of the next plane
 * (planes past the grid's face count as empty). c is bits 2 (z & 31) and
 * 2 (z & 31) + 1 of word 4096 a + 64 x + y + EPPF_CODE_HALF (z >> 5): each
 * grid is 64 x 64 words a half (rows of 64 whatever g), the z < 32 halves
 * of the three grids first, the z >= 32 ones EPPF_CODE_HALF words on (the
 * walk's word index then comes from one multiply-add of bytes, see
 * ``eppf_f4_walkq_avx512``). The sets O_m of voxels with C < m: O_1 the
 * occupied ones, O_{m+1} = O_1 or the voxels whose next plane's 3^2 box
 * meets O_m (``eppf_cone_step``). ``bits``: g^2 words, one per (x, y) row,
 * z bits (none past z = g - 1); ``work``: 4 g^2 words of scratch, which may
 * be ``code + EPPF_CODE_SCRATCH`` (between the two halves); 2 <= g <= 64. */
#define EPPF_CODE_HALF 65536
#define EPPF_CODE_WORDS (EPPF_CODE_HALF + 3 * 4096)
#define EPPF_CODE_SCRATCH (3 * 4096)
/* The skipping walk reads ``code`` at word indices below this bound (its
   fields masked: y + 64 (x + 64 a) + EPPF_CODE_HALF (z >> 5) with y, x < 64,
   a < 4, for any position, lanes past their line included), so the buffer
   must hold this many words (it holds the grids and the scratch). */
#define EPPF_CODE_READ_WORDS (EPPF_CODE_HALF + 4 * 4096)
#if EPPF_CODE_SCRATCH + 4 * 4096 > EPPF_CODE_HALF || EPPF_CODE_WORDS > EPPF_CODE_READ_WORDS
#error "the cone grids' scratch must fit between their halves, the grids inside the read bound"
#endif
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
/* The code words of eight rows r from their bit planes b0 (code bit 0) and
   b1 (code bit 1), z bits each: out[r] holds z = i and out[r +
   EPPF_CODE_HALF] z = 32 + i, at bits 2 i (b0) and 2 i + 1 (b1). Bytes
   pairing a nibble of b0 with the same nibble of b1 (lo: the low nibbles of
   each byte, hi: the high ones), put in order by a byte permutation, and
   spread by one GF(2) affine map (bit i to 2 i, bit 4 + i to 2 i + 1). */
__attribute__((target(EPPF_AVX512_TARGET ",gfni")))
static inline void eppf_code_rows8(__m512i b0, __m512i b1, uint64_t *out)
{
    const __m512i m4 = _mm512_set1_epi8(0x0F);
    const __m512i spread = _mm512_set1_epi64(0x0110022004400880LL);
    /* nibble bytes: lo = low nibbles (b0 | b1 << 4), hi = high nibbles (b0 >> 4 | b1 & 0xF0) */
    const __m512i lo = _mm512_ternarylogic_epi64(m4, b0, _mm512_slli_epi64(b1, 4), 0xCA);
    const __m512i hi = _mm512_ternarylogic_epi64(m4, _mm512_srli_epi64(b0, 4), b1, 0xCA);
    /* word R of the first output (z < 32): bytes 8 R + 2 k + e (k < 4) from lo (e = 0) or hi (e = 1)
       byte 8 R + k; of the second (z >= 32): from byte 8 R + 4 + k */
    const __m512i i0 = _mm512_set_epi8(
        123, 59, 122, 58, 121, 57, 120, 56, 115, 51, 114, 50, 113, 49, 112, 48,
        107, 43, 106, 42, 105, 41, 104, 40, 99, 35, 98, 34, 97, 33, 96, 32,
        91, 27, 90, 26, 89, 25, 88, 24, 83, 19, 82, 18, 81, 17, 80, 16,
        75, 11, 74, 10, 73, 9, 72, 8, 67, 3, 66, 2, 65, 1, 64, 0);
    const __m512i i1 = _mm512_add_epi8(i0, _mm512_set1_epi8(4));
    _mm512_storeu_si512(out, _mm512_gf2p8affine_epi64_epi8(_mm512_permutex2var_epi8(lo, i0, hi), spread, 0));
    _mm512_storeu_si512(out + EPPF_CODE_HALF,
                        _mm512_gf2p8affine_epi64_epi8(_mm512_permutex2var_epi8(lo, i1, hi), spread, 0));
}
/* Words w..w+7 of a cone step's result, r or-ed with bits: stored to out,
   or (where code is not NULL: the second step, o the first one's result)
   made into the code words of their eight rows. */
__attribute__((target(EPPF_AVX512_TARGET ",gfni")))
static inline void eppf_cone_emit8(const uint64_t *bits, const uint64_t *o, uint64_t *out, uint64_t *code, int w,
                                   __m512i r)
{
    const __m512i b = _mm512_loadu_si512(bits + w), u3 = _mm512_or_si512(r, b);
    if (code) {
        const __m512i u2 = _mm512_loadu_si512(o + w);
        const __m512i b0 = _mm512_ternarylogic_epi64(u2, b, u3, 0x75);  /* (u2 & ~b) | ~u3: c = 1 or 3 */
        const __m512i b1 = _mm512_ternarylogic_epi64(u2, u2, u2, 0x55); /* ~u2: c = 2 or 3 */
        eppf_code_rows8(b0, b1, code + w);
    } else {
        _mm512_storeu_si512(out + w, u3);
    }
}
/* out = bits | D_axis(o) for g = 64 (``eppf_cone_step``), or its code words
   (code not NULL, o = O_2: see eppf_cone_emit8); a: 192 words of scratch */
__attribute__((target(EPPF_AVX512_TARGET ",gfni")))
static void eppf_cone_step64(const uint64_t *bits, const uint64_t *o, uint64_t *out, uint64_t *a, int axis,
                             uint64_t *code)
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
                for (k = 0; k < 8; k++)
                    eppf_cone_emit8(bits, o, out, code, x * 64 + 8 * k,
                                    _mm512_ternarylogic_epi64(v[k], eppf_yprev(v, k), eppf_ynext(v, k), 0xFE));
            } else {
                for (k = 0; k < 8; k++)
                    eppf_cone_emit8(bits, o, out, code, x * 64 + 8 * k, _mm512_setzero_si512());
            }
        }
        return;
    }
    /* the slabs' own boxes, z +- 1 (axis 1) or y +- 1 (axis 2), in a ring of three slabs in a
       (kept in the L1 cache), or-ed over x +- 1, then the next y (axis 1) or the next z (axis 2) */
    for (x = -1; x < 64; x++) {
        if (x < 63) {
            uint64_t *box = a + 64 * ((x + 1) % 3);
            EPPF_SLAB_LOAD(v, o + (x + 1) * 64);
            for (k = 0; k < 8; k++)
                _mm512_storeu_si512(box + 8 * k, axis == 1 ? eppf_zdil(v[k])
                                    : _mm512_ternarylogic_epi64(v[k], eppf_yprev(v, k), eppf_ynext(v, k), 0xFE));
        }
        if (x < 0)
            continue;
        for (k = 0; k < 8; k++) {
            __m512i r = _mm512_loadu_si512(a + 64 * (x % 3) + 8 * k);
            if (x > 0)
                r = _mm512_or_si512(r, _mm512_loadu_si512(a + 64 * ((x + 2) % 3) + 8 * k));
            if (x < 63)
                r = _mm512_or_si512(r, _mm512_loadu_si512(a + 64 * ((x + 1) % 3) + 8 * k));
            v[k] = r;
        }
        for (k = 0; k < 8; k++)
            eppf_cone_emit8(bits, o, out, code, x * 64 + 8 * k,
                            axis == 1 ? eppf_ynext(v, k) : _mm512_srli_epi64(v[k], 1));
    }
}
__attribute__((target(EPPF_AVX512_TARGET ",gfni")))
static void eppf_code_grid64(const uint64_t *bits, uint64_t *work, uint64_t *code)
{
    uint64_t *o2 = work, *a = work + 4096;
    int axis;
    for (axis = 0; axis < 3; axis++) {
        eppf_cone_step64(bits, bits, o2, a, axis, NULL);
        eppf_cone_step64(bits, o2, NULL, a, axis, code + 4096 * axis);
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
        uint64_t *c = code + 4096 * axis;
        eppf_cone_step(bits, bits, o2, a, b, g, axis);
        eppf_cone_step(bits, o2, o3, a, b, g, axis);
        for (r = 0; r < g * g; r++) {
            const uint64_t b0 = (o2[r] & ~bits[r]) | ~o3[r];  /* c = 1 or 3 */
            const uint64_t b1 = ~o2[r];                       /* c = 2 or 3 */
            const int64_t w = 64 * (r / g) + r % g;
            c[w] = eppf_spread32(b0) | (eppf_spread32(b1) << 1);
            c[w + EPPF_CODE_HALF] = eppf_spread32(b0 >> 32) | (eppf_spread32(b1 >> 32) << 1);
        }
    }
}
#if EPPF_WALK_SIMD
/* The skipping AVX-512 walk (level 3), in two parts per batch of pairs:
 * ``eppf_f123q_avx512`` bins f1-f3 and sets up the lines in one pass over
 * the pairs (the rows of ``pn`` also hold each point's packed voxel, so the
 * setup costs no loads of its own), queueing each line with inner voxels;
 * ``eppf_f4_walkq_avx512`` walks the queue in six sets of eight lanes, each
 * lane refilled as soon as its line's bin is certain, each step
 * skipping the voxels the cone grids prove empty, and counts the pairs.
 *
 * A queued line is (first position, increment, state) in batch order. It is
 * walked along a dominant axis a (|delta_a| = L: its increment's field is
 * exactly +-2**14, so that coordinate moves by one voxel every step), in the
 * direction in which that coordinate grows: a line whose delta_a is negative
 * starts at its last inner voxel (first + (L - 2) INC) and steps by -INC,
 * which visits the same integer positions in reverse. a sits in bits 62-63
 * of the position (above the x field, which never reaches them), where the
 * word index picks the cone grid of axis a.
 *
 * A lane's state is one int64: four signed bytes R = rem - 1,
 * U = rem + occ - lo, O = hi - 1 - occ and X = lo - 1 - occ (rem the inner
 * voxels not yet passed, occ the occupied voxels counted, both ends
 * included; lo and hi the thresholds of the f4 bins, ``thr``) and, in bits
 * 32-55, the pair's f1-f3 bin B (bits 56-61: L, for n4 > 3). The bin is
 * certain once R < 0 (the line has ended), U < 0 (occ + rem < lo: the
 * bottom bin, whatever the rest holds) or O < 0 (occ >= hi: the top bin);
 * the bin is then (X < 0) + (O < 0) for n4 = 3, (O < 0) for n4 = 2, and
 * from occ = hi - 1 - O for n4 > 3 (occ is exact when the line has ended,
 * below lo in the bottom case and at least hi in the top one). With the
 * middle bin's early stop of the other walks left out, those are the cases.
 *
 * A step of a lane reads c = min(C, 3) at its voxel in the grid of its axis
 * (``eppf_code_grid``). c = 0: the voxel is occupied (R, O, X down by one),
 * one step. c > 0: the voxel and the next c - 1 of the line are empty, since
 * the k-th voxel after this one lies in its cone k planes on (one plane a
 * step, the other coordinates at most one voxel a step): the lane advances c
 * steps at once (P += c INC, the same integer position as that many single
 * steps) and R and U go down by c. One byte-wise addition of a table entry
 * picked by c does both (bytes: no carry between the counters; each stays
 * within -64..63). Only lanes with R >= 0 change their state; the others
 * still look up (every word index is below EPPF_CODE_READ_WORDS, whatever
 * the position: its fields are masked) and drift. The stopping test and the
 * refill run after every fourth step: walking past the point where the bin
 * became certain cannot change it (U < 0 stays so until the line ends; O
 * and X only fall). A lane whose bin is certain hands its state to a list
 * and takes the next queued line; after the walk, one vector pass over the
 * list turns each state into its counts index B + bin (fewer operations in
 * the loop: 3% of the kernel) and the counts are added.
 *
 * Lines still being walked when the queue runs dry stay in ``lanes``
 * (EPPF_LANES_WORDS int64, all zero before an object's first call) for the
 * next call; ``drain`` walks them to their end (the object's last call,
 * nq = 0). A histogram is a sum, so the order in which lines finish does not
 * change it: the counts are the scalar kernel's.
 */

/* The f1-f3 bins and the f4 walk setup of the pairs (ii[t], jj[t]),
 * t < m <= EPPF_QUEUE_BATCH, with the points, normals and voxels in the rows
 * of ``pn`` (``eppf_pack_rows``) and the lines' first states in ``states``
 * (``eppf_walk_states``). Lines with inner voxels (L > 1) join the
 * queue (QP, QI, QM; *nq_out of them); the others are counted at once
 * (occ = T = L + 1, every voxel occupied). As ``eppf_f123_batch_avx512``,
 * returns the first t whose two points coincide, or m; no pair from there
 * on is queued or counted. */
__attribute__((target(EPPF_AVX512_TARGET)))
static int eppf_f123q_avx512(int m, const int32_t *ii, const int32_t *jj, double scale, int n1, int n2, int n3,
                             int n4, double f1_density, const double *cos2, const double *cos3, const double *pn,
                             const int32_t *thr, const int64_t *states, int64_t *QP, int64_t *QI, int64_t *QM,
                             int *nq_out, int32_t *counts)
{
    const __m512i zero = _mm512_setzero_si512(), one = _mm512_set1_epi64(1), two = _mm512_set1_epi64(2);
    __m512i tab[8];
    int32_t ri[8], rj[8];
    int t, l, bad = m, nq = 0;
    eppf_lohi_tab_avx512(states, tab);
    for (t = 0; t < m && bad == m; t += 8) {
        const int32_t *vi, *vj;
        __mmask8 keep = eppf_group8(m, t, ii, jj, ri, rj, &vi, &vj), same, walk, few;
        __m512d a[7], b[7];
        __m512i p, inc, L, st, key, d[3];
        __m256i bins;
        eppf_load7x8(pn, vi, a);
        eppf_load7x8(pn, vj, b);
        same = keep & eppf_same8(a, b);
        if (same) {  /* the first pair whose points coincide ends the batch */
            bad = t + __builtin_ctz(same);
            keep &= (__mmask8)((1u << __builtin_ctz(same)) - 1);
        }
        bins = eppf_bins123_8(a, a + 3, b, b + 3, scale, n1, n2, n3, n4, f1_density, cos2, cos3);
        eppf_line8_avx512(_mm512_castpd_si512(a[6]), _mm512_castpd_si512(b[6]), tab, &p, &inc, &L, &st, d);
        {
            /* along the dominant axis (any of them on a tie), in the direction in which it grows */
            const __mmask8 onx = _mm512_cmpeq_epi64_mask(_mm512_abs_epi64(d[0]), L);
            const __mmask8 ony = (__mmask8)~onx & _mm512_cmpeq_epi64_mask(_mm512_abs_epi64(d[1]), L);
            const __mmask8 onz = (__mmask8)~(onx | ony);
            const __m512i da = _mm512_mask_blend_epi64(onz, _mm512_mask_blend_epi64(ony, d[0], d[1]), d[2]);
            const __mmask8 back = _mm512_cmplt_epi64_mask(da, zero);
            const __m512i axis = _mm512_mask_blend_epi64(onz, _mm512_maskz_mov_epi64(ony, one), two);
            p = _mm512_mask_add_epi64(p, back, p, _mm512_mullo_epi64(_mm512_sub_epi64(L, two), inc));
            inc = _mm512_mask_sub_epi64(inc, back, zero, inc);
            p = _mm512_add_epi64(p, _mm512_slli_epi64(axis, 62));
        }
        walk = keep & _mm512_cmpgt_epi64_mask(L, one);
        few = keep & (__mmask8)~walk;
        key = _mm512_cvtepi32_epi64(bins);
        if (n4 > 3)
            key = _mm512_add_epi64(key, _mm512_slli_epi64(L, 24));
        st = _mm512_add_epi64(st, _mm512_slli_epi64(key, 32));
        _mm512_storeu_si512(QP + nq, _mm512_maskz_compress_epi64(walk, p));
        _mm512_storeu_si512(QI + nq, _mm512_maskz_compress_epi64(walk, inc));
        _mm512_storeu_si512(QM + nq, _mm512_maskz_compress_epi64(walk, st));
        nq += __builtin_popcount(walk);
        if (few) {
            int64_t Lf[8] __attribute__((aligned(64)));
            int32_t Bf[8] __attribute__((aligned(32)));
            _mm512_store_si512(Lf, L);
            _mm256_store_si256((__m256i *)Bf, bins);
            for (l = 0; l < 8; l++)
                if ((few >> l) & 1)  /* no inner voxel: occ = T = L + 1 */
                    counts[Bf[l] + eppf_f4_bin(thr, n4, Lf[l] + 1, Lf[l] + 1)]++;
        }
    }
    *nq_out = nq;
    return bad;
}

/* The words tab[k_l], l < 8, k_l the high half of lane l of ix, by scalar
 * loads: on Zen 4 (whose gathers are microcoded) cheaper than a gather, and
 * other work overlaps them. Every index must be valid. */
__attribute__((target(EPPF_AVX512_TARGET)))
static inline __m512i eppf_soft_gather8(__m512i ix, const uint64_t *tab)
{
    uint32_t idx[16] __attribute__((aligned(64)));
    __m128i a0, a1, a2, a3;
    __m256i b0, b1;
    _mm512_store_si512(idx, ix);
    /* read the indices back from memory: the compiler would otherwise extract
       them from the register, 2-3 vector operations each */
    __asm__("" : "+m"(idx));
#define EPPF_W(k) ((long long)tab[idx[2 * (k) + 1]])
    a0 = _mm_insert_epi64(_mm_cvtsi64_si128(EPPF_W(0)), EPPF_W(1), 1);
    a1 = _mm_insert_epi64(_mm_cvtsi64_si128(EPPF_W(2)), EPPF_W(3), 1);
    a2 = _mm_insert_epi64(_mm_cvtsi64_si128(EPPF_W(4)), EPPF_W(5), 1);
    a3 = _mm_insert_epi64(_mm_cvtsi64_si128(EPPF_W(6)), EPPF_W(7), 1);
#undef EPPF_W
    b0 = _mm256_inserti128_si256(_mm256_castsi128_si256(a0), a1, 1);
    b1 = _mm256_inserti128_si256(_mm256_castsi128_si256(a2), a3, 1);
    return _mm512_inserti64x4(_mm512_castsi256_si512(b0), b1, 1);
}

/* Walk the nq queued lines (and those in ``lanes``) and count the pairs whose
 * bin becomes certain; ``code`` holds at least EPPF_CODE_READ_WORDS words. */
__attribute__((target(EPPF_AVX512_TARGET)))
static void eppf_f4_walkq_avx512(int nq, const int64_t *QP, const int64_t *QI, const int64_t *QM,
                                 const uint64_t *code, int64_t g, const int32_t *thr, int n4, int64_t *lanes,
                                 int drain, int32_t *counts)
{
    /* the states of the finished lines (at most 48 + nq of them), then their counts indices (n4 <= 3) */
    int64_t OK[EPPF_QUEUE_BATCH + 64] __attribute__((aligned(64)));
    const __m512i one = _mm512_set1_epi64(1);
    /* multishift fields: byte 0 <- bits 13.. (2 z and a fraction bit), byte 4 <- bits 35.. (y),
       byte 5 <- bits 56.. (x and the axis a above it), byte 6 <- bit 19 (z >> 5); kept: 2 (z & 31),
       6, 8 bits and 1 bit */
    const __m512i ctrl = _mm512_set1_epi64(((int64_t)(EPPF_PK_ZSHIFT + 5) << 48) | ((int64_t)EPPF_PK_XSHIFT << 40)
                                           | ((int64_t)EPPF_PK_YSHIFT << 32) | (EPPF_PK_ZSHIFT - 1));
    const __m512i mfield = _mm512_set1_epi64(0x0001FF3F0000003ELL), offset = _mm512_set1_epi64(0x3E);
    /* bytes 4, 5, 6 times 1, 64, 1 and added in pairs: the lane's high half is the word index
       y + 64 (x + 64 a) + EPPF_CODE_HALF (z >> 5) (the cone grid of axis a; below EPPF_CODE_READ_WORDS
       for any position) */
    const __m512i wdot = _mm512_set1_epi64(0x0001400100000000LL);
    /* steps a look-up advances by its code c (index bits 0-1; bit 2 is the next voxel's): max(c, 1) */
    const __m512i tsteps = _mm512_set_epi64(3, 2, 1, 1, 3, 2, 1, 1);
    /* and what it adds to the state's bytes R, U, O, X (c = 0: an occupied voxel) */
    const __m512i tdelta = _mm512_set_epi64(EPPF_ST(-3, -3, 0, 0), EPPF_ST(-2, -2, 0, 0), EPPF_ST(-1, -1, 0, 0),
                                            EPPF_ST(-1, 0, -1, -1), EPPF_ST(-3, -3, 0, 0), EPPF_ST(-2, -2, 0, 0),
                                            EPPF_ST(-1, -1, 0, 0), EPPF_ST(-1, 0, -1, -1));
    /* the sign bits of R; of R, U and O; of O; of X */
    const __m512i rsign = _mm512_set1_epi64(0x80), dsign = _mm512_set1_epi64(0x808080);
    const __m512i osign = _mm512_set1_epi64(0x800000), xsign = _mm512_set1_epi64(0x80000000LL);
    const int wide = n4 > 3;
    __m512i pA, incA, stA, pB, incB, stB, pC, incC, stC;
    __m512i pD, incD, stD, pE, incE, stE, pF, incF, stF;
    __mmask8 actA, actB, actC, actD, actE, actF;
    int q = 0, nout = 0, i;

/* Set S's lanes (position, increment, state and the mask of lanes in use)
   from and to ``lanes``. */
#define EPPF_LOADL(S, o)                                                                          \
    do {                                                                                          \
        p##S = _mm512_loadu_si512(lanes + (o));                                                   \
        inc##S = _mm512_loadu_si512(lanes + (o) + 8);                                             \
        st##S = _mm512_loadu_si512(lanes + (o) + 16);                                             \
        act##S = (__mmask8)lanes[(o) + 56];                                                       \
    } while (0)
#define EPPF_SAVEL(S, o)                                                                          \
    do {                                                                                          \
        _mm512_storeu_si512(lanes + (o), p##S);                                                   \
        _mm512_storeu_si512(lanes + (o) + 8, inc##S);                                             \
        _mm512_storeu_si512(lanes + (o) + 16, st##S);                                             \
        lanes[(o) + 56] = act##S;                                                                 \
    } while (0)
/* The free lanes of set S take the next lines of the queue, in lane order. */
#define EPPF_REFILL(S)                                                                            \
    do {                                                                                          \
        __mmask8 fill_ = (__mmask8)~act##S;                                                       \
        if (nq - q < 8) {                                                                         \
            while (__builtin_popcount(fill_) > nq - q)                                            \
                fill_ &= (__mmask8)~(1u << (31 - __builtin_clz(fill_)));                          \
        }                                                                                         \
        p##S = _mm512_mask_expand_epi64(p##S, fill_, _mm512_loadu_si512(QP + q));                 \
        inc##S = _mm512_mask_expand_epi64(inc##S, fill_, _mm512_loadu_si512(QI + q));             \
        st##S = _mm512_mask_expand_epi64(st##S, fill_, _mm512_loadu_si512(QM + q));               \
        act##S |= fill_;                                                                          \
        q += __builtin_popcount(fill_);                                                           \
    } while (0)
/* One step of set S. The fields of the word index come from one
   multishift and one multiply-add of bytes (no multiply by g: the grids'
   rows are 64 words whatever g); byte 0 of t_ is the code's bit offset, so
   word >> (t_ & 0x3E) puts c in bits 0-1 (the next voxel's code above,
   ignored by the tables, which read bits 0-2 and repeat themselves; a
   variable shift, not a second multishift: the shuffle units are the
   busier). */
#define EPPF_STEPD(S)                                                                             \
    do {                                                                                          \
        const __mmask8 on_ = _mm512_testn_epi64_mask(st##S, rsign);                               \
        const __m512i t_ = _mm512_and_si512(_mm512_multishift_epi64_epi8(ctrl, p##S), mfield);   \
        const __m512i wi_ = _mm512_maddubs_epi16(t_, wdot);                                      \
        __m512i c_ = _mm512_srlv_epi64(eppf_soft_gather8(wi_, code), _mm512_and_si512(t_, offset)); \
        st##S = _mm512_add_epi8(st##S, _mm512_maskz_permutexvar_epi64(on_, c_, tdelta));          \
        c_ = _mm512_permutexvar_epi64(c_, tsteps);                                                \
        p##S = _mm512_add_epi64(p##S, _mm512_mullo_epi64(c_, inc##S));                            \
    } while (0)
/* The lanes of set S whose bin is certain give their state to OK and free
   their lane (state -1: R < 0). */
#define EPPF_DONE(S)                                                                              \
    do {                                                                                          \
        const __mmask8 done_ = _mm512_test_epi64_mask(st##S, dsign) & act##S;                     \
        _mm512_storeu_si512(OK + nout, _mm512_maskz_compress_epi64(done_, st##S));                \
        nout += __builtin_popcount(done_);                                                        \
        act##S &= (__mmask8)~done_;                                                               \
        st##S = _mm512_mask_mov_epi64(st##S, done_, _mm512_set1_epi64(-1));                       \
    } while (0)
#define EPPF_ROUND(STEP)                                                                          \
    do {                                                                                          \
        STEP(A);                                                                                  \
        STEP(B);                                                                                  \
        STEP(C);                                                                                  \
        STEP(D);                                                                                  \
        STEP(E);                                                                                  \
        STEP(F);                                                                                  \
    } while (0)

    (void)g;  /* the grids' layout is the same for every g */
    EPPF_LOADL(A, 0);
    EPPF_LOADL(B, 64);
    EPPF_LOADL(C, 128);
    EPPF_LOADL(D, 192);
    EPPF_LOADL(E, 256);
    EPPF_LOADL(F, 320);
    for (;;) {
        EPPF_ROUND(EPPF_REFILL);
        if (drain ? (actA | actB | actC | actD | actE | actF) == 0
                  : (q >= nq && (actA & actB & actC & actD & actE & actF) != 0xff))
            break;
        EPPF_ROUND(EPPF_STEPD);
        EPPF_ROUND(EPPF_STEPD);
        EPPF_ROUND(EPPF_STEPD);
        EPPF_ROUND(EPPF_STEPD);
        EPPF_ROUND(EPPF_DONE);
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
#undef EPPF_ROUND

    if (!wide) {
        for (i = 0; i < nout; i += 8) {
            const __m512i st = _mm512_maskz_loadu_epi64(nout - i >= 8 ? 0xff : (1u << (nout - i)) - 1, OK + i);
            __m512i bb = _mm512_srli_epi64(st, 32);
            bb = _mm512_mask_add_epi64(bb, _mm512_test_epi64_mask(st, osign), bb, one);
            if (n4 == 3)
                bb = _mm512_mask_add_epi64(bb, _mm512_test_epi64_mask(st, xsign), bb, one);
            _mm512_storeu_si512(OK + i, bb);
        }
        for (i = 0; i < nout; i++)
            counts[OK[i]]++;
    } else {
        for (i = 0; i < nout; i++) {
            const int64_t T = ((OK[i] >> 56) & 63) + 1;
            const int occ = thr[T * n4 + n4 - 1] - 1 - (int8_t)(OK[i] >> 16);  /* hi - 1 - O */
            counts[(int32_t)((OK[i] >> 32) & 0xFFFFFF) + eppf_f4_bin(thr, n4, T, occ)]++;
        }
    }
}
#else
static int eppf_f123q_avx512(int m, const int32_t *ii, const int32_t *jj, double scale, int n1, int n2, int n3,
                             int n4, double f1_density, const double *cos2, const double *cos3, const double *pn,
                             const int32_t *thr, const int64_t *states, int64_t *QP, int64_t *QI, int64_t *QM,
                             int *nq_out, int32_t *counts)
{
    (void)states; (void)m; (void)ii; (void)jj; (void)scale; (void)n1; (void)n2; (void)n3; (void)n4; (void)f1_density;
    (void)cos2; (void)cos3; (void)pn; (void)thr; (void)QP; (void)QI; (void)QM; (void)counts;
    *nq_out = 0;
    return 0;
}

static void eppf_f4_walkq_avx512(int nq, const int64_t *QP, const int64_t *QI, const int64_t *QM,
                                 const uint64_t *code, int64_t g, const int32_t *thr, int n4, int64_t *lanes,
                                 int drain, int32_t *counts)
{
    (void)nq; (void)QP; (void)QI; (void)QM; (void)code; (void)g; (void)thr; (void)n4; (void)lanes;
    (void)drain; (void)counts;
}
#endif

#endif /* EPPF_WALK_H */
