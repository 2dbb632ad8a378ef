"""OUR-CVFH, Aldoma et al. (2012), after PCL 1.13's ``OURCVFHEstimation``, in NumPy/SciPy."""

import numbers

import numpy as np
from joblib import Parallel, delayed
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from ._esf import _check_int
from ._chunks import transform_in_chunks
from ._validation import check_n_jobs, check_point_clouds, condition_point_clouds
from ._wahl import _points_and_normals

__all__ = ["OURCVFHTransformer"]

N_ANGLE_BINS = 45
N_VIEW_BINS = 128
N_OCTANTS = 8
N_SHELLS = 13
# PCL writes the 8 x 13 shape distribution over bins 135-238 of the 308-bin
# VFH signature, so only the viewpoint bins 59-127 survive at 239-307.
VIEW_KEPT = 308 - 3 * N_ANGLE_BINS - N_OCTANTS * N_SHELLS
N_FEATURES = 308


def _check_float(value, name, owner, low=0.0, low_open=True, high=None):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{owner}: {name} must be a float, got {type(value).__name__}")
    value = float(value)
    bad = not np.isfinite(value) or (value <= low if low_open else value < low) or (high is not None and value > high)
    if bad:
        rng = f"> {low}" if low_open else f">= {low}"
        if high is not None:
            rng += f" and <= {high}"
        raise ValueError(f"{owner}: {name} must be finite and {rng}, got {value}")
    return value


def _curvature(points, k):
    """Surface variation lambda_min / sum(lambda) of the k nearest neighbours."""
    n = points.shape[0]
    k = min(k, n)
    _, idx = cKDTree(points).query(points, k=k)
    nb = points[idx.reshape(n, k)]
    nb = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    ev = np.linalg.eigvalsh(cov)
    total = ev.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        curv = np.where(total > 0, ev[:, 0] / total, 0.0)
    return np.clip(curv, 0.0, None)


def _smooth_clusters(points, normals, keep, tolerance, cos_eps, min_points):
    """Components of the graph 'closer than tolerance and normals within eps'.

    This is what PCL's seeded region growing returns: a point joins a region
    when a member within ``tolerance`` has a normal less than eps away.
    Returns a list of index arrays (into ``points``), in order of their
    lowest index, with at least ``min_points`` points each.
    """
    sub = np.flatnonzero(keep)
    if sub.size == 0:
        return []
    pairs = cKDTree(points[sub]).query_pairs(tolerance, output_type="ndarray")
    if pairs.size:
        dots = np.einsum("ij,ij->i", normals[sub[pairs[:, 0]]], normals[sub[pairs[:, 1]]])
        pairs = pairs[dots > cos_eps]
    m = sub.size
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    n_comp, labels = connected_components(graph, directed=False)
    counts = np.bincount(labels, minlength=n_comp)
    # Order the components by their first member, like PCL's scan.
    first = np.full(n_comp, m, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(m))
    clusters = []
    for c in np.argsort(first, kind="stable"):
        if counts[c] >= min_points:
            clusters.append(sub[labels == c])
    return clusters


def _pair_features(c, nc, points, normals):
    """PCL's pair features (f1, f2, f3) of (c, nc) against every point.

    Source is the more parallel normal (PCL's rule): with d = p - c,
    u = source normal, v = d x u / |d x u|, w = u x v: f1 = atan2(w . n_t,
    u . n_t), f2 = v . n_t, f3 = u . d / |d|. Undefined pairs are dropped.
    """
    d = points - c
    dist = np.linalg.norm(d, axis=1)
    ok = dist > 0
    d, dist, nt_all = d[ok], dist[ok], normals[ok]
    dh = d / dist[:, None]
    a1 = dh @ nc
    a2 = np.einsum("ij,ij->i", nt_all, dh)
    swap = np.arccos(np.clip(np.abs(a1), 0, 1)) > np.arccos(np.clip(np.abs(a2), 0, 1))
    u = np.where(swap[:, None], nt_all, nc[None, :])
    nt = np.where(swap[:, None], nc[None, :], nt_all)
    dd = np.where(swap[:, None], -d, d)
    f3 = np.where(swap, -a2, a1)
    v = np.cross(dd, u)
    vn = np.linalg.norm(v, axis=1)
    good = vn > 0
    v = v[good] / vn[good, None]
    u, nt, f3 = u[good], nt[good], f3[good]
    w = np.cross(u, v)
    f1 = np.arctan2(np.einsum("ij,ij->i", w, nt), np.einsum("ij,ij->i", u, nt))
    f2 = np.einsum("ij,ij->i", v, nt)
    return f1, f2, f3


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
    """OUR-CVFH signatures of one centred, scaled object.

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
    keep = _curvature(points, n_neighbors) <= curvature_threshold
    cos_eps = np.cos(eps_angle)
    raw = _smooth_clusters(points, normals, keep, cluster_tolerance, cos_eps, min_points)
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
        f1, f2, f3 = _pair_features(c, nc, points, normals)
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


class OURCVFHTransformer(TransformerMixin, BaseEstimator):
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
        Every object is centred on its mean; then scaled so its largest
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
        Largest angle in radians between the normals of neighbouring points
        of one region, and between a member's normal and the region's mean
        normal (PCL's default).
    cluster_tolerance : float or None, default=None
        Largest distance between neighbouring points of one region; None:
        five times the object's median nearest-neighbour distance.
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
        Neighbourhood size for PCA normals (of clouds given without normals)
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
    different layout). No randomness: the output is deterministic.

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

    def _check_params(self):
        owner = type(self).__name__
        if self.aggregate not in ("largest", "first", "mean"):
            raise ValueError(f"{owner}: aggregate must be 'largest', 'first' or 'mean', got {self.aggregate!r}")
        if self.scaling not in ("object", "fit", "none"):
            raise ValueError(f"{owner}: scaling must be 'object', 'fit' or 'none', got {self.scaling!r}")
        params = dict(
            curvature_threshold=_check_float(self.curvature_threshold, "curvature_threshold", owner),
            eps_angle=_check_float(self.eps_angle, "eps_angle", owner, high=np.pi),
            cluster_tolerance=None
            if self.cluster_tolerance is None
            else _check_float(self.cluster_tolerance, "cluster_tolerance", owner),
            min_points=_check_int(self.min_points, "min_points", owner, 1),
            axis_ratio=_check_float(self.axis_ratio, "axis_ratio", owner, high=1.0),
            sigma=_check_float(self.sigma, "sigma", owner),
            n_neighbors=_check_int(self.n_neighbors, "n_neighbors", owner, 3),
        )
        if self.normal_orientation not in ("centroid", "origin", None):
            raise ValueError(
                f"{owner}: normal_orientation must be 'centroid', 'origin' or None, got {self.normal_orientation!r}"
            )
        if not isinstance(self.normalize, (bool, np.bool_)):
            raise TypeError(f"{owner}: normalize must be a bool, got {type(self.normalize).__name__}")
        n_threads = 1 if self.n_jobs is None else check_n_jobs(self.n_jobs, owner=owner)
        return params, n_threads

    def fit(self, X, y=None):
        """Check the parameters and clouds; learn the scale for ``scaling="fit"``.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 3 points, with normals in columns 3-5
            when available.
        y : None
            Ignored.

        Returns
        -------
        self : OURCVFHTransformer
            The fitted transformer.
        """
        self._check_params()
        clouds = check_point_clouds(X, owner=type(self).__name__, min_points=3)
        self.scale_ = 1.0
        if self.scaling == "fit":
            with np.errstate(over="ignore"):
                side = max(float(np.ptp(c[:, :3], axis=0).max()) for c in clouds)
            self.scale_ = 1.0 / side if side > 0 else np.inf
            if not (np.isfinite(side) and np.isfinite(self.scale_) and self.scale_ > 0):
                raise ValueError(
                    f"{type(self).__name__}: the largest training object's side ({side:.3g}) is out of float64's "
                    "range for one data-set scale (1 / side must be finite and non-zero); rescale the data or "
                    "use scaling='object'"
                )
        self.n_features_out_ = N_FEATURES
        return self

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

    def transform(self, X):
        """Compute one OUR-CVFH row per cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds of at least 3 points; normals are estimated for
            clouds with three columns.

        Returns
        -------
        X_new : ndarray of shape (n_objects, 308)
            One row per cloud (summing to one when ``normalize``).
        """
        check_is_fitted(self)
        owner = type(self).__name__
        params, n_threads = self._check_params()
        clouds = check_point_clouds(X, owner=owner, min_points=3, n_threads=n_threads)
        # Exact 2**e rescaling of clouds outside the safe magnitude window; only
        # scaling="object" is invariant to it (the others apply sigma and
        # cluster_tolerance in the input's units).
        exps = condition_point_clouds(clouds, owner=owner)
        if self.scaling != "object" and exps.any():
            k = int(np.flatnonzero(exps)[0])
            raise ValueError(
                f"{owner}: point cloud {k} has coordinates out of the magnitude range this estimator computes in "
                f"without overflow or underflow (largest side >= 2**-100, |coordinates| <= 2**100); with "
                f"scaling={self.scaling!r} its lengths are taken in the input's units, so rescale the data or "
                "use scaling='object'"
            )
        return transform_in_chunks(_ourcvfh_chunk, self, clouds, n_features=308)

    def get_feature_names_out(self, input_features=None):
        """Names of the output columns.

        Parameters
        ----------
        input_features : None
            Ignored (point clouds have no input feature names).

        Returns
        -------
        feature_names_out : ndarray of str
            ``ourcvfh_f1_<i>``, ``_f2_``, ``_f3_``, ``ourcvfh_octant<k>_shell<j>``,
            ``ourcvfh_view_<i>`` (i = 59..127), in the output's order.
        """
        check_is_fitted(self)
        names = [f"ourcvfh_{f}_{i}" for f in ("f1", "f2", "f3") for i in range(N_ANGLE_BINS)]
        names += [f"ourcvfh_octant{k}_shell{j}" for k in range(N_OCTANTS) for j in range(N_SHELLS)]
        names += [f"ourcvfh_view_{i}" for i in range(N_VIEW_BINS - VIEW_KEPT, N_VIEW_BINS)]
        return np.asarray(names, dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        return tags


def _ourcvfh_chunk(est, clouds, first_index):
    """OUR-CVFH rows of one chunk of validated clouds (a joblib task)."""
    owner = type(est).__name__
    params, n_threads = est._check_params()
    points, normals, offsets = _points_and_normals(
        clouds, params["n_neighbors"], est.normal_orientation, n_threads, owner
    )
    spans = [(offsets[k], offsets[k + 1]) for k in range(len(clouds))]
    if n_threads == 1:
        rows = [est._one(points[a:b], normals[a:b], params) for a, b in spans]
    else:
        rows = Parallel(n_jobs=n_threads, prefer="threads")(
            delayed(est._one)(points[a:b], normals[a:b], params) for a, b in spans
        )
    return np.vstack(rows)
