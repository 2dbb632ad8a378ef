# cython: language_level=3
"""Compiled kernel for PCA surface normals, parallel over objects (or over the
points of one object) with OpenMP.

- Exact k nearest neighbors on a uniform grid of cubic cells. The cell size
  adapts to the object and to k (about ``_CELL_OVER_RADIUS`` times the radius
  of a k-neighborhood, from the grid's occupancy), so the 3x3x3 block of
  cells around a query usually holds its neighborhood. Fast path: candidates of that block closer than a guess of the
  k-th distance (taken from the previous query) are ranked without branches,
  and the result is accepted when the k-th distance is provably smaller than
  the distance to the block's boundary. With too few or too many candidates
  it tries once more with a guess four times larger or smaller (and, when
  that overshoots, twice or half); when the k-th lies beyond what the block
  proves, the 5x5x5 block within that distance is tried; otherwise an exact
  search over growing shells of cells with a sorted k-list takes over. All
  paths return the same list: the k smallest squared distances, ties broken
  by the point's position in the grid order (cell, then original index).
- The fast path scans the 3x3x3 block's points gathered once per cell (the
  queries go in grid order, so a cell's queries come one after another),
  the rows beyond the guess skipped. The distance scan runs eight points at
  a time with AVX-512, four with AVX2 where the CPU has them
  (``_normals_simd.h``, chosen at import) and two elsewhere (portable vector
  code, any CPU), over x, y and z arrays; with AVX-512 and AVX2 its k-th
  selection too (bisection over bucket counts). The same IEEE operations in
  the same order as the scalar loops here, so every level gives the same
  candidates and normals bit for bit (``_set_simd_level`` picks a lower one
  for tests).
- The normal is the eigenvector of the smallest eigenvalue of the
  neighborhood's covariance: closed-form eigenvalues plus a cross product of
  two rows of ``C - lambda_min I``, with cyclic Jacobi for nearly degenerate
  spectra (``_smallest_eigvec``). Eight neighborhoods are solved at once,
  one per vector lane, covariance included (``_normals_lanes.h``): each
  lane's operations are those of the one-at-a-time code (``_smallest_eigvec``
  and ``eppf_nrm_covariance``, the sums in ascending grid position), so the
  bits are too, at every level.

Every normal depends only on its own object's coordinates and k, never on the
thread that computed it or on the order in which points were visited, so the
output is bit-identical for any thread count.
"""
from cython.parallel cimport prange, threadid
from libc.math cimport sqrt, fabs, floor, frexp, ldexp, cbrt, log, pow, INFINITY
from libc.float cimport DBL_EPSILON
from libc.stdint cimport int64_t
from libc.stdlib cimport malloc, free

from ..utils._common cimport clamp_floor64

import numpy as np

cdef extern from "_normals_simd.h":
    enum:
        EPPF_NRM_SLACK
        EPPF_NRM_BUCKETS
        EPPF_NRM_LANES
        EPPF_NRM_EIG_VEC
    double EPPF_NRM_GAP_RATIO
    int eppf_nrm_has_avx2() noexcept nogil
    int eppf_nrm_has_avx512() noexcept nogil
    int64_t eppf_nrm_scan_portable(const double* sx, const double* sy, const double* sz, int64_t b, int64_t e,
                                   double qx, double qy, double qz, double guess, double* cand_d2,
                                   int64_t* cand_pos, int64_t m) noexcept nogil
    int64_t eppf_nrm_scan_avx2(const double* sx, const double* sy, const double* sz, int64_t b, int64_t e,
                               double qx, double qy, double qz, double guess, double* cand_d2,
                               int64_t* cand_pos, int64_t m) noexcept nogil
    int64_t eppf_nrm_scan_avx512(const double* sx, const double* sy, const double* sz, int64_t b, int64_t e,
                                 double qx, double qy, double qz, double guess, double* cand_d2,
                                 int64_t* cand_pos, int64_t m) noexcept nogil
    int64_t eppf_nrm_select_avx512(const double* cand_d2, const int64_t* cand_pos, int64_t m, int64_t k,
                                   double to_bucket, int64_t* sel, int64_t* kpos) noexcept nogil
    void eppf_nrm_covariance(const double* spts, const int64_t* kpos, int64_t k, double* cov) noexcept nogil
    int64_t eppf_nrm_select_avx2(const double* cand_d2, const int64_t* cand_pos, int64_t m, int64_t k,
                                 double to_bucket, int64_t* sel, int64_t* kpos) noexcept nogil
    unsigned eppf_nrm_eig8_portable(const double* c, double* out) noexcept nogil
    unsigned eppf_nrm_eig8_avx2(const double* c, double* out) noexcept nogil
    unsigned eppf_nrm_eig8_avx512(const double* c, double* out) noexcept nogil
    void eppf_nrm_cov8_portable(const double* nb, int64_t k, double* c) noexcept nogil
    void eppf_nrm_cov8_avx2(const double* nb, int64_t k, double* c) noexcept nogil
    void eppf_nrm_cov8_avx512(const double* nb, int64_t k, double* c) noexcept nogil

# The fast path's distance scan: 0 scalar, 1 AVX2, 2 AVX-512 (the best the
# CPU has, checked at import; ``_set_simd_level`` picks a lower one for tests).
# Every level gives the same candidates, bit for bit.
cdef int _max_level():
    if eppf_nrm_has_avx2() == 0:
        return 0
    return 2 if eppf_nrm_has_avx512() != 0 else 1

cdef int _simd = _max_level()


def _simd_level():
    """The level of the fast path's distance scan in use: 0 scalar, 1 AVX2, 2 AVX-512."""
    return _simd


def _set_simd_level(int level):
    """Use distance-scan level ``level`` (clipped to what the CPU has); return the level in use."""
    global _simd
    _simd = max(0, min(level, _max_level()))
    return _simd

# Buckets of the fast path's histogram selection.
cdef enum:
    _N_BUCKETS = EPPF_NRM_BUCKETS

# Neighborhoods whose eigenvectors are solved together (one per vector lane).
cdef enum:
    _LANES = EPPF_NRM_LANES

# Outcomes of the fast path.
cdef enum:
    _FAST_OK = 0
    _FAST_FEW = 1
    _FAST_MANY = 2
    _FAST_FAR = 3

# Modes of orientation understood by the kernel.
cdef enum:
    ORIENT_NONE = 0
    ORIENT_CENTROID = 1
    ORIENT_VIEWPOINT = 2


# Below this ratio of (lambda_mid - lambda_min) to (lambda_max - lambda_min)
# the closed-form eigenvector is replaced by Jacobi's.
cdef double _GAP_RATIO = EPPF_NRM_GAP_RATIO
# Grid cell size over the estimated radius of a k-neighborhood.
cdef double _CELL_OVER_RADIUS = 1.2
# The fast path keeps candidates within this factor of the previous query's
# k-th squared distance, and gives up when more than _MAX_CAND_PER_K * k pass.
cdef double _GUESS_FACTOR = 1.6
cdef Py_ssize_t _MAX_CAND_PER_K = 8


cdef struct Grid:
    double scale          # grid coordinates are (x * scale - shift) * scale2
    double shift[3]
    double scale2
    double lo[3]
    double h
    double inv_h
    double margin
    int64_t res[3]
    int64_t ncells
    double* sx            # the grid-order coordinates as three arrays (the
    double* sy            # fast path's distance scan reads these)
    double* sz


cdef struct Scratch:
    # Object part (sized by the largest object, max_n points).
    double* spts          # 3 * max_n  coordinates in grid order, rescaled
    double* sxyz          # 3 * max_n  the same as x, y and z arrays (max_n each)
    double* cand_d2       # max_n + EPPF_NRM_SLACK  fast-path candidate squared distances
    int64_t* sidx         # max_n      original index of each grid-order point
    int64_t* cell_of      # max_n      cell of each point
    int64_t* cell_start   # cap + 1    first grid-order position of each cell
    int64_t* cand_pos     # max_n + EPPF_NRM_SLACK  fast-path candidate positions
    int64_t* sel          # max_n + EPPF_NRM_SLACK  fast-path candidates of the k-th's bucket
    # Query part (sized by k).
    double* kd2           # k          the k-list's squared distances, ascending
    double* guess         # 1          k-th squared distance guess for the next query
    int64_t* kpos         # k + EPPF_NRM_SLACK  the k-list's grid-order positions (+ slack
                          #            for the fast path's branch-free compaction)
    unsigned char* cand_b # max_n      fast-path candidate buckets (in the int64 row's tail)
    # The 3x3x3 block of cells around the last query's cell, gathered: the
    # points of its rows (runs of grid order) one after another, so in
    # ascending grid position.
    double* blk           # 3 * max_n  their x, y and z arrays (max_n apart)
    int64_t* blk_pos      # max_n      their grid-order positions
    int64_t blk_cell      #            the cell it surrounds (-1: none yet)
    int64_t blk_n         #            its number of points
    int64_t blk_stride    #            max_n
    int64_t blk_row[10]   #            where each of its nine rows starts (dz, then dy,
                          #            from -1 to 1; empty outside the grid), then its end
    double* nb            # 3 * k * _LANES  the eigenvector batch's neighbors (Batch.nb)


cdef struct Batch:
    # Neighborhoods waiting for the eigenvector solver, one per lane: their
    # k points staged in ``nb`` (the layout of _normals_lanes.h; NULL where
    # the covariances are given), the covariances' entries c00, c01, c02,
    # c11, c12, c22 (``_LANES`` lanes each), and where each lane's normal goes.
    double c[6 * _LANES]
    double* dst[_LANES]
    int count
    double* nb
    Py_ssize_t k


def max_cells(Py_ssize_t n):
    """Upper bound on the number of grid cells for an object of ``n`` points."""
    return 4 * n + 64


def scratch_sizes(Py_ssize_t max_n, Py_ssize_t k):
    """Lengths of one thread's float64 and int64 scratch rows for objects of
    at most ``max_n`` points and neighborhoods of ``k`` points."""
    return (10 * max_n + EPPF_NRM_SLACK + k + 1 + 3 * k * EPPF_NRM_LANES,
            5 * max_n + 2 * EPPF_NRM_SLACK + max_cells(max_n) + 1 + k + EPPF_NRM_SLACK + (max_n + 7) // 8)


cdef inline void _split_scratch(double* fs, int64_t* its, Py_ssize_t max_n, Py_ssize_t k,
                                Scratch* sc) noexcept nogil:
    """Carve one thread's scratch rows (see :func:`scratch_sizes`)."""
    cdef Py_ssize_t cap = 4 * max_n + 64
    sc.spts = fs
    sc.sxyz = fs + 3 * max_n
    sc.cand_d2 = sc.sxyz + 3 * max_n
    sc.kd2 = sc.cand_d2 + max_n + EPPF_NRM_SLACK
    sc.guess = sc.kd2 + k
    sc.sidx = its
    sc.cell_of = its + max_n
    sc.cell_start = sc.cell_of + max_n
    sc.cand_pos = sc.cell_start + cap + 1
    sc.sel = sc.cand_pos + max_n + EPPF_NRM_SLACK
    sc.kpos = sc.sel + max_n + EPPF_NRM_SLACK
    sc.cand_b = <unsigned char*>(sc.kpos + k + EPPF_NRM_SLACK)
    sc.blk = sc.guess + 1
    sc.nb = sc.blk + 3 * max_n
    sc.blk_pos = sc.kpos + k + EPPF_NRM_SLACK + (max_n + 7) // 8
    sc.blk_cell = -1
    sc.blk_n = 0
    sc.blk_stride = max_n


cdef inline double _pow2_below(double m) noexcept nogil:
    """The power of two 2**-e that maps m > 0 into [0.5, 1) (1 for m == 0),
    clamped so that it stays finite."""
    cdef int expo
    if not (m > 0.0):
        return 1.0
    frexp(m, &expo)
    if expo < -1000:
        expo = -1000
    return ldexp(1.0, -expo)


cdef inline double _tr(const Grid* g, double x, int a) noexcept nogil:
    """Grid coordinate of input coordinate ``x`` along axis ``a``."""
    return (x * g.scale - g.shift[a]) * g.scale2


cdef inline int64_t _cell_coord(double x, double lo, double inv_h, int64_t res) noexcept nogil:
    """clip(floor((x - lo) * inv_h), 0, res - 1), clamped in floating point
    before the conversion (NaN gives 0), so any double gives a cell."""
    return clamp_floor64((x - lo) * inv_h, res)


cdef inline double _snap_cell(double h) noexcept nogil:
    """``h`` rounded down to m 2^e with m in {1, 1.25, 1.5, 1.75} (exactly).

    The cell size is estimated with the C library's cbrt, log and pow, whose
    last bit may differ between libraries and CPUs; the grid's order decides
    the order of each covariance's sum and of ties at the k-th distance, so
    the normals' bits would follow it. Rounded, the size changes only where
    such a last bit straddles one of these values.
    """
    cdef int e
    cdef double m = frexp(h, &e)
    return ldexp(floor(m * 8.0) / 8.0, e)


cdef int64_t _set_resolution(Grid* g, const double* e, double h, Py_ssize_t cap) noexcept nogil:
    """Cells per axis for cell size ``h`` (grown until at most ``cap`` cells)."""
    cdef int64_t prod, r
    cdef double x
    cdef int a
    if not (h > 0.0):
        h = 1.0
    h = _snap_cell(h)
    while True:
        prod = 1
        for a in range(3):
            x = floor(e[a] / h)
            r = 1 if not (x >= 1.0) else (<int64_t>x if x < 1048576.0 else 1048576)
            g.res[a] = r
            prod *= r
        if prod <= cap:
            break
        h *= 1.25
    g.h = h
    g.inv_h = 1.0 / h
    g.ncells = prod
    # Rounding slack for the geometric bounds (coordinates are below 1).
    g.margin = 64.0 * DBL_EPSILON * (1.0 + h)
    return prod


cdef int64_t _count_cells(const double* tpts, Py_ssize_t n, Grid* g, int64_t* cell_of,
                          int64_t* counts) noexcept nogil:
    """Cell of every point (grid coordinates ``tpts``, x, y, z per point) and
    points per cell (in ``counts[c + 1]``); return the number of occupied
    cells."""
    cdef Py_ssize_t i
    cdef int64_t c, cx, cy, cz, occupied = 0
    for c in range(g.ncells + 1):
        counts[c] = 0
    for i in range(n):
        cx = _cell_coord(tpts[3 * i], g.lo[0], g.inv_h, g.res[0])
        cy = _cell_coord(tpts[3 * i + 1], g.lo[1], g.inv_h, g.res[1])
        cz = _cell_coord(tpts[3 * i + 2], g.lo[2], g.inv_h, g.res[2])
        c = (cz * g.res[1] + cy) * g.res[0] + cx
        cell_of[i] = c
        occupied += counts[c + 1] == 0
        counts[c + 1] += 1
    return occupied


cdef void _build_grid(const double* pts, Py_ssize_t n, Py_ssize_t k, Py_ssize_t cap,
                      Grid* g, double* spts, double* sxyz, Py_ssize_t stride, int64_t* sidx,
                      int64_t* cell_of, int64_t* cell_start, double* tpts) noexcept nogil:
    """Move and rescale the object into the unit cube, choose the cell size,
    bin the points and store them sorted by cell (stable: ascending original
    index within a cell), in ``spts`` (x, y, z per point) and in ``sxyz``
    (x, y and z arrays, ``stride`` apart). ``tpts`` (3 n doubles) holds the
    grid coordinates in the input order meanwhile."""
    cdef Py_ssize_t i, a
    cdef double hi[3]
    cdef double e[3]
    cdef double m = 0.0, x, h, t, e1, e2, e3, tmp, h0, h1, pc0, pc1, d, tau
    cdef int expo
    cdef int64_t c, r
    g.sx = sxyz
    g.sy = sxyz + stride
    g.sz = sxyz + 2 * stride
    # Exact rescaling by a power of two: the largest |coordinate| lands in
    # [0.5, 1), so nothing below overflows or underflows.
    for i in range(3 * n):
        x = fabs(pts[i])
        if x > m:
            m = x
    g.scale = _pow2_below(m)
    for a in range(3):
        g.shift[a] = INFINITY
        hi[a] = -INFINITY
    for i in range(n):
        for a in range(3):
            x = pts[3 * i + a] * g.scale
            if x < g.shift[a]:
                g.shift[a] = x
            if x > hi[a]:
                hi[a] = x
    # Then move the bounding box's corner to the origin and rescale, again by
    # a power of two, so the largest extent lands in [0.5, 1): rounding slack
    # in the grid's bounds is then relative to the object's size, not to its
    # distance from the origin. Scaling the input by a power of two changes
    # nothing downstream.
    m = 0.0
    for a in range(3):
        if hi[a] - g.shift[a] > m:
            m = hi[a] - g.shift[a]
    g.scale2 = _pow2_below(m)
    for a in range(3):
        g.lo[a] = 0.0
        e[a] = (hi[a] - g.shift[a]) * g.scale2
    for i in range(n):
        for a in range(3):
            tpts[3 * i + a] = _tr(g, pts[3 * i + a], a)
    # First guess: about one cell per point of the bounding box, flat axes
    # ignored.
    t = <double>n
    e1 = e[0]
    e2 = e[1]
    e3 = e[2]
    if e1 < e2:
        tmp = e1; e1 = e2; e2 = tmp
    if e2 < e3:
        tmp = e2; e2 = e3; e3 = tmp
    if e1 < e2:
        tmp = e1; e1 = e2; e2 = tmp
    if e1 <= 0.0:
        h = 1.0
    else:
        h = cbrt(e1 * e2 * e3 / t)
        if not (h > 0.0 and e3 >= h):
            h = sqrt(e1 * e2 / t)
            if not (h > 0.0 and e2 >= h):
                h = e1 / t
    _set_resolution(g, e, h, cap)
    # Then resize so that a cell is about _CELL_OVER_RADIUS times the radius of
    # a k-neighborhood. The local dimension d (1 for curves, 2 for surfaces,
    # 3 for volumes) is read from how occupancy changes with the cell size.
    h0 = g.h
    pc0 = <double>n / <double>_count_cells(tpts, n, g, cell_of, cell_start)
    _set_resolution(g, e, h0 * 1.5, cap)
    h1 = g.h
    pc1 = <double>n / <double>_count_cells(tpts, n, g, cell_of, cell_start)
    d = 2.0
    if pc1 > pc0 and h1 > h0:
        d = log(pc1 / pc0) / log(h1 / h0)
    if d < 1.0:
        d = 1.0
    if d > 3.0:
        d = 3.0
    # Points per occupied cell when the cell is the neighborhood radius:
    # about 0.7 k on curves and surfaces (a cell holds ~1.5 h^2 of surface)
    # down to 0.24 k in volumes (k / (4 pi / 3)).
    tau = 0.7 if d <= 2.0 else 0.7 - (0.7 - 0.24) * (d - 2.0)
    tmp = (tau * k * pow(_CELL_OVER_RADIUS, d) / pc1) ** (1.0 / d)
    if tmp < 0.125:
        tmp = 0.125
    if tmp > 8.0:
        tmp = 8.0
    _set_resolution(g, e, h1 * tmp, cap)
    _count_cells(tpts, n, g, cell_of, cell_start)
    for c in range(g.ncells):
        cell_start[c + 1] += cell_start[c]
    for i in range(n):
        c = cell_of[i]
        r = cell_start[c]
        cell_start[c] = r + 1
        sidx[r] = i
        spts[3 * r] = tpts[3 * i]
        spts[3 * r + 1] = tpts[3 * i + 1]
        spts[3 * r + 2] = tpts[3 * i + 2]
        g.sx[r] = spts[3 * r]
        g.sy[r] = spts[3 * r + 1]
        g.sz[r] = spts[3 * r + 2]
    for c in range(g.ncells, 0, -1):
        cell_start[c] = cell_start[c - 1]
    cell_start[0] = 0


cdef inline Py_ssize_t _scan_cell(const double* spts, int64_t begin, int64_t end,
                                  double qx, double qy, double qz, Py_ssize_t k, Py_ssize_t count,
                                  double* kd2, int64_t* kpos) noexcept nogil:
    """Offer the points of one cell to the k-list, kept sorted by (squared
    distance, grid-order position); return the new count."""
    cdef int64_t p
    cdef double dx, dy, dz, d2
    cdef Py_ssize_t pos
    for p in range(begin, end):
        dx = spts[3 * p] - qx
        dy = spts[3 * p + 1] - qy
        dz = spts[3 * p + 2] - qz
        d2 = dx * dx + dy * dy + dz * dz
        if count < k:
            pos = count
            count += 1
        elif d2 < kd2[k - 1] or (d2 == kd2[k - 1] and p < kpos[k - 1]):
            pos = k - 1
        else:
            continue
        while pos > 0 and (kd2[pos - 1] > d2 or (kd2[pos - 1] == d2 and kpos[pos - 1] > p)):
            kd2[pos] = kd2[pos - 1]
            kpos[pos] = kpos[pos - 1]
            pos -= 1
        kd2[pos] = d2
        kpos[pos] = p
    return count


cdef inline double _gap(double q, double lo, double h, int64_t c, int64_t j) noexcept nogil:
    """Distance along one axis from q (in cell c) to cell j's slab (0 for j == c)."""
    if j < c:
        return q - (lo + (j + 1) * h)
    if j > c:
        return (lo + j * h) - q
    return 0.0


cdef inline bint _block_done(const Grid* g, const double* q, const int64_t* c, int64_t r,
                             double kth) noexcept nogil:
    """True when the block of cells within Chebyshev distance ``r`` of cell
    ``c`` holds every point closer to ``q`` than sqrt(kth) (or the whole
    grid)."""
    cdef bint full_cover = True
    cdef double bound = INFINITY, b
    cdef int a
    for a in range(3):
        if c[a] - r >= 1:
            full_cover = False
            b = q[a] - (g.lo[a] + (c[a] - r) * g.h)
            if b < bound:
                bound = b
        if c[a] + r + 1 <= g.res[a] - 1:
            full_cover = False
            b = (g.lo[a] + (c[a] + r + 1) * g.h) - q[a]
            if b < bound:
                bound = b
    if full_cover:
        return True
    bound -= g.margin
    return bound > 0.0 and kth < bound * bound


cdef void _knn_shells(const Grid* g, const double* spts, const int64_t* cell_start,
                      const double* q, const int64_t* c, Py_ssize_t k,
                      double* kd2, int64_t* kpos) noexcept nogil:
    """Exact search over growing shells of cells with a sorted k-list."""
    cdef double qx = q[0], qy = q[1], qz = q[2]
    cdef int64_t r, jx, jy, jz, x0, x1, y0, y1, z0, z1, step, cell
    cdef Py_ssize_t count = 0
    cdef double gz, gy, gx, gz2, gyz2
    cdef bint edge_y, edge_z
    r = 0
    while True:
        # Visit the shell of cells at Chebyshev distance r from the query's
        # cell, skipping slabs, rows and cells farther than the current k-th.
        z0 = c[2] - r
        z1 = c[2] + r
        y0 = c[1] - r
        y1 = c[1] + r
        x0 = c[0] - r
        x1 = c[0] + r
        for jz in range(z0 if z0 > 0 else 0, (z1 if z1 < g.res[2] - 1 else g.res[2] - 1) + 1):
            edge_z = jz == z0 or jz == z1
            gz = _gap(qz, g.lo[2], g.h, c[2], jz) - g.margin
            gz2 = gz * gz if gz > 0.0 else 0.0
            if count == k and gz2 > kd2[k - 1]:
                continue
            for jy in range(y0 if y0 > 0 else 0, (y1 if y1 < g.res[1] - 1 else g.res[1] - 1) + 1):
                edge_y = edge_z or jy == y0 or jy == y1
                gy = _gap(qy, g.lo[1], g.h, c[1], jy) - g.margin
                gyz2 = gz2 + (gy * gy if gy > 0.0 else 0.0)
                if count == k and gyz2 > kd2[k - 1]:
                    continue
                # In the shell's interior rows only the two end cells are new.
                step = 1 if (edge_y or r == 0) else 2 * r
                jx = x0
                while jx <= x1:
                    if jx >= 0 and jx < g.res[0]:
                        gx = _gap(qx, g.lo[0], g.h, c[0], jx) - g.margin
                        if not (count == k and gyz2 + (gx * gx if gx > 0.0 else 0.0) > kd2[k - 1]):
                            cell = (jz * g.res[1] + jy) * g.res[0] + jx
                            count = _scan_cell(spts, cell_start[cell], cell_start[cell + 1],
                                               qx, qy, qz, k, count, kd2, kpos)
                    jx += step
        if count == k and _block_done(g, q, c, r, kd2[k - 1]):
            return
        r += 1


cdef inline Py_ssize_t _bucket(double x) noexcept nogil:
    """min(floor(x), _N_BUCKETS - 1) for x >= 0, clamped before the
    conversion (NaN to the top bucket, negative values to 0)."""
    if not (x < _N_BUCKETS):
        return _N_BUCKETS - 1
    if not (x > 0.0):
        return 0
    return <Py_ssize_t>x


cdef inline Py_ssize_t _scan(const double* sx, const double* sy, const double* sz, int64_t b, int64_t e,
                             const double* q, double guess, double* cand_d2, int64_t* cand_pos,
                             Py_ssize_t m) noexcept nogil:
    """Offer points [b, e) of the x, y, z arrays to the candidate list with the
    level's distance scan (``_simd``); return the new count."""
    if _simd == 2:
        return eppf_nrm_scan_avx512(sx, sy, sz, b, e, q[0], q[1], q[2], guess, cand_d2, cand_pos, m)
    if _simd == 1:
        return eppf_nrm_scan_avx2(sx, sy, sz, b, e, q[0], q[1], q[2], guess, cand_d2, cand_pos, m)
    return eppf_nrm_scan_portable(sx, sy, sz, b, e, q[0], q[1], q[2], guess, cand_d2, cand_pos, m)


cdef int _knn_block(const Grid* g, const double* spts, const int64_t* cell_start,
                     const double* q, const int64_t* c, Py_ssize_t k, double guess,
                     double* cand_d2, int64_t* cand_pos, int64_t* sel, double* kd2,
                     int64_t* kpos, unsigned char* cand_b, int64_t r) noexcept nogil:
    """Fast path: select the k nearest among the points of the block of
    cells within Chebyshev distance ``r`` of the query's cell (3x3x3 for
    ``r = 1``) within squared distance ``guess`` of the query. On success, ``kpos`` holds
    their grid-order positions in ascending order and ``kd2[k - 1]`` the k-th
    squared distance, and the return value is _FAST_OK. Otherwise (outputs
    undefined) it says why: _FAST_FEW (fewer than k within the guess),
    _FAST_MANY (more than ``_MAX_CAND_PER_K * k``) or _FAST_FAR (the k-th
    lies too far to prove that the block holds the k nearest)."""
    cdef int64_t jy, jz, row, x0, x1, b, e
    cdef Py_ssize_t m = 0, max_cand = _MAX_CAND_PER_K * k
    cdef double qx = q[0], qy = q[1], qz = q[2], gz, gz2, gy, gyz2, gx
    cdef int64_t xlo = c[0] - r if c[0] - r > 0 else 0
    cdef int64_t xhi = c[0] + r if c[0] + r < g.res[0] else g.res[0] - 1
    for jz in range(c[2] - r if c[2] - r > 0 else 0, (c[2] + r if c[2] + r < g.res[2] else g.res[2] - 1) + 1):
        gz = _gap(qz, g.lo[2], g.h, c[2], jz) - g.margin
        gz2 = gz * gz if gz > 0.0 else 0.0
        if gz2 > guess:
            continue
        for jy in range(c[1] - r if c[1] - r > 0 else 0, (c[1] + r if c[1] + r < g.res[1] else g.res[1] - 1) + 1):
            gy = _gap(qy, g.lo[1], g.h, c[1], jy) - g.margin
            gyz2 = gz2 + (gy * gy if gy > 0.0 else 0.0)
            if gyz2 > guess:
                continue
            # Trim the row's end cells that lie beyond the guess; what is left
            # is one contiguous run of grid-order positions, and runs come in
            # ascending position order.
            x0 = c[0]
            while x0 > xlo:
                gx = qx - (g.lo[0] + x0 * g.h) - g.margin
                if gyz2 + (gx * gx if gx > 0.0 else 0.0) > guess:
                    break
                x0 -= 1
            x1 = c[0]
            while x1 < xhi:
                gx = (g.lo[0] + (x1 + 1) * g.h) - qx - g.margin
                if gyz2 + (gx * gx if gx > 0.0 else 0.0) > guess:
                    break
                x1 += 1
            row = (jz * g.res[1] + jy) * g.res[0]
            b = cell_start[row + x0]
            e = cell_start[row + x1 + 1]
            if m > max_cand:
                return _FAST_MANY
            m = _scan(g.sx, g.sy, g.sz, b, e, q, guess, cand_d2, cand_pos, m)
    return _select_k(g, q, c, r, k, guess, m, cand_d2, cand_pos, sel, kd2, kpos, cand_b)


cdef int _select_k(const Grid* g, const double* q, const int64_t* c, int64_t r, Py_ssize_t k, double guess,
                   Py_ssize_t m, const double* cand_d2, const int64_t* cand_pos, int64_t* sel, double* kd2,
                   int64_t* kpos, unsigned char* cand_b) noexcept nogil:
    """The fast path's selection among the ``m`` candidates (squared
    distances at most ``guess``, in ascending position) of the block of
    cells within Chebyshev distance ``r`` of the query's cell: outputs and
    return value as :func:`_knn_block`'s (``kpos`` holds the candidates'
    ``cand_pos`` entries)."""
    cdef Py_ssize_t i, j, rank, max_cand = _MAX_CAND_PER_K * k
    cdef int counts[_N_BUCKETS]
    cdef Py_ssize_t bk, below, need, n_in, kth_i
    cdef double to_bucket, kth, di
    if m < k:
        return _FAST_FEW
    if m > max_cand:
        return _FAST_MANY
    if _simd != 0:
        if _simd == 2:
            kth_i = eppf_nrm_select_avx512(cand_d2, cand_pos, m, k, _N_BUCKETS / guess, sel, kpos)
        else:
            kth_i = eppf_nrm_select_avx2(cand_d2, cand_pos, m, k, _N_BUCKETS / guess, sel, kpos)
        kd2[k - 1] = cand_d2[kth_i]
        return _FAST_OK if _block_done(g, q, c, r, kd2[k - 1]) else _FAST_FAR
    # The k-th smallest (d2, position) by a histogram of d2 over [0, guess]
    # (the bucket is monotone in d2), then ranking inside its bucket only.
    for i in range(_N_BUCKETS):
        counts[i] = 0
    to_bucket = _N_BUCKETS / guess
    for i in range(m):
        bk = _bucket(cand_d2[i] * to_bucket)
        cand_b[i] = bk
        counts[bk] += 1
    below = 0
    bk = 0
    while below + counts[bk] < k:
        below += counts[bk]
        bk += 1
    need = k - below
    n_in = 0
    for i in range(m):
        sel[n_in] = i
        n_in += cand_b[i] == bk
    kth_i = sel[0]
    for i in range(n_in):
        di = cand_d2[sel[i]]
        rank = 0
        for j in range(i):
            rank += cand_d2[sel[j]] <= di
        for j in range(i + 1, n_in):
            rank += cand_d2[sel[j]] < di
        if rank == need - 1:
            kth_i = sel[i]
    kth = cand_d2[kth_i]
    # Keep everything up to the k-th in (d2, position) order, in position
    # order (candidates are in ascending position): d2 <= kth up to the k-th
    # itself, d2 < kth after it.
    j = 0
    for i in range(kth_i + 1):
        kpos[j] = cand_pos[i]
        j += cand_d2[i] <= kth
    for i in range(kth_i + 1, m):
        kpos[j] = cand_pos[i]
        j += cand_d2[i] < kth
    kd2[k - 1] = kth
    return _FAST_OK if _block_done(g, q, c, r, kth) else _FAST_FAR


cdef void _gather_block(const Grid* g, const int64_t* cell_start, const int64_t* c, int64_t cell,
                        Scratch* sc) noexcept nogil:
    """Copy the points of the 3x3x3 block of cells around cell ``c`` (index
    ``cell``) to ``sc``'s block arrays, row after row: ascending grid
    position, at most all the object's points (the rows' runs are disjoint)."""
    cdef int64_t dy, dz, jy, jz, row, p, b, e, nb = 0
    cdef int64_t xlo = c[0] - 1 if c[0] > 0 else 0
    cdef int64_t xhi = c[0] + 1 if c[0] + 1 < g.res[0] else g.res[0] - 1
    cdef double* bx = sc.blk
    cdef double* by = sc.blk + sc.blk_stride
    cdef double* bz = sc.blk + 2 * sc.blk_stride
    for dz in range(3):
        jz = c[2] + dz - 1
        for dy in range(3):
            jy = c[1] + dy - 1
            sc.blk_row[3 * dz + dy] = nb
            if jz < 0 or jz >= g.res[2] or jy < 0 or jy >= g.res[1]:
                continue
            row = (jz * g.res[1] + jy) * g.res[0]
            b = cell_start[row + xlo]
            e = cell_start[row + xhi + 1]
            for p in range(b, e):
                bx[nb] = g.sx[p]
                by[nb] = g.sy[p]
                bz[nb] = g.sz[p]
                sc.blk_pos[nb] = p
                nb += 1
    sc.blk_row[9] = nb
    sc.blk_n = nb
    sc.blk_cell = cell


cdef inline Py_ssize_t _scan_block(const Scratch* sc, int64_t b, int64_t e, const double* q, double guess,
                                   Py_ssize_t m) noexcept nogil:
    """Offer the gathered block's points [b, e) to the candidate list; return the new count."""
    cdef const double* bx = sc.blk
    return _scan(bx, bx + sc.blk_stride, bx + 2 * sc.blk_stride, b, e, q, guess, sc.cand_d2, sc.cand_pos, m)


cdef int _knn_near(const Grid* g, const int64_t* cell_start, const double* q, const int64_t* c,
                   Py_ssize_t k, double guess, Scratch* sc) noexcept nogil:
    """:func:`_knn_block` for the 3x3x3 block (``r = 1``), over its points
    gathered once for all queries of a cell (``_gather_block``): the rows
    within the guess (by the same bounds), merged into runs where they
    follow one another, instead of one scan per row trimmed at its ends. The
    points it adds lie beyond the guess, so the candidates, hence the
    outputs, are the same."""
    cdef int64_t cell = (c[2] * g.res[1] + c[1]) * g.res[0] + c[0]
    cdef double gz2[3]
    cdef double gy2[3]
    cdef double gap
    cdef int64_t rb = 0, re = 0
    cdef Py_ssize_t m = 0, i
    cdef int t, res
    if cell != sc.blk_cell:
        _gather_block(g, cell_start, c, cell, sc)
    for t in range(3):
        gap = _gap(q[2], g.lo[2], g.h, c[2], c[2] + t - 1) - g.margin
        gz2[t] = gap * gap if gap > 0.0 else 0.0
        gap = _gap(q[1], g.lo[1], g.h, c[1], c[1] + t - 1) - g.margin
        gy2[t] = gap * gap if gap > 0.0 else 0.0
    for t in range(9):
        if not (gz2[t // 3] + gy2[t % 3] <= guess):
            continue
        if sc.blk_row[t] != re:
            m = _scan_block(sc, rb, re, q, guess, m)
            rb = sc.blk_row[t]
        re = sc.blk_row[t + 1]
    m = _scan_block(sc, rb, re, q, guess, m)
    res = _select_k(g, q, c, 1, k, guess, m, sc.cand_d2, sc.cand_pos, sc.sel, sc.kd2, sc.kpos, sc.cand_b)
    if res == _FAST_OK:
        # block indices to grid positions (ascending, as the block is)
        for i in range(k):
            sc.kpos[i] = sc.blk_pos[sc.kpos[i]]
    return res


cdef void _point_normal(const Grid* g, const double* spts, const int64_t* cell_start,
                        Py_ssize_t s, Py_ssize_t k, Scratch* sc, Batch* bt, double* out) noexcept nogil:
    """Normal of grid-order point ``s``, to be written to ``out`` (unoriented)
    when batch ``bt`` is solved. The covariance sums the k nearest in
    ascending grid position, whichever path found them, so the result does
    not depend on the search path."""
    cdef Py_ssize_t i, j, p
    cdef double q[3]
    cdef int64_t c[3]
    cdef double kth
    cdef double cov[9]
    cdef double guess = sc.guess[0]
    cdef int a, res = _FAST_FAR
    for a in range(3):
        q[a] = spts[3 * s + a]
        c[a] = _cell_coord(q[a], g.lo[a], g.inv_h, g.res[a])
    if guess < INFINITY:
        res = _knn_near(g, cell_start, q, c, k, guess, sc)
        # One more try with a guess four times larger or smaller (any
        # positive guess gives the same, exact list) and, when that
        # overshoots, one with the guess in between, before the shells.
        if res == _FAST_FEW:
            res = _knn_near(g, cell_start, q, c, k, 4.0 * guess, sc)
            if res == _FAST_MANY:
                res = _knn_near(g, cell_start, q, c, k, 2.0 * guess, sc)
        elif res == _FAST_MANY:
            res = _knn_near(g, cell_start, q, c, k, 0.25 * guess, sc)
            if res == _FAST_FEW:
                res = _knn_near(g, cell_start, q, c, k, 0.5 * guess, sc)
        if res == _FAST_FAR:
            # The k found bound the k-th distance from above: the 5x5x5 block
            # within that distance holds at least k, often enough to prove it.
            kth = sc.kd2[k - 1]
            if not (kth > 1e-200):
                kth = g.h * g.h
            res = _knn_block(g, spts, cell_start, q, c, k, kth, sc.cand_d2, sc.cand_pos,
                             sc.sel, sc.kd2, sc.kpos, sc.cand_b, 2)
    if res == _FAST_OK:
        kth = sc.kd2[k - 1]
    else:
        _knn_shells(g, spts, cell_start, q, c, k, sc.kd2, sc.kpos)
        kth = sc.kd2[k - 1]
        # Same summation order as the fast path: ascending grid position.
        for i in range(1, k):
            p = sc.kpos[i]
            j = i
            while j > 0 and sc.kpos[j - 1] > p:
                sc.kpos[j] = sc.kpos[j - 1]
                j -= 1
            sc.kpos[j] = p
    # Any positive guess keeps the result exact; a tiny one (duplicates)
    # would overflow the histogram's scale, so fall back to a cell's size.
    sc.guess[0] = kth * _GUESS_FACTOR
    if not (sc.guess[0] > 1e-200):
        sc.guess[0] = g.h * g.h
    if EPPF_NRM_EIG_VEC == 0:
        eppf_nrm_covariance(spts, sc.kpos, k, cov)
        _smallest_eigvec(cov, out)
    else:
        _batch_stage(bt, spts, sc.kpos, out)


cdef inline void _lane_cov(const Batch* bt, int j, double* cov) noexcept nogil:
    """The symmetric 3x3 covariance of lane ``j`` (row-major)."""
    cov[0] = bt.c[j]
    cov[1] = cov[3] = bt.c[_LANES + j]
    cov[2] = cov[6] = bt.c[2 * _LANES + j]
    cov[4] = bt.c[3 * _LANES + j]
    cov[5] = cov[7] = bt.c[4 * _LANES + j]
    cov[8] = bt.c[5 * _LANES + j]


cdef void _batch_solve(Batch* bt) noexcept nogil:
    """Write the unit eigenvector of the smallest eigenvalue of every waiting
    covariance to its destination and empty the batch: ``_smallest_eigvec``'s
    arithmetic in vector lanes (``eppf_nrm_eig8_*``, the same bits), Jacobi
    for the lanes it hands back."""
    cdef double res[3 * _LANES]
    cdef double cov[9]
    cdef unsigned bad
    cdef int j, i
    if bt.count == 0:
        return
    if bt.nb != NULL:
        # the covariances of the staged neighborhoods (unused lanes: zeros)
        for j in range(bt.count, _LANES):
            for i in range(3 * bt.k):
                bt.nb[_LANES * i + j] = 0.0
        if _simd == 2:
            eppf_nrm_cov8_avx512(bt.nb, bt.k, bt.c)
        elif _simd == 1:
            eppf_nrm_cov8_avx2(bt.nb, bt.k, bt.c)
        else:
            eppf_nrm_cov8_portable(bt.nb, bt.k, bt.c)
    elif EPPF_NRM_EIG_VEC == 0:
        for j in range(bt.count):
            _lane_cov(bt, j, cov)
            _smallest_eigvec(cov, bt.dst[j])
        bt.count = 0
        return
    for j in range(bt.count, _LANES):
        for i in range(6):
            bt.c[i * _LANES + j] = 0.0
    if _simd == 2:
        bad = eppf_nrm_eig8_avx512(bt.c, res)
    elif _simd == 1:
        bad = eppf_nrm_eig8_avx2(bt.c, res)
    else:
        bad = eppf_nrm_eig8_portable(bt.c, res)
    for j in range(bt.count):
        if (bad >> j) & 1u:
            _lane_cov(bt, j, cov)
            _jacobi_smallest(cov, bt.dst[j])
        else:
            bt.dst[j][0] = res[j]
            bt.dst[j][1] = res[_LANES + j]
            bt.dst[j][2] = res[2 * _LANES + j]
    bt.count = 0


cdef inline void _batch_stage(Batch* bt, const double* spts, const int64_t* kpos, double* dst) noexcept nogil:
    """Queue the neighborhood of the ``bt.k`` points of ``spts`` at grid
    positions ``kpos`` (in that order) for the solver, its normal to go to
    ``dst``; solve when every lane is taken."""
    cdef int j = bt.count
    cdef Py_ssize_t i, k = bt.k
    cdef int64_t p
    for i in range(k):
        p = 3 * kpos[i]
        bt.nb[_LANES * i + j] = spts[p]
        bt.nb[_LANES * (k + i) + j] = spts[p + 1]
        bt.nb[_LANES * (2 * k + i) + j] = spts[p + 2]
    bt.dst[j] = dst
    bt.count = j + 1
    if bt.count == _LANES:
        _batch_solve(bt)


cdef inline void _batch_add(Batch* bt, const double* cov, double* dst) noexcept nogil:
    """Queue covariance ``cov`` (symmetric, row-major) for the solver, its
    normal to go to ``dst``; solve when every lane is taken."""
    cdef int j = bt.count
    bt.c[j] = cov[0]
    bt.c[_LANES + j] = cov[1]
    bt.c[2 * _LANES + j] = cov[2]
    bt.c[3 * _LANES + j] = cov[4]
    bt.c[4 * _LANES + j] = cov[5]
    bt.c[5 * _LANES + j] = cov[8]
    bt.dst[j] = dst
    bt.count = j + 1
    if bt.count == _LANES:
        _batch_solve(bt)


cdef void _jacobi_smallest(const double* cov, double* out) noexcept nogil:
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix
    (row-major ``cov``) by cyclic Jacobi rotations. Ties between
    equal eigenvalues go to the lowest diagonal position, so a zero matrix
    gives (1, 0, 0)."""
    cdef double a[3][3]
    cdef double v[3][3]
    cdef int i, j, sweep, pair, p, qq, o
    cdef double apq, theta, t, cs, sn, aop, aoq, vip, viq, nrm
    cdef bint rotated
    for i in range(3):
        for j in range(3):
            a[i][j] = cov[3 * i + j]
            v[i][j] = 1.0 if i == j else 0.0
    for sweep in range(64):
        rotated = False
        for pair in range(3):
            if pair == 0:
                p = 0; qq = 1; o = 2
            elif pair == 1:
                p = 0; qq = 2; o = 1
            else:
                p = 1; qq = 2; o = 0
            apq = a[p][qq]
            # Demmel-Veselic threshold: an off-diagonal entry negligible against
            # the geometric mean of its diagonal entries is dropped.
            if fabs(apq) <= 0.5 * DBL_EPSILON * sqrt(fabs(a[p][p]) * fabs(a[qq][qq])):
                a[p][qq] = 0.0
                a[qq][p] = 0.0
                continue
            rotated = True
            theta = (a[qq][qq] - a[p][p]) / (2.0 * apq)
            if fabs(theta) > 1e150:
                t = 0.5 / theta
            else:
                t = 1.0 / (fabs(theta) + sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
            cs = 1.0 / sqrt(t * t + 1.0)
            sn = t * cs
            a[p][p] -= t * apq
            a[qq][qq] += t * apq
            a[p][qq] = 0.0
            a[qq][p] = 0.0
            aop = a[o][p]
            aoq = a[o][qq]
            a[o][p] = cs * aop - sn * aoq
            a[p][o] = a[o][p]
            a[o][qq] = sn * aop + cs * aoq
            a[qq][o] = a[o][qq]
            for i in range(3):
                vip = v[i][p]
                viq = v[i][qq]
                v[i][p] = cs * vip - sn * viq
                v[i][qq] = sn * vip + cs * viq
        if not rotated:
            break
    j = 0
    if a[1][1] < a[j][j]:
        j = 1
    if a[2][2] < a[j][j]:
        j = 2
    nrm = sqrt(v[0][j] * v[0][j] + v[1][j] * v[1][j] + v[2][j] * v[2][j])
    for i in range(3):
        out[i] = v[i][j] / nrm


cdef inline void _cubic_roots(double r, double* x1, double* x3) noexcept nogil:
    """The roots of 4 x^3 - 3 x = r (r in [-1, 1]) in [1/2, 1] (``x1``) and in
    [-1, -1/2] (``x3``), by Newton's method, both in one loop.

    On [1/2, 1] the cubic rises and is convex, on [-1, -1/2] it rises and is
    concave, so from a start on the right of ``x1`` and one on the left of
    ``x3`` every step moves towards the root and none passes it; each stops
    when a step no longer moves it (at most 200 steps; the slow case, a double
    root at r = +-1, is one the caller hands to Jacobi). The starts are the
    tangents at r = 0 of cos(acos(r) / 3) and of its mirror -cos(acos(-r) / 3),
    which lie on those sides since the first is concave in r. Only +, -, *, /
    (correctly rounded, no contraction): the same bits on every CPU.
    """
    cdef double a = 0.8661 + r / 6.0, b = -0.8661 + r / 6.0, na, nb, fa, fb
    cdef bint moving_a = True, moving_b = True
    cdef int step
    if a > 1.0:
        a = 1.0
    if b < -1.0:
        b = -1.0
    for step in range(200):
        if moving_a:
            fa = 12.0 * a * a - 3.0
            na = a - ((4.0 * a * a - 3.0) * a - r) / fa if fa > 0.0 else a
            moving_a = na < a
            if moving_a:
                a = na
        if moving_b:
            fb = 12.0 * b * b - 3.0
            nb = b - ((4.0 * b * b - 3.0) * b - r) / fb if fb > 0.0 else b
            moving_b = nb > b
            if moving_b:
                b = nb
        if not (moving_a or moving_b):
            break
    x1[0] = a
    x3[0] = b


cdef void _smallest_eigvec(const double* a, double* out) noexcept nogil:
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix
    (row-major ``a``).

    The eigenvalues come from the characteristic cubic, normalized to
    4 x^3 - 3 x = r and solved by Newton's method (``_cubic_roots``); the eigenvector is the longest cross product of two
    rows of ``a - lambda_min I``, which spans its null space. When the two
    smallest eigenvalues are within a factor ``_GAP_RATIO`` of the spread
    (nearly collinear or isotropic neighborhoods, where that construction
    loses accuracy), cyclic Jacobi takes over.
    """
    cdef double q, p1, p2, p, d0, d1, d2, b00, b11, b22, b01, b02, b12, r, x1, x2, x3, lam
    cdef double m00, m01, m02, m11, m12, m22
    cdef double c0x, c0y, c0z, c1x, c1y, c1z, c2x, c2y, c2z, n0, n1, n2, nrm
    q = (a[0] + a[4] + a[8]) / 3.0
    p1 = a[1] * a[1] + a[2] * a[2] + a[5] * a[5]
    d0 = a[0] - q
    d1 = a[4] - q
    d2 = a[8] - q
    p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1
    p = sqrt(p2 / 6.0)
    if not (p > 0.0):
        _jacobi_smallest(a, out)
        return
    b00 = d0 / p
    b11 = d1 / p
    b22 = d2 / p
    b01 = a[1] / p
    b02 = a[2] / p
    b12 = a[5] / p
    r = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
               + b02 * (b01 * b12 - b11 * b02))
    if r < -1.0:
        r = -1.0
    elif r > 1.0:
        r = 1.0
    # The eigenvalues of (a - q I) / p are 2 x for the three roots x of
    # 4 x^3 - 3 x = r (the trigonometric solution's cos(acos(r) / 3 + 2 pi k / 3)),
    # found without the C library's acos, cos and sin, whose last bit differs
    # between libraries and CPUs: x1 in [1/2, 1], x3 in [-1, -1/2], x2 = -x1 - x3.
    _cubic_roots(r, &x1, &x3)
    x2 = -(x1 + x3)
    # Jacobi takes over when lambda_mid - lambda_min < _GAP_RATIO * (lambda_max - lambda_min).
    if x2 - x3 < _GAP_RATIO * (x1 - x3):
        _jacobi_smallest(a, out)
        return
    lam = q + 2.0 * p * x3
    m00 = a[0] - lam
    m11 = a[4] - lam
    m22 = a[8] - lam
    m01 = a[1]
    m02 = a[2]
    m12 = a[5]
    # Rows (m00 m01 m02), (m01 m11 m12), (m02 m12 m22).
    c0x = m01 * m12 - m02 * m11
    c0y = m02 * m01 - m00 * m12
    c0z = m00 * m11 - m01 * m01
    c1x = m01 * m22 - m02 * m12
    c1y = m02 * m02 - m00 * m22
    c1z = m00 * m12 - m01 * m02
    c2x = m11 * m22 - m12 * m12
    c2y = m12 * m02 - m01 * m22
    c2z = m01 * m12 - m11 * m02
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    if n0 >= n1 and n0 >= n2:
        nrm = sqrt(n0)
        out[0] = c0x / nrm
        out[1] = c0y / nrm
        out[2] = c0z / nrm
    elif n1 >= n2:
        nrm = sqrt(n1)
        out[0] = c1x / nrm
        out[1] = c1y / nrm
        out[2] = c1z / nrm
    else:
        nrm = sqrt(n2)
        out[0] = c2x / nrm
        out[1] = c2y / nrm
        out[2] = c2z / nrm
    if not (nrm > 0.0):
        _jacobi_smallest(a, out)


cdef void _orient(const double* pts, Py_ssize_t n, int mode, const double* viewpoint,
                  double* out) noexcept nogil:
    """Flip normals of one object in place: away from its centroid (mode 1) or
    towards ``viewpoint`` (mode 2). A normal exactly perpendicular to the
    reference direction is left as it is."""
    cdef Py_ssize_t i
    cdef double cx = 0.0, cy = 0.0, cz = 0.0, dot, rx, ry, rz
    if mode == ORIENT_NONE or n == 0:
        return
    if mode == ORIENT_CENTROID:
        for i in range(n):
            cx += pts[3 * i]
            cy += pts[3 * i + 1]
            cz += pts[3 * i + 2]
        cx /= n
        cy /= n
        cz /= n
    for i in range(n):
        if mode == ORIENT_CENTROID:
            rx = pts[3 * i] - cx
            ry = pts[3 * i + 1] - cy
            rz = pts[3 * i + 2] - cz
        else:
            rx = viewpoint[0] - pts[3 * i]
            ry = viewpoint[1] - pts[3 * i + 1]
            rz = viewpoint[2] - pts[3 * i + 2]
        dot = out[3 * i] * rx + out[3 * i + 1] * ry + out[3 * i + 2] * rz
        if dot < 0.0:
            out[3 * i] = -out[3 * i]
            out[3 * i + 1] = -out[3 * i + 1]
            out[3 * i + 2] = -out[3 * i + 2]


cdef void _object_normals(const double* pts, Py_ssize_t n, Py_ssize_t k, int mode,
                          const double* viewpoint, double* fs, int64_t* its, Py_ssize_t max_n,
                          double* out) noexcept nogil:
    """All normals of one object, serially, in one thread's scratch rows."""
    cdef Grid g
    cdef Scratch sc
    cdef Batch bt
    cdef Py_ssize_t s, kk = k if k < n else n
    if n == 0:
        return
    _split_scratch(fs, its, max_n, k, &sc)
    bt.count = 0
    bt.nb = sc.nb
    bt.k = kk
    # The cell cap of the object's own size (4 n + 64), not of the largest
    # object's: the grid, hence the neighbors' order and the sums, are those
    # of the object alone (:func:`normals_single`), whatever it is packed with.
    _build_grid(pts, n, kk, 4 * n + 64, &g, sc.spts, sc.sxyz, max_n, sc.sidx, sc.cell_of, sc.cell_start, sc.blk)
    sc.guess[0] = INFINITY
    for s in range(n):
        _point_normal(&g, sc.spts, sc.cell_start, s, kk, &sc, &bt, out + 3 * sc.sidx[s])
    _batch_solve(&bt)
    _orient(pts, n, mode, viewpoint, out)


# Grid-order points per task of :func:`normals_single`'s threads.
cdef Py_ssize_t _SINGLE_CHUNK = 32


cdef void _shared_grid_normals(const Grid* g, const Scratch* shared, Py_ssize_t chunk, Py_ssize_t k,
                               double* fs, int64_t* its, Py_ssize_t n, double* out) noexcept nogil:
    """Normals of the grid-order points of chunk ``chunk`` (``_SINGLE_CHUNK``
    points, fewer in the last) of a grid built in ``shared``, with this
    thread's scratch rows for the query buffers."""
    cdef Scratch sc
    cdef Batch bt
    cdef Py_ssize_t s, end = (chunk + 1) * _SINGLE_CHUNK
    if end > n:
        end = n
    _split_scratch(fs, its, n, k, &sc)
    bt.count = 0
    bt.nb = sc.nb
    bt.k = k
    for s in range(chunk * _SINGLE_CHUNK, end):
        _point_normal(g, shared.spts, shared.cell_start, s, k, &sc, &bt, out + 3 * shared.sidx[s])
    _batch_solve(&bt)


def _check_scratch(fscratch, iscratch, Py_ssize_t max_n, Py_ssize_t k, int num_threads, name):
    f_len, i_len = scratch_sizes(max_n, k)
    if fscratch.shape[0] < num_threads or iscratch.shape[0] < num_threads:
        raise ValueError(f"{name}: fewer scratch rows than threads")
    if fscratch.shape[1] < f_len or iscratch.shape[1] < i_len:
        raise ValueError(f"{name}: scratch rows too short")


def normals_packed(const double[:, ::1] points, const int64_t[::1] offsets, Py_ssize_t k,
                   int mode, const double[::1] viewpoint, double[:, ::1] out,
                   double[:, ::1] fscratch, int64_t[:, ::1] iscratch,
                   Py_ssize_t max_n, int num_threads):
    """Fill ``out`` with the normals of every packed object.

    Objects are spread over ``num_threads`` OpenMP threads (dynamic schedule);
    ``fscratch``/``iscratch`` hold one row per thread, sized by
    :func:`scratch_sizes` for ``max_n``, the size of the largest object.
    Inputs are otherwise trusted: the Python layer validates them.
    """
    cdef Py_ssize_t n_obj = offsets.shape[0] - 1
    cdef Py_ssize_t o, tid
    cdef const double* pbase
    cdef double* obase
    if n_obj <= 0 or points.shape[0] == 0:
        return
    _check_scratch(fscratch, iscratch, max_n, k, num_threads, "normals_packed")
    pbase = &points[0, 0]
    obase = &out[0, 0]
    with nogil:
        for o in prange(n_obj, num_threads=num_threads, schedule="dynamic", chunksize=1):
            tid = threadid()
            _object_normals(pbase + 3 * offsets[o], offsets[o + 1] - offsets[o], k, mode,
                            &viewpoint[0], &fscratch[tid, 0], &iscratch[tid, 0], max_n,
                            obase + 3 * offsets[o])


cdef void _normals_single(const double* pts, Py_ssize_t n, Py_ssize_t k, int mode,
                          const double* viewpoint, double* obase, double* fs, Py_ssize_t f_stride,
                          int64_t* its, Py_ssize_t i_stride, int num_threads) noexcept:
    """Body of :func:`normals_single` on raw rows of ``f_stride`` doubles and
    ``i_stride`` int64 per thread."""
    cdef Py_ssize_t cap = 4 * n + 64
    cdef Py_ssize_t kk = k if k < n else n
    cdef Py_ssize_t c, tid, t, n_chunks = (n + _SINGLE_CHUNK - 1) // _SINGLE_CHUNK
    cdef Grid g
    cdef Scratch shared
    cdef Scratch sc
    _split_scratch(fs, its, n, k, &shared)
    with nogil:
        _build_grid(pts, n, kk, cap, &g, shared.spts, shared.sxyz, n, shared.sidx,
                    shared.cell_of, shared.cell_start, shared.blk)
        for t in range(num_threads):
            # carved as _shared_grid_normals carves it (with the clipped k), so that its
            # first query reads this guess
            _split_scratch(fs + t * f_stride, its + t * i_stride, n, kk, &sc)
            sc.guess[0] = INFINITY
        if num_threads == 1:
            for c in range(n_chunks):
                _shared_grid_normals(&g, &shared, c, kk, fs, its, n, obase)
        else:
            for c in prange(n_chunks, num_threads=num_threads, schedule="dynamic", chunksize=1):
                tid = threadid()
                _shared_grid_normals(&g, &shared, c, kk, fs + tid * f_stride, its + tid * i_stride, n, obase)
        _orient(pts, n, mode, viewpoint, obase)


def normals_single(const double[:, ::1] points, Py_ssize_t k, int mode,
                   const double[::1] viewpoint, double[:, ::1] out,
                   double[:, ::1] fscratch, int64_t[:, ::1] iscratch, int num_threads):
    """Fill ``out`` with the normals of one object, its points spread over
    ``num_threads`` OpenMP threads after a serial grid build.

    Thread 0's scratch row holds the shared grid; every row holds that
    thread's query buffers (layout of :func:`scratch_sizes` with
    ``max_n = len(points)``).
    """
    cdef Py_ssize_t n = points.shape[0]
    if n == 0:
        return
    _check_scratch(fscratch, iscratch, n, k, num_threads, "normals_single")
    _normals_single(&points[0, 0], n, k, mode, &viewpoint[0], &out[0, 0], &fscratch[0, 0],
                    fscratch.shape[1], &iscratch[0, 0], iscratch.shape[1], num_threads)


def cloud_in_window(const double[:, ::1] points, double min_side, double max_abs):
    """True when every coordinate is finite, the largest bounding-box side is
    at least ``min_side`` and every |coordinate| at most ``max_abs``: the
    clouds the validation layer would accept and leave unscaled. One pass
    over the points, without copies, for :func:`estimate_normals`'s fast
    path (anything else goes through the full validation)."""
    cdef Py_ssize_t i, n = points.shape[0]
    cdef double lo[3]
    cdef double hi[3]
    cdef double x, side = 0.0, amax = 0.0
    cdef int a
    cdef bint finite = True
    if n == 0 or points.shape[1] != 3:
        return False
    for a in range(3):
        lo[a] = INFINITY
        hi[a] = -INFINITY
    with nogil:
        for i in range(n):
            for a in range(3):
                x = points[i, a]
                # NaN fails both comparisons below and the finiteness test.
                finite = finite & (fabs(x) <= 1.7976931348623157e308)
                if x < lo[a]:
                    lo[a] = x
                if x > hi[a]:
                    hi[a] = x
    if not finite:
        return False
    for a in range(3):
        if hi[a] - lo[a] > side:
            side = hi[a] - lo[a]
        if fabs(lo[a]) > amax:
            amax = fabs(lo[a])
        if fabs(hi[a]) > amax:
            amax = fabs(hi[a])
    return side >= min_side and amax <= max_abs


def normals_cloud(const double[:, ::1] points, Py_ssize_t k, int mode,
                  const double[::1] viewpoint, int num_threads):
    """Normals of one validated object (as :func:`normals_single`), with the
    output and the scratch rows allocated here: one call per cloud."""
    cdef Py_ssize_t n = points.shape[0]
    cdef Py_ssize_t f_len, i_len
    cdef double* fs
    cdef int64_t* its
    if num_threads < 1:
        num_threads = 1
    f_len, i_len = scratch_sizes(n, k)
    out_arr = np.empty((n, 3), dtype=np.float64)
    if n == 0:
        return out_arr
    cdef double[:, ::1] out = out_arr
    fs = <double*>malloc(num_threads * f_len * sizeof(double))
    its = <int64_t*>malloc(num_threads * i_len * sizeof(int64_t))
    if fs == NULL or its == NULL:
        free(fs)
        free(its)
        raise MemoryError(f"estimate_normals: no memory for the scratch of {n} points")
    try:
        _normals_single(&points[0, 0], n, k, mode, &viewpoint[0], &out[0, 0], fs, f_len, its, i_len,
                        num_threads)
    finally:
        free(fs)
        free(its)
    return out_arr


def smallest_eigvecs(const double[:, :, ::1] covs, bint jacobi=False, bint lanes=False):
    """Unit eigenvector of the smallest eigenvalue of each symmetric 3x3
    matrix, by the kernel's solver one matrix at a time, with
    ``lanes=True`` by its vector-lane form at the level in use (symmetric
    matrices only: it reads the upper triangle), or with ``jacobi=True`` by
    its Jacobi fallback alone (exposed for tests)."""
    cdef Py_ssize_t i, n = covs.shape[0]
    cdef double buf[9]
    cdef int a, b
    cdef Batch bt
    out_arr = np.empty((n, 3), dtype=np.float64)
    cdef double[:, ::1] out = out_arr
    bt.count = 0
    bt.nb = NULL
    with nogil:
        for i in range(n):
            for a in range(3):
                for b in range(3):
                    buf[3 * a + b] = covs[i, a, b]
            if jacobi:
                _jacobi_smallest(buf, &out[i, 0])
            elif lanes:
                _batch_add(&bt, buf, &out[i, 0])
            else:
                _smallest_eigvec(buf, &out[i, 0])
        _batch_solve(&bt)
    return out_arr
