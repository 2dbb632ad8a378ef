"""ASTM E57 scans through pye57 (libE57Format).

pye57 is an optional dependency (``pip install 'eppf[e57]'``); without it
an E57 file raises an :class:`ImportError` whose one line names the extra.
The file's 48-byte header is checked here first (signature, the physical
length equal to the file's size, the XML section inside the file);
libE57Format then checks every 1,024-byte page's CRC as it reads. A scan's
declared record count times the bits its prototype packs per record must
fit the file before anything is allocated, and the records are read in
pieces of at most :data:`PIECE` points, so a hostile count cannot allocate
beyond what the file holds.

Every scan's cartesian coordinates (or spherical ones, converted) are moved
by the scan's pose (rotation quaternion and translation) into the file's
frame, and the scans are concatenated, as pye57's ``read_scan`` does.
"""

import os
import struct

import numpy as np

from ._common import NORMAL_NAME_SETS, Cloud, check_file, widened
from ._errors import FileFormatError

#: Records read from a scan at a time.
PIECE = 1 << 20
_HEADER = 48
_CARTESIAN = ("cartesianX", "cartesianY", "cartesianZ")
_NORMALS = NORMAL_NAME_SETS[2]  # the E57 surface-normals extension
_SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")


def pye57_module(owner, path):
    """pye57's libe57 binding, or an ImportError whose one line names the extra."""
    try:
        from pye57 import libe57
    except ImportError:
        raise ImportError(f"{owner}: {os.fspath(path)!r} is an E57 file, which needs pye57: "
                          "pip install 'eppf[e57]'") from None
    return libe57


def check_header(path, owner):
    """The E57 file header (ASTM E2807 section 8.2) against the file's size."""
    size = check_file(path, owner)
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEADER)
    except OSError as exc:
        raise type(exc)(exc.errno, f"{owner}: cannot read the file ({exc.strerror})", path) from None
    if len(head) < _HEADER:
        raise FileFormatError(f"{owner}: {path!r} byte {len(head)}: file ends inside the 48-byte E57 header (truncated)")
    if head[:8] != b"ASTM-E57":
        raise FileFormatError(f"{owner}: {path!r} byte 0: not an E57 file (expected the signature 'ASTM-E57', "
                              f"got {head[:8]!r})")
    physical, xml_offset, xml_length, page = struct.unpack_from("<QQQQ", head, 16)
    if physical != size:
        raise FileFormatError(f"{owner}: {path!r} byte 16: the header declares {physical} bytes, but the file has "
                              f"{size} (truncated or padded)")
    if page != 1024:
        raise FileFormatError(f"{owner}: {path!r} byte 40: page size {page}; E57 pages are 1024 bytes")
    if xml_offset > size or xml_length > size - xml_offset:
        raise FileFormatError(f"{owner}: {path!r} byte 24: the XML section ({xml_length} bytes from byte "
                              f"{xml_offset}) does not fit the file's {size} bytes")
    return size


def _bits(libe57, node, path, owner):
    """(bits per record, dtype read, dtype returned) of one prototype field."""
    t = node.type()
    if t == libe57.E57_FLOAT:
        single = libe57.FloatNode(node).precision() == libe57.E57_SINGLE
        return (32, "f4", "f4") if single else (64, "f8", "f8")
    if t in (libe57.E57_INTEGER, libe57.E57_SCALED_INTEGER):
        n = libe57.IntegerNode(node) if t == libe57.E57_INTEGER else libe57.ScaledIntegerNode(node)
        lo, hi = int(n.minimum()), int(n.maximum())
        bits = max(hi - lo, 0).bit_length()
        if t == libe57.E57_SCALED_INTEGER:
            return bits, "f8", "f8"
        for code in ("i1", "u1", "i2", "u2", "i4", "u4"):
            info = np.iinfo(code)
            if info.min <= lo and hi <= info.max:
                return bits, (code if code[1] != "4" else "q"), code
        return bits, "q", "i8"
    raise FileFormatError(f"{owner}: {path!r}: E57 point field {node.elementName()!r} has an unsupported type {t} "
                          "(strings are not per-point numbers)")


def _rotation(quaternion):
    w, x, y, z = np.asarray(quaternion, dtype=np.float64) / np.linalg.norm(quaternion)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _scan(libe57, imf, scan, size, path, owner, k):
    """(points, fields) of scan ``k`` of the file, in the file's frame."""
    points_node = libe57.CompressedVectorNode(scan.get("points"))
    proto = libe57.StructureNode(points_node.prototype())
    count = points_node.childCount()
    names, spec, bits = [], [], 0
    for i in range(proto.childCount()):
        node = proto.get(i)
        b, read_code, out_code = _bits(libe57, node, path, owner)
        names.append(node.elementName())
        spec.append((read_code, out_code))
        bits += b
    if count * max(bits, 1) > 8 * size:
        raise FileFormatError(f"{owner}: {path!r}: scan {k} declares {count} points of {bits} bits, more than the "
                              f"file's {size} bytes can hold")
    have = set(names)
    if not (set(_CARTESIAN) <= have or set(_SPHERICAL) <= have):
        raise FileFormatError(f"{owner}: {path!r}: scan {k} has neither cartesianX/Y/Z nor sphericalRange/Azimuth/"
                              f"Elevation; its fields are {names}")
    parts = {n: [] for n in names}
    capacity = max(1, min(count, PIECE))
    arrays = {n: np.empty(capacity, dtype=np.dtype(code)) for n, (code, _) in zip(names, spec)}
    buffers = libe57.VectorSourceDestBuffer()
    for n in names:
        buffers.append(libe57.SourceDestBuffer(imf, n, arrays[n], capacity, True, True))
    reader = points_node.reader(buffers)
    try:
        got = 0
        while got < count:
            n_read = reader.read()
            if n_read == 0:
                raise FileFormatError(f"{owner}: {path!r}: scan {k} ends after {got} of {count} points (truncated)")
            for n in names:
                parts[n].append(arrays[n][:n_read].copy())
            got += n_read
    finally:
        reader.close()
    columns = {n: (np.concatenate(parts[n]) if parts[n] else np.empty(0, dtype=np.dtype(spec[j][0])))
               .astype(spec[j][1], copy=False) for j, n in enumerate(names)}
    if set(_CARTESIAN) <= have:
        xyz = np.column_stack([widened(columns[n]) for n in _CARTESIAN])
        state = columns.get("cartesianInvalidState")
    else:
        r, az, el = (widened(columns[n]) for n in _SPHERICAL)
        xyz = np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)])
        state = columns.get("sphericalInvalidState")  # (the state of the coordinates the points come from)
    # 0: a valid point; 1: a direction without a range; 2: no point
    valid = None if state is None else np.asarray(state) == 0
    if scan.isDefined("pose"):
        pose = libe57.StructureNode(scan.get("pose"))
        if pose.isDefined("rotation"):
            rot = libe57.StructureNode(pose.get("rotation"))
            q = [libe57.FloatNode(rot.get(c)).value() for c in "wxyz"]
            turn = _rotation(q).T
            xyz = xyz @ turn
            if set(_NORMALS) <= have and q != [1.0, 0.0, 0.0, 0.0]:
                # normals are directions: the pose's rotation turns them too (no translation)
                turned = np.column_stack([widened(columns[n]) for n in _NORMALS]) @ turn
                for k, n in enumerate(_NORMALS):
                    columns[n] = turned[:, k]
        if pose.isDefined("translation"):
            tr = libe57.StructureNode(pose.get("translation"))
            xyz = xyz + np.array([libe57.FloatNode(tr.get(c)).value() for c in "xyz"])
    fields = {n: np.ascontiguousarray(columns[n]) for n in names if n not in _CARTESIAN}
    return np.ascontiguousarray(xyz), fields, valid


def _reason(exc):
    """The first line of an exception's message: libE57Format's add a blank line and a multi-line
    "**** Got an e57 exception" report with debug context after the reason."""
    lines = str(exc).strip().splitlines()
    return lines[0].strip() if lines else type(exc).__name__


def read_e57_fields(path, owner):
    """(points, fields) of every scan of an E57 file, one after the other."""
    points, fields, _ = _read_scans(path, owner)
    return points, fields


def _read_scans(path, owner):
    """(points, fields, valid) of every scan of an E57 file, one after the other; ``valid`` marks the points
    whose invalid state (of the coordinates they come from) is 0, or is None when no scan has one."""
    size = check_header(path, owner)
    libe57 = pye57_module(owner, path)
    try:
        imf = libe57.ImageFile(path, "r")
    except Exception as exc:  # noqa: BLE001 - libE57Format's E57Exception: a corrupt file
        raise FileFormatError(f"{owner}: {path!r}: malformed E57 file ({_reason(exc)})") from None
    try:
        root = imf.root()
        if not root.isDefined("data3D"):
            raise FileFormatError(f"{owner}: {path!r}: the E57 file has no data3D section (no scans)")
        data3d = libe57.VectorNode(root.get("data3D"))
        scans = [_scan(libe57, imf, libe57.StructureNode(data3d.get(k)), size, path, owner, k)
                 for k in range(data3d.childCount())]
    except FileFormatError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise FileFormatError(f"{owner}: {path!r}: malformed E57 file ({type(exc).__name__}: {_reason(exc)})") from None
    finally:
        imf.close()
    if not scans:
        raise FileFormatError(f"{owner}: {path!r}: the E57 file holds no scans")
    common = [n for n in scans[0][1] if all(n in f for _, f, _ in scans[1:])]
    points = np.concatenate([p for p, _, _ in scans]) if len(scans) > 1 else scans[0][0]
    fields = {n: (np.concatenate([f[n] for _, f, _ in scans]) if len(scans) > 1 else scans[0][1][n])
              for n in common}
    if len(scans) > 1:
        fields["scan_index"] = np.repeat(np.arange(len(scans), dtype=np.uint32), [p.shape[0] for p, _, _ in scans])
    valid = None
    if any(v is not None for _, _, v in scans):
        valid = np.concatenate([np.ones(p.shape[0], dtype=bool) if v is None else v for p, _, v in scans])
    return points, fields, valid


def read_e57(path, owner, want_normals="auto"):
    """The Cloud of an E57 file: points whose ``cartesianInvalidState`` (``sphericalInvalidState`` for a scan
    of spherical coordinates) is not 0 are dropped.

    Normals are those of the E57 surface-normals extension (``nor:normalX``,
    ``nor:normalY``, ``nor:normalZ``), turned by each scan's pose as its
    points are.
    """
    points, fields, valid = _read_scans(path, owner)
    normals = None
    if want_normals is not False and all(n in fields for n in _NORMALS):
        normals = np.column_stack([widened(fields[n]) for n in _NORMALS])
    if valid is not None:
        points = points[valid]
        normals = None if normals is None else normals[valid]
    return Cloud(points, normals)
