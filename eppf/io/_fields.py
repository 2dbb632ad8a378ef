"""Every per-point field of a file: :func:`read_point_fields` and :func:`write_point_fields`."""

import os
import shutil
import tempfile

import numpy as np

from . import _e57, _las, _pcd, _ply, _xyz
from ._api import guard
from ._common import NORMAL_NAMES, read_bytes
from ._errors import FileFormatError
from ._formats import lookup

__all__ = ["read_point_fields", "write_point_fields"]

_WRITABLE = ("pcd", "ply", "las", "laz")


def _read(path, fmt, owner):
    name = fmt.name
    if name in ("las", "laz"):
        return _las.read_las_fields(path, owner)
    if name == "e57":
        return _e57.read_e57_fields(path, owner)
    if fmt.raw:  # NumPy arrays: columns 4 to 6 are normals
        cloud = fmt.reader(path, owner, "auto")
        fields = {} if cloud.normals is None else {n: np.ascontiguousarray(cloud.normals[:, k])
                                                   for k, n in enumerate(NORMAL_NAMES)}
        return np.ascontiguousarray(cloud.xyz, dtype=np.float64), fields
    data = read_bytes(path, owner)
    if name == "pcd":
        return _pcd.read_pcd_fields(path, data, owner)
    if name == "ply":
        return _ply.read_ply_fields(path, data, owner)
    return _xyz.read_text_fields(path, data, owner, name)


def read_point_fields(path, *, format=None):
    """Read a point cloud's coordinates and every other per-point field.

    Parameters
    ----------
    path : str or path-like
        The file: PCD, PLY, LAS, LAZ, E57, a text table
        (``.xyz``/``.txt``/``.csv``/``.pts``/``.xyzn``/``.xyzrgb``) or NumPy
        (``.npy``/``.npz``); its extension (any case) chooses the format
        unless ``format`` is given.
    format : str, default=None
        Override the format given by the extension (a name from
        :func:`format_of`, e.g. ``"las"``).

    Returns
    -------
    points : ndarray of shape (n_points, 3), dtype float64
        The coordinates in the file's own units and offsets. LAS/LAZ:
        ``X * scale + offset`` (projected coordinates of 1e5 to 1e7 m keep
        their millimeters). E57: every scan's cartesian (or spherical,
        converted) coordinates moved by its pose into the file's frame, the
        scans one after the other. Every point of the file is kept,
        including PCL's NaN points. A well-formed file of no points (PCD
        ``POINTS 0``, PLY ``element vertex 0``, a ``.pts`` count line ``0``,
        a text table of only a header line or comments, an empty array, LAS
        or E57 scans of no points) gives shape (0, 3), and its fields no
        rows; :func:`read_point_cloud` refuses such a file.
    fields : dict of str to ndarray
        Every other per-point field, in the file's order, each an array of
        length ``n_points`` in the file's own type (shape ``(n_points, k)``
        for a field of ``k`` values per point):

        - PCD: every ``FIELDS`` entry but ``x y z`` and ``_`` padding.
          PCL's packed color ``rgb`` (``TYPE F``) and ``rgba`` (``TYPE U``)
          are kept packed as uint32 ``0xAARRGGBB`` (the bits of the float):
          ``red = (rgb >> 16) & 255``, ``green = (rgb >> 8) & 255``,
          ``blue = rgb & 255``.
        - PLY: every property of the ``vertex`` element but ``x y z``; a
          list property whose rows all have one length ``k`` gives shape
          ``(n_points, k)`` (lists of varying length are refused).
        - LAS/LAZ: every dimension of the point format but ``X Y Z``
          (``intensity``, ``return_number``, ..., ``classification``,
          ``gps_time``, ``red``, ...; bit fields as uint8), then every
          extra-bytes dimension (scaled ones as float64).
        - E57: every field of the scans' point prototype but
          ``cartesianX/Y/Z`` (``intensity``, ``colorRed``, ``rowIndex``,
          ``timeStamp``, ``cartesianInvalidState``, ...): floats as float32
          or float64 by their precision, scaled integers as float64,
          integers in the smallest type that holds their range; and
          ``scan_index`` (uint32) when the file has more than one scan. Only
          the fields every scan has are kept.
        - Text tables: the columns named by a header line (``x y z`` found
          by name, else the first three columns), or by the layout of
          ``.xyzn`` (``nx ny nz``), ``.xyzrgb`` (``red green blue``) and
          ``.pts`` (``intensity`` and/or ``red green blue``), else
          ``column_4``, ``column_5``, ... (counting from 1), all float64.
        - NumPy: ``normal_x normal_y normal_z`` for an (n, 6) array, or a
          wider one whose columns 4 to 6 have unit length in every row.

        Normals keep the file's own names: PCD ``normal_x normal_y
        normal_z``, PLY ``nx ny nz`` (or ``normal_x ...``), E57
        ``nor:normalX nor:normalY nor:normalZ`` (turned by the scan's pose
        rotation, like the points, and then float64).

    Raises
    ------
    FileNotFoundError, IsADirectoryError, PermissionError
        If the file cannot be opened; the message names it.
    FileFormatError
        A :class:`ValueError`: the file is empty, truncated or malformed, or
        a header count, offset or descriptor does not fit the file (checked
        before anything is allocated); the message names the file.
    ImportError
        For LAS/LAZ without laspy and lazrs, or E57 without pye57; its one
        line names the extra to install (``pip install 'eppf[las]'``,
        ``'eppf[e57]'``).
    ValueError
        If the extension is unknown or the file holds a mesh (OFF, OBJ, STL:
        use :func:`read_mesh`).

    See Also
    --------
    write_point_fields : The inverse (PCD, PLY, LAS, LAZ).
    read_point_cloud : Only the coordinates (and normals), as estimators take them.

    Notes
    -----
    ``write_point_fields(path, *read_point_fields(path))`` then
    ``read_point_fields`` gives every field back bit for bit (PCD, PLY,
    LAS, LAZ), and the coordinates too. ASCII PCD and PLY values are parsed
    through float64 and then stored in their declared type.

    Examples
    --------
    >>> import numpy as np, os, tempfile
    >>> from eppf.io import read_point_fields, write_point_fields
    >>> path = os.path.join(tempfile.mkdtemp(), "scan.pcd")
    >>> points = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> write_point_fields(path, points, {"intensity": np.array([0.5, 1, 2], dtype=np.float32),
    ...                                   "label": np.array([3, 3, 7], dtype=np.uint32)})
    >>> points, fields = read_point_fields(path)
    >>> points.shape, list(fields), fields["label"]
    ((3, 3), ['intensity', 'label'], array([3, 3, 7], dtype=uint32))
    """
    owner = "read_point_fields"
    path = os.fspath(path)
    fmt = lookup(path, format, owner)
    if fmt.kind == "mesh":
        raise ValueError(f"{owner}: {path!r} is a {fmt.name} mesh file; read its vertices with read_mesh")
    points, fields = guard(owner, path, fmt, _read, path, fmt, owner)
    n = points.shape[0]
    bad = [k for k, v in fields.items() if v.shape[0] != n]
    if bad:  # pragma: no cover - each reader gives every field n rows
        raise FileFormatError(f"{owner}: {path!r}: field {bad[0]!r} has {fields[bad[0]].shape[0]} values for {n} points")
    return points, fields


def _check_fields(points, fields, owner, fmt):
    arr = np.asarray(points)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{owner}: points must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{owner}: points must have shape (n_points, 3), got {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    n = arr.shape[0]
    out = {}
    for name, values in ({} if fields is None else dict(fields)).items():
        if not isinstance(name, str) or not name or any(c.isspace() for c in name) or not name.isprintable() \
                or not name.isascii():
            raise ValueError(f"{owner}: field names must be non-empty ASCII strings without spaces, got {name!r}")
        if name.lower() in ("x", "y", "z"):
            raise ValueError(f"{owner}: field {name!r} would repeat a coordinate; coordinates go in points")
        if name in ("_",) or name.startswith("_n_"):
            raise ValueError(f"{owner}: field name {name!r} is reserved")
        values = np.asarray(values)
        if values.dtype.kind == "b":
            values = values.astype(np.uint8)
        if values.dtype.kind not in "iuf" or values.dtype.itemsize > 8 or values.dtype == np.float16:
            raise TypeError(f"{owner}: field {name!r} must hold integers or float32/float64, got dtype {values.dtype}")
        if values.ndim not in (1, 2) or values.shape[0] != n:
            raise ValueError(f"{owner}: field {name!r} must have shape ({n},) or ({n}, k), got {values.shape}")
        if values.ndim == 2 and values.shape[1] == 0:
            raise ValueError(f"{owner}: field {name!r} has no values per point (shape {values.shape})")
        values = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("="))
        if fmt == "ply" and values.dtype.itemsize == 8 and values.dtype.kind in "iu":
            values = _narrow(values, name, owner)
        out[name] = values
    return arr, out


def _narrow(values, name, owner):
    """A 64-bit integer field as PLY's 32-bit int or uint, when its values fit."""
    for target in (np.int32, np.uint32):
        info = np.iinfo(target)
        if values.size == 0 or (values.min() >= info.min and values.max() <= info.max):
            return values.astype(target)
    raise ValueError(f"{owner}: field {name!r} holds 64-bit integers beyond 32 bits, which PLY cannot store; "
                     "write PCD or LAS instead")


def write_point_fields(path, points, fields=None, *, format=None):
    """Write a point cloud with every per-point field: PCD, PLY, LAS or LAZ.

    Parameters
    ----------
    path : str or path-like
        Destination; its extension (``.pcd``, ``.ply``, ``.las``, ``.laz``,
        any case) chooses the format unless ``format`` is given.
    points : array-like of shape (n_points, 3)
        Coordinates. PCD and PLY store them as float32 when every value is
        a float32 value (so a file read from float32 data is written back
        bit for bit), else as float64. LAS stores integers on a grid
        (``scale``, ``offset`` per axis): the coarsest decimal grid (scales
        1 to 1e-9, offsets 0 or the minimum rounded down to a power of ten)
        that gives every coordinate back bit for bit, which a file read from
        LAS always has; otherwise the finest decimal grid whose integers fit
        32 bits, so coordinates move by at most half its scale. LAS needs
        finite coordinates.
    fields : dict of str to array-like, default=None
        Per-point fields, each of length ``n_points`` (shape ``(n_points,)``
        or ``(n_points, k)``), integers, float32 or float64 (bool is written
        as uint8), written in the dict's order under their own names (no
        spaces; not ``x``, ``y``, ``z``).

        - PCD: each field with its type; a uint32 ``rgb`` is written as
          PCL's packed color (``TYPE F``, the same bits).
        - PLY: each field a ``vertex`` property; an (n, k) field a list
          property of length k; 64-bit integers as ``int``/``uint`` when
          their values fit (else ValueError).
        - LAS/LAZ: fields named as LAS dimensions (``intensity``,
          ``classification``, ``gps_time``, ``red``, ``overlap``, ...) fill
          those dimensions, in the first point format (0, 1, 2, 3, 6, 7, 8,
          then the waveform formats) that has all of them and stores their
          values exactly (e.g. a classification above 31 needs format 6);
          every other field becomes an extra-bytes dimension (names of at
          most 32 bytes, 1 to 3 values per point).
    format : {"pcd", "ply", "las", "laz"}, default=None
        Override the format given by the extension.

    Raises
    ------
    ValueError
        If the extension is unknown or not one of these four, an array has
        the wrong shape, or a field cannot be stored in the format.
    TypeError
        If ``points`` or a field is not numeric.
    ImportError
        For LAS/LAZ without laspy and lazrs; its one line names the extra.

    See Also
    --------
    read_point_fields : The inverse.
    write_point_cloud : Write coordinates and normals only.

    Notes
    -----
    Data are written binary (PCD ``DATA binary``, PLY
    ``binary_little_endian``), a PCD with ``WIDTH n HEIGHT 1`` and the
    default viewpoint.

    Examples
    --------
    >>> import numpy as np, os, tempfile
    >>> from eppf.io import read_point_fields, write_point_fields
    >>> path = os.path.join(tempfile.mkdtemp(), "labelled.ply")
    >>> write_point_fields(path, np.eye(3), {"segment": np.array([0, 0, 1], dtype=np.int32)})
    >>> read_point_fields(path)[1]["segment"]
    array([0, 0, 1], dtype=int32)
    """
    owner = "write_point_fields"
    path = os.fspath(path)
    fmt = lookup(path, format, owner)
    if fmt.name not in _WRITABLE:
        raise ValueError(f"{owner}: cannot write fields to a {fmt.name} file ({path!r}); "
                         f"write_point_fields writes {', '.join(_WRITABLE)}")
    points, fields = _check_fields(points, fields, owner, fmt.name)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"{owner}: cannot write {path!r}: no such folder {folder}")
    # written under its own name in a scratch folder beside the target (laspy writes by name), then renamed
    # into place: an interrupted or failed write leaves no partial file and any old file as it was
    scratch = tempfile.mkdtemp(dir=folder, prefix=".eppf-")
    try:
        tmp = os.path.join(scratch, os.path.basename(path))
        if fmt.name == "pcd":
            _pcd.write_pcd_fields(tmp, points, fields)
        elif fmt.name == "ply":
            _ply.write_ply_fields(tmp, points, fields, "f4" if _pcd.exact_float32(points) else "f8")
        else:
            _las.write_las(tmp, points, fields, owner, compressed=fmt.name == "laz", shown=path)
        os.replace(tmp, path)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
