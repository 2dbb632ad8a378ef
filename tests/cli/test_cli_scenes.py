"""From a scan of a scene to classified objects: ``eppf segment`` and ``eppf predict --segment``.

The scenes are made here: objects of known class and position on a noisy ground plane, so every segment is
checked against the object it must be (its points, its centroid, its class)."""

import os

import numpy as np
import pytest

from eppf.cli import main
from eppf.datasets import make_shapes
from eppf.io import read_point_cloud, read_point_fields, write_point_cloud, write_point_fields

from tests.cli._helpers import read_csv as _csv
from tests.cli._helpers import run as _run

#: Projected coordinates (UTM metres) of the scenes' origin: 1e5-1e7 m, as LiDAR tiles have.
ORIGIN = np.array([512000.0, 5403000.0, 250.0])


def _scene(n_objects=8, spacing=3.0, n_points=1000, seed=1, ground_spacing=0.1, noise=0.01):
    """Upright built-in objects (one per class) in a row of 4 per line, ``spacing`` apart, standing on a noisy
    ground plane; returns (points, fields, object positions (x, y), class names, point -> object (-1 ground))."""
    rng = np.random.default_rng(seed)
    objects = make_shapes(n_samples_per_class=1, n_points=n_points, rotate="z", random_state=seed)
    parts, where, names, owner = [], [], [], []
    for k in range(n_objects):
        cloud = objects.data[k].copy()
        x, y = (k % 4) * spacing, (k // 4) * spacing
        cloud[:, :2] += [x, y] - cloud[:, :2].mean(axis=0)
        cloud[:, 2] -= cloud[:, 2].min()  # standing on the ground
        parts.append(cloud)
        where.append((x, y))
        names.append(str(objects.target_names[objects.target[k]]))
        owner.append(np.full(len(cloud), k))
    lo = np.array([-spacing / 2, -spacing / 2])
    hi = lo + [4 * spacing, ((n_objects + 3) // 4) * spacing]
    n_ground = int(np.prod(hi - lo) / ground_spacing ** 2)
    ground = np.column_stack([rng.uniform(lo, hi, size=(n_ground, 2)), rng.normal(0, noise, n_ground)])
    points = np.vstack(parts + [ground]) + ORIGIN
    fields = {"intensity": rng.integers(0, 4000, len(points)).astype(np.uint16)}
    truth = np.concatenate(owner + [np.full(n_ground, -1)])
    return points, fields, np.asarray(where) + ORIGIN[:2], names, truth


def _match(rows, where):
    """Object index of each segment row: the object whose position is within 0.5 m of its centroid (or -1)."""
    found = []
    for row in rows:
        d = np.hypot(where[:, 0] - float(row["x"]), where[:, 1] - float(row["y"]))
        found.append(int(np.argmin(d)) if d.min() < 0.5 else -1)
    return found


@pytest.fixture(scope="module")
def las_model(tmp_path_factory):
    """A KL 1-NN model trained by ``eppf train`` on a folder of LAS files of the built-in shapes."""
    pytest.importorskip("laspy")
    root = tmp_path_factory.mktemp("las_model")
    shapes = make_shapes(n_samples_per_class=8, n_points=1024, random_state=0)
    for k, (cloud, label) in enumerate(zip(shapes.data, shapes.target)):
        folder = root / "train" / str(shapes.target_names[label])
        folder.mkdir(parents=True, exist_ok=True)
        write_point_cloud(folder / f"{k:03d}.las", cloud)
    status = main(["train", "--data", str(root / "train"), "-o", str(root / "m.eppf"), "--test-size", "0",
                   "--n-pairs", "5000", "--no-progress"])
    assert status == 0
    return root / "m.eppf"


def test_predict_segment_finds_and_classifies_the_objects_of_a_laz_scene(tmp_path, las_model, capsys):
    laspy = pytest.importorskip("laspy")
    if not laspy.LazBackend.detect_available():
        pytest.skip("no LAZ backend (lazrs) installed")
    points, fields, where, names, truth = _scene()
    scene = tmp_path / "tile.laz"
    write_point_fields(scene, points, fields)
    status, out, err = _run(["predict", "--model", las_model, scene, "--segment", "-o", tmp_path / "labels.csv",
                             "--labelled-output", tmp_path / "labelled.laz", "--no-progress"], capsys)
    assert status == 0, err
    rows = _csv(tmp_path / "labels.csv")
    assert list(rows[0])[:6] == ["segment", "n_points", "x", "y", "z", "class"]
    found = _match(rows, where)
    hits = {k for k in found if k >= 0}
    assert len(hits) >= 7, rows
    right = sum(1 for row, k in zip(rows, found) if k >= 0 and row["class"] == names[k])
    assert right >= 6, [(row["class"], names[k] if k >= 0 else None) for row, k in zip(rows, found)]
    # the labelled scene: every point where it was, every field kept, and the rows' segments and classes
    back, back_fields = read_point_fields(tmp_path / "labelled.laz")
    np.testing.assert_array_equal(back, read_point_fields(scene)[0])
    np.testing.assert_array_equal(back_fields["intensity"], fields["intensity"])
    segment, klass = back_fields["segment"], back_fields["class"]
    for row in rows:
        mine = segment == int(row["segment"])
        assert mine.sum() == int(row["n_points"])
        np.testing.assert_allclose(back[mine].mean(axis=0), [float(row[c]) for c in "xyz"], rtol=0, atol=1e-4)
    assert ((segment >= 0) == (klass >= 0)).all()
    classes = out.split("class numbers: ")[1].split(")")[0].split(", ")
    named = dict(c.split(" ") for c in classes)
    for row in rows:
        assert {named[str(c)] for c in np.unique(klass[segment == int(row["segment"])])} == {row["class"]}
    # most ground points are no segment's, and no object is cut away whole
    assert (segment[truth == -1] == -1).mean() > 0.99


def _pcd_scene(tmp_path, **kwargs):
    points, fields, where, names, truth = _scene(n_objects=4, n_points=400, ground_spacing=0.15, **kwargs)
    fields["instance"] = truth.astype(np.int32) + 1  # 0 for the ground
    path = tmp_path / "room.pcd"
    write_point_fields(path, points, fields)
    return path, points, fields, where, truth


def test_segment_writes_one_file_per_object_and_an_index(tmp_path, capsys):
    scene, points, fields, where, truth = _pcd_scene(tmp_path)
    points = read_point_fields(scene)[0]  # as stored (PCD keeps float64 here)
    status, out, err = _run(["segment", scene, "-o", tmp_path / "objects", "--no-progress"], capsys)
    assert status == 0 and err == "", err
    rows = _csv(tmp_path / "objects" / "segments.csv")
    assert list(rows[0]) == ["segment", "file", "n_points", "x", "y", "z"]
    assert sorted(_match(rows, where)) == [0, 1, 2, 3]
    assert sorted(os.listdir(tmp_path / "objects")) == [r["file"] for r in rows] + ["segments.csv"]
    seen = np.zeros(len(points), dtype=bool)
    for row in rows:
        assert row["file"].endswith(".pcd")  # the scene's format
        obj, obj_fields = read_point_fields(tmp_path / "objects" / row["file"])
        assert len(obj) == int(row["n_points"]) and set(obj_fields) == set(fields)
        np.testing.assert_allclose(obj.mean(axis=0), [float(row[c]) for c in "xyz"], rtol=0, atol=1e-4)
        # every point is one of the scene's, with its fields, in the file's coordinates
        index = {tuple(p): i for i, p in enumerate(points)}
        idx = np.array([index[tuple(p)] for p in obj])
        assert not seen[idx].any()
        seen[idx] = True
        np.testing.assert_array_equal(obj_fields["intensity"], fields["intensity"][idx])
        # one object's points (how much of it the ground takes is the segmentation's business, and the
        # target test's: test_predict_segment_finds_and_classifies_the_objects_of_a_laz_scene)
        owner = np.unique(truth[idx])
        assert len(owner) == 1 and owner[0] >= 0
    assert "4 segments" in out and "4 PCD files" in out
    # predict reads the folder without the index
    status, out, err = _run(["describe", tmp_path / "objects", "-o", tmp_path / "d.npz", "--no-progress",
                             "--n-pairs", "500"], capsys)
    assert status == 0 and "segments.csv" not in err and "eppf: 4 eppf descriptors" in out


def test_segment_by_a_field_and_in_another_format(tmp_path, capsys):
    scene, points, fields, where, truth = _pcd_scene(tmp_path)
    status, _, err = _run(["segment", scene, "-o", tmp_path / "by", "--by", "instance", "--format", "ply",
                           "--no-progress"], capsys)
    assert status == 0, err
    rows = _csv(tmp_path / "by" / "segments.csv")
    # one segment per value, the ground's value (0) included, in increasing order of the value
    assert [int(r["instance"]) for r in rows] == [0, 1, 2, 3, 4]
    assert [int(r["n_points"]) for r in rows] == [int((truth == v - 1).sum()) for v in range(5)]
    assert all(r["file"].endswith(".ply") for r in rows)
    obj = read_point_cloud(tmp_path / "by" / rows[1]["file"])
    np.testing.assert_allclose(obj.mean(axis=0), [float(rows[1][c]) for c in "xyz"], rtol=0, atol=1e-4)
    # a text scene keeps its columns in PLY files
    text = tmp_path / "scene.xyz"
    write_point_cloud(text, points[::3])
    status, out, err = _run(["segment", text, "-o", tmp_path / "from_text", "--no-progress"], capsys)
    assert status == 0, err
    assert {f.rsplit(".", 1)[1] for f in os.listdir(tmp_path / "from_text")} == {"ply", "csv"}


def test_tolerance_and_sizes_reach_the_segmentation(tmp_path, capsys):
    scene, *_ = _pcd_scene(tmp_path)
    # with the ground kept, it joins the objects into one; a max size smaller than an object drops them all
    _, out, _ = _run(["segment", scene, "-o", tmp_path / "a", "--tolerance", "0.5", "--ground", "none",
                      "--no-progress"], capsys)
    assert "1 segment of" in out and "0 ground" in out
    _, out, _ = _run(["segment", scene, "-o", tmp_path / "b", "--max-points", "100", "--no-progress"], capsys)
    assert "0 segments of" in out
    _, out, _ = _run(["segment", scene, "-o", tmp_path / "c", "--ground", "plane", "--no-progress"], capsys)
    assert "4 segments of" in out


def test_random_state_reaches_the_ground_plane(tmp_path, capsys, monkeypatch):
    # --random-state seeds RANSAC's ground plane (the help says it seeds everything random; it was ignored)
    from eppf.segmentation import _scene

    scene, *_ = _pcd_scene(tmp_path)
    starts = []
    real = _scene.ground_mask
    monkeypatch.setattr(_scene, "ground_mask", lambda *a: starts.append(a[-1].get_state()[1][0]) or real(*a))
    for k, seed in enumerate(("0", "11")):
        status, _, err = _run(["segment", scene, "-o", tmp_path / f"s{k}", "--random-state", seed, "--no-progress"],
                              capsys)
        assert status == 0, err
    assert starts == [np.random.RandomState(0).get_state()[1][0], np.random.RandomState(11).get_state()[1][0]]


def test_scene_errors_name_the_option_and_come_before_the_work(tmp_path, capsys):
    scene, *_ = _pcd_scene(tmp_path)
    model = tmp_path / "missing.eppf"
    full = tmp_path / "full"
    full.mkdir()
    (full / "old.txt").write_text("x")
    cases = [
        (["segment", scene, "-o", full], "is not empty"),
        (["segment", scene, "-o", tmp_path / "new", "--by", "nope"], "has no field 'nope' (its fields: "),
        (["segment", tmp_path, "-o", tmp_path / "new"], "is a folder"),
        (["predict", "--model", model, scene, "--tolerance", "0.1"], "--tolerance applies to scenes: add --segment"),
        (["predict", "--model", model, scene, scene, "--segment"], "one scene; got 2 inputs"),
        (["predict", "--model", model, scene, "--segment", "--labelled-output", tmp_path / "x.xyz"],
         "--labelled-output must end in .las or .laz or .pcd or .ply"),
    ]
    for argv, text in cases:
        status, _, err = _run([*argv, "--no-progress"], capsys)
        assert status == 2 and text in err, (argv, err)
        assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "new").exists()


def test_predict_segment_table_and_progress(tmp_path, capsys):
    scene, points, fields, where, truth = _pcd_scene(tmp_path)
    data = tmp_path / "train"
    shapes = make_shapes(n_samples_per_class=3, n_points=300, random_state=0)
    for k, (cloud, label) in enumerate(zip(shapes.data, shapes.target)):
        (data / str(shapes.target_names[label])).mkdir(parents=True, exist_ok=True)
        write_point_cloud(data / str(shapes.target_names[label]) / f"{k}.ply", cloud)
    assert main(["train", "--data", str(data), "-o", str(tmp_path / "m.eppf"), "--test-size", "0", "--n-pairs",
                 "800", "--no-progress"]) == 0
    capsys.readouterr()
    status, out, err = _run(["predict", "--model", tmp_path / "m.eppf", scene, "--segment", "--n-jobs", "1"],
                            capsys)
    assert status == 0
    lines = out.splitlines()
    assert [c.strip() for c in lines[0].split(" | ")][:6] == ["segment", "n_points", "x", "y", "z", "class"]
    assert len(lines) == 2 + 4
    assert "segmenting" in err and "4 segments" in err
    status, out, err = _run(["predict", "--model", tmp_path / "m.eppf", scene, "--segment", "--n-jobs", "1",
                             "--no-progress"], capsys)
    assert status == 0 and err == ""


def test_segments_are_resampled_as_the_models_training_files_were(tmp_path, capsys):
    scene, points, fields, where, truth = _pcd_scene(tmp_path)
    data = tmp_path / "train"
    shapes = make_shapes(n_samples_per_class=2, n_points=300, classes=["box", "sphere"], random_state=0)
    for k, (cloud, label) in enumerate(zip(shapes.data, shapes.target)):
        (data / str(shapes.target_names[label])).mkdir(parents=True, exist_ok=True)
        write_point_cloud(data / str(shapes.target_names[label]) / f"{k}.ply", cloud)
    assert main(["train", "--data", str(data), "-o", str(tmp_path / "m.eppf"), "--test-size", "0", "--n-pairs",
                 "800", "--n-points", "150", "--no-progress"]) == 0
    args = ["predict", "--model", tmp_path / "m.eppf", scene, "--segment", "--n-jobs", "1", "--no-progress",
            "-o", tmp_path / "a.csv", "--labelled-output", tmp_path / "labelled.ply"]
    status, out, err = _run(args, capsys)
    assert status == 0, err
    rows = _csv(tmp_path / "a.csv")
    # n_points counts the segment's points in the scan, not the resampled cloud's
    back, back_fields = read_point_fields(tmp_path / "labelled.ply")
    assert [int(r["n_points"]) for r in rows] == [int((back_fields["segment"] == k).sum()) for k in range(4)]
    assert set(back_fields) == {"intensity", "instance", "segment", "class"}
    np.testing.assert_array_equal(back, read_point_fields(scene)[0])
    # resampling is seeded: the same rows on a second run
    assert _run([*args[:-4], "-o", tmp_path / "b.csv"], capsys)[0] == 0
    assert _csv(tmp_path / "b.csv") == rows


def test_a_las_file_without_the_extra_ends_in_one_line_naming_it(tmp_path, capsys, monkeypatch):
    import eppf.io._las as las

    def missing(owner, path, compressed=False):
        raise ImportError(f"{owner}: {str(path)!r} is a LAS file, which needs laspy: pip install 'eppf[las]'")

    pytest.importorskip("laspy")
    scene = tmp_path / "tile.las"
    write_point_fields(scene, _scene(n_objects=1, n_points=100)[0])
    monkeypatch.setattr(las, "laspy_module", missing)
    status, _, err = _run(["segment", scene, "-o", tmp_path / "objects", "--no-progress"], capsys)
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and lines[0].startswith("eppf segment: error: ")
    assert "pip install 'eppf[las]'" in lines[0]


@pytest.mark.parametrize("names", [("normal_x", "normal_y", "normal_z"), ("nx", "ny", "nz"),
                                   ("nor:normalX", "nor:normalY", "nor:normalZ")])
def test_segment_clouds_carry_the_scene_normals_under_every_format_name(names):
    # the normals each reader names as its format does (PCD/LAS, PLY, E57) reach the segments' clouds
    from eppf.cli._segment import Scene

    rng = np.random.default_rng(0)
    points = rng.normal(size=(6, 3))
    normals = rng.normal(size=(6, 3)).astype(np.float32)
    fields = {n: normals[:, k] for k, n in enumerate(names)}
    scene = Scene("scene", points, fields, np.array([0, 0, 1, 1, 1, -1]), np.zeros(6, bool), None,
                  np.array([0, 1, 2, 3, 4]), np.array([0, 2, 5]))
    cloud = scene.cloud(1)
    assert cloud.shape == (3, 6)
    np.testing.assert_array_equal(cloud[:, :3], points[2:5])
    np.testing.assert_array_equal(cloud[:, 3:], normals[2:5].astype(np.float64))
    assert Scene("scene", points, {}, scene.labels, scene.ground, None, scene.order, scene.starts).cloud(1).shape == (3, 3)
