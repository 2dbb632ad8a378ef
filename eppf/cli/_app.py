"""The ``eppf`` command line.

``eppf`` (or ``eppf run``, or ``python -m eppf``) runs the main job: EPPF
descriptors of a data set (the built-in synthetic shapes unless ``--data``
names a ``.npz`` file), leave-one-out retrieval by symmetric KL divergence,
and a train/test classification, printed as a table.

Subcommands: ``describe`` (descriptors of files, folders or a ``.npz`` data
set to ``.npy``/``.npz``), ``retrieve`` (top-k database neighbours by
symmetric KL divergence), ``train`` (fit and save a pipeline as a safe model file),
``predict`` (classify files with a saved model), ``evaluate`` (leave-one-out
retrieval and a saved model's test metrics) and ``bench`` (descriptor speed).
Bad input ends with a one-line ``eppf: error: ...`` message and exit code 1;
Ctrl-C ends with ``eppf: interrupted`` and exit code 130. Every output file is
written to a temporary file first and renamed into place when complete.
"""

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..registry import DESCRIPTORS as REGISTRY
from ..utils._atomic import atomic_write

__all__ = ["build_parser", "load_model", "main", "make_pipeline_from_args", "run_main_job"]


def _positive_int(text):
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def _n_jobs(text):
    value = int(text)
    if value == 0:
        raise argparse.ArgumentTypeError("0 has no meaning; use a positive count or -1 for all cores")
    return value


def build_parser():
    """The argument parser of the ``eppf`` command."""
    parser = argparse.ArgumentParser(
        prog="eppf",
        description="Noise-resistant 3D object retrieval and classification with the EPPF descriptor.",
    )
    sub = parser.add_subparsers(dest="command")
    run = sub.add_parser(
        "run",
        help="main job: descriptors, leave-one-out retrieval and train/test classification (the default)",
        description="Compute EPPF descriptors of a data set, run leave-one-out 1-NN retrieval by symmetric "
        "KL divergence and a train/test classification, and print the metrics.",
    )
    _add_run_arguments(run)
    build_subcommands(sub)
    _add_run_arguments(parser, defaults_only=True)
    return parser


def _add_run_arguments(parser, defaults_only=False):
    kw = {"help": argparse.SUPPRESS} if defaults_only else {}

    def h(text):
        return kw.get("help", text)

    parser.add_argument("--data", metavar="FILE.npz|FOLDER", default=None,
                        help=h("a .npz of point clouds (points, offsets, labels, class_names[, split]) or a "
                               "folder with one subfolder of files per class; default: the built-in "
                               "synthetic shapes"))
    parser.add_argument("--scaling", choices=["fit", "object", "none"], default=None,
                        help=h("descriptor scaling (default: 'fit', the paper's data-set scale; use 'object' "
                               "for data in mixed units such as raw CAD files)"))
    parser.add_argument("--n-pairs", type=_positive_int, default=20000, help=h("point pairs per object"))
    parser.add_argument("--n-bins", type=_positive_int, nargs=4, default=(20, 4, 5, 3),
                        metavar=("F1", "F2", "F3", "F4"), help=h("bins of the four functions"))
    parser.add_argument("--n-neighbors", type=_positive_int, default=None,
                        help=h("neighbours for normal estimation (default: the transformer's)"))
    parser.add_argument("--repeats", type=_positive_int, default=1,
                        help=h("descriptor draws for retrieval mean and std (the paper uses 10)"))
    parser.add_argument("--test-size", type=float, default=0.25,
                        help=h("test fraction when the data has no split"))
    parser.add_argument("--n-jobs", type=_n_jobs, default=-1, help=h("threads (-1: all cores)"))
    parser.add_argument("--random-state", type=int, default=0, help=h("seed of everything random"))
    parser.add_argument("--no-progress", action="store_true", help=h("hide progress bars"))


def _load(args):
    from sklearn.model_selection import train_test_split

    if args.data is None:
        from ..datasets import make_shapes

        bunch = make_shapes(random_state=args.random_state)
        name = "built-in synthetic shapes"
    else:
        bunch = _load_labelled(args.data)
        name = args.data
    y = np.asarray(bunch.target)
    split = getattr(bunch, "split", None)
    if split is None:
        idx = np.arange(len(y))
        train, test = train_test_split(idx, test_size=args.test_size, stratify=y, random_state=args.random_state)
        split = np.full(len(y), "train", dtype=object)
        split[test] = "test"
    return name, bunch.data, y, np.asarray(bunch.target_names), np.asarray(split)


def run_main_job(args, out=None):
    """Run the main job for parsed arguments and print its report.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf run`` arguments.
    out : file-like, default=None
        Where the report goes (standard output by default).

    Returns
    -------
    report : dict
        The measured metrics and timings.
    """
    from .. import EPPFTransformer, KLNearestNeighbors
    from ..metrics import leave_one_out_retrieval, retrieval_scores

    out = out or sys.stdout
    name, clouds, y, class_names, split = _load(args)
    scaling = args.scaling or "fit"
    params = dict(n_bins=tuple(args.n_bins), n_pairs=args.n_pairs, scaling=scaling, n_jobs=args.n_jobs,
                  verbose=0 if args.no_progress else 1)
    if args.n_neighbors is not None:
        params["n_neighbors"] = args.n_neighbors
    n = len(clouds)
    sizes = np.array([len(c) for c in clouds])
    print(f"eppf: {name}: {n} objects, {len(class_names)} classes, {sizes.min()}-{sizes.max()} points "
          f"(median {int(np.median(sizes))})", file=out)

    rng = np.random.RandomState(args.random_state)
    loo, times, X_first = [], [], None
    for r in range(args.repeats):
        est = EPPFTransformer(random_state=rng.randint(2**31 - 1), **params)
        t0 = time.perf_counter()
        X = est.fit_transform(clouds)
        times.append(time.perf_counter() - t0)
        X_first = X if X_first is None else X_first
        t0 = time.perf_counter()
        pred = leave_one_out_retrieval(X, y)
        loo_time = time.perf_counter() - t0
        loo.append(retrieval_scores(y, pred))

    train, test = split == "train", split == "test"
    clf = KLNearestNeighbors().fit(X_first[train], y[train])
    test_scores = retrieval_scores(y[test], clf.predict(X_first[test]))

    metrics = ["total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1"]
    labels = ["Total accuracy (%)", "Mean class accuracy (%)", "Macro precision (%)", "Macro recall (%)",
              "Macro F1 (%)"]
    col1 = f"Leave-one-out retrieval ({n})" + (f", {args.repeats} draws" if args.repeats > 1 else "")
    col2 = f"Train/test 1-NN ({train.sum()}/{test.sum()})"
    w0 = max(len(s) for s in labels)
    print("", file=out)
    print(f"{'Metric':<{w0}} | {col1:>{len(col1)}} | {col2}", file=out)
    print(f"{'-' * w0}-+-{'-' * len(col1)}-+-{'-' * len(col2)}", file=out)
    for key, label in zip(metrics, labels):
        vals = 100 * np.array([s[key] for s in loo])
        cell = f"{vals.mean():.2f}" + (f" (±{vals.std():.2f})" if args.repeats > 1 else "")
        print(f"{label:<{w0}} | {cell:>{len(col1)}} | {100 * test_scores[key]:>{len(col2)}.2f}", file=out)
    ms = 1e3 * np.mean(times) / n
    print("", file=out)
    print(f"Descriptor: {X_first.shape[1]} bins, {args.n_pairs} pairs, scaling={scaling}; "
          f"{ms:.2f} ms per object (normal estimation included, n_jobs={args.n_jobs}); "
          f"leave-one-out search {loo_time:.2f} s", file=out)
    return {"retrieval": loo, "classification": test_scores, "ms_per_object": ms, "loo_seconds": loo_time}


# ---------------------------------------------------------------------------
# Subcommands: describe, retrieve, train, predict, evaluate, bench
# ---------------------------------------------------------------------------

#: Extensions read as point clouds when a folder is given.
CLOUD_EXTENSIONS = (".ply", ".pcd", ".xyz", ".txt", ".csv", ".pts", ".npy", ".off", ".obj")

DESCRIPTORS = tuple(REGISTRY)

_MODEL_FORMAT = "eppf-model"

_MODEL_HELP = ("a model saved by 'eppf train' (safe to load from anyone: the model format cannot run code; "
               "pickled eppf 0.1 models need --trust)")
_TRUST_HELP = ("load a pickled (eppf 0.1, joblib) model file; pickles can run any code while loading, so use "
               "this only for files you made yourself")


class _Progress:
    """A tqdm bar, or a plain iterator when progress is off or tqdm is missing."""

    def __init__(self, iterable, enabled, desc):
        self.iterable, self.enabled, self.desc = iterable, enabled, desc

    def __iter__(self):
        if self.enabled:
            try:
                from tqdm.auto import tqdm
            except ImportError:  # pragma: no cover
                return iter(self.iterable)
            return iter(tqdm(self.iterable, desc=self.desc, file=sys.stderr, leave=False))
        return iter(self.iterable)


def _add_common(parser, n_pairs=True, scaling=True):
    if n_pairs:
        parser.add_argument("--n-pairs", type=_positive_int, default=20000,
                            help="point pairs (EPPF, Wahl) or triplets (ESF) per object")
    if scaling:
        parser.add_argument("--scaling", choices=["fit", "object", "none"], default=None,
                            help="descriptor scaling: 'fit' (the paper's data-set scale, EPPF's default), "
                                 "'object' (each object to unit size; for files in mixed units) or 'none'; "
                                 "other descriptors keep their own default unless this is given")
    parser.add_argument("--n-jobs", type=_n_jobs, default=-1, help="threads (-1: all cores)")
    parser.add_argument("--random-state", type=int, default=0, help="seed of everything random")
    parser.add_argument("--no-progress", action="store_true", help="hide progress bars")


def _add_data_source(parser):
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--data", metavar="FILE.npz|FOLDER",
                       help="a .npz data set (points, offsets, labels, class_names[, split][, ids]) or a folder "
                            "with one subfolder of point cloud or mesh files per class (optionally inside "
                            "train/ and test/)")
    group.add_argument("--built-in", action="store_true", help="the built-in synthetic shapes")


def build_subcommands(sub):
    """Add the ``describe``, ``retrieve``, ``train``, ``predict``, ``evaluate`` and ``bench`` parsers.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``eppf`` parser.
    """
    p = sub.add_parser("describe", help="compute descriptors of point cloud files, a folder or a .npz data set",
                       description="Compute descriptors of point clouds and save them to .npy (the matrix) or "
                                   ".npz (with object ids, labels when known, and the descriptor's parameters).")
    p.add_argument("inputs", nargs="+", help="point cloud files (PLY, PCD, XYZ, NPY, OFF, OBJ...), folders "
                                             "(searched recursively) or one .npz data set")
    p.add_argument("-o", "--output", required=True, help="output file, .npy or .npz")
    p.add_argument("--descriptor", choices=DESCRIPTORS, default="eppf", help="which descriptor (default: eppf)")
    _add_common(p)

    p = sub.add_parser("retrieve", help="top-k nearest database objects of query objects by symmetric KL",
                       description="Find the k nearest objects of a descriptor database (a .npz written by "
                                   "'eppf describe') for each query, by symmetric KL divergence.")
    p.add_argument("queries", nargs="*", help="query point cloud files or folders (described with the "
                                              "database's descriptor and parameters)")
    p.add_argument("--database", required=True, metavar="DB.npz", help="descriptors from 'eppf describe'")
    p.add_argument("--query-descriptors", metavar="FILE", help="precomputed query descriptors (.npy or .npz) "
                                                               "instead of files")
    p.add_argument("-k", "--top-k", type=_positive_int, default=5, help="neighbours per query (default: 5)")
    p.add_argument("-o", "--output", help="write a CSV file instead of printing a table")
    _add_common(p, n_pairs=False, scaling=False)

    p = sub.add_parser("train", help="fit a descriptor + classifier pipeline on a data set and save it",
                       description="Fit a Pipeline (EPPF descriptor + 1-NN by symmetric KL, or the 4D CNN) on "
                                   "the training objects of a data set and save it as a model file (a zip of "
                                   "JSON and arrays that loading cannot turn into code), together with its "
                                   "parameters and the eppf version.")
    _add_data_source(p)
    p.add_argument("-o", "--output", required=True, metavar="MODEL.joblib", help="where to save the model")
    p.add_argument("--classifier", choices=["knn", "cnn"], default="knn",
                   help="'knn': KLNearestNeighbors (default); 'cnn': EPPF4DClassifier")
    p.add_argument("--n-bins", type=_positive_int, nargs=4, default=(20, 4, 5, 3), metavar=("F1", "F2", "F3", "F4"),
                   help="bins of the four functions")
    p.add_argument("--n-neighbors", type=_positive_int, default=1, help="neighbours of the KL classifier")
    p.add_argument("--max-epochs", type=_positive_int, default=100, help="CNN training epochs")
    p.add_argument("--precision", choices=["float32", "bfloat16"], default="float32",
                   help="CNN arithmetic: 'bfloat16' is mixed precision, faster on CPUs with native bfloat16 "
                        "(AVX512_BF16 or AMX), slower elsewhere")
    p.add_argument("--all", action="store_true", help="train on every object, ignoring the train/test split")
    p.add_argument("--test-size", type=float, default=0.25, help="test fraction when the data has no split")
    _add_common(p)

    p = sub.add_parser("predict", help="classify point cloud files with a saved model",
                       description="Load a model saved by 'eppf train' and classify point cloud files. Model "
                                   "files are safe to load; old pickled models need --trust.")
    p.add_argument("inputs", nargs="+", help="point cloud files or folders (searched recursively)")
    p.add_argument("--model", required=True, metavar="MODEL.joblib", help=_MODEL_HELP)
    p.add_argument("--trust", action="store_true", help=_TRUST_HELP)
    p.add_argument("-o", "--output", help="write a CSV file instead of printing a table")
    p.add_argument("--n-jobs", type=_n_jobs, default=None, help="threads (default: the model's)")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")

    p = sub.add_parser("evaluate", help="leave-one-out retrieval metrics and/or a saved model's test metrics",
                       description="Leave-one-out 1-NN retrieval by symmetric KL divergence on EPPF "
                                   "descriptors of a data set, and with --model, the saved model's metrics on "
                                   "the data set's test split (every object when there is no split).")
    _add_data_source(p)
    p.add_argument("--model", metavar="MODEL.joblib", help="also evaluate this saved model; " + _MODEL_HELP)
    p.add_argument("--trust", action="store_true", help=_TRUST_HELP)
    p.add_argument("--no-retrieval", action="store_true", help="skip the leave-one-out retrieval")
    p.add_argument("-o", "--output", help="also write the metrics to a CSV file")
    _add_common(p)

    p = sub.add_parser("bench", help="speed of the EPPF descriptor on the built-in data (ms per object)",
                       description="Time the EPPF descriptor (normal estimation included) on the built-in "
                                   "synthetic shapes and print milliseconds per object.")
    p.add_argument("--n-pairs", type=_positive_int, nargs="+", default=[5000, 20000], help="pair counts to time")
    p.add_argument("--n-per-class", type=_positive_int, default=10, help="objects per class (10 classes)")
    p.add_argument("--n-points", type=_positive_int, default=1024, help="points per object")
    p.add_argument("--repeats", type=_positive_int, default=3, help="timings per row (the best is shown)")
    p.add_argument("--n-jobs", type=_n_jobs, nargs="+", default=[-1], help="thread counts to time")
    p.add_argument("--random-state", type=int, default=0, help="seed of everything random")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")

    p = sub.add_parser("experiment", add_help=False,
                       help="the paper's experiments (retrieval, classification, ablation, noise, runtime): "
                            "table, CSV and plot; 'eppf experiment --help' for their options",
                       description="Forwarded to python -m eppf.experiments.")
    p.add_argument("experiment_args", nargs=argparse.REMAINDER)


def _find_files(inputs):
    files = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found = sorted(f for f in path.rglob("*") if f.is_file() and f.suffix.lower() in CLOUD_EXTENSIONS)
            if not found:
                raise ValueError(f"no point cloud files ({', '.join(CLOUD_EXTENSIONS)}) in folder {item}")
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            raise FileNotFoundError(f"no such file or folder: {item}")
    return files


def _read_clouds(inputs, progress):
    """Read files/folders or one .npz data set: (clouds, ids, labels or None, class_names or None)."""
    from ..io import read_point_cloud

    if len(inputs) == 1 and str(inputs[0]).lower().endswith(".npz") and Path(inputs[0]).is_file():
        from ..datasets import load_npz

        try:
            with np.load(inputs[0], allow_pickle=False) as f:
                is_data_set = "offsets" in f.files
        except Exception as exc:  # not a zip, pickled, truncated...
            raise ValueError(f"cannot read {inputs[0]} as .npz: {type(exc).__name__}") from None
        if not is_data_set:  # a single point cloud stored as .npz
            return [np.asarray(read_point_cloud(inputs[0], normals=False), dtype=np.float64)[:, :3]], \
                np.array([str(inputs[0])]), None, None
        bunch = load_npz(inputs[0])
        ids = bunch.ids if bunch.ids is not None else [str(i) for i in range(len(bunch.data))]
        return list(bunch.data), np.asarray(ids, dtype=str), np.asarray(bunch.target), np.asarray(bunch.target_names)
    files = _find_files(inputs)
    clouds = []
    for f in _Progress(files, progress, "reading"):
        try:
            cloud = read_point_cloud(f, normals=False)
        except (ValueError, TypeError, OSError) as exc:
            msg = str(exc)
            raise ValueError(msg if str(f) in msg else f"{f}: {msg}") from None
        clouds.append(np.asarray(cloud, dtype=np.float64)[:, :3])
    return clouds, np.array([str(f) for f in files]), None, None


def _make_transformer(name, params):
    params = dict(params)
    return REGISTRY[name].make(n_samples=params.pop("n_pairs", None), **params)


def _descriptor_params(args, progress):
    params = dict(n_pairs=args.n_pairs, n_jobs=args.n_jobs, random_state=args.random_state,
                  verbose=1 if progress else 0)
    if args.scaling is not None:
        params["scaling"] = args.scaling
    return params


def run_describe(args, out=None):
    """Run ``eppf describe``: compute descriptors of files and save them.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf describe`` arguments.
    out : file-like, default=None
        Where the summary line goes (standard output by default).

    Returns
    -------
    X : ndarray of shape (n_objects, n_features)
        The descriptors that were saved.
    """
    out = out or sys.stdout
    output = str(args.output)
    if not output.lower().endswith((".npy", ".npz")):
        raise ValueError(f"--output must end in .npy or .npz, got {output}")
    progress = not args.no_progress
    clouds, ids, labels, class_names = _read_clouds(args.inputs, progress)
    est = _make_transformer(args.descriptor, _descriptor_params(args, progress))
    t0 = time.perf_counter()
    X = est.fit_transform(clouds)
    seconds = time.perf_counter() - t0
    if output.lower().endswith(".npy"):
        with atomic_write(output) as fh:
            np.save(fh, X)
    else:
        params = {k: v for k, v in est.get_params().items() if k not in ("verbose", "n_jobs")}
        arrays = dict(descriptors=X, ids=ids, descriptor=np.array(args.descriptor),
                      params=np.array(json.dumps(params, default=list)),
                      scale=np.array(np.nan if getattr(est, "scale_", None) is None else est.scale_))
        if labels is not None:
            arrays.update(labels=labels, class_names=class_names)
        with atomic_write(output) as fh:
            np.savez(fh, **arrays)
    print(f"eppf: {len(X)} {args.descriptor} descriptors of {X.shape[1]} bins -> {output} "
          f"({1e3 * seconds / len(X):.2f} ms per object)", file=out)
    return X


def _load_descriptors(path, owner):
    path = str(path)
    if not Path(path).is_file():
        raise FileNotFoundError(f"no such file: {path}")
    try:
        if path.lower().endswith(".npy"):
            return dict(descriptors=np.load(path, allow_pickle=False))
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
    except Exception as exc:
        raise ValueError(f"cannot read descriptors from {path}: {exc}") from None
    if "descriptors" not in data:
        raise ValueError(f"{path} has no 'descriptors' array; write it with 'eppf describe -o {owner}.npz'")
    return data


def run_retrieve(args, out=None):
    """Run ``eppf retrieve``: top-k database neighbours of each query by symmetric KL divergence.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf retrieve`` arguments.
    out : file-like, default=None
        Where the table goes (standard output by default).

    Returns
    -------
    rows : list of tuple
        ``(query, rank, match_id, match_label, distance)`` for every query and rank.
    """
    from .. import symmetric_kl_distances

    out = out or sys.stdout
    db = _load_descriptors(args.database, "database")
    X_db = np.asarray(db["descriptors"], dtype=np.float64)
    if X_db.ndim != 2 or len(X_db) == 0:
        raise ValueError(f"database descriptors must be a non-empty 2D array, got shape {X_db.shape}")
    db_ids = db.get("ids", np.array([str(i) for i in range(len(X_db))]))
    if len(db_ids) != len(X_db):
        raise ValueError(f"{args.database} has {len(db_ids)} ids for {len(X_db)} descriptors")
    db_labels = None
    if "labels" in db and "class_names" in db:
        db_labels = np.asarray(db["class_names"])[np.asarray(db["labels"])]
    if (args.query_descriptors is None) == (not args.queries):
        raise ValueError("give query files or --query-descriptors (exactly one of the two)")
    if args.query_descriptors is not None:
        q = _load_descriptors(args.query_descriptors, "queries")
        X_q = np.atleast_2d(np.asarray(q["descriptors"], dtype=np.float64))
        q_ids = q.get("ids", np.array([str(i) for i in range(len(X_q))]))
    else:
        if "descriptor" not in db or "params" not in db:
            raise ValueError(f"{args.database} does not say how its descriptors were made; "
                             "pass --query-descriptors computed the same way")
        params = json.loads(str(db["params"]))
        params.update(n_jobs=args.n_jobs, verbose=0 if args.no_progress else 1)
        clouds, q_ids, _, _ = _read_clouds(args.queries, not args.no_progress)
        est = _make_transformer(str(db["descriptor"]), params)
        est.fit(clouds)
        if "scale" in db and np.isfinite(db["scale"]) and getattr(est, "scale_", None) is not None:
            est.scale_ = float(db["scale"])  # describe the queries in the database's units
        X_q = est.transform(clouds)
    if X_q.shape[1] != X_db.shape[1]:
        raise ValueError(f"queries have {X_q.shape[1]} bins but the database has {X_db.shape[1]}")
    D = symmetric_kl_distances(X_q, X_db, n_jobs=args.n_jobs)
    k = min(args.top_k, len(X_db))
    order = np.argsort(D, axis=1, kind="stable")[:, :k]
    rows = []
    for i in range(len(X_q)):
        for r, j in enumerate(order[i]):
            rows.append((str(q_ids[i]), r + 1, str(db_ids[j]), "" if db_labels is None else str(db_labels[j]),
                         float(D[i, j])))
    _emit(rows, ["query", "rank", "match", "label", "distance"], args.output, out)
    return rows


def _emit(rows, header, output, out):
    if output:
        with atomic_write(output, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            for row in rows:
                writer.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in row])
        print(f"eppf: {len(rows)} rows -> {output}", file=out)
        return
    cells = [[f"{v:.4f}" if isinstance(v, float) else str(v) for v in row] for row in rows]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, h in enumerate(header)]
    print(" | ".join(h.ljust(w) for h, w in zip(header, widths)), file=out)
    print("-+-".join("-" * w for w in widths), file=out)
    for c in cells:
        print(" | ".join(v.ljust(w) for v, w in zip(c, widths)), file=out)


def _load_labelled(path):
    """A labelled data set from a .npz file or a folder of class subfolders."""
    from ..datasets import load_folder, load_npz

    if Path(path).is_dir():
        return load_folder(path)
    return load_npz(path)


def _load_data(args):
    """(name, clouds, y, class_names, split or None, ids) of --data or --built-in."""
    if args.built_in:
        from ..datasets import make_shapes

        bunch = make_shapes(random_state=args.random_state)
        name = "built-in synthetic shapes"
    else:
        bunch = _load_labelled(args.data)
        name = args.data
    split = getattr(bunch, "split", None)
    ids = getattr(bunch, "ids", None)
    ids = np.array([str(i) for i in range(len(bunch.data))]) if ids is None else np.asarray(ids, dtype=str)
    return (name, list(bunch.data), np.asarray(bunch.target), np.asarray(bunch.target_names),
            None if split is None else np.asarray(split), ids)


def make_pipeline_from_args(args):
    """The Pipeline that ``eppf train`` fits for parsed arguments.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf train`` arguments.

    Returns
    -------
    pipeline : :class:`~sklearn.pipeline.Pipeline`
        An unfitted ``EPPFTransformer`` + classifier pipeline.
    """
    from sklearn.pipeline import Pipeline

    from .. import EPPF4DClassifier, EPPFTransformer, KLNearestNeighbors

    eppf = EPPFTransformer(n_bins=tuple(args.n_bins), n_pairs=args.n_pairs, scaling=args.scaling or "fit",
                           random_state=args.random_state, n_jobs=args.n_jobs,
                           verbose=0 if args.no_progress else 1)
    if args.classifier == "cnn":
        clf = EPPF4DClassifier(n_bins=tuple(args.n_bins), max_epochs=args.max_epochs,
                               precision=args.precision, random_state=args.random_state, n_jobs=None if args.n_jobs < 0 else args.n_jobs,
                               verbose=0)
    else:
        clf = KLNearestNeighbors(n_neighbors=args.n_neighbors, n_jobs=args.n_jobs)
    return Pipeline([("descriptor", eppf), ("classifier", clf)])


def run_train(args, out=None):
    """Run ``eppf train``: fit a pipeline on a data set and save it as a model file.

    The saved object is a dict with ``"format"`` (``"eppf-model"``),
    ``"model"`` (the fitted Pipeline), ``"eppf_version"``, ``"params"`` (the
    command's arguments), ``"classes"`` (class names indexed by the model's
    labels) and ``"data"`` (the training data's name), written with
    :func:`eppf.save_model`.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf train`` arguments.
    out : file-like, default=None
        Where the summary goes (standard output by default).

    Returns
    -------
    saved : dict
        What was written to ``args.output``.
    """
    from .. import __version__, save_model

    out = out or sys.stdout
    if not 0 < args.test_size < 1:
        raise ValueError(f"--test-size must be in (0, 1), got {args.test_size}")
    name, clouds, y, class_names, split, _ = _load_data(args)
    if args.all:
        train = np.ones(len(y), dtype=bool)
    elif split is not None:
        train = split == "train"
    else:
        from sklearn.model_selection import train_test_split

        idx, _ = train_test_split(np.arange(len(y)), test_size=args.test_size, stratify=y,
                                  random_state=args.random_state)
        train = np.zeros(len(y), dtype=bool)
        train[idx] = True
    model = make_pipeline_from_args(args)
    t0 = time.perf_counter()
    model.fit([clouds[i] for i in np.flatnonzero(train)], y[train])
    seconds = time.perf_counter() - t0
    model.set_params(descriptor__verbose=0)
    params = {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items() if k != "func"}
    saved = {"format": _MODEL_FORMAT, "model": model, "eppf_version": __version__, "params": params,
             "classes": [str(c) for c in class_names], "data": str(name)}
    save_model(saved, args.output)
    print(f"eppf: trained {args.classifier} on {int(train.sum())} objects of {name} ({len(class_names)} classes) "
          f"in {seconds:.1f} s -> {args.output}", file=out)
    return saved


def load_model(path, trust=False):
    """Load a model saved by ``eppf train``.

    Parameters
    ----------
    path : str or path-like
        The model file.
    trust : bool, default=False
        Also load a pickled model of eppf 0.1; see :func:`eppf.load_model`
        (a pickle can run any code, so only for files you made yourself).

    Returns
    -------
    saved : dict
        With keys ``"model"``, ``"eppf_version"``, ``"params"`` and ``"classes"``.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file cannot be read, is a pickle and ``trust`` is False, or is
        not an eppf model. A warning is printed on standard error if it was
        saved by another eppf version.
    """
    import warnings

    from .. import __version__
    from .._persist import load_model as _load_model_file

    path = str(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        saved = _load_model_file(path, trust=trust)
    for w in caught:
        print(f"eppf: warning: {w.message}", file=sys.stderr)
    if not (isinstance(saved, dict) and saved.get("format") == _MODEL_FORMAT and hasattr(saved.get("model"), "predict")):
        raise ValueError(f"{path} is not an eppf model (write one with 'eppf train')")
    if saved.get("eppf_version") != __version__ and not caught:
        print(f"eppf: warning: {path} was saved by eppf {saved.get('eppf_version')}, this is eppf {__version__}",
              file=sys.stderr)
    return saved


def _set_runtime(model, n_jobs, progress):
    """Set threads and progress of a loaded pipeline where it has those parameters."""
    names = model.get_params()
    updates = {}
    if "descriptor__verbose" in names:
        updates["descriptor__verbose"] = 1 if progress else 0
    if n_jobs is not None:
        from .. import EPPF4DClassifier

        for key in names:
            if key.endswith("__n_jobs"):
                owner = names[key.rsplit("__", 1)[0]] if key.rsplit("__", 1)[0] in names else None
                updates[key] = (None if n_jobs < 0 else n_jobs) if isinstance(owner, EPPF4DClassifier) else n_jobs
    if updates:
        model.set_params(**updates)


def _class_name(saved, label):
    classes = saved.get("classes") or []
    try:
        return str(classes[int(label)])
    except (IndexError, ValueError, TypeError):
        return str(label)


def run_predict(args, out=None):
    """Run ``eppf predict``: classify point cloud files with a saved model.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf predict`` arguments.
    out : file-like, default=None
        Where the table goes (standard output by default).

    Returns
    -------
    labels : ndarray of shape (n_files,)
        The model's predicted labels.
    """
    out = out or sys.stdout
    saved = load_model(args.model, trust=args.trust)
    model = saved["model"]
    _set_runtime(model, args.n_jobs, not args.no_progress)
    clouds, ids, _, _ = _read_clouds(args.inputs, not args.no_progress)
    labels = model.predict(clouds)
    rows = [(str(i), _class_name(saved, lab)) for i, lab in zip(ids, labels)]
    _emit(rows, ["file", "class"], args.output, out)
    return labels


def _score_rows(title, scores):
    return [(title, key, 100 * float(scores[key])) for key in
            ["total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1"]]


def run_evaluate(args, out=None):
    """Run ``eppf evaluate``: leave-one-out retrieval and/or a saved model's test metrics.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf evaluate`` arguments.
    out : file-like, default=None
        Where the table goes (standard output by default).

    Returns
    -------
    report : dict
        ``"retrieval"`` and/or ``"model"``: the scores of
        :func:`eppf.metrics.retrieval_scores` (fractions).
    """
    from .. import EPPFTransformer
    from ..metrics import leave_one_out_retrieval, retrieval_scores

    out = out or sys.stdout
    if args.no_retrieval and args.model is None:
        raise ValueError("nothing to evaluate: --no-retrieval without --model")
    saved = load_model(args.model, trust=args.trust) if args.model is not None else None
    name, clouds, y, class_names, split, _ = _load_data(args)
    print(f"eppf: {name}: {len(clouds)} objects, {len(class_names)} classes", file=out)
    report, rows = {}, []
    if not args.no_retrieval:
        est = EPPFTransformer(n_pairs=args.n_pairs, scaling=args.scaling or "fit", random_state=args.random_state,
                              n_jobs=args.n_jobs, verbose=0 if args.no_progress else 1)
        X = est.fit_transform(clouds)
        report["retrieval"] = retrieval_scores(y, leave_one_out_retrieval(X, y, n_jobs=args.n_jobs))
        rows += _score_rows(f"leave-one-out retrieval ({len(y)})", report["retrieval"])
    if saved is not None:
        test = np.ones(len(y), dtype=bool) if split is None else (split == "test")
        if not test.any():
            raise ValueError(f"{name} has no test objects")
        model = saved["model"]
        _set_runtime(model, None, not args.no_progress)
        pred = model.predict([clouds[i] for i in np.flatnonzero(test)])
        report["model"] = retrieval_scores(y[test], pred)
        where = "test split" if split is not None else "all objects"
        rows += _score_rows(f"model, {where} ({int(test.sum())})", report["model"])
    _emit(rows, ["evaluation", "metric", "percent"], None, out)
    if args.output:
        _emit(rows, ["evaluation", "metric", "percent"], args.output, out)
    return report


def run_bench(args, out=None):
    """Run ``eppf bench``: milliseconds per object of the EPPF descriptor on the built-in shapes.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf bench`` arguments.
    out : file-like, default=None
        Where the table goes (standard output by default).

    Returns
    -------
    rows : list of tuple
        ``(n_pairs, n_jobs, ms_per_object)`` per timed setting.
    """
    from .. import EPPFTransformer
    from ..datasets import make_shapes

    out = out or sys.stdout
    clouds, _ = make_shapes(args.n_per_class, n_points=args.n_points, random_state=args.random_state,
                            return_X_y=True)
    print(f"eppf bench: {len(clouds)} built-in objects of {args.n_points} points; best of {args.repeats}",
          file=out)
    rows = []
    settings = [(p, j) for p in args.n_pairs for j in args.n_jobs]
    for n_pairs, n_jobs in _Progress(settings, not args.no_progress, "bench"):
        best = np.inf
        for _ in range(args.repeats):
            est = EPPFTransformer(n_pairs=n_pairs, n_jobs=n_jobs, random_state=args.random_state)
            t0 = time.perf_counter()
            est.fit_transform(clouds)
            best = min(best, time.perf_counter() - t0)
        rows.append((n_pairs, n_jobs, 1e3 * best / len(clouds)))
    _emit(rows, ["n_pairs", "n_jobs", "ms_per_object"], None, out)
    return rows


_COMMANDS = {"describe": run_describe, "retrieve": run_retrieve, "train": run_train, "predict": run_predict,
             "evaluate": run_evaluate, "bench": run_bench}


def main(argv=None):
    """Entry point of the ``eppf`` console command.

    Parameters
    ----------
    argv : list of str, default=None
        Arguments (``sys.argv[1:]`` when None).

    Returns
    -------
    status : int
        0 on success, 1 on bad input (with a one-line message on stderr),
        130 when interrupted with Ctrl-C (with ``eppf: interrupted``).
    """
    try:
        return _main(argv)
    except KeyboardInterrupt:
        print("eppf: interrupted", file=sys.stderr)
        return 130


def _main(argv):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["experiment"]:
        # The experiments have their own parser (and their own --help).
        from eppf.experiments import main as run_experiment

        return run_experiment(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command in (None, "run"):
            run_main_job(args)
        else:
            _COMMANDS[args.command](args)
        return 0
    except (ValueError, TypeError, FileNotFoundError, OSError, KeyError) as exc:
        print(f"eppf: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
