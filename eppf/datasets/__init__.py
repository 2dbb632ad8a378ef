"""Data sets: the built-in synthetic shapes and loaders for files on disk."""

from ._npz import load_npz

__all__ = ["load_npz"]
