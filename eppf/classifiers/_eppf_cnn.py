"""EPPF4DClassifier: the paper's 2D/3D/4D networks on EPPF descriptors, via skorch."""

import functools
import math
import numbers

import numpy as np

from ..utils._param_validation import Interval, IntTuple, Options, StrOptions
from ._base import COMMON_CONSTRAINTS, SkorchClassifierBase

__all__ = ["EPPF4DClassifier"]


class EPPF4DClassifier(SkorchClassifierBase):
    """The paper's convolutional classifier on EPPF descriptors.

    Trains the 4D network of Bobkov et al. (two 4D convolutions, a 2D
    convolution, max-pool, dense 1024, dropout, dense) or its 2D and 3D
    comparison variants on flat EPPF histograms, with Adam as in the paper.
    The network is a :mod:`skorch` ``NeuralNetClassifier`` built in ``fit``
    (wrapped, not subclassed); this class adds label encoding, input
    standardization, a validation split taken from the training data for
    early stopping, a time budget, seeding and thread control (the parts
    shared with :class:`PointNetClassifier` live in one base class).

    Parameters
    ----------
    n_bins : tuple of 4 ints, default=(20, 4, 5, 3)
        Histogram bins along (f1, f2, f3, f4). Descriptors must have
        ``prod(n_bins)`` columns in C order over (f1, f2, f3, f4), f4 fastest,
        as :class:`eppf.descriptors.EPPFTransformer` writes them; use (15, 3, 4, 3) for
        "EPPF short".
    conv : {"4d", "3d", "2d"}, default="4d"
        Network variant: :class:`eppf.nn.EPPFNet4D`,
        :class:`eppf.nn.EPPFNet3D` or :class:`eppf.nn.EPPFNet2D`.
    max_epochs : int, default=100
        Upper bound on training epochs (the paper trained 2,000 epochs on a
        GPU; early stopping usually ends far sooner).
    lr : float, default=5e-4
        Adam learning rate (the paper's value).
    lr_schedule : {"constant", "plateau"}, default="constant"
        ``"constant"`` keeps ``lr`` throughout (the paper). ``"plateau"``
        halves the learning rate whenever the monitored loss (validation
        loss with early stopping, training loss without) has not improved
        for ``max(1, n_iter_no_change // 3)`` epochs.
    batch_size : int, default=64
        Minibatch size.
    dropout : float, default=0.5
        Dropout probability before the last dense layer (the paper's value).
    weight_decay : float, default=0.0
        Adam's L2 penalty.
    n_hidden : int, default=1024
        Units of the first dense layer.
    filters : tuple of 3 ints, default=(32, 64, 48)
        Filters of the three convolutions (Table I). With ``n_bins``,
        ``n_hidden``, ``side_hidden`` and the number of classes they set the
        network's size, which may be at most a billion parameters
        (``eppf.utils._validation.MAX_PARAMETERS``; the paper's network has
        15 million): a larger one is refused in ``fit`` before it is built.
    early_stopping : bool, default=True
        Hold out ``validation_fraction`` of the training objects (stratified,
        drawn from ``random_state``), stop when the validation loss has not
        improved for ``n_iter_no_change`` epochs and keep the weights of the
        best epoch. With False, all training objects are used for
        ``max_epochs`` epochs. The test set is never involved either way.
    validation_fraction : float, default=0.1
        Share of the training objects held out when ``early_stopping``.
    n_iter_no_change : int, default=10
        Patience of early stopping, in epochs.
    max_time : float, default=None
        Wall-clock budget of ``fit`` in seconds: training ends after the
        first epoch that finishes past it (with early stopping, the best
        epoch's weights are still the ones kept). None sets no budget. The
        number of epochs then depends on the machine's speed, so a run with
        a budget is reproducible only as far as it trains the same epochs.
    input_scaling : {"global", "bin", "none"}, default="global"
        Standardization learned in ``fit``. EPPF histograms sum to 1, so their
        values are tiny (mean ``1 / prod(n_bins)``). ``"global"`` subtracts the
        mean and divides by the standard deviation of all training values
        (one pair of numbers, so the histogram's shape is kept); ``"bin"``
        standardizes every bin on its own (as sklearn's ``StandardScaler``;
        amplifies rarely filled bins); ``"none"`` feeds values as they are.
    n_side_features : int or "auto", default=0
        Side features after the ``prod(n_bins)`` bins of every row (beyond
        the paper): e.g. GASD and :class:`eppf.descriptors.ProportionTransformer`
        columns of a :class:`eppf.descriptors.DescriptorUnion` that starts
        with EPPF. They are standardized column by column and pass a dense
        branch of ``side_hidden`` ReLU units that joins the flattened
        convolution features at the first dense layer. ``"auto"`` takes
        every column after the bins; 0 (Table I) refuses extra columns.
    side_hidden : int, default=128
        Units of the side branch.
    batch_norm : bool, default=False
        Batch normalization between every convolution and its ReLU.
    label_smoothing : float, default=0.0
        Label smoothing of the cross-entropy loss, in [0, 1).
    conv_impl : {"auto", "direct", "spectral"}, default="auto"
        How the 4D network (``conv="4d"``) computes its convolutions:
        directly or the same convolutions in the frequency domain (equal up
        to rounding; see :class:`eppf.nn.EPPFNet4D`). ``"auto"`` chooses per
        layer: in float32 the frequency domain for the paper's wide layers,
        and in training for the recommended recipe's narrower ones too
        (which predict directly); direct under bfloat16 and for the
        single-channel first layer. Ignored by the 3D and 2D networks.
    n_estimators : int, default=1
        Networks trained (beyond the paper): with more than one, ``fit``
        trains a small ensemble, every member on the same validation
        hold-out and standardization but with its own weight initialization,
        minibatch order and descriptor draws (seeded from ``random_state``
        after the first member, which is the network a single-model fit
        trains), and ``predict_proba`` averages the members' probabilities.
        ``fit`` and prediction take ``n_estimators`` times as long;
        ``max_time`` is a budget per member.
    swa_epochs : int, default=0
        Stochastic weight averaging (beyond the paper): with ``k > 0``, the
        network keeps the mean of the weights of the last ``k`` epochs it
        trained (with early stopping, the epochs up to the one that ended
        training, patience included) instead of the best epoch's weights.
        One network of averaged weights costs one training and predicts
        like one network, where an ensemble costs ``n_estimators`` of each.
        0 keeps the best (or last) epoch's weights.
    precision : {"auto", "float32", "bfloat16"}, default="auto"
        Arithmetic of the network. ``"bfloat16"`` trains and predicts in
        mixed precision (:func:`torch.autocast`): convolutions and dense
        layers multiply in bfloat16, while weights, gradients, Adam's state,
        the loss and the returned probabilities stay float32. On CPUs with
        native bfloat16 (AVX512_BF16 or AMX-BF16 on x86: AMD Zen 4 and later,
        Intel Cooper Lake, Sapphire Rapids and later; BF16 on ARM) an epoch
        of the 4D network is faster than in float32 (timings: the
        documentation's Performance page, "CNN training"); on other CPUs
        PyTorch emulates bfloat16 and an epoch takes several times as long, so
        asking for it there warns (:class:`eppf.nn.BFloat16EmulationWarning`,
        once per process). ``"auto"`` chooses bfloat16 where the device
        computes it natively (such a CPU, or a CUDA GPU of compute
        capability 8.0 or later) and float32 elsewhere
        (:func:`eppf.nn.resolve_precision`); the choice is ``precision_``.
        Accuracy is unchanged within run-to-run spread on our benchmarks,
        but bfloat16 predictions are not bit-identical to float32 ones, so
        with ``"auto"`` one seed gives other bits on machines that choose
        differently; pass ``"float32"`` for results that do not depend on
        the hardware.
    device : str, default="cpu"
        Torch device.
    n_jobs : int, default=None
        Torch threads during ``fit`` and ``predict`` (joblib's meaning:
        -1 is all cores). None leaves torch's setting alone, which follows
        ``OMP_NUM_THREADS``; joblib sets that variable in its workers, so
        ``GridSearchCV(n_jobs=k)`` does not oversubscribe.
    random_state : int, RandomState instance or None, default=None
        Seeds weight initialization, dropout, minibatch order, the
        validation split and the choice of descriptor draws. With an int,
        results on CPU are reproducible (the global torch RNG is left as it
        was).
    verbose : int, default=1
        1 or more (the default, as in skorch) prints one line per epoch
        (epoch, training loss, validation loss and accuracy, seconds) and why
        training stopped; 0 prints nothing. With an ensemble, a line
        announces each network ("network 1 of 3 of the ensemble").

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        Class labels, any sortable type (strings included).
    n_features_in_ : int
        ``prod(n_bins)`` plus the side features.
    n_side_features_ : int
        Side features per row (0 without).
    side_mean_ : ndarray of shape (``n_side_features_``,)
        Subtracted from the side features.
    side_scale_ : ndarray of shape (``n_side_features_``,)
        Divides the centered side features.
    n_draws_fit_ : int
        Descriptor draws per object seen in ``fit`` (1 for a 2D ``X``).
    precision_ : {"float32", "bfloat16"}
        The arithmetic the network was trained in and predicts in:
        ``precision`` with ``"auto"`` resolved for ``device``. Saved with the
        model; models saved before it existed lack it and run in their
        ``precision``.
    input_mean_ : ndarray of shape (1,) or (n_features,)
        Subtracted from the descriptors.
    input_scale_ : ndarray of shape (1,) or (n_features,)
        Divides the centered descriptors.
    net_ : skorch.NeuralNetClassifier
        The trained network (the first member of an ensemble);
        ``net_.history`` holds the per-epoch record.
    ensemble_nets_ : list of skorch.NeuralNetClassifier
        The other ``n_estimators - 1`` members (empty for one network).
    n_epochs_ : int
        Epochs trained (by ``net_``).
    best_epoch_ : int
        Epoch whose weights were kept (1-based; the last one without early
        stopping), of ``net_``.

    See Also
    --------
    eppf.EPPFTransformer : Computes the descriptors.
    eppf.nn.EPPFNet4D : The network.

    Notes
    -----
    Descriptor pools (augmentation beyond the paper): ``X`` may be a 3D
    array of shape (n_objects, n_draws, n_features), ``n_draws`` descriptors
    of every object computed with different random pairs, as
    :func:`eppf.descriptors.descriptor_pool` makes them. In ``fit`` every epoch draws
    one of them per object afresh; validation uses the first draw. In
    ``predict_proba`` the class probabilities are averaged over the draws
    (test-time averaging). Pools whose training draws describe slightly
    stretched copies of the clouds (``descriptor_pool(...,
    augment=RandomScaling())``, see :class:`eppf.preprocessing.RandomScaling`)
    generalize better still (test accuracies on ModelNet10: the
    documentation's Performance page, "CNN training").

    Side features (beyond the paper): the EPPF histogram is scaled per
    object and rotation invariant, so it hardly sees an object's size and
    proportions, which tell ModelNet10's dresser from night stand and table
    from desk. Rows of EPPF followed by GASD and six proportion ratios,
    drawn per pool member from the same stretched cloud, with a smaller
    network (``filters=(16, 32, 24), n_hidden=256``), classify ModelNet10
    better at the same training time; this is the recommended recipe for
    such objects ("EPPF 4D+" of ``eppf experiment classification``, ``eppf
    train --recipe recommended``). On small, data-set scaled objects such
    as DALES's a single such network can do worse than the paper's network
    and the KL 1-NN.

    Ensembles, weight averaging and label smoothing (beyond the paper):
    averaging networks of different seeds (``n_estimators``) and
    ``label_smoothing=0.1`` each made that network more accurate on DALES
    objects, ``batch_norm=True`` did not; with label smoothing, neither an
    ensemble nor ``swa_epochs`` was more accurate than one network on
    validation data, so the recommended recipe trains one network with label
    smoothing 0.1. The figures of both paragraphs are in the documentation's
    "Reproducing the paper" page ("Classification beyond the paper: EPPF
    4D+").

    The Table I reading (same padding, layer sizes, dense input of 14,400
    for 1,200 bins) is documented in ``eppf.nn``.

    References
    ----------
    .. [1] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 3(2), 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import EPPF4DClassifier
    >>> rng = np.random.default_rng(0)
    >>> X = rng.dirichlet(np.ones(12), size=40)
    >>> y = np.where(X[:, 0] > X[:, 1], "a", "b")
    >>> clf = EPPF4DClassifier(n_bins=(2, 2, 3, 1), max_epochs=2, n_hidden=8,
    ...                        early_stopping=False, random_state=0, verbose=0).fit(X, y)
    >>> clf.predict(X[:3]).shape
    (3,)
    """

    def __init__(
        self,
        n_bins=(20, 4, 5, 3),
        conv="4d",
        *,
        max_epochs=100,
        lr=5e-4,
        lr_schedule="constant",
        batch_size=64,
        dropout=0.5,
        weight_decay=0.0,
        n_hidden=1024,
        filters=(32, 64, 48),
        early_stopping=True,
        validation_fraction=0.1,
        n_iter_no_change=10,
        max_time=None,
        input_scaling="global",
        n_side_features=0,
        side_hidden=128,
        batch_norm=False,
        label_smoothing=0.0,
        conv_impl="auto",
        n_estimators=1,
        swa_epochs=0,
        precision="auto",
        device="cpu",
        n_jobs=None,
        random_state=None,
        verbose=1,
    ):
        self.n_bins = n_bins
        self.conv = conv
        self.max_epochs = max_epochs
        self.lr = lr
        self.lr_schedule = lr_schedule
        self.batch_size = batch_size
        self.dropout = dropout
        self.weight_decay = weight_decay
        self.n_hidden = n_hidden
        self.filters = filters
        self.early_stopping = early_stopping
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.max_time = max_time
        self.input_scaling = input_scaling
        self.n_side_features = n_side_features
        self.side_hidden = side_hidden
        self.batch_norm = batch_norm
        self.label_smoothing = label_smoothing
        self.conv_impl = conv_impl
        self.n_estimators = n_estimators
        self.swa_epochs = swa_epochs
        self.precision = precision
        self.device = device
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.verbose = verbose


    _parameter_constraints = {
        **COMMON_CONSTRAINTS,
        "n_bins": [IntTuple(4, 1, None, description="a tuple of 4 positive ints")],
        "conv": [StrOptions(["4d", "3d", "2d"])],
        "weight_decay": [Interval(numbers.Real, 0, None, closed="left")],
        "n_hidden": [Interval(numbers.Integral, 1, None, closed="left")],
        "filters": [IntTuple(3, 1, None, description="a tuple of 3 positive ints")],
        "input_scaling": [StrOptions(["global", "bin", "none"])],
        "precision": [StrOptions(["auto", "float32", "bfloat16"])],
        "n_side_features": [Interval(numbers.Integral, 0, None, closed="left"), StrOptions(["auto"])],
        "side_hidden": [Interval(numbers.Integral, 1, None, closed="left")],
        "batch_norm": [Options(bool)],
        "label_smoothing": [Interval(numbers.Real, 0, 1, closed="left")],
        "conv_impl": [StrOptions(["auto", "direct", "spectral"])],
        "n_estimators": [Interval(numbers.Integral, 1, None, closed="left")],
        "swa_epochs": [Interval(numbers.Integral, 0, None, closed="left")],
    }
    _seed_names = ("torch", "split", "draws")
    _size_parameters = ("n_bins", "filters", "n_hidden", "side_hidden")

    # ------------------------------------------------------------------ hooks
    def _check_params(self):
        super()._check_params()
        self._n_bins = tuple(int(b) for b in self.n_bins)

    def _parameter_lower_bound(self, n_classes):
        from ..nn._networks import parameter_lower_bound

        return parameter_lower_bound(self._n_bins, self.n_hidden, n_classes, self.filters,
                                     getattr(self, "n_side_features_", 0), self.side_hidden)

    def _validate_X(self, X, n_features, n_side=0):
        """Return X as float32 of shape (n_objects, n_draws, n_features + n_side)."""
        owner = self._owner
        if X is None or isinstance(X, (str, bytes, dict)):
            raise TypeError(f"{owner}: X must be an array of descriptors, got {type(X).__name__}")
        try:
            arr = np.asarray(X)
        except Exception as exc:
            raise ValueError(f"{owner}: X could not be converted to an array: {exc}") from None
        if arr.dtype == object and arr.ndim == 0:  # a sparse matrix, a generator: not a sequence of rows
            hint = " (dense descriptors are needed: use X.toarray())" if hasattr(X, "toarray") else ""
            raise TypeError(f"{owner}: X must be an array of descriptors, got {type(X).__name__}{hint}")
        if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
            raise TypeError(f"{owner}: X must hold numbers, got dtype {arr.dtype}")
        if np.iscomplexobj(arr):  # (a cast to float32 would drop the imaginary parts with a ComplexWarning)
            raise TypeError(f"{owner}: X must hold real numbers, got dtype {arr.dtype}")
        if arr.ndim == 2:
            arr = arr[:, None, :]
        elif arr.ndim != 3:
            raise ValueError(
                f"{owner}: X must have shape (n_objects, n_features) or (n_objects, n_draws, n_features), "
                f"got shape {arr.shape}"
            )
        if arr.shape[0] == 0 or arr.shape[1] == 0:
            raise ValueError(f"{owner}: X is empty (shape {arr.shape})")
        if n_side == "auto":
            if arr.shape[2] < n_features:
                raise ValueError(
                    f"{owner}: descriptors have {arr.shape[2]} values but n_bins={tuple(self.n_bins)} needs at least "
                    f"{n_features} (the descriptor's bins, then the side features); pass the n_bins the "
                    "descriptors were computed with"
                )
        elif arr.shape[2] != n_features + n_side:
            side = f" + n_side_features={n_side}" if n_side else ""
            raise ValueError(
                f"{owner}: descriptors have {arr.shape[2]} values but n_bins={tuple(self.n_bins)}{side} needs "
                f"{n_features + n_side}; pass the n_bins the descriptors were computed with"
                + (" (or n_side_features for extra columns)" if not n_side else "")
            )
        with np.errstate(over="ignore"):  # (values beyond float32 become inf: named below)
            out = arr.astype(np.float32)
        if not np.isfinite(out).all():
            if np.isfinite(arr).all():
                raise ValueError(f"{owner}: X holds values beyond float32's range (largest magnitude "
                                 f"{np.abs(arr).max():.6g}; the networks compute in float32): rescale the descriptors")
            raise ValueError(f"{owner}: X contains NaN or infinite values")
        return out

    def _fit_inputs(self, X, seeds):
        from ..nn import resolve_precision

        n_bins = math.prod(self._n_bins)
        X = self._validate_X(X, n_bins, self.n_side_features)
        self.n_side_features_ = X.shape[2] - n_bins
        self.n_features_in_ = X.shape[2]
        self.n_draws_fit_ = X.shape[1]
        self.precision_ = resolve_precision(self.precision, self.device, owner=self._owner)
        return X

    def _check_X(self, X):
        """A fitted estimator's input as float32 (n_objects, n_draws, n_features_in_)."""
        n_side = getattr(self, "n_side_features_", 0)
        return self._validate_X(X, self.n_features_in_ - n_side, n_side)

    def _standardise(self, X):
        n_side = getattr(self, "n_side_features_", 0)
        if not n_side:
            return (X - self.input_mean_) / self.input_scale_
        n = X.shape[-1] - n_side
        out = np.empty_like(X)
        out[..., :n] = (X[..., :n] - self.input_mean_) / self.input_scale_
        out[..., n:] = (X[..., n:] - self.side_mean_) / self.side_scale_
        return out

    def _make_datasets(self, X, y_enc, train_idx, valid_idx, seeds):
        from ..nn import DescriptorPoolDataset

        n_side = self.n_side_features_
        n_features = self.n_features_in_ - n_side
        # Side features are standardized column by column whatever input_scaling says.
        side = X[train_idx][..., n_features:].reshape(-1, max(n_side, 1)).astype(np.float64)
        self.side_mean_ = side.mean(axis=0).astype(np.float32) if n_side else np.zeros(0, np.float32)
        self.side_scale_ = side.std(axis=0).astype(np.float32) if n_side else np.ones(0, np.float32)
        self.side_scale_[~(self.side_scale_ > 0)] = 1.0
        X_bins = X[..., :n_features]
        if self.input_scaling == "global":
            values = X_bins[train_idx].astype(np.float64)
            self.input_mean_ = np.array([values.mean()], dtype=np.float32)
            self.input_scale_ = np.array([values.std()], dtype=np.float32)
        elif self.input_scaling == "bin":
            values = X_bins[train_idx].reshape(-1, n_features).astype(np.float64)
            self.input_mean_ = values.mean(axis=0).astype(np.float32)
            self.input_scale_ = values.std(axis=0).astype(np.float32)
        else:
            self.input_mean_ = np.zeros(1, dtype=np.float32)
            self.input_scale_ = np.ones(1, dtype=np.float32)
        self.input_scale_[~(self.input_scale_ > 0)] = 1.0
        Xs = self._standardise(X)
        train_ds = DescriptorPoolDataset(Xs[train_idx], y_enc[train_idx], seeds["draws"])
        valid_ds = None
        if valid_idx is not None:
            # Validation always sees the first draw of every object.
            valid_ds = DescriptorPoolDataset(Xs[valid_idx][:, :1], y_enc[valid_idx], 0)
        return train_ds, valid_ds

    def _net_params(self, n_classes, n_train):
        import torch

        from ..nn import EPPFNet2D, EPPFNet3D, EPPFNet4D

        # A model saved before conv_impl existed runs "auto" (the same results up to rounding).
        conv_impl = {"module__conv_impl": getattr(self, "conv_impl", "auto")} if self.conv == "4d" else {}
        return dict(
            **conv_impl,
            module={"4d": EPPFNet4D, "3d": EPPFNet3D, "2d": EPPFNet2D}[self.conv],
            module__n_bins=self._n_bins,
            module__n_classes=n_classes,
            module__dropout=float(self.dropout),
            module__n_hidden=int(self.n_hidden),
            module__filters=tuple(int(f) for f in self.filters),
            module__precision=self._precision_in_use(),
            module__n_side=int(getattr(self, "n_side_features_", 0)),
            module__side_hidden=int(self.side_hidden),
            module__batch_norm=bool(self.batch_norm),
            criterion=torch.nn.CrossEntropyLoss,
            criterion__label_smoothing=float(self.label_smoothing),
            optimizer=torch.optim.Adam,
            optimizer__weight_decay=float(self.weight_decay),
            # One fused kernel instead of a dozen passes over the 15 M
            # parameters: the same Adam update, 8x faster on CPU.
            optimizer__fused=_fused_adam(torch.device(self.device).type),
        )

    def _precision_in_use(self):
        """``precision_`` once fitted (or loaded); a model saved before it existed runs in its ``precision``."""
        precision = getattr(self, "precision_", None)
        if precision is None:
            from ..nn import resolve_precision

            precision = resolve_precision(self.precision, self.device, owner=self._owner)
        return precision

    def _predict_proba(self, X):
        X = self._check_X(X)
        n, k, f = X.shape
        proba = self._infer(self._standardise(X.reshape(n * k, f)))
        return proba.reshape(n, k, -1).mean(axis=1)

    # ------------------------------------------------------------ public API
    def fit(self, X, y):
        """Train the network on descriptors.

        Parameters
        ----------
        X : array-like of shape (n_objects, n_features) or (n_objects, n_draws, n_features)
            EPPF descriptors, ``n_features == prod(n_bins)``; a 3D array is a
            pool of draws per object (see Notes).
        y : array-like of shape (n_objects,)
            Class labels, any sortable type.

        Returns
        -------
        self : EPPF4DClassifier
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
        return super().fit(X, y)

    def predict_proba(self, X):
        """Class probabilities, averaged over descriptor draws for a 3D ``X``.

        Parameters
        ----------
        X : array-like of shape (n_objects, n_features) or (n_objects, n_draws, n_features)
            Descriptors computed as in ``fit``.

        Returns
        -------
        proba : ndarray of shape (n_objects, n_classes)
            Columns follow ``classes_``.
        """
        return super().predict_proba(X)

    def predict(self, X):
        """Predicted class labels.

        Parameters
        ----------
        X : array-like of shape (n_objects, n_features) or (n_objects, n_draws, n_features)
            Descriptors computed as in ``fit``.

        Returns
        -------
        y : ndarray of shape (n_objects,)
            Labels from ``classes_``.
        """
        return super().predict(X)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.three_d_array = True
        return tags


@functools.lru_cache(maxsize=None)
def _fused_adam(device_type):
    """Whether torch's fused Adam runs on ``device_type``: on CUDA, and on the CPU from torch 2.4."""
    if device_type == "cuda":
        return True
    if device_type != "cpu":
        return False
    import torch

    try:
        torch.optim.Adam([torch.zeros(1, requires_grad=True)], fused=True)
    except RuntimeError:  # torch < 2.4: "`fused=True` requires ... devices: ['cuda', ...]"
        return False
    return True


def __getattr__(name):
    # Models pickled before the callbacks moved name eppf.classifiers._eppf_cnn._TimeBudget;
    # resolve it lazily so that importing this module needs no skorch.
    if name == "_TimeBudget":
        from ._callbacks import TimeBudget

        return TimeBudget
    if name in ("_silent", "_torch_threads", "_validation_split"):  # names 0.1 code and pickles use
        from . import _base

        return getattr(_base, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
