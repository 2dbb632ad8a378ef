"""remove_ground on analytic scenes: floors, tilted planes, hills, nothing but ground."""

import warnings

import numpy as np
import pytest

from eppf.segmentation import remove_ground
from eppf.segmentation._cluster import default_tolerance
from eppf.segmentation._ground import _plane_ransac, ground_mask
from tests.segmentation.conftest import floor, sphere


def _scene(height=None, noise=0.01, rng=None):
    """A 20 m square of terrain (20,000 points) and 4 boxes of 400 points standing 0.3 m to 1.3 m above it."""
    rng = rng or np.random.default_rng(0)
    ground = floor(20.0, 20000, rng, noise=noise, height=height)
    boxes = []
    for cx, cy in ((4, 4), (4, 16), (16, 4), (16, 16)):
        box = rng.uniform([cx - 0.5, cy - 0.5, 0.3], [cx + 0.5, cy + 0.5, 1.3], size=(400, 3))
        if height is not None:
            box[:, 2] += height(box[:, 0], box[:, 1])
        boxes.append(box)
    return np.vstack([ground] + boxes), len(ground)


@pytest.mark.parametrize("method", ["auto", "plane", "grid"])
def test_flat_floor(method):
    points, n_ground = _scene()
    mask = remove_ground(points, method=method)
    assert mask[:n_ground].mean() > 0.999
    assert not mask[n_ground:].any()


@pytest.mark.parametrize("method", ["auto", "plane"])
def test_tilted_plane_in_any_orientation(method):
    points, n_ground = _scene(height=lambda x, y: 0.4 * x - 0.2 * y)
    assert remove_ground(points, method=method)[:n_ground].mean() > 0.999
    # the scene on its side (ground plane x = const): RANSAC finds it all the same
    rotated = points[:, [2, 0, 1]]
    mask = remove_ground(rotated, method="plane")
    assert mask[:n_ground].mean() > 0.999 and mask[n_ground:].mean() < 0.05


def test_hills_need_the_grid_and_auto_chooses_it():
    gentle = lambda x, y: 0.8 * np.sin(x / 4.0) * np.cos(y / 5.0)  # slopes below 0.3
    points, n_ground = _scene(height=gentle)
    plane = remove_ground(points, method="plane")
    grid = remove_ground(points, method="grid")
    auto = remove_ground(points)
    assert plane[:n_ground].mean() < 0.9  # one plane cannot follow the hills
    assert grid[:n_ground].mean() > 0.99 and grid[n_ground:].mean() < 0.05
    np.testing.assert_array_equal(auto, grid)


def test_auto_reports_its_choice():
    flat, _ = _scene()
    hilly, _ = _scene(height=lambda x, y: 0.8 * np.sin(x / 4.0) * np.cos(y / 5.0))
    for points, expected in ((flat, "plane"), (hilly, "grid")):
        _, method = ground_mask(points, "auto", None, 0.3, 0.3, 100, np.random.RandomState(0))
        assert method == expected


@pytest.mark.parametrize("method", ["auto", "plane", "grid"])
def test_all_ground(method):
    points = floor(10.0, 5000, np.random.default_rng(1), noise=0.005)
    assert remove_ground(points, method=method).all()


def test_the_plane_threshold_follows_the_noise():
    rng = np.random.default_rng(2)
    ground = floor(10.0, 20000, rng, noise=0.01)
    ball = sphere((5, 5, 0.5), 0.5, 2000, rng)  # touches the floor at its bottom
    mask = remove_ground(np.vstack([ground, ball]), method="plane")
    kept = ball[~mask[len(ground):]]
    # four robust standard deviations of the noise (0.04) at most, and at least a quarter of the tolerance
    assert mask[:len(ground)].mean() > 0.999
    assert 0.02 < kept[:, 2].min() < 0.08
    # a given threshold is used as it is
    mask = remove_ground(np.vstack([ground, ball]), method="plane", threshold=0.2)
    assert ball[~mask[len(ground):], 2].min() >= 0.2 - 0.03


def _objects_on_a_floor(rng, noise):
    """An 8 m floor (6,400 points, truth -1) and as many points again on 8 objects standing on it (truth 0-7),
    their lowest parts within a point spacing of the floor: 4 boxes with a bottom plate at the floor's height,
    4 L-brackets (a plate on the floor and a plate standing on its edge); normal noise of standard deviation
    ``noise`` on every coordinate of the objects and on the floor's heights."""
    parts, truth = [floor(8.0, 6400, rng, noise=noise)], [np.full(6400, -1)]
    for k in range(8):
        x, y = 1.0 + 2.0 * (k % 4), 2.0 + 4.0 * (k // 4)
        if k < 4:  # a box 1 m wide and 0.5 m high: walls, top and bottom
            cloud = rng.uniform([-0.5, -0.5, 0.0], [0.5, 0.5, 0.5], size=(800, 3))
            face = rng.integers(0, 6, 800)
            cloud[face < 4, face[face < 4] // 2] = np.where(face[face < 4] % 2, 0.5, -0.5)
            cloud[face == 4, 2], cloud[face == 5, 2] = 0.0, 0.5
        else:  # an L-bracket: a 1 m x 0.6 m plate on the floor, another standing on its edge
            cloud = rng.uniform([-0.5, -0.3, 0.0], [0.5, 0.3, 0.6], size=(800, 3))
            cloud[:400, 2] = 0.0
            cloud[400:, 1] = -0.3
        parts.append(cloud + [x, y, 0.0] + rng.normal(0, noise, cloud.shape))  # the scanner's noise
        truth.append(np.full(800, k))
    return np.vstack(parts), np.concatenate(truth)


def test_the_objects_lowest_parts_neither_lift_nor_widen_the_plane():
    # within the tolerance of the plane lie the objects' lowest parts, as many points as the floor's: the
    # least-squares refit and the noise under the plane leave them out
    noise = 0.01
    points, truth = _objects_on_a_floor(np.random.default_rng(6), noise)
    tolerance = default_tolerance(points, "test")
    assert tolerance > 10 * noise  # the objects' lowest 10 cm within RANSAC's inlier distance
    nrm, offset, sigma = _plane_ransac(points, tolerance, 100, np.random.RandomState(0))
    assert nrm[2] > 1 - 1e-6 and abs(offset) < 0.2 * noise
    assert 0.9 * noise < sigma < 1.1 * noise
    mask = remove_ground(points, method="plane")
    assert mask[truth == -1].mean() > 0.999
    # the objects keep all but their lowest 5 cm (four standard deviations of the noise, and the offset)
    objects, height = ~mask[truth >= 0], points[truth >= 0, 2]
    assert objects[height > 5 * noise].all() and not objects[height < 3 * noise].any()
    # the limit: a plate lying on the floor is taken for ground, the bracket keeps its standing plate
    for k in range(4, 8):
        bracket = ~mask[truth == k]
        assert not bracket[:400].any() and bracket[400:].mean() > 0.9


def test_noise_below_the_floor_is_ground():
    rng = np.random.default_rng(3)
    ground = floor(10.0, 10000, rng, noise=0.005)
    below = np.column_stack([rng.uniform(0, 10, (50, 2)), rng.uniform(-2, -1, 50)])
    objects = rng.uniform([2, 2, 0.5], [4, 4, 2.0], size=(500, 3))
    mask = remove_ground(np.vstack([ground, below, objects]), method="plane")
    assert mask[:10050].all() and not mask[10050:].any()


def test_auto_keeps_the_objects_above_a_floor_with_more_low_noise_under_it():
    # the plane's "above" was the side holding more points off it: 50 low points under a floor outnumbered a
    # box of 40 points, the box was taken for ground and the low points for objects; auto, which keeps the
    # plane only where the lowest surface along z lies on it, now turns it up
    rng = np.random.default_rng(3)
    ground = floor(10.0, 10000, rng, noise=0.005)
    below = np.column_stack([rng.uniform(0, 10, (50, 2)), rng.uniform(-2, -1, 50)])
    box = rng.uniform([2, 2, 0.5], [3, 3, 2.0], size=(40, 3))
    mask, used = ground_mask(np.vstack([ground, below, box]), "auto", None, 0.2, 0.3, 100, np.random.RandomState(0))
    assert used == "plane" and mask[:10050].all() and not mask[10050:].any()


def test_deterministic_and_seeded():
    points, _ = _scene(height=lambda x, y: 0.1 * x)
    first = remove_ground(points, method="plane")
    np.testing.assert_array_equal(remove_ground(points, method="plane"), first)
    np.testing.assert_array_equal(remove_ground(points, method="plane", random_state=np.random.RandomState(0)), first)


def test_wide_scene_with_a_tiny_threshold_keeps_the_grid_bounded():
    rng = np.random.default_rng(4)
    points = np.column_stack([rng.uniform(0, 1e6, (2000, 2)), rng.normal(0, 1e-3, 2000)])
    mask = remove_ground(points, method="grid", threshold=1e-3)  # 1e18 cells asked: the grid widens its cells
    assert mask.mean() > 0.99


@pytest.mark.parametrize("scale", [1e-90, 1e90])
def test_the_plane_does_not_depend_on_the_scale(scale):
    # within the extents check_scene accepts (1e-100 to 1e100): the hypotheses' normals once came from cross
    # products whose squared components underflowed to 0 (every triple taken for collinear) or overflowed
    rng = np.random.default_rng(6)
    ground = floor(10.0, 400, rng)
    box = rng.uniform([4, 4, 1.0], [5, 5, 2.0], size=(100, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mask = remove_ground(np.vstack([ground, box]) * scale, method="plane", threshold=0.1 * scale)
    assert mask[:400].all() and not mask[400:].any()


@pytest.mark.parametrize("kwargs, kind, pattern", [
    (dict(method="ransac"), ValueError, r"method must be one of 'auto', 'plane', 'grid', got 'ransac'"),
    (dict(threshold=0), ValueError, r"threshold must be None or a float in \(0.0, inf\)"),
    (dict(max_slope=-1), ValueError, r"max_slope must be a float in \[0.0, inf\)"),
    (dict(n_trials=0), ValueError, r"n_trials must be an int in \[1, 100000\]"),
    (dict(random_state="x"), TypeError, r"random_state must be"),
])
def test_bad_parameters_are_named(kwargs, kind, pattern):
    with pytest.raises(kind, match=r"^remove_ground: " + pattern):
        remove_ground(np.eye(3), **kwargs)


@pytest.mark.parametrize("points, pattern", [
    (np.empty((0, 3)), r"has 0 points"),
    (np.zeros((1, 3)), r"has 1 point"),
    (np.array([[0, 0, 0], [np.nan, 1, 1]]), r"NaN"),
])
def test_bad_scenes_are_named(points, pattern):
    with pytest.raises(ValueError, match=r"^remove_ground: .*" + pattern):
        remove_ground(points)


def test_slope_envelope_is_the_exact_chamfer_envelope():
    from eppf.segmentation import _cluster_fast

    rng = np.random.default_rng(5)
    zmin = rng.uniform(0, 5, size=(9, 13))
    zmin[rng.random(zmin.shape) < 0.3] = np.inf  # empty cells
    step, diagonal = 0.3, 0.3 * np.sqrt(2)
    surface = zmin.copy()
    _cluster_fast.slope_envelope(surface, step, diagonal)
    i, j = np.indices(zmin.shape)
    expected = np.empty_like(zmin)
    for a in range(zmin.shape[0]):
        for b in range(zmin.shape[1]):
            di, dj = np.abs(i - a), np.abs(j - b)
            chamfer = (np.maximum(di, dj) - np.minimum(di, dj)) * step + np.minimum(di, dj) * diagonal
            expected[a, b] = np.min(zmin + chamfer)
    np.testing.assert_allclose(surface, expected, rtol=1e-12)


def test_ransac_subset_of_a_big_scene_takes_memory_of_the_subset_only(monkeypatch):
    # the 50,000 points RANSAC scores its planes on were the head of a permutation of the whole scene: 8 bytes
    # a point (800 MB at 10^8 points) for a subset of 400 KB
    import tracemalloc

    from eppf.segmentation import _ground

    monkeypatch.setattr(_ground, "_RANSAC_SAMPLE", 200)
    monkeypatch.setattr(_ground, "_PERMUTED", 800, raising=False)
    rng = np.random.default_rng(7)
    points = np.column_stack([rng.uniform(0, 100, (10**6, 2)), np.zeros(10**6)])
    tracemalloc.start()
    try:
        nrm, offset, _ = _plane_ransac(points, 0.1, 20, np.random.RandomState(0))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10**6  # the permutation took 8 MB
    np.testing.assert_allclose(np.abs(nrm), [0, 0, 1], atol=1e-12)
    assert abs(offset) < 1e-12


def test_ransac_subset_is_distinct_uniform_and_seeded():
    from eppf.segmentation._ground import _PERMUTED, _subset

    n, k = 10**7, 5000
    first = _subset(n, k, np.random.RandomState(3))
    np.testing.assert_array_equal(_subset(n, k, np.random.RandomState(3)), first)  # same seed, same subset
    assert not np.array_equal(_subset(n, k, np.random.RandomState(4)), first)
    assert len(np.unique(first)) == k and first[0] >= 0 and first[-1] < n and (np.diff(first) > 0).all()
    # uniform: as many in each tenth of the range, within six standard deviations of the binomial's 500
    counts = np.bincount(first * 10 // n, minlength=10)
    assert np.abs(counts - k / 10).max() < 6 * np.sqrt(k * 0.1 * 0.9)
    # a scene just over the subset: every index but a few, still distinct
    assert len(np.unique(_subset(k + 3, k, np.random.RandomState(0)))) == k
    # up to _PERMUTED points, the subset of the earlier draw: those scenes keep their ground
    for m in (k + 1, _PERMUTED):
        np.testing.assert_array_equal(_subset(m, k, np.random.RandomState(5)),
                                      np.sort(np.random.RandomState(5).choice(m, k, replace=False)))
    assert len(np.unique(_subset(_PERMUTED + 1, 50000, np.random.RandomState(0)))) == 50000


def test_no_slope_limit_raises_no_overflow_warning():
    # max_slope over a flat surface's slope (max_slope / 1e-300) overflowed for max_slope near 1e308
    points, _ = _scene()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mask = remove_ground(points, method="grid", max_slope=1e308)
    np.testing.assert_array_equal(mask, remove_ground(points, method="grid", max_slope=1e6))


@pytest.mark.parametrize("method", ["grid", "auto"])
def test_stray_points_far_away_leave_the_grid_ground_as_it_was(method):
    # a point 1e12 away made the grid's cells 1e9 wide (four cells a point at most): the whole scene in one
    # cell, ground 9325 of 20,000 floor points and no object left apart; now each far run has its own grid
    points, n_ground = _scene(height=lambda x, y: np.sin(x / 3) * 2 + 0.1 * y)
    stray = np.array([[1e12, 0, 0], [0, -1e12, 0.5], [3e3, 3e3, 0], [1e12, 1e12, 2.0]])
    alone = remove_ground(points, method=method, threshold=0.3)
    mask = remove_ground(np.vstack([points, stray]), method=method, threshold=0.3)
    np.testing.assert_array_equal(mask[:len(points)], alone)
    assert mask[len(points):].all()  # each the lowest point of its own grid
    flat, _ = _scene()
    mask = remove_ground(np.vstack([flat, [[1e12, 0, 0]]]), method=method)
    assert mask[:n_ground].all() and not mask[n_ground:-1].any()


def _low_noise(kind, depth, rng):
    """Low noise (multipath returns) ``depth`` under the ground of :func:`_scene` at z = 0: one point, five
    points apart, or a clump of three points within 2 cm."""
    if kind == "one":
        xy = np.array([[10.3, 10.2]])
    elif kind == "five":
        xy = np.array([[2.5, 10.0], [10.0, 2.5], [10.2, 10.1], [17.5, 10.0], [9.0, 17.5]])
    else:
        xy = np.array([7.1, 12.3]) + rng.uniform(-0.01, 0.01, (3, 2))
    return np.column_stack([xy, np.full(len(xy), depth) + rng.uniform(-0.01, 0.01, len(xy))])


@pytest.mark.parametrize("kind", ["one", "five", "clump"])
@pytest.mark.parametrize("depth", [-0.5, -50.0, -1e12])
@pytest.mark.parametrize("method", ["grid", "auto"])
def test_low_noise_leaves_the_ground_as_it_was(method, depth, kind):
    # a point 50 m under the floor pulled the grid's surface down around it (0.3 m a cell): every floor point
    # rose above the threshold and none was ground, and "auto", whose grid cells no longer lay on the plane,
    # chose the grid; now points with fewer than three others within reach of a slope-limited surface
    # through them (in their cell and the adjacent ones) are low noise, left out of the cells' lowest
    # heights, and ground as the points under the plane are
    # the scene of _scene on a 10 m square (spacing 7 cm, tolerance 0.17 m): a surface reaching from the
    # ground 0.5 m down within the cells around (0.3 a cell and the threshold) would be a real dip
    points, n_ground = _scene()
    points[:, :2] *= 0.5
    noise = _low_noise(kind, depth, np.random.default_rng(1))
    noise[:, :2] *= 0.5
    tolerance = default_tolerance(points)  # the same for both (one point more shifts its sample of the scene)
    alone, used = ground_mask(points, method, None, tolerance, 0.3, 100, np.random.RandomState(0))
    scene = np.vstack([points, noise])
    mask, with_noise = ground_mask(scene, method, None, tolerance, 0.3, 100, np.random.RandomState(0))
    np.testing.assert_array_equal(mask[:len(points)], alone)
    assert mask[len(points):].all() and with_noise == used
    assert alone[:n_ground].mean() > 0.999 and not alone[n_ground:].any()


@pytest.mark.parametrize("method", ["grid", "auto"])
def test_low_noise_on_hills_and_a_ditch_that_is_ground(method):
    # the grid on terrain that is not a plane, low noise under it; and a ditch 0.6 m deep (real low terrain,
    # many points) still followed as ground
    hills = lambda x, y: np.sin(x / 6) * 0.8 + 0.05 * y - 0.6 * np.clip(1 - np.abs(x - 10) / 5, 0, None)  # noqa: E731
    points, n_ground = _scene(height=hills)
    tolerance = default_tolerance(points)
    alone, used = ground_mask(points, method, None, tolerance, 0.3, 100, np.random.RandomState(0))
    assert used == "grid"
    assert alone[:n_ground].all() and not alone[n_ground:].any()
    noise = _low_noise("five", -20.0, np.random.default_rng(2))
    noise[:, 2] += hills(noise[:, 0], noise[:, 1])
    scene = np.vstack([points, noise])
    mask, used = ground_mask(scene, method, None, tolerance, 0.3, 100, np.random.RandomState(0))
    assert used == "grid"
    np.testing.assert_array_equal(mask[:len(points)], alone)
    assert mask[len(points):].all()


@pytest.mark.parametrize("where", [(21.0, 10.0), (23.0, 10.0), (50.0, 10.0), (10.0, 10.0)])
@pytest.mark.parametrize("method", ["grid", "auto"])
def test_low_noise_off_the_ground_or_in_a_hole_of_it(method, where):
    # with no point over it (1 m to 30 m off the floor's edge, or in a hole of it where water returns
    # nothing), a point 50 m down pulled the grid's whole surface down: no floor point was ground; now a point
    # alone is low noise where it lies farther under the surface of the others than their reach
    points, n_ground = _scene()
    hole = np.hypot(points[:, 0] - 10.0, points[:, 1] - 10.0) < 3.0
    points, n_ground = points[~hole], n_ground - int(np.count_nonzero(hole[:n_ground]))
    tolerance = default_tolerance(points)
    alone, used = ground_mask(points, method, None, tolerance, 0.3, 100, np.random.RandomState(0))
    mask, with_noise = ground_mask(np.vstack([points, [[*where, -50.0]]]), method, None, tolerance, 0.3, 100,
                                   np.random.RandomState(0))
    np.testing.assert_array_equal(mask[:-1], alone)
    assert mask[-1] and with_noise == used
    assert alone[:n_ground].all() and not alone[n_ground:].any()


def test_a_pit_of_three_points_is_low_noise_and_four_are_ground():
    # the rule's size: three points alone under the floor are noise, four within the band are a surface
    rng = np.random.default_rng(4)
    ground = floor(10.0, 5000, rng, noise=0.005)
    box = rng.uniform([4, 4, 0.5], [5, 5, 1.5], size=(300, 3))
    for count, pulls in ((3, False), (4, True)):
        pit = np.column_stack([7.0 + rng.uniform(-0.02, 0.02, (count, 2)), np.full(count, -1.0)])
        mask = remove_ground(np.vstack([ground, box, pit]), method="grid", threshold=0.2)
        # a surface pulls the ground around it down: the floor points next to it rise above the threshold
        near = np.hypot(ground[:, 0] - 7.0, ground[:, 1] - 7.0) < 0.3
        assert mask[:len(ground)][near].all() != pulls and not mask[len(ground):-count].any()
