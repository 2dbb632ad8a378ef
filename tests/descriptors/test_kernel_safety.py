"""Memory safety of the compiled kernels and exact rescaling of clouds of extreme magnitude.

Two layers are tested: the kernels themselves (every float->int conversion
that feeds an index is clamped, so NaN, inf and huge values cannot index out
of bounds: a histogram still counts every pair), and the Python-level
conditioning that brings clouds outside the kernels' magnitude window into
it by an exact power of two (scale-invariant descriptors then give,
bit for bit, what they give at a sane scale).
"""

import numpy as np
import pytest

from eppf import EPPFTransformer, ESFTransformer, OURCVFHTransformer, WahlTransformer, estimate_normals
from eppf.descriptors import _eppf_fast as _core
from eppf.descriptors import _esf_fast as _baselines
from eppf.descriptors import _wahl_fast
from eppf.preprocessing._normals import estimate_normals_batch
from eppf.preprocessing._normals_fast import normals_packed, scratch_sizes
from eppf.utils._validation import check_packed_clouds, check_point_cloud, check_point_clouds, condition_point_clouds


def _sphere(n=400, seed=1):
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1)[:, None]


def _huge_pair_cloud():
    p = np.random.default_rng(0).normal(size=(500, 3))
    p[0, 0] = 1e308
    p[1, 0] = -1e308
    return p


@pytest.fixture(params=[True, False], ids=["simd", "scalar"])
def simd(request):
    old_core = _core._set_simd(request.param)
    old_esf = _baselines._set_simd(request.param)
    yield request.param
    _core._set_simd(old_core)
    _baselines._set_simd(old_esf)


# ------------------------------------------------------------------ kernels
@pytest.mark.parametrize("grid", [2, 17, 64, 100])
def test_eppf_kernel_counts_every_pair_of_an_overflowing_cloud(simd, grid):
    # the cloud's side overflows to inf: before the clamps _voxel cast NaN to
    # INT_MIN and wrote outside the bit grid
    p = _huge_pair_cloud()
    nrm = _sphere(500)
    offsets = np.array([0, 500], dtype=np.int64)
    seeds = np.array([7], dtype=np.uint64)
    for scale in (1.0, np.inf, np.nan, -1.0, 0.0):
        counts, status = _core.eppf_counts(
            p, nrm, offsets, np.array([scale]), seeds, 3000, (5, 4, 3, 3), grid, np.sqrt(3.0), 1
        )
        assert status[0] == 0
        assert counts.sum() == 3000 and counts.min() >= 0  # no pair lost to an out-of-range bin


@pytest.mark.parametrize("grid", [2, 17, 64, 100])
def test_eppf_pair_features_bins_stay_in_range(grid):
    p = _huge_pair_cloud()
    nrm = _sphere(500)
    pairs = _core.eppf_pairs(np.ascontiguousarray(p), np.uint64(3), 2000)
    for scale in (1.0, np.inf, np.nan, -2.0):
        out = _core.eppf_pair_features(p, nrm, pairs, scale, (6, 4, 5, 3), grid, np.sqrt(3.0))
        for col, n in enumerate((6, 4, 5, 3)):
            assert out[:, col].min() >= 0 and out[:, col].max() < n
        assert (out[:, 4] >= 1).all() and (out[:, 4] <= out[:, 5]).all() and (out[:, 5] <= grid).all()


def test_eppf_kernel_rejects_objects_too_small_to_draw_from():
    p = np.zeros((3, 3))
    counts, status = _core.eppf_counts(
        p, p, np.array([0, 1, 1, 3], dtype=np.int64), np.ones(3), np.arange(3, dtype=np.uint64), 10,
        (2, 1, 1, 1), 8, 1.0, 1,
    )
    assert status[0] == 1 and status[1] == 1  # one point, no point: no pair can be drawn
    with pytest.raises(ValueError):
        _core.eppf_counts(p, p, np.array([0, 2, 1], dtype=np.int64), np.ones(2), np.zeros(2, np.uint64), 10,
                          (2, 1, 1, 1), 8, 1.0, 1)


@pytest.mark.parametrize("grid", [8, 64, 80])
def test_esf_kernel_survives_non_finite_and_overflowing_points(simd, grid):
    rng = np.random.default_rng(2)
    clouds = [_sphere(200), _huge_pair_cloud()[:200], rng.normal(size=(200, 3)) * 1e-320,
              np.full((200, 3), np.nan), np.zeros((200, 3)), np.array([[0.0, 0, 0], [1, 0, 0]])]
    points = np.ascontiguousarray(np.concatenate(clouds))
    offsets = np.cumsum([0] + [len(c) for c in clouds]).astype(np.int64)
    out = np.zeros((len(clouds), 10 * 17))
    status = np.zeros(len(clouds), dtype=np.int8)
    _baselines.esf_batch(points, offsets, np.arange(len(clouds), dtype=np.uint64), 500, grid, 17, 1e-12,
                         out, status, 1)
    assert status[0] == 0 and np.isclose(out[0].sum(), 1.0)
    assert status[-1] == 1  # two points: no triangle
    for k in range(len(clouds)):  # a zero row with status 1, or a histogram
        assert (status[k] == 1 and not out[k].any()) or (status[k] == 0 and np.isclose(out[k].sum(), 1.0))
    with pytest.raises(ValueError, match="one entry"):
        _baselines.esf_batch(points, offsets, np.zeros(2, dtype=np.uint64), 10, grid, 17, 1e-12, out, status, 1)


def test_wahl_kernel_bins_of_non_finite_values():
    vals = np.array([np.nan, np.inf, -np.inf, 1e308, -1e308, 0.0, -0.0, 1.0, -1.0])
    y, x = np.meshgrid(vals, vals)
    for exact in (False, True):
        b = _wahl_fast.wahl_alpha_bins(y.ravel(), x.ravel(), 7, exact)
        assert b.min() >= 0 and b.max() < 7
    rng = np.random.default_rng(4)
    p = np.ascontiguousarray(np.concatenate([_huge_pair_cloud()[:100], np.full((50, 3), np.nan)]))
    nrm = np.ascontiguousarray(np.concatenate([_sphere(100), _sphere(50, 2)]))
    out = np.zeros((2, 4 ** 4))
    status = np.zeros(2, dtype=np.int8)
    _wahl_fast.wahl_batch(p, nrm, np.array([0, 100, 150], dtype=np.int64), np.arange(2, dtype=np.uint64), 400,
                          np.full(4, 4, dtype=np.int32), False, out, status, 1)
    for k in range(2):
        assert (status[k] == 1 and not out[k].any()) or np.isclose(out[k].sum(), 1.0)
    del rng


def test_normals_kernel_survives_non_finite_points():
    pts = np.concatenate([_sphere(60), np.full((30, 3), np.nan), _huge_pair_cloud()[:40] * np.inf])
    pts = np.ascontiguousarray(pts)
    off = np.array([0, 60, 90, 130], dtype=np.int64)
    f_len, i_len = scratch_sizes(60, 10)
    out = np.zeros((len(pts), 3))
    normals_packed(pts, off, 10, 1, np.zeros(3), out, np.empty((1, f_len)), np.empty((1, i_len), dtype=np.int64),
                   60, 1)
    assert np.allclose(np.linalg.norm(out[:60], axis=1), 1.0)


# ---------------------------------------------------------- the reproducers
@pytest.mark.parametrize("grid", [2, 17, 64, 100])
def test_eppf_on_a_pair_at_plus_minus_1e308(grid):
    p = _huge_pair_cloud()
    for scaling in ("object", "none"):
        X = EPPFTransformer(n_pairs=2000, random_state=0, scaling=scaling, grid_size=grid).fit_transform([p])
        assert np.isfinite(X).all() and np.isclose(X.sum(), 1.0)
    # one data-set scale cannot be 1 / inf
    with pytest.raises(ValueError, match="EPPFTransformer.*scaling='object'"):
        EPPFTransformer(n_pairs=2000, random_state=0, grid_size=grid).fit([p])


def _transformers():
    return [
        EPPFTransformer(n_pairs=2000, scaling="object", random_state=0),
        ESFTransformer(n_triplets=2000, random_state=0),
        WahlTransformer(n_pairs=2000, random_state=0),
        OURCVFHTransformer(),
    ]


@pytest.mark.parametrize("est", _transformers(), ids=lambda e: type(e).__name__)
def test_scaled_sphere_gives_the_unit_sphere_descriptor(est):
    s = _sphere()
    ref = est.fit_transform([s])
    # powers of two (the scaled coordinates are exact): bit for bit
    for k in (-1000, -340, -101, 101, 515, 1000):
        assert np.array_equal(est.fit_transform([np.ldexp(s, k)]), ref), k
    for f in (1e-307, 1e-310, 1e155, 1e-200):
        X = est.fit_transform([s * f])
        assert np.isfinite(X).all() and np.isclose(X.sum(), 1.0)
        # exactly what the same numbers give once brought to a sane scale (a
        # power of two: exact, subnormal coordinates included, on every CPU)
        sane = np.ldexp(s * f, -int(np.frexp(f)[1]))
        assert np.array_equal(X, est.fit_transform([sane])), f
        # near the unit sphere's descriptor: s * f rounds each coordinate (to 44
        # bits at 1e-310). OUR-CVFH's clusters are chaotic under such jitter (a
        # 1e-13 relative change moves 0.1-0.35 of its mass, by CPU, since its
        # frames and weights come from LAPACK and NumPy), so the bound is for the
        # others only.
        if not isinstance(est, OURCVFHTransformer):
            assert np.abs(X - ref).sum() < 0.02, f


def test_estimate_normals_of_scaled_spheres():
    s = _sphere()
    ref = estimate_normals(s)
    for k in (-1000, -340, 515, 1000):
        assert np.array_equal(estimate_normals(np.ldexp(s, k)), ref)
    for f in (1e-307, 1e-310, 1e155, 1e-200, 1e308):
        n = estimate_normals(s * f)
        assert np.isfinite(n).all() and (np.einsum("ij,ij->i", n, s) > 0.9).mean() > 0.95


def test_eppf_absolute_scalings_compensate_the_rescaling():
    s = _sphere()
    est = EPPFTransformer(n_pairs=2000, random_state=0, scaling="none")
    # f1 is |d| in the input's units: all in bin 0 for a tiny sphere, all in the
    # top bin for a huge one, whichever power of two the kernel sees
    assert np.array_equal(est.fit_transform([np.ldexp(s, -300)]), est.fit_transform([np.ldexp(s, -90)]))
    assert np.array_equal(est.fit_transform([np.ldexp(s, 300)]), est.fit_transform([np.ldexp(s, 90)]))
    h = est.to_histogram(est.fit_transform([np.ldexp(s, -300)]))[0]
    assert h[1:].sum() == 0
    fit = EPPFTransformer(n_pairs=2000, random_state=0)
    for k in (-600, -200, 200, 900):
        assert np.array_equal(fit.fit_transform([np.ldexp(s, k)]), fit.fit_transform([s])), k
    with pytest.raises(ValueError, match="EPPFTransformer: the largest training object's side"):
        EPPFTransformer().fit([s * 1e-320])


def test_ourcvfh_absolute_scalings_reject_out_of_range_clouds():
    s = _sphere()
    for scaling in ("none", "fit"):
        est = OURCVFHTransformer(scaling=scaling).fit([s])
        with pytest.raises(ValueError, match="OURCVFHTransformer: point cloud 1 .*scaling='object'"):
            est.transform([s, s * 1e-200])
    with pytest.raises(ValueError, match="OURCVFHTransformer: the largest training object's side"):
        OURCVFHTransformer(scaling="fit").fit([_huge_pair_cloud()])


@pytest.mark.parametrize("est", _transformers() + [None], ids=lambda e: type(e).__name__ if e else "normals")
def test_tiny_object_far_from_the_origin_is_a_clear_error(est):
    # a 1e-10 object at x = 1e300: distinct points (in y and z), but no power
    # of two fits both its size and its distance from the origin in the window
    cloud = _sphere() * 1e-10 + [1e300, 0.0, 0.0]
    assert len(np.unique(cloud, axis=0)) == len(cloud)
    with pytest.raises(ValueError, match=r"point cloud (1 )?is too small for its distance from the origin.*centre"):
        if est is None:
            estimate_normals(cloud)
        else:
            est.fit_transform([_sphere(), cloud])
    if est is not None:
        with pytest.raises(ValueError, match=f"{type(est).__name__}: point cloud 1 "):
            est.fit_transform([_sphere(), cloud])


# ------------------------------------------------------------ conditioning
def test_condition_leaves_ordinary_clouds_alone_and_rescales_the_others_in_place():
    rng = np.random.default_rng(5)
    X = [rng.normal(size=(30, 3)), rng.normal(size=(30, 3)) * 1e-200, rng.normal(size=(30, 3)) * 1e250]
    for check, batched in ((check_packed_clouds, True), (check_packed_clouds, False), (check_point_clouds, True),
                           (check_point_clouds, False)):
        clouds = check(X if batched else [c.tolist() for c in X])
        before = [c.copy() for c in clouds]
        exps = condition_point_clouds(clouds)
        assert exps[0] == 0 and exps[1] > 0 and exps[2] < 0
        assert np.array_equal(clouds[0], before[0])
        for c, b, e in zip(clouds, before, exps):
            assert np.array_equal(c, np.ldexp(b, int(e)))
            side = np.ptp(c, axis=0).max()
            assert 2.0**-100 <= side and np.abs(c).max() <= 2.0**100
        # the input arrays are never touched (the validated clouds are copies)
        assert np.abs(X[1]).max() < 1e-190
        if check is check_packed_clouds:  # the bounding boxes follow the rescaling
            assert np.array_equal(clouds.lower, np.array([c.min(axis=0) for c in clouds]))
            assert np.array_equal(clouds.upper, np.array([c.max(axis=0) for c in clouds]))


def test_estimate_normals_does_not_touch_the_callers_array_and_keeps_the_viewpoint():
    xy = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0)), -1).reshape(-1, 2)
    plane = np.column_stack([xy, np.zeros(len(xy))]) * 1e-305
    copy = plane.copy()
    for vp, sign in (([0, 0, 1e-300], 1), ([0, 0, -5.0], -1), ([0, 0, 1e300], 1)):
        n = estimate_normals(plane, 8, orientation=vp)
        assert np.allclose(n, [0, 0, sign])
    assert np.array_equal(plane, copy)
    # a batch whose objects need different powers of two, with one viewpoint
    big = np.column_stack([xy, np.zeros(len(xy))]) * 1e250
    pts = np.concatenate([plane, big, plane * 1e300])
    off = np.array([0, 36, 72, 108])
    n = estimate_normals_batch(pts, off, 8, [0.0, 0.0, -5.0])
    assert np.allclose(n, [0, 0, -1])


def test_huge_normals_are_normalised_the_same_on_both_paths():
    rng = np.random.default_rng(6)
    p = rng.normal(size=(40, 3))
    for mag in (1.0, 1e153, 1e155, 1e200, 1e300, 1.7e308):
        nrm = np.clip(rng.normal(size=(40, 3)), -1, 1) * mag
        cloud = np.hstack([p, nrm])
        single = check_point_cloud(cloud)
        batch = check_point_clouds([cloud, cloud])[1]
        assert np.array_equal(single, batch)
        assert np.allclose(np.linalg.norm(single[:, 3:], axis=1), 1.0)
        assert np.allclose(single[:, 3:], nrm / np.linalg.norm(nrm / mag, axis=1)[:, None] / mag)
    # normals too short to have a direction are still refused on both paths
    for path in (check_point_cloud, lambda c: check_point_clouds([c, c])):
        with pytest.raises(ValueError, match="zero-length normal"):
            path(np.hstack([p, rng.normal(size=(40, 3)) * 1e-310]))
