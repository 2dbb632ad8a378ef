"""load_folder: a labelled data set from one subfolder per class."""

import os
import re

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from eppf.datasets import load_folder
from eppf.io import read_point_cloud, write_mesh, write_point_cloud

RNG = np.random.default_rng(0)
CLOUDS = {name: [RNG.normal(size=(50 + 10 * k, 3)) for k in range(3)] for name in ("mug", "box")}



def _has(module):
    import importlib.util

    return importlib.util.find_spec(module) is not None

def _write_flat(root, ext=".xyz"):
    for name, clouds in CLOUDS.items():
        os.makedirs(root / name / "deeper", exist_ok=True)
        for k, cloud in enumerate(clouds):
            sub = "deeper" if k == 2 else ""
            write_point_cloud(root / name / sub / f"o{k}{ext}", cloud)


def test_flat_layout_reads_files_as_they_are(tmp_path):
    _write_flat(tmp_path)
    (tmp_path / "box" / "notes.md").write_text("not an object")
    (tmp_path / "box" / ".hidden.xyz").write_text("1 2 3\n")
    data = load_folder(tmp_path)
    assert data.target_names.tolist() == ["box", "mug"]
    assert data.split is None
    assert data.ids.tolist() == ["box/deeper/o2", "box/o0", "box/o1", "mug/deeper/o2", "mug/o0", "mug/o1"]
    assert data.target.tolist() == [0, 0, 0, 1, 1, 1]
    for cloud, ident in zip(data.data, data.ids):
        name, k = ident.split("/")[0], int(ident[-1])
        assert_array_equal(cloud, read_point_cloud(tmp_path / f"{ident}.xyz"))
        np.testing.assert_allclose(cloud, CLOUDS[name][k], rtol=1e-6)


@pytest.mark.parametrize("layout", ["split_first", "class_first"])
def test_split_layouts(tmp_path, layout):
    for name, clouds in CLOUDS.items():
        for k, cloud in enumerate(clouds):
            split = "test" if k == 0 else "train"
            folder = tmp_path / (f"{split}/{name}" if layout == "split_first" else f"{name}/{split}")
            os.makedirs(folder, exist_ok=True)
            write_point_cloud(folder / f"o{k}.pcd", cloud)
    data = load_folder(tmp_path)
    assert sorted(data.split.tolist()) == ["test"] * 2 + ["train"] * 4
    test = load_folder(tmp_path, subset="test")
    assert len(test.data) == 2 and set(test.split.tolist()) == {"test"}
    assert test.target_names.tolist() == ["box", "mug"]


def test_classes_select_and_order(tmp_path):
    _write_flat(tmp_path)
    data = load_folder(tmp_path, classes=["mug", "box"])
    assert data.target_names.tolist() == ["mug", "box"]
    assert data.target.tolist() == [1, 1, 1, 0, 0, 0]
    X, y = load_folder(tmp_path, classes=["mug"], return_X_y=True)
    assert len(X) == 3 and set(y.tolist()) == {0}


def test_meshes_are_sampled_deterministically(tmp_path):
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    faces = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    for name in ("a", "b"):
        os.makedirs(tmp_path / name)
        write_mesh(tmp_path / name / "tet.off", vertices, faces)
        write_mesh(tmp_path / name / "tet.ply", vertices, faces)
    data = load_folder(tmp_path)
    assert [c.shape for c in data.data] == [(2048, 6)] * 4
    for cloud in data.data:  # on the tetrahedron's surface: x, y, z >= 0, x + y + z <= 1
        assert cloud[:, :3].min() >= -1e-12 and cloud[:, :3].sum(axis=1).max() <= 1 + 1e-9
    again = load_folder(tmp_path, n_points=100, normals=False)
    assert [c.shape for c in again.data] == [(100, 3)] * 4
    assert_array_equal(again.data[0], load_folder(tmp_path, n_points=100, normals=False).data[0])
    assert not np.array_equal(again.data[0], load_folder(tmp_path, n_points=100, normals=False,
                                                        random_state=1).data[0])


def test_bad_file_raise_and_skip(tmp_path):
    _write_flat(tmp_path)
    (tmp_path / "mug" / "broken.xyz").write_text("1 2\n3 4 5 6\n")
    with pytest.raises(ValueError, match="load_folder: could not read .*broken.xyz"):
        load_folder(tmp_path)
    with pytest.warns(UserWarning, match="skipped 1 of 7 files"):
        data = load_folder(tmp_path, on_error="skip")
    assert len(data.data) == 6 and len(data.skipped) == 1


@pytest.mark.parametrize("kwargs, msg", [
    (dict(classes=["cat"]), "load_folder: no object files for the classes ['cat']"),
    (dict(classes="mug"), "load_folder: classes must be None or a non-empty sequence"),
    # a repeated class gave two target names and every object the second label
    (dict(classes=["mug", "box", "mug"]), "load_folder: classes repeats ['mug']; each class must be named once"),
    (dict(subset="train"), "load_folder: "),
    (dict(subset="val"), "subset"),
    (dict(n_points=0), "n_points"),
    (dict(on_error="ignore"), "on_error"),
])
def test_parameter_errors(tmp_path, kwargs, msg):
    _write_flat(tmp_path)
    with pytest.raises(ValueError, match=re.escape(msg)):
        load_folder(tmp_path, **kwargs)


def test_empty_or_missing_folder(tmp_path):
    with pytest.raises(ValueError, match=re.escape("load_folder: ") + ".*holds no class folders"):
        load_folder(tmp_path)
    with pytest.raises((ValueError, FileNotFoundError), match="load_folder"):
        load_folder(tmp_path / "absent")


def test_every_supported_format_in_any_case_is_loaded_like_read_point_cloud(tmp_path):
    """load_folder reads each file with read_point_cloud and the file's own seed, for every format."""
    from eppf.datasets._loaders import file_seeds
    from eppf.io import supported_extensions

    rng = np.random.RandomState(1)
    v = rng.normal(size=(8, 3))
    f = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [4, 5, 6], [5, 6, 7]])
    cloud = np.hstack([rng.normal(size=(40, 3)), np.tile([0.0, 0.0, 1.0], (40, 1))])
    os.makedirs(tmp_path / "a")
    # every format eppf writes (E57 is only read; LAS and LAZ need the las extra): tests/io reads the others
    exts = [e for e in supported_extensions() if e != ".e57" and (e not in (".las", ".laz") or _has("laspy"))]
    for k, ext in enumerate(exts):
        name = tmp_path / "a" / f"o{k}{ext.upper() if k % 2 else ext}"
        if ext in (".off", ".obj", ".stl"):
            write_mesh(name, v, f)
        elif ext == ".xyzrgb":
            np.savetxt(name, np.hstack([cloud[:, :3], np.full((40, 3), 128.0)]))
        else:
            write_point_cloud(name, cloud)
    for n_points in (None, 64):
        data = load_folder(tmp_path, n_points=n_points, random_state=5)
        assert len(data.data) == len(exts)
        seeds = file_seeds(5, str(tmp_path), list(data.filenames))
        for got, name, seed in zip(data.data, data.filenames, seeds):
            assert_array_equal(got, read_point_cloud(name, n_points=n_points, random_state=seed))
            assert got.shape[0] == (n_points or (2048 if name.lower().endswith((".off", ".obj", ".stl")) else 40))


@pytest.mark.parametrize("folders, kind, want", [
    # train|test/<class>/...: files elsewhere (a class folder beside the splits, loose files) are left out
    (["train/cup", "test/cup", "train/pot/deep", "plate", "."], "split/class",
     {"train/cup": ("cup", "train"), "test/cup": ("cup", "test"), "train/pot/deep": ("pot", "train")}),
    # <class>/train|test/...: the class folders' other files are left out
    (["cup/train", "cup/test", "pot/test/deep", "pot/old", "."], "class/split",
     {"cup/train": ("cup", "train"), "cup/test": ("cup", "test"), "pot/test/deep": ("pot", "test")}),
    # <class>/...: no split, deeper folders belong to their class
    (["cup", "pot/deep/er", "."], "class", {"cup": ("cup", ""), "pot/deep/er": ("pot", "")}),
])
def test_load_folder_and_the_command_line_read_a_folder_by_one_rule(tmp_path, folders, kind, want):
    from eppf.cli._common import plan_inputs
    from eppf.datasets._folder import folder_layout, object_files

    root = tmp_path / "d"
    for k, sub in enumerate(folders + [".hidden", "cup/.cache"]):
        os.makedirs(root / sub, exist_ok=True)
        write_point_cloud(root / sub / f"o{k}.xyz", RNG.normal(size=(20, 3)))
    files = object_files(root)
    assert not any("/." in f.replace(os.sep, "/") for f in files)  # hidden files and folders skipped
    layout, got_kind = folder_layout(root, files)
    got = {os.path.relpath(os.path.dirname(f), root).replace(os.sep, "/"): cls for f, cls in zip(files, layout)}
    assert {k: v for k, v in got.items() if v is not None} == want
    assert got_kind == kind
    data = load_folder(root)
    expected = sorted(want.items(), key=lambda kv: kv[1])
    assert sorted(zip(data.ids.tolist(), data.target_names[data.target].tolist(),
                      [""] * len(data.ids) if data.split is None else data.split.tolist())) == \
        sorted((f"{where}/o{folders.index(where)}", cls, split) for where, (cls, split) in expected)
    plan = plan_inputs([str(root)], {"random_state": 0}, labelled=True)
    cli = sorted((os.path.relpath(f, root).replace(os.sep, "/").rsplit(".", 1)[0], *cls) for f, _, cls in plan.entries)
    assert cli == sorted(zip(data.ids.tolist(), data.target_names[data.target].tolist(),
                             [""] * len(data.ids) if data.split is None else data.split.tolist()))


def _undecodable_name(folder):
    """A file name that is not UTF-8 (Latin-1 bytes, as some tools and archives write), or skip where the
    file system refuses one (macOS, Windows)."""
    path = os.path.join(os.fsencode(folder), b"caf\xe9.xyz")
    try:
        with open(path, "wb") as fh:
            fh.write(b"".join(b"%r %r %r\n" % tuple(row) for row in RNG.normal(size=(60, 3)).tolist()))
    except (OSError, ValueError):
        pytest.skip("this file system does not store names that are not UTF-8")
    return os.fsdecode(path)


def test_a_file_name_that_is_not_utf8_is_loaded_with_its_own_seed(tmp_path):
    import hashlib

    from eppf.datasets._loaders import file_seeds

    _write_flat(tmp_path)
    name = _undecodable_name(tmp_path / "mug")
    data = load_folder(tmp_path, n_points=20, random_state=3)  # (it raised UnicodeEncodeError hashing the name)
    assert name in list(data.filenames)
    seed = file_seeds(3, str(tmp_path), [name])[0]
    k = list(data.filenames).index(name)
    assert_array_equal(data.data[k], read_point_cloud(name, n_points=20, random_state=seed))
    # the seed hashes the name's own bytes, and a UTF-8 name's as before (its str encoded as UTF-8)
    base = int(np.random.RandomState(3).randint(0, np.iinfo(np.int64).max, dtype=np.int64))
    for path, raw in ((name, b"mug/caf\xe9.xyz"), (str(tmp_path / "box" / "0.xyz"), b"box/0.xyz")):
        want = int.from_bytes(hashlib.blake2b(b"%d/%s" % (base, raw), digest_size=8).digest(), "little")
        assert file_seeds(3, str(tmp_path), [path]) == [want]


def test_classes_that_are_not_a_collection(tmp_path):
    # len(5) raised a bare "object of type 'int' has no len()"
    _write_flat(tmp_path)
    with pytest.raises(TypeError, match=re.escape("load_folder: classes must be None or a non-empty sequence of class names, got 5")):
        load_folder(tmp_path, classes=5)
    # any iterable of names is read once, in its order
    data = load_folder(tmp_path, classes=(name for name in ["mug", "box"]))
    assert data.target_names.tolist() == ["mug", "box"]


def _symlink_or_skip(target, link, **kwargs):
    try:
        os.symlink(target, link, **kwargs)
    except (OSError, NotImplementedError, AttributeError) as exc:  # (Windows without the privilege, ...)
        pytest.skip(f"symbolic links are not supported here ({exc})")


def test_symlinked_class_folders_and_files_are_followed(tmp_path):
    # os.walk does not follow links by default: a class folder that is a link was left out
    root, store = tmp_path / "data", tmp_path / "store"
    os.makedirs(root / "mug")
    write_point_cloud(root / "mug" / "o0.xyz", CLOUDS["mug"][0])
    os.makedirs(store / "boxes")
    write_point_cloud(store / "boxes" / "o0.xyz", CLOUDS["box"][0])
    write_point_cloud(store / "lone.xyz", CLOUDS["mug"][1])
    _symlink_or_skip(store / "boxes", root / "box", target_is_directory=True)
    _symlink_or_skip(store / "lone.xyz", root / "mug" / "o1.xyz")
    data = load_folder(root)
    assert data.target_names.tolist() == ["box", "mug"]
    assert data.ids.tolist() == ["box/o0", "mug/o0", "mug/o1"]
    np.testing.assert_allclose(data.data[0], CLOUDS["box"][0], rtol=1e-6)
    np.testing.assert_allclose(data.data[2], CLOUDS["mug"][1], rtol=1e-6)


def test_a_symlink_back_up_the_tree_is_not_followed(tmp_path):
    # following links must not loop forever on a link to a folder above it
    _write_flat(tmp_path)
    _symlink_or_skip(tmp_path, tmp_path / "mug" / "deeper" / "up", target_is_directory=True)
    _symlink_or_skip(tmp_path / "mug", tmp_path / "mug" / "again", target_is_directory=True)
    data = load_folder(tmp_path)
    assert data.ids.tolist() == ["box/deeper/o2", "box/o0", "box/o1", "mug/deeper/o2", "mug/o0", "mug/o1"]


@pytest.mark.parametrize("kind", ["str", "bytes", "pathlib"])
def test_path_may_be_str_bytes_or_path_like(tmp_path, kind):
    # a bytes path failed inside os.walk ("startswith first arg must be bytes")
    _write_flat(tmp_path)
    path = {"str": str(tmp_path), "bytes": os.fsencode(tmp_path), "pathlib": tmp_path}[kind]
    data = load_folder(path)
    assert data.ids.tolist() == ["box/deeper/o2", "box/o0", "box/o1", "mug/deeper/o2", "mug/o0", "mug/o1"]
    assert all(isinstance(f, str) for f in data.filenames.tolist())


@pytest.mark.parametrize("path", [3, None, ["a"]])
def test_a_path_of_another_type_is_a_type_error_naming_it(path):
    with pytest.raises(TypeError, match=r"load_folder: path must be a str, bytes or os\.PathLike path, got "):
        load_folder(path)


def test_a_huge_n_points_is_refused_before_allocating(tmp_path):
    # NumPy's "Unable to allocate 7.28 TiB" came out of the resampling, naming neither loader nor parameter
    _write_flat(tmp_path)
    with pytest.raises(ValueError, match=re.escape("load_folder: n_points must be at most 1,000,000,000 points "
                                                   "per object, got 1,000,000,000,000")):
        load_folder(tmp_path, n_points=10**12)
