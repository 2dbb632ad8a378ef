"""The runtime paragraph: milliseconds per object of every descriptor and of normal estimation."""

import os
import time

import numpy as np

from ..registry import make_descriptor
from ._common import (
    ExperimentSettings,
    DESCRIPTORS,
    ExperimentError,
    Logger,
    check_positive_int,
    command_text,
    cpu_model,
    load_or_pass,
    markdown_table,
    n_samples_setting,
    params_text,
    resolve_scaling,
    write_report,
)

__all__ = ["run_runtime"]

NORMALS = "normals (PCA, 20 neighbours)"


def _threads(n_jobs):
    if n_jobs is None:
        return 1
    n_cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if n_jobs < 0:
        return max(1, n_cores + 1 + n_jobs)
    return n_jobs


def _time(func, n_objects, repeats):
    """Best (wall, process CPU) milliseconds per object over ``repeats`` calls."""
    best = (np.inf, np.inf)
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        func()
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        if wall < best[0]:
            best = (wall, cpu)
    return 1e3 * best[0] / n_objects, 1e3 * best[1] / n_objects


def run_runtime(
    data="builtin",
    *,
    out=None,
    n_objects=None,
    repeats=None,
    **settings,
):
    """Time every descriptor and normal estimation, in milliseconds per object.

    ``n_objects`` objects spread evenly over the data set are described at
    their own point counts, on one thread and on ``n_jobs`` threads. Normals
    are estimated once beforehand (:func:`eppf.preprocessing.estimate_normals`, timed
    separately, object by object) and given to the descriptors, so the
    descriptor rows exclude normal estimation. Each figure is the best of
    ``repeats`` runs (wall time; the process CPU time of that run, summed
    over threads, beside it).

    Parameters
    ----------
    data : str or Dataset, default="builtin"
        ``"builtin"``, a ``.npz`` path, or a loaded :class:`Dataset`.
    out : str, default=None
        Folder for ``runtime.md``/``.csv``/``.png``.
    n_objects : int, default=None
        Objects timed (200, or 20 with ``quick``; at most all of them).
    repeats : int, default=None
        Timing repeats, the fastest kept (3, or 1 with ``quick``).
    **settings
        The shared settings of :class:`ExperimentSettings` (``scaling``,
        ``random_state``, ``n_jobs``, ``quick``, ``cache_dir``, ``verbose``,
        ``command``).

    Returns
    -------
    result : dict
        ``"rows"`` (as in the CSV) and ``"paths"``.

    See Also
    --------
    run_retrieval : The descriptors timed here, scored.

    Examples
    --------
    >>> import tempfile
    >>> from eppf.experiments import run_runtime
    >>> result = run_runtime("builtin", quick=True, n_objects=5, repeats=1, n_jobs=1, out=tempfile.mkdtemp(),
    ...                      verbose=False)
    >>> from eppf.registry import DESCRIPTORS
    >>> items = [row["item"] for row in result["rows"]]
    >>> items[0], items[1:] == [spec.title for spec in DESCRIPTORS.values()]
    ('normals (PCA, 20 neighbours)', True)
    """
    scaling, random_state, n_jobs, quick, cache_dir, verbose, command = ExperimentSettings.from_kwargs(
        "run_runtime", settings).astuple()
    from .. import estimate_normals

    log = Logger("runtime", verbose)
    n_objects = check_positive_int(n_objects if n_objects is not None else (20 if quick else 200), "--n-objects")
    repeats = check_positive_int(repeats if repeats is not None else (1 if quick else 3), "--repeats")
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, (int, np.integer)) or n_jobs == 0:
        raise ExperimentError(f"--n-jobs must be a non-zero int, got {n_jobs!r}")
    ds = load_or_pass(data, quick=quick, random_state=random_state)
    scaling = resolve_scaling(scaling, ds)
    stride = max(1, len(ds.clouds) // n_objects)
    clouds = ds.clouds[::stride][:n_objects]
    n = len(clouds)
    sizes = np.array([len(c) for c in clouds])
    thread_counts = sorted({1, _threads(n_jobs)})
    log(f"timing {n} objects (median {int(np.median(sizes))} points) on {thread_counts} thread(s)")
    rows = []
    normals = None
    for threads in thread_counts:
        def run_normals():
            return [estimate_normals(c, 20, n_jobs=threads) for c in clouds]

        normals = run_normals()  # warm-up, and the normals the descriptors get
        wall, cpu = _time(run_normals, n, repeats)
        rows.append({"item": NORMALS, "threads": threads, "wall_ms": round(wall, 3), "cpu_ms": round(cpu, 3)})
        log(f"{NORMALS}, {threads} thread(s): {wall:.2f} ms/object wall, {cpu:.2f} CPU")
    with_normals = [np.hstack([c, nrm]) for c, nrm in zip(clouds, normals)]
    for name in DESCRIPTORS:
        for threads in thread_counts:
            est = make_descriptor(name, n_samples=n_samples_setting(quick), scaling=scaling, random_state=random_state,
                                  n_jobs=threads)
            est.fit(with_normals)
            est.transform(with_normals[:2])  # warm-up
            wall, cpu = _time(lambda: est.transform(with_normals), n, repeats)
            rows.append({"item": DESCRIPTORS[name], "threads": threads, "wall_ms": round(wall, 3),
                         "cpu_ms": round(cpu, 3)})
            log(f"{DESCRIPTORS[name]}, {threads} thread(s): {wall:.2f} ms/object wall, {cpu:.2f} CPU")
    for row in rows:
        row["n_objects"] = n
        row["median_points"] = int(np.median(sizes))
    result = {"rows": rows, "paths": {}}
    if out is None:
        return result
    table = markdown_table(
        ["Item", "Threads", "Wall ms/object", "CPU ms/object"],
        [[r["item"], r["threads"], f"{r['wall_ms']:.2f}", f"{r['cpu_ms']:.2f}"] for r in rows],
    )
    protocol = {
        "objects timed": f"{n} (every {stride}th object), their own point counts: median {int(np.median(sizes))}, "
                         f"min {sizes.min()}, max {sizes.max()}",
        "timing": f"best of {repeats} run(s) of transform over all timed objects after a warm-up, wall clock "
                  "(time.perf_counter) and process CPU time summed over threads (time.process_time); "
                  "the paper reports 8 ms per object for EPPF (C++/OpenMP, Intel i7)",
        "normals": "estimated once per object with eppf.estimate_normals(points, 20), timed object by object, "
                   "then given to every descriptor (descriptor rows exclude normal estimation; ESF ignores normals)",
        "descriptors": "; ".join(
            f"{DESCRIPTORS[k]}: `{params_text(make_descriptor(k, n_samples=n_samples_setting(quick), scaling=scaling, random_state=0, n_jobs=1))}`"
            for k in DESCRIPTORS),
        "pairs / triplets per object": n_samples_setting(quick),
        "threads": f"{thread_counts} (n_jobs={n_jobs})",
        "machine": cpu_model().lstrip("- "),
        "note": "the machine may be shared with other work; CPU time is the steadier figure",
    }

    def plot(plotting, plt):
        fig, ax = plt.subplots(figsize=(6, 3.6))
        bars = {r["item"].split(" (")[0]: r["wall_ms"] for r in rows if r["threads"] == 1}
        plotting.plot_scores_bar(bars, ax=ax, ylabel="ms per object (1 thread, wall)")
        ax.set_title(f"Runtime, {ds.name}")
        return fig

    result["paths"] = write_report(
        out, "runtime", title=f"Runtime on {ds.name}", command=command or command_text("runtime"), data=ds,
        protocol=protocol, table=table, csv_rows=rows, plot=plot, log=log, elapsed=log.elapsed(),
    )
    return result
