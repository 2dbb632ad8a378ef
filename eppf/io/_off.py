"""OFF meshes (Princeton/ModelNet), including ModelNet's malformed first line
where ``OFF`` is glued to the counts (``OFF490 518 0``), ``COFF``/``NOFF``
variants (extra vertex columns ignored), Geomview's ``4OFF`` (homogeneous
vertices ``x y z w``, divided by ``w``), ``#`` comments and polygons. Binary
OFF (``OFF BINARY``) and n-dimensional ``nOFF`` files are refused, naming
the variant.

Three readers, fastest first, each giving up (None) on what it does not
handle: a compiled parser of the plain all-triangle body, a vectorized NumPy
one, and the line-by-line reader that reads everything else or names the line
at fault. The counts are checked against the file's size before the compiled
parser allocates: a vertex line takes at least 6 bytes (``0 0 0`` and a line
break) and a triangle line at least 8.
"""

import numpy as np

from ._common import Mesh, content, fan, next_line, parse_float_rows, text_lines
from ._errors import FileFormatError

try:  # compiled parser for plain OFF bodies
    from ._off_fast import parse_off_body as _parse_off_body
except ImportError:  # pragma: no cover - an uncompiled checkout
    _parse_off_body = None

_VERTEX_BYTES, _FACE_BYTES = 6, 8


def _fits(n_v, n_f, available):
    return n_v >= 0 and n_f >= 0 and _VERTEX_BYTES * n_v + _FACE_BYTES * n_f <= available + 1


def _read_off_compiled(data):
    """Header in Python, body in C; None for anything but a plain OFF file."""
    if _parse_off_body is None or b"#" in data:
        return None
    first, pos = next_line(data, 0)
    if first is None or not first.startswith(b"OFF"):
        return None
    tokens = first.split()
    if tokens[0] == b"OFF" and len(tokens) == 1:
        counts, pos = next_line(data, pos)
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
    if n_v <= 0 or not _fits(n_v, n_f, len(data) - pos):
        return None  # the line-by-line reader reports the counts
    parsed = _parse_off_body(data, pos, n_v, n_f)
    if parsed is None:
        return None
    verts, faces, end = parsed
    if data[end:].strip() or (n_f and (faces.min() < 0 or faces.max() >= n_v)) or not np.isfinite(verts).all():
        return None  # the line-by-line reader names the line
    return Mesh(verts, faces)


def _read_off_fast(text):
    """Vectorized reader for the common OFF file: no comments, triangles only.

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
    if verts.size != 3 * n_v or not np.isfinite(verts).all():
        return None
    if n_f == 0:
        return Mesh(verts.reshape(n_v, 3), np.empty((0, 3), dtype=np.int64))
    if set(map(len, map(str.split, flines))) != {4}:
        return None
    try:
        ints = np.fromstring(" ".join(flines), dtype=np.int64, sep=" ")
    except (ValueError, OverflowError):
        return None
    if ints.size != 4 * n_f:
        return None
    quad = ints.reshape(n_f, 4)
    faces = quad[:, 1:]
    if np.any(quad[:, 0] != 3) or faces.min() < 0 or faces.max() >= n_v:
        return None
    return Mesh(verts.reshape(n_v, 3), np.ascontiguousarray(faces))


def _check_variant(path, data, owner):
    """Refuse the Geomview OFF variants this reader cannot read, naming them, before the text is decoded."""
    first, pos = next_line(data, 0)
    tokens = (first or b"").split(b"#", 1)[0].split()
    if not tokens:
        return
    line = data[:pos].rstrip(b"\n").count(b"\n") + 1
    kw = tokens[0].rstrip(b"0123456789.-+")
    if not kw.upper().endswith(b"OFF"):
        return
    if len(tokens) > 1 and tokens[1].upper() == b"BINARY":
        raise FileFormatError(f"{owner}: {path!r} line {line}: a binary OFF file ({first[:40].decode('ascii', 'replace')!r}); "
                              "eppf reads text OFF only")
    if b"n" in kw[:-3]:
        raise FileFormatError(f"{owner}: {path!r} line {line}: an OFF file of n-dimensional vertices "
                              f"({kw.decode('ascii', 'replace')!r}); eppf reads 3D vertices only")


def read_off(path, data, owner):
    _check_variant(path, data, owner)
    mesh = _read_off_compiled(data)
    if mesh is not None:
        return mesh
    try:
        mesh = _read_off_fast(data.decode("ascii"))
    except (UnicodeDecodeError, ValueError, OverflowError):
        mesh = None
    if mesh is not None:
        return mesh
    return _read_off_lines(path, data, owner)


def _read_off_lines(path, data, owner):
    lines = text_lines(data, path, owner)
    idx, rows = content(lines)
    if not rows:
        raise FileFormatError(f"{owner}: {path!r} is empty")
    first = rows[0]
    head = first.split()[0] if first.split() else ""
    # ModelNet ships files whose first line is e.g. "OFF490 518 0": keyword glued to the counts
    kw = head.rstrip("0123456789.-+")
    if not kw.upper().endswith("OFF") or kw.upper().lstrip("STCN4") != "OFF":
        raise FileFormatError(f"{owner}: {path!r} line {idx[0] + 1}: expected an 'OFF' header, got {first[:40]!r}")
    rest = first[len(kw):].strip()
    if rest:
        count_line, count_k = rest, 0
        body_start = 1
    else:
        if len(rows) < 2:
            raise FileFormatError(f"{owner}: {path!r} line {idx[0] + 1}: file ends after the OFF keyword, before the counts")
        count_line, count_k = rows[1], 1
        body_start = 2
    try:
        counts = [int(t) for t in count_line.split()]
        if len(counts) < 2 or counts[0] < 0 or counts[1] < 0:
            raise ValueError
    except ValueError:
        raise FileFormatError(
            f"{owner}: {path!r} line {idx[count_k] + 1}: expected the counts 'n_vertices n_faces n_edges', "
            f"got {count_line[:60]!r}"
        ) from None
    n_v, n_f = counts[0], counts[1]
    if n_v == 0 and n_f == 0:
        # a mesh of nothing, as a PLY file of no vertices is: read_mesh gives it, read_point_cloud says it holds
        # no points (lines after the counts are ignored, as lines after the faces of any OFF file are)
        return Mesh(np.empty((0, 3)), np.empty((0, 3), dtype=np.int64))
    if n_v == 0:  # (faces of no vertices)
        raise FileFormatError(f"{owner}: {path!r} line {idx[count_k] + 1}: the mesh has no vertices")
    avail = len(rows) - body_start
    if avail < n_v + n_f:
        got_v = min(avail, n_v)
        got_f = max(0, avail - n_v)
        last = idx[-1] + 1
        what = f"{got_v} of {n_v} vertices" if got_v < n_v else f"{got_f} of {n_f} faces"
        raise FileFormatError(f"{owner}: {path!r} line {last}: file ends after {what} (truncated)")
    vrows = rows[body_start:body_start + n_v]
    vidx = idx[body_start:body_start + n_v]
    verts = parse_float_rows(vrows, vidx, path, owner, "vertex")
    if verts.shape[1] < 3:
        raise FileFormatError(f"{owner}: {path!r} line {vidx[0] + 1}: a vertex needs 3 coordinates, got {verts.shape[1]}")
    if "4" in kw[:-3]:  # Geomview's 4OFF: homogeneous vertices x y z w, the point is (x, y, z) / w
        if verts.shape[1] < 4:
            raise FileFormatError(f"{owner}: {path!r} line {vidx[0] + 1}: a {kw} vertex needs 4 coordinates "
                                  f"(x y z w), got {verts.shape[1]}")
        w = verts[:, 3:4]
        at_infinity = np.flatnonzero(w[:, 0] == 0)
        if at_infinity.size:
            k = int(at_infinity[0])
            raise FileFormatError(f"{owner}: {path!r} line {vidx[k] + 1}: vertex {k} has w = 0 (a point at "
                                  f"infinity): {vrows[k][:80]!r}")
        with np.errstate(over="ignore"):  # (a quotient beyond float64's range is refused as not finite below)
            verts = verts[:, :3] / w
    verts = np.ascontiguousarray(verts[:, :3])
    bad = np.flatnonzero(~np.isfinite(verts).all(axis=1))
    if bad.size:
        k = int(bad[0])
        raise FileFormatError(f"{owner}: {path!r} line {vidx[k] + 1}: vertex {k} is not finite: {vrows[k][:80]!r}")
    frows = rows[body_start + n_v:body_start + n_v + n_f]
    fidx = idx[body_start + n_v:body_start + n_v + n_f]
    faces = None
    if n_f:
        try:
            flat = np.array(" ".join(frows).split(), dtype=np.int64)
        except (ValueError, OverflowError):
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
                    ids = [int(t) for t in parts[1:1 + m]] if 3 <= m <= len(parts) else []
                except ValueError:
                    raise FileFormatError(f"{owner}: {path!r} line {fidx[k] + 1}: malformed face: {row[:80]!r}") from None
                if m < 3 or len(ids) != m:
                    raise FileFormatError(
                        f"{owner}: {path!r} line {fidx[k] + 1}: a face needs at least 3 vertex indices "
                        f"and as many as its count says: {row[:80]!r}"
                    )
                if min(ids) < 0 or max(ids) >= n_v:
                    raise FileFormatError(
                        f"{owner}: {path!r} line {fidx[k] + 1}: face index out of range 0..{n_v - 1}: {row[:80]!r}"
                    )
                polys.append(ids)
            faces = fan(polys)
        bad = np.flatnonzero((faces < 0).any(axis=1) | (faces >= n_v).any(axis=1))
        if bad.size:
            k = int(bad[0])
            raise FileFormatError(
                f"{owner}: {path!r} line {fidx[k] + 1}: face index out of range 0..{n_v - 1}: {frows[k][:80]!r}"
            )
    else:
        faces = np.empty((0, 3), dtype=np.int64)
    return Mesh(verts, faces.astype(np.int64, copy=False))


def write_off(path, vertices, faces, binary=True):
    with open(path, "w") as fh:
        fh.write(f"OFF\n{vertices.shape[0]} {faces.shape[0]} 0\n")
        np.savetxt(fh, vertices, fmt="%.17g")
        np.savetxt(fh, np.column_stack([np.full(faces.shape[0], faces.shape[1]), faces]), fmt="%d")
