"""Command line of the experiments: ``python -m eppf.experiments NAME [options]``."""

import argparse
import os
import shlex
import sys
import textwrap

from ._common import DESCRIPTORS, SCALINGS, ExperimentError, data_name, load_data
from ._presets import PRESETS, apply_preset

__all__ = ["main"]

PROG = "python -m eppf.experiments"


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
                   help="'builtin' (synthetic shapes, the default) or a .npz file in the flat layout (eppf.datasets.load_npz)")
    p.add_argument("--out", default=None, help="output folder (default: results/<experiment>/<data name>)")
    p.add_argument("--cache-dir", default=None, help="descriptor cache folder (default: OUT/cache)")
    p.add_argument("--random-state", type=int, default=0, help="seed of everything random (default 0)")
    p.add_argument("--n-jobs", type=int, default=-1, help="threads (default -1: all cores)")
    p.add_argument("--quick", action="store_true", help="tiny settings for a smoke run (< 2 minutes on the built-in set)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--scaling", choices=SCALINGS, default="auto",
                   help="EPPF scaling: auto = fit for the built-in set, object (per-object unit cube) for files")
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
    p.add_argument("--preset", choices=list(PRESETS), default=None, metavar="NAME",
                   help="resample and perturb every object as a preset of the paper's protocol says (listed below)")


def build_parser():
    """The argument parser of ``python -m eppf.experiments``."""
    from ._classification import DEFAULT_MODELS, MODELS
    from ._noise import DEFAULT_LEVELS, DEFAULT_NOISE_MODELS

    parser = _Parser(prog=PROG, description="Re-run the paper's experiments on a data set; each writes NAME.md, "
                                            "NAME.csv and NAME.png into --out.")
    sub = parser.add_subparsers(dest="experiment", required=True, metavar="NAME", parser_class=_Parser)
    p = sub.add_parser("retrieval", help="Table II: leave-one-out KL 1-NN retrieval of all descriptors")
    _add_common(p, draws=True)
    p.add_argument("--descriptors", nargs="+", choices=list(DESCRIPTORS), default=list(DESCRIPTORS))
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
    return parser


def main(argv=None):
    """Run one experiment from command-line arguments.

    Parameters
    ----------
    argv : list of str, default=None
        Arguments after the program name (``sys.argv[1:]`` when None), e.g.
        ``["retrieval", "--data", "builtin", "--quick"]``.

    Returns
    -------
    status : int
        0 on success, 2 on a bad argument or input (with a one-line message
        on stderr).

    See Also
    --------
    run_retrieval : Table II.
    run_classification : Table III.
    run_ablation : EPPF without each function.
    run_noise : Accuracy against noise.
    run_runtime : Descriptor timings.

    Examples
    --------
    >>> import tempfile
    >>> from eppf.experiments import main
    >>> main(["retrieval", "--quick", "--quiet", "--descriptors", "eppf", "--draws", "1", "--out", tempfile.mkdtemp()])
    0
    >>> main(["retrieval", "--data", "no_such_file.npz", "--quiet"])
    2
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    command = f"{PROG} {shlex.join(argv)}"
    preset = getattr(args, "preset", None)
    out = args.out or os.path.join("results", args.experiment, data_name(args.data) + (f"_{preset}" if preset else ""))
    common = dict(data=args.data, out=out, random_state=args.random_state, n_jobs=args.n_jobs, quick=args.quick,
                  cache_dir=args.cache_dir, verbose=not args.quiet, command=command, scaling=args.scaling)
    from ._ablation import run_ablation
    from ._classification import run_classification
    from ._noise import run_noise
    from ._retrieval import run_retrieval
    from ._runtime import run_runtime

    draws = getattr(args, "draws", None)
    draws = draws if draws is not None else (2 if args.quick else 10)
    try:
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
                    kw["data"] = apply_preset(load_data(args.data, quick=args.quick, random_state=args.random_state),
                                              preset, random_state=args.random_state)
                run_classification(**kw)
        else:
            run_runtime(n_objects=args.n_objects, repeats=args.repeats, **common)
    except (ExperimentError, FileNotFoundError) as exc:
        print(f"{PROG} {args.experiment}: error: {exc}", file=sys.stderr)
        return 2
    return 0
