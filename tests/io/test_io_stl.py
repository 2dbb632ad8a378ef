"""STL meshes: binary (told apart by its size, not by 'solid') and ASCII."""

import re
import struct

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.utils._sampling import object_rng, sample_mesh
from eppf.io import FileFormatError, read_mesh, read_point_cloud, write_mesh

SQUARE = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
FACES = np.array([[0, 1, 2], [0, 2, 3]])


def _binary(triangles, header=b"binary", count=None):
    n = len(triangles) if count is None else count
    body = b"".join(struct.pack("<12fH", 0, 0, 1, *np.ravel(t), 0) for t in triangles)
    return header.ljust(80, b" ") + struct.pack("<I", n) + body


ASCII = """solid square
  facet normal 0 0 1
    outer loop
      vertex 0 0 0
      vertex 1 0 0
      vertex 1 1 0
    endloop
  endfacet
  facet normal 0 0 1
    outer loop
      vertex 0 0 0
      vertex 1 1 0
      vertex 0 1 0
    endloop
  endfacet
endsolid square
"""


def _same_triangles(mesh, triangles):
    assert_array_equal(mesh.vertices[mesh.faces], np.asarray(triangles, dtype=np.float64))


@pytest.mark.parametrize("header", [b"binary", b"solid square (a binary file that starts like an ASCII one)"])
def test_binary_stl(tmp_path, header):
    path = tmp_path / "b.stl"
    path.write_bytes(_binary(SQUARE[FACES], header))
    mesh = read_mesh(path)
    _same_triangles(mesh, SQUARE[FACES])
    assert mesh.vertices.shape == (4, 3)  # shared corners merged


def test_ascii_stl(tmp_path):
    path = tmp_path / "a.STL"
    path.write_text(ASCII)
    mesh = read_mesh(path)
    _same_triangles(mesh, SQUARE[FACES])
    assert mesh.faces.dtype == np.int64 and mesh.vertices.dtype == np.float64


@pytest.mark.parametrize("binary", [True, False])
def test_stl_round_trip_and_polygons(tmp_path, binary):
    rng = np.random.RandomState(0)
    v = rng.normal(size=(10, 3))
    f = np.array([[0, 1, 2, 3], [4, 5, 6, 7], [7, 8, 9, 0]])
    path = tmp_path / "m.stl"
    write_mesh(path, v, f, binary=binary)
    fan = np.array([[a, b, c] for p in f for a, b, c in zip([p[0]] * 2, p[1:3], p[2:4])])
    expected = v[fan].astype(np.float32) if binary else v[fan]
    _same_triangles(read_mesh(path), expected)


def test_stl_sampled_like_sample_mesh(tmp_path):
    path = tmp_path / "s.stl"
    path.write_text(ASCII)
    mesh = read_mesh(path)
    ref = sample_mesh(mesh.vertices, mesh.faces, n_points=300, random_state=object_rng(11))
    assert_array_equal(read_point_cloud(path, n_points=300, random_state=11), ref)
    assert_allclose(ref[:, 3:], np.tile([0, 0, 1], (300, 1)))


@pytest.mark.parametrize(
    "data, msg",
    [
        (_binary(SQUARE[FACES], count=10 ** 9), "nor a binary one (184 bytes, not 84 + 50 x 1000000000"),
        (_binary(SQUARE[FACES], header=b"solid x", count=10 ** 9), "not an ASCII STL (non-ASCII byte)"),
        (_binary(SQUARE[FACES])[:-1], "nor a binary one (183 bytes"),
        (b"\x00" * 20, "less than the 84 of a binary header"),
        (ASCII.replace("      vertex 0 1 0\n", "").encode(), "line 13: a facet needs 3 vertices, got 2"),
        (ASCII.replace("vertex 1 1 0\n    endloop", "vertex 1 1\n    endloop", 1).encode(), "line 6: a vertex needs 3 coordinates"),
        (ASCII.replace("vertex 1 0 0", "vertex 1 zero 0").encode(), "line 5: malformed vertex"),
        (ASCII.replace("vertex 1 0 0", "vertex nan 0 0").encode(), "triangle 0 has a non-finite vertex"),
        (ASCII[:ASCII.index("    endloop")].encode(), "file ends inside a facet (truncated)"),
        (ASCII.replace("outer loop", "inner loop", 1).encode(), "line 3: unexpected 'inner'"),
    ],
)
def test_stl_malformed(tmp_path, data, msg):
    path = tmp_path / "bad.stl"
    path.write_bytes(data)
    for reader in (read_mesh, read_point_cloud):
        with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
            reader(path)
        assert "bad.stl" in str(info.value)


def test_binary_stl_nan_vertex_names_the_byte(tmp_path):
    tri = SQUARE[FACES].copy()
    tri[1, 2, 0] = np.nan
    path = tmp_path / "n.stl"
    path.write_bytes(_binary(tri))
    with pytest.raises(FileFormatError, match=re.escape("byte 134: triangle 1 has a non-finite vertex")):
        read_mesh(path)
