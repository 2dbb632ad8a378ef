"""Options reach the work they say they control, or are refused: --n-jobs of every command, --on-error and
--test-size where the mode asked for reads no file or has its own split, --out of ``eppf experiment``, and
the partial folders that a killed ``eppf segment`` leaves behind."""

import os

import numpy as np
import pytest

import eppf
import eppf.cli._evaluate as evaluate_module
import eppf.metrics
from eppf.cli import main

from tests.cli._helpers import run as _run

FAST = ["--n-pairs", "400", "--no-progress"]


def _write_npz(path, with_split=True, n_per_class=4):
    """Two classes (blobs, sticks) of ``n_per_class`` clouds, with a train/test split when asked."""
    rng = np.random.default_rng(0)
    pts, offsets, labels = [], [0], []
    for label, stretch in enumerate(([1.0, 1.0, 1.0], [2.0, 0.3, 0.3])):
        for _ in range(n_per_class):
            pts.append(rng.normal(size=(60, 3)) * stretch)
            offsets.append(offsets[-1] + 60)
            labels.append(label)
    arrays = dict(points=np.vstack(pts), offsets=np.array(offsets), labels=np.array(labels),
                  class_names=np.array(["blob", "stick"]))
    if with_split:
        arrays["split"] = np.array((["train"] * (n_per_class // 2) + ["test"] * (n_per_class - n_per_class // 2)) * 2)
    np.savez(path, **arrays)
    return path


@pytest.fixture(scope="module")
def data_and_model(tmp_path_factory):
    root = tmp_path_factory.mktemp("options")
    data = _write_npz(root / "d.npz")
    assert main(["train", "--data", str(data), "-o", str(root / "m.eppf"), "--n-jobs", "1", *FAST]) == 0
    return data, root / "m.eppf"


# ---------------------------------------------------------------------------
# --n-jobs
# ---------------------------------------------------------------------------


def _jobs_of(model):
    """The n_jobs of every eppf estimator inside a model that has one."""
    from eppf.cli._common import _estimators

    return {type(e).__name__: e.get_params(deep=False)["n_jobs"] for e in _estimators(model)
            if type(e).__module__.startswith("eppf.") and "n_jobs" in e.get_params(deep=False)}


def test_evaluate_n_jobs_reaches_the_saved_model(data_and_model, capsys, monkeypatch):
    data, model = data_and_model
    loaded = []

    def load_and_keep(path, trust=False):
        saved = eppf.cli._common.load_model(path, trust=trust)
        loaded.append(saved["model"])
        return saved

    monkeypatch.setattr(evaluate_module, "load_model", load_and_keep)
    status, _, err = _run(["evaluate", "--data", data, "--model", model, "--no-retrieval", "--n-jobs", "2",
                           "--no-progress"], capsys)
    assert status == 0, err
    jobs = _jobs_of(loaded[0])
    assert jobs and set(jobs.values()) == {2}, jobs  # (trained with --n-jobs 1)


def test_run_n_jobs_reaches_the_retrieval_and_the_classifier(tmp_path, capsys, monkeypatch):
    data = _write_npz(tmp_path / "d.npz")
    seen = []
    original = eppf.metrics.leave_one_out_retrieval

    def retrieval(X, y, **kw):
        seen.append(("retrieval", kw.get("n_jobs")))
        return original(X, y, **kw)

    class Recorded(eppf.KLNearestNeighbors):
        def predict(self, X):
            seen.append(("classifier", self.n_jobs))
            return super().predict(X)

    monkeypatch.setattr(eppf.metrics, "leave_one_out_retrieval", retrieval)
    monkeypatch.setattr(eppf, "KLNearestNeighbors", Recorded)
    status, _, err = _run(["run", "--data", data, "--n-jobs", "2", *FAST], capsys)
    assert status == 0, err
    assert sorted(seen) == [("classifier", 2), ("retrieval", 2)]


def test_experiment_n_jobs_zero_is_refused_as_in_every_command(capsys):
    with pytest.raises(SystemExit) as exc:  # (argparse's error: one line, status 2)
        main(["experiment", "retrieval", "--n-jobs", "0"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "--n-jobs: 0 has no meaning" in err, err


# ---------------------------------------------------------------------------
# Options the mode asked for would ignore: refused, naming them
# ---------------------------------------------------------------------------


def _scene(path):
    """A small scene: two boxes of points on a plane."""
    from eppf.io import write_point_cloud

    rng = np.random.default_rng(1)
    ground = np.column_stack([rng.uniform(0, 10, (600, 2)), np.zeros(600)])
    boxes = [rng.uniform(0, 1, (150, 3)) + [2, 2, 0.2], rng.uniform(0, 1, (150, 3)) + [6, 6, 0.2]]
    write_point_cloud(path, np.vstack([ground, *boxes]))
    return path


@pytest.mark.parametrize("value", ["skip", "raise"])
def test_predict_segment_refuses_on_error(tmp_path, data_and_model, capsys, value):
    _, model = data_and_model
    scene = _scene(tmp_path / "scene.xyz")
    status, out, err = _run(["predict", "--model", model, scene, "--segment", "--on-error", value, "--no-progress"],
                            capsys)
    assert status == 2 and out == "", err
    assert err.startswith("eppf predict: error: --on-error: --segment reads one scene file") and "leave it out" in err
    # without it, the scene is classified
    status, out, err = _run(["predict", "--model", model, scene, "--segment", "--no-progress", "--n-jobs", "1"],
                            capsys)
    assert status == 0, err


@pytest.mark.parametrize("value", ["skip", "raise"])
def test_retrieve_query_descriptors_refuses_on_error(tmp_path, capsys, value):
    np.savez(tmp_path / "db.npz", descriptors=np.full((3, 4), 0.25), ids=np.array(["a", "b", "c"]))
    np.save(tmp_path / "q.npy", np.full((1, 4), 0.25))
    argv = ["retrieve", "--database", tmp_path / "db.npz", "--query-descriptors", tmp_path / "q.npy"]
    status, out, err = _run([*argv, "--on-error", value], capsys)
    assert status == 2 and out == "", err
    assert err.startswith("eppf retrieve: error: --on-error: with --query-descriptors no point file is read")
    status, out, err = _run(argv, capsys)
    assert status == 0 and "a" in out, err


@pytest.mark.parametrize("data", ["builtin", "npz"])
def test_experiment_on_error_skip_is_refused_without_a_folder(tmp_path, capsys, data):
    if data == "npz":
        data = str(_write_npz(tmp_path / "d.npz"))
    status, out, err = _run(["experiment", "retrieval", "--data", data, "--on-error", "skip", "--out",
                             tmp_path / "out", "--quick", "--no-progress"], capsys)
    assert status == 2, err
    assert err.startswith(f"eppf experiment: error: --on-error skip: --data {data} ") and "leave it out" in err
    assert not (tmp_path / "out").exists()


def test_run_test_size_is_refused_with_data_that_has_its_own_split(tmp_path, capsys):
    with_split = _write_npz(tmp_path / "split.npz")
    status, out, err = _run(["run", "--data", with_split, "--test-size", "0.5", "--n-jobs", "1", *FAST], capsys)
    assert status == 2, err
    assert err.strip() == (f"eppf run: error: --test-size: {with_split} has its own train/test split, which the "
                           "classification uses; leave it out")
    assert "Total accuracy" not in out
    # the same without a subcommand; and data without a split takes it
    status, _, err = _run(["--data", with_split, "--test-size", "0.5", "--n-jobs", "1", *FAST], capsys)
    assert status == 2 and err.startswith("eppf: error: --test-size:"), err
    no_split = _write_npz(tmp_path / "flat.npz", with_split=False)
    status, out, err = _run(["run", "--data", no_split, "--test-size", "0.5", "--n-jobs", "1", *FAST], capsys)
    assert status == 0 and "Train/test 1-NN (4/4)" in out, err


# ---------------------------------------------------------------------------
# eppf experiment --out
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("option", ["--out", "--cache-dir"])
def test_experiment_output_folder_that_is_a_file_is_one_clear_line(tmp_path, capsys, option):
    taken = tmp_path / "taken.txt"
    taken.write_text("mine\n")
    argv = ["experiment", "retrieval", "--quick", "--no-progress"]
    if option == "--cache-dir":
        argv += ["--out", tmp_path / "out"]
    status, _, err = _run([*argv, option, taken], capsys)
    assert status == 2
    assert err.strip() == f"eppf experiment: error: {option} {taken} is a file; give a new or existing folder"
    status, _, err = _run([*argv, option, taken / "sub"], capsys)  # a folder to be made inside the file
    assert status == 2
    assert err.strip() == (f"eppf experiment: error: {option} {taken / 'sub'}: {taken} is not a folder, so the "
                           "folder cannot be made in it")
    assert taken.read_text() == "mine\n" and sorted(os.listdir(tmp_path)) == ["taken.txt"]
