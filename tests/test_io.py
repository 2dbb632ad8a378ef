"""Tests of eppf.io: round trips, hand-written fixtures, and malformed files."""

import re
import struct

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.io import Mesh, read_mesh, read_point_cloud, write_mesh, write_point_cloud


def _cloud(n=40, normals=True, seed=0):
    rng = np.random.RandomState(seed)
    xyz = rng.uniform(-2, 3, size=(n, 3))
    if not normals:
        return xyz
    nrm = rng.normal(size=(n, 3))
    return np.hstack([xyz, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)])


def _write(path, text, mode="w"):
    with open(path, mode) as fh:
        fh.write(text)
    return str(path)


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("ext", ["pcd", "ply", "xyz", "txt", "csv", "npy", "npz"])
@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("normals", [True, False])
def test_point_cloud_round_trip(tmp_path, ext, binary, normals):
    if ext == "ply":
        pytest.importorskip("plyfile")
    cloud = _cloud(normals=normals)
    path = tmp_path / f"cloud.{ext}"
    write_point_cloud(path, cloud, binary=binary)
    back = read_point_cloud(path)
    assert back.shape == cloud.shape and back.dtype == np.float64
    # PCD and PLY store float32
    tol = 1e-6 if ext in ("pcd", "ply") else 0
    assert_allclose(back, cloud, rtol=tol, atol=tol)


@pytest.mark.parametrize("ext", ["off", "obj", "ply"])
def test_mesh_round_trip(tmp_path, ext):
    if ext == "ply":
        pytest.importorskip("plyfile")
    vertices = _cloud(normals=False, n=6)
    faces = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 0]])
    path = tmp_path / f"mesh.{ext}"
    write_mesh(path, vertices, faces)
    mesh = read_mesh(path)
    assert isinstance(mesh, Mesh)
    assert_allclose(mesh.vertices, vertices, rtol=1e-6 if ext == "ply" else 0)
    assert_array_equal(mesh.faces, faces)


def test_normals_false_drops_and_true_requires(tmp_path):
    path = tmp_path / "c.npy"
    write_point_cloud(path, _cloud())
    assert read_point_cloud(path, normals=False).shape == (40, 3)
    path3 = tmp_path / "c3.npy"
    write_point_cloud(path3, _cloud(normals=False))
    with pytest.raises(ValueError, match="has no normals, but normals=True"):
        read_point_cloud(path3, normals=True)


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


def test_pcd_ascii_extra_fields(tmp_path):
    body = "1 2 3 4278190080 0 0 1\n-1.5 0.25 7 0 1 0 0\nnan nan nan 0 0 0 1\n"
    path = _write(tmp_path / "a.pcd", PCD_HEAD.format(n=3, kind="ascii") + body)
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
    head = "VERSION 0.7\nFIELDS x\nSIZE 1\nTYPE U\nCOUNT 4\nPOINTS 1\nDATA binary_compressed\n"
    path = tmp_path / "e.pcd"
    path.write_bytes(head.encode() + struct.pack("<II", len(comp), 4) + comp)
    with pytest.raises(ValueError, match=r"e\.pcd' byte \d+: corrupt compressed data"):
        read_point_cloud(path)


def test_pcd_truncated_binary_names_byte(tmp_path):
    path = tmp_path / "t.pcd"
    write_point_cloud(path, _cloud(n=10), binary=True)
    data = path.read_bytes()
    path.write_bytes(data[:-5])
    size = len(data) - 5
    msg = f"read_point_cloud: {str(path)!r} byte {size}: file ends 5 bytes early"
    with pytest.raises(ValueError, match=re.escape(msg)):
        read_point_cloud(path)


def test_pcd_truncated_ascii_names_line(tmp_path):
    body = "1 2 3 0 0 0 1\n"
    path = _write(tmp_path / "t.pcd", PCD_HEAD.format(n=3, kind="ascii") + body)
    with pytest.raises(ValueError, match=re.escape("line 12: file ends after 1 of 3 points (truncated)")):
        read_point_cloud(path)


def test_pcd_malformed_number_names_line(tmp_path):
    body = "1 2 3 0 0 0 1\n1 2 x 0 0 0 1\n"
    path = _write(tmp_path / "m.pcd", PCD_HEAD.format(n=2, kind="ascii") + body)
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
def test_pcd_malformed_header(tmp_path, header, msg):
    path = _write(tmp_path / "h.pcd", header)
    with pytest.raises(ValueError, match=re.escape(msg)):
        read_point_cloud(path)


# --------------------------------------------------------------------------- text fixtures


def test_xyz_header_and_separators(tmp_path):
    path = _write(tmp_path / "p.csv", "x,y,z\n1,2,3\n# comment\n\n4,5,6\n")
    assert_allclose(read_point_cloud(path), [[1, 2, 3], [4, 5, 6]])


def test_xyz_colour_columns_are_not_normals(tmp_path):
    # S3DIS-style x y z r g b
    path = _write(tmp_path / "p.txt", "1 2 3 255 0 12\n4 5 6 0 128 7\n")
    assert read_point_cloud(path).shape == (2, 3)
    assert_allclose(read_point_cloud(path, normals=True)[:, 3:], [[255, 0, 12], [0, 128, 7]])


def test_xyz_unit_normal_columns_are_normals(tmp_path):
    # modelnet40_normal_resampled-style x,y,z,nx,ny,nz
    path = _write(tmp_path / "p.txt", "1,2,3,0,0,1\n4,5,6,0.6,0.8,0\n")
    assert_allclose(read_point_cloud(path), [[1, 2, 3, 0, 0, 1], [4, 5, 6, 0.6, 0.8, 0]])


@pytest.mark.parametrize(
    "text, msg",
    [
        ("1 2 3\n4 5\n", "line 2: expected 3 values in point 1, got 2"),
        ("1 2 3\n\n4 5 six\n", "line 3: malformed number in point 1"),
        ("1 2\n3 4\n", "line 1: expected at least 3 columns (x y z), got 2"),
        ("# only a comment\n", "holds no points (only blank or comment lines)"),
    ],
)
def test_xyz_malformed(tmp_path, text, msg):
    path = _write(tmp_path / "bad.xyz", text)
    with pytest.raises(ValueError, match=re.escape(msg)):
        read_point_cloud(path)


def test_npz_data_set_points_to_load_npz(tmp_path):
    path = tmp_path / "set.npz"
    np.savez(path, points=np.zeros((4, 3)), offsets=np.array([0, 4]))
    with pytest.raises(ValueError, match=re.escape("read it with eppf.datasets.load_npz")):
        read_point_cloud(path)


def test_npy_wrong_shape(tmp_path):
    path = tmp_path / "x.npy"
    np.save(path, np.zeros((4, 2)))
    with pytest.raises(ValueError, match=re.escape("must hold a numeric array of shape (n_points, 3+)")):
        read_point_cloud(path)


# --------------------------------------------------------------------------- OFF / OBJ fixtures

SQUARE = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n"


@pytest.mark.parametrize(
    "text",
    [
        "OFF\n4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 3\n",
        "OFF4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 3\n",  # ModelNet's glued header
        "OFF 4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 3\n",
        "# made by hand\nOFF\n\n4 2 0 # counts\n" + SQUARE + "3 0 1 2   \n3 0 2 3\n",
        "OFF\n4 1 0\n" + SQUARE + "4 0 1 2 3\n",  # a quad, split by a fan
        "COFF\n4 2 0\n" + "0 0 0 9 9 9 255\n1 0 0 9 9 9 255\n1 1 0 9 9 9 255\n0 1 0 9 9 9 255\n"
        + "3 0 1 2 1 1 1\n3 0 2 3 1 1 1\n",
    ],
)
def test_off_variants(tmp_path, text):
    mesh = read_mesh(_write(tmp_path / "m.off", text))
    assert_allclose(mesh.vertices, np.loadtxt(SQUARE.splitlines()))
    assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
    assert mesh.faces.dtype == np.int64


@pytest.mark.parametrize(
    "text, msg",
    [
        ("", "is empty"),
        ("PLY\n3 1 0\n", "line 1: expected an 'OFF' header, got 'PLY'"),
        ("OFF\nthree 1 0\n", "line 2: expected the counts 'n_vertices n_faces n_edges', got 'three 1 0'"),
        ("OFF\n4 2 0\n0 0 0\n1 0 0\n", "line 4: file ends after 2 of 4 vertices (truncated)"),
        ("OFF4 2 0\n" + SQUARE + "3 0 1 2\n", "line 6: file ends after 1 of 2 faces (truncated)"),
        ("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1\n0 1 0\n3 0 1 2\n", "line 5: expected 3 values in vertex 2, got 2"),
        ("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 z\n0 1 0\n3 0 1 2\n", "line 5: malformed number in vertex 2"),
        ("OFF\n4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 4\n", "line 8: face index out of range 0..3"),
        ("OFF\n4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2\n", "line 8: a face needs at least 3 vertex indices"),
        ("OFF\n4 2 0\n" + SQUARE + "3 0 1 2\n3 0 b 2\n", "line 8: malformed face"),
        ("OFF\n0 0 0\n", "line 2: the mesh has no vertices"),
    ],
)
def test_off_malformed(tmp_path, text, msg):
    path = _write(tmp_path / "bad.off", text)
    with pytest.raises(ValueError, match=re.escape(msg)) as info:
        read_mesh(path)
    assert "bad.off" in str(info.value)


def test_obj_index_forms(tmp_path):
    text = (
        "# cube corner\nmtllib x.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
        "f 1/1/1 2/1/1 3/1/1\nf 1//1 3//1 4//1\nf -4 -3 -2 -1\n"
    )
    mesh = read_mesh(_write(tmp_path / "m.obj", text))
    assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize(
    "text, msg",
    [
        ("v 0 0\n", "line 1: malformed vertex"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4: face index out of range 1..3"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4: OBJ indices start at 1, got 0"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "line 3: a face needs at least 3 vertices"),
        ("# nothing\nf 1 2 3\n", "holds no vertices"),
    ],
)
def test_obj_malformed(tmp_path, text, msg):
    path = _write(tmp_path / "bad.obj", text)
    with pytest.raises(ValueError, match=re.escape(msg)):
        read_mesh(path)


# --------------------------------------------------------------------------- PLY fixtures


def test_ply_ascii_fixture_with_quads_and_normals(tmp_path):
    pytest.importorskip("plyfile")
    text = (
        "ply\nformat ascii 1.0\ncomment by hand\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n4 0 1 2 3\n"
    )
    path = _write(tmp_path / "q.ply", text)
    assert_allclose(read_point_cloud(path)[:, 3:], np.tile([0, 0, 1], (4, 1)))
    assert_array_equal(read_mesh(path).faces, [[0, 1, 2], [0, 2, 3]])


def test_ply_truncated_binary(tmp_path):
    pytest.importorskip("plyfile")
    path = tmp_path / "t.ply"
    write_point_cloud(path, _cloud(n=10), binary=True)
    path.write_bytes(path.read_bytes()[:-7])
    with pytest.raises(ValueError, match=r"t\.ply': malformed PLY element 'vertex', row 9"):
        read_point_cloud(path)


def test_ply_malformed_header(tmp_path):
    pytest.importorskip("plyfile")
    path = _write(tmp_path / "h.ply", "ply\nformat ascii 1.0\nelement vertex two\nend_header\n")
    with pytest.raises(ValueError, match=r"h\.ply' line 3: malformed PLY header"):
        read_point_cloud(path)


# --------------------------------------------------------------------------- generic errors


@pytest.mark.parametrize("ext", ["pcd", "xyz", "npy", "off", "obj", "ply"])
def test_empty_file(tmp_path, ext):
    path = _write(tmp_path / f"empty.{ext}", "")
    reader = read_mesh if ext in ("off", "obj") else read_point_cloud
    if ext == "ply":
        reader = read_mesh
    with pytest.raises(ValueError, match=re.escape(f"{path!r} is empty")):
        reader(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="read_point_cloud: no such file"):
        read_point_cloud(tmp_path / "none.pcd")


@pytest.mark.parametrize(
    "func, args, kwargs, exc, msg",
    [
        (read_point_cloud, ("x.foo",), {}, ValueError, "cannot tell the format of 'x.foo' from its extension '.foo'"),
        (read_point_cloud, ("x.pcd",), {"format": "las"}, ValueError, "unknown format 'las'"),
        (read_point_cloud, ("x.pcd",), {"normals": "yes"}, ValueError, "normals must be 'auto', True or False"),
        (read_mesh, ("x.stl",), {}, ValueError, "cannot tell the format of 'x.stl'"),
        (write_point_cloud, ("x.xyz", np.zeros((3, 2))), {}, ValueError, "cloud must have shape (n_points, 3) or (n_points, 6)"),
        (write_point_cloud, ("x.xyz", [[np.nan, 0, 0]]), {}, ValueError, "cloud contains NaN or infinite values"),
        (write_point_cloud, ("x.xyz", np.zeros((0, 3))), {}, ValueError, "cloud has no points"),
        (write_point_cloud, ("x.xyz", [["a", "b", "c"]]), {}, TypeError, "cloud must be a numeric array"),
        (write_mesh, ("x.off", np.eye(3), [[0, 1, 3]]), {}, ValueError, "face indices must lie in 0..2"),
        (write_mesh, ("x.off", np.eye(3), [[0.5, 1, 2]]), {}, ValueError, "faces must be an integer array"),
    ],
)
def test_argument_errors(tmp_path, monkeypatch, func, args, kwargs, exc, msg):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(exc, match=re.escape(msg)):
        func(*args, **kwargs)


def test_missing_plyfile_names_the_extra(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "plyfile", None)  # makes `import plyfile` fail
    path = _write(tmp_path / "x.ply", "ply\nformat ascii 1.0\nend_header\n")
    with pytest.raises(ImportError, match=re.escape("read_point_cloud: reading and writing PLY files needs the 'plyfile' package; install it with `pip install eppf[io]`")):
        read_point_cloud(path)
    with pytest.raises(ImportError, match=re.escape("write_mesh: reading and writing PLY files needs the 'plyfile' package")):
        write_mesh(tmp_path / "m.ply", np.eye(3), [[0, 1, 2]])


def test_core_import_needs_no_optional_dependency():
    import subprocess
    import sys

    code = (
        "import sys; import eppf, eppf.io, eppf.datasets, eppf.preprocessing; "
        "bad = [m for m in ('plyfile', 'h5py', 'trimesh') if m in sys.modules]; "
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize(
    "text, plain",
    [
        ("OFF\n4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 3\n", True),
        ("OFF4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 3", True),  # no final newline
        ("\n OFF 4 2 0\r\n" + SQUARE.replace("\n", "\r\n") + "\n\n3 0 1 2\r\n3\t0 2 3\n\n", True),
        ("OFF\n4 2 0\n0 0 0\n1e0 -0 0\n+1 1.0 0\n.0 1 0\n3 0 1 2\n3 0 2 3\n", True),
        ("OFF\n4 1 0\n" + SQUARE + "4 0 1 2 3\n", False),  # a quad: the general reader
        ("OFF\n4 2 0\n" + SQUARE + "3 0 1 2 255 0 0\n3 0 2 3 255 0 0\n", False),  # face colours
        ("OFF\n4 2 0\n0 0 0\n1 0 0\nnan 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", False),
        ("OFF\n4 2 0 # counts\n" + SQUARE + "3 0 1 2\n3 0 2 3\n", False),
    ],
)
def test_off_compiled_path_matches_general_reader(tmp_path, text, plain):
    from eppf import io

    if io._parse_off_body is None:
        pytest.skip("eppf._io_cy is not compiled")
    data = text.encode()
    fast = io._read_off_compiled(data)
    assert (fast is not None) == plain
    # the reference: the line-by-line reader, with both fast paths switched off
    path = _write(tmp_path / "m.off", text)
    ref_parser, ref_fast = io._parse_off_body, io._read_off_fast
    try:
        io._parse_off_body, io._read_off_fast = None, lambda text: None
        ref = read_mesh(path)
    finally:
        io._parse_off_body, io._read_off_fast = ref_parser, ref_fast
    got = read_mesh(path)
    assert_array_equal(got.faces, ref.faces)
    assert_array_equal(got.vertices, ref.vertices)
    if fast is not None:
        assert_array_equal(fast.vertices, ref.vertices)
        assert_array_equal(fast.faces, ref.faces)


def test_off_compiled_path_random_mesh(tmp_path):
    from eppf import io

    if io._parse_off_body is None:
        pytest.skip("eppf._io_cy is not compiled")
    rng = np.random.RandomState(0)
    v = rng.normal(size=(300, 3)) * 10 ** rng.uniform(-5, 5, size=(300, 1))
    f = rng.randint(0, 300, size=(500, 3))
    path = tmp_path / "r.off"
    write_mesh(path, v, f)
    data = path.read_bytes()
    compiled = io._read_off_compiled(data)
    numpy_path = io._read_off_fast(data.decode())
    assert_array_equal(compiled.vertices, v)  # %.17g round-trips exactly
    assert_array_equal(compiled.vertices, numpy_path.vertices)
    assert_array_equal(compiled.faces, f)


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
def test_text_compiled_path_matches_general_reader(tmp_path, text, plain):
    from eppf import io

    if io._parse_float_table is None:
        pytest.skip("eppf._io_cy is not compiled")
    assert (io._xyz_compiled(text.encode()) is not None) == plain
    path = _write(tmp_path / "p.xyz", text)
    saved = io._parse_float_table
    try:
        io._parse_float_table = None
        ref = read_point_cloud(path)
    finally:
        io._parse_float_table = saved
    assert_array_equal(read_point_cloud(path), ref)


def test_text_compiled_path_random_table(tmp_path):
    from eppf import io

    if io._parse_float_table is None:
        pytest.skip("eppf._io_cy is not compiled")
    arr = np.random.RandomState(0).normal(size=(500, 6)) * 10.0 ** np.arange(-4, 2)
    path = tmp_path / "t.csv"
    write_point_cloud(path, arr)  # 17 significant digits: exact round trip
    assert_array_equal(io._xyz_compiled(path.read_bytes()), arr)
    assert_array_equal(read_point_cloud(path, normals=True), arr)
