"""Your own files, end to end: every command reads a mixed folder of every
supported format the same way, meshes sampled exactly as load_folder samples
them, one unreadable file skipped (or fatal with --on-error raise)."""

import os
import re
import struct

import numpy as np
import pytest

from eppf import EPPFTransformer
from eppf.cli import build_parser, make_pipeline_from_args
from eppf.datasets import load_folder
from eppf.io import write_mesh, write_point_cloud
from eppf.registry import RECIPE

from tests.cli._helpers import read_csv as _csv
from tests.cli._helpers import run as _run

N_PAIRS = "800"
SMALL = ["--n-bins", "4", "2", "2", "2"]  # a small 4D network: fast epochs
COMMON = ["--n-pairs", N_PAIRS, "--n-jobs", "1", "--no-progress"]


def _box_mesh(rng):
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    v = v * rng.uniform(0.8, 1.2, size=3) * [2.0, 1.0, 0.5]
    f = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return v, np.array(f)


def _ball_mesh(rng, n_lat=8, n_lon=12):
    r = rng.uniform(0.9, 1.1)
    verts = [[0, 0, r], [0, 0, -r]]
    for i in range(1, n_lat):
        t = np.pi * i / n_lat
        for j in range(n_lon):
            p = 2 * np.pi * j / n_lon
            verts.append([r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t)])
    idx = lambda i, j: 2 + (i - 1) * n_lon + j % n_lon  # noqa: E731
    faces = []
    for j in range(n_lon):
        faces.append([0, idx(1, j), idx(1, j + 1)])
        faces.append([1, idx(n_lat - 1, j + 1), idx(n_lat - 1, j)])
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            faces += [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)], [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]]
    return np.array(verts), np.array(faces)


def _box_cloud(rng, n=300):
    pts = rng.uniform(0, 1, size=(n, 3))
    face = rng.integers(0, 6, size=n)
    pts[np.arange(n), face % 3] = face // 3
    return pts * [2.0, 1.0, 0.5]


def _ball_cloud(rng, n=300):
    p = rng.normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def _pcd_compressed(path, cloud):
    """A PCD ``binary_compressed`` file: fields stored one after another, LZF with literal runs only."""
    n = len(cloud)
    raw = np.ascontiguousarray(np.asarray(cloud, dtype="<f4").T).tobytes()
    lzf = b"".join(bytes([len(raw[i:i + 32]) - 1]) + raw[i:i + 32] for i in range(0, len(raw), 32))
    head = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
            f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary_compressed\n")
    with open(path, "wb") as fh:
        fh.write(head.encode() + struct.pack("<II", len(lzf), len(raw)) + lzf)


def _pts(path, cloud, count_line):
    with open(path, "w") as fh:
        if count_line:
            fh.write(f"{len(cloud)}\n")
        np.savetxt(fh, cloud, fmt="%.9g")


def _stl_ascii(path, v, f):
    with open(path, "w") as fh:
        fh.write("solid s\n")
        for tri in f:
            fh.write(" facet normal 0 0 0\n  outer loop\n")
            for k in tri:
                fh.write(f"   vertex {v[k][0]:.9g} {v[k][1]:.9g} {v[k][2]:.9g}\n")
            fh.write("  endloop\n endfacet\n")
        fh.write("endsolid s\n")


def write_mixed_folder(root):
    """Two classes, every format of the brief in each; returns (readable files, unreadable file)."""
    rng = np.random.default_rng(7)
    files = []
    for cls, cloud_of, mesh_of in (("box", _box_cloud, _box_mesh), ("ball", _ball_cloud, _ball_mesh)):
        d = root / cls
        d.mkdir(parents=True)
        write_point_cloud(d / "p_ascii.pcd", cloud_of(rng), binary=False)
        write_point_cloud(d / "p_binary.PCD", cloud_of(rng), binary=True)
        _pcd_compressed(d / "p_compressed.pcd", cloud_of(rng))
        write_point_cloud(d / "cloud.ply", cloud_of(rng))
        write_mesh(d / "mesh.ply", *mesh_of(rng))
        write_mesh(d / "mesh.OFF", *mesh_of(rng))
        write_mesh(d / "mesh.obj", *mesh_of(rng))
        _stl_ascii(d / "ascii.stl", *mesh_of(rng))
        write_mesh(d / "binary.STL", *mesh_of(rng), binary=True)
        _pts(d / "count.pts", cloud_of(rng), True)
        _pts(d / "nocount.pts", cloud_of(rng), False)
        write_point_cloud(d / "plain.XYZ", cloud_of(rng))
        files += sorted(str(p) for p in d.iterdir())
    bad = root / "ball" / "broken.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nend_header\n\x00")
    return sorted(files), str(bad)


@pytest.fixture()
def mixed(tmp_path):
    files, bad = write_mixed_folder(tmp_path / "mixed")
    return tmp_path / "mixed", files, bad


def test_mixed_folder_trains_predicts_describes_and_retrieves(tmp_path, capsys, mixed):
    folder, files, bad = mixed
    model = tmp_path / "m.model"
    status, out, err = _run(["train", "--data", folder, "-o", model, "--test-size", "0", *COMMON], capsys)
    assert status == 0, err
    assert f"on {len(files)} objects" in out and "all 24 objects" in out
    assert "skipped 1 of 25" in err and "broken.ply" in err

    # the in-memory pipeline on load_folder's objects gives the same labels
    with pytest.warns(UserWarning, match="skipped 1 of 25"):
        bunch = load_folder(folder, on_error="skip")
    assert sorted(bunch.filenames) == files
    argv = ["train", "--data", str(folder), "-o", str(model), *COMMON]
    pipe = make_pipeline_from_args(build_parser().parse_args(argv)).fit(bunch.data, bunch.target)
    expected = dict(zip(bunch.filenames, bunch.target_names[pipe.predict(bunch.data)]))

    status, _, err = _run(["predict", folder, "--model", model, "-o", tmp_path / "p.csv", *COMMON[2:]], capsys)
    assert status == 0 and "skipped 1 of 25" in err
    rows = _csv(tmp_path / "p.csv")
    assert [r["file"] for r in rows] == files
    assert {r["file"]: r["class"] for r in rows} == expected
    assert {r["class"] for r in rows} == {"box", "ball"}
    # KL 1-NN evidence: each training file is its own nearest neighbour, at distance 0
    assert [r["neighbour"] for r in rows] == files
    assert all(float(r["distance"]) < 1e-9 for r in rows)

    # describe keeps the class folders' labels; the descriptors are load_folder's objects'
    status, out, _ = _run(["describe", folder, "-o", tmp_path / "d.npz", "--random-state", "3", *COMMON], capsys)
    assert status == 0 and "24 eppf descriptors" in out and "2 classes" in out
    with np.load(tmp_path / "d.npz") as f:
        X, ids, labels, names = f["descriptors"], list(f["ids"]), f["labels"], list(f["class_names"])
    assert ids == files and names == ["ball", "box"]
    assert [names[k] for k in labels] == [os.path.basename(os.path.dirname(i)) for i in ids]
    # --random-state seeds the mesh sampling too, as load_folder's random_state
    with pytest.warns(UserWarning):
        bunch3 = load_folder(folder, on_error="skip", random_state=3)
    assert list(bunch3.filenames) == ids
    ref = EPPFTransformer(n_pairs=800, random_state=3, n_jobs=1).fit_transform(bunch3.data)
    np.testing.assert_array_equal(X, ref)

    # retrieve shows the database's class names, and the queries' when they come from class folders
    status, out, _ = _run(["retrieve", folder, "--database", tmp_path / "d.npz", "-k", "1",
                           "-o", tmp_path / "r.csv", *COMMON[2:]], capsys)
    assert status == 0
    rows = _csv(tmp_path / "r.csv")
    assert len(rows) == 24 and all(r["match"] == r["query"] for r in rows)
    assert all(r["label"] == r["query_label"] == os.path.basename(os.path.dirname(r["query"])) for r in rows)


def test_predict_reuses_the_models_sampling(tmp_path, capsys, mixed):
    folder, files, _ = mixed
    model = tmp_path / "m.model"
    assert _run(["train", "--data", folder, "-o", model, "--test-size", "0", "--n-points", "256",
                 "--random-state", "5", *COMMON], capsys)[0] == 0
    from eppf import load_model

    saved = load_model(model)
    assert saved["sampling"]["n_points"] == 256 and saved["sampling"]["random_state"] == 5
    assert saved["train_ids"] == files
    with pytest.warns(UserWarning):
        bunch = load_folder(folder, n_points=256, random_state=5, on_error="skip")
    argv = ["train", "--data", str(folder), "-o", str(model), "--random-state", "5", *COMMON]
    pipe = make_pipeline_from_args(build_parser().parse_args(argv)).fit(bunch.data, bunch.target)
    status, out, _ = _run(["predict", folder, "--model", model, "-o", tmp_path / "p.csv", *COMMON[2:]], capsys)
    assert status == 0
    rows = _csv(tmp_path / "p.csv")
    expected = dict(zip(bunch.filenames, bunch.target_names[pipe.predict(bunch.data)]))
    assert {r["file"]: r["class"] for r in rows} == expected
    assert all(float(r["distance"]) < 1e-9 for r in rows)  # the very same clouds as in training
    # a mesh named alone (or through a subfolder) is read with its training seed: the model keeps its folder
    from eppf.cli._common import file_seeds, read_inputs
    from eppf.io import read_point_cloud

    mesh = str(folder / "box" / "mesh.OFF")
    k = list(bunch.filenames).index(mesh)
    for item in (mesh, folder / "box"):
        got = read_inputs([item], saved["sampling"], cmd="test")
        np.testing.assert_array_equal(got.clouds[list(got.ids).index(mesh)], bunch.data[k])
    # --resolution instead of --n-points: saved the same way, and the voxel-grid sampling of load's reader
    assert _run(["train", "--data", folder, "-o", model, "--test-size", "0", "--resolution", "0.2", *COMMON],
                capsys)[0] == 0
    res = load_model(model)["sampling"]
    assert res["resolution"] == 0.2 and res["n_points"] is None
    got = read_inputs([mesh], res, cmd="test").clouds[0]
    np.testing.assert_array_equal(got, read_point_cloud(mesh, resolution=0.2,
                                                        random_state=file_seeds(0, str(folder), [mesh])[0]))
    other = dict(saved["sampling"], root=None)  # without the rule: seeded from the file's own folder
    assert not np.array_equal(read_inputs([mesh], other, cmd="test").clouds[0], bunch.data[k])


@pytest.mark.parametrize("command", ["describe", "predict", "train", "evaluate"])
def test_on_error_raise_stops_at_the_unreadable_file(tmp_path, capsys, mixed, command):
    folder, _, bad = mixed
    argv = {"describe": ["describe", folder, "-o", tmp_path / "d.npz"],
            "predict": ["predict", folder, "--model", tmp_path / "m.model"],
            "train": ["train", "--data", folder, "-o", tmp_path / "m2.model"],
            "evaluate": ["evaluate", "--data", folder]}[command]
    if command == "predict":
        assert _run(["train", "--data", folder, "-o", tmp_path / "m.model", *COMMON], capsys)[0] == 0
    status, out, err = _run(argv + ["--on-error", "raise", *(COMMON[2:] if command == "predict" else COMMON)],
                            capsys)
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1, err
    assert lines[0].startswith(f"eppf {command}: error:") and bad in lines[0]
    assert not (tmp_path / "d.npz").exists() and not (tmp_path / "m2.model").exists()


def test_train_holds_out_says_so_and_evaluate_warns_about_seen_objects(tmp_path, capsys, mixed):
    folder, _, _ = mixed
    model = tmp_path / "m.model"
    status, out, _ = _run(["train", "--data", folder, "-o", model, *COMMON], capsys)
    train_out = out
    assert status == 0
    assert "holding out 6 of 24 objects" in out and "held-out score on 6 objects: accuracy" in out
    assert "on 18 objects" in out
    # (no --n-pairs: it sets the retrieval's descriptor, and --no-retrieval refuses it)
    status, out, err = _run(["evaluate", "--data", folder, "--model", model, "--no-retrieval", *COMMON[2:]], capsys)
    assert status == 0 and "model, all objects (24)" in out
    assert "18 of the 24 objects scored were seen in training" in err
    # the held-out objects are scored on their own too, as train scored them
    held = re.search(r"held-out score on 6 objects: accuracy ([0-9.]+)%", train_out).group(1)
    unseen = [line for line in out.splitlines() if "not seen in training (6)" in line and "total_accuracy" in line]
    assert len(unseen) == 1 and float(unseen[0].split("|")[2]) == pytest.approx(float(held), abs=0.01)


def test_cnn_training_prints_one_line_per_epoch_and_predict_gives_probabilities(tmp_path, capsys, mixed):
    folder, files, _ = mixed
    model = tmp_path / "cnn.model"
    status, out, _ = _run(["train", "--data", folder, "-o", model, "--classifier", "4d", "--max-epochs", "2", *SMALL,
                           "--test-size", "0", "--n-pairs", N_PAIRS, "--n-jobs", "1"], capsys)
    assert status == 0
    epochs = [line for line in out.splitlines() if line.startswith("epoch")]
    # the recommended recipe trains RECIPE["n_estimators"] networks, two epochs each, numbered from 1 when several
    n_networks = RECIPE["n_estimators"]
    assert len(epochs) == 2 * n_networks and "train_loss" in epochs[0] and epochs[0].rstrip().endswith(" s")
    assert "valid_acc" in epochs[0]
    numbered = [f"network {k} of {n_networks} of the ensemble" in out for k in range(1, n_networks + 1)]
    assert all(numbered) if n_networks > 1 else "of the ensemble" not in out
    status, _, _ = _run(["predict", folder, "--model", model, "-o", tmp_path / "p.csv", *COMMON[2:]], capsys)
    rows = _csv(tmp_path / "p.csv")
    assert status == 0 and len(rows) == len(files)
    assert all(0.5 <= float(r["probability"]) <= 1 for r in rows)  # the top class of two
    # --no-progress silences the epochs
    status, out, _ = _run(["train", "--data", folder, "-o", model, "--classifier", "4d", "--max-epochs", "1", *SMALL,
                           "--test-size", "0", *COMMON], capsys)
    assert status == 0 and not any(line.startswith("epoch") for line in out.splitlines())


def test_predict_csv_keeps_a_file_name_that_is_not_utf8(tmp_path, capsys):
    # the CSV is UTF-8 on every system, and a name that is not UTF-8 goes back as its own bytes
    rng = np.random.default_rng(0)
    data = tmp_path / "objects"
    for name in ("mug", "box"):
        os.makedirs(data / name)
        for k in range(3):
            write_point_cloud(data / name / f"{k}.xyz", rng.normal(size=(60, 3)) * (1 + len(name)))
    odd = os.path.join(os.fsencode(data / "box"), b"caf\xe9.xyz")
    try:
        with open(odd, "wb") as fh:
            fh.write(open(data / "box" / "0.xyz", "rb").read())
    except (OSError, ValueError):
        pytest.skip("this file system does not store names that are not UTF-8")
    assert _run(["train", "--data", data, "-o", tmp_path / "m.model", "--test-size", "0", "--n-pairs", "500",
                 "--no-progress"], capsys)[0] == 0
    status, _, err = _run(["predict", "--model", tmp_path / "m.model", data, "-o", tmp_path / "p.csv", "--no-progress"],
                          capsys)
    assert status == 0, err  # (it stopped: 'utf-8' codec can't encode ... surrogates not allowed)
    raw = (tmp_path / "p.csv").read_bytes()
    assert odd in raw
    rows = _csv(tmp_path / "p.csv")
    assert len(rows) == 7 and os.fsdecode(odd) in {row["file"] for row in rows}
