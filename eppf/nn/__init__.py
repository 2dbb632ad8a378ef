"""Neural-network building blocks: a 4D convolution, the paper's networks, PointNet.

Importing this subpackage imports torch (``import eppf`` does not).

How we read Table I
-------------------
* Convolutions use stride 1 and zero "same" padding (TensorFlow's convention,
  the extra zero after for even kernels), each followed by a ReLU.
* 4D network: two :class:`Conv4d` layers (32 and 64 filters, kernel
  (5, 2, 2, 1)) on the (N1, N2, N3, N4) histogram; each channel's 4D
  response is then reshaped in C order to the plane that the 2D network
  uses (see :func:`plane_shape`; (40, 30) for 1,200 bins), followed by a 5x5
  2D convolution of 48 filters.
* 2D network: the flat descriptor reshaped in C order to :func:`plane_shape`,
  three 5x5 convolutions of 32, 64 and 48 filters.
* 3D network: the descriptor reshaped to (N1, N2, N3 * N4) ((20, 4, 15) for
  the default bins), three convolutions of kernel (5, 5, 1).
* One 2x2 max-pool of stride 2 over the first two spatial axes (for the 3D
  network the third is left alone), rounding up as TensorFlow's "same"
  pooling does, so no bin row is dropped for odd sizes.
* Dense layer of ``n_hidden=1024`` units (ReLU), dropout, dense to the
  classes. The dense layer's input size is computed: with the sizes above it
  is 48 * 20 * 15 = 14,400 for every variant on 1,200 bins. Table I prints
  "(192, 1024)", which no consistent reading of the table reproduces, and the
  authors' public code flattens 30 x 40 x 48 = 57,600 values; we keep the
  table's layers and let the size follow from them.

How the 4D network's convolutions are computed
----------------------------------------------
``EPPFNet4D(conv_impl="auto")`` (the default) runs its second 4D convolution
and its 5x5 convolution in the frequency domain and the first, single-channel
layer directly, in float32 and where a layer mixes at least 2,048 channel
pairs (the paper's filters), or 512 in a training step (where gradients are
recorded: the recommended recipe's narrower layers train in the frequency
domain and predict directly, the faster way for each); bfloat16 mixed
precision stays direct, since there the frequency domain was measured no
faster (``conv_impl="direct"`` and ``"spectral"`` force one way for all
three; :class:`Conv4d` and :func:`conv4d` take the same option). The
frequency-domain form is the same convolution up to floating-point rounding
(relative differences about 1e-6 in float32, forward and gradients) with 4.9
and 3.8 times fewer multiply-adds for the two layers; the parameters, their
names and shapes do not change, so a network trained one way runs the other.
Its Fourier transforms are small dense matrix products on a spatial-major
memory layout (nothing CPU-specific: the same code runs on CUDA), and under
bfloat16 mixed precision these layers compute in float32. Networks unpickled
from before the option existed run directly.

Parameter counts for 10 classes (dense layer of 1,024 units):

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
