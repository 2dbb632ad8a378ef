"""Speed of PCA normal estimation (``eppf.estimate_normals``), side by side with Open3D.

Default table: milliseconds of CPU per cloud, one thread, ``n_neighbors=20``,
for ``eppf.estimate_normals(cloud, 20, n_jobs=1)`` (the whole public call:
validation included) and Open3D's
``PointCloud.estimate_normals(KDTreeSearchParamKNN(20))`` on the same clouds,
and their ratio (Open3D / eppf). The clouds:

- ``modelnet10 1024``: ModelNet10 objects as stored (1,024 Poisson-disk
  samples of each mesh, float64), every ``len / n``-th object of the file;
- ``modelnet10 10000``: the same objects resampled to 10,000 points, the
  1,024 originals plus points drawn uniformly on segments from a random
  original to one of its 6 nearest originals (seeded), so the new points lie
  on the sampled surface at about 10 times the density;
- ``dales 1024``: DALES Objects segments (aerial LiDAR) of at least 1,024
  points, 1,024 of them drawn without replacement (seeded);
- ``dales 10000``: the DALES segments of 10,000 points, as stored.

Each figure is the best of ``--repeats`` rounds, CPU time of a pass over
all the clouds of a row divided by the number of clouds. eppf runs in one
worker process per ``--levels`` level (``EPPF_SIMD`` set before eppf is
imported; default: the CPU's own level only; ``--levels native,avx2,scalar``
also runs an AVX2-only and a portable machine's kernels on this one, marked
"emulated"), Open3D in a worker of its own pinned to one CPU with
``OMP_NUM_THREADS=1`` (its normals cleared before each call, untimed: with
normals present it would also orient them to the old ones), PCL 1.13's
``NormalEstimation`` (k-d tree, one thread) in the harness of
``benchmarks/pcl_harness`` (built on demand; left out with one line where
PCL or a compiler is missing); their passes alternate round by round, so all
see the same load. The ``p99 angle`` column is the 99th percentile over all
points of the angle between eppf's and Open3D's normals, up to sign (both are
exact PCA over the 20 nearest neighbors; they differ only by rounding, or
where the 20th neighbor is tied with the 21st). Open3D is a benchmark-only
dependency (``pip install open3d``): without it its columns are skipped with
a printed line. The CPU model and the level each kernel ran at are printed
with the table; figures measured on the project's machines are in the
performance page of the documentation, one table per CPU kind.

``--table`` prints instead the older table of eppf alone: milliseconds per
object at 1,024 / 2,048 / 10,000 points for k = 10, 20 and 30, through the
batch kernel on 1 and 2 threads and through single calls, and scipy's
cKDTree plus ``np.linalg.eigh`` for scale, on noisy bumpy ellipsoids.

Usage: ``python benchmarks/bench_normals.py [--data-dir DIR | --data modelnet10_1024.npz
--dales dales_objects.npz] [--clouds 40] [--repeats 5] [--levels native,avx2,scalar] [--no-pcl]
[--table [--quick]]`` (``--data-dir`` defaults to ``$EPPF_BENCH_DATA``; a data set not found is
left out with a printed line; with no data at all the built-in synthetic shapes are used).
"""

import argparse
import os
import platform
import sys
import time

import tempfile

import numpy as np
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from eppf import estimate_normals
from eppf.preprocessing._normals import estimate_normals_batch

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import _pcl  # noqa: E402
from _data import benchmark_objects, default_dir, densify, write_objects  # noqa: E402
from _sidebyside import (Worker, WorkerError, cpu_model, describe_levels, load_average, parse_levels,  # noqa: E402
                         run_rounds)
from _worker import K_NORMALS as K  # noqa: E402


def _load(path):
    with np.load(path, allow_pickle=False) as d:
        return d["points"], d["offsets"]


def modelnet_sets(path, n_clouds, rng):
    pts, off = _load(path)
    n_obj = len(off) - 1
    pick = np.linspace(0, n_obj - 1, n_clouds).astype(int)
    small = [np.ascontiguousarray(pts[off[i]:off[i + 1]], dtype=np.float64) for i in pick]
    big = [densify(c, 10_000, rng) for c in small]
    return [("modelnet10", small), ("modelnet10", big)]


def dales_sets(path, n_clouds, rng):
    pts, off = _load(path)
    sizes = np.diff(off)
    out = []
    for n in (1024, 10_000):
        idx = np.flatnonzero(sizes >= n)[:n_clouds]
        clouds = []
        for i in idx:
            c = np.asarray(pts[off[i]:off[i + 1]], dtype=np.float64)
            if len(c) > n:
                c = c[np.sort(rng.choice(len(c), n, replace=False))]
            clouds.append(np.ascontiguousarray(c))
        if clouds:
            out.append(("dales", clouds))
    return out


def compare(datasets, repeats, levels=("native",), pcl=True, open3d=True):
    """Time eppf (one worker per level), Open3D and PCL on each data set, rounds alternating; print the table."""
    with tempfile.TemporaryDirectory(prefix="eppf-bench-") as tmp:
        files = []
        for i, (name, clouds) in enumerate(datasets):
            files.append(os.path.join(tmp, f"set{i}.bin"))
            write_objects(files[-1], clouds)
        workers, jobs, cols = [], [], []
        try:
            seen = set()
            for lv in levels:
                w = Worker(lv)
                workers.append(w)
                got = describe_levels(w.ask(op="info")["levels"])
                if got in seen:
                    print(f"{lv}: the kernels run as at an earlier level ({got}): left out")
                    continue
                seen.add(got)
                cols.append((f"eppf {lv}", lv, w))
                print(f"eppf {lv}: {got}", flush=True)
                jobs += [((lv, i), f"eppf {lv} set {i}", w.timer("normals", f)) for i, f in enumerate(files)]
            o3d = None
            if open3d:
                o3d = Worker("native", pin=True)
                workers.append(o3d)
                try:
                    o3d.ask(op="time", task="open3d_normals", file=files[0])
                    jobs += [(("open3d", i), f"open3d set {i}", o3d.timer("open3d_normals", f))
                             for i, f in enumerate(files)]
                except WorkerError as exc:
                    print(f"open3d is not available ({exc}); its columns are skipped")
                    o3d = None
            exe = _pcl.harness() if pcl else None
            if exe is not None:
                jobs += [(("pcl", i), f"pcl set {i}", (lambda f=f: _pcl.time_pcl(exe, f, "normals", k=K) / 1e3))
                         for i, f in enumerate(files)]
            t = run_rounds(jobs, repeats)
            angles = _angles(cols[0][2], o3d, files, tmp) if o3d is not None and cols else {}
        finally:
            for w in workers:
                w.close()
    print(f"\nms of CPU per cloud, one thread, n_neighbors={K}, best of {repeats} rounds; CPU: {cpu_model()}; "
          f"load average {load_average():.1f}")
    head = f"{'data':<11} {'points':>6} {'clouds':>6}" + "".join(f" {c[0]:>13}" for c in cols)
    others = [("open3d", "open3d") for _ in [0] if o3d is not None] + [("pcl", "pcl") for _ in [0] if exe is not None]
    head += "".join(f" {n:>8} {n + '/' + cols[0][0].split()[1][:6]:>13}" for n, _ in others)
    head += f" {'p99 angle':>10}" if angles else ""
    print(head)
    print("-" * len(head))
    for i, (name, clouds) in enumerate(datasets):
        ms = {c[1]: t.ms((c[1], i)) for c in cols}
        line = f"{name:<11} {len(clouds[0]):>6} {len(clouds):>6}" + "".join(f" {_f(ms[c[1]]):>13}" for c in cols)
        for who, _ in others:
            v = t.ms((who, i))
            first = ms[cols[0][1]]
            line += f" {_f(v):>8} {_f(v / first if v and first else None, 2):>13}"
        if angles:
            line += f" {angles[i]:>9.1e}°"
        print(line, flush=True)
    for key, msg in t.errors.items():
        print(f"not measured: {key}: {msg}")


def _f(v, digits=3):
    return "-" if v is None else f"{v:.{digits}f}"


def _angles(ours, o3d, files, tmp):
    """99th percentile of the angle between eppf's and Open3D's normals, up to sign, per file."""
    out = {}
    for i, f in enumerate(files):
        a, b = os.path.join(tmp, f"a{i}.npy"), os.path.join(tmp, f"b{i}.npy")
        ours.ask(op="rows", task="normals", file=f, out=a)
        o3d.ask(op="rows", task="open3d_normals", file=f, out=b)
        cos = np.abs(np.sum(np.load(a) * np.load(b), axis=1))
        sines = np.sqrt(np.maximum(0.0, 1.0 - cos * cos))
        out[i] = float(np.degrees(np.arcsin(np.clip(np.percentile(sines, 99), 0.0, 1.0))))
    return out


# ---------------------------------------------------------------- --table


def surface(rng, n):
    """Noisy points on a squashed, bumpy ellipsoid."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = 1 + 0.1 * np.sin(4 * u[:, 0]) * np.cos(3 * u[:, 1])
    return u * r[:, None] * [1.0, 0.6, 0.3] + 0.002 * rng.normal(size=(n, 3))


def reference(points, k):
    _, idx = cKDTree(points).query(points, k)
    nb = points[idx]
    centered = nb - nb.mean(axis=1, keepdims=True)
    return np.linalg.eigh(np.einsum("nki,nkj->nij", centered, centered))[1][:, :, 0]


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
    t = best_of(lambda: estimate_normals_batch(points, offsets, k, "centroid", 1), repeats, time.process_time)
    row["cpu 1t"] = 1e3 * t / n_obj
    few = clouds[: max(1, min(n_obj, 20))]
    t = best_of(lambda: [estimate_normals(c, k, n_jobs=1) for c in few], repeats)
    row["single 1t"] = 1e3 * t / len(few)
    with threadpool_limits(1):
        t = best_of(lambda: reference(clouds[0], k), max(1, repeats // 2))
    row["reference"] = 1e3 * t
    return row


def table(repeats, quick):
    budget = 50_000 if quick else 200_000  # points per timed batch
    rng = np.random.default_rng(0)
    print("ms per object (best of %d); batch = estimate_normals_batch over many objects" % repeats)
    cols = ["cpu 1t", "batch 1t", "batch 2t", "single 1t", "reference"]
    header = f"{'data':<11} {'points':>6} {'k':>3} " + " ".join(f"{c:>10}" for c in cols)
    print(header)
    print("-" * len(header))
    for n in (1024, 2048, 10_000):
        clouds = [surface(rng, n) for _ in range(max(4, budget // n))]
        for k in (10, 20, 30):
            row = bench(clouds, k, repeats)
            print(f"{'surface':<11} {n:>6} {k:>3} " + " ".join(f"{row[c]:>10.3f}" for c in cols), flush=True)


def _find(explicit, name, data_dir):
    if explicit is not None:
        return explicit
    if data_dir is not None:
        return os.path.join(data_dir, name)
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", default=default_dir(), help="folder of the .npz sets (default $EPPF_BENCH_DATA)")
    parser.add_argument("--data", default=None, help="modelnet10_1024.npz (default: in --data-dir)")
    parser.add_argument("--dales", default=None, help="dales_objects.npz (default: in --data-dir)")
    parser.add_argument("--clouds", type=int, default=40, help="clouds per row (fewer where the set has fewer)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--table", action="store_true", help="the older eppf-only table over k and threads")
    parser.add_argument("--quick", action="store_true", help="with --table: fewer objects and repeats")
    parser.add_argument("--levels", default="native",
                        help="comma-separated EPPF_SIMD levels for eppf, each in a process of its own: native, "
                             "avx512, avx2, scalar or all (default: native)")
    parser.add_argument("--no-pcl", action="store_true", help="leave PCL out (otherwise timed where its harness builds)")
    parser.add_argument("--no-open3d", action="store_true", help="leave Open3D out")
    args = parser.parse_args()
    try:
        levels = parse_levels(args.levels)
    except ValueError as exc:
        parser.error(str(exc))
    print(f"machine: {platform.machine()}, {cpu_model()}, {os.cpu_count()} logical CPUs, "
          f"load average {load_average():.2f}")
    if args.table:
        table(2 if args.quick else args.repeats, args.quick)
        return
    rng = np.random.default_rng(0)
    datasets = []
    for path, loader, what in ((_find(args.data, "modelnet10_1024.npz", args.data_dir), modelnet_sets, "ModelNet10"),
                               (_find(args.dales, "dales_objects.npz", args.data_dir), dales_sets, "DALES")):
        if path is None or not os.path.isfile(path):
            print(f"{what}: no file ({path!r}); pass --data-dir DIR, --data or --dales, or set $EPPF_BENCH_DATA")
            continue
        datasets += loader(path, args.clouds, rng)
    if not datasets:
        small, big, source = benchmark_objects(None, args.clouds, args.clouds)
        print(f"no data set found: timing {source} instead")
        datasets = [("shapes", small), ("shapes", big)]
    compare(datasets, args.repeats, levels, pcl=not args.no_pcl, open3d=not args.no_open3d)


if __name__ == "__main__":
    main()
