"""Descriptor computation in chunks of objects, through joblib.

Every descriptor transformer hands its objects to :func:`transform_in_chunks`.
Chunks run in-process by default (the compiled kernels are multi-threaded
already) and on a cluster under ``joblib.parallel_config(backend="dask")``.
Per-object inputs such as seeds are computed for the whole input before
chunking, so where or in which order a chunk runs never changes a result.
"""

import numpy as np
from joblib import Parallel, delayed

__all__ = ["CHUNK", "transform_in_chunks"]

#: Objects per chunk: bounds the memory of one packed chunk and one task.
CHUNK = 256


def _progress(total, verbose, desc):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="obj", disable=not verbose, leave=False)


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
    clouds : list of ndarray
        Validated point clouds.
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
    bounds = list(range(0, n, CHUNK)) + [n]
    chunks = list(zip(bounds[:-1], bounds[1:]))
    jobs = Parallel(return_as="generator")(
        delayed(task)(est, clouds[lo:hi], *[a[lo:hi] for a in per_object], lo) for lo, hi in chunks
    )
    out = np.empty((n, n_features), dtype=np.float64)
    progress = _progress(n, verbose, desc)
    for (lo, hi), block in zip(chunks, jobs):
        out[lo:hi] = block
        progress.update(hi - lo)
    progress.close()
    return out
