"""``eppf predict``: classify files with a saved model, read the way its training files were; with
``--segment``, classify every object of a scene (split as ``eppf segment`` splits it)."""

import os
import sys

import numpy as np

from ._common import (MODEL_HELP, TRUST_HELP, Command, add_on_error, add_runtime, check_distinct_outputs,
                      check_not_input, check_output, class_name, count, emit, fewest_points, file_seeds, given_options,
                      load_model, model_sampling, on_error_of, progress_of, read_inputs, register, set_runtime,
                      too_few_points, warn, warn_tiny)
from ._segment import (FIELD_FORMATS, add_segmentation, coordinate, given_segmentation_options, segment_file,
                       segmentation_settings, stage, summary)

__all__ = ["run_predict"]


#: Suffixes of the labeled scene file: the formats that keep every field.
LABELLED_SUFFIXES = tuple(f".{f}" for f in FIELD_FORMATS)


def add_arguments(p):
    p.add_argument("inputs", nargs="+", help="point cloud or mesh files or folders (searched recursively), or "
                                             "one .npz data set; meshes are sampled as the model's training "
                                             "meshes were. With --segment: the file of one scene")
    p.add_argument("--model", required=True, metavar="MODEL", help=MODEL_HELP)
    p.add_argument("--trust", action="store_true", help=TRUST_HELP)
    p.add_argument("-o", "--output", help="write a CSV file instead of printing a table")
    add_on_error(p, refusable=True)
    scene = p.add_argument_group("scenes", "classify every object of a scan (the options of 'eppf segment')")
    scene.add_argument("--segment", action="store_true",
                       help="split the scene into objects first and classify each: one row per segment with "
                            "segment, n_points, the centroid x, y, z (the file's coordinates) and the class")
    add_segmentation(scene, prefix="with --segment: ")
    scene.add_argument("--labelled-output", metavar="OUT", default=None,
                       help="with --segment: write the scene with every field and two more per point, 'segment' "
                            "(-1: ground or no segment) and 'class' (the class's number in the model, as "
                            "printed; -1: none), as .ply, .pcd, .las or .laz")
    # files are read and described with the seeds the model saved: only a scene's ground plane draws more
    scene.add_argument("--random-state", type=int, default=None,
                       help="with --segment: seed of the RANSAC fit of the ground plane (default: 0)")
    add_runtime(p, random_state=False)


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
    inputs = [("--model", args.model)] + [(None, str(i)) for i in args.inputs]
    check_not_input(args.output, inputs)
    if getattr(args, "segment", False):
        return run_predict_scene(args, out)
    given = given_segmentation_options(args) + (["--labelled-output"] if args.labelled_output else []) \
        + given_options(args, "--random-state")
    if given:
        raise ValueError(f"{given[0]} applies to scenes: add --segment")
    saved = load_model(args.model, trust=args.trust)
    model = saved["model"]
    set_runtime(model, args.n_jobs, progress_of(args))
    objects = read_inputs(args.inputs, model_sampling(saved, cmd), on_error=on_error_of(args),
                          progress=progress_of(args), cmd=cmd, labelled=False, min_points=fewest_points(model),
                          exclude=[args.output])
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


def run_predict_scene(args, out):
    """``eppf predict --segment``: split one scene into objects and classify each (see :func:`run_predict`)."""
    from ..io import write_point_fields
    from ..utils._sampling import object_rng, resample

    cmd = getattr(args, "prog", "eppf predict")
    if len(args.inputs) != 1:
        raise ValueError(f"--segment classifies the objects of one scene; got {len(args.inputs)} inputs")
    if getattr(args, "on_error", None) is not None:
        # one file, read whole: an unreadable scene stops the command, there is no other file to go on with
        raise ValueError("--on-error: --segment reads one scene file, which stops the command when it cannot be "
                         "read (there is no other file to skip to); leave it out")
    scene_path = str(args.inputs[0])
    labelled = check_output(args.labelled_output, LABELLED_SUFFIXES, "--labelled-output")
    check_not_input(labelled, [(None, scene_path), ("--model", args.model)], "--labelled-output")
    check_distinct_outputs([("--output", args.output), ("--labelled-output", labelled)])
    progress = progress_of(args)
    saved = load_model(args.model, trust=args.trust)
    model = saved["model"]
    set_runtime(model, args.n_jobs, progress)
    sampling = model_sampling(saved, cmd)
    scene = segment_file(scene_path, segmentation_settings(args), cmd, progress)
    if scene.n_segments == 0:
        warn(cmd, f"{scene_path}: no segment found ({summary(scene)}); a smaller --min-points or a larger "
                  "--tolerance may find some")
    clouds = [scene.cloud(k) for k in range(scene.n_segments)]
    if sampling.get("n_points") is not None:  # the model's objects were resampled to n points: so are these
        seeds = file_seeds(sampling["random_state"], os.path.dirname(scene_path) or ".",
                           [f"{scene_path}#{k}" for k in range(scene.n_segments)])
        clouds = [resample(c, sampling["n_points"], random_state=object_rng(s)) for c, s in zip(clouds, seeds)]
    need = fewest_points(model)
    small = {k: too_few_points(len(c), need) for k, c in enumerate(clouds) if len(c) < need}
    if small:
        listed = "; ".join(f"segment {k}: {w}" for k, w in list(small.items())[:3])
        warn(cmd, f"{count(len(small), 'segment')} too small to describe, not classified: {listed}")
    described = [k for k in range(len(clouds)) if k not in small]
    kept = [clouds[k] for k in described]
    why = {f"segment {k}": w for k, w in small.items()}
    why.update(warn_unreliable(model, kept, [f"segment {k}" for k in described], cmd))
    labels = proba = dist = neighbour = []
    if kept:
        stage(cmd, f"classifying {count(len(kept), 'segment')}", progress)
        labels, proba, dist, neighbour = _evidence(model, kept, saved)
    header, columns = evidence_columns(proba, dist, neighbour)
    header = ["segment", "n_points", "x", "y", "z"] + header[1:]
    position = {k: j for j, k in enumerate(described)}
    classes = np.full(scene.n_segments, -1, dtype=np.int32)
    rows = []
    for k in range(scene.n_segments):
        centroid = [coordinate(v) for v in scene.centroid(k)]
        j = position.get(k)
        if j is None:
            cells = [""] * (len(header) - 5)
        else:
            classes[k] = int(labels[j])
            cells = [class_name(saved, labels[j]), *[c[j] for c in columns]]
        rows.append((k, len(scene.indices(k)), *centroid, *cells))
    header, rows = mark_unreliable(header, rows, [why.get(f"segment {k}", "") for k in range(scene.n_segments)],
                                   args.output)
    emit(rows, header, args.output, out)
    if labelled:
        fields = dict(scene.fields)
        clash = [f for f in ("segment", "class") if f in fields]
        if clash:
            warn(cmd, f"{scene_path} has a field {clash[0]!r}; --labelled-output replaces it")
        point_class = np.full(len(scene.points), -1, dtype=np.int32)
        point_class[scene.order] = classes[scene.labels[scene.order]]
        fields.update(segment=scene.labels.astype(np.int32), **{"class": point_class})
        write_point_fields(labelled, scene.points, fields)  # written whole or not at all
        codes = ", ".join(f"{k} {c}" for k, c in enumerate(saved.get("classes") or []))
        print(f"eppf: {summary(scene)} -> {labelled} (fields 'segment' and 'class'; class numbers: {codes})",
              file=out)
    return classes


register(Command(
    "predict", "classify point cloud or mesh files with a saved model",
    "Classify point clouds and meshes with a model saved by 'eppf train', reading and sampling them as the "
    "model's training files were. The table (or CSV) gives the class and the evidence: the probability of a "
    "network, or the distance to and the id of the nearest training object of the KL 1-NN.",
    add_arguments, run_predict,
))
