"""The ``eppf`` command line."""

from ._app import build_parser, load_model, main, make_pipeline_from_args, run_main_job

__all__ = ["build_parser", "load_model", "main", "make_pipeline_from_args", "run_main_job"]
