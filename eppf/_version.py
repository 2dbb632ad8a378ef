"""The version of eppf, written in this one place.

``pyproject.toml`` reads it at build time (``[tool.setuptools.dynamic]``), and
``eppf.__version__``, ``eppf --version`` and the manifest of every saved model
take it from here.
"""

__version__ = "0.2.0"
