"""PLY clouds and meshes read without plyfile (which, when installed, serves as the reference)."""

import re
import struct

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.io import FileFormatError, read_mesh, read_point_cloud, write_mesh, write_point_cloud



# --------------------------------------------------------------------------- PLY fixtures


def test_ply_ascii_fixture_with_quads_and_normals(write_file, tmp_path):
    text = (
        "ply\nformat ascii 1.0\ncomment by hand\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n4 0 1 2 3\n"
    )
    path = write_file(tmp_path / "q.ply", text)
    # a PLY with faces is a mesh: read_point_cloud samples it unless mesh="vertices"
    assert_allclose(read_point_cloud(path, mesh="vertices")[:, 3:], np.tile([0, 0, 1], (4, 1)))
    assert_array_equal(read_mesh(path).faces, [[0, 1, 2], [0, 2, 3]])
    sampled = read_point_cloud(path, n_points=300)
    assert sampled.shape == (300, 6) and np.all((sampled[:, :2] >= 0) & (sampled[:, :2] <= 1))


def test_ply_truncated_binary(make_cloud, tmp_path):
    path = tmp_path / "t.ply"
    write_point_cloud(path, make_cloud(n=10), binary=True)
    path.write_bytes(path.read_bytes()[:-7])
    with pytest.raises(FileFormatError, match=r"t\.ply' byte \d+: malformed PLY element 'vertex', row 9"):
        read_point_cloud(path)


def test_ply_malformed_header(write_file, tmp_path):
    path = write_file(tmp_path / "h.ply", "ply\nformat ascii 1.0\nelement vertex two\nend_header\n")
    with pytest.raises(ValueError, match=r"h\.ply' line 3: malformed PLY header"):
        read_point_cloud(path)



# --------------------------------------------------------------------------- against plyfile


def _header(fmt, n_v, n_f, props=("float x", "float y", "float z"), face="list uchar int vertex_indices"):
    lines = ["ply", f"format {fmt} 1.0", "comment test", f"element vertex {n_v}"]
    lines += [f"property {p}" for p in props]
    if n_f is not None:
        lines += [f"element face {n_f}", f"property {face}"]
    return ("\n".join(lines + ["end_header"]) + "\n").encode()


def _random_mixed_mesh(rng, fmt):
    """Vertices with double coordinates and uchar colours, triangles and quads, then an extra element."""
    n_v, n_f = 30, 25
    v = rng.normal(size=(n_v, 3))
    rgb = rng.randint(0, 256, size=(n_v, 3))
    sizes = rng.choice([3, 4], size=n_f)
    polys = [rng.choice(n_v, size=k, replace=False) for k in sizes]
    endian = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    head = _header(fmt, n_v, n_f, props=("double x", "double y", "double z", "uchar red", "uchar green", "uchar blue"),
                   face="list uchar uint vertex_indices")
    head = head.replace(b"end_header\n", b"element edge 2\nproperty int vertex1\nproperty int vertex2\nend_header\n")
    if endian is None:
        body = "".join(f"{float(a)!r} {float(b)!r} {float(c)!r} {r} {g} {bl}\n" for (a, b, c), (r, g, bl) in zip(v, rgb))
        body += "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys) + "0 1\n1 2\n"
        return head + body.encode(), v, polys
    body = b"".join(struct.pack(endian + "dddBBB", *xyz, *c) for xyz, c in zip(v, rgb))
    body += b"".join(struct.pack(f"{endian}B{len(p)}I", len(p), *p) for p in polys)
    body += struct.pack(endian + "iiii", 0, 1, 1, 2)
    return head + body, v, polys


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_mixed_polygons_match_plyfile(tmp_path, fmt):
    data, v, polys = _random_mixed_mesh(np.random.RandomState(3), fmt)
    path = tmp_path / "m.ply"
    path.write_bytes(data)
    mesh = read_mesh(path)
    # independent expectation: the fan of every polygon
    expected = [(p[0], p[k], p[k + 1]) for p in polys for k in range(1, len(p) - 1)]
    assert_array_equal(mesh.faces, expected)
    assert_array_equal(mesh.vertices, v)
    plyfile = pytest.importorskip("plyfile")
    ref = plyfile.PlyData.read(str(path))
    assert_array_equal(mesh.vertices, np.column_stack([ref["vertex"][c] for c in "xyz"]))
    ref_polys = [list(p) for p in ref["face"]["vertex_indices"]]
    assert [list(map(int, p)) for p in polys] == ref_polys


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("normals", [True, False])
def test_ply_written_files_read_by_plyfile(make_cloud, tmp_path, binary, normals):
    plyfile = pytest.importorskip("plyfile")
    cloud = make_cloud(n=25, normals=normals)
    path = tmp_path / "c.ply"
    write_point_cloud(path, cloud, binary=binary)
    ref = plyfile.PlyData.read(str(path))
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals else [])
    assert_array_equal(read_point_cloud(path), np.column_stack([ref["vertex"][c] for c in names]).astype(np.float64))
    faces = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    write_mesh(tmp_path / "q.ply", cloud[:, :3], faces, binary=binary)
    ref = plyfile.PlyData.read(str(tmp_path / "q.ply"))
    assert_array_equal(np.vstack(ref["face"]["vertex_indices"]), faces)
    assert_array_equal(read_mesh(tmp_path / "q.ply").faces, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])


def test_ply_reads_without_plyfile(make_cloud, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "plyfile", None)  # makes `import plyfile` fail
    write_point_cloud(tmp_path / "c.ply", make_cloud(n=5))
    assert read_point_cloud(tmp_path / "c.ply").shape == (5, 6)
    write_mesh(tmp_path / "m.ply", np.eye(3), [[0, 1, 2]], binary=False)
    assert_array_equal(read_mesh(tmp_path / "m.ply").faces, [[0, 1, 2]])


# --------------------------------------------------------------------------- hostile headers and data


def test_ply_huge_face_count_in_a_tiny_binary_file(tmp_path):
    # plyfile allocates from such a header (8 s and 900 MB for this 213-byte file)
    data = _header("binary_little_endian", 3, 100000000) + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) \
        + struct.pack("<B3i", 3, 0, 1, 2)
    path = tmp_path / "f.ply"
    path.write_bytes(data)
    msg = "declares 100000000 rows of at least 1 bytes (100000000 bytes), but the file has 13 bytes left"
    for reader in (read_mesh, read_point_cloud):
        with pytest.raises(FileFormatError, match=re.escape(msg)):
            reader(path)


@pytest.mark.parametrize(
    "data, msg",
    [
        (_header("ascii", 999999999999, None) + b"0 0 0\n", "declares 999999999999 rows of at least 3 values"),
        (_header("ascii", 3, 999999999999) + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "declares 999999999999 rows"),
        (_header("ascii", -1, None), "line 4: malformed PLY header (negative count"),
        (_header("ascii", 1, None).replace(b"vertex 1", b"vertex 1e308") + b"0 0 0\n", "line 4: malformed PLY header"),
        (_header("ascii", 1, None).replace(b"vertex 1", b"vertex nan") + b"0 0 0\n", "line 4: malformed PLY header"),
        (_header("ascii", 3, 1) + b"0 0 0\n1 0 0\n0 1 0\n1e308 0 1 2\n", "list 'vertex_indices' has a bad length"),
        (_header("ascii", 3, 1) + b"0 0 0\n1 0 0\n0 1 0\nnan 0 1 2\n", "list 'vertex_indices' has a bad length"),
        (_header("ascii", 3, 1) + b"0 0 0\n1 0 0\n0 1 0\n-1 0 1 2\n", "list 'vertex_indices' has a bad length"),
        (_header("ascii", 3, 1) + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 99999999999999999999\n", "PLY face 0 has a vertex index outside 0..2"),
        (_header("ascii", 3, 1) + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 1.5\n", "PLY face 0 has a vertex index outside"),
        (_header("ascii", 3, 1) + b"0 0 0\n1 0 0\n0 x 0\n3 0 1 2\n", "line 13: malformed number 'x' in PLY data"),
        (_header("binary_little_endian", 3, 1, face="list char int vertex_indices") + b"\0" * 36 + b"\xff" + b"\0" * 12,
         "list 'vertex_indices' of -1 items does not fit"),
        (_header("binary_little_endian", 3, 1, face="list int int vertex_indices") + b"\0" * 36
         + struct.pack("<i", 2 ** 31 - 1) + b"\0" * 12, "list 'vertex_indices' of 2147483647 items does not fit"),
        (_header("binary_little_endian", 3, 1, face="list float int vertex_indices"), "unsupported property line"),
        (_header("ascii", 1, None).replace(b"format ascii", b"format binary"), "unsupported format line"),
        (_header("ascii", 1, None).replace(b"end_header\n", b""), "no 'end_header' line"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nend_header\n", "appears twice"),
        (b"plyx\n", "expected the magic 'ply'"),
        (_header("ascii", 1, None, props=("float x", "float y")) + b"0 0\n", "PLY 'vertex' element lacks ['z']"),
        (_header("ascii", 3, 1) + b"0 0 0\n1 0 0\nnan 1 0\n3 0 1 2\n", "vertex 2 (counting from 0) is not finite"),
    ],
)
def test_ply_hostile(tmp_path, data, msg):
    path = tmp_path / "h.ply"
    path.write_bytes(data)
    with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
        read_mesh(path)
    assert "h.ply" in str(info.value)


def test_ply_cloud_with_nan_vertices_drops_them(tmp_path):
    path = tmp_path / "n.ply"
    path.write_bytes(_header("ascii", 3, None) + b"0 0 0\nnan 1 0\n1 1 1\n")
    assert_array_equal(read_point_cloud(path), [[0, 0, 0], [1, 1, 1]])


def test_ascii_compiled_token_parser_matches_numpy(tmp_path, monkeypatch):
    from eppf.io import _ply

    if _ply._parse_tokens is None:
        pytest.skip("eppf.io._xyz_fast is not compiled")
    data, v, polys = _random_mixed_mesh(np.random.RandomState(4), "ascii")
    good = tmp_path / "g.ply"
    good.write_bytes(data.replace(b"\n", b" \r\n", 5))
    bad = tmp_path / "b.ply"
    bad.write_bytes(data.replace(b"\n1 2\n", b"\n1 0x2\n"))
    compiled = read_mesh(good)
    with pytest.raises(FileFormatError) as c_err:
        read_mesh(bad)
    monkeypatch.setattr(_ply, "_parse_tokens", None)
    reference = read_mesh(good)
    assert_array_equal(compiled.vertices, reference.vertices)
    assert_array_equal(compiled.faces, reference.faces)
    with pytest.raises(FileFormatError) as n_err:
        read_mesh(bad)
    assert str(c_err.value) == str(n_err.value)
    assert "malformed number '0x2' in PLY data" in str(c_err.value)


@pytest.mark.parametrize("binary", [True, False])
def test_ply_polygon_longer_than_a_uchar_count(tmp_path, binary):
    # a 300-gon: its length does not fit the usual 'list uchar int', so the writer uses an int count
    angle = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    v = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(300)])
    path = tmp_path / "g.ply"
    write_mesh(path, v, np.arange(300)[None, :], binary=binary)
    assert b"property list int int vertex_indices" in path.read_bytes()[:400]
    mesh = read_mesh(path)
    assert_array_equal(mesh.faces, [[0, k, k + 1] for k in range(1, 299)])


def test_ply_cached_header_still_checks_every_file_against_its_own_size(make_cloud, tmp_path):
    # many files of one folder share a header, parsed once: the checks of each file's body stay its own
    from eppf.io import _ply

    _ply._HEADERS.clear()
    cloud = make_cloud(30)
    write_point_cloud(tmp_path / "a.ply", cloud)
    data = (tmp_path / "a.ply").read_bytes()
    assert_array_equal(read_point_cloud(tmp_path / "a.ply"), cloud.astype(np.float32).astype(np.float64))
    assert len(_ply._HEADERS) == 1
    body = data.index(b"end_header\n") + len(b"end_header\n")
    (tmp_path / "b.ply").write_bytes(data[:body + 24 * 10])  # the same header, 10 of 30 rows
    with pytest.raises(FileFormatError, match=r"b\.ply.*declares 30 rows.*truncated"):
        read_point_cloud(tmp_path / "b.ply")
    # a different header (one more comment) is parsed anew; a header that fails is never cached
    other = data.replace(b"comment written by eppf\n", b"comment written by eppf\ncomment end_header\n")
    (tmp_path / "c.ply").write_bytes(other)
    assert_array_equal(read_point_cloud(tmp_path / "c.ply"), read_point_cloud(tmp_path / "a.ply"))
    bad = data.replace(b"property float nz", b"property floatt nz")
    (tmp_path / "d.ply").write_bytes(bad)
    for _ in range(2):
        with pytest.raises(FileFormatError, match=r"d\.ply.*unsupported property line"):
            read_point_cloud(tmp_path / "d.ply")
    assert all(b"floatt" not in key for key in _ply._HEADERS)


def test_ply_header_cache_is_bounded(make_cloud, tmp_path):
    from eppf.io import _ply

    _ply._HEADERS.clear()
    cloud = make_cloud(5, normals=False)
    for i in range(_ply._HEADERS_MAX + 10):
        path = tmp_path / f"{i}.ply"
        write_point_cloud(path, cloud)
        data = path.read_bytes().replace(b"comment written by eppf", b"comment file %d" % i)
        path.write_bytes(data)
        read_point_cloud(path)
        assert len(_ply._HEADERS) <= _ply._HEADERS_MAX


def _binary_ply(path, props, rows, endian="<", more=b""):
    """A binary PLY file of one vertex element with the scalar ``props`` ((type, name) pairs), then ``more``."""
    codes = {"float": "f4", "double": "f8", "uchar": "u1", "int": "i4"}
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    head = f"ply\nformat {fmt} 1.0\nelement vertex {len(rows)}\n" + "".join(f"property {t} {n}\n" for t, n in props)
    rec = np.zeros(len(rows), dtype=[(n, endian + codes[t]) for t, n in props])
    for j, (_, n) in enumerate(props):
        rec[n] = rows[:, j]
    path.write_bytes(head.encode() + b"end_header\n" + rec.tobytes() + more)
    return path


_XYZ = ("x", "y", "z")


@pytest.mark.parametrize("endian", ["<", ">"])
@pytest.mark.parametrize("typ", ["float", "double"])
@pytest.mark.parametrize("names", [_XYZ, _XYZ + ("nx", "ny", "nz"), _XYZ + ("normal_x", "normal_y", "normal_z")])
def test_ply_plain_vertex_block_is_read_as_the_general_path_reads_it(make_cloud, tmp_path, monkeypatch, endian, typ, names):
    from eppf.io import _ply

    rows = make_cloud(300, normals=True, seed=4)[:, :len(names)] * 1e3
    rows[5, 1], rows[9, 2] = np.nan, -np.inf  # dropped rows
    path = _binary_ply(tmp_path / "v.ply", [(typ, n) for n in names], rows, endian, more=b"trailing bytes")
    data = path.read_bytes()
    assert _ply._plain_vertices(data, *_ply._header(data, str(path), "t")) is not None  # the one-call path
    got = {normals: read_point_cloud(path, normals=normals) for normals in ("auto", False)}
    monkeypatch.setattr(_ply, "_plain_vertices", lambda *args: None)
    for normals, cloud in got.items():
        want = read_point_cloud(path, normals=normals)
        assert cloud.dtype == want.dtype == np.float64 and cloud.flags.c_contiguous and cloud.flags.writeable
        assert cloud.shape == want.shape == (298, len(names) if normals == "auto" else 3)
        assert cloud.tobytes() == want.tobytes()
    # and both are the file's values, widened exactly from float32
    ref = rows.astype(np.float32 if typ == "float" else np.float64).astype(np.float64)
    assert_array_equal(got["auto"], ref[np.isfinite(ref).all(axis=1)])


@pytest.mark.parametrize("props", [
    [("float", "x"), ("double", "y"), ("float", "z")],   # mixed types
    [("float", "y"), ("float", "x"), ("float", "z")],    # another order
    [("float", "x"), ("float", "y"), ("float", "z"), ("uchar", "red")],
    [("float", "x"), ("float", "y"), ("float", "z"), ("float", "nx"), ("float", "ny")],
    [("int", "x"), ("int", "y"), ("int", "z")],
])
def test_ply_other_vertex_layouts_take_the_general_path(tmp_path, props):
    from eppf.io import _ply

    rows = np.arange(12 * len(props), dtype=np.float64).reshape(12, len(props))
    path = _binary_ply(tmp_path / "o.ply", props, rows)
    data = path.read_bytes()
    assert _ply._plain_vertices(data, *_ply._header(data, str(path), "t")) is None
    cols = [n for _, n in props]
    assert_array_equal(read_point_cloud(path), rows[:, [cols.index(c) for c in _XYZ]])


def test_ply_plain_layout_truncated_or_with_faces_is_left_to_the_general_path(make_cloud, tmp_path):
    from eppf.io import _ply

    rows = make_cloud(50, normals=False)
    path = _binary_ply(tmp_path / "t.ply", [("float", n) for n in _XYZ], rows)
    path.write_bytes(path.read_bytes()[:-4])
    data = path.read_bytes()
    assert _ply._plain_vertices(data, *_ply._header(data, str(path), "t")) is None
    with pytest.raises(FileFormatError, match=r"t\.ply.*truncated, or a wrong count"):
        read_point_cloud(path)
    mesh = tmp_path / "m.ply"
    write_mesh(str(mesh), np.eye(3), np.array([[0, 1, 2]]))
    data = mesh.read_bytes()
    assert _ply._plain_vertices(data, *_ply._header(data, str(mesh), "t")) is None
    assert read_mesh(mesh).faces.tolist() == [[0, 1, 2]]


@pytest.mark.parametrize("extra", [False, True])  # the one-call vertex block, or the general path
def test_ply_signalling_nan_is_dropped_without_a_warning(tmp_path, extra):
    import warnings

    from eppf.io import read_point_fields

    rows = np.arange(12, dtype=np.float32).reshape(4, 3)
    bits = rows.view(np.uint32)
    bits[2, 1] = 0x7FA00000  # a signalling NaN: widening it to float64 raises the CPU's "invalid" flag
    props = [("float", n) for n in _XYZ] + ([("uchar", "red")] if extra else [])
    head = "ply\nformat binary_little_endian 1.0\nelement vertex 4\n" + "".join(f"property {t} {n}\n" for t, n in props)
    rec = np.zeros(4, dtype=[(n, "<f4" if t == "float" else "u1") for t, n in props])
    for j, n in enumerate(_XYZ):
        rec[n] = rows[:, j]  # (float32 into float32: the bits are copied)
    assert rec["y"].view(np.uint32)[2] == 0x7FA00000
    path = tmp_path / "s.ply"
    path.write_bytes(head.encode() + b"end_header\n" + rec.tobytes())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # NumPy's "invalid value encountered in cast" would fail here
        cloud = read_point_cloud(path)
        points, _ = read_point_fields(path)
    assert_array_equal(cloud, rows[[0, 1, 3]].astype(np.float64))
    assert points.shape == (4, 3) and np.isnan(points[2, 1]) and points[3, 1] == 10.0  # every point kept there


@pytest.mark.parametrize("binary", [False, True])
def test_ply_cloud_as_pcl_writes_it_with_an_empty_face_element(tmp_path, binary):
    # PCL's PLYWriter writes every cloud with "element face 0" of no properties (then a camera element):
    # read_point_cloud and read_mesh refused them ("'face' element has no 'vertex_indices' list")
    from eppf.io import read_point_fields

    head = ("ply\nformat {} 1.0\ncomment PCL generated\nelement vertex 2\nproperty float x\nproperty float y\n"
            "property float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float curvature\n"
            "element face 0\nelement camera 1\nproperty float view_px\nproperty float focal\nend_header\n")
    rows = np.array([[1, 2, 3, 0, 0, 1, 0.5], [4, 5, 6, 0, 1, 0, 0.25]], dtype="<f4")
    path = tmp_path / "pcl.ply"
    if binary:
        path.write_bytes(head.format("binary_little_endian").encode() + rows.tobytes()
                         + np.array([0, 1], dtype="<f4").tobytes())
    else:
        path.write_text(head.format("ascii") + "1 2 3 0 0 1 0.5\n4 5 6 0 1 0 0.25\n0 1\n")
    assert_array_equal(read_point_cloud(path), rows[:, :6])
    mesh = read_mesh(path)
    assert_array_equal(mesh.vertices, rows[:, :3])
    assert mesh.faces.shape == (0, 3)
    assert read_point_fields(path)[1]["curvature"].tolist() == [0.5, 0.25]
