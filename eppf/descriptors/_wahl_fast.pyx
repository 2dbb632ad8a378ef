# cython: language_level=3
"""Compiled kernels of Wahl et al. (2003)'s surflet-pair-relation histograms.

Python allocates every array; the kernels fill them. Work is parallel over
objects (``prange``); each object has a private generator seeded from one
64-bit seed, so the output never depends on the number of threads. An object
without enough usable surflet pairs gets ``status[k] = 1`` and a zero row; the
Python layer (``eppf/descriptors/_wahl.py``) turns that into a ``ValueError``.
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

cnp.import_array()


# ---------------------------------------------------------------------------
# Wahl et al. (2003): surflet-pair-relation histograms.

cdef inline int _lin_bin(double v, double lo, double hi, int n_bins) noexcept nogil:
    """clip(floor(n_bins * (v - lo) / (hi - lo)), 0, n_bins - 1); NaN gives 0.

    Clamped in floating point before the conversion to int, so any double
    gives a bin in range.
    """
    return clamp_floor(n_bins * (v - lo) / (hi - lo), n_bins)


cdef inline int _surflet_frame(const double* p1, const double* n1,
                               const double* p2, const double* n2,
                               int source_parallel, double* feat) noexcept nogil:
    """The surflet frame of one pair: Wahl's beta, gamma, delta into ``feat``.

    The source s is the point whose normal is more perpendicular to the
    connecting line (smaller |n . d_hat|) by default, the more parallel one
    when ``source_parallel`` (PCL's PFH rule). With t = target, d = p_t - p_s,
    u = n_s, v = d x u / |d x u|, w = u x v:
    alpha = atan2(w . n_t, u . n_t), beta = v . n_t, gamma = u . d / |d|,
    delta = |d|. Returns 0 when |d| = 0 or n_s is parallel to d. ``feat``
    (5 doubles) gets alpha's arguments: w . n_t in ``feat[0]``, u . n_t in
    ``feat[4]``.
    """
    cdef double dx = p2[0] - p1[0], dy = p2[1] - p1[1], dz = p2[2] - p1[2]
    cdef double dist = sqrt(dx * dx + dy * dy + dz * dz)
    cdef double c1, c2, vx, vy, vz, vn, wx, wy, wz
    cdef const double* u
    cdef const double* nt
    cdef int swap
    if dist == 0.0:
        return 0
    dx /= dist
    dy /= dist
    dz /= dist
    c1 = n1[0] * dx + n1[1] * dy + n1[2] * dz
    c2 = n2[0] * dx + n2[1] * dy + n2[2] * dz
    if source_parallel:
        swap = fabs(c1) < fabs(c2)
    else:
        swap = fabs(c1) > fabs(c2)
    if swap:
        u = n2
        nt = n1
        dx = -dx
        dy = -dy
        dz = -dz
        feat[2] = -c2
    else:
        u = n1
        nt = n2
        feat[2] = c1
    vx = dy * u[2] - dz * u[1]
    vy = dz * u[0] - dx * u[2]
    vz = dx * u[1] - dy * u[0]
    vn = sqrt(vx * vx + vy * vy + vz * vz)
    if vn < 1e-12:
        return 0
    vx /= vn
    vy /= vn
    vz /= vn
    wx = u[1] * vz - u[2] * vy
    wy = u[2] * vx - u[0] * vz
    wz = u[0] * vy - u[1] * vx
    feat[0] = wx * nt[0] + wy * nt[1] + wz * nt[2]
    feat[4] = u[0] * nt[0] + u[1] * nt[1] + u[2] * nt[2]
    feat[1] = vx * nt[0] + vy * nt[1] + vz * nt[2]
    feat[3] = dist
    return 1


cdef inline int _surflet_pair(const double* p1, const double* n1,
                              const double* p2, const double* n2,
                              int source_parallel, double* feat) noexcept nogil:
    """Wahl's (alpha, beta, gamma, delta) of one surflet pair into ``feat`` (5
    doubles); see ``_surflet_frame``."""
    if not _surflet_frame(p1, n1, p2, n2, source_parallel, feat):
        return 0
    feat[0] = atan2(feat[0], feat[4])
    return 1


cdef inline int _alpha_bin(double y, double x, int n_bins, double guard) noexcept nogil:
    """``_lin_bin(atan2(y, x), -pi, pi, n_bins)`` without atan2 in nearly all cases.

    atan on [0, 1] by a degree-11 odd polynomial (error below 1.7e-6 rad),
    extended to the circle by symmetry. ``guard`` (in bins) exceeds that
    error's effect; a value that close to a bin boundary, the circle's ends
    (signed zeros), or (0, 0) takes atan2, so the bin is always atan2's.
    """
    cdef double ax = fabs(x), ay = fabs(y), mn, mx, z, z2, a, t
    cdef int i
    mn = ax if ax < ay else ay
    mx = ay if ax < ay else ax
    if not (mx > 0.0):
        return _lin_bin(atan2(y, x), -M_PI, M_PI, n_bins)
    z = mn / mx
    z2 = z * z
    a = z * (0.99997726 + z2 * (-0.33262347 + z2 * (0.19354346 + z2 * (-0.11643287
             + z2 * (0.05265332 + z2 * -0.01172120)))))
    if ay > ax:
        a = M_PI / 2 - a
    if x < 0.0:
        a = M_PI - a
    if y < 0.0:
        a = -a
    t = (a + M_PI) * (n_bins / (2 * M_PI))
    # out of [0, n_bins) (NaN included, e.g. from inf / inf): atan2 decides,
    # before any conversion to int
    if not (t >= 0.0 and t < n_bins):
        return _lin_bin(atan2(y, x), -M_PI, M_PI, n_bins)
    i = <int>t
    if t - i < guard or i + 1 - t < guard:
        return _lin_bin(atan2(y, x), -M_PI, M_PI, n_bins)
    return i


def surflet_pair_features(const double[::1] p1, const double[::1] n1,
                          const double[::1] p2, const double[::1] n2,
                          bint source_parallel=False):
    """Wahl's (alpha, beta, gamma, delta) for one pair (None when undefined)."""
    cdef double feat[5]
    if not _surflet_pair(&p1[0], &n1[0], &p2[0], &n2[0], source_parallel, feat):
        return None
    return (feat[0], feat[1], feat[2], feat[3])


cdef int _wahl_object(const double* points, const double* normals,
                      int64_t start, int64_t n, uint64_t seed, int n_pairs,
                      const int32_t* nb, int source_parallel,
                      int32_t* cell, double* dist, double* out) noexcept nogil:
    cdef uint64_t state = seed
    cdef int64_t attempts = 0, max_attempts = 1000 + <int64_t>200 * n_pairs
    cdef int t = 0, i
    cdef uint32_t a, b
    cdef double feat[5]
    cdef double dmax = 0.0, inv
    cdef double guard = nb[0] * 1e-5 / (2 * M_PI) + 1e-9
    while t < n_pairs:
        attempts += 1
        if attempts > max_attempts:
            return 1
        a = rand_below(&state, <uint32_t>n)
        b = rand_below(&state, <uint32_t>n)
        if a == b:
            continue
        if not _surflet_frame(points + 3 * (start + a), normals + 3 * (start + a),
                              points + 3 * (start + b), normals + 3 * (start + b),
                              source_parallel, feat):
            continue
        cell[t] = ((_alpha_bin(feat[0], feat[4], nb[0], guard) * nb[1]
                    + _lin_bin(feat[1], -1.0, 1.0, nb[1])) * nb[2]
                   + _lin_bin(feat[2], -1.0, 1.0, nb[2]))
        dist[t] = feat[3]
        if feat[3] > dmax:
            dmax = feat[3]
        t += 1
    for i in range(n_pairs):
        out[cell[i] * nb[3] + _lin_bin(dist[i] / dmax, 0.0, 1.0, nb[3])] += 1.0
    inv = 1.0 / n_pairs
    for i in range(nb[0] * nb[1] * nb[2] * nb[3]):
        out[i] *= inv
    return 0


def wahl_batch(const double[:, ::1] points, const double[:, ::1] normals,
               const int64_t[::1] offsets, const uint64_t[::1] seeds,
               int n_pairs, const int32_t[::1] n_bins, bint source_parallel,
               double[:, ::1] out, int8_t[::1] status, int num_threads):
    """Fill ``out`` (n_objects, prod(n_bins)) with Wahl histograms."""
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1
    cdef Py_ssize_t k
    cdef int tid
    if n_bins.shape[0] != 4 or np.min(np.asarray(n_bins)) < 1 or n_pairs < 1:
        raise ValueError("wahl_batch: n_bins must hold four positive counts, n_pairs must be positive")
    cdef int n_out = n_bins[0] * n_bins[1] * n_bins[2] * n_bins[3]
    check_batch(points.shape[0], offsets, seeds, out, status, n_out, "wahl_batch")
    if normals.shape[0] != points.shape[0] or normals.shape[1] != 3 or points.shape[1] != 3:
        raise ValueError("wahl_batch: points and normals must both be (N, 3)")
    num_threads = max(1, num_threads)
    cdef int32_t[:, ::1] cell = np.empty((num_threads, n_pairs), dtype=np.int32)
    cdef double[:, ::1] dist = np.empty((num_threads, n_pairs), dtype=np.float64)
    for k in prange(n_objects, nogil=True, schedule="dynamic", num_threads=num_threads):
        tid = threadid()
        if offsets[k + 1] - offsets[k] < 2:  # no pair
            status[k] = 1
        else:
            status[k] = <int8_t>_wahl_object(
                &points[0, 0], &normals[0, 0], offsets[k], offsets[k + 1] - offsets[k], seeds[k],
                n_pairs, &n_bins[0], source_parallel, &cell[tid, 0], &dist[tid, 0],
                &out[k, 0])
        if status[k] != 0:
            memset(&out[k, 0], 0, n_out * sizeof(double))


def wahl_alpha_bins(const double[::1] y, const double[::1] x, int n_bins, bint exact=False):
    """Bins of alpha = atan2(y, x) on [-pi, pi] as the Wahl kernel takes them
    (``exact``: straight from atan2). For the tests."""
    cdef Py_ssize_t k
    cdef int32_t[::1] out = np.empty(y.shape[0], dtype=np.int32)
    cdef double guard = n_bins * 1e-5 / (2 * M_PI) + 1e-9
    for k in range(y.shape[0]):
        if exact:
            out[k] = _lin_bin(atan2(y[k], x[k]), -M_PI, M_PI, n_bins)
        else:
            out[k] = _alpha_bin(y[k], x[k], n_bins, guard)
    return np.asarray(out)
