"""Region growing and pair features shared by the CVFH-family descriptors.

The shared module of :class:`eppf.OURCVFHTransformer` and
:class:`eppf.CVFHTransformer` (its functions are public within the package
for that reason): the curvature filter (:func:`low_curvature`, compiled), the
smooth regions grown from the points that pass it (:func:`smooth_clusters`),
PCL's pair features of a
reference point (a region's centroid and mean normal) against every point of
the object (:func:`pair_features`), and FLANN's single k-d tree radius search
(:func:`radius_neighbors_flann`, compiled with CVFH's kernel on the tree
GRSD's kernel searches too) for PCL's own region growing.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from . import _cvfh_fast
from ._cvfh_fast import radius_neighbors_flann

__all__ = ["low_curvature", "pair_features", "radius_neighbors_flann", "smooth_clusters"]


def low_curvature(points, k, threshold):
    """Whether each point's surface variation is at most ``threshold``.

    The surface variation ``lambda_min / sum(lambda)`` of the scatter of a
    point's ``k`` nearest neighbors (itself included), decided by the compiled
    kernel (``+ - * /`` only, the same bits on every CPU). Where the k-th
    nearest neighbor ties with the next one (grids, repeated points), the ``k``
    nearest are those SciPy's k-d tree returns (as eppf's earlier NumPy filter took);
    elsewhere they are unique.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    keep, tied = _cvfh_fast.low_curvature(points, k, threshold)
    if tied.size:
        k = min(k, len(points))
        _, idx = cKDTree(points).query(points[tied], k=k)
        keep[tied] = _cvfh_fast.low_curvature_of(points, np.ascontiguousarray(idx.reshape(len(tied), k), dtype=np.int64),
                                                 threshold)
    return keep


def smooth_clusters(points, normals, keep, tolerance, cos_eps, min_points):
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


def pair_features(c, nc, points, normals):
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
