"""Tests of the EPPF networks' options beyond the paper: side features and batch normalisation."""

import math
import re

import numpy as np
import pytest
import torch

from eppf.nn import EPPFNet2D, EPPFNet3D, EPPFNet4D, count_parameters
from eppf.nn._networks import _ChannelNorm

NETS = {"2d": EPPFNet2D, "3d": EPPFNet3D, "4d": EPPFNet4D}
N_BINS = (4, 2, 3, 2)
N = math.prod(N_BINS)


@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
def test_side_features_join_the_dense_layer_as_written(conv):
    torch.manual_seed(0)
    net = NETS[conv](n_bins=N_BINS, n_classes=3, filters=(2, 3, 2), n_hidden=5, n_side=4, side_hidden=6).eval()
    x = torch.rand(7, N + 4)
    # reference: the same layers applied by hand, the side branch concatenated after the flattened pool
    conv_out = net.pool(net._body(x[:, :N])).flatten(1)
    side = torch.relu(net.side[0](x[:, N:]))
    ref = net.fc2(torch.relu(net.fc1(torch.cat([conv_out, side], 1))))
    torch.testing.assert_close(net(x), ref)
    assert net.fc1.in_features == net.n_flat + 6
    # the side columns matter, and only through the branch
    x2 = x.clone()
    x2[:, N:] += 1.0
    assert not torch.allclose(net(x), net(x2))
    plain = NETS[conv](n_bins=N_BINS, n_classes=3, filters=(2, 3, 2), n_hidden=5)
    assert count_parameters(net) == count_parameters(plain) + (4 * 6 + 6) + 6 * 5


def test_paper_network_unchanged_by_default():
    net = EPPFNet4D(n_classes=10)
    assert net.n_side == 0 and net.batch_norm is False
    assert not hasattr(net, "side") and not hasattr(net, "norms")
    assert count_parameters(net) == 14_875_418


@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
def test_batch_norm_normalises_every_channel(conv):
    torch.manual_seed(0)
    net = NETS[conv](n_bins=N_BINS, n_classes=3, filters=(2, 3, 2), n_hidden=5, batch_norm=True).train()
    seen = []
    for norm in net.norms:
        norm.register_forward_hook(lambda m, inp, out: seen.append(out.detach()))
    net(torch.rand(16, N) * 5 + 3)
    assert len(seen) == 3
    for out in seen:  # per channel over the batch and every position: mean 0, variance 1
        flat = out.transpose(0, 1).reshape(out.shape[1], -1)
        torch.testing.assert_close(flat.mean(1), torch.zeros(out.shape[1]), atol=1e-5, rtol=0)
        torch.testing.assert_close(flat.var(1, unbiased=False), torch.ones(out.shape[1]), atol=1e-3, rtol=0)


def test_channel_norm_matches_batchnorm3d():
    torch.manual_seed(0)
    x = torch.randn(4, 3, 5, 2, 3)
    ours, ref = _ChannelNorm(3), torch.nn.BatchNorm3d(3)
    torch.testing.assert_close(ours(x), ref(x))
    torch.testing.assert_close(ours.running_var, ref.running_var)
    with pytest.raises(ValueError, match="rank"):
        ours(torch.zeros(3))


def test_4d_folded_route_matches_general_route_with_batch_norm():
    torch.manual_seed(0)
    net = EPPFNet4D(n_bins=N_BINS, n_classes=3, filters=(2, 3, 2), n_hidden=5, batch_norm=True, n_side=2).eval()
    for norm in net.norms:  # non-trivial running statistics
        norm.running_mean.uniform_(-1, 1)
        norm.running_var.uniform_(0.5, 2)
    x = torch.rand(5, N + 2)
    folded = net(x)
    net.folded = False
    torch.testing.assert_close(net(x), folded, atol=1e-5, rtol=1e-5)


def test_bfloat16_with_side_features_matches_float32_up_to_rounding():
    torch.manual_seed(0)
    net = EPPFNet4D(n_bins=N_BINS, n_classes=3, filters=(2, 3, 2), n_hidden=5, n_side=3, batch_norm=True).eval()
    x = torch.rand(6, N + 3)
    ref = net(x)
    net.precision = "bfloat16"
    out = net(x)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, ref, atol=0.05, rtol=0.05)


@pytest.mark.parametrize("kwargs, msg", [
    (dict(n_side=-1), "n_side must be an int >= 0"),
    (dict(n_side=1.5), "n_side must be an int >= 0"),
    (dict(side_hidden=0), "side_hidden must be an int >= 1"),
    (dict(batch_norm="yes"), "batch_norm must be True or False"),
])
def test_option_errors(kwargs, msg):
    with pytest.raises(ValueError, match=msg):
        EPPFNet4D(n_bins=N_BINS, **kwargs)


def test_wrong_width_names_the_side_features():
    net = EPPFNet2D(n_bins=N_BINS, n_side=3, filters=(2, 2, 2), n_hidden=4)
    with pytest.raises(ValueError, match=r"\(batch, 51\).*\+ 3 side features"):
        net(torch.zeros(2, N))
    assert np.isfinite(net(torch.zeros(2, N + 3)).detach().numpy()).all()


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
def test_empty_batch_and_input_dtype(conv, precision):
    # An empty batch gives empty logits (the 4D network's folded layouts failed to reshape it); an input
    # of another dtype than the parameters' is a TypeError naming the network (torch's own errors named
    # neither), and a network converted to float64 takes float64 input.
    for impl in (("direct", "spectral") if conv == "4d" else (None,)):
        extra = {"conv_impl": impl} if impl else {}
        net = NETS[conv](n_bins=(6, 3, 4, 3), n_classes=4, filters=(4, 6, 5), n_hidden=8, precision=precision,
                         **extra).eval()
        out = net(torch.zeros(0, 216))
        assert out.shape == (0, 4) and out.dtype == torch.float32
        for dtype in (torch.float64, torch.int64, torch.bfloat16):
            msg = f"{type(net).__name__}: expected a float32 input, the dtype of the network's parameters, got "
            with pytest.raises(TypeError, match=re.escape(msg + str(dtype).replace("torch.", ""))):
                net(torch.zeros(2, 216, dtype=dtype))
    if precision == "float32":
        net = net.double()
        assert net(torch.zeros(3, 216, dtype=torch.float64)).dtype == torch.float64
        assert net(torch.zeros(0, 216, dtype=torch.float64)).dtype == torch.float64


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
def test_prediction_without_autograd_gives_the_training_forward_bits(conv, precision):
    # Without autograd the convolutions pad inside themselves and the ReLUs run in place; with it
    # every layer pads an explicit copy, as in training: the logits must be the same bits.
    torch.manual_seed(0)
    extra = {"conv_impl": "direct"} if conv == "4d" else {}
    for batch_norm in (False, True):
        net = NETS[conv](n_bins=(6, 3, 4, 3), n_classes=4, filters=(4, 6, 5), n_hidden=8, n_side=3,
                         batch_norm=batch_norm, precision=precision, **extra).eval()
        x = torch.randn(9, 216 + 3)
        with torch.enable_grad():
            ref = net(x)
        assert ref.requires_grad
        with torch.no_grad():
            assert torch.equal(net(x), ref)
        with torch.inference_mode():
            assert torch.equal(net(x), ref)


@pytest.mark.parametrize("kernel", [(5, 5), (2, 3), (4, 1), (5, 2, 2), (1, 4, 3)])
def test_same_conv_pads_as_tensorflow_with_or_without_autograd(kernel):
    from eppf.nn._conv4d import same_conv, same_padding

    torch.manual_seed(1)
    x = torch.randn(3, 2, *(7 - i for i in range(len(kernel))))
    w = torch.randn(4, 2, *kernel)
    b = torch.randn(4)
    # reference: the zeros TensorFlow's "same" adds (the extra one after), written out by hand
    pads = [p for k in reversed(kernel) for p in same_padding(k)]
    conv = torch.nn.functional.conv3d if len(kernel) == 3 else torch.nn.functional.conv2d
    ref = conv(torch.nn.functional.pad(x, pads), w, b)
    assert ref.shape[2:] == x.shape[2:]
    with torch.no_grad():
        out = same_conv(x, w, b)
    torch.testing.assert_close(out, ref, rtol=1e-6, atol=1e-5)
    torch.testing.assert_close(same_conv(x, w, b).detach(), ref)


@pytest.mark.parametrize("cls", [EPPFNet2D, EPPFNet3D, EPPFNet4D])
@pytest.mark.parametrize("kwargs", [{"n_hidden": 10**12}, {"n_hidden": 10**30}, {"filters": (10**6, 10**6, 4)},
                                    {"n_bins": (10**9, 10**9, 1, 1)}, {"n_side": 10**6, "side_hidden": 10**6}])
def test_a_network_too_large_is_refused_before_any_layer_is_built(cls, kwargs):
    # torch's allocator raised RuntimeError ("you tried to allocate 57600000000000 bytes"), torch.empty an
    # overflow TypeError, or plane_shape searched a divisor of 10**18 for minutes
    with pytest.raises(ValueError, match=rf"{cls.__name__}: the network would have at least [\d,]+ parameters \(n_bins="
                                         r".*\), more than the 1,000,000,000 it may have"):
        cls(n_classes=3, **kwargs)


def test_the_lower_bound_is_below_the_parameter_count():
    from eppf.nn._networks import parameter_lower_bound

    for cls in (EPPFNet2D, EPPFNet3D, EPPFNet4D):
        for n_bins, filters, n_side in (((20, 4, 5, 3), (32, 64, 48), 0), ((3, 1, 1, 1), (1, 1, 1), 0),
                                        ((5, 3, 3, 2), (4, 8, 4), 7), ((7, 1, 1, 1), (2, 3, 5), 2)):
            net = cls(n_bins=n_bins, n_classes=4, filters=filters, n_hidden=16, n_side=n_side, side_hidden=8)
            assert parameter_lower_bound(n_bins, 16, 4, filters, n_side, 8) <= count_parameters(net)
