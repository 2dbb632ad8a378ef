"""Surflet-pair-relation histograms, Wahl, Hillenbrand & Hirzinger (2003)."""

import numbers

import numpy as np

from ..utils import check_n_jobs
from ..utils._param_validation import Interval, IntTuple, StrOptions
from ._base import N_JOBS, N_NEIGHBORS, NORMAL_ORIENTATION, RANDOM_STATE, PointCloudDescriptor
from ._wahl_fast import wahl_batch

__all__ = ["WahlTransformer"]

_NAMES = ("alpha", "beta", "gamma", "delta")


class WahlTransformer(PointCloudDescriptor):
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
        Neighborhood size for PCA normals of clouds given without normals
        (see :func:`eppf.preprocessing.estimate_normals`); clouds with six columns use
        their own normals.
    normal_orientation : {"centroid", "origin"} or None, default="centroid"
        Sign of estimated normals: away from the object's centroid, towards
        the origin (a sensor there), or unoriented (as in
        :class:`eppf.descriptors.EPPFTransformer`).
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

    _parameter_constraints = {
        "n_bins": [
            Interval(numbers.Integral, 1, 1024, closed="both"),
            IntTuple(4, 1, 1024, max_product=2**26,
                     description="a tuple of 4 ints in [1, 1024] (alpha, beta, gamma, delta; at most 2**26 bins in all)"),
        ],
        "n_pairs": [Interval(numbers.Integral, 1, 2**31 - 1, closed="both")],
        "source": [StrOptions(["perpendicular", "parallel"])],
        "n_neighbors": N_NEIGHBORS,
        "normal_orientation": NORMAL_ORIENTATION,
        "random_state": RANDOM_STATE,
        "n_jobs": N_JOBS,
    }

    def _resolve_params(self):
        n_bins = self.n_bins
        n_bins = (int(n_bins),) * 4 if isinstance(n_bins, numbers.Integral) else tuple(int(b) for b in n_bins)
        n_threads = check_n_jobs(self.n_jobs, owner=type(self).__name__)
        return n_bins, int(self.n_pairs), int(self.n_neighbors), n_threads

    def _learn(self, clouds, params):
        self.n_bins_ = params[0]

    def _n_features(self, params):
        return int(np.prod(params[0]))

    def _feature_names(self):
        idx = np.indices(self.n_bins_).reshape(4, -1).T
        return [f"wahl_a{a}_b{b}_g{g}_d{d}" for a, b, g, d in idx]

    def _describe(self, clouds, params, seeds, *, first_index):
        """Wahl histograms of one chunk of packed clouds."""
        n_bins, n_pairs, n_neighbors, n_threads = params
        points, normals, offsets = self._points_and_normals(clouds, n_neighbors, self.normal_orientation, n_threads)
        out = np.zeros((len(clouds), int(np.prod(n_bins))), dtype=np.float64)
        status = np.zeros(len(clouds), dtype=np.int8)
        n_threads = max(1, min(n_threads, len(clouds)))
        wahl_batch(
            points, normals, offsets, seeds, n_pairs, np.asarray(n_bins, dtype=np.int32),
            self.source == "parallel", out, status, n_threads,
        )
        self._raise_for_status(status, first_index, {
            1: "has too few usable surflet pairs (coincident points, or every normal parallel to the lines "
               "between points)"})
        return out
