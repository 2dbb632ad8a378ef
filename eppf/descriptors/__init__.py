"""Global descriptors of point clouds, as scikit-learn transformers.

Every transformer takes a list of point clouds (arrays of shape (n_i, 3), or
(n_i, 6) with normals) and returns one row per object. Each descriptor lives in
its own module with its compiled kernel beside it (``_esf.py`` over
``_esf_fast.pyx``):

- :class:`EPPFTransformer`: the paper's extended point-pair feature histogram;
- :class:`ESFTransformer`: Ensemble of Shape Functions (Wohlkinger & Vincze 2011);
- :class:`WahlTransformer`: surflet-pair relation histograms (Wahl et al. 2003);
- :class:`OURCVFHTransformer`: oriented, unique and repeatable clustered VFH
  (Aldoma et al. 2012);
- :class:`VFHTransformer`: Viewpoint Feature Histogram (Rusu et al. 2010);
- :class:`CVFHTransformer`: Clustered VFH (Aldoma et al. 2011);
- :class:`GRSDTransformer`: Global Radius-based Surface Descriptor (Marton et al. 2010);
- :class:`GASDTransformer`, :class:`GASDColorTransformer`: Globally Aligned
  Spatial Distribution (Lima & Teichrieb 2016), shape and shape + color;
- :class:`DescriptorUnion`: several descriptors weighted into one row;
  :class:`EPPFGASDTransformer`, its measured EPPF + GASD preset;
- :func:`descriptor_pool`: several seeded draws of one descriptor per object;
  :class:`DescriptorPool`, the same as a pipeline step;
- :class:`CachedTransformer`: a descriptor's output cached on disk;
- :class:`ProportionTransformer`: six scale-invariant proportions (a side input).
"""

from ._eppf import FUNCTIONS, EPPFTransformer
from ._cached import CachedTransformer
from ._cvfh import CVFHTransformer
from ._esf import ESFTransformer
from ._gasd import GASDColorTransformer, GASDTransformer, gasd_alignment
from ._grsd import GRSDTransformer
from ._ourcvfh import OURCVFHTransformer
from ._pool import DescriptorPool, descriptor_pool
from ._proportions import ProportionTransformer
from ._union import DescriptorUnion, EPPFGASDTransformer
from ._vfh import VFHTransformer
from ._wahl import WahlTransformer

__all__ = [
    "CVFHTransformer",
    "CachedTransformer",
    "DescriptorPool",
    "DescriptorUnion",
    "EPPFTransformer",
    "EPPFGASDTransformer",
    "ESFTransformer",
    "FUNCTIONS",
    "GASDColorTransformer",
    "GASDTransformer",
    "GRSDTransformer",
    "OURCVFHTransformer",
    "ProportionTransformer",
    "VFHTransformer",
    "WahlTransformer",
    "descriptor_pool",
    "gasd_alignment",
]
