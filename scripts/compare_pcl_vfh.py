"""Compare eppf's VFHTransformer with PCL 1.13's VFHEstimation on a labelled data set.

Same preprocessing as the PCL reference runs: every object centred on its
mean and scaled by its largest bounding-box side, PCA normals from 10
neighbours oriented away from the centroid, given to the transformer.
Reports, for eppf's rows and PCL's reference rows (``vfh`` key): leave-one-out
1-NN total accuracy with the L1 distance and with the symmetric KL divergence
(zero bins floored at half the smallest positive value); the L1 distance
between the two mean descriptors and the median per-row L1 distance, for the
whole row and for its angle (0-134) and viewpoint (180-307) parts; eppf's
time per object on one thread; and whether the output is bit-identical for
2 threads and for another chunk size.

Usage::

    python scripts/compare_pcl_vfh.py --data DATA.npz --reference PCL_GLOBAL.npz [--n-objects 1000]

Exits with a message (status 2) when a file is missing.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _pcl_compare import run  # noqa: E402


def main(argv=None):
    from eppf.descriptors import VFHTransformer

    return run(argv, prog="compare_pcl_vfh", key="vfh", title="VFH",
               make=lambda n_jobs: VFHTransformer(n_jobs=n_jobs), normals=True,
               parts=(("whole row", slice(0, 308)), ("angles f1-f3", slice(0, 135)), ("viewpoint", slice(180, 308))))


if __name__ == "__main__":
    sys.exit(main())
