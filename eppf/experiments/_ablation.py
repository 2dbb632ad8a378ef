"""The paper's function ablation: EPPF retrieval with one point-pair function left out."""

import numpy as np

from .. import FUNCTIONS
from ..metrics import METRICS
from ..registry import make_descriptor
from ._common import (
    ExperimentSettings,
    DescriptorCache,
    Logger,
    check_positive_int,
    command_text,
    draw_seeds,
    fmt_pct,
    load_or_pass,
    markdown_table,
    n_samples_setting,
    resolve_scaling,
    write_report,
)
from ._retrieval import METRIC_TITLES, csv_metrics, score_draws

__all__ = ["run_ablation"]


def ablation_configs():
    """``(label, removed function or "", functions)`` for all four, then each one removed."""
    configs = [("all four", "", FUNCTIONS)]
    configs += [(f"without {f}", f, tuple(g for g in FUNCTIONS if g != f)) for f in FUNCTIONS]
    return configs


def run_ablation(
    data="builtin",
    *,
    out=None,
    draws=10,
    **settings,
):
    """Leave-one-out KL retrieval of EPPF with each point-pair function removed in turn.

    Five descriptors: all four functions (distance, angle, normal,
    occupancy), then each one left out (``EPPFTransformer(functions=...)``,
    the remaining functions keep their bins). Each is drawn ``draws`` times
    with the same seeds as :func:`run_retrieval`, so the "all four" row
    shares its cached descriptors with the EPPF row there.

    Parameters
    ----------
    data : str or Dataset, default="builtin"
        ``"builtin"``, a ``.npz`` path, or a loaded :class:`Dataset`.
    out : str, default=None
        Folder for ``ablation.md``, ``ablation.csv`` and ``ablation.png``.
    draws : int, default=10
        Descriptor draws per configuration.
    **settings
        The shared settings of :class:`ExperimentSettings` (``scaling``,
        ``random_state``, ``n_jobs``, ``quick``, ``cache_dir``, ``verbose``,
        ``command``).

    Returns
    -------
    result : dict
        ``"rows"`` (as in the CSV), ``"scores"`` (label -> metric -> per-draw
        array), ``"paths"``, ``"cache"``.

    See Also
    --------
    run_retrieval : The same protocol over all descriptors.
    eppf.descriptors.EPPFTransformer : Its ``functions`` parameter removes a function.

    Examples
    --------
    >>> import tempfile
    >>> from eppf.experiments import run_ablation
    >>> result = run_ablation("builtin", quick=True, draws=1, out=tempfile.mkdtemp(), verbose=False)
    >>> [row["removed"] for row in result["rows"]]
    ['', 'distance', 'angle', 'normal', 'occupancy']
    """
    scaling, random_state, n_jobs, quick, cache_dir, verbose, command = ExperimentSettings.from_kwargs(
        "run_ablation", settings).astuple()
    log = Logger("ablation", verbose)
    draws = check_positive_int(draws, "--draws")
    ds = load_or_pass(data, quick=quick, random_state=random_state)
    scaling = resolve_scaling(scaling, ds)
    cache = DescriptorCache(cache_dir if cache_dir is not None else (out and f"{out}/cache"), log)
    seeds = draw_seeds(random_state, draws)
    rows, scores, marginals = [], {}, None
    for label, removed, functions in ablation_configs():
        X_draws = []
        for r, seed in enumerate(seeds):
            est = make_descriptor("eppf", n_samples=n_samples_setting(quick), scaling=scaling, random_state=seed,
                                  n_jobs=n_jobs, functions=functions)
            X_draws.append(cache.describe(est, ds.clouds, {"all": ds.clouds}, f"EPPF {label} draw {r + 1}/{draws}")["all"])
        scores[label] = score_draws(X_draws, ds.y, n_jobs)
        if label == "all four":
            # how the weighted histogram mass spreads over each function's bins (first draw)
            H = X_draws[0].reshape((-1,) + tuple(est.get_params()["n_bins"]))
            marginals = {f: H.sum(axis=tuple(a + 1 for a in range(4) if a != i)).mean(axis=0)
                         for i, f in enumerate(FUNCTIONS)}
        log(f"{label}: F1 {fmt_pct(scores[label]['macro_f1'])}, total accuracy {fmt_pct(scores[label]['total_accuracy'])}")
        rows.append({"configuration": label, "removed": removed, "functions": " ".join(functions), "draws": draws,
                     "n_bins": X_draws[0].shape[1], **csv_metrics(scores[label])})
    base = {k: float(np.mean(scores["all four"][k])) for k in METRICS}
    for row, label in zip(rows, scores):
        row["f1_drop"] = round(base["macro_f1"] - row["macro_f1_mean"], 6) + 0.0
        row["total_accuracy_drop"] = round(base["total_accuracy"] - row["total_accuracy_mean"], 6) + 0.0
    result = {"rows": rows, "scores": scores, "paths": {}, "cache": cache}
    if out is None:
        return result
    titles = {k: METRIC_TITLES[k] for k in ("total_accuracy", "mean_class_accuracy", "macro_f1")}
    table = markdown_table(
        ["Configuration", "Bins"] + list(titles.values()) + ["F1 drop (pp)", "Total acc. drop (pp)"],
        [[row["configuration"], row["n_bins"]] + [fmt_pct(scores[row["configuration"]][k]) for k in titles]
         + [f"{100 * row['f1_drop']:.2f}", f"{100 * row['total_accuracy_drop']:.2f}"] for row in rows],
    )
    notes = ["Mean share of the (distance-weighted) histogram mass in each bin of each function, all four "
             "functions, first draw: " + "; ".join(
                 f"{f}: " + ", ".join(f"{100 * v:.1f}%" for v in m) for f, m in marginals.items())
             + ". A function whose mass sits in one bin carries little information, so removing it changes little."]
    protocol = {
        "task": "leave-one-out 1-NN retrieval over all objects by symmetric KL divergence (as in retrieval)",
        "descriptor": f"EPPFTransformer(n_bins=(20, 4, 5, 3), n_pairs={n_samples_setting(quick)}, c=1.2, "
                      f"scaling={scaling!r}, functions=...): the left-out function's axis is dropped, the "
                      "others keep their bins",
        "draws": f"{draws} per configuration (mean ± std), seeds {seeds} from random_state={random_state}",
        "drop": "score of all four minus score of the configuration, in percentage points (positive: the "
                "removed function helped)",
        "n_jobs": n_jobs,
        "descriptor sets computed / read from cache": f"{cache.n_computed} / {cache.n_loaded}",
    }

    def plot(plotting, plt):
        fig, ax = plt.subplots(figsize=(6, 3.6))
        bars = {label: (100 * float(np.mean(s["macro_f1"])), 100 * float(np.std(s["macro_f1"])))
                for label, s in scores.items()}
        plotting.plot_scores_bar(bars, ax=ax, ylabel="F1 (%)")
        ax.set_title(f"EPPF function ablation, {ds.name}")
        return fig

    result["paths"] = write_report(
        out, "ablation", title=f"EPPF function ablation on {ds.name}", command=command or command_text("ablation"),
        data=ds, protocol=protocol, table=table, csv_rows=rows, plot=plot, notes=notes, log=log, elapsed=log.elapsed(),
    )
    return result
