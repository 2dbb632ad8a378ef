"""Leave-one-out EPPF retrieval accuracy on real data sets in the flat ``.npz`` layout.

The check that the descriptor is right (foundation issue): leave-one-out 1-NN
by symmetric KL over every object of ``modelnet10_1024.npz`` (raw CAD units,
so per-object scaling) and ``dales_objects.npz`` (metres, the paper's data-set
scaling). Prints total accuracy, mean class accuracy, macro precision, recall
and F1, as mean and std over ``--repeats`` descriptor draws.

The data are not part of the repository. ``--data-dir`` (or the environment
variable ``EPPF_BENCH_DATA``) names the folder that holds them; make
``modelnet10_1024.npz`` with ``scripts/make_modelnet_npz.py`` (see the user
guide, "ModelNet10 as a .npz file"); any other set in the same layout can be
written with :func:`eppf.datasets.save_npz`. A requested set that is missing
stops the script with exit status 2 before anything is computed.

Usage: ``python scripts/reproduce_retrieval.py --data-dir DIR [--sets modelnet10_1024] [--repeats 3]``
"""

import argparse
import os
import sys
import time

import numpy as np

from eppf import EPPFTransformer
from eppf.datasets import load_npz
from eppf.metrics import leave_one_out_retrieval, retrieval_scores

SETS = {"modelnet10_1024": "object", "dales_objects": "fit"}
ENV = "EPPF_BENCH_DATA"
HOW_TO_GET = (
    "make modelnet10_1024.npz with\n"
    "  python scripts/make_modelnet_npz.py --root PATH/TO/ModelNet10 -o DIR/modelnet10_1024.npz\n"
    "  (or --download instead of --root to fetch Princeton's archive, about 450 MB);\n"
    "other sets go in the same layout through eppf.datasets.save_npz; "
    "pick the sets to run with --sets"
)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", default=os.environ.get(ENV),
                        help=f"folder holding the .npz files (default: ${ENV}; no default otherwise)")
    parser.add_argument("--sets", nargs="+", choices=list(SETS), default=list(SETS), help="data sets to run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--n-neighbors", type=int, default=None, help="normal-estimation neighbours")
    parser.add_argument("--n-jobs", type=int, default=-1)
    args = parser.parse_args(argv)
    if not args.data_dir:
        print(f"reproduce_retrieval: no data folder; give --data-dir DIR or set {ENV}.\n{HOW_TO_GET}", file=sys.stderr)
        return 2
    paths = {name: os.path.join(args.data_dir, name + ".npz") for name in args.sets}
    missing = [p for p in paths.values() if not os.path.isfile(p)]
    if missing:
        print(f"reproduce_retrieval: missing {', '.join(missing)}.\n{HOW_TO_GET}", file=sys.stderr)
        return 2
    keys = ["total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1"]
    print(f"{'data set':<16} {'scaling':<7} " + " ".join(f"{k:>22}" for k in keys) + f" {'ms/obj':>7}")
    for name, path in paths.items():
        scaling = SETS[name]
        data = load_npz(path)
        extra = {} if args.n_neighbors is None else {"n_neighbors": args.n_neighbors}
        scores, times = [], []
        for r in range(args.repeats):
            est = EPPFTransformer(scaling=scaling, random_state=r, n_jobs=args.n_jobs, **extra)
            t0 = time.perf_counter()
            X = est.fit_transform(data.data)
            times.append((time.perf_counter() - t0) / len(data.data))
            scores.append(retrieval_scores(data.target, leave_one_out_retrieval(X, data.target)))
        cells = []
        for k in keys:
            v = 100 * np.array([s[k] for s in scores])
            cells.append(f"{v.mean():6.2f} ± {v.std():4.2f}")
        print(f"{name:<16} {scaling:<7} " + " ".join(f"{c:>22}" for c in cells) + f" {1e3 * np.mean(times):7.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
