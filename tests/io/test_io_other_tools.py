"""LAS/LAZ and E57 files written by other tools (TerraScan, LAStools, LASzip 1.2, PDAL, Global Mapper, YellowScan,
libE57Format, pye57; see tests/data/README.md): read as laspy/pye57 read them, and LAS/LAZ round trips."""

import os

import numpy as np
import pytest

from eppf.io import read_point_cloud, read_point_fields, write_point_fields

DATA = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data")
LAS_DIR = os.path.join(DATA, "las_other_tools")
E57_DIR = os.path.join(DATA, "e57_other_tools")

# file: (LAS version, point format, points, extra-bytes names, read -> write -> read is bit for bit)
LAS_FILES = {
    "simple.las": ("1.2", 3, 1065, [], True),  # TerraScan
    "simple.laz": ("1.2", 3, 1065, [], True),  # the same points as LAZ (LASzip compression)
    "simple1_1.las": ("1.1", 1, 1065, [], True),  # LAStools las2las
    "simple1_3.las": ("1.3", 4, 999, [], True),  # ALSXX, wave packet fields
    "test1_4.las": ("1.4", 6, 1000, [], False),  # Global Mapper: scales 1.16e-6 are off any decimal grid
    "extra.laz": ("1.4", 3, 1065, ["Colors", "Reserved", "Flags", "Intensity", "Time"], False),  # PDAL 1.0
    "plane.laz": ("1.2", 3, 28185, [], True),  # PDAL 1.6
    "fullwave.laz": ("1.4", 10, 10750, [], True),  # YellowScan: format 10 (format 8's fields + wave packets)
}


@pytest.mark.parametrize("name", sorted(LAS_FILES))
def test_las_of_other_tools_read_as_laspy_reads_them(name):
    laspy = pytest.importorskip("laspy")
    if name.endswith(".laz") and not laspy.LazBackend.detect_available():
        pytest.skip("no LAZ backend (lazrs) installed")
    version, fmt, count, extra, _ = LAS_FILES[name]
    path = os.path.join(LAS_DIR, name)
    las = laspy.read(path)
    assert str(las.header.version) == version and las.point_format.id == fmt  # the file is what we think it is
    points, fields = read_point_fields(path)
    assert points.shape == (count, 3) and points.dtype == np.float64
    for k, axis in enumerate("xyz"):
        assert points[:, k].tobytes() == np.asarray(las[axis], dtype=np.float64).tobytes(), axis
    names = [n for n in las.point_format.dimension_names if n not in ("X", "Y", "Z")]
    assert list(fields) == names and names[len(names) - len(extra):] == extra
    for field in names:
        want = np.asarray(las[field])
        assert fields[field].dtype == want.dtype and fields[field].tobytes() == want.tobytes(), field
    assert read_point_cloud(path).tobytes() == points.tobytes()


@pytest.mark.parametrize("name", sorted(n for n, spec in LAS_FILES.items() if spec[-1]))
def test_las_of_other_tools_round_trip_bit_for_bit(tmp_path, name):
    laspy = pytest.importorskip("laspy")
    if not laspy.LazBackend.detect_available():
        pytest.skip("no LAZ backend (lazrs) installed")
    points, fields = read_point_fields(os.path.join(LAS_DIR, name))
    for ext in ("las", "laz"):
        out = tmp_path / f"again.{ext}"
        write_point_fields(out, points, fields)
        assert laspy.read(str(out)).point_format.id == LAS_FILES[name][1]
        points2, fields2 = read_point_fields(out)
        assert points2.tobytes() == points.tobytes() and list(fields2) == list(fields)
        for field in fields:
            assert fields2[field].dtype == fields[field].dtype, field
            assert fields2[field].tobytes() == fields[field].tobytes(), field


def test_las_off_a_decimal_grid_round_trips_within_half_the_written_scale(tmp_path):
    laspy = pytest.importorskip("laspy")
    points, fields = read_point_fields(os.path.join(LAS_DIR, "test1_4.las"))
    write_point_fields(tmp_path / "again.las", points, fields)
    header = laspy.read(str(tmp_path / "again.las")).header
    points2, fields2 = read_point_fields(tmp_path / "again.las")
    assert np.all(np.abs(points2 - points) <= header.scales / 2 * (1 + 1e-9))
    for field in fields:
        assert fields2[field].tobytes() == fields[field].tobytes(), field


def test_las_extra_bytes_of_more_than_three_values_are_refused_on_write_naming_the_field(tmp_path):
    pytest.importorskip("laspy")
    points, fields = read_point_fields(os.path.join(LAS_DIR, "extra.laz"))
    assert fields["Reserved"].shape == (1065, 7)  # LAS 1.4's deprecated array of 7 values
    with pytest.raises(ValueError, match="field 'Reserved' has 7"):
        write_point_fields(tmp_path / "again.laz", points, fields)
    del fields["Reserved"]
    write_point_fields(tmp_path / "again.laz", points, fields)
    points2, fields2 = read_point_fields(tmp_path / "again.laz")
    assert points2.tobytes() == points.tobytes() and list(fields2) == list(fields)
    for field in fields:
        assert fields2[field].tobytes() == fields[field].tobytes(), field


@pytest.mark.parametrize("name, translation", [("testWithNormals.e57", [0.0, 0.0, 0.0]),
                                               ("translationWithoutRotation.e57", [4.0, 5.0, 6.0])])
def test_e57_of_other_tools_read_as_pye57_reads_them(name, translation):
    pye57 = pytest.importorskip("pye57")
    path = os.path.join(E57_DIR, name)
    e57 = pye57.E57(path)
    try:
        assert e57.scan_count == 1
        header = e57.get_header(0)
        np.testing.assert_array_equal(header.translation, translation)
        raw = e57.read_scan_raw(0, ignore_unsupported_fields=True)  # pye57 does not read the normals extension
        placed = e57.read_scan(0, transform=True, ignore_missing_fields=True)
    finally:
        e57.close()
    points, fields = read_point_fields(path)
    expected = np.column_stack([placed[f"cartesian{a}"] for a in "XYZ"])
    assert points.tobytes() == expected.tobytes()
    np.testing.assert_array_equal(points - translation, np.column_stack([raw[f"cartesian{a}"] for a in "XYZ"]))
    assert read_point_cloud(path, normals=False).tobytes() == points.tobytes()
    if name == "testWithNormals.e57":
        assert list(fields) == ["nor:normalX", "nor:normalY", "nor:normalZ"]
        normals = np.column_stack([fields[f"nor:normal{a}"] for a in "XYZ"]).astype(np.float64)
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
        np.testing.assert_allclose(normals, [[0, 0, 1], [0, 1, 0]], atol=1e-3)
        cloud = read_point_cloud(path)  # the extension's normals are the cloud's normals
        assert cloud.shape == (2, 6) and cloud[:, :3].tobytes() == points.tobytes()
        assert cloud[:, 3:].tobytes() == normals.tobytes()
    else:
        assert fields == {}
        assert read_point_cloud(path).tobytes() == points.tobytes()


def test_laz_of_laszip_1_2_point_wise_compressor_is_refused_naming_it():
    # LASzip 1.x's point-wise LAZ has no chunk table: its first point bytes were taken for the table's offset
    # and the file refused as "LAZ chunk table offset 364654882546516200 outside 341..22141"
    laspy = pytest.importorskip("laspy")
    if not laspy.LazBackend.detect_available():
        pytest.skip("no LAZ backend (lazrs) installed")
    path = os.path.join(LAS_DIR, "simple-laszip-compressor-version-1.2r0.laz")
    for read in (read_point_cloud, read_point_fields):
        with pytest.raises(ValueError) as info:
            read(path)
        assert str(info.value) == (
            f"{read.__name__}: {path!r} byte 281: the LAZ file uses LASzip 1.x's point-wise compressor (compressor 1, "
            "without chunks), which the lazrs backend cannot decompress; recompress it with a current LASzip "
            "(laszip, PDAL)")
