"""Tests of the point-cloud transformers of eppf.preprocessing."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.distance import pdist
from sklearn.base import clone
from sklearn.pipeline import make_pipeline
from sklearn.utils import get_tags

from eppf.preprocessing._perturb import scale
from eppf.preprocessing import GaussianNoise, Occlusion, RandomDropout, RandomRotation, RandomScaling, Resampler


def _clouds(n=4, n_points=60, normals=True, seed=0):
    rng = np.random.RandomState(seed)
    out = []
    for _ in range(n):
        xyz = rng.normal(size=(n_points, 3)) * rng.uniform(0.5, 3)
        if normals:
            nrm = rng.normal(size=(n_points, 3))
            xyz = np.hstack([xyz, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)])
        out.append(xyz)
    return out


ALL = [
    GaussianNoise(0.02, random_state=0),
    RandomDropout(0.3, random_state=0),
    Occlusion(0.3, random_state=0),
    RandomRotation(random_state=0),
    Resampler(32, random_state=0),
    RandomScaling(random_state=0),
]


def _rows_in(sub, full):
    """True when every row of ``sub`` is a row of ``full``."""
    return all(np.any(np.all(np.abs(full - r) <= 1e-12, axis=1)) for r in sub)


@pytest.mark.parametrize("est", ALL, ids=lambda e: type(e).__name__)
def test_list_in_list_out_and_no_mutation(est):
    X = _clouds()
    copies = [c.copy() for c in X]
    out = clone(est).fit(X).transform(X)
    assert isinstance(out, list) and len(out) == len(X)
    assert all(o.dtype == np.float64 and o.shape[1] == 6 for o in out)
    for a, b in zip(X, copies):
        assert_array_equal(a, b)
    # stateless (test_common.py checks that it then works unfitted, and that fit returns self)
    assert get_tags(est).requires_fit is False


@pytest.mark.parametrize("est", ALL, ids=lambda e: type(e).__name__)
def test_fit_transform_is_fit_then_transform(est):
    # fit_transform validates the clouds once (fit learns nothing): the same clouds, the same errors
    X = _clouds()
    ref = clone(est).fit(X).transform(X)
    for a, b in zip(clone(est).fit_transform(X), ref):
        assert_array_equal(a, b)
    with pytest.raises(ValueError, match="point cloud 1 contains NaN"):
        clone(est).fit_transform([X[0], np.full((5, 3), np.nan)])


@pytest.mark.parametrize("est", ALL, ids=lambda e: type(e).__name__)
def test_seeding(est):
    X = _clouds()
    a = clone(est).transform(X)
    b = clone(est).transform(X)
    for u, v in zip(a, b):
        assert_array_equal(u, v)
    # object k depends only on random_state and k: chunks give the same result
    head = clone(est).transform(X[:2])
    for u, v in zip(head, a[:2]):
        assert_array_equal(u, v)
    # identical objects get independent draws
    twin = clone(est).transform([X[0], X[0]])
    assert twin[0].shape != twin[1].shape or not np.array_equal(twin[0], twin[1])
    # a RandomState instance draws afresh on each call
    stream = clone(est).set_params(random_state=np.random.RandomState(0))
    first, second = stream.transform(X), stream.transform(X)
    assert any(u.shape != v.shape or not np.array_equal(u, v) for u, v in zip(first, second))


def test_gaussian_noise_scale_and_invariance():
    cloud = np.random.RandomState(0).uniform(size=(20000, 3))  # extent ~1 on every axis
    noisy = GaussianNoise(0.05, random_state=1).transform([cloud])[0]
    assert_allclose((noisy - cloud).std(axis=0), 0.05, rtol=0.03)
    # relative to the unit cube: scaling the object scales its noise
    big = GaussianNoise(0.05, random_state=1).transform([10 * cloud])[0]
    assert_allclose(big, 10 * noisy, rtol=1e-10, atol=1e-10)
    absolute = GaussianNoise(0.05, relative_to="none", random_state=1).transform([10 * cloud])[0]
    assert_allclose((absolute - 10 * cloud).std(axis=0), 0.05, rtol=0.03)
    X = _clouds(1)
    # (normals are re-normalised on input, hence the round-off tolerance)
    assert_allclose(GaussianNoise(0.0).transform(X)[0], X[0], rtol=0, atol=1e-15)
    assert_allclose(GaussianNoise(0.1, random_state=0).transform(X)[0][:, 3:], X[0][:, 3:], rtol=0, atol=1e-15)


def test_dropout_and_occlusion_keep_original_rows():
    X = _clouds(n_points=100)
    for est in (RandomDropout(0.25, random_state=3), Occlusion(0.25, random_state=3)):
        for orig, out in zip(X, est.transform(X)):
            assert out.shape == (75, 6)
            assert _rows_in(out, orig)


def test_occlusion_fixed_direction_removes_far_side():
    X = _clouds(n_points=50)
    out = Occlusion(0.4, direction="z").transform(X)
    for orig, kept in zip(X, out):
        threshold = np.sort(orig[:, 2])[20]
        assert_allclose(kept, orig[orig[:, 2] >= threshold], rtol=0, atol=1e-15)


def test_rotation_is_rigid_and_moves_normals():
    X = _clouds(n_points=30)
    for orig, rot in zip(X, RandomRotation(random_state=5).transform(X)):
        assert_allclose(pdist(rot[:, :3]), pdist(orig[:, :3]), atol=1e-10)
        # angle between each normal and each point-to-point vector is kept
        assert_allclose(np.einsum("ij,ij->i", rot[1:, :3] - rot[0, :3], rot[1:, 3:]),
                        np.einsum("ij,ij->i", orig[1:, :3] - orig[0, :3], orig[1:, 3:]), atol=1e-10)
        assert not np.allclose(rot, orig)
    for orig, rot in zip(X, RandomRotation(axis="z", random_state=5).transform(X)):
        assert_allclose(rot[:, 2], orig[:, 2], atol=1e-12)  # about the vertical axis through the centroid


def test_random_scaling_matches_the_function():
    X = _clouds()
    out = RandomScaling(0.5, 2.0, random_state=0).transform(X)
    for cloud, new in zip(X, out):
        factors = np.ptp(new[:, :3], axis=0) / np.ptp(cloud[:, :3], axis=0)
        assert ((factors >= 0.5 - 1e-12) & (factors <= 2.0 + 1e-12)).all()
        assert_allclose(new, scale(cloud, factors), atol=1e-12)


@pytest.mark.parametrize("params", [dict(), dict(low=0.5, high=2.0, center="origin"), dict(anisotropic=False)])
def test_random_scaling_of_many_clouds_is_the_cloud_by_cloud_function_bit_for_bit(params):
    # the transformer stretches all clouds in whole-array operations; each must be exactly what
    # random_scaling gives that cloud with its own seed (the descriptor pools of saved models depend on it)
    from eppf.preprocessing._perturb import random_scaling
    from eppf.utils import object_seeds
    from eppf.utils._sampling import object_rng

    rng = np.random.RandomState(7)
    sized = [rng.normal(size=(n, 3)) * 50 + 3 for n in (5, 300, 300, 41, 2)]
    with_normals = _clouds(5, n_points=37)
    mixed = [with_normals[0], sized[1], with_normals[2]]
    ragged_normals = [with_normals[0][:20], with_normals[1], with_normals[2][:5]]
    for X in (sized, with_normals, mixed, ragged_normals):
        out = RandomScaling(random_state=3, **params).fit_transform(X)
        seeds = object_seeds(3, len(X))
        for cloud, new, seed in zip(X, out, seeds):
            ref = random_scaling(cloud, params.get("low", 0.8), params.get("high", 1.25),
                                 anisotropic=params.get("anisotropic", True), center=params.get("center", "centroid"),
                                 random_state=object_rng(seed))
            assert new.shape == cloud.shape
            assert_array_equal(new, ref)


def test_resampler_sizes():
    small, large = _clouds(1, n_points=10)[0], _clouds(1, n_points=500)[0]
    out_small, out_large = Resampler(64, random_state=0).transform([small, large])
    assert out_small.shape == out_large.shape == (64, 6)
    assert _rows_in(out_large, large) and len(np.unique(out_large, axis=0)) == 64
    assert len(np.unique(out_small, axis=0)) == 10  # every point kept, then repeats


def test_pipeline():
    X = _clouds()
    pipe = make_pipeline(RandomRotation(axis="z", random_state=0), GaussianNoise(0.01, random_state=0), Resampler(16, random_state=0))
    out = pipe.fit_transform(X)
    assert [c.shape for c in out] == [(16, 6)] * 4
    assert pipe.get_params()["gaussiannoise__sigma"] == 0.01


@pytest.mark.parametrize(
    "est, exc, msg",
    [
        (GaussianNoise(-0.1), ValueError, "GaussianNoise: sigma must be a finite float >= 0, got -0.1"),
        (GaussianNoise("big"), TypeError, "GaussianNoise: sigma must be a finite float >= 0, got 'big'"),
        (GaussianNoise(0.1, relative_to="bbox"), ValueError, "GaussianNoise: relative_to must be 'unit_cube' or 'none', got 'bbox'"),
        (RandomDropout(1.0), ValueError, "RandomDropout: fraction must be a float in [0, 1), got 1.0"),
        (Occlusion(0.2, direction=[0, 0, 0]), ValueError, "Occlusion: direction must be 'x', 'y', 'z' or a finite non-zero vector of length 3 or None, got [0, 0, 0]"),
        (Occlusion(0.2, direction="w"), ValueError, "Occlusion: direction must be 'x', 'y', 'z' or a finite non-zero vector of length 3 or None, got 'w'"),
        (RandomRotation(axis=[1, 0]), ValueError, "RandomRotation: axis must be 'x', 'y', 'z' or a finite non-zero vector of length 3 or None, got [1, 0]"),
        (RandomRotation(center="middle"), ValueError, "RandomRotation: center must be 'centroid' or 'origin', got 'middle'"),
        (Resampler(1), ValueError, "Resampler: n_points must be an int >= 2, got 1"),
        (RandomScaling(2.0, 1.0), ValueError, "RandomScaling: need 0 < low <= high, got low=2.0, high=1.0"),
        (RandomScaling(anisotropic="yes"), TypeError, "RandomScaling: anisotropic must be True or False, got 'yes'"),
        (RandomScaling(center="middle"), ValueError, "RandomScaling: center must be 'centroid' or 'origin', got 'middle'"),
        (Resampler(3.5), TypeError, "Resampler: n_points must be an int >= 2, got 3.5"),
    ],
)
def test_parameter_errors(est, exc, msg):
    for method in ("fit", "transform"):
        with pytest.raises(exc, match=re.escape(msg)):
            getattr(est, method)(_clouds(1))


@pytest.mark.parametrize(
    "X, exc, msg",
    [
        ([], ValueError, "RandomDropout: X is empty"),
        ([np.zeros((1, 3))], ValueError, "RandomDropout: point cloud 0 has 1 point; at least 2 are needed"),
        ([np.array([[0, 0, 0], [np.nan, 1, 1]])], ValueError, "RandomDropout: point cloud 0 contains NaN or infinite values"),
        ([np.zeros((5, 4))], ValueError, "RandomDropout: point cloud 0 must have shape"),
        (np.zeros((5, 3)), ValueError, "RandomDropout: X is a single 2D array"),
        ("clouds", TypeError, "RandomDropout: X must be a list of point clouds"),
    ],
)
def test_input_errors(X, exc, msg):
    with pytest.raises(exc, match=re.escape(msg)):
        RandomDropout(0.1).fit_transform(X)


@pytest.mark.parametrize(
    "est, msg",
    [
        (RandomRotation(random_state=0), "RandomRotation: the rotated point cloud 1 overflows float64"),
        (RandomScaling(2.0, 2.5, random_state=0), "RandomScaling: the stretched point cloud 1 overflows float64"),
        (RandomScaling(2.0, 2.5, center="origin", random_state=0), "RandomScaling: the stretched point cloud 1 overflows"),
        (GaussianNoise(1.0, random_state=0), "GaussianNoise: the noisy point cloud 1 overflows float64"),
    ],
)
def test_overflow_names_the_transformer_and_the_cloud(est, msg):
    # the second cloud reaches float64's limit: NaN or inf coordinates (and NumPy warnings) came back
    huge = np.array([[1e308, 1e308, 0.0], [-1e308, 1e308, 0.0], [0.0, -1e308, 1e308], [1e308, 0.0, -1e308]])
    with np.errstate(all="raise"):
        with pytest.raises(ValueError, match=re.escape(msg)):
            est.fit_transform([_clouds(1)[0], huge])
