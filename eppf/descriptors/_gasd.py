"""Globally Aligned Spatial Distribution (GASD), Lima & Teichrieb (2016), as in PCL 1.13."""

import numbers

import numpy as np
from sklearn.utils.validation import check_is_fitted

from ..utils import check_n_jobs, check_point_clouds
from ..utils._param_validation import Interval, Satisfies, StrOptions, validate_parameter
from ._base import N_JOBS, PointCloudDescriptor, as_vector3
from ._gasd_fast import gasd_batch

__all__ = ["GASDColorTransformer", "GASDTransformer", "gasd_alignment"]

_INTERP = {"none": 0, "trilinear": 1, "quadrilinear": 2}
_SIGNS = {"pcl": 0, "majority": 1}
#: Most values of one grid (cells times histogram bins).
_MAX_VALUES = 2**24

_HALF_GRID = [Interval(numbers.Integral, 1, 64, closed="both")]
_HISTS = [Interval(numbers.Integral, 1, 1024, closed="both")]
_INTERPOLATION = [StrOptions(["trilinear", "none", "quadrilinear"])]
_SIGN_CONVENTION = [StrOptions(["pcl", "majority"])]


def _is_direction(value):
    v = as_vector3(value)
    return v is not None and np.abs(v).max() > 0


_VIEW_DIRECTION = [Satisfies(_is_direction, "an array-like of 3 finite numbers, not all zero")]


def _unit(value):
    """The validated direction with unit length (float64)."""
    v = as_vector3(value)
    v = v / np.abs(v).max()  # no overflow in the norm, even for 1e308
    return np.ascontiguousarray(v / np.linalg.norm(v))


def _grid_fits(pair):
    half, hists = pair
    return (2 * half) ** 3 * hists <= _MAX_VALUES


#: A grid's (half size, histogram size) pair, checked jointly once each is valid.
_GRID = [Satisfies(_grid_fits, "a grid of at most 2**24 values ((2 half)**3 * hists)")]


def _check_grid(owner, h_name, half, s_name, hs):
    """Check the pair ``(half, hs)`` against :data:`_GRID` (an error naming both parameters)."""
    validate_parameter((half, hs), _GRID, name=f"({h_name}, {s_name})", owner=owner)


class GASDTransformer(PointCloudDescriptor):
    """Globally Aligned Spatial Distribution (GASD) shape descriptor.

    Aligns each cloud with its principal axes (a PCA reference frame at the
    centroid), then counts the aligned points in a regular
    ``(2 h)^3`` grid over the cube ``[-m, m]^3`` that just holds them, with
    trilinear interpolation between cell centers: ``8^3 = 512`` values by
    default, PCL 1.13's ``GASDEstimation`` (``GASDSignature512``) step by
    step, including its scaling (see Notes).

    Read more in the papers of Lima and Teichrieb (2016) and Rusu and Cousins
    (2011).

    Parameters
    ----------
    half_grid_size : int, default=4
        ``h``: the grid has ``2 h`` cells along each axis (PCL: 4).
    hists_size : int, default=1
        Bins of the histogram of each cell (PCL: 1). With 1 a cell holds a
        (weighted) point count; with more, a histogram of the fractional
        part of ``d / (d_max / h)`` over the cell's points, ``d`` being the
        distance to the centroid.
    interpolation : {"trilinear", "none", "quadrilinear"}, default="trilinear"
        How a point is shared between cells: by trilinear weights between
        the 8 nearest cell centers (PCL's default), not at all (the cell it
        falls in), or trilinearly in space and linearly between the two
        nearest distance bins.
    view_direction : array-like of shape (3,), default=(0, 0, 1)
        PCL's viewing direction: the frame's z axis (the direction of least
        spread) is flipped to point against it. Used by
        ``sign_convention="pcl"`` only.
    sign_convention : {"pcl", "majority"}, default="pcl"
        How the signs of the axes are chosen. ``"pcl"``: z against
        ``view_direction``, x as PCL's eigen solver returns it, so the
        descriptor depends on the cloud's orientation (what pays on
        consistently oriented CAD models). ``"majority"``: x and z each point
        to the side of the centroid that holds more points (ties: the side
        of positive third moment), which makes the descriptor invariant to
        rotations of the input (not PCL's behavior).
    n_jobs : int, default=None
        Number of OpenMP threads over objects, with joblib's meaning
        (``None``: OpenMP's default; ``-1``: all cores). The output does not
        depend on it.

    Attributes
    ----------
    n_features_out_ : int
        ``(2 * half_grid_size) ** 3 * hists_size``.

    See Also
    --------
    gasd_alignment : The 4x4 transforms that align each cloud to GASD's frame.
    ESFTransformer : Ensemble of shape functions (rotation invariant).

    Notes
    -----
    Per object, as PCL 1.13 does (in double precision where PCL uses float):

    1. Centroid :math:`c` and scatter :math:`C = \\sum_i (p_i - c)(p_i - c)^T`;
       eigenvectors by PCL's closed-form solver ``pcl::eigen33``. The x axis
       is the eigenvector of the largest eigenvalue, z that of the smallest,
       negated when :math:`z \\cdot v > 0` for the view direction :math:`v`,
       and :math:`y = z \\times x`. The aligned points are
       :math:`q_i = R (p_i - c)` with rows x, y, z of R.
    2. :math:`m = \\max_{i,j} |q_{ij}|`, :math:`d_{max} = \\max_i \\|q_i\\|`.
       Grid coordinate of a point along each axis: :math:`s = h q / m + h`
       (minus 1/2 when interpolating); distance coordinate: the fractional
       part of :math:`\\|q\\| h / d_{max}` times ``hists_size`` (minus 1/2
       when interpolating).
    3. Each point adds :math:`100 / (n - 1)` in all, shared out by the
       interpolation weights. PCL pads the grid with one cell on each side
       and each histogram with one bin at each end and drops the padding
       from the output; so do we. Two consequences of PCL's reading that we
       keep: without interpolation a point at exactly :math:`q_j = +m` is
       dropped, and with trilinear interpolation and ``hists_size=1`` only
       the points whose distance coordinate is at least 1/2 are counted
       (the others fall in the dropped bin below), so rows sum to about 50,
       not 100.

    Layout: cell ``(i, j, k)`` (along x, y, z), histogram bin ``b`` at
    column ``((i * 2h + j) * 2h + k) * hists_size + b``, PCL's order.
    Normals (six columns) are accepted and ignored. PCL's color variant
    (``GASDColorEstimation``, hue histograms) is :class:`GASDColorTransformer`.

    References
    ----------
    .. [1] J. P. Lima and V. Teichrieb, "An Efficient Global Point Cloud
       Descriptor for Object Recognition and Pose Estimation", SIBGRAPI 2016.
    .. [2] R. B. Rusu and S. Cousins, "3D is here: Point Cloud Library (PCL)",
       ICRA 2011 (``pcl::GASDEstimation``).

    Examples
    --------
    >>> from eppf.datasets import make_shapes
    >>> from eppf.descriptors import GASDTransformer
    >>> data = make_shapes(2, n_points=256, random_state=0)
    >>> X = GASDTransformer().fit_transform(data.data)
    >>> X.shape
    (20, 512)
    """

    # magnitudes are brought into range by the kernel itself (exact powers of two)
    _conditioning = "none"

    def __init__(self, half_grid_size=4, hists_size=1, interpolation="trilinear", view_direction=(0.0, 0.0, 1.0),
                 sign_convention="pcl", n_jobs=None):
        self.half_grid_size = half_grid_size
        self.hists_size = hists_size
        self.interpolation = interpolation
        self.view_direction = view_direction
        self.sign_convention = sign_convention
        self.n_jobs = n_jobs

    _parameter_constraints = {
        "half_grid_size": _HALF_GRID,
        "hists_size": _HISTS,
        "interpolation": _INTERPOLATION,
        "view_direction": _VIEW_DIRECTION,
        "sign_convention": _SIGN_CONVENTION,
        "n_jobs": N_JOBS,
    }

    def _resolve_params(self):
        owner = type(self).__name__
        half, hs = int(self.half_grid_size), int(self.hists_size)
        _check_grid(owner, "half_grid_size", half, "hists_size", hs)
        n_threads = check_n_jobs(self.n_jobs, owner=owner)
        return half, hs, _INTERP[self.interpolation], _SIGNS[self.sign_convention], _unit(self.view_direction), n_threads

    def _n_features(self, params):
        half, hs = params[:2]
        return (2 * half) ** 3 * hs

    def _feature_names(self):
        """``gasd_<i>_<j>_<k>`` (and ``_<b>`` with ``hists_size > 1``)."""
        half, hs = int(self.half_grid_size), int(self.hists_size)
        return _cell_names(half, hs)

    def _describe(self, clouds, params, *, first_index):
        """GASD rows of one chunk of packed clouds."""
        return _gasd_compute(self, clouds, params, first_index)[0]

    def alignment_transforms(self, X):
        """The 4x4 rigid transforms that map each cloud into GASD's frame.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 2 distinct points.

        Returns
        -------
        transforms : ndarray of shape (n_objects, 4, 4)
            ``T[k] @ [p, 1]`` is point ``p`` of cloud ``k`` in its frame
            (PCL's ``getTransform()``).
        """
        check_is_fitted(self, "n_features_out_")
        owner = type(self).__name__
        params = self._check_params()
        clouds, _ = self._validate_clouds(X, params[5])
        transforms = _gasd_compute(self, clouds, params, 0)[1]
        bad = np.flatnonzero(~np.isfinite(transforms).all(axis=(1, 2)))
        if bad.size:
            raise ValueError(
                f"{owner}: point cloud {bad[0]} lies too far from the origin for a finite transform "
                "(its centroid's coordinates overflow)"
            )
        return transforms


def _cell_names(half, hs, prefix="gasd"):
    g = 2 * half
    cells = [f"{prefix}_{i}_{j}_{k}" for i in range(g) for j in range(g) for k in range(g)]
    if hs == 1:
        return cells
    return [f"{c}_{b}" for c in cells for b in range(hs)]


def _gasd_compute(est, clouds, params, first_index, hues=None):
    """GASD rows and alignment transforms of packed clouds (with ``hues``: the color grid too)."""
    half, hs, interp, sign, view, n_threads, *color = params
    points, offsets = clouds.points, clouds.offsets
    width = (2 * half) ** 3 * hs
    extra = {}
    if hues is not None:
        chalf, chs, cinterp = color
        width += (2 * chalf) ** 3 * chs
        extra = dict(hue=np.ascontiguousarray(np.concatenate(hues), dtype=np.float64), chalf=chalf, chs=chs,
                     cinterp=cinterp)
    out = np.zeros((len(clouds), width), dtype=np.float64)
    transforms = np.zeros((len(clouds), 4, 4), dtype=np.float64)
    status = np.zeros(len(clouds), dtype=np.int8)
    n_threads = max(1, min(n_threads, len(clouds)))
    gasd_batch(points, offsets, view, sign, half, hs, interp, out, transforms, status, n_threads, **extra)
    est._raise_for_status(status, first_index, {1: "has no principal axes (no spread)"})
    return out, transforms


def gasd_alignment(cloud, *, view_direction=(0.0, 0.0, 1.0), sign_convention="pcl"):
    """Align one cloud to GASD's reference frame.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        At least 2 distinct points; normals, when given, are rotated too.
    view_direction : array-like of shape (3,), default=(0, 0, 1)
        As in :class:`GASDTransformer`.
    sign_convention : {"pcl", "majority"}, default="pcl"
        As in :class:`GASDTransformer`.

    Returns
    -------
    aligned : ndarray of shape (n_points, 3) or (n_points, 6)
        The cloud in its frame (centroid at the origin, principal axes along
        x, y, z).
    transform : ndarray of shape (4, 4)
        The rigid transform used.

    See Also
    --------
    GASDTransformer.alignment_transforms : The transforms of many clouds at once.
    GASDTransformer : The descriptor computed in this frame.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.descriptors import gasd_alignment
    >>> rng = np.random.default_rng(0)
    >>> cloud = rng.normal(size=(500, 3)) * [3.0, 2.0, 1.0] + 5.0
    >>> aligned, T = gasd_alignment(cloud)
    >>> bool(np.allclose(aligned.mean(axis=0), 0.0))
    True
    """
    est = GASDTransformer(view_direction=view_direction, sign_convention=sign_convention, n_jobs=1)
    est.fit([cloud])
    T = est.alignment_transforms([cloud])[0]
    c = check_point_clouds([cloud], owner="gasd_alignment", min_points=2)[0]
    out = c.copy()
    out[:, :3] = c[:, :3] @ T[:3, :3].T + T[:3, 3]
    if c.shape[1] == 6:
        out[:, 3:] = c[:, 3:] @ T[:3, :3].T
    return out, T


def _hue(rgb):
    """PCL's hue of 8-bit colors, in float32 as PCL computes it, divided by 360."""
    rgb = rgb.astype(np.int32)
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    mx, mn = rgb.max(axis=1), rgb.min(axis=1)
    hue = np.zeros(len(rgb), dtype=np.float32)
    ok = mx > mn
    inv = np.float32(1) / np.maximum(mx - mn, 1).astype(np.float32)
    six = np.float32(60)
    h_r = six * ((g - b).astype(np.float32) * inv)
    h_g = six * (np.float32(2) + (b - r).astype(np.float32) * inv)
    h_b = six * (np.float32(4) + (r - g).astype(np.float32) * inv)
    hue = np.where(mx == r, h_r, np.where(mx == g, h_g, h_b)).astype(np.float32)
    hue = np.where(hue < 0, hue + np.float32(360), hue).astype(np.float32)
    hue = np.where(ok, hue, np.float32(0))
    return (hue / np.float32(360)).astype(np.float64)


class GASDColorTransformer(PointCloudDescriptor):
    """GASD with color: a shape grid and a grid of hue histograms.

    PCL 1.13's ``GASDColorEstimation`` (``GASDSignature984``): the cloud is
    aligned as by :class:`GASDTransformer`; a ``(2 h_s)^3`` shape grid
    (PCL: 6^3, no interpolation) is followed by a ``(2 h_c)^3`` grid of
    circular hue histograms (PCL: 4^3 cells of 12 bins), ``216 + 768 = 984``
    values by default.

    Parameters
    ----------
    shape_half_grid_size : int, default=3
        Half the side of the shape grid (PCL's color default: 3).
    shape_hists_size : int, default=1
        Bins of each shape cell's distance histogram (PCL: 1).
    color_half_grid_size : int, default=2
        Half the side of the color grid (PCL: 2).
    color_hists_size : int, default=12
        Hue bins of each color cell (PCL: 12, 30 degrees each).
    shape_interpolation : {"none", "trilinear", "quadrilinear"}, default="none"
        As ``interpolation`` of :class:`GASDTransformer` (PCL's color
        default: none).
    color_interpolation : {"none", "trilinear", "quadrilinear"}, default="none"
        The same for the color grid; the hue histogram is circular, so the
        bins beyond its ends wrap around (PCL's reading).
    view_direction : array-like of shape (3,), default=(0, 0, 1)
        As in :class:`GASDTransformer`.
    sign_convention : {"pcl", "majority"}, default="pcl"
        As in :class:`GASDTransformer`.
    n_jobs : int, default=None
        Number of OpenMP threads over objects (joblib's meaning). The output
        does not depend on it.

    Attributes
    ----------
    n_features_out_ : int
        ``(2 h_s)^3 shape_hists_size + (2 h_c)^3 color_hists_size``.

    See Also
    --------
    GASDTransformer : The shape-only descriptor.

    Notes
    -----
    Input clouds are ``(n, 6)`` arrays of coordinates and RGB, or
    ``(n, 9)`` arrays of coordinates, normals (ignored) and RGB. Colors are
    8-bit values in ``[0, 255]``, rounded to the nearest integer as PCL
    stores them. The hue is PCL's (in degrees, in single precision:
    ``60 (g - b) / (max - min)`` when red is largest, ``60 (2 + (b - r) /
    (max - min))`` for green, ``60 (4 + (r - g) / (max - min))`` for blue,
    plus 360 when negative; 0 for grays); its histogram coordinate is
    ``hue / 360 * color_hists_size``. Each point adds ``100 / (n - 1)`` to
    each grid, shared by the interpolation weights. Layout: the shape grid
    as in :class:`GASDTransformer`, then color cell ``(i, j, k)``, hue bin
    ``b`` at ``shape_size + ((i * 2h_c + j) * 2h_c + k) * color_hists_size
    + b``.

    References
    ----------
    .. [1] J. P. Lima and V. Teichrieb, "An Efficient Global Point Cloud
       Descriptor for Object Recognition and Pose Estimation", SIBGRAPI 2016.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.descriptors import GASDColorTransformer
    >>> rng = np.random.default_rng(0)
    >>> xyz = rng.normal(size=(300, 3)) * [3.0, 2.0, 1.0]
    >>> rgb = rng.integers(0, 256, size=(300, 3))
    >>> X = GASDColorTransformer().fit_transform([np.hstack([xyz, rgb])])
    >>> X.shape
    (1, 984)
    """

    # magnitudes are brought into range by the kernel itself (exact powers of two)
    _conditioning = "none"

    def __init__(self, shape_half_grid_size=3, shape_hists_size=1, color_half_grid_size=2, color_hists_size=12,
                 shape_interpolation="none", color_interpolation="none", view_direction=(0.0, 0.0, 1.0),
                 sign_convention="pcl", n_jobs=None):
        self.shape_half_grid_size = shape_half_grid_size
        self.shape_hists_size = shape_hists_size
        self.color_half_grid_size = color_half_grid_size
        self.color_hists_size = color_hists_size
        self.shape_interpolation = shape_interpolation
        self.color_interpolation = color_interpolation
        self.view_direction = view_direction
        self.sign_convention = sign_convention
        self.n_jobs = n_jobs

    _parameter_constraints = {
        "shape_half_grid_size": _HALF_GRID,
        "shape_hists_size": _HISTS,
        "color_half_grid_size": _HALF_GRID,
        "color_hists_size": _HISTS,
        "shape_interpolation": _INTERPOLATION,
        "color_interpolation": _INTERPOLATION,
        "view_direction": _VIEW_DIRECTION,
        "sign_convention": _SIGN_CONVENTION,
        "n_jobs": N_JOBS,
    }

    _extra_columns = 3
    _extra_columns_name = "rgb"

    def _resolve_params(self):
        owner = type(self).__name__
        half, hs = int(self.shape_half_grid_size), int(self.shape_hists_size)
        chalf, chs = int(self.color_half_grid_size), int(self.color_hists_size)
        _check_grid(owner, "shape_half_grid_size", half, "shape_hists_size", hs)
        _check_grid(owner, "color_half_grid_size", chalf, "color_hists_size", chs)
        n_threads = check_n_jobs(self.n_jobs, owner=owner)
        return (half, hs, _INTERP[self.shape_interpolation], _SIGNS[self.sign_convention], _unit(self.view_direction),
                n_threads, chalf, chs, _INTERP[self.color_interpolation])

    def _check_extra_columns(self, index, values):
        """PCL's hue / 360 of the RGB columns (8-bit values in [0, 255], rounded); normals are checked, then ignored."""
        rgb = values.astype(np.float64)
        if not np.isfinite(rgb).all() or (rgb < 0).any() or (rgb > 255).any():
            raise ValueError(f"{type(self).__name__}: point cloud {index} has colours outside [0, 255] (or NaN)")
        return _hue(np.rint(rgb).astype(np.uint8))

    def _n_features(self, params):
        half, hs, *_, chalf, chs, _ = params
        return (2 * half) ** 3 * hs + (2 * chalf) ** 3 * chs

    def _feature_names(self):
        """``gasd_...`` for the shape grid, then ``gasd_hue_<i>_<j>_<k>_<b>``."""
        cells = _cell_names(int(self.shape_half_grid_size), int(self.shape_hists_size))
        cg, chs = 2 * int(self.color_half_grid_size), int(self.color_hists_size)
        cells += [f"gasd_hue_{i}_{j}_{k}_{b}" for i in range(cg) for j in range(cg) for k in range(cg)
                  for b in range(chs)]
        return cells

    def _describe(self, clouds, params, hues, *, first_index):
        """Color GASD rows of one chunk of packed clouds (``hues``: one array per cloud)."""
        return _gasd_compute(self, clouds, params, first_index, list(hues))[0]
