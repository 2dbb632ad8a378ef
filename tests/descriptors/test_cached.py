"""Tests of CachedTransformer (descriptor outputs cached as .npz files; fit always runs)."""

import re
import warnings

import joblib
import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.pipeline import make_pipeline

from eppf.descriptors import CachedTransformer

CALLS = {"fit": 0, "transform": 0}


class _Histogram(TransformerMixin, BaseEstimator):
    """A small seeded stand-in for a descriptor transformer that counts its work."""

    def __init__(self, n_bins=4, random_state=0, n_jobs=None):
        self.n_bins = n_bins
        self.random_state = random_state
        self.n_jobs = n_jobs

    def fit(self, X, y=None):
        CALLS["fit"] += 1
        self.scale_ = max(np.abs(c).max() for c in X)
        return self

    def transform(self, X):
        CALLS["transform"] += 1
        rng = np.random.RandomState(self.random_state)
        noise = rng.uniform(size=self.n_bins) * 1e-3
        return np.array([np.histogram(c[:, 0] / self.scale_, bins=self.n_bins, range=(-1, 1))[0] + noise for c in X])


def _clouds(seed, n=5):
    rng = np.random.RandomState(seed)
    return [rng.normal(size=(20, 3)) for _ in range(n)]


@pytest.fixture(autouse=True)
def _reset():
    CALLS.update(fit=0, transform=0)


def test_cache_hits_and_matches_direct(tmp_path):
    X, Z = _clouds(0), _clouds(1)
    direct = _Histogram().fit(X)
    expected = direct.transform(Z)
    CALLS.update(fit=0, transform=0)
    cached = CachedTransformer(_Histogram(), memory=tmp_path).fit(X)
    assert_array_equal(cached.transform(Z), expected)
    assert CALLS == {"fit": 1, "transform": 2}  # fit_transform inside fit, then transform
    again = CachedTransformer(_Histogram(n_jobs=4), memory=str(tmp_path)).fit(X)  # n_jobs only changes speed
    assert_array_equal(again.transform(Z), expected)
    assert CALLS == {"fit": 2, "transform": 2}  # the cheap fit runs again; both outputs come from the cache
    assert again.transformer_.scale_ == direct.scale_


@pytest.mark.parametrize("change", ["param", "data", "fitted_state"])
def test_cache_key_changes(tmp_path, change):
    X, Z = _clouds(0), _clouds(1)
    CachedTransformer(_Histogram(), memory=tmp_path).fit(X).transform(Z)
    before = dict(CALLS)
    if change == "param":
        out = CachedTransformer(_Histogram(n_bins=5), memory=tmp_path).fit(X).transform(Z)
        assert out.shape == (5, 5)
    elif change == "data":
        CachedTransformer(_Histogram(), memory=tmp_path).fit(X).transform(_clouds(2))
    else:
        CachedTransformer(_Histogram(), memory=tmp_path).fit([10 * c for c in X]).transform(Z)
    assert CALLS["transform"] > before["transform"]


def test_no_memory_means_no_cache():
    X = _clouds(0)
    est = CachedTransformer(_Histogram()).fit(X)
    est.transform(X)
    est.transform(X)
    assert CALLS["transform"] == 3


def test_joblib_memory_object_and_pipeline(tmp_path):
    X = _clouds(0)
    memory = joblib.Memory(tmp_path, verbose=0)
    pipe = make_pipeline(CachedTransformer(_Histogram(), memory=memory))
    a = pipe.fit_transform(X)
    b = clone(pipe).fit_transform(X)
    assert_array_equal(a, b)
    assert CALLS == {"fit": 2, "transform": 1}
    assert any(f.suffix == ".npz" for f in tmp_path.iterdir())


def test_cache_files_hold_no_pickle(tmp_path):
    CachedTransformer(_Histogram(), memory=tmp_path).fit_transform(_clouds(0))
    (path,) = [f for f in tmp_path.iterdir() if f.suffix == ".npz"]
    with np.load(path, allow_pickle=False) as f:
        assert list(f) == ["X"] and f["X"].dtype == np.float64


def test_random_state_none_warns(tmp_path):
    with pytest.warns(UserWarning, match=re.escape("has random_state=None; the cache returns the first draw")):
        CachedTransformer(_Histogram(random_state=None), memory=tmp_path).fit(_clouds(0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        CachedTransformer(_Histogram(random_state=None)).fit(_clouds(0))  # no cache, no warning


@pytest.mark.parametrize(
    "transformer, memory, exc, msg",
    [
        (_Histogram(), 3, ValueError, "CachedTransformer: memory must be None, a folder or a joblib.Memory"),
        ("eppf", None, TypeError, "CachedTransformer: transformer must have fit and transform methods, got str"),
    ],
)
def test_errors(transformer, memory, exc, msg):
    with pytest.raises(exc, match=re.escape(msg)):
        CachedTransformer(transformer, memory=memory).fit(_clouds(0))


def test_the_old_import_path_still_works():
    import eppf.datasets

    assert eppf.datasets.CachedTransformer is CachedTransformer


def test_feature_names_are_the_wrapped_descriptors_and_only_where_it_has_them(tmp_path):
    from eppf import GASDTransformer

    clouds = [np.random.default_rng(k).normal(size=(80, 3)) for k in range(3)]
    cached = CachedTransformer(GASDTransformer(), memory=tmp_path).fit(clouds)
    names = cached.get_feature_names_out()
    assert_array_equal(names, GASDTransformer().fit(clouds).get_feature_names_out())
    assert len(names) == cached.transform(clouds).shape[1]
    # a wrapped transformer without names: the wrapper has none either (as a Pipeline step would expect)
    assert not hasattr(CachedTransformer(_Histogram(), memory=tmp_path), "get_feature_names_out")
