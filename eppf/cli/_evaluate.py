"""``eppf evaluate``: leave-one-out retrieval and a saved model's test metrics."""

import sys

import numpy as np

from ._common import (DEFAULT_N_PAIRS, MODEL_HELP, TRUST_HELP, Command, add_data_source, add_descriptor, add_runtime,
                      add_sampling, check_not_input, check_output, count, descriptor_from_args, emit, fewest_points,
                      given_options, load_labelled, load_model, model_sampling, progress_of, register,
                      sampling_from_args, set_runtime, warn, warn_tiny)

__all__ = ["run_evaluate"]


def add_arguments(p):
    add_data_source(p)
    p.add_argument("--model", metavar="MODEL", help="also evaluate this saved model; " + MODEL_HELP)
    p.add_argument("--trust", action="store_true", help=TRUST_HELP)
    p.add_argument("--no-retrieval", action="store_true", help="skip the leave-one-out retrieval")
    p.add_argument("-o", "--output", help="also write the metrics to a CSV file")
    add_descriptor(p)
    add_sampling(p)
    add_runtime(p)


def _score_rows(title, scores):
    return [(title, key, 100 * float(scores[key])) for key in
            ["total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1"]]


def run_evaluate(args, out=None):
    """Run ``eppf evaluate``: leave-one-out retrieval and/or a saved model's test metrics.

    With ``--model``, the data are read with the model's sampling settings,
    and a warning says how many of the scored objects the model was trained
    on.

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
        :func:`eppf.metrics.retrieval_scores` (fractions); with
        ``"model_unseen"`` the model's scores on the objects it was not
        trained on, when some of the others were.
    """
    from ..metrics import leave_one_out_retrieval, retrieval_scores
    from ..registry import DESCRIPTORS

    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf evaluate")
    if args.no_retrieval and args.model is None:
        raise ValueError("nothing to evaluate: --no-retrieval without --model")
    if args.no_retrieval:
        # the descriptor options make the retrieval's descriptors only: without it they would be ignored
        given = [o for o, v in (("--descriptor", args.descriptor != "eppf"),
                                ("--n-pairs", args.n_pairs != DEFAULT_N_PAIRS), ("--scaling", args.scaling is not None),
                                ("--normal-neighbors", args.normal_neighbors is not None)) if v]
        if given:
            raise ValueError(f"{given[0]}: it sets the descriptor of the retrieval, which --no-retrieval skips (the "
                             "model keeps its own descriptor); leave it out")
        if args.random_state != 0:  # (0, the default, changes nothing either way)
            raise ValueError("--random-state: it seeds the retrieval's descriptors, which --no-retrieval skips (the "
                             "model reads the files with its saved seeds); leave it out")
    if args.model is not None:
        # the model's files are read as its training files were: a sampling option here would be ignored
        given = given_options(args, "--n-points", "--resolution")
        if given:
            raise ValueError(f"{given[0]}: with --model the files are read as the model's training files were "
                             "(its saved sampling settings); leave it out")
    check_output(args.output)
    check_not_input(args.output, [("--data", args.data), ("--model", args.model)])
    saved = load_model(args.model, trust=args.trust) if args.model is not None else None
    sampling = model_sampling(saved, cmd) if saved is not None else sampling_from_args(args)
    est = None if args.no_retrieval else descriptor_from_args(args)
    objects = load_labelled(args, sampling, cmd, min_points=fewest_points(est, saved and saved["model"]))
    y = objects.labels
    print(f"eppf: {objects.name}: {count(len(y), 'object')}, "
          f"{count(len(objects.class_names), 'class', 'classes')}", file=out)
    report, rows = {}, []
    if not args.no_retrieval:
        warn_tiny(objects.clouds, objects.ids, est, cmd, args.descriptor)
        X = est.fit_transform(objects.clouds)
        metric = DESCRIPTORS[args.descriptor].metric
        if metric == "kl":
            pred = leave_one_out_retrieval(X, y, n_jobs=args.n_jobs)
        else:
            D = np.stack([np.abs(X - x).sum(axis=1) for x in X])
            np.fill_diagonal(D, np.inf)
            pred = y[np.argmin(D, axis=1)]
        report["retrieval"] = retrieval_scores(y, pred)
        rows += _score_rows(f"leave-one-out retrieval ({len(y)})", report["retrieval"])
    if saved is not None:
        test = np.ones(len(y), dtype=bool) if objects.split is None else (objects.split == "test")
        if not test.any():
            raise ValueError(f"{objects.name} has no test objects")
        scored = objects.subset(test)
        seen = set(saved.get("train_keys") or [])
        n_seen = sum(k in seen for k in scored.keys)
        if n_seen:
            warn(cmd, f"{n_seen} of the {count(len(scored.keys), 'object')} scored {'was' if n_seen == 1 else 'were'} "
                      f"seen in training by {args.model}; "
                      "its score on them is optimistic (train with a held-out split, or evaluate on other files)")
        model = saved["model"]
        set_runtime(model, args.n_jobs, progress_of(args))  # --n-jobs: the threads of its predictions too
        pred = model.predict(scored.clouds)
        classes = saved.get("classes")
        if classes is not None and list(classes) != [str(c) for c in objects.class_names]:
            # labels are indices into each one's class list: compare by name
            names = np.asarray(classes, dtype=str)
            pred = np.asarray([{c: k for k, c in enumerate(objects.class_names)}.get(names[int(p)], -1)
                               for p in pred])
        report["model"] = retrieval_scores(scored.labels, pred)
        where = "test split" if objects.split is not None else "all objects"
        rows += _score_rows(f"model, {where} ({int(test.sum())})", report["model"])
        unseen = np.array([k not in seen for k in scored.keys])
        if n_seen and unseen.any():
            report["model_unseen"] = retrieval_scores(scored.labels[unseen], np.asarray(pred)[unseen])
            rows += _score_rows(f"model, objects not seen in training ({int(unseen.sum())})", report["model_unseen"])
    emit(rows, ["evaluation", "metric", "percent"], None, out)
    if args.output:
        emit(rows, ["evaluation", "metric", "percent"], args.output, out)
    return report


register(Command(
    "evaluate", "leave-one-out retrieval metrics and/or a saved model's test metrics",
    "Leave-one-out 1-NN retrieval on descriptors of a data set (symmetric KL divergence, or L1 for the VFH "
    "family), and with --model, the saved model's metrics on the data set's test split (every object when "
    "there is no split, with a warning for the objects it was trained on).",
    add_arguments, run_evaluate,
))
