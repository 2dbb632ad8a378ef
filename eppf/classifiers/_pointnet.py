"""PointNetClassifier: PointNet (Qi et al. 2017) on raw point clouds, via skorch."""

import functools
import math
import numbers

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils import check_random_state
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted

from ._eppf_cnn import _check_float as _cnn_check_float
from ._eppf_cnn import _check_int as _cnn_check_int
from ._eppf_cnn import _silent, _torch_threads, _validation_split
from ..utils._validation import check_point_clouds, object_seeds

__all__ = ["PointNetClassifier"]

_OWNER = "PointNetClassifier"
_ROTATIONS = ("z", None)


# The descriptor CNN's parameter checks, with this estimator's name in their messages.
_check_int = functools.partial(_cnn_check_int, owner=_OWNER)
_check_float = functools.partial(_cnn_check_float, owner=_OWNER)


def _check_bool(name, value):
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{_OWNER}: {name} must be True or False, got {value!r}")
    return bool(value)


# ---------------------------------------------------------------------- modules
def _torch_modules():
    """Build the module classes lazily so that importing eppf needs no torch."""
    import torch
    from torch import nn

    class TNet(nn.Module):
        """Predicts a ``k x k`` transform from a (batch, k, n_points) input.

        Shared MLP (64, 128, 1024), max-pool, dense 512-256-k*k with batch
        norm. The last layer starts with zero weights and the identity as
        bias, so the predicted transform is exactly the identity at
        initialisation (as in the reference implementation).
        """

        def __init__(self, k):
            super().__init__()
            self.k = k
            self.features = nn.Sequential(
                nn.Conv1d(k, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
                nn.Conv1d(64, 128, 1), nn.BatchNorm1d(128), nn.ReLU(),
                nn.Conv1d(128, 1024, 1), nn.BatchNorm1d(1024), nn.ReLU(),
            )
            self.head = nn.Sequential(
                nn.Linear(1024, 512), nn.BatchNorm1d(512), nn.ReLU(),
                nn.Linear(512, 256), nn.BatchNorm1d(256), nn.ReLU(),
            )
            self.out = nn.Linear(256, k * k)
            nn.init.zeros_(self.out.weight)
            with torch.no_grad():
                self.out.bias.copy_(torch.eye(k).flatten())

        def forward(self, x):
            g = self.features(x).max(dim=2).values
            return self.out(self.head(g)).view(-1, self.k, self.k)

    class PointNet(nn.Module):
        """PointNet classification network on (batch, n_points, 3) input.

        Returns ``(logits, feature_transform)``: the logits of shape
        (batch, n_classes) and the 64 x 64 feature transform of shape
        (batch, 64, 64) that the orthogonality regulariser needs.
        """

        def __init__(self, n_classes, dropout=0.3):
            super().__init__()
            self.input_tnet = TNet(3)
            self.mlp1 = nn.Sequential(
                nn.Conv1d(3, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
                nn.Conv1d(64, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
            )
            self.feature_tnet = TNet(64)
            self.mlp2 = nn.Sequential(
                nn.Conv1d(64, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
                nn.Conv1d(64, 128, 1), nn.BatchNorm1d(128), nn.ReLU(),
                nn.Conv1d(128, 1024, 1), nn.BatchNorm1d(1024), nn.ReLU(),
            )
            self.head = nn.Sequential(
                nn.Linear(1024, 512), nn.BatchNorm1d(512), nn.ReLU(),
                nn.Linear(512, 256), nn.BatchNorm1d(256), nn.ReLU(),
                nn.Dropout(p=dropout),
                nn.Linear(256, n_classes),
            )

        def forward(self, X):
            x = X.transpose(1, 2)  # (batch, 3, n_points)
            x = torch.bmm(self.input_tnet(x), x)
            x = self.mlp1(x)
            feat = self.feature_tnet(x)
            x = torch.bmm(feat, x)
            g = self.mlp2(x).max(dim=2).values
            return self.head(g), feat

    class PointNetLoss(nn.Module):
        """Cross-entropy plus ``reg_weight * mean ||I - A A^T||_F^2``.

        Takes the network's ``(logits, feature_transform)`` pair as
        prediction, so skorch adds the regulariser to every training and
        validation loss without a custom ``get_loss``.
        """

        def __init__(self, reg_weight=0.001):
            super().__init__()
            self.reg_weight = reg_weight
            self.ce = nn.CrossEntropyLoss()

        def forward(self, y_pred, y_true):
            logits, feat = y_pred
            return self.ce(logits, y_true) + self.reg_weight * orthogonality_penalty(feat)

    def orthogonality_penalty(A):
        """Batch mean of the squared Frobenius norm of ``I - A A^T``."""
        eye = torch.eye(A.shape[-1], dtype=A.dtype, device=A.device)
        diff = eye - torch.bmm(A, A.transpose(1, 2))
        return (diff**2).sum(dim=(1, 2)).mean()

    built = (TNet, PointNet, PointNetLoss, orthogonality_penalty)
    # Make the classes importable as eppf._pointnet.<name> so that pickle
    # (and skorch's pickling of ``net_``) finds them.
    for obj in built:
        obj.__qualname__ = obj.__name__
        obj.__module__ = __name__
        globals()[obj.__name__] = obj
    return built


_MODULES = None


def _modules():
    global _MODULES
    if _MODULES is None:
        _MODULES = _torch_modules()
    return _MODULES


def __getattr__(name):
    # Expose the torch modules as eppf._pointnet.TNet etc. without importing
    # torch when eppf is imported.
    names = ("TNet", "PointNet", "PointNetLoss", "orthogonality_penalty")
    if name in names:
        return _modules()[names.index(name)]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _softmax(logits):
    import torch

    return torch.softmax(logits, dim=1)


# ------------------------------------------------------------------ preprocess
def _normalise_and_sample(clouds, n_points, seeds):
    """Centre on the bbox centre, scale by the largest bbox side, resample.

    Clouds with more than ``n_points`` points are subsampled without
    replacement, smaller ones are topped up with replacement (all points kept
    and ``n_points - n`` drawn again), equal ones are kept as they are.
    """
    out = np.empty((len(clouds), n_points, 3), dtype=np.float32)
    for k, cloud in enumerate(clouds):
        xyz = cloud[:, :3]
        lo, hi = xyz.min(axis=0), xyz.max(axis=0)
        xyz = (xyz - (lo + hi) / 2) / (hi - lo).max()
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
    import torch
    from torch.utils.data import Dataset

    class AugmentedClouds(Dataset):
        """Training clouds augmented afresh on every access (seeded)."""

        def __init__(self):
            self.rng = np.random.default_rng(seed)

        def __len__(self):
            return X.shape[0]

        def __getitem__(self, i):
            pts = X[i].astype(np.float64)
            rng = self.rng
            if rotation == "z":
                a = rng.uniform(0.0, 2 * np.pi)
                c, s = np.cos(a), np.sin(a)
                rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
                pts = pts @ rot.T
            if scale:
                pts = pts * rng.uniform(0.8, 1.25)
            if jitter:
                pts = pts + np.clip(0.01 * rng.standard_normal(pts.shape), -0.05, 0.05)
            return torch.from_numpy(pts.astype(np.float32)), int(y[i])

    return AugmentedClouds()


# ------------------------------------------------------------------- estimator
class PointNetClassifier(ClassifierMixin, BaseEstimator):
    """PointNet classifier on raw point clouds.

    The classification network of Qi et al. [1]_: a learned 3 x 3 input
    transform, a shared MLP (64, 64), a learned 64 x 64 feature transform
    regularised towards orthogonality, a shared MLP (64, 128, 1024), a global
    max-pool and a dense head 512-256-classes with batch norm and dropout,
    trained with Adam. Used by the paper [2]_ as the raw-point baseline.
    The network is a :mod:`skorch` ``NeuralNetClassifier`` built in ``fit``
    (wrapped, not subclassed); this class adds preprocessing, augmentation,
    label encoding, a validation split for early stopping, seeding and
    thread control.

    Parameters
    ----------
    n_points : int, default=2048
        Points fed to the network per object (the paper's value). Every
        object is normalised to the unit cube (centred on its bounding-box
        centre and divided by the bounding box's largest side), then
        subsampled without replacement when larger, or topped up with points
        drawn with replacement when smaller.
    max_epochs : int, default=100
        Upper bound on training epochs.
    lr : float, default=1e-3
        Adam learning rate.
    batch_size : int, default=32
        Minibatch size.
    dropout : float, default=0.3
        Dropout probability before the last dense layer (keep probability
        0.7, the value of the authors' code).
    reg_weight : float, default=0.001
        Weight of the feature-transform regulariser
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
    device : str, default="cpu"
        Torch device, e.g. "cpu" or "cuda".
    n_jobs : int, default=None
        Torch threads during ``fit`` and ``predict`` (joblib's meaning: -1 is
        all cores). None leaves torch's setting alone.
    random_state : int, RandomState instance or None, default=None
        Seeds weight initialisation, dropout, minibatch order, the
        validation split, point resampling and augmentation. With an int,
        results on CPU are reproducible (the global torch RNG is left as it
        was).
    verbose : int, default=0
        1 or more prints skorch's per-epoch table.

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
    ignored. The orthogonality regulariser is added through the loss module
    (``eppf._pointnet.PointNetLoss``) that receives the network's
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
    ...                          random_state=0).fit(X, y)
    >>> clf.predict(X[:3]).shape
    (3,)
    """

    def __init__(
        self,
        n_points=2048,
        *,
        max_epochs=100,
        lr=1e-3,
        batch_size=32,
        dropout=0.3,
        reg_weight=0.001,
        augment_rotation="z",
        jitter=True,
        scale_augmentation=True,
        early_stopping=True,
        validation_fraction=0.1,
        n_iter_no_change=10,
        device="cpu",
        n_jobs=None,
        random_state=None,
        verbose=0,
    ):
        self.n_points = n_points
        self.max_epochs = max_epochs
        self.lr = lr
        self.batch_size = batch_size
        self.dropout = dropout
        self.reg_weight = reg_weight
        self.augment_rotation = augment_rotation
        self.jitter = jitter
        self.scale_augmentation = scale_augmentation
        self.early_stopping = early_stopping
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.device = device
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.verbose = verbose

    # ------------------------------------------------------------------ checks
    def _check_params(self):
        _check_int("n_points", self.n_points, 1)
        _check_int("max_epochs", self.max_epochs, 1)
        _check_float("lr", self.lr, 0.0, math.inf)
        _check_int("batch_size", self.batch_size, 2)
        _check_float("dropout", self.dropout, 0.0, 1.0, low_open=False)
        _check_float("reg_weight", self.reg_weight, 0.0, math.inf, low_open=False)
        if not any(self.augment_rotation is r or self.augment_rotation == r for r in _ROTATIONS):
            raise ValueError(f"{_OWNER}: augment_rotation must be 'z' or None, got {self.augment_rotation!r}")
        _check_bool("jitter", self.jitter)
        _check_bool("scale_augmentation", self.scale_augmentation)
        _check_bool("early_stopping", self.early_stopping)
        _check_float("validation_fraction", self.validation_fraction, 0.0, 1.0)
        _check_int("n_iter_no_change", self.n_iter_no_change, 1)
        if not isinstance(self.device, str):
            raise ValueError(f"{_OWNER}: device must be a str such as 'cpu' or 'cuda', got {self.device!r}")
        if self.n_jobs is not None:
            if not isinstance(self.n_jobs, numbers.Integral) or isinstance(self.n_jobs, bool) or self.n_jobs == 0:
                raise ValueError(f"{_OWNER}: n_jobs must be None or a non-zero int, got {self.n_jobs!r}")
        _check_int("verbose", self.verbose, 0)

    def _n_threads(self):
        if self.n_jobs is None:
            return None
        from ..utils._validation import check_n_jobs

        return check_n_jobs(self.n_jobs, owner=_OWNER)

    def _prepare(self, X, seed):
        clouds = check_point_clouds(X, owner=_OWNER, min_points=2)
        return _normalise_and_sample(clouds, int(self.n_points), object_seeds(seed, len(clouds)))

    # --------------------------------------------------------------------- fit
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
        """
        import torch
        from skorch import NeuralNetClassifier
        from skorch.callbacks import EarlyStopping
        from skorch.dataset import Dataset as SkorchDataset
        from skorch.helper import predefined_split

        _, PointNet, PointNetLoss, _ = _modules()
        self._check_params()
        rng = check_random_state(self.random_state)
        seed_torch, seed_split, seed_aug, seed_fit_sample, seed_predict = (
            int(s) for s in rng.randint(0, 2**31 - 1, size=5)
        )
        pts = self._prepare(X, seed_fit_sample)
        y = np.asarray(y)
        if y.ndim != 1:
            raise ValueError(f"{_OWNER}: y must be 1D, got shape {y.shape}")
        if y.shape[0] != pts.shape[0]:
            raise ValueError(f"{_OWNER}: X has {pts.shape[0]} objects but y has {y.shape[0]} labels")
        check_classification_targets(y)
        classes, y_enc = np.unique(y, return_inverse=True)
        if classes.shape[0] < 2:
            raise ValueError(f"{_OWNER}: y has a single class {classes[0].tolist()!r}; at least 2 are needed")
        self.classes_ = classes
        y_enc = y_enc.astype(np.int64)
        self._predict_seed = seed_predict

        train_idx = np.arange(pts.shape[0])
        valid_idx = None
        if self.early_stopping:
            train_idx, valid_idx = _validation_split(
                y_enc, len(self.classes_), self.validation_fraction, seed_split, _OWNER
            )
        if train_idx.shape[0] < 2:
            raise ValueError(f"{_OWNER}: at least 2 training objects are needed (batch norm), got {train_idx.shape[0]}")

        train_ds = _make_dataset(
            pts[train_idx], y_enc[train_idx], seed=seed_aug, rotation=self.augment_rotation,
            jitter=bool(self.jitter), scale=bool(self.scale_augmentation),
        )
        callbacks = []
        train_split = None
        if valid_idx is not None:
            train_split = predefined_split(SkorchDataset(pts[valid_idx], y_enc[valid_idx]))
            callbacks.append(
                (
                    "early_stopping",
                    EarlyStopping(
                        monitor="valid_loss",
                        patience=self.n_iter_no_change,
                        load_best=True,
                        sink=print if self.verbose else _silent,
                    ),
                )
            )
        # A last batch of one object would break batch norm: drop it then.
        drop_last = train_idx.shape[0] % int(self.batch_size) == 1

        self.net_ = NeuralNetClassifier(
            PointNet,
            module__n_classes=len(self.classes_),
            module__dropout=float(self.dropout),
            criterion=PointNetLoss,
            criterion__reg_weight=float(self.reg_weight),
            optimizer=torch.optim.Adam,
            lr=float(self.lr),
            max_epochs=int(self.max_epochs),
            batch_size=int(self.batch_size),
            iterator_train__shuffle=True,
            iterator_train__drop_last=drop_last,
            train_split=train_split,
            callbacks=callbacks,
            classes=np.arange(len(self.classes_)),
            predict_nonlinearity=_softmax,
            device=self.device,
            verbose=int(self.verbose),
        )
        with _torch_threads(self._n_threads()), torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed_torch)
            self.net_.fit(train_ds, y=None)
        self.net_.train_split = None
        history = self.net_.history
        self.n_epochs_ = len(history)
        if valid_idx is not None:
            self.best_epoch_ = int(np.argmin(history[:, "valid_loss"])) + 1
        else:
            self.best_epoch_ = self.n_epochs_
        return self

    # ----------------------------------------------------------------- predict
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
        import torch

        check_is_fitted(self, "net_")
        pts = self._prepare(X, self._predict_seed)
        with _torch_threads(self._n_threads()), torch.random.fork_rng(devices=[]):
            return self.net_.predict_proba(pts)

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
        proba = self.predict_proba(X)
        return self.classes_[np.argmax(proba, axis=1)]

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.non_deterministic = self.device != "cpu"
        return tags
