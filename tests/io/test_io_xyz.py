"""Text tables: .xyz/.txt/.csv, Open3D's .pts, .xyzn and .xyzrgb, and the compiled table parser."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.io import FileFormatError, read_point_cloud, write_point_cloud



# --------------------------------------------------------------------------- text fixtures


def test_xyz_header_and_separators(write_file, tmp_path):
    path = write_file(tmp_path / "p.csv", "x,y,z\n1,2,3\n# comment\n\n4,5,6\n")
    assert_allclose(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])


def test_xyz_colour_columns_are_not_normals(write_file, tmp_path):
    # S3DIS-style x y z r g b
    path = write_file(tmp_path / "p.txt", "1 2 3 255 0 12\n4 5 6 0 128 7\n")
    assert read_point_cloud(path).shape == (2, 3)
    assert_allclose(read_point_cloud(path, normals=True)[:, 3:], [[255, 0, 12], [0, 128, 7]])


def test_xyz_unit_normal_columns_are_normals(write_file, tmp_path):
    # modelnet40_normal_resampled-style x,y,z,nx,ny,nz
    path = write_file(tmp_path / "p.txt", "1,2,3,0,0,1\n4,5,6,0.6,0.8,0\n")
    assert_allclose(read_point_cloud(path), [[1, 2, 3, 0, 0, 1], [4, 5, 6, 0.6, 0.8, 0]])


@pytest.mark.parametrize(
    "text, msg",
    [
        ("1 2 3\n4 5\n", "line 2: expected 3 values in point 1, got 2"),
        ("1 2 3\n\n4 5 six\n", "line 3: malformed number in point 1"),
        ("1 2\n3 4\n", "line 1: expected at least 3 columns (x y z), got 2"),
        ("# only a comment\n", "holds no points"),
    ],
)
def test_xyz_malformed(write_file, tmp_path, text, msg):
    path = write_file(tmp_path / "bad.xyz", text)
    with pytest.raises(FileFormatError, match=re.escape(msg)):
        read_point_cloud(path)



@pytest.mark.parametrize("token", ["0x10", "-0x1p3", "+0X1", "+nan(1)", "-inf(2)"])
def test_text_compiled_path_refuses_what_python_float_refuses(write_file, tmp_path, token):
    # strtod takes hexadecimal and nan(...) tokens; Python's float, hence the general reader, does not.
    # Both paths must read a file the same way, so the compiled one hands such a table back.
    from eppf.io import _xyz as io

    text = f"0 0 0\n1 0 0\n{token} 1 0\n0 0 1\n"
    if io._parse_float_table is not None:
        assert io._xyz_compiled(text.encode()) is None
    path = write_file(tmp_path / "hex.xyz", text)
    with pytest.raises(FileFormatError, match=re.escape("line 3: malformed number in point 2")):
        read_point_cloud(path)


@pytest.mark.parametrize(
    "text, plain",
    [
        ("1,2,3,0,0,1\n4,5,6,0.6,0.8,0\n", True),
        ("x y z\n1 2 3\n\n4\t5  6\r\n7 8 9", True),
        ("x;y;z\n-1e-3;+2.5;.5\n", True),
        ("1 2 3 255 0 12\n4 5 6 0 128 7\n", True),
        ("1 2 3\n4 nan 6\n", False),  # NaN: the general reader keeps it, remove_nan drops it
        ("1 2 3 # a comment\n4 5 6\n", False),
    ],
)
def test_text_compiled_path_matches_general_reader(write_file, tmp_path, text, plain):
    from eppf.io import _xyz as io

    if io._parse_float_table is None:
        pytest.skip("eppf.io._xyz_fast is not compiled")
    assert (io._xyz_compiled(text.encode()) is not None) == plain
    path = write_file(tmp_path / "p.xyz", text)
    saved = io._parse_float_table
    try:
        io._parse_float_table = None
        ref = read_point_cloud(path)
    finally:
        io._parse_float_table = saved
    assert_array_equal(read_point_cloud(path), ref)


def test_text_compiled_path_random_table(tmp_path):
    from eppf.io import _xyz as io

    if io._parse_float_table is None:
        pytest.skip("eppf.io._xyz_fast is not compiled")
    arr = np.random.RandomState(0).normal(size=(500, 6)) * 10.0 ** np.arange(-4, 2)
    path = tmp_path / "t.csv"
    write_point_cloud(path, arr)  # 17 significant digits: exact round trip
    assert_array_equal(io._xyz_compiled(path.read_bytes()), arr)
    assert_array_equal(read_point_cloud(path, normals=True), arr)



# --------------------------------------------------------------------------- Open3D's .pts, .xyzn, .xyzrgb


@pytest.mark.parametrize("count_line", [True, False])
def test_pts_with_and_without_count_line(write_file, tmp_path, count_line):
    rows = "1 2 3 0.5 10 20 30\n4 5 6 0.1 40 50 60\n7 8 9 0.9 70 80 90\n"
    path = write_file(tmp_path / "p.pts", ("3\n" if count_line else "") + rows)
    assert_array_equal(read_point_cloud(path), [[1, 2, 3], [4, 5, 6], [7, 8, 9]])


def test_pts_count_line_without_final_newline_and_xyz_only(write_file, tmp_path):
    path = write_file(tmp_path / "p.PTS", "\n2\n1 2 3\n4 5 6")
    assert_array_equal(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize(
    "text, msg",
    [
        ("999999999\n1 2 3\n", "line 1: the count line says 999999999 points, but the file holds 1 rows"),
        ("2\n1 2 3\n4 5 6\n7 8 9\n", "line 1: the count line says 2 points, but the file holds 3 rows"),
        ("-5\n1 2 3\n", "line 1: negative point count -5"),
        ("3\n", "holds no points"),
        ("1e308\n1 2 3\n", "expected 1 values in point 1, got 3"),
    ],
)
def test_pts_bad_count_line(write_file, tmp_path, text, msg):
    path = write_file(tmp_path / "bad.pts", text)
    with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
        read_point_cloud(path)
    assert "bad.pts" in str(info.value)


def test_pts_of_no_points_as_open3d_writes_it_is_refused_as_other_empty_files_are(write_file, tmp_path):
    # Open3D writes an empty cloud as the count line alone ("0", with Windows line ends); it was refused as
    # holding "only blank or comment lines". Now it is a file of no points, as an empty PLY file is.
    from eppf.io import read_point_fields

    path = write_file(tmp_path / "empty.pts", b"0\r\n", mode="wb")
    ply = write_file(tmp_path / "empty.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                                             "property float y\nproperty float z\nend_header\n")
    for name in (path, ply):
        with pytest.raises(FileFormatError) as info:
            read_point_cloud(name)
        assert str(info.value) == f"read_point_cloud: {name!r} holds no points"
        points, fields = read_point_fields(name)
        assert points.shape == (0, 3) and fields == {}
    write_file(path, "0\n# no points\n\n")
    assert read_point_fields(path)[0].shape == (0, 3)


@pytest.mark.parametrize("text, line", [
    ("8\n" + "".join(f"{k} {k} {k}\n" for k in range(9)), 10),  # as PDAL's bunny_8.pts: 8, then 9 rows
    ("8\r\n# scan\r\nx y z\r\n" + "".join(f"{k} 0 1\r\n\r\n" for k in range(9)), 20),
])
def test_pts_of_more_rows_than_its_count_line_says_names_both_lines(write_file, tmp_path, text, line):
    # refused (PDAL and Open3D read the first 8 and drop the rest without a word), but the message said only
    # "holds 9 rows": now it says how many more, from which line, and how to read the file
    path = write_file(tmp_path / "bunny_8.pts", text)
    with pytest.raises(FileFormatError) as info:
        read_point_cloud(path)
    assert str(info.value) == (
        f"read_point_cloud: {path!r} line 1: the count line says 8 points, but the file holds 9 rows, 1 more from "
        f"line {line} (PDAL and Open3D would drop them: correct the count line, or delete it to read every row)")
    write_file(path, text.split("\n", 1)[1])  # without the count line: every row
    assert read_point_cloud(path).shape == (9, 3)


@pytest.mark.parametrize("ext", ["xyz", "txt", "xyzn"])
def test_a_count_line_in_a_table_without_one_is_named_as_such(write_file, tmp_path, ext):
    # read as a row of one value, it was reported as "line 2: expected 1 values in point 1, got 3"
    path = write_file(tmp_path / f"counted.{ext}", "2\n1 2 3 0 0 1\n4 5 6 0 0 1\n")
    with pytest.raises(FileFormatError, match=re.escape(
            "counted." + ext + "' line 1: a count line (2) as a .pts file begins with, but the rows of this file's "
            "format hold x y z; read it as .pts (format='pts') to use the count")):
        read_point_cloud(path)
    assert read_point_cloud(path, format="pts").shape == (2, 6)


def test_pts_count_line_after_a_comment_is_the_count_line(write_file, tmp_path):
    # the count line was looked for on the first line only: after a comment it was read as a row of one value
    # (and then named a count line of a format that has none, in a .pts file)
    path = write_file(tmp_path / "c.pts", "# exported\r\n2 # points\r\n1 2 3 7\r\n4 5 6 8\r\n")
    assert_array_equal(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])
    from eppf.io import read_point_fields

    assert read_point_fields(path)[1]["intensity"].tolist() == [7, 8]


def test_pts_count_line_without_rows_is_truncated(write_file, tmp_path):
    path = write_file(tmp_path / "cut.pts", "3\n# the rows are missing\n")
    with pytest.raises(FileFormatError, match=re.escape(
            "cut.pts' line 1: the count line says 3 points, but the file holds no points (truncated)")):
        read_point_cloud(path)


@pytest.mark.parametrize("text, line", [
    ("2\n1 2 3 5\n4 5 6 7\n1\n7 8 9 1\n", 4),
    ("2\r\n1 2 3\r\n4 5 6\r\n\r\n# the second scan\r\n1\r\n7 8 9\r\n", 6),
])
def test_pts_of_several_scans_is_refused_naming_the_second_count_line(write_file, tmp_path, text, line):
    # Leica's PTS may hold several scans, each after its count line; the second count line was reported as a
    # row of too few values ("expected 4 values in point 2, got 1")
    path = write_file(tmp_path / "scans.pts", text.encode(), mode="wb")
    with pytest.raises(FileFormatError, match=re.escape(
            f"scans.pts' line {line}: a second count line (1): the file holds several scans, each after its count "
            "line; eppf reads .pts files of one scan")):
        read_point_cloud(path)


def test_xyzn_always_normals_and_round_trip(make_cloud, write_file, tmp_path):
    # normals need not be unit length in an .xyzn file: the format says they are normals
    path = write_file(tmp_path / "p.xyzn", "1 2 3 0 0 2\n4 5 6 0 3 0\n")
    assert_array_equal(read_point_cloud(path), [[1, 2, 3, 0, 0, 2], [4, 5, 6, 0, 3, 0]])
    assert read_point_cloud(path, normals=False).shape == (2, 3)
    cloud = make_cloud(n=20)
    write_point_cloud(tmp_path / "c.xyzn", cloud)
    assert_array_equal(read_point_cloud(tmp_path / "c.xyzn"), cloud)
    with pytest.raises(ValueError, match="an .xyzn file holds normals"):
        write_point_cloud(tmp_path / "d.xyzn", cloud[:, :3])


def test_xyzrgb_colour_is_ignored(make_cloud, write_file, tmp_path):
    # unit-length colours must not turn into normals
    path = write_file(tmp_path / "p.XYZRGB", "1 2 3 1 0 0\n4 5 6 0 1 0\n")
    assert_array_equal(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])
    with pytest.raises(FileFormatError, match="has no normals, but normals=True"):
        read_point_cloud(path, normals=True)
    with pytest.raises(ValueError, match="does not write xyzrgb files"):
        write_point_cloud(tmp_path / "c.xyzrgb", make_cloud(n=3))


@pytest.mark.parametrize("ext", ["xyzn", "xyzrgb"])
def test_six_column_formats_need_six_columns(write_file, tmp_path, ext):
    path = write_file(tmp_path / f"p.{ext}", "1 2 3\n4 5 6\n")
    with pytest.raises(FileFormatError, match=re.escape(f"line 1: a .{ext} row holds 6 values, got 3")):
        read_point_cloud(path)


def test_text_not_utf8(tmp_path):
    path = tmp_path / "b.xyz"
    path.write_bytes(b"1 2 3\n\xff\xfe 1 2\n")
    with pytest.raises(FileFormatError, match=re.escape("is not a text file (undecodable byte at offset 6)")):
        read_point_cloud(path)


def test_compiled_number_parser_gives_python_floats_bit_for_bit():
    # the short-decimal shortcut of the compiled parsers must round exactly as float() (strtod) does
    from eppf.io._xyz_fast import parse_float_table, parse_tokens

    rng = np.random.default_rng(0)
    values = np.concatenate([rng.normal(size=3000) * 10.0 ** rng.integers(-30, 30, size=3000),
                             rng.uniform(-1, 1, size=3000), rng.integers(-10 ** 6, 10 ** 6, size=3000)])
    tokens = []
    for k, v in enumerate(values):
        fmt = ("%.9g", "%.17g", "%.6e", "%.3f", "%.15g", "%.1E", "%+.7g", "%.0f")[k % 8]
        tokens.append(fmt % v)
    tokens += ["0", "-0", "+.5", "5.", "1e22", "1e23", "9007199254740993", "9007199254740992", "123456789012345678901",
               "0.1", "1e-22", "4.9e-324", "1.7976931348623157e308", "2.2250738585072014e-308", "000000.0001",
               "1E+5", "3.14159265358979323846", "7e-23", "-1.5e-3", "12345678901234567e5"]
    while len(tokens) % 3:
        tokens.append("1")
    text = "\n".join(" ".join(tokens[i:i + 3]) for i in range(0, len(tokens), 3)).encode()
    expected = np.array([float(t) for t in tokens])
    table = parse_float_table(text, 0)
    assert table.shape == (len(tokens) // 3, 3)
    assert table.ravel().tobytes() == expected.tobytes()
    flat, bad = parse_tokens(text, 0)
    assert bad == -1 and flat.tobytes() == expected.tobytes()
    # tokens that merely start like a number are still refused as before
    for row in (b"1 2 3\n1e 2 3\n", b"1 2 3\n1.5x 2 3\n", b"1 2 3\n1.5.5 2 3\n"):
        assert parse_float_table(row, 0) is None
    assert parse_tokens(b"1 2 0x10", 0) == (None, 4)
    assert parse_tokens(b"1 2 1.5.5", 0) == (None, 4)
