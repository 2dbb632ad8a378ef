"""Sampling primitives: per-object generators, area-weighted mesh sampling, resampling to a point count.

They sit under every layer because files (``eppf.io``), loaders and the
preprocessing transformers all sample the same way.
"""

import numbers

import numpy as np
from sklearn.utils import check_random_state

from ._param_validation import Interval, validate_parameter
from ._validation import check_point_cloud

__all__ = ["CONSTRAINTS", "MAX_N_POINTS", "check_n_points", "check_resolution", "object_rng", "resample", "sample_mesh"]

#: What the sampling parameters accept (:mod:`eppf.utils._param_validation`):
#: the functions here, the readers of :mod:`eppf.io` and the loaders of
#: :mod:`eppf.datasets` check theirs against these lists.
CONSTRAINTS = {
    # a point count of a cloud (resample, readers, loaders): a cloud needs two points
    "n_points": [Interval(numbers.Integral, 2, None, closed="left")],
    # a point count drawn from a mesh's surface (sample_mesh)
    "mesh_n_points": [Interval(numbers.Integral, 1, None, closed="left")],
    "n_samples": [Interval(numbers.Integral, 1, None, closed="left")],
    "resolution": [Interval(numbers.Real, 0, None, closed="neither", description="a positive finite float")],
}


#: Most points per cloud that a reader (:func:`eppf.io.read_point_cloud`), a loader of
#: :mod:`eppf.datasets` or :func:`resample` samples or resamples to: a billion points are 24 GB of
#: float64 coordinates (48 GB with normals) in one cloud. A larger ``n_points`` is refused before
#: anything is allocated, where NumPy's "Unable to allocate" came out of the middle of the reading,
#: naming neither the function nor the parameter.
MAX_N_POINTS = 10**9


def check_n_points(n_points, owner, allow_none=True):
    """Check a point count against ``CONSTRAINTS["n_points"]`` (None too when ``allow_none``) and
    :data:`MAX_N_POINTS`; return an int or None.

    The one check of every ``n_points`` of the readers, the loaders and :func:`resample`, so that they
    accept the same counts and refuse the others with the same message.
    """
    validate_parameter(n_points, ([None] if allow_none else []) + CONSTRAINTS["n_points"], name="n_points", owner=owner)
    if n_points is not None and n_points > MAX_N_POINTS:
        raise ValueError(f"{owner}: n_points must be at most {MAX_N_POINTS:,} points per object, got {n_points:,}")
    return None if n_points is None else int(n_points)


def check_resolution(resolution, owner):
    """Check a sampling resolution against ``CONSTRAINTS["resolution"]`` or None; return a float or None."""
    validate_parameter(resolution, [None] + CONSTRAINTS["resolution"], name="resolution", owner=owner)
    return None if resolution is None else float(resolution)


def object_rng(seed):
    """A NumPy RandomState from one 64-bit object seed.

    The seeds come from :func:`eppf.utils._validation.object_seeds` (or a loader's
    per-file seeds); each object gets its own generator so its draws do not
    depend on the other objects. The legacy ``RandomState`` interface runs
    on a PCG64 bit generator, which is seeded from all 64 bits and is twenty
    times cheaper to create than a Mersenne Twister (this matters once per
    object).
    """
    return np.random.RandomState(np.random.PCG64(int(seed)))


def _check_mesh(vertices, faces, owner):
    v = np.asarray(vertices)
    if v.dtype == object or not np.issubdtype(v.dtype, np.number):
        raise TypeError(f"{owner}: vertices must be a numeric array, got dtype {v.dtype}")
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise ValueError(f"{owner}: vertices must have shape (n_vertices, 3) with n_vertices >= 1, got {v.shape}")
    v = np.ascontiguousarray(v, dtype=np.float64)
    if not np.isfinite(v).all():
        raise ValueError(f"{owner}: vertices contain NaN or infinite values")
    f = np.asarray(faces)
    if f.size == 0:
        raise ValueError(f"{owner}: the mesh has no faces")
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"{owner}: faces must be an integer array of shape (n_faces, 3), got {f.dtype} {f.shape}")
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise ValueError(f"{owner}: face indices must lie in 0..{v.shape[0] - 1}, got {f.min()}..{f.max()}")
    return v, f.astype(np.intp, copy=False)


def _voxel_average(cloud, leaf, owner):
    """Average the points (and normals) falling in each cube of side ``leaf``, cubes in lexicographic order."""
    xyz = cloud[:, :3]
    with np.errstate(over="ignore"):
        scaled = (xyz - xyz.min(axis=0)) / leaf
    if not scaled.max() < 2.0**62:  # (a cell index must fit an int64; inf for a subnormal leaf)
        raise ValueError(f"{owner}: resolution {leaf:g} is too small for the mesh's extent "
                         f"{np.ptp(xyz, axis=0).max():.6g} (more than 2**62 cells along an axis)")
    cell = np.floor(scaled).astype(np.int64)
    dims = cell.max(axis=0) + 1
    if int(dims[0]) * int(dims[1]) * int(dims[2]) < 2**63:  # one int64 key per cell, in the same order
        key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
        _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    else:  # (the packed key would overflow: the rows themselves, sorted the same way)
        _, inverse, counts = np.unique(cell, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
    out = np.empty((counts.size, cloud.shape[1]))
    for c in range(cloud.shape[1]):
        out[:, c] = np.bincount(inverse, weights=cloud[:, c], minlength=counts.size)
    out[:, :3] /= counts[:, None]
    if cloud.shape[1] == 6:
        nrm = out[:, 3:]
        length = np.sqrt(np.einsum("ij,ij->i", nrm, nrm))
        # opposite faces in one voxel can cancel: keep a member's own normal then
        weak = length < 1e-6
        if weak.any():
            first = np.full(counts.size, -1)
            first[inverse[::-1]] = np.arange(inverse.size)[::-1]
            nrm[weak] = cloud[first[weak], 3:]
            length[weak] = 1.0
        out[:, 3:] = nrm / length[:, None]
    return out


def _face_areas(ab, ac):
    """The faces' cross products ``ab x ac``, their lengths (twice the areas) and the lengths' running sum."""
    cross = np.cross(ab, ac)
    double_area = np.sqrt(np.einsum("ij,ij->i", cross, cross))
    return cross, double_area, np.cumsum(double_area)


def sample_mesh(vertices, faces, *, n_points=None, resolution=None, n_samples=100_000,
                return_normals=True, random_state=None):
    """Sample a point cloud uniformly over the surface of a triangle mesh.

    Faces are chosen with probability proportional to their area and a point
    is drawn uniformly inside each chosen triangle, so the density is uniform
    over the surface. Each point carries its face's unit normal, oriented by
    the face's winding (right-hand rule).

    Parameters
    ----------
    vertices : array-like of shape (n_vertices, 3)
        Vertex coordinates.
    faces : array-like of shape (n_faces, 3)
        Vertex indices of each triangle (see :func:`eppf.io.read_mesh`).
    n_points : int, default=None
        Draw exactly this many points. Give either ``n_points`` or
        ``resolution``.
    resolution : float, default=None
        Draw ``n_samples`` points, then average them on a voxel grid of this
        cell size (in the mesh's units), as PCL's ``pcl_mesh_sampling`` tool
        does with its leaf size; the paper used 1 cm. The number of points
        then follows from the surface area.
    n_samples : int, default=100000
        Points drawn before voxel averaging when ``resolution`` is given
        (PCL's default). Ignored with ``n_points``.
    return_normals : bool, default=True
        Whether to return the normals as columns 3 to 5.
    random_state : int, RandomState instance or None, default=None
        Seed of the draws; the same seed gives the same cloud.

    Returns
    -------
    cloud : ndarray of shape (n, 6) or (n, 3), dtype float64
        Points, then normals when ``return_normals`` is True.

    Raises
    ------
    ValueError
        If the mesh is empty, has indices out of range, non-finite vertices or
        zero total area, or both or neither of ``n_points`` and
        ``resolution`` are given.

    See Also
    --------
    eppf.io.read_mesh : Read a mesh from a file.
    Resampler : Draw a fixed number of points from clouds.

    Notes
    -----
    A point inside triangle (a, b, c) is
    ``a + sqrt(r1) (1 - r2) (b - a) + sqrt(r1) r2 (c - a)`` with
    ``r1, r2 ~ U(0, 1)``, which is uniform over the triangle (Osada et al.,
    "Shape distributions", 2002). Zero-area faces are never chosen.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing import sample_mesh
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    >>> cloud = sample_mesh(square, [[0, 1, 2], [0, 2, 3]], n_points=100, random_state=0)
    >>> cloud.shape
    (100, 6)
    >>> bool(np.allclose(cloud[:, 3:], [0, 0, 1]))
    True
    """
    owner = "sample_mesh"
    v, f = _check_mesh(vertices, faces, owner)
    if (n_points is None) == (resolution is None):
        raise ValueError(f"{owner}: give exactly one of n_points and resolution")
    if n_points is not None:
        count = int(validate_parameter(n_points, CONSTRAINTS["mesh_n_points"], name="n_points", owner=owner))
    else:
        validate_parameter(resolution, CONSTRAINTS["resolution"], name="resolution", owner=owner)
        count = int(validate_parameter(n_samples, CONSTRAINTS["n_samples"], name="n_samples", owner=owner))
    rng = check_random_state(random_state)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        ab, ac = b - a, c - a
        cross, double_area, cum = _face_areas(ab, ac)
    total = cum[-1]
    if not (np.isfinite(total) and total > 0):
        # areas beyond float64 (coordinates near 1e154 and above) or below it (subnormal ones): the same
        # weights and normals from the mesh scaled to a unit extent, the points from the mesh as it is
        with np.errstate(over="ignore"):
            span = float(np.ptp(v, axis=0).max())
        if not np.isfinite(span):
            raise ValueError(f"{owner}: the mesh's extent overflows float64 (coordinates from {v.min():.6g} to "
                             f"{v.max():.6g}): rescale it")
        if span > 0:
            cross, double_area, cum = _face_areas(ab / span, ac / span)
            total = cum[-1]
        if not total > 0:
            raise ValueError(f"{owner}: the mesh has zero surface area (all {f.shape[0]} faces are degenerate)")
    draws = rng.random_sample((3, count))
    pick = np.searchsorted(cum, draws[0] * total, side="right")
    np.minimum(pick, f.shape[0] - 1, out=pick)
    # uniform in the triangle without a branch: weights sqrt(r1) (1 - r2) and sqrt(r1) r2
    root = np.sqrt(draws[1])
    w_b = root * (1.0 - draws[2])
    w_c = root * draws[2]
    keep_normals = return_normals or resolution is not None
    # one gather of a per-face table [a, b - a, c - a, unit normal], laid out by
    # component so that every row of the arithmetic below is contiguous
    parts = [a, ab, ac, cross / np.maximum(double_area, 1e-300)[:, None]] if keep_normals else [a, ab, ac]
    rows = np.take(np.hstack(parts).T, pick, axis=1)
    out = np.empty((6 if keep_normals else 3, count))
    np.multiply(rows[3:6], w_b, out=out[:3])
    out[:3] += rows[0:3]
    out[:3] += w_c * rows[6:9]
    if keep_normals:
        out[3:] = rows[9:12]
    cloud = out.T.copy()
    if resolution is not None:
        cloud = _voxel_average(cloud, float(resolution), owner)
        if not return_normals:
            cloud = np.ascontiguousarray(cloud[:, :3])
    return cloud


def resample(cloud, n_points, *, random_state=None):
    """Draw a fixed number of points from a cloud.

    Parameters
    ----------
    cloud : array-like of shape (n, 3) or (n, 6)
        Coordinates, optionally followed by unit normals.
    n_points : int
        Number of points to return, >= 2 and at most a billion
        (:data:`MAX_N_POINTS`). When ``n_points <= n`` the points
        are drawn without replacement. When ``n_points > n`` every point is
        kept once and the ``n_points - n`` extra points are drawn with
        replacement, so no information is lost.
    random_state : int, RandomState instance or None, default=None
        Seed of the draw.

    Returns
    -------
    sampled : ndarray of shape (n_points, 3) or (n_points, 6)
        The drawn points with their normals, in random order.

    See Also
    --------
    random_dropout : Remove a share of the points.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils._sampling import resample
    >>> cloud = np.random.RandomState(0).normal(size=(100, 3))
    >>> resample(cloud, 64, random_state=0).shape
    (64, 3)
    >>> resample(cloud, 256, random_state=0).shape
    (256, 3)
    """
    owner = "resample"
    arr = check_point_cloud(cloud, owner=owner)
    n_points = check_n_points(n_points, owner, allow_none=False)
    rng = check_random_state(random_state)
    n = arr.shape[0]
    if n_points <= n:
        index = rng.choice(n, size=int(n_points), replace=False)
    else:
        extra = rng.randint(0, n, size=int(n_points) - n)
        index = rng.permutation(np.concatenate([np.arange(n), extra]))
    return arr[index]
