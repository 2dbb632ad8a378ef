"""Tests of the compiled curvature filter of CVFH and OUR-CVFH
(``_regions.low_curvature``) against independent NumPy references: the
NumPy filter it replaced (SciPy's k-d tree, LAPACK's eigenvalues), and
brute-force nearest neighbors for the kernel's own search and its tie
detection; degenerate neighborhoods, grids, bad input."""

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from scipy.spatial import cKDTree

from eppf.descriptors import _cvfh_fast
from eppf.descriptors._regions import low_curvature


def _knn_brute(points, k):
    """Indices of each point's k nearest points, ordered by (squared distance, index)."""
    d = points[:, None, :] - points[None, :, :]
    d2 = (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]
    order = np.lexsort((np.broadcast_to(np.arange(len(points)), d2.shape), d2), axis=1)
    return order[:, :k]


def curvature_reference(points, k, brute=False):
    """Surface variation lambda_min / sum(lambda) of the k nearest neighbors
    (LAPACK): eppf's earlier NumPy filter (SciPy's k-d tree), or with
    brute-force neighbors, ties to the lower index."""
    k = min(k, len(points))
    idx = _knn_brute(points, k) if brute else cKDTree(points).query(points, k=k)[1].reshape(len(points), k)
    nb = points[idx]
    nb = nb - nb.mean(axis=1, keepdims=True)
    ev = np.linalg.eigvalsh(np.einsum("nki,nkj->nij", nb, nb))
    total = ev.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.clip(np.where(total > 0, ev[:, 0] / total, 0.0), 0.0, None)


def _check_against_reference(points, k, threshold, margin=1e-9):
    """The filter equals the reference wherever the reference's curvature is
    not within ``margin`` (relative) of the threshold; returns how many were."""
    got = low_curvature(np.ascontiguousarray(points), k, threshold)
    curv = curvature_reference(points, k)
    clear = np.abs(curv - threshold) > margin * max(threshold, 1e-300)
    assert_array_equal(got[clear], (curv <= threshold)[clear])
    return int((~clear).sum())


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("k", [3, 10, 25])
def test_matches_numpy_reference_on_random_surfaces(seed, k):
    rng = np.random.default_rng(seed)
    # a noisy sphere and a noisy plane with a fold: curvatures on both sides of the thresholds
    u = rng.normal(size=(300, 3))
    sphere = u / np.linalg.norm(u, axis=1, keepdims=True) + rng.normal(scale=0.02, size=(300, 3))
    xy = rng.uniform(-1, 1, size=(300, 2))
    fold = np.column_stack([xy, np.abs(xy[:, 0]) + rng.normal(scale=0.01, size=300)])
    split = 0
    for pts in (sphere, fold):
        for threshold in (0.001, 0.01, 0.03, 0.1, 0.3):
            curv = curvature_reference(pts, k)
            kept = low_curvature(pts, k, threshold)
            split += 0 < kept.sum() < len(pts)
            assert _check_against_reference(pts, k, threshold) == 0
            assert_array_equal(kept, curv <= threshold)
    # three points are always coplanar; more give curvatures on both sides of some thresholds
    assert split >= (0 if k == 3 else 4)


def test_kernel_search_and_tie_detection_against_brute_force():
    rng = np.random.default_rng(5)
    g = np.arange(5, dtype=float)
    lattice = np.stack(np.meshgrid(g, g, g[:3], indexing="ij"), -1).reshape(-1, 3)
    noisy = rng.normal(size=(400, 3))
    dup = np.vstack([noisy[:100], noisy[:50]])  # repeated points tie
    for pts in (lattice, noisy, dup):
        for k in (1, 5, 10):
            passes, tied = _cvfh_fast.low_curvature(pts, k, 0.05)
            d = pts[:, None, :] - pts[None, :, :]
            d2 = np.sort((d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2], axis=1)
            assert_array_equal(tied, np.flatnonzero(d2[:, k] == d2[:, k - 1]))
            assert not passes[tied].any()
            free = np.setdiff1d(np.arange(len(pts)), tied)
            curv = curvature_reference(pts, k, brute=True)[free]
            clear = np.abs(curv - 0.05) > 1e-9
            assert_array_equal(passes[free][clear], (curv <= 0.05)[clear])
        assert (len(tied) > 0) == (pts is not noisy)


def _check_search_against_brute_force(pts, k, threshold=0.05):
    """The kernel's tie detection and decisions against brute-force neighbors."""
    passes, tied = _cvfh_fast.low_curvature(pts, k, threshold)
    with np.errstate(over="ignore", invalid="ignore"):  # the huge cloud's distances overflow to inf
        d = pts[:, None, :] - pts[None, :, :]
        d2 = np.sort((d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2], axis=1)
        k = min(k, len(pts))
        idx = _knn_brute(pts, k)
    if k < len(pts):
        assert_array_equal(tied, np.flatnonzero(d2[:, k] == d2[:, k - 1]))
    free = np.setdiff1d(np.arange(len(pts)), tied)
    idx = idx[free]
    assert_array_equal(passes[free], _cvfh_fast.low_curvature_of(pts, np.ascontiguousarray(idx), threshold))
    return tied


def test_grid_search_on_awkward_layouts():
    # the grid search's paths: extents beyond double range (one cell), far-apart clusters and a
    # thin line (many empty cells, the cell cap), repeated points (zero distances), sizes of a few
    # points, against brute-force neighbors (the decisions for given neighbors are tested below)
    rng = np.random.default_rng(7)
    huge = rng.normal(size=(60, 3)) * 1e307
    huge[:2] = [[1.7e308, 0, 0], [-1.7e308, 0, 0]]
    clusters = np.vstack([rng.normal(size=(80, 3)) * 1e-3 + c for c in ([0, 0, 0], [50, 0, 0], [0, 0, 1e4])])
    line = np.column_stack([rng.uniform(-1, 1, 300), np.zeros(300), rng.normal(size=300) * 1e-9])
    line[0] = [0.0, 1e6, 0.0]
    dup = np.repeat(rng.normal(size=(40, 3)), 6, axis=0)
    for pts in (huge, clusters, line, dup, rng.normal(size=(3, 3)), rng.normal(size=(12, 3))):
        for k in (1, 5, 10, 30):
            _check_search_against_brute_force(np.ascontiguousarray(pts), k)
    assert len(_check_search_against_brute_force(dup, 10)) == len(dup)  # every point ties at the 10th


def test_low_curvature_of_given_neighbors():
    rng = np.random.default_rng(6)
    pts = rng.normal(size=(50, 3))
    idx = cKDTree(pts).query(pts, k=8)[1]
    curv = curvature_reference(pts, 8)
    assert_array_equal(_cvfh_fast.low_curvature_of(pts, idx, 0.1), curv <= 0.1)
    assert _cvfh_fast.low_curvature_of(pts, np.zeros((0, 8), dtype=np.int64), 0.1).shape == (0,)
    with pytest.raises(ValueError, match="out of range"):
        _cvfh_fast.low_curvature_of(pts, idx + 1, 0.1)
    with pytest.raises(ValueError, match="at least one"):
        _cvfh_fast.low_curvature_of(pts, np.zeros((3, 0), dtype=np.int64), 0.1)


def test_ties_as_scipys_tree_breaks_them():
    # a lattice: many neighbors at equal distances; the filter takes SciPy's tree's choice among them,
    # as the earlier NumPy filter did
    g = np.arange(6, dtype=float)
    lattice = np.stack(np.meshgrid(g, g, g[:3], indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(0)
    for perm in (np.arange(len(lattice)), rng.permutation(len(lattice))):
        pts = lattice[perm]
        for k in (4, 7, 10, 19):
            curv = curvature_reference(pts, k)
            # the lattice's curvatures take few values; the thresholds sit between them
            levels = np.unique(np.round(curv, 12))
            for threshold in (levels[:-1] + levels[1:]) / 2:
                assert_array_equal(low_curvature(pts, k, threshold), curv <= threshold)


def test_degenerate_neighborhoods_pass():
    rng = np.random.default_rng(1)
    same = np.tile([0.25, -1.0, 3.0], (20, 1))  # all points equal: no scatter at all
    line = np.outer(rng.uniform(-1, 1, 40), [1.0, 2.0, -0.5])  # lambda_min = 0
    plane = np.column_stack([rng.uniform(-1, 1, (60, 2)), np.zeros(60)])
    for pts in (same, line, plane):
        assert low_curvature(pts, 10, 0.0).all()
        assert low_curvature(pts, 10, 1e-12).all()
    assert low_curvature(rng.normal(size=(30, 3)), 1, 0.0).all()  # one neighbor: the point itself
    # k above n: all points are every point's neighbors
    blob = rng.normal(size=(8, 3))
    assert_array_equal(low_curvature(blob, 50, 0.1), low_curvature(blob, 8, 0.1))
    assert_array_equal(low_curvature(blob, 50, 0.1), curvature_reference(blob, 8) <= 0.1)
    assert low_curvature(np.zeros((0, 3)), 10, 0.03).shape == (0,)


def test_threshold_above_any_curvature_keeps_all_and_zero_keeps_flat_only():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(200, 3))
    assert low_curvature(pts, 10, 1.0 / 3.0 + 1e-12).all()  # surface variation <= 1/3
    assert low_curvature(pts, 10, 1e300).all()
    assert not low_curvature(pts, 10, 0.0).any()


def test_large_cloud_against_reference():
    # enough points for a deep tree: every leaf and pruning path is used
    rng = np.random.default_rng(4)
    u = rng.normal(size=(3000, 3))
    pts = u / np.linalg.norm(u, axis=1, keepdims=True) * rng.uniform(0.95, 1.05, (3000, 1))
    pts[::7] *= 1e-3  # a dense core beside the shell
    assert _check_against_reference(pts, 10, 0.03) == 0


def test_bad_input():
    with pytest.raises(ValueError, match="shape"):
        _cvfh_fast.low_curvature(np.zeros((5, 2)), 3, 0.1)
    with pytest.raises(ValueError, match="at least 1"):
        low_curvature(np.zeros((5, 3)), 0, 0.1)
    bad = np.zeros((5, 3))
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        low_curvature(bad, 3, 0.1)
    with pytest.raises(ValueError, match="shape"):
        _cvfh_fast.low_curvature_of(np.zeros((5, 2)), np.zeros((5, 3), dtype=np.int64), 0.1)
