"""NumPy .npy arrays and .npz archives, including hostile headers and corrupt archives."""

import re

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from eppf.io import FileFormatError, read_point_cloud



def test_npz_data_set_points_to_load_npz(tmp_path):
    path = tmp_path / "set.npz"
    np.savez(path, points=np.zeros((4, 3)), offsets=np.array([0, 4]))
    with pytest.raises(FileFormatError, match=re.escape("read it with eppf.datasets.load_npz")):
        read_point_cloud(path)


def test_npy_wrong_shape(tmp_path):
    path = tmp_path / "x.npy"
    np.save(path, np.zeros((4, 2)))
    with pytest.raises(FileFormatError, match=re.escape("must hold a numeric array of shape (n_points, 3+)")):
        read_point_cloud(path)



def test_npy_wider_than_six_columns_has_normals_only_where_they_are_unit_vectors(tmp_path):
    # columns 4 to 6 of a (100, 100) grid (PDAL's test data) or of x y z r g b intensity rows were returned as
    # normals; they are normals only where every row there has unit length, as in a text table
    from eppf.io import read_point_fields

    rng = np.random.default_rng(0)
    colour = np.column_stack([rng.normal(size=(5, 3)), rng.integers(0, 256, size=(5, 3)), rng.random(5)])
    np.save(tmp_path / "colour.npy", colour)
    assert_array_equal(read_point_cloud(tmp_path / "colour.npy"), colour[:, :3])
    assert read_point_fields(tmp_path / "colour.npy")[1] == {}
    assert_array_equal(read_point_cloud(tmp_path / "colour.npy", normals=True), colour[:, :6])
    unit = rng.normal(size=(5, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    curvature = np.column_stack([colour[:, :3], unit, rng.random(5)])
    np.savez(tmp_path / "curvature.npz", points=curvature)
    assert_array_equal(read_point_cloud(tmp_path / "curvature.npz"), curvature[:, :6])
    np.save(tmp_path / "six.npy", colour[:, :6])  # six columns: normals, as write_point_cloud writes them
    assert_array_equal(read_point_cloud(tmp_path / "six.npy"), colour[:, :6])


def _npy_bytes(arr):
    import io

    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def test_npy_npz_match_numpy(tmp_path):
    arr = np.random.RandomState(0).normal(size=(30, 6)).astype(np.float32)
    np.save(tmp_path / "a.npy", arr)
    np.save(tmp_path / "f.npy", np.asfortranarray(arr))
    np.savez_compressed(tmp_path / "c.npz", points=arr[:, :3], normals=arr[:, 3:])
    for name in ("a.npy", "f.npy", "c.npz"):
        assert_array_equal(read_point_cloud(tmp_path / name, normals=True), arr.astype(np.float64))



def test_npz_of_open3d_positions_and_normals(tmp_path):
    """Open3D's o3d.t.io.write_point_cloud(.npz) stores 'positions', 'normals', 'colors', 'intensity' (float32,
    intensity (n, 1)); it was refused as holding several arrays none named 'points'."""
    rng = np.random.RandomState(1)
    xyz, nrm = rng.normal(size=(20, 3)).astype(np.float32), rng.normal(size=(20, 3)).astype(np.float32)
    np.savez(tmp_path / "o3d.npz", positions=xyz, normals=nrm, colors=rng.uniform(size=(20, 3)).astype(np.float32),
             intensity=rng.uniform(size=(20, 1)).astype(np.float32))
    assert read_point_cloud(tmp_path / "o3d.npz").tobytes() == np.hstack([xyz, nrm]).astype(np.float64).tobytes()
    np.savez(tmp_path / "o3d_xyz.npz", positions=xyz, colors=rng.uniform(size=(20, 3)).astype(np.float32))
    assert read_point_cloud(tmp_path / "o3d_xyz.npz").tobytes() == xyz.astype(np.float64).tobytes()
    np.savez(tmp_path / "other.npz", a=xyz, b=nrm)
    with pytest.raises(FileFormatError, match=re.escape("holds the arrays ['a', 'b']; expected one array or one named")):
        read_point_cloud(tmp_path / "other.npz")


@pytest.mark.parametrize(
    "shape, msg",
    [
        ("(1000000000000, 3)", "the header declares an array of shape (1000000000000, 3) (24000000000000 bytes), but only"),
        ("(4, 3)", "the header declares an array of shape (4, 3) (96 bytes), but only 24 bytes"),
        ("(-1, 3)", "negative shape"),
    ],
)
def test_npy_shape_checked_against_the_file(tmp_path, shape, msg):
    data = _npy_bytes(np.zeros((1, 3)))
    data = data.replace(b"(1, 3)", shape.encode())
    path = tmp_path / "h.npy"
    path.write_bytes(data)
    with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
        read_point_cloud(path)
    assert "h.npy" in str(info.value)


@pytest.mark.parametrize(
    "data, msg",
    [
        (b"\x93NUMPY\x01\x00\x10\x00{'descr': 'nope'", "not a readable .npy array"),
        (b"not numpy at all", "not a readable .npy array"),
        (_npy_bytes(np.array([[1, 2, 3]], dtype=object)), "pickled objects are refused"),
        (_npy_bytes(np.zeros((2, 3), dtype=complex)), "must hold a numeric array"),
        (_npy_bytes(np.zeros(2, dtype=[("x", "f4"), ("y", "f4")])),
         "holds a structured array with the fields ['x', 'y']; expected a plain numeric array"),
    ],
)
def test_npy_malformed(tmp_path, data, msg):
    path = tmp_path / "m.npy"
    path.write_bytes(data)
    with pytest.raises(FileFormatError, match=re.escape(msg)) as info:
        read_point_cloud(path)
    assert "m.npy" in str(info.value)


def test_npz_corrupt_archives(tmp_path):
    import zipfile

    np.savez_compressed(tmp_path / "ok.npz", points=np.zeros((100, 3)))
    good = (tmp_path / "ok.npz").read_bytes()
    cases = {
        "trunc.npz": good[:len(good) // 2],  # zipfile.BadZipFile
        "notzip.npz": b"PK\x03\x04" + b"\0" * 40,
    }
    # flip bytes inside the deflated member: zlib.error or a CRC error
    flipped = bytearray(good)
    for k in range(60, 90):
        flipped[k] ^= 0x5A
    cases["flip.npz"] = bytes(flipped)
    # an unsupported compression method (NotImplementedError inside zipfile)
    method = bytearray(good)
    method[8:10] = (99).to_bytes(2, "little")
    cd = bytes(method).rfind(b"PK\x01\x02")
    method[cd + 10:cd + 12] = (99).to_bytes(2, "little")
    cases["method.npz"] = bytes(method)
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(FileFormatError, match=re.escape(name)):
            read_point_cloud(tmp_path / name)
    # a member declaring far more bytes than deflate can give
    with zipfile.ZipFile(tmp_path / "bomb.npz", "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("points.npy", _npy_bytes(np.zeros((10, 3))))
    data = bytearray((tmp_path / "bomb.npz").read_bytes())
    cd = bytes(data).rfind(b"PK\x01\x02")
    data[cd + 24:cd + 28] = (2 ** 32 - 1).to_bytes(4, "little")
    (tmp_path / "bomb.npz").write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match="more than its compression can give"):
        read_point_cloud(tmp_path / "bomb.npz")


@pytest.mark.parametrize("ext", ["npy", "npz"])
def test_float32_signalling_nan_is_read_without_a_warning(tmp_path, ext):
    import warnings

    from eppf.io import read_point_fields

    rows = np.arange(12, dtype=np.float32).reshape(4, 3)
    rows.view(np.uint32)[2, 1] = 0x7FA00000  # a signalling NaN: widening it raises the CPU's "invalid" flag
    path = tmp_path / f"s.{ext}"
    np.save(path, rows) if ext == "npy" else np.savez(path, points=rows)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # NumPy's cast warning would fail here (the reader called it a malformed file)
        cloud = read_point_cloud(path)
        points, _ = read_point_fields(path)
    assert_array_equal(cloud, rows[[0, 1, 3]].astype(np.float64))  # the NaN point dropped
    assert points.shape == (4, 3) and np.isnan(points[2, 1])
