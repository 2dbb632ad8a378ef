/* ESF's per-triplet work for grids up to 64 voxels, in batches.
 *
 * Used by _esf_fast.pyx, which draws the candidate triplets with the
 * shared per-object generator and hands them over ESF_BATCH at a time. Each
 * batch goes through separate loops (geometry of every candidate, then the
 * accepted ones in draw order, their line set-up, the line walks, the
 * histogram updates), so the latencies of one triplet's square roots,
 * divisions and voxel walks overlap with its neighbors' instead of stalling
 * one after the other. The output is the same as a triplet-by-triplet loop.
 *
 * The occupancy grid is kept three times, once with each axis as the outer
 * index u of a 64-bit word index 64 * u + v (the bit in the word being the
 * third axis w): layout m = 0 has (u, v, w) = (x, y, z), m = 1 (y, x, z),
 * m = 2 (z, x, y). A line is walked in the layout whose u is its dominant
 * axis, which steps by exactly one voxel per step, so the word index needs
 * only one fixed-point field: position = 4096 m + 64 u + v in a 36-bit lane
 * and w in a 28-bit lane of one 64-bit integer, both with ESF_FRAC fraction
 * bits. A step is one 64-bit addition; a voxel test is two shifts, a load, a
 * variable shift and an AND.
 *
 * PCL's lci visits, after k steps of a line of dominant length L >= 2, the
 * offset floor((2 D k + L - 1) / (2 L)) from the start on an axis of length
 * D, for k = 0 .. L - 1 (the end voxel is not visited). With S = 2**ESF_FRAC
 * and R = floor(S / L), the lane value start + k D R with
 * start = (L - 1) floor(R / 2) + L**2 + 2 lies in (X, X + L**2 + 2] units,
 * X = S (2 D k + L - 1) / (2 L) the exact value (the truncation of R loses
 * less than k D (L - 1) / L <= (L - 1)**2 units, the start gains at least
 * L**2 - L + 3). A non-integer X / S is at least S / (2 L) units below the
 * next integer, so the floor is exact while 2 L**3 + 4 L < S (L <= 63 needs
 * S > 500346: ESF_FRAC = 22 is ample). A negative direction uses
 * S (a + 1) - start - k D R, whose floor is a - floor(X / S) because the
 * positive-direction value never equals X. The walk is checked against a
 * plain Bresenham loop for every L, D and sign by the tests.
 *
 * Where the CPU has AVX2 and BMI2 (checked at run time; esf_const.simd),
 * esf_take runs a copy of its body compiled for them (esf_take_avx2: four
 * doubles per vector for the square roots and divisions) and walks a
 * batch's lines four at a time (esf_walk_lines_avx2), and the D2/D3 values
 * are binned four at a time (esf_block_bins_avx2). Only integer steps and
 * plain IEEE operations are involved (no FMA), so the descriptor is
 * bit-identical either way; the tests compare both paths.
 */
#ifndef EPPF_ESF_KERNEL_H
#define EPPF_ESF_KERNEL_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "../utils/_cpu.h"

#if EPPF_CPU_CHECKS  /* (gcc or clang on x86-64, EPPF_NO_SIMD not defined: _cpu.h) */
#define ESF_SIMD 1
#include <immintrin.h>
#else
#define ESF_SIMD 0
#endif

#define ESF_BATCH 64
#define ESF_FRAC 22
#define ESF_WLANE (ESF_FRAC + 6)               /* w: 6 integer bits + fraction */
#define ESF_WORD_SHIFT (ESF_WLANE + ESF_FRAC)  /* word index: the top 14 bits */
#define ESF_LAYOUT_WORDS 4096                  /* 64 * 64 words per layout */
/* x where the mask is all ones, y where it is zero */
#define ESF_SEL(mask, x, y) ((y) ^ (((x) ^ (y)) & (mask)))

typedef struct {
    int n_bins;
    int grid;
    double area_eps;
    const double *edges;   /* A3 bin edges on the cosine scale (padded) */
    const int32_t *lut;    /* A3 bin lower bounds over u = sin(angle / 2) */
    double lut_scale;
    int lut_on_cos;        /* table over c (1) or over sin(angle / 2) (0) */
    const int32_t *rs;     /* rs[L] = floor(2**ESF_FRAC / L), rs[0] = 0 (L <= 64) */
    const int32_t *st;     /* st[L] = (L - 1) floor(rs[L] / 2) + L**2 + 2 */
    const int16_t *ratio_bin; /* [64 * cnt + occ]: bin of occ / cnt, cnt < 64 */
    int simd;              /* run the AVX2 kernels (esf_take_avx2, esf_walk_lines_avx2) */
} esf_const;

typedef struct {
    const double *pts;     /* centered, scaled points (3 n) */
    const int32_t *cells;  /* their voxels (3 n) */
    const uint64_t *g3;    /* the three grid layouts, 3 * 4096 words */
    int64_t *acc;          /* 19 * n_bins integer counts (A3: in 32nds): the
                            * ten histograms, then three more copies of the
                            * ratio one and two more of the three A3 ones */
    double *out;           /* 10 * n_bins, the result */
    double *d2v;           /* 3 n_triplets side lengths */
    double *d3v;           /* n_triplets sqrt(area) */
    int8_t *cls2;          /* line classes of the sides */
    int8_t *cls3;          /* classes of the triangles */
    double maxd2, maxd3;
    int64_t attempts, max_attempts;
    int t, n_triplets;
} esf_state;

enum { ESF_IN = 0, ESF_OUT = 1, ESF_MIX = 2 };

/* Layout m: axis roles (u, v, w). */
static const int esf_vax[3] = {1, 0, 0};
static const int esf_wax[3] = {2, 2, 1};

/* Fill the three layouts from the voxels of the points and their 26
 * neighbors (PCL's voxelize9). */
static void esf_fill_layouts(const int32_t *cells, int64_t n, int grid, uint64_t *g3)
{
    int64_t i;
    int x, y, z;
    memset(g3, 0, 3 * ESF_LAYOUT_WORDS * sizeof(uint64_t));
    for (i = 0; i < n; i++) {
        const int32_t *c = cells + 3 * i;
        int x0 = c[0] > 0 ? c[0] - 1 : 0, x1 = c[0] + 1 < grid ? c[0] + 1 : grid - 1;
        int y0 = c[1] > 0 ? c[1] - 1 : 0, y1 = c[1] + 1 < grid ? c[1] + 1 : grid - 1;
        int z0 = c[2] > 0 ? c[2] - 1 : 0, z1 = c[2] + 1 < grid ? c[2] + 1 : grid - 1;
        /* layout 0: word 64 x + y, bit z: the z run is one mask */
        uint64_t zmask = ((~(uint64_t)0) >> (63 - (z1 - z0))) << z0;
        for (x = x0; x <= x1; x++)
            for (y = y0; y <= y1; y++) {
                g3[64 * x + y] |= zmask;
                g3[ESF_LAYOUT_WORDS + 64 * y + x] |= zmask;
            }
        /* layout 2: word 64 z + x, bit y */
        {
            uint64_t ymask = ((~(uint64_t)0) >> (63 - (y1 - y0))) << y0;
            for (z = z0; z <= z1; z++)
                for (x = x0; x <= x1; x++)
                    g3[2 * ESF_LAYOUT_WORDS + 64 * z + x] |= ymask;
        }
    }
}

/* Packed start and increment of the line from voxel a towards voxel b,
 * without data-dependent branches or indexed loads but the two tables
 * (rs[L] = floor(S / L), st[L] = (L - 1) floor(rs[L] / 2) + L**2 + 2), in
 * 32-bit integers up to the packing (every intermediate is below 2**30), so
 * that a loop over lines vectorizes. Returns the number of voxels PCL
 * visits, max(L, 1). L = 1 and L = 0 come out right from the same formulas
 * (one step from the start voxel). */
static inline int esf_line_setup(int32_t a0, int32_t a1, int32_t a2, int32_t b0, int32_t b1,
                                 int32_t b2, const int32_t *rs, const int32_t *st,
                                 uint64_t *pos_out, uint64_t *inc_out)
{
    int32_t d0 = b0 - a0, d1 = b1 - a1, d2 = b2 - a2;
    int32_t n0 = d0 >> 31, n1 = d1 >> 31, n2 = d2 >> 31; /* -1 when negative */
    int32_t ad0 = (d0 ^ n0) - n0, ad1 = (d1 ^ n1) - n1, ad2 = (d2 ^ n2) - n2;
    /* dominant axis m, the first one on ties (as PCL); layout m's (u, v, w)
     * are (x, y, z), (y, x, z), (z, x, y). Selections by masks (all ones
     * or zero), which the compiler cannot turn into unpredictable jumps. */
    int32_t m1 = -(int32_t)((ad1 > ad0) & (ad1 >= ad2)), m2 = -(int32_t)((ad2 > ad0) & (ad2 > ad1));
    int32_t m12 = m1 | m2;
    int32_t L = ESF_SEL(m2, ad2, ESF_SEL(m1, ad1, ad0));
    int32_t R = rs[L], start = st[L], flip = ((int32_t)1 << ESF_FRAC) - 2 * start;
    /* each axis as a minor one: S a + start, or S (a + 1) - start when
     * negative; increment d R */
    int32_t l0 = (a0 << ESF_FRAC) + start + (n0 & flip);
    int32_t l1 = (a1 << ESF_FRAC) + start + (n1 & flip);
    int32_t l2 = (a2 << ESF_FRAC) + start + (n2 & flip);
    /* the dominant one exactly: 64 u in the word index, 64 per step */
    int32_t au = ESF_SEL(m2, a2, ESF_SEL(m1, a1, a0));
    int32_t nu = ESF_SEL(m2, n2, ESF_SEL(m1, n1, n0));
    int32_t word = ((m1 & 1) + (m2 & 2)) * ESF_LAYOUT_WORDS + 64 * au;
    int32_t iu = (((int32_t)64 << ESF_FRAC) ^ nu) - nu;
    int32_t pv = ESF_SEL(m12, l0, l1), iv = ESF_SEL(m12, d0, d1) * R;
    int32_t pw = ESF_SEL(m2, l1, l2), iw = ESF_SEL(m2, d1, d2) * R;
    *pos_out = ((uint64_t)(((int64_t)word << ESF_FRAC) + pv) << ESF_WLANE) + (uint64_t)(int64_t)pw;
    *inc_out = ((uint64_t)((int64_t)iu + iv) << ESF_WLANE) + (uint64_t)(int64_t)iw;
    return L + (L == 0);
}

/* esf_line_setup over n lines given as coordinate arrays. (An AVX2 clone of
 * this loop, vectorized with gathers for the two tables, was slower here.) */
static void esf_setup_lines(int n, const int32_t *ax, const int32_t *ay, const int32_t *az,
                            const int32_t *bx, const int32_t *by, const int32_t *bz,
                            const int32_t *rs, const int32_t *st, uint64_t *pos, uint64_t *inc,
                            int *cnt)
{
    int q;
    for (q = 0; q < n; q++)
        cnt[q] = esf_line_setup(ax[q], ay[q], az[q], bx[q], by[q], bz[q], rs, st, &pos[q], &inc[q]);
}

/* Occupied voxels among the n >= 0 steps of a packed line. */
static inline int esf_walk(const uint64_t *g3, uint64_t pos, uint64_t inc, int n)
{
    int occ = 0;
    uint64_t end = pos + (uint64_t)n * inc;
    while (pos != end) {
        occ += (int)((g3[pos >> ESF_WORD_SHIFT] >> ((pos >> ESF_FRAC) & 63)) & 1);
        pos += inc;
    }
    return occ;
}

/* Whether the CPU runs the AVX2 kernels (esf_walk_lines_avx2,
 * esf_take_avx2). (An AVX-512 walk with eight lanes was slower than the AVX2
 * one on AMD Zen 4, whose 512-bit gathers are slow.) */
static int esf_has_avx2(void)
{
    return eppf_cpu_has(EPPF_CPU_AVX2 | EPPF_CPU_BMI2);
}

/* occ[q] = esf_walk(g3, pos[q], inc[q], cnt[q]) for q < n, one line after
 * the other. */
static void esf_walk_lines(const uint64_t *g3, const uint64_t *pos, const uint64_t *inc, const int *cnt,
                           int *occ, int n)
{
    int q;
    for (q = 0; q < n; q++)
        occ[q] = esf_walk(g3, pos[q], inc[q], cnt[q]);
}

#if ESF_SIMD
/* The same counts, four lines at a time in the lanes of AVX2 vectors (the
 * four grid words of a step come from four scalar loads: AVX2-only AMD CPUs
 * run gathers as slow microcode, and on a Zen 2 the loads made ESF 7-9%
 * faster; the masked tail keeps a masked gather). The lines are first ordered
 * by their number of steps (a counting sort; 0 <= cnt <= 64), so the four
 * lanes of a group need similar numbers of steps: all four walk the
 * group's smallest count without a test, then the lanes still running walk
 * on with a masked gather while the others add zero. The integer steps are
 * those of esf_walk, so the counts are identical; n <= 3 * ESF_BATCH. */
__attribute__((target("avx2")))
static void esf_walk_lines_avx2(const uint64_t *g3, const uint64_t *pos, const uint64_t *inc, const int *cnt,
                                int *occ, int n)
{
    int first[66], order[3 * ESF_BATCH + 3], q, g, k, c;
    const __m256i m63 = _mm256_set1_epi64x(63), one = _mm256_set1_epi64x(1), zero = _mm256_setzero_si256();
    memset(first, 0, sizeof(first));
    for (q = 0; q < n; q++)
        first[cnt[q] + 1]++;
    for (c = 1; c < 66; c++)
        first[c] += first[c - 1];
    for (q = 0; q < n; q++)
        order[first[cnt[q]]++] = q;
    for (g = 0; g < n; g += 4) {
        int lanes = n - g < 4 ? n - g : 4, l[4], lo, hi;
        __m256i p, d, steps, sum = zero;
        int64_t out[4];
        for (k = 0; k < 4; k++)
            l[k] = order[g + (k < lanes ? k : 0)];
        p = _mm256_set_epi64x((int64_t)pos[l[3]], (int64_t)pos[l[2]], (int64_t)pos[l[1]], (int64_t)pos[l[0]]);
        d = _mm256_set_epi64x((int64_t)inc[l[3]], (int64_t)inc[l[2]], (int64_t)inc[l[1]], (int64_t)inc[l[0]]);
        /* absent lanes (a short last group) repeat lane 0 with no steps */
        steps = _mm256_set_epi64x(lanes > 3 ? cnt[l[3]] : 0, lanes > 2 ? cnt[l[2]] : 0,
                                  lanes > 1 ? cnt[l[1]] : 0, cnt[l[0]]);
        lo = lanes == 4 ? cnt[l[0]] : 0;
        hi = cnt[l[lanes - 1]];
        for (k = 0; k < lo; k++) {
            int64_t ix[4] __attribute__((aligned(32)));
            __m256i w, b;
            _mm256_store_si256((__m256i *)ix, _mm256_srli_epi64(p, ESF_WORD_SHIFT));
            w = _mm256_set_epi64x((int64_t)g3[ix[3]], (int64_t)g3[ix[2]], (int64_t)g3[ix[1]], (int64_t)g3[ix[0]]);
            b = _mm256_and_si256(_mm256_srli_epi64(p, ESF_FRAC), m63);
            sum = _mm256_add_epi64(sum, _mm256_and_si256(_mm256_srlv_epi64(w, b), one));
            p = _mm256_add_epi64(p, d);
        }
        for (; k < hi; k++) {
            __m256i live = _mm256_cmpgt_epi64(steps, _mm256_set1_epi64x(k));
            __m256i w = _mm256_mask_i64gather_epi64(zero, (const long long *)g3,
                                                    _mm256_srli_epi64(p, ESF_WORD_SHIFT), live, 8);
            __m256i b = _mm256_and_si256(_mm256_srli_epi64(p, ESF_FRAC), m63);
            sum = _mm256_add_epi64(sum, _mm256_and_si256(_mm256_srlv_epi64(w, b), one));
            p = _mm256_add_epi64(p, d);
        }
        _mm256_storeu_si256((__m256i *)out, sum);
        for (k = 0; k < lanes; k++)
            occ[l[k]] = (int)out[k];
    }
}

#else
static void esf_walk_lines_avx2(const uint64_t *g3, const uint64_t *pos, const uint64_t *inc, const int *cnt,
                                int *occ, int n)
{
    esf_walk_lines(g3, pos, inc, cnt, occ, n);
}
#endif

/* The line walks of a batch of n <= 3 * ESF_BATCH lines, in AVX2 lanes when
 * simd (the counts are the same either way). */
static void esf_walk_batch(const uint64_t *g3, const uint64_t *pos, const uint64_t *inc, const int *cnt, int *occ,
                           int n, int simd)
{
    if (simd)
        esf_walk_lines_avx2(g3, pos, inc, cnt, occ, n);
    else
        esf_walk_lines(g3, pos, inc, cnt, occ, n);
}

/* |cos| = x clipped to [0, 1] for any double x, as ``esf_angle_bin`` needs
 * it: NaN (from a repeated point) and values from 1 up give 1, negative ones
 * 0 (none of the kernel's: |dot| / (|u| |v|) is never negative; the clip
 * keeps the bound for every input, not only the kernel's). */
static inline double esf_clip_cos(double x)
{
    x = x < 1.0 ? x : 1.0;
    return x >= 0.0 ? x : 0.0;
}

/* round((n_bins - 1) arccos(c) / (pi / 2)) for c in [0, 1] without arccos:
 * the number of bin edges (cosines, decreasing, padded with -2) not below c.
 * The table gives, per cell of its argument, a lower bound that is at most
 * one short (no cell holds two edges); one comparison completes it. The
 * argument is c itself when the cells can be that fine (coarse bins), else
 * u = sqrt((1 - c) / 2) = sin(angle / 2).
 *
 * c must lie in [0, 1] (never NaN), which bounds the table index: the caller
 * clips it there (``esf_clip_cos``) in its vectorized loop, where the clip
 * costs next to nothing, rather than here, once per look-up. */
static inline int esf_angle_bin(double c, int on_cos, const int32_t *lut, double lut_scale,
                                const double *edges)
{
    double arg;
    int lo;
    arg = on_cos ? c : sqrt((1.0 - c) * 0.5);
    lo = lut[(int)(arg * lut_scale)];
    lo += edges[lo] >= c;
    return lo;
}

/* Clamped in floating point before the conversion: NaN gives 0, +inf and
 * huge values n_bins - 1. */
static inline int esf_round_bin(double v, int n_bins)
{
    double x = v * (n_bins - 1) + 0.5;
    if (!(x > 0.0))
        return 0;
    if (x >= n_bins)
        return n_bins - 1;
    return (int)x;
}

/* esf_round_bin(v / vmax, n_bins) with a multiplication by
 * scale = (n_bins - 1) / vmax instead of a division; the rare values within
 * 1e-9 of a bin boundary (where the two could round differently) take the
 * division. */
static inline int esf_scaled_bin(double v, double vmax, double scale, int n_bins)
{
    double x = v * scale + 0.5;
    int i;
    if (!(x > 0.0))  /* NaN too, before the conversion */
        return 0;
    if (x >= n_bins) /* (the division would clip to the top bin as well) */
        return n_bins - 1;
    i = (int)x;
    if (x - i < 1e-9 || i + 1 - x < 1e-9)
        return esf_round_bin(v / vmax, n_bins);
    return i;
}

/* ratio_bin[64 * c + o] = esf_round_bin(o / c, n_bins) for 1 <= c < 64, o <= c. */
static void esf_fill_ratio_bins(int n_bins, int16_t *ratio_bin)
{
    int c, o;
    for (c = 0; c < 64; c++)
        for (o = 0; o < 64; o++)
            ratio_bin[64 * c + o] = (int16_t)(c > 0 && o <= c ? esf_round_bin((double)o / (double)c, n_bins) : 0);
}

/* bin[i] = esf_scaled_bin(v[i], vmax, scale, n_bins) for i < m, except that
 * values near a rounding boundary get the multiplication's bin; returns
 * whether there was any (the caller then redoes the block with
 * esf_scaled_bin). Each value is clamped to [0, n_bins] before the
 * conversion (NaN to 0); a value clamped to an end is an integer, so it
 * counts as near too and esf_scaled_bin's clamps decide. */
static inline int esf_block_bins(const double *v, int64_t m, double scale, int n_bins, int32_t *bin)
{
    int64_t i;
    int near = 0;
    const double top = (double)n_bins;
    for (i = 0; i < m; i++) {
        double x = v[i] * scale + 0.5, f;
        int32_t k;
        x = x > 0.0 ? x : 0.0;
        x = x < top ? x : top;
        k = (int32_t)x;
        f = x - (double)k;
        near |= (f < 1e-9) | (1.0 - f < 1e-9);
        k = k < n_bins - 1 ? k : n_bins - 1;
        bin[i] = k;
    }
    return near;
}

#if ESF_SIMD
/* esf_block_bins four values at a time: the same IEEE operations (max and
 * min give the clamps' results, NaN included: they return their second
 * operand when the first is NaN), so the same bins and the same answer. (The
 * compiler does not vectorize the plain loop: the clamps are branches to
 * it.) */
__attribute__((target("avx2")))
static int esf_block_bins_avx2(const double *v, int64_t m, double scale, int n_bins, int32_t *bin)
{
    const __m256d vs = _mm256_set1_pd(scale), half = _mm256_set1_pd(0.5), zero = _mm256_setzero_pd(),
                  top = _mm256_set1_pd((double)n_bins), eps = _mm256_set1_pd(1e-9), one = _mm256_set1_pd(1.0);
    const __m128i kmax = _mm_set1_epi32(n_bins - 1);
    __m256d near = _mm256_setzero_pd();
    int64_t i;
    for (i = 0; i + 4 <= m; i += 4) {
        __m256d x = _mm256_add_pd(_mm256_mul_pd(_mm256_loadu_pd(v + i), vs), half), f;
        __m128i k;
        x = _mm256_min_pd(_mm256_max_pd(x, zero), top);
        k = _mm256_cvttpd_epi32(x);
        f = _mm256_sub_pd(x, _mm256_cvtepi32_pd(k));
        near = _mm256_or_pd(near, _mm256_or_pd(_mm256_cmp_pd(f, eps, _CMP_LT_OQ),
                                               _mm256_cmp_pd(_mm256_sub_pd(one, f), eps, _CMP_LT_OQ)));
        _mm_storeu_si128((__m128i *)(bin + i), _mm_min_epi32(k, kmax));
    }
    return (_mm256_movemask_pd(near) != 0) | esf_block_bins(v + i, m - i, scale, n_bins, bin + i);
}
#else
#define esf_block_bins_avx2 esf_block_bins
#endif

/* acc[cls[i] * n_bins + esf_scaled_bin(v[i], vmax, scale, n_bins)] += 1 for
 * i < n, in blocks: the bins of a block first, without branches (with AVX2
 * when simd), the values near a rounding boundary (which take
 * esf_scaled_bin's division) redone one by one, then the counts. The values
 * are lengths, never negative. */
static void esf_count_scaled(const double *v, const int8_t *cls, int64_t n, double vmax, double scale, int n_bins,
                             int64_t *acc, int simd)
{
    enum { BLOCK = 256 };
    int32_t bin[BLOCK];
    int64_t b, i, m;
    for (b = 0; b < n; b += BLOCK) {
        int near;
        m = n - b < BLOCK ? n - b : BLOCK;
        near = simd ? esf_block_bins_avx2(v + b, m, scale, n_bins, bin) : esf_block_bins(v + b, m, scale, n_bins, bin);
        if (near)
            for (i = 0; i < m; i++)
                bin[i] = esf_scaled_bin(v[b + i], vmax, scale, n_bins);
        for (i = 0; i < m; i++)
            acc[cls[b + i] * n_bins + bin[i]] += 1;
    }
}

/* D3 and D2 histograms from the stored values, then weights and division by
 * the sum into out; simd: bin with esf_block_bins_avx2. */
static void esf_finish(const esf_state *s, int n_bins, int simd)
{
    static const double weights[10] = {0.5, 0.5, 0.5, 0.5, 0.5, 1.0, 0.5, 2.0, 2.0, 1.0};
    int64_t *acc = s->acc;
    double *out = s->out, total = 0.0, inv, sc3 = (n_bins - 1) / s->maxd3,
           sc2 = (n_bins - 1) / s->maxd2;
    int64_t i;
    int h;
    const int8_t *cls2 = s->cls2, *cls3 = s->cls3;
    const double *d2v = s->d2v, *d3v = s->d3v, maxd2 = s->maxd2, maxd3 = s->maxd3;
    const int64_t n_triplets = s->n_triplets;
    esf_count_scaled(d3v, cls3, n_triplets, maxd3, sc3, n_bins, acc + 3 * n_bins, simd);
    esf_count_scaled(d2v, cls2, 3 * n_triplets, maxd2, sc2, n_bins, acc + 6 * n_bins, simd);
    for (i = 0; i < n_bins; i++)
        acc[9 * n_bins + i] += acc[10 * n_bins + i] + acc[11 * n_bins + i] + acc[12 * n_bins + i];
    for (i = 0; i < 3 * n_bins; i++)
        acc[i] += acc[13 * n_bins + i] + acc[16 * n_bins + i];
    for (h = 0; h < 10; h++)
        for (i = 0; i < n_bins; i++) {
            /* A3 sums are multiples of 1/32: exact in either order */
            out[h * n_bins + i] = (h < 3 ? (double)acc[h * n_bins + i] / 32.0 : (double)acc[h * n_bins + i]) * weights[h];
            total += out[h * n_bins + i];
        }
    inv = 1.0 / total;
    for (i = 0; i < 10 * n_bins; i++)
        out[i] *= inv;
}

/* Squared sides A = |p2 - p1|^2, B = |p3 - p1|^2, C = |p2 - p3|^2 and
 * absolute dot products c1 = |v21 . v31|, c2 = |v23 . v31|, c3 = |v23 . v21|
 * of the candidates' triangles (p1, p2, p3 = points i1[j], i2[j], i3[j]),
 * sums from x to z. */
static inline void esf_sides(const double *pts, const uint32_t *i1, const uint32_t *i2, const uint32_t *i3,
                             int n, double *A, double *B, double *C, double *c1, double *c2, double *c3)
{
    int j;
    for (j = 0; j < n; j++) {
        const double *p1 = pts + 3 * (int64_t)i1[j], *p2 = pts + 3 * (int64_t)i2[j],
                     *p3 = pts + 3 * (int64_t)i3[j];
        double v21x = p2[0] - p1[0], v21y = p2[1] - p1[1], v21z = p2[2] - p1[2];
        double v31x = p3[0] - p1[0], v31y = p3[1] - p1[1], v31z = p3[2] - p1[2];
        double v23x = p2[0] - p3[0], v23y = p2[1] - p3[1], v23z = p2[2] - p3[2];
        A[j] = v21x * v21x + v21y * v21y + v21z * v21z;
        B[j] = v31x * v31x + v31y * v31y + v31z * v31z;
        C[j] = v23x * v23x + v23y * v23y + v23z * v23z;
        c1[j] = fabs(v21x * v31x + v21y * v31y + v21z * v31z);
        c2[j] = fabs(v23x * v31x + v23y * v31y + v23z * v31z);
        c3[j] = fabs(v23x * v21x + v23y * v21y + v23z * v21z);
    }
}

#if ESF_SIMD
/* The x, y and z of the points i[0..3] as three vectors: each point's three
 * doubles by one masked load (nothing read past them), then a 4x4
 * transpose; AVX2-only AMD CPUs run gathers as slow microcode. */
__attribute__((target("avx2")))
static inline void esf_load_xyz4(const double *pts, const uint32_t *i, __m256d *x, __m256d *y, __m256d *z)
{
    const __m256i m = _mm256_set_epi64x(0, -1, -1, -1);
    __m256d r0 = _mm256_maskload_pd(pts + 3 * (size_t)i[0], m), r1 = _mm256_maskload_pd(pts + 3 * (size_t)i[1], m);
    __m256d r2 = _mm256_maskload_pd(pts + 3 * (size_t)i[2], m), r3 = _mm256_maskload_pd(pts + 3 * (size_t)i[3], m);
    __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1); /* x0 x1 z0 z1, y0 y1 0 0 */
    __m256d t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3); /* x2 x3 z2 z3, y2 y3 0 0 */
    *x = _mm256_permute2f128_pd(t0, t2, 0x20);
    *y = _mm256_permute2f128_pd(t1, t3, 0x20);
    *z = _mm256_permute2f128_pd(t0, t2, 0x31);
}

/* esf_sides four candidates at a time (loads of the coordinates; the same
 * subtractions, products and sums in the same order, so the same values;
 * |x| by clearing the sign bit, as fabs). */
__attribute__((target("avx2")))
static void esf_sides_avx2(const double *pts, const uint32_t *i1, const uint32_t *i2, const uint32_t *i3,
                           int n, double *A, double *B, double *C, double *c1, double *c2, double *c3)
{
    const __m256d sign = _mm256_set1_pd(-0.0);
    int j;
    for (j = 0; j + 4 <= n; j += 4) {
        __m256d x1, x2, x3, y1, y2, y3, z1, z2, z3;
        esf_load_xyz4(pts, i1 + j, &x1, &y1, &z1);
        esf_load_xyz4(pts, i2 + j, &x2, &y2, &z2);
        esf_load_xyz4(pts, i3 + j, &x3, &y3, &z3);
        {
            __m256d v21x = _mm256_sub_pd(x2, x1), v21y = _mm256_sub_pd(y2, y1), v21z = _mm256_sub_pd(z2, z1);
            __m256d v31x = _mm256_sub_pd(x3, x1), v31y = _mm256_sub_pd(y3, y1), v31z = _mm256_sub_pd(z3, z1);
            __m256d v23x = _mm256_sub_pd(x2, x3), v23y = _mm256_sub_pd(y2, y3), v23z = _mm256_sub_pd(z2, z3);
#define ESF_DOT(ax, ay, az, bx, by, bz) \
    _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ax, bx), _mm256_mul_pd(ay, by)), _mm256_mul_pd(az, bz))
            _mm256_storeu_pd(A + j, ESF_DOT(v21x, v21y, v21z, v21x, v21y, v21z));
            _mm256_storeu_pd(B + j, ESF_DOT(v31x, v31y, v31z, v31x, v31y, v31z));
            _mm256_storeu_pd(C + j, ESF_DOT(v23x, v23y, v23z, v23x, v23y, v23z));
            _mm256_storeu_pd(c1 + j, _mm256_andnot_pd(sign, ESF_DOT(v21x, v21y, v21z, v31x, v31y, v31z)));
            _mm256_storeu_pd(c2 + j, _mm256_andnot_pd(sign, ESF_DOT(v23x, v23y, v23z, v31x, v31y, v31z)));
            _mm256_storeu_pd(c3 + j, _mm256_andnot_pd(sign, ESF_DOT(v23x, v23y, v23z, v21x, v21y, v21z)));
#undef ESF_DOT
        }
    }
    esf_sides(pts, i1 + j, i2 + j, i3 + j, n - j, A + j, B + j, C + j, c1 + j, c2 + j, c3 + j);
}
#else
#define esf_sides_avx2 esf_sides
#endif

/* esf_take's body, compiled once per target below. */
static inline __attribute__((always_inline)) int
esf_take_impl(const esf_const *k, esf_state *s, const uint32_t *i1, const uint32_t *i2, const uint32_t *i3,
              int n_cand, int simd)
{
    double A[ESF_BATCH], B[ESF_BATCH], C[ESF_BATCH], H[ESF_BATCH], D3[ESF_BATCH];
    double c1[ESF_BATCH], c2[ESF_BATCH], c3[ESF_BATCH];
    int sel[ESF_BATCH];
    uint64_t pos[3 * ESF_BATCH], inc[3 * ESF_BATCH];
    int cnt[3 * ESF_BATCH], occ[3 * ESF_BATCH], steps[3 * ESF_BATCH], known[3 * ESF_BATCH];
    int32_t ax[3 * ESF_BATCH], ay[3 * ESF_BATCH], az[3 * ESF_BATCH];
    int32_t bx[3 * ESF_BATCH], by[3 * ESF_BATCH], bz[3 * ESF_BATCH];
    const double *pts = s->pts;
    const int n_bins = k->n_bins;
    int j, q, nsel = 0, fail = 0;
    /* squared sides and dot products of every candidate (gathers) ... */
    if (simd)
        esf_sides_avx2(pts, i1, i2, i3, n_cand, A, B, C, c1, c2, c3);
    else
        esf_sides(pts, i1, i2, i3, n_cand, A, B, C, c1, c2, c3);
    /* ... then the square roots and divisions, element-wise (vectorized) */
    for (j = 0; j < n_cand; j++) {
        double a = sqrt(A[j]), b = sqrt(B[j]), c = sqrt(C[j]);
        double hs = (a + b + c) * 0.5;
        A[j] = a;
        B[j] = b;
        C[j] = c;
        H[j] = hs * (hs - a) * (hs - b) * (hs - c);
        D3[j] = sqrt(sqrt(H[j])); /* NaN for a rejected candidate, unused */
        c1[j] = esf_clip_cos(c1[j] / (a * b));
        c2[j] = esf_clip_cos(c2[j] / (c * b));
        c3[j] = esf_clip_cos(c3[j] / (c * a));
    }
    /* the accepted ones, in draw order */
    for (j = 0; j < n_cand && s->t + nsel < s->n_triplets; j++) {
        s->attempts++;
        if (s->attempts > s->max_attempts) {
            fail = 1;
            break;
        }
        if (i1[j] != i2[j] && i1[j] != i3[j] && i2[j] != i3[j] && H[j] > k->area_eps)
            sel[nsel++] = j;
    }
    /* line set-up: sides 12, 13, 23 */
    for (q = 0; q < nsel; q++) {
        const int32_t *cl = s->cells;
        int64_t e1 = 3 * (int64_t)i1[sel[q]], e2 = 3 * (int64_t)i2[sel[q]], e3 = 3 * (int64_t)i3[sel[q]];
        ax[3 * q] = cl[e1]; ay[3 * q] = cl[e1 + 1]; az[3 * q] = cl[e1 + 2];
        bx[3 * q] = cl[e2]; by[3 * q] = cl[e2 + 1]; bz[3 * q] = cl[e2 + 2];
        ax[3 * q + 1] = cl[e1]; ay[3 * q + 1] = cl[e1 + 1]; az[3 * q + 1] = cl[e1 + 2];
        bx[3 * q + 1] = cl[e3]; by[3 * q + 1] = cl[e3 + 1]; bz[3 * q + 1] = cl[e3 + 2];
        ax[3 * q + 2] = cl[e2]; ay[3 * q + 2] = cl[e2 + 1]; az[3 * q + 2] = cl[e2 + 2];
        bx[3 * q + 2] = cl[e3]; by[3 * q + 2] = cl[e3 + 1]; bz[3 * q + 2] = cl[e3 + 2];
    }
    esf_setup_lines(3 * nsel, ax, ay, az, bx, by, bz, k->rs, k->st, pos, inc, cnt);
    /* A line's ends are voxels of points, whose 3x3x3 neighborhoods are all
     * occupied: so are its first two voxels and its last (all within one
     * voxel of an end, see esf_line_setup). Only the others are walked. */
    for (q = 0; q < 3 * nsel; q++) {
        known[q] = cnt[q] < 3 ? cnt[q] : 3;
        steps[q] = cnt[q] - known[q];
        pos[q] += 2 * inc[q];
    }
    esf_walk_batch(s->g3, pos, inc, steps, occ, 3 * nsel, k->simd);
    for (q = 0; q < 3 * nsel; q++)
        occ[q] += known[q];
    /* histograms, in integers (A3 in 32nds of a voxel), without branches;
     * the state's fields in locals (the int8 stores could alias them) */
    {
        int64_t *acc = s->acc;
        const int16_t *ratio_bin = k->ratio_bin;
        const int32_t *lut = k->lut;
        const double *edges = k->edges, lut_scale = k->lut_scale;
        const int on_cos = k->lut_on_cos;
        int8_t *cls2 = s->cls2, *cls3 = s->cls3;
        double *d2v = s->d2v, *d3v = s->d3v, maxd2 = s->maxd2, maxd3 = s->maxd3;
        int t = s->t;
        for (q = 0; q < nsel; q++, t++) {
            int l, cls, in_sum, n_sum, h, o, c;
            j = sel[q];
            for (l = 0; l < 3; l++) {
                o = occ[3 * q + l];
                c = cnt[3 * q + l];
                /* in: at most one empty voxel; out: at most 7 occupied; else mixed */
                cls = (o < c - 1) * (2 - (o <= 7));
                /* one copy of the ratio histogram per side: no chains of
                 * read-modify-writes on one bin */
                acc[(10 + l) * n_bins + ratio_bin[c * 64 + o]] += cls == ESF_MIX;
                cls2[3 * t + l] = (int8_t)cls;
            }
            d2v[3 * t] = A[j];
            d2v[3 * t + 1] = B[j];
            d2v[3 * t + 2] = C[j];
            d3v[t] = D3[j];
            in_sum = occ[3 * q] + occ[3 * q + 1] + occ[3 * q + 2];
            n_sum = cnt[3 * q] + cnt[3 * q + 1] + cnt[3 * q + 2];
            /* out: at most 21 occupied in all; in: fewer than 4 empty; else mixed */
            cls = in_sum <= 21 ? ESF_OUT : 2 * (n_sum - in_sum >= 4);
            cls3[t] = (int8_t)cls;
            h = cls * n_bins; /* A3 histograms 0, 1, 2 */
            acc[h + esf_angle_bin(c1[j], on_cos, lut, lut_scale, edges)] += cnt[3 * q + 2];
            acc[13 * n_bins + h + esf_angle_bin(c2[j], on_cos, lut, lut_scale, edges)] += cnt[3 * q];
            acc[16 * n_bins + h + esf_angle_bin(c3[j], on_cos, lut, lut_scale, edges)] += cnt[3 * q + 1];
            maxd2 = A[j] > maxd2 ? A[j] : maxd2;
            maxd2 = B[j] > maxd2 ? B[j] : maxd2;
            maxd2 = C[j] > maxd2 ? C[j] : maxd2;
            maxd3 = D3[j] > maxd3 ? D3[j] : maxd3;
        }
        s->maxd2 = maxd2;
        s->maxd3 = maxd3;
        s->t = t;
    }
    return fail;
}

static int esf_take_default(const esf_const *k, esf_state *s, const uint32_t *i1, const uint32_t *i2,
                            const uint32_t *i3, int n_cand)
{
    return esf_take_impl(k, s, i1, i2, i3, n_cand, 0);
}

#if ESF_SIMD
/* The same code compiled for AVX2 and BMI2: wider vectors for the square
 * roots and divisions, shifts without the count register. Plain IEEE
 * operations either way (no FMA is enabled, and the build passes
 * -ffp-contract=off), so the results are bit-identical. */
__attribute__((target("avx2,bmi,bmi2")))
static int esf_take_avx2(const esf_const *k, esf_state *s, const uint32_t *i1, const uint32_t *i2,
                         const uint32_t *i3, int n_cand)
{
    return esf_take_impl(k, s, i1, i2, i3, n_cand, 1);
}
#else
#define esf_take_avx2 esf_take_default
#endif

/* Take the candidates i1, i2, i3 (n_cand of them, in draw order): accept
 * those of three distinct points and Heron product above area_eps until
 * n_triplets are accepted. Returns 1 when the attempts run out. */
static int esf_take(const esf_const *k, esf_state *s, const uint32_t *i1, const uint32_t *i2,
                    const uint32_t *i3, int n_cand)
{
    if (k->simd)
        return esf_take_avx2(k, s, i1, i2, i3, n_cand);
    return esf_take_default(k, s, i1, i2, i3, n_cand);
}

#endif
