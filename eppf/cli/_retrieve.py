"""``eppf retrieve``: top-k database neighbors by the descriptor's metric."""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ..io._npy import read_npy_array, read_npz_arrays
from ..registry import DESCRIPTORS, make_descriptor
from ._common import (SEED_RULE, Command, add_on_error, add_runtime, check_not_input, check_output, emit, fewest_points,
                      on_error_of, positive_int, progress_of, read_inputs, register, warn_tiny)

__all__ = ["run_retrieve"]


def add_arguments(p):
    p.add_argument("queries", nargs="*", help="query point cloud or mesh files or folders (described with the "
                                              "database's descriptor, parameters and sampling)")
    p.add_argument("--database", required=True, metavar="DB.npz", help="descriptors from 'eppf describe'")
    p.add_argument("--query-descriptors", metavar="FILE", help="precomputed query descriptors (.npy or .npz) "
                                                               "instead of files")
    p.add_argument("-k", "--top-k", type=positive_int, default=5, help="neighbours per query (default: 5)")
    p.add_argument("-o", "--output", help="write a CSV file instead of printing a table")
    add_on_error(p, refusable=True)
    add_runtime(p, random_state=False)
    # (listed by earlier versions, which ignored it: refused by run_retrieve)
    p.add_argument("--random-state", type=int, default=None, help=argparse.SUPPRESS)


def _load_descriptors(path, owner):
    path = str(path)
    if not Path(path).is_file():
        raise FileNotFoundError(f"no such file: {path}")
    try:  # (eppf.io's readers: every header checked against the stored bytes before anything is allocated)
        if path.lower().endswith(".npy"):
            return dict(descriptors=read_npy_array(path, owner))
        data = read_npz_arrays(path, owner)
    except ValueError as exc:
        raise ValueError(f"cannot read descriptors from {path}: {exc}") from None
    if "descriptors" not in data:
        raise ValueError(f"{path} has no 'descriptors' array; write it with 'eppf describe -o {owner}.npz'")
    return data


def _named_labels(data, n, path):
    if "labels" not in data or "class_names" not in data:
        return None
    labels, names = np.asarray(data["labels"]), np.asarray(data["class_names"])
    if len(labels) != n or labels.dtype.kind not in "iu" or (len(labels) and not
                                                             (0 <= labels.min() and labels.max() < len(names))):
        raise ValueError(f"{path}: its labels do not fit its {n} descriptors and {len(names)} class names")
    return names[labels].astype(str)


def run_retrieve(args, out=None):
    """Run ``eppf retrieve``: top-k database neighbors of each query.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf retrieve`` arguments.
    out : file-like, default=None
        Where the table goes (standard output by default).

    Returns
    -------
    rows : list of tuple
        ``(query, query_label, rank, match_id, match_label, distance)`` for
        every query and rank.
    """
    from .. import symmetric_kl_distances

    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf retrieve")
    check_output(args.output)
    check_not_input(args.output, [("--database", args.database), ("--query-descriptors", args.query_descriptors)]
                    + [(None, str(q)) for q in args.queries])
    db = _load_descriptors(args.database, "database")
    X_db = np.asarray(db["descriptors"], dtype=np.float64)
    if X_db.ndim != 2 or len(X_db) == 0:
        raise ValueError(f"database descriptors must be a non-empty 2D array, got shape {X_db.shape}")
    db_ids = db.get("ids", np.array([str(i) for i in range(len(X_db))]))
    if len(db_ids) != len(X_db):
        raise ValueError(f"{args.database} has {len(db_ids)} ids for {len(X_db)} descriptors")
    db_labels = _named_labels(db, len(X_db), args.database)
    if (args.query_descriptors is None) == (not args.queries):
        raise ValueError("give query files or --query-descriptors (exactly one of the two)")
    if getattr(args, "random_state", None) is not None:
        raise ValueError("--random-state: the queries are sampled and described with the seeds that "
                         f"{args.database} records (as its objects were); leave it out")
    if args.query_descriptors is not None and getattr(args, "on_error", None) is not None:
        raise ValueError("--on-error: with --query-descriptors no point file is read (the queries are "
                         "precomputed descriptors); leave it out")
    q_labels = None
    descriptor = str(db["descriptor"]) if "descriptor" in db else None
    if args.query_descriptors is not None:
        q = _load_descriptors(args.query_descriptors, "queries")
        X_q = np.atleast_2d(np.asarray(q["descriptors"], dtype=np.float64))
        q_ids = q.get("ids", np.array([str(i) for i in range(len(X_q))]))
        q_labels = _named_labels(q, len(X_q), args.query_descriptors)
    else:
        if descriptor is None or "params" not in db:
            raise ValueError(f"{args.database} does not say how its descriptors were made; "
                             "pass --query-descriptors computed the same way")
        if descriptor not in DESCRIPTORS:
            raise ValueError(f"{args.database} was made with the descriptor {descriptor!r}, which this eppf "
                             f"does not have (it has {', '.join(DESCRIPTORS)})")
        params = json.loads(str(db["params"]))
        sampling = json.loads(str(db["sampling"])) if "sampling" in db else \
            {"n_points": None, "resolution": None, "normals": "auto", "random_state": 0, "seed_rule": SEED_RULE}
        settings = dict(params, n_jobs=args.n_jobs, verbose=1 if progress_of(args) else 0)
        est = make_descriptor(descriptor, **settings)
        objects = read_inputs(args.queries, sampling, on_error=on_error_of(args), progress=progress_of(args),
                              cmd=cmd, min_points=fewest_points(est), exclude=[args.output])
        q_ids = objects.ids
        if objects.labels is not None:
            q_labels = objects.class_names[objects.labels]
        warn_tiny(objects.clouds, q_ids, est, cmd, descriptor)
        est.fit(objects.clouds)
        if "scale" in db and np.isfinite(db["scale"]) and getattr(est, "scale_", None) is not None:
            est.scale_ = float(db["scale"])  # describe the queries in the database's units
        X_q = est.transform(objects.clouds)
    if X_q.shape[1] != X_db.shape[1]:
        raise ValueError(f"queries have {X_q.shape[1]} bins but the database has {X_db.shape[1]}")
    metric = DESCRIPTORS[descriptor].metric if descriptor in DESCRIPTORS else "kl"
    if metric == "l1":
        D = np.stack([np.abs(X_db - x).sum(axis=1) for x in X_q])  # one query at a time: bounded memory
    else:
        D = symmetric_kl_distances(X_q, X_db, n_jobs=args.n_jobs)
    k = min(args.top_k, len(X_db))
    order = np.argsort(D, axis=1, kind="stable")[:, :k]
    rows = []
    for i in range(len(X_q)):
        for r, j in enumerate(order[i]):
            rows.append((str(q_ids[i]), "" if q_labels is None else str(q_labels[i]), r + 1, str(db_ids[j]),
                         "" if db_labels is None else str(db_labels[j]), float(D[i, j])))
    emit(rows, ["query", "query_label", "rank", "match", "label", "distance"], args.output, out)
    return rows


register(Command(
    "retrieve", "top-k nearest database objects of query objects",
    "Find the k nearest objects of a descriptor database (a .npz written by 'eppf describe') for each query, by "
    "the descriptor's metric (symmetric KL divergence, or L1 for the VFH family), with the class names the "
    "database keeps.",
    add_arguments, run_retrieve,
))
