"""Tests of area-weighted mesh sampling (eppf.preprocessing.sample_mesh)."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.preprocessing import sample_mesh

SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])


def _tetrahedron():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    # counter-clockwise seen from outside, so normals point outwards
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return v, f


@pytest.mark.parametrize("n_points", [1, 7, 2048])
def test_count_and_layout(n_points):
    cloud = sample_mesh(SQUARE_V, SQUARE_F, n_points=n_points, random_state=0)
    assert cloud.shape == (n_points, 6) and cloud.dtype == np.float64
    assert sample_mesh(SQUARE_V, SQUARE_F, n_points=n_points, return_normals=False, random_state=0).shape == (n_points, 3)


def test_deterministic_under_random_state():
    v, f = _tetrahedron()
    a = sample_mesh(v, f, n_points=500, random_state=3)
    b = sample_mesh(v, f, n_points=500, random_state=np.random.RandomState(3))
    c = sample_mesh(v, f, n_points=500, random_state=4)
    assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_points_on_surface_and_outward_normals():
    v, f = _tetrahedron()
    cloud = sample_mesh(v, f, n_points=3000, random_state=0)
    xyz, nrm = cloud[:, :3], cloud[:, 3:]
    # every point lies on one of the four planes x=0, y=0, z=0, x+y+z=1, inside the solid's hull
    on_plane = np.isclose(xyz, 0).any(axis=1) | np.isclose(xyz.sum(axis=1), 1)
    assert on_plane.all()
    assert (xyz >= -1e-12).all() and (xyz.sum(axis=1) <= 1 + 1e-12).all()
    assert_allclose(np.linalg.norm(nrm, axis=1), 1)
    # outward: the normal points away from the centroid
    assert ((xyz - v.mean(axis=0)) * nrm).sum(axis=1).min() > 0


def test_area_weighting():
    # two disjoint triangles with areas 1/2 and 3/2 (3x)
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 0], [8, 0, 0], [5, 1, 0]], dtype=float)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    cloud = sample_mesh(v, f, n_points=40000, random_state=1)
    share_big = np.mean(cloud[:, 0] >= 5)
    assert abs(share_big - 0.75) < 0.01  # 0.75 +- 5 standard errors


def test_uniform_inside_triangle():
    # the medial triangle holds a quarter of the area, so a quarter of the points
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    cloud = sample_mesh(v, [[0, 1, 2]], n_points=40000, random_state=2)
    x, y = cloud[:, 0], cloud[:, 1]
    medial = (x <= 0.5) & (y <= 0.5) & (x + y >= 0.5)
    assert abs(medial.mean() - 0.25) < 0.011
    assert_allclose(cloud[:, :2].mean(axis=0), [1 / 3, 1 / 3], atol=0.006)


def test_zero_area_faces_never_chosen():
    v = np.vstack([SQUARE_V, [[5, 5, 5], [6, 6, 6], [7, 7, 7]]])
    f = np.vstack([[[4, 5, 6]], SQUARE_F, [[4, 5, 6]]])  # collinear triangles first and last
    cloud = sample_mesh(v, f, n_points=5000, random_state=0)
    assert cloud[:, :3].max() <= 1 + 1e-12


def _voxel_reference(cloud, leaf):
    """Slow reference: group points by cell in a dict and average."""
    origin = cloud[:, :3].min(axis=0)
    groups = {}
    for row in cloud:
        key = tuple(np.floor((row[:3] - origin) / leaf).astype(int))
        groups.setdefault(key, []).append(row)
    out = []
    for key in sorted(groups):
        pts = np.array(groups[key])
        mean = pts.mean(axis=0)
        mean[3:] /= np.linalg.norm(mean[3:])
        out.append(mean)
    return np.array(out)


def test_resolution_matches_voxel_reference():
    v, f = _tetrahedron()
    leaf = 0.1
    cloud = sample_mesh(v, f, resolution=leaf, n_samples=3000, random_state=0)
    dense = sample_mesh(v, f, n_points=3000, random_state=0)
    assert_allclose(cloud, _voxel_reference(dense, leaf), atol=1e-12)


def test_resolution_density_follows_area():
    # a unit square at 0.1 resolution fills its 10 x 10 cells
    cloud = sample_mesh(SQUARE_V, SQUARE_F, resolution=0.1, n_samples=20000, random_state=0)
    assert cloud.shape == (100, 6)
    assert_allclose(cloud[:, 3:], np.tile([0, 0, 1], (100, 1)))


@pytest.mark.parametrize(
    "vertices, faces, kwargs, exc, msg",
    [
        (SQUARE_V, SQUARE_F, {}, ValueError, "sample_mesh: give exactly one of n_points and resolution"),
        (SQUARE_V, SQUARE_F, {"n_points": 5, "resolution": 0.1}, ValueError, "give exactly one of n_points and resolution"),
        (SQUARE_V, SQUARE_F, {"n_points": 0}, ValueError, "sample_mesh: n_points must be an int >= 1, got 0"),
        (SQUARE_V, SQUARE_F, {"n_points": 2.5}, TypeError, "sample_mesh: n_points must be an int >= 1, got 2.5"),
        (SQUARE_V, SQUARE_F, {"n_points": True}, TypeError, "n_points must be an int >= 1, got True"),
        (SQUARE_V, SQUARE_F, {"resolution": -1.0}, ValueError, "resolution must be a positive finite float, got -1.0"),
        (SQUARE_V, SQUARE_F, {"resolution": np.inf}, ValueError, "resolution must be a positive finite float, got inf"),
        (SQUARE_V, [[0, 1, 4]], {"n_points": 5}, ValueError, "face indices must lie in 0..3, got 0..4"),
        (SQUARE_V, np.zeros((0, 3), int), {"n_points": 5}, ValueError, "sample_mesh: the mesh has no faces"),
        (SQUARE_V, [[0, 1]], {"n_points": 5}, ValueError, "faces must be an integer array of shape (n_faces, 3)"),
        (SQUARE_V[:, :2], SQUARE_F, {"n_points": 5}, ValueError, "vertices must have shape (n_vertices, 3)"),
        (np.where(SQUARE_V == 1, np.nan, 0), SQUARE_F, {"n_points": 5}, ValueError, "vertices contain NaN"),
        (np.zeros((4, 3)), SQUARE_F, {"n_points": 5}, ValueError, "the mesh has zero surface area (all 2 faces are degenerate)"),
        ([["a", "b", "c"]], [[0, 0, 0]], {"n_points": 5}, TypeError, "vertices must be a numeric array"),
    ],
)
def test_errors(vertices, faces, kwargs, exc, msg):
    with pytest.raises(exc, match=re.escape(msg)):
        sample_mesh(vertices, faces, **kwargs)


@pytest.mark.parametrize("scale", [1e300, 1e-310])
def test_meshes_whose_areas_leave_float64_sample_as_their_unit_copies(scale):
    # the cross products overflowed (1e300) or underflowed (subnormal coordinates): inf or zero areas
    import warnings

    v, f = _tetrahedron()
    ref = sample_mesh(v, f, n_points=300, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = sample_mesh(v * scale, f, n_points=300, random_state=0)
    assert np.isfinite(got).all()
    assert_allclose(got[:, 3:], ref[:, 3:], atol=1e-9)  # the same faces chosen, the same normals
    if scale > 1:
        assert_allclose(got[:, :3] / scale, ref[:, :3], rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match=r"^sample_mesh: the mesh's extent overflows float64"):
        sample_mesh(np.array([[-1e308, 0, 0], [1e308, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]), n_points=10)


def test_a_resolution_finer_than_every_spacing_keeps_every_sample_in_order():
    # 1e-7 on a unit mesh: 1e21 cells, more than an int64 key packs (it wrapped around silently); every
    # sample alone in its cube, the cubes in lexicographic order
    v, f = _tetrahedron()
    samples = sample_mesh(v, f, n_points=3000, random_state=0)
    got = sample_mesh(v, f, resolution=1e-7, n_samples=3000, random_state=0)
    assert_array_equal(got, samples[np.lexsort(samples[:, 2::-1].T)])
    with pytest.raises(ValueError, match=r"^sample_mesh: resolution 4.94066e-324 is too small for the mesh's extent"):
        sample_mesh(v, f, resolution=5e-324, n_samples=100)
