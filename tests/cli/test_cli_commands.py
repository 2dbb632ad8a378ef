"""Tests of the ``eppf`` command's main job."""

import io
import os
import subprocess
import sys

import numpy as np
import pytest

from eppf.cli import build_parser, main, run_main_job


def _write_npz(path, n_per_class=6, with_split=True):
    rng = np.random.default_rng(0)
    pts, offsets, labels = [], [0], []
    for label in range(2):
        for _ in range(n_per_class):
            c = rng.normal(size=(80, 3)) * ([1.0, 1.0, 1.0] if label == 0 else [2.0, 0.3, 0.3])
            pts.append(c.astype(np.float32))
            offsets.append(offsets[-1] + len(c))
            labels.append(label)
    arrays = dict(points=np.vstack(pts), offsets=np.array(offsets), labels=np.array(labels),
                  class_names=np.array(["blob", "stick"]))
    if with_split:
        arrays["split"] = np.array((["train"] * 4 + ["test"] * 2) * 2)
    np.savez(path, **arrays)


@pytest.mark.parametrize("with_split", [True, False])
def test_main_job_on_npz_prints_metrics_table(tmp_path, with_split):
    path = tmp_path / "tiny.npz"
    _write_npz(path, with_split=with_split)
    args = build_parser().parse_args(["--data", str(path), "--n-pairs", "2000", "--no-progress", "--repeats", "2"])
    out = io.StringIO()
    report = run_main_job(args, out=out)
    text = out.getvalue()
    assert "12 objects, 2 classes" in text
    for label in ["Total accuracy (%)", "Mean class accuracy (%)", "Macro precision (%)", "Macro F1 (%)"]:
        assert label in text
    assert "ms per object" in text
    assert len(report["retrieval"]) == 2
    # blobs and sticks are easy to tell apart
    assert report["retrieval"][0]["total_accuracy"] >= 0.9


def test_main_bad_input_gives_one_line_error_and_status_2(tmp_path, capsys):
    assert main(["--data", str(tmp_path / "missing.npz"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("eppf: error:") and "missing.npz" in err[0]
    assert "does not exist" in err[0]


def test_main_job_old_n_neighbors_flag_is_normal_neighbors_with_a_warning(tmp_path, capsys):
    _write_npz(tmp_path / "tiny.npz")
    argv = ["--data", str(tmp_path / "tiny.npz"), "--n-pairs", "500", "--n-jobs", "1", "--no-progress"]
    assert main(argv + ["--n-neighbors", "6"]) == 0
    old = capsys.readouterr()
    assert "--n-neighbors is now --normal-neighbors" in old.err
    assert main(argv + ["--normal-neighbors", "6"]) == 0
    new = capsys.readouterr()
    assert new.err == "" and new.out.split("Descriptor:")[0] == old.out.split("Descriptor:")[0]


def test_readme_main_command_runs_on_built_in_data():
    # The README's first command ends in `eppf`; run it the same way, as a process.
    env = dict(os.environ, OMP_NUM_THREADS="2")
    proc = subprocess.run([sys.executable, "-m", "eppf", "--no-progress", "--n-pairs", "5000"],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "built-in synthetic shapes" in proc.stdout
    assert "Total accuracy (%)" in proc.stdout


# ---------------------------------------------------------------------------
# Subcommands
# ---------------------------------------------------------------------------

import csv  # noqa: E402
import re  # noqa: E402

import joblib  # noqa: E402

import eppf  # noqa: E402
from eppf import EPPFTransformer, symmetric_kl_distances  # noqa: E402
from eppf.cli import load_model, make_pipeline_from_args  # noqa: E402
from eppf.datasets import load_npz  # noqa: E402
from eppf.io import read_point_cloud, write_point_cloud  # noqa: E402
from eppf.metrics import leave_one_out_retrieval, retrieval_scores  # noqa: E402

N_PAIRS = "1000"


def _write_files(folder):
    """Three blobs as PLY and three sticks as XYZ (in a subfolder); returns the paths in sorted order."""
    rng = np.random.default_rng(1)
    (folder / "sub").mkdir(parents=True)
    paths = []
    for i in range(3):
        paths.append(folder / f"blob{i}.ply")
        write_point_cloud(paths[-1], rng.normal(size=(90, 3)))
    for i in range(3):
        paths.append(folder / "sub" / f"stick{i}.xyz")
        write_point_cloud(paths[-1], rng.normal(size=(90, 3)) * [2.0, 0.3, 0.3])
    return sorted(paths)


def _run(argv, capsys):
    status = main(list(map(str, argv)))
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def _read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("command", ["run", "describe", "retrieve", "train", "predict", "segment", "evaluate", "bench"])
def test_every_subcommand_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: eppf {command}")
    if command != "run":
        assert "--no-progress" in out


def test_describe_folder_matches_transformer_on_the_same_files(tmp_path, capsys):
    paths = _write_files(tmp_path / "files")
    status, out, _ = _run(["describe", tmp_path / "files", "-o", tmp_path / "d.npz", "--n-pairs", N_PAIRS,
                           "--random-state", "3", "--n-jobs", "1", "--no-progress"], capsys)
    assert status == 0 and "6 eppf descriptors of 1200 bins" in out
    with np.load(tmp_path / "d.npz") as f:
        X, ids, descriptor = f["descriptors"], f["ids"], str(f["descriptor"])
    assert descriptor == "eppf"
    assert list(ids) == [str(p) for p in paths]
    clouds = [read_point_cloud(p, normals=False) for p in paths]
    expected = EPPFTransformer(n_pairs=1000, random_state=3, n_jobs=1).fit_transform(clouds)
    np.testing.assert_array_equal(X, expected)
    # .npy output: the bare matrix, the same numbers
    assert main(["describe", *map(str, paths), "-o", str(tmp_path / "d.npy"), "--n-pairs", N_PAIRS,
                 "--random-state", "3", "--no-progress"]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "d.npy"), expected)
    # one point cloud stored as .npz is read as a cloud, not as a data set
    write_point_cloud(tmp_path / "one.npz", clouds[0])
    assert main(["describe", str(tmp_path / "one.npz"), "-o", str(tmp_path / "one.npy"), "--n-pairs", N_PAIRS,
                 "--random-state", "3", "--no-progress"]) == 0
    one = EPPFTransformer(n_pairs=1000, random_state=3).fit_transform(clouds[:1])
    np.testing.assert_array_equal(np.load(tmp_path / "one.npy"), one)


@pytest.mark.parametrize("descriptor, name", [("esf", "ESFTransformer"), ("wahl", "WahlTransformer"),
                                              ("ourcvfh", "OURCVFHTransformer")])
def test_describe_npz_data_set_with_other_descriptors_keeps_labels(tmp_path, capsys, descriptor, name):
    _write_npz(tmp_path / "tiny.npz")
    status, _, _ = _run(["describe", tmp_path / "tiny.npz", "-o", tmp_path / "d.npz", "--descriptor", descriptor,
                         "--n-pairs", N_PAIRS, "--no-progress"], capsys)
    assert status == 0
    with np.load(tmp_path / "d.npz") as f:
        X, labels, class_names = f["descriptors"], f["labels"], f["class_names"]
    bunch = load_npz(tmp_path / "tiny.npz")
    est = getattr(eppf, name)()
    params = est.get_params()
    est.set_params(**{k: v for k, v in dict(n_pairs=1000, n_triplets=1000, random_state=0).items() if k in params})
    np.testing.assert_allclose(X, est.fit_transform(bunch.data))
    np.testing.assert_array_equal(labels, bunch.target)
    assert list(class_names) == ["blob", "stick"]


def test_retrieve_descriptors_top_k_table_and_csv(tmp_path, capsys):
    _write_npz(tmp_path / "tiny.npz")
    assert _run(["describe", tmp_path / "tiny.npz", "-o", tmp_path / "db.npz", "--n-pairs", N_PAIRS,
                 "--no-progress"], capsys)[0] == 0
    with np.load(tmp_path / "db.npz") as f:
        X = f["descriptors"]
    np.save(tmp_path / "q.npy", X[[0, 11]])
    status, out, _ = _run(["retrieve", "--database", tmp_path / "db.npz", "--query-descriptors", tmp_path / "q.npy",
                           "-k", "3", "--no-progress"], capsys)
    assert status == 0
    lines = out.splitlines()
    assert lines[0].split() == ["query", "|", "query_label", "|", "rank", "|", "match", "|", "label", "|",
                                "distance"]
    assert len(lines) == 2 + 2 * 3
    status, _, _ = _run(["retrieve", "--database", tmp_path / "db.npz", "--query-descriptors", tmp_path / "q.npy",
                         "-k", "3", "-o", tmp_path / "r.csv", "--no-progress"], capsys)
    rows = _read_csv(tmp_path / "r.csv")
    D = symmetric_kl_distances(X[[0, 11]], X)
    for q, query_rows in enumerate([rows[:3], rows[3:]]):
        expected = np.argsort(D[q], kind="stable")[:3]
        assert [int(r["match"]) for r in query_rows] == list(expected)
        assert [int(r["rank"]) for r in query_rows] == [1, 2, 3]
        np.testing.assert_allclose([float(r["distance"]) for r in query_rows], D[q, expected], rtol=1e-5, atol=1e-9)
    # each query finds itself first, and its class
    assert rows[0]["match"] == "0" and rows[3]["match"] == "11"
    assert rows[0]["label"] == "blob" and rows[3]["label"] == "stick"


def test_retrieve_files_against_a_described_folder(tmp_path, capsys):
    paths = _write_files(tmp_path / "files")
    assert main(["describe", str(tmp_path / "files"), "-o", str(tmp_path / "db.npz"), "--n-pairs", "3000",
                 "--no-progress"]) == 0
    status, _, _ = _run(["retrieve", paths[0], paths[-1], "--database", tmp_path / "db.npz", "-k", "2",
                         "-o", tmp_path / "r.csv", "--no-progress"], capsys)
    assert status == 0
    rows = _read_csv(tmp_path / "r.csv")
    assert [r["query"] for r in rows] == [str(paths[0])] * 2 + [str(paths[-1])] * 2
    # described in the database's units, a blob's neighbours are blobs and a stick's are sticks
    assert all("blob" in r["match"] for r in rows[:2])
    assert all("stick" in r["match"] for r in rows[2:])


@pytest.mark.parametrize("classifier", ["knn", "cnn"])
def test_train_save_load_predict_gives_in_memory_predictions(tmp_path, capsys, classifier):
    _write_npz(tmp_path / "tiny.npz")
    paths = _write_files(tmp_path / "files")
    argv = ["train", "--data", str(tmp_path / "tiny.npz"), "-o", str(tmp_path / "m.joblib"), "--n-pairs", N_PAIRS,
            "--classifier", classifier, "--n-jobs", "1", "--random-state", "4", "--no-progress"]
    argv += ["--max-epochs", "1"] if classifier == "cnn" else []  # (the KL 1-NN has no epochs: refused)
    status, out, _ = _run(argv, capsys)
    assert status == 0 and "trained" in out
    saved = eppf.load_model(tmp_path / "m.joblib")
    assert saved["eppf_version"] == eppf.__version__
    assert saved["params"]["n_pairs"] == 1000 and saved["params"]["classifier"] == classifier
    assert saved["classes"] == ["blob", "stick"]

    # the same pipeline fitted in memory on the training split
    bunch = load_npz(tmp_path / "tiny.npz")
    train = bunch.split == "train"
    model = make_pipeline_from_args(build_parser().parse_args(argv))
    model.fit([c for c, t in zip(bunch.data, train) if t], bunch.target[train])
    clouds = [read_point_cloud(p, normals=False) for p in paths]
    expected = model.predict(clouds)
    np.testing.assert_array_equal(saved["model"].predict(clouds), expected)

    status, _, _ = _run(["predict", tmp_path / "files", "--model", tmp_path / "m.joblib", "-o", tmp_path / "p.csv",
                         "--no-progress"], capsys)
    assert status == 0
    rows = _read_csv(tmp_path / "p.csv")
    assert [r["file"] for r in rows] == [str(p) for p in paths]
    assert [r["class"] for r in rows] == [saved["classes"][k] for k in expected]
    if classifier == "knn":  # 1-NN separates blobs from sticks
        assert [r["class"] for r in rows] == ["blob"] * 3 + ["stick"] * 3
    # printed table
    status, out, _ = _run(["predict", paths[0], "--model", tmp_path / "m.joblib", "--no-progress"], capsys)
    assert status == 0 and out.splitlines()[2].split(" | ")[0].strip() == str(paths[0])


def _bad_model(tmp_path, kind, capsys):
    path = tmp_path / "model.joblib"
    if kind == "missing":
        return path
    if kind == "corrupt":
        path.write_bytes(b"\x00\x01garbage" * 10)
    elif kind == "foreign":
        joblib.dump({"weights": [1, 2, 3]}, path)
    elif kind == "truncated":
        _write_npz(tmp_path / "tiny.npz")
        assert main(["train", "--data", str(tmp_path / "tiny.npz"), "-o", str(path), "--n-pairs", N_PAIRS,
                     "--no-progress"]) == 0
        path.write_bytes(path.read_bytes()[:200])
        capsys.readouterr()
    return path


@pytest.mark.parametrize("kind, message", [("missing", "no such model file"), ("corrupt", "cannot load model"),
                                           ("foreign", "is not an eppf model"), ("truncated", "cannot load model")])
def test_predict_with_bad_model_file_gives_one_line_error(tmp_path, capsys, kind, message):
    model = _bad_model(tmp_path, kind, capsys)
    cloud = tmp_path / "c.ply"
    write_point_cloud(cloud, np.random.default_rng(0).normal(size=(50, 3)))
    status, out, err = _run(["predict", cloud, "--model", model, "--no-progress"], capsys)
    assert status == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("eppf predict: error:") and message in lines[0]
    assert "Traceback" not in err
    with pytest.raises((ValueError, FileNotFoundError), match=re.escape(message)):
        load_model(model)


def test_predict_warns_when_saved_by_another_version(tmp_path, capsys):
    _write_npz(tmp_path / "tiny.npz")
    assert main(["train", "--data", str(tmp_path / "tiny.npz"), "-o", str(tmp_path / "m.joblib"), "--n-pairs",
                 N_PAIRS, "--no-progress"]) == 0
    saved = eppf.load_model(tmp_path / "m.joblib")
    saved["eppf_version"] = "0.0.0-old"
    eppf.save_model(saved, tmp_path / "old.joblib")
    cloud = tmp_path / "c.xyz"
    write_point_cloud(cloud, np.random.default_rng(0).normal(size=(60, 3)))
    status, out, err = _run(["predict", cloud, "--model", tmp_path / "old.joblib", "--no-progress"], capsys)
    assert status == 0 and ("blob" in out or "stick" in out)
    assert "warning" in err and "0.0.0-old" in err and eppf.__version__ in err


def test_evaluate_retrieval_and_model_match_direct_computation(tmp_path, capsys):
    _write_npz(tmp_path / "tiny.npz")
    assert main(["train", "--data", str(tmp_path / "tiny.npz"), "-o", str(tmp_path / "m.joblib"), "--n-pairs",
                 N_PAIRS, "--no-progress"]) == 0
    status, out, _ = _run(["evaluate", "--data", tmp_path / "tiny.npz", "--model", tmp_path / "m.joblib",
                           "--n-pairs", N_PAIRS, "--random-state", "2", "-o", tmp_path / "e.csv", "--no-progress"],
                          capsys)
    assert status == 0 and "leave-one-out retrieval (12)" in out and "model, test split (4)" in out
    rows = _read_csv(tmp_path / "e.csv")
    got = {(r["evaluation"].split(" (")[0], r["metric"]): float(r["percent"]) for r in rows}

    bunch = load_npz(tmp_path / "tiny.npz")
    X = EPPFTransformer(n_pairs=1000, random_state=2).fit_transform(bunch.data)
    loo = retrieval_scores(bunch.target, leave_one_out_retrieval(X, bunch.target))
    test = bunch.split == "test"
    model = eppf.load_model(tmp_path / "m.joblib")["model"]
    split_scores = retrieval_scores(bunch.target[test], model.predict([c for c, t in zip(bunch.data, test) if t]))
    for key in ["total_accuracy", "macro_f1"]:
        assert got[("leave-one-out retrieval", key)] == pytest.approx(100 * loo[key], abs=1e-4)
        assert got[("model, test split", key)] == pytest.approx(100 * split_scores[key], abs=1e-4)


def test_bench_prints_one_row_per_setting(capsys):
    status, out, _ = _run(["bench", "--n-pairs", "500", "1000", "--n-per-class", "1", "--n-points", "200",
                           "--repeats", "1", "--n-jobs", "1", "--no-progress"], capsys)
    assert status == 0
    rows = [line.split(" | ") for line in out.splitlines()[3:]]
    assert [(int(r[0]), int(r[1])) for r in rows] == [(500, 1), (1000, 1)]
    assert all(float(r[2]) > 0 for r in rows)


@pytest.mark.parametrize("argv, message", [
    (["describe", "{tmp}/files", "-o", "{tmp}/d.txt"], "--output must end in .npy or .npz"),
    (["describe", "{tmp}/nowhere", "-o", "{tmp}/d.npz"], "no such file or folder"),
    (["describe", "{tmp}/empty", "-o", "{tmp}/d.npz"], "no point cloud or mesh files"),
    (["describe", "{tmp}/bad.xyz", "-o", "{tmp}/d.npz"], "bad.xyz"),
    (["describe", "{tmp}/bad.xyz", "-o", "{tmp}/d.npz", "--on-error", "raise"], "bad.xyz"),
    (["describe", "{tmp}/bad.npz", "-o", "{tmp}/d.npz"], "cannot read"),
    (["retrieve", "--database", "{tmp}/db.npz"], "give query files or --query-descriptors"),
    (["retrieve", "--database", "{tmp}/db.npz", "--query-descriptors", "{tmp}/wrong.npy"], "bins"),
    (["retrieve", "--database", "{tmp}/missing.npz", "--query-descriptors", "{tmp}/wrong.npy"], "no such file"),
    (["retrieve", "--database", "{tmp}/ids.npz", "--query-descriptors", "{tmp}/wrong.npy"], "2 ids for 3"),
    (["train", "--data", "{tmp}/tiny.npz", "-o", "{tmp}/m.joblib", "--test-size", "2"], "--test-size"),
    (["evaluate", "--data", "{tmp}/tiny.npz", "--no-retrieval"], "nothing to evaluate"),
])
def test_bad_input_gives_one_line_error_and_status_2(tmp_path, capsys, argv, message):
    _write_files(tmp_path / "files")
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad.xyz").write_text("1 2 three\n")
    (tmp_path / "bad.npz").write_text("not a zip\n")
    _write_npz(tmp_path / "tiny.npz")
    np.savez(tmp_path / "db.npz", descriptors=np.full((3, 8), 1 / 8))
    np.save(tmp_path / "wrong.npy", np.full((2, 5), 0.2))
    np.savez(tmp_path / "ids.npz", descriptors=np.full((3, 5), 0.2), ids=np.array(["a", "b"]))
    argv = [a.format(tmp=tmp_path) for a in argv] + ["--no-progress"]
    status, _, err = _run(argv, capsys)
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"eppf {argv[0]}: error:") and message in lines[0], err
    assert "Traceback" not in err


def test_train_on_a_folder_of_class_subfolders(tmp_path, capsys):
    """Own files, one subfolder per class: train from the folder, predict new files."""
    rng = np.random.default_rng(5)
    for split, n in (("train", 4), ("test", 2)):
        for name, scale in (("blob", [1.0, 1.0, 1.0]), ("stick", [2.0, 0.3, 0.3])):
            os.makedirs(tmp_path / "objects" / split / name)
            for i in range(n):
                write_point_cloud(tmp_path / "objects" / split / name / f"{i}.ply", rng.normal(size=(90, 3)) * scale)
    status, out, _ = _run(["train", "--data", tmp_path / "objects", "-o", tmp_path / "m.joblib", "--n-pairs",
                           N_PAIRS, "--no-progress"], capsys)
    assert status == 0 and "on 8 objects" in out
    saved = eppf.load_model(tmp_path / "m.joblib")
    assert saved["classes"] == ["blob", "stick"]
    status, _, _ = _run(["predict", tmp_path / "objects" / "test", "--model", tmp_path / "m.joblib",
                         "-o", tmp_path / "p.csv", "--no-progress"], capsys)
    assert status == 0
    rows = _read_csv(tmp_path / "p.csv")
    assert [r["class"] for r in rows] == [os.path.basename(os.path.dirname(r["file"])) for r in rows]


def test_experiment_subcommand_is_the_experiments_command_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["experiment", "no-such-experiment"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "no-such-experiment" in err and len(err.strip().splitlines()) == 1


def test_train_passes_precision_to_the_cnn():
    base = ["train", "--data", "x.npz", "-o", "m.joblib", "--classifier", "cnn"]
    assert make_pipeline_from_args(build_parser().parse_args(base))[-1].precision == "auto"  # recommended
    assert make_pipeline_from_args(build_parser().parse_args(base + ["--precision", "float32"]))[-1].precision \
        == "float32"
    from eppf.registry import RECIPE

    assert make_pipeline_from_args(build_parser().parse_args(base))[-1].n_estimators == RECIPE["n_estimators"]
    base = base + ["--recipe", "paper"]
    assert make_pipeline_from_args(build_parser().parse_args(base))[-1].precision == "float32"
    assert make_pipeline_from_args(build_parser().parse_args(base))[-1].n_estimators == 1  # Table I's one network
    args = build_parser().parse_args(base + ["--precision", "bfloat16"])
    assert make_pipeline_from_args(args)[-1].precision == "bfloat16"
    args = build_parser().parse_args(base + ["--precision", "auto"])
    assert make_pipeline_from_args(args)[-1].precision == "auto"
    with pytest.raises(SystemExit):
        build_parser().parse_args(base + ["--precision", "half"])
