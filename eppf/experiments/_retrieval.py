"""Table II: leave-one-out 1-NN retrieval by symmetric KL divergence."""

import numpy as np

from ..metrics import METRICS, leave_one_out_retrieval, retrieval_scores
from ..registry import make_descriptor
from ._common import (
    ExperimentSettings,
    DESCRIPTORS,
    DETERMINISTIC,
    DescriptorCache,
    ExperimentError,
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

__all__ = ["run_retrieval"]

#: Column titles of the metrics in the Markdown tables.
METRIC_TITLES = {
    "total_accuracy": "Total acc. (%)",
    "mean_class_accuracy": "Mean class acc. (%)",
    "macro_recall": "Mean recall (%)",
    "macro_precision": "Macro precision (%)",
    "macro_f1": "F1 (%)",
}


def score_draws(X_draws, y, n_jobs):
    """Leave-one-out KL retrieval scores of each descriptor draw, as metric -> array."""
    out = {k: [] for k in METRICS}
    for X in X_draws:
        s = retrieval_scores(y, leave_one_out_retrieval(X, y, n_jobs=n_jobs))
        for k in METRICS:
            out[k].append(s[k])
    return {k: np.array(v) for k, v in out.items()}


def csv_metrics(scores):
    """``metric_mean`` and ``metric_std`` columns (fractions) of a scores dict."""
    row = {}
    for k in METRICS:
        row[f"{k}_mean"] = round(float(np.mean(scores[k])), 6)
        row[f"{k}_std"] = round(float(np.std(scores[k])), 6)
    return row


def run_retrieval(
    data="builtin",
    *,
    out=None,
    descriptors=tuple(DESCRIPTORS),
    draws=10,
    **settings,
):
    """Leave-one-out KL 1-NN retrieval of the paper's descriptors (Table II).

    Every object of the data set (both splits) is queried against all the
    others; the label of its nearest descriptor under symmetric KL divergence
    is its answer (:func:`eppf.metrics.leave_one_out_retrieval`). Random
    descriptors are drawn ``draws`` times with seeds from ``random_state``;
    OUR-CVFH is deterministic and drawn once.

    Parameters
    ----------
    data : str or Dataset, default="builtin"
        ``"builtin"``, a ``.npz`` path, or a loaded :class:`Dataset`.
    out : str, default=None
        Folder for ``retrieval.md``, ``retrieval.csv`` and ``retrieval.png``;
        None writes nothing.
    descriptors : sequence of str, default=all
        Keys of :data:`DESCRIPTORS` (``ourcvfh``, ``esf``, ``wahl``,
        ``eppf_short``, ``eppf``).
    draws : int, default=10
        Descriptor draws of the random descriptors.
    **settings
        The shared settings of :class:`ExperimentSettings` (``scaling``,
        ``random_state``, ``n_jobs``, ``quick``, ``cache_dir``, ``verbose``,
        ``command``).

    Returns
    -------
    result : dict
        ``"rows"`` (one dict per descriptor, as in the CSV), ``"scores"``
        (descriptor -> metric -> per-draw array), ``"paths"``, ``"cache"``.

    See Also
    --------
    eppf.metrics.repeated_retrieval : The protocol for one descriptor.
    run_ablation : EPPF with each function removed.

    Examples
    --------
    >>> import os, tempfile
    >>> from eppf.experiments import run_retrieval
    >>> out = tempfile.mkdtemp()
    >>> result = run_retrieval("builtin", quick=True, descriptors=["eppf"], draws=1, out=out, verbose=False)
    >>> sorted(os.listdir(out))
    ['cache', 'retrieval.csv', 'retrieval.md', 'retrieval.png']
    >>> row = result["rows"][0]
    >>> row["descriptor"], 0.0 <= row["total_accuracy_mean"] <= 1.0
    ('EPPF', True)
    """
    scaling, random_state, n_jobs, quick, cache_dir, verbose, command = ExperimentSettings.from_kwargs(
        "run_retrieval", settings).astuple()
    log = Logger("retrieval", verbose)
    draws = check_positive_int(draws, "--draws")
    descriptors = list(descriptors)
    unknown = [d for d in descriptors if d not in DESCRIPTORS]
    if unknown or not descriptors:
        raise ExperimentError(f"--descriptors: unknown {unknown}; choose from {list(DESCRIPTORS)}")
    ds = load_or_pass(data, quick=quick, random_state=random_state)
    scaling = resolve_scaling(scaling, ds)
    cache = DescriptorCache(cache_dir if cache_dir is not None else (out and f"{out}/cache"), log)
    seeds = draw_seeds(random_state, draws)
    log(f"{len(ds.clouds)} objects, {len(ds.target_names)} classes; descriptors {descriptors}, {draws} draw(s)")
    rows, scores = [], {}
    for name in descriptors:
        these = [None] if name in DETERMINISTIC else seeds
        X_draws = []
        for r, seed in enumerate(these):
            est = make_descriptor(name, n_samples=n_samples_setting(quick), scaling=scaling, random_state=seed,
                                  n_jobs=n_jobs)
            X_draws.append(cache.describe(est, ds.clouds, {"all": ds.clouds}, f"{name} draw {r + 1}/{len(these)}")["all"])
        scores[name] = score_draws(X_draws, ds.y, n_jobs)
        log(f"{DESCRIPTORS[name]}: total accuracy {fmt_pct(scores[name]['total_accuracy'])}, "
            f"F1 {fmt_pct(scores[name]['macro_f1'])}")
        rows.append({"descriptor": DESCRIPTORS[name], "draws": len(these), **csv_metrics(scores[name])})
    result = {"rows": rows, "scores": scores, "paths": {}, "cache": cache}
    if out is None:
        return result
    table = markdown_table(
        ["Descriptor", "Draws"] + list(METRIC_TITLES.values()),
        [[DESCRIPTORS[n], len(scores[n]["macro_f1"])] + [fmt_pct(scores[n][k]) for k in METRIC_TITLES] for n in descriptors],
    )
    protocol = {
        "task": "leave-one-out 1-NN retrieval over all objects (both splits), symmetric KL divergence, "
                "zero bins floored at half the smallest positive value of the data set",
        "draws": f"{draws} for the random descriptors (mean ± std, ddof=0), 1 for OUR-CVFH (deterministic); "
                 f"seeds {seeds} from random_state={random_state}",
        "EPPF scaling": scaling,
        "pairs / triplets per object": n_samples_setting(quick),
        "normals": "PCA normals estimated from the points by each descriptor "
                   "(EPPF 20 neighbours, Wahl and OUR-CVFH 10), oriented away from the centroid",
        "descriptors": "; ".join(
            f"{DESCRIPTORS[n]}: `{_params(n, scaling, quick)}`" for n in descriptors),
        "metrics": "mean class accuracy = macro recall for leave-one-out; macro precision is the paper's "
                   "most plausible 'mean recall' (see eppf.metrics.retrieval_scores)",
        "n_jobs": n_jobs,
        "descriptor sets computed / read from cache": f"{cache.n_computed} / {cache.n_loaded}",
    }

    def plot(plotting, plt):
        fig, ax = plt.subplots(figsize=(6, 3.6))
        bars = {DESCRIPTORS[n]: (100 * float(np.mean(scores[n]["macro_f1"])), 100 * float(np.std(scores[n]["macro_f1"])))
                for n in descriptors}
        plotting.plot_scores_bar(bars, ax=ax, ylabel="F1 (%)")
        ax.set_title(f"Leave-one-out KL retrieval, {ds.name}")
        return fig

    result["paths"] = write_report(
        out, "retrieval", title=f"Retrieval (Table II) on {ds.name}", command=command or command_text("retrieval"),
        data=ds, protocol=protocol, table=table, csv_rows=rows, plot=plot, log=log, elapsed=log.elapsed(),
    )
    return result


def _params(name, scaling, quick):
    from ._common import params_text

    return params_text(make_descriptor(name, n_samples=n_samples_setting(quick), scaling=scaling, random_state=0,
                                       n_jobs=1))
