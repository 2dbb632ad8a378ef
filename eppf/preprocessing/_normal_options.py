"""The parameters both normal estimators (PCA and Hough) take: ``n_neighbors`` and ``orientation``."""

import numbers

import numpy as np

from ..utils._param_validation import Interval, Satisfies, StrOptions, validate_parameter
from ..utils._validation import as_vector3

__all__ = [
    "N_NEIGHBORS", "ORIENTATION", "ORIENT_CENTROID", "ORIENT_NONE", "ORIENT_VIEWPOINT", "check_n_neighbors",
    "resolve_orientation",
]

#: The kernels' orientation modes: none, away from the centroid, towards a viewpoint.
ORIENT_NONE, ORIENT_CENTROID, ORIENT_VIEWPOINT = 0, 1, 2


#: ``n_neighbors`` of PCA normals (:mod:`eppf.utils._param_validation`); the descriptors that
#: estimate normals declare it too.
N_NEIGHBORS = [Interval(numbers.Integral, 3, None, closed="left", description="an int >= 3 (a plane needs three points)")]


#: ``orientation`` of estimated normals: none, away from the centroid, towards
#: the origin (``"origin"`` and ``"viewpoint"``) or towards a given viewpoint.
ORIENTATION = [
    None,
    StrOptions(["centroid", "origin", "viewpoint"]),
    Satisfies(lambda value: as_vector3(value) is not None, "a finite viewpoint of shape (3,)"),
]


def check_n_neighbors(n_neighbors, owner):
    """Check ``n_neighbors`` against :data:`N_NEIGHBORS`; return it as an int."""
    validate_parameter(n_neighbors, N_NEIGHBORS, name="n_neighbors", owner=owner)
    return int(n_neighbors)


def resolve_orientation(orientation, owner):
    """Check ``orientation`` against :data:`ORIENTATION`; return (kernel mode, viewpoint as float64 (3,))."""
    validate_parameter(orientation, ORIENTATION, name="orientation", owner=owner)
    if orientation is None:
        return ORIENT_NONE, np.zeros(3, dtype=np.float64)
    if isinstance(orientation, str):
        return (ORIENT_CENTROID if orientation == "centroid" else ORIENT_VIEWPOINT), np.zeros(3, dtype=np.float64)
    return ORIENT_VIEWPOINT, as_vector3(orientation)
