"""``eppf run`` (and ``eppf`` alone): the main job.

EPPF descriptors of a data set, leave-one-out retrieval by symmetric KL
divergence and a train/test 1-NN classification, printed as a table.
"""

import argparse
import sys
import time

import numpy as np

from ._common import (DEFAULT_N_PAIRS, Command, add_sampling, load_labelled, n_jobs_type, positive_float,
                      positive_int, register, sampling_from_args, warn, warn_tiny)

__all__ = ["run_main_job"]


def add_arguments(parser, defaults_only=False):
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
    parser.add_argument("--n-pairs", type=positive_int, default=DEFAULT_N_PAIRS,
                        help=h(f"point pairs per object (default: {DEFAULT_N_PAIRS})"))
    parser.add_argument("--n-bins", type=positive_int, nargs=4, default=(20, 4, 5, 3),
                        metavar=("F1", "F2", "F3", "F4"), help=h("bins of the four functions (default: 20 4 5 3)"))
    parser.add_argument("--normal-neighbors", type=positive_int, default=None,
                        help=h("neighbours of the PCA normal estimation (default: the descriptor's)"))
    # eppf 0.1 spelled it --n-neighbors; kept, hidden, with a warning
    parser.add_argument("--n-neighbors", dest="old_n_neighbors", type=positive_int, default=None,
                        help=argparse.SUPPRESS)
    parser.add_argument("--repeats", type=positive_int, default=1,
                        help=h("descriptor draws for retrieval mean and std (default: 1; the paper uses 10)"))
    parser.add_argument("--test-size", type=float, default=None,
                        help=h("test fraction when the data has no train/test split (default: 0.25; refused "
                               "with data that has one)"))
    if defaults_only:
        # checked as `eppf run` checks them: `eppf --data x` is the README's spelling of `eppf run --data x`
        group = parser.add_mutually_exclusive_group()
        group.add_argument("--n-points", type=positive_int, default=None, help=argparse.SUPPRESS)
        group.add_argument("--resolution", type=positive_float, default=None, help=argparse.SUPPRESS)
        parser.add_argument("--on-error", choices=["skip", "raise"], default=None, help=argparse.SUPPRESS)
    else:
        add_sampling(parser)
    parser.add_argument("--n-jobs", type=n_jobs_type, default=-1, help=h("threads (default: -1, all cores)"))
    parser.add_argument("--random-state", type=int, default=0, help=h("seed of everything random (default: 0)"))
    parser.add_argument("--no-progress", action="store_true", help=h("hide progress bars"))


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
    from sklearn.model_selection import train_test_split

    from .. import EPPFTransformer, KLNearestNeighbors
    from ..metrics import leave_one_out_retrieval, retrieval_scores
    from ._common import check_classes

    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf")
    test_size = 0.25 if args.test_size is None else args.test_size
    if not 0 < test_size < 1:
        raise ValueError(f"--test-size must be in (0, 1), got {test_size}")
    normal_neighbors = args.normal_neighbors
    if getattr(args, "old_n_neighbors", None) is not None:
        warn(cmd, "--n-neighbors is now --normal-neighbors (the PCA neighbourhood of the normals)")
        normal_neighbors = normal_neighbors or args.old_n_neighbors
    args.built_in = args.data is None
    objects = load_labelled(args, sampling_from_args(args), cmd)
    check_classes(objects, cmd, need_two_per_class=objects.split is None)
    clouds, y, class_names, name = objects.clouds, objects.labels, objects.class_names, objects.name
    split = objects.split
    if split is not None and args.test_size is not None:
        # the data's own split is the one scored: the option would be ignored
        raise ValueError(f"--test-size: {name} has its own train/test split, which the classification uses; "
                         "leave it out")
    if split is None:
        _, test = train_test_split(np.arange(len(y)), test_size=test_size, stratify=y,
                                   random_state=args.random_state)
        split = np.full(len(y), "train", dtype=object)
        split[test] = "test"
    scaling = args.scaling or "fit"
    params = dict(n_bins=tuple(args.n_bins), n_pairs=args.n_pairs, scaling=scaling, n_jobs=args.n_jobs,
                  verbose=0 if args.no_progress else 1)
    if normal_neighbors is not None:
        params["n_neighbors"] = normal_neighbors
    n = len(clouds)
    sizes = np.array([len(c) for c in clouds])
    print(f"eppf: {name}: {n} objects, {len(class_names)} classes, {sizes.min()}-{sizes.max()} points "
          f"(median {int(np.median(sizes))})", file=out, flush=True)
    warn_tiny(clouds, objects.ids, EPPFTransformer(**params), cmd, "eppf")

    rng = np.random.RandomState(args.random_state)
    loo, times, X_first = [], [], None
    for _ in range(args.repeats):
        est = EPPFTransformer(random_state=rng.randint(2**31 - 1), **params)
        t0 = time.perf_counter()
        X = est.fit_transform(clouds)
        times.append(time.perf_counter() - t0)
        X_first = X if X_first is None else X_first
        t0 = time.perf_counter()
        pred = leave_one_out_retrieval(X, y, n_jobs=args.n_jobs)
        loo_time = time.perf_counter() - t0
        loo.append(retrieval_scores(y, pred))

    train, test = split == "train", split == "test"
    clf = KLNearestNeighbors(n_jobs=args.n_jobs).fit(X_first[train], y[train])
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


register(Command(
    "run", "main job: descriptors, leave-one-out retrieval and train/test classification (the default)",
    "Compute EPPF descriptors of a data set, run leave-one-out 1-NN retrieval by symmetric KL divergence and a "
    "train/test classification, and print the metrics.",
    add_arguments, run_main_job,
))
