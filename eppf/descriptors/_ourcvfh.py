"""OUR-CVFH, Aldoma et al. (2012), after PCL 1.13's ``OURCVFHEstimation``, in NumPy/SciPy (its curvature filter compiled)."""

import numbers

import numpy as np
from joblib import Parallel, delayed
from scipy.spatial import cKDTree

from ..utils import check_n_jobs
from ..utils._param_validation import Interval, Options, StrOptions
from ._base import N_JOBS, N_NEIGHBORS, NORMAL_ORIENTATION, SCALING, PointCloudDescriptor
from ._regions import low_curvature, pair_features, smooth_clusters

__all__ = ["OURCVFHTransformer"]

N_ANGLE_BINS = 45
N_VIEW_BINS = 128
N_OCTANTS = 8
N_SHELLS = 13
# PCL writes the 8 x 13 shape distribution over bins 135-238 of the 308-bin
# VFH signature, so only the viewpoint bins 59-127 survive at 239-307.
VIEW_KEPT = 308 - 3 * N_ANGLE_BINS - N_OCTANTS * N_SHELLS
N_FEATURES = 308


def _angle_hist(f):
    """PCL's VFH binning: floor(45 (f + pi) / (2 pi)), clipped, for every feature."""
    idx = np.floor(N_ANGLE_BINS * (f + np.pi) / (2 * np.pi)).astype(np.int64)
    return np.bincount(np.clip(idx, 0, N_ANGLE_BINS - 1), minlength=N_ANGLE_BINS).astype(np.float64)


def _sgurf(points, normals, cluster, c, nc, axis_ratio, min_axis_value):
    """PCL's semi-global unique reference frames of one cluster.

    Returns a list of 3x3 matrices whose rows are the frame's (x, y, z) axes.
    """
    q = points[cluster] - c
    dk = np.linalg.norm(q, axis=1)
    w = dk.max() - dk
    if w.sum() <= 0:
        w = np.ones_like(dk)
    scatter = (q * w[:, None]).T @ q / w.sum()
    _, vecs = np.linalg.eigh(scatter)
    evx, evy, evz = vecs[:, 2].copy(), vecs[:, 1].copy(), vecs[:, 0].copy()
    allq = points - c
    px, py = allq @ evx, allq @ evy
    sxp, sxm = np.abs(px[px >= 0]).sum(), np.abs(px[px < 0]).sum()
    syp, sym = np.abs(py[py >= 0]).sum(), np.abs(py[py < 0]).sum()
    if sxp < sxm:
        evx = -evx
    if syp < sym:
        evy = -evy
    fx = min(sxp, sxm) / max(max(sxp, sxm), 1e-300)
    fy = min(syp, sym) / max(max(syp, sym), 1e-300)
    if nc @ evz < 0:
        evz = -evz
    hi, lo = max(fx, fy), min(fx, fy)
    if hi > 0 and lo / hi > axis_ratio:
        xs = [evx, -evx, evy, -evy] if lo > min_axis_value else [evx, evy]
    else:
        xs = [evy if fy < fx else evx]
    return [np.stack([x, np.cross(x, evz), evz]) for x in xs]


def _octant_hist(local, sigma):
    """PCL's 8 x 13 shape distribution of points in a frame (cluster centroid at 0)."""
    d = np.linalg.norm(local, axis=1)
    dmax = d.max()
    s2 = sigma * sigma
    wgt = 1.0 - np.exp(-(local * local) / (2.0 * s2))  # (n, 3)
    # Weight of the positive half-space along each axis.
    pos = np.where(local >= 0, 0.5 + 0.5 * wgt, 0.5 - 0.5 * wgt)
    neg = 1.0 - pos
    if dmax > 0:
        shell = np.ceil(N_SHELLS * d / dmax).astype(np.int64) - 1
    else:
        shell = np.zeros(len(d), dtype=np.int64)
    shell = np.clip(np.where(d <= 0, 0, shell), 0, N_SHELLS - 1)
    hist = np.zeros((N_OCTANTS, N_SHELLS))
    for k in range(N_OCTANTS):
        bx, by, bz = (k >> 2) & 1, (k >> 1) & 1, k & 1
        wk = (pos[:, 0] if bx else neg[:, 0]) * (pos[:, 1] if by else neg[:, 1]) * (pos[:, 2] if bz else neg[:, 2])
        hist[k] = np.bincount(shell, weights=wk, minlength=N_SHELLS)
    return hist.ravel()


def _ourcvfh_object(points, normals, *, n_neighbors=10, curvature_threshold=0.03, eps_angle=0.125,
                    cluster_tolerance=None, min_points=50, refine=1.0, axis_ratio=0.8,
                    min_axis_value=0.925, sigma=0.01):
    """OUR-CVFH signatures of one centered, scaled object.

    Returns ``(signatures, clusters)``: a list of 308-bin arrays (one per
    cluster and reference frame, clusters in order) with the cluster index of
    each, and the refined clusters as index arrays. An object without any
    cluster is treated as one cluster of all its points.
    """
    n = points.shape[0]
    if cluster_tolerance is None:
        dist, _ = cKDTree(points).query(points, k=2)
        cluster_tolerance = 5.0 * float(np.median(dist[:, 1]))
        if cluster_tolerance <= 0:
            cluster_tolerance = 5.0 * float(dist[:, 1].max())
    keep = low_curvature(points, n_neighbors, curvature_threshold)
    cos_eps = np.cos(eps_angle)
    raw = smooth_clusters(points, normals, keep, cluster_tolerance, cos_eps, min_points)
    cos_refine = np.cos(eps_angle * refine)
    clusters = []
    for cl in raw:
        avg = normals[cl].mean(axis=0)
        norm = np.linalg.norm(avg)
        if norm == 0:
            continue
        avg /= norm
        ref = cl[normals[cl] @ avg > cos_refine]
        if ref.size:
            clusters.append(ref)
    if not clusters:
        clusters = [np.arange(n)]
    sigs, owners = [], []
    for ci, cl in enumerate(clusters):
        c = points[cl].mean(axis=0)
        nc = normals[cl].mean(axis=0)
        norm = np.linalg.norm(nc)
        nc = nc / norm if norm > 1e-12 else np.array([0.0, 0.0, 1.0])
        f1, f2, f3 = pair_features(c, nc, points, normals)
        angles = np.concatenate([_angle_hist(f1), _angle_hist(f2), _angle_hist(f3)])
        # Viewpoint component, viewpoint at the origin (the object's centroid).
        vp = -c
        vn = np.linalg.norm(vp)
        vp = vp / vn if vn > 0 else np.zeros(3)
        alpha = (normals @ vp + 1.0) * 0.5
        vbin = np.clip(np.floor(alpha * N_VIEW_BINS).astype(np.int64), 0, N_VIEW_BINS - 1)
        view = np.bincount(vbin, minlength=N_VIEW_BINS).astype(np.float64)[N_VIEW_BINS - VIEW_KEPT :]
        for frame in _sgurf(points, normals, cl, c, nc, axis_ratio, min_axis_value):
            local = (points - c) @ frame.T
            sigs.append(np.concatenate([angles, _octant_hist(local, sigma), view]))
            owners.append(ci)
    return sigs, owners, clusters


class OURCVFHTransformer(PointCloudDescriptor):
    """Oriented, Unique and Repeatable Clustered Viewpoint Feature Histogram.

    OUR-CVFH (Aldoma et al. 2012) after PCL 1.13's ``OURCVFHEstimation``:
    points of high curvature are removed, the rest grown into smooth regions
    (clusters); for each cluster a VFH is computed against the cluster's
    centroid and mean normal, a semi-global unique reference frame (SGURF)
    is fixed, and the object's points are histogrammed over the frame's 8
    octants and 13 distance shells. Each signature has 308 bins; the
    ``aggregate`` parameter turns the several signatures of an object into
    one row.

    Read more in the paper's baseline section (Bobkov et al. 2018, Table II).

    Parameters
    ----------
    aggregate : {"largest", "first", "mean"}, default="largest"
        One row per object from its signatures (one per cluster and frame):
        the first frame's signature of the cluster with most points, PCL's
        first signature (the cluster met first in point order), or the mean
        of all signatures.
    scaling : {"object", "fit", "none"}, default="object"
        Every object is centered on its mean; then scaled so its largest
        bounding-box side is 1 (``"object"``, as PCL's reference runs), by
        one factor learnt in ``fit`` so the largest training object's side
        is 1 (``"fit"``), or not at all. Distances below are in these units.
        ``"object"`` takes clouds of any finite magnitude (they are first
        rescaled by an exact power of two); with ``"fit"`` and ``"none"``, a
        cloud whose largest side is below ``2**-100`` or whose coordinates
        exceed ``2**100`` in magnitude gets a ``ValueError``, since ``sigma``
        and ``cluster_tolerance`` would no longer be in its units.
    curvature_threshold : float, default=0.03
        Points whose surface variation ``lambda_min / sum(lambda)`` over
        ``n_neighbors`` exceeds it are left out of the clusters (PCL's
        default; 1.0 switches the filter off).
    eps_angle : float, default=0.125
        Largest angle in radians between the normals of neighboring points
        of one region, and between a member's normal and the region's mean
        normal (PCL's default).
    cluster_tolerance : float or None, default=None
        Largest distance between neighboring points of one region; None:
        five times the object's median nearest-neighbor distance.
    min_points : int, default=50
        Smallest region kept (PCL's default).
    axis_ratio : float, default=0.8
        When the two in-plane axes are about equally hard to disambiguate
        (ratio of their disambiguation factors above this), the cluster gets
        2 or 4 frames (PCL's default).
    sigma : float, default=0.01
        Softness of the octant boundaries (PCL: 1 cm; here in scaled units).
    normalize : bool, default=True
        Divide each row by its sum (needed for KL matching); False keeps
        PCL's raw counts.
    n_neighbors : int, default=10
        Neighborhood size for PCA normals (of clouds given without normals)
        and for the curvature.
    normal_orientation : {"centroid", "origin"} or None, default="centroid"
        Sign of estimated normals: away from the object's centroid, towards
        the origin, or unoriented (as in :class:`eppf.descriptors.EPPFTransformer`).
    n_jobs : int, default=None
        Threads over objects, with joblib's meaning for integers (``-1``:
        all cores); None is the OpenMP default, as for every eppf estimator
        (see :func:`eppf.utils.check_n_jobs`). Output does not depend on it.

    Attributes
    ----------
    scale_ : float
        The scale factor learnt with ``scaling="fit"`` (1.0 otherwise).
    n_features_out_ : int
        308.

    See Also
    --------
    ESFTransformer : Ensemble of shape functions.
    WahlTransformer : Surflet-pair-relation histograms.

    Notes
    -----
    Signature layout (PCL's ``VFHSignature308`` as OUR-CVFH fills it):
    bins 0-134 the three VFH angles (45 bins each over ``[-pi, pi]``, PCL's
    binning, so the cosines f2 and f3 only reach bins 15-29), bins 135-238
    the 8 x 13 octant-shell distribution (octant ``4 [x >= 0] + 2 [y >= 0] +
    [z >= 0]``, shells ``ceil(13 d / d_max) - 1``, soft weights
    ``0.5 +- 0.5 (1 - exp(-x^2 / (2 sigma^2)))`` per axis), bins 239-307 the
    upper 69 of the 128 viewpoint bins (viewpoint at the object's centroid).

    Differences from PCL: normals for region growing are the input (or PCA)
    normals rather than a second radius-based estimate; the cluster
    tolerance defaults to a multiple of the point spacing so clusters form
    on sparse clouds; an object without any cluster is described as one
    cluster of all its points (PCL falls back to a plain VFH with a
    different layout). No randomness: the output is deterministic, bit for
    bit for any ``n_jobs``. Its curvature filter is compiled and decides alike
    on every CPU; across CPUs its reference frames, octant weights and angles
    (NumPy and LAPACK) can differ in the last bit, which can move points
    between regions or bins (class (b) of the documentation's Reproducibility
    page).

    References
    ----------
    .. [1] A. Aldoma, F. Tombari, R. B. Rusu and M. Vincze, "OUR-CVFH -
       Oriented, Unique and Repeatable Clustered Viewpoint Feature Histogram
       for Object Recognition and 6DOF Pose Estimation", DAGM-OAGM 2012.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import OURCVFHTransformer
    >>> rng = np.random.default_rng(0)
    >>> box = rng.uniform(-1, 1, size=(600, 3))
    >>> box[np.arange(600), rng.integers(0, 3, 600)] = rng.choice([-1.0, 1.0], 600)
    >>> X = OURCVFHTransformer().fit_transform([box])
    >>> X.shape
    (1, 308)
    """

    def __init__(
        self,
        aggregate="largest",
        scaling="object",
        curvature_threshold=0.03,
        eps_angle=0.125,
        cluster_tolerance=None,
        min_points=50,
        axis_ratio=0.8,
        sigma=0.01,
        normalize=True,
        n_neighbors=10,
        normal_orientation="centroid",
        n_jobs=None,
    ):
        self.aggregate = aggregate
        self.scaling = scaling
        self.curvature_threshold = curvature_threshold
        self.eps_angle = eps_angle
        self.cluster_tolerance = cluster_tolerance
        self.min_points = min_points
        self.axis_ratio = axis_ratio
        self.sigma = sigma
        self.normalize = normalize
        self.n_neighbors = n_neighbors
        self.normal_orientation = normal_orientation
        self.n_jobs = n_jobs

    _parameter_constraints = {
        "aggregate": [StrOptions(["largest", "first", "mean"])],
        "scaling": SCALING,
        "curvature_threshold": [Interval(numbers.Real, 0, None, closed="neither")],
        "eps_angle": [Interval(numbers.Real, 0, np.pi, closed="right")],
        "cluster_tolerance": [None, Interval(numbers.Real, 0, None, closed="neither")],
        "min_points": [Interval(numbers.Integral, 1, None, closed="left")],
        "axis_ratio": [Interval(numbers.Real, 0, 1, closed="right")],
        "sigma": [Interval(numbers.Real, 0, None, closed="neither")],
        "normalize": [Options(bool)],
        "n_neighbors": N_NEIGHBORS,
        "normal_orientation": NORMAL_ORIENTATION,
        "n_jobs": N_JOBS,
    }

    def _resolve_params(self):
        params = dict(
            curvature_threshold=float(self.curvature_threshold),
            eps_angle=float(self.eps_angle),
            cluster_tolerance=None if self.cluster_tolerance is None else float(self.cluster_tolerance),
            min_points=int(self.min_points),
            axis_ratio=float(self.axis_ratio),
            sigma=float(self.sigma),
            n_neighbors=int(self.n_neighbors),
        )
        return params, check_n_jobs(self.n_jobs, owner=type(self).__name__)

    _min_points = 3

    def _learn(self, clouds, params):
        self.scale_ = self._fit_scale(clouds)

    def _n_features(self, params):
        return N_FEATURES

    def _feature_names(self):
        names = [f"ourcvfh_{f}_{i}" for f in ("f1", "f2", "f3") for i in range(N_ANGLE_BINS)]
        names += [f"ourcvfh_octant{k}_shell{j}" for k in range(N_OCTANTS) for j in range(N_SHELLS)]
        names += [f"ourcvfh_view_{i}" for i in range(N_VIEW_BINS - VIEW_KEPT, N_VIEW_BINS)]
        return names

    def _one(self, pts, nrm, params):
        pts = pts - pts.mean(axis=0)
        if self.scaling == "object":
            pts = pts / np.ptp(pts, axis=0).max()
        elif self.scaling == "fit":
            pts = pts * self.scale_
        sigs, owners, clusters = _ourcvfh_object(pts, nrm, **params)
        if self.aggregate == "mean":
            row = np.mean(sigs, axis=0)
        elif self.aggregate == "first":
            row = sigs[0]
        else:
            sizes = [len(c) for c in clusters]
            row = sigs[owners.index(int(np.argmax(sizes)))]
        if self.normalize:
            row = row / row.sum()
        return row

    def _describe(self, clouds, params, *, first_index):
        """OUR-CVFH rows of one chunk of packed clouds."""
        params, n_threads = params
        points, normals, offsets = self._points_and_normals(
            clouds, params["n_neighbors"], self.normal_orientation, n_threads
        )
        spans = [(offsets[k], offsets[k + 1]) for k in range(len(clouds))]
        if n_threads == 1:
            rows = [self._one(points[a:b], normals[a:b], params) for a, b in spans]
        else:
            rows = Parallel(n_jobs=n_threads, prefer="threads")(
                delayed(self._one)(points[a:b], normals[a:b], params) for a, b in spans
            )
        return np.vstack(rows)
