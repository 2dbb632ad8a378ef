"""Speed of PCA normal estimation (``eppf.estimate_normals`` and its batch kernel).

Prints a table of milliseconds per object at 1,024 / 2,048 / 10,000 points for
k = 10, 20 and 30 neighbours:

- ``cpu 1t``: CPU time of the one-thread batch run (stable when other
  processes share the machine);
- ``batch 1t`` / ``batch 2t``: many objects through
  ``eppf.preprocessing._normals.estimate_normals_batch`` (OpenMP over objects, what
  ``EPPFTransformer`` calls), wall time divided by the number of objects;
- ``single 1t``: one call of ``estimate_normals`` per object (Python overhead
  included);
- ``reference``: scipy's cKDTree plus batched ``np.linalg.eigh`` on one object,
  for scale (numpy's own threads are limited to one).

Objects are noisy, bumpy ellipsoid surfaces (object-like); with
``--data modelnet10_1024.npz`` (made by ``scripts/make_modelnet_npz.py``),
real ModelNet10 objects of 1,024 points are timed too. Each figure is the
best of ``--repeats`` runs.

Usage: ``python benchmarks/bench_normals.py [--repeats 5] [--quick] [--data modelnet10_1024.npz]``
"""

import argparse
import os
import platform
import sys
import time

import numpy as np
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from eppf import estimate_normals
from eppf.preprocessing._normals import estimate_normals_batch

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _data import require  # noqa: E402


def surface(rng, n):
    """Noisy points on a squashed, bumpy ellipsoid."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = 1 + 0.1 * np.sin(4 * u[:, 0]) * np.cos(3 * u[:, 1])
    return u * r[:, None] * [1.0, 0.6, 0.3] + 0.002 * rng.normal(size=(n, 3))


def reference(points, k):
    _, idx = cKDTree(points).query(points, k)
    nb = points[idx]
    centred = nb - nb.mean(axis=1, keepdims=True)
    return np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))[1][:, :, 0]


def best_of(fn, repeats, clock=time.perf_counter):
    fn()  # warm-up: thread pool, caches
    times = []
    for _ in range(repeats):
        t = clock()
        fn()
        times.append(clock() - t)
    return min(times)


def bench(clouds, k, repeats):
    points = np.concatenate(clouds)
    offsets = np.r_[0, np.cumsum([len(c) for c in clouds])].astype(np.int64)
    n_obj = len(clouds)
    row = {}
    for n_jobs in (1, 2):
        t = best_of(lambda: estimate_normals_batch(points, offsets, k, "centroid", n_jobs), repeats)
        row[f"batch {n_jobs}t"] = 1e3 * t / n_obj
    # CPU time of the one-thread run: robust to other processes taking turns
    # on a shared machine (not to their cache pressure).
    t = best_of(lambda: estimate_normals_batch(points, offsets, k, "centroid", 1), repeats, time.process_time)
    row["cpu 1t"] = 1e3 * t / n_obj
    few = clouds[: max(1, min(n_obj, 20))]
    t = best_of(lambda: [estimate_normals(c, k, n_jobs=1) for c in few], repeats)
    row["single 1t"] = 1e3 * t / len(few)
    with threadpool_limits(1):
        t = best_of(lambda: reference(clouds[0], k), max(1, repeats // 2))
    row["reference"] = 1e3 * t
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="fewer objects and repeats")
    parser.add_argument("--data", default=None, help="modelnet10_1024.npz, to time real objects too (optional)")
    args = parser.parse_args()
    repeats = 2 if args.quick else args.repeats
    budget = 50_000 if args.quick else 200_000  # points per timed batch
    rng = np.random.default_rng(0)

    datasets = []
    if args.data is not None:
        data = np.load(require("bench_normals", args.data))
        off = data["offsets"]
        n_obj = budget // 1024
        pts = data["points"][: off[n_obj]].astype(np.float64)
        datasets.append(("modelnet10", [pts[off[i] : off[i + 1]] for i in range(n_obj)]))
    for n in (1024, 2048, 10_000):
        datasets.append(("surface", [surface(rng, n) for _ in range(max(4, budget // n))]))

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine: {platform.machine()}, {os.cpu_count()} logical CPUs, load average {load:.2f}")
    print("ms per object (best of %d); batch = estimate_normals_batch over many objects" % repeats)
    cols = ["cpu 1t", "batch 1t", "batch 2t", "single 1t", "reference"]
    header = f"{'data':<11} {'points':>6} {'k':>3} " + " ".join(f"{c:>10}" for c in cols)
    print(header)
    print("-" * len(header))
    for name, clouds in datasets:
        for k in (10, 20, 30):
            row = bench(clouds, k, repeats)
            n = len(clouds[0])
            print(f"{name:<11} {n:>6} {k:>3} " + " ".join(f"{row[c]:>10.3f}" for c in cols), flush=True)


if __name__ == "__main__":
    main()
