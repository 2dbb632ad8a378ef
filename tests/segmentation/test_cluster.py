"""euclidean_clusters against an independent reference: SciPy's connected components of the radius graph."""

import warnings

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from eppf.segmentation import euclidean_clusters
from tests.segmentation.conftest import floor, sphere


def reference(points, tolerance, min_points=1, max_points=None):
    """PCL's semantics from first principles: points closer than ``tolerance`` (strictly) are connected;
    clusters outside [min_points, max_points] give -1; the rest numbered by size, largest first, ties by
    smallest point index."""
    n = len(points)
    pairs = cKDTree(points).query_pairs(np.nextafter(tolerance, 0), output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    comp = connected_components(graph, directed=False)[1]
    sizes = np.bincount(comp)
    first = np.full(len(sizes), n)
    np.minimum.at(first, comp, np.arange(n))
    kept = [c for c in range(len(sizes)) if sizes[c] >= min_points and (max_points is None or sizes[c] <= max_points)]
    kept.sort(key=lambda c: (-sizes[c], first[c]))
    number = np.full(len(sizes), -1)
    number[kept] = np.arange(len(kept))
    return number[comp]


@pytest.mark.parametrize("seed", range(12))
def test_random_scenes_match_the_reference(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 4000))
    points = rng.uniform(0, 1, (n, 3)) * rng.uniform(0.5, 20, 3)
    if seed % 3 == 0:  # many coincident points and points on cell boundaries
        points = np.round(points, 1)
    tolerance = float(rng.uniform(0.05, 1.5))
    min_points = int(rng.integers(1, 5))
    max_points = None if seed % 2 else int(rng.integers(min_points, n + 1))
    np.testing.assert_array_equal(
        euclidean_clusters(points, tolerance, min_points=min_points, max_points=max_points),
        reference(points, tolerance, min_points, max_points))


@pytest.mark.parametrize("scale, offset", [(1e-3, 0.0), (1.0, 0.0), (1e3, 0.0), (1.0, 4.5e6), (1e-6, 1.0)])
def test_scales_and_projected_offsets_match_the_reference(scale, offset):
    rng = np.random.default_rng(1)
    points = np.vstack([sphere((0, 0, 0), 1, 500, rng), sphere((2.5, 0, 0), 1, 400, rng),
                        rng.uniform(-3, 3, (50, 3))]) * scale + offset
    tolerance = 0.35 * scale
    labels = euclidean_clusters(points, tolerance)
    np.testing.assert_array_equal(labels, reference(points, tolerance))
    assert np.unique(labels[:500]).size == 1 and np.unique(labels[500:900]).size == 1 and labels[0] != labels[500]


def test_derived_tolerance_separates_spheres_at_any_scale():
    rng = np.random.default_rng(2)
    base = np.vstack([sphere((0, 0, 0), 1, 800, rng), sphere((4, 0, 0), 1, 700, rng), sphere((0, 4, 0), 1, 600, rng)])
    expected = np.repeat([0, 1, 2], [800, 700, 600])
    for scale, offset in ((1.0, 0.0), (1e-3, 0.0), (1e4, 0.0), (1.0, 6e6)):
        np.testing.assert_array_equal(euclidean_clusters(base * scale + offset), expected)


def test_numbering_by_size_then_first_index():
    points = np.array([[0, 0, 0], [10, 0, 0], [10.5, 0, 0], [20, 0, 0], [30, 0, 0], [30.5, 0, 0], [40, 0, 0.0]])
    # sizes 1, 2, 1, 2, 1: the pairs first (the one at index 1 before index 4), then singles in index order
    np.testing.assert_array_equal(euclidean_clusters(points, 1.0), [2, 0, 0, 3, 1, 1, 4])
    np.testing.assert_array_equal(euclidean_clusters(points, 1.0, min_points=2), [-1, 0, 0, -1, 1, 1, -1])
    np.testing.assert_array_equal(euclidean_clusters(points, 1.0, max_points=1), [0, -1, -1, 1, -1, -1, 2])


def test_strictly_closer_than_the_tolerance():
    points = np.array([[0, 0, 0], [1, 0, 0], [2.5, 0, 0.0]])
    np.testing.assert_array_equal(euclidean_clusters(points, 1.0), [0, 1, 2])  # distance 1 is not < 1
    np.testing.assert_array_equal(euclidean_clusters(points, np.nextafter(1.0, 2)), [0, 0, 1])


def test_touching_objects_merge_and_separated_ones_do_not():
    rng = np.random.default_rng(3)
    a = sphere((0, 0, 0), 1, 2000, rng)
    touching = sphere((2.0, 0, 0), 1, 2000, rng)  # the spheres meet at (1, 0, 0)
    apart = sphere((2.6, 0, 0), 1, 2000, rng)
    assert np.unique(euclidean_clusters(np.vstack([a, touching]), 0.15)).size == 1
    assert np.unique(euclidean_clusters(np.vstack([a, apart]), 0.15)).size == 2


def test_dense_plane_is_one_cluster_and_normals_are_ignored():
    rng = np.random.default_rng(4)
    plane = floor(10, 20000, rng)
    labels = euclidean_clusters(plane)
    assert (labels == 0).all()
    with_normals = np.column_stack([plane, np.tile([0, 0, 1.0], (len(plane), 1))])
    np.testing.assert_array_equal(euclidean_clusters(with_normals), labels)


def test_same_labels_on_every_call_and_for_a_reordered_scene():
    rng = np.random.default_rng(5)
    points = np.vstack([sphere((k * 3.0, 0, 0), 1, 300 + 50 * k, rng) for k in range(4)])
    first = euclidean_clusters(points, 0.3)
    np.testing.assert_array_equal(euclidean_clusters(points, 0.3), first)
    perm = rng.permutation(len(points))
    again = euclidean_clusters(points[perm], 0.3)
    # sizes differ, so the numbering (by size) survives the permutation
    np.testing.assert_array_equal(again, first[perm])


def test_float32_and_int_input():
    points = np.array([[0, 0, 0], [1, 0, 0], [5, 0, 0]])
    np.testing.assert_array_equal(euclidean_clusters(points, 1.5), [0, 0, 1])
    np.testing.assert_array_equal(euclidean_clusters(points.astype(np.float32), 1.5), [0, 0, 1])


@pytest.mark.parametrize("points, tolerance, kind, pattern", [
    (np.empty((0, 3)), 1.0, ValueError, r"has 0 points"),
    (np.zeros((1, 3)), 1.0, ValueError, r"has 1 point;"),
    (np.array([[0, 0, 0], [np.nan, 0, 0]]), 1.0, ValueError, r"NaN or infinite"),
    (np.array([[0, 0, 0], [np.inf, 0, 0]]), 1.0, ValueError, r"NaN or infinite"),
    (np.zeros((4, 2)), 1.0, ValueError, r"shape \(n_points, 3\)"),
    (np.zeros(4), 1.0, ValueError, r"shape"),
    (np.zeros((3, 3)), 1.0, ValueError, r"all 3 points identical"),
    (np.array([[-1e308, 0, 0], [1e308, 0, 0]]), 1.0, ValueError, r"extent overflows"),
    (np.array([[0, 0, 0], [1e200, 0, 0]]), 1.0, ValueError, r"spans 1e\+200 along one axis; at most 1e\+100"),
    (np.array([["a", "b", "c"]] * 2), 1.0, TypeError, r"must hold numbers"),
    (np.eye(3), 0.0, ValueError, r"tolerance must be None or a float in \(0.0, inf\), got 0.0"),
    (np.eye(3), -1.0, ValueError, r"tolerance"),
    (np.eye(3), np.nan, ValueError, r"tolerance"),
    (np.eye(3), np.inf, ValueError, r"tolerance"),
    (np.eye(3), True, TypeError, r"tolerance"),
    (np.eye(3), 1e-320, ValueError, r"tolerance must be at least 1e-150 \(squared distances below it underflow"),
    (np.eye(3), "1", TypeError, r"tolerance"),
])
def test_bad_input_is_named(points, tolerance, kind, pattern):
    with pytest.raises(kind, match=r"^euclidean_clusters: .*" + pattern):
        euclidean_clusters(points, tolerance)


def test_scenes_whose_squared_distances_overflow_are_refused_by_every_function():
    from eppf.segmentation import remove_ground, segment_scene

    scene = np.random.default_rng(0).normal(size=(200, 3)) * 1e300  # finite extent, infinite squares
    for function in (euclidean_clusters, remove_ground, segment_scene):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # refused before any overflow warning
            with pytest.raises(ValueError, match=rf"^{function.__name__}: the scene spans .* rescale"):
                function(scene)


@pytest.mark.parametrize("scale, tolerance", [(5e-320, None), (5e-320, 1e-321), (1e-150, None), (1e-150, 1e-151)])
def test_scenes_too_small_for_float64_cells_are_refused_by_every_function(scale, tolerance):
    """Subnormal (or nearly) coordinates: a cell's side would underflow and its reciprocal overflow."""
    from eppf.segmentation import remove_ground, segment_scene

    scene = np.random.default_rng(0).uniform(size=(300, 3)) * scale
    for function, kwargs in ((euclidean_clusters, dict(tolerance=tolerance)), (remove_ground, {}),
                             (segment_scene, dict(tolerance=tolerance))):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # refused before any division by zero or overflow
            with pytest.raises(ValueError, match=rf"^{function.__name__}: the scene spans only .* at least 1e-100 "
                                                 r"is needed .* rescale"):
                function(scene, **kwargs)


def test_a_scene_just_above_the_smallest_extent_is_segmented_as_its_scaled_copy():
    scene = np.random.default_rng(1).uniform(size=(400, 3))
    labels = euclidean_clusters(scene, 0.08)
    assert labels.max() >= 1  # more than one cluster: the comparison below means something
    np.testing.assert_array_equal(euclidean_clusters(scene * 1e-99, 0.08e-99), labels)


@pytest.mark.parametrize("kwargs, pattern", [
    (dict(min_points=0), r"min_points must be an int >= 1, got 0"),
    (dict(min_points=2.0), r"min_points must be an int"),
    (dict(max_points=0), r"max_points must be None or an int >= 1"),
    (dict(min_points=5, max_points=3), r"max_points \(3\) is smaller than min_points \(5\)"),
])
def test_bad_sizes_are_named(kwargs, pattern):
    with pytest.raises(ValueError, match=r"^euclidean_clusters: " + pattern):
        euclidean_clusters(np.eye(3), 1.0, **kwargs)


def test_cell_coordinates_stay_in_range_for_any_double():
    from eppf.segmentation import _cluster_fast

    pts = np.array([[np.nan, np.inf, -np.inf], [1e308, -1e308, 5e-324], [0.5, 2.5, 1e20]])
    cells = _cluster_fast.cells(pts, 0.0, 0.0, 0.0, 1.0, 8)
    np.testing.assert_array_equal(cells, [[0, 7, 0], [7, 0, 0], [0, 2, 7]])


@pytest.mark.parametrize("seed", range(4))
def test_derived_tolerance_is_five_median_nearest_neighbor_distances(seed):
    from eppf.segmentation._cluster import TOLERANCE_FACTOR, default_tolerance

    rng = np.random.default_rng(seed)
    points = rng.uniform(0, 1, (3000, 3)) * [10, 3, 0.01 if seed % 2 else 4]
    points[:200] = points[200:400]  # coincident points are left out of the nearest-neighbor distances
    dist, _ = cKDTree(points).query(points, k=3)
    nearest = np.where(dist[:, 1] > 0, dist[:, 1], dist[:, 2])
    assert np.isclose(default_tolerance(points), TOLERANCE_FACTOR * np.partition(nearest, 1500)[1500], rtol=1e-12)


def test_derived_tolerance_searches_coincident_points_once(monkeypatch):
    # 200,000 points at the origin (a scanner's missing returns) and one more: the pile's 19,999 sample points
    # were each compared with the whole pile, for minutes; one of them stands for all
    from eppf.segmentation import _cluster, _cluster_fast
    from eppf.segmentation._cluster import TOLERANCE_FACTOR, default_tolerance

    searched, search = [], _cluster_fast.nearest_distances

    def nearest_distances(*args):
        searched.append(len(args[-1]))
        return search(*args)

    monkeypatch.setattr(_cluster._cluster_fast, "nearest_distances", nearest_distances)
    points = np.vstack([np.zeros((200000, 3)), [[1.0, 2.0, 2.0]]])
    assert default_tolerance(points) == TOLERANCE_FACTOR * 3.0
    assert searched and max(searched) == 2


def _exact_derived_tolerance(points):
    """Five times the median distance from the derived tolerance's sample points to their nearest other point,
    computed as the kernel does (the squares summed x, y, z), for points with no coincident ones."""
    from eppf.segmentation._cluster import _SPACING_SAMPLE, TOLERANCE_FACTOR

    sample = np.unique(np.linspace(0, len(points) - 1, min(len(points), _SPACING_SAMPLE)).astype(np.int64))
    _, nearest = cKDTree(points).query(points[sample], k=2)
    d = points[sample] - points[nearest[:, 1]]
    dist = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    return TOLERANCE_FACTOR * np.partition(dist, len(sample) // 2)[len(sample) // 2]


@pytest.mark.parametrize("scene", ["blob and a far point", "two flat blobs far apart", "blob and a point 1e12 away"])
def test_derived_tolerance_on_dense_blobs_searches_few_points(monkeypatch, scene):
    # the first cells come from the bounding box: a dense blob (points within 1e-6 of each other) and a far
    # point, or two blobs 1 apart, put each blob in one cell, searched in full for each of its sample points
    # (3.6 s for 200,000 points); finer cells now part the crowd, and the tolerance is the same, to the bit
    from eppf.segmentation import _cluster, _cluster_fast
    from eppf.segmentation._cluster import default_tolerance

    compared, search = [], _cluster_fast.nearest_distances

    def nearest_distances(pts, cells, order, start, cell, sample):
        rows = {tuple(c): k for k, c in enumerate(cell)} if len(cell) < 10**5 else None
        own = [start[rows[tuple(cells[p])] + 1] - start[rows[tuple(cells[p])]] for p in sample]
        compared.append(int(np.sum(own)))
        return search(pts, cells, order, start, cell, sample)

    monkeypatch.setattr(_cluster._cluster_fast, "nearest_distances", nearest_distances)
    rng = np.random.default_rng(8)
    blob = rng.uniform(0, 1e-6, (6000, 3))
    if scene == "blob and a far point":
        points = np.vstack([blob, [[1.0, 1.0, 1.0]]])
    elif scene == "blob and a point 1e12 away":  # the cells were kept wider than 1e12 / 2**29
        points = np.vstack([blob, [[1e12, 0.0, 0.0]]])
    else:
        points = np.vstack([blob * [1, 1, 1e-3], blob * [1, 1, 1e-3] + [0, 0, 1.0]])
    assert default_tolerance(points) == _exact_derived_tolerance(points)
    assert compared and max(compared) < 100 * 6000  # a whole blob per sample point: 6000 * 6000


@pytest.mark.parametrize("seed", range(4))
def test_stray_points_far_from_the_scene_match_the_reference(seed):
    # a point 1e12 away (a bad return) made the grid span more than 2**30 cells of the tolerance: an error
    # telling to take a larger tolerance, which would have merged the scene's objects
    from eppf.segmentation import segment_scene

    rng = np.random.default_rng(seed)
    scene = rng.uniform(0, 1, (1500, 3)) * [8, 6, 2]
    stray = np.array([[1e12, 0, 0], [0, -1e12, 3], [1e12, 1e12, -1e12], [1e12 + 0.01, 0, 0], [-7e11, 5, 5]])
    points = np.vstack([scene, stray])[rng.permutation(len(scene) + len(stray))]
    tolerance = float(rng.uniform(0.2, 0.6))
    np.testing.assert_array_equal(euclidean_clusters(points, tolerance), reference(points, tolerance))
    # the stray points change neither the derived tolerance nor the scene's segments
    alone = segment_scene(scene, ground="none", min_points=3)
    labels = segment_scene(np.vstack([scene, stray]), ground="none", min_points=3)
    np.testing.assert_array_equal(labels[:len(scene)], alone)
    assert (labels[len(scene):] == -1).all()


def test_a_run_of_points_spanning_too_many_cells_is_refused(monkeypatch):
    from eppf.segmentation import _cluster

    monkeypatch.setattr(_cluster, "_MAX_CELLS", 1000)  # 2**30 cells take 5e8 points without a gap
    points = np.column_stack([np.arange(2000) * 0.5, np.zeros(2000), np.zeros(2000)])
    with pytest.raises(ValueError, match=r"^euclidean_clusters: the scene spans more than 2\*\*30 cells of the "
                                         r"tolerance along x \(extent 999.5, cell 0.57735\) without a gap; give"):
        euclidean_clusters(points, 1.0)
    # the same points in runs with gaps: clustered run by run
    points[:, 0] += np.repeat(np.arange(20) * 10.0, 100)
    np.testing.assert_array_equal(euclidean_clusters(points, 1.0), reference(points, 1.0))


def test_a_derived_tolerance_whose_squares_underflow_is_refused():
    # most points a few subnormal steps apart beside a unit-scale scene: their squared distances underflow to 0,
    # so they were taken for coincident points and left out of the spacing (and a finer search took minutes)
    from eppf.segmentation import remove_ground, segment_scene

    rng = np.random.default_rng(9)
    crowd = np.column_stack([np.arange(1500) * 5e-324, np.zeros((1500, 2))])
    points = np.vstack([crowd, rng.uniform(0, 1, (500, 3))])
    for function in (euclidean_clusters, remove_ground, segment_scene):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(ValueError, match=rf"^{function.__name__}: the median nearest-neighbor distance of "
                                                 r"the points is 0, so the tolerance derived .* below 1e-150"):
                function(points)


def test_tiny_tolerances_are_refused_by_segment_scene_too():
    from eppf.segmentation import SceneSegmenter, segment_scene

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the cells' side overflowed in 1 / side
        with pytest.raises(ValueError, match=r"^segment_scene: tolerance must be at least 1e-150"):
            segment_scene(np.eye(3), tolerance=1e-320)
        with pytest.raises(ValueError, match=r"^SceneSegmenter: tolerance must be at least 1e-150"):
            SceneSegmenter(tolerance=1e-200).fit(np.eye(3))
    assert segment_scene(np.eye(3), ground="none", tolerance=1e-150, min_points=1).tolist() == [0, 1, 2]
