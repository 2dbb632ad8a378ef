"""What every subcommand shares: option types and groups, the table of
subcommands, output helpers, and the one way files are read.

Reading
-------
:func:`read_inputs` is the only reader of the command line. Folders are
searched recursively for every extension of
:func:`eppf.io.supported_extensions` (in any case; hidden files are skipped),
and every file is read by :func:`eppf.io.read_point_cloud` with
``normals="auto"`` and the sampling settings of :func:`sampling_from_args`
(meshes: ``n_points`` or ``resolution``, 2,048 points when neither is given).
Each file's seed is the one :func:`eppf.datasets.load_folder` gives it: a
hash of the base seed and the file's path relative to the folder named on
the command line (relative to its own folder for a file named directly), so
a file is the same cloud in ``train``, ``predict``, ``describe``,
``retrieve`` and ``evaluate`` and in ``load_folder``. A folder of class
subfolders (``<class>/...``, ``train|test/<class>/...`` or
``<class>/train|test/...``, by the rule of
:func:`eppf.datasets._folder.folder_layout` that ``load_folder`` follows)
gives labels, class names and the split.
"""

import argparse
import csv
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..registry import CLASSIFIERS, DESCRIPTORS, make_descriptor
from ..utils import progress_bar
from ..utils._atomic import atomic_write

__all__ = []

# ---------------------------------------------------------------------------
# The table of subcommands
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Command:
    """One subcommand: its name, help line, argument setup and runner."""

    name: str
    help: str
    description: str
    add_arguments: object
    run: object
    parser_kwargs: dict = field(default_factory=dict)


#: Subcommand name -> :class:`Command`, in the order of ``eppf --help``.
SUBCOMMANDS = {}


def register(command):
    """Add a :class:`Command` to :data:`SUBCOMMANDS` and return it."""
    if command.name in SUBCOMMANDS:
        raise RuntimeError(f"subcommand {command.name!r} registered twice")
    SUBCOMMANDS[command.name] = command
    return command


# ---------------------------------------------------------------------------
# Option types and shared option groups
# ---------------------------------------------------------------------------

DESCRIPTOR_NAMES = tuple(DESCRIPTORS)
#: Names of 0.1 kept as aliases of registry classifiers.
CLASSIFIER_ALIASES = {"knn": "kl", "cnn": "4d"}
CLASSIFIER_NAMES = tuple(CLASSIFIERS) + tuple(CLASSIFIER_ALIASES)

MODEL_HELP = ("a model saved by 'eppf train' (safe to load from anyone: the model format cannot run code; "
              "pickled eppf 0.1 models need --trust)")
TRUST_HELP = ("load a pickled (eppf 0.1, joblib) model file; pickles can run any code while loading, so use "
              "this only for files you made yourself")


def positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def n_jobs_type(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if value == 0:
        raise argparse.ArgumentTypeError("0 has no meaning; use a positive count or -1 for all cores")
    return value


def add_runtime(parser, n_jobs=True, random_state=True):
    """``--n-jobs``, ``--random-state`` and ``--no-progress``: the same in every subcommand (a command whose
    work draws nothing at random, or draws it with seeds of its own, leaves ``--random-state`` out; one that
    draws only some of those things gives, as ``random_state``, the help that names them)."""
    if n_jobs:
        parser.add_argument("--n-jobs", type=n_jobs_type, default=-1, help="threads (default: -1, all cores)")
    if random_state:
        parser.add_argument("--random-state", type=int, default=0,
                            help=random_state if isinstance(random_state, str) else
                            "seed of everything random: descriptor draws, mesh sampling, splits, a scene's "
                            "RANSAC ground plane (default: 0)")
    parser.add_argument("--no-progress", action="store_true", help="hide progress bars and per-epoch lines")


#: ``--n-pairs`` when not given.
DEFAULT_N_PAIRS = 20000


def add_descriptor(parser, choice=True, default="eppf"):
    """``--descriptor``, ``--n-pairs``, ``--scaling`` and ``--normal-neighbors``."""
    if choice:
        parser.add_argument("--descriptor", choices=DESCRIPTOR_NAMES, default=default,
                            help=f"which registered descriptor (default: {default})")
    parser.add_argument("--n-pairs", type=positive_int, default=DEFAULT_N_PAIRS,
                        help="random samples per object: point pairs (EPPF, Wahl) or triplets (ESF); "
                             f"deterministic descriptors ignore it (default: {DEFAULT_N_PAIRS})")
    parser.add_argument("--scaling", choices=["fit", "object", "none"], default=None,
                        help="descriptor scaling: 'fit' (the paper's data-set scale, EPPF's default), "
                             "'object' (each object to unit size; for files in mixed units) or 'none'; "
                             "descriptors without this setting keep their own")
    parser.add_argument("--normal-neighbors", type=positive_int, default=None,
                        help="neighbours of the PCA normal estimation (default: the descriptor's)")


def add_sampling(parser):
    """``--n-points``, ``--resolution`` (how meshes are sampled) and ``--on-error``."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--n-points", type=positive_int, default=None,
                       help="points per object: meshes are sampled with this many (default 2,048), point "
                            "files resampled to it (default: kept as they are)")
    group.add_argument("--resolution", type=positive_float, default=None,
                       help="instead of --n-points, sample meshes on a voxel grid of this cell size")
    add_on_error(parser, refusable=True)  # (refused with --built-in: no file is read)


def add_on_error(parser, refusable=False):
    """``--on-error``; ``refusable``: its default is None (read as "skip"), so that a mode of the command that
    reads no files can refuse it when given instead of ignoring it."""
    parser.add_argument("--on-error", choices=["skip", "raise"], default=None if refusable else "skip",
                        help="a file that cannot be read: skip it with a summary on stderr (default) or stop")


def on_error_of(args):
    """``--on-error`` as the readers take it: "skip" where it was not given (:func:`add_on_error`'s None)."""
    return getattr(args, "on_error", None) or "skip"


def add_data_source(parser):
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--data", metavar="FILE.npz|FOLDER",
                       help="a .npz data set (points, offsets, labels, class_names[, split][, ids]) or a folder "
                            "with one subfolder of point cloud or mesh files per class (optionally inside "
                            "train/ and test/)")
    group.add_argument("--built-in", action="store_true", help="the built-in synthetic shapes")


def progress_of(args):
    return not getattr(args, "no_progress", False)


def count(n, word, plural=None):
    """``"1 point"``, ``"2 points"``: ``n`` and ``word``, plural (``word + "s"`` unless given) unless 1."""
    return f"{n} {word if n == 1 else (plural or word + 's')}"


def warn(cmd, text):
    print(f"{cmd}: warning: {text}", file=sys.stderr)


def descriptor_settings(args, progress=None):
    """Settings of :func:`eppf.registry.make_descriptor` from the shared options."""
    progress = progress_of(args) if progress is None else progress
    settings = dict(n_samples=args.n_pairs, n_jobs=args.n_jobs, random_state=args.random_state,
                    verbose=1 if progress else 0)
    if args.scaling is not None:
        settings["scaling"] = args.scaling
    if getattr(args, "normal_neighbors", None) is not None:
        settings["n_neighbors"] = args.normal_neighbors
    return settings


def descriptor_from_args(args, progress=None, **params):
    """The ``--descriptor`` of the shared options (:func:`eppf.registry.make_descriptor`), with ``params``;
    a ``--normal-neighbors`` it cannot use is refused."""
    name = args.descriptor
    settings = dict(descriptor_settings(args, progress), **params)
    if "n_neighbors" in settings and "n_neighbors" not in DESCRIPTORS[name].estimator_class()().get_params():
        raise ValueError(f"--normal-neighbors: the {name} descriptor estimates no normals")
    return make_descriptor(name, **settings)


# ---------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------


def check_output(path, suffixes=None, option="--output"):
    """Refuse an output path before any work: wrong suffix, missing folder, a folder."""
    if path is None:
        return None
    path = str(path)
    if suffixes and not path.lower().endswith(tuple(suffixes)):
        raise ValueError(f"{option} must end in {' or '.join(suffixes)}, got {path}")
    if os.path.isdir(path):
        raise ValueError(f"{option} {path} is a folder; give a file name")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise ValueError(f"{option} {path}: the folder {os.path.dirname(path) or '.'} does not exist")
    if not os.access(parent, os.W_OK):
        raise ValueError(f"{option} {path}: the folder {os.path.dirname(path) or '.'} is not writable")
    return path


#: Starts of the CSV tables the commands write (predict, predict --segment, retrieve, evaluate).
OWN_CSV_HEADERS = ("file,class", "segment,n_points,", "query,query_label,", "evaluation,metric,percent")


def is_own_output(path):
    """True for a file that an eppf command may have written: a CSV table with one of their headers, a
    descriptor ``.npz`` of ``describe``, any ``.npy`` (a descriptor matrix cannot be told from a point cloud)."""
    import zipfile

    low = str(path).lower()
    try:
        if low.endswith(".npy"):
            return True
        if low.endswith(".npz"):
            with zipfile.ZipFile(path) as zf:
                return "descriptors.npy" in zf.namelist()
        with open(path, newline="", encoding="utf-8", errors="replace") as fh:
            return fh.readline(200).startswith(OWN_CSV_HEADERS)
    except (OSError, zipfile.BadZipFile):
        return False


def check_not_input(output, inputs, option="--output"):
    """Refuse, before any work, an output that is one of the inputs: writing it would replace the input.

    ``inputs`` are ``(option, path)`` pairs (option ``None`` for a positional input), ``None`` paths left out.
    The same file under another spelling, through a symbolic link or as a hard link is found with
    :func:`os.path.samefile`; an output that does not exist yet replaces nothing. An output inside an input
    folder is left out of its listing (:func:`find_files`), so it must be this command's own earlier output
    (:func:`is_own_output`) when it is a file the readers read: a data file there is refused too.
    """
    if output is None or not os.path.exists(output):
        return
    for name, path in inputs:
        if path is None:
            continue
        try:
            same = os.path.samefile(output, path)
        except OSError:  # an input that does not exist: its command names it
            continue
        what = f"the input {path}" if name is None else f"the {name} {path}"
        if same:
            raise ValueError(f"{option} {output} is {what} (the same file); writing it would replace that "
                             "input, so give another output file")
        if os.path.isdir(path) and within_folder(output, path) and _readable_point_file(output) \
                and not is_own_output(output):
            where = f"the input folder {path}" if name is None else f"the {name} folder {path}"
            raise ValueError(f"{option} {output} is a point file in {where}; writing it would replace that "
                             "object, so give another output file")


def within_folder(path, folder):
    """True when ``path`` is ``folder`` or lies inside it, after links are resolved (case-folded where the file
    system folds case)."""
    real, root = (os.path.normcase(os.path.realpath(p)) for p in (path, folder))
    return real == root or real.startswith(os.path.join(root, ""))


def _readable_point_file(path):
    from ..io import supported_extensions

    name = os.path.basename(str(path))
    return not name.startswith(".") and name.lower().endswith(tuple(e.lower() for e in supported_extensions()))


def check_distinct_outputs(outputs):
    """Refuse two outputs of one command that are one file (``(option, path)`` pairs; ``None`` paths left out):
    the second would replace the first."""
    seen = {}
    for name, path in outputs:
        if path is None:
            continue
        key = os.path.normcase(os.path.realpath(path))
        same = seen.get(key)
        if same is None and os.path.exists(path):
            same = next((s for s in seen.values() if os.path.exists(s[1]) and os.path.samefile(s[1], path)), None)
        if same is not None:
            raise ValueError(f"{name} {path} and {same[0]} {same[1]} are the same file; give two file names")
        seen[key] = (name, path)


def emit(rows, header, output, out):
    """Rows as a printed table, or as a CSV file written atomically."""
    out = out or sys.stdout
    if output:
        # UTF-8 on every system; a file name that is not UTF-8 goes back as its own bytes (surrogateescape)
        with atomic_write(output, "w", newline="", encoding="utf-8", errors="surrogateescape") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            for row in rows:
                writer.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in row])
        print(f"eppf: {count(len(rows), 'row')} -> {output}", file=out)
        return
    cells = [[f"{v:.4f}" if isinstance(v, float) else str(v) for v in row] for row in rows]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, h in enumerate(header)]
    print(" | ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip(), file=out)
    print("-+-".join("-" * w for w in widths), file=out)
    for c in cells:
        print(" | ".join(v.ljust(w) for v, w in zip(c, widths)).rstrip(), file=out)


# ---------------------------------------------------------------------------
# Reading: the one way
# ---------------------------------------------------------------------------

#: The seed rule saved in models, so that a later eppf can tell whether it still applies.
SEED_RULE = "blake2b-relpath-v1"


def sampling_from_args(args):
    """The sampling settings of the reading options (saved in models by ``train``)."""
    return {"n_points": getattr(args, "n_points", None), "resolution": getattr(args, "resolution", None),
            "normals": "auto", "random_state": int(args.random_state), "seed_rule": SEED_RULE}


def file_seeds(random_state, root, files):
    """Per-file sampling seeds, exactly those of :func:`eppf.datasets.load_folder`.

    The rule is the folder loaders' (``eppf.datasets``), so the command line
    and :func:`eppf.datasets.load_folder` seed every file alike.
    """
    from ..datasets._loaders import file_seeds as loader_seeds

    return loader_seeds(random_state, root, files)


#: The index CSV that ``eppf segment`` writes beside the object files, and the start of its header.
SEGMENT_INDEX = "segments.csv"
SEGMENT_INDEX_HEADER = "segment,file,n_points,x,y,z"


def is_segment_index(path):
    """True for the index of ``eppf segment`` (a CSV, which is also a point file extension): a folder of
    segments is read without it."""
    if os.path.basename(path) != SEGMENT_INDEX:
        return False
    try:
        with open(path, newline="", encoding="utf-8", errors="replace") as fh:
            return fh.readline().startswith(SEGMENT_INDEX_HEADER)
    except (OSError, UnicodeDecodeError):
        return False


def find_files(item, exclude=()):
    """Files of one command-line input: ``(root, [files])``, sorted; root is the seed folder. A folder's
    ``eppf segment`` index is left out, and so are the files of ``exclude`` (the command's own output: a
    ``-o labels.csv`` inside the input folder is not read as a point file by the next run)."""
    from ..datasets._folder import object_files
    from ..io import supported_extensions

    path = Path(item)
    if path.is_dir():
        own = {os.path.realpath(e) for e in exclude if e}
        names = {os.path.basename(e) for e in own}  # (resolved only where the name matches: one syscall chain each)
        found = [f for f in object_files(path) if not is_segment_index(f)
                 and not (os.path.basename(f) in names and os.path.realpath(f) in own)]
        if not found:
            raise ValueError(f"no point cloud or mesh files ({' '.join(supported_extensions())}, any case) in the "
                             f"folder {item}")
        return str(path), found
    if path.is_file():
        return os.path.dirname(str(path)) or ".", [str(path)]
    if path.exists():
        raise ValueError(f"{item} is neither a file nor a folder")
    if str(item).endswith(("/", os.sep)):
        raise FileNotFoundError(f"the folder {item} does not exist")
    raise FileNotFoundError(f"no such file or folder: {item}")


@dataclass
class Objects:
    """Objects read from the command line's inputs."""

    clouds: list
    ids: np.ndarray            # shown in tables: the file path as given, or the data set's id
    keys: list                 # stable identity (resolved path, or data set path + id) for seen-in-training checks
    labels: np.ndarray = None  # int labels when the input has them
    class_names: np.ndarray = None
    split: np.ndarray = None   # "train"/"test" per object, or None
    skipped: list = field(default_factory=list)
    name: str = ""
    sampling: dict = None      # how they were read (with the seed root of a data folder)

    def subset(self, mask):
        idx = np.flatnonzero(mask)
        return Objects([self.clouds[i] for i in idx], self.ids[idx], [self.keys[i] for i in idx],
                       None if self.labels is None else self.labels[idx], self.class_names,
                       None if self.split is None else self.split[idx], self.skipped, self.name)


def _read_npz_data_set(path):
    from ..datasets import load_npz

    bunch = load_npz(path)
    n = len(bunch.data)
    ids = bunch.ids if bunch.ids is not None else [str(i) for i in range(n)]
    ids = np.asarray(ids, dtype=str)
    real = os.path.realpath(path)
    return Objects([np.asarray(c, dtype=np.float64) for c in bunch.data], ids, [f"{real}#{i}" for i in ids],
                   np.asarray(bunch.target), np.asarray(bunch.target_names, dtype=str),
                   None if bunch.split is None else np.asarray(bunch.split, dtype=str), [], str(path))


def _is_npz_data_set(path):
    try:
        with np.load(path, allow_pickle=False) as f:
            return "offsets" in f.files
    except Exception as exc:  # not a zip, pickled, truncated...
        raise ValueError(f"cannot read {path} as .npz: {type(exc).__name__}: {exc}") from None


#: Fewest points every descriptor needs (some need more: :func:`fewest_points`).
MIN_POINTS = 2


def fewest_points(*estimators):
    """Fewest points per cloud that every one of ``estimators`` (descriptors, pipelines, their nested
    steps) accepts: below it they raise."""
    need = MIN_POINTS
    for est in estimators:
        if est is None:
            continue
        nested = est.get_params(deep=True).values() if hasattr(est, "get_params") else ()
        for part in (est, *nested):
            need = max(need, int(getattr(part, "_min_points", MIN_POINTS)))
    return need


def too_few_points(n, min_points, name=None):
    """The message of a cloud (``name``, when given) of ``n`` points, fewer than the ``min_points`` a
    descriptor needs."""
    text = f"{count(n, 'point')}, too few to describe (at least {min_points} are needed)"
    return text if name is None else f"{name}: {text}"


def check_enough_points(n, min_points, name):
    """A ValueError naming ``name`` when a cloud of ``n`` points has fewer than ``min_points``."""
    if n < min_points:
        raise ValueError(too_few_points(n, min_points, name))


@dataclass
class InputPlan:
    """The files of the command line's inputs, before any is read.

    ``entries`` are ``(file, root, class)`` triples (``class`` a ``(name,
    split)`` pair or None), ``seeds`` their sampling seeds, ``class_names``
    the sorted class names of a folder of class subfolders (else None).
    """

    entries: list
    seeds: list
    sampling: dict
    class_names: np.ndarray = None
    labelled: bool = None
    name: str = ""
    cmd: str = "eppf"
    min_points: int = MIN_POINTS

    def read(self, k):
        """The cloud of entry ``k`` as float64; ValueError/OSError/KeyError when it cannot be read, or has
        fewer than ``min_points`` points (a file the descriptor would refuse is skipped like an unreadable
        one, by name, instead of stopping the command)."""
        from ..io import read_point_cloud

        f = self.entries[k][0]
        s = self.sampling
        cloud = read_point_cloud(f, normals=s.get("normals", "auto"), n_points=s.get("n_points"),
                                 resolution=s.get("resolution"), random_state=self.seeds[k])
        check_enough_points(len(cloud), self.min_points, f)
        return np.asarray(cloud, dtype=np.float64)

    def error(self, k, exc, on_error):
        """The message of a file that could not be read; raised as a ValueError when ``on_error="raise"``."""
        f = self.entries[k][0]
        msg = str(exc)
        msg = msg if f in msg else f"{f}: {msg}"
        if on_error == "raise":
            raise ValueError(f"{msg} (--on-error skip reads the other files)") from None
        return msg

    def report_skipped(self, skipped, n_read):
        """Warn about skipped files (``(file, message)`` pairs), or raise when no file could be read."""
        from ..streaming import nothing_read, skipped_summary

        if not skipped:
            return
        if not n_read:
            raise nothing_read(skipped, len(self.entries))
        warn(self.cmd, skipped_summary(skipped, len(self.entries)))

    def objects(self, kept, clouds, skipped):
        """:class:`Objects` of the entries ``kept`` (indices, in order), with their ``clouds`` (or None)."""
        kept_entries = [self.entries[k] for k in kept]
        ids = np.asarray([f for f, _, _ in kept_entries], dtype=str)
        keys = [os.path.realpath(f) for f, _, _ in kept_entries]
        labels = split = None
        if self.class_names is not None:
            index = {c: k for k, c in enumerate(self.class_names)}
            labels = np.asarray([index[c[0]] for _, _, c in kept_entries], dtype=np.int64)
            split = np.asarray([c[1] for _, _, c in kept_entries], dtype=str)
            split = split if (split != "").all() else None
            present = set(labels.tolist())
            lost = [self.class_names[k] for k in range(len(self.class_names)) if k not in present]
            if lost and self.labelled:
                raise ValueError(f"no file of the class {lost[0]!r} could be read")
        return Objects(clouds, ids, keys, labels, self.class_names, split, skipped, self.name)


def given_options(args, *options):
    """Those of ``options`` (spelled ``--n-points``, ...) given on the command line: the ones whose value is
    not None, their default when not given (a command that lacks one has not been given it)."""
    return [o for o in options if getattr(args, o[2:].replace("-", "_"), None) is not None]


def refuse_sampling_of_data_set(args, data):
    """Refuse ``--n-points``/``--resolution`` with a ``.npz`` data set: its clouds are read as they are stored, so
    the option would be ignored (and ``train`` would record it in the model as how its objects were read)."""
    given = given_options(args, "--n-points", "--resolution")
    if given:
        raise ValueError(f"{given[0]}: {data} is a .npz data set, whose clouds are read as they are stored (the "
                         "option samples mesh files and resamples point files); leave it out")


def is_data_set_input(inputs):
    """True when the inputs are one ``.npz`` data set (read whole by :func:`read_inputs`)."""
    inputs = [str(i) for i in inputs]
    return len(inputs) == 1 and inputs[0].lower().endswith(".npz") and os.path.isfile(inputs[0]) \
        and _is_npz_data_set(inputs[0])


def plan_inputs(inputs, sampling, *, cmd="eppf", labelled=None, min_points=MIN_POINTS, exclude=()):
    """The :class:`InputPlan` of files and folders (see :func:`read_inputs`); nothing is read yet."""
    inputs = [str(i) for i in inputs]
    if labelled and (len(inputs) != 1 or not os.path.isdir(inputs[0])):
        if len(inputs) == 1 and not os.path.exists(inputs[0]):
            raise FileNotFoundError(f"--data {inputs[0]}: no such file or folder")
        raise ValueError(f"--data must be a .npz data set or a folder of class subfolders, got {' '.join(inputs)}")
    groups = [find_files(item, exclude) for item in inputs]
    folder_input = len(inputs) == 1 and os.path.isdir(inputs[0])
    root = groups[0][0] if folder_input else None
    entries = [(f, r, None) for r, files in groups for f in files]  # (file, root, class)
    class_names = None
    if folder_input and labelled is not False:
        from ..datasets._folder import folder_layout

        layout, _ = folder_layout(root, groups[0][1])
        entries = [(f, r, cls) for (f, r, _), cls in zip(entries, layout)]
        with_class = [e for e in entries if e[2] is not None]
        if labelled and not with_class:
            raise ValueError(f"{root} holds no class subfolders with object files; expected <class>/<file>, "
                             "train|test/<class>/<file> or <class>/train|test/<file>")
        if with_class and (labelled or len(with_class) == len(entries)):
            loose = sum(1 for f, _, _ in entries if os.path.dirname(os.path.relpath(f, root)) == "")
            if loose:
                warn(cmd, f"{count(loose, 'file')} directly in {root} (outside the class subfolders) "
                          f"{'is' if loose == 1 else 'are'} left out")
            dropped = len(entries) - len(with_class) - loose
            if dropped:
                warn(cmd, f"{count(dropped, 'file')} of {root} {'is' if dropped == 1 else 'are'} outside its "
                          "train/test folders and left out")
            entries = with_class
            class_names = np.asarray(sorted({e[2][0] for e in entries}), dtype=str)
    # A model trained on a folder keeps that folder as its seed root: a file under it gets its training seed
    # however it is named on the command line (the folder itself, a subfolder, the file alone).
    # A file's seed depends on its root and path alone, so the files of one root are seeded in one call.
    seed_root = sampling.get("root")
    by_root = {}  # seed folder -> (entry indices, paths)
    for k, (f, r, _) in enumerate(entries):
        real = os.path.realpath(f) if seed_root else None
        if seed_root and real.startswith(os.path.join(seed_root, "")):
            key, path = seed_root, real
        else:
            key, path = r, f
        idx, paths = by_root.setdefault(key, ([], []))
        idx.append(k)
        paths.append(path)
    seeds = [None] * len(entries)
    for key, (idx, paths) in by_root.items():
        for k, seed in zip(idx, file_seeds(sampling["random_state"], key, paths)):
            seeds[k] = seed
    return InputPlan(entries, seeds, sampling, class_names, labelled, " ".join(inputs), cmd, min_points)


def read_inputs(inputs, sampling, *, on_error="skip", progress=False, cmd="eppf", labelled=None,
                min_points=MIN_POINTS, exclude=()):
    """Read files, folders or one ``.npz`` data set the one way (see the module docstring).

    Parameters
    ----------
    inputs : list of str
        Files and folders, or one ``.npz`` data set.
    sampling : dict
        From :func:`sampling_from_args` or a saved model.
    on_error : {"skip", "raise"}
        A file that cannot be read is skipped (counted in a summary on
        stderr) or stops the command.
    progress : bool
        Show a progress bar while reading.
    cmd : str
        The command's name for messages.
    labeled : bool or None
        True: the inputs must give labels (one folder of class subfolders or
        a data set); None: labels when the input has them; False: none.
    min_points : int
        A cloud with fewer points (:func:`fewest_points` of the descriptor)
        is skipped, or stops the command, like a file that cannot be read.
    exclude : sequence of str
        Files a folder's listing leaves out: the command's own output.
    """
    inputs = [str(i) for i in inputs]
    if is_data_set_input(inputs):
        return _drop_tiny(_read_npz_data_set(inputs[0]), min_points, on_error, cmd)
    plan = plan_inputs(inputs, sampling, cmd=cmd, labelled=labelled, min_points=min_points, exclude=exclude)
    clouds, kept, skipped = [], [], []
    for k in progress_bar(range(len(plan.entries)), desc="reading", enabled=progress):
        try:
            cloud = plan.read(k)
        except (ValueError, OSError, KeyError) as exc:
            skipped.append((plan.entries[k][0], plan.error(k, exc, on_error)))
            continue
        clouds.append(cloud)
        kept.append(k)
    plan.report_skipped(skipped, len(clouds))
    return plan.objects(kept, clouds, skipped)


def _drop_tiny(objects, min_points, on_error, cmd):
    """The objects of a data set without its clouds of fewer than ``min_points`` points (or the error of the
    first, with ``on_error="raise"``), as :func:`read_inputs` treats files."""
    from ..streaming import nothing_read, skipped_summary

    small = [k for k, c in enumerate(objects.clouds) if len(c) < min_points]
    if not small:
        return objects
    names = [f"{objects.name} object {objects.ids[k]}" for k in small]
    skipped = [(name, too_few_points(len(objects.clouds[k]), min_points, name)) for k, name in zip(small, names)]
    if on_error == "raise":
        raise ValueError(f"{skipped[0][1]} (--on-error skip leaves it out)")
    n = len(objects.clouds)
    if len(small) == n:
        raise nothing_read(skipped, n)
    warn(cmd, skipped_summary(skipped, n))
    keep = np.ones(n, dtype=bool)
    keep[small] = False
    kept = objects.subset(keep)
    kept.skipped = skipped
    return kept


def load_labelled(args, sampling, cmd, min_points=MIN_POINTS):
    """Objects of ``--data`` or ``--built-in``, with labels; clouds of fewer than ``min_points`` points are
    skipped as unreadable files are."""
    if getattr(args, "built_in", False):
        from ..datasets import make_shapes

        # no file is read: a reading option would be ignored (and train would record it as how its objects were read)
        given = given_options(args, "--n-points", "--resolution", "--on-error")
        if given:
            raise ValueError(f"{given[0]}: the built-in synthetic shapes are made in memory, not read from files; "
                             "leave it out")

        bunch = make_shapes(random_state=args.random_state)
        n = len(bunch.data)
        ids = np.asarray([str(i) for i in range(n)])
        return Objects(list(bunch.data), ids, [f"built-in:{args.random_state}#{i}" for i in ids],
                       np.asarray(bunch.target), np.asarray(bunch.target_names, dtype=str), None, [],
                       "built-in synthetic shapes")
    data = str(args.data)
    if not os.path.exists(data):
        what = "folder" if data.endswith(("/", os.sep)) or not data.lower().endswith(".npz") else "file"
        raise FileNotFoundError(f"--data {data}: the {what} does not exist")
    if os.path.isfile(data) and not data.lower().endswith(".npz"):
        raise ValueError(f"--data {data}: give a .npz data set or a folder of class subfolders, not one file")
    if os.path.isfile(data):
        refuse_sampling_of_data_set(args, data)
    if os.path.isdir(data) and not sampling.get("root"):
        sampling = dict(sampling, root=os.path.realpath(data))
    objects = read_inputs([data], sampling, on_error=on_error_of(args),
                          progress=progress_of(args), cmd=cmd, labelled=True, min_points=min_points)
    objects.name = data
    objects.sampling = sampling
    return objects


def check_classes(objects, cmd, need_two_per_class=False):
    """Refuse one-class data, and classes too small for a stratified split, by name."""
    counts = np.bincount(objects.labels, minlength=len(objects.class_names))
    present = np.flatnonzero(counts)
    if len(present) < 2:
        only = str(objects.class_names[present[0]]) if len(present) else "none"
        raise ValueError(f"{objects.name} has one class ({only!r}); a classifier needs at least two classes")
    if need_two_per_class:
        small = [str(objects.class_names[k]) for k in present if counts[k] < 2]
        if small:
            raise ValueError(f"the class {small[0]!r} of {objects.name} has only one object; a held-out test "
                             "set needs at least two per class (add objects, or --test-size 0 to train on all)")


def min_points_needed(est):
    """Fewest points per cloud the descriptor can describe, and why."""
    params = est.get_params()
    k = params.get("n_neighbors")
    if isinstance(k, int):
        return k + 1, f"normal estimation from {k} neighbours (--normal-neighbors) needs {k + 1} points"
    return 3, "a descriptor needs at least 3 points"


def warn_tiny(clouds, ids, est, cmd, name, shapes=None):
    """Warn, naming the files, about clouds with fewer points than the descriptor needs (``shapes``, the
    clouds' shapes, instead of ``clouds``); returns ``{id: why}`` of those objects, for tables that mark
    their rows."""
    need, why = min_points_needed(est)
    shapes = [np.shape(c) for c in clouds] if shapes is None else shapes
    tiny = [(str(i), int(n)) for (n, width), i in zip(shapes, ids) if n < need and not (width >= 6 and n >= 3)]
    if tiny:
        listed = ", ".join(f"{i} ({count(n, 'point')})" for i, n in tiny[:5]) + (f" and {len(tiny) - 5} more"
                                                                                if len(tiny) > 5 else "")
        one = len(tiny) == 1
        warn(cmd, f"{count(len(tiny), 'object')} {'has' if one else 'have'} too few points for {name}: {why}; "
                  f"{'its result is' if one else 'their results are'} unreliable: {listed}")
    return {i: f"{count(n, 'point')}; {why}" for i, n in tiny}


# ---------------------------------------------------------------------------
# Saved models
# ---------------------------------------------------------------------------


def load_model(path, trust=False):
    """Load a model saved by ``eppf train``.

    Parameters
    ----------
    path : str or path-like
        The model file.
    trust : bool, default=False
        Also load a pickled model of eppf 0.1; see :func:`eppf.load_model`
        (a pickle can run any code, so only for files you made yourself).

    Returns
    -------
    saved : dict
        With keys ``"model"``, ``"eppf_version"``, ``"params"`` and
        ``"classes"``, and, for models of this eppf, ``"sampling"`` and
        ``"train_ids"``/``"train_keys"``.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file cannot be read, is a pickle and ``trust`` is False, or is
        not an eppf model. A warning is printed on standard error if it was
        saved by another eppf version.
    """
    import warnings

    from .. import __version__
    from .._persist import load_model as _load_model_file

    path = str(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        saved = _load_model_file(path, trust=trust)
    for w in caught:
        print(f"eppf: warning: {w.message}", file=sys.stderr)
    if not (isinstance(saved, dict) and saved.get("format") == "eppf-model" and hasattr(saved.get("model"), "predict")):
        raise ValueError(f"{path} is not an eppf model (write one with 'eppf train')")
    if saved.get("eppf_version") != __version__ and not caught:
        print(f"eppf: warning: {path} was saved by eppf {saved.get('eppf_version')}, this is eppf {__version__}",
              file=sys.stderr)
    return saved


def model_sampling(saved, cmd):
    """How the model's training files were read; eppf 0.1 models read point files as they are."""
    sampling = saved.get("sampling")
    if not isinstance(sampling, dict):
        warn(cmd, "the model does not record how its training files were read (eppf 0.1); meshes are sampled "
                  "with 2,048 points and seed 0")
        return {"n_points": None, "resolution": None, "normals": "auto", "random_state": 0, "seed_rule": SEED_RULE}
    if sampling.get("seed_rule") != SEED_RULE:
        warn(cmd, f"the model's seed rule {sampling.get('seed_rule')!r} is not this eppf's {SEED_RULE!r}; "
                  "sampled meshes will differ from the training ones")
    return dict(sampling)


def _estimators(est, seen=None):
    """``est`` and every estimator inside it: its parameters (steps, transformer lists) and its fitted
    attributes (``transformers_``, the fitted copies that a loaded model computes with)."""
    from sklearn.base import BaseEstimator

    seen = set() if seen is None else seen
    if id(est) in seen:
        return
    seen.add(id(est))
    yield est
    values = list(est.get_params(deep=False).values())
    values += [v for k, v in vars(est).items() if k.endswith("_") and not k.startswith("_")]
    for value in values:
        for item in (value if isinstance(value, (list, tuple)) else [value]):
            item = item[1] if isinstance(item, tuple) and len(item) >= 2 else item
            if isinstance(item, BaseEstimator):
                yield from _estimators(item, seen)


def set_runtime(model, n_jobs, progress):
    """Set threads and progress of a loaded model wherever it has those parameters.

    Fitted copies inside the model (a descriptor pool's per-draw descriptors, a union's fitted blocks) are
    set too: they, not the parameters, compute its predictions, and they keep the settings of training.
    """
    from sklearn.pipeline import Pipeline

    from .. import EPPF4DClassifier, PointNetClassifier

    for est in _estimators(model):
        if not type(est).__module__.startswith(__package__.split(".")[0] + ".") or isinstance(est, Pipeline):
            continue  # eppf's estimators only: a torch network's own verbosity is the classifier's business
        names = est.get_params(deep=False)
        updates = {}
        if "verbose" in names:
            updates["verbose"] = 1 if progress else 0
        if "n_jobs" in names and n_jobs is not None:
            torch_owned = isinstance(est, (EPPF4DClassifier, PointNetClassifier))
            updates["n_jobs"] = (None if n_jobs < 0 else n_jobs) if torch_owned else n_jobs
        if updates:
            est.set_params(**updates)


def class_name(saved, label):
    classes = saved.get("classes") or []
    try:
        return str(classes[int(label)])
    except (IndexError, ValueError, TypeError):
        return str(label)
