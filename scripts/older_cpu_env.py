"""Print the shell settings that make NumPy, OpenBLAS, torch and eppf's kernels run as on an AVX2-only CPU.

Used by ``.ci/run`` (``eval "$(python scripts/older_cpu_env.py)"``) to run the
equivalence and kernel tests once more with every library held to older
instruction sets, so that a change which only breaks other CPUs fails on any
machine. On x86-64:

- ``EPPF_SIMD=scalar``: eppf's kernels run their portable C code (the code of
  ARM64 and every CPU without AVX2);
- ``NPY_DISABLE_CPU_FEATURES``: NumPy's dispatched code above AVX2 (AVX-512 and
  newer: the names come from the running NumPy, which renamed them in 2.x);
- ``OPENBLAS_CORETYPE=Haswell``: OpenBLAS's AVX2 kernels, unless the variable is
  already set (some machines set it to avoid a faulty kernel: never override);
- ``ATEN_CPU_CAPABILITY=avx2``: torch's AVX2 kernels;
- ``ONEDNN_MAX_CPU_ISA=AVX2``: oneDNN's AVX2 kernels, which torch's CPU convolutions
  run (``ATEN_CPU_CAPABILITY`` does not reach them);
- ``MKL_ENABLE_INSTRUCTIONS=AVX2``: Intel MKL's AVX2 kernels, which torch's
  matrix products run on x86-64 (the dense layers and the frequency-domain
  convolutions), unless the variable is already set.

Elsewhere only ``EPPF_SIMD=scalar`` is printed. ``--eppf LEVEL`` prints another
``EPPF_SIMD`` level instead.
"""

import argparse
import os
import platform
import shlex


def numpy_above_avx2():
    """NumPy's dispatch targets above AVX2 that this CPU runs (AVX-512 and newer)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    newer = [name for name in __cpu_dispatch__ if name.startswith("AVX512") or name == "X86_V4"]
    return [name for name in newer if __cpu_features__.get(name)]


def settings(eppf_level="scalar"):
    """The environment variables to set, as an ordered list of (name, value)."""
    out = [("EPPF_SIMD", eppf_level)]
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return out
    disabled = numpy_above_avx2()
    if disabled:
        out.append(("NPY_DISABLE_CPU_FEATURES", " ".join(disabled)))
    if not os.environ.get("OPENBLAS_CORETYPE"):
        out.append(("OPENBLAS_CORETYPE", "Haswell"))
    out.append(("ATEN_CPU_CAPABILITY", "avx2"))
    out.append(("ONEDNN_MAX_CPU_ISA", "AVX2"))
    if not os.environ.get("MKL_ENABLE_INSTRUCTIONS"):
        out.append(("MKL_ENABLE_INSTRUCTIONS", "AVX2"))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eppf", default="scalar", choices=("scalar", "avx2", "avx512"),
                        help="the EPPF_SIMD level to print (default: scalar)")
    args = parser.parse_args()
    for name, value in settings(args.eppf):
        print(f"export {name}={shlex.quote(value)}")


if __name__ == "__main__":
    main()
