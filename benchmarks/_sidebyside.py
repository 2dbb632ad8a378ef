"""Side-by-side timing for the benchmarks: the machine, eppf at several SIMD levels and builds, PCL and Open3D.

Every figure of a side-by-side table comes from one run on one machine:
eppf's kernels at each requested level (``EPPF_SIMD``) and, optionally, from
a second checkout (``--compare-build``) run in worker processes
(``_worker.py``), PCL 1.13 in its harness (``_pcl.py``), Open3D in a worker of
its own; the passes of all of them alternate round by round, so a busy spell
of a shared machine hits every column, and each figure is the best round's
CPU time per object. :func:`run_callgrind` counts instructions instead
(valgrind's callgrind), which another process's load cannot change.
"""

import glob
import json
import os
import platform
import queue
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
WORKER = os.path.join(HERE, "_worker.py")
LEVELS = ("scalar", "avx2", "avx512")
REPLY_TIMEOUT = 1800  # seconds one request may take before the run stops (a pass, with its set-up)


# ------------------------------------------------------------------ the machine

def cpu_model(cpuinfo=None, system=None):
    """The CPU in words: model name, x86 family/model and its widest SIMD, e.g.
    ``"AMD EPYC (family 25, model 17; AVX-512)"``.

    Read from ``/proc/cpuinfo`` on Linux (``cpuinfo``: its text, for tests),
    ``sysctl`` on macOS, ``platform.processor()`` elsewhere.
    """
    system = system or platform.system()
    if cpuinfo is None and system == "Linux" and os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            cpuinfo = f.read()
    if cpuinfo:
        fields = {}
        for line in cpuinfo.splitlines():
            key, sep, value = line.partition(":")
            if sep and key.strip() not in fields:
                fields[key.strip()] = value.strip()
        name = fields.get("model name") or fields.get("Model") or fields.get("Hardware") or platform.machine()
        if name == platform.machine() and "CPU part" in fields:  # ARM: implementer and part numbers
            name = f"ARM CPU (implementer {fields.get('CPU implementer', '?')}, part {fields['CPU part']})"
        notes = []
        if "cpu family" in fields and "model" in fields:
            notes.append(f"family {fields['cpu family']}, model {fields['model']}")
        flags = set((fields.get("flags") or fields.get("Features") or "").split())
        simd = ("AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "NEON/ASIMD" if "asimd" in flags
                else "SSE2" if "sse2" in flags else None)
        if simd:
            notes.append(simd)
        return f"{name} ({'; '.join(notes)})" if notes else name
    if system == "Darwin":
        try:
            out = subprocess.run(["sysctl", "-n", "machdep.cpu.brand_string"], capture_output=True, text=True,
                                 timeout=10).stdout.strip()
            if out:
                return out
        except (OSError, subprocess.SubprocessError):
            pass
    return platform.processor() or platform.machine() or "unknown CPU"


def load_average():
    """The 1-minute load average, or NaN where the OS has none."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def describe_levels(levels):
    """``eppf.simd_levels()``'s kernels in one phrase: ``"eppf avx2, esf avx2, normals avx2"``."""
    return ", ".join(f"{k} {v}" for k, v in sorted(levels.items()) if k not in ("machine", "EPPF_SIMD"))


def parse_levels(text):
    """``"scalar,avx2,avx512"`` (or ``"all"``, ``"native"``) as a tuple of ``EPPF_SIMD`` values; None is the default.

    ``"native"`` (and None) is the default level of this CPU, run without
    ``EPPF_SIMD``; ``"all"`` is every level, the highest first.
    """
    out = []
    for word in (text or "native").replace(" ", "").split(","):
        word = word.lower()
        if word == "all":
            out += ["native", "avx2", "scalar"]
        elif word in ("native", "default"):
            out.append("native")
        elif word in ("avx512", "avx-512"):
            out.append("avx512")
        elif word in LEVELS:
            out.append(word)
        elif word:
            raise ValueError(f"unknown SIMD level {word!r}: use scalar, avx2, avx512, native or all")
    seen = []
    for lv in out:
        if lv not in seen:
            seen.append(lv)
    return tuple(seen)


def level_env(level, older_cpu=True):
    """The environment variables a worker at ``level`` gets.

    ``EPPF_SIMD`` caps eppf's kernels; below ``avx512`` NumPy and OpenBLAS are
    also held to AVX2 (``scripts/older_cpu_env.py``'s settings, when
    ``older_cpu``), so the whole eppf process runs as on an AVX2-only CPU.
    ``"native"`` sets nothing. PCL and Open3D always run natively.
    """
    if level == "native":
        return {}
    if level == "avx512" or not older_cpu:
        return {"EPPF_SIMD": level}
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    try:
        from older_cpu_env import settings
    except ImportError:
        return {"EPPF_SIMD": level}
    finally:
        sys.path.pop(0)
    return dict(settings(level))


# ------------------------------------------------------------------ workers

class WorkerError(RuntimeError):
    """A worker's request failed, timed out, or the worker died."""


class Worker:
    """An eppf (or Open3D) timing process: ``EPPF_SIMD`` at ``level``, eppf from ``build`` (a checkout) or ours.

    Its replies are read by a thread, so a request that hangs ends after
    ``timeout`` seconds with :class:`WorkerError` instead of stopping the run.
    """

    def __init__(self, level="native", build=None, pin=False, timeout=REPLY_TIMEOUT, older_cpu=True):
        env = dict(os.environ)
        env.update(level_env(level, older_cpu))
        if level == "native":
            env.pop("EPPF_SIMD", None)
        env["OMP_NUM_THREADS"] = "1"
        env["OPENBLAS_NUM_THREADS"] = "1"
        if build is not None:
            env["PYTHONPATH"] = os.path.abspath(build) + os.pathsep + env.get("PYTHONPATH", "")
        self.level, self.build, self.timeout = level, build, timeout
        cmd = [sys.executable, WORKER] + (["--pin"] if pin else [])
        # Start outside the repository so that a --compare-build's eppf is not shadowed by the current directory's.
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
                                     cwd=tempfile.gettempdir(), bufsize=1)
        self.replies = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.replies.put(line)
        self.replies.put(None)

    def ask(self, **req):
        try:
            self.proc.stdin.write(json.dumps(req) + "\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            raise WorkerError(f"the worker has stopped ({exc})") from None
        try:
            line = self.replies.get(timeout=self.timeout)
        except queue.Empty:
            self.close()
            raise WorkerError(f"no reply within {self.timeout} s") from None
        if line is None:
            raise WorkerError(f"the worker has stopped (exit status {self.proc.wait()})")
        out = json.loads(line)
        if "error" in out:
            raise WorkerError(out["error"])
        return out

    def timer(self, task, path):
        """A job for :func:`run_rounds`: one pass of ``task`` over the objects file ``path``, CPU s per object."""
        def call():
            r = self.ask(op="time", task=task, file=path)
            return r["cpu_s"] / max(1, r["n"])
        return call

    def close(self):
        if self.proc.poll() is None:
            try:
                self.proc.stdin.write(json.dumps({"op": "quit"}) + "\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()


def check_build(build):
    """The absolute path of a checkout with built extensions, or a ValueError saying what is wrong with it."""
    path = os.path.abspath(build)
    if not os.path.isfile(os.path.join(path, "eppf", "__init__.py")):
        raise ValueError(f"--compare-build {build!r}: no eppf package there (give the root of a checkout)")
    if not glob.glob(os.path.join(path, "eppf", "**", "*.so"), recursive=True) + \
            glob.glob(os.path.join(path, "eppf", "**", "*.pyd"), recursive=True):
        raise ValueError(f"--compare-build {build!r}: no built extensions; run "
                         "'python setup.py build_ext --inplace' in it first")
    return path


# ------------------------------------------------------------------ rounds

class Timings:
    """Best CPU seconds per object of each (column, task, objects file), over rounds."""

    def __init__(self):
        self.best, self.errors = {}, {}

    def add(self, key, seconds_per_object):
        self.best[key] = min(self.best.get(key, float("inf")), seconds_per_object)

    def ms(self, key):
        """Milliseconds per object, or None when the figure is missing."""
        v = self.best.get(key)
        return None if v is None or v == float("inf") else 1e3 * v

    def fail(self, key, message):
        self.errors.setdefault(key, message)


def run_rounds(jobs, rounds, log=None):
    """Run every job once a round, ``rounds`` times, printing progress; return :class:`Timings`.

    ``jobs``: a list of (key, label, call), ``call()`` returning CPU seconds
    per object. A job that raises is reported once and not run again.
    """
    log = sys.stdout if log is None else log
    out = Timings()
    for r in range(rounds):
        t0 = time.perf_counter()
        print(f"round {r + 1}/{rounds} (load average {load_average():.1f}):", end="", file=log, flush=True)
        for key, label, call in jobs:
            if key in out.errors:
                continue
            print(f" {label}", end="", file=log, flush=True)
            try:
                out.add(key, call())
            except (WorkerError, RuntimeError, ValueError, OSError, subprocess.SubprocessError) as exc:
                out.fail(key, str(exc))
                print(f" [failed: {exc}]", end="", file=log, flush=True)
        print(f" ({time.perf_counter() - t0:.0f} s)", file=log, flush=True)
    return out


# ------------------------------------------------------------------ callgrind

def callgrind_command(out_file, argv, toggle="__pyx_pw_4eppf_*"):
    """valgrind's command line counting the instructions of eppf's compiled code in each marked stretch.

    Collection runs only inside eppf's compiled entry points (``toggle``:
    Cython's Python-facing wrappers, so NumPy and the interpreter between
    them are left out); counts are zeroed at the worker's start marker and
    written out (one part file each) at its end marker.
    """
    from _worker import MARK_END, MARK_START

    return ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}", "--collect-atstart=no",
            f"--toggle-collect={toggle}", f"--zero-before={MARK_START}", f"--dump-before={MARK_END}"] + list(argv)


def callgrind_parts(out_file):
    """The instruction totals of the part files ``out_file.1``, ``.2``, ... written at the end markers, in order."""
    parts = []
    for path in sorted(glob.glob(out_file + ".*"), key=lambda p: int(p.rsplit(".", 1)[1])
                       if p.rsplit(".", 1)[1].isdigit() else -1):
        if not path.rsplit(".", 1)[1].isdigit():
            continue
        with open(path) as f:
            text = f.read()
        if "--dump-before" not in text:
            continue
        m = re.search(r"^(?:summary|totals):\s*(\d+)", text, re.M)
        parts.append(int(m.group(1)) if m else 0)
    return parts


def split_parts(parts, n_tasks):
    """Per-task instruction counts from the part files: the end marker may match several functions (the
    interpreter's wrapper, libc's), each writing a part, so the parts come in equal groups, one per task."""
    if n_tasks == 0 or not parts or len(parts) % n_tasks:
        raise ValueError(f"callgrind wrote {len(parts)} marked parts for {n_tasks} tasks")
    m = len(parts) // n_tasks
    return [sum(parts[k * m:(k + 1) * m]) for k in range(n_tasks)]


def run_callgrind(tasks, objects_file, level="native", build=None, timeout=3600):
    """Instructions per object of each task in eppf's compiled code, under callgrind: {task: count}.

    valgrind models a CPU without AVX-512, so the kernels run at most their
    AVX2 code there; the levels they ran at are returned too: (counts, levels).
    """
    if shutil.which("valgrind") is None:
        raise RuntimeError("valgrind is not on PATH")
    env = dict(os.environ)
    env.update(level_env(level))
    if level == "native":
        env.pop("EPPF_SIMD", None)
    env["OMP_NUM_THREADS"] = "1"
    if build is not None:
        env["PYTHONPATH"] = os.path.abspath(build) + os.pathsep + env.get("PYTHONPATH", "")
    with tempfile.TemporaryDirectory() as tmp:
        out_file = os.path.join(tmp, "callgrind.out")
        cmd = callgrind_command(out_file, [sys.executable, WORKER, "--once", ",".join(tasks), objects_file])
        done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout, cwd=tmp)
        if done.returncode != 0:
            raise RuntimeError(f"callgrind run failed: {done.stderr.strip()[-400:]}")
        order = [line.split() for line in done.stdout.splitlines() if line.startswith("once ")]
        levels = next((json.loads(line[7:]) for line in done.stdout.splitlines() if line.startswith("levels ")), {})
        counts = split_parts(callgrind_parts(out_file), len(order))
    return {name: c / int(n) for (_, name, n), c in zip(order, counts)}, levels
