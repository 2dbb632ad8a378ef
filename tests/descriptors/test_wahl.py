"""Tests of eppf.WahlTransformer (hand-computed surflet pairs, invariants, errors)."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import make_pipeline

from eppf import KLNearestNeighbors, WahlTransformer
from eppf.preprocessing._normals import estimate_normals
from eppf.descriptors._wahl_fast import surflet_pair_features

A = 1 / np.sqrt(2)


def _surflets(n=300, seed=0, shape=(1.0, 0.6, 0.3)):
    """Points on an ellipsoid with their exact outward normals."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    ax = np.asarray(shape)
    p = u * ax
    nrm = u / ax
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return np.hstack([p, nrm])


@pytest.mark.parametrize(
    "n2, source, expected",
    [
        # source p1 (its normal is perpendicular to d): u = z, v = d x u = -y, w = x
        ([1, 0, 0], "perpendicular", (np.pi / 2, 0.0, 0.0, 1.0)),
        ([A, 0, A], "perpendicular", (np.pi / 4, 0.0, 0.0, 1.0)),
        ([0, A, A], "perpendicular", (0.0, -A, 0.0, 1.0)),
        # PCL's rule: the source is p2, d = -x, u = (x + z)/sqrt2, v = y, w = (-x + z)/sqrt2
        ([A, 0, A], "parallel", (np.pi / 4, 0.0, -A, 1.0)),
    ],
)
def test_known_surflet_pairs(n2, source, expected):
    p1, n1, p2 = np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    n2 = np.asarray(n2, dtype=float)
    feat = surflet_pair_features(p1, n1, p2, n2, source == "parallel")
    assert_allclose(feat, expected, atol=1e-12)
    # the pair's order does not matter
    assert_allclose(surflet_pair_features(p2, n2, p1, n1, source == "parallel"), expected, atol=1e-12)


def test_undefined_frame_is_none():
    p1, p2 = np.zeros(3), np.array([1.0, 0.0, 0.0])
    x = np.array([1.0, 0.0, 0.0])
    assert surflet_pair_features(p1, x, p2, x, False) is None
    assert surflet_pair_features(p1, x, p1, x, False) is None


def test_two_surflets_fill_one_bin():
    # alpha = pi/4 -> bin 3, beta = 0 -> 2, gamma = 0 -> 2, delta = 1 -> 4 (5 bins each)
    cloud = np.array([[0, 0, 0, 0, 0, 1], [1, 0, 0, A, 0, A]], dtype=float)
    X = WahlTransformer(n_pairs=100, random_state=0).fit_transform([cloud])
    expected = np.zeros(625)
    expected[((3 * 5 + 2) * 5 + 2) * 5 + 4] = 1.0
    assert_array_equal(X[0], expected)
    X6 = WahlTransformer(n_bins=(6, 2, 3, 4), n_pairs=10, random_state=0).fit_transform([cloud])
    # alpha: floor(6 * 0.625) = 3, beta: 1, gamma: floor(3 * 0.5) = 1, delta: 3
    assert X6.shape == (1, 144) and X6[0, ((3 * 2 + 1) * 3 + 1) * 4 + 3] == 1.0


def test_sum_layout_and_names():
    est = WahlTransformer(n_bins=(2, 3, 4, 5), n_pairs=2000, random_state=0)
    X = est.fit_transform([_surflets(), _surflets(seed=1, shape=(1, 1, 1))])
    assert X.shape == (2, 120)
    assert_allclose(X.sum(axis=1), 1.0)
    names = est.get_feature_names_out()
    assert names[0] == "wahl_a0_b0_g0_d0" and names[1] == "wahl_a0_b0_g0_d1" and names[-1] == "wahl_a1_b2_g3_d4"
    assert WahlTransformer(n_bins=6).fit([_surflets()]).n_features_out_ == 1296


def test_threads_and_repeats_are_bit_identical():
    clouds = [_surflets(200, seed=s) for s in range(5)]
    a = WahlTransformer(n_pairs=3000, random_state=2, n_jobs=1).fit_transform(clouds)
    b = WahlTransformer(n_pairs=3000, random_state=2, n_jobs=2).fit_transform(clouds)
    assert_array_equal(a, b)
    assert not np.array_equal(a, WahlTransformer(n_pairs=3000, random_state=3).fit_transform(clouds))


def test_rotation_translation_scale_invariance():
    cloud = _surflets(400)
    rng = np.random.default_rng(5)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    moved = np.hstack([cloud[:, :3] @ q.T * 2.0 + [3.0, -1.0, 2.0], cloud[:, 3:] @ q.T])
    est = WahlTransformer(n_pairs=20000, random_state=0)
    a, b = est.fit_transform([cloud])[0], est.transform([moved])[0]
    # the same pairs are drawn; only values on a bin edge may move (rounding)
    assert np.abs(a - b).sum() <= 10 / 20000
    other = est.transform([_surflets(400, seed=1, shape=(1, 1, 1))])[0]
    assert np.abs(a - other).sum() > 0.1


def test_estimated_normals_match_given_ones():
    cloud = _surflets(300)[:, :3]
    normals = estimate_normals(cloud, 10, orientation="centroid")
    est = WahlTransformer(n_pairs=2000, random_state=0)
    assert_array_equal(est.fit_transform([cloud]), est.transform([np.hstack([cloud, normals])]))
    # a mix of clouds with and without normals
    given = np.hstack([cloud, normals])
    assert_array_equal(est.transform([cloud, given]), est.transform([given, given]))


def test_source_rule_matters():
    clouds = [_surflets(300)]
    a = WahlTransformer(n_pairs=5000, random_state=0).fit_transform(clouds)
    b = WahlTransformer(n_pairs=5000, source="parallel", random_state=0).fit_transform(clouds)
    assert not np.array_equal(a, b)


def test_pipeline_and_grid_search():
    clouds = [_surflets(150, seed=k, shape=(1, 1, 1) if k % 2 else (1, 0.3, 0.1)) for k in range(12)]
    y = [k % 2 for k in range(12)]
    pipe = make_pipeline(WahlTransformer(n_pairs=2000, random_state=0), KLNearestNeighbors())
    search = GridSearchCV(pipe, {"wahltransformer__n_bins": [4, 5]}, cv=2).fit(clouds, y)
    assert search.best_score_ > 0.8


_N_BINS = ("n_bins must be an int in [1, 1024] or a tuple of 4 ints in [1, 1024] "
           "(alpha, beta, gamma, delta; at most 2**26 bins in all), got ")


@pytest.mark.parametrize(
    "params, err, msg",
    [
        ({"n_bins": (5, 5, 5)}, ValueError, _N_BINS + "(5, 5, 5)"),
        ({"n_bins": 0}, ValueError, _N_BINS + "0"),
        ({"n_bins": "5"}, ValueError, _N_BINS + "'5'"),
        ({"n_bins": 2.5}, TypeError, _N_BINS + "2.5"),
        ({"n_bins": (1024, 1024, 64, 2)}, ValueError, _N_BINS + "(1024, 1024, 64, 2)"),  # 2**27 bins
        ({"n_pairs": 0}, ValueError, "n_pairs must be an int in [1, 2147483647], got 0"),
        ({"source": "target"}, ValueError, "source must be 'perpendicular' or 'parallel', got 'target'"),
        ({"n_neighbors": 2}, ValueError, "n_neighbors must be an int >= 3 (a plane needs three points), got 2"),
        ({"normal_orientation": "up"}, ValueError, "normal_orientation must be 'centroid', 'origin' or None, got 'up'"),
    ],
)
def test_bad_parameters(params, err, msg):
    with pytest.raises(err, match=re.escape("WahlTransformer: " + msg)):
        WahlTransformer(**params).fit([_surflets()])


@pytest.mark.parametrize(
    "X, msg",
    [
        ([np.zeros((1, 6)) + [0, 0, 0, 0, 0, 1]], "point cloud 0 has 1 point; at least 2 are needed"),
        ([np.array([[0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 1.0]])], "point cloud 0 has 1 zero-length normal(s)"),
        ([np.array([[0, 0, 0, 0, 0, 1], [np.inf, 0, 0, 0, 0, 1.0]])], "point cloud 0 contains NaN or infinite"),
        ([np.ones((4, 5))], "point cloud 0 must have shape"),
    ],
)
def test_bad_clouds(X, msg):
    with pytest.raises(ValueError, match=re.escape("WahlTransformer: " + msg)):
        WahlTransformer().fit(X)


def test_degenerate_pairs_are_rejected():
    # every normal along the line through all points: no frame can be built
    line = np.zeros((10, 6))
    line[:, 0] = np.arange(10)
    line[:, 3] = 1.0
    est = WahlTransformer(n_pairs=50, random_state=0).fit([line])
    with pytest.raises(ValueError, match=re.escape("WahlTransformer: point cloud 0 has too few usable surflet pairs")):
        est.transform([line])


def test_not_fitted():
    with pytest.raises(NotFittedError):
        WahlTransformer().transform([_surflets()])


@pytest.mark.parametrize("n_bins", [1, 2, 5, 6, 7, 64, 1000])
def test_alpha_bins_without_atan2_match_atan2(n_bins):
    # The kernel bins alpha from a polynomial atan and falls back on atan2
    # near bin boundaries: every bin must be atan2's, including at the
    # boundaries themselves, on the axes and for signed zeros.
    from eppf.descriptors._wahl_fast import wahl_alpha_bins

    rng = np.random.default_rng(n_bins)
    edges = -np.pi + 2 * np.pi * np.arange(n_bins + 1) / n_bins
    ang = np.concatenate([rng.uniform(-np.pi, np.pi, 20000), edges, np.nextafter(edges, 0), [0.0, np.pi / 2]])
    r = np.concatenate([rng.uniform(0.01, 10.0, ang.size - 2), [1.0, 1.0]])
    y = np.concatenate([r * np.sin(ang), [0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 0.0]])
    x = np.concatenate([r * np.cos(ang), [-1.0, -1.0, 1.0, 1.0, 0.0, 0.0, 0.0]])
    got = wahl_alpha_bins(y, x, n_bins)
    assert_array_equal(got, wahl_alpha_bins(y, x, n_bins, True))
    assert got.min() >= 0 and got.max() == n_bins - 1
