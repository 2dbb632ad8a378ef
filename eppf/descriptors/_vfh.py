"""Viewpoint Feature Histogram (VFH), Rusu, Bradski, Thibaux & Hsu (2010), as in PCL 1.13."""


import numpy as np

from ..utils import check_n_jobs
from ..utils._param_validation import Options, Satisfies
from ._base import N_JOBS, N_NEIGHBORS, NORMAL_ORIENTATION, PointCloudDescriptor, as_vector3
from ._vfh_fast import vfh_batch

__all__ = ["VFHTransformer"]

N_ANGLE_BINS = 45
N_VIEW_BINS = 128
N_FEATURES = 4 * N_ANGLE_BINS + N_VIEW_BINS
# Beyond this the centroid-to-viewpoint difference could overflow.
_MAX_COORD = 1e300
_FLAGS = ("normalize_bins", "normalize_distances", "size_component", "pcl_homogeneous", "pcl_centroid")


def _is_viewpoint(value):
    v = as_vector3(value)
    return v is not None and np.abs(v).max() <= _MAX_COORD


class VFHTransformer(PointCloudDescriptor):
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
        On clouds centered at the origin the direction to it is undefined;
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
        4-vector (w = 1): it normalizes ``(v - c, -1)`` rather than ``v - c``
        and divides distances by ``sqrt(d_max^2 + 1)`` rather than ``d_max``.
        So the cosine of the viewpoint component is scaled by
        ``|v - c| / sqrt(|v - c|^2 + 1)``: on a centered cloud with the
        viewpoint at the origin all normals fall in bins 63-64, as in PCL's
        output. False gives the paper's unit direction and ``d_max``.
    pcl_centroid : bool, default=True
        For the viewpoint direction, compute the centroid as PCL does: the
        coordinates (and the viewpoint) rounded to single precision and
        summed in single precision. It matters only when the centroid is
        within rounding of the viewpoint, as for centered clouds viewed from
        the origin: PCL's rounding noise then decides between bins 63 and 64,
        and True reproduces PCL's rows exactly; False uses the
        double-precision centroid (such normals then all fall in bin 64).
        Clouds whose largest coordinate is outside ``[1e-30, 1e30]``, or
        viewpoints beyond ``1e30``, use the double centroid either way.
    n_neighbors : int, default=10
        Neighborhood size for PCA normals of clouds given without normals
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
    normalized, as in PCL) and, for every point :math:`p` with normal
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
    >>> from eppf.descriptors import VFHTransformer
    >>> data = make_shapes(2, n_points=256, random_state=0)
    >>> X = VFHTransformer().fit_transform(data.data)
    >>> X.shape
    (20, 308)
    >>> round(float(X[0, 180:].sum()), 6)
    100.0
    """

    # magnitudes are brought into range by the kernel itself (exact powers of two)
    _conditioning = "none"

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

    _parameter_constraints = {
        "viewpoint": [Satisfies(_is_viewpoint, f"an array-like of 3 finite numbers of magnitude at most {_MAX_COORD:g}")],
        **{name: [Options(bool)] for name in _FLAGS},
        "n_neighbors": N_NEIGHBORS,
        "normal_orientation": NORMAL_ORIENTATION,
        "n_jobs": N_JOBS,
    }

    def _resolve_params(self):
        flags = tuple(bool(getattr(self, name)) for name in _FLAGS)
        n_threads = check_n_jobs(self.n_jobs, owner=type(self).__name__)
        return as_vector3(self.viewpoint), flags, int(self.n_neighbors), n_threads

    def _validate_clouds(self, X, n_threads=1):
        owner = type(self).__name__
        clouds, extras = super()._validate_clouds(X, n_threads)
        big = np.maximum(np.abs(clouds.lower), np.abs(clouds.upper)).max(axis=1)
        sizes = clouds.sizes
        bad = np.flatnonzero((big > _MAX_COORD) | (~clouds.has_normals & (sizes < 3)))
        if bad.size:
            i = int(bad[0])
            if big[i] > _MAX_COORD:
                raise ValueError(
                    f"{owner}: point cloud {i} has coordinates of magnitude {big[i]:g}; at most {_MAX_COORD:g} "
                    "are supported"
                )
            raise ValueError(
                f"{owner}: point cloud {i} has {sizes[i]} points and no normals; estimating normals "
                "needs at least 3 points"
            )
        return clouds, extras

    def _n_features(self, params):
        return N_FEATURES

    def _feature_names(self):
        """``vfh_f1_<i>`` ... ``vfh_f4_<i>``, ``vfh_view_<i>``."""
        names = [f"vfh_{f}_{i}" for f in ("f1", "f2", "f3", "f4") for i in range(N_ANGLE_BINS)]
        names += [f"vfh_view_{i}" for i in range(N_VIEW_BINS)]
        return names

    def _describe(self, clouds, params, *, first_index):
        """VFH rows of one chunk of packed clouds."""
        vp, flags, k, n_threads = params
        points, normals, offsets = self._points_and_normals(clouds, k, self.normal_orientation, n_threads)
        out = np.zeros((len(clouds), N_FEATURES), dtype=np.float64)
        n_threads = max(1, min(n_threads, len(clouds)))
        vfh_batch(points, normals, offsets, vp, *flags, out, n_threads)
        return out
