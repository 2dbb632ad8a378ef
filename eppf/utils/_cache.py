"""The one on-disk cache of descriptor matrices.

Descriptors of a large data set take minutes and are needed again by every
classifier, grid-search candidate and experiment. :class:`DescriptorCache`
stores them as ``.npz`` files (read with ``allow_pickle=False``: a cache file
cannot run code), keyed on what the output depends on: the transformer's
class, its parameters except those that only change speed
(:data:`NEUTRAL_PARAMS`), its fitted attributes, and a digest of the input.
:class:`eppf.descriptors.CachedTransformer` and the experiments both use it.
"""

import hashlib
import os
import time

import numpy as np

__all__ = ["NEUTRAL_PARAMS", "DescriptorCache", "data_digest", "estimator_key"]

#: Parameters that change how fast an estimator runs, never what it returns.
NEUTRAL_PARAMS = ("n_jobs", "verbose", "chunk_size", "batch_size")


def _update(h, value):
    """Feed ``value`` to the hash ``h``: arrays by dtype, shape and bytes, the rest by repr."""
    if isinstance(value, np.ndarray) and value.dtype != object:
        arr = np.ascontiguousarray(value)
        h.update(f"{arr.dtype}{arr.shape}".encode())
        h.update(arr.data)
    elif isinstance(value, (list, tuple)) and any(isinstance(v, np.ndarray) for v in value):
        h.update(f"{type(value).__name__}{len(value)}".encode())
        for v in value:
            _update(h, v)
    else:
        h.update(repr(value).encode())


def data_digest(X):
    """A digest of a list of clouds or an array (shapes and values).

    Parameters
    ----------
    X : list of array-like or ndarray
        The input of a transformer.

    Returns
    -------
    digest : str
        32 hexadecimal characters.
    """
    h = hashlib.blake2b(digest_size=16)
    if isinstance(X, np.ndarray) and X.dtype != object:
        _update(h, np.asarray(X, dtype=np.float64))
        return h.hexdigest()
    h.update(str(len(X)).encode())
    for c in X:
        c = np.ascontiguousarray(c, dtype=np.float64)
        h.update(str(c.shape).encode())
        h.update(c.data)
    return h.hexdigest()


def estimator_key(est, *, fitted=False):
    """What an estimator's output depends on, as a string.

    Parameters
    ----------
    est : estimator
        Any scikit-learn estimator.
    fitted : bool, default=False
        Also include the fitted attributes (names ending in ``_``).

    Returns
    -------
    key : str
        The class path and the sorted parameters (except
        :data:`NEUTRAL_PARAMS`), then a digest of the fitted state.
    """
    params = est.get_params(deep=False)
    items = sorted((k, repr(v)) for k, v in params.items() if k not in NEUTRAL_PARAMS)
    key = f"{type(est).__module__}.{type(est).__qualname__}{items}"
    if fitted:
        h = hashlib.blake2b(digest_size=16)
        for name in sorted(k for k in vars(est) if k.endswith("_") and not k.startswith("_")):
            h.update(name.encode())
            _update(h, getattr(est, name))
        key += h.hexdigest()
    return key


class DescriptorCache:
    """Descriptor matrices on disk, keyed by transformer parameters and input clouds.

    Parameters
    ----------
    folder : str or None
        Where the ``.npz`` files go; None disables caching.
    log : callable, default=None
        Receives one line per hit or computation.

    Attributes
    ----------
    n_computed : int
        Descriptor sets computed (cache misses) so far.
    n_loaded : int
        Descriptor sets read from the cache so far.
    seconds : float
        Time spent computing (not loading) so far.
    """

    def __init__(self, folder, log=None):
        self.folder = folder
        self.log = log or (lambda msg: None)
        self.n_computed = 0
        self.n_loaded = 0
        self.seconds = 0.0
        if folder is not None:
            os.makedirs(folder, exist_ok=True)

    def _path(self, name, key_parts):
        if self.folder is None:
            return None
        key = hashlib.blake2b("|".join(key_parts).encode(), digest_size=12).hexdigest()
        return os.path.join(self.folder, f"{name}-{key}.npz")

    def _load(self, path, names, label):
        if path is None or not os.path.exists(path):
            return None
        try:
            with np.load(path, allow_pickle=False) as f:
                out = {k: f[k] for k in names}
        except Exception:  # noqa: BLE001 - a cut or corrupt file of any kind (BadZipFile, zlib.error...): recomputed
            self.log(f"{label}: unreadable cache file {path}, recomputing")
            return None
        self.n_loaded += 1
        self.log(f"{label}: descriptors from cache {os.path.basename(path)}")
        return out

    def _store(self, path, out):
        if path is None:
            return
        tmp = f"{path}.{os.getpid()}.tmp.npz"
        try:
            np.savez(tmp, **out)
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)

    def get(self, name, key_parts, compute, names, label):
        """The arrays ``names`` stored under ``key_parts``, or ``compute()``'s, stored.

        Parameters
        ----------
        name : str
            Start of the file name (the transformer's class name).
        key_parts : list of str
            What the arrays depend on.
        compute : callable
            Returns a dict with the arrays ``names`` when they are not cached.
        names : sequence of str
            Keys of the arrays.
        label : str
            Name in progress lines.

        Returns
        -------
        arrays : dict of str to ndarray
        """
        path = self._path(name, key_parts)
        out = self._load(path, names, label)
        if out is not None:
            return out
        t = time.perf_counter()
        out = compute()
        dt = time.perf_counter() - t
        self.seconds += dt
        self.n_computed += 1
        self.log(f"{label}: computed {sum(len(v) for v in out.values())} descriptors in {dt:.1f} s")
        self._store(path, out)
        return out

    def describe(self, est, fit_clouds, sets, label):
        """Fit ``est`` on ``fit_clouds`` and transform every set of clouds (cached).

        Parameters
        ----------
        est : transformer
            Unfitted descriptor transformer (its ``random_state`` fixed).
        fit_clouds : list of ndarray
            Clouds passed to ``fit``.
        sets : dict of str to list of ndarray
            Clouds to transform, by name.
        label : str
            Name in progress lines.

        Returns
        -------
        descriptors : dict of str to ndarray
            One descriptor matrix per set.
        """
        key_parts = [estimator_key(est), data_digest(fit_clouds)]
        key_parts += [f"{k}:{data_digest(v)}" for k, v in sorted(sets.items())]

        def compute():
            est.fit(fit_clouds)
            return {k: np.asarray(est.transform(v)) for k, v in sets.items()}

        # the file name depends on what was computed only, so experiments share files
        return self.get(type(est).__name__, key_parts, compute, list(sets), label)
