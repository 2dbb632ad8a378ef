"""Viewpoint Feature Histogram (VFH), Rusu, Bradski, Thibaux & Hsu (2010), as in PCL 1.13."""

import numbers

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from ..utils._chunks import transform_in_chunks
from ..preprocessing._normals import estimate_normals_batch
from ..utils._validation import check_n_jobs, check_point_clouds, pack_point_clouds
from ._vfh_fast import vfh_batch

__all__ = ["VFHTransformer"]

N_ANGLE_BINS = 45
N_VIEW_BINS = 128
N_FEATURES = 4 * N_ANGLE_BINS + N_VIEW_BINS
# Beyond this the centroid-to-viewpoint difference could overflow.
_MAX_COORD = 1e300


def _check_bool(value, name, owner):
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{owner}: {name} must be a bool, got {type(value).__name__}")
    return bool(value)


def _check_viewpoint(value, owner):
    try:
        v = np.asarray(value)
    except Exception:
        v = None
    if v is None or v.dtype == object or not (np.issubdtype(v.dtype, np.number) or v.dtype == bool):
        raise TypeError(f"{owner}: viewpoint must be an array-like of 3 numbers, got {type(value).__name__}")
    if np.iscomplexobj(v) or v.shape != (3,):
        raise ValueError(f"{owner}: viewpoint must have shape (3,), got shape {v.shape}")
    v = np.ascontiguousarray(v, dtype=np.float64)
    if not np.isfinite(v).all():
        raise ValueError(f"{owner}: viewpoint contains NaN or infinite values")
    if np.abs(v).max() > _MAX_COORD:
        raise ValueError(f"{owner}: viewpoint coordinates must be at most {_MAX_COORD:g} in magnitude, got {v}")
    return v


def _check_n_neighbors(value, owner):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{owner}: n_neighbors must be an int, got {type(value).__name__}")
    if value < 3:
        raise ValueError(f"{owner}: n_neighbors must be >= 3 (a plane needs three points), got {value}")
    return int(value)


def _points_and_normals(clouds, n_neighbors, orientation, n_threads, owner):
    """Pack validated clouds; estimate PCA normals for those given without."""
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


class VFHTransformer(TransformerMixin, BaseEstimator):
    """Viewpoint Feature Histogram (VFH) global descriptor.

    Pairs the centroid surflet (the centroid with the mean normal) with every
    point and histograms PCL's three angle features of the pair (45 bins
    each), optionally their distance (45 bins), and the angle between each
    normal and the direction from the centroid to the viewpoint (128 bins):
    308 values, PCL 1.13's ``VFHEstimation`` (``VFHSignature308``) step by
    step, including its scaling (see Notes).

    Read more in the paper of Rusu et al. (2010) and the paper's baseline
    section (Bobkov et al. 2018).

    Parameters
    ----------
    viewpoint : array-like of shape (3,), default=(0, 0, 0)
        The viewpoint (PCL's default: the origin), in the clouds' units.
        On clouds centred at the origin the direction to it is undefined;
        see ``pcl_homogeneous``.
    normalize_bins : bool, default=True
        Each angle-feature pair adds ``100 / (n - 1)`` and each viewpoint
        sample ``100 / n`` (PCL's default); False counts 1 for each.
    normalize_distances : bool, default=False
        With ``size_component``: the distance bin is
        ``floor(45 d / d_max)``; otherwise ``round(100 d)`` (in the clouds'
        units), both clipped to the 45 bins. PCL's default is False.
    size_component : bool, default=False
        Fill the distance histogram (bins 135-179); PCL's default leaves it
        zero.
    pcl_homogeneous : bool, default=True
        Reproduce PCL 1.13's arithmetic with the centroid as a homogeneous
        4-vector (w = 1): it normalises ``(v - c, -1)`` rather than ``v - c``
        and divides distances by ``sqrt(d_max^2 + 1)`` rather than ``d_max``.
        So the cosine of the viewpoint component is scaled by
        ``|v - c| / sqrt(|v - c|^2 + 1)``: on a centred cloud with the
        viewpoint at the origin all normals fall in bins 63-64, as in PCL's
        output. False gives the paper's unit direction and ``d_max``.
    pcl_centroid : bool, default=True
        For the viewpoint direction, compute the centroid as PCL does: the
        coordinates (and the viewpoint) rounded to single precision and
        summed in single precision. It matters only when the centroid is
        within rounding of the viewpoint, as for centred clouds viewed from
        the origin: PCL's rounding noise then decides between bins 63 and 64,
        and True reproduces PCL's rows exactly; False uses the
        double-precision centroid (such normals then all fall in bin 64).
        Clouds whose largest coordinate is outside ``[1e-30, 1e30]``, or
        viewpoints beyond ``1e30``, use the double centroid either way.
    n_neighbors : int, default=10
        Neighbourhood size for PCA normals of clouds given without normals
        (see :func:`eppf.estimate_normals`); six-column clouds use their own
        normals.
    normal_orientation : {"centroid", "origin"} or None, default="centroid"
        Sign of estimated normals: away from the object's centroid, towards
        the origin, or unoriented.
    n_jobs : int, default=None
        Number of OpenMP threads over objects, with joblib's meaning
        (``None``: OpenMP's default; ``-1``: all cores). The output does not
        depend on it.

    Attributes
    ----------
    n_features_out_ : int
        308.

    See Also
    --------
    OURCVFHTransformer : Clustered VFH with a semi-global reference frame.
    GASDTransformer : Globally aligned spatial distribution.

    Notes
    -----
    With the centroid :math:`c`, the mean normal :math:`\\bar n` (not
    normalised, as in PCL) and, for every point :math:`p` with normal
    :math:`n` and :math:`d = p - c \\neq 0`, PCL's pair features: the source
    is the surflet whose normal is more parallel to :math:`d`
    (:math:`|n \\cdot d| > |\\bar n \\cdot d|` makes :math:`(p, n)` the
    source and flips :math:`d`); with source normal :math:`u`, target
    normal :math:`t`, :math:`v = d \\times u / |d \\times u|` and
    :math:`w = u \\times v`:

    - :math:`f_1 = \\operatorname{atan2}(w \\cdot t, u \\cdot t)`,
    - :math:`f_2 = v \\cdot t`,
    - :math:`f_3 = u \\cdot d / |d|` (with the flipped :math:`d` after a
      swap, so :math:`-n \\cdot d / |d|` of the original),
    - :math:`f_4 = |d|`.

    Pairs with :math:`d = 0` or :math:`d \\times u = 0` are skipped (PCL's
    ``computePairFeatures`` fails on them). Each of :math:`f_1, f_2, f_3`
    goes to bin ``floor(45 (f + pi) / (2 pi))`` clipped to ``[0, 44]``, so
    the cosines :math:`f_2, f_3` only reach bins 15-29, as in PCL. The
    viewpoint bin of a normal is ``floor(128 (n . e + 1) / 2)`` clipped to
    ``[0, 127]``, with :math:`e` the direction from the centroid to the
    viewpoint (see ``pcl_homogeneous``).

    Layout (PCL's): bins 0-44 :math:`f_1`, 45-89 :math:`f_2`, 90-134
    :math:`f_3`, 135-179 :math:`f_4`, 180-307 the viewpoint component.
    With the defaults the three angle histograms sum to
    ``100 * n_valid / (n - 1)`` each and the viewpoint histogram to 100.

    The angle histograms are invariant to rotations and translations of the
    cloud (the centroid surflet moves with it); the viewpoint component
    varies with the cloud's pose relative to ``viewpoint`` (it is invariant
    only when the viewpoint moves with the cloud). All values are computed
    in double precision where PCL uses float, so a value within rounding of
    a bin edge may land one bin away from PCL's.

    References
    ----------
    .. [1] R. B. Rusu, G. Bradski, R. Thibaux and J. Hsu, "Fast 3D
       recognition and pose using the Viewpoint Feature Histogram", IROS
       2010.
    .. [2] R. B. Rusu and S. Cousins, "3D is here: Point Cloud Library
       (PCL)", ICRA 2011 (``pcl::VFHEstimation``).

    Examples
    --------
    >>> from eppf.datasets import make_shapes
    >>> from eppf.descriptors._vfh import VFHTransformer
    >>> data = make_shapes(2, n_points=256, random_state=0)
    >>> X = VFHTransformer().fit_transform(data.data)
    >>> X.shape
    (20, 308)
    >>> round(float(X[0, 180:].sum()), 6)
    100.0
    """

    def __init__(self, viewpoint=(0.0, 0.0, 0.0), normalize_bins=True, normalize_distances=False,
                 size_component=False, pcl_homogeneous=True, pcl_centroid=True, n_neighbors=10,
                 normal_orientation="centroid", n_jobs=None):
        self.viewpoint = viewpoint
        self.normalize_bins = normalize_bins
        self.normalize_distances = normalize_distances
        self.size_component = size_component
        self.pcl_homogeneous = pcl_homogeneous
        self.pcl_centroid = pcl_centroid
        self.n_neighbors = n_neighbors
        self.normal_orientation = normal_orientation
        self.n_jobs = n_jobs

    def _check_params(self):
        owner = type(self).__name__
        vp = _check_viewpoint(self.viewpoint, owner)
        flags = tuple(
            _check_bool(getattr(self, name), name, owner)
            for name in ("normalize_bins", "normalize_distances", "size_component", "pcl_homogeneous", "pcl_centroid")
        )
        k = _check_n_neighbors(self.n_neighbors, owner)
        if not (self.normal_orientation is None or (isinstance(self.normal_orientation, str)
                                                    and self.normal_orientation in ("centroid", "origin"))):
            raise ValueError(
                f"{owner}: normal_orientation must be 'centroid', 'origin' or None, got {self.normal_orientation!r}"
            )
        n_threads = check_n_jobs(self.n_jobs, owner=owner)
        return vp, flags, k, n_threads

    def _check_clouds(self, X, n_threads=1):
        owner = type(self).__name__
        clouds = check_point_clouds(X, owner=owner, min_points=2, n_threads=n_threads)
        for i, c in enumerate(clouds):
            big = np.abs(c[:, :3]).max()
            if big > _MAX_COORD:
                raise ValueError(
                    f"{owner}: point cloud {i} has coordinates of magnitude {big:g}; at most {_MAX_COORD:g} "
                    "are supported"
                )
            if c.shape[1] == 3 and c.shape[0] < 3:
                raise ValueError(
                    f"{owner}: point cloud {i} has {c.shape[0]} points and no normals; estimating normals "
                    "needs at least 3 points"
                )
        return clouds

    def fit(self, X, y=None):
        """Check the parameters and the clouds; VFH learns nothing from data.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 2 distinct points (3 without normals),
            normals in columns 3-5 when available.
        y : None
            Ignored.

        Returns
        -------
        self : VFHTransformer
            The fitted transformer.
        """
        self._check_params()
        self._check_clouds(X)
        self.n_features_out_ = N_FEATURES
        return self

    def transform(self, X):
        """Compute one VFH row per cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds; normals are estimated for clouds with three
            columns.

        Returns
        -------
        X_new : ndarray of shape (n_objects, 308)
            PCL-scaled histograms (see Notes).
        """
        check_is_fitted(self)
        *_, n_threads = self._check_params()
        clouds = self._check_clouds(X, n_threads)
        return transform_in_chunks(_vfh_chunk, self, clouds, n_features=N_FEATURES)

    def get_feature_names_out(self, input_features=None):
        """Names of the output columns: ``vfh_f1_<i>`` ... ``vfh_f4_<i>``, ``vfh_view_<i>``.

        Parameters
        ----------
        input_features : None
            Ignored (point clouds have no input feature names).

        Returns
        -------
        feature_names_out : ndarray of str
            In the output's order.
        """
        check_is_fitted(self)
        names = [f"vfh_{f}_{i}" for f in ("f1", "f2", "f3", "f4") for i in range(N_ANGLE_BINS)]
        names += [f"vfh_view_{i}" for i in range(N_VIEW_BINS)]
        return np.asarray(names, dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        return tags


def _vfh_chunk(est, clouds, first_index):
    """VFH rows of one chunk of validated clouds (a joblib task)."""
    owner = type(est).__name__
    vp, flags, k, n_threads = est._check_params()
    points, normals, offsets = _points_and_normals(clouds, k, est.normal_orientation, n_threads, owner)
    out = np.zeros((len(clouds), N_FEATURES), dtype=np.float64)
    n_threads = max(1, min(n_threads, len(clouds)))
    vfh_batch(points, normals, offsets, vp, *flags, out, n_threads)
    return out
