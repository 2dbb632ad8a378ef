"""Read and write point clouds and meshes.

Point clouds: PCD (PCL; ``ascii``, ``binary`` and ``binary_compressed``),
PLY (ASCII and binary, through `plyfile`), XYZ/TXT/CSV/PTS text, NPY and NPZ.
Meshes: OFF (including ModelNet's malformed first line, where ``OFF`` is glued
to the counts), OBJ and PLY faces.

A cloud is returned as a float64 array of shape (n_points, 3), or
(n_points, 6) with the normals in columns 3 to 5 when the file has them, the
layout every eppf estimator accepts. A mesh is returned as a :class:`Mesh`
``(vertices, faces)`` with polygons split into triangles (a fan from each
polygon's first vertex).

Which code reads what, and why:

- PLY goes through `plyfile <https://github.com/dranjan/python-plyfile>`_, a
  small, maintained, NumPy-only package that handles every PLY variant (ASCII,
  both byte orders, list properties, comments) and reports the element and row
  of a bad entry. It is an optional dependency (``pip install eppf[io]``).
- OFF, OBJ, PCD and the text formats are simple enough that a careful reader
  here is shorter than the glue to a library, and it lets every error name the
  file and the line (text) or byte (binary). It is also fast: OFF meshes are
  parsed with vectorised NumPy on the common all-triangle case, which matters
  for data sets of ten thousand meshes. Mesh libraries (trimesh) build
  heavier objects per file, and the PCD libraries on PyPI are unmaintained.
- ``binary_compressed`` PCD files use LZF; the decompressor here is a plain
  implementation of the published LZF format (no extra dependency).
"""

import os
import struct
from collections import namedtuple

import numpy as np

try:  # compiled parser for plain OFF bodies; the pure-Python readers below do the rest
    from ._io_cy import parse_float_table as _parse_float_table
    from ._io_cy import parse_off_body as _parse_off_body
except ImportError:  # pragma: no cover - an uncompiled checkout
    _parse_off_body = _parse_float_table = None

__all__ = ["Mesh", "read_mesh", "read_point_cloud", "write_mesh", "write_point_cloud"]

Mesh = namedtuple("Mesh", ["vertices", "faces"])
Mesh.__doc__ = """A triangle mesh.

Attributes
----------
vertices : ndarray of shape (n_vertices, 3), dtype float64
    Vertex coordinates.
faces : ndarray of shape (n_faces, 3), dtype int64
    Vertex indices of each triangle.

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

_CLOUD_FORMATS = {
    ".pcd": "pcd",
    ".ply": "ply",
    ".xyz": "xyz",
    ".txt": "xyz",
    ".csv": "xyz",
    ".pts": "xyz",
    ".npy": "npy",
    ".npz": "npz",
}
_MESH_FORMATS = {".off": "off", ".obj": "obj", ".ply": "ply"}


def _fmt(path, fmt, table, owner):
    if fmt is not None:
        fmt = str(fmt).lower().lstrip(".")
        if fmt in ("txt", "csv", "pts"):
            fmt = "xyz"
        if fmt not in set(table.values()):
            raise ValueError(f"{owner}: unknown format {fmt!r}; expected one of {sorted(set(table.values()))}")
        return fmt
    ext = os.path.splitext(path)[1].lower()
    if ext not in table:
        raise ValueError(
            f"{owner}: cannot tell the format of {path!r} from its extension {ext!r}; "
            f"known extensions are {sorted(table)}, or pass format="
        )
    return table[ext]


def _read_bytes(path, owner):
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"{owner}: no such file: {path!r}")
    with open(path, "rb") as fh:
        data = fh.read()
    if not data.strip():
        raise ValueError(f"{owner}: {path!r} is empty")
    return data


def _check_normals_arg(normals, owner):
    if normals not in ("auto", True, False):
        raise ValueError(f"{owner}: normals must be 'auto', True or False, got {normals!r}")


def _finish_cloud(xyz, nrm, path, normals, owner, remove_nan=True):
    """Combine coordinates and optional normals; drop non-finite points."""
    if normals is True and nrm is None:
        raise ValueError(f"{owner}: {path!r} has no normals, but normals=True")
    if normals is False:
        nrm = None
    cloud = xyz if nrm is None else np.hstack([xyz, nrm])
    cloud = np.ascontiguousarray(cloud, dtype=np.float64)
    if remove_nan:
        keep = np.isfinite(cloud).all(axis=1)
        if not keep.all():
            cloud = cloud[keep]
    if cloud.shape[0] == 0:
        raise ValueError(f"{owner}: {path!r} holds no points")
    return cloud


# --------------------------------------------------------------------------- text


def _text_lines(data, path, owner):
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{owner}: {path!r} is not a text file (undecodable byte at offset {exc.start})") from None
    return text.splitlines()


def _content(lines, comment="#"):
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


def _parse_float_rows(rows, idx, path, owner, what):
    """Parse whitespace-separated rows into a 2D float array.

    Every row must have as many values as the first; an error names the line
    (``idx`` holds each row's 0-based line number in the file).
    """
    split = [r.split() for r in rows]
    width = len(split[0])
    if any(len(s) != width for s in split):
        k = next(k for k, s in enumerate(split) if len(s) != width)
        raise ValueError(
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
                raise ValueError(
                    f"{owner}: {path!r} line {idx[k] + 1}: malformed number in {what} {k}: {rows[k][:80]!r}"
                ) from None
        raise


def _xyz_compiled(data):
    """The table of a plain numeric text file parsed in C, or None."""
    if _parse_float_table is None or b"#" in data:
        return None
    first, pos = _next_line(data, 0)
    if first is None:
        return None
    try:
        float(first.replace(b",", b" ").replace(b";", b" ").split()[0])
        start = 0
    except (ValueError, IndexError):  # one header line of names
        start = pos
    return _parse_float_table(data, start)


def _read_xyz(path, data, normals, owner, remove_nan):
    arr = _xyz_compiled(data)
    if arr is not None and arr.shape[1] >= 3:
        return _xyz_columns(arr, path, normals, owner, remove_nan)
    lines = _text_lines(data, path, owner)
    idx, rows = _content(lines)
    rows = [r.replace(",", " ").replace(";", " ") for r in rows]
    if not rows:
        raise ValueError(f"{owner}: {path!r} holds no points (only blank or comment lines)")
    # one header line of names (e.g. "x,y,z") is allowed
    try:
        [float(t) for t in rows[0].split()]
    except ValueError:
        idx, rows = idx[1:], rows[1:]
        if not rows:
            raise ValueError(f"{owner}: {path!r} holds no points (only a header line)") from None
    arr = _parse_float_rows(rows, idx, path, owner, "point")
    if arr.shape[1] < 3:
        raise ValueError(f"{owner}: {path!r} line {idx[0] + 1}: expected at least 3 columns (x y z), got {arr.shape[1]}")
    return _xyz_columns(arr, path, normals, owner, remove_nan)


def _xyz_columns(arr, path, normals, owner, remove_nan):
    """Coordinates, and normals from columns 4 to 6 when asked or when they look like normals."""
    xyz, nrm = arr[:, :3], None
    if arr.shape[1] >= 6:
        cand = arr[:, 3:6]
        if normals is True:
            nrm = cand
        elif normals == "auto":
            lengths = np.sqrt(np.einsum("ij,ij->i", cand, cand))
            if np.all(np.abs(lengths - 1.0) < 1e-2):
                nrm = cand
    return _finish_cloud(xyz, nrm, path, normals, owner, remove_nan)


def _write_xyz(path, cloud, fmt_ext):
    sep = "," if fmt_ext == ".csv" else " "
    np.savetxt(path, cloud, fmt="%.17g", delimiter=sep)


# --------------------------------------------------------------------------- numpy


def _read_npy(path, normals, owner, remove_nan, fmt):
    try:
        obj = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise ValueError(f"{owner}: {path!r} is not a readable .{fmt} file ({exc})") from None
    if fmt == "npz":
        with obj:
            files = obj.files
            if "points" in files and "offsets" in files:
                raise ValueError(
                    f"{owner}: {path!r} holds a data set (points and offsets); read it with eppf.datasets.load_npz"
                )
            if "points" in files:
                arr = obj["points"]
                if "normals" in files:
                    arr = np.hstack([np.asarray(arr)[:, :3], obj["normals"]]) if np.ndim(arr) == 2 else arr
            elif len(files) == 1:
                arr = obj[files[0]]
            else:
                raise ValueError(
                    f"{owner}: {path!r} holds the arrays {sorted(files)}; expected one array or one named 'points'"
                )
    else:
        arr = obj
    arr = np.asarray(arr)
    if arr.ndim != 2 or arr.shape[1] < 3 or not np.issubdtype(arr.dtype, np.number):
        raise ValueError(f"{owner}: {path!r} must hold a numeric array of shape (n_points, 3+), got {arr.dtype} {arr.shape}")
    arr = arr.astype(np.float64)
    nrm = arr[:, 3:6] if arr.shape[1] >= 6 else None
    return _finish_cloud(arr[:, :3], nrm, path, normals, owner, remove_nan)


# --------------------------------------------------------------------------- PCD

_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}


def _lzf_decompress(src, expected, path, owner, base):
    """Decompress an LZF stream (the format of liblzf, used by PCL)."""
    out = bytearray(expected)
    ip, op, n = 0, 0, len(src)
    while ip < n:
        ctrl = src[ip]
        ip += 1
        if ctrl < 32:  # literal run of ctrl + 1 bytes
            length = ctrl + 1
            if ip + length > n or op + length > expected:
                raise ValueError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (literal run overflows)")
            out[op:op + length] = src[ip:ip + length]
            ip += length
            op += length
        else:  # back reference
            length = ctrl >> 5
            if length == 7:
                if ip >= n:
                    raise ValueError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (truncated reference)")
                length += src[ip]
                ip += 1
            if ip >= n:
                raise ValueError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (truncated reference)")
            ref = op - ((ctrl & 0x1F) << 8) - src[ip] - 1
            ip += 1
            length += 2
            if ref < 0 or op + length > expected:
                raise ValueError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (bad back reference)")
            if ref + length <= op:
                out[op:op + length] = out[ref:ref + length]
            else:  # overlapping copy, byte by byte
                for k in range(length):
                    out[op + k] = out[ref + k]
            op += length
    if op != expected:
        raise ValueError(f"{owner}: {path!r}: compressed data gives {op} bytes, header says {expected}")
    return bytes(out)


def _parse_pcd_header(data, path, owner):
    header, pos, lineno = {}, 0, 0
    while True:
        if pos >= len(data):
            raise ValueError(f"{owner}: {path!r} line {lineno}: header ends before its DATA line")
        end = data.find(b"\n", pos)
        if end < 0:
            end = len(data)
        raw = data[pos:end]
        lineno += 1
        pos = end + 1
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ValueError(f"{owner}: {path!r} line {lineno}: non-ASCII bytes in the header") from None
        if not line or line.startswith("#"):
            continue
        key, _, rest = line.partition(" ")
        header[key.upper()] = (rest.split(), lineno)
        if key.upper() == "DATA":
            return header, pos, lineno


def _read_pcd(path, data, normals, owner, remove_nan):
    header, pos, lineno = _parse_pcd_header(data, path, owner)
    if "FIELDS" not in header:
        raise ValueError(f"{owner}: {path!r}: header has no FIELDS line")
    fields, fline = header["FIELDS"]
    n_fields = len(fields)

    def column(key, default):
        if key not in header:
            if default is None:
                raise ValueError(f"{owner}: {path!r}: header has no {key} line")
            return [default] * n_fields
        vals, ln = header[key]
        if len(vals) != n_fields:
            raise ValueError(f"{owner}: {path!r} line {ln}: {key} has {len(vals)} entries but FIELDS has {n_fields}")
        return vals

    sizes = column("SIZE", None)
    types = column("TYPE", None)
    counts = column("COUNT", "1")
    try:
        sizes = [int(s) for s in sizes]
        counts = [int(c) for c in counts]
    except ValueError:
        raise ValueError(f"{owner}: {path!r} line {header['SIZE'][1]}: SIZE and COUNT must be integers") from None
    dtype_fields = []
    for k, (name, s, t, c) in enumerate(zip(fields, sizes, types, counts)):
        code = _PCD_TYPES.get((t.upper(), s))
        if code is None:
            raise ValueError(f"{owner}: {path!r} line {header['TYPE'][1]}: unsupported TYPE/SIZE {t}/{s} for field {name!r}")
        fname = name if name != "_" else f"_pad{k}"
        dtype_fields.append((fname, "<" + code, (c,)) if c > 1 else (fname, "<" + code))
    dtype = np.dtype(dtype_fields)
    try:
        if "POINTS" in header:
            n_points = int(header["POINTS"][0][0])
        else:
            n_points = int(header["WIDTH"][0][0]) * int(header.get("HEIGHT", (["1"], 0))[0][0])
    except (ValueError, IndexError, KeyError):
        raise ValueError(f"{owner}: {path!r}: header lacks a valid POINTS (or WIDTH and HEIGHT) entry") from None
    if n_points < 0:
        raise ValueError(f"{owner}: {path!r}: negative POINTS count {n_points}")
    kind = header["DATA"][0][0].lower() if header["DATA"][0] else ""
    body = data[pos:]
    if kind == "ascii":
        text = body.decode("ascii", errors="replace").splitlines()
        idx, rows = _content(text)
        idx = [i + lineno for i in idx]
        if len(rows) < n_points:
            raise ValueError(
                f"{owner}: {path!r} line {lineno + len(text)}: file ends after {len(rows)} of {n_points} points (truncated)"
            )
        n_cols = sum(counts)
        arr = _parse_float_rows(rows[:n_points], idx, path, owner, "point")
        if n_points and arr.shape[1] != n_cols:
            raise ValueError(f"{owner}: {path!r} line {idx[0] + 1}: expected {n_cols} values per point, got {arr.shape[1]}")
        flat_names = []
        for name, c in zip(fields, counts):
            flat_names += [name] * c
        cols = {name: arr[:, flat_names.index(name)] for name in fields}
    elif kind == "binary":
        need = n_points * dtype.itemsize
        if len(body) < need:
            raise ValueError(
                f"{owner}: {path!r} byte {pos + len(body)}: file ends {need - len(body)} bytes early "
                f"(binary data of {n_points} points needs {need} bytes from byte {pos}; truncated)"
            )
        rec = np.frombuffer(body, dtype=dtype, count=n_points)
        cols = {name: rec[dtype.names[k]] for k, name in enumerate(fields)}
    elif kind == "binary_compressed":
        if len(body) < 8:
            raise ValueError(f"{owner}: {path!r} byte {pos + len(body)}: file ends inside the compressed-size header (truncated)")
        csize, usize = struct.unpack("<II", body[:8])
        if len(body) < 8 + csize:
            raise ValueError(
                f"{owner}: {path!r} byte {pos + len(body)}: file ends {8 + csize - len(body)} bytes early "
                f"(compressed block of {csize} bytes from byte {pos + 8}; truncated)"
            )
        if usize != n_points * dtype.itemsize:
            raise ValueError(
                f"{owner}: {path!r} byte {pos + 4}: uncompressed size {usize} does not match "
                f"{n_points} points of {dtype.itemsize} bytes"
            )
        raw = _lzf_decompress(body[8:8 + csize], usize, path, owner, pos + 8)
        # PCL stores compressed data field by field (structure of arrays)
        cols, off = {}, 0
        for k, name in enumerate(fields):
            sub = dtype.fields[dtype.names[k]][0]
            cols[name] = np.frombuffer(raw, dtype=sub, count=n_points, offset=off)
            off += sub.itemsize * n_points
    else:
        raise ValueError(
            f"{owner}: {path!r} line {lineno}: unknown DATA kind {kind!r}; expected ascii, binary or binary_compressed"
        )
    missing = [f for f in "xyz" if f not in cols]
    if missing:
        raise ValueError(f"{owner}: {path!r} line {fline}: FIELDS lacks {missing}; it has {fields}")
    xyz = np.column_stack([np.asarray(cols[f], dtype=np.float64).reshape(n_points, -1)[:, 0] for f in "xyz"])
    nrm = None
    if all(f in cols for f in ("normal_x", "normal_y", "normal_z")):
        nrm = np.column_stack([np.asarray(cols[f], dtype=np.float64).reshape(n_points, -1)[:, 0]
                               for f in ("normal_x", "normal_y", "normal_z")])
    return _finish_cloud(xyz, nrm, path, normals, owner, remove_nan)


def _write_pcd(path, cloud, binary):
    fields = ["x", "y", "z"] + (["normal_x", "normal_y", "normal_z"] if cloud.shape[1] == 6 else [])
    n = cloud.shape[0]
    k = len(fields)
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(fields)}\nSIZE {' '.join(['4'] * k)}\nTYPE {' '.join(['F'] * k)}\n"
        f"COUNT {' '.join(['1'] * k)}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    )
    data32 = np.ascontiguousarray(cloud, dtype="<f4")
    with open(path, "wb") as fh:
        fh.write(head.encode("ascii"))
        if binary:
            fh.write(data32.tobytes())
        else:
            np.savetxt(fh, data32, fmt="%.9g")


# --------------------------------------------------------------------------- PLY


def _plyfile(owner):
    try:
        import plyfile
    except ImportError:
        raise ImportError(
            f"{owner}: reading and writing PLY files needs the 'plyfile' package; "
            "install it with `pip install eppf[io]` (or `pip install plyfile`)"
        ) from None
    return plyfile


def _read_ply_data(path, owner):
    plyfile = _plyfile(owner)
    try:
        return plyfile.PlyData.read(path)
    except plyfile.PlyHeaderParseError as exc:
        raise ValueError(f"{owner}: {path!r} line {exc.line}: malformed PLY header ({exc.message})") from None
    except plyfile.PlyElementParseError as exc:
        where = f"element {exc.element.name!r}" if exc.element is not None else "data"
        row = f", row {exc.row}" if exc.row is not None else ""
        raise ValueError(f"{owner}: {path!r}: malformed PLY {where}{row}: {exc.message}") from None
    except (ValueError, EOFError, struct.error) as exc:
        raise ValueError(f"{owner}: {path!r}: malformed PLY file ({exc})") from None


def _ply_vertices(ply, path, owner):
    if "vertex" not in ply:
        raise ValueError(f"{owner}: {path!r}: PLY file has no 'vertex' element")
    v = ply["vertex"].data
    names = v.dtype.names or ()
    missing = [f for f in "xyz" if f not in names]
    if missing:
        raise ValueError(f"{owner}: {path!r}: PLY 'vertex' element lacks {missing}; it has {list(names)}")
    xyz = np.column_stack([np.asarray(v[f], dtype=np.float64) for f in "xyz"])
    nrm = None
    if all(f in names for f in ("nx", "ny", "nz")):
        nrm = np.column_stack([np.asarray(v[f], dtype=np.float64) for f in ("nx", "ny", "nz")])
    elif all(f in names for f in ("normal_x", "normal_y", "normal_z")):
        nrm = np.column_stack([np.asarray(v[f], dtype=np.float64) for f in ("normal_x", "normal_y", "normal_z")])
    return xyz, nrm


def _write_ply(path, cloud, faces, binary, owner):
    plyfile = _plyfile(owner)
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if cloud.shape[1] == 6 else [])
    vert = np.empty(cloud.shape[0], dtype=[(n, "<f4") for n in names])
    for k, n in enumerate(names):
        vert[n] = cloud[:, k]
    elements = [plyfile.PlyElement.describe(vert, "vertex")]
    if faces is not None:
        fa = np.empty(faces.shape[0], dtype=[("vertex_indices", "<i4", (faces.shape[1],))])
        fa["vertex_indices"] = faces
        elements.append(plyfile.PlyElement.describe(fa, "face", len_types={"vertex_indices": "u1"}))
    plyfile.PlyData(elements, text=not binary).write(path)


# --------------------------------------------------------------------------- meshes


def _fan(polys):
    """Triangulate a list of index lists by fans from the first vertex."""
    tris = []
    for p in polys:
        for k in range(1, len(p) - 1):
            tris.append((p[0], p[k], p[k + 1]))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _next_line(data, pos):
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


def _read_off_compiled(data):
    """Header in Python, body in C; None for anything but a plain OFF file."""
    if _parse_off_body is None or b"#" in data:
        return None
    first, pos = _next_line(data, 0)
    if first is None or not first.startswith(b"OFF"):
        return None
    tokens = first.split()
    if tokens[0] == b"OFF" and len(tokens) == 1:
        counts, pos = _next_line(data, pos)
        if counts is None:
            return None
        tokens = counts.split()
    elif tokens[0] == b"OFF":
        tokens = tokens[1:]
    else:  # ModelNet's "OFF490 518 0"
        tokens = [tokens[0][3:]] + tokens[1:]
    try:
        n_v, n_f = int(tokens[0]), int(tokens[1])
    except (ValueError, IndexError):
        return None
    if n_v <= 0 or n_f < 0:
        return None
    parsed = _parse_off_body(data, pos, n_v, n_f)
    if parsed is None:
        return None
    verts, faces, end = parsed
    if data[end:].strip() or (n_f and (faces.min() < 0 or faces.max() >= n_v)):
        return None
    return Mesh(verts, faces)


def _read_off_fast(text):
    """Vectorised reader for the common OFF file: no comments, triangles only.

    Returns None whenever the file is anything else (or malformed), and the
    line-by-line reader then reads it or reports the error.
    """
    if "#" in text:
        return None
    lines = text.split("\n")
    k = 0
    while k < len(lines) and not lines[k].strip():
        k += 1
    if k == len(lines):
        return None
    first = lines[k].split()
    if not first or not first[0].startswith("OFF"):
        return None
    if first[0] == "OFF" and len(first) == 1:
        k += 1
        if k >= len(lines):
            return None
        count_tokens = lines[k].split()
    else:
        count_tokens = [first[0][3:]] + first[1:] if first[0] != "OFF" else first[1:]
    try:
        n_v, n_f = int(count_tokens[0]), int(count_tokens[1])
    except (ValueError, IndexError):
        return None
    if n_v <= 0 or n_f < 0:
        return None
    start = k + 1
    vlines = lines[start:start + n_v]
    flines = lines[start + n_v:start + n_v + n_f]
    if len(vlines) != n_v or len(flines) != n_f or any(t.strip() for t in lines[start + n_v + n_f:]):
        return None
    if set(map(len, map(str.split, vlines))) != {3}:
        return None
    verts = np.fromstring(" ".join(vlines), sep=" ")  # C parser; sizes checked below
    if verts.size != 3 * n_v:
        return None
    if n_f == 0:
        return Mesh(verts.reshape(n_v, 3), np.empty((0, 3), dtype=np.int64))
    if set(map(len, map(str.split, flines))) != {4}:
        return None
    ints = np.fromstring(" ".join(flines), dtype=np.int64, sep=" ")
    if ints.size != 4 * n_f:
        return None
    quad = ints.reshape(n_f, 4)
    faces = quad[:, 1:]
    if np.any(quad[:, 0] != 3) or faces.min() < 0 or faces.max() >= n_v:
        return None
    return Mesh(verts.reshape(n_v, 3), np.ascontiguousarray(faces))


def _read_off(path, data, owner):
    mesh = _read_off_compiled(data)
    if mesh is not None:
        return mesh
    try:
        mesh = _read_off_fast(data.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        mesh = None
    if mesh is not None:
        return mesh
    lines = _text_lines(data, path, owner)
    idx, rows = _content(lines)
    if not rows:
        raise ValueError(f"{owner}: {path!r} is empty")
    first = rows[0]
    head = first.split()[0] if first.split() else ""
    # ModelNet ships files whose first line is e.g. "OFF490 518 0": keyword glued to the counts
    kw = head.rstrip("0123456789.-+")
    if not kw.upper().endswith("OFF") or kw.upper().lstrip("STCN4") != "OFF":
        raise ValueError(f"{owner}: {path!r} line {idx[0] + 1}: expected an 'OFF' header, got {first[:40]!r}")
    rest = first[len(kw):].strip()
    if rest:
        count_line, count_k = rest, 0
        body_start = 1
    else:
        if len(rows) < 2:
            raise ValueError(f"{owner}: {path!r} line {idx[0] + 1}: file ends after the OFF keyword, before the counts")
        count_line, count_k = rows[1], 1
        body_start = 2
    try:
        counts = [int(t) for t in count_line.split()]
        if len(counts) < 2 or counts[0] < 0 or counts[1] < 0:
            raise ValueError
    except ValueError:
        raise ValueError(
            f"{owner}: {path!r} line {idx[count_k] + 1}: expected the counts 'n_vertices n_faces n_edges', "
            f"got {count_line[:60]!r}"
        ) from None
    n_v, n_f = counts[0], counts[1]
    if n_v == 0:
        raise ValueError(f"{owner}: {path!r} line {idx[count_k] + 1}: the mesh has no vertices")
    avail = len(rows) - body_start
    if avail < n_v + n_f:
        got_v = min(avail, n_v)
        got_f = max(0, avail - n_v)
        last = idx[-1] + 1
        what = f"{got_v} of {n_v} vertices" if got_v < n_v else f"{got_f} of {n_f} faces"
        raise ValueError(f"{owner}: {path!r} line {last}: file ends after {what} (truncated)")
    vrows = rows[body_start:body_start + n_v]
    vidx = idx[body_start:body_start + n_v]
    verts = _parse_float_rows(vrows, vidx, path, owner, "vertex")
    if verts.shape[1] < 3:
        raise ValueError(f"{owner}: {path!r} line {vidx[0] + 1}: a vertex needs 3 coordinates, got {verts.shape[1]}")
    verts = np.ascontiguousarray(verts[:, :3])
    frows = rows[body_start + n_v:body_start + n_v + n_f]
    fidx = idx[body_start + n_v:body_start + n_v + n_f]
    faces = None
    if n_f:
        try:
            flat = np.array(" ".join(frows).split(), dtype=np.int64)
        except ValueError:
            flat = None
        if flat is not None and flat.size == 4 * n_f:
            quad = flat.reshape(n_f, 4)
            if np.all(quad[:, 0] == 3):
                faces = np.ascontiguousarray(quad[:, 1:])
        if faces is None:
            polys = []
            for k, row in enumerate(frows):
                parts = row.split()
                try:
                    m = int(parts[0])
                    ids = [int(t) for t in parts[1:1 + m]]
                except ValueError:
                    raise ValueError(f"{owner}: {path!r} line {fidx[k] + 1}: malformed face: {row[:80]!r}") from None
                if m < 3 or len(ids) != m:
                    raise ValueError(
                        f"{owner}: {path!r} line {fidx[k] + 1}: a face needs at least 3 vertex indices "
                        f"and as many as its count says: {row[:80]!r}"
                    )
                polys.append(ids)
            faces = _fan(polys)
            rows_of = np.repeat(np.arange(n_f), [len(p) - 2 for p in polys])
        else:
            rows_of = np.arange(n_f)
        bad = np.flatnonzero((faces < 0).any(axis=1) | (faces >= n_v).any(axis=1))
        if bad.size:
            k = int(rows_of[bad[0]])
            raise ValueError(
                f"{owner}: {path!r} line {fidx[k] + 1}: face index out of range 0..{n_v - 1}: {frows[k][:80]!r}"
            )
    else:
        faces = np.empty((0, 3), dtype=np.int64)
    return Mesh(verts, faces.astype(np.int64, copy=False))


def _read_obj(path, data, owner):
    lines = _text_lines(data, path, owner)
    verts, polys, poly_lines = [], [], []
    for i, line in enumerate(lines):
        if "#" in line:
            line = line.split("#", 1)[0]
        parts = line.split()
        if not parts:
            continue
        tag = parts[0]
        if tag == "v":
            try:
                if len(parts) < 4:
                    raise ValueError
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except ValueError:
                raise ValueError(f"{owner}: {path!r} line {i + 1}: malformed vertex: {line.strip()[:80]!r}") from None
        elif tag == "f":
            if len(parts) < 4:
                raise ValueError(f"{owner}: {path!r} line {i + 1}: a face needs at least 3 vertices: {line.strip()[:80]!r}")
            ids = []
            for tok in parts[1:]:
                try:
                    j = int(tok.split("/", 1)[0])
                except ValueError:
                    raise ValueError(f"{owner}: {path!r} line {i + 1}: malformed face index {tok!r}") from None
                if j == 0:
                    raise ValueError(f"{owner}: {path!r} line {i + 1}: OBJ indices start at 1, got 0")
                # negative indices count back from the latest vertex
                ids.append(j - 1 if j > 0 else len(verts) + j)
            polys.append(ids)
            poly_lines.append(i)
    if not verts:
        raise ValueError(f"{owner}: {path!r} holds no vertices ('v' lines)")
    n_v = len(verts)
    for ids, i in zip(polys, poly_lines):
        if min(ids) < 0 or max(ids) >= n_v:
            raise ValueError(f"{owner}: {path!r} line {i + 1}: face index out of range 1..{n_v}")
    return Mesh(np.array(verts, dtype=np.float64), _fan(polys))


def _read_ply_mesh(path, owner):
    ply = _read_ply_data(path, owner)
    xyz, _ = _ply_vertices(ply, path, owner)
    if "face" not in ply:
        faces = np.empty((0, 3), dtype=np.int64)
    else:
        fdata = ply["face"].data
        name = next((n for n in ("vertex_indices", "vertex_index") if n in (fdata.dtype.names or ())), None)
        if name is None:
            raise ValueError(f"{owner}: {path!r}: PLY 'face' element has no 'vertex_indices' list")
        col = fdata[name]
        if col.dtype != object and col.ndim == 2 and col.shape[1] == 3:
            faces = col.astype(np.int64)
        else:
            polys = [list(np.asarray(p, dtype=np.int64)) for p in col]
            short = [k for k, p in enumerate(polys) if len(p) < 3]
            if short:
                raise ValueError(f"{owner}: {path!r}: PLY face {short[0]} has fewer than 3 vertices")
            faces = _fan(polys)
        if faces.size and (faces.min() < 0 or faces.max() >= xyz.shape[0]):
            k = int(np.flatnonzero((faces < 0).any(1) | (faces >= xyz.shape[0]).any(1))[0])
            raise ValueError(f"{owner}: {path!r}: PLY face index out of range 0..{xyz.shape[0] - 1} (triangle {k})")
    return Mesh(np.ascontiguousarray(xyz), faces)


# --------------------------------------------------------------------------- public API


def read_point_cloud(path, *, format=None, normals="auto", remove_nan=True):
    """Read a point cloud from a file.

    Parameters
    ----------
    path : str or path-like
        The file. Its extension chooses the format unless ``format`` is given:
        ``.pcd``, ``.ply``, ``.xyz``/``.txt``/``.csv``/``.pts``, ``.npy``,
        ``.npz``. Mesh files (``.off``, ``.obj``) are read with
        :func:`read_mesh` and sampled with :func:`eppf.preprocessing.sample_mesh`.
    format : {"pcd", "ply", "xyz", "npy", "npz"}, default=None
        Override the format given by the extension.
    normals : {"auto", True, False}, default="auto"
        Whether to return normals. ``"auto"`` returns them when the file has
        them: PCD fields ``normal_x normal_y normal_z``, PLY properties
        ``nx ny nz``, columns 4 to 6 of a text file when every row there has
        unit length (so that ``x y z r g b`` files are not mistaken), and
        columns 4 to 6 of an array. True requires them; False drops them.
    remove_nan : bool, default=True
        Drop points with a NaN or infinite value (PCL marks invalid points of
        organised clouds with NaN).

    Returns
    -------
    cloud : ndarray of shape (n_points, 3) or (n_points, 6), dtype float64
        Coordinates, followed by the normals when returned.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file is empty, truncated or malformed; the message names the
        file and the line (text) or byte (binary) where reading failed.
    ImportError
        For PLY files when `plyfile` is not installed.

    See Also
    --------
    write_point_cloud : The inverse.
    read_mesh : Read OFF, OBJ and PLY meshes.

    Examples
    --------
    >>> import numpy as np, os, tempfile
    >>> from eppf.io import read_point_cloud, write_point_cloud
    >>> path = os.path.join(tempfile.mkdtemp(), "cloud.xyz")
    >>> write_point_cloud(path, np.eye(3))
    >>> read_point_cloud(path).shape
    (3, 3)
    """
    owner = "read_point_cloud"
    _check_normals_arg(normals, owner)
    path = os.fspath(path)
    fmt = _fmt(path, format, _CLOUD_FORMATS, owner)
    if fmt in ("npy", "npz"):
        if not os.path.exists(path):
            raise FileNotFoundError(f"{owner}: no such file: {path!r}")
        if os.path.getsize(path) == 0:
            raise ValueError(f"{owner}: {path!r} is empty")
        return _read_npy(path, normals, owner, remove_nan, fmt)
    data = _read_bytes(path, owner)
    if fmt == "pcd":
        return _read_pcd(path, data, normals, owner, remove_nan)
    if fmt == "ply":
        xyz, nrm = _ply_vertices(_read_ply_data(path, owner), path, owner)
        return _finish_cloud(xyz, nrm, path, normals, owner, remove_nan)
    return _read_xyz(path, data, normals, owner, remove_nan)


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


def write_point_cloud(path, cloud, *, format=None, binary=True):
    """Write a point cloud to a file.

    Parameters
    ----------
    path : str or path-like
        Destination; its extension chooses the format unless ``format`` is
        given (see :func:`read_point_cloud`).
    cloud : array-like of shape (n_points, 3) or (n_points, 6)
        Coordinates, optionally followed by normals.
    format : {"pcd", "ply", "xyz", "npy", "npz"}, default=None
        Override the format given by the extension.
    binary : bool, default=True
        For PCD and PLY, write binary (little endian) rather than ASCII data.

    Notes
    -----
    PCD and PLY files store float32, as PCL and most scanners do; text files
    keep full float64 precision (17 significant digits), NPY/NPZ are exact.
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
    fmt = _fmt(path, format, _CLOUD_FORMATS, owner)
    cloud = _check_cloud_arg(cloud, owner)
    if fmt == "pcd":
        _write_pcd(path, cloud, binary)
    elif fmt == "ply":
        _write_ply(path, cloud, None, binary, owner)
    elif fmt == "npy":
        with open(path, "wb") as fh:
            np.save(fh, cloud)
    elif fmt == "npz":
        with open(path, "wb") as fh:
            np.savez(fh, points=cloud)
    else:
        _write_xyz(path, cloud, os.path.splitext(path)[1].lower())


def read_mesh(path, *, format=None):
    """Read a triangle mesh from an OFF, OBJ or PLY file.

    Parameters
    ----------
    path : str or path-like
        The file; its extension (``.off``, ``.obj``, ``.ply``) chooses the
        format unless ``format`` is given.
    format : {"off", "obj", "ply"}, default=None
        Override the format given by the extension.

    Returns
    -------
    mesh : Mesh
        ``(vertices, faces)``: float64 (n_vertices, 3) and int64 (n_faces, 3).
        Polygons are split into triangles by a fan from their first vertex.
        OBJ texture and normal indices are ignored.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file is empty, truncated or malformed, or a face refers to a
        missing vertex; the message names the file and the line.

    Notes
    -----
    OFF files of ModelNet often glue the keyword to the counts on the first
    line (``OFF490 518 0``); such files are read as if the counts were on a
    line of their own. ``COFF``/``NOFF`` variants are read (extra vertex
    columns are ignored), and ``#`` comments are skipped.

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
    fmt = _fmt(path, format, _MESH_FORMATS, owner)
    if fmt == "ply":
        if not os.path.exists(path):
            raise FileNotFoundError(f"{owner}: no such file: {path!r}")
        if os.path.getsize(path) == 0:
            raise ValueError(f"{owner}: {path!r} is empty")
        return _read_ply_mesh(path, owner)
    data = _read_bytes(path, owner)
    if fmt == "off":
        return _read_off(path, data, owner)
    return _read_obj(path, data, owner)


def write_mesh(path, vertices, faces, *, format=None, binary=True):
    """Write a triangle mesh to an OFF, OBJ or PLY file.

    Parameters
    ----------
    path : str or path-like
        Destination; its extension chooses the format unless ``format`` is given.
    vertices : array-like of shape (n_vertices, 3)
        Vertex coordinates.
    faces : array-like of shape (n_faces, k)
        Vertex indices (0-based) of each polygon, k >= 3.
    format : {"off", "obj", "ply"}, default=None
        Override the format given by the extension.
    binary : bool, default=True
        For PLY, write binary rather than ASCII data.

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
    fmt = _fmt(path, format, _MESH_FORMATS, owner)
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
    faces = faces.astype(np.int64)
    if fmt == "ply":
        _write_ply(path, vertices, faces, binary, owner)
        return
    with open(path, "w") as fh:
        if fmt == "off":
            fh.write(f"OFF\n{vertices.shape[0]} {faces.shape[0]} 0\n")
            np.savetxt(fh, vertices, fmt="%.17g")
            np.savetxt(fh, np.column_stack([np.full(faces.shape[0], faces.shape[1]), faces]), fmt="%d")
        else:
            np.savetxt(fh, vertices, fmt="v %.17g %.17g %.17g")
            np.savetxt(fh, faces + 1, fmt="f" + " %d" * faces.shape[1])
