"""Data sets: the built-in synthetic shapes and loaders for files on disk."""

from ._npz import load_npz
from ._synthetic import make_shapes

__all__ = ["load_npz", "make_shapes"]
