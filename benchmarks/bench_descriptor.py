"""Speed of the EPPF descriptor and of leave-one-out KL retrieval.

Prints a table of milliseconds per object for the descriptor alone (normals
given) and with PCA normal estimation, at 1,024 / 2,048 / 10,000 points, on 1
and 2 threads, then the time and peak memory of leave-one-out symmetric-KL
retrieval over 5,000 and 12,000 descriptors of 1,200 bins.

Clouds come from ``--data modelnet10_1024.npz`` when given (real CAD
objects, made by ``scripts/make_modelnet_npz.py``; larger sizes are drawn by
resampling their points with a small jitter) and from the built-in synthetic
shapes otherwise.

The load average is printed with the table: wall-clock speed-ups over threads
only mean something on an otherwise idle machine, CPU time per object is robust
to other load.

``--contention`` adds a check of the machine rather than of eppf: the CPU
time per object of one single-threaded process alone, then of two such
processes running side by side. They share nothing, so any slow-down of the
pair is the hardware's (shared core, caches or memory bandwidth) and bounds
the two-thread speed-up any code can reach on the machine.

Usage: ``python benchmarks/bench_descriptor.py [--objects 200] [--repeats 3] [--quick]
[--sizes 1024 2048 10000] [--no-retrieval] [--contention] [--data modelnet10_1024.npz]``
"""

import argparse
import os
import platform
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _data import require  # noqa: E402
from _sidebyside import cpu_model, describe_levels  # noqa: E402

DATA = None  # the --data file, set by main()


def _clouds(n_objects, n_points, rng):
    from eppf.datasets import load_npz, make_shapes

    if DATA is not None:
        base = load_npz(DATA).data
        pick = rng.choice(len(base), size=n_objects, replace=False)
        out = []
        for k in pick:
            c = base[k] / np.ptp(base[k], axis=0).max()
            if n_points != len(c):
                idx = rng.integers(0, len(c), size=n_points)
                c = c[idx] + rng.normal(scale=2e-3, size=(n_points, 3))
            out.append(c)
        return out, f"ModelNet10 ({os.path.basename(DATA)})"
    per_class = max(1, n_objects // 10)
    shapes = make_shapes(per_class, n_points=n_points, random_state=0)
    return shapes.data[:n_objects], "built-in shapes"


def _best(fn, repeats):
    """Best wall time and best process CPU time over ``repeats`` calls."""
    best, best_cpu = np.inf, np.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return best, best_cpu


def bench_descriptor(n_objects, repeats, sizes=(1024, 2048, 10000)):
    """Rows (points, threads, wall ms/obj normals given, wall ms/obj with
    normal estimation, CPU ms/obj normals given), best of ``repeats``.

    The one- and two-thread passes alternate, so a slow spell of a shared
    machine hits both settings instead of biasing their ratio."""
    from eppf import EPPFTransformer, estimate_normals

    rng = np.random.default_rng(0)
    rows = []
    for n_points in sizes:
        clouds, source = _clouds(n_objects, n_points, rng)
        with_normals = [np.hstack([c, estimate_normals(c, 20)]) for c in clouds]
        ests = {t: EPPFTransformer(scaling="object", random_state=0, n_jobs=t).fit(clouds) for t in (1, 2)}
        for est in ests.values():  # warm up (first-touch pages, thread pool start)
            est.transform(with_normals[:4])
            est.transform(clouds[:4])
        best = {t: [np.inf, np.inf, np.inf] for t in ests}  # wall given, wall full, CPU given
        for _ in range(repeats):
            for threads, est in ests.items():
                t_desc, cpu_desc = _best(lambda: est.transform(with_normals), 1)
                t_full, _ = _best(lambda: est.transform(clouds), 1)
                b = best[threads]
                b[:] = min(b[0], t_desc), min(b[1], t_full), min(b[2], cpu_desc)
        for threads in ests:
            t_desc, t_full, cpu_desc = best[threads]
            rows.append((n_points, threads, 1e3 * t_desc / n_objects, 1e3 * t_full / n_objects,
                         1e3 * cpu_desc / n_objects))
    return rows, source


def _loo_child(n, bins):
    """Run one leave-one-out search in this process and print seconds and peak RSS."""
    import resource

    from eppf.metrics import leave_one_out_retrieval

    rng = np.random.default_rng(1)
    # sparse histograms like EPPF's: about 40% of the bins empty
    X = rng.gamma(0.3, size=(n, bins))
    X[X < 0.05] = 0.0
    X /= X.sum(axis=1, keepdims=True)
    y = rng.integers(0, 10, size=n)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    leave_one_out_retrieval(X, y)
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"{dt} {peak / 1024} {(peak - before) / 1024}")


def bench_loo(sizes, bins=1200):
    rows = []
    for n in sizes:
        out = subprocess.run(
            [sys.executable, __file__, "--loo-child", str(n), str(bins)], capture_output=True, text=True, check=True
        )
        dt, peak, extra = map(float, out.stdout.split())
        rows.append((n, bins, dt, peak))
    return rows


def _contention_child(n_objects, n_points, repeats):
    """Print the best CPU ms per object of a one-thread transform in this process."""
    from eppf import EPPFTransformer, estimate_normals

    clouds, _ = _clouds(n_objects, n_points, np.random.default_rng(0))
    with_normals = [np.hstack([c, estimate_normals(c, 20)]) for c in clouds]
    est = EPPFTransformer(scaling="object", random_state=0, n_jobs=1).fit(clouds)
    est.transform(with_normals)
    _, cpu = _best(lambda: est.transform(with_normals), repeats)
    print(1e3 * cpu / n_objects)


def bench_contention(n_objects, repeats, sizes):
    """CPU ms per object of one process alone and of each of two side by side."""
    rows = []
    for n_points in sizes:
        cmd = [sys.executable, __file__, "--contention-child", str(n_objects), str(n_points), str(repeats)]
        cmd += ["--data", DATA] if DATA is not None else []
        alone = float(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout)
        procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True) for _ in range(2)]
        pair = [float(p.communicate()[0]) for p in procs]
        rows.append((n_points, alone, pair))
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="fewer objects and no 12,000-descriptor search")
    parser.add_argument("--sizes", nargs="+", type=int, default=[1024, 2048, 10000], help="points per object")
    parser.add_argument("--no-retrieval", action="store_true", help="skip the leave-one-out retrieval timing")
    parser.add_argument("--contention", action="store_true",
                        help="also time two independent one-thread processes side by side (a machine check)")
    parser.add_argument("--loo-child", nargs=2, type=int, help=argparse.SUPPRESS)
    parser.add_argument("--contention-child", nargs=3, type=int, help=argparse.SUPPRESS)
    parser.add_argument("--data", default=None, help="modelnet10_1024.npz for real objects (default: built-in shapes)")
    args = parser.parse_args()
    global DATA
    DATA = None if args.data is None else require("bench_descriptor", args.data)
    if args.loo_child:
        _loo_child(*args.loo_child)
        return
    if args.contention_child:
        _contention_child(*args.contention_child)
        return
    if args.quick:
        args.objects, args.repeats = 40, 1
    import eppf
    from eppf.utils._scan_fast import has_openmp

    print(f"machine: {platform.machine()}, {cpu_model()}, {os.cpu_count()} logical CPUs, "
          f"OpenMP {'on' if has_openmp() else 'off'}")
    load_before = os.getloadavg()[0]
    rows, source = bench_descriptor(args.objects, args.repeats, tuple(args.sizes))
    print(f"\nEPPF descriptor, 20,000 pairs, 64^3 grid, {args.objects} objects from {source}, best of {args.repeats}")
    print(f"(1-minute load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after; "
          f"kernels: {describe_levels(eppf.simd_levels())})")
    print("(wall ms per object; 'CPU ms/obj' is the process CPU time per object summed over threads: the")
    print(" per-core cost, meaningful even when other processes share the cores; normals: PCA, 20 neighbours)")
    print(f"{'points':>7} | {'threads':>7} | {'ms/obj (normals given)':>22} | {'CPU ms/obj':>10} | "
          f"{'ms/obj (+ normals)':>18} | {'speed-up':>8}")
    print("-" * 91)
    one = {}
    for n_points, threads, t_desc, t_full, cpu in rows:
        if threads == 1:
            one[n_points] = t_desc
        speed = one[n_points] / t_desc
        print(f"{n_points:>7} | {threads:>7} | {t_desc:>22.3f} | {cpu:>10.3f} | {t_full:>18.3f} | {speed:>7.2f}x")
    if args.contention:
        print("\nTwo independent one-thread processes side by side (CPU ms per object; a slow-down is the machine's)")
        print(f"{'points':>7} | {'alone':>7} | {'side by side':>15} | {'slow-down':>9}")
        print("-" * 49)
        for n_points, alone, pair in bench_contention(args.objects, args.repeats, tuple(args.sizes)):
            both = " / ".join(f"{v:.3f}" for v in pair)
            print(f"{n_points:>7} | {alone:>7.3f} | {both:>15} | {max(pair) / alone - 1:>8.0%}")
    if args.no_retrieval:
        return
    sizes = (5000,) if args.quick else (5000, 12000)
    print("\nLeave-one-out symmetric-KL 1-NN retrieval (1,200 bins, all cores)")
    print(f"{'descriptors':>11} | {'seconds':>8} | {'peak RSS (MB)':>13}")
    print("-" * 40)
    for n, bins, dt, peak in bench_loo(sizes):
        print(f"{n:>11} | {dt:>8.2f} | {peak:>13.0f}")


if __name__ == "__main__":
    main()
