"""Global Radius-based Surface Descriptor (GRSD), Marton et al., as in PCL 1.13."""

import numbers

import numpy as np

from ..utils._param_validation import Interval, Options
from ._base import N_JOBS, N_NEIGHBORS, NORMAL_ORIENTATION, SCALING, PointCloudDescriptor
from ._grsd_fast import grid_check, grsd_batch

__all__ = ["GRSDTransformer"]

#: Surface classes in PCL's numbering (``GRSDEstimation::getSimpleType``), then empty.
CLASSES = ("noise", "plane", "cylinder", "sphere", "edge", "empty")
#: getSimpleType's thresholds: min_radius_plane, max_radius_noise,
#: min_radius_cylinder, max_min_radius_diff (PCL's defaults, in cloud units).
THRESHOLDS = (0.100, 0.015, 0.175, 0.050)
#: A length in the scaled cloud's units.
_LENGTH = [Interval(numbers.Real, 1e-15, 1e15, closed="both", description="a float in [1e-15, 1e+15]")]
N_FEATURES = 21
# PCL's VoxelGrid refuses grids of more than INT32_MAX cells; cells must also
# stay within +-2**30 of the origin for the kernel's integer cell indices.
_MAX_CELLS = 2**31 - 1
_MAX_CELL_INDEX = 2**30


class GRSDTransformer(PointCloudDescriptor):
    """Global Radius-based Surface Descriptor (GRSD) of point clouds.

    The cloud is voxelized; every occupied voxel gets a surface class from
    the radius-based surface descriptor (RSD) of its neighborhood (plane,
    cylinder, sphere, edge or noise), and the descriptor counts the classes
    of neighboring voxel pairs, empty neighbors included: 21 bins (PCL's
    ``GRSDSignature21``). The computation follows PCL 1.13's
    ``pcl::GRSDEstimation`` step by step, in single precision (see Notes),
    so the rows equal PCL's but where rounding in the normals moves a voxel
    (how often, on the PCL reference runs: :ref:`api-figures-pcl` in the
    documentation).

    Read more in the paper's baseline section (Bobkov et al. 2018).

    Parameters
    ----------
    radius : float, default=0.05
        Voxel width and RSD search radius (PCL's ``setRadiusSearch``, which
        sets both), in the units of the cloud after ``scaling``: with the
        default object scaling, a twentieth of the object's largest side
        (the PCL reference runs used 0.05 on scaled objects).
    scaling : {"object", "fit", "none"}, default="object"
        Every object is centered on its mean; then scaled so its largest
        bounding-box side is 1 (``"object"``, as the PCL reference runs), by
        one factor learnt in ``fit`` so the largest training object's side
        is 1 (``"fit"``), or not at all (``"none"``: ``radius`` and the
        class thresholds are then in the cloud's own units, meters for PCL).
    n_subdivisions : int, default=5
        Distance bins of the RSD fit (PCL's default).
    plane_radius : float, default=0.2
        Radius above which a surface counts as planar; RSD radii are capped
        there (PCL's default, in cloud units).
    normalize : bool, default=True
        Divide each row by its sum (needed for KL matching); False keeps
        PCL's raw counts.
    n_neighbors : int, default=10
        Neighborhood size for PCA normals of clouds given without normals.
    normal_orientation : {"centroid", "origin"} or None, default="centroid"
        Sign of estimated normals (irrelevant to GRSD, which ignores normal
        signs, but kept for a common interface).
    n_jobs : int, default=None
        Number of OpenMP threads over objects, with joblib's meaning; None
        means 1. The output does not depend on it.

    Attributes
    ----------
    scale_ : float
        The scale factor learnt with ``scaling="fit"`` (1.0 otherwise).
    n_features_out_ : int
        21.

    See Also
    --------
    OURCVFHTransformer : Viewpoint-feature histograms of smooth regions.
    ESFTransformer : Ensemble of shape functions.

    Notes
    -----
    Per object (points and normals in single precision, as PCL's clouds):

    1. Voxels of width ``w = radius`` on the grid anchored at multiples of
       ``w``: cell ``floor(x / w)`` per axis (PCL's ``VoxelGrid``, computed
       as ``floor(x * (1 / w))`` in single precision). Each occupied voxel
       is represented by the mean of its points.
    2. RSD at each voxel mean ``c`` (PCL's ``RSDEstimation`` with the whole
       cloud as search surface and radius ``max(w, sqrt(3) w / 2) = w``):
       the neighbors within ``w`` of ``c`` are found with a k-d tree; the
       *first* neighbor the tree returns is the reference, and for every
       other neighbor ``i`` the angle ``a_i = arccos(n_i . n_ref)`` folded
       to ``[0, pi/2]`` is put in distance bin
       ``floor(n_subdivisions |p_i - c| / w)``. With the smallest and
       largest angle per bin (``m_b``, ``M_b``; bin 0 also holds 0) and bin
       centers ``f_b``, the radii are the least-squares slopes
       ``r = sum(a_b f_b) / sum(a_b^2)`` of the min and max lines, capped at
       ``plane_radius`` (``plane_radius`` when the sum is 0), times 1.1 and
       0.9, and ordered so ``r_min <= r_max``. Fewer than two neighbors
       give ``r_min = r_max = 0``.
    3. Class (PCL's ``getSimpleType``): plane if ``r_min > 0.1``, else
       cylinder if ``r_max > 0.175``, else noise if ``r_min < 0.015``,
       else sphere if ``r_max - r_min < 0.05``, else edge.
    4. For every occupied voxel and each of its 26 neighbor cells, count
       the pair (voxel class, neighbor class), an empty or out-of-grid
       cell being class "empty": a 6 x 6 matrix ``T``. The descriptor is
       ``T[i, j] + T[j, i]`` for ``i <= j`` in PCL's order (noise, plane,
       cylinder, sphere, edge, empty), so pairs of occupied voxels count
       twice and the (empty, empty) bin is always 0.

    PCL's reference neighbor is the first one of an *unsorted* radius
    search (the tree PCL builds internally is unsorted), i.e. the first hit
    in the depth-first order of FLANN's single k-d tree. The kernel builds
    that tree (FLANN 1.9's middle split, leaf size 15) and searches it in
    the same order, which is what makes the rows match PCL's; the paper's
    RSD instead fits each point's own neighborhood.

    Rotation: the voxel grid is axis-aligned, so GRSD is not rotation
    invariant. A rotation by a multiple of 90 degrees about a coordinate
    axis maps the grid onto itself, leaving the occupied cells (hence the
    sum of the "empty" bins, the number of occupied-empty neighbor pairs)
    unchanged up to points on cell faces; the classes may still change
    through the reference neighbor, which depends on the k-d tree. Other rotations
    change the voxelization itself. The descriptor is invariant to
    translation (objects are centered) and, with ``scaling="object"``, to
    uniform scaling. No randomness: the output is deterministic.

    References
    ----------
    .. [1] Z.-C. Marton, D. Pangercic, N. Blodow and M. Beetz, "Combined
       2D-3D categorization and classification for multimodal perception
       systems", The International Journal of Robotics Research 30(11),
       2011.
    .. [2] Z.-C. Marton, D. Pangercic, R. B. Rusu, A. Holzbach and M. Beetz,
       "Hierarchical object geometric categorization and appearance
       classification for mobile manipulation", IEEE-RAS Humanoids 2010.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.datasets import make_shapes
    >>> from eppf.descriptors import GRSDTransformer
    >>> X, y = make_shapes(2, n_points=512, return_X_y=True)
    >>> G = GRSDTransformer().fit_transform(X)
    >>> G.shape
    (20, 21)
    >>> bool(np.allclose(G.sum(axis=1), 1.0))
    True
    """

    def __init__(
        self,
        radius=0.05,
        scaling="object",
        n_subdivisions=5,
        plane_radius=0.2,
        normalize=True,
        n_neighbors=10,
        normal_orientation="centroid",
        n_jobs=None,
    ):
        self.radius = radius
        self.scaling = scaling
        self.n_subdivisions = n_subdivisions
        self.plane_radius = plane_radius
        self.normalize = normalize
        self.n_neighbors = n_neighbors
        self.normal_orientation = normal_orientation
        self.n_jobs = n_jobs

    _parameter_constraints = {
        "radius": _LENGTH,
        "scaling": SCALING,
        "n_subdivisions": [Interval(numbers.Integral, 1, 64, closed="both")],
        "plane_radius": _LENGTH,
        "normalize": [Options(bool)],
        "n_neighbors": N_NEIGHBORS,
        "normal_orientation": NORMAL_ORIENTATION,
        "n_jobs": N_JOBS,
    }

    _min_points = 3

    def _resolve_params(self):
        params = dict(
            radius=float(self.radius),
            n_subdivisions=int(self.n_subdivisions),
            plane_radius=float(self.plane_radius),
            n_neighbors=int(self.n_neighbors),
        )
        # None means one thread (see n_jobs).
        return params, self._threads(none_means=1)

    def _learn(self, clouds, params):
        self.scale_ = self._fit_scale(clouds)

    def _n_features(self, params):
        return N_FEATURES

    def _feature_names(self):
        """``grsd_<class>_<class>`` for the 21 class pairs in PCL's order, e.g. ``grsd_plane_empty``."""
        return [f"grsd_{a}_{b}" for i, a in enumerate(CLASSES) for b in CLASSES[i:]]

    def _describe(self, clouds, params, *, first_index):
        """GRSD rows of one chunk of packed clouds."""
        params, n_threads = params
        owner = type(self).__name__
        points, normals, offsets = self._centred_points_and_normals(clouds, params["n_neighbors"], n_threads)
        p32, n32 = _single(points, normals, offsets, params["radius"], owner, first_index)
        out = np.zeros((len(clouds), N_FEATURES), dtype=np.float64)
        grsd_batch(
            p32, n32, offsets, params["radius"], params["n_subdivisions"], params["plane_radius"],
            np.asarray(THRESHOLDS, dtype=np.float64), out, max(1, min(n_threads, len(clouds))),
        )
        if self.normalize:
            out /= out.sum(axis=1, keepdims=True)
        return out


def _single(points, normals, offsets, width, owner, first_index):
    """Single-precision copies (PCL's clouds), checked for the kernel's grid."""
    with np.errstate(over="ignore"):
        p32 = points.astype(np.float32)
    n32 = normals.astype(np.float32)
    bad, cells = grid_check(p32, offsets, np.float32(1.0) / np.float32(width), float(_MAX_CELLS),
                            float(_MAX_CELL_INDEX))
    if bad >= 0 and cells is None:
        raise ValueError(
            f"{owner}: point cloud {first_index + bad} has coordinates beyond single precision "
            "after scaling; use scaling='object'"
        )
    if bad >= 0:
        raise ValueError(
            f"{owner}: point cloud {first_index + bad} spans {int(cells[0])} x {int(cells[1])} x "
            f"{int(cells[2])} voxels of width {width:g}; at most 2**31 - 1 voxels (PCL's VoxelGrid "
            "limit): use a larger radius or scaling='object'"
        )
    return p32, n32
