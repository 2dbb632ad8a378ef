# cython: language_level=3
"""Compiled kernels of eppf (EPPF kernel being written)."""
from ._common cimport omp_get_max_threads, EPPF_HAVE_OPENMP


def openmp_max_threads():
    """Return OpenMP's default thread count (1 in a serial build)."""
    return omp_get_max_threads()


def has_openmp():
    """Return True when the kernels were compiled with OpenMP."""
    return bool(EPPF_HAVE_OPENMP)
