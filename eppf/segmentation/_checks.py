"""Validation shared by the segmentation functions: scenes, fields, tolerances."""

import numbers

import numpy as np

from ..utils._param_validation import Interval, validate_parameter
from ..utils._validation import check_point_cloud

__all__ = ["MAX_EXTENT", "MAX_POINTS", "MIN_EXTENT", "MIN_TOLERANCE", "TOLERANCE", "check_field", "check_scene",
           "check_tolerance"]

#: The largest scene extent per axis: squared distances and the plane fit's sums of squares
#: (up to 1e9 points) stay finite below it, with a wide margin over any real scan (1e7 m).
MAX_EXTENT = 1e100

#: The most points a scene may have (the readers' bound on a cloud too): the grid ground model's int64 sort
#: keys, a cell (at most 4 per point) times the points plus a rank, stay below 2**63 up to about 1.5e9.
MAX_POINTS = 10**9

#: The smallest largest extent of a scene: below it, cell sides derived from the extent or a tolerance
#: consistent with it reach subnormal numbers, whose reciprocals overflow (a real scan spans 1e-3 m at least).
MIN_EXTENT = 1e-100

#: The smallest clustering distance: below it the squares of the distances compared with it underflow
#: float64 (1e-150 squared is 1e-300, still a normal number), and the cells' sides with them.
MIN_TOLERANCE = 1e-150

#: ``tolerance``: None (derived from the point spacing) or a positive distance.
TOLERANCE = [None, Interval(numbers.Real, 0, None, closed="neither")]


def check_scene(points, owner):
    """The scene's coordinates as a C-contiguous float64 array of shape (n, 3).

    Six-column input (points and normals) is accepted; the normals are dropped.
    Raises TypeError/ValueError naming ``owner`` for a wrong type or shape, an
    empty scene, a single point, more than :data:`MAX_POINTS` points, NaN or
    infinite coordinates, a scene whose points are all identical, one whose
    extent is beyond :data:`MAX_EXTENT` (its squared distances would overflow
    float64) or one whose largest extent is below :data:`MIN_EXTENT`.
    """
    arr = check_point_cloud(points, owner=owner, min_points=2, allow_normals=True)
    if len(arr) > MAX_POINTS:
        raise ValueError(f"{owner}: the scene has {len(arr):,} points; at most {MAX_POINTS:,} can be segmented: "
                         "split it into tiles")
    xyz = np.ascontiguousarray(arr[:, :3])
    with np.errstate(over="ignore"):
        extent = xyz.max(axis=0) - xyz.min(axis=0)
    if not np.isfinite(extent).all():
        raise ValueError(f"{owner}: the scene's extent overflows float64 (coordinates from {xyz.min():.6g} to "
                         f"{xyz.max():.6g})")
    if extent.max() > MAX_EXTENT:
        raise ValueError(f"{owner}: the scene spans {extent.max():.6g} along one axis; at most {MAX_EXTENT:g} can be "
                         "segmented (squared distances would overflow float64): rescale the coordinates")
    if extent.max() < MIN_EXTENT:
        raise ValueError(f"{owner}: the scene spans only {extent.max():.6g} along its longest axis; at least "
                         f"{MIN_EXTENT:g} is needed (smaller cells underflow float64): rescale the coordinates")
    return xyz


def check_tolerance(tolerance, owner):
    """``tolerance`` as a float (None stays None), or the validator's error naming ``owner``; a ValueError
    too for a tolerance below :data:`MIN_TOLERANCE`."""
    validate_parameter(tolerance, TOLERANCE, name="tolerance", owner=owner)
    if tolerance is None:
        return None
    if tolerance < MIN_TOLERANCE:
        raise ValueError(f"{owner}: tolerance must be at least {MIN_TOLERANCE:g} (squared distances below it "
                         f"underflow float64), got {float(tolerance)!r}: rescale the coordinates")
    return float(tolerance)


def check_field(values, n_points, owner, name="values"):
    """An integer field as an int64 array of ``n_points`` entries.

    Integer and boolean arrays are taken as they are; floating-point arrays only
    when every value is a whole number (as fields written as float by some tools).
    """
    if isinstance(values, (str, bytes)) or values is None:
        raise TypeError(f"{owner}: {name} must be an integer array, got {type(values).__name__}")
    try:
        arr = np.asarray(values)
    except Exception as exc:
        raise TypeError(f"{owner}: {name} could not be converted to an array: {exc}") from None
    if arr.ndim != 1:
        raise ValueError(f"{owner}: {name} must be one-dimensional, one value per point, got shape {arr.shape}")
    if n_points is not None and arr.shape[0] != n_points:
        raise ValueError(f"{owner}: {name} has {arr.shape[0]} values for {n_points} points")
    if arr.dtype == bool or np.issubdtype(arr.dtype, np.integer):
        if arr.dtype == np.uint64 and arr.size and arr.max() > np.iinfo(np.int64).max:
            raise ValueError(f"{owner}: {name} holds values above 2**63 - 1, which no segment number can hold")
        return arr.astype(np.int64)
    if np.issubdtype(arr.dtype, np.floating):
        whole = np.isfinite(arr) & (arr == np.round(arr)) & (np.abs(arr) < 2.0**63)
        if not whole.all():
            raise TypeError(f"{owner}: {name} must be an integer field, got {arr.dtype} values that are not "
                            f"whole numbers (first at point {int(np.flatnonzero(~whole)[0])})")
        return arr.astype(np.int64)
    raise TypeError(f"{owner}: {name} must be an integer field, got dtype {arr.dtype}")
