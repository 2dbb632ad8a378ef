"""Loaders for the paper's data sets in their published folder layouts.

Every loader reads a local folder (see :mod:`eppf.datasets._fetch` for
downloads), returns a :class:`~sklearn.utils.Bunch` (or ``(X, y)`` with
``return_X_y=True``), and shares these conventions:

- ``data`` is a list of float64 clouds of shape (n_i, 3), or (n_i, 6) with
  normals; ``target`` int64 indices into ``target_names``; ``split`` the
  ``"train"``/``"test"`` string of each object; ``ids`` its name in the source;
  ``filenames`` the file it came from; ``skipped`` a list of
  ``(filename, message)`` for files that could not be read.
- ``on_error="raise"`` stops at the first unreadable file with an error that
  names it; ``on_error="skip"`` loads the rest and warns how many it skipped.
- Meshes are sampled with :func:`eppf.preprocessing.sample_mesh`; each file
  gets its own seed from ``random_state`` and its path inside the folder, so
  a cloud does not depend on ``n_jobs``, ``subset`` or on which other files
  could be read.
- Paths may be ``str``, ``bytes`` or path-like (:func:`os.fsdecode` makes
  them ``str``; anything else is a TypeError naming the parameter), and a
  folder's symbolic links are followed.
- ``n_points`` is at most a billion (``eppf.utils._sampling.MAX_N_POINTS``,
  the bound of :func:`eppf.io.read_point_cloud` too), refused before
  anything is allocated.
"""

import glob
import hashlib
import json
import numbers
import os
import re
import warnings

import numpy as np
from joblib import Parallel, delayed
from sklearn.utils import Bunch, check_random_state

from ..io import read_point_cloud, supported_extensions
from ..io._api import check_flag, check_normals
from ..utils._param_validation import RANDOM_STATE, Interval, Options, Satisfies, validate_parameter
from ..utils._validation import check_n_jobs
from ..utils._sampling import check_n_points, check_resolution

__all__ = ["load_modelnet", "load_s3dis_objects", "load_scannet_objects"]

MODELNET10_CLASSES = (
    "bathtub", "bed", "chair", "desk", "dresser", "monitor", "night_stand", "sofa", "table", "toilet",
)
SCANNET_CLASSES = (
    "basket", "bathtub", "bed", "cabinet", "chair", "keyboard", "lamp", "microwave", "pillow", "printer",
    "shelf", "stove", "table", "tv",
)
S3DIS_CLASSES = ("beam", "board", "bookcase", "chair", "column", "door", "sofa", "stairs", "table", "window")

# --------------------------------------------------------------------------- shared checks


def check_path(path, name, owner):
    """``path`` as a ``str``: a ``str``, ``bytes`` or :class:`os.PathLike` path (decoded by :func:`os.fsdecode`).

    Every path parameter of :mod:`eppf.datasets` accepts these three kinds
    alike; anything else is a TypeError naming ``owner`` and ``name``
    (``os.fspath``'s own message names neither, and a bytes path used to
    fail deep inside, where it met a ``str``).
    """
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise TypeError(f"{owner}: {name} must be a str, bytes or os.PathLike path, got {type(path).__name__}")
    try:
        return os.fsdecode(path)
    except TypeError:  # (a PathLike whose __fspath__ returns neither str nor bytes)
        raise TypeError(f"{owner}: {name} must be a str, bytes or os.PathLike path; {path!r} is a "
                        f"{type(path).__name__} whose __fspath__ returns neither") from None


def check_dir(path, owner, name="path"):
    path = check_path(path, name, owner)
    if not os.path.isdir(path):
        raise FileNotFoundError(f"{owner}: no such folder: {path!r}")
    return path


#: ModelNet's ``version`` (:mod:`eppf.utils._param_validation`), for the loader and the fetcher.
MODELNET_VERSION = [Options(numbers.Integral, values=[40, 10])]
#: ``train_size`` of the loaders that split by object.
TRAIN_SIZE = [Interval(numbers.Real, 0, 1, closed="neither", description="a number in (0, 1)")]


def check_class_names(classes, owner, *, allow_none=False, lower=False):
    """``classes`` as a list of distinct names (``str``, lower case when ``lower``), or None when allowed and given.

    A string, an empty collection or a repeated name is a ValueError and a
    value that is not a collection a TypeError, each naming ``owner``.
    """
    if classes is None and allow_none:
        return None
    what = "None or a non-empty sequence" if allow_none else "a non-empty sequence"
    if isinstance(classes, (str, bytes)) or not hasattr(classes, "__iter__"):
        exc = ValueError if isinstance(classes, (str, bytes)) else TypeError
        raise exc(f"{owner}: classes must be {what} of class names, got {classes!r}")
    names = [str(c).lower() if lower else str(c) for c in classes]
    if not names:
        raise ValueError(f"{owner}: classes must be {what} of class names, got {classes!r}")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"{owner}: classes repeats {repeated}; each class must be named once")
    return names


def check_choice(value, name, choices, owner):
    """Check that ``value`` is one of ``choices`` (compared with ``==``); return it."""
    choices = tuple(choices)
    validate_parameter(value, [Satisfies(lambda v: v in choices, f"one of {list(choices)}")], name=name, owner=owner)
    return value


def file_seeds(random_state, folder, files):
    """One 64-bit seed per file from ``random_state`` and the file's relative path.

    A file's seed does not depend on which other files are loaded (subset,
    classes, skipped files), so an object is the same cloud in every call.
    """
    base = int(check_random_state(random_state).randint(0, np.iinfo(np.int64).max, dtype=np.int64))
    seeds = []
    for f in files:
        # (surrogateescape: a name that is not UTF-8 hashes as its own bytes; UTF-8 names as before)
        key = f"{base}/{os.path.relpath(f, folder).replace(os.sep, '/')}".encode("utf-8", "surrogateescape")
        seeds.append(int.from_bytes(hashlib.blake2b(key, digest_size=8).digest(), "little"))
    return seeds


def _subset_splits(subset):
    return ("train", "test") if subset == "all" else (subset,)


# --------------------------------------------------------------------------- loading with error policy


def _guarded(func, args):
    # the errors a bad file raises (readers: ValueError; OS and h5py: OSError, KeyError)
    try:
        return func(*args), None
    except (ValueError, OSError, KeyError) as exc:
        return None, str(exc)


def load_all(jobs, *, owner, on_error, n_jobs):
    """Run ``jobs`` (list of (filename, func, args)); apply the error policy.

    Returns the list of results (None for skipped) and the skipped list.
    """
    if n_jobs is not None:  # (joblib's "n_jobs == 0 in Parallel has no meaning" named no loader; 1.5 passed)
        check_n_jobs(n_jobs, owner=owner)
    results = Parallel(n_jobs=n_jobs)(delayed(_guarded)(func, args) for _, func, args in jobs)
    skipped = []
    for (filename, _, _), (_, err) in zip(jobs, results):
        if err is not None:
            if on_error == "raise":
                raise ValueError(f"{owner}: could not read {filename!r}: {err}")
            skipped.append((filename, err))
    if skipped:
        warnings.warn(
            f"{owner}: skipped {len(skipped)} of {len(jobs)} files that could not be read; "
            f"the first is {skipped[0][0]!r} ({skipped[0][1]}). The list is in the 'skipped' field.",
            UserWarning,
            stacklevel=3,
        )
    return [r for r, _ in results], skipped


def _finish(owner, clouds, labels, names, splits, ids, filenames, skipped, return_X_y, **extra):
    keep = [k for k, c in enumerate(clouds) if c is not None]
    if not keep:
        raise ValueError(f"{owner}: no object could be loaded ({len(skipped)} files skipped)")
    data = [clouds[k] for k in keep]
    target = np.asarray([labels[k] for k in keep], dtype=np.int64)
    if return_X_y:
        return data, target
    return Bunch(
        data=data,
        target=target,
        target_names=np.asarray(names, dtype=str),
        split=np.asarray([splits[k] for k in keep], dtype=str),
        ids=np.asarray([ids[k] for k in keep], dtype=str),
        filenames=np.asarray([filenames[k] for k in keep], dtype=str),
        skipped=skipped,
        **extra,
    )


def _from_mesh(filename, n_points, resolution, normals, seed):
    return read_point_cloud(filename, normals=normals, n_points=n_points, resolution=resolution, random_state=seed)


def _from_cloud_file(filename, n_points, normals, seed, first=False):
    if first:  # pre-sampled files: their first n_points points
        cloud = read_point_cloud(filename, normals=normals)
        if n_points is not None:
            if cloud.shape[0] < n_points:
                raise ValueError(f"{filename!r} has {cloud.shape[0]} points, fewer than n_points={n_points}")
            cloud = cloud[:n_points]
        return cloud
    return read_point_cloud(filename, normals=normals, n_points=n_points, random_state=seed)


def _from_any(filename, n_points, resolution, normals, seed):
    """Any supported file: meshes sampled (n_points, or resolution without it), point files resampled."""
    return read_point_cloud(filename, normals=normals, n_points=n_points,
                            resolution=None if n_points is not None else resolution, random_state=seed)


# --------------------------------------------------------------------------- ModelNet


def _find_modelnet(root, version):
    """Return (layout, folder) for the first layout found under ``root``."""
    candidates = [root, os.path.join(root, f"ModelNet{version}"), os.path.join(root, "ModelNet40"),
                  os.path.join(root, "modelnet40_ply_hdf5_2048"), os.path.join(root, "modelnet40_normal_resampled")]
    for folder in candidates:
        if not os.path.isdir(folder):
            continue
        if glob.glob(os.path.join(folder, "ply_data_*.h5")):
            return "hdf5", folder
        if glob.glob(os.path.join(folder, "modelnet*_shape_names.txt")):
            return "resampled", folder
        for entry in sorted(os.listdir(folder)):
            sub = os.path.join(folder, entry)
            if os.path.isdir(os.path.join(sub, "train")) or os.path.isdir(os.path.join(sub, "test")):
                return "official", folder
    raise ValueError(
        f"load_modelnet: no ModelNet layout found in {root!r}: expected <class>/<train|test>/*.off folders, "
        "modelnet40_shape_names.txt with <class>/<id>.txt files (modelnet40_normal_resampled), "
        "or ply_data_*.h5 files (modelnet40_ply_hdf5_2048)"
    )


def _read_lines(path):
    with open(path) as fh:
        return [line.strip() for line in fh if line.strip()]


def _restrict(names, version, owner, folder):
    """Class names kept for ``version`` and the map from old to new label."""
    if version == 10:
        kept = [n for n in names if n in MODELNET10_CLASSES]
        if not kept:
            raise ValueError(f"{owner}: {folder!r} holds none of the ModelNet10 classes {list(MODELNET10_CLASSES)}")
    else:
        kept = list(names)
    return kept, {n: k for k, n in enumerate(kept)}


def _h5_file_index(path):
    match = re.search(r"(\d+)\.h5$", os.path.basename(path))
    return int(match.group(1)) if match else 0


def _read_h5(filename, n_points, normals):
    try:
        import h5py
    except ImportError:
        raise ImportError(
            "load_modelnet: the HDF5 layout needs the 'h5py' package; install it with `pip install eppf[io]`"
        ) from None
    try:
        with h5py.File(filename, "r") as fh:
            if "data" not in fh or "label" not in fh:
                raise ValueError(f"{filename!r} lacks the 'data' or 'label' data set; it has {sorted(fh.keys())}")
            data = np.asarray(fh["data"], dtype=np.float64)
            label = np.asarray(fh["label"]).reshape(-1).astype(np.int64)
            nrm = np.asarray(fh["normal"], dtype=np.float64) if "normal" in fh and normals is not False else None
    except OSError as exc:
        raise ValueError(f"{filename!r} is not a readable HDF5 file ({exc})") from None
    if data.ndim != 3 or data.shape[2] != 3 or label.shape[0] != data.shape[0]:
        raise ValueError(f"{filename!r}: 'data' must have shape (n, n_points, 3) matching 'label', got {data.shape}")
    if normals is True and nrm is None:
        raise ValueError(f"{filename!r} has no 'normal' data set, but normals=True")
    if n_points is not None:
        if data.shape[1] < n_points:
            raise ValueError(f"{filename!r} has {data.shape[1]} points per object, fewer than n_points={n_points}")
        data = data[:, :n_points]
        nrm = nrm[:, :n_points] if nrm is not None else None
    if nrm is not None:
        data = np.concatenate([data, nrm], axis=2)
    return data, label


def load_modelnet(path, *, version=40, subset="all", n_points=2048, resolution=None, normals="auto",
                  on_error="raise", n_jobs=None, random_state=0, return_X_y=False):
    """Load ModelNet10 or ModelNet40 from a local folder.

    Three published layouts are recognized (in ``path`` or its
    ``ModelNet40``/``ModelNet10`` subfolder):

    - ``official``: Princeton's ``<class>/<train|test>/<class>_<k>.off``
      meshes, sampled here to ``n_points`` points (or at ``resolution``).
    - ``resampled``: ``modelnet40_normal_resampled``, with
      ``modelnet40_shape_names.txt``, ``modelnet40_train.txt``,
      ``modelnet40_test.txt`` (or the ``modelnet10_*`` lists) and
      ``<class>/<id>.txt`` files of ``x,y,z,nx,ny,nz`` rows.
    - ``hdf5``: ``modelnet40_ply_hdf5_2048``, with ``ply_data_train*.h5`` and
      ``ply_data_test*.h5`` (data sets ``data``, ``label`` and optionally
      ``normal``) and ``shape_names.txt``.

    Parameters
    ----------
    path : str or path-like
        The folder.
    version : {40, 10}, default=40
        ModelNet40, or its ten-class subset. With ``version=10`` a ModelNet40
        folder is restricted to the ModelNet10 classes.
    subset : {"all", "train", "test"}, default="all"
        Which part of the official split to load.
    n_points : int or None, default=2048
        Points per object. Meshes are sampled with this many points;
        pre-sampled layouts keep their first ``n_points`` points (their order
        is already random); None keeps them all (pre-sampled layouts only).
    resolution : float, default=None
        Instead of ``n_points``, sample meshes on a voxel grid of this size
        (the paper: 1 cm in the model's units); official layout only.
    normals : {"auto", True, False}, default="auto"
        Whether to return normals as columns 3 to 5: face normals of sampled
        meshes, stored normals of pre-sampled layouts. ``"auto"`` returns them
        when available; True requires them.
    on_error : {"raise", "skip"}, default="raise"
        What to do with a file that cannot be read: stop with an error naming
        it, or skip it with a warning that says how many were skipped.
    n_jobs : int, default=None
        Files read in parallel through joblib (None: one, unless inside a
        :func:`joblib.parallel_config` context).
    random_state : int, RandomState instance or None, default=0
        Seed of mesh sampling; each file's seed derives from it and the
        file's path inside the folder.
    return_X_y : bool, default=False
        Return ``(data, target)`` instead of a Bunch.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        ``data``, ``target``, ``target_names``, ``split``, ``ids``,
        ``filenames``, ``skipped`` (see :mod:`eppf.datasets`) and ``layout``.
    (data, target) : tuple
        If ``return_X_y`` is True.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a folder.
    ValueError
        If no layout is found, a parameter is invalid, or (with
        ``on_error="raise"``) a file cannot be read.

    See Also
    --------
    load_npz : The flat ``.npz`` layout.
    eppf.preprocessing.sample_mesh : How meshes become clouds.

    Examples
    --------
    >>> import os, tempfile
    >>> from eppf.datasets import load_modelnet
    >>> root = tempfile.mkdtemp()
    >>> os.makedirs(os.path.join(root, "chair", "train"))
    >>> with open(os.path.join(root, "chair", "train", "chair_0001.off"), "w") as fh:
    ...     _ = fh.write("OFF3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
    >>> data = load_modelnet(root, n_points=64)
    >>> data.data[0].shape, data.target_names.tolist(), data.layout
    ((64, 6), ['chair'], 'official')
    """
    owner = "load_modelnet"
    root = check_dir(path, owner)
    validate_parameter(version, MODELNET_VERSION, name="version", owner=owner)
    check_choice(subset, "subset", ("all", "train", "test"), owner)
    check_choice(on_error, "on_error", ("raise", "skip"), owner)
    normals = check_normals(normals, owner)
    return_X_y = check_flag(return_X_y, "return_X_y", owner)
    resolution = check_resolution(resolution, owner)
    if resolution is not None and n_points is not None:
        raise ValueError(f"{owner}: give n_points or resolution, not both (set n_points=None to use resolution)")
    n_points = check_n_points(n_points, owner)
    validate_parameter(random_state, RANDOM_STATE, name="random_state", owner=owner)
    layout, folder = _find_modelnet(root, version)
    splits = _subset_splits(subset)
    if layout == "official":
        if n_points is None and resolution is None:
            raise ValueError(f"{owner}: meshes need n_points or resolution to be sampled")
        classes = sorted(
            e for e in os.listdir(folder)
            if any(os.path.isdir(os.path.join(folder, e, s)) for s in ("train", "test"))
        )
        names, index = _restrict(classes, version, owner, folder)
        files, labels, split_of = [], [], []
        for name in names:
            for s in splits:
                found = sorted(glob.glob(os.path.join(folder, name, s, "*.off")))
                files += found
                labels += [index[name]] * len(found)
                split_of += [s] * len(found)
        if not files:
            raise ValueError(f"{owner}: {folder!r} holds no .off files for subset={subset!r}")
        seeds = file_seeds(random_state, folder, files)
        use_normals = normals is not False
        jobs = [(f, _from_mesh, (f, n_points, resolution, use_normals, seed)) for f, seed in zip(files, seeds)]
        clouds, skipped = load_all(jobs, owner=owner, on_error=on_error, n_jobs=n_jobs)
        ids = [os.path.splitext(os.path.basename(f))[0] for f in files]
        return _finish(owner, clouds, labels, names, split_of, ids, files, skipped, return_X_y, layout=layout)
    if resolution is not None:
        raise ValueError(f"{owner}: resolution applies to meshes; the {layout!r} layout in {folder!r} is already sampled")
    if layout == "resampled":
        return _load_resampled(folder, version, splits, n_points, normals, on_error, n_jobs, return_X_y, owner)
    return _load_hdf5(folder, version, splits, n_points, normals, on_error, return_X_y, owner)


def _load_resampled(folder, version, splits, n_points, normals, on_error, n_jobs, return_X_y, owner):
    prefix = f"modelnet{version}" if os.path.exists(os.path.join(folder, f"modelnet{version}_shape_names.txt")) else "modelnet40"
    all_names = _read_lines(os.path.join(folder, f"{prefix}_shape_names.txt"))
    names, index = _restrict(all_names, version, owner, folder)
    files, labels, split_of, ids = [], [], [], []
    for s in splits:
        list_file = os.path.join(folder, f"{prefix}_{s}.txt")
        if not os.path.exists(list_file):
            raise ValueError(f"{owner}: {folder!r} lacks the split list {os.path.basename(list_file)!r}")
        for obj_id in _read_lines(list_file):
            name = obj_id.rsplit("_", 1)[0]
            if name not in index:
                if name not in all_names:
                    raise ValueError(f"{owner}: {list_file!r} names {obj_id!r}, whose class {name!r} is not in the shape names")
                continue
            files.append(os.path.join(folder, name, obj_id + ".txt"))
            labels.append(index[name])
            split_of.append(s)
            ids.append(obj_id)
    jobs = [(f, _from_cloud_file, (f, n_points, normals, 0, True)) for f in files]
    clouds, skipped = load_all(jobs, owner=owner, on_error=on_error, n_jobs=n_jobs)
    return _finish(owner, clouds, labels, names, split_of, ids, files, skipped, return_X_y, layout="resampled")


def _load_hdf5(folder, version, splits, n_points, normals, on_error, return_X_y, owner):
    names_file = os.path.join(folder, "shape_names.txt")
    if not os.path.exists(names_file):
        raise ValueError(f"{owner}: {folder!r} lacks shape_names.txt, which names the HDF5 labels")
    all_names = _read_lines(names_file)
    names, index = _restrict(all_names, version, owner, folder)
    remap = np.array([index.get(n, -1) for n in all_names], dtype=np.int64)
    files = []
    for s in splits:
        files += [(f, s) for f in sorted(glob.glob(os.path.join(folder, f"ply_data_{s}*.h5")), key=_h5_file_index)]
    jobs = [(f, _read_h5, (f, n_points, normals)) for f, _ in files]
    blocks, skipped = load_all(jobs, owner=owner, on_error=on_error, n_jobs=None)
    clouds, labels, split_of, ids, filenames = [], [], [], [], []
    for (f, s), block in zip(files, blocks):
        if block is None:
            continue
        data, label = block
        if label.size and (label.min() < 0 or label.max() >= len(all_names)):
            msg = f"labels outside 0..{len(all_names) - 1}"
            if on_error == "raise":
                raise ValueError(f"{owner}: could not read {f!r}: {msg}")
            skipped.append((f, msg))
            continue
        id_file = os.path.splitext(f)[0].replace(f"ply_data_{s}", f"ply_data_{s}_") + "_id2file.json"
        file_ids = None
        if os.path.exists(id_file):
            with open(id_file) as fh:
                file_ids = json.load(fh)
        for row in range(data.shape[0]):
            new = remap[label[row]]
            if new < 0:
                continue
            clouds.append(data[row])
            labels.append(int(new))
            split_of.append(s)
            ids.append(os.path.splitext(os.path.basename(file_ids[row]))[0] if file_ids else f"{os.path.basename(f)}:{row}")
            filenames.append(f)
    return _finish(owner, clouds, labels, names, split_of, ids, filenames, skipped, return_X_y, layout="hdf5")


# --------------------------------------------------------------------------- ScanNet


def load_scannet_objects(path, *, subset="all", classes=SCANNET_CLASSES, n_points=None, resolution=0.01,
                         normals="auto", on_error="raise", n_jobs=None, random_state=0, return_X_y=False):
    """Load ScanNet object crops with the paper's 14 classes and the official split.

    The paper keeps the ShapeNet-compatible ScanNet classes of Dai et al.
    (2017) and drops *laptop* (18 instances): basket, bathtub, bed, cabinet,
    chair, keyboard, lamp, microwave, pillow, printer, shelf, stove, table, tv;
    5,203 training and 1,699 test objects.

    The folder holds one file per object, arranged as
    ``<train|test>/<class>/<object>.<ext>`` or ``<class>/<train|test>/<object>.<ext>``,
    or ``<class>/<object>.<ext>`` next to ``train.txt`` and ``test.txt`` lists
    of object names or scene ids (``sceneXXXX_XX``, matched against the start
    of the object's file name). Class folder names are compared in lower case;
    other classes are ignored. Meshes (``.off``, ``.obj``, ``.ply`` with
    faces) are sampled; point files (``.ply``, ``.pcd``, ``.xyz``, ``.txt``,
    ``.npy``, ...) are read as they are.

    Parameters
    ----------
    path : str or path-like
        The folder.
    subset : {"all", "train", "test"}, default="all"
        Which part of the split to load.
    classes : sequence of str, default=the paper's 14 classes
        Classes to keep; ``target_names`` follows this order.
    n_points : int, default=None
        If given, meshes are sampled with this many points and point files
        are resampled to it (see :func:`eppf.preprocessing.Resampler`).
    resolution : float, default=0.01
        Voxel size for sampling meshes when ``n_points`` is None (the paper's
        1 cm, in meters).
    normals : {"auto", True, False}, default="auto"
        Whether to return normals (columns 3 to 5) when the files have them.
    on_error : {"raise", "skip"}, default="raise"
        Stop at an unreadable file, or skip it with a warning.
    n_jobs : int, default=None
        Files read in parallel through joblib.
    random_state : int, RandomState instance or None, default=0
        Seed of sampling; one seed per file.
    return_X_y : bool, default=False
        Return ``(data, target)`` instead of a Bunch.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        ``data``, ``target``, ``target_names``, ``split``, ``ids``,
        ``filenames``, ``skipped``.
    (data, target) : tuple
        If ``return_X_y`` is True.

    Examples
    --------
    A folder in the ``<split>/<class>/<object>`` layout, written here from
    two built-in shapes per class:

    >>> import os
    >>> from eppf.datasets import load_scannet_objects, make_shapes
    >>> from eppf.io import write_point_cloud
    >>> clouds, y = make_shapes(2, n_points=200, classes=["box", "sphere"], return_X_y=True)
    >>> for k, (cloud, label) in enumerate(zip(clouds, y)):
    ...     folder = os.path.join("scans", ("train", "test")[k % 2], ("cabinet", "basket")[label])
    ...     os.makedirs(folder, exist_ok=True)
    ...     write_point_cloud(os.path.join(folder, f"obj{k}.xyz"), cloud)
    >>> train = load_scannet_objects("scans", subset="train")
    >>> len(train.data), train.data[0].shape, set(train.split.tolist())
    (2, (200, 3), {'train'})
    """
    owner = "load_scannet_objects"
    root = check_dir(path, owner)
    check_choice(subset, "subset", ("all", "train", "test"), owner)
    check_choice(on_error, "on_error", ("raise", "skip"), owner)
    normals = check_normals(normals, owner)
    return_X_y = check_flag(return_X_y, "return_X_y", owner)
    n_points = check_n_points(n_points, owner)
    validate_parameter(random_state, RANDOM_STATE, name="random_state", owner=owner)
    resolution = check_resolution(resolution, owner)
    if n_points is None and resolution is None:
        raise ValueError(f"{owner}: give n_points or resolution (meshes must be sampled)")
    names = check_class_names(classes, owner, lower=True)
    index = {n: k for k, n in enumerate(names)}
    exts = supported_extensions()

    def objects_in(folder):
        return sorted(f for f in glob.glob(os.path.join(folder, "*")) if os.path.splitext(f)[1].lower() in exts)

    entries = []  # (file, class, split)
    if any(os.path.isdir(os.path.join(root, s)) for s in ("train", "test")):
        for s in ("train", "test"):
            for cls_dir in sorted(glob.glob(os.path.join(root, s, "*"))):
                entries += [(f, os.path.basename(cls_dir).lower(), s) for f in objects_in(cls_dir)]
    else:
        class_dirs = sorted(d for d in glob.glob(os.path.join(root, "*")) if os.path.isdir(d))
        nested = any(os.path.isdir(os.path.join(d, s)) for d in class_dirs for s in ("train", "test"))
        if nested:
            for d in class_dirs:
                for s in ("train", "test"):
                    entries += [(f, os.path.basename(d).lower(), s) for f in objects_in(os.path.join(d, s))]
        else:
            lists = {s: os.path.join(root, f"{s}.txt") for s in ("train", "test")}
            missing = [os.path.basename(p) for p in lists.values() if not os.path.exists(p)]
            if missing:
                raise ValueError(
                    f"{owner}: {root!r} has neither train/ and test/ folders nor the split lists {missing}"
                )
            members = {s: set(_read_lines(p)) for s, p in lists.items()}
            for d in class_dirs:
                for f in objects_in(d):
                    stem = os.path.splitext(os.path.basename(f))[0]
                    scene = re.match(r"scene\d+_\d+", stem)
                    keys = {stem} | ({scene.group(0)} if scene else set())
                    where = [s for s in ("train", "test") if keys & members[s]]
                    if len(where) == 1:
                        entries.append((f, os.path.basename(d).lower(), where[0]))
    entries = [e for e in entries if e[1] in index and e[2] in _subset_splits(subset)]
    if not entries:
        raise ValueError(f"{owner}: {root!r} holds no object files of the classes {names} for subset={subset!r}")
    files = [e[0] for e in entries]
    seeds = file_seeds(random_state, root, files)
    jobs = [(f, _from_any, (f, n_points, resolution, normals, seed)) for f, seed in zip(files, seeds)]
    clouds, skipped = load_all(jobs, owner=owner, on_error=on_error, n_jobs=n_jobs)
    labels = [index[e[1]] for e in entries]
    ids = [os.path.splitext(os.path.basename(f))[0] for f in files]
    return _finish(owner, clouds, labels, names, [e[2] for e in entries], ids, files, skipped, return_X_y)


# --------------------------------------------------------------------------- S3DIS


def _check_areas(areas, owner):
    """``areas`` as a list of non-negative ints, or an error naming ``owner``.

    (``int(a)`` for ``a`` in ``areas`` read the string "12" as areas 1 and 2,
    a float 1.7 as area 1, and an int failed with "'int' object is not iterable".)
    """
    if isinstance(areas, (str, bytes)) or not hasattr(areas, "__iter__"):
        raise TypeError(f"{owner}: areas must be None or a sequence of area numbers (ints), got {areas!r}")
    areas = list(areas)
    bad = [a for a in areas if not isinstance(a, numbers.Integral) or isinstance(a, bool) or a < 0]
    if bad:
        raise ValueError(f"{owner}: areas must be non-negative ints (the n of Area_<n>), got {bad[0]!r}")
    return [int(a) for a in areas]


def load_s3dis_objects(path, *, subset="all", classes=S3DIS_CLASSES, areas=None, train_size=0.6, n_points=None,
                       on_error="raise", n_jobs=None, random_state=0, return_X_y=False):
    """Load the object instances of the Stanford indoor data set (S3DIS).

    Reads the ``Area_<n>/<room>/Annotations/<class>_<k>.txt`` files of
    ``Stanford3dDataset_v1.2`` (rows ``x y z r g b``; colors are dropped).
    The paper keeps 10 classes, leaving out *clutter* and the planar *floor*,
    *ceiling* and *wall*, and, since the official split by building leaves
    some classes out of one side, splits each class's instances 60/40 at
    random into training and test sets. That split is seeded by
    ``random_state`` and does not depend on which files could be read.

    Parameters
    ----------
    path : str or path-like
        The folder holding the ``Area_<n>`` folders (or its parent).
    subset : {"all", "train", "test"}, default="all"
        Which part of the split to load.
    classes : sequence of str, default=the paper's 10 classes
        Classes to keep: beam, board, bookcase, chair, column, door, sofa,
        stairs, table, window.
    areas : sequence of int, default=None
        Areas to read (e.g. ``[1, 2, 3]``); None reads all.
    train_size : float, default=0.6
        Share of each class's instances in the training set.
    n_points : int, default=None
        If given, resample every object to this many points.
    on_error : {"raise", "skip"}, default="raise"
        Stop at an unreadable file, or skip it with a warning.
    n_jobs : int, default=None
        Files read in parallel through joblib.
    random_state : int, RandomState instance or None, default=0
        Seed of the split and of resampling.
    return_X_y : bool, default=False
        Return ``(data, target)`` instead of a Bunch.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        ``data`` (xyz clouds), ``target``, ``target_names``, ``split``,
        ``ids`` (``Area_1/office_1/chair_3``), ``filenames``, ``skipped``.
    (data, target) : tuple
        If ``return_X_y`` is True.

    Examples
    --------
    One room whose annotation files (``x y z r g b`` rows) hold two chairs
    and two tables, written here from built-in shapes:

    >>> import os
    >>> import numpy as np
    >>> from eppf.datasets import load_s3dis_objects, make_shapes
    >>> clouds, y = make_shapes(2, n_points=200, classes=["box", "sphere"], return_X_y=True)
    >>> folder = os.path.join("s3dis", "Area_1", "office_1", "Annotations")
    >>> os.makedirs(folder)
    >>> for k, (cloud, label) in enumerate(zip(clouds, y)):
    ...     rows = np.hstack([cloud, np.full((len(cloud), 3), 128.0)])
    ...     np.savetxt(os.path.join(folder, f"{('chair', 'table')[label]}_{k}.txt"), rows)
    >>> data = load_s3dis_objects("s3dis", train_size=0.5)
    >>> len(data.data), sorted(set(data.split.tolist())), str(data.ids[0])
    (4, ['test', 'train'], 'Area_1/office_1/chair_0')
    """
    owner = "load_s3dis_objects"
    root = check_dir(path, owner)
    check_choice(subset, "subset", ("all", "train", "test"), owner)
    check_choice(on_error, "on_error", ("raise", "skip"), owner)
    return_X_y = check_flag(return_X_y, "return_X_y", owner)
    n_points = check_n_points(n_points, owner)
    validate_parameter(random_state, RANDOM_STATE, name="random_state", owner=owner)
    validate_parameter(train_size, TRAIN_SIZE, name="train_size", owner=owner)
    names = check_class_names(classes, owner)
    areas = None if areas is None else _check_areas(areas, owner)
    index = {n: k for k, n in enumerate(names)}
    pattern = os.path.join("Area_*", "*", "Annotations", "*.txt")
    files = sorted(glob.glob(os.path.join(root, pattern))) or sorted(glob.glob(os.path.join(root, "*", pattern)))
    if not files:
        raise ValueError(f"{owner}: no Area_<n>/<room>/Annotations/<class>_<k>.txt files under {root!r}")
    if areas is not None:
        wanted = {f"Area_{a}" for a in areas}
        files = [f for f in files if f.split(os.sep)[-4] in wanted]
    entries = []
    for f in files:
        cls = os.path.basename(f)[:-4].rsplit("_", 1)[0]
        if cls in index:
            entries.append((f, cls))
    if not entries:
        raise ValueError(f"{owner}: no annotation files of the classes {names} under {root!r}")
    rng = check_random_state(random_state)
    split_of = [""] * len(entries)
    for name in names:
        members = [k for k, e in enumerate(entries) if e[1] == name]
        order = rng.permutation(len(members))
        n_train = int(np.floor(train_size * len(members) + 0.5))
        for rank, j in enumerate(order):
            split_of[members[j]] = "train" if rank < n_train else "test"
    seeds = file_seeds(rng, root, [f for f, _ in entries])
    keep = [k for k in range(len(entries)) if split_of[k] in _subset_splits(subset)]
    jobs = [(entries[k][0], _from_cloud_file, (entries[k][0], n_points, False, seeds[k])) for k in keep]
    clouds, skipped = load_all(jobs, owner=owner, on_error=on_error, n_jobs=n_jobs)
    kept = [entries[k] for k in keep]
    ids = ["/".join(f.split(os.sep)[-4:-2] + [os.path.basename(f)[:-4]]) for f, _ in kept]
    return _finish(owner, clouds, [index[c] for _, c in kept], names, [split_of[k] for k in keep], ids,
                   [f for f, _ in kept], skipped, return_X_y)
