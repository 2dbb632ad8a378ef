"""The frequency-domain convolution against direct convolution: values, gradients, networks, precision."""

import itertools
import pickle

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from eppf.nn import Conv4d, EPPFNet4D, conv4d, same_padding
from eppf.nn._networks import _MaxPool2d
from eppf.nn._spectral import choose_impl, direct_cost, is_spatial_major, patch_conv, spectral_conv, spectral_cost
from eppf.utils._param_validation import InvalidParameterError

from .test_conv4d import _brute_force_conv4d


def _direct(x, w, b):
    """torch's own convolution with TensorFlow 'same' zero padding: the reference."""
    pads = []
    for k in reversed(w.shape[2:]):
        pads.extend(same_padding(k))
    conv = {3: F.conv1d, 4: F.conv2d, 5: F.conv3d}[x.dim()]
    return conv(F.pad(x, pads), w, b)


def _rel(a, b):
    return ((a - b).norm() / b.norm()).item()


SHAPES = [  # spatial, kernel, in, out
    ((11,), (3,), 2, 3),
    ((40, 30), (5, 5), 6, 5),
    ((27, 20), (5, 5), 3, 4),
    ((9, 8), (4, 3), 3, 2),  # even kernel: the extra zero after
    ((6, 5), (6, 1), 2, 2),
    ((3, 2), (5, 4), 2, 3),  # kernel larger than the input
    ((20, 4, 5), (5, 2, 2), 4, 7),
    ((7, 6, 5), (1, 3, 4), 2, 3),
]


@pytest.mark.parametrize("spatial, kernel, c_in, c_out", SHAPES)
@pytest.mark.parametrize("dtype, tol", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
def test_values_and_gradients_match_direct_convolution(spatial, kernel, c_in, c_out, dtype, tol):
    gen = torch.Generator().manual_seed(sum(spatial) + sum(kernel))
    x = torch.randn(3, c_in, *spatial, dtype=dtype, generator=gen, requires_grad=True)
    w = torch.randn(c_out, c_in, *kernel, dtype=dtype, generator=gen, requires_grad=True)
    b = torch.randn(c_out, dtype=dtype, generator=gen, requires_grad=True)
    ref, got = _direct(x, w, b), spectral_conv(x, w, b)
    assert got.shape == ref.shape and got.dtype == dtype
    assert _rel(got, ref) < tol
    g = torch.randn(ref.shape, dtype=dtype, generator=gen)
    for a, e in zip(torch.autograd.grad(got, (x, w, b), g), torch.autograd.grad(ref, (x, w, b), g)):
        assert _rel(a, e) < tol


def test_without_bias_and_input_gradient_only():
    x = torch.randn(2, 3, 8, 7, dtype=torch.float64, requires_grad=True)
    w = torch.randn(4, 3, 3, 2, dtype=torch.float64)
    got = spectral_conv(x, w)
    torch.testing.assert_close(got, _direct(x, w, None))
    (gx,) = torch.autograd.grad(got.square().sum(), x)
    (ex,) = torch.autograd.grad(_direct(x, w, None).square().sum(), x)
    torch.testing.assert_close(gx, ex)


@pytest.mark.parametrize("kernel", [(5, 2, 2, 1), (3, 3, 3, 3), (2, 3, 1, 2), (1, 1, 1, 3)])
def test_conv4d_spectral_matches_brute_force(kernel):
    rng = np.random.default_rng(sum(kernel))
    x = rng.normal(size=(2, 3, 5, 4, 3, 4))
    w = rng.normal(size=(2, 3, *kernel))
    b = rng.normal(size=2)
    expected = _brute_force_conv4d(x, w, b)
    for path in ("auto", "general"):
        got = conv4d(torch.from_numpy(x), torch.from_numpy(w), torch.from_numpy(b), path=path, conv_impl="spectral")
        np.testing.assert_allclose(got.numpy(), expected, rtol=1e-10, atol=1e-10)


def test_layout_of_the_result_is_spatial_major():
    x = torch.randn(2, 3, 6, 5)
    y = spectral_conv(x, torch.randn(4, 3, 3, 3))
    assert y.permute(2, 3, 1, 0).is_contiguous()
    # and such a tensor is read without a copy: the result is the same
    torch.testing.assert_close(spectral_conv(y, torch.ones(1, 4, 1, 1)), y.sum(1, keepdim=True))


def test_cost_model_and_auto_choice():
    # the paper's layers: 4.9x and 3.8x fewer multiply-adds in the frequency domain
    assert direct_cost((40, 30), (5, 5), 64, 48) / spectral_cost((40, 30), (5, 5), 64, 48) == pytest.approx(4.88, abs=0.01)
    assert direct_cost((20, 4, 5), (5, 2, 2), 32, 64) / spectral_cost((20, 4, 5), (5, 2, 2), 32, 64) == pytest.approx(3.78, abs=0.01)
    assert direct_cost((40, 30), (5, 5), 64, 48) == 3 * 1200 * 25 * 64 * 48
    assert choose_impl("auto", (40, 30), (5, 5), 64, 48) == "spectral"
    assert choose_impl("auto", (20, 4, 5), (5, 2, 2), 1, 32) == "direct"  # one input channel: direct is cheap
    assert choose_impl("direct", (40, 30), (5, 5), 64, 48) == "direct"
    assert choose_impl("spectral", (20, 4, 5), (5, 2, 2), 1, 32) == "spectral"


def _pair(conv_impl_a="direct", conv_impl_b="spectral", **kwargs):
    torch.manual_seed(0)
    a = EPPFNet4D(conv_impl=conv_impl_a, **kwargs).double()
    b = EPPFNet4D(conv_impl=conv_impl_b, **kwargs).double()
    b.load_state_dict(a.state_dict())
    return a, b


@pytest.mark.parametrize("kwargs", [
    {},
    dict(filters=(16, 32, 24), n_hidden=256, n_side=5),
    dict(n_bins=(15, 3, 4, 3), batch_norm=True),
    dict(kernel_size=(3, 3, 3, 1), kernel_size_2d=(4, 3), n_bins=(6, 3, 4, 2)),
    dict(kernel_size=(3, 2, 2, 2), n_bins=(6, 3, 4, 2)),  # a real 4D kernel: the unfolded route
])
def test_network_spectral_equals_direct_in_values_and_gradients(kwargs):
    a, b = _pair(**kwargs)
    a.train(), b.train()
    x = torch.randn(6, a.n_features + a.n_side, dtype=torch.float64)
    grads = []
    for net in (a, b):
        torch.manual_seed(1)  # the same dropout mask
        out = net(x)
        out.square().sum().backward()
        grads.append((out, [p.grad for p in net.parameters()]))
    (out_a, ga), (out_b, gb) = grads
    assert _rel(out_b, out_a) < 1e-12
    for (name, _), p, q in zip(a.named_parameters(), ga, gb):
        scale = max(p.norm().item(), 1.0)  # a bias before batch normalization has a gradient of ~0
        assert (p - q).norm().item() / scale < 1e-10, name


def test_paper_network_chooses_per_layer_and_keeps_its_parameters():
    direct, auto = EPPFNet4D(conv_impl="direct"), EPPFNet4D()
    assert auto.conv_impl == "auto"
    assert [auto.conv1.impl_for((20, 4, 5)), auto.conv2.impl_for((20, 4, 5)), auto.conv3.impl_for(auto.plane)] == [
        "direct", "spectral", "spectral"]
    assert direct.conv3.impl_for(direct.plane) == "direct"
    assert {k: v.shape for k, v in direct.state_dict().items()} == {k: v.shape for k, v in auto.state_dict().items()}
    assert "conv_impl='auto'" in repr(auto.conv2)


def test_auto_keeps_narrow_layers_direct_in_prediction_and_lower_precision():
    # the recommended network's layers mix too few channel pairs to gain in prediction, enough to gain in training
    net = EPPFNet4D(filters=(16, 32, 24), n_hidden=256)
    with torch.no_grad():
        assert [net.conv2.impl_for((20, 4, 5)), net.conv3.impl_for(net.plane)] == ["direct", "direct"]
        assert choose_impl("auto", (40, 30), (5, 5), 32, 64) == "spectral"  # 2,048 pairs: the bound itself
        assert choose_impl("auto", (40, 30), (5, 5), 31, 64) == "direct"
    with torch.inference_mode():
        assert choose_impl("auto", (40, 30), (5, 5), 31, 64) == "direct"
    assert torch.is_grad_enabled()
    assert [net.conv1.impl_for((20, 4, 5)), net.conv2.impl_for((20, 4, 5)), net.conv3.impl_for(net.plane)] == [
        "direct", "spectral", "spectral"]
    assert choose_impl("auto", (40, 30), (5, 5), 16, 32) == "spectral"  # 512 pairs: the training bound itself
    assert choose_impl("auto", (40, 30), (5, 5), 15, 34) == "direct"
    assert choose_impl("auto", (40, 30), (1, 1), 64, 48) == "direct"  # pairs enough, but no saving
    # under (bfloat16) autocast "auto" is direct; an explicit choice is kept
    with torch.autocast("cpu", dtype=torch.bfloat16):
        assert choose_impl("auto", (40, 30), (5, 5), 64, 48) == "direct"
        assert choose_impl("auto", (40, 30), (5, 5), 16, 32) == "direct"
        assert choose_impl("spectral", (40, 30), (5, 5), 64, 48) == "spectral"
    assert choose_impl("auto", (40, 30), (5, 5), 64, 48) == "spectral"


def test_recommended_network_trains_in_frequency_domain_and_predicts_directly():
    # "auto" in a training step and in prediction: the same network up to rounding either way
    torch.manual_seed(0)
    auto = EPPFNet4D(filters=(16, 32, 24), n_hidden=256, n_side=3).double()
    direct = EPPFNet4D(filters=(16, 32, 24), n_hidden=256, n_side=3, conv_impl="direct").double()
    direct.load_state_dict(auto.state_dict())
    x = torch.rand(5, auto.n_features + 3, dtype=torch.float64)
    auto.eval(), direct.eval()
    out = auto(x)  # grad recorded: conv2 and conv3 in the frequency domain
    ref = direct(x)
    assert _rel(out, ref) < 1e-12 and not torch.equal(out, ref)
    with torch.no_grad():
        assert torch.equal(auto(x), direct(x))  # both direct: the same operations


def test_bfloat16_auto_network_equals_direct_one():
    torch.manual_seed(0)
    ref = EPPFNet4D(n_bins=(6, 3, 4, 2), filters=(32, 64, 48), n_hidden=16, conv_impl="direct",
                    precision="bfloat16").eval()
    net = EPPFNet4D(n_bins=(6, 3, 4, 2), filters=(32, 64, 48), n_hidden=16, precision="bfloat16").eval()
    net.load_state_dict(ref.state_dict())
    x = torch.rand(4, 144)
    with torch.no_grad():
        assert torch.equal(net(x), ref(x))


def test_float32_network_close_to_direct():
    torch.manual_seed(0)
    a = EPPFNet4D(conv_impl="direct").eval()
    b = EPPFNet4D(conv_impl="spectral").eval()
    b.load_state_dict(a.state_dict())
    x = torch.rand(8, 1200)
    with torch.no_grad():
        assert _rel(b(x), a(x)) < 1e-5


def test_bfloat16_autocast_runs_the_spectral_layers_in_float32():
    x = torch.randn(2, 3, 8, 7)
    w = torch.randn(4, 3, 5, 5)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        got = spectral_conv(x, w)
    assert got.dtype == torch.float32
    assert _rel(got, _direct(x, w, None)) < 1e-5
    # the bfloat16 network: the spectral layers are float32, so it stays closer to float32 than bfloat16's rounding
    torch.manual_seed(0)
    ref = EPPFNet4D(n_bins=(6, 3, 4, 2), filters=(8, 16, 8), n_hidden=16, conv_impl="direct").eval()
    net = EPPFNet4D(n_bins=(6, 3, 4, 2), filters=(8, 16, 8), n_hidden=16, conv_impl="spectral",
                    precision="bfloat16").eval()
    net.load_state_dict(ref.state_dict())
    x = torch.rand(16, 144)
    with torch.no_grad():
        out, expected = net(x), ref(x)
    assert out.dtype == torch.float32
    assert _rel(out, expected) < 3e-2
    # and it trains: gradients reach every parameter in float32
    net.train()
    net(x).sum().backward()
    assert all(p.grad is not None and p.grad.dtype == torch.float32 and torch.isfinite(p.grad).all()
               for p in net.parameters())


def _train(conv_impl, steps=3):
    torch.manual_seed(0)
    net = EPPFNet4D(n_bins=(8, 3, 4, 3), filters=(4, 8, 6), n_hidden=16, n_classes=3, conv_impl=conv_impl)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(1)
    for _ in range(steps):
        x, y = torch.rand(16, 288, generator=gen), torch.randint(0, 3, (16,), generator=gen)
        opt.zero_grad()
        F.cross_entropy(net(x), y).backward()
        opt.step()
    return [p.detach().clone() for p in net.parameters()]


def test_training_is_bit_identical_from_run_to_run():
    first, second = _train("spectral"), _train("spectral")
    assert all(torch.equal(p, q) for p, q in zip(first, second))
    direct = _train("direct")
    assert all(torch.allclose(p, q, rtol=1e-3, atol=1e-5) for p, q in zip(first, direct))


def test_layers_pickled_before_the_option_run_directly():
    net = EPPFNet4D(n_bins=(6, 3, 4, 2), filters=(8, 16, 8), n_hidden=16).eval()
    for module in (net, net.conv1, net.conv2, net.conv3):
        del module.conv_impl  # as unpickled from a file written before conv_impl existed
    old = pickle.loads(pickle.dumps(net))
    assert old.conv2.impl_for((6, 3, 4)) == "direct" and old.conv3.impl_for(old.plane) == "direct"
    ref = EPPFNet4D(n_bins=(6, 3, 4, 2), filters=(8, 16, 8), n_hidden=16, conv_impl="direct").eval()
    ref.load_state_dict(old.state_dict())
    x = torch.rand(4, 144)
    with torch.no_grad():
        assert torch.equal(old(x), ref(x))


@pytest.mark.parametrize("make, owner, value", [
    (lambda: Conv4d(2, 3, 3, conv_impl="fft"), "Conv4d", "'fft'"),
    (lambda: EPPFNet4D(conv_impl="Spectral"), "EPPFNet4D", "'Spectral'"),
    (lambda: conv4d(torch.zeros(1, 1, 2, 2, 2, 2), torch.zeros(1, 1, 1, 1, 1, 1), conv_impl=None), "conv4d", "None"),
])
def test_conv_impl_is_validated(make, owner, value):
    with pytest.raises(InvalidParameterError, match=f"^{owner}: conv_impl must be one of 'auto', 'direct', 'spectral', "
                                                    f"got {value}$"):
        make()


@pytest.mark.parametrize("rows, cols", [(40, 30), (27, 20), (7, 5)])
def test_pooling_in_the_spatial_major_layout_equals_max_pool2d(rows, cols):
    gen = torch.Generator().manual_seed(rows)
    m = torch.randn(rows, cols, 3, 4, dtype=torch.float64, generator=gen).relu()
    m[0, 0] = m[0, 1]  # equal values in one window: the first one takes the gradient, as in max_pool2d
    m[2, 2, 0, 0] = float("nan")
    x = m.permute(3, 2, 0, 1).requires_grad_()
    pool = _MaxPool2d((2, 2), stride=(2, 2), ceil_mode=True)
    ref, got = F.max_pool2d(x, 2, 2, ceil_mode=True), pool(x)
    assert torch.allclose(ref, got, rtol=0, atol=0, equal_nan=True)
    g = torch.randn(ref.shape, dtype=torch.float64, generator=gen)
    assert torch.equal(torch.autograd.grad(ref, x, g)[0], torch.autograd.grad(got, x, g)[0])
    # other layouts go to max_pool2d itself
    assert torch.allclose(pool(x.detach().contiguous()), ref.detach(), rtol=0, atol=0, equal_nan=True)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_on_cuda():
    a, b = _pair(n_bins=(6, 3, 4, 2), filters=(8, 16, 8), n_hidden=16)
    x = torch.randn(4, 144, dtype=torch.float64)
    a.eval(), b.eval()
    with torch.no_grad():
        torch.testing.assert_close(b.cuda()(x.cuda()).cpu(), a(x))


@pytest.mark.parametrize("spatial, kernel, c_in", [((20, 4, 5), (5, 2, 2), 1), ((6, 5), (3, 4), 3), ((7,), (2,), 2)])
def test_patch_conv_matches_direct_and_keeps_the_layout(spatial, kernel, c_in):
    gen = torch.Generator().manual_seed(len(spatial))
    x = torch.randn(*spatial, c_in, 5, dtype=torch.float64, generator=gen)
    x = x.permute(len(spatial) + 1, len(spatial), *range(len(spatial)))  # spatial-major
    w = torch.randn(4, c_in, *kernel, dtype=torch.float64, generator=gen, requires_grad=True)
    b = torch.randn(4, dtype=torch.float64, generator=gen, requires_grad=True)
    got, ref = patch_conv(x, w, b), _direct(x.contiguous(), w, b)
    torch.testing.assert_close(got, ref)
    assert is_spatial_major(got)
    g = torch.randn(ref.shape, dtype=torch.float64, generator=gen)
    for a, e in zip(torch.autograd.grad(got, (w, b), g), torch.autograd.grad(ref, (w, b), g)):
        torch.testing.assert_close(a, e)
