"""Approximate symmetric-KL retrieval for large descriptor sets.

Candidates come from an inverted-file index (faiss ``IndexIVFFlat``) over an
embedding in which Euclidean distance approximates the symmetric KL
divergence; every candidate is then re-ranked by the exact divergence.

The embedding is the square-root (Hellinger) map of the floored histograms,
each divided by its sum: ``e(x) = sqrt(h / sum h)`` with ``h = max(x,
floor)``. For nearby distributions ``p`` and ``q`` the symmetric KL
divergence and four times the squared Hellinger distance,
``4 * sum (sqrt p_i - sqrt q_i)**2``, agree to second order (both are
``sum (p_i - q_i)**2 / p_i`` up to third-order terms), so near neighbors in
one are near neighbors in the other. The embedded vectors are optionally
projected onto their leading principal components to make the index
smaller and its scans faster.
"""

import numbers

import numpy as np
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from ..utils._blas import single_blas_thread
from ..utils._param_validation import RANDOM_STATE, Interval, StrOptions
from ..utils._stream import ordered_map
from ..utils._validation import check_n_jobs
from ._base import KL_CONSTRAINTS, KLNeighborsBase, check_mass, learn_floor, prepare_histograms, validate_histograms
from ._rerank import rerank_candidates, rerank_sparse_candidates

__all__ = ["ApproximateKLNearestNeighbors"]

# Entries (query rows x candidates x bins) of one re-ranking block: bounds the
# float64 temporaries of a block to a few times 64 MiB.
_RERANK_ENTRIES = 1 << 23
# Rows embedded at a time while building the index.
_EMBED_ROWS = 8192
# Rows used to fit the principal components.
_PCA_ROWS = 10000
# Training rows per inverted list for k-means.
_TRAIN_PER_LIST = 64
# Candidate-list size while inserting into an HNSW graph.
_EF_CONSTRUCTION = 64
# Fewest training rows per inverted list that "auto" allows.
_MIN_PER_LIST = 39

_HOW_TO_INSTALL = "pip install faiss-cpu  (or: pip install eppf[ann])"
# Largest float32 row sum the float32 embedding takes; rows above it are normalized in float64 first.
_F32_SUM_MAX = float(np.finfo(np.float32).max) / 2
# Smallest float32 row sum it takes (float32's smallest normal number); rows below it are normalized in float64 first.
_F32_SUM_MIN = float(np.finfo(np.float32).tiny)


def _import_faiss(owner):
    try:
        import faiss
    except ImportError as exc:
        raise ImportError(
            f"{owner} needs the faiss library for its candidate index, which is not installed; "
            f"install it with: {_HOW_TO_INSTALL}"
        ) from exc
    return faiss


class _faiss_threads:
    """Context: faiss (and its OpenMP BLAS) on ``n`` threads in the calling thread."""

    def __init__(self, faiss, n):
        self.faiss, self.n = faiss, n

    def __enter__(self):
        self.old = self.faiss.omp_get_max_threads()
        self.faiss.omp_set_num_threads(self.n)

    def __exit__(self, *exc):
        self.faiss.omp_set_num_threads(self.old)


def _drop_own(cand, start):
    """Remove from row ``r`` of ``cand`` the query's own index ``start + r`` (or, when absent, the last entry)."""
    n_q, m = cand.shape
    is_own = cand == np.arange(start, start + n_q)[:, None]
    drop = np.where(is_own.any(axis=1), np.argmax(is_own, axis=1), m - 1)
    keep = np.ones(cand.shape, dtype=bool)
    keep[np.arange(n_q), drop] = False
    return cand[keep].reshape(n_q, m - 1)


class ApproximateKLNearestNeighbors(KLNeighborsBase):
    """Approximate nearest neighbors by symmetric KL divergence, for millions of histograms.

    A fast index proposes ``n_candidates`` neighbors per query in the
    Hellinger embedding of the histograms (square roots of the floored,
    normalized bins, optionally reduced by PCA), searched by faiss's
    inverted-file index; the candidates are then ranked by the exact
    symmetric KL divergence of :class:`KLNearestNeighbors`, so every
    returned distance is exact and only a neighbor missed by the index
    can make a result differ from exact search.

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
        Bins below ``floor`` are raised to it before taking logarithms (and
        square roots), as in :class:`KLNearestNeighbors`; ``"auto"`` learns
        half the smallest positive value of the training ``X``.
    renormalize : bool, default=False
        Whether floored histograms are divided by their sum in the exact
        divergence (the embedding always normalizes).
    n_candidates : int, default=32
        Candidates proposed by the index and re-ranked exactly per query;
        at least ``n_neighbors``. More candidates: higher recall, slower
        queries.
    n_components : int or None, default=32
        Dimension of the PCA-reduced embedding in the index; ``None``, or a
        value not below the number of bins, keeps all bins (no PCA).
    index : {"ivf", "hnsw"}, default="ivf"
        The candidate index. ``"ivf"``: faiss's ``IndexIVFFlat``, k-means
        cells of which a query scans the ``n_probe`` nearest; quick to build.
        ``"hnsw"``: faiss's ``IndexHNSWFlat``, a navigable small-world graph
        walked with ``ef_search`` entries; faster queries at equal recall on
        large databases, but much slower to build (one thread, so that the
        graph is the same on every run).
    n_lists : int or "auto", default="auto"
        Inverted lists (k-means cells) of the index. ``"auto"`` uses about
        ``4 * sqrt(n_samples)`` (4,000 for a million), with at least 39
        training rows per list.
    n_probe : int, default=128
        Lists scanned per query (capped at ``n_lists``; ``"ivf"`` only).
        More lists: higher recall, slower queries (recall and speed on a
        million EPPF-like descriptors: the documentation's Performance page,
        "Approximate retrieval").
    hnsw_m : int, default=16
        Links per node of the HNSW graph (``"hnsw"`` only).
    ef_search : int, default=64
        Size of the HNSW search's candidate list (``"hnsw"`` only; at least
        ``n_candidates`` is used). Larger: higher recall, slower queries.
    chunk_size : int, default=None
        Queries handled per block; ``None`` picks blocks whose re-ranking
        temporaries are about 64 MiB each.
    random_state : int, RandomState instance or None, default=None
        Seeds the rows sampled to fit the PCA and the k-means, and the
        k-means itself. With a fixed value the index, and every result,
        are the same on every run and for any ``n_jobs``.
    n_jobs : int, default=None
        Threads over blocks of queries (joblib's meaning; ``None`` is the
        OpenMP default, see :func:`eppf.utils.check_n_jobs`). Each block
        runs its faiss search and its matrix products on one thread, so
        results do not depend on it. Building the index is single-threaded.
        Queries always run in threads of this process, also under a joblib
        backend such as dask (the index is not sent to a cluster; the exact
        :class:`KLNearestNeighbors` is the one that spreads over one).

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
    mean_ : ndarray of shape (n_bins,)
        Mean embedded training vector (the PCA's center), or None without PCA.
    components_ : ndarray of shape (n_components, n_bins)
        Principal axes of the embedding, or None without PCA.
    n_lists_ : int or None
        Inverted lists of the index (None for ``"hnsw"``).
    index_ : faiss.IndexIVFFlat or faiss.IndexHNSWFlat
        The candidate index (serialized to bytes when pickled).

    See Also
    --------
    KLNearestNeighbors : Exact search with the same distance and tie rule.
    symmetric_kl_distances : The distance used for re-ranking.

    Notes
    -----
    Memory: re-ranking needs the candidates' exact bins, and only the bins
    above the floor matter (the others contribute nothing to the
    divergence), so those are kept, in compressed rows and in the dtype of
    ``X`` (float32 stays float32); the index holds ``n_samples *
    n_components`` float32 values plus one 64-bit id per row. One million
    EPPF descriptors (1,200 bins) in
    float32 take 4.8 GB as input; what is kept is their bins above the floor
    in compressed rows (about 0.4 GB for 4 % non-empty bins) and the index
    (about 0.14 GB with ``n_components=32``). With ``renormalize=True`` the
    dense ``X`` itself is kept, as given.

    The principal components are fitted on at most 10,000 training rows
    and the k-means on at most 64 rows per list, all drawn with
    ``random_state``. A query whose probed lists hold fewer than
    ``n_neighbors`` rows is searched again over all lists. Among
    candidates, distances equal up to rounding go to the lowest training
    index, as in :class:`KLNearestNeighbors`; with ``n_candidates`` and
    ``n_probe`` at their maxima the search is exhaustive and the results
    are those of :class:`KLNearestNeighbors`. :meth:`kneighbors` without
    ``X`` excludes each training row from its own neighbors.

    The default index, faiss's ``IndexIVFFlat`` (inverted file, vectors
    stored uncompressed), is deterministic and quick to build, exact within
    the lists it scans, and has one parameter (``n_probe``) trading speed
    for recall. ``index="hnsw"`` answers queries faster on large databases
    at the price of a long single-threaded build (for determinism: a graph
    built by several threads depends on their scheduling).

    References
    ----------
    .. [1] H. Jegou, M. Douze and C. Schmid, "Product Quantization for
       Nearest Neighbor Search", IEEE Transactions on Pattern Analysis and
       Machine Intelligence, 2011 (inverted-file search).
    .. [2] J. Johnson, M. Douze and H. Jegou, "Billion-scale similarity
       search with GPUs", IEEE Transactions on Big Data, 2019 (faiss).
    .. [3] Y. A. Malkov and D. A. Yashunin, "Efficient and Robust Approximate
       Nearest Neighbor Search Using Hierarchical Navigable Small World
       Graphs", IEEE Transactions on Pattern Analysis and Machine
       Intelligence, 2020 (HNSW).

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.neighbors import ApproximateKLNearestNeighbors
    >>> rng = np.random.default_rng(0)
    >>> X = rng.dirichlet(np.ones(30), size=500)
    >>> y = np.arange(500) % 4
    >>> ann = ApproximateKLNearestNeighbors(n_components=8, random_state=0).fit(X, y)
    >>> dist, ind = ann.kneighbors(X[:3] * 0.9 + 0.1 / 30, n_neighbors=2)
    >>> ind[:, 0]
    array([0, 1, 2])
    """

    _parameter_constraints = {
        **KL_CONSTRAINTS,
        "n_candidates": [Interval(numbers.Integral, 1, None, closed="left")],
        "n_components": [Interval(numbers.Integral, 1, None, closed="left"), None],
        "index": [StrOptions(["ivf", "hnsw"])],
        "n_lists": [Interval(numbers.Integral, 1, None, closed="left"), StrOptions(["auto"])],
        "n_probe": [Interval(numbers.Integral, 1, None, closed="left")],
        "hnsw_m": [Interval(numbers.Integral, 2, None, closed="left")],
        "ef_search": [Interval(numbers.Integral, 1, None, closed="left")],
        "random_state": RANDOM_STATE,
    }

    def __init__(self, n_neighbors=1, *, weights="uniform", floor="auto", renormalize=False, n_candidates=32,
                 n_components=32, index="ivf", n_lists="auto", n_probe=128, hnsw_m=16, ef_search=64,
                 chunk_size=None, random_state=None, n_jobs=None):
        self.n_neighbors = n_neighbors
        self.weights = weights
        self.floor = floor
        self.renormalize = renormalize
        self.n_candidates = n_candidates
        self.n_components = n_components
        self.index = index
        self.n_lists = n_lists
        self.n_probe = n_probe
        self.hnsw_m = hnsw_m
        self.ef_search = ef_search
        self.chunk_size = chunk_size
        self.random_state = random_state
        self.n_jobs = n_jobs

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.non_deterministic = self.random_state is None
        return tags

    # ------------------------------------------------------------ parameters

    def _check_params(self):
        floor, renormalize, chunk_size = super()._check_params()
        if self.n_candidates < self.n_neighbors:
            raise ValueError(
                f"{type(self).__name__}: n_candidates={self.n_candidates} must be at least "
                f"n_neighbors={self.n_neighbors}"
            )
        return floor, renormalize, chunk_size

    # ------------------------------------------------------------ embedding

    def _embed(self, rows):
        """float32 index vectors of raw histogram rows (float32 or float64), computed in float32.

        Rows whose values or sum lie beyond float32's range (checked
        histograms: their sums are finite in float64), or whose sum is below
        its smallest normal number (their bins round to 0 or lose their
        digits), are divided by their sum in float64 before the cast, so
        they embed as their rescaled copies do instead of as infinities and
        NaN.
        """
        with np.errstate(over="ignore"):  # values beyond float32 become inf here; their rows are redone below
            h = np.maximum(rows, np.float32(self.floor_), dtype=np.float32)
        sums = h.sum(axis=1, keepdims=True, dtype=np.float64)
        odd = ~((sums[:, 0] >= _F32_SUM_MIN) & (sums[:, 0] <= _F32_SUM_MAX))
        if odd.any():
            wide = np.maximum(rows[odd], self.floor_, dtype=np.float64)
            h[odd] = wide / wide.sum(axis=1, keepdims=True)
            sums[odd] = 1.0
        h /= sums.astype(np.float32)
        np.sqrt(h, out=h)
        if self.components_ is not None:
            h -= self.mean_.astype(np.float32)
            h = h @ self.components_.T.astype(np.float32)
        return np.ascontiguousarray(h, dtype=np.float32)

    # ------------------------------------------------------------ fit

    def fit(self, X, y):
        """Keep the training histograms and build the candidate index.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_bins)
            Non-negative training histograms. float32 arrays are kept as
            float32 (the divergence is still computed in float64).
        y : array-like of shape (n_samples,)
            Class labels (numbers or strings).

        Returns
        -------
        self : ApproximateKLNearestNeighbors
            The fitted classifier.
        """
        name = type(self).__name__
        floor, renormalize, _ = self._check_params()
        n_components, n_lists = self.n_components, self.n_lists
        faiss = _import_faiss(name)
        X, y = validate_histograms(self, X, y, reset=True, dtype=[np.float64, np.float32])
        n, n_bins = X.shape
        if n_components is not None and n_components >= n_bins:
            n_components = None
        if self.index == "hnsw":
            n_lists = None
        elif n_lists == "auto":
            n_lists = int(max(1, min(round(4 * np.sqrt(n)), n // _MIN_PER_LIST)))
        elif n_lists > n:
            raise ValueError(f"{name}: n_lists={n_lists} is more than the {n} training samples")
        self.floor_ = learn_floor([X], name) if floor == "auto" else floor
        self.classes_, self._y = np.unique(y, return_inverse=True)
        self._renormalize = renormalize
        self.n_samples_fit_ = n
        self._store(X)
        self.n_lists_ = n_lists

        rng = check_random_state(self.random_state)
        seed = int(rng.randint(np.iinfo(np.int32).max))
        n_train = min(n, _TRAIN_PER_LIST * n_lists) if n_lists else min(n, _PCA_ROWS)
        train = np.sort(rng.permutation(n)[:n_train])
        with single_blas_thread(), _faiss_threads(faiss, 1):
            self.components_ = self.mean_ = None
            if n_components is not None:
                pca_rows = train[:: max(1, n_train // _PCA_ROWS)][:_PCA_ROWS]
                E = np.maximum(X[pca_rows], self.floor_, dtype=np.float64)
                E = np.sqrt(E / E.sum(axis=1, keepdims=True))
                mean = E.mean(axis=0)
                E -= mean
                cov = E.T @ E
                _, vecs = np.linalg.eigh(cov)
                comps = vecs[:, ::-1][:, :n_components].T.copy()
                # a fixed sign per axis: its largest coordinate positive
                big = np.argmax(np.abs(comps), axis=1)
                comps *= np.sign(comps[np.arange(n_components), big])[:, None]
                self.mean_, self.components_ = mean, comps
            dim = n_bins if n_components is None else n_components
            if n_lists is None:
                index = faiss.IndexHNSWFlat(dim, self.hnsw_m, faiss.METRIC_L2)
                index.hnsw.efConstruction = _EF_CONSTRUCTION
            else:
                quantizer = faiss.IndexFlatL2(dim)
                index = faiss.IndexIVFFlat(quantizer, dim, n_lists, faiss.METRIC_L2)
                index.own_fields = True
                quantizer.this.disown()
                index.cp.seed = seed
                index.cp.max_points_per_centroid = _TRAIN_PER_LIST
                index.cp.min_points_per_centroid = 1
                index.verbose = False
                index.train(self._embed(X[train]))
            for start in range(0, n, _EMBED_ROWS):
                index.add(self._embed(X[start : start + _EMBED_ROWS]))
        self.index_ = index
        return self

    def _store(self, X):
        """Keep what re-ranking needs: compressed supports and row terms, or (renormalising) ``X``."""
        name = type(self).__name__
        if self._renormalize:
            self._X, self._support, self._row_terms = X, None, None
            return
        n = X.shape[0]
        counts = np.empty(n, dtype=np.int64)
        indices, values = [], []
        row_terms = np.empty((3, n))
        f, n_bins = self.floor_, X.shape[1]
        f_ln_f = f * np.log(f)
        for start in range(0, n, _EMBED_ROWS):
            rows = X[start : start + _EMBED_ROWS]
            m = rows.shape[0]
            mask = rows > f
            cnt = mask.sum(axis=1)
            counts[start : start + m] = cnt
            row_id, col = np.nonzero(mask)
            indices.append(col.astype(np.int32 if n_bins < 2**31 else np.int64))
            vals = rows[mask]
            values.append(vals)
            # the floored rows' sum h ln h, mass and largest |ln h|, from their support alone
            v = vals.astype(np.float64)
            with np.errstate(over="ignore"):
                mass = np.bincount(row_id, weights=v, minlength=m) + (n_bins - cnt) * f
            check_mass(mass, name)
            s_rows = np.bincount(row_id, weights=v * np.log(v), minlength=m) + (n_bins - cnt) * f_ln_f
            lo = np.maximum(rows.min(axis=1), f).astype(np.float64)
            hi = np.maximum(rows.max(axis=1), f).astype(np.float64)
            lam = np.maximum(np.abs(np.log(lo)), np.abs(np.log(hi)))
            row_terms[:, start : start + m] = s_rows, mass, lam
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        self._X = None
        self._support = (indptr, np.concatenate(indices), np.concatenate(values))
        self._row_terms = tuple(row_terms)

    def _rows(self, start, stop):
        """Training rows ``start:stop`` as dense histograms (bins at or below the floor read as zero)."""
        if self._X is not None:
            return self._X[start:stop]
        indptr, indices, values = self._support
        out = np.zeros((stop - start, self.n_features_in_), dtype=values.dtype)
        lo, hi = indptr[start], indptr[stop]
        rows = np.repeat(np.arange(stop - start), np.diff(indptr[start : stop + 1]))
        out[rows, indices[lo:hi]] = values[lo:hi]
        return out

    # ------------------------------------------------------------ pickling

    def __getstate__(self):
        state = dict(super().__getstate__())  # a copy: the base class may return __dict__ itself
        if "index_" in state:
            faiss = _import_faiss(type(self).__name__)
            state["index_"] = faiss.serialize_index(state["index_"])
        return state

    def __setstate__(self, state):
        if "index_" in state:
            faiss = _import_faiss(type(self).__name__)
            state = dict(state)
            state["index_"] = faiss.deserialize_index(state["index_"])
        super().__setstate__(state)

    # ------------------------------------------------------------ queries

    def _search_block(self, faiss, rows, m, k, n_probe, loo_start):
        """Exact-re-ranked neighbors of a block of raw query rows.

        ``loo_start`` is the training index of the first row when the
        queries are the training rows themselves (leave-one-out), else None.
        """
        name = type(self).__name__
        faiss.omp_set_num_threads(1)  # this thread's OpenMP setting only
        P = prepare_histograms(rows, self.floor_, self._renormalize, name)  # (checks the rows before they embed)
        Z = self._embed(rows)
        extra = 1 if loo_start is not None else 0
        m_search = min(m + extra, self.n_samples_fit_)
        if self.n_lists_ is None:
            params = faiss.SearchParametersHNSW(efSearch=max(self.ef_search, m_search))
        else:
            params = faiss.SearchParametersIVF(nprobe=n_probe)
        _, cand = self.index_.search(Z, m_search, params=params)
        short = (cand >= 0).sum(axis=1) < k + extra
        if short.any():  # too few rows reached (probed lists, graph walk): scan every vector
            if self.n_lists_ is None:
                exhaustive = faiss.downcast_index(self.index_.storage)
                cand[short] = exhaustive.search(Z[short], m_search)[1]
            else:
                full = faiss.SearchParametersIVF(nprobe=self.n_lists_)
                cand[short] = self.index_.search(Z[short], m_search, params=full)[1]
        if loo_start is not None:
            cand = _drop_own(cand, loo_start)
        if self._X is not None:
            return rerank_candidates(P, self._X, cand, k, self.floor_, self._renormalize, name)
        return rerank_sparse_candidates(P, self._support, self._row_terms, cand, k, self.floor_)

    def kneighbors(self, X=None, n_neighbors=None, return_distance=True):
        """Find approximate nearest training histograms of each query, with exact distances.

        Parameters
        ----------
        X : array-like of shape (n_queries, n_bins), default=None
            Query histograms. ``None`` queries the training histograms, each
            one excluded from its own neighbors (leave-one-out).
        n_neighbors : int, default=None
            Number of neighbors; ``None`` uses the ``n_neighbors``
            parameter. At most ``n_candidates``.
        return_distance : bool, default=True
            Whether to return the distances too.

        Returns
        -------
        neigh_dist : ndarray of shape (n_queries, n_neighbors)
            Exact symmetric KL distances to the neighbors found, increasing
            along each row. Only returned if ``return_distance=True``.
        neigh_ind : ndarray of shape (n_queries, n_neighbors)
            Indices of the neighbors in the training set.
        """
        check_is_fitted(self)
        name = type(self).__name__
        _, _, chunk_size = self._check_params()
        n_candidates, n_probe = self.n_candidates, self.n_probe
        faiss = _import_faiss(name)
        loo = X is None
        k = self._check_k(n_neighbors, loo)
        Q = None if loo else validate_histograms(self, X, reset=False)
        available = self.n_samples_fit_ - (1 if loo else 0)
        if k > n_candidates:
            raise ValueError(f"{name}: n_neighbors={k} is more than n_candidates={n_candidates}")
        m = min(n_candidates, available)
        n_probe = min(n_probe, self.n_lists_ or 1)
        n_q = self.n_samples_fit_ if loo else Q.shape[0]
        step = chunk_size or max(1, _RERANK_ENTRIES // (m * self.n_features_in_))
        starts = range(0, n_q, step)

        def block(start):
            rows = self._rows(start, min(start + step, n_q)) if loo else Q[start : start + step]
            return self._search_block(faiss, rows, m, k, n_probe, start if loo else None)

        ind = np.empty((n_q, k), dtype=np.intp)
        dist = np.empty((n_q, k))
        n_threads = check_n_jobs(self.n_jobs, owner=name)
        with single_blas_thread(), _faiss_threads(faiss, 1):
            if n_threads <= 1 or len(starts) <= 1:
                results = map(block, starts)
            else:
                results = ordered_map(block, starts, workers=n_threads, depth=2 * n_threads)
            for start, (d, i) in zip(starts, results):
                dist[start : start + step], ind[start : start + step] = d, i
        return (dist, ind) if return_distance else ind
