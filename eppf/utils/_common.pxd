# cython: language_level=3
"""Shared inline helpers for eppf's compiled kernels.

- An OpenMP shim: ``omp_get_max_threads`` works in serial builds too.
- ``splitmix64``: the small private random generator each object gets, seeded
  from one 64-bit seed per object so results do not depend on thread count.
- ``rand_below``: an unbiased-enough bounded draw (Lemire's multiply-shift on
  the high 32 bits), fine for clouds below 2**32 points.
- ``pow2_scale``: the exact power of two that brings a cloud's largest
  coordinate to [0.5, 1), for kernels that work on scaled coordinates.
- ``clamp_floor`` / ``clamp_floor64``: the one way a kernel turns a float into
  an index: ``floor(t)`` clipped to ``[0, n - 1]``, clamped in floating point
  before the conversion so that NaN (to 0), infinities and huge values give an
  index in range for every double.
"""
from libc.math cimport fabs, frexp, ldexp
from libc.stdint cimport int64_t, uint64_t, uint32_t

cdef extern from *:
    """
    #ifdef _OPENMP
    #include <omp.h>
    #define EPPF_HAVE_OPENMP 1
    #else
    static int omp_get_max_threads(void) { return 1; }
    #define EPPF_HAVE_OPENMP 0
    #endif
    """
    int omp_get_max_threads() nogil
    int EPPF_HAVE_OPENMP


cdef inline uint64_t splitmix64(uint64_t* state) noexcept nogil:
    cdef uint64_t z
    state[0] += <uint64_t>0x9E3779B97F4A7C15
    z = state[0]
    z = (z ^ (z >> 30)) * <uint64_t>0xBF58476D1CE4E5B9
    z = (z ^ (z >> 27)) * <uint64_t>0x94D049BB133111EB
    return z ^ (z >> 31)


cdef inline uint32_t rand_below(uint64_t* state, uint32_t n) noexcept nogil:
    """Uniform integer in [0, n) from the next draw's high 32 bits."""
    cdef uint64_t r = splitmix64(state) >> 32
    return <uint32_t>((r * <uint64_t>n) >> 32)


cdef inline int clamp_floor(double t, int n) noexcept nogil:
    """floor(t) clipped to [0, n - 1]; NaN gives 0 (every double gives an index in range)."""
    if not (t > 0.0):
        return 0
    if t >= n:
        return n - 1
    return <int>t


cdef inline int64_t clamp_floor64(double t, int64_t n) noexcept nogil:
    """:func:`clamp_floor` for 64-bit index ranges."""
    if not (t > 0.0):
        return 0
    if t >= <double>n:
        return n - 1
    return <int64_t>t


cdef inline int64_t counts_to_starts(int64_t* counts, int64_t n) noexcept nogil:
    """Turn ``counts[:n]`` into where each bucket starts (the exclusive prefix sums) in place, the
    first step of a counting sort; returns the total."""
    cdef int64_t i, c, total = 0
    for i in range(n):
        c = counts[i]
        counts[i] = total
        total += c
    return total


cdef inline double pow2_scale(const double* pts, Py_ssize_t n) noexcept nogil:
    """A power of two that brings the largest |coordinate| of ``n`` xyz rows to [0.5, 1): exact to apply.

    A kernel working on ``scale * p`` then neither overflows nor underflows
    (squares, sums) near 1e308 or in the subnormal range, and any other cloud
    gives bit for bit the result it gives unscaled. The exponent is bounded to
    [-1000, 1000]; an all-zero cloud gives 1.
    """
    cdef double m = 0.0
    cdef Py_ssize_t i
    cdef int e
    for i in range(3 * n):
        if fabs(pts[i]) > m:
            m = fabs(pts[i])
    if not (m > 0.0):
        return 1.0
    frexp(m, &e)
    if e < -1000:
        e = -1000
    elif e > 1000:
        e = 1000
    return ldexp(1.0, -e)
