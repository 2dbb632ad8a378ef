"""Descriptor pools: several descriptor draws per object, for augmentation."""

import numbers

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from ..utils import check_n_jobs, check_packed_clouds
from ..utils._param_validation import RANDOM_STATE, Interval, Options, validate_parameter, validate_params
from ..utils._validation import condition_point_clouds
from ._base import points_and_normals

__all__ = ["DescriptorPool", "descriptor_pool"]

_OWNER = "descriptor_pool"


#: ``n_draws`` (and ``test_draws``): draws per object.
_N_DRAWS = [Interval(numbers.Integral, 1, None, closed="left")]


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
        a ``random_state`` parameter (nested ones included, e.g. in a
        :class:`~eppf.descriptors.DescriptorUnion`); one without (GASD,
        VFH, ...) needs ``augment``, whose perturbed copies make its draws
        differ. Each draw fits a clone on ``X`` as
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
    validate_parameter(n_draws, _N_DRAWS, name="n_draws", owner=_OWNER)
    _check_parts(_OWNER, transformer, augment)
    if hasattr(X, "__next__"):
        X = list(X)  # an iterator (a generator) would be used up by the first draw
    rng = check_random_state(random_state)
    seeds = rng.randint(np.iinfo(np.int32).max, size=(int(n_draws), 2))
    draws = []
    for r, (seed, aug_seed) in enumerate(seeds):
        est = _seed_params(clone(transformer), seed).fit(X)
        clouds = X if augment is None or r == 0 else _seed_params(clone(augment), aug_seed).fit_transform(X)
        draws.append(np.asarray(est.transform(clouds)))
    return np.stack(draws, axis=1)


def _random_state_keys(est):
    """The names of ``est``'s ``random_state`` parameters, nested ones included."""
    params = getattr(est, "get_params", lambda deep=True: {})(deep=True)
    return [k for k in params if k == "random_state" or k.endswith("__random_state")]


def _seed_params(est, seed):
    """``est`` with every ``random_state`` it has, nested ones included, set to ``seed``."""
    return est.set_params(**{k: int(seed) for k in _random_state_keys(est)})


def _check_parts(owner, transformer, augment):
    """The pool's transformer and augmentation as the pools use them, or a TypeError naming ``owner``.

    The transformer needs ``fit`` and ``transform`` and a (nested) ``random_state``, which each draw
    sets, unless ``augment`` is given: then a deterministic transformer (GASD, VFH, ...) still gives
    draws that differ, by their perturbed copies. ``augment`` needs ``fit_transform`` and a
    ``random_state``.
    """
    for role, est, methods in (("transformer", transformer, ("fit", "transform")),
                               ("augment", augment, ("fit_transform",))):
        if est is None and role == "augment":
            continue
        missing = [m for m in methods if not callable(getattr(est, m, None))]
        seeded = bool(_random_state_keys(est)) or (role == "transformer" and augment is not None)
        if missing or not seeded:
            need = "a random_state parameter" if role == "augment" else \
                "a random_state parameter (or an augment, whose perturbed copies make the draws differ)"
            raise TypeError(
                f"{owner}: {role} must be a scikit-learn style estimator with {' and '.join(methods)} and {need}, "
                f"got {type(est).__name__}"
            )


class DescriptorPool(TransformerMixin, BaseEstimator):
    """Describe every cloud several times: a descriptor pool as a pipeline step.

    The transformer form of :func:`descriptor_pool`, so that a
    :class:`~sklearn.pipeline.Pipeline` of this step and
    :class:`eppf.classifiers.EPPF4DClassifier` trains on fresh draws every
    epoch and averages its predictions over draws, with no hand-stacked
    arrays. ``fit_transform`` (what ``Pipeline.fit`` calls) returns the
    training pool: draw 0 describes the clouds as given, draws ``1 ..
    n_draws - 1`` describe copies perturbed by ``augment``. ``transform``
    (what ``Pipeline.predict`` calls) returns ``test_draws`` draws for
    test-time averaging: draw 0 plain, the others perturbed when
    ``test_augment``, with seeds of their own (never the training ones).

    Parameters
    ----------
    transformer : estimator
        A descriptor transformer (:class:`EPPFTransformer`,
        :class:`DescriptorUnion`, ...). Every ``random_state`` parameter it
        has, nested ones included, is set per draw; draw ``r`` is described
        by a clone fitted on the clouds given to ``fit``. A transformer
        without one (GASD, VFH, ...) needs ``augment``: its draws then differ
        only by their perturbed copies (draw 0, and every test draw where
        ``test_augment=False``, describe the same clouds the same way).
    n_draws : int, default=8
        Draws per object in the training pool.
    augment : transformer or None, default=None
        Perturbs a list of clouds (``fit_transform``) and has a
        ``random_state`` parameter, e.g.
        :class:`eppf.preprocessing.RandomScaling`. None: the draws differ
        only in their random point pairs.
    test_draws : int, default=None
        Draws per object returned by ``transform``; None means ``n_draws``.
    test_augment : bool, default=True
        Whether draws ``1 ..`` of ``transform`` describe perturbed copies too
        (test-time augmentation); False describes the clouds as given in
        every draw.
    share_normals : bool, default=False
        Estimate the normals of the clouds given without normals once per
        call, on the clouds as given, and hand every draw the clouds with
        those normals (columns 3-5), instead of every draw's transformer
        estimating them again on its perturbed copy. ``augment`` must carry
        normals along: :class:`eppf.preprocessing.RandomScaling` maps each
        by the inverse factors (for a stretch ``S``, ``S^-1 n`` made unit:
        the exact normal of the stretched surface, and the exact PCA normal
        of a stretched planar neighborhood). The normals are the
        transformer's own: PCA normals from its ``n_neighbors`` neighbors,
        oriented by its ``normal_orientation`` (nested parameters included;
        every block that has them must agree). One normal estimation per
        object instead of one per draw; draw 0 describes the same normals
        the transformer would estimate itself.
    random_state : int, RandomState instance or None, default=None
        Seed of the per-draw seeds; an int gives the same pools on every call.

    Attributes
    ----------
    transformers_ : list of estimator
        The fitted clone of ``transformer`` of every draw.
    n_features_out_ : int
        Values per draw.

    See Also
    --------
    descriptor_pool : The same pool as a function.
    eppf.classifiers.EPPF4DClassifier : Reads pools of shape (n_objects, n_draws, n_features).

    Notes
    -----
    ``fit_transform(X)`` differs from ``fit(X).transform(X)`` on purpose:
    the first is the augmented training pool, the second the test-time pool
    (other seeds), as for any augmentation step.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import EPPFTransformer
    >>> from eppf.descriptors import DescriptorPool
    >>> from eppf.preprocessing import RandomScaling
    >>> clouds = [np.random.RandomState(i).normal(size=(200, 3)) for i in range(3)]
    >>> pool = DescriptorPool(EPPFTransformer(n_pairs=500), 3, augment=RandomScaling(), test_draws=2,
    ...                       random_state=0)
    >>> pool.fit_transform(clouds).shape, pool.transform(clouds).shape
    ((3, 3, 1200), (3, 2, 1200))
    """

    def __init__(self, transformer, n_draws=8, *, augment=None, test_draws=None, test_augment=True,
                 share_normals=False, random_state=None):
        self.transformer = transformer
        self.n_draws = n_draws
        self.augment = augment
        self.test_draws = test_draws
        self.test_augment = test_augment
        self.share_normals = share_normals
        self.random_state = random_state

    _parameter_constraints = {
        "transformer": ["no_validation"],  # (its methods and random_state: see _check_params)
        "n_draws": _N_DRAWS,
        "augment": ["no_validation"],
        "test_draws": [*_N_DRAWS, None],
        "test_augment": [Options(bool)],
        "share_normals": [Options(bool)],
        "random_state": RANDOM_STATE,
    }

    def _check_params(self):
        owner = type(self).__name__
        validate_params(self)
        _check_parts(owner, self.transformer, self.augment)
        if self.share_normals:
            self._normal_settings()

    def _normal_settings(self):
        """``(n_neighbors, normal_orientation, n_threads)`` of the transformer's normals, for ``share_normals``."""
        owner = type(self).__name__
        params = self.transformer.get_params(deep=True)
        settings = {}
        for key, value in params.items():
            if key == "n_neighbors" or key.endswith("__n_neighbors"):
                prefix = key[: -len("n_neighbors")]
                # (EPPFGASDTransformer has no normal_orientation: its EPPF block keeps the default)
                settings[prefix or "transformer"] = (value, params.get(prefix + "normal_orientation", "centroid"))
        if not settings:
            raise ValueError(f"{owner}: share_normals=True but the transformer {type(self.transformer).__name__} "
                             "estimates no normals (it has no n_neighbors parameter)")
        if len(set(settings.values())) > 1:
            found = "; ".join(f"{name.rstrip('_')}: n_neighbors={k!r}, normal_orientation={o!r}"
                              for name, (k, o) in settings.items())
            raise ValueError(f"{owner}: share_normals=True needs one normal setting, but the transformer's blocks "
                             f"differ ({found})")
        n_neighbors, orientation = next(iter(settings.values()))
        return int(n_neighbors), orientation, check_n_jobs(params.get("n_jobs"), owner=owner)

    def _with_shared_normals(self, X):
        """The clouds with normals (n_i, 6): their own, or the transformer's PCA normals of the clouds as given."""
        owner = type(self).__name__
        n_neighbors, orientation, n_threads = self._normal_settings()
        clouds = check_packed_clouds(X, owner=owner, n_threads=n_threads)
        if clouds.normals is not None and clouds.has_normals.all():
            return list(clouds)
        points = clouds.points.copy()
        # the normals of the conditioned copy (an exact power of two away: the same normals), as the
        # descriptors estimate them
        condition_point_clouds(clouds, owner=owner)
        normals = points_and_normals(clouds, n_neighbors, orientation, n_threads, owner=owner)[1]
        block = np.hstack([points, normals])
        bounds = clouds.offsets.tolist()
        return [block[a:b] for a, b in zip(bounds[:-1], bounds[1:])]

    def _seeds(self):
        # Columns: descriptor seed and augmentation seed of each training draw, then of each test draw.
        rng = check_random_state(self.random_state)
        n_test = self.n_draws if self.test_draws is None else self.test_draws
        return rng.randint(np.iinfo(np.int32).max, size=(int(self.n_draws), 2)), \
            rng.randint(np.iinfo(np.int32).max, size=(int(n_test), 2))

    def _draws(self, X, transformers, aug_seeds, augment):
        if getattr(self, "share_normals", False):  # (pools pickled before the option existed have none)
            X = self._with_shared_normals(X)
        draws = []
        for r, aug_seed in enumerate(aug_seeds):
            clouds = X
            if augment and self.augment is not None and r > 0:
                clouds = _seed_params(clone(self.augment), aug_seed).fit_transform(X)
            draws.append(np.asarray(transformers[r % len(transformers)].transform(clouds)))
        pool = np.stack(draws, axis=1)
        self.n_features_out_ = pool.shape[2]
        return pool

    def fit(self, X, y=None):
        """Fit one clone of ``transformer`` per draw.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds.
        y : None
            Ignored.

        Returns
        -------
        self : DescriptorPool
            Fitted transformer.
        """
        self._check_params()
        if hasattr(X, "__next__"):
            X = list(X)
        train_seeds, _ = self._seeds()
        self.transformers_ = [_seed_params(clone(self.transformer), s).fit(X) for s, _ in train_seeds]
        return self

    def fit_transform(self, X, y=None):
        """Fit, then return the augmented training pool.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds.
        y : None
            Ignored.

        Returns
        -------
        pool : ndarray of shape (n_objects, n_draws, n_features)
            Draw 0 of the clouds as given, the others of perturbed copies.
        """
        if hasattr(X, "__next__"):
            X = list(X)
        self.fit(X)
        train_seeds, _ = self._seeds()
        return self._draws(X, self.transformers_, train_seeds[:, 1], True)

    def transform(self, X):
        """The test-time pool.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds.

        Returns
        -------
        pool : ndarray of shape (n_objects, test_draws, n_features)
            Draw 0 of the clouds as given; the others perturbed when
            ``test_augment``. Draw ``r`` uses the fitted transformer
            ``r % n_draws``.
        """
        check_is_fitted(self, "transformers_")
        if hasattr(X, "__next__"):
            X = list(X)
        _, test_seeds = self._seeds()
        return self._draws(X, self.transformers_, test_seeds[:, 1], bool(self.test_augment))

    def get_feature_names_out(self, input_features=None):
        """Get the names of the values of every draw (the last axis of the pools).

        Parameters
        ----------
        input_features : None
            Ignored (point clouds have no input feature names).

        Returns
        -------
        feature_names_out : ndarray of str
            The wrapped transformer's names.
        """
        check_is_fitted(self, "transformers_")
        return np.asarray(self.transformers_[0].get_feature_names_out(), dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True  # a list of clouds (an (n, n_points, 3) array is read as one)
        tags.requires_fit = True
        tags.non_deterministic = self.random_state is None
        return tags
