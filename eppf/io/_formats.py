"""The one table of file formats: extension -> format, kind, reader, writer.

Every reader and writer of :mod:`eppf.io`, the folder loaders of
:mod:`eppf.datasets` and the command line find formats here, so they accept
the same files. Each format lives in its own module (``_pcd``, ``_ply``,
...) with its compiled parser beside it.

``kind`` is ``"cloud"`` (points, optionally normals), ``"mesh"`` (vertices
and faces) or ``"both"`` (PLY: a cloud, or a mesh when it has faces).
A cloud reader is ``reader(path, data, owner, want_normals)`` returning a
``Cloud``; a mesh reader ``reader(path, data, owner)`` returning a ``Mesh``;
PLY's reader returns both. ``raw=True`` readers open the file themselves
(NumPy formats) and take ``(path, owner, want_normals)``; so do LAS, LAZ (laspy) and E57 (pye57), whose
optional packages are imported only when such a file is read or written. A cloud writer is
``writer(path, cloud, binary=...)``, a mesh writer
``writer(path, vertices, faces, binary=...)``; PLY's writer is both.
"""

import os
from collections import namedtuple

from . import _e57, _las, _npy, _obj, _off, _pcd, _ply, _stl, _xyz

Format = namedtuple("Format", ["name", "extensions", "kind", "reader", "writer", "raw"])

FORMATS = (
    Format("pcd", (".pcd",), "cloud", _pcd.read_pcd, _pcd.write_pcd, False),
    Format("ply", (".ply",), "both", _ply.read_ply, _ply.write_ply, False),
    Format("xyz", (".xyz", ".txt", ".csv"), "cloud", _xyz.read_xyz, _xyz.write_xyz, False),
    Format("pts", (".pts",), "cloud", _xyz.read_pts, _xyz.write_xyz, False),
    Format("xyzn", (".xyzn",), "cloud", _xyz.read_xyzn, _xyz.write_xyzn, False),
    Format("xyzrgb", (".xyzrgb",), "cloud", _xyz.read_xyzrgb, None, False),
    Format("npy", (".npy",), "cloud", _npy.read_npy, _npy.write_npy, True),
    Format("npz", (".npz",), "cloud", _npy.read_npz, _npy.write_npz, True),
    Format("las", (".las",), "cloud", _las.read_las, _las.write_las_cloud, True),
    Format("laz", (".laz",), "cloud", _las.read_las, _las.write_laz_cloud, True),
    Format("e57", (".e57",), "cloud", _e57.read_e57, None, True),
    Format("off", (".off",), "mesh", _off.read_off, _off.write_off, False),
    Format("obj", (".obj",), "mesh", _obj.read_obj, _obj.write_obj, False),
    Format("stl", (".stl",), "mesh", _stl.read_stl, _stl.write_stl, False),
)

BY_NAME = {f.name: f for f in FORMATS}
BY_EXTENSION = {ext: f for f in FORMATS for ext in f.extensions}
_KINDS = (None, "cloud", "mesh")


def supported_extensions(kind=None):
    """The file extensions eppf reads, lower case with their dot.

    Parameters
    ----------
    kind : {None, "cloud", "mesh"}, default=None
        None: every extension :func:`read_point_cloud` reads (point clouds
        and meshes, which it samples). ``"cloud"``: formats that store points
        (PCD, PLY, the text tables, NPY, NPZ, LAS, LAZ, E57). ``"mesh"``: formats that
        store triangles, the ones :func:`read_mesh` reads (OFF, OBJ, STL,
        PLY).

    Returns
    -------
    extensions : tuple of str
        Sorted, e.g. ``(".csv", ".npy", ...)``. Matching is case-insensitive:
        ``scan.PLY`` is a ``.ply`` file.

    See Also
    --------
    format_of : The format of one file.

    Examples
    --------
    >>> from eppf.io import supported_extensions
    >>> supported_extensions("mesh")
    ('.obj', '.off', '.ply', '.stl')
    >>> ".pcd" in supported_extensions()
    True
    """
    if kind not in _KINDS:
        raise ValueError(f"supported_extensions: kind must be None, 'cloud' or 'mesh', got {kind!r}")
    return tuple(sorted(ext for ext, f in BY_EXTENSION.items() if kind is None or f.kind in (kind, "both")))


def format_of(path):
    """The name of a file's format, from its extension (ignoring case).

    Parameters
    ----------
    path : str or path-like
        A file name; the file need not exist.

    Returns
    -------
    name : str
        One of ``"pcd"``, ``"ply"``, ``"xyz"`` (``.xyz``, ``.txt``,
        ``.csv``), ``"pts"``, ``"xyzn"``, ``"xyzrgb"``, ``"npy"``,
        ``"npz"``, ``"las"``, ``"laz"``, ``"e57"``, ``"off"``, ``"obj"``,
        ``"stl"``.

    Raises
    ------
    ValueError
        If the extension is not one of :func:`supported_extensions`.

    See Also
    --------
    supported_extensions : The extensions eppf reads and writes.
    read_point_cloud : Read a point cloud in the format of its extension.

    Examples
    --------
    >>> from eppf.io import format_of
    >>> format_of("scans/chair_01.PLY"), format_of("bunny.Off"), format_of("room.txt")
    ('ply', 'off', 'xyz')
    """
    return lookup(path, None, "format_of").name


def lookup(path, fmt, owner, kind=None):
    """The Format of ``path`` (or of the override ``fmt``), for a reader of ``kind``."""
    if fmt is not None:
        name = str(fmt).lower().lstrip(".")
        found = BY_NAME.get(name) or BY_EXTENSION.get("." + name)
        names = sorted(f.name for f in FORMATS if kind is None or f.kind in (kind, "both"))
        if found is None or found.name not in names:
            raise ValueError(f"{owner}: unknown format {fmt!r}; expected one of {names}")
        return found
    ext = os.path.splitext(os.fspath(path))[1].lower()
    found = BY_EXTENSION.get(ext)
    if found is not None and kind is not None and found.kind not in (kind, "both"):
        raise ValueError(
            f"{owner}: {os.fspath(path)!r} is a {found.name} file, which holds {found.kind}s, not {kind}es; "
            f"{kind} extensions are {list(supported_extensions(kind))}"
        )
    if found is None:
        known = supported_extensions(kind)
        raise ValueError(
            f"{owner}: cannot tell the format of {os.fspath(path)!r} from its extension {ext!r}; "
            f"known extensions are {list(known)}, or pass format="
        )
    return found
