import itertools
import re

import numpy as np
import pytest
import torch
from numpy.testing import assert_allclose

from eppf.nn import Conv4d, conv4d, same_padding


def _brute_force_conv4d(x, w, b):
    """Direct 4D cross-correlation with TensorFlow 'same' zero padding (NumPy loops)."""
    batch, c_in, *spatial = x.shape
    c_out, _, *kernel = w.shape
    pads = [((k - 1) // 2, (k - 1) - (k - 1) // 2) for k in kernel]
    xp = np.pad(x, [(0, 0), (0, 0)] + pads)
    out = np.zeros((batch, c_out, *spatial))
    for pos in itertools.product(*(range(n) for n in spatial)):
        window = xp[
            :,
            :,
            pos[0] : pos[0] + kernel[0],
            pos[1] : pos[1] + kernel[1],
            pos[2] : pos[2] + kernel[2],
            pos[3] : pos[3] + kernel[3],
        ]
        out[(slice(None), slice(None)) + pos] = np.einsum("bcijkl,ocijkl->bo", window, w)
    if b is not None:
        out += b[None, :, None, None, None, None]
    return out


@pytest.mark.parametrize("kernel", [(1, 1, 1, 1), (3, 3, 3, 3), (5, 2, 2, 1), (2, 2, 2, 2), (2, 3, 1, 2), (1, 1, 1, 3), (4, 1, 2, 1)])
@pytest.mark.parametrize("bias", [True, False])
def test_conv4d_matches_brute_force(kernel, bias):
    rng = np.random.default_rng(sum(kernel))
    x = rng.normal(size=(2, 3, 5, 4, 3, 4))
    w = rng.normal(size=(2, 3, *kernel))
    b = rng.normal(size=2) if bias else None
    expected = _brute_force_conv4d(x, w, b)
    got = conv4d(torch.from_numpy(x), torch.from_numpy(w), None if b is None else torch.from_numpy(b))
    assert got.shape == x.shape[:1] + (2,) + x.shape[2:]
    assert_allclose(got.numpy(), expected, rtol=1e-10, atol=1e-10)
    # the general path is exact for every kernel, the fast one included
    general = conv4d(torch.from_numpy(x), torch.from_numpy(w), None if b is None else torch.from_numpy(b), path="general")
    assert_allclose(general.numpy(), expected, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("kernel", [(5, 2, 2, 1), (3, 3, 3, 1), (1, 1, 1, 1), (2, 1, 4, 1)])
def test_fast_path_equals_general_path(kernel):
    rng = np.random.default_rng(0)
    x = torch.from_numpy(rng.normal(size=(3, 2, 6, 4, 5, 3)))
    w = torch.from_numpy(rng.normal(size=(4, 2, *kernel)))
    b = torch.from_numpy(rng.normal(size=4))
    fast = conv4d(x, w, b, path="fast")
    assert_allclose(fast.numpy(), conv4d(x, w, b, path="general").numpy(), rtol=1e-12, atol=1e-12)
    assert_allclose(fast.numpy(), conv4d(x, w, b).numpy())


@pytest.mark.parametrize("kernel", [(3, 3, 3, 3), (5, 2, 2, 1), (2, 2, 2, 2)])
def test_bias_added_once(kernel):
    layer = Conv4d(2, 3, kernel).double()
    with torch.no_grad():
        layer.bias.copy_(torch.tensor([1.5, -2.0, 0.25]))
        out = layer(torch.zeros(2, 2, 4, 3, 3, 2, dtype=torch.float64))
    expected = np.broadcast_to(np.array([1.5, -2.0, 0.25])[None, :, None, None, None, None], out.shape)
    assert_allclose(out.numpy(), expected)


def test_even_kernel_pads_after():
    # A (1,1,1,2) kernel of ones sums each value with its successor along f4;
    # the last position sees the zero padding that goes after.
    x = torch.arange(4, dtype=torch.float64).reshape(1, 1, 1, 1, 1, 4)
    w = torch.ones(1, 1, 1, 1, 1, 2, dtype=torch.float64)
    assert conv4d(x, w).flatten().tolist() == [1.0, 3.0, 5.0, 3.0]


@pytest.mark.parametrize("k, expected", [(1, (0, 0)), (2, (0, 1)), (3, (1, 1)), (4, (1, 2)), (5, (2, 2))])
def test_same_padding(k, expected):
    assert same_padding(k) == expected


def test_conv4d_layer_forward_folded_matches_forward():
    torch.manual_seed(0)
    layer = Conv4d(3, 5, (5, 2, 2, 1))
    x = torch.randn(2, 3, 6, 4, 5, 3)
    out = layer(x)
    folded = x.permute(0, 5, 1, 2, 3, 4).reshape(6, 3, 6, 4, 5)
    out_folded = layer.forward_folded(folded).reshape(2, 3, 5, 6, 4, 5).permute(0, 2, 3, 4, 5, 1)
    assert_allclose(out_folded.detach().numpy(), out.detach().numpy(), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("kernel", [(2, 2, 1, 2), (3, 1, 2, 1)])
def test_conv4d_gradients(kernel):
    torch.manual_seed(0)
    x = torch.randn(1, 2, 3, 3, 2, 3, dtype=torch.float64, requires_grad=True)
    w = torch.randn(2, 2, *kernel, dtype=torch.float64, requires_grad=True)
    b = torch.randn(2, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x, w, b: conv4d(x, w, b), (x, w, b))


def test_conv4d_layer_shapes_and_parameters():
    layer = Conv4d(1, 32, (5, 2, 2, 1))
    assert layer.weight.shape == (32, 1, 5, 2, 2, 1)
    assert layer.bias.shape == (32,)
    assert Conv4d(2, 3, 3, bias=False).bias is None
    assert Conv4d(2, 3, 3).kernel_size == (3, 3, 3, 3)
    assert layer(torch.zeros(2, 1, 15, 3, 4, 3)).shape == (2, 32, 15, 3, 4, 3)
    assert "kernel_size=(5, 2, 2, 1)" in repr(layer)


@pytest.mark.parametrize(
    "kwargs, err, msg",
    [
        ({"in_channels": 0, "out_channels": 2, "kernel_size": 3}, ValueError, "Conv4d: in_channels must be a positive int, got 0"),
        ({"in_channels": 1, "out_channels": 2.5, "kernel_size": 3}, ValueError, "Conv4d: out_channels must be a positive int, got 2.5"),
        ({"in_channels": 1, "out_channels": 2, "kernel_size": (3, 3, 3)}, ValueError, "Conv4d: kernel_size must be an int >= 1 or a tuple of 4 positive ints, got (3, 3, 3)"),
        ({"in_channels": 1, "out_channels": 2, "kernel_size": (3, 0, 3, 1)}, ValueError, "Conv4d: kernel_size must be an int >= 1 or a tuple of 4 positive ints, got (3, 0, 3, 1)"),
        ({"in_channels": 1, "out_channels": 2, "kernel_size": None}, TypeError, "Conv4d: kernel_size must be an int >= 1 or a tuple of 4 positive ints, got None"),
    ],
)
def test_conv4d_layer_errors(kwargs, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        Conv4d(**kwargs)


@pytest.mark.parametrize(
    "x_shape, w_shape, b_shape, kwargs, msg",
    [
        ((1, 2, 3, 3, 3), (1, 2, 1, 1, 1, 1), None, {}, "conv4d: input must have shape (batch, channels, n1, n2, n3, n4), got (1, 2, 3, 3, 3)"),
        ((1, 2, 3, 3, 3, 3), (1, 2, 1, 1, 1), None, {}, "conv4d: weight must have shape (out_channels, in_channels, k1, k2, k3, k4), got (1, 2, 1, 1, 1)"),
        ((1, 2, 3, 3, 3, 3), (1, 3, 1, 1, 1, 1), None, {}, "conv4d: input has 2 channels but weight expects 3"),
        ((1, 2, 3, 3, 3, 3), (4, 2, 1, 1, 1, 1), (3,), {}, "conv4d: bias must have shape (4,), got (3,)"),
        ((1, 2, 3, 3, 3, 3), (1, 2, 1, 1, 1, 2), None, {"path": "fast"}, "conv4d: the fast path needs a kernel of size 1 along the fourth axis, got (1, 1, 1, 2)"),
        ((1, 2, 3, 3, 3, 3), (1, 2, 1, 1, 1, 1), None, {"path": "quick"}, "conv4d: path must be one of 'auto', 'fast', 'general', got 'quick'"),
    ],
)
def test_conv4d_errors(x_shape, w_shape, b_shape, kwargs, msg):
    b = None if b_shape is None else torch.zeros(b_shape)
    with pytest.raises(ValueError, match=re.escape(msg)):
        conv4d(torch.zeros(x_shape), torch.zeros(w_shape), b, **kwargs)


def test_forward_folded_rejects_wide_kernel():
    with pytest.raises(ValueError, match=re.escape("Conv4d: forward_folded needs a kernel of size 1 along the fourth axis")):
        Conv4d(1, 1, (1, 1, 1, 2)).forward_folded(torch.zeros(1, 1, 2, 2, 2))
