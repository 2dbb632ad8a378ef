"""Globally Aligned Spatial Distribution (GASD), Lima & Teichrieb (2016), as in PCL 1.13."""

import numbers

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from .._chunks import transform_in_chunks
from .._validation import check_n_jobs, check_point_clouds, pack_point_clouds
from ._gasd_fast import gasd_batch

__all__ = ["GASDTransformer", "gasd_alignment"]

_INTERP = {"none": 0, "trilinear": 1, "quadrilinear": 2}
_SIGNS = {"pcl": 0, "majority": 1}


def _check_int(value, name, owner, low, high):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{owner}: {name} must be an int, got {type(value).__name__}")
    if value < low or value > high:
        raise ValueError(f"{owner}: {name} must be in [{low}, {high}], got {value}")
    return int(value)


def _check_direction(value, owner):
    """A finite, non-zero 3-vector, returned with unit length (float64)."""
    try:
        v = np.asarray(value)
    except Exception:
        v = None
    if v is None or v.dtype == object or not (np.issubdtype(v.dtype, np.number) or v.dtype == bool):
        raise TypeError(f"{owner}: view_direction must be an array-like of 3 numbers, got {type(value).__name__}")
    if np.iscomplexobj(v) or v.shape != (3,):
        raise ValueError(f"{owner}: view_direction must have shape (3,), got shape {v.shape}")
    v = v.astype(np.float64)
    if not np.isfinite(v).all():
        raise ValueError(f"{owner}: view_direction contains NaN or infinite values")
    big = np.abs(v).max()
    if big == 0:
        raise ValueError(f"{owner}: view_direction must not be the zero vector")
    v = v / big  # no overflow in the norm, even for 1e308
    return np.ascontiguousarray(v / np.linalg.norm(v))


class GASDTransformer(TransformerMixin, BaseEstimator):
    """Globally Aligned Spatial Distribution (GASD) shape descriptor.

    Aligns each cloud with its principal axes (a PCA reference frame at the
    centroid), then counts the aligned points in a regular
    ``(2 h)^3`` grid over the cube ``[-m, m]^3`` that just holds them, with
    trilinear interpolation between cell centres: ``8^3 = 512`` values by
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
        the 8 nearest cell centres (PCL's default), not at all (the cell it
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
        rotations of the input (not PCL's behaviour).
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
    Normals (six columns) are accepted and ignored. PCL's colour variant
    (``GASDColorEstimation``, hue histograms) is not implemented.

    References
    ----------
    .. [1] J. P. Lima and V. Teichrieb, "An Efficient Global Point Cloud
       Descriptor for Object Recognition and Pose Estimation", SIBGRAPI 2016.
    .. [2] R. B. Rusu and S. Cousins, "3D is here: Point Cloud Library (PCL)",
       ICRA 2011 (``pcl::GASDEstimation``).

    Examples
    --------
    >>> from eppf.datasets import make_shapes
    >>> from eppf.descriptors._gasd import GASDTransformer
    >>> data = make_shapes(2, n_points=256, random_state=0)
    >>> X = GASDTransformer().fit_transform(data.data)
    >>> X.shape
    (20, 512)
    """

    def __init__(self, half_grid_size=4, hists_size=1, interpolation="trilinear", view_direction=(0.0, 0.0, 1.0),
                 sign_convention="pcl", n_jobs=None):
        self.half_grid_size = half_grid_size
        self.hists_size = hists_size
        self.interpolation = interpolation
        self.view_direction = view_direction
        self.sign_convention = sign_convention
        self.n_jobs = n_jobs

    def _check_params(self):
        owner = type(self).__name__
        half = _check_int(self.half_grid_size, "half_grid_size", owner, 1, 64)
        hs = _check_int(self.hists_size, "hists_size", owner, 1, 1024)
        if (2 * half) ** 3 * hs > 2**24:
            raise ValueError(
                f"{owner}: half_grid_size={half} and hists_size={hs} give {(2 * half) ** 3 * hs} values; "
                "at most 2**24 are allowed"
            )
        if not isinstance(self.interpolation, str) or self.interpolation not in _INTERP:
            raise ValueError(
                f"{owner}: interpolation must be 'trilinear', 'none' or 'quadrilinear', got {self.interpolation!r}"
            )
        if not isinstance(self.sign_convention, str) or self.sign_convention not in _SIGNS:
            raise ValueError(f"{owner}: sign_convention must be 'pcl' or 'majority', got {self.sign_convention!r}")
        view = _check_direction(self.view_direction, owner)
        n_threads = check_n_jobs(self.n_jobs, owner=owner)
        return half, hs, _INTERP[self.interpolation], _SIGNS[self.sign_convention], view, n_threads

    def fit(self, X, y=None):
        """Check the parameters and the clouds; GASD learns nothing from data.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 2 distinct points (normals are ignored).
        y : None
            Ignored.

        Returns
        -------
        self : GASDTransformer
            The fitted transformer.
        """
        half, hs, *_ = self._check_params()
        check_point_clouds(X, owner=type(self).__name__, min_points=2)
        self.n_features_out_ = (2 * half) ** 3 * hs
        return self

    def transform(self, X):
        """Compute one GASD row per cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 2 distinct points.

        Returns
        -------
        X_new : ndarray of shape (n_objects, (2 * half_grid_size) ** 3 * hists_size)
            PCL-scaled grids (each point carries ``100 / (n - 1)``).
        """
        check_is_fitted(self)
        owner = type(self).__name__
        half, hs, *_, n_threads = self._check_params()
        clouds = check_point_clouds(X, owner=owner, min_points=2, n_threads=n_threads)
        return transform_in_chunks(_gasd_chunk, self, clouds, n_features=(2 * half) ** 3 * hs)

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
        check_is_fitted(self)
        owner = type(self).__name__
        *_, n_threads = self._check_params()
        clouds = check_point_clouds(X, owner=owner, min_points=2, n_threads=n_threads)
        transforms = _gasd_compute(self, clouds, 0)[1]
        bad = np.flatnonzero(~np.isfinite(transforms).all(axis=(1, 2)))
        if bad.size:
            raise ValueError(
                f"{owner}: point cloud {bad[0]} lies too far from the origin for a finite transform "
                "(its centroid's coordinates overflow)"
            )
        return transforms

    def get_feature_names_out(self, input_features=None):
        """Names of the output columns, ``gasd_<i>_<j>_<k>`` (and ``_<b>`` with ``hists_size > 1``).

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
        half, hs, *_ = self._check_params()
        g = 2 * half
        cells = [f"gasd_{i}_{j}_{k}" for i in range(g) for j in range(g) for k in range(g)]
        if hs == 1:
            return np.asarray(cells, dtype=object)
        return np.asarray([f"{c}_{b}" for c in cells for b in range(hs)], dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        return tags


def _gasd_compute(est, clouds, first_index):
    owner = type(est).__name__
    half, hs, interp, sign, view, n_threads = est._check_params()
    points, _, offsets = pack_point_clouds([c[:, :3] for c in clouds])
    out = np.zeros((len(clouds), (2 * half) ** 3 * hs), dtype=np.float64)
    transforms = np.zeros((len(clouds), 4, 4), dtype=np.float64)
    status = np.zeros(len(clouds), dtype=np.int8)
    n_threads = max(1, min(n_threads, len(clouds)))
    gasd_batch(points, offsets, view, sign, half, hs, interp, out, transforms, status, n_threads)
    bad = np.flatnonzero(status)
    if bad.size:
        raise ValueError(f"{owner}: point cloud {first_index + bad[0]} has no principal axes (no spread)")
    return out, transforms


def _gasd_chunk(est, clouds, first_index):
    """GASD rows of one chunk of validated clouds (a joblib task)."""
    return _gasd_compute(est, clouds, first_index)[0]


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

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.descriptors._gasd import gasd_alignment
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
