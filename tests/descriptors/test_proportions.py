"""Tests of eppf.descriptors.ProportionTransformer (scale-invariant proportions, a side input)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from eppf.descriptors import ProportionTransformer
from eppf.descriptors._proportions import proportions


def _box(sides, n=20000, seed=0):
    return np.random.RandomState(seed).uniform(-0.5, 0.5, size=(n, 3)) * np.asarray(sides)


def test_uniform_box_gives_its_side_ratios():
    # a uniform box's spread along a side is side / sqrt(12), its central 96% extent 0.96 * side
    row = ProportionTransformer().fit_transform([_box([4.0, 2.0, 1.0])])[0]
    expected = np.log([2 / 4, 1 / 4, 2 / 4, 1 / 4, 2 / 4, 1 / 4])
    assert_allclose(row, expected, atol=0.02)
    # tall box: the vertical term sees the height
    tall = ProportionTransformer().fit_transform([_box([1.0, 1.0, 3.0])])[0]
    assert tall[3] == pytest.approx(np.log(3.0), abs=0.03)
    assert ProportionTransformer(up_axis=0).fit_transform([_box([1.0, 1.0, 3.0])])[0][3] == \
        pytest.approx(np.log(1 / 3), abs=0.03)


def test_invariant_to_scale_translation_and_rotation_about_up():
    cloud = _box([3.0, 1.5, 1.0], n=2000) @ np.diag([1.0, 1.0, 1.0])
    a = 0.7
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    t = ProportionTransformer()
    base = t.fit_transform([cloud])[0]
    moved = t.transform([cloud @ rot.T * 1e3 + [5, -2, 7]])[0]
    assert_allclose(moved[:4], base[:4], atol=1e-9)  # spreads: exact invariants
    assert_allclose(moved[4:], base[4:], atol=0.02)  # quantiles move by a point or so
    # a general rotation keeps the principal terms
    q, _ = np.linalg.qr(np.random.RandomState(1).normal(size=(3, 3)))
    assert_allclose(t.transform([cloud @ q.T])[0][:2], base[:2], atol=1e-9)


def test_matches_the_reference_function_and_names():
    clouds = [_box([1.0, 2.0, 3.0], n=300, seed=s) for s in range(3)]
    t = ProportionTransformer(coverage=0.8, n_jobs=2).fit(clouds)
    out = t.transform(clouds)
    assert out.shape == (3, 6) and t.n_features_out_ == 6
    for c, row in zip(clouds, out):
        assert_allclose(row, proportions(c, 2, 0.8))
    assert list(t.get_feature_names_out())[0] == "pca_mid_over_major"


@pytest.mark.parametrize("sizes", [[300] * 5, [300, 40, 300, 7, 40, 2, 300]])
def test_whole_array_rows_are_the_reference_functions_bit_for_bit(sizes):
    # clouds of one size go through the stacked computation, a size of its own through the reference;
    # both must give the reference's bits (the models trained on them depend on it), degenerate clouds too
    rng = np.random.RandomState(3)
    clouds = [rng.normal(size=(n, 3)) * rng.uniform(0.1, 10.0, size=3) + rng.normal(size=3) * 100 for n in sizes]
    clouds[1] = np.column_stack([np.linspace(0, 1, sizes[1]), np.zeros(sizes[1]), np.zeros(sizes[1])])  # a line
    clouds[2] = np.column_stack([rng.uniform(size=(sizes[2], 2)), np.full(sizes[2], 4.0)])  # a horizontal plane
    for up_axis, coverage in ((2, 0.96), (0, 0.5), (1, 1.0)):
        out = ProportionTransformer(up_axis=up_axis, coverage=coverage).fit_transform(clouds)
        ref = np.stack([proportions(c, up_axis, coverage) for c in clouds])
        np.testing.assert_array_equal(out, ref)


def test_threads_split_the_clouds_and_keep_the_bits():
    # n_jobs splits a call's clouds into runs, one a thread (at least 16 clouds each): the same rows bit for bit,
    # for clouds of one size and of mixed sizes, with runs that cut through a group of equal sizes
    rng = np.random.RandomState(5)
    for sizes in ([50] * 200, list(rng.choice([9, 50, 51], size=301))):
        clouds = [rng.normal(size=(n, 3)) * rng.uniform(0.1, 10.0, size=3) for n in sizes]
        ref = np.stack([proportions(c, 2, 0.96) for c in clouds])
        for n_jobs in (1, 2, 3, -1):
            np.testing.assert_array_equal(ProportionTransformer(n_jobs=n_jobs).fit_transform(clouds), ref)


def test_degenerate_clouds_are_finite():
    out = ProportionTransformer().fit_transform([np.array([[0, 0, 0], [1, 0, 0.0]]),
                                                 np.array([[1e300, 1e300, 1e300], [-1e300, 1e300, 0.0]])])
    assert np.isfinite(out).all()
    # the reference function: a single point has all spreads 0, so every ratio is 1
    assert_allclose(proportions(np.zeros((1, 3))), 0.0)


@pytest.mark.parametrize("X, msg", [
    ([np.array([[0.0, np.nan, 0.0], [1.0, 0.0, 0.0]])], "NaN|finite"),
    ([np.zeros((3, 2))], "shape|columns"),
    ([np.zeros((0, 3))], "empty|point"),
    ([np.zeros((1, 3))], "1 point"),
])
def test_bad_clouds(X, msg):
    with pytest.raises(ValueError, match=msg):
        ProportionTransformer().fit_transform(X)


@pytest.mark.parametrize("params", [dict(up_axis=3), dict(coverage=0.0), dict(coverage=1.5), dict(n_jobs=0)])
def test_bad_parameters(params):
    with pytest.raises(ValueError, match="ProportionTransformer"):
        ProportionTransformer(**params).fit([np.zeros((3, 3))])


def test_quantiles_near_the_ends_are_numpys_bit_for_bit():
    # the robust extents read two order statistics from each end instead of partitioning the rows;
    # they must give np.quantile's bits, for ties, sorted rows, the ends themselves and short rows,
    # and quantiles far from the ends go through np.quantile itself
    from eppf.descriptors._proportions import _quantiles

    rng = np.random.RandomState(7)
    for n in (2, 3, 5, 50, 1024, 1031):
        rows = rng.normal(size=(6, n)) * 10.0 ** rng.randint(-3, 4, size=(6, 1))
        rows[1] = np.round(rows[1], 1)  # ties
        rows[2] = np.sort(rows[2])
        rows[3] = np.sort(rows[3])[::-1]
        rows[4] = 1.5  # all equal
        for qs in ([0.02, 0.98], [0.0, 1.0], [0.25, 0.75], [0.5], [0.013, 0.5, 0.999]):
            np.testing.assert_array_equal(_quantiles(np.ascontiguousarray(rows), qs),
                                          np.quantile(rows, qs, axis=1))
