"""Compare eppf's VFHTransformer with PCL 1.13's VFHEstimation on a labelled data set.

Same preprocessing as the PCL reference runs: every object centred on its
mean and scaled by its largest bounding-box side, PCA normals from 10
neighbours oriented away from the centroid, given to the transformer.
Reports, for eppf's rows and PCL's reference rows (``vfh`` key): leave-one-out
1-NN total accuracy with the L1 distance and with the symmetric KL divergence
(zero bins floored at half the smallest positive value); the L1 distance
between the two mean descriptors and the median per-row L1 distance, for the
whole row and for its angle (0-134) and viewpoint (180-307) parts; eppf's
time per object on one thread; and whether the output is bit-identical for
2 threads and for another chunk size.

Usage::

    python scripts/compare_pcl_vfh.py --data DATA.npz --reference PCL_GLOBAL.npz [--n-objects 1000]

Exits with a message (status 2) when a file is missing.
"""

import argparse
import os
import sys
import time

import numpy as np
from sklearn.metrics import pairwise_distances_chunked

KEY = "vfh"


def load_objects(path, n_objects):
    d = np.load(path)
    pts, off = d["points"].astype(np.float64), d["offsets"]
    labels = d["labels"]
    n = len(off) - 1 if n_objects is None else min(n_objects, len(off) - 1)
    clouds = []
    for k in range(n):
        p = pts[off[k] : off[k + 1]]
        p = p - p.mean(axis=0)
        clouds.append(p / np.ptp(p, axis=0).max())
    from eppf.preprocessing._normals import estimate_normals_batch
    from eppf.utils._validation import pack_point_clouds

    points, _, offsets = pack_point_clouds(clouds)
    normals = estimate_normals_batch(points, offsets, 10, "centroid", n_jobs=1)
    clouds = [np.hstack([points[a:b], normals[a:b]]) for a, b in zip(offsets[:-1], offsets[1:])]
    return clouds, labels[:n], n


def loo_l1(X, y):
    """Leave-one-out 1-NN total accuracy with the L1 distance."""
    pred = np.empty(len(X), dtype=y.dtype)
    start = 0
    for block in pairwise_distances_chunked(X, metric="manhattan", working_memory=256):
        rows = np.arange(start, start + len(block))
        block[np.arange(len(block)), rows] = np.inf
        pred[rows] = y[np.argmin(block, axis=1)]
        start += len(block)
    return float(np.mean(pred == y))


def loo_kl(X, y):
    from eppf.metrics import leave_one_out_retrieval

    return float(np.mean(leave_one_out_retrieval(X, y) == y))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="data set (.npz with points, offsets, labels)")
    ap.add_argument("--reference", required=True, help="PCL reference outputs (.npz with key 'vfh')")
    ap.add_argument("--n-objects", type=int, default=None, help="first N objects only (default: all)")
    ap.add_argument("--n-time", type=int, default=500, help="objects timed (default 500)")
    args = ap.parse_args(argv)
    for name in ("data", "reference"):
        if not os.path.isfile(getattr(args, name)):
            sys.stderr.write(f"compare_pcl_vfh: the --{name} file does not exist\n")
            return 2
    ref = np.load(args.reference)
    if KEY not in ref.files:
        sys.stderr.write(f"compare_pcl_vfh: the --reference file has no '{KEY}' key\n")
        return 2

    from eppf.utils import _chunks
    from eppf.descriptors._vfh import VFHTransformer

    clouds, y, n = load_objects(args.data, args.n_objects)
    R = ref[KEY][:n].astype(np.float64)
    est = VFHTransformer(n_jobs=1).fit(clouds)
    timed = clouds[: args.n_time]
    est.transform(timed[:2])
    best = np.inf
    for _ in range(3):
        t = time.process_time()
        est.transform(timed)
        best = min(best, time.process_time() - t)
    X = est.transform(clouds)
    print(f"objects: {n}; eppf VFH: {1e3 * best / len(timed):.3f} ms per object (CPU time, 1 thread, best of 3)")

    for part, sl in (("whole row", slice(0, 308)), ("angles f1-f3", slice(0, 135)), ("viewpoint", slice(180, 308))):
        l1 = np.abs(X[:, sl] - R[:, sl]).sum(axis=1)
        print(f"{part}: L1(mean eppf, mean PCL) = {np.abs(X[:, sl].mean(axis=0) - R[:, sl].mean(axis=0)).sum():.5f}; "
              f"per-row L1(eppf, PCL): median {np.median(l1):.2e}, 99th percentile {np.percentile(l1, 99):.2e}, "
              f"max {l1.max():.3f}")
    for label, M in (("eppf", X), ("PCL", R)):
        print(f"LOO 1-NN total accuracy, {label}: L1 {100 * loo_l1(M, y):.2f}%, "
              f"sym. KL {100 * loo_kl(M, y):.2f}%", flush=True)

    sub = clouds[: min(n, 600)]
    base = VFHTransformer(n_jobs=1).fit_transform(sub)
    two = VFHTransformer(n_jobs=2).fit_transform(sub)
    old = _chunks.CHUNK
    try:
        _chunks.CHUNK = 37
        chunked = VFHTransformer(n_jobs=1).fit_transform(sub)
    finally:
        _chunks.CHUNK = old
    same = np.array_equal(base, two) and np.array_equal(base, chunked)
    print(f"bit-identical for n_jobs=1/2 and chunk sizes {old}/37 on {len(sub)} objects: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
