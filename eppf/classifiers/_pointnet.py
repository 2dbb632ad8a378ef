"""PointNetClassifier: PointNet (Qi et al. 2017) on raw point clouds, via skorch."""

import numbers

import numpy as np

from ..utils._param_validation import Interval, Options, StrOptions
from ..utils._validation import check_point_clouds, object_seeds
from ._base import COMMON_CONSTRAINTS, SkorchClassifierBase

__all__ = ["PointNetClassifier"]

#: Most points per object ``PointNetClassifier`` feeds its network (``n_points``).
MAX_N_POINTS = 2**24


def _softmax(logits):
    import torch

    return torch.softmax(logits, dim=1)


# ------------------------------------------------------------------ preprocess
def _normalise_and_sample(clouds, n_points, seeds, owner):
    """Center on the bbox center, scale by the largest bbox side, resample.

    A cloud whose bounding box overflows float64 (coordinates near +-1.8e308)
    has no finite side to scale by: ValueError naming ``owner`` and the
    object (clouds of one position are refused before, by their check).

    Clouds with more than ``n_points`` points are subsampled without
    replacement, smaller ones are topped up with replacement (all points kept
    and ``n_points - n`` drawn again), equal ones are kept as they are.
    """
    out = np.empty((len(clouds), n_points, 3), dtype=np.float32)
    for k, cloud in enumerate(clouds):
        xyz = cloud[:, :3]
        lo, hi = xyz.min(axis=0), xyz.max(axis=0)
        with np.errstate(over="ignore"):
            side = (hi - lo).max()
        if not np.isfinite(side):
            raise ValueError(f"{owner}: object {k}'s bounding box overflows float64 (coordinates from "
                             f"{lo.min():.6g} to {hi.max():.6g}): rescale it")
        xyz = (xyz - (lo / 2 + hi / 2)) / side
        n = xyz.shape[0]
        if n != n_points:
            rng = np.random.default_rng(int(seeds[k]))
            if n > n_points:
                idx = rng.choice(n, size=n_points, replace=False)
            else:
                idx = np.concatenate([np.arange(n), rng.integers(0, n, size=n_points - n)])
            xyz = xyz[idx]
        out[k] = xyz
    return out


def _make_dataset(X, y, *, seed, rotation, jitter, scale):
    """The training dataset: clouds augmented afresh on every access (seeded)."""
    from ..nn import AugmentedPointClouds

    return AugmentedPointClouds(X, y, seed, rotation=rotation, jitter=jitter, scale=scale)


# ------------------------------------------------------------------- estimator
class PointNetClassifier(SkorchClassifierBase):
    """PointNet classifier on raw point clouds.

    The classification network of Qi et al. [1]_: a learned 3 x 3 input
    transform, a shared MLP (64, 64), a learned 64 x 64 feature transform
    regularized towards orthogonality, a shared MLP (64, 128, 1024), a global
    max-pool and a dense head 512-256-classes with batch norm and dropout,
    trained with Adam. Used by the paper [2]_ as the raw-point baseline.
    The network is a :mod:`skorch` ``NeuralNetClassifier`` built in ``fit``
    (wrapped, not subclassed); this class adds preprocessing, augmentation,
    label encoding, a validation split for early stopping, a time budget,
    seeding and thread control (the parts shared with
    :class:`EPPF4DClassifier` live in one base class).

    Parameters
    ----------
    n_points : int, default=2048
        Points fed to the network per object (the paper's value). Every
        object is normalized to the unit cube (centered on its bounding-box
        center and divided by the bounding box's largest side), then
        subsampled without replacement when larger, or topped up with points
        drawn with replacement when smaller. At most 2**24 (16,777,216): the
        network's widest layer holds 1,024 values per point, 64 GiB for one
        object of that many.
    max_epochs : int, default=100
        Upper bound on training epochs.
    lr : float, default=1e-3
        Adam learning rate.
    lr_schedule : {"constant", "plateau"}, default="constant"
        ``"constant"`` keeps ``lr`` throughout. ``"plateau"`` halves the
        learning rate whenever the monitored loss (validation loss with early
        stopping, training loss without) has not improved for
        ``max(1, n_iter_no_change // 3)`` epochs.
    batch_size : int, default=32
        Minibatch size.
    dropout : float, default=0.3
        Dropout probability before the last dense layer (keep probability
        0.7, the value of the authors' code).
    reg_weight : float, default=0.001
        Weight of the feature-transform regularizer
        ``||I - A A^T||_F^2`` added to the cross-entropy.
    augment_rotation : {"z", None}, default="z"
        During training, rotate every object by a random angle about the up
        (z) axis on every access; None disables it.
    jitter : bool, default=True
        During training, add Gaussian noise (sigma 0.01, clipped to +-0.05)
        to every coordinate.
    scale_augmentation : bool, default=True
        During training, scale every object by a random factor in
        [0.8, 1.25].
    early_stopping : bool, default=True
        Hold out ``validation_fraction`` of the training objects (stratified,
        drawn from ``random_state``), stop when the validation loss has not
        improved for ``n_iter_no_change`` epochs and keep the weights of the
        best epoch. With False, all training objects are used for
        ``max_epochs`` epochs.
    validation_fraction : float, default=0.1
        Share of the training objects held out when ``early_stopping``.
    n_iter_no_change : int, default=10
        Patience of early stopping, in epochs.
    max_time : float, default=None
        Wall-clock budget of ``fit`` in seconds: training ends after the
        first epoch that finishes past it (with early stopping, the best
        epoch's weights are still the ones kept). None sets no budget; with
        a budget the number of epochs depends on the machine's speed.
    device : str, default="cpu"
        Torch device, e.g. "cpu" or "cuda".
    n_jobs : int, default=None
        Torch threads during ``fit`` and ``predict`` (joblib's meaning: -1 is
        all cores). None leaves torch's setting alone.
    random_state : int, RandomState instance or None, default=None
        Seeds weight initialization, dropout, minibatch order, the
        validation split, point resampling and augmentation. With an int,
        results on CPU are reproducible (the global torch RNG is left as it
        was).
    verbose : int, default=1
        1 or more (the default, as in skorch) prints one line per epoch
        (epoch, training loss, validation loss and accuracy, seconds) and why
        training stopped; 0 prints nothing.

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        Class labels, any sortable type (strings included).
    net_ : skorch.NeuralNetClassifier
        The trained network; ``net_.history`` holds the per-epoch record.
    n_epochs_ : int
        Epochs trained.
    best_epoch_ : int
        Epoch whose weights were kept (1-based; the last one without early
        stopping).

    See Also
    --------
    eppf.EPPF4DClassifier : The paper's network on EPPF descriptors.

    Notes
    -----
    Only the xyz columns are used; six-column clouds have their normals
    ignored. The orthogonality regularizer is added through the loss module
    (:class:`eppf.nn.PointNetLoss`) that receives the network's
    ``(logits, feature_transform)`` output, so skorch is used unchanged.
    The T-Nets start at the identity transform (their last layer has zero
    weights and an identity bias). Resampling in ``predict`` is seeded from
    ``random_state`` and the object's position in ``X``; a cloud with exactly
    ``n_points`` points is used as it is. Training batches of a single object
    are dropped (batch norm needs two).

    References
    ----------
    .. [1] C. R. Qi, H. Su, K. Mo and L. J. Guibas, "PointNet: Deep Learning
       on Point Sets for 3D Classification and Segmentation", CVPR 2017.
    .. [2] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 3(2), 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import PointNetClassifier
    >>> rng = np.random.default_rng(0)
    >>> X = [rng.normal(size=(50, 3)) * [1, 1, 1 + 3 * (i % 2)] for i in range(8)]
    >>> y = ["ball", "stick"] * 4
    >>> clf = PointNetClassifier(n_points=32, max_epochs=1, early_stopping=False,
    ...                          random_state=0, verbose=0).fit(X, y)
    >>> clf.predict(X[:3]).shape
    (3,)
    """

    def __init__(
        self,
        n_points=2048,
        *,
        max_epochs=100,
        lr=1e-3,
        lr_schedule="constant",
        batch_size=32,
        dropout=0.3,
        reg_weight=0.001,
        augment_rotation="z",
        jitter=True,
        scale_augmentation=True,
        early_stopping=True,
        validation_fraction=0.1,
        n_iter_no_change=10,
        max_time=None,
        device="cpu",
        n_jobs=None,
        random_state=None,
        verbose=1,
    ):
        self.n_points = n_points
        self.max_epochs = max_epochs
        self.lr = lr
        self.lr_schedule = lr_schedule
        self.batch_size = batch_size
        self.dropout = dropout
        self.reg_weight = reg_weight
        self.augment_rotation = augment_rotation
        self.jitter = jitter
        self.scale_augmentation = scale_augmentation
        self.early_stopping = early_stopping
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.max_time = max_time
        self.device = device
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.verbose = verbose

    _parameter_constraints = {
        **COMMON_CONSTRAINTS,
        "n_points": [Interval(numbers.Integral, 1, None, closed="left")],
        # Batch norm needs two objects per batch.
        "batch_size": [Interval(numbers.Integral, 2, None, closed="left")],
        "reg_weight": [Interval(numbers.Real, 0, None, closed="left")],
        "augment_rotation": [StrOptions(["z"]), None],
        "jitter": [Options(bool)],
        "scale_augmentation": [Options(bool)],
    }
    _seed_names = ("torch", "split", "augment", "fit_sample", "predict")

    # ------------------------------------------------------------------ hooks
    def _check_params(self):
        super()._check_params()
        # (the network's widest layer holds 1,024 float32 values per point, 64 GiB for an object of
        # MAX_N_POINTS; a larger count failed in NumPy's allocator, resampling, or torch's)
        if self.n_points > MAX_N_POINTS:
            raise ValueError(f"{self._owner}: n_points must be at most 2**24 = {MAX_N_POINTS:,}, got {self.n_points:,}")

    def _prepare(self, X, seed):
        clouds = check_point_clouds(X, owner=self._owner, min_points=2)
        return _normalise_and_sample(clouds, int(self.n_points), object_seeds(seed, len(clouds)), self._owner)

    def _fit_inputs(self, X, seeds):
        pts = self._prepare(X, seeds["fit_sample"])
        self._predict_seed = seeds["predict"]
        return pts

    def _make_datasets(self, X, y_enc, train_idx, valid_idx, seeds):
        from skorch.dataset import Dataset as SkorchDataset

        if train_idx.shape[0] < 2:
            raise ValueError(
                f"{self._owner}: at least 2 training objects are needed (batch norm), got {train_idx.shape[0]}"
            )
        train_ds = _make_dataset(
            X[train_idx], y_enc[train_idx], seed=seeds["augment"], rotation=self.augment_rotation,
            jitter=bool(self.jitter), scale=bool(self.scale_augmentation),
        )
        valid_ds = None if valid_idx is None else SkorchDataset(X[valid_idx], y_enc[valid_idx])
        return train_ds, valid_ds

    def _net_params(self, n_classes, n_train):
        import torch

        from ..nn import PointNet, PointNetLoss

        return dict(
            module=PointNet,
            module__n_classes=n_classes,
            module__dropout=float(self.dropout),
            criterion=PointNetLoss,
            criterion__reg_weight=float(self.reg_weight),
            optimizer=torch.optim.Adam,
            # A last batch of one object would break batch norm: drop it then.
            iterator_train__drop_last=n_train % int(self.batch_size) == 1,
            predict_nonlinearity=_softmax,
        )

    def _predict_proba(self, X):
        return self._infer(self._prepare(X, self._predict_seed))

    # ------------------------------------------------------------ public API
    def fit(self, X, y):
        """Train PointNet on point clouds.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds; only the xyz columns are used.
        y : array-like of shape (n_objects,)
            Class labels, any sortable type.

        Returns
        -------
        self : PointNetClassifier
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
        """Class probabilities.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds; only the xyz columns are used.

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
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds; only the xyz columns are used.

        Returns
        -------
        y : ndarray of shape (n_objects,)
            Labels from ``classes_``.
        """
        return super().predict(X)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True  # a list of clouds, or an (n_objects, n_points, 3) array
        return tags


def __getattr__(name):
    # The torch modules lived here until they moved to eppf.nn; models pickled
    # then name eppf.classifiers._pointnet.PointNet etc. Resolved lazily so that
    # importing this module needs no torch.
    if name in ("TNet", "PointNet", "PointNetLoss", "orthogonality_penalty"):
        from ..nn._pointnet import PointNet, PointNetLoss, TNet, orthogonality_penalty

        return {"TNet": TNet, "PointNet": PointNet, "PointNetLoss": PointNetLoss,
                "orthogonality_penalty": orthogonality_penalty}[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
