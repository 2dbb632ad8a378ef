"""Neural-network building blocks: a 4D convolution, the paper's networks, PointNet.

Importing this subpackage imports torch (``import eppf`` does not).

Parameter counts for 10 classes (dense layer of 1,024 units; how Table I is
read is documented in ``eppf.nn._networks``):

=================  ============  ==================  ===========
bins               variant       dense-layer input   parameters
=================  ============  ==================  ===========
(20, 4, 5, 3)      EPPFNet2D     48 x 20 x 15        14,885,818
(20, 4, 5, 3)      EPPFNet3D     48 x 10 x 2 x 15    14,885,818
(20, 4, 5, 3)      EPPFNet4D     48 x 20 x 15        14,875,418
(15, 3, 4, 3)      EPPFNet2D     48 x 14 x 10         7,021,498
(15, 3, 4, 3)      EPPFNet3D     48 x 8 x 2 x 12      9,577,402
(15, 3, 4, 3)      EPPFNet4D     48 x 14 x 10         7,011,098
=================  ============  ==================  ===========
"""

from ._conv4d import Conv4d, conv4d, same_padding
from ._data import AugmentedPointClouds, DescriptorPoolDataset
from ._networks import (
    EPPFNet2D,
    EPPFNet3D,
    EPPFNet4D,
    check_n_bins,
    count_parameters,
    plane_shape,
)
from ._pointnet import PointNet, PointNetLoss, TNet, orthogonality_penalty
from ._precision import BFloat16EmulationWarning, check_precision, native_bfloat16, resolve_precision

__all__ = [
    "AugmentedPointClouds",
    "BFloat16EmulationWarning",
    "Conv4d",
    "DescriptorPoolDataset",
    "EPPFNet2D",
    "EPPFNet3D",
    "EPPFNet4D",
    "PointNet",
    "PointNetLoss",
    "TNet",
    "check_n_bins",
    "check_precision",
    "conv4d",
    "count_parameters",
    "native_bfloat16",
    "orthogonality_penalty",
    "plane_shape",
    "resolve_precision",
    "same_padding",
]
