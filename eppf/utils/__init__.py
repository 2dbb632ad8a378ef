"""Foundations shared by every layer of eppf: validation, seeding, chunking.

Nothing here imports any other part of eppf. Point-cloud estimators validate
their input with :func:`check_point_clouds` (one error style everywhere;
:func:`check_packed_clouds` gives the clouds packed, as :class:`PackedClouds`),
draw per-object seeds with :func:`object_seeds` (results independent of
threads and chunking) and hand chunks of objects to joblib with
:func:`transform_in_chunks`; :func:`check_n_jobs` gives ``n_jobs`` joblib's
meaning everywhere. :func:`ordered_map` is the one ordered thread map and
:func:`progress_bar` the one progress bar.
"""

from ._chunks import transform_in_chunks
from ._progress import progress_bar
from ._stream import ordered_map
from ._validation import (
    PackedClouds, check_int, check_n_jobs, check_packed_clouds, check_point_cloud, check_point_clouds, object_seeds,
    pack_point_clouds,
)

__all__ = [
    "PackedClouds",
    "check_int",
    "check_n_jobs",
    "check_packed_clouds",
    "check_point_cloud",
    "check_point_clouds",
    "object_seeds",
    "ordered_map",
    "pack_point_clouds",
    "progress_bar",
    "transform_in_chunks",
]
