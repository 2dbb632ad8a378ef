"""Tests of the synthetic shapes data set (eppf.datasets.make_shapes)."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import stats

from eppf.datasets import make_shapes
from eppf.datasets._synthetic import _CLASSES, _sample_surface

ALL_CLASSES = ["box", "sphere", "cylinder", "cone", "torus", "capsule", "pyramid", "bracket", "table", "chair"]
CONVEX = ["box", "sphere", "cylinder", "cone", "capsule", "pyramid"]
COMPOSITE = ["bracket", "table", "chair"]


def _clean(name, n_points=4000, **kw):
    """One noise-free, unoccluded object with normals."""
    params = dict(n_points=n_points, classes=[name], noise=0.0, occlusion=0.0, with_normals=True, random_state=1)
    params.update(kw)
    return make_shapes(1, **params).data[0]


def _fraction_close(count, total, p, n_sigma=4.0):
    """Whether count / total matches probability p within n_sigma binomial errors."""
    return abs(count / total - p) <= n_sigma * np.sqrt(p * (1 - p) / total)


def _fit_sphere_from_normals(cloud):
    """Least squares c, r in p = c + r n."""
    n = cloud.shape[0]
    design = np.zeros((3 * n, 4))
    design[:, :3] = np.tile(np.eye(3), (n, 1))
    design[:, 3] = cloud[:, 3:].ravel()
    sol, *_ = np.linalg.lstsq(design, cloud[:, :3].ravel(), rcond=None)
    resid = cloud[:, :3] - sol[:3] - sol[3] * cloud[:, 3:]
    return sol[:3], sol[3], resid


# --------------------------------------------------------------------------- #
# layout
# --------------------------------------------------------------------------- #
def test_default_layout():
    shapes = make_shapes()
    assert list(shapes.target_names) == ALL_CLASSES
    assert len(shapes.data) == 400 and shapes.target.shape == (400,) and shapes.split.shape == (400,)
    assert shapes.target.dtype == np.int64
    assert_array_equal(np.bincount(shapes.target), np.full(10, 40))
    assert all(c.shape == (1024, 3) and c.dtype == np.float64 and np.isfinite(c).all() for c in shapes.data)
    assert set(shapes.split) == {"train", "test"}
    for label in range(10):
        assert np.sum((shapes.target == label) & (shapes.split == "test")) == 10
    assert isinstance(shapes.DESCR, str) and "chair" in shapes.DESCR


def test_return_X_y_matches_bunch():
    shapes = make_shapes(3, n_points=64)
    X, y = make_shapes(3, n_points=64, return_X_y=True)
    assert_array_equal(y, shapes.target)
    assert len(X) == len(shapes.data)
    for a, b in zip(X, shapes.data):
        assert_array_equal(a, b)


@pytest.mark.parametrize("occlusion", [0.0, 0.2, 0.5, 0.9, 0.99])
@pytest.mark.parametrize("n_points", [2, 37, 256])
def test_exact_point_count(occlusion, n_points):
    X, _ = make_shapes(1, n_points=n_points, occlusion=occlusion, with_normals=True, return_X_y=True)
    assert [c.shape for c in X] == [(n_points, 6)] * 10


def test_class_subset_and_order():
    shapes = make_shapes(2, n_points=32, classes=["torus", "box", "chair"])
    assert list(shapes.target_names) == ["torus", "box", "chair"]
    assert_array_equal(shapes.target, [0, 0, 1, 1, 2, 2])
    # the torus (first class) is flat: one bounding-box side much shorter
    flat = make_shapes(1, n_points=500, classes=["torus"], rotate=False, noise=0.0).data[0]
    sides = np.sort(np.ptp(flat, axis=0))
    assert sides[0] < 0.5 * sides[1]


@pytest.mark.parametrize(
    "n_per_class, test_size, n_test",
    [(8, 0.0, 0), (8, 0.25, 2), (8, 0.5, 4), (8, 0.6, 5), (8, 0.99, 7), (2, 0.75, 1), (1, 0.9, 0)],
)
def test_split_is_stratified(n_per_class, test_size, n_test):
    shapes = make_shapes(n_per_class, n_points=16, test_size=test_size)
    for label in range(10):
        assert np.sum((shapes.target == label) & (shapes.split == "test")) == n_test
        assert np.sum((shapes.target == label) & (shapes.split == "train")) == n_per_class - n_test


def test_split_depends_on_seed():
    a, b = make_shapes(8, n_points=16, random_state=0), make_shapes(8, n_points=16, random_state=1)
    assert not np.array_equal(a.split, b.split)


# --------------------------------------------------------------------------- #
# determinism
# --------------------------------------------------------------------------- #
def test_same_seed_same_data_other_seed_other_data():
    a = make_shapes(2, n_points=100, random_state=7)
    b = make_shapes(2, n_points=100, random_state=7)
    c = make_shapes(2, n_points=100, random_state=8)
    assert all(np.array_equal(x, y) for x, y in zip(a.data, b.data))
    assert_array_equal(a.split, b.split)
    assert not any(np.allclose(x, y) for x, y in zip(a.data, c.data))
    # a RandomState instance is consumed as usual
    d = make_shapes(2, n_points=100, random_state=np.random.RandomState(7))
    assert all(np.array_equal(x, y) for x, y in zip(a.data, d.data))


def test_normals_do_not_change_the_points():
    a = make_shapes(2, n_points=100, with_normals=False)
    b = make_shapes(2, n_points=100, with_normals=True)
    for x, y in zip(a.data, b.data):
        assert x.shape[1] == 3 and y.shape[1] == 6
        assert_array_equal(x, y[:, :3])


# --------------------------------------------------------------------------- #
# geometry and normals
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("rotate", [True, "z", False])
def test_normals_are_unit(rotate):
    X, _ = make_shapes(2, n_points=200, with_normals=True, rotate=rotate, return_X_y=True)
    for cloud in X:
        assert_allclose(np.linalg.norm(cloud[:, 3:], axis=1), 1.0, atol=1e-12)


def test_sphere_normals_are_radial_and_outward():
    cloud = _clean("sphere", rotate=True, size_variation=0.3)
    center, radius, resid = _fit_sphere_from_normals(cloud)
    assert radius > 0.3  # positive: outward
    assert np.abs(resid).max() < 1e-12
    radial = cloud[:, :3] - center
    assert_allclose(cloud[:, 3:], radial / np.linalg.norm(radial, axis=1, keepdims=True), atol=1e-12)


@pytest.mark.parametrize("name", CONVEX)
@pytest.mark.parametrize("rotate", [True, False])
def test_convex_normals_give_supporting_planes(name, rotate):
    # for a convex surface the tangent plane at every point has the whole
    # object behind it, on the side opposite to the outward normal
    cloud = _clean(name, n_points=1500, rotate=rotate, size_variation=0.3)
    pts, nrm = cloud[:, :3], cloud[:, 3:]
    height = np.einsum("ik,jk->ij", nrm, pts) - np.einsum("ik,ik->i", nrm, pts)[:, None]
    assert height.max() < 1e-9
    # and the plane is tangent, not merely supporting: points crowd onto it
    assert np.all(np.sort(height, axis=1)[:, -2] > -0.05)


def test_torus_points_and_normals_match_implicit_surface():
    cloud = _clean("torus", n_points=20000, rotate=False, size_variation=0.0)
    pts, nrm = cloud[:, :3], cloud[:, 3:]
    minor = np.ptp(pts[:, 2]) / 2
    rho = np.hypot(pts[:, 0], pts[:, 1])
    major = rho.max() - minor
    assert_allclose(np.hypot(rho - major, pts[:, 2]), minor, atol=2e-3)
    expected = np.column_stack([(rho - major) * pts[:, 0] / rho, (rho - major) * pts[:, 1] / rho, pts[:, 2]])
    assert_allclose(nrm, expected / minor, atol=2e-2)


def _in_union(points, boxes):
    inside = np.zeros(len(points), dtype=bool)
    for center, half in boxes:
        inside |= np.all(np.abs(points - np.asarray(center)) <= np.asarray(half), axis=1)
    return inside


@pytest.mark.parametrize("name", COMPOSITE + ["box"])
def test_composites_sample_only_the_outer_surface(name):
    # just inside along -n lies the solid; just outside along +n lies nothing
    rng = np.random.RandomState(0)
    _, boxes = _CLASSES[name](lambda x: x * rng.uniform(0.85, 1.15))
    cloud = _sample_surface(None, boxes, 5000, rng)
    pts, nrm = cloud[:, :3], cloud[:, 3:]
    assert _in_union(pts - 1e-4 * nrm, boxes).all()
    assert not _in_union(pts + 1e-4 * nrm, boxes).any()
    # normals are axis-aligned for axis-aligned boxes
    assert_allclose(np.sort(np.abs(nrm), axis=1), np.tile([0.0, 0.0, 1.0], (5000, 1)))


# --------------------------------------------------------------------------- #
# area-weighted sampling (statistics on noise-free, axis-aligned objects)
# --------------------------------------------------------------------------- #
N = 20000


def test_sphere_height_is_uniform():
    # Archimedes: a sphere's area is spread uniformly along any axis
    cloud = _clean("sphere", n_points=N, rotate=False, size_variation=0.0)
    z = cloud[:, 2]
    r = np.ptp(z) / 2
    assert stats.kstest(z, stats.uniform(loc=-r, scale=2 * r).cdf).pvalue > 1e-3


def test_box_faces_by_area():
    cloud = _clean("box", n_points=N, rotate=False, size_variation=0.3)
    sides = np.ptp(cloud[:, :3], axis=0)
    areas = np.array([sides[1] * sides[2], sides[0] * sides[2], sides[0] * sides[1]])
    axis = np.argmax(np.abs(cloud[:, 3:]), axis=1)
    for a in range(3):
        assert _fraction_close(np.sum(axis == a), N, areas[a] / areas.sum())
    # on a face, the two free coordinates are uniform
    on_top = cloud[cloud[:, 5] > 0.5]
    assert_allclose(on_top[:, 2], cloud[:, 2].max())
    lo = cloud[:, 0].min()
    assert stats.kstest(on_top[:, 0], stats.uniform(loc=lo, scale=sides[0]).cdf).pvalue > 1e-3


def test_cylinder_caps_by_area():
    cloud = _clean("cylinder", n_points=N, rotate=False, size_variation=0.3)
    r, h = np.ptp(cloud[:, 0]) / 2, np.ptp(cloud[:, 2])
    caps = np.abs(cloud[:, 5]) > 0.5
    assert _fraction_close(caps.sum(), N, r / (r + h))
    # mantle points are uniform in height, cap points uniform over the disk
    z = cloud[~caps, 2]
    assert stats.kstest(z, stats.uniform(loc=z.min(), scale=h).cdf).pvalue > 1e-3
    rho2 = np.sum((cloud[caps, :2] - cloud[:, :2].mean(axis=0)) ** 2, axis=1) / r**2
    assert stats.kstest(rho2, "uniform").pvalue > 1e-3


def test_cone_mantle_by_area():
    cloud = _clean("cone", n_points=N, rotate=False, size_variation=0.3)
    base = cloud[:, 5] < -0.5
    mantle = cloud[~base]
    r = np.ptp(cloud[base, 0]) / 2
    # the normal of the mantle is (h cos, h sin, r) / s: recover the height exactly
    h = r * np.hypot(mantle[0, 3], mantle[0, 4]) / mantle[0, 5]
    s = np.hypot(r, h)
    assert _fraction_close(base.sum(), N, r / (r + s))
    # the mantle area above height z shrinks as (1 - z/h)^2
    above = mantle[:, 2] - cloud[base, 2].mean() > h / 2
    assert _fraction_close(above.sum(), len(mantle), 0.25)


def test_torus_outer_half_by_area():
    cloud = _clean("torus", n_points=N, rotate=False, size_variation=0.3)
    minor = np.ptp(cloud[:, 2]) / 2
    rho = np.hypot(cloud[:, 0], cloud[:, 1])
    major = rho.max() - minor
    outer = rho > major
    assert _fraction_close(outer.sum(), N, 0.5 + minor / (np.pi * major))


def test_capsule_mantle_by_area():
    cloud = _clean("capsule", n_points=N, rotate=False, size_variation=0.3)
    r = np.ptp(cloud[:, 0]) / 2
    h = np.ptp(cloud[:, 2]) - 2 * r
    mantle = np.abs(cloud[:, 5]) < 1e-12
    assert _fraction_close(mantle.sum(), N, h / (h + 2 * r))


def test_pyramid_faces_by_area():
    cloud = _clean("pyramid", n_points=N, rotate=False, size_variation=0.3)
    base = cloud[:, 5] < -0.5
    x, y = np.ptp(cloud[base, 0]) / 2, np.ptp(cloud[base, 1]) / 2
    # side normals are (0, +-h, y) / .. and (+-h, 0, x) / ..: recover h
    side = cloud[~base]
    k = np.argmax(np.abs(side[:, 4]))
    h = y * abs(side[k, 4]) / side[k, 5]
    areas = np.array([4 * x * y, 2 * x * np.hypot(y, h), 2 * y * np.hypot(x, h)])
    along_y = (~base) & (np.abs(cloud[:, 4]) > 1e-12)
    along_x = (~base) & (np.abs(cloud[:, 3]) > 1e-12)
    for count, area in zip([base.sum(), along_y.sum(), along_x.sum()], areas):
        assert _fraction_close(count, N, area / areas.sum())


def test_bracket_hidden_contact_is_not_sampled():
    cloud = _clean("bracket", n_points=N, rotate=False, size_variation=0.0)
    pts, nrm = cloud[:, :3], cloud[:, 3:]
    length, width, height = np.ptp(pts, axis=0)
    up = nrm[:, 2] > 0.5
    thick = pts[up, 2].min() - pts[:, 2].min()
    # the two boxes' surfaces less their shared contact rectangle, twice
    foot = 2 * (length * width + length * thick + width * thick)
    upright = 2 * (thick * width + thick * (height - thick) + width * (height - thick))
    visible = foot + upright - 2 * thick * width
    bottom = nrm[:, 2] < -0.5
    assert _fraction_close(bottom.sum(), N, length * width / visible)
    # nothing at the contact plane inside the upright's footprint
    x0 = pts[:, 0].min()
    contact = (np.abs(pts[:, 2] - (pts[:, 2].min() + thick)) < 1e-9) & (pts[:, 0] < x0 + thick - 1e-9)
    assert not contact.any()


# --------------------------------------------------------------------------- #
# perturbations inside make_shapes
# --------------------------------------------------------------------------- #
def test_occlusion_removes_the_far_hemisphere():
    full = _clean("sphere", n_points=4000, rotate=True)
    half = _clean("sphere", n_points=4000, rotate=True, occlusion=0.5)
    for cloud, offset in [(full, 0.0), (half, 0.5)]:
        center, radius, _ = _fit_sphere_from_normals(cloud)
        # the centroid of a hemisphere's surface sits r / 2 from the centre
        assert_allclose(np.linalg.norm(cloud[:, :3].mean(axis=0) - center) / radius, offset, atol=0.03)
    # all visible normals lie within a half-space around the view direction
    view = half[:, 3:].mean(axis=0)
    assert (half[:, 3:] @ (view / np.linalg.norm(view))).min() > -0.06


def test_noise_level():
    cloud = _clean("sphere", n_points=N, noise=0.02, rotate=False)
    _, _, resid = _fit_sphere_from_normals(cloud)
    assert_allclose(resid.std(axis=0), 0.02, rtol=0.05)


def test_rotation_options():
    kw = dict(n_points=300, classes=["box", "table"], noise=0.0, with_normals=True, return_X_y=True)
    upright, _ = make_shapes(3, rotate="z", **kw)
    aligned, _ = make_shapes(3, rotate=False, **kw)
    free, _ = make_shapes(3, rotate=True, **kw)
    for cloud in upright:
        assert_allclose(np.sort(np.abs(cloud[:, 5]))[[0, -1]], [0.0, 1.0], atol=1e-12)
        assert set(np.round(np.abs(cloud[:, 5]), 12)) == {0.0, 1.0}
    for cloud in aligned:
        assert_allclose(np.abs(cloud[:, 3:]).max(axis=1), 1.0)
    for cloud in free:
        assert np.abs(cloud[:, 5]).max() < 1 - 1e-6


def test_size_alone_does_not_separate_classes():
    X, y = make_shapes(20, n_points=200, noise=0.0, occlusion=0.0, rotate=False, return_X_y=True)
    size = np.array([np.ptp(c, axis=0).max() for c in X])
    lows = np.array([size[y == k].min() for k in range(10)])
    highs = np.array([size[y == k].max() for k in range(10)])
    # every class's size range overlaps every other's
    assert lows.max() < highs.min()
    # a sphere's diameter 1 varies by the scale (1 -+ 0.3) times the jitter
    # of its radius (1 -+ 0.15): wider than either factor alone
    spheres = size[y == 1]
    assert 0.7 * 0.85 <= spheres.min() and spheres.max() <= 1.3 * 1.15
    assert spheres.max() / spheres.min() > 1.15 / 0.85
    # without size variation a class's objects are congruent
    X0, y0 = make_shapes(5, n_points=2000, noise=0.0, occlusion=0.0, rotate=False, size_variation=0.0, return_X_y=True)
    for k in range(10):
        sides = np.array([np.ptp(c, axis=0) for c, t in zip(X0, y0) if t == k])
        assert np.ptp(sides, axis=0).max() < 0.05


# --------------------------------------------------------------------------- #
# parameter errors
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize(
    "kwargs, err, msg",
    [
        (dict(n_samples_per_class=0), ValueError, "make_shapes: n_samples_per_class must be an int >= 1, got 0"),
        (dict(n_samples_per_class=2.0), TypeError, "make_shapes: n_samples_per_class must be an int >= 1, got 2.0"),
        (dict(n_points=1), ValueError, "make_shapes: n_points must be an int >= 2, got 1"),
        (dict(n_points=True), TypeError, "make_shapes: n_points must be an int >= 2, got True"),
        (dict(noise=-0.01), ValueError, "make_shapes: noise must be a finite float >= 0, got -0.01"),
        (dict(noise=np.inf), ValueError, "make_shapes: noise must be a finite float >= 0, got inf"),
        (dict(occlusion=1.0), ValueError, "make_shapes: occlusion must be a float in [0, 0.99], got 1.0"),
        (dict(occlusion=0.995), ValueError, "make_shapes: occlusion must be a float in [0, 0.99], got 0.995"),
        (dict(occlusion=-0.1), ValueError, "make_shapes: occlusion must be a float in [0, 0.99], got -0.1"),
        (dict(size_variation=1.2), ValueError, "make_shapes: size_variation must be a float in [0, 1), got 1.2"),
        (dict(test_size=1.0), ValueError, "make_shapes: test_size must be a float in [0, 1), got 1.0"),
        (dict(rotate="y"), ValueError, "make_shapes: rotate must be True, False or 'z', got 'y'"),
        (dict(rotate=1), ValueError, "make_shapes: rotate must be True, False or 'z', got 1"),
        (dict(rotate=None), ValueError, "make_shapes: rotate must be True, False or 'z', got None"),
        (
            dict(classes=["box", "sofa"]),
            ValueError,
            "make_shapes: unknown class 'sofa'; choose from " + ", ".join(ALL_CLASSES),
        ),
        (dict(classes=[]), ValueError, "make_shapes: classes is empty; choose from box"),
        (dict(classes="box"), TypeError, "make_shapes: classes must be a list of class names, got str"),
        (dict(classes=["box", "box"]), ValueError, "make_shapes: classes contains duplicates: ['box', 'box']"),
    ],
)
def test_parameter_errors(kwargs, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        make_shapes(**kwargs)


def test_noise_beyond_float64_is_an_error():
    # noise=1e308 passed the parameter check and gave inf coordinates
    with pytest.raises(ValueError, match=re.escape("make_shapes: the noisy point cloud overflows float64")):
        make_shapes(1, n_points=20, classes=["box"], noise=1e308)


@pytest.mark.parametrize("kwargs", [{"n_points": 10**12}, {"n_samples_per_class": 10**8, "n_points": 64}])
def test_a_data_set_too_large_is_refused_before_drawing(kwargs):
    # NumPy's "Unable to allocate" (or a drawing loop that did not end) instead of an error naming make_shapes
    with pytest.raises(ValueError, match=r"make_shapes: .* points in all, more than the 1,000,000,000 a data set may hold"):
        make_shapes(**kwargs)
