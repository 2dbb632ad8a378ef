"""Ground removal: a RANSAC plane, or a slope-limited lowest surface on a grid."""

import numbers

import numpy as np
from sklearn.utils import check_random_state

from . import _cluster_fast
from ._checks import check_scene
from ._cluster import default_tolerance
from ..utils._param_validation import RANDOM_STATE, Interval, StrOptions, validate_parameter

__all__ = ["GROUND_METHODS", "ground_mask", "remove_ground"]

GROUND_METHODS = ("auto", "plane", "grid")
_CONSTRAINTS = {
    "method": [StrOptions(GROUND_METHODS)],
    "threshold": [None, Interval(numbers.Real, 0, None, closed="neither")],
    "max_slope": [Interval(numbers.Real, 0, None, closed="left")],
    "n_trials": [Interval(numbers.Integral, 1, 100000, closed="both")],
    "random_state": RANDOM_STATE,
}
#: Points the RANSAC hypotheses are scored on (a fixed random subset of the scene).
_RANSAC_SAMPLE = 50000
#: Largest scene whose RANSAC subset is drawn from a permutation of all its points (as before the draw of
#: :func:`_subset` existed, so such scenes keep their ground): beyond it the permutation's memory (8 bytes a
#: point, 800 MB for 10^8 points) is not proportional to the subset's.
_PERMUTED = 4 * _RANSAC_SAMPLE
#: Most least-squares refits of the RANSAC plane (each on the band its noise leaves, till it settles).
_REFITS = 10
#: Narrowest band of a refit, as a share of RANSAC's inlier distance (a noise-free plane).
_FLAT = 1e-3
#: Share of the lowest-surface cells that must lie on the plane for "auto" to keep it.
_PLANAR_SHARE = 0.9
#: Most runs of points far apart the grid model takes one by one (see :func:`_apart`); beyond, one grid.
_MAX_RUNS = 64
#: Fewest other points within reach above a point, in its cell and the 8 adjacent ones, that make it a part
#: of a surface rather than low noise (see :func:`_low_outliers`): lone points, pairs and clumps of three
#: have fewer.
_SUPPORT = 3
#: Side of the cells whose blocks of 3 x 3 the support is counted in, at least: in mean point spacings (the
#: side of the scene's box over the square root of its points), some 36 points a block.
_SUPPORT_CELL = 2.0


def _toward_objects(local, nrm, d, threshold, up=False):
    """The plane ``local @ nrm = d`` with its normal turned toward the side holding more of the points
    farther than ``threshold`` from it (the objects); with ``up``, toward +z (unless the plane is vertical)."""
    if up and nrm[2] != 0:
        return (-nrm, -d) if nrm[2] < 0 else (nrm, d)
    dist = local @ nrm - d
    flip = np.count_nonzero(dist <= -threshold) > np.count_nonzero(dist >= threshold)
    return (-nrm, -d) if flip else (nrm, d)


def _subset(n, k, rng):
    """``k`` distinct indices of ``range(n)`` (``k < n``), sorted: a uniformly random subset, drawn with memory
    proportional to ``k`` and the same for the same state of ``rng``.

    Up to :data:`_PERMUTED` points, the first ``k`` of a permutation (``rng.choice``); beyond, indices drawn
    with replacement in batches, kept in the order drawn with repeats dropped (each new index uniform among
    those not yet kept), until there are ``k``: a batch of ``k`` or fewer draws holds under a quarter of
    repeats, so there are few batches.
    """
    if n <= _PERMUTED:
        return np.sort(rng.choice(n, k, replace=False))
    kept = np.empty(0, dtype=np.int64)
    while len(kept) < k:
        drawn = np.concatenate([kept, rng.randint(0, n, size=k - len(kept), dtype=np.int64)])
        _, first = np.unique(drawn, return_index=True)
        kept = drawn[np.sort(first)]  # the kept ones first, then the new ones in the order drawn
    return np.sort(kept)


def _plane_ransac(points, threshold, n_trials, rng, up=False):
    """(unit normal toward the objects, offset, robust standard deviation of the ground's noise) of the plane
    with most points within ``threshold``, refined by least squares; with ``up``, the normal is toward +z
    (see :func:`_toward_objects`).

    The refinement fits the points within a band around the plane, from ``threshold`` down to twice the
    noise's standard deviation: within ``threshold`` lie the lowest parts of the objects standing on the
    plane, which would lift and tilt it. The deviation is measured under the plane only (1.4826 times the
    median distance of the points less than ``threshold`` under it), where there are no objects.
    """
    n = len(points)
    sample = points if n <= _RANSAC_SAMPLE else points[_subset(n, _RANSAC_SAMPLE, rng)]
    center = sample.mean(axis=0)
    local = sample - center
    picks = rng.randint(0, len(sample), size=(n_trials, 3))
    a, b, c = local[picks[:, 0]], local[picks[:, 1]], local[picks[:, 2]]
    # the normals' directions from coordinates of unit scale: the squares of the cross products' components
    # underflow (a scene 1e-90 wide) or overflow (1e90 wide) on the scene's own scale
    scale = float(np.abs(local).max())
    normals = np.cross((b - a) / scale, (c - a) / scale)
    length = np.linalg.norm(normals, axis=1)
    ok = length > 0
    best, best_count = None, -1
    for k in np.flatnonzero(ok):
        nrm = normals[k] / length[k]
        count = int(np.count_nonzero(np.abs(local @ nrm - a[k] @ nrm) < threshold))
        if count > best_count:
            best, best_count = (nrm, a[k] @ nrm), count
    if best is None:  # every triple collinear: the points lie on a line; any plane through it
        axis = local[np.argmax(np.linalg.norm(local, axis=1))]
        helper = np.eye(3)[np.argmin(np.abs(axis))]
        nrm = np.cross(axis, helper)
        best = (nrm / np.linalg.norm(nrm), 0.0)
    nrm, d = _toward_objects(local, *best, threshold, up)
    band, sigma = threshold, threshold / 4.0
    for _ in range(_REFITS):
        inliers = local[np.abs(local @ nrm - d) < band]
        if len(inliers) < 3:
            break
        mean = inliers.mean(axis=0)
        _, _, vt = np.linalg.svd(inliers - mean, full_matrices=False)
        nrm, d = _toward_objects(local, vt[2], mean @ vt[2], threshold, up)
        height = local @ nrm - d
        under = height[(height < 0) & (height > -threshold)]
        if not under.size:  # nothing under the plane: a noise-free plane
            sigma = 0.0
            break
        sigma = 1.4826 * float(np.median(-under))
        narrower = min(band, max(2.0 * sigma, _FLAT * threshold))
        if narrower > 0.99 * band:  # settled
            break
        band = narrower
    return nrm, d + center @ nrm, sigma


def _cells_over_budget(points, cell):
    """Whether the grid of ``cell`` over ``points`` has more cells than its budget, the one of :func:`_one_grid`
    (which then widens its cells)."""
    extent = np.ptp(points[:, :2], axis=0)
    budget = max(4.0 * len(points), 2.0**20)
    with np.errstate(over="ignore"):
        cells = (extent[0] / cell + 1.0) * (extent[1] / cell + 1.0)
    return not cells <= budget


def _apart(points, cell, max_slope):
    """The runs of points (index arrays) along x, then along y within each, parted by horizontal gaps across
    which the lowest surface does not reach: wider than the scene's height range over ``max_slope`` and three
    cells; None when there is one run, or more than :data:`_MAX_RUNS`."""
    height = float(np.ptp(points[:, 2]))
    if max_slope == 0 and height > 0:
        return None
    gap = height / max_slope + 3.0 * cell if height > 0 else 3.0 * cell
    runs = [np.arange(len(points))]
    for axis in (0, 1):
        parted = []
        for run in runs:
            order = run[np.argsort(points[run, axis], kind="stable")]
            cuts = np.flatnonzero(np.diff(points[order, axis]) > gap) + 1
            parted.extend(np.split(order, cuts))
            if len(parted) > _MAX_RUNS:
                return None
        runs = parted
    return [np.sort(run) for run in runs] if len(runs) > 1 else None


def _grid_surface(points, cell, max_slope):
    """:func:`_one_grid` of the scene, or of each of its runs (:func:`_apart`) where the scene's grid would be
    over its budget: stray points far from the scene (1e12 away) widened the cells of the whole scene, and
    the ground model with them, where the lowest surface between them and the scene is never reached.
    The runs' cells are numbered one run after the other."""
    runs = _apart(points, cell, max_slope) if _cells_over_budget(points, cell) else None
    if runs is None:
        return _one_grid(points, cell, max_slope)
    rise = np.empty(len(points))
    flat = np.empty(len(points), dtype=np.int64)
    low = np.empty(len(points), dtype=bool)
    zmins, first = [], 0
    for run in runs:
        rise[run], run_flat, run_zmin, _, low[run] = _one_grid(points[run], cell, max_slope)
        flat[run] = run_flat + first
        zmins.append(run_zmin)
        first += len(run_zmin)
    return rise, flat, np.concatenate(zmins), cell, low


def _low_outliers(flat, n_cells, n_columns, z, reach):
    """(whether each point is low noise, whether it is alone) on the grid of cells ``flat`` (``n_cells`` of
    them, ``n_columns`` a row). Low noise (a multipath return, LAS class 7) under the ground: in its cell
    and the 8 adjacent ones, fewer than :data:`_SUPPORT` other points lie within ``reach`` above it (from
    ``z`` to ``z + reach``), and at least :data:`_SUPPORT` points lie higher (the ground it is under).
    Alone: fewer than :data:`_SUPPORT` of either (for :func:`_one_grid` to compare with the ground around).

    ``reach`` is the most a ground surface through the point rises within those cells: the threshold, plus
    ``max_slope`` times the farthest two points of the 3 x 3 cells can be apart. Ground, sampled densely
    enough for the cells, has points in that reach: those of its noise and of the terrain around; a lone
    point farther under it, or a clump of three, has none. Points with nothing over them (stray points,
    sparse returns far from the scene, low noise off the ground's edge or in a hole of it, where water
    returns nothing) are not noise but alone. Only the points that would set their cell's lowest height are
    looked at: each cell's lowest point, then, while that one is noise, the next one up.
    """
    n = len(z)
    order = np.argsort(z)
    heights = z[order]
    # each point's rank among the heights, tied points sharing the lowest: the points of a cell from z up
    # are those of rank >= the point's
    first = np.ones(n, dtype=bool)
    first[1:] = heights[1:] != heights[:-1]
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.maximum.accumulate(np.where(first, np.arange(n), 0))
    keys = flat * n + rank  # below 1e19: a grid holds at most max(4 n, 2^20) cells
    by_cell = np.argsort(keys)
    keys = keys[by_cell]
    bounds = np.zeros(n_cells + 1, dtype=np.int64)
    np.cumsum(np.bincount(flat, minlength=n_cells), out=bounds[1:])
    low, alone = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    at = bounds[:-1][bounds[1:] > bounds[:-1]]  # each nonempty cell's lowest point, as a position in keys
    while at.size:
        # most points have _SUPPORT points of their own cell within reach: those are not looked at further
        ahead = at + _SUPPORT
        ahead_inside = ahead < bounds[flat[by_cell[at]] + 1]
        ahead[~ahead_inside] = at[~ahead_inside]
        at = at[~ahead_inside | (z[by_cell[ahead]] > z[by_cell[at]] + reach)]
        point = by_cell[at]
        top = np.searchsorted(heights, z[point] + reach, side="right")  # within reach: ranks below top
        cell = flat[point]
        row, column = np.divmod(cell, n_columns)
        support = np.full(len(at), -1, dtype=np.int64)  # the point itself is counted in its own cell
        above = np.zeros(len(at), dtype=np.int64)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                i, j = row + di, column + dj
                inside = np.flatnonzero((i >= 0) & (j >= 0) & (j < n_columns) & (i * n_columns + j < n_cells))
                other = i[inside] * n_columns + j[inside]
                start = np.searchsorted(keys, other * n + rank[point[inside]])
                middle = np.searchsorted(keys, other * n + top[inside])
                support[inside] += middle - start
                above[inside] += bounds[other + 1] - middle
        noise = (support < _SUPPORT) & (above >= _SUPPORT)
        low[point[noise]] = True
        alone[point[(support < _SUPPORT) & (above < _SUPPORT)]] = True
        at = at[noise] + 1  # the next point up of the cells whose lowest was noise
        at = at[at < bounds[flat[by_cell[at - 1]] + 1]]
    return low, alone


def _one_grid(points, cell, max_slope):
    """(height of each point above the grid's ground surface, cell of each point, lowest z per cell, cell side,
    whether each point is low noise).

    Low noise is found by :func:`_low_outliers` on cells at least :data:`_SUPPORT_CELL` mean spacings
    wide, its reach ``cell`` (as given: the threshold) plus ``max_slope`` across 3 x 3 of them. The cells'
    lowest points, low noise left out, give the surface ``S(c) = min over cells c' of
    (zmin(c') + max_slope * |c - c'|)`` (8-neighbor chamfer distances between
    cell centers): objects standing on the ground leave it, roofs and other
    raised flat parts too where they are narrower than their height over
    ``max_slope``. The ground under a point is then ``S(c)`` carried from the
    lowest point of its cell (the cell's center for an empty cell) along the
    surface's gradient (central differences, at most ``max_slope`` steep).
    """
    band = cell  # the ground's band: its threshold, or the tolerance that bounds it
    xy = points[:, :2] - points[:, :2].min(axis=0)
    extent = xy.max(axis=0)
    budget = max(4.0 * len(points), 2.0**20)  # memory linear in the points, whatever the cell
    with np.errstate(over="ignore"):
        cells = (extent[0] / cell + 1.0) * (extent[1] / cell + 1.0)
    if not cells <= budget:  # wider cells, as many as the budget
        cell = max(cell, float(np.sqrt(extent[0] + cell) * np.sqrt(extent[1] + cell) / np.sqrt(budget)))
    shape = np.minimum(np.floor(extent / cell), budget).astype(np.int64) + 1
    ij = np.minimum(np.floor(xy / cell), shape - 1).astype(np.int64)
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    # the support is counted on cells at least twice the mean spacing of the points over the scene's box, so
    # that a block of 3 x 3 holds some 36 points where the ground is as dense as the scene: cells of a
    # threshold finer than the spacing hold too few, and took the ground points under an object for noise
    with np.errstate(over="ignore"):
        spacing = float(np.sqrt(extent[0] + band) * np.sqrt(extent[1] + band) / np.sqrt(len(points)))
    wide = max(cell, _SUPPORT_CELL * spacing)
    wide_shape = np.minimum(np.floor(extent / wide), budget).astype(np.int64) + 1
    wide_ij = np.minimum(np.floor(xy / wide), wide_shape - 1).astype(np.int64)
    # ground within reach of a point: under the band over a surface rising at most max_slope across the block
    with np.errstate(over="ignore"):
        reach = band + max_slope * (2.0 * np.sqrt(2.0) * wide)
    low, alone = _low_outliers(wide_ij[:, 0] * wide_shape[1] + wide_ij[:, 1],
                               int(wide_shape[0] * wide_shape[1]), int(wide_shape[1]), points[:, 2], reach)
    rest = ~(low | alone)
    if alone.any() and rest.any():
        # a point alone is low noise too where it lies farther than reach under the surface of the others
        # (off the ground's edge, in a hole of it): it would pull that surface down; stray points far from
        # the scene, under that surface too, are ground either way
        others = np.full(int(shape[0] * shape[1]), np.inf)
        np.minimum.at(others, flat[rest], points[rest, 2])
        others = others.reshape(tuple(shape))
        _cluster_fast.slope_envelope(others, max_slope * cell, max_slope * cell * np.sqrt(2.0))
        low |= alone & (points[:, 2] < others.reshape(-1)[flat] - reach)
    zmin = np.full(int(shape[0] * shape[1]), np.inf)
    if low.any():  # a cell of low noise only is empty: the surface around fills it
        np.minimum.at(zmin, flat[~low], points[~low, 2])
    else:
        np.minimum.at(zmin, flat, points[:, 2])
    surface = zmin.reshape(tuple(shape)).copy()
    _cluster_fast.slope_envelope(surface, max_slope * cell, max_slope * cell * np.sqrt(2.0))
    gradient = np.zeros((2,) + surface.shape)
    for axis in (0, 1):
        if surface.shape[axis] > 1:
            gradient[axis] = np.gradient(surface, cell, axis=axis)
    steep = np.hypot(gradient[0], gradient[1])
    # only where steeper than max_slope: max_slope over a nearly flat surface's slope overflowed (max_slope 1e308)
    over = steep > max_slope
    gradient[:, over] *= max_slope / steep[over]
    # where the ground surface is known: the lowest point of each cell, else the cell's center
    anchor = (np.indices(tuple(shape)).reshape(2, -1).T + 0.5) * cell
    lowest = np.flatnonzero((points[:, 2] == zmin[flat]) & ~low)
    anchor[flat[lowest]] = xy[lowest]
    offset = xy - anchor[flat]
    ground = surface.reshape(-1)[flat] + gradient[0].reshape(-1)[flat] * offset[:, 0] \
        + gradient[1].reshape(-1)[flat] * offset[:, 1]
    return points[:, 2] - ground, flat, zmin, cell, low


def grid_threshold(rise, tolerance):
    """The grid model's threshold when none is given: the median height above the ground surface plus
    four robust standard deviations (1.4826 times the median absolute deviation), of the points below
    the threshold found so far (from ``tolerance``, three rounds: the objects' lower parts leave the
    sample), kept between a quarter of ``tolerance`` and ``tolerance``."""
    cap = tolerance
    for _ in range(3):
        near = rise[rise < cap]
        if not near.size:
            break
        middle = float(np.median(near))
        sigma = 1.4826 * float(np.median(np.abs(near - middle)))
        cap = min(tolerance, max(middle + 4.0 * sigma, tolerance / 4.0))
    return cap


def ground_mask(points, method, threshold, tolerance, max_slope, n_trials, rng):
    """The ground mask of checked points (float64, (n, 3)) and the method used ("plane" or "grid").

    ``tolerance`` (positive) is the distance of the point spacing: RANSAC's inlier
    distance and the grid's cell. ``threshold`` is the height above the ground model
    under which a point is ground; None: four of the noise's standard deviations
    :func:`_plane_ransac` measures for the plane (kept between a quarter of ``tolerance`` and
    ``tolerance``), :func:`grid_threshold` for the grid.
    """
    if method in ("plane", "auto"):
        fit_distance = tolerance if threshold is None else threshold
        # auto keeps the plane only where the lowest surface (along z) lies on it: its objects are above it
        # along z, even where low noise under it outnumbers them (the side holding more took it for them)
        nrm, offset, sigma = _plane_ransac(points, fit_distance, n_trials, rng, up=method == "auto")
        height = points @ nrm - offset
        plane = height < (min(tolerance, max(4.0 * sigma, tolerance / 4.0)) if threshold is None else threshold)
        if method == "plane":
            return plane, "plane"
    rise, flat, zmin, cell, low = _grid_surface(points, tolerance if threshold is None else threshold, max_slope)
    if threshold is None:  # from the ground without its low noise, which would lower its median
        threshold = grid_threshold(rise[~low] if low.any() else rise, tolerance)
    grid = rise < threshold  # low noise, under the surface, included
    if method == "grid":
        return grid, "grid"
    # auto: the plane where the lowest surface is planar (a floor, flat or tilted ground), else the grid
    lowest = np.flatnonzero((points[:, 2] == zmin[flat]) & grid & ~low)  # each ground cell's lowest point(s)
    ground_cells = np.zeros(len(zmin), dtype=bool)
    ground_cells[flat[lowest]] = True
    planar = np.zeros(len(zmin), dtype=bool)
    planar[flat[lowest]] = np.abs(height[lowest]) < threshold
    share = np.count_nonzero(planar) / max(1, np.count_nonzero(ground_cells))
    return (plane, "plane") if share >= _PLANAR_SHARE else (grid, "grid")


def remove_ground(points, *, method="auto", threshold=None, max_slope=0.3, n_trials=100, random_state=0):
    """Find the ground points of a scene.

    Two models of the ground:

    - ``"plane"``: the plane holding most points within ``threshold``, found by
      RANSAC (``n_trials`` planes through three random points, scored on up to
      50,000 points of the scene) and refined by least squares on the points
      within a band around it, narrowed round after round to twice the
      ground's noise (the lowest parts of the objects, also within
      ``threshold`` of the plane, would lift and tilt it). "Above" is the side
      holding more of the points off the plane (the objects); ground is every
      point less than ``threshold`` above the plane, points below it (noise
      under a floor) included. For floors, CAD scenes and flat or evenly
      tilted terrain, in any orientation. Limits: the ground must be the
      largest plane of the scene; the objects lose their parts lower than the
      threshold, and a flat part lying on the ground (a plate, a sheet) is
      taken for ground.
    - ``"grid"``: for terrain that is not one plane (aerial tiles): the lowest
      point of each cell of a horizontal grid (cells ``threshold`` wide, wider
      where that would make more than four cells per point), and the surface
      that rises at most ``max_slope`` (rise over run) from the lowest points
      around it; the ground under a point is that surface carried from its
      cell's lowest point along the surface's gradient, and ground is every
      point less than ``threshold`` above it. The vertical axis is z.
      Points farther apart horizontally than the scene's height range over
      ``max_slope`` (stray points far from the scene), where the surface of
      one never reaches the other, get grids of their own when one grid
      would widen its cells (up to 64 such runs).
      Low noise (multipath returns, LAS class 7: lone points or clumps of up
      to three far under the ground) is left out of the cells' lowest
      points, so it does not pull the surface down: a point is low noise
      when, in its cell and the 8 adjacent ones of a grid of cells at least
      twice the scene's mean point spacing wide, fewer than three other
      points lie within reach above it (no higher than ``threshold`` plus
      ``max_slope`` times the farthest two points of those cells can be
      apart: where a surface through it could reach; the tolerance when
      ``threshold`` is None), and at least three lie higher; or, with fewer
      than three higher too (off the ground's edge, in a hole of it where
      water returns nothing), when it lies more than that reach under the
      surface of the other points. Low noise is ground, as the points under
      the plane are.
      Real low terrain (a ditch, a pit of more than three points) holds its
      own support and is followed.
      Limits: a flat object of height ``h`` is taken for ground where it is
      farther than ``h / max_slope`` from its edge (the middle of a large
      flat roof), terrain steeper than ``max_slope`` is partly left out of
      the ground, a clump of more than three low points, or low points
      within that reach of the ground (``threshold`` plus ``2.83 *
      max_slope`` cells or more: 0.63 m for cells and threshold of 0.34 m
      and the default slope), still pull the surface down around them, and
      the lowest points of an object overhanging the scene's edge, with no
      ground under it, are taken for low noise.
    - ``"auto"``: the plane when the lowest points of at least 90% of the
      grid's ground cells (low noise left out) lie within the grid's
      threshold of it (a floor, flat or evenly tilted ground), else the
      grid: a few low points under a floor leave it the plane. The plane's
      "above" is then +z (the lowest surface's objects stand on it), not
      the side holding more points off it, which low noise under a floor
      with few objects on it would be.

    Parameters
    ----------
    points : array-like of shape (n_points, 3) or (n_points, 6)
        The scene (normals, when given, are ignored); at least two points,
        all finite.
    method : {"auto", "plane", "grid"}, default="auto"
        The ground model, see above.
    threshold : float, default=None
        Height above the ground model under which a point is ground, > 0, in
        the units of the points; also RANSAC's inlier distance and the grid's
        cell. None starts from the tolerance :func:`euclidean_clusters` derives
        from the point spacing: RANSAC takes inliers within it and the grid's
        cells are that wide; the threshold is then the ground's noise, four
        robust standard deviations of the distances to the plane (1.4826 times
        the median distance of the points under it, where no object is), or
        for the grid the median height above its surface (low noise left
        out) plus four robust standard deviations (1.4826 times a median
        absolute deviation), kept between a quarter of the tolerance and the
        tolerance.
    max_slope : float, default=0.3
        Steepest ground of the grid model, as rise over run (0.3 is about 17
        degrees), >= 0.
    n_trials : int, default=100
        RANSAC's planes tried (between 1 and 100,000).
    random_state : int, RandomState instance or None, default=0
        Seed of RANSAC's draws; the default gives the same ground on every call.

    Returns
    -------
    ground : ndarray of shape (n_points,), dtype bool
        True for the ground points.

    Raises
    ------
    ValueError
        If the points are not of shape (n, 3) or (n, 6), hold NaN or infinite
        values, are fewer than two or all identical, span more than 1e100 or
        (along their longest axis) less than 1e-100, the tolerance derived for
        ``threshold=None`` is below 1e-150, or a parameter is out of range.

    See Also
    --------
    segment_scene : Ground removal followed by clustering.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.segmentation import remove_ground
    >>> rng = np.random.default_rng(0)
    >>> floor = np.column_stack([rng.uniform(0, 10, (2000, 2)), rng.normal(0, 0.01, 2000)])
    >>> box = rng.uniform([4, 4, 1.0], [5, 5, 2.0], size=(300, 3))
    >>> ground = remove_ground(np.vstack([floor, box]), method="plane")
    >>> int(ground[:2000].sum()), int(ground[2000:].sum())
    (2000, 0)
    """
    owner = "remove_ground"
    for name, value in (("method", method), ("threshold", threshold), ("max_slope", max_slope),
                        ("n_trials", n_trials), ("random_state", random_state)):
        validate_parameter(value, _CONSTRAINTS[name], name=name, owner=owner)
    pts = check_scene(points, owner)
    thr = None if threshold is None else float(threshold)
    tol = default_tolerance(pts, owner) if thr is None else thr
    mask, _ = ground_mask(pts, method, thr, tol, float(max_slope), int(n_trials), check_random_state(random_state))
    return mask
