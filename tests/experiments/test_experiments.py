"""Tests of eppf.experiments: every experiment end to end on a tiny built-in set."""

import csv
import os
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose

from eppf import EPPFTransformer, KLNearestNeighbors
from eppf.experiments import (
    ExperimentError,
    load_data,
    run_ablation,
    run_classification,
    run_noise,
    run_retrieval,
    run_runtime,
)
from eppf.experiments._common import draw_seeds
from eppf.metrics import leave_one_out_retrieval, retrieval_scores

from . import experiment_main as main

try:
    import matplotlib  # noqa: F401

    HAVE_MPL = True
except ImportError:  # pragma: no cover
    HAVE_MPL = False


@pytest.fixture(scope="module")
def tiny():
    # 3 objects of 96 points per class, 10 classes: 20 train / 10 test
    return load_data("builtin", n_per_class=3, n_points=96, random_state=0)


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def check_outputs(paths, name):
    assert os.path.basename(paths["md"]) == f"{name}.md"
    with open(paths["md"]) as f:
        md = f.read()
    for heading in ("Made by:", "## Data", "## Protocol", "## Results", "## Machine", "|---|"):
        assert heading in md
    if HAVE_MPL:
        with open(paths["png"], "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    return md, read_csv(paths["csv"])


def eppf_quick(seed, **kw):
    # the EPPF settings of quick=True on the built-in set (scaling "fit")
    return EPPFTransformer(n_pairs=5000, scaling="fit", random_state=seed, n_jobs=1, **kw)


def test_retrieval_matches_direct_computation(tiny, tmp_path):
    res = run_retrieval(tiny, out=str(tmp_path), descriptors=("ourcvfh", "eppf"), draws=2, n_jobs=1, quick=True,
                        verbose=False)
    md, rows = check_outputs(res["paths"], "retrieval")
    assert [r["descriptor"] for r in rows] == ["OUR-CVFH", "EPPF"]
    assert [int(r["draws"]) for r in rows] == [1, 2]
    for key in ("total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1"):
        assert {f"{key}_mean", f"{key}_std"} <= set(rows[0])
    # independent route: transformer + leave-one-out by hand, same seeds
    acc = []
    for seed in draw_seeds(0, 2):
        X = eppf_quick(seed).fit_transform(tiny.clouds)
        acc.append(retrieval_scores(tiny.y, leave_one_out_retrieval(X, tiny.y))["total_accuracy"])
    assert_allclose(float(rows[1]["total_accuracy_mean"]), np.mean(acc), atol=1e-6)
    assert_allclose(float(rows[1]["total_accuracy_std"]), np.std(acc), atol=1e-6)
    assert "| EPPF | 2 |" in md


def test_cache_is_reused(tiny, tmp_path, monkeypatch):
    kw = dict(descriptors=("eppf",), draws=2, n_jobs=1, quick=True, verbose=False, cache_dir=str(tmp_path / "c"))
    first = run_retrieval(tiny, **kw)
    assert (first["cache"].n_computed, first["cache"].n_loaded) == (2, 0)

    def boom(self, X):
        raise AssertionError("the transformer ran although its descriptors were cached")

    monkeypatch.setattr(EPPFTransformer, "transform", boom)
    second = run_retrieval(tiny, **kw)
    assert (second["cache"].n_computed, second["cache"].n_loaded) == (0, 2)
    assert second["rows"] == first["rows"]


def test_cache_log_line_on_rerun(tmp_path, capsys):
    argv = ["retrieval", "--quick", "--descriptors", "eppf", "--draws", "1", "--n-jobs", "1", "--out", str(tmp_path)]
    assert main(argv) == 0
    assert "computed" in capsys.readouterr().out
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "descriptors from cache" in out and "computed 60" not in out


def test_ablation(tiny, tmp_path):
    cache = str(tmp_path / "c")
    run_retrieval(tiny, descriptors=("eppf",), draws=1, n_jobs=1, quick=True, verbose=False, cache_dir=cache)
    res = run_ablation(tiny, out=str(tmp_path), draws=1, n_jobs=1, quick=True, verbose=False, cache_dir=cache)
    md, rows = check_outputs(res["paths"], "ablation")
    assert [r["configuration"] for r in rows] == [
        "all four", "without distance", "without angle", "without normal", "without occupancy"]
    assert [int(r["n_bins"]) for r in rows] == [1200, 60, 300, 240, 400]
    # "all four" is the retrieval's EPPF draw, read from the cache
    assert res["cache"].n_loaded == 1 and res["cache"].n_computed == 4
    assert float(rows[0]["f1_drop"]) == 0.0
    seed = draw_seeds(0, 1)[0]
    X = eppf_quick(seed, functions=("angle", "normal", "occupancy")).fit_transform(tiny.clouds)
    f1 = retrieval_scores(tiny.y, leave_one_out_retrieval(X, tiny.y))["macro_f1"]
    assert_allclose(float(rows[1]["macro_f1_mean"]), f1, atol=1e-6)
    assert_allclose(float(rows[1]["f1_drop"]), float(rows[0]["macro_f1_mean"]) - f1, atol=1e-5)
    assert "occupancy: " in md and "Mean share of the" in md


def test_module_entry_point_names_the_command_that_replaced_it():
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "eppf.experiments", "nope"], capture_output=True, text=True, env=env,
                          cwd=root, timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "now 'eppf experiment'" in proc.stderr and proc.stderr.strip().endswith("eppf experiment nope")


def test_classification(tiny, tmp_path):
    res = run_classification(tiny, out=str(tmp_path), models=["kl", "2d", "pointnet"], epochs=1, pointnet_points=32,
                             n_jobs=1, quick=True, verbose=False)
    md, rows = check_outputs(res["paths"], "classification")
    assert [r["model"] for r in rows] == ["EPPF KL 1-NN", "EPPF 2D", "PointNet"]
    assert all(int(r["n_test"]) == tiny.test.size and int(r["n_train"]) == tiny.train.size for r in rows)
    assert int(rows[1]["epochs"]) == 1 and int(rows[2]["epochs"]) == 1
    assert "validation hold-out" in md
    # the KL row by hand: descriptors fitted on the training split, 1-NN by KL
    est = eppf_quick(draw_seeds(0, 1)[0])
    Xtr = est.fit_transform([tiny.clouds[i] for i in tiny.train])
    Xte = est.transform([tiny.clouds[i] for i in tiny.test])
    pred = KLNearestNeighbors(n_neighbors=1).fit(Xtr, tiny.y[tiny.train]).predict(Xte)
    expected = retrieval_scores(tiny.y[tiny.test], pred)
    assert_allclose(float(rows[0]["total_accuracy"]), expected["total_accuracy"], atol=1e-6)
    assert_allclose(float(rows[0]["macro_f1"]), expected["macro_f1"], atol=1e-6)


def test_classification_subsamples_per_class(tiny):
    res = run_classification(tiny, models=["kl"], train_per_class=1, test_per_class=1, n_jobs=1, quick=True,
                             verbose=False)
    assert res["rows"][0]["n_train"] == 10 and res["rows"][0]["n_test"] == 10


def test_noise(tiny, tmp_path):
    res = run_noise(tiny, out=str(tmp_path), levels=[0.06, 0.0], models=["kl", "4d"], epochs=1, n_jobs=1, quick=True,
                    verbose=False)
    md, rows = check_outputs(res["paths"], "noise")
    assert [(float(r["sigma"]), r["model"]) for r in rows] == [
        (0.0, "EPPF KL 1-NN"), (0.0, "EPPF 4D"), (0.06, "EPPF KL 1-NN"), (0.06, "EPPF 4D")]
    # new descriptors at each level (noisy clouds), and the drop is level 0 minus level 0.06
    assert res["cache"].n_computed == 2
    acc = {(float(r["sigma"]), r["model"]): float(r["total_accuracy"]) for r in rows}
    assert_allclose(res["drops"]["EPPF KL 1-NN"], acc[0.0, "EPPF KL 1-NN"] - acc[0.06, "EPPF KL 1-NN"])
    assert "σ=0.06" in md and "drop" in md
    # level 0 is the classification experiment's KL row
    clean = run_classification(tiny, models=["kl"], n_jobs=1, quick=True, verbose=False)
    assert_allclose(acc[0.0, "EPPF KL 1-NN"], clean["rows"][0]["total_accuracy"], atol=1e-6)


def test_runtime(tiny, tmp_path):
    res = run_runtime(tiny, out=str(tmp_path), n_objects=4, repeats=1, n_jobs=1, quick=True, verbose=False)
    md, rows = check_outputs(res["paths"], "runtime")
    from eppf.registry import DESCRIPTORS

    # one row per registered descriptor: a new descriptor needs no code here
    assert [r["item"] for r in rows] == ["normals (PCA, 20 neighbours)"] + [s.title for s in DESCRIPTORS.values()]
    assert all(int(r["threads"]) == 1 and int(r["n_objects"]) == 4 for r in rows)
    assert all(float(r["wall_ms"]) > 0 and float(r["cpu_ms"]) >= 0 for r in rows)
    assert "CPU:" in md


def test_without_matplotlib(tiny, tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    res = run_retrieval(tiny, out=str(tmp_path), descriptors=("eppf",), draws=1, n_jobs=1, quick=True)
    assert "png" not in res["paths"] and not (tmp_path / "retrieval.png").exists()
    assert os.path.exists(res["paths"]["md"]) and os.path.exists(res["paths"]["csv"])
    assert "matplotlib is not installed" in capsys.readouterr().out


def write_npz(path, tiny, with_split=True):
    points = np.concatenate(tiny.clouds).astype(np.float32)
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in tiny.clouds])]).astype(np.int64)
    arrays = dict(points=points, offsets=offsets, labels=tiny.y.astype(np.int64), class_names=tiny.target_names,
                  ids=np.array([f"obj{k}" for k in range(len(tiny.clouds))]))
    if with_split:
        arrays["split"] = tiny.split
    np.savez(path, **arrays)


def test_npz_data(tiny, tmp_path, capsys):
    path = tmp_path / "tiny_set.npz"
    write_npz(path, tiny)
    out = tmp_path / "out"
    argv = ["retrieval", "--data", str(path), "--descriptors", "eppf_short", "--draws", "1", "--quick", "--n-jobs", "1",
            "--quiet", "--out", str(out)]
    assert main(argv) == 0
    with open(out / "retrieval.md") as f:
        md = f.read()
    assert str(path) not in md and "- data: `tiny_set.npz`" in md and "EPPF scaling: object" in md and "the file's split" in md
    rows = read_csv(out / "retrieval.csv")
    assert [r["descriptor"] for r in rows] == ["EPPF short"]
    data = load_data(path)
    assert len(data.clouds) == 30 and data.clouds[0].shape == (96, 3)
    np.testing.assert_array_equal(data.split, tiny.split)


def test_npz_without_split_gets_stratified_split(tiny, tmp_path):
    path = tmp_path / "nosplit.npz"
    write_npz(path, tiny, with_split=False)
    data = load_data(path, random_state=3)
    assert data.test.size == 10 and data.train.size == 20
    assert all(np.sum(data.y[data.test] == c) == 1 for c in range(10))
    assert set(data.y[data.test]) <= set(data.y[data.train])
    np.testing.assert_array_equal(load_data(path, random_state=3).split, data.split)


def test_cli_quick_ablation(tmp_path):
    assert main(["ablation", "--quick", "--draws", "1", "--n-jobs", "1", "--quiet", "--out", str(tmp_path)]) == 0
    assert len(read_csv(tmp_path / "ablation.csv")) == 5


@pytest.mark.parametrize(
    "argv, msg",
    [
        (["nope"], "invalid choice: 'nope'"),
        ([], "required: NAME"),
        (["retrieval", "--data", "/no/such/file.npz"], "no such file or folder: '/no/such/file.npz'"),
        (["noise", "--levels", "-0.1"], "--levels must lie in [0, 1]"),
        (["noise", "--levels", "0,abc"], "noise levels must be numbers"),
        (["noise", "--levels", "0,0"], "--levels has duplicates"),
        (["noise", "--levels", ","], "--levels must name at least one noise level"),
        (["retrieval", "--draws", "0"], "--draws must be a positive int, got 0"),
        (["classification", "--epochs", "-1"], "--epochs must be a positive int, got -1"),
        (["classification", "--validation-fraction", "1.5"], "--validation-fraction must lie in (0, 1)"),
        (["retrieval", "--descriptors", "fpfh"], "invalid choice: 'fpfh'"),
        (["runtime", "--n-jobs", "0"], "argument --n-jobs: 0 has no meaning; use a positive count or -1"),
    ],
)
def test_cli_errors(argv, msg, tmp_path, capsys):
    assert main(argv + (["--out", str(tmp_path)] if len(argv) > 1 else [])) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert msg in err
    assert len(err.splitlines()) == 1
    assert not os.path.exists(tmp_path / "retrieval.md")


def test_folder_data_is_read_with_its_split(tmp_path):
    rng = np.random.default_rng(0)
    for split, n in (("train", 4), ("test", 2)):
        for name, scale in (("ball", 1.0), ("rod", (5.0, 0.2, 0.2))):
            folder = tmp_path / "objs" / split / name
            folder.mkdir(parents=True)
            for k in range(n):
                np.savetxt(folder / f"{k}.xyz", rng.normal(size=(60, 3)) * scale)
    data = load_data(tmp_path / "objs")
    assert data.name == "objs" and data.default_scaling == "object"
    assert list(data.target_names) == ["ball", "rod"]
    assert data.train.size == 8 and data.test.size == 4
    assert "folder's split" in data.split_source
    assert all(c.shape == (60, 3) and c.dtype == np.float64 for c in data.clouds)
    # runs end to end on it
    table = run_retrieval(tmp_path / "objs", out=tmp_path / "out", descriptors=["eppf"], draws=1, quick=True,
                          verbose=False)
    assert os.path.exists(tmp_path / "out" / "retrieval.md")
    assert table is not None


def test_empty_or_missing_folder_is_one_line_error(tmp_path, capsys):
    with pytest.raises(ExperimentError, match="no class folders|no object files"):
        load_data(tmp_path)
    assert main(["retrieval", "--data", str(tmp_path / "nope"), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "no such file or folder" in err and len(err.splitlines()) == 1


def test_bad_npz_is_one_line_error(tmp_path, capsys):
    path = tmp_path / "bad.npz"
    np.savez(path, points=np.zeros((3, 3)))
    assert main(["retrieval", "--data", str(path), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "lacks the arrays" in err and len(err.splitlines()) == 1


def test_precision_reaches_the_eppf_networks_and_the_report(tmp_path, capsys):
    from eppf.experiments._classification import TrainingSettings
    from eppf.cli import build_parser

    common = dict(epochs=None, pointnet_epochs=None, pointnet_points=None, validation_fraction=0.1, patience=None,
                  scaling="fit", quick=True, n_jobs=1, random_state=0)
    assert TrainingSettings.resolve(**common).make_model("4d").precision == "float32"
    assert TrainingSettings.resolve(**common, precision="bfloat16").make_model("2d").precision == "bfloat16"
    with pytest.raises(ExperimentError, match="--precision must be 'float32', 'bfloat16' or 'auto', got 'half'"):
        TrainingSettings.resolve(**common, precision="half")
    auto = TrainingSettings.resolve(**common, precision="auto")
    assert auto.make_model("4d").precision == "auto"
    from eppf.nn import resolve_precision

    # the report says what "auto" chose on the machine that ran it
    assert auto.protocol(["4d"])["precision 'auto'"].startswith(f"{resolve_precision('auto')} on this machine")
    assert "precision 'auto'" not in TrainingSettings.resolve(**common).protocol(["4d"])
    assert "precision 'auto'" in TrainingSettings.resolve(**common).protocol(["4d+"])  # the recipe's "auto"
    args = build_parser().parse_args(["experiment", "noise", "--precision", "bfloat16"])
    assert args.precision == "bfloat16"
    result = run_classification("builtin", quick=True, models=["4d"], n_jobs=1, out=str(tmp_path), verbose=False,
                                precision="bfloat16")
    assert capsys.readouterr().out == ""  # verbose=False: silent, the networks' epochs included
    assert result["rows"][0]["model"] == "EPPF 4D"
    assert "precision='bfloat16'" in (tmp_path / "classification.md").read_text()


def test_retrieval_runs_every_registered_descriptor(tiny, tmp_path):
    # the experiment reads the registry: a new descriptor gets its column with no code here
    from eppf.registry import DESCRIPTORS

    res = run_retrieval(tiny, out=str(tmp_path), draws=1, n_jobs=1, quick=True, verbose=False)
    md, rows = check_outputs(res["paths"], "retrieval")
    assert [r["descriptor"] for r in rows] == [spec.title for spec in DESCRIPTORS.values()]
    for r in rows:
        assert 0.0 <= float(r["total_accuracy_mean"]) <= 1.0
        assert f"| {r['descriptor']} |" in md


def test_shared_settings_reject_unknown_keywords_and_split_training_options():
    from eppf.experiments import ExperimentSettings, TrainingOptions

    with pytest.raises(TypeError, match=re.escape("run_retrieval() got unexpected keyword argument(s) ['quik']")):
        run_retrieval("builtin", quik=True)
    with pytest.raises(TypeError, match=re.escape("run_noise() got unexpected keyword argument(s) ['epoch']")):
        run_noise("builtin", epoch=2)
    s = ExperimentSettings.from_kwargs("f", {"quick": True, "n_jobs": 1})
    assert s.astuple() == ("auto", 0, 1, True, None, True, None)
    options, rest = TrainingOptions.split("f", {"epochs": 3, "patience": 1, "quick": True})
    assert (options.epochs, options.patience, options.validation_fraction) == (3, 1, 0.1) and rest == {"quick": True}
