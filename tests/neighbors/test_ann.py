"""Tests of ApproximateKLNearestNeighbors: recall, exact re-ranking, determinism, errors."""

import pickle
import re
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import clone

from eppf import KLNearestNeighbors, symmetric_kl_distances
from eppf.neighbors import ApproximateKLNearestNeighbors

pytest.importorskip("faiss", reason="faiss-cpu is in the test extra (pip install eppf[test] or eppf[ann])")


def _clustered(n, n_bins=60, n_classes=8, seed=0, sparsity=0.6):
    """Sparse normalised histograms around one sparse profile per class (like EPPF descriptors)."""
    rng = np.random.default_rng(seed)
    profiles = rng.dirichlet(np.full(n_bins, 0.4), size=n_classes)
    profiles[rng.random(profiles.shape) < sparsity] = 0.0
    profiles[:, 0] += 1e-2
    y = rng.integers(n_classes, size=n)
    X = profiles[y] * np.exp(0.6 * rng.standard_normal((n, n_bins)))
    X[X < 2e-3] = 0.0
    X[:, 0] += 1e-3
    return X / X.sum(axis=1, keepdims=True), y


def _slow_kl(q, c, floor):
    a, b = np.maximum(q, floor), np.maximum(c, floor)
    return float(np.sum((a - b) * (np.log(a) - np.log(b))))


@pytest.fixture(scope="module")
def data():
    X, y = _clustered(800, seed=0)
    Q, _ = _clustered(150, seed=1)
    return X, y, Q


@pytest.fixture(scope="module")
def fitted(data):
    X, y, _ = data
    return ApproximateKLNearestNeighbors(n_neighbors=3, n_candidates=128, n_components=32, random_state=0).fit(X, y)


# ---------------------------------------------------------------- recall and exactness


def test_recall_against_exact_search(data, fitted):
    X, y, Q = data
    exact = KLNearestNeighbors(n_neighbors=3).fit(X, y)
    e_dist, e_ind = exact.kneighbors(Q)
    a_dist, a_ind = fitted.kneighbors(Q)
    recall_at_1 = np.mean(a_dist[:, 0] <= e_dist[:, 0] * (1 + 1e-9))
    assert recall_at_1 >= 0.97
    recall_at_3 = np.mean([len(set(a) & set(e)) / 3 for a, e in zip(a_ind, e_ind)])
    assert recall_at_3 >= 0.95
    # an approximate search never beats the exact one
    assert np.all(a_dist >= e_dist * (1 - 1e-12) - 1e-14)
    # leave-one-out too
    loo_e = exact.kneighbors(n_neighbors=1)[1][:, 0]
    loo_a = fitted.kneighbors(n_neighbors=1)[1][:, 0]
    assert np.mean(loo_a == loo_e) >= 0.97
    assert np.all(loo_a != np.arange(len(X)))
    # without PCA the Hellinger embedding alone finds (nearly) every neighbour
    full = clone(fitted).set_params(n_components=None, n_candidates=32).fit(X, y)
    assert np.mean(full.kneighbors(Q)[0][:, 0] <= e_dist[:, 0] * (1 + 1e-9)) >= 0.99
    graph = clone(fitted).set_params(index="hnsw").fit(X, y)
    assert graph.n_lists_ is None
    assert np.mean(graph.kneighbors(Q)[0][:, 0] <= e_dist[:, 0] * (1 + 1e-9)) >= 0.97


def test_fewer_probes_lose_recall(data):
    # the parameters do what they say: a single probed list with few candidates is worse
    X, y, Q = data
    e_dist = KLNearestNeighbors().fit(X, y).kneighbors(Q)[0][:, 0]
    ann = ApproximateKLNearestNeighbors(n_probe=1, n_candidates=2, n_components=4, random_state=0).fit(X, y)
    poor = np.mean(ann.kneighbors(Q)[0][:, 0] <= e_dist * (1 + 1e-9))
    good = np.mean(ann.set_params(n_probe=64, n_candidates=32).kneighbors(Q)[0][:, 0] <= e_dist * (1 + 1e-9))
    assert poor < good


def test_reranked_distances_are_exact(data, fitted):
    X, _, Q = data
    dist, ind = fitted.kneighbors(Q[:20])
    for q, row_d, row_i in zip(Q[:20], dist, ind):
        ref = [_slow_kl(q, X[i], fitted.floor_) for i in row_i]
        assert_allclose(row_d, ref, rtol=1e-12, atol=1e-13)
    assert np.all(np.diff(dist, axis=1) >= 0)
    full = symmetric_kl_distances(Q[:20], X, floor=fitted.floor_)
    assert_allclose(dist, np.take_along_axis(full, ind, axis=1), rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("renormalize, floor, index", [(False, "auto", "ivf"), (True, "auto", "ivf"),
                                                        (False, 5e-3, "ivf"), (True, 5e-3, "hnsw")])
def test_exhaustive_settings_give_exact_search(data, renormalize, floor, index):
    # all candidates from all lists: the same neighbours as KLNearestNeighbors, ties included
    X, y, Q = data
    X, y = X[:150], y[:150]
    X = np.vstack([X, X[:10]])  # exact duplicates: ties go to the lowest index
    y = np.concatenate([y, y[:10]])
    Q = np.vstack([Q[:40], X[:5]])
    params = dict(n_neighbors=4, floor=floor, renormalize=renormalize)
    exact = KLNearestNeighbors(**params).fit(X, y)
    ann = ApproximateKLNearestNeighbors(n_candidates=len(X), n_probe=10**6, index=index, random_state=0,
                                        **params).fit(X, y)
    for args in [(Q,), ()]:
        e_dist, e_ind = exact.kneighbors(*args)
        a_dist, a_ind = ann.kneighbors(*args)
        assert_array_equal(a_ind, e_ind)
        assert_allclose(a_dist, e_dist, rtol=1e-12, atol=1e-13)
    assert_array_equal(ann.predict(Q), exact.predict(Q))
    assert_allclose(ann.predict_proba(Q), exact.predict_proba(Q))


def test_float32_input_is_kept_compact_and_gives_float64_results(data):
    X, y, Q = data
    X32 = X.astype(np.float32)
    a32 = ApproximateKLNearestNeighbors(random_state=0).fit(X32, y)
    a64 = ApproximateKLNearestNeighbors(random_state=0).fit(X32.astype(np.float64), y)
    d32, i32 = a32.kneighbors(Q)
    d64, i64 = a64.kneighbors(Q)
    assert_array_equal(i32, i64)
    assert_array_equal(d32, d64)
    assert a32._support[2].dtype == np.float32
    # only the bins above the floor are kept
    assert a32._support[2].size == np.count_nonzero(X32 > a32.floor_)


def test_predict_uses_the_neighbours_votes(data, fitted):
    X, y, Q = data
    ind = fitted.kneighbors(Q, return_distance=False)
    proba = fitted.predict_proba(Q)
    votes = np.stack([(y[ind] == c).mean(axis=1) for c in fitted.classes_], axis=1)
    assert_allclose(proba, votes)
    assert_array_equal(fitted.predict(Q), fitted.classes_[np.argmax(votes, axis=1)])
    weighted = clone(fitted).set_params(weights="distance").fit(X, y)
    assert_allclose(weighted.predict_proba(Q).sum(axis=1), 1.0)


# ---------------------------------------------------------------- determinism


@pytest.mark.parametrize("index", ["ivf", "hnsw"])
def test_same_random_state_same_index_and_results(data, index):
    X, y, Q = data
    a = ApproximateKLNearestNeighbors(n_probe=2, ef_search=8, n_candidates=8, index=index, random_state=3).fit(X, y)
    b = ApproximateKLNearestNeighbors(n_probe=2, ef_search=8, n_candidates=8, index=index, random_state=3).fit(X, y)
    assert_array_equal(a.components_, b.components_)
    import faiss

    assert faiss.serialize_index(a.index_).tobytes() == faiss.serialize_index(b.index_).tobytes()
    da, ia = a.kneighbors(Q)
    db, ib = b.kneighbors(Q)
    assert_array_equal(ia, ib)
    assert_array_equal(da, db)


@pytest.mark.parametrize("index", ["ivf", "hnsw"])
def test_results_do_not_depend_on_n_jobs(data, index):
    X, y, Q = data
    one = ApproximateKLNearestNeighbors(n_probe=2, ef_search=8, n_candidates=8, index=index, chunk_size=16,
                                        n_jobs=1, random_state=0).fit(X, y)
    two = clone(one).set_params(n_jobs=2).fit(X, y)
    for args in [(Q,), ()]:
        d1, i1 = one.kneighbors(*args)
        d2, i2 = two.kneighbors(*args)
        assert_array_equal(i1, i2)
        assert_array_equal(d1, d2)


def test_pickle_round_trip(data, fitted):
    _, _, Q = data
    again = pickle.loads(pickle.dumps(fitted))
    d0, i0 = fitted.kneighbors(Q)
    d1, i1 = again.kneighbors(Q)
    assert_array_equal(i0, i1)
    assert_array_equal(d0, d1)
    assert type(fitted.index_).__name__ == "IndexIVFFlat"  # pickling left the original intact


def test_too_few_rows_in_probed_lists_falls_back_to_all_lists():
    # four far-apart groups, one list each, one probe: a query's own list has 5 rows, k = 8
    rng = np.random.default_rng(0)
    X = np.zeros((20, 8))
    for g in range(4):
        X[5 * g : 5 * g + 5, 2 * g : 2 * g + 2] = rng.uniform(0.4, 0.6, size=(5, 2))
    X /= X.sum(axis=1, keepdims=True)
    y = np.repeat(np.arange(4), 5)
    ann = ApproximateKLNearestNeighbors(n_neighbors=8, n_candidates=10, n_lists=4, n_probe=1,
                                        n_components=None, random_state=0).fit(X, y)
    dist, ind = ann.kneighbors(X[:2])
    assert np.all(np.isfinite(dist))
    assert ind.shape == (2, 8) and all(len(set(r)) == 8 for r in ind)
    exact = KLNearestNeighbors(n_neighbors=8).fit(X, y).kneighbors(X[:2])[1]
    assert set(ind[0][:5]) == set(exact[0][:5]) == set(range(5))


# ---------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "params, error, message",
    [
        (dict(n_candidates=2, n_neighbors=3), ValueError, "n_candidates=2 must be at least n_neighbors=3"),
        (dict(n_candidates=0), ValueError, "n_candidates must be an int >= 1"),
        (dict(n_candidates=2.5), TypeError, "n_candidates must be an int >= 1"),
        (dict(n_components=0), ValueError, "n_components must be an int >= 1 or None"),
        (dict(n_lists="many"), TypeError, "n_lists must be an int >= 1 or 'auto'"),
        (dict(n_lists=0), ValueError, "n_lists must be an int >= 1 or 'auto'"),
        (dict(n_probe=True), TypeError, "n_probe must be an int >= 1"),
        (dict(index="flat"), ValueError, "index must be 'ivf' or 'hnsw', got 'flat'"),
        (dict(hnsw_m=1), ValueError, "hnsw_m must be an int >= 2"),
        (dict(ef_search=0), ValueError, "ef_search must be an int >= 1"),
        (dict(n_lists=500), ValueError, "n_lists=500 is more than the 50 training samples"),
        (dict(floor=-1.0), ValueError, "floor must be 'auto' or a positive float"),
        (dict(weights="far"), ValueError, "weights must be 'uniform' or 'distance'"),
        (dict(n_jobs=0), ValueError, "n_jobs"),
    ],
)
def test_bad_parameters(params, error, message):
    X, y = _clustered(50)
    with pytest.raises(error, match=re.escape(message)):
        ApproximateKLNearestNeighbors(**params).fit(X, y)


def test_bad_data_is_refused_by_name():
    X, y = _clustered(50)
    name = "ApproximateKLNearestNeighbors"
    bad = X.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match=f"{name}.*NaN"):
        ApproximateKLNearestNeighbors().fit(bad, y)
    bad[3, 4] = -0.5
    with pytest.raises(ValueError, match=f"Negative values in data passed to {name}"):
        ApproximateKLNearestNeighbors().fit(bad, y)
    ann = ApproximateKLNearestNeighbors(random_state=0).fit(X, y)
    with pytest.raises(ValueError, match="features"):
        ann.kneighbors(X[:, :10])
    with pytest.raises(ValueError, match=re.escape("n_neighbors=40 is more than n_candidates=32")):
        ann.kneighbors(X, n_neighbors=40)
    with pytest.raises(ValueError, match=re.escape("n_neighbors=50 is more than the 49 training sample(s)")):
        ann.set_params(n_candidates=64).kneighbors(n_neighbors=50)
    with pytest.raises(TypeError, match="n_neighbors must be a positive int"):
        ann.kneighbors(X, n_neighbors=1.0)
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        ApproximateKLNearestNeighbors().kneighbors(X)


def test_missing_faiss_names_the_pip_command(monkeypatch):
    X, y = _clustered(50)
    monkeypatch.setitem(sys.modules, "faiss", None)  # import faiss now raises ImportError
    with pytest.raises(ImportError, match=re.escape("pip install faiss-cpu")):
        ApproximateKLNearestNeighbors().fit(X, y)


def test_row_terms_from_supports_match_the_dense_ones(data, fitted):
    # s = sum h ln h, the mass and the largest |ln h| of the floored rows, from the kept bins alone
    X, _, _ = data
    h = np.maximum(X, fitted.floor_)
    L = np.log(h)
    s, mass, lam = fitted._row_terms
    assert_allclose(s, (h * L).sum(axis=1), rtol=1e-12)
    assert_allclose(mass, h.sum(axis=1), rtol=1e-12)
    assert_allclose(lam, np.abs(L).max(axis=1), rtol=1e-12)


@pytest.mark.parametrize("scale", [1e39, 1e300, 1e-40, 1e-50, 1e-300])
def test_histograms_beyond_float32_embed_as_their_scaled_down_copies(data, scale):
    # float32 index vectors: rows whose values or sums overflow float32 are normalised in float64 first
    # (they embedded as inf and NaN: wrong candidates, or faiss failing inside k-means), and so are rows
    # whose sums are below float32's normal range (their bins rounded to 0: NaN vectors, faiss's k-means
    # raising RuntimeError at fit)
    import warnings

    X, y, Q = data
    X, Q = X[:200], Q[:30]
    y = y[:200]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        small = ApproximateKLNearestNeighbors(random_state=0).fit(X, y)
        big = ApproximateKLNearestNeighbors(random_state=0).fit(X * scale, y)
        assert_allclose(big._embed(X * scale), small._embed(X), rtol=1e-5, atol=1e-6)
        exhaustive = dict(n_neighbors=3, n_candidates=len(X), n_probe=10**6, random_state=0)
        a_dist, a_ind = ApproximateKLNearestNeighbors(**exhaustive).fit(X * scale, y).kneighbors(Q * scale)
    e_dist, e_ind = KLNearestNeighbors(n_neighbors=3).fit(X * scale, y).kneighbors(Q * scale)
    assert_array_equal(a_ind, e_ind)
    assert np.isfinite(a_dist).all()
    assert_allclose(a_dist, e_dist, rtol=1e-12)


def test_queries_too_large_for_the_divergence_are_refused_before_they_embed(data, fitted):
    _, _, Q = data
    with pytest.raises(ValueError, match=r"^ApproximateKLNearestNeighbors: histogram values are too large"):
        fitted.kneighbors(Q[:3] * 1e306)


@pytest.mark.parametrize("renormalize", [False, True])
def test_training_rows_whose_cross_terms_would_overflow_are_refused(renormalize):
    # the compressed supports' row terms were finite, but re-ranking two such rows overflowed to wrong distances
    X = np.array([[1.2e305, 1.2e305], [1.2e305, 1.19e305], [1.2e305, 1.0]] * 20)
    est = ApproximateKLNearestNeighbors(floor=0.5, renormalize=renormalize, n_components=None, random_state=0)
    if renormalize:  # (the divergence sees each row divided by its sum)
        dist, ind = est.fit(X, np.arange(60) % 3).kneighbors(X[:3], n_neighbors=2)
        assert np.isfinite(dist).all()
        return
    with pytest.raises(ValueError, match=r"^ApproximateKLNearestNeighbors: histogram values are too large"):
        est.fit(X, np.arange(60) % 3)
