"""Region growing and pair features shared by the CVFH-family descriptors.

Used by :class:`eppf.OURCVFHTransformer` and :class:`CVFHTransformer`: the
surface variation of a point's neighbourhood (for the curvature filter), the
smooth regions grown from the points that pass it, and PCL's pair features
of a reference point (a region's centroid and mean normal) against every
point of the object. Also the parameter checks and the centring, scaling and
normal estimation that GRSD and CVFH share.
"""

import numbers

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..preprocessing._normals import estimate_normals_batch
from ..utils._validation import check_n_jobs, pack_point_clouds

__all__ = []


def _curvature(points, k):
    """Surface variation lambda_min / sum(lambda) of the k nearest neighbours."""
    n = points.shape[0]
    k = min(k, n)
    _, idx = cKDTree(points).query(points, k=k)
    nb = points[idx.reshape(n, k)]
    nb = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    ev = np.linalg.eigvalsh(cov)
    total = ev.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        curv = np.where(total > 0, ev[:, 0] / total, 0.0)
    return np.clip(curv, 0.0, None)


def _smooth_clusters(points, normals, keep, tolerance, cos_eps, min_points):
    """Components of the graph 'closer than tolerance and normals within eps'.

    This is what PCL's seeded region growing returns: a point joins a region
    when a member within ``tolerance`` has a normal less than eps away.
    Returns a list of index arrays (into ``points``), in order of their
    lowest index, with at least ``min_points`` points each.
    """
    sub = np.flatnonzero(keep)
    if sub.size == 0:
        return []
    pairs = cKDTree(points[sub]).query_pairs(tolerance, output_type="ndarray")
    if pairs.size:
        dots = np.einsum("ij,ij->i", normals[sub[pairs[:, 0]]], normals[sub[pairs[:, 1]]])
        pairs = pairs[dots > cos_eps]
    m = sub.size
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    n_comp, labels = connected_components(graph, directed=False)
    counts = np.bincount(labels, minlength=n_comp)
    # Order the components by their first member, like PCL's scan.
    first = np.full(n_comp, m, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(m))
    clusters = []
    for c in np.argsort(first, kind="stable"):
        if counts[c] >= min_points:
            clusters.append(sub[labels == c])
    return clusters


def _pair_features(c, nc, points, normals):
    """PCL's pair features (f1, f2, f3) of (c, nc) against every point.

    Source is the more parallel normal (PCL's rule): with d = p - c,
    u = source normal, v = d x u / |d x u|, w = u x v: f1 = atan2(w . n_t,
    u . n_t), f2 = v . n_t, f3 = u . d / |d|. Undefined pairs are dropped.
    """
    d = points - c
    dist = np.linalg.norm(d, axis=1)
    ok = dist > 0
    d, dist, nt_all = d[ok], dist[ok], normals[ok]
    dh = d / dist[:, None]
    a1 = dh @ nc
    a2 = np.einsum("ij,ij->i", nt_all, dh)
    swap = np.arccos(np.clip(np.abs(a1), 0, 1)) > np.arccos(np.clip(np.abs(a2), 0, 1))
    u = np.where(swap[:, None], nt_all, nc[None, :])
    nt = np.where(swap[:, None], nc[None, :], nt_all)
    dd = np.where(swap[:, None], -d, d)
    f3 = np.where(swap, -a2, a1)
    v = np.cross(dd, u)
    vn = np.linalg.norm(v, axis=1)
    good = vn > 0
    v = v[good] / vn[good, None]
    u, nt, f3 = u[good], nt[good], f3[good]
    w = np.cross(u, v)
    f1 = np.arctan2(np.einsum("ij,ij->i", w, nt), np.einsum("ij,ij->i", u, nt))
    f2 = np.einsum("ij,ij->i", v, nt)
    return f1, f2, f3


def _check_int(value, name, owner, low, high=None):
    """An int parameter in [low, high] (TypeError / ValueError naming it)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{owner}: {name} must be an int, got {type(value).__name__}")
    if value < low or (high is not None and value > high):
        bound = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{owner}: {name} must be {bound}, got {value}")
    return int(value)


def _check_real(value, name, owner, low, high):
    """A finite float parameter in [low, high] (TypeError / ValueError naming it)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{owner}: {name} must be a float, got {type(value).__name__}")
    value = float(value)
    if not (np.isfinite(value) and low <= value <= high):
        raise ValueError(f"{owner}: {name} must be finite and in [{low:g}, {high:g}], got {value}")
    return value


def _check_common(est, owner):
    """The parameters GRSD and CVFH share: scaling, normalize, normals, n_jobs."""
    if est.scaling not in ("object", "fit", "none"):
        raise ValueError(f"{owner}: scaling must be 'object', 'fit' or 'none', got {est.scaling!r}")
    if not isinstance(est.normalize, (bool, np.bool_)):
        raise TypeError(f"{owner}: normalize must be a bool, got {type(est.normalize).__name__}")
    if est.normal_orientation not in ("centroid", "origin", None):
        raise ValueError(
            f"{owner}: normal_orientation must be 'centroid', 'origin' or None, got {est.normal_orientation!r}"
        )
    n_neighbors = _check_int(est.n_neighbors, "n_neighbors", owner, 3)
    n_threads = 1 if est.n_jobs is None else check_n_jobs(est.n_jobs, owner=owner)
    return n_neighbors, n_threads


def _fit_scale(clouds, scaling):
    """1 / (largest bounding-box side of any cloud) for scaling='fit', else 1."""
    if scaling != "fit":
        return 1.0
    return 1.0 / max(float(np.ptp(c[:, :3], axis=0).max()) for c in clouds)


def _prepared(clouds, n_neighbors, orientation, scaling, scale, n_threads, owner):
    """Packed, centred and scaled points with their normals (estimated for
    clouds given without), as for OUR-CVFH: each object centred on its mean,
    then divided by its largest bounding-box side (``scaling="object"``) or
    multiplied by ``scale``. Returns ``points``, ``normals`` (N, 3) float64
    and ``offsets``."""
    points, _, offsets = pack_point_clouds([c[:, :3] for c in clouds])
    points = points.copy()
    normals = np.empty_like(points)
    missing = [k for k, c in enumerate(clouds) if c.shape[1] == 3]
    for k, c in enumerate(clouds):
        if c.shape[1] == 6:
            normals[offsets[k] : offsets[k + 1]] = c[:, 3:]
    if missing:
        sub_pts, _, sub_off = pack_point_clouds([clouds[k][:, :3] for k in missing])
        est = estimate_normals_batch(sub_pts, sub_off, n_neighbors, orientation, n_threads, owner=owner)
        for j, k in enumerate(missing):
            normals[offsets[k] : offsets[k + 1]] = est[sub_off[j] : sub_off[j + 1]]
    for k in range(len(clouds)):
        p = points[offsets[k] : offsets[k + 1]]
        p -= p.mean(axis=0)
        if scaling == "object":
            p /= np.ptp(p, axis=0).max()
        elif scaling == "fit":
            p *= scale
    return points, normals, offsets
