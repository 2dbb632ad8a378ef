"""Neural-network building blocks: a 4D convolution and the paper's networks.

Importing this subpackage imports torch.
"""

from ._conv4d import Conv4d, conv4d, same_padding
from ._data import DescriptorPoolDataset
from ._networks import EPPFNet2D, EPPFNet3D, EPPFNet4D, check_n_bins, count_parameters, plane_shape

__all__ = [
    "Conv4d",
    "DescriptorPoolDataset",
    "EPPFNet2D",
    "EPPFNet3D",
    "EPPFNet4D",
    "check_n_bins",
    "conv4d",
    "count_parameters",
    "plane_shape",
    "same_padding",
]
