"""Compare eppf's GASDTransformer with PCL 1.13's GASDEstimation on a labelled data set.

Same preprocessing as the PCL reference runs: every object centred on its
mean and scaled by its largest bounding-box side (GASD needs no normals).
Reports, for eppf's rows and PCL's reference rows (``gasd`` key): leave-one-out
1-NN total accuracy with the L1 distance and with the symmetric KL divergence
(zero bins floored at half the smallest positive value); the L1 distance
between the two mean descriptors and the median per-row L1 distance; eppf's
time per object on one thread; and whether the output is bit-identical for
2 threads and for another chunk size.

Usage::

    python scripts/compare_pcl_gasd.py --data DATA.npz --reference PCL_GLOBAL.npz [--n-objects 1000]

Exits with a message (status 2) when a file is missing.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _pcl_compare import run  # noqa: E402


def main(argv=None):
    from eppf.descriptors import GASDTransformer

    return run(argv, prog="compare_pcl_gasd", key="gasd", title="GASD",
               make=lambda n_jobs: GASDTransformer(n_jobs=n_jobs), normals=False)


if __name__ == "__main__":
    sys.exit(main())
