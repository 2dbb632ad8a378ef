"""Descriptor computation in chunks of objects, through joblib.

Every descriptor transformer hands its objects to :func:`transform_in_chunks`.
Chunks run in-process by default (the compiled kernels are multi-threaded
already) and on a cluster under ``joblib.parallel_config(backend="dask")``.
Per-object inputs such as seeds are computed for the whole input before
chunking, so where or in which order a chunk runs never changes a result.
Chunks are bounded in objects (:data:`CHUNK`) and in points
(:data:`CHUNK_POINTS`), so that Python regains control, and handles Ctrl-C,
at least about once a second.
"""

import numpy as np
from joblib import Parallel, delayed

from ._validation import PackedClouds, check_n_jobs
from ._progress import progress_bar

__all__ = ["CHUNK", "CHUNK_POINTS", "transform_in_chunks"]

#: Objects per chunk: bounds the memory of one packed chunk and one task.
CHUNK = 256

#: Points per chunk and thread, summed over the chunk's clouds (a chunk always
#: holds at least one cloud). The compiled kernels do not return to Python
#: until a chunk is done, and Python handles Ctrl-C only then: this keeps one
#: chunk to about half a second or less (OUR-CVFH, the slowest descriptor, on
#: 2,048-point clouds), so an interrupt is prompt, while each thread still
#: gets a dozen or more objects of a chunk to balance its load.
CHUNK_POINTS = 1 << 15


def _n_threads(est):
    """Threads the estimator's kernels use (1 if it cannot say)."""
    try:
        return check_n_jobs(getattr(est, "n_jobs", None))
    except (TypeError, ValueError, ImportError):
        return 1


def _chunk_bounds(clouds, chunk, chunk_points):
    """``(lo, hi)`` pairs covering ``clouds`` with at most ``chunk`` objects and
    (unless one cloud alone is larger) at most ``chunk_points`` points each."""
    sizes = clouds.sizes.tolist() if isinstance(clouds, PackedClouds) else [len(c) for c in clouds]
    chunks, lo, points = [], 0, 0
    for i, size in enumerate(sizes):
        if i > lo and (i - lo >= chunk or points + size > chunk_points):
            chunks.append((lo, i))
            lo, points = i, 0
        points += size
    if lo < len(sizes):
        chunks.append((lo, len(sizes)))
    return chunks


def transform_in_chunks(task, est, clouds, per_object=(), *, n_features, verbose=0, desc=""):
    """Compute descriptor rows chunk by chunk through joblib.

    Parameters
    ----------
    task : callable
        ``task(est, clouds_chunk, *per_object_chunks, first_index)`` returning
        an array of shape (len(clouds_chunk), n_features). It must be a
        module-level function so that it pickles.
    est : estimator
        The fitted transformer, passed to every task.
    clouds : PackedClouds or list of ndarray
        Validated point clouds; chunks are its slices ``clouds[lo:hi]``.
    per_object : sequence of ndarray
        Arrays with one entry per object (seeds, scales), sliced with the clouds.
    n_features : int
        Columns of the result.
    verbose : int, default=0
        Show a progress bar over objects when positive.
    desc : str, default=""
        Label of the progress bar.

    Returns
    -------
    X : ndarray of shape (len(clouds), n_features)
        The tasks' rows, in the order of ``clouds``.

    See Also
    --------
    object_seeds : Per-object seeds drawn before chunking.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.utils import transform_in_chunks
    >>> def centroid(est, chunk, first_index):
    ...     return np.array([c.mean(axis=0) for c in chunk])
    >>> clouds = [np.full((4, 3), float(k)) for k in range(3)]
    >>> transform_in_chunks(centroid, None, clouds, n_features=3)
    array([[0., 0., 0.],
           [1., 1., 1.],
           [2., 2., 2.]])
    """
    n = len(clouds)
    chunks = _chunk_bounds(clouds, CHUNK, CHUNK_POINTS * _n_threads(est))
    jobs = Parallel(return_as="generator")(
        delayed(task)(est, clouds[lo:hi], *[a[lo:hi] for a in per_object], lo) for lo, hi in chunks
    )
    out = np.empty((n, n_features), dtype=np.float64)
    progress = progress_bar(total=n, desc=desc, unit="obj", enabled=bool(verbose))
    for (lo, hi), block in zip(chunks, jobs):
        out[lo:hi] = block
        progress.update(hi - lo)
    progress.close()
    return out
