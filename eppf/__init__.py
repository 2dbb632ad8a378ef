"""eppf: noise-resistant 3D object classification and retrieval with the EPPF descriptor.

A scikit-learn compatible toolkit implementing Bobkov et al., "Noise-resistant
Deep Learning for Object Classification in 3D Point Clouds Using a Point Pair
Descriptor", IEEE Robotics and Automation Letters, 2018.
"""

from ._version import __version__

from ._command import command_interrupt_guard as _command_interrupt_guard

# The imports take about a second: Ctrl-C then ends the eppf command with its one line, not a traceback
with _command_interrupt_guard():
    from .utils._simd import simd_cap as _simd_cap

    _simd_cap()  # a wrong EPPF_SIMD is an error before any kernel reads it

    from .descriptors import FUNCTIONS, EPPFTransformer, ESFTransformer, OURCVFHTransformer, WahlTransformer
    from .descriptors import CVFHTransformer, GASDTransformer, GRSDTransformer, VFHTransformer
    from .descriptors import descriptor_pool
    from .neighbors import KLNearestNeighbors, symmetric_kl_distances
    from .classifiers import EPPF4DClassifier, PointNetClassifier
    from .preprocessing import estimate_normals

    from ._persist import load_model, save_model
    from ._simd import simd_levels
    from .streaming import describe_files

__all__ = [
    "CVFHTransformer",
    "EPPF4DClassifier",
    "EPPFTransformer",
    "ESFTransformer",
    "FUNCTIONS",
    "GASDTransformer",
    "GRSDTransformer",
    "KLNearestNeighbors",
    "OURCVFHTransformer",
    "PointNetClassifier",
    "VFHTransformer",
    "WahlTransformer",
    "describe_files",
    "descriptor_pool",
    "estimate_normals",
    "load_model",
    "save_model",
    "simd_levels",
    "symmetric_kl_distances",
]
