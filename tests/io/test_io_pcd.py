"""PCD files: PCL's three DATA kinds, padding and COUNT fields, LZF, hostile headers."""

import re
import struct

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.io import FileFormatError, read_point_cloud, write_point_cloud



# --------------------------------------------------------------------------- PCD fixtures

PCD_HEAD = """# .PCD v0.7 - Point Cloud Data file format
VERSION 0.7
FIELDS x y z rgb normal_x normal_y normal_z
SIZE 4 4 4 4 4 4 4
TYPE F F F U F F F
COUNT 1 1 1 1 1 1 1
WIDTH {n}
HEIGHT 1
VIEWPOINT 0 0 0 1 0 0 0
POINTS {n}
DATA {kind}
"""


def test_pcd_ascii_extra_fields(write_file, tmp_path):
    body = "1 2 3 4278190080 0 0 1\n-1.5 0.25 7 0 1 0 0\nnan nan nan 0 0 0 1\n"
    path = write_file(tmp_path / "a.pcd", PCD_HEAD.format(n=3, kind="ascii") + body)
    cloud = read_point_cloud(path)
    # the NaN point (PCL's marker of an invalid point) is dropped
    assert_allclose(cloud, [[1, 2, 3, 0, 0, 1], [-1.5, 0.25, 7, 1, 0, 0]])
    assert read_point_cloud(path, remove_nan=False).shape == (3, 6)


def test_pcd_binary_padding_and_count(tmp_path):
    # a padding field "_" and a field with COUNT 2 must be skipped correctly
    head = (
        "VERSION 0.7\nFIELDS x _ y z extra\nSIZE 4 4 8 4 2\nTYPE F U F F I\nCOUNT 1 1 1 1 2\n"
        "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n"
    )
    rec = b"".join(struct.pack("<fIdfhh", x, 9, y, z, 5, 6) for x, y, z in [(1.0, 2.0, 3.0), (4.0, 5.0, 6.0)])
    path = tmp_path / "b.pcd"
    path.write_bytes(head.encode() + rec)
    assert_allclose(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])


def _lzf_literals(data):
    """Encode bytes as an LZF stream of literal runs only (valid, uncompressed)."""
    out = bytearray()
    for k in range(0, len(data), 32):
        chunk = data[k:k + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def test_pcd_binary_compressed_literals(tmp_path):
    xyz = np.arange(12, dtype="<f4").reshape(4, 3) * 0.5
    # PCL compresses field by field: all x, then all y, then all z
    raw = b"".join(np.ascontiguousarray(xyz[:, k]).tobytes() for k in range(3))
    comp = _lzf_literals(raw)
    head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 1\nPOINTS 4\nDATA binary_compressed\n"
    path = tmp_path / "c.pcd"
    path.write_bytes(head.encode() + struct.pack("<II", len(comp), len(raw)) + comp)
    assert_allclose(read_point_cloud(path), xyz)


def test_pcd_binary_compressed_back_references(tmp_path):
    # 10 points with x = 1.5 everywhere, y = 2.5 everywhere, z = 0 .. 9
    n = 10
    x = struct.pack("<f", 1.5)
    y = struct.pack("<f", 2.5)
    z = np.arange(n, dtype="<f4").tobytes()
    # x block: 4 literal bytes, then a long overlapping reference (offset 4, length 36)
    long_ref = bytes([7 << 5 | 0, 36 - 2 - 7, 3])
    # y block: 4 literal bytes, then short references (offset 4): 2 x length 8, then length 20
    short8 = bytes([(8 - 2) << 5 | 0, 3])
    tail = bytes([7 << 5 | 0, 20 - 2 - 7, 3])
    comp = bytes([3]) + x + long_ref + bytes([3]) + y + short8 + short8 + tail + _lzf_literals(z)
    raw_size = 3 * 4 * n
    head = (
        f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
        f"POINTS {n}\nDATA binary_compressed\n"
    )
    path = tmp_path / "d.pcd"
    path.write_bytes(head.encode() + struct.pack("<II", len(comp), raw_size) + comp)
    expected = np.column_stack([np.full(n, 1.5), np.full(n, 2.5), np.arange(n)])
    assert_allclose(read_point_cloud(path), expected)


def test_pcd_binary_compressed_corrupt_reference(tmp_path):
    # a reference before the start of the output
    comp = bytes([0]) + b"A" + bytes([(3 - 2) << 5 | 0, 9])
    head = "VERSION 0.7\nFIELDS x y z\nSIZE 1 1 1\nTYPE U U U\nCOUNT 1 1 1\nPOINTS 1\nDATA binary_compressed\n"
    path = tmp_path / "e.pcd"
    path.write_bytes(head.encode() + struct.pack("<II", len(comp), 3) + comp)
    with pytest.raises(FileFormatError, match=r"e\.pcd' byte \d+: corrupt compressed data"):
        read_point_cloud(path)


def test_pcd_truncated_binary_names_byte(make_cloud, tmp_path):
    path = tmp_path / "t.pcd"
    write_point_cloud(path, make_cloud(n=10), binary=True)
    data = path.read_bytes()
    path.write_bytes(data[:-5])
    size = len(data) - 5
    msg = f"read_point_cloud: {str(path)!r} byte {size}: file ends 5 bytes early"
    with pytest.raises(ValueError, match=re.escape(msg)):
        read_point_cloud(path)


def test_pcd_truncated_ascii_names_line(write_file, tmp_path):
    body = "1 2 3 0 0 0 1\n"
    path = write_file(tmp_path / "t.pcd", PCD_HEAD.format(n=3, kind="ascii") + body)
    with pytest.raises(ValueError, match=re.escape("line 12: file ends after 1 of 3 points (truncated)")):
        read_point_cloud(path)


def test_pcd_malformed_number_names_line(write_file, tmp_path):
    body = "1 2 3 0 0 0 1\n1 2 x 0 0 0 1\n"
    path = write_file(tmp_path / "m.pcd", PCD_HEAD.format(n=2, kind="ascii") + body)
    with pytest.raises(ValueError, match=re.escape(f"{path!r} line 13: malformed number in point 1")):
        read_point_cloud(path)


@pytest.mark.parametrize(
    "header, msg",
    [
        ("VERSION 0.7\nFIELDS x y z\n", "line 2: header ends before its DATA line"),
        ("FIELDS x y z\nSIZE 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n", "line 2: SIZE has 2 entries but FIELDS has 3"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA zip\n", "line 5: unknown DATA kind 'zip'"),
        ("FIELDS a b c\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n", "line 1: FIELDS lacks ['x', 'y', 'z']"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F Q\nPOINTS 1\nDATA ascii\n", "line 3: unsupported TYPE/SIZE Q/4"),
    ],
)
def test_pcd_malformed_header(write_file, tmp_path, header, msg):
    path = write_file(tmp_path / "h.pcd", header)
    with pytest.raises(ValueError, match=re.escape(msg)):
        read_point_cloud(path)



# --------------------------------------------------------------------------- LZF: compiled against pure Python


def _lzf_compress(data):
    """The fuzz script's greedy LZF encoder (3-byte hash, references up to 8 KiB back): one encoder for both."""
    import os
    import sys

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
    try:
        import fuzz_files
    finally:
        sys.path.pop(0)
    return fuzz_files._lzf_compress(data)


def _compressed_pcd(path, xyz, csize=None, usize=None, points=None):
    raw = b"".join(np.ascontiguousarray(xyz[:, k], dtype="<f4").tobytes() for k in range(3))
    comp = _lzf_compress(raw)
    n = len(xyz) if points is None else points
    head = f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary_compressed\n"
    path.write_bytes(head.encode() + struct.pack("<II", len(comp) if csize is None else csize,
                                                 len(raw) if usize is None else usize) + comp)
    return comp, raw


def test_lzf_compiled_matches_python_reference(tmp_path):
    from eppf.io import _pcd

    if _pcd._lzf_compiled is None:
        pytest.skip("eppf.io._pcd_fast is not compiled")
    rng = np.random.RandomState(0)
    # repetitive data gives long, short and overlapping references
    xyz = np.round(rng.normal(size=(3000, 3)), 1)
    xyz[::7] = 0.0
    comp, raw = _compressed_pcd(tmp_path / "l.pcd", xyz)
    assert len(comp) < len(raw) and any(b >= 32 for b in comp)  # back references are used
    got = _pcd.lzf_decompress(comp, len(raw), "x", "t", 0)
    ref = _pcd._lzf_python(comp, len(raw), "x", "t", 0)
    assert bytes(got) == ref == raw
    assert_array_equal(read_point_cloud(tmp_path / "l.pcd"), xyz.astype(np.float32))


def test_lzf_corrupt_streams_compiled_and_python_agree():
    from eppf.io import _pcd

    if _pcd._lzf_compiled is None:
        pytest.skip("eppf.io._pcd_fast is not compiled")
    raw = bytes(range(50)) * 20
    comp = _lzf_compress(raw)
    rng = np.random.RandomState(1)
    for _ in range(300):
        bad = bytearray(comp)
        k = rng.randint(len(bad))
        bad[k] = rng.randint(256)
        bad = bytes(bad[:rng.randint(1, len(bad) + 1)])
        outcomes = []
        for compiled in (_pcd._lzf_compiled, None):
            saved, _pcd._lzf_compiled = _pcd._lzf_compiled, compiled
            try:
                outcomes.append(bytes(_pcd.lzf_decompress(bad, len(raw), "x", "t", 0)))
            except FileFormatError as exc:
                # the same error at the same byte (the short-output wording differs)
                outcomes.append(str(exc).split(" (")[0] if "byte" in str(exc) else "short output")
            finally:
                _pcd._lzf_compiled = saved
        assert outcomes[0] == outcomes[1]


def test_lzf_declared_size_beyond_what_lzf_can_give(tmp_path):
    # PCL's 85-byte attack: a tiny block declaring 357913941 points of 12 bytes
    head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 357913941\nDATA binary_compressed\n"
    path = tmp_path / "bomb.pcd"
    path.write_bytes(head.encode() + struct.pack("<II", 4, 357913941 * 12 % 2 ** 32) + b"\x00abc")
    with pytest.raises(FileFormatError, match="bomb.pcd"):
        read_point_cloud(path)
    # the size matches the points but not the compressed block: refused before allocating
    head = head.replace("357913941", "1000000")
    path.write_bytes(head.encode() + struct.pack("<II", 4, 12_000_000) + b"\x00abc")
    with pytest.raises(FileFormatError, match=re.escape("the compressed block of 4 bytes declares 12000000 "
                                                        "uncompressed bytes, more than LZF can expand it to (88 x 4)")):
        read_point_cloud(path)


def test_lzf_longest_reference_is_within_the_ratio_bound():
    # a literal byte then long references of 264 bytes: the densest LZF stream
    from eppf.io import _pcd

    n_refs = 100
    comp = bytes([0, 7]) + bytes([7 << 5, 255, 0]) * n_refs
    expected = 1 + 264 * n_refs
    assert expected <= _pcd.LZF_MAX_RATIO * len(comp)
    assert bytes(_pcd.lzf_decompress(comp, expected, "x", "t", 0)) == bytes([7]) * expected


# --------------------------------------------------------------------------- hostile headers


@pytest.mark.parametrize(
    "header, body, msg",
    [
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 999999999999\nDATA ascii\n", "1 2 3\n",
         "the header declares 999999999999 points, more than the 6 bytes"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 99999999999\nDATA binary\n", "\0" * 24, "file ends"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS -1\nDATA binary\n", "", "negative POINTS count -1"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1e308\nDATA binary\n", "", "POINTS must be one integer"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS nan\nDATA binary\n", "", "POINTS must be one integer"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 2\nPOINTS 5\nDATA ascii\n", "1 2 3\n" * 6,
         "POINTS 5 differs from WIDTH x HEIGHT = 6"),
        ("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 0 1\nPOINTS 1\nDATA binary\n", "\0" * 8, "COUNT entries must lie in"),
        ("FIELDS x y x\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA binary\n", "\0" * 12, "FIELDS names a field twice"),
        ("FIELDS x y z\nSIZE 4 4 -4\nTYPE F F F\nPOINTS 1\nDATA binary\n", "\0" * 12, "unsupported TYPE/SIZE F/-4"),
    ],
)
def test_pcd_hostile_headers(tmp_path, header, body, msg):
    path = tmp_path / "h.pcd"
    path.write_bytes((header + body).encode("latin-1"))
    with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
        read_point_cloud(path)
    assert "h.pcd" in str(info.value)


def test_pcd_ascii_fast_path_matches_general_reader(make_cloud, tmp_path):
    from eppf.io import _pcd

    cloud = make_cloud(n=200)
    path = tmp_path / "a.pcd"
    write_point_cloud(path, cloud, binary=False)
    fast = read_point_cloud(path)
    saved = _pcd._parse_float_table
    try:
        _pcd._parse_float_table = None
        ref = read_point_cloud(path)
    finally:
        _pcd._parse_float_table = saved
    assert_array_equal(fast, ref)
    assert_allclose(fast, cloud, rtol=1e-6, atol=1e-6)


def test_pcd_ascii_values_are_rounded_to_their_declared_type(write_file, tmp_path):
    """An ASCII body is text, but a SIZE 4 field is float32: read as PCL (and Open3D) read it, and as the same
    cloud in binary reads, not as the float64 nearest to the text (PCL writes 8 significant digits)."""
    rows = [[0.1, 0.29552022, -1.5, 4278190080, 0, 0.9800666, 0.19866933], [1e-3, 2.5, 3, 0, 1, 0, 0]]
    body = "".join(" ".join(repr(v) for v in row) + "\n" for row in rows)
    ascii_path = write_file(tmp_path / "a.pcd", PCD_HEAD.format(n=2, kind="ascii") + body)
    rec = b"".join(struct.pack("<fffIfff", *row) for row in rows)
    binary_path = write_file(tmp_path / "b.pcd", PCD_HEAD.format(n=2, kind="binary").encode() + rec, "wb")
    cloud = read_point_cloud(ascii_path)
    expected = np.array(rows, dtype=np.float32)[:, [0, 1, 2, 4, 5, 6]].astype(np.float64)
    assert cloud.tobytes() == expected.tobytes()
    assert cloud.tobytes() == read_point_cloud(binary_path).tobytes()


@pytest.mark.parametrize("typ, size, value, shown", [
    ("I", 4, "nan", "nan"), ("I", 4, "1.5", "1.5"), ("I", 4, "7e10", "70000000000"), ("U", 1, "300", "300"),
    ("U", 1, "-1", "-1"), ("I", 2, "inf", "inf"), ("F", 4, "1e40", "1e+40"), ("F", 4, "-3.5e38", "-3.5e+38"),
])
def test_pcd_ascii_value_its_declared_type_cannot_hold_is_refused(write_file, tmp_path, typ, size, value, shown):
    # Rounding an ASCII column to its declared type must not wrap or overflow silently: NaN in an integer
    # field became -2147483648, 300 in a one-byte field 44, 1e40 in a float32 field an infinity (a dropped
    # point). Both readers name the field and the value.
    from eppf.io import read_point_fields

    head = (f"VERSION .7\nFIELDS x y z\nSIZE {size} {size} {size}\nTYPE {typ} {typ} {typ}\nCOUNT 1 1 1\n"
            "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n")
    path = write_file(tmp_path / "v.pcd", head + f"1 2 3\n4 {value} 6\n")
    msg = f"field 'y' (TYPE {typ} SIZE {size}) holds {shown}, which that type cannot hold"
    for reader in (read_point_cloud, read_point_fields):
        with pytest.raises(FileFormatError, match=re.escape(msg)):
            reader(path)


def test_pcd_ascii_values_at_their_types_limits_are_read(write_file, tmp_path):
    # The bounds themselves, NaN and infinities in a float field (PCL's invalid points), and a decimal
    # just above float32's largest value that rounds to it, all read.
    from eppf.io import read_point_fields

    head = ("VERSION .7\nFIELDS x y z i\nSIZE 4 4 4 1\nTYPE F F F U\nCOUNT 1 1 1 1\n"
            "WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n")
    path = write_file(tmp_path / "l.pcd", head + "3.4028235e38 -1 0 255\nnan inf 0 0\n1 2 3 7\n")
    points, fields = read_point_fields(path)
    assert points[0, 0] == float(np.finfo(np.float32).max) and np.isnan(points[1, 0]) and np.isinf(points[1, 1])
    assert_array_equal(fields["i"], np.array([255, 0, 7], dtype=np.uint8))
    assert_array_equal(read_point_cloud(path), [[np.finfo(np.float32).max, -1, 0], [1, 2, 3]])  # (NaN point dropped)


def test_pcd_headers_and_values_as_pcl_reads_them(write_file, tmp_path):
    # PCL's reader takes COLUMNS for FIELDS (PCD v.5), header entries separated by tabs, and ASCII values
    # separated by commas; these were refused ("no FIELDS line", "header ends before its DATA line",
    # "malformed number")
    from eppf.io import read_point_fields

    want = [[1, 2, 3], [4, 5, 6]]
    old = write_file(tmp_path / "v5.pcd", "# .PCD v.5 - Point Cloud Data file format\nVERSION .5\nCOLUMNS x y z\n"
                                          "SIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n")
    tabs = write_file(tmp_path / "tabs.pcd", "VERSION 0.7\nFIELDS\tx\ty\tz\tlabel\nSIZE\t4\t4\t4\t8\nTYPE\tF\tF\tF\tU\n"
                                             "COUNT\t1\t1\t1\t1\nWIDTH\t2\nHEIGHT\t1\nPOINTS\t2\nDATA\tascii\n"
                                             "1\t2\t3\t9007199254740993\n4\t5\t6\t7\n")
    commas = write_file(tmp_path / "commas.pcd", "VERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 8\nTYPE F F F U\n"
                                                 "COUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n"
                                                 "1,2,3,9007199254740993 # a comment: the general parser\n4,5,6,7\n")
    for path in (old, tabs, commas):
        assert_array_equal(read_point_cloud(path), want)
    for path in (tabs, commas):
        points, fields = read_point_fields(path)
        assert_array_equal(points, want)
        assert fields["label"].dtype == np.uint64 and fields["label"].tolist() == [9007199254740993, 7]
