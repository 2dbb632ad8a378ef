"""Wavefront OBJ meshes."""

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.io import FileFormatError, read_mesh, read_point_cloud



def test_obj_index_forms(write_file, tmp_path):
    text = (
        "# cube corner\nmtllib x.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
        "f 1/1/1 2/1/1 3/1/1\nf 1//1 3//1 4//1\nf -4 -3 -2 -1\n"
    )
    mesh = read_mesh(write_file(tmp_path / "m.obj", text))
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
def test_obj_malformed(write_file, tmp_path, text, msg):
    path = write_file(tmp_path / "bad.obj", text)
    with pytest.raises(FileFormatError, match=re.escape(msg)):
        read_mesh(path)



def test_obj_polygon_fan_and_sampling(write_file, tmp_path):
    path = write_file(tmp_path / "q.OBJ", "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nf 1 2 3 4\n")
    mesh = read_mesh(path)
    assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
    cloud = read_point_cloud(path, n_points=400, random_state=5)
    assert cloud.shape == (400, 6)
    assert_allclose(cloud[:, 2], 0)
    assert cloud[:, 0].min() >= 0 and cloud[:, 0].max() <= 2 and cloud[:, 1].max() <= 1
    assert_allclose(cloud[:, 3:], np.tile([0, 0, 1], (400, 1)))


@pytest.mark.parametrize(
    "text, msg",
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n", "line 4: face index out of range 1..3"),
        ("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "vertex 1 (counting from 0) is not finite"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -99999999999999999999\n", "line 4: face index out of range 1..3"),
        ("v 0 0 0\n\xff\n", "is not a text file (undecodable byte at offset 8)"),
    ],
)
def test_obj_hostile(tmp_path, text, msg):
    path = tmp_path / "h.obj"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
        read_mesh(path)
    assert "h.obj" in str(info.value)
