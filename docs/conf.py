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

# The API reference is grouped by subpackage in the navigation: api.rst's
# sections become pages of their own (_write_api_pages below), which both
# themes list by title under "API reference".
try:
    import pydata_sphinx_theme  # noqa: F401

    html_theme = "pydata_sphinx_theme"
    html_theme_options = {"navigation_depth": 3, "show_toc_level": 1}
except ImportError:  # pragma: no cover - the docs extra installs it
    html_theme = "alabaster"
    html_sidebars = {"**": ["about.html", "navigation_titles.html", "relations.html", "searchbox.html"]}
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
                for nested in sub._actions:  # eppf experiment NAME
                    if isinstance(nested, argparse._SubParsersAction):
                        for exp_name, exp in nested.choices.items():
                            texts[f"{name}-{exp_name}"] = exp.format_help()
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


def _write_if_changed(path, text):
    """Write ``text`` to ``path`` unless it already holds it (keeps rebuilds incremental)."""
    if os.path.exists(path):
        with open(path) as f:
            if f.read() == text:
                return
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def _write_api_pages(docs_dir):
    """One page per section of api.rst, so the navigation groups the API by subpackage.

    api.rst is the one list of public names (tests/test_docs.py checks it is
    complete); each of its sections, in its order, becomes
    ``generated/api/<n>_<slug>.rst`` with the same text and an autosummary
    whose ``:toctree:`` makes the stub pages; api.rst's hidden toctree globs
    them in that numbered order. The sidebar then reads API reference >
    Foundations (eppf.utils) > check_int, ...
    """
    import re

    with open(os.path.join(docs_dir, "api.rst")) as f:
        text = f.read()
    folder = os.path.join(docs_dir, "generated", "api")
    os.makedirs(folder, exist_ok=True)
    heads = list(re.finditer(r"^(\S[^\n]*)\n-{3,}\n", text, flags=re.M))
    names = []
    for k, head in enumerate(heads):
        title = head.group(1).strip()
        body = text[head.end():heads[k + 1].start() if k + 1 < len(heads) else len(text)].strip("\n")
        body = body.replace(".. autosummary::\n", ".. autosummary::\n   :toctree: ..\n")
        slug = re.sub(r"[^a-z0-9]+", "_", title.split(" (")[0].lower()).strip("_")
        name = f"{k + 1:02d}_{slug}"
        names.append(name)
        _write_if_changed(os.path.join(docs_dir, "generated", "api", name + ".rst"),
                          f"{title}\n{'=' * len(title)}\n\n{body}\n")
    for f in set(os.listdir(folder)) - {n + ".rst" for n in names}:  # sections renamed or removed
        os.remove(os.path.join(folder, f))
    listed, module = set(), None
    for line in text.splitlines():
        m = re.match(r"\.\. currentmodule:: (\S+)", line)
        if m:
            module = m.group(1)
        elif module and re.fullmatch(r"   [A-Za-z_]\w*", line):
            listed.add(f"{module}.{line.strip()}")
    stubs = os.path.join(docs_dir, "generated")
    for f in os.listdir(stubs):  # stub pages of names moved or removed from api.rst
        if f.startswith("eppf.") and f.endswith(".rst") and f[:-4] not in listed:
            os.remove(os.path.join(stubs, f))


_write_api_pages(os.path.dirname(os.path.abspath(__file__)))


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
