"""A labeled data set from a folder of point cloud or mesh files, one
subfolder per class: the layout most users already have for their own scans."""

import os

import numpy as np
from sklearn.utils import Bunch

from ..io import read_point_cloud, supported_extensions
from ..io._api import check_flag, check_normals
from ..utils._param_validation import RANDOM_STATE, validate_parameter
from ._loaders import check_choice, check_class_names, check_dir, check_n_points, file_seeds, load_all

__all__ = ["folder_layout", "load_folder", "object_files"]

#: The split folders of a data folder, in the order a split layout lists them.
SPLITS = ("train", "test")


def _identity(path):
    """The (device, inode) of the folder ``path`` leads to, links followed; None when it cannot be read."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def object_files(folder):
    """Point cloud and mesh files under ``folder``, searched recursively, sorted by path.

    Every extension of :func:`eppf.io.supported_extensions` counts, in any
    case; hidden files and folders (names starting with ``.``) are skipped.
    Symbolic links are followed, to files and to folders alike (a class
    folder may be a link to where the scans are kept), and listed under the
    link's path; a link back to a folder it sits in (a cycle) is not
    descended into, so the search ends.
    """
    found, extensions = [], supported_extensions()
    # Per folder still to be visited, the identities of the folders above it
    # (and its own): a subfolder that is one of them is a link back up.
    above = {}
    for dirpath, dirnames, filenames in os.walk(folder, followlinks=True):
        chain = above.pop(dirpath, frozenset()) | {_identity(dirpath)}
        kept = []
        for d in sorted(d for d in dirnames if not d.startswith(".")):
            sub = os.path.join(dirpath, d)
            identity = _identity(sub)
            if identity is not None and identity not in chain:
                above[sub] = chain
                kept.append(d)
        dirnames[:] = kept
        found += [os.path.join(dirpath, f) for f in filenames
                  if not f.startswith(".") and os.path.splitext(f)[1].lower() in extensions]
    return sorted(found)


def folder_layout(root, files):
    """The class and split of each file of a data folder: the one train/test rule of eppf.

    The layout is the folder's, read from where its files sit (paths
    relative to ``root``):

    - ``train/<class>/...`` and ``test/<class>/...`` when some file sits
      under a ``train`` or ``test`` folder of ``root`` inside a class folder;
      then every other file is outside the layout;
    - otherwise ``<class>/train/...`` and ``<class>/test/...`` when some
      file sits in a ``train`` or ``test`` folder of a class folder; then the
      other files of the class folders are outside the layout;
    - otherwise ``<class>/...``, without a split.

    Files deeper in a class (or split) folder belong to it; files directly
    in ``root`` (or directly in ``root/train``) are outside the layout.
    ``eppf.datasets.load_folder`` and the ``eppf`` command line (``--data
    FOLDER``, a folder given to ``describe``) read folders by this rule.

    Parameters
    ----------
    root : str
        The data folder.
    files : list of str
        Files under ``root`` (as :func:`object_files` lists them).

    Returns
    -------
    layout : list of tuple or None
        Per file, ``(class, split)`` with ``split`` ``"train"``, ``"test"``
        or ``""`` (no split), or None for a file outside the layout.
    kind : {"split/class", "class/split", "class"}
        Which of the three layouts (the first two have a train/test split).

    Examples
    --------
    >>> from eppf.datasets._folder import folder_layout
    >>> folder_layout("d", ["d/train/cup/a.ply", "d/test/cup/b.ply", "d/notes.ply"])
    ([('cup', 'train'), ('cup', 'test'), None], 'split/class')
    >>> folder_layout("d", ["d/cup/a.ply", "d/cup/old/b.ply"])
    ([('cup', ''), ('cup', '')], 'class')
    """
    parts = [os.path.relpath(f, root).replace(os.sep, "/").split("/") for f in files]
    if any(len(p) >= 3 and p[0] in SPLITS for p in parts):
        return [(p[1], p[0]) if len(p) >= 3 and p[0] in SPLITS else None for p in parts], "split/class"
    if any(len(p) >= 3 and p[1] in SPLITS for p in parts):
        return [(p[0], p[1]) if len(p) >= 3 and p[1] in SPLITS else None for p in parts], "class/split"
    return [(p[0], "") if len(p) >= 2 else None for p in parts], "class"


def _read_object(filename, n_points, normals, seed):
    """One object: meshes sampled (``n_points`` or 2,048 points), point files read (and resampled)."""
    return read_point_cloud(filename, normals=normals, n_points=n_points, random_state=seed)


def load_folder(path, *, classes=None, subset="all", n_points=None, normals="auto", on_error="raise",
                n_jobs=None, random_state=0, return_X_y=False):
    """Load a labeled data set from a folder with one subfolder per class.

    Three layouts are recognized, the class of an object being the name of
    its class folder (the rule of :func:`folder_layout`, which the ``eppf``
    command line shares):

    - ``<class>/<object file>`` (files may sit in deeper subfolders): no split;
    - ``train/<class>/<object file>`` and ``test/<class>/<object file>``;
      other files are left out;
    - ``<class>/train/<object file>`` and ``<class>/test/<object file>``;
      other files of the class folders are left out.

    Every file :func:`eppf.io.read_point_cloud` reads is loaded with it
    (extensions in any case, see :func:`eppf.io.supported_extensions`):
    point files (PLY without faces, PCD, XYZ, TXT, CSV, PTS, XYZN, XYZRGB,
    NPY, NPZ) as they are, meshes (OFF, OBJ, STL, PLY with faces) sampled
    area-uniformly. Hidden files and folders and other extensions are
    ignored. Symbolic links to files and folders are followed (a class
    folder may be a link), except a link back to a folder above it, which
    would make the search endless.

    Parameters
    ----------
    path : str, bytes or path-like
        The folder.
    classes : sequence of str, default=None
        Class folders to keep, in the order of ``target_names``; None keeps
        every class folder, sorted by name.
    subset : {"all", "train", "test"}, default="all"
        Which part of the split to load; only "all" for a folder without a
        split.
    n_points : int, default=None
        If given, every object is resampled (point files) or sampled (meshes)
        to this many points. If None, point files are kept as they are and
        meshes are sampled with 2,048 points. At most a billion
        (``eppf.utils._sampling.MAX_N_POINTS``).
    normals : {"auto", True, False}, default="auto"
        Whether to return normals (columns 3 to 5) when the files have them
        (face normals for meshes).
    on_error : {"raise", "skip"}, default="raise"
        Stop at an unreadable file, or skip it with a warning.
    n_jobs : int, default=None
        Files read in parallel through joblib.
    random_state : int, RandomState instance or None, default=0
        Seed of sampling; one seed per file, from its path relative to
        ``path``, so an object is the same cloud in every call.
    return_X_y : bool, default=False
        Return ``(data, target)`` instead of a Bunch.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        ``data`` (list of float64 arrays), ``target``, ``target_names``,
        ``split`` (None without a split), ``ids`` (paths relative to
        ``path`` without the extension), ``filenames``, ``skipped``.
    (data, target) : tuple
        If ``return_X_y`` is True.

    Raises
    ------
    TypeError
        If ``path`` is not a str, bytes or path-like object.
    FileNotFoundError
        If ``path`` is not a folder.
    ValueError
        If the folder holds no class folders or no object files of the
        requested classes, if a requested class has no folder, or if a file
        cannot be read and ``on_error="raise"``.

    Examples
    --------
    >>> import os
    >>> from eppf.datasets import load_folder, make_shapes
    >>> from eppf.io import write_point_cloud
    >>> clouds, y = make_shapes(2, n_points=300, classes=["box", "sphere"], return_X_y=True)
    >>> for k, (cloud, label) in enumerate(zip(clouds, y)):
    ...     os.makedirs(os.path.join("my_objects", ("crate", "ball")[label]), exist_ok=True)
    ...     write_point_cloud(os.path.join("my_objects", ("crate", "ball")[label], f"scan{k}.ply"), cloud)
    >>> data = load_folder("my_objects")
    >>> data.target_names.tolist(), data.target.tolist(), data.data[0].shape
    (['ball', 'crate'], [0, 0, 1, 1], (300, 3))
    """
    owner = "load_folder"
    root = check_dir(path, owner)
    check_choice(subset, "subset", ("all", "train", "test"), owner)
    check_choice(on_error, "on_error", ("raise", "skip"), owner)
    normals = check_normals(normals, owner)
    return_X_y = check_flag(return_X_y, "return_X_y", owner)
    n_points = check_n_points(n_points, owner)
    validate_parameter(random_state, RANDOM_STATE, name="random_state", owner=owner)
    classes = check_class_names(classes, owner, allow_none=True)

    files = object_files(root)
    layout, kind = folder_layout(root, files)
    has_split = kind != "class"
    entries = [(f, *cls) for f, cls in zip(files, layout) if cls is not None]  # (file, class, split)
    # listed split by split (train first) and class by class, or class by class (and split by split)
    order = {s: k for k, s in enumerate(("",) + SPLITS)}
    if kind == "split/class":
        entries.sort(key=lambda e: (order[e[2]], e[1], e[0]))
    else:
        entries.sort(key=lambda e: (e[1], order[e[2]], e[0]))
    found = sorted({e[1] for e in entries})
    if not found:
        raise ValueError(f"{owner}: {root!r} holds no class folders with object files "
                         f"({', '.join(supported_extensions())}); expected <class>/<file>, train|test/<class>/<file> "
                         "or <class>/train|test/<file>")
    if classes is None:
        names = found
    else:
        names = classes
        absent = [c for c in names if c not in found]
        if absent:
            raise ValueError(f"{owner}: no object files for the classes {absent} under {root!r}; "
                             f"its class folders are {found}")
    if not has_split and subset != "all":
        raise ValueError(f"{owner}: {root!r} has no train/test split, so subset must be 'all', got {subset!r}")
    index = {n: k for k, n in enumerate(names)}
    entries = [e for e in entries if e[1] in index and (subset == "all" or e[2] == subset)]
    if not entries:
        raise ValueError(f"{owner}: {root!r} holds no object files for subset={subset!r}")

    files = [e[0] for e in entries]
    seeds = file_seeds(random_state, root, files)
    jobs = [(f, _read_object, (f, n_points, normals, seed)) for f, seed in zip(files, seeds)]
    clouds, skipped = load_all(jobs, owner=owner, on_error=on_error, n_jobs=n_jobs)
    keep = [k for k, c in enumerate(clouds) if c is not None]
    if not keep:
        raise ValueError(f"{owner}: no object could be loaded ({len(skipped)} files skipped)")
    data = [np.asarray(clouds[k], dtype=np.float64) for k in keep]
    target = np.asarray([index[entries[k][1]] for k in keep], dtype=np.int64)
    if return_X_y:
        return data, target
    ids = [os.path.splitext(os.path.relpath(files[k], root))[0].replace(os.sep, "/") for k in keep]
    return Bunch(
        data=data,
        target=target,
        target_names=np.asarray(names, dtype=str),
        split=np.asarray([entries[k][2] for k in keep], dtype=str) if has_split else None,
        ids=np.asarray(ids, dtype=str),
        filenames=np.asarray([files[k] for k in keep], dtype=str),
        skipped=skipped,
    )
