"""The public modules whose names the API reference and the docstring checks cover."""

import importlib

PUBLIC_MODULES = ("eppf", "eppf.utils", "eppf.io", "eppf.preprocessing", "eppf.segmentation",
                  "eppf.descriptors", "eppf.neighbors",
                  "eppf.classifiers", "eppf.nn", "eppf.datasets", "eppf.metrics", "eppf.plotting", "eppf.experiments",
                  "eppf.registry")


def public_modules():
    """The public modules that import here (eppf.plotting needs matplotlib), as (name, module) pairs."""
    out = []
    for name in PUBLIC_MODULES:
        try:
            out.append((name, importlib.import_module(name)))
        except ImportError:
            continue
    return out
