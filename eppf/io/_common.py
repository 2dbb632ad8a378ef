"""Helpers shared by the format modules: reading bytes, text lines, clouds, meshes."""

import errno
import os
import stat
from collections import namedtuple

import numpy as np

from ._errors import FileFormatError

#: Normal field names as the formats write them: PCD, NumPy arrays and LAS extra bytes; PLY (and LAS
#: extra bytes again); E57's surface-normals extension. Readers return normals found under any of them.
NORMAL_NAMES = ("normal_x", "normal_y", "normal_z")
NORMAL_NAME_SETS = (NORMAL_NAMES, ("nx", "ny", "nz"), ("nor:normalX", "nor:normalY", "nor:normalZ"))

Mesh = namedtuple("Mesh", ["vertices", "faces"])
Mesh.__doc__ = """A triangle mesh.

Parameters
----------
vertices : ndarray of shape (n_vertices, 3), dtype float64
    Vertex coordinates.
faces : ndarray of shape (n_faces, 3), dtype int64
    Vertex indices of each triangle.

See Also
--------
read_mesh : Read a mesh from a file.
write_mesh : Write a mesh to a file.

Examples
--------
>>> import numpy as np
>>> from eppf.io import Mesh, read_mesh, write_mesh
>>> square = Mesh(np.array([[0., 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
...               np.array([[0, 1, 2], [0, 2, 3]]))
>>> write_mesh("square.off", *square)
>>> mesh = read_mesh("square.off")
>>> mesh.vertices.shape, mesh.faces.tolist()
((4, 3), [[0, 1, 2], [0, 2, 3]])
"""

# A cloud read from a file: coordinates and optional normals (both float64, n rows).
Cloud = namedtuple("Cloud", ["xyz", "normals"])


def float_code(values):
    """``"f4"``, the float32 that PCD and PLY files of clouds hold, unless a finite value lies beyond float32's
    range (it would be stored as an infinity): then ``"f8"``."""
    finite = np.abs(values[np.isfinite(values)])
    return "f8" if finite.size and finite.max() > np.finfo(np.float32).max else "f4"


def widened(values):
    """A float64 copy of a numeric array, without NumPy's cast warning for signaling NaNs.

    Widening float32 (or float16) to float64 is exact; a signaling NaN in a
    file (a corrupt or hostile one) becomes a quiet NaN and raises the CPU's
    "invalid" flag, which NumPy turns into a RuntimeWarning (an exception
    under ``-W error``) that says nothing about the file. The readers drop or
    keep NaN points as they always do.
    """
    with np.errstate(invalid="ignore"):
        return np.asarray(values).astype(np.float64)


def check_file(path, owner):
    """Stat ``path``: OSError (naming it) unless it is a regular, readable file; returns its size."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(errno.ENOENT, f"{owner}: no such file", path) from None
    if stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, f"{owner}: a folder, not a file", path)
    if not stat.S_ISREG(st.st_mode):  # a FIFO or a device (/dev/zero) would block or never end
        raise OSError(errno.EINVAL, f"{owner}: not a regular file", path)
    return st.st_size


def read_bytes(path, owner):
    """The whole file; OSError naming the file if it cannot be read, FileFormatError if it is empty."""
    check_file(path, owner)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise type(exc)(exc.errno, f"{owner}: cannot read the file ({exc.strerror})", path) from None
    if not data.strip():
        raise FileFormatError(f"{owner}: {path!r} is empty")
    return data


def text_lines(data, path, owner, split=True):
    """The lines of a UTF-8 text file (or, with ``split=False``, its text)."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{owner}: {path!r} is not a text file (undecodable byte at offset {exc.start})") from None
    return text.splitlines() if split else text


def content(lines, comment="#"):
    """Indices and comment-free contents of the non-blank lines."""
    idx, out = [], []
    for i, line in enumerate(lines):
        if comment in line:
            line = line.split(comment, 1)[0]
        line = line.strip()
        if line:
            idx.append(i)
            out.append(line)
    return idx, out


def parse_float_rows(rows, idx, path, owner, what):
    """Parse whitespace-separated rows into a 2D float array.

    Every row must have as many values as the first; an error names the line
    (``idx`` holds each row's 0-based line number in the file).
    """
    split = [r.split() for r in rows]
    width = len(split[0])
    if any(len(s) != width for s in split):
        k = next(k for k, s in enumerate(split) if len(s) != width)
        raise FileFormatError(
            f"{owner}: {path!r} line {idx[k] + 1}: expected {width} values in {what} {k}, "
            f"got {len(split[k])}: {rows[k][:80]!r}"
        )
    try:
        return np.array(split, dtype=np.float64)
    except ValueError:
        for k, s in enumerate(split):
            try:
                [float(t) for t in s]
            except ValueError:
                raise FileFormatError(
                    f"{owner}: {path!r} line {idx[k] + 1}: malformed number in {what} {k}: {rows[k][:80]!r}"
                ) from None
        raise


def next_line(data, pos):
    """The next non-blank line of ``data`` from ``pos``, and the offset after it."""
    n = len(data)
    while pos < n:
        end = data.find(b"\n", pos)
        end = n if end < 0 else end
        line = data[pos:end].strip()
        pos = end + 1
        if line:
            return line, pos
    return None, pos


def fan(polys):
    """Triangulate a list of index lists by fans from the first vertex."""
    tris = []
    for p in polys:
        for k in range(1, len(p) - 1):
            tris.append((p[0], p[k], p[k + 1]))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def check_count(count, record_bytes, available, path, owner, what, where):
    """A header count must fit the bytes left in the file, before anything is allocated.

    ``record_bytes`` is the least number of bytes one record can take (its
    exact size in binary data, a lower bound for text); ``where`` describes
    the position (e.g. ``"byte 120"`` or ``"line 3"``).
    """
    if count < 0:
        raise FileFormatError(f"{owner}: {path!r} {where}: negative {what} count {count}")
    if count * record_bytes > available:
        raise FileFormatError(
            f"{owner}: {path!r} {where}: the header declares {count} {what}, which need at least "
            f"{count * record_bytes} bytes, but the file has only {available} bytes left "
            "(a wrong count or a truncated file)"
        )


def check_polygon_faces(faces, n_vertices, path, owner, where=""):
    """Face indices in 0..n_vertices-1 (an int64 array of shape (n, 3))."""
    if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
        k = int(np.flatnonzero((faces < 0).any(1) | (faces >= n_vertices).any(1))[0])
        raise FileFormatError(
            f"{owner}: {path!r}{where}: face index out of range 0..{n_vertices - 1} (triangle {k})"
        )
