"""Neural classifiers: the paper's EPPF networks on descriptors, and PointNet on raw points.

Both wrap skorch (they do not subclass it) through one base class
(``_base.SkorchClassifierBase``): labels encoded to int64 with ``classes_``
kept, a seeded stratified validation split for early stopping, a time budget,
a one-line-per-epoch log with ``verbose=1``, torch seeded from
``random_state`` and its thread count restored after ``fit`` and ``predict``,
predictions mapped back to the original labels. Their torch modules are
plain classes in :mod:`eppf.nn`; importing this subpackage imports neither
torch nor skorch (``fit`` does).
"""

from ._eppf_cnn import EPPF4DClassifier
from ._pointnet import PointNetClassifier

__all__ = ["EPPF4DClassifier", "PointNetClassifier"]
