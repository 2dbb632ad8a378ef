"""Matching of histogram descriptors by symmetric Kullback-Leibler divergence.

The symmetric KL divergence of two histograms ``a`` and ``b`` is

    d(a, b) = sum_i (a_i - b_i) (ln a_i - ln b_i)
            = sum_i a_i ln a_i + sum_i b_i ln b_i - a . ln(b) - b . ln(a).

The two cross terms are matrix products, so the distances between every row
of a query block and every row of a reference set cost two GEMMs. Rows are
processed in chunks so that no more than a chunk of the distance matrix
(plus the floored histograms and their logarithms) is held at once.
"""

import numbers
import threading
from collections import namedtuple
from contextlib import contextmanager

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils import check_array
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

__all__ = ["KLNearestNeighbors", "symmetric_kl_distances"]

# Target size of one block of the distance matrix, in float64 entries (64 MiB).
_BLOCK_ENTRIES = 1 << 23
# Side of the square blocks used by the leave-one-out search.
_LOO_BLOCK = 1024


def _check_floor(floor, owner):
    """Return ``"auto"`` or ``floor`` as a positive finite float."""
    if isinstance(floor, str):
        if floor != "auto":
            raise ValueError(f"{owner}: floor must be 'auto' or a positive float, got {floor!r}")
        return floor
    if isinstance(floor, bool) or not isinstance(floor, numbers.Real):
        raise TypeError(f"{owner}: floor must be 'auto' or a positive float, got {type(floor).__name__}")
    floor = float(floor)
    if not (np.isfinite(floor) and floor > 0):
        raise ValueError(f"{owner}: floor must be 'auto' or a positive float, got {floor!r}")
    return floor


def _check_chunk_size(chunk_size, owner):
    if chunk_size is None:
        return None
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, numbers.Integral):
        raise TypeError(f"{owner}: chunk_size must be a positive int or None, got {type(chunk_size).__name__}")
    if chunk_size < 1:
        raise ValueError(f"{owner}: chunk_size must be a positive int or None, got {chunk_size}")
    return int(chunk_size)


def _check_renormalize(renormalize, owner):
    if not isinstance(renormalize, (bool, np.bool_)):
        raise TypeError(f"{owner}: renormalize must be a bool, got {type(renormalize).__name__}")
    return bool(renormalize)


_one_blas_lock = threading.Lock()
_one_blas_state = {"depth": 0, "limiter": None}


@contextmanager
def _one_blas_thread():
    """Every BLAS call in this process on one thread while any holder is inside.

    Reference-counted, so that blocks running concurrently in the threads of
    one process (a thread pool, a dask worker with several threads) never
    restore the original thread count under one another's matrix products.
    """
    from threadpoolctl import threadpool_limits

    with _one_blas_lock:
        if _one_blas_state["depth"] == 0:
            _one_blas_state["limiter"] = threadpool_limits(limits=1, user_api="blas")
        _one_blas_state["depth"] += 1
    try:
        yield
    finally:
        with _one_blas_lock:
            _one_blas_state["depth"] -= 1
            if _one_blas_state["depth"] == 0:
                _one_blas_state["limiter"].restore_original_limits()
                _one_blas_state["limiter"] = None


class _blas_limits:
    """Context for the distance computations: every matrix product single-threaded.

    OpenBLAS rounds a product differently depending on its thread count (and
    on the shape of the operands), so the products run on one BLAS thread
    each, over row blocks whose shapes never depend on ``n_jobs``; the
    blocks themselves are spread over ``n_jobs`` threads (joblib's meaning)
    by :func:`_map_blocks`, or handed to the joblib backend set by an
    enclosing ``joblib.parallel_config`` (e.g. a dask cluster). Distances
    are therefore bit-identical for any thread count and any backend.
    Entering the context gives the number of threads.
    """

    def __init__(self, n_jobs, owner):
        from ..utils._validation import check_n_jobs

        self.n_threads = check_n_jobs(n_jobs, owner=owner)

    def __enter__(self):
        self._limits = _one_blas_thread()
        self._limits.__enter__()
        return self.n_threads

    def __exit__(self, *exc):
        return self._limits.__exit__(*exc)


def _ordered_map(func, items, n_threads):
    """``func`` over ``items`` in up to ``n_threads`` threads, results yielded in order.

    At most ``2 * n_threads`` results are pending at a time, so memory stays
    bounded however many items there are.
    """
    items = list(items)
    if n_threads <= 1 or len(items) <= 1:
        for item in items:
            yield func(item)
        return
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=n_threads) as pool:
        pending = deque()
        for item in items:
            pending.append(pool.submit(func, item))
            if len(pending) >= 2 * n_threads:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def _joblib_backend_is_set():
    """Whether an enclosing ``joblib.parallel_config`` (or ``parallel_backend``) names a backend."""
    from joblib import parallel

    config = getattr(parallel._backend, "config", None)
    return isinstance(config, dict) and isinstance(config.get("backend"), parallel.ParallelBackendBase)


def _run_on_one_blas_thread(func, *args):
    """Task wrapper: ``func(*args)`` with single-threaded BLAS in whatever process runs it."""
    with _one_blas_thread():
        return func(*args)


def _map_blocks(func, arg_tuples, n_threads):
    """``func(*args)`` for each tuple of ``arg_tuples``, results yielded in order.

    Under a joblib backend set by the caller (``with
    joblib.parallel_config(backend="dask"): ...``) the blocks are joblib
    tasks on that backend, with its ``n_jobs``; otherwise they run in up to
    ``n_threads`` threads of this process. ``func`` is a module-level
    function and the large arrays are passed as separate arguments, so that
    joblib's dask backend ships each of them to the cluster once (it
    scatters every large argument once per call). Each block runs with
    single-threaded BLAS wherever it runs, and the blocks are fixed by the
    caller, so the results do not depend on where or in which order they run.
    """
    if _joblib_backend_is_set():
        from joblib import Parallel, delayed

        yield from Parallel(return_as="generator")(
            delayed(_run_on_one_blas_thread)(func, *args) for args in arg_tuples
        )
    else:
        yield from _ordered_map(lambda args: func(*args), arg_tuples, n_threads)


def _check_non_negative(X, owner, name="X"):
    """Raise if the (finite, numeric) array ``X`` holds a negative value."""
    if X.size and X.min() < 0:
        raise ValueError(
            f"Negative values in data passed to {owner} ({name}): histograms must be "
            f"non-negative, found minimum {float(X.min())!r}"
        )


def _learn_floor(arrays, owner):
    """Half the smallest positive value over ``arrays`` (the paper's floor)."""
    smallest = np.inf
    for A in arrays:
        positive = A[A > 0]
        if positive.size:
            smallest = min(smallest, float(positive.min()))
    if not np.isfinite(smallest):
        raise ValueError(
            f"{owner}: cannot learn floor='auto' because X has no positive value; "
            "pass floor as a positive float"
        )
    return smallest / 2.0


class _Prepared(namedtuple("_Prepared", "H L s mass lam")):
    """Floored histograms ``H``, ``L = ln H``, ``s = sum H ln H`` per row,
    the row masses and the largest ``|ln H|`` per row (for rounding bounds)."""

    def rows(self, start, stop):
        return _Prepared(*(a[start:stop] for a in self))


def _prepare(X, floor, renormalize, owner):
    """Floor, optionally renormalise, and precompute logs and row terms."""
    H = np.maximum(X, floor, dtype=np.float64)
    if renormalize:
        H /= H.sum(axis=1, keepdims=True)
    with np.errstate(over="ignore", invalid="ignore"):
        L = np.log(H)
        s = np.einsum("ij,ij->i", H, L)
    if not np.all(np.isfinite(s)):
        raise ValueError(f"{owner}: histogram values are too large for the KL divergence (overflow in x ln x)")
    lam = np.abs(L).max(axis=1) if L.shape[1] else np.zeros(L.shape[0])
    return _Prepared(H, L, s, H.sum(axis=1), lam)


def _kl_block(P, Q, out, tmp):
    """Fill ``out`` with the symmetric KL distances between rows of P and of Q.

    ``out`` and ``tmp`` are C-contiguous buffers of shape (len(P.H), len(Q.H)).
    """
    np.matmul(P.H, Q.L.T, out=out)
    np.matmul(P.L, Q.H.T, out=tmp)
    out += tmp
    np.subtract(P.s[:, None], out, out=out)
    out += Q.s[None, :]
    np.maximum(out, 0.0, out=out)  # rounding can leave tiny negative values
    return out


def _tie_tolerance(P, Q, out):
    """Bound on the rounding error of each entry of ``_kl_block(P, Q)``.

    The terms summed are bounded by ``|s_p| + |s_q| + m_p lam_q + m_q lam_p``
    (masses ``m``, largest ``|ln h|`` per row ``lam``); a dot product of
    length ``n`` carries a relative error of at most about ``n`` units in the
    last place. Distances closer than this are treated as ties.
    """
    rel = 4.0 * max(P.H.shape[1], 16) * np.finfo(np.float64).eps
    np.multiply(P.mass[:, None], Q.lam[None, :], out=out)
    out += P.lam[:, None] * Q.mass[None, :]
    out += np.abs(P.s)[:, None]
    out += np.abs(Q.s)[None, :]
    out *= rel
    return out


def _auto_chunk(n_ref):
    return max(1, _BLOCK_ENTRIES // max(1, n_ref))


def _row_bounds(n_p, n_q, chunk_size):
    """Fixed ``(start, stop)`` row blocks of P: they depend on ``chunk_size`` and the shapes only."""
    step = chunk_size if chunk_size is not None else _auto_chunk(n_q)
    step = min(step, max(n_p, 1))
    return [(start, min(start + step, n_p)) for start in range(0, n_p, step)]


_N_FIELDS = len(_Prepared._fields)


def _distance_task(start, stop, with_tolerance, *arrays):
    """Distances (and tie tolerances) of rows ``start:stop`` of P to all of Q.

    ``arrays`` are the fields of P followed by those of Q (see :func:`_map_blocks`).
    """
    P, Q = _Prepared(*arrays[:_N_FIELDS]), _Prepared(*arrays[_N_FIELDS:])
    Pc = P.rows(start, stop)
    shape = (stop - start, Q.H.shape[0])
    D = _kl_block(Pc, Q, np.empty(shape), np.empty(shape))
    T = _tie_tolerance(Pc, Q, np.empty(shape)) if with_tolerance else None
    return D, T


def _kneighbors_task(start, stop, k, loo, *arrays):
    """Indices and distances of the ``k`` nearest rows of Q for rows ``start:stop`` of P."""
    D, T = _distance_task(start, stop, True, *arrays)
    if loo:
        D[np.arange(stop - start), np.arange(start, stop)] = np.inf
    idx = _smallest_k(D, T, k)
    return idx, np.take_along_axis(D, idx, axis=1)


def _iter_kl_chunks(P, Q, chunk_size, with_tolerance=False, n_threads=1):
    """Yield ``(start, D, T)``: distances of rows ``start:start+len(D)`` of P to all of Q.

    ``T`` holds the tie tolerance of each entry (None unless asked for).
    Blocks are computed by :func:`_map_blocks` (call it inside
    :class:`_blas_limits`) and yielded in row order; their shapes depend on
    ``chunk_size`` and the data only.
    """
    bounds = _row_bounds(P.H.shape[0], Q.H.shape[0], chunk_size)
    args = [(start, stop, with_tolerance, *P, *Q) for start, stop in bounds]
    for (start, _), (D, T) in zip(bounds, _map_blocks(_distance_task, args, n_threads)):
        yield start, D, T


def _iter_kneighbors(P, Q, chunk_size, k, loo, n_threads=1):
    """Yield ``(start, indices, distances)`` of the ``k`` nearest rows of Q, block by block of P."""
    bounds = _row_bounds(P.H.shape[0], Q.H.shape[0], chunk_size)
    args = [(start, stop, k, loo, *P, *Q) for start, stop in bounds]
    for (start, _), (idx, dist) in zip(bounds, _map_blocks(_kneighbors_task, args, n_threads)):
        yield start, idx, dist


def _named(owner, func, *args, **kwargs):
    """Call a scikit-learn validator, prefixing its error messages with ``owner``."""
    try:
        return func(*args, **kwargs)
    except (ValueError, TypeError) as exc:
        if type(exc) not in (ValueError, TypeError) or str(exc).startswith(owner):
            raise
        raise type(exc)(f"{owner}: {exc}") from exc


def _validate_histograms(X, owner, name):
    X = _named(owner, check_array, X, dtype=np.float64, ensure_all_finite=True, input_name=name)
    _check_non_negative(X, owner, name)
    return X


def symmetric_kl_distances(X, Y=None, *, floor="auto", renormalize=False, chunk_size=None, n_jobs=None):
    """Compute the symmetric Kullback-Leibler divergence between all pairs of histograms.

    Parameters
    ----------
    X : array-like of shape (n_samples_X, n_bins)
        Non-negative histograms, one per row.
    Y : array-like of shape (n_samples_Y, n_bins), default=None
        Second set of histograms. ``None`` means ``Y = X``; the diagonal of
        the result is then exactly zero.
    floor : "auto" or float, default="auto"
        Every bin below ``floor`` (in particular every empty bin) is raised to
        ``floor`` before taking logarithms. ``"auto"`` uses half the smallest
        positive value in ``X`` and ``Y`` together, the paper's "common
        minimum value that is twice smaller than the smallest observed bin
        value"; on that data the floor only ever replaces zeros.
    renormalize : bool, default=False
        Whether each floored histogram is divided by its sum. The paper does
        not say; by default histograms are left as they are, so flooring adds
        a little mass to sparse histograms.
    chunk_size : int, default=None
        Rows of ``X`` handled per block; temporaries are two blocks of shape
        ``(chunk_size, n_samples_Y)``. ``None`` picks blocks of about 64 MiB.
        Distances may differ with it in the last bits only (a matrix
        product's rounding depends on its shape); for a given value they
        are bit-identical whatever ``n_jobs`` or joblib backend.
    n_jobs : int, default=None
        Threads over blocks of distances (joblib's meaning; ``None``
        is the OpenMP default, see :func:`eppf.utils.check_n_jobs`). Each
        block's matrix products run on one BLAS thread, so the result is
        bit-identical for any value. Inside ``joblib.parallel_config``
        (or ``parallel_backend``) naming a backend, e.g. ``"dask"`` with a
        ``dask.distributed`` client, the same fixed blocks are that
        backend's tasks instead, with bit-identical results.

    Returns
    -------
    distances : ndarray of shape (n_samples_X, n_samples_Y)
        ``d(x, y) = sum_i (x_i - y_i)(ln x_i - ln y_i)``, non-negative
        (rounding below zero is clipped).

    See Also
    --------
    KLNearestNeighbors : Nearest-neighbor classification with this distance.

    Notes
    -----
    With ``h`` the floored histograms, ``d(x, y) = sum x ln x + sum y ln y -
    x . ln y - y . ln x``; the two cross terms are computed as matrix
    products, chunk by chunk. The cancellation between these terms limits
    the absolute accuracy to a small multiple of machine precision times
    the size of the terms (``sum |x ln y|``), e.g. about ``1e-13`` for
    normalized histograms of 1,200 bins, however small ``d`` is.

    References
    ----------
    .. [1] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import symmetric_kl_distances
    >>> X = np.array([[0.5, 0.5, 0.0], [0.25, 0.25, 0.5]])
    >>> D = symmetric_kl_distances(X, floor=0.01)
    >>> D.shape
    (2, 2)
    >>> bool(np.isclose(D[0, 1], (0.5 - 0.25) * np.log(2) * 2 + (0.01 - 0.5) * np.log(0.02)))
    True
    """
    owner = "symmetric_kl_distances"
    floor = _check_floor(floor, owner)
    renormalize = _check_renormalize(renormalize, owner)
    chunk_size = _check_chunk_size(chunk_size, owner)
    X = _validate_histograms(X, owner, "X")
    same = Y is None
    if not same:
        Y = _validate_histograms(Y, owner, "Y")
        if Y.shape[1] != X.shape[1]:
            raise ValueError(
                f"{owner}: X and Y must have the same number of bins, got {X.shape[1]} and {Y.shape[1]}"
            )
    if floor == "auto":
        floor = _learn_floor([X] if same else [X, Y], owner)
    PX = _prepare(X, floor, renormalize, owner)
    PY = PX if same else _prepare(Y, floor, renormalize, owner)
    D = np.empty((X.shape[0], PY.H.shape[0]))
    with _blas_limits(n_jobs, owner) as n_threads:
        for start, block, _ in _iter_kl_chunks(PX, PY, chunk_size, n_threads=n_threads):
            D[start : start + block.shape[0]] = block
    if same:
        np.fill_diagonal(D, 0.0)
    return D


def _first_near_min(D, T, axis):
    """Lowest index along ``axis`` whose distance is within ``T`` of the minimum."""
    m = D.min(axis=axis, keepdims=True)
    return np.argmax(D <= m + T, axis=axis)


def _smallest_k(D, T, k):
    """Indices of the ``k`` nearest columns of each row of ``D``.

    Greedy rule, applied ``k`` times: among the columns not yet taken, the
    lowest index whose distance is within its tie tolerance ``T`` of the
    smallest remaining distance. Without near-ties this is plain sorting by
    distance; with exact or rounding-level ties it prefers low indices.
    """
    n_rows, n_cols = D.shape
    if k == 1:
        return _first_near_min(D, T, axis=1)[:, None]
    if k < n_cols:
        kth = np.partition(D, k - 1, axis=1)[:, k - 1 : k]
        cand = D <= kth + T  # the k nearest and everything tied with them
    else:
        cand = np.ones(D.shape, dtype=bool)
    rows, cols = np.nonzero(cand)  # sorted by row, then column
    counts = np.bincount(rows, minlength=n_rows)
    width = int(counts.max())
    pos = np.arange(rows.size) - np.repeat(np.cumsum(counts) - counts, counts)
    vals = np.full((n_rows, width), np.inf)
    tols = np.zeros((n_rows, width))
    idx = np.full((n_rows, width), n_cols, dtype=np.intp)
    vals[rows, pos] = D[rows, cols]
    tols[rows, pos] = T[rows, cols]
    idx[rows, pos] = cols
    out = np.empty((n_rows, k), dtype=np.intp)
    r = np.arange(n_rows)
    for step in range(k):
        m = vals.min(axis=1, keepdims=True)
        pick = np.argmax(vals <= m + tols, axis=1)
        out[:, step] = idx[r, pick]
        vals[r, pick] = np.inf
        tols[r, pick] = 0.0
    return out


def _loo_block_task(i0, i1, j0, j1, *arrays):
    """Each row's and each column's nearest candidate in block (i0:i1, j0:j1) of P against itself."""
    P = _Prepared(*arrays)
    Pi, Pj = P.rows(i0, i1), P.rows(j0, j1)
    D = _kl_block(Pi, Pj, np.empty((i1 - i0, j1 - j0)), np.empty((i1 - i0, j1 - j0)))
    T = _tie_tolerance(Pi, Pj, np.empty((i1 - i0, j1 - j0)))
    if i0 == j0:
        np.fill_diagonal(D, np.inf)
    arg = _first_near_min(D, T, axis=1)
    r = np.arange(i1 - i0)
    rows = (D[r, arg], T[r, arg], arg + j0)
    cols = None
    if j0 != i0:
        arg = _first_near_min(D, T, axis=0)
        c = np.arange(j1 - j0)
        cols = (D[arg, c], T[arg, c], arg + i0)
    return rows, cols


def _loo_nearest(P, block=None, n_threads=1):
    """Leave-one-out nearest neighbor of every row of ``P`` among the others.

    Uses the symmetry of the distance: only blocks on or above the block
    diagonal are computed, each serving both its rows and its columns, so
    the cost is half that of the full matrix. Near-ties (within rounding)
    go to the lowest index. Blocks are computed by :func:`_map_blocks`
    (call it inside :class:`_blas_limits`) and merged in a fixed order, so
    the result depends neither on the thread count nor on the backend.

    Returns ``(indices, distances)``, each of shape (n_samples,).
    """
    n = P.H.shape[0]
    b = min(block or _LOO_BLOCK, n)
    best_d = np.full(n, np.inf)
    best_t = np.zeros(n)
    best_i = np.full(n, n, dtype=np.intp)

    def merge(rows, cand_d, cand_t, cand_i):
        cur_d, cur_t, cur_i = best_d[rows], best_t[rows], best_i[rows]
        tol = np.maximum(cand_t, cur_t)
        better = (cand_d < cur_d - tol) | ((cand_d <= cur_d + tol) & (cand_i < cur_i))
        best_d[rows] = np.where(better, cand_d, cur_d)
        best_t[rows] = np.where(better, cand_t, cur_t)
        best_i[rows] = np.where(better, cand_i, cur_i)

    blocks = [(i0, min(i0 + b, n), j0, min(j0 + b, n)) for i0 in range(0, n, b) for j0 in range(i0, n, b)]
    args = [(*blk, *P) for blk in blocks]
    for (i0, i1, j0, j1), (rows, cols) in zip(blocks, _map_blocks(_loo_block_task, args, n_threads)):
        merge(slice(i0, i1), *rows)
        if cols is not None:
            merge(slice(j0, j1), *cols)
    return best_i, best_d


class NeighbourVotesMixin:
    """``predict_proba`` and ``predict`` from the votes of ``kneighbors``.

    For the symmetric-KL neighbor classifiers of this package: they set
    ``classes_``, ``weights`` and ``_y`` (training labels as indices into
    ``classes_``) in ``fit`` and implement ``kneighbors``.
    """

    def predict_proba(self, X):
        """Class probabilities from the votes of the nearest neighbors.

        Parameters
        ----------
        X : array-like of shape (n_queries, n_bins)
            Query histograms.

        Returns
        -------
        proba : ndarray of shape (n_queries, n_classes)
            Share of the (weighted) votes per class, columns ordered as
            ``classes_``.
        """
        check_is_fitted(self)
        dist, ind = self.kneighbors(X)
        return neighbour_votes(dist, ind, self._y, self.classes_.size, self.weights)

    def predict(self, X):
        """Predict the class of each query histogram.

        Parameters
        ----------
        X : array-like of shape (n_queries, n_bins)
            Query histograms.

        Returns
        -------
        y_pred : ndarray of shape (n_queries,)
            Predicted labels; a tie between classes goes to the first of them
            in ``classes_``.
        """
        check_is_fitted(self)
        proba = self.predict_proba(X)
        return self.classes_[np.argmax(proba, axis=1)]


class KLNearestNeighbors(NeighbourVotesMixin, ClassifierMixin, BaseEstimator):
    """Nearest-neighbor classifier on histograms with symmetric KL divergence.

    The paper's retrieval matcher: descriptors are compared with the
    symmetric Kullback-Leibler divergence after raising empty bins to a
    common floor; with ``n_neighbors=1`` a query takes the label of its
    closest training descriptor.

    Parameters
    ----------
    n_neighbors : int, default=1
        Number of neighbors used by :meth:`predict` and
        :meth:`predict_proba`.
    weights : {"uniform", "distance"}, default="uniform"
        ``"uniform"``: every neighbor votes equally. ``"distance"``: votes
        are weighted by the inverse distance; neighbors at distance zero,
        when there are any, take all the weight.
    floor : "auto" or float, default="auto"
        Bins below ``floor`` (in particular empty bins) are raised to it
        before taking logarithms, in training and query histograms alike.
        ``"auto"`` learns half the smallest positive value of the training
        ``X`` in :meth:`fit` (the paper's choice).
    renormalize : bool, default=False
        Whether floored histograms are divided by their sum (the paper does
        not say; by default they are not).
    chunk_size : int, default=None
        Query rows handled per block; memory beyond the training data is two
        blocks of ``chunk_size * n_samples_fit`` floats. ``None`` picks blocks
        of about 64 MiB. Neighbors do not depend on it (near-ties within
        rounding go to the lowest index); distances only in the last bits.
    n_jobs : int, default=None
        Threads over blocks of distances (joblib's meaning; ``None``
        is the OpenMP default, see :func:`eppf.utils.check_n_jobs`). Each
        block's matrix products run on one BLAS thread, so the result is
        bit-identical for any value. Inside ``joblib.parallel_config``
        (or ``parallel_backend``) naming a backend, e.g. ``"dask"`` with a
        ``dask.distributed`` client, the same fixed blocks are that
        backend's tasks instead, with bit-identical results.

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        Class labels seen in :meth:`fit`.
    floor_ : float
        The floor used for all histograms.
    n_features_in_ : int
        Number of bins seen in :meth:`fit`.
    feature_names_in_ : ndarray of shape (`n_features_in_`,)
        Names of features seen in :meth:`fit`, when ``X`` has string column
        names.
    n_samples_fit_ : int
        Number of training histograms.

    See Also
    --------
    symmetric_kl_distances : The distance used here.
    eppf.metrics.leave_one_out_retrieval : The paper's retrieval protocol.

    Notes
    -----
    The distance between histograms ``a`` and ``b`` (after flooring) is

    .. math:: d(a, b) = \\sum_i (a_i - b_i) \\ln \\frac{a_i}{b_i}.

    It is computed as two matrix products per block of query rows. Equal
    distances, and distances closer than the rounding error of that
    computation (about ``1e-12`` relative to the summed terms), are resolved
    in favor of the training sample with the lowest index, so exact
    duplicates in the training set give the same answer whatever the
    chunking. Equal votes go to the first class in ``classes_``.
    :meth:`kneighbors` without ``X`` excludes each training point from its
    own neighbors, which gives leave-one-out retrieval.

    The divergence compares distributions: histograms of raw counts with
    different totals (e.g. OUR-CVFH over clouds of different sizes) should be
    L1-normalized first, e.g. with
    ``sklearn.preprocessing.Normalizer(norm="l1")`` in a pipeline. EPPF
    descriptors already are. Flooring adds a little mass to sparse
    histograms; ``renormalize=True`` removes it again.

    References
    ----------
    .. [1] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import KLNearestNeighbors
    >>> X = np.array([[0.7, 0.3, 0.0], [0.6, 0.4, 0.0], [0.0, 0.2, 0.8], [0.1, 0.1, 0.8]])
    >>> y = ["chair", "chair", "table", "table"]
    >>> clf = KLNearestNeighbors().fit(X, y)
    >>> clf.predict([[0.65, 0.35, 0.0], [0.0, 0.3, 0.7]])
    array(['chair', 'table'], dtype='<U5')
    >>> clf.kneighbors(return_distance=False).ravel()
    array([1, 0, 3, 2])
    """

    def __init__(self, n_neighbors=1, *, weights="uniform", floor="auto", renormalize=False, chunk_size=None, n_jobs=None):
        self.n_neighbors = n_neighbors
        self.weights = weights
        self.floor = floor
        self.renormalize = renormalize
        self.chunk_size = chunk_size
        self.n_jobs = n_jobs

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.positive_only = True
        return tags

    def _check_params(self):
        name = type(self).__name__
        k = self.n_neighbors
        if isinstance(k, bool) or not isinstance(k, numbers.Integral):
            raise TypeError(f"{name}: n_neighbors must be a positive int, got {type(k).__name__}")
        if k < 1:
            raise ValueError(f"{name}: n_neighbors must be a positive int, got {k}")
        if self.weights not in ("uniform", "distance"):
            raise ValueError(f"{name}: weights must be 'uniform' or 'distance', got {self.weights!r}")
        floor = _check_floor(self.floor, name)
        renormalize = _check_renormalize(self.renormalize, name)
        chunk_size = _check_chunk_size(self.chunk_size, name)
        if self.n_jobs is not None:
            from ..utils._validation import check_n_jobs

            check_n_jobs(self.n_jobs, owner=name)
        return floor, renormalize, chunk_size

    def fit(self, X, y):
        """Store the training histograms and learn the floor.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_bins)
            Non-negative training histograms.
        y : array-like of shape (n_samples,)
            Class labels (numbers or strings).

        Returns
        -------
        self : KLNearestNeighbors
            The fitted classifier.
        """
        name = type(self).__name__
        floor, renormalize, _ = self._check_params()
        X, y = _named(name, validate_data, self, X, y, dtype=np.float64, ensure_all_finite=True)
        _named(name, check_classification_targets, y)
        _check_non_negative(X, name)
        self.floor_ = _learn_floor([X], name) if floor == "auto" else floor
        self.classes_, self._y = np.unique(y, return_inverse=True)
        self._renormalize = renormalize
        self._fit_data = _prepare(X, self.floor_, renormalize, name)
        self.n_samples_fit_ = X.shape[0]
        return self

    def _query(self, X):
        check_is_fitted(self)
        X = _named(type(self).__name__, validate_data, self, X, dtype=np.float64, ensure_all_finite=True, reset=False)
        _check_non_negative(X, type(self).__name__)
        return _prepare(X, self.floor_, self._renormalize, type(self).__name__)

    def kneighbors(self, X=None, n_neighbors=None, return_distance=True):
        """Find the nearest training histograms of each query.

        Parameters
        ----------
        X : array-like of shape (n_queries, n_bins), default=None
            Query histograms. ``None`` queries the training histograms, each
            one excluded from its own neighbors (leave-one-out).
        n_neighbors : int, default=None
            Number of neighbors; ``None`` uses the ``n_neighbors`` parameter.
        return_distance : bool, default=True
            Whether to return the distances too.

        Returns
        -------
        neigh_dist : ndarray of shape (n_queries, n_neighbors)
            Symmetric KL distances to the neighbors, increasing along each
            row. Only returned if ``return_distance=True``.
        neigh_ind : ndarray of shape (n_queries, n_neighbors)
            Indices of the neighbors in the training set.
        """
        check_is_fitted(self)
        name = type(self).__name__
        _, _, chunk_size = self._check_params()
        k = self.n_neighbors if n_neighbors is None else n_neighbors
        if isinstance(k, bool) or not isinstance(k, numbers.Integral):
            raise TypeError(f"{name}: n_neighbors must be a positive int, got {type(k).__name__}")
        if k < 1:
            raise ValueError(f"{name}: n_neighbors must be a positive int, got {k}")
        loo = X is None
        if loo:
            P = self._fit_data
        else:
            P = self._query(X)
        available = self.n_samples_fit_ - (1 if loo else 0)
        if k > available:
            extra = " excluding each query itself" if loo else ""
            raise ValueError(
                f"{name}: n_neighbors={k} is more than the {available} training sample(s) available{extra}"
            )
        n_q = P.H.shape[0]
        ind = np.empty((n_q, k), dtype=np.intp)
        dist = np.empty((n_q, k)) if return_distance else None
        with _blas_limits(self.n_jobs, name) as n_threads:
            for start, idx, d in _iter_kneighbors(P, self._fit_data, chunk_size, k, loo, n_threads):
                ind[start : start + idx.shape[0]] = idx
                if return_distance:
                    dist[start : start + idx.shape[0]] = d
        return (dist, ind) if return_distance else ind


# ------------------------------------------------------------------------
# Shared with the approximate search (eppf.neighbors._ann): public names of
# this private module, not part of the package's API.


def single_blas_thread():
    """Context manager: every BLAS call of this process on one thread while inside.

    Reference-counted across threads (see ``_one_blas_thread``), so that
    the matrix products of blocks running concurrently are all
    single-threaded and round the same way as when they run alone.

    Returns
    -------
    context : context manager
        The single-thread BLAS context.
    """
    return _one_blas_thread()


def check_kl_params(est):
    """Validate an estimator's ``n_neighbors``, ``weights``, ``floor``, ``renormalize``, ``chunk_size``, ``n_jobs``.

    Parameters
    ----------
    est : estimator
        An estimator with those parameters.

    Returns
    -------
    floor : "auto" or float
        The checked floor.
    renormalize : bool
        The checked flag.
    chunk_size : int or None
        The checked block size.
    """
    name = type(est).__name__
    check_n_neighbors(est.n_neighbors, name)
    if est.weights not in ("uniform", "distance"):
        raise ValueError(f"{name}: weights must be 'uniform' or 'distance', got {est.weights!r}")
    floor = _check_floor(est.floor, name)
    renormalize = _check_renormalize(est.renormalize, name)
    chunk_size = _check_chunk_size(est.chunk_size, name)
    if est.n_jobs is not None:
        from ..utils._validation import check_n_jobs

        check_n_jobs(est.n_jobs, owner=name)
    return floor, renormalize, chunk_size


def check_n_neighbors(k, owner):
    """Raise unless ``k`` is a positive int (not a bool); return it as an int.

    Parameters
    ----------
    k : object
        The value to check.
    owner : str
        Name used in the error message.

    Returns
    -------
    k : int
        The checked value.
    """
    if isinstance(k, bool) or not isinstance(k, numbers.Integral):
        raise TypeError(f"{owner}: n_neighbors must be a positive int, got {type(k).__name__}")
    if k < 1:
        raise ValueError(f"{owner}: n_neighbors must be a positive int, got {k}")
    return int(k)


def validate_histograms(est, X, y="no_validation", *, reset, dtype=np.float64):
    """Validate training or query histograms of a KL estimator (finite, non-negative).

    Parameters
    ----------
    est : estimator
        The estimator (``n_features_in_`` is set or checked, errors name it).
    X : array-like of shape (n_samples, n_bins)
        Histograms.
    y : array-like of shape (n_samples,) or None, default="no_validation"
        Class labels, checked to be classification targets (``None`` is an
        error, as for scikit-learn's ``validate_data``); the default checks
        ``X`` only.
    reset : bool
        Whether this is :meth:`fit` (set ``n_features_in_``).
    dtype : dtype or list of dtypes, default=np.float64
        Accepted dtype(s), as in :func:`sklearn.utils.check_array`.

    Returns
    -------
    X : ndarray of shape (n_samples, n_bins)
        The validated histograms.
    y : ndarray of shape (n_samples,)
        The validated labels, only returned when ``y`` is passed.
    """
    name = type(est).__name__
    no_y = isinstance(y, str) and y == "no_validation"
    if no_y:
        X = _named(name, validate_data, est, X, dtype=dtype, ensure_all_finite=True, reset=reset)
    else:
        X, y = _named(name, validate_data, est, X, y, dtype=dtype, ensure_all_finite=True, reset=reset)
        _named(name, check_classification_targets, y)
    for start in range(0, X.shape[0], max(1, _BLOCK_ENTRIES // max(1, X.shape[1]))):
        _check_non_negative(X[start : start + _BLOCK_ENTRIES // max(1, X.shape[1])], name)
    return X if no_y else (X, y)


def learn_floor(X, owner):
    """Half the smallest positive value of ``X`` (read in blocks, so no full-size temporary).

    Parameters
    ----------
    X : ndarray of shape (n_samples, n_bins)
        Non-negative histograms.
    owner : str
        Name used in the error message.

    Returns
    -------
    floor : float
        The floor of ``floor="auto"``.
    """
    step = max(1, _BLOCK_ENTRIES // max(1, X.shape[1]))
    return _learn_floor([X[i : i + step] for i in range(0, X.shape[0], step)], owner)


def prepare_histograms(X, floor, renormalize, owner):
    """Floored histograms, their logarithms and row terms, as used by every distance here.

    Parameters
    ----------
    X : ndarray of shape (n_samples, n_bins)
        Non-negative histograms (float32 or float64; computed in float64).
    floor : float
        Positive floor.
    renormalize : bool
        Whether floored rows are divided by their sum.
    owner : str
        Name used in error messages.

    Returns
    -------
    prepared : namedtuple
        Fields ``H, L, s, mass, lam`` (see ``_Prepared``).
    """
    return _prepare(X, floor, renormalize, owner)


def rerank_candidates(P, database, candidates, k, floor, renormalize, owner):
    """Exact symmetric KL re-ranking of candidate neighbors.

    Parameters
    ----------
    P : namedtuple
        Prepared queries (:func:`prepare_histograms`), ``n_queries`` rows.
    database : ndarray of shape (n_database, n_bins)
        Raw database histograms (any float dtype; rows are floored, optionally
        renormalised and taken to float64 exactly as :func:`prepare_histograms` does).
    candidates : ndarray of shape (n_queries, n_candidates)
        Candidate database indices per query; ``-1`` marks no candidate.
        Each row must hold at least ``k`` valid, distinct indices.
    k : int
        Neighbors kept per query.
    floor : float
        Positive floor.
    renormalize : bool
        Whether floored rows are divided by their sum.
    owner : str
        Name used in error messages.

    Returns
    -------
    neigh_dist : ndarray of shape (n_queries, k)
        Symmetric KL distances, increasing along each row.
    neigh_ind : ndarray of shape (n_queries, k)
        Database indices. Among candidates, near-ties (within the rounding
        bound of the distance) go to the lowest index, as in
        :class:`KLNearestNeighbors`.
    """
    n_q, m = candidates.shape
    order = np.argsort(np.where(candidates < 0, np.iinfo(np.intp).max, candidates), axis=1, kind="stable")
    cand = np.take_along_axis(candidates, order, axis=1).astype(np.intp)
    valid = cand >= 0
    C = _prepare(database[np.where(valid, cand, 0).ravel()], floor, renormalize, owner)
    n_bins = C.H.shape[1]
    Hc = C.H.reshape(n_q, m, n_bins)
    Lc = C.L.reshape(n_q, m, n_bins)
    # d = s_q + s_c - (h_q . ln h_c + ln h_q . h_c), in _kl_block's order
    D = np.matmul(Lc, P.H[:, :, None])[:, :, 0]
    D += np.matmul(Hc, P.L[:, :, None])[:, :, 0]
    np.subtract(P.s[:, None], D, out=D)
    D += C.s.reshape(n_q, m)
    np.maximum(D, 0.0, out=D)
    rel = 4.0 * max(n_bins, 16) * np.finfo(np.float64).eps
    T = (P.mass[:, None] * C.lam.reshape(n_q, m) + P.lam[:, None] * C.mass.reshape(n_q, m)
         + np.abs(P.s)[:, None] + np.abs(C.s.reshape(n_q, m))) * rel
    D[~valid] = np.inf
    T[~valid] = 0.0
    pick = _smallest_k(D, T, k)
    return np.take_along_axis(D, pick, axis=1), np.take_along_axis(cand, pick, axis=1)


def neighbour_votes(dist, ind, labels, n_classes, weights):
    """Class probabilities from the (weighted) votes of neighbors.

    Parameters
    ----------
    dist : ndarray of shape (n_queries, k)
        Distances to the neighbors.
    ind : ndarray of shape (n_queries, k)
        Indices of the neighbors in the training set.
    labels : ndarray of shape (n_samples_fit,)
        Encoded training labels (indices into ``classes_``).
    n_classes : int
        Number of classes.
    weights : {"uniform", "distance"}
        Voting rule: equal votes, or inverse-distance votes where neighbors
        at distance zero, when there are any, take all the weight.

    Returns
    -------
    proba : ndarray of shape (n_queries, n_classes)
        Share of the votes per class.
    """
    if weights == "uniform":
        w = np.ones_like(dist)
    else:
        zero = dist == 0
        with np.errstate(divide="ignore"):
            w = 1.0 / dist
        rows = zero.any(axis=1)
        w[rows] = zero[rows].astype(np.float64)
    proba = np.zeros((ind.shape[0], n_classes))
    np.add.at(proba, (np.arange(ind.shape[0])[:, None], labels[ind]), w)
    proba /= proba.sum(axis=1, keepdims=True)
    return proba


def rerank_sparse_candidates(P, support, row_terms, candidates, k, floor):
    """Exact symmetric KL re-ranking of candidates stored as sparse supports.

    For histograms floored at ``f`` (not renormalised), every bin at or
    below ``f`` in both histograms contributes nothing, so the divergence
    between a query ``q`` and a candidate ``c`` is a sum over the support of
    ``c`` (its bins above ``f``) plus one term per query:

    .. math:: d(q, c) = A_q + \\sum_{i \\in S_c} \\left[(q_i - c_i)(\\ln q_i - \\ln c_i)
              - (q_i - f)(\\ln q_i - \\ln f)\\right],
              \\quad A_q = \\sum_i (q_i - f)(\\ln q_i - \\ln f),

    with ``q`` floored. Only the candidates' non-empty bins are read, so a
    database of sparse histograms (EPPF descriptors fill a few percent of
    their bins) is kept in compressed rows and re-ranked in a small
    fraction of the time of the dense formula.

    Parameters
    ----------
    P : namedtuple
        Prepared queries (:func:`prepare_histograms` with
        ``renormalize=False``).
    support : tuple of ndarray
        ``(indptr, indices, values)``: compressed rows of the database
        holding its bins above ``floor`` (values in any float dtype).
    row_terms : tuple of ndarray
        ``(s, mass, lam)`` of the database rows, as in
        :func:`prepare_histograms`; they set the tie tolerance.
    candidates : ndarray of shape (n_queries, n_candidates)
        Candidate database indices per query; ``-1`` marks no candidate.
    k : int
        Neighbors kept per query.
    floor : float
        Positive floor.

    Returns
    -------
    neigh_dist : ndarray of shape (n_queries, k)
        Symmetric KL distances, increasing along each row.
    neigh_ind : ndarray of shape (n_queries, k)
        Database indices; near-ties go to the lowest index.
    """
    indptr, indices, values = support
    row_s, row_mass, row_lam = row_terms
    n_q, m = candidates.shape
    order = np.argsort(np.where(candidates < 0, np.iinfo(np.intp).max, candidates), axis=1, kind="stable")
    cand = np.take_along_axis(candidates, order, axis=1).astype(np.intp)
    valid = cand >= 0
    c = np.where(valid, cand, 0).ravel()
    lo = indptr[c]
    lens = np.where(valid.ravel(), indptr[c + 1] - lo, 0)
    pair = np.repeat(np.arange(n_q * m), lens)
    pos = np.arange(pair.size) - np.repeat(np.cumsum(lens) - lens, lens) + np.repeat(lo, lens)
    bins = indices[pos]
    cv = values[pos].astype(np.float64)
    qrow = pair // m
    hq, lq = P.H[qrow, bins], P.L[qrow, bins]
    ln_f = np.log(floor)
    term = (hq - cv) * (lq - np.log(cv))
    term -= (hq - floor) * (lq - ln_f)
    A = np.einsum("ij,ij->i", P.H - floor, P.L - ln_f)
    D = np.bincount(pair, weights=term, minlength=n_q * m).reshape(n_q, m)
    D += A[:, None]
    np.maximum(D, 0.0, out=D)
    rel = 4.0 * max(P.H.shape[1], 16) * np.finfo(np.float64).eps
    T = (P.mass[:, None] * row_lam[cand] + P.lam[:, None] * row_mass[cand]
         + np.abs(P.s)[:, None] + np.abs(row_s[cand])) * rel
    D[~valid] = np.inf
    T[~valid] = 0.0
    pick = _smallest_k(D, T, k)
    return np.take_along_axis(D, pick, axis=1), np.take_along_axis(cand, pick, axis=1)
