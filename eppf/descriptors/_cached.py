"""Caching of descriptor outputs on disk, for pipelines and grid searches."""

import os
import warnings

from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.utils import get_tags
from sklearn.utils.metaestimators import available_if
from sklearn.utils.validation import check_is_fitted

from ..utils._cache import DescriptorCache, data_digest, estimator_key

__all__ = ["CachedTransformer"]


class CachedTransformer(TransformerMixin, BaseEstimator):
    """Cache the output of a descriptor transformer on disk.

    Descriptors of a large data set take minutes to compute and are needed
    again for every classifier, grid-search candidate and experiment. This
    wrapper stores them with :class:`joblib.Memory`, keyed on the wrapped
    transformer's class, its parameters (except ones that only change speed:
    ``n_jobs``, ``verbose``, ``chunk_size``, ``batch_size``), its fitted
    attributes and a hash of the input clouds. A second call with the same
    key loads the result instead of computing it.

    Parameters
    ----------
    transformer : estimator
        The transformer to cache, e.g. :class:`eppf.descriptors.EPPFTransformer`; it is
        cloned in ``fit``.
    memory : str, path-like or joblib.Memory, default=None
        Where to cache: a folder (or a Memory object, whose location is
        used); None disables caching.

    Attributes
    ----------
    transformer_ : estimator
        The fitted clone of ``transformer``.

    See Also
    --------
    eppf.descriptors.EPPFTransformer : A descriptor worth caching.
    eppf.descriptors.descriptor_pool : Several draws of a descriptor per object.

    Notes
    -----
    Only cache transformers with a fixed ``random_state``: with
    ``random_state=None`` every call should draw afresh, but the cache
    returns the first draw (a warning says so).

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> from sklearn.preprocessing import FunctionTransformer
    >>> from eppf.descriptors import CachedTransformer
    >>> X = np.arange(6.0).reshape(3, 2)
    >>> cached = CachedTransformer(FunctionTransformer(np.sqrt), memory=tempfile.mkdtemp())
    >>> cached.fit_transform(X).shape
    (3, 2)
    """

    def __init__(self, transformer, *, memory=None):
        self.transformer = transformer
        self.memory = memory

    def _cache(self):
        owner = type(self).__name__
        if not hasattr(self.transformer, "fit") or not hasattr(self.transformer, "transform"):
            raise TypeError(f"{owner}: transformer must have fit and transform methods, got {type(self.transformer).__name__}")
        memory = self.memory
        if memory is not None and hasattr(memory, "location") and hasattr(memory, "cache"):
            memory = memory.location
        if isinstance(memory, os.PathLike):
            memory = os.fspath(memory)
        if memory is not None and not isinstance(memory, str):
            raise ValueError(f"{owner}: memory must be None, a folder or a joblib.Memory, got {type(memory).__name__}")
        params = self.transformer.get_params(deep=True)
        if memory is not None and "random_state" in params and params["random_state"] is None:
            warnings.warn(
                f"{owner}: the wrapped {type(self.transformer).__name__} has random_state=None; the cache "
                "returns the first draw on every call. Set an integer random_state.",
                UserWarning,
                stacklevel=3,
            )
        return DescriptorCache(memory)

    def _cached_transform(self, cache, est, X):
        key = [estimator_key(est, fitted=True), data_digest(X)]
        return cache.get(type(est).__name__, key, lambda: {"X": est.transform(X)}, ["X"], type(est).__name__)["X"]

    def fit(self, X, y=None):
        """Fit a clone of the transformer (cached).

        Parameters
        ----------
        X : list of array-like
            Point clouds, as the wrapped transformer takes them.
        y : array-like, default=None
            Passed on to the wrapped transformer.

        Returns
        -------
        self : object
            The fitted wrapper.
        """
        self.fit_transform(X, y)
        return self

    def fit_transform(self, X, y=None):
        """Fit a clone of the transformer and return its output (cached).

        Parameters
        ----------
        X : list of array-like
            Point clouds.
        y : array-like, default=None
            Passed on to the wrapped transformer.

        Returns
        -------
        X_new : ndarray
            The wrapped transformer's output.
        """
        if hasattr(X, "__next__"):  # an iterator (a generator) is read once: fit would use it up
            X = list(X)
        cache = self._cache()
        est = clone(self.transformer)
        if y is None:
            est.fit(X)
        else:
            est.fit(X, y)
        self.transformer_ = est
        return self._cached_transform(cache, est, X)

    def transform(self, X):
        """Transform with the fitted transformer (cached).

        Parameters
        ----------
        X : list of array-like
            Point clouds.

        Returns
        -------
        X_new : ndarray
            The wrapped transformer's output.
        """
        check_is_fitted(self, "transformer_")
        if hasattr(X, "__next__"):  # (read twice: hashed for the cache key, then transformed)
            X = list(X)
        return self._cached_transform(self._cache(), self.transformer_, X)

    @available_if(lambda self: hasattr(self.transformer, "get_feature_names_out"))
    def get_feature_names_out(self, input_features=None):
        """Get the names of the output columns: the wrapped transformer's.

        Available when the wrapped transformer has ``get_feature_names_out``.

        Parameters
        ----------
        input_features : array-like of str or None, default=None
            Passed on to the fitted transformer.

        Returns
        -------
        feature_names_out : ndarray of str
            One name per output column.
        """
        check_is_fitted(self, "transformer_")
        return self.transformer_.get_feature_names_out(input_features)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        inner = get_tags(self.transformer)
        tags.input_tags = inner.input_tags
        tags.transformer_tags = inner.transformer_tags
        return tags
