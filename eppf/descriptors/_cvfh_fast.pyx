# cython: language_level=3
"""Compiled VFH histograms for CVFH (see :class:`CVFHTransformer`).

One 308-bin signature per (centroid, normal) pair of an object, in single
precision with the summation orders of PCL 1.13's Eigen code (four-wide
vectors reduce as ``(x + z) + y``; three-wide ones as ``(x + y) + z``), so
that bins match PCL's except in rare ties: three angle histograms of the
pair features (f1, f2, f3) between the reference and every point, the
distance histogram (f4 over the largest distance) and 128 viewpoint bins.
"""

from libc.math cimport floor, acos, acosf, atan2f, sqrtf, fabsf, M_PI
from libc.stdint cimport int32_t, int64_t

import numpy as np
from libc.string cimport memset

from ..utils._common cimport clamp_floor
from ._flann_tree cimport build_tree, radius_search


cdef enum:
    NB = 45       # bins of f1, f2, f3, f4
    NV = 128      # viewpoint bins
    NSIG = 308

cdef double PI = M_PI


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
