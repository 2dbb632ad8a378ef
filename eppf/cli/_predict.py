"""``eppf predict``: classify files with a saved model, read the way its training files were."""

import sys

import numpy as np

from ._common import (MODEL_HELP, TRUST_HELP, Command, add_on_error, add_runtime, check_output, class_name, emit,
                      fewest_points, load_model, model_sampling, progress_of, read_inputs, register, set_runtime,
                      warn_tiny)

__all__ = ["run_predict"]


def add_arguments(p):
    p.add_argument("inputs", nargs="+", help="point cloud or mesh files or folders (searched recursively), or "
                                             "one .npz data set; meshes are sampled as the model's training "
                                             "meshes were")
    p.add_argument("--model", required=True, metavar="MODEL", help=MODEL_HELP)
    p.add_argument("--trust", action="store_true", help=TRUST_HELP)
    p.add_argument("-o", "--output", help="write a CSV file instead of printing a table")
    add_on_error(p)
    add_runtime(p)


def _evidence(model, clouds, saved):
    """Per object: (probability, nearest distance, nearest training id), None where the model has none."""
    n = len(clouds)
    clf = model.steps[-1][1] if hasattr(model, "steps") else model
    head = model[:-1] if hasattr(model, "steps") and len(model.steps) > 1 else None
    if hasattr(clf, "kneighbors"):
        X = head.transform(clouds) if head is not None else clouds
        labels = clf.predict(X)
        dist, ind = clf.kneighbors(X, n_neighbors=1)
        train_ids = saved.get("train_ids")
        ids = [str(train_ids[j]) if train_ids is not None and j < len(train_ids) else f"#{j}" for j in ind[:, 0]]
        return labels, [None] * n, [float(d) for d in dist[:, 0]], ids
    if hasattr(clf, "predict_proba"):
        proba = np.asarray(model.predict_proba(clouds))
        labels = clf.classes_[np.argmax(proba, axis=1)]
        return labels, [float(p) for p in proba.max(axis=1)], [None] * n, [None] * n
    return model.predict(clouds), [None] * n, [None] * n, [None] * n


def run_predict(args, out=None):
    """Run ``eppf predict``: classify point cloud or mesh files with a saved model.

    Files are read with the sampling settings and seed rule saved in the
    model, so a mesh is the same cloud it was in ``eppf train``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf predict`` arguments.
    out : file-like, default=None
        Where the table goes (standard output by default).

    Returns
    -------
    labels : ndarray of shape (n_files,)
        The model's predicted labels of the files that could be read.
    """
    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf predict")
    check_output(args.output)
    saved = load_model(args.model, trust=args.trust)
    model = saved["model"]
    set_runtime(model, args.n_jobs, progress_of(args))
    objects = read_inputs(args.inputs, model_sampling(saved, cmd), on_error=args.on_error,
                          progress=progress_of(args), cmd=cmd, labelled=False, min_points=fewest_points(model))
    unreliable = warn_unreliable(model, objects.clouds, objects.ids, cmd)
    labels, proba, dist, neighbour = _evidence(model, objects.clouds, saved)
    header, columns = evidence_columns(proba, dist, neighbour)
    rows = [(str(i), class_name(saved, lab), *[c[k] for c in columns])
            for k, (i, lab) in enumerate(zip(objects.ids, labels))]
    header, rows = mark_unreliable(header, rows, [unreliable.get(str(i), "") for i in objects.ids], args.output)
    emit(rows, header, args.output, out)
    return np.asarray(labels)


def warn_unreliable(model, clouds, ids, cmd):
    """Warn about the clouds too small for the model's descriptor; ``{id: why}`` of them."""
    if hasattr(model, "named_steps") and "descriptor" in model.named_steps:
        return warn_tiny(clouds, ids, model.named_steps["descriptor"], cmd, "the model's descriptor")
    return {}


def evidence_columns(proba, dist, neighbour):
    """The header and columns of the evidence that :func:`_evidence` found."""
    header, columns = ["file", "class"], []
    if any(p is not None for p in proba):
        header.append("probability")
        columns.append(proba)
    if any(d is not None for d in dist):
        header += ["distance", "neighbour"]
        columns += [dist, neighbour]
    return header, columns


def mark_unreliable(header, rows, why, output):
    """Rows with an ``unreliable`` column (empty, or why the row's result is unreliable): always in a CSV
    (one header for scripts), in a printed table only when a row is marked."""
    if not output and not any(why):
        return header, rows
    return header + ["unreliable"], [(*row, w) for row, w in zip(rows, why)]


register(Command(
    "predict", "classify point cloud or mesh files with a saved model",
    "Classify point clouds and meshes with a model saved by 'eppf train', reading and sampling them as the "
    "model's training files were. The table (or CSV) gives the class and the evidence: the probability of a "
    "network, or the distance to and the id of the nearest training object of the KL 1-NN.",
    add_arguments, run_predict,
))
