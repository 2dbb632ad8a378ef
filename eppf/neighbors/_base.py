"""What exact and approximate symmetric-KL search share.

- the parameters and their constraints (:data:`KL_CONSTRAINTS`, checked by
  :mod:`eppf.utils._param_validation`), resolved by
  :func:`check_distance_params` for the functions that take them;
- the validation of histograms (finite, non-negative, named errors) and the
  floor ``"auto"`` learns;
- :class:`Prepared` histograms: floored, with logarithms and the row terms
  that every distance here and its rounding bound use;
- the tie rule (near-ties within rounding go to the lowest index) and the
  votes that turn neighbors into class probabilities;
- :class:`KLNeighborsBase`, the base class of both classifiers.
"""

import numbers
from collections import namedtuple

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils import check_array
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

from ..utils._param_validation import N_JOBS, Interval, Options, StrOptions, validate_parameter, validate_params

__all__ = [
    "BLOCK_ENTRIES",
    "KL_CONSTRAINTS",
    "KLNeighborsBase",
    "MASS_MAX",
    "Prepared",
    "check_mass",
    "check_distance_params",
    "check_n_neighbors",
    "first_near_min",
    "learn_floor",
    "named",
    "neighbour_votes",
    "prepare_histograms",
    "relative_rounding",
    "smallest_k",
    "validate_histogram_array",
    "validate_histograms",
]

#: Target size of one block of a distance matrix, or of rows read at a time,
#: in float64 entries (64 MiB).
BLOCK_ENTRIES = 1 << 23


#: Largest row mass (sum of the floored bins) the divergence takes. A distance
#: and its rounding bound sum a few terms, each at most a row's mass times the
#: largest ``|ln h|`` of a row (below 745 for any positive float64): below
#: this they stay finite, above it two large rows' cross terms can overflow
#: (to a distance of 0 or NaN, or a rounding bound that ties everything).
MASS_MAX = float(np.finfo(np.float64).max) / (16 * 745)


#: The parameters of the symmetric-KL estimators and functions, and what they accept.
KL_CONSTRAINTS = {
    "n_neighbors": [Interval(numbers.Integral, 1, None, closed="left", description="a positive int")],
    "weights": [StrOptions(["uniform", "distance"])],
    "floor": [StrOptions(["auto"]), Interval(numbers.Real, 0, None, closed="neither", description="a positive float")],
    "renormalize": [Options(bool, description="a bool")],
    "chunk_size": [Interval(numbers.Integral, 1, None, closed="left", description="a positive int"), None],
    "n_jobs": N_JOBS,
}


def check_n_neighbors(k, owner):
    """``k`` checked against the ``n_neighbors`` constraint, as an int.

    Parameters
    ----------
    k : object
        The value (the ``n_neighbors`` argument of ``kneighbors``).
    owner : str
        Name used in the error message.

    Returns
    -------
    k : int
        The checked value.
    """
    return int(validate_parameter(k, KL_CONSTRAINTS["n_neighbors"], name="n_neighbors", owner=owner))


def check_distance_params(owner, *, floor, renormalize, chunk_size, n_jobs):
    """Check a distance function's parameters against :data:`KL_CONSTRAINTS`; return them resolved.

    Parameters
    ----------
    owner : str
        Name used in error messages.
    floor, renormalize, chunk_size, n_jobs : object
        The parameters, as documented by :func:`eppf.neighbors.symmetric_kl_distances`.

    Returns
    -------
    floor : "auto" or float
    renormalize : bool
    chunk_size : int or None
    """
    params = {"floor": floor, "renormalize": renormalize, "chunk_size": chunk_size, "n_jobs": n_jobs}
    for name, value in params.items():
        validate_parameter(value, KL_CONSTRAINTS[name], name=name, owner=owner)
    return _resolved(floor, renormalize, chunk_size)


def _resolved(floor, renormalize, chunk_size):
    return (
        floor if isinstance(floor, str) else float(floor),
        bool(renormalize),
        None if chunk_size is None else int(chunk_size),
    )


def named(owner, func, *args, **kwargs):
    """Call a scikit-learn validator, prefixing its error messages with ``owner``.

    Parameters
    ----------
    owner : str
        The prefix.
    func : callable
        The validator, called as ``func(*args, **kwargs)``.

    Returns
    -------
    result : object
        What ``func`` returns.
    """
    try:
        return func(*args, **kwargs)
    except (ValueError, TypeError) as exc:
        if type(exc) not in (ValueError, TypeError) or str(exc).startswith(owner):
            raise
        raise type(exc)(f"{owner}: {exc}") from exc


def _check_non_negative(X, owner, name="X"):
    """Raise if the (finite, numeric) array ``X`` holds a negative value, reading it in blocks of rows."""
    step = max(1, BLOCK_ENTRIES // max(1, X.shape[1]))
    for start in range(0, X.shape[0], step):
        block = X[start : start + step]
        if block.size and block.min() < 0:
            raise ValueError(
                f"Negative values in data passed to {owner} ({name}): histograms must be "
                f"non-negative, found minimum {float(X.min())!r}"
            )


def validate_histogram_array(X, owner, name):
    """A function's histograms as a finite, non-negative float64 array.

    Parameters
    ----------
    X : array-like of shape (n_samples, n_bins)
        Histograms.
    owner : str
        The function's name, for error messages.
    name : str
        The argument's name, for error messages.

    Returns
    -------
    X : ndarray of shape (n_samples, n_bins)
        The validated histograms.
    """
    X = named(owner, check_array, X, dtype=np.float64, ensure_all_finite=True, input_name=name)
    _check_non_negative(X, owner, name)
    return X


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
        X = named(name, validate_data, est, X, dtype=dtype, ensure_all_finite=True, reset=reset)
    else:
        X, y = named(name, validate_data, est, X, y, dtype=dtype, ensure_all_finite=True, reset=reset)
        named(name, check_classification_targets, y)
    _check_non_negative(X, name)
    return X if no_y else (X, y)


def learn_floor(arrays, owner):
    """Half the smallest positive value over ``arrays`` (the paper's floor), read in blocks of rows.

    Parameters
    ----------
    arrays : list of ndarray of shape (n_samples, n_bins)
        Non-negative histograms.
    owner : str
        Name used in the error message.

    Returns
    -------
    floor : float
        The floor of ``floor="auto"``.
    """
    smallest = np.inf
    for X in arrays:
        step = max(1, BLOCK_ENTRIES // max(1, X.shape[1]))
        for start in range(0, X.shape[0], step):
            block = X[start : start + step]
            positive = block[block > 0]
            if positive.size:
                smallest = min(smallest, float(positive.min()))
    if not np.isfinite(smallest):
        raise ValueError(
            f"{owner}: cannot learn floor='auto' because X has no positive value; "
            "pass floor as a positive float"
        )
    if smallest / 2.0 == 0.0:  # (the smallest subnormal: a floor of 0 has no logarithm)
        raise ValueError(
            f"{owner}: cannot learn floor='auto' because half the smallest positive value of the histograms "
            f"({smallest!r}) is 0 in float64; pass floor as a positive float"
        )
    return smallest / 2.0


def check_mass(mass, owner):
    """Raise if a row mass is above :data:`MASS_MAX` (or infinite).

    Parameters
    ----------
    mass : ndarray of shape (n_samples,)
        Row sums of floored histograms.
    owner : str
        Name used in the error message.
    """
    if not np.all(mass <= MASS_MAX):
        raise ValueError(
            f"{owner}: histogram values are too large for the KL divergence (a row sums to "
            f"{float(np.max(mass)):.4g}; its terms stay finite for sums up to {MASS_MAX:.4g})"
        )


class Prepared(namedtuple("Prepared", "H L s mass lam")):
    """Floored histograms ``H``, ``L = ln H``, ``s = sum H ln H`` per row,
    the row masses and the largest ``|ln H|`` per row (for rounding bounds)."""

    __slots__ = ()

    def rows(self, start, stop):
        """Rows ``start:stop`` of every field."""
        return Prepared(*(a[start:stop] for a in self))


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
    prepared : Prepared
        Fields ``H, L, s, mass, lam``.
    """
    H = np.maximum(X, floor, dtype=np.float64)
    with np.errstate(over="ignore"):
        mass = H.sum(axis=1)
    if renormalize and np.all(np.isfinite(mass)):
        H /= mass[:, None]
        mass = H.sum(axis=1)
    check_mass(mass, owner)
    with np.errstate(over="ignore", invalid="ignore"):
        L = np.log(H)
        s = np.einsum("ij,ij->i", H, L)
    if not np.all(np.isfinite(s)):
        raise ValueError(f"{owner}: histogram values are too large for the KL divergence (overflow in x ln x)")
    lam = np.abs(L).max(axis=1) if L.shape[1] else np.zeros(L.shape[0])
    return Prepared(H, L, s, mass, lam)


def relative_rounding(n_bins):
    """Relative rounding bound of the distances between histograms of ``n_bins`` bins.

    A dot product of length ``n`` carries a relative error of at most about
    ``n`` units in the last place; the tie tolerance of a distance is this
    times the size of the terms it sums.

    Parameters
    ----------
    n_bins : int
        Bins per histogram.

    Returns
    -------
    rel : float
        ``4 max(n_bins, 16)`` machine epsilons.
    """
    return 4.0 * max(n_bins, 16) * np.finfo(np.float64).eps


def first_near_min(D, T, axis):
    """Lowest index along ``axis`` whose distance is within ``T`` of the minimum.

    Parameters
    ----------
    D, T : ndarray
        Distances and their tie tolerances.
    axis : int
        The axis searched.

    Returns
    -------
    index : ndarray
        ``D``'s shape without ``axis``.
    """
    m = D.min(axis=axis, keepdims=True)
    return np.argmax(D <= m + T, axis=axis)


def smallest_k(D, T, k):
    """Indices of the ``k`` nearest columns of each row of ``D``.

    Greedy rule, applied ``k`` times: among the columns not yet taken, the
    lowest index whose distance is within its tie tolerance ``T`` of the
    smallest remaining distance. Without near-ties this is plain sorting by
    distance; with exact or rounding-level ties it prefers low indices.

    Parameters
    ----------
    D, T : ndarray of shape (n_rows, n_cols)
        Distances and their tie tolerances.
    k : int
        Columns kept per row, at most ``n_cols``.

    Returns
    -------
    indices : ndarray of shape (n_rows, k)
        Column indices, nearest first.
    """
    n_rows, n_cols = D.shape
    if k == 1:
        return first_near_min(D, T, axis=1)[:, None]
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


class KLNeighborsBase(ClassifierMixin, BaseEstimator):
    """Base of the symmetric-KL neighbor classifiers.

    A subclass declares ``_parameter_constraints`` (those of
    :data:`KL_CONSTRAINTS` and its own), sets ``classes_``, ``_y`` (training
    labels as indices into ``classes_``) and ``n_samples_fit_`` in ``fit``
    and implements ``kneighbors``; this class gives the parameter check,
    the check of the number of neighbors asked for, and ``predict_proba``
    and ``predict`` from the votes of ``kneighbors``.
    """

    _parameter_constraints = dict(KL_CONSTRAINTS)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.positive_only = True
        return tags

    def _check_params(self):
        """Validate every parameter; return ``floor``, ``renormalize`` and ``chunk_size`` resolved."""
        validate_params(self)
        return _resolved(self.floor, self.renormalize, self.chunk_size)

    def _check_k(self, n_neighbors, loo):
        """The number of neighbors asked for (``None``: the parameter), checked against the training set."""
        name = type(self).__name__
        k = check_n_neighbors(self.n_neighbors if n_neighbors is None else n_neighbors, name)
        available = self.n_samples_fit_ - (1 if loo else 0)
        if k > available:
            extra = " excluding each query itself" if loo else ""
            raise ValueError(
                f"{name}: n_neighbors={k} is more than the {available} training sample(s) available{extra}"
            )
        return k

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
