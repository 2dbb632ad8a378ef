"""The format table, the public API over all formats, round trips and generic errors."""

import os
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.io import (FileFormatError, Mesh, read_mesh, read_point_cloud, read_point_fields, write_mesh,
                     write_point_cloud, write_point_fields)



# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("ext", ["pcd", "ply", "xyz", "txt", "csv", "pts", "npy", "npz", "PCD", "Ply", "XYZ", "NPZ"])
@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("normals", [True, False])
def test_point_cloud_round_trip(make_cloud, tmp_path, ext, binary, normals):
    cloud = make_cloud(normals=normals)
    path = tmp_path / f"cloud.{ext}"
    write_point_cloud(path, cloud, binary=binary)
    back = read_point_cloud(path)
    assert back.shape == cloud.shape and back.dtype == np.float64
    # PCD and PLY store float32
    tol = 1e-6 if ext.lower() in ("pcd", "ply") else 0
    assert_allclose(back, cloud, rtol=tol, atol=tol)


@pytest.mark.parametrize("ext", ["off", "obj", "ply", "stl", "OFF", "Obj", "PLY", "STL"])
def test_mesh_round_trip(make_cloud, tmp_path, ext):
    vertices = make_cloud(normals=False, n=6)
    faces = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 0]])
    path = tmp_path / f"mesh.{ext}"
    write_mesh(path, vertices, faces)
    mesh = read_mesh(path)
    assert isinstance(mesh, Mesh)
    if ext.lower() == "stl":  # triangle soup with merged corners, float32 in binary
        assert_allclose(mesh.vertices[mesh.faces], vertices[faces], rtol=1e-6)
        return
    assert_allclose(mesh.vertices, vertices, rtol=1e-6 if ext.lower() == "ply" else 0)
    assert_array_equal(mesh.faces, faces)


def test_normals_false_drops_and_true_requires(make_cloud, tmp_path):
    path = tmp_path / "c.npy"
    write_point_cloud(path, make_cloud())
    assert read_point_cloud(path, normals=False).shape == (40, 3)
    path3 = tmp_path / "c3.npy"
    write_point_cloud(path3, make_cloud(normals=False))
    with pytest.raises(ValueError, match="has no normals, but normals=True"):
        read_point_cloud(path3, normals=True)



# --------------------------------------------------------------------------- generic errors


@pytest.mark.parametrize("ext", ["pcd", "xyz", "pts", "xyzn", "npy", "npz", "off", "obj", "ply", "stl"])
def test_empty_file(write_file, tmp_path, ext):
    path = write_file(tmp_path / f"empty.{ext}", "")
    readers = [read_point_cloud] + ([read_mesh] if ext in ("off", "obj", "ply", "stl") else [])
    for reader in readers:
        with pytest.raises(FileFormatError, match=re.escape(f"{path!r} is empty")):
            reader(path)


_PCD_HEAD = "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 0\nHEIGHT 1\n" \
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 0\nDATA "
_PLY_HEAD = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"


def _no_fields(path):
    write_point_fields(path, np.zeros((0, 3)), {"intensity": np.zeros(0, np.float32)})


def _las(path):
    pytest.importorskip("laspy")
    _no_fields(path)


def _e57(path):
    from .test_io_las_e57 import _e57_with_normals  # (skips without laspy, as that module does)

    pytest.importorskip("pye57")
    _e57_with_normals(path, np.zeros((0, 3)), np.zeros((0, 3)), [1, 0, 0, 0], [0, 0, 0])


def _text(content):
    def write(path):
        with open(path, "wb") as fh:
            fh.write(content.encode() if isinstance(content, str) else content)
    return write


#: A file of no points (or a mesh of no vertices) in every format, as its writers (or its tools) write one.
_NO_POINTS = {
    "ascii.pcd": _text(_PCD_HEAD + "ascii\n"),
    "binary.pcd": _text(_PCD_HEAD + "binary\n"),
    "compressed.pcd": _text((_PCD_HEAD + "binary_compressed\n").encode() + bytes(8)),
    "compressed_no_sizes.pcd": _text(_PCD_HEAD + "binary_compressed\n"),
    "written.pcd": _no_fields,
    "ascii.ply": _text(_PLY_HEAD + "property float intensity\nend_header\n"),
    "written.ply": _no_fields,
    "a.npy": lambda path: np.save(path, np.zeros((0, 3))),
    "a.npz": lambda path: np.savez(path, np.zeros((0, 6))),
    "points.npz": lambda path: np.savez(path, points=np.zeros((0, 3))),
    "open3d.pts": _text("0\r\n"),
    "header.xyz": _text("x y z intensity\n"),
    "comment.txt": _text("# no points\n\n"),
    "header.csv": _text("x,y,z\n"),
    "comment.xyzn": _text("# no points\n"),
    "header.xyzrgb": _text("x y z r g b\n"),
    "a.las": _las,
    "a.laz": _las,
    "a.e57": _e57,
    # meshes
    "a.off": _text("OFF\n0 0 0\n"),
    "a.obj": _text("# no vertices\no nothing\n"),
    "binary.stl": _text(b"empty".ljust(80) + bytes(4)),
    "ascii.stl": _text("solid empty\nendsolid empty\n"),
    "mesh.ply": _text(_PLY_HEAD + "element face 0\nproperty list uchar int vertex_indices\nend_header\n"),
}


@pytest.mark.parametrize("name", list(_NO_POINTS))
def test_a_file_of_no_points_reads_alike_in_every_format(tmp_path, name):
    # PCD's POINTS 0 was refused by every reader, as were an OFF of no vertices, an STL of no facets, an OBJ of
    # no 'v' lines and a text table of only a header or comments, while a PLY, NPY, LAS, E57 or .pts file of no
    # points was read. Now every format agrees: the readers of a file's content (read_point_fields, read_mesh)
    # give it with no rows, read_point_cloud, whose cloud needs points, says the file holds none.
    path = str(tmp_path / name)
    _NO_POINTS[name](path)
    if name.endswith((".off", ".obj", ".stl")) or name == "mesh.ply":
        mesh = read_mesh(path)
        assert mesh.vertices.shape == (0, 3) and mesh.faces.shape == (0, 3) and mesh.faces.dtype == np.int64
        modes = ("sample", "vertices")
    else:
        points, fields = read_point_fields(path)
        assert points.shape == (0, 3) and points.dtype == np.float64
        assert all(v.shape[0] == 0 for v in fields.values())
        if name in ("ascii.pcd", "written.pcd", "ascii.ply", "written.ply", "header.xyz", "a.las", "a.laz"):
            assert "intensity" in fields
        modes = ("sample",)
    for mesh_mode in modes:
        with pytest.raises(FileFormatError) as info:
            read_point_cloud(path, mesh=mesh_mode)
        assert str(info.value) == f"read_point_cloud: {path!r} holds no points"


def test_missing_file_and_folder(tmp_path):
    for name in ("none.pcd", "none.npy", "none.OFF"):
        with pytest.raises(FileNotFoundError, match="read_point_cloud: no such file") as info:
            read_point_cloud(tmp_path / name)
        assert info.value.filename == str(tmp_path / name) and name in str(info.value)
    if os.path.exists("/dev/zero"):  # an endless file must not be read
        os.symlink("/dev/zero", tmp_path / "zero.pcd")
        with pytest.raises(OSError, match="not a regular file") as info:
            read_point_cloud(tmp_path / "zero.pcd")
        assert "zero.pcd" in str(info.value)
    folder = tmp_path / "cloud.ply"
    folder.mkdir()
    for reader in (read_point_cloud, read_mesh):
        with pytest.raises(IsADirectoryError, match="a folder, not a file") as info:
            reader(folder)
        assert "cloud.ply" in str(info.value)


@pytest.mark.parametrize(
    "func, args, kwargs, exc, msg",
    [
        (read_point_cloud, ("x.foo",), {}, ValueError, "cannot tell the format of 'x.foo' from its extension '.foo'"),
        (read_point_cloud, ("x.pcd",), {"format": "rcp"}, ValueError, "unknown format 'rcp'"),
        (read_point_cloud, ("x.pcd",), {"normals": "yes"}, ValueError, "normals must be 'auto', True or False"),
        (read_mesh, ("x.rcp",), {}, ValueError, "cannot tell the format of 'x.rcp'"),
        (read_mesh, ("x.las",), {}, ValueError, "'x.las' is a las file, which holds clouds, not meshes"),
        (read_mesh, ("x.pcd",), {}, ValueError, "'x.pcd' is a pcd file, which holds clouds, not meshes"),
        (write_mesh, ("x.npy", np.eye(3), [[0, 1, 2]]), {}, ValueError, "'x.npy' is a npy file, which holds clouds"),
        (read_point_cloud, ("x.pcd",), {"mesh": "faces"}, ValueError, "mesh must be 'sample' or 'vertices'"),
        (read_point_cloud, ("x.pcd",), {"n_points": 1}, ValueError, "n_points must be None or an int >= 2, got 1"),
        (read_point_cloud, ("x.pcd",), {"n_points": 2.5}, TypeError, "n_points must be None or an int >= 2, got 2.5"),
        (read_point_cloud, ("x.pcd",), {"n_points": 10**12}, ValueError,
         "read_point_cloud: n_points must be at most 1,000,000,000 points per object, got 1,000,000,000,000"),
        (read_point_cloud, ("x.pcd",), {"resolution": np.nan}, ValueError, "resolution must be None or a positive finite float, got nan"),
        (read_point_cloud, ("x.pcd",), {"n_points": 10, "resolution": 0.1}, ValueError, "give n_points or resolution, not both"),
        (read_point_cloud, ("x.pcd",), {"random_state": -1}, ValueError, "an int random_state must lie in 0..2**64-1"),
        (read_point_cloud, ("x.pcd",), {"random_state": "seed"}, TypeError, "random_state must be None, an int or a RandomState"),
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


@pytest.mark.parametrize("value", ["yes", 1, 0, None, 1.0])
@pytest.mark.parametrize("func, args, name", [
    (read_point_cloud, ("x.npy",), "normals"),
    (read_point_cloud, ("x.npy",), "remove_nan"),
    (write_point_cloud, ("x.ply", np.eye(3)), "binary"),
    (write_mesh, ("x.ply", np.eye(3), [[0, 1, 2]]), "binary"),
])
def test_a_flag_that_is_not_a_bool_is_refused(tmp_path, monkeypatch, func, args, name, value):
    # remove_nan and binary were taken by truthiness ("yes" wrote a binary file, None an ASCII one), normals
    # by ==, which took 1 and 0 and then read them as "auto" (normals=0 kept a file's normals)
    monkeypatch.chdir(tmp_path)
    accepted = "'auto', True or False" if name == "normals" else "True or False"
    with pytest.raises(TypeError, match=re.escape(f"{func.__name__}: {name} must be {accepted}, got {value!r}")):
        func(*args, **{name: value})
    assert not os.listdir(tmp_path)  # (refused before any file is written)


def test_a_numpy_bool_flag_is_the_bool_it_holds(make_cloud, tmp_path):
    path = tmp_path / "c.ply"
    write_point_cloud(path, make_cloud(n=5), binary=np.False_)
    assert path.read_bytes().startswith(b"ply\nformat ascii")
    assert read_point_cloud(path, normals=np.False_).shape == (5, 3)  # (np.False_ read as "auto": (5, 6))
    write_point_cloud(tmp_path / "d.ply", make_cloud(n=5, normals=False))
    with pytest.raises(FileFormatError, match="has no normals, but normals=True"):  # (np.True_ read as "auto")
        read_point_cloud(tmp_path / "d.ply", normals=np.True_)


def test_the_readers_and_the_loaders_share_one_bound_on_n_points(tmp_path):
    # read_point_cloud had no upper bound (10**12 reached NumPy's allocator, naming neither it nor n_points)
    # while the loaders refused more than a billion: one check serves both, and resample too
    from eppf.datasets import load_folder
    from eppf.utils._sampling import MAX_N_POINTS, resample

    path = tmp_path / "c.npy"
    write_point_cloud(path, np.eye(3))
    for func, args in ((read_point_cloud, (path,)), (load_folder, (tmp_path,)), (resample, (np.eye(3),))):
        with pytest.raises(ValueError, match=re.escape(f"{func.__name__}: n_points must be at most 1,000,000,000 "
                                                       f"points per object, got {MAX_N_POINTS + 1:,}")):
            func(*args, n_points=MAX_N_POINTS + 1)
    assert MAX_N_POINTS == 10**9


def test_core_import_needs_no_optional_dependency(tmp_path):
    import subprocess
    import sys

    # a base install reads and writes every format, PLY included, without plyfile
    code = (
        "import sys; sys.modules['plyfile'] = None; import eppf, eppf.io, eppf.datasets, eppf.preprocessing; "
        "import numpy as np; "
        f"eppf.io.write_mesh({str(tmp_path / 'm.ply')!r}, np.eye(3), [[0, 1, 2]]); "
        f"assert eppf.io.read_point_cloud({str(tmp_path / 'm.ply')!r}, n_points=10).shape == (10, 6); "
        "bad = [m for m in ('h5py', 'trimesh') if m in sys.modules]; "
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)



# --------------------------------------------------------------------------- the one format table


def test_table_discovery_and_supported_extensions_agree(tmp_path):
    from eppf.datasets import _folder
    from eppf.io import _formats, format_of, supported_extensions

    table = set(_formats.BY_EXTENSION)
    assert set(supported_extensions()) == table
    assert set(supported_extensions("cloud")) | set(supported_extensions("mesh")) == table
    assert set(supported_extensions("mesh")) == {".off", ".obj", ".stl", ".ply"}
    assert set(supported_extensions("cloud")) & set(supported_extensions("mesh")) == {".ply"}
    # load_folder's discovery finds exactly the table's extensions, in any case, and nothing else
    exts = sorted(table) + [e.upper() for e in table] + [".rcp", ".ply.bak", ".pcd~", ".dwg", ""]
    for k, ext in enumerate(exts):
        (tmp_path / f"f{k}{ext}").write_text("x")
    found = {os.path.splitext(f)[1].lower() for f in _folder.object_files(str(tmp_path))}
    assert found == table
    assert len(_folder.object_files(str(tmp_path))) == 2 * len(table)
    # and the command line's discovery finds the very same files
    from eppf.cli._common import find_files

    _, cli_files = find_files(str(tmp_path))
    assert sorted(map(os.path.basename, cli_files)) == sorted(map(os.path.basename, _folder.object_files(str(tmp_path))))
    # every extension maps to a format that read_point_cloud dispatches, in any case
    for ext in table:
        assert format_of("a" + ext) == format_of("A" + ext.upper()) == _formats.BY_EXTENSION[ext].name


def test_format_of():
    from eppf.io import format_of

    assert [format_of(p) for p in ("a.PLY", "b.Off", "c.txt", "d.CSV", "e.xyzn", "f.pts", "g.npz", "h.Stl")] == \
        ["ply", "off", "xyz", "xyz", "xyzn", "pts", "npz", "stl"]
    assert [format_of(p) for p in ("a.LAS", "b.laz", "c.E57")] == ["las", "laz", "e57"]
    with pytest.raises(ValueError, match=re.escape("format_of: cannot tell the format of 'x.rcp'")):
        format_of("x.rcp")
    with pytest.raises(ValueError, match="kind must be None, 'cloud' or 'mesh'"):
        from eppf.io import supported_extensions

        supported_extensions("points")


def _mesh(seed=0):
    rng = np.random.RandomState(seed)
    v = rng.normal(size=(8, 3))
    f = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [4, 5, 6], [5, 6, 7], [7, 0, 3]])
    return v, f


@pytest.mark.parametrize("ext", ["off", "obj", "stl", "ply", "OFF", "Stl"])
@pytest.mark.parametrize("normals", ["auto", False])
def test_mesh_files_are_sampled_like_sample_mesh(tmp_path, ext, normals):
    """read_point_cloud of a mesh file = sample_mesh of read_mesh with the per-file generator."""
    from eppf.utils._sampling import object_rng, sample_mesh

    v, f = _mesh()
    path = tmp_path / f"m.{ext}"
    write_mesh(path, v, f)
    mesh = read_mesh(path)
    seed = 2 ** 63 + 12345  # the loaders' per-file seeds use all 64 bits
    for n_points, resolution, count in ((None, None, 2048), (500, None, 500), (None, 0.5, None)):
        ref = sample_mesh(mesh.vertices, mesh.faces, n_points=count, resolution=resolution,
                          return_normals=normals is not False, random_state=object_rng(seed))
        got = read_point_cloud(path, normals=normals, n_points=n_points, resolution=resolution, random_state=seed)
        assert_array_equal(got, ref)
    # the same settings give the same cloud; another seed another one
    assert_array_equal(read_point_cloud(path, random_state=3), read_point_cloud(path, random_state=3))
    assert not np.array_equal(read_point_cloud(path, random_state=3), read_point_cloud(path, random_state=4))
    rs = np.random.RandomState(8)
    assert_array_equal(read_point_cloud(path, normals=normals, random_state=rs),
                       sample_mesh(mesh.vertices, mesh.faces, n_points=2048,
                                   return_normals=normals is not False, random_state=np.random.RandomState(8)))


@pytest.mark.parametrize("ext", ["off", "obj", "ply"])
def test_mesh_vertices_mode(tmp_path, ext):
    v, f = _mesh()
    path = tmp_path / f"m.{ext}"
    write_mesh(path, v, f)
    assert_allclose(read_point_cloud(path, mesh="vertices"), v, rtol=1e-6 if ext == "ply" else 0)


def test_mesh_without_faces(write_file, tmp_path):
    path = write_file(tmp_path / "p.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n")
    with pytest.raises(FileFormatError, match=re.escape("has no faces, so it cannot be sampled; pass mesh='vertices'")):
        read_point_cloud(path)
    assert read_point_cloud(path, mesh="vertices").shape == (3, 3)
    # a PLY without faces is a cloud
    write_point_cloud(tmp_path / "c.ply", np.eye(3))
    assert_allclose(read_point_cloud(tmp_path / "c.ply", n_points=None), np.eye(3))


def test_degenerate_mesh_error_names_the_file(write_file, tmp_path):
    path = write_file(tmp_path / "flat.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n")
    with pytest.raises(FileFormatError, match=r"flat\.off': the off file's mesh cannot be sampled \(sample_mesh: .*area"):
        read_point_cloud(path)


@pytest.mark.parametrize("rows", ["1 2 3\n", "1 2 3\n1 2 3\n1 2 3\n"])
def test_cloud_that_cannot_be_resampled_is_not_called_malformed(write_file, tmp_path, rows):
    # A well-formed file whose cloud resample refuses (one point; all points identical) says so, with
    # resample's reason, instead of "malformed xyz file".
    path = write_file(tmp_path / "few.xyz", rows)
    assert read_point_cloud(path).shape[1] == 3
    with pytest.raises(FileFormatError, match=r"few\.xyz': the xyz file's cloud cannot be resampled to 100 points "
                                              r"\(resample: "):
        read_point_cloud(path, n_points=100)


def test_point_files_resampled_like_resample(make_cloud, tmp_path):
    from eppf.utils._sampling import resample
    from eppf.utils._sampling import object_rng

    cloud = make_cloud(n=50)
    write_point_cloud(tmp_path / "c.npy", cloud)
    for n in (20, 80):
        assert_array_equal(read_point_cloud(tmp_path / "c.npy", n_points=n, random_state=77),
                           resample(cloud, n, random_state=object_rng(77)))
    # resolution applies to meshes only: point files are kept
    assert_array_equal(read_point_cloud(tmp_path / "c.npy", resolution=0.1), cloud)


def test_every_reader_error_is_documented(tmp_path):
    """Bad bytes in every format raise FileFormatError or OSError naming the file, never another type."""
    rng = np.random.RandomState(0)
    from eppf.io import supported_extensions

    for ext in supported_extensions():
        for k in range(5):
            data = rng.randint(0, 256, size=rng.randint(1, 300), dtype=np.uint8).tobytes()
            if k == 1:
                data = b"ply\nformat binary_little_endian 1.0\n" + data
            path = tmp_path / f"r{k}{ext}"
            path.write_bytes(data)
            for reader in (read_point_cloud, read_mesh):
                try:
                    reader(path)
                except FileFormatError as exc:
                    assert path.name in str(exc)
                except ValueError as exc:  # read_mesh of a cloud format: an argument error
                    assert reader is read_mesh and "not meshes" in str(exc)


@pytest.mark.parametrize("ext", [".pcd", ".ply"])
@pytest.mark.parametrize("binary", [True, False])
def test_pcd_and_ply_store_float64_only_for_values_beyond_float32(tmp_path, ext, binary):
    # float32 as PCL writes it; a finite value beyond float32's range was written as an infinity (and the
    # point dropped on reading)
    import warnings

    rng = np.random.default_rng(0)
    unit = rng.normal(size=(30, 3))
    for cloud, wide in ((unit, False), (unit * 1e300, True), (np.hstack([unit * 1e200, unit / 2]), True)):
        path = tmp_path / f"c{ext}"
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)  # (NumPy's overflow warning of the float32 cast)
            write_point_cloud(path, cloud, binary=binary)
        head = path.read_bytes()[:400]
        assert (b"double x" in head or b"SIZE 8 8 8" in head) == wide
        back = read_point_cloud(path, normals=cloud.shape[1] == 6)
        if wide:
            assert_array_equal(back, cloud)  # (text: 17 significant digits)
        else:
            assert_allclose(back, cloud, rtol=1e-7)  # float32's precision
