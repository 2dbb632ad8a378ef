"""Validation of point clouds (eppf.utils._validation): the block path over a whole collection, its cache, its errors."""

import pickle
import re

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from eppf.utils._validation import (
    _bounding_sides,
    _stacked_view,
    check_point_cloud,
    check_point_clouds,
    pack_point_clouds,
)


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


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64, np.int8])
@pytest.mark.parametrize("cols", [3, 6])
def test_block_validation_equals_per_cloud_validation(dtype, cols):
    # The whole-collection path must return bit for bit what check_point_cloud returns.
    rng = np.random.default_rng(cols)
    X = _mixed_magnitude_clouds(rng, dtype, cols)
    got = check_point_clouds(X, owner="T")
    assert _stacked_view(got) is not None  # the block path was taken
    for k, c in enumerate(X):
        want = check_point_cloud(c, owner="T", index=k)
        assert got[k].flags.c_contiguous and got[k].dtype == np.float64
        assert_array_equal(got[k], want)
        assert not np.shares_memory(got[k], c)
    assert_array_equal(_bounding_sides(got), [np.ptp(c[:, :3], axis=0).max() for c in map(np.asarray, got)])
    for a, b in zip(pack_point_clouds(got), pack_point_clouds(list(got))):
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
            got = check_point_clouds(clouds, n_threads=n_threads)
            assert _stacked_view(got) is not None
            for a, b in zip(got, want):
                assert_array_equal(a, b)
    # a bad cloud among many is still found and named, whichever thread meets it
    bad = [c.copy() for c in X]
    bad[-2][1, 0] = np.nan
    with pytest.raises(ValueError, match=f"point cloud {len(X) - 2} contains NaN"):
        check_point_clouds(bad, owner="T", n_threads=2)


def test_block_validation_of_3d_array_and_mixed_widths():
    rng = np.random.default_rng(1)
    arr = rng.normal(size=(4, 50, 6))
    got = check_point_clouds(arr)
    assert _stacked_view(got) is not None
    for k in range(4):
        assert_array_equal(got[k], check_point_cloud(arr[k]))
    mixed = [arr[0], arr[1][:, :3]]  # widths differ: per-cloud path, same results
    got = check_point_clouds(mixed)
    assert _stacked_view(got) is None
    assert_array_equal(got[1], arr[1][:, :3])


def test_cloud_list_cache_follows_slices_and_ignores_replaced_items():
    rng = np.random.default_rng(2)
    X = [rng.normal(size=(n, 6)) for n in (5, 9, 12, 7)]
    got = check_point_clouds(X)
    part = got[1:3]
    assert _stacked_view(part) is not None
    points, normals, offsets = pack_point_clouds(part)
    assert_array_equal(offsets, [0, 9, 21])
    assert_array_equal(points, np.vstack([got[1][:, :3], got[2][:, :3]]))
    assert_array_equal(normals, np.vstack([got[1][:, 3:], got[2][:, 3:]]))
    assert_array_equal(_bounding_sides(part), [np.ptp(got[k][:, :3], axis=0).max() for k in (1, 2)])
    # Replacing a cloud invalidates the shared block: packing must see the new cloud.
    new = rng.normal(size=(4, 6))
    part[0] = new
    assert _stacked_view(part) is None
    points, _, offsets = pack_point_clouds(part)
    assert_array_equal(points[:4], new[:, :3])
    assert_array_equal(offsets, [0, 4, 16])
    assert_array_equal(_bounding_sides(part)[0], np.ptp(new[:, :3], axis=0).max())
    # Pickles and copies are plain lists.
    assert type(pickle.loads(pickle.dumps(got))) is list
    assert type(got[::2]) is list and type(got[0:0]) is list


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
def test_block_validation_reports_the_first_bad_cloud(X, match):
    with pytest.raises(ValueError, match=re.escape(match)):
        check_point_clouds(X, owner="T")
