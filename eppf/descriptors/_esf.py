"""Ensemble of Shape Functions (ESF), Wohlkinger & Vincze (2011), as in PCL 1.13."""

import numbers

import numpy as np

from ..utils import check_n_jobs
from ..utils._param_validation import Interval, Satisfies
from ..utils._simd import register_kernel
from ._base import N_JOBS, RANDOM_STATE, PointCloudDescriptor
from . import _esf_fast
from ._esf_fast import MAX_BINS, MAX_GRID, MAX_TRIPLETS, MIN_GRID, esf_batch

__all__ = ["ESFTransformer"]

_HISTOGRAMS = ("a3_in", "a3_out", "a3_mix", "d3_in", "d3_out", "d3_mix", "d2_in", "d2_out", "d2_mix", "d2_ratio")

# PCL redraws a triplet when Heron's s(s-a)(s-b)(s-c) is at most 0.001 in
# voxel units of its 64^3 grid (radius 32): a triangle of area below ~0.03
# voxel^2. Kept in voxel units for any grid size.
_AREA_EPS = 0.001


def _even_grid(value):
    return Interval(numbers.Integral, MIN_GRID, MAX_GRID, closed="both").is_satisfied_by(value) and value % 2 == 0


class ESFTransformer(PointCloudDescriptor):
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

    1. Center the points on their mean and scale them so the farthest point
       lies at distance ``grid_size / 2``; voxel of a coordinate ``v``:
       ``floor(v) + grid_size/2`` for ``v < 0``, else
       ``ceil(v) + grid_size/2 - 1``. A voxel is occupied when a point lies in
       it or in one of its 26 neighbors (PCL's 3x3x3 dilation).
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
    voxelization.

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

    _parameter_constraints = {
        "n_triplets": [Interval(numbers.Integral, 1, MAX_TRIPLETS, closed="both")],
        "grid_size": [Satisfies(_even_grid, f"an even int in [{MIN_GRID}, {MAX_GRID}]")],
        "n_bins": [Interval(numbers.Integral, 1, MAX_BINS, closed="both")],
        "random_state": RANDOM_STATE,
        "n_jobs": N_JOBS,
    }

    def _resolve_params(self):
        n_threads = check_n_jobs(self.n_jobs, owner=type(self).__name__)
        return int(self.n_triplets), int(self.grid_size), int(self.n_bins), n_threads

    _min_points = 3

    def _n_features(self, params):
        return 10 * params[2]

    def _feature_names(self):
        n_bins = self.n_features_out_ // 10
        return [f"esf_{h}_{i}" for h in _HISTOGRAMS for i in range(n_bins)]

    def _describe(self, clouds, params, seeds, *, first_index):
        """ESF rows of one chunk of packed clouds."""
        n_triplets, grid_size, n_bins, n_threads = params
        points, offsets = clouds.points, clouds.offsets
        out = np.zeros((len(clouds), 10 * n_bins), dtype=np.float64)
        status = np.zeros(len(clouds), dtype=np.int8)
        n_threads = max(1, min(n_threads, len(clouds)))
        esf_batch(points, offsets, seeds, n_triplets, grid_size, n_bins, _AREA_EPS, out, status, n_threads)
        self._raise_for_status(status, first_index, {
            1: "has no triangles of non-zero area (all points collinear or nearly so); ESF needs a surface"})
        return out


# the SIMD code this module's kernel runs, for eppf.simd_levels()
register_kernel("esf", lambda: "avx2" if _esf_fast._simd_enabled() else "scalar")
