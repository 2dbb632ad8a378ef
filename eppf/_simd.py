"""Which SIMD code each compiled kernel runs on this CPU (see ``EPPF_SIMD``)."""

import platform

from . import descriptors, preprocessing  # noqa: F401  (their kernels register their levels on import)
from .utils._simd import kernel_levels, simd_cap


def simd_levels():
    """The SIMD code each of eppf's compiled kernels runs, by kernel.

    The kernels choose the best code the CPU runs when they are imported, at
    most what the environment variable ``EPPF_SIMD`` allows: ``"scalar"``
    (the portable C code, which ARM64 and other non-x86 CPUs run), ``"avx2"``
    or ``"avx512"`` (the default, everything). Every level gives the same
    outputs bit for bit, so the variable lets one machine run the code of
    others (see the reproducibility page of the documentation).

    Returns
    -------
    levels : dict
        ``"machine"``: the processor architecture (``platform.machine()``);
        ``"EPPF_SIMD"``: the cap in force, or None; ``"eppf"``: the EPPF pair
        walk ("scalar", "avx2", "avx512-grouped" or "avx512-skipping");
        ``"normals"``: the neighbor scan of :func:`eppf.estimate_normals`
        ("scalar", "avx2" or "avx512"); ``"esf"``: the ESF triplet kernel
        ("scalar" or "avx2"). The other descriptors' kernels are portable C.

    See Also
    --------
    eppf.estimate_normals : Normals, computed by the neighbor-scan kernel.
    eppf.EPPFTransformer : The descriptor computed by the pair-walk kernel.

    Examples
    --------
    >>> import eppf
    >>> sorted(eppf.simd_levels())
    ['EPPF_SIMD', 'eppf', 'esf', 'machine', 'normals']
    """
    return {"machine": platform.machine(), "EPPF_SIMD": simd_cap(), **kernel_levels()}
