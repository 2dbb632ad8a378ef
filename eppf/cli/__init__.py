"""The ``eppf`` command line: one module per subcommand.

:mod:`._main` assembles the parser from the table of subcommands
(:data:`._common.SUBCOMMANDS`) and turns errors into one line;
:mod:`._common` holds the shared options and the one way files are read;
``_run``, ``_describe``, ``_retrieve``, ``_train``, ``_predict``,
``_evaluate``, ``_bench`` and ``_experiment`` are the subcommands.
"""

from .._command import command_interrupt_guard

with command_interrupt_guard():  # (as eppf's own imports: Ctrl-C before main() runs is still one line)
    from ._common import load_model
    from ._main import build_parser, main
    from ._run import run_main_job
    from ._train import make_pipeline_from_args

__all__ = ["build_parser", "load_model", "main", "make_pipeline_from_args", "run_main_job"]
