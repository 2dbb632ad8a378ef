"""Tests of CVFHTransformer: two planar regions at a known angle (regions,
centroids, normals, signature against a NumPy VFH built on the shared pair
features), PCL's fallback, aggregation, rotation invariance, layout,
determinism, thread/chunk bit-identity and bad input."""

import re
import doctest

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import eppf.utils._chunks
import eppf.descriptors._cvfh as cvfh_module
from eppf.datasets import make_shapes
from eppf.descriptors._cvfh import CVFHTransformer, _cvfh_object, _cvfh_regions
from eppf.descriptors._cvfh_fast import crowded_points, vfh_signatures
from eppf.descriptors._regions import pair_features

PHI = 1.0  # angle between the two planes' normals (radians)
H = 0.3  # distance of both planes from the (uncentred) origin

PARAMS = dict(eps_angle=0.125, curvature_threshold=0.03, cluster_tolerance=0.015, radius_normals=0.015,
              min_points=50, normalize_bins=False, n_neighbors=10)


def _rx(a):
    return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])


def _two_planes(m_a=20, m_b=20, spacing=0.01):
    """Square grids on the plane z = -H (normal +z, towards the origin) and
    on its copy rotated by PHI about the x axis; no grid point at a patch
    centre. Returns the centred points, normals, and each patch's indices."""
    def grid(m):
        g = (np.arange(m) - (m - 1) / 2) * spacing
        xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
        return np.column_stack([xy, np.full(len(xy), -H)])

    a, b = grid(m_a), grid(m_b) @ _rx(PHI).T
    pts = np.vstack([a, b])
    nrm = np.vstack([np.tile([0.0, 0.0, 1.0], (len(a), 1)), np.tile(_rx(PHI) @ [0.0, 0.0, 1.0], (len(b), 1))])
    pts = pts - pts.mean(axis=0)
    return pts, nrm, np.arange(len(a)), np.arange(len(a), len(pts))


def _np_vfh(points, normals, c, nc):
    """VFH of (c, nc) against every point from the shared double-precision
    pair features, PCL's binning (every pair defined here)."""
    f1, f2, f3 = pair_features(c, nc, points, normals)
    assert len(f1) == len(points)
    d = np.linalg.norm(points - c, axis=1)

    def hist(v, n):
        return np.bincount(np.clip(np.floor(v).astype(np.int64), 0, n - 1), minlength=n)

    angles = [hist(45 * (f + np.pi) / (2 * np.pi), 45) for f in (f1, f2, f3)]
    view = -c / np.linalg.norm(c)
    return np.concatenate(angles + [hist(45 * d / d.max(), 45), hist(128 * (normals @ view + 1) / 2, 128)])


def test_two_planar_regions_at_a_known_angle():
    pts, nrm, ia, ib = _two_planes()
    clusters, cents, refs = _cvfh_regions(pts, nrm, **PARAMS)
    assert len(clusters) == 2
    assert_array_equal(clusters[0], ia)
    assert_array_equal(clusters[1], ib)
    assert_allclose(cents[0], pts[ia].mean(0), atol=1e-6)
    assert_allclose(cents[1], pts[ib].mean(0), atol=1e-6)
    # the second normals face the origin (the object's centroid): +z and the rotated +z
    assert_allclose(refs[0], [0.0, 0.0, 1.0], atol=1e-6)
    assert_allclose(refs[1], [0.0, -np.sin(PHI), np.cos(PHI)], atol=1e-6)
    assert np.arccos(np.clip(refs[0] @ refs[1], -1, 1)) == pytest.approx(PHI, abs=1e-6)
    # hand facts: a patch's own points lie in the plane through its centroid
    # with the reference normal, so all three angles are 0 (bin 22 of 45)
    f1, f2, f3 = pair_features(cents[0].astype(float), refs[0].astype(float), pts[ia], nrm[ia])
    assert_allclose(np.c_[f1, f2, f3], 0.0, atol=1e-4)  # single-precision centroid
    sigs, sizes = _cvfh_object(pts, nrm, **PARAMS)
    assert sizes == [400, 400] and sigs.shape == (2, 308)
    for r in range(2):
        want = _np_vfh(pts, nrm, cents[r].astype(float), refs[r].astype(float))
        assert_array_equal(sigs[r], want)
        assert sigs[r][22] >= 400 and sigs[r][45 + 22] >= 400 and sigs[r][90 + 22] >= 400
        # the origin seen from a region's centroid: v = -c / |c| makes the
        # angle pi/2 - PHI/2 with the region's normal, so the patch's 400
        # points all fall in viewpoint bin floor(64 (1 + sin(PHI / 2)))
        assert sigs[r][180 + int(64 * (1 + np.sin(PHI / 2)))] >= 400
        # every pair is defined: each histogram holds all 800 points
        assert_array_equal(sigs[r].reshape(-1)[:180].reshape(4, 45).sum(1), 800)
        assert sigs[r][180:].sum() == 800


def test_kernel_matches_numpy_vfh_on_random_clouds():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(300, 3))
    nrm = rng.normal(size=(300, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    c = rng.normal(size=(4, 3)) * 0.3
    nc = rng.normal(size=(4, 3))
    nc /= np.linalg.norm(nc, axis=1, keepdims=True)
    p32, n32, c32, nc32 = (a.astype(np.float32) for a in (pts, nrm, c, nc))
    out = np.empty((4, 308))
    vfh_signatures(p32, n32, c32, nc32, False, out)
    for r in range(4):
        assert_array_equal(out[r], _np_vfh(p32.astype(float), n32.astype(float), c32[r].astype(float),
                                           nc32[r].astype(float)))
    # normalize_bins: 100 / (n - 1) per angle/distance pair, 100 / n per viewpoint
    scaled = np.empty((4, 308))
    vfh_signatures(p32, n32, c32, nc32, True, scaled)
    assert_allclose(scaled[:, :180], out[:, :180] * 100 / 299, rtol=1e-5)
    assert_allclose(scaled[:, 180:], out[:, 180:] * 100 / 300, rtol=1e-5)


def test_fallback_without_regions_is_pcls():
    # 300 points over a unit sphere are ~0.2 apart: no point has neighbours
    # within PCL's default radii, so no region forms
    rng = np.random.default_rng(1)
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    clusters, cents, refs = _cvfh_regions(u, u, **PARAMS)
    assert clusters == []
    # PCL's fallback: single-precision centroid, unnormalised mean normal
    assert_allclose(cents[0], u.mean(0), atol=1e-6)
    assert_allclose(refs[0], u.mean(0), atol=1e-6)
    assert np.linalg.norm(refs[0]) < 0.5
    sigs, sizes = _cvfh_object(u, u, **PARAMS)
    assert sizes == [300] and sigs.shape == (1, 308)
    rows = {a: CVFHTransformer(aggregate=a, normalize=False).fit_transform([np.hstack([u, u])])[0]
            for a in ("first", "largest", "mean")}
    assert_array_equal(rows["first"], rows["largest"])
    assert_array_equal(rows["first"], rows["mean"])


def test_curvature_filter_removes_regions():
    pts, nrm, _, _ = _two_planes()
    noisy = pts + np.random.default_rng(2).normal(scale=0.003, size=pts.shape)
    assert len(_cvfh_regions(noisy, nrm, **{**PARAMS, "curvature_threshold": 1.0, "eps_angle": 1.0})[0]) == 2
    assert _cvfh_regions(noisy, nrm, **{**PARAMS, "curvature_threshold": 1e-9})[0] == []


def test_aggregate():
    pts, nrm, ia, ib = _two_planes(m_a=10, m_b=20)  # the first region is the smaller one
    cloud = np.hstack([pts, nrm])
    sigs, sizes = _cvfh_object(pts, nrm, **PARAMS)
    assert sizes == [100, 400]
    rows = {a: CVFHTransformer(aggregate=a, scaling="none", normalize=False).fit_transform([cloud])[0]
            for a in ("first", "largest", "mean")}
    assert_array_equal(rows["first"], sigs[0])
    assert_array_equal(rows["largest"], sigs[1])
    assert_allclose(rows["mean"], sigs.mean(0))
    norm = CVFHTransformer(scaling="none").fit_transform([cloud])[0]
    assert_allclose(norm, sigs[1] / sigs[1].sum())


def test_rotation_invariance():
    pts, nrm, _, _ = _two_planes()
    est = CVFHTransformer(scaling="none", normalize=False).fit([np.hstack([pts, nrm])])
    base = est.transform([np.hstack([pts, nrm])])[0]
    rng = np.random.default_rng(3)
    for _ in range(3):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        rot = est.transform([np.hstack([pts @ q.T, nrm @ q.T])])[0]
        # equal up to single-precision rounding at bin edges
        assert np.abs(rot - base).sum() <= 4


@pytest.fixture(scope="module")
def shapes():
    X, y = make_shapes(3, n_points=400, random_state=0, with_normals=True, return_X_y=True)
    return X, y


def test_layout_sums_and_names(shapes):
    X, _ = shapes
    est = CVFHTransformer(normalize=False).fit(X)
    raw = est.transform(X)
    assert raw.shape == (len(X), 308)
    assert np.all(raw == np.round(raw)) and np.all(raw >= 0)
    n = np.array([len(c) for c in X])
    assert_array_equal(raw[:, 180:].sum(1), n)  # one viewpoint count per point
    assert np.all(raw[:, :180].reshape(-1, 4, 45).sum(2) <= n[:, None])
    norm = CVFHTransformer().fit_transform(X)
    assert_allclose(norm.sum(1), 1.0)
    assert_allclose(norm, raw / raw.sum(1, keepdims=True))
    names = est.get_feature_names_out()
    assert len(names) == 308 == len(set(names))
    assert names[0] == "cvfh_f1_0" and names[135] == "cvfh_sdc_0" and names[-1] == "cvfh_view_127"


def test_regions_form_with_larger_radii(shapes):
    # 400 points over a unit object: PCL's 0.015 radii find no region, 0.15 do
    X, _ = shapes
    c = X[0][:, :3] - X[0][:, :3].mean(0)
    c /= np.ptp(c, axis=0).max()
    assert _cvfh_regions(c, X[0][:, 3:], **PARAMS)[0] == []
    wide = {**PARAMS, "radius_normals": 0.15, "cluster_tolerance": 0.15, "min_points": 20}
    assert len(_cvfh_regions(c, X[0][:, 3:], **wide)[0]) >= 1


def test_normals_given_or_estimated(shapes):
    X, _ = shapes
    from eppf.preprocessing._normals import estimate_normals

    bare = [c[:, :3] for c in X[:4]]
    a = CVFHTransformer().fit_transform(bare)
    b = CVFHTransformer().fit_transform([np.hstack([c, estimate_normals(c, 10)]) for c in bare])
    assert_allclose(a, b)


def test_deterministic_and_bit_identical_across_threads_and_chunks(shapes, monkeypatch):
    X, _ = shapes
    kw = dict(radius_normals=0.1, cluster_tolerance=0.1, min_points=20)
    ref = CVFHTransformer(n_jobs=1, **kw).fit_transform(X)
    assert_array_equal(CVFHTransformer(n_jobs=1, **kw).fit_transform(X), ref)
    assert_array_equal(CVFHTransformer(n_jobs=2, **kw).fit_transform(X), ref)
    monkeypatch.setattr(eppf.utils._chunks, "CHUNK", 7)
    assert_array_equal(CVFHTransformer(n_jobs=2, **kw).fit_transform(X), ref)


def test_scaling_fit(shapes):
    X, _ = shapes
    big = [np.hstack([8.0 * c[:, :3], c[:, 3:]]) for c in X]
    est = CVFHTransformer(scaling="fit").fit(big)
    assert est.scale_ == pytest.approx(1.0 / max(np.ptp(c[:, :3], axis=0).max() for c in big))
    assert_array_equal(CVFHTransformer().fit_transform(big), CVFHTransformer().fit_transform(X))


def test_doctest():
    assert doctest.testmod(cvfh_module, raise_on_error=False).failed == 0


def _cloud(n=60, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3))


@pytest.mark.parametrize(
    "params, err, match",
    [
        ({"aggregate": "max"}, ValueError, "aggregate must be"),
        ({"region_growing": "flood"}, ValueError, "region_growing must be"),
        ({"eps_angle": -0.1}, ValueError, "eps_angle must be a float in [0.0, 3.141592653589793], got -0.1"),
        ({"eps_angle": 4.0}, ValueError, "eps_angle"),
        ({"eps_angle": "5"}, TypeError, "eps_angle must be a float"),
        ({"curvature_threshold": np.inf}, ValueError, "curvature_threshold"),
        ({"cluster_tolerance": 0.0}, ValueError, "cluster_tolerance"),
        ({"radius_normals": np.nan}, ValueError, "radius_normals"),
        ({"min_points": 0}, ValueError, "min_points must be an int >= 1, got 0"),
        ({"min_points": 5.0}, TypeError, "min_points must be an int"),
        ({"normalize_bins": "yes"}, TypeError, "normalize_bins must be True or False, got 'yes'"),
        ({"normalize": None}, TypeError, "normalize must be True or False, got None"),
        ({"scaling": "unit"}, ValueError, "scaling must be"),
        ({"n_neighbors": 1}, ValueError, "n_neighbors must be an int >= 3 (a plane needs three points), got 1"),
        ({"normal_orientation": "up"}, ValueError, "normal_orientation"),
        ({"n_jobs": 1.5}, TypeError, "n_jobs"),
    ],
)
def test_bad_parameters(params, err, match):
    with pytest.raises(err, match=re.escape(match)):
        CVFHTransformer(**params).fit([_cloud()])


@pytest.mark.parametrize(
    "X, err, match",
    [
        ([], ValueError, "empty"),
        ([np.full((5, 3), np.inf)], ValueError, "NaN or infinite"),
        ([np.zeros((2, 3))], ValueError, "at least 3"),
        ([np.zeros((10, 5))], ValueError, "shape"),
        ([np.hstack([_cloud(), np.zeros((60, 3))])], ValueError, "normal"),
        ([np.ones((6, 3))], ValueError, "identical"),
        (None, TypeError, "list of point clouds"),
    ],
)
def test_bad_clouds(X, err, match):
    with pytest.raises(err, match=re.escape(match)):
        CVFHTransformer().fit_transform(X)


def test_beyond_single_precision():
    est = CVFHTransformer(scaling="none").fit([_cloud() * 1e300])
    with pytest.raises(ValueError, match="CVFHTransformer: point cloud 0 has coordinates (beyond single precision|out of the magnitude range)"):
        est.transform([_cloud() * 1e300])


def _crowded_brute(points, radius):
    """Points with at least two other points closer than ``radius`` (brute force)."""
    with np.errstate(over="ignore"):  # far points' distances overflow to inf
        d = points[:, None, :] - points[None, :, :]
        d2 = (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]
    return int(((d2 < radius * radius).sum(axis=1) >= 3).sum())


def test_crowded_points_against_brute_force():
    # The count that lets CVFH skip its second normals: equal to brute force away from the radius,
    # never below it (pairs within 1e-9 of the radius count), stopped at `enough`; on sparse and
    # dense clouds, repeated points, far-apart clusters (empty cells) and huge extents (one cell).
    rng = np.random.default_rng(11)
    sphere = rng.normal(size=(400, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    far = np.vstack([rng.normal(size=(60, 3)) * 0.01, rng.normal(size=(60, 3)) * 0.01 + [1e3, 0, 0]])
    dup = np.repeat(rng.uniform(size=(30, 3)), 3, axis=0)
    for pts in (sphere, far, dup, rng.uniform(size=(300, 3)), rng.uniform(size=(2, 3))):
        for radius in (0.02, 0.05, 0.1, 0.3, 5.0):
            want = _crowded_brute(pts, radius)
            assert crowded_points(pts, radius, len(pts)) == want
            assert crowded_points(pts, radius, 7) == min(want, 7)
    assert crowded_points(dup, 0.0, len(dup)) == len(dup)  # radius 0: the repeats are at distance 0
    # a pair at exactly the radius counts (an upper bound), one clearly beyond it does not
    trio = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.5, 0.0]])
    assert crowded_points(trio, 0.5, 3) == 1 and _crowded_brute(trio, 0.5) == 0
    assert crowded_points(trio, 0.5 * (1 - 1e-6), 3) == 0
    huge = rng.normal(size=(50, 3)) * 1e150  # and two points whose distance overflows: one cell
    huge[0, 0] = 1.7e308
    huge[1, 0] = -1.7e308
    assert crowded_points(huge, 1e150, 50) == _crowded_brute(huge / 1e150, 1.0) > 10
    assert crowded_points(np.zeros((0, 3)), 0.1, 5) == 0
    with pytest.raises(ValueError, match="finite"):
        crowded_points(np.full((3, 3), np.nan), 0.1, 5)
    with pytest.raises(ValueError, match="radius"):
        crowded_points(sphere, np.nan, 5)


def test_kernel_rejects_inconsistent_shapes():
    p = np.zeros((5, 3), np.float32)
    with pytest.raises(ValueError, match="inconsistent array shapes"):
        vfh_signatures(p, p, p[:2], p[:2], False, np.empty((1, 308)))
    with pytest.raises(ValueError, match="at least two points"):
        vfh_signatures(p[:1], p[:1], p[:1], p[:1], False, np.empty((1, 308)))


def test_not_fitted():
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        CVFHTransformer().transform([_cloud()])


# ----------------------------------------------------------- PCL's region growing
def test_pcl_region_growing_hand_cases():
    from eppf.descriptors._cvfh_fast import pcl_region_growing

    up = np.tile(np.float32([0, 0, 1]), (3, 1))

    def grow(lists, normals, min_points=1, eps=0.1):
        nbr = np.concatenate([np.asarray(x, dtype=np.int32) for x in lists])
        off = np.r_[0, np.cumsum([len(x) for x in lists])].astype(np.int64)
        labels = np.empty(len(lists), dtype=np.int64)
        m = pcl_region_growing(nbr, off, np.ascontiguousarray(normals, dtype=np.float32), eps, min_points, labels)
        return m, labels.tolist()

    # the search returns the query first: 0 -> 1 -> 2 all join
    assert grow([[0, 1], [1, 0, 2], [2, 1]], up) == (1, [0, 0, 0])
    # point 0's search returns 1 first, which PCL skips; 1 is then a region of its own
    assert grow([[1, 0], [1, 0], [2]], up[:3]) == (3, [0, 1, 2])
    # min_points drops the singletons
    assert grow([[1, 0], [1, 0], [2]], up, min_points=2) == (0, [-1, -1, -1])
    # normals further apart than eps do not join; NaN normals join nothing
    tilted = up.copy()
    tilted[1] = [0, np.sin(0.2), np.cos(0.2)]
    assert grow([[0, 1], [1, 0, 2], [2, 1]], tilted) == (3, [0, 1, 2])
    nan = up.copy()
    nan[2] = np.nan
    assert grow([[0, 1, 2], [1, 0], [2, 0]], nan) == (2, [0, 0, 1])
    with pytest.raises(ValueError, match="out of range"):
        grow([[0, 5], [1], [2]], up)


def test_flann_radius_lists():
    from eppf.descriptors._cvfh_fast import radius_neighbors_flann

    rng = np.random.default_rng(4)
    p = rng.uniform(size=(300, 3)).astype(np.float32)
    nbr, off = radius_neighbors_flann(p, 0.1)
    d = p[:, None, :] - p[None, :, :]
    d2 = (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]
    for i in range(len(p)):
        assert sorted(nbr[off[i] : off[i + 1]].tolist()) == np.flatnonzero(d2[i] < np.float32(0.01)).tolist()
    # 15 points or fewer are one leaf: the order is the point order
    small, small_off = radius_neighbors_flann(p[:15], 10.0)
    assert_array_equal(small.reshape(15, 15), np.tile(np.arange(15), (15, 1)))
    assert_array_equal(small_off, 15 * np.arange(16))


def test_pcl_region_growing_on_two_planes():
    pts, nrm, ia, ib = _two_planes()
    comp, _, _ = _cvfh_regions(pts, nrm, **PARAMS)
    pcl, cents, refs = _cvfh_regions(pts, nrm, region_growing="pcl", **PARAMS)
    assert len(pcl) == 2
    for a, b in zip(pcl, comp):
        # PCL's skipped neighbours can only shrink a region
        assert set(a.tolist()) <= set(b.tolist()) and len(a) >= 0.95 * len(b)
    assert_allclose(refs[1], [0.0, -np.sin(PHI), np.cos(PHI)], atol=1e-6)
    # the same seed-by-seed growth in Python over the same neighbour lists
    from eppf.descriptors._cvfh import _radius_normals
    from eppf.descriptors._cvfh_fast import radius_neighbors_flann

    p32 = pts.astype(np.float32)
    rn = _radius_normals(p32.astype(np.float64), 0.015).astype(np.float32)
    nbr, off = radius_neighbors_flann(p32, float(np.float32(0.015)))
    eps = float(np.float32(0.125))
    done, regions = np.zeros(len(pts), bool), []
    for i in range(len(pts)):
        if done[i]:
            continue
        done[i] = True
        queue = [i]
        for s in queue:
            for j in nbr[off[s] + 1 : off[s + 1]]:
                dot = float(np.float32(rn[s, 0] * rn[j, 0] + rn[s, 1] * rn[j, 1]) + np.float32(rn[s, 2] * rn[j, 2]))
                if not done[j] and np.arccos(dot) < eps:
                    done[j] = True
                    queue.append(j)
        if len(queue) >= 50:
            regions.append(sorted(queue))
    assert [r.tolist() for r in pcl] == regions


def test_pipeline_clone_and_tags(shapes):
    from sklearn.base import clone
    from sklearn.model_selection import GridSearchCV
    from sklearn.pipeline import make_pipeline

    from eppf import KLNearestNeighbors

    X, y = shapes
    est = CVFHTransformer(aggregate="mean")
    assert clone(est).get_params() == est.get_params()
    tags = est.__sklearn_tags__()
    assert tags.input_tags.three_d_array and not tags.input_tags.two_d_array
    pipe = make_pipeline(CVFHTransformer(), KLNearestNeighbors())
    search = GridSearchCV(pipe, {"cvfhtransformer__region_growing": ["components", "pcl"]}, cv=2).fit(X, y)
    assert search.best_params_["cvfhtransformer__region_growing"] in ("components", "pcl")


def test_radii_too_large_for_memory(monkeypatch):
    monkeypatch.setattr(cvfh_module, "MAX_PAIRS", 1000)
    cloud = _cloud(200)
    est = CVFHTransformer(radius_normals=10.0, cluster_tolerance=10.0, curvature_threshold=1.0).fit([cloud])
    with pytest.raises(ValueError, match=r"CVFHTransformer: point cloud 0: radius_normals and cluster_tolerance "
                                         r"give 19900 neighbour pairs, more than 1000"):
        est.transform([cloud])
