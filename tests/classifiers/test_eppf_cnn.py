import copy
import math
import pickle
import re
import warnings

import numpy as np
import pytest
import scipy.sparse
import torch
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import Pipeline

from eppf import EPPF4DClassifier
from eppf.nn import DescriptorPoolDataset, EPPFNet2D, EPPFNet3D, EPPFNet4D, count_parameters, plane_shape

NETS = {"2d": EPPFNet2D, "3d": EPPFNet3D, "4d": EPPFNet4D}
SMALL = dict(filters=(4, 8, 4), n_hidden=16, batch_size=16, n_jobs=1)
N_BINS = (4, 2, 3, 2)


def _toy(n, rng, n_bins=N_BINS, labels=("cat", "dog", "eel"), noise=0.3):
    """Histogram-like rows whose mass sits in a class-specific block of f1 bins."""
    n_features = math.prod(n_bins)
    y = rng.integers(0, len(labels), n)
    X = rng.random((n, n_features)) * noise
    block = n_features // len(labels)
    for c in range(len(labels)):
        X[y == c, c * block : (c + 1) * block] += 1.0
    X /= X.sum(axis=1, keepdims=True)
    return X, np.asarray(labels)[y]


# ----------------------------------------------------------------- networks
@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
@pytest.mark.parametrize("n_bins", [(20, 4, 5, 3), (15, 3, 4, 3), (4, 2, 3, 2), (3, 1, 1, 1), (5, 3, 3, 2)])
def test_network_output_shapes(conv, n_bins):
    net = NETS[conv](n_bins=n_bins, n_classes=7, filters=(2, 3, 2), n_hidden=8)
    out = net(torch.rand(3, math.prod(n_bins)))
    assert out.shape == (3, 7)


@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
def test_default_networks_dense_input_and_parameter_count(conv):
    net = NETS[conv](n_classes=10)
    assert net.n_flat == 48 * 20 * 15
    dense = (14400 * 1024 + 1024) + (1024 * 10 + 10)
    if conv == "4d":  # two (5,2,2,1) 4D convolutions, then a 5x5 2D one
        convs = (32 * 20 + 32) + (64 * 32 * 20 + 64) + (48 * 64 * 25 + 48)
    else:  # three 5x5 (or 5x5x1) convolutions
        convs = (32 * 25 + 32) + (64 * 32 * 25 + 64) + (48 * 64 * 25 + 48)
    assert count_parameters(net) == convs + dense


def test_short_descriptor_sizes():
    # EPPF short: 540 bins -> plane (27, 20) -> pooled (14, 10); 3D (15, 3, 12) -> (8, 2, 12)
    assert EPPFNet4D(n_bins=(15, 3, 4, 3), n_hidden=8).n_flat == 48 * 14 * 10
    assert EPPFNet2D(n_bins=(15, 3, 4, 3), n_hidden=8).n_flat == 48 * 14 * 10
    assert EPPFNet3D(n_bins=(15, 3, 4, 3), n_hidden=8).n_flat == 48 * 8 * 2 * 12


@pytest.mark.parametrize("n, expected", [(1200, (40, 30)), (540, (27, 20)), (48, (8, 6)), (7, (7, 1)), (1, (1, 1))])
def test_plane_shape(n, expected):
    assert plane_shape(n) == expected


@pytest.mark.parametrize("kernel", [(5, 2, 2, 1), (3, 2, 2, 2)])
def test_4d_network_folded_route_matches_general_route(kernel):
    torch.manual_seed(0)
    net = EPPFNet4D(n_bins=(5, 3, 2, 3), n_classes=3, filters=(3, 4, 2), kernel_size=kernel, n_hidden=8).eval()
    x = torch.rand(4, 90)
    out = net(x)
    net.folded = False
    assert_allclose(net(x).detach().numpy(), out.detach().numpy(), rtol=1e-5, atol=1e-6)


def test_4d_network_reshape_follows_c_order():
    # With identity-like layers the 4D network's plane is each channel's
    # (f1, f2, f3, f4) volume in C order: check by hooking the 2D conv input.
    torch.manual_seed(0)
    net = EPPFNet4D(n_bins=(4, 2, 3, 2), n_classes=2, filters=(1, 1, 1), kernel_size=(1, 1, 1, 1), n_hidden=4)
    with torch.no_grad():
        for conv in (net.conv1, net.conv2):
            conv.weight.fill_(1.0)
            conv.bias.zero_()
    seen = {}
    net.conv3.register_forward_hook(lambda m, inp, out: seen.setdefault("x", inp[0]))
    x = torch.rand(2, 48)
    net(x)
    assert_allclose(seen["x"][:, 0].detach().numpy(), x.reshape(2, 8, 6).numpy())


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        ({"n_bins": (20, 4, 5)}, "EPPFNet4D: n_bins must be a tuple of 4 positive ints, got (20, 4, 5)"),
        ({"n_bins": (20, 0, 5, 3)}, "EPPFNet4D: n_bins must be a tuple of 4 positive ints, got (20, 0, 5, 3)"),
        ({"n_classes": 1}, "EPPFNet4D: n_classes must be an int >= 2, got 1"),
        ({"dropout": 1.0}, "EPPFNet4D: dropout must be a float in [0, 1), got 1.0"),
        ({"filters": (32, 64)}, "EPPFNet4D: filters must be a tuple of 3 positive ints, got (32, 64)"),
        ({"n_hidden": 0}, "EPPFNet4D: n_hidden must be a positive int, got 0"),
        ({"precision": "float16"}, "EPPFNet4D: precision must be 'float32' or 'bfloat16', got 'float16'"),
    ],
)
def test_network_errors(kwargs, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        EPPFNet4D(**kwargs)


def test_network_rejects_wrong_length():
    msg = "EPPFNet3D: expected input of shape (batch, 540) for n_bins=(15, 3, 4, 3), got (2, 1200)"
    with pytest.raises(ValueError, match=re.escape(msg)):
        EPPFNet3D(n_bins=(15, 3, 4, 3), n_hidden=4)(torch.zeros(2, 1200))


@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
def test_bfloat16_network_matches_float32_up_to_rounding(conv):
    # Same weights, same input: mixed precision changes only the rounding of
    # the products (bfloat16 keeps 8 significant bits), so the logits agree
    # to about 1% of their spread, and the parameters and logits stay float32.
    torch.manual_seed(0)
    ref = NETS[conv](n_bins=(15, 3, 4, 3), n_classes=5).eval()
    torch.manual_seed(0)
    mixed = NETS[conv](n_bins=(15, 3, 4, 3), n_classes=5, precision="bfloat16").eval()
    x = torch.randn(16, 540, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        a, b = ref(x), mixed(x)
    assert b.dtype == torch.float32
    assert all(p.dtype == torch.float32 for p in mixed.parameters())
    assert not torch.equal(a, b)  # the bfloat16 path really ran
    assert (a - b).abs().max() <= 0.05 * (a.max() - a.min())
    assert (a.argmax(1) == b.argmax(1)).float().mean() >= 0.8


def test_descriptor_pool_dataset_draws_every_member():
    X = np.stack([np.full((5, 3), k, dtype=np.float32) for k in range(4)], axis=1)  # draw k holds k
    ds = DescriptorPoolDataset(X, np.arange(5), random_state=0)
    seen = {float(ds[i % 5][0][0]) for i in range(200)}
    assert seen == {0.0, 1.0, 2.0, 3.0}
    single = DescriptorPoolDataset(X[:, 2:3], np.arange(5))
    assert {float(single[i][0][0]) for i in range(5)} == {2.0}


# --------------------------------------------------------------- classifier
@pytest.mark.parametrize("conv", ["2d", "3d", "4d"])
def test_learns_separable_toy_set(conv):
    rng = np.random.default_rng(0)
    X, y = _toy(150, rng)
    X_test, y_test = _toy(90, rng)
    clf = EPPF4DClassifier(n_bins=N_BINS, conv=conv, max_epochs=8, lr=5e-3, early_stopping=False, random_state=0, **SMALL)
    clf.fit(X, y)
    assert clf.score(X_test, y_test) >= 0.9
    assert clf.n_epochs_ == 8 and clf.best_epoch_ == 8


def test_bfloat16_classifier_learns_and_is_deterministic():
    rng = np.random.default_rng(5)
    X, y = _toy(150, rng)
    X_test, y_test = _toy(90, rng)
    make = lambda: EPPF4DClassifier(  # noqa: E731
        n_bins=N_BINS, max_epochs=8, lr=5e-3, early_stopping=False, precision="bfloat16", random_state=0, **SMALL
    )
    clf = make().fit(X, y)
    assert clf.net_.module_.precision == "bfloat16"
    assert clf.score(X_test, y_test) >= 0.9
    proba = clf.predict_proba(X_test)
    assert proba.dtype == np.float32
    assert_array_equal(make().fit(X, y).predict_proba(X_test), proba)


def _native(monkeypatch, native):
    """Make "auto" see a CPU with (True) or without (False) native bfloat16."""
    from eppf.nn import _precision

    monkeypatch.setattr(_precision, "native_bfloat16", lambda device="cpu", **kw: native)
    monkeypatch.setattr(_precision, "_warned_emulation", False)


@pytest.mark.parametrize("native", [False, True])
def test_auto_precision_is_chosen_in_fit_and_kept_as_precision_(monkeypatch, native):
    _native(monkeypatch, native)
    expected = "bfloat16" if native else "float32"
    X, y = _toy(48, np.random.default_rng(6))
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=2, early_stopping=False, n_estimators=2, random_state=0, **SMALL)
    assert clf.get_params()["precision"] == "auto"  # the default
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "auto" never warns
        clf.fit(X, y)
    assert clf.precision == "auto" and clf.precision_ == expected
    assert clf.net_.module_.precision == expected
    assert [net.module_.precision for net in clf.ensemble_nets_] == [expected]
    explicit = EPPF4DClassifier(n_bins=N_BINS, max_epochs=2, early_stopping=False, n_estimators=2, random_state=0,
                                precision=expected, **SMALL).fit(X, y)
    assert explicit.precision_ == expected
    assert_array_equal(explicit.predict_proba(X), clf.predict_proba(X))


def test_refit_resolves_precision_again(monkeypatch):
    X, y = _toy(30, np.random.default_rng(7))
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, early_stopping=False, random_state=0, **SMALL)
    _native(monkeypatch, True)
    assert clf.fit(X, y).precision_ == "bfloat16"
    _native(monkeypatch, False)
    assert clf.fit(X, y).precision_ == "float32"
    from eppf.nn import BFloat16EmulationWarning

    with pytest.warns(BFloat16EmulationWarning):
        assert clf.set_params(precision="bfloat16").fit(X, y).net_.module_.precision == "bfloat16"


def test_explicit_bfloat16_on_an_emulating_cpu_warns_once_per_process(monkeypatch):
    from eppf.nn import BFloat16EmulationWarning

    _native(monkeypatch, False)
    X, y = _toy(30, np.random.default_rng(8))
    make = lambda: EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, early_stopping=False, precision="bfloat16",  # noqa: E731
                                    random_state=0, **SMALL)
    with pytest.warns(BFloat16EmulationWarning, match=r"EPPF4DClassifier: precision='bfloat16' on a CPU without "
                                                       r"native bfloat16 .* 3\.6 times as long as in float32"):
        clf = make().fit(X, y)
    assert clf.precision_ == "bfloat16"  # asked for explicitly: kept, only warned of
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make().fit(X, y)  # the second fit in the process is silent


def test_deterministic_under_random_state():
    rng = np.random.default_rng(1)
    X, y = _toy(60, rng)
    make = lambda seed: EPPF4DClassifier(n_bins=N_BINS, max_epochs=3, random_state=seed, **SMALL)  # noqa: E731
    before = torch.get_rng_state()
    p1 = make(3).fit(X, y).predict_proba(X)
    p2 = make(3).fit(X, y).predict_proba(X)
    assert_array_equal(p1, p2)
    assert not np.allclose(p1, make(4).fit(X, y).predict_proba(X))
    assert torch.equal(torch.get_rng_state(), before)  # the global torch RNG is left alone


def test_string_and_integer_labels_map_back():
    rng = np.random.default_rng(2)
    X, y = _toy(60, rng, labels=("zebra", "ant", "moose"))
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=2, random_state=0, **SMALL).fit(X, y)
    assert_array_equal(clf.classes_, ["ant", "moose", "zebra"])
    assert set(clf.predict(X)) <= set(clf.classes_)
    proba = clf.predict_proba(X)
    assert proba.shape == (60, 3)
    assert_allclose(proba.sum(axis=1), 1.0, rtol=1e-5)
    assert_array_equal(clf.predict(X), clf.classes_[proba.argmax(axis=1)])

    y_int = np.select([y == "ant", y == "moose"], [10, -3], 7)
    clf_int = EPPF4DClassifier(n_bins=N_BINS, max_epochs=2, random_state=0, **SMALL).fit(X, y_int)
    assert_array_equal(clf_int.classes_, [-3, 7, 10])
    assert set(clf_int.predict(X)) <= {-3, 7, 10}


def test_pickle_roundtrip_and_clone():
    rng = np.random.default_rng(3)
    X, y = _toy(50, rng)
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=2, random_state=0, **SMALL).fit(X, y)
    restored = pickle.loads(pickle.dumps(clf))
    assert_array_equal(restored.predict_proba(X), clf.predict_proba(X))
    assert_array_equal(restored.classes_, clf.classes_)
    fresh = clone(clf)
    assert fresh.get_params() == clf.get_params()
    assert not hasattr(fresh, "net_")
    with pytest.raises(NotFittedError):
        fresh.predict(X)


def test_descriptor_pool_fit_and_test_time_averaging():
    rng = np.random.default_rng(4)
    draws = [_toy(60, np.random.default_rng(7))[0] for _ in range(3)]
    _, y = _toy(60, np.random.default_rng(7))
    pool = np.stack([d + rng.random(d.shape) * 1e-3 for d in draws], axis=1)
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=3, random_state=0, **SMALL).fit(pool, y)
    assert clf.n_draws_fit_ == 3
    averaged = clf.predict_proba(pool)
    per_draw = np.mean([clf.predict_proba(pool[:, k]) for k in range(3)], axis=0)
    assert_allclose(averaged, per_draw, rtol=1e-6)
    assert clf.predict(pool).shape == (60,)
    assert clf.predict(pool[:, 0]).shape == (60,)  # single draws work too


def test_global_input_scaling_learned_on_training_part():
    rng = np.random.default_rng(5)
    X, y = _toy(40, rng)
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, early_stopping=False, random_state=0, **SMALL).fit(X, y)
    assert_allclose(clf.input_mean_, [X.mean()], rtol=1e-5)
    assert_allclose(clf.input_scale_, [X.std()], rtol=1e-4)
    clf_bin = clone(clf).set_params(input_scaling="bin").fit(X, y)
    assert_allclose(clf_bin.input_mean_, X.mean(axis=0), rtol=1e-5)
    clf_none = clone(clf).set_params(input_scaling="none").fit(X, y)
    assert_allclose(clf_none.input_scale_, [1.0])


def test_early_stopping_uses_validation_from_training_data():
    rng = np.random.default_rng(6)
    X, y = _toy(80, rng)
    clf = EPPF4DClassifier(
        n_bins=N_BINS, max_epochs=30, n_iter_no_change=2, validation_fraction=0.25, lr=0.05, random_state=0, **SMALL
    ).fit(X, y)
    history = clf.net_.history
    losses = history[:, "valid_loss"]
    assert clf.n_epochs_ == len(history) <= 30
    assert clf.best_epoch_ == int(np.argmin(losses)) + 1
    if clf.n_epochs_ < 30:  # stopped early: no improvement over the patience window
        assert clf.n_epochs_ - clf.best_epoch_ == 2
    # 20 of 80 objects are held out: one epoch trains on 60
    assert sum(b["train_batch_size"] for b in history[0]["batches"] if "train_batch_size" in b) == 60


@pytest.mark.parametrize("early_stopping", [True, False])
def test_max_time_ends_training_after_the_epoch_past_the_budget(early_stopping):
    rng = np.random.default_rng(11)
    X, y = _toy(40, rng)
    clf = EPPF4DClassifier(
        n_bins=N_BINS, max_epochs=50, max_time=1e-9, early_stopping=early_stopping, random_state=0, **SMALL
    ).fit(X, y)
    assert clf.n_epochs_ == clf.best_epoch_ == 1
    # The same single epoch as a run capped by max_epochs.
    ref = EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, early_stopping=early_stopping, random_state=0, **SMALL).fit(X, y)
    assert_allclose(clf.predict_proba(X), ref.predict_proba(X), rtol=1e-6)
    pickle.loads(pickle.dumps(clf)).predict(X)
    # A generous budget changes nothing.
    long = clone(clf).set_params(max_epochs=3, max_time=1e6).fit(X, y)
    assert long.n_epochs_ == 3 or early_stopping


@pytest.mark.parametrize("early_stopping", [True, False])
def test_plateau_schedule_halves_lr_after_stalled_epochs(early_stopping):
    rng = np.random.default_rng(13)
    X, y = _toy(40, rng)
    # lr so small that the monitored loss stalls (relative improvement < 1e-4);
    # not below 1e-8, the smallest change ReduceLROnPlateau makes.
    clf = EPPF4DClassifier(
        n_bins=N_BINS, max_epochs=8, lr=1e-6, lr_schedule="plateau", n_iter_no_change=3,
        early_stopping=early_stopping, random_state=0, **SMALL,
    ).fit(X, y)
    lrs = [group["lr"] for group in clf.net_.optimizer_.param_groups]
    assert clf.n_epochs_ >= 3
    assert all(lr <= 0.5e-6 for lr in lrs)
    const = clone(clf).set_params(lr_schedule="constant").fit(X, y)
    assert [group["lr"] for group in const.net_.optimizer_.param_groups] == [1e-6]


def test_adam_is_the_fused_kernel_on_cpu():
    rng = np.random.default_rng(12)
    X, y = _toy(30, rng)
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, early_stopping=False, random_state=0, **SMALL).fit(X, y)
    opt = clf.net_.optimizer_
    # torch has a fused Adam for the CPU from 2.4 on; before, the plain one runs
    fused_on_cpu = tuple(int(v) for v in torch.__version__.split(".")[:2]) >= (2, 4)
    assert isinstance(opt, torch.optim.Adam) and opt.defaults["fused"] is fused_on_cpu
    assert opt.defaults["lr"] == 5e-4


def test_n_jobs_restores_torch_threads():
    rng = np.random.default_rng(7)
    X, y = _toy(30, rng)
    before = torch.get_num_threads()
    EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, random_state=0, **SMALL).fit(X, y)
    assert torch.get_num_threads() == before


def test_verbose_prints_epochs(capsys):
    rng = np.random.default_rng(8)
    X, y = _toy(40, rng)
    EPPF4DClassifier(n_bins=N_BINS, max_epochs=2, random_state=0, verbose=1, **SMALL).fit(X, y)
    out = capsys.readouterr().out
    assert "train_loss" in out and "valid_loss" in out
    EPPF4DClassifier(n_bins=N_BINS, max_epochs=2, random_state=0, verbose=0, **SMALL).fit(X, y)
    assert capsys.readouterr().out == ""


class _BlockHistogram(TransformerMixin, BaseEstimator):
    """Stand-in descriptor: normalised histogram of a 1D signal's values over n_bins."""

    def __init__(self, n_bins=N_BINS):
        self.n_bins = n_bins

    def fit(self, X, y=None):
        return self

    def transform(self, X):
        n = math.prod(self.n_bins)
        H = np.stack([np.histogram(x, bins=n, range=(0, 1))[0] for x in np.asarray(X)]).astype(float) + 1e-3
        return H / H.sum(axis=1, keepdims=True)


def test_pipeline_grid_search_with_stand_in_transformer():
    rng = np.random.default_rng(9)
    y = np.repeat(["low", "high"], 20)
    signals = np.where(y[:, None] == "low", rng.random((40, 50)) * 0.5, 0.5 + rng.random((40, 50)) * 0.5)
    pipe = Pipeline(
        [
            ("desc", _BlockHistogram()),
            ("cnn", EPPF4DClassifier(max_epochs=6, lr=1e-2, random_state=0, early_stopping=False, **SMALL)),
        ]
    )
    grid = GridSearchCV(
        pipe,
        {"desc__n_bins": [(4, 2, 3, 2), (2, 2, 2, 2)], "cnn__conv": ["4d", "2d"]},
        cv=2,
        n_jobs=1,
    )
    # the classifier's n_bins must follow the descriptor's: tie them in the grid
    grid.set_params(
        param_grid=[
            {"desc__n_bins": [nb], "cnn__n_bins": [nb], "cnn__conv": ["4d", "2d"]} for nb in [(4, 2, 3, 2), (2, 2, 2, 2)]
        ]
    )
    grid.fit(signals, y)
    assert len(grid.cv_results_["params"]) == 4
    assert grid.score(signals, y) >= 0.9


def test_pipeline_with_eppf_transformer():
    EPPFTransformer = pytest.importorskip("eppf").__dict__.get("EPPFTransformer")
    if EPPFTransformer is None:
        pytest.skip("EPPFTransformer not available")
    rng = np.random.default_rng(10)
    clouds, y = [], []
    for i in range(24):
        if i % 2:  # flat square
            pts = np.c_[rng.random((60, 2)), 0.01 * rng.random(60)]
        else:  # long thin stick
            pts = np.c_[rng.random(60), 0.05 * rng.random((60, 2))]
        clouds.append(pts)
        y.append("plate" if i % 2 else "stick")
    y = np.asarray(y)
    n_bins = (4, 2, 3, 2)
    pipe = Pipeline(
        [
            ("eppf", EPPFTransformer(n_bins=n_bins, n_pairs=500, scaling="object", random_state=0, n_jobs=1)),
            ("cnn", EPPF4DClassifier(n_bins=n_bins, max_epochs=8, lr=1e-2, early_stopping=False, random_state=0, **SMALL)),
        ]
    )
    grid = GridSearchCV(pipe, {"eppf__c": [1.2, 2.0]}, cv=2, n_jobs=1).fit(clouds, y)
    assert grid.score(clouds, y) >= 0.9


# ------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "params, err, msg",
    [
        ({"n_bins": (20, 4, 5)}, ValueError, "EPPF4DClassifier: n_bins must be a tuple of 4 positive ints, got (20, 4, 5)"),
        ({"n_bins": 1200}, TypeError, "EPPF4DClassifier: n_bins must be a tuple of 4 positive ints, got 1200"),
        ({"conv": "5d"}, ValueError, "EPPF4DClassifier: conv must be one of '4d', '3d', '2d', got '5d'"),
        ({"max_epochs": 0}, ValueError, "EPPF4DClassifier: max_epochs must be an int >= 1, got 0"),
        ({"lr": -1.0}, ValueError, "EPPF4DClassifier: lr must be a float in (0.0, inf), got -1.0"),
        ({"lr": float("nan")}, ValueError, "EPPF4DClassifier: lr must be a float in (0.0, inf), got nan"),
        ({"lr_schedule": "cosine"}, ValueError, "EPPF4DClassifier: lr_schedule must be 'constant' or 'plateau', got 'cosine'"),
        ({"batch_size": 0}, ValueError, "EPPF4DClassifier: batch_size must be an int >= 1, got 0"),
        ({"dropout": 1.0}, ValueError, "EPPF4DClassifier: dropout must be a float in [0.0, 1.0), got 1.0"),
        ({"weight_decay": -0.1}, ValueError, "EPPF4DClassifier: weight_decay must be a float in [0.0, inf), got -0.1"),
        ({"n_hidden": 0}, ValueError, "EPPF4DClassifier: n_hidden must be an int >= 1, got 0"),
        ({"filters": (4, 8)}, ValueError, "EPPF4DClassifier: filters must be a tuple of 3 positive ints, got (4, 8)"),
        ({"early_stopping": "yes"}, ValueError, "EPPF4DClassifier: early_stopping must be True or False, got 'yes'"),
        ({"validation_fraction": 1.0}, ValueError, "EPPF4DClassifier: validation_fraction must be a float in (0.0, 1.0), got 1.0"),
        ({"n_iter_no_change": 0}, ValueError, "EPPF4DClassifier: n_iter_no_change must be an int >= 1, got 0"),
        ({"max_time": 0}, ValueError, "EPPF4DClassifier: max_time must be None or a float in (0.0, inf), got 0"),
        ({"max_time": "1h"}, TypeError, "EPPF4DClassifier: max_time must be None or a float in (0.0, inf), got '1h'"),
        ({"input_scaling": "minmax"}, ValueError, "EPPF4DClassifier: input_scaling must be one of 'global', 'bin', 'none', got 'minmax'"),
        ({"precision": "half"}, ValueError, "EPPF4DClassifier: precision must be one of 'auto', 'float32', 'bfloat16', got 'half'"),
        ({"device": None}, ValueError, "EPPF4DClassifier: device must be a str such as 'cpu' or 'cuda', got None"),
        ({"n_jobs": 0}, ValueError, "EPPF4DClassifier: n_jobs must be None or a non-zero int (-1: all cores), got 0"),
        ({"verbose": -1}, ValueError, "EPPF4DClassifier: verbose must be an int >= 0, got -1"),
    ],
)
def test_bad_parameters(params, err, msg):
    X, y = _toy(20, np.random.default_rng(0))
    kwargs = {"n_bins": N_BINS, **SMALL, **params}
    with pytest.raises(err, match=re.escape(msg)):
        EPPF4DClassifier(**kwargs).fit(X, y)


@pytest.mark.parametrize(
    "X, y, err, msg",
    [
        (np.full((6, 1200), 1 / 1200), ["a", "b"] * 3, ValueError,
         "EPPF4DClassifier: descriptors have 1200 values but n_bins=(4, 2, 3, 2) needs 48; pass the n_bins the descriptors were computed with"),
        (np.zeros(48), ["a"], ValueError, "EPPF4DClassifier: X must have shape (n_objects, n_features) or (n_objects, n_draws, n_features), got shape (48,)"),
        (np.zeros((0, 48)), [], ValueError, "EPPF4DClassifier: X is empty (shape (0, 1, 48))"),
        (np.full((4, 48), np.nan), ["a", "b"] * 2, ValueError, "EPPF4DClassifier: X contains NaN or infinite values"),
        (np.full((4, 48), 1e300), ["a", "b"] * 2, ValueError,
         "EPPF4DClassifier: X holds values beyond float32's range (largest magnitude 1e+300; the networks compute in "
         "float32): rescale the descriptors"),
        (np.full((4, 48), 1 / 48), np.array(["a", 1, 2.5, "b"], dtype=object), TypeError,
         "EPPF4DClassifier: y must hold class labels of one kind (numbers or strings, no NaN); got float, int, str labels"),
        (np.full((4, 48), "x"), ["a", "b"] * 2, TypeError, "EPPF4DClassifier: X must hold numbers, got dtype <U1"),
        (None, ["a"], TypeError, "EPPF4DClassifier: X must be an array of descriptors, got NoneType"),
        (np.full((4, 48), 1 / 48) + 0j, ["a", "b"] * 2, TypeError, "EPPF4DClassifier: X must hold real numbers, got dtype complex128"),
        (scipy.sparse.csr_matrix(np.full((4, 48), 1 / 48)), ["a", "b"] * 2, TypeError,
         "EPPF4DClassifier: X must be an array of descriptors, got csr_matrix (dense descriptors are needed: use X.toarray())"),
        ((row for row in np.full((4, 48), 1 / 48)), ["a", "b"] * 2, TypeError,
         "EPPF4DClassifier: X must be an array of descriptors, got generator"),
        (np.full((4, 48), 1 / 48), ["a", "b", "a"], ValueError, "EPPF4DClassifier: X has 4 objects but y has 3 labels"),
        (np.full((4, 48), 1 / 48), ["a"] * 4, ValueError, "EPPF4DClassifier: y has a single class 'a'; at least 2 are needed"),
        (np.full((4, 48), 1 / 48), [[0, 1]] * 4, ValueError, "EPPF4DClassifier: y must be 1D, got shape (4, 2)"),
    ],
)
def test_bad_input(X, y, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        EPPF4DClassifier(n_bins=N_BINS, **SMALL).fit(X, np.asarray(y))


def test_predict_checks_length_and_fit():
    X, y = _toy(20, np.random.default_rng(0))
    with pytest.raises(NotFittedError):
        EPPF4DClassifier(n_bins=N_BINS).predict(X)
    clf = EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, early_stopping=False, random_state=0, **SMALL).fit(X, y)
    msg = "EPPF4DClassifier: descriptors have 540 values but n_bins=(4, 2, 3, 2) needs 48"
    with pytest.raises(ValueError, match=re.escape(msg)):
        clf.predict(np.full((3, 540), 1 / 540))


def test_validation_fraction_too_large_for_data():
    X, y = _toy(3, np.random.default_rng(0))
    msg = "EPPF4DClassifier: validation_fraction=0.9 of 3 objects leaves no validation or no training objects"
    with pytest.raises(ValueError, match=re.escape(msg)):
        EPPF4DClassifier(n_bins=N_BINS, validation_fraction=0.9, **SMALL).fit(X, y)


def test_tags():
    tags = EPPF4DClassifier().__sklearn_tags__()
    assert tags.estimator_type == "classifier"
    assert tags.input_tags.three_d_array
    assert not tags.non_deterministic
    assert EPPF4DClassifier(device="cuda").__sklearn_tags__().non_deterministic


# ------------------------------------------------- options beyond the paper
def _side_toy(rng, n=60):
    """Descriptors that are pure noise; the label sits in one of two side columns."""
    X = rng.dirichlet(np.ones(math.prod(N_BINS)), size=n)
    y = rng.integers(0, 2, n)
    side = np.column_stack([np.where(y == 1, 1.0, -1.0) + 0.1 * rng.standard_normal(n), rng.standard_normal(n)])
    return X, side * 50 + 7, np.asarray(["no", "yes"])[y]  # far from standardised: the classifier must scale them


def test_side_features_are_learned_and_standardised_on_their_own():
    rng = np.random.default_rng(0)
    X, side, y = _side_toy(rng)
    params = dict(n_bins=N_BINS, max_epochs=6, lr=1e-2, early_stopping=False, random_state=0, **SMALL)
    with_side = EPPF4DClassifier(n_side_features="auto", **params).fit(np.hstack([X, side]), y)
    assert with_side.n_side_features_ == 2 and with_side.n_features_in_ == X.shape[1] + 2
    assert_allclose(with_side.side_mean_, side.mean(axis=0), rtol=1e-5)
    assert_allclose(with_side.side_scale_, side.std(axis=0), rtol=1e-5)
    # the descriptor's global scaling ignores the side columns
    assert_allclose(with_side.input_mean_, [X.mean()], rtol=1e-5)
    X2, side2, y2 = _side_toy(np.random.default_rng(1))
    assert np.mean(with_side.predict(np.hstack([X2, side2])) == y2) > 0.9
    # an explicit count is the same model
    one = dict(params, max_epochs=1)
    explicit = EPPF4DClassifier(n_side_features=2, **one).fit(np.hstack([X, side]), y)
    auto = EPPF4DClassifier(n_side_features="auto", **one).fit(np.hstack([X, side]), y)
    assert_allclose(explicit.predict_proba(np.hstack([X2, side2])), auto.predict_proba(np.hstack([X2, side2])))
    # without the side columns the label cannot be learned
    alone = EPPF4DClassifier(**params).fit(X, y)
    assert np.mean(alone.predict(X2) == y2) < 0.75


def test_side_features_in_pools_and_width_errors():
    rng = np.random.default_rng(0)
    X, side, y = _side_toy(rng, 40)
    pool = np.stack([np.hstack([X, side]), np.hstack([X[::-1] * 0 + X, side + 1])], axis=1)
    clf = EPPF4DClassifier(n_bins=N_BINS, n_side_features="auto", max_epochs=1, early_stopping=False, random_state=0,
                           **SMALL).fit(pool, y)
    assert clf.n_draws_fit_ == 2 and clf.predict_proba(pool).shape == (40, 2)
    with pytest.raises(ValueError, match="descriptors have 48 values but n_bins=.* needs 50"):
        clf.predict(X)
    with pytest.raises(ValueError, match="n_side_features for extra columns"):
        EPPF4DClassifier(n_bins=N_BINS, max_epochs=1, **SMALL).fit(np.hstack([X, side]), y)
    with pytest.raises(ValueError, match="n_side_features=3 needs 51"):
        EPPF4DClassifier(n_bins=N_BINS, n_side_features=3, max_epochs=1, **SMALL).fit(np.hstack([X, side]), y)
    with pytest.raises(ValueError, match="needs at least 48"):
        EPPF4DClassifier(n_bins=N_BINS, n_side_features="auto", max_epochs=1, **SMALL).fit(X[:, :10], y)


def test_batch_norm_label_smoothing_and_side_features_survive_save_and_load(tmp_path):
    import eppf

    rng = np.random.default_rng(0)
    X, side, y = _side_toy(rng, 40)
    Xs = np.hstack([X, side])
    clf = EPPF4DClassifier(n_bins=N_BINS, n_side_features="auto", batch_norm=True, label_smoothing=0.2, max_epochs=2,
                           early_stopping=False, random_state=0, **SMALL).fit(Xs, y)
    assert clf.net_.criterion_.label_smoothing == pytest.approx(0.2)
    assert clf.net_.module_.batch_norm and len(clf.net_.module_.norms) == 3
    path = tmp_path / "m.eppf"
    eppf.save_model(clf, path)
    loaded = eppf.load_model(path)
    assert_array_equal(loaded.predict_proba(Xs), clf.predict_proba(Xs))


def test_label_smoothing_softens_the_training_loss_floor():
    # with smoothing s over k classes the cross-entropy cannot fall below the entropy of the smoothed target
    rng = np.random.default_rng(0)
    X, y = _toy(60, rng)
    clf = EPPF4DClassifier(n_bins=N_BINS, label_smoothing=0.3, max_epochs=10, lr=1e-2, early_stopping=False,
                           random_state=0, **SMALL).fit(X, y)
    k, s = 3, 0.3
    q = np.full(k, s / k)
    q[0] += 1 - s
    floor = -(q * np.log(q)).sum()
    assert min(clf.net_.history[:, "train_loss"]) > floor - 1e-3


def test_ensemble_averages_members_and_survives_save_and_load(tmp_path):
    import eppf

    rng = np.random.default_rng(6)
    X, y = _toy(60, rng)
    X_test, _ = _toy(30, rng)
    common = dict(n_bins=N_BINS, max_epochs=3, validation_fraction=0.2, random_state=0, **SMALL)
    single = EPPF4DClassifier(**common).fit(X, y)
    ens = EPPF4DClassifier(n_estimators=3, **common).fit(X, y)
    assert len(ens.ensemble_nets_) == 2 and single.ensemble_nets_ == []
    members = [ens.net_] + ens.ensemble_nets_

    def member_proba(net):
        one = copy.copy(ens)
        one.net_, one.ensemble_nets_ = net, []
        return one.predict_proba(X_test)

    per_member = [member_proba(m) for m in members]
    # member 0 is the single-model network; the others were trained with other seeds
    assert_array_equal(per_member[0], single.predict_proba(X_test))
    assert not np.allclose(per_member[0], per_member[1]) and not np.allclose(per_member[1], per_member[2])
    proba = ens.predict_proba(X_test)
    assert_allclose(proba, np.mean(per_member, axis=0), rtol=1e-6)
    assert_allclose(proba.sum(axis=1), 1.0, rtol=1e-5)
    # every member was early-stopped on the same hold-out (its own best epoch kept)
    assert all(len(m.history) >= 1 for m in members)
    path = tmp_path / "ens.eppf"
    eppf.save_model(ens, path)
    loaded = eppf.load_model(path)
    assert len(loaded.ensemble_nets_) == 2
    assert_array_equal(loaded.predict_proba(X_test), proba)
    assert_array_equal(pickle.loads(pickle.dumps(ens)).predict_proba(X_test), proba)


@pytest.mark.parametrize("params, msg", [
    (dict(n_estimators=0), "n_estimators"),
    (dict(n_side_features=-1), "n_side_features"),
    (dict(n_side_features="some"), "n_side_features"),
    (dict(side_hidden=0), "side_hidden"),
    (dict(batch_norm=1), "batch_norm"),
    (dict(label_smoothing=1.0), "label_smoothing"),
])
def test_bad_option_values(params, msg):
    X, y = _toy(20, np.random.default_rng(0))
    with pytest.raises(ValueError, match=msg):
        EPPF4DClassifier(n_bins=N_BINS, **params).fit(X, y)


# ------------------------------------------------------- weight averaging
def test_swa_weights_are_the_mean_of_the_last_epochs_weights():
    # Reference: the same training stopped after each of the averaged epochs (constant lr, no early
    # stopping: epoch k of a longer run is the k-epoch run), its weights averaged here in float64.
    rng = np.random.default_rng(3)
    X, y = _toy(48, rng)
    common = dict(n_bins=N_BINS, early_stopping=False, random_state=0, verbose=0, **SMALL)
    swa = EPPF4DClassifier(max_epochs=4, swa_epochs=3, **common).fit(X, y)
    runs = [EPPF4DClassifier(max_epochs=k, **common).fit(X, y) for k in (2, 3, 4)]
    got = swa.net_.module_.state_dict()
    for key, value in got.items():
        expected = np.mean([r.net_.module_.state_dict()[key].double().numpy() for r in runs], axis=0)
        assert_allclose(value.double().numpy(), expected, rtol=1e-5, atol=1e-7, err_msg=key)
    # the last epoch's weights (what swa_epochs=0 keeps) are not the average
    assert not torch.equal(got["fc2.weight"], runs[-1].net_.module_.state_dict()["fc2.weight"])
    assert swa.n_epochs_ == 4 and swa.best_epoch_ == 4


def test_swa_with_early_stopping_averages_up_to_the_last_epoch_and_is_deterministic(tmp_path, capsys):
    import eppf

    rng = np.random.default_rng(4)
    X, y = _toy(60, rng)
    params = dict(n_bins=N_BINS, max_epochs=6, n_iter_no_change=2, validation_fraction=0.2, swa_epochs=2,
                  random_state=1, **SMALL)
    a = EPPF4DClassifier(verbose=1, **params).fit(X, y)
    n = a.n_epochs_
    assert f"weights averaged over epochs {n - 1} to {n}" in capsys.readouterr().out
    b = EPPF4DClassifier(verbose=0, **params).fit(X, y)
    assert_array_equal(a.predict_proba(X), b.predict_proba(X))
    # the snapshots are dropped once averaged; the averaged weights are the model's and are saved as such
    assert not dict(a.net_.callbacks_)["weight_averaging"].snapshots_
    path = tmp_path / "swa.eppf"
    eppf.save_model(a, path)
    loaded = eppf.load_model(path)
    assert loaded.swa_epochs == 2
    assert_array_equal(loaded.predict_proba(X), a.predict_proba(X))


def test_swa_epochs_is_validated():
    X, y = _toy(20, np.random.default_rng(0))
    with pytest.raises(ValueError, match="swa_epochs"):
        EPPF4DClassifier(n_bins=N_BINS, swa_epochs=-1).fit(X, y)


def test_model_of_the_previous_recipe_still_loads():
    # tests/data/eppf4d_recipe_0_2.eppf: an EPPF4DClassifier with the options of the "EPPF 4D+" recipe of
    # eppf 0.2.0 (pool input, side features, plateau schedule, label smoothing, a 2-network ensemble), saved
    # by that release's save_model before swa_epochs existed; the .npz holds its inputs and probabilities then.
    import os

    import eppf

    here = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")
    model = eppf.load_model(os.path.join(here, "eppf4d_recipe_0_2.eppf"))
    recorded = np.load(os.path.join(here, "eppf4d_recipe_0_2.npz"))
    assert model.swa_epochs == 0 and len(model.ensemble_nets_) == 1
    assert_allclose(model.predict_proba(recorded["X"]), recorded["proba"], rtol=1e-5, atol=1e-6)


def test_conv_impl_reaches_the_4d_network_and_survives_save_and_load(tmp_path):
    import eppf

    rng = np.random.default_rng(0)
    X, y = _toy(40, rng)
    fits = {}
    for impl in ("direct", "spectral"):
        clf = EPPF4DClassifier(n_bins=N_BINS, conv_impl=impl, precision="float32", max_epochs=2,
                               early_stopping=False, random_state=0, **SMALL).fit(X, y)
        assert clf.net_.module_.conv_impl == impl
        assert clf.net_.module_.conv2.impl_for(N_BINS[:3]) == impl
        fits[impl] = clf
    # the same training in both computations, equal up to float32 rounding
    assert_allclose(fits["spectral"].predict_proba(X), fits["direct"].predict_proba(X), atol=1e-5)
    path = tmp_path / "m.eppf"
    eppf.save_model(fits["spectral"], path)
    loaded = eppf.load_model(path)
    assert loaded.conv_impl == "spectral" and loaded.net_.module_.conv_impl == "spectral"
    assert_array_equal(loaded.predict_proba(X), fits["spectral"].predict_proba(X))
    # the 3D and 2D networks have no such choice and ignore it
    clf3 = EPPF4DClassifier(n_bins=N_BINS, conv="3d", conv_impl="spectral", max_epochs=1, early_stopping=False,
                            random_state=0, **SMALL).fit(X, y)
    assert not hasattr(clf3.net_.module_, "conv_impl")
    with pytest.raises(ValueError, match="conv_impl must be one of"):
        EPPF4DClassifier(n_bins=N_BINS, conv_impl="fft", **SMALL).fit(X, y)


@pytest.mark.parametrize("conv, params", [
    (conv, params) for conv in ["4d", "3d", "2d"]
    for params in [{"n_hidden": 10**12}, {"n_hidden": 10**30}, {"filters": (10**6, 10**6, 4)}]
] + [(conv, {"n_hidden": 6 * 10**7}) for conv in ["4d", "2d"]])  # (these two: refused by the exact count)
def test_a_network_too_large_is_refused_before_it_is_built(conv, params, monkeypatch):
    # torch's allocator failed with a RuntimeError ("you tried to allocate 57600000000000 bytes"),
    # or torch.empty with an overflow TypeError, instead of an error naming the parameters
    built = []  # (the training data are made just before the network)
    monkeypatch.setattr(EPPF4DClassifier, "_make_datasets", lambda *a, **k: built.append(1))
    rng = np.random.default_rng(0)
    X, y = rng.dirichlet(np.ones(12), size=12), np.arange(12) % 3
    clf = EPPF4DClassifier(n_bins=(2, 2, 3, 1), conv=conv, max_epochs=1, early_stopping=False, verbose=0,
                           **{**SMALL, **params})
    with pytest.raises(ValueError, match=r"EPPF4DClassifier: the network would have (at least )?[\d,]+ parameters "
                                         r"\(n_bins=\(2, 2, 3, 1\), .*, 3 classes\), more than the 1,000,000,000 it may have"):
        clf.fit(X, y)
    assert not built and not hasattr(clf, "classes_")


def test_the_exact_parameter_count_decides_near_the_bound():
    from eppf.classifiers import _base

    clf = EPPF4DClassifier(n_bins=(2, 2, 3, 1), conv="2d", verbose=0, **SMALL)
    clf._check_params()
    with torch.device("meta"):
        n = count_parameters(EPPFNet2D(n_bins=(2, 2, 3, 1), n_classes=3, filters=(4, 8, 4), n_hidden=16))
    assert clf._parameter_lower_bound(3) <= n
    clf._check_network_size(3)
    import unittest.mock

    with unittest.mock.patch.object(_base, "MAX_PARAMETERS", n - 1):
        with pytest.raises(ValueError, match=f"the network would have {n:,} parameters"):
            clf._check_network_size(3)
