"""Neural classifiers: the paper's EPPF networks on descriptors, and PointNet on raw points.

Both wrap skorch (they do not subclass it): float32 input, labels encoded to
int64 with ``classes_`` kept, a validation split chosen on purpose for early
stopping, torch seeded from ``random_state``, predictions mapped back to the
original labels.
"""

from ._eppf_cnn import EPPF4DClassifier
from ._pointnet import PointNetClassifier

__all__ = ["EPPF4DClassifier", "PointNetClassifier"]
