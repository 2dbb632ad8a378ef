"""From a scene to its objects: ground removal, then clustering or a field's segments."""

import numpy as np
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils import check_random_state

from ._checks import TOLERANCE, check_field, check_scene, check_tolerance
from ._cluster import (
    MAX_POINTS, MIN_POINTS, check_sizes, cluster_roots, default_tolerance, number_segments, split_field,
)
from ._ground import ground_mask
from ..utils._param_validation import RANDOM_STATE, Options, StrOptions, validate_parameter

__all__ = ["SceneSegmenter", "segment_scene"]

GROUND = ("auto", "plane", "grid", "none")
#: Smallest segment kept by default: smaller clusters are noise or bits of ground.
DEFAULT_MIN_POINTS = 30
#: RANSAC's settings for the ground plane of a scene (its seed is ``random_state``).
_N_TRIALS, _MAX_SLOPE = 100, 0.3


def _segment(points, fields, by, ground, tolerance, min_points, max_points, random_state, owner):
    """(labels, ground mask, tolerance, ground method used) of a scene; parameters already validated."""
    pts = check_scene(points, owner)
    min_points, max_points = check_sizes(min_points, max_points, owner)
    field = None
    if by is not None:
        if fields is None:
            raise ValueError(f"{owner}: by={by!r} names a field, but no fields were given")
        if not hasattr(fields, "keys"):
            raise TypeError(f"{owner}: fields must be a dict of per-point arrays, got {type(fields).__name__}")
        if by not in fields:
            raise ValueError(f"{owner}: by={by!r} is not a field of the scene; its fields are {sorted(fields)}")
        field = check_field(fields[by], len(pts), owner, name=f"field {by!r}")
    tol = check_tolerance(tolerance, owner)
    if tol is None and (by is None or ground not in ("none", "auto")):
        tol = default_tolerance(pts, owner)
    method = "none" if ground == "none" or (ground == "auto" and by is not None) else ground
    if method == "none":
        mask = np.zeros(len(pts), dtype=bool)
    else:
        mask, method = ground_mask(pts, method, None, tol, _MAX_SLOPE, _N_TRIALS, check_random_state(random_state))
    keep = np.flatnonzero(~mask)
    labels = np.full(len(pts), -1, dtype=np.int64)
    if keep.size:
        if field is not None:
            labels[keep] = split_field(field[keep], min_points, max_points)
        else:
            labels[keep] = number_segments(cluster_roots(pts[keep], tol, owner), min_points, max_points)
    return labels, mask, tol, method


def segment_scene(points, fields=None, *, by=None, ground="auto", tolerance=None, min_points=DEFAULT_MIN_POINTS,
                  max_points=None, random_state=0):
    """Split a scene into objects: remove the ground, then cluster (or split by a field).

    PCL's recipe for a scene of objects standing on a floor or on terrain
    (its cluster-recognition tutorial): remove the ground, then
    :func:`euclidean_clusters` on the remaining points. When the file already
    tells objects apart (a field ``instance``, ``label``, ``classification``
    ...), ``by`` takes the segments from that field instead.

    Parameters
    ----------
    points : array-like of shape (n_points, 3) or (n_points, 6)
        The scene (normals, when given, are ignored); at least two points,
        all finite.
    fields : dict of str to array-like of shape (n_points,), default=None
        Per-point fields of the scene, as ``eppf.io.read_point_fields``
        returns them; only needed with ``by``.
    by : str, default=None
        Name of an integer field of ``fields`` to split by: one segment per
        value (see :func:`split_by_field`). None clusters the points.
    ground : {"auto", "plane", "grid", "none"}, default="auto"
        The ground model of :func:`remove_ground` (ground points get label -1
        and are not clustered), or "none" to keep every point. With ``by``,
        "auto" removes no ground (the field tells objects apart).
    tolerance : float, default=None
        Clustering distance, at least 1e-150, in the units of the points
        (meters for LiDAR), also the scale of the ground model (RANSAC's
        inlier distance, the grid's cell; see :func:`remove_ground` with
        ``threshold=None``). None derives it from the point spacing (five
        times the median nearest-neighbor distance), which suits LiDAR in
        meters and CAD-scale scenes alike.
    min_points : int, default=30
        Smallest kept segment; smaller ones (noise, bits of ground) get -1.
    max_points : int, default=None
        Largest kept segment; None keeps segments of any size.
    random_state : int, RandomState instance or None, default=0
        Seed of RANSAC's trials for a ground plane (``ground`` "plane", or
        "auto" where it tries the plane); the default gives the same labels
        on every call.

    Returns
    -------
    labels : ndarray of shape (n_points,), dtype int64
        The segment of each point, -1 for ground and for points in no kept
        segment. Segments are numbered 0, 1, ...: clusters by size, largest
        first, ties by smallest point index; a field's segments in increasing
        order of its value. The same scene and ``random_state`` (an int) give
        the same labels on every call.

    Raises
    ------
    ValueError
        If the points are not of shape (n, 3) or (n, 6), hold NaN or infinite
        values, are fewer than two or all identical, span more than 1e100 or
        (along their longest axis) less than 1e-100, the derived tolerance is
        below 1e-150, ``by`` names no field,
        the field has the wrong length, or a parameter is out of range.
    TypeError
        If the points are not numbers, the field is not an integer field, or
        a parameter has a wrong type.

    See Also
    --------
    SceneSegmenter : The same as an estimator, with the ground mask and tolerance used.
    remove_ground : The ground models.
    euclidean_clusters : The clustering.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.segmentation import segment_scene
    >>> rng = np.random.default_rng(0)
    >>> floor = np.column_stack([rng.uniform(0, 10, (4000, 2)), np.zeros(4000)])
    >>> box_a = rng.uniform([2, 2, 1.0], [3, 3, 2.0], size=(500, 3))
    >>> box_b = rng.uniform([7, 7, 1.0], [8, 8, 1.7], size=(400, 3))
    >>> labels = segment_scene(np.vstack([floor, box_a, box_b]))
    >>> [int(np.sum(labels == k)) for k in range(labels.max() + 1)]
    [500, 400]
    """
    owner = "segment_scene"
    return SceneSegmenter(by=by, ground=ground, tolerance=tolerance, min_points=min_points,
                          max_points=max_points, random_state=random_state)._fit(points, fields, owner).labels_


class SceneSegmenter(ClusterMixin, BaseEstimator):
    """Split a scene into objects: remove the ground, then cluster (or split by a field).

    The estimator form of :func:`segment_scene`: ``fit`` segments one scene
    and keeps the labels, the ground mask and the tolerance it used.

    Parameters
    ----------
    by : str, default=None
        Name of an integer field (passed to ``fit`` as ``fields``) to split
        by: one segment per value. None clusters the points.
    ground : {"auto", "plane", "grid", "none"}, default="auto"
        The ground model of :func:`remove_ground`, or "none" to keep every
        point. With ``by``, "auto" removes no ground.
    tolerance : float, default=None
        Clustering distance and scale of the ground model, at least 1e-150,
        in the units of the points; None derives it from the point spacing.
    min_points : int, default=30
        Smallest kept segment (>= 1).
    max_points : int, default=None
        Largest kept segment; None keeps segments of any size.
    random_state : int, RandomState instance or None, default=0
        Seed of RANSAC's trials for a ground plane; the default gives the
        same segments on every fit.

    Attributes
    ----------
    labels_ : ndarray of shape (n_points,), dtype int64
        The segment of each point of the scene, -1 for ground and unassigned
        points; segments numbered as in :func:`segment_scene`.
    ground_mask_ : ndarray of shape (n_points,), dtype bool
        True for the points taken for ground.
    ground_method_ : {"plane", "grid", "none"}
        The ground model used ("auto" resolved).
    tolerance_ : float or None
        The clustering distance used (given or derived); None when no
        distance was needed (a split by a field without ground removal).
    n_segments_ : int
        Number of segments (``labels_.max() + 1``).

    See Also
    --------
    segment_scene : The function form.
    euclidean_clusters : The clustering alone.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.segmentation import SceneSegmenter
    >>> rng = np.random.default_rng(0)
    >>> floor = np.column_stack([rng.uniform(0, 10, (4000, 2)), np.zeros(4000)])
    >>> box = rng.uniform([2, 2, 1.0], [3, 3, 2.0], size=(500, 3))
    >>> seg = SceneSegmenter().fit(np.vstack([floor, box]))
    >>> seg.n_segments_, int(seg.ground_mask_.sum()), seg.ground_method_
    (1, 4000, 'plane')
    """

    _parameter_constraints = {
        "by": [None, Options(str)],
        "ground": [StrOptions(GROUND)],
        "tolerance": TOLERANCE,
        "min_points": MIN_POINTS,
        "max_points": MAX_POINTS,
        "random_state": RANDOM_STATE,
    }

    def __init__(self, *, by=None, ground="auto", tolerance=None, min_points=DEFAULT_MIN_POINTS, max_points=None,
                 random_state=0):
        self.by = by
        self.ground = ground
        self.tolerance = tolerance
        self.min_points = min_points
        self.max_points = max_points
        self.random_state = random_state

    def _fit(self, points, fields, owner):
        for name, value in self.get_params(deep=False).items():
            validate_parameter(value, self._parameter_constraints[name], name=name, owner=owner)
        labels, mask, tol, method = _segment(points, fields, self.by, self.ground, self.tolerance, self.min_points,
                                             self.max_points, self.random_state, owner)
        self.labels_ = labels
        self.ground_mask_ = mask
        self.ground_method_ = method
        self.tolerance_ = tol
        self.n_segments_ = int(labels.max()) + 1 if labels.size else 0
        return self

    def fit(self, X, y=None, *, fields=None):
        """Segment a scene.

        Parameters
        ----------
        X : array-like of shape (n_points, 3) or (n_points, 6)
            The scene's points (normals, when given, are ignored).
        y : None
            Ignored.
        fields : dict of str to array-like of shape (n_points,), default=None
            Per-point fields of the scene; needed when ``by`` is set.

        Returns
        -------
        self : SceneSegmenter
            The fitted segmenter.
        """
        return self._fit(X, fields, type(self).__name__)

    def fit_predict(self, X, y=None, *, fields=None):
        """Segment a scene and return the segment of each point.

        Parameters
        ----------
        X : array-like of shape (n_points, 3) or (n_points, 6)
            The scene's points (normals, when given, are ignored).
        y : None
            Ignored.
        fields : dict of str to array-like of shape (n_points,), default=None
            Per-point fields of the scene; needed when ``by`` is set.

        Returns
        -------
        labels : ndarray of shape (n_points,), dtype int64
            ``labels_``: the segment of each point, -1 for ground and unassigned points.
        """
        return self.fit(X, fields=fields).labels_

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags
