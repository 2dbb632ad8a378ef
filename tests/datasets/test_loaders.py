"""Tests of the folder loaders on tiny layouts written by the tests."""

import json
import os
import re
import warnings

import joblib
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from eppf.datasets import load_modelnet, load_s3dis_objects, load_scannet_objects

# a box of half-size h centred at the origin: 8 vertices, 12 triangles
_BOX_F = np.array(
    [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
     [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
)


def _box_vertices(h):
    return np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], dtype=float)


def _write_off(path, h, glued=True):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    v = _box_vertices(h)
    head = "OFF8 12 0\n" if glued else "OFF\n8 12 0\n"
    body = "".join(f"{a:g} {b:g} {c:g}\n" for a, b, c in v) + "".join(f"3 {a} {b} {c}\n" for a, b, c in _BOX_F)
    with open(path, "w") as fh:
        fh.write(head + body)


def _modelnet_official(root):
    """ModelNet40/<class>/<split>/*.off with sizes that encode the object."""
    base = os.path.join(root, "ModelNet40")
    sizes = {}
    for cls, k_train, k_test in (("chair", 3, 1), ("bed", 2, 2), ("airplane", 2, 1)):
        for split, count in (("train", k_train), ("test", k_test)):
            for k in range(count):
                h = 1.0 + len(sizes) * 0.5
                name = f"{cls}_{k + 1:04d}"
                _write_off(os.path.join(base, cls, split, name + ".off"), h, glued=k % 2 == 0)
                sizes[name if split == "train" else name + "t"] = h
    return base


def test_modelnet_official_layout(tmp_path):
    _modelnet_official(tmp_path)
    data = load_modelnet(tmp_path, n_points=100)
    assert data.layout == "official"
    assert data.target_names.tolist() == ["airplane", "bed", "chair"]
    assert len(data.data) == 11
    assert all(c.shape == (100, 6) for c in data.data)
    assert sorted(data.split.tolist()) == ["test"] * 4 + ["train"] * 7
    assert data.skipped == []
    # every point lies on its box: its largest absolute coordinate is the half-size
    for cloud, fname in zip(data.data, data.filenames):
        h = np.abs(cloud[:, :3]).max()
        assert_allclose(np.abs(cloud[:, :3]).max(axis=1), h)
        assert_allclose(np.linalg.norm(cloud[:, 3:], axis=1), 1)
    chair = data.target_names.tolist().index("chair")
    assert (data.target == chair).sum() == 4


def test_modelnet_subset_version_and_determinism(tmp_path):
    _modelnet_official(tmp_path)
    train = load_modelnet(tmp_path, n_points=50, subset="train")
    assert set(train.split) == {"train"} and len(train.data) == 7
    ten = load_modelnet(tmp_path, n_points=50, version=10)
    assert ten.target_names.tolist() == ["bed", "chair"] and len(ten.data) == 8
    again = load_modelnet(tmp_path, n_points=50, subset="train")
    for a, b in zip(train.data, again.data):
        assert_array_equal(a, b)
    other = load_modelnet(tmp_path, n_points=50, subset="train", random_state=1)
    assert not np.allclose(train.data[0], other.data[0])
    with joblib.parallel_config(backend="threading"):
        par = load_modelnet(tmp_path, n_points=50, subset="train", n_jobs=2)
    for a, b in zip(train.data, par.data):
        assert_array_equal(a, b)
    X, y = load_modelnet(tmp_path, n_points=50, subset="test", return_X_y=True, normals=False)
    assert len(X) == 4 and X[0].shape == (50, 3) and y.dtype == np.int64


def test_modelnet_resolution(tmp_path):
    _modelnet_official(tmp_path)
    data = load_modelnet(tmp_path, n_points=None, resolution=0.5, subset="test")
    # boxes of side 2h sampled on a 0.5 grid: more points for larger boxes
    sizes = [np.abs(c[:, :3]).max() for c in data.data]
    counts = [c.shape[0] for c in data.data]
    assert np.all(np.diff(np.array(counts)[np.argsort(sizes)]) > 0)


def test_modelnet_corrupt_file_raise_and_skip(tmp_path):
    base = _modelnet_official(tmp_path)
    bad = os.path.join(base, "bed", "train", "bed_0002.off")
    with open(bad, "w") as fh:
        fh.write("OFF\n8 12 0\n0 0 0\n1 0 0\n")  # truncated
    with pytest.raises(ValueError, match=re.escape(f"load_modelnet: could not read {bad!r}")) as info:
        load_modelnet(tmp_path, n_points=20)
    assert "line 4: file ends after 2 of 8 vertices (truncated)" in str(info.value)
    with pytest.warns(UserWarning, match=re.escape("load_modelnet: skipped 1 of 11 files that could not be read")):
        data = load_modelnet(tmp_path, n_points=20, on_error="skip")
    assert len(data.data) == 10
    assert bad not in data.filenames.tolist()
    assert data.skipped[0][0] == bad
    # the other objects do not change when one file is skipped
    clean = load_modelnet(tmp_path, n_points=20, subset="test")
    part = data.split == "test"
    for a, b in zip(np.array(data.data, dtype=object)[part], clean.data):
        assert_array_equal(a, b)


def _modelnet_resampled(root, n_rows=20):
    base = os.path.join(root, "modelnet40_normal_resampled")
    os.makedirs(base)
    names = ["airplane", "bed", "chair"]
    with open(os.path.join(base, "modelnet40_shape_names.txt"), "w") as fh:
        fh.write("\n".join(names) + "\n")
    rng = np.random.RandomState(0)
    split = {"train": ["bed_0001", "chair_0001", "airplane_0001"], "test": ["chair_0002"]}
    arrays = {}
    for s, ids in split.items():
        with open(os.path.join(base, f"modelnet40_{s}.txt"), "w") as fh:
            fh.write("\n".join(ids) + "\n")
        for obj in ids:
            cls = obj.rsplit("_", 1)[0]
            os.makedirs(os.path.join(base, cls), exist_ok=True)
            xyz = rng.uniform(-1, 1, size=(n_rows, 3))
            nrm = rng.normal(size=(n_rows, 3))
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            arr = np.hstack([xyz, nrm])
            np.savetxt(os.path.join(base, cls, obj + ".txt"), arr, fmt="%.6f", delimiter=",")
            arrays[obj] = np.round(arr, 6)
    return base, arrays


def test_modelnet_resampled_layout(tmp_path):
    base, arrays = _modelnet_resampled(tmp_path)
    data = load_modelnet(tmp_path, n_points=8)
    assert data.layout == "resampled"
    assert data.target_names.tolist() == ["airplane", "bed", "chair"]
    assert data.ids.tolist() == ["bed_0001", "chair_0001", "airplane_0001", "chair_0002"]
    assert data.target.tolist() == [1, 2, 0, 2]
    for obj, cloud in zip(data.ids, data.data):
        assert_allclose(cloud, arrays[obj][:8], atol=2e-6)
    full = load_modelnet(base, n_points=None, normals=False, subset="test")
    assert full.data[0].shape == (20, 3)
    ten = load_modelnet(base, n_points=None, version=10)
    assert ten.target_names.tolist() == ["bed", "chair"] and ten.target.tolist() == [0, 1, 1]
    with pytest.raises(ValueError, match=re.escape("has 20 points, fewer than n_points=50")):
        load_modelnet(base, n_points=50)
    with pytest.raises(ValueError, match=re.escape("resolution applies to meshes")):
        load_modelnet(base, n_points=None, resolution=0.1)


def test_modelnet_hdf5_layout(tmp_path):
    h5py = pytest.importorskip("h5py")
    base = tmp_path / "modelnet40_ply_hdf5_2048"
    base.mkdir()
    (base / "shape_names.txt").write_text("airplane\nbed\nchair\n")
    rng = np.random.RandomState(0)
    blocks = {}
    for name, labels in (("ply_data_train0.h5", [0, 2, 1]), ("ply_data_train1.h5", [2]), ("ply_data_test0.h5", [1, 0])):
        data = rng.uniform(size=(len(labels), 16, 3)).astype("f4")
        nrm = rng.normal(size=(len(labels), 16, 3)).astype("f4")
        with h5py.File(base / name, "w") as fh:
            fh["data"] = data
            fh["label"] = np.array(labels, dtype="u1")[:, None]
            fh["normal"] = nrm
        blocks[name] = (data, nrm, labels)
    (base / "ply_data_test_0_id2file.json").write_text(json.dumps(["bed/bed_0517.ply", "airplane/airplane_0700.ply"]))
    data = load_modelnet(tmp_path, n_points=10)
    assert data.layout == "hdf5"
    assert data.target.tolist() == [0, 2, 1, 2, 1, 0]
    assert data.split.tolist() == ["train"] * 4 + ["test"] * 2
    assert data.ids.tolist()[-2:] == ["bed_0517", "airplane_0700"]
    d0, n0, _ = blocks["ply_data_train0.h5"]
    assert_allclose(data.data[1], np.hstack([d0[1, :10], n0[1, :10]]))
    ten = load_modelnet(tmp_path, n_points=None, version=10, normals=False)
    assert ten.target_names.tolist() == ["bed", "chair"] and ten.target.tolist() == [1, 0, 1, 0]
    assert ten.data[0].shape == (16, 3)
    (base / "ply_data_train1.h5").write_bytes(b"not an hdf5 file")
    with pytest.raises(ValueError, match=r"could not read '.*ply_data_train1\.h5'.*not a readable HDF5 file"):
        load_modelnet(tmp_path, n_points=None)
    with pytest.warns(UserWarning, match="skipped 1 of 3 files"):
        assert len(load_modelnet(tmp_path, on_error="skip", n_points=None).data) == 5


@pytest.mark.parametrize(
    "kwargs, exc, msg",
    [
        ({"version": 20}, ValueError, "load_modelnet: version must be 40 or 10, got 20"),
        ({"subset": "val"}, ValueError, "load_modelnet: subset must be one of ['all', 'train', 'test'], got 'val'"),
        ({"on_error": "ignore"}, ValueError, "on_error must be one of ['raise', 'skip'], got 'ignore'"),
        ({"n_points": 1}, ValueError, "load_modelnet: n_points must be None or an int >= 2, got 1"),
        ({"n_points": 2.0}, TypeError, "load_modelnet: n_points must be None or an int >= 2, got 2.0"),
        ({"resolution": 0.0, "n_points": None}, ValueError, "resolution must be None or a positive finite float, got 0.0"),
        ({"resolution": 0.1}, ValueError, "give n_points or resolution, not both"),
        ({"n_points": None}, ValueError, "meshes need n_points or resolution"),
        ({"normals": "yes"}, ValueError, "load_modelnet: normals must be 'auto', True or False, got 'yes'"),
    ],
)
def test_modelnet_parameter_errors(tmp_path, kwargs, exc, msg):
    _modelnet_official(tmp_path)
    with pytest.raises(exc, match=re.escape(msg)):
        load_modelnet(tmp_path, **kwargs)


def _flag_calls():
    from eppf.datasets import fetch_file, fetch_modelnet, load_folder, load_npz, make_shapes

    folder = lambda func: lambda tmp_path, **kw: func(tmp_path, **kw)  # noqa: E731
    return [
        ("load_modelnet", "return_X_y", folder(load_modelnet)),
        ("load_modelnet", "normals", folder(load_modelnet)),
        ("load_scannet_objects", "return_X_y", folder(load_scannet_objects)),
        ("load_scannet_objects", "normals", folder(load_scannet_objects)),
        ("load_s3dis_objects", "return_X_y", folder(load_s3dis_objects)),
        ("load_folder", "return_X_y", folder(load_folder)),
        ("load_folder", "normals", folder(load_folder)),
        ("load_npz", "return_X_y", lambda tmp_path, **kw: load_npz(tmp_path / "none.npz", **kw)),
        ("make_shapes", "return_X_y", lambda tmp_path, **kw: make_shapes(1, n_points=8, **kw)),
        ("make_shapes", "with_normals", lambda tmp_path, **kw: make_shapes(1, n_points=8, **kw)),
        ("fetch_file", "download_if_missing", lambda tmp_path, **kw: fetch_file("file:///x", data_home=tmp_path, **kw)),
        ("fetch_modelnet", "download_if_missing", lambda tmp_path, **kw: fetch_modelnet(10, data_home=tmp_path, **kw)),
    ]


@pytest.mark.parametrize("value", ["yes", 1, 0, None, np.int64(1)])
@pytest.mark.parametrize("owner, name, call", _flag_calls(), ids=lambda x: x if isinstance(x, str) else "")
def test_a_flag_that_is_not_a_bool_is_refused_naming_the_function(tmp_path, owner, name, call, value):
    # the flags were taken by truthiness ("yes" was True, None False) and normals by ==, which took 1 and 0
    # and then read them as "auto": every one is now True or False (or a numpy.bool_), as estimators check theirs
    accepted = "'auto', True or False" if name == "normals" else "True or False"
    with pytest.raises(TypeError, match=re.escape(f"{owner}: {name} must be {accepted}, got {value!r}")):
        call(tmp_path, **{name: value})


def test_a_numpy_bool_flag_is_the_bool_it_holds():
    from eppf.datasets import make_shapes

    X, y = make_shapes(1, n_points=8, classes=["box"], with_normals=np.True_, return_X_y=np.True_)
    assert X[0].shape == (8, 6) and y.tolist() == [0]
    assert make_shapes(1, n_points=8, classes=["box"], with_normals=np.False_).data[0].shape == (8, 3)


def test_modelnet_missing_and_unknown_layout(tmp_path):
    with pytest.raises(FileNotFoundError, match="load_modelnet: no such folder"):
        load_modelnet(tmp_path / "nothing")
    (tmp_path / "stuff").mkdir()
    with pytest.raises(ValueError, match="load_modelnet: no ModelNet layout found"):
        load_modelnet(tmp_path)


# --------------------------------------------------------------------------- ScanNet


def _cloud(rng, n=30):
    return rng.uniform(-1, 1, size=(n, 3))


def test_scannet_split_folders(tmp_path):
    rng = np.random.RandomState(0)
    saved = {}
    for split, cls, k in (("train", "chair", 3), ("train", "table", 2), ("test", "Chair", 1), ("train", "laptop", 2)):
        folder = tmp_path / split / cls
        folder.mkdir(parents=True)
        for j in range(k):
            arr = _cloud(rng)
            np.save(folder / f"scene000{j}_00_{cls}_{j}.npy", arr)
            saved[f"{split}/{cls}/{j}"] = arr
    _write_off(str(tmp_path / "test" / "table" / "scene0100_00_7.off"), 0.5)
    data = load_scannet_objects(tmp_path, n_points=None, resolution=0.25)
    assert data.target_names.tolist()[:3] == ["basket", "bathtub", "bed"]
    names = data.target_names.tolist()
    # laptop is not one of the paper's classes; "Chair" is matched in lower case
    assert sorted(names[t] for t in data.target) == ["chair"] * 4 + ["table"] * 3
    assert (data.split == "test").sum() == 2
    first_chair = data.data[data.ids.tolist().index("scene0000_00_chair_0")]
    assert_array_equal(first_chair, saved["train/chair/0"])
    mesh_cloud = data.data[data.ids.tolist().index("scene0100_00_7")]
    assert mesh_cloud.shape[1] == 6 and mesh_cloud.shape[0] > 8
    resampled = load_scannet_objects(tmp_path, n_points=16, subset="train")
    assert all(c.shape[0] == 16 for c in resampled.data) and len(resampled.data) == 5


def test_scannet_list_files(tmp_path):
    rng = np.random.RandomState(1)
    for cls, stems in (("bed", ["scene0001_00_3", "scene0002_00_1"]), ("lamp", ["scene0001_00_9", "odd_object"])):
        (tmp_path / cls).mkdir()
        for stem in stems:
            np.savetxt(tmp_path / cls / f"{stem}.xyz", _cloud(rng))
    (tmp_path / "train.txt").write_text("scene0001_00\nodd_object\n")
    (tmp_path / "test.txt").write_text("scene0002_00\n")
    data = load_scannet_objects(tmp_path, classes=["lamp", "bed"])
    assert data.target_names.tolist() == ["lamp", "bed"]
    got = dict(zip(data.ids.tolist(), data.split.tolist()))
    assert got == {"scene0001_00_3": "train", "scene0002_00_1": "test", "scene0001_00_9": "train", "odd_object": "train"}
    os.remove(tmp_path / "test.txt")
    with pytest.raises(ValueError, match=re.escape("has neither train/ and test/ folders nor the split lists ['test.txt']")):
        load_scannet_objects(tmp_path)


def test_scannet_corrupt_and_errors(tmp_path):
    folder = tmp_path / "train" / "chair"
    folder.mkdir(parents=True)
    np.save(folder / "a.npy", _cloud(np.random.RandomState(0)))
    (folder / "b.xyz").write_text("1 2 3\n4 5\n")
    with pytest.raises(ValueError, match=re.escape("b.xyz' line 2: expected 3 values in point 1, got 2")):
        load_scannet_objects(tmp_path)
    with pytest.warns(UserWarning, match="load_scannet_objects: skipped 1 of 2 files"):
        assert len(load_scannet_objects(tmp_path, on_error="skip").data) == 1
    with pytest.raises(ValueError, match="give n_points or resolution"):
        load_scannet_objects(tmp_path, resolution=None)
    with pytest.raises(ValueError, match="classes must be a non-empty sequence"):
        load_scannet_objects(tmp_path, classes="chair")
    # names are compared in lower case: the same class twice gave two target names, one never used
    with pytest.raises(ValueError, match=re.escape("load_scannet_objects: classes repeats ['chair']")):
        load_scannet_objects(tmp_path, classes=["Chair", "chair"])
    with pytest.raises(ValueError, match="holds no object files of the classes"):
        load_scannet_objects(tmp_path, classes=["sofa"])


# --------------------------------------------------------------------------- S3DIS


def _s3dis(root, layout):
    """layout: {(area, room): {class: count}}; rows x y z r g b."""
    rng = np.random.RandomState(0)
    for (area, room), counts in layout.items():
        folder = root / f"Area_{area}" / room / "Annotations"
        folder.mkdir(parents=True)
        for cls, count in counts.items():
            for k in range(1, count + 1):
                arr = np.hstack([rng.uniform(size=(12, 3)), rng.randint(0, 256, size=(12, 3))])
                np.savetxt(folder / f"{cls}_{k}.txt", arr, fmt=["%.6f"] * 3 + ["%d"] * 3)


S3DIS_LAYOUT = {
    (1, "office_1"): {"chair": 3, "wall": 4, "clutter": 2, "table": 1},
    (1, "hallway_2"): {"door": 2, "floor": 1},
    (2, "office_1"): {"chair": 2, "table": 4, "ceiling": 1},
}


def test_s3dis_classes_and_split(tmp_path):
    _s3dis(tmp_path, S3DIS_LAYOUT)
    data = load_s3dis_objects(tmp_path)
    names = data.target_names.tolist()
    assert len(names) == 10 and "wall" not in names and "clutter" not in names
    labels = [names[t] for t in data.target]
    assert sorted(labels) == ["chair"] * 5 + ["door"] * 2 + ["table"] * 5
    assert all(c.shape == (12, 3) for c in data.data)  # colours dropped
    for cls, n in (("chair", 5), ("door", 2), ("table", 5)):
        in_class = np.array(labels) == cls
        # 60/40 per class, rounded to nearest
        assert (data.split[in_class] == "train").sum() == int(np.floor(0.6 * n + 0.5))
    assert "Area_1/office_1/chair_1" in data.ids.tolist()
    k = data.ids.tolist().index("Area_2/office_1/table_3")
    assert_allclose(data.data[k], np.loadtxt(tmp_path / "Area_2" / "office_1" / "Annotations" / "table_3.txt")[:, :3])
    again = load_s3dis_objects(tmp_path)
    assert_array_equal(again.split, data.split)
    splits = {tuple(load_s3dis_objects(tmp_path, random_state=s).split) for s in range(6)}
    assert len(splits) > 1
    train = load_s3dis_objects(tmp_path, subset="train", n_points=5)
    assert len(train.data) == (data.split == "train").sum() and all(c.shape == (5, 3) for c in train.data)
    area2 = load_s3dis_objects(tmp_path, areas=[2])
    assert all(i.startswith("Area_2/") for i in area2.ids)


def test_s3dis_corrupt_file(tmp_path):
    _s3dis(tmp_path, S3DIS_LAYOUT)
    bad = tmp_path / "Area_1" / "hallway_2" / "Annotations" / "door_2.txt"
    bad.write_text("1 2 3 4 5 6\n1 2 3 4 5 \x7f\n")
    with pytest.raises(ValueError, match=re.escape(f"{str(bad)!r} line 2: malformed number")):
        load_s3dis_objects(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = load_s3dis_objects(tmp_path, on_error="skip")
    assert len(data.data) == 11
    assert any("skipped 1 of 12 files" in str(w.message) for w in caught)
    assert data.skipped[0][0] == str(bad)


@pytest.mark.parametrize(
    "kwargs, exc, msg",
    [
        ({"train_size": 1.0}, ValueError, "load_s3dis_objects: train_size must be a number in (0, 1), got 1.0"),
        ({"classes": []}, ValueError, "classes must be a non-empty sequence"),
        ({"classes": ["chair", "chair"]}, ValueError, "load_s3dis_objects: classes repeats ['chair']"),
        ({"classes": ["wall2"]}, ValueError, "no annotation files of the classes ['wall2']"),
        ({"subset": "val"}, ValueError, "subset must be one of"),
    ],
)
def test_s3dis_errors(tmp_path, kwargs, exc, msg):
    _s3dis(tmp_path, S3DIS_LAYOUT)
    with pytest.raises(exc, match=re.escape(msg)):
        load_s3dis_objects(tmp_path, **kwargs)


def test_s3dis_empty_folder(tmp_path):
    with pytest.raises(ValueError, match="no Area_<n>/<room>/Annotations/<class>_<k>.txt files"):
        load_s3dis_objects(tmp_path)


def test_hdf5_without_h5py_names_the_extra(tmp_path, monkeypatch):
    import sys

    base = tmp_path / "h5"
    base.mkdir()
    (base / "shape_names.txt").write_text("chair\n")
    (base / "ply_data_train0.h5").write_bytes(b"")
    monkeypatch.setitem(sys.modules, "h5py", None)
    with pytest.raises(ImportError, match=re.escape("the HDF5 layout needs the 'h5py' package; install it with `pip install eppf[io]`")):
        load_modelnet(base, n_points=None)


# --------------------------------------------------------------------------- paths and sizes, every loader


@pytest.mark.parametrize("loader", [load_modelnet, load_scannet_objects, load_s3dis_objects])
def test_a_path_of_another_type_is_a_type_error_naming_the_loader(loader):
    # os.fspath's "expected str, bytes or os.PathLike object, not int" named no loader
    with pytest.raises(TypeError, match=rf"{loader.__name__}: path must be a str, bytes or os\.PathLike path, got int"):
        loader(5)


def test_loaders_read_a_bytes_path(tmp_path):
    _modelnet_official(tmp_path)
    by_str = load_modelnet(str(tmp_path), n_points=32)
    by_bytes = load_modelnet(os.fsencode(tmp_path), n_points=32)
    assert by_bytes.filenames.tolist() == by_str.filenames.tolist()
    for a, b in zip(by_bytes.data, by_str.data):
        assert_array_equal(a, b)


@pytest.mark.parametrize("loader", [load_modelnet, load_scannet_objects, load_s3dis_objects])
def test_a_huge_n_points_is_refused_by_every_loader(tmp_path, loader):
    with pytest.raises(ValueError, match=rf"{loader.__name__}: n_points must be at most 1,000,000,000 points per object"):
        loader(tmp_path, n_points=10**12)


def test_npz_and_data_home_paths(tmp_path):
    from eppf.datasets import fetch_file, get_data_home, load_npz, save_npz

    clouds = [np.zeros((3, 3)), np.ones((2, 3))]
    path = os.fsencode(tmp_path / "pair.npz")
    assert save_npz(path, clouds, [0, 1], ["a", "b"]) == str(tmp_path / "pair.npz")
    assert load_npz(path).filename == str(tmp_path / "pair.npz")
    assert get_data_home(os.fsencode(tmp_path / "home")) == str(tmp_path / "home")
    for call, name in ((lambda: load_npz(1.5), "load_npz: path"), (lambda: save_npz(None, clouds, [0, 1], ["a", "b"]), "save_npz: path"),
                       (lambda: get_data_home(7), "get_data_home: data_home"),
                       (lambda: fetch_file("file:///x", data_home=7, download_if_missing=False), "fetch_file: data_home"),
                       (lambda: fetch_file("file:///x", data_home=tmp_path, filename=3), "fetch_file: filename")):
        with pytest.raises(TypeError, match=rf"{name} must be a str, bytes or os\.PathLike path"):
            call()


@pytest.mark.parametrize("random_state, exc", [(1.5, TypeError), ("seed", TypeError), (-1, ValueError)])
def test_a_bad_random_state_is_named_by_every_loader(tmp_path, random_state, exc):
    # scikit-learn's "1.5 cannot be used to seed a numpy.random.RandomState instance" named no loader
    from eppf.datasets import load_folder, make_shapes

    for loader in (load_modelnet, load_scannet_objects, load_s3dis_objects, load_folder):
        with pytest.raises(exc, match=rf"{loader.__name__}: random_state must be "):
            loader(tmp_path, random_state=random_state)
    with pytest.raises(exc, match=r"make_shapes: random_state must be "):
        make_shapes(1, n_points=8, random_state=random_state)


@pytest.mark.parametrize("areas, exc, msg", [
    ("12", TypeError, "load_s3dis_objects: areas must be None or a sequence of area numbers (ints), got '12'"),
    (2, TypeError, "load_s3dis_objects: areas must be None or a sequence of area numbers (ints), got 2"),
    ([1.7], ValueError, "load_s3dis_objects: areas must be non-negative ints (the n of Area_<n>), got 1.7"),
    ([True], ValueError, "load_s3dis_objects: areas must be non-negative ints (the n of Area_<n>), got True"),
])
def test_s3dis_areas_that_are_not_area_numbers(tmp_path, areas, exc, msg):
    # int(a) for a in areas read "12" as areas 1 and 2 and 1.7 as area 1, silently
    _s3dis(tmp_path, S3DIS_LAYOUT)
    with pytest.raises(exc, match=re.escape(msg)):
        load_s3dis_objects(tmp_path, areas=areas)
    assert {i.split("/")[0] for i in load_s3dis_objects(tmp_path, areas=(a for a in [2])).ids} == {"Area_2"}


@pytest.mark.parametrize("n_jobs, exc, msg", [(0, ValueError, "n_jobs must be None or a non-zero int"),
                                              (1.5, TypeError, "n_jobs must be None or a non-zero int"),
                                              (10**9, ValueError, "n_jobs=1000000000 asks for more threads")])
def test_loaders_check_n_jobs(tmp_path, n_jobs, exc, msg):
    # joblib's "n_jobs == 0 in Parallel has no meaning" named no loader, and 1.5 was taken
    _modelnet_official(tmp_path)
    with pytest.raises(exc, match=re.escape(f"load_modelnet: {msg}")):
        load_modelnet(tmp_path, n_points=32, n_jobs=n_jobs)


def test_save_npz_to_a_folder_names_itself(tmp_path):
    # the rename into place failed with "Is a directory: '.../.pair.npz.xxxx.tmp' -> ...", naming a temporary file
    from eppf.datasets import save_npz

    with pytest.raises(IsADirectoryError, match=re.escape("save_npz: a folder, not a file")):
        save_npz(tmp_path, [np.zeros((2, 3))], [0], ["a"])
    assert os.listdir(tmp_path) == []
