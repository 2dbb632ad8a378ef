"""Euclidean clustering (PCL's ``EuclideanClusterExtraction``) and splitting by a field."""

import numbers

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ._checks import check_field, check_scene, check_tolerance
from ..utils._param_validation import Interval, validate_parameter

__all__ = ["MIN_POINTS", "MAX_POINTS", "TOLERANCE_FACTOR", "default_tolerance", "euclidean_clusters",
           "number_segments", "split_by_field"]

#: ``min_points``: the smallest kept segment.
MIN_POINTS = [Interval(numbers.Integral, 1, None, closed="left")]
#: ``max_points``: None (no limit) or the largest kept segment.
MAX_POINTS = [None, Interval(numbers.Integral, 1, None, closed="left")]
#: The derived tolerance, in units of the median nearest-neighbour distance.
TOLERANCE_FACTOR = 5.0
#: Points whose nearest-neighbour distance the derived tolerance is taken from.
_SPACING_SAMPLE = 20000


def default_tolerance(points):
    """The tolerance derived from the point spacing of ``points`` (float64, shape (n, 3), n >= 2).

    ``TOLERANCE_FACTOR`` times the median distance from a point to its nearest
    other point, over up to 20,000 points spread evenly through the array (the
    same points on every call). Coincident points are left out of the median;
    a positive value is always returned for a scene of two distinct points or more.
    """
    n = len(points)
    tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
    sample = points[np.unique(np.linspace(0, n - 1, min(n, _SPACING_SAMPLE)).astype(np.int64))]
    k = 2
    while True:
        dist, _ = tree.query(sample, k=min(k, n))
        nearest = dist[:, 1:]
        positive = np.where(nearest > 0, nearest, np.inf).min(axis=1)
        found = positive[np.isfinite(positive)]
        if found.size >= max(1, len(sample) // 2) or k >= n:
            break
        k = min(4 * k, n)  # many duplicates: look further
    spacing = float(np.median(found)) if found.size else float(np.ptp(points, axis=0).max())
    return TOLERANCE_FACTOR * spacing


def number_segments(roots, min_points, max_points):
    """Segment labels from one component id per point.

    Components of fewer than ``min_points`` or more than ``max_points`` points
    get -1; the others are numbered 0, 1, ... by size, largest first, ties by
    the smallest point index in the component.
    """
    n = len(roots)
    if n == 0:
        return np.empty(0, dtype=np.int64)
    _, first, inverse, counts = np.unique(roots, return_index=True, return_inverse=True, return_counts=True)
    keep = counts >= min_points
    if max_points is not None:
        keep &= counts <= max_points
    order = np.lexsort((first, -counts))
    order = order[keep[order]]
    number = np.full(len(counts), -1, dtype=np.int64)
    number[order] = np.arange(len(order), dtype=np.int64)
    return number[inverse.reshape(-1)]


def check_sizes(min_points, max_points, owner):
    """Validate ``min_points`` and ``max_points`` (ints >= 1, None for no upper limit, min <= max)."""
    validate_parameter(min_points, MIN_POINTS, name="min_points", owner=owner)
    validate_parameter(max_points, MAX_POINTS, name="max_points", owner=owner)
    if max_points is not None and max_points < min_points:
        raise ValueError(f"{owner}: max_points ({max_points}) is smaller than min_points ({min_points})")
    return int(min_points), None if max_points is None else int(max_points)


def cluster_roots(points, tolerance):
    """One component id per point: points closer than ``tolerance`` share one."""
    tree = cKDTree(points)
    pairs = tree.query_pairs(np.nextafter(tolerance, 0), output_type="ndarray")
    n = len(points)
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def euclidean_clusters(points, tolerance=None, *, min_points=1, max_points=None):
    """Split a scene into clusters of points closer than a distance to each other.

    The semantics of PCL's ``EuclideanClusterExtraction``: two points closer
    than ``tolerance`` are connected, a cluster is a connected set of points,
    and clusters of fewer than ``min_points`` or more than ``max_points`` points
    are dropped.

    Parameters
    ----------
    points : array-like of shape (n_points, 3) or (n_points, 6)
        The scene (normals, when given, are ignored); at least two points,
        all finite.
    tolerance : float, default=None
        Largest distance (excluded) between two connected points, > 0, in the
        units of ``points``. None derives it from the point spacing: five
        times the median nearest-neighbour distance.
    min_points : int, default=1
        Smallest kept cluster (PCL's ``setMinClusterSize``).
    max_points : int, default=None
        Largest kept cluster (PCL's ``setMaxClusterSize``); None keeps clusters
        of any size.

    Returns
    -------
    labels : ndarray of shape (n_points,), dtype int64
        The cluster of each point, -1 for points in no kept cluster. Clusters
        are numbered 0, 1, ... by size, largest first (as PCL orders them),
        ties by the smallest point index in the cluster, so the numbering is
        the same on every run and for any number of threads.

    Raises
    ------
    ValueError
        If the points are not of shape (n, 3) or (n, 6), hold NaN or infinite
        values, are fewer than two or all identical, or a parameter is out of
        range.
    TypeError
        If the points are not numbers or a parameter has a wrong type.

    See Also
    --------
    segment_scene : Ground removal, then clustering or splitting by a field.
    split_by_field : Segments from an integer per-point field.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.segmentation import euclidean_clusters
    >>> points = np.array([[0, 0, 0], [0.5, 0, 0], [5, 0, 0], [5.5, 0, 0], [6, 0, 0]])
    >>> euclidean_clusters(points, tolerance=1.0)
    array([1, 1, 0, 0, 0])
    >>> euclidean_clusters(points, tolerance=1.0, min_points=3)
    array([-1, -1,  0,  0,  0])
    """
    owner = "euclidean_clusters"
    pts = check_scene(points, owner)
    tol = check_tolerance(tolerance, owner)
    min_points, max_points = check_sizes(min_points, max_points, owner)
    if tol is None:
        tol = default_tolerance(pts)
    return number_segments(cluster_roots(pts, tol), min_points, max_points)


def split_by_field(values, *, min_points=1):
    """Split a scene by an integer per-point field: one segment per distinct value.

    For fields that already tell objects apart: ``instance`` or ``label`` of a
    PCD file, ``classification`` or ``point_source_id`` of a LAS file.

    Parameters
    ----------
    values : array-like of shape (n_points,)
        An integer field (or a float field holding whole numbers only).
    min_points : int, default=1
        Values held by fewer points give no segment (label -1).

    Returns
    -------
    labels : ndarray of shape (n_points,), dtype int64
        The segment of each point, -1 for points of a value held by fewer than
        ``min_points`` points. Segments are numbered 0, 1, ... in increasing
        order of the value (``np.unique(values)`` order, dropped values left out).

    Raises
    ------
    TypeError
        If the field is not an integer field.
    ValueError
        If the field is not one-dimensional or ``min_points`` is out of range.

    See Also
    --------
    segment_scene : Segments by a field of a scene read with its fields.

    Examples
    --------
    >>> from eppf.segmentation import split_by_field
    >>> split_by_field([7, 7, 3, 9, 3, 7])
    array([1, 1, 0, 2, 0, 1])
    >>> split_by_field([7, 7, 3, 9, 3, 7], min_points=2)
    array([ 1,  1,  0, -1,  0,  1])
    """
    owner = "split_by_field"
    validate_parameter(min_points, MIN_POINTS, name="min_points", owner=owner)
    field = check_field(values, None, owner)
    return split_field(field, int(min_points))


def split_field(field, min_points):
    """:func:`split_by_field` on a checked int64 field."""
    if field.size == 0:
        return np.empty(0, dtype=np.int64)
    uniq, inverse, counts = np.unique(field, return_inverse=True, return_counts=True)
    keep = counts >= min_points
    number = np.full(len(uniq), -1, dtype=np.int64)
    number[keep] = np.arange(int(keep.sum()), dtype=np.int64)
    return number[inverse.reshape(-1)]
