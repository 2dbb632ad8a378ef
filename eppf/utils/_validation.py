"""Validation and packing of ragged point-cloud input.

Every estimator that takes point clouds goes through :func:`check_point_clouds`
(a list of arrays) or :func:`check_packed_clouds` (a :class:`PackedClouds`, the
form the descriptors hold their clouds in and hand to the kernels), so that bad
input fails the same way everywhere: a ``TypeError`` for the wrong kind of
object, a ``ValueError`` naming the estimator, the object index and the problem
for wrong shapes, non-finite values, too few or identical points and
zero-length normals. :func:`condition_point_clouds` then brings clouds of
extreme magnitude into the range the compiled kernels compute in, by an
exact power of two.
"""

import numbers
import operator

import numpy as np
from sklearn.utils.multiclass import type_of_target

from ._param_validation import N_JOBS, Interval, validate_parameter

__all__ = [
    "MAX_PARAMETERS", "PackedClouds", "as_vector3", "check_class_labels", "check_int", "check_n_jobs",
    "check_packed_clouds", "check_point_cloud", "check_point_clouds", "condition_point_clouds", "object_seeds",
    "pack_point_clouds",
]


def _prefix(owner):
    return f"{owner}: " if owner else ""


def check_point_cloud(cloud, *, owner=None, index=None, min_points=2, allow_normals=True):
    """Validate one point cloud and return it as a C-contiguous float64 array.

    Parameters
    ----------
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by normals (columns 3 to 5).
    owner : str, default=None
        Name of the calling estimator or function, used in error messages.
    index : int, default=None
        Position of the cloud in a collection, used in error messages.
    min_points : int, default=2
        Smallest accepted number of points.
    allow_normals : bool, default=True
        Whether six-column input (points and normals) is accepted.

    Returns
    -------
    cloud : ndarray of shape (n_points, 3) or (n_points, 6), dtype float64
        The cloud; normals, when present, are scaled to unit length.

    Raises
    ------
    TypeError
        If ``cloud`` is not numeric array-like.
    ValueError
        If the shape is wrong, a value is NaN or infinite, there are fewer than
        ``min_points`` points or fewer than two distinct ones, or a normal has
        zero length.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils import check_point_cloud
    >>> check_point_cloud([[0, 0, 0, 0, 0, 2], [1, 0, 0, 0, 0, 3]])[:, 3:]
    array([[0., 0., 1.],
           [0., 0., 1.]])
    """
    pre = _prefix(owner)
    what = "point cloud" if index is None else f"point cloud {index}"
    if isinstance(cloud, (str, bytes)) or cloud is None:
        raise TypeError(f"{pre}{what} must be an array of shape (n_points, 3) or (n_points, 6), got {type(cloud).__name__}")
    try:
        arr = np.asarray(cloud)
    except Exception as exc:  # ragged nested lists and the like
        raise TypeError(f"{pre}{what} could not be converted to an array: {exc}") from None
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{pre}{what} must hold numbers, got dtype {arr.dtype}")
    if np.iscomplexobj(arr):
        raise TypeError(f"{pre}{what} must hold real numbers, got dtype {arr.dtype}")
    allowed = (3, 6) if allow_normals else (3,)
    if arr.ndim != 2 or arr.shape[1] not in allowed:
        cols = " or ".join(f"(n_points, {c})" for c in allowed)
        raise ValueError(f"{pre}{what} must have shape {cols}, got shape {arr.shape}")
    n = arr.shape[0]
    if n < min_points:
        raise ValueError(f"{pre}{what} has {n} point{'s' if n != 1 else ''}; at least {min_points} are needed")
    arr = np.array(arr, dtype=np.float64, order="C", copy=True)
    if not np.isfinite(arr).all():
        raise ValueError(f"{pre}{what} contains NaN or infinite values")
    xyz = arr[:, :3]
    if n >= 2 and np.all(xyz == xyz[0]):
        raise ValueError(f"{pre}{what} has all {n} points identical; at least two distinct points are needed")
    if arr.shape[1] == 6:
        normals = arr[:, 3:]
        # Components above 2**510 would overflow the squares: such normals are
        # first multiplied by 2**-514 (exact), as in the compiled batch path.
        big = np.abs(normals).max(axis=1) > 2.0**510
        if big.any():
            normals[big] *= 2.0**-514
        x, y, z = normals.T
        norms = np.sqrt((x * x + y * y) + z * z)  # as the compiled batch path (_scan_fast._scan_object)
        bad = np.flatnonzero(norms < 1e-12)
        if bad.size:
            raise ValueError(f"{pre}{what} has {bad.size} zero-length normal(s), first at point {bad[0]}")
        arr[:, 3:] = normals / norms[:, None]
    return arr


def _items(X, pre):
    """The clouds of a collection ``X`` as a list, or the TypeError/ValueError for a wrong kind of collection."""
    if isinstance(X, PackedClouds):
        return X
    if X is None or isinstance(X, (str, bytes, dict, numbers.Number)):
        raise TypeError(f"{pre}X must be a list of point clouds (arrays of shape (n_i, 3) or (n_i, 6)), got {type(X).__name__}")
    if isinstance(X, np.ndarray) and X.dtype != object:
        if X.ndim == 2:
            raise ValueError(
                f"{pre}X is a single 2D array of shape {X.shape}; pass a list of point clouds, "
                "e.g. [cloud], or a 3D array of shape (n_objects, n_points, 3|6)"
            )
        if X.ndim != 3:
            raise ValueError(f"{pre}X must be a list of (n_i, 3|6) arrays or a 3D array, got an array of shape {X.shape}")
        items = list(X)
    else:
        try:
            items = list(X)
        except TypeError:
            raise TypeError(f"{pre}X must be a list of point clouds, got {type(X).__name__}") from None
    if len(items) == 0:
        raise ValueError(f"{pre}X is empty: at least one point cloud is needed")
    return items


def check_point_clouds(X, *, owner=None, min_points=2, allow_normals=True, n_threads=1):
    """Validate a collection of point clouds.

    Parameters
    ----------
    X : list of array-like of shape (n_i, 3) or (n_i, 6), or ndarray of shape (n_objects, n_points, 3|6)
        The clouds. Clouds may differ in size; a collection may mix clouds
        with and without normals.
    owner : str, default=None
        Name of the calling estimator or function, used in error messages.
    min_points : int, default=2
        Smallest accepted number of points per cloud.
    allow_normals : bool, default=True
        Whether six-column clouds are accepted.
    n_threads : int, default=1
        Threads of the compiled validation pass over many clouds (copies,
        finiteness, bounding boxes, normal lengths); the result does not
        depend on it.

    Returns
    -------
    clouds : list of ndarray
        Validated float64 clouds (see :func:`check_point_cloud`).

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils import check_point_clouds
    >>> clouds = check_point_clouds([np.eye(3), np.ones((4, 3)) * np.arange(4)[:, None]], owner="Mine")
    >>> [c.shape for c in clouds]
    [(3, 3), (4, 3)]
    """
    items = _items(X, _prefix(owner))
    if isinstance(items, PackedClouds):
        items = list(items)
    block = _scan_block(items, min_points, allow_normals, n_threads)
    if block is not None:
        stacked, offsets = block[0], block[1].tolist()
        return [stacked[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
    return _check_each(items, owner, min_points, allow_normals)


def _check_each(items, owner, min_points, allow_normals):
    """Per-cloud path: mixed or unusual input, and every error message."""
    return [
        check_point_cloud(c, owner=owner, index=i, min_points=min_points, allow_normals=allow_normals)
        for i, c in enumerate(items)
    ]


class PackedClouds:
    """A validated batch of point clouds, packed for the compiled kernels.

    The one form in which an estimator holds its clouds after validation
    (:func:`check_packed_clouds` makes it): object ``k`` is the rows
    ``offsets[k]:offsets[k + 1]`` of ``points`` (and of ``normals``). Kernels
    read the arrays directly; slicing by a range of objects
    (``packed[a:b]``) gives a ``PackedClouds`` whose arrays are views of
    these (only the small ``offsets`` array is new), which is how chunks of
    objects are made. Indexing by an int gives object ``k`` as one array,
    ``(n_k, 3)`` or, with normals, ``(n_k, 6)`` (a copy), so a
    ``PackedClouds`` can stand wherever a list of clouds is read.

    Parameters
    ----------
    points : ndarray of shape (n_points, 3), float64, C-contiguous
        The coordinates of every object, one after another.
    normals : ndarray of shape (n_points, 3), float64, C-contiguous, or None
        Unit normals, None when no object has them; the rows of objects
        without normals (``has_normals[k]`` False) are zeros.
    offsets : ndarray of shape (n_objects + 1,), int64
        Start of each object in ``points``, then ``n_points``; starts at 0.
    lower : ndarray of shape (n_objects, 3), float64
        Per-axis minimum of each object's coordinates.
    upper : ndarray of shape (n_objects, 3), float64
        Per-axis maximum of each object's coordinates.
    has_normals : ndarray of shape (n_objects,), bool
        Which objects came with normals.

    Attributes
    ----------
    dtype : numpy.dtype
        The dtype of ``points`` and ``normals`` (float64).
    sizes : ndarray of shape (n_objects,), int64
        Points of each object.

    See Also
    --------
    check_packed_clouds : Validates clouds into a ``PackedClouds``.
    pack_point_clouds : The ``(points, normals, offsets)`` of validated clouds.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils import check_packed_clouds
    >>> packed = check_packed_clouds([np.eye(3), np.ones((2, 3)) * [[0], [2]]])
    >>> len(packed), packed.points.shape, packed.offsets
    (2, (5, 3), array([0, 3, 5]))
    >>> packed[1:].points
    array([[0., 0., 0.],
           [2., 2., 2.]])
    >>> packed.sides()
    array([1., 2.])
    """

    __slots__ = ("points", "normals", "offsets", "lower", "upper", "has_normals")

    def __init__(self, points, normals, offsets, lower, upper, has_normals):
        self.points = points
        self.normals = normals
        self.offsets = offsets
        self.lower = lower
        self.upper = upper
        self.has_normals = has_normals

    @property
    def dtype(self):
        """The dtype of ``points`` and ``normals`` (float64)."""
        return self.points.dtype

    @property
    def sizes(self):
        """Points of each object, ndarray of shape (n_objects,)."""
        return np.diff(self.offsets)

    def sides(self):
        """Largest bounding-box side of each object.

        Returns
        -------
        sides : ndarray of shape (n_objects,), float64
            ``np.ptp`` of each object's coordinates, largest over the axes
            (inf where the difference is past float64's range).
        """
        with np.errstate(over="ignore"):
            return (self.upper - self.lower).max(axis=1)

    def __len__(self):
        return len(self.offsets) - 1

    def __iter__(self):
        for k in range(len(self)):
            yield self[k]

    def __getitem__(self, key):
        n = len(self)
        if isinstance(key, slice):
            start, stop, step = key.indices(n)
            if step != 1:
                raise TypeError(f"PackedClouds takes slices of consecutive objects, got step {step}")
            stop = max(start, stop)
            a, b = self.offsets[start], self.offsets[stop]
            return PackedClouds(
                self.points[a:b], None if self.normals is None else self.normals[a:b],
                self.offsets[start:stop + 1] - a, self.lower[start:stop], self.upper[start:stop],
                self.has_normals[start:stop],
            )
        k = operator.index(key)
        if not -n <= k < n:
            raise IndexError(f"object {key} out of range for {n} objects")
        k %= n
        a, b = self.offsets[k], self.offsets[k + 1]
        if self.has_normals[k]:
            return np.hstack([self.points[a:b], self.normals[a:b]])
        return self.points[a:b]

    def __repr__(self):
        return (f"PackedClouds(n_objects={len(self)}, n_points={len(self.points)}, "
                f"normals={'none' if self.normals is None else int(self.has_normals.sum())})")


class CheckedClouds(PackedClouds):
    """Clouds without normals that :func:`check_packed_clouds` has just validated, handed on by an estimator
    to the estimators it is made of (:class:`eppf.descriptors.DescriptorUnion` to its blocks).

    :func:`check_packed_clouds` copies such clouds instead of validating
    them again: the validation pass of a valid cloud without normals is a
    copy of it, so the result is the same bits. Clouds with normals are
    validated again, as every block always did (which normalizes the normals
    once more). Never handed to code outside eppf.
    """

    __slots__ = ()

    @classmethod
    def of(cls, packed):
        """The validated ``packed`` (without normals) marked as such; its arrays are shared."""
        if packed.normals is not None:
            raise ValueError("CheckedClouds: only clouds without normals skip their validation")
        return cls(packed.points, None, packed.offsets, packed.lower, packed.upper, packed.has_normals)


def check_packed_clouds(X, *, owner=None, min_points=2, allow_normals=True, n_threads=1):
    """Validate a collection of point clouds into one :class:`PackedClouds`.

    What :func:`check_point_clouds` accepts and refuses, with the same
    messages; the result is packed instead of a list. The arrays are new
    (the caller's own: :func:`condition_point_clouds` may change them in
    place). A ``PackedClouds`` given as ``X`` is validated again like any
    list of clouds.

    Parameters
    ----------
    X : list of array-like of shape (n_i, 3) or (n_i, 6), ndarray of shape (n_objects, n_points, 3|6), \
or PackedClouds
        The clouds.
    owner : str, default=None
        Name of the calling estimator or function, used in error messages.
    min_points : int, default=2
        Smallest accepted number of points per cloud.
    allow_normals : bool, default=True
        Whether six-column clouds are accepted.
    n_threads : int, default=1
        Threads of the compiled validation pass.

    Returns
    -------
    packed : PackedClouds
        The validated clouds.

    See Also
    --------
    check_point_clouds : The same validation, giving a list of arrays.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils import check_packed_clouds
    >>> packed = check_packed_clouds([np.eye(3), [[0, 0, 0, 0, 0, 2], [1, 0, 0, 0, 0, 3]]])
    >>> packed.has_normals
    array([False,  True])
    >>> packed[1]
    array([[0., 0., 0., 0., 0., 1.],
           [1., 0., 0., 0., 0., 1.]])
    """
    if type(X) is CheckedClouds and X.normals is None and len(X) and int(X.sizes.min()) >= max(min_points, 2):
        # validated by the estimator that hands them on: a copy is what the scan would give
        return PackedClouds(X.points.copy(), None, X.offsets.copy(), X.lower.copy(), X.upper.copy(),
                            X.has_normals.copy())
    items = _items(X, _prefix(owner))
    if isinstance(items, PackedClouds):
        items = _packed_items(items)
    block = _scan_block(items, min_points, allow_normals, n_threads)
    if block is not None:
        stacked, offsets, lo, hi = block
        if stacked.shape[1] == 6:
            from ._scan_fast import split_columns

            points, normals = split_columns(stacked)
            has = np.ones(len(offsets) - 1, dtype=bool)
        else:
            points, normals, has = stacked, None, np.zeros(len(offsets) - 1, dtype=bool)
        return PackedClouds(points, normals, offsets, lo, hi, has)
    return _pack_checked(_check_each(items, owner, min_points, allow_normals))


def _packed_items(packed):
    """The objects of a ``PackedClouds`` as C-contiguous float64 arrays for :func:`_scan_block`.

    All with normals: views of one new (N, 6) block; otherwise one array each.
    """
    if packed.normals is not None and packed.has_normals.all():
        block = np.hstack([packed.points, packed.normals])
        offsets = packed.offsets.tolist()
        return [block[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
    return list(packed)


def _pack_checked(clouds):
    """A :class:`PackedClouds` of clouds validated one by one (copied into new arrays)."""
    sizes = np.fromiter((c.shape[0] for c in clouds), dtype=np.int64, count=len(clouds))
    offsets = np.zeros(len(clouds) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    points = np.ascontiguousarray(np.concatenate([c[:, :3] for c in clouds], axis=0), dtype=np.float64)
    has = np.fromiter((c.shape[1] == 6 for c in clouds), dtype=bool, count=len(clouds))
    normals = None
    if has.any():
        normals = np.zeros_like(points)
        for k in np.flatnonzero(has):
            normals[offsets[k]:offsets[k + 1]] = clouds[k][:, 3:6]
    lo = np.full((len(clouds), 3), np.inf)
    hi = np.full((len(clouds), 3), -np.inf)
    full = np.flatnonzero(sizes > 0)
    if full.size:
        lo[full] = np.minimum.reduceat(points, offsets[full], axis=0)
        hi[full] = np.maximum.reduceat(points, offsets[full], axis=0)
    return PackedClouds(points, normals, offsets, lo, hi, has)


def _scan_block(items, min_points, allow_normals, n_threads=1):
    """Validate plain float/int arrays of one width with a few whole-collection calls.

    Returns ``(stacked, offsets, lo, hi)``: the clouds copied into one new
    C-ordered float64 array, rows ``offsets[k]:offsets[k + 1]`` of it bit for
    bit what :func:`check_point_cloud` returns for cloud ``k``, and their
    bounding boxes; or None when some item is not such an array or is
    invalid (the per-cloud path then finds the first problem and words the
    error). C-contiguous float64 clouds are copied, checked and normalized
    by one compiled pass with the objects spread over ``n_threads`` threads;
    others are first cast and concatenated by NumPy.
    """
    from ._scan_fast import scan_clouds

    allowed = (3, 6) if allow_normals else (3,)
    cols = None
    sizes = np.empty(len(items), dtype=np.int64)
    plain = True
    need = max(min_points, 2)
    ndarray = np.ndarray
    for k, c in enumerate(items):
        if type(c) is not ndarray or c.ndim != 2 or c.dtype.kind not in "biuf":
            return None
        n, m = c.shape
        if cols is None:
            cols = m
        if m != cols or n < need:
            return None
        sizes[k] = n
        plain = plain and c.dtype == np.float64 and c.flags.c_contiguous
    if cols not in allowed:
        return None
    offsets = np.zeros(len(items) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    stacked = np.empty((int(offsets[-1]), cols), dtype=np.float64)
    if plain:
        lo, hi, status = scan_clouds(stacked, offsets, list(items), int(n_threads))
    else:  # (into a C-ordered block whatever the clouds' own order)
        np.concatenate(items, axis=0, out=stacked, casting="unsafe")
        lo, hi, status = scan_clouds(stacked, offsets, None, int(n_threads))
    if status.any():
        return None
    return stacked, offsets, lo, hi


#: The magnitude window the compiled kernels work in without overflow or
#: underflow: largest bounding-box side at least ``2**SAFE_MIN_EXP`` and every
#: |coordinate| at most ``2**SAFE_MAX_EXP``. The kernels square and cube
#: differences of coordinates (ESF: products of two cross products, i.e.
#: fourth powers, in its own grid units; Wahl, EPPF, the normals and
#: OUR-CVFH at most fourth powers in the input's units), and
#: ``2**(4 * 101)`` and ``2**(-4 * 100)`` stay far inside float64's normal
#: range, with room for sums of many such terms.
SAFE_MIN_EXP = -100
SAFE_MAX_EXP = 100


def scale_exponents(lo, hi, owner=None, first_index=0, single=False):
    """Power-of-two exponents that bring each cloud into the safe window.

    ``lo`` and ``hi`` are (n_objects, 3) per-axis minima and maxima. Returns
    an int64 array: 0 for clouds already in the window (left untouched),
    otherwise the ``e`` for which ``cloud * 2**e`` is in the window, as close
    as it allows to a largest side in [0.5, 1). Raises a ValueError naming
    the first cloud that no power of two brings in (its extent is too small
    for its distance from the origin).
    """
    lo = np.asarray(lo, dtype=np.float64).reshape(-1, 3)
    hi = np.asarray(hi, dtype=np.float64).reshape(-1, 3)
    with np.errstate(over="ignore"):
        side = (hi - lo).max(axis=1)
        # hi - lo overflows past float64's range; the halves do not
        half = (hi * 0.5 - lo * 0.5).max(axis=1)
    amax = np.maximum(np.abs(lo), np.abs(hi)).max(axis=1)
    inside = (side >= 2.0 ** SAFE_MIN_EXP) & (amax <= 2.0 ** SAFE_MAX_EXP)
    exps = np.zeros(len(side), dtype=np.int64)
    if inside.all():
        return exps
    out = np.flatnonzero(~inside)
    # side >= 2**(es - 1) and amax < 2**ea (frexp's exponents); for a side that
    # overflowed, the half's exponent plus one
    es = np.where(np.isfinite(side[out]), np.frexp(side[out])[1], np.frexp(half[out])[1] + 1).astype(np.int64)
    ea = np.frexp(amax[out])[1].astype(np.int64)
    e_lo = SAFE_MIN_EXP + 1 - es  # side * 2**e >= 2**SAFE_MIN_EXP from here up
    e_lo[side[out] == 0] = -4096  # (a single point, or one repeated: only its magnitude matters)
    e_hi = SAFE_MAX_EXP - ea      # amax * 2**e <= 2**SAFE_MAX_EXP up to here
    bad = np.flatnonzero(e_lo > e_hi)
    if bad.size:
        k = int(out[bad[0]])
        raise ValueError(
            f"{_prefix(owner)}point cloud {'' if single else f'{first_index + k} '}is too small for its distance from the origin: "
            f"its largest side is {side[k]:.3g} at coordinates up to {amax[k]:.3g}, a ratio float64 cannot "
            "resolve in the descriptors' computations; centre it first (subtract its mean or its bounding-box "
            "centre)"
        )
    exps[out] = np.clip(-es, e_lo, e_hi)  # -es puts the largest side in [0.5, 1)
    return exps


def _ldexp_inplace(a, e):
    """``a *= 2**e`` in place, exactly short of underflow (``np.ldexp`` never forms ``2**e``)."""
    np.ldexp(a, int(e), out=a)


def condition_point_clouds(clouds, *, owner=None, single=False):
    """Bring validated clouds into the kernels' magnitude window, in place.

    A cloud whose largest bounding-box side is below ``2**SAFE_MIN_EXP`` or
    whose largest |coordinate| is above ``2**SAFE_MAX_EXP`` has its
    coordinates (columns 0-2; normals are unit vectors already) multiplied
    by a power of two ``2**e``, exact short of underflow, so that it fits
    the window; the others are left untouched, bit for bit. Scale-invariant
    computations then give the result they give at a sane scale; callers
    that use absolute lengths multiply them by ``2**-e``.

    Parameters
    ----------
    clouds : PackedClouds or list of ndarray
        Clouds returned by :func:`check_packed_clouds`,
        :func:`check_point_clouds` or :func:`check_point_cloud` (the
        caller's own copies: they are modified in place). The bounds of a
        ``PackedClouds`` are updated with them.
    owner : str, default=None
        Name used in error messages.
    single : bool, default=False
        The clouds are one cloud given alone: error messages give no index.

    Returns
    -------
    exponents : ndarray of shape (n_objects,), int64
        The ``e`` of each cloud (0 for untouched ones).

    Raises
    ------
    ValueError
        If a cloud's extent is too small for its distance from the origin
        for any power of two to bring it in (e.g. points at 1e300 +- 1e-10);
        centering it first fixes that.
    """
    if isinstance(clouds, PackedClouds):
        exps = scale_exponents(clouds.lower, clouds.upper, owner, single=single)
        offsets = clouds.offsets
        for k in np.flatnonzero(exps):
            _ldexp_inplace(clouds.points[offsets[k]:offsets[k + 1]], exps[k])
            # min and max commute with the (monotone) scaling
            _ldexp_inplace(clouds.lower[k], exps[k])
            _ldexp_inplace(clouds.upper[k], exps[k])
        return exps
    lo = np.array([c[:, :3].min(axis=0) for c in clouds], dtype=np.float64).reshape(-1, 3)
    hi = np.array([c[:, :3].max(axis=0) for c in clouds], dtype=np.float64).reshape(-1, 3)
    exps = scale_exponents(lo, hi, owner, single=single)
    for k in np.flatnonzero(exps):
        _ldexp_inplace(clouds[k][:, :3], exps[k])
    return exps


def pack_point_clouds(clouds):
    """Pack validated clouds into contiguous arrays for the compiled kernels.

    Parameters
    ----------
    clouds : list of ndarray of shape (n_i, 3) or (n_i, 6), or PackedClouds
        Validated clouds, all with normals or all without.

    Returns
    -------
    points : ndarray of shape (sum n_i, 3), float64
    normals : ndarray of shape (sum n_i, 3), float64, or None
        None when the clouds carry no normals.
    offsets : ndarray of shape (n_objects + 1,), int64
        Object ``k`` is ``points[offsets[k]:offsets[k + 1]]``.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils import pack_point_clouds
    >>> points, normals, offsets = pack_point_clouds([np.eye(3), np.ones((2, 3))])
    >>> points.shape, normals, offsets
    ((5, 3), None, array([0, 3, 5]))
    """
    if isinstance(clouds, PackedClouds):
        if clouds.normals is not None and not clouds.has_normals.all():
            raise ValueError("pack_point_clouds: the clouds must all have normals or all have none")
        return clouds.points, clouds.normals, clouds.offsets.copy()
    sizes = np.fromiter((c.shape[0] for c in clouds), dtype=np.int64, count=len(clouds))
    offsets = np.zeros(len(clouds) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    stacked = np.concatenate(clouds, axis=0) if len(clouds) > 1 else clouds[0]
    points = np.ascontiguousarray(stacked[:, :3], dtype=np.float64)
    normals = None
    if stacked.shape[1] == 6:
        normals = np.ascontiguousarray(stacked[:, 3:6], dtype=np.float64)
    return points, normals, offsets


#: The most parameters a network of eppf may have (the networks of :mod:`eppf.nn` and the classifiers that
#: build them): 4 GB of float32 weights, about four times that to train (gradients and Adam's two moments).
#: The paper's 4D network has 15 million. A larger one is refused before it is built: torch's allocator
#: failed with a RuntimeError ("you tried to allocate 57600000000000 bytes"), torch.empty with an overflow
#: TypeError. (Here, not beside the networks, for the classifiers, which import torch only on use.)
MAX_PARAMETERS = 10**9

#: The most threads ``n_jobs`` may ask for (positive or, counted from the cores, negative): OpenMP runs the
#: threads it is asked for, and far more than any machine has cores crashed it (65,536 on a 2-core guest).
MAX_THREADS = 1024


def check_n_jobs(n_jobs, *, owner=None):
    """Resolve ``n_jobs`` to a positive thread count: the one meaning of ``n_jobs`` in eppf.

    Integers have joblib's meaning: a positive number of threads, ``-1`` all
    cores, ``-2`` all but one, and so on. ``None`` means "do not override
    the environment": the OpenMP default, which honours ``OMP_NUM_THREADS``
    and threadpoolctl limits, so estimators nested in joblib workers (which
    set those limits) do not oversubscribe. Every eppf estimator and
    function with an ``n_jobs`` parameter resolves it here (or, for torch
    and BLAS, leaves the library's own default, which follows the same
    variables); no result ever depends on it.

    Parameters
    ----------
    n_jobs : int or None
        The parameter's value.
    owner : str, default=None
        Name of the estimator, for error messages.

    Returns
    -------
    n_threads : int
        At least 1.

    Raises
    ------
    TypeError
        If ``n_jobs`` is neither an int nor None.
    ValueError
        If ``n_jobs`` is 0, or above :data:`MAX_THREADS` in magnitude.

    Examples
    --------
    >>> from eppf.utils import check_n_jobs
    >>> check_n_jobs(2)
    2
    """
    import os

    from ._scan_fast import openmp_max_threads

    validate_parameter(n_jobs, N_JOBS, name="n_jobs", owner=owner or "check_n_jobs")
    if n_jobs is None:
        return max(1, int(openmp_max_threads()))
    if abs(n_jobs) > MAX_THREADS:  # (the kernels' thread counts are C ints: 10**18 overflowed there)
        raise ValueError(f"{owner or 'check_n_jobs'}: n_jobs={n_jobs} asks for more threads than eppf runs "
                         f"(at most {MAX_THREADS:,}); -1 uses all cores")
    if n_jobs > 0:
        return int(n_jobs)
    n_cpus = os.cpu_count() or 1
    return max(1, n_cpus + 1 + int(n_jobs))


def object_seeds(random_state, n_objects):
    """Draw one 64-bit seed per object from ``random_state``.

    Kernels give each object a private generator seeded from its entry, so a
    descriptor depends only on ``random_state`` and the object's position,
    never on the number of threads or on chunking.

    Examples
    --------
    >>> from eppf.utils import object_seeds
    >>> (object_seeds(0, 3) == object_seeds(0, 3)).all()
    np.True_
    """
    from sklearn.utils import check_random_state

    rng = check_random_state(random_state)
    return rng.randint(0, np.iinfo(np.int64).max, size=n_objects, dtype=np.int64).astype(np.uint64)


def check_int(value, name, owner, low, high=None):
    """Check an integer parameter: ``int(value)``, or a TypeError/ValueError naming ``owner`` and ``name``.

    Parameters
    ----------
    value : object
        The parameter's value; bools are refused.
    name : str
        The parameter's name, for the message.
    owner : str
        The estimator's name, for the message.
    low : int
        Smallest accepted value.
    high : int, default=None
        Largest accepted value (no bound when None).

    Returns
    -------
    value : int
        The value as a Python int.

    See Also
    --------
    check_n_jobs : The check of ``n_jobs``.

    Examples
    --------
    >>> from eppf.utils import check_int
    >>> check_int(5, "n_pairs", "MyDescriptor", 1)
    5
    """
    closed = "left" if high is None else "both"
    validate_parameter(value, [Interval(numbers.Integral, low, high, closed=closed)], name=name, owner=owner)
    return int(value)


def as_vector3(value):
    """``value`` as a float64 array of 3 finite real numbers, or None if it is not one.

    For vector parameters (VFH's ``viewpoint``, GASD's ``view_direction``,
    a viewpoint ``orientation`` of normals): their constraints accept what
    this converts, and the code that resolves them converts with it.
    """
    try:
        v = np.asarray(value)
    except Exception:
        return None
    if v.dtype == object or np.iscomplexobj(v) or not (np.issubdtype(v.dtype, np.number) or v.dtype == bool):
        return None
    if v.shape != (3,):
        return None
    v = np.ascontiguousarray(v, dtype=np.float64)
    return v if np.isfinite(v).all() else None


def check_class_labels(y, owner, name):
    """``y`` as a 1D array of class labels (a column vector is flattened), or an error naming ``owner``.

    Refused: None, other shapes, no labels, NaN or infinite float labels, complex labels, labels that do not
    sort together (TypeError), and targets scikit-learn does not call "binary" or "multiclass" (continuous values).
    """
    if y is None:
        raise ValueError(f"{owner}: {name} is None; class labels are needed")
    y = np.asarray(y)
    if y.ndim == 2 and y.shape[1] == 1:
        y = y.ravel()
    if y.ndim != 1:
        raise ValueError(f"{owner}: {name} must be a 1D array of class labels, got shape {y.shape}")
    if y.shape[0] == 0:
        raise ValueError(f"{owner}: {name} is empty")
    if y.dtype.kind == "f" and not np.all(np.isfinite(y)):
        raise ValueError(f"{owner}: {name} contains NaN or infinite values")
    if y.dtype.kind in "mM" and np.isnat(y).any():
        raise ValueError(f"{owner}: {name} contains NaT (not-a-time) labels")
    if y.dtype.kind == "c":  # (type_of_target's bare "Complex data not supported")
        raise ValueError(f"{owner}: {name} must hold class labels, got complex values")
    if y.dtype == object:
        try:
            np.unique(y)  # (what scikit-learn's type_of_target and the scores do with the labels)
        except TypeError:
            kinds = sorted({type(v).__name__ for v in y.tolist()})
            raise TypeError(f"{owner}: {name} mixes labels that do not sort together ({', '.join(kinds)})") from None
    kind = type_of_target(y)
    if kind not in ("binary", "multiclass"):
        raise ValueError(f"{owner}: {name} must hold class labels, got a {kind!r} target")
    return y
