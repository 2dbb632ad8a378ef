"""``eppf describe``: descriptors of files, folders or a ``.npz`` data set."""

import json
import sys
import time

import numpy as np

from ..utils._atomic import atomic_write
from ._common import (Command, add_descriptor, add_runtime, add_sampling, check_output, make_descriptor,
                      descriptor_settings, progress_of, read_inputs, register, sampling_from_args, warn_tiny)

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
    X : ndarray of shape (n_objects, n_features)
        The descriptors that were saved.
    """
    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf describe")
    output = check_output(args.output, (".npy", ".npz"))
    progress = progress_of(args)
    est = make_descriptor(args.descriptor, descriptor_settings(args, progress))
    sampling = sampling_from_args(args)
    objects = read_inputs(args.inputs, sampling, on_error=args.on_error, progress=progress, cmd=cmd)
    warn_tiny(objects.clouds, objects.ids, est, cmd, args.descriptor)
    t0 = time.perf_counter()
    X = est.fit_transform(objects.clouds)
    seconds = time.perf_counter() - t0
    if output.lower().endswith(".npy"):
        with atomic_write(output) as fh:
            np.save(fh, X)
    else:
        params = {k: v for k, v in est.get_params().items() if k not in ("verbose", "n_jobs")}
        arrays = dict(descriptors=X, ids=objects.ids, descriptor=np.array(args.descriptor),
                      params=np.array(json.dumps(params, default=list)),
                      sampling=np.array(json.dumps(sampling)),
                      scale=np.array(np.nan if getattr(est, "scale_", None) is None else est.scale_))
        if objects.labels is not None:
            arrays.update(labels=objects.labels, class_names=objects.class_names)
        if objects.split is not None:
            arrays.update(split=objects.split)
        with atomic_write(output) as fh:
            np.savez(fh, **arrays)
    labelled = "" if objects.labels is None else f", {len(objects.class_names)} classes"
    print(f"eppf: {len(X)} {args.descriptor} descriptors of {X.shape[1]} bins{labelled} -> {output} "
          f"({1e3 * seconds / len(X):.2f} ms per object)", file=out)
    return X


register(Command(
    "describe", "compute descriptors of point cloud or mesh files, a folder or a .npz data set",
    "Compute descriptors of point clouds and save them to .npy (the matrix) or .npz (with object ids, labels and "
    "class names when the input has them, and the descriptor's parameters).",
    add_arguments, run_describe,
))
