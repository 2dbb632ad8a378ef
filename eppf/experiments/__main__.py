"""``python -m eppf.experiments NAME [options]``: the same command as ``eppf experiment NAME [options]``."""

import sys


def main(argv=None):
    """Run ``eppf experiment`` with ``argv`` (``sys.argv[1:]`` when None); the exit status.

    Parameters
    ----------
    argv : list of str, default=None
        What follows ``python -m eppf.experiments``, e.g. ``["retrieval", "--quick"]``.

    Returns
    -------
    status : int
        0 on success, 2 on a bad option or input (one line on stderr).
    """
    from eppf.cli import main as eppf_main

    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return eppf_main(["experiment", *argv])
    except SystemExit as exc:  # argparse: --help, bad options
        return int(exc.code or 0)


if __name__ == "__main__":
    sys.exit(main())
