"""read_point_fields / write_point_fields: every per-point field of PCD, PLY, LAS/LAZ, E57 and text tables,
compared with files and readers of other tools (PCL, plyfile, laspy, pye57), and read -> write -> read bit for bit."""

import os
import struct

import numpy as np
import pytest

from eppf.io import FileFormatError, read_point_cloud, read_point_fields, write_point_fields

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "pcd_pcl")


def _same(a, b):
    """Equal shape, dtype and bytes (NaN payloads included)."""
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _assert_round_trip(path, tmp_path, ext):
    points, fields = read_point_fields(path)
    out = str(tmp_path / f"again.{ext}")
    write_point_fields(out, points, fields)
    points2, fields2 = read_point_fields(out)
    assert _same(points, points2)
    assert list(fields2) == list(fields)
    for name in fields:
        assert _same(fields[name], fields2[name]), name
    return points, fields


# --------------------------------------------------------------------------- PCD written by PCL


@pytest.mark.parametrize("name", sorted(f for f in os.listdir(DATA) if f.endswith(".pcd")))
def test_pcd_written_by_pcl_round_trips_bit_for_bit(name, tmp_path):
    points, fields = _assert_round_trip(os.path.join(DATA, name), tmp_path, "pcd")
    assert "_" not in fields and not any(n.startswith("_") for n in fields)


def test_pcd_fields_agree_across_pcl_data_kinds():
    """PCL wrote one cloud as ascii, binary and binary_compressed: every field reads the same from each."""
    kinds = [read_point_fields(os.path.join(DATA, f"xyzrgbnormal_{k}.pcd")) for k in ("ascii", "binary", "compressed")]
    for points, fields in kinds[1:]:
        np.testing.assert_array_equal(points, kinds[0][0])
        assert list(fields) == list(kinds[0][1]) == ["rgb", "normal_x", "normal_y", "normal_z", "curvature"]
        for name in fields:
            np.testing.assert_array_equal(fields[name], kinds[0][1][name])
            assert fields[name].dtype == kinds[0][1][name].dtype
    points, fields = kinds[0]
    # the values the C++ program that wrote these files set (tests/data/README.md)
    i = np.arange(12)
    rgb = fields["rgb"]
    assert rgb.dtype == np.uint32
    np.testing.assert_array_equal((rgb >> 16) & 255, 10 * i)
    np.testing.assert_array_equal((rgb >> 8) & 255, 255 - 7 * i)
    np.testing.assert_array_equal(rgb & 255, 3 * i)
    np.testing.assert_array_equal(rgb >> 24, 255)
    assert np.isnan(points[3]).all() and np.isfinite(np.delete(points, 3, axis=0)).all()
    np.testing.assert_array_equal(fields["curvature"], (np.float32(0.01) * i.astype(np.float32)))
    labels = read_point_fields(os.path.join(DATA, "xyzrgbl_binary.pcd"))[1]["label"]
    assert labels.dtype == np.uint32 and labels.tolist() == (1000 + 7 * i).tolist()
    np.testing.assert_array_equal(read_point_fields(os.path.join(DATA, "xyzrgbl_compressed.pcd"))[1]["label"], labels)
    assert read_point_fields(os.path.join(DATA, "xyzi_ascii.pcd"))[1]["intensity"].dtype == np.float32


def test_pcd_read_point_cloud_unchanged_for_pcl_files():
    cloud = read_point_cloud(os.path.join(DATA, "xyzrgbnormal_binary.pcd"))
    points, fields = read_point_fields(os.path.join(DATA, "xyzrgbnormal_binary.pcd"))
    keep = np.isfinite(points).all(axis=1)
    np.testing.assert_array_equal(cloud[:, :3], points[keep])
    np.testing.assert_array_equal(cloud[:, 3:], np.column_stack([fields[f"normal_{a}"] for a in "xyz"])[keep])


def test_pcd_float_rgb_and_wide_integers(tmp_path, write_file):
    """A float rgb (older PCL) keeps its bits; 8-byte integers in ASCII keep every digit."""
    bits = np.array([0xFF102030, 0x00FFFFFF], dtype=np.uint32)
    body = b"".join(struct.pack("<fff", 1, 2, 3) + struct.pack("<I", b) + struct.pack("<Q", 2 ** 63 + 5) for b in bits)
    head = ("VERSION 0.7\nFIELDS x y z rgb big\nSIZE 4 4 4 4 8\nTYPE F F F F U\nCOUNT 1 1 1 1 1\n"
            "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n").encode()
    path = write_file(tmp_path / "f.pcd", head + body, "wb")
    _, fields = _assert_round_trip(path, tmp_path, "pcd")
    assert fields["rgb"].tolist() == bits.tolist() and fields["big"].tolist() == [2 ** 63 + 5] * 2
    text = ("VERSION 0.7\nFIELDS x y z big hist\nSIZE 4 4 4 8 2\nTYPE F F F I U\nCOUNT 1 1 1 1 3\nWIDTH 2\nHEIGHT 1\n"
            "POINTS 2\nDATA ascii\n1 2 3 -9007199254740993 1 2 3\n4 5 6 9223372036854775807 4 5 65535\n")
    _, fields = read_point_fields(write_file(tmp_path / "a.pcd", text))
    assert fields["big"].tolist() == [-9007199254740993, 9223372036854775807]
    assert fields["hist"].dtype == np.uint16 and fields["hist"].tolist() == [[1, 2, 3], [4, 5, 65535]]


# --------------------------------------------------------------------------- PLY with custom properties


def _plyfile_vertices(n, rng):
    return np.array(
        [tuple(row) for row in zip(rng.normal(size=n).astype("f4"), rng.normal(size=n).astype("f4"),
                                   rng.normal(size=n).astype("f4"), rng.integers(0, 256, n), rng.integers(0, 256, n),
                                   rng.integers(0, 256, n), rng.integers(-2 ** 31, 2 ** 31, n),
                                   rng.normal(size=n), rng.normal(size=n).astype("f4"), rng.integers(-100, 100, n))],
        dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1"),
               ("label", "i4"), ("gps", "f8"), ("scalar_Intensity", "f4"), ("tag", "i2")])


@pytest.mark.parametrize("text, byte_order", [(False, "<"), (False, ">"), (True, "=")])
def test_ply_custom_properties_by_plyfile(tmp_path, text, byte_order):
    plyfile = pytest.importorskip("plyfile")
    rng = np.random.default_rng(3)
    vert = _plyfile_vertices(30, rng)
    path = str(tmp_path / "custom.ply")
    plyfile.PlyData([plyfile.PlyElement.describe(vert, "vertex")], text=text, byte_order=byte_order).write(path)
    points, fields = _assert_round_trip(path, tmp_path, "ply")
    assert list(fields) == ["red", "green", "blue", "label", "gps", "scalar_Intensity", "tag"]
    for name in fields:
        np.testing.assert_array_equal(fields[name], vert[name])
        assert fields[name].dtype == vert.dtype[name].newbyteorder("=")
    np.testing.assert_array_equal(points, np.column_stack([vert[a] for a in "xyz"]).astype(np.float64))


def test_ply_list_property_of_one_length(tmp_path):
    plyfile = pytest.importorskip("plyfile")
    n = 5
    vert = np.empty(n, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("feature", "O")])
    for k in range(n):
        vert[k] = (k, 0, 0, np.arange(4, dtype="f4") + k)
    path = str(tmp_path / "lists.ply")
    plyfile.PlyData([plyfile.PlyElement.describe(vert, "vertex", val_types={"feature": "f4"})]).write(path)
    _, fields = _assert_round_trip(path, tmp_path, "ply")
    assert fields["feature"].shape == (n, 4) and fields["feature"][2].tolist() == [2, 3, 4, 5]
    vert[1] = (1, 0, 0, np.arange(3, dtype="f4"))
    plyfile.PlyData([plyfile.PlyElement.describe(vert, "vertex", val_types={"feature": "f4"})]).write(path)
    with pytest.raises(FileFormatError, match="lists.ply.*'feature' has rows of different lengths"):
        read_point_fields(path)


# --------------------------------------------------------------------------- text tables


def test_text_with_header(tmp_path, write_file):
    path = write_file(tmp_path / "t.csv", "intensity,X,Y,Z,label\n0.5,1,2,3,7\n0.25,4,5,6,8\n")
    points, fields = read_point_fields(path)
    assert points.tolist() == [[1, 2, 3], [4, 5, 6]] and list(fields) == ["intensity", "label"]
    assert fields["label"].tolist() == [7, 8]
    _, fields = read_point_fields(write_file(tmp_path / "n.xyz", "1 2 3 9\n4 5 6 10\n"))
    assert list(fields) == ["column_4"] and fields["column_4"].tolist() == [9, 10]
    _, fields = read_point_fields(write_file(tmp_path / "c.pts", "2\n1 2 3 5 10 20 30\n4 5 6 6 40 50 60\n"))
    assert list(fields) == ["intensity", "red", "green", "blue"] and fields["blue"].tolist() == [30, 60]
    with pytest.raises(FileFormatError, match="h.csv.*names 2 columns, but the rows hold 3"):
        read_point_fields(write_file(tmp_path / "h.csv", "x,y\n1,2,3\n"))


# --------------------------------------------------------------------------- argument errors


@pytest.mark.parametrize("fields, exc, msg", [
    ({"a b": np.zeros(3)}, ValueError, "field names must be non-empty ASCII strings without spaces"),
    ({"\u00e9t\u00e9": np.zeros(3)}, ValueError, "field names must be non-empty ASCII strings without spaces"),
    ({"x": np.zeros(3)}, ValueError, "would repeat a coordinate"),
    ({"a": np.zeros(2)}, ValueError, r"field 'a' must have shape \(3,\) or \(3, k\)"),
    ({"a": np.array(["u", "v", "w"])}, TypeError, "field 'a' must hold integers or float32/float64"),
    ({"a": np.full(3, 2 ** 40)}, ValueError, "64-bit integers beyond 32 bits, which PLY cannot store"),
])
def test_write_argument_errors(tmp_path, fields, exc, msg):
    with pytest.raises(exc, match=msg):
        write_point_fields(tmp_path / "o.ply", np.zeros((3, 3)), fields)


def test_a_failed_write_leaves_the_old_file_and_no_scratch(tmp_path, monkeypatch):
    from eppf.io import _pcd

    target = tmp_path / "scene.pcd"
    write_point_fields(target, np.eye(3), {"label": np.arange(3, dtype=np.int32)})
    before = target.read_bytes()

    def half_then_fail(path, points, fields):
        with open(path, "wb") as fh:
            fh.write(b"# .PCD v0.7 - truncated")
        raise KeyboardInterrupt

    monkeypatch.setattr(_pcd, "write_pcd_fields", half_then_fail)
    with pytest.raises(KeyboardInterrupt):
        write_point_fields(target, np.zeros((5, 3)))
    assert target.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["scene.pcd"]


def test_write_into_a_missing_folder_names_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"write_point_fields: cannot write .*o\.ply.*: no such folder"):
        write_point_fields(tmp_path / "nowhere" / "o.ply", np.zeros((3, 3)))


def test_write_refuses_other_formats_and_meshes(tmp_path):
    with pytest.raises(ValueError, match="cannot write fields to a xyz file"):
        write_point_fields(tmp_path / "o.xyz", np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 3\)"):
        write_point_fields(tmp_path / "o.pcd", np.zeros((3, 6)))
    with pytest.raises(ValueError, match="is a off mesh file; read its vertices with read_mesh"):
        read_point_fields(tmp_path / "o.off")


def test_write_narrows_int64_for_ply_and_keeps_it_for_pcd(tmp_path):
    seg = np.array([0, 5, 2 ** 31 - 1])
    write_point_fields(tmp_path / "a.ply", np.zeros((3, 3)), {"segment": seg, "flag": np.array([True, False, True])})
    _, fields = read_point_fields(tmp_path / "a.ply")
    assert fields["segment"].dtype == np.int32 and fields["segment"].tolist() == seg.tolist()
    assert fields["flag"].dtype == np.uint8 and fields["flag"].tolist() == [1, 0, 1]
    write_point_fields(tmp_path / "a.pcd", np.zeros((3, 3)), {"segment": seg})
    assert _same(read_point_fields(tmp_path / "a.pcd")[1]["segment"], seg.astype(np.int64))


def test_float64_points_stay_float64(tmp_path):
    points = np.array([[512345.678, 4012345.671, 101.25], [512345.679, 4012345.672, 101.5]])
    for ext in ("pcd", "ply"):
        write_point_fields(tmp_path / f"p.{ext}", points)
        assert _same(read_point_fields(tmp_path / f"p.{ext}")[0], points)


def test_a_field_of_one_column_is_one_value_per_point(tmp_path):
    column = np.arange(3, dtype=np.float32).reshape(3, 1)
    write_point_fields(tmp_path / "c.pcd", np.zeros((3, 3)), {"v": column})
    assert _same(read_point_fields(tmp_path / "c.pcd")[1]["v"], column.ravel())
    write_point_fields(tmp_path / "c.ply", np.zeros((3, 3)), {"v": column})
    assert _same(read_point_fields(tmp_path / "c.ply")[1]["v"], column)  # a PLY list of length 1
