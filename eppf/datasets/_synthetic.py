"""A built-in synthetic data set: surface point clouds of simple objects.

Each object is a union of analytic surface patches (rectangles, disks,
cylinder and cone mantles, spheres, a torus, triangles). Points are drawn
uniformly over the object's surface area, so every point comes with the exact
outward unit normal of the patch it lies on. Objects built from several boxes
(bracket, table, chair) drop the points that fall inside or on another box of
the same object, so only the outer surface is sampled.
"""

import numbers

import numpy as np
from sklearn.utils import Bunch, check_random_state

from ..preprocessing._perturb import (
    CONSTRAINTS as PERTURB_CONSTRAINTS,
    add_noise_array,
    check_finite,
    occlude_array,
    random_rotation_matrix,
    random_unit_vector,
    rotate_array,
)
from ..utils._param_validation import RANDOM_STATE, Interval, Options, StrOptions, validate_parameter
from ..utils._sampling import CONSTRAINTS as SAMPLING_CONSTRAINTS
from ..utils._sampling import MAX_N_POINTS

__all__ = ["make_shapes"]

_OWNER = "make_shapes"
_MAX_OCCLUSION = 0.99

#: What each parameter of :func:`make_shapes` accepts (:mod:`eppf.utils._param_validation`).
_CONSTRAINTS = {
    "n_samples_per_class": [Interval(numbers.Integral, 1, None, closed="left")],
    "n_points": SAMPLING_CONSTRAINTS["n_points"],
    "noise": PERTURB_CONSTRAINTS["sigma"],
    # each object is sampled with n_points / (1 - occlusion) points
    "occlusion": [Interval(numbers.Real, 0, _MAX_OCCLUSION, closed="both", description=f"a float in [0, {_MAX_OCCLUSION}]")],
    "size_variation": PERTURB_CONSTRAINTS["fraction"],
    "rotate": [Options(bool, description="True, False"), StrOptions(["z"])],
    "with_normals": [Options(bool)],
    "test_size": PERTURB_CONSTRAINTS["fraction"],
    "random_state": RANDOM_STATE,
    "return_X_y": [Options(bool)],
}


# --------------------------------------------------------------------------- #
# surface patches: each is (area, sampler); sampler(k, rng) -> (points, normals)
# --------------------------------------------------------------------------- #
def _rectangle(origin, u, v, normal):
    origin, u, v, normal = (np.asarray(a, dtype=np.float64) for a in (origin, u, v, normal))
    area = float(np.linalg.norm(np.cross(u, v)))

    def sample(k, rng):
        s, t = rng.random_sample((2, k))
        pts = origin + s[:, None] * u + t[:, None] * v
        return pts, np.broadcast_to(normal, (k, 3))

    return area, sample


def _sample_boxes(centers, halves, k, rng):
    """``k`` points area-weighted over the faces of boxes, the box of each point.

    ``centers`` and ``halves`` (n_boxes, 3) give the axis-aligned boxes; a
    face is picked with probability proportional to its area, then a point
    uniformly on it.
    """
    # the two faces orthogonal to axis a of box b each have area 4 h_{a+1} h_{a+2}
    areas = halves[:, [1, 2, 0]] * halves[:, [2, 0, 1]]
    pick = rng.choice(areas.size, size=k, p=(areas / areas.sum()).ravel())
    box, axis = np.divmod(pick, 3)
    sign = 2.0 * rng.randint(0, 2, size=k) - 1.0
    rows = np.arange(k)
    unit = np.empty((k, 3))
    unit[rows, axis] = sign
    unit[rows, (axis + 1) % 3] = rng.uniform(-1.0, 1.0, k)
    unit[rows, (axis + 2) % 3] = rng.uniform(-1.0, 1.0, k)
    normals = np.zeros((k, 3))
    normals[rows, axis] = sign
    return centers[box] + halves[box] * unit, normals, box


def _disk(z, radius, sign):
    """Horizontal disk at height ``z`` centered on the z axis, normal ``(0, 0, sign)``."""
    normal = np.array([0.0, 0.0, sign])

    def sample(k, rng):
        r = radius * np.sqrt(rng.random_sample(k))
        theta = rng.uniform(0.0, 2.0 * np.pi, k)
        pts = np.column_stack([r * np.cos(theta), r * np.sin(theta), np.full(k, z)])
        return pts, np.broadcast_to(normal, (k, 3))

    return np.pi * radius**2, sample


def _cylinder_mantle(radius, z0, z1):
    def sample(k, rng):
        theta = rng.uniform(0.0, 2.0 * np.pi, k)
        c, s = np.cos(theta), np.sin(theta)
        pts = np.column_stack([radius * c, radius * s, rng.uniform(z0, z1, k)])
        return pts, np.column_stack([c, s, np.zeros(k)])

    return 2.0 * np.pi * radius * (z1 - z0), sample


def _cone_mantle(radius, z0, height):
    """Mantle of a cone with base radius ``radius`` at ``z0`` and apex at ``z0 + height``."""
    slant = np.hypot(radius, height)

    def sample(k, rng):
        # the circumference grows linearly with the distance from the apex,
        # so that distance (as a fraction t of the slant) has density 2t
        t = np.sqrt(rng.random_sample(k))
        theta = rng.uniform(0.0, 2.0 * np.pi, k)
        c, s = np.cos(theta), np.sin(theta)
        pts = np.column_stack([radius * t * c, radius * t * s, z0 + height * (1.0 - t)])
        nrm = np.column_stack([height * c, height * s, np.full(k, radius)]) / slant
        return pts, nrm

    return np.pi * radius * slant, sample


def _sphere(radius, z=0.0, half=0):
    """Sphere centered at ``(0, 0, z)``; ``half=+1``/``-1`` keeps the upper/lower hemisphere."""

    def sample(k, rng):
        d = rng.normal(size=(k, 3))
        d /= np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
        if half:
            d[:, 2] = half * np.abs(d[:, 2])
        return radius * d + np.array([0.0, 0.0, z]), d

    return (2.0 if half else 4.0) * np.pi * radius**2, sample


def _torus(major, minor):
    """Torus about the z axis; the area element is ``minor * (major + minor cos(phi))``."""

    def sample(k, rng):
        phis = []
        have = 0
        while have < k:
            phi = rng.uniform(0.0, 2.0 * np.pi, 2 * (k - have) + 8)
            accept = rng.random_sample(phi.size) * (major + minor) <= major + minor * np.cos(phi)
            phis.append(phi[accept])
            have += phis[-1].size
        phi = np.concatenate(phis)[:k]
        theta = rng.uniform(0.0, 2.0 * np.pi, k)
        ct, st, cp, sp = np.cos(theta), np.sin(theta), np.cos(phi), np.sin(phi)
        ring = major + minor * cp
        pts = np.column_stack([ring * ct, ring * st, minor * sp])
        return pts, np.column_stack([cp * ct, cp * st, sp])

    return 4.0 * np.pi**2 * major * minor, sample


def _triangle(a, b, c, inside):
    """Triangle ``abc`` with the normal pointing away from the point ``inside``."""
    a, b, c = (np.asarray(p, dtype=np.float64) for p in (a, b, c))
    cross = np.cross(b - a, c - a)
    area = 0.5 * float(np.linalg.norm(cross))
    normal = cross / (2.0 * area)
    if normal @ (a - np.asarray(inside, dtype=np.float64)) < 0:
        normal = -normal

    def sample(k, rng):
        s, t = rng.random_sample((2, k))
        flip = s + t > 1.0
        s[flip], t[flip] = 1.0 - s[flip], 1.0 - t[flip]
        pts = a + s[:, None] * (b - a) + t[:, None] * (c - a)
        return pts, np.broadcast_to(normal, (k, 3))

    return area, sample


# --------------------------------------------------------------------------- #
# object classes: builder(j) -> (patches, boxes); j(x) jitters a nominal size.
# Objects made of axis-aligned boxes give boxes, a list of (center, half
# sides), and no patches; a box's faces inside or on another box are hidden.
# Nominal objects fit the unit cube (largest side about 1).
# --------------------------------------------------------------------------- #
def _build_box(j):
    return None, [((0.0, 0.0, 0.0), (j(0.5), j(0.375), j(0.25)))]


def _build_sphere(j):
    return [_sphere(j(0.5))], None


def _build_cylinder(j):
    r, h = j(0.25), j(1.0)
    return [_cylinder_mantle(r, 0.0, h), _disk(0.0, r, -1.0), _disk(h, r, 1.0)], None


def _build_cone(j):
    r, h = j(0.4), j(1.0)
    return [_cone_mantle(r, 0.0, h), _disk(0.0, r, -1.0)], None


def _build_torus(j):
    return [_torus(j(0.35), j(0.13))], None


def _build_capsule(j):
    r, h = j(0.2), j(0.6)
    return [_cylinder_mantle(r, 0.0, h), _sphere(r, 0.0, -1), _sphere(r, h, 1)], None


def _build_pyramid(j):
    x, y, h = j(0.45), j(0.45), j(0.8)
    corners = [(-x, -y, 0.0), (x, -y, 0.0), (x, y, 0.0), (-x, y, 0.0)]
    apex, inside = (0.0, 0.0, h), (0.0, 0.0, 0.25 * h)
    patches = [_rectangle(corners[0], (2 * x, 0.0, 0.0), (0.0, 2 * y, 0.0), (0.0, 0.0, -1.0))]
    patches += [_triangle(corners[i], corners[(i + 1) % 4], apex, inside) for i in range(4)]
    return patches, None


def _build_bracket(j):
    length, width, thick, height = j(1.0), j(0.5), j(0.1), j(0.8)
    boxes = [
        ((length / 2, 0.0, thick / 2), (length / 2, width / 2, thick / 2)),  # foot
        ((thick / 2, 0.0, (thick + height) / 2), (thick / 2, width / 2, (height - thick) / 2)),  # upright
    ]
    return None, boxes


def _build_table(j):
    length, depth, height, top, leg = j(1.0), j(0.6), j(0.75), j(0.05), j(0.06)
    boxes = [((0.0, 0.0, height - top / 2), (length / 2, depth / 2, top / 2))]
    lx, ly = length / 2 - leg, depth / 2 - leg  # legs inset by half their thickness
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            boxes.append(((sx * lx, sy * ly, (height - top) / 2), (leg / 2, leg / 2, (height - top) / 2)))
    return None, boxes


def _build_chair(j):
    width, depth, seat, thick, leg, back = j(0.5), j(0.5), j(0.45), j(0.05), j(0.05), j(0.5)
    boxes = [
        ((0.0, 0.0, seat - thick / 2), (width / 2, depth / 2, thick / 2)),  # seat
        ((0.0, depth / 2 - thick / 2, seat + back / 2), (width / 2, thick / 2, back / 2)),  # back rest
    ]
    lx, ly = width / 2 - leg / 2, depth / 2 - leg / 2  # legs flush with the seat's edges
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            boxes.append(((sx * lx, sy * ly, (seat - thick) / 2), (leg / 2, leg / 2, (seat - thick) / 2)))
    return None, boxes


_CLASSES = {
    "box": _build_box,
    "sphere": _build_sphere,
    "cylinder": _build_cylinder,
    "cone": _build_cone,
    "torus": _build_torus,
    "capsule": _build_capsule,
    "pyramid": _build_pyramid,
    "bracket": _build_bracket,
    "table": _build_table,
    "chair": _build_chair,
}


def _draw(patches, k, rng):
    """``k`` points area-weighted over ``patches``, grouped by patch."""
    areas = np.array([a for a, _ in patches])
    counts = rng.multinomial(k, areas / areas.sum())
    drawn = [sample(int(c), rng) for (_, sample), c in zip(patches, counts) if c]
    return np.concatenate([x for x, _ in drawn]), np.concatenate([n for _, n in drawn])


def _sample_surface(patches, boxes, k, rng):
    """Draw ``k`` points uniformly over the visible surface, shuffled; shape (k, 6)."""
    if boxes is None:
        pts, nrm = _draw(patches, k, rng)
    else:
        centers = np.array([c for c, _ in boxes], dtype=np.float64)
        halves = np.array([h for _, h in boxes], dtype=np.float64)
        tol = 1e-9 * halves.max()
        kept_pts, kept_nrm, have, batch = [], [], 0, k + (k // 4 + 16 if len(boxes) > 1 else 0)
        while have < k:
            pts, nrm, own = _sample_boxes(centers, halves, batch, rng)
            hidden = np.zeros(batch, dtype=bool)
            for b in range(len(boxes) if len(boxes) > 1 else 0):
                inside = np.all(np.abs(pts - centers[b]) <= halves[b] + tol, axis=1)
                hidden |= inside & (own != b)
            kept_pts.append(pts[~hidden])
            kept_nrm.append(nrm[~hidden])
            have += kept_pts[-1].shape[0]
            batch = 2 * (k - have) + 16
        pts, nrm = np.concatenate(kept_pts), np.concatenate(kept_nrm)
    # a random subset of i.i.d. draws in random order is again i.i.d.
    order = rng.permutation(pts.shape[0])[:k]
    return np.hstack([pts[order], nrm[order]])


# --------------------------------------------------------------------------- #
# public generator
# --------------------------------------------------------------------------- #
def _check_classes(classes):
    if classes is None:
        return list(_CLASSES)
    if isinstance(classes, (str, bytes)):
        raise TypeError(f"{_OWNER}: classes must be a list of class names, got {type(classes).__name__}")
    try:
        classes = list(classes)
    except TypeError:
        raise TypeError(f"{_OWNER}: classes must be a list of class names, got {type(classes).__name__}") from None
    if not classes:
        raise ValueError(f"{_OWNER}: classes is empty; choose from {', '.join(_CLASSES)}")
    for name in classes:
        if not isinstance(name, str) or name not in _CLASSES:
            raise ValueError(f"{_OWNER}: unknown class {name!r}; choose from {', '.join(_CLASSES)}")
    if len(set(classes)) != len(classes):
        raise ValueError(f"{_OWNER}: classes contains duplicates: {classes}")
    return classes


def _descr(classes, n_per_class, n_points, noise, occlusion, size_variation, rotate, test_size):
    rot = {True: "uniformly over SO(3)", "z": "about the up axis z", False: "not at all (upright)"}[rotate]
    return (
        "Synthetic shapes\n"
        "----------------\n\n"
        f"{len(classes)} classes ({', '.join(classes)}), {n_per_class} objects each, "
        f"{n_points} surface points per object.\n"
        f"Size variation {size_variation}, rotated {rot}, Gaussian noise sigma={noise} "
        f"(nominal object fits the unit cube), view-dependent occlusion of {occlusion} of the "
        f"sampled surface; stratified split with test share {test_size}.\n"
        "Generated by eppf.datasets.make_shapes."
    )


def make_shapes(
    n_samples_per_class=40,
    *,
    n_points=1024,
    classes=None,
    noise=0.01,
    occlusion=0.2,
    size_variation=0.3,
    rotate=True,
    with_normals=False,
    test_size=0.25,
    random_state=0,
    return_X_y=False,
):
    """Generate a synthetic data set of surface point clouds of simple objects.

    Ten classes, in this order: ``box``, ``sphere``, ``cylinder``, ``cone``,
    ``torus``, ``capsule`` (a cylinder with hemispherical ends), ``pyramid``
    (rectangular base), ``bracket`` (an L of two plates), ``table`` (a top on
    four inset legs) and ``chair`` (a seat on four legs with a back rest).
    Every object is made as follows:

    1. Its nominal dimensions (largest side about 1) are each multiplied by an
       independent factor from ``[1 - size_variation / 2, 1 + size_variation / 2]``
       (aspect ratios vary) and ``m = ceil(n_points / (1 - occlusion))``
       points are drawn uniformly over its outer surface area, each with the
       exact outward unit normal.
    2. It is centered on its bounding-box center and scaled by a factor from
       ``[1 - size_variation, 1 + size_variation]``, so size alone does not
       tell the classes apart.
    3. It is rotated (points and normals) as ``rotate`` says.
    4. A random viewing direction is drawn and the far side is removed by a
       plane cut (as :class:`eppf.preprocessing.Occlusion` does), leaving
       exactly ``n_points`` points.
    5. Gaussian noise of standard deviation ``noise`` is added to the
       coordinates (as :class:`eppf.preprocessing.GaussianNoise` does).

    Parameters
    ----------
    n_samples_per_class : int, default=40
        Objects per class, >= 1.
    n_points : int, default=1024
        Points per object after occlusion, >= 2.
    classes : list of str, default=None
        Names of the classes to generate, in the order of their labels.
        ``None`` means all ten.
    noise : float, default=0.01
        Standard deviation of the coordinate noise, >= 0, in the units in which
        a nominal object fits the unit cube (the paper's unit).
    occlusion : float, default=0.2
        Share of each object's sampled surface points removed on the side
        facing away from the random viewer, ``0 <= occlusion <= 0.99``.
    size_variation : float, default=0.3
        Relative spread of the overall scale and of each dimension,
        ``0 <= size_variation < 1``. ``0`` makes all objects of a class
        congruent.
    rotate : bool or "z", default=True
        ``True``: a uniform random rotation in SO(3); ``"z"``: a uniform
        rotation about the up axis z (upright objects, as in indoor scans);
        ``False``: no rotation (axis-aligned, z up).
    with_normals : bool, default=False
        If True, clouds have six columns, the last three the exact outward
        unit normals of the noise-free surface (rotated with the object, not
        perturbed by the noise).
    test_size : float, default=0.25
        Share of each class put in the test split, ``0 <= test_size < 1``:
        ``round(test_size * n_samples_per_class)`` objects per class, but at
        least one object per class stays in the training split.
    random_state : int, RandomState instance or None, default=0
        Seed of everything random; the same seed gives the same data set.
    return_X_y : bool, default=False
        If True, return ``(data, target)`` instead of a Bunch.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        Dictionary-like object with attributes:

        data : list of ndarray of shape (n_points, 3) or (n_points, 6)
            The clouds, float64, ordered by class then by object.
        target : ndarray of shape (n_objects,), dtype int64
            Class index of each cloud into ``target_names``.
        target_names : ndarray of shape (n_classes,), dtype str
            Class names.
        split : ndarray of shape (n_objects,), dtype str
            ``"train"`` or ``"test"``, stratified by class.
        DESCR : str
            Description of the data set.
    (data, target) : tuple
        If ``return_X_y`` is True.

    Raises
    ------
    ValueError
        If a parameter is out of range or a class name is unknown, or if the
        data set would hold more than a billion points in all
        (``n_samples_per_class * len(classes) * n_points``; 24 GB of float64
        coordinates), which is refused before anything is drawn.
    TypeError
        If a parameter has the wrong type.

    See Also
    --------
    eppf.datasets.load_npz : Load a real data set in the same layout.

    Examples
    --------
    >>> from eppf.datasets import make_shapes
    >>> shapes = make_shapes(5, n_points=256)
    >>> len(shapes.data), shapes.data[0].shape
    (50, (256, 3))
    >>> shapes.target_names[:3].tolist()
    ['box', 'sphere', 'cylinder']
    """
    params = {
        "n_samples_per_class": n_samples_per_class, "n_points": n_points, "noise": noise, "occlusion": occlusion,
        "size_variation": size_variation, "rotate": rotate, "with_normals": with_normals, "test_size": test_size,
        "random_state": random_state, "return_X_y": return_X_y,
    }
    for name, value in params.items():
        validate_parameter(value, _CONSTRAINTS[name], name=name, owner=_OWNER)
    n_per_class, n_points = int(n_samples_per_class), int(n_points)
    classes = _check_classes(classes)
    total = n_per_class * len(classes) * n_points
    if total > MAX_N_POINTS:  # (NumPy's "Unable to allocate" came from the middle of the drawing, or never)
        raise ValueError(
            f"{_OWNER}: n_samples_per_class={n_per_class:,} objects of {len(classes)} classes with n_points="
            f"{n_points:,} are {total:,} points in all, more than the {MAX_N_POINTS:,} a data set may hold")
    noise, occlusion, size_variation, test_size = float(noise), float(occlusion), float(size_variation), float(test_size)
    rotate = rotate if isinstance(rotate, str) else bool(rotate)
    rng = check_random_state(random_state)

    n_sampled = int(np.ceil(n_points / (1.0 - occlusion)))
    # the share of the n_sampled points that occlude() must remove to leave n_points
    removed = (n_sampled - n_points) / n_sampled
    low, high = 1.0 - size_variation / 2, 1.0 + size_variation / 2

    def jitter(x):
        return x * rng.uniform(low, high)

    data = []
    for name in classes:
        build = _CLASSES[name]
        for _ in range(n_per_class):
            patches, boxes = build(jitter)
            cloud = _sample_surface(patches, boxes, n_sampled, rng)
            xyz = cloud[:, :3]
            xyz -= 0.5 * (xyz.min(axis=0) + xyz.max(axis=0))
            xyz *= rng.uniform(1.0 - size_variation, 1.0 + size_variation)
            if rotate is not False:
                axis = "z" if rotate == "z" else None
                cloud = rotate_array(cloud, random_rotation_matrix(axis=axis, random_state=rng), "origin")
            cloud = occlude_array(cloud, removed, random_unit_vector(rng))
            with np.errstate(over="ignore", invalid="ignore"):
                cloud = add_noise_array(cloud, noise, rng)
            check_finite(cloud, _OWNER, "noisy", "use a smaller noise (the objects are about 1 across)")
            data.append(cloud if with_normals else np.ascontiguousarray(cloud[:, :3]))
    target = np.repeat(np.arange(len(classes), dtype=np.int64), n_per_class)

    split = np.full(target.size, "train", dtype="<U5")
    n_test = min(int(np.floor(test_size * n_per_class + 0.5)), n_per_class - 1)
    for label in range(len(classes)):
        members = np.flatnonzero(target == label)
        split[rng.permutation(members)[:n_test]] = "test"

    if return_X_y:
        return data, target
    return Bunch(
        data=data,
        target=target,
        target_names=np.array(classes, dtype=str),
        split=split,
        DESCR=_descr(classes, n_per_class, n_points, noise, occlusion, size_variation, rotate, test_size),
    )

