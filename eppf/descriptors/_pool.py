"""Descriptor pools: several descriptor draws per object, for augmentation."""

import numbers

import numpy as np
from sklearn.base import clone
from sklearn.utils import check_random_state

__all__ = ["descriptor_pool"]

_OWNER = "descriptor_pool"


def descriptor_pool(transformer, X, n_draws=4, *, augment=None, random_state=None):
    """Describe every cloud ``n_draws`` times, for a classifier's descriptor pool.

    Draw ``r`` runs a clone of ``transformer`` with its own ``random_state``
    (other random point pairs). With ``augment``, draws ``1 .. n_draws - 1``
    describe perturbed copies of the clouds (a clone of ``augment``, e.g.
    :class:`eppf.preprocessing.RandomScaling`, with its own seed per draw),
    while draw 0 always describes the clouds as given: it is the draw
    :class:`eppf.classifiers.EPPF4DClassifier` validates on.

    Parameters
    ----------
    transformer : estimator
        A descriptor transformer such as :class:`eppf.descriptors.EPPFTransformer`, with
        a ``random_state`` parameter. Each draw fits a clone on ``X`` as
        given (so ``scaling="fit"`` learns its scale from the unperturbed
        clouds) and transforms the draw's clouds.
    X : list of array-like of shape (n_i, 3) or (n_i, 6)
        Point clouds, normals in the last three columns.
    n_draws : int, default=4
        Draws per object, >= 1.
    augment : transformer or None, default=None
        Maps a list of clouds to a list of clouds (``fit_transform``); it
        needs a ``random_state`` parameter. ``None``: every draw describes
        the clouds as given and differs only in its point pairs.
    random_state : int, RandomState instance or None, default=None
        Seed of the per-draw seeds. A fixed integer gives the same pool on
        every call.

    Returns
    -------
    pool : ndarray of shape (n_objects, n_draws, n_features)
        ``pool[:, r]`` is draw ``r``; pass the pool to
        :meth:`eppf.classifiers.EPPF4DClassifier.fit` (a fresh draw per object every
        epoch) or to ``predict_proba`` (probabilities averaged over draws).

    See Also
    --------
    eppf.classifiers.EPPF4DClassifier : Trains on descriptor pools.
    eppf.nn.DescriptorPoolDataset : Draws one descriptor per object and epoch.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import EPPFTransformer, descriptor_pool
    >>> from eppf.preprocessing import RandomScaling
    >>> rng = np.random.RandomState(0)
    >>> clouds = [rng.normal(size=(200, 3)) for _ in range(3)]
    >>> pool = descriptor_pool(EPPFTransformer(n_pairs=500), clouds, 3,
    ...                        augment=RandomScaling(), random_state=0)
    >>> pool.shape
    (3, 3, 1200)
    """
    if isinstance(n_draws, (bool, np.bool_)) or not isinstance(n_draws, numbers.Integral):
        raise TypeError(f"{_OWNER}: n_draws must be an int, got {type(n_draws).__name__}")
    if n_draws < 1:
        raise ValueError(f"{_OWNER}: n_draws must be >= 1, got {n_draws}")
    for role, est, methods in (("transformer", transformer, ("fit", "transform")),
                               ("augment", augment, ("fit_transform",))):
        if est is None and role == "augment":
            continue
        missing = [m for m in methods if not callable(getattr(est, m, None))]
        if missing or "random_state" not in getattr(est, "get_params", lambda: {})():
            raise TypeError(
                f"{_OWNER}: {role} must be a scikit-learn style estimator with "
                f"{' and '.join(methods)} and a random_state parameter, got {type(est).__name__}"
            )
    if hasattr(X, "__next__"):
        X = list(X)  # an iterator (a generator) would be used up by the first draw
    rng = check_random_state(random_state)
    seeds = rng.randint(np.iinfo(np.int32).max, size=(int(n_draws), 2))
    draws = []
    for r, (seed, aug_seed) in enumerate(seeds):
        est = clone(transformer).set_params(random_state=int(seed)).fit(X)
        clouds = X if augment is None or r == 0 else clone(augment).set_params(random_state=int(aug_seed)).fit_transform(X)
        draws.append(np.asarray(est.transform(clouds)))
    return np.stack(draws, axis=1)
