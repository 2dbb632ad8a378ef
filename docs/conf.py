"""Sphinx configuration of the eppf documentation.

Build with ``make -C docs html`` (warnings are errors). Intersphinx links to
Python, NumPy, scikit-learn and PyTorch need the network, so they are only
loaded when the environment variable ``EPPF_DOCS_INTERSPHINX=1`` is set; the
default build is offline and warning-free.
"""

import os
import sys

sys.path.insert(0, os.path.abspath(".."))

import eppf  # noqa: E402

project = "eppf"
author = "the eppf developers"
copyright = "2026, the eppf developers"
version = eppf.__version__
release = eppf.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.intersphinx",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": "/plot_",
    # ``-D plot_gallery=0`` builds the pages without running the examples
    "plot_gallery": "True",
    "download_all_examples": False,
}

templates_path = ["_templates"]
exclude_patterns = ["_build", "generated/*.examples", "generated/results", "results"]
root_doc = "index"
# single backticks render as code, as in scikit-learn's docstrings
default_role = "literal"

autosummary_generate = True
autosummary_imported_members = True
autodoc_typehints = "none"

numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

if os.environ.get("EPPF_DOCS_INTERSPHINX") == "1":
    intersphinx_mapping = {
        "python": ("https://docs.python.org/3", None),
        "numpy": ("https://numpy.org/doc/stable", None),
        "sklearn": ("https://scikit-learn.org/stable", None),
        "torch": ("https://docs.pytorch.org/docs/stable", None),
    }
else:
    intersphinx_mapping = {}

try:
    import pydata_sphinx_theme  # noqa: F401

    html_theme = "pydata_sphinx_theme"
except ImportError:  # pragma: no cover - the docs extra installs it
    html_theme = "alabaster"
html_title = f"eppf {release}"
html_static_path = []


def _write_cli_help(directory):
    """Write the ``--help`` text of ``eppf`` and each subcommand for cli.rst."""
    import argparse

    from eppf.cli import build_parser

    os.environ["COLUMNS"] = "88"
    os.makedirs(directory, exist_ok=True)
    parser = build_parser()
    parser.prog = "eppf"
    texts = {"eppf": parser.format_help()}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                texts[name] = sub.format_help()
    from eppf.experiments._cli import build_parser as build_experiments_parser

    exp = build_experiments_parser()
    exp.prog = "eppf experiment"
    texts["experiment"] = exp.format_help()
    for action in exp._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                sub.prog = f"eppf experiment {name}"
                texts[f"experiment-{name}"] = sub.format_help()
    for name, text in texts.items():
        path = os.path.join(directory, f"{name}.txt")
        old = None
        if os.path.exists(path):
            with open(path) as f:
                old = f.read()
        if old != text:  # rewrite only on change, so rebuilds stay incremental
            with open(path, "w") as f:
                f.write(text)


_write_cli_help(os.path.join(os.path.dirname(os.path.abspath(__file__)), "generated", "cli"))


def _data_docstring(app, what, name, obj, options, lines):
    """Document re-exported constants by their ``#:`` comment, not their type.

    autodoc looks for the comment in the module the name is documented under
    (``eppf``), but it lives in the private module that defines the constant;
    without this, ``eppf.FUNCTIONS`` would show the docstring of ``tuple``.
    """
    if what != "data":
        return
    from sphinx.pycode import ModuleAnalyzer

    attr = name.rsplit(".", 1)[-1]
    for modname, module in sorted(sys.modules.items()):
        if not modname.startswith("eppf") or getattr(module, attr, None) is not obj:
            continue
        try:
            docs = ModuleAnalyzer.for_module(modname).find_attr_docs()
        except Exception:  # compiled or source-less module
            continue
        if ("", attr) in docs:
            lines[:] = list(docs[("", attr)])
            return
    if type(obj).__doc__ and "\n".join(lines).strip() == type(obj).__doc__.strip():
        lines[:] = []


def _skip_member(app, what, name, obj, skip, options):
    """Leave out scikit-learn's generated ``set_*_request`` metadata-routing methods.

    They are not written by eppf and their docstrings link into scikit-learn's
    own glossary, which only resolves with intersphinx.
    """
    if name.startswith("set_") and name.endswith("_request"):
        return True
    return None


def setup(app):
    app.connect("autodoc-process-docstring", _data_docstring)
    app.connect("autodoc-skip-member", _skip_member)


def _write_results_pages(docs_dir):
    """Turn the experiment reports under results/ into reST for reproducing.rst."""
    sys.path.insert(0, docs_dir)
    from _md2rst import write_results

    generated = os.path.join(docs_dir, "generated", "results")
    done = write_results(os.path.join(docs_dir, "results"), generated)
    titles = {"retrieval": "Retrieval (Table II)", "classification": "Classification (Table III)",
              "ablation": "Function ablation", "noise": "Noise robustness", "runtime": "Runtime"}
    data_titles = {"modelnet10_1024": "ModelNet10 (1,024 points per object)",
                   "dales_objects": "DALES objects (aerial LiDAR)", "builtin": "Built-in synthetic shapes"}
    lines = []
    for data in sorted({d for d, _ in done}, key=lambda d: (list(data_titles).index(d) if d in data_titles else 99, d)):
        title = data_titles.get(data, data)
        lines += [title, "-" * len(title), ""]
        names = [n for d, n in done if d == data]
        for name in sorted(names, key=lambda n: (list(titles).index(n) if n in titles else 99, n)):
            sub = titles.get(name, name)
            lines += [sub, "~" * len(sub), "", f".. include:: /generated/results/{data}_{name}.rst", ""]
    if not lines:
        lines = ["No experiment results have been written to ``docs/results`` yet.", ""]
    text = "\n".join(lines)
    path = os.path.join(generated, "all.rst")
    if not os.path.exists(path) or open(path).read() != text:
        os.makedirs(generated, exist_ok=True)
        with open(path, "w") as f:
            f.write(text)


_write_results_pages(os.path.dirname(os.path.abspath(__file__)))
