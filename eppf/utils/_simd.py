"""The ``EPPF_SIMD`` switch: the most the compiled kernels may use of the CPU's SIMD.

Every kernel chooses its code by the CPU's features (``_cpu.h``), capped by the
environment variable ``EPPF_SIMD``, read once when a kernel module is imported:

- unset, empty or ``"avx512"``: the best code the CPU runs;
- ``"avx2"``: no AVX-512 (the code an AVX2-only CPU runs);
- ``"scalar"``: the portable C code (the code ARM64 and other CPUs run).

The outputs are the same bits at every level (the kernels' level tests check
this); the switch lets one machine run and test the others' code paths. This
module only validates the value, so that a typo is an error rather than a
silent "use everything".
"""

import os

#: The values ``EPPF_SIMD`` may take, from the least to the most the kernels may use.
SIMD_CAPS = ("scalar", "avx2", "avx512")


def simd_cap():
    """The value of ``EPPF_SIMD``, or None when it is unset or empty.

    Raises
    ------
    ValueError
        If ``EPPF_SIMD`` holds anything but "scalar", "avx2" or "avx512".
    """
    value = os.environ.get("EPPF_SIMD", "")
    if value == "":
        return None
    if value not in SIMD_CAPS:
        raise ValueError(
            f"the environment variable EPPF_SIMD must be one of {', '.join(repr(c) for c in SIMD_CAPS)} "
            f"or unset, got {value!r}"
        )
    return value


#: How to read each compiled kernel's SIMD level: kernel name -> function
#: returning the level's name. Each kernel's Python module registers itself.
_KERNELS = {}


def register_kernel(name, level):
    """Record ``level``, a function returning the name of the SIMD code kernel ``name`` runs."""
    _KERNELS[name] = level


def kernel_levels():
    """The SIMD code each registered kernel runs, as {kernel name: level name}."""
    return {name: level() for name, level in sorted(_KERNELS.items())}
