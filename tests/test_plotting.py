import itertools
import math
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from sklearn.exceptions import NotFittedError  # noqa: E402
from sklearn.metrics import confusion_matrix  # noqa: E402

from eppf import EPPF4DClassifier  # noqa: E402
from eppf.plotting import (  # noqa: E402
    filter_responses,
    plot_confusion_matrix,
    plot_descriptor,
    plot_filter_responses,
    plot_learning_curve,
    plot_noise_curve,
    plot_scores_bar,
)

N_BINS = (6, 2, 2, 2)
TINY = dict(filters=(4, 5, 3), n_hidden=8, batch_size=8, n_jobs=1, random_state=0)


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _toy(n, rng, n_bins=N_BINS):
    n_features = math.prod(n_bins)
    y = np.repeat(["cup", "mug"], n // 2)
    X = rng.random((n, n_features))
    X[y == "cup", : n_features // 2] += 1.0
    X /= X.sum(axis=1, keepdims=True)
    return X, y


@pytest.fixture(scope="module")
def fitted():
    X, y = _toy(24, np.random.default_rng(0))
    # float32: the responses are compared with a float64 forward pass
    clf = EPPF4DClassifier(N_BINS, max_epochs=2, validation_fraction=0.25, precision="float32", **TINY).fit(X, y)
    return clf, X, y


def test_import_eppf_does_not_import_matplotlib():
    code = "import sys, eppf; assert 'matplotlib' not in sys.modules; import eppf.plotting; print('ok')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "ok"


# ---------------------------------------------------------------- descriptor
@pytest.mark.parametrize("n_bins", [(20, 4, 5, 3), (15, 3, 4, 3), (3, 2, 1, 1)])
@pytest.mark.parametrize("as_4d", [False, True])
def test_plot_descriptor_panels_show_the_slices(n_bins, as_4d):
    rng = np.random.default_rng(1)
    x = rng.random(math.prod(n_bins))
    hist = x.reshape(n_bins)
    fig = plot_descriptor(hist if as_4d else x, n_bins)
    n1, n2, n3, n4 = n_bins
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == n3 * n4
    assert len(fig.axes) == n3 * n4 + 1  # and the colour bar
    for (i4, i3), ax in zip(itertools.product(range(n4), range(n3)), panels):
        assert_array_equal(np.asarray(ax.images[0].get_array()), hist[:, :, i3, i4].T)
    # one shared colour scale
    assert {ax.images[0].get_clim() for ax in panels} == {(x.min(), x.max())}


def test_plot_descriptor_log_blanks_empty_bins():
    x = np.zeros(48)
    x[[0, 5, 47]] = [1.0, 10.0, 100.0]
    fig = plot_descriptor(x, N_BINS, log=True, title="t")
    data = fig.axes[0].images[0].get_array()
    assert np.ma.is_masked(data) or np.isnan(np.asarray(data, dtype=float)).any()
    assert fig._suptitle.get_text() == "t"


@pytest.mark.parametrize(
    "value, log",
    [(v, False) for v in (0.0, 7.0, -3.0, 1e150, -1e150, 1e-280)] + [(v, True) for v in (7.0, 1e150, 1e-280)],
)
def test_plot_descriptor_draws_extreme_and_constant_values(value, log):
    # Every bin equal, or one bin apart (of opposite sign, or 1e150 on a log scale): the figure draws
    # without matplotlib's warnings or errors, and the color range holds every value.
    for x in (np.full(48, value), np.r_[np.full(47, value), (1e150 if log else -value)]):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            fig = plot_descriptor(x, N_BINS, log=log)
            fig.canvas.draw()
        image = fig.axes[0].images[0]
        low, high = image.norm.vmin, image.norm.vmax
        assert low < high
        assert low <= x[x > 0].min() if log else low <= x.min()
        assert high >= x.max()
        plt.close(fig)


def test_plot_descriptor_into_given_figure():
    fig = plt.figure()
    assert plot_descriptor(np.ones(48), N_BINS, fig=fig) is fig


@pytest.mark.parametrize(
    "descriptor, n_bins, msg",
    [
        (np.ones(47), N_BINS, "plot_descriptor: descriptor has 47 values but n_bins=(6, 2, 2, 2) needs 48"),
        (np.ones((6, 2, 2, 3)), N_BINS, "plot_descriptor: descriptor has shape (6, 2, 2, 3) but n_bins=(6, 2, 2, 2)"),
        (np.ones((2, 24)), N_BINS, "plot_descriptor: descriptor must be one flat descriptor"),
        (np.full(48, np.nan), N_BINS, "plot_descriptor: descriptor contains NaN or infinite values"),
        (np.ones(48), (6, 2, 4), "plot_descriptor: n_bins must be a tuple of 4 positive ints"),
        (np.ones(48), (6, 2, 4, 0), "plot_descriptor: n_bins must be a tuple of 4 positive ints"),
        (np.zeros(48), N_BINS, "plot_descriptor: log=True needs at least one positive bin"),
        (np.full(48, 1e308), N_BINS, "plot_descriptor: descriptor holds values beyond 1e+150 in magnitude"),
        (np.r_[np.ones(47), -1e200], N_BINS, "plot_descriptor: descriptor holds values beyond 1e+150 in magnitude"),
        (np.full(48, 5e-324), N_BINS, "plot_descriptor: log=True cannot draw the positive value 4.94e-324"),
    ],
)
def test_plot_descriptor_errors(descriptor, n_bins, msg):
    log = "log=True" in msg
    with pytest.raises(ValueError, match=re.escape(msg)):
        plot_descriptor(descriptor, n_bins, log=log)


# ---------------------------------------------------------- filter responses
def _same_conv4d_reference(x, weight, bias):
    """Slow NumPy 4D cross-correlation, stride 1, TensorFlow "same" zero padding."""
    c_out, c_in, *kernel = weight.shape
    pads = [((k - 1) // 2, k // 2) for k in kernel]
    xp = np.pad(x, [(0, 0)] + pads)
    spatial = x.shape[1:]
    out = np.zeros((c_out, *spatial))
    for o in range(c_out):
        acc = np.full(spatial, float(bias[o]))
        for offset in itertools.product(*(range(k) for k in kernel)):
            window = xp[(slice(None),) + tuple(slice(d, d + s) for d, s in zip(offset, spatial))]
            acc += np.tensordot(weight[(o, slice(None)) + offset], window, axes=(0, 0))
        out[o] = acc
    return out


def test_filter_responses_match_a_numpy_forward_pass(fitted):
    clf, X, _ = fitted
    module = clf.net_.module_
    r1, r2 = filter_responses(clf, X[3])
    assert r1.shape == (4, *N_BINS) and r2.shape == (5, *N_BINS)
    x = ((X[3].astype(np.float32) - clf.input_mean_) / clf.input_scale_).reshape(1, *N_BINS).astype(np.float64)
    w1, b1 = module.conv1.weight.detach().double().numpy(), module.conv1.bias.detach().double().numpy()
    w2, b2 = module.conv2.weight.detach().double().numpy(), module.conv2.bias.detach().double().numpy()
    ref1 = np.maximum(_same_conv4d_reference(x, w1, b1), 0)
    ref2 = np.maximum(_same_conv4d_reference(ref1, w2, b2), 0)
    assert_allclose(r1, ref1, rtol=1e-4, atol=1e-5)
    assert_allclose(r2, ref2, rtol=1e-4, atol=1e-4)
    # the module is left as it was: fast route on, no hooks, same mode
    assert module.folded is True
    assert not module.conv1._forward_hooks and not module.conv2._forward_hooks


def test_filter_responses_of_a_bfloat16_network_are_float32(fitted):
    # A network trained in bfloat16 (precision="bfloat16", or "auto" on a CPU that has it) records
    # bfloat16 responses; they come back as float32 arrays, equal to the float32 ones up to rounding.
    clf, X, y = fitted
    mixed = EPPF4DClassifier(N_BINS, max_epochs=2, validation_fraction=0.25, precision="float32", **TINY).fit(X, y)
    mixed.net_.module_.precision = "bfloat16"  # the same weights, run in mixed precision
    for r, ref in zip(filter_responses(mixed, X[3]), filter_responses(clf, X[3])):
        assert r.dtype == np.float32 and r.shape == ref.shape
        assert not np.array_equal(r, ref)
        assert_allclose(r, ref, rtol=0.05, atol=0.05 * np.abs(ref).max())


def test_filter_responses_leave_predictions_unchanged(fitted):
    clf, X, _ = fitted
    before = clf.predict_proba(X)
    filter_responses(clf, X[0].reshape(N_BINS), layers=(1,))
    assert_array_equal(clf.predict_proba(X), before)


@pytest.mark.parametrize("reduce", ["max", "sum"])
@pytest.mark.parametrize("layers, n_filters", [((0, 1), 8), ((0, 1), 2), ((1,), 3), ((0,), 1)])
def test_plot_filter_responses_panels(fitted, layers, n_filters, reduce):
    clf, X, _ = fitted
    fig = plot_filter_responses(clf, X[1], layers=layers, n_filters=n_filters, reduce=reduce)
    responses = filter_responses(clf, X[1], layers=layers)
    k = min(n_filters, 4 if 0 in layers else 5)
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == len(layers) * k
    assert len(fig.axes) == len(layers) * k + len(layers)
    reducer = np.max if reduce == "max" else np.sum
    for row, response in enumerate(responses):
        for j in range(k):
            image = np.asarray(panels[row * k + j].images[0].get_array())
            assert image.shape == (N_BINS[1], N_BINS[0])
            assert_allclose(image, reducer(response[j], axis=(2, 3)).T)


def test_plot_filter_responses_unfitted():
    msg = "plot_filter_responses: this EPPF4DClassifier is not fitted yet"
    with pytest.raises(NotFittedError, match=re.escape(msg)):
        plot_filter_responses(EPPF4DClassifier(N_BINS), np.ones(48))


def test_plot_filter_responses_not_4d():
    X, y = _toy(12, np.random.default_rng(2))
    clf = EPPF4DClassifier(N_BINS, conv="2d", max_epochs=1, early_stopping=False, **TINY).fit(X, y)
    msg = "plot_filter_responses: the classifier has conv='2d'; filter responses are shown for the 4D network only"
    with pytest.raises(ValueError, match=re.escape(msg)):
        plot_filter_responses(clf, X[0])


@pytest.mark.parametrize(
    "kwargs, err, msg",
    [
        (dict(layers=(2,)), ValueError, "plot_filter_responses: layers must be a non-empty tuple of 0"),
        (dict(layers=()), ValueError, "plot_filter_responses: layers must be a non-empty tuple of 0"),
        (dict(n_filters=0), ValueError, "plot_filter_responses: n_filters must be an int >= 1, got 0"),
        (dict(reduce="mean"), ValueError, "plot_filter_responses: reduce must be 'max' or 'sum', got 'mean'"),
        (dict(descriptor=np.ones(40)), ValueError, "plot_filter_responses: descriptor has 40 values but"),
    ],
)
def test_plot_filter_responses_errors(fitted, kwargs, err, msg):
    clf, X, _ = fitted
    kwargs = {"descriptor": X[0], **kwargs}
    with pytest.raises(err, match=re.escape(msg)):
        plot_filter_responses(clf, **kwargs)


def test_plot_filter_responses_needs_the_classifier():
    msg = "plot_filter_responses: classifier must be an eppf.EPPF4DClassifier, got str"
    with pytest.raises(TypeError, match=re.escape(msg)):
        plot_filter_responses("net", np.ones(48))


# ---------------------------------------------------------- confusion matrix
@pytest.mark.parametrize("normalize", ["true", "pred", "all", None])
@pytest.mark.parametrize("labels", [None, ["eel", "cat", "dog"]])
def test_plot_confusion_matrix_matches_sklearn(normalize, labels):
    rng = np.random.default_rng(3)
    y_true = rng.choice(["cat", "dog", "eel"], 40)
    y_pred = np.where(rng.random(40) < 0.6, y_true, rng.choice(["cat", "dog", "eel"], 40))
    ax = plot_confusion_matrix(y_true, y_pred, labels=labels, normalize=normalize)
    expected = confusion_matrix(y_true, y_pred, labels=labels, normalize=normalize)
    assert_allclose(np.asarray(ax.images[0].get_array()), expected)
    names = labels if labels is not None else ["cat", "dog", "eel"]
    assert [t.get_text() for t in ax.get_xticklabels()] == names
    assert [t.get_text() for t in ax.get_yticklabels()] == names
    assert len(ax.texts) == 9
    if normalize is None:
        assert sorted(int(t.get_text()) for t in ax.texts) == sorted(expected.ravel().tolist())


def test_plot_confusion_matrix_display_labels_and_no_values():
    ax = plot_confusion_matrix([0, 1, 1], [0, 1, 0], display_labels=["box", "ball"], values=False)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["box", "ball"]
    assert len(ax.texts) == 0


@pytest.mark.parametrize(
    "args, kwargs, msg",
    [
        (([0, 1], [0]), {}, "plot_confusion_matrix: y_true and y_pred have different lengths (2 and 1)"),
        (([], []), {}, "plot_confusion_matrix: y_true is empty"),
        (([[0]], [[0]]), {}, "plot_confusion_matrix: y_true and y_pred must be 1D"),
        (([0, 1], [0, 1]), dict(normalize="rows"), "plot_confusion_matrix: normalize must be 'true', 'pred', 'all'"),
        (([0, 1], [0, 1]), dict(display_labels=["a"]), "plot_confusion_matrix: display_labels has 1 names"),
        (([0.0, np.nan], [0.0, 0.0]), {}, "plot_confusion_matrix: y_true contains NaN or infinite values"),
        (([0, 1], [0.5, 1.5]), {}, "plot_confusion_matrix: y_pred must hold class labels, got a 'continuous' target"),
    ],
)
def test_plot_confusion_matrix_errors(args, kwargs, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        plot_confusion_matrix(*args, **kwargs)


def test_plot_confusion_matrix_refuses_labels_that_do_not_sort():
    y = np.array([1, "a", 2.5], dtype=object)
    with pytest.raises(TypeError, match=re.escape("plot_confusion_matrix: y_true mixes labels that do not sort")):
        plot_confusion_matrix(y, y)


def test_plot_learning_curve_draws_a_diverged_loss():
    # Infinite and NaN losses (a diverged epoch) stay drawable: gaps in the line, no error.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ax = plot_learning_curve([{"train_loss": 1.0}, {"train_loss": np.inf}, {"train_loss": np.nan}])
        ax.figure.canvas.draw()
    assert_array_equal(ax.lines[0].get_ydata(), [1.0, np.inf, np.nan])


# --------------------------------------------------------------- noise curve
def test_plot_noise_curve_mean_and_band():
    rng = np.random.default_rng(4)
    sigmas = [0.0, 0.005, 0.01, 0.02]
    draws = rng.random((4, 5))
    single = rng.random(4)
    ax = plot_noise_curve(sigmas, {"EPPF": draws, "ESF": single}, ylabel="acc")
    assert len(ax.lines) == 2
    assert_allclose(ax.lines[0].get_xdata(), sigmas)
    assert_allclose(ax.lines[0].get_ydata(), draws.mean(axis=1))
    assert_allclose(ax.lines[1].get_ydata(), single)
    assert len(ax.collections) == 1  # a band only for the method with draws
    band = ax.collections[0].get_paths()[0].vertices
    assert_allclose(band[:, 1].max(), (draws.mean(axis=1) + draws.std(axis=1)).max())
    assert_allclose(band[:, 1].min(), (draws.mean(axis=1) - draws.std(axis=1)).min())
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["EPPF", "ESF"]
    assert ax.get_ylabel() == "acc"


@pytest.mark.parametrize(
    "sigmas, scores, msg",
    [
        ([0, 1], {"a": [1, 2, 3]}, "plot_noise_curve: scores['a'] has shape (3,); expected (2,) or (2, n_draws)"),
        ([0, 1], {"a": np.ones((3, 2))}, "plot_noise_curve: scores['a'] has shape (3, 2)"),
        ([0, 1], {}, "plot_noise_curve: scores must be a non-empty dict"),
        ([], {"a": []}, "plot_noise_curve: sigmas must be a non-empty 1D array"),
        ([0, np.nan], {"a": [1, 2]}, "plot_noise_curve: sigmas contains NaN or infinite values"),
        ([0, 1], {"a": [1, np.nan]}, "plot_noise_curve: scores['a'] contains NaN or infinite values"),
        ([0, 1e200], {"a": [1, 2]}, "plot_noise_curve: sigmas holds values beyond 1e+150 in magnitude"),
        ([0, 1], {"a": [[1e300, -1e300], [0, 1]]}, "plot_noise_curve: scores['a'] holds values beyond 1e+150"),
    ],
)
def test_plot_noise_curve_errors(sigmas, scores, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        plot_noise_curve(sigmas, scores)


# ---------------------------------------------------------------- scores bar
def _error_segments(ax):
    from matplotlib.container import BarContainer

    (bars,) = [c for c in ax.containers if isinstance(c, BarContainer)]
    (vertical,) = bars.errorbar.lines[2]
    return vertical.get_segments()


@pytest.mark.parametrize("sort", [False, True])
def test_plot_scores_bar(sort):
    scores = {"no f1": 0.5, "all": (0.9, 0.02), "no f4": (0.7, 0.01)}
    ax = plot_scores_bar(scores, sort=sort, ylabel="macro F1")
    heights = [p.get_height() for p in ax.patches]
    names = [t.get_text() for t in ax.get_xticklabels()]
    if sort:
        assert names == ["all", "no f4", "no f1"]
        assert_allclose(heights, [0.9, 0.7, 0.5])
    else:
        assert names == ["no f1", "all", "no f4"]
        assert_allclose(heights, [0.5, 0.9, 0.7])
    assert ax.get_ylabel() == "macro F1"
    segments = _error_segments(ax)
    spans = {n: s[1, 1] - s[0, 1] for n, s in zip(names, segments)}
    assert_allclose([spans["all"], spans["no f4"], spans["no f1"]], [0.04, 0.02, 0.0], atol=1e-12)


def test_plot_scores_bar_errors_dict_overrides():
    ax = plot_scores_bar({"a": (1.0, 0.5), "b": 2.0}, errors={"a": 0.1, "b": 0.2})
    segments = _error_segments(ax)
    assert_allclose([s[1, 1] - s[0, 1] for s in segments], [0.2, 0.4])


@pytest.mark.parametrize(
    "scores, errors, msg",
    [
        ({}, None, "plot_scores_bar: scores must be a non-empty dict"),
        ({"a": (1, 2, 3)}, None, "plot_scores_bar: scores['a'] must be a number or a (mean, std) pair"),
        ({"a": "high"}, None, "plot_scores_bar: scores['a'] must be numbers"),
        ({"a": 1.0}, {"b": 0.1}, "plot_scores_bar: errors has 'b', which is not in scores"),
        ({"a": np.inf}, None, "plot_scores_bar: scores['a'] contains NaN or infinite values"),
        ({"a": 1e308, "b": -1e308}, None, "plot_scores_bar: scores['a'] holds values beyond 1e+150 in magnitude"),
        ({"a": 0.5}, {"a": 1e200}, "plot_scores_bar: errors['a'] holds values beyond 1e+150 in magnitude"),
    ],
)
def test_plot_scores_bar_errors(scores, errors, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        plot_scores_bar(scores, errors=errors)


# ------------------------------------------------------------ learning curve
def test_plot_learning_curve_from_classifier(fitted):
    clf, _, _ = fitted
    ax = plot_learning_curve(clf)
    history = clf.net_.history
    assert [line.get_label() for line in ax.lines] == ["train_loss", "valid_loss"]
    assert_allclose(ax.lines[0].get_xdata(), history[:, "epoch"])
    assert_allclose(ax.lines[0].get_ydata(), history[:, "train_loss"])
    assert_allclose(ax.lines[1].get_ydata(), history[:, "valid_loss"])
    (twin,) = [other for other in ax.figure.axes if other is not ax and other.lines]
    assert [line.get_label() for line in twin.lines] == ["valid_acc"]
    assert_allclose(twin.lines[0].get_ydata(), history[:, "valid_acc"])


def test_plot_learning_curve_from_list_skips_absent_keys():
    history = [{"epoch": 1, "train_loss": 2.0}, {"epoch": 2, "train_loss": 1.5}]
    ax = plot_learning_curve(history)
    assert [line.get_label() for line in ax.lines] == ["train_loss"]
    assert len(ax.figure.axes) == 1  # no twin axis without accuracy


def test_plot_learning_curve_unfitted():
    msg = "plot_learning_curve: this EPPF4DClassifier is not fitted yet"
    with pytest.raises(NotFittedError, match=re.escape(msg)):
        plot_learning_curve(EPPF4DClassifier())


@pytest.mark.parametrize(
    "history, err, msg",
    [
        ([], ValueError, "plot_learning_curve: the history is empty"),
        ([{"epoch": 1, "loss": 1.0}], ValueError, "plot_learning_curve: none of the keys"),
        ([1, 2], TypeError, "plot_learning_curve: the history must be a list of per-epoch dicts"),
        (3.0, TypeError, "plot_learning_curve: expected a fitted EPPF4DClassifier or PointNetClassifier"),
        ([{"train_loss": "high"}], ValueError, "plot_learning_curve: the history's 'train_loss' values must be numbers"),
        ([{"train_loss": 1e308}], ValueError, "plot_learning_curve: the history's 'train_loss' values reach beyond"),
        ([{"epoch": "one", "train_loss": 1.0}], ValueError, "plot_learning_curve: the history's epochs must be numbers"),
        ([{"epoch": np.nan, "train_loss": 1.0}], ValueError,
         "plot_learning_curve: the history's epochs contains NaN or infinite values"),
    ],
)
def test_plot_learning_curve_errors(history, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        plot_learning_curve(history)
