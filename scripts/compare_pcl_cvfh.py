"""Compare eppf's CVFHTransformer with PCL 1.13's CVFHEstimation outputs.

Same preprocessing and figures as ``compare_pcl_grsd.py`` (which this script
reuses), with the reference runs' settings: EPS angle 5 degrees, curvature
threshold 1.0, no bin normalisation, PCL's first signature.

Usage::

    python scripts/compare_pcl_cvfh.py DATA_DIR REFERENCE_DIR [--n 500] [--datasets modelnet10_1024]

``REFERENCE_DIR`` holds ``pcl_global_<name>.npz`` with key ``cvfh``.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from compare_pcl_grsd import main as compare_main  # noqa: E402


def make():
    from eppf.descriptors._cvfh import CVFHTransformer

    return CVFHTransformer(
        aggregate="first", eps_angle=float(np.deg2rad(5.0)), curvature_threshold=1.0,
        normalize_bins=False, normalize=False, n_jobs=1,
    )


if __name__ == "__main__":
    compare_main(key="cvfh", make=make)
