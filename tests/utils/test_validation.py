"""Tests of eppf/utils/_validation.py: whole-collection validation and the packed clouds."""

import pickle
import re

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from eppf.utils import PackedClouds, check_packed_clouds, check_point_cloud, check_point_clouds, pack_point_clouds
from eppf.utils._chunks import _chunk_bounds
from eppf.utils._validation import condition_point_clouds


def _mixed_magnitude_clouds(rng, dtype=np.float64, cols=6):
    out = []
    for n in [2, 3, 17, 256, 1024]:
        if np.issubdtype(dtype, np.integer):  # distinct points, no zero normals
            c = rng.integers(1, 100, size=(n, cols)) * rng.choice([-1, 1], size=(n, cols))
            c[:, 0] = np.arange(n) % 100
        else:
            c = rng.normal(size=(n, cols)) * 10.0 ** rng.integers(-6, 6, size=(1, cols))
        out.append(c.astype(dtype))
    return out


def _assert_packs(packed, want):
    """``packed`` holds exactly the clouds ``want`` (validated one by one), with their bounds."""
    assert isinstance(packed, PackedClouds) and len(packed) == len(want)
    sizes = [len(c) for c in want]
    assert_array_equal(packed.offsets, np.concatenate([[0], np.cumsum(sizes)]))
    assert packed.offsets.dtype == np.int64
    assert packed.points.flags.c_contiguous and packed.points.dtype == np.float64 == packed.dtype
    assert_array_equal(packed.points, np.vstack([c[:, :3] for c in want]))
    has = np.array([c.shape[1] == 6 for c in want])
    assert_array_equal(packed.has_normals, has)
    if has.any():
        assert packed.normals.flags.c_contiguous and packed.normals.shape == packed.points.shape
        assert_array_equal(packed.normals, np.vstack([c[:, 3:] if c.shape[1] == 6 else np.zeros((len(c), 3))
                                                      for c in want]))
    else:
        assert packed.normals is None
    assert_array_equal(packed.lower, [c[:, :3].min(axis=0) for c in want])
    assert_array_equal(packed.upper, [c[:, :3].max(axis=0) for c in want])
    assert_array_equal(packed.sides(), [np.ptp(c[:, :3], axis=0).max() for c in want])
    for k, c in enumerate(want):
        assert_array_equal(packed[k], c)


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64, np.int8])
@pytest.mark.parametrize("cols", [3, 6])
def test_block_validation_equals_per_cloud_validation(dtype, cols):
    # The whole-collection path must return bit for bit what check_point_cloud returns.
    rng = np.random.default_rng(cols)
    X = _mixed_magnitude_clouds(rng, dtype, cols)
    want = [check_point_cloud(c, owner="T", index=k) for k, c in enumerate(X)]
    got = check_point_clouds(X, owner="T")
    assert type(got) is list
    for k, c in enumerate(X):
        assert got[k].flags.c_contiguous and got[k].dtype == np.float64
        assert_array_equal(got[k], want[k])
        assert not np.shares_memory(got[k], c)
    packed = check_packed_clouds(X, owner="T")
    _assert_packs(packed, want)
    assert not any(np.shares_memory(packed.points, c) for c in X)
    for a, b in zip(pack_point_clouds(packed), pack_point_clouds(got)):
        assert_array_equal(a, b)


@pytest.mark.parametrize("cols", [3, 6])
def test_block_validation_is_the_same_on_any_thread_count_and_layout(cols):
    # C-contiguous float64 clouds are copied and checked by the compiled pass
    # (objects spread over the threads); other layouts are concatenated by
    # NumPy first. Both give check_point_cloud's arrays, bit for bit.
    rng = np.random.default_rng(10 + cols)
    X = _mixed_magnitude_clouds(rng, np.float64, cols)
    want = [check_point_cloud(c) for c in X]
    for layout in ("C", "F"):
        clouds = [np.asarray(c, order=layout) for c in X]
        for n_threads in (1, 2, 3):
            for a, b in zip(check_point_clouds(clouds, n_threads=n_threads), want):
                assert_array_equal(a, b)
            _assert_packs(check_packed_clouds(clouds, n_threads=n_threads), want)
    # a bad cloud among many is still found and named, whichever thread meets it
    bad = [c.copy() for c in X]
    bad[-2][1, 0] = np.nan
    for check in (check_point_clouds, check_packed_clouds):
        with pytest.raises(ValueError, match=f"point cloud {len(X) - 2} contains NaN"):
            check(bad, owner="T", n_threads=2)


def test_block_validation_of_3d_array_and_mixed_widths():
    rng = np.random.default_rng(1)
    arr = rng.normal(size=(4, 50, 6))
    got = check_point_clouds(arr)
    for k in range(4):
        assert_array_equal(got[k], check_point_cloud(arr[k]))
    _assert_packs(check_packed_clouds(arr), [check_point_cloud(c) for c in arr])
    # widths differ: per-cloud path, same results; the packed normals say which objects have them
    mixed = [arr[0], arr[1][:, :3], np.asarray(arr[2], dtype=np.float32), arr[3][:, :3].tolist()]
    want = [check_point_cloud(c) for c in mixed]
    got = check_point_clouds(mixed)
    for a, b in zip(got, want):
        assert_array_equal(a, b)
    packed = check_packed_clouds(mixed)
    _assert_packs(packed, want)
    assert_array_equal(packed.normals[50:100], 0.0)
    with pytest.raises(ValueError, match="all have normals or all have none"):
        pack_point_clouds(packed)


def test_packed_slices_are_views_and_chunks_follow_sizes():
    rng = np.random.default_rng(2)
    X = [rng.normal(size=(n, 6)) for n in (5, 9, 12, 7)]
    packed = check_packed_clouds(X)
    part = packed[1:3]
    assert isinstance(part, PackedClouds) and len(part) == 2
    assert np.shares_memory(part.points, packed.points) and np.shares_memory(part.normals, packed.normals)
    assert_array_equal(part.offsets, [0, 9, 21])
    assert_array_equal(part.points, packed.points[5:26])
    assert_array_equal(part.sides(), packed.sides()[1:3])
    _assert_packs(part, [packed[1], packed[2]])
    points, normals, offsets = pack_point_clouds(part)
    assert_array_equal(offsets, [0, 9, 21])
    assert_array_equal(normals, np.vstack([packed[1][:, 3:], packed[2][:, 3:]]))
    # ends past the range are clipped as for lists; an empty range is an empty batch
    assert len(packed[2:100]) == 2 and len(packed[3:1]) == 0 and len(packed[-1:]) == 1
    assert_array_equal(packed[-1], packed[3])
    with pytest.raises(TypeError, match="consecutive objects"):
        packed[::2]
    with pytest.raises(IndexError):
        packed[4]
    # an int gives the object as the caller passed it (validated): (n, 6) with normals, a copy
    assert packed[0].shape == (5, 6) and not np.shares_memory(packed[0], packed.points)
    # chunks are cut from the sizes, as for a list of clouds
    assert_array_equal(packed.sizes, [5, 9, 12, 7])
    assert _chunk_bounds(packed, 2, 100) == _chunk_bounds(list(packed), 2, 100) == [(0, 2), (2, 4)]
    assert _chunk_bounds(packed, 8, 15) == [(0, 2), (2, 3), (3, 4)]
    # pickles (joblib's workers) keep the values, a slice only its own rows
    back = pickle.loads(pickle.dumps(part))
    _assert_packs(back, [packed[1], packed[2]])
    assert len(back.points) == 21


def test_packed_clouds_are_validated_again_like_a_list():
    # a PackedClouds passed back in is checked as the list of its objects would be, into new arrays
    rng = np.random.default_rng(3)
    X = [rng.normal(size=(n, 6)) for n in (5, 9)] + [rng.normal(size=(4, 3))]
    packed = check_packed_clouds(X)
    again = check_packed_clouds(packed)
    _assert_packs(again, [check_point_cloud(c) for c in packed])
    assert not np.shares_memory(again.points, packed.points)
    same_width = check_packed_clouds(X[:2])
    again = check_packed_clouds(same_width, n_threads=2)
    _assert_packs(again, check_point_clouds(list(same_width)))
    for a, b in zip(check_point_clouds(same_width), check_point_clouds(list(same_width))):
        assert_array_equal(a, b)
    with pytest.raises(ValueError, match=re.escape("T: point cloud 2 has 4 points; at least 5 are needed")):
        check_packed_clouds(packed, owner="T", min_points=5)


def test_conditioning_rescales_packed_points_and_their_bounds():
    rng = np.random.default_rng(5)
    X = [rng.normal(size=(30, 6)) * ([scale] * 3 + [1.0] * 3) for scale in (1.0, 1e-200, 1e250)]
    packed = check_packed_clouds(X)
    before = [c.copy() for c in packed]
    exps = condition_point_clouds(packed)
    assert exps[0] == 0 and exps[1] > 0 and exps[2] < 0
    for k, (b, e) in enumerate(zip(before, exps)):
        c = packed[k]
        assert_array_equal(c[:, :3], np.ldexp(b[:, :3], int(e)))
        assert_array_equal(c[:, 3:], b[:, 3:])  # normals are unit vectors: untouched
        assert_array_equal(packed.lower[k], c[:, :3].min(axis=0))
        assert_array_equal(packed.upper[k], c[:, :3].max(axis=0))
    assert np.abs(X[1][:, :3]).max() < 1e-190  # the input arrays are never touched


@pytest.mark.parametrize(
    "X, match",
    [
        ([np.eye(3), np.eye(3), np.array([[0, 0, np.nan], [1, 1, 1]])], "T: point cloud 2 contains NaN or infinite"),
        ([np.eye(3), np.ones((4, 3)), np.ones((4, 3))], "T: point cloud 1 has all 4 points identical"),
        ([np.hstack([np.eye(3)] * 2), np.hstack([np.eye(3)] * 2), np.hstack([np.eye(3), np.zeros((3, 3))])],
         "T: point cloud 2 has 3 zero-length normal(s), first at point 0"),
        ([np.eye(3), np.eye(3)[:1]], "T: point cloud 1 has 1 point; at least 2 are needed"),
    ],
)
@pytest.mark.parametrize("check", [check_point_clouds, check_packed_clouds])
def test_block_validation_reports_the_first_bad_cloud(X, match, check):
    with pytest.raises(ValueError, match=re.escape(match)):
        check(X, owner="T")


@pytest.mark.parametrize(
    "X, match, exc",
    [
        ([], "T: X is empty", ValueError),
        (None, "T: X must be a list of point clouds", TypeError),
        ("cloud.ply", "T: X must be a list of point clouds", TypeError),
        (3, "T: X must be a list of point clouds", TypeError),
        (np.zeros((10, 3)), "T: X is a single 2D array of shape (10, 3)", ValueError),
        (np.zeros((2, 3, 3, 3)), "T: X must be a list of (n_i, 3|6) arrays or a 3D array", ValueError),
    ],
)
@pytest.mark.parametrize("check", [check_point_clouds, check_packed_clouds])
def test_wrong_collections_are_refused_the_same_way(X, match, exc, check):
    with pytest.raises(exc, match=re.escape(match)):
        check(X, owner="T")


def test_check_n_jobs_resolves_joblibs_meaning_and_bounds_the_threads():
    # Positive counts as given, negative ones from the cores, None OpenMP's default; a count beyond
    # MAX_THREADS in either direction is refused naming the owner (10**18 overflowed the kernels' C int, and
    # 65,536 OpenMP threads crashed the process on a 2-core guest).
    import os

    from eppf import EPPFTransformer
    from eppf.utils._validation import MAX_THREADS, check_n_jobs

    cores = os.cpu_count() or 1
    assert check_n_jobs(3) == 3 and check_n_jobs(MAX_THREADS) == MAX_THREADS
    assert check_n_jobs(-1) == cores and check_n_jobs(-cores - 5) == 1 and check_n_jobs(None) >= 1
    for n_jobs in (MAX_THREADS + 1, -MAX_THREADS - 1, 10**18, -(10**18)):
        with pytest.raises(ValueError, match=rf"^EPPFTransformer: n_jobs={n_jobs} asks for more threads"):
            EPPFTransformer(n_jobs=n_jobs, n_pairs=50).fit_transform([np.random.default_rng(0).random((20, 3))])
        with pytest.raises(ValueError, match=rf"^check_n_jobs: n_jobs={n_jobs} asks for more threads"):
            check_n_jobs(n_jobs)
