"""Shared steps of the ``compare_pcl_*.py`` scripts: eppf's rows against PCL 1.13's reference rows.

Same preprocessing as the PCL reference runs (each object centred on its mean
and scaled by its largest bounding-box side; optionally PCA normals from 10
neighbours oriented away from the centroid), then: the L1 distance between the
mean descriptors and per-row L1 distances, leave-one-out 1-NN total accuracy of
both sets of rows with the L1 distance and with the symmetric KL divergence,
eppf's CPU time per object on one thread, and whether eppf's output is
bit-identical for 2 threads and for another chunk size.
"""

import argparse
import os
import sys
import time

import numpy as np
from sklearn.metrics import pairwise_distances_chunked


def load_objects(path, n_objects, normals=False):
    """The first ``n_objects`` clouds of a flat ``.npz`` (all when None), centred and scaled; labels; count."""
    d = np.load(path)
    pts, off = d["points"].astype(np.float64), d["offsets"]
    labels = d["labels"]
    n = len(off) - 1 if n_objects is None else min(n_objects, len(off) - 1)
    clouds = []
    for k in range(n):
        p = pts[off[k] : off[k + 1]]
        p = p - p.mean(axis=0)
        clouds.append(p / np.ptp(p, axis=0).max())
    if normals:
        from eppf.preprocessing._normals import estimate_normals_batch
        from eppf.utils._validation import pack_point_clouds

        points, _, offsets = pack_point_clouds(clouds)
        nrm = estimate_normals_batch(points, offsets, 10, "centroid", n_jobs=1)
        clouds = [np.hstack([points[a:b], nrm[a:b]]) for a, b in zip(offsets[:-1], offsets[1:])]
    return clouds, labels[:n], n


def loo_l1(X, y):
    """Leave-one-out 1-NN total accuracy with the L1 distance (ties to the lowest index)."""
    pred = np.empty(len(X), dtype=y.dtype)
    start = 0
    for block in pairwise_distances_chunked(X, metric="manhattan", working_memory=256):
        rows = np.arange(start, start + len(block))
        block[np.arange(len(block)), rows] = np.inf
        pred[rows] = y[np.argmin(block, axis=1)]
        start += len(block)
    return float(np.mean(pred == y))


def loo_kl(X, y):
    """Leave-one-out 1-NN total accuracy with eppf's symmetric KL retrieval."""
    from eppf.metrics import leave_one_out_retrieval

    return float(np.mean(leave_one_out_retrieval(X, y) == y))


def run(argv, *, prog, key, title, make, normals=False, parts=(("whole row", slice(None)),)):
    """The whole comparison for one descriptor; returns the exit status.

    ``make(n_jobs)`` builds eppf's transformer; ``parts`` are the slices of
    the row whose mean and per-row L1 distances are reported.
    """
    ap = argparse.ArgumentParser(prog=prog, description=f"Compare eppf's {title} with PCL 1.13's on a labelled data set.")
    ap.add_argument("--data", required=True, help="data set (.npz with points, offsets, labels)")
    ap.add_argument("--reference", required=True, help=f"PCL reference outputs (.npz with key '{key}')")
    ap.add_argument("--n-objects", type=int, default=None, help="first N objects only (default: all)")
    ap.add_argument("--n-time", type=int, default=500, help="objects timed (default 500)")
    args = ap.parse_args(argv)
    for name in ("data", "reference"):
        if not os.path.isfile(getattr(args, name)):
            sys.stderr.write(f"{prog}: the --{name} file does not exist\n")
            return 2
    ref = np.load(args.reference)
    if key not in ref.files:
        sys.stderr.write(f"{prog}: the --reference file has no '{key}' key\n")
        return 2

    from eppf.utils import _chunks

    clouds, y, n = load_objects(args.data, args.n_objects, normals=normals)
    R = ref[key][:n].astype(np.float64)
    est = make(1).fit(clouds)
    timed = clouds[: args.n_time]
    est.transform(timed[:2])
    best = np.inf
    for _ in range(3):
        t = time.process_time()
        est.transform(timed)
        best = min(best, time.process_time() - t)
    X = est.transform(clouds)
    print(f"objects: {n}; eppf {title}: {1e3 * best / len(timed):.3f} ms per object (CPU time, 1 thread, best of 3)")
    print(f"mean row sum: eppf {X.sum(axis=1).mean():.3f}, PCL {R.sum(axis=1).mean():.3f}")
    for part, sl in parts:
        l1 = np.abs(X[:, sl] - R[:, sl]).sum(axis=1)
        print(f"{part}: L1(mean eppf, mean PCL) = {np.abs(X[:, sl].mean(axis=0) - R[:, sl].mean(axis=0)).sum():.5f}; "
              f"per-row L1(eppf, PCL): median {np.median(l1):.2e}, 99th percentile {np.percentile(l1, 99):.2e}, "
              f"max {l1.max():.3f}")
    for label, M in (("eppf", X), ("PCL", R)):
        print(f"LOO 1-NN total accuracy, {label}: L1 {100 * loo_l1(M, y):.2f}%, "
              f"sym. KL {100 * loo_kl(M, y):.2f}%", flush=True)

    sub = clouds[: min(n, 600)]
    base = make(1).fit_transform(sub)
    two = make(2).fit_transform(sub)
    old = _chunks.CHUNK
    try:
        _chunks.CHUNK = 37
        chunked = make(1).fit_transform(sub)
    finally:
        _chunks.CHUNK = old
    same = np.array_equal(base, two) and np.array_equal(base, chunked)
    print(f"bit-identical for n_jobs=1/2 and chunk sizes {old}/37 on {len(sub)} objects: {same}")
    return 0 if same else 1
