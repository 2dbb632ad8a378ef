"""Reader and writer of the flat ``.npz`` layout of point-cloud data sets."""

import errno
import numbers
import os

import numpy as np
from sklearn.utils import Bunch

from ..io._api import check_flag
from ..io._npy import read_npz_arrays
from ..utils._atomic import atomic_write
from ._loaders import check_path

__all__ = ["load_npz", "save_npz"]

_REQUIRED = ("points", "offsets", "labels", "class_names")


def load_npz(path, *, return_X_y=False):
    """Load point clouds stored in the flat ``.npz`` layout.

    The layout holds ``points`` (sum n_i, 3) or (sum n_i, 6) float, ``offsets``
    (n_objects + 1,) int, ``labels`` (n_objects,) int indices into
    ``class_names`` (n_classes,) str, and optionally ``split`` (n_objects,) str
    of ``"train"``/``"test"`` and ``ids`` (n_objects,) str. Object ``k`` is
    ``points[offsets[k]:offsets[k + 1]]``. The file is read without pickle.

    Parameters
    ----------
    path : str or path-like
        The ``.npz`` file.
    return_X_y : bool, default=False
        If True, return ``(clouds, labels)`` instead of a Bunch.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        ``data`` (list of float64 arrays), ``target`` (int64 labels),
        ``target_names``, ``split`` (or None), ``ids`` (or None), ``filename``.
    (clouds, labels) : tuple
        If ``return_X_y`` is True.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file is not a readable ``.npz`` or its arrays are inconsistent.

    See Also
    --------
    save_npz : Write clouds in this layout.
    make_shapes : The built-in synthetic data set, in the same layout.
    load_folder : Point clouds from a folder of files.

    Examples
    --------
    Two objects of 3 and 2 points, one per class:

    >>> import numpy as np
    >>> from eppf.datasets import load_npz
    >>> points = np.arange(15, dtype=float).reshape(5, 3)
    >>> np.savez("two.npz", points=points, offsets=[0, 3, 5], labels=[1, 0],
    ...          class_names=["chair", "table"], split=["train", "test"])
    >>> data = load_npz("two.npz")
    >>> [cloud.shape for cloud in data.data]
    [(3, 3), (2, 3)]
    >>> data.target_names[data.target].tolist(), data.split.tolist()
    (['table', 'chair'], ['train', 'test'])
    """
    path = check_path(path, "path", "load_npz")
    return_X_y = check_flag(return_X_y, "return_X_y", "load_npz")
    if not os.path.exists(path):
        raise FileNotFoundError(f"load_npz: no such file: {path!r}")
    archive = read_npz_arrays(path, "load_npz")  # (headers checked against the stored bytes before allocating)
    missing = [k for k in _REQUIRED if k not in archive]
    if missing:
        raise ValueError(f"load_npz: {path!r} lacks the arrays {missing}; it has {sorted(archive)}")
    points = np.asarray(archive["points"], dtype=np.float64)
    offsets = np.asarray(archive["offsets"], dtype=np.int64)
    labels = np.asarray(archive["labels"], dtype=np.int64)
    class_names = np.asarray(archive["class_names"]).astype(str)
    split = np.asarray(archive["split"]).astype(str) if "split" in archive else None
    ids = np.asarray(archive["ids"]).astype(str) if "ids" in archive else None
    n_objects = offsets.size - 1
    if points.ndim != 2 or points.shape[1] not in (3, 6):
        raise ValueError(f"load_npz: {path!r}: 'points' must have shape (n, 3) or (n, 6), got {points.shape}")
    if offsets.ndim != 1 or n_objects < 1 or offsets[0] != 0 or offsets[-1] != points.shape[0] or np.any(np.diff(offsets) < 0):
        raise ValueError(f"load_npz: {path!r}: 'offsets' must rise from 0 to len(points)={points.shape[0]}")
    if labels.shape != (n_objects,):
        raise ValueError(f"load_npz: {path!r}: 'labels' has shape {labels.shape}, expected ({n_objects},)")
    if labels.size and (labels.min() < 0 or labels.max() >= class_names.size):
        raise ValueError(f"load_npz: {path!r}: 'labels' must index 'class_names' (0..{class_names.size - 1})")
    for name, arr in (("split", split), ("ids", ids)):
        if arr is not None and arr.shape != (n_objects,):
            raise ValueError(f"load_npz: {path!r}: {name!r} has shape {arr.shape}, expected ({n_objects},)")
    clouds = [points[offsets[k]:offsets[k + 1]] for k in range(n_objects)]
    if return_X_y:
        return clouds, labels
    return Bunch(data=clouds, target=labels, target_names=class_names, split=split, ids=ids, filename=path)


def _strings(values, name, n, owner):
    """``values`` as a 1-D unicode array of length ``n`` (None stays None)."""
    if values is None:
        return None
    if isinstance(values, (str, bytes)):
        raise TypeError(f"{owner}: {name!r} must be a sequence of strings, got a single {type(values).__name__}")
    arr = np.asarray(values, dtype=object)
    if arr.ndim != 1 or arr.shape[0] != n:
        raise ValueError(f"{owner}: {name!r} must have {n} entries, got shape {arr.shape}")
    bad = [k for k, v in enumerate(arr) if not isinstance(v, (str, np.str_))]
    if bad:
        raise TypeError(f"{owner}: {name!r} must hold strings; entry {bad[0]} is {type(arr[bad[0]]).__name__}")
    return np.asarray([str(v) for v in arr], dtype=str) if n else np.zeros(0, dtype="<U1")


def save_npz(path, clouds, labels, class_names, *, split=None, ids=None):
    """Write point clouds in the flat ``.npz`` layout that :func:`load_npz` reads.

    The clouds are concatenated into ``points`` with ``offsets`` marking
    where each object starts, next to ``labels``, ``class_names`` and, when
    given, ``split`` and ``ids`` (see :func:`load_npz`). Every array is a
    plain numeric or unicode array, so the file loads without pickle. The
    file is written to a temporary name in the target's folder and renamed
    into place when complete, so an error or Ctrl-C never leaves a truncated
    file.

    Parameters
    ----------
    path : str or path-like
        The file to write. Its folder must exist; an existing file is
        replaced. The name is used as given (NumPy's ``.npz`` suffix is not
        appended).
    clouds : sequence of array-like of shape (n_i, 3) or (n_i, 6)
        The objects, with or without normals (all alike), each with at least
        one point and only finite coordinates. float32 clouds are stored as
        float32, anything else as float64.
    labels : array-like of int of shape (n_objects,)
        Class index of each object into ``class_names``.
    class_names : sequence of str of shape (n_classes,)
        Distinct class names.
    split : sequence of {"train", "test"} of shape (n_objects,), default=None
        Train/test assignment of each object.
    ids : sequence of str of shape (n_objects,), default=None
        A name for each object (its file name, for instance).

    Returns
    -------
    path : str
        The file written.

    Raises
    ------
    TypeError
        If an argument has the wrong type (strings where numbers belong, or
        the reverse).
    ValueError
        If the clouds, labels, names, split or ids are empty, inconsistent,
        non-finite or out of range; the message names the offending object.
    FileNotFoundError
        If the folder of ``path`` does not exist.
    IsADirectoryError
        If ``path`` is a folder.

    See Also
    --------
    load_npz : Read the file back.
    load_folder : Point clouds from a folder of files, to save in this layout.
    load_modelnet : ModelNet from a local folder, to save in this layout.

    Notes
    -----
    ``load_npz(path)`` returns the same clouds (as float64), labels, class
    names, split and ids.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.datasets import load_npz, save_npz
    >>> clouds = [np.zeros((3, 3)), np.ones((2, 3))]
    >>> _ = save_npz("pair.npz", clouds, [1, 0], ["chair", "table"], split=["train", "test"])
    >>> data = load_npz("pair.npz")
    >>> [c.shape for c in data.data], data.target.tolist(), data.target_names.tolist()
    ([(3, 3), (2, 3)], [1, 0], ['chair', 'table'])
    """
    owner = "save_npz"
    path = check_path(path, "path", owner)
    if isinstance(clouds, np.ndarray) and clouds.ndim == 3:
        clouds = list(clouds)
    if isinstance(clouds, (str, bytes)) or not hasattr(clouds, "__len__"):
        raise TypeError(f"{owner}: clouds must be a sequence of (n_i, 3) or (n_i, 6) arrays, got {type(clouds).__name__}")
    n = len(clouds)
    if n == 0:
        raise ValueError(f"{owner}: clouds is empty; a data set needs at least one object")
    arrays = []
    for k, cloud in enumerate(clouds):
        try:
            arr = np.asarray(cloud)
        except Exception as exc:
            raise ValueError(f"{owner}: cloud {k} is not an array ({exc})") from None
        if arr.dtype.kind not in "fiu" or arr.dtype == np.float16:
            raise TypeError(f"{owner}: cloud {k} must hold real numbers, got dtype {arr.dtype}")
        if arr.ndim != 2 or arr.shape[1] not in (3, 6):
            raise ValueError(f"{owner}: cloud {k} must have shape (n, 3) or (n, 6), got {arr.shape}")
        if arr.shape[0] == 0:
            raise ValueError(f"{owner}: cloud {k} has no points")
        if arrays and arr.shape[1] != arrays[0].shape[1]:
            raise ValueError(f"{owner}: cloud {k} has {arr.shape[1]} columns, cloud 0 has {arrays[0].shape[1]}; "
                             "give normals for every cloud or for none")
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise ValueError(f"{owner}: cloud {k} holds NaN or infinite values")
        arrays.append(arr)
    dtype = np.float32 if all(a.dtype == np.float32 for a in arrays) else np.float64
    points = np.concatenate([a.astype(dtype, copy=False) for a in arrays])
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum([a.shape[0] for a in arrays], out=offsets[1:])

    if isinstance(class_names, (str, bytes)):
        raise TypeError(f"{owner}: class_names must be a sequence of strings, got a single {type(class_names).__name__}")
    names_list = list(class_names) if hasattr(class_names, "__len__") else None
    if not names_list:
        raise ValueError(f"{owner}: class_names must be a non-empty sequence of strings")
    names = _strings(names_list, "class_names", len(names_list), owner)
    if len(set(names.tolist())) != names.size:
        dup = sorted({v for v in names.tolist() if names.tolist().count(v) > 1})
        raise ValueError(f"{owner}: class_names must be distinct; repeated: {dup}")

    lab = np.asarray(labels)
    if lab.shape != (n,):
        raise ValueError(f"{owner}: labels must have shape ({n},) (one per cloud), got {lab.shape}")
    if lab.dtype.kind == "b" or (lab.dtype.kind not in "iu" and not (
            lab.dtype.kind == "O" and all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in lab))):
        raise TypeError(f"{owner}: labels must be integer indices into class_names, got dtype {lab.dtype}")
    lab = lab.astype(np.int64)
    out_of_range = np.flatnonzero((lab < 0) | (lab >= names.size))
    if out_of_range.size:
        k = int(out_of_range[0])
        raise ValueError(f"{owner}: labels must lie in 0..{names.size - 1} (indices into class_names); "
                         f"object {k} has {lab[k]}")

    if os.path.isdir(path):  # (the rename into place failed naming the temporary file, not save_npz)
        raise IsADirectoryError(errno.EISDIR, f"{owner}: a folder, not a file", path)
    out = {"points": points, "offsets": offsets, "labels": lab, "class_names": names}
    split_arr = _strings(split, "split", n, owner)
    if split_arr is not None:
        wrong = np.flatnonzero(~np.isin(split_arr, ["train", "test"]))
        if wrong.size:
            k = int(wrong[0])
            raise ValueError(f"{owner}: split must be 'train' or 'test'; object {k} has {str(split_arr[k])!r}")
        out["split"] = split_arr
    ids_arr = _strings(ids, "ids", n, owner)
    if ids_arr is not None:
        out["ids"] = ids_arr
    with atomic_write(path, "wb") as fh:
        np.savez(fh, **out)
    return path
