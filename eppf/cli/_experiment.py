"""``eppf experiment``: the paper's experiments, forwarded to :mod:`eppf.experiments`.

The experiments have their own parser and ``--help``; ``eppf experiment
classification --help`` and ``eppf experiment noise --help`` list the presets
of the paper's ModelNet40 protocol (``--preset``). ``--no-progress``
(the flag of every other subcommand) is translated to the experiments'
``--quiet``, which stays accepted as a deprecated alias.
"""

import argparse
import sys

from ._common import Command, register

__all__ = ["run_experiment"]


def add_arguments(p):
    p.add_argument("experiment_args", nargs=argparse.REMAINDER)


def run_experiment(argv):
    """Forward ``argv`` (what follows ``eppf experiment``) to the experiments' command line.

    Parameters
    ----------
    argv : list of str or argparse.Namespace
        The experiment's arguments.

    Returns
    -------
    status : int
        The experiments' exit status.
    """
    from ..experiments import main

    if isinstance(argv, argparse.Namespace):
        argv = argv.experiment_args
    argv = list(argv)
    if "--quiet" in argv:
        print("eppf experiment: warning: --quiet is deprecated; use --no-progress", file=sys.stderr)
    argv = ["--quiet" if a == "--no-progress" else a for a in argv]
    return main(argv)


register(Command(
    "experiment", "the paper's experiments (retrieval, classification, ablation, noise, runtime): table, CSV and "
    "plot; classification and noise take --preset (the paper's ModelNet40 protocol: clean, noisy, occluded); "
    "'eppf experiment NAME --help' for their options",
    "Forwarded to python -m eppf.experiments.",
    add_arguments, run_experiment, {"add_help": False},
))
