"""Matplotlib figures of descriptors, network responses and results.

Importing this module imports matplotlib, an optional dependency
(``pip install eppf[plot]``); ``import eppf`` does not. Figures are created
through :mod:`matplotlib.pyplot` when no ``fig`` or ``ax`` is given, so they
show in notebooks and in the documentation gallery; pass your own to draw
into an existing layout. Every function returns what it drew on.
"""

import math
import numbers

import numpy as np

from .utils._param_validation import Interval, IntTuple, StrOptions, validate_parameter
from .utils._validation import check_class_labels

try:
    import matplotlib  # noqa: F401
except ImportError as exc:  # pragma: no cover - exercised only without matplotlib
    raise ImportError("eppf.plotting needs matplotlib: pip install eppf[plot]") from exc

__all__ = [
    "filter_responses",
    "plot_confusion_matrix",
    "plot_descriptor",
    "plot_filter_responses",
    "plot_learning_curve",
    "plot_noise_curve",
    "plot_scores_bar",
]

# Axis labels of the four EPPF functions, in histogram order (f1, f2, f3, f4).
_FUNCTION_LABELS = (
    "f1: distance",
    "f2: max angle to the line",
    "f3: angle between normals",
    "f4: occupancy ratio",
)

_NORMALIZE = ("true", "pred", "all", None)
_REDUCE = ("max", "sum")

#: The numeric and choice parameters of plot_filter_responses, declared once.
FILTER_RESPONSES = {
    "n_filters": [Interval(numbers.Integral, 1, None, closed="left")],
    "reduce": [StrOptions(set(_REDUCE))],
}


def _pyplot():
    import matplotlib.pyplot as plt

    return plt


def _new_axes(ax):
    if ax is None:
        _, ax = _pyplot().subplots()
    return ax


#: The bin counts a descriptor is plotted with (the same declaration as eppf.nn's, without importing torch).
N_BINS = [IntTuple(4, 1, None, description="a tuple of 4 positive ints")]


#: The magnitudes the plots draw: matplotlib overflows near float64's largest values (a scale's padding),
#: the noise band's standard deviation squares them, and matplotlib's log color bar fails below about
#: 2e-287 (it widens such a range to +-0.1).
_DRAWABLE_MAX = 1e150
_DRAWABLE_MIN = 1e-280


def _check_bins(n_bins, owner):
    """Validate four positive bin counts without importing torch."""
    return tuple(int(v) for v in validate_parameter(n_bins, N_BINS, name="n_bins", owner=owner))


def _as_histogram(descriptor, n_bins, owner):
    """Return a float64 array of shape n_bins from a flat or 4D descriptor."""
    n_bins = _check_bins(n_bins, owner)
    arr = np.asarray(descriptor)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{owner}: descriptor must hold numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if arr.ndim == 1:
        if arr.shape[0] != math.prod(n_bins):
            raise ValueError(
                f"{owner}: descriptor has {arr.shape[0]} values but n_bins={n_bins} needs "
                f"{math.prod(n_bins)}; pass the n_bins it was computed with"
            )
        arr = arr.reshape(n_bins)
    elif arr.ndim == 4:
        if arr.shape != n_bins:
            raise ValueError(f"{owner}: descriptor has shape {arr.shape} but n_bins={n_bins}")
    else:
        raise ValueError(
            f"{owner}: descriptor must be one flat descriptor of length prod(n_bins) or a 4D array, "
            f"got shape {arr.shape}"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"{owner}: descriptor contains NaN or infinite values")
    return _check_drawable(arr, owner, "descriptor")


def _slice_grid(fig, hist, *, log, cmap, title, colorbar_label):
    """Draw hist (n1, n2, n3, n4) as n4 rows x n3 columns of f1 x f2 images."""
    n1, n2, n3, n4 = hist.shape
    values = hist
    norm = None
    if log:
        from matplotlib.colors import LogNorm

        positive = hist[hist > 0]
        if positive.size == 0:
            raise ValueError("plot_descriptor: log=True needs at least one positive bin")
        values = np.where(hist > 0, hist, np.nan)
        if positive.min() < _DRAWABLE_MIN:
            raise ValueError(
                f"plot_descriptor: log=True cannot draw the positive value {positive.min():.3g} (matplotlib's log "
                f"color bar needs values from {_DRAWABLE_MIN:g}); rescale the descriptor first"
            )
        low, high = float(positive.min()), float(positive.max())
        if low == high:  # (a decade either side: matplotlib's own widening fails on small values)
            low, high = low / 10.0, high * 10.0
        norm = LogNorm(vmin=low, vmax=high)
        vmin = vmax = None
    else:
        vmin, vmax = float(hist.min()), float(hist.max())
        if vmin == vmax:
            vmax = vmin + max(1.0, abs(vmin) / 2.0)  # (a step that moves vmax whatever vmin's size)
    axes = fig.subplots(n4, n3, sharex=True, sharey=True, squeeze=False)
    image = None
    for i4 in range(n4):
        for i3 in range(n3):
            ax = axes[i4, i3]
            image = ax.imshow(
                values[:, :, i3, i4].T,
                origin="lower",
                aspect="auto",
                cmap=cmap,
                norm=norm,
                vmin=vmin,
                vmax=vmax,
                interpolation="nearest",
            )
            if i4 == 0:
                ax.set_title(f"f3 bin {i3}", fontsize="small")
            if i3 == 0:
                ax.set_ylabel(f"f4 bin {i4}\nf2 bin", fontsize="small")
            if i4 == n4 - 1:
                ax.set_xlabel("f1 bin", fontsize="small")
    fig.colorbar(image, ax=axes.ravel().tolist(), label=colorbar_label, shrink=0.9)
    fig.supxlabel(f"{_FUNCTION_LABELS[0]} (x) and {_FUNCTION_LABELS[2]} (columns)", fontsize="small")
    fig.supylabel(f"{_FUNCTION_LABELS[1]} (y) and {_FUNCTION_LABELS[3]} (rows)", fontsize="small")
    if title is not None:
        fig.suptitle(title)
    return axes


def plot_descriptor(descriptor, n_bins=(20, 4, 5, 3), *, fig=None, log=False, cmap="viridis", title=None):
    """Show an EPPF descriptor as a grid of 2D slices of its 4D histogram.

    The layout of the network-response figure of Bobkov et al.: one panel
    per (f3, f4) bin pair, ``n4`` rows (f4 bins, top row bin 0) by ``n3``
    columns (f3 bins), each panel an image of the f1 x f2 slice with f1 bins
    along x and f2 bins along y (origin lower left). All panels share one
    color scale and one color bar.

    Parameters
    ----------
    descriptor : array-like of shape (prod(n_bins),) or n_bins
        One flat descriptor in C order over (f1, f2, f3, f4), f4 fastest, as
        :class:`eppf.descriptors.EPPFTransformer` writes it, or the 4D histogram itself.
    n_bins : tuple of 4 ints, default=(20, 4, 5, 3)
        Bins along (f1, f2, f3, f4).
    fig : matplotlib.figure.Figure, default=None
        Figure to draw into (it should be empty); a new one if None.
    log : bool, default=False
        Logarithmic color scale; empty bins are left blank.
    cmap : str or matplotlib.colors.Colormap, default="viridis"
        Color map.
    title : str, default=None
        Figure title.

    Returns
    -------
    fig : matplotlib.figure.Figure
        The figure; ``fig.axes[:n3 * n4]`` are the panels in row-major order
        (panel ``i4 * n3 + i3`` shows ``hist[:, :, i3, i4].T``), the last axes
        is the color bar.

    Raises
    ------
    ValueError
        If the descriptor's length or shape does not match ``n_bins``, it
        holds NaN or infinite values or values beyond 1e150 in magnitude, or
        (``log=True``) it has no positive bin or one below 1e-280 (beyond
        what matplotlib's scales draw).

    See Also
    --------
    eppf.EPPFTransformer.to_histogram : Reshape flat descriptors to 4D.
    plot_filter_responses : The same view of a network's responses.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import numpy as np
    >>> from eppf.plotting import plot_descriptor
    >>> x = np.random.default_rng(0).dirichlet(np.ones(1200))
    >>> fig = plot_descriptor(x, n_bins=(20, 4, 5, 3))
    >>> len(fig.axes)  # 5 x 3 panels and the colour bar
    16
    """
    owner = "plot_descriptor"
    hist = _as_histogram(descriptor, n_bins, owner)
    if fig is None:
        n1, n2, n3, n4 = hist.shape
        fig = _pyplot().figure(figsize=(1.6 * n3 + 2.0, 1.2 * n4 + 1.2), layout="constrained")
    _slice_grid(fig, hist, log=bool(log), cmap=cmap, title=title, colorbar_label="bin value")
    return fig


def _check_fitted_4d(classifier, owner):
    from sklearn.exceptions import NotFittedError
    from sklearn.utils.validation import check_is_fitted

    from .classifiers import EPPF4DClassifier

    if not isinstance(classifier, EPPF4DClassifier):
        raise TypeError(f"{owner}: classifier must be an eppf.EPPF4DClassifier, got {type(classifier).__name__}")
    try:
        check_is_fitted(classifier, "net_")
    except NotFittedError:
        raise NotFittedError(
            f"{owner}: this EPPF4DClassifier is not fitted yet; call fit before plotting its responses"
        ) from None
    if classifier.conv != "4d":
        raise ValueError(
            f"{owner}: the classifier has conv={classifier.conv!r}; filter responses are shown for the "
            "4D network only (conv='4d')"
        )


def filter_responses(classifier, descriptor, *, layers=(0, 1)):
    """Record the responses of the 4D convolution layers of a fitted classifier to one descriptor.

    Parameters
    ----------
    classifier : eppf.EPPF4DClassifier
        Fitted, with ``conv="4d"``.
    descriptor : array-like of shape (prod(n_bins),) or n_bins
        One descriptor computed as the training descriptors were.
    layers : tuple of ints, default=(0, 1)
        Which of the two 4D convolutions (0: first, 1: second).

    Returns
    -------
    responses : list of ndarray of shape (n_filters, n1, n2, n3, n4)
        One per entry of ``layers``: the layer's output after its ReLU, the
        input standardized as ``predict`` does, recorded by forward hooks.

    See Also
    --------
    plot_filter_responses : Plot these responses.
    plot_descriptor : Plot the input descriptor.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import EPPF4DClassifier
    >>> from eppf.plotting import filter_responses
    >>> X = np.random.default_rng(0).dirichlet(np.ones(24), size=20)
    >>> y = np.repeat(["a", "b"], 10)
    >>> clf = EPPF4DClassifier(n_bins=(6, 2, 2, 1), filters=(4, 5, 3), n_hidden=8, max_epochs=1,
    ...                        early_stopping=False, random_state=0, verbose=0).fit(X, y)
    >>> [r.shape for r in filter_responses(clf, X[0])]
    [(4, 6, 2, 2, 1), (5, 6, 2, 2, 1)]
    """
    return _filter_responses(classifier, descriptor, layers, "filter_responses")


def _filter_responses(classifier, descriptor, layers, owner):
    import torch

    _check_fitted_4d(classifier, owner)
    hist = _as_histogram(descriptor, classifier.n_bins, owner)
    layers = _check_layers(layers, owner)
    x = hist.reshape(1, -1).astype(np.float32)
    x = (x - classifier.input_mean_) / classifier.input_scale_

    module = classifier.net_.module_
    convs = (module.conv1, module.conv2)
    recorded = {}
    handles = []
    for index in layers:

        def hook(mod, args, output, index=index):
            # float(): a bfloat16 network (precision_) records bfloat16, which NumPy lacks
            recorded[index] = torch.relu(output).detach().float().cpu().numpy()[0]

        handles.append(convs[index].register_forward_hook(hook))
    was_training = module.training
    was_folded = module.folded
    # the folded fast route calls the layers' forward_folded, which hooks do
    # not see; the unfolded route computes the same values through __call__
    module.folded = False
    module.eval()
    try:
        with torch.no_grad(), torch.random.fork_rng(devices=[]):
            device = next(module.parameters()).device
            module(torch.as_tensor(x, device=device))
    finally:
        module.folded = was_folded
        module.train(was_training)
        for handle in handles:
            handle.remove()
    return [recorded[index] for index in layers]


def _check_layers(layers, owner):
    try:
        values = tuple(layers)
    except TypeError:
        raise ValueError(f"{owner}: layers must be a tuple of 0 and/or 1, got {layers!r}") from None
    if len(values) == 0 or not all(
        isinstance(v, numbers.Integral) and not isinstance(v, bool) and v in (0, 1) for v in values
    ):
        raise ValueError(
            f"{owner}: layers must be a non-empty tuple of 0 (first 4D convolution) and/or 1 (second), "
            f"got {layers!r}"
        )
    return tuple(int(v) for v in values)


def plot_filter_responses(classifier, descriptor, *, layers=(0, 1), n_filters=8, fig=None, reduce="max"):
    """Show how the 4D convolutions of a fitted classifier respond to one descriptor.

    For each of the chosen 4D convolution layers of a fitted
    :class:`eppf.classifiers.EPPF4DClassifier` (``conv="4d"``), the responses (after the
    ReLU) of the first ``n_filters`` filters are recorded with forward hooks,
    the input standardized exactly as ``predict`` does. Each response is a 4D
    array over the (f1, f2, f3, f4) bins; a panel shows it reduced over
    (f3, f4) (``reduce``) as an image with f1 bins along x and f2 bins along
    y. Rows are layers, columns filters, each row with its own color bar.

    Parameters
    ----------
    classifier : eppf.EPPF4DClassifier
        Fitted, with ``conv="4d"``.
    descriptor : array-like of shape (prod(n_bins),) or n_bins
        One descriptor computed as the training descriptors were.
    layers : tuple of ints, default=(0, 1)
        Which of the two 4D convolutions to show (0: first, 1: second).
    n_filters : int, default=8
        Filters shown per layer (the first ones; fewer if the layer has
        fewer).
    fig : matplotlib.figure.Figure, default=None
        Figure to draw into (it should be empty); a new one if None.
    reduce : {"max", "sum"}, default="max"
        How each 4D response is reduced over f3 and f4 to an f1 x f2 image.

    Returns
    -------
    fig : matplotlib.figure.Figure
        Panel ``row * k + j`` of ``fig.axes`` (``k`` filters shown) shows
        ``reduce(response[j], axis=(2, 3)).T`` of layer ``layers[row]``; the
        color bars come after the panels.

    Raises
    ------
    sklearn.exceptions.NotFittedError
        If the classifier is not fitted.
    ValueError
        If the classifier is not the 4D variant, or an argument is invalid.

    See Also
    --------
    filter_responses : The responses as arrays.
    plot_descriptor : The input descriptor in the same view.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import numpy as np
    >>> from eppf import EPPF4DClassifier
    >>> from eppf.plotting import plot_filter_responses
    >>> X = np.random.default_rng(0).dirichlet(np.ones(24), size=20)
    >>> y = np.repeat(["a", "b"], 10)
    >>> clf = EPPF4DClassifier(n_bins=(6, 2, 2, 1), filters=(4, 5, 3), n_hidden=8, max_epochs=1,
    ...                        early_stopping=False, random_state=0, verbose=0).fit(X, y)
    >>> fig = plot_filter_responses(clf, X[0], n_filters=3)
    >>> len(fig.axes)  # 2 layers x 3 filters and 2 colour bars
    8
    """
    owner = "plot_filter_responses"
    validate_parameter(n_filters, FILTER_RESPONSES["n_filters"], name="n_filters", owner=owner)
    validate_parameter(reduce, FILTER_RESPONSES["reduce"], name="reduce", owner=owner)
    layers = _check_layers(layers, owner)
    responses = _filter_responses(classifier, descriptor, layers, owner)
    k = min(int(n_filters), min(r.shape[0] for r in responses))
    if fig is None:
        fig = _pyplot().figure(figsize=(1.5 * k + 1.5, 1.6 * len(layers) + 0.8), layout="constrained")
    axes = fig.subplots(len(layers), k, sharex=True, sharey=True, squeeze=False)
    reducer = np.max if reduce == "max" else np.sum
    for row, (layer, response) in enumerate(zip(layers, responses)):
        images = [reducer(response[j], axis=(2, 3)).T for j in range(k)]
        vmin = min(float(im.min()) for im in images)
        vmax = max(float(im.max()) for im in images)
        if vmin == vmax:
            vmax = vmin + 1.0
        for j in range(k):
            ax = axes[row, j]
            artist = ax.imshow(
                images[j], origin="lower", aspect="auto", cmap="viridis", vmin=vmin, vmax=vmax,
                interpolation="nearest",
            )
            if row == 0:
                ax.set_title(f"filter {j}", fontsize="small")
            if j == 0:
                ax.set_ylabel(f"layer {layer + 1}\nf2 bin", fontsize="small")
            if row == len(layers) - 1:
                ax.set_xlabel("f1 bin", fontsize="small")
        fig.colorbar(artist, ax=axes[row].tolist(), label=f"{reduce} over f3, f4", shrink=0.9)
    fig.suptitle("4D convolution responses (after ReLU)")
    return fig


def plot_confusion_matrix(
    y_true,
    y_pred,
    *,
    labels=None,
    normalize="true",
    ax=None,
    cmap="Blues",
    values=True,
    display_labels=None,
):
    """Show a confusion matrix with class names on the axes.

    Parameters
    ----------
    y_true : array-like of shape (n_samples,)
        True labels.
    y_pred : array-like of shape (n_samples,)
        Predicted or retrieved labels.
    labels : array-like of shape (n_classes,), default=None
        Labels to show, in this order; all labels present in ``y_true`` or
        ``y_pred`` (sorted) if None.
    normalize : {"true", "pred", "all"} or None, default="true"
        Divide counts by the row sums (true classes; the diagonal is then the
        per-class recall), the column sums, the total, or not at all.
    ax : matplotlib.axes.Axes, default=None
        Axes to draw on; a new figure if None.
    cmap : str or matplotlib.colors.Colormap, default="Blues"
        Color map.
    values : bool, default=True
        Write each cell's value into it.
    display_labels : array-like of shape (n_classes,), default=None
        Names shown for ``labels`` (e.g. ``target_names`` for integer
        targets); the labels themselves if None.

    Returns
    -------
    ax : matplotlib.axes.Axes
        The axes; ``ax.images[0].get_array()`` is the matrix (rows: true,
        columns: predicted), as :func:`sklearn.metrics.confusion_matrix`
        computes it.

    Raises
    ------
    ValueError
        If the lengths differ, a label is NaN or continuous, ``normalize`` is
        unknown or the display names do not match the labels.
    TypeError
        If the labels do not sort together (numbers mixed with strings).

    See Also
    --------
    eppf.metrics.retrieval_scores : Scores of the same labels.
    plot_scores_bar : Per-method scores as bars.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from eppf.plotting import plot_confusion_matrix
    >>> ax = plot_confusion_matrix(["a", "a", "b"], ["a", "b", "b"])
    >>> ax.images[0].get_array().tolist()
    [[0.5, 0.5], [0.0, 1.0]]
    """
    from sklearn.metrics import confusion_matrix

    owner = "plot_confusion_matrix"
    y_true = np.asarray(y_true)
    y_pred = np.asarray(y_pred)
    if y_true.ndim != 1 or y_pred.ndim != 1:
        raise ValueError(f"{owner}: y_true and y_pred must be 1D, got shapes {y_true.shape} and {y_pred.shape}")
    if y_true.shape[0] != y_pred.shape[0]:
        raise ValueError(
            f"{owner}: y_true and y_pred have different lengths ({y_true.shape[0]} and {y_pred.shape[0]})"
        )
    if y_true.shape[0] == 0:
        raise ValueError(f"{owner}: y_true is empty")
    if normalize not in _NORMALIZE:
        raise ValueError(f"{owner}: normalize must be 'true', 'pred', 'all' or None, got {normalize!r}")
    y_true = check_class_labels(y_true, owner, "y_true")
    y_pred = check_class_labels(y_pred, owner, "y_pred")
    if labels is None:
        labels = np.unique(np.concatenate([y_true, y_pred]))
    labels = np.asarray(labels)
    if display_labels is None:
        names = [str(v) for v in labels]
    else:
        names = [str(v) for v in display_labels]
        if len(names) != labels.shape[0]:
            raise ValueError(f"{owner}: display_labels has {len(names)} names but there are {labels.shape[0]} labels")
    cm = confusion_matrix(y_true, y_pred, labels=labels, normalize=normalize)
    ax = _new_axes(ax)
    image = ax.imshow(cm, cmap=cmap, interpolation="nearest", vmin=0)
    ax.figure.colorbar(image, ax=ax, label="share" if normalize else "count")
    n = labels.shape[0]
    ax.set_xticks(np.arange(n), names, rotation=45, ha="right", rotation_mode="anchor")
    ax.set_yticks(np.arange(n), names)
    ax.set_xlabel("predicted label")
    ax.set_ylabel("true label")
    if values:
        threshold = (cm.max() + cm.min()) / 2.0
        for i in range(n):
            for j in range(n):
                text = f"{cm[i, j]:.2f}" if normalize else f"{int(cm[i, j])}"
                ax.text(
                    j, i, text, ha="center", va="center", fontsize="small",
                    color="white" if cm[i, j] > threshold else "black",
                )
    return ax


def _finite_float_array(values, owner, name):
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}: {name} must be numbers") from None
    if not np.isfinite(arr).all():
        raise ValueError(f"{owner}: {name} contains NaN or infinite values")
    return _check_drawable(arr, owner, name)


def _check_drawable(arr, owner, name):
    """``arr`` (finite), or a ValueError naming ``owner`` and ``name`` when a value is beyond ``_DRAWABLE_MAX``."""
    largest = float(np.abs(arr).max()) if arr.size else 0.0
    if largest > _DRAWABLE_MAX:
        raise ValueError(f"{owner}: {name} holds values beyond {_DRAWABLE_MAX:g} in magnitude (largest {largest:.3g}), "
                         "which matplotlib cannot draw; rescale them first")
    return arr


def plot_noise_curve(sigmas, scores, *, ax=None, ylabel="total accuracy", xlabel="noise sigma (fraction of the unit cube)"):
    """Plot scores against the noise level, one line per method.

    Parameters
    ----------
    sigmas : array-like of shape (n_levels,)
        Noise standard deviations (x axis).
    scores : dict of str to array-like of shape (n_levels,) or (n_levels, n_draws)
        Score of each method at each level. With several draws per level the
        line is their mean and a band shows plus and minus one standard
        deviation.
    ax : matplotlib.axes.Axes, default=None
        Axes to draw on; a new figure if None.
    ylabel : str, default="total accuracy"
        Label of the y axis.
    xlabel : str, default="noise sigma (fraction of the unit cube)"
        Label of the x axis.

    Returns
    -------
    ax : matplotlib.axes.Axes
        The axes; ``ax.lines[i]`` is the mean line of the ``i``-th method.

    Raises
    ------
    ValueError
        If a method's scores do not have one row per noise level, or a
        value is NaN, infinite or beyond 1e150 in magnitude.

    See Also
    --------
    eppf.experiments.run_noise : The experiment that draws this curve.
    plot_scores_bar : Scores at one noise level.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from eppf.plotting import plot_noise_curve
    >>> ax = plot_noise_curve([0.0, 0.01, 0.02], {"EPPF": [0.9, 0.85, 0.8],
    ...                                           "ESF": [[0.8, 0.7], [0.6, 0.5], [0.4, 0.4]]})
    >>> ax.lines[1].get_ydata().tolist()
    [0.75, 0.55, 0.4]
    """
    owner = "plot_noise_curve"
    sigmas = _finite_float_array(sigmas, owner, "sigmas")
    if sigmas.ndim != 1 or sigmas.shape[0] == 0:
        raise ValueError(f"{owner}: sigmas must be a non-empty 1D array, got shape {sigmas.shape}")
    if not isinstance(scores, dict) or len(scores) == 0:
        raise ValueError(f"{owner}: scores must be a non-empty dict of method name to scores")
    curves = {}
    for name, values in scores.items():
        arr = _finite_float_array(values, owner, f"scores[{name!r}]")
        if arr.ndim not in (1, 2) or arr.shape[0] != sigmas.shape[0] or (arr.ndim == 2 and arr.shape[1] == 0):
            raise ValueError(
                f"{owner}: scores[{name!r}] has shape {arr.shape}; expected ({sigmas.shape[0]},) or "
                f"({sigmas.shape[0]}, n_draws), one row per noise level"
            )
        curves[name] = arr
    ax = _new_axes(ax)
    for name, arr in curves.items():
        if arr.ndim == 1:
            ax.plot(sigmas, arr, marker="o", label=str(name))
        else:
            mean, std = arr.mean(axis=1), arr.std(axis=1)
            (line,) = ax.plot(sigmas, mean, marker="o", label=str(name))
            ax.fill_between(sigmas, mean - std, mean + std, color=line.get_color(), alpha=0.2, linewidth=0)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend()
    return ax


def plot_scores_bar(scores, *, ax=None, ylabel="F1", errors=None, sort=False):
    """Bar plot of one score per method or setting.

    Used for the function ablation (F1 with each function left out) and the
    comparison of descriptors.

    Parameters
    ----------
    scores : dict of str to float or to (mean, std)
        Bar heights; a pair gives the height and an error bar.
    ax : matplotlib.axes.Axes, default=None
        Axes to draw on; a new figure if None.
    ylabel : str, default="F1"
        Label of the y axis.
    errors : dict of str to float, default=None
        Error bar (e.g. a standard deviation) per name; overrides the second
        value of a pair.
    sort : bool, default=False
        Order the bars by height, highest first; insertion order otherwise.

    Returns
    -------
    ax : matplotlib.axes.Axes
        The axes; ``ax.patches`` are the bars in the order drawn.

    Raises
    ------
    ValueError
        If ``scores`` is empty, a value is not a number or a pair or lies
        beyond 1e150 in magnitude, or ``errors`` names a key that is not in
        ``scores``.

    See Also
    --------
    plot_noise_curve : Scores against the noise level.
    eppf.metrics.retrieval_scores : Computes the scores.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from eppf.plotting import plot_scores_bar
    >>> ax = plot_scores_bar({"all": (0.9, 0.01), "no f4": (0.8, 0.02), "no f1": 0.6}, sort=True)
    >>> [round(float(p.get_height()), 2) for p in ax.patches]
    [0.9, 0.8, 0.6]
    """
    owner = "plot_scores_bar"
    if not isinstance(scores, dict) or len(scores) == 0:
        raise ValueError(f"{owner}: scores must be a non-empty dict of name to value or (mean, std)")
    names, heights, errs = [], [], []
    for name, value in scores.items():
        arr = _finite_float_array(value, owner, f"scores[{name!r}]")
        if arr.ndim == 0:
            height, err = float(arr), 0.0
        elif arr.shape == (2,):
            height, err = float(arr[0]), float(arr[1])
        else:
            raise ValueError(f"{owner}: scores[{name!r}] must be a number or a (mean, std) pair, got {value!r}")
        names.append(str(name))
        heights.append(height)
        errs.append(err)
    if errors is not None:
        if not isinstance(errors, dict):
            raise ValueError(f"{owner}: errors must be a dict of name to error, got {type(errors).__name__}")
        keys = [str(k) for k in scores]
        for name, err in errors.items():
            if str(name) not in keys:
                raise ValueError(f"{owner}: errors has {name!r}, which is not in scores")
            value = _finite_float_array(err, owner, f"errors[{name!r}]")
            if value.ndim != 0:
                raise ValueError(f"{owner}: errors[{name!r}] must be a number, got {err!r}")
            errs[keys.index(str(name))] = float(value)
    order = np.argsort(-np.asarray(heights), kind="stable") if sort else np.arange(len(names))
    names = [names[i] for i in order]
    heights = [heights[i] for i in order]
    errs = [errs[i] for i in order]
    ax = _new_axes(ax)
    x = np.arange(len(names))
    ax.bar(x, heights, yerr=errs if any(errs) else None, capsize=3, color="C0")
    ax.set_xticks(x, names, rotation=30 if len(names) > 4 else 0, ha="right" if len(names) > 4 else "center")
    ax.set_ylabel(ylabel)
    ax.grid(True, axis="y", alpha=0.3)
    return ax


def _history_rows(history_or_classifier, owner):
    from sklearn.exceptions import NotFittedError

    obj = history_or_classifier
    if hasattr(obj, "get_params") and not hasattr(obj, "history"):  # an eppf estimator
        if not hasattr(obj, "net_"):
            raise NotFittedError(f"{owner}: this {type(obj).__name__} is not fitted yet; call fit first")
        obj = obj.net_
    if hasattr(obj, "history"):  # a skorch net
        obj = obj.history
    try:
        rows = list(obj)
    except TypeError:
        raise TypeError(
            f"{owner}: expected a fitted EPPF4DClassifier or PointNetClassifier, a skorch net or a list of "
            f"per-epoch dicts, got {type(history_or_classifier).__name__}"
        ) from None
    if len(rows) == 0:
        raise ValueError(f"{owner}: the history is empty")
    if not all(isinstance(r, dict) for r in rows):
        raise TypeError(f"{owner}: the history must be a list of per-epoch dicts")
    return rows


def plot_learning_curve(history_or_classifier, *, ax=None, keys=("train_loss", "valid_loss", "valid_acc")):
    """Plot per-epoch losses and accuracy of a trained network.

    Parameters
    ----------
    history_or_classifier : EPPF4DClassifier, PointNetClassifier, skorch net or list of dict
        A fitted eppf network classifier (its ``net_.history`` is read), a
        skorch net, or a history as a list of per-epoch dicts.
    ax : matplotlib.axes.Axes, default=None
        Axes for the losses; accuracy-like keys (containing ``"acc"``) go on
        a twin axis on the right. A new figure if None.
    keys : tuple of str, default=("train_loss", "valid_loss", "valid_acc")
        Keys to plot; those absent from every epoch are skipped (e.g. the
        validation keys without early stopping).

    Returns
    -------
    ax : matplotlib.axes.Axes
        The loss axes (the twin accuracy axes, if any, shares its x axis).

    Raises
    ------
    sklearn.exceptions.NotFittedError
        If the classifier is not fitted.
    ValueError
        If the history is empty, none of ``keys`` is in it, or a value is
        not a number or a finite one beyond 1e150 in magnitude (infinite and
        NaN losses are drawn as spikes and gaps).

    See Also
    --------
    eppf.classifiers.EPPF4DClassifier : Records its history in ``net_.history``.
    eppf.classifiers.PointNetClassifier : Likewise.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from eppf.plotting import plot_learning_curve
    >>> history = [{"epoch": 1, "train_loss": 1.2, "valid_loss": 1.3, "valid_acc": 0.4},
    ...            {"epoch": 2, "train_loss": 0.9, "valid_loss": 1.0, "valid_acc": 0.6}]
    >>> ax = plot_learning_curve(history)
    >>> [line.get_label() for line in ax.lines]
    ['train_loss', 'valid_loss']
    """
    owner = "plot_learning_curve"
    if isinstance(keys, str):
        keys = (keys,)
    rows = _history_rows(history_or_classifier, owner)
    present = [k for k in keys if any(k in r for r in rows)]
    if not present:
        raise ValueError(f"{owner}: none of the keys {tuple(keys)} is in the history; it has {sorted(rows[0])}")
    epochs = _finite_float_array([r.get("epoch", i + 1) for i, r in enumerate(rows)], owner, "the history's epochs")
    ax = _new_axes(ax)
    twin = None
    handles = []
    for i, key in enumerate(present):
        try:
            y = np.array([r.get(key, np.nan) for r in rows], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{owner}: the history's {key!r} values must be numbers") from None
        finite = y[np.isfinite(y)]  # (NaN and infinities, e.g. a diverged loss, leave gaps or spikes)
        if finite.size and np.abs(finite).max() > _DRAWABLE_MAX:
            raise ValueError(f"{owner}: the history's {key!r} values reach beyond {_DRAWABLE_MAX:g} in magnitude, "
                             "which matplotlib cannot draw")
        target = ax
        if "acc" in key:
            if twin is None:
                twin = ax.twinx()
                twin.set_ylabel("accuracy")
            target = twin
        (line,) = target.plot(epochs, y, marker="." if len(rows) < 30 else None, color=f"C{i}", label=key,
                              linestyle="--" if target is twin else "-")
        handles.append(line)
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss")
    ax.grid(True, alpha=0.3)
    ax.legend(handles=handles, loc="best")
    return ax
