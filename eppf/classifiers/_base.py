"""The scaffolding shared by eppf's skorch classifiers, written once.

:class:`SkorchClassifierBase` holds what :class:`EPPF4DClassifier` and
:class:`PointNetClassifier` have in common: parameter validation (through
``_parameter_constraints``), label encoding and ``classes_``, the seeded and
stratified validation split, early stopping, the learning-rate schedule and
the time budget as skorch callbacks, the per-epoch log, torch thread control
(restored after ``fit`` and ``predict``), the fitted-state attributes and the
mapping of probabilities back to labels. Subclasses fill in the hooks:

``_seed_names``
    Names of the seeds drawn from ``random_state``, in drawing order (the
    first two must be ``"torch"`` and ``"split"``).
``_fit_inputs(X, seeds)``
    Validate and convert the training ``X``; return an array whose first
    axis is the objects.
``_make_datasets(X, y_enc, train_idx, valid_idx, seeds)``
    The training dataset and the validation one (None without early
    stopping).
``_net_params(n_classes, n_train)``
    The ``skorch.NeuralNetClassifier`` arguments that differ: module,
    criterion, optimizer and iterator options.
``_predict_proba(X)``
    Class probabilities of a fitted estimator, through :meth:`_infer`.

The base never subclasses skorch: the network is a ``NeuralNetClassifier``
built in ``fit`` and stored as ``net_``. Nothing here imports torch or skorch
at module level, so ``import eppf`` does not pay for them.
"""

import math
import numbers

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils import check_random_state
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted

from ..utils._param_validation import N_JOBS, RANDOM_STATE, Interval, Options, StrOptions, validate_params
from ..utils._validation import MAX_PARAMETERS, check_n_jobs

__all__ = []


def _silent(*args, **kwargs):
    """Sink for the callbacks' messages when not verbose."""


def _print_line(text):
    """Sink for the callbacks' messages when verbose (not ``print`` itself:
    skorch mutes a ``print`` sink when the net's own ``verbose`` is 0)."""
    print(text, flush=True)


#: Constraints of the parameters every subclass has.
COMMON_CONSTRAINTS = {
    "max_epochs": [Interval(numbers.Integral, 1, None, closed="left")],
    "lr": [Interval(numbers.Real, 0, None, closed="neither")],
    "lr_schedule": [StrOptions(["constant", "plateau"])],
    "batch_size": [Interval(numbers.Integral, 1, None, closed="left")],
    "dropout": [Interval(numbers.Real, 0, 1, closed="left")],
    "early_stopping": [Options(bool)],
    "validation_fraction": [Interval(numbers.Real, 0, 1, closed="neither")],
    "n_iter_no_change": [Interval(numbers.Integral, 1, None, closed="left")],
    "max_time": [None, Interval(numbers.Real, 0, None, closed="neither")],
    "device": [Options(str, description="a str such as 'cpu' or 'cuda'")],
    "n_jobs": N_JOBS,
    "random_state": RANDOM_STATE,
    "verbose": [Interval(numbers.Integral, 0, None, closed="left")],
}


class _torch_threads:
    """Set torch's intra-op thread count for a block; None changes nothing.

    The previous count is restored on exit, also when the block raises.
    """

    def __init__(self, n):
        self.n = n

    def __enter__(self):
        import torch

        self.previous = torch.get_num_threads()
        if self.n is not None:
            torch.set_num_threads(self.n)
        return self

    def __exit__(self, *exc):
        import torch

        if self.n is not None:
            torch.set_num_threads(self.previous)
        return False


def _validation_split(y_enc, n_classes, fraction, seed, owner):
    """Indices of a seeded hold-out of the training objects for early stopping.

    Stratified by class when every class can appear on both sides.
    """
    from sklearn.model_selection import train_test_split

    n = y_enc.shape[0]
    n_valid = int(math.ceil(fraction * n))
    if n_valid < 1 or n - n_valid < 1:
        raise ValueError(
            f"{owner}: validation_fraction={fraction} of {n} objects leaves no "
            "validation or no training objects; use more data or early_stopping=False"
        )
    counts = np.bincount(y_enc, minlength=n_classes)
    stratify = y_enc if (counts.min() >= 2 and n_valid >= n_classes and n - n_valid >= n_classes) else None
    return train_test_split(np.arange(n), test_size=n_valid, random_state=seed, stratify=stratify)


def _interrupted(net, max_epochs):
    """Whether skorch's ``fit`` returned because it caught a ``KeyboardInterrupt`` no callback raised.

    ``NeuralNet.partial_fit`` swallows every ``KeyboardInterrupt``: those of
    early stopping and the time budget, which end training on purpose, and a
    user's Ctrl-C, after which the network is half trained. Training ended
    as planned when one of those callbacks stopped it or when ``max_epochs``
    epochs finished (the epoch timer wrote the last one's duration).
    """
    callbacks = dict(net.callbacks_)
    early = callbacks.get("early_stopping")
    if early is not None and early.misses_ >= early.patience:
        return False
    budget = callbacks.get("time_budget")
    if budget is not None and budget.stopped_:
        return False
    history = net.history
    return not (len(history) == max_epochs and "dur" in history[-1])


class SkorchClassifierBase(ClassifierMixin, BaseEstimator):
    """Base of the skorch-backed classifiers (see the module docstring for the hooks).

    Subclasses define ``__init__`` with their parameters (which must include
    every key of ``COMMON_CONSTRAINTS``), ``_parameter_constraints`` and the
    hooks.
    """

    _parameter_constraints = dict(COMMON_CONSTRAINTS)
    _seed_names = ("torch", "split")
    #: The parameters that set the network's size, named when it would be too large.
    _size_parameters = ()

    # ------------------------------------------------------------------ hooks
    def _check_params(self):
        """Validate the parameters; subclasses may return derived values."""
        validate_params(self)
        self._check_device()

    def _check_device(self):
        """A ValueError naming the estimator when ``device`` names hardware torch cannot use here."""
        import torch

        try:
            device = torch.device(self.device)
        except (RuntimeError, TypeError, ValueError) as exc:
            raise ValueError(f"{self._owner}: device={self.device!r} is not a torch device ({exc})") from None
        if device.type == "cuda" and not torch.cuda.is_available():
            raise ValueError(
                f"{self._owner}: device={self.device!r} but torch sees no CUDA GPU on this machine "
                f"(torch {torch.__version__}, CUDA build: {torch.version.cuda or 'no'}); use device='cpu'"
            )
        if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
            raise ValueError(
                f"{self._owner}: device={self.device!r} but only {torch.cuda.device_count()} CUDA device(s) exist"
            )

    def _parameter_lower_bound(self, n_classes):
        """A lower bound of the network's parameter count, in Python ints (no torch): a network far
        beyond :data:`MAX_PARAMETERS` is refused from it before its exact count is taken, whose layer
        shapes may overflow torch's 64-bit sizes. 0 (the default) always counts exactly."""
        return 0

    def _fit_inputs(self, X, seeds):  # pragma: no cover - abstract
        raise NotImplementedError

    def _make_datasets(self, X, y_enc, train_idx, valid_idx, seeds):  # pragma: no cover - abstract
        raise NotImplementedError

    def _net_params(self, n_classes, n_train):  # pragma: no cover - abstract
        raise NotImplementedError

    def _predict_proba(self, X):  # pragma: no cover - abstract
        raise NotImplementedError

    # ---------------------------------------------------------------- helpers
    @property
    def _owner(self):
        return type(self).__name__

    def _check_network_size(self, n_classes):
        """A ValueError naming the size parameters when the network would have more than
        :data:`MAX_PARAMETERS` parameters; checked before the network (or its data) is built, where
        torch's allocator failed with a RuntimeError ("you tried to allocate 57600000000000 bytes")."""
        n = self._parameter_lower_bound(n_classes)
        exact = n <= MAX_PARAMETERS
        if exact:
            import torch

            from ..nn import count_parameters

            params = self._net_params(n_classes, 0)
            kwargs = {k[len("module__"):]: v for k, v in params.items() if k.startswith("module__")}
            with torch.device("meta"):  # (shapes only: no memory is allocated)
                n = count_parameters(params["module"](**kwargs))
        if n > MAX_PARAMETERS:
            sizes = ", ".join([f"{name}={getattr(self, name)!r}" for name in self._size_parameters]
                              + [f"{n_classes:,} classes"])
            raise ValueError(
                f"{self._owner}: the network would have {'' if exact else 'at least '}{n:,} parameters "
                f"({sizes}), more than the {MAX_PARAMETERS:,} it may have "
                f"({4 * MAX_PARAMETERS / 1e9:g} GB of float32 weights, four times that to train); "
                f"use smaller layers"
            )

    def _n_threads(self):
        """Torch threads for fit and predict, or None to leave torch alone."""
        if self.n_jobs is None:
            return None
        return check_n_jobs(self.n_jobs, owner=self._owner)

    def _sink(self):
        return _print_line if self.verbose else _silent

    def _encode_labels(self, y, n_objects):
        """Check y against the objects; set ``classes_``; return int64 codes."""
        owner = self._owner
        if y is None:  # (np.asarray makes it a 0-d array, which the shape check would name as shape ())
            raise ValueError(f"{owner}: y is None; class labels are needed")
        try:
            y = np.asarray(y)
        except ValueError as exc:  # (ragged nested labels: NumPy's message names neither the estimator nor y)
            raise ValueError(f"{owner}: y must be a 1D sequence of class labels ({exc})") from None
        if y.ndim != 1:
            raise ValueError(f"{owner}: y must be 1D, got shape {y.shape}")
        if y.shape[0] != n_objects:
            raise ValueError(f"{owner}: X has {n_objects} objects but y has {y.shape[0]} labels")
        if y.dtype.kind in "mM" and np.isnat(y).any():  # (NaT, as NaN, is no class; np.unique keeps it as one)
            raise ValueError(f"{owner}: y contains NaT (not-a-time) labels")
        try:
            with np.errstate(invalid="ignore"):  # (scikit-learn's cast of NaN labels warns before it raises)
                check_classification_targets(y)
            classes, y_enc = np.unique(y, return_inverse=True)
        except (ValueError, TypeError) as exc:  # NaN labels; labels of types that do not sort together (str and float)
            kinds = sorted({type(v).__name__ for v in y.tolist()}) if y.dtype == object else [str(y.dtype)]
            # (the plain class, not the caught one's: a subclass's constructor may take other arguments)
            kind = TypeError if isinstance(exc, TypeError) else ValueError
            raise kind(f"{owner}: y must hold class labels of one kind (numbers or strings, no NaN); got "
                       f"{', '.join(kinds)} labels ({exc})") from None
        if classes.shape[0] < 2:
            raise ValueError(f"{owner}: y has a single class {classes[0].tolist()!r}; at least 2 are needed")
        self.classes_ = classes
        return y_enc.astype(np.int64)

    def _callbacks(self, validating):
        """Named skorch callbacks: epoch log, early stopping, LR schedule, time budget."""
        import torch
        from skorch.callbacks import EarlyStopping, LRScheduler

        from ._callbacks import EpochLog, TimeBudget, WeightAveraging

        sink = self._sink()
        callbacks = []
        if self.verbose:
            # First, so that it logs the epoch in which another callback stops training.
            callbacks.append(("epoch_log", EpochLog(sink, int(self.max_epochs))))
        if getattr(self, "swa_epochs", 0):
            # Before early stopping and the time budget, which may end training in on_epoch_end.
            callbacks.append(("weight_averaging", WeightAveraging(int(self.swa_epochs), sink)))
        if validating:
            callbacks.append(
                (
                    "early_stopping",
                    EarlyStopping(monitor="valid_loss", patience=self.n_iter_no_change, load_best=True, sink=sink),
                )
            )
        if self.lr_schedule == "plateau":
            callbacks.append(
                (
                    "lr_scheduler",
                    LRScheduler(
                        policy=torch.optim.lr_scheduler.ReduceLROnPlateau,
                        monitor="valid_loss" if validating else "train_loss",
                        mode="min",
                        factor=0.5,
                        patience=max(1, self.n_iter_no_change // 3),
                    ),
                )
            )
        if self.max_time is not None:
            callbacks.append(("time_budget", TimeBudget(float(self.max_time), sink)))
        return callbacks

    def _infer(self, X):
        """``net_.predict_proba`` under the thread setting, leaving torch's global RNG alone."""
        import torch

        # fork_rng: torch's data loader draws a seed from the global generator
        # even at inference; leave the caller's random stream untouched.
        with _torch_threads(self._n_threads()), torch.random.fork_rng(devices=[]):
            proba = self.net_.predict_proba(X)
            members = getattr(self, "ensemble_nets_", None) or []
            if not members:
                return proba
            # An ensemble: the members' probabilities averaged (float64 sum, fixed order).
            total = proba.astype(np.float64)
            for net in members:
                total += net.predict_proba(X)
            return (total / (1 + len(members))).astype(proba.dtype)

    # -------------------------------------------------------------------- fit
    def fit(self, X, y):
        """Train the network.

        Parameters
        ----------
        X : array-like or list
            Training objects, as the subclass documents.
        y : array-like of shape (n_objects,)
            Class labels, any sortable type.

        Returns
        -------
        self : object
            Fitted estimator.

        Raises
        ------
        KeyboardInterrupt
            On Ctrl-C during training (skorch alone would swallow it and
            return a half-trained network).

        Notes
        -----
        ``fit`` is all or nothing: when it raises (an error found midway,
        a ``KeyboardInterrupt``), the estimator is left exactly as it was
        before the call. A fitted estimator keeps its previous fit, with
        ``classes_``, ``net_`` and every other fitted attribute from that
        one fit; an unfitted one stays unfitted.
        """
        # Every attribute fit sets is set anew (none is changed in place), so the state before the
        # call is its attribute dict, copied: restored on failure, a refit that failed midway left a
        # new classes_ beside the old net_, which then predicted the old classes under the new names.
        before = dict(self.__dict__)
        try:
            return self._fit(X, y)
        except BaseException:
            self.__dict__.clear()
            self.__dict__.update(before)
            raise

    def _fit(self, X, y):
        """``fit``'s work, which may leave the estimator half changed when it raises."""
        self._check_params()
        rng = check_random_state(self.random_state)
        seeds = dict(zip(self._seed_names, (int(s) for s in rng.randint(0, 2**31 - 1, size=len(self._seed_names)))))
        X = self._fit_inputs(X, seeds)
        y_enc = self._encode_labels(y, X.shape[0])
        n_classes = len(self.classes_)
        self._check_network_size(n_classes)

        train_idx = np.arange(X.shape[0])
        valid_idx = None
        if self.early_stopping:
            train_idx, valid_idx = _validation_split(
                y_enc, n_classes, self.validation_fraction, seeds["split"], self._owner
            )
        n_members = int(getattr(self, "n_estimators", 1))
        if n_members > 1:
            self._sink()(f"network 1 of {n_members} of the ensemble")
        self.net_ = self._train_member(X, y_enc, train_idx, valid_idx, seeds, n_classes)
        history = self.net_.history
        self.n_epochs_ = len(history)
        if valid_idx is not None:
            self.best_epoch_ = int(np.argmin(history[:, "valid_loss"])) + 1
        else:
            self.best_epoch_ = self.n_epochs_
        # Further members of an ensemble (``n_estimators`` > 1): the same
        # validation hold-out and standardization, their own weights,
        # minibatch order and draws, seeded after member 0 so that member 0
        # is the network a single-model fit trains.
        self.ensemble_nets_ = []
        for m in range(1, n_members):
            self._sink()(f"network {m + 1} of {n_members} of the ensemble")
            member = dict(zip(self._seed_names, (int(s) for s in rng.randint(0, 2**31 - 1, size=len(self._seed_names)))))
            member["split"] = seeds["split"]
            self.ensemble_nets_.append(self._train_member(X, y_enc, train_idx, valid_idx, member, n_classes))
        return self

    def _train_member(self, X, y_enc, train_idx, valid_idx, seeds, n_classes):
        """One trained skorch network (``fit``'s work for one seed set)."""
        import torch
        from skorch import NeuralNetClassifier
        from skorch.helper import predefined_split

        train_ds, valid_ds = self._make_datasets(X, y_enc, train_idx, valid_idx, seeds)
        params = dict(
            lr=float(self.lr),
            max_epochs=int(self.max_epochs),
            batch_size=int(self.batch_size),
            iterator_train__shuffle=True,
            train_split=None if valid_ds is None else predefined_split(valid_ds),
            callbacks=self._callbacks(valid_ds is not None),
            classes=np.arange(n_classes),
            device=self.device,
            # skorch's own table is off (EpochLog prints one line per epoch);
            # its verbose still lets EarlyStopping say why it stopped.
            callbacks__print_log=None,
            verbose=int(self.verbose),
        )
        params.update(self._net_params(n_classes, train_idx.shape[0]))
        net = NeuralNetClassifier(**params)
        with _torch_threads(self._n_threads()), torch.random.fork_rng(devices=[]):
            torch.manual_seed(seeds["torch"])
            net.fit(train_ds, y=None)
        if _interrupted(net, int(self.max_epochs)):
            # Ctrl-C: end fit as Python would (skorch alone returns a half-trained network,
            # which the next ensemble member, the caller and eppf's commands would take as trained).
            raise KeyboardInterrupt
        averaging = dict(net.callbacks_).get("weight_averaging")
        if averaging is not None:  # after early stopping loaded the best epoch: the average replaces it
            averaging.apply(net)
        # The validation set lives in train_split; drop it so it is not pickled.
        net.train_split = None
        return net

    def _untrained_net(self, n_classes):
        """The skorch network ``fit`` builds for ``n_classes``, initialized but untrained and without
        training callbacks or validation data: what a saved model's weights are loaded into."""
        from skorch import NeuralNetClassifier

        self._check_params()
        self._check_network_size(n_classes)
        params = dict(
            lr=float(self.lr),
            max_epochs=int(self.max_epochs),
            batch_size=int(self.batch_size),
            train_split=None,
            classes=np.arange(n_classes),
            device=self.device,
            verbose=int(self.verbose),
        )
        params.update(self._net_params(n_classes, 0))
        return NeuralNetClassifier(**params).initialize()

    # ---------------------------------------------------------------- predict
    def predict_proba(self, X):
        """Class probabilities.

        Parameters
        ----------
        X : array-like or list
            Objects, as in ``fit``.

        Returns
        -------
        proba : ndarray of shape (n_objects, n_classes)
            Columns follow ``classes_``.
        """
        check_is_fitted(self, "net_")
        return self._predict_proba(X)

    def predict(self, X):
        """Predicted class labels.

        Parameters
        ----------
        X : array-like or list
            Objects, as in ``fit``.

        Returns
        -------
        y : ndarray of shape (n_objects,)
            Labels from ``classes_``.
        """
        proba = self.predict_proba(X)
        return self.classes_[np.argmax(proba, axis=1)]

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.non_deterministic = self.device != "cpu"
        return tags
