"""``eppf describe``: every registered descriptor on the built-in shapes, and files and folders streamed
chunk by chunk into the rows of one ``fit_transform``."""

import json
import os

import numpy as np
import pytest

import eppf.cli._describe as describe_module
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
        monkeypatch.setattr(describe_module, "CHUNK_FILES", chunk)
        monkeypatch.setattr(describe_module, "FIRST_CHUNK_FILES", first)
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
    monkeypatch.setattr(describe_module, "CHUNK_FILES", 2)
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
    monkeypatch.setattr(describe_module, "CHUNK_FILES", 2)
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
    monkeypatch.setattr(describe_module, "CHUNK_FILES", 2)
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
    monkeypatch.setattr(describe_module, "CHUNK_FILES", 3)
    for rate, times in ((float("inf"), 1), (0.0, 2), (describe_module.SPILL_BYTES_PER_SECOND, None)):
        reads.clear()
        monkeypatch.setattr(describe_module, "SPILL_BYTES_PER_SECOND", rate)
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
    monkeypatch.setattr(describe_module, "SPILL_BYTES_PER_SECOND", 0.0)  # every file read again
    real = describe_module._read_back

    def change_then_read(plan, fd, group):
        write_point_cloud(paths[2], np.random.default_rng(0).normal(size=(11, 3)))
        return real(plan, fd, group)

    monkeypatch.setattr(describe_module, "_read_back", change_then_read)
    status = main(["describe", str(tmp_path / "data"), "-o", str(tmp_path / "d.npy"), "--n-pairs", "500",
                   "--no-progress"])
    err = capsys.readouterr().err
    assert status == 2 and str(paths[2]) in err and "changed while eppf describe ran" in err
    assert not (tmp_path / "d.npy").exists()


# ---------------------------------------------------------------------------
# Chunks described side by side (--n-jobs above 1)
# ---------------------------------------------------------------------------


class _SeedRows:
    """A toy descriptor: one row per cloud, (its seed, its sum, the n_jobs and thread that described it).

    ``per_cloud`` seeds are drawn per cloud (1 as every eppf descriptor
    does); ``odd_after`` > 0 draws one more seed in every transform after
    that many calls (a descriptor whose draws the first chunk cannot predict).
    """

    def __init__(self, random_state=None, n_jobs=None, per_cloud=1, odd_after=0):
        self.random_state, self.n_jobs, self.per_cloud, self.odd_after = random_state, n_jobs, per_cloud, odd_after
        self.calls = [0]

    def get_params(self, deep=True):
        return dict(random_state=self.random_state, n_jobs=self.n_jobs, per_cloud=self.per_cloud,
                    odd_after=self.odd_after)

    def set_params(self, **params):
        for k, v in params.items():
            setattr(self, k, v)
        return self

    def transform(self, clouds):
        import threading

        from eppf.utils import object_seeds

        self.calls[0] += 1
        n = len(clouds) * self.per_cloud + (self.odd_after > 0 and self.calls[0] > self.odd_after)
        seeds = object_seeds(self.random_state, n)[::self.per_cloud][:len(clouds)]
        return np.column_stack([seeds.astype(np.float64), [c.sum() for c in clouds],
                                np.full(len(clouds), -1 if self.n_jobs is None else self.n_jobs),
                                np.full(len(clouds), threading.get_ident(), dtype=np.float64)])


def _stream_rows(est, chunks, n_threads):
    out = []
    rows = describe_module._ParallelRows(est, n_threads)
    try:
        for k, chunk in enumerate(chunks):
            rows.submit(chunk, [f"f{k}_{i}" for i in range(len(chunk))], out.append)
        rows.finish(out.append)
    finally:
        rows.close()
    return np.vstack(out), rows


@pytest.mark.parametrize("per_cloud", [1, 2])
def test_chunks_side_by_side_give_the_rows_of_one_generator(per_cloud):
    import threading

    rng = np.random.default_rng(3)
    clouds = [rng.normal(size=(int(rng.integers(5, 40)), 3)) for _ in range(40)]
    sizes = [7, 1, 5, 9, 3, 2, 8, 5]
    chunks = np.split(np.arange(40), np.cumsum(sizes)[:-1])
    chunks = [[clouds[i] for i in c] for c in chunks]
    expected = _SeedRows(np.random.RandomState(4), 2, per_cloud).transform(clouds)
    for n_threads in (1, 2, 3):
        got, rows = _stream_rows(_SeedRows(np.random.RandomState(4), n_threads, per_cloud), chunks, n_threads)
        np.testing.assert_array_equal(got[:, :2], expected[:, :2])  # seeds and clouds, in order
        side_by_side = n_threads > 1 and per_cloud == 1
        assert rows.parallel == side_by_side
        # the first chunk on the calling thread with the descriptor's n_jobs; then copies on one thread each
        assert (got[:7, 2] == n_threads).all() and (got[:7, 3] == threading.get_ident()).all()
        if side_by_side:
            assert (got[7:, 2] == 1).all() and (got[7:, 3] != threading.get_ident()).all()
        else:
            assert (got[:, 2] == n_threads).all() and (got[:, 3] == threading.get_ident()).all()


def test_chunks_side_by_side_stop_on_draws_the_first_chunk_did_not_show():
    clouds = [np.full((4, 3), float(k)) for k in range(12)]
    chunks = [clouds[:4], clouds[4:8], clouds[8:]]
    with pytest.raises(RuntimeError, match="drew seeds other than one per cloud"):
        _stream_rows(_SeedRows(np.random.RandomState(0), 2, odd_after=1), chunks, 2)


def test_chunks_side_by_side_name_the_file_of_a_refused_cloud():
    class Refuses(_SeedRows):
        def transform(self, clouds):
            if len(clouds) == 3:
                raise ValueError("Refuses: point cloud 2 is bad")
            return super().transform(clouds)

    chunks = [[np.ones((4, 3))] * 2, [np.ones((4, 3))] * 2, [np.ones((4, 3))] * 3, [np.ones((4, 3))] * 2]
    with pytest.raises(ValueError, match="point cloud f2_2 is bad"):
        _stream_rows(Refuses(np.random.RandomState(0), 2), chunks, 2)


def test_a_nested_generator_is_described_one_chunk_at_a_time():
    est = DESCRIPTORS["eppf+gasd"].make(n_samples=500, random_state=0, n_jobs=2)
    assert not describe_module._ParallelRows(est, 2).parallel
    est = DESCRIPTORS["eppf"].make(n_samples=500, random_state=0, n_jobs=2).set_params(
        random_state=np.random.RandomState(0))
    assert describe_module._ParallelRows(est, 2).parallel
    assert not describe_module._ParallelRows(est, 1).parallel


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
