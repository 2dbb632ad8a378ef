"""Randomized-Hough normals (``estimate_normals(method="hough")``) against
analytic surfaces, a slow pure-Python reference of the same algorithm, and
PCA where the two must differ (sharp edges, outliers)."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from eppf.preprocessing import estimate_normals
from eppf.preprocessing import _hough
from eppf.preprocessing._hough import estimate_normals_hough, triplets_for
from eppf.preprocessing._hough_fast import ring_layout
from eppf.preprocessing._normals import estimate_normals_batch
from eppf.utils import object_seeds

M64 = (1 << 64) - 1


def _angles_deg(a, b):
    """Angle between unoriented axes, in degrees."""
    return np.degrees(np.arccos(np.clip(np.abs(np.sum(a * b, axis=1)), 0.0, 1.0)))


def _tilted_plane(n=400, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1, 1, (n, 2))
    pts = np.column_stack([xy, 0.3 * xy[:, 0] - 0.2 * xy[:, 1] + 0.5])
    normal = np.array([-0.3, 0.2, 1.0]) / np.linalg.norm([-0.3, 0.2, 1.0])
    return pts, normal


def _sphere(n=1500, seed=1):
    s = np.random.default_rng(seed).normal(size=(n, 3))
    return s / np.linalg.norm(s, axis=1, keepdims=True)


def _edge(m=1200, seed=2):
    """Two unit faces of a cube meeting at the edge x = z = 0."""
    rng = np.random.default_rng(seed)
    a = np.column_stack([rng.uniform(0, 1, m), rng.uniform(0, 1, m), np.zeros(m)])
    b = np.column_stack([np.zeros(m), rng.uniform(0, 1, m), rng.uniform(0, 1, m)])
    return np.vstack([a, b])


# --- a slow reference of the same algorithm, written from its description ---

def _splitmix(state):
    state = (state + 0x9E3779B97F4A7C15) & M64
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M64
    return state, z ^ (z >> 31)


class _Rng:
    def __init__(self, seed, local):
        s = (seed ^ ((local * 0xD1B54A32D192ED03) & M64)) & M64
        _, self.s = _splitmix(s)

    def next(self):
        self.s, z = _splitmix(self.s)
        return z

    def below(self, n):
        return ((self.next() >> 32) * n) >> 32

    def rotation(self):
        u1 = (self.next() >> 11) * (1.0 / 9007199254740992.0)
        u2 = (self.next() >> 11) * (2.0 * math.pi / 9007199254740992.0)
        u3 = (self.next() >> 11) * (2.0 * math.pi / 9007199254740992.0)
        a, b = math.sqrt(1.0 - u1), math.sqrt(u1)
        w, x, y, z = a * math.sin(u2), a * math.cos(u2), b * math.sin(u3), b * math.cos(u3)
        return np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ])


def _ref_rings(n_phi):
    """Bins per ring: ring 0 a polar cap of half a step, then rings of one
    polar step, the last one clipped at the equator; about one bin per
    step^2 of area."""
    d = math.pi / n_phi
    rings = []
    j = 0
    while True:
        lo = 0.0 if j == 0 else (j - 0.5) * d
        if lo >= math.pi / 2 - 1e-12:
            return d, rings
        hi = min(0.5 * d if j == 0 else (j + 0.5) * d, math.pi / 2)
        rings.append(max(1, int(math.floor(2 * math.pi * (math.cos(lo) - math.cos(hi)) / (d * d) + 0.5))))
        j += 1


def _ref_bin(u, d, rings):
    """(bin id, centre) of a unit vector with u_z >= 0, by its polar angle."""
    last = len(rings) - 1
    j = min(int(math.floor(math.acos(min(u[2], 1.0)) / d + 0.5)), last)
    span = math.pi if j == last else 2 * math.pi
    th = math.atan2(u[1], u[0]) % (2 * math.pi)
    th = th - span if th >= span else th
    b = min(max(int(th / span * rings[j]), 0), rings[j] - 1)
    phic = math.pi / 2 if j == last else j * d
    thc = (b + 0.5) * span / rings[j]
    centre = np.array([math.sin(phic) * math.cos(thc), math.sin(phic) * math.sin(thc), math.cos(phic)])
    return (j, b), centre


def _ref_pass(nb_pts, rng, rot, T, d, rings):
    k = len(nb_pts)
    counts, sums, order = {}, {}, []
    i1 = i2 = None
    votes = 0
    for _ in range(T):
        a0 = rng.below(k)
        a1 = rng.below(k)
        tries = 0
        while a1 == a0 and tries < 64:
            a1, tries = rng.below(k), tries + 1
        a2 = rng.below(k)
        tries = 0
        while (a2 == a0 or a2 == a1) and tries < 64:
            a2, tries = rng.below(k), tries + 1
        e1, e2 = nb_pts[a1] - nb_pts[a0], nb_pts[a2] - nb_pts[a0]
        n = np.cross(e1, e2)
        if not (n @ n > 1e-20 * (e1 @ e1) * (e2 @ e2)) or not (n @ n > 0):
            continue
        n = n / math.sqrt(n @ n)
        u = rot @ n
        s = 1.0
        if u[2] < 0:
            u, s = -u, -1.0
        key, centre = _ref_bin(u, d, rings)
        if u @ centre < 0:
            s = -s
        counts[key] = counts.get(key, 0) + 1
        sums[key] = sums.get(key, np.zeros(3)) + s * n
        votes += 1
        if key == i1:
            pass
        elif i1 is None or counts[key] > counts[i1]:
            i2, i1 = i1, key
        elif i2 is None or (key != i2 and counts[key] > counts[i2]):
            i2 = key
        lead = counts[i1] - (counts[i2] if i2 is not None else 0)
        if lead * lead > 4 * votes:
            break
    if votes == 0:
        return None, 0.0
    v = sums[i1]
    return v / np.linalg.norm(v), counts[i1] / votes


def _ref_point(nb_pts, seed, local, T, n_phi, n_rot, angle):
    rng = _Rng(seed, local)
    d, rings = _ref_rings(n_phi)
    res = []
    for _ in range(max(n_rot, 1)):
        rot = rng.rotation() if n_rot > 0 else np.eye(3)
        res.append(_ref_pass(nb_pts, rng, rot, T, d, rings))
    res = [(n, c) for n, c in res if n is not None]
    best, best_c = None, -1.0
    left = sorted(range(len(res)), key=lambda i: -res[i][1])  # stable: ties keep pass order
    used = set()
    for i in left:
        if i in used:
            continue
        used.add(i)
        s, sc = res[i][1] * res[i][0], res[i][1]
        for j in range(len(res)):
            if j in used:
                continue
            dot = res[i][0] @ res[j][0]
            if abs(dot) > math.cos(angle):
                used.add(j)
                s = s + math.copysign(1.0, dot) * res[j][1] * res[j][0]
                sc += res[j][1]
        if sc > best_c:
            best, best_c = s / np.linalg.norm(s), sc
    return best


def test_matches_slow_reference():
    rng = np.random.default_rng(5)
    # A bent sheet with noise: votes spread over several bins, so early
    # stopping, leader tracking and grouping all matter.
    xy = rng.uniform(-1, 1, (60, 2))
    pts = np.column_stack([xy, np.abs(xy[:, 0]) + 0.05 * rng.normal(size=60)])
    k, T, n_phi, n_rot, angle = 9, 40, 11, 3, 0.79
    got = estimate_normals_hough(pts, k, n_triplets=T, n_phi=n_phi, n_rotations=n_rot,
                                 cluster_angle=angle, orientation=None, random_state=3)
    seed = int(object_seeds(3, 1)[0])
    _, idx = cKDTree(pts).query(pts, k=k)
    ref = np.array([_ref_point(pts[idx[i]], seed, i, T, n_phi, n_rot, angle) for i in range(len(pts))])
    np.testing.assert_allclose(np.abs(np.sum(got * ref, axis=1)), 1.0, atol=1e-12)
    # No rotation: one unrotated accumulator.
    got0 = estimate_normals_hough(pts, k, n_triplets=T, n_phi=n_phi, n_rotations=0,
                                  orientation=None, random_state=3)
    ref0 = np.array([_ref_point(pts[idx[i]], seed, i, T, n_phi, 0, angle) for i in range(len(pts))])
    np.testing.assert_allclose(np.abs(np.sum(got0 * ref0, axis=1)), 1.0, atol=1e-12)


@pytest.mark.parametrize("n_phi", [2, 7, 15, 16, 40])
def test_accumulator_bins_have_about_equal_area(n_phi):
    starts, bins, ring_z, edges, centres = ring_layout(n_phi)
    d = math.pi / n_phi
    _, ref_bins = _ref_rings(n_phi)
    assert list(bins) == ref_bins
    assert starts[0] == 0 and np.all(np.diff(starts) == bins[:-1])
    lower = np.concatenate([[0.0], (np.arange(1, len(bins)) - 0.5) * d])
    upper = np.minimum(np.concatenate([[0.5 * d], (np.arange(1, len(bins)) + 0.5) * d]), math.pi / 2)
    area = 2 * math.pi * (np.cos(lower) - np.cos(upper))
    assert math.isclose(area.sum(), 2 * math.pi)  # the half sphere, exactly covered
    if n_phi >= 7:
        assert np.all((area / bins > 0.7 * d * d) & (area / bins < 1.3 * d * d))
    np.testing.assert_allclose(ring_z, np.cos(upper))
    np.testing.assert_allclose(np.linalg.norm(centres, axis=1), 1.0)
    assert centres.shape == (bins.sum(), 3) and np.all(centres[:, 2] >= -1e-15)
    # Azimuth boundaries: increasing within each ring (equal steps of azimuth
    # through an increasing pseudo angle), half the circle on the last ring.
    for j, (s, m) in enumerate(zip(starts, bins)):
        e = edges[s:s + m - 1]
        assert np.all(np.diff(e) > 0) and np.all((e > 0) & (e < (2 if j == len(bins) - 1 else 4)))


def test_plane_is_exact():
    pts, normal = _tilted_plane()
    n = estimate_normals(pts, 20, method="hough", orientation=[0, 0, 10])
    np.testing.assert_allclose(n, np.tile(normal, (len(pts), 1)), atol=1e-10)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)


def test_sphere_radial_small_error_and_outward():
    s = _sphere()
    n = estimate_normals(s, 20, method="hough")
    err = _angles_deg(n, s)
    assert err.mean() < 3.0 and err.max() < 12.0
    assert np.all(np.sum(n * s, axis=1) > 0)  # "centroid": outwards


def test_sharp_edge_gets_a_face_normal_not_the_blend():
    pts = _edge()
    near = ((pts[:, 2] == 0) & (pts[:, 0] < 0.05)) | ((pts[:, 0] == 0) & (pts[:, 2] < 0.05))
    assert near.sum() > 80
    h = estimate_normals(pts, 30, method="hough", orientation=None)[near]
    p = estimate_normals(pts, 30, orientation=None)[near]
    face_h = np.maximum(np.abs(h[:, 0]), np.abs(h[:, 2]))
    face_p = np.maximum(np.abs(p[:, 0]), np.abs(p[:, 2]))
    # Hough: every point next to the edge gets one of the two face normals.
    assert np.all(face_h > 0.999)
    own = np.where(pts[near][:, 2] == 0, np.abs(h[:, 2]), np.abs(h[:, 0]))
    assert np.mean(own > 0.999) > 0.75
    # PCA: most of them get a blend of the two.
    assert np.mean(face_p < 0.99) > 0.4


def test_outliers_barely_move_hough_normals():
    pts, normal = _tilted_plane(600, seed=3)
    rng = np.random.default_rng(4)
    noisy = np.vstack([pts, rng.uniform(pts.min(0), pts.max(0), (60, 3))])
    h = estimate_normals(noisy, 20, method="hough")[: len(pts)]
    p = estimate_normals(noisy, 20)[: len(pts)]
    eh, ep = _angles_deg(h, normal[None, :]), _angles_deg(p, normal[None, :])
    assert np.median(eh) < 1e-6
    assert np.mean(eh > 5) < 0.5 * np.mean(ep > 5)
    assert np.mean(ep > 5) > 0.1


def test_deterministic_and_seeded():
    s = _sphere(150)
    a = estimate_normals(s, 15, method="hough", random_state=7)
    b = estimate_normals(s, 15, method="hough", random_state=7)
    c = estimate_normals(s, 15, method="hough", random_state=8)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.array_equal(estimate_normals(s, 15, method="hough"),
                          estimate_normals(s, 15, method="hough", random_state=0))


def test_bit_identical_for_any_thread_count_chunking_and_batch(monkeypatch):
    clouds = [_sphere(150, seed=10), _edge(100, seed=11), _tilted_plane(100, seed=12)[0], _sphere(2, seed=1)]
    pts = np.concatenate(clouds)
    off = np.concatenate([[0], np.cumsum([len(c) for c in clouds])]).astype(np.int64)
    ref = estimate_normals_batch(pts, off, 16, method="hough", random_state=5, n_jobs=1)
    for n_jobs in (2, 3):
        assert np.array_equal(ref, estimate_normals_batch(pts, off, 16, method="hough", random_state=5, n_jobs=n_jobs))
    monkeypatch.setattr(_hough, "_MAX_NEIGHBOR_ENTRIES", 100)
    assert np.array_equal(ref, estimate_normals_batch(pts, off, 16, method="hough", random_state=5, n_jobs=2))
    # Object i is seeded by the i-th seed: given explicitly, per object, the
    # same normals come back, for the whole batch or for one object alone.
    seeds = object_seeds(5, len(clouds))
    assert np.array_equal(ref, estimate_normals_batch(pts, off, 16, method="hough", random_state=seeds))
    alone = estimate_normals_batch(clouds[1], np.array([0, len(clouds[1])]), 16, method="hough",
                                   random_state=seeds[1:2])
    assert np.array_equal(alone, ref[off[1]:off[2]])
    with pytest.raises(ValueError, match="uint64 array of shape"):
        estimate_normals_batch(pts, off, 16, method="hough", random_state=seeds[:2])
    one = estimate_normals(clouds[1], 16, method="hough", random_state=None)  # runs unseeded too
    assert one.shape == (len(clouds[1]), 3)
    assert np.allclose(np.linalg.norm(ref, axis=1), 1.0)


def test_pca_path_unchanged():
    s = _sphere(500)
    assert np.array_equal(estimate_normals(s, 12), estimate_normals(s, 12, method="pca"))
    off = np.array([0, 200, 500])
    assert np.array_equal(estimate_normals_batch(s, off, 12), estimate_normals_batch(s, off, 12, method="pca"))


def test_degenerate_neighbourhoods_and_duplicates():
    pts, normal = _tilted_plane(150, seed=6)
    doubled = np.vstack([pts, pts])  # every point twice: duplicate triplets do not vote
    n = estimate_normals(doubled, 12, method="hough", orientation=[0, 0, 10])
    np.testing.assert_allclose(n, np.tile(normal, (len(doubled), 1)), atol=1e-10)
    line = np.column_stack([np.arange(20.0), 2 * np.arange(20.0), np.zeros(20)])
    n = estimate_normals(line, 5, method="hough")
    assert np.all(np.isfinite(n))
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    np.testing.assert_allclose(n @ np.array([1.0, 2.0, 0.0]), 0.0, atol=1e-12)
    # k above the cloud's size is clipped, as for PCA.
    small = _sphere(30)
    assert np.array_equal(estimate_normals(small, 500, method="hough"), estimate_normals(small, 30, method="hough"))


@pytest.mark.parametrize("exponent", [-1000, -30, 7, 1000])
def test_power_of_two_scaling_is_exact(exponent):
    # Far beyond where cross products of raw coordinates would overflow or
    # underflow (|p| ~ 2**1000 or 2**-1000).
    pts = _edge(200, seed=9)
    ref = estimate_normals(pts, 12, method="hough")
    assert np.array_equal(estimate_normals(np.ldexp(pts, exponent), 12, method="hough"), ref)


def test_auto_triplets_bound():
    # ceil(ln(2 / 0.05) / (2 * 0.05^2)) = ceil(3.6889 / 0.005) = 738
    assert triplets_for(0.05, 0.95) == 738
    assert triplets_for(0.1, 0.9) == math.ceil(math.log(20) / 0.02)
    s = _sphere(100)
    a = estimate_normals(s, 10, method="hough", method_params={"n_triplets": "auto"})
    b = estimate_normals(s, 10, method="hough", method_params={"n_triplets": 738})
    assert np.array_equal(a, b)


@pytest.mark.parametrize(
    "points, kwargs, error, msg",
    [
        (np.array([[0.0, 0, 0], [1, 0, 0], [np.nan, 0, 1]]), {}, ValueError, "NaN"),
        (np.zeros((2, 3)), {}, ValueError, "estimate_normals"),
        (np.ones((10, 3)), {}, ValueError, "estimate_normals"),
        (np.eye(3), {"n_neighbors": 2}, ValueError, "n_neighbors"),
        (np.eye(3), {"method": "ransac"}, ValueError, "method must be"),
        (np.eye(3), {"method": "pca", "method_params": {"n_phi": 3}}, ValueError, "hough"),
        (np.eye(3), {"method_params": {"n_phi": 1}, "method": "hough"}, ValueError, "n_phi"),
        (np.eye(3), {"method_params": {"nphi": 9}, "method": "hough"}, ValueError, "unknown"),
        (np.eye(3), {"method_params": {"n_triplets": True}, "method": "hough"}, TypeError, "n_triplets"),
        (np.eye(3), {"method_params": {"n_triplets": "many"}, "method": "hough"}, ValueError, "auto"),
        (np.eye(3), {"method_params": {"cluster_angle": float("nan")}, "method": "hough"}, ValueError, "cluster_angle"),
        (np.eye(3), {"method_params": {"n_triplets": "auto", "tolerance": 1e-6}, "method": "hough"}, ValueError, "triplets"),
        (np.eye(3), {"method_params": [1], "method": "hough"}, TypeError, "dict"),
        (np.eye(3), {"method": "hough", "random_state": "x"}, TypeError, "random_state"),
        (np.eye(3), {"method": "hough", "orientation": "up"}, ValueError, "orientation"),
    ],
)
def test_errors(points, kwargs, error, msg):
    with pytest.raises(error, match=msg):
        estimate_normals(points, **kwargs)


def test_batch_errors_name_the_owner():
    with pytest.raises(ValueError, match="MyDescriptor"):
        estimate_normals_batch(np.eye(3), np.array([0, 3]), 3, owner="MyDescriptor", method="hogh")
