"""Loader for the flat ``.npz`` layout of point-cloud data sets."""

import os

import numpy as np
from sklearn.utils import Bunch

__all__ = ["load_npz"]

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
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"load_npz: no such file: {path!r}")
    try:
        archive = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise ValueError(f"load_npz: {path!r} is not a readable .npz file ({exc})") from None
    with archive:
        missing = [k for k in _REQUIRED if k not in archive.files]
        if missing:
            raise ValueError(f"load_npz: {path!r} lacks the arrays {missing}; it has {sorted(archive.files)}")
        points = np.asarray(archive["points"], dtype=np.float64)
        offsets = np.asarray(archive["offsets"], dtype=np.int64)
        labels = np.asarray(archive["labels"], dtype=np.int64)
        class_names = np.asarray(archive["class_names"]).astype(str)
        split = np.asarray(archive["split"]).astype(str) if "split" in archive.files else None
        ids = np.asarray(archive["ids"]).astype(str) if "ids" in archive.files else None
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
