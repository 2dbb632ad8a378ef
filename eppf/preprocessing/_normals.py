"""Surface normals of point clouds by PCA over k nearest neighbors.

The Python layer validates input and resolves parameters; the work is done by
the compiled kernel in ``eppf.preprocessing._normals_fast`` (exact kNN on a uniform grid,
Jacobi 3x3 eigensolver, OpenMP over objects or over the points of one object).
"""

import numpy as np

from ._hough import hough_batch, hough_single
from ._normal_options import ORIENT_NONE, ORIENT_VIEWPOINT, check_n_neighbors, resolve_orientation
from . import _normals_fast
from ._normals_fast import cloud_in_window, normals_cloud, normals_packed, normals_single, scratch_sizes
from ..utils._validation import (
    SAFE_MAX_EXP, SAFE_MIN_EXP, scale_exponents, check_n_jobs, check_point_cloud, condition_point_clouds,
)
from ..utils._simd import register_kernel

__all__ = ["estimate_normals", "estimate_normals_batch"]

_MIN_SIDE, _MAX_ABS = 2.0**SAFE_MIN_EXP, 2.0**SAFE_MAX_EXP


def _scaled_viewpoint(viewpoint, e):
    """The viewpoint in the units of a cloud rescaled by ``2**e``.

    Exact (``np.ldexp``) unless it underflows (the viewpoint is then, to
    float64's precision, at the origin) or overflows, which means the viewpoint is
    more than ``2**900`` times farther from the origin than any point; it is
    then moved along its own direction to ``|v| ~ 2**1000``, where ``v - p``
    still points the same way for every point of the (conditioned) cloud.
    """
    if e == 0 or not viewpoint.any():
        return viewpoint
    with np.errstate(over="ignore"):
        vp = np.ldexp(viewpoint, int(e))
    if not np.isfinite(vp).all():
        vp = np.ldexp(viewpoint, 1000 - int(np.frexp(np.abs(viewpoint).max())[1]))
    return np.ascontiguousarray(vp)


def _orient_towards(points, normals, viewpoint):
    """Flip ``normals`` in place to point towards ``viewpoint``, as the kernel's orientation does."""
    r = viewpoint[None, :] - points
    dot = (normals[:, 0] * r[:, 0] + normals[:, 1] * r[:, 1]) + normals[:, 2] * r[:, 2]
    normals[dot < 0.0] *= -1.0


def _check_other_method(method, method_params, owner):
    """Raise unless ``method`` is "hough" (``method_params`` apply to it only)."""
    if method == "hough":
        return
    if method == "pca":
        raise ValueError(f"{owner}: method_params apply to method='hough' only, got {method_params!r}")
    raise ValueError(f"{owner}: method must be 'pca' or 'hough', got {method!r}")


def _scratch(n_threads, max_n, k):
    f_len, i_len = scratch_sizes(max_n, k)
    return (
        np.empty((n_threads, f_len), dtype=np.float64),
        np.empty((n_threads, i_len), dtype=np.int64),
    )


def estimate_normals(points, n_neighbors=10, *, orientation="centroid", n_jobs=None, method="pca",
                     random_state=0, method_params=None):
    """Estimate unit surface normals of one point cloud by local PCA or a Hough transform.

    For each point, the covariance of its ``n_neighbors`` nearest neighbors
    (the point itself included, as its own nearest neighbor) is computed, and
    the normal is the eigenvector of its smallest eigenvalue. Neighbors are
    exact Euclidean nearest neighbors; points at exactly equal distance are
    taken in a fixed order that depends only on the cloud (grid cell, then
    index), so the result is deterministic.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Coordinates of the cloud, at least 3 points, not all identical.
    n_neighbors : int, default=10
        Size of each neighborhood, the point itself included; at least 3.
        A value larger than the cloud is clipped to ``n_points`` (every
        neighborhood is then the whole cloud).
    orientation : {"centroid", "origin", "viewpoint"}, array-like of shape (3,) or None, \
default="centroid"
        How the sign of each normal is chosen:

        - ``"centroid"``: pointing away from the centroid of the cloud
          (``n · (p - centroid) >= 0``), our default reading for closed
          objects;
        - ``"origin"`` or ``"viewpoint"``: pointing towards a sensor at the
          origin (``n · (0 - p) >= 0``), as with the estimator used in the
          paper;
        - an array-like of shape (3,): pointing towards that viewpoint;
        - ``None``: no orientation; the sign is whatever the eigensolver
          returns (deterministic but meaningless).

        A normal exactly perpendicular to the reference direction is not
        flipped.
    n_jobs : int, default=None
        Number of OpenMP threads, with joblib's meaning: ``None`` is OpenMP's
        default (honours ``OMP_NUM_THREADS`` and threadpoolctl limits), ``-1``
        all cores. The result is bit-identical for any value.
    method : {"pca", "hough"}, default="pca"
        ``"pca"``: local PCA (below). ``"hough"``: Boulch and Marlet's
        randomized Hough transform, the estimator of the paper, which keeps
        edges sharp.
    random_state : int, RandomState instance or None, default=0
        Seeds the ``"hough"`` estimator (unused by ``"pca"``).
    method_params : dict, default=None
        Parameters of the ``"hough"`` estimator (``n_triplets``, ``n_phi``,
        ``n_rotations``, ``cluster_angle``, ``tolerance``, ``confidence``);
        ``None`` keeps the authors' defaults.

    Returns
    -------
    normals : ndarray of shape (n_points, 3), dtype float64
        Unit normals. Degenerate neighborhoods (collinear or coincident
        points) give a finite unit vector orthogonal to the line, or an
        arbitrary axis for coincident points, never NaN.

    Raises
    ------
    TypeError
        If ``points`` is not numeric array-like or ``n_neighbors`` is not an int.
    ValueError
        If ``points`` does not have shape (n_points, 3), holds NaN or infinite
        values, has fewer than 3 points or only identical points, is too
        small for its distance from the origin (e.g. a 1e-10 object at
        1e300: center it), or if ``n_neighbors < 3`` or ``orientation`` is
        not understood.

    See Also
    --------
    eppf.EPPFTransformer : Estimates normals this way for clouds given without.

    Notes
    -----
    With neighbors :math:`q_1, \\dots, q_k` and mean :math:`\\bar q`, the
    normal is the unit eigenvector of the smallest eigenvalue of
    :math:`C = \\sum_i (q_i - \\bar q)(q_i - \\bar q)^T`.

    The compiled kernel finds exact neighbors on a uniform grid whose cell
    size adapts to the cloud and to ``n_neighbors``, takes the eigenvalues of
    :math:`C` in closed form and the eigenvector as a cross product of two
    rows of :math:`C - \\lambda_{min} I`, falling back to cyclic Jacobi
    rotations when the two smallest eigenvalues nearly coincide. A cloud of
    extreme magnitude (largest side below ``2**-100`` or coordinates above
    ``2**100``) is first rescaled by an exact power of two, and a viewpoint
    with it, so any finite coordinates give the normals of a sane scale. The search's
    distance scan runs on AVX-512 or AVX2 where the CPU has them, with the
    same normals bit for bit (timings against Open3D: the documentation's
    Performance page, "Normal estimation"). The grid's cost grows with the
    square of the number of points that share one cell, so tens of thousands
    of exact duplicates of one point are slow, though still exact.

    References
    ----------
    .. [1] H. Hoppe, T. DeRose, T. Duchamp, J. McDonald and W. Stuetzle,
       "Surface reconstruction from unorganized points", SIGGRAPH 1992.
    .. [2] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import estimate_normals
    >>> xy = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    >>> plane = np.column_stack([xy, np.zeros(len(xy))])
    >>> normals = estimate_normals(plane, n_neighbors=8, orientation=[0, 0, 10])
    >>> np.allclose(normals, [0, 0, 1])
    True
    """
    owner = "estimate_normals"
    if method != "pca" or method_params is not None:
        _check_other_method(method, method_params, owner)
        return hough_single(points, n_neighbors, orientation, n_jobs, random_state, method_params, owner)
    if (type(points) is np.ndarray and points.ndim == 2 and points.shape[1] == 3 and points.shape[0] >= 3
            and points.dtype.kind == "f" and points.dtype.itemsize in (4, 8)):
        # Fast path for the common case, a float array already inside the
        # kernel's magnitude window (most small clouds spend more time in
        # validation than in the kernel otherwise): one pass checks what
        # check_point_cloud and condition_point_clouds would (finite values,
        # not all points identical, no rescaling needed), and the kernel
        # reads the caller's array without a copy. Anything else takes the
        # general path below, with its error messages; the normals are the
        # same either way.
        cloud = points if points.dtype == np.float64 else points.astype(np.float64)
        cloud = np.ascontiguousarray(cloud)
        if cloud_in_window(cloud, _MIN_SIDE, _MAX_ABS):
            k = min(check_n_neighbors(n_neighbors, owner), cloud.shape[0])
            mode, viewpoint = resolve_orientation(orientation, owner)
            n_threads = max(1, min(check_n_jobs(n_jobs, owner=owner), cloud.shape[0] // 512))
            return normals_cloud(cloud, k, mode, viewpoint, n_threads)
    cloud = check_point_cloud(points, owner=owner, min_points=3, allow_normals=False)
    k = check_n_neighbors(n_neighbors, owner)
    mode, viewpoint = resolve_orientation(orientation, owner)
    # Our own copy: brought into the kernel's magnitude window by an exact 2**e
    # (PCA normals are scale-invariant), the viewpoint with it.
    e = int(condition_point_clouds([cloud], owner=owner, single=True)[0])
    viewpoint = _scaled_viewpoint(viewpoint, e)
    n_threads = check_n_jobs(n_jobs, owner=owner)
    n = cloud.shape[0]
    k = min(k, n)
    # Below a few hundred points per thread, starting threads costs more than
    # it saves (the result is the same either way).
    n_threads = max(1, min(n_threads, n // 512))
    out = np.empty((n, 3), dtype=np.float64)
    fs, its = _scratch(n_threads, n, k)
    normals_single(cloud, k, mode, viewpoint, out, fs, its, n_threads)
    return out


def estimate_normals_batch(points, offsets, n_neighbors=10, orientation="centroid", n_jobs=None, *, owner=None,
                           method="pca", random_state=0, method_params=None):
    """Estimate normals of many packed point clouds at once.

    The packed layout is that of :func:`eppf.utils._validation.pack_point_clouds`:
    object ``i`` is ``points[offsets[i]:offsets[i + 1]]``. Objects are spread
    over OpenMP threads; each object's normals are exactly those
    :func:`estimate_normals` returns for it alone, for any thread count.

    Parameters
    ----------
    points : ndarray of shape (n_total, 3)
        Coordinates of all objects, one after another.
    offsets : ndarray of shape (n_objects + 1,)
        Start of each object in ``points``, then ``n_total``; non-decreasing,
        starting at 0.
    n_neighbors : int, default=10
        Neighborhood size, the point itself included; at least 3. Clipped to
        each object's size, so objects with fewer than 3 points still get
        finite unit normals (for 1 or 2 points: an arbitrary unit vector
        orthogonal to their line), and empty objects are allowed.
    orientation : {"centroid", "origin", "viewpoint"}, array-like of shape (3,) or None, \
default="centroid"
        As in :func:`estimate_normals`; the centroid is each object's own.
    n_jobs : int, default=None
        Number of OpenMP threads (joblib's meaning, see
        :func:`estimate_normals`).
    owner : str, default=None
        Name used in error messages (the calling estimator); defaults to
        ``"estimate_normals_batch"``.
    method : {"pca", "hough"}, default="pca"
        As in :func:`estimate_normals`.
    random_state : int, RandomState instance, None or ndarray of uint64, default=0
        Seeds ``"hough"``: object ``i`` gets the ``i``-th seed drawn from it,
        or ``random_state[i]`` for an array of ``n_objects`` seeds (which
        keeps each object's normals independent of how objects are chunked).
    method_params : dict, default=None
        As in :func:`estimate_normals`.

    Returns
    -------
    normals : ndarray of shape (n_total, 3), dtype float64
        Unit normals, row for row with ``points``.
    """
    owner = owner or "estimate_normals_batch"
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"{owner}: points must have shape (n_total, 3), got shape {pts.shape}")
    if not (np.issubdtype(pts.dtype, np.number) or pts.dtype == bool) or np.iscomplexobj(pts):
        raise TypeError(f"{owner}: points must hold real numbers, got dtype {pts.dtype}")
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    if not np.isfinite(pts).all():
        raise ValueError(f"{owner}: points contain NaN or infinite values")
    off = np.asarray(offsets)
    if off.ndim != 1 or off.shape[0] < 2 or not np.issubdtype(off.dtype, np.integer):
        raise ValueError(f"{owner}: offsets must be a 1D integer array of length n_objects + 1 >= 2, got shape {off.shape} and dtype {off.dtype}")
    off = np.ascontiguousarray(off, dtype=np.int64)
    if off[0] != 0 or off[-1] != pts.shape[0] or np.any(np.diff(off) < 0):
        raise ValueError(
            f"{owner}: offsets must be non-decreasing from 0 to len(points) = {pts.shape[0]}, "
            f"got offsets[0] = {off[0]} and offsets[-1] = {off[-1]}"
        )
    k = check_n_neighbors(n_neighbors, owner)
    mode, viewpoint = resolve_orientation(orientation, owner)
    n_threads = check_n_jobs(n_jobs, owner=owner)
    if method != "pca" or method_params is not None:
        _check_other_method(method, method_params, owner)
        return hough_batch(pts, off, k, orientation, n_threads, random_state, method_params, owner,
                           small_objects=estimate_normals_batch)
    sizes = np.diff(off)
    max_n = int(sizes.max())
    k = min(k, max(max_n, 1))
    out = np.empty((pts.shape[0], 3), dtype=np.float64)
    if max_n == 0:
        return out
    # Objects outside the kernel's magnitude window are rescaled by an exact
    # 2**e (on a copy: ``points`` may be the caller's array).
    full = np.flatnonzero(sizes > 0)
    lo = np.zeros((len(sizes), 3))
    hi = np.ones((len(sizes), 3))  # (empty objects: inside the window)
    lo[full] = np.minimum.reduceat(pts, off[full], axis=0)
    hi[full] = np.maximum.reduceat(pts, off[full], axis=0)
    exps = scale_exponents(lo, hi, owner)
    orient_here = False
    if exps.any():
        pts = pts.copy()
        for j in np.flatnonzero(exps):
            np.ldexp(pts[off[j]:off[j + 1]], int(exps[j]), out=pts[off[j]:off[j + 1]])
        # a viewpoint off the origin moves with each object's own 2**e: oriented below
        orient_here = mode == ORIENT_VIEWPOINT and viewpoint.any()
    kmode = ORIENT_NONE if orient_here else mode
    n_objects = off.shape[0] - 1
    if n_objects == 1:
        n_threads = max(1, min(n_threads, max_n // 512))
        fs, its = _scratch(n_threads, max_n, k)
        normals_single(pts, k, kmode, viewpoint, out, fs, its, n_threads)
    else:
        n_threads = min(n_threads, n_objects)
        fs, its = _scratch(n_threads, max_n, k)
        normals_packed(pts, off, k, kmode, viewpoint, out, fs, its, max_n, n_threads)
    if orient_here:
        for j in full:
            a, b = off[j], off[j + 1]
            _orient_towards(pts[a:b], out[a:b], _scaled_viewpoint(viewpoint, exps[j]))
    return out


# the SIMD code this module's kernel runs, for eppf.simd_levels()
register_kernel("normals", lambda: ("scalar", "avx2", "avx512")[_normals_fast._simd_level()])
