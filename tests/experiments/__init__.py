"""Tests of eppf.experiments and of its command line, ``eppf experiment``."""


def experiment_main(argv):
    """``eppf experiment ARGV`` as a shell runs it: the exit status (argparse's too, for --help and bad options)."""
    from eppf.cli import main

    try:
        return main(["experiment", *argv])
    except SystemExit as exc:
        return int(exc.code or 0)
