"""Euclidean clustering (PCL's ``EuclideanClusterExtraction``) and splitting by a field."""

import numbers

import numpy as np

from . import _cluster_fast
from ._checks import MIN_TOLERANCE, check_field, check_scene, check_tolerance
from ..utils._param_validation import Interval, validate_parameter

__all__ = ["MIN_POINTS", "MAX_POINTS", "TOLERANCE_FACTOR", "default_tolerance", "euclidean_clusters",
           "number_segments", "split_by_field"]

#: ``min_points``: the smallest kept segment.
MIN_POINTS = [Interval(numbers.Integral, 1, None, closed="left")]
#: ``max_points``: None (no limit) or the largest kept segment.
MAX_POINTS = [None, Interval(numbers.Integral, 1, None, closed="left")]
#: The derived tolerance, in units of the median nearest-neighbor distance.
TOLERANCE_FACTOR = 5.0
#: Points whose nearest-neighbor distance the derived tolerance is taken from.
_SPACING_SAMPLE = 20000
#: Points in a cell above which the derived tolerance's search takes finer cells (see :func:`_finer_side`).
_CROWDED = 64


def default_tolerance(points, owner="segment_scene"):
    """The tolerance derived from the point spacing of ``points`` (float64, shape (n, 3), n >= 2).

    ``TOLERANCE_FACTOR`` times the median distance from a point to its nearest
    other point (coincident points left out), over up to 20,000 points spread
    evenly through the array (the same points on every call). The distances are
    found on a grid whose cells start at twice the spacing the points would have
    on the bounding box's two longest sides (finer where most of those points
    lie in crowded cells, see :func:`_finer_side`), and grow at least fourfold,
    up to the median distance found, until more than half of those points have
    a neighbor within one cell: the median is then exact. Raises a ValueError
    naming ``owner`` when the tolerance would be below :data:`MIN_TOLERANCE`.
    """
    n = len(points)
    sample = np.unique(np.linspace(0, n - 1, min(n, _SPACING_SAMPLE)).astype(np.int64))
    # coincident sample points have the same distance: each is searched once (a pile of 10^6 identical
    # points, as scanners write for missing returns, was scanned in full for each of its sample points)
    _, first, copy = np.unique(points[sample], axis=0, return_index=True, return_inverse=True)
    distinct, copy = sample[first], copy.reshape(-1)
    extent = np.sort(points.max(axis=0) - points.min(axis=0))
    side = 2.0 * float(np.sqrt(extent[2]) * np.sqrt(max(extent[1], extent[2] * 1e-6)) / np.sqrt(n))
    # finer cells would hold squared distances that underflow (and scenes of points far apart take them
    # run by run, see grid_cells)
    finest = MIN_TOLERANCE
    middle = len(sample) // 2
    shrink = True
    while True:
        grid = grid_cells(points, side, owner)
        if shrink:
            finer = _finer_side(points, grid, distinct, side, finest)
            if finer is not None:
                side = finer
                continue
            shrink = False
        dist = _cluster_fast.nearest_distances(points, *grid, distinct)[copy]
        spacing = float(np.partition(dist, middle)[middle])
        if spacing <= side:
            break
        # every distance found is that of a point, so the median is at most the one found: with cells that
        # wide the next round ends (cells at least four times wider keep the rounds few where none was found)
        side = max(4.0 * side, spacing) if np.isfinite(spacing) else 4.0 * side
    if TOLERANCE_FACTOR * spacing < MIN_TOLERANCE:
        raise ValueError(f"{owner}: the median nearest-neighbor distance of the points is {spacing:.6g}, so the "
                         f"tolerance derived from it ({TOLERANCE_FACTOR:g} times that) is below {MIN_TOLERANCE:g}, "
                         "where squared distances underflow float64: rescale the coordinates")
    return TOLERANCE_FACTOR * spacing


def _finer_side(points, grid, distinct, side, finest):
    """A side of cells finer than ``side`` for :func:`default_tolerance` when most of the ``distinct`` sample
    points lie in crowded cells of the ``grid`` (each search would compare with every point of a crowd),
    else None.

    The side from the bounding box suits points spread over it; a dense blob (most points within 1e-6 of
    each other, a far point or two widening the box) put the whole blob in one cell, searched in full for
    each of its sample points (seconds for 200,000 points). The finer side aims at :data:`_CROWDED` points a
    cell in the crowds' boxes (their median count and longest side), at most half ``side`` (a flat or thin
    crowd fills its box less), never finer than ``finest`` (None when ``side`` is already that fine). Piles
    of coincident points are no crowds: finer cells do not part them, and each is searched once (for its one
    distinct sample point). Whatever the side, the median :func:`default_tolerance` returns is exact, so
    finer cells change its time, not its value.
    """
    count, width = _cluster_fast.crowding(points, *grid, distinct)
    crowded = (count > _CROWDED) & (width > 0)  # a pile of coincident points is no crowd: no cell parts it
    if 2 * np.count_nonzero(crowded) <= len(distinct):
        return None
    target = float(np.median(width[crowded])) * float(np.cbrt(_CROWDED / np.median(count[crowded])))
    finer = max(min(target, 0.5 * side), finest)  # at least halved: the target is for crowds filling 3D boxes
    return finer if finer < side else None


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


#: Most cells along one axis: below this, the rounding of a cell coordinate (about 2**30 * 3.3e-16,
#: 3.6e-7 of a cell, for each of two points) stays under the 1e-6 margin left in the cell's side.
_MAX_CELLS = 2**30
#: Below this many cells along every axis, the three coordinates pack into one int64 sort key.
_PACKED = 2**21


def _gapped_cells(x, side):
    """Cell coordinates along one axis of coordinates ``x`` spanning too many cells of ``side``: the points
    part into runs at gaps of at least two cells (no two points across one are within a tolerance, or a
    cell's side, of each other), each run gets cells from its own lowest point, and the runs follow each
    other in cell coordinates with empty cells between them. None when a run spans :data:`_MAX_CELLS` cells.

    So a stray point far from the scene (1e12 away, a scanner's bad return) costs a run of its own, not
    2**40 cells' worth of coordinates whose rounding would exceed the margin of the cells' side.
    """
    order = np.argsort(x, kind="stable")
    xs = x[order]
    first = np.concatenate([[0], np.flatnonzero(np.diff(xs) >= 2.0 * side) + 1])
    last = np.append(first[1:], len(xs)) - 1
    span = (xs[last] - xs[first]) / side
    if not (span < _MAX_CELLS).all():
        return None
    # four more than the run's cells: room for the floor's rounding and for two empty cells between runs
    offset = np.concatenate([[0], np.cumsum(np.floor(span[:-1]).astype(np.int64) + 4)])
    run = np.repeat(np.arange(len(first)), last - first + 1)
    out = np.empty(len(xs), dtype=np.int64)
    out[order] = np.floor((xs - xs[first][run]) * (1.0 / side)).astype(np.int64) + offset[run]
    return out


def grid_cells(points, side, owner):
    """The cubic cells of ``side`` holding ``points``: (cell of each point, order, start, occupied cells).

    ``order`` sorts the points by cell lexicographically; the points of the
    ``a``-th occupied cell are ``order[start[a]:start[a + 1]]``. Along an axis
    where the scene spans 2**30 cells or more, the cells come from
    :func:`_gapped_cells`. Raises a ValueError naming ``owner`` when even a run
    of points without gaps of two cells spans 2**30 cells along an axis (a
    tolerance too small for the scene's extent).
    """
    lo = points.min(axis=0)
    with np.errstate(over="ignore"):
        span = (points.max(axis=0) - lo) / side
    cells = _cluster_fast.cells(points, lo[0], lo[1], lo[2], 1.0 / side, _MAX_CELLS)
    for axis in np.flatnonzero(~(span < _MAX_CELLS)):
        gapped = _gapped_cells(np.ascontiguousarray(points[:, axis]), side)
        if gapped is None:
            raise ValueError(f"{owner}: the scene spans more than 2**30 cells of the tolerance along "
                             f"{'xyz'[axis]} (extent {np.ptp(points, axis=0).max():.6g}, cell {side:.6g}) without "
                             f"a gap; give a larger tolerance or split the scene")
        cells[:, axis] = gapped
        span[axis] = float(gapped.max())
    if (span < _PACKED - 1).all():
        # the order of the points within a cell does not matter: any sort will do
        order = np.argsort((cells[:, 0] * _PACKED + cells[:, 1]) * _PACKED + cells[:, 2])
    else:
        order = np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0]))
    start, occupied = _cluster_fast.runs(cells, order)
    return cells, order, start, occupied


def cluster_roots(points, tolerance, owner="euclidean_clusters"):
    """One component id per point (a point index): points closer than ``tolerance`` share one."""
    side = tolerance / np.sqrt(3.0) * (1.0 - 1e-6)  # any two points of a cell are closer than the tolerance
    _, order, start, occupied = grid_cells(points, side, owner)
    return _cluster_fast.connect(points, order, start, occupied, tolerance)


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
        Largest distance (excluded) between two connected points, at least
        1e-150 (smaller squared distances underflow float64), in the units of
        ``points``. None derives it from the point spacing: five times the
        median nearest-neighbor distance.
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
        values, are fewer than two or all identical, span more than 1e100 or
        (along their longest axis) less than 1e-100, a run of points without
        gaps of a tolerance spans more than 2**30 tolerances along an axis
        (far stray points are no such run), the derived tolerance is below
        1e-150, or a parameter is out of range.
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
        tol = default_tolerance(pts, owner)
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


def split_field(field, min_points, max_points=None):
    """:func:`split_by_field` on a checked int64 field; values held by more than ``max_points`` points
    (None: no limit) give no segment either."""
    if field.size == 0:
        return np.empty(0, dtype=np.int64)
    uniq, inverse, counts = np.unique(field, return_inverse=True, return_counts=True)
    keep = counts >= min_points
    if max_points is not None:
        keep &= counts <= max_points
    number = np.full(len(uniq), -1, dtype=np.int64)
    number[keep] = np.arange(int(keep.sum()), dtype=np.int64)
    return number[inverse.reshape(-1)]
