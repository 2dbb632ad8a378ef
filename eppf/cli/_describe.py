"""``eppf describe``: descriptors of files, folders or a ``.npz`` data set.

Files and folders are streamed by :func:`eppf.streaming.stream_descriptors`
(the engine of :func:`eppf.describe_files`): read, described and written
chunk by chunk in bounded memory, with the rows of ``fit_transform`` on all
the clouds read the one way (:func:`read_inputs`). This module parses the
arguments, plans the files (labels, seeds) and writes the ``.npy`` or
``.npz`` output and the summary.

A ``.npz`` data set is read whole and described in one ``fit_transform``.
"""

import json
import shutil
import sys
import tempfile
import time
import zipfile

import numpy as np

from ..streaming import write_descriptors
from ..utils._atomic import atomic_write
from ._common import (Command, add_descriptor, count, fewest_points, add_runtime, add_sampling, check_not_input,
                      check_output, descriptor_from_args, is_data_set_input, on_error_of, plan_inputs, progress_of,
                      read_inputs, refuse_sampling_of_data_set, register, sampling_from_args, warn_tiny)

__all__ = ["run_describe"]


def add_arguments(p):
    p.add_argument("inputs", nargs="+", help="point cloud or mesh files (every extension of "
                                             "eppf.io.supported_extensions(), any case), folders (searched "
                                             "recursively; a folder of class subfolders keeps its labels) or "
                                             "one .npz data set")
    p.add_argument("-o", "--output", required=True, help="output file, .npy (the matrix) or .npz (with ids, "
                                                         "labels and class names when known, and how the "
                                                         "descriptors were made)")
    add_descriptor(p)
    add_sampling(p)
    add_runtime(p)


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
    shape : tuple of int
        ``(n_objects, n_features)`` of the descriptors that were saved.
    """
    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf describe")
    output = check_output(args.output, (".npy", ".npz"))
    check_not_input(output, [(None, str(i)) for i in args.inputs])
    progress = progress_of(args)
    t0 = time.perf_counter()
    sampling = sampling_from_args(args)
    if is_data_set_input(args.inputs):
        refuse_sampling_of_data_set(args, args.inputs[0])
        est = descriptor_from_args(args, progress)
        params = _saved_params(est)
        objects = read_inputs(args.inputs, sampling, on_error=on_error_of(args), progress=progress, cmd=cmd,
                              min_points=fewest_points(est), exclude=[output])
        warn_tiny(objects.clouds, objects.ids, est, cmd, args.descriptor)
        X = est.fit_transform(objects.clouds)
        meta = _Meta(objects.ids, objects.labels, objects.class_names, objects.split,
                     getattr(est, "scale_", None), params)
        _save(output, X, meta, args, sampling)
        n, n_features = X.shape
    else:
        est = descriptor_from_args(args, False)
        n, n_features, meta = _stream(args, est, sampling, output, progress, cmd)
    seconds = time.perf_counter() - t0
    labelled = "" if meta.labels is None else f", {count(len(meta.class_names), 'class', 'classes')}"
    print(f"eppf: {count(n, args.descriptor + ' descriptor')} of {n_features} bins{labelled} -> {output} "
          f"({1e3 * seconds / n:.2f} ms per object, {n / seconds:.0f} files per second, {seconds:.1f} s)", file=out)
    return n, n_features


class _Meta:
    """What the .npz output keeps beside the descriptors."""

    def __init__(self, ids, labels, class_names, split, scale, params):
        self.ids, self.labels, self.class_names, self.split = ids, labels, class_names, split
        self.scale, self.params = scale, params


def _saved_params(est):
    return {k: v for k, v in est.get_params().items() if k not in ("verbose", "n_jobs")}


def _npz_extras(meta, args, sampling):
    arrays = dict(ids=meta.ids, descriptor=np.array(args.descriptor),
                  params=np.array(json.dumps(meta.params, default=list)),
                  sampling=np.array(json.dumps(sampling)),
                  scale=np.array(np.nan if meta.scale is None else meta.scale))
    if meta.labels is not None:
        arrays.update(labels=meta.labels, class_names=meta.class_names)
    if meta.split is not None:
        arrays.update(split=meta.split)
    return arrays


def _save(output, X, meta, args, sampling):
    """The in-memory path: save ``X`` (and, for .npz, ``meta``) atomically."""
    if output.lower().endswith(".npy"):
        with atomic_write(output) as fh:
            np.save(fh, X)
        return
    with atomic_write(output) as fh:
        np.savez(fh, descriptors=X, **_npz_extras(meta, args, sampling))


# ---------------------------------------------------------------------------
# The stream
# ---------------------------------------------------------------------------


def _stream(args, est, sampling, output, progress, cmd):
    """Files and folders through :func:`eppf.streaming.stream_descriptors`, rows to ``output`` as they come."""
    plan = plan_inputs(args.inputs, sampling, cmd=cmd, min_points=fewest_points(est), exclude=[output])
    params = _saved_params(est)
    names = [f for f, _, _ in plan.entries]

    def unreadable(k, exc):
        return plan.error(k, exc, on_error_of(args))

    def run(fh):
        result = write_descriptors(fh, names, plan.read, est, n_jobs=args.n_jobs, unreadable=unreadable,
                                   progress=progress, owner=cmd)
        plan.report_skipped(result.skipped, len(result.kept))
        return result

    if output.lower().endswith(".npy"):
        with atomic_write(output) as fh:
            result = run(fh)
        meta = _kept_meta(plan, result.kept, None, params)
    else:
        with tempfile.TemporaryFile(prefix="eppf-describe-rows-") as rows_file:
            result = run(rows_file)
            meta = _kept_meta(plan, result.kept, getattr(result.descriptor, "scale_", None), params)
            rows_file.seek(0)
            with atomic_write(output) as fh:
                # np.savez's layout (stored, one .npy per array); the descriptors are copied from the rows file
                with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
                    with zf.open("descriptors.npy", "w", force_zip64=True) as entry:
                        shutil.copyfileobj(rows_file, entry, 1 << 20)
                    for name, value in _npz_extras(meta, args, sampling).items():
                        with zf.open(name + ".npy", "w", force_zip64=True) as entry:
                            np.lib.format.write_array(entry, np.asanyarray(value), allow_pickle=False)
    warn_tiny(None, meta.ids, est, cmd, args.descriptor, shapes=result.shapes)
    return len(result.kept), result.n_features, meta


def _kept_meta(plan, kept, scale, params):
    """The :class:`_Meta` of the entries ``kept`` (indices, in order): the ids, labels, class names and split
    that ``plan.objects`` gives them (the same arrays), without the resolved paths it also makes (a
    ``realpath`` per file, which describe does not save)."""
    entries = plan.entries
    ids = np.asarray([entries[k][0] for k in kept], dtype=str)
    labels = split = None
    if plan.class_names is not None:
        index = {c: j for j, c in enumerate(plan.class_names)}
        labels = np.asarray([index[entries[k][2][0]] for k in kept], dtype=np.int64)
        split = np.asarray([entries[k][2][1] for k in kept], dtype=str)
        split = split if (split != "").all() else None
    return _Meta(ids, labels, plan.class_names, split, scale, params)


register(Command(
    "describe", "compute descriptors of point cloud or mesh files, a folder or a .npz data set",
    "Compute descriptors of point clouds and save them to .npy (the matrix) or .npz (with object ids, labels and "
    "class names when the input has them, and the descriptor's parameters). Files and folders are streamed: "
    "read, described and written chunk by chunk, in memory that does not grow with the number of files.",
    add_arguments, run_describe,
))
