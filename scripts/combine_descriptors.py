"""Retrieval with combined descriptors (DescriptorUnion): EPPF alone, GASD alone, EPPF + another.

Every descriptor matrix is computed once per data set (one seeded draw per
``--draws``) and optionally cached as ``.npy`` in ``--cache``. A union row is
the blocks L1-normalised and weighted ``w`` (EPPF) and ``1 - w`` (the other),
exactly what :class:`eppf.descriptors.DescriptorUnion` computes, so the
weights are tried on the cached matrices without recomputing descriptors.

Protocol (honest: the test objects never choose anything):

- the weight of each pair is chosen on the TRAINING split only: a seeded
  stratified quarter of the training objects is queried (1-NN, symmetric KL)
  against the other three quarters, for ``w`` in 0.1, 0.2, ..., 0.9; the
  best ``w`` wins (ties to the smaller ``w``);
- the registered preset's weight (``EPPFGASDTransformer().eppf_weight``)
  is shown for EPPF + GASD too;
- reported: that held-out training accuracy, the leave-one-out 1-NN total
  accuracy over the whole set (the paper's protocol), and the train -> test
  1-NN accuracy (fit on the training split, predict the test split), all
  with the symmetric KL divergence, floor "auto" (half the smallest positive
  value), as mean over draws.

Usage::

    python scripts/combine_descriptors.py --data modelnet10_1024.npz --scaling object [--draws 1] [--cache DIR]
    python scripts/combine_descriptors.py --data dales_objects.npz --scaling fit

``--scaling`` is EPPF's: ``object`` for data whose objects are in unrelated
units (raw CAD models), ``fit`` for data in one unit (LiDAR in metres).
Exits with status 2 and a message when the data file is missing or has no
train/test split.
"""

import argparse
import os
import sys
import time

import numpy as np

WEIGHT_GRID = tuple(round(0.1 * k, 1) for k in range(1, 10))
SHOWN_WEIGHTS = (0.25, 0.5, 0.75)
OTHERS = ("gasd", "esf", "grsd")


def make_descriptor(name, scaling, seed, n_jobs):
    from eppf.descriptors import EPPFTransformer, ESFTransformer, GASDTransformer, GRSDTransformer

    if name == "eppf":
        return EPPFTransformer(scaling=scaling, random_state=seed, n_jobs=n_jobs)
    if name == "gasd":
        return GASDTransformer(n_jobs=n_jobs)
    if name == "esf":
        return ESFTransformer(random_state=seed, n_jobs=n_jobs)
    if name == "grsd":
        return GRSDTransformer(n_jobs=n_jobs)
    raise ValueError(name)


def descriptor_matrix(name, data, args, draw, digest):
    """One draw of one descriptor for every object, from the cache when there."""
    deterministic = name in ("gasd", "grsd")
    seed = None if deterministic else draw
    tag = f"{digest}_{name}" + ("" if deterministic else f"_seed{draw}") + (f"_{args.scaling}" if name == "eppf" else "")
    path = os.path.join(args.cache, tag + ".npy") if args.cache else None
    if path and os.path.exists(path):
        X = np.load(path, allow_pickle=False)
        if X.shape[0] == len(data.data):
            return X, 0.0
    t0 = time.perf_counter()
    X = make_descriptor(name, args.scaling, seed, args.n_jobs).fit_transform(data.data)
    seconds = time.perf_counter() - t0
    if path:
        os.makedirs(args.cache, exist_ok=True)
        np.save(path, X)
    return X, seconds


def preset_weight():
    """EPPF's weight in the registered ``"eppf+gasd"`` preset (shown in the table)."""
    from eppf.descriptors import EPPFGASDTransformer

    return EPPFGASDTransformer().eppf_weight


def l1(B):
    return B / B.sum(axis=1, keepdims=True)


def union(blocks, weights):
    return np.hstack([w * l1(B) for B, w in zip(blocks, weights)])


def holdout_split(y_train, seed=0):
    from sklearn.model_selection import train_test_split

    idx = np.arange(len(y_train))
    return train_test_split(idx, test_size=0.25, stratify=y_train, random_state=seed)


def one_nn(X_ref, y_ref, X_query, y_query):
    from eppf.neighbors import KLNearestNeighbors

    return float(np.mean(KLNearestNeighbors().fit(X_ref, y_ref).predict(X_query) == y_query))


def scores(X, y, train, test, ref, val):
    from eppf.metrics import leave_one_out_retrieval

    Xtr, ytr = X[train], y[train]
    return (
        one_nn(Xtr[ref], ytr[ref], Xtr[val], ytr[val]),
        float(np.mean(leave_one_out_retrieval(X, y) == y)),
        one_nn(Xtr, ytr, X[test], y[test]),
    )


def check_union(data, args, mats, others, chosen, n=40):
    """DescriptorUnion on the first ``n`` objects gives the rows scored here (last draw)."""
    from eppf.descriptors import DescriptorUnion

    for other in others:
        w = chosen[other][-1]
        seed = args.draws - 1
        est = DescriptorUnion([("eppf", make_descriptor("eppf", args.scaling, seed, args.n_jobs)),
                               ("other", make_descriptor(other, args.scaling, None if other in ("gasd", "grsd") else seed,
                                                         args.n_jobs))],
                              weights={"eppf": w, "other": 1 - w})
        if args.scaling == "fit":  # the data-set scale is learned from every object, as in the matrices
            est.fit(data.data)
            got = est.transform(data.data[:n])
        else:
            got = est.fit_transform(data.data[:n])
        want = union((mats["eppf"][:n], mats[other][:n]), (w, 1 - w))
        # Seeds are drawn per object over the whole input, so a prefix of the
        # data set gets the same draws as the full pass did.
        if not np.allclose(got, want, rtol=1e-12, atol=1e-15):
            raise SystemExit(f"combine_descriptors: DescriptorUnion disagrees with the cached EPPF+{other} rows")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="a labelled .npz of point clouds with a train/test split")
    parser.add_argument("--scaling", default="fit", choices=["fit", "object", "none"], help="EPPF's scaling")
    parser.add_argument("--draws", type=int, default=1, help="seeded draws of the sampled descriptors")
    parser.add_argument("--others", default=",".join(OTHERS), help="descriptors paired with EPPF")
    parser.add_argument("--cache", default=None, help="folder for the descriptor matrices (.npy)")
    parser.add_argument("--n-jobs", type=int, default=1)
    args = parser.parse_args(argv)
    if not os.path.isfile(args.data):
        print(f"combine_descriptors: data file {args.data!r} not found", file=sys.stderr)
        return 2
    if args.draws < 1:
        print(f"combine_descriptors: --draws must be at least 1, got {args.draws}", file=sys.stderr)
        return 2
    others = [o for o in args.others.split(",") if o]
    bad = [o for o in others if o not in OTHERS]
    if bad:
        print(f"combine_descriptors: unknown --others {bad}; choose from {list(OTHERS)}", file=sys.stderr)
        return 2

    from eppf.datasets import load_npz
    from eppf.utils._cache import data_digest

    data = load_npz(args.data)
    if data.split is None or not {"train", "test"} <= set(data.split.tolist()):
        print(f"combine_descriptors: {args.data!r} has no train/test split", file=sys.stderr)
        return 2
    y = np.asarray(data.target)
    train, test = np.flatnonzero(data.split == "train"), np.flatnonzero(data.split == "test")
    ref, val = holdout_split(y[train])
    digest = data_digest(data.data)[:16]
    print(f"{os.path.basename(args.data)}: {len(y)} objects ({len(train)} train / {len(test)} test), "
          f"EPPF scaling {args.scaling!r}, {args.draws} draw(s)")

    rows = {}  # label -> list over draws of (holdout, loo, train->test)
    chosen = {o: [] for o in others}
    for draw in range(args.draws):
        mats = {}
        for name in ["eppf"] + others:
            mats[name], seconds = descriptor_matrix(name, data, args, draw, digest)
            if seconds:
                print(f"  draw {draw}: {name} computed in {seconds:.1f} s", flush=True)
        for name in ["eppf"] + others:
            rows.setdefault(name.upper(), []).append(scores(l1(mats[name]), y, train, test, ref, val))
        for other in others:
            pair = (mats["eppf"], mats[other])
            ytr = y[train]
            held = []
            for w in WEIGHT_GRID:
                U = union(pair, (w, 1 - w))[train]
                held.append(one_nn(U[ref], ytr[ref], U[val], ytr[val]))
            best = WEIGHT_GRID[int(np.argmax(held))]
            chosen[other].append(best)
            shown = set(SHOWN_WEIGHTS) | {best} | ({preset_weight()} if other == "gasd" else set())
            for w in sorted(shown):
                label = f"EPPF+{other.upper()} w={w:g}"
                rows.setdefault(label, []).append(scores(union(pair, (w, 1 - w)), y, train, test, ref, val))
            rows.setdefault(f"EPPF+{other.upper()} chosen", []).append(
                scores(union(pair, (best, 1 - best)), y, train, test, ref, val))

    check_union(data, args, mats, others, chosen)
    print()
    print("| descriptor | held-out train 1-NN | LOO 1-NN (whole set) | train -> test 1-NN |")
    print("| --- | ---: | ---: | ---: |")
    for label, vals in rows.items():
        if label.endswith("chosen"):
            continue
        if len(vals) != args.draws:  # a weight chosen in some draws only
            continue
        v = 100 * np.asarray(vals).mean(axis=0)
        print(f"| {label} | {v[0]:.2f}% | {v[1]:.2f}% | {v[2]:.2f}% |")
    for other in others:
        v = 100 * np.asarray(rows[f"EPPF+{other.upper()} chosen"]).mean(axis=0)
        ws = ", ".join(f"{w:g}" for w in chosen[other])
        print(f"| EPPF+{other.upper()}, w chosen on train ({ws}) | {v[0]:.2f}% | {v[1]:.2f}% | {v[2]:.2f}% |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
