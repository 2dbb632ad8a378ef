"""The paper's 2D, 3D and 4D classification networks (Table I).

All three take a batch of flat descriptors of length ``prod(n_bins)`` in C
order over (f1, f2, f3, f4), f4 fastest, and return class logits. Layer sizes
follow from ``n_bins``; nothing is hard-coded to the (20, 4, 5, 3) histogram.

How Table I is read is documented in :mod:`eppf.nn`.

A network of more than a billion parameters (:data:`MAX_PARAMETERS`; the
paper's 4D network has 15 million) is refused with a ValueError naming its
sizes before any layer is built.

Precision
---------
Every network takes ``precision="float32"`` (default) or ``"bfloat16"``. The
latter runs the forward pass under :func:`torch.autocast` with bfloat16:
convolutions and dense layers multiply in bfloat16 (and their backward
passes follow), while the parameters, their gradients, the optimizer state
and the returned logits stay float32 ("mixed precision"). On hardware with
native bfloat16 arithmetic (see :func:`native_bfloat16`) it trains markedly
faster; elsewhere PyTorch emulates it and it is slower. Results differ from
float32 by bfloat16's rounding (8 significant bits). The estimators'
``precision="auto"`` picks one of the two by :func:`resolve_precision`; a
network itself needs a concrete precision.
"""

import math
import numbers

import torch
from torch import nn

from ..utils._param_validation import Interval, IntTuple, Options, StrOptions, validate_parameter
from ..utils._validation import MAX_PARAMETERS
from ._conv4d import Conv4d, same_conv, same_padding
from ._precision import check_precision
from ._spectral import choose_impl, spectral_conv

__all__ = [
    "EPPFNet2D",
    "EPPFNet3D",
    "EPPFNet4D",
    "check_n_bins",
    "check_precision",
    "count_parameters",
    "plane_shape",
]


#: What the networks' parameters accept (:mod:`eppf.utils._param_validation`);
#: the classifiers that build them declare the same lists.
NETWORK_CONSTRAINTS = {
    "n_bins": [IntTuple(4, 1, None, description="a tuple of 4 positive ints")],
    "n_classes": [Interval(numbers.Integral, 2, None, closed="left")],
    "dropout": [Interval(numbers.Real, 0, 1, closed="left", description="a float in [0, 1)")],
    "filters": [IntTuple(3, 1, None, description="a tuple of 3 positive ints")],
    "n_hidden": [Interval(numbers.Integral, 1, None, closed="left", description="a positive int")],
    "n_side": [Interval(numbers.Integral, 0, None, closed="left")],
    "side_hidden": [Interval(numbers.Integral, 1, None, closed="left")],
    "batch_norm": [Options(bool)],
    "conv_impl": [StrOptions({"auto", "direct", "spectral"})],
}


def check_network_values(owner, **values):
    """Check each named value against :data:`NETWORK_CONSTRAINTS` (an error naming ``owner``)."""
    for name, value in values.items():
        validate_parameter(value, NETWORK_CONSTRAINTS[name], name=name, owner=owner)


def check_n_bins(n_bins, *, owner=None):
    """Validate a tuple of four positive bin counts.

    Parameters
    ----------
    n_bins : tuple of 4 ints
        Bins along (f1, f2, f3, f4).
    owner : str, default=None
        Name used in error messages.

    Returns
    -------
    n_bins : tuple of 4 ints

    Examples
    --------
    >>> from eppf.nn import check_n_bins
    >>> check_n_bins([15, 3, 4, 3])
    (15, 3, 4, 3)
    >>> check_n_bins((20, 4, 5), owner="MyNet")
    Traceback (most recent call last):
        ...
    eppf.utils._param_validation.InvalidParameterError: MyNet: n_bins must be a tuple of 4 positive ints, got (20, 4, 5)
    """
    check_network_values(owner or "check_n_bins", n_bins=n_bins)
    return tuple(int(v) for v in n_bins)


def plane_shape(n_features):
    """Most nearly square (rows, cols) with rows * cols == n_features, rows >= cols.

    The paper reshapes its 1,200 bins to (40, 30); this rule gives that plane
    and generalizes it to other bin counts (540 -> (27, 20)).

    Parameters
    ----------
    n_features : int
        Number of descriptor bins.

    Returns
    -------
    rows, cols : int

    Examples
    --------
    >>> from eppf.nn import plane_shape
    >>> plane_shape(1200), plane_shape(540), plane_shape(7)
    ((40, 30), (27, 20), (7, 1))
    """
    n = int(n_features)
    if n < 1:
        raise ValueError(f"plane_shape: n_features must be positive, got {n_features!r}")
    cols = max(d for d in range(1, math.isqrt(n) + 1) if n % d == 0)
    return n // cols, cols


def count_parameters(module):
    """Number of trainable parameters of a torch module.

    Parameters
    ----------
    module : torch.nn.Module

    Returns
    -------
    n : int

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import count_parameters
    >>> count_parameters(torch.nn.Linear(10, 3))  # 10 * 3 weights + 3 biases
    33
    """
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


class _SamePadConv(nn.Module):
    """2D or 3D convolution, stride 1, TensorFlow "same" padding (extra zero after).

    ``conv_impl`` ("auto", "direct" or "spectral", see :func:`eppf.nn.conv4d`)
    chooses between ``self.conv`` and the same convolution in the frequency
    domain with ``self.conv``'s parameters.
    """

    def __init__(self, in_channels, out_channels, kernel_size, conv_impl="direct"):
        super().__init__()
        kernel_size = tuple(int(k) for k in kernel_size)
        pads = []
        for k in reversed(kernel_size):
            pads.extend(same_padding(k))
        self.pad = nn.ZeroPad3d(pads) if len(kernel_size) == 3 else nn.ZeroPad2d(pads)
        conv = nn.Conv3d if len(kernel_size) == 3 else nn.Conv2d
        self.conv = conv(in_channels, out_channels, kernel_size)
        self.conv_impl = conv_impl

    def impl_for(self, spatial):
        """``"direct"`` or ``"spectral"``: what ``forward`` runs on inputs of these spatial sizes."""
        # (getattr: layers pickled before the option existed ran the direct convolution)
        return choose_impl(getattr(self, "conv_impl", "direct"), tuple(spatial), self.conv.kernel_size,
                           self.conv.in_channels, self.conv.out_channels)

    def forward(self, x):
        if self.impl_for(x.shape[2:]) == "spectral":
            return spectral_conv(x, self.conv.weight, self.conv.bias)
        if torch.is_grad_enabled():
            return self.conv(self.pad(x))
        return same_conv(x, self.conv.weight, self.conv.bias)  # (the padding inside the convolution)


def _check_network_args(owner, n_bins, n_classes, dropout, filters, n_hidden):
    check_network_values(owner, n_bins=n_bins, n_classes=n_classes, dropout=dropout, filters=filters,
                         n_hidden=n_hidden)
    return tuple(int(b) for b in n_bins), int(n_classes), float(dropout), tuple(int(f) for f in filters), int(n_hidden)


def _check_options(owner, n_side, side_hidden, batch_norm):
    check_network_values(owner, n_side=n_side, side_hidden=side_hidden, batch_norm=batch_norm)
    return int(n_side), int(side_hidden), bool(batch_norm)


def parameter_lower_bound(n_bins, n_hidden, n_classes, filters, n_side, side_hidden):
    """A lower bound of the parameter count of the 2D, 3D and 4D networks, in Python ints.

    The layers' own shapes could overflow torch's 64-bit sizes, so sizes are
    bounded from this before any layer is built: every convolution has at
    least in * out weights, and the first dense layer reads at least
    ``filters[2] * ceil(prod(n_bins) / 4)`` values (the 2 x 2 max-pool of the
    plane or volume of ``prod(n_bins)`` cells), plus the side branch's units.
    """
    f0, f1, f2 = (int(f) for f in filters)
    n_hidden, n_side, side_hidden = int(n_hidden), int(n_side), int(side_hidden)
    n_in = f2 * -(-math.prod(int(b) for b in n_bins) // 4) + (side_hidden if n_side else 0)
    return f0 + f0 * f1 + f1 * f2 + n_side * side_hidden + n_in * n_hidden + n_hidden * int(n_classes)


def _check_size(owner, n_bins, n_hidden, n_classes, filters, n_side, side_hidden):
    """A ValueError naming ``owner`` and the sizes when the network would certainly exceed :data:`MAX_PARAMETERS`."""
    lower = parameter_lower_bound(n_bins, n_hidden, n_classes, filters, n_side, side_hidden)
    if lower > MAX_PARAMETERS:
        raise ValueError(
            f"{owner}: the network would have at least {lower:,} parameters (n_bins={n_bins}, filters={filters}, "
            f"n_hidden={n_hidden}, n_classes={n_classes}), more than the {MAX_PARAMETERS:,} it may have "
            "(4 GB of float32 weights); use smaller layers"
        )


class _MaxPool2d(nn.MaxPool2d):
    """``MaxPool2d`` that pools a spatial-major tensor from a channels-last copy.

    A (batch, C, rows, cols) tensor laid out (rows, cols, C, batch) in memory,
    as the frequency-domain convolution returns it, would be copied to the
    contiguous layout, where ``max_pool2d`` is slow; the channels-last copy
    costs as much and pools several times faster (same values and gradients).
    """

    def forward(self, x):
        if x.dim() == 4 and x.permute(2, 3, 1, 0).is_contiguous():
            x = x.contiguous(memory_format=torch.channels_last)
        return super().forward(x)


class _ChannelNorm(nn.BatchNorm1d):
    """Batch normalization over dimension 1 of a tensor of any rank >= 2.

    ``torch.nn.functional.batch_norm`` normalizes every channel over all
    other axes whatever the rank; only the rank check of ``BatchNorm1d`` is
    relaxed, so the 4D network's (batch, C, n1, n2, n3) tensors need no copy.
    """

    def _check_input_dim(self, input):
        if input.dim() < 2:
            raise ValueError(f"_ChannelNorm: expected a tensor of rank >= 2, got {input.dim()}")


class _EPPFNetBase(nn.Module):
    """Shared head (max-pool, dense, dropout, dense), options and the precision switch.

    Subclasses implement ``_body``: the convolutions (each followed by
    :meth:`_act`) from a checked (batch, n_features) tensor to the head's
    input, and call :meth:`_init_options` before building their layers.
    """

    def _init_options(self, owner, n_side, side_hidden, batch_norm, filters, size):
        self.n_side, self.side_hidden, self.batch_norm = _check_options(owner, n_side, side_hidden, batch_norm)
        _check_size(owner, *size, filters, self.n_side, self.side_hidden)
        if self.batch_norm:
            self.norms = nn.ModuleList(_ChannelNorm(f) for f in filters)

    def _act(self, x, i):
        """ReLU after convolution ``i``, batch-normalized first when ``batch_norm``."""
        if getattr(self, "batch_norm", False):
            x = self.norms[i](x)
        # (in place when no gradient is recorded: x is the layer's own new output)
        return torch.relu(x) if torch.is_grad_enabled() else torch.relu_(x)

    def forward(self, x):
        """Logits, float32, for a (batch, prod(n_bins) + n_side) tensor: descriptors, then side features."""
        self._check_features(x)
        if x.shape[0] == 0:  # (the 4D network's folded layouts cannot reshape an empty batch)
            return x.new_zeros((0, self.fc2.out_features))
        n = self.n_features
        side = x[:, n:] if getattr(self, "n_side", 0) else None
        x = x[:, :n] if side is not None else x
        # (getattr: networks pickled before the option existed are float32)
        if getattr(self, "precision", "float32") == "float32":
            return self._head(self._body(x), side)
        with torch.autocast(device_type=x.device.type, dtype=torch.bfloat16):
            out = self._head(self._body(x), side)
        return out.float()

    def _build_head(self, n_channels, spatial, pool, n_hidden, dropout, n_classes):
        pool_layer = nn.MaxPool3d if len(pool) == 3 else _MaxPool2d
        self.pool = pool_layer(pool, stride=pool, ceil_mode=True)
        pooled = [math.ceil(s / p) for s, p in zip(spatial, pool)]
        self.n_flat = n_channels * math.prod(pooled)
        n_in = self.n_flat
        if getattr(self, "n_side", 0):
            self.side = nn.Sequential(nn.Linear(self.n_side, self.side_hidden), nn.ReLU())
            n_in += self.side_hidden
        self.fc1 = nn.Linear(n_in, n_hidden)
        self.dropout = nn.Dropout(dropout)
        self.fc2 = nn.Linear(n_hidden, n_classes)

    def _head(self, x, side=None):
        x = self.pool(x)
        x = torch.flatten(x, 1)
        if side is not None:
            x = torch.cat([x, self.side(side).to(x.dtype)], dim=1)
        x = self.dropout(torch.relu(self.fc1(x)))
        return self.fc2(x)

    def _check_features(self, x):
        n_side = getattr(self, "n_side", 0)
        if x.dim() != 2 or x.shape[1] != self.n_features + n_side:
            extra = f" + {n_side} side features" if n_side else ""
            raise ValueError(
                f"{type(self).__name__}: expected input of shape (batch, {self.n_features + n_side}) for n_bins="
                f"{self.n_bins}{extra}, got {tuple(x.shape)}"
            )
        weights = self.fc1.weight.dtype
        if x.dtype != weights:
            raise TypeError(
                f"{type(self).__name__}: expected a {str(weights).replace('torch.', '')} input, the dtype of the "
                f"network's parameters, got {str(x.dtype).replace('torch.', '')}; convert it with "
                f"x.to({weights})"
            )


class EPPFNet4D(_EPPFNetBase):
    """The paper's 4D network: two 4D convolutions, a 2D convolution, dense layers.

    Parameters
    ----------
    n_bins : tuple of 4 ints, default=(20, 4, 5, 3)
        Histogram bins along (f1, f2, f3, f4); the input is the flat
        descriptor in C order (f4 fastest).
    n_classes : int, default=10
        Number of output logits.
    dropout : float, default=0.5
        Dropout probability before the last dense layer.
    filters : tuple of 3 ints, default=(32, 64, 48)
        Filters of the two 4D and the 2D convolution.
    kernel_size : tuple of 4 ints, default=(5, 2, 2, 1)
        Kernel of both 4D convolutions.
    kernel_size_2d : tuple of 2 ints, default=(5, 5)
        Kernel of the 2D convolution.
    n_hidden : int, default=1024
        Units of the first dense layer.
    precision : {"float32", "bfloat16"}, default="float32"
        Arithmetic of the forward pass; "bfloat16" is mixed precision under
        :func:`torch.autocast` (see :func:`check_precision`).
    n_side : int, default=0
        Side features after the descriptor's bins in every input row (beyond
        the paper; 0 is Table I). They pass a dense layer of ``side_hidden``
        units with a ReLU whose output joins the flattened convolution
        features at the input of the first dense layer.
    side_hidden : int, default=128
        Units of the side branch (unused when ``n_side == 0``).
    batch_norm : bool, default=False
        Batch normalization between every convolution and its ReLU (beyond
        the paper).
    conv_impl : {"auto", "direct", "spectral"}, default="auto"
        How the three convolutions are computed: ``"direct"`` (``conv3d``,
        ``conv2d``) or ``"spectral"`` (the same convolutions in the frequency
        domain, equal up to rounding; see :func:`eppf.nn.conv4d`); ``"auto"``
        chooses per layer by its shape and the precision (for the default
        network in float32: the first layer direct, the other two in the
        frequency domain, 0.73-0.80 of the direct training time on 2 CPU
        cores; narrower layers, such as the recommended recipe's filters
        (16, 32, 24), train in the frequency domain (0.75 of the direct
        time on an AVX2-only CPU) and predict directly, and bfloat16
        autocast stays direct, where the frequency domain does not gain).
        Parameters and their names are the same
        whichever is chosen, so a trained network can run either way.

    Attributes
    ----------
    plane : tuple of 2 ints
        Plane the 4D responses are reshaped to (:func:`plane_shape`).
    n_flat : int
        Input size of the first dense layer.

    See Also
    --------
    EPPFNet2D, EPPFNet3D : The paper's comparison networks.

    Notes
    -----
    How Table I is read is documented in :mod:`eppf.nn`.
    With the default arguments the network has 14,875,418 parameters for 10
    classes; the dense layer (14,400 x 1,024) holds 99% of them.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import EPPFNet4D
    >>> net = EPPFNet4D(n_bins=(15, 3, 4, 3), n_classes=5)
    >>> net(torch.zeros(2, 540)).shape
    torch.Size([2, 5])
    """

    def __init__(
        self,
        n_bins=(20, 4, 5, 3),
        n_classes=10,
        dropout=0.5,
        filters=(32, 64, 48),
        kernel_size=(5, 2, 2, 1),
        kernel_size_2d=(5, 5),
        n_hidden=1024,
        precision="float32",
        *,
        n_side=0,
        side_hidden=128,
        batch_norm=False,
        conv_impl="auto",
    ):
        super().__init__()
        n_bins, n_classes, dropout, filters, n_hidden = _check_network_args(
            "EPPFNet4D", n_bins, n_classes, dropout, filters, n_hidden
        )
        check_network_values("EPPFNet4D", conv_impl=conv_impl)
        self.conv_impl = conv_impl
        self._init_options("EPPFNet4D", n_side, side_hidden, batch_norm, filters, size=(n_bins, n_hidden, n_classes))
        self.precision = check_precision(precision, owner="EPPFNet4D")
        self.n_bins = n_bins
        self.n_features = math.prod(n_bins)
        self.plane = plane_shape(self.n_features)
        self.conv1 = Conv4d(1, filters[0], kernel_size, conv_impl=conv_impl)
        self.conv2 = Conv4d(filters[0], filters[1], kernel_size, conv_impl=conv_impl)
        self.conv3 = _SamePadConv(filters[1], filters[2], tuple(kernel_size_2d), conv_impl=conv_impl)
        self.folded = True
        self._build_head(filters[2], self.plane, (2, 2), n_hidden, dropout, n_classes)

    def _body(self, x):
        batch = x.shape[0]
        n1, n2, n3, n4 = self.n_bins
        folded = self.conv1.kernel_size[3] == 1 and self.conv2.kernel_size[3] == 1 and self.folded
        if folded and self.conv2.impl_for((n1, n2, n3)) == "spectral":
            return self._spectral_body(x)
        if folded:
            # Fast route: keep f4 folded into the batch through both 4D layers.
            x = x.reshape(batch, 1, n1, n2, n3, n4).permute(0, 5, 1, 2, 3, 4).reshape(batch * n4, 1, n1, n2, n3)
            x = self._act(self.conv1.forward_folded(x), 0)
            x = self._act(self.conv2.forward_folded(x), 1)
            x = x.reshape(batch, n4, x.shape[1], n1, n2, n3).permute(0, 3, 4, 5, 1, 2)
        else:
            x = x.reshape(batch, 1, n1, n2, n3, n4)
            x = self._act(self.conv1(x), 0)
            x = self._act(self.conv2(x), 1)
            x = x.permute(0, 2, 3, 4, 5, 1)
        # (batch, n1, n2, n3, n4, C) -> channels-last (batch, C, rows, cols): the
        # plane is each channel's 4D response in C order, and the channels-last
        # memory layout is the fast one for the CPU convolution that follows.
        x = x.reshape(batch, *self.plane, x.shape[-1]).permute(0, 3, 1, 2)
        return self._act(self.conv3(x), 2)

    def _spectral_body(self, x):
        """The folded route with the second convolution in the frequency domain.

        Everything is laid out spatial-major, (*spatial, channels, columns):
        the input transposed, (n1, n2, n3, n4, batch), is already the first
        layer's input with f4 folded into the batch f4-major (column
        ``l * batch + b``); the second layer's result, (n1, n2, n3, C, n4,
        batch) in memory, needs one transpose to become the plane the third
        layer reads, (rows, cols, C, batch).
        """
        batch = x.shape[0]
        n1, n2, n3, n4 = self.n_bins
        x = x.t().contiguous().reshape(n1, n2, n3, 1, n4 * batch).permute(4, 3, 0, 1, 2)
        x = self._act(self.conv1.forward_folded(x), 0)
        x = self._act(self.conv2.forward_folded(x), 1)
        c = x.shape[1]
        # logical (n4 * batch, C, n1, n2, n3) -> memory order (n1, n2, n3, C, n4, batch)
        x = x.permute(2, 3, 4, 1, 0).reshape(n1, n2, n3, c, n4, batch)
        x = x.permute(0, 1, 2, 4, 3, 5).reshape(*self.plane, c, batch)
        return self._act(self.conv3(x.permute(3, 2, 0, 1)), 2)


class EPPFNet2D(_EPPFNetBase):
    """The paper's 2D comparison network: the descriptor as a single plane.

    Parameters
    ----------
    n_bins : tuple of 4 ints, default=(20, 4, 5, 3)
        Histogram bins; the flat descriptor is reshaped in C order to
        :func:`plane_shape` of ``prod(n_bins)`` ((40, 30) for 1,200 bins).
    n_classes : int, default=10
        Number of output logits.
    dropout : float, default=0.5
        Dropout probability before the last dense layer.
    filters : tuple of 3 ints, default=(32, 64, 48)
        Filters of the three convolutions.
    kernel_size : tuple of 2 ints, default=(5, 5)
        Kernel of all three convolutions.
    n_hidden : int, default=1024
        Units of the first dense layer.
    precision : {"float32", "bfloat16"}, default="float32"
        Arithmetic of the forward pass (see :class:`EPPFNet4D`).
    n_side : int, default=0
        Side features after the descriptor's bins in every input row (beyond
        the paper; 0 is Table I). They pass a dense layer of ``side_hidden``
        units with a ReLU whose output joins the flattened convolution
        features at the input of the first dense layer.
    side_hidden : int, default=128
        Units of the side branch (unused when ``n_side == 0``).
    batch_norm : bool, default=False
        Batch normalization between every convolution and its ReLU (beyond
        the paper).

    Attributes
    ----------
    plane : tuple of 2 ints
        Input plane.
    n_flat : int
        Input size of the first dense layer.

    See Also
    --------
    EPPFNet4D : The paper's network.

    Notes
    -----
    14,885,818 parameters with the default arguments and 10 classes.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import EPPFNet2D
    >>> EPPFNet2D(n_classes=3)(torch.zeros(2, 1200)).shape
    torch.Size([2, 3])
    """

    def __init__(
        self,
        n_bins=(20, 4, 5, 3),
        n_classes=10,
        dropout=0.5,
        filters=(32, 64, 48),
        kernel_size=(5, 5),
        n_hidden=1024,
        precision="float32",
        *,
        n_side=0,
        side_hidden=128,
        batch_norm=False,
    ):
        super().__init__()
        n_bins, n_classes, dropout, filters, n_hidden = _check_network_args(
            "EPPFNet2D", n_bins, n_classes, dropout, filters, n_hidden
        )
        self._init_options("EPPFNet2D", n_side, side_hidden, batch_norm, filters, size=(n_bins, n_hidden, n_classes))
        self.precision = check_precision(precision, owner="EPPFNet2D")
        self.n_bins = n_bins
        self.n_features = math.prod(n_bins)
        self.plane = plane_shape(self.n_features)
        kernel_size = tuple(kernel_size)
        self.conv1 = _SamePadConv(1, filters[0], kernel_size)
        self.conv2 = _SamePadConv(filters[0], filters[1], kernel_size)
        self.conv3 = _SamePadConv(filters[1], filters[2], kernel_size)
        self._build_head(filters[2], self.plane, (2, 2), n_hidden, dropout, n_classes)

    def _body(self, x):
        x = x.reshape(x.shape[0], 1, *self.plane).contiguous(memory_format=torch.channels_last)
        x = self._act(self.conv1(x), 0)
        x = self._act(self.conv2(x), 1)
        return self._act(self.conv3(x), 2)


class EPPFNet3D(_EPPFNetBase):
    """The paper's 3D comparison network: f3 and f4 merged into one axis.

    Parameters
    ----------
    n_bins : tuple of 4 ints, default=(20, 4, 5, 3)
        Histogram bins; the flat descriptor is reshaped in C order to
        (N1, N2, N3 * N4), (20, 4, 15) for the default bins.
    n_classes : int, default=10
        Number of output logits.
    dropout : float, default=0.5
        Dropout probability before the last dense layer.
    filters : tuple of 3 ints, default=(32, 64, 48)
        Filters of the three convolutions.
    kernel_size : tuple of 3 ints, default=(5, 5, 1)
        Kernel of all three convolutions.
    n_hidden : int, default=1024
        Units of the first dense layer.
    precision : {"float32", "bfloat16"}, default="float32"
        Arithmetic of the forward pass (see :class:`EPPFNet4D`).
    n_side : int, default=0
        Side features after the descriptor's bins in every input row (beyond
        the paper; 0 is Table I). They pass a dense layer of ``side_hidden``
        units with a ReLU whose output joins the flattened convolution
        features at the input of the first dense layer.
    side_hidden : int, default=128
        Units of the side branch (unused when ``n_side == 0``).
    batch_norm : bool, default=False
        Batch normalization between every convolution and its ReLU (beyond
        the paper).

    Attributes
    ----------
    volume : tuple of 3 ints
        Input volume.
    n_flat : int
        Input size of the first dense layer.

    See Also
    --------
    EPPFNet4D : The paper's network.

    Notes
    -----
    The 2x2 max-pool acts on the first two axes ((2, 2, 1)), so the dense
    layer sees 48 * 10 * 2 * 15 = 14,400 values for the default bins, as in
    the other variants; 14,885,818 parameters with 10 classes.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import EPPFNet3D
    >>> EPPFNet3D(n_classes=3)(torch.zeros(2, 1200)).shape
    torch.Size([2, 3])
    """

    def __init__(
        self,
        n_bins=(20, 4, 5, 3),
        n_classes=10,
        dropout=0.5,
        filters=(32, 64, 48),
        kernel_size=(5, 5, 1),
        n_hidden=1024,
        precision="float32",
        *,
        n_side=0,
        side_hidden=128,
        batch_norm=False,
    ):
        super().__init__()
        n_bins, n_classes, dropout, filters, n_hidden = _check_network_args(
            "EPPFNet3D", n_bins, n_classes, dropout, filters, n_hidden
        )
        self._init_options("EPPFNet3D", n_side, side_hidden, batch_norm, filters, size=(n_bins, n_hidden, n_classes))
        self.precision = check_precision(precision, owner="EPPFNet3D")
        self.n_bins = n_bins
        self.n_features = math.prod(n_bins)
        self.volume = (n_bins[0], n_bins[1], n_bins[2] * n_bins[3])
        kernel_size = tuple(kernel_size)
        self.conv1 = _SamePadConv(1, filters[0], kernel_size)
        self.conv2 = _SamePadConv(filters[0], filters[1], kernel_size)
        self.conv3 = _SamePadConv(filters[1], filters[2], kernel_size)
        self._build_head(filters[2], self.volume, (2, 2, 1), n_hidden, dropout, n_classes)

    def _body(self, x):
        x = x.reshape(x.shape[0], 1, *self.volume)
        x = self._act(self.conv1(x), 0)
        x = self._act(self.conv2(x), 1)
        return self._act(self.conv3(x), 2)
