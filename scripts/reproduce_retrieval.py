"""Leave-one-out EPPF retrieval accuracy on the shared real data sets.

The check that the descriptor is right (foundation issue): leave-one-out 1-NN
by symmetric KL over every object of ``modelnet10_1024.npz`` (raw CAD units,
so per-object scaling) and ``dales_objects.npz`` (metres, the paper's data-set
scaling). Prints total accuracy, mean class accuracy, macro precision, recall
and F1, as mean and std over ``--repeats`` descriptor draws.

Usage: ``python scripts/reproduce_retrieval.py [--data-dir ../shared/data] [--repeats 3]``
"""

import argparse
import os
import time

import numpy as np

from eppf import EPPFTransformer
from eppf.datasets import load_npz
from eppf.metrics import leave_one_out_retrieval, retrieval_scores

SETS = {"modelnet10_1024": "object", "dales_objects": "fit"}


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", default=os.path.join(here, "..", "..", "shared", "data"))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--n-neighbors", type=int, default=None, help="normal-estimation neighbours")
    parser.add_argument("--n-jobs", type=int, default=-1)
    args = parser.parse_args()
    keys = ["total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1"]
    print(f"{'data set':<16} {'scaling':<7} " + " ".join(f"{k:>22}" for k in keys) + f" {'ms/obj':>7}")
    for name, scaling in SETS.items():
        path = os.path.join(args.data_dir, name + ".npz")
        if not os.path.exists(path):
            print(f"{name}: {path} not found, skipped")
            continue
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


if __name__ == "__main__":
    main()
