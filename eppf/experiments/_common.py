"""Shared pieces of the experiments: data, descriptor cache, seeds, reports."""

import csv
import io
import os
import platform
import shlex
import sys
import time
from dataclasses import dataclass, field, fields

import numpy as np
from sklearn.utils import check_random_state

from ..registry import DESCRIPTORS as REGISTRY
from ..utils._cache import NEUTRAL_PARAMS, DescriptorCache

__all__ = [
    "Dataset",
    "ExperimentSettings",
    "DescriptorCache",
    "ExperimentError",
    "Logger",
    "draw_seeds",
    "load_data",
    "machine_info",
    "write_report",
]

#: How :func:`load_data` describes the split it makes up for data without one.
GENERATED_SPLIT = "seeded per-class 70/30 split"


class ExperimentError(ValueError):
    """A bad argument or input of an experiment (reported as one line).

    A subclass of :class:`ValueError`; the command line prints its message
    as one line and exits with status 2.

    See Also
    --------
    main : The command line that reports these errors.

    Examples
    --------
    >>> from eppf.experiments import ExperimentError, load_data
    >>> try:
    ...     load_data("no_such_file.npz")
    ... except ExperimentError as exc:
    ...     print(exc)
    --data: no such file or folder: 'no_such_file.npz'
    """


# ------------------------------------------------------------------ logging
@dataclass(frozen=True)
class ExperimentSettings:
    """The settings every experiment takes, written once.

    Every ``run_*`` function accepts these as keyword arguments (``**settings``)
    besides its own, and the command line fills them from its shared options.

    Parameters
    ----------
    scaling : {"auto", "fit", "object", "none"}, default="auto"
        EPPF scaling; ``"auto"`` is ``"fit"`` for the built-in set and
        ``"object"`` for files.
    random_state : int, default=0
        Seed of the data (built-in), the draws, the training and everything else.
    n_jobs : int, default=-1
        Threads of the descriptors, the distance computations and training.
    quick : bool, default=False
        Tiny settings (smaller built-in set, 5,000 pairs per object, one epoch).
    cache_dir : str, default=None
        Descriptor cache; None means ``out/cache`` (or no cache without
        ``out``). The runtime experiment computes everything afresh and
        ignores it.
    verbose : bool, default=True
        Print progress.
    command : str, default=None
        The command line recorded in the report.

    See Also
    --------
    TrainingOptions : The options the classification and noise experiments share.

    Examples
    --------
    >>> from eppf.experiments import ExperimentSettings
    >>> ExperimentSettings.from_kwargs("run_retrieval", {"quick": True}).quick
    True
    """

    scaling: str = "auto"
    random_state: int = 0
    n_jobs: int = -1
    quick: bool = False
    cache_dir: str = None
    verbose: bool = True
    command: str = None

    @classmethod
    def from_kwargs(cls, owner, settings):
        """The settings given as keyword arguments to ``owner``, the others at their defaults.

        Parameters
        ----------
        owner : str
            The function's name, for the error message.
        settings : dict
            Keyword arguments; every key must be a field.

        Returns
        -------
        settings : ExperimentSettings

        Raises
        ------
        TypeError
            If a key is not a setting.
        """
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(settings) - set(names))
        if unknown:
            raise TypeError(f"{owner}() got unexpected keyword argument(s) {unknown}; the shared settings are {names}")
        return cls(**settings)

    def astuple(self):
        """The settings in field order.

        Returns
        -------
        values : tuple
            ``(scaling, random_state, n_jobs, quick, cache_dir, verbose, command)``.
        """
        return tuple(getattr(self, f.name) for f in fields(self))


class Logger:
    """Print progress lines with the time since the experiment started.

    Parameters
    ----------
    name : str
        Prefix of every line (the experiment's name).
    verbose : bool, default=True
        Whether to print at all.
    """

    def __init__(self, name, verbose=True):
        self.name = name
        self.verbose = verbose
        self.start = time.perf_counter()

    def __call__(self, msg):
        """Print ``msg`` with the elapsed time."""
        if self.verbose:
            print(f"[{self.name} {time.perf_counter() - self.start:7.1f}s] {msg}", flush=True)

    def elapsed(self):
        """Seconds since the logger was made."""
        return time.perf_counter() - self.start


# --------------------------------------------------------------------- data
@dataclass
class Dataset:
    """Point clouds of one data set, ready for the experiments.

    Every parameter is kept as the attribute of the same name.

    Parameters
    ----------
    name : str
        Short name (``"builtin"`` or the file's stem); names output folders.
    source : str
        Where the data came from, with the settings that made it.
    clouds : list of ndarray of shape (n_i, 3)
        Coordinates only (float64); normals are always estimated.
    y : ndarray of shape (n_objects,)
        Integer labels.
    target_names : ndarray of shape (n_classes,)
        Class names.
    split : ndarray of shape (n_objects,)
        ``"train"`` or ``"test"``.
    split_source : str
        How the split was made.
    default_scaling : str
        EPPF ``scaling`` used when the experiment is given ``scaling="auto"``.
    _hashes : dict, default={}
        Hashes of the clouds, filled in on first use by the descriptor
        cache; not meant to be passed.

    Attributes
    ----------
    train : ndarray of int
        Indices of the training objects.
    test : ndarray of int
        Indices of the test objects.

    See Also
    --------
    load_data : Load a data set by name or path.

    Examples
    --------
    >>> from eppf.experiments import load_data
    >>> data = load_data("builtin", quick=True)
    >>> data.default_scaling, data.train.size, data.test.size
    ('fit', 40, 20)
    >>> print(data.summary()[1])
    - objects: 60 (40 train / 20 test; split: make_shapes' stratified split (test_size=0.25))
    """

    name: str
    source: str
    clouds: list
    y: np.ndarray
    target_names: np.ndarray
    split: np.ndarray
    split_source: str
    default_scaling: str
    _hashes: dict = field(default_factory=dict, repr=False)

    @property
    def train(self):
        """Indices of the training objects."""
        return np.flatnonzero(self.split == "train")

    @property
    def test(self):
        """Indices of the test objects."""
        return np.flatnonzero(self.split == "test")

    def summary(self):
        """Describe the data set in Markdown.

        Returns
        -------
        lines : list of str
            Bullet lines: source, objects and split, classes, points per object.
        """
        sizes = np.array([len(c) for c in self.clouds])
        counts = np.bincount(self.y, minlength=len(self.target_names))
        per_class = ", ".join(f"{n} {c}" for n, c in zip(self.target_names, counts))
        return [
            f"- data: {self.source}",
            f"- objects: {len(self.clouds)} ({self.train.size} train / {self.test.size} test; split: {self.split_source})",
            f"- classes ({len(self.target_names)}): {per_class}",
            f"- points per object: median {int(np.median(sizes))}, min {sizes.min()}, max {sizes.max()}",
        ]


def _stratified_split(y, test_size, random_state):
    """``round(test_size * n_c)`` random test objects of every class ``c``, at least one left for training."""
    rng = check_random_state(random_state)
    split = np.full(y.size, "train", dtype="<U5")
    for label in np.unique(y):
        members = np.flatnonzero(y == label)
        n_test = min(int(round(test_size * members.size)), members.size - 1)
        split[rng.permutation(members)[:n_test]] = "test"
    return split


def data_name(spec):
    """Short name of a data set spec: ``"builtin"`` or the file's or folder's stem (names output folders)."""
    spec = os.fspath(spec)
    return spec if spec == "builtin" else os.path.splitext(os.path.basename(os.path.normpath(spec)))[0]


def load_data(spec, *, quick=False, random_state=0, n_per_class=None, n_points=None, on_error="raise"):
    """Load the data set named by ``spec``.

    Parameters
    ----------
    spec : str or path-like
        ``"builtin"``: :func:`eppf.datasets.make_shapes` (ten synthetic
        classes, its own stratified split); a folder with one subfolder per
        class, read by :func:`eppf.datasets.load_folder` (meshes sampled with
        ``n_points`` or 2,048 points); otherwise a ``.npz`` file in the flat
        layout read by :func:`eppf.datasets.load_npz`. The split of the
        folder or file is used; data without one gets a seeded stratified
        70/30 split.
    quick : bool, default=False
        Smaller built-in set (6 objects per class, 256 points).
    random_state : int, default=0
        Seed of the built-in set and of a missing split.
    n_per_class, n_points : int, default=None
        Size of the built-in set (defaults: 40 and 1024, or 6 and 256 with
        ``quick``); ``n_points`` also resamples the objects of a folder.
    on_error : {"raise", "skip"}, default="raise"
        A file of a folder that cannot be read stops the loading, or is
        skipped with a warning (:func:`eppf.datasets.load_folder`); the
        returned ``source`` then says how many were skipped, so a report
        shows that its figures are not those of the whole folder.

    Returns
    -------
    data : Dataset
        The clouds (xyz only), labels and split.

    Raises
    ------
    ExperimentError
        If the file or folder does not exist or cannot be read.

    See Also
    --------
    Dataset : What is returned.
    eppf.datasets.load_npz : The ``.npz`` layout read here.

    Examples
    --------
    >>> from eppf.experiments import load_data
    >>> data = load_data("builtin", quick=True)
    >>> data.name, len(data.clouds), data.clouds[0].shape
    ('builtin', 60, (256, 3))
    >>> data.train.size + data.test.size == len(data.clouds)
    True
    """
    spec = os.fspath(spec)
    if spec == "builtin":
        from ..datasets import make_shapes

        n_per_class = n_per_class or (6 if quick else 40)
        n_points = n_points or (256 if quick else 1024)
        b = make_shapes(n_per_class, n_points=n_points, random_state=random_state)
        source = f"built-in synthetic shapes (make_shapes({n_per_class}, n_points={n_points}, random_state={random_state}))"
        return Dataset(
            name="builtin",
            source=source,
            clouds=[np.ascontiguousarray(c[:, :3], dtype=np.float64) for c in b.data],
            y=np.asarray(b.target, dtype=np.int64),
            target_names=np.asarray(b.target_names).astype(str),
            split=np.asarray(b.split).astype(str),
            split_source="make_shapes' stratified split (test_size=0.25)",
            default_scaling="fit",
        )
    if on_error not in ("raise", "skip"):
        raise ExperimentError(f"on_error must be 'raise' or 'skip', got {on_error!r}")
    if not os.path.exists(spec):
        raise ExperimentError(f"--data: no such file or folder: {spec!r}")
    from ..datasets import load_folder, load_npz

    try:
        if os.path.isdir(spec):
            b = load_folder(spec, n_points=n_points, normals=False, on_error=on_error, random_state=random_state)
        else:
            b = load_npz(spec)
    except (ValueError, OSError) as exc:
        raise ExperimentError(f"--data {spec!r}: {exc}") from None
    y = np.asarray(b.target, dtype=np.int64)
    if b.split is not None:
        split = np.asarray(b.split).astype(str)
        bad = sorted(set(split) - {"train", "test"})
        if bad:
            raise ExperimentError(f"--data {spec!r}: split holds values other than 'train'/'test': {bad}")
        split_source = "the folder's split" if os.path.isdir(spec) else "the file's split"
    else:
        split = _stratified_split(y, 0.3, random_state)
        split_source = f"{GENERATED_SPLIT} (random_state={random_state})"
    clouds = [np.ascontiguousarray(c[:, :3], dtype=np.float64) for c in b.data]
    skipped = len(getattr(b, "skipped", None) or [])
    source = f"`{_base_name(spec)}`"
    if skipped:
        source += (f" ({skipped} of {skipped + len(clouds)} files could not be read and were left out, the first: "
                   f"`{os.path.relpath(b.skipped[0][0], spec)}`)")
    return Dataset(
        name=data_name(spec),
        source=source,
        clouds=clouds,
        y=y,
        target_names=np.asarray(b.target_names).astype(str),
        split=split,
        split_source=split_source,
        default_scaling="object",
    )


def subsample_train(data, per_class, random_state, part="train"):
    """Indices of at most ``per_class`` objects of every class of one split (seeded)."""
    train = data.train if part == "train" else data.test
    if per_class is None:
        return train
    rng = check_random_state(random_state)
    keep = []
    for label in np.unique(data.y[train]):
        members = train[data.y[train] == label]
        if members.size > per_class:
            members = np.sort(rng.choice(members, per_class, replace=False))
        keep.append(members)
    return np.sort(np.concatenate(keep))


def draw_seeds(random_state, n):
    """The ``n`` descriptor seeds of an experiment (as :func:`eppf.metrics.repeated_retrieval` draws them)."""
    rng = check_random_state(random_state)
    return [int(s) for s in rng.randint(np.iinfo(np.int32).max, size=n)]


# -------------------------------------------------------------------- cache
# ------------------------------------------------------------------ machine
def machine_info():
    """CPU model, core count and library versions, as Markdown lines."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        n_cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        n_cores = os.cpu_count()
    versions = []
    from importlib.metadata import PackageNotFoundError, version

    for pkg in ("eppf", "numpy", "scikit-learn", "torch", "skorch"):
        try:
            versions.append(f"{pkg} {version(pkg)}")
        except PackageNotFoundError:
            pass
    load = ""
    if hasattr(os, "getloadavg"):
        load = ", load average at the end {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    return [
        f"- CPU: {cpu}, {n_cores} cores available{load}",
        f"- {platform.platform()}, Python {sys.version.split()[0]}",
        f"- {', '.join(versions)}",
    ]


def cpu_model():
    """The CPU model name (first line of the machine description)."""
    return machine_info()[0]


# ------------------------------------------------------------------ reports
def fmt_pct(values):
    """``mean ± std`` in percent of an array of fractions (no ± for one value)."""
    v = 100 * np.asarray(values, dtype=float)
    if v.size == 1:
        return f"{v[0]:.2f}"
    return f"{v.mean():.2f} ± {v.std():.2f}"


def markdown_table(header, rows):
    """A GitHub Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def write_report(out, name, *, title, command, data, protocol, table, csv_rows, plot=None, notes=(), log=None,
                 elapsed=None):
    """Write ``NAME.md``, ``NAME.csv`` and ``NAME.png`` into ``out``.

    Parameters
    ----------
    out : str
        Output folder (made if missing).
    name : str
        File stem.
    title : str
        Heading of the Markdown file.
    command : str
        The command line (or call) that made the results. It is recorded
        without machine-local paths: the value of ``--data`` becomes the
        file's or folder's base name, an absolute ``--out`` its base name, and
        ``--cache-dir`` (which does not change the results) is dropped.
    data : Dataset
        Described in the Markdown file.
    protocol : dict
        Settings, one Markdown bullet each.
    table : str
        The results as a Markdown table.
    csv_rows : list of dict
        Rows of the CSV file (the keys of the first row are the columns).
    plot : callable, default=None
        ``plot(plotting, plt)`` draws and returns a matplotlib figure;
        skipped with a warning when matplotlib or ``eppf.plotting`` is missing.
    notes : sequence of str
        Paragraphs after the table.
    log : callable, default=None
        Progress printer.
    elapsed : float, default=None
        Wall seconds of the experiment.

    Returns
    -------
    paths : dict
        ``"md"``, ``"csv"`` and (when drawn) ``"png"`` file paths.
    """
    log = log or print
    os.makedirs(out, exist_ok=True)
    paths = {"md": os.path.join(out, f"{name}.md"), "csv": os.path.join(out, f"{name}.csv")}
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(csv_rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(csv_rows)
    with open(paths["csv"], "w", newline="", encoding="utf-8") as f:
        f.write(buf.getvalue())
    png = None
    if plot is not None:
        png = _draw(plot, os.path.join(out, f"{name}.png"), log)
        if png:
            paths["png"] = png
    md = [f"# {title}", "", "Made by:", "", "```", portable_command(command), "```", "", "## Data", ""]
    md += data.summary()
    md += ["", "## Protocol", ""]
    md += [f"- {k}: {v}" for k, v in protocol.items()]
    if elapsed is not None:
        md.append(f"- wall time of the whole experiment: {elapsed:.0f} s")
    md += ["", "## Results", "", table, ""]
    for n in notes:
        md += [n, ""]
    if png:
        md += [f"![{name}]({os.path.basename(png)})", ""]
    md += ["## Machine", ""]
    md += machine_info()
    md.append("")
    with open(paths["md"], "w", encoding="utf-8") as f:
        f.write("\n".join(md))
    log(f"wrote {', '.join(paths.values())}")
    return paths


def _base_name(path):
    """The last component of ``path`` (a folder keeps a trailing ``/``)."""
    path = os.fspath(path)
    base = os.path.basename(os.path.normpath(path))
    return base + "/" if os.path.isdir(path) else base


def portable_command(command):
    """``command`` with its machine-local paths removed, for a report.

    ``--data PATH`` keeps only the base name of ``PATH`` (``builtin`` stays),
    an absolute ``--out PATH`` keeps its base name, and ``--cache-dir PATH`` is
    dropped, so a report regenerated on another machine reads the same.
    A command that is not a shell-like command line is returned unchanged.

    Parameters
    ----------
    command : str
        The command line.

    Returns
    -------
    command : str
        The command line to record.

    Examples
    --------
    >>> from eppf.experiments._common import portable_command
    >>> portable_command("eppf-experiments retrieval --data my_sets/modelnet10_1024.npz --cache-dir my_cache")
    'eppf-experiments retrieval --data modelnet10_1024.npz'
    """
    try:
        tokens = shlex.split(command)
    except ValueError:
        return command
    if "#" in tokens:  # a recorded function call, not a command line
        return command
    out, k = [], 0
    while k < len(tokens):
        tok = tokens[k]
        opt, eq, value = tok.partition("=")
        if opt in ("--data", "--out", "--cache-dir"):
            if not eq:
                if k + 1 >= len(tokens):
                    out.append(tok)
                    break
                value = tokens[k + 1]
                k += 1
            k += 1
            if opt == "--cache-dir":
                continue
            if opt == "--data" and value != "builtin":
                value = _base_name(value)
            elif opt == "--out" and os.path.isabs(value):
                value = os.path.basename(os.path.normpath(value))
            out += [opt, value]
            continue
        out.append(tok)
        k += 1
    return shlex.join(out)


def _draw(plot, path, log):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("warning: matplotlib is not installed; no plot written")
        return None
    try:
        from .. import plotting
    except ImportError as exc:
        log(f"warning: eppf.plotting is unavailable ({exc}); drawing a plain plot")
        plotting = _PlainPlots(plt)
    fig = plot(plotting, plt)
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)
    return path


# -------------------------------------------------------------- descriptors
#: Descriptor keys and their names in the tables (the paper's Table II order).
DESCRIPTORS = {name: spec.title for name, spec in REGISTRY.items()}
#: Descriptors without random sampling (one draw suffices).
DETERMINISTIC = tuple(name for name, spec in REGISTRY.items() if spec.deterministic)
SCALINGS = ("auto", "fit", "object", "none")


def resolve_scaling(scaling, data):
    """EPPF's ``scaling`` for ``data``: ``"auto"`` is the data set's default.

    The built-in shapes share one unit (``"fit"``, the paper's data-set
    scaling); files may hold raw CAD units spanning orders of magnitude, so
    they default to per-object scaling (``"object"``). Pass ``"fit"`` for a
    file in one physical unit (e.g. meters) to keep size information.
    """
    if scaling not in SCALINGS:
        raise ExperimentError(f"--scaling must be one of {SCALINGS}, got {scaling!r}")
    return data.default_scaling if scaling == "auto" else scaling


def n_samples_setting(quick):
    """Random pairs (EPPF, Wahl) or triplets (ESF) per object: 20,000, or 5,000 with ``quick``."""
    return 5000 if quick else 20000


def params_text(est):
    """The parameters of an estimator that matter, for the protocol."""
    p = {k: v for k, v in est.get_params(deep=False).items() if k not in NEUTRAL_PARAMS + ("random_state", "device")}
    return f"{type(est).__name__}(" + ", ".join(f"{k}={v!r}" for k, v in p.items()) + ")"


class _PlainPlots:
    """Minimal stand-ins for the two ``eppf.plotting`` functions the experiments use."""

    def __init__(self, plt):
        self.plt = plt

    def _ax(self, ax):
        return ax if ax is not None else self.plt.subplots(figsize=(6, 4))[1]

    def plot_scores_bar(self, scores, *, ax=None, ylabel="F1", errors=None, sort=False):
        ax = self._ax(ax)
        names = list(scores)
        vals = [scores[n][0] if isinstance(scores[n], tuple) else scores[n] for n in names]
        errs = [scores[n][1] if isinstance(scores[n], tuple) else 0.0 for n in names]
        ax.bar(range(len(names)), vals, yerr=errs, capsize=3)
        ax.set_xticks(range(len(names)), names, rotation=20, ha="right")
        ax.set_ylabel(ylabel)
        return ax

    def plot_noise_curve(self, sigmas, scores, *, ax=None, ylabel="accuracy", xlabel="noise sigma"):
        ax = self._ax(ax)
        for name, v in scores.items():
            v = np.asarray(v, dtype=float)
            ax.plot(sigmas, v if v.ndim == 1 else v.mean(axis=1), marker="o", label=name)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.legend()
        return ax


# ------------------------------------------------------------------ helpers
def check_positive_int(value, name):
    """``value`` as an int >= 1, or an ExperimentError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ExperimentError(f"{name} must be a positive int, got {value!r}")
    return int(value)


def command_text(name, **kwargs):
    """How a function call is recorded when no command line is given."""
    return f"eppf.experiments.run_{name}(...)  # function call; see the protocol for its settings"


def load_or_pass(data, *, quick, random_state):
    """``data`` itself if it is a :class:`Dataset`, else :func:`load_data` of it."""
    if isinstance(data, Dataset):
        return data
    return load_data(data, quick=quick, random_state=random_state)
