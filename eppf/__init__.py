"""eppf: noise-resistant 3D object classification and retrieval with the EPPF descriptor.

A scikit-learn compatible toolkit implementing Bobkov et al., "Noise-resistant
Deep Learning for Object Classification in 3D Point Clouds Using a Point Pair
Descriptor", IEEE Robotics and Automation Letters, 2018.
"""

__version__ = "0.1.0"

from ._descriptor import FUNCTIONS, EPPFTransformer
from ._neighbors import KLNearestNeighbors, symmetric_kl_distances
from ._cnn import EPPF4DClassifier
from ._pool import descriptor_pool

from ._esf import ESFTransformer
from ._ourcvfh import OURCVFHTransformer
from ._wahl import WahlTransformer
from ._normals import estimate_normals
from ._pointnet import PointNetClassifier
from ._persist import load_model, save_model

__all__ = ["EPPF4DClassifier", "EPPFTransformer", "ESFTransformer", "FUNCTIONS", "KLNearestNeighbors", "OURCVFHTransformer", "PointNetClassifier", "WahlTransformer", "descriptor_pool", "estimate_normals", "load_model", "save_model", "symmetric_kl_distances"]
