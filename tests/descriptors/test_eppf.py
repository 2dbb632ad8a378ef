"""Tests of EPPFTransformer and its compiled kernel."""

import pickle
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import Pipeline

from tests import eppf_reference as ref
from eppf import FUNCTIONS, EPPFTransformer, KLNearestNeighbors
from eppf.descriptors._eppf_fast import (
    _cone_codes,
    _set_line_walk,
    _set_simd,
    _set_simd_level,
    _simd_levels,
    eppf_counts,
    eppf_pair_features,
    eppf_pairs,
)
from eppf.utils import object_seeds


def _sphere(n, rng, radius=1.0, center=(0.0, 0.0, 0.0)):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return np.hstack([np.asarray(center) + radius * v, v])


def _box(n, rng, size=(1.0, 0.6, 0.3)):
    size = np.asarray(size)
    pts = rng.uniform(-0.5, 0.5, size=(n, 3)) * size
    axis = rng.integers(0, 3, size=n)
    sign = rng.choice([-1.0, 1.0], size=n)
    pts[np.arange(n), axis] = sign * size[axis] / 2
    normals = np.zeros((n, 3))
    normals[np.arange(n), axis] = sign
    return np.hstack([pts, normals])


@pytest.fixture
def clouds():
    rng = np.random.default_rng(42)
    return [_sphere(300, rng), _box(250, rng), _sphere(120, rng, 0.4, (1, 2, 3)), _box(400, rng, (2, 0.2, 0.2))]


def _rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


# ---------------------------------------------------------------- kernel vs reference
@pytest.mark.parametrize("n_bins", [(20, 4, 5, 3), (15, 3, 4, 3), (7, 5, 2, 6)])
@pytest.mark.parametrize("grid", [64, 8, 17])
def test_pair_bins_match_numpy_reference(n_bins, grid):
    rng = np.random.default_rng(grid)
    cloud = np.vstack([_sphere(150, rng)[:, :6], _box(150, rng)])
    cloud[:, :3] *= 0.5
    points = np.ascontiguousarray(cloud[:, :3])
    normals = np.ascontiguousarray(cloud[:, 3:])
    pairs = eppf_pairs(points, 7, 4000)
    got = eppf_pair_features(points, normals, pairs, 0.8, n_bins, grid, ref.F1_MAX)
    want, occ, tot = ref.pair_bins(points, normals, pairs[:, 0], pairs[:, 1], 0.8, n_bins, grid)
    assert_array_equal(got[:, :4], want)
    assert_array_equal(got[:, 4], occ)
    assert_array_equal(got[:, 5], tot)


def test_transform_matches_reference_histogram(clouds):
    est = EPPFTransformer(n_pairs=3000, scaling="object", random_state=3).fit(clouds)
    X = est.transform(clouds)
    seeds = object_seeds(3, len(clouds))
    for k, cloud in enumerate(clouds):
        points = np.ascontiguousarray(cloud[:, :3])
        pairs = eppf_pairs(points, seeds[k], 3000)
        scale = 1.0 / np.ptp(points, axis=0).max()
        want = ref.descriptor(points, cloud[:, 3:], pairs, scale)
        assert_allclose(X[k], want, rtol=1e-12, atol=0)


def _reference_counts(cloud, seed, n_pairs, scale, n_bins, grid):
    points = np.ascontiguousarray(cloud[:, :3])
    pairs = eppf_pairs(points, seed, n_pairs)
    bins, _, _ = ref.pair_bins(points, cloud[:, 3:], pairs[:, 0], pairs[:, 1], scale, n_bins, grid)
    counts = np.zeros(n_bins, dtype=np.int64)
    np.add.at(counts, tuple(bins.T), 1)
    return counts.ravel()


def _packed(clouds):
    points = np.ascontiguousarray(np.vstack([c[:, :3] for c in clouds]))
    normals = np.ascontiguousarray(np.vstack([c[:, 3:] for c in clouds]))
    offsets = np.cumsum([0] + [len(c) for c in clouds]).astype(np.int64)
    return points, normals, offsets


# Every kernel level the CPU has: 0 scalar, 1 AVX2, 2 AVX-512 (draws, f1-f3 and walk in 8 lanes),
# 3 AVX-512 with the walk that skips voxels proved free by the empty cone ahead of a line (walked along
# its dominant axis).
LEVELS = _simd_levels()


def _counts_at(level, *args):
    old = _set_simd_level(level)
    try:
        return eppf_counts(*args)
    finally:
        _set_simd_level(old)


def _line_counts(*args):
    """Counts of the scalar kernel walking every f4 line voxel by voxel (``_line_bin``): the walk
    that every level's skipping walk (portable at levels 0 and 1, AVX-512 at level 3) is compared with."""
    old = _set_line_walk(True)
    try:
        return _counts_at(0, *args)
    finally:
        _set_line_walk(old)


# Grids 64 and <= 64 take the SIMD walks (where the CPU has them), 100 the generic
# walk, n4 = 1 none (the SIMD f1-f3 then write bins rather than queue lines); odd pair
# counts leave partial batches of 256 (1,024 for the skipping walk) and partial groups
# of 4 and 8 lanes.
@pytest.mark.parametrize("grid, n_bins, n_pairs", [
    (64, (20, 4, 5, 3), 1001), (64, (20, 4, 5, 3), 2100), (64, (3, 2, 2, 2), 67), (64, (2, 1, 1, 7), 1),
    (64, (20, 4, 5, 1), 1001),
    (8, (7, 5, 2, 6), 130), (17, (15, 3, 4, 3), 999), (100, (20, 4, 5, 3), 515), (2, (3, 1, 1, 3), 66),
])
def test_counts_match_reference_on_every_walk(clouds, grid, n_bins, n_pairs):
    seeds = object_seeds(5, len(clouds))
    points, normals, offsets = _packed(clouds)
    scales = np.full(len(clouds), 0.3)
    for level in LEVELS:
        got, status = _counts_at(level, points, normals, offsets, scales, seeds, n_pairs, n_bins, grid, ref.F1_MAX, 2)
        assert not status.any()
        for k, cloud in enumerate(clouds):
            want = _reference_counts(cloud, seeds[k], n_pairs, 0.3, n_bins, grid)
            assert_array_equal(got[k], want)


@pytest.mark.parametrize("simd", [True, False])
def test_huge_distances_fall_in_the_last_distance_bin(clouds, simd):
    # dist * scale * density far beyond the int range must clamp, not wrap around.
    seeds = object_seeds(8, len(clouds))
    points, normals, offsets = _packed(clouds)
    old = _set_simd(simd)
    try:
        got, _ = eppf_counts(points, normals, offsets, np.full(len(clouds), 1e15), seeds, 500, (20, 4, 5, 3), 64,
                             ref.F1_MAX, 1)
    finally:
        _set_simd(old)
    for k, cloud in enumerate(clouds):
        assert_array_equal(got[k], _reference_counts(cloud, seeds[k], 500, 1e15, (20, 4, 5, 3), 64))
    assert got.reshape(len(clouds), 20, -1)[:, 19].sum() == 500 * len(clouds)


@pytest.mark.parametrize("grid", [64, 63, 33, 32, 5, 2, 128])
@pytest.mark.parametrize("n4", [2, 3, 6, 64])
def test_simd_and_scalar_walks_give_identical_counts(grid, n4):
    # Dense and sparse occupancy, long and short lines: every stopping rule of the walk,
    # and (level 3) skips over free voxels at every distance, up to the grid's faces.
    rng = np.random.default_rng(grid * n4)
    clouds = [_sphere(600, rng), _box(900, rng), np.hstack([rng.uniform(size=(3000, 3)), _sphere(3000, rng)[:, 3:]])]
    points, normals, offsets = _packed(clouds)
    seeds = object_seeds(grid, len(clouds))
    args = (points, normals, offsets, np.ones(len(clouds)), seeds, 3001, (4, 1, 1, n4), grid, ref.F1_MAX, 1)
    slow, _ = _line_counts(*args)
    for level in LEVELS:
        fast, _ = _counts_at(level, *args)
        assert_array_equal(fast, slow)
    assert (slow.reshape(len(clouds), 4, n4)[:, :, 1:].sum() > 0)  # not every pair in the bottom f4 bin



@pytest.mark.parametrize("spacing", [1, 2, 3, 4, 7])
@pytest.mark.parametrize("n4", [3, 5])
def test_walks_on_lattices_give_identical_counts(spacing, n4):
    # Points on a voxel lattice (every ``spacing``-th voxel, some left out): lines run along
    # and across rows of occupied voxels, so free distances of 1, 2, 3 and more lie next to
    # occupied voxels on the same lines, where a skip one voxel too long would miss a count.
    rng = np.random.default_rng(spacing * 10 + n4)
    axis = np.arange(0, 64, spacing) + 0.5
    grid_pts = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    keep = rng.uniform(size=len(grid_pts)) < min(1.0, 1500 / len(grid_pts))
    pts = np.vstack([grid_pts[keep], [[0.0, 0.0, 0.0], [64.0, 64.0, 64.0]]])
    cloud = np.hstack([pts, _sphere(len(pts), rng)[:, 3:]])
    points, normals, offsets = _packed([cloud])
    args = (points, normals, offsets, np.ones(1), object_seeds(spacing, 1), 5000, (2, 1, 1, n4), 64,
            ref.F1_MAX, 1)
    slow, _ = _line_counts(*args)
    for level in LEVELS:
        assert_array_equal(_counts_at(level, *args)[0], slow)
    # dense enough lattices put some lines above the bottom f4 bin
    assert spacing > 4 or slow.reshape(2, n4)[:, 1:].sum() > 0

def _cone_codes_reference(occupied):
    """min(C, 3) per axis and voxel, C the number of empty planes of the cone ahead along the axis.

    Written from the definition: C = 0 at an occupied voxel, else 1 + the smallest C of the 3 x 3
    voxels of the next plane (voxels past the grid count as free, C = 3 at the last plane)."""
    g = occupied.shape[0]
    out = np.zeros((3,) + occupied.shape, dtype=np.uint8)
    for a in range(3):
        occ = np.moveaxis(occupied, a, 0)
        code = np.zeros(occ.shape, dtype=np.int64)
        nxt = np.full((g + 2, g + 2), 3, dtype=np.int64)  # the plane past the grid, padded by free voxels
        for s in range(g - 1, -1, -1):
            box = np.min([nxt[1 + u : g + 1 + u, 1 + v : g + 1 + v] for u in (-1, 0, 1) for v in (-1, 0, 1)], axis=0)
            code[s] = np.where(occ[s], 0, np.minimum(box + 1, 3))
            nxt[1 : g + 1, 1 : g + 1] = code[s]
        out[a] = np.moveaxis(code, 0, a)
    return out


@pytest.mark.parametrize("portable", [False, True])
@pytest.mark.parametrize("grid", [64, 63, 33, 32, 17, 2])
@pytest.mark.parametrize("density", [0.002, 0.05, 0.5])
def test_cone_codes_match_reference(grid, density, portable):
    # The skipping walks' proof of empty voxels: every code of all three cone grids, at the
    # grid's faces too, against the definition (level 3: 64 takes the in-register build, others
    # the generic one; levels 0 and 1: the portable build, on every CPU).
    if not portable and 3 not in LEVELS:
        pytest.skip("the AVX-512 cone codes need the AVX-512 kernels")
    rng = np.random.default_rng(int(grid * 1000 * density))
    occupied = rng.uniform(size=(grid, grid, grid)) < density
    occupied[0, 0, 0] = occupied[-1, -1, -1] = True
    got = _cone_codes(occupied, portable)
    want = _cone_codes_reference(occupied)
    assert_array_equal(got, want)
    if density < 0.01 and grid >= 32:
        assert (got == 3).any() and (got == 2).any() and (got == 1).any()  # every skip length occurs


@pytest.mark.parametrize("grid", [64, 63, 17])
@pytest.mark.parametrize("n4", [3, 4])
def test_walks_near_planes_give_identical_counts(grid, n4):
    # Points on planes across each axis and on lines along them: lines are walked along their
    # dominant axis in either direction (backwards where it decreases), past cones that a plane
    # cuts off on one side only, and some run inside a plane.
    rng = np.random.default_rng(grid + n4)
    parts = []
    for a in range(3):
        for level in (0.1, 0.55, 0.9):
            p = rng.uniform(size=(150, 3))
            p[:, a] = level
            parts.append(p)
        q = np.full((40, 3), 0.3 + 0.2 * a)
        q[:, a] = np.linspace(0.0, 1.0, 40)
        parts.append(q)
    pts = np.vstack(parts + [[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]])
    cloud = np.hstack([pts, _sphere(len(pts), rng)[:, 3:]])
    points, normals, offsets = _packed([cloud])
    seed = object_seeds(grid, 1)
    args = (points, normals, offsets, np.ones(1), seed, 4001, (2, 1, 1, n4), grid, ref.F1_MAX, 1)
    want = _reference_counts(cloud, seed[0], 4001, 1.0, (2, 1, 1, n4), grid)
    for level in LEVELS:
        assert_array_equal(_counts_at(level, *args)[0][0], want)
    assert want.reshape(2, n4)[:, 1:].sum() > 0  # some lines above the bottom f4 bin


def test_objects_past_the_row_copy_limit_match_reference():
    # Objects up to 65,536 points have their points and normals copied into rows of eight
    # doubles for the AVX-512 f1-f3; a larger one is read in place; both beside each other.
    rng = np.random.default_rng(65)
    clouds = [_sphere(70000, rng), _box(500, rng)]
    points, normals, offsets = _packed(clouds)
    seeds = object_seeds(65, len(clouds))
    args = (points, normals, offsets, np.full(2, 0.5), seeds, 300, (20, 4, 5, 3), 64, ref.F1_MAX, 1)
    want = [_reference_counts(c, seeds[k], 300, 0.5, (20, 4, 5, 3), 64) for k, c in enumerate(clouds)]
    for level in LEVELS:
        got, _ = _counts_at(level, *args)
        for k in range(2):
            assert_array_equal(got[k], want[k])
    small, _ = _counts_at(LEVELS[-1], *_packed(clouds[1:]), np.full(1, 0.5), seeds[1:], 300, (20, 4, 5, 3), 64,
                          ref.F1_MAX, 1)
    assert_array_equal(small[0], want[1])


def _first_coinciding_draw(points, seed, n_draws):
    """Index of the first of ``n_draws`` splitmix64 candidate pairs whose points coincide, or None.

    Written from the generator's definition (Python integers), independently of the kernel."""
    mask, n, state = (1 << 64) - 1, len(points), int(seed)
    for k in range(n_draws):
        state = (state + 0x9E3779B97F4A7C15) & mask
        z = ((state ^ (state >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        z ^= z >> 31
        i, j = ((z >> 32) * n) >> 32, ((z & 0xFFFFFFFF) * (n - 1)) >> 32
        j += j >= i
        if (points[i] == points[j]).all():
            return k
    return None


@pytest.mark.parametrize("n_pairs", [1, 9, 300, 2001, 6000])
def test_draws_past_coinciding_points_match_reference_at_every_level(n_pairs):
    # The SIMD draws (AVX2 and AVX-512) skip the check for coinciding points and leave the rest
    # of the object to the scalar draw (with its redraws) from the first such
    # candidate on; the pairs must be the ones eppf_pairs draws one at a time.
    rng = np.random.default_rng(n_pairs)
    early = _sphere(40, rng)
    early[20:] = early[:20]  # half the points repeated: a coinciding candidate in the first batch
    late = _sphere(60, rng)
    late[59] = late[0]  # one repeated point: for 2001 pairs, the first coinciding candidate comes after batch one
    heavy = _sphere(30, rng)
    heavy[2:] = heavy[0]  # 29 of 30 points equal: most draws are redrawn
    later = _sphere(120, rng)
    later[119] = later[0]  # for 6000 pairs, the first coinciding candidate comes after the first 1,024
    clouds = [early, late, _sphere(2, rng), _sphere(500, rng), heavy, later]
    seeds = object_seeds(n_pairs, len(clouds))
    if n_pairs == 2001:
        assert _first_coinciding_draw(early[:, :3], seeds[0], n_pairs) < 256
        assert 256 < _first_coinciding_draw(late[:, :3], seeds[1], n_pairs) < n_pairs
        assert _first_coinciding_draw(clouds[3][:, :3], seeds[3], n_pairs) is None
    if n_pairs == 6000:
        assert 1024 < _first_coinciding_draw(later[:, :3], seeds[5], n_pairs) < n_pairs
    points, normals, offsets = _packed(clouds)
    args = (points, normals, offsets, np.full(len(clouds), 0.4), seeds, n_pairs, (6, 3, 2, 3), 64, ref.F1_MAX, 2)
    want = [_reference_counts(c, seeds[k], n_pairs, 0.4, (6, 3, 2, 3), 64) for k, c in enumerate(clouds)]
    for level in LEVELS:
        got, status = _counts_at(level, *args)
        assert not status.any()
        for k in range(len(clouds)):
            assert_array_equal(got[k], want[k])


def test_coinciding_cloud_is_reported_at_every_level():
    # all points equal: no pair can be drawn, on every path
    cloud = np.tile(np.array([[0.5, 0.5, 0.5, 0.0, 0.0, 1.0]]), (20, 1))
    points, normals, offsets = _packed([cloud])
    for level in LEVELS:
        _, status = _counts_at(level, points, normals, offsets, np.ones(1), np.array([3], dtype=np.uint64), 100,
                               (20, 4, 5, 3), 64, ref.F1_MAX, 1)
        assert status[0] == 1


@pytest.mark.parametrize("grid", [2, 17, 64])
def test_every_level_counts_every_pair_of_non_finite_clouds(grid):
    # Overflowing sides, NaN/inf scales and coordinates: every level clamps its
    # indices (each pair still lands in a bin) and all levels agree bit for bit.
    rng = np.random.default_rng(grid)
    huge = rng.normal(size=(300, 6))
    huge[0, 0], huge[1, 0] = 1e308, -1e308
    odd = rng.normal(size=(200, 6))
    odd[5, :3] = np.inf
    odd[6, 1] = np.nan
    points, normals, offsets = _packed([huge, odd])
    seeds = object_seeds(11, 2)
    for scale in (1.0, np.inf, np.nan, -1.0):
        args = (points, normals, offsets, np.full(2, scale), seeds, 777, (5, 4, 3, 3), grid, ref.F1_MAX, 1)
        want, _ = _line_counts(*args)
        assert (want.sum(axis=1) == 777).all()
        for level in LEVELS:
            assert_array_equal(_counts_at(level, *args)[0], want)


def test_levels_agree_on_the_voxel_grid_of_edge_case_clouds():
    # The AVX-512 levels voxelise eight points at a time (bounding box lane by lane,
    # then across lanes): objects shorter than eight points or one past a multiple of
    # it, a NaN first point (the scalar loop's box keeps it), box extremes that are
    # +0 and -0 in either order, flat objects (two zero extents) and points on the
    # voxel boundaries must give every level the scalar kernel's counts.
    rng = np.random.default_rng(44)
    normal = np.array([0.0, 0.0, 1.0])

    def cloud(p):
        return np.hstack([p, np.tile(normal, (len(p), 1))])

    zeros = rng.normal(size=(40, 3))
    zeros[[3, 20], 0] = [-0.0, 0.0]
    zeros[:, 0] = np.abs(zeros[:, 0])  # the x minimum is a zero (+0 and -0 both present)
    zeros2 = zeros.copy()
    zeros2[[3, 20], 0] = [0.0, -0.0]
    first_nan = rng.normal(size=(25, 3))
    first_nan[0, 1] = np.nan
    flat = np.column_stack([rng.normal(size=33), np.zeros(33), np.zeros(33)])
    lattice = np.stack(np.meshgrid(*[np.arange(5.0)] * 3), axis=-1).reshape(-1, 3) / 4.0
    clouds = [cloud(rng.normal(size=(n, 3))) for n in (2, 3, 7, 8, 9, 15, 17)]
    clouds += [cloud(zeros), cloud(zeros2), cloud(first_nan), cloud(flat), cloud(lattice)]
    points, normals, offsets = _packed(clouds)
    seeds = object_seeds(8, len(clouds))
    for grid in (2, 17, 64):
        args = (points, normals, offsets, np.ones(len(clouds)), seeds, 900, (5, 4, 3, 3), grid, ref.F1_MAX, 1)
        want, status = _line_counts(*args)
        assert not status.any()
        for k in (0, 4, 5, 11):  # finite clouds against the NumPy reference
            assert_array_equal(want[k], _reference_counts(clouds[k], seeds[k], 900, 1.0, (5, 4, 3, 3), grid))
        for level in LEVELS:
            assert_array_equal(_counts_at(level, *args)[0], want)


def test_levels_agree_on_strided_mixed_size_objects_with_odd_normals_and_two_threads():
    # The AVX-512 f1-f3 read every point with its normal from a per-object,
    # per-thread copy in 64-byte rows built from strided input: objects of very
    # different sizes in one call (the copy sized for the largest), both threads'
    # copies, normals read through the second half of one (N, 6) block, and normals
    # that are NaN, infinite, zero or not unit length; every level must agree with
    # the scalar kernel and with the NumPy reference.
    rng = np.random.default_rng(2026)
    clouds = [_sphere(9, rng), _box(2500, rng), _sphere(300, rng), _box(17, rng), _sphere(1100, rng)]
    clouds[2][:, 3:] *= 3.0
    clouds[2][4, 3:] = np.nan
    clouds[2][5, 4] = np.inf
    clouds[2][6, 3:] = 0.0
    block = np.vstack(clouds)
    offsets = np.cumsum([0] + [len(c) for c in clouds]).astype(np.int64)
    seeds = object_seeds(5, len(clouds))
    scales = rng.uniform(0.5, 2.0, size=len(clouds))
    args = (block[:, :3], block[:, 3:], offsets, scales, seeds, 1003, (7, 4, 5, 3), 64, ref.F1_MAX, 2)
    want, _ = _line_counts(*args)
    for k, c in enumerate(clouds):
        if k != 2:  # the reference assumes finite normals
            assert_array_equal(want[k], _reference_counts(c, seeds[k], 1003, scales[k], (7, 4, 5, 3), 64))
    for level in LEVELS:
        assert_array_equal(_counts_at(level, *args)[0], want)
        one, _ = _counts_at(level, *args[:-1], 1)
        assert_array_equal(one, want)


@pytest.mark.parametrize("n4", [2, 3, 4, 64])
def test_levels_agree_on_dense_lattices_for_every_f4_bin_count(n4):
    # Lines inside a fully occupied plane and along a full row of the 64 grid: up to
    # 62 occupied inner voxels a line, the extremes of the skipping walk's byte
    # counters (and, at n4 = 64, thresholds one voxel apart), for every level.
    rng = np.random.default_rng(n4)
    u, v = np.meshgrid(np.arange(64.0), np.arange(64.0))
    plane = np.column_stack([u.ravel(), v.ravel(), np.full(u.size, 31.0)])
    row = np.column_stack([np.arange(64.0), np.full(64, 63.0), np.zeros(64)])
    scatter = rng.uniform(0, 63, size=(200, 3))
    cloud = np.vstack([plane, row, scatter])
    cloud = np.hstack([cloud, np.tile([0.0, 0.0, 1.0], (len(cloud), 1))])
    points, normals, offsets = _packed([cloud])
    seeds = object_seeds(21, 1)
    n_bins = (2, 1, 1, n4)
    args = (points, normals, offsets, np.ones(1), seeds, 1500, n_bins, 64, ref.F1_MAX, 1)
    want, _ = _line_counts(*args)
    assert_array_equal(want[0], _reference_counts(cloud, seeds[0], 1500, 1.0, n_bins, 64))
    assert want[0].reshape(-1, n4)[:, -1].sum() > 100  # many lines in the top bin
    for level in LEVELS:
        assert_array_equal(_counts_at(level, *args)[0], want)


def test_levels_agree_on_an_object_too_large_for_the_row_copy():
    # Past 65,536 points the SIMD f1-f3 (levels 1 to 3) read the points in place and the
    # skipping walk, which needs the row copy, hands over to the grouped one.
    rng = np.random.default_rng(7)
    clouds = [_box(70_000, rng), _sphere(500, rng)]
    points, normals, offsets = _packed(clouds)
    seeds = object_seeds(3, 2)
    args = (points, normals, offsets, np.full(2, 0.8), seeds, 700, (5, 4, 3, 3), 64, ref.F1_MAX, 1)
    want, _ = _line_counts(*args)
    assert_array_equal(want[1], _reference_counts(clouds[1], seeds[1], 700, 0.8, (5, 4, 3, 3), 64))
    for level in LEVELS:
        assert_array_equal(_counts_at(level, *args)[0], want)


def test_kernel_levels_report_what_the_cpu_has():
    assert LEVELS[0] == 0 and list(LEVELS) == list(range(len(LEVELS)))
    old = _set_simd_level(99)  # capped at the best level the CPU has
    try:
        assert _set_simd_level(old) == LEVELS[-1]
    finally:
        _set_simd_level(old)
    old = _set_simd(False)
    try:
        assert _set_simd_level(LEVELS[-1]) == 0
        assert _set_simd(False) is (len(LEVELS) > 1)
    finally:
        _set_simd(old)


def test_pairs_are_distinct_and_in_range():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(50, 3))
    pts[10:20] = pts[0]  # duplicates must never be paired with each other
    pairs = eppf_pairs(pts, 11, 5000)
    assert pairs.min() >= 0 and pairs.max() < 50
    assert np.all(np.any(pts[pairs[:, 0]] != pts[pairs[:, 1]], axis=1))
    # both orders occur: the pair order is never canonicalised
    assert np.any(pairs[:, 0] < pairs[:, 1]) and np.any(pairs[:, 0] > pairs[:, 1])


# ---------------------------------------------------------------- hand-computed cases
def test_occupancy_hand_computed_paper_style():
    # An 8-voxel grid over the unit cube: voxel (i, j, k) holds [i/8, (i+1)/8) etc.
    # The line from voxel (0, 0, 0) to voxel (7, 3, 0) visits, for k = 0..7,
    # x = k, y = floor(3k/7 + 1/2) = 0, 0, 1, 1, 2, 2, 3, 3.
    centre = lambda i, j, k: [(i + 0.5) / 8, (j + 0.5) / 8, (k + 0.5) / 8]  # noqa: E731
    pts = [centre(0, 0, 0), centre(7, 3, 0), centre(2, 1, 0), centre(5, 2, 0), centre(4, 0, 0)]
    pts += [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]  # fix the bounding cube to [0, 1]^3
    pts = np.ascontiguousarray(pts, dtype=float)
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    pairs = np.array([[0, 1], [1, 0], [0, 4], [5, 6]], dtype=np.int64)
    out = eppf_pair_features(pts, normals, pairs, 1.0, (2, 2, 2, 13), 8, ref.F1_MAX)
    # (0,0,0) -> (7,3,0): 8 voxels, occupied: both ends, (2,1,0), (5,2,0) -> 4/8
    assert out[0, 4:].tolist() == [4, 8]
    assert out[1, 4:].tolist() == [4, 8]  # symmetric in the pair
    assert out[0, 3] == (13 * 4) // 8
    # (0,0,0) -> (4,0,0): 5 voxels, only the ends occupied: 2/5
    assert out[2, 4:].tolist() == [2, 5]
    # corner to corner (0,0,0) -> (7,7,7): 8 voxels; (0,0,0) and (7,7,7) occupied
    assert out[3, 4:].tolist() == [2, 8]


def test_occupancy_is_one_within_a_voxel():
    pts = np.array([[0.0, 0, 0], [0.01, 0, 0], [1, 1, 1]])
    normals = np.tile([1.0, 0, 0], (3, 1))
    out = eppf_pair_features(pts, normals, np.array([[0, 1]]), 1.0, (2, 2, 2, 3), 64, ref.F1_MAX)
    assert out[0, 4:].tolist() == [1, 1]
    assert out[0, 3] == 2  # f4 = 1 falls in the last bin


def test_line_walk_exact_for_all_directions():
    # Every voxel step of the fixed-point walk equals floor(k * delta / L + 1/2);
    # check all end voxels of an empty 64^3 grid reachable from a corner and the centre.
    grid = 64
    rng = np.random.default_rng(5)
    for start in ([0, 0, 0], [31, 40, 7]):
        ends = rng.integers(0, grid, size=(300, 3))
        for end in ends:
            line = ref.line_voxels(start, end)
            # occupy exactly the reference line's voxels plus the far corner (to fix the grid)
            cells = np.vstack([line, [[0, 0, 0], [grid - 1, grid - 1, grid - 1]]])
            pts = (cells + 0.5) / grid
            normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
            pts[-2] = 0.0
            pts[-1] = 1.0
            out = eppf_pair_features(np.ascontiguousarray(pts), normals, np.array([[0, len(line) - 1]]),
                                     1.0, (1, 1, 1, 2), grid, ref.F1_MAX)
            assert out[0, 4] == out[0, 5] == len(line), (start, end)


@pytest.mark.parametrize(
    "dist, expected",
    [(0.0, 0), (np.sqrt(3) / 20 * 0.999, 0), (np.sqrt(3) / 20 * 1.001, 1), (np.sqrt(3), 19), (5.0, 19)],
)
def test_distance_bin_edges(dist, expected):
    pts = np.array([[0.0, 0.0, 0.0], [dist + 1e-300, 0.0, 0.0], [0.0, 1.0, 0.0]])
    if dist == 0.0:
        pts[1, 0] = 1e-12
    normals = np.tile([0.0, 0.0, 1.0], (3, 1))
    out = eppf_pair_features(pts, normals, np.array([[0, 1]]), 1.0, (20, 4, 5, 3), 64, ref.F1_MAX)
    assert out[0, 0] == expected


@pytest.mark.parametrize(
    "n1, n2, expected",
    [
        # d = +x; beta_k = arccos(n_k . d) - pi/2; f2 = max -> bin of 4 over [-pi/2, pi/2]
        ([1, 0, 0], [1, 0, 0], 0),  # both betas -pi/2
        ([-1, 0, 0], [-1, 0, 0], 3),  # both +pi/2 -> top edge, last bin
        ([0, 0, 1], [1, 0, 0], 2),  # max(0, -pi/2) = 0 -> bin 2
        ([np.cos(0.3), np.sin(0.3), 0], [1, 0, 0], 0),  # beta1 = 0.3 - pi/2 -> bin 0
        ([np.cos(2.0), np.sin(2.0), 0], [1, 0, 0], 2),  # beta1 = 2.0 - pi/2 = 0.43 -> bin 2
    ],
)
def test_angle_bins_hand_computed(n1, n2, expected):
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]])
    normals = np.array([n1, n2, [0, 0, 1]], dtype=float)
    out = eppf_pair_features(pts, normals, np.array([[0, 1]]), 1.0, (20, 4, 5, 3), 64, ref.F1_MAX)
    assert out[0, 1] == expected


@pytest.mark.parametrize(
    "angle, expected",
    [(0.0, 0), (np.pi, 0), (np.pi / 2, 4), (0.2, 0), (0.35, 1), (np.pi - 0.35, 1), (1.2, 3)],
)
def test_normal_bins_hand_computed(angle, expected):
    # f3 = arccos(|n1 . n2|) in 5 bins of pi/10 over [0, pi/2]
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]])
    normals = np.array([[0, 0, 1.0], [0, np.sin(angle), np.cos(angle)], [0, 0, 1.0]])
    out = eppf_pair_features(pts, normals, np.array([[0, 1]]), 1.0, (20, 4, 5, 3), 64, ref.F1_MAX)
    assert out[0, 2] == expected


# ---------------------------------------------------------------- transformer behaviour
def test_output_shape_sum_and_dtype(clouds):
    X = EPPFTransformer(n_pairs=2000, random_state=0).fit_transform(clouds)
    assert X.shape == (4, 1200)
    assert X.dtype == np.float64
    assert np.all(X >= 0)
    assert_allclose(X.sum(axis=1), 1.0)


def test_weighting_follows_log_formula(clouds):
    est = EPPFTransformer(n_pairs=2000, c=1.5, scaling="object", random_state=0).fit(clouds)
    H = est.to_histogram(est.transform(clouds))
    plain = EPPFTransformer(n_pairs=2000, c=1e9, scaling="object", random_state=0).fit(clouds)
    P = plain.to_histogram(plain.transform(clouds))  # c -> inf: weights become equal
    alpha = np.log(np.arange(20) / 20 + 1.5)
    W = P * alpha[None, :, None, None, None]
    W /= W.sum(axis=(1, 2, 3, 4), keepdims=True)
    assert_allclose(H, W, rtol=1e-6)


def test_thread_count_and_repeat_determinism(clouds):
    X1 = EPPFTransformer(n_pairs=3000, random_state=1, n_jobs=1).fit_transform(clouds * 3)
    X2 = EPPFTransformer(n_pairs=3000, random_state=1, n_jobs=2).fit_transform(clouds * 3)
    X3 = EPPFTransformer(n_pairs=3000, random_state=1, n_jobs=2).fit_transform(clouds * 3)
    assert_array_equal(X1, X2)
    assert_array_equal(X2, X3)
    X4 = EPPFTransformer(n_pairs=3000, random_state=2).fit_transform(clouds * 3)
    assert not np.array_equal(X1, X4)


def test_prefix_of_input_gives_prefix_of_output(clouds):
    est = EPPFTransformer(n_pairs=1000, random_state=4, scaling="object").fit(clouds)
    assert_array_equal(est.transform(clouds)[:2], est.transform(clouds[:2]))


def test_rotation_invariance_of_f1_to_f3(clouds):
    rng = np.random.default_rng(9)
    funcs = ("distance", "angle", "normal")
    est = EPPFTransformer(n_pairs=20000, functions=funcs, scaling="none", random_state=0).fit(clouds)
    # curved objects only: on a box, pairs on one face have n . d == 0 exactly, on
    # f2's bin edge, and rounding after a rotation moves them across it legitimately
    small = [np.hstack([c[:, :3] / (2 * np.abs(c[:, :3]).max()), c[:, 3:]]) for c in clouds[::2]]
    X = est.transform(small)
    R = _rotation(rng)
    rotated = [np.hstack([c[:, :3] @ R.T, c[:, 3:] @ R.T]) for c in small]
    Xr = est.transform(rotated)
    # the same pairs are drawn; only pairs within rounding of a bin edge may move
    assert np.abs(X - Xr).sum(axis=1).max() < 2e-3


@pytest.mark.parametrize("scaling", ["fit", "object"])
def test_scaling_modes_are_invariant_to_exact_rescaling(clouds, scaling):
    big = [np.hstack([c[:, :3] * 4.0, c[:, 3:]]) for c in clouds]
    X = EPPFTransformer(n_pairs=2000, scaling=scaling, random_state=0).fit_transform(clouds)
    Xb = EPPFTransformer(n_pairs=2000, scaling=scaling, random_state=0).fit_transform(big)
    assert_array_equal(X, Xb)


def test_fit_scale_is_learned_from_training_set(clouds):
    est = EPPFTransformer(scaling="fit").fit(clouds)
    assert est.scale_ == pytest.approx(1.0 / 2.0)  # the (2, 0.2, 0.2) box is the largest
    assert EPPFTransformer(scaling="object").fit(clouds).scale_ is None


def test_dropping_a_function_marginalises_the_histogram(clouds):
    full = EPPFTransformer(n_pairs=3000, random_state=5, scaling="object").fit(clouds)
    H = full.to_histogram(full.transform(clouds))
    for axis, name in [(4, "occupancy"), (3, "normal"), (2, "angle")]:
        funcs = tuple(f for f in FUNCTIONS if f != name)
        part = EPPFTransformer(n_pairs=3000, random_state=5, scaling="object", functions=funcs).fit(clouds)
        Xp = part.transform(clouds)
        assert Xp.shape[1] == 1200 // full.n_bins_[axis - 1]
        assert_allclose(part.to_histogram(Xp), H.sum(axis=axis), rtol=1e-12, atol=1e-15)


def test_functions_subset_without_normals_needs_no_normals():
    rng = np.random.default_rng(0)
    clouds = [rng.normal(size=(2, 3)) for _ in range(2)]  # too small for normal estimation
    X = EPPFTransformer(n_pairs=100, functions=("distance", "occupancy"), random_state=0).fit_transform(clouds)
    assert X.shape == (2, 60)


def test_estimated_normals_equal_given_normals(clouds):
    from eppf import estimate_normals

    xyz = [c[:, :3] for c in clouds]
    given = [np.hstack([p, estimate_normals(p, 12)]) for p in xyz]
    a = EPPFTransformer(n_pairs=2000, n_neighbors=12, random_state=0).fit(xyz).transform(xyz)
    b = EPPFTransformer(n_pairs=2000, n_neighbors=12, random_state=0).fit(given).transform(given)
    assert_array_equal(a, b)
    # clouds of both widths (validated one by one, normals estimated for the three-column ones only)
    mixed = [given[k] if k % 2 else xyz[k] for k in range(len(xyz))]
    c = EPPFTransformer(n_pairs=2000, n_neighbors=12, random_state=0).fit(mixed).transform(mixed)
    assert_array_equal(a, c)


def test_feature_names_and_histogram_view(clouds):
    est = EPPFTransformer(n_bins=(15, 3, 4, 3), n_pairs=500, random_state=0).fit(clouds)
    names = est.get_feature_names_out()
    assert names.shape == (540,)
    assert names[0] == "eppf_d00_a0_n0_o0"
    assert names[1] == "eppf_d00_a0_n0_o1"
    assert names[-1] == "eppf_d14_a2_n3_o2"
    X = est.transform(clouds)
    assert est.to_histogram(X).shape == (4, 15, 3, 4, 3)
    assert est.to_histogram(X[0]).shape == (15, 3, 4, 3)
    # flat index = ((i1 * N2 + i2) * N3 + i3) * N4 + i4
    H = est.to_histogram(X)
    assert H[1, 2, 1, 3, 2] == X[1, ((2 * 3 + 1) * 4 + 3) * 3 + 2]


def test_eppf_short_has_540_bins(clouds):
    X = EPPFTransformer(n_bins=(15, 3, 4, 3), n_pairs=1000, random_state=0).fit_transform(clouds)
    assert X.shape == (4, 540)
    assert_allclose(X.sum(axis=1), 1.0)


def test_accepts_3d_array_and_float32():
    rng = np.random.default_rng(0)
    arr = rng.normal(size=(3, 100, 3)).astype(np.float32)
    X = EPPFTransformer(n_pairs=500, random_state=0).fit_transform(arr)
    assert X.shape == (3, 1200)


def test_pickle_and_clone_round_trip(clouds):
    est = EPPFTransformer(n_pairs=1000, random_state=0).fit(clouds)
    again = pickle.loads(pickle.dumps(est))
    assert_array_equal(est.transform(clouds), again.transform(clouds))
    assert clone(est).get_params() == est.get_params()


def test_pipeline_and_grid_search_over_bins_and_c():
    rng = np.random.default_rng(0)
    X = [_sphere(200, rng)[:, :3] * rng.uniform(0.8, 1.2) for _ in range(8)]
    X += [_box(200, rng)[:, :3] * rng.uniform(0.8, 1.2) for _ in range(8)]
    y = np.array(["sphere"] * 8 + ["box"] * 8)
    pipe = Pipeline([("eppf", EPPFTransformer(n_pairs=1000, random_state=0)), ("knn", KLNearestNeighbors())])
    grid = GridSearchCV(
        pipe, {"eppf__n_bins": [(20, 4, 5, 3), (15, 3, 4, 3)], "eppf__c": [1.2, 2.0]}, cv=2,
    )
    grid.fit(X, y)
    assert set(grid.cv_results_["param_eppf__c"]) == {1.2, 2.0}
    assert grid.best_score_ >= 0.9
    assert set(grid.predict(X)) <= {"sphere", "box"}


# ---------------------------------------------------------------- errors
def _err(X, match, exc=ValueError, **params):
    est = EPPFTransformer(**{"n_pairs": 100, **params})
    with pytest.raises(exc, match=re.escape(match)):
        est.fit_transform(X)


@pytest.mark.parametrize(
    "X, match, exc",
    [
        ([], "EPPFTransformer: X is empty", ValueError),
        (None, "EPPFTransformer: X must be a list of point clouds", TypeError),
        ("cloud.ply", "EPPFTransformer: X must be a list of point clouds", TypeError),
        (np.zeros((10, 3)), "EPPFTransformer: X is a single 2D array of shape (10, 3)", ValueError),
        ([np.zeros((0, 3))], "EPPFTransformer: point cloud 0 has 0 points; at least 2 are needed", ValueError),
        ([np.ones((1, 3))], "EPPFTransformer: point cloud 0 has 1 point; at least 2 are needed", ValueError),
        ([np.ones((5, 3))], "EPPFTransformer: point cloud 0 has all 5 points identical", ValueError),
        ([np.ones((5, 2))], "EPPFTransformer: point cloud 0 must have shape (n_points, 3) or (n_points, 6)", ValueError),
        ([np.ones(5)], "EPPFTransformer: point cloud 0 must have shape", ValueError),
        ([np.array([["a", "b", "c"]] * 3)], "EPPFTransformer: point cloud 0 must hold numbers", TypeError),
        ([np.eye(3), np.array([[0, 0, np.nan], [1, 1, 1]])], "EPPFTransformer: point cloud 1 contains NaN or infinite", ValueError),
        ([np.array([[0, 0, np.inf], [1, 1, 1]])], "EPPFTransformer: point cloud 0 contains NaN or infinite", ValueError),
        ([np.hstack([np.eye(3), np.zeros((3, 3))])], "EPPFTransformer: point cloud 0 has 3 zero-length normal(s)", ValueError),
    ],
)
def test_bad_input_raises(X, match, exc):
    _err(X, match, exc)


_FUNCTIONS = ("functions must be a non-empty sequence of distinct names from "
              "('distance', 'angle', 'normal', 'occupancy'), got ")


@pytest.mark.parametrize(
    "params, match, exc",
    [
        ({"n_bins": (20, 4, 5)}, "n_bins must be a tuple of 4 ints in [1, 64] (bins of f1, f2, f3, f4), "
                                 "got (20, 4, 5)", ValueError),
        ({"n_bins": (20, 0, 5, 3)}, "n_bins must be a tuple of 4 ints in [1, 64] (bins of f1, f2, f3, f4), "
                                    "got (20, 0, 5, 3)", ValueError),
        ({"n_bins": (20, 4.5, 5, 3)}, "n_bins must be a tuple of 4 ints in [1, 64] (bins of f1, f2, f3, f4), "
                                      "got (20, 4.5, 5, 3)", TypeError),
        ({"n_bins": 20}, "n_bins must be a tuple of 4 ints in [1, 64] (bins of f1, f2, f3, f4), got 20", TypeError),
        ({"n_pairs": 0}, "n_pairs must be an int in [1, 2147483647], got 0", ValueError),
        ({"n_pairs": 10.0}, "n_pairs must be an int in [1, 2147483647], got 10.0", TypeError),
        ({"c": 1.0}, "c must be a finite float > 1 (so that ln(i/N + c) > 0), got 1.0", ValueError),
        ({"c": float("nan")}, "c must be a finite float > 1 (so that ln(i/N + c) > 0), got nan", ValueError),
        ({"c": "1.2"}, "c must be a finite float > 1 (so that ln(i/N + c) > 0), got '1.2'", TypeError),
        ({"grid_size": 1}, "grid_size must be an int in [2, 1023], got 1", ValueError),
        ({"functions": ("distance", "colour")}, _FUNCTIONS + "('distance', 'colour')", ValueError),
        ({"functions": ()}, _FUNCTIONS + "()", ValueError),
        ({"functions": ("angle", "angle")}, _FUNCTIONS + "('angle', 'angle')", ValueError),
        ({"scaling": "unit"}, "scaling must be one of 'fit', 'object', 'none', got 'unit'", ValueError),
        ({"n_neighbors": 2}, "n_neighbors must be an int in [3, 1000000], got 2", ValueError),
        ({"normal_orientation": "up"}, "normal_orientation must be 'centroid', 'origin' or None, got 'up'", ValueError),
        ({"n_jobs": 0}, "n_jobs must be None or a non-zero int (-1: all cores), got 0", ValueError),
        ({"n_jobs": 1.5}, "n_jobs must be None or a non-zero int (-1: all cores), got 1.5", TypeError),
    ],
)
def test_bad_parameters_raise(params, match, exc):
    rng = np.random.default_rng(0)
    _err([rng.normal(size=(20, 3))], "EPPFTransformer: " + match, exc, **params)


def test_transform_before_fit_raises():
    with pytest.raises(NotFittedError):
        EPPFTransformer().transform([np.eye(3)])


def test_to_histogram_rejects_wrong_length(clouds):
    est = EPPFTransformer(n_pairs=100).fit(clouds)
    with pytest.raises(ValueError, match=re.escape("descriptors must have 1200 values in the last axis")):
        est.to_histogram(np.zeros((2, 540)))


def test_degenerate_cloud_reports_object():
    pts = np.zeros((200000, 3))
    pts[0] = 1.0  # two distinct points among 200,000: pairs are almost never distinct
    clouds = [np.random.default_rng(0).normal(size=(10, 3)), pts]
    est = EPPFTransformer(n_pairs=50, functions=("distance",), random_state=0)
    with pytest.raises(ValueError, match=re.escape("EPPFTransformer: point cloud 1 has too few distinct points")):
        est.fit_transform(clouds)


def test_kernel_reads_wide_rows_in_place_with_the_same_counts():
    # Points and normals may be strided views (the two halves of an (N, 6) block): the counts must
    # be those of the contiguous (N, 3) copies, for every SIMD setting.
    rng = np.random.default_rng(5)
    block = rng.normal(size=(300, 6))
    block[:, 3:] /= np.linalg.norm(block[:, 3:], axis=1, keepdims=True)
    offsets = np.array([0, 120, 300], dtype=np.int64)
    args = (offsets, np.ones(2), np.array([3, 4], dtype=np.uint64), 500, (20, 4, 5, 3), 64, np.sqrt(3.0), 1)
    for simd in (False, True):
        old = _set_simd(simd)
        try:
            wide = eppf_counts(block[:, :3], block[:, 3:], *args)
            packed = eppf_counts(np.ascontiguousarray(block[:, :3]), np.ascontiguousarray(block[:, 3:]), *args)
        finally:
            _set_simd(old)
        assert_array_equal(wide[0], packed[0])
        assert_array_equal(wide[1], packed[1])
    with pytest.raises(ValueError, match="do not match"):
        eppf_counts(block[:, :3], block[:200, 3:], *args)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        eppf_counts(block[:, :2], block[:, 3:], *args)


_WEIGHTS_DIGEST = (
    "import hashlib, numpy as np, eppf\n"
    "from eppf.datasets import make_shapes\n"
    "clouds = [c.astype(np.float32).astype(np.float64) for c in make_shapes(random_state=0).data[:3]]\n"
    "X = eppf.EPPFTransformer(n_pairs=500, n_bins=(61, 2, 2, 2), c=2.0, random_state=0).fit_transform(clouds)\n"
    "print(hashlib.sha256(X.tobytes()).hexdigest())\n"
)


def test_f1_weights_do_not_depend_on_numpys_simd_code():
    """ln(i / N1 + c) with N1 = 61, c = 2: NumPy's AVX-512 log and the C library's differ at i = 4."""
    import importlib.util
    import os
    import subprocess
    import sys

    script = os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "older_cpu_env.py")
    spec = importlib.util.spec_from_file_location("older_cpu_env", script)
    older_cpu_env = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(older_cpu_env)

    runs = []
    for disabled in ("", " ".join(older_cpu_env.numpy_above_avx2())):
        env = {k: v for k, v in os.environ.items() if k != "NPY_DISABLE_CPU_FEATURES"}
        if disabled:
            env["NPY_DISABLE_CPU_FEATURES"] = disabled
        run = subprocess.run([sys.executable, "-c", _WEIGHTS_DIGEST], env=env, capture_output=True, text=True,
                             timeout=300)
        assert run.returncode == 0, run.stderr
        runs.append(run.stdout.strip())
    assert runs[0] == runs[1]
