"""The largest bounding-box side of each cloud: what object scaling divides by and ``scaling="fit"`` learns."""

import numpy as np

__all__ = ["largest_sides"]


def largest_sides(clouds):
    """Largest bounding-box side of each cloud, as ``np.ptp(c[:, :3], axis=0).max()`` gives it.

    One reduction over the stacked coordinates instead of three per cloud;
    maxima, minima and their difference are the same floats either way.
    Sides beyond float64 are inf (callers that need a finite scale refuse
    them).

    Parameters
    ----------
    clouds : sequence of ndarray of shape (n_i, 3) or (n_i, 6)
        Non-empty clouds with finite coordinates (extra columns are ignored).

    Returns
    -------
    sides : ndarray of shape (n_clouds,)
        float64.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils._bounds import largest_sides
    >>> largest_sides([np.array([[0.0, 0.0, 0.0], [1.0, 3.0, 2.0]]), np.zeros((1, 3))])
    array([3., 0.])
    """
    if len(clouds) == 0:
        return np.zeros(0, dtype=np.float64)
    starts = np.cumsum([0] + [len(c) for c in clouds[:-1]])
    xyz = np.concatenate([np.asarray(c, dtype=np.float64)[:, :3] for c in clouds])
    with np.errstate(over="ignore", invalid="ignore"):
        return (np.maximum.reduceat(xyz, starts, axis=0) - np.minimum.reduceat(xyz, starts, axis=0)).max(axis=1)
