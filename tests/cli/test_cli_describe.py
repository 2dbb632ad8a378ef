"""``eppf describe``: every registered descriptor on the built-in shapes, and files and folders streamed
chunk by chunk into the rows of one ``fit_transform``."""

import json
import os

import numpy as np
import pytest

import eppf.cli._describe as describe_module
import eppf.streaming as streaming
from eppf.cli import main
from eppf.datasets import make_shapes
from eppf.io import write_mesh, write_point_cloud
from eppf.registry import DESCRIPTORS


@pytest.fixture(scope="module")
def shapes_npz(tmp_path_factory):
    bunch = make_shapes(2, n_points=300, classes=["box", "sphere", "cylinder"], random_state=0)
    offsets = np.cumsum([0] + [len(c) for c in bunch.data])
    path = tmp_path_factory.mktemp("shapes") / "shapes.npz"
    np.savez(path, points=np.vstack(bunch.data), offsets=offsets, labels=bunch.target,
             class_names=bunch.target_names)
    return path, bunch


@pytest.mark.parametrize("name", list(DESCRIPTORS))
def test_every_registered_descriptor_runs_through_describe(tmp_path, capsys, shapes_npz, name):
    path, bunch = shapes_npz
    out = tmp_path / "d.npz"
    status = main(["describe", str(path), "-o", str(out), "--descriptor", name, "--n-pairs", "500",
                   "--n-jobs", "1", "--no-progress"])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert "Traceback" not in captured.err
    with np.load(out) as f:
        X, labels, names, descriptor = f["descriptors"], f["labels"], list(f["class_names"]), str(f["descriptor"])
    spec = DESCRIPTORS[name]
    expected = spec.make(n_samples=500, random_state=0, n_jobs=1).fit_transform(bunch.data)
    np.testing.assert_allclose(X, expected, rtol=1e-12, atol=1e-12)
    assert descriptor == name and np.isfinite(X).all() and len(X) == len(bunch.data)
    np.testing.assert_array_equal(labels, bunch.target)
    assert names == list(bunch.target_names)
    # retrieve on this database, by the descriptor's own metric, shows the class names
    status = main(["retrieve", "--database", str(out), "--query-descriptors", str(out), "-k", "1",
                   "--no-progress"])
    table = capsys.readouterr().out.splitlines()[2:]
    assert status == 0 and len(table) == len(X)
    for line, truth in zip(table, bunch.target_names[bunch.target]):
        cells = [c.strip() for c in line.split("|")]
        assert cells[1] == truth and cells[4] == truth and float(cells[5]) == pytest.approx(0, abs=1e-9)


# ---------------------------------------------------------------------------
# Streaming files and folders: the rows of one fit_transform, chunk after chunk
# ---------------------------------------------------------------------------


def _class_folder(root):
    """Two classes of mixed files (PLY with normals, XYZ, PCD, an OFF mesh); returns the sorted paths."""
    rng = np.random.default_rng(7)
    paths = []
    for cls, stretch in (("blob", [1.0, 1.0, 1.0]), ("stick", [3.0, 0.3, 0.3])):
        (root / cls).mkdir(parents=True)
        for i in range(4):
            p = rng.normal(size=(60 + 10 * i, 3)) * stretch
            if i == 0:
                paths.append(root / cls / f"{cls}{i}.ply")
                write_point_cloud(paths[-1], np.hstack([p, p / np.linalg.norm(p, axis=1, keepdims=True)]))
            elif i == 1:
                paths.append(root / cls / f"{cls}{i}.pcd")
                write_point_cloud(paths[-1], p)
            else:
                paths.append(root / cls / f"{cls}{i}.xyz")
                write_point_cloud(paths[-1], p)
        box = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                       dtype=float) * stretch
        faces = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [2, 3, 7], [2, 7, 6],
                 [1, 2, 6], [1, 6, 5], [0, 3, 7], [0, 7, 4]]
        paths.append(root / cls / f"{cls}_mesh.off")
        write_mesh(paths[-1], box, faces)
    return sorted(paths)


def _reference(paths, root, name, seed, n_points=None, **settings):
    """Rows of the in-memory path: every file read the one way, one fit_transform."""
    from eppf.cli._common import read_inputs

    sampling = {"n_points": n_points, "resolution": None, "normals": "auto", "random_state": seed,
                "seed_rule": "blake2b-relpath-v1"}
    objects = read_inputs([str(root)], sampling)
    assert list(objects.ids) == [str(p) for p in paths]
    est = DESCRIPTORS[name].make(n_samples=500, random_state=seed, n_jobs=1, **settings)
    return est.fit_transform(objects.clouds), objects


@pytest.mark.parametrize("name, extra", [("eppf", []), ("eppf", ["--scaling", "object"]), ("esf", []),
                                         ("eppf+gasd", [])])
def test_streamed_folder_is_bit_identical_to_fit_transform_for_any_chunking_and_threads(
        tmp_path, capsys, monkeypatch, name, extra):
    paths = _class_folder(tmp_path / "data")
    settings = {"scaling": extra[1]} if extra else {}
    expected, objects = _reference(paths, tmp_path / "data", name, 4, **settings)
    for chunk, first, n_jobs in ((3, 16, "1"), (1, 16, "2"), (3, 2, "2")):  # (a first chunk shorter than others)
        monkeypatch.setattr(streaming, "CHUNK_FILES", chunk)
        monkeypatch.setattr(streaming, "FIRST_CHUNK_FILES", first)
        out = tmp_path / f"d{chunk}_{first}.npz"
        status = main(["describe", str(tmp_path / "data"), "-o", str(out), "--descriptor", name, "--n-pairs", "500",
                       "--random-state", "4", "--n-jobs", n_jobs, "--no-progress", *extra])
        captured = capsys.readouterr()
        assert status == 0, captured.err
        assert "files per second" in captured.out and f"{len(paths)} {name} descriptors" in captured.out
        with np.load(out) as f:
            np.testing.assert_array_equal(f["descriptors"], expected)
            assert list(f["ids"]) == [str(p) for p in paths]
            np.testing.assert_array_equal(f["labels"], objects.labels)
            assert list(f["class_names"]) == ["blob", "stick"]
        if chunk != 3:
            continue
        npy = tmp_path / f"d{chunk}.npy"
        assert main(["describe", str(tmp_path / "data"), "-o", str(npy), "--descriptor", name, "--n-pairs", "500",
                     "--random-state", "4", "--n-jobs", n_jobs, "--no-progress", *extra]) == 0
        np.testing.assert_array_equal(np.load(npy), expected)
    capsys.readouterr()


def test_streamed_npz_keeps_the_data_set_scale_and_parameters_of_the_in_memory_path(tmp_path, capsys, monkeypatch):
    paths = _class_folder(tmp_path / "data")
    _, objects = _reference(paths, tmp_path / "data", "eppf", 0)
    est = DESCRIPTORS["eppf"].make(n_samples=500, random_state=0, n_jobs=1).fit(objects.clouds)
    monkeypatch.setattr(streaming, "CHUNK_FILES", 2)
    assert main(["describe", str(tmp_path / "data"), "-o", str(tmp_path / "d.npz"), "--n-pairs", "500",
                 "--no-progress"]) == 0
    with np.load(tmp_path / "d.npz") as f:
        assert float(f["scale"]) == est.scale_
        params = json.loads(str(f["params"]))
    assert params["random_state"] == 0 and params["n_pairs"] == 500 and params["scaling"] == "fit"
    capsys.readouterr()


def test_skipped_files_leave_the_other_rows_as_without_them(tmp_path, capsys, monkeypatch):
    paths = _class_folder(tmp_path / "data")
    expected, _ = _reference(paths, tmp_path / "data", "eppf", 2)
    bad = tmp_path / "data" / "blob" / "blob1b.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99999\nproperty float x\n"
                    b"property float y\nproperty float z\nend_header\n" + b"\0" * 24)
    monkeypatch.setattr(streaming, "CHUNK_FILES", 2)
    status = main(["describe", str(tmp_path / "data"), "-o", str(tmp_path / "d.npz"), "--n-pairs", "500",
                   "--random-state", "2", "--no-progress"])
    captured = capsys.readouterr()
    assert status == 0
    assert "skipped 1 of 11 files" in captured.err and "blob1b.ply" in captured.err and "99999" in captured.err
    with np.load(tmp_path / "d.npz") as f:
        assert str(bad) not in list(f["ids"]) and len(f["ids"]) == len(paths)
        np.testing.assert_array_equal(f["descriptors"], expected)
    # --on-error raise: stops at that file, naming it, and leaves an existing output as it was
    before = (tmp_path / "d.npz").read_bytes()
    status = main(["describe", str(tmp_path / "data"), "-o", str(tmp_path / "d.npz"), "--n-pairs", "500",
                   "--on-error", "raise", "--no-progress"])
    err = capsys.readouterr().err
    assert status == 2 and "blob1b.ply" in err and "--on-error skip" in err and "Traceback" not in err
    assert (tmp_path / "d.npz").read_bytes() == before
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_no_readable_file_is_an_error_naming_them(tmp_path, capsys):
    folder = tmp_path / "bad"
    folder.mkdir()
    for i in range(2):
        (folder / f"x{i}.xyz").write_text("1 2\n")
    status = main(["describe", str(folder), "-o", str(tmp_path / "d.npy"), "--no-progress"])
    err = capsys.readouterr().err
    assert status == 2 and "no file could be read (2 of 2)" in err and "x0.xyz" in err
    assert not (tmp_path / "d.npy").exists()


def test_a_cloud_the_descriptor_refuses_is_named_by_its_file(tmp_path, capsys, monkeypatch):
    folder = tmp_path / "c"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        write_point_cloud(folder / f"ok{i}.xyz", rng.normal(size=(80, 3)))
    write_point_cloud(folder / "ok3_flat.xyz", np.ones((80, 3)))  # every point the same: no pair to draw
    monkeypatch.setattr(streaming, "CHUNK_FILES", 2)
    status = main(["describe", str(folder), "-o", str(tmp_path / "d.npy"), "--n-pairs", "500", "--scaling",
                   "object", "--no-progress"])
    err = capsys.readouterr().err
    assert status == 2 and "ok3_flat.xyz" in err and "Traceback" not in err, err
    assert not (tmp_path / "d.npy").exists()


def test_second_pass_rows_are_the_same_whether_clouds_are_spilled_or_read_again(tmp_path, capsys, monkeypatch):
    # the data-set scale needs a first pass; its clouds are spilled to a temporary file when reading them took
    # longer than writing them would (meshes: sampled once), else read again: the rows never change
    from eppf.cli._common import InputPlan

    paths = _class_folder(tmp_path / "data")
    expected, _ = _reference(paths, tmp_path / "data", "eppf", 9, n_points=64)
    reads = []
    real = InputPlan.read

    def counting(self, k):
        reads.append(self.entries[k][0])
        return real(self, k)

    monkeypatch.setattr(InputPlan, "read", counting)
    monkeypatch.setattr(streaming, "CHUNK_FILES", 3)
    for rate, times in ((float("inf"), 1), (0.0, 2), (streaming.SPILL_BYTES_PER_SECOND, None)):
        reads.clear()
        monkeypatch.setattr(streaming, "SPILL_BYTES_PER_SECOND", rate)
        assert main(["describe", str(tmp_path / "data"), "-o", str(tmp_path / "d.npy"), "--n-pairs", "500",
                     "--n-points", "64", "--random-state", "9", "--no-progress"]) == 0
        np.testing.assert_array_equal(np.load(tmp_path / "d.npy"), expected)
        if times is not None:  # always spilled: every file read once; never: every file read twice
            assert sorted(reads) == sorted([str(p) for p in paths] * times)
        else:  # the default rule: a sampled mesh is slower to make than to spill, so it is read once
            assert all(reads.count(str(p)) == 1 for p in paths if p.suffix == ".off")
    capsys.readouterr()


def test_a_file_that_changes_between_the_passes_stops_describe_naming_it(tmp_path, capsys, monkeypatch):
    paths = _class_folder(tmp_path / "data")
    monkeypatch.setattr(streaming, "SPILL_BYTES_PER_SECOND", 0.0)  # every file read again
    real = streaming._Stream._read_back

    def change_then_read(self, fd, group):
        write_point_cloud(paths[2], np.random.default_rng(0).normal(size=(11, 3)))
        return real(self, fd, group)

    monkeypatch.setattr(streaming._Stream, "_read_back", change_then_read)
    status = main(["describe", str(tmp_path / "data"), "-o", str(tmp_path / "d.npy"), "--n-pairs", "500",
                   "--no-progress"])
    err = capsys.readouterr().err
    assert status == 2 and str(paths[2]) in err and "changed while eppf describe ran" in err
    assert not (tmp_path / "d.npy").exists()


@pytest.mark.parametrize("layout", ["split", "classes", "loose"])
def test_kept_meta_is_what_plan_objects_gives(tmp_path, layout):
    """describe's own ids, labels, class names and split of the kept files are those of ``plan.objects``."""
    from eppf.cli._common import plan_inputs

    rng = np.random.default_rng(0)
    folders = {"split": ["train/chair", "test/chair", "train/desk", "test/desk", "train/lamp"],
               "classes": ["chair", "desk", "lamp"], "loose": ["."]}[layout]
    for k, sub in enumerate(folders):
        os.makedirs(tmp_path / "d" / sub, exist_ok=True)
        for j in range(3):
            write_point_cloud(str(tmp_path / "d" / sub / f"o{k}_{j}.xyz"), rng.normal(size=(10, 3)))
    plan = plan_inputs([str(tmp_path / "d")], {"random_state": 0})
    kept = [k for k in range(len(plan.entries)) if k % 4 != 1]  # some files skipped
    want = plan.objects(kept, None, [])
    got = describe_module._kept_meta(plan, kept, 0.5, {"a": 1})
    assert (got.labels is None) == (want.labels is None) == (layout == "loose")
    for name in ("ids", "labels", "class_names", "split"):
        a, b = getattr(got, name), getattr(want, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert a.dtype == b.dtype and a.shape == b.shape and (a == b).all(), name
    assert (got.split is None) == (layout != "split") and got.scale == 0.5 and got.params == {"a": 1}
