"""Table III: PointNet and the EPPF 2D/3D/4D networks on a train/test split."""

import time
from dataclasses import dataclass, fields

from ..metrics import METRICS, retrieval_scores
from ..registry import RECIPE, make_descriptor, recommended_pipeline_parts
from ._common import (
    DescriptorCache,
    ExperimentError,
    ExperimentSettings,
    Logger,
    check_positive_int,
    command_text,
    draw_seeds,
    load_or_pass,
    markdown_table,
    n_samples_setting,
    params_text,
    resolve_scaling,
    subsample_train,
    write_report,
)
from ._retrieval import METRIC_TITLES

__all__ = ["TrainingOptions", "run_classification"]

#: Model keys and their names in the tables.
MODELS = {"pointnet": "PointNet", "2d": "EPPF 2D", "3d": "EPPF 3D", "4d": "EPPF 4D", "4d+": "EPPF 4D+",
          "kl": "EPPF KL 1-NN"}
DEFAULT_MODELS = ("pointnet", "2d", "3d", "4d", "4d+", "kl")

@dataclass(frozen=True)
class TrainingOptions:
    """The options the classification and noise experiments share, written once.

    :func:`run_classification` and :func:`run_noise` accept these as keyword
    arguments besides those of :class:`ExperimentSettings`.

    Parameters
    ----------
    models : list of str, default=None
        Keys of :data:`MODELS`; None runs each experiment's default list.
    epochs : int, default=None
        Max epochs of the EPPF networks (30, or 2 with ``quick``).
    pointnet_epochs : int, default=None
        Max epochs of PointNet (default ``epochs``).
    pointnet_points : int, default=None
        Points per object fed to PointNet (1024, or 128 with ``quick``).
    validation_fraction : float, default=0.1
        Share of the training objects held out for early stopping.
    patience : int, default=None
        Early-stopping patience (5, or 2 with ``quick``).
    precision : {"float32", "bfloat16", "auto"}, default="float32"
        Arithmetic of the paper's EPPF networks ("2d", "3d", "4d"; see
        :class:`eppf.classifiers.EPPF4DClassifier`); "4d+" follows its recipe.
    train_per_class : int, default=None
        Train on at most this many objects per class (seeded), to fit a CPU
        budget; None uses the whole training split.
    test_per_class : int, default=None
        Score on at most this many test objects per class (seeded); None uses
        the whole test split.

    See Also
    --------
    ExperimentSettings : The settings every experiment shares.

    Examples
    --------
    >>> from eppf.experiments import TrainingOptions
    >>> options, rest = TrainingOptions.split("run_noise", {"epochs": 3, "quick": True})
    >>> options.epochs, rest
    (3, {'quick': True})
    """

    models: tuple = None
    epochs: int = None
    pointnet_epochs: int = None
    pointnet_points: int = None
    validation_fraction: float = 0.1
    patience: int = None
    precision: str = "float32"
    train_per_class: int = None
    test_per_class: int = None

    @classmethod
    def split(cls, owner, kwargs):
        """The training options among ``kwargs``, and the other keyword arguments.

        Parameters
        ----------
        owner : str
            The calling function's name (the rest is checked by
            :meth:`ExperimentSettings.from_kwargs`).
        kwargs : dict
            Keyword arguments.

        Returns
        -------
        options : TrainingOptions
            The training options given, the others at their defaults.
        rest : dict
            The other keyword arguments.
        """
        names = {f.name for f in fields(cls)}
        options = cls(**{k: v for k, v in kwargs.items() if k in names})
        return options, {k: v for k, v in kwargs.items() if k not in names}

    def astuple(self):
        """The options in field order.

        Returns
        -------
        values : tuple
            ``(models, epochs, ..., test_per_class)``.
        """
        return tuple(getattr(self, f.name) for f in fields(self))


@dataclass
class TrainingSettings:
    """How the classifiers are trained (written into the protocol)."""

    epochs: int
    pointnet_epochs: int
    pointnet_points: int
    validation_fraction: float
    patience: int
    scaling: str
    quick: bool
    n_jobs: int
    random_state: int
    precision: str = "float32"

    @classmethod
    def resolve(cls, *, epochs, pointnet_epochs, pointnet_points, validation_fraction, patience, scaling, quick,
                n_jobs, random_state, precision="float32"):
        """Fill in the defaults and check the values."""
        epochs = check_positive_int(epochs if epochs is not None else (1 if quick else 30), "--epochs")
        pointnet_epochs = check_positive_int(pointnet_epochs if pointnet_epochs is not None else epochs,
                                             "--pointnet-epochs")
        pointnet_points = check_positive_int(
            pointnet_points if pointnet_points is not None else (128 if quick else 1024), "--pointnet-points")
        patience = check_positive_int(patience if patience is not None else (1 if quick else 5), "--patience")
        if not (isinstance(validation_fraction, (int, float)) and 0 < validation_fraction < 1):
            raise ExperimentError(f"--validation-fraction must lie in (0, 1), got {validation_fraction!r}")
        if precision not in ("float32", "bfloat16", "auto"):
            raise ExperimentError(f"--precision must be 'float32', 'bfloat16' or 'auto', got {precision!r}")
        return cls(epochs, pointnet_epochs, pointnet_points, float(validation_fraction), patience, scaling, quick,
                   n_jobs, random_state, precision)

    def make_model(self, key):
        """An unfitted classifier for a model key (None for the KL 1-NN)."""
        from .. import EPPF4DClassifier, KLNearestNeighbors, PointNetClassifier

        # verbose=0: the experiment's own log reports each fit (the classifiers' default prints every epoch)
        common = dict(early_stopping=True, validation_fraction=self.validation_fraction,
                      n_iter_no_change=self.patience, n_jobs=self.n_jobs, random_state=self.random_state, verbose=0)
        if key == "pointnet":
            return PointNetClassifier(n_points=self.pointnet_points, max_epochs=self.pointnet_epochs, **common)
        if key in ("2d", "3d", "4d"):
            return EPPF4DClassifier(conv=key, max_epochs=self.epochs, precision=self.precision, **common)
        if key == "4d+":
            return self.recommended()[1]
        if key == "kl":
            return KLNearestNeighbors(n_neighbors=1, n_jobs=self.n_jobs)
        raise ExperimentError(f"unknown model {key!r}; choose from {list(MODELS)}")

    def descriptor(self):
        """The EPPF transformer whose descriptors the CNNs and the KL 1-NN use."""
        seed = draw_seeds(self.random_state, 1)[0]
        return make_descriptor("eppf", n_samples=n_samples_setting(self.quick), scaling=self.scaling,
                               random_state=seed, n_jobs=self.n_jobs)

    def recommended(self):
        """The descriptor pool and the classifier of "EPPF 4D+"."""
        return recommended_pipeline_parts(
            self.descriptor(), n_jobs=self.n_jobs, random_state=self.random_state, max_epochs=self.epochs,
            n_iter_no_change=self.patience, validation_fraction=self.validation_fraction, quick=self.quick)

    def protocol(self, models):
        """Protocol lines for the report."""
        lines = {}
        if "pointnet" in models:
            lines["PointNet"] = (f"{self.pointnet_points} points per object (unit cube), at most {self.pointnet_epochs} "
                                 f"epochs, augmentation: rotation about z, jitter, scaling; "
                                 f"`{params_text(self.make_model('pointnet'))}`")
        cnns = [MODELS[m] for m in models if m in ("2d", "3d", "4d")]
        if cnns:
            lines["EPPF CNNs"] = (f"{', '.join(cnns)}: the paper's networks, at most {self.epochs} epochs, Adam lr "
                                  f"5e-4, dropout 0.5; `{params_text(self.make_model('4d'))}`")
        if "4d+" in models:
            pool, clf = self.recommended()
            n_test = pool.n_draws if pool.test_draws is None else pool.test_draws
            copies = {1: "the plain copy of each test object", 2: "a plain and a stretched copy of each test object"}
            lines["EPPF 4D+"] = (
                f"the recommended recipe beyond the paper: {pool.n_draws} descriptor draws per object (draws 1.. of "
                f"copies stretched per axis in [{RECIPE['stretch'][0]}, {RECIPE['stretch'][1]}], a fresh draw every "
                "epoch), EPPF + GASD + 6 proportion ratios (side features) per draw"
                + (", the normals estimated once per object and carried to its stretched copies"
                   if pool.share_normals else "") + ", "
                + (f"an ensemble of {clf.n_estimators} networks (own seeds, one validation hold-out), "
                   if clf.n_estimators > 1 else "")
                + ("probabilities of " if n_test == 1 else "probabilities averaged over ")
                + copies.get(n_test, f"a plain and {n_test - 1} stretched copies of each test object")
                + (" and over the networks" if clf.n_estimators > 1 else "") + f"; `{params_text(clf)}`")
        if any(m in models for m in ("2d", "3d", "4d", "kl")):
            lines["EPPF descriptor"] = (f"one draw, fitted on the training objects; `{params_text(self.descriptor())}`; "
                                        "normals: PCA over 20 neighbours estimated from the (noisy) points")
        lines["model choice"] = (
            f"early stopping on a stratified validation hold-out of {self.validation_fraction:.0%} of the training "
            f"objects (patience {self.patience} epochs"
            + (f", {self.recommended()[1].n_iter_no_change} for EPPF 4D+" if "4d+" in models else "")
            + "; the weights of the best validation epoch are kept). "
            "The test split is used once, for the scores below; no setting was tuned on it")
        if "4d+" in models or (cnns and self.precision == "auto"):
            from ..nn import resolve_precision

            lines["precision 'auto'"] = (f"{resolve_precision('auto')} on this machine (bfloat16 only where the CPU "
                                         "computes it natively)")
        lines["seeds"] = f"random_state={self.random_state} (weights, batches, validation split, descriptor draw)"
        lines["threads (n_jobs)"] = self.n_jobs
        return lines


class TrainingDescriptors:
    """EPPF descriptors of one set of clouds, computed (or read) once."""

    def __init__(self, settings, cache, clouds, train, test):
        self.settings, self.cache = settings, cache
        self.clouds, self.train, self.test = clouds, train, test
        self._X = None

    def get_pool(self):
        """The training and test pools of the "4D+" recipe (computed once, cached)."""
        if getattr(self, "_pool", None) is None:
            from ..utils._cache import estimator_key
            from ..utils._cache import data_digest

            train = [self.clouds[i] for i in self.train]
            test = [self.clouds[i] for i in self.test]
            pool = self.settings.recommended()[0]

            def compute():
                return {"train": pool.fit_transform(train).astype("float32"),
                        "test": pool.transform(test).astype("float32")}

            key = [estimator_key(pool), data_digest(train), f"test:{data_digest(test)}"]
            X = self.cache.get("DescriptorPool", key, compute, ["train", "test"], "EPPF 4D+ pools")
            self._pool = X["train"], X["test"]
        return self._pool

    def get(self):
        if self._X is None:
            train = [self.clouds[i] for i in self.train]
            test = [self.clouds[i] for i in self.test]
            X = self.cache.describe(self.settings.descriptor(), train, {"train": train, "test": test}, "EPPF train/test")
            self._X = X["train"], X["test"]
        return self._X


def train_and_score(key, settings, clouds, y, train, test, descriptors, log):
    """Fit one model on ``train`` and score it on ``test``.

    Returns a dict with the metrics (fractions), ``epochs``, ``best_epoch``
    and ``fit_s``/``predict_s`` (wall seconds).
    """
    model = settings.make_model(key)
    if key == "pointnet":
        X_train, X_test = [clouds[i] for i in train], [clouds[i] for i in test]
    elif key == "4d+":
        X_train, X_test = descriptors.get_pool()
    else:
        X_train, X_test = descriptors.get()
    log(f"{MODELS[key]}: training on {len(train)} objects")
    t = time.perf_counter()
    model.fit(X_train, y[train])
    fit_s = time.perf_counter() - t
    t = time.perf_counter()
    y_pred = model.predict(X_test)
    predict_s = time.perf_counter() - t
    scores = retrieval_scores(y[test], y_pred)
    epochs = getattr(model, "n_epochs_", "")
    best = getattr(model, "best_epoch_", "")
    log(f"{MODELS[key]}: test total accuracy {100 * scores['total_accuracy']:.2f}%, F1 {100 * scores['macro_f1']:.2f}% "
        f"(fit {fit_s:.0f} s" + (f", {epochs} epochs, best {best})" if epochs != "" else ")"))
    return {**scores, "epochs": epochs, "best_epoch": best, "fit_s": round(fit_s, 2), "predict_s": round(predict_s, 2),
            "y_pred": y_pred}


def check_models(models, default):
    """The model keys to run, checked."""
    models = list(default if models is None else models)
    unknown = [m for m in models if m not in MODELS]
    if unknown or not models:
        raise ExperimentError(f"--models: unknown {unknown}; choose from {list(MODELS)}")
    return models


def prepare_training(data, options, scaling, quick, n_jobs, random_state):
    """What the classification and noise experiments set up alike before training.

    Returns the resolved :class:`TrainingSettings`, the loaded data set, and
    the indices of the (optionally subsampled) training and test objects.
    """
    settings = TrainingSettings.resolve(
        epochs=options.epochs, pointnet_epochs=options.pointnet_epochs, pointnet_points=options.pointnet_points,
        validation_fraction=options.validation_fraction, patience=options.patience, scaling=None,
        quick=quick, n_jobs=n_jobs, random_state=random_state, precision=options.precision)
    train_per_class, test_per_class = options.train_per_class, options.test_per_class
    if train_per_class is not None:
        train_per_class = check_positive_int(train_per_class, "--train-per-class")
    if test_per_class is not None:
        test_per_class = check_positive_int(test_per_class, "--test-per-class")
    ds = load_or_pass(data, quick=quick, random_state=random_state)
    settings.scaling = resolve_scaling(scaling, ds)
    train = subsample_train(ds, train_per_class, random_state)
    test = subsample_train(ds, test_per_class, random_state, part="test")
    return settings, ds, train, test


def run_classification(
    data="builtin",
    *,
    out=None,
    **settings,
):
    """Object classification on the test split (Table III).

    PointNet on the raw points and the EPPF 2D, 3D and 4D networks on EPPF
    descriptors are trained on the training split and scored once on the
    test split; a KL 1-NN on the same descriptors is a training-free
    reference. Early stopping and the choice of the kept weights use only a
    validation hold-out of the training objects.

    Parameters
    ----------
    data : str or Dataset, default="builtin"
        ``"builtin"``, a ``.npz`` path, or a loaded :class:`Dataset`.
    out : str, default=None
        Folder for ``classification.md``/``.csv``/``.png``.
    **settings
        The options of :class:`TrainingOptions` (``models``, ``epochs``,
        ``pointnet_epochs``, ``pointnet_points``, ``validation_fraction``,
        ``patience``, ``precision``, ``train_per_class``, ``test_per_class``)
        and the shared settings of :class:`ExperimentSettings` (``scaling``,
        ``random_state``, ``n_jobs``, ``quick``, ``cache_dir``, ``verbose``,
        ``command``).

    Returns
    -------
    result : dict
        ``"rows"`` (as in the CSV), ``"paths"``, ``"cache"``.

    See Also
    --------
    run_noise : The same models as noise grows.
    run_retrieval : Retrieval without training.

    Examples
    --------
    The 4D network for one epoch and the KL 1-NN on the quick built-in set:

    >>> import tempfile
    >>> from eppf.experiments import run_classification
    >>> result = run_classification("builtin", quick=True, models=["4d", "kl"], n_jobs=1, out=tempfile.mkdtemp(),
    ...                             verbose=False)
    >>> [(row["model"], row["n_test"]) for row in result["rows"]]
    [('EPPF 4D', 20), ('EPPF KL 1-NN', 20)]
    """
    options, settings = TrainingOptions.split("run_classification", settings)
    (models, epochs, pointnet_epochs, pointnet_points, validation_fraction, patience, precision, train_per_class,
     test_per_class) = options.astuple()
    scaling, random_state, n_jobs, quick, cache_dir, verbose, command = ExperimentSettings.from_kwargs(
        "run_classification", settings).astuple()
    log = Logger("classification", verbose)
    models = check_models(models, DEFAULT_MODELS)
    settings, ds, train, test = prepare_training(data, options, scaling, quick, n_jobs, random_state)
    if train.size < 2 or test.size < 1:
        raise ExperimentError(f"--data: need training and test objects, got {train.size} and {test.size}")
    cache = DescriptorCache(cache_dir if cache_dir is not None else (out and f"{out}/cache"), log)
    descriptors = TrainingDescriptors(settings, cache, ds.clouds, train, test)
    rows, preds = [], {}
    for key in models:
        r = train_and_score(key, settings, ds.clouds, ds.y, train, test, descriptors, log)
        preds[key] = r.pop("y_pred")
        rows.append({"model": MODELS[key], "n_train": train.size, "n_test": test.size,
                     **{k: round(r[k], 6) for k in METRICS},
                     **{k: r[k] for k in ("epochs", "best_epoch", "fit_s", "predict_s")}})
    result = {"rows": rows, "predictions": preds, "paths": {}, "cache": cache}
    if out is None:
        return result
    table = markdown_table(
        ["Model"] + list(METRIC_TITLES.values()) + ["Epochs (best)", "Fit (s)"],
        [[row["model"]] + [f"{100 * row[k]:.2f}" for k in METRIC_TITLES]
         + [f"{row['epochs']} ({row['best_epoch']})" if row["epochs"] != "" else "-", f"{row['fit_s']:.0f}"]
         for row in rows],
    )
    protocol = {
        "task": f"train on the training split ({train.size} objects"
                + (f", at most {train_per_class} per class" if train_per_class else "")
                + f"), score once on the test split ({test.size} objects"
                + (f", at most {test_per_class} per class" if test_per_class else "") + ")",
        **settings.protocol(models),
        "pairs per object": n_samples_setting(quick),
        "descriptor sets computed / read from cache": f"{cache.n_computed} / {cache.n_loaded}",
    }
    names = ds.target_names
    best = max(rows, key=lambda row: row["total_accuracy"])
    best_key = next(k for k in models if MODELS[k] == best["model"])

    def plot(plotting, plt):
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        plotting.plot_scores_bar({row["model"]: 100 * row["total_accuracy"] for row in rows}, ax=axes[0],
                                 ylabel="Total accuracy (%)")
        axes[0].set_title(f"Test accuracy, {ds.name}")
        if hasattr(plotting, "plot_confusion_matrix"):
            plotting.plot_confusion_matrix(names[ds.y[test]], names[preds[best_key]], labels=list(names), ax=axes[1])
            axes[1].set_title(f"{best['model']} (row-normalised)")
        else:
            axes[1].set_axis_off()
        fig.tight_layout()
        return fig

    result["paths"] = write_report(
        out, "classification", title=f"Classification (Table III) on {ds.name}",
        command=command or command_text("classification"), data=ds, protocol=protocol, table=table, csv_rows=rows,
        plot=plot, log=log, elapsed=log.elapsed(),
    )
    return result
