"""Per-object centroids, order statistics and stretches of packed point clouds, the bits NumPy gives.

The compiled kernels of :mod:`eppf.utils._stats_fast`, for the packages
above ``utils`` (``preprocessing``'s :class:`~eppf.preprocessing.RandomScaling`,
``descriptors``' :class:`~eppf.descriptors.ProportionTransformer`), which
take a package's kernels only through the package's Python modules.
"""

from ._stats_fast import cloud_means, extreme_values, stretch_about

__all__ = ["cloud_means", "extreme_values", "stretch_about"]
