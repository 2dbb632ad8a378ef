/* SIMD kernels of a batch of pairs for _eppf_fast.pyx, chosen at run time,
 * one file a level (this file includes them all):
 *
 * - _eppf_walk_common.h: the packed walk's layout, the batch size, the CPU
 *   checks, the skipping walks' lane state and what the walks share;
 * - _eppf_walk_port.h, levels 0 and 1: level 3's skipping walk in portable C
 *   (the cone codes as two bit planes, built with whole-word operations; the
 *   lines of a batch walked in rounds of a few steps, several side by side,
 *   no branch on the data), which level 0 runs as it is, after its pair
 *   draws (``eppf_draw_batch``) and one pass for the coincidence check,
 *   f1-f3 and the walk setup (``eppf_f123q_port``), as level 1 does;
 * - _eppf_walk_avx2.h, level 1: AVX2, four pairs at a time: the pair draws
 *   (``eppf_draw_batch_avx2``), the f1-f3 bins with the coincidence check
 *   and the portable walk's setup in one pass (``eppf_f123q_avx2``) and its
 *   steps (``eppf_port_walk_avx2``), with no gathers (AVX2-only AMD CPUs run
 *   them slowly);
 * - _eppf_walk_avx512.h, level 2: AVX-512 (F, BW, VL, DQ and VBMI), eight
 *   pairs at a time: the pair draws (``eppf_draw_batch_avx512``), the f1-f3
 *   bins with the check for coinciding points (``eppf_f123_batch_avx512``)
 *   and the grouped f4 walk (``eppf_f4_batch_avx512``);
 * - _eppf_walk_skip.h, level 3: the same draws and the skipping walk
 *   (``eppf_f123q_avx512`` and ``eppf_f4_walkq_avx512``), which
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
 * only every fourth step (the skipping walks also freeze a line's state once
 * its bin is certain, so steps past the line's end change nothing either).
 *
 * The SIMD code is compiled with target attributes and chosen at run time
 * (``eppf_walk_has_avx2`` / ``eppf_walk_has_avx512``); other compilers and
 * CPUs use the portable code (_eppf_walk_port.h, and _eppf_fast.pyx's scalar
 * code, whose voxel-by-voxel ``_line_bin`` walks the grids above 64 at every
 * level). No floating point is involved in
 * the walks beyond the setup, which uses the same expressions as _eppf_fast.pyx.
 */
#ifndef EPPF_WALK_H
#define EPPF_WALK_H

#include "_eppf_walk_common.h"  /* layout, batch size, CPU checks, walk order */
#include "_eppf_walk_avx2.h"    /* level 1 */
#include "_eppf_walk_avx512.h"  /* level 2, and the AVX-512 parts of level 3 */
#include "_eppf_walk_skip.h"    /* level 3 */
#include "_eppf_walk_port.h"    /* levels 0 and 1: the portable skipping walk */

#if !EPPF_WALK_SIMD
#define eppf_port_walk_avx2 eppf_port_walk
#endif

/* The candidate pairs of a batch's draws at kernel level ``level`` (0 portable, 1 AVX2, 2 and 3 AVX-512):
   the same pairs at every level; out_i, out_j: room for m + 7 entries. */
static void eppf_draw_batch_at(int level, int m, uint64_t state, uint32_t n, int32_t *out_i, int32_t *out_j)
{
    if (level >= 2)
        eppf_draw_batch_avx512(m, state, n, out_i, out_j);
    else if (level == 1)
        eppf_draw_batch_avx2(m, state, n, out_i, out_j);
    else
        eppf_draw_batch(m, state, n, out_i, out_j);
}

/* The f1-f3 pass with the coincidence check and the portable walk's setup at level 1 (``eppf_f123q_avx2``)
   or 0 (``eppf_f123q_port``, which reads 2**14 / L from ``recip_packed``; level 1 divides in its lanes): the
   same results. */
static int eppf_f123q(int level, int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                      const double *nrm, int64_t ns, const int32_t *vox, int64_t g, double scale, int n1, int n2,
                      int n3, int n4, double f1_density, const double *cos2, const double *cos3,
                      const int64_t *states, const int32_t *thr, const double *recip_packed, const double *pn,
                      int32_t *B, int64_t *QP, int64_t *QI, int64_t *QS, int *nq_out, int32_t *counts)
{
    if (level == 1)
        return eppf_f123q_avx2(m, ii, jj, pts, ps, nrm, ns, vox, g, scale, n1, n2, n3, n4, f1_density, cos2, cos3,
                               states, thr, pn, B, QP, QI, QS, nq_out, counts);
    return eppf_f123q_port(m, ii, jj, pts, ps, nrm, ns, vox, g, scale, n1, n2, n3, n4, f1_density, cos2, cos3,
                           states, thr, recip_packed, pn, B, QP, QI, QS, nq_out, counts);
}

#endif /* EPPF_WALK_H */
