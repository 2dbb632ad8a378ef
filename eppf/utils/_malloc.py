"""Let the ``eppf`` command keep large freed blocks in its heap (glibc).

Training a network allocates and frees tensors of tens of megabytes every
step. glibc serves blocks above its mmap threshold (at most 32 MiB by its
dynamic rule) with fresh ``mmap`` pages, which the kernel zeroes again at
every step, and gives freed memory at the top of the heap back to the
kernel beyond its trim threshold. For the paper's 4D network in float32
that page traffic was about a sixth of a training step's CPU time. The
``eppf`` command, which owns its process, raises both thresholds at start;
a Python program that trains through the estimators can do the same with
the environment variables ``MALLOC_MMAP_THRESHOLD_`` and
``MALLOC_TRIM_THRESHOLD_`` (see the documentation's performance page).
Results are the same either way: only where memory comes from changes.
"""

import ctypes
import os
import platform
import sys

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_freed_memory"]

#: Blocks below this many bytes come from the heap instead of fresh pages.
MMAP_THRESHOLD = 256 << 20
#: Freed memory at the top of the heap kept before any is given back.
TRIM_THRESHOLD = 512 << 20
# mallopt's parameter numbers (malloc.h); glibc caps the mmap threshold at
# 32 MiB in versions older than about 2.35, hence the second try.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_FALLBACK_MMAP_THRESHOLD = 32 << 20
_USER_SETTINGS = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_")


def keep_freed_memory(environ=None):
    """Raise glibc's mmap and trim thresholds of this process, if nobody chose them.

    Parameters
    ----------
    environ : mapping, default=None
        Environment to read (``os.environ`` when None). When it sets any of
        ``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``,
        ``MALLOC_TOP_PAD_`` or a ``glibc.malloc`` tunable in
        ``GLIBC_TUNABLES``, nothing is changed: the user's choice stands.

    Returns
    -------
    applied : bool
        True when both thresholds were set; False on other C libraries and
        platforms, or when the environment already chose.
    """
    environ = os.environ if environ is None else environ
    if any(name in environ for name in _USER_SETTINGS) or "glibc.malloc" in environ.get("GLIBC_TUNABLES", ""):
        return False
    if not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc":
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    if mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) != 1 and mallopt(_M_MMAP_THRESHOLD, _FALLBACK_MMAP_THRESHOLD) != 1:
        return False
    return mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
