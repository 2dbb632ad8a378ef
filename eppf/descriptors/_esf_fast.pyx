# cython: language_level=3
"""Compiled kernels of ESF (Wohlkinger & Vincze 2011).

Python allocates every array (outputs and per-thread scratch); the kernels
fill them. Work is parallel over objects (``prange``); each object has a
private generator seeded from one 64-bit seed, so the output never depends on
the number of threads. An object whose samples cannot be drawn (for example
all points collinear) gets ``status[k] = 1`` and a zero row; the
Python layer turns that into a ``ValueError``.

ESF follows PCL 1.13's ``ESFEstimation`` (Wohlkinger & Vincze 2011): see
``eppf/descriptors/_esf.py`` for the description of every step.
"""
import numpy as np

cimport numpy as cnp
from cython.parallel cimport prange, threadid
from libc.math cimport sqrt, atan2, floor, ceil, fabs, M_PI
from libc.stdint cimport int8_t, int16_t, int32_t, int64_t, uint32_t, uint64_t
from libc.string cimport memset

from ..utils._common cimport splitmix64, rand_below
from ..utils._common cimport clamp_floor
from ..utils._scan_fast import check_batch

cdef extern from "_esf_kernel.h" nogil:
    enum:
        ESF_BATCH
        ESF_LAYOUT_WORDS
    ctypedef struct esf_const:
        int n_bins
        int grid
        double area_eps
        const double* edges
        const int32_t* lut
        double lut_scale
        int lut_on_cos
        const int32_t* rs
        const int32_t* st
        const int16_t* ratio_bin
        int simd
    ctypedef struct esf_state:
        const double* pts
        const int32_t* cells
        const uint64_t* g3
        int64_t* acc
        double* out
        double* d2v
        double* d3v
        int8_t* cls2
        int8_t* cls3
        double maxd2, maxd3
        int64_t attempts, max_attempts
        int t, n_triplets
    void esf_fill_layouts(const int32_t* cells, int64_t n, int grid, uint64_t* g3)
    void esf_fill_ratio_bins(int n_bins, int16_t* ratio_bin)
    int esf_take(const esf_const* k, esf_state* s, const uint32_t* i1, const uint32_t* i2,
                 const uint32_t* i3, int n_cand)
    void esf_finish(const esf_state* s, int n_bins, int simd)
    void esf_count_scaled(const double* v, const int8_t* cls, int64_t n, double vmax, double scale, int n_bins,
                          int64_t* acc, int simd)
    int esf_line_setup(int32_t a0, int32_t a1, int32_t a2, int32_t b0, int32_t b1, int32_t b2,
                       const int32_t* rs, const int32_t* st, uint64_t* pos_out, uint64_t* inc_out)
    int esf_walk(const uint64_t* g3, uint64_t pos, uint64_t inc, int n)
    int esf_has_avx2()
    void esf_walk_batch(const uint64_t* g3, const uint64_t* pos, const uint64_t* inc, const int* cnt,
                        int* occ, int n, int simd)

cnp.import_array()

# ESF's AVX2 kernels where the CPU has them (``esf_take_avx2``: the triplet
# batch compiled for AVX2, its line walks four at a time in vector lanes);
# ``_set_simd`` turns them off for tests. The results are identical.
cdef bint _esf_simd = esf_has_avx2() != 0


def _simd_enabled():
    """Whether ESF runs its AVX2 kernels."""
    return bool(_esf_simd)


def _set_simd(enabled):
    """Use (True, where the CPU allows) or avoid ESF's AVX2 kernels; returns
    the previous setting. The descriptors are identical either way."""
    global _esf_simd
    old = bool(_esf_simd)
    _esf_simd = bool(enabled) and esf_has_avx2() != 0
    return old

cdef enum:
    # ESF histograms, in PCL's order.
    A3_IN = 0
    A3_OUT = 1
    A3_MIX = 2
    D3_IN = 3
    D3_OUT = 4
    D3_MIX = 5
    D2_IN = 6
    D2_OUT = 7
    D2_MIX = 8
    D2_RATIO = 9
    # Line classes.
    LINE_IN = 0
    LINE_OUT = 1
    LINE_MIX = 2


cdef inline int _pcl_cell(double v, int half, int grid) noexcept nogil:
    """PCL's voxel of a coordinate in grid units centered on ``half``.

    Values at or below ``-half`` (and NaN) give 0, values at or above
    ``grid`` give ``grid - 1``, before any conversion to int, so every
    double maps into the grid; in between the value is PCL's.
    """
    cdef int c
    if not (v > -half):
        return 0
    if v >= grid:
        return grid - 1
    if v < 0.0:
        c = <int>floor(v) + half
    else:
        c = <int>ceil(v) + half - 1
    if c < 0:
        return 0
    if c >= grid:
        return grid - 1
    return c


cdef inline int _bit(const uint64_t* bits, int64_t idx) noexcept nogil:
    return <int>((bits[idx >> 6] >> (idx & 63)) & 1)


cdef inline int _lci(const uint64_t* bits, int grid, const int* a, const int* b,
                     const uint64_t* recip, int* n_in, int* n_total, double* ratio) noexcept nogil:
    """Classify the voxel line from ``a`` towards ``b`` like PCL's ``lci``.

    PCL walks a 3D Bresenham line along the dominant axis (length L) and
    visits max(L, 1) voxels: the start voxel and the next L - 1, not the end
    voxel. After k steps its offset along an axis of length D is exactly
    ``floor((2 D k + L - 1) / (2 L))`` (checked against PCL's loop for every
    L < 200; for the dominant axis it is k, so PCL's tie order between axes
    does not matter). Here every axis is walked in 32.32 fixed point with
    R = floor(2**32 / L) = ``recip[L]``:
    ``P_k = (L - 1) floor(R / 2) + L**2 + 2 + k D R``. The exact value
    X_k = (2 D k + L - 1) 2**31 / L exceeds the products by less than L**2
    units, so P_k lies in (X_k, X_k + L**2 + 2]; a non-integer X_k / 2**32 is
    a multiple of 1 / (2 L), at least 2**31 / L units below the next integer,
    so ``P_k >> 32`` is exact for L < 1290 (grids up to 1024). The dominant
    axis (offset k) simply steps by its stride.

    Returns LINE_IN when at most one visited voxel is empty, LINE_OUT when at
    most 7 are occupied, LINE_MIX otherwise (with ``ratio`` = occupied /
    visited).
    """
    cdef int64_t g = grid
    cdef int dx = b[0] - a[0], dy = b[1] - a[1], dz = b[2] - a[2]
    cdef int64_t sx = g * g, sy = g, sz = 1
    cdef int L, k, occ = 0, cnt
    cdef int64_t idx = a[0] * sx + a[1] * sy + a[2]
    cdef uint64_t R, px, py, pz, ix, iy, iz, start, i1, i2
    cdef int64_t smaj, s1, s2
    if dx < 0:
        dx = -dx
        sx = -sx
    if dy < 0:
        dy = -dy
        sy = -sy
    if dz < 0:
        dz = -dz
        sz = -sz
    L = dx
    if dy > L: L = dy
    if dz > L: L = dz
    if L <= 1:
        occ = _bit(bits, idx)
        cnt = 1
    else:
        cnt = L
        R = recip[L]
        start = <uint64_t>(L - 1) * (R >> 1) + <uint64_t>L * <uint64_t>L + 2
        # dominant axis steps by its stride; the other two in fixed point
        if L == dx:
            smaj = sx; s1 = sy; s2 = sz; i1 = <uint64_t>dy * R; i2 = <uint64_t>dz * R
        elif L == dy:
            smaj = sy; s1 = sx; s2 = sz; i1 = <uint64_t>dx * R; i2 = <uint64_t>dz * R
        else:
            smaj = sz; s1 = sx; s2 = sy; i1 = <uint64_t>dx * R; i2 = <uint64_t>dy * R
        px = start
        py = start
        for k in range(L):
            occ += _bit(bits, idx + (<int64_t>(px >> 32)) * s1 + (<int64_t>(py >> 32)) * s2)
            idx += smaj
            px += i1
            py += i2
    n_in[0] = occ
    n_total[0] = cnt
    if occ >= cnt - 1:
        return LINE_IN
    if occ <= 7:
        return LINE_OUT
    ratio[0] = <double>occ / <double>cnt
    return LINE_MIX


cdef inline int _angle_bin(double c, const double* edges, const int32_t* lut,
                           double lut_scale) noexcept nogil:
    """round((n_bins - 1) * arccos(c) / (pi / 2)) for c in [0, 1], without arccos.

    ``edges[j] = cos((j + 1/2) (pi/2) / (n_bins - 1))`` decrease (padded with
    -2); the bin is the number of edges not below ``c``. With
    u = sqrt((1 - c) / 2) = sin(angle / 2), nearly proportional to the angle,
    ``lut`` holds for each of its cells in u a lower bound of the bin that is
    at most one short (cells are narrower than a bin), fixed by one
    comparison.
    """
    cdef double u
    cdef int lo
    # c is clamped to [0, 1] (NaN to 1) first, so the table index stays in range.
    if not (c <= 1.0):
        c = 1.0
    elif not (c >= 0.0):
        c = 0.0
    u = sqrt((1.0 - c) * 0.5)
    lo = lut[<int>(u * lut_scale)]
    lo += edges[lo] >= c
    return lo


cdef inline int _round_bin(double v, int n_bins) noexcept nogil:
    """PCL's ``round(v * (n_bins - 1))`` for v in [0, 1], clipped.

    Truncation is the floor here (the argument is non-negative), and avoids
    a libm call.
    """
    return clamp_floor(v * (n_bins - 1) + 0.5, n_bins)


cdef inline double _abs_cos(double ax, double ay, double az,
                            double bx, double by, double bz, double norm) noexcept nogil:
    """|a . b| / norm, clipped to 1."""
    cdef double c = fabs(ax * bx + ay * by + az * bz) / norm
    return c if c < 1.0 else 1.0


cdef void _esf_centre(const double* points, int64_t start, int64_t n, int grid,
                      double* pts, int32_t* cells) noexcept nogil:
    """Center on the mean, scale the farthest point to radius grid / 2, voxels."""
    cdef int64_t i
    cdef int half = grid // 2
    cdef double cx = 0.0, cy = 0.0, cz = 0.0, r2, rmax = 0.0, sc
    for i in range(n):
        cx += points[3 * (start + i) + 0]
        cy += points[3 * (start + i) + 1]
        cz += points[3 * (start + i) + 2]
    cx /= n
    cy /= n
    cz /= n
    for i in range(n):
        pts[3 * i] = points[3 * (start + i) + 0] - cx
        pts[3 * i + 1] = points[3 * (start + i) + 1] - cy
        pts[3 * i + 2] = points[3 * (start + i) + 2] - cz
        r2 = pts[3 * i] * pts[3 * i] + pts[3 * i + 1] * pts[3 * i + 1] + pts[3 * i + 2] * pts[3 * i + 2]
        if r2 > rmax:
            rmax = r2
    sc = half / sqrt(rmax)
    for i in range(3 * n):
        pts[i] *= sc
        cells[i] = _pcl_cell(pts[i], half, grid)


cdef int _esf_object_fast(const double* points, int64_t start, int64_t n,
                          uint64_t seed, int n_triplets, const esf_const* kc,
                          double* pts, int32_t* cells, uint64_t* g3, int64_t* acc,
                          double* d2v, double* d3v, int8_t* cls2, int8_t* cls3,
                          double* out) noexcept nogil:
    """One object's ESF for grids up to 64 (``eppf/_esf_kernel.h``)."""
    cdef esf_state st
    cdef uint32_t i1[ESF_BATCH]
    cdef uint32_t i2[ESF_BATCH]
    cdef uint32_t i3[ESF_BATCH]
    cdef uint64_t state = seed
    cdef int j
    _esf_centre(points, start, n, kc.grid, pts, cells)
    esf_fill_layouts(cells, n, kc.grid, g3)
    memset(acc, 0, 19 * kc.n_bins * sizeof(int64_t))
    st.pts = pts
    st.cells = cells
    st.g3 = g3
    st.acc = acc
    st.out = out
    st.d2v = d2v
    st.d3v = d3v
    st.cls2 = cls2
    st.cls3 = cls3
    st.maxd2 = 0.0
    st.maxd3 = 0.0
    st.attempts = 0
    st.max_attempts = 1000 + <int64_t>200 * n_triplets
    st.t = 0
    st.n_triplets = n_triplets
    while st.t < n_triplets:
        # candidates in the generator's order; the kernel takes them in order
        for j in range(ESF_BATCH):
            i1[j] = rand_below(&state, <uint32_t>n)
            i2[j] = rand_below(&state, <uint32_t>n)
            i3[j] = rand_below(&state, <uint32_t>n)
        if esf_take(kc, &st, i1, i2, i3, ESF_BATCH):
            return 1
    esf_finish(&st, kc.n_bins, kc.simd)
    return 0


cdef int _esf_object(const double* points, int64_t start, int64_t n,
                     uint64_t seed, int n_triplets, int grid, int n_bins,
                     double area_eps, const double* edges, const int32_t* lut, double lut_scale,
                     const uint64_t* recip,
                     double* pts, int32_t* cells, uint64_t* bits, double* d2v, double* d3v,
                     int8_t* cls2, int8_t* cls3, double* out) noexcept nogil:
    """One object's ESF into ``out`` (10 * n_bins, zeroed), triplet by triplet,
    for any grid size. Returns a status."""
    cdef int64_t i, k, idx, n_words
    cdef int cell[3]
    cdef int c1[3]
    cdef int c2[3]
    cdef int c3[3]
    cdef int x, y, z, ax
    cdef uint64_t state = seed
    cdef int64_t attempts = 0, max_attempts = 1000 + <int64_t>200 * n_triplets
    cdef uint32_t i1, i2, i3
    cdef double a, b, c, s, heron, inv
    cdef double v21x, v21y, v21z, v31x, v31y, v31z, v23x, v23y, v23z
    cdef int th1, th2, th3, w12, w13, w23
    cdef int in12, in13, in23, n12, n13, n23, in_sum, n_sum
    cdef double ratio = 0.0, maxd2 = 0.0, maxd3 = 0.0, total
    cdef int t = 0
    cdef double weights[10]
    _esf_centre(points, start, n, grid, pts, cells)
    # Occupancy: every point's voxel and its 26 neighbors (PCL's voxelize9).
    n_words = (<int64_t>grid * grid * grid + 63) // 64
    memset(bits, 0, n_words * sizeof(uint64_t))
    for i in range(n):
        for ax in range(3):
            cell[ax] = cells[3 * i + ax]
        for x in range(cell[0] - 1, cell[0] + 2):
            if x < 0 or x >= grid:
                continue
            for y in range(cell[1] - 1, cell[1] + 2):
                if y < 0 or y >= grid:
                    continue
                for z in range(cell[2] - 1, cell[2] + 2):
                    if z < 0 or z >= grid:
                        continue
                    idx = (<int64_t>x * grid + y) * grid + z
                    bits[idx >> 6] |= (<uint64_t>1) << (idx & 63)
    while t < n_triplets:
        attempts += 1
        if attempts > max_attempts:
            return 1
        i1 = rand_below(&state, <uint32_t>n)
        i2 = rand_below(&state, <uint32_t>n)
        i3 = rand_below(&state, <uint32_t>n)
        if i1 == i2 or i1 == i3 or i2 == i3:
            continue
        v21x = pts[3 * i2] - pts[3 * i1]
        v21y = pts[3 * i2 + 1] - pts[3 * i1 + 1]
        v21z = pts[3 * i2 + 2] - pts[3 * i1 + 2]
        v31x = pts[3 * i3] - pts[3 * i1]
        v31y = pts[3 * i3 + 1] - pts[3 * i1 + 1]
        v31z = pts[3 * i3 + 2] - pts[3 * i1 + 2]
        v23x = pts[3 * i2] - pts[3 * i3]
        v23y = pts[3 * i2 + 1] - pts[3 * i3 + 1]
        v23z = pts[3 * i2 + 2] - pts[3 * i3 + 2]
        a = sqrt(v21x * v21x + v21y * v21y + v21z * v21z)
        b = sqrt(v31x * v31x + v31y * v31y + v31z * v31z)
        c = sqrt(v23x * v23x + v23y * v23y + v23z * v23z)
        s = (a + b + c) * 0.5
        heron = s * (s - a) * (s - b) * (s - c)
        if heron <= area_eps:
            continue
        # A3: the triangle's angles folded into [0, pi/2] (|cos|).
        th1 = _angle_bin(_abs_cos(v21x, v21y, v21z, v31x, v31y, v31z, a * b), edges, lut, lut_scale)
        th2 = _angle_bin(_abs_cos(v23x, v23y, v23z, v31x, v31y, v31z, c * b), edges, lut, lut_scale)
        th3 = _angle_bin(_abs_cos(v23x, v23y, v23z, v21x, v21y, v21z, c * a), edges, lut, lut_scale)
        # D2 and the three lines.
        for ax in range(3):
            c1[ax] = cells[3 * i1 + ax]
            c2[ax] = cells[3 * i2 + ax]
            c3[ax] = cells[3 * i3 + ax]
        d2v[3 * t] = a
        d2v[3 * t + 1] = b
        d2v[3 * t + 2] = c
        w12 = _lci(bits, grid, c1, c2, recip, &in12, &n12, &ratio)
        if w12 == LINE_MIX:
            out[D2_RATIO * n_bins + _round_bin(ratio, n_bins)] += 1.0
        w13 = _lci(bits, grid, c1, c3, recip, &in13, &n13, &ratio)
        if w13 == LINE_MIX:
            out[D2_RATIO * n_bins + _round_bin(ratio, n_bins)] += 1.0
        w23 = _lci(bits, grid, c2, c3, recip, &in23, &n23, &ratio)
        if w23 == LINE_MIX:
            out[D2_RATIO * n_bins + _round_bin(ratio, n_bins)] += 1.0
        cls2[3 * t] = <int8_t>w12
        cls2[3 * t + 1] = <int8_t>w13
        cls2[3 * t + 2] = <int8_t>w23
        # D3: square root of the area; the triangle's class from its lines.
        d3v[t] = sqrt(sqrt(heron))
        in_sum = in12 + in13 + in23
        n_sum = n12 + n13 + n23
        if in_sum <= 21:
            k = LINE_OUT
        elif n_sum - in_sum < 4:
            k = LINE_IN
        else:
            k = LINE_MIX
        cls3[t] = <int8_t>k
        k = A3_IN + k
        # Each angle weighted by the voxel count of the opposite side / 32.
        out[k * n_bins + th1] += n23 / 32.0
        out[k * n_bins + th2] += n12 / 32.0
        out[k * n_bins + th3] += n13 / 32.0
        if a > maxd2: maxd2 = a
        if b > maxd2: maxd2 = b
        if c > maxd2: maxd2 = c
        if d3v[t] > maxd3: maxd3 = d3v[t]
        t += 1
    # Histogram k = first histogram of the family + line class (0 in, 1 out, 2 mixed).
    for i in range(n_triplets):
        k = D3_IN + cls3[i]
        out[k * n_bins + _round_bin(d3v[i] / maxd3, n_bins)] += 1.0
    for i in range(3 * <int64_t>n_triplets):
        k = D2_IN + cls2[i]
        out[k * n_bins + _round_bin(d2v[i] / maxd2, n_bins)] += 1.0
    # PCL's weights (the D2-in and ratio halves folded in), then sum to one.
    weights[A3_IN] = 0.5
    weights[A3_OUT] = 0.5
    weights[A3_MIX] = 0.5
    weights[D3_IN] = 0.5
    weights[D3_OUT] = 0.5
    weights[D3_MIX] = 1.0
    weights[D2_IN] = 0.5
    weights[D2_OUT] = 2.0
    weights[D2_MIX] = 2.0
    weights[D2_RATIO] = 1.0
    total = 0.0
    for k in range(10):
        for i in range(n_bins):
            out[k * n_bins + i] *= weights[k]
            total += out[k * n_bins + i]
    inv = 1.0 / total
    for i in range(10 * n_bins):
        out[i] *= inv
    return 0


#: Limits of :func:`esf_batch`'s parameters (the transformer's constraints read them): an
#: even grid side in [MIN_GRID, MAX_GRID], at most MAX_BINS bins per histogram and at most
#: MAX_TRIPLETS triplets (a C int counts the triplets, and 3 n_triplets side lengths are
#: kept per thread: 2**29 leaves that count and its multiples below 2**31).
MIN_GRID = 4
MAX_GRID = 1024
MAX_BINS = 4096
MAX_TRIPLETS = 2**31 // 4


def esf_batch(const double[:, ::1] points, const int64_t[::1] offsets,
              const uint64_t[::1] seeds, int n_triplets, int grid, int n_bins,
              double area_eps, double[:, ::1] out, int8_t[::1] status,
              int num_threads):
    """Fill ``out`` (n_objects, 10 * n_bins) with ESF histograms.

    Parameters are validated by the caller. ``area_eps`` is the threshold on
    Heron's s(s-a)(s-b)(s-c) (grid units) under which a triplet is redrawn.
    Grids up to 64 go through the batched kernel of ``_esf_kernel.h``, larger
    ones through ``_esf_object``; both give the same histograms.
    """
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1
    cdef Py_ssize_t k
    cdef int64_t max_n = 0
    cdef int tid
    cdef bint fast = grid <= 64
    if points.shape[1] != 3:
        raise ValueError("esf_batch: points must be (N, 3)")
    check_batch(points.shape[0], offsets, seeds, out, status, 10 * n_bins, "esf_batch")
    if not (MIN_GRID <= grid <= MAX_GRID and grid % 2 == 0 and 1 <= n_bins <= MAX_BINS
            and 1 <= n_triplets <= MAX_TRIPLETS):
        raise ValueError(f"esf_batch: grid must be even in [{MIN_GRID}, {MAX_GRID}], n_bins in [1, {MAX_BINS}], "
                         f"n_triplets in [1, {MAX_TRIPLETS}]")
    num_threads = max(1, num_threads)
    for k in range(n_objects):
        if offsets[k + 1] - offsets[k] > max_n:
            max_n = offsets[k + 1] - offsets[k]
    cdef int64_t n_words = 3 * ESF_LAYOUT_WORDS if fast else (<int64_t>grid * grid * grid + 63) // 64
    cdef double[:, ::1] pts = np.empty((num_threads, 3 * max_n), dtype=np.float64)
    cdef int32_t[:, ::1] cells = np.empty((num_threads, 3 * max_n), dtype=np.int32)
    cdef uint64_t[:, ::1] bits = np.empty((num_threads, n_words), dtype=np.uint64)
    cdef int64_t[:, ::1] acc = np.empty((num_threads, 19 * n_bins), dtype=np.int64)
    cdef double[:, ::1] d2v = np.empty((num_threads, 3 * <int64_t>n_triplets), dtype=np.float64)
    cdef double[:, ::1] d3v = np.empty((num_threads, n_triplets), dtype=np.float64)
    cdef int8_t[:, ::1] cls2 = np.empty((num_threads, 3 * <int64_t>n_triplets), dtype=np.int8)
    cdef int8_t[:, ::1] cls3 = np.empty((num_threads, n_triplets), dtype=np.int8)
    # A3 bin edges on the cosine scale, padded with -2 to a power of two.
    cdef int n_pow2 = 1
    while n_pow2 < n_bins:
        n_pow2 *= 2
    edges_arr = np.full(n_pow2, -2.0)
    edges_arr[: n_bins - 1] = np.cos((np.arange(n_bins - 1) + 0.5) / max(n_bins - 1, 1) * (np.pi / 2))
    cdef double[::1] edges = edges_arr
    cdef int32_t[::1] lut
    cdef int32_t[::1] lut_u
    cdef double lut_scale, lut_u_scale
    cdef int lut_on_cos
    lut_u, lut_u_scale = _a3_table_sin(edges_arr, n_pow2)
    cos_table = _a3_table_cos(edges_arr, n_bins)
    if cos_table is None:
        lut, lut_scale, lut_on_cos = lut_u, lut_u_scale, 0
    else:
        lut, lut_scale, lut_on_cos = cos_table[0], cos_table[1], 1
    # recip[L] = floor(2**32 / L) for the general line walk.
    recip_arr = np.zeros(grid + 1, dtype=np.uint64)
    recip_arr[1:] = (2**32) // np.arange(1, grid + 1, dtype=np.uint64)
    cdef uint64_t[::1] recip = recip_arr
    rs_arr, st_arr = _walk_tables()
    cdef int32_t[::1] rs = rs_arr
    cdef int32_t[::1] st = st_arr
    cdef int16_t[::1] ratio_bin = np.empty(64 * 64, dtype=np.int16)
    esf_fill_ratio_bins(n_bins, &ratio_bin[0])
    cdef esf_const kc
    kc.n_bins = n_bins
    kc.grid = grid
    kc.area_eps = area_eps
    kc.edges = &edges[0]
    kc.lut = &lut[0]
    kc.lut_scale = lut_scale
    kc.lut_on_cos = lut_on_cos
    kc.rs = &rs[0]
    kc.st = &st[0]
    kc.ratio_bin = &ratio_bin[0]
    kc.simd = _esf_simd
    for k in prange(n_objects, nogil=True, schedule="dynamic", num_threads=num_threads):
        tid = threadid()
        if offsets[k + 1] - offsets[k] < 3:  # no triangle (the draws would read past the object)
            status[k] = 1
        elif fast:
            status[k] = <int8_t>_esf_object_fast(
                &points[0, 0], offsets[k], offsets[k + 1] - offsets[k], seeds[k], n_triplets,
                &kc, &pts[tid, 0], &cells[tid, 0], &bits[tid, 0], &acc[tid, 0], &d2v[tid, 0],
                &d3v[tid, 0], &cls2[tid, 0], &cls3[tid, 0], &out[k, 0])
        else:
            status[k] = <int8_t>_esf_object(
                &points[0, 0], offsets[k], offsets[k + 1] - offsets[k], seeds[k], n_triplets,
                grid, n_bins, area_eps, &edges[0], &lut_u[0], lut_u_scale, &recip[0], &pts[tid, 0],
                &cells[tid, 0], &bits[tid, 0], &d2v[tid, 0], &d3v[tid, 0], &cls2[tid, 0],
                &cls3[tid, 0], &out[k, 0])
        if status[k] != 0:
            memset(&out[k, 0], 0, 10 * n_bins * sizeof(double))


def _walk_tables():
    """rs[L] = floor(2**22 / L) and st[L] = (L - 1) floor(rs[L] / 2) + L**2 + 2,
    L = 0..64, the packed line walk's increments and start offsets."""
    L = np.arange(65, dtype=np.int64)
    rs = np.zeros(65, dtype=np.int64)
    rs[1:] = (2**22) // L[1:]
    st = (L - 1) * (rs >> 1) + L * L + 2
    return rs.astype(np.int32), st.astype(np.int32)


def _a3_table_sin(edges_arr, int n_pow2):
    """A3 table over u = sqrt((1 - c) / 2) in [0, sin(pi/4)].

    2 * n_pow2 cells, each narrower than a bin (the angle is 2 asin(u), whose
    slope is at most 2 sqrt(2), so a cell spans at most 1 / n_pow2 radians, a
    bin (pi/2) / (n_bins - 1)); each entry is the number of edges not below
    the cosine at the cell's start taken a hundredth of a cell lower, against
    rounding: a lower bound of the bin at most one short.
    """
    n_cells = 2 * n_pow2
    scale = n_cells / np.sqrt(0.5)
    u_lo = np.maximum(np.arange(n_cells + 1) - 0.01, 0.0) / scale
    c_hi = 1.0 - 2.0 * u_lo * u_lo
    return (edges_arr[None, :] >= c_hi[:, None]).sum(axis=1).astype(np.int32), scale


def _a3_table_cos(edges_arr, int n_bins, int max_cells=65536):
    """A3 table over the cosine c in [0, 1], or None when it would be too large.

    N cells (a power of two) at most half as wide as the narrowest gap between
    edges, so a cell with a 1e-12 margin either side holds at most one edge;
    entry j counts the edges at or above (j + 1) / N + 1e-12: a lower bound
    of the bin for every c with int(c * N) == j, at most one short.
    """
    inner = edges_arr[: max(n_bins - 1, 0)]
    gap = np.min(-np.diff(inner)) if inner.size > 1 else 1.0
    n_cells = 1
    while n_cells < 2.0 / gap:
        n_cells *= 2
        if n_cells > max_cells:
            return None
    hi = (np.arange(n_cells + 1) + 1.0) / n_cells + 1e-12
    return np.searchsorted(-edges_arr, -hi, side="right").astype(np.int32), float(n_cells)


def esf_line_counts(const int32_t[:, ::1] occupied, const int32_t[:, ::1] starts,
                    const int32_t[:, ::1] ends, int grid, bint batch=False):
    """Occupied and visited voxels of ESF's packed line walk (grids up to 64).

    The grid is the 3x3x3 dilation of the voxels ``occupied``; line k runs
    from voxel ``starts[k]`` towards ``ends[k]``. ``batch`` walks the lines
    in batches of at most ``3 * ESF_BATCH`` as ``esf_take`` does (in AVX2
    lanes when ``_simd_enabled()``). For the tests: an independent Bresenham
    loop must give the same counts.
    """
    cdef Py_ssize_t k, b, m, n_lines = starts.shape[0]
    cdef uint64_t[::1] g3 = np.empty(3 * ESF_LAYOUT_WORDS, dtype=np.uint64)
    rs_arr, st_arr = _walk_tables()
    cdef int32_t[::1] rs = rs_arr
    cdef int32_t[::1] st = st_arr
    cdef int32_t[::1] occ = np.empty(n_lines, dtype=np.int32)
    cdef int32_t[::1] cnt = np.empty(n_lines, dtype=np.int32)
    cdef uint64_t[::1] pos = np.empty(n_lines, dtype=np.uint64)
    cdef uint64_t[::1] inc = np.empty(n_lines, dtype=np.uint64)
    if grid > 64:
        raise ValueError("esf_line_counts: grid must be at most 64")
    esf_fill_layouts(&occupied[0, 0], occupied.shape[0], grid, &g3[0])
    for k in range(n_lines):
        cnt[k] = esf_line_setup(starts[k, 0], starts[k, 1], starts[k, 2], ends[k, 0], ends[k, 1],
                                ends[k, 2], &rs[0], &st[0], &pos[k], &inc[k])
    if not batch:
        for k in range(n_lines):
            occ[k] = esf_walk(&g3[0], pos[k], inc[k], cnt[k])
    else:
        for b in range(0, n_lines, 3 * ESF_BATCH):
            m = min(3 * ESF_BATCH, n_lines - b)
            esf_walk_batch(&g3[0], &pos[b], &inc[b], <int*>&cnt[b], <int*>&occ[b], <int>m, _esf_simd)
    return np.asarray(occ), np.asarray(cnt)


def esf_scaled_counts(const double[::1] values, const int8_t[::1] classes, double vmax, int n_bins, bint simd):
    """The D2/D3 binning of the batched kernel, for the tests: ``(3, n_bins)``
    counts of ``round(values / vmax * (n_bins - 1))`` (clipped, NaN to bin 0)
    per class (0, 1 or 2), with the AVX2 binning when ``simd`` and the CPU
    has it."""
    cdef int64_t n = values.shape[0], i
    if classes.shape[0] != n or n_bins < 1 or not vmax > 0:
        raise ValueError("esf_scaled_counts: one class per value, n_bins >= 1 and vmax > 0 are needed")
    for i in range(n):
        if not 0 <= classes[i] <= 2:
            raise ValueError("esf_scaled_counts: classes must be 0, 1 or 2")
    acc = np.zeros((3, n_bins), dtype=np.int64)
    cdef int64_t[:, ::1] a = acc
    if n:
        esf_count_scaled(&values[0], &classes[0], n, vmax, (n_bins - 1) / vmax, n_bins, &a[0, 0],
                         simd and esf_has_avx2() != 0)
    return acc

