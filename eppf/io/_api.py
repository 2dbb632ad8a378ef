"""The public readers and writers: one way from any supported file to a cloud."""

import numbers
import os

import numpy as np
from sklearn.utils import check_random_state

from ..utils._param_validation import Options, validate_parameter
from ..utils._sampling import check_n_points, check_resolution, object_rng, resample, sample_mesh
from . import _ply
from ._common import Cloud, Mesh, read_bytes
from ._errors import FileFormatError
from ._formats import lookup

__all__ = ["MESH_POINTS", "NORMALS", "check_flag", "check_normals", "read_mesh", "read_point_cloud", "write_mesh",
           "write_point_cloud"]

# points drawn from a mesh when neither n_points nor resolution is given (as load_folder does)
MESH_POINTS = 2048


# --------------------------------------------------------------------------- argument checks


#: ``normals`` of the readers and of the loaders of :mod:`eppf.datasets`
#: (:mod:`eppf.utils._param_validation`): "auto", or a bool (``numpy.bool_`` too). It was compared with
#: ``in ("auto", True, False)``, which took 1, 0 and 1.0 (equal to True and False) and then, since
#: ``normals is True`` did not hold for them, read them as "auto".
NORMALS = [Options((str, bool), values=["auto", True, False], description="'auto', True or False")]


def check_normals(normals, owner):
    """``normals`` checked against :data:`NORMALS`: ``"auto"``, True or False (a ``numpy.bool_`` as its bool)."""
    validate_parameter(normals, NORMALS, name="normals", owner=owner)
    return normals if isinstance(normals, str) else bool(normals)


def check_flag(value, name, owner):
    """A bool parameter (``remove_nan``, ``binary``, ``return_X_y``, ...) as the estimators check theirs
    (``Options(bool)``): True or False, or a ``numpy.bool_``; anything else (``"yes"``, 1, None) is an
    InvalidParameterError, a TypeError, naming ``owner`` and ``name``, where truthiness took it."""
    validate_parameter(value, [Options(bool)], name=name, owner=owner)
    return bool(value)


def check_sampling_args(owner, normals, n_points, resolution):
    """``(n_points, resolution)`` checked as :func:`read_point_cloud` takes them, with ``normals``: for
    callers that read many files, so that a bad option fails once, before any file is read."""
    check_normals(normals, owner)
    n_points = check_n_points(n_points, owner)
    resolution = check_resolution(resolution, owner)
    if n_points is not None and resolution is not None:
        raise ValueError(f"{owner}: give n_points or resolution, not both")
    return n_points, resolution


def _check_random_state_arg(random_state, owner):
    """Refuse a ``random_state`` that :func:`_rng` cannot use (before any file is read)."""
    if isinstance(random_state, numbers.Integral) and not isinstance(random_state, bool):
        if not 0 <= random_state < 2 ** 64:
            raise ValueError(f"{owner}: an int random_state must lie in 0..2**64-1, got {random_state}")
        return
    if random_state is None or isinstance(random_state, np.random.RandomState):
        return
    raise TypeError(f"{owner}: random_state must be None, an int or a RandomState, got {type(random_state).__name__}")


def _rng(random_state, owner):
    """An int seeds a PCG64 generator from all its 64 bits (as the folder loaders' per-file seeds do)."""
    _check_random_state_arg(random_state, owner)
    if isinstance(random_state, numbers.Integral):
        return object_rng(int(random_state))
    return check_random_state(random_state)


def _check_cloud_arg(cloud, owner):
    arr = np.asarray(cloud)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{owner}: cloud must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] not in (3, 6):
        raise ValueError(f"{owner}: cloud must have shape (n_points, 3) or (n_points, 6), got {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{owner}: cloud has no points")
    if not np.isfinite(arr).all():
        raise ValueError(f"{owner}: cloud contains NaN or infinite values")
    return arr.astype(np.float64)


# --------------------------------------------------------------------------- helpers


def _finish_cloud(cloud, path, normals, owner, remove_nan):
    """Combine coordinates and optional normals; drop non-finite points."""
    xyz, nrm = cloud
    if normals is True and nrm is None:
        raise FileFormatError(f"{owner}: {path!r} has no normals, but normals=True")
    if normals is False:
        nrm = None
    base = xyz.base
    if nrm is not None and base is not None and nrm.base is base and _is_block(base, xyz, nrm):
        out = base  # a reader's (n, 6) block already (PLY): no copy
    else:
        out = xyz if nrm is None else np.hstack([xyz, nrm])
    out = np.ascontiguousarray(out, dtype=np.float64)
    if remove_nan and not np.isfinite(out).all():  # (one pass over the block; rows only when some value is not)
        out = out[np.isfinite(out).all(axis=1)]
    if out.shape[0] == 0:
        raise FileFormatError(f"{owner}: {path!r} holds no points")
    return out


def _is_block(base, xyz, nrm):
    """True when ``xyz`` and ``nrm`` are columns 0-2 and 3-5 of the C-ordered float64 (n, 6) ``base``."""
    if not (isinstance(base, np.ndarray) and base.dtype == np.float64 and base.ndim == 2 and base.shape[1] == 6
            and base.flags.c_contiguous and xyz.shape == nrm.shape == (base.shape[0], 3)):
        return False
    start = base.__array_interface__["data"][0]
    return (xyz.__array_interface__["data"][0] == start and nrm.__array_interface__["data"][0] == start + 24
            and xyz.strides == nrm.strides == base.strides)


def _check_vertices(mesh, path, owner):
    bad = np.flatnonzero(~np.isfinite(mesh.vertices).all(axis=1))
    if bad.size:
        k = int(bad[0])
        raise FileFormatError(
            f"{owner}: {path!r}: vertex {k} (counting from 0) is not finite: {mesh.vertices[k].tolist()}"
        )
    return mesh


def guard(owner, path, fmt, func, *args, **kwargs):
    """Run a reader; every failure that is not already a FileFormatError or OSError becomes one (an ImportError
    naming a missing optional package passes as it is)."""
    try:
        return func(*args, **kwargs)
    except (FileFormatError, OSError, ImportError):
        raise
    except MemoryError:
        raise FileFormatError(f"{owner}: {path!r}: reading this {fmt.name} file needs more memory than is free") from None
    except RecursionError:
        raise FileFormatError(f"{owner}: {path!r}: malformed {fmt.name} file (nested too deeply)") from None
    except Exception as exc:  # noqa: BLE001 - translated into the one documented type
        raise FileFormatError(f"{owner}: {path!r}: malformed {fmt.name} file ({type(exc).__name__}: {exc})") from None


def _sampled(owner, path, fmt, what, func, *args, **kwargs):
    """Run ``resample`` or ``sample_mesh`` on a file's content: their refusals (a cloud of one point, a
    degenerate mesh) are FileFormatErrors saying that the content, read as it is, cannot be sampled, not
    that the file is malformed."""
    try:
        return func(*args, **kwargs)
    except (TypeError, ValueError) as exc:
        raise FileFormatError(f"{owner}: {path!r}: the {fmt.name} file's {what} ({exc})") from None


def _read_any(path, fmt, owner, normals, want_faces):
    """(Cloud or None, Mesh or None) from any format."""
    if fmt.raw:
        return fmt.reader(path, owner, normals), None
    data = read_bytes(path, owner)
    if fmt.name == "ply":
        cloud, faces = _ply.read_ply(path, data, owner, want_faces=want_faces)
        if faces is None:
            return cloud, None
        return cloud, Mesh(np.ascontiguousarray(cloud.xyz), faces)
    if fmt.kind == "cloud":
        return fmt.reader(path, data, owner, normals), None
    return None, fmt.reader(path, data, owner)


# --------------------------------------------------------------------------- public API


def read_point_cloud(path, *, format=None, normals="auto", remove_nan=True, mesh="sample", n_points=None,
                     resolution=None, random_state=0):
    """Read a point cloud from any supported file, sampling meshes.

    Parameters
    ----------
    path : str or path-like
        The file. Its extension (any case) chooses the format unless
        ``format`` is given; :func:`supported_extensions` lists them all.
        Point files: ``.pcd``, ``.ply``, ``.xyz``/``.txt``/``.csv``,
        ``.pts``, ``.xyzn``, ``.xyzrgb``, ``.npy``, ``.npz``. Mesh files:
        ``.off``, ``.obj``, ``.stl`` and ``.ply`` with faces.
    format : str, default=None
        Override the format given by the extension (a name from
        :func:`format_of`, e.g. ``"pcd"``).
    normals : {"auto", True, False}, default="auto"
        Whether to return normals. ``"auto"`` returns them when the file has
        them: PCD fields ``normal_x normal_y normal_z``, PLY properties
        ``nx ny nz``, LAS/LAZ extra bytes ``normal_x normal_y normal_z`` (or
        ``nx ny nz``), E57's surface-normals extension ``nor:normalX
        nor:normalY nor:normalZ`` (turned by each scan's pose, as its
        points are), the columns of an ``.xyzn`` file, columns 4 to 6 of an
        ``.xyz``/``.txt``/``.csv``/``.pts`` file when every row there has
        unit length (so that ``x y z r g b`` files are not mistaken), columns
        4 to 6 of an array of 6 columns (of a wider array when every row
        there has unit length), and the face normals of points sampled from
        a mesh. True requires them; False drops them.
    remove_nan : bool, default=True
        Drop points with a NaN or infinite value (PCL marks invalid points of
        organized clouds with NaN).
    mesh : {"sample", "vertices"}, default="sample"
        What a mesh file (OFF, OBJ, STL, PLY with faces) gives: points drawn
        uniformly over its surface (area-weighted, with
        :func:`eppf.preprocessing.sample_mesh`), or its vertices.
    n_points : int, default=None
        Points per cloud. Meshes are sampled with this many points (2,048
        when neither ``n_points`` nor ``resolution`` is given); point files
        are resampled to it (:func:`eppf.preprocessing.resample`: without
        replacement when they have more points, every point plus random
        repeats when fewer). None keeps point files as they are. At most a
        billion, as in the loaders of :mod:`eppf.datasets` (a larger count is
        refused before any file is read).
    resolution : float, default=None
        Instead of ``n_points``, sample meshes on a voxel grid of this cell
        size (see :func:`eppf.preprocessing.sample_mesh`); point files are
        kept as they are.
    random_state : int, RandomState instance or None, default=0
        Seed of the sampling. An int seeds a PCG64 generator from all its 64
        bits, so ``random_state=seed`` gives the same cloud as
        :func:`eppf.datasets.load_folder` when ``seed`` is that file's seed.

    Returns
    -------
    cloud : ndarray of shape (n_points, 3) or (n_points, 6), dtype float64
        Coordinates, followed by the normals when returned.

    Raises
    ------
    FileNotFoundError, IsADirectoryError, PermissionError
        If the file cannot be opened; the message names it.
    FileFormatError
        A :class:`ValueError`: the file is empty, truncated or malformed, it
        holds no points (a well-formed file of no points or vertices, in
        every format, or only NaN points), a header count does not fit the
        file, a mesh cannot be sampled (no faces, non-finite vertices, zero
        area) or a cloud cannot be resampled to ``n_points`` (fewer than two
        distinct points); the message names the file and the line (text) or
        byte (binary) where reading failed.
    ValueError
        If the extension is unknown or an argument is invalid.
    TypeError
        If ``normals`` or ``remove_nan`` is not one of the values listed
        (``numpy.bool_`` is taken as a bool; ``1``, ``0`` or ``"yes"`` are
        not); the error is a ValueError too.

    See Also
    --------
    write_point_cloud : The inverse.
    read_mesh : Read a mesh's vertices and triangles.
    supported_extensions : What can be read.

    Notes
    -----
    The same file with the same ``n_points``, ``resolution``, ``normals`` and
    ``random_state`` always gives the same cloud, so a model trained on
    sampled meshes can be applied to new meshes sampled the same way.

    Examples
    --------
    >>> import numpy as np, os, tempfile
    >>> from eppf.io import read_point_cloud, write_mesh, write_point_cloud
    >>> folder = tempfile.mkdtemp()
    >>> write_point_cloud(os.path.join(folder, "cloud.xyz"), np.eye(3))
    >>> read_point_cloud(os.path.join(folder, "cloud.xyz")).shape
    (3, 3)
    >>> square = np.array([[0., 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    >>> write_mesh(os.path.join(folder, "square.STL"), square, [[0, 1, 2], [0, 2, 3]])
    >>> read_point_cloud(os.path.join(folder, "square.STL"), n_points=500).shape
    (500, 6)
    """
    owner = "read_point_cloud"
    if mesh not in ("sample", "vertices"):
        raise ValueError(f"{owner}: mesh must be 'sample' or 'vertices', got {mesh!r}")
    n_points, resolution = check_sampling_args(owner, normals, n_points, resolution)
    normals = check_normals(normals, owner)
    remove_nan = check_flag(remove_nan, "remove_nan", owner)
    # the generator is made only for a file that is sampled (a mesh, or resampling to n_points)
    _check_random_state_arg(random_state, owner)
    path = os.fspath(path)
    fmt = lookup(path, format, owner)
    cloud, shape = guard(owner, path, fmt, _read_any, path, fmt, owner, normals, mesh == "sample")
    if shape is not None and (mesh == "vertices" or fmt.name == "ply" and shape.faces.shape[0] == 0):
        cloud, shape = (cloud if fmt.name == "ply" else Cloud(shape.vertices, None)), None
    if shape is not None:
        if shape.vertices.shape[0] == 0:  # (as a point file of no points, not as a mesh without faces)
            raise FileFormatError(f"{owner}: {path!r} holds no points")
        _check_vertices(shape, path, owner)
        if shape.faces.shape[0] == 0:
            raise FileFormatError(f"{owner}: {path!r} has no faces, so it cannot be sampled; pass mesh='vertices'")
        count = n_points if n_points is not None or resolution is not None else MESH_POINTS
        with np.errstate(over="ignore", invalid="ignore"):
            out = _sampled(owner, path, fmt, "mesh cannot be sampled", sample_mesh, shape.vertices, shape.faces,
                           n_points=count, resolution=resolution, return_normals=normals is not False,
                           random_state=_rng(random_state, owner))
        if not np.isfinite(out).all():
            raise FileFormatError(
                f"{owner}: {path!r}: the mesh's coordinates are too large to sample (its areas overflow float64)"
            )
        return out
    out = _finish_cloud(cloud, path, normals, owner, remove_nan)
    if n_points is not None:
        out = _sampled(owner, path, fmt, f"cloud cannot be resampled to {n_points} points", resample, out, n_points,
                       random_state=_rng(random_state, owner))
    return out


def read_mesh(path, *, format=None):
    """Read a triangle mesh from an OFF, OBJ, STL or PLY file.

    Parameters
    ----------
    path : str or path-like
        The file; its extension (``.off``, ``.obj``, ``.stl``, ``.ply``, any
        case) chooses the format unless ``format`` is given.
    format : {"off", "obj", "stl", "ply"}, default=None
        Override the format given by the extension.

    Returns
    -------
    mesh : Mesh
        ``(vertices, faces)``: float64 (n_vertices, 3) and int64 (n_faces, 3).
        Polygons are split into triangles by a fan from their first vertex.
        OBJ texture and normal indices are ignored. A PLY file without a
        ``face`` element gives a mesh with no faces, and a well-formed file
        of no vertices (PLY ``element vertex 0``, OFF counts ``0 0 0``, an
        STL of no facets, an OBJ of no ``v`` and no ``f`` lines) an empty
        mesh, as :func:`read_point_fields` gives a file of no points.

    Raises
    ------
    FileNotFoundError, IsADirectoryError, PermissionError
        If the file cannot be opened; the message names it.
    FileFormatError
        A :class:`ValueError`: the file is empty, truncated or malformed, a
        header count does not fit the file, a face refers to a missing
        vertex, or a vertex is not finite (NaN or infinite vertices are
        rejected, not dropped, since faces refer to them); the message names
        the file and the line or byte.

    See Also
    --------
    write_mesh : Write a triangle mesh.
    read_point_cloud : Read a point cloud.
    eppf.preprocessing.sample_mesh : Sample points on a mesh's surface.

    Notes
    -----
    OFF files of ModelNet often glue the keyword to the counts on the first
    line (``OFF490 518 0``); such files are read as if the counts were on a
    line of their own. ``COFF``/``NOFF`` variants are read (extra vertex
    columns are ignored), ``4OFF``'s homogeneous vertices ``x y z w`` are
    divided by ``w``, and ``#`` comments are skipped. STL files are
    binary when their size is ``84 + 50 n`` for the triangle count ``n``
    they declare, ASCII otherwise; their shared corners are merged into one
    vertex each.

    Examples
    --------
    >>> import os, tempfile
    >>> from eppf.io import read_mesh
    >>> path = os.path.join(tempfile.mkdtemp(), "tri.off")
    >>> with open(path, "w") as fh:
    ...     _ = fh.write("OFF3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
    >>> read_mesh(path).faces
    array([[0, 1, 2]])
    """
    owner = "read_mesh"
    path = os.fspath(path)
    fmt = lookup(path, format, owner, kind="mesh")
    cloud, shape = guard(owner, path, fmt, _read_any, path, fmt, owner, "auto", True)
    if shape is None:  # a PLY cloud
        shape = Mesh(np.ascontiguousarray(cloud.xyz), np.empty((0, 3), dtype=np.int64))
    return _check_vertices(shape, path, owner)


def write_point_cloud(path, cloud, *, format=None, binary=True):
    """Write a point cloud to a file.

    Parameters
    ----------
    path : str or path-like
        Destination; its extension chooses the format unless ``format`` is
        given: ``.pcd``, ``.ply``, ``.xyz``/``.txt``/``.csv``, ``.pts``,
        ``.xyzn`` (needs normals), ``.npy``, ``.npz``.
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by normals.
    format : str, default=None
        Override the format given by the extension.
    binary : bool, default=True
        For PCD and PLY, write binary (little endian) rather than ASCII data.

    See Also
    --------
    read_point_cloud : Read a point cloud.
    write_mesh : Write a triangle mesh.

    Notes
    -----
    PCD and PLY files store float32, as PCL and most scanners do (float64
    when a finite value lies beyond float32's range, which would store it as
    an infinity); text files keep full float64 precision (17 significant
    digits), NPY/NPZ are exact.
    Normals are written as PCD ``normal_x normal_y normal_z`` fields, PLY
    ``nx ny nz`` properties, or columns 4 to 6.

    Examples
    --------
    >>> import numpy as np, os, tempfile
    >>> from eppf.io import read_point_cloud, write_point_cloud
    >>> path = os.path.join(tempfile.mkdtemp(), "cloud.npy")
    >>> write_point_cloud(path, np.eye(3))
    >>> np.array_equal(read_point_cloud(path), np.eye(3))
    True
    """
    owner = "write_point_cloud"
    path = os.fspath(path)
    fmt = lookup(path, format, owner, kind="cloud")
    binary = check_flag(binary, "binary", owner)
    if fmt.writer is None:
        raise ValueError(f"{owner}: eppf does not write {fmt.name} files (clouds have no colour); write .xyz instead")
    cloud = _check_cloud_arg(cloud, owner)
    if fmt.name == "xyzn" and cloud.shape[1] != 6:
        raise ValueError(f"{owner}: an .xyzn file holds normals: cloud must have shape (n_points, 6), got {cloud.shape}")
    fmt.writer(path, cloud, binary=binary)


def write_mesh(path, vertices, faces, *, format=None, binary=True):
    """Write a mesh to an OFF, OBJ, STL or PLY file.

    Parameters
    ----------
    path : str or path-like
        Destination; its extension chooses the format unless ``format`` is given.
    vertices : array-like of shape (n_vertices, 3)
        Vertex coordinates.
    faces : array-like of shape (n_faces, k)
        Vertex indices (0-based) of each polygon, k >= 3 (STL stores
        triangles: polygons are split by fans).
    format : {"off", "obj", "stl", "ply"}, default=None
        Override the format given by the extension.
    binary : bool, default=True
        For PLY and STL, write binary rather than ASCII data.

    See Also
    --------
    read_mesh : Read a triangle mesh.
    write_point_cloud : Write a point cloud.

    Examples
    --------
    >>> import numpy as np, os, tempfile
    >>> from eppf.io import read_mesh, write_mesh
    >>> path = os.path.join(tempfile.mkdtemp(), "tri.obj")
    >>> write_mesh(path, np.eye(3), [[0, 1, 2]])
    >>> read_mesh(path).vertices.shape
    (3, 3)
    """
    owner = "write_mesh"
    path = os.fspath(path)
    fmt = lookup(path, format, owner, kind="mesh")
    binary = check_flag(binary, "binary", owner)
    vertices = _check_cloud_arg(vertices, owner)
    if vertices.shape[1] != 3:
        raise ValueError(f"{owner}: vertices must have shape (n_vertices, 3), got {vertices.shape}")
    faces = np.asarray(faces)
    if faces.size == 0:
        faces = faces.reshape(0, 3)
    if faces.ndim != 2 or faces.shape[1] < 3 or not np.issubdtype(faces.dtype, np.integer):
        raise ValueError(f"{owner}: faces must be an integer array of shape (n_faces, k>=3), got {faces.dtype} {faces.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= vertices.shape[0]):
        raise ValueError(f"{owner}: face indices must lie in 0..{vertices.shape[0] - 1}")
    fmt.writer(path, vertices, faces.astype(np.int64), binary=binary)
