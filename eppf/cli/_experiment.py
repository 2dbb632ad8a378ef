"""``eppf experiment``: the paper's experiments (:mod:`eppf.experiments`) from the command line.

One subcommand per experiment (retrieval, ablation, classification, noise,
runtime), each with its ``--help``; ``eppf experiment classification --help``
and ``eppf experiment noise --help`` list the presets of the paper's
ModelNet40 protocol (``--preset``). ``python -m eppf.experiments`` was a
second parser of these options; it now only points here. ``--no-progress`` hides progress lines, as in every
other subcommand; ``--quiet`` is kept as a deprecated alias. Bad options are
one line on stderr.
"""

import argparse
import functools
import os
import shlex
import sys
import textwrap
import warnings

from ._common import Command, n_jobs_type, register, within_folder

__all__ = ["run_experiment"]


class _Quiet(argparse.Action):
    """``--quiet``: the deprecated spelling of ``--no-progress``."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, "no_progress", nargs=0, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print("eppf experiment: warning: --quiet is deprecated; use --no-progress", file=sys.stderr)
        namespace.no_progress = True


class _Parser(argparse.ArgumentParser):
    """Argument errors as one line on stderr, exit status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _levels(text):
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"noise levels must be numbers, got {text!r}") from None
    return values


def _add_common(p, draws=False):
    p.add_argument("--data", default="builtin",
                   help="'builtin' (synthetic shapes, the default), a folder with one subfolder of files per class "
                        "(optionally inside train/ and test/; eppf.datasets.load_folder) or a .npz file in the flat "
                        "layout (eppf.datasets.load_npz)")
    p.add_argument("--out", default=None, help="output folder (default: results/<experiment>/<data name>)")
    p.add_argument("--cache-dir", default=None, help="descriptor cache folder (default: OUT/cache)")
    p.add_argument("--on-error", choices=["skip", "raise"], default="raise",
                   help="a file of a --data folder that cannot be read: stop, naming it (the default: an "
                        "experiment's figures are those of the whole data set), or skip it with a summary on stderr "
                        "and a count in the report's data line")
    p.add_argument("--random-state", type=int, default=0, help="seed of everything random (default 0)")
    p.add_argument("--n-jobs", type=n_jobs_type, default=-1, help="threads (default -1: all cores)")
    p.add_argument("--quick", action="store_true", help="tiny settings for a smoke run (< 2 minutes on the built-in set)")
    p.add_argument("--no-progress", action="store_true", help="no progress lines")
    p.add_argument("--quiet", action=_Quiet, help=argparse.SUPPRESS)
    from ..experiments._common import SCALINGS

    p.add_argument("--scaling", choices=SCALINGS, default="auto",
                   help="EPPF scaling (default: auto = fit for the built-in set, object (per-object unit cube) "
                        "for files)")
    if draws:
        p.add_argument("--draws", type=int, default=None, help="descriptor draws (default 10, 2 with --quick)")


def _add_training(p, models, default_models):
    p.add_argument("--models", nargs="+", choices=models, default=None,
                   help=f"models to run (default: {' '.join(default_models)})")
    p.add_argument("--epochs", type=int, default=None, help="max epochs of the EPPF CNNs (default 30, 1 with --quick)")
    p.add_argument("--pointnet-epochs", type=int, default=None, help="max epochs of PointNet (default: --epochs)")
    p.add_argument("--pointnet-points", type=int, default=None, help="points fed to PointNet (default 1024, 128 with --quick)")
    p.add_argument("--validation-fraction", type=float, default=0.1,
                   help="share of the training objects held out for early stopping (default 0.1)")
    p.add_argument("--patience", type=int, default=None, help="early-stopping patience in epochs (default 5, 1 with --quick)")
    p.add_argument("--precision", choices=["float32", "bfloat16", "auto"], default="float32",
                   help="arithmetic of the paper's EPPF CNNs: 'bfloat16' is mixed precision, faster on CPUs with "
                        "native bfloat16 (AVX512_BF16, AMX or ARM BF16), slower elsewhere; 'auto' chooses it only "
                        "there (default float32; 4d+ always uses 'auto')")
    p.add_argument("--train-per-class", type=int, default=None,
                   help="use at most this many training objects per class (seeded; default: all)")
    p.add_argument("--test-per-class", type=int, default=None,
                   help="score on at most this many test objects per class (seeded; default: all)")


def _presets_epilog(experiment):
    from ..experiments._presets import PRESETS

    width = 100
    text = textwrap.fill("presets (--preset NAME): the paper's ModelNet40 protocol, on any data set with its own "
                         "train/test split and at least 1024 points per object:", width) + "\n"
    for p in PRESETS.values():
        text += textwrap.fill(p.summary, width, initial_indent=f"  {p.name:<23}", subsequent_indent=" " * 25) + "\n"
    if experiment == "noise":
        text += textwrap.fill(
            "The noise experiment sweeps a noise preset's sigma from 0 (levels 0 and sigma) instead of adding it "
            "once; the clean and occluded presets sweep the levels "
            + ", ".join(f"{s:g}" for s in PRESETS["modelnet40-clean"].noise_levels)
            + "; --levels replaces the preset's levels.", width)
    return text.rstrip("\n")


def _add_preset(p):
    from ..experiments._presets import PRESETS

    p.add_argument("--preset", choices=list(PRESETS), default=None, metavar="NAME",
                   help="resample and perturb every object as a preset of the paper's protocol says (listed below)")


def add_arguments(parser):
    """One subparser per experiment on ``parser`` (that of ``eppf experiment``); bad options are one line."""
    parser.error = functools.partial(_Parser.error, parser)
    from ..experiments._classification import DEFAULT_MODELS, MODELS
    from ..experiments._common import DESCRIPTORS
    from ..experiments._noise import DEFAULT_LEVELS, DEFAULT_NOISE_MODELS

    sub = parser.add_subparsers(dest="experiment", required=True, metavar="NAME", parser_class=_Parser)
    p = sub.add_parser("retrieval", help="Table II: leave-one-out KL 1-NN retrieval of all descriptors")
    _add_common(p, draws=True)
    p.add_argument("--descriptors", nargs="+", choices=list(DESCRIPTORS), default=list(DESCRIPTORS), metavar="NAME",
                   help=f"descriptors to compare: {', '.join(DESCRIPTORS)} (default: all)")
    p = sub.add_parser("ablation", help="EPPF retrieval with each point-pair function removed")
    _add_common(p, draws=True)
    p = sub.add_parser("classification", help="Table III: PointNet and the EPPF 2D/3D/4D CNNs on the test split",
                       epilog=_presets_epilog("classification"), formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(p)
    _add_training(p, MODELS, DEFAULT_MODELS)
    _add_preset(p)
    p = sub.add_parser("noise", help="accuracy against Gaussian noise, retraining at every level",
                       epilog=_presets_epilog("noise"), formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_common(p)
    _add_training(p, MODELS, DEFAULT_NOISE_MODELS)
    _add_preset(p)
    p.add_argument("--levels", type=_levels, default=None,
                   help=f"noise sigmas as fractions of the unit cube, e.g. '0,0.02,0.06' (default {DEFAULT_LEVELS}, "
                        "or the preset's levels)")
    p = sub.add_parser("runtime", help="milliseconds per object of every descriptor and of normal estimation")
    _add_common(p)
    p.add_argument("--n-objects", type=int, default=None, help="objects timed (default 200, 20 with --quick)")
    p.add_argument("--repeats", type=int, default=None, help="timing repeats, best kept (default 3, 1 with --quick)")


def _check_outside_data(data, outputs):
    """Refuse an output folder that is the ``--data`` folder or inside it: its tables, figures and cache would
    be read as objects of the data set by the next run (a CSV is a point file)."""
    if data == "builtin" or not os.path.isdir(data):
        return
    for option, path in outputs:
        if path is not None and within_folder(path, data):
            raise ValueError(f"{option} {path} is inside the --data folder {data}; the next run would read its "
                             "files as objects of the data set, so give a folder outside it")


def _check_folders(outputs):
    """Refuse, before any work, an output folder (``(option, path)`` pairs, ``None`` paths left out) that is a
    file or would be made inside one: the experiment would stop when it makes it, with a bare errno line."""
    for option, path in outputs:
        if path is None:
            continue
        if os.path.lexists(path) and not os.path.isdir(path):
            what = "is a file" if os.path.isfile(path) else "exists and is not a folder"
            raise ValueError(f"{option} {path} {what}; give a new or existing folder")
        above = os.path.dirname(os.path.abspath(path))
        while not os.path.lexists(above) and os.path.dirname(above) != above:
            above = os.path.dirname(above)
        if not os.path.isdir(above):
            raise ValueError(f"{option} {path}: {above} is not a folder, so the folder cannot be made in it")


def run_experiment(args):
    """Run one experiment from parsed ``eppf experiment`` arguments.

    Parameters
    ----------
    args : argparse.Namespace or list of str
        Parsed arguments (``args.argv``, when set, the command line after
        ``eppf``, recorded in the report), or what follows ``eppf
        experiment`` on a command line (run as ``eppf.cli.main`` runs it).

    Returns
    -------
    status : int
        0 on success (bad input raises, as in every subcommand; with a list,
        the status of ``eppf.cli.main``).
    """
    if not isinstance(args, argparse.Namespace):
        from ._main import main

        return main(["experiment", *args])
    from ..experiments import run_ablation, run_classification, run_noise, run_retrieval, run_runtime
    from ..experiments._common import Dataset, data_name, load_data
    from ..experiments._presets import apply_preset

    argv = getattr(args, "argv", None)
    command = "eppf " + shlex.join(argv) if argv else f"eppf experiment {args.experiment}"
    preset = getattr(args, "preset", None)
    out = args.out or os.path.join("results", args.experiment, data_name(args.data) + (f"_{preset}" if preset else ""))
    _check_outside_data(args.data, [("--out", out), ("--cache-dir", args.cache_dir)])
    _check_folders([("--out", out), ("--cache-dir", args.cache_dir)])
    data = args.data
    if args.on_error == "skip" and (data == "builtin" or os.path.isfile(data)):
        # nothing of them can be skipped: the option would do nothing
        what = ("is generated, not read from files" if data == "builtin" else
                "is a .npz data set, read whole (no part of it is a file that can be skipped)")
        raise ValueError(f"--on-error skip: --data {data} {what}; it applies to a --data folder, so leave it out")
    if args.on_error == "skip" and os.path.isdir(data):
        # loaded here, not by the experiment, to skip unreadable files (the report's data line counts them)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            data = load_data(data, quick=args.quick, random_state=args.random_state, on_error="skip")
        for w in caught:  # (the skipped files' summary) one line each, as every subcommand warns
            print(f"eppf experiment: warning: {' '.join(str(w.message).split())}", file=sys.stderr)
    common = dict(data=data, out=out, random_state=args.random_state, n_jobs=args.n_jobs, quick=args.quick,
                  cache_dir=args.cache_dir, verbose=not args.no_progress, command=command, scaling=args.scaling)
    draws = getattr(args, "draws", None)
    draws = draws if draws is not None else (2 if args.quick else 10)
    if args.experiment == "retrieval":
        run_retrieval(descriptors=args.descriptors, draws=draws, **common)
    elif args.experiment == "ablation":
        run_ablation(draws=draws, **common)
    elif args.experiment in ("classification", "noise"):
        kw = dict(models=args.models, epochs=args.epochs, pointnet_epochs=args.pointnet_epochs,
                  pointnet_points=args.pointnet_points, validation_fraction=args.validation_fraction,
                  patience=args.patience, precision=args.precision, train_per_class=args.train_per_class,
                  test_per_class=args.test_per_class, **common)
        if args.experiment == "noise":
            run_noise(levels=args.levels, preset=preset, **kw)
        else:
            if preset is not None:
                loaded = data if isinstance(data, Dataset) else load_data(data, quick=args.quick,
                                                                          random_state=args.random_state)
                kw["data"] = apply_preset(loaded, preset, random_state=args.random_state)
            run_classification(**kw)
    else:
        run_runtime(n_objects=args.n_objects, repeats=args.repeats, **common)
    return 0


register(Command(
    "experiment", "the paper's experiments (retrieval, classification, ablation, noise, runtime): table, CSV and "
    "plot; classification and noise take --preset (the paper's ModelNet40 protocol: clean, noisy, occluded); "
    "'eppf experiment NAME --help' for their options",
    "Re-run the paper's experiments on a data set; each writes NAME.md, NAME.csv and NAME.png into --out.",
    add_arguments, run_experiment,
))
