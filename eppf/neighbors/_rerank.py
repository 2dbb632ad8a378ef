"""Exact symmetric-KL re-ranking of the candidates an approximate index proposes.

:class:`~eppf.neighbors.ApproximateKLNearestNeighbors` asks its index for a
few candidates per query and ranks them here by the exact divergence, with
the tie rule of exact search (near-ties within rounding go to the lowest
index): from dense database rows (:func:`rerank_candidates`) or from their
bins above the floor in compressed rows (:func:`rerank_sparse_candidates`).
"""

import numpy as np

from ._base import prepare_histograms, relative_rounding, smallest_k

__all__ = ["rerank_candidates", "rerank_sparse_candidates"]


def _sorted_candidates(candidates):
    """Each row's candidates in increasing index order (``-1``, no candidate, last), and which are valid."""
    order = np.argsort(np.where(candidates < 0, np.iinfo(np.intp).max, candidates), axis=1, kind="stable")
    cand = np.take_along_axis(candidates, order, axis=1).astype(np.intp)
    return cand, cand >= 0


def _nearest(D, T, cand, valid, k):
    """The ``k`` nearest valid candidates of each row, by the tie rule of exact search."""
    D[~valid] = np.inf
    T[~valid] = 0.0
    pick = smallest_k(D, T, k)
    return np.take_along_axis(D, pick, axis=1), np.take_along_axis(cand, pick, axis=1)


def rerank_candidates(P, database, candidates, k, floor, renormalize, owner):
    """Exact symmetric KL re-ranking of candidate neighbors.

    Parameters
    ----------
    P : namedtuple
        Prepared queries (:func:`~eppf.neighbors._base.prepare_histograms`), ``n_queries`` rows.
    database : ndarray of shape (n_database, n_bins)
        Raw database histograms (any float dtype; rows are floored, optionally
        renormalised and taken to float64 exactly as :func:`~eppf.neighbors._base.prepare_histograms` does).
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
        :class:`~eppf.neighbors.KLNearestNeighbors`.
    """
    n_q, m = candidates.shape
    cand, valid = _sorted_candidates(candidates)
    C = prepare_histograms(database[np.where(valid, cand, 0).ravel()], floor, renormalize, owner)
    n_bins = C.H.shape[1]
    Hc = C.H.reshape(n_q, m, n_bins)
    Lc = C.L.reshape(n_q, m, n_bins)
    # d = s_q + s_c - (h_q . ln h_c + ln h_q . h_c), in _kl_block's order
    D = np.matmul(Lc, P.H[:, :, None])[:, :, 0]
    D += np.matmul(Hc, P.L[:, :, None])[:, :, 0]
    np.subtract(P.s[:, None], D, out=D)
    D += C.s.reshape(n_q, m)
    np.maximum(D, 0.0, out=D)
    rel = relative_rounding(n_bins)
    T = (P.mass[:, None] * C.lam.reshape(n_q, m) + P.lam[:, None] * C.mass.reshape(n_q, m)
         + np.abs(P.s)[:, None] + np.abs(C.s.reshape(n_q, m))) * rel
    return _nearest(D, T, cand, valid, k)


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
        Prepared queries (:func:`~eppf.neighbors._base.prepare_histograms` with
        ``renormalize=False``).
    support : tuple of ndarray
        ``(indptr, indices, values)``: compressed rows of the database
        holding its bins above ``floor`` (values in any float dtype).
    row_terms : tuple of ndarray
        ``(s, mass, lam)`` of the database rows, as in
        :func:`~eppf.neighbors._base.prepare_histograms`; they set the tie tolerance.
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
    cand, valid = _sorted_candidates(candidates)
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
    rel = relative_rounding(P.H.shape[1])
    T = (P.mass[:, None] * row_lam[cand] + P.lam[:, None] * row_mass[cand]
         + np.abs(P.s)[:, None] + np.abs(row_s[cand])) * rel
    return _nearest(D, T, cand, valid, k)
