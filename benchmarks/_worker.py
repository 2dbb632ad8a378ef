"""One process that times eppf (or Open3D) for a side-by-side benchmark run.

The benchmarks start one worker per SIMD level (``EPPF_SIMD`` set in its
environment before eppf is imported: the kernels read it once) and per build
(``PYTHONPATH`` naming another checkout), and ask each in turn for one timed
pass, so that every level and build sees the same spells of load on a shared
machine. Requests and replies are JSON lines on stdin and stdout:

- ``{"op": "info"}`` -> ``{"levels": eppf.simd_levels(), "eppf": eppf.__file__, ...}``
- ``{"op": "time", "task": T, "file": F}`` -> ``{"cpu_s": seconds, "n": objects}``:
  the process CPU time of one pass of task T over the objects of file F
  (written by ``_data.write_objects``), after a one-time set-up and warm-up;
- ``{"op": "rows", "task": T, "file": F, "out": P}`` -> ``{"ok": true}``: the
  task's output saved to P (``.npy``; for normals, the stacked normals);
- ``{"op": "quit"}``.

A failing request answers ``{"error": "..."}`` and the worker carries on.

``python _worker.py --once TASKS FILE`` runs each task of the comma-separated
list once after its set-up and warm-up, bracketed by the markers the callgrind
mode of ``bench_baselines.py`` counts between (:func:`mark_start`,
:func:`mark_end`), and prints the tasks' order.
"""

import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _data import read_objects  # noqa: E402

K_NORMALS = 20  # neighbors of the timed normals (as bench_normals.py and the figures)


def _xyz(clouds):
    return [np.ascontiguousarray(c[:, :3]) for c in clouds]


def _transform(make, columns=6):
    """A task timing ``make().fit(clouds).transform(clouds)``'s transform, one thread."""
    def setup(clouds):
        data = clouds if columns == 6 else _xyz(clouds)
        est = make().fit(data)
        return (lambda: est.transform(data)), (lambda: est.transform(data))
    return setup


def _eppf():
    from eppf import EPPFTransformer
    return EPPFTransformer(scaling="object", random_state=0, n_jobs=1)


def _gasd():
    from eppf import GASDTransformer
    return GASDTransformer(n_jobs=1)


def _vfh():
    from eppf import VFHTransformer
    return VFHTransformer(n_jobs=1)


def _esf():
    from eppf import ESFTransformer
    return ESFTransformer(random_state=0, n_jobs=1)


def _cvfh():
    # The PCL reference runs' settings: EPS angle 5 degrees, curvature threshold 1.0, bins not normalized.
    from eppf.descriptors import CVFHTransformer
    return CVFHTransformer(aggregate="first", eps_angle=float(np.deg2rad(5.0)), curvature_threshold=1.0,
                           normalize_bins=False, normalize=False, n_jobs=1)


def _cvfh_default():
    # PCL's CVFHEstimation defaults (EPS angle 0.125, curvature threshold 0.03, bins not normalized).
    from eppf.descriptors import CVFHTransformer
    return CVFHTransformer(aggregate="first", normalize=False, n_jobs=1)


def _grsd():
    from eppf.descriptors import GRSDTransformer
    return GRSDTransformer(normalize=False, n_jobs=1)


def _eppf_kernel(clouds):
    """The EPPF counts kernel alone (no validation or weighting), through its private entry point.

    The paper's settings, as :func:`_eppf`. Raises when this build's kernel
    has another signature: the task is then reported as unavailable.
    """
    from eppf.descriptors import _eppf_fast as core
    from eppf.utils._validation import object_seeds

    est = _eppf().fit(clouds)
    stacked = np.ascontiguousarray(np.vstack(clouds))
    points, normals = stacked[:, :3], stacked[:, 3:6]
    offsets = np.cumsum([0] + [len(c) for c in clouds]).astype(np.int64)
    scales = np.array([1.0 / np.ptp(c[:, :3], axis=0).max() for c in clouds])
    args = (points, normals, offsets, scales, object_seeds(0, len(clouds)), est.n_pairs, tuple(est.n_bins),
            est.grid_size, float(np.sqrt(3.0)), 1)
    return (lambda: core.eppf_counts(*args)), (lambda: core.eppf_counts(*args)[0])


def _normals(clouds):
    from eppf import estimate_normals

    data = _xyz(clouds)
    run = lambda: [estimate_normals(c, K_NORMALS, n_jobs=1) for c in data]  # noqa: E731
    return run, (lambda: np.vstack(run()))


class _Open3D:
    """Open3D's ``estimate_normals`` (k nearest neighbors), its normals cleared before each call, untimed."""

    def __init__(self, clouds):
        import open3d as o3d

        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        self.o3d = o3d
        self.param = o3d.geometry.KDTreeSearchParamKNN(K_NORMALS)
        self.pcs = [o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c)) for c in _xyz(clouds)]

    def timed(self):
        total = 0.0
        for pc in self.pcs:
            pc.normals = self.o3d.utility.Vector3dVector()
            t = time.process_time()
            pc.estimate_normals(self.param)
            total += time.process_time() - t
        return total

    def rows(self):
        self.timed()
        return np.vstack([np.asarray(pc.normals) for pc in self.pcs])


def _open3d(clouds):
    o = _Open3D(clouds)
    return o.timed, o.rows


#: task -> set-up(clouds) returning (one pass, the pass's output). A pass that returns a float
#: has timed itself (Open3D: the clearing of old normals is left out).
TASKS = {
    "eppf": _transform(_eppf),
    "eppf_kernel": _eppf_kernel,
    "gasd": _transform(_gasd, columns=3),
    "vfh": _transform(_vfh),
    "esf": _transform(_esf, columns=3),
    "cvfh": _transform(_cvfh),
    "cvfh_default": _transform(_cvfh_default),
    "grsd": _transform(_grsd),
    "normals": _normals,
    "open3d_normals": _open3d,
}


class Worker:
    def __init__(self):
        self.files = {}
        self.ready = {}

    def clouds(self, path):
        if path not in self.files:
            self.files[path] = read_objects(path)
        return self.files[path]

    def task(self, name, path):
        if name not in TASKS:
            raise ValueError(f"unknown task {name!r}; known: {', '.join(TASKS)}")
        key = (name, path)
        if key not in self.ready:
            run, rows = TASKS[name](self.clouds(path))
            run()  # warm up: first-touch pages, lazy imports, thread pools
            self.ready[key] = (run, rows)
        return self.ready[key]

    def time(self, name, path):
        run, _ = self.task(name, path)
        c = time.process_time()
        out = run()
        spent = time.process_time() - c
        return {"cpu_s": out if isinstance(out, float) else spent, "n": len(self.clouds(path))}

    def handle(self, req):
        op = req.get("op")
        if op == "info":
            import eppf

            return {"levels": eppf.simd_levels(), "eppf": os.path.dirname(os.path.abspath(eppf.__file__)),
                    "version": getattr(eppf, "__version__", "?")}
        if op == "time":
            return self.time(req["task"], req["file"])
        if op == "rows":
            _, rows = self.task(req["task"], req["file"])
            np.save(req["out"], np.asarray(rows(), dtype=np.float64))
            return {"ok": True}
        raise ValueError(f"unknown request {op!r}")


def serve(stdin=sys.stdin):
    # Replies go to the original stdout; anything libraries print goes to stderr instead.
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    worker = Worker()
    for line in stdin:
        req = json.loads(line)
        if req.get("op") == "quit":
            break
        try:
            out = worker.handle(req)
        except Exception as exc:  # reported to the parent, which shows it as "n/a (...)"
            out = {"error": f"{type(exc).__name__}: {exc}"}
        reply.write(json.dumps(out) + "\n")


def mark_start():
    """The call the callgrind mode zeroes its counts at (``--zero-before``): one libc function nothing else calls."""
    os.sched_get_priority_max(os.SCHED_OTHER)


def mark_end():
    """The call the callgrind mode dumps its counts at (``--dump-before``)."""
    os.sched_get_priority_min(os.SCHED_OTHER)


#: Marker functions as callgrind matches them (glibc may name them with leading underscores).
MARK_START, MARK_END = "*sched_get_priority_max*", "*sched_get_priority_min*"


def once(tasks, path):
    """Each task once, between the markers; prints the kernels' levels (``levels {json}``)
    and ``once TASK N`` (N objects) per task, in order."""
    import eppf

    print("levels " + json.dumps(eppf.simd_levels()), flush=True)
    worker = Worker()
    for name in tasks:
        run, _ = worker.task(name, path)
        mark_start()
        run()
        mark_end()
        print(f"once {name} {len(worker.clouds(path))}", flush=True)


if __name__ == "__main__":
    if "--pin" in sys.argv and hasattr(os, "sched_setaffinity"):
        # Open3D starts threads of its own despite OMP_NUM_THREADS=1: pinned, it has one CPU.
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    if len(sys.argv) >= 4 and sys.argv[1] == "--once":
        once(sys.argv[2].split(","), sys.argv[3])
    else:
        serve()
