# cython: language_level=3
"""Compiled kernels of CVFH (see :class:`CVFHTransformer`) and OUR-CVFH.

The curvature filter (:func:`low_curvature`: k nearest neighbors on a
uniform grid, their 3x3 scatter and a test of its smallest eigenvalue against the
threshold, with ``+ - * /`` only in a fixed order, so the same bits on every
CPU), PCL's region growing and FLANN's radius search, and the VFH histograms.

VFH: one 308-bin signature per (centroid, normal) pair of an object, in single
precision with the summation orders of PCL 1.13's Eigen code (four-wide
vectors reduce as ``(x + z) + y``; three-wide ones as ``(x + y) + z``), so
that bins match PCL's except in rare ties: three angle histograms of the
pair features (f1, f2, f3) between the reference and every point, the
distance histogram (f4 over the largest distance) and 128 viewpoint bins.
"""

from libc.math cimport floor, acos, acosf, atan2f, sqrtf, fabsf, cbrt, sqrt, fmin, fmax, isfinite, INFINITY, M_PI
from libc.stdint cimport int32_t, int64_t, uint8_t

import numpy as np
from libc.string cimport memset

from ..utils._common cimport clamp_floor, clamp_floor64, counts_to_starts
from ._flann_tree cimport build_tree, radius_search


cdef enum:
    NB = 45       # bins of f1, f2, f3, f4
    NV = 128      # viewpoint bins
    NSIG = 308

cdef double PI = M_PI

cdef enum:
    N_BUCKETS = 32  # buckets of the curvature search's counting sort
    GRID_CELLS_PER_POINT = 4  # most cells of the curvature's grid per point (plus 64)

# Points in an occupied cell of the curvature's grid, aimed at.
cdef double GRID_POINTS_PER_CELL = 5.0
# The fast path's guess: the previous query's k-th squared distance times this.
cdef double GUESS_FACTOR = 1.6


cdef inline float _dot4(float a0, float a1, float a2, float b0, float b1, float b2) noexcept nogil:
    """Eigen's SSE dot of two Vector4f with w = 0: (a0 b0 + a2 b2) + a1 b1."""
    cdef float t = a0 * b0 + a2 * b2
    return t + a1 * b1


cdef inline int _clamp_bin(double t, int n) noexcept nogil:
    return clamp_floor(t, n)


cdef void _vfh_one(const float* p, const float* nrm, int64_t n, const float* c, const float* nc,
                   bint normalize_bins, float* hist, double* out) noexcept nogil:
    cdef int64_t i, far = -1
    cdef float dx, dy, dz, f4, a1, a2, u0, u1, u2, t0, t1, t2, v0, v1, v2, vn, w0, w1, w2
    cdef float f1, f2, f3, best = -3.4028234663852886e38, dist, dnf, incr, incr_vp
    cdef float vx, vy, vz, vnorm
    cdef double pf, d_pi, alpha
    cdef int b, k
    memset(hist, 0, NSIG * sizeof(float))
    # distance normalization: the point farthest from the centroid (Vector3f norm)
    for i in range(n):
        dx = c[0] - p[3 * i]
        dy = c[1] - p[3 * i + 1]
        dz = c[2] - p[3 * i + 2]
        dist = sqrtf((dx * dx + dy * dy) + dz * dz)
        if dist > best:
            best = dist
            far = i
    if far < 0:  # only NaN distances
        far = 0
    dx = c[0] - p[3 * far]
    dy = c[1] - p[3 * far + 1]
    dz = c[2] - p[3 * far + 2]
    dnf = sqrtf(_dot4(dx, dy, dz, dx, dy, dz))
    incr = 1.0
    incr_vp = 1.0
    if normalize_bins:
        incr = (<float>100.0) / <float>(n - 1)
        incr_vp = <float>(100.0 / <double>n)
    d_pi = <double>((<float>1.0) / ((<float>2.0) * <float>PI))
    for i in range(n):
        dx = p[3 * i] - c[0]
        dy = p[3 * i + 1] - c[1]
        dz = p[3 * i + 2] - c[2]
        f4 = sqrtf(_dot4(dx, dy, dz, dx, dy, dz))
        if f4 == 0:
            continue
        a1 = _dot4(nc[0], nc[1], nc[2], dx, dy, dz) / f4
        a2 = _dot4(nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2], dx, dy, dz) / f4
        if acosf(fabsf(a1)) > acosf(fabsf(a2)):
            u0 = nrm[3 * i]
            u1 = nrm[3 * i + 1]
            u2 = nrm[3 * i + 2]
            t0 = nc[0]
            t1 = nc[1]
            t2 = nc[2]
            dx = -dx
            dy = -dy
            dz = -dz
            f3 = -a2
        else:
            u0 = nc[0]
            u1 = nc[1]
            u2 = nc[2]
            t0 = nrm[3 * i]
            t1 = nrm[3 * i + 1]
            t2 = nrm[3 * i + 2]
            f3 = a1
        # v = d x u, w = u x v
        v0 = dy * u2 - dz * u1
        v1 = dz * u0 - dx * u2
        v2 = dx * u1 - dy * u0
        vn = sqrtf(_dot4(v0, v1, v2, v0, v1, v2))
        if vn == 0:
            continue
        v0 = v0 / vn
        v1 = v1 / vn
        v2 = v2 / vn
        w0 = u1 * v2 - u2 * v1
        w1 = u2 * v0 - u0 * v2
        w2 = u0 * v1 - u1 * v0
        f2 = _dot4(v0, v1, v2, t0, t1, t2)
        f1 = atan2f(_dot4(w0, w1, w2, t0, t1, t2), _dot4(u0, u1, u2, t0, t1, t2))
        b = _clamp_bin(floor(NB * ((f1 + PI) * d_pi)), NB)
        hist[b] += incr
        b = _clamp_bin(floor(NB * ((f2 + PI) * d_pi)), NB)
        hist[NB + b] += incr
        b = _clamp_bin(floor(NB * ((f3 + PI) * d_pi)), NB)
        hist[2 * NB + b] += incr
        b = _clamp_bin(floor(NB * (f4 / <double>dnf)), NB)
        hist[3 * NB + b] += incr
    # viewpoint component, viewpoint at the origin
    vx = -c[0]
    vy = -c[1]
    vz = -c[2]
    vnorm = _dot4(vx, vy, vz, vx, vy, vz)
    if vnorm > 0:
        vnorm = sqrtf(vnorm)
        vx = vx / vnorm
        vy = vy / vnorm
        vz = vz / vnorm
    for i in range(n):
        alpha = (_dot4(nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2], vx, vy, vz) + 1.0) * 0.5
        b = _clamp_bin(floor(alpha * NV), NV)
        hist[4 * NB + b] += incr_vp
    for k in range(NSIG):
        out[k] = hist[k]


def vfh_signatures(const float[:, ::1] points, const float[:, ::1] normals,
                   const float[:, ::1] centroids, const float[:, ::1] ref_normals,
                   bint normalize_bins, double[:, ::1] out):
    """Fill ``out`` (n_refs, 308) with one VFH per (centroid, normal) row.

    ``points`` and ``normals`` (n, 3) single precision with n >= 2 (checked
    by the caller), references (n_refs, 3); runs without the GIL.
    """
    cdef int64_t n = points.shape[0], r
    cdef float hist[NSIG]
    if n < 2:
        raise ValueError("vfh_signatures: at least two points are needed")
    if (points.shape[1] != 3 or normals.shape[0] != n or normals.shape[1] != 3
            or centroids.shape[1] != 3 or ref_normals.shape[0] != centroids.shape[0]
            or ref_normals.shape[1] != 3 or out.shape[0] != centroids.shape[0] or out.shape[1] != NSIG):
        raise ValueError("vfh_signatures: inconsistent array shapes")
    with nogil:
        for r in range(centroids.shape[0]):
            _vfh_one(&points[0, 0], &normals[0, 0], n, &centroids[r, 0], &ref_normals[r, 0],
                     normalize_bins, hist, &out[r, 0])


def pcl_region_growing(const int32_t[::1] neighbors, const int64_t[::1] offsets,
                       const float[:, ::1] normals, double eps_angle, int64_t min_points,
                       int64_t[::1] labels):
    """PCL's ``extractEuclideanClustersSmooth``, seed by seed.

    Point ``i``'s radius neighbors are ``neighbors[offsets[i]:offsets[i + 1]]``
    in the search's order; as PCL, the first one is skipped (taken to be the
    query itself) and an unprocessed neighbor joins when
    ``acos(n_s . n_j) < eps_angle`` for the point ``s`` being expanded
    (single-precision dot products; NaN normals join nothing). Regions of at
    least ``min_points`` points are numbered in seed order into ``labels``
    (-1 elsewhere). Returns the number of regions.
    """
    cdef int64_t n = labels.shape[0], i, j, t, head, tail, s, k, n_regions = 0
    cdef float dot
    if (offsets.shape[0] != n + 1 or normals.shape[0] != n or normals.shape[1] != 3
            or (n > 0 and (offsets[0] != 0 or offsets[n] != neighbors.shape[0]))):
        raise ValueError("pcl_region_growing: inconsistent array shapes")
    for i in range(n):
        if offsets[i + 1] < offsets[i]:
            raise ValueError("pcl_region_growing: offsets must not decrease")
    for k in range(neighbors.shape[0]):
        if neighbors[k] < 0 or neighbors[k] >= n:
            raise ValueError("pcl_region_growing: neighbour index out of range")
    queue_arr = np.empty(max(n, 1), dtype=np.int64)
    done_arr = np.zeros(max(n, 1), dtype=np.int8)
    cdef int64_t[::1] queue = queue_arr
    cdef signed char[::1] done = done_arr
    with nogil:
        for i in range(n):
            labels[i] = -1
        for i in range(n):
            if done[i]:
                continue
            done[i] = 1
            queue[0] = i
            head = 0
            tail = 1
            while head < tail:
                s = queue[head]
                head += 1
                for k in range(offsets[s] + 1, offsets[s + 1]):
                    j = neighbors[k]
                    if done[j]:
                        continue
                    dot = normals[s, 0] * normals[j, 0] + normals[s, 1] * normals[j, 1]
                    dot = dot + normals[s, 2] * normals[j, 2]
                    if acos(<double>dot) < eps_angle:
                        done[j] = 1
                        queue[tail] = j
                        tail += 1
            if tail >= min_points:
                for t in range(tail):
                    labels[queue[t]] = n_regions
                n_regions += 1
    return n_regions


def radius_neighbors_flann(const float[:, ::1] points, double radius):
    """Every point's neighbors in the order PCL's unsorted radius search gives.

    Neighbors are the points whose single-precision squared distance is
    below ``float(radius**2)`` (the point itself included), listed in the
    depth-first order of FLANN's single k-d tree, as PCL's
    ``search::KdTree(false)`` returns them. Returns ``(indices, offsets)``:
    point ``i``'s neighbors are ``indices[offsets[i]:offsets[i + 1]]``.
    """
    cdef int64_t n = points.shape[0], i, total = 0, m
    cdef int d
    if points.shape[1] != 3:
        raise ValueError("radius_neighbors_flann: points must have shape (n, 3)")
    if n >= 2**30:
        raise ValueError("radius_neighbors_flann: at most 2**30 points")
    offsets = np.zeros(n + 1, dtype=np.int64)
    if n == 0:
        return np.zeros(0, dtype=np.int32), offsets
    n_nodes = 2 * n
    cdef int32_t[::1] vind = np.empty(n, dtype=np.int32)
    cdef int32_t[::1] ni = np.empty(5 * n_nodes, dtype=np.int32)
    cdef float[::1] nf = np.empty(2 * n_nodes, dtype=np.float32)
    cdef int32_t[::1] stk = np.empty(3 * n_nodes, dtype=np.int32)
    cdef float[::1] sbox = np.empty(6 * n_nodes, dtype=np.float32)
    cdef int32_t[::1] hits = np.empty(n, dtype=np.int32)
    cdef float[::1] hd2 = np.empty(n, dtype=np.float32)
    cdef int64_t[::1] off = offsets
    cdef float root_box[6]
    cdef float r2 = <float>(radius * radius)
    cdef const float* p = &points[0, 0]
    with nogil:
        for d in range(3):
            root_box[d] = p[d]
            root_box[3 + d] = p[d]
        for i in range(1, n):
            for d in range(3):
                if p[3 * i + d] < root_box[d]:
                    root_box[d] = p[3 * i + d]
                if p[3 * i + d] > root_box[3 + d]:
                    root_box[3 + d] = p[3 * i + d]
        build_tree(p, <int>n, &vind[0], &ni[0], &nf[0], &stk[0], &sbox[0])
        for i in range(n):
            m = radius_search(p, &p[3 * i], r2, &vind[0], &ni[0], &nf[0], root_box, &stk[0], &sbox[0],
                               &hits[0], &hd2[0])
            total += m
            off[i + 1] = total
    indices = np.empty(total, dtype=np.int32)
    cdef int32_t[::1] idx = indices
    with nogil:
        for i in range(n):
            m = radius_search(p, &p[3 * i], r2, &vind[0], &ni[0], &nf[0], root_box, &stk[0], &sbox[0],
                               &hits[0], &hd2[0])
            for d in range(<int>m):
                idx[off[i] + d] = hits[d]
    return indices, offsets


# ------------------------------------------------------------ curvature filter
# Exact k nearest neighbors on a uniform grid of cells (cell (x, y, z) is
# number (z * res_y + y) * res_x + x): the points are stored cell by cell
# (ascending index within a cell) and each query visits shells of cells of
# growing Chebyshev distance around its own until no point outside the
# visited block can be as close as its k-th. Every bound a cell or the block
# gets is a coordinate of a stored point minus the query's (the nearest
# coordinate of the points of the slabs of cells beyond it), rounded as the
# point distances are, so no rounding slack is needed: a pruned point's
# rounded squared distance is never below the bound that pruned it.


cdef inline double _first_cell(const double* e, int64_t n) noexcept nogil:
    """About one cell per point of the bounding box (extents ``e``), flat axes ignored."""
    cdef double e1 = e[0], e2 = e[1], e3 = e[2], t, h
    if e1 < e2:
        t = e1; e1 = e2; e2 = t
    if e2 < e3:
        t = e2; e2 = e3; e3 = t
    if e1 < e2:
        t = e1; e1 = e2; e2 = t
    if not (e1 > 0.0):
        return 1.0
    h = cbrt(e1 * e2 * e3 / n)
    if not (h > 0.0 and e3 >= h):
        h = sqrt(e1 * e2 / n)
        if not (h > 0.0 and e2 >= h):
            h = e1 / n
    return h


cdef double _grid_resolution(const double* e, double h, int64_t cap, int64_t* res) noexcept nogil:
    """Cells per axis for cell size ``h`` (enlarged until there are at most
    ``cap`` cells); returns the cell size used."""
    cdef double prod
    cdef int a
    while True:
        prod = 1.0
        for a in range(3):
            prod *= floor(e[a] / h) + 1.0
        if prod <= <double>cap:
            break
        h *= 1.25
    for a in range(3):
        res[a] = <int64_t>(floor(e[a] / h) + 1.0)
    return h


cdef int64_t _bin_points(const double* p, int64_t n, const double* lo, double inv_h, const int64_t* res,
                         int64_t* cell_of, int64_t* counts, int64_t* xyz) noexcept nogil:
    """Each point's cell into ``cell_of`` (and its cell coordinates into
    ``xyz``, 3 per point, unless NULL), the points per cell into ``counts``
    (zeroed here); returns the number of occupied cells."""
    cdef int64_t i, c, cx, cy, cz, occupied = 0, ncells = res[0] * res[1] * res[2]
    memset(counts, 0, ncells * sizeof(int64_t))
    for i in range(n):
        cx = clamp_floor64((p[3 * i] - lo[0]) * inv_h, res[0])
        cy = clamp_floor64((p[3 * i + 1] - lo[1]) * inv_h, res[1])
        cz = clamp_floor64((p[3 * i + 2] - lo[2]) * inv_h, res[2])
        c = (cz * res[1] + cy) * res[0] + cx
        if xyz != NULL:
            xyz[3 * i] = cx
            xyz[3 * i + 1] = cy
            xyz[3 * i + 2] = cz
        cell_of[i] = c
        occupied += counts[c] == 0
        counts[c] += 1
    return occupied


cdef void _fill_grid(const double* p, int64_t n, const double* lo, const double* e, double h, int64_t cap,
                     int64_t* res, int64_t* cell_of, int64_t* cell_start, int64_t* sidx, double* sp,
                     int64_t* cc) noexcept nogil:
    """Bin the points into cells of about size ``h`` (larger when there would
    be more than ``cap`` cells; one cell when ``h`` or an extent ``e`` is not
    finite) and store them cell by cell, ascending index within a cell: the
    point stored at ``s`` is ``sidx[s]``, its coordinates ``sp[3 s:3 s + 3]``
    and its cell's ``cc[3 s:3 s + 3]`` (``cc`` has room for ``6 n``: the
    first half is scratch), cell ``c`` holds the stored points
    ``cell_start[c]:cell_start[c + 1]`` (room for ``cap + 1``), and
    ``cell_of`` each point's cell."""
    cdef int64_t i, c, s
    cdef double inv_h = 0.0
    res[0] = res[1] = res[2] = 1
    if isfinite(h) and h > 0.0 and isfinite(e[0]) and isfinite(e[1]) and isfinite(e[2]):
        inv_h = 1.0 / _grid_resolution(e, h, cap, res)
    _bin_points(p, n, lo, inv_h, res, cell_of, cell_start, cc + 3 * n)
    c = res[0] * res[1] * res[2]
    counts_to_starts(cell_start, c)
    for i in range(n):
        s = cell_start[cell_of[i]]
        cell_start[cell_of[i]] = s + 1
        sidx[s] = i
        sp[3 * s] = p[3 * i]
        sp[3 * s + 1] = p[3 * i + 1]
        sp[3 * s + 2] = p[3 * i + 2]
        cc[3 * s] = cc[3 * (n + i)]
        cc[3 * s + 1] = cc[3 * (n + i) + 1]
        cc[3 * s + 2] = cc[3 * (n + i) + 2]
    for i in range(c, 0, -1):
        cell_start[i] = cell_start[i - 1]
    cell_start[0] = 0


cdef void _slab_bounds(const double* sp, int64_t n, const int64_t* cc, const int64_t* res, double* slabs,
                       double** above, double** below) noexcept nogil:
    """Point ``above[a]``/``below[a]`` into ``slabs`` (room for ``2 (res[0] +
    res[1] + res[2])``) and fill them: the least coordinate ``a`` of the
    points in the cell slabs j and up along axis ``a``, and the greatest of
    those in the slabs j and down (infinite where there are none)."""
    cdef int64_t s, i, t = 0
    cdef const int64_t* c
    cdef double x
    cdef int a
    for a in range(3):
        above[a] = &slabs[t]
        below[a] = &slabs[t + res[a]]
        for i in range(res[a]):
            above[a][i] = INFINITY
            below[a][i] = -INFINITY
        t += 2 * res[a]
    # (comparisons, not fmin/fmax: library calls here, and the coordinates are never NaN)
    for s in range(n):
        c = cc + 3 * s
        for a in range(3):
            x = sp[3 * s + a]
            if x < above[a][c[a]]:
                above[a][c[a]] = x
            if x > below[a][c[a]]:
                below[a][c[a]] = x
    for a in range(3):
        for i in range(res[a] - 2, -1, -1):
            if above[a][i + 1] < above[a][i]:
                above[a][i] = above[a][i + 1]
        for i in range(1, res[a]):
            if below[a][i - 1] > below[a][i]:
                below[a][i] = below[a][i - 1]


cdef inline double _slab_gap(double q, int64_t j, int64_t c, const double* above, const double* below) noexcept nogil:
    """Lower bound on |x - q| (rounded) over the points of cell slab ``j``
    for a query in slab ``c``: ``above[j]`` is the least coordinate of the
    slabs j and up, ``below[j]`` the greatest of the slabs j and down."""
    if j > c:
        return above[j] - q
    if j < c:
        return q - below[j]
    return 0.0


cdef inline int64_t _offer(double d2, int64_t j, int64_t count, int64_t k, double* bd, int64_t* bi) noexcept nogil:
    """Offer point ``j`` at squared distance ``d2`` to the k-list (``count``
    entries, ordered by (squared distance, index)); returns the new count."""
    cdef int64_t s
    if count == k:
        if d2 > bd[k - 1] or (d2 == bd[k - 1] and j > bi[k - 1]):
            return count
        s = k - 1
    else:
        s = count
        count += 1
    while s > 0 and bd[s - 1] > d2:
        bd[s] = bd[s - 1]
        bi[s] = bi[s - 1]
        s -= 1
    # equal distances (rare): the lower index first
    while s > 0 and bd[s - 1] == d2 and bi[s - 1] > j:
        bd[s] = bd[s - 1]
        bi[s] = bi[s - 1]
        s -= 1
    bd[s] = d2
    bi[s] = j
    return count


cdef inline bint _block_holds(const double* q, const int64_t* c, int64_t r, const int64_t* res,
                              double** above, double** below, double kth) noexcept nogil:
    """True when the block of cells within Chebyshev distance ``r`` of cell
    ``c`` is the whole grid, or when every point outside it lies farther
    from ``q`` than ``sqrt(kth)`` (its squared distance, rounded, above kth)."""
    cdef bint cover = True
    cdef double bound = INFINITY, b
    cdef int a
    for a in range(3):
        if c[a] - r > 0:
            cover = False
            b = q[a] - below[a][c[a] - r - 1]
            if b < bound:
                bound = b
        if c[a] + r < res[a] - 1:
            cover = False
            b = above[a][c[a] + r + 1] - q[a]
            if b < bound:
                bound = b
    return cover or kth < bound * bound


cdef bint _grid_knn_guess(const double* sp, const int64_t* sidx, const int64_t* cell_start, const int64_t* res,
                          double** above, double** below, const double* q, const int64_t* c, int64_t k,
                          double guess, double* cd, int64_t* ci, int64_t n_max, double* bd, int64_t* bi) noexcept nogil:
    """Fast path of :func:`_grid_knn`: the points of the 3x3x3 block around
    cell ``c`` within squared distance ``guess`` of ``q`` are collected
    without branches (into ``cd``/``ci``, room for every point), and the k
    nearest of them are the k nearest of all when there are at least k and
    no point outside the block can be as close as the k-th. Returns whether
    it succeeded (``bd``/``bi`` then hold the result)."""
    cdef int64_t jy, jz, x0, x1, row, i, j, m = 0, count = 0
    cdef int b
    cdef int64_t counts[N_BUCKETS]
    cdef double scale
    cdef double* sd = cd + n_max
    cdef int64_t* si = ci + n_max
    cdef int64_t* cb = ci + 2 * n_max
    cdef int64_t xlo = c[0] - 1 if c[0] > 0 else 0
    cdef int64_t xhi = c[0] + 1 if c[0] + 1 < res[0] else res[0] - 1
    cdef double qx = q[0], qy = q[1], qz = q[2], dx, dy, dz, d2, gx, gy, gy2, gz2
    for jz in range(c[2] - 1 if c[2] > 0 else 0, (c[2] + 1 if c[2] + 1 < res[2] else res[2] - 1) + 1):
        gz2 = _slab_gap(qz, jz, c[2], above[2], below[2])
        gz2 = gz2 * gz2
        if gz2 > guess:
            continue
        for jy in range(c[1] - 1 if c[1] > 0 else 0, (c[1] + 1 if c[1] + 1 < res[1] else res[1] - 1) + 1):
            gy = _slab_gap(qy, jy, c[1], above[1], below[1])
            gy2 = gy * gy
            if gy2 + gz2 > guess:
                continue
            # the row's cells within the guess: one run of stored points
            x0 = c[0]
            if x0 > xlo:
                gx = qx - below[0][x0 - 1]
                if not ((gx * gx + gy2) + gz2 > guess):
                    x0 -= 1
            x1 = c[0]
            if x1 < xhi:
                gx = above[0][x1 + 1] - qx
                if not ((gx * gx + gy2) + gz2 > guess):
                    x1 += 1
            row = (jz * res[1] + jy) * res[0]
            for i in range(cell_start[row + x0], cell_start[row + x1 + 1]):
                dx = sp[3 * i] - qx
                dy = sp[3 * i + 1] - qy
                dz = sp[3 * i + 2] - qz
                d2 = (dx * dx + dy * dy) + dz * dz
                cd[m] = d2
                ci[m] = sidx[i]
                m += d2 <= guess
    if m < k:
        return False
    # A counting sort by bucket of squared distance (monotone in it; on a
    # surface the buckets hold about as many each), then the k-list from the
    # candidates up to the k-th's bucket, offered nearly in order.
    for b in range(N_BUCKETS):
        counts[b] = 0
    scale = N_BUCKETS / guess
    for i in range(m):
        b = clamp_floor(cd[i] * scale, N_BUCKETS)
        cb[i] = b
        counts[b] += 1
    counts_to_starts(counts, N_BUCKETS)
    for i in range(m):
        j = counts[cb[i]]
        counts[cb[i]] = j + 1
        sd[j] = cd[i]
        si[j] = ci[i]
    b = 0
    while counts[b] < k:
        b += 1
    for i in range(counts[b]):
        count = _offer(sd[i], si[i], count, k, bd, bi)
    return _block_holds(q, c, 1, res, above, below, bd[k - 1])


cdef void _grid_knn(const double* sp, const int64_t* sidx, const int64_t* cell_start, const int64_t* res,
                    double** above, double** below, const double* q, const int64_t* c,
                    int64_t k, double* bd, int64_t* bi) noexcept nogil:
    """The k points nearest to ``q`` (in cell ``c``) into ``bi`` (original
    indices) and their squared distances ``(dx^2 + dy^2) + dz^2`` into ``bd``,
    ordered by (squared distance, index); ``k`` must not exceed the number
    of points. Exact search over growing shells of cells."""
    cdef int64_t r = 0, jx, jy, jz, step, cell, i, count = 0
    cdef double qx = q[0], qy = q[1], qz = q[2], dx, dy, dz, d2, gx, gy, gz, gz2, gyz2
    cdef bint edge_z, edge_yz
    while True:
        for jz in range(c[2] - r if c[2] > r else 0, (c[2] + r if c[2] + r < res[2] else res[2] - 1) + 1):
            gz = _slab_gap(qz, jz, c[2], above[2], below[2])
            gz2 = gz * gz
            if count == k and gz2 > bd[k - 1]:
                continue
            edge_z = jz == c[2] - r or jz == c[2] + r
            for jy in range(c[1] - r if c[1] > r else 0, (c[1] + r if c[1] + r < res[1] else res[1] - 1) + 1):
                gy = _slab_gap(qy, jy, c[1], above[1], below[1])
                gyz2 = gy * gy + gz2
                if count == k and gyz2 > bd[k - 1]:
                    continue
                edge_yz = edge_z or jy == c[1] - r or jy == c[1] + r
                # inside the shell's faces only the row's two end cells are new
                step = 1 if edge_yz or r == 0 else 2 * r
                jx = c[0] - r
                while jx <= c[0] + r:
                    if jx >= 0 and jx < res[0]:
                        gx = _slab_gap(qx, jx, c[0], above[0], below[0])
                        # (gx^2 + gy^2) + gz^2: the association of the distances, so never above them
                        if not (count == k and (gx * gx + gy * gy) + gz2 > bd[k - 1]):
                            cell = (jz * res[1] + jy) * res[0] + jx
                            for i in range(cell_start[cell], cell_start[cell + 1]):
                                dx = sp[3 * i] - qx
                                dy = sp[3 * i + 1] - qy
                                dz = sp[3 * i + 2] - qz
                                d2 = (dx * dx + dy * dy) + dz * dz
                                count = _offer(d2, sidx[i], count, k, bd, bi)
                    jx += step
        if count == k and _block_holds(q, c, r, res, above, below, bd[k - 1]):
            return
        r += 1


cdef bint _has_close(const double* sp, const int64_t* cell_start, const int64_t* res, double** above,
                     double** below, int64_t s, const int64_t* c, double r2, int64_t enough) noexcept nogil:
    """Whether at least ``enough`` stored points (stored point ``s`` itself
    included) lie within squared distance ``r2`` of stored point ``s`` (in
    cell ``c``). Only the box of cells whose slabs come that close along
    every axis is searched: a point outside it is farther along some axis."""
    cdef int64_t lo[3]
    cdef int64_t hi[3]
    cdef int64_t jy, jz, row, i, j, count = 0
    cdef double q, g, dx, dy, dz
    cdef int a
    for a in range(3):
        q = sp[3 * s + a]
        j = c[a]
        while j > 0:
            g = q - below[a][j - 1]
            if g * g > r2:
                break
            j -= 1
        lo[a] = j
        j = c[a]
        while j + 1 < res[a]:
            g = above[a][j + 1] - q
            if g * g > r2:
                break
            j += 1
        hi[a] = j
    for jz in range(lo[2], hi[2] + 1):
        for jy in range(lo[1], hi[1] + 1):
            # the row's cells are one run of stored points
            row = (jz * res[1] + jy) * res[0]
            for i in range(cell_start[row + lo[0]], cell_start[row + hi[0] + 1]):
                dx = sp[3 * i] - sp[3 * s]
                dy = sp[3 * i + 1] - sp[3 * s + 1]
                dz = sp[3 * i + 2] - sp[3 * s + 2]
                count += (dx * dx + dy * dy) + dz * dz <= r2
            if count >= enough:
                return True
    return False


def _grid_arrays(const double[:, ::1] points, name):
    """Check ``points`` (finite, n >= 1) and allocate a grid's arrays (see
    :func:`_fill_grid`, :func:`_slab_bounds`): ``(cap, box, cell_of,
    cell_start, sidx, sp, slabs, cc)`` with ``box`` the least coordinates and
    the extents as a (2, 3) array (infinite extents beyond double range)."""
    cdef int64_t n = points.shape[0], i
    cdef int a
    cdef double x
    cdef bint finite = True
    box = np.empty((2, 3))
    cdef double[:, ::1] bx = box
    with nogil:
        for a in range(3):
            bx[0, a] = points[0, a]
            bx[1, a] = points[0, a]
        for i in range(n):
            for a in range(3):
                x = points[i, a]
                finite = finite and isfinite(x)
                if x < bx[0, a]:
                    bx[0, a] = x
                if x > bx[1, a]:
                    bx[1, a] = x
        for a in range(3):
            bx[1, a] = bx[1, a] - bx[0, a]
    if not finite:
        raise ValueError(f"{name}: points must be finite")
    cap = GRID_CELLS_PER_POINT * n + 64
    return (cap, box, np.empty(n, dtype=np.int64), np.empty(cap + 1, dtype=np.int64), np.empty(n, dtype=np.int64),
            np.empty((n, 3)), np.empty(2 * (cap + 2)), np.empty(6 * n, dtype=np.int64))


def crowded_points(const double[:, ::1] points, double radius, Py_ssize_t enough):
    """How many points have at least two other points closer than ``radius``,
    counted up to ``enough``: at least as many as any count of such points
    made with other roundings of the distances, because a pair counts here
    when its squared distance is at most ``radius**2 * (1 + 1e-9)``. CVFH
    skips its second normals when this is below ``min_points``: fewer points
    than that would get a normal. Runs without the GIL.
    """
    cdef int64_t n = points.shape[0], cap, s, found = 0
    cdef double r2 = radius * radius * (1.0 + 1e-9)
    cdef int64_t res[3]
    cdef double* above[3]
    cdef double* below[3]
    if points.shape[1] != 3:
        raise ValueError("crowded_points: points must have shape (n, 3)")
    if not (radius >= 0.0):
        raise ValueError(f"crowded_points: radius must be a number >= 0, got {radius}")
    if n == 0 or enough <= 0:
        return 0
    cap, box, cell_of_a, cell_start_a, sidx_a, sp_a, slabs_a, cc_a = _grid_arrays(points, "crowded_points")
    cdef double[:, ::1] bx = box
    cdef int64_t[::1] cell_of = cell_of_a
    cdef int64_t[::1] cell_start = cell_start_a
    cdef int64_t[::1] sidx = sidx_a
    cdef double[:, ::1] sp = sp_a
    cdef double[::1] slabs = slabs_a
    cdef int64_t[::1] cc = cc_a
    with nogil:
        # cells of about the radius (the cell cap makes them larger on sparse clouds)
        _fill_grid(&points[0, 0], n, &bx[0, 0], &bx[1, 0], radius, cap, res, &cell_of[0], &cell_start[0], &sidx[0],
                   &sp[0, 0], &cc[0])
        _slab_bounds(&sp[0, 0], n, &cc[0], res, &slabs[0], above, below)
        for s in range(n):
            found += _has_close(&sp[0, 0], &cell_start[0], res, above, below, s, &cc[3 * s], r2, 3)
            if found >= enough:
                break
    return found


cdef bint _low_curvature_one(const double* p, const int64_t* nb, int64_t k, double threshold) noexcept nogil:
    """Whether lambda_min <= threshold * trace for the scatter matrix of the
    points ``nb`` (lambda_min / trace is PCL's surface variation).

    The scatter ``C`` about the neighbors' mean; ``C - t I`` with ``t =
    threshold * trace(C)`` is positive definite exactly when lambda_min > t,
    which its LDL^T decomposition tells by the signs of its pivots: no
    eigenvalue, only ``+ - * /`` in a fixed order.
    """
    cdef int64_t i, j
    cdef double mx = 0.0, my = 0.0, mz = 0.0, x, y, z
    cdef double c00 = 0.0, c01 = 0.0, c02 = 0.0, c11 = 0.0, c12 = 0.0, c22 = 0.0
    cdef double t, d0, d1, d2, l10, l20, r21
    for i in range(k):
        j = nb[i]
        mx += p[3 * j]
        my += p[3 * j + 1]
        mz += p[3 * j + 2]
    mx /= k
    my /= k
    mz /= k
    for i in range(k):
        j = nb[i]
        x = p[3 * j] - mx
        y = p[3 * j + 1] - my
        z = p[3 * j + 2] - mz
        c00 += x * x
        c01 += x * y
        c02 += x * z
        c11 += y * y
        c12 += y * z
        c22 += z * z
    t = threshold * ((c00 + c11) + c22)
    d0 = c00 - t
    if not (d0 > 0.0):
        return True
    l10 = c01 / d0
    l20 = c02 / d0
    d1 = (c11 - t) - l10 * c01
    if not (d1 > 0.0):
        return True
    r21 = c12 - l20 * c01
    d2 = ((c22 - t) - l20 * c02) - (r21 / d1) * r21
    return not (d2 > 0.0)


def low_curvature(const double[:, ::1] points, Py_ssize_t k, double threshold):
    """Which points pass CVFH's curvature filter, and where neighbors tie.

    Point ``i`` passes when the surface variation ``lambda_min / (lambda_0 +
    lambda_1 + lambda_2)`` of the scatter of its ``k`` nearest neighbors (the
    point itself included; ``min(k, n)`` of them) is at most ``threshold``,
    or when those neighbors all coincide. Returns ``(passes, tied)``: a
    boolean array of length ``n``, and the points (int64 indices) whose k-th
    nearest neighbor ties with the next one, so that their ``k`` nearest
    are not unique: their ``passes`` is left False for the caller to decide
    on the neighbors of its choice (:func:`low_curvature_of`). Runs without
    the GIL.
    """
    cdef int64_t n = points.shape[0], kk, kq, n_tied = 0, cap, s
    cdef double h, occupied, guess = -1.0
    cdef int64_t res[3]
    cdef const int64_t* cq
    cdef double* above[3]
    cdef double* below[3]
    if points.shape[1] != 3:
        raise ValueError("low_curvature: points must have shape (n, 3)")
    if k < 1:
        raise ValueError(f"low_curvature: k must be at least 1, got {k}")
    out = np.zeros(n, dtype=np.bool_)
    tied_arr = np.empty(n, dtype=np.int64)
    if n == 0:
        return out, tied_arr
    cap, box, cell_of_a, cell_start_a, sidx_a, sp_a, slabs_a, cc_a = _grid_arrays(points, "low_curvature")
    kk = min(<int64_t>k, n)
    kq = kk + 1 if kk < n else kk  # one more, to see a tie at the k-th
    cdef double[:, ::1] bx = box
    cdef int64_t[::1] cell_of = cell_of_a
    cdef int64_t[::1] cell_start = cell_start_a
    cdef int64_t[::1] sidx = sidx_a
    cdef double[:, ::1] sp = sp_a
    cdef double[::1] slabs = slabs_a
    cdef int64_t[::1] cc = cc_a
    cdef double[::1] bd = np.empty(kq, dtype=np.float64)
    cdef double[::1] cd = np.empty(2 * n, dtype=np.float64)
    cdef int64_t[::1] ci = np.empty(3 * n, dtype=np.int64)
    cdef int64_t[::1] bi = np.empty(kq, dtype=np.int64)
    cdef int64_t[::1] tied = tied_arr
    cdef uint8_t[::1] r = out.view(np.uint8)
    cdef const double* p = &points[0, 0]
    cdef const double* lo = &bx[0, 0]
    cdef const double* e = &bx[1, 0]
    with nogil:
        h = INFINITY
        if isfinite(e[0]) and isfinite(e[1]) and isfinite(e[2]):
            # a first grid, then the cell size that puts about GRID_POINTS_PER_CELL
            # points in an occupied cell of a surface (its occupancy grows as h^2)
            h = _grid_resolution(e, _first_cell(e, n), cap, res)
            occupied = <double>_bin_points(p, n, lo, 1.0 / h, res, &cell_of[0], &cell_start[0], NULL)
            h = h * fmin(fmax(sqrt(GRID_POINTS_PER_CELL * occupied / n), 0.25), 4.0)
        _fill_grid(p, n, lo, e, h, cap, res, &cell_of[0], &cell_start[0], &sidx[0], &sp[0, 0], &cc[0])
        _slab_bounds(&sp[0, 0], n, &cc[0], res, &slabs[0], above, below)
        # queries cell by cell, for locality
        for s in range(n):
            cq = &cc[3 * s]
            # the previous query's k-th, a little larger, as the guess (queries come cell by cell)
            if not _grid_knn_guess(&sp[0, 0], &sidx[0], &cell_start[0], res, above, below, &sp[s, 0], cq, kq,
                                   guess * GUESS_FACTOR, &cd[0], &ci[0], n, &bd[0], &bi[0]):
                _grid_knn(&sp[0, 0], &sidx[0], &cell_start[0], res, above, below, &sp[s, 0], cq, kq, &bd[0], &bi[0])
            guess = bd[kq - 1]
            if kq > kk and bd[kk] == bd[kk - 1]:
                tied[n_tied] = sidx[s]
                n_tied += 1
            else:
                r[sidx[s]] = _low_curvature_one(p, &bi[0], kk, threshold)
    tied_arr = np.sort(tied_arr[:n_tied])
    return out, tied_arr


def low_curvature_of(const double[:, ::1] points, const int64_t[:, ::1] neighbors, double threshold):
    """:func:`low_curvature`'s test for given neighbors: row ``r`` of
    ``neighbors`` lists the neighbors of one point (indices into ``points``).
    Returns a boolean array with one entry per row."""
    cdef int64_t m = neighbors.shape[0], k = neighbors.shape[1], n = points.shape[0], r, j
    if points.shape[1] != 3:
        raise ValueError("low_curvature_of: points must have shape (n, 3)")
    out = np.zeros(m, dtype=np.bool_)
    if m == 0:
        return out
    if k < 1:
        raise ValueError("low_curvature_of: at least one neighbor per row is needed")
    for r in range(m):
        for j in range(k):
            if neighbors[r, j] < 0 or neighbors[r, j] >= n:
                raise ValueError("low_curvature_of: neighbor index out of range")
    cdef uint8_t[::1] res = out.view(np.uint8)
    with nogil:
        for r in range(m):
            res[r] = _low_curvature_one(&points[0, 0], &neighbors[r, 0], k, threshold)
    return out

