"""Matching of histogram descriptors by symmetric Kullback-Leibler divergence.

The symmetric KL divergence of two histograms ``a`` and ``b`` is

    d(a, b) = sum_i (a_i - b_i) (ln a_i - ln b_i)
            = sum_i a_i ln a_i + sum_i b_i ln b_i - a . ln(b) - b . ln(a).

The two cross terms are matrix products, so the distances between every row
of a query block and every row of a reference set cost two GEMMs. Rows are
processed in chunks so that no more than a chunk of the distance matrix
(plus the floored histograms and their logarithms) is held at once.
"""

import numpy as np
from sklearn.utils.validation import check_is_fitted

from ..utils._blas import blas_limits, map_blocks
from ._base import (
    BLOCK_ENTRIES,
    KL_CONSTRAINTS,
    KLNeighborsBase,
    Prepared,
    check_distance_params,
    first_near_min,
    learn_floor,
    prepare_histograms,
    relative_rounding,
    smallest_k,
    validate_histogram_array,
    validate_histograms,
)

__all__ = ["KLNearestNeighbors", "loo_nearest", "symmetric_kl_distances"]

# Side of the square blocks used by the leave-one-out search.
_LOO_BLOCK = 1024
# Pickles of fitted estimators made before the shared code moved to ._base name it here.
_Prepared = Prepared


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
    last place (:func:`~eppf.neighbors._base.relative_rounding`). Distances
    closer than this are treated as ties.
    """
    rel = relative_rounding(P.H.shape[1])
    np.multiply(P.mass[:, None], Q.lam[None, :], out=out)
    out += P.lam[:, None] * Q.mass[None, :]
    out += np.abs(P.s)[:, None]
    out += np.abs(Q.s)[None, :]
    out *= rel
    return out


def _auto_chunk(n_ref):
    return max(1, BLOCK_ENTRIES // max(1, n_ref))


def _row_bounds(n_p, n_q, chunk_size):
    """Fixed ``(start, stop)`` row blocks of P: they depend on ``chunk_size`` and the shapes only."""
    step = chunk_size if chunk_size is not None else _auto_chunk(n_q)
    step = min(step, max(n_p, 1))
    return [(start, min(start + step, n_p)) for start in range(0, n_p, step)]


_N_FIELDS = len(Prepared._fields)


def _distance_task(start, stop, with_tolerance, *arrays):
    """Distances (and tie tolerances) of rows ``start:stop`` of P to all of Q.

    ``arrays`` are the fields of P followed by those of Q (see :func:`~eppf.utils._blas.map_blocks`).
    """
    P, Q = Prepared(*arrays[:_N_FIELDS]), Prepared(*arrays[_N_FIELDS:])
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
    idx = smallest_k(D, T, k)
    return idx, np.take_along_axis(D, idx, axis=1)


def _iter_kl_chunks(P, Q, chunk_size, with_tolerance=False, n_threads=1):
    """Yield ``(start, D, T)``: distances of rows ``start:start+len(D)`` of P to all of Q.

    ``T`` holds the tie tolerance of each entry (None unless asked for).
    Blocks are computed by :func:`~eppf.utils._blas.map_blocks` (call it
    inside :class:`~eppf.utils._blas.blas_limits`) and yielded in row order;
    their shapes depend on ``chunk_size`` and the data only.
    """
    bounds = _row_bounds(P.H.shape[0], Q.H.shape[0], chunk_size)
    args = [(start, stop, with_tolerance, *P, *Q) for start, stop in bounds]
    for (start, _), (D, T) in zip(bounds, map_blocks(_distance_task, args, n_threads)):
        yield start, D, T


def _iter_kneighbors(P, Q, chunk_size, k, loo, n_threads=1):
    """Yield ``(start, indices, distances)`` of the ``k`` nearest rows of Q, block by block of P."""
    bounds = _row_bounds(P.H.shape[0], Q.H.shape[0], chunk_size)
    args = [(start, stop, k, loo, *P, *Q) for start, stop in bounds]
    for (start, _), (idx, dist) in zip(bounds, map_blocks(_kneighbors_task, args, n_threads)):
        yield start, idx, dist


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
    normalized histograms of 1,200 bins, however small ``d`` is. The
    distances are bit-identical for any ``n_jobs`` on one machine; BLAS and
    NumPy choose their code by CPU, so between machines they agree within
    that accuracy (class (b) of the documentation's Reproducibility page).

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
    floor, renormalize, chunk_size = check_distance_params(
        owner, floor=floor, renormalize=renormalize, chunk_size=chunk_size, n_jobs=n_jobs
    )
    X = validate_histogram_array(X, owner, "X")
    same = Y is None
    if not same:
        Y = validate_histogram_array(Y, owner, "Y")
        if Y.shape[1] != X.shape[1]:
            raise ValueError(
                f"{owner}: X and Y must have the same number of bins, got {X.shape[1]} and {Y.shape[1]}"
            )
    if floor == "auto":
        floor = learn_floor([X] if same else [X, Y], owner)
    PX = prepare_histograms(X, floor, renormalize, owner)
    PY = PX if same else prepare_histograms(Y, floor, renormalize, owner)
    D = np.empty((X.shape[0], PY.H.shape[0]))
    with blas_limits(n_jobs, owner) as n_threads:
        for start, block, _ in _iter_kl_chunks(PX, PY, chunk_size, n_threads=n_threads):
            D[start : start + block.shape[0]] = block
    if same:
        np.fill_diagonal(D, 0.0)
    return D


def _loo_block_task(i0, i1, j0, j1, *arrays):
    """Each row's and each column's nearest candidate in block (i0:i1, j0:j1) of P against itself."""
    P = Prepared(*arrays)
    Pi, Pj = P.rows(i0, i1), P.rows(j0, j1)
    D = _kl_block(Pi, Pj, np.empty((i1 - i0, j1 - j0)), np.empty((i1 - i0, j1 - j0)))
    T = _tie_tolerance(Pi, Pj, np.empty((i1 - i0, j1 - j0)))
    if i0 == j0:
        np.fill_diagonal(D, np.inf)
    arg = first_near_min(D, T, axis=1)
    r = np.arange(i1 - i0)
    rows = (D[r, arg], T[r, arg], arg + j0)
    cols = None
    if j0 != i0:
        arg = first_near_min(D, T, axis=0)
        c = np.arange(j1 - j0)
        cols = (D[arg, c], T[arg, c], arg + i0)
    return rows, cols


def loo_nearest(P, block=None, n_threads=1):
    """Leave-one-out nearest neighbor of every row of ``P`` among the others.

    Uses the symmetry of the distance: only blocks on or above the block
    diagonal are computed, each serving both its rows and its columns, so
    the cost is half that of the full matrix. Near-ties (within rounding)
    go to the lowest index. Blocks are computed by
    :func:`~eppf.utils._blas.map_blocks` (call it inside
    :class:`~eppf.utils._blas.blas_limits`) and merged in a fixed order, so
    the result depends neither on the thread count nor on the backend.

    Parameters
    ----------
    P : Prepared
        The prepared histograms.
    block : int, default=None
        Side of the square blocks; ``None`` means 1024.
    n_threads : int, default=1
        Threads over blocks.

    Returns
    -------
    indices : ndarray of shape (n_samples,)
        Each row's nearest other row.
    distances : ndarray of shape (n_samples,)
        The distance to it.
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
    for (i0, i1, j0, j1), (rows, cols) in zip(blocks, map_blocks(_loo_block_task, args, n_threads)):
        merge(slice(i0, i1), *rows)
        if cols is not None:
            merge(slice(j0, j1), *cols)
    return best_i, best_d


class KLNearestNeighbors(KLNeighborsBase):
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

    _parameter_constraints = dict(KL_CONSTRAINTS)

    def __init__(self, n_neighbors=1, *, weights="uniform", floor="auto", renormalize=False, chunk_size=None, n_jobs=None):
        self.n_neighbors = n_neighbors
        self.weights = weights
        self.floor = floor
        self.renormalize = renormalize
        self.chunk_size = chunk_size
        self.n_jobs = n_jobs

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
        X, y = validate_histograms(self, X, y, reset=True)
        self.floor_ = learn_floor([X], name) if floor == "auto" else floor
        self.classes_, self._y = np.unique(y, return_inverse=True)
        self._renormalize = renormalize
        self._fit_data = prepare_histograms(X, self.floor_, renormalize, name)
        self.n_samples_fit_ = X.shape[0]
        return self

    def _query(self, X):
        check_is_fitted(self)
        X = validate_histograms(self, X, reset=False)
        return prepare_histograms(X, self.floor_, self._renormalize, type(self).__name__)

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
        loo = X is None
        k = self._check_k(n_neighbors, loo)
        P = self._fit_data if loo else self._query(X)
        n_q = P.H.shape[0]
        ind = np.empty((n_q, k), dtype=np.intp)
        dist = np.empty((n_q, k)) if return_distance else None
        with blas_limits(self.n_jobs, name) as n_threads:
            for start, idx, d in _iter_kneighbors(P, self._fit_data, chunk_size, k, loo, n_threads):
                ind[start : start + idx.shape[0]] = idx
                if return_distance:
                    dist[start : start + idx.shape[0]] = d
        return (dist, ind) if return_distance else ind
