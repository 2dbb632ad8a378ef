"""Tests of GRSDTransformer: hand-built RSD classes, a planar patch, a slow
NumPy model of PCL's pipeline (FLANN tree order included), layout, rotation
behaviour, determinism, thread/chunk bit-identity and bad input."""

import re
import doctest

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import eppf.utils._chunks
import eppf.descriptors._grsd as grsd_module
from eppf.datasets import make_shapes
from eppf.descriptors._grsd import CLASSES, THRESHOLDS, GRSDTransformer
from eppf.descriptors._grsd_fast import grsd_voxels

f32 = np.float32
THR = np.asarray(THRESHOLDS, dtype=np.float64)
NOISE, PLANE, CYLINDER, SPHERE, EDGE, EMPTY = range(6)
PAIRS = [(i, j) for i in range(6) for j in range(i, 6)]


def _bin(a, b):
    return PAIRS.index((min(a, b), max(a, b)))


# ----------------------------------------------------------- slow model
class _FlannTree:
    """FLANN 1.9's single k-d tree (middle split, leaf size 15), recursively."""

    def __init__(self, p):
        self.p = p
        self.vind = list(range(len(p)))
        self.nodes = []
        self.root = self._divide(0, len(p), p.min(0).copy(), p.max(0).copy())

    def _minmax(self, lo, hi, d):
        v = self.p[self.vind[lo:hi], d]
        return v.min(), v.max()

    def _divide(self, lo, hi, blo, bhi):
        nid = len(self.nodes)
        self.nodes.append(None)
        if hi - lo <= 15:
            v = self.p[self.vind[lo:hi]]
            blo[:], bhi[:] = v.min(0), v.max(0)
            self.nodes[nid] = ("leaf", lo, hi)
            return nid
        spans = [f32(bhi[i] - blo[i]) for i in range(3)]
        cut = int(np.argmax(spans))  # first maximum, as the strict '>' scan
        mn, mx = self._minmax(lo, hi, cut)
        cutval, best = f32(f32(mn + mx) / f32(2)), f32(mx - mn)
        first = cut
        for i in range(3):
            if i != first and spans[i] > best:
                mn, mx = self._minmax(lo, hi, i)
                if f32(mx - mn) > best:
                    best, cut, cutval = f32(mx - mn), i, f32(f32(mn + mx) / f32(2))
        ind, P, count = self.vind, self.p, hi - lo
        a, b = 0, count - 1
        for strict in (True, False):
            if not strict:
                b = count - 1
            while True:
                if strict:
                    while a <= b and P[ind[lo + a], cut] < cutval:
                        a += 1
                    while a <= b and P[ind[lo + b], cut] >= cutval:
                        b -= 1
                else:
                    while a <= b and P[ind[lo + a], cut] <= cutval:
                        a += 1
                    while a <= b and P[ind[lo + b], cut] > cutval:
                        b -= 1
                if a > b:
                    break
                ind[lo + a], ind[lo + b] = ind[lo + b], ind[lo + a]
                a, b = a + 1, b - 1
            if strict:
                lim1 = a
        lim2 = a
        idx = lim1 if lim1 > count // 2 else (lim2 if lim2 < count // 2 else count // 2)
        llo, lhi = blo.copy(), bhi.copy()
        lhi[cut] = cutval
        c1 = self._divide(lo, lo + idx, llo, lhi)
        rlo, rhi = blo.copy(), bhi.copy()
        rlo[cut] = cutval
        c2 = self._divide(lo + idx, hi, rlo, rhi)
        self.nodes[nid] = ("inner", cut, lhi[cut], rlo[cut], c1, c2)
        blo[:], bhi[:] = np.minimum(llo, rlo), np.maximum(lhi, rhi)
        return nid

    def radius(self, q, r2):
        """All points with single-precision squared distance < r2, depth-first."""
        out = []

        def visit(nid):
            node = self.nodes[nid]
            if node[0] == "leaf":
                idx = np.asarray(self.vind[node[1] : node[2]])
                d = q[None, :] - self.p[idx]
                d2 = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]
                out.extend((int(i), v) for i, v in zip(idx, d2) if v < r2)
                return
            _, cut, dlo, dhi, c1, c2 = node
            first = c1 if f32(f32(q[cut] - dlo) + f32(q[cut] - dhi)) < 0 else c2
            visit(first)
            visit(c2 if first == c1 else c1)

        visit(self.root)
        return out


def _rsd_class(n32, hits, w, nsub=5, plane=0.2):
    if len(hits) < 2:
        rmin = rmax = f32(0)
    else:
        lo = [np.inf] * nsub
        hi = [-np.inf] * nsub
        lo[0] = hi[0] = 0.0
        ref = n32[hits[0][0]]
        for i, d2 in hits[1:]:
            c = float(f32(f32(n32[i, 0] * ref[0]) + f32(n32[i, 1] * ref[1])) + f32(n32[i, 2] * ref[2]))
            a = np.arccos(min(max(c, -1.0), 1.0))
            a = np.pi - a if a > np.pi / 2 else a
            b = min(int(np.floor(nsub * np.sqrt(float(d2)) / w)), nsub - 1)
            lo[b], hi[b] = min(lo[b], a), max(hi[b], a)
        used = [b for b in range(nsub) if hi[b] >= 0]
        f = {b: (b + 0.5) * w / nsub for b in used}
        aa, ad = sum(lo[b] ** 2 for b in used), sum(lo[b] * f[b] for b in used)
        bb, bd = sum(hi[b] ** 2 for b in used), sum(hi[b] * f[b] for b in used)
        rmin = f32(plane if aa == 0 else min(ad / aa, plane)) * f32(1.1)
        rmax = f32(plane if bb == 0 else min(bd / bb, plane)) * f32(0.9)
        rmin, rmax = (rmin, rmax) if rmin < rmax else (rmax, rmin)
    if rmin > THR[0]:
        return PLANE
    if rmax > THR[2]:
        return CYLINDER
    if rmin < THR[1]:
        return NOISE
    return SPHERE if f32(rmax - rmin) < THR[3] else EDGE


def _slow_grsd(p32, n32, w):
    """(classes per voxel in key order, 21 counts) of PCL's pipeline in NumPy."""
    inv = f32(1) / f32(w)
    cells = np.floor(p32 * inv).astype(np.int64)
    cells -= np.floor(p32.min(0) * inv).astype(np.int64)
    dims = cells.max(0) + 1
    keys = cells[:, 0] + dims[0] * (cells[:, 1] + dims[1] * cells[:, 2])
    uk, owner = np.unique(keys, return_inverse=True)
    cent = np.zeros((len(uk), 3), dtype=f32)
    for i in range(len(p32)):  # single-precision sums in point order
        cent[owner[i]] += p32[i]
    cent /= np.bincount(owner).astype(f32)[:, None]
    tree = _FlannTree(p32)
    types = np.array([_rsd_class(n32, tree.radius(c, f32(w * w)), w) for c in cent])
    lookup = dict(zip(uk.tolist(), types.tolist()))
    T = np.zeros((6, 6), dtype=np.int64)
    for key, t in zip(uk, types):
        c = np.array([key % dims[0], (key // dims[0]) % dims[1], key // (dims[0] * dims[1])])
        for off in np.ndindex(3, 3, 3):
            q = c + np.asarray(off) - 1
            if not np.any(q != c):
                continue
            inside = np.all(q >= 0) and np.all(q < dims)
            T[t, lookup.get(int(q[0] + dims[0] * (q[1] + dims[1] * q[2])), EMPTY) if inside else EMPTY] += 1
    return types, np.array([T[i, j] + T[j, i] for i, j in PAIRS], dtype=np.float64)


# ----------------------------------------------------------- hand-built cases
def _star(tilts, d=0.015, w=0.05):
    """A point at a voxel's centre (normal +z, the reference: a single k-d
    leaf returns points in index order) and four at distance d along +-x and
    +-y whose normals lean outwards by the given angles (x pair, y pair)."""
    c = np.full(3, 0.5 * w)
    pts, nrm = [c], [np.array([0.0, 0.0, 1.0])]
    for axis, tilt in ((0, tilts[0]), (0, tilts[0]), (1, tilts[1]), (1, tilts[1])):
        sign = 1.0 if len(pts) % 2 else -1.0
        e = np.zeros(3)
        e[axis] = sign
        pts.append(c + d * e)
        nrm.append(np.sin(tilt) * e + np.cos(tilt) * np.array([0.0, 0.0, 1.0]))
    return np.asarray(pts, dtype=f32), np.asarray(nrm, dtype=f32)


# Distance bin floor(5 * 0.015 / 0.05) = 1, centre f = 0.015. One angle a in
# the bin: both fitted radii are f / a, times 1.1 and 0.9.
@pytest.mark.parametrize(
    "tilts, expected",
    [
        ((0.0, 0.0), PLANE),  # no angle: both radii 0.2 -> 0.18, 0.22; 0.18 > 0.1
        ((0.15, 0.15), SPHERE),  # f/a = 0.1: r = 0.09, 0.11; diff 0.02 < 0.05
        ((0.0, 0.15), CYLINDER),  # min line 0 -> 0.22 > 0.175; max line 0.09
        ((0.1, 0.3), EDGE),  # 0.15 * 1.1 = 0.165 <= 0.175, 0.05 * 0.9 = 0.045; diff 0.12
        ((1.2, 1.2), NOISE),  # f/a = 0.0125: r_min = 0.01125 < 0.015
    ],
)
def test_hand_built_rsd_classes(tilts, expected):
    p, n = _star(tilts)
    cells, cent, types, counts = grsd_voxels(p, n, 0.05, 5, 0.2, THR)
    assert_array_equal(cells, [[0, 0, 0]])
    assert_array_equal(types, [expected])
    # one voxel: its 26 neighbour cells are empty
    want = np.zeros(21)
    want[_bin(expected, EMPTY)] = 26
    assert_array_equal(counts, want)


def test_single_neighbour_is_noise():
    p = np.array([[0.01, 0.01, 0.01], [0.2, 0.2, 0.2], [0.21, 0.2, 0.2]], dtype=f32)
    n = np.tile(f32([0, 0, 1]), (3, 1))
    _, _, types, counts = grsd_voxels(p, n, 0.05, 5, 0.2, THR)
    # voxel of the lone point: one neighbour (itself) -> r = 0 -> noise;
    # the pair's voxel: two equal normals -> plane
    assert_array_equal(types, [NOISE, PLANE])
    assert counts[_bin(NOISE, EMPTY)] == 26 and counts[_bin(PLANE, EMPTY)] == 26


def test_planar_patch_counts():
    # 30 x 30 points 0.01 apart on a plane, unit normals along z: a 6 x 6
    # layer of plane voxels (points stay 0.005 away from the cell faces).
    g = 0.005 + 0.01 * np.arange(30)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    cloud = np.column_stack([xy, np.full(len(xy), 0.3), np.zeros((len(xy), 2)), np.ones(len(xy))])
    est = GRSDTransformer(scaling="none", normalize=False).fit([cloud])
    row = est.transform([cloud])[0]
    # ordered pairs of 8-connected cells in a 6 x 6 square
    pairs = 2 * (5 * 6 + 6 * 5 + 2 * 5 * 5)
    want = np.zeros(21)
    want[_bin(PLANE, PLANE)] = 2 * pairs
    want[_bin(PLANE, EMPTY)] = 26 * 36 - pairs
    assert_array_equal(row, want)
    norm = GRSDTransformer(scaling="none").fit_transform([cloud])[0]
    assert_array_equal(norm, want / want.sum())


def test_sphere_and_cylinder_classes():
    # PCL's RSD measures distances from the voxel mean but angles against the
    # first neighbour found: on a sampled sphere of radius 0.12 most voxels
    # come out "cylinder" (the off-centre reference puts near-zero angles at
    # non-zero distance); a cylinder of radius 0.06 is "cylinder" everywhere.
    i = np.arange(5000) + 0.5
    phi, th = np.arccos(1 - 2 * i / 5000), np.pi * (1 + 5**0.5) * i
    u = np.c_[np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)]
    _, _, types, _ = grsd_voxels((0.12 * u).astype(f32), u.astype(f32), 0.05, 5, 0.2, THR)
    assert set(np.unique(types)) <= {CYLINDER, EDGE}
    assert np.mean(types == CYLINDER) > 0.8
    T, Z = np.meshgrid(np.linspace(0, 2 * np.pi, 60, endpoint=False), np.linspace(-0.3, 0.3, 100))
    nrm = np.c_[np.cos(T.ravel()), np.sin(T.ravel()), np.zeros(T.size)]
    pts = np.c_[0.06 * nrm[:, :2], Z.ravel()]
    _, _, types, _ = grsd_voxels(pts.astype(f32), nrm.astype(f32), 0.05, 5, 0.2, THR)
    assert np.mean(types == CYLINDER) > 0.95


@pytest.mark.parametrize("seed, n", [(0, 40), (1, 150), (2, 400)])
def test_kernel_matches_slow_model(seed, n):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3)) * [0.2, 0.1, 0.05]
    p[: n // 4] = p[0] + 0.002 * rng.normal(size=(n // 4, 3))  # a dense clump: deep tree
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    p32, n32 = p.astype(f32), nrm.astype(f32)
    _, _, types, counts = grsd_voxels(p32, n32, 0.05, 5, 0.2, THR)
    slow_types, slow_counts = _slow_grsd(p32, n32, 0.05)
    assert_array_equal(types, slow_types)
    assert_array_equal(counts, slow_counts)



@pytest.mark.parametrize("seed, side", [(3, 3.0), (4, 40.0)])
def test_kernel_matches_slow_model_on_wide_grids(seed, side):
    # voxel keys beyond 2**16 and 2**24 (three and four radix passes of the
    # key sort), clusters meeting across rows and slabs of the grid, and
    # voxels on the grid's faces
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, side, size=(12, 3))
    p = centres[rng.integers(0, 12, size=300)] + 0.03 * rng.normal(size=(300, 3))
    p[:4] = [[0, 0, 0], [side, 0, 0], [0, side, side], [side, side, side]]
    nrm = rng.normal(size=(300, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    p32, n32 = p.astype(f32), nrm.astype(f32)
    cells, cent, types, counts = grsd_voxels(p32, n32, 0.05, 5, 0.2, THR)
    dims = cells.max(0) + 1
    keys = cells[:, 0] + dims[0] * (cells[:, 1] + dims[1] * cells[:, 2].astype(np.int64))
    assert np.all(np.diff(keys) > 0) and keys.max() >= 2**16
    slow_types, slow_counts = _slow_grsd(p32, n32, 0.05)
    assert_array_equal(types, slow_types)
    assert_array_equal(counts, slow_counts)


def test_grid_check_matches_numpy_rule():
    from eppf.descriptors._grsd_fast import grid_check

    rng = np.random.default_rng(9)
    clouds = [rng.normal(size=(n, 3)).astype(f32) for n in (1, 5, 40)]
    offsets = np.cumsum([0] + [len(c) for c in clouds]).astype(np.int64)
    P = np.vstack(clouds)
    inv = f32(1.0) / f32(0.05)
    assert grid_check(P, offsets, inv, 2.0**31 - 1, 2.0**30) == (-1, None)
    for k, c in enumerate(clouds):
        lo, hi = c.min(0), c.max(0)
        cells = np.floor(hi.astype(np.float64) * inv) - np.floor(lo.astype(np.float64) * inv) + 1
        # a cap just below this object's cell count flags it, and no earlier one
        bad, got = grid_check(P[offsets[k]:], offsets[k:] - offsets[k], inv, float(np.prod(cells)) - 1, 2.0**30)
        assert bad == 0 and got == tuple(cells)
        reach = np.abs(np.concatenate([lo, hi]).astype(np.float64)).max() * float(inv)
        assert grid_check(P[offsets[k]:], offsets[k:] - offsets[k], inv, 2.0**31, reach)[0] == 0
        assert grid_check(P[offsets[k]:offsets[k + 1]], offsets[k:k + 2] - offsets[k], inv, 2.0**31,
                          np.nextafter(reach, np.inf)) == (-1, None)
    for bad_value in (np.inf, -np.inf, np.nan):
        Q = P.copy()
        Q[offsets[2] + 7, 1] = bad_value
        assert grid_check(Q, offsets, inv, 2.0**31 - 1, 2.0**30) == (2, None)
    with pytest.raises(ValueError, match="lie within"):
        grid_check(P, offsets + 1, inv, 2.0**31 - 1, 2.0**30)
    with pytest.raises(ValueError, match="lie within"):
        grid_check(P, offsets - 1, inv, 2.0**31 - 1, 2.0**30)
    with pytest.raises(ValueError, match="at least one point"):
        grid_check(P, np.array([0, 5, 5, len(P)], dtype=np.int64), inv, 2.0**31 - 1, 2.0**30)
    with pytest.raises(ValueError, match="at least one point"):
        grid_check(P, np.array([0, 20, 5, len(P)], dtype=np.int64), inv, 2.0**31 - 1, 2.0**30)

def test_reference_neighbour_is_the_tree_order_not_the_nearest():
    # 16 points (two leaves): the query's own leaf is searched first, so the
    # reference is the first point of that leaf, not the nearest point
    rng = np.random.default_rng(5)
    p = rng.uniform(0, 0.04, size=(16, 3)).astype(f32)
    tree = _FlannTree(p)
    c = p.mean(0).astype(f32)
    hits = tree.radius(c, f32(0.0025))
    d = np.linalg.norm(p.astype(np.float64) - c, axis=1)
    assert {h[0] for h in hits} == set(np.flatnonzero(d**2 < 0.0025))
    assert hits[0][0] != int(np.argmin(d))


# ----------------------------------------------------------- interface
@pytest.fixture(scope="module")
def shapes():
    X, y = make_shapes(3, n_points=400, random_state=0, with_normals=True, return_X_y=True)
    return X, y


def _rotate(c, R):
    return np.hstack([c[:, :3] @ R.T, c[:, 3:] @ R.T])


def test_layout_sums_and_names(shapes):
    X, _ = shapes
    est = GRSDTransformer(normalize=False).fit(X)
    raw = est.transform(X)
    assert raw.shape == (len(X), 21)
    assert np.all(raw == np.round(raw)) and np.all(raw >= 0)
    assert np.all(raw[:, _bin(EMPTY, EMPTY)] == 0)
    # every occupied voxel has 26 neighbour cells; a pair of occupied voxels
    # is met from both ends, so T is symmetric: occupied bins are even, and
    # 26 V = sum(empty bins) + sum(occupied bins) - sum(diagonal bins) / 2
    occupied = [_bin(i, j) for i in range(5) for j in range(i, 5)]
    diagonal = [_bin(i, i) for i in range(5)]
    empty = [_bin(i, EMPTY) for i in range(5)]
    assert np.all(raw[:, occupied] % 2 == 0)
    for cloud, row in zip(X[:5], raw[:5]):
        c = cloud[:, :3] - cloud[:, :3].mean(0)
        c = c / np.ptp(c, axis=0).max()
        cells = grsd_voxels(c.astype(f32), np.ones_like(c, dtype=f32) / np.sqrt(f32(3)), 0.05, 5, 0.2, THR)[0]
        assert row[empty].sum() + row[occupied].sum() - row[diagonal].sum() / 2 == 26 * len(cells)
    norm = GRSDTransformer().fit_transform(X)
    np.testing.assert_allclose(norm.sum(axis=1), 1.0)
    np.testing.assert_allclose(norm, raw / raw.sum(axis=1, keepdims=True))
    names = est.get_feature_names_out()
    assert len(names) == 21 == len(set(names))
    assert names[_bin(PLANE, EMPTY)] == "grsd_plane_empty" and names[0] == f"grsd_{CLASSES[0]}_{CLASSES[0]}"


def test_rotation_behaviour(shapes):
    X, _ = shapes
    est = GRSDTransformer(normalize=False).fit(X)
    base = est.transform(X)
    empty = [_bin(i, EMPTY) for i in range(5)]
    # 90 degrees about z maps the grid onto itself: same occupied cells
    R90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    r90 = est.transform([_rotate(c, R90) for c in X])
    assert_array_equal(r90[:, empty].sum(axis=1), base[:, empty].sum(axis=1))
    # a generic rotation changes the voxelisation (and so the row)
    a = 0.4
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    gen = est.transform([_rotate(c, R) for c in X])
    assert not np.array_equal(gen, base)
    # but the descriptor stays close: rotated rows are nearer their own
    # object than the average other object (normalised L1)
    bn, gn = base / base.sum(1, keepdims=True), gen / gen.sum(1, keepdims=True)
    own = np.abs(bn - gn).sum(1)
    other = np.abs(bn[:, None] - bn[None]).sum(-1).mean(1)
    assert np.mean(own < other) > 0.8


def test_scale_and_translation_invariance(shapes):
    X, _ = shapes
    est = GRSDTransformer().fit(X)
    base = est.transform(X)
    assert_array_equal(est.transform([np.hstack([2.0 * c[:, :3], c[:, 3:]]) for c in X]), base)  # exact in binary
    assert_array_equal(est.transform([c.copy() for c in X]), base)


def test_normals_given_or_estimated(shapes):
    X, _ = shapes
    from eppf.preprocessing._normals import estimate_normals

    bare = [c[:, :3] for c in X[:4]]
    with_n = [np.hstack([c, estimate_normals(c, 10)]) for c in bare]
    a = GRSDTransformer().fit_transform(bare)
    b = GRSDTransformer().fit_transform(with_n)
    np.testing.assert_allclose(a, b)
    # normal signs do not matter (angles are folded to [0, pi/2])
    flipped = [np.hstack([c[:, :3], -c[:, 3:]]) for c in with_n]
    assert_array_equal(GRSDTransformer().fit_transform(flipped), b)


def test_deterministic_and_bit_identical_across_threads_and_chunks(shapes, monkeypatch):
    X, _ = shapes
    ref = GRSDTransformer(n_jobs=1).fit_transform(X)
    assert_array_equal(GRSDTransformer(n_jobs=1).fit_transform(X), ref)
    assert_array_equal(GRSDTransformer(n_jobs=2).fit_transform(X), ref)
    monkeypatch.setattr(eppf.utils._chunks, "CHUNK", 7)
    assert_array_equal(GRSDTransformer(n_jobs=2).fit_transform(X), ref)


def test_scaling_modes(shapes):
    X, _ = shapes
    big = [np.hstack([8.0 * c[:, :3], c[:, 3:]]) for c in X]
    fit = GRSDTransformer(scaling="fit").fit(big)
    assert fit.scale_ == pytest.approx(1.0 / max(np.ptp(c, axis=0).max() for c in big))
    obj = GRSDTransformer().fit_transform(big)
    assert_array_equal(obj, GRSDTransformer().fit_transform(X))
    # without scaling, radius and class thresholds are in the cloud's units
    assert not np.array_equal(GRSDTransformer(scaling="none").fit_transform(big), obj)


def test_doctest():
    assert doctest.testmod(grsd_module, raise_on_error=False).failed == 0


def _cloud(n=50, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3))


@pytest.mark.parametrize(
    "params, err, match",
    [
        ({"radius": 0.0}, ValueError, "radius must be a float in [1e-15, 1e+15], got 0.0"),
        ({"radius": np.nan}, ValueError, "radius"),
        ({"radius": "a"}, TypeError, "radius must be a float"),
        ({"radius": True}, TypeError, "radius must be a float"),
        ({"n_subdivisions": 0}, ValueError, "n_subdivisions must be an int in [1, 64], got 0"),
        ({"n_subdivisions": 65}, ValueError, "n_subdivisions must be an int in [1, 64], got 65"),
        ({"n_subdivisions": 2.5}, TypeError, "n_subdivisions must be an int"),
        ({"plane_radius": -1.0}, ValueError, "plane_radius"),
        ({"scaling": "unit"}, ValueError, "scaling must be"),
        ({"normalize": 1}, TypeError, "normalize must be True or False, got 1"),
        ({"n_neighbors": 2}, ValueError, "n_neighbors must be an int >= 3 (a plane needs three points), got 2"),
        ({"normal_orientation": "up"}, ValueError, "normal_orientation"),
        ({"n_jobs": 0}, ValueError, "n_jobs"),
    ],
)
def test_bad_parameters(params, err, match):
    with pytest.raises(err, match=re.escape(match)):
        GRSDTransformer(**params).fit([_cloud()])


@pytest.mark.parametrize(
    "X, err, match",
    [
        ([], ValueError, "empty"),
        ([np.full((5, 3), np.nan)], ValueError, "NaN or infinite"),
        ([np.zeros((1, 3))], ValueError, "at least 3"),
        ([np.zeros((10, 4))], ValueError, "shape"),
        ([np.hstack([_cloud(), np.zeros((50, 3))])], ValueError, "normal"),
        ([np.ones((6, 3))], ValueError, "identical"),
        ("cloud", TypeError, "list of point clouds"),
    ],
)
def test_bad_clouds(X, err, match):
    with pytest.raises(err, match=re.escape(match)):
        GRSDTransformer().fit_transform(X)


def test_bad_scale_for_the_grid():
    est = GRSDTransformer(scaling="none", radius=1e-12).fit([_cloud()])
    with pytest.raises(ValueError, match=r"GRSDTransformer: point cloud 0 spans .* voxels"):
        est.transform([_cloud()])
    huge = GRSDTransformer(scaling="none").fit([_cloud() * 1e300])
    with pytest.raises(ValueError, match="GRSDTransformer: point cloud 0 has coordinates (beyond single precision|out of the magnitude range)"):
        huge.transform([_cloud() * 1e300])


def test_not_fitted():
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        GRSDTransformer().transform([_cloud()])


def test_kernel_rejects_bad_arrays():
    from eppf.descriptors._grsd_fast import grsd_batch

    p = np.zeros((4, 3), dtype=f32)
    out = np.zeros((1, 21))
    with pytest.raises(ValueError, match="at least one point"):
        grsd_voxels(p[:0], p[:0], 0.05, 5, 0.2, THR)
    with pytest.raises(ValueError, match="shape"):
        grsd_voxels(p, p[:2], 0.05, 5, 0.2, THR)
    with pytest.raises(ValueError, match="n_subdivisions"):
        grsd_voxels(p, p, 0.05, 65, 0.2, THR)
    with pytest.raises(ValueError, match="thresholds"):
        grsd_voxels(p, p, 0.05, 5, 0.2, THR[:3])
    with pytest.raises(ValueError, match="offsets"):
        grsd_batch(p, p, np.array([0, 3], dtype=np.int64), 0.05, 5, 0.2, THR, out, 1)
    with pytest.raises(ValueError, match="at least one point"):
        grsd_batch(p, p, np.array([0, 0, 4], dtype=np.int64), 0.05, 5, 0.2, THR, np.zeros((2, 21)), 1)
    with pytest.raises(ValueError, match="out must have shape"):
        grsd_batch(p, p, np.array([0, 4], dtype=np.int64), 0.05, 5, 0.2, THR, np.zeros((1, 20)), 1)


def test_kernel_survives_non_finite_values():
    # the transformer rejects them; the kernel itself must still stay in bounds
    p = np.random.default_rng(0).normal(size=(40, 3)).astype(f32)
    p[3] = np.nan
    p[7] = np.inf
    n = np.ones_like(p) / np.sqrt(f32(3))
    _, _, types, counts = grsd_voxels(p, n, 0.05, 5, 0.2, THR)
    assert np.all((types >= 0) & (types <= 4)) and np.all(np.isfinite(counts))


def test_pipeline_clone_and_tags(shapes):
    from sklearn.base import clone
    from sklearn.model_selection import GridSearchCV
    from sklearn.pipeline import make_pipeline

    from eppf import KLNearestNeighbors

    X, y = shapes
    est = GRSDTransformer(radius=0.1)
    assert clone(est).get_params() == est.get_params()
    tags = est.__sklearn_tags__()
    assert tags.input_tags.three_d_array and not tags.input_tags.two_d_array
    pipe = make_pipeline(GRSDTransformer(), KLNearestNeighbors())
    search = GridSearchCV(pipe, {"grsdtransformer__radius": [0.05, 0.1]}, cv=2).fit(X, y)
    assert search.best_params_["grsdtransformer__radius"] in (0.05, 0.1)
