# cython: language_level=3
"""Compiled kernel of the Viewpoint Feature Histogram (Rusu et al. 2010, PCL 1.13).

Python allocates every array; the kernel fills one 308-bin row per object, in
parallel over objects (``prange``). Each object is computed by one thread in
point order, so the output does not depend on the number of threads. See
``eppf/descriptors/_vfh.py`` for the description of every step.
"""
from cython.parallel cimport prange
from libc.math cimport sqrt, floor, fabs, atan2, frexp, ldexp, M_PI
from libc.stdint cimport int64_t

from ..utils._common cimport clamp_floor64, pow2_scale

DEF N_ANGLE = 45
DEF N_VIEW = 128


cdef inline int64_t _bin(double t, int64_t n) noexcept nogil:
    """``floor(t)`` clamped to ``[0, n - 1]`` in floating point first (NaN -> 0)."""
    return clamp_floor64(t, n)


cdef inline int64_t _round_bin(double t, int64_t n) noexcept nogil:
    """PCL's ``pcl_round`` (half away from zero: ``floor(t + 0.5)`` for t >= 0), clamped."""
    if not (t > 0.0):
        return 0
    return _bin(t + 0.5, n)


cdef void _vfh_object(const double* pts, const double* nrm, Py_ssize_t n, const double* vp,
                      bint normalize_bins, bint normalize_distances, bint size_component,
                      bint homogeneous, bint pcl_centroid, double* out) noexcept nogil:
    cdef double sc = pow2_scale(pts, n)
    cdef float cf[3]
    cdef float fv
    cdef bint single = pcl_centroid
    cdef double c[3]
    cdef double nc[3]
    cdef double dv[3]
    cdef double d[3]
    cdef double v[3]
    cdef double w[3]
    cdef const double* u
    cdef const double* t
    cdef double f1, f2, f3, f4, a1, a2, vn, dmax = 0.0, dnorm = 1.0, incr, m, big
    cdef double two_pi = 2.0 * M_PI
    cdef Py_ssize_t i
    cdef int j
    c[0] = 0.0
    c[1] = 0.0
    c[2] = 0.0
    nc[0] = 0.0
    nc[1] = 0.0
    nc[2] = 0.0
    for i in range(n):
        for j in range(3):
            c[j] += pts[3 * i + j] * sc
            nc[j] += nrm[3 * i + j]
    for j in range(3):
        c[j] /= n
        nc[j] /= n  # PCL keeps the mean normal unnormalised
    if size_component and normalize_distances:
        for i in range(n):
            for j in range(3):
                d[j] = pts[3 * i + j] * sc - c[j]
            f4 = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            if f4 > dmax:
                dmax = f4
        # PCL: |centroid - farthest point| with the centroid's w = 1 left in
        dnorm = sqrt(dmax * dmax + sc * sc) if homogeneous else dmax
        if not (dnorm > 0.0):
            dnorm = 1.0
    incr = 100.0 / <double>(n - 1) if normalize_bins else 1.0
    for i in range(n):
        for j in range(3):
            d[j] = pts[3 * i + j] * sc - c[j]
        f4 = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if f4 == 0.0:
            continue
        a1 = (nc[0] * d[0] + nc[1] * d[1] + nc[2] * d[2]) / f4
        a2 = (nrm[3 * i] * d[0] + nrm[3 * i + 1] * d[1] + nrm[3 * i + 2] * d[2]) / f4
        # PCL: acos(|a1|) > acos(|a2|), false when either is NaN (|a| > 1)
        if fabs(a1) <= 1.0 and fabs(a2) <= 1.0 and fabs(a1) < fabs(a2):
            u = &nrm[3 * i]
            t = nc
            for j in range(3):
                d[j] = -d[j]
            f3 = -a2
        else:
            u = nc
            t = &nrm[3 * i]
            f3 = a1
        v[0] = d[1] * u[2] - d[2] * u[1]
        v[1] = d[2] * u[0] - d[0] * u[2]
        v[2] = d[0] * u[1] - d[1] * u[0]
        vn = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if vn == 0.0:
            continue
        for j in range(3):
            v[j] /= vn
        w[0] = u[1] * v[2] - u[2] * v[1]
        w[1] = u[2] * v[0] - u[0] * v[2]
        w[2] = u[0] * v[1] - u[1] * v[0]
        f2 = v[0] * t[0] + v[1] * t[1] + v[2] * t[2]
        f1 = atan2(w[0] * t[0] + w[1] * t[1] + w[2] * t[2], u[0] * t[0] + u[1] * t[1] + u[2] * t[2])
        out[_bin(N_ANGLE * ((f1 + M_PI) / two_pi), N_ANGLE)] += incr
        out[N_ANGLE + _bin(N_ANGLE * ((f2 + M_PI) / two_pi), N_ANGLE)] += incr
        out[2 * N_ANGLE + _bin(N_ANGLE * ((f3 + M_PI) / two_pi), N_ANGLE)] += incr
        if size_component:
            if normalize_distances:
                out[3 * N_ANGLE + _bin(N_ANGLE * (f4 / dnorm), N_ANGLE)] += incr
            else:
                out[3 * N_ANGLE + _round_bin((f4 / sc) * 100.0, N_ANGLE)] += incr
    # viewpoint component: direction from the centroid to the viewpoint, in
    # the input's units
    if single:
        # PCL's centroid: coordinates rounded to float, summed in float; only
        # for clouds and viewpoints of magnitude within 1e-30 to 1e30, where
        # floats hold them (PCL cannot hold other clouds at all)
        big = 0.0
        for j in range(3):
            if not (fabs(vp[j]) <= 1e30):
                single = False
        for i in range(3 * n):
            if fabs(pts[i]) > big:
                big = fabs(pts[i])
        if not (big >= 1e-30 and big <= 1e30):
            single = False
    big = 0.0
    if single:
        cf[0] = 0.0
        cf[1] = 0.0
        cf[2] = 0.0
        for i in range(n):
            for j in range(3):
                fv = <float>pts[3 * i + j]
                cf[j] = cf[j] + fv
        for j in range(3):
            cf[j] = cf[j] / <float>n
            fv = <float>vp[j]
            fv = fv - cf[j]
            dv[j] = <double>fv
            if fabs(dv[j]) > big:
                big = fabs(dv[j])
    else:
        for j in range(3):
            dv[j] = 0.5 * vp[j] - 0.5 * (c[j] / sc)  # halved: no difference overflows
            if fabs(dv[j]) > big:
                big = fabs(dv[j])
    if big > 0.0:
        for j in range(3):
            dv[j] /= big  # |v - c| = 2 big |dv| without overflow
        m = dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]
        if homogeneous:
            # PCL normalizes the 4-vector (v - c, -1): the centroid's w = 1 is left in
            m = m + ((1.0 if single else 0.5) / big) * ((1.0 if single else 0.5) / big)
        m = sqrt(m)
        for j in range(3):
            dv[j] /= m
    incr = 100.0 / <double>n if normalize_bins else 1.0
    for i in range(n):
        a1 = (nrm[3 * i] * dv[0] + nrm[3 * i + 1] * dv[1] + nrm[3 * i + 2] * dv[2] + 1.0) * 0.5
        out[4 * N_ANGLE + _bin(a1 * N_VIEW, N_VIEW)] += incr


def vfh_batch(const double[:, ::1] points, const double[:, ::1] normals, const int64_t[::1] offsets,
              const double[::1] viewpoint, bint normalize_bins, bint normalize_distances,
              bint size_component, bint homogeneous, bint pcl_centroid, double[:, ::1] out, int num_threads):
    """VFH rows of packed objects: object k is ``points[offsets[k]:offsets[k + 1]]``.

    ``out`` (n_objects, 308) must be zeroed.
    """
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1
    cdef Py_ssize_t k
    if out.shape[0] != n_objects or out.shape[1] != 4 * N_ANGLE + N_VIEW:
        raise ValueError("vfh_batch: out must have shape (n_objects, 308)")
    if points.shape[1] != 3 or normals.shape[1] != 3 or normals.shape[0] != points.shape[0]:
        raise ValueError("vfh_batch: points and normals must both have shape (n_total, 3)")
    if viewpoint.shape[0] != 3:
        raise ValueError("vfh_batch: viewpoint needs 3 entries")
    for k in range(n_objects):
        if offsets[k + 1] - offsets[k] < 2 or offsets[k] < 0 or offsets[k + 1] > points.shape[0]:
            raise ValueError("vfh_batch: every object needs at least 2 points inside points")
    if n_objects == 0:
        return
    for k in prange(n_objects, nogil=True, schedule="dynamic", num_threads=num_threads):
        _vfh_object(&points[offsets[k], 0], &normals[offsets[k], 0], offsets[k + 1] - offsets[k], &viewpoint[0],
                    normalize_bins, normalize_distances, size_component, homogeneous, pcl_centroid, &out[k, 0])
