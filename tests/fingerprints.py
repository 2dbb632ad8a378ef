"""Fingerprints of eppf's outputs on the built-in shapes, for the output-equivalence test.

``python tests/fingerprints.py --write tests/data/fingerprints.json`` records a
fingerprint of every public computation below (descriptors, normals,
matching, metrics, preprocessing, the networks' predictions, the experiments'
tables) for fixed inputs and seeds; ``tests/test_equivalence.py`` recomputes
them and compares. Each output is compared as its reproducibility class (the
documentation's reproducibility page) promises, so the references hold on
every CPU, whichever machine recorded them:

- class (a), eppf's compiled kernels (descriptors, normals): the SHA-256 of
  the bits (:func:`_digest`), equal on every CPU, SIMD level and thread count;
- class (b), computations whose last bits come from NumPy's SIMD dispatch,
  BLAS, LAPACK or torch's kernels (matching distances, preprocessing, network
  probabilities): values within a stated tolerance (:func:`_close`,
  :func:`_approx`);
- class (c), labels and neighbours: digests (the inputs have no ties within
  the class-(b) tolerance).

The inputs are the built-in shapes rounded to float32: ``make_shapes`` itself
is NumPy and BLAS arithmetic (class (b): its coordinates move by an ulp from
one CPU to another), and the rounding gives every CPU the same input bits.

Only public names are used (``eppf.X``, ``eppf.preprocessing.X``, ...), so the
same script runs on old and new layouts.
"""

import argparse
import hashlib
import json
import platform
import sys
import tempfile

import numpy as np


def _digest(value):
    """SHA-256 of an array (dtype, shape and bytes) or of a JSON-able value."""
    h = hashlib.sha256()
    if isinstance(value, np.ndarray):
        arr = np.ascontiguousarray(value)
        h.update(str(arr.dtype).encode())
        h.update(str(arr.shape).encode())
        if arr.dtype == object:
            h.update(json.dumps([str(v) for v in arr.ravel()]).encode())
        else:
            h.update(arr.tobytes())
    else:
        h.update(json.dumps(value, sort_keys=True, default=str).encode())
    return h.hexdigest()


#: Tolerance of the recorded network probabilities: about 8x the largest change
#: seen between torch's CPU kernel choices, 4x below the change a 10% different
#: learning rate makes to the one-epoch PointNet (7.7e-4).
PROBA_ATOL = 2e-4

#: Where the recorded network probabilities hold: torch's x86-64 kernels agree within
#: PROBA_ATOL after training; its aarch64 kernels sum in other orders, and two epochs of
#: training on 40 objects amplify that beyond the tolerance (labels included), so the
#: documentation promises the networks' class (b) on x86-64 only.
NETWORK_MACHINES = ("x86_64", "amd64")


def networks_compared():
    """Whether this machine's network fingerprints are compared with the recorded ones."""
    return platform.machine().lower() in NETWORK_MACHINES


#: Tolerance of class-(b) outputs, relative to the output's scale: the largest
#: change seen between CPUs' NumPy/BLAS kernels is about 1e-14 of it
#: (symmetric KL distances, OpenBLAS's Haswell against its SkylakeX kernels),
#: the worst case of a 1,200-term float64 sum about 1e-13. The weighted sums of a
#: large output then catch a change of one value by about 1e-8 of its scale.
RTOL = 1e-11

#: How many values of a large class-(b) output are recorded as they are, and
#: how many weighted sums of all its values.
N_PROBES, N_SUMS = 256, 16


def _approx(values):
    """A fingerprint compared within PROBA_ATOL instead of bit for bit."""
    return {"values": np.round(np.asarray(values, dtype=float), 6).tolist(), "atol": PROBA_ATOL}


def _weights(n):
    """N_SUMS fixed weight vectors in [-1, 1) of length n (the same bits on every CPU)."""
    return np.random.Generator(np.random.PCG64(20261204)).uniform(-1.0, 1.0, size=(N_SUMS, n))


def _close(values, rtol=RTOL):
    """A class-(b) fingerprint: values compared within ``rtol`` of the output's scale.

    Small outputs are recorded whole; larger ones by N_PROBES values at fixed
    places and N_SUMS weighted sums of all values (with the magnitudes the sums'
    rounding is measured against), so that a change anywhere moves a sum.
    """
    arr = np.asarray(values, dtype=float)
    flat = arr.ravel()
    out = {"kind": "close", "rtol": rtol, "shape": list(arr.shape),
           "scale": float(np.abs(flat).max()) if flat.size else 0.0}
    if flat.size <= N_PROBES:
        out["values"] = flat.tolist()
        return out
    w = _weights(flat.size)
    out["probes"] = flat[np.linspace(0, flat.size - 1, N_PROBES).astype(np.int64)].tolist()
    out["sums"] = (w * flat).sum(axis=1).tolist()
    out["magnitudes"] = (np.abs(w) * np.abs(flat)).sum(axis=1).tolist()
    return out


def _regions(values):
    """OUR-CVFH's fingerprint: per-object L1 distances within 0.5, on average within 0.1.

    Its clusters and reference frames come from LAPACK and NumPy's SIMD code,
    and a change in the last bit can move a point across a region or flip a
    frame's sign: between CPUs objects moved by up to 0.16 (L1, of a total of
    1), 0.02 on average. A different descriptor moves them by about 1.
    """
    arr = np.asarray(values, dtype=float)
    return {"kind": "regions", "shape": list(arr.shape), "values": np.round(arr, 6).tolist(),
            "max_l1": 0.5, "mean_l1": 0.1}


def matches(now, ref):
    """Whether a fingerprint equals the recorded one (a digest exactly, the others within their tolerance)."""
    if not isinstance(ref, dict):
        return now == ref
    if not isinstance(now, dict) or now.get("kind") != ref.get("kind"):
        return False
    kind = ref.get("kind")
    if kind is None:  # network probabilities
        a, b = np.asarray(now["values"]), np.asarray(ref["values"])
        return a.shape == b.shape and bool(np.all(np.abs(a - b) <= ref["atol"]))
    if now["shape"] != ref["shape"]:
        return False
    if kind == "regions":
        l1 = np.abs(np.asarray(now["values"]) - np.asarray(ref["values"])).reshape(len(ref["values"]), -1).sum(axis=1)
        return bool(l1.max(initial=0.0) <= ref["max_l1"] and l1.mean() <= ref["mean_l1"]) if l1.size else True
    tol = ref["rtol"] * ref["scale"]
    if "values" in ref:
        return bool(np.all(np.abs(np.asarray(now["values"]) - np.asarray(ref["values"])) <= tol))
    probes_ok = np.all(np.abs(np.asarray(now["probes"]) - np.asarray(ref["probes"])) <= tol)
    sums_ok = np.all(np.abs(np.asarray(now["sums"]) - np.asarray(ref["sums"])) <= ref["rtol"] * np.asarray(ref["magnitudes"]))
    return bool(probes_ok and sums_ok)


def _shapes(n=60):
    from eppf.datasets import make_shapes

    shapes = make_shapes(random_state=0)
    rng = np.random.RandomState(0)
    pick = np.sort(rng.choice(len(shapes.data), size=n, replace=False))
    # float32 values: the same input bits on every CPU (see the module's docstring)
    clouds = [shapes.data[k].astype(np.float32).astype(np.float64) for k in pick]
    return clouds, np.asarray(shapes.target)[pick], shapes


def descriptor_fingerprints():
    """Descriptors, normals and preprocessing outputs."""
    import eppf
    from eppf import preprocessing

    clouds, y, _ = _shapes()
    out = {}
    out["inputs"] = _digest(np.vstack(clouds))  # the same bits on every CPU, or nothing below can be
    normals = [eppf.estimate_normals(c, n_neighbors=20) for c in clouds[:10]]
    out["estimate_normals_k20"] = _digest(np.vstack(normals))
    out["estimate_normals_k10_viewpoint"] = _digest(
        np.vstack([eppf.estimate_normals(c, n_neighbors=10, orientation="centroid") for c in clouds[:5]])
    )
    with_normals = [np.hstack([c, n]) for c, n in zip(clouds[:10], normals)]
    for scaling in ("fit", "object", "none"):
        est = eppf.EPPFTransformer(n_pairs=3000, scaling=scaling, random_state=0)
        out[f"eppf_{scaling}"] = _digest(est.fit_transform(clouds))
    out["eppf_given_normals"] = _digest(eppf.EPPFTransformer(n_pairs=3000, random_state=1).fit_transform(with_normals))
    out["eppf_short_grid32"] = _digest(
        eppf.EPPFTransformer(n_pairs=2000, n_bins=(15, 3, 4, 3), grid_size=32, random_state=2).fit_transform(clouds)
    )
    out["eppf_functions"] = _digest(
        eppf.EPPFTransformer(n_pairs=2000, functions=("distance", "occupancy"), random_state=3).fit_transform(clouds)
    )
    out["esf"] = _digest(eppf.ESFTransformer(n_triplets=3000, random_state=0).fit_transform(clouds))
    out["wahl"] = _digest(eppf.WahlTransformer(n_pairs=3000, random_state=0).fit_transform(clouds))
    out["ourcvfh"] = _regions(eppf.OURCVFHTransformer().fit_transform(clouds[:20]))
    # PCL's global descriptors, normals given: class (a)
    for name, est in (("vfh", eppf.VFHTransformer()), ("gasd", eppf.GASDTransformer()),
                      ("grsd", eppf.GRSDTransformer()), ("cvfh", eppf.CVFHTransformer())):
        out[name] = _digest(est.fit_transform(with_normals))
    out["descriptor_pool"] = _digest(
        eppf.descriptor_pool(eppf.EPPFTransformer(n_pairs=1000), clouds[:12], 3, random_state=0)
    )
    for name, est in [
        ("noise", preprocessing.GaussianNoise(sigma=0.02, random_state=0)),
        ("occlusion", preprocessing.Occlusion(random_state=0)),
        ("dropout", preprocessing.RandomDropout(random_state=0)),
        ("rotation", preprocessing.RandomRotation(random_state=0)),
        ("scaling", preprocessing.RandomScaling(random_state=0)),
        ("resampler", preprocessing.Resampler(n_points=256, random_state=0)),
    ]:
        res = est.fit_transform(clouds[:8])
        out[f"preprocessing_{name}"] = _close(np.vstack(res))
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    out["sample_mesh"] = _close(preprocessing.sample_mesh(verts, faces, n_points=500, random_state=0))
    return out


def matching_fingerprints():
    """KL matching, metrics and the experiments' accuracy tables."""
    import eppf
    from eppf.metrics import leave_one_out_retrieval, retrieval_scores

    clouds, y, _ = _shapes()
    X = eppf.EPPFTransformer(n_pairs=3000, random_state=0).fit_transform(clouds)
    out = {}
    out["symmetric_kl"] = _close(eppf.symmetric_kl_distances(X[:30], X[30:]))
    knn = eppf.KLNearestNeighbors().fit(X[:40], y[:40])
    out["kl_predict"] = _digest(knn.predict(X[40:]))
    dist, idx = knn.kneighbors(X[40:], n_neighbors=3)
    out["kl_kneighbors_distances"] = _close(dist)
    out["kl_kneighbors_indices"] = _digest(idx)
    res = leave_one_out_retrieval(X, y)
    out["loo_retrieval"] = _digest(res if isinstance(res, np.ndarray) else json.loads(json.dumps(res, default=str)))
    out["retrieval_scores"] = _digest(retrieval_scores(y, np.roll(y, 1)))
    return out


def torch_release():
    """The running torch's release, "major.minor" (the network fingerprints hold within one)."""
    import torch

    return ".".join(torch.__version__.split("+")[0].split(".")[:2])


def network_fingerprints():
    """Predictions of tiny EPPF networks and PointNet (label digests, probabilities as values)."""
    import torch

    import eppf

    torch.set_num_threads(1)
    clouds, y, _ = _shapes()
    X = eppf.EPPFTransformer(n_pairs=3000, random_state=0).fit_transform(clouds)
    out = {}
    for conv in ("2d", "3d", "4d"):
        # float32 explicitly: the default "auto" trains in bfloat16 on CPUs that have it
        clf = eppf.EPPF4DClassifier(conv=conv, max_epochs=2, early_stopping=False, n_hidden=32,
                                    filters=(4, 4, 4), precision="float32", n_jobs=1, random_state=0,
                                    verbose=0)
        clf.fit(X[:40], y[:40])
        proba = clf.predict_proba(X[40:])
        out[f"cnn_{conv}_labels"] = _digest(clf.predict(X[40:]))
        out[f"cnn_{conv}_proba"] = _approx(proba)
    pn = eppf.PointNetClassifier(n_points=128, max_epochs=1, early_stopping=False, n_jobs=1, random_state=0,
                                 verbose=0)
    pn.fit(clouds[:30], y[:30])
    out["pointnet_labels"] = _digest(pn.predict(clouds[30:40]))
    out["pointnet_proba"] = _approx(pn.predict_proba(clouds[30:40]))
    out["torch"] = torch_release()  # the release these were recorded with: another's kernels train otherwise
    return out


def experiment_fingerprints():
    """The accuracy columns of the quick retrieval and ablation experiments on the built-in set."""
    import csv
    import os

    from eppf.experiments import run_ablation, run_retrieval

    out = {}
    for name, run in (("retrieval", run_retrieval), ("ablation", run_ablation)):
        with tempfile.TemporaryDirectory() as tmp:
            # the descriptors of 0.1.0 (the registry has grown since; new columns are additions) but
            # OUR-CVFH, whose accuracy on these 30 objects moves by one object between CPUs (its
            # fingerprint above says why)
            extra = {"descriptors": ("esf", "wahl", "eppf_short", "eppf")} if name == "retrieval" else {}
            run("builtin", out=tmp, quick=True, verbose=False, n_jobs=1, **extra)
            csvs = sorted(f for f in os.listdir(tmp) if f.endswith(".csv"))
            rows = []
            for f in csvs:
                with open(os.path.join(tmp, f), newline="") as fh:
                    for row in csv.DictReader(fh):
                        rows.append({k: v for k, v in row.items() if "time" not in k and "ms" not in k
                                     and "seconds" not in k})
            out[f"experiment_{name}"] = _digest(rows)
    return out


GROUPS = {
    "descriptors": descriptor_fingerprints,
    "matching": matching_fingerprints,
    "networks": network_fingerprints,
    "experiments": experiment_fingerprints,
}


def compute(groups=tuple(GROUPS)):
    """All fingerprints of the named groups, as one flat dict."""
    out = {}
    for g in groups:
        out.update({f"{g}.{k}": v for k, v in GROUPS[g]().items()})
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", metavar="JSON", help="write the fingerprints to this file")
    parser.add_argument("--check", metavar="JSON", help="compare with the fingerprints in this file")
    args = parser.parse_args(argv)
    fp = compute()
    if args.write:
        with open(args.write, "w") as fh:
            json.dump(fp, fh, indent=1, sort_keys=True)
            fh.write("\n")
    if args.check:
        with open(args.check) as fh:
            ref = json.load(fh)
        compared = {k: v for k, v in ref.items() if networks_compared() or not k.startswith("networks.")}
        bad = sorted(k for k in compared if not matches(fp.get(k), compared[k]))
        for k in bad:
            print(f"differs: {k}")
        print(f"{len(compared) - len(bad)} of {len(compared)} fingerprints equal")
        if len(compared) < len(ref):
            print(f"not compared on {platform.machine()}: {', '.join(sorted(set(ref) - set(compared)))} (the "
                  "networks' probabilities are promised on x86-64 only)")
        return 1 if bad else 0
    if not args.write:
        json.dump(fp, sys.stdout, indent=1, sort_keys=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
