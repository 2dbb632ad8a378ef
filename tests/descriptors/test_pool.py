"""Tests of eppf.descriptor_pool (descriptor draws for the CNN's pools)."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import BaseEstimator, TransformerMixin, clone

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
        ({"transformer": "eppf"}, TypeError, "descriptor_pool: transformer must be a scikit-learn style estimator with fit and transform and a random_state parameter (or an augment, whose perturbed copies make the draws differ), got str"),
        ({"augment": np.sqrt}, TypeError, "descriptor_pool: augment must be a scikit-learn style estimator with fit_transform and a random_state parameter, got ufunc"),
    ],
)
def test_errors(kwargs, exc, msg):
    args = {"transformer": TR, "n_draws": 2, **kwargs}
    with pytest.raises(exc, match=re.escape(msg)):
        descriptor_pool(args.pop("transformer"), _clouds(2), args.pop("n_draws"), **args)


def test_deterministic_transformer_draws_differ_by_augmentation():
    # GASD has no random_state: without augment its draws would be identical (refused); with it, draw r
    # describes the copy stretched with draw r's augmentation seed, in the function and the step alike.
    from eppf.descriptors import DescriptorPool, GASDTransformer

    X = _clouds()
    msg = ("transformer must be a scikit-learn style estimator with fit and transform and a random_state parameter "
           "(or an augment, whose perturbed copies make the draws differ), got GASDTransformer")
    with pytest.raises(TypeError, match=re.escape(f"descriptor_pool: {msg}")):
        descriptor_pool(GASDTransformer(), X, 2)
    with pytest.raises(TypeError, match=re.escape(f"DescriptorPool: {msg}")):
        DescriptorPool(GASDTransformer(), 2).fit(X)
    pool = descriptor_pool(GASDTransformer(), X, 3, augment=RandomScaling(0.5, 2.0), random_state=4)
    seeds = np.random.RandomState(4).randint(np.iinfo(np.int32).max, size=(3, 2))
    for r in range(3):
        clouds = X if r == 0 else RandomScaling(0.5, 2.0, random_state=int(seeds[r, 1])).fit_transform(X)
        assert_array_equal(pool[:, r], GASDTransformer().fit(X).transform(clouds))
    assert not np.array_equal(pool[:, 1], pool[:, 2])
    step = DescriptorPool(GASDTransformer(), 3, augment=RandomScaling(0.5, 2.0), random_state=4)
    assert_array_equal(step.fit_transform(X), pool)
    assert not np.array_equal(step.transform(X)[:, 1], step.transform(X)[:, 0])


def test_nested_random_states_are_seeded_by_the_function():
    # A union has no random_state of its own: each draw seeds its blocks' (as DescriptorPool does).
    from eppf.descriptors import DescriptorPool, DescriptorUnion, ProportionTransformer

    X = _clouds()
    union = DescriptorUnion([("eppf", TR), ("prop", ProportionTransformer())], normalize="none")
    pool = descriptor_pool(union, X, 2, random_state=3)
    assert_array_equal(pool, DescriptorPool(union, 2, random_state=3).fit_transform(X))
    seeds = np.random.RandomState(3).randint(np.iinfo(np.int32).max, size=(2, 2))
    assert_array_equal(pool[:, 1], clone(union).set_params(eppf__random_state=int(seeds[1, 0])).fit(X).transform(X))
    assert not np.array_equal(pool[:, 0], pool[:, 1])


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


# ------------------------------------------------------------ share_normals
class _Received(TransformerMixin, BaseEstimator):
    """Returns the clouds it is given, flattened: the points and normals a pool's draws hand a descriptor."""

    def __init__(self, n_neighbors=20, normal_orientation="centroid", random_state=None):
        self.n_neighbors = n_neighbors
        self.normal_orientation = normal_orientation
        self.random_state = random_state

    def fit(self, X, y=None):
        return self

    def transform(self, X):
        return np.stack([np.asarray(c, dtype=np.float64).ravel() for c in X])


def _ellipsoid(n, axes, seed):
    """Points on the ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 and its outward unit normals."""
    rng = np.random.RandomState(seed)
    u = rng.normal(size=(n, 3))
    points = u / np.linalg.norm(u, axis=1, keepdims=True) * axes
    normals = points / np.square(axes)
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def _angles(a, b):
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def test_shared_normals_follow_the_stretch_of_an_analytic_surface():
    # The normals a stretched draw receives with share_normals are the normals estimated once on the cloud
    # as given, mapped by the stretch; on an ellipsoid they must match the analytic normals of the stretched
    # ellipsoid (an independent reference) and the PCA normals a draw would estimate on its own copy.
    from eppf.descriptors import DescriptorPool
    from eppf.preprocessing import estimate_normals

    axes = np.array([3.0, 2.0, 1.0])
    clouds = [_ellipsoid(3000, axes, seed)[0] for seed in (0, 1)]
    pool = DescriptorPool(_Received(), 3, augment=RandomScaling(), share_normals=True, random_state=0)
    for X_pool in (pool.fit_transform(clouds), pool.transform(clouds)):
        for k, cloud in enumerate(clouds):
            draws = X_pool[k].reshape(3, len(cloud), 6)
            # draw 0: the clouds as given, with the normals the descriptor would have estimated itself
            assert_array_equal(draws[0, :, :3], cloud)
            assert_allclose(draws[0, :, 3:], estimate_normals(cloud, n_neighbors=20, orientation="centroid"),
                            atol=1e-15)
            for r in (1, 2):
                points, normals = draws[r, :, :3], draws[r, :, 3:]
                c0, c1 = cloud.mean(axis=0), points.mean(axis=0)
                factors = np.linalg.lstsq((cloud - c0)[:, :1], (points - c1)[:, :1], rcond=None)[0][0, 0], \
                    np.linalg.lstsq((cloud - c0)[:, 1:2], (points - c1)[:, 1:2], rcond=None)[0][0, 0], \
                    np.linalg.lstsq((cloud - c0)[:, 2:], (points - c1)[:, 2:], rcond=None)[0][0, 0]
                assert not np.allclose(factors, 1.0)
                factors = np.array(factors)
                # the stretch about the centroid c0 maps the ellipsoid to that of axes * factors about c0 - S c0
                rel = points - (c0 - factors * c0)
                analytic = rel / np.square(axes * factors)
                analytic /= np.linalg.norm(analytic, axis=1, keepdims=True)
                # PCA normals of 3,000 points are about 1 degree off the surface's (median) whichever way they
                # are made; the shared ones may be a little further off than a draw's own, not much
                per_draw = estimate_normals(points, n_neighbors=20, orientation="centroid")
                shared_off, own_off = _angles(normals, analytic), _angles(per_draw, analytic)
                assert np.median(shared_off) < 2.0 and np.percentile(shared_off, 95) < 6.0
                assert np.median(shared_off) < np.median(own_off) + 0.5
                assert np.median(_angles(normals, per_draw)) < 1.5
    # a plane's PCA normal is exact, and so is its image: S^-1 n is the normal of the stretched plane
    rng = np.random.RandomState(2)
    n = np.array([1.0, -2.0, 3.0]) / np.sqrt(14.0)
    basis = np.linalg.svd(n[None, :])[2][1:]
    plane = rng.uniform(-1, 1, size=(500, 2)) @ basis + [4.0, 0.0, -1.0]
    draws = pool.fit_transform([plane])[0].reshape(3, len(plane), 6)
    for r in (1, 2):
        points, normals = draws[r, :, :3], draws[r, :, 3:]
        tangents = points[1:] - points[0]
        assert_allclose(tangents @ normals[0], 0.0, atol=1e-12)  # perpendicular to the stretched plane
        assert_allclose(np.abs(normals @ normals[0]), 1.0, atol=1e-12)
        own = estimate_normals(points, n_neighbors=20, orientation="centroid")
        assert_allclose(np.abs(np.einsum("ij,ij->i", normals, own)), 1.0, atol=1e-12)


def test_shared_normals_are_estimated_once_and_given_normals_are_kept(monkeypatch):
    from eppf.descriptors import DescriptorPool, DescriptorUnion, GASDTransformer
    from eppf.preprocessing import _normals

    calls = []
    real = _normals.estimate_normals_batch

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(_normals, "estimate_normals_batch", counting)
    X = _clouds()
    union = DescriptorUnion([("eppf", TR), ("gasd", GASDTransformer())], normalize="none")
    for share, expected in ((False, 4), (True, 1)):
        calls.clear()
        pool = DescriptorPool(union, 2, augment=RandomScaling(), test_draws=4, share_normals=share, random_state=0)
        pool.fit(X).transform(X)
        assert len(calls) == expected
    # draw 0 describes the normals the descriptor estimates itself (GASD reads none); the stretched draws differ
    shared = pool.transform(X)
    own = pool.set_params(share_normals=False).transform(X)
    assert_allclose(shared[:, 0], own[:, 0], atol=1e-12)
    assert not np.allclose(shared[:, 1:], own[:, 1:])
    pool.set_params(share_normals=True)
    # clouds that carry normals keep them: nothing is estimated and the pools are those without sharing
    calls.clear()
    with_normals = [np.hstack([c, np.tile([0.0, 0.0, 1.0], (len(c), 1))]) for c in X]
    a = pool.transform(with_normals)
    assert not calls
    assert_array_equal(a, pool.set_params(share_normals=False).fit(with_normals).transform(with_normals))


@pytest.mark.parametrize("transformer, msg", [
    ("esf", "share_normals=True but the transformer ESFTransformer estimates no normals"),
    ("mixed", "share_normals=True needs one normal setting, but the transformer's blocks differ "
              "(a: n_neighbors=10, normal_orientation='centroid'; b: n_neighbors=12, normal_orientation='centroid')"),
])
def test_share_normals_needs_one_normal_setting(transformer, msg):
    from eppf.descriptors import DescriptorPool, DescriptorUnion, ESFTransformer

    est = ESFTransformer(n_triplets=500) if transformer == "esf" else DescriptorUnion(
        [("a", TR), ("b", EPPFTransformer(n_pairs=800, n_neighbors=12))])
    with pytest.raises(ValueError, match=re.escape(f"DescriptorPool: {msg}")):
        DescriptorPool(est, 2, share_normals=True).fit(_clouds(2))


def test_share_normals_is_saved_and_older_pools_load_without_it(tmp_path):
    import json
    import zipfile

    from eppf import load_model, save_model
    from eppf.descriptors import DescriptorPool

    X = _clouds()
    pool = DescriptorPool(TR, 2, augment=RandomScaling(), share_normals=True, random_state=0).fit(X)
    save_model(pool, tmp_path / "pool.eppf")
    back = load_model(tmp_path / "pool.eppf")
    assert back.share_normals is True
    assert_array_equal(back.transform(X), pool.transform(X))
    # a file of a pool saved before the option existed: its pools estimate normals per draw, as then
    with zipfile.ZipFile(tmp_path / "pool.eppf") as zf:
        manifest, blob = json.loads(zf.read("manifest.json")), zf.read("arrays.npz")
    del manifest["root"]["params"]["share_normals"]
    with zipfile.ZipFile(tmp_path / "old.eppf", "w") as zf:
        zf.writestr("manifest.json", json.dumps(manifest))
        zf.writestr("arrays.npz", blob)
    old = load_model(tmp_path / "old.eppf")
    assert old.share_normals is False
    assert_array_equal(old.transform(X), pool.set_params(share_normals=False).transform(X))
