"""Tests of the single-cloud perturbations in eppf.preprocessing._perturb."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import stats
from scipy.optimize import linprog
from scipy.spatial.distance import pdist
from scipy.spatial.transform import Rotation

from eppf.preprocessing._perturb import (
    add_gaussian_noise,
    occlude,
    random_dropout,
    random_rotation,
    random_rotation_matrix,
    random_scaling,
    resample,
    rotate,
    rotation_matrix,
    scale,
)


def _cloud(n=200, normals=True, seed=0):
    rng = np.random.RandomState(seed)
    pts = rng.normal(size=(n, 3)) * [1.0, 2.0, 0.5] + [3.0, -1.0, 2.0]
    if not normals:
        return pts
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return np.hstack([pts, nrm])


def _row_index(sub, full):
    """Position in ``full`` of every row of ``sub``, matched on the (distinct) coordinates."""
    lookup = {row[:3].tobytes(): i for i, row in enumerate(full)}
    return np.array([lookup[row[:3].tobytes()] for row in sub])


def _unit(axis):
    vec = {"x": [1.0, 0.0, 0.0], "y": [0.0, 1.0, 0.0], "z": [0.0, 0.0, 1.0]}[axis] if isinstance(axis, str) else axis
    vec = np.asarray(vec, dtype=float)
    return vec / np.linalg.norm(vec)


def _separable(a, b):
    """Whether a plane w.x = c strictly separates point sets a and b (an LP)."""
    # variables (w, c): w.a_i - c >= 1 and w.b_j - c <= -1
    a_ub = np.vstack([np.hstack([-a, np.ones((len(a), 1))]), np.hstack([b, -np.ones((len(b), 1))])])
    res = linprog(np.zeros(4), A_ub=a_ub, b_ub=-np.ones(len(a_ub)), bounds=[(None, None)] * 4)
    return res.status == 0


ALL = [
    lambda c, rs: add_gaussian_noise(c, 0.05, random_state=rs),
    lambda c, rs: occlude(c, 0.3, random_state=rs),
    lambda c, rs: random_dropout(c, 0.3, random_state=rs),
    lambda c, rs: random_rotation(c, random_state=rs),
    lambda c, rs: random_rotation(c, axis="z", random_state=rs),
    lambda c, rs: resample(c, 150, random_state=rs),
    lambda c, rs: resample(c, 350, random_state=rs),
    lambda c, rs: random_scaling(c, random_state=rs),
    lambda c, rs: random_scaling(c, 0.5, 2.0, anisotropic=False, random_state=rs),
]


# --------------------------------------------------------------------------- #
# common behaviour
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("func", ALL)
@pytest.mark.parametrize("normals", [False, True])
def test_deterministic_and_input_untouched(func, normals):
    cloud = _cloud(normals=normals)
    before = cloud.copy()
    a, b, c = func(cloud, 0), func(cloud, 0), func(cloud, 1)
    assert_array_equal(cloud, before)
    assert_array_equal(a, b)
    assert a.dtype == np.float64 and a.shape[1] == cloud.shape[1]
    assert not np.array_equal(a, c) or a.shape != c.shape


@pytest.mark.parametrize("func", ALL)
def test_normals_stay_unit_and_attached(func):
    cloud = _cloud(normals=True)
    out = func(cloud, 3)
    assert_allclose(np.linalg.norm(out[:, 3:], axis=1), 1.0)


@pytest.mark.parametrize(
    "func",
    [add_gaussian_noise, occlude, random_dropout, random_rotation, resample, random_scaling, scale],
)
@pytest.mark.parametrize(
    "cloud, msg",
    [
        (np.zeros((5, 4)), "must have shape (n_points, 3) or (n_points, 6), got shape (5, 4)"),
        (np.ones((1, 3)), "has 1 point; at least 2 are needed"),
        (np.array([[0.0, 0.0, np.nan], [1.0, 0.0, 0.0]]), "contains NaN or infinite values"),
        (np.zeros((4, 3)), "has all 4 points identical"),
        (np.hstack([np.eye(3), np.zeros((3, 3))]), "has 3 zero-length normal(s), first at point 0"),
    ],
)
def test_bad_cloud(func, cloud, msg):
    args = {resample: (10,), random_rotation: (), random_scaling: (), scale: (2.0,)}.get(func, (0.1,))
    with pytest.raises(ValueError, match=re.escape(f"{func.__name__}: point cloud {msg}")):
        func(cloud, *args)


# --------------------------------------------------------------------------- #
# noise
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("relative_to, scale", [("unit_cube", 4.0), ("none", 1.0)])
def test_noise_standard_deviation(relative_to, scale):
    # a cloud whose bounding box has largest side 4
    rng = np.random.RandomState(0)
    pts = rng.uniform(0.0, 1.0, size=(20000, 3)) * [4.0, 1.0, 2.0]
    pts[0], pts[1] = [0.0, 0.0, 0.0], [4.0, 1.0, 2.0]
    noisy = add_gaussian_noise(pts, 0.05, relative_to=relative_to, random_state=1)
    delta = noisy - pts
    assert_allclose(delta.mean(axis=0), 0.0, atol=4 * 0.05 * scale / np.sqrt(20000))
    assert_allclose(delta.std(axis=0), 0.05 * scale, rtol=0.03)
    # the noise is Gaussian
    assert stats.kstest(delta[:, 0] / (0.05 * scale), "norm").pvalue > 1e-3


def test_noise_leaves_normals_and_zero_sigma_copies():
    cloud = _cloud()
    noisy = add_gaussian_noise(cloud, 0.1, random_state=0)
    # normals are only renormalised by the validation
    assert_allclose(noisy[:, 3:], cloud[:, 3:], rtol=1e-14)
    assert not np.allclose(noisy[:, :3], cloud[:, :3])
    assert_allclose(add_gaussian_noise(cloud, 0.0, random_state=0), cloud, rtol=1e-14)


# --------------------------------------------------------------------------- #
# occlusion and dropout
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("fraction, n_removed", [(0.0, 0), (0.1, 20), (0.25, 50), (0.5, 100), (0.999, 198)])
@pytest.mark.parametrize("func", [occlude, random_dropout])
def test_removal_count(func, fraction, n_removed):
    cloud = _cloud(200)
    out = func(cloud, fraction, random_state=0)
    assert out.shape == (200 - n_removed, 6)
    # kept rows are original rows, in their original order, with their normals
    idx = _row_index(out, cloud)
    assert np.all(np.diff(idx) > 0)


def test_removal_rounds_to_nearest():
    cloud = _cloud(10)
    assert occlude(cloud, 0.34, direction="x").shape[0] == 7
    assert occlude(cloud, 0.36, direction="x").shape[0] == 6
    assert random_dropout(cloud, 0.34, random_state=0).shape[0] == 7


@pytest.mark.parametrize("direction", ["x", "z", [1.0, -2.0, 0.5], [0.0, 0.0, -3.0]])
def test_occlude_removes_far_side(direction):
    cloud = _cloud(300)
    out = occlude(cloud, 0.4, direction=direction)
    view = _unit(direction)
    removed = np.setdiff1d(np.arange(300), _row_index(out, cloud))
    assert removed.size == 120
    proj = cloud[:, :3] @ view
    # every removed point is farther from the viewer than every kept point
    assert proj[removed].max() <= np.delete(proj, removed).min()
    # the removed points are exactly the 120 farthest (a slow reference)
    assert_array_equal(np.sort(removed), np.sort(np.argsort(proj)[:120]))


def test_occlude_half_sphere_is_hemisphere():
    rng = np.random.RandomState(0)
    d = rng.normal(size=(4000, 3))
    sphere = d / np.linalg.norm(d, axis=1, keepdims=True)
    out = occlude(sphere, 0.5, direction=[0.0, 1.0, 0.0])
    assert out.shape[0] == 2000
    # the cut plane sits at the sample median of y, within sampling error of 0
    assert out[:, 1].min() > -0.05
    assert np.sum(sphere[:, 1] > 0.05) <= np.sum(out[:, 1] > 0.05)
    # the visible cap's centroid sits r / 2 towards the viewer
    assert_allclose(out.mean(axis=0), [0.0, 0.5, 0.0], atol=0.03)


@pytest.mark.parametrize("seed", range(5))
def test_occlude_random_direction_is_a_plane_cut(seed):
    cloud = _cloud(150, normals=False, seed=seed)
    out = occlude(cloud, 0.3, random_state=seed)
    kept = _row_index(out, cloud)
    removed = np.setdiff1d(np.arange(150), kept)
    assert _separable(cloud[kept], cloud[removed])
    # a random dropout is (almost surely) not a plane cut
    drop = _row_index(random_dropout(cloud, 0.3, random_state=seed), cloud)
    assert not _separable(cloud[drop], cloud[np.setdiff1d(np.arange(150), drop)])


def test_occlude_direction_changes_with_seed():
    cloud = _cloud(300)
    kept = [set(_row_index(occlude(cloud, 0.3, random_state=s), cloud)) for s in range(4)]
    assert len({frozenset(k) for k in kept}) == 4


def test_occlude_direction_ignores_random_state():
    cloud = _cloud()
    assert_array_equal(occlude(cloud, 0.3, direction="y", random_state=0), occlude(cloud, 0.3, direction="y", random_state=1))


def test_dropout_is_uniform():
    # every point is kept with probability 1 - fraction
    cloud = _cloud(20)
    counts = np.zeros(20)
    for seed in range(2000):
        counts[_row_index(random_dropout(cloud, 0.25, random_state=seed), cloud)] += 1
    assert stats.chisquare(counts).pvalue > 1e-3
    assert_allclose(counts.sum(), 2000 * 15)


# --------------------------------------------------------------------------- #
# resampling
# --------------------------------------------------------------------------- #
def test_resample_down_without_replacement():
    cloud = _cloud(100)
    out = resample(cloud, 60, random_state=0)
    idx = _row_index(out, cloud)
    assert np.unique(idx).size == 60


def test_resample_up_keeps_every_point():
    cloud = _cloud(100)
    out = resample(cloud, 250, random_state=0)
    idx = _row_index(out, cloud)
    counts = np.bincount(idx, minlength=100)
    assert out.shape == (250, 6) and counts.min() >= 1 and counts.sum() == 250


def test_resample_same_size_is_permutation():
    cloud = _cloud(100)
    out = resample(cloud, 100, random_state=0)
    assert_array_equal(np.sort(_row_index(out, cloud)), np.arange(100))


# --------------------------------------------------------------------------- #
# rotation
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("axis", ["x", "y", "z", [1.0, 2.0, -0.5]])
@pytest.mark.parametrize("angle", [0.0, 0.3, -2.0, np.pi])
def test_rotation_matrix_matches_scipy(axis, angle):
    vec = _unit(axis)
    assert_allclose(rotation_matrix(axis, angle), Rotation.from_rotvec(angle * vec).as_matrix(), atol=1e-12)


def test_rotation_matrix_hand_case():
    assert_allclose(rotation_matrix("z", np.pi / 2) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(rotation_matrix("x", np.pi / 2) @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-15)


@pytest.mark.parametrize("axis", [None, "z", [1.0, 1.0, 0.0]])
@pytest.mark.parametrize("center", ["centroid", "origin"])
def test_random_rotation_is_rigid_and_rotates_normals(axis, center):
    cloud = _cloud(80)
    out = random_rotation(cloud, axis=axis, center=center, random_state=0)
    assert_allclose(pdist(out[:, :3]), pdist(cloud[:, :3]), rtol=1e-10)
    # the same rotation acts on points and normals: with R found by
    # least squares from the normals, the centred points map by R too
    rot, *_ = np.linalg.lstsq(cloud[:, 3:], out[:, 3:], rcond=None)
    assert_allclose(out[:, 3:], cloud[:, 3:] @ rot, atol=1e-10)
    moved = out[:, :3] - out[:, :3].mean(axis=0)
    assert_allclose(moved, (cloud[:, :3] - cloud[:, :3].mean(axis=0)) @ rot, atol=1e-10)
    assert not np.allclose(rot, np.eye(3))
    if center == "centroid":
        assert_allclose(out[:, :3].mean(axis=0), cloud[:, :3].mean(axis=0), atol=1e-12)
    else:
        assert_allclose(np.linalg.norm(out[:, :3], axis=1), np.linalg.norm(cloud[:, :3], axis=1))
    if axis is not None:
        u = _unit(axis)
        assert_allclose(out[:, :3] @ u, cloud[:, :3] @ u, atol=1e-12)


def test_rotate_given_matrix():
    cloud = _cloud(30)
    rot = rotation_matrix("y", 0.7)
    out = rotate(cloud, rot, center="origin")
    assert_allclose(out[:, :3], cloud[:, :3] @ rot.T)
    assert_allclose(out[:, 3:], cloud[:, 3:] @ rot.T)


@pytest.mark.parametrize("seed", range(3))
def test_random_rotation_matrix_is_proper(seed):
    rot = random_rotation_matrix(random_state=seed)
    assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    assert_allclose(np.linalg.det(rot), 1.0)


def test_random_rotation_matrix_is_uniform():
    # under the Haar measure each column is uniform on the sphere: its z
    # component is uniform on [-1, 1], and the rotation angle has density
    # (1 - cos t) / pi on [0, pi]
    rs = np.random.RandomState(0)
    mats = np.array([random_rotation_matrix(random_state=rs) for _ in range(3000)])
    for col in range(3):
        assert stats.kstest(mats[:, 2, col], stats.uniform(loc=-1, scale=2).cdf).pvalue > 1e-3
    angle = np.arccos(np.clip((np.trace(mats, axis1=1, axis2=2) - 1) / 2, -1, 1))
    assert stats.kstest(angle, lambda t: (t - np.sin(t)) / np.pi).pvalue > 1e-3


def test_random_rotation_about_axis_is_uniform_angle():
    rs = np.random.RandomState(0)
    angles = []
    for _ in range(2000):
        rot = random_rotation_matrix(axis="z", random_state=rs)
        assert_allclose(rot[:, 2], [0, 0, 1], atol=1e-12)
        angles.append(np.arctan2(rot[1, 0], rot[0, 0]) % (2 * np.pi))
    assert stats.kstest(angles, stats.uniform(scale=2 * np.pi).cdf).pvalue > 1e-3


# --------------------------------------------------------------------------- #
# scaling
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("center", ["centroid", "origin"])
def test_scale_hand_case_and_normals_stay_perpendicular(center):
    # a tilted plane x + y + z = 1 with its normal; stretched, the points stay on
    # a plane whose normal the function must report
    rng = np.random.RandomState(0)
    uv = rng.uniform(-1, 1, size=(50, 2))
    pts = np.column_stack([uv[:, 0], uv[:, 1], 1.0 - uv.sum(axis=1)])
    nrm = np.tile(np.ones(3) / np.sqrt(3), (50, 1))
    factors = np.array([2.0, 0.5, 1.5])
    out = scale(np.hstack([pts, nrm]), factors, center=center)
    origin = pts.mean(axis=0) if center == "centroid" else np.zeros(3)
    assert_allclose(out[:, :3], (pts - origin) * factors + origin)
    assert_allclose(np.linalg.norm(out[:, 3:], axis=1), 1.0)
    # every difference of two stretched points is perpendicular to the new normal
    diffs = out[1:, :3] - out[0, :3]
    assert_allclose(diffs @ out[0, 3:], 0.0, atol=1e-12)
    expected = (1.0 / factors) / np.linalg.norm(1.0 / factors)
    assert_allclose(out[:, 3:], np.tile(expected, (50, 1)))


def test_scale_single_factor_keeps_normals_and_shape():
    cloud = _cloud()
    out = scale(cloud, 3.0)
    assert_allclose(out[:, 3:], cloud[:, 3:])
    assert_allclose(pdist(out[:, :3]), 3.0 * pdist(cloud[:, :3]))


@pytest.mark.parametrize("anisotropic", [True, False])
def test_random_scaling_factors_in_range_and_log_uniform(anisotropic):
    cloud = _cloud(normals=False)
    ratios = np.array(
        [np.ptp(random_scaling(cloud, 0.5, 2.0, anisotropic=anisotropic, random_state=s), axis=0) / np.ptp(cloud, axis=0)
         for s in range(400)]
    )
    assert ((ratios >= 0.5 - 1e-12) & (ratios <= 2.0 + 1e-12)).all()
    if anisotropic:
        assert np.std(ratios[:, 0] / ratios[:, 1]) > 0.1
    else:
        assert_allclose(ratios[:, 0], ratios[:, 1])
    # log-uniform on [ln 0.5, ln 2]: stretching and shrinking equally likely
    logs = np.log(ratios[:, 0])
    assert stats.kstest(logs, stats.uniform(loc=np.log(0.5), scale=np.log(4.0)).cdf).pvalue > 1e-3


def test_random_scaling_degenerate_range_is_exact():
    cloud = _cloud()
    assert_allclose(random_scaling(cloud, 1.5, 1.5, random_state=0), scale(cloud, 1.5))


# --------------------------------------------------------------------------- #
# parameter errors
# --------------------------------------------------------------------------- #
C = _cloud(20)


@pytest.mark.parametrize(
    "call, err, msg",
    [
        (lambda: add_gaussian_noise(C, -0.1), ValueError, "add_gaussian_noise: sigma must be a finite float >= 0, got -0.1"),
        (lambda: add_gaussian_noise(C, np.nan), ValueError, "add_gaussian_noise: sigma must be a finite float >= 0, got nan"),
        (lambda: add_gaussian_noise(C, "0.1"), TypeError, "add_gaussian_noise: sigma must be a finite float >= 0, got '0.1'"),
        (
            lambda: add_gaussian_noise(C, 0.1, relative_to="cube"),
            ValueError,
            "add_gaussian_noise: relative_to must be 'unit_cube' or 'none', got 'cube'",
        ),
        (lambda: occlude(C, 1.0), ValueError, "occlude: fraction must be a float in [0, 1), got 1.0"),
        (lambda: occlude(C, -0.2), ValueError, "occlude: fraction must be a float in [0, 1), got -0.2"),
        (lambda: occlude(C, True), TypeError, "occlude: fraction must be a float in [0, 1), got True"),
        (lambda: occlude(C, 0.2, direction=[0, 0, 0]), ValueError, "occlude: direction must be 'x', 'y', 'z' or a finite non-zero vector of length 3, got [0, 0, 0]"),
        (lambda: occlude(C, 0.2, direction=[1, 0]), ValueError, "occlude: direction must be 'x', 'y', 'z' or a finite non-zero vector of length 3, got [1, 0]"),
        (lambda: occlude(C, 0.2, direction=[1, np.inf, 0]), ValueError, "occlude: direction must be 'x', 'y', 'z' or a finite non-zero vector of length 3, got [1, inf, 0]"),
        (
            lambda: occlude(C, 0.2, direction="up"),
            ValueError,
            "occlude: direction must be 'x', 'y', 'z' or a finite non-zero vector of length 3, got 'up'",
        ),
        (lambda: random_dropout(C, 1.5), ValueError, "random_dropout: fraction must be a float in [0, 1), got 1.5"),
        (lambda: resample(C, 1), ValueError, "resample: n_points must be an int >= 2, got 1"),
        (lambda: resample(C, 10.0), TypeError, "resample: n_points must be an int >= 2, got 10.0"),
        (lambda: rotation_matrix("w", 0.1), ValueError, "rotation_matrix: axis must be 'x', 'y', 'z' or a finite non-zero vector of length 3, got 'w'"),
        (lambda: rotation_matrix("x", np.inf), ValueError, "rotation_matrix: angle must be a finite float, got inf"),
        (lambda: random_rotation(C, axis=[0, 0, 0]), ValueError, "random_rotation: axis must be 'x', 'y', 'z' or a finite non-zero vector of length 3, got [0, 0, 0]"),
        (
            lambda: random_rotation(C, center="mean"),
            ValueError,
            "random_rotation: center must be 'centroid' or 'origin', got 'mean'",
        ),
        (lambda: random_rotation_matrix(axis=[1, 2]), ValueError, "random_rotation_matrix: axis must be 'x', 'y', 'z' or a finite non-zero vector of length 3, got [1, 2]"),
        (lambda: rotate(C, np.eye(2)), ValueError, "rotate: rotation must be a proper rotation matrix (orthonormal, determinant +1) of shape (3, 3), got array([[1., 0.],\n       [0., 1.]])"),
        (
            lambda: rotate(C, np.diag([1.0, 1.0, -1.0])),
            ValueError,
            "rotate: rotation must be a proper rotation matrix (orthonormal, determinant +1)",
        ),
        (lambda: rotate(C, 2 * np.eye(3)), ValueError, "rotate: rotation must be a proper rotation matrix"),
        (lambda: rotate(C, np.full((3, 3), np.nan)), ValueError, "rotate: rotation must be a proper rotation matrix (orthonormal, determinant +1) of shape (3, 3), got array([[nan, nan, nan],"),
        (lambda: scale(C, [1.0, 0.0, 1.0]), ValueError, "scale: factors must be a finite number > 0 or a vector of length 3 of them, got [1.0, 0.0, 1.0]"),
        (lambda: scale(C, np.nan), ValueError, "scale: factors must be a finite number > 0 or a vector of length 3 of them, got nan"),
        (lambda: scale(C, [1.0, 2.0]), ValueError, "scale: factors must be a finite number > 0 or a vector of length 3 of them, got [1.0, 2.0]"),
        (lambda: scale(C, "big"), TypeError, "scale: factors must be a finite number > 0 or a vector of length 3 of them, got 'big'"),
        (lambda: scale(C, 2.0, center="mean"), ValueError, "scale: center must be 'centroid' or 'origin', got 'mean'"),
        (lambda: random_scaling(C, 1.25, 0.8), ValueError, "random_scaling: need 0 < low <= high, got low=1.25, high=0.8"),
        (lambda: random_scaling(C, 0.0, 1.0), ValueError, "random_scaling: low must be a finite float > 0, got 0.0"),
        (lambda: random_scaling(C, 0.8, np.inf), ValueError, "random_scaling: high must be a finite float > 0, got inf"),
        (lambda: random_scaling(C, anisotropic=1), TypeError, "random_scaling: anisotropic must be True or False, got 1"),
    ],
)
def test_parameter_errors(call, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        call()


def test_keeps_at_least_two_points():
    cloud = _cloud(3)
    assert occlude(cloud, 0.99, direction="x").shape[0] == 2
    assert random_dropout(cloud, 0.99, random_state=0).shape[0] == 2


_HUGE = np.array([[1e308, 1e308, 0.0], [-1e308, 1e308, 0.0], [0.0, -1e308, 1e308], [1e308, 0.0, -1e308]])


@pytest.mark.parametrize(
    "call, msg",
    [
        # the centroid's sum overflowed (NaN coordinates and NumPy warnings)
        (lambda: random_rotation(_HUGE, random_state=0), "random_rotation: the rotated point cloud overflows float64"),
        (lambda: rotate(_HUGE, rotation_matrix("z", 0.5)), "rotate: the rotated point cloud overflows float64"),
        # stretched beyond float64's range: inf coordinates came back
        (lambda: scale(_HUGE, 2.0, center="origin"), "scale: the stretched point cloud overflows float64"),
        (lambda: random_scaling(_HUGE, 2.0, 2.5, random_state=0), "random_scaling: the stretched point cloud overflows"),
        # normals divided by a factor near float64's smallest: inf / inf = NaN normals
        (lambda: scale(_cloud(10), [1e-310, 1.0, 1.0]), "scale: the stretched point cloud overflows float64"),
        # noise larger than float64 holds
        (lambda: add_gaussian_noise(_cloud(10), 1e308, relative_to="none", random_state=0), "add_gaussian_noise: the noisy"),
        (lambda: add_gaussian_noise(_HUGE, 1.0, random_state=0), "add_gaussian_noise: the noisy point cloud overflows"),
    ],
)
def test_overflow_is_an_error_not_inf_or_nan(call, msg):
    with np.errstate(all="raise"):  # and no NumPy warning on the way
        with pytest.raises(ValueError, match=re.escape(msg)):
            call()


def test_near_float64_limit_still_perturbed():
    # what does fit in float64 is perturbed as before, rigidly
    cloud = _HUGE * 0.25
    rotated = random_rotation(cloud, center="origin", random_state=0)
    assert_allclose(pdist(rotated), pdist(cloud), rtol=1e-12)
    assert np.isfinite(random_scaling(cloud, 1.1, 1.2, random_state=0)).all()
