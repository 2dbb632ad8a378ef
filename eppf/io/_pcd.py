"""PCL's PCD format: ``DATA ascii``, ``binary`` and ``binary_compressed``.

Every count is checked against the file before anything is allocated:
``POINTS`` (or ``WIDTH`` x ``HEIGHT``) times the record size must fit the
binary body; an ASCII body must have a line per point; a compressed block's
declared size must be one LZF can reach from its compressed size (LZF writes
at most 88 bytes per input byte, see :mod:`eppf.io._pcd_fast`).

As PCL reads them, header entries may be separated by tabs, ``COLUMNS``
names the fields of PCD v.5 files, and ASCII values may be separated by
commas.
"""

import struct

import numpy as np

from ._common import NORMAL_NAMES, Cloud, content, float_code, parse_float_rows
from ._errors import FileFormatError

try:  # compiled LZF decoder and table parser; pure-Python fallbacks below
    from ._pcd_fast import LZF_MAX_RATIO, lzf_decompress as _lzf_compiled
except ImportError:  # pragma: no cover - an uncompiled checkout
    _lzf_compiled, LZF_MAX_RATIO = None, 88
try:
    from ._xyz_fast import parse_float_table as _parse_float_table
except ImportError:  # pragma: no cover
    _parse_float_table = None

_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
          ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}
_LZF_ERRORS = {1: "literal run overflows", 2: "truncated reference", 3: "bad back reference"}


def _lzf_python(src, expected, path, owner, base):
    """Decompress an LZF stream (pure Python; the compiled decoder is used when built)."""
    out = bytearray(expected)
    ip, op, n = 0, 0, len(src)
    while ip < n:
        ctrl = src[ip]
        ip += 1
        if ctrl < 32:  # literal run of ctrl + 1 bytes
            length = ctrl + 1
            if ip + length > n or op + length > expected:
                raise FileFormatError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (literal run overflows)")
            out[op:op + length] = src[ip:ip + length]
            ip += length
            op += length
        else:  # back reference
            length = ctrl >> 5
            if length == 7:
                if ip >= n:
                    raise FileFormatError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (truncated reference)")
                length += src[ip]
                ip += 1
            if ip >= n:
                raise FileFormatError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (truncated reference)")
            ref = op - ((ctrl & 0x1F) << 8) - src[ip] - 1
            ip += 1
            length += 2
            if ref < 0 or op + length > expected:
                raise FileFormatError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data (bad back reference)")
            if ref + length <= op:
                out[op:op + length] = out[ref:ref + length]
            else:  # overlapping copy, byte by byte
                for k in range(length):
                    out[op + k] = out[ref + k]
            op += length
    if op != expected:
        raise FileFormatError(f"{owner}: {path!r}: compressed data gives {op} bytes, header says {expected}")
    return bytes(out)


def lzf_decompress(src, expected, path, owner, base):
    """Decompress ``src`` into exactly ``expected`` bytes; FileFormatError naming the byte if corrupt."""
    if expected > LZF_MAX_RATIO * len(src):
        raise FileFormatError(
            f"{owner}: {path!r} byte {base - 4}: the compressed block of {len(src)} bytes declares "
            f"{expected} uncompressed bytes, more than LZF can expand it to ({LZF_MAX_RATIO} x {len(src)})"
        )
    if _lzf_compiled is None:
        return _lzf_python(src, expected, path, owner, base)
    out, status, ip, op = _lzf_compiled(src, expected)
    if status == 4:
        raise FileFormatError(f"{owner}: {path!r}: compressed data gives {op} bytes, header says {expected}")
    if status:
        raise FileFormatError(f"{owner}: {path!r} byte {base + ip}: corrupt compressed data ({_LZF_ERRORS[status]})")
    return out


def _parse_header(data, path, owner):
    header, pos, lineno = {}, 0, 0
    while True:
        if pos >= len(data):
            raise FileFormatError(f"{owner}: {path!r} line {lineno}: header ends before its DATA line")
        end = data.find(b"\n", pos)
        if end < 0:
            end = len(data)
        raw = data[pos:end]
        lineno += 1
        pos = end + 1
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise FileFormatError(f"{owner}: {path!r} line {lineno}: non-ASCII bytes in the header") from None
        if not line or line.startswith("#"):
            continue
        key, *rest = line.split()  # (PCL separates header entries by spaces or tabs)
        key = key.upper()
        if key == "COLUMNS":  # PCD v.5's name of FIELDS, which PCL still reads
            key = "FIELDS"
        header[key] = (rest, lineno)
        if key == "DATA":
            return header, min(pos, len(data)), lineno


def _int_entry(header, key, path, owner):
    vals, ln = header[key]
    try:
        if len(vals) != 1:
            raise ValueError
        return int(vals[0]), ln
    except ValueError:
        raise FileFormatError(f"{owner}: {path!r} line {ln}: {key} must be one integer, got {' '.join(vals)[:40]!r}") from None


def _point_count(header, path, owner):
    wh = None
    if "WIDTH" in header:
        width, wline = _int_entry(header, "WIDTH", path, owner)
        height, _ = _int_entry(header, "HEIGHT", path, owner) if "HEIGHT" in header else (1, 0)
        if width < 0 or height < 0:
            raise FileFormatError(f"{owner}: {path!r} line {wline}: negative WIDTH or HEIGHT ({width} x {height})")
        wh = width * height
    if "POINTS" in header:
        n_points, pline = _int_entry(header, "POINTS", path, owner)
        if n_points < 0:
            raise FileFormatError(f"{owner}: {path!r} line {pline}: negative POINTS count {n_points}")
        if wh is not None and wh != n_points:
            raise FileFormatError(
                f"{owner}: {path!r} line {pline}: POINTS {n_points} differs from WIDTH x HEIGHT = {wh}"
            )
        return n_points, pline
    if wh is None:
        raise FileFormatError(f"{owner}: {path!r}: header lacks a valid POINTS (or WIDTH and HEIGHT) entry")
    return wh, wline


def _columns(path, data, owner):
    """Parse a PCD file: (FIELDS names, their (dtype, COUNT), n_points, DATA kind, columns, offset of the data).

    ``columns`` maps every FIELDS name to its values, shape (n,) or (n, COUNT):
    typed views of the records for binary data, float64 columns of the
    parsed table for ASCII data.
    """
    header, pos, lineno = _parse_header(data, path, owner)
    if "FIELDS" not in header:
        raise FileFormatError(f"{owner}: {path!r}: header has no FIELDS line")
    fields, fline = header["FIELDS"]
    n_fields = len(fields)
    if n_fields == 0:
        raise FileFormatError(f"{owner}: {path!r} line {fline}: FIELDS names no field")
    if len(set(f for f in fields if f != "_")) != len([f for f in fields if f != "_"]):
        raise FileFormatError(f"{owner}: {path!r} line {fline}: FIELDS names a field twice: {fields}")

    def column(key, default):
        if key not in header:
            if default is None:
                raise FileFormatError(f"{owner}: {path!r}: header has no {key} line")
            return [default] * n_fields, 0
        vals, ln = header[key]
        if len(vals) != n_fields:
            raise FileFormatError(f"{owner}: {path!r} line {ln}: {key} has {len(vals)} entries but FIELDS has {n_fields}")
        return vals, ln

    sizes, sline = column("SIZE", None)
    types, tline = column("TYPE", None)
    counts, cline = column("COUNT", "1")
    try:
        sizes = [int(s) for s in sizes]
    except ValueError:
        raise FileFormatError(f"{owner}: {path!r} line {sline}: SIZE entries must be integers") from None
    try:
        counts = [int(c) for c in counts]
    except ValueError:
        raise FileFormatError(f"{owner}: {path!r} line {cline}: COUNT entries must be integers") from None
    if any(c < 1 or c > 1 << 20 for c in counts):
        raise FileFormatError(f"{owner}: {path!r} line {cline}: COUNT entries must lie in 1..{1 << 20}, got {counts}")
    dtype_fields = []
    for k, (name, s, t, c) in enumerate(zip(fields, sizes, types, counts)):
        code = _TYPES.get((t.upper(), s))
        if code is None:
            raise FileFormatError(f"{owner}: {path!r} line {tline}: unsupported TYPE/SIZE {t}/{s} for field {name!r}")
        fname = name if name != "_" else f"_pad{k}"
        dtype_fields.append((fname, "<" + code, (c,)) if c > 1 else (fname, "<" + code))
    dtype = np.dtype(dtype_fields)
    n_points, nline = _point_count(header, path, owner)
    kind = header["DATA"][0][0].lower() if header["DATA"][0] else ""
    body = data[pos:]
    if kind not in ("ascii", "binary", "binary_compressed"):
        raise FileFormatError(
            f"{owner}: {path!r} line {lineno}: unknown DATA kind {kind!r}; expected ascii, binary or binary_compressed"
        )
    missing = [f for f in "xyz" if f not in fields]
    if missing:
        raise FileFormatError(f"{owner}: {path!r} line {fline}: FIELDS lacks {missing}; it has {fields}")
    if n_points == 0 and (kind != "binary_compressed" or not body):
        # a cloud of no points, as PLY, NPY, LAS, E57 and .pts files may hold: its columns are empty (a
        # compressed one may leave out its size header, as there is nothing to compress)
        empty = np.zeros(0, dtype=dtype)
        cols = {name: empty[dtype.names[k]] for k, name in enumerate(fields)}
        if kind == "ascii":
            cols = {name: np.asarray(col, dtype=np.float64) for name, col in cols.items()}
    elif kind == "ascii":
        n_cols = sum(counts)
        # each point is a line holding at least one digit and a line break
        if n_points > len(body) // 2 + 1:
            raise FileFormatError(
                f"{owner}: {path!r} line {nline}: the header declares {n_points} points, more than the "
                f"{len(body)} bytes of ASCII data from byte {pos} can hold (a wrong count or a truncated file)"
            )
        arr = None
        if _parse_float_table is not None and b"#" not in body:
            table = _parse_float_table(body, 0)
            if table is not None and table.shape[0] >= n_points and table.shape[1] == n_cols:
                arr = table[:n_points]
        if arr is None:
            text = body.decode("ascii", errors="replace").splitlines()
            idx, rows = content(text)
            idx = [i + lineno for i in idx]
            rows = [r.replace(",", " ") for r in rows]  # PCL splits ASCII values at commas too
            if len(rows) < n_points:
                raise FileFormatError(
                    f"{owner}: {path!r} line {lineno + len(text)}: file ends after {len(rows)} of {n_points} points (truncated)"
                )
            arr = parse_float_rows(rows[:n_points], idx, path, owner, "point")
            if arr.shape[1] != n_cols:
                raise FileFormatError(
                    f"{owner}: {path!r} line {idx[0] + 1}: expected {n_cols} values per point, got {arr.shape[1]}"
                )
        cols, col = {}, 0
        for name, c in zip(fields, counts):
            cols[name] = arr[:, col] if c == 1 else arr[:, col:col + c]
            col += c
    elif kind == "binary":
        need = n_points * dtype.itemsize
        if len(body) < need:
            raise FileFormatError(
                f"{owner}: {path!r} byte {pos + len(body)}: file ends {need - len(body)} bytes early "
                f"(binary data of {n_points} points needs {need} bytes from byte {pos}; truncated)"
            )
        rec = np.frombuffer(body, dtype=dtype, count=n_points)
        cols = {name: rec[dtype.names[k]] for k, name in enumerate(fields)}
    else:
        if len(body) < 8:
            raise FileFormatError(f"{owner}: {path!r} byte {pos + len(body)}: file ends inside the compressed-size header (truncated)")
        csize, usize = struct.unpack("<II", body[:8])
        if len(body) < 8 + csize:
            raise FileFormatError(
                f"{owner}: {path!r} byte {pos + len(body)}: file ends {8 + csize - len(body)} bytes early "
                f"(compressed block of {csize} bytes from byte {pos + 8}; truncated)"
            )
        if usize != n_points * dtype.itemsize:
            raise FileFormatError(
                f"{owner}: {path!r} byte {pos + 4}: uncompressed size {usize} does not match "
                f"{n_points} points of {dtype.itemsize} bytes"
            )
        raw = lzf_decompress(body[8:8 + csize], usize, path, owner, pos + 8)
        # PCL stores compressed data field by field (structure of arrays)
        cols, off = {}, 0
        for k, name in enumerate(fields):
            sub = dtype.fields[dtype.names[k]][0]
            cols[name] = np.frombuffer(raw, dtype=sub, count=n_points, offset=off)
            off += sub.itemsize * n_points

    return fields, [(dtype.fields[name][0].base, c) for name, c in zip(dtype.names, counts)], n_points, kind, cols, pos


def _as_declared(values, dtype, name, path, owner):
    """An ASCII column, parsed as float64, in its declared type (as PCL reads it and the binary kinds hold it).

    A value that type cannot hold is a FileFormatError naming the field, not a wrapped or infinite number:
    for integer types a NaN, infinite, fractional or out-of-range value; for float types a finite value
    beyond their range. NaN and infinities stay what they are in float types (NaN marks PCL's invalid points).
    """
    dtype = dtype.newbyteorder("=")
    values = np.asarray(values, dtype=np.float64)
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        bad = ~(np.isfinite(values) & (values == np.floor(values)) & (values >= info.min) & (values <= info.max))
    else:
        with np.errstate(over="ignore"):
            narrow = values.astype(dtype)
        bad = np.isfinite(values) & ~np.isfinite(narrow)
    if bad.any():
        code = f"TYPE {_CODES[dtype.kind]} SIZE {dtype.itemsize}"
        raise FileFormatError(
            f"{owner}: {path!r}: field {name!r} ({code}) holds {values[bad].flat[0]:.17g}, which that type cannot hold"
        )
    with np.errstate(invalid="ignore"):  # (NaN to a float type is exact; its cast warning is noise)
        return values.astype(dtype)


def _coordinates(fields, types, n_points, kind, cols, path, owner, names="xyz"):
    """The first values of the fields ``names`` as an (n_points, 3) float64 array, ASCII ones in their
    declared type first (``_as_declared``)."""
    declared = {name: base for name, (base, _) in zip(fields, types)}

    def first(name):
        values = _as_declared(cols[name], declared[name], name, path, owner) if kind == "ascii" else cols[name]
        with np.errstate(invalid="ignore"):  # (NaN to float64 is exact; its cast warning is noise)
            values = np.asarray(values, dtype=np.float64)
            return values if values.ndim == 1 else values[:, 0]

    return np.column_stack([first(f) for f in names])


def read_pcd(path, data, owner, want_normals="auto"):
    fields, types, n_points, kind, cols, _ = _columns(path, data, owner)
    xyz = _coordinates(fields, types, n_points, kind, cols, path, owner)
    nrm = None
    if all(f in cols for f in NORMAL_NAMES):
        nrm = _coordinates(fields, types, n_points, kind, cols, path, owner, NORMAL_NAMES)
    return Cloud(xyz, nrm)


def write_pcd(path, cloud, binary=True):
    fields = ["x", "y", "z"] + (list(NORMAL_NAMES) if cloud.shape[1] == 6 else [])
    n = cloud.shape[0]
    k = len(fields)
    code = float_code(cloud)
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(fields)}\nSIZE {' '.join([code[1]] * k)}\nTYPE {' '.join(['F'] * k)}\n"
        f"COUNT {' '.join(['1'] * k)}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    )
    data = np.ascontiguousarray(cloud, dtype="<" + code)
    with open(path, "wb") as fh:
        fh.write(head.encode("ascii"))
        if binary:
            fh.write(data.tobytes())
        else:
            np.savetxt(fh, data, fmt="%.9g" if code == "f4" else "%.17g")


# --------------------------------------------------------------------------- every field

#: PCL packs color into one 4-byte field: ``rgb`` (TYPE F, the float's bits are 0xAARRGGBB) or ``rgba`` (TYPE U).
PACKED_COLOR = ("rgb", "rgba")
_CODES = {"f": "F", "i": "I", "u": "U"}


def _ascii_field(values, dtype, name, path, owner):
    """An ASCII column (parsed as float64) in its declared type; packed color as its uint32 bits."""
    if name in PACKED_COLOR and dtype.itemsize == 4:
        # PCL writes a float rgb as the unsigned integer of its bits; older files wrote the float itself
        whole = np.isfinite(values).all() and (values == np.floor(values)).all() and \
            (values.size == 0 or (values.min() >= 0 and values.max() < 2 ** 32))
        if whole:
            return values.astype(np.uint32)
        return values.astype(np.float32).view(np.uint32)
    return _as_declared(values, dtype, name, path, owner)


def _ascii_wide_ints(data, pos, n_points, n_cols, path, owner):
    """The tokens of an ASCII body as an (n_points, n_cols) string array, for 8-byte integer fields
    (which float64 cannot hold exactly above 2**53)."""
    rows = [line.split("#", 1)[0].replace(",", " ").split()
            for line in data[pos:].decode("ascii", "replace").splitlines()]
    rows = [r for r in rows if r][:n_points]
    return np.array(rows, dtype=str).reshape(n_points, n_cols)


def read_pcd_fields(path, data, owner):
    """(points, fields) of a PCD file: every FIELDS entry but x y z and ``_`` padding, in the file's types."""
    fields, types, n_points, kind, cols, pos = _columns(path, data, owner)
    tokens = None
    if kind == "ascii" and any(b.kind in "iu" and b.itemsize == 8 for b, _ in types):
        tokens = _ascii_wide_ints(data, pos, n_points, sum(c for _, c in types), path, owner)
    out, col = {}, 0
    for name, (base, width) in zip(fields, types):
        values = cols[name]
        if name in ("x", "y", "z", "_"):
            col += width
            continue
        if kind != "ascii":
            if name in PACKED_COLOR and base.itemsize == 4:  # the color's bits, whatever the declared type
                values = np.ascontiguousarray(values.view("<u4"), dtype=np.uint32)
            else:
                values = np.ascontiguousarray(values, dtype=base.newbyteorder("="))
        elif tokens is not None and base.kind in "iu" and base.itemsize == 8:
            text = tokens[:, col] if width == 1 else tokens[:, col:col + width]
            try:
                values = text.astype(base.newbyteorder("="))
            except (ValueError, OverflowError):
                raise FileFormatError(f"{owner}: {path!r}: field {name!r} holds a value that is not a {base} integer") from None
        else:
            values = np.ascontiguousarray(_ascii_field(values, base, name, path, owner))
        out[name] = values
        col += width
    return _coordinates(fields, types, n_points, kind, cols, path, owner), out


def write_pcd_fields(path, points, fields):
    """A binary PCD file: x y z (float32 when that holds them exactly, else float64), then every field."""
    coord = "f4" if exact_float32(points) else "f8"
    spec = [("x", "<" + coord), ("y", "<" + coord), ("z", "<" + coord)]
    head_types = [("F", int(coord[1]), 1)] * 3
    for name, values in fields.items():
        base = values.dtype
        if name in PACKED_COLOR and base == np.uint32:
            code, size = "F", 4  # PCL's rgb is a float field holding the color's bits
        else:
            code, size = _CODES[base.kind], base.itemsize
        count = 1 if values.ndim == 1 else values.shape[1]
        spec.append((name, "<" + base.str[1:], (count,)) if count != 1 else (name, "<" + base.str[1:]))
        head_types.append((code, size, count))
    n = points.shape[0]
    rec = np.empty(n, dtype=np.dtype(spec))
    for k, axis in enumerate("xyz"):
        rec[axis] = points[:, k]
    for name, values in fields.items():
        rec[name] = values.reshape(rec[name].shape)  # (an (n, 1) field is COUNT 1)
    names = ["x", "y", "z"] + list(fields)
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(names)}\nSIZE {' '.join(str(t[1]) for t in head_types)}\n"
        f"TYPE {' '.join(t[0] for t in head_types)}\nCOUNT {' '.join(str(t[2]) for t in head_types)}\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n"
    )
    with open(path, "wb") as fh:
        fh.write(head.encode("ascii"))
        fh.write(rec.tobytes())


def exact_float32(points):
    """True when every coordinate is a float32 value (NaN and infinities included), so float32 stores it exactly."""
    with np.errstate(over="ignore", invalid="ignore"):
        narrow = points.astype(np.float32).astype(np.float64)
    return bool(np.array_equal(narrow, points, equal_nan=True))
