"""Surface normals by the randomized Hough transform of Boulch and Marlet (2012).

The estimator the EPPF paper used for its normals. Unlike PCA, which blends
the planes of a neighborhood, the Hough estimator votes for the dominant
plane: near a sharp edge a point gets the normal of one of the two faces.

The Python layer validates input, finds the k nearest neighbors
(:class:`scipy.spatial.cKDTree`) and draws one seed per object; the voting is
done by the compiled kernel in ``eppf.preprocessing._hough_fast`` (OpenMP over
points). :func:`eppf.preprocessing.estimate_normals` and
:func:`~eppf.preprocessing._normals.estimate_normals_batch` call it for
``method="hough"``.
"""

import math
import numbers

import numpy as np
from scipy.spatial import cKDTree

from ._hough_fast import hough_normals
from ._normal_options import ORIENT_CENTROID, ORIENT_NONE, check_n_neighbors, resolve_orientation
from ..utils._param_validation import RANDOM_STATE, Interval, StrOptions, validate_parameter
from ..utils._validation import check_n_jobs, check_point_cloud, object_seeds

__all__ = ["estimate_normals_hough"]

# Defaults of the authors' released implementation (Boulch and Marlet,
# normals_Hough): 700 triplets per accumulator, 15 polar slices of the
# sphere, 5 random rotations, 0.79 rad to group the rotations' normals.
_DEFAULTS = {"n_triplets": 700, "n_phi": 15, "n_rotations": 5, "cluster_angle": 0.79,
             "tolerance": 0.05, "confidence": 0.95}

# Neighbor indices held at once in the batch path (rows x k), bounding memory.
_MAX_NEIGHBOR_ENTRIES = 1 << 22


#: Most triplets per point and accumulator.
MAX_TRIPLETS = 10_000_000

#: What each Hough parameter accepts (:mod:`eppf.utils._param_validation`).
PARAMETER_CONSTRAINTS = {
    "n_triplets": [Interval(numbers.Integral, 1, MAX_TRIPLETS, closed="both"), StrOptions(["auto"])],
    "n_phi": [Interval(numbers.Integral, 2, 180, closed="both")],
    "n_rotations": [Interval(numbers.Integral, 0, 100, closed="both")],
    "cluster_angle": [Interval(numbers.Real, 0, math.pi / 2, closed="left")],
    "tolerance": [Interval(numbers.Real, 0, 1, closed="neither")],
    "confidence": [Interval(numbers.Real, 0, 1, closed="neither")],
}


def _check_params(params, owner):
    """Validate Hough parameters (dict, unknown keys refused); return a full dict."""
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise TypeError(f"{owner}: method_params must be a dict or None, got {type(params).__name__}")
    unknown = sorted(set(params) - set(_DEFAULTS))
    if unknown:
        raise ValueError(f"{owner}: unknown Hough parameter(s) {unknown}; known: {sorted(_DEFAULTS)}")
    p = dict(_DEFAULTS, **params)
    for name in ("tolerance", "confidence"):  # (first: n_triplets="auto" is computed from them)
        validate_parameter(p[name], PARAMETER_CONSTRAINTS[name], name=name, owner=owner)
        p[name] = float(p[name])
    if isinstance(p["n_triplets"], str) and p["n_triplets"] == "auto":
        p["n_triplets"] = triplets_for(p["tolerance"], p["confidence"])
        if p["n_triplets"] > MAX_TRIPLETS:
            raise ValueError(
                f"{owner}: tolerance={p['tolerance']} and confidence={p['confidence']} ask for "
                f"{p['n_triplets']} triplets per point (more than {MAX_TRIPLETS:,})"
            )
    for name in ("n_triplets", "n_phi", "n_rotations", "cluster_angle"):
        validate_parameter(p[name], PARAMETER_CONSTRAINTS[name], name=name, owner=owner)
    for name in ("n_triplets", "n_phi", "n_rotations"):
        p[name] = int(p[name])
    p["cluster_angle"] = float(p["cluster_angle"])
    return p


def triplets_for(tolerance, confidence):
    """Return the triplets needed for a given accuracy of a bin's share of votes.

    The number of triplets per accumulator such that a bin's share of the
    votes is within ``tolerance`` of its expectation with probability
    ``confidence``, by Hoeffding's inequality
    ``P(|p_hat - p| >= t) <= 2 exp(-2 T t^2)``.

    Parameters
    ----------
    tolerance : float
        Largest accepted error on a bin's share, in (0, 1).
    confidence : float
        Probability that it holds, in (0, 1).

    Returns
    -------
    n_triplets : int
        ``ceil(ln(2 / (1 - confidence)) / (2 tolerance^2))``.

    See Also
    --------
    estimate_normals_hough : Takes it with ``n_triplets="auto"``.

    Examples
    --------
    >>> from eppf.preprocessing._hough import triplets_for
    >>> triplets_for(0.05, 0.95)
    738
    """
    return int(math.ceil(math.log(2.0 / (1.0 - confidence)) / (2.0 * tolerance * tolerance)))


def _orient_packed(pts, off, normals, orientation, owner):
    """Flip normals in place as :func:`estimate_normals` orients PCA normals."""
    mode, viewpoint = resolve_orientation(orientation, owner)
    if mode == ORIENT_NONE or pts.shape[0] == 0:
        return
    sizes = np.diff(off)
    if mode == ORIENT_CENTROID:
        nonempty = sizes > 0
        sums = np.add.reduceat(pts, off[:-1][nonempty], axis=0)
        centroids = np.zeros((sizes.shape[0], 3))
        centroids[nonempty] = sums / sizes[nonempty, None]
        ref = pts - np.repeat(centroids, sizes, axis=0)
    else:
        ref = viewpoint[None, :] - pts
    flip = np.einsum("ij,ij->i", normals, ref) < 0.0
    normals[flip] *= -1.0


def _hough_packed(pts, off, k, seeds, params, n_threads, owner):
    """Unoriented Hough normals of packed objects (each with >= 3 points)."""
    out = np.empty((pts.shape[0], 3), dtype=np.float64)
    sizes = np.diff(off)
    n_obj = sizes.shape[0]
    start = 0
    while start < n_obj:
        # A chunk of objects whose neighbor table stays below the bound.
        stop, entries = start, 0
        while stop < n_obj and (stop == start or entries + sizes[stop] * min(k, sizes[stop]) <= _MAX_NEIGHBOR_ENTRIES):
            entries += sizes[stop] * min(k, sizes[stop])
            stop += 1
        lo, hi = off[start], off[stop]
        kk = int(min(k, sizes[start:stop].max()))
        nbr = np.zeros((hi - lo, kk), dtype=np.int64)
        nvalid = np.empty(hi - lo, dtype=np.int64)
        local = np.empty(hi - lo, dtype=np.int64)
        pseeds = np.empty(hi - lo, dtype=np.uint64)
        scaled = np.empty((hi - lo, 3), dtype=np.float64)
        for o in range(start, stop):
            a, b = off[o] - lo, off[o + 1] - lo
            # Exact rescaling by a power of two (largest |coordinate| in
            # [0.5, 1)): cross products then neither overflow nor underflow,
            # and the normals are those of the unscaled object.
            _, expo = np.frexp(np.abs(pts[off[o]:off[o + 1]]).max())
            obj = scaled[a:b] = np.ldexp(pts[off[o]:off[o + 1]], -int(expo))
            ko = int(min(k, b - a))
            _, idx = cKDTree(obj).query(obj, k=ko, workers=n_threads)
            nbr[a:b, :ko] = idx + a
            nvalid[a:b] = ko
            local[a:b] = np.arange(b - a)
            pseeds[a:b] = seeds[o]
        hough_normals(scaled, nbr, nvalid, pseeds, local, params["n_triplets"], params["n_phi"],
                      params["n_rotations"], params["cluster_angle"], out[lo:hi], n_threads)
        start = stop
    return out


def _check_random_state_seeds(random_state, n_objects, owner):
    """One uint64 seed per object: drawn from ``random_state``, or given as
    an array of ``n_objects`` uint64 seeds (what a descriptor that draws its
    own per-object seeds passes, so that chunking changes nothing)."""
    if isinstance(random_state, np.ndarray):
        if random_state.dtype != np.uint64 or random_state.shape != (n_objects,):
            raise ValueError(
                f"{owner}: per-object seeds must be a uint64 array of shape ({n_objects},), "
                f"got dtype {random_state.dtype} and shape {random_state.shape}"
            )
        return random_state
    if isinstance(random_state, np.random.RandomState) or random_state is None:
        return object_seeds(random_state, n_objects)
    validate_parameter(random_state, RANDOM_STATE, name="random_state", owner=owner)
    return object_seeds(int(random_state), n_objects)


def hough_batch(pts, off, k, orientation, n_threads, random_state, method_params, owner, small_objects=None):
    """Hough normals of validated packed objects (the ``method="hough"`` path
    of :func:`~eppf.preprocessing._normals.estimate_normals_batch`). Objects
    below 3 points get PCA's answer for them (an arbitrary unit vector
    orthogonal to their line) from ``small_objects``, the PCA estimator
    ``estimate_normals_batch`` that calls this (there are none when
    ``small_objects`` is None)."""
    params = _check_params(method_params, owner)
    sizes = np.diff(off)
    seeds = _check_random_state_seeds(random_state, sizes.shape[0], owner)
    out = np.empty((pts.shape[0], 3), dtype=np.float64)
    small = sizes < 3
    if small.any():
        idx = np.flatnonzero(small)
        s_pts = np.concatenate([pts[off[i]:off[i + 1]] for i in idx]) if pts.shape[0] else pts
        s_off = np.concatenate([[0], np.cumsum(sizes[idx])]).astype(np.int64)
        if s_off[-1] > 0:
            est = small_objects(s_pts, s_off, 3, None, n_threads, owner=owner)
            for j, i in enumerate(idx):
                out[off[i]:off[i + 1]] = est[s_off[j]:s_off[j + 1]]
    big = np.flatnonzero(~small)
    if big.size:
        b_pts = np.concatenate([pts[off[i]:off[i + 1]] for i in big]) if big.size < sizes.shape[0] else pts
        b_off = np.concatenate([[0], np.cumsum(sizes[big])]).astype(np.int64)
        est = _hough_packed(np.ascontiguousarray(b_pts), b_off, k, seeds[big], params, n_threads, owner)
        if big.size == sizes.shape[0]:
            out = est
        else:
            for j, i in enumerate(big):
                out[off[i]:off[i + 1]] = est[b_off[j]:b_off[j + 1]]
    _orient_packed(pts, off, out, orientation, owner)
    return out


def estimate_normals_hough(points, n_neighbors=20, *, n_triplets=700, n_phi=15, n_rotations=5,
                           cluster_angle=0.79, tolerance=0.05, confidence=0.95,
                           orientation="centroid", random_state=0, n_jobs=None):
    """Estimate unit surface normals by the randomized Hough transform.

    Boulch and Marlet's estimator [1]_, the one the EPPF paper [2]_ used:
    for each point, random triplets of its ``n_neighbors`` nearest neighbors
    each vote with their plane's normal into an accumulator over the
    directions of the half sphere; the normal is the mean of the votes of the
    most voted bin. Where PCA averages the planes of a neighborhood, this
    picks the dominant one, so normals stay sharp at edges and corners and
    outliers barely move them.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Coordinates of the cloud, at least 3 points, not all identical.
    n_neighbors : int, default=20
        Neighborhood size, the point itself included; at least 3, clipped to
        ``n_points``. The authors used 100 to 200 on dense scans; 20 is
        :class:`eppf.EPPFTransformer`'s default for clouds of about 1,000
        points.
    n_triplets : int or "auto", default=700
        Largest number of triplets drawn per accumulator (the authors'
        implementation's default). ``"auto"`` takes the bound of
        :func:`triplets_for` from ``tolerance`` and ``confidence``.
    n_phi : int, default=15
        Polar slices of the whole sphere (polar step ``pi / n_phi``), as in
        the authors' implementation; bins have about the area of a
        ``pi / n_phi`` square.
    n_rotations : int, default=5
        Accumulators under independent random rotations, which lessens the
        dependence on where bin boundaries fall; 0 means one unrotated
        accumulator.
    cluster_angle : float, default=0.79
        Angle in radians within which the rotations' normals are grouped
        (the authors' default).
    tolerance, confidence : float, default=0.05 and 0.95
        Only used with ``n_triplets="auto"``: the accepted error on a bin's
        share of the votes and the probability that it holds.
    orientation : {"centroid", "origin", "viewpoint"}, array-like of shape (3,) or None, \
default="centroid"
        Sign of the normals, as in :func:`eppf.preprocessing.estimate_normals`.
    random_state : int, RandomState instance or None, default=0
        Seeds the triplets and rotations. One seed is drawn for the cloud and
        each point gets a private generator derived from it and from its
        index, so a fixed value gives the same normals for any ``n_jobs``.
    n_jobs : int, default=None
        OpenMP threads, joblib's meaning (``None``: OpenMP's default).

    Returns
    -------
    normals : ndarray of shape (n_points, 3), dtype float64
        Unit normals. A neighborhood where no triplet spans a plane
        (coincident or collinear points) gets a unit vector orthogonal to
        its line, or (1, 0, 0) when all its points coincide.

    Raises
    ------
    TypeError
        If ``points`` is not numeric array-like or a parameter has the wrong
        type.
    ValueError
        If ``points`` does not have shape (n_points, 3), holds NaN or
        infinite values, has fewer than 3 points or only identical points,
        or if a parameter is out of range.

    See Also
    --------
    eppf.preprocessing.estimate_normals : PCA normals, or these with ``method="hough"``.

    Notes
    -----
    Triplets of three distinct neighbors are drawn uniformly (with
    replacement between triplets); collinear or coincident triplets do not
    vote. Each normal, flipped into ``z >= 0`` of the (rotated) accumulator,
    falls into a ring of polar angle (step ``pi / n_phi``, a cap at the pole)
    and a bin of azimuth; rings hold about as many bins as their area over
    ``(pi / n_phi)^2``, and the ring at the equator identifies azimuths
    ``theta`` and ``theta + pi`` so that opposite normals share one bin.
    Voting stops early once the leading bin's share of the ``t`` votes so far
    exceeds the second's by ``2 / sqrt(t)``, the authors' confidence test.
    Each rotation gives the mean of its winning bin's votes and a confidence
    (that bin's share); the rotations' normals are grouped greedily, most
    confident first, with those within ``cluster_angle``, and the group of
    largest summed confidence gives the confidence-weighted mean.

    Neighbors come from :class:`scipy.spatial.cKDTree`, so points at exactly
    equal distance may be taken in another order than PCA's grid search.
    The cost is that of up to ``n_triplets * max(n_rotations, 1)`` votes per
    point (3,500 by default), fewer where early stopping ends the voting
    (flat regions): with the defaults, 0.5 to 0.9 s per 1,024-point
    ModelNet10 object on one shared core, against 1.5 to 3 ms for PCA (see
    ``scripts/compare_normals.py``).

    References
    ----------
    .. [1] A. Boulch and R. Marlet, "Fast and robust normal estimation for
       point clouds with sharp features", Computer Graphics Forum 31(5)
       (SGP 2012), pp. 1765-1774.
    .. [2] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._hough import estimate_normals_hough
    >>> xy = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0)), -1).reshape(-1, 2)
    >>> plane = np.column_stack([xy, np.zeros(len(xy))])
    >>> normals = estimate_normals_hough(plane, n_neighbors=8, orientation=[0, 0, 10])
    >>> np.allclose(normals, [0, 0, 1])
    True
    """
    params = {"n_triplets": n_triplets, "n_phi": n_phi, "n_rotations": n_rotations,
              "cluster_angle": cluster_angle, "tolerance": tolerance, "confidence": confidence}
    return hough_single(points, n_neighbors, orientation, n_jobs, random_state, params,
                        "estimate_normals_hough")


def hough_single(points, n_neighbors, orientation, n_jobs, random_state, method_params, owner):
    """One cloud, validated as :func:`estimate_normals` validates it."""
    cloud = check_point_cloud(points, owner=owner, min_points=3, allow_normals=False)
    k = check_n_neighbors(n_neighbors, owner)
    resolve_orientation(orientation, owner)
    n_threads = check_n_jobs(n_jobs, owner=owner)
    off = np.array([0, cloud.shape[0]], dtype=np.int64)
    return hough_batch(cloud, off, k, orientation, n_threads, random_state, method_params, owner)
