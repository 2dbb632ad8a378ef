"""Data sets: the built-in synthetic shapes and loaders for files on disk."""

from ._npz import load_npz, save_npz
from ._synthetic import make_shapes
from ._loaders import load_modelnet, load_s3dis_objects, load_scannet_objects
from ._fetch import clear_data_home, fetch_file, fetch_modelnet, get_data_home
from ..descriptors import CachedTransformer  # noqa: F401 - its 0.1 place; it lives in eppf.descriptors
from ._folder import load_folder

__all__ = [
    "clear_data_home",
    "fetch_file",
    "fetch_modelnet",
    "get_data_home",
    "load_folder",
    "load_modelnet",
    "load_npz",
    "load_s3dis_objects",
    "load_scannet_objects",
    "make_shapes",
    "save_npz",
]
