"""Surflet-pair-relation histograms, Wahl, Hillenbrand & Hirzinger (2003)."""

import numbers

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from ._baselines import wahl_batch
from ._esf import _check_int
from ._chunks import transform_in_chunks
from ._validation import check_n_jobs, check_point_clouds, condition_point_clouds, object_seeds, pack_point_clouds

__all__ = ["WahlTransformer"]

_NAMES = ("alpha", "beta", "gamma", "delta")


def _points_and_normals(clouds, n_neighbors, orientation, n_threads, owner):
    """Pack validated clouds; estimate normals for those given without.

    Returns ``points`` (N, 3), ``normals`` (N, 3) and ``offsets``.
    """
    from ._normals import estimate_normals_batch

    points, _, offsets = pack_point_clouds([c[:, :3] for c in clouds])
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
    return points, normals, offsets


def _check_n_bins(n_bins, owner):
    if isinstance(n_bins, numbers.Integral) and not isinstance(n_bins, bool):
        n_bins = (n_bins,) * 4
    try:
        bins = tuple(n_bins)
    except TypeError:
        raise TypeError(f"{owner}: n_bins must be an int or a sequence of 4 ints, got {type(n_bins).__name__}") from None
    if len(bins) != 4:
        raise ValueError(f"{owner}: n_bins must have 4 entries (alpha, beta, gamma, delta), got {len(bins)}")
    out = tuple(_check_int(b, "each entry of n_bins", owner, 1, 1024) for b in bins)
    if np.prod(out, dtype=np.int64) > 2**26:
        raise ValueError(f"{owner}: n_bins {out} gives more than 2**26 bins")
    return out


class WahlTransformer(TransformerMixin, BaseEstimator):
    """Surflet-pair-relation histogram of Wahl et al. (2003).

    Draws random pairs of oriented points (surflets) and histograms their
    four pose-invariant relations (alpha, beta, gamma, delta) jointly:
    ``5**4 = 625`` bins by default, summing to one.

    Read more in the paper's baseline section (Bobkov et al. 2018, Table II).

    Parameters
    ----------
    n_bins : int or tuple of 4 int, default=5
        Bins of (alpha, beta, gamma, delta); an int applies to all four (the
        EPPF authors also used ``6`` for their CNN).
    n_pairs : int, default=20000
        Ordered pairs of distinct points drawn per object, as for EPPF.
    source : {"perpendicular", "parallel"}, default="perpendicular"
        Which point of a pair is the source: the one whose normal is more
        perpendicular to the connecting line (smaller ``|n . d|``, our reading
        of Wahl et al.), or the more parallel one (PCL's PFH rule).
    n_neighbors : int, default=10
        Neighbourhood size for PCA normals of clouds given without normals
        (see :func:`eppf.estimate_normals`); clouds with six columns use
        their own normals.
    normal_orientation : {"centroid", "origin"} or None, default="centroid"
        Sign of estimated normals: away from the object's centroid, towards
        the origin (a sensor there), or unoriented (as in
        :class:`eppf.EPPFTransformer`).
    random_state : int, RandomState instance or None, default=None
        Draws one seed per object; each object's pairs come from a private
        generator seeded with it, so the output does not depend on ``n_jobs``.
    n_jobs : int, default=None
        Number of OpenMP threads over objects, with joblib's meaning.

    Attributes
    ----------
    n_bins_ : tuple of 4 int
        Resolved bin counts.
    n_features_out_ : int
        Length of each descriptor, ``prod(n_bins_)``.

    See Also
    --------
    ESFTransformer : Ensemble of shape functions (no normals needed).
    OURCVFHTransformer : Viewpoint-feature histogram with a semi-global frame.

    Notes
    -----
    For a pair with source ``(p_s, n_s)`` and target ``(p_t, n_t)``,
    ``d = p_t - p_s``, the Darboux frame ``u = n_s``,
    ``v = d x u / |d x u|``, ``w = u x v`` gives

    - ``alpha = atan2(w . n_t, u . n_t)`` on ``[-pi, pi]``,
    - ``beta = v . n_t`` on ``[-1, 1]``,
    - ``gamma = u . d / |d|`` on ``[-1, 1]``,
    - ``delta = |d| / max |d|`` on ``[0, 1]``, the maximum over the object's
      sampled pairs (scale invariance).

    Each value is binned as ``clip(floor(N (v - lo) / (hi - lo)), 0, N - 1)``.
    Pairs whose source normal is parallel to ``d`` (the frame is undefined)
    are redrawn. Layout: C order over (alpha, beta, gamma, delta), delta
    fastest. The descriptor is invariant to rotation and translation (up to
    normal estimation) and to uniform scaling.

    References
    ----------
    .. [1] E. Wahl, U. Hillenbrand and G. Hirzinger, "Surflet-pair-relation
       histograms: a statistical 3D-shape representation for rapid
       classification", 3DIM 2003.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import WahlTransformer
    >>> rng = np.random.default_rng(0)
    >>> sphere = rng.normal(size=(300, 3))
    >>> sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    >>> cloud = np.hstack([sphere, sphere])  # points and their normals
    >>> X = WahlTransformer(n_pairs=5000, random_state=0).fit_transform([cloud])
    >>> X.shape
    (1, 625)
    """

    def __init__(
        self,
        n_bins=5,
        n_pairs=20000,
        source="perpendicular",
        n_neighbors=10,
        normal_orientation="centroid",
        random_state=None,
        n_jobs=None,
    ):
        self.n_bins = n_bins
        self.n_pairs = n_pairs
        self.source = source
        self.n_neighbors = n_neighbors
        self.normal_orientation = normal_orientation
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _check_params(self):
        owner = type(self).__name__
        n_bins = _check_n_bins(self.n_bins, owner)
        n_pairs = _check_int(self.n_pairs, "n_pairs", owner, 1, 2**31 - 1)
        if self.source not in ("perpendicular", "parallel"):
            raise ValueError(f"{owner}: source must be 'perpendicular' or 'parallel', got {self.source!r}")
        n_neighbors = _check_int(self.n_neighbors, "n_neighbors", owner, 3)
        if self.normal_orientation not in ("centroid", "origin", None):
            raise ValueError(
                f"{owner}: normal_orientation must be 'centroid', 'origin' or None, got {self.normal_orientation!r}"
            )
        n_threads = check_n_jobs(self.n_jobs, owner=owner)
        return n_bins, n_pairs, n_neighbors, n_threads

    def fit(self, X, y=None):
        """Check the parameters and the clouds; nothing is learnt from data.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 2 points, with normals in columns 3-5
            when available.
        y : None
            Ignored.

        Returns
        -------
        self : WahlTransformer
            The fitted transformer.
        """
        n_bins, _, _, _ = self._check_params()
        check_point_clouds(X, owner=type(self).__name__, min_points=2)
        self.n_bins_ = n_bins
        self.n_features_out_ = int(np.prod(n_bins))
        return self

    def transform(self, X):
        """Compute one surflet-pair-relation histogram per cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 2 points; normals are estimated for
            clouds with three columns.

        Returns
        -------
        X_new : ndarray of shape (n_objects, prod(n_bins))
            Histograms, each summing to one.
        """
        check_is_fitted(self)
        owner = type(self).__name__
        n_bins, n_pairs, n_neighbors, n_threads = self._check_params()
        clouds = check_point_clouds(X, owner=owner, min_points=2, n_threads=n_threads)
        condition_point_clouds(clouds, owner=owner)  # exact 2**e rescaling: the histogram is scale-invariant
        seeds = object_seeds(self.random_state, len(clouds))
        return transform_in_chunks(_wahl_chunk, self, clouds, (seeds,), n_features=int(np.prod(n_bins)))

    def get_feature_names_out(self, input_features=None):
        """Names of the output columns, e.g. ``wahl_a0_b1_g2_d3``.

        Parameters
        ----------
        input_features : None
            Ignored (point clouds have no input feature names).

        Returns
        -------
        feature_names_out : ndarray of str
            One name per bin, in the output's (C) order.
        """
        check_is_fitted(self)
        idx = np.indices(self.n_bins_).reshape(4, -1).T
        return np.asarray([f"wahl_a{a}_b{b}_g{g}_d{d}" for a, b, g, d in idx], dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        tags.non_deterministic = self.random_state is None
        return tags


def _wahl_chunk(est, clouds, seeds, first_index):
    """Wahl histograms of one chunk of validated clouds (a joblib task)."""
    owner = type(est).__name__
    n_bins, n_pairs, n_neighbors, n_threads = est._check_params()
    points, normals, offsets = _points_and_normals(clouds, n_neighbors, est.normal_orientation, n_threads, owner)
    out = np.zeros((len(clouds), int(np.prod(n_bins))), dtype=np.float64)
    status = np.zeros(len(clouds), dtype=np.int8)
    n_threads = max(1, min(n_threads, len(clouds)))
    wahl_batch(
        points, normals, offsets, seeds, n_pairs, np.asarray(n_bins, dtype=np.int32),
        est.source == "parallel", out, status, n_threads,
    )
    bad = np.flatnonzero(status)
    if bad.size:
        raise ValueError(
            f"{owner}: point cloud {first_index + bad[0]} has too few usable surflet pairs (coincident points, "
            "or every normal parallel to the lines between points)"
        )
    return out
