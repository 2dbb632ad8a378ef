"""Tests for eppf.estimate_normals and the packed batch kernel."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial import cKDTree

from eppf import estimate_normals
from eppf.preprocessing._normals import estimate_normals_batch
from eppf.preprocessing._normals_fast import _set_simd_level, _simd_level, smallest_eigvecs
from eppf.utils._validation import pack_point_clouds


def reference_normals(points, k):
    """Slow reference: cKDTree neighbours and np.linalg.eigh, unoriented.

    Also returns each neighbourhood's relative eigen-gap and whether its k-th
    distance is tied with the (k+1)-th (then the neighbourhood is ambiguous).
    """
    n = len(points)
    kq = min(k + 1, n)
    dist, idx = cKDTree(points).query(points, kq)
    nb = points[idx[:, :k]]
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centred, centred)
    w, v = np.linalg.eigh(cov)
    gap = (w[:, 1] - w[:, 0]) / np.maximum(w[:, 2] - w[:, 0], 1e-300)
    tied = np.zeros(n, dtype=bool) if kq == k else np.isclose(dist[:, k - 1], dist[:, k], rtol=1e-12, atol=0)
    return v[:, :, 0], gap, tied


def sine_angle(a, b):
    """Sine of the angle between rows, ignoring sign."""
    return np.linalg.norm(np.cross(a, b), axis=1)


def random_surface(rng, n):
    """Noisy points on a squashed, bumpy ellipsoid (an object-like surface)."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = 1 + 0.1 * np.sin(4 * u[:, 0]) * np.cos(3 * u[:, 1])
    return u * r[:, None] * [1.0, 0.6, 0.3] + 0.002 * rng.normal(size=(n, 3))


def unit_sphere(rng, n):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


@pytest.mark.parametrize(
    "plane_normal", [(0, 0, 1), (1, 0, 0), (0, 1, 0), (1, 2, 3), (-0.3, 0.2, 0.9)]
)
@pytest.mark.parametrize("k", [3, 10, 30])
def test_plane_normal_up_to_sign_then_oriented(plane_normal, k):
    rng = np.random.default_rng(0)
    n0 = np.asarray(plane_normal, dtype=float)
    n0 /= np.linalg.norm(n0)
    # Orthonormal basis of the plane.
    t1 = np.cross(n0, [1.0, 0.0, 0.0] if abs(n0[0]) < 0.9 else [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n0, t1)
    st = rng.uniform(-1, 1, size=(400, 2))
    points = st[:, :1] * t1 + st[:, 1:] * t2 + [0.5, -2.0, 3.0]
    normals = estimate_normals(points, k, orientation=None)
    assert_allclose(np.abs(normals @ n0), 1.0, atol=1e-9)
    # A viewpoint on the positive side of the plane makes them all equal n0.
    viewpoint = points.mean(axis=0) + 5 * n0
    oriented = estimate_normals(points, k, orientation=viewpoint)
    assert_allclose(oriented, np.tile(n0, (len(points), 1)), atol=1e-9)


def test_lattice_plane_with_tied_neighbours():
    # A regular grid has many neighbours at equal distance; any tie choice
    # lies in the plane, so the normal is exact.
    xy = np.stack(np.meshgrid(np.arange(20.0), np.arange(15.0)), -1).reshape(-1, 2)
    points = np.column_stack([xy, np.full(len(xy), 7.0)])
    normals = estimate_normals(points, 9, orientation=[0, 0, 100])
    assert_array_equal(normals, np.tile([0.0, 0.0, 1.0], (len(points), 1)))


@pytest.mark.parametrize("center", [(0, 0, 0), (3.0, -1.0, 2.0)])
def test_sphere_radial_and_outward_with_centroid(center):
    rng = np.random.default_rng(1)
    u = unit_sphere(rng, 3000)
    points = 2.5 * u + center
    normals = estimate_normals(points, 10)
    assert (np.einsum("ij,ij->i", normals, u) > 0.99).all()


def test_sphere_origin_orientation_points_inward():
    rng = np.random.default_rng(2)
    u = unit_sphere(rng, 2000)
    # Sensor at the centre of the sphere: normals point towards it.
    for orientation in ["origin", "viewpoint", (0, 0, 0)]:
        normals = estimate_normals(u, 12, orientation=orientation)
        assert (np.einsum("ij,ij->i", normals, u) < -0.99).all()


def test_cylinder_normals_radial_and_horizontal():
    rng = np.random.default_rng(3)
    theta = rng.uniform(0, 2 * np.pi, 3000)
    z = rng.uniform(-1, 1, 3000)
    radial = np.column_stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)])
    points = 0.7 * radial + np.column_stack([np.zeros((3000, 2)), z])
    normals = estimate_normals(points, 15)
    # Away from the caps' missing rims the centroid rule points outwards.
    inner = np.abs(z) < 0.8
    assert (np.einsum("ij,ij->i", normals, radial)[inner] > 0.99).all()
    assert np.abs(normals[inner, 2]).max() < 0.1


@pytest.mark.parametrize("shape", ["cube", "surface"])
@pytest.mark.parametrize("n, k", [(5, 3), (50, 3), (300, 10), (1024, 10), (2048, 20), (3000, 30), (40, 40)])
def test_matches_slow_reference(shape, n, k):
    rng = np.random.default_rng(n * 100 + k)
    points = rng.random((n, 3)) if shape == "cube" else random_surface(rng, n)
    normals = estimate_normals(points, k, orientation=None)
    ref, gap, tied = reference_normals(points, k)
    ok = (gap > 1e-6) & ~tied
    assert ok.mean() > 0.95
    assert sine_angle(normals, ref)[ok].max() < 1e-8
    assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-14)


def test_kernel_neighbourhoods_are_exact_on_clustered_data():
    # Dense clusters next to sparse background stress the grid's cell size
    # and its fall-back search.
    rng = np.random.default_rng(4)
    points = np.concatenate(
        [
            rng.normal(scale=0.001, size=(500, 3)),
            rng.normal(scale=0.01, size=(300, 3)) + 1,
            rng.random((200, 3)) * 10,
            np.column_stack([np.linspace(0, 5, 100), np.zeros(100), np.zeros(100)])
            + rng.normal(scale=1e-4, size=(100, 3)),
        ]
    )
    for k in [3, 8, 25]:
        normals = estimate_normals(points, k, orientation=None)
        ref, gap, tied = reference_normals(points, k)
        ok = (gap > 1e-6) & ~tied
        assert ok.mean() > 0.9
        assert sine_angle(normals, ref)[ok].max() < 1e-8


def test_orientation_rules():
    rng = np.random.default_rng(5)
    points = random_surface(rng, 800) + [0.2, 0.1, -0.3]
    free = estimate_normals(points, 10, orientation=None)
    centroid = estimate_normals(points, 10, orientation="centroid")
    origin = estimate_normals(points, 10, orientation="origin")
    alias = estimate_normals(points, 10, orientation="viewpoint")
    vp = np.array([3.0, -4.0, 5.0])
    towards = estimate_normals(points, 10, orientation=list(vp))
    # Same lines, only signs differ.
    for other in (centroid, origin, towards):
        assert_allclose(np.abs(np.einsum("ij,ij->i", free, other)), 1.0, atol=1e-12)
    assert_array_equal(origin, alias)
    assert_array_equal(origin, estimate_normals(points, 10, orientation=np.zeros(3)))
    assert (np.einsum("ij,ij->i", centroid, points - points.mean(axis=0)) >= 0).all()
    assert (np.einsum("ij,ij->i", origin, -points) >= 0).all()
    assert (np.einsum("ij,ij->i", towards, vp - points) >= 0).all()
    # Default is "centroid".
    assert_array_equal(estimate_normals(points, 10), centroid)


@pytest.mark.parametrize("n", [40, 1500])
def test_deterministic_across_thread_counts(n):
    rng = np.random.default_rng(6)
    points = random_surface(rng, n)
    expected = estimate_normals(points, 10, n_jobs=1)
    for n_jobs in [2, 3, -1, None]:
        assert_array_equal(estimate_normals(points, 10, n_jobs=n_jobs), expected)


def test_batch_matches_single_and_threads():
    rng = np.random.default_rng(7)
    clouds = [random_surface(rng, int(m)) for m in rng.integers(3, 1500, size=12)]
    clouds.append(rng.random((700, 3)))
    points, _, offsets = pack_point_clouds(clouds)
    expected = np.concatenate([estimate_normals(c, 14, orientation="origin") for c in clouds])
    for n_jobs in [1, 2, 4]:
        got = estimate_normals_batch(points, offsets, 14, "origin", n_jobs)
        assert_array_equal(got, expected)


def test_batch_object_is_independent_of_larger_neighbours():
    # A small k wants more grid cells than the cap of 4 n + 64; the cap must
    # be the object's own, not the largest packed object's, or the grid (and
    # with it the summation order) would depend on what it is packed with.
    rng = np.random.default_rng(17)
    small = density_steps(rng, 2000)
    large = random_surface(rng, 4099)
    points, _, offsets = pack_point_clouds([small, large, small[:700]])
    for k in (3, 4, 20):
        got = estimate_normals_batch(points, offsets, k, "centroid", 1)
        assert_array_equal(got[: len(small)], estimate_normals(small, k))
        assert_array_equal(got[len(small) : len(small) + len(large)], estimate_normals(large, k))
        assert_array_equal(got[len(small) + len(large) :], estimate_normals(small[:700], k))


def test_batch_single_object_uses_same_result():
    rng = np.random.default_rng(8)
    cloud = random_surface(rng, 900)
    points, _, offsets = pack_point_clouds([cloud])
    for n_jobs in [1, 2]:
        assert_array_equal(estimate_normals_batch(points, offsets, 10, n_jobs=n_jobs), estimate_normals(cloud, 10))


def test_batch_tiny_and_empty_objects_are_finite_units():
    rng = np.random.default_rng(9)
    clouds = [rng.random((1, 3)), rng.random((2, 3)), np.zeros((0, 3)), rng.random((3, 3)), rng.random((50, 3))]
    points = np.concatenate(clouds)
    offsets = np.r_[0, np.cumsum([len(c) for c in clouds])]
    normals = estimate_normals_batch(points, offsets, 10, n_jobs=2)
    assert normals.shape == points.shape
    assert np.isfinite(normals).all()
    assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-14)
    # The two-point object's normal is perpendicular to its segment.
    d = clouds[1][1] - clouds[1][0]
    assert_allclose(normals[1:3] @ d, 0.0, atol=1e-12)


def test_n_neighbors_larger_than_cloud_is_clipped():
    rng = np.random.default_rng(10)
    points = rng.random((25, 3))
    assert_array_equal(estimate_normals(points, 100), estimate_normals(points, 25))
    # Every neighbourhood is the whole cloud: one normal, up to orientation.
    whole = reference_normals(points, 25)[0][0]
    assert_allclose(np.abs(estimate_normals(points, 100) @ whole), 1.0, atol=1e-10)


@pytest.mark.parametrize("orientation", ["centroid", None, "origin"])
def test_degenerate_neighbourhoods_are_finite(orientation):
    rng = np.random.default_rng(11)
    line = np.outer(rng.random(60), [1.0, 2.0, -1.0]) + [5.0, 5.0, 5.0]
    # Flat bounding boxes: zero extent along one or two axes.
    x_axis = np.column_stack([rng.random(70), np.full(70, 2.0), np.zeros(70)])
    xy_plane = np.column_stack([rng.random((90, 2)), np.full(90, -1.0)])
    dupes = np.repeat(rng.random((4, 3)), 15, axis=0)
    mixed = np.concatenate([dupes, [[9.0, 9.0, 9.0]]])
    for points in (line, x_axis, xy_plane, dupes, mixed):
        normals = estimate_normals(points, 10, orientation=orientation)
        assert np.isfinite(normals).all()
        assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-14)
    # On a line the normal is perpendicular to it.
    normals = estimate_normals(line, 10, orientation=orientation)
    assert_allclose(normals @ np.array([1.0, 2.0, -1.0]), 0.0, atol=1e-8)


@pytest.mark.parametrize("exponent", [-1000, -60, 0, 60, 1000])
def test_power_of_two_scaling_is_exact(exponent):
    # The kernel rescales by a power of two internally, so tiny and huge
    # coordinates neither underflow nor overflow and give the same normals.
    rng = np.random.default_rng(12)
    points = random_surface(rng, 500)
    scaled = points * 2.0**exponent
    assert np.isfinite(scaled).all() and (scaled != 0).all()
    assert_array_equal(estimate_normals(scaled, 10), estimate_normals(points, 10))


def test_translation_and_rotation_invariance():
    rng = np.random.default_rng(13)
    points = random_surface(rng, 700)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    moved = points @ q.T + [100.0, -50.0, 20.0]
    base = estimate_normals(points, 10)
    got = estimate_normals(moved, 10)
    assert sine_angle(got, base @ q.T).max() < 1e-6
    # The centroid rule is equivariant too, so the signs match.
    assert (np.einsum("ij,ij->i", got, base @ q.T) > 0).all()


def test_input_types_and_read_only_arrays():
    rng = np.random.default_rng(14)
    points = rng.random((200, 3))
    expected = estimate_normals(points, 8)
    ro = points.copy()
    ro.setflags(write=False)
    assert_array_equal(estimate_normals(ro, 8), expected)
    assert_array_equal(estimate_normals(points.tolist(), 8), expected)
    assert_array_equal(estimate_normals(np.asfortranarray(points), 8), expected)
    got32 = estimate_normals(points.astype(np.float32), 8)
    assert got32.dtype == np.float64 and got32.shape == (200, 3)


def test_smallest_eigvecs_against_eigh():
    rng = np.random.default_rng(15)
    mats = []
    for scales in ([1, 1, 1], [1, 1, 1e-3], [1, 1e-3, 1e-3], [1, 0.5, 0.1], [1, 1, 1 - 1e-9]):
        a = rng.normal(size=(200, 3, 3)) * scales
        q = np.linalg.qr(rng.normal(size=(200, 3, 3)))[0]
        w = np.sort(np.abs(rng.normal(size=(200, 3))) * scales, axis=1)
        mats.append(np.einsum("nij,nj,nkj->nik", q, w, q))
        mats.append(np.einsum("nki,nkj->nij", a, a))
    covs = np.ascontiguousarray(np.concatenate(mats))
    w, v = np.linalg.eigh(covs)
    gap = (w[:, 1] - w[:, 0]) / (w[:, 2] - w[:, 0])
    well = gap > 1e-6
    for jacobi in (False, True):
        got = smallest_eigvecs(covs, jacobi)
        assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-14)
        assert sine_angle(got, v[:, :, 0])[well].max() < 1e-9
        # Where the two smallest eigenvalues (nearly) coincide any vector of
        # their eigenspace is right: the residual is what must be small.
        residual = np.einsum("nij,nj->ni", covs, got) - w[:, :1] * got
        assert (np.linalg.norm(residual, axis=1) <= 1e-9 * w[:, 2]).all()


def test_smallest_eigvecs_special_matrices():
    covs = np.ascontiguousarray(
        [
            np.zeros((3, 3)),
            np.eye(3),
            np.diag([3.0, 1.0, 2.0]),
            np.diag([1.0, 1.0, 5.0]),
            np.diag([2.0, 0.0, 0.0]),
        ]
    )
    got = smallest_eigvecs(covs)
    assert np.isfinite(got).all()
    assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-15)
    assert_allclose(np.abs(got[2]), [0.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(got[3, 2], 0.0, atol=1e-15)
    assert_allclose(got[4, 0], 0.0, atol=1e-15)


def test_smallest_eigvecs_in_lanes_give_the_scalar_solvers_bits():
    # The kernel solves eight covariances at once in vector lanes: each lane
    # must give the one-at-a-time solver's bits at every SIMD level, for
    # well-separated spectra, the Jacobi cases (nearly equal eigenvalues, a
    # zero matrix, a double root at r = +-1) and non-finite entries alike,
    # in any batch length (a partial last batch included).
    rng = np.random.default_rng(16)
    mats = []
    for scales in ([1, 1, 1], [1, 1, 1e-3], [1, 1e-3, 1e-3], [1, 1, 1 - 1e-9], [1e-300, 1e-300, 1e-300]):
        a = rng.normal(size=(300, 3, 3)) * scales
        mats.append(np.einsum("nki,nkj->nij", a, a))
    special = [np.zeros((3, 3)), np.eye(3), np.diag([3.0, 1.0, 2.0]), np.diag([1.0, 1.0, 5.0]),
               np.diag([2.0, 0.0, 0.0]), np.full((3, 3), np.nan), np.diag([np.inf, 1.0, 2.0]),
               np.diag([1.0, 2.0, 2.0]), np.diag([1.0, 1.0, 1.0 + 1e-12])]
    covs = np.ascontiguousarray(np.concatenate(mats + [np.array(special)]))
    expected = smallest_eigvecs(covs)
    old = _simd_level()
    try:
        for level in sorted({_set_simd_level(level) for level in (0, 1, 2)}):
            _set_simd_level(level)
            for stop in (len(covs), 13, 3):
                got = smallest_eigvecs(covs[:stop], lanes=True)
                assert_array_equal(got.view(np.uint64), expected[:stop].view(np.uint64))
    finally:
        _set_simd_level(old)


@pytest.mark.parametrize(
    "points, kwargs, error, msg",
    [
        (np.zeros((10, 2)), {}, ValueError, "estimate_normals: point cloud must have shape (n_points, 3), got shape (10, 2)"),
        (np.zeros((10, 6)), {}, ValueError, "estimate_normals: point cloud must have shape (n_points, 3), got shape (10, 6)"),
        (np.zeros(30), {}, ValueError, "estimate_normals: point cloud must have shape (n_points, 3), got shape (30,)"),
        (np.arange(6.0).reshape(2, 3), {}, ValueError, "estimate_normals: point cloud has 2 points; at least 3 are needed"),
        (np.zeros((0, 3)), {}, ValueError, "estimate_normals: point cloud has 0 points; at least 3 are needed"),
        (np.zeros((5, 3)), {}, ValueError, "estimate_normals: point cloud has all 5 points identical"),
        (np.array([[0.0, 0, 0], [1, np.nan, 0], [0, 1, 0]]), {}, ValueError, "estimate_normals: point cloud contains NaN or infinite values"),
        (np.array([[0.0, 0, 0], [1, np.inf, 0], [0, 1, 0]]), {}, ValueError, "estimate_normals: point cloud contains NaN or infinite values"),
        ("abc", {}, TypeError, "estimate_normals: point cloud must be an array of shape (n_points, 3) or (n_points, 6), got str"),
        (None, {}, TypeError, "estimate_normals: point cloud must be an array"),
        (np.eye(3), {"n_neighbors": 2}, ValueError, "estimate_normals: n_neighbors must be an int >= 3 (a plane needs three points), got 2"),
        (np.eye(3), {"n_neighbors": 0}, ValueError, "estimate_normals: n_neighbors must be an int >= 3 (a plane needs three points), got 0"),
        (np.eye(3), {"n_neighbors": 10.0}, TypeError, "estimate_normals: n_neighbors must be an int >= 3 (a plane needs three points), got 10.0"),
        (np.eye(3), {"n_neighbors": True}, TypeError, "estimate_normals: n_neighbors must be an int >= 3 (a plane needs three points), got True"),
        (np.eye(3), {"orientation": "up"}, ValueError, "estimate_normals: orientation must be None or one of 'centroid', 'origin', 'viewpoint' or a finite viewpoint of shape (3,), got 'up'"),
        (np.eye(3), {"orientation": [1.0, 2.0]}, ValueError, "estimate_normals: orientation must be None or one of 'centroid', 'origin', 'viewpoint' or a finite viewpoint of shape (3,), got [1.0, 2.0]"),
        (np.eye(3), {"orientation": np.zeros((1, 3))}, ValueError, "estimate_normals: orientation must be None or one of 'centroid', 'origin', 'viewpoint' or a finite viewpoint of shape (3,), got array([[0., 0., 0.]])"),
        (np.eye(3), {"orientation": [0.0, np.nan, 1.0]}, ValueError, "estimate_normals: orientation must be None or one of 'centroid', 'origin', 'viewpoint' or a finite viewpoint of shape (3,), got [0.0, nan, 1.0]"),
        (np.eye(3), {"orientation": {"x": 1}}, TypeError, "estimate_normals: orientation must be None or one of 'centroid', 'origin', 'viewpoint' or a finite viewpoint of shape (3,), got {'x': 1}"),
        (np.eye(3), {"n_jobs": 0}, ValueError, "estimate_normals: n_jobs must be None or a non-zero int (-1: all cores), got 0"),
        (np.eye(3), {"n_jobs": 1.5}, TypeError, "estimate_normals: n_jobs must be None or a non-zero int (-1: all cores), got 1.5"),
    ],
)
def test_estimate_normals_errors(points, kwargs, error, msg):
    with pytest.raises(error, match=re.escape(msg)):
        estimate_normals(points, **kwargs)


@pytest.mark.parametrize(
    "points, offsets, kwargs, error, msg",
    [
        (np.zeros((4, 2)), [0, 4], {}, ValueError, "estimate_normals_batch: points must have shape (n_total, 3), got shape (4, 2)"),
        (np.full((4, 3), np.nan), [0, 4], {}, ValueError, "estimate_normals_batch: points contain NaN or infinite values"),
        (np.eye(3), [0, 2], {}, ValueError, "estimate_normals_batch: offsets must be non-decreasing from 0 to len(points) = 3, got offsets[0] = 0 and offsets[-1] = 2"),
        (np.eye(3), [0, 2, 1, 3], {}, ValueError, "estimate_normals_batch: offsets must be non-decreasing from 0 to len(points) = 3"),
        (np.eye(3), [1, 3], {}, ValueError, "estimate_normals_batch: offsets must be non-decreasing from 0 to len(points) = 3, got offsets[0] = 1"),
        (np.eye(3), [3], {}, ValueError, "estimate_normals_batch: offsets must be a 1D integer array of length n_objects + 1 >= 2"),
        (np.eye(3), [0.0, 3.0], {}, ValueError, "estimate_normals_batch: offsets must be a 1D integer array"),
        (np.eye(3), [0, 3], {"n_neighbors": 1}, ValueError, "estimate_normals_batch: n_neighbors must be an int >= 3"),
        (np.eye(3), [0, 3], {"owner": "EPPFTransformer", "n_neighbors": 1}, ValueError, "EPPFTransformer: n_neighbors must be an int >= 3"),
        (np.eye(3), [0, 3], {"orientation": "away"}, ValueError, "estimate_normals_batch: orientation must be"),
    ],
)
def test_estimate_normals_batch_errors(points, offsets, kwargs, error, msg):
    with pytest.raises(error, match=re.escape(msg)):
        estimate_normals_batch(points, np.asarray(offsets), **kwargs)


@pytest.mark.parametrize("offset", [1e4, 1e9])
def test_cloud_far_from_origin(offset):
    rng = np.random.default_rng(16)
    local = random_surface(rng, 1500)
    normals = estimate_normals(local + offset, 10, orientation=None)
    assert np.isfinite(normals).all()
    ref, gap, tied = reference_normals(local, 10)
    ok = gap > 1e-3
    # The offset costs the coordinates' low bits, nothing more.
    assert sine_angle(normals, ref)[ok].max() < 1e-13 * offset


def density_steps(rng, n):
    """Points on a wavy sheet whose density changes by 100x in steps, plus a
    sparse background: consecutive queries see very different k-th
    distances, so the kernel's fast path misses and retries and its shell
    search runs."""
    parts = []
    for i, share in enumerate([0.5, 0.3, 0.15, 0.05]):
        m = int(n * share)
        xy = rng.random((m, 2)) * [1.0, 1.0] + [i, 0.0]
        z = 0.05 * np.sin(6 * xy[:, 0]) + 1e-3 * rng.normal(size=m)
        parts.append(np.column_stack([xy, z]))
    parts.append(rng.random((n // 50, 3)) * [4.0, 1.0, 1.0] + [0.0, 0.0, 0.5])
    return np.concatenate(parts)


@pytest.mark.parametrize("n", [1024, 10_000])
def test_k20_matches_slow_reference_across_densities(n):
    # n_neighbors=20 (the benchmarked setting) on surfaces and on clouds of
    # changing density: exact neighbours, so the eigh reference agrees.
    rng = np.random.default_rng(n)
    for points in (random_surface(rng, n), density_steps(rng, n)):
        normals = estimate_normals(points, 20, orientation=None)
        ref, gap, tied = reference_normals(points, 20)
        ok = (gap > 1e-6) & ~tied
        assert ok.mean() > 0.95
        assert sine_angle(normals, ref)[ok].max() < 1e-8


def test_fast_path_gives_the_general_paths_normals():
    # A float array inside the magnitude window skips the copy and the full
    # validation; any other input (a list, a strided view, Fortran order,
    # float32 converted once) must give the very same bits.
    rng = np.random.default_rng(21)
    points = density_steps(rng, 3000)
    for orientation in ("centroid", "origin", None, [1.0, -2.0, 3.0]):
        general = estimate_normals(points.tolist(), 20, orientation=orientation)
        assert_array_equal(estimate_normals(points, 20, orientation=orientation), general)
        assert_array_equal(estimate_normals(np.asfortranarray(points), 20, orientation=orientation), general)
        wide = np.zeros((len(points), 5))
        wide[:, 1:4] = points
        assert_array_equal(estimate_normals(wide[:, 1:4], 20, orientation=orientation), general)
    single = points.astype(np.float32)
    assert_array_equal(estimate_normals(single, 20), estimate_normals(single.astype(np.float64).tolist(), 20))
    for n_jobs in (1, 2, 3):
        assert_array_equal(estimate_normals(points, 20, n_jobs=n_jobs), estimate_normals(points.tolist(), 20))
    # Outside the window (rescaled by the general path): the normals of the
    # cloud at a sane scale, bit for bit, as before.
    assert_array_equal(estimate_normals(points * 2.0**-150, 20), estimate_normals(points, 20))
    assert_array_equal(estimate_normals(points * 2.0**200, 20), estimate_normals(points, 20))


@pytest.mark.parametrize(
    "bad, msg",
    [
        (np.nan, "NaN or infinite"),
        (np.inf, "NaN or infinite"),
        (-np.inf, "NaN or infinite"),
    ],
)
def test_fast_path_refuses_what_the_general_path_refuses(bad, msg):
    rng = np.random.default_rng(22)
    points = rng.random((600, 3))
    points[417, 1] = bad
    for arr in (points, points.astype(np.float32)):
        with pytest.raises(ValueError, match=msg):
            estimate_normals(arr, 20)
    with pytest.raises(ValueError, match="identical"):
        estimate_normals(np.full((50, 3), 0.25), 20)
    # Input errors still come before parameter errors, as on the general path.
    with pytest.raises(ValueError, match="NaN or infinite"):
        estimate_normals(points, 2)
    with pytest.raises(ValueError, match="n_neighbors"):
        estimate_normals(rng.random((600, 3)), 2)


def _level_clouds(rng):
    """Clouds that exercise the fast path's scan and selection: every size
    remainder modulo 8, volumes (many candidates per block), surfaces, a line,
    duplicates, a lattice full of ties, and a strong density change."""
    clouds = [rng.normal(size=(n, 3)) * [0.5, 1.0, 2.0] for n in (3, 5, 7, 8, 9, 17, 63, 250, 1024, 3001)]
    clouds += [random_surface(rng, n) for n in (31, 1000, 4099)]
    clouds.append(np.outer(np.linspace(0, 1, 200), [1.0, 2.0, 3.0]) + 1e-9 * rng.normal(size=(200, 3)))
    dup = rng.random((300, 3))
    clouds.append(np.concatenate([dup, dup[:150], dup[:40]]))
    grid = np.stack(np.meshgrid(*[np.arange(9.0)] * 3), -1).reshape(-1, 3)
    clouds.append(grid)
    clouds.append(density_steps(rng, 2000))
    return clouds


@pytest.mark.parametrize("k", [3, 10, 20, 45])
def test_simd_levels_give_the_scalar_normals(k):
    # The fast path's distance scan and selection run with AVX2 or AVX-512
    # where the CPU has them: every level must give the scalar code's normals
    # bit for bit (same candidates, same neighbour lists, same sums), single
    # calls and packed batches alike, on any number of threads.
    rng = np.random.default_rng(100 + k)
    clouds = _level_clouds(rng)
    points, _, offsets = pack_point_clouds(clouds)
    old = _simd_level()
    try:
        assert _set_simd_level(0) == 0
        single = [estimate_normals(c, k, n_jobs=1) for c in clouds]
        batch = estimate_normals_batch(points, offsets, k, "centroid", 1)
        levels = sorted({_set_simd_level(level) for level in (1, 2)})
        for level in levels:
            _set_simd_level(level)
            for c, expected in zip(clouds, single):
                assert_array_equal(estimate_normals(c, k, n_jobs=1), expected)
            assert_array_equal(estimate_normals(clouds[9], k, n_jobs=2), single[9])
            assert_array_equal(estimate_normals_batch(points, offsets, k, "centroid", 2), batch)
    finally:
        _set_simd_level(old)
    assert_array_equal(batch, np.concatenate(single))
    # and the normals are exact PCA ones (the scalar level against cKDTree + eigh)
    ref, gap, tied = reference_normals(clouds[8], k)
    ok = (gap > 1e-6) & ~tied
    assert ok.mean() > 0.9
    assert sine_angle(single[8], ref)[ok].max() < 1e-8


def test_simd_level_is_clipped_to_the_cpu():
    old = _simd_level()
    try:
        assert _set_simd_level(-3) == 0
        top = _set_simd_level(99)
        assert top in (0, 1, 2) and top >= old
    finally:
        _set_simd_level(old)


@pytest.mark.parametrize("threads", [1, 2])
def test_kernel_with_k_above_n_reads_no_stale_scratch(threads):
    # callers clip k to the cloud's size; the kernel itself must not depend on what its scratch held before
    from eppf.preprocessing._normals import resolve_orientation
    from eppf.preprocessing._normals_fast import normals_single, scratch_sizes

    pts = np.random.default_rng(3).normal(size=(7, 3))
    mode, _ = resolve_orientation("centroid", "test")
    results = []
    for fill in (np.nan, 0.0, 1e300):
        f_len, i_len = scratch_sizes(7, 20)
        out = np.empty((7, 3))
        normals_single(pts, 20, mode, np.zeros(3), out, np.full((threads, f_len), fill),
                       np.full((threads, i_len), -1, dtype=np.int64), threads)
        results.append(out)
    expected = estimate_normals(pts, 20)
    for out in results:
        assert out.tobytes() == expected.tobytes()
