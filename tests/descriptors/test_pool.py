"""Tests of eppf.descriptor_pool (descriptor draws for the CNN's pools)."""

import re

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from eppf import EPPF4DClassifier, EPPFTransformer, descriptor_pool
from eppf.preprocessing import RandomScaling


def _clouds(n=4, seed=0):
    rng = np.random.RandomState(seed)
    return [rng.normal(size=(150, 3)) * rng.uniform(0.5, 2.0, size=3) for _ in range(n)]


TR = EPPFTransformer(n_pairs=800, n_neighbors=10)


def test_shape_and_each_draw_is_a_seeded_transformer():
    X = _clouds()
    pool = descriptor_pool(TR, X, 3, random_state=0)
    assert pool.shape == (4, 3, 1200)
    seeds = np.random.RandomState(0).randint(np.iinfo(np.int32).max, size=(3, 2))
    for r in range(3):
        ref = EPPFTransformer(n_pairs=800, n_neighbors=10, random_state=int(seeds[r, 0])).fit_transform(X)
        assert_array_equal(pool[:, r], ref)
    # draws differ (other pairs), the transformer passed in is left unfitted
    assert not np.array_equal(pool[:, 0], pool[:, 1])
    assert not hasattr(TR, "n_bins_")


def test_augment_leaves_draw_zero_alone_and_is_deterministic():
    X = _clouds()
    plain = descriptor_pool(TR, X, 3, random_state=1)
    aug = descriptor_pool(TR, X, 3, augment=RandomScaling(0.5, 2.0), random_state=1)
    assert_array_equal(aug[:, 0], plain[:, 0])
    seeds = np.random.RandomState(1).randint(np.iinfo(np.int32).max, size=(3, 2))
    stretched = RandomScaling(0.5, 2.0, random_state=int(seeds[2, 1])).fit_transform(X)
    # the scale (scaling="fit") is learnt from the clouds as given, then applied to the stretched ones
    ref = EPPFTransformer(n_pairs=800, n_neighbors=10, random_state=int(seeds[2, 0])).fit(X).transform(stretched)
    assert_array_equal(aug[:, 2], ref)
    assert not np.array_equal(aug[:, 1], plain[:, 1])
    assert_array_equal(descriptor_pool(TR, X, 3, augment=RandomScaling(0.5, 2.0), random_state=1), aug)


def test_generator_input_is_read_once():
    X = _clouds(3)
    assert_array_equal(descriptor_pool(TR, (c for c in X), 2, random_state=0), descriptor_pool(TR, X, 2, random_state=0))


def test_pool_feeds_the_classifier():
    rng = np.random.RandomState(0)
    X = [rng.normal(size=(120, 3)) * ([1, 1, 1] if k % 2 else [3, 1, 0.3]) for k in range(12)]
    y = np.array(["ball", "plate"] * 6)
    pool = descriptor_pool(EPPFTransformer((4, 2, 2, 2), n_pairs=600, n_neighbors=8), X, 2,
                           augment=RandomScaling(), random_state=0)
    clf = EPPF4DClassifier((4, 2, 2, 2), max_epochs=2, n_hidden=8, early_stopping=False, random_state=0).fit(pool, y)
    assert clf.n_draws_fit_ == 2
    assert clf.predict_proba(pool).shape == (12, 2)


@pytest.mark.parametrize(
    "kwargs, exc, msg",
    [
        ({"n_draws": 0}, ValueError, "descriptor_pool: n_draws must be >= 1, got 0"),
        ({"n_draws": 2.0}, TypeError, "descriptor_pool: n_draws must be an int, got float"),
        ({"n_draws": True}, TypeError, "descriptor_pool: n_draws must be an int, got bool"),
        ({"transformer": "eppf"}, TypeError, "descriptor_pool: transformer must be a scikit-learn style estimator with fit and transform and a random_state parameter, got str"),
        ({"augment": np.sqrt}, TypeError, "descriptor_pool: augment must be a scikit-learn style estimator with fit_transform and a random_state parameter, got ufunc"),
    ],
)
def test_errors(kwargs, exc, msg):
    args = {"transformer": TR, "n_draws": 2, **kwargs}
    with pytest.raises(exc, match=re.escape(msg)):
        descriptor_pool(args.pop("transformer"), _clouds(2), args.pop("n_draws"), **args)


def test_bad_clouds_are_reported_by_the_transformer():
    with pytest.raises(ValueError, match="EPPFTransformer: point cloud 1 contains NaN"):
        descriptor_pool(TR, [np.ones((5, 3)) * np.arange(5)[:, None], np.full((5, 3), np.nan)], 2)
