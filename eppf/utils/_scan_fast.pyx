# cython: language_level=3
"""Compiled validation and packing of ragged point-cloud input.

:func:`scan_clouds` checks many clouds in one pass with the objects spread
over OpenMP threads (copy, finiteness, bounding box, normal lengths), and
:func:`split_columns` splits a packed (N, 6) block into points and normals.
Every estimator's validation goes through them (``eppf.utils._validation``);
they know nothing of any descriptor.
"""
import numpy as np

cimport numpy as cnp
from cython.parallel cimport prange
from libc.math cimport sqrt, isfinite, fabs, ldexp
from libc.stdint cimport int8_t, int64_t, uint64_t
from libc.string cimport memcpy

from ._common cimport omp_get_max_threads, EPPF_HAVE_OPENMP

cnp.import_array()


def openmp_max_threads():
    """Return OpenMP's default thread count (1 in a serial build)."""
    return omp_get_max_threads()


def has_openmp():
    """Return True when the kernels were compiled with OpenMP."""
    return bool(EPPF_HAVE_OPENMP)


# Normals with a component above _NORMAL_BIG = 2**510 are multiplied by
# _NORMAL_SHRINK = 2**-514 before their length is taken (as in
# ``eppf.utils._validation.check_point_cloud``): the sum of squares then stays below
# 3 * 2**1020 and the length above 1/16.
cdef double _NORMAL_BIG = ldexp(1.0, 510)
cdef double _NORMAL_SHRINK = ldexp(1.0, -514)


cdef signed char _scan_object(const double* src, double* dst, int64_t n, int cols, double* lo,
                              double* hi) noexcept nogil:
    """Validate one cloud of ``n`` rows of ``cols`` (3 or 6) float64 values.

    Copies ``src`` to ``dst`` first unless they are the same memory, then
    checks finiteness, takes the bounding box of columns 0-2 into ``lo`` and
    ``hi`` and, with normals, divides each normal by its length
    ``sqrt((x * x + y * y) + z * z)`` in place (after an exact 2**-514 for
    normals with a component above 2**510). Returns 0 (valid), 1 (a NaN
    or infinite value), 2 (all points identical) or 3 (a normal shorter
    than 1e-12). ``dst`` is the caller's own copy, so an invalid cloud may be
    left partly normalized there (the caller then validates the original
    cloud by cloud to word the error).
    """
    cdef int64_t i, m = n * cols
    cdef int c
    cdef double v, d
    cdef double* row
    if src != dst:
        memcpy(dst, src, m * sizeof(double))
    for i in range(m):
        if not isfinite(dst[i]):
            return 1
    for c in range(3):
        lo[c] = dst[c]
        hi[c] = dst[c]
    for i in range(1, n):
        row = dst + i * cols
        for c in range(3):
            v = row[c]
            if v < lo[c]:
                lo[c] = v
            if v > hi[c]:
                hi[c] = v
    if lo[0] == hi[0] and lo[1] == hi[1] and lo[2] == hi[2]:
        return 2
    if cols == 6:
        for i in range(n):
            row = dst + i * 6
            # A normal with a component above 2**510 is first multiplied by
            # 2**-514 (exact), so that its squares cannot overflow (which
            # made such normals silently zero); others are as they were.
            v = fabs(row[3])
            if fabs(row[4]) > v:
                v = fabs(row[4])
            if fabs(row[5]) > v:
                v = fabs(row[5])
            if v > _NORMAL_BIG:
                row[3] = row[3] * _NORMAL_SHRINK
                row[4] = row[4] * _NORMAL_SHRINK
                row[5] = row[5] * _NORMAL_SHRINK
            d = sqrt((row[3] * row[3] + row[4] * row[4]) + row[5] * row[5])
            if d < 1e-12:
                return 3
            row[3] = row[3] / d
            row[4] = row[4] / d
            row[5] = row[5] / d
    return 0


def scan_clouds(double[:, ::1] data, const int64_t[::1] offsets, list sources=None, int num_threads=1):
    """One validation pass over packed clouds, objects in parallel.

    ``data`` is (N, 3) or (N, 6) float64, object ``k`` its rows
    ``offsets[k]:offsets[k + 1]`` (at least one row each). With ``sources``
    (one C-contiguous float64 array per object, of its rows), the objects
    are first copied into ``data``; otherwise ``data`` already holds them.
    Each object is checked for finiteness and distinct points, its bounding
    box is taken and, with six columns, its normals are divided by their
    lengths ``sqrt((x * x + y * y) + z * z)`` in place (see
    ``_scan_object``).

    Returns
    -------
    lo, hi : (n_objects, 3) float64
        Per-axis minimum and maximum of the coordinates (columns 0-2).
    status : (n_objects,) int8
        0 valid, 1 a NaN or infinite value in any column, 2 all points
        identical, 3 a zero-length normal.
    """
    cdef Py_ssize_t n_obj = offsets.shape[0] - 1
    cdef int cols = <int>data.shape[1]
    cdef Py_ssize_t k
    if cols != 3 and cols != 6:
        raise ValueError("data must have 3 or 6 columns")
    lo_arr = np.zeros((n_obj, 3), dtype=np.float64)
    hi_arr = np.zeros((n_obj, 3), dtype=np.float64)
    status_arr = np.zeros(n_obj, dtype=np.int8)
    if n_obj <= 0:
        return lo_arr, hi_arr, status_arr
    if offsets[0] != 0 or offsets[n_obj] != data.shape[0]:
        raise ValueError("offsets do not match the data")
    for k in range(n_obj):
        if offsets[k + 1] <= offsets[k]:
            raise ValueError("every object needs at least one row")
    src_arr = np.zeros(n_obj, dtype=np.uintp)
    cdef size_t[::1] src = src_arr
    cdef cnp.ndarray item
    if sources is not None:
        if len(sources) != n_obj:
            raise ValueError("sources must hold one array per object")
        for k in range(n_obj):
            item = sources[k]
            if (item.dtype != np.float64 or not item.flags.c_contiguous or item.ndim != 2
                    or item.shape[0] != offsets[k + 1] - offsets[k] or item.shape[1] != cols):
                raise ValueError("sources must be C-contiguous float64 arrays of the objects' shapes")
            src[k] = <size_t>cnp.PyArray_DATA(item)
    cdef double[:, ::1] lo = lo_arr
    cdef double[:, ::1] hi = hi_arr
    cdef signed char[::1] status = status_arr
    cdef double* base = &data[0, 0]
    for k in prange(n_obj, nogil=True, num_threads=max(1, num_threads), schedule="dynamic", chunksize=4):
        status[k] = _scan_object(
            <const double*>src[k] if src[k] != 0 else base + offsets[k] * cols, base + offsets[k] * cols,
            offsets[k + 1] - offsets[k], cols, &lo[k, 0], &hi[k, 0])
    return lo_arr, hi_arr, status_arr


def split_columns(const double[:, ::1] data):
    """C-contiguous copies of columns 0-2 and 3-5 of ``data`` (N, 6)."""
    cdef Py_ssize_t i, n = data.shape[0]
    if data.shape[1] != 6:
        raise ValueError("data must be (N, 6)")
    points_arr = np.empty((n, 3), dtype=np.float64)
    normals_arr = np.empty((n, 3), dtype=np.float64)
    cdef double[:, ::1] points = points_arr
    cdef double[:, ::1] normals = normals_arr
    with nogil:
        for i in range(n):
            points[i, 0] = data[i, 0]
            points[i, 1] = data[i, 1]
            points[i, 2] = data[i, 2]
            normals[i, 0] = data[i, 3]
            normals[i, 1] = data[i, 4]
            normals[i, 2] = data[i, 5]
    return points_arr, normals_arr


def check_batch(Py_ssize_t n_rows, const int64_t[::1] offsets, const uint64_t[::1] seeds,
                 double[:, ::1] out, int8_t[::1] status, Py_ssize_t n_out, name):
    """Shapes a batch kernel relies on: objects are row ranges of the points
    (non-decreasing offsets from 0 to at most ``n_rows``), one seed, one
    output row of ``n_out`` values and one status per object."""
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1
    if n_objects < 0 or offsets[0] < 0 or offsets[n_objects] > n_rows or np.any(np.diff(np.asarray(offsets)) < 0):
        raise ValueError(f"{name}: offsets must be non-decreasing within the rows of points")
    if (seeds.shape[0] < n_objects or status.shape[0] < n_objects or out.shape[0] < n_objects
            or out.shape[1] != n_out):
        raise ValueError(f"{name}: seeds, status and out must have one entry (row) per object")
