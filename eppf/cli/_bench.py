"""``eppf bench``: descriptor speed on the built-in shapes."""

import sys
import time

import numpy as np

from ..utils import progress_bar
from ._common import (DESCRIPTOR_NAMES, Command, add_runtime, emit, n_jobs_type, positive_int, progress_of,
                      register)

__all__ = ["run_bench"]


def add_arguments(p):
    p.add_argument("--descriptor", choices=DESCRIPTOR_NAMES, default="eppf", help="which registered descriptor "
                                                                                  "(default: eppf)")
    p.add_argument("--n-pairs", type=positive_int, nargs="+", default=[5000, 20000],
                   help="sample counts to time (pairs or triplets; deterministic descriptors: one row each; "
                        "default: 5000 20000)")
    p.add_argument("--n-per-class", type=positive_int, default=10, help="objects per class (10 classes; default: 10)")
    p.add_argument("--n-points", type=positive_int, default=1024, help="points per object (default: 1024)")
    p.add_argument("--repeats", type=positive_int, default=3, help="timings per row, the best shown (default: 3)")
    p.add_argument("--n-jobs", type=n_jobs_type, nargs="+", default=[-1],
                   help="thread counts to time (default: -1, all cores)")
    add_runtime(p, n_jobs=False)


def run_bench(args, out=None):
    """Run ``eppf bench``: milliseconds per object of a descriptor on the built-in shapes.

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
    from ..datasets import make_shapes
    from ..registry import DESCRIPTORS

    out = out or sys.stdout
    spec = DESCRIPTORS[getattr(args, "descriptor", "eppf")]
    clouds, _ = make_shapes(args.n_per_class, n_points=args.n_points, random_state=args.random_state,
                            return_X_y=True)
    print(f"eppf bench: {spec.title}, {len(clouds)} built-in objects of {args.n_points} points; best of "
          f"{args.repeats}", file=out)
    rows = []
    counts = args.n_pairs if not spec.deterministic else [None]
    settings = [(p, j) for p in counts for j in args.n_jobs]
    for n_pairs, n_jobs in progress_bar(settings, desc="bench", enabled=progress_of(args)):
        best = np.inf
        for _ in range(args.repeats):
            est = spec.make(n_samples=n_pairs, n_jobs=n_jobs, random_state=args.random_state)
            t0 = time.perf_counter()
            est.fit_transform(clouds)
            best = min(best, time.perf_counter() - t0)
        rows.append(("-" if n_pairs is None else n_pairs, n_jobs, 1e3 * best / len(clouds)))
    emit(rows, ["n_pairs", "n_jobs", "ms_per_object"], None, out)
    return rows


register(Command(
    "bench", "speed of a descriptor on the built-in data (ms per object)",
    "Time a registered descriptor (normal estimation included) on the built-in synthetic shapes and print "
    "milliseconds per object.",
    add_arguments, run_bench,
))
