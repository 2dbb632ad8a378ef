"""Which arithmetic a network runs in: float32, bfloat16, or the one the hardware suits.

bfloat16 mixed precision (:func:`torch.autocast`) pays only where the
hardware multiplies bfloat16 natively: x86 CPUs with AVX512_BF16 (AMD Zen 4
and later, Intel Cooper Lake) or AMX-BF16 (Intel Sapphire Rapids and later),
ARM CPUs with the BF16 extension (Graviton 3, Neoverse V1/N2 and later), and
CUDA GPUs of compute capability 8.0 (Ampere) or later. Elsewhere PyTorch
emulates it with float32 instructions and conversions, and a training epoch
takes several times as long as in float32 (3.6 times for the 4D network on
an AVX2-only AMD EPYC). ``precision="auto"`` therefore resolves to bfloat16
only on such hardware and to float32 everywhere else, including wherever
the hardware cannot be identified.

The CPU's features come from :func:`torch.cpu.get_capabilities` where torch
has it (2.13 and later, on every operating system), otherwise from the
``flags`` (x86) or ``Features`` (ARM) lines of Linux's ``/proc/cpuinfo``.
"""

import warnings

__all__ = [
    "BFloat16EmulationWarning",
    "check_precision",
    "native_bfloat16",
    "resolve_precision",
]

_PRECISIONS = ("float32", "bfloat16")

#: Feature names (as ``/proc/cpuinfo`` and :func:`torch.cpu.get_capabilities` spell them) of
#: bfloat16 arithmetic in hardware: AVX512_BF16 and AMX-BF16 on x86, FEAT_BF16 on ARM.
NATIVE_BF16_FEATURES = frozenset({"avx512_bf16", "amx_bf16", "bf16"})

_CPUINFO = "/proc/cpuinfo"

# The emulation warning is given once per process.
_warned_emulation = False

#: What the warning says emulation costs: measured by training the 4D network in both precisions
#: (2 threads) on an AVX2-only AMD EPYC. A figure taken on the spot was tried and dropped: on a
#: loaded 2-core machine the same float32/bfloat16 ratio of a few training steps varied by 2x from
#: run to run, and small operations are not representative of an epoch.
EMULATION_COST = ("an epoch of the 4D network took 3.6 times as long as in float32 (3.6 s against 1.0 s) on an "
                  "AVX2-only AMD EPYC with 2 threads")


class BFloat16EmulationWarning(UserWarning):
    """Warns that bfloat16 was asked for on a CPU that only emulates it (slower than float32).

    Given once per process by :func:`resolve_precision`; silence it with
    ``warnings.filterwarnings("ignore", category=BFloat16EmulationWarning)``
    or avoid it with ``precision="auto"``.

    See Also
    --------
    native_bfloat16 : Whether a device computes bfloat16 natively.

    Examples
    --------
    >>> import warnings
    >>> from eppf.nn import BFloat16EmulationWarning, resolve_precision
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore", BFloat16EmulationWarning)
    ...     resolve_precision("bfloat16")
    'bfloat16'
    """


def check_precision(precision, *, owner=None, allow_auto=False):
    """Validate a network precision: ``"float32"``, ``"bfloat16"`` or (where allowed) ``"auto"``.

    Parameters
    ----------
    precision : str
        ``"float32"`` computes in single precision; ``"bfloat16"`` runs the
        forward pass under :func:`torch.autocast` with bfloat16 (mixed
        precision: parameters, gradients and logits stay float32);
        ``"auto"`` is resolved by :func:`resolve_precision` to one of them.
    owner : str, default=None
        Name used in error messages.
    allow_auto : bool, default=False
        Accept ``"auto"`` (estimators do; a network module needs a concrete
        precision).

    Returns
    -------
    precision : str
        ``precision`` itself, once checked.

    See Also
    --------
    resolve_precision : Turns ``"auto"`` into a concrete precision.

    Examples
    --------
    >>> from eppf.nn import check_precision
    >>> check_precision("bfloat16")
    'bfloat16'
    >>> check_precision("fp16", owner="MyNet")
    Traceback (most recent call last):
        ...
    ValueError: MyNet: precision must be 'float32' or 'bfloat16', got 'fp16'
    """
    allowed = ("auto",) + _PRECISIONS if allow_auto else _PRECISIONS
    if not isinstance(precision, str) or precision not in allowed:
        pre = f"{owner}: " if owner else ""
        names = " or ".join(", ".join(repr(p) for p in allowed).rsplit(", ", 1))
        raise ValueError(f"{pre}precision must be {names}, got {precision!r}")
    return precision


def _cpuinfo_features(text):
    """The lowercase feature words of every ``flags`` (x86) or ``Features`` (ARM) line of cpuinfo text."""
    words = set()
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip().lower() in ("flags", "features"):
            words.update(value.lower().split())
    return words


def _cpu_features():
    """This CPU's feature names, or None when neither torch nor ``/proc/cpuinfo`` tells them."""
    import torch

    get_capabilities = getattr(getattr(torch, "cpu", None), "get_capabilities", None)
    if get_capabilities is not None:
        try:
            caps = get_capabilities()
        except Exception:  # torch could not query the CPU; try the kernel's list
            caps = None
        if caps:
            return {name for name, value in caps.items() if value is True}
    try:
        with open(_CPUINFO, encoding="utf-8", errors="replace") as fh:
            words = _cpuinfo_features(fh.read())
    except OSError:
        return None
    return words or None


def native_bfloat16(device="cpu", *, cpuinfo=None):
    """Whether ``device`` computes bfloat16 in hardware rather than emulating it.

    Parameters
    ----------
    device : str or torch.device, default="cpu"
        ``"cpu"``: true for x86 CPUs with AVX512_BF16 or AMX-BF16 and ARM
        CPUs with BF16, unless ``ONEDNN_MAX_CPU_ISA`` holds oneDNN below
        them (:func:`onednn_isa_below_bf16`). ``"cuda"`` (any index): true for GPUs of compute
        capability 8.0 or later (``torch.cuda.is_bf16_supported`` without
        emulation). Any other device type: false.
    cpuinfo : str, default=None
        Text in the format of Linux's ``/proc/cpuinfo`` to decide from
        instead of this machine's CPU (for tests and for reasoning about
        other machines). None asks :func:`torch.cpu.get_capabilities`, or
        reads ``/proc/cpuinfo`` where torch has no such function.

    Returns
    -------
    native : bool
        False also where the features cannot be read.

    See Also
    --------
    resolve_precision : Chooses the precision ``"auto"`` stands for.

    Examples
    --------
    >>> from eppf.nn import native_bfloat16
    >>> native_bfloat16(cpuinfo="flags\\t\\t: fpu sse2 avx2 fma")  # AVX2 only
    False
    >>> native_bfloat16(cpuinfo="flags\\t\\t: avx2 avx512f avx512_bf16")  # AMD Zen 4
    True
    >>> native_bfloat16(cpuinfo="Features\\t: fp asimd sve bf16 i8mm")  # ARM Neoverse V1
    True
    """
    import torch

    device = torch.device(device)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            return False
        try:
            return bool(torch.cuda.is_bf16_supported(including_emulation=False))
        except TypeError:  # torch before 2.3 has no including_emulation (and does not emulate)
            return bool(torch.cuda.is_bf16_supported())
    if device.type != "cpu":
        return False
    if cpuinfo is None and onednn_isa_below_bf16():
        return False  # oneDNN, which computes torch's CPU convolutions, was told not to use it
    features = _cpuinfo_features(cpuinfo) if cpuinfo is not None else _cpu_features()
    return bool(features and NATIVE_BF16_FEATURES & set(features))


#: oneDNN's instruction-set caps (``ONEDNN_MAX_CPU_ISA``) under which it has no
#: bfloat16 dot products: a CPU with AVX512_BF16 then emulates bfloat16.
_ISA_WITHOUT_BF16 = frozenset({"SSE41", "AVX", "AVX2", "AVX2_VNNI", "AVX2_VNNI_2", "AVX512_CORE",
                               "AVX512_CORE_VNNI"})


def onednn_isa_below_bf16(environ=None):
    """Whether this process caps oneDNN below the instruction sets that compute bfloat16.

    ``ONEDNN_MAX_CPU_ISA`` (or its older name ``DNNL_MAX_CPU_ISA``) set to,
    e.g., ``AVX2`` makes a CPU with AVX512_BF16 run torch's convolutions as
    an AVX2-only CPU would, emulating bfloat16; ``precision="auto"`` then
    chooses float32, as it would on that CPU.

    Parameters
    ----------
    environ : mapping, default=None
        Environment to read (``os.environ`` when None).

    Returns
    -------
    below : bool
    """
    import os

    environ = os.environ if environ is None else environ
    isa = environ.get("ONEDNN_MAX_CPU_ISA", environ.get("DNNL_MAX_CPU_ISA", ""))
    return isa.strip().upper() in _ISA_WITHOUT_BF16


def resolve_precision(precision, device="cpu", *, owner=None):
    """The concrete precision to train in: ``"auto"`` resolved, emulated bfloat16 warned of.

    Parameters
    ----------
    precision : {"auto", "float32", "bfloat16"}
        ``"auto"`` becomes ``"bfloat16"`` where :func:`native_bfloat16` says
        the device computes it in hardware and ``"float32"`` elsewhere.
        ``"float32"`` and ``"bfloat16"`` are kept as they are.
    device : str or torch.device, default="cpu"
        The device the network will run on.
    owner : str, default=None
        Name used in error messages and in the warning.

    Returns
    -------
    precision : {"float32", "bfloat16"}
        The precision to build the network with.

    Warns
    -----
    BFloat16EmulationWarning
        Once per process, when ``"bfloat16"`` is asked for explicitly on a
        CPU that emulates it, naming the slowdown measured on such a CPU
        (an epoch 3.6 times as long as in float32 on an AVX2-only AMD EPYC).

    See Also
    --------
    native_bfloat16 : The hardware test behind ``"auto"``.
    check_precision : Validation without resolving.

    Examples
    --------
    >>> from eppf.nn import native_bfloat16, resolve_precision
    >>> resolve_precision("float32")
    'float32'
    >>> resolve_precision("auto") == ("bfloat16" if native_bfloat16() else "float32")
    True
    """
    global _warned_emulation

    import torch

    precision = check_precision(precision, owner=owner, allow_auto=True)
    if precision == "auto":
        return "bfloat16" if native_bfloat16(device) else "float32"
    if precision == "bfloat16" and torch.device(device).type == "cpu" and not _warned_emulation \
            and not native_bfloat16("cpu"):
        _warned_emulation = True
        pre = f"{owner}: " if owner else ""
        warnings.warn(
            f"{pre}precision='bfloat16' on a CPU without native bfloat16 arithmetic (no AVX512_BF16, AMX-BF16 "
            f"or ARM BF16): PyTorch emulates it, and training is several times slower than in float32 "
            f"({EMULATION_COST}). precision='auto' (the default) or 'float32' trains faster on this CPU.",
            BFloat16EmulationWarning,
            stacklevel=2,
        )
    return precision
