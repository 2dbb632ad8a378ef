# cython: language_level=3
"""Shared inline helpers for eppf's compiled kernels.

- An OpenMP shim: ``omp_get_max_threads`` works in serial builds too.
- ``splitmix64``: the small private random generator each object gets, seeded
  from one 64-bit seed per object so results do not depend on thread count.
- ``rand_below``: an unbiased-enough bounded draw (Lemire's multiply-shift on
  the high 32 bits), fine for clouds below 2**32 points.
- ``clamp_floor`` / ``clamp_floor64``: the one way a kernel turns a float into
  an index: ``floor(t)`` clipped to ``[0, n - 1]``, clamped in floating point
  before the conversion so that NaN (to 0), infinities and huge values give an
  index in range for every double.
"""
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
