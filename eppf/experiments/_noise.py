"""Accuracy against Gaussian noise, retraining at every noise level (the paper's noise figure)."""

import math
from dataclasses import replace

import numpy as np

from ..metrics import METRICS
from ._classification import MODELS, TrainingOptions, TrainingDescriptors, check_models, prepare_training, train_and_score
from ._common import (
    DescriptorCache,
    ExperimentError,
    ExperimentSettings,
    Logger,
    command_text,
    draw_seeds,
    load_or_pass,
    markdown_table,
    write_report,
)
from ._presets import apply_preset, get_preset

__all__ = ["run_noise"]

DEFAULT_LEVELS = (0.0, 0.02, 0.04, 0.06, 0.08, 0.1)
QUICK_LEVELS = (0.0, 0.06)
DEFAULT_NOISE_MODELS = ("4d", "pointnet", "kl")
#: The level at which the paper says PointNet starts to break down.
REPORTED_LEVEL = 0.06


def check_levels(levels):
    """Sorted unique noise sigmas in [0, 1], or an ExperimentError."""
    try:
        values = [float(v) for v in levels]
    except (TypeError, ValueError):
        raise ExperimentError(f"--levels must be numbers, got {levels!r}") from None
    if not values:
        raise ExperimentError("--levels must name at least one noise level")
    bad = [v for v in values if not (math.isfinite(v) and 0 <= v <= 1)]
    if bad:
        raise ExperimentError(f"--levels must lie in [0, 1] (fractions of the unit cube), got {bad}")
    if len(set(values)) != len(values):
        raise ExperimentError(f"--levels has duplicates: {values}")
    return sorted(values)


def run_noise(
    data="builtin",
    *,
    out=None,
    levels=None,
    preset=None,
    **settings,
):
    """Test accuracy as Gaussian noise grows, retraining at every level.

    At every level, zero-mean Gaussian noise of standard deviation ``sigma``
    times the largest bounding-box side of each object
    (:class:`eppf.preprocessing.GaussianNoise`, ``relative_to="unit_cube"``)
    is added to the coordinates of every object, training and test alike, as
    the paper did; normals are then estimated from the noisy points (no clean
    normals are used), the descriptors are recomputed and every model is
    trained afresh on the noisy training split and scored on the noisy test
    split.

    Parameters
    ----------
    data : str or Dataset, default="builtin"
        ``"builtin"``, a ``.npz`` path, or a loaded :class:`Dataset`.
    out : str, default=None
        Folder for ``noise.md``/``.csv``/``.png``.
    levels : sequence of float, default=None
        Noise sigmas as fractions of the unit cube, in [0, 1]. None: the
        preset's ``noise_levels`` when a preset is given, else
        ``(0, 0.02, 0.04, 0.06, 0.08, 0.1)`` (``(0, 0.06)`` with ``quick``).
    preset : str or Preset, default=None
        A key of :data:`PRESETS`: every object is first resampled (and, for
        ``"modelnet40-occluded"``, occluded) as the preset says, by
        :func:`apply_preset`; the preset's own noise is not added, its sigma
        is swept instead (``"modelnet40-noise-0.10"`` runs the levels 0 and
        0.1, the clean and occluded presets 0, 0.07, 0.1 and 0.15).
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
        ``"rows"`` (one per level and model, as in the CSV), ``"drops"``
        (model -> total-accuracy drop from the lowest level to
        ``REPORTED_LEVEL`` when both were run), ``"paths"``, ``"cache"``,
        ``"preset"`` (its name, or None).

    See Also
    --------
    run_classification : The same models without noise.
    apply_preset : What ``preset`` does to the clouds.
    eppf.preprocessing.GaussianNoise : The noise added.

    Examples
    --------
    The KL 1-NN alone (the networks take longer) at two noise levels:

    >>> import tempfile
    >>> from eppf.experiments import run_noise
    >>> result = run_noise("builtin", quick=True, models=["kl"], levels=[0.0, 0.05], out=tempfile.mkdtemp(),
    ...                    verbose=False)
    >>> [(row["sigma"], row["model"]) for row in result["rows"]]
    [(0.0, 'EPPF KL 1-NN'), (0.05, 'EPPF KL 1-NN')]
    """
    options, settings = TrainingOptions.split("run_noise", settings)
    (models, epochs, pointnet_epochs, pointnet_points, validation_fraction, patience, precision, train_per_class,
     test_per_class) = options.astuple()
    scaling, random_state, n_jobs, quick, cache_dir, verbose, command = ExperimentSettings.from_kwargs(
        "run_noise", settings).astuple()
    from ..preprocessing import GaussianNoise

    log = Logger("noise", verbose)
    models = check_models(models, DEFAULT_NOISE_MODELS)
    if preset is not None:
        preset = get_preset(preset)
        default_levels = preset.noise_levels
    else:
        default_levels = QUICK_LEVELS if quick else DEFAULT_LEVELS
    levels = check_levels(levels if levels is not None else default_levels)
    if preset is not None:
        data = apply_preset(load_or_pass(data, quick=quick, random_state=random_state), preset,
                            random_state=random_state, noise=False)
        log(f"preset {preset.name}: {replace(preset, noise=0.0).describe()}")
    settings, ds, train, test = prepare_training(data, options, scaling, quick, n_jobs, random_state)
    used = np.concatenate([train, test])
    cache = DescriptorCache(cache_dir if cache_dir is not None else (out and f"{out}/cache"), log)
    noise_seeds = draw_seeds(random_state + 1, len(levels))
    rows, acc = [], {MODELS[m]: [] for m in models}
    for sigma, seed in zip(levels, noise_seeds):
        log(f"sigma {sigma:g}: adding noise to {used.size} objects")
        clouds = list(ds.clouds)
        if sigma > 0:
            noisy = GaussianNoise(sigma, relative_to="unit_cube", random_state=seed).fit_transform([clouds[i] for i in used])
            for i, c in zip(used, noisy):
                clouds[i] = c
        descriptors = TrainingDescriptors(settings, cache, clouds, train, test)
        for key in models:
            r = train_and_score(key, settings, clouds, ds.y, train, test, descriptors, log)
            r.pop("y_pred")
            acc[MODELS[key]].append(r["total_accuracy"])
            rows.append({"sigma": sigma, "model": MODELS[key], **{k: round(r[k], 6) for k in METRICS},
                         **{k: r[k] for k in ("epochs", "best_epoch", "fit_s")}})
    base_level = levels[0]
    drops = {}
    if REPORTED_LEVEL in levels and len(levels) > 1:
        j = levels.index(REPORTED_LEVEL)
        drops = {name: v[0] - v[j] for name, v in acc.items()}
    result = {"rows": rows, "accuracy": acc, "levels": levels, "drops": drops, "paths": {}, "cache": cache,
              "preset": preset.name if preset is not None else None}
    for name, d in drops.items():
        log(f"{name}: total accuracy drops {100 * d:.2f} pp from sigma {base_level:g} to {REPORTED_LEVEL:g}")
    if out is None:
        return result
    table = markdown_table(
        ["Model"] + [f"σ={s:g}" for s in levels],
        [[name] + [f"{100 * a:.2f}" for a in v] for name, v in acc.items()],
    )
    f1 = {MODELS[m]: [row["macro_f1"] for row in rows if row["model"] == MODELS[m]] for m in models}
    table += "\n\nF1 (%):\n\n" + markdown_table(
        ["Model"] + [f"σ={s:g}" for s in levels], [[name] + [f"{100 * a:.2f}" for a in v] for name, v in f1.items()])
    notes = []
    if drops:
        notes.append(f"Total-accuracy drop from σ={base_level:g} to σ={REPORTED_LEVEL:g} (percentage points): "
                     + ", ".join(f"{name} {100 * d:.2f}" for name, d in drops.items()) + ".")
    else:
        notes.append(f"σ={REPORTED_LEVEL:g} was not among the levels, so no drop at it is reported.")
        if len(levels) > 1:
            notes.append(f"Total-accuracy drop from σ={base_level:g} to σ={levels[-1]:g} (percentage points): "
                         + ", ".join(f"{name} {100 * (v[0] - v[-1]):.2f}" for name, v in acc.items()) + ".")
    protocol = {
        "task": "total accuracy (%) on the test split, retraining every model at every noise level",
        "noise": "zero-mean Gaussian on x, y, z with standard deviation σ times the largest bounding-box side of "
                 "each object (GaussianNoise(relative_to='unit_cube')), added to training and test objects; "
                 f"noise seeds {noise_seeds}",
        "normals": "re-estimated from the noisy points (PCA, 20 neighbours); clean normals are never used",
        **({"preset": f"`{preset.name}` ({preset.summary}); applied before the noise: "
                      f"{replace(preset, noise=0.0).describe()}"
                      + ("; its σ is swept from 0 here instead of being added once" if preset.noise else "")}
           if preset is not None else {}),
        "data used": f"{train.size} training objects"
                     + (f" (at most {train_per_class} per class)" if train_per_class else "")
                     + f", {test.size} test objects"
                     + (f" (at most {test_per_class} per class)" if test_per_class else ""),
        **settings.protocol(models),
        "descriptor sets computed / read from cache": f"{cache.n_computed} / {cache.n_loaded}",
    }

    on_preset = f", preset {preset.name}" if preset is not None else ""

    def plot(plotting, plt):
        fig, ax = plt.subplots(figsize=(6, 4))
        plotting.plot_noise_curve(np.array(levels), {k: 100 * np.array(v) for k, v in acc.items()}, ax=ax,
                                  ylabel="Total accuracy (%)", xlabel="Noise σ (fraction of the unit cube)")
        ax.set_title(f"Accuracy against noise, {ds.name}{on_preset}")
        return fig

    result["paths"] = write_report(
        out, "noise", title=f"Accuracy against Gaussian noise on {ds.name}{on_preset}", command=command or command_text("noise"),
        data=ds, protocol=protocol, table=table, csv_rows=rows, plot=plot, notes=notes, log=log, elapsed=log.elapsed(),
    )
    return result
