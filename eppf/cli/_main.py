"""Parser assembly, ``--version`` and error handling of the ``eppf`` command.

Every subcommand is a module of this package that registers a
:class:`~eppf.cli._common.Command` in :data:`~eppf.cli._common.SUBCOMMANDS`;
importing :data:`_MODULES` fills that table, and :func:`build_parser` adds
one subparser per entry. Errors are reported in one line:

- bad input (``ValueError``, which includes :class:`eppf.io.FileFormatError`,
  ``TypeError``, ``OSError``): ``eppf <command>: error: ...``, exit status 2
  (the status argparse gives a bad option);
- a missing optional dependency: the same line with the command that
  installs it (or the reader's own line naming the extra, for LAS, LAZ and
  E57 files), exit status 2;
- Ctrl-C: ``eppf: interrupted``, exit status 130;
- the reader of standard output gone (``eppf predict ... | head``): no
  message, exit status 141.
"""

import argparse
import importlib
import sys

from ..utils._malloc import keep_freed_memory
from ._common import SUBCOMMANDS

__all__ = ["build_parser", "main"]

#: Subcommand modules, in the order of ``eppf --help``.
_MODULES = ("_run", "_describe", "_retrieve", "_train", "_predict", "_segment", "_evaluate", "_bench", "_experiment")

_ORDER = [m[1:] for m in _MODULES]

#: Optional dependency (top-level module) -> the extra that installs it.
_EXTRAS = {"matplotlib": "plot", "h5py": "io", "plyfile": "io", "dask": "dask", "distributed": "dask",
           "laspy": "las", "lazrs": "las", "pye57": "e57"}


def _load_commands():
    for name in _MODULES:
        importlib.import_module(f"{__package__}.{name}")
    return SUBCOMMANDS


def _version():
    from .. import __version__

    return __version__


def build_parser():
    """The argument parser of the ``eppf`` command.

    Returns
    -------
    parser : argparse.ArgumentParser
        With one subparser per registered subcommand; without a subcommand
        the options of ``run`` apply.
    """
    commands = _load_commands()
    parser = argparse.ArgumentParser(
        prog="eppf",
        description="Noise-resistant 3D object retrieval and classification with the EPPF descriptor.",
    )
    parser.add_argument("--version", action="version", version=f"eppf {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for command in sorted(commands.values(), key=lambda c: _ORDER.index(c.name)):
        p = sub.add_parser(command.name, help=command.help, description=command.description,
                           **command.parser_kwargs)
        command.add_arguments(p)
    # `eppf --data x.npz` is `eppf run --data x.npz`
    commands["run"].add_arguments(parser, defaults_only=True)
    return parser


def _install_advice(exc):
    name = (getattr(exc, "name", None) or "").split(".")[0]
    extra = _EXTRAS.get(name)
    if extra is None:
        return None
    return (f"{name} is not installed; from a clone: pip install -c constraints.txt -e \".[{extra}]\", "
            f"otherwise: pip install \"eppf[{extra}]\"")


def main(argv=None):
    """Entry point of the ``eppf`` console command.

    Parameters
    ----------
    argv : list of str, default=None
        Arguments (``sys.argv[1:]`` when None).

    Returns
    -------
    status : int
        0 on success; 2 on bad input or a missing optional dependency, with
        one ``eppf <command>: error: ...`` line on stderr; 130 when
        interrupted with Ctrl-C (with ``eppf: interrupted``).

    Notes
    -----
    Run as the command (``argv`` None: the ``eppf`` script, ``python -m
    eppf``), it first lets glibc keep large freed blocks in the process's
    heap (:func:`eppf.utils._malloc.keep_freed_memory`; training steps then
    reuse memory instead of faulting in fresh pages), unless the
    environment sets glibc's malloc variables. Called with an ``argv``
    list from a Python program, it leaves that program's allocator alone.
    """
    if argv is None:
        keep_freed_memory()
    try:
        return _main(argv)
    except KeyboardInterrupt:
        print("eppf: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # `eppf predict ... | head`: the reader left; stop quietly, as other commands do
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


def _main(argv):
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    name = args.command or "run"
    prefix = "eppf" if args.command is None else f"eppf {name}"
    args.prog, args.argv = prefix, argv
    try:
        SUBCOMMANDS[name].run(args)
        return 0
    except ModuleNotFoundError as exc:
        advice = _install_advice(exc)
        if advice is None:
            raise
        print(f"{prefix}: error: {advice}", file=sys.stderr)
        return 2
    except ImportError as exc:
        # a reader of an optional format (LAS, LAZ, E57) says in one line which extra installs it
        print(f"{prefix}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        raise
    except (ValueError, TypeError, OSError) as exc:
        text = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{prefix}: error: {text}", file=sys.stderr)
        return 2
