"""OFF meshes: ModelNet's variants, the compiled and vectorised fast paths, hostile counts."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.io import FileFormatError, read_mesh, read_point_cloud, write_mesh



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
def test_off_variants(write_file, tmp_path, text):
    mesh = read_mesh(write_file(tmp_path / "m.off", text))
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
        ("OFF\n0 1 0\n3 0 1 2\n", "line 2: the mesh has no vertices"),
    ],
)
def test_off_malformed(write_file, tmp_path, text, msg):
    path = write_file(tmp_path / "bad.off", text)
    with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
        read_mesh(path)
    assert "bad.off" in str(info.value)



@pytest.mark.parametrize(
    "text, plain",
    [
        ("OFF\n4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 3\n", True),
        ("OFF4 2 0\n" + SQUARE + "3 0 1 2\n3 0 2 3", True),  # no final newline
        ("\n OFF 4 2 0\r\n" + SQUARE.replace("\n", "\r\n") + "\n\n3 0 1 2\r\n3\t0 2 3\n\n", True),
        ("OFF\n4 2 0\n0 0 0\n1e0 -0 0\n+1 1.0 0\n.0 1 0\n3 0 1 2\n3 0 2 3\n", True),
        ("OFF\n4 1 0\n" + SQUARE + "4 0 1 2 3\n", False),  # a quad: the general reader
        ("OFF\n4 2 0\n" + SQUARE + "3 0 1 2 255 0 0\n3 0 2 3 255 0 0\n", False),  # face colours
        ("OFF\n4 2 0 # counts\n" + SQUARE + "3 0 1 2\n3 0 2 3\n", False),
    ],
)
def test_off_compiled_path_matches_general_reader(write_file, tmp_path, text, plain):
    from eppf.io import _off as io

    if io._parse_off_body is None:
        pytest.skip("eppf.io._off_fast is not compiled")
    data = text.encode()
    fast = io._read_off_compiled(data)
    assert (fast is not None) == plain
    # the reference: the line-by-line reader, with both fast paths switched off
    path = write_file(tmp_path / "m.off", text)
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
    from eppf.io import _off as io

    if io._parse_off_body is None:
        pytest.skip("eppf.io._off_fast is not compiled")
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



# --------------------------------------------------------------------------- hostile counts and values


@pytest.mark.parametrize(
    "text, msg",
    [
        ("OFF\n999999999999 1 0\n0 0 0\n", "line 3: file ends after 1 of 999999999999 vertices (truncated)"),
        ("OFF999999999999 1 0\n0 0 0\n", "file ends after 1 of 999999999999 vertices"),
        ("OFF\n3 99999999999999999999999999 0\n" + "0 0 0\n" * 3, "file ends after 0 of 99999999999999999999999999 faces"),
        ("OFF\n-1 1 0\n0 0 0\n", "line 2: expected the counts"),
        ("OFF\n1e308 1 0\n0 0 0\n", "line 2: expected the counts"),
        ("OFF\nnan 1 0\n0 0 0\n", "line 2: expected the counts"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 99999999999999999999999\n", "line 6: face index out of range 0..2"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -99999999999999999999999\n", "line 6: face index out of range 0..2"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n99999999999999999999999 0 1 2\n", "line 6: a face needs at least 3"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n-1 0 1 2\n", "line 6: a face needs at least 3"),
        ("OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "line 4: vertex 1 is not finite"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 -inf 0\n3 0 1 2\n", "line 5: vertex 2 is not finite"),
        ("OFF\n3 1 0\n0 0 0\n1e999 0 0\n0 1 0\n3 0 1 2\n", "is not finite"),
    ],
)
def test_off_hostile(write_file, tmp_path, text, msg):
    path = write_file(tmp_path / "h.off", text)
    for reader in (read_mesh, read_point_cloud):
        with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
            reader(path)
        assert "h.off" in str(info.value)


def test_off_nan_vertex_rejected_on_every_path(write_file, tmp_path):
    # the compiled parser leaves NaN to the general reader, which names the line
    from eppf.io import _off

    text = "OFF\n4 2 0\n0 0 0\n1 0 0\nnan 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"
    assert _off._read_off_compiled(text.encode()) is None
    with pytest.raises(FileFormatError, match=re.escape("line 5: vertex 2 is not finite")):
        read_mesh(write_file(tmp_path / "n.off", text))


def test_off_counts_checked_before_the_compiled_parser_allocates():
    from eppf.io import _off

    # 10**9 vertices declared in 20 bytes: the compiled reader refuses (and the general one reports)
    assert not _off._fits(10 ** 9, 0, 20)
    assert _off._fits(3, 1, len("0 0 0\n1 0 0\n0 1 0\n3 0 1 2"))
    assert _off._read_off_compiled(b"OFF\n1000000000 0 0\n0 0 0\n") is None


def test_off_homogeneous_vertices_are_divided_by_w(write_file, tmp_path):
    # Geomview's 4OFF stores x y z w (then normals, colours); its first three columns were taken as the point
    path = write_file(tmp_path / "h.off", "4OFF\n3 1 0\n0 0 0 2\n2 0 0 2\n0 3 0 0.5\n3 0 1 2\n")
    mesh = read_mesh(path)
    assert_array_equal(mesh.vertices, [[0, 0, 0], [1, 0, 0], [0, 6, 0]])
    assert_array_equal(mesh.faces, [[0, 1, 2]])
    path = write_file(tmp_path / "inf.off", "C4OFF\n3 1 0\n0 0 0 1 0 0 0\n1 0 0 0 0 0 0\n0 1 0 1 0 0 0\n3 0 1 2\n")
    with pytest.raises(FileFormatError, match=re.escape("inf.off' line 4: vertex 1 has w = 0 (a point at infinity)")):
        read_mesh(path)


@pytest.mark.parametrize("head, body, msg", [
    (b"OFF BINARY\n", b"\x00\x00\x00\x03\x00\x00\x00\x01\x00\x00\x00\x00" + b"\x80" * 36,
     "line 1: a binary OFF file ('OFF BINARY'); eppf reads text OFF only"),
    (b"\nOFF BINARY\n", b"3 1 0\n",  # (bytes that happen to decode: not read as counts either)
     "line 2: a binary OFF file ('OFF BINARY'); eppf reads text OFF only"),
    (b"nOFF\n3\n", b"3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
     "line 1: an OFF file of n-dimensional vertices ('nOFF'); eppf reads 3D vertices only"),
])
def test_off_variants_eppf_cannot_read_are_refused_naming_them(write_file, tmp_path, head, body, msg):
    # these were refused as "not a text file (undecodable byte ...)" or "expected the counts ..."
    path = write_file(tmp_path / "v.off", head + body, mode="wb")
    with pytest.raises(FileFormatError, match=re.escape(f"v.off' {msg}")):
        read_mesh(path)
