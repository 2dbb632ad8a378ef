"""Ctrl-C while the ``eppf`` command is still importing eppf.

The command's entry points (the ``eppf`` script installed by pip, which runs ``from eppf.cli import main``,
and ``python -m eppf``) import eppf, scikit-learn and the rest before :func:`eppf.cli.main` runs, which
takes about a second; a Ctrl-C then would end in a Python traceback instead of the documented line and
exit status. The package's ``__init__`` modules import under :func:`command_interrupt_guard`, which turns
that KeyboardInterrupt into ``eppf: interrupted`` and exit status 130, as ``main`` does, when the process
is the ``eppf`` command; imported from any other program, eppf lets the KeyboardInterrupt go on, as
every import does.

Only the standard library is imported here: this module is loaded first.
"""

import contextlib
import os
import sys

__all__ = []

#: The line and exit status of an interrupted command (those of :func:`eppf.cli.main`).
INTERRUPTED = "eppf: interrupted"
INTERRUPTED_STATUS = 130


def is_eppf_command():
    """True when this process is the ``eppf`` command: the installed script or ``python -m eppf``."""
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    if spec is not None and spec.name == "eppf.__main__":
        return True  # python -m eppf, once eppf.__main__ runs
    if sys.argv[:1] == ["-m"]:
        # python -m eppf while runpy imports the package: sys.argv[0] is "-m" until the module is found
        argv = list(getattr(sys, "orig_argv", []))
        return any(a == "-m" and b == "eppf" for a, b in zip(argv, argv[1:])) or "-meppf" in argv
    if spec is not None and spec.name != "__main__":
        return False  # python -m another_module
    # the installed script, run as the main program: eppf, or eppf.exe (a zip whose __main__ runs) and
    # eppf-script.py on Windows
    name = os.path.basename(sys.argv[0]) if sys.argv else ""
    return os.path.splitext(name)[0] in ("eppf", "eppf-script")


@contextlib.contextmanager
def command_interrupt_guard():
    """Within it, a KeyboardInterrupt ends the ``eppf`` command with one line and exit status 130 (a
    SystemExit, which the interpreter ends quietly); in any other program it is raised as it came."""
    try:
        yield
    except KeyboardInterrupt:
        if not is_eppf_command():
            raise
        print(INTERRUPTED, file=sys.stderr)
        raise SystemExit(INTERRUPTED_STATUS) from None
