# cython: language_level=3
"""Compiled per-object statistics and stretches of packed point clouds, the bits NumPy's own code gives.

:func:`cloud_means` is each object's centroid as ``cloud[:, :3].mean(axis=0)``
computes it (NumPy adds the rows one after another from 0.0 along that
axis, then divides by the count), without NumPy's slow strided reduction
over three columns. :func:`extreme_values` is the ``m`` smallest and ``m``
largest values of each row, exact copies of the input (order statistics,
e.g. for quantiles near 0 and 1, without sorting or partitioning the row).
:func:`stretch_about` stretches each object about its own fixed point in one
pass, with NumPy's operations in NumPy's order.
The preprocessing transformers and the descriptors call them
(``eppf.preprocessing.RandomScaling``, ``eppf.descriptors.ProportionTransformer``);
they know nothing of either.
"""
import numpy as np

from cython.parallel cimport prange
from libc.stdint cimport int64_t


def cloud_means(const double[:, ::1] block, const int64_t[::1] offsets, int n_threads=1):
    """Centroids of packed clouds, bit for bit ``block[a:b, :3].mean(axis=0)``.

    Parameters
    ----------
    block : ndarray of shape (n_points, n_columns), float64, C-contiguous
        The clouds' rows one after another; columns 0-2 are averaged
        (``n_columns >= 3``, e.g. 6 with normals).
    offsets : ndarray of shape (n_objects + 1,), int64
        Object ``k`` is ``block[offsets[k]:offsets[k + 1]]``; every object
        has at least one row.
    n_threads : int, default=1
        Threads over the objects (the result does not depend on it).

    Returns
    -------
    means : ndarray of shape (n_objects, 3), float64
    """
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1, k
    cdef int64_t i, a, b
    cdef double s0, s1, s2
    if block.shape[1] < 3:
        raise ValueError(f"cloud_means: block needs at least 3 columns, got {block.shape[1]}")
    if n_objects < 0 or (n_objects > 0 and (offsets[0] < 0 or offsets[n_objects] > block.shape[0])):
        raise ValueError("cloud_means: offsets out of the block's rows")
    for k in range(n_objects):
        if offsets[k + 1] <= offsets[k]:
            raise ValueError(f"cloud_means: object {k} has no rows")
    means = np.empty((n_objects, 3), dtype=np.float64)
    cdef double[:, ::1] out = means
    for k in prange(n_objects, nogil=True, num_threads=max(1, n_threads), schedule="static"):
        a = offsets[k]
        b = offsets[k + 1]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for i in range(a, b):
            s0 = s0 + block[i, 0]
            s1 = s1 + block[i, 1]
            s2 = s2 + block[i, 2]
        out[k, 0] = s0 / <double>(b - a)
        out[k, 1] = s1 / <double>(b - a)
        out[k, 2] = s2 / <double>(b - a)
    return means


cdef void _keep_extremes(const double* x, Py_ssize_t n, Py_ssize_t m, double* low, double* high) noexcept nogil:
    """The ``m`` smallest values of ``x`` ascending into ``low``, the ``m`` largest descending into ``high``.

    One pass: a value enters a list only when it beats the list's last entry
    (insertion keeps the list sorted), so a row costs about ``n``
    comparisons per list unless it is nearly sorted the wrong way.
    """
    cdef Py_ssize_t i, j
    cdef double v
    for i in range(m):  # the first m values, insertion-sorted
        v = x[i]
        j = i
        while j > 0 and low[j - 1] > v:
            low[j] = low[j - 1]
            j -= 1
        low[j] = v
        j = i
        while j > 0 and high[j - 1] < v:
            high[j] = high[j - 1]
            j -= 1
        high[j] = v
    for i in range(m, n):
        v = x[i]
        if v < low[m - 1]:
            j = m - 1
            while j > 0 and low[j - 1] > v:
                low[j] = low[j - 1]
                j -= 1
            low[j] = v
        if v > high[m - 1]:  # (both, when 2 m > i: the lists overlap)
            j = m - 1
            while j > 0 and high[j - 1] < v:
                high[j] = high[j - 1]
                j -= 1
            high[j] = v


def extreme_values(const double[:, ::1] rows, Py_ssize_t m, int n_threads=1):
    """The ``m`` smallest and the ``m`` largest values of every row.

    ``low[r, i]`` is the value at position ``i`` of row ``r`` sorted
    ascending and ``high[r, i]`` the one at position ``n - 1 - i``: what
    ``np.sort(rows, axis=1)`` holds there, for rows of finite values (NaN is
    not ordered). Meant for ``m`` much smaller than the row length.

    Parameters
    ----------
    rows : ndarray of shape (n_rows, n), float64, C-contiguous
        Finite values.
    m : int
        Values kept at each end, ``1 <= m <= n``.
    n_threads : int, default=1
        Threads over the rows (the result does not depend on it).

    Returns
    -------
    low : ndarray of shape (n_rows, m), float64
        Smallest values, ascending.
    high : ndarray of shape (n_rows, m), float64
        Largest values, descending.
    """
    cdef Py_ssize_t n_rows = rows.shape[0], n = rows.shape[1], r
    if m < 1 or m > n:
        raise ValueError(f"extreme_values: m must be in [1, {n}] for rows of {n} values, got {m}")
    low_arr = np.empty((n_rows, m), dtype=np.float64)
    high_arr = np.empty((n_rows, m), dtype=np.float64)
    cdef double[:, ::1] low = low_arr
    cdef double[:, ::1] high = high_arr
    if n_rows == 0:
        return low_arr, high_arr
    for r in prange(n_rows, nogil=True, num_threads=max(1, n_threads), schedule="static"):
        _keep_extremes(&rows[r, 0], n, m, &low[r, 0], &high[r, 0])
    return low_arr, high_arr


def stretch_about(const double[:, ::1] block, const int64_t[::1] offsets, const double[:, ::1] origins,
                  const double[:, ::1] factors, double[:, ::1] out, int n_threads=1):
    """``out[i, :3] = (block[i, :3] - origins[k]) * factors[k] + origins[k]`` for every row ``i`` of object ``k``.

    The arithmetic NumPy does for ``(xyz - origin) * factors + origin``, one
    operation at a time in that order (the build never fuses a multiply and
    an add), so the same bits, in one pass instead of three temporaries.
    Columns after the third are not touched.

    Parameters
    ----------
    block : ndarray of shape (n_points, n_columns), float64, C-contiguous
        Packed clouds, ``n_columns >= 3``.
    offsets : ndarray of shape (n_objects + 1,), int64
        Object ``k`` is ``block[offsets[k]:offsets[k + 1]]``.
    origins, factors : ndarray of shape (n_objects, 3), float64
        Each object's fixed point and factors.
    out : ndarray of the shape of ``block``, float64, C-contiguous
        Receives the stretched coordinates.
    n_threads : int, default=1
        Threads over the objects (the result does not depend on it).
    """
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1, k
    cdef int64_t i
    cdef int c
    if block.shape[1] < 3 or out.shape[0] != block.shape[0] or out.shape[1] != block.shape[1]:
        raise ValueError("stretch_about: out must have block's shape, with at least 3 columns")
    if origins.shape[0] != n_objects or factors.shape[0] != n_objects or origins.shape[1] != 3 \
            or factors.shape[1] != 3:
        raise ValueError("stretch_about: origins and factors need one row of 3 per object")
    if n_objects > 0 and (offsets[0] < 0 or offsets[n_objects] > block.shape[0]):
        raise ValueError("stretch_about: offsets out of the block's rows")
    for k in range(n_objects):
        if offsets[k + 1] < offsets[k]:
            raise ValueError("stretch_about: offsets must not decrease")
    for k in prange(n_objects, nogil=True, num_threads=max(1, n_threads), schedule="static"):
        for i in range(offsets[k], offsets[k + 1]):
            for c in range(3):
                out[i, c] = (block[i, c] - origins[k, c]) * factors[k, c] + origins[k, c]
