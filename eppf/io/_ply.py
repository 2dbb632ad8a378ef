"""PLY (Stanford) point clouds and meshes, read and written without plyfile.

Formats ``ascii 1.0``, ``binary_little_endian 1.0`` and
``binary_big_endian 1.0``; any elements and scalar properties of the PLY
types (``char uchar short ushort int uint float double`` and their
``int8 ... float64`` aliases) and list properties (``property list uchar int
vertex_indices``). The ``vertex`` element gives the cloud (``x y z`` and
``nx ny nz`` or ``normal_x normal_y normal_z``), the ``face`` element's
``vertex_indices`` (or ``vertex_index``) list the mesh; other elements are
read past.

Every element count is checked against the rest of the file before anything
is allocated: in binary data a row takes at least the sum of its scalar sizes
and list-count sizes, in ASCII data at least one token per property.
"""

import struct

import numpy as np

from ._common import Cloud, float_code, widened
from ._errors import FileFormatError

try:  # compiled token parser for ASCII bodies; NumPy's string conversion otherwise
    from ._xyz_fast import parse_tokens as _parse_tokens
except ImportError:  # pragma: no cover - an uncompiled checkout
    _parse_tokens = None

_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
          "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
          "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f", "f8": "d"}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}


class _Prop:
    __slots__ = ("name", "code", "count_code")

    def __init__(self, name, code, count_code=None):
        self.name, self.code, self.count_code = name, code, count_code


#: Parsed headers by their bytes: a folder of files written by one program repeats one header, parsed once.
_HEADERS = {}
_HEADERS_MAX, _HEADER_BYTES_MAX = 64, 4096


def _header(data, path, owner):
    """(format, elements, body offset); elements are [name, count, [props], line].

    A header parsed before (the same bytes up to and including its
    ``end_header`` line) is taken from a small cache: parsing reads nothing
    past that line, so equal bytes give an equal result. Only headers that
    parsed without error are kept, so every error is raised as before.
    """
    i = data.find(b"end_header", 0, _HEADER_BYTES_MAX)
    if i >= 0:
        j = data.find(b"\n", i)
        hit = _HEADERS.get(data[:j + 1]) if j >= 0 else None
        if hit is not None:
            return hit
    parsed = _parse_header(data, path, owner)
    pos = parsed[2]
    if pos <= _HEADER_BYTES_MAX:
        if len(_HEADERS) >= _HEADERS_MAX:
            _HEADERS.clear()
        _HEADERS[data[:pos]] = parsed
    return parsed


def _parse_header(data, path, owner):
    """:func:`_header` without the cache."""
    if not data.startswith(b"ply"):
        raise FileFormatError(f"{owner}: {path!r} line 1: malformed PLY header (expected the magic 'ply')")
    pos, lineno, fmt, elements = 0, 0, None, []
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            raise FileFormatError(f"{owner}: {path!r} line {lineno + 1}: malformed PLY header (no 'end_header' line)")
        try:
            line = data[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise FileFormatError(f"{owner}: {path!r} line {lineno + 1}: malformed PLY header (non-ASCII bytes)") from None
        pos, lineno = end + 1, lineno + 1
        parts = line.split()
        where = f"{owner}: {path!r} line {lineno}: malformed PLY header"
        if lineno == 1:
            if parts != ["ply"]:
                raise FileFormatError(f"{where} (expected the magic 'ply', got {line[:40]!r})")
            continue
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        key = parts[0]
        if key == "format":
            if len(parts) != 3 or parts[1] not in _FORMATS or parts[2] != "1.0":
                raise FileFormatError(f"{where} (unsupported format line {line[:60]!r})")
            fmt = parts[1]
        elif key == "element":
            try:
                if len(parts) != 3:
                    raise ValueError
                count = int(parts[2])
            except ValueError:
                raise FileFormatError(f"{where} (expected 'element <name> <count>', got {line[:60]!r})") from None
            if count < 0:
                raise FileFormatError(f"{where} (negative count in {line[:60]!r})")
            elements.append([parts[1], count, [], lineno])
        elif key == "property":
            if not elements:
                raise FileFormatError(f"{where} (a property before any element)")
            if len(parts) == 3 and parts[1] in _TYPES:
                prop = _Prop(parts[2], _TYPES[parts[1]])
            elif len(parts) == 5 and parts[1] == "list" and parts[2] in _TYPES and parts[3] in _TYPES \
                    and _TYPES[parts[2]][0] in "iu":
                prop = _Prop(parts[4], _TYPES[parts[3]], _TYPES[parts[2]])
            else:
                raise FileFormatError(f"{where} (unsupported property line {line[:60]!r})")
            if any(p.name == prop.name for p in elements[-1][2]):
                raise FileFormatError(f"{where} (property {prop.name!r} appears twice)")
            elements[-1][2].append(prop)
        elif key == "end_header":
            if fmt is None:
                raise FileFormatError(f"{where} (no 'format' line)")
            return fmt, elements, pos
        else:
            raise FileFormatError(f"{where} (unknown keyword {key[:20]!r})")


def _read_binary(data, pos, elements, endian, path, owner, keep):
    out = {}
    for name, count, props, line in elements:
        scalars = [p for p in props if p.count_code is None]
        lists = [p for p in props if p.count_code is not None]
        least = sum(np.dtype(p.code).itemsize for p in scalars) + sum(np.dtype(p.count_code).itemsize for p in lists)
        left = len(data) - pos
        if count * least > left:
            raise FileFormatError(
                f"{owner}: {path!r} byte {pos}: malformed PLY element {name!r}, row {left // least if least else 0}: "
                f"the header (line {line}) declares {count} rows of at least {least} bytes "
                f"({count * least} bytes), but the file has {left} bytes left (truncated, or a wrong count)"
            )
        if count == 0 or not props:
            out[name] = {}
            continue
        if not lists:
            dtype = np.dtype([(p.name, endian + p.code) for p in props])
            rec = np.frombuffer(data, dtype=dtype, count=count, offset=pos)
            pos += count * dtype.itemsize
            out[name] = {p.name: rec[p.name] for p in props} if name in keep else {}
            continue
        # lists: first try rows that all have the first row's list lengths
        fixed, off = [], pos
        for p in props:
            if p.count_code is None:
                fixed.append((p.name, endian + p.code))
                off += np.dtype(p.code).itemsize
            else:
                (n,) = struct.unpack_from(endian + _STRUCT[p.count_code], data, off)
                if n < 0 or n > left:
                    break
                fixed += [("_n_" + p.name, endian + p.count_code), (p.name, endian + p.code, (n,))]
                off += np.dtype(p.count_code).itemsize + n * np.dtype(p.code).itemsize
        else:
            dtype = np.dtype(fixed)
            if count * dtype.itemsize <= left:
                rec = np.frombuffer(data, dtype=dtype, count=count, offset=pos)
                if all(np.all(rec["_n_" + p.name] == rec["_n_" + p.name][0]) for p in lists):
                    pos += count * dtype.itemsize
                    out[name] = {p.name: rec[p.name] for p in props} if name in keep else {}
                    continue
        # general rows, one at a time
        cols = {p.name: [] for p in props}
        store = name in keep
        formats = [(p, endian + _STRUCT[p.code], np.dtype(p.code).itemsize,
                    None if p.count_code is None else endian + _STRUCT[p.count_code],
                    0 if p.count_code is None else np.dtype(p.count_code).itemsize) for p in props]
        for row in range(count):
            for p, code, size, ccode, csize in formats:
                if ccode is None:
                    if pos + size > len(data):
                        raise FileFormatError(f"{owner}: {path!r} byte {pos}: malformed PLY element {name!r}, row {row}: "
                                              f"file ends (truncated)")
                    if store:
                        cols[p.name].append(struct.unpack_from(code, data, pos)[0])
                    pos += size
                    continue
                if pos + csize > len(data):
                    raise FileFormatError(f"{owner}: {path!r} byte {pos}: malformed PLY element {name!r}, row {row}: "
                                          f"file ends (truncated)")
                (n,) = struct.unpack_from(ccode, data, pos)
                pos += csize
                if n < 0 or pos + n * size > len(data):
                    raise FileFormatError(
                        f"{owner}: {path!r} byte {pos - csize}: malformed PLY element {name!r}, row {row}: "
                        f"list {p.name!r} of {n} items does not fit the {len(data) - pos} bytes left"
                    )
                if store:
                    cols[p.name].append(struct.unpack_from(f"{endian}{n}{_STRUCT[p.code]}", data, pos))
                pos += n * size
        out[name] = cols if store else {}
    return out


def _ascii_values(data, pos, path, owner):
    """Every number of an ASCII body as float64 (one float per token, no list of strings when compiled)."""
    if _parse_tokens is not None:
        values, bad = _parse_tokens(data, pos)
        if values is not None:
            return values
        token = (data[bad:bad + 40].split() or [data[bad:bad + 1]])[0].decode("ascii", "replace")
        line = data.count(b"\n", 0, bad) + 1
        raise FileFormatError(f"{owner}: {path!r} line {line}: malformed number {token!r} in PLY data")
    try:
        body = data[pos:].decode("ascii")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{owner}: {path!r} byte {pos + exc.start}: non-ASCII byte in ASCII PLY data") from None
    tokens = body.split()
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        k = next(k for k, t in enumerate(tokens) if not _is_number(t))
        line = data[:pos].count(b"\n") + body[:body.find(tokens[k])].count("\n") + 1
        raise FileFormatError(f"{owner}: {path!r} line {line}: malformed number {tokens[k][:40]!r} in PLY data") from None


def _read_ascii(data, pos, elements, path, owner, keep):
    values = _ascii_values(data, pos, path, owner)
    out, t = {}, 0
    for name, count, props, line in elements:
        left = values.size - t
        least = len(props)
        if count * least > left:
            raise FileFormatError(
                f"{owner}: {path!r}: malformed PLY element {name!r}, row {left // least if least else 0}: "
                f"the header (line {line}) declares {count} rows of at least {least} values, "
                f"but the file holds {left} more values (truncated, or a wrong count)"
            )
        if count == 0 or not props:
            out[name] = {}
            continue
        store = name in keep
        lists = [k for k, p in enumerate(props) if p.count_code is not None]
        if not lists:
            block = values[t:t + count * least].reshape(count, least)
            t += count * least
            out[name] = {p.name: block[:, k] for k, p in enumerate(props)} if store else {}
            continue
        # rows that all have the first row's list lengths, else one row at a time
        widths, u = [], t
        for p in props:
            if p.count_code is None:
                widths.append(1)
                u += 1
            else:
                n = values[u] if u < values.size else -1
                if not (0 <= n <= left) or n != int(n):
                    break
                widths += [1, int(n)]
                u += 1 + int(n)
        else:
            width = sum(widths)
            if count * width <= left:
                block = values[t:t + count * width].reshape(count, width)
                col, starts = 0, []
                for p in props:
                    if p.count_code is None:
                        starts.append((p, col, None))
                        col += 1
                    else:
                        n = int(block[0, col])
                        starts.append((p, col + 1, n))
                        col += 1 + n
                if all(np.all(block[:, s - 1] == n) for p, s, n in starts if n is not None):
                    t += count * width
                    out[name] = {p.name: (block[:, s] if n is None else block[:, s:s + n])
                                 for p, s, n in starts} if store else {}
                    continue
        cols = {p.name: [] for p in props}
        vals = values
        for row in range(count):
            for p in props:
                if t >= vals.size:
                    raise FileFormatError(f"{owner}: {path!r}: malformed PLY element {name!r}, row {row}: "
                                          "file ends (truncated)")
                if p.count_code is None:
                    if store:
                        cols[p.name].append(vals[t])
                    t += 1
                    continue
                n = vals[t]
                if not (0 <= n <= vals.size - t - 1) or n != int(n):
                    raise FileFormatError(
                        f"{owner}: {path!r}: malformed PLY element {name!r}, row {row}: list {p.name!r} "
                        f"has a bad length {n!r} ({vals.size - t - 1} values left)"
                    )
                n = int(n)
                if store:
                    cols[p.name].append(vals[t + 1:t + 1 + n])
                t += 1 + n
        out[name] = cols if store else {}
    return out


def _is_number(token):
    try:
        float(token)
        return True
    except ValueError:
        return False


def _column(values, code, copy=True):
    """Values of one scalar property as float64, rounded through its declared type.

    With ``copy=False`` a binary float column comes back as it is (float32 or
    float64), for the caller to widen while copying it into place.
    """
    arr = np.asarray(values)
    if arr.dtype == np.float64 and code == "f8":
        return arr
    if arr.dtype == np.float32 and code == "f4":  # binary float columns: the exact widening, nothing to round
        return widened(arr) if copy else arr
    with np.errstate(over="ignore", invalid="ignore"):  # out-of-range values become inf, as in C
        if code in ("f4",) and arr.dtype != np.float32:
            arr = arr.astype(np.float32)
        return np.asarray(arr, dtype=np.float64)


#: Vertex properties of the plain layout :func:`_plain_vertices` reads in one call.
_PLAIN_NAMES = (("x", "y", "z"), ("x", "y", "z", "nx", "ny", "nz"),
                ("x", "y", "z", "normal_x", "normal_y", "normal_z"))


def _plain_vertices(data, fmt, elements, pos):
    """The Cloud of a binary file whose only element is ``vertex`` with the scalar properties ``x y z`` (and
    normals), all ``float`` or all ``double``: one float64 block from a single conversion, or None for any
    other layout (read by the general path) and for a body too short for the header's count (whose error the
    general path words). The values are those of the general path, bit for bit: the same bytes, widened
    exactly from float32 or taken as they are."""
    if fmt == "ascii" or len(elements) != 1:
        return None
    name, count, props, _ = elements[0]
    if name != "vertex" or count == 0 or tuple(p.name for p in props) not in _PLAIN_NAMES:
        return None
    code = props[0].code
    if code not in ("f4", "f8") or any(p.code != code or p.count_code is not None for p in props):
        return None
    width = len(props)
    if count * width * int(code[1]) > len(data) - pos:
        return None
    values = np.frombuffer(data, dtype=_FORMATS[fmt] + code, count=count * width, offset=pos)
    full = widened(values.reshape(count, width))  # (a new C-ordered block: what _finish_cloud keeps)
    return Cloud(full[:, :3], full[:, 3:] if width == 6 else None)


def read_ply(path, data, owner, want_faces=True):
    """(Cloud of the vertices, faces as an int64 (n, 3) array or None without a 'face' element)."""
    fmt, elements, pos = _header(data, path, owner)
    block = _plain_vertices(data, fmt, elements, pos)
    if block is not None:
        return block, None
    keep = {"vertex", "face"} if want_faces else {"vertex"}
    if fmt == "ascii":
        out = _read_ascii(data, pos, elements, path, owner, keep)
    else:
        out = _read_binary(data, pos, elements, _FORMATS[fmt], path, owner, keep)
    spec = {name: (count, {p.name: p for p in props}) for name, count, props, _ in elements}
    if "vertex" not in spec:
        raise FileFormatError(f"{owner}: {path!r}: PLY file has no 'vertex' element")
    n_v, vprops = spec["vertex"]
    missing = [f for f in "xyz" if f not in vprops or vprops[f].count_code is not None]
    if missing:
        raise FileFormatError(f"{owner}: {path!r}: PLY 'vertex' element lacks {missing}; it has {list(vprops)}")
    v = out["vertex"]
    normal_names = ()
    for names in (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z")):
        if n_v and all(f in vprops and vprops[f].count_code is None for f in names):
            normal_names = names
            break
    # one float64 block: xyz in columns 0-2, normals (when there are) in 3-5, each column copied once
    full = np.empty((n_v, 3 + len(normal_names)))
    for j, f in enumerate(("x", "y", "z") + normal_names):
        if n_v:
            with np.errstate(invalid="ignore"):  # float32 widened in place (a signaling NaN: see widened)
                full[:, j] = _column(v[f], vprops[f].code, copy=False)
    cloud = Cloud(full[:, :3], full[:, 3:] if normal_names else None)
    if not want_faces or "face" not in spec:
        return cloud, None
    n_f, fprops = spec["face"]
    if n_f == 0:  # (PCL writes every cloud with an "element face 0" of no properties)
        return cloud, np.empty((0, 3), dtype=np.int64)
    name = next((n for n in ("vertex_indices", "vertex_index") if n in fprops), None)
    if name is None or fprops[name].count_code is None:
        raise FileFormatError(f"{owner}: {path!r}: PLY 'face' element has no 'vertex_indices' list")
    col = out["face"][name]
    if isinstance(col, np.ndarray) and col.ndim == 2 and col.shape[1] == 3:
        tri = np.asarray(col, dtype=np.float64)
        rows = np.arange(n_f)
    else:
        polys = [np.asarray(p, dtype=np.float64) for p in col]
        short = [k for k, p in enumerate(polys) if len(p) < 3]
        if short:
            raise FileFormatError(f"{owner}: {path!r}: PLY face {short[0]} has fewer than 3 vertices")
        rows = np.repeat(np.arange(n_f), [len(p) - 2 for p in polys])
        tri = np.array([(p[0], p[k], p[k + 1]) for p in polys for k in range(1, len(p) - 1)], dtype=np.float64)
    ok = (tri >= 0) & (tri < n_v) & (tri == np.floor(tri))
    bad = np.flatnonzero(~ok.all(axis=1))
    if bad.size:
        raise FileFormatError(
            f"{owner}: {path!r}: PLY face {int(rows[bad[0]])} has a vertex index outside 0..{n_v - 1}"
        )
    return cloud, tri.astype(np.int64)


def _header_text(binary, elements):
    lines = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "comment written by eppf"]
    for name, count, props in elements:
        lines.append(f"element {name} {count}")
        lines += [f"property {p}" for p in props]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


def write_ply(path, cloud, faces=None, binary=True):
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if cloud.shape[1] == 6 else [])
    code = float_code(cloud)
    elements = [("vertex", cloud.shape[0], [f"{'float' if code == 'f4' else 'double'} {n}" for n in names])]
    vert = np.ascontiguousarray(cloud, dtype="<" + code)
    if faces is not None:
        k = faces.shape[1]
        count_type = "uchar" if k <= 255 else "int"
        elements.append(("face", faces.shape[0], [f"list {count_type} int vertex_indices"]))
        frec = np.empty(faces.shape[0], dtype=[("n", "u1" if k <= 255 else "<i4"), ("v", "<i4", (k,))])
        frec["n"] = k
        frec["v"] = faces
    with open(path, "wb") as fh:
        fh.write(_header_text(binary, elements))
        if binary:
            fh.write(vert.tobytes())
            if faces is not None:
                fh.write(frec.tobytes())
        else:
            np.savetxt(fh, vert, fmt="%.9g" if code == "f4" else "%.17g")
            if faces is not None:
                np.savetxt(fh, np.column_stack([np.full(faces.shape[0], k), faces]), fmt="%d")


# --------------------------------------------------------------------------- every field

_PLY_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
              "f4": "float", "f8": "double"}


def _typed(values, code, name, path, owner):
    """One vertex property's values as an array of its declared type: (n,) or (n, k) for a list of one length."""
    if isinstance(values, np.ndarray):
        with np.errstate(invalid="ignore", over="ignore"):
            return np.ascontiguousarray(values, dtype=np.dtype(code))
    lengths = {len(v) for v in values} if values and not np.isscalar(values[0]) else None
    if lengths is not None and len(lengths) > 1:
        raise FileFormatError(f"{owner}: {path!r}: PLY vertex list property {name!r} has rows of different lengths "
                              f"({min(lengths)} to {max(lengths)}); only lists of one length are read as a field")
    with np.errstate(invalid="ignore", over="ignore"):
        return np.ascontiguousarray(np.array(values, dtype=np.float64 if code[0] == "f" else None), dtype=np.dtype(code))


def read_ply_fields(path, data, owner):
    """(points, fields): x y z as float64 and every other ``vertex`` property in its declared type, in file order."""
    fmt, elements, pos = _header(data, path, owner)
    if fmt == "ascii":
        out = _read_ascii(data, pos, elements, path, owner, {"vertex"})
    else:
        out = _read_binary(data, pos, elements, _FORMATS[fmt], path, owner, {"vertex"})
    spec = {name: (count, props) for name, count, props, _ in elements}
    if "vertex" not in spec:
        raise FileFormatError(f"{owner}: {path!r}: PLY file has no 'vertex' element")
    n_v, props = spec["vertex"]
    by_name = {p.name: p for p in props}
    missing = [f for f in "xyz" if f not in by_name or by_name[f].count_code is not None]
    if missing:
        raise FileFormatError(f"{owner}: {path!r}: PLY 'vertex' element lacks {missing}; it has {list(by_name)}")
    columns = out["vertex"]
    points = np.empty((n_v, 3))
    fields = {}
    for p in props:
        values = columns.get(p.name, []) if n_v else np.empty((0,), dtype=p.code)
        if p.name in ("x", "y", "z"):
            points[:, "xyz".index(p.name)] = _column(values, p.code) if n_v else 0
            continue
        fields[p.name] = _typed(values, p.code, p.name, path, owner)
    return points, fields


def write_ply_fields(path, points, fields, coord):
    """A binary little-endian PLY: one ``vertex`` element, x y z as ``coord`` (``"f4"`` or ``"f8"``), then every
    field as a scalar property, or a list property of one length for an (n, k) field."""
    props = [f"{_PLY_NAMES[coord]} {axis}" for axis in "xyz"]
    spec = [(axis, "<" + coord) for axis in "xyz"]
    for name, values in fields.items():
        code = values.dtype.str[1:]
        if values.ndim == 1:
            props.append(f"{_PLY_NAMES[code]} {name}")
            spec.append((name, "<" + code))
        else:
            k = values.shape[1]
            count_type = "uchar" if k <= 255 else "int"
            props.append(f"list {count_type} {_PLY_NAMES[code]} {name}")
            spec += [("_n_" + name, "u1" if k <= 255 else "<i4"), (name, "<" + code, (k,))]
    rec = np.empty(points.shape[0], dtype=np.dtype(spec))
    for k, axis in enumerate("xyz"):
        rec[axis] = points[:, k]
    for name, values in fields.items():
        if values.ndim == 2:
            rec["_n_" + name] = values.shape[1]
        rec[name] = values
    with open(path, "wb") as fh:
        fh.write(_header_text(True, [("vertex", points.shape[0], props)]))
        fh.write(rec.tobytes())
