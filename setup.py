"""Build the Cython extensions of eppf, with OpenMP when the compiler has it.

All metadata lives in ``pyproject.toml``; this file only declares the compiled
modules and probes for OpenMP, falling back to a serial build (``prange`` runs
as a plain loop) when ``-fopenmp`` does not compile.

The kernels are translated and compiled in parallel, one job per core
(``EPPF_BUILD_JOBS=N`` for N jobs), and only when their sources changed: the C
files and compiled modules stay in the source tree and ``build/`` between
installs, ``pip install -e`` included (see ``BuildExt`` and ``_translated``).
``pip install -v`` shows one line per kernel as it compiles.

Every kernel is named after its caller and sits beside it: ``eppf/<pkg>/_x_fast.pyx``
builds the extension ``eppf.<pkg>._x_fast`` used by ``eppf/<pkg>/_x.py``. Each
extension sees only its own folder's C headers (and depends on the headers it
includes, so editing one rebuilds just the kernels that use it) plus the shared
``eppf/utils/_common.pxd``.

Debug build
-----------
``EPPF_DEBUG=1`` builds the kernels for hunting memory errors: Cython's
``boundscheck`` and ``wraparound`` on, and (GCC or Clang) ``-O1 -g
-fsanitize=address,undefined,float-cast-overflow -fno-omit-frame-pointer``
at compile and link time. Its C files go to ``build/debug`` so the normal
build's are left alone; pass ``--force`` when switching between the two
builds, since the in-place modules have the same names::

    EPPF_DEBUG=1 python setup.py build_ext --inplace --force -j 1

The Python interpreter is not instrumented, so AddressSanitizer's runtime
must be loaded first, and its leak checker (which would report the
interpreter's own allocations) turned off; UBSAN_OPTIONS makes undefined
behaviour (an out-of-range float-to-int conversion, say) abort like a
memory error instead of printing and going on::

    LD_PRELOAD=$(gcc -print-file-name=libasan.so) \\
        ASAN_OPTIONS=detect_leaks=0:hard_rss_limit_mb=4096 \\
        UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \\
        python scripts/fuzz_clouds.py --short

A memory error aborts the forked child and is counted as a FAIL, with the
sanitizer's report on stderr (the fuzz script leaves memory limits to
``hard_rss_limit_mb`` there: ASan's shadow memory needs more address space
than its usual RLIMIT_AS). Rebuild normally afterwards::

    python setup.py build_ext --inplace --force -j 1
"""
import glob
import multiprocessing
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np
from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
try:
    from setuptools.modified import newer_group
except ImportError:  # setuptools < 69
    from setuptools.dep_util import newer_group
import Cython
from Cython.Build import cythonize


def _jobs():
    """Parallel compile jobs: ``EPPF_BUILD_JOBS`` if set, else every core this process may use."""
    value = os.environ.get("EPPF_BUILD_JOBS", "").strip()
    if value:
        try:
            jobs = int(value)
        except ValueError:
            jobs = 0
        if jobs < 1:
            sys.exit(f"eppf: EPPF_BUILD_JOBS must be a positive integer, got {value!r}")
        return jobs
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


class BuildExt(build_ext):
    """``build_ext`` that compiles the kernels in parallel and, under ``pip install -e``,
    keeps them between installs.

    Without ``-j`` it runs one compile job per core (``EPPF_BUILD_JOBS`` overrides),
    largest kernel first so that no core waits on a big file started last. An editable
    install (PEP 660) builds in throw-away temporary folders, so every ``pip install -e``
    would recompile every kernel; here the build folders stay in ``build/``, where the
    next install finds each module newer than its sources and copies it instead. Each
    kernel prints one line as it starts and one when it is done (``pip install -v``
    shows them).
    """

    def finalize_options(self):
        super().finalize_options()
        if self.parallel is None:
            self.parallel = _jobs()
        if getattr(self, "editable_mode", False):
            # the folders of a plain build (``build/lib.<platform>-<python>``), shared
            # with ``python setup.py build_ext --inplace`` and ``pip install .``
            plain = type(self.distribution.get_command_obj("build"))(self.distribution)
            plain.ensure_finalized()
            self.build_lib, self.build_temp = plain.build_platlib, plain.build_temp

    def build_extensions(self):
        self.extensions.sort(key=lambda ext: -sum(os.path.getsize(s) for s in ext.sources))
        self._done = 0
        self._lock = threading.Lock()
        super().build_extensions()

    def build_extension(self, ext):
        target = self.get_ext_fullpath(ext.name)
        source = ext.sources[0]
        if not (self.force or newer_group(ext.sources + ext.depends, target, "newer")):
            self._progress(f"{source} is up to date, not compiled")
            return
        print(f"eppf: compiling {source} ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        super().build_extension(ext)
        self._progress(f"{source} compiled in {time.perf_counter() - start:.0f} s")

    def _progress(self, message):
        with self._lock:
            self._done += 1
            print(f"eppf: [{self._done}/{len(self.extensions)}] {message}", file=sys.stderr, flush=True)


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
debug = os.environ.get("EPPF_DEBUG", "") not in ("", "0")
link_args = []
if debug and sys.platform != "win32":
    sanitize = ["-fsanitize=address,undefined,float-cast-overflow", "-fno-omit-frame-pointer"]
    base_args = ["-O1", "-g", "-ffp-contract=off", "-fno-math-errno", *sanitize]
    link_args = sanitize


def _included_headers(pyx):
    """The C headers of the pyx's own folder that it names in ``cdef extern from``, and
    those they name in turn in ``#include "..."`` (a header split into parts)."""
    folder = os.path.dirname(pyx)
    headers = sorted(glob.glob(os.path.join(folder, "*.h")))
    found, texts = [], [pyx]
    while texts:
        with open(texts.pop()) as fh:
            text = fh.read()
        for h in headers:
            if h not in found and '"%s"' % os.path.basename(h) in text:
                found.append(h)
                texts.append(h)
    return sorted(found)


def _extension(pyx):
    name = os.path.splitext(pyx)[0].replace(os.sep, ".")
    with open(pyx) as fh:
        uses_numpy = "cimport numpy" in fh.read()
    return Extension(
        name,
        [pyx],
        include_dirs=([np.get_include()] if uses_numpy else []) + [os.path.dirname(pyx)],
        depends=_included_headers(pyx) + [os.path.join("eppf", "utils", "_common.pxd"), os.path.join("eppf", "utils", "_cpu.h")],
        extra_compile_args=base_args + omp_compile,
        extra_link_args=omp_link + link_args,
        define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
    )


def _translated(extensions, stamp):
    """Split ``extensions`` into those whose C file is current and those Cython must translate.

    cythonize's own test compares the C file with every file the .pyx depends on,
    Cython's and NumPy's .pxd files included; pip builds each install in a new
    environment where those are freshly written, so it would translate every kernel
    again, and build_ext would then compile every one. What those files say is fixed by
    the versions of Cython and NumPy, so a C file is current here when Cython's and
    NumPy's versions are those of the last translation (``stamp``), the file says it was
    written by this Cython, and it is newer than its .pyx and every .pxd and .pxi of eppf.
    A current extension is built from its C file as it stands.
    """
    own = glob.glob(os.path.join("eppf", "**", "*.pxd"), recursive=True)
    own += glob.glob(os.path.join("eppf", "**", "*.pxi"), recursive=True)
    try:
        with open(stamp) as fh:
            same_tools = fh.read() == _tools()
    except OSError:
        same_tools = False
    current, stale = [], []
    for ext in extensions:
        pyx = ext.sources[0]
        c_file = os.path.splitext(pyx)[0] + ".c"
        try:
            with open(c_file) as fh:
                ours = fh.readline().strip() == f"/* Generated by Cython {Cython.__version__} */"
            newest = max(os.path.getmtime(f) for f in [pyx, *own])
            fresh = same_tools and ours and os.path.getmtime(c_file) > newest
        except OSError:
            fresh = False
        if fresh:
            ext.sources = [c_file]
        (current if fresh else stale).append(ext)
    return current, stale


def _tools():
    return f"Cython {Cython.__version__}, NumPy {np.__version__}\n"


extensions = [_extension(p) for p in sorted(glob.glob(os.path.join("eppf", "**", "_*.pyx"), recursive=True))]
directives = {
    "language_level": "3",
    "boundscheck": debug,
    "wraparound": debug,
    "cdivision": True,
    "initializedcheck": False,
}
if debug:
    # its C files go to build/debug, translated afresh every time
    extensions = cythonize(extensions, compiler_directives=directives, build_dir=os.path.join("build", "debug"), force=True)
else:
    stamp = os.path.join("build", "cython-tools.txt")
    current, stale = _translated(extensions, stamp)
    # Cython translates in parallel where its worker processes are forked (spawned
    # ones would run this script again)
    fork = multiprocessing.get_start_method(allow_none=False) == "fork"
    extensions = current + cythonize(stale, compiler_directives=directives, nthreads=_jobs() if fork else 0)
    if stale:
        os.makedirs("build", exist_ok=True)
        with open(stamp, "w") as fh:
            fh.write(_tools())

setup(cmdclass={"build_ext": BuildExt}, ext_modules=extensions)
