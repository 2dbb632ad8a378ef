"""Speed and memory of leave-one-out retrieval by symmetric KL divergence.

Usage::

    nice -n 10 python benchmarks/bench_retrieval.py              # 5,000 and 12,000 x 1,200
    python benchmarks/bench_retrieval.py --sizes 2000 --n-bins 540 --compare
    nice -n 10 python benchmarks/bench_retrieval.py --sizes 5000 --dask 2 --no-reference

For each size, sparse histograms like EPPF descriptors (a class profile per
object, 20,000 pair samples drawn into 1,200 bins) are written to a temporary
``.npy`` file; a fresh Python process loads them and runs
:func:`eppf.metrics.leave_one_out_retrieval`, reporting wall time and the
process's peak resident memory (interpreter, libraries and the input
included). ``--compare`` also times ``KLNearestNeighbors().fit(X, y).kneighbors()``
(the full, non-symmetric route) and checks both give the same neighbours.
``--dask N`` runs the leave-one-out again inside
``joblib.parallel_config(backend="dask")`` on a local cluster of ``N``
one-thread worker processes, and checks its neighbours are bit-identical.

When PCL's reference descriptors are given (``--reference-dir`` with
``pcl_modelnet10_1024.npz`` / ``pcl_dales_objects.npz``, arrays ``esf`` and
``ourcvfh``) together with the data sets' labels (``--data-dir`` or
``$EPPF_BENCH_DATA``, holding ``modelnet10_1024.npz`` / ``dales_objects.npz``;
see ``scripts/make_modelnet_npz.py``), the leave-one-out accuracies of ESF
and OUR-CVFH are printed next to the values published with those reference
files, an independent check of the whole matching path. Without them the
check is skipped (and said so); a ``--reference-dir`` whose files or labels
are missing is exit status 2.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _data import default_dir, in_dir, require  # noqa: E402

# leave-one-out total accuracy by symmetric KL, as published with the reference files
# (OUR-CVFH histograms L1-normalised first, which is how those figures arise)
README_ACCURACY = {
    ("modelnet10_1024", "esf"): 78.85,
    ("modelnet10_1024", "ourcvfh"): 58.60,
    ("dales_objects", "esf"): 89.98,
    ("dales_objects", "ourcvfh"): 57.52,
}

CHILD = r"""
import json, resource, sys, time
import numpy as np
from threadpoolctl import threadpool_info
from eppf.metrics import leave_one_out_retrieval
X = np.load(sys.argv[1]); y = np.load(sys.argv[2])
compare = sys.argv[3] == "1"
n_jobs = None if sys.argv[4] == "None" else int(sys.argv[4])
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
t, c = time.perf_counter(), cpu()
y_pred, ind = leave_one_out_retrieval(X, y, return_indices=True, n_jobs=n_jobs)
t_loo, c_loo = time.perf_counter() - t, cpu() - c
peak_loo = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
out = {"t_loo": t_loo, "cpu_loo": c_loo, "peak_mib": peak_loo, "acc": float(np.mean(y_pred == y)),
       "blas_threads": n_jobs or max((i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"), default=None)}
if compare:
    from eppf import KLNearestNeighbors
    t = time.perf_counter()
    ind2 = KLNearestNeighbors(n_jobs=n_jobs).fit(X, y).kneighbors(return_distance=False)[:, 0]
    out["t_full"] = time.perf_counter() - t
    out["same"] = int(np.sum(ind2 == ind))
n_dask = int(sys.argv[5])
if n_dask:
    from dask.distributed import Client, LocalCluster
    from joblib import parallel_config
    with LocalCluster(n_workers=n_dask, threads_per_worker=1, dashboard_address=None) as cluster, Client(cluster):
        with parallel_config(backend="dask"):
            t = time.perf_counter()
            y2, ind2 = leave_one_out_retrieval(X, y, return_indices=True, n_jobs=n_jobs)
            out["t_dask"] = time.perf_counter() - t
    out["dask_identical"] = bool(np.array_equal(ind2, ind) and np.array_equal(y2, y_pred))
print(json.dumps(out))
"""


def make_descriptors(n, n_bins, n_classes=40, n_pairs=20000, seed=0):
    """Sparse normalised histograms: per-class sparse profiles, multinomial counts.

    Each object's bin probabilities are a Dirichlet draw concentrated on its
    class profile (itself a sparse Dirichlet draw); 20,000 samples are then
    binned, so most bins are empty, as in EPPF descriptors.
    """
    rng = np.random.default_rng(seed)
    profiles = rng.dirichlet(np.full(n_bins, 0.05), size=n_classes)
    y = rng.integers(0, n_classes, size=n)
    X = np.empty((n, n_bins))
    for start in range(0, n, 1000):
        stop = min(start + 1000, n)
        g = rng.standard_gamma(100 * profiles[y[start:stop]] + 1e-3)
        p = g / g.sum(axis=1, keepdims=True)
        X[start:stop] = rng.multinomial(n_pairs, p) / n_pairs
    return X, y


def run_size(n, n_bins, compare, n_jobs=None, dask_workers=0):
    X, y = make_descriptors(n, n_bins)
    with tempfile.TemporaryDirectory() as tmp:
        xp, yp = os.path.join(tmp, "X.npy"), os.path.join(tmp, "y.npy")
        np.save(xp, X)
        np.save(yp, y)
        res = subprocess.run(
            [sys.executable, "-c", CHILD, xp, yp, "1" if compare else "0", str(n_jobs), str(dask_workers)], capture_output=True, text=True, check=True
        )
    out = json.loads(res.stdout.strip().splitlines()[-1])
    out["zero_share"] = float(np.mean(X == 0))
    return out


def reference_check(reference_dir, data_dir):
    from eppf.metrics import leave_one_out_retrieval

    rows = []
    for (name, key), expected in README_ACCURACY.items():
        ref_path = require("bench_retrieval", os.path.join(reference_dir, f"pcl_{name}.npz"), "reference file")
        data_path = in_dir("bench_retrieval", data_dir, name)
        X = np.load(ref_path)[key].astype(np.float64)
        X /= X.sum(axis=1, keepdims=True)
        y = np.load(data_path)["labels"]
        t = time.perf_counter()
        y_pred = leave_one_out_retrieval(X, y)
        rows.append((name, key, X.shape, 100 * np.mean(y_pred == y), expected, time.perf_counter() - t))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[5000, 12000])
    parser.add_argument("--n-bins", type=int, default=1200)
    parser.add_argument("--n-jobs", type=int, default=None, help="BLAS threads (default: BLAS's own setting)")
    parser.add_argument("--compare", action="store_true", help="also time KLNearestNeighbors.kneighbors()")
    parser.add_argument("--dask", type=int, default=0, metavar="N",
                        help="also run leave-one-out on a local dask cluster of N one-thread worker processes "
                             "(joblib's dask backend) and check it is bit-identical")
    parser.add_argument("--no-reference", action="store_true", help="skip the check on the PCL reference descriptors")
    parser.add_argument("--reference-dir", default=None, help="folder with PCL's pcl_<data set>.npz (optional)")
    parser.add_argument("--data-dir", default=default_dir(),
                        help="folder with the data sets' .npz, for their labels (default: $EPPF_BENCH_DATA)")
    args = parser.parse_args(argv)
    if args.reference_dir and not args.no_reference:  # check the inputs before the long timings
        for name, _ in README_ACCURACY:
            require("bench_retrieval", os.path.join(args.reference_dir, f"pcl_{name}.npz"), "reference file")
            in_dir("bench_retrieval", args.data_dir, name)

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine: {os.cpu_count()} CPUs, load average {load:.2f}; leave-one-out 1-NN, symmetric KL, float64")
    print("LOO s: wall time; CPU s: user + system time of all threads (less sensitive to other load)")
    header = f"{'n':>7} {'bins':>5} {'zeros':>6} {'threads':>7} {'LOO s':>7} {'CPU s':>7} {'peak MiB':>9}"
    if args.compare:
        header += f" {'kneighbors s':>12} {'same NN':>8}"
    if args.dask:
        header += f" {'dask s':>7} {'identical':>9}"
    print(header)
    for n in args.sizes:
        r = run_size(n, args.n_bins, args.compare, args.n_jobs, args.dask)
        line = f"{n:>7} {args.n_bins:>5} {r['zero_share']:>6.2f} {str(r['blas_threads']):>7} {r['t_loo']:>7.2f} {r['cpu_loo']:>7.2f} {r['peak_mib']:>9.0f}"
        if args.compare:
            line += f" {r['t_full']:>12.2f} {r['same']:>8}"
        if args.dask:
            line += f" {r['t_dask']:>7.2f} {str(r['dask_identical']):>9}"
        print(line, flush=True)

    if args.no_reference:
        return
    if not args.reference_dir:
        print("\n(PCL reference check skipped: no --reference-dir given)")
        return
    rows = reference_check(args.reference_dir, args.data_dir)
    if rows:
        print("\nPCL reference descriptors (L1-normalised), leave-one-out total accuracy")
        print(f"{'data':<16} {'desc':<8} {'shape':<12} {'eppf %':>7} {'published %':>11} {'s':>6}")
        for name, key, shape, acc, expected, t in rows:
            print(f"{name:<16} {key:<8} {str(shape):<12} {acc:>7.2f} {expected:>11.2f} {t:>6.2f}")


if __name__ == "__main__":
    main()
