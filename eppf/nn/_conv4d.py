"""A real four-dimensional convolution built from ``conv3d``.

PyTorch has no ``conv4d``. A 4D convolution with kernel ``(k1, k2, k3, k4)``
is a sum over the ``k4`` taps of 3D convolutions, each applied to the input
shifted by that tap along the fourth axis. Folding the fourth axis into the
batch turns every shifted slice into an ordinary 3D volume, and stacking the
``k4`` shifted copies along the channel axis lets one ``conv3d`` call do the
whole sum (the "general path"). When ``k4 == 1`` no shifted copies are needed:
the fourth axis is folded into the batch and a single ``conv3d`` with the
unchanged weight does the work (the "fast path"), which is the case of the
paper's (5, 2, 2, 1) kernels.

Either path can instead run in the frequency domain (``conv_impl``, see
:mod:`eppf.nn._spectral`): the same convolution up to rounding with several
times fewer multiply-adds for layers of many channels.
"""

import math
import numbers

import torch
import torch.nn.functional as F
from torch import nn

from ..utils._param_validation import Interval, IntTuple, StrOptions, validate_parameter
from ._spectral import PATCH_MAX_TAPS, choose_impl, is_spatial_major, patch_conv, spectral_conv

__all__ = ["Conv4d", "conv4d", "same_padding"]


def same_padding(kernel_size):
    """Zero padding before and after one axis for "same" output size.

    Follows TensorFlow's convention for stride 1: the total padding is
    ``kernel_size - 1``; when it is odd, the extra zero goes after.

    Parameters
    ----------
    kernel_size : int
        Kernel extent along the axis.

    Returns
    -------
    before, after : int
        Zeros to add before and after the axis.

    Examples
    --------
    >>> from eppf.nn import same_padding
    >>> same_padding(5), same_padding(2), same_padding(1)
    ((2, 2), (0, 1), (0, 0))
    """
    total = int(kernel_size) - 1
    before = total // 2
    return before, total - before


def _check_input(input, weight, bias):
    if input.dim() != 6:
        raise ValueError(
            f"conv4d: input must have shape (batch, channels, n1, n2, n3, n4), got {tuple(input.shape)}"
        )
    if weight.dim() != 6:
        raise ValueError(
            f"conv4d: weight must have shape (out_channels, in_channels, k1, k2, k3, k4), got {tuple(weight.shape)}"
        )
    if input.shape[1] != weight.shape[1]:
        raise ValueError(
            f"conv4d: input has {input.shape[1]} channels but weight expects {weight.shape[1]}"
        )
    if bias is not None and tuple(bias.shape) != (weight.shape[0],):
        raise ValueError(f"conv4d: bias must have shape ({weight.shape[0]},), got {tuple(bias.shape)}")


def _pad_first_three(input, kernel):
    """Zero-pad axes n1, n2, n3 of a (B, C, n1, n2, n3) tensor for "same" output (both axes of a 2D kernel)."""
    pads = []
    for k in reversed(kernel[:3]):  # F.pad lists the last axis first
        pads.extend(same_padding(k))
    if any(pads):
        input = F.pad(input, pads)
    return input


def same_conv(input, weight, bias=None):
    """Stride-1 "same" ``conv2d`` or ``conv3d`` (by the weight's rank), padded as :func:`same_padding` says.

    With autograd recording, the input is zero-padded first (one copy) and
    convolved unpadded, the way the layers have always trained. Without it
    (prediction: :func:`torch.no_grad` or :func:`torch.inference_mode`) the
    convolution pads the symmetric part itself and only the extra zero after
    an even kernel is a copy: for the recipe's 5 x 5 layer no copy at all.
    The values are the same bits either way (oneDNN adds the same products in
    the same order; the zeros it skips add nothing), and prediction saves
    the padded copies and their conversions to oneDNN's blocked layouts.

    Parameters
    ----------
    input : torch.Tensor of shape (batch, in_channels, *spatial)
        Two or three spatial axes.
    weight : torch.Tensor of shape (out_channels, in_channels, *kernel)
    bias : torch.Tensor of shape (out_channels,), default=None

    Returns
    -------
    output : torch.Tensor of shape (batch, out_channels, *spatial)
    """
    kernel = weight.shape[2:]
    conv = F.conv3d if len(kernel) == 3 else F.conv2d
    if torch.is_grad_enabled():
        return conv(_pad_first_three(input, kernel), weight, bias)
    pads = [same_padding(k) for k in kernel]
    inner = tuple(before for before, _ in pads)  # (same_padding: before <= after)
    extra = [p for before, after in reversed(pads) for p in (0, after - before)]
    if any(extra):
        input = F.pad(input, extra)
    return conv(input, weight, bias, padding=inner)


def _fold_last_axis(input):
    """(B, C, n1, n2, n3, n4) -> (B * n4, C, n1, n2, n3), fourth axis into the batch."""
    b, c, n1, n2, n3, n4 = input.shape
    return input.permute(0, 5, 1, 2, 3, 4).reshape(b * n4, c, n1, n2, n3)


def _unfold_last_axis(output, batch, n4):
    """(B * n4, O, n1, n2, n3) -> (B, O, n1, n2, n3, n4)."""
    _, o, n1, n2, n3 = output.shape
    return output.reshape(batch, n4, o, n1, n2, n3).permute(0, 2, 3, 4, 5, 1)


def _conv3d(input, weight, bias, conv_impl):
    """"Same" conv3d of a (B, C, n1, n2, n3) tensor, direct or in the frequency domain.

    A direct convolution of a spatial-major input (as the frequency-domain
    layers return) with few input channels keeps that layout (:func:`patch_conv`).
    """
    impl = choose_impl(conv_impl, input.shape[2:], weight.shape[2:], weight.shape[1], weight.shape[0])
    if impl == "spectral":
        return spectral_conv(input, weight, bias)
    if weight.shape[1:].numel() <= PATCH_MAX_TAPS and is_spatial_major(input):
        return patch_conv(input, weight, bias)
    return same_conv(input, weight, bias)


def _conv4d_fast(input, weight, bias, conv_impl="direct"):
    """Kernel of size 1 along the fourth axis: one conv3d over the folded batch."""
    batch, n4 = input.shape[0], input.shape[5]
    out = _conv3d(_fold_last_axis(input), weight[..., 0], bias, conv_impl)
    return _unfold_last_axis(out, batch, n4)


def _conv4d_general(input, weight, bias, conv_impl="direct"):
    """Any kernel: the k4 shifted copies of the input are stacked as channels."""
    if choose_impl(conv_impl, input.shape[2:], weight.shape[2:], weight.shape[1], weight.shape[0]) == "spectral":
        return spectral_conv(input, weight, bias)  # all four axes in the frequency domain
    batch, c = input.shape[0], input.shape[1]
    n4 = input.shape[5]
    k4 = weight.shape[5]
    before, after = same_padding(k4)
    padded = F.pad(input, (before, after)) if (before or after) else input
    # shifted[..., t, l] = padded[..., l + t]: tap t of the kernel meets it at output l.
    shifted = torch.stack([padded[..., t : t + n4] for t in range(k4)], dim=2)
    # (B, C, k4, n1, n2, n3, n4) -> (B * n4, C * k4, n1, n2, n3)
    _, _, _, n1, n2, n3, _ = shifted.shape
    folded = shifted.permute(0, 6, 1, 2, 3, 4, 5).reshape(batch * n4, c * k4, n1, n2, n3)
    folded = _pad_first_three(folded, weight.shape[2:])
    # weight (O, C, k1, k2, k3, k4) -> (O, C * k4, k1, k2, k3) with the same (C, k4) order.
    w = weight.permute(0, 1, 5, 2, 3, 4).reshape(weight.shape[0], c * k4, *weight.shape[2:5])
    out = F.conv3d(folded, w, bias)
    return _unfold_last_axis(out, batch, n4)


def conv4d(input, weight, bias=None, *, path="auto", conv_impl="auto"):
    """Four-dimensional convolution, stride 1, zero "same" padding.

    Computes the cross-correlation (as every deep-learning framework does)

    ``out[b, o, x] = bias[o] + sum_{c, t} weight[o, c, t] * in_pad[b, c, x + t]``

    over the four spatial axes, where ``in_pad`` is the input padded with
    zeros as :func:`same_padding` says, so the output has the input's spatial
    shape.

    Parameters
    ----------
    input : torch.Tensor of shape (batch, in_channels, n1, n2, n3, n4)
        Input volume.
    weight : torch.Tensor of shape (out_channels, in_channels, k1, k2, k3, k4)
        Filters; any positive kernel size, even ones included.
    bias : torch.Tensor of shape (out_channels,), default=None
        Added once per output channel.
    path : {"auto", "fast", "general"}, default="auto"
        ``"fast"`` needs ``k4 == 1`` and runs one ``conv3d`` with the fourth
        axis folded into the batch; ``"general"`` stacks the ``k4`` shifted
        copies of the input as channels (any kernel); ``"auto"`` takes the
        fast path whenever it applies.
    conv_impl : {"auto", "direct", "spectral"}, default="auto"
        ``"direct"`` runs ``conv3d``; ``"spectral"`` computes the same
        convolution in the frequency domain (three of the axes on the fast
        path, all four on the general one; equal up to rounding, several times
        fewer multiply-adds for layers with many channels, computed in
        float32 under bfloat16 autocast); ``"auto"`` takes the frequency
        domain where it saves at least 2.5 times the multiply-adds and the
        layer mixes at least 2,048 input x output channel pairs (512 where
        gradients are recorded, as in a training step), and never under
        autocast (see :func:`eppf.nn._spectral.choose_impl`).

    Returns
    -------
    output : torch.Tensor of shape (batch, out_channels, n1, n2, n3, n4)
        Convolution result.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import conv4d
    >>> x = torch.ones(1, 1, 3, 3, 3, 3)
    >>> w = torch.ones(1, 1, 3, 3, 3, 3)
    >>> conv4d(x, w)[0, 0, 1, 1, 1, 1].item()  # interior: all 81 taps see a one
    81.0
    """
    _check_input(input, weight, bias)
    validate_parameter(path, CONSTRAINTS["path"], name="path", owner="conv4d")
    validate_parameter(conv_impl, CONSTRAINTS["conv_impl"], name="conv_impl", owner="conv4d")
    if path == "fast" and weight.shape[5] != 1:
        raise ValueError(
            f"conv4d: the fast path needs a kernel of size 1 along the fourth axis, got {tuple(weight.shape[2:])}"
        )
    if path == "fast" or (path == "auto" and weight.shape[5] == 1):
        return _conv4d_fast(input, weight, bias, conv_impl)
    return _conv4d_general(input, weight, bias, conv_impl)


#: The parameters of :func:`conv4d` and :class:`Conv4d`, declared once.
CONSTRAINTS = {
    "in_channels": [Interval(numbers.Integral, 1, None, closed="left", description="a positive int")],
    "out_channels": [Interval(numbers.Integral, 1, None, closed="left", description="a positive int")],
    "kernel_size": [Interval(numbers.Integral, 1, None, closed="left"),
                    IntTuple(4, 1, None, description="a tuple of 4 positive ints")],
    "path": [StrOptions({"auto", "fast", "general"})],
    "conv_impl": [StrOptions({"auto", "direct", "spectral"})],
}


def _check_kernel_size(kernel_size):
    kernel_size = validate_parameter(kernel_size, CONSTRAINTS["kernel_size"], name="kernel_size", owner="Conv4d")
    if isinstance(kernel_size, numbers.Integral):
        return (int(kernel_size),) * 4
    return tuple(int(k) for k in kernel_size)


class Conv4d(nn.Module):
    """Four-dimensional convolution layer (stride 1, zero "same" padding).

    The layer the paper uses on the 4D EPPF histogram. PyTorch has no 4D
    convolution; this one is exact for any kernel size and is built from
    ``conv3d`` (see :func:`conv4d`). With a kernel of size 1 along the last
    axis, as the paper's (5, 2, 2, 1), it runs a single ``conv3d`` with the
    last axis folded into the batch.

    Parameters
    ----------
    in_channels : int
        Channels of the input.
    out_channels : int
        Number of filters.
    kernel_size : int or tuple of 4 ints
        Kernel extent along the four spatial axes. Even sizes are padded as
        TensorFlow does: the extra zero goes after.
    bias : bool, default=True
        Whether to learn one additive bias per filter.
    conv_impl : {"auto", "direct", "spectral"}, default="auto"
        Direct ``conv3d`` or the same convolution in the frequency domain
        (see :func:`conv4d`); ``"auto"`` chooses by the layer's shape on
        every call. The parameters are the same either way.

    Attributes
    ----------
    weight : torch.nn.Parameter of shape (out_channels, in_channels, k1, k2, k3, k4)
        Filters, initialized as ``torch.nn.Conv3d`` initializes its own
        (Kaiming uniform over the fan-in ``in_channels * k1 * k2 * k3 * k4``).
    bias : torch.nn.Parameter of shape (out_channels,) or None
        Per-filter bias.

    See Also
    --------
    conv4d : The functional form.

    References
    ----------
    .. [1] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 3(2), 2018.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import Conv4d
    >>> layer = Conv4d(1, 32, (5, 2, 2, 1))
    >>> layer(torch.zeros(8, 1, 20, 4, 5, 3)).shape
    torch.Size([8, 32, 20, 4, 5, 3])
    """

    def __init__(self, in_channels, out_channels, kernel_size, bias=True, *, conv_impl="auto"):
        super().__init__()
        for name, value in (("in_channels", in_channels), ("out_channels", out_channels), ("conv_impl", conv_impl)):
            validate_parameter(value, CONSTRAINTS[name], name=name, owner="Conv4d")
        self.conv_impl = conv_impl
        self.in_channels = int(in_channels)
        self.out_channels = int(out_channels)
        self.kernel_size = _check_kernel_size(kernel_size)
        self.weight = nn.Parameter(torch.empty(self.out_channels, self.in_channels, *self.kernel_size))
        self.bias = nn.Parameter(torch.empty(self.out_channels)) if bias else None
        self.reset_parameters()

    def reset_parameters(self):
        """Initialize weight and bias as ``torch.nn.Conv3d`` does."""
        nn.init.kaiming_uniform_(self.weight, a=math.sqrt(5))
        if self.bias is not None:
            fan_in = self.in_channels * math.prod(self.kernel_size)
            bound = 1.0 / math.sqrt(fan_in)
            nn.init.uniform_(self.bias, -bound, bound)

    def forward(self, input):
        """Convolve a (batch, in_channels, n1, n2, n3, n4) tensor."""
        return conv4d(input, self.weight, self.bias, conv_impl=self._impl())

    def _impl(self):
        # (getattr: layers pickled before the option existed ran conv3d)
        return getattr(self, "conv_impl", "direct")

    def impl_for(self, spatial):
        """The implementation ``forward_folded`` runs on inputs of these three spatial sizes.

        Parameters
        ----------
        spatial : tuple of 3 ints
            (n1, n2, n3).

        Returns
        -------
        impl : {"direct", "spectral"}
            ``conv_impl`` itself unless it is ``"auto"``, then the choice
            that the layer's shape makes.
        """
        return choose_impl(self._impl(), tuple(spatial), self.kernel_size[:3], self.in_channels, self.out_channels)

    def forward_folded(self, input):
        """Convolve an input whose fourth axis is already folded into the batch.

        Only for kernels of size 1 along the fourth axis. Networks that stack
        such layers keep the folded (batch * n4, channels, n1, n2, n3) layout
        between them and skip the permutations around every layer. The
        frequency-domain implementation returns its result laid out
        spatial-major in memory (see :func:`eppf.nn._spectral.spectral_conv`).

        Parameters
        ----------
        input : torch.Tensor of shape (batch * n4, in_channels, n1, n2, n3)

        Returns
        -------
        output : torch.Tensor of shape (batch * n4, out_channels, n1, n2, n3)
        """
        if self.kernel_size[3] != 1:
            raise ValueError(f"Conv4d: forward_folded needs a kernel of size 1 along the fourth axis, got {self.kernel_size}")
        return _conv3d(input, self.weight[..., 0], self.bias, self._impl())

    def extra_repr(self):
        return (
            f"{self.in_channels}, {self.out_channels}, kernel_size={self.kernel_size}, "
            f"padding='same', bias={self.bias is not None}, conv_impl={self._impl()!r}"
        )
