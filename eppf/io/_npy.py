"""NumPy ``.npy`` arrays and ``.npz`` archives of point clouds.

The array header (shape and dtype) is read first and the data it declares is
checked against the bytes the file (or the archive member) holds before
anything is allocated; pickled (object) arrays are refused. An ``.npz``
member's declared size must also be one its compression can reach from its
compressed size (deflate expands at most about 1032 times).
"""

import math
import zipfile

import numpy as np

from ._common import Cloud, check_file, widened
from ._errors import FileFormatError
from ._xyz import cloud_of_table

_DEFLATE_MAX_RATIO = 1032  # deflate's longest match (258 bytes) from 2 bits, rounded up
_READ_PIECE = 1 << 18  # bytes an array is read in at a time (numpy's own piece: larger ones were slower)


def _read_array(fh, size, path, owner, what):
    """The array stored in an open .npy stream of ``size`` bytes."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = fmt.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except Exception as exc:  # noqa: BLE001 - ValueError, SyntaxError, tokenize.TokenError, EOFError, ...
        raise FileFormatError(f"{owner}: {path!r}{what}: not a readable .npy array ({exc})") from None
    if dtype.hasobject:
        raise FileFormatError(f"{owner}: {path!r}{what}: holds a {dtype} array; expected plain numbers (pickled objects are refused)")
    if dtype.fields is not None:  # (PDAL's numpy writer: one named field per dimension)
        raise FileFormatError(f"{owner}: {path!r}{what}: holds a structured array with the fields "
                              f"{list(dtype.names)[:12]}; expected a plain numeric array of shape (n_points, 3+) "
                              "(columns x y z first)")
    if dtype.subdtype is not None:
        raise FileFormatError(f"{owner}: {path!r}{what}: holds a {dtype} array; expected plain numbers")
    if any(d < 0 for d in shape):
        raise FileFormatError(f"{owner}: {path!r}{what}: the header declares a negative shape {shape}")
    count = math.prod(shape)
    need = count * dtype.itemsize
    left = size - fh.tell()
    if need > left:
        raise FileFormatError(
            f"{owner}: {path!r}{what}: the header declares an array of shape {shape} ({need} bytes), "
            f"but only {left} bytes follow it (truncated, or a wrong shape)"
        )
    raw = bytearray(need)  # (a writable array, as np.load gives, read in pieces without a second whole copy)
    view, got = memoryview(raw), 0
    while got < need:
        n = fh.readinto(view[got : got + _READ_PIECE])
        if not n:
            break
        got += n
    if got != need:
        raise FileFormatError(f"{owner}: {path!r}{what}: array data ends after {got} of {need} bytes (truncated)")
    return np.frombuffer(raw, dtype=dtype, count=count).reshape(shape, order="F" if fortran else "C")


def _member(zf, name, path, owner):
    info = zf.getinfo(name)
    bound = info.compress_size if info.compress_type == zipfile.ZIP_STORED else _DEFLATE_MAX_RATIO * info.compress_size
    if info.file_size > bound + 1024:
        raise FileFormatError(
            f"{owner}: {path!r} member {name!r}: declares {info.file_size} bytes from {info.compress_size} "
            "compressed bytes, more than its compression can give"
        )
    with zf.open(info) as fh:
        return _read_array(fh, info.file_size, path, owner, f" member {name!r}")


def _read_npz(fh, path, owner):
    with zipfile.ZipFile(fh) as zf:
        names = zf.namelist()
        keys = {n[:-4] if n.endswith(".npy") else n: n for n in names}
        files = list(keys)
        if "points" in keys and "offsets" in keys:
            raise FileFormatError(
                f"{owner}: {path!r} holds a data set (points and offsets); read it with eppf.datasets.load_npz"
            )
        # eppf writes 'points' (and 'normals'); Open3D's tensor point clouds write 'positions' (and 'normals',
        # 'colors', ...)
        name = "points" if "points" in keys else "positions" if "positions" in keys else None
        if name is not None:
            arr = _member(zf, keys[name], path, owner)
            if "normals" in keys and arr.ndim == 2:
                nrm = _member(zf, keys["normals"], path, owner)
                if nrm.ndim != 2 or nrm.shape[0] != arr.shape[0] or nrm.shape[1] != 3:
                    raise FileFormatError(
                        f"{owner}: {path!r}: 'normals' has shape {nrm.shape}, expected ({arr.shape[0]}, 3)"
                    )
                arr = np.hstack([arr[:, :3], nrm])
        elif len(files) == 1:
            arr = _member(zf, names[0], path, owner)
        else:
            raise FileFormatError(
                f"{owner}: {path!r} holds the arrays {sorted(files)}; expected one array or one named 'points' "
                "(or Open3D's 'positions')"
            )
    return arr


def _to_cloud(arr, path, owner, want_normals="auto"):
    if arr.ndim != 2 or arr.shape[1] < 3 or not np.issubdtype(arr.dtype, np.number) \
            or np.issubdtype(arr.dtype, np.complexfloating):
        raise FileFormatError(
            f"{owner}: {path!r} must hold a numeric array of shape (n_points, 3+), got {arr.dtype} {arr.shape}"
        )
    arr = widened(arr)
    if arr.shape[1] == 6:  # x y z nx ny nz, as write_point_cloud writes normals
        return Cloud(arr[:, :3], arr[:, 3:])
    # a wider array (x y z r g b intensity, a grid of values) has normals in columns 4 to 6 only when they
    # have unit length there, as a text table's
    return cloud_of_table(arr, want_normals)


def read_npy(path, owner, want_normals="auto"):
    return _to_cloud(read_npy_array(path, owner), path, owner, want_normals)


def _size(path, owner):
    """The size of the readable, non-empty file ``path`` (OSError or FileFormatError naming it)."""
    size = check_file(path, owner)
    if size == 0:
        raise FileFormatError(f"{owner}: {path!r} is empty")
    return size


def _in_archive(path, owner, read):
    """``read(open file)`` on the .npz file ``path``; anything but a FileFormatError from a malformed archive
    (BadZipFile, zlib.error, NotImplementedError, EOFError, OSError from seeks, ...) becomes one naming it."""
    _size(path, owner)
    with open(path, "rb") as fh:  # an OSError here names the file
        try:
            return read(fh)
        except FileFormatError:
            raise
        except Exception as exc:  # noqa: BLE001 - the archive's content, not the file system
            raise FileFormatError(
                f"{owner}: {path!r} is not a readable .npz archive ({type(exc).__name__}: {exc})"
            ) from None


def read_npz(path, owner, want_normals="auto"):
    return _to_cloud(_in_archive(path, owner, lambda fh: _read_npz(fh, path, owner)), path, owner, want_normals)


def read_npy_array(path, owner):
    """The array of an ``.npy`` file, its header checked against the file's size before anything is allocated."""
    size = _size(path, owner)
    with open(path, "rb") as fh:
        return _read_array(fh, size, path, owner, "")


def read_npz_arrays(path, owner):
    """Every array of an ``.npz`` archive by name (``.npy`` dropped), each checked as a cloud's is.

    Pickled (object) arrays are refused, every header is checked against the
    bytes its member holds before anything is allocated, and a malformed
    archive or member raises :class:`FileFormatError` naming ``owner`` and
    the file (``np.load`` would allocate what a hostile header declares).
    """
    def read(fh):
        with zipfile.ZipFile(fh) as zf:
            names = zf.namelist()
            return {n[:-4] if n.endswith(".npy") else n: _member(zf, n, path, owner) for n in names}

    return _in_archive(path, owner, read)


def write_npy(path, cloud, binary=True):
    with open(path, "wb") as fh:
        np.save(fh, cloud)


def write_npz(path, cloud, binary=True):
    with open(path, "wb") as fh:
        np.savez(fh, points=cloud)
