# cython: language_level=3
"""Compiled GRSD kernel (see :class:`GRSDTransformer` for the formulas).

Per object, in single precision as PCL 1.13 computes it:

1. voxelize on an axis-aligned grid of width ``w`` anchored at multiples of
   ``w`` (PCL's ``VoxelGrid``); each occupied voxel is represented by the
   mean of its points;
2. build a k-d tree over the object's points with the splitting rule and
   leaf size of FLANN's single-index tree (the tree PCL's ``KdTree`` wraps),
   because PCL's RSD takes the normal of the *first* neighbor the tree
   returns as the reference normal, and an unsorted radius search returns
   neighbors in the tree's depth-first order;
3. radius search (radius ``w``) around each voxel centroid, RSD radii from
   the min/max normal angle per distance bin, surface class;
4. count, for every occupied voxel, the classes of its 26 neighbor cells
   (empty cells are class 5) and fold the 6 x 6 matrix to its 21 upper
   triangular entries, ``T[i, j] + T[j, i]``.

Work is parallel over objects (``prange``); each object's result depends on
that object alone. Scratch memory is allocated once per thread before the
loop.
"""

from cython.parallel cimport prange, threadid
from libc.math cimport floorf, floor, fabs, sqrt, acos
from libc.stdint cimport int64_t, int32_t, int8_t
from libc.string cimport memset

from ..utils._common cimport counts_to_starts
from ._flann_tree cimport build_tree, radius_search

import numpy as np

cdef enum:
    N_CLASSES = 6       # noise, plane, cylinder, sphere, edge, empty
    N_BINS = 21
    MAX_SUBDIV = 64

cdef struct KeyIdx:
    int64_t key
    int64_t idx


cdef KeyIdx* _sort_by_key(KeyIdx* a, KeyIdx* b, int n, int64_t n_keys) noexcept nogil:
    """Sort ``a[:n]`` by key, stably (so by (key, index) when the indices
    ascend, as the voxelization writes them), keys in [0, n_keys): a least
    significant digit radix sort, 8 bits a pass, as many passes as ``n_keys``
    needs, between ``a`` and ``b`` (n entries each). Returns the array that
    holds the result."""
    cdef int64_t counts[256]
    cdef int i, shift = 0, d
    cdef KeyIdx* t
    while shift < 64 and (n_keys - 1) >> shift > 0:
        memset(counts, 0, sizeof(counts))
        for i in range(n):
            counts[(a[i].key >> shift) & 255] += 1
        counts_to_starts(counts, 256)
        for i in range(n):
            d = <int>((a[i].key >> shift) & 255)
            b[counts[d]] = a[i]
            counts[d] += 1
        t = a
        a = b
        b = t
        shift += 8
    return a


cdef inline int _clamp_cell(float t, int hi) noexcept nogil:
    """Cell index from a float, bounded for every float (NaN -> 0)."""
    if not (t > 0):
        return 0
    if t >= hi:
        return hi
    return <int>t


cdef inline int _clamp_signed(float t, int lim) noexcept nogil:
    """Integer-valued float to int in [-lim, lim], for every float (NaN -> -lim)."""
    if not (t > -lim):
        return -lim
    if t >= lim:
        return lim
    return <int>t


# --------------------------------------------------------------- RSD class

cdef int _rsd_class(const float* nrm, const int32_t* hits, const float* hd2, int n_hits,
                    double max_dist, int nsub, double plane_radius, const double* thr,
                    double* amin, double* amax) noexcept nogil:
    """PCL's computeRSD (distance-sorted variant) then getSimpleType."""
    cdef int i, b, ref
    cdef float c32, rmin, rmax, tmp
    cdef double c, a, dist, f, aa = 0.0, ad = 0.0, bb = 0.0, bd = 0.0, t
    cdef double half_pi = 1.5707963267948966
    if n_hits < 2:
        rmin = 0.0
        rmax = 0.0
    else:
        for b in range(nsub):
            amin[b] = 1.7976931348623157e308
            amax[b] = -1.7976931348623157e308
        amin[0] = 0.0
        amax[0] = 0.0
        ref = hits[0]
        for i in range(1, n_hits):
            c32 = nrm[3 * hits[i]] * nrm[3 * ref] + nrm[3 * hits[i] + 1] * nrm[3 * ref + 1]
            c32 = c32 + nrm[3 * hits[i] + 2] * nrm[3 * ref + 2]
            c = c32
            if c > 1:
                c = 1
            if c < -1:
                c = -1
            a = acos(c)
            if a > half_pi:
                a = 3.141592653589793 - a
            dist = sqrt(<double>hd2[i])
            if dist > max_dist:
                continue
            t = floor(nsub * dist / max_dist)
            if not (t > 0):
                b = 0
            elif t >= nsub:
                b = nsub - 1
            else:
                b = <int>t
            if a < amin[b]:
                amin[b] = a
            if a > amax[b]:
                amax[b] = a
        for b in range(nsub):
            if amax[b] >= 0:
                f = (b + 0.5) * max_dist / nsub
                aa = aa + amin[b] * amin[b]
                ad = ad + amin[b] * f
                bb = bb + amax[b] * amax[b]
                bd = bd + amax[b] * f
        if aa == 0.0:
            rmin = <float>plane_radius
        else:
            rmin = <float>(ad / aa if ad / aa < plane_radius else plane_radius)
        if bb == 0.0:
            rmax = <float>plane_radius
        else:
            rmax = <float>(bd / bb if bd / bb < plane_radius else plane_radius)
        rmin = rmin * <float>1.1
        rmax = rmax * <float>0.9
        if not (rmin < rmax):
            tmp = rmin
            rmin = rmax
            rmax = tmp
    # thr = min_radius_plane, max_radius_noise, min_radius_cylinder, max_min_radius_diff
    if rmin > thr[0]:
        return 1
    if rmax > thr[2]:
        return 2
    if rmin < thr[1]:
        return 0
    if <float>(rmax - rmin) < thr[3]:
        return 3
    return 4


cdef int _grsd_object(const float* p, const float* nrm, int n, float width, double max_dist,
                      int nsub, double plane_radius, const double* thr,
                      KeyIdx* ki, int64_t* ukeys, int32_t* vijk, float* cent, int8_t* types,
                      int32_t* vind, int32_t* ni, float* nf, int32_t* stk, float* sbox,
                      int32_t* hits, float* hd2, double* work, double* out) noexcept nogil:
    """One object's 21 transition counts into out; voxel classes into types.
    Returns the number of occupied voxels."""
    cdef int i, d, v, n_vox, start, cnt, dx, dy, dz, t, n_hits
    cdef int64_t key, j
    cdef int64_t row_ptr[9]
    cdef bint row_in
    cdef float inv = (<float>1.0) / width
    cdef float mins[3]
    cdef float maxs[3]
    cdef int minb[3]
    cdef int dims[3]
    cdef int cell[3]
    cdef float sx, sy, sz, fc, r2
    cdef float root_box[6]
    cdef int64_t T[N_CLASSES * N_CLASSES]
    cdef int a, b, k, r
    for d in range(3):
        mins[d] = p[d]
        maxs[d] = p[d]
    for i in range(1, n):
        for d in range(3):
            if p[3 * i + d] < mins[d]:
                mins[d] = p[3 * i + d]
            if p[3 * i + d] > maxs[d]:
                maxs[d] = p[3 * i + d]
    for d in range(3):
        root_box[d] = mins[d]
        root_box[3 + d] = maxs[d]
        # the caller checked that the grid has fewer than 2**31 cells
        minb[d] = _clamp_signed(floorf(mins[d] * inv), 1 << 30)
        dims[d] = _clamp_cell(floorf(maxs[d] * inv) - <float>minb[d], 1 << 30) + 1
    for i in range(n):
        for d in range(3):
            cell[d] = _clamp_cell(floorf(p[3 * i + d] * inv) - <float>minb[d], dims[d] - 1)
        ki[i].key = cell[0] + <int64_t>dims[0] * (cell[1] + <int64_t>dims[1] * cell[2])
        ki[i].idx = i
    ki = _sort_by_key(ki, ki + n, n, <int64_t>dims[0] * dims[1] * dims[2])
    # voxels: unique keys, centroids (float sums in point order, as PCL's VoxelGrid)
    n_vox = 0
    start = 0
    while start < n:
        key = ki[start].key
        cnt = 0
        sx = 0.0
        sy = 0.0
        sz = 0.0
        while start + cnt < n and ki[start + cnt].key == key:
            i = <int>ki[start + cnt].idx
            sx = sx + p[3 * i]
            sy = sy + p[3 * i + 1]
            sz = sz + p[3 * i + 2]
            cnt += 1
        fc = <float>cnt
        cent[3 * n_vox] = sx / fc
        cent[3 * n_vox + 1] = sy / fc
        cent[3 * n_vox + 2] = sz / fc
        ukeys[n_vox] = key
        vijk[3 * n_vox] = <int32_t>(key % dims[0])
        vijk[3 * n_vox + 1] = <int32_t>((key // dims[0]) % dims[1])
        vijk[3 * n_vox + 2] = <int32_t>(key // (<int64_t>dims[0] * dims[1]))
        n_vox += 1
        start += cnt
    build_tree(p, n, vind, ni, nf, stk, sbox)
    r2 = <float>(max_dist * max_dist)
    for v in range(n_vox):
        n_hits = radius_search(p, &cent[3 * v], r2, vind, ni, nf, root_box, stk,
                               sbox, hits, hd2)
        types[v] = <int8_t>_rsd_class(nrm, hits, hd2, n_hits, max_dist, nsub, plane_radius,
                                      thr, work, work + MAX_SUBDIV)
    memset(T, 0, sizeof(T))
    # Neighbor classes: voxels come in ascending key order, so for each of
    # the nine (dy, dz) rows the key of the row's dx = -1 cell grows with v,
    # and one pointer per row sweeps the keys once (the three cells of a row
    # are consecutive keys, hence consecutive entries when occupied).
    for r in range(9):
        row_ptr[r] = 0
    for v in range(n_vox):
        for r in range(9):
            dy = r % 3 - 1
            dz = r // 3 - 1
            key = ukeys[v] - 1 + dims[0] * (dy + <int64_t>dims[1] * dz)
            j = row_ptr[r]
            while j < n_vox and ukeys[j] < key:
                j += 1
            row_ptr[r] = j
            cell[1] = vijk[3 * v + 1] + dy
            cell[2] = vijk[3 * v + 2] + dz
            row_in = cell[1] >= 0 and cell[1] < dims[1] and cell[2] >= 0 and cell[2] < dims[2]
            for dx in range(-1, 2):
                if dx == 0 and r == 4:
                    continue
                cell[0] = vijk[3 * v] + dx
                t = N_CLASSES - 1
                if row_in and cell[0] >= 0 and cell[0] < dims[0]:
                    while j < n_vox and ukeys[j] < key + 1 + dx:
                        j += 1
                    if j < n_vox and ukeys[j] == key + 1 + dx:
                        t = types[j]
                T[types[v] * N_CLASSES + t] += 1
    k = 0
    for a in range(N_CLASSES):
        for b in range(a, N_CLASSES):
            out[k] = <double>(T[a * N_CLASSES + b] + T[b * N_CLASSES + a])
            k += 1
    return n_vox


def _check_arrays(points, normals, int n_subdivisions, thresholds):
    """Shapes the kernel relies on (the transformer passes valid ones)."""
    if points.shape[1] != 3 or normals.shape[0] != points.shape[0] or normals.shape[1] != 3:
        raise ValueError("GRSD kernel: points and normals must both have shape (n, 3)")
    if not 1 <= n_subdivisions <= MAX_SUBDIV:
        raise ValueError(f"GRSD kernel: n_subdivisions must be in [1, {MAX_SUBDIV}]")
    if thresholds.shape[0] != 4:
        raise ValueError("GRSD kernel: 4 class thresholds are needed")
    if points.shape[0] >= 2**30:
        raise ValueError("GRSD kernel: at most 2**30 points per object")


def _scratch(int num_threads, int64_t max_n):
    m = max(int(max_n), 1)
    n_nodes = 2 * m
    return dict(
        ki=np.empty((num_threads, 4 * m), dtype=np.int64),  # two arrays of m (key, index) pairs
        ukeys=np.empty((num_threads, m), dtype=np.int64),
        vijk=np.empty((num_threads, 3 * m), dtype=np.int32),
        cent=np.empty((num_threads, 3 * m), dtype=np.float32),
        types=np.empty((num_threads, m), dtype=np.int8),
        vind=np.empty((num_threads, m), dtype=np.int32),
        ni=np.empty((num_threads, 5 * n_nodes), dtype=np.int32),
        nf=np.empty((num_threads, 2 * n_nodes), dtype=np.float32),
        stk=np.empty((num_threads, 3 * n_nodes), dtype=np.int32),
        sbox=np.empty((num_threads, 6 * n_nodes), dtype=np.float32),
        hits=np.empty((num_threads, m), dtype=np.int32),
        hd2=np.empty((num_threads, m), dtype=np.float32),
        work=np.empty((num_threads, 2 * MAX_SUBDIV), dtype=np.float64),
    )


def grsd_batch(const float[:, ::1] points, const float[:, ::1] normals,
               const int64_t[::1] offsets, double width, int n_subdivisions,
               double plane_radius, const double[::1] thresholds, double[:, ::1] out,
               int num_threads):
    """Fill ``out`` (n_objects, 21) with GRSD transition counts.

    ``points`` and ``normals`` are single precision, packed by ``offsets``;
    objects have at least one point and a grid of fewer than 2**31 cells
    (checked by the caller); ``n_subdivisions`` is in [1, 64].
    """
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1
    cdef Py_ssize_t k
    cdef int64_t max_n = 0
    cdef int tid
    for k in range(n_objects):
        if offsets[k + 1] - offsets[k] > max_n:
            max_n = offsets[k + 1] - offsets[k]
    s = _scratch(num_threads, max_n)
    cdef int64_t[:, ::1] ki = s["ki"]
    cdef int64_t[:, ::1] ukeys = s["ukeys"]
    cdef int32_t[:, ::1] vijk = s["vijk"]
    cdef float[:, ::1] cent = s["cent"]
    cdef int8_t[:, ::1] types = s["types"]
    cdef int32_t[:, ::1] vind = s["vind"]
    cdef int32_t[:, ::1] ni = s["ni"]
    cdef float[:, ::1] nf = s["nf"]
    cdef int32_t[:, ::1] stk = s["stk"]
    cdef float[:, ::1] sbox = s["sbox"]
    cdef int32_t[:, ::1] hits = s["hits"]
    cdef float[:, ::1] hd2 = s["hd2"]
    cdef double[:, ::1] work = s["work"]
    cdef float w = <float>width
    _check_arrays(points, normals, n_subdivisions, thresholds)
    if offsets.shape[0] < 1 or out.shape[0] != n_objects or out.shape[1] != N_BINS:
        raise ValueError("grsd_batch: out must have shape (n_objects, 21)")
    if n_objects == 0:
        return
    if offsets[0] != 0 or offsets[n_objects] != points.shape[0]:
        raise ValueError("grsd_batch: offsets must run from 0 to len(points)")
    for k in range(n_objects):
        if offsets[k + 1] - offsets[k] < 1:
            raise ValueError("grsd_batch: every object needs at least one point")
    for k in prange(n_objects, nogil=True, schedule="dynamic", num_threads=num_threads):
        tid = threadid()
        _grsd_object(&points[offsets[k], 0], &normals[offsets[k], 0],
                     <int>(offsets[k + 1] - offsets[k]), w, width, n_subdivisions, plane_radius,
                     &thresholds[0], <KeyIdx*>&ki[tid, 0], &ukeys[tid, 0], &vijk[tid, 0],
                     &cent[tid, 0], &types[tid, 0], &vind[tid, 0], &ni[tid, 0], &nf[tid, 0],
                     &stk[tid, 0], &sbox[tid, 0], &hits[tid, 0], &hd2[tid, 0], &work[tid, 0],
                     &out[k, 0])


def grsd_voxels(const float[:, ::1] points, const float[:, ::1] normals, double width,
                int n_subdivisions, double plane_radius, const double[::1] thresholds):
    """Test hook: one object's (voxel cells (V, 3), centroids (V, 3), classes (V,),
    counts (21,)), voxels in key order (x fastest)."""
    cdef int64_t n = points.shape[0]
    _check_arrays(points, normals, n_subdivisions, thresholds)
    if n < 1:
        raise ValueError("grsd_voxels: at least one point is needed")
    s = _scratch(1, n)
    cdef int64_t[:, ::1] ki = s["ki"]
    cdef int64_t[:, ::1] ukeys = s["ukeys"]
    cdef int32_t[:, ::1] vijk = s["vijk"]
    cdef float[:, ::1] cent = s["cent"]
    cdef int8_t[:, ::1] types = s["types"]
    cdef int32_t[:, ::1] vind = s["vind"]
    cdef int32_t[:, ::1] ni = s["ni"]
    cdef float[:, ::1] nf = s["nf"]
    cdef int32_t[:, ::1] stk = s["stk"]
    cdef float[:, ::1] sbox = s["sbox"]
    cdef int32_t[:, ::1] hits = s["hits"]
    cdef float[:, ::1] hd2 = s["hd2"]
    cdef double[:, ::1] work = s["work"]
    counts = np.zeros(N_BINS, dtype=np.float64)
    cdef double[::1] cv = counts
    cdef int n_vox
    with nogil:
        n_vox = _grsd_object(&points[0, 0], &normals[0, 0], <int>n, <float>width, width,
                             n_subdivisions, plane_radius, &thresholds[0], <KeyIdx*>&ki[0, 0],
                             &ukeys[0, 0], &vijk[0, 0], &cent[0, 0], &types[0, 0], &vind[0, 0],
                             &ni[0, 0], &nf[0, 0], &stk[0, 0], &sbox[0, 0], &hits[0, 0],
                             &hd2[0, 0], &work[0, 0], &cv[0])
    return (np.asarray(s["vijk"][0, : 3 * n_vox]).reshape(-1, 3).copy(),
            np.asarray(s["cent"][0, : 3 * n_vox]).reshape(-1, 3).copy(),
            np.asarray(s["types"][0, :n_vox]).copy(), counts)


def grid_check(const float[:, ::1] points, const int64_t[::1] offsets, float inv, double max_cells,
               double max_index):
    """The first object (by ``offsets``) whose single-precision points
    ``points`` are not all finite (returned as ``(k, None)``) or whose voxel
    grid of width ``1 / inv`` has more than ``max_cells`` cells or reaches a
    cell index of ``max_index`` (``(k, (nx, ny, nz))``, cells per axis);
    ``(-1, None)`` when every object is fine. Per axis, the cells are
    ``floor(hi * inv) - floor(lo * inv) + 1`` in double precision from the
    object's float32 extremes, their product is compared with
    ``max_cells``, and the largest ``|coordinate| * inv`` with ``max_index``.
    Objects have at least one point (the caller checks)."""
    cdef Py_ssize_t n_obj = offsets.shape[0] - 1
    cdef Py_ssize_t k, i
    cdef int d
    cdef float x
    cdef float lo[3]
    cdef float hi[3]
    cdef double cells[3]
    cdef double reach, dinv = inv
    cdef bint finite
    if points.shape[1] != 3 or n_obj < 0 or offsets[0] < 0 or offsets[n_obj] > points.shape[0]:
        raise ValueError("grid_check: points must have shape (n, 3) and offsets lie within them")
    for k in range(n_obj):
        if offsets[k + 1] <= offsets[k]:
            raise ValueError("grid_check: every object needs at least one point (offsets must increase)")
    with nogil:
        for k in range(n_obj):
            finite = True
            for d in range(3):
                lo[d] = points[offsets[k], d]
                hi[d] = lo[d]
            for i in range(offsets[k], offsets[k + 1]):
                for d in range(3):
                    x = points[i, d]
                    # NaN and infinities fail (x - x is NaN for both)
                    finite = finite & (x - x == 0)
                    if x < lo[d]:
                        lo[d] = x
                    if x > hi[d]:
                        hi[d] = x
            if not finite:
                with gil:
                    return k, None
            reach = 0.0
            for d in range(3):
                cells[d] = floor(<double>hi[d] * dinv) - floor(<double>lo[d] * dinv) + 1
                if fabs(<double>lo[d]) * dinv > reach:
                    reach = fabs(<double>lo[d]) * dinv
                if fabs(<double>hi[d]) * dinv > reach:
                    reach = fabs(<double>hi[d]) * dinv
            if cells[0] * cells[1] * cells[2] > max_cells or reach >= max_index:
                with gil:
                    return k, (cells[0], cells[1], cells[2])
    return -1, None
