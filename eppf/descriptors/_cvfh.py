"""Clustered Viewpoint Feature Histogram (CVFH), Aldoma et al. (2011), as in PCL 1.13."""

import numbers

import numpy as np
from joblib import Parallel, delayed
from scipy.spatial import cKDTree

from ..utils._param_validation import Interval, Options, StrOptions
from ._base import N_JOBS, N_NEIGHBORS, NORMAL_ORIENTATION, SCALING, PointCloudDescriptor
from ._cvfh_fast import crowded_points, pcl_region_growing, vfh_signatures
from ._regions import low_curvature, radius_neighbors_flann, smooth_clusters

__all__ = ["CVFHTransformer"]

N_ANGLE_BINS = 45
N_VIEW_BINS = 128
#: A length in the scaled cloud's units.
_LENGTH = [Interval(numbers.Real, 1e-15, 1e15, closed="both", description="a float in [1e-15, 1e+15]")]
N_FEATURES = 4 * N_ANGLE_BINS + N_VIEW_BINS  # 308, PCL's VFHSignature308
#: Most neighbor pairs the radius searches of one object may hold in memory.
MAX_PAIRS = 5_000_000


def _f32_mean(a):
    """Single-precision mean with sequential sums (Eigen's accumulation in PCL)."""
    return np.cumsum(a.astype(np.float32), axis=0, dtype=np.float32)[-1] / np.float32(len(a))


def _radius_normals(points, radius):
    """PCL's NormalEstimation with a radius search, viewpoint at the origin.

    PCA normal of the points strictly closer than ``radius`` (the point
    itself included), flipped to face the origin; NaN where fewer than three
    points are that close.
    """
    n = len(points)
    out = np.full((n, 3), np.nan)
    pairs = cKDTree(points).query_pairs(np.nextafter(radius, 0.0), output_type="ndarray")
    if len(pairs) == 0:
        return out
    i, j = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])
    count = np.bincount(i, minlength=n) + 1
    ok = np.flatnonzero(count >= 3)
    if ok.size == 0:
        return out
    # moments about each point (the point itself contributes zero)
    d = points[j] - points[i]
    s1 = np.stack([np.bincount(i, weights=d[:, a], minlength=n) for a in range(3)], 1)[ok]
    s2 = np.empty((ok.size, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            s2[:, a, b] = s2[:, b, a] = np.bincount(i, weights=d[:, a] * d[:, b], minlength=n)[ok]
    k = count[ok].astype(np.float64)[:, None]
    mean = s1 / k
    cov = s2 / k[:, :, None] - mean[:, :, None] * mean[:, None, :]
    _, vecs = np.linalg.eigh(cov)
    nrm = vecs[:, :, 0]
    flip = np.einsum("ij,ij->i", -points[ok], nrm) < 0
    nrm[flip] *= -1.0
    out[ok] = nrm
    return out


def _cvfh_regions(points, normals, *, eps_angle, curvature_threshold, cluster_tolerance, radius_normals,
                  min_points, n_neighbors, region_growing="components", **_):
    """Stable regions of one centered, scaled object and their references.

    Returns ``(clusters, centroids, ref_normals)``: the regions as arrays of
    point indices in PCL's order (by lowest index), and float32 (m, 3)
    arrays of their centroids and unit mean (second) normals; without any
    region, ``[]`` and PCL's fallback: the object's centroid and its
    unnormalised mean input normal.
    """
    p32 = points.astype(np.float32)
    n = len(points)
    if curvature_threshold < 0.5:  # surface variation never exceeds 1/3
        keep = np.flatnonzero(low_curvature(points, n_neighbors, curvature_threshold))
    else:
        keep = np.arange(n)
    clusters = []
    if keep.size >= min_points:
        sub = p32[keep].astype(np.float64)
        if keep.size * (keep.size - 1) // 2 > MAX_PAIRS:
            tree = cKDTree(sub)
            pairs = (tree.count_neighbors(tree, max(radius_normals, cluster_tolerance)) - keep.size) // 2
            if pairs > MAX_PAIRS:
                raise ValueError(
                    f"radius_normals and cluster_tolerance give {pairs} neighbour pairs, more than "
                    f"{MAX_PAIRS}: use smaller radii"
                )
        # Fewer than min_points points with two neighbors within radius_normals: no point
        # count below can reach min_points, and the second normals are not needed.
        crowded = crowded_points(sub, radius_normals, min_points) >= min_points
        rn = _radius_normals(sub, radius_normals) if crowded else np.full((len(sub), 3), np.nan)
        finite = np.isfinite(rn[:, 0])
        if finite.sum() >= min_points and region_growing == "pcl":
            nbr, off = radius_neighbors_flann(p32[keep], float(np.float32(cluster_tolerance)))
            labels = np.empty(len(sub), dtype=np.int64)
            m = pcl_region_growing(nbr, off, rn.astype(np.float32), float(np.float32(eps_angle)), min_points, labels)
            clusters = [np.flatnonzero(labels == c) for c in range(m)]
        elif finite.sum() >= min_points:
            tol = float(np.nextafter(cluster_tolerance, 0.0))
            cos_eps = float(np.cos(np.float64(np.float32(eps_angle))))
            clusters = smooth_clusters(sub, np.where(finite[:, None], rn, 0.0), finite, tol, cos_eps, min_points)
    if not clusters:
        return [], _f32_mean(p32)[None, :], _f32_mean(normals.astype(np.float32))[None, :]
    cents, refs = [], []
    for cl in clusters:
        cents.append(_f32_mean(sub[cl]))
        avg = _f32_mean(rn[cl])
        # Eigen's Vector4f normalization: |v|^2 summed as (x^2 + z^2) + y^2
        refs.append(avg / np.sqrt(np.float32(avg[0] * avg[0] + avg[2] * avg[2]) + np.float32(avg[1] * avg[1])))
    return [keep[cl] for cl in clusters], np.asarray(cents, np.float32), np.asarray(refs, np.float32)


def _cvfh_object(points, normals, **params):
    """CVFH signatures of one centered, scaled object.

    Returns ``(signatures, sizes)``: an (m, 308) array, one row per stable
    region in PCL's order, and the regions' point counts; without any
    region, one row of the whole object and ``[n]``.
    """
    clusters, cents, refs = _cvfh_regions(points, normals, **params)
    out = np.empty((len(cents), N_FEATURES), dtype=np.float64)
    vfh_signatures(points.astype(np.float32), normals.astype(np.float32), np.ascontiguousarray(cents),
                   np.ascontiguousarray(refs), params["normalize_bins"], out)
    return out, [len(c) for c in clusters] or [len(points)]


class CVFHTransformer(PointCloudDescriptor):
    """Clustered Viewpoint Feature Histogram (CVFH) of point clouds.

    CVFH (Aldoma et al. 2011) after PCL 1.13's ``CVFHEstimation``: points of
    high curvature are left out, the rest are grown into smooth regions, and
    every stable region (at least ``min_points`` points) gets a Viewpoint
    Feature Histogram of the *whole* object computed against the region's
    centroid and mean normal: three angle histograms, the shape distribution
    component (distances to the centroid) and the viewpoint component, 308
    bins (PCL's ``VFHSignature308``). ``aggregate`` turns an object's
    signatures into one row. How often the first signature equals PCL's row
    on the PCL reference runs is in :ref:`api-figures-pcl` of the
    documentation.

    Read more in the paper's baseline section (Bobkov et al. 2018).

    Parameters
    ----------
    aggregate : {"largest", "first", "mean"}, default="largest"
        One row per object from its signatures (one per region): the
        signature of the region with most points, PCL's first signature (the
        region met first in point order, as the PCL reference runs keep), or
        the mean of all signatures.
    scaling : {"object", "fit", "none"}, default="object"
        Every object is centered on its mean; then scaled so its largest
        bounding-box side is 1 (``"object"``, as PCL's reference runs), by
        one factor learnt in ``fit`` so the largest training object's side
        is 1 (``"fit"``), or not at all. Distances below are in these units
        (PCL's defaults are meters).
    eps_angle : float, default=0.125
        Largest angle in radians between the normals of neighboring points
        of one region (PCL's default; the reference runs used 5 degrees).
    curvature_threshold : float, default=0.03
        Points whose surface variation ``lambda_min / sum(lambda)`` over
        ``n_neighbors`` neighbors exceeds it are left out of the regions
        (PCL's default; the reference runs used 1.0, which keeps every point).
    cluster_tolerance : float, default=0.015
        Points strictly closer than this are neighbors in region growing
        (PCL's default, three times its 5 mm leaf size).
    radius_normals : float, default=0.015
        Radius of the second normal estimate that region growing uses
        (PCL's default); points with fewer than three points that close
        (themselves included) get no normal and join no region.
    min_points : int, default=50
        Smallest stable region, and smallest number of points left by the
        curvature filter for regions to be grown at all (PCL's default).
    region_growing : {"components", "pcl"}, default="components"
        ``"components"``: the regions are the connected components of the
        "close and similar normals" graph, the region growing shared with
        :class:`eppf.OURCVFHTransformer`. ``"pcl"``: PCL's seeded growth
        step by step, which skips the first point of each radius search
        (see Notes) and so reproduces PCL's regions.
    normalize_bins : bool, default=False
        PCL's option: each angle and distance bin counts ``100 / (n - 1)``
        per point and each viewpoint bin ``100 / n``, instead of 1.
    normalize : bool, default=True
        Divide each row by its sum (needed for KL matching); False with
        ``normalize_bins=False`` keeps PCL's raw counts.
    n_neighbors : int, default=10
        Neighborhood size for PCA normals (of clouds given without normals)
        and for the curvature.
    normal_orientation : {"centroid", "origin"} or None, default="centroid"
        Sign of estimated normals: away from the object's centroid, towards
        the origin, or unoriented (as in :class:`eppf.EPPFTransformer`).
    n_jobs : int, default=None
        Threads over objects (joblib); None means 1. Output does not depend
        on it.

    Attributes
    ----------
    scale_ : float
        The scale factor learnt with ``scaling="fit"`` (1.0 otherwise).
    n_features_out_ : int
        308.

    See Also
    --------
    OURCVFHTransformer : CVFH with semi-global reference frames.
    GRSDTransformer : Global radius-based surface descriptor.

    Notes
    -----
    Regions: the points that pass the curvature filter get normals from a
    radius search (``radius_normals``, PCA, facing the viewpoint at the
    origin, i.e. the object's centroid); two of them are linked when closer
    than ``cluster_tolerance`` with normals less than ``eps_angle`` apart,
    and the regions are the connected components (the same region growing
    as :class:`eppf.OURCVFHTransformer`). Region ``r`` has centroid ``c_r``
    and normal ``n_r``, the normalized mean of its (second) normals.

    Signature of a region, over all ``n`` points ``p_i`` with their input
    normals ``n_i``: PCL's pair features of ``(c_r, n_r)`` and ``(p_i,
    n_i)``: with ``d = p_i - c_r`` the source is the point whose normal is
    more parallel to ``d``; ``u`` its normal, ``v = d x u / |d x u|``,
    ``w = u x v``: ``f1 = atan2(w . n_t, u . n_t)``, ``f2 = v . n_t``,
    ``f3 = u . d / |d|``, each binned as ``floor(45 (f + pi) / (2 pi))``
    (so the cosines f2 and f3 only reach bins 15-29, as in PCL), and the
    shape distribution component ``f4 = |d|``, bin ``floor(45 |d| / max_j
    |p_j - c_r|)``. Pairs with ``d = 0`` or ``d`` parallel to ``u`` are
    left out. Viewpoint component: ``floor(128 (n_i . v + 1) / 2)`` with
    ``v`` the unit vector from ``c_r`` to the origin. Layout: f1, f2, f3,
    f4 (45 bins each), viewpoint (128).

    Without any region PCL describes the whole object: its centroid and its
    *unnormalised* mean input normal. After centering that centroid is a
    rounding residue, so its direction to the origin, and with it the
    viewpoint component, is arbitrary: we reproduce PCL's single-precision
    arithmetic to match its rows, but that component is then neither
    rotation invariant nor stable under tiny perturbations. With regions,
    CVFH is invariant to rotation about the object's centroid. On sparse
    clouds (1,024 points over a unit object are about 0.03 apart) PCL's
    defaults of 0.015 give no region at all; larger ``radius_normals`` and
    ``cluster_tolerance`` do.

    Region growing: PCL grows a region from each unassigned seed in point
    order, adding the unassigned neighbors (radius search) of each member
    whose normal is within ``eps_angle`` of that member's. It skips the
    first point each search returns, assuming it is the query itself; but
    PCL's k-d tree search is unsorted and returns points in its depth-first
    order, so a true neighbor is sometimes skipped and PCL's regions can be
    smaller or split. ``region_growing="components"`` (the default) links
    every such pair; ``"pcl"`` rebuilds FLANN's tree to skip the same points
    as PCL, and so reproduces PCL's regions more often (figures:
    :ref:`api-figures-pcl`). The
    second normals are computed in double precision (PCL: single). No
    randomness: the output is deterministic, bit for bit for any ``n_jobs``.
    The curvature filter is compiled and decides alike on every CPU; across
    CPUs the second normals (LAPACK) can differ in their last bit, which moves
    a point only where its normal lies within that bit of ``eps_angle`` from a
    neighbor's (class (b) of the documentation's Reproducibility page).

    References
    ----------
    .. [1] A. Aldoma, M. Vincze, N. Blodow, D. Gossow, S. Gedikli, R. B. Rusu
       and G. Bradski, "CAD-model recognition and 6DOF pose estimation using
       3D cues", ICCV Workshops (3dRR), 2011.
    .. [2] R. B. Rusu, G. Bradski, R. Thibaux and J. Hsu, "Fast 3D
       recognition and pose using the Viewpoint Feature Histogram", IROS
       2010.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.datasets import make_shapes
    >>> from eppf.descriptors import CVFHTransformer
    >>> X, y = make_shapes(2, n_points=512, return_X_y=True)
    >>> C = CVFHTransformer().fit_transform(X)
    >>> C.shape
    (20, 308)
    >>> bool(np.allclose(C.sum(axis=1), 1.0))
    True
    """

    def __init__(
        self,
        aggregate="largest",
        scaling="object",
        eps_angle=0.125,
        curvature_threshold=0.03,
        cluster_tolerance=0.015,
        radius_normals=0.015,
        min_points=50,
        region_growing="components",
        normalize_bins=False,
        normalize=True,
        n_neighbors=10,
        normal_orientation="centroid",
        n_jobs=None,
    ):
        self.aggregate = aggregate
        self.scaling = scaling
        self.eps_angle = eps_angle
        self.curvature_threshold = curvature_threshold
        self.cluster_tolerance = cluster_tolerance
        self.radius_normals = radius_normals
        self.min_points = min_points
        self.region_growing = region_growing
        self.normalize_bins = normalize_bins
        self.normalize = normalize
        self.n_neighbors = n_neighbors
        self.normal_orientation = normal_orientation
        self.n_jobs = n_jobs

    _parameter_constraints = {
        "aggregate": [StrOptions(["largest", "first", "mean"])],
        "scaling": SCALING,
        "eps_angle": [Interval(numbers.Real, 0, np.pi, closed="both")],
        "curvature_threshold": [Interval(numbers.Real, 0, 1e300, closed="both")],
        "cluster_tolerance": _LENGTH,
        "radius_normals": _LENGTH,
        "min_points": [Interval(numbers.Integral, 1, None, closed="left")],
        "region_growing": [StrOptions(["components", "pcl"])],
        "normalize_bins": [Options(bool)],
        "normalize": [Options(bool)],
        "n_neighbors": N_NEIGHBORS,
        "normal_orientation": NORMAL_ORIENTATION,
        "n_jobs": N_JOBS,
    }

    _min_points = 3

    def _resolve_params(self):
        params = dict(
            eps_angle=float(self.eps_angle),
            curvature_threshold=float(self.curvature_threshold),
            cluster_tolerance=float(self.cluster_tolerance),
            radius_normals=float(self.radius_normals),
            min_points=int(self.min_points),
            normalize_bins=bool(self.normalize_bins),
            region_growing=self.region_growing,
            n_neighbors=int(self.n_neighbors),
        )
        # None means one thread (see n_jobs).
        return params, self._threads(none_means=1)

    def _learn(self, clouds, params):
        self.scale_ = self._fit_scale(clouds)

    def _n_features(self, params):
        return N_FEATURES

    def _feature_names(self):
        """``cvfh_f1_<i>``, ``cvfh_f2_<i>``, ``cvfh_f3_<i>``, ``cvfh_sdc_<i>`` (distances), ``cvfh_view_<i>``."""
        names = [f"cvfh_{f}_{i}" for f in ("f1", "f2", "f3", "sdc") for i in range(N_ANGLE_BINS)]
        names += [f"cvfh_view_{i}" for i in range(N_VIEW_BINS)]
        return names

    def _row(self, points, normals, params):
        sigs, sizes = _cvfh_object(points, normals, **params)
        if self.aggregate == "mean":
            row = sigs.mean(axis=0)
        elif self.aggregate == "first":
            row = sigs[0]
        else:
            row = sigs[int(np.argmax(sizes))]
        if self.normalize:
            row = row / row.sum()
        return row

    def _describe(self, clouds, params, *, first_index):
        """CVFH rows of one chunk of packed clouds."""
        owner = type(self).__name__
        params, n_threads = params
        points, normals, offsets = self._centred_points_and_normals(clouds, params["n_neighbors"], n_threads)
        with np.errstate(over="ignore"):
            bad = [k for k in range(len(clouds))
                   if not np.isfinite(points[offsets[k] : offsets[k + 1]].astype(np.float32)).all()]
        if bad:
            raise ValueError(
                f"{owner}: point cloud {first_index + bad[0]} has coordinates beyond single precision after "
                "scaling; use scaling='object'"
            )

        def row(k):
            a, b = offsets[k], offsets[k + 1]
            try:
                return self._row(points[a:b], normals[a:b], params)
            except ValueError as exc:
                raise ValueError(f"{owner}: point cloud {first_index + k}: {exc}") from None

        if n_threads == 1:
            rows = [row(k) for k in range(len(clouds))]
        else:
            rows = Parallel(n_jobs=n_threads, prefer="threads")(delayed(row)(k) for k in range(len(clouds)))
        return np.vstack(rows)
