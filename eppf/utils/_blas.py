"""Matrix products that round the same way whatever the thread count.

OpenBLAS rounds a product differently depending on its thread count (and on
the shape of the operands), so code whose results must not depend on
``n_jobs`` runs each product on one BLAS thread, over blocks whose shapes
are fixed by the caller, and spreads the blocks over threads itself:

- :func:`single_blas_thread`: every BLAS call of the process on one thread
  while any holder is inside (reference-counted across threads);
- :class:`blas_limits`: that context for a computation with an ``n_jobs``
  parameter, giving the number of threads for its blocks;
- :func:`map_blocks`: the blocks, in order, on those threads or as tasks of
  the joblib backend an enclosing ``joblib.parallel_config`` names (a dask
  cluster, say), each on one BLAS thread wherever it runs.
"""

import threading
from contextlib import contextmanager

from ._stream import ordered_map
from ._validation import check_n_jobs

__all__ = ["blas_limits", "joblib_backend_is_set", "map_blocks", "single_blas_thread"]

_lock = threading.Lock()
_state = {"depth": 0, "limiter": None}


@contextmanager
def single_blas_thread():
    """Context manager: every BLAS call of this process on one thread while inside.

    Reference-counted, so that blocks running concurrently in the threads of
    one process (a thread pool, a dask worker with several threads) never
    restore the original thread count under one another's matrix products.

    Yields
    ------
    None
    """
    from threadpoolctl import threadpool_limits

    with _lock:
        if _state["depth"] == 0:
            _state["limiter"] = threadpool_limits(limits=1, user_api="blas")
        _state["depth"] += 1
    try:
        yield
    finally:
        with _lock:
            _state["depth"] -= 1
            if _state["depth"] == 0:
                _state["limiter"].restore_original_limits()
                _state["limiter"] = None


class blas_limits:
    """Context for blocked matrix products: every product single-threaded.

    The products run on one BLAS thread each, over blocks whose shapes never
    depend on ``n_jobs``; the blocks themselves are spread over ``n_jobs``
    threads (joblib's meaning) by :func:`map_blocks`, or handed to the
    joblib backend set by an enclosing ``joblib.parallel_config`` (e.g. a
    dask cluster). Results are therefore bit-identical for any thread count
    and any backend. Entering the context gives the number of threads.

    Parameters
    ----------
    n_jobs : int or None
        Threads over blocks, resolved by :func:`eppf.utils.check_n_jobs`.
    owner : str
        Name used in error messages.
    """

    def __init__(self, n_jobs, owner):
        self.n_threads = check_n_jobs(n_jobs, owner=owner)

    def __enter__(self):
        self._limits = single_blas_thread()
        self._limits.__enter__()
        return self.n_threads

    def __exit__(self, *exc):
        return self._limits.__exit__(*exc)


def joblib_backend_is_set():
    """Whether an enclosing ``joblib.parallel_config`` (or ``parallel_backend``) names a backend.

    Returns
    -------
    is_set : bool
        True inside ``parallel_config(backend=...)``.
    """
    from joblib import parallel

    config = getattr(parallel._backend, "config", None)
    return isinstance(config, dict) and isinstance(config.get("backend"), parallel.ParallelBackendBase)


def _run_on_one_blas_thread(func, *args):
    """Task wrapper: ``func(*args)`` with single-threaded BLAS in whatever process runs it."""
    with single_blas_thread():
        return func(*args)


def map_blocks(func, arg_tuples, n_threads):
    """``func(*args)`` for each tuple of ``arg_tuples``, results yielded in order.

    Under a joblib backend set by the caller (``with
    joblib.parallel_config(backend="dask"): ...``) the blocks are joblib
    tasks on that backend, with its ``n_jobs``; otherwise they run in up to
    ``n_threads`` threads of this process (call it inside
    :class:`blas_limits`). ``func`` is a module-level function and the
    large arrays are passed as separate arguments, so that joblib's dask
    backend ships each of them to the cluster once (it scatters every large
    argument once per call). Each block runs with single-threaded BLAS
    wherever it runs, and the blocks are fixed by the caller, so the results
    do not depend on where or in which order they run.

    Parameters
    ----------
    func : callable
        A module-level function.
    arg_tuples : list of tuple
        The arguments of each block.
    n_threads : int
        Threads of this process (without a joblib backend).

    Yields
    ------
    result : object
        ``func(*args)``, in the order of ``arg_tuples``; at most
        ``2 * n_threads`` are computed ahead of the consumer.
    """
    if joblib_backend_is_set():
        from joblib import Parallel, delayed

        yield from Parallel(return_as="generator")(
            delayed(_run_on_one_blas_thread)(func, *args) for args in arg_tuples
        )
    elif n_threads <= 1 or len(arg_tuples) <= 1:
        for args in arg_tuples:
            yield func(*args)
    else:
        yield from ordered_map(lambda args: func(*args), arg_tuples, workers=n_threads, depth=2 * n_threads)
