"""The parameters both normal estimators (PCA and Hough) take: ``n_neighbors`` and ``orientation``."""

import numbers

import numpy as np

from ..utils._param_validation import Interval, validate_parameter

__all__ = [
    "N_NEIGHBORS", "ORIENT_CENTROID", "ORIENT_NONE", "ORIENT_VIEWPOINT", "check_n_neighbors", "resolve_orientation",
]

#: The kernels' orientation modes: none, away from the centroid, towards a viewpoint.
ORIENT_NONE, ORIENT_CENTROID, ORIENT_VIEWPOINT = 0, 1, 2


#: ``n_neighbors`` of PCA normals (:mod:`eppf.utils._param_validation`); the descriptors that
#: estimate normals declare it too.
N_NEIGHBORS = [Interval(numbers.Integral, 3, None, closed="left", description="an int >= 3 (a plane needs three points)")]


def check_n_neighbors(n_neighbors, owner):
    """Check ``n_neighbors`` against :data:`N_NEIGHBORS`; return it as an int."""
    validate_parameter(n_neighbors, N_NEIGHBORS, name="n_neighbors", owner=owner)
    return int(n_neighbors)


def resolve_orientation(orientation, owner):
    """Return (kernel mode, viewpoint as float64 (3,))."""
    viewpoint = np.zeros(3, dtype=np.float64)
    if orientation is None:
        return ORIENT_NONE, viewpoint
    if isinstance(orientation, str):
        if orientation == "centroid":
            return ORIENT_CENTROID, viewpoint
        if orientation in ("origin", "viewpoint"):
            return ORIENT_VIEWPOINT, viewpoint
        raise ValueError(
            f"{owner}: orientation must be 'centroid', 'origin', 'viewpoint', None or a viewpoint "
            f"of shape (3,), got {orientation!r}"
        )
    try:
        vp = np.asarray(orientation)
    except Exception:
        vp = None
    if vp is None or vp.dtype == object or not (np.issubdtype(vp.dtype, np.number) or vp.dtype == bool):
        raise TypeError(
            f"{owner}: orientation must be 'centroid', 'origin', 'viewpoint', None or a viewpoint "
            f"of shape (3,), got {type(orientation).__name__}"
        )
    if np.iscomplexobj(vp) or vp.shape != (3,):
        raise ValueError(f"{owner}: a viewpoint orientation must have shape (3,), got shape {vp.shape}")
    vp = vp.astype(np.float64)
    if not np.isfinite(vp).all():
        raise ValueError(f"{owner}: the viewpoint contains NaN or infinite values")
    return ORIENT_VIEWPOINT, np.ascontiguousarray(vp)
