"""save_npz: the writer of the flat .npz layout, checked against load_npz and the raw arrays."""

import errno
import os
import zipfile

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import eppf.utils._atomic as atomic_module
from eppf.datasets import load_npz, make_shapes, save_npz


def _clouds(rng, sizes, cols=3, dtype=np.float64):
    return [rng.normal(size=(n, cols)).astype(dtype) for n in sizes]


@pytest.mark.parametrize("cols", [3, 6])
def test_round_trip_with_load_npz(tmp_path, cols):
    rng = np.random.default_rng(0)
    clouds = _clouds(rng, [5, 1, 17, 3], cols)
    labels = [2, 0, 1, 2]
    names = ["bed", "chair", "table"]
    split = ["train", "test", "train", "test"]
    ids = ["a_1", "b", "ä_ünïcode", "d"]
    path = tmp_path / "set.npz"
    assert save_npz(path, clouds, labels, names, split=split, ids=ids) == str(path)
    data = load_npz(path)
    assert len(data.data) == 4
    for got, want in zip(data.data, clouds):
        assert got.dtype == np.float64
        assert_array_equal(got, want)
    assert data.target.tolist() == labels
    assert data.target_names.tolist() == names
    assert data.split.tolist() == split
    assert data.ids.tolist() == ids


def test_raw_layout_offsets_and_dtypes(tmp_path):
    # Hand-computed layout: sizes 2, 3 -> offsets [0, 2, 5]; float32 kept.
    clouds = [np.ones((2, 3), np.float32), np.full((3, 3), 2, np.float32)]
    path = tmp_path / "raw.npz"
    save_npz(path, clouds, np.array([0, 1], dtype=np.int32), ("x", "y"))
    with np.load(path, allow_pickle=False) as z:
        assert sorted(z.files) == ["class_names", "labels", "offsets", "points"]
        assert z["offsets"].tolist() == [0, 2, 5]
        assert z["offsets"].dtype == np.int64 and z["labels"].dtype == np.int64
        assert z["points"].dtype == np.float32
        assert z["points"][:2].tolist() == [[1, 1, 1]] * 2 and z["points"][2:].tolist() == [[2, 2, 2]] * 3
        assert z["class_names"].dtype.kind == "U"
    # integer and mixed-dtype clouds are stored as float64
    save_npz(path, [np.ones((2, 3), np.float32), np.arange(6).reshape(2, 3)], [0, 0], ["x"])
    with np.load(path, allow_pickle=False) as z:
        assert z["points"].dtype == np.float64
        assert z["points"][2:].tolist() == [[0, 1, 2], [3, 4, 5]]


def test_round_trip_of_the_built_in_shapes(tmp_path):
    shapes = make_shapes(2, n_points=50, random_state=0)
    path = tmp_path / "shapes.npz"
    save_npz(path, shapes.data, shapes.target, shapes.target_names, split=shapes.split)
    back = load_npz(path)
    assert all(np.array_equal(a, b) for a, b in zip(back.data, shapes.data))
    assert_array_equal(back.target, shapes.target)
    assert_array_equal(back.target_names, shapes.target_names)
    assert_array_equal(back.split, shapes.split)
    # a 3-D array of equal-size clouds is accepted as a sequence of clouds
    stacked = np.stack([c[:10] for c in shapes.data])
    save_npz(path, stacked, shapes.target, shapes.target_names)
    assert load_npz(path).data[3].shape == (10, 3)


@pytest.mark.parametrize(
    "clouds, labels, names, kwargs, exc, match",
    [
        ([], [], ["a"], {}, ValueError, "clouds is empty"),
        ("abc", [0], ["a"], {}, TypeError, "sequence of"),
        ([np.zeros((0, 3))], [0], ["a"], {}, ValueError, "cloud 0 has no points"),
        ([np.zeros((3, 3)), np.zeros((3, 4))], [0, 0], ["a"], {}, ValueError, r"cloud 1 must have shape"),
        ([np.zeros((3, 3)), np.zeros((3, 6))], [0, 0], ["a"], {}, ValueError, "cloud 1 has 6 columns"),
        ([np.zeros(3)], [0], ["a"], {}, ValueError, "cloud 0 must have shape"),
        ([np.array([[0, 0, np.nan]])], [0], ["a"], {}, ValueError, "cloud 0 holds NaN"),
        ([np.zeros((2, 3)), np.array([[np.inf, 0, 0]])], [0, 0], ["a"], {}, ValueError, "cloud 1 holds NaN or inf"),
        ([np.array([["a", "b", "c"]])], [0], ["a"], {}, TypeError, "cloud 0 must hold real numbers"),
        ([np.zeros((2, 3))], [0, 1], ["a", "b"], {}, ValueError, r"labels must have shape \(1,\)"),
        ([np.zeros((2, 3))], [2], ["a", "b"], {}, ValueError, "object 0 has 2"),
        ([np.zeros((2, 3))], [-1], ["a", "b"], {}, ValueError, "0..1"),
        ([np.zeros((2, 3))], [0.5], ["a"], {}, TypeError, "integer indices"),
        ([np.zeros((2, 3))], [True], ["a"], {}, TypeError, "integer indices"),
        ([np.zeros((2, 3))], ["a"], ["a"], {}, TypeError, "integer indices"),
        ([np.zeros((2, 3))], [0], "ab", {}, TypeError, "class_names must be a sequence"),
        ([np.zeros((2, 3))], [0], [], {}, ValueError, "non-empty"),
        ([np.zeros((2, 3))], [0], ["a", "a"], {}, ValueError, r"repeated: \['a'\]"),
        ([np.zeros((2, 3))], [0], [1], {}, TypeError, "'class_names' must hold strings"),
        ([np.zeros((2, 3))], [0], ["a"], {"split": ["val"]}, ValueError, "object 0 has 'val'"),
        ([np.zeros((2, 3))], [0], ["a"], {"split": ["train", "test"]}, ValueError, "'split' must have 1 entries"),
        ([np.zeros((2, 3))], [0], ["a"], {"ids": [3]}, TypeError, "'ids' must hold strings"),
    ],
)
def test_bad_input_is_refused_by_name(tmp_path, clouds, labels, names, kwargs, exc, match):
    path = tmp_path / "bad.npz"
    with pytest.raises(exc, match=match):
        save_npz(path, clouds, labels, names, **kwargs)
    assert not path.exists()
    assert os.listdir(tmp_path) == []


def test_missing_folder_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such folder"):
        save_npz(tmp_path / "nope" / "x.npz", [np.zeros((2, 3))], [0], ["a"])


def test_failed_write_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "set.npz"
    save_npz(path, [np.zeros((2, 3))], [0], ["old"])
    before = path.read_bytes()
    real_fdopen = os.fdopen

    class Full:
        def __init__(self, fh):
            self._fh, self._n = fh, 0

        def write(self, data):
            self._n += len(data)
            if self._n > 100:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return self._fh.write(data)

        def __getattr__(self, name):
            return getattr(self._fh, name)

    monkeypatch.setattr(atomic_module, "_fdopen", lambda fd, mode, **kw: Full(real_fdopen(fd, mode, **kw)))
    with pytest.raises(OSError):
        save_npz(path, [np.ones((1000, 3))], [0], ["new"])
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["set.npz"]
    assert zipfile.is_zipfile(path) and load_npz(path).target_names.tolist() == ["old"]



def _script(name="make_modelnet_npz"):
    import importlib.util

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    spec = importlib.util.spec_from_file_location(name, os.path.join(root, "scripts", f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_make_modelnet_npz_from_a_local_folder(tmp_path, capsys):
    # a two-class ModelNet10 folder in Princeton's layout: one tetrahedron mesh per file
    mesh = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 2 3\n3 1 2 3\n"
    for cls, parts in (("chair", ("train", "train", "test")), ("table", ("train", "test"))):
        for k, part in enumerate(parts):
            folder = tmp_path / "ModelNet10" / cls / part
            folder.mkdir(parents=True, exist_ok=True)
            (folder / f"{cls}_{k:04d}.off").write_text(mesh)
    out = tmp_path / "mn.npz"
    main = _script().main
    assert main(["--root", str(tmp_path / "ModelNet10"), "-o", str(out), "--n-points", "64"]) == 0
    assert "5 objects (3 train / 2 test), 2 classes" in capsys.readouterr().out
    data = load_npz(out)
    assert data.target_names.tolist() == ["chair", "table"]
    assert sorted(data.ids.tolist()) == ["chair_0000", "chair_0001", "chair_0002", "table_0000", "table_0001"]
    assert all(c.shape == (64, 3) for c in data.data)
    # sampled points lie on the mesh: in the unit tetrahedron, x, y, z >= 0 and x + y + z <= 1
    pts = np.concatenate(data.data)
    assert pts.min() >= 0 and pts.sum(axis=1).max() <= 1 + 1e-9
    split_of = dict(zip(data.ids, data.split))
    assert split_of["chair_0002"] == "test" and split_of["table_0000"] == "train"
    # seeded: a second run writes the same clouds
    assert main(["--root", str(tmp_path / "ModelNet10"), "-o", str(tmp_path / "again.npz"), "--n-points", "64"]) == 0
    assert all(np.array_equal(a, b) for a, b in zip(load_npz(tmp_path / "again.npz").data, data.data))


def test_make_modelnet_npz_missing_folder_says_what_to_do(tmp_path, capsys):
    main = _script().main
    assert main(["--root", str(tmp_path / "nowhere"), "-o", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "no such folder" in err and "--download" in err
    assert main(["--root", str(tmp_path), "-o", str(tmp_path / "x.npz")]) == 2  # no ModelNet inside
    assert "make_modelnet_npz: load_modelnet" in capsys.readouterr().err
    assert main(["--root", str(tmp_path), "-o", str(tmp_path / "no" / "x.npz")]) == 2
    assert "no such folder" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()
    with pytest.raises(SystemExit) as exc:  # neither --root nor --download
        main(["-o", str(tmp_path / "x.npz")])
    assert exc.value.code == 2 and "--root" in capsys.readouterr().err


def test_make_modelnet_npz_as_a_program_exits_2_without_traceback(tmp_path):
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    res = subprocess.run([sys.executable, os.path.join(root, "scripts", "make_modelnet_npz.py"),
                          "--root", str(tmp_path / "nowhere"), "-o", str(tmp_path / "x.npz")],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": root})
    assert res.returncode == 2 and "no such folder" in res.stderr and "Traceback" not in res.stderr


def test_reproduce_retrieval_needs_its_data_and_says_how_to_get_it(tmp_path, capsys, monkeypatch):
    main = _script("reproduce_retrieval").main
    monkeypatch.delenv("EPPF_BENCH_DATA", raising=False)
    assert main([]) == 2
    err = capsys.readouterr().err
    assert "--data-dir" in err and "make_modelnet_npz.py" in err
    assert main(["--data-dir", str(tmp_path)]) == 2
    assert "missing" in capsys.readouterr().err
    # with a (tiny) modelnet10_1024.npz present, the table is printed for the requested set
    shapes = make_shapes(3, n_points=60, random_state=0)
    save_npz(tmp_path / "modelnet10_1024.npz", shapes.data, shapes.target, shapes.target_names)
    monkeypatch.setenv("EPPF_BENCH_DATA", str(tmp_path))
    assert main(["--sets", "modelnet10_1024", "--repeats", "1", "--n-jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and lines[1].split()[:2] == ["modelnet10_1024", "object"]


def _hostile_archives(tmp_path):
    """A valid flat-layout archive, then copies of it with a huge 'points' header, a corrupt compressed member
    and an end record whose directory offset places every entry before the file's start."""
    import io
    import struct

    clouds = _clouds(np.random.default_rng(0), [5, 5])
    good = tmp_path / "good.npz"
    save_npz(good, clouds, [0, 1], ["a", "b"])
    out = {}
    with zipfile.ZipFile(good) as zin:
        members = {n: zin.read(n) for n in zin.namelist()}
    head = io.BytesIO()
    np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False, "shape": (10**11, 3)})
    for name, build in (("huge", lambda n, b: head.getvalue() + b[-240:] if n == "points.npy" else b),):
        path = tmp_path / f"{name}.npz"
        with zipfile.ZipFile(path, "w") as zout:
            for n, b in members.items():
                zout.writestr(n, build(n, b))
        out[name] = (path, r"member 'points.npy': the header declares an array of shape \(100000000000, 3\)")
    path = tmp_path / "deflated.npz"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zout:
        for n, b in members.items():
            zout.writestr(n, b)
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("points.npy")
    data[info.header_offset + 30 + len(info.filename) + 2] ^= 0xFF
    (tmp_path / "corrupt.npz").write_bytes(bytes(data))
    out["corrupt"] = (tmp_path / "corrupt.npz", r"member 'points.npy'|not a readable \.npz archive")
    data = bytearray(good.read_bytes())
    end = data.rindex(b"PK\x05\x06")
    struct.pack_into("<I", data, end + 16, struct.unpack_from("<I", data, end + 16)[0] + 2**24)
    (tmp_path / "offset.npz").write_bytes(bytes(data))
    out["offset"] = (tmp_path / "offset.npz", r"not a readable \.npz archive \(OSError")
    return out


def test_hostile_archives_give_value_errors_naming_the_file_before_allocating(tmp_path):
    # np.load allocated what a header declared (2.4 TB here), and a corrupt member or directory raised
    # zlib.error or a bare OSError
    import resource

    limit = resource.getrlimit(resource.RLIMIT_AS)
    for name, (path, pattern) in _hostile_archives(tmp_path).items():
        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, limit[1]) if limit[1] == resource.RLIM_INFINITY
                           or limit[1] > 4 << 30 else limit)
        try:
            with pytest.raises(ValueError, match=rf"^load_npz: '{path}'.*({pattern})"):
                load_npz(path)
        finally:
            resource.setrlimit(resource.RLIMIT_AS, limit)


def test_loaded_clouds_are_writable_arrays(tmp_path):
    path = tmp_path / "w.npz"
    save_npz(path, _clouds(np.random.default_rng(1), [4, 6]), [0, 0], ["a"])
    data = load_npz(path)
    assert all(c.flags.writeable for c in data.data)
    data.data[0][0, 0] = 7.0
    assert data.data[0][0, 0] == 7.0
