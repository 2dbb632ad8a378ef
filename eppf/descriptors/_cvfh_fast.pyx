# cython: language_level=3
"""Compiled kernels of CVFH (see :class:`CVFHTransformer`) and OUR-CVFH.

The curvature filter (:func:`low_curvature`: k nearest neighbors on a k-d
tree, their 3x3 scatter and a test of its smallest eigenvalue against the
threshold, with ``+ - * /`` only in a fixed order, so the same bits on every
CPU), PCL's region growing and FLANN's radius search, and the VFH histograms.

VFH: one 308-bin signature per (centroid, normal) pair of an object, in single
precision with the summation orders of PCL 1.13's Eigen code (four-wide
vectors reduce as ``(x + z) + y``; three-wide ones as ``(x + y) + z``), so
that bins match PCL's except in rare ties: three angle histograms of the
pair features (f1, f2, f3) between the reference and every point, the
distance histogram (f4 over the largest distance) and 128 viewpoint bins.
"""

from libc.math cimport floor, acos, acosf, atan2f, sqrtf, fabsf, M_PI
from libc.stdint cimport int32_t, int64_t, uint8_t

import numpy as np
from libc.string cimport memset

from ..utils._common cimport clamp_floor
from ._flann_tree cimport build_tree, radius_search


cdef enum:
    NB = 45       # bins of f1, f2, f3, f4
    NV = 128      # viewpoint bins
    NSIG = 308

cdef double PI = M_PI

cdef enum:
    KD_LEAF = 8   # most points in a leaf of the curvature's k-d tree


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
# A k-d tree over double-precision points: node ``t`` holds the points
# perm[lo[t]:hi[t]]; an inner node splits them on axis dim[t] at the value
# cut[t] of its median point: its left child's points have that coordinate
# <= cut[t], its right child's >= cut[t].


cdef void _select(const double* p, int64_t* perm, int64_t lo, int64_t hi, int64_t m, int d) noexcept nogil:
    """Reorder perm[lo:hi] so that perm[m] holds the point of rank m - lo by
    coordinate d, smaller or equal ones before it and greater or equal ones
    after it (Hoare's selection, middle pivot: deterministic)."""
    cdef int64_t i, j, t
    cdef double pivot
    hi -= 1
    while lo < hi:
        pivot = p[3 * perm[(lo + hi) >> 1] + d]
        i = lo
        j = hi
        while i <= j:
            while p[3 * perm[i] + d] < pivot:
                i += 1
            while p[3 * perm[j] + d] > pivot:
                j -= 1
            if i <= j:
                t = perm[i]
                perm[i] = perm[j]
                perm[j] = t
                i += 1
                j -= 1
        if m <= j:
            hi = j
        elif m >= i:
            lo = i
        else:
            return


cdef int64_t _build_kd(const double* p, int64_t n, int64_t* perm, int64_t* lo, int64_t* hi,
                       int64_t* left, int* dim, double* cut, int64_t* stack) noexcept nogil:
    """Build the tree (node 0 the root; the right child of an inner node ``t``
    is ``left[t] + 1``); returns the number of nodes."""
    cdef int64_t i, t, a, b, m, n_nodes = 1, top = 1
    cdef int d, best
    cdef double mn[3]
    cdef double mx[3]
    cdef double v
    for i in range(n):
        perm[i] = i
    lo[0] = 0
    hi[0] = n
    stack[0] = 0
    while top > 0:
        top -= 1
        t = stack[top]
        a = lo[t]
        b = hi[t]
        if b - a <= KD_LEAF:
            left[t] = -1
            continue
        for d in range(3):
            mn[d] = p[3 * perm[a] + d]
            mx[d] = mn[d]
        for i in range(a + 1, b):
            for d in range(3):
                v = p[3 * perm[i] + d]
                if v < mn[d]:
                    mn[d] = v
                if v > mx[d]:
                    mx[d] = v
        best = 0
        for d in range(1, 3):
            if mx[d] - mn[d] > mx[best] - mn[best]:
                best = d
        m = a + ((b - a) >> 1)
        _select(p, perm, a, b, m, best)
        dim[t] = best
        cut[t] = p[3 * perm[m] + best]
        left[t] = n_nodes
        lo[n_nodes] = a
        hi[n_nodes] = m
        lo[n_nodes + 1] = m
        hi[n_nodes + 1] = b
        stack[top] = n_nodes
        stack[top + 1] = n_nodes + 1
        top += 2
        n_nodes += 2
    return n_nodes


cdef void _knn(const double* sp, const double* q, int64_t k, const int64_t* perm, const int64_t* lo,
               const int64_t* hi, const int64_t* left, const int* dim, const double* cut,
               int64_t* stack, double* gap, double* bd, int64_t* bi) noexcept nogil:
    """The k points nearest to ``q`` into ``bi`` (``sp``: the points in the
    tree's order, ``sp[i] = p[perm[i]]``; their squared distances,
    ``(dx^2 + dy^2) + dz^2``, into ``bd``), ordered by (squared distance,
    index): ties are broken by the lower index, whatever the tree."""
    cdef int64_t top = 1, t, i, j, s, found = 0, near
    cdef double dx, dy, dz, d2, diff
    stack[0] = 0
    gap[0] = 0.0
    while top > 0:
        top -= 1
        t = stack[top]
        # a child whose points all lie farther than the k-th neighbor (ties
        # with it are visited: a lower index wins them)
        if found == k and gap[top] > bd[k - 1]:
            continue
        while left[t] >= 0:
            diff = q[dim[t]] - cut[t]
            near = left[t] if diff < 0 else left[t] + 1
            # the other child's points lie at least |diff| away along dim[t]
            stack[top] = left[t] + 1 if diff < 0 else left[t]
            gap[top] = diff * diff
            top += 1
            t = near
        for i in range(lo[t], hi[t]):
            j = perm[i]
            dx = sp[3 * i] - q[0]
            dy = sp[3 * i + 1] - q[1]
            dz = sp[3 * i + 2] - q[2]
            d2 = (dx * dx + dy * dy) + dz * dz
            if found == k and (d2 > bd[k - 1] or (d2 == bd[k - 1] and j > bi[k - 1])):
                continue
            s = found if found < k else k - 1
            while s > 0 and (bd[s - 1] > d2 or (bd[s - 1] == d2 and bi[s - 1] > j)):
                bd[s] = bd[s - 1]
                bi[s] = bi[s - 1]
                s -= 1
            bd[s] = d2
            bi[s] = j
            if found < k:
                found += 1


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
    cdef int64_t n = points.shape[0], i, kk, kq, n_tied = 0
    if points.shape[1] != 3:
        raise ValueError("low_curvature: points must have shape (n, 3)")
    if k < 1:
        raise ValueError(f"low_curvature: k must be at least 1, got {k}")
    out = np.zeros(n, dtype=np.bool_)
    tied_arr = np.empty(n, dtype=np.int64)
    if n == 0:
        return out, tied_arr
    if not np.isfinite(np.asarray(points)).all():
        raise ValueError("low_curvature: points must be finite")
    kk = min(<int64_t>k, n)
    kq = kk + 1 if kk < n else kk  # one more, to see a tie at the k-th
    cdef int64_t[::1] perm = np.empty(n, dtype=np.int64)
    cdef int64_t[::1] lo = np.empty(2 * n, dtype=np.int64)
    cdef int64_t[::1] hi = np.empty(2 * n, dtype=np.int64)
    cdef int64_t[::1] left = np.empty(2 * n, dtype=np.int64)
    cdef int[::1] dim = np.empty(2 * n, dtype=np.intc)
    cdef double[::1] cut = np.empty(2 * n, dtype=np.float64)
    cdef int64_t[::1] stack = np.empty(2 * n + 2, dtype=np.int64)
    cdef double[::1] gap = np.empty(2 * n + 2, dtype=np.float64)
    cdef double[:, ::1] sp = np.empty((n, 3), dtype=np.float64)
    cdef double[::1] bd = np.empty(kq, dtype=np.float64)
    cdef int64_t[::1] bi = np.empty(kq, dtype=np.int64)
    cdef int64_t[::1] tied = tied_arr
    cdef uint8_t[::1] res = out.view(np.uint8)
    cdef const double* p = &points[0, 0]
    with nogil:
        _build_kd(p, n, &perm[0], &lo[0], &hi[0], &left[0], &dim[0], &cut[0], &stack[0])
        for i in range(n):
            sp[i, 0] = p[3 * perm[i]]
            sp[i, 1] = p[3 * perm[i] + 1]
            sp[i, 2] = p[3 * perm[i] + 2]
        # queries in the tree's order, for locality
        for i in range(n):
            _knn(&sp[0, 0], &sp[i, 0], kq, &perm[0], &lo[0], &hi[0], &left[0], &dim[0], &cut[0], &stack[0],
                 &gap[0], &bd[0], &bi[0])
            if kq > kk and bd[kk] == bd[kk - 1]:
                tied[n_tied] = perm[i]
                n_tied += 1
            else:
                res[perm[i]] = _low_curvature_one(p, &bi[0], kk, threshold)
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
