"""Text tables of points: XYZ/TXT/CSV, Open3D's PTS, XYZN and XYZRGB.

- ``.xyz``, ``.txt``, ``.csv``: rows ``x y z [more columns]`` separated by
  spaces, tabs, commas or semicolons, ``#`` comments, and one optional header
  line of names; columns 4 to 6 are normals when every row there has unit
  length (so ``x y z r g b`` files are not mistaken). A table of no rows (a
  header line or comments only) is a file of no points.
- ``.pts`` (Open3D): the same rows, optionally after a first line holding
  only the number of points (``0`` alone: a file of no points); extra
  columns are intensity and color, read as in ``.xyz``. A Leica PTS file of
  several scans, each after its count line, is refused naming the second.
  The count must be the number of rows: a file of more rows than its count
  line says is refused (PDAL and Open3D read the first rows and drop the
  rest, which would be a silently shortened cloud), naming the count line
  and the first row past the count.
- ``.xyzn`` (Open3D): ``x y z nx ny nz``, normals always.
- ``.xyzrgb`` (Open3D): ``x y z r g b``, the color is ignored.
"""

import numpy as np

from ._common import Cloud, content, next_line, parse_float_rows, text_lines
from ._errors import FileFormatError

try:  # compiled table parser; the line-by-line reader below does the rest
    from ._xyz_fast import parse_float_table as _parse_float_table
except ImportError:  # pragma: no cover - an uncompiled checkout
    _parse_float_table = None


def _xyz_compiled(data, start=0):
    """The table of a plain numeric text file parsed in C, or None."""
    if _parse_float_table is None or b"#" in data:
        return None
    first, pos = next_line(data, start)
    if first is None:
        return None
    try:
        float(first.replace(b",", b" ").replace(b";", b" ").split()[0])
    except (ValueError, IndexError):  # one header line of names
        start = pos
    return _parse_float_table(data, start)


def _table(path, data, owner, start=0, start_line=0):
    """Rows of numbers of a text file from byte ``start`` (line ``start_line``, 0-based):
    (array, 0-based line of each row, or None when the compiled parser read it)."""
    arr = _xyz_compiled(data, start)
    if arr is not None and arr.shape[1] >= 3:
        return arr, None
    lines = text_lines(data, path, owner)
    idx, rows = content(lines[start_line:])
    idx = [i + start_line for i in idx]
    rows = [r.replace(",", " ").replace(";", " ") for r in rows]
    # a table of no rows (only blank or comment lines, or a header line) is a file of no points, as an empty
    # PLY, PCD, NPY, LAS or E57 file is: read_point_fields gives it, read_point_cloud says it holds no points
    if not rows:
        return np.empty((0, 3)), []
    # one header line of names (e.g. "x,y,z") is allowed
    try:
        [float(t) for t in rows[0].split()]
    except ValueError:
        if len(rows) == 1:
            width = len(rows[0].split())
            if width < 3:
                raise FileFormatError(
                    f"{owner}: {path!r} line {idx[0] + 1}: expected at least 3 columns (x y z), got {width}"
                ) from None
            return np.empty((0, width)), []
        idx, rows = idx[1:], rows[1:]
    first = rows[0].split()
    if start_line == 0 and len(rows) > 1 and len(first) == 1 and first[0].isdigit() and len(rows[1].split()) >= 3:
        # (read as a row of one value, it was reported as "expected 1 values in point 1" on the next line)
        raise FileFormatError(
            f"{owner}: {path!r} line {idx[0] + 1}: a count line ({first[0]}) as a .pts file begins with, but "
            f"the rows of this file's format hold x y z; read it as .pts (format='pts') to use the count"
        )
    arr = parse_float_rows(rows, idx, path, owner, "point")
    if arr.shape[1] < 3:
        raise FileFormatError(
            f"{owner}: {path!r} line {idx[0] + 1}: expected at least 3 columns (x y z), got {arr.shape[1]}"
        )
    return arr, idx


def _guess_normals(arr):
    """Columns 4 to 6 when they look like unit normals, else None."""
    if arr.shape[1] < 6:
        return None
    cand = arr[:, 3:6]
    lengths = np.sqrt(np.einsum("ij,ij->i", cand, cand))
    return cand if np.all(np.abs(lengths - 1.0) < 1e-2) else None


def read_xyz(path, data, owner, want_normals="auto"):
    """``.xyz``/``.txt``/``.csv`` (and the rows of ``.pts``)."""
    arr, _ = _table(path, data, owner)
    return cloud_of_table(arr, want_normals)


def cloud_of_table(arr, want_normals):
    """The Cloud of a float64 table: columns 1-3, and columns 4-6 as normals when they have unit length in
    every row (or when ``want_normals`` is True); the text tables' rule, and the NumPy readers' for arrays
    wider than 6 columns."""
    if want_normals is True and arr.shape[1] >= 6:
        return Cloud(arr[:, :3], arr[:, 3:6])
    return Cloud(arr[:, :3], _guess_normals(arr))


def _refuse_several_scans(path, data, owner, pos, count):
    """A FileFormatError naming a second count line after the first ``count`` rows from byte ``pos``: Leica's
    PTS files may hold several scans, each after its own count line (Open3D and PDAL read the first). Only
    called once the file failed to read as one scan, so its lines are split here in Python."""
    idx, rows = content(data[pos:].decode("utf-8", "replace").splitlines())
    if len(rows) > count and rows[count].isdigit():
        line = data[:pos].count(b"\n") + idx[count] + 1
        raise FileFormatError(f"{owner}: {path!r} line {line}: a second count line ({rows[count]}): the file holds "
                              "several scans, each after its count line; eppf reads .pts files of one scan")


def _first_content(data, pos=0):
    """The first line of ``data`` from byte ``pos`` holding more than blanks and a ``#`` comment, without the
    comment, and the offset after it (None and the end when there is none): where a .pts file's count line
    is, so that a comment line before it does not make it a row of one value, and whether rows follow it."""
    line, pos = next_line(data, pos)
    while line is not None and not line.split(b"#", 1)[0].strip():
        line, pos = next_line(data, pos)
    return (None if line is None else line.split(b"#", 1)[0].strip()), pos


def _line_of_row(data, pos, k):
    """The 1-based line of row ``k`` (from 0) of the table from byte ``pos``, past a header line of names as
    the table readers skip it. Only called to name a line in an error, so the lines are split here in Python."""
    idx, rows = content(data[pos:].decode("utf-8", "replace").splitlines())
    try:
        [float(t) for t in rows[0].replace(",", " ").replace(";", " ").split()]
    except ValueError:
        idx = idx[1:]
    return data[:pos].count(b"\n") + idx[k] + 1


def read_pts(path, data, owner, want_normals="auto"):
    """Open3D's ``.pts``: an optional first line with the point count, then rows.

    The count must match the rows. Fewer rows are a truncated file; more rows are refused too, naming the
    count line and the first row past the count, rather than read as PDAL and Open3D read them (the first
    ``count`` rows, the rest dropped without a word): which of the two is wrong, the count or the rows, the
    file does not say, and a cloud cut short would look like a whole one. A second count line is a Leica
    file of several scans, refused as such.
    """
    first, pos = _first_content(data)
    if first is not None and len(first.split()) == 1:
        token = first.split()[0]
        try:
            count = int(token)
        except ValueError:
            count = None  # a header word or a one-column row: the table reader reports it
        if count is not None:
            line_no = data[:pos].rstrip(b"\n").count(b"\n")
            if count < 0:
                raise FileFormatError(f"{owner}: {path!r} line {line_no + 1}: negative point count {count}")
            if _first_content(data, pos)[0] is None:  # (no rows after the count line)
                # Open3D writes an empty cloud as the count line "0" alone: a file of no points, as an empty
                # PLY, NPY, LAS or E57 file is (read_point_cloud then says it holds no points)
                if count == 0:
                    return Cloud(np.empty((0, 3)), None)
                raise FileFormatError(f"{owner}: {path!r} line {line_no + 1}: the count line says {count} points, "
                                      "but the file holds no points (truncated)")
            try:
                arr, idx = _table(path, data, owner, start=pos, start_line=line_no + 1)
            except FileFormatError:
                _refuse_several_scans(path, data, owner, pos, count)
                raise
            if arr.shape[0] != count:
                _refuse_several_scans(path, data, owner, pos, count)
                more = ""
                if arr.shape[0] > count:
                    more = (f", {arr.shape[0] - count} more from line {_line_of_row(data, pos, count)} (PDAL and Open3D "
                            "would drop them: correct the count line, or delete it to read every row)")
                raise FileFormatError(
                    f"{owner}: {path!r} line {line_no + 1}: the count line says {count} points, "
                    f"but the file holds {arr.shape[0]} rows{more}"
                )
            return cloud_of_table(arr, want_normals)
    return read_xyz(path, data, owner, want_normals)


def _fixed(path, data, owner, what):
    arr, idx = _table(path, data, owner)
    if arr.shape == (0, 3) and not idx:  # (no rows and no header line: no points, of any width)
        return np.empty((0, 6))
    if arr.shape[1] != 6:
        line = idx[0] + 1 if idx else 1
        raise FileFormatError(f"{owner}: {path!r} line {line}: a .{what} row holds 6 values, got {arr.shape[1]}")
    return arr


def read_xyzn(path, data, owner, want_normals="auto"):
    """Open3D's ``.xyzn``: ``x y z nx ny nz`` rows."""
    arr = _fixed(path, data, owner, "xyzn")
    return Cloud(arr[:, :3], arr[:, 3:6])


def read_xyzrgb(path, data, owner, want_normals="auto"):
    """Open3D's ``.xyzrgb``: ``x y z r g b`` rows; the color is dropped."""
    arr = _fixed(path, data, owner, "xyzrgb")
    return Cloud(arr[:, :3], None)


def write_xyz(path, cloud, binary=True):
    sep = "," if str(path).lower().endswith(".csv") else " "
    np.savetxt(path, cloud, fmt="%.17g", delimiter=sep)


def write_xyzn(path, cloud, binary=True):
    if cloud.shape[1] != 6:
        raise ValueError("write_point_cloud: an .xyzn file needs normals: cloud must have shape (n_points, 6)")
    np.savetxt(path, cloud, fmt="%.17g")


# --------------------------------------------------------------------------- every field

#: Column names of the fixed text layouts, after x y z (Open3D's: .xyzn normals, .xyzrgb color).
FIXED_NAMES = {"xyzn": ("nx", "ny", "nz"), "xyzrgb": ("red", "green", "blue")}
#: Open3D's .pts rows: x y z, then intensity and/or r g b.
_PTS_NAMES = {4: ("intensity",), 6: ("red", "green", "blue"), 7: ("intensity", "red", "green", "blue")}


def _header_names(data, start):
    """The names of the first content line from byte ``start`` when it is a header of names, else None."""
    line, pos = next_line(data, start)
    while line is not None:
        line = line.split(b"#", 1)[0].strip()
        if line:
            break
        line, pos = next_line(data, pos)
    if line is None:
        return None
    tokens = line.replace(b",", b" ").replace(b";", b" ").split()
    try:
        float(tokens[0])
        return None
    except ValueError:
        return [t.decode("utf-8", "replace") for t in tokens]


def read_text_fields(path, data, owner, fmt):
    """(points, fields) of a text table: columns named by its header line (x y z found by name, else the first
    three), by the layout of .xyzn/.xyzrgb/.pts, else ``column_4``, ``column_5``, ... (counting from 1)."""
    start = 0
    if fmt == "pts":
        first, pos = _first_content(data)
        if first is not None and len(first.split()) == 1:
            try:
                int(first.split()[0])
                start = pos
            except ValueError:
                pass
    if start:
        if read_pts(path, data, owner).xyz.shape[0] == 0:  # (checks the count line against the rows)
            return np.empty((0, 3)), {}
        arr = _table(path, data, owner, start=start, start_line=data[:start].count(b"\n"))[0]
    elif fmt in FIXED_NAMES:
        arr = _fixed(path, data, owner, fmt)
    else:
        arr, _ = _table(path, data, owner)
    width = arr.shape[1]
    names = _header_names(data, start) if fmt in ("xyz", "pts") else None
    if names is not None:
        if len(names) != width:
            raise FileFormatError(f"{owner}: {path!r}: the header line names {len(names)} columns, "
                                  f"but the rows hold {width}: {names[:12]}")
        if len(set(names)) != len(names):
            raise FileFormatError(f"{owner}: {path!r}: the header line names a column twice: {names[:12]}")
    elif fmt in FIXED_NAMES:
        names = ["x", "y", "z", *FIXED_NAMES[fmt]]
    elif fmt == "pts" and width in _PTS_NAMES:
        names = ["x", "y", "z", *_PTS_NAMES[width]]
    else:
        names = ["x", "y", "z"] + [f"column_{k + 1}" for k in range(3, width)]
    lower = [n.lower() for n in names]
    xyz = [lower.index(a) for a in "xyz"] if all(a in lower for a in "xyz") else [0, 1, 2]
    points = np.ascontiguousarray(arr[:, xyz])
    fields = {names[k]: np.ascontiguousarray(arr[:, k]) for k in range(width) if k not in xyz}
    return points, fields
