/* Level 3 of _eppf_walk.h: the skipping AVX-512 walk. The cone grids that
 * prove voxels empty (``eppf_code_grid``), the one pass over a batch that bins
 * f1-f3 and queues the lines (``eppf_f123q_avx512``) and the walk of the
 * queue in six sets of eight lanes (``eppf_f4_walkq_avx512``). */
#ifndef EPPF_WALK_SKIP_H
#define EPPF_WALK_SKIP_H

#include "_eppf_walk_common.h"
#include "_eppf_walk_avx512.h"
#include "_eppf_walk_port.h" /* the cone steps of the generic build */

/* Pairs per batch of the skipping walk (level 3), which needs no sorting:
   fewer, longer calls (its lanes carry over between them). */
#define EPPF_QUEUE_BATCH 1024
/* The lane state of ``eppf_f4_walkq_avx512`` between calls for one object: per
   set of eight lanes (six sets, 64 words each), three vectors of eight int64
   (words 0-23) and the mask of lanes in use (word 56). */
#define EPPF_LANES_WORDS 384
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
 * meets O_m (``eppf_port_cone_step``). ``bits``: g^2 words, one per (x, y) row,
 * z bits (none past z = g - 1); ``work``: 4 g^2 words of scratch, which may
 * be ``code + EPPF_CODE_SCRATCH`` (between the two halves); 2 <= g <= 64. */
/* Where the z >= 32 halves start: 2**16, since the skipping walk's word index
   takes z >> 5 as its upper 16-bit field. */
#define EPPF_CODE_HALF 65536
#define EPPF_CODE_WORDS (EPPF_CODE_HALF + 3 * EPPF_CODE_AXIS_WORDS)
#define EPPF_CODE_SCRATCH (3 * EPPF_CODE_AXIS_WORDS)
/* The skipping walk reads ``code`` at word indices below this bound (its
   fields masked: y + 64 (x + 64 a) + EPPF_CODE_HALF (z >> 5) with y, x < 64,
   a < 4, for any position, lanes past their line included), so the buffer
   must hold this many words (it holds the grids and the scratch). */
#define EPPF_CODE_READ_WORDS (EPPF_CODE_HALF + 4 * EPPF_CODE_AXIS_WORDS)
#if EPPF_CODE_SCRATCH + 4 * EPPF_CODE_AXIS_WORDS > EPPF_CODE_HALF || EPPF_CODE_WORDS > EPPF_CODE_READ_WORDS
#error "the cone grids' scratch must fit between their halves, the grids inside the read bound"
#endif
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
/* out = bits | D_axis(o) for g = 64 (``eppf_port_cone_step``), or its code words
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
    uint64_t *o2 = work, *a = work + EPPF_CODE_AXIS_WORDS;
    int axis;
    for (axis = 0; axis < 3; axis++) {
        eppf_cone_step64(bits, bits, o2, a, axis, NULL);
        eppf_cone_step64(bits, o2, NULL, a, axis, code + EPPF_CODE_AXIS_WORDS * axis);
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
        uint64_t *c = code + EPPF_CODE_AXIS_WORDS * axis;
        eppf_port_cone_step(bits, bits, o2, a, b, g, axis);
        eppf_port_cone_step(bits, o2, o3, a, b, g, axis);
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

#endif /* EPPF_WALK_SKIP_H */
