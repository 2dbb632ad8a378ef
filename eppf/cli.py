"""The ``eppf`` command line.

``eppf`` (or ``eppf run``, or ``python -m eppf``) runs the main job: EPPF
descriptors of a data set (the built-in synthetic shapes unless ``--data``
names a ``.npz`` file), leave-one-out retrieval by symmetric KL divergence,
and a train/test classification, printed as a table.
"""

import argparse
import sys
import time

import numpy as np

__all__ = ["main", "run_main_job"]


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
    _add_run_arguments(parser, defaults_only=True)
    return parser


def _add_run_arguments(parser, defaults_only=False):
    kw = {"help": argparse.SUPPRESS} if defaults_only else {}

    def h(text):
        return kw.get("help", text)

    parser.add_argument("--data", metavar="FILE.npz", default=None,
                        help=h("a .npz of point clouds (points, offsets, labels, class_names[, split]); "
                               "default: the built-in synthetic shapes"))
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
        from .datasets import make_shapes

        bunch = make_shapes(random_state=args.random_state)
        name = "built-in synthetic shapes"
    else:
        from .datasets import load_npz

        bunch = load_npz(args.data)
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
    from . import EPPFTransformer, KLNearestNeighbors
    from .metrics import leave_one_out_retrieval, retrieval_scores

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


def main(argv=None):
    """Entry point of the ``eppf`` console command.

    Parameters
    ----------
    argv : list of str, default=None
        Arguments (``sys.argv[1:]`` when None).

    Returns
    -------
    status : int
        0 on success, 1 on bad input (with a one-line message on stderr).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command in (None, "run"):
            run_main_job(args)
        return 0
    except (ValueError, TypeError, FileNotFoundError, OSError) as exc:
        print(f"eppf: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
