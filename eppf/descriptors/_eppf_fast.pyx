# cython: language_level=3
"""Compiled EPPF kernels.

Python allocates every array; the kernels fill them. Work is parallel over
objects (``prange``), each object with its own generator seeded from one
64-bit seed, so results never depend on the number of threads.

Conventions (the user guide's reading of the paper):

- f1 = |d| * scale on [0, f1_max]; bin = min(floor(f1 * (n1 / f1_max)), n1 - 1)
  (one multiplication by a precomputed bin density: no division per pair).
- f2 = max(beta1, beta2), beta_k = arccos(n_k . d_hat) - pi/2 on [-pi/2, pi/2].
  Because arccos decreases, f2 = arccos(min(n1 . d_hat, n2 . d_hat)) - pi/2,
  and its bin is the number of inner edges e_k = cos(k pi / n2) with
  m <= e_k: no arccos in the loop.
- f3 = arccos(|n1 . n2|) on [0, pi/2], binned the same way.
- f4 = occupied / total voxels on the integer 3D line between the two points'
  voxels of a per-object ``grid_size``^3 bit grid over the bounding cube.
  Step k (0..L, L the largest axis difference) visits
  v1 + floor(k * delta / L + 1/2) on every axis, i.e. a Bresenham line with
  ties rounded up; it is walked in 32.32 fixed point, which is exact for
  grids below 1024 (see ``_line_bin``). Both end voxels are occupied.
  bin = min(n4 * occ // (L + 1), n4 - 1) in integers.
- A bin count of 1 switches a function off (its value is never computed).

Batches of pairs (256; 1,024 for the skipping walks of levels 0, 1 and 3)
go through the kernels of ``_eppf_walk.h``; where the CPU has them (checked at
import), the SIMD ones: with AVX-512 (F,
BW, VL, DQ, VBMI) the draws, the f1-f3 bins and the f4 walks of grids up to
64 run eight pairs at a time (level 2: walks grouped by line length;
level 3: f1-f3 and the walk setup in one pass, lanes refilled from a queue,
each line walked along its dominant axis, skipping voxels proved empty by
the empty cone ahead of them, look-ups by scalar loads; level 3 is the
default on AMD, where gathers are slow). Levels 0 (portable C, every CPU)
and 1 (AVX2) walk grids up to 64 with the same skipping algorithm in
``_eppf_walk_port.h``; both draw a batch's pairs before checking them, then
bin f1-f3 and set up the walks in one pass over a copy of the points,
normals and voxels in 64-byte rows (level 0 one pair at a time in portable
C; level 1 draws, bins and sets up four pairs at a time, as level 3 does
eight, and walks four lines to a vector; no gathers). f1-f3 use the
same IEEE operations in the same order, the walks visit the same voxels or
prove them empty. Their bins and draws are bit-identical to the scalar code
here (``_line_bin``, voxel by voxel, walks grids above 64 at every level, and
every grid where ``_set_line_walk(True)``); ``_set_simd(False)`` forces level
0 and ``_set_simd_level`` picks a level (tests compare all levels with each
other, with ``_line_bin`` and with the NumPy reference).
"""
import numpy as np

cimport numpy as cnp
from cython.parallel cimport prange, threadid
from libc.math cimport sqrt, cos, fabs, ldexp, llrint, isfinite, M_PI
from libc.stdint cimport int32_t, int64_t, uint32_t, uint64_t
from libc.string cimport memcpy, memset

from ..utils._common cimport splitmix64, rand_below
from ..utils._common cimport clamp_floor

cnp.import_array()

cdef extern from "_eppf_walk.h":
    # the packed walk's layout and the batch size, defined once in the header
    enum:
        EPPF_PK_S
        EPPF_PK_ZSHIFT
        EPPF_PK_YSHIFT
        EPPF_PK_XSHIFT
        EPPF_WALK_BATCH
        EPPF_QUEUE_BATCH
        EPPF_META_LO
        EPPF_META_HI
        EPPF_WALK_MAX_GRID
    int64_t EPPF_PK_X
    uint64_t EPPF_SM_GAMMA
    int64_t EPPF_PK_Y
    int eppf_walk_has_avx2() noexcept nogil
    int eppf_walk_has_avx512() noexcept nogil
    int eppf_walk_prefers_skips() noexcept nogil
    void eppf_draw_batch_at(int level, int m, uint64_t state, uint32_t n, int32_t* I, int32_t* J) noexcept nogil
    int eppf_f123q(int level, int m, const int32_t* I, const int32_t* J, const double* pts, int64_t ps,
                        const double* nrm, int64_t ns, const int32_t* vox, int64_t g, double scale, int n1, int n2,
                        int n3, int n4, double f1_density, const double* cos2, const double* cos3,
                        const int64_t* states, const int32_t* thr, const double* recip_packed, const double* pn,
                        int32_t* B, int64_t* QP, int64_t* QI, int64_t* QS, int* nq_out, int32_t* counts) noexcept nogil
    void eppf_fill_grid_avx512(const double* pts, int64_t ps, int64_t n, int64_t g, uint64_t* bits,
                               int64_t* pv) noexcept nogil
    int eppf_f123_batch_avx512(int m, const int32_t* I, const int32_t* J, const double* pts, int64_t ps,
                               const double* nrm, int64_t ns, double scale, int n1, int n2, int n3, int n4,
                               double f1_density, const double* cos2, const double* cos3,
                               int32_t* B, const double* pn) noexcept nogil
    void eppf_pack_rows(int64_t n, const double* pts, int64_t ps, const double* nrm, int64_t ns,
                        const int64_t* pv, const int32_t* vox, double* pn) noexcept nogil
    void eppf_f4_batch_avx512(int m, const int32_t* I, const int32_t* J, const int64_t* pv,
                              const uint64_t* bits, int64_t g, const int32_t* thr, int n4,
                              const int64_t* lohi, const double* recip_packed, int32_t* B) noexcept nogil
    enum:
        EPPF_LANES_WORDS
        EPPF_CODE_READ_WORDS
        EPPF_CODE_HALF
        EPPF_CODE_SCRATCH
        EPPF_CODE_AXIS_WORDS
    void eppf_code_grid(const uint64_t* bits, int64_t g, uint64_t* work, uint64_t* code) noexcept nogil
    int eppf_f123q_avx512(int m, const int32_t* I, const int32_t* J, double scale, int n1, int n2, int n3, int n4,
                          double f1_density, const double* cos2, const double* cos3, const double* pn,
                          const int32_t* thr, const int64_t* states, int64_t* QP, int64_t* QI, int64_t* QM,
                          int* nq_out, int32_t* counts) noexcept nogil
    void eppf_walk_states(const int32_t* thr, int n4, int64_t g, int64_t* st) noexcept nogil
    void eppf_f4_walkq_avx512(int nq, const int64_t* QP, const int64_t* QI, const int64_t* QM,
                              const uint64_t* code, int64_t g, const int32_t* thr, int n4, int64_t* lanes,
                              int drain, int32_t* counts) noexcept nogil
    enum:
        EPPF_PORT_WORDS
        EPPF_PORT_CODE_WORDS
    void eppf_port_code_grid(const uint64_t* bits, int64_t g, uint64_t* work, uint64_t* code) noexcept nogil
    void eppf_port_code_grid_avx2(const uint64_t* bits, int64_t g, uint64_t* work, uint64_t* code) noexcept nogil
    void eppf_port_walk(int n, int64_t* QP, int64_t* QI, int64_t* QS, const uint64_t* code, const int32_t* thr,
                        int n4, int64_t* done, int32_t* counts) noexcept nogil
    void eppf_port_walk_avx2(int n, int64_t* QP, int64_t* QI, int64_t* QS, const uint64_t* code,
                             const int32_t* thr, int n4, int64_t* done, int32_t* counts) noexcept nogil

# The best kernels of ``_eppf_walk.h`` the CPU has: 0 scalar, 1 AVX2, 2 AVX-512
# with the grouped f4 walk, 3 AVX-512 with the skipping f4 walk (f1-f3 use AVX2
# at level 1, AVX-512 at levels 2 and 3). ``_set_simd`` / ``_set_simd_level``
# choose another level for tests.
cdef int _max_level():
    if eppf_walk_has_avx2() == 0:
        return 0
    return 3 if eppf_walk_has_avx512() != 0 else 1


# The level used by default: the best, except that of the two AVX-512 walks the
# skipping one (fewer gathers, more other work) is the default only where
# gathers are slow (AMD).
cdef int _default_level():
    cdef int best = _max_level()
    if best == 3 and eppf_walk_prefers_skips() == 0:
        return 2
    return best


cdef int _level = _default_level()

# Whether levels 0 and 1 take the per-pair walk of ``_line_bin`` instead of the
# portable skipping walk (``_set_line_walk``: tests compare the two).
cdef bint _line_walk = False


cdef enum:
    # Consecutive zero-length pairs after which an object is declared degenerate.
    MAX_REDRAWS = 10000
    # The parameters' limits (``MIN_N_BINS`` ... ``MAX_GRID_SIZE`` below): bins per
    # function (1 switches it off), and grid sizes for which the 32.32 fixed-point
    # walk of ``_line_bin`` is exact (below 1024).
    MIN_BINS = 1
    MAX_BINS = 64
    MIN_GRID = 2
    MAX_GRID = 1023
    FIX_SHIFT = 32
    # Grids up to this size are walked in the packed form (one 64-bit word a row),
    # and only they by the SIMD walks.
    PACKED_GRID = EPPF_WALK_MAX_GRID
    # Objects up to this many points get the AVX-512 f1-f3's copy of their rows;
    # larger ones are read in place.
    ROWS_MAX_POINTS = 65536
    BATCH = EPPF_WALK_BATCH
    QBATCH = EPPF_QUEUE_BATCH  # the pairs of a batch at level 3 (at least BATCH)
    CODE_HALF = EPPF_CODE_HALF  # where their z >= 32 halves start
    CODE_SCRATCH = EPPF_CODE_SCRATCH  # where the grids' scratch goes (between the halves)
    CODE_READ_WORDS = EPPF_CODE_READ_WORDS  # the words of the buffer the skipping walk may read
    CODE_AXIS_WORDS = EPPF_CODE_AXIS_WORDS  # one half of one axis's grid: 64 rows of 64 words
    # packed line walk for grids up to 64 (layout in _eppf_walk_common.h)
    PK_S = EPPF_PK_S
    PK_ZSHIFT = EPPF_PK_ZSHIFT
    PK_YSHIFT = EPPF_PK_YSHIFT
    PK_XSHIFT = EPPF_PK_XSHIFT

cdef int64_t PK_Y = EPPF_PK_Y
cdef int64_t PK_X = EPPF_PK_X

cdef uint64_t LOW32 = 0xFFFFFFFF

# The limits of ``eppf_counts``' parameters, for the estimator's parameter checks:
# each of the four bin counts in [MIN_N_BINS, MAX_N_BINS], grid_size in
# [MIN_GRID_SIZE, MAX_GRID_SIZE], n_pairs at most MAX_N_PAIRS (a C int).
MIN_N_BINS = MIN_BINS
MAX_N_BINS = MAX_BINS
MIN_GRID_SIZE = MIN_GRID
MAX_GRID_SIZE = MAX_GRID
MAX_N_PAIRS = 2**31 - 1


def _simd_enabled():
    """Whether the SIMD kernels of ``_eppf_walk.h`` are in use."""
    return _level > 0


def _set_simd(enabled):
    """Use the default SIMD kernels for this CPU when ``enabled``, the scalar
    code otherwise; return the previous setting (True or False)."""
    global _level
    old = _level > 0
    _level = _default_level() if enabled else 0
    return old


def _set_line_walk(enabled):
    """Make levels 0 and 1 walk every f4 line voxel by voxel (``_line_bin``)
    instead of by the portable skipping walk when ``enabled`` (tests: the
    per-pair walk is the one the skipping walks are compared with); return
    the previous setting."""
    global _line_walk
    old = _line_walk
    _line_walk = bool(enabled)
    return old


def _simd_levels():
    """The kernel levels this CPU can run: 0 scalar, 1 AVX2, 2 AVX-512 (grouped
    walk), 3 AVX-512 (skipping walk)."""
    return tuple(range(_max_level() + 1))


def _simd_level():
    """The kernel level in use: 0 scalar, 1 AVX2, 2 AVX-512 grouped walk, 3 AVX-512 skipping walk."""
    return _level


def _default_simd_level():
    """The kernel level used unless ``_set_simd_level`` says otherwise."""
    return _default_level()


def _set_simd_level(int level):
    """Use kernel level ``level`` (0 scalar, 1 AVX2, 2 AVX-512 with the grouped
    walk, 3 AVX-512 with the skipping walk; capped at what the CPU has);
    return the previous level."""
    global _level
    old = _level
    _level = max(0, min(level, _max_level()))
    return old


cdef struct Params:
    int n1, n2, n3, n4
    int grid
    double f1_max
    double f1_density       # n1 / f1_max
    double cos2[MAX_BINS]   # inner edges of f2 on the cosine scale, k = 1..n2-1
    double cos3[MAX_BINS]   # inner edges of f3 on the cosine scale, k = 1..n3-1
    const int64_t* recip    # recip[L] = floor(2**32 / L) for the line walk
    const int32_t* thr      # thr[T * n4 + b] = ceil(b * T / n4): f4 thresholds for T voxels
    # 2**14 / L for the packed walk, L = 0..PACKED_GRID - 1
    double recip_packed[PACKED_GRID]
    # thr[T * n4 + 1] and thr[T * n4 + n4 - 1], T = 0..PACKED_GRID + 1, packed as the AVX-512 walk reads them
    int64_t lohi[PACKED_GRID + 2]
    # the skipping walk's first state of a line of T voxels (eppf_walk_states), T = 0..PACKED_GRID
    int64_t first_states[PACKED_GRID + 1]
    int walk_level          # f4 walks: AVX2 (1), AVX-512 grouped (2) or skipping (3) (grids up to 64), scalar (0)
    int f123_level          # draws and f1-f3 bins (and levels 1 and 3's walk setup): AVX-512 (2), AVX2 (1), scalar (0)


cdef inline bint _port_walk(const Params* prm) noexcept nogil:
    """Whether f4 goes through the portable skipping walk (levels 0 and 1, grids up to 64)."""
    return prm.walk_level < 2 and prm.grid <= PACKED_GRID and prm.n4 > 1 and not _line_walk


cdef inline int _voxel(double v, double lo, double inv, int grid) noexcept nogil:
    """clip(floor((v - lo) * inv), 0, grid - 1), clamped in floating point
    before the conversion so that NaN (to 0), infinities and huge values give
    an index inside the grid."""
    return clamp_floor((v - lo) * inv, grid)


cdef inline int64_t _row_words(int grid) noexcept nogil:
    return (grid + 63) >> 6


cdef inline int64_t _grid_words(int grid) noexcept nogil:
    return <int64_t>grid * grid * _row_words(grid)


cdef inline void _fill_grid(const double* pts, int64_t ps, int64_t n, int grid, uint64_t* bits,
                            int32_t* vox, int64_t* pv) noexcept nogil:
    """Voxelize ``n`` points on a grid over their bounding cube.

    Sets the occupied voxels in the bit grid ``bits`` (row (x, y) is
    ``_row_words`` 64-bit words of z bits, so a 64^3 grid is one word per
    row, 32 KiB) and writes each point's voxel coordinates to ``vox`` (n, 3)
    or, unless ``pv`` is NULL (grids up to 64 with the AVX-512 kernels, which
    read no ``vox``), to ``pv`` (n,) as the packed walk's start word, lanes
    v * S + S/2 + g: ``eppf_fill_grid_avx512``, the same voxels eight points
    at a time.
    """
    cdef int64_t i, idx
    if pv != NULL:
        eppf_fill_grid_avx512(pts, ps, n, grid, bits, pv)
        return
    cdef double mnx = pts[0], mny = pts[1], mnz = pts[2]
    cdef double mxx = mnx, mxy = mny, mxz = mnz
    cdef double side, inv
    for i in range(1, n):
        if pts[ps * i] < mnx: mnx = pts[ps * i]
        if pts[ps * i] > mxx: mxx = pts[ps * i]
        if pts[ps * i + 1] < mny: mny = pts[ps * i + 1]
        if pts[ps * i + 1] > mxy: mxy = pts[ps * i + 1]
        if pts[ps * i + 2] < mnz: mnz = pts[ps * i + 2]
        if pts[ps * i + 2] > mxz: mxz = pts[ps * i + 2]
    side = mxx - mnx
    if mxy - mny > side: side = mxy - mny
    if mxz - mnz > side: side = mxz - mnz
    inv = grid / side
    memset(bits, 0, _grid_words(grid) * sizeof(uint64_t))
    for i in range(n):
        vox[3 * i] = _voxel(pts[ps * i], mnx, inv, grid)
        vox[3 * i + 1] = _voxel(pts[ps * i + 1], mny, inv, grid)
        vox[3 * i + 2] = _voxel(pts[ps * i + 2], mnz, inv, grid)
        idx = ((<int64_t>vox[3 * i] * grid) + vox[3 * i + 1]) * _row_words(grid) + (vox[3 * i + 2] >> 6)
        bits[idx] |= (<uint64_t>1) << (vox[3 * i + 2] & 63)


cdef inline int _line_bin(const int32_t* va, const int32_t* vb, const Params* prm,
                          const uint64_t* bits, int64_t g, int64_t row_words, bint early,
                          int* occ_out, int* total_out) noexcept nogil:
    """f4's bin for the integer line between voxels ``va`` and ``vb``.

    Step k = 0..L (L the largest axis difference) visits
    v1 + floor(k * delta / L + 1/2) on each axis. It is walked in fixed point
    with S = 2**32: position_k = v1 * S + S/2 + E + k * delta * floor(S / L),
    E = grid**2. The accumulated error of the increment is below L**2 < E
    units in either direction, so position_k lies in (exact, exact + 2E), and
    a non-tie value of k * delta / L + 1/2 is at least 1 / (2L) from the next
    integer: the floor is exact whenever 4 * grid**3 < S (grid < 1024).
    Both end voxels hold a point, so only the inner L - 1 voxels are looked up.

    With ``early``, the walk stops as soon as the bin is certain (the top bin
    reached, or the bottom bin unavoidable); ``occ_out`` is then a partial
    count. The bin is the number of thresholds ceil(b T / n4), b = 1..n4-1,
    that the occupied count reaches, T = L + 1: no division per pair.
    """
    cdef int64_t dx = vb[0] - va[0], dy = vb[1] - va[1], dz = vb[2] - va[2]
    cdef int64_t L = dx if dx >= 0 else -dx
    cdef int64_t t
    t = dy if dy >= 0 else -dy
    if t > L: L = t
    t = dz if dz >= 0 else -dz
    if t > L: L = t
    cdef const int32_t* thr = prm.thr + (L + 1) * prm.n4
    cdef int occ = <int>(L + 1) if L <= 1 else 2
    cdef int lo = thr[1], hi = thr[prm.n4 - 1]
    cdef int64_t r, ix, iy, iz, px, py, pz, k, z
    cdef int64_t half = ((<int64_t>1) << (FIX_SHIFT - 1)) + g * g
    cdef int64_t quiet
    cdef int b = 0
    cdef int64_t P, I
    cdef double q
    total_out[0] = <int>(L + 1)
    # After inner step k the count can still grow by L - 1 - k, so the bottom
    # bin is certain once occ + L - 1 - k < lo; that needs k >= L + 2 - lo,
    # and steps before it are walked without checks.
    quiet = L - 1 if not early else min(L - 1, L + 1 - lo)
    if L > 1 and g <= PACKED_GRID:
        # Packed walk: x, y, z in three 21-bit lanes of one integer, each in
        # fixed point with S = 2**14 and increments round(delta * S / L), so a
        # step is one addition. The accumulated rounding error stays below
        # L / 2 + tiny units, the offset E = grid keeps every position above
        # the exact value, and 1.5 grid + 1 units < S / (2L): exact floors.
        q = prm.recip_packed[L]
        ix = llrint(dx * q)
        iy = llrint(dy * q)
        iz = llrint(dz * q)
        P = ((va[0] * PK_S + PK_S // 2 + g) * PK_X + (va[1] * PK_S + PK_S // 2 + g) * PK_Y
             + va[2] * PK_S + PK_S // 2 + g)
        I = ix * PK_X + iy * PK_Y + iz
        P += I
        for k in range(1, quiet + 1):
            z = (P >> PK_ZSHIFT) & 63
            occ += <int>((bits[(P >> PK_XSHIFT) * g + ((P >> PK_YSHIFT) & 63)] >> z) & 1)
            P += I
        for k in range(quiet + 1, L):
            if occ >= hi or occ + <int>(L - k) < lo:
                break
            z = (P >> PK_ZSHIFT) & 63
            occ += <int>((bits[(P >> PK_XSHIFT) * g + ((P >> PK_YSHIFT) & 63)] >> z) & 1)
            P += I
    elif L > 1:
        r = prm.recip[L]
        ix = dx * r
        iy = dy * r
        iz = dz * r
        px = ((<int64_t>va[0]) << FIX_SHIFT) + half + ix
        py = ((<int64_t>va[1]) << FIX_SHIFT) + half + iy
        pz = ((<int64_t>va[2]) << FIX_SHIFT) + half + iz
        for k in range(1, quiet + 1):
            z = pz >> FIX_SHIFT
            occ += <int>((bits[((px >> FIX_SHIFT) * g + (py >> FIX_SHIFT)) * row_words + (z >> 6)]
                          >> (z & 63)) & 1)
            px += ix
            py += iy
            pz += iz
        for k in range(quiet + 1, L):
            if occ >= hi or occ + <int>(L - k) < lo:
                break
            z = pz >> FIX_SHIFT
            occ += <int>((bits[((px >> FIX_SHIFT) * g + (py >> FIX_SHIFT)) * row_words + (z >> 6)]
                          >> (z & 63)) & 1)
            px += ix
            py += iy
            pz += iz
    occ_out[0] = occ
    for k in range(1, prm.n4):
        b += occ >= thr[k]
    return b


cdef inline int _bin_f123(const double* pts, int64_t ps, const double* nrm, int64_t ns, int64_t i, int64_t j,
                          double scale, const Params* prm, int* parts) noexcept nogil:
    """Bins of f1, f2, f3 of the ordered pair (i, j) combined as (b1 * n2 + b2) * n3 + b3."""
    cdef double dx = pts[ps * j] - pts[ps * i]
    cdef double dy = pts[ps * j + 1] - pts[ps * i + 1]
    cdef double dz = pts[ps * j + 2] - pts[ps * i + 2]
    cdef double dist = sqrt(dx * dx + dy * dy + dz * dz)
    cdef double v, m1, m2, inv
    cdef int b1 = 0, b2 = 0, b3 = 0, k
    # No branch on the data below (selects the compiler makes minimum and maximum
    # instructions of; fabs): the pairs are random, so such branches would often
    # be mispredicted.
    if prm.n1 > 1:
        # Clamped before the conversion, so that huge distances cannot overflow the int.
        # NaN and +inf land in the top bin, negative values (a negative scale) in bin 0.
        v = dist * scale
        v = v * prm.f1_density
        v = v if v < prm.n1 - 1 else <double>(prm.n1 - 1)
        b1 = <int>(v if v > 0.0 else 0.0)
    if prm.n2 > 1:
        inv = 1.0 / dist
        m1 = (nrm[ns * i] * dx + nrm[ns * i + 1] * dy + nrm[ns * i + 2] * dz) * inv
        m2 = (nrm[ns * j] * dx + nrm[ns * j + 1] * dy + nrm[ns * j + 2] * dz) * inv
        m1 = m2 if m2 < m1 else m1
        for k in range(prm.n2 - 1):
            b2 += m1 <= prm.cos2[k]
    if prm.n3 > 1:
        # |v| (fabs turns -0.0 into +0.0, which compares the same)
        v = fabs(nrm[ns * i] * nrm[ns * j] + nrm[ns * i + 1] * nrm[ns * j + 1] + nrm[ns * i + 2] * nrm[ns * j + 2])
        for k in range(prm.n3 - 1):
            b3 += v <= prm.cos3[k]
    if parts != NULL:
        parts[0] = b1
        parts[1] = b2
        parts[2] = b3
    return (b1 * prm.n2 + b2) * prm.n3 + b3


cdef inline int _draw_pair(const double* pts, int64_t ps, uint32_t n, uint64_t* state,
                           int64_t* i_out, int64_t* j_out) noexcept nogil:
    """Draw an ordered pair i != j with distinct coordinates; 0 on success."""
    cdef uint32_t i, j
    cdef uint64_t r
    cdef int fails = 0
    while True:
        r = splitmix64(state)
        i = <uint32_t>(((r >> 32) * <uint64_t>n) >> 32)
        j = <uint32_t>(((r & LOW32) * <uint64_t>(n - 1)) >> 32)
        if j >= i:
            j += 1
        if (pts[ps * i] != pts[ps * j] or pts[ps * i + 1] != pts[ps * j + 1]
                or pts[ps * i + 2] != pts[ps * j + 2]):
            i_out[0] = i
            j_out[0] = j
            return 0
        fails += 1
        if fails >= MAX_REDRAWS:
            return 1


cdef int _object_counts(const double* pts, int64_t ps, const double* nrm, int64_t ns, int64_t n, double scale,
                        uint64_t seed, int64_t n_pairs, Params* prm, uint64_t* bits,
                        int32_t* vox, int64_t* pv, uint64_t* code, double* pn, int32_t* counts) noexcept nogil:
    """Histogram counts of one object; returns 1 if pairs could not be drawn.

    Pairs go in batches through separate loops (draw, f1-f3, f4, count) so
    that the latency of one pair's square root and divisions overlaps with
    the next pair's instead of stalling behind a voxel walk. At level 3 one
    pass over a batch bins f1-f3 and queues the lines (``eppf_f123q_avx512``),
    the f4 walk counts the pairs itself, and lines still being walked at the
    end of a batch carry over (in ``lanes``) to the next one; the one pass of
    levels 1 and 0 (``eppf_f123q_avx2``, ``eppf_f123q_port``) queues a batch's
    lines for the portable walk (level 1: its AVX2 form). Unless ``pn`` is NULL,
    the f1-f3 passes read the points, normals
    and voxels from a copy of them there, one 64-byte row a point
    (``eppf_pack_rows``); level 3 needs it and, where it is NULL (objects too
    large for the copy), takes the grouped walk of level 2, levels 0 and 1 read
    the arrays in place (the same counts).
    """
    cdef uint64_t state = seed
    cdef int64_t base, t, m, i, j
    cdef int32_t pair_i[QBATCH + 8]  # (the AVX2 draws write, its f1-f3 pass reads, pairs in fours)
    cdef int32_t pair_j[QBATCH + 8]
    cdef int32_t pair_bins[QBATCH + 8]
    cdef int occ, total
    cdef int64_t row_words = _row_words(prm.grid)
    # Every level draws a batch's candidate pairs at once (AVX2 four, AVX-512
    # eight at a time); the f1-f3 pass then finds the first pair whose points coincide, if any,
    # and from there on the scalar draw (with its redraws) takes over for the
    # rest of the object.
    cdef bint vec_draw = True
    cdef int first_same
    cdef int64_t lanes[EPPF_LANES_WORDS]
    # the level-3 queue of a batch's lines (first position, increment, state)
    cdef int64_t queue_pos[QBATCH + 8]
    cdef int64_t queue_inc[QBATCH + 8]
    cdef int64_t queue_state[QBATCH + 8]
    cdef int64_t done[QBATCH + 8]  # the portable walks' finished states
    cdef int n_queued = 0
    if n < 2:  # no pair of distinct indices (the draw below would read past the object)
        return 1
    cdef bint skipping = prm.walk_level == 3 and prm.n4 > 1 and pn != NULL  # f4 by the skipping walk (level 3)
    cdef bint port = _port_walk(prm)  # f4 by the portable skipping walk (levels 0 and 1)
    cdef int64_t batch = QBATCH if skipping or port else BATCH
    if prm.n4 > 1:
        _fill_grid(pts, ps, n, prm.grid, bits, vox, pv if prm.walk_level >= 2 else NULL)
    if pn != NULL:
        eppf_pack_rows(n, pts, ps, nrm, ns, pv if prm.walk_level >= 2 and prm.n4 > 1 else NULL,
                       vox if prm.f123_level <= 1 and prm.n4 > 1 else NULL, pn)
    if skipping:
        eppf_code_grid(bits, prm.grid, code + CODE_SCRATCH, code)
        memset(lanes, 0, sizeof(lanes))
    elif port and prm.walk_level == 1:
        eppf_port_code_grid_avx2(bits, prm.grid, code + EPPF_PORT_CODE_WORDS, code)
    elif port:
        eppf_port_code_grid(bits, prm.grid, code + EPPF_PORT_CODE_WORDS, code)
    base = 0
    while base < n_pairs:
        m = n_pairs - base
        if m > batch:
            m = batch
        if vec_draw:
            eppf_draw_batch_at(prm.f123_level, <int>m, state, <uint32_t>n, pair_i, pair_j)
        else:
            for t in range(m):
                if _draw_pair(pts, ps, <uint32_t>n, &state, &i, &j) != 0:
                    return 1
                pair_i[t] = <int32_t>i
                pair_j[t] = <int32_t>j
        # f1-f3 (levels 0, 1 and 3: with the f4 walk setup); the passes also
        # find the first pair whose points coincide (none among scalar draws)
        first_same = <int>m
        if skipping:
            first_same = eppf_f123q_avx512(<int>m, pair_i, pair_j, scale, prm.n1, prm.n2, prm.n3, prm.n4,
                                           prm.f1_density, prm.cos2, prm.cos3, pn, prm.thr, prm.first_states,
                                           queue_pos, queue_inc, queue_state, &n_queued, counts)
        elif prm.f123_level == 2:
            first_same = eppf_f123_batch_avx512(<int>m, pair_i, pair_j, pts, ps, nrm, ns, scale, prm.n1, prm.n2,
                                                prm.n3, prm.n4, prm.f1_density, prm.cos2, prm.cos3, pair_bins, pn)
        else:
            first_same = eppf_f123q(prm.f123_level, <int>m, pair_i, pair_j, pts, ps, nrm, ns, vox, prm.grid, scale,
                                    prm.n1, prm.n2, prm.n3, prm.n4, prm.f1_density, prm.cos2, prm.cos3,
                                    prm.first_states, prm.thr, prm.recip_packed, pn, pair_bins,
                                    queue_pos if port else NULL,
                                    queue_inc, queue_state, &n_queued, counts)
        if vec_draw:
            if first_same < m:
                vec_draw = False
                m = first_same
            state += <uint64_t>m * EPPF_SM_GAMMA
            if m == 0:
                continue
        base += m
        # Literal grid sizes let the compiler turn the index arithmetic into shifts.
        if skipping:
            eppf_f4_walkq_avx512(n_queued, queue_pos, queue_inc, queue_state, code, prm.grid, prm.thr, prm.n4,
                                 lanes, 0, counts)
            continue
        if port and prm.walk_level == 1:
            eppf_port_walk_avx2(n_queued, queue_pos, queue_inc, queue_state, code, prm.thr, prm.n4, done, counts)
            continue
        if port:
            eppf_port_walk(n_queued, queue_pos, queue_inc, queue_state, code, prm.thr, prm.n4, done, counts)
            continue
        if prm.n4 > 1:
            if prm.walk_level >= 2:
                eppf_f4_batch_avx512(<int>m, pair_i, pair_j, pv, bits, prm.grid, prm.thr, prm.n4, prm.lohi,
                                     prm.recip_packed, pair_bins)
            elif prm.grid == PACKED_GRID:
                for t in range(m):
                    pair_bins[t] += _line_bin(vox + 3 * pair_i[t], vox + 3 * pair_j[t], prm, bits, PACKED_GRID, 1,
                                              True, &occ, &total)
            elif row_words == 1:
                for t in range(m):
                    pair_bins[t] += _line_bin(vox + 3 * pair_i[t], vox + 3 * pair_j[t], prm, bits, prm.grid, 1,
                                              True, &occ, &total)
            else:
                for t in range(m):
                    pair_bins[t] += _line_bin(vox + 3 * pair_i[t], vox + 3 * pair_j[t], prm, bits, prm.grid,
                                              row_words, True, &occ, &total)
        for t in range(m):
            counts[pair_bins[t]] += 1
    if skipping:
        eppf_f4_walkq_avx512(0, queue_pos, queue_inc, queue_state, code, prm.grid, prm.thr, prm.n4, lanes, 1,
                             counts)
    return 0


cdef void _init_params(Params* prm, int n1, int n2, int n3, int n4, int grid, double f1_max,
                       const int64_t* recip, const int32_t* thr):
    cdef int k
    prm.recip = recip
    prm.thr = thr
    prm.recip_packed[0] = 0.0
    for k in range(1, PACKED_GRID):
        prm.recip_packed[k] = (<double>PK_S) / k
    prm.n1 = n1
    prm.n2 = n2
    prm.n3 = n3
    prm.n4 = n4
    prm.grid = grid
    prm.walk_level = _level if grid <= PACKED_GRID else 0
    for k in range(PACKED_GRID + 2):
        prm.lohi[k] = 0
        if n4 > 1 and k <= grid + 1:
            prm.lohi[k] = ((<int64_t>thr[k * n4 + 1]) << EPPF_META_LO) | ((<int64_t>thr[k * n4 + n4 - 1]) << EPPF_META_HI)
    if n4 > 1:
        eppf_walk_states(thr, n4, grid, prm.first_states)  # (every entry; unused where n4 = 1)
    else:
        memset(prm.first_states, 0, sizeof(prm.first_states))
    prm.f123_level = _level if _level < 2 else 2
    prm.f1_max = f1_max
    prm.f1_density = n1 / f1_max
    for k in range(1, n2):
        prm.cos2[k - 1] = cos(k * M_PI / n2)
    for k in range(1, n3):
        prm.cos3[k - 1] = cos(k * (M_PI / 2) / n3)


def _check_bins(n_bins, int grid):
    if len(n_bins) != 4:
        raise ValueError("n_bins must have four entries")
    for b in n_bins:
        if not MIN_BINS <= b <= MAX_BINS:
            raise ValueError(f"each bin count must lie in [{MIN_BINS}, {MAX_BINS}]")
    if not MIN_GRID <= grid <= MAX_GRID:
        raise ValueError(f"grid_size must lie in [{MIN_GRID}, {MAX_GRID}]")


def _tables(int grid, int n4):
    """Line-walk reciprocals floor(2**32 / L), L = 0..grid (entry 0 unused), and
    f4 thresholds ceil(b * T / n4) laid out as [T, b], T = 0..grid + 1."""
    recip = np.zeros(grid + 1, dtype=np.int64)
    recip[1:] = np.int64(2**32) // np.arange(1, grid + 1, dtype=np.int64)
    T = np.arange(grid + 2, dtype=np.int64)[:, None]
    b = np.arange(max(n4, 2), dtype=np.int64)[None, :]
    thr = np.ascontiguousarray(-((-b * T) // n4), dtype=np.int32)
    return recip, thr


def _rows_of_doubles(a, what):
    """``a`` as float64 rows whose first three columns are contiguous (a view when it already is)."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 3:
        raise ValueError(f"{what} must have shape (N, 3) or wider")
    if a.strides[1] != 8 or a.strides[0] < 24 or a.strides[0] % 8:
        a = np.ascontiguousarray(a[:, :3])
    return a


def eppf_counts(points_in, normals_in,
                const int64_t[::1] offsets, const double[::1] scales,
                const uint64_t[::1] seeds, int n_pairs, n_bins, int grid_size,
                double f1_max, int num_threads):
    """Unweighted EPPF histograms (counts) of every object.

    Parameters
    ----------
    points_in, normals_in : (N, 3) float64, normals unit length; wider rows
        (e.g. the two halves of one (N, 6) array) are read in place as long as
        their first three columns are contiguous.
    offsets : (n_objects + 1,) int64.
    scales : (n_objects,) float64, multiplies distances for f1.
    seeds : (n_objects,) uint64, one generator seed per object.
    n_pairs : pairs drawn per object.
    n_bins : four bin counts; 1 switches a function off.
    grid_size, f1_max, num_threads : see module docstring.

    Returns
    -------
    counts : (n_objects, prod(n_bins)) int32
    status : (n_objects,) int32, non-zero where an object had too few
        distinct points to draw pairs.
    """
    _check_bins(n_bins, grid_size)
    cdef const double[:, :] points = _rows_of_doubles(points_in, "points")
    cdef const double[:, :] normals = _rows_of_doubles(normals_in, "normals")
    if normals.shape[0] != points.shape[0] or offsets.shape[0] < 1 or offsets[offsets.shape[0] - 1] > points.shape[0]:
        raise ValueError("points, normals and offsets do not match")
    if offsets[0] < 0 or np.any(np.diff(np.asarray(offsets)) < 0):
        raise ValueError("offsets must be non-decreasing from a non-negative start")
    if scales.shape[0] < offsets.shape[0] - 1 or seeds.shape[0] < offsets.shape[0] - 1:
        raise ValueError("scales and seeds need one entry per object")
    cdef int64_t ps = points.strides[0] // 8, ns = normals.strides[0] // 8
    recip_arr, thr_arr = _tables(grid_size, n_bins[3])
    cdef const int64_t[::1] recip = recip_arr
    cdef const int32_t[:, ::1] thr = thr_arr
    cdef Params prm
    _init_params(&prm, n_bins[0], n_bins[1], n_bins[2], n_bins[3], grid_size, f1_max, &recip[0], &thr[0, 0])
    cdef Py_ssize_t n_obj = offsets.shape[0] - 1
    cdef Py_ssize_t n_feat = n_bins[0] * n_bins[1] * n_bins[2] * n_bins[3]
    if num_threads < 1:
        num_threads = 1
    cdef Py_ssize_t words = _grid_words(grid_size)
    counts_arr = np.zeros((n_obj, n_feat), dtype=np.int32)
    status_arr = np.zeros(n_obj, dtype=np.int32)
    if n_obj == 0:
        return counts_arr, status_arr
    cdef int64_t max_n = np.max(np.diff(offsets))
    grids_arr = np.zeros((num_threads, words), dtype=np.uint64)
    # (one int32 more: level 1's walk setup reads a point's voxel as 16 bytes where it has no rows)
    vox_arr = np.zeros((num_threads, 3 * max_n + 1), dtype=np.int32)
    pv_arr = np.zeros((num_threads, max_n if prm.walk_level >= 2 else 1), dtype=np.int64)
    # the skipping walks' cone grids and their scratch: level 3's (scratch between the grids' halves;
    # the walk reads any of the first CODE_READ_WORDS words) or the portable walk's (levels 0 and 1)
    code_arr = np.zeros((num_threads, CODE_READ_WORDS if prm.walk_level == 3
                         else EPPF_PORT_WORDS if _port_walk(&prm) else 1), dtype=np.uint64)
    # the f1-f3 passes' rows of points, normals and voxels (8 doubles a point; objects up to ROWS_MAX_POINTS
    # points, larger ones are read in place)
    cdef bint use_rows = max_n <= ROWS_MAX_POINTS
    # (each thread's rows start on a 64-byte boundary, so that no row straddles two cache lines)
    pn_buf = np.zeros(num_threads * (8 * max_n + 8) + 8 if use_rows else 8, dtype=np.float64)
    cdef Py_ssize_t pn_skip = (-(pn_buf.ctypes.data // 8)) % 8
    pn_arr = pn_buf[pn_skip : pn_skip + num_threads * (8 * max_n + 8)].reshape(num_threads, -1) if use_rows \
        else pn_buf[:8].reshape(1, 8)
    cdef int32_t[:, ::1] counts = counts_arr
    cdef int32_t[::1] status = status_arr
    cdef uint64_t[:, ::1] grids = grids_arr
    cdef int32_t[:, ::1] vox = vox_arr
    cdef int64_t[:, ::1] pv = pv_arr
    cdef uint64_t[:, ::1] code = code_arr
    cdef double[:, ::1] pn = pn_arr
    cdef Py_ssize_t k, tid
    cdef int64_t start
    with nogil:
        for k in prange(n_obj, num_threads=num_threads, schedule="dynamic", chunksize=1):
            start = offsets[k]
            tid = threadid()
            status[k] = _object_counts(&points[start, 0], ps, &normals[start, 0], ns,
                                       offsets[k + 1] - start, scales[k], seeds[k], n_pairs,
                                       &prm, &grids[tid, 0], &vox[tid, 0], &pv[tid, 0], &code[tid, 0],
                                       &pn[tid, 0] if use_rows else NULL, &counts[k, 0])
    return counts_arr, status_arr


def eppf_pairs(const double[:, ::1] points, uint64_t seed, int n_pairs):
    """The ordered pairs (i, j) that ``eppf_counts`` draws for one object.

    Exposed so tests can rebuild a histogram independently from the same pairs.
    """
    cdef int64_t n = points.shape[0]
    out_arr = np.empty((n_pairs, 2), dtype=np.int64)
    cdef int64_t[:, ::1] out = out_arr
    cdef uint64_t state = seed
    cdef int64_t t, i, j
    if n < 2 and n_pairs > 0:
        raise ValueError("too few distinct points to draw pairs")
    for t in range(n_pairs):
        if _draw_pair(&points[0, 0], 3, <uint32_t>n, &state, &i, &j) != 0:
            raise ValueError("too few distinct points to draw pairs")
        out[t, 0] = i
        out[t, 1] = j
    return out_arr


def eppf_pair_features(const double[:, ::1] points, const double[:, ::1] normals,
                       const int64_t[:, ::1] pairs, double scale, n_bins,
                       int grid_size, double f1_max):
    """Per-pair bins for one object and given pairs.

    Returns an (n_pairs, 6) int64 array: the four bin indices, then the
    occupied and total voxel counts of f4 (0 when f4 is off).
    """
    _check_bins(n_bins, grid_size)
    recip_arr, thr_arr = _tables(grid_size, n_bins[3])
    cdef const int64_t[::1] recip = recip_arr
    cdef const int32_t[:, ::1] thr = thr_arr
    cdef Params prm
    _init_params(&prm, n_bins[0], n_bins[1], n_bins[2], n_bins[3], grid_size, f1_max, &recip[0], &thr[0, 0])
    cdef int64_t n_p = pairs.shape[0], t
    vox_arr = np.zeros((points.shape[0], 3), dtype=np.int32)
    cdef int32_t[:, ::1] vox = vox_arr
    cdef Py_ssize_t words = _grid_words(grid_size)
    grid_arr = np.zeros(words, dtype=np.uint64)
    cdef uint64_t[::1] bits = grid_arr
    out_arr = np.zeros((n_p, 6), dtype=np.int64)
    cdef int64_t[:, ::1] out = out_arr
    cdef int parts[6]
    cdef int64_t n
    n = points.shape[0]
    if n == 0 or normals.shape[0] != n or pairs.shape[1] != 2:
        raise ValueError("points and normals must have the same (non-zero) number of rows, pairs two columns")
    for t in range(n_p):
        if not (0 <= pairs[t, 0] < n and 0 <= pairs[t, 1] < n):
            raise ValueError("pair indices out of range")
    _fill_grid(&points[0, 0], 3, n, grid_size, &bits[0], &vox[0, 0], NULL)
    for t in range(n_p):
        _bin_f123(&points[0, 0], 3, &normals[0, 0], 3, pairs[t, 0], pairs[t, 1], scale, &prm, parts)
        parts[3] = parts[4] = parts[5] = 0
        if prm.n4 > 1:
            parts[3] = _line_bin(&vox[pairs[t, 0], 0], &vox[pairs[t, 1], 0], &prm, &bits[0],
                                 grid_size, _row_words(grid_size), False, &parts[4], &parts[5])
        for k in range(6):
            out[t, k] = parts[k]
    return out_arr


cdef void _port_code_grid(const uint64_t* bits, int g, uint64_t[::1] buf):
    eppf_port_code_grid(bits, g, &buf[EPPF_PORT_CODE_WORDS], &buf[0])


def _cone_codes(occupied, portable=False):
    """The skipping walks' cone codes of an occupancy grid (tests).

    ``occupied``: (g, g, g) booleans, 2 <= g <= 64, indexed [x, y, z].
    Returns a (3, g, g, g) uint8 array: entry [a, x, y, z] is min(C, 3), C
    the number of planes of the cone along axis a from voxel (x, y, z) on
    with no occupied voxel, as built for level 3 (``eppf_code_grid`` in
    ``_eppf_walk_skip.h``; needs the AVX-512 kernels) or, with ``portable``,
    for levels 0 and 1 (``eppf_port_code_grid`` in ``_eppf_walk_port.h``).
    """
    occ = np.asarray(occupied, dtype=bool)
    if (occ.ndim != 3 or occ.shape[0] != occ.shape[1] or occ.shape[0] != occ.shape[2]
            or not MIN_GRID <= occ.shape[0] <= PACKED_GRID):
        raise ValueError(f"occupied must be a (g, g, g) grid with {MIN_GRID} <= g <= {PACKED_GRID}")
    if not portable and _max_level() < 3:
        raise ValueError("the cone codes need the AVX-512 kernels, which this CPU lacks")
    cdef int g = occ.shape[0]
    packed = np.zeros((g, g, 8), dtype=np.uint8)
    packed[:, :, : (g + 7) // 8] = np.packbits(occ, axis=2, bitorder="little")
    cdef uint64_t[::1] bits = np.ascontiguousarray(packed.reshape(-1).view(np.uint64))
    z = np.arange(g)
    if portable:
        port_arr = np.zeros(EPPF_PORT_WORDS, dtype=np.uint64)
        port_view = port_arr
        _port_code_grid(&bits[0], g, port_view)
        # words 2 r and 2 r + 1, r = CODE_AXIS_WORDS a + 64 x + y: the code's bits 0 and 1 at bit z
        rows = port_arr[: 2 * 3 * CODE_AXIS_WORDS].reshape(3, 64, 64, 2)[:, :g, :g]
        shift = z.astype(np.uint64)
        bit0 = (rows[..., 0, None] >> shift) & 1
        bit1 = (rows[..., 1, None] >> shift) & 1
        return (bit0 + 2 * bit1).astype(np.uint8)
    code_arr = np.zeros(CODE_READ_WORDS, dtype=np.uint64)
    cdef uint64_t[::1] code = code_arr
    eppf_code_grid(&bits[0], g, &code[CODE_SCRATCH], &code[0])
    # word CODE_AXIS_WORDS a + 64 x + y holds z < 32, the same word CODE_HALF on z >= 32
    halves = [code_arr[h : h + 3 * CODE_AXIS_WORDS].reshape(3, 64, 64)[:, :g, :g] for h in (0, CODE_HALF)]
    words = np.stack(halves, axis=-1)
    return ((words[..., z >> 5] >> (2 * (z & 31)).astype(np.uint64)) & 3).astype(np.uint8)
