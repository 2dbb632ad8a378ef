"""Tests of the retrieval protocol and metrics (eppf.metrics)."""

import re
import warnings

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.metrics import (
    accuracy_score,
    balanced_accuracy_score,
    f1_score,
    precision_score,
    recall_score,
)
from sklearn.utils import check_random_state

from eppf import KLNearestNeighbors, symmetric_kl_distances
from eppf.metrics import (
    RepeatedRetrievalResult,
    leave_one_out_retrieval,
    repeated_retrieval,
    retrieval_scores,
)


def _sklearn_scores(y_true, y_pred):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {
            "total_accuracy": accuracy_score(y_true, y_pred),
            "mean_class_accuracy": balanced_accuracy_score(y_true, y_pred),
            "macro_precision": precision_score(y_true, y_pred, average="macro", zero_division=0),
            "macro_recall": recall_score(y_true, y_pred, average="macro", zero_division=0),
            "macro_f1": f1_score(y_true, y_pred, average="macro", zero_division=0),
        }


# ------------------------------------------------------------------ scores


def test_scores_hand_example():
    # classes a (4 objects), b (2), c (1)
    y_true = ["a", "a", "a", "a", "b", "b", "c"]
    y_pred = ["a", "a", "a", "b", "b", "a", "a"]
    s = retrieval_scores(y_true, y_pred)
    # per class: recall a 3/4, b 1/2, c 0; precision a 3/5, b 1/2, c 0 (never predicted)
    # F1 = 2 tp / (support + predicted): a 6/9, b 2/4, c 0
    assert s["total_accuracy"] == pytest.approx(4 / 7)
    assert s["mean_class_accuracy"] == pytest.approx((3 / 4 + 1 / 2 + 0) / 3)
    assert s["macro_recall"] == pytest.approx((3 / 4 + 1 / 2 + 0) / 3)
    assert s["macro_precision"] == pytest.approx((3 / 5 + 1 / 2 + 0) / 3)
    assert s["macro_f1"] == pytest.approx((6 / 9 + 2 / 4 + 0) / 3)
    assert list(s) == ["total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1"]
    assert all(isinstance(v, float) for v in s.values())
    for k, v in _sklearn_scores(y_true, y_pred).items():
        assert s[k] == pytest.approx(v, abs=1e-15), k


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("n_classes", [2, 5, 12])
def test_scores_match_sklearn(seed, n_classes):
    rng = np.random.default_rng(seed)
    y_true = rng.integers(0, n_classes, size=60)
    y_pred = np.where(rng.random(60) < 0.6, y_true, rng.integers(0, n_classes, size=60))
    s = retrieval_scores(y_true, y_pred)
    for k, v in _sklearn_scores(y_true, y_pred).items():
        assert s[k] == pytest.approx(v, abs=1e-14), k


def test_mean_class_accuracy_differs_from_macro_recall_only_for_foreign_predictions():
    # "z" is predicted but never true: macro recall counts it as a class with
    # recall 0 (sklearn), the mean per-class accuracy does not.
    y_true = [0, 0, 1, 1]
    y_pred = [0, 0, 1, 2]
    s = retrieval_scores(y_true, y_pred)
    assert s["mean_class_accuracy"] == pytest.approx(0.75)
    assert s["macro_recall"] == pytest.approx(0.5)
    for k, v in _sklearn_scores(y_true, y_pred).items():
        assert s[k] == pytest.approx(v, abs=1e-15), k


def test_scores_perfect_and_column_vectors():
    s = retrieval_scores(np.array([[1], [2], [2]]), [1, 2, 2])
    assert s == {k: 1.0 for k in s}


@pytest.mark.parametrize(
    "y_true, y_pred, msg",
    [
        ([0, 1], [0, 1, 1], "retrieval_scores: y_true and y_pred have different lengths (2 and 3)"),
        ([], [], "retrieval_scores: y_true is empty"),
        ([[0, 1], [1, 0]], [0, 1], "retrieval_scores: y_true must be a 1D array of class labels, got shape (2, 2)"),
        ([0.5, 1.5], [0.5, 1.5], "retrieval_scores: y_true must hold class labels, got a 'continuous' target"),
        ([0, np.nan], [0, 1], "retrieval_scores: y_true contains NaN or infinite values"),
        (["a", "b"], [0, 1], "retrieval_scores: y_true and y_pred mix string and numeric labels"),
        (None, [0, 1], "retrieval_scores: y_true is None; class labels are needed"),
        ([1j, 2], [1j, 2], "retrieval_scores: y_true must hold class labels, got complex values"),
        ([0, 1], np.array([0, 1], dtype=complex), "retrieval_scores: y_pred must hold class labels, got complex values"),
        (np.array(["2020-01-01", "NaT"], dtype="datetime64[D]"), np.array(["2020-01-01"] * 2, dtype="datetime64[D]"),
         "retrieval_scores: y_true contains NaT (not-a-time) labels"),
    ],
)
def test_scores_errors(y_true, y_pred, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        retrieval_scores(y_true, y_pred)


def test_labels_that_do_not_sort_together_are_named():
    from eppf.metrics import leave_one_out_retrieval

    mixed = np.array(["a", 1, 2.5, "b"], dtype=object)
    with pytest.raises(TypeError, match=re.escape("retrieval_scores: y_true mixes labels that do not sort together "
                                                  "(float, int, str)")):
        retrieval_scores(mixed, mixed)
    X = np.random.default_rng(0).random((4, 6))
    with pytest.raises(TypeError, match=re.escape("leave_one_out_retrieval: y mixes labels")):
        leave_one_out_retrieval(X, mixed)  # (NumPy's bare "'<' not supported" before)


# ------------------------------------------------------------ leave-one-out


def _data(n_per_class=20, n_classes=4, n_bins=60, seed=0):
    rng = np.random.default_rng(seed)
    profiles = rng.dirichlet(np.full(n_bins, 0.3), size=n_classes)
    X = np.vstack([rng.dirichlet(30 * p + 0.01, size=n_per_class) for p in profiles])
    X[X < 2e-3] = 0.0
    X /= X.sum(axis=1, keepdims=True)
    return X, np.repeat(np.arange(n_classes), n_per_class)


@pytest.mark.parametrize("chunk_size", [None, 1, 7, 32, 500])
@pytest.mark.parametrize("renormalize", [False, True])
def test_loo_matches_brute_force(chunk_size, renormalize):
    X, y = _data(seed=1)
    y_pred, ind = leave_one_out_retrieval(X, y, chunk_size=chunk_size, renormalize=renormalize, return_indices=True)
    D = symmetric_kl_distances(X, renormalize=renormalize)
    np.fill_diagonal(D, np.inf)
    assert_array_equal(ind, np.argmin(D, axis=1))
    assert_array_equal(y_pred, y[ind])
    # the same as the estimator's leave-one-out neighbours
    knn = KLNearestNeighbors(renormalize=renormalize).fit(X, y)
    assert_array_equal(ind, knn.kneighbors(return_distance=False)[:, 0])


@pytest.mark.parametrize("chunk_size", [None, 3, 37, 64])
def test_loo_ties_go_to_lowest_index(chunk_size):
    # exact copies of rows, with enough bins and rows that the matrix products
    # round differently at different positions
    rng = np.random.default_rng(2)
    base = rng.dirichlet(np.full(300, 0.1), size=6)
    filler = rng.dirichlet(np.full(300, 0.1), size=200)
    X = np.vstack([base, filler, base, filler[:3], base])
    y = np.arange(X.shape[0])
    _, ind = leave_one_out_retrieval(X, y, chunk_size=chunk_size, return_indices=True)
    first, second, third = np.arange(6), np.arange(206, 212), np.arange(215, 221)
    assert_array_equal(ind[first], second)
    assert_array_equal(ind[second], first)
    assert_array_equal(ind[third], first)
    assert_array_equal(ind[6:9], np.arange(212, 215))  # filler rows and their copies
    assert_array_equal(ind[212:215], np.arange(6, 9))


def test_loo_string_labels_and_floor():
    X, y = _data(seed=3)
    class_names = np.array(["bed", "chair", "desk", "sofa"])
    y_pred = leave_one_out_retrieval(X, class_names[y])
    assert y_pred.dtype.kind == "U"
    assert_array_equal(y_pred, class_names[leave_one_out_retrieval(X, y)])
    # an explicit floor equal to the automatic one gives the same answer
    floor = X[X > 0].min() / 2
    assert_array_equal(leave_one_out_retrieval(X, y, floor=floor), leave_one_out_retrieval(X, y))
    assert retrieval_scores(y, leave_one_out_retrieval(X, y))["total_accuracy"] > 0.9


def test_loo_n_jobs():
    X, y = _data(seed=4)
    assert_array_equal(leave_one_out_retrieval(X, y, n_jobs=1), leave_one_out_retrieval(X, y))


@pytest.mark.parametrize(
    "X, y, kwargs, err, msg",
    [
        ([[0.5, 0.5]], [0], {}, ValueError, "leave_one_out_retrieval: leave-one-out needs at least 2 samples, got 1"),
        ([[0.5, 0.5], [0.1, 0.9]], [0], {}, ValueError, "leave_one_out_retrieval: X has 2 samples but y has 1 labels"),
        ([[0.5, -0.5], [0.1, 0.9]], [0, 1], {}, ValueError, "Negative values in data passed to leave_one_out_retrieval (X)"),
        ([[0.5, np.nan], [0.1, 0.9]], [0, 1], {}, ValueError, "leave_one_out_retrieval: Input X contains NaN"),
        ([0.5, 0.5], [0, 1], {}, ValueError, "leave_one_out_retrieval: Expected 2D array, got 1D array instead"),
        ([[0.5, 0.5], [0.1, 0.9]], [0.5, 0.7], {}, ValueError, "leave_one_out_retrieval: y must hold class labels, got a 'continuous' target"),
        ([[0.5, 0.5], [0.1, 0.9]], [0, 1], {"floor": -1}, ValueError, "leave_one_out_retrieval: floor must be 'auto' or a positive float, got -1"),
        ([[0.5, 0.5], [0.1, 0.9]], [0, 1], {"chunk_size": 0}, ValueError, "leave_one_out_retrieval: chunk_size must be a positive int or None, got 0"),
        ([[0.5, 0.5], [0.1, 0.9]], [0, 1], {"renormalize": 1}, TypeError, "leave_one_out_retrieval: renormalize must be a bool, got 1"),
        ([[0.0, 0.0], [0.0, 0.0]], [0, 1], {}, ValueError, "leave_one_out_retrieval: cannot learn floor='auto' because X has no positive value"),
    ],
)
def test_loo_errors(X, y, kwargs, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        leave_one_out_retrieval(X, y, **kwargs)


# --------------------------------------------------------- repeated draws


class _NoisyHistogram(TransformerMixin, BaseEstimator):
    """Test double: a 2D histogram of each cloud's x, y plus seeded noise."""

    def __init__(self, n_bins=6, noise=0.02, random_state=None):
        self.n_bins = n_bins
        self.noise = noise
        self.random_state = random_state

    def fit(self, clouds, y=None):
        self.n_fits_ = getattr(self, "n_fits_", 0) + 1
        return self

    def transform(self, clouds):
        rng = check_random_state(self.random_state)
        out = []
        for c in clouds:
            h, _, _ = np.histogram2d(c[:, 0], c[:, 1], bins=self.n_bins, range=[[-1, 1], [-1, 1]])
            h = h.ravel() / h.sum()
            out.append(np.abs(h + self.noise * rng.standard_normal(h.size)))
        return np.array(out)


class _NoSeed(TransformerMixin, BaseEstimator):
    def fit(self, clouds, y=None):
        return self

    def transform(self, clouds):
        return np.ones((len(clouds), 3))


def _clouds(n_per_class=8, seed=0):
    rng = np.random.default_rng(seed)
    centres = np.array([[-0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    clouds, y = [], []
    for label, c in enumerate(centres):
        for _ in range(n_per_class):
            pts = np.column_stack([c + 0.25 * rng.standard_normal((50, 2)), rng.standard_normal(50)])
            clouds.append(pts)
            y.append(label)
    return clouds, np.array(y)


def test_repeated_retrieval_matches_manual_loop():
    clouds, y = _clouds()
    transformer = _NoisyHistogram(noise=0.05)
    result = repeated_retrieval(transformer, clouds, y, n_repeats=4, random_state=0)
    assert isinstance(result, RepeatedRetrievalResult)
    # the seeds are draws from random_state
    assert_array_equal(result.seeds, np.random.RandomState(0).randint(np.iinfo(np.int32).max, size=4))
    assert len(set(result.seeds.tolist())) == 4
    # each draw is what a direct computation with that seed gives
    for r, seed in enumerate(result.seeds):
        X = _NoisyHistogram(noise=0.05, random_state=int(seed)).fit_transform(clouds)
        expected = retrieval_scores(y, leave_one_out_retrieval(X, y))
        for k, v in expected.items():
            assert result.per_repeat[k][r] == v
    for k, values in result.per_repeat.items():
        assert result.mean[k] == pytest.approx(np.mean(values))
        assert result.std[k] == pytest.approx(np.std(values))
        assert result[k] == (result.mean[k], result.std[k])
    # draws differ, so something varies across repeats
    assert max(result.std.values()) > 0
    # the transformer passed in is untouched
    assert transformer.random_state is None
    assert not hasattr(transformer, "n_fits_")


def test_repeated_retrieval_reads_an_iterator_of_clouds_once():
    # every draw describes all the clouds: a generator gave a bare "object of type 'generator' has no len()"
    clouds, y = _clouds()
    a = repeated_retrieval(_NoisyHistogram(), (c for c in clouds), y, n_repeats=3, random_state=0)
    b = repeated_retrieval(_NoisyHistogram(), clouds, y, n_repeats=3, random_state=0)
    assert_array_equal(a.seeds, b.seeds)
    for k in b.per_repeat:
        assert_array_equal(a.per_repeat[k], b.per_repeat[k])


def test_repeated_retrieval_deterministic_and_table():
    clouds, y = _clouds(seed=1)
    a = repeated_retrieval(_NoisyHistogram(), clouds, y, n_repeats=3, random_state=7)
    b = repeated_retrieval(_NoisyHistogram(), clouds, y, n_repeats=3, random_state=7)
    for k in a.per_repeat:
        assert_array_equal(a.per_repeat[k], b.per_repeat[k])
    table = str(a)
    assert table.splitlines()[0].startswith("metric")
    assert "over 3 draws" in table
    for k in a.per_repeat:
        line = next(line for line in table.splitlines() if line.startswith(k))
        assert f"{100 * a.mean[k]:.2f} (±{100 * a.std[k]:.2f})" in line
    assert f"{a.mean['macro_f1']:.2f}" in a.to_table(percent=False)


@pytest.mark.parametrize(
    "transformer, kwargs, err, msg",
    [
        (_NoisyHistogram(), {"n_repeats": 0}, ValueError, "repeated_retrieval: n_repeats must be a positive int, got 0"),
        (_NoisyHistogram(), {"n_repeats": 2.0}, TypeError, "repeated_retrieval: n_repeats must be a positive int, got 2.0"),
        (_NoSeed(), {}, ValueError, "repeated_retrieval: _NoSeed has no random_state parameter, so repeated draws would be identical"),
        ("eppf", {}, TypeError, "repeated_retrieval: transformer must be a scikit-learn transformer with get_params and fit_transform, got str"),
        (_NoisyHistogram(), {"y": [0, 1]}, ValueError, "repeated_retrieval: 24 point clouds but 2 labels"),
    ],
)
def test_repeated_retrieval_errors(transformer, kwargs, err, msg):
    clouds, y = _clouds()
    kwargs = {"y": y, **kwargs}
    with pytest.raises(err, match=re.escape(msg)):
        repeated_retrieval(transformer, clouds, **kwargs)


def test_repeated_retrieval_with_eppf_transformer():
    eppf = pytest.importorskip("eppf")
    if not hasattr(eppf, "EPPFTransformer"):
        pytest.skip("EPPFTransformer not available")
    try:
        from eppf.datasets import make_shapes
    except ImportError:
        pytest.skip("eppf.datasets.make_shapes not available")
    data = make_shapes(5, n_points=256, classes=["box", "sphere", "cylinder", "torus"], with_normals=True, random_state=0)
    transformer = eppf.EPPFTransformer(n_pairs=2000)
    result = repeated_retrieval(transformer, data.data, data.target, n_repeats=2, random_state=0)
    assert result.per_repeat["total_accuracy"].shape == (2,)
    # four clearly different shapes: retrieval is far above chance (25%)
    assert result.mean["total_accuracy"] > 0.6


def test_repeated_retrieval_result_without_metrics_or_draws_is_refused():
    # str() of an empty result raised max()'s bare "arg is an empty sequence"
    with pytest.raises(ValueError, match="RepeatedRetrievalResult: per_repeat is empty; a result needs at least one metric"):
        RepeatedRetrievalResult(per_repeat={}, seeds=np.zeros(0, dtype=int))
    with pytest.raises(ValueError, match="RepeatedRetrievalResult: metric 'total_accuracy' has no values"):
        RepeatedRetrievalResult(per_repeat={"total_accuracy": np.zeros(0)}, seeds=np.zeros(0, dtype=int))
    with pytest.raises(TypeError, match="RepeatedRetrievalResult: per_repeat must be a dict"):
        RepeatedRetrievalResult(per_repeat=[0.5], seeds=np.zeros(1, dtype=int))
    one = RepeatedRetrievalResult(per_repeat={"total_accuracy": np.array([0.5])}, seeds=np.array([3]))
    assert str(one).splitlines() == ["metric          mean (std) over 1 draw", "total_accuracy  50.00 (±0.00)"]
