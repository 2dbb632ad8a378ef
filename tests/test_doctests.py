"""Every Examples section in the public docstrings runs and prints what it
says (the docs promise a working example for each public name)."""

import doctest
import importlib
import pkgutil

import numpy as np
import pytest

import eppf

OPTIONAL = {"eppf.plotting": "matplotlib"}


def _modules():
    names = ["eppf"]
    # Private modules too: they hold the public classes and functions.
    for info in pkgutil.walk_packages(eppf.__path__, prefix="eppf."):
        names += [info.name]
    # ``__main__`` modules run the command line when imported.
    return sorted(n for n in set(names) if not n.endswith("__main__"))


MODULES = _modules()


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name, monkeypatch, tmp_path):
    if int(np.__version__.split(".")[0]) < 2:
        pytest.skip("the examples print NumPy 2's scalars (np.True_, np.float64(0.5)); this is NumPy " + np.__version__)
    if name in OPTIONAL:
        pytest.importorskip(OPTIONAL[name])
    if name.startswith("eppf.experiments"):
        pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)  # examples that write files write them here
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(
        optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in finder.find(module, name):
        # Only docstrings defined in this module: re-exports are tested where
        # they live.
        if test.filename and not test.filename.endswith(
                module.__file__.rsplit("/", 1)[-1]):
            continue
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} docstring example(s) failed in {name}"


def test_public_names_have_examples():
    """Every public class and function in the API reference shows an example."""
    import inspect

    from tests._public_api import public_modules

    missing = []
    for modname, module in public_modules():
        for attr in module.__all__:
            obj = getattr(module, attr)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue
            if "Examples\n--------" not in (inspect.getdoc(obj) or ""):
                missing.append(f"{modname}.{attr}")
    assert not missing, "no Examples section: " + ", ".join(missing)
