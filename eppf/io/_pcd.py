"""PCL's PCD format: ``DATA ascii``, ``binary`` and ``binary_compressed``.

Every count is checked against the file before anything is allocated:
``POINTS`` (or ``WIDTH`` x ``HEIGHT``) times the record size must fit the
binary body; an ASCII body must have a line per point; a compressed block's
declared size must be one LZF can reach from its compressed size (LZF writes
at most 88 bytes per input byte, see :mod:`eppf.io._pcd_fast`).
"""

import struct

import numpy as np

from ._common import Cloud, content, parse_float_rows
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
        key, _, rest = line.partition(" ")
        header[key.upper()] = (rest.split(), lineno)
        if key.upper() == "DATA":
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


def read_pcd(path, data, owner, want_normals="auto"):
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
    if n_points == 0:
        raise FileFormatError(f"{owner}: {path!r} line {nline}: the header declares 0 points")
    if kind == "ascii":
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
            if len(rows) < n_points:
                raise FileFormatError(
                    f"{owner}: {path!r} line {lineno + len(text)}: file ends after {len(rows)} of {n_points} points (truncated)"
                )
            arr = parse_float_rows(rows[:n_points], idx, path, owner, "point")
            if arr.shape[1] != n_cols:
                raise FileFormatError(
                    f"{owner}: {path!r} line {idx[0] + 1}: expected {n_cols} values per point, got {arr.shape[1]}"
                )
        flat_names = []
        for name, c in zip(fields, counts):
            flat_names += [name] * c
        cols = {name: arr[:, flat_names.index(name)] for name in fields}
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

    def first(name):
        with np.errstate(invalid="ignore"):  # NaN to float64 is exact; its cast warning is noise
            return np.asarray(cols[name], dtype=np.float64).reshape(n_points, -1)[:, 0]

    xyz = np.column_stack([first(f) for f in "xyz"])
    nrm = None
    if all(f in cols for f in ("normal_x", "normal_y", "normal_z")):
        nrm = np.column_stack([first(f) for f in ("normal_x", "normal_y", "normal_z")])
    return Cloud(xyz, nrm)


def write_pcd(path, cloud, binary=True):
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
