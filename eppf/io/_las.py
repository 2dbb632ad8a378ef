"""LAS and LAZ (ASPRS LiDAR) through laspy, with the lazrs backend for LAZ.

laspy is an optional dependency (``pip install 'eppf[las]'``); without it a
LAS or LAZ file raises an :class:`ImportError` whose one line names the
extra. Before laspy sees a file, its header is checked here against the
file's size (:func:`check_header`), so that no count, offset or length in a
hostile header makes laspy or lazrs allocate beyond the file:

- the public header's own size, the offset of the point data and every
  variable-length record (VLR) must lie inside the file, the VLRs before the
  points;
- a LAS point record must be at least its point format's size, and the
  extra-bytes descriptors (192 bytes each) may not describe more bytes than
  a record has beyond that;
- uncompressed: the point count times the record length must fit the bytes
  after the offset of the point data;
- LAZ: the laszip VLR must name a chunked compressor (2 or 3; lazrs cannot
  decode LASzip 1.x's point-wise data without chunks, compressor 1), the
  chunk table's offset must lie inside the file and its number of
  chunks may not exceed the compressed bytes (every chunk holds at least its
  first point uncompressed); every chunk must lie inside the compressed
  points, declare at most 50,000 points (LASzip's default) or 64 times the
  file's size in decoded bytes (lazrs's parallel decoder allocates a whole
  chunk), and, in the layered formats 6 to 10, declare layers that fit the
  chunk (lazrs reserves a layer's declared size before reading it). LAZ compresses constant points about 2,900
  times (measured with lazrs), so a declared count is not bounded by the
  compressed size: the points are decoded in pieces of at most
  :data:`LAZ_PIECE_RATIO` times the file's size, and a file whose data ends
  before its count stops with a :class:`FileFormatError`;
- LAS 1.4 extended VLRs after the points must lie inside the file;
- every scale factor must be finite and non-zero and every offset finite,
  with ``|scale| * 2**31 + |offset|`` finite (no int32 coordinate overflows).

Coordinates are returned as float64 ``X * scale + offset``, the values
laspy's ``las.x`` gives, in the file's own units.
"""

import math
import os
import struct

import numpy as np

from ._common import NORMAL_NAME_SETS, NORMAL_NAMES, Cloud, check_file, widened
from ._errors import FileFormatError

#: Decoded LAZ data is allocated in pieces of at most this many times the file's size.
LAZ_PIECE_RATIO = 64

#: LASzip's default points per chunk: a chunk of at most this many points is always accepted.
_DEFAULT_CHUNK = 50000

#: Point formats in the order the writer tries them (waveform formats last).
_WRITE_ORDER = (0, 1, 2, 3, 6, 7, 8, 4, 5, 9, 10)
_HEADER_MIN = 227
_VLR_HEADER = 54
_EVLR_HEADER = 60
_EXTRA_BYTES_SIZES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 8, 8: 8, 9: 4, 10: 8}


def laspy_module(owner, path, compressed=False):
    """laspy (and for LAZ a lazrs backend), or an ImportError whose one line names the extra."""
    hint = f"{owner}: {os.fspath(path)!r} is a {'LAZ' if compressed else 'LAS'} file, which needs laspy"
    try:
        import laspy
    except ImportError:
        raise ImportError(f"{hint}: pip install 'eppf[las]'") from None
    if compressed and not laspy.LazBackend.detect_available():
        raise ImportError(f"{hint} with the lazrs backend: pip install 'eppf[las]'") from None
    return laspy


def _base_sizes():
    """Record sizes of LAS point formats 0..10 (from the specification)."""
    return (20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67)


def _fail(owner, path, where, what):
    raise FileFormatError(f"{owner}: {path!r} {where}: {what}")


def check_header(fh, size, path, owner):
    """Validate a LAS/LAZ file's header, VLRs and point-data extents against ``size``.

    Returns ``(point_count, record_length, compressed, point format, laszip VLR data, offset to the points,
    offset of the LAZ chunk table)``; raises
    FileFormatError naming the byte of the first problem.
    """
    head = fh.read(375)
    if len(head) < _HEADER_MIN:
        _fail(owner, path, f"byte {len(head)}", f"file ends inside the {_HEADER_MIN}-byte LAS header (truncated)")
    if head[:4] != b"LASF":
        _fail(owner, path, "byte 0", f"not a LAS file (expected the signature 'LASF', got {head[:4]!r})")
    major, minor = head[24], head[25]
    if major != 1 or minor > 4:
        _fail(owner, path, "byte 24", f"unsupported LAS version {major}.{minor}")
    header_size, offset, n_vlrs = struct.unpack_from("<HII", head, 94)
    fmt_byte, record_length, legacy_count = struct.unpack_from("<BHI", head, 104)
    least = 375 if minor >= 4 else (235 if minor == 3 else _HEADER_MIN)
    if header_size < least or header_size > size:
        _fail(owner, path, "byte 94", f"header size {header_size} outside {least}..{size} (the file's size)")
    if len(head) < least:
        _fail(owner, path, f"byte {len(head)}", "file ends inside the LAS header (truncated)")
    if offset < header_size or offset > size:
        _fail(owner, path, "byte 96", f"offset to the point data {offset} outside {header_size}..{size}")
    compressed = bool(fmt_byte & 0x80)
    fmt = fmt_byte & 0x3F
    if fmt > 10:
        _fail(owner, path, "byte 104", f"unknown point format {fmt} (LAS has 0..10)")
    base = _base_sizes()[fmt]
    if record_length < base:
        _fail(owner, path, "byte 105", f"point record length {record_length} is below the {base} bytes of point format {fmt}")
    count = struct.unpack_from("<Q", head, 247)[0] if minor >= 4 else legacy_count
    if minor >= 4 and count == 0:
        count = legacy_count
    # coordinates are X * scale + offset: a zero or non-finite scale (or offset) gives no coordinates, and a
    # scale so large that an int32 times it overflows gives infinities
    scales, offsets = struct.unpack_from("<3d", head, 131), struct.unpack_from("<3d", head, 155)
    for k, axis in enumerate("xyz"):
        scale, off = scales[k], offsets[k]
        if not (math.isfinite(scale) and scale != 0.0):
            _fail(owner, path, f"byte {131 + 8 * k}",
                  f"{axis} scale factor {scale!r} (a LAS header's must be finite and non-zero)")
        if not math.isfinite(off) or not math.isfinite(abs(scale) * 2.0 ** 31 + abs(off)):
            _fail(owner, path, f"byte {155 + 8 * k}",
                  f"{axis} offset {off!r} with scale factor {scale!r} gives no finite coordinates")
    # the VLRs, each inside the header region before the points
    pos = header_size
    extra = 0
    laszip = None
    for k in range(n_vlrs):
        if pos + _VLR_HEADER > offset:
            _fail(owner, path, f"byte {pos}", f"VLR {k} of {n_vlrs} does not fit before the point data at byte {offset}")
        fh.seek(pos)
        vlr = fh.read(_VLR_HEADER)
        if len(vlr) < _VLR_HEADER:
            _fail(owner, path, f"byte {pos}", f"file ends inside VLR {k} (truncated)")
        user = vlr[2:18].split(b"\0", 1)[0]
        record_id, length = struct.unpack_from("<HH", vlr, 18)
        data_at = pos + _VLR_HEADER
        if data_at + length > offset:
            _fail(owner, path, f"byte {pos + 20}", f"VLR {k} of {length} bytes runs past the point data at byte {offset}")
        if user == b"LASF_Spec" and record_id == 4:
            if length % 192:
                _fail(owner, path, f"byte {pos + 20}", f"extra-bytes VLR of {length} bytes is not a whole number "
                      "of 192-byte descriptors")
            fh.seek(data_at)
            body = fh.read(length)
            for d in range(length // 192):
                dtype_id, options = body[d * 192 + 2], body[d * 192 + 3]
                if dtype_id == 0:
                    extra += options
                elif dtype_id <= 10:
                    extra += _EXTRA_BYTES_SIZES[dtype_id]
                elif dtype_id <= 30:
                    extra += _EXTRA_BYTES_SIZES[(dtype_id - 1) % 10 + 1] * (2 if dtype_id <= 20 else 3)
                else:
                    _fail(owner, path, f"byte {data_at + d * 192 + 2}", f"extra-bytes descriptor {d} has an unknown "
                          f"data type {dtype_id}")
        if user == b"laszip encoded":
            fh.seek(data_at)
            laszip, laszip_at = fh.read(length), data_at
        pos = data_at + length
    if base + extra > record_length:
        _fail(owner, path, "byte 105", f"the extra-bytes descriptors describe {extra} bytes, but a record of "
              f"{record_length} bytes has only {record_length - base} beyond point format {fmt}")
    if compressed and laszip is None:
        _fail(owner, path, "byte 104", "the point format is marked compressed (LAZ), but there is no laszip VLR")
    if compressed:
        compressor = struct.unpack_from("<H", laszip, 0)[0] if len(laszip) >= 2 else None
        if compressor == 1:  # lazrs decodes chunked data only: it would report a garbage chunk table
            _fail(owner, path, f"byte {laszip_at}", "the LAZ file uses LASzip 1.x's point-wise compressor "
                  "(compressor 1, without chunks), which the lazrs backend cannot decompress; recompress it with a "
                  "current LASzip (laszip, PDAL)")
        if compressor not in (2, 3):
            _fail(owner, path, f"byte {laszip_at}", f"unknown LAZ compressor {compressor} in the laszip VLR "
                  "(LASzip writes 2, point-wise chunked, or 3, layered chunked)")
    points_end = size
    if minor >= 4:
        evlr_start, n_evlrs = struct.unpack_from("<QI", head, 235)
        if n_evlrs:
            if evlr_start < offset or evlr_start > size:
                _fail(owner, path, "byte 235", f"start of the extended VLRs {evlr_start} outside {offset}..{size}")
            points_end = evlr_start
            pos = evlr_start
            for k in range(n_evlrs):
                if pos + _EVLR_HEADER > size:
                    _fail(owner, path, f"byte {pos}", f"extended VLR {k} of {n_evlrs} does not fit the file (truncated)")
                fh.seek(pos + 20)
                (length,) = struct.unpack("<Q", fh.read(8))
                if length > size - pos - _EVLR_HEADER:
                    _fail(owner, path, f"byte {pos + 20}", f"extended VLR {k} of {length} bytes runs past the end "
                          f"of the file ({size} bytes)")
                pos += _EVLR_HEADER + length
    available = points_end - offset
    if not compressed:
        if count * record_length > available:
            _fail(owner, path, "byte 107" if minor < 4 else "byte 247",
                  f"the header declares {count} points of {record_length} bytes ({count * record_length} bytes), "
                  f"but the file has {available} bytes of point data from byte {offset} (a wrong count or a truncated file)")
        return count, record_length, compressed, fmt, laszip, offset, None
    # LAZ: the chunk table (its offset is the first 8 bytes of the point data, or the file's last 8 bytes)
    if count == 0:
        return count, record_length, compressed, fmt, laszip, offset, None
    if available < 8:
        _fail(owner, path, f"byte {offset}", "file ends inside the LAZ chunk-table offset (truncated)")
    fh.seek(offset)
    (table,) = struct.unpack("<q", fh.read(8))
    where = offset
    if table == -1:
        fh.seek(size - 8)
        (table,) = struct.unpack("<q", fh.read(8))
        where = size - 8
    if table < offset + 8 or table > size - 8:
        _fail(owner, path, f"byte {where}", f"LAZ chunk table offset {table} outside {offset + 8}..{size - 8}")
    fh.seek(table)
    _version, n_chunks = struct.unpack("<II", fh.read(8))
    if n_chunks > table - offset - 8:
        _fail(owner, path, f"byte {table + 4}", f"the LAZ chunk table declares {n_chunks} chunks, more than the "
              f"{table - offset - 8} bytes of compressed points can hold")
    return count, record_length, compressed, fmt, laszip, offset, table


#: Layers of a LAZ 1.4 (layered) chunk per point format 6..10, besides one per extra byte:
#: the point's 9 (xy, z, classification, flags, intensity, scan angle, user data, source, GPS time),
#: RGB 1, NIR 1, wave packet 1.
_LAYERS = {6: 9, 7: 10, 8: 11, 9: 10, 10: 12}


def check_chunks(fh, size, path, owner, record_length, fmt, laszip, offset, table):
    """Every LAZ chunk inside the compressed points, and for layered formats (6..10) every layer's declared
    size inside its chunk: lazrs reserves a layer's declared size before reading it."""
    import lazrs

    fh.seek(offset)
    try:
        chunks = lazrs.read_chunk_table(fh, lazrs.LazVlr(laszip))
    except Exception as exc:  # noqa: BLE001 - lazrs's own errors on a corrupt table or VLR
        raise FileFormatError(f"{owner}: {path!r} byte {table}: unreadable LAZ chunk table ({exc})") from None
    pos, end = offset + 8, table
    n_layers = _LAYERS.get(fmt, 0) + (record_length - _base_sizes()[fmt] if fmt >= 6 else 0)
    head = record_length + 4 + 4 * n_layers
    most = max(LAZ_PIECE_RATIO * size, _DEFAULT_CHUNK * record_length)
    for k, (n_points, n_bytes) in enumerate(chunks):
        if n_points * record_length > most:  # lazrs's parallel decoder allocates a whole chunk's points
            _fail(owner, path, f"byte {table}", f"LAZ chunk {k} declares {n_points} points ({n_points * record_length} "
                  f"bytes), more than {most} bytes (the larger of {LAZ_PIECE_RATIO} times the file's size and "
                  f"{_DEFAULT_CHUNK} points)")
        if n_bytes < 0 or n_bytes > end - pos:
            _fail(owner, path, f"byte {pos}", f"LAZ chunk {k} of {n_bytes} bytes runs past the compressed points "
                  f"(which end at byte {end})")
        if fmt >= 6 and n_bytes:
            if head > n_bytes:
                _fail(owner, path, f"byte {pos}", f"LAZ chunk {k} of {n_bytes} bytes is shorter than its "
                      f"{head}-byte header")
            fh.seek(pos + record_length + 4)
            sizes = struct.unpack(f"<{n_layers}I", fh.read(4 * n_layers))
            if head + sum(sizes) > n_bytes:
                _fail(owner, path, f"byte {pos + record_length + 4}", f"the layers of LAZ chunk {k} declare "
                      f"{sum(sizes)} bytes, more than the chunk's {n_bytes - head}")
        pos += n_bytes


def _open(path, owner):
    """(laspy module, size, count, record length, compressed) after the header checks."""
    size = check_file(path, owner)
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise type(exc)(exc.errno, f"{owner}: cannot read the file ({exc.strerror})", path) from None
    with fh:
        count, record_length, compressed, fmt, laszip, offset, table = check_header(fh, size, path, owner)
        laspy = laspy_module(owner, path, compressed)
        if table is not None:
            check_chunks(fh, size, path, owner, record_length, fmt, laszip, offset, table)
    return laspy, size, count, record_length, compressed


def _records(path, owner):
    """(laspy header, structured point records, the laspy PointFormat) of a checked file."""
    laspy, size, count, record_length, compressed = _open(path, owner)
    try:
        with laspy.open(path) as reader:
            header = reader.header
            if header.point_format.size != record_length:
                raise FileFormatError(f"{owner}: {path!r} byte 105: point record length {record_length} differs "
                                      f"from the {header.point_format.size} bytes its format and extra bytes give")
            if not compressed:  # one read into fresh memory (count * record_length was checked against the file)
                array = np.fromfile(path, dtype=header.point_format.dtype(), count=count, offset=header.offset_to_point_data)
                if array.shape[0] != count:
                    raise FileFormatError(f"{owner}: {path!r}: point data ends after {array.shape[0]} of {count} points")
                return laspy, header, array
            piece = max(1, LAZ_PIECE_RATIO * size // record_length)
            parts, got = [], 0
            while got < count:
                want = min(piece, count - got)
                try:
                    part = reader.read_points(want)
                except FileFormatError:
                    raise
                except Exception as exc:  # noqa: BLE001 - lazrs/laspy errors: the data ends early or is corrupt
                    raise FileFormatError(f"{owner}: {path!r}: point data unreadable after {got} of {count} points "
                                          f"({type(exc).__name__}: {exc})") from None
                if len(part) == 0:
                    raise FileFormatError(f"{owner}: {path!r}: point data ends after {got} of {count} points (truncated)")
                parts.append(part.array)
                got += len(part)
    except (FileFormatError, OSError, ImportError):
        raise
    except BaseException as exc:
        if type(exc).__name__ != "PanicException":  # pyo3's panic (a BaseException): corrupt LAZ data
            if isinstance(exc, Exception):
                raise FileFormatError(f"{owner}: {path!r}: malformed LAS file ({type(exc).__name__}: {exc})") from None
            raise
        raise FileFormatError(f"{owner}: {path!r}: corrupt LAZ data ({exc})") from None
    if not parts:
        array = np.zeros(0, dtype=header.point_format.dtype())
    else:
        array = parts[0] if len(parts) == 1 else np.concatenate(parts)
    return laspy, header, array


def _coordinates(header, array):
    """float64 (n, 3): ``X * scale + offset`` per axis, as laspy's ``las.x`` computes it."""
    out = np.empty((array.shape[0], 3))
    for k, name in enumerate("XYZ"):
        np.multiply(array[name], header.scales[k], out=out[:, k])
        out[:, k] += header.offsets[k]
    return out


def read_las(path, owner, want_normals="auto"):
    """The Cloud of a LAS/LAZ file; extra bytes ``normal_x normal_y normal_z`` (or ``nx ny nz``) are its normals."""
    laspy, header, array = _records(path, owner)
    names = array.dtype.names
    nrm = None
    for trio in NORMAL_NAME_SETS[:2]:
        if all(n in names for n in trio):
            points = laspy.ScaleAwarePointRecord(array, header.point_format, header.scales, header.offsets)
            nrm = np.column_stack([widened(points[n]) for n in trio])
            break
    return Cloud(_coordinates(header, array), nrm)


def read_las_fields(path, owner):
    """(points, fields): every dimension of the point format but X, Y, Z, extra bytes included, in file order."""
    laspy, header, array = _records(path, owner)
    points = laspy.ScaleAwarePointRecord(array, header.point_format, header.scales, header.offsets)
    fields = {}
    for name in header.point_format.dimension_names:
        if name in ("X", "Y", "Z"):
            continue
        fields[name] = np.asarray(points[name])  # whole-byte dimensions: views of the records, no copy
    return _coordinates(header, array), fields


# --------------------------------------------------------------------------- writing


def _same_bits(a, b):
    return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


def _axis_grid(values):
    """(scale, offset) for one axis: a decimal grid that gives ``values`` back bit for bit, else the finest
    decimal grid whose integers fit LAS's 32 bits (from an offset at the floor of the minimum). An empty
    file (no points) gets millimeters from 0."""
    if values.size == 0:
        return 0.001, 0.0
    lo, hi = float(values.min()), float(values.max())
    sample = values[:: max(1, values.shape[0] // 64)]
    offsets = [0.0] + [float(np.floor(lo / m) * m) for m in (1e6, 1e5, 1e4, 1e3, 1e2, 10.0, 1.0)]
    for k in range(10):
        scale = 10.0 ** -k
        for off in dict.fromkeys(offsets):
            if max(abs(hi - off), abs(lo - off)) / scale >= 2 ** 31 - 1:
                continue
            for part in (sample, values):
                back = np.rint((part - off) / scale) * scale + off
                if not _same_bits(back, part):
                    break
            else:
                return scale, off
    off = float(np.floor(lo))
    for k in range(9, -1, -1):
        scale = 10.0 ** -k
        if (hi - off) / scale < 2 ** 31 - 1:
            return scale, off
    return 10.0 ** int(np.ceil(np.log10((hi - off) / (2 ** 31 - 1)))), off


def _fits(values, dim):
    """True when every value is stored exactly by LAS dimension ``dim`` (a laspy DimensionInfo)."""
    if values.ndim != 1:
        return False
    if values.dtype.kind == "b":
        values = values.astype(np.uint8)
    if dim.dtype is None:  # a bit field (return_number, classification of formats 0-5, ...)
        return values.dtype.kind in "iu" and (values.size == 0 or values.min() >= 0 and values.max() < 2 ** dim.num_bits)
    target = dim.dtype
    with np.errstate(invalid="ignore", over="ignore"):
        cast = values.astype(target)
        return np.array_equal(cast.astype(values.dtype), values, equal_nan=values.dtype.kind == "f")


def _choose_format(laspy, fields, owner):
    standard = set()
    for fmt in _WRITE_ORDER:
        standard |= set(laspy.PointFormat(fmt).dimension_names)
    named = [n for n in fields if n in standard]
    misfits = {}
    for fmt in _WRITE_ORDER:
        pf = laspy.PointFormat(fmt)
        dims = {d.name: d for d in pf.dimensions}
        if any(n not in dims for n in named):
            continue
        bad = [n for n in named if not _fits(fields[n], dims[n])]
        if not bad:
            return fmt
        misfits.setdefault(bad[0], dims[bad[0]])
    if misfits:
        name, dim = next(iter(misfits.items()))
        raise ValueError(f"{owner}: field {name!r} ({fields[name].dtype}, shape {fields[name].shape}) does not fit "
                         f"LAS's {name} ({dim.num_bits} bits) in any point format that has the other "
                         "fields; convert it, or rename it to keep it as extra bytes")
    raise ValueError(f"{owner}: no LAS point format has all of the fields {named}")


def write_las(path, points, fields, owner, compressed, shown=None):
    """Write a LAS/LAZ file; messages name ``shown`` (the user's name of a file written under another)."""
    shown = path if shown is None else shown
    laspy = laspy_module(owner, shown, compressed)
    fields = dict(fields)
    if not np.isfinite(points).all():
        raise ValueError(f"{owner}: LAS stores coordinates as integers on a grid: points must be finite")
    fmt = _choose_format(laspy, fields, owner)
    pf = laspy.PointFormat(fmt)
    header = laspy.LasHeader(point_format=fmt)
    standard = set(pf.dimension_names)
    for name, values in fields.items():
        if name in standard:
            continue
        if len(name.encode("utf-8", "replace")) > 32:
            raise ValueError(f"{owner}: LAS extra-bytes names hold at most 32 bytes, got {name!r}")
        count = 1 if values.ndim == 1 else values.shape[1]
        if not 1 <= count <= 3:
            raise ValueError(f"{owner}: LAS extra bytes hold 1 to 3 values per point; field {name!r} has {count}")
        code = values.dtype.newbyteorder("=").str[1:] if values.dtype.kind != "b" else "u1"
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=code if count == 1 else f"{count}{code}"))
    grids = [_axis_grid(points[:, k]) for k in range(3)]
    header.scales = np.array([g[0] for g in grids])
    header.offsets = np.array([g[1] for g in grids])
    las = laspy.LasData(header)
    las.points = laspy.ScaleAwarePointRecord.zeros(points.shape[0], header=header)
    for k, name in enumerate("XYZ"):
        las.points.array[name] = np.rint((points[:, k] - header.offsets[k]) / header.scales[k]).astype(np.int32)
    for name, values in fields.items():
        if values.dtype.kind == "b":
            values = values.astype(np.uint8)
        if name in standard:
            las[name] = values
        else:
            las.points.array[name] = values.reshape(las.points.array[name].shape)  # (an (n, 1) field: one value)
    las.update_header()
    try:
        las.write(path, do_compress=compressed)
    except OSError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise ValueError(f"{owner}: cannot write {os.fspath(shown)!r} ({type(exc).__name__}: {exc})") from None


def _cloud_fields(cloud):
    return {} if cloud.shape[1] == 3 else {n: cloud[:, 3 + k] for k, n in enumerate(NORMAL_NAMES)}


def write_las_cloud(path, cloud, binary=True):
    """write_point_cloud's LAS writer: normals (if any) as float64 extra bytes ``normal_x normal_y normal_z``."""
    write_las(path, cloud[:, :3], _cloud_fields(cloud), "write_point_cloud", compressed=False)


def write_laz_cloud(path, cloud, binary=True):
    """write_point_cloud's LAZ writer (as :func:`write_las_cloud`, compressed)."""
    write_las(path, cloud[:, :3], _cloud_fields(cloud), "write_point_cloud", compressed=True)
