"""Ensemble of Shape Functions (ESF), Wohlkinger & Vincze (2011), as in PCL 1.13."""

import numbers

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from ._baselines import esf_batch
from ._chunks import transform_in_chunks
from ._validation import check_n_jobs, check_point_clouds, condition_point_clouds, object_seeds, pack_point_clouds

__all__ = ["ESFTransformer"]

_HISTOGRAMS = ("a3_in", "a3_out", "a3_mix", "d3_in", "d3_out", "d3_mix", "d2_in", "d2_out", "d2_mix", "d2_ratio")

# PCL redraws a triplet when Heron's s(s-a)(s-b)(s-c) is at most 0.001 in
# voxel units of its 64^3 grid (radius 32): a triangle of area below ~0.03
# voxel^2. Kept in voxel units for any grid size.
_AREA_EPS = 0.001


def _check_int(value, name, owner, low, high=None):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{owner}: {name} must be an int, got {type(value).__name__}")
    if value < low or (high is not None and value > high):
        bound = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{owner}: {name} must be {bound}, got {value}")
    return int(value)


class ESFTransformer(TransformerMixin, BaseEstimator):
    """Ensemble of Shape Functions (ESF) global descriptor of point clouds.

    Samples point triplets and histograms three shape functions, the angle
    (A3), the area (D3) and the distance (D2), each split by whether the
    connecting lines run inside, outside or partly inside the object's voxel
    occupancy; plus the occupied fraction of the partly-inside lines. Ten
    histograms of ``n_bins`` (640 values by default), summing to one. The
    computation follows PCL 1.13's ``pcl::ESFEstimation`` step by step (see
    Notes), but is seeded and reproducible where PCL reseeds from the clock.

    Read more in the paper's baseline section (Bobkov et al. 2018, Table II).

    Parameters
    ----------
    n_triplets : int, default=20000
        Number of point triplets drawn per object (PCL: 20,000).
    grid_size : int, default=64
        Side of the occupancy grid in voxels (PCL: 64). Must be even.
    n_bins : int, default=64
        Bins of each of the ten histograms (PCL: 64).
    random_state : int, RandomState instance or None, default=None
        Draws one seed per object; each object's triplets come from a private
        generator seeded with it, so the output does not depend on
        ``n_jobs``. Pass an int for reproducible output across calls.
    n_jobs : int, default=None
        Number of OpenMP threads over objects, with joblib's meaning
        (``None``: OpenMP's default, which honours ``OMP_NUM_THREADS`` and
        threadpoolctl limits; ``-1``: all cores).

    Attributes
    ----------
    n_features_out_ : int
        Length of each descriptor, ``10 * n_bins``.

    See Also
    --------
    WahlTransformer : Surflet-pair-relation histograms (needs normals).
    OURCVFHTransformer : Viewpoint-feature histogram with a semi-global frame.
    KLNearestNeighbors : 1-NN matching with the symmetric KL divergence.

    Notes
    -----
    Per object, as PCL does:

    1. Centre the points on their mean and scale them so the farthest point
       lies at distance ``grid_size / 2``; voxel of a coordinate ``v``:
       ``floor(v) + grid_size/2`` for ``v < 0``, else
       ``ceil(v) + grid_size/2 - 1``. A voxel is occupied when a point lies in
       it or in one of its 26 neighbours (PCL's 3x3x3 dilation).
    2. Draw triplets of distinct points; redraw when Heron's product
       ``s(s-a)(s-b)(s-c) <= 0.001`` (voxel units).
    3. A3: the three angles folded to ``[0, pi/2]`` as ``arccos(|cos|)``,
       bin ``round(63 * angle / (pi/2))``; each counts the voxels of the
       opposite side's line divided by 32.
    4. Each side's voxel line (3D Bresenham along the dominant axis, visiting
       the start voxel and the next ``L - 1``) is *in* when at most one of
       its voxels is empty, *out* when at most 7 are occupied, else *mixed*
       (its occupied fraction goes into the ratio histogram,
       ``round(63 * ratio)``). D2: side lengths over the largest sampled side,
       ``round(63 * d / d_max)``, into the in/out/mixed histogram of its line.
    5. D3 = sqrt(area) over the largest sampled one; the triangle (and its
       A3 angles) is *out* when its lines hold at most 21 occupied voxels in
       all, *in* when fewer than 4 of their voxels are empty, else *mixed*.
    6. Weights (0.5, 0.5, 0.5 for A3; 0.5, 0.5, 1 for D3; 0.5, 2, 2 for D2;
       1 for the ratio), then division by the sum.

    Layout: ``[a3_in, a3_out, a3_mix, d3_in, d3_out, d3_mix, d2_in, d2_out,
    d2_mix, d2_ratio]``, ``n_bins`` each, as PCL's ``ESFSignature640``. Six
    columns (normals) are accepted and ignored. ESF is invariant to the
    cloud's position and scale by construction; rotation changes only the
    voxelisation.

    References
    ----------
    .. [1] W. Wohlkinger and M. Vincze, "Ensemble of shape functions for 3D
       object classification", IEEE ROBIO 2011.
    .. [2] R. B. Rusu and S. Cousins, "3D is here: Point Cloud Library (PCL)",
       ICRA 2011 (``pcl::ESFEstimation``).

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import ESFTransformer
    >>> rng = np.random.default_rng(0)
    >>> clouds = [rng.normal(size=(200, 3)), rng.uniform(size=(300, 3))]
    >>> X = ESFTransformer(n_triplets=2000, random_state=0).fit_transform(clouds)
    >>> X.shape
    (2, 640)
    >>> bool(np.allclose(X.sum(axis=1), 1.0))
    True
    """

    def __init__(self, n_triplets=20000, grid_size=64, n_bins=64, random_state=None, n_jobs=None):
        self.n_triplets = n_triplets
        self.grid_size = grid_size
        self.n_bins = n_bins
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _check_params(self):
        owner = type(self).__name__
        n_triplets = _check_int(self.n_triplets, "n_triplets", owner, 1, 2**31 // 4)
        grid_size = _check_int(self.grid_size, "grid_size", owner, 4, 1024)
        if grid_size % 2:
            raise ValueError(f"{owner}: grid_size must be even, got {grid_size}")
        n_bins = _check_int(self.n_bins, "n_bins", owner, 1, 4096)
        n_threads = check_n_jobs(self.n_jobs, owner=owner)
        return n_triplets, grid_size, n_bins, n_threads

    def fit(self, X, y=None):
        """Check the parameters and the clouds; ESF learns nothing from data.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 3 points each (normals are ignored).
        y : None
            Ignored.

        Returns
        -------
        self : ESFTransformer
            The fitted transformer.
        """
        _, _, n_bins, _ = self._check_params()
        check_point_clouds(X, owner=type(self).__name__, min_points=3)
        self.n_features_out_ = 10 * n_bins
        return self

    def transform(self, X):
        """Compute one ESF histogram per cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 3 points each, not all collinear.

        Returns
        -------
        X_new : ndarray of shape (n_objects, 10 * n_bins)
            Histograms, each summing to one.
        """
        check_is_fitted(self)
        owner = type(self).__name__
        n_triplets, grid_size, n_bins, n_threads = self._check_params()
        clouds = check_point_clouds(X, owner=owner, min_points=3, n_threads=n_threads)
        condition_point_clouds(clouds, owner=owner)  # exact 2**e rescaling: ESF is scale-invariant
        seeds = object_seeds(self.random_state, len(clouds))
        return transform_in_chunks(_esf_chunk, self, clouds, (seeds,), n_features=10 * n_bins)

    def get_feature_names_out(self, input_features=None):
        """Names of the output columns, e.g. ``esf_a3_in_0``.

        Parameters
        ----------
        input_features : None
            Ignored (point clouds have no input feature names).

        Returns
        -------
        feature_names_out : ndarray of str
            ``esf_<histogram>_<bin>`` in the output's order.
        """
        check_is_fitted(self)
        n_bins = self.n_features_out_ // 10
        return np.asarray([f"esf_{h}_{i}" for h in _HISTOGRAMS for i in range(n_bins)], dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        tags.non_deterministic = self.random_state is None
        return tags


def _esf_chunk(est, clouds, seeds, first_index):
    """ESF rows of one chunk of validated clouds (a joblib task)."""
    owner = type(est).__name__
    n_triplets, grid_size, n_bins, n_threads = est._check_params()
    points, _, offsets = pack_point_clouds([c[:, :3] for c in clouds])
    out = np.zeros((len(clouds), 10 * n_bins), dtype=np.float64)
    status = np.zeros(len(clouds), dtype=np.int8)
    n_threads = max(1, min(n_threads, len(clouds)))
    esf_batch(points, offsets, seeds, n_triplets, grid_size, n_bins, _AREA_EPS, out, status, n_threads)
    bad = np.flatnonzero(status)
    if bad.size:
        raise ValueError(
            f"{owner}: point cloud {first_index + bad[0]} has no triangles of non-zero area "
            "(all points collinear or nearly so); ESF needs a surface"
        )
    return out
