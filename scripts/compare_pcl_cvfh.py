"""Compare eppf's CVFHTransformer with PCL 1.13's CVFHEstimation outputs.

Same preprocessing and figures as ``compare_pcl_grsd.py`` (which this script
reuses), with the reference runs' settings: EPS angle 5 degrees, curvature
threshold 1.0, no bin normalisation, PCL's first signature; PCL's region
growing by default (``--region-growing components`` for the default one).

Usage::

    python scripts/compare_pcl_cvfh.py DATA_DIR REFERENCE_DIR [--n 500] [--datasets modelnet10_1024]
        [--region-growing {pcl,components}]

``REFERENCE_DIR`` holds ``pcl_global_<name>.npz`` with key ``cvfh``.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from compare_pcl_grsd import main as compare_main  # noqa: E402


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    growing = "pcl"
    if "--region-growing" in argv:
        at = argv.index("--region-growing")
        if at + 1 >= len(argv) or argv[at + 1] not in ("pcl", "components"):
            sys.exit("compare_pcl_cvfh: --region-growing takes 'pcl' or 'components'")
        growing = argv[at + 1]
        del argv[at : at + 2]
    print(f"CVFH with region_growing={growing!r}")

    def make():
        from eppf.descriptors._cvfh import CVFHTransformer

        return CVFHTransformer(
            aggregate="first", eps_angle=float(np.deg2rad(5.0)), curvature_threshold=1.0,
            region_growing=growing, normalize_bins=False, normalize=False, n_jobs=1,
        )

    compare_main(argv, key="cvfh", make=make)


if __name__ == "__main__":
    main()
