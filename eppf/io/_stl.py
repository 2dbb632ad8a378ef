"""STL meshes, binary and ASCII.

A binary STL is an 80-byte header, a little-endian uint32 triangle count
``n`` and ``n`` records of 50 bytes (normal, three vertices as float32, a
uint16 attribute), so its size is exactly ``84 + 50 n``. That size, not a
leading ``solid`` (which many binary exporters write into the header), tells
a binary file from an ASCII one::

    solid name
      facet normal nx ny nz
        outer loop
          vertex x y z
          vertex x y z
          vertex x y z
        endloop
      endfacet
    endsolid name

The stored facet normals are ignored (eppf orients faces by their winding,
as STL's right-hand rule does). Vertices shared by several triangles are
merged (exact duplicates only), so the mesh has one vertex per position.
"""

import struct

import numpy as np

from ._common import Mesh, fan
from ._errors import FileFormatError

_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


def _merge(corners):
    """One vertex per distinct corner position (sorted), and the triangles' indices into them."""
    order = np.lexsort((corners[:, 2], corners[:, 1], corners[:, 0]))
    ordered = corners[order]
    first = np.ones(len(ordered), dtype=bool)
    first[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    inverse = np.empty(len(corners), dtype=np.int64)
    inverse[order] = np.cumsum(first) - 1
    return Mesh(np.ascontiguousarray(ordered[first]), inverse.reshape(-1, 3))


def read_stl(path, data, owner):
    if len(data) >= 84:
        (n,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * n == len(data):
            if n == 0:  # a mesh of nothing, as a PLY file of no vertices is
                return Mesh(np.empty((0, 3)), np.empty((0, 3), dtype=np.int64))
            rec = np.frombuffer(data, dtype=_RECORD, count=n, offset=84)
            with np.errstate(invalid="ignore"):
                corners = rec["vertices"].reshape(-1, 3).astype(np.float64)
            bad = np.flatnonzero(~np.isfinite(corners).all(axis=1))
            if bad.size:
                k = int(bad[0]) // 3
                raise FileFormatError(f"{owner}: {path!r} byte {84 + 50 * k}: triangle {k} has a non-finite vertex")
            return _merge(corners)
    if data.lstrip()[:5].lower() != b"solid":
        binary = f"{len(data)} bytes, not 84 + 50 x {n} for the count at byte 80" if len(data) >= 84 \
            else f"{len(data)} bytes, less than the 84 of a binary header"
        raise FileFormatError(
            f"{owner}: {path!r} is neither an ASCII STL (it does not start with 'solid') "
            f"nor a binary one ({binary})"
        )
    return _read_ascii(path, data, owner)


def _read_ascii(path, data, owner):
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        raise FileFormatError(
            f"{owner}: {path!r} byte {exc.start}: not an ASCII STL (non-ASCII byte), and its size "
            f"{len(data)} is not that of a binary STL"
        ) from None
    corners, loop_start, facets = [], 0, 0
    state = "top"  # top, facet, loop
    for i, line in enumerate(text.splitlines()):
        parts = line.split()
        if not parts:
            continue
        kw = parts[0].lower()
        where = f"{owner}: {path!r} line {i + 1}"
        if kw == "solid" and state == "top":
            continue
        if kw == "endsolid" and state == "top":
            continue
        if kw == "facet" and state == "top":
            state = "facet"
        elif kw == "outer" and state == "facet":
            state, loop_start = "loop", len(corners)
        elif kw == "vertex" and state == "loop":
            if len(parts) != 4:
                raise FileFormatError(f"{where}: a vertex needs 3 coordinates: {line.strip()[:80]!r}")
            try:
                corners.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except ValueError:
                raise FileFormatError(f"{where}: malformed vertex: {line.strip()[:80]!r}") from None
        elif kw == "endloop" and state == "loop":
            if len(corners) - loop_start != 3:
                raise FileFormatError(f"{where}: a facet needs 3 vertices, got {len(corners) - loop_start}")
            state = "endloop"
        elif kw == "endfacet" and state == "endloop":
            state = "top"
            facets += 1
        else:
            raise FileFormatError(f"{where}: unexpected {parts[0][:20]!r} (inside {state!r})")
    if state != "top":
        raise FileFormatError(f"{owner}: {path!r}: file ends inside a facet (truncated)")
    if not facets:  # a mesh of nothing, as a PLY file of no vertices is
        return Mesh(np.empty((0, 3)), np.empty((0, 3), dtype=np.int64))
    corners = np.array(corners, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(corners).all(axis=1))
    if bad.size:
        raise FileFormatError(f"{owner}: {path!r}: triangle {int(bad[0]) // 3} has a non-finite vertex")
    return _merge(corners)


def write_stl(path, vertices, faces, binary=True):
    """STL stores triangles: polygons are split by fans from their first vertex."""
    if faces.shape[1] > 3:
        faces = fan(faces.tolist())
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    if binary:
        rec = np.zeros(len(faces), dtype=_RECORD)
        rec["normal"] = normal
        rec["vertices"] = tri
        with open(path, "wb") as fh:
            fh.write(b"binary STL written by eppf".ljust(80, b" "))
            fh.write(struct.pack("<I", len(faces)))
            fh.write(rec.tobytes())
        return
    with open(path, "w") as fh:
        fh.write("solid eppf\n")
        for nrm, (a, b, c) in zip(normal, tri):
            fh.write(f"  facet normal {nrm[0]:.9g} {nrm[1]:.9g} {nrm[2]:.9g}\n    outer loop\n")
            for p in (a, b, c):
                fh.write(f"      vertex {p[0]:.17g} {p[1]:.17g} {p[2]:.17g}\n")
            fh.write("    endloop\n  endfacet\n")
        fh.write("endsolid eppf\n")
