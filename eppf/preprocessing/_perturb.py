"""Perturbations of a single point cloud: noise, occlusion, dropout, rotation, resampling.

Every function takes one cloud, an array of shape (n_points, 3) or
(n_points, 6) whose last three columns are normals, validates it with
:func:`eppf.utils._validation.check_point_cloud` and returns a new float64 array with
the same number of columns; the input is never modified. Normals follow the
points: they are rotated with them and dropped with them. Randomness comes
from ``random_state`` (anything :func:`sklearn.utils.check_random_state`
accepts), so a fixed integer gives the same output on every call. A result
that overflows float64 (coordinates near its limit, huge noise or factors)
raises a ValueError instead of returning inf or NaN.

The functions are the building blocks of the synthetic data set
(:func:`eppf.datasets.make_shapes`) and of the point-cloud transformers in
:mod:`eppf.preprocessing`.
"""

import numbers

import numpy as np
from sklearn.utils import check_random_state

from ..utils._param_validation import Interval, Options, Satisfies, StrOptions, validate_parameter
from ..utils._sampling import resample
from ..utils._cloud_stats import cloud_means, stretch_about
from ..utils._validation import check_point_cloud

__all__ = [
    "add_gaussian_noise",
    "occlude",
    "random_dropout",
    "random_rotation",
    "random_rotation_matrix",
    "random_scaling",
    "resample",
    "rotate",
    "rotation_matrix",
    "scale",
]

_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


# --------------------------------------------------------------------------- #
# parameter checks
# --------------------------------------------------------------------------- #
def _is_direction(value):
    """``'x'``, ``'y'``, ``'z'`` or a finite vector of length 3 that is not (near) zero."""
    if isinstance(value, str):
        return value in _AXES
    vec = np.asarray(value, dtype=np.float64)
    return vec.shape == (3,) and bool(np.isfinite(vec).all()) and bool(np.sqrt(vec @ vec) >= 1e-12)


def _is_factors(value):
    """A finite number > 0, or a vector of 3 of them."""
    if isinstance(value, (str, bytes)):
        return False
    fac = np.asarray(value, dtype=np.float64)
    return fac.shape in ((), (3,)) and bool(np.isfinite(fac).all()) and bool((fac > 0).all())


def _is_rotation(value):
    """A finite (3, 3) proper rotation matrix: orthonormal (to 1e-6) with determinant +1."""
    if isinstance(value, (str, bytes)):
        return False
    rot = np.asarray(value, dtype=np.float64)
    return (
        rot.shape == (3, 3)
        and bool(np.isfinite(rot).all())
        and bool(np.allclose(rot @ rot.T, np.eye(3), atol=1e-6))
        and not np.linalg.det(rot) < 0
    )


#: What each parameter of the perturbations accepts: the functions here and
#: the transformers of :mod:`eppf.preprocessing` check their parameters
#: against these lists (:mod:`eppf.utils._param_validation`).
CONSTRAINTS = {
    "sigma": [Interval(numbers.Real, 0, None, closed="left", description="a finite float >= 0")],
    "relative_to": [StrOptions(["unit_cube", "none"])],
    "fraction": [Interval(numbers.Real, 0, 1, closed="left", description="a float in [0, 1)")],
    "direction": [Satisfies(_is_direction, "'x', 'y', 'z' or a finite non-zero vector of length 3")],
    "axis": [Satisfies(_is_direction, "'x', 'y', 'z' or a finite non-zero vector of length 3")],
    "angle": [Interval(numbers.Real, None, None, closed="neither", description="a finite float")],
    "center": [StrOptions(["centroid", "origin"])],
    "factors": [Satisfies(_is_factors, "a finite number > 0 or a vector of length 3 of them")],
    "low": [Interval(numbers.Real, 0, None, closed="neither", description="a finite float > 0")],
    "high": [Interval(numbers.Real, 0, None, closed="neither", description="a finite float > 0")],
    "anisotropic": [Options(bool)],
    "rotation": [Satisfies(_is_rotation, "a proper rotation matrix (orthonormal, determinant +1) of shape (3, 3)")],
}


def _check(owner, **values):
    """Check each named value against :data:`CONSTRAINTS` (an InvalidParameterError naming ``owner``)."""
    for name, value in values.items():
        validate_parameter(value, CONSTRAINTS[name], name=name, owner=owner)


def check_non_negative(value, name, owner):
    """Check a finite number >= 0 (as ``sigma``); return it as a float."""
    validate_parameter(value, CONSTRAINTS["sigma"], name=name, owner=owner)
    return float(value)


def check_fraction(value, name, owner):
    """Check a share in [0, 1) (as ``fraction``); return it as a float."""
    validate_parameter(value, CONSTRAINTS["fraction"], name=name, owner=owner)
    return float(value)


def _unit_vector(value):
    """A checked direction (see :func:`_is_direction`) as a unit 3-vector."""
    if isinstance(value, str):
        return np.array(_AXES[value])
    vec = np.asarray(value, dtype=np.float64)
    return vec / np.sqrt(vec @ vec)


def _check_vector(value, name, owner):
    """Check the direction ``name`` (``'x'``, ``'y'``, ``'z'`` or a vector); return it as a unit 3-vector."""
    _check(owner, **{name: value})
    return _unit_vector(value)


def _check_scale_range(low, high, owner):
    """Checked ``low`` and ``high`` as floats, with ``low <= high``."""
    _check(owner, low=low, high=high)
    low, high = float(low), float(high)
    if not low <= high:
        raise ValueError(f"{owner}: need 0 < low <= high, got low={low!r}, high={high!r}")
    return low, high


def _n_removed(fraction, n_points):
    """Points removed for ``fraction``: rounded to nearest, leaving at least 2."""
    return min(int(np.floor(fraction * n_points + 0.5)), n_points - 2)


class NotFiniteError(ValueError):
    """A perturbed cloud that is not finite in float64 (its values overflowed).

    Raised with the name of the function or transformer (``owner``) and,
    from a transformer, the index of the cloud; the transformers of
    :mod:`eppf.preprocessing` catch the error of the function they call and
    raise it again under their own name.
    """

    def __init__(self, owner, what, remedy, index=None):
        cloud = "point cloud" if index is None else f"point cloud {index}"
        super().__init__(f"{owner}: the {what} {cloud} overflows float64; {remedy}")
        self.what, self.remedy = what, remedy


def check_finite(out, owner, what, remedy):
    """Return ``out``, or raise :class:`NotFiniteError` when the ``what`` cloud has a non-finite value."""
    if not np.isfinite(out).all():
        raise NotFiniteError(owner, what, remedy)
    return out


#: The remedies :func:`check_finite` suggests, by perturbation.
NOISE_REMEDY = "use a smaller sigma or rescale the cloud"
ROTATION_REMEDY = "center or rescale the cloud first"
SCALING_REMEDY = "use factors nearer 1 or center or rescale the cloud first"


def random_unit_vector(rng):
    while True:
        vec = rng.normal(size=3)
        norm = np.sqrt(vec @ vec)
        if norm > 1e-12:
            return vec / norm


# --------------------------------------------------------------------------- #
# noise
# --------------------------------------------------------------------------- #
def add_gaussian_noise(cloud, sigma, *, relative_to="unit_cube", random_state=None):
    """Add zero-mean Gaussian noise to the coordinates of a point cloud.

    Each coordinate of each point receives an independent draw from
    :math:`\\mathcal{N}(0, s^2)`. This is the perturbation of the paper's
    noise experiment (Fig. 8), where the standard deviation is measured in
    units of the unit cube that the data set is scaled into.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by unit normals.
    sigma : float
        Standard deviation of the noise, >= 0. ``0`` returns a copy.
    relative_to : {"unit_cube", "none"}, default="unit_cube"
        ``"unit_cube"``: ``s = sigma * L`` where ``L`` is the largest side of
        the cloud's axis-aligned bounding box, so ``sigma=0.06`` means 6 % of
        the cube the cloud fits in, whatever its size. ``"none"``: ``s = sigma``
        in the cloud's own units.
    random_state : int, RandomState instance or None, default=None
        Seed of the noise.

    Returns
    -------
    noisy : ndarray of shape (n_points, 3) or (n_points, 6)
        The perturbed cloud. Normals, when present, are copied unchanged and
        so describe the noise-free surface: re-estimate them from the noisy
        points if the experiment needs normals consistent with the data.

    See Also
    --------
    occlude : View-dependent removal of points.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._perturb import add_gaussian_noise
    >>> cloud = np.random.RandomState(0).uniform(size=(100, 3))
    >>> noisy = add_gaussian_noise(cloud, 0.01, random_state=0)
    >>> noisy.shape
    (100, 3)
    """
    owner = "add_gaussian_noise"
    arr = check_point_cloud(cloud, owner=owner)
    sigma = check_non_negative(sigma, "sigma", owner)
    _check(owner, relative_to=relative_to)
    rng = check_random_state(random_state)
    with np.errstate(over="ignore", invalid="ignore"):
        if relative_to == "unit_cube":
            sigma = sigma * float(np.ptp(arr[:, :3], axis=0).max())
        noisy = add_noise_array(arr, sigma, rng)
    return check_finite(noisy, owner, "noisy", NOISE_REMEDY)


def add_noise_array(arr, sigma, rng):
    """Kernel of :func:`add_gaussian_noise` on a validated array, in place (unchecked: may overflow)."""
    if sigma > 0:
        arr[:, :3] += rng.normal(scale=sigma, size=(arr.shape[0], 3))
    return arr


# --------------------------------------------------------------------------- #
# point removal
# --------------------------------------------------------------------------- #
def occlude(cloud, fraction, *, direction=None, random_state=None):
    """Remove the far side of a point cloud as seen from one viewing direction.

    A sensor that looks at an object from one side does not see the side
    facing away from it. This function models that self-occlusion by a plane
    cut: the sensor sits far away along ``direction``, every point is ranked
    by its projection ``p . direction`` (its nearness to the sensor), and the
    ``fraction`` of points with the smallest projections, those behind a plane
    orthogonal to ``direction``, are removed. The removed points therefore all
    lie on one side of that plane; for a sphere and ``fraction=0.5`` exactly
    the hemisphere facing away from the sensor is removed.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by unit normals.
    fraction : float
        Share of the points to remove, ``0 <= fraction < 1``. The number
        removed is ``round(fraction * n_points)``, but at least two points are
        always kept.
    direction : {"x", "y", "z"} or array-like of shape (3,), default=None
        Direction from the object towards the sensor (need not be unit
        length). ``None`` draws it uniformly on the unit sphere from
        ``random_state``.
    random_state : int, RandomState instance or None, default=None
        Seed of the random direction; unused when ``direction`` is given.

    Returns
    -------
    visible : ndarray of shape (n_kept, 3) or (n_kept, 6)
        The points facing the sensor, with their normals, in their original
        order.

    See Also
    --------
    random_dropout : Removal of points independent of geometry.

    Notes
    -----
    Ties in the projection are broken by point order, so the result is
    deterministic for a given direction.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._perturb import occlude
    >>> cloud = np.random.RandomState(0).normal(size=(100, 3))
    >>> occlude(cloud, 0.3, direction="z").shape
    (70, 3)
    """
    owner = "occlude"
    arr = check_point_cloud(cloud, owner=owner)
    fraction = check_fraction(fraction, "fraction", owner)
    if direction is None:
        view = random_unit_vector(check_random_state(random_state))
    else:
        view = _check_vector(direction, "direction", owner)
    return occlude_array(arr, fraction, view)


def occlude_array(arr, fraction, view):
    """Kernel of :func:`occlude` on a validated array and a unit direction."""
    n_remove = _n_removed(fraction, arr.shape[0])
    if n_remove == 0:
        return arr
    order = np.argsort(arr[:, :3] @ view, kind="stable")
    keep = np.ones(arr.shape[0], dtype=bool)
    keep[order[:n_remove]] = False
    return arr[keep]


def random_dropout(cloud, fraction, *, random_state=None):
    """Remove a random subset of the points of a cloud.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by unit normals.
    fraction : float
        Share of the points to remove, ``0 <= fraction < 1``. The number
        removed is ``round(fraction * n_points)``, but at least two points are
        always kept. Every subset of that size is equally likely.
    random_state : int, RandomState instance or None, default=None
        Seed of the choice of points.

    Returns
    -------
    kept : ndarray of shape (n_kept, 3) or (n_kept, 6)
        The remaining points, with their normals, in their original order.

    See Also
    --------
    occlude : View-dependent removal of points.
    resample : Draw a fixed number of points.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._perturb import random_dropout
    >>> cloud = np.random.RandomState(0).normal(size=(100, 3))
    >>> random_dropout(cloud, 0.25, random_state=0).shape
    (75, 3)
    """
    owner = "random_dropout"
    arr = check_point_cloud(cloud, owner=owner)
    fraction = check_fraction(fraction, "fraction", owner)
    rng = check_random_state(random_state)
    n = arr.shape[0]
    n_remove = _n_removed(fraction, n)
    if n_remove == 0:
        return arr
    keep = np.sort(rng.choice(n, size=n - n_remove, replace=False))
    return arr[keep]


# --------------------------------------------------------------------------- #
# rotation
# --------------------------------------------------------------------------- #
def rotation_matrix(axis, angle):
    """Matrix of the rotation by ``angle`` about ``axis`` (right-hand rule).

    Parameters
    ----------
    axis : {"x", "y", "z"} or array-like of shape (3,)
        Rotation axis; a vector need not be unit length.
    angle : float
        Angle in radians.

    Returns
    -------
    rotation : ndarray of shape (3, 3)
        Proper rotation matrix ``R`` (``R @ R.T = I``, ``det R = 1``); a point
        ``p`` (row) maps to ``p @ R.T``.

    Notes
    -----
    Rodrigues' formula: ``R = I + sin(a) K + (1 - cos(a)) K^2`` with ``K`` the
    cross-product matrix of the unit axis.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._perturb import rotation_matrix
    >>> np.round(rotation_matrix("z", np.pi / 2) @ [1.0, 0.0, 0.0], 12)
    array([0., 1., 0.])
    """
    owner = "rotation_matrix"
    u = _check_vector(axis, "axis", owner)
    _check(owner, angle=angle)
    angle = float(angle)
    k = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def random_rotation_matrix(*, axis=None, random_state=None):
    """Draw a random rotation matrix.

    Parameters
    ----------
    axis : {"x", "y", "z"} or array-like of shape (3,), default=None
        ``None`` draws uniformly from all rotations (the Haar measure on
        SO(3)). Otherwise the rotation is about this axis, e.g. the up axis
        ``"z"`` for upright objects, by an angle uniform in [0, 2 pi).
    random_state : int, RandomState instance or None, default=None
        Seed of the draw.

    Returns
    -------
    rotation : ndarray of shape (3, 3)
        Proper rotation matrix.

    Notes
    -----
    A uniform rotation is the matrix of a unit quaternion whose four
    components are independent standard normal draws, normalized; the
    normalized Gaussian is uniform on the 3-sphere, and the double cover maps
    that uniform measure to the Haar measure on SO(3).
    """
    owner = "random_rotation_matrix"
    rng = check_random_state(random_state)
    if axis is not None:
        u = _check_vector(axis, "axis", owner)
        return rotation_matrix(u, rng.uniform(0.0, 2.0 * np.pi))
    while True:
        q = rng.normal(size=4)
        norm = np.sqrt(q @ q)
        if norm > 1e-12:
            break
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotate_array(arr, rotation, center):
    """Kernel of :func:`rotate` on a validated array (unchecked: coordinates near float64's limit may overflow)."""
    out = arr.copy()
    with np.errstate(over="ignore", invalid="ignore"):
        if center == "centroid":
            origin = arr[:, :3].mean(axis=0)
            out[:, :3] = (arr[:, :3] - origin) @ rotation.T + origin
        else:
            out[:, :3] = arr[:, :3] @ rotation.T
    if arr.shape[1] == 6:
        out[:, 3:] = arr[:, 3:] @ rotation.T
    return out


def rotate(cloud, rotation, *, center="centroid"):
    """Rotate a point cloud and its normals by a given rotation matrix.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by unit normals.
    rotation : array-like of shape (3, 3)
        Proper rotation matrix ``R``; each point ``p`` becomes ``R p`` (about
        the center) and each normal ``n`` becomes ``R n``.
    center : {"centroid", "origin"}, default="centroid"
        Fixed point of the rotation: the mean of the points, so the object
        stays where it is, or the coordinate origin.

    Returns
    -------
    rotated : ndarray of shape (n_points, 3) or (n_points, 6)
        The rotated cloud.

    See Also
    --------
    rotation_matrix, random_rotation
    """
    owner = "rotate"
    arr = check_point_cloud(cloud, owner=owner)
    _check(owner, center=center, rotation=rotation)
    rot = np.asarray(rotation, dtype=np.float64)
    return check_finite(rotate_array(arr, rot, center), owner, "rotated", ROTATION_REMEDY)


def random_rotation(cloud, *, axis=None, center="centroid", random_state=None):
    """Rotate a point cloud and its normals by a random rotation.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by unit normals.
    axis : {"x", "y", "z"} or array-like of shape (3,), default=None
        ``None`` draws a rotation uniformly from SO(3); otherwise the rotation
        is about this axis (e.g. ``"z"``, the up axis of upright objects) by
        a uniform angle.
    center : {"centroid", "origin"}, default="centroid"
        Fixed point of the rotation: the mean of the points or the origin.
    random_state : int, RandomState instance or None, default=None
        Seed of the rotation.

    Returns
    -------
    rotated : ndarray of shape (n_points, 3) or (n_points, 6)
        The rotated cloud. Pairwise distances are unchanged.

    See Also
    --------
    random_rotation_matrix : The matrix this function applies.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._perturb import random_rotation
    >>> cloud = np.random.RandomState(0).normal(size=(10, 3))
    >>> rotated = random_rotation(cloud, random_state=0)
    >>> bool(np.allclose(np.linalg.norm(rotated[0] - rotated[1]),
    ...                  np.linalg.norm(cloud[0] - cloud[1])))
    True
    """
    owner = "random_rotation"
    arr = check_point_cloud(cloud, owner=owner)
    _check(owner, center=center)
    if axis is not None:
        axis = _check_vector(axis, "axis", owner)
    rot = random_rotation_matrix(axis=axis, random_state=random_state)
    return check_finite(rotate_array(arr, rot, center), owner, "rotated", ROTATION_REMEDY)


# --------------------------------------------------------------------------- #
# scaling
# --------------------------------------------------------------------------- #
def _scale(arr, factors, center):
    """The stretch of :func:`scale` on a validated array (unchecked: extreme values or factors may overflow)."""
    out = arr.copy()
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        origin = arr[:, :3].mean(axis=0) if center == "centroid" else np.zeros(3)
        out[:, :3] = (arr[:, :3] - origin) * factors + origin
        if arr.shape[1] == 6:
            # Normals transform with the inverse transpose of diag(factors), then get unit length again.
            normals = arr[:, 3:] / factors
            out[:, 3:] = normals / np.sqrt(np.einsum("ij,ij->i", normals, normals))[:, None]
    return out


def _scale_clouds(clouds, factors, center):
    """:func:`_scale` of every validated cloud with its row of ``factors`` (n_clouds, 3), bit for bit.

    Clouds of one width (all with normals, or none) are stretched in
    one compiled pass over all their points (each row's arithmetic is
    :func:`_scale`'s, and the centroids are each cloud's own mean, as
    there) and their normals in whole-array operations, so a list of many
    small clouds costs a few array operations instead of a few per cloud;
    the clouds returned are views of one new array. Mixed widths go cloud
    by cloud. Unchecked: extreme values or factors may overflow.
    """
    if len({c.shape[1] for c in clouds}) != 1:
        return [_scale(c, f, center) for c, f in zip(clouds, factors)]
    sizes = np.array([c.shape[0] for c in clouds])
    block = np.concatenate(clouds)
    out = np.empty_like(block)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    factors = np.ascontiguousarray(factors, dtype=np.float64)
    # each cloud's own mean, as c[:, :3].mean(axis=0) adds it, and (xyz - origin) * factors + origin in one
    # compiled pass with NumPy's operations in NumPy's order (its strided reduction over three columns and
    # its three temporaries are slow)
    origins = cloud_means(block, offsets) if center == "centroid" else np.zeros((len(clouds), 3))
    stretch_about(block, offsets, origins, factors, out)
    if block.shape[1] == 6:
        with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
            np.divide(block[:, 3:], np.repeat(factors, sizes, axis=0), out=out[:, 3:])
            flat = out[:, 3:]
            flat /= np.sqrt(np.einsum("ij,ij->i", flat, flat))[:, None]
    bounds = offsets.tolist()
    return [out[a:b] for a, b in zip(bounds[:-1], bounds[1:])]


def _scaling_factors(rng, low, high, anisotropic):
    """The factors :func:`random_scaling` draws from ``rng``: log-uniform in [low, high], three (one per axis)
    or one for all three axes (shape (1,): arithmetic and assignment broadcast it, with the same bits)."""
    return np.exp(rng.uniform(np.log(low), np.log(high), size=3 if anisotropic else 1))


def scale(cloud, factors, *, center="centroid"):
    """Stretch a point cloud along the coordinate axes.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by unit normals.
    factors : float or array-like of shape (3,)
        Positive scale factor per axis (one number scales all three axes
        alike). Each point ``p`` becomes ``diag(factors) (p - c) + c`` for the
        center ``c``; each normal ``n`` becomes ``diag(factors)^-1 n``, scaled
        back to unit length, so it stays perpendicular to the stretched
        surface.
    center : {"centroid", "origin"}, default="centroid"
        Fixed point of the scaling: the mean of the points, so the object
        stays where it is, or the coordinate origin.

    Returns
    -------
    scaled : ndarray of shape (n_points, 3) or (n_points, 6)
        The stretched cloud.

    See Also
    --------
    random_scaling : Random factors, for augmentation.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._perturb import scale
    >>> cloud = np.array([[0.0, 0.0, 0.0], [2.0, 2.0, 2.0]])
    >>> scale(cloud, [1.0, 0.5, 2.0])
    array([[ 0. ,  0.5, -1. ],
           [ 2. ,  1.5,  3. ]])
    """
    owner = "scale"
    arr = check_point_cloud(cloud, owner=owner)
    _check(owner, center=center, factors=factors)
    fac = np.asarray(factors, dtype=np.float64)
    return check_finite(_scale(arr, np.broadcast_to(fac, (3,)), center), owner, "stretched", SCALING_REMEDY)


def random_scaling(cloud, low=0.8, high=1.25, *, anisotropic=True, center="centroid", random_state=None):
    """Stretch a point cloud by random factors, for augmentation.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by unit normals.
    low, high : float, default=0.8, 1.25
        Range of the factors, ``0 < low <= high``. Factors are drawn
        log-uniformly, so with ``high = 1 / low`` stretching and shrinking by
        the same ratio are equally likely.
    anisotropic : bool, default=True
        Draw one factor per axis (the object's proportions change) or one for
        all three (only its size changes, which a per-object scaled descriptor
        does not see).
    center : {"centroid", "origin"}, default="centroid"
        Fixed point of the scaling.
    random_state : int, RandomState instance or None, default=None
        Seed of the factors.

    Returns
    -------
    scaled : ndarray of shape (n_points, 3) or (n_points, 6)
        The stretched cloud; normals follow as in :func:`scale`.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing._perturb import random_scaling
    >>> cloud = np.random.RandomState(0).uniform(size=(100, 3))
    >>> sides = np.ptp(random_scaling(cloud, 0.5, 2.0, random_state=0), axis=0) / np.ptp(cloud, axis=0)
    >>> bool(((sides >= 0.5) & (sides <= 2.0)).all())
    True
    """
    owner = "random_scaling"
    arr = check_point_cloud(cloud, owner=owner)
    low, high = _check_scale_range(low, high, owner)
    _check(owner, anisotropic=anisotropic, center=center)
    factors = _scaling_factors(check_random_state(random_state), low, high, bool(anisotropic))
    return check_finite(_scale(arr, factors, center), owner, "stretched", SCALING_REMEDY)
