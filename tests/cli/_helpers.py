"""What the command-line tests share: running ``eppf`` in the test's process, and reading its CSV files."""

import csv

from eppf.cli import main


def run(argv, capsys):
    """``eppf ARGV`` in this process: (exit status, stdout, stderr); a traceback on stderr fails the test."""
    status = main([str(a) for a in argv])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return status, captured.out, captured.err


def read_csv(path):
    """The rows of a CSV file written by ``eppf``, as dicts keyed by its header."""
    with open(path, newline="", encoding="utf-8", errors="surrogateescape") as fh:  # (as eppf writes them)
        return list(csv.DictReader(fh))
