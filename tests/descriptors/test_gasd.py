"""GASDTransformer: hand-computed grids, a NumPy reference, invariances, errors."""

import itertools
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from sklearn.exceptions import NotFittedError

from eppf.utils import _chunks
from eppf.descriptors._gasd import GASDTransformer, gasd_alignment
from eppf.descriptors._gasd_fast import eigen33_pcl


def _box():
    """A product cloud X x Y x Z, each factor heavier on one side (64 points).

    Centred factors: x' in {2, 2, 2, -6}, y' in {1.5, -0.5, -0.5, -0.5},
    z' in {0.25, 0.25, 0.25, -0.75}: the scatter is exactly diagonal
    (768, 48, 12), so the principal axes are the coordinate axes.
    """
    xs, ys, zs = [3.0, 3, 3, -5], [1.0, -1, -1, -1], [0.25, 0.25, 0.25, -0.75]
    return np.array(list(itertools.product(xs, ys, zs)))


def _cloud(n=400, seed=0):
    """A skewed, anisotropic cloud: well-separated eigenvalues and clear majorities."""
    rng = np.random.default_rng(seed)
    return rng.exponential(size=(n, 3)) * [3.0, 1.5, 0.6]


def _grid(cx, cy, cz):
    return np.einsum("i,j,k->ijk", cx, cy, cz).ravel()


def test_box_grid_pcl_signs():
    # PCL's solver returns +x and +z for a diagonal scatter; z . (0, 0, 1) > 0
    # flips z, and y = z x x = -y: the frame is diag(1, -1, -1).
    box = _box()
    est = GASDTransformer(half_grid_size=1, interpolation="none").fit([box])
    T = est.alignment_transforms([box])[0]
    np.testing.assert_allclose(T[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [-1.0, -0.5, 0.0], atol=1e-12)
    # aligned: x' (3 positive, 1 negative), -y' (3 positive), -z' (1 positive);
    # the largest |coordinate| is x' = -6, so no point sits on the +m face
    expected = _grid([1, 3], [1, 3], [3, 1]) * 100.0 / 63
    np.testing.assert_allclose(est.transform([box])[0], expected, rtol=1e-12)


def test_box_grid_majority_signs():
    box = _box()
    est = GASDTransformer(half_grid_size=1, interpolation="none", sign_convention="majority").fit([box])
    T = est.alignment_transforms([box])[0]
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [-1.0, 0.5, 0.0], atol=1e-12)
    # x and z toward their 3-point sides; y = z x x = +y (its 1-point side)
    expected = _grid([1, 3], [3, 1], [1, 3]) * 100.0 / 63
    np.testing.assert_allclose(est.transform([box])[0], expected, rtol=1e-12)


def test_view_direction_flips_z():
    box = _box()
    T = GASDTransformer(view_direction=(0, 0, -2.0)).fit([box]).alignment_transforms([box])[0]
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)  # z kept, y = z x x = +y


def test_point_on_the_far_face_is_dropped_without_interpolation():
    # PCL's grid index of a coordinate at +m is 2h, its padding cell.
    pts = np.array([[-1.0, -0.5, -0.25], [0.4, 0.2, 0.1], [0.6, 0.3, 0.15], [-0.1, 0.1, 0.1], [0.1, -0.1, -0.1]])
    est = GASDTransformer(half_grid_size=2, interpolation="none", sign_convention="majority").fit([pts])
    X = est.transform([pts])[0]
    aligned, _ = gasd_alignment(pts, sign_convention="majority")
    m = np.abs(aligned).max()
    on_face = np.isclose(aligned, m, rtol=0, atol=1e-12).any(axis=1)
    np.testing.assert_allclose(X.sum(), 100.0 / 4 * (len(pts) - on_face.sum()), rtol=1e-12)


def _reference(cloud, T, half, hs, interp):
    """PCL's grid, written out with its padded arrays, from a given frame."""
    q = cloud @ T[:3, :3].T + T[:3, 3]
    g = 2 * half
    hists = np.zeros((g + 2, g + 2, g + 2, hs + 2))
    m = np.abs(q).max()
    dmax = np.linalg.norm(q, axis=1).max()
    incr = 100.0 / (len(q) - 1)
    for p in q:
        t = np.linalg.norm(p) / (dmax / half)
        hb = (t - np.floor(t)) * hs
        s = (p / m) * half + half
        if interp != "none":
            s = s - 0.5
            hb = hb - 0.5
        b = np.floor(s).astype(int)
        h = int(np.floor(hb))
        if interp == "none":
            hists[b[0] + 1, b[1] + 1, b[2] + 1, h + 1] += incr
            continue
        f = s - b
        for a in itertools.product((0, 1), repeat=3):
            w = incr * np.prod([f[j] if a[j] else 1 - f[j] for j in range(3)])
            idx = (b[0] + 1 + a[0], b[1] + 1 + a[1], b[2] + 1 + a[2])
            if interp == "trilinear":
                hists[idx + (h + 1,)] += w
            else:
                ft = hb - h
                hists[idx + (h + 1,)] += w * (1 - ft)
                hists[idx + (h + 2,)] += w * ft
    return hists[1:-1, 1:-1, 1:-1, 1:-1].ravel()


@pytest.mark.parametrize("interp", ["none", "trilinear", "quadrilinear"])
@pytest.mark.parametrize("half, hs", [(4, 1), (2, 3)])
def test_matches_numpy_reference(interp, half, hs):
    clouds = [_cloud(150, seed) for seed in range(2)]
    est = GASDTransformer(half_grid_size=half, hists_size=hs, interpolation=interp).fit(clouds)
    X = est.transform(clouds)
    Ts = est.alignment_transforms(clouds)
    for c, row, T in zip(clouds, X, Ts):
        np.testing.assert_allclose(row, _reference(c, T, half, hs, interp), atol=1e-9)


def test_frame_is_pcas_with_pcl_sign():
    c = _cloud(500, 3)
    T = GASDTransformer().fit([c]).alignment_transforms([c])[0]
    R = T[:3, :3]
    _, vecs = np.linalg.eigh(np.cov(c.T))
    np.testing.assert_allclose(np.abs(R[0] @ vecs[:, 2]), 1.0, atol=1e-9)  # x: largest spread
    np.testing.assert_allclose(np.abs(R[2] @ vecs[:, 0]), 1.0, atol=1e-9)  # z: smallest
    assert R[2] @ [0.0, 0.0, 1.0] <= 0  # z against the view direction
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) > 0
    np.testing.assert_allclose(T[:3, :3] @ c.mean(axis=0) + T[:3, 3], 0.0, atol=1e-12)


def test_eigen33_solves_random_matrices():
    rng = np.random.default_rng(1)
    for _ in range(20):
        a = rng.normal(size=(3, 3))
        m = a @ a.T
        vals, vecs = eigen33_pcl(m)
        np.testing.assert_allclose(vals, np.linalg.eigvalsh(m), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(m @ vecs, vecs * vals, atol=1e-6 * vals.max())
        np.testing.assert_allclose(vecs.T @ vecs, np.eye(3), atol=1e-9)


def test_majority_is_invariant_to_rotation_and_translation():
    c = _cloud(400, 4)
    est = GASDTransformer(sign_convention="majority").fit([c])
    base = est.transform([c])[0]
    for seed in range(4):
        Q = Rotation.random(random_state=seed).as_matrix()
        moved = c @ Q.T + [5.0, -3.0, 2.0]
        np.testing.assert_allclose(est.transform([moved])[0], base, atol=1e-9)


def test_pcl_signs_vary_with_rotation_only_by_axis_flips():
    # The frame's axes are the same up to sign, so the grid is the original
    # one with x and/or z reversed (y follows as z x x).
    c = _cloud(400, 5)
    est = GASDTransformer().fit([c])
    base = est.transform([c])[0].reshape(8, 8, 8)
    np.testing.assert_allclose(est.transform([c + [7.0, 1.0, -4.0]])[0], base.ravel(), atol=1e-9)
    flips = [base, base[::-1, ::-1, :], base[:, ::-1, ::-1], base[::-1, :, ::-1]]
    seen = set()
    for seed in range(12):
        Q = Rotation.random(random_state=seed).as_matrix()
        row = est.transform([c @ Q.T])[0]
        match = [k for k, f in enumerate(flips) if np.allclose(row, f.ravel(), atol=1e-9)]
        assert len(match) == 1
        seen.add(match[0])
    assert len(seen) > 1  # the variance is real: not every rotation gives the same row


def test_layout_names_and_sums():
    clouds = [_cloud(200, s) for s in range(2)]
    est = GASDTransformer().fit(clouds)
    X = est.transform(clouds)
    assert X.shape == (2, 512) and est.n_features_out_ == 512
    assert (X >= 0).all() and (X.sum(axis=1) < 100.0 + 1e-9).all()
    names = est.get_feature_names_out()
    assert names[0] == "gasd_0_0_0" and names[1] == "gasd_0_0_1" and names[8] == "gasd_0_1_0" and len(names) == 512
    est3 = GASDTransformer(half_grid_size=2, hists_size=3).fit(clouds)
    assert est3.transform(clouds).shape == (2, 192)
    assert est3.get_feature_names_out()[:2].tolist() == ["gasd_0_0_0_0", "gasd_0_0_0_1"]
    # without interpolation every point but those on the +m faces counts 100 / (n - 1)
    Xn = GASDTransformer(interpolation="none").fit_transform(clouds)
    assert np.all(Xn.sum(axis=1) >= 100.0 * (200 - 3) / 199 - 1e-9)


def test_normals_are_ignored():
    c = _cloud(200, 6)
    with_normals = np.hstack([c, np.tile([0.0, 0.0, 1.0], (200, 1))])
    np.testing.assert_array_equal(GASDTransformer().fit_transform([c]), GASDTransformer().fit_transform([with_normals]))


def test_bit_identical_across_threads_and_chunks(monkeypatch):
    clouds = [_cloud(100 + 7 * s, s) for s in range(12)]
    base = GASDTransformer(n_jobs=1).fit_transform(clouds)
    np.testing.assert_array_equal(GASDTransformer(n_jobs=3).fit_transform(clouds), base)
    np.testing.assert_array_equal(GASDTransformer(n_jobs=1).fit_transform(clouds), base)
    monkeypatch.setattr(_chunks, "CHUNK", 5)
    np.testing.assert_array_equal(GASDTransformer(n_jobs=2).fit_transform(clouds), base)


def test_extreme_scales():
    c = _cloud(200, 7)
    base = GASDTransformer().fit_transform([c])
    np.testing.assert_allclose(GASDTransformer().fit_transform([c * 1e200]), base, atol=1e-9)
    np.testing.assert_allclose(GASDTransformer().fit_transform([c * 2.0**-1000]), base, atol=1e-9)
    tiny = GASDTransformer().fit_transform([c * 1e-310])  # subnormal coordinates: coarse but finite
    assert np.isfinite(tiny).all()
    with pytest.raises(ValueError, match="too far from the origin for a finite transform"):
        GASDTransformer().fit([c]).alignment_transforms([c * 1e300 + 1.7e308])


def test_two_points_and_collinear_clouds():
    line = np.outer(np.random.default_rng(0).uniform(size=30), [1.0, 2.0, 3.0])
    X = GASDTransformer().fit_transform([line])
    assert np.isfinite(X).all() and X.sum() > 0
    pair = np.array([[0.0, 0, 0], [1, 1, 1]])
    # both points at d_max: distance coordinate 0, below 1/2, so trilinear
    # GASD drops both (PCL's reading); without interpolation the point at
    # -m counts 100 / (2 - 1) and the one at +m falls in the padding
    np.testing.assert_array_equal(GASDTransformer().fit_transform([pair]), 0.0)
    Xn = GASDTransformer(interpolation="none").fit_transform([pair])
    assert Xn.sum() == 100.0 and np.count_nonzero(Xn) == 1


_VIEW_DIRECTION = "view_direction must be an array-like of 3 finite numbers, not all zero, got "


@pytest.mark.parametrize(
    "params, err, msg",
    [
        ({"half_grid_size": 0}, ValueError, "half_grid_size must be an int in [1, 64], got 0"),
        ({"half_grid_size": 2.0}, TypeError, "half_grid_size must be an int in [1, 64], got 2.0"),
        ({"hists_size": 0}, ValueError, "hists_size must be an int in [1, 1024], got 0"),
        ({"half_grid_size": 64, "hists_size": 10}, ValueError, "(half_grid_size, hists_size) must be a grid of at most 2**24 values ((2 half)**3 * hists), got (64, 10)"),
        ({"interpolation": "cubic"}, ValueError, "interpolation must be one of 'trilinear', 'none', 'quadrilinear', "
                                                 "got 'cubic'"),
        ({"sign_convention": "x"}, ValueError, "sign_convention must be 'pcl' or 'majority', got 'x'"),
        ({"view_direction": (0, 0, 0)}, ValueError, _VIEW_DIRECTION + "(0, 0, 0)"),
        ({"view_direction": (0, np.nan, 1)}, ValueError, _VIEW_DIRECTION + "(0, nan, 1)"),
        ({"view_direction": (0, 1)}, ValueError, _VIEW_DIRECTION + "(0, 1)"),
        ({"view_direction": "up"}, TypeError, "view_direction must be an array-like of 3 finite numbers, not all zero, "
                                              "got 'up'"),
        ({"n_jobs": 0}, ValueError, "n_jobs must be None or a non-zero int (-1: all cores), got 0"),
    ],
)
def test_bad_parameters(params, err, msg):
    with pytest.raises(err, match=re.escape("GASDTransformer: " + msg)):
        GASDTransformer(**params).fit([_cloud(20)])


@pytest.mark.parametrize(
    "X, err, msg",
    [
        ([np.array([[0.0, 0, 0]])], ValueError, "point cloud 0 has 1 point; at least 2 are needed"),
        ([np.zeros((0, 3))], ValueError, "point cloud 0 has 0 points"),
        ([np.array([[0.0, 0, 0], [1, 0, np.inf]])], ValueError, "point cloud 0 contains NaN or infinite values"),
        ([np.ones((3, 2))], ValueError, "point cloud 0 must have shape"),
        ([np.ones((3, 3))], ValueError, "point cloud 0 has all 3 points identical"),
        ([], ValueError, "X is empty"),
        ("cloud", TypeError, "X must be a list of point clouds"),
    ],
)
def test_bad_clouds(X, err, msg):
    with pytest.raises(err, match=re.escape("GASDTransformer: " + msg)):
        GASDTransformer().fit(X)


def test_not_fitted_and_tags():
    with pytest.raises(NotFittedError):
        GASDTransformer().transform([_cloud(20)])
    tags = GASDTransformer().__sklearn_tags__()
    assert tags.input_tags.three_d_array and not tags.input_tags.two_d_array


def test_gasd_alignment_helper():
    c = _cloud(300, 8) + [10.0, 0.0, -5.0]
    cn = np.hstack([c, np.tile([1.0, 0.0, 0.0], (300, 1))])
    aligned, T = gasd_alignment(cn)
    np.testing.assert_allclose(aligned[:, :3].mean(axis=0), 0.0, atol=1e-9)
    cov = np.cov(aligned[:, :3].T)
    np.testing.assert_allclose(cov - np.diag(np.diag(cov)), 0.0, atol=1e-9)
    assert cov[0, 0] > cov[1, 1] > cov[2, 2]
    np.testing.assert_allclose(aligned[:, 3:], np.tile(T[:3, 0], (300, 1)), atol=1e-12)


# --- colour variant --------------------------------------------------------

from eppf.descriptors._gasd import GASDColorTransformer, _hue  # noqa: E402


def test_hue_hand_computed():
    rgb = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [255, 0, 255], [10, 10, 10], [255, 0, 128]])
    # red 0, green 120, blue 240, yellow 60 (red is max first), magenta 300, grey 0,
    # (255, 0, 128): 60 * (0 - 128) / 255 + 360 = 329.88
    expected = np.array([0.0, 120, 240, 60, 300, 0, 360 - 60 * 128 / 255]) / 360
    np.testing.assert_allclose(_hue(rgb.astype(np.uint8)), expected, rtol=1e-6)


def test_color_box_hand_computed():
    box = _box()
    red = np.where(box[:, :1] > 0, [[255, 0, 0]], [[0, 0, 255]])  # x' > 0 red (hue bin 0), else blue (bin 8)
    est = GASDColorTransformer(shape_half_grid_size=1, color_half_grid_size=1).fit([np.hstack([box, red])])
    X = est.transform([np.hstack([box, red])])[0]
    assert X.shape == (8 + 8 * 12,) and est.n_features_out_ == 104
    np.testing.assert_allclose(X[:8], _grid([1, 3], [1, 3], [3, 1]) * 100.0 / 63, rtol=1e-12)
    color = X[8:].reshape(2, 2, 2, 12)
    counts = np.einsum("j,k->jk", [1, 3], [3, 1]) * 100.0 / 63
    np.testing.assert_allclose(color[1, :, :, 0], 3 * counts, rtol=1e-12)  # the three red +x copies
    np.testing.assert_allclose(color[0, :, :, 8], counts, rtol=1e-12)
    assert np.count_nonzero(color) == 8
    # normals in the middle columns are accepted and ignored
    nine = np.hstack([box, np.tile([0.0, 0.0, 1.0], (64, 1)), red])
    np.testing.assert_array_equal(est.transform([nine])[0], X)


def test_color_hue_wraps_around():
    c = _cloud(200, 9)
    rgb = np.tile([255, 21, 0], (200, 1))  # hue 60 * 21 / 255 = 4.94 degrees: coordinate 0.165 of 12
    X = GASDColorTransformer(color_interpolation="trilinear").fit_transform([np.hstack([c, rgb])])[0, 216:]
    per_bin = X.reshape(-1, 12).sum(axis=0)
    # interpolation shifts the coordinate by -1/2: below 0, PCL folds it onto the last bin
    assert per_bin[11] > 0 and np.count_nonzero(per_bin) == 1
    X = GASDColorTransformer(color_interpolation="quadrilinear").fit_transform([np.hstack([c, rgb])])[0, 216:]
    per_bin = X.reshape(-1, 12).sum(axis=0)
    t = 60 * 21 / 255 / 30 - 0.5 + 1  # fraction towards bin 0 from bin -1
    np.testing.assert_allclose(per_bin[0] / per_bin[11], t / (1 - t), rtol=1e-5)
    assert np.count_nonzero(per_bin) == 2


def test_color_bit_identical_and_names(monkeypatch):
    clouds = [np.hstack([_cloud(60 + 5 * s, s), np.random.default_rng(s).integers(0, 256, (60 + 5 * s, 3))])
              for s in range(9)]
    base = GASDColorTransformer(n_jobs=1).fit_transform(clouds)
    monkeypatch.setattr(_chunks, "CHUNK", 4)
    np.testing.assert_array_equal(GASDColorTransformer(n_jobs=2).fit_transform(clouds), base)
    names = GASDColorTransformer().fit(clouds).get_feature_names_out()
    assert len(names) == 984 and names[216] == "gasd_hue_0_0_0_0" and names[-1] == "gasd_hue_3_3_3_11"


@pytest.mark.parametrize(
    "X, err, msg",
    [
        ([np.ones((5, 3))], ValueError, "point cloud 0 must have shape (n_points, 6) (xyz, rgb) or (n_points, 9)"),
        ([np.hstack([_cloud(5), np.full((5, 3), 256.0)])], ValueError, "point cloud 0 has colours outside [0, 255]"),
        ([np.hstack([_cloud(5), np.full((5, 3), np.nan)])], ValueError, "point cloud 0 has colours outside [0, 255]"),
        ([np.array([[0.0, 0, np.inf, 1, 1, 1], [0, 0, 0, 1, 1, 1]])], ValueError, "point cloud 0 contains NaN or infinite values"),
        ([np.array([["a"] * 6])], TypeError, "point cloud 0 must hold real numbers"),
        ([np.hstack([_cloud(5), np.zeros((5, 3)), np.ones((5, 3))])], ValueError, "point cloud 0 has 5 zero-length"),
        ([], ValueError, "X is empty"),
        ("abc", TypeError, "X must be a list of (n_i, 6) or (n_i, 9) arrays"),
    ],
)
def test_color_bad_clouds(X, err, msg):
    with pytest.raises(err, match=re.escape("GASDColorTransformer: " + msg)):
        GASDColorTransformer().fit(X)


@pytest.mark.parametrize(
    "params, msg",
    [
        ({"color_hists_size": 0}, "color_hists_size must be an int in [1, 1024], got 0"),
        ({"color_interpolation": "linear"}, "color_interpolation must be one of 'trilinear', 'none', 'quadrilinear', "
                                            "got 'linear'"),
        ({"shape_half_grid_size": 65}, "shape_half_grid_size must be an int in [1, 64], got 65"),
    ],
)
def test_color_bad_parameters(params, msg):
    with pytest.raises(ValueError, match=re.escape("GASDColorTransformer: " + msg)):
        GASDColorTransformer(**params).fit([np.hstack([_cloud(5), np.zeros((5, 3))])])
