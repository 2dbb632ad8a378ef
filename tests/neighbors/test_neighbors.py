"""Tests of symmetric KL matching: distances and KLNearestNeighbors."""

import pickle
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.model_selection import GridSearchCV, StratifiedKFold, cross_val_score
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import Normalizer

from eppf import KLNearestNeighbors, symmetric_kl_distances


def _histograms(n, n_bins=40, seed=0, sparsity=0.5, alpha=0.3):
    """Sparse normalised histograms (Dirichlet draws with zeroed bins)."""
    rng = np.random.default_rng(seed)
    X = rng.dirichlet(np.full(n_bins, alpha), size=n)
    X[rng.random(X.shape) < sparsity] = 0.0
    X[:, 0] += 1e-3  # no empty rows
    return X / X.sum(axis=1, keepdims=True)


def _clustered(n_per_class=15, n_classes=3, n_bins=30, seed=0):
    """Histograms around one random profile per class."""
    rng = np.random.default_rng(seed)
    profiles = rng.dirichlet(np.full(n_bins, 0.5), size=n_classes)
    X = np.vstack([rng.dirichlet(200 * p + 0.01, size=n_per_class) for p in profiles])
    X[X < 1e-3] = 0.0
    y = np.repeat(np.arange(n_classes), n_per_class)
    return X, y


def _slow_kl(X, Y, floor, renormalize=False):
    """Direct double loop over pairs: sum (a - b)(ln a - ln b)."""
    D = np.empty((len(X), len(Y)))
    for i, x in enumerate(X):
        a = np.maximum(np.asarray(x, dtype=float), floor)
        if renormalize:
            a = a / a.sum()
        for j, z in enumerate(Y):
            b = np.maximum(np.asarray(z, dtype=float), floor)
            if renormalize:
                b = b / b.sum()
            D[i, j] = np.sum((a - b) * (np.log(a) - np.log(b)))
    return D


def _half_min_positive(*arrays):
    values = np.concatenate([np.ravel(a) for a in arrays])
    return values[values > 0].min() / 2


# ---------------------------------------------------------------- distances


@pytest.mark.parametrize("n_x, n_y, n_bins", [(1, 1, 1), (5, 7, 3), (23, 11, 40), (40, 40, 120)])
@pytest.mark.parametrize("renormalize", [False, True])
def test_distances_match_double_loop(n_x, n_y, n_bins, renormalize):
    X = _histograms(n_x, n_bins, seed=1)
    Y = _histograms(n_y, n_bins, seed=2)
    D = symmetric_kl_distances(X, Y, renormalize=renormalize)
    ref = _slow_kl(X, Y, _half_min_positive(X, Y), renormalize)
    assert_allclose(D, ref, rtol=0, atol=1e-10)


@pytest.mark.parametrize("floor", [1e-6, 0.01, 0.3])
def test_distances_explicit_floor(floor):
    X = _histograms(9, 15, seed=3)
    Y = _histograms(6, 15, seed=4)
    assert_allclose(symmetric_kl_distances(X, Y, floor=floor), _slow_kl(X, Y, floor), rtol=0, atol=1e-10)


def test_distances_hand_computed():
    # a = (1/2, 1/2, 0), b = (1/4, 1/4, 1/2), floor 0.01 for the empty bin:
    # 2 * (1/4) ln 2 + (0.01 - 1/2) ln(0.01 / (1/2))
    X = np.array([[0.5, 0.5, 0.0], [0.25, 0.25, 0.5]])
    D = symmetric_kl_distances(X, floor=0.01)
    expected = 0.5 * np.log(2) + (0.01 - 0.5) * np.log(0.02)
    assert_allclose(D, [[0, expected], [expected, 0]], rtol=1e-14, atol=0)


def test_distances_symmetric_non_negative_zero_diagonal():
    X = _histograms(60, 50, seed=5)
    D = symmetric_kl_distances(X)
    assert_array_equal(np.diag(D), 0.0)
    assert_allclose(D, D.T, rtol=0, atol=1e-12)
    assert (D >= 0).all()
    assert (D[~np.eye(60, dtype=bool)] > 0).all()
    # passing X twice gives the same up to rounding, the diagonal included
    assert_allclose(symmetric_kl_distances(X, X), D, rtol=0, atol=1e-12)


def test_distances_scale_with_mass():
    # with the floor scaled along, d(c a, c b) = c d(a, b)
    X = _histograms(8, 20, seed=6)
    assert_allclose(symmetric_kl_distances(7 * X), 7 * symmetric_kl_distances(X), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("chunk_size", [1, 2, 5, 16, 1000])
def test_distances_chunking_invariance(chunk_size):
    X = _histograms(37, 25, seed=7)
    Y = _histograms(19, 25, seed=8)
    ref = symmetric_kl_distances(X, Y)
    assert_allclose(symmetric_kl_distances(X, Y, chunk_size=chunk_size), ref, rtol=0, atol=1e-12)
    ref_same = symmetric_kl_distances(X)
    assert_allclose(symmetric_kl_distances(X, chunk_size=chunk_size), ref_same, rtol=0, atol=1e-12)


def test_distances_auto_floor_uses_both_sets():
    X = np.array([[0.5, 0.5, 0.0]])
    Y = np.array([[0.9, 0.08, 0.02]])
    # floor is half of 0.02 (the smallest positive value in X and Y)
    assert_allclose(symmetric_kl_distances(X, Y), symmetric_kl_distances(X, Y, floor=0.01), rtol=1e-15)


def test_distances_values_below_floor_are_raised():
    X = np.array([[0.5, 0.5, 1e-9]])
    Y = np.array([[0.5, 0.5, 0.0]])
    assert_array_equal(symmetric_kl_distances(X, Y, floor=1e-3), [[0.0]])


def test_distances_n_jobs_and_dtypes():
    X = _histograms(12, 10, seed=9)
    ref = symmetric_kl_distances(X)
    assert_allclose(symmetric_kl_distances(X, n_jobs=1), ref, rtol=0, atol=1e-12)
    counts = np.round(X * 1000).astype(np.int32)
    assert_allclose(symmetric_kl_distances(counts), _slow_kl(counts, counts, 0.5), rtol=0, atol=1e-9)
    assert_allclose(
        symmetric_kl_distances(X.astype(np.float32)),
        _slow_kl(X.astype(np.float32), X.astype(np.float32), _half_min_positive(X.astype(np.float32))),
        rtol=0,
        atol=1e-9,
    )


@pytest.mark.parametrize(
    "kwargs, err, msg",
    [
        ({"X": [[0.5, -0.1]]}, ValueError, "Negative values in data passed to symmetric_kl_distances (X)"),
        ({"X": [[0.5, 0.5]], "Y": [[-1.0, 0.5]]}, ValueError, "Negative values in data passed to symmetric_kl_distances (Y)"),
        ({"X": [[0.5, np.nan]]}, ValueError, "symmetric_kl_distances: Input X contains NaN"),
        ({"X": [[0.5, np.inf]]}, ValueError, "symmetric_kl_distances: Input X contains infinity"),
        ({"X": [0.5, 0.5]}, ValueError, "symmetric_kl_distances: Expected 2D array, got 1D array instead"),
        ({"X": [[0.5, 0.5]], "Y": [[0.2, 0.3, 0.5]]}, ValueError, "symmetric_kl_distances: X and Y must have the same number of bins, got 2 and 3"),
        ({"X": [[0.0, 0.0]]}, ValueError, "symmetric_kl_distances: cannot learn floor='auto' because X has no positive value; pass floor as a positive float"),
        ({"X": [[5e-324, 1.0]]}, ValueError, "symmetric_kl_distances: cannot learn floor='auto' because half the smallest positive value of the histograms (5e-324) is 0 in float64; pass floor as a positive float"),
        ({"X": [[1.0]], "floor": 0.0}, ValueError, "symmetric_kl_distances: floor must be 'auto' or a positive float, got 0.0"),
        ({"X": [[1.0]], "floor": "min"}, ValueError, "symmetric_kl_distances: floor must be 'auto' or a positive float, got 'min'"),
        ({"X": [[1.0]], "floor": np.nan}, ValueError, "symmetric_kl_distances: floor must be 'auto' or a positive float, got nan"),
        ({"X": [[1.0]], "floor": None}, TypeError, "symmetric_kl_distances: floor must be 'auto' or a positive float, got None"),
        ({"X": [[1.0]], "chunk_size": 0}, ValueError, "symmetric_kl_distances: chunk_size must be a positive int or None, got 0"),
        ({"X": [[1.0]], "chunk_size": 2.5}, TypeError, "symmetric_kl_distances: chunk_size must be a positive int or None, got 2.5"),
        ({"X": [[1.0]], "renormalize": "yes"}, TypeError, "symmetric_kl_distances: renormalize must be a bool, got 'yes'"),
        ({"X": [[1.0]], "n_jobs": 0}, ValueError, "symmetric_kl_distances: n_jobs must be None or a non-zero int (-1: all cores), got 0"),
        ({"X": [[1e308, 1.0]]}, ValueError, "symmetric_kl_distances: histogram values are too large for the KL divergence (a row sums to 1e+308"),
    ],
)
def test_distances_errors(kwargs, err, msg):
    kwargs = dict(kwargs)
    X = kwargs.pop("X")
    with pytest.raises(err, match=re.escape(msg)):
        symmetric_kl_distances(X, **kwargs)


def test_rows_whose_cross_terms_would_overflow_are_refused():
    # Each row's sum h ln h is finite (about 1.7e308), but the two cross terms of a pair of them overflowed:
    # d(0, 1) came out 0 instead of about 8.4e300, the rounding bound infinite (every candidate tied, the query
    # itself returned as its own leave-one-out neighbor), with RuntimeWarnings only.
    X = np.array([[1.2e305, 1.2e305], [1.2e305, 1.19e305], [1.2e305, 1.0]])
    msg = "histogram values are too large for the KL divergence (a row sums to 2.4e+305"
    with pytest.raises(ValueError, match="^symmetric_kl_distances: " + re.escape(msg)):
        symmetric_kl_distances(X, floor=0.5)
    with pytest.raises(ValueError, match="^KLNearestNeighbors: " + re.escape(msg)):
        KLNearestNeighbors(floor=0.5).fit(X, [0, 1, 2])
    fitted = KLNearestNeighbors(floor=0.5).fit(X * 1e-5, [0, 1, 2])
    with pytest.raises(ValueError, match="^KLNearestNeighbors: " + re.escape(msg)):
        fitted.kneighbors(X)


def test_rows_near_the_largest_mass_give_finite_exact_distances():
    import warnings

    from eppf.neighbors._base import MASS_MAX

    X = np.array([[0.5, 0.5], [0.5, 0.49], [0.5, 1e-300]]) * MASS_MAX
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        D = symmetric_kl_distances(X, floor=0.5)
        ind = KLNearestNeighbors(n_neighbors=2, floor=0.5).fit(X, [0, 1, 2]).kneighbors(return_distance=False)
    assert_allclose(D, _slow_kl(X, X, 0.5), rtol=1e-6)
    assert_array_equal(ind, [[1, 2], [0, 2], [1, 0]])


# ------------------------------------------------------------- the estimator


# scikit-learn's estimator checks for KLNearestNeighbors are in test_common.py.


def test_tags():
    tags = KLNearestNeighbors().__sklearn_tags__()
    assert tags.input_tags.positive_only
    assert tags.estimator_type == "classifier"


def test_floor_learned():
    X, y = _clustered()
    clf = KLNearestNeighbors().fit(X, y)
    assert clf.floor_ == X[X > 0].min() / 2
    assert clf.floor_ < X[X > 0].min()
    assert KLNearestNeighbors(floor=0.25).fit(X, y).floor_ == 0.25
    assert clf.n_features_in_ == X.shape[1]
    assert clf.n_samples_fit_ == X.shape[0]
    assert_array_equal(clf.classes_, [0, 1, 2])


def _stable_knn(D, k):
    """Reference: stable sort of each row (ties to the lowest index)."""
    return np.argsort(D, axis=1, kind="stable")[:, :k]


@pytest.mark.parametrize("k", [1, 2, 5])
@pytest.mark.parametrize("chunk_size", [None, 1, 4])
def test_kneighbors_matches_brute_force(k, chunk_size):
    X, y = _clustered(seed=1)
    Q = _histograms(10, X.shape[1], seed=11)
    clf = KLNearestNeighbors(n_neighbors=k, chunk_size=chunk_size).fit(X, y)
    D = symmetric_kl_distances(Q, X, floor=clf.floor_)
    dist, ind = clf.kneighbors(Q)
    assert_array_equal(ind, _stable_knn(D, k))
    assert_allclose(dist, np.take_along_axis(D, ind, axis=1), rtol=0, atol=1e-12)
    assert (np.diff(dist, axis=1) >= 0).all()


@pytest.mark.parametrize("k", [1, 3])
def test_kneighbors_none_excludes_self(k):
    X, y = _clustered(seed=2)
    # duplicate a few rows so that zero distances to other points exist
    X = np.vstack([X, X[:5]])
    y = np.concatenate([y, y[:5]])
    clf = KLNearestNeighbors(n_neighbors=k).fit(X, y)
    dist, ind = clf.kneighbors()
    n = X.shape[0]
    assert not (ind == np.arange(n)[:, None]).any()
    D = symmetric_kl_distances(X, floor=clf.floor_)
    np.fill_diagonal(D, np.inf)
    # rows 0..4 and their copies find each other first, at distance ~0
    assert_array_equal(ind[:5, 0], np.arange(n - 5, n))
    assert_array_equal(ind[n - 5 :, 0], np.arange(5))
    assert_allclose(dist[:5, 0], 0.0, atol=1e-12)
    assert_array_equal(ind, _stable_knn(D, k))
    # same answer as querying with X itself after removing each point
    assert_array_equal(clf.kneighbors(return_distance=False), ind)


@pytest.mark.parametrize("seed", [0, 1])
def test_kneighbors_ties_go_to_lowest_index(seed):
    # With a few hundred bins the matrix products round differently for
    # identical training rows at different positions; the result must not.
    rng = np.random.default_rng(seed)
    n_bins = 300
    base = rng.dirichlet(np.full(n_bins, 0.1), size=4)
    # three copies of the four rows (0-3, 11-14, 15-18) around distinct filler rows
    X = np.vstack([base, rng.dirichlet(np.full(n_bins, 0.1), size=7), base, base])
    y = np.arange(X.shape[0])
    near = base + 0.05 * rng.dirichlet(np.ones(n_bins), size=4)
    far = rng.dirichlet(np.full(n_bins, 0.1), size=100)
    for chunk_size in (None, 1, 3, 7):
        clf = KLNearestNeighbors(n_neighbors=3, chunk_size=chunk_size).fit(X, y)
        ind = clf.kneighbors(near, return_distance=False)
        assert_array_equal(ind, np.arange(4)[:, None] + [0, 11, 15])
        # the nearest row of any query is never a later copy
        assert (clf.kneighbors(far, n_neighbors=1, return_distance=False) < 11).all()
        # leave-one-out: a copy's nearest neighbours are the other copies, in index order
        ind = clf.kneighbors(n_neighbors=2, return_distance=False)
        assert_array_equal(ind[:4], np.arange(4)[:, None] + [11, 15])
        assert_array_equal(ind[11:15], np.arange(4)[:, None] + [0, 15])
        assert_array_equal(ind[15:19], np.arange(4)[:, None] + [0, 11])


@pytest.mark.parametrize("chunk_size", [1, 2, 3, 10, 100])
def test_chunking_invariance(chunk_size):
    X, y = _clustered(n_bins=300, seed=5)
    X = np.vstack([X, X[::4]])  # exact duplicates: ties must not depend on chunking
    y = np.concatenate([y, y[::4]])
    Q = _histograms(13, X.shape[1], seed=12)
    ref = KLNearestNeighbors(n_neighbors=4).fit(X, y)
    clf = KLNearestNeighbors(n_neighbors=4, chunk_size=chunk_size).fit(X, y)
    for query in (Q, None):
        d_ref, i_ref = ref.kneighbors(query)
        d, i = clf.kneighbors(query)
        assert_array_equal(i, i_ref)
        assert_allclose(d, d_ref, rtol=0, atol=1e-12)
    assert_array_equal(clf.predict(Q), ref.predict(Q))
    assert_allclose(clf.predict_proba(Q), ref.predict_proba(Q), rtol=0, atol=1e-12)


@pytest.mark.parametrize("weights", ["uniform", "distance"])
@pytest.mark.parametrize("k", [1, 3, 6])
def test_predict_proba_consistent_with_votes(weights, k):
    X, y = _clustered(seed=6)
    Q = _histograms(20, X.shape[1], seed=13)
    clf = KLNearestNeighbors(n_neighbors=k, weights=weights).fit(X, y)
    proba = clf.predict_proba(Q)
    dist, ind = clf.kneighbors(Q)
    w = np.ones_like(dist) if weights == "uniform" else 1 / dist
    expected = np.stack([(w * (y[ind] == c)).sum(axis=1) for c in clf.classes_], axis=1)
    expected /= expected.sum(axis=1, keepdims=True)
    assert_allclose(proba, expected, rtol=1e-12)
    assert_allclose(proba.sum(axis=1), 1.0)
    assert_array_equal(clf.predict(Q), clf.classes_[np.argmax(proba, axis=1)])
    if k == 1:
        assert_array_equal(clf.predict(Q), y[ind[:, 0]])
        assert set(np.unique(proba)) <= {0.0, 1.0}


def test_distance_weights_with_exact_match():
    X, y = _clustered(seed=7)
    clf = KLNearestNeighbors(n_neighbors=5, weights="distance").fit(X, y)
    # a training point queried again is at distance 0 from itself: it takes all the weight
    proba = clf.predict_proba(X[:3])
    assert_array_equal(proba, np.eye(3)[y[:3]])


def test_vote_ties_go_to_first_class():
    X = np.array([[0.9, 0.1], [0.1, 0.9]])
    clf = KLNearestNeighbors(n_neighbors=2).fit(X, ["zebra", "ant"])
    assert_array_equal(clf.predict([[0.5, 0.5]]), ["ant"])
    assert_array_equal(clf.predict_proba([[0.5, 0.5]]), [[0.5, 0.5]])


def test_string_labels():
    X, y = _clustered(seed=8)
    names = np.array(["chair", "sofa", "table"])[y]
    clf = KLNearestNeighbors(n_neighbors=3).fit(X, list(names))
    assert_array_equal(clf.classes_, ["chair", "sofa", "table"])
    pred = clf.predict(X)
    assert pred.dtype.kind == "U"
    assert_array_equal(pred, names)
    num = KLNearestNeighbors(n_neighbors=3).fit(X, y)
    assert_array_equal(clf.predict_proba(X), num.predict_proba(X))


def test_pickle_roundtrip():
    X, y = _clustered(seed=9)
    Q = _histograms(8, X.shape[1], seed=14)
    clf = KLNearestNeighbors(n_neighbors=3, weights="distance").fit(X, y)
    clone_ = pickle.loads(pickle.dumps(clf))
    assert_array_equal(clone_.predict(Q), clf.predict(Q))
    assert_array_equal(clone_.predict_proba(Q), clf.predict_proba(Q))
    assert clone_.floor_ == clf.floor_


def test_renormalize_matches_reference():
    X, y = _clustered(seed=10)
    clf = KLNearestNeighbors(n_neighbors=2, renormalize=True).fit(X, y)
    D = _slow_kl(X, X, clf.floor_, renormalize=True)
    np.fill_diagonal(D, np.inf)
    assert_array_equal(clf.kneighbors(return_distance=False), _stable_knn(D, 2))


def test_pipeline_grid_search():
    X, y = _clustered(n_per_class=12, seed=11)
    counts = np.round(X * 500)  # count histograms; the pipeline normalises them
    pipe = Pipeline([("norm", Normalizer(norm="l1")), ("knn", KLNearestNeighbors())])
    cv = StratifiedKFold(3, shuffle=True, random_state=0)
    grid = GridSearchCV(pipe, {"knn__n_neighbors": [1, 3, 5], "knn__weights": ["uniform", "distance"]}, cv=cv)
    grid.fit(counts, y)
    assert grid.best_params_["knn__n_neighbors"] in (1, 3, 5)
    assert grid.best_score_ > 0.9
    # the grid's score for one setting is what cross-validation of that setting gives
    row = list(grid.cv_results_["params"]).index({"knn__n_neighbors": 3, "knn__weights": "uniform"})
    manual = cross_val_score(pipe.set_params(knn__n_neighbors=3, knn__weights="uniform"), counts, y, cv=cv)
    assert_allclose(grid.cv_results_["mean_test_score"][row], manual.mean())


def _fitted():
    return KLNearestNeighbors().fit([[0.5, 0.5], [0.9, 0.1]], [0, 1])


@pytest.mark.parametrize(
    "make, call, err, msg",
    [
        (lambda: KLNearestNeighbors(n_neighbors=0), lambda c: c.fit([[1.0, 0.0]], [0]), ValueError, "KLNearestNeighbors: n_neighbors must be a positive int, got 0"),
        (lambda: KLNearestNeighbors(n_neighbors=1.5), lambda c: c.fit([[1.0, 0.0]], [0]), TypeError, "KLNearestNeighbors: n_neighbors must be a positive int, got 1.5"),
        (lambda: KLNearestNeighbors(weights="gaussian"), lambda c: c.fit([[1.0, 0.0]], [0]), ValueError, "KLNearestNeighbors: weights must be 'uniform' or 'distance', got 'gaussian'"),
        (lambda: KLNearestNeighbors(floor=-1.0), lambda c: c.fit([[1.0, 0.0]], [0]), ValueError, "KLNearestNeighbors: floor must be 'auto' or a positive float, got -1.0"),
        (lambda: KLNearestNeighbors(floor=[0.1]), lambda c: c.fit([[1.0, 0.0]], [0]), TypeError, "KLNearestNeighbors: floor must be 'auto' or a positive float, got [0.1]"),
        (lambda: KLNearestNeighbors(chunk_size=-3), lambda c: c.fit([[1.0, 0.0]], [0]), ValueError, "KLNearestNeighbors: chunk_size must be a positive int or None, got -3"),
        (lambda: KLNearestNeighbors(renormalize=None), lambda c: c.fit([[1.0, 0.0]], [0]), TypeError, "KLNearestNeighbors: renormalize must be a bool, got None"),
        (lambda: KLNearestNeighbors(n_jobs="all"), lambda c: c.fit([[1.0, 0.0]], [0]), TypeError, "KLNearestNeighbors: n_jobs must be None or a non-zero int (-1: all cores), got 'all'"),
        (KLNearestNeighbors, lambda c: c.fit([[1.0, -0.5]], [0]), ValueError, "Negative values in data passed to KLNearestNeighbors (X): histograms must be non-negative, found minimum -0.5"),
        (KLNearestNeighbors, lambda c: c.fit([[0.0, 0.0]], [0]), ValueError, "KLNearestNeighbors: cannot learn floor='auto' because X has no positive value; pass floor as a positive float"),
        (KLNearestNeighbors, lambda c: c.fit([[5e-324, 0.0]], [0]), ValueError, "KLNearestNeighbors: cannot learn floor='auto' because half the smallest positive value of the histograms (5e-324) is 0 in float64"),
        (KLNearestNeighbors, lambda c: c.fit([[1.0, np.nan]], [0]), ValueError, "KLNearestNeighbors: Input X contains NaN"),
        (KLNearestNeighbors, lambda c: c.fit([[1.0, 0.0], [0.0, 1.0]], [0]), ValueError, "KLNearestNeighbors: Found input variables with inconsistent numbers of samples: [2, 1]"),
        (KLNearestNeighbors, lambda c: c.fit([[1.0, 0.0], [0.0, 1.0]], [0.5, 1.5]), ValueError, "KLNearestNeighbors: Unknown label type: continuous"),
        (KLNearestNeighbors, lambda c: c.fit([[1.0, 0.0]], None), ValueError, "KLNearestNeighbors: This KLNearestNeighbors estimator requires y to be passed, but the target y is None"),
        (_fitted, lambda c: c.predict([[1.0, 0.0, 0.0]]), ValueError, "KLNearestNeighbors: X has 3 features, but KLNearestNeighbors is expecting 2 features as input"),
        (_fitted, lambda c: c.predict([[1.0, -1.0]]), ValueError, "Negative values in data passed to KLNearestNeighbors (X)"),
        (_fitted, lambda c: c.predict_proba([[np.inf, 1.0]]), ValueError, "KLNearestNeighbors: Input X contains infinity"),
        (_fitted, lambda c: c.kneighbors([[0.5, 0.5]], n_neighbors=3), ValueError, "KLNearestNeighbors: n_neighbors=3 is more than the 2 training sample(s) available"),
        (_fitted, lambda c: c.kneighbors(n_neighbors=2), ValueError, "KLNearestNeighbors: n_neighbors=2 is more than the 1 training sample(s) available excluding each query itself"),
        (_fitted, lambda c: c.kneighbors(n_neighbors=0), ValueError, "KLNearestNeighbors: n_neighbors must be a positive int, got 0"),
        (_fitted, lambda c: c.kneighbors(n_neighbors="2"), TypeError, "KLNearestNeighbors: n_neighbors must be a positive int, got '2'"),
    ],
)
def test_estimator_errors(make, call, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        call(make())


@pytest.mark.parametrize("method", ["predict", "predict_proba", "kneighbors"])
def test_not_fitted(method):
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError, match="KLNearestNeighbors instance is not fitted yet"):
        getattr(KLNearestNeighbors(), method)([[0.5, 0.5]])


@pytest.mark.parametrize("blas_threads", [1, 2])
@pytest.mark.parametrize("n_jobs", [1, 2, 3, None])
def test_distances_bit_identical_for_any_thread_count(n_jobs, blas_threads):
    # OpenBLAS rounds a product differently with 1 and 2 threads: the
    # products run single-threaded over blocks whose shapes ignore n_jobs
    from threadpoolctl import threadpool_limits

    from eppf.metrics import leave_one_out_retrieval

    rng = np.random.default_rng(0)
    X = rng.dirichlet(np.full(300, 0.3), size=260)
    Y = rng.dirichlet(np.full(300, 0.3), size=90)
    y = rng.integers(0, 4, size=260)
    with threadpool_limits(1, user_api="blas"):
        ref_d = symmetric_kl_distances(X, Y, n_jobs=1, chunk_size=7)
        ref_l = leave_one_out_retrieval(X, y, n_jobs=1, chunk_size=64, return_indices=True)[1]
        ref_k = KLNearestNeighbors(n_neighbors=3, n_jobs=1, chunk_size=7).fit(X, y).kneighbors(Y)
    with threadpool_limits(blas_threads, user_api="blas"):
        d = symmetric_kl_distances(X, Y, n_jobs=n_jobs, chunk_size=7)
        l = leave_one_out_retrieval(X, y, n_jobs=n_jobs, chunk_size=64, return_indices=True)[1]
        k = KLNearestNeighbors(n_neighbors=3, n_jobs=n_jobs, chunk_size=7).fit(X, y).kneighbors(Y)
    assert_array_equal(d, ref_d)
    assert_array_equal(l, ref_l)
    assert_array_equal(k[0], ref_k[0])
    assert_array_equal(k[1], ref_k[1])


# ---------------------------------------------------------------- joblib backends and dask


def _force_small_blocks(monkeypatch):
    import eppf.neighbors._kl as kl

    monkeypatch.setattr(kl, "_LOO_BLOCK", 16)
    monkeypatch.setattr(kl, "BLOCK_ENTRIES", 16 * 70)  # 16-row blocks against 70 references


def test_joblib_backend_is_detected():
    from joblib import parallel_config

    from eppf.utils._blas import joblib_backend_is_set

    assert not joblib_backend_is_set()
    with parallel_config(backend="threading", n_jobs=2):
        assert joblib_backend_is_set()
    with parallel_config(n_jobs=2):  # no backend named: the thread pool of n_jobs stays in charge
        assert not joblib_backend_is_set()


def _local_and_remote_results(X, Q, y):
    from eppf.metrics import leave_one_out_retrieval

    clf = KLNearestNeighbors(n_neighbors=3).fit(X, y)
    return (
        symmetric_kl_distances(X),
        symmetric_kl_distances(Q, X),
        clf.kneighbors(Q),
        clf.kneighbors(),
        leave_one_out_retrieval(X, y, return_indices=True),
    )


def _assert_same(a, b):
    for u, v in zip(a, b):
        if isinstance(u, tuple):
            _assert_same(u, v)
        else:
            assert_array_equal(u, v)


def test_threading_backend_gives_bit_identical_results(monkeypatch):
    from joblib import parallel_config

    X, y = _clustered(n_per_class=23, n_bins=50)
    Q = _histograms(40, n_bins=50, seed=4)
    _force_small_blocks(monkeypatch)  # many blocks: the same fixed blocks run in every case
    local = _local_and_remote_results(X, Q, y)
    with parallel_config(backend="threading", n_jobs=3):
        threaded = _local_and_remote_results(X, Q, y)
    _assert_same(local, threaded)


def test_dask_local_cluster_gives_bit_identical_results(monkeypatch):
    distributed = pytest.importorskip("dask.distributed")
    from joblib import parallel_config

    X, y = _clustered(n_per_class=23, n_bins=50)
    Q = _histograms(40, n_bins=50, seed=4)
    _force_small_blocks(monkeypatch)
    local = _local_and_remote_results(X, Q, y)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        with parallel_config(backend="dask"), distributed.get_task_stream(client) as stream:
            remote = _local_and_remote_results(X, Q, y)
    _assert_same(local, remote)
    assert len({task["worker"] for task in stream.data}) == 2  # both workers computed blocks
