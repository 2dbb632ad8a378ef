"""Convolution in the frequency domain, with the transforms as matrix products.

The 5x5 convolution of the 4D network over its (40, 30) plane and the
(5, 2, 2) convolutions over the (20, 4, 5) histogram cost 92 M and 49 M
multiply-adds per descriptor computed directly. Transformed to the frequency
domain the convolution becomes one small channel-mixing matrix product per
frequency, and the whole layer (forward and backward) takes four to five
times fewer multiply-adds.

The convolution theorem is exact: a "same" convolution (stride 1, zero
padding as :func:`eppf.nn.same_padding` says) equals a circular one over
``N = n + max(before, after)`` points per axis, of which the first ``n``
outputs are kept. Every step below is a real linear map, so the result
equals the direct convolution up to floating-point rounding (relative
differences around 1e-6 in float32) and the backward pass is the exact
transpose of the forward pass.

How it is computed
------------------
The discrete Fourier transforms are not FFTs but products with small dense
matrices, one axis after the other (the axes are at most a few dozen points
long, and matrix products run near the CPU's peak where small FFTs do not).
The activations live in a *spatial-major* memory layout, ``(*spatial,
channels, batch)``: then every transform stage is one batched matrix product
on contiguous memory, its output is already in the layout the next stage
needs, and the channel mixing finds, for each frequency, a contiguous
``(2 * channels, batch)`` matrix (real and imaginary parts stacked). No FFT
library, no transposes, nothing specific to the CPU: the same code runs on
CUDA.

1. Forward transform, outermost axis first: the first stage maps real
   values to (real, imaginary) pairs; one axis (the one that saves most)
   keeps only its non-negative frequencies (the spectrum of real data is
   Hermitian).
2. Mixing: for each frequency ``f``, ``Y[f] = K[f] @ X[f]`` with ``K[f]`` the
   ``(2 * out, 2 * in)`` real form of the complex filter spectrum, computed
   from the weight by one more matrix product (the "before" offset of the
   padding is a phase of that spectrum).
3. Inverse transform, innermost axis first, computing only the ``n`` output
   points of each axis; the last stage keeps the real part, with the
   non-negative frequencies of the halved axis counted twice.
"""

import functools
import math

import torch

__all__ = ["choose_impl", "direct_cost", "is_spatial_major", "patch_conv", "spectral_conv", "spectral_cost"]


def _same(k):
    before = (k - 1) // 2
    return before, k - 1 - before


def _stage_costs(spatial, sizes, n_freq, c):
    """Multiply-adds of the forward transform stages for ``c`` channels per batch column."""
    total = 0
    prefix = 1
    d = len(spatial)
    for j in range(d):
        rows_in = spatial[j] if j == 0 else 2 * spatial[j]
        rest = math.prod(spatial[j + 1:]) * c
        total += prefix * 2 * n_freq[j] * rows_in * rest
        prefix *= n_freq[j]
    return total


def _layout(spatial, kernel):
    """Padded sizes, the halved axis and the frequencies per axis, fewest multiply-adds first."""
    pads = [_same(k) for k in kernel]
    sizes = [s + max(p) for s, p in zip(spatial, pads)]
    best = None
    for h in range(len(spatial)):
        n_freq = [n // 2 + 1 if j == h else n for j, n in enumerate(sizes)]
        cost = (_stage_costs(spatial, sizes, n_freq, 1), math.prod(n_freq), -h)
        if best is None or cost < best[0]:
            best = (cost, h, n_freq)
    return sizes, best[1], best[2]


def spectral_cost(spatial, kernel, in_channels, out_channels):
    """Multiply-adds per batch column of one forward and backward pass in the frequency domain.

    Parameters
    ----------
    spatial : tuple of ints
        Spatial sizes of the input.
    kernel : tuple of ints
        Kernel sizes, one per spatial axis.
    in_channels, out_channels : int

    Returns
    -------
    macs : int
        Transforms of input, output and their gradients plus three
        channel-mixing products (forward, input gradient, weight gradient).
    """
    sizes, _, n_freq = _layout(spatial, kernel)
    transforms = 2 * _stage_costs(spatial, sizes, n_freq, in_channels + out_channels)
    return transforms + 3 * math.prod(n_freq) * 4 * in_channels * out_channels


def direct_cost(spatial, kernel, in_channels, out_channels):
    """Multiply-adds per batch column of one forward and backward pass of the direct convolution."""
    return 3 * math.prod(spatial) * math.prod(kernel) * in_channels * out_channels


def _left(matrix, t):
    """``matrix @ t[p]`` for every ``p`` of a (P, k, R) tensor, as one matrix product per block.

    (``torch.matmul`` folds a tensor that needs no gradient into one tall
    product by transposing it: two copies of the data.)
    """
    if t.shape[0] == 1:
        return torch.mm(matrix, t[0]).unsqueeze(0)
    return torch.bmm(matrix.expand(t.shape[0], -1, -1), t)


class _Plan:
    """Transform matrices of one (spatial, kernel) shape, on one device and dtype."""

    def __init__(self, spatial, kernel, device, dtype):
        self.spatial = tuple(spatial)
        self.kernel = tuple(kernel)
        sizes, halved, n_freq = _layout(spatial, kernel)
        self.n_freq = tuple(n_freq)
        self.size = math.prod(sizes)  # points of the circular convolution
        d = len(spatial)
        f64 = torch.float64
        self.forward_mats, self.inverse_mats = [], []
        for j in range(d):
            f = torch.arange(n_freq[j], dtype=f64)[:, None]
            s = torch.arange(spatial[j], dtype=f64)[None, :]
            theta = 2 * math.pi * f * s / sizes[j]  # (n_freq, n)
            cos, sin = torch.cos(theta), torch.sin(theta)
            # forward: X[f] = sum_s x[s] exp(-i theta); rows (f, re/im)
            if j == 0:
                fwd = torch.stack([cos, -sin], 1).reshape(2 * n_freq[j], spatial[j])
            else:  # columns (re/im, s): (a + ib)(cos - i sin)
                fwd = torch.stack([torch.cat([cos, sin], 1), torch.cat([-sin, cos], 1)], 1)
                fwd = fwd.reshape(2 * n_freq[j], 2 * spatial[j])
            # inverse: y[s] = sum_f a_f Y[f] exp(+i theta), a_f = 1/N (2/N for the halved
            # axis's frequencies whose mirror image is not stored)
            a = torch.full((n_freq[j], 1), 1.0 / sizes[j], dtype=f64)
            if j == halved:
                a[1:] *= 2
                if sizes[j] % 2 == 0:
                    a[-1] = 1.0 / sizes[j]
            c, sn = (a * cos).T, (a * sin).T  # (n, n_freq)
            if j == 0:  # real part only: rows s, columns (f, re/im)
                inv = torch.stack([c, -sn], 2).reshape(spatial[j], 2 * n_freq[j])
            else:  # rows (re/im, s), columns (f, re/im)
                inv = torch.stack([torch.stack([c, -sn], 2), torch.stack([sn, c], 2)], 0)
                inv = inv.reshape(2 * spatial[j], 2 * n_freq[j])
            self.forward_mats.append(fwd.to(device, dtype))
            self.inverse_mats.append(inv.to(device, dtype))
        # filter spectrum K[f] = sum_t w[t] exp(-2 pi i sum_j f_j (before_j - t_j) / N_j)
        grids = torch.meshgrid(*[torch.arange(n, dtype=f64) for n in n_freq], indexing="ij")
        taps = torch.meshgrid(*[torch.arange(k, dtype=f64) for k in kernel], indexing="ij")
        phase = torch.zeros(math.prod(n_freq), math.prod(kernel), dtype=f64)
        for j in range(d):
            before = _same(kernel[j])[0]
            phase += grids[j].reshape(-1, 1) * (before - taps[j].reshape(1, -1)) / sizes[j]
        phase *= 2 * math.pi
        self.kernel_re = torch.cos(phase).to(device, dtype)  # (F, T)
        self.kernel_im = (-torch.sin(phase)).to(device, dtype)

    def forward_transform(self, x, channels):
        """(*spatial, C, cols) real -> (F, 2C, cols) spectrum, (re, im) stacked per frequency."""
        cols = x.shape[-1]
        d = len(self.spatial)
        t = x.reshape(1, self.spatial[0], -1)
        prefix = 1
        for j in range(d):
            t = _left(self.forward_mats[j], t)  # (prefix, 2 n_j, rest)
            prefix *= self.n_freq[j]
            if j + 1 < d:
                t = t.reshape(prefix, 2 * self.spatial[j + 1], -1)
        return t.reshape(prefix, 2 * channels, cols)

    def forward_transform_t(self, g, channels):
        """Transpose of :meth:`forward_transform`: (F, 2C, cols) -> (*spatial, C, cols)."""
        cols = g.shape[-1]
        d = len(self.spatial)
        prefix = math.prod(self.n_freq)
        t = g
        for j in reversed(range(d)):
            prefix //= self.n_freq[j]
            t = t.reshape(prefix, 2 * self.n_freq[j], -1)
            t = _left(self.forward_mats[j].T, t)  # (prefix, rows_in_j, rest)
        return t.reshape(*self.spatial, channels, cols)

    def inverse_transform(self, y, channels):
        """(F, 2C, cols) spectrum -> (*spatial, C, cols) real, the first n points per axis."""
        cols = y.shape[-1]
        d = len(self.spatial)
        prefix = math.prod(self.n_freq)
        t = y
        for j in reversed(range(d)):
            prefix //= self.n_freq[j]
            t = _left(self.inverse_mats[j], t.reshape(prefix, 2 * self.n_freq[j], -1))
        return t.reshape(*self.spatial, channels, cols)

    def inverse_transform_t(self, g, channels):
        """Transpose of :meth:`inverse_transform`: (*spatial, C, cols) -> (F, 2C, cols)."""
        cols = g.shape[-1]
        d = len(self.spatial)
        t = g.reshape(1, self.spatial[0], -1)
        prefix = 1
        for j in range(d):
            t = _left(self.inverse_mats[j].T, t)
            prefix *= self.n_freq[j]
            if j + 1 < d:
                t = t.reshape(prefix, 2 * self.spatial[j + 1], -1)
        return t.reshape(prefix, 2 * channels, cols)

    def blocks(self, weight):
        """(O, C, *kernel) weight -> (F, 2O, 2C) real form of the filter spectrum."""
        o, c = weight.shape[:2]
        w = weight.reshape(o * c, -1).T  # (T, O*C)
        re = (self.kernel_re @ w).view(-1, o, c)
        im = (self.kernel_im @ w).view(-1, o, c)
        out = torch.empty(re.shape[0], 2, o, 2, c, dtype=re.dtype, device=re.device)
        out[:, 0, :, 0] = re
        out[:, 1, :, 1] = re
        torch.neg(im, out=im)
        out[:, 0, :, 1] = im
        torch.neg(im, out=im)
        out[:, 1, :, 0] = im
        return out.view(-1, 2 * o, 2 * c)

    def blocks_t(self, g, weight_shape):
        """Transpose of :meth:`blocks`: (F, 2O, 2C) -> (O, C, *kernel)."""
        o, c = weight_shape[:2]
        f = g.shape[0]
        re = (g[:, :o, :c] + g[:, o:, c:]).reshape(f, o * c)
        im = (g[:, o:, :c] - g[:, :o, c:]).reshape(f, o * c)
        w = self.kernel_re.T @ re + self.kernel_im.T @ im  # (T, O*C)
        return w.T.reshape(weight_shape)


@functools.lru_cache(maxsize=32)
def _plan(spatial, kernel, device, dtype):
    return _Plan(spatial, kernel, device, dtype)


class _SpectralConv(torch.autograd.Function):
    """Convolution of a spatial-major (*spatial, C, cols) tensor; returns (*spatial, O, cols)."""

    @staticmethod
    def forward(ctx, x, weight, bias, plan):
        c, o = weight.shape[1], weight.shape[0]
        spectrum = plan.forward_transform(x, c)
        blocks = plan.blocks(weight)
        mixed = torch.bmm(blocks, spectrum)
        if bias is not None:  # a constant is the zero frequency alone: N times the bias, real
            mixed[0, :o] += plan.size * bias.view(o, 1)
        y = plan.inverse_transform(mixed, o)
        ctx.save_for_backward(spectrum, blocks)
        ctx.plan = plan
        ctx.weight_shape = weight.shape
        ctx.has_bias = bias is not None
        return y

    @staticmethod
    def backward(ctx, grad):
        spectrum, blocks = ctx.saved_tensors
        plan = ctx.plan
        o, c = ctx.weight_shape[:2]
        grad = grad.contiguous()
        with torch.autocast(grad.device.type, enabled=False):
            g_spec = plan.inverse_transform_t(grad, o)  # (F, 2O, cols)
            gx = gw = gb = None
            if ctx.needs_input_grad[0]:
                gx = plan.forward_transform_t(torch.bmm(blocks.transpose(1, 2), g_spec), c)
            if ctx.needs_input_grad[1]:
                gw = plan.blocks_t(torch.bmm(g_spec, spectrum.transpose(1, 2)), ctx.weight_shape)
            if ctx.has_bias and ctx.needs_input_grad[2]:
                gb = plan.size * g_spec[0, :o].sum(1)
        return gx, gw, gb, None


def spectral_conv(input, weight, bias=None):
    """"Same" convolution (stride 1) of a (batch, C, *spatial) tensor in the frequency domain.

    Equals ``convNd(pad(input), weight, bias)`` with the zero padding of
    :func:`eppf.nn.same_padding` up to floating-point rounding, for any
    number of spatial axes and any kernel sizes. Fastest when ``input`` is
    laid out spatial-major in memory (``input.permute(2, ..., 1, 0)``
    contiguous); the result is laid out that way. Under
    :func:`torch.autocast` it computes in float32 and returns float32.

    Parameters
    ----------
    input : torch.Tensor of shape (batch, in_channels, *spatial)
    weight : torch.Tensor of shape (out_channels, in_channels, *kernel)
    bias : torch.Tensor of shape (out_channels,), default=None

    Returns
    -------
    output : torch.Tensor of shape (batch, out_channels, *spatial)
    """
    d = input.dim() - 2
    device_type = input.device.type
    autocast = torch.is_autocast_enabled(device_type)
    dtype = torch.float32 if autocast else input.dtype
    with torch.autocast(device_type, enabled=False):
        x = input.permute(*range(2, 2 + d), 1, 0).to(dtype).contiguous()
        w = weight.to(dtype)
        b = None if bias is None else bias.to(dtype)
        plan = _plan(tuple(x.shape[:d]), tuple(w.shape[2:]), x.device, dtype)
        y = _SpectralConv.apply(x, w, b, plan)
    return y.permute(d + 1, d, *range(d))


#: How many times fewer multiply-adds the frequency domain must take before
#: "auto" uses it: its small matrix products run at about half the rate of
#: oneDNN's direct convolutions (measured on the 4D network's layers, float32,
#: AVX2 and AVX-512: 4.9x fewer multiply-adds gave 2.1x less time, 2.9x fewer
#: 1.3x less, 0.5x (the single-channel first layer) 0.9x).
AUTO_MIN_SAVING = 2.5


#: The fewest input x output channel pairs for which "auto" uses the frequency
#: domain without gradients (prediction, validation): below it the transforms'
#: passes over the activations cost more than the channel mixing saves
#: (measured with 2 threads, float32: the recommended network's 16 x 32 and
#: 32 x 24 pairs predicted 1.2-1.25x slower on Zen 4, natively and held to
#: AVX2; the paper's 32 x 64 and 64 x 48 pairs gain).
AUTO_MIN_CHANNEL_PAIRS = 2048


#: The same bound where gradients are recorded (a training step: the backward
#: pass's two products per layer gain as the forward one does). Measured with
#: 2 threads in float32, ``benchmarks/bench_cnn.py epoch --recommended``: the
#: recommended network's 16 x 32 and 32 x 24 pairs trained an epoch in 0.75 of
#: the direct time on an AVX2-only AMD EPYC (Zen 2; 7.1-7.5 against 9.7 s over
#: 4,000 descriptors), in 1.0-1.01 of it on Zen 4 (natively and held to AVX2).
AUTO_MIN_TRAIN_CHANNEL_PAIRS = 512


def choose_impl(conv_impl, spatial, kernel, in_channels, out_channels):
    """The implementation a layer runs: ``"direct"`` or ``"spectral"``.

    Parameters
    ----------
    conv_impl : {"auto", "direct", "spectral"}
        ``"auto"`` takes the frequency domain where it needs at least
        :data:`AUTO_MIN_SAVING` times fewer multiply-adds than the direct
        convolution (forward and backward together) and the layer mixes at
        least :data:`AUTO_MIN_CHANNEL_PAIRS` channel pairs, or
        :data:`AUTO_MIN_TRAIN_CHANNEL_PAIRS` where gradients are recorded
        (``torch.is_grad_enabled()``: a training step, whose backward pass
        gains as much again); never under bfloat16 or float16 autocast (where
        the direct convolution runs in the lower precision, natively fast
        where the hardware has it, and the frequency domain would compute in
        float32).
    spatial, kernel : tuple of ints
        Input sizes and kernel sizes along the spatial axes.
    in_channels, out_channels : int

    Returns
    -------
    impl : {"direct", "spectral"}
        ``conv_impl`` itself unless it is ``"auto"``.
    """
    if conv_impl != "auto":
        return conv_impl
    if _lower_precision_autocast():
        return "direct"
    key = (tuple(spatial), tuple(kernel), int(in_channels), int(out_channels), torch.is_grad_enabled())
    return _auto(*key)


def _lower_precision_autocast():
    """Whether a CPU or CUDA autocast region is active (eppf's networks open one only for bfloat16)."""
    return any(torch.is_autocast_enabled(device) for device in ("cpu", "cuda"))


@functools.lru_cache(maxsize=256)
def _auto(spatial, kernel, in_channels, out_channels, training):
    if in_channels * out_channels < (AUTO_MIN_TRAIN_CHANNEL_PAIRS if training else AUTO_MIN_CHANNEL_PAIRS):
        return "direct"
    saving = direct_cost(spatial, kernel, in_channels, out_channels) / spectral_cost(
        spatial, kernel, in_channels, out_channels)
    return "spectral" if saving >= AUTO_MIN_SAVING else "direct"


def is_spatial_major(input):
    """Whether a (batch, C, *spatial) tensor is laid out (*spatial, C, batch) in memory."""
    d = input.dim() - 2
    return input.permute(*range(2, 2 + d), 1, 0).is_contiguous()


#: :func:`patch_conv` copies every input value once per tap; beyond this many
#: taps times input channels the copy costs more than a layout change.
PATCH_MAX_TAPS = 64


def patch_conv(input, weight, bias=None):
    """Direct "same" convolution of a spatial-major tensor, with its layout kept.

    The input's patches (every tap of every input channel) are gathered into
    a ``(positions, in_channels * taps, batch)`` tensor and multiplied by the
    weight, one matrix product per position: the result is laid out
    spatial-major like :func:`spectral_conv`'s. For layers of few input
    channels (at most :data:`PATCH_MAX_TAPS` channels times taps), such as a
    network's first layer in front of frequency-domain layers.

    Parameters
    ----------
    input : torch.Tensor of shape (batch, in_channels, *spatial)
    weight : torch.Tensor of shape (out_channels, in_channels, *kernel)
    bias : torch.Tensor of shape (out_channels,), default=None

    Returns
    -------
    output : torch.Tensor of shape (batch, out_channels, *spatial)
    """
    d = input.dim() - 2
    kernel = weight.shape[2:]
    o = weight.shape[0]
    x = input.permute(*range(2, 2 + d), 1, 0)  # (*spatial, C, batch)
    spatial, c, n = x.shape[:d], x.shape[d], x.shape[d + 1]
    pads = [0, 0, 0, 0]
    for k in reversed(kernel):
        pads.extend(_same(k))
    x = torch.nn.functional.pad(x, pads)
    for j, k in enumerate(kernel):
        x = x.unfold(j, k, 1)  # (*spatial, C, batch, k_1, ..., k_j)
    patches = x.permute(*range(d), d, *range(d + 2, 2 * d + 2), d + 1).reshape(math.prod(spatial), -1, n)
    w = weight.reshape(1, o, -1).expand(patches.shape[0], -1, -1)
    if bias is None:
        y = torch.bmm(w, patches)  # (positions, O, batch)
    else:
        y = torch.baddbmm(bias.view(1, o, 1).expand(patches.shape[0], o, n), w, patches)
    return y.reshape(*spatial, o, n).permute(d + 1, d, *range(d))
