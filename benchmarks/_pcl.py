"""PCL 1.13 beside eppf in the same run: the harness in ``benchmarks/pcl_harness``, built on demand.

:func:`harness` compiles ``pcl_harness/pcl_bench.cpp`` once with the system
C++ compiler and ``pkg-config``'s flags for PCL's ``pcl_features`` (Debian and
Ubuntu: ``apt install libpcl-dev pkg-config g++``) into a cache folder,
``build/pcl_bench-<hash of the source>`` in this checkout (``$EPPF_BENCH_CACHE``
names another folder), and returns the program's path. Where PCL, pkg-config
or a compiler is missing, or the build fails, it prints one line saying so and
returns None: the PCL columns are then left out, nothing else changes.

:func:`time_pcl` runs one task of the program on an objects file written by
:func:`_data.write_objects` and returns PCL's CPU milliseconds per object (one
thread; PCL's estimators are single-threaded unless their OMP variants are
used, which the harness does not).
"""

import hashlib
import os
import shutil
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.join(HERE, "pcl_harness", "pcl_bench.cpp")
PKG_MODULES = ("pcl_features", "pcl_search", "pcl_kdtree", "pcl_common")
#: Tasks the harness knows, with the width of one output row (normals: 3 per point).
TASKS = {"normals": None, "esf": 640, "gasd": 512, "vfh": 308, "cvfh": 308, "cvfh_default": 308, "ourcvfh": 308, "grsd": 21}
BUILD_TIMEOUT = 900  # seconds: PCL's headers are heavy, and the machine may be busy
RUN_TIMEOUT = 1800


def cache_dir():
    """The folder that holds built harnesses: ``$EPPF_BENCH_CACHE`` or ``build/`` of this checkout."""
    return os.environ.get("EPPF_BENCH_CACHE") or os.path.join(os.path.dirname(HERE), "build")


def source_hash(path=SOURCE):
    """First 12 hex digits of the SHA-256 of the harness source: a changed source builds anew."""
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:12]


def compile_command(compiler, flags, output, source=SOURCE):
    """The command line that builds the harness: ``compiler -O2 -std=c++17 source -o output flags``."""
    return [compiler, "-O2", "-std=c++17", source, "-o", output] + list(flags)


def _say(message, log):
    print(message, file=log, flush=True)


def find_tools(which=shutil.which):
    """(compiler, pkg-config) found on PATH, or a sentence saying what is missing."""
    compiler = os.environ.get("CXX") or next((c for c in ("c++", "g++", "clang++") if which(c)), None)
    if compiler is None or which(compiler) is None:
        return None, "no C++ compiler (c++, g++ or clang++; or $CXX) on PATH"
    pkg = which("pkg-config")
    if pkg is None:
        return None, "pkg-config is not on PATH"
    return (compiler, pkg), None


def harness(log=None, rebuild=False):
    """The path of the built harness, building it first if needed; None (with one printed line) if it cannot be.

    Parameters
    ----------
    log : file, default=None
        Where progress and the skip line go (None: ``sys.stdout``).
    rebuild : bool, default=False
        Build even if the cache already holds this source's program.
    """
    log = sys.stdout if log is None else log
    if not os.path.isfile(SOURCE):
        _say(f"PCL: skipped (the harness source {SOURCE} is missing)", log)
        return None
    folder = os.path.join(cache_dir(), f"pcl_bench-{source_hash()}")
    exe = os.path.join(folder, "pcl_bench")
    if os.path.isfile(exe) and os.access(exe, os.X_OK) and not rebuild:
        return exe
    tools, missing = find_tools()
    if tools is None:
        _say(f"PCL: skipped ({missing})", log)
        return None
    compiler, pkg = tools
    probe = subprocess.run([pkg, "--cflags", "--libs", *PKG_MODULES], capture_output=True, text=True)
    if probe.returncode != 0:
        _say("PCL: skipped (pkg-config finds no PCL: install libpcl-dev, or set PKG_CONFIG_PATH)", log)
        return None
    version = subprocess.run([pkg, "--modversion", "pcl_features"], capture_output=True, text=True).stdout.strip()
    os.makedirs(folder, exist_ok=True)
    tmp = exe + f".tmp{os.getpid()}"
    cmd = compile_command(compiler, probe.stdout.split(), tmp)
    _say(f"PCL {version}: building the benchmark harness once into {folder} (a minute or so) ...", log)
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT)
    except subprocess.TimeoutExpired:
        _say(f"PCL: skipped (building the harness took over {BUILD_TIMEOUT} s)", log)
        return None
    if done.returncode != 0:
        with open(os.path.join(folder, "build.log"), "w") as f:
            f.write(" ".join(cmd) + "\n" + done.stdout + done.stderr)
        first = next((line for line in done.stderr.splitlines() if "error" in line), done.stderr.strip()[:200])
        _say(f"PCL: skipped (the harness did not compile: {first}; full log in {folder}/build.log)", log)
        return None
    os.replace(tmp, exe)
    return exe


def parse_line(text, task):
    """PCL's ms per object from the harness's output (its ``pcl_bench TASK objects N ms_per_object T`` line)."""
    for line in text.splitlines():
        words = line.split()
        if len(words) >= 6 and words[0] == "pcl_bench" and words[1] == task and words[4] == "ms_per_object":
            return float(words[5])
    raise ValueError(f"the PCL harness printed no result line for {task!r}: {text.strip()[:200]!r}")


def time_pcl(exe, objects_file, task, repeats=1, k=20, rows=None):
    """PCL's CPU ms per object for ``task`` on the objects of ``objects_file`` (best of ``repeats`` passes).

    With ``rows`` (a path), the output rows are also written there; read them
    with :func:`read_rows`.
    """
    if task not in TASKS:
        raise ValueError(f"unknown PCL task {task!r}; known: {', '.join(TASKS)}")
    cmd = [exe, objects_file, task, "--repeats", str(repeats), "--k", str(k)]
    if rows is not None:
        cmd += ["--out", rows]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=RUN_TIMEOUT)
    if done.returncode != 0:
        raise RuntimeError(f"the PCL harness failed on {task}: {done.stderr.strip()[:300]}")
    return parse_line(done.stdout, task)


def read_rows(path, task, sizes):
    """The rows written by ``--out``: (n_objects, width) float32, or one (n_i, 3) array per object for normals."""
    flat = np.fromfile(path, dtype=np.float32)
    if TASKS[task] is None:
        ends = np.cumsum([0] + [3 * n for n in sizes])
        return [flat[a:b].reshape(-1, 3) for a, b in zip(ends[:-1], ends[1:])]
    return flat.reshape(len(sizes), TASKS[task])
