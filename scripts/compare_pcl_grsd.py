"""Compare eppf's GRSDTransformer with PCL 1.13's GRSDEstimation outputs.

Preprocessing as the PCL reference runs: every object centred on its mean
and scaled by its largest bounding-box side, PCA normals from 10 neighbours
pointing away from the centroid (computed once, given to the descriptor).
Reports, per data set: the share of rows identical to PCL's, the median
per-row L1 distance (raw counts and row-normalised), the L1 distance between
the mean normalised descriptors, leave-one-out 1-NN total accuracy with the
L1 distance (raw counts) and the symmetric KL divergence (normalised rows,
zero bins floored at half the smallest positive value) for both, and the
CPU time per object on one thread.

Usage::

    python scripts/compare_pcl_grsd.py DATA_DIR REFERENCE_DIR [--n 500] [--datasets modelnet10_1024]

``DATA_DIR`` holds ``<name>.npz`` (``points``, ``offsets``, ``labels``) and
``REFERENCE_DIR`` holds ``pcl_global_<name>.npz`` (key ``grsd``).
"""

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _pcl_compare import loo_l1  # noqa: E402

DATASETS = ("modelnet10_1024", "dales_objects")


def load(data_dir, name, n=None):
    """Centred, scaled clouds (n_i, 6) with PCA normals, labels and the kept rows."""
    from eppf.preprocessing._normals import estimate_normals_batch
    from eppf.utils._validation import pack_point_clouds

    d = np.load(os.path.join(data_dir, name + ".npz"))
    pts, off, labels = d["points"].astype(np.float64), d["offsets"], d["labels"]
    rows = np.arange(len(off) - 1)
    if n is not None and n < len(rows):
        rows = np.linspace(0, len(rows) - 1, n).round().astype(int)
    clouds = []
    for k in rows:
        p = pts[off[k] : off[k + 1]]
        p = p - p.mean(axis=0)
        clouds.append(p / np.ptp(p, axis=0).max())
    P, _, O = pack_point_clouds(clouds)
    N = estimate_normals_batch(P, O, 10, "centroid", n_jobs=1)
    return [np.hstack([P[a:b], N[a:b]]) for a, b in zip(O[:-1], O[1:])], labels[rows], rows


def loo_kl(X, y):
    from eppf.metrics import leave_one_out_retrieval, retrieval_scores

    Xn = X / X.sum(axis=1, keepdims=True)
    return float(retrieval_scores(y, leave_one_out_retrieval(Xn, y))["total_accuracy"])


def compare(ours, ref, y, label):
    """Print the agreement and retrieval figures of two row sets."""
    l1 = np.abs(ours - ref).sum(axis=1)
    on = ours / ours.sum(axis=1, keepdims=True)
    rn = ref / ref.sum(axis=1, keepdims=True)
    l1n = np.abs(on - rn).sum(axis=1)
    print(f"  {label}: rows identical to PCL's {100 * np.mean(l1 == 0):.2f}%, median per-row L1 "
          f"{np.median(l1):.4g} (raw), {np.median(l1n):.4g} (normalised); L1 between mean "
          f"normalised descriptors {np.abs(on.mean(0) - rn.mean(0)).sum():.4g}")
    for name, X in (("eppf", ours), ("PCL", ref)):
        print(f"  {label}: LOO 1-NN total accuracy {name}: L1 {100 * loo_l1(X, y):.2f}%, "
              f"sym. KL {100 * loo_kl(X, y):.2f}%", flush=True)


def time_per_object(est, clouds, repeats=3):
    est.fit(clouds)
    est.transform(clouds[:2])
    best = np.inf
    for _ in range(repeats):
        c = time.process_time()
        est.transform(clouds)
        best = min(best, time.process_time() - c)
    return 1e3 * best / len(clouds)


def main(argv=None, key="grsd", make=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data_dir")
    ap.add_argument("reference_dir")
    ap.add_argument("--n", type=int, default=None, help="objects per data set, evenly spaced (default all)")
    ap.add_argument("--datasets", nargs="+", default=list(DATASETS))
    ap.add_argument("--n-time", type=int, default=200, help="1,024-point objects timed (default 200)")
    args = ap.parse_args(argv)
    if make is None:
        from eppf.descriptors._grsd import GRSDTransformer

        def make():
            return GRSDTransformer(normalize=False, n_jobs=1)

    for name in args.datasets:
        data = os.path.join(args.data_dir, name + ".npz")
        refp = os.path.join(args.reference_dir, f"pcl_global_{name}.npz")
        for path in (data, refp):
            if not os.path.exists(path):
                sys.exit(f"compare_pcl_{key}: {os.path.basename(path)} not found in the given folder")
        clouds, y, rows = load(args.data_dir, name, args.n)
        ref = np.load(refp)[key][rows].astype(np.float64)
        t = time.perf_counter()
        ours = make().fit_transform(clouds)
        print(f"{name}: {len(clouds)} objects, {time.perf_counter() - t:.1f} s", flush=True)
        compare(ours, ref, y, name)
        if name.startswith("modelnet"):
            timed = [c for c in clouds if len(c) == 1024][: args.n_time]
            print(f"  {name}: {time_per_object(make(), timed):.3f} ms per 1,024-point object "
                  "(CPU time, 1 thread, normals given, best of 3)", flush=True)


if __name__ == "__main__":
    main()
