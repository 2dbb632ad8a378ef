"""Proportions of a point cloud: scale-invariant log ratios of its spreads and extents.

A side input for the EPPF classifiers: per-object scaling and rotation
invariance make the EPPF histogram blind to an object's proportions (a wide
dresser and a cube-like night stand), which these few numbers state directly.
"""

import numbers
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..utils._param_validation import Interval
from ..utils._cloud_stats import cloud_means, extreme_values
from ..utils._validation import check_n_jobs
from ._base import N_JOBS, PointCloudDescriptor

__all__ = ["ProportionTransformer"]

_NAMES = ("pca_mid_over_major", "pca_minor_over_major", "horizontal_minor_over_major", "up_over_horizontal",
          "extent_mid_over_major", "extent_minor_over_major")


def _log_ratio(a, b, tiny):
    return np.log((a + tiny) / (b + tiny))


def proportions(points, up_axis=2, coverage=0.96):
    """The six proportion features of one cloud (the reference implementation of the transformer).

    Parameters
    ----------
    points : ndarray of shape (n, 3), float64
        Finite coordinates.
    up_axis : int, default=2
        Index of the vertical axis.
    coverage : float, default=0.96
        Share of the points inside the robust extents (the central
        ``coverage`` along every principal axis).

    Returns
    -------
    features : ndarray of shape (6,)
        See :class:`ProportionTransformer`.
    """
    p = points - points.mean(axis=0)
    scale = float(np.abs(p).max()) if p.size else 0.0
    tiny = 1e-9 * scale + 1e-300
    cov = p.T @ p / max(len(p), 1)
    w, v = np.linalg.eigh(cov)
    w, v = np.maximum(w[::-1], 0.0), v[:, ::-1]
    s = np.sqrt(w)
    horiz = [a for a in range(3) if a != up_axis]
    h = np.sqrt(np.maximum(np.linalg.eigvalsh(cov[np.ix_(horiz, horiz)])[::-1], 0.0))
    up = float(np.sqrt(max(cov[up_axis, up_axis], 0.0)))
    q = p @ v
    lo = (1.0 - coverage) / 2.0
    ext = np.quantile(q, 1.0 - lo, axis=0) - np.quantile(q, lo, axis=0)
    return np.array([
        float(_log_ratio(s[1], s[0], tiny)), float(_log_ratio(s[2], s[0], tiny)), float(_log_ratio(h[1], h[0], tiny)),
        float(_log_ratio(up, h[0], tiny)), float(_log_ratio(ext[1], ext[0], tiny)),
        float(_log_ratio(ext[2], ext[0], tiny)),
    ])


def _proportions_stacked(P, up_axis, coverage):
    """:func:`proportions` of ``m`` clouds of ``n`` points each, ``P`` of shape (m, n, 3), in whole-array
    operations: every step is the reference's, taken along one more axis (the covariances and the
    projections by one matrix product per cloud, the eigen-decompositions by LAPACK cloud by cloud, the
    robust extents from one partition of the projections laid out point-last), so the rows are bit for
    bit the reference's (a test checks it), at a fraction of its cost per object."""
    m, n, _ = P.shape
    P = np.ascontiguousarray(P, dtype=np.float64)
    # (the centroids NumPy's P.mean(axis=1) gives, without its slow strided reduction)
    p = P - cloud_means(P.reshape(m * n, 3), np.arange(0, m * n + 1, n, dtype=np.int64))[:, None, :]
    tiny = 1e-9 * np.abs(p).max(axis=(1, 2)) + 1e-300
    cov = np.matmul(p.transpose(0, 2, 1), p) / max(n, 1)
    w, v = np.linalg.eigh(cov)
    w, v = np.maximum(w[:, ::-1], 0.0), v[:, :, ::-1]
    s = np.sqrt(w)
    horiz = [a for a in range(3) if a != up_axis]
    h = np.sqrt(np.maximum(np.linalg.eigvalsh(cov[:, horiz][:, :, horiz])[:, ::-1], 0.0))
    up = np.sqrt(np.maximum(cov[:, up_axis, up_axis], 0.0))
    q = np.ascontiguousarray(np.matmul(p, v).transpose(0, 2, 1))
    lo = (1.0 - coverage) / 2.0
    bounds = _quantiles(q.reshape(m * 3, n), [lo, 1.0 - lo]).reshape(2, m, 3)
    ext = bounds[1] - bounds[0]
    return np.stack([
        _log_ratio(s[:, 1], s[:, 0], tiny), _log_ratio(s[:, 2], s[:, 0], tiny), _log_ratio(h[:, 1], h[:, 0], tiny),
        _log_ratio(up, h[:, 0], tiny), _log_ratio(ext[:, 1], ext[:, 0], tiny), _log_ratio(ext[:, 2], ext[:, 0], tiny),
    ], axis=1)


#: Most order statistics :func:`_quantiles` takes from each end of a row by
#: :func:`eppf.utils._cloud_stats.extreme_values` (a one-pass insertion list);
#: quantiles farther from 0 and 1 go through :func:`numpy.quantile`.
_MAX_EXTREMES = 64


def _quantiles(rows, quantiles):
    """``np.quantile(rows, quantiles, axis=1)`` (its default "linear" method), bit for bit.

    Quantiles near 0 and 1 (the robust extents' 2% and 98%) read their two
    neighboring order statistics from :func:`extreme_values` instead of
    partitioning every row, and interpolate between them as NumPy's
    ``_lerp`` does: the virtual index ``(n - 1) q``, its floor ``i`` and
    fraction ``g``, then ``a + (b - a) g``, or ``b - (b - a) (1 - g)`` for
    ``g >= 0.5``, with ``a``, ``b`` the values at sorted positions ``i``
    and ``i + 1`` (a test compares the two on many rows).
    """
    n = rows.shape[1]
    q = np.asarray(quantiles, dtype=np.float64)
    virtual = (n - 1) * q
    below = np.floor(virtual)
    # sorted positions of the values on both sides, counted from the nearer end
    first = np.minimum(below.astype(np.intp), n - 1)
    second = np.minimum(first + 1, n - 1)
    depth = np.maximum(np.minimum(first, n - 1 - second), 0)
    if n < 2 or depth.max() + 2 > min(_MAX_EXTREMES, n) or not (q >= 0).all() or not (q <= 1).all():
        return np.quantile(rows, quantiles, axis=1)
    low, high = extreme_values(rows, int(depth.max()) + 2)

    def at(position):  # the values at sorted position ``position`` of every row
        return low[:, position] if position < low.shape[1] else high[:, n - 1 - position]

    out = np.empty((len(q), rows.shape[0]))
    for j in range(len(q)):
        if virtual[j] >= n - 1:  # (NumPy takes the last value there)
            out[j] = at(n - 1)
            continue
        a, b = at(int(first[j])), at(int(second[j]))
        gamma = virtual[j] - below[j]
        diff = b - a
        out[j] = a + diff * gamma
        if gamma >= 0.5:
            out[j] = b - diff * (1 - gamma)
    return out


#: The fewest clouds a thread of :class:`ProportionTransformer` takes (fewer are not worth a thread).
_MIN_PER_THREAD = 16


def _proportions_packed(points, offsets, up_axis, coverage):
    """The rows of packed clouds (object ``k`` is ``points[offsets[k]:offsets[k + 1]]``): clouds of one
    size together through :func:`_proportions_stacked`, a cloud of a size of its own through
    :func:`proportions`."""
    sizes = np.diff(offsets)
    if len(sizes) > 1 and (sizes == sizes[0]).all():  # one size (resampled data): a view, no gathering
        return _proportions_stacked(points[offsets[0]:offsets[-1]].reshape(len(sizes), sizes[0], 3), up_axis,
                                    coverage)
    out = np.empty((len(sizes), len(_NAMES)))
    for size in np.unique(sizes):
        members = np.flatnonzero(sizes == size)
        if len(members) == 1:
            k = members[0]
            out[k] = proportions(points[offsets[k]:offsets[k + 1]], up_axis, coverage)
            continue
        rows = offsets[members][:, None] + np.arange(size)
        out[members] = _proportions_stacked(points[rows], up_axis, coverage)
    return out


class ProportionTransformer(PointCloudDescriptor):
    """Six scale-invariant proportions of every point cloud, as log ratios.

    From the centered points: the principal spreads ``s1 >= s2 >= s3`` (square
    roots of the covariance's eigenvalues), the horizontal spreads ``h1 >=
    h2`` (the same in the plane orthogonal to ``up_axis``), the vertical
    spread ``u`` and the robust extents ``e1, e2, e3`` along the principal
    axes (the range of the central ``coverage`` of the points on each). The
    row is ``log(s2/s1), log(s3/s1), log(h2/h1), log(u/h1), log(e2/e1),
    log(e3/e1)``: invariant to scale and translation, to rotations about the
    up axis, and (except the two upright terms) to any rotation. A tiny
    floor relative to the cloud's size keeps degenerate clouds (a line, a
    plane) finite; a cloud needs two distinct points.

    Parameters
    ----------
    up_axis : {0, 1, 2}, default=2
        Coordinate axis that points up (z for ModelNet and most scans).
    coverage : float, default=0.96
        Share of the points inside the robust extents, in (0, 1].
    n_jobs : int, default=None
        Threads (joblib's meaning) over which a call's clouds are split, at
        least 16 clouds a thread (NumPy's partitions and eigen solves
        release the GIL); results do not depend on it.

    Attributes
    ----------
    n_features_out_ : int
        6.

    See Also
    --------
    eppf.descriptors.DescriptorUnion : Joins these to EPPF as side features.
    eppf.classifiers.EPPF4DClassifier : Reads them through ``n_side_features``.

    Notes
    -----
    Meant as a side input, not a descriptor on its own (six numbers tell
    few classes apart by themselves: :ref:`api-figures-side-features`), but
    they add to EPPF what the classifier confuses most (dresser and night
    stand, table and desk: classes told apart by proportions).

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.descriptors import ProportionTransformer
    >>> box = np.random.RandomState(0).uniform(size=(500, 3)) * [4.0, 2.0, 1.0]
    >>> row = ProportionTransformer().fit_transform([box])[0]
    >>> np.round(np.exp(row[:2]), 1)  # spreads about 2 : 1 and 1 : 4 of the longest
    array([0.5, 0.2])
    """

    _parameter_constraints = {
        "up_axis": [Interval(numbers.Integral, 0, 2, closed="both")],
        "coverage": [Interval(numbers.Real, 0, 1, closed="right")],
        "n_jobs": N_JOBS,
    }
    _min_points = 2

    def __init__(self, up_axis=2, coverage=0.96, n_jobs=None):
        self.up_axis = up_axis
        self.coverage = coverage
        self.n_jobs = n_jobs

    def _resolve_params(self):
        return int(self.up_axis), float(self.coverage)

    def _n_features(self, params):
        return len(_NAMES)

    def _feature_names(self):
        return list(_NAMES)

    def _describe(self, clouds, params, *per_object, first_index):
        up_axis, coverage = params
        points, offsets = clouds.points, clouds.offsets
        n_threads = min(check_n_jobs(self.n_jobs, owner=type(self).__name__), len(offsets) // _MIN_PER_THREAD)
        if n_threads <= 1:
            return _proportions_packed(points, offsets, up_axis, coverage)
        # contiguous runs of clouds, one a thread: every row is computed as in one call, so the same bits
        bounds = np.linspace(0, len(offsets) - 1, n_threads + 1).astype(np.intp)
        with ThreadPoolExecutor(n_threads) as pool:
            parts = pool.map(lambda lo, hi: _proportions_packed(points, offsets[lo:hi + 1], up_axis, coverage),
                             bounds[:-1], bounds[1:])
            return np.concatenate(list(parts))
