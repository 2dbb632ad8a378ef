/* Levels 0 and 1 of _eppf_walk.h: level 3's skipping walk in portable C.
 *
 * The same cone codes c = min(C, 3) as ``eppf_code_grid`` (see
 * _eppf_walk_skip.h), the same packed positions (each line walked along its
 * dominant axis, in the direction in which that coordinate grows, the axis
 * in bits 62-63), the same lane states (bytes R, U, O, X, the pair's f1-f3
 * bin above) and the same stopping rule, with plain 64-bit integer
 * operations only: no gathers, nothing a compiler for ARM64 or any other
 * CPU lacks. What differs:
 *
 * - The codes are kept as two bit planes of z bits, two words per (x, y) row
 *   and axis, rather than interleaved 2-bit fields: the row's first word
 *   holds the code's bit 0 (c = 1 or 3), its second bit 1 (c = 2 or 3). Both
 *   come straight from the cone sets O_2 and O_3 with word operations (no
 *   bit spreading), so the build is a few whole-word passes that compilers
 *   vectorize. A look-up reads the 16 bytes of row (p >> 56) 64 + y, which is
 *   below EPPF_PORT_ROWS for any 64-bit position (x with the axis above it
 *   is 8 bits, y 6), so lanes past their line's end read inside the buffer.
 * - The lines of a batch are walked in rounds rather than lanes refilled from
 *   a queue: each round takes every line still in the list EPPF_PORT_STEPS
 *   steps further, without a test, then keeps the lines whose bin is not yet
 *   certain (in place, in order) and lists the states of the others. A
 *   line's state stops changing once its bin is certain (its R, U or O byte
 *   negative), so the steps it takes past that point, inside or past its
 *   line, change nothing. No branch depends on the data but the loop's end,
 *   and the steps of successive lines are independent, so an out-of-order
 *   CPU overlaps their look-ups.
 *
 * Level 0 runs this code as it is, in level 1's order: a batch's pair draws
 * (``eppf_draw_batch``), one pass for the coincidence check, the f1-f3 bins
 * and the walks' setup over ``eppf_pack_rows``' rows (``eppf_f123q_port``),
 * then the walk. Level 1 builds the same grids with it (compiled for AVX2:
 * ``eppf_port_code_grid_avx2``) and runs the AVX2 forms of the draws, the
 * pass and the walk (``eppf_draw_batch_avx2``, ``eppf_f123q_avx2`` and
 * ``eppf_port_walk_avx2`` in _eppf_walk_avx2.h), which give the same pairs,
 * lines, steps and states.
 */
#ifndef EPPF_WALK_PORT_H
#define EPPF_WALK_PORT_H

#include "_eppf_walk_common.h"

/* Rows of the portable walk's cone grids: the row index (p >> 56) 64 + y of any position. */
#define EPPF_PORT_ROWS 16384
/* The cone grids of the portable walk: two words a row. */
#define EPPF_PORT_CODE_WORDS (2 * EPPF_PORT_ROWS)
/* Their build's scratch: four g^2-word grids. */
#define EPPF_PORT_SCRATCH_WORDS (4 * EPPF_CODE_AXIS_WORDS)
/* The buffer a thread needs for both. */
#define EPPF_PORT_WORDS (EPPF_PORT_CODE_WORDS + EPPF_PORT_SCRATCH_WORDS)
/* Steps a round takes every line (a line's look-ups: about 9 on surface
   scans; each round wastes half a round's steps on average on the lines that
   finish in it). */
#define EPPF_PORT_STEPS 4
/* Lines walked side by side (their look-ups overlap; with the branch-free steps below, 6 lines measured 4%
   faster than 4 on a Zen 4 and 3% faster on a Zen 2, 8 no faster). */
#define EPPF_PORT_LINES 6
/* The portable walk keeps each of a state's bytes R, U, O, X plus 128 (the
   byte's sign bit flipped), so that one 64-bit subtraction updates all four
   without a borrow between them: a byte's value stays within -128..127
   (R, U and O stop at -3 at the least, X at -3 - T / n4), so its biased
   form never drops below 0. Bit 7 of R, U and O all set: the bin is still
   uncertain. */
#define EPPF_PORT_BIAS 0x80808080
#define EPPF_PORT_LIVE 0x808080

/* Count the pairs of the nd finished states ``done`` of the portable walks
   (biased bytes, EPPF_PORT_BIAS), each at its f1-f3 bin plus f4 bin. */
static void eppf_port_count_done(int nd, const int64_t *done, const int32_t *thr, int n4, int32_t *counts)
{
    int i;
    for (i = 0; i < nd; i++) {
        const int64_t st = done[i];
        const int32_t b = (int32_t)((st >> 32) & 0xFFFFFF);
        if (n4 > 3) {
            const int64_t T = ((st >> 56) & 63) + 1;
            const int occ = thr[T * n4 + n4 - 1] - 1 - ((int)((st >> 16) & 0xFF) - 128); /* hi - 1 - O */
            counts[b + eppf_f4_bin(thr, n4, T, occ)]++;
        } else {
            /* n4 = 2: occ >= hi (O < 0: bit 23 clear); n4 = 3: also occ >= lo (X < 0: bit 31 clear) */
            counts[b + (~(st >> 23) & 1) + (n4 == 3 ? (~(st >> 31) & 1) : 0)]++;
        }
    }
}

/* Walk the n lines of the list (QP, QI, QS, overwritten) over the cone grids
 * ``code`` (``code_grid``) until every line's bin is certain, and count each
 * pair at its f1-f3 bin plus f4 bin (the states' meaning: _eppf_walk_skip.h).
 * ``done``: room for n states. Lines go EPPF_PORT_LINES at a time, their
 * steps interleaved, so that their look-ups (in the L2 cache: the grids are
 * 192 KiB at g = 64) overlap. */
static void eppf_port_walk(int n, int64_t *QP, int64_t *QI, int64_t *QS, const uint64_t *code, const int32_t *thr,
                           int n4, int64_t *done, int32_t *counts)
{
    /* by c: what a step takes from the state while the bin is uncertain, and the steps it moves (a line
       whose bin is certain moves on too, as at level 1: its state stays, and any position's look-up lies
       inside the grids; no live bit in the index keeps the step's chain short) */
    static const int64_t delta[4] = { EPPF_ST(1, 0, 1, 1), EPPF_ST(1, 1, 0, 0), EPPF_ST(2, 2, 0, 0),
                                      EPPF_ST(3, 3, 0, 0) };
    static const uint64_t steps[4] = { 1, 1, 2, 3 };
    int nd = 0;
/* One step of line l: the code c at row (x + 64 a) 64 + y (below EPPF_PORT_ROWS for any p; its two
   words at 2 row), bit z. */
#define EPPF_PORT_STEP(l)                                                                          \
    do {                                                                                           \
        const uint64_t *w_ = code + (((p[l] >> 56) << 7) + ((p[l] >> (EPPF_PK_YSHIFT - 1)) & 126)); \
        const unsigned z_ = (unsigned)(p[l] >> EPPF_PK_ZSHIFT) & 63;                                \
        const unsigned c_ = (unsigned)((w_[0] >> z_) & 1) | (unsigned)(((w_[1] >> z_) & 1) << 1);    \
        /* all ones while R, U and O are all >= 0 (bits 7, 15 and 23 set), else 0 */               \
        const uint64_t live_ = 0 - (((uint64_t)(~st[l] & EPPF_PORT_LIVE) - 1) >> 63);              \
        st[l] -= (int64_t)((uint64_t)delta[c_] & live_);                                            \
        p[l] += steps[c_] * inc[l];                                                                \
    } while (0)
/* Line l of the group at t: kept (its bin still uncertain) or listed as done. */
#define EPPF_PORT_SORT(l)                                                                          \
    do {                                                                                           \
        const int fin_ = (st[l] & EPPF_PORT_LIVE) != EPPF_PORT_LIVE;                                \
        done[nd] = st[l];                                                                          \
        nd += fin_;                                                                                \
        QP[keep] = (int64_t)p[l];                                                                  \
        QI[keep] = (int64_t)inc[l];                                                                \
        QS[keep] = st[l];                                                                          \
        keep += 1 - fin_;                                                                          \
    } while (0)
    while (n > 0) {
        int t = 0, keep = 0, k, l;
        for (; t + EPPF_PORT_LINES <= n; t += EPPF_PORT_LINES) {
            uint64_t p[EPPF_PORT_LINES], inc[EPPF_PORT_LINES];
            int64_t st[EPPF_PORT_LINES];
            for (l = 0; l < EPPF_PORT_LINES; l++) {
                p[l] = (uint64_t)QP[t + l];
                inc[l] = (uint64_t)QI[t + l];
                st[l] = QS[t + l];
            }
            for (k = 0; k < EPPF_PORT_STEPS; k++)
                for (l = 0; l < EPPF_PORT_LINES; l++)
                    EPPF_PORT_STEP(l);
            for (l = 0; l < EPPF_PORT_LINES; l++)
                EPPF_PORT_SORT(l);
        }
        for (; t < n; t++) {
            uint64_t p[1], inc[1];
            int64_t st[1];
            p[0] = (uint64_t)QP[t];
            inc[0] = (uint64_t)QI[t];
            st[0] = QS[t];
            for (k = 0; k < EPPF_PORT_STEPS; k++)
                EPPF_PORT_STEP(0);
            EPPF_PORT_SORT(0);
        }
        n = keep;
    }
#undef EPPF_PORT_STEP
#undef EPPF_PORT_SORT
    eppf_port_count_done(nd, done, thr, n4, counts);
}


/* ``out[x g + y]`` = ``in`` of rows y - 1, y and y + 1 of the same x (those
   inside the grid) or-ed: the y +- 1 part of a 3^2 box; 2 <= g <= 64. */
static inline __attribute__((always_inline)) void eppf_port_rows_pm1(const uint64_t *in, uint64_t *out, int64_t g)
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
   ``o`` in its 3^2 box (``eppf_code_grid``'s O_{m+1} from O_m = o); a and b:
   g^2 words of scratch each; 2 <= g <= 64. */
static inline __attribute__((always_inline)) void eppf_port_cone_step(const uint64_t *bits, const uint64_t *o,
                                                                      uint64_t *out, uint64_t *a, uint64_t *b,
                                                                      int64_t g, int axis)
{
    const uint64_t gm = g == 64 ? ~(uint64_t)0 : (((uint64_t)1 << g) - 1);
    int64_t x, y, r;
    if (axis == 2) {
        /* the 3^2 box in (x, y), then the next z (bit z + 1) */
        eppf_port_rows_pm1(o, b, g);
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
        eppf_port_rows_pm1(a, b, g);
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

/* (eppf_port_cone_step and eppf_port_rows_pm1 are inlined wherever they
   are called, so that each build below vectorizes them for its target.) */

/* The portable walk's cone grids from ``bits`` (g^2 words, one per (x, y)
 * row, z bits, none past z = g - 1): words 2 r and 2 r + 1 of ``code``, r =
 * 4096 a + 64 x + y, hold bit 0 and bit 1 of c = min(C, 3) at bit z, C as in
 * ``eppf_code_grid``; 2 <= g <= 64.
 * ``work``: EPPF_PORT_SCRATCH_WORDS words. Words of rows past g are left as
 * they are (no line reads them before its bin is certain). */
static inline __attribute__((always_inline)) void eppf_port_code_grid_impl(const uint64_t *bits, int64_t g,
                                                                            uint64_t *work, uint64_t *code)
{
    uint64_t *o2 = work, *o3 = work + g * g, *a = work + 2 * g * g, *b = work + 3 * g * g;
    int64_t x, y;
    int axis;
    for (axis = 0; axis < 3; axis++) {
        uint64_t *c = code + 2 * EPPF_CODE_AXIS_WORDS * axis;
        eppf_port_cone_step(bits, bits, o2, a, b, g, axis);
        eppf_port_cone_step(bits, o2, o3, a, b, g, axis);
        for (x = 0; x < g; x++)
            for (y = 0; y < g; y++) {
                const int64_t r = x * g + y;
                c[2 * (64 * x + y)] = (o2[r] & ~bits[r]) | ~o3[r]; /* c = 1 or 3 */
                c[2 * (64 * x + y) + 1] = ~o2[r];                  /* c = 2 or 3 */
            }
    }
}

/* eppf_port_code_grid_impl's body, compiled for the CPU's baseline (level 0)
   and, where the SIMD kernels are built, for AVX2 (level 1): the same
   integer operations on the same words, so the same grids. */
static void eppf_port_code_grid(const uint64_t *bits, int64_t g, uint64_t *work, uint64_t *code)
{
    eppf_port_code_grid_impl(bits, g, work, code);
}
#if EPPF_WALK_SIMD
__attribute__((target("avx2")))
static void eppf_port_code_grid_avx2(const uint64_t *bits, int64_t g, uint64_t *work, uint64_t *code)
{
    eppf_port_code_grid_impl(bits, g, work, code);
}
#else
#define eppf_port_code_grid_avx2 eppf_port_code_grid
#endif

/* The candidate pairs of the next m draws of splitmix64 from ``state``,
 * exactly as _eppf_fast.pyx's ``_draw_pair`` draws them but without its
 * check for coinciding points (``eppf_f123q_port`` does that check): draw k
 * is that of state + (k + 1) gamma, independent of the others, so compilers
 * overlap or vectorize them (``eppf_draw_batch_avx2`` is this four draws to
 * a vector). out_i, out_j: room for m entries. */
static void eppf_draw_batch(int m, uint64_t state, uint32_t n, int32_t *out_i, int32_t *out_j)
{
    int t;
    for (t = 0; t < m; t++) {
        uint64_t z = state + (uint64_t)(t + 1) * EPPF_SM_GAMMA;
        uint32_t i, j;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
        z ^= z >> 31;
        i = (uint32_t)(((z >> 32) * (uint64_t)n) >> 32);
        j = (uint32_t)(((z & 0xFFFFFFFFULL) * (uint64_t)(n - 1)) >> 32);
        out_i[t] = (int32_t)i;
        out_j[t] = (int32_t)(j + (j >= i));
    }
}

/* Point r's x, y, z, nx, ny, nz into x[0..5] and, unless ``vox`` and ``pn``
   are both NULL, its voxel's x, y, z into v[0..2]: from ``pn``'s row
   (``eppf_pack_rows``, level 1's form) or, where it is NULL, from the arrays
   in place. */
static inline void eppf_port_load(const double *pn, const double *pts, int64_t ps, const double *nrm, int64_t ns,
                                  const int32_t *vox, int64_t r, double *x, int32_t *v)
{
    int k;
    if (pn) {
        const double *row = pn + 8 * r;
        int32_t w[4];
        for (k = 0; k < 6; k++)
            x[k] = row[k];
        memcpy(w, row + 6, sizeof w);
        for (k = 0; k < 3; k++)
            v[k] = w[k];
        return;
    }
    for (k = 0; k < 3; k++) {
        x[k] = pts[ps * r + k];
        x[k + 3] = nrm[ns * r + k];
    }
    if (vox)
        for (k = 0; k < 3; k++)
            v[k] = vox[3 * r + k];
}

/* Level 0's pass over a batch of pairs (ii[t], jj[t]), t < m, in the form of
 * level 1's ``eppf_f123q_avx2`` (the same arguments, results and order of
 * lines), one pair at a time (measured: faster in scalar code than groups of
 * pairs laid out for a compiler's vectorizer, and than separate passes for
 * f1-f3 and the setup): finds the first t whose two points coincide
 * (returned; m when none does), bins f1-f3 with _eppf_fast.pyx's
 * ``_bin_f123``'s IEEE operations in the same order, and where QP is not NULL
 * sets up the f4 walks of the pairs before the first coinciding one (lines
 * with inner voxels, L > 1, into QP, QI, QS, *nq_out of them; the others
 * are counted at once: occ = T = L + 1, every voxel occupied), otherwise
 * writes B[t], the f1-f3 bin times n4. The start and increment are
 * _eppf_fast.pyx's ``_line_bin``'s (its ``recip_packed``, 2**14 / L correctly
 * rounded for L < 64, and llrint); each line goes along its dominant axis
 * (the first on a tie) in the direction in which that coordinate grows, the
 * axis in bits 62-63. Rows come from ``pn`` (``eppf_pack_rows``) or, where it
 * is NULL, from the arrays in place (then ``vox``, (n, 3) int32, gives the
 * voxels). ``states``: ``eppf_walk_states``. */
static int eppf_f123q_port(int m, const int32_t *ii, const int32_t *jj, const double *pts, int64_t ps,
                           const double *nrm, int64_t ns, const int32_t *vox, int64_t g, double scale, int n1, int n2,
                           int n3, int n4, double f1_density, const double *cos2, const double *cos3,
                           const int64_t *states, const int32_t *thr, const double *recip_packed, const double *pn,
                           int32_t *B, int64_t *QP, int64_t *QI, int64_t *QS, int *nq_out, int32_t *counts)
{
    const int64_t half = EPPF_PK_S / 2 + g;
    const double top1 = (double)(n1 - 1);
    int t, k, nq = 0;
    for (t = 0; t < m; t++) {
        double a[6], b[6], dx, dy, dz, dist, v;
        int32_t va[3] = {0, 0, 0}, vb[3] = {0, 0, 0}, bins, b1, b2 = 0, b3 = 0;
        eppf_port_load(pn, pts, ps, nrm, ns, QP ? vox : NULL, ii[t], a, va);
        eppf_port_load(pn, pts, ps, nrm, ns, QP ? vox : NULL, jj[t], b, vb);
        if (a[0] == b[0] && a[1] == b[1] && a[2] == b[2])
            break;  /* the first pair whose points coincide ends the batch */
        /* f1-f3 as _bin_f123 (no branch on the data: the compiler's minimum and maximum) */
        dx = b[0] - a[0];
        dy = b[1] - a[1];
        dz = b[2] - a[2];
        dist = sqrt(dx * dx + dy * dy + dz * dz);
        v = dist * scale;
        v = v * f1_density;
        v = v < top1 ? v : top1;
        b1 = (int32_t)(v > 0.0 ? v : 0.0);
        if (n2 > 1) {
            const double inv = 1.0 / dist;
            const double u1 = (a[3] * dx + a[4] * dy + a[5] * dz) * inv;
            const double u2 = (b[3] * dx + b[4] * dy + b[5] * dz) * inv;
            const double m1 = u2 < u1 ? u2 : u1;
            for (k = 0; k < n2 - 1; k++)
                b2 += m1 <= cos2[k];
        }
        if (n3 > 1) {
            /* (fabs turns -0.0 into +0.0, which compares the same) */
            const double v3 = fabs(a[3] * b[3] + a[4] * b[4] + a[5] * b[5]);
            for (k = 0; k < n3 - 1; k++)
                b3 += v3 <= cos3[k];
        }
        bins = ((b1 * n2 + b2) * n3 + b3) * n4;
        if (!QP) {
            B[t] = bins;
            continue;
        }
        {
            const int64_t ex = vb[0] - va[0], ey = vb[1] - va[1], ez = vb[2] - va[2];
            const int64_t ax = ex < 0 ? -ex : ex, ay = ey < 0 ? -ey : ey, az = ez < 0 ? -ez : ez;
            const int64_t axy = ax > ay ? ax : ay, L = axy > az ? axy : az;
            const double q = recip_packed[L & 63];
            int64_t inc = (int64_t)llrint((double)ex * q) * EPPF_PK_X + (int64_t)llrint((double)ey * q) * EPPF_PK_Y
                          + (int64_t)llrint((double)ez * q);
            int64_t p = (va[0] * EPPF_PK_S + half) * EPPF_PK_X + (va[1] * EPPF_PK_S + half) * EPPF_PK_Y
                        + va[2] * EPPF_PK_S + half + inc;
            /* from the last inner voxel, by -inc, where the dominant axis falls (no branch: the direction is random) */
            const int64_t axis = ax == L ? 0 : ay == L ? 1 : 2;
            const int64_t da = axis == 0 ? ex : axis == 1 ? ey : ez;
            const int64_t back = -(int64_t)(da < 0);
            if (L <= 1) {
                counts[bins + eppf_f4_bin(thr, n4, L + 1, L + 1)]++;
                continue;
            }
            p += ((L - 2) * inc) & back;
            inc = (inc ^ back) - back;
            QP[nq] = (int64_t)((uint64_t)p + ((uint64_t)axis << 62));
            QI[nq] = inc;
            QS[nq] = (states[(L & 63) + 1] ^ EPPF_PORT_BIAS) + (((int64_t)bins + (n4 > 3 ? L << 24 : 0)) << 32);
            nq++;
        }
    }
    if (nq_out)
        *nq_out = nq;
    return t;
}

#endif /* EPPF_WALK_PORT_H */
