"""Tests of eppf.ESFTransformer (hand-computed triangle, slow reference, invariants, errors)."""

import math
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import make_pipeline

from eppf import ESFTransformer, KLNearestNeighbors
from eppf.utils._validation import object_seeds

MASK = (1 << 64) - 1


def _clouds(n_objects=4, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n_objects):
        p = rng.normal(size=(60 + 10 * k, 3)) * [1.0, 0.5 + 0.2 * k, 0.3]
        out.append(p)
    return out


# --- an independent, slow reading of PCL's ESF with eppf's generator --------


def _splitmix(state):
    state = (state + 0x9E3779B97F4A7C15) & MASK
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return state, z ^ (z >> 31)


def _below(state, n):
    state, z = _splitmix(state)
    return state, ((z >> 32) * n) >> 32


def _cell(v, half):
    return math.floor(v) + half if v < 0 else math.ceil(v) + half - 1


def _walk(occ, a, b):
    """PCL's lci as a plain loop over a set of occupied voxels."""
    d = [abs(b[i] - a[i]) for i in range(3)]
    s = [1 if b[i] >= a[i] else -1 for i in range(3)]
    if d[0] >= d[1] and d[0] >= d[2]:
        major, minors = 0, (1, 2)
    elif d[1] >= d[0] and d[1] >= d[2]:
        major, minors = 1, (0, 2)
    else:
        major, minors = 2, (1, 0)
    L = d[major]
    err = [2 * d[m] - L for m in minors]
    cur = list(a)
    n_in = 0
    for _ in range(1, L):
        n_in += tuple(cur) in occ
        for j, m in enumerate(minors):
            if err[j] > 0:
                cur[m] += s[m]
                err[j] -= 2 * L
            err[j] += 2 * d[m]
        cur[major] += s[major]
    n_in += tuple(cur) in occ
    count = max(L, 1)
    if n_in >= count - 1:
        return 0, n_in, count, None
    if n_in <= 7:
        return 1, n_in, count, None
    return 2, n_in, count, n_in / count


def _rbin(v, n_bins=64):
    return min(max(math.floor(v * (n_bins - 1) + 0.5), 0), n_bins - 1)


def _esf_reference(cloud, seed, n_triplets, grid=64, n_bins=64):
    half = grid // 2
    p = cloud - cloud.mean(axis=0)
    p = p * (half / np.sqrt((p**2).sum(axis=1).max()))
    pts = [tuple(float(x) for x in row) for row in p]
    cells = [tuple(min(max(_cell(v, half), 0), grid - 1) for v in q) for q in pts]
    occ = set()
    for c in cells:
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    v = (c[0] + dx, c[1] + dy, c[2] + dz)
                    if all(0 <= x < grid for x in v):
                        occ.add(v)
    h = np.zeros((10, n_bins))
    d2, d3 = [], []
    state, n, t = seed, len(pts), 0
    while t < n_triplets:
        state, i1 = _below(state, n)
        state, i2 = _below(state, n)
        state, i3 = _below(state, n)
        if len({i1, i2, i3}) < 3:
            continue
        P1, P2, P3 = (np.array(pts[i]) for i in (i1, i2, i3))
        v21, v31, v23 = P2 - P1, P3 - P1, P2 - P3
        a, b, c = (math.sqrt(float(v @ v)) for v in (v21, v31, v23))
        s = (a + b + c) * 0.5
        heron = s * (s - a) * (s - b) * (s - c)
        if heron <= 0.001:
            continue

        def ang(x, y, norm):
            return _rbin(math.acos(min(abs(float(x @ y)) / norm, 1.0)) / (math.pi / 2), n_bins)

        th1, th2, th3 = ang(v21, v31, a * b), ang(v23, v31, c * b), ang(v23, v21, c * a)
        lines = [_walk(occ, cells[i1], cells[i2]), _walk(occ, cells[i1], cells[i3]), _walk(occ, cells[i2], cells[i3])]
        for cls, _, _, ratio in lines:
            if cls == 2:
                h[9, _rbin(ratio, n_bins)] += 1
        for side, (cls, _, _, _) in zip((a, b, c), lines):
            d2.append((side, cls))
        in_sum = sum(x[1] for x in lines)
        n_sum = sum(x[2] for x in lines)
        k = 1 if in_sum <= 21 else (0 if n_sum - in_sum < 4 else 2)
        h[k, th1] += lines[2][2] / 32.0
        h[k, th2] += lines[0][2] / 32.0
        h[k, th3] += lines[1][2] / 32.0
        d3.append((math.sqrt(math.sqrt(heron)), k))
        t += 1
    m2, m3 = max(x for x, _ in d2), max(x for x, _ in d3)
    for v, k in d3:
        h[3 + k, _rbin(v / m3, n_bins)] += 1
    for v, k in d2:
        h[6 + k, _rbin(v / m2, n_bins)] += 1
    h *= np.array([0.5, 0.5, 0.5, 0.5, 0.5, 1.0, 0.5, 2.0, 2.0, 1.0])[:, None]
    return (h / h.sum()).ravel()


# (64, 64): the batched kernel with the A3 table over the cosine; (64, 300):
# with the table over sin(angle / 2) (bins too fine for the cosine table);
# (128, 7): the triplet-by-triplet kernel of larger grids.
@pytest.mark.parametrize(
    "random_state, grid, n_bins", [(0, 64, 64), (7, 64, 64), (1, 32, 100), (3, 64, 300), (2, 128, 7)]
)
def test_matches_slow_reference(random_state, grid, n_bins):
    clouds = _clouds(3, seed=random_state)
    est = ESFTransformer(n_triplets=300, grid_size=grid, n_bins=n_bins, random_state=random_state)
    X = est.fit_transform(clouds)
    seeds = object_seeds(random_state, len(clouds))
    for k, cloud in enumerate(clouds):
        assert_allclose(X[k], _esf_reference(cloud, int(seeds[k]), 300, grid, n_bins), rtol=0, atol=1e-12)


def test_right_triangle_by_hand():
    # Three points: every triplet is the same 3-4-5 triangle, all lines "out"
    # (a line holds occupied voxels only next to its ends), so the histogram
    # follows from the triangle alone.
    tri = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]])
    X = ESFTransformer(n_triplets=50, random_state=0).fit_transform([tri])[0].reshape(10, 64)
    p = tri - tri.mean(axis=0)
    p *= 32 / np.sqrt((p**2).sum(axis=1).max())
    cells = np.where(p < 0, np.floor(p) + 32, np.ceil(p) + 31)
    n_vox = lambda i, j: max(int(np.abs(cells[i] - cells[j]).max()), 1)  # noqa: E731
    expected = np.zeros((10, 64))
    # A3 (out): angle at each vertex (90, atan(3/4), atan(4/3) degrees), weight = opposite side's voxels / 32.
    for angle, opposite in ((np.pi / 2, (1, 2)), (np.arctan2(3, 4), (0, 2)), (np.arctan2(4, 3), (0, 1))):
        expected[1, int(np.floor(angle / (np.pi / 2) * 63 + 0.5))] += 0.5 * n_vox(*opposite) / 32
    expected[4, 63] = 0.5  # D3 (out): one triangle, at the maximum
    for side in (5.0, 4.0, 3.0):  # D2 (out), relative to the longest side
        expected[7, int(np.floor(side / 5.0 * 63 + 0.5))] += 2.0
    expected /= expected.sum()
    assert_allclose(X, expected, rtol=1e-12, atol=1e-15)
    assert X[1, 63] > 0 and X[1, 26] > 0 and X[1, 37] > 0


def test_shape_sum_layout_and_names():
    est = ESFTransformer(n_triplets=2000, random_state=0)
    X = est.fit_transform(_clouds())
    assert X.shape == (4, 640)
    assert np.all(X >= 0)
    assert_allclose(X.sum(axis=1), 1.0)
    names = est.get_feature_names_out()
    assert len(names) == 640 and names[0] == "esf_a3_in_0" and names[-1] == "esf_d2_ratio_63"
    assert ESFTransformer(n_bins=16, n_triplets=500, random_state=0).fit_transform(_clouds()).shape == (4, 160)


def test_threads_and_repeats_are_bit_identical():
    clouds = _clouds(6)
    a = ESFTransformer(n_triplets=3000, random_state=3, n_jobs=1).fit_transform(clouds)
    b = ESFTransformer(n_triplets=3000, random_state=3, n_jobs=2).fit_transform(clouds)
    est = ESFTransformer(n_triplets=3000, random_state=3).fit(clouds)
    assert_array_equal(a, b)
    assert_array_equal(est.transform(clouds), est.transform(clouds))
    assert_array_equal(a[2], ESFTransformer(n_triplets=3000, random_state=3).fit_transform(clouds)[2])
    c = ESFTransformer(n_triplets=3000, random_state=4).fit_transform(clouds)
    assert not np.array_equal(a, c)


def test_scale_invariant_and_normals_ignored():
    clouds = _clouds(2)
    est = ESFTransformer(n_triplets=2000, random_state=1)
    a = est.fit_transform(clouds)
    b = est.transform([2.0 * c for c in clouds])  # a power of two keeps every value exact
    assert_array_equal(a, b)
    with_normals = [np.hstack([c, np.tile([0.0, 0.0, 1.0], (len(c), 1))]) for c in clouds]
    assert_array_equal(a, est.transform(with_normals))


def test_rotation_changes_little():
    # ESF is rotation invariant up to its voxelisation.
    rng = np.random.default_rng(0)
    clouds = [rng.normal(size=(400, 3)) * [1.0, 0.4, 0.2], rng.uniform(size=(400, 3))]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    est = ESFTransformer(n_triplets=20000, random_state=0)
    X = est.fit_transform(clouds)
    R = est.transform([c @ q.T for c in clouds])
    assert np.abs(X[0] - R[0]).sum() < 0.5 * np.abs(X[0] - X[1]).sum()


def test_pipeline_and_grid_search():
    rng = np.random.default_rng(0)
    clouds, y = [], []
    for k in range(12):
        scale = [1.0, 1.0, 0.05] if k % 2 else [1.0, 0.3, 0.3]
        clouds.append(rng.normal(size=(80, 3)) * scale)
        y.append(k % 2)
    pipe = make_pipeline(ESFTransformer(n_triplets=1000, random_state=0), KLNearestNeighbors())
    search = GridSearchCV(pipe, {"esftransformer__n_bins": [16, 32]}, cv=2).fit(clouds, y)
    assert search.best_score_ > 0.8


@pytest.mark.parametrize(
    "params, err, msg",
    [
        ({"n_triplets": 0}, ValueError, "ESFTransformer: n_triplets must be an int in [1, 536870912], got 0"),
        ({"n_triplets": 1.5}, TypeError, "ESFTransformer: n_triplets must be an int in [1, 536870912], got 1.5"),
        ({"grid_size": 63}, ValueError, "ESFTransformer: grid_size must be an even int in [4, 1024], got 63"),
        ({"grid_size": 2}, ValueError, "ESFTransformer: grid_size must be an even int in [4, 1024], got 2"),
        ({"n_bins": 0}, ValueError, "ESFTransformer: n_bins must be an int in [1, 4096], got 0"),
        ({"n_jobs": 0}, ValueError, "n_jobs must be None or a non-zero int (-1: all cores), got 0"),
    ],
)
def test_bad_parameters(params, err, msg):
    with pytest.raises(err, match=re.escape(msg)):
        ESFTransformer(**params).fit(_clouds())


@pytest.mark.parametrize(
    "X, err, msg",
    [
        ([np.zeros((2, 3)) + [[0, 0, 0], [1, 0, 0]]], ValueError, "point cloud 0 has 2 points; at least 3 are needed"),
        ([np.array([[0.0, 0, 0], [1, 0, 0], [np.nan, 0, 0]])], ValueError, "point cloud 0 contains NaN"),
        ([np.ones((5, 4))], ValueError, "point cloud 0 must have shape"),
        ([], ValueError, "X is empty"),
        (np.ones((5, 3)), ValueError, "X is a single 2D array"),
        ("cloud", TypeError, "X must be a list of point clouds"),
    ],
)
def test_bad_clouds(X, err, msg):
    with pytest.raises(err, match=re.escape("ESFTransformer: " + msg)):
        ESFTransformer(n_triplets=100).fit(X)


def test_collinear_cloud_is_rejected():
    line = np.outer(np.linspace(0, 1, 20), [1.0, 2.0, 3.0])
    est = ESFTransformer(n_triplets=100, random_state=0).fit([line])
    msg = "ESFTransformer: point cloud 0 has no triangles of non-zero area"
    with pytest.raises(ValueError, match=re.escape(msg)):
        est.transform([line])


def test_not_fitted():
    with pytest.raises(NotFittedError):
        ESFTransformer().transform(_clouds())


def _dilated(cells, grid):
    occ = set()
    for c in cells:
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    v = (int(c[0]) + dx, int(c[1]) + dy, int(c[2]) + dz)
                    if all(0 <= x < grid for x in v):
                        occ.add(v)
    return occ


def test_packed_line_walk_matches_bresenham_for_every_length_and_slope():
    # The batched kernel walks lines in packed fixed point over three grid
    # layouts; every dominant axis, direction, length 0..63 and minor slope
    # -L..L must visit exactly PCL's voxels (about 40% of them occupied).
    from eppf.descriptors._esf_fast import esf_line_counts

    rng = np.random.default_rng(0)
    grid = 64
    occupied = rng.integers(0, grid, size=(5000, 3)).astype(np.int32)
    occ = _dilated(occupied, grid)
    starts, ends = [], []
    for major in range(3):
        for sign in (1, -1):
            for L in range(grid):
                for d1 in range(-L, L + 1):
                    d2 = (d1 * 7 + 3) % (2 * L + 1) - L
                    a, b = [0, 0, 0], [0, 0, 0]
                    a[major] = 0 if sign > 0 else grid - 1
                    b[major] = a[major] + sign * L
                    for ax, d in zip([x for x in range(3) if x != major], (d1, d2)):
                        a[ax] = int(rng.integers(0, grid - d)) if d >= 0 else int(rng.integers(-d, grid))
                        b[ax] = a[ax] + d
                    starts.append(a)
                    ends.append(b)
    starts, ends = np.array(starts, np.int32), np.array(ends, np.int32)
    got_occ, got_cnt = esf_line_counts(occupied, starts, ends, grid)
    ref = [_walk(occ, tuple(a), tuple(b)) for a, b in zip(starts, ends)]
    assert_array_equal(got_cnt, [r[2] for r in ref])
    assert_array_equal(got_occ, [r[1] for r in ref])
    assert 0.2 < np.mean(got_occ / got_cnt) < 0.6
    # The batched walks of esf_take (scalar, and four AVX2 lanes where the
    # CPU has them), on the lines in a shuffled order so that every batch
    # mixes lengths, must give the same counts.
    from eppf.descriptors._esf_fast import _set_simd

    perm = rng.permutation(len(starts))
    for simd in (False, True):
        old = _set_simd(simd)
        try:
            b_occ, b_cnt = esf_line_counts(occupied, starts[perm], ends[perm], grid, batch=True)
        finally:
            _set_simd(old)
        assert_array_equal(b_cnt, got_cnt[perm])
        assert_array_equal(b_occ, got_occ[perm])


@pytest.mark.parametrize("n_bins", [1, 7, 64, 300])
def test_scaled_binning_with_and_without_simd(n_bins):
    # D2/D3 binning (four at a time with AVX2, a scalar tail; blocks with a value near a bin boundary
    # redone by division) against NumPy's division, clamps and NaN included, over several blocks
    from eppf.descriptors._esf_fast import esf_scaled_counts

    rng = np.random.default_rng(n_bins)
    vmax = 1.7
    boundary = (np.arange(n_bins) + 0.5) / max(n_bins - 1, 1) * vmax  # exact bin boundaries
    special = np.array([0.0, -0.0, -1.0, vmax, 2 * vmax, np.inf, -np.inf, np.nan, 1e300])
    for n, with_special in ((1, False), (3, False), (255, False), (1001, False), (1001, True), (3000, True)):
        v = rng.uniform(0, vmax, n)
        if with_special:
            v[rng.choice(n, 20, replace=False)] = rng.choice(np.concatenate([special, boundary]), 20)
        cls = rng.integers(0, 3, n).astype(np.int8)
        with np.errstate(invalid="ignore"):
            x = np.nan_to_num(v / vmax * (n_bins - 1) + 0.5, nan=0.0, posinf=n_bins, neginf=0.0)
        ref = np.zeros((3, n_bins), np.int64)
        np.add.at(ref, (cls, np.clip(np.floor(x), 0, n_bins - 1).astype(np.int64)), 1)
        for simd in (False, True):
            assert_array_equal(esf_scaled_counts(v, cls, vmax, n_bins, simd), ref)


@pytest.mark.parametrize("n_points", [5, 1024])
def test_simd_line_walks_give_identical_descriptors(n_points):
    # The walk kernels are chosen at run time; the descriptor must not depend on it.
    from eppf.descriptors._esf_fast import _set_simd

    rng = np.random.default_rng(3)
    clouds = [rng.normal(size=(n_points, 3)) * [1, 2, 0.5] for _ in range(4)]
    outs = []
    for simd in (False, True):
        old = _set_simd(simd)
        try:
            outs.append(ESFTransformer(n_triplets=3000, random_state=0, n_jobs=1).fit(clouds).transform(clouds))
        finally:
            _set_simd(old)
    assert_array_equal(outs[1], outs[0])
