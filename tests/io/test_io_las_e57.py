"""LAS/LAZ (laspy + lazrs) and E57 (pye57): coordinates and every field against those packages' own readers,
round trips, hostile headers bounded by the file's size, and the one-line hint when an extra is missing."""

import os
import re
import struct
import subprocess
import sys

import numpy as np
import pytest

from eppf.io import FileFormatError, read_point_cloud, read_point_fields, write_point_cloud, write_point_fields

laspy = pytest.importorskip("laspy")


def _las_file(path, n=200, fmt=3, seed=0, extra=True, version=None):
    """A LAS/LAZ file written by laspy: projected coordinates on a millimeter grid, every dimension filled."""
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=fmt, version=version)
    header.scales = np.array([0.001, 0.001, 0.01])
    header.offsets = np.array([512000.0, 5403000.0, 0.0])
    if extra:
        header.add_extra_dims([laspy.ExtraBytesParams("reflectance", "f4"), laspy.ExtraBytesParams("normal", "3f8"),
                               laspy.ExtraBytesParams("amplitude", "u2", scales=np.array([0.1]), offsets=np.array([5.0]))])
    las = laspy.LasData(header)
    las.points = laspy.ScaleAwarePointRecord.zeros(n, header=header)
    las.X = rng.integers(-10 ** 6, 10 ** 6, n)
    las.Y = rng.integers(-10 ** 6, 10 ** 6, n)
    las.Z = rng.integers(0, 5000, n)
    for dim in las.point_format.dimensions:
        if dim.name in ("X", "Y", "Z") or not dim.is_standard:
            continue
        values = las[dim.name]
        if dim.kind.name == "BitField":
            las[dim.name] = rng.integers(0, 2 ** dim.num_bits, n)
        elif np.asarray(values).dtype.kind == "f":
            las[dim.name] = rng.normal(size=n) * 1e5
        else:
            info = np.iinfo(np.asarray(values).dtype)
            las[dim.name] = rng.integers(max(info.min, -100), min(info.max, 30000), n)
    if extra:
        las.reflectance = rng.normal(size=n).astype("f4")
        las.normal = rng.normal(size=(n, 3))
        las.amplitude = 5.0 + 0.1 * rng.integers(0, 1000, n)
    las.write(str(path))
    return laspy.read(str(path))


@pytest.mark.parametrize("ext", ["las", "laz"])
@pytest.mark.parametrize("fmt", [0, 3, 6, 8])
def test_las_every_field_as_laspy_reads_it(tmp_path, ext, fmt):
    path = tmp_path / f"tile.{ext}"
    las = _las_file(path, fmt=fmt)
    points, fields = read_point_fields(path)
    assert points.dtype == np.float64
    for k, axis in enumerate("xyz"):
        np.testing.assert_array_equal(points[:, k], np.asarray(las[axis]))  # bit for bit, millimeters kept
    names = [n for n in las.point_format.dimension_names if n not in ("X", "Y", "Z")]
    assert list(fields) == names and names[-3:] == ["reflectance", "normal", "amplitude"]
    for name in names:
        np.testing.assert_array_equal(fields[name], np.asarray(las[name]), err_msg=name)
    assert fields["normal"].shape == (200, 3) and fields["amplitude"].dtype == np.float64
    np.testing.assert_array_equal(read_point_cloud(path), points)


@pytest.mark.parametrize("ext", ["las", "laz"])
def test_las_round_trip_bit_for_bit(tmp_path, ext):
    las = _las_file(tmp_path / f"a.{ext}", fmt=7)
    points, fields = read_point_fields(tmp_path / f"a.{ext}")
    write_point_fields(tmp_path / f"b.{ext}", points, fields)
    again = laspy.read(str(tmp_path / f"b.{ext}"))
    assert again.point_format.id == 7 and again.header.are_points_compressed == (ext == "laz")
    points2, fields2 = read_point_fields(tmp_path / f"b.{ext}")
    assert points2.tobytes() == points.tobytes() and list(fields2) == list(fields)
    for name in fields:
        assert fields2[name].tobytes() == fields[name].tobytes() and fields2[name].dtype == fields[name].dtype, name
    assert las.header.point_count == again.header.point_count


@pytest.mark.parametrize("ext", ["las", "laz"])
def test_a_scene_of_no_points_writes_an_empty_las_file(tmp_path, ext):
    write_point_fields(tmp_path / f"e.{ext}", np.zeros((0, 3)), {"intensity": np.zeros(0, np.uint16)})
    assert laspy.read(str(tmp_path / f"e.{ext}")).header.point_count == 0
    points, fields = read_point_fields(tmp_path / f"e.{ext}")
    assert points.shape == (0, 3) and fields["intensity"].shape == (0,)


def test_las_writer_chooses_the_point_format(tmp_path):
    pts = np.array([[1.5, 2.25, 3.0], [4.0, 5.0, 6.125]])
    write_point_fields(tmp_path / "a.las", pts, {"classification": np.array([2, 31])})
    assert laspy.read(str(tmp_path / "a.las")).point_format.id == 0
    write_point_fields(tmp_path / "b.las", pts, {"classification": np.array([2, 200]), "segment": np.array([0, 1])})
    las = laspy.read(str(tmp_path / "b.las"))
    assert las.point_format.id == 6 and las.classification.tolist() == [2, 200] and las.segment.tolist() == [0, 1]
    assert np.asarray(las.x).tolist() == [1.5, 4.0]
    with pytest.raises(ValueError, match="field 'intensity'.*does not fit LAS's intensity"):
        write_point_fields(tmp_path / "c.las", pts, {"intensity": np.array([0.5, 1.5])})
    with pytest.raises(ValueError, match="hold 1 to 3 values per point; field 'f' has 4"):
        write_point_fields(tmp_path / "d.las", pts, {"f": np.zeros((2, 4))})
    with pytest.raises(ValueError, match="points must be finite"):
        write_point_fields(tmp_path / "e.las", np.full((2, 3), np.nan))


def test_las_coordinates_off_any_decimal_grid_move_by_at_most_half_the_scale(tmp_path):
    pts = np.random.default_rng(0).uniform(0, 1000, size=(50, 3)) + [6.5e5, 5.4e6, 0]
    write_point_fields(tmp_path / "g.las", pts)
    header = laspy.read(str(tmp_path / "g.las")).header
    back = read_point_fields(tmp_path / "g.las")[0]
    assert np.all(np.abs(back - pts) <= header.scales / 2 * (1 + 1e-9))


def test_write_point_cloud_las_keeps_normals(tmp_path):
    cloud = np.hstack([np.random.default_rng(1).normal(size=(20, 3)), np.tile([0.0, 0.6, 0.8], (20, 1))])
    write_point_cloud(tmp_path / "n.laz", cloud)
    np.testing.assert_allclose(read_point_cloud(tmp_path / "n.laz"), cloud, rtol=0, atol=1e-8)  # a 1e-8 grid


def test_load_folder_of_las_files(tmp_path):
    from eppf.datasets import load_folder

    for cls in ("pole", "car"):
        (tmp_path / cls).mkdir()
        for k in range(2):
            _las_file(tmp_path / cls / f"{k}.las", n=30, seed=k, extra=False)
    data = load_folder(tmp_path)
    assert sorted(set(data.target_names)) == ["car", "pole"] and len(data.data) == 4
    assert all(c.shape == (30, 3) and c.dtype == np.float64 for c in data.data)


# --------------------------------------------------------------------------- hostile headers


def _patched(tmp_path, src, name, edits):
    data = bytearray(open(src, "rb").read())
    for fmt, offset, value in edits:
        offset = offset(data) if callable(offset) else offset
        struct.pack_into(fmt, data, offset, value)
    path = tmp_path / name
    path.write_bytes(bytes(data))
    return path


def _offset_to_points(data):
    return struct.unpack_from("<I", data, 96)[0]


def _chunk_table(data):
    return struct.unpack_from("<q", data, _offset_to_points(data))[0]


@pytest.mark.parametrize("ext, edits, msg", [
    ("las", [("<I", 107, 10 ** 9)], "declares 1000000000 points of 34 bytes"),
    ("las", [("<I", 96, 10 ** 9)], "offset to the point data 1000000000 outside"),
    ("las", [("<H", 105, 20)], "point record length 20 is below the 34 bytes of point format 3"),
    ("las", [("<B", 104, 42)], "unknown point format 42"),
    ("las", [("<I", 100, 4 * 10 ** 9)], "VLR 0 of 4000000000 does not fit before the point data"),
    ("las", [("<H", 94, 60000)], "header size 60000 outside"),
    ("laz", [("<q", _offset_to_points, 10 ** 12)], "LAZ chunk table offset 1000000000000 outside"),
    ("las", [("<d", 131, 0.0)], "byte 131: x scale factor 0.0 .a LAS header's must be finite and non-zero"),
    ("laz", [("<d", 147, float("nan"))], "byte 147: z scale factor nan"),
    ("las", [("<d", 139, float("-inf"))], "byte 139: y scale factor -inf"),
    ("las", [("<d", 131, 1e300)], "byte 155: x offset .* with scale factor 1e.300 gives no finite coordinates"),
    ("las", [("<d", 163, float("inf"))], "byte 163: y offset inf"),
    ("laz", [("<I", lambda d: _chunk_table(d) + 4, 2 ** 31)], "declares 2147483648 chunks"),
])
def test_hostile_las_headers_are_refused_before_allocating(tmp_path, ext, edits, msg):
    src = tmp_path / f"src.{ext}"
    _las_file(src, n=300, fmt=3, extra=False)
    path = _patched(tmp_path, src, f"bad.{ext}", edits)
    for reader in (read_point_cloud, read_point_fields):
        with pytest.raises(FileFormatError, match=f"bad.{ext}.*{msg}"):
            reader(path)


def test_hostile_extra_bytes_and_laz_counts(tmp_path):
    src = tmp_path / "src.las"
    _las_file(src, n=50, fmt=1)
    data = bytearray(src.read_bytes())
    k = data.find(b"LASF_Spec")
    struct.pack_into("<B", data, k - 2 + 54 + 2, 29)  # first descriptor: 3 x float64 = 24 bytes, beyond the record
    (tmp_path / "eb.las").write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match="eb.las.*extra-bytes descriptors describe"):
        read_point_fields(tmp_path / "eb.las")
    # a LAZ count far beyond its data: decoded in bounded pieces, refused when the data ends
    _las_file(tmp_path / "src.laz", n=300, fmt=3, extra=False, version="1.4")
    path = _patched(tmp_path, tmp_path / "src.laz", "many.laz", [("<Q", 247, 10 ** 12), ("<I", 107, 0)])
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (1 << 31, 1 << 31)); "
            "from eppf.io import read_point_fields, FileFormatError\n"
            f"try:\n    read_point_fields({str(path)!r})\nexcept FileFormatError as e:\n    print('refused', e)")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "refused" in run.stdout and "many.laz" in run.stdout, run.stdout + run.stderr


# --------------------------------------------------------------------------- a missing extra


@pytest.mark.parametrize("name, blocked, extra", [("a.las", ["laspy"], "las"), ("a.laz", ["laspy"], "las"),
                                                  ("a.e57", ["pye57", "pye57.libe57"], "e57")])
def test_missing_extra_gives_one_line_naming_it(tmp_path, monkeypatch, name, blocked, extra):
    path = tmp_path / name
    if name.endswith(".e57"):
        _e57_file(path)
    else:
        _las_file(path, n=10, extra=False)
    for module in blocked:
        monkeypatch.setitem(sys.modules, module, None)  # import fails as if not installed
    for reader in (read_point_cloud, read_point_fields):
        with pytest.raises(ImportError) as info:
            reader(path)
        message = str(info.value)
        assert "\n" not in message and f"pip install 'eppf[{extra}]'" in message and name in message


def test_base_install_imports_no_optional_reader():
    code = "import sys, eppf.io; print(sorted(m for m in ('laspy', 'lazrs', 'pye57') if m in sys.modules))"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.stdout.strip() == "[]", run.stderr


# --------------------------------------------------------------------------- E57


def _e57_file(path, translation=(100.0, -20.0, 3.0)):
    pye57 = pytest.importorskip("pye57")
    rng = np.random.default_rng(0)
    scans = []
    with pye57.E57(str(path), mode="w") as e57:
        for k in range(2):
            n = 40 + k
            data = {"cartesianX": rng.normal(size=n), "cartesianY": rng.normal(size=n), "cartesianZ": rng.normal(size=n),
                    "intensity": rng.uniform(0, 1, n), "cartesianInvalidState": np.where(np.arange(n) == 5, 2, 0).astype("i1")}
            rotation = np.array([np.cos(0.3), 0, 0, np.sin(0.3)]) if k else np.array([1.0, 0, 0, 0])
            e57.write_scan_raw(data, rotation=rotation, translation=np.array(translation) * k)
            scans.append(data)
    return scans


def test_e57_points_and_fields_as_pye57_reads_them(tmp_path):
    pye57 = pytest.importorskip("pye57")
    path = tmp_path / "scan.e57"
    _e57_file(path)
    points, fields = read_point_fields(path)
    e57 = pye57.E57(str(path))
    want = [e57.read_scan(k, intensity=True, transform=True, ignore_missing_fields=True) for k in range(2)]
    raw = [e57.read_scan_raw(k) for k in range(2)]
    e57.close()
    assert points.shape == (81, 3) and list(fields) == ["intensity", "cartesianInvalidState", "scan_index"]
    assert fields["scan_index"].tolist() == [0] * 40 + [1] * 41
    np.testing.assert_array_equal(fields["intensity"], np.concatenate([r["intensity"] for r in raw]))
    valid = fields["cartesianInvalidState"] == 0
    assert valid.sum() == 79
    expected = np.concatenate([np.column_stack([w[f"cartesian{a}"] for a in "XYZ"]) for w in want])
    np.testing.assert_allclose(points[valid], expected, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(read_point_cloud(path), points[valid])


def _e57_scan(libe57, imf, serial):
    """The one data3D scan of a new E57 file ``imf``, whose root gets a format name, version 1.0 and a guid
    ending in ``serial`` (the scan's: ``serial`` + 1)."""
    root = imf.root()
    root.set("formatName", libe57.StringNode(imf, "ASTM E57 3D Imaging Data File"))
    root.set("guid", libe57.StringNode(imf, "{6107aa1c-0000-4000-8000-%012d}" % serial))
    root.set("versionMajor", libe57.IntegerNode(imf, 1))
    root.set("versionMinor", libe57.IntegerNode(imf, 0))
    data3d = libe57.VectorNode(imf, True)
    root.set("data3D", data3d)
    scan = libe57.StructureNode(imf)
    data3d.append(scan)
    scan.set("guid", libe57.StringNode(imf, "{6107aa1c-0000-4000-8000-%012d}" % (serial + 1)))
    return scan


def _e57_with_normals(path, xyz, normals, quaternion, translation, invalid=None):
    """One scan with the E57 surface-normals extension (``nor:normalX/Y/Z``), written through libE57Format's
    own node API (pye57's writer knows no extension fields)."""
    libe57 = pytest.importorskip("pye57.libe57")
    imf = libe57.ImageFile(str(path), "w")
    try:
        imf.extensionsAdd("nor", "http://www.libe57.org/E57_NOR_surface_normals.txt")
        scan = _e57_scan(libe57, imf, 1)
        pose, rot, tr = libe57.StructureNode(imf), libe57.StructureNode(imf), libe57.StructureNode(imf)
        scan.set("pose", pose)
        pose.set("rotation", rot)
        pose.set("translation", tr)
        for c, v in zip("wxyz", quaternion):
            rot.set(c, libe57.FloatNode(imf, float(v)))
        for c, v in zip("xyz", translation):
            tr.set(c, libe57.FloatNode(imf, float(v)))
        names = ["cartesianX", "cartesianY", "cartesianZ", "nor:normalX", "nor:normalY", "nor:normalZ"]
        cols = [np.ascontiguousarray(xyz[:, k], dtype=np.float64) for k in range(3)] + \
               [np.ascontiguousarray(normals[:, k], dtype=np.float32) for k in range(3)]
        proto = libe57.StructureNode(imf)
        for n in names:
            proto.set(n, libe57.FloatNode(imf, 0.0, libe57.E57_DOUBLE if n[0] == "c" else libe57.E57_SINGLE))
        if invalid is not None:
            names.append("cartesianInvalidState")
            cols.append(np.ascontiguousarray(invalid, dtype=np.int8))
            proto.set("cartesianInvalidState", libe57.IntegerNode(imf, 0, 0, 2))
        points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
        scan.set("points", points)
        buffers = libe57.VectorSourceDestBuffer()
        for n, c in zip(names, cols):
            buffers.append(libe57.SourceDestBuffer(imf, n, c, len(c), True, True))
        writer = points.writer(buffers)
        writer.write(len(cols[0]))
        writer.close()
    finally:
        imf.close()


def test_e57_normals_extension_read_as_normals_and_turned_by_the_pose(tmp_path):
    pye57 = pytest.importorskip("pye57")
    path = tmp_path / "normals.e57"
    xyz = np.array([[1.0, 2, 3], [4, 5, 6], [-1, 0.5, 2], [7, 7, 7]])
    normals = np.array([[0, 0, 1.0], [0, 1, 0], [0.6, 0.8, 0], [1, 0, 0]])
    half = np.sqrt(0.5)
    _e57_with_normals(path, xyz, normals, [half, 0, 0, half], [10, 20, 30], invalid=[0, 0, 0, 2])
    cloud = read_point_cloud(path)
    assert cloud.shape == (3, 6)  # the point marked invalid is dropped with its normal
    e57 = pye57.E57(str(path))
    placed = e57.read_scan(0, transform=True, ignore_missing_fields=True)
    e57.close()
    valid = slice(0, 3)
    np.testing.assert_allclose(cloud[:, :3], np.column_stack([placed[f"cartesian{a}"] for a in "XYZ"])[valid],
                               rtol=0, atol=1e-12)
    # a quarter turn about z takes (x, y, z) to (-y, x, z): by hand, not through the reader's rotation
    turned = np.column_stack([-normals[:, 1], normals[:, 0], normals[:, 2]])[valid]
    np.testing.assert_allclose(cloud[:, 3:], turned, rtol=0, atol=1e-7)
    assert read_point_cloud(path, normals=False).tobytes() == cloud[:, :3].copy().tobytes()
    points, fields = read_point_fields(path)  # fields in the points' frame too
    np.testing.assert_allclose(np.column_stack([fields[f"nor:normal{a}"] for a in "XYZ"])[valid], turned,
                               rtol=0, atol=1e-7)


def test_e57_without_normals_refuses_normals_true(tmp_path):
    path = tmp_path / "scan.e57"
    _e57_file(path)
    assert read_point_cloud(path).shape[1] == 3
    with pytest.raises(FileFormatError, match="scan.e57.* has no normals"):
        read_point_cloud(path, normals=True)


def test_e57_truncated_or_not_e57(tmp_path):
    path = tmp_path / "scan.e57"
    _e57_file(path)
    data = path.read_bytes()
    (tmp_path / "cut.e57").write_bytes(data[:-1024])
    with pytest.raises(FileFormatError, match="cut.e57.*the header declares .* bytes, but the file has"):
        read_point_fields(tmp_path / "cut.e57")
    (tmp_path / "flip.e57").write_bytes(data[:2000] + bytes([data[2000] ^ 4]) + data[2001:])
    with pytest.raises(FileFormatError, match="flip.e57"):
        read_point_cloud(tmp_path / "flip.e57")
    (tmp_path / "no.e57").write_bytes(b"LASF" + data[4:])
    with pytest.raises(FileFormatError, match="no.e57.*not an E57 file"):
        read_point_cloud(tmp_path / "no.e57")


def test_hostile_laz_layer_size_is_refused_before_lazrs_reserves_it(tmp_path):
    """LAZ 1.4 chunks declare each layer's size, which lazrs reserves before reading: a size beyond the chunk
    would abort the process (found by scripts/fuzz_files.py); it is refused first."""
    _las_file(tmp_path / "src.laz", n=300, fmt=6, extra=False, version="1.4")
    record = struct.unpack_from("<H", (tmp_path / "src.laz").read_bytes(), 105)[0]
    path = _patched(tmp_path, tmp_path / "src.laz", "layer.laz",
                    [("<I", lambda d: _offset_to_points(d) + 8 + record + 4, 4 * 10 ** 9)])
    with pytest.raises(FileFormatError, match="layer.laz.*the layers of LAZ chunk 0 declare"):
        read_point_fields(path)
    np.testing.assert_array_equal(read_point_fields(tmp_path / "src.laz")[0], np.asarray(
        [laspy.read(str(tmp_path / "src.laz"))[a] for a in "xyz"]).T)


def test_hostile_e57_record_count_is_refused_before_allocating(tmp_path):
    """A scan's recordCount beyond what the file's bytes can hold, with the page checksum made valid again."""
    pye57 = pytest.importorskip("pye57")
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                                    "scripts"))
    try:
        from fuzz_files import e57_fix_checksums
    finally:
        sys.path.pop(0)
    n = 100000
    rng = np.random.default_rng(0)
    path = tmp_path / "big.e57"
    with pye57.E57(str(path), mode="w") as e57:
        e57.write_scan_raw({f"cartesian{a}": rng.normal(size=n) for a in "XYZ"})
    data = path.read_bytes()
    assert data.count(b'recordCount="100000"') == 1
    for count, msg in ((b"999999", "scan 0 declares 999999 points of 96 bits, more than the file's"),
                       (b"100001", "scan 0 ends after 100000 of 100001 points|malformed E57")):
        bad = tmp_path / f"count{count.decode()}.e57"
        bad.write_bytes(e57_fix_checksums(data.replace(b'recordCount="100000"', b'recordCount="' + count + b'"')))
        with pytest.raises(FileFormatError, match=f"count{count.decode()}.e57.*({msg})"):
            read_point_fields(bad)
    assert read_point_fields(path)[0].shape == (n, 3)


def test_las_extra_bytes_of_one_column(tmp_path):
    column = np.arange(2, dtype=np.int16).reshape(2, 1)
    write_point_fields(tmp_path / "o.las", np.ones((2, 3)), {"v": column})
    got = read_point_fields(tmp_path / "o.las")[1]["v"]
    assert got.dtype == np.int16 and got.tolist() == [0, 1]


def test_hostile_laz_chunk_size_is_refused(tmp_path):
    """A laszip VLR declaring 3e9 points per chunk made lazrs's parallel decoder allocate 87 GB and abort
    (found by scripts/fuzz_files.py); a chunk may hold 50,000 points or 64 times the file's size."""
    _las_file(tmp_path / "src.laz", n=100, fmt=1, extra=False)
    path = _patched(tmp_path, tmp_path / "src.laz", "chunk.laz",
                    [("<I", lambda d: d.find(b"laszip encoded") - 2 + 54 + 12, 3_099_803_465)])
    with pytest.raises(FileFormatError, match="chunk.laz.*LAZ chunk 0 declares 3099803465 points"):
        read_point_fields(path)


@pytest.mark.parametrize("compressor, msg", [
    (1, "the LAZ file uses LASzip 1.x's point-wise compressor (compressor 1, without chunks), which the lazrs backend cannot"),
    (0, "unknown LAZ compressor 0 in the laszip VLR"),
    (7, "unknown LAZ compressor 7 in the laszip VLR"),
])
def test_laz_of_a_compressor_lazrs_cannot_decode_is_refused_naming_it(tmp_path, compressor, msg):
    """LASzip 1.x wrote point-wise LAZ without chunks (compressor 1; PDAL's test data has one,
    simple-laszip-compressor-version-1.2r0.laz): its first point bytes were read as a chunk table offset and
    refused as 'LAZ chunk table offset ... outside'. The laszip VLR's compressor is checked first."""
    _las_file(tmp_path / "src.laz", n=50, fmt=1, extra=False)
    path = _patched(tmp_path, tmp_path / "src.laz", "old.laz",
                    [("<H", lambda d: d.find(b"laszip encoded") - 2 + 54, compressor)])
    for read in (read_point_cloud, read_point_fields):
        with pytest.raises(FileFormatError, match=r"old\.laz' byte \d+: .*" + re.escape(msg)):
            read(path)
    assert read_point_fields(tmp_path / "src.laz")[0].shape == (50, 3)


def _e57_spherical(path, columns):
    """One scan of spherical coordinates (pye57's writer takes cartesian ones only), through libE57Format's
    node API: float64 range, azimuth and elevation, then int8 ``sphericalInvalidState`` if given."""
    libe57 = pytest.importorskip("pye57.libe57")
    imf = libe57.ImageFile(str(path), "w")
    try:
        scan = _e57_scan(libe57, imf, 3)
        proto = libe57.StructureNode(imf)
        cols = {}
        for name, values in columns.items():
            if name.endswith("InvalidState"):
                proto.set(name, libe57.IntegerNode(imf, 0, 0, 2))
                cols[name] = np.ascontiguousarray(values, dtype=np.int8)
            else:
                proto.set(name, libe57.FloatNode(imf, 0.0))
                cols[name] = np.ascontiguousarray(values, dtype=np.float64)
        points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
        scan.set("points", points)
        buffers = libe57.VectorSourceDestBuffer()
        for name, c in cols.items():
            buffers.append(libe57.SourceDestBuffer(imf, name, c, len(c), True, True))
        writer = points.writer(buffers)
        writer.write(len(next(iter(cols.values()))))
        writer.close()
    finally:
        imf.close()


def test_e57_spherical_points_marked_invalid_are_dropped(tmp_path):
    # only cartesianInvalidState was looked at: a spherical scan's invalid points (range 0) came back as the
    # scanner's origin
    path = tmp_path / "spherical.e57"
    half = np.pi / 2
    _e57_spherical(path, {"sphericalRange": [1.0, 2, 3, 0, 5], "sphericalAzimuth": [0, half, 0, 0, np.pi],
                          "sphericalElevation": [0, 0, half, 0, 0], "sphericalInvalidState": [0, 0, 0, 2, 1]})
    cloud = read_point_cloud(path)
    np.testing.assert_allclose(cloud, [[1, 0, 0], [0, 2, 0], [0, 0, 3]], rtol=0, atol=1e-15)
    points, fields = read_point_fields(path)  # every point, as the file holds them
    assert points.shape == (5, 3) and fields["sphericalInvalidState"].tolist() == [0, 0, 0, 2, 1]
    np.testing.assert_array_equal(points[:3], cloud)


def test_e57_errors_of_libe57format_are_one_line(tmp_path):
    # libE57Format's messages go on with a blank line and a "**** Got an e57 exception" report of debug
    # context; the FileFormatError keeps the reason
    path = tmp_path / "scan.e57"
    _e57_file(path)
    data = bytearray(path.read_bytes())
    data[1500] ^= 0xFF  # inside the first page: its checksum no longer matches
    (tmp_path / "crc.e57").write_bytes(bytes(data))
    with pytest.raises(FileFormatError) as info:
        read_point_cloud(tmp_path / "crc.e57")
    message = str(info.value)
    assert "crc.e57" in message and "\n" not in message and "****" not in message
    assert message.endswith("malformed E57 file (checksum mismatch, file is corrupted (ErrorBadChecksum))")


def test_e57_invalid_points_of_one_scan_are_dropped_when_another_scan_has_no_state(tmp_path):
    # the state was looked up among the fields every scan has: a second scan without one kept the first's
    # invalid points
    pye57 = pytest.importorskip("pye57")
    path = tmp_path / "two.e57"
    with pye57.E57(str(path), mode="w") as e57:
        e57.write_scan_raw({"cartesianX": np.array([1.0, 2.0]), "cartesianY": np.zeros(2), "cartesianZ": np.zeros(2),
                            "cartesianInvalidState": np.array([0, 2], dtype=np.int8)})
        e57.write_scan_raw({"cartesianX": np.array([3.0]), "cartesianY": np.zeros(1), "cartesianZ": np.zeros(1)})
    np.testing.assert_array_equal(read_point_cloud(path), [[1, 0, 0], [3, 0, 0]])
    points, fields = read_point_fields(path)
    assert points.shape == (3, 3) and list(fields) == ["scan_index"]
