"""Options reach the work they say they control, or are refused: --n-jobs of every command, --on-error and
--test-size where the mode asked for reads no file or has its own split, --out of ``eppf experiment``, and
the partial folders that a killed ``eppf segment`` leaves behind."""

import os
import shutil

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


def test_train_test_size_is_refused_with_data_that_has_its_own_split(tmp_path, capsys):
    # as eppf run: the data's own split is the one trained and scored on, so the option would do nothing
    with_split = _write_npz(tmp_path / "split.npz")
    model = tmp_path / "m.joblib"
    status, out, err = _run(["train", "--data", with_split, "--classifier", "kl", "--test-size", "0.5",
                             "--n-pairs", "400", "-o", model, "--no-progress"], capsys)
    assert status == 2, err
    assert err.strip() == (f"eppf train: error: --test-size: {with_split} has its own train/test split, which "
                           "training uses; leave it out")
    assert not model.exists()


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


# ---------------------------------------------------------------------------
# eppf segment after a run that was killed outright
# ---------------------------------------------------------------------------

#: A process id that no process has (above the largest that Linux or macOS gives).
GONE = 2 ** 22 + 1

posix_only = pytest.mark.skipif(os.name != "posix", reason="stale partial folders are told by a POSIX process check")


def _left_partial(parent, prefix=".eppf-partial-", pid=GONE, age=3600, host=None):
    """A partial folder as a killed ``eppf segment`` leaves it: a segment file in it, untouched for ``age``
    seconds."""
    from eppf.cli._segment import _host

    path = parent / f"{prefix}{host or _host()}-{pid}-0123abcd"
    path.mkdir()
    (path / "segment_000.ply").write_bytes(b"ply\n")
    old = os.path.getmtime(path) - age
    os.utime(path, (old, old))
    return path


@posix_only
def test_segment_removes_the_stale_partial_folder_of_a_killed_run(tmp_path, capsys):
    scene = _scene(tmp_path / "scene.xyz")
    out = tmp_path / "objects"
    out.mkdir()
    stale = _left_partial(out)
    status, _, err = _run(["segment", scene, "-o", out, "--no-progress"], capsys)
    assert status == 0, err
    assert not stale.exists()
    assert "segments.csv" in os.listdir(out) and not [n for n in os.listdir(out) if n.startswith(".")]
    # beside a new folder: removed too, and only that folder's
    beside = _left_partial(tmp_path, prefix=".new.eppf-partial-")
    other = _left_partial(tmp_path, prefix=".other.eppf-partial-")
    status, _, err = _run(["segment", scene, "-o", tmp_path / "new", "--no-progress"], capsys)
    assert status == 0, err
    assert not beside.exists() and other.exists() and (tmp_path / "new" / "segments.csv").exists()


@posix_only
@pytest.mark.parametrize("case", ["running", "recent", "other machine", "earlier eppf"])
def test_segment_names_a_partial_folder_that_may_be_in_use(tmp_path, capsys, case):
    scene = _scene(tmp_path / "scene.xyz")
    out = tmp_path / "objects"
    out.mkdir()
    if case == "earlier eppf":  # (its name says no process)
        left = out / ".eppf-partial-0123abcd"
        left.mkdir()
        (left / "segment_000.ply").write_bytes(b"ply\n")
    else:
        left = _left_partial(out, pid=os.getppid() if case == "running" else GONE,
                             age=0 if case == "recent" else 3600, host="ffffffff" if case == "other machine" else None)
    status, _, err = _run(["segment", scene, "-o", out, "--no-progress"], capsys)
    assert status == 2
    assert err.strip() == (f"eppf segment: error: --output {out} is not empty: it holds {left.name}, the partial "
                           "folder of an eppf segment run that was stopped or is still running; if no eppf segment "
                           "is writing into the folder, delete it and run again")
    assert os.listdir(out) == [left.name] and os.listdir(left)  # left as it was
    shutil.rmtree(left)  # as the message says
    status, _, err = _run(["segment", scene, "-o", out, "--no-progress"], capsys)
    assert status == 0, err


@posix_only
def test_segment_leaves_partial_folders_alone_in_a_folder_with_other_files(tmp_path, capsys):
    out = tmp_path / "objects"
    out.mkdir()
    stale = _left_partial(out)
    (out / "mine.txt").write_text("x")
    status, _, err = _run(["segment", _scene(tmp_path / "scene.xyz"), "-o", out, "--no-progress"], capsys)
    assert status == 2 and f"--output {out} is not empty; give a new or empty folder" in err
    assert stale.exists()


def test_the_partial_folder_name_says_which_process_writes_it(tmp_path):
    from eppf.cli._segment import _host, _partial_folder

    inside = _partial_folder(str(tmp_path))
    beside = _partial_folder(str(tmp_path / "new"))
    assert os.path.basename(inside).startswith(f".eppf-partial-{_host()}-{os.getpid()}-")
    assert os.path.basename(beside).startswith(f".new.eppf-partial-{_host()}-{os.getpid()}-")


# ---------------------------------------------------------------------------
# --random-state where the seeds are the saved ones
# ---------------------------------------------------------------------------


def test_predict_random_state_without_segment_is_refused(tmp_path, data_and_model, capsys):
    data, model = data_and_model
    status, out, err = _run(["predict", "--model", model, data, "--random-state", "3", "--no-progress"], capsys)
    assert status == 2 and out == ""
    assert err.strip() == "eppf predict: error: --random-state applies to scenes: add --segment"
    status, out, err = _run(["predict", "--model", model, _scene(tmp_path / "scene.xyz"), "--segment",
                             "--random-state", "3", "--no-progress", "--n-jobs", "1"], capsys)
    assert status == 0, err


def test_retrieve_random_state_is_refused(tmp_path, capsys):
    np.savez(tmp_path / "db.npz", descriptors=np.full((3, 4), 0.25), ids=np.array(["a", "b", "c"]))
    np.save(tmp_path / "q.npy", np.full((1, 4), 0.25))
    status, out, err = _run(["retrieve", "--database", tmp_path / "db.npz", "--query-descriptors", tmp_path / "q.npy",
                             "--random-state", "3"], capsys)
    assert status == 2 and out == ""
    assert err.startswith("eppf retrieve: error: --random-state: the queries are sampled and described with the "
                          f"seeds that {tmp_path / 'db.npz'} records")


# ---------------------------------------------------------------------------
# --help and docs/cli.rst
# ---------------------------------------------------------------------------


def _options(parser, name="eppf"):
    """``(command, action)`` of every option of ``parser`` and its subcommands, hidden ones included."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _options(sub, f"{name} {sub_name}")
        elif action.option_strings:
            yield name, action


def test_every_option_with_a_default_says_it_in_its_help():
    import argparse

    from eppf.cli import build_parser

    silent = [f"{name} {a.option_strings[-1]}" for name, a in _options(build_parser())
              if a.help != argparse.SUPPRESS and a.nargs != 0 and a.default not in (None, False, argparse.SUPPRESS)
              and "default" not in (a.help or "")]
    assert silent == []


def test_eppf_alone_has_the_defaults_of_eppf_run():
    from eppf.cli import build_parser

    parser = build_parser()
    alone, run = vars(parser.parse_args([])), vars(parser.parse_args(["run"]))
    assert {k: v for k, v in alone.items() if k != "command"} == {k: v for k, v in run.items() if k != "command"}


def test_every_option_in_the_cli_docs_is_an_option_of_the_command():
    import re
    from pathlib import Path

    from eppf.cli import build_parser

    text = (Path(__file__).resolve().parents[2] / "docs" / "cli.rst").read_text(encoding="utf-8")
    known = {s for _, a in _options(build_parser()) for s in a.option_strings}
    documented = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", text))
    assert documented and documented - known == set()


@pytest.mark.parametrize("argv", [["train", "--built-in", "-o", "m.eppf", "--n-points", "300"],
                                  ["evaluate", "--built-in", "--on-error", "raise"],
                                  ["run", "--resolution", "0.1"], ["--on-error", "skip"]])
def test_reading_options_are_refused_with_the_built_in_shapes(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    status, out, err = _run([*argv, "--no-progress"], capsys)
    option = argv[-2]
    assert status == 2, err
    assert err.strip().endswith(f"error: {option}: the built-in synthetic shapes are made in memory, not read from "
                                "files; leave it out")
    assert os.listdir(tmp_path) == []


def test_segment_random_state_help_names_only_what_segment_draws(capsys):
    # the shared help lists descriptor draws, mesh sampling and splits, none of which eppf segment makes
    with pytest.raises(SystemExit) as stop:
        main(["segment", "--help"])
    assert stop.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    help_text = text[text.rindex("--random-state RANDOM_STATE"):]  # (its entry, not the usage line)
    assert help_text.startswith("--random-state RANDOM_STATE seed of the RANSAC ground plane, the only thing it")
    assert "descriptor draws" not in help_text.split("--no-progress")[0]
