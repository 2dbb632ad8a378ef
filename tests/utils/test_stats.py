"""Tests of eppf.utils._stats_fast: per-object centroids and order statistics, NumPy's bits."""

import numpy as np
import pytest

from eppf.utils._stats_fast import cloud_means, extreme_values


@pytest.mark.parametrize("n_threads", [1, 2])
@pytest.mark.parametrize("columns", [3, 6])
def test_cloud_means_are_numpys_mean_bit_for_bit(columns, n_threads):
    rng = np.random.RandomState(0)
    sizes = [1, 2, 7, 1024, 333, 2, 1500]
    clouds = [rng.normal(size=(n, columns)) * rng.uniform(0.01, 1e3, size=columns) + rng.normal(size=columns) * 1e4
              for n in sizes]
    clouds[1][:] = -0.0  # NumPy adds from +0.0: a mean of negative zeros is +0.0
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    means = cloud_means(np.concatenate(clouds), offsets, n_threads)
    ref = np.array([c[:, :3].mean(axis=0) for c in clouds])
    np.testing.assert_array_equal(means, ref)
    assert not np.signbit(means[1]).any()
    # a stack of equal-size clouds: what P.mean(axis=1) gives
    P = rng.normal(size=(9, 100, 3)) * 50 + 3
    np.testing.assert_array_equal(cloud_means(P.reshape(-1, 3), np.arange(0, 901, 100, dtype=np.int64)),
                                  P.mean(axis=1))


def test_cloud_means_errors():
    block = np.zeros((4, 3))
    with pytest.raises(ValueError, match="no rows"):
        cloud_means(block, np.array([0, 2, 2, 4], dtype=np.int64))
    with pytest.raises(ValueError, match="out of the block"):
        cloud_means(block, np.array([0, 5], dtype=np.int64))
    with pytest.raises(ValueError, match="3 columns"):
        cloud_means(np.zeros((4, 2)), np.array([0, 4], dtype=np.int64))
    assert cloud_means(block, np.array([0], dtype=np.int64)).shape == (0, 3)


@pytest.mark.parametrize("n_threads", [1, 3])
def test_extreme_values_are_the_ends_of_the_sorted_rows(n_threads):
    rng = np.random.RandomState(1)
    rows = rng.normal(size=(8, 200))
    rows[1] = np.round(rows[1])  # many ties
    rows[2] = np.sort(rows[2])  # every value enters the largest list
    rows[3] = np.sort(rows[3])[::-1]  # every value enters the smallest list
    rows[4] = 2.0
    ordered = np.sort(rows, axis=1)
    for m in (1, 2, 22, 150, 200):  # m > n / 2: the two lists overlap
        low, high = extreme_values(rows, m, n_threads)
        np.testing.assert_array_equal(low, ordered[:, :m])
        np.testing.assert_array_equal(high, ordered[:, ::-1][:, :m])


def test_extreme_values_errors():
    with pytest.raises(ValueError, match=r"m must be in \[1, 5\]"):
        extreme_values(np.zeros((2, 5)), 6)
    with pytest.raises(ValueError, match="m must be"):
        extreme_values(np.zeros((2, 5)), 0)
    low, high = extreme_values(np.zeros((0, 5)), 2)
    assert low.shape == high.shape == (0, 2)


@pytest.mark.parametrize("n_threads", [1, 2])
@pytest.mark.parametrize("columns", [3, 6])
def test_stretch_about_is_numpys_expression_bit_for_bit(columns, n_threads):
    from eppf.utils._stats_fast import stretch_about

    rng = np.random.RandomState(2)
    sizes = [3, 1024, 2, 57]
    block = rng.normal(size=(sum(sizes), columns)) * 1e3
    block[:3, :3] = -0.0  # (-0.0 - 0.0) * f + 0.0 is +0.0, as in NumPy
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    factors = np.exp(rng.uniform(np.log(0.8), np.log(1.25), size=(4, 3)))
    for origins in (rng.normal(size=(4, 3)) * 1e3, np.zeros((4, 3))):
        out = np.full_like(block, 7.0)
        stretch_about(block, offsets, origins, factors, out, n_threads)
        each, at = np.repeat(factors, sizes, axis=0), np.repeat(origins, sizes, axis=0)
        np.testing.assert_array_equal(out[:, :3], (block[:, :3] - at) * each + at)
        assert (out[:, 3:] == 7.0).all()  # the other columns are left alone
    assert not np.signbit(out[:3, :3]).any()
    with pytest.raises(ValueError, match="block's shape"):
        stretch_about(block, offsets, origins, factors, np.empty((2, columns)))
    with pytest.raises(ValueError, match="one row of 3 per object"):
        stretch_about(block, offsets, origins[:2], factors, out)
