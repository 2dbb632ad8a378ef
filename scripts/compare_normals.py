"""Compare PCA and randomized-Hough normals (Boulch and Marlet 2012, the
estimator of the EPPF paper) by what they do to EPPF retrieval.

For each data set and noise level, normals are estimated both ways
(:func:`eppf.preprocessing._normals.estimate_normals_batch` with
``method="pca"`` and ``method="hough"``, same ``n_neighbors``, centroid
orientation), given to :class:`eppf.EPPFTransformer` as six-column clouds,
and scored by leave-one-out 1-NN retrieval
(:func:`eppf.metrics.leave_one_out_retrieval`). The table also gives each
estimator's time per object and the median angle between the two normal
fields.

Usage::

    python scripts/compare_normals.py DATA [--max-objects 300] [--sigmas 0,0.02,0.05]
        [--n-neighbors 20] [--scaling auto|fit|object|none] [--n-jobs 1]

``DATA`` is a ``.npz`` file in eppf's packed layout (keys ``points``,
``offsets``, ``labels``) or a folder, in which every ``*.npz`` is compared.
``--max-objects`` keeps a seeded stratified subset (about equal shares per
class, in file order). Noise is :class:`eppf.preprocessing.GaussianNoise`
(``sigma`` relative to each object's bounding cube, ``random_state=0``).
``--scaling auto`` uses ``"object"`` for files whose name starts with
``modelnet`` and ``"fit"`` otherwise.
"""

import argparse
import glob
import os
import sys
import time

import numpy as np


def _load(path, max_objects):
    with np.load(path, allow_pickle=False) as d:
        try:
            pts, off, labels = d["points"], d["offsets"], d["labels"]
        except KeyError as exc:
            sys.exit(f"compare_normals: {path} lacks key {exc}")
    n = len(labels)
    keep = np.arange(n)
    if max_objects is not None and max_objects < n:
        rng = np.random.default_rng(0)
        classes = np.unique(labels)
        per = [rng.permutation(np.flatnonzero(labels == c)) for c in classes]
        chosen, i = [], 0
        while len(chosen) < max_objects:
            for p in per:
                if i < len(p) and len(chosen) < max_objects:
                    chosen.append(p[i])
            i += 1
        keep = np.sort(np.array(chosen))
    clouds = [np.asarray(pts[off[k]:off[k + 1]], dtype=np.float64) for k in keep]
    return clouds, np.asarray(labels)[keep]


def _pack(clouds):
    pts = np.concatenate(clouds)
    off = np.concatenate([[0], np.cumsum([len(c) for c in clouds])]).astype(np.int64)
    return pts, off


def _compare(name, clouds, y, sigmas, k, scaling, n_jobs):
    from eppf import EPPFTransformer
    from eppf.metrics import leave_one_out_retrieval
    from eppf.preprocessing import GaussianNoise
    from eppf.preprocessing._normals import estimate_normals_batch

    rows = []
    for sigma in sigmas:
        noisy = clouds if sigma == 0 else GaussianNoise(sigma, random_state=0).fit_transform(clouds)
        pts, off = _pack(noisy)
        normals = {}
        for method in ("pca", "hough"):
            t0 = time.perf_counter()
            normals[method] = estimate_normals_batch(pts, off, k, "centroid", n_jobs, method=method, random_state=0)
            dt = (time.perf_counter() - t0) / len(noisy)
            six = [np.hstack([pts[off[i]:off[i + 1]], normals[method][off[i]:off[i + 1]]]) for i in range(len(noisy))]
            X = EPPFTransformer(scaling=scaling, random_state=0, n_jobs=n_jobs).fit_transform(six)
            acc = float(np.mean(leave_one_out_retrieval(X, y) == y))
            rows.append((name, sigma, method, dt * 1e3, acc))
            print(f"  {name} sigma={sigma:g} {method}: {dt * 1e3:.2f} ms/object, LOO 1-NN {100 * acc:.1f}%", flush=True)
        cos = np.abs(np.sum(normals["pca"] * normals["hough"], axis=1))
        med = float(np.degrees(np.arccos(np.clip(np.median(cos), 0, 1))))
        rows.append((name, sigma, "angle", med, None))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data", help="an eppf .npz file or a folder of them")
    ap.add_argument("--max-objects", type=int, default=None)
    ap.add_argument("--sigmas", default="0,0.02,0.05")
    ap.add_argument("--n-neighbors", type=int, default=20)
    ap.add_argument("--scaling", default="auto", choices=["auto", "fit", "object", "none"])
    ap.add_argument("--n-jobs", type=int, default=1)
    args = ap.parse_args(argv)
    if os.path.isdir(args.data):
        paths = sorted(glob.glob(os.path.join(args.data, "*.npz")))
        if not paths:
            sys.exit(f"compare_normals: no .npz file in {args.data}")
    elif os.path.isfile(args.data):
        paths = [args.data]
    else:
        sys.exit(f"compare_normals: {args.data} does not exist (give an eppf .npz file or a folder of them)")
    try:
        sigmas = [float(s) for s in args.sigmas.split(",")]
    except ValueError:
        sys.exit(f"compare_normals: --sigmas must be comma-separated numbers, got {args.sigmas!r}")
    rows = []
    for path in paths:
        name = os.path.splitext(os.path.basename(path))[0]
        scaling = args.scaling
        if scaling == "auto":
            scaling = "object" if name.startswith("modelnet") else "fit"
        clouds, y = _load(path, args.max_objects)
        print(f"{name}: {len(clouds)} objects, {sum(len(c) for c in clouds)} points, scaling={scaling!r}", flush=True)
        rows += _compare(name, clouds, y, sigmas, args.n_neighbors, scaling, args.n_jobs)
    print()
    print(f"{'data':<18} {'sigma':>5} {'PCA ms':>8} {'Hough ms':>9} {'PCA acc':>8} {'Hough acc':>9} {'median angle':>13}")
    by = {}
    for name, sigma, method, a, b in rows:
        by.setdefault((name, sigma), {})[method] = (a, b)
    for (name, sigma), r in by.items():
        print(f"{name:<18} {sigma:>5g} {r['pca'][0]:>8.2f} {r['hough'][0]:>9.1f} {100 * r['pca'][1]:>7.1f}% "
              f"{100 * r['hough'][1]:>8.1f}% {r['angle'][0]:>12.1f}°")
    return 0


if __name__ == "__main__":
    sys.exit(main())
