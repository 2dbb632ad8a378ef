"""Where the benchmarks find the real data sets, and what to say when they are absent.

The data are not part of the repository. A benchmark takes a file with
``--data FILE.npz`` or a folder of them with ``--data-dir DIR`` (default: the
environment variable ``EPPF_BENCH_DATA``; there is no other default), and
stops with exit status 2 and :data:`HOW_TO_GET` when a file it needs is
missing.
"""

import os
import sys

ENV = "EPPF_BENCH_DATA"
HOW_TO_GET = (
    "The data are not part of the repository. Make modelnet10_1024.npz (ModelNet10, 1,024 points per object) with\n"
    "  python scripts/make_modelnet_npz.py --root PATH/TO/ModelNet10 -o modelnet10_1024.npz\n"
    "or with --download instead of --root to fetch Princeton's archive (about 450 MB) into the data home.\n"
    "Other sets (dales_objects.npz, ...) go in the same flat layout through eppf.datasets.save_npz."
)


def default_dir():
    """The data folder named by ``$EPPF_BENCH_DATA``, or None."""
    return os.environ.get(ENV) or None


def _stop(message):
    print(message, file=sys.stderr)
    sys.exit(2)


def require(prog, path, what="data file"):
    """Return ``path`` if it is a file; otherwise exit 2 saying how to get it."""
    if path is None:
        _stop(f"{prog}: no {what} given; pass --data FILE.npz (or set ${ENV} to the folder holding it).\n{HOW_TO_GET}")
    if not os.path.isfile(path):
        _stop(f"{prog}: {what} {path!r} not found.\n{HOW_TO_GET}")
    return path


def in_dir(prog, folder, name):
    """``folder/name.npz``, required to exist (exit 2 with the recipe otherwise)."""
    if not folder:
        _stop(f"{prog}: no data folder; give --data-dir DIR or set ${ENV}.\n{HOW_TO_GET}")
    return require(prog, os.path.join(folder, name + ".npz"))
