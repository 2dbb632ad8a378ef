"""Tests of eppf.OURCVFHTransformer (plane, box and hemisphere clusters, layout, invariants, errors)."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import make_pipeline

from eppf import KLNearestNeighbors, OURCVFHTransformer
from eppf.descriptors._ourcvfh import _ourcvfh_object
from eppf.descriptors._regions import pair_features


def _plane(n_side=20):
    g = np.linspace(-0.5, 0.5, n_side)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    return np.column_stack([xy, np.zeros(len(xy))]), np.tile([0.0, 0.0, 1.0], (len(xy), 1))


def _box(sides=(1.0, 0.6, 0.35), per_face=12, seed=None):
    """Grid samples of the six faces of a box, with their outward normals."""
    pts, nrm, face = [], [], []
    half = np.asarray(sides) / 2
    f = 0
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        ga = np.linspace(-half[a], half[a], per_face)[1:-1]
        gb = np.linspace(-half[b], half[b], per_face)[1:-1]
        uv = np.stack(np.meshgrid(ga, gb), -1).reshape(-1, 2)
        for sign in (-1.0, 1.0):
            p = np.zeros((len(uv), 3))
            p[:, a], p[:, b], p[:, axis] = uv[:, 0], uv[:, 1], sign * half[axis]
            n = np.zeros((len(uv), 3))
            n[:, axis] = sign
            pts.append(p)
            nrm.append(n)
            face.append(np.full(len(uv), f))
            f += 1
    return np.vstack(pts), np.vstack(nrm), np.concatenate(face)


def test_plane_is_one_cluster():
    p, n = _plane()
    sigs, owners, clusters = _ourcvfh_object(p, n, cluster_tolerance=0.1)
    assert len(clusters) == 1
    assert_array_equal(clusters[0], np.arange(len(p)))
    # Source normal equals every target normal: f1 = atan2(0, 1) = 0, f2 = 0, f3 = 0
    f1, f2, f3 = pair_features(p.mean(axis=0), np.array([0.0, 0.0, 1.0]), p, n)
    assert_allclose(np.c_[f1, f2, f3], 0.0, atol=1e-12)
    # so each angle histogram holds every defined pair in one bin, floor(45 * (0 + pi) / (2 pi)) = 22
    sig = sigs[0]
    for block in range(3):
        assert sig[45 * block + 22] == len(f1) and sig[45 * block : 45 * (block + 1)].sum() == len(f1)


def test_box_faces_are_the_clusters():
    p, n, face = _box()
    _, _, clusters = _ourcvfh_object(p, n, min_points=10, cluster_tolerance=0.12)
    assert len(clusters) == 6
    found = sorted(np.unique(face[c]).tolist() for c in clusters)
    assert found == [[f] for f in range(6)]
    for c in clusters:
        # a face keeps its interior; its rim (high curvature) may go
        assert np.all(n[c] == n[c[0]])
        assert len(c) >= 0.5 * np.sum(face == face[c[0]])


def test_hemisphere_cluster_is_the_polar_cap():
    rng = np.random.default_rng(0)
    u = rng.normal(size=(3000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u = u[u[:, 2] > 0]
    eps = 0.5
    _, _, clusters = _ourcvfh_object(u, u, eps_angle=eps, curvature_threshold=1.0, cluster_tolerance=0.15)
    assert len(clusters) == 1
    # one smooth region (the whole hemisphere), refined to the normals within eps of its mean normal
    mean = u.mean(axis=0) / np.linalg.norm(u.mean(axis=0))
    assert_allclose(mean, [0, 0, 1], atol=0.05)
    assert_array_equal(clusters[0], np.flatnonzero(u @ mean > np.cos(eps)))


def test_signature_layout_and_sums():
    p, n, _ = _box()
    sigs, owners, clusters = _ourcvfh_object(p, n, min_points=10, cluster_tolerance=0.12)
    assert len(sigs) >= len(clusters) and sorted(set(owners)) == list(range(len(clusters)))
    for s in sigs:
        assert s.shape == (308,)
        assert_allclose(s[135:239].sum(), len(p))  # octant weights of a point sum to 1
        assert s[239:].sum() <= len(p)
    est = OURCVFHTransformer(min_points=10, cluster_tolerance=0.12, normalize=False, scaling="none")
    raw = est.fit_transform([np.hstack([p, n])])[0]
    sizes = [len(c) for c in clusters]
    assert_allclose(raw, sigs[owners.index(int(np.argmax(sizes)))])
    first = est.set_params(aggregate="first").transform([np.hstack([p, n])])[0]
    assert_allclose(first, sigs[0])
    mean = est.set_params(aggregate="mean").transform([np.hstack([p, n])])[0]
    assert_allclose(mean, np.mean(sigs, axis=0))
    X = OURCVFHTransformer(min_points=10).fit_transform([np.hstack([p, n])])
    assert X.shape == (1, 308)
    assert_allclose(X.sum(), 1.0)
    names = OURCVFHTransformer().fit([p]).get_feature_names_out()
    assert len(names) == 308 and names[135] == "ourcvfh_octant0_shell0" and names[-1] == "ourcvfh_view_127"


def test_rotation_and_scale_invariance():
    p, n, _ = _box()
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    est = OURCVFHTransformer(min_points=10)
    a = est.fit_transform([np.hstack([p, n])])[0]
    b = est.transform([np.hstack([3.0 * p @ q.T + 1.0, n @ q.T])])[0]
    # the frame-based octant distribution is invariant to rounding
    assert_allclose(a[135:239], b[135:239], atol=1e-9)
    # the box's knife edges (f1 = +-pi for opposite faces, viewpoint cosine 0
    # on the faces along it) may flip a few bins in the other blocks
    assert np.abs(a - b).sum() < 0.3
    other = est.transform([np.hstack(_box((1.0, 1.0, 0.2))[:2])])[0]
    assert np.abs(a - other).sum() > 0.3


def test_threads_and_normal_estimation():
    p, n, _ = _box()
    clouds = [p, p * [1, 1.5, 1], np.hstack([p, n])]
    a = OURCVFHTransformer(min_points=10, n_jobs=1).fit_transform(clouds)
    b = OURCVFHTransformer(min_points=10, n_jobs=2).fit_transform(clouds)
    assert_array_equal(a, b)
    assert not np.allclose(a[0], a[1])


def test_scaling_fit_learns_one_factor():
    p, n, _ = _box()
    est = OURCVFHTransformer(scaling="fit", min_points=10).fit([p, 2 * p])
    assert_allclose(est.scale_, 0.5)
    assert OURCVFHTransformer().fit([p]).scale_ == 1.0


def test_no_cluster_falls_back_to_the_whole_object():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(60, 3))
    sigs, _, clusters = _ourcvfh_object(p, p / np.linalg.norm(p, axis=1, keepdims=True), min_points=1000)
    assert len(clusters) == 1 and len(clusters[0]) == 60 and sigs[0].shape == (308,)


def test_pipeline_and_grid_search():
    clouds, y = [], []
    for k in range(8):
        sides = (1.0, 0.9, 0.8) if k % 2 else (1.0, 0.3, 0.1)
        p, n, _ = _box(sides, per_face=8)
        clouds.append(np.hstack([p, n]))
        y.append(k % 2)
    pipe = make_pipeline(OURCVFHTransformer(min_points=5), KLNearestNeighbors())
    search = GridSearchCV(pipe, {"ourcvfhtransformer__aggregate": ["largest", "mean"]}, cv=2).fit(clouds, y)
    assert search.best_score_ > 0.8


@pytest.mark.parametrize(
    "params, err, msg",
    [
        ({"aggregate": "max"}, ValueError, "aggregate must be one of 'largest', 'first', 'mean', got 'max'"),
        ({"scaling": "unit"}, ValueError, "scaling must be one of 'object', 'fit', 'none', got 'unit'"),
        ({"curvature_threshold": 0.0}, ValueError, "curvature_threshold must be a float in (0.0, inf), got 0.0"),
        ({"eps_angle": 4.0}, ValueError, "eps_angle must be a float in (0.0, 3.141592653589793], got 4.0"),
        ({"eps_angle": "a"}, TypeError, "eps_angle must be a float in (0.0, 3.141592653589793], got 'a'"),
        ({"cluster_tolerance": -1.0}, ValueError, "cluster_tolerance must be None or a float in (0.0, inf), got -1.0"),
        ({"min_points": 0}, ValueError, "min_points must be an int >= 1, got 0"),
        ({"axis_ratio": 1.5}, ValueError, "axis_ratio must be a float in (0.0, 1.0], got 1.5"),
        ({"sigma": np.nan}, ValueError, "sigma must be a float in (0.0, inf), got nan"),
        ({"normalize": 1}, TypeError, "normalize must be True or False, got 1"),
        ({"n_neighbors": 2}, ValueError, "n_neighbors must be an int >= 3 (a plane needs three points), got 2"),
        ({"normal_orientation": "up"}, ValueError, "normal_orientation must be 'centroid', 'origin' or None, got 'up'"),
        ({"n_jobs": 0}, ValueError, "n_jobs must be None or a non-zero int (-1: all cores), got 0"),
    ],
)
def test_bad_parameters(params, err, msg):
    with pytest.raises(err, match=re.escape("OURCVFHTransformer: " + msg)):
        OURCVFHTransformer(**params).fit([_plane()[0]])


@pytest.mark.parametrize(
    "X, msg",
    [
        ([np.array([[0.0, 0, 0], [1, 0, 0]])], "point cloud 0 has 2 points; at least 3 are needed"),
        ([np.array([[0.0, 0, 0], [1, 0, 0], [0, np.nan, 0]])], "point cloud 0 contains NaN or infinite values"),
        ([np.ones((3, 2))], "point cloud 0 must have shape"),
        ([np.ones((3, 3))], "point cloud 0 has all 3 points identical"),
    ],
)
def test_bad_clouds(X, msg):
    with pytest.raises(ValueError, match=re.escape("OURCVFHTransformer: " + msg)):
        OURCVFHTransformer().fit(X)


def test_not_fitted():
    with pytest.raises(NotFittedError):
        OURCVFHTransformer().transform([_plane()[0]])
