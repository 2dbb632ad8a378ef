"""Build the Cython extensions of eppf, with OpenMP when the compiler has it.

All metadata lives in ``pyproject.toml``; this file only declares the compiled
modules (every ``eppf/_*.pyx``) and probes for OpenMP, falling back to a serial
build (``prange`` runs as a plain loop) when ``-fopenmp`` does not compile.
"""
import glob
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
from setuptools import Extension, setup
from Cython.Build import cythonize


def _openmp_flags():
    """Return (compile_args, link_args) for OpenMP, or ([], []) if unusable."""
    if os.environ.get("EPPF_NO_OPENMP"):
        return [], []
    if sys.platform == "win32":
        return ["/openmp"], []
    cc = os.environ.get("CC", "cc")
    flags = ["-fopenmp"]
    src = "#include <omp.h>\nint main(void){return omp_get_max_threads() > 0 ? 0 : 1;}\n"
    tmp = tempfile.mkdtemp()
    try:
        c_file = os.path.join(tmp, "probe.c")
        with open(c_file, "w") as fh:
            fh.write(src)
        cmd = [cc, *flags, c_file, "-o", os.path.join(tmp, "probe")]
        ok = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0
    except OSError:
        ok = False
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if not ok:
        print("eppf: compiler has no OpenMP; building serial kernels", file=sys.stderr)
        return [], []
    return flags, flags


omp_compile, omp_link = _openmp_flags()
base_args = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off", "-fno-math-errno"]

extensions = [
    Extension(
        os.path.splitext(path)[0].replace(os.sep, "."),
        [path],
        include_dirs=[np.get_include(), "eppf"],
        # C headers and the shared .pxd: editing one rebuilds the extensions
        depends=sorted(glob.glob(os.path.join("eppf", "*.h"))) + [os.path.join("eppf", "_common.pxd")],
        extra_compile_args=base_args + omp_compile,
        extra_link_args=omp_link,
        define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
    )
    for path in sorted(glob.glob(os.path.join("eppf", "_*.pyx")))
    + sorted(glob.glob(os.path.join("eppf", "descriptors", "_*_fast.pyx")))
]

setup(
    ext_modules=cythonize(
        extensions,
        compiler_directives={
            "language_level": "3",
            "boundscheck": False,
            "wraparound": False,
            "cdivision": True,
            "initializedcheck": False,
        },
    )
)
