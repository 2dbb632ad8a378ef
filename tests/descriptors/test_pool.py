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
        ({"n_draws": 0}, ValueError, "descriptor_pool: n_draws must be an int >= 1, got 0"),
        ({"n_draws": 2.0}, TypeError, "descriptor_pool: n_draws must be an int >= 1, got 2.0"),
        ({"n_draws": True}, TypeError, "descriptor_pool: n_draws must be an int >= 1, got True"),
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


# ------------------------------------------------------------ DescriptorPool
def test_descriptor_pool_step_training_and_test_pools():
    from eppf.descriptors import DescriptorPool
    from eppf.descriptors._pool import _seed_params

    X = _clouds()
    step = DescriptorPool(TR, 3, augment=RandomScaling(0.5, 2.0), test_draws=2, random_state=0)
    train = step.fit_transform(X)
    assert train.shape == (4, 3, 1200) and step.n_features_out_ == 1200 and len(step.transformers_) == 3
    rng = np.random.RandomState(0)
    seeds, test_seeds = rng.randint(np.iinfo(np.int32).max, size=(3, 2)), rng.randint(np.iinfo(np.int32).max, size=(2, 2))
    for r in range(3):  # draw r: its own seeded transformer; draws 1.. of stretched copies
        clouds = X if r == 0 else RandomScaling(0.5, 2.0, random_state=int(seeds[r, 1])).fit_transform(X)
        ref = EPPFTransformer(n_pairs=800, n_neighbors=10, random_state=int(seeds[r, 0])).fit(X).transform(clouds)
        assert_array_equal(train[:, r], ref)
    test = step.transform(X)
    assert test.shape == (4, 2, 1200)
    assert_array_equal(test[:, 0], train[:, 0])  # draw 0 is the plain clouds through transformer 0
    stretched = RandomScaling(0.5, 2.0, random_state=int(test_seeds[1, 1])).fit_transform(X)
    assert_array_equal(test[:, 1], step.transformers_[1].transform(stretched))
    assert not np.array_equal(test[:, 1], train[:, 1])  # test copies are not the training ones
    # without test-time augmentation every draw describes the clouds as given
    plain = step.set_params(test_augment=False).transform(X)
    assert_array_equal(plain[:, 1], step.transformers_[1].transform(X))
    # reproducible, and nested random_state parameters are the ones seeded
    assert_array_equal(DescriptorPool(TR, 3, augment=RandomScaling(0.5, 2.0), random_state=0).fit_transform(X), train)
    from eppf.descriptors import DescriptorUnion, GASDTransformer

    union = _seed_params(DescriptorUnion([("e", TR), ("g", GASDTransformer())]), 7)
    assert union.get_params()["e__random_state"] == 7


def test_descriptor_pool_step_in_a_pipeline_with_side_features():
    from sklearn.pipeline import Pipeline

    from eppf.descriptors import DescriptorPool, DescriptorUnion, ProportionTransformer

    X = _clouds(12, seed=3)
    y = np.arange(12) % 2
    union = DescriptorUnion([("eppf", TR), ("prop", ProportionTransformer())], normalize="none")
    pipe = Pipeline([("pool", DescriptorPool(union, 2, augment=RandomScaling(), random_state=0)),
                     ("cnn", EPPF4DClassifier(n_side_features="auto", max_epochs=1, filters=(2, 2, 2), n_hidden=4,
                                              early_stopping=False, random_state=0, n_jobs=1))])
    pipe.fit(X, y)
    assert pipe[-1].n_side_features_ == 6 and pipe[-1].n_draws_fit_ == 2
    assert pipe.predict_proba(X).shape == (12, 2)


@pytest.mark.parametrize("params, err, msg", [
    (dict(n_draws=0), ValueError, "n_draws must be an int >= 1, got 0"),
    (dict(n_draws=2.0), TypeError, "n_draws must be an int >= 1, got 2.0"),
    (dict(test_draws=0), ValueError, "test_draws must be an int >= 1 or None, got 0"),
    (dict(test_augment="no"), TypeError, "test_augment must be True or False, got 'no'"),
    (dict(augment=object()), TypeError, "augment must be a scikit-learn style estimator"),
    (dict(transformer=object()), TypeError, "transformer must be a scikit-learn style estimator"),
])
def test_descriptor_pool_step_bad_parameters(params, err, msg):
    from eppf.descriptors import DescriptorPool

    kwargs = {"transformer": TR, **params}
    with pytest.raises(err, match=f"DescriptorPool: {msg}"):
        DescriptorPool(**kwargs).fit(_clouds(2))


def test_descriptor_pool_step_needs_fit():
    from sklearn.exceptions import NotFittedError

    from eppf.descriptors import DescriptorPool

    with pytest.raises(NotFittedError):
        DescriptorPool(TR).transform(_clouds(2))
