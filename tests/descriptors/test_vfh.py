"""VFHTransformer: hand-computed planes and spheres, a NumPy reference, invariances, errors."""

import itertools
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from sklearn.exceptions import NotFittedError

from eppf.utils import _chunks
from eppf.preprocessing._normals import estimate_normals
from eppf.descriptors._vfh import VFHTransformer

F1, F2, F3, F4, VIEW = slice(0, 45), slice(45, 90), slice(90, 135), slice(135, 180), slice(180, 308)


def _plane():
    """A 5 x 5 grid of spacing 1.25 at z = 2, normals +z; the centroid (2.5, 2.5, 2) is its middle point.

    Every coordinate and the centroid are exact in binary, so d = 0 at the middle.
    """
    xy = 1.25 * np.array(list(itertools.product(range(5), range(5))), dtype=float)
    pts = np.column_stack([xy, np.full(25, 2.0)])
    return np.hstack([pts, np.tile([0.0, 0.0, 1.0], (25, 1))])


def _sphere(n=1280):
    """Fibonacci points on the unit sphere, z = 1 - (2i + 1) / n, normals radial."""
    i = np.arange(n)
    z = 1.0 - (2 * i + 1) / n
    r = np.sqrt(1 - z * z)
    phi = i * np.pi * (3 - np.sqrt(5))
    p = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    return np.hstack([p, p])


def _cloud(n=300, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3)) * [2.0, 1.0, 0.5]
    nrm = rng.normal(size=(n, 3))
    return np.hstack([p, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)])


def test_plane_hand_computed():
    plane = _plane()
    X = VFHTransformer().fit_transform([plane])[0]
    # Every normal equals the mean normal and is perpendicular to d: no swap,
    # f1 = atan2(0, 1) = 0, f2 = f3 = 0, bin floor(45 * pi / (2 pi)) = 22; the
    # middle point (d = 0) is skipped: 24 pairs of 100 / 24.
    for part in (F1, F2, F3):
        expected = np.zeros(45)
        expected[22] = 100.0
        np.testing.assert_allclose(X[part], expected, rtol=1e-12)
    assert not X[F4].any()
    # v - c = (-2.5, -2.5, -2); PCL divides by sqrt(16.5 + 1): n . e = -0.47809,
    # alpha = (1 - 0.47809) / 2 = 0.26095, bin floor(128 alpha) = 33
    view = np.zeros(128)
    view[33] = 100.0
    np.testing.assert_allclose(X[VIEW], view, rtol=1e-12)
    # the paper's unit direction: n . e = -2 / sqrt(16.5) = -0.49237, alpha = 0.25381, bin 32
    Xu = VFHTransformer(pcl_homogeneous=False).fit_transform([plane])[0]
    view = np.zeros(128)
    view[32] = 100.0
    np.testing.assert_allclose(Xu[VIEW], view, rtol=1e-12)
    np.testing.assert_array_equal(Xu[:180], X[:180])


def test_plane_distance_component():
    plane = _plane()
    # PCL's round(100 d): every distance (1.25 to 1.25 sqrt 8) is above 44, so bin 44
    X = VFHTransformer(size_component=True).fit_transform([plane])[0]
    expected = np.zeros(45)
    expected[44] = 100.0
    np.testing.assert_allclose(X[F4], expected, rtol=1e-12)
    # normalised: floor(45 d / sqrt(d_max^2 + 1)) with d = 1.25 s, d_max^2 = 12.5:
    # 45 * 1.25 / sqrt(13.5) = 15.309 per unit of s, s = 1 (4 points) -> 15,
    # sqrt 2 (4) -> 21, 2 (4) -> 30, sqrt 5 (8) -> 34, sqrt 8 (4) -> 43
    X = VFHTransformer(size_component=True, normalize_distances=True).fit_transform([plane])[0]
    expected = np.zeros(45)
    for b, count in ((15, 4), (21, 4), (30, 4), (34, 8), (43, 4)):
        expected[b] = count * 100.0 / 24
    np.testing.assert_allclose(X[F4], expected, rtol=1e-12)
    # without PCL's w = 1: floor(45 s / sqrt 8): 15, 22 (22.5), 31, 35, 45 -> 44
    X = VFHTransformer(size_component=True, normalize_distances=True, pcl_homogeneous=False).fit_transform([plane])[0]
    expected = np.zeros(45)
    for b, count in ((15, 4), (22, 4), (31, 4), (35, 8), (44, 4)):
        expected[b] = count * 100.0 / 24
    np.testing.assert_allclose(X[F4], expected, rtol=1e-12)
    # raw counts
    X = VFHTransformer(normalize_bins=False).fit_transform([plane])[0]
    assert X[F1][22] == 24 and X[VIEW][33] == 25


def test_sphere_hand_computed():
    sphere = _sphere()
    n = len(sphere)
    X = VFHTransformer(viewpoint=(0.0, 0.0, 10.0), pcl_homogeneous=False).fit_transform([sphere])[0]
    # The mean normal nearly vanishes, every normal is parallel to d: the point
    # is the source, f3 = -n . d / |d| = -1 (bin floor(45 (pi - 1) / (2 pi)) = 15)
    # and f2 = v . mean normal ~ 0 (bin 22).
    valid = X[F3].sum() / (100.0 / (n - 1))
    assert round(valid) == n
    np.testing.assert_allclose(X[F3][15], X[F3].sum())
    np.testing.assert_allclose(X[F2][22], X[F2].sum())
    np.testing.assert_allclose(X[F1].sum(), X[F3].sum())
    # the direction to the viewpoint is +z: alpha = (z + 1) / 2 = 1 - (i + 0.5) / n,
    # exactly 10 points in each of the 128 bins
    np.testing.assert_allclose(X[VIEW], np.full(128, 10 * 100.0 / n), rtol=1e-12)
    # PCL's w = 1 scales the cosine by 10 / sqrt(101)
    Xh = VFHTransformer(viewpoint=(0.0, 0.0, 10.0)).fit_transform([sphere])[0]
    alpha = (sphere[:, 5] * 10 / np.sqrt(101) + 1) / 2
    expected = np.bincount(np.floor(alpha * 128).astype(int), minlength=128) * 100.0 / n
    np.testing.assert_allclose(Xh[VIEW], expected, rtol=1e-12)


def _reference(cloud, vp, normalize_bins=True, normalize_distances=False, size_component=False, homogeneous=True):
    """PCL's VFH written out point by point (double-precision centroid)."""
    p, nrm = cloud[:, :3], cloud[:, 3:]
    n = len(p)
    c, nc = p.mean(axis=0), nrm.mean(axis=0)
    hist = np.zeros(308)
    incr = 100.0 / (n - 1) if normalize_bins else 1.0
    dmax = np.linalg.norm(p - c, axis=1).max()
    dnorm = np.sqrt(dmax**2 + 1) if homogeneous else dmax
    for q, m in zip(p, nrm):
        d = q - c
        f4 = np.linalg.norm(d)
        if f4 == 0:
            continue
        a1, a2 = nc @ d / f4, m @ d / f4
        if np.arccos(abs(a1)) > np.arccos(abs(a2)):
            u, t, d, f3 = m, nc, -d, -a2
        else:
            u, t, f3 = nc, m, a1
        v = np.cross(d, u)
        if np.linalg.norm(v) == 0:
            continue
        v = v / np.linalg.norm(v)
        w = np.cross(u, v)
        f1, f2 = np.arctan2(w @ t, u @ t), v @ t
        for k, f in enumerate((f1, f2, f3)):
            hist[45 * k + min(max(int(np.floor(45 * (f + np.pi) / (2 * np.pi))), 0), 44)] += incr
        if size_component:
            b = np.floor(45 * f4 / dnorm) if normalize_distances else np.floor(100 * f4 + 0.5)
            hist[135 + int(min(max(b, 0), 44))] += incr
    e = vp - c
    e = e / (np.sqrt(e @ e + 1) if homogeneous else np.linalg.norm(e))
    alpha = (nrm @ e + 1) * 0.5
    b = np.clip(np.floor(alpha * 128), 0, 127).astype(int)
    hist[180:] = np.bincount(b, minlength=128) * (100.0 / n if normalize_bins else 1.0)
    return hist


@pytest.mark.parametrize(
    "flags",
    [
        {},
        {"normalize_bins": False},
        {"size_component": True},
        {"size_component": True, "normalize_distances": True},
        {"size_component": True, "normalize_distances": True, "pcl_homogeneous": False},
    ],
)
def test_matches_numpy_reference(flags):
    vp = np.array([3.0, -1.0, 2.0])
    clouds = [_cloud(150, s) for s in range(2)]
    X = VFHTransformer(viewpoint=vp, **flags).fit_transform(clouds)
    ref_flags = {k: v for k, v in flags.items() if k != "pcl_homogeneous"}
    for c, row in zip(clouds, X):
        ref = _reference(c, vp, homogeneous=flags.get("pcl_homogeneous", True), **ref_flags)
        np.testing.assert_allclose(row, ref, rtol=1e-12, atol=1e-12)


def test_pcl_centroid_rounding_decides_bins_63_64():
    # A centred cloud viewed from its centroid: PCL's single-precision centroid
    # noise splits the normals between bins 63 and 64 by the sign of n . c.
    c = _cloud(400, 3)
    c[:, :3] -= c[:, :3].mean(axis=0)
    p32 = c[:, :3].astype(np.float32)
    acc = np.zeros(3, dtype=np.float32)
    for q in p32:
        acc = acc + q
    cf = (acc / np.float32(len(c))).astype(np.float64)
    expected = np.zeros(128)
    expected[63] = np.sum(c[:, 3:] @ cf > 0) * 100.0 / len(c)  # n . (0 - c) < 0
    expected[64] = np.sum(c[:, 3:] @ cf <= 0) * 100.0 / len(c)
    X = VFHTransformer().fit_transform([c])[0]
    np.testing.assert_allclose(X[VIEW], expected, rtol=1e-12)
    assert 0 < expected[63] < 100
    Xd = VFHTransformer(pcl_centroid=False).fit_transform([c])[0]
    np.testing.assert_array_equal(Xd[:180], X[:180])


def test_angles_invariant_viewpoint_varies():
    c = _cloud(300, 4)
    vp = np.array([4.0, 1.0, -2.0])
    base = VFHTransformer(viewpoint=vp).fit_transform([c])[0]
    changed = 0
    for seed in range(4):
        Q = Rotation.random(random_state=seed).as_matrix()
        t = np.array([1.0, -2.0, 0.5])
        moved = np.hstack([c[:, :3] @ Q.T + t, c[:, 3:] @ Q.T])
        fixed = VFHTransformer(viewpoint=vp).fit_transform([moved])[0]
        np.testing.assert_allclose(fixed[:180], base[:180], atol=1e-9)
        # the viewpoint moving with the object: the whole row is invariant
        along = VFHTransformer(viewpoint=Q @ vp + t).fit_transform([moved])[0]
        np.testing.assert_allclose(along, base, atol=1e-9)
        changed += not np.allclose(fixed[VIEW], base[VIEW])
    assert changed == 4  # a fixed viewpoint sees the rotated object differently


def test_layout_names_sums_and_estimated_normals():
    clouds = [_cloud(200, s) for s in range(3)]
    est = VFHTransformer().fit(clouds)
    X = est.transform(clouds)
    assert X.shape == (3, 308) and est.n_features_out_ == 308
    np.testing.assert_allclose(X[:, VIEW].sum(axis=1), 100.0)
    for part in (F1, F2, F3):
        assert np.all(X[:, part].sum(axis=1) <= 100.0 * 200 / 199 + 1e-9)
        np.testing.assert_allclose(X[:, part].sum(axis=1), X[:, F1].sum(axis=1))
    assert not X[:, F4].any()
    names = est.get_feature_names_out()
    assert len(names) == 308 and names[0] == "vfh_f1_0" and names[135] == "vfh_f4_0" and names[-1] == "vfh_view_127"
    pts = clouds[0][:, :3]
    given = np.hstack([pts, estimate_normals(pts, 10, orientation="centroid")])
    np.testing.assert_array_equal(VFHTransformer().fit_transform([pts]), VFHTransformer().fit_transform([given]))


def test_bit_identical_across_threads_and_chunks(monkeypatch):
    clouds = [_cloud(80 + 9 * s, s) for s in range(12)]
    base = VFHTransformer(n_jobs=1).fit_transform(clouds)
    np.testing.assert_array_equal(VFHTransformer(n_jobs=3).fit_transform(clouds), base)
    np.testing.assert_array_equal(VFHTransformer(n_jobs=1).fit_transform(clouds), base)
    monkeypatch.setattr(_chunks, "CHUNK", 5)
    np.testing.assert_array_equal(VFHTransformer(n_jobs=2).fit_transform(clouds), base)


def test_extreme_scales():
    c = _cloud(200, 5)
    base = VFHTransformer(viewpoint=(1.0, 2.0, 3.0), pcl_homogeneous=False).fit_transform([c])[0]
    for s in (1e200, 2.0**-1000):
        scaled = np.hstack([c[:, :3] * s, c[:, 3:]])
        row = VFHTransformer(viewpoint=(s, 2 * s, 3 * s), pcl_homogeneous=False).fit_transform([scaled])[0]
        np.testing.assert_allclose(row, base, atol=1e-9)
    tiny = np.hstack([c[:, :3] * 1e-310, c[:, 3:]])
    assert np.isfinite(VFHTransformer().fit_transform([tiny])).all()


_VIEWPOINT = "viewpoint must be an array-like of 3 finite numbers of magnitude at most 1e+300, got "


@pytest.mark.parametrize(
    "params, err, msg",
    [
        ({"viewpoint": (0, 0)}, ValueError, _VIEWPOINT + "(0, 0)"),
        ({"viewpoint": (0, np.inf, 0)}, ValueError, _VIEWPOINT + "(0, inf, 0)"),
        ({"viewpoint": (0, 1e301, 0)}, ValueError, _VIEWPOINT + "(0, 1e+301, 0)"),
        ({"viewpoint": "here"}, TypeError, _VIEWPOINT + "'here'"),
        ({"normalize_bins": 1}, TypeError, "normalize_bins must be True or False, got 1"),
        ({"size_component": "yes"}, TypeError, "size_component must be True or False, got 'yes'"),
        ({"pcl_centroid": None}, TypeError, "pcl_centroid must be True or False, got None"),
        ({"n_neighbors": 2}, ValueError, "n_neighbors must be an int >= 3 (a plane needs three points), got 2"),
        ({"n_neighbors": 3.0}, TypeError, "n_neighbors must be an int >= 3 (a plane needs three points), got 3.0"),
        ({"normal_orientation": "up"}, ValueError, "normal_orientation must be 'centroid', 'origin' or None, got 'up'"),
        ({"n_jobs": 0}, ValueError, "n_jobs must be None or a non-zero int (-1: all cores), got 0"),
    ],
)
def test_bad_parameters(params, err, msg):
    with pytest.raises(err, match=re.escape("VFHTransformer: " + msg)):
        VFHTransformer(**params).fit([_cloud(20)])


@pytest.mark.parametrize(
    "X, err, msg",
    [
        ([np.array([[0.0, 0, 0, 0, 0, 1]])], ValueError, "point cloud 0 has 1 point; at least 2 are needed"),
        ([np.array([[0.0, 0, 0], [1, 0, 0]])], ValueError, "point cloud 0 has 2 points and no normals"),
        ([np.array([[0.0, 0, 0, 0, 0, 1], [1, 0, 0, 0, 0, 0]])], ValueError, "point cloud 0 has 1 zero-length normal"),
        ([np.array([[0.0, 0, 0], [1, np.nan, 0], [0, 1, 0]])], ValueError, "point cloud 0 contains NaN or infinite"),
        ([np.array([[0.0, 0, 0], [1e301, 0, 0], [0, 1, 0]])], ValueError, "point cloud 0 has coordinates of magnitude 1e+301"),
        ([np.ones((4, 4))], ValueError, "point cloud 0 must have shape"),
        ([np.ones((3, 3))], ValueError, "point cloud 0 has all 3 points identical"),
        ([], ValueError, "X is empty"),
        (None, TypeError, "X must be a list of point clouds"),
    ],
)
def test_bad_clouds(X, err, msg):
    with pytest.raises(err, match=re.escape("VFHTransformer: " + msg)):
        VFHTransformer().fit(X)


def test_not_fitted_and_tags():
    with pytest.raises(NotFittedError):
        VFHTransformer().transform([_cloud(20)])
    tags = VFHTransformer().__sklearn_tags__()
    assert tags.input_tags.three_d_array and not tags.input_tags.two_d_array
