"""What the commands refuse before any work, and what they leave behind when they stop midway: an output that
is one of the inputs (under any spelling or link), options that the chosen mode would ignore, a partial
``eppf segment`` folder; and ``eppf experiment --on-error``."""

import os

import numpy as np
import pytest

from eppf.cli import build_parser, make_pipeline_from_args, main
from eppf.io import write_point_cloud, write_point_fields

from tests.cli._helpers import read_csv as _csv
from tests.cli._helpers import run as _run


def _same_file_spellings(path):
    """``path`` under other names: another spelling, a symbolic link, a hard link (those the system has)."""
    folder, name = os.path.split(str(path))
    names = [("same path", str(path)), ("another spelling", os.path.join(folder, ".", "x", "..", name))]
    os.makedirs(os.path.join(folder, "x"), exist_ok=True)
    for label, make in (("symbolic link", os.symlink), ("hard link", os.link)):
        link = os.path.join(folder, f"{label.replace(' ', '_')}_{name}")
        try:
            make(str(path), link)
        except (OSError, NotImplementedError):
            continue
        names.append((label, link))
    return names


def _unchanged(path, before):
    with open(path, "rb") as fh:
        assert fh.read() == before, f"{path} was written"


def _bytes(path):
    with open(path, "rb") as fh:
        return fh.read()


def _refused(argv, capsys, *texts):
    status, _, err = _run([*argv, "--no-progress"], capsys)
    assert status == 2, (argv, err)
    assert len(err.strip().splitlines()) == 1, err
    for text in texts:
        assert text in err, (argv, err)
    return err


# ---------------------------------------------------------------------------
# An output that is an input
# ---------------------------------------------------------------------------


def test_labelled_output_that_is_the_scene_is_refused_under_every_name(tmp_path, capsys):
    scene = tmp_path / "tile.ply"
    write_point_fields(scene, np.random.default_rng(0).normal(size=(50, 3)), {})
    before = _bytes(scene)
    model = tmp_path / "missing.eppf"  # refused before the model is read
    for how, name in _same_file_spellings(scene):
        err = _refused(["predict", "--model", model, scene, "--segment", "--labelled-output", name,
                        "-o", tmp_path / "rows.csv"], capsys, f"--labelled-output {name}", str(scene), "same file")
        assert "replace" in err, how
        _unchanged(scene, before)
    assert not (tmp_path / "rows.csv").exists()


def test_predict_outputs_that_are_inputs_or_each_other_are_refused(tmp_path, capsys):
    cloud = tmp_path / "a.xyz"
    write_point_cloud(cloud, np.random.default_rng(0).normal(size=(50, 3)))
    model = tmp_path / "m.eppf"
    model.write_bytes(b"not read: refused before")
    before, model_before = _bytes(cloud), _bytes(model)
    for how, name in _same_file_spellings(cloud):
        _refused(["predict", "--model", model, cloud, "-o", name], capsys, f"--output {name}", "same file")
        _unchanged(cloud, before)
    _refused(["predict", "--model", model, cloud, "-o", model], capsys, f"--model {model}")
    _unchanged(model, model_before)
    # the table and the labelled scene cannot be one file, even a new one
    _refused(["predict", "--model", model, cloud, "--segment", "-o", tmp_path / "out.ply", "--labelled-output",
              tmp_path / "x" / ".." / "out.ply"], capsys, "--labelled-output", "same file")
    assert not (tmp_path / "out.ply").exists()


def test_describe_train_evaluate_retrieve_refuse_writing_over_an_input(tmp_path, capsys):
    cloud = tmp_path / "cloud.npy"
    np.save(cloud, np.random.default_rng(0).normal(size=(50, 3)))
    before = _bytes(cloud)
    for how, name in _same_file_spellings(cloud):
        _refused(["describe", cloud, "-o", name], capsys, f"--output {name}", f"the input {cloud}")
        _unchanged(cloud, before)
    data = tmp_path / "set.npz"
    data.write_bytes(b"a data set: not read, refused before")
    data_before = _bytes(data)
    link = _same_file_spellings(data)[-1][1]
    _refused(["train", "--data", data, "-o", link], capsys, f"--data {data}", "same file")
    _refused(["evaluate", "--data", data, "-o", link], capsys, f"--data {data}")
    _refused(["evaluate", "--data", data, "--model", cloud, "--no-retrieval", "-o", cloud], capsys,
             f"--model {cloud}")
    _refused(["retrieve", "--database", data, "-o", link, cloud], capsys, f"--database {data}")
    _refused(["retrieve", "--database", cloud, "--query-descriptors", data, "-o", link], capsys,
             f"--query-descriptors {data}")
    _unchanged(data, data_before)
    _unchanged(cloud, before)


def test_an_object_file_in_an_input_folder_is_not_taken_for_the_commands_own_output(tmp_path, capsys):
    # a folder's listing leaves the output out (a command's CSV in its input folder, run twice): a data file
    # named as the output was left out of the input and replaced
    scans = tmp_path / "scans"
    scans.mkdir()
    rng = np.random.default_rng(0)
    np.savetxt(scans / "a.csv", rng.normal(size=(50, 3)), delimiter=",")
    np.savez(scans / "b.npz", points=rng.normal(size=(50, 3)))
    before = {n: _bytes(scans / n) for n in ("a.csv", "b.npz")}
    model = tmp_path / "missing.eppf"
    _refused(["predict", "--model", model, scans, "-o", scans / "a.csv"], capsys,
             f"--output {scans / 'a.csv'} is a point file in the input folder {scans}")
    _refused(["describe", scans, "-o", scans / "b.npz"], capsys, "is a point file in the input folder")
    for name, data in before.items():
        _unchanged(scans / name, data)
    # the command's own table from an earlier run may be replaced (it is then read by nothing)
    (scans / "labels.csv").write_text("file,class,distance,neighbour,unreliable\n")
    err = _refused(["predict", "--model", model, scans, "-o", scans / "labels.csv"], capsys, str(model))
    assert "point file" not in err


def test_experiment_output_inside_the_data_folder_is_refused(tmp_path, capsys, monkeypatch):
    ran = []
    monkeypatch.setattr("eppf.experiments.run_retrieval", lambda **kw: ran.append(kw))
    (tmp_path / "data" / "box").mkdir(parents=True)
    for out in (tmp_path / "data", tmp_path / "data" / "results"):
        _refused(["experiment", "retrieval", "--data", tmp_path / "data", "--out", out], capsys,
                 f"--out {out} is inside the --data folder")
    _refused(["experiment", "retrieval", "--data", tmp_path / "data", "--out", tmp_path / "r", "--cache-dir",
              tmp_path / "data" / "cache"], capsys, "--cache-dir")
    assert ran == []


# ---------------------------------------------------------------------------
# eppf segment: the output folder appears only when complete
# ---------------------------------------------------------------------------


def _blobs_scene(tmp_path):
    rng = np.random.default_rng(0)
    points = np.concatenate([rng.normal(size=(60, 3)) * 0.1 + [5.0 * k, 0, 0] for k in range(3)])
    path = tmp_path / "room.pcd"
    write_point_fields(path, points, {"intensity": np.arange(len(points), dtype=np.float32)})
    return path


SEGMENT = ["--ground", "none", "--tolerance", "1", "--min-points", "10", "--no-progress"]


def _fail_on_second_file(monkeypatch, exc):
    import eppf.io

    real, calls = eppf.io.write_point_fields, []

    def write(path, *args, **kwargs):
        calls.append(path)
        if len(calls) == 2:
            raise exc
        return real(path, *args, **kwargs)

    monkeypatch.setattr(eppf.io, "write_point_fields", write)
    return calls


@pytest.mark.parametrize("exc, status", [(OSError(28, "No space left on device"), 2), (KeyboardInterrupt(), 130)])
def test_segment_stopped_midway_leaves_no_output_and_the_rerun_works(tmp_path, capsys, monkeypatch, exc, status):
    scene = _blobs_scene(tmp_path)
    out = tmp_path / "objects"
    before = sorted(os.listdir(tmp_path))
    calls = _fail_on_second_file(monkeypatch, exc)
    got, _, err = _run(["segment", scene, "-o", out, *SEGMENT], capsys)
    assert got == status and len(calls) == 2, err
    assert sorted(os.listdir(tmp_path)) == before  # no output, no partial folder beside it
    monkeypatch.undo()
    got, _, err = _run(["segment", scene, "-o", out, *SEGMENT], capsys)
    assert got == 0, err
    rows = _csv(out / "segments.csv")
    assert len(rows) == 3 and sorted(os.listdir(out)) == [r["file"] for r in rows] + ["segments.csv"]
    assert sorted(os.listdir(tmp_path)) == sorted(before + ["objects"])


def test_segment_into_an_empty_folder_keeps_it_when_stopped(tmp_path, capsys, monkeypatch):
    scene = _blobs_scene(tmp_path)
    out = tmp_path / "objects"
    out.mkdir()
    (out / "keep").mkdir()  # not empty: refused, untouched
    _refused(["segment", scene, "-o", out, *SEGMENT], capsys, "is not empty")
    assert os.listdir(out) == ["keep"]
    (out / "keep").rmdir()
    calls = _fail_on_second_file(monkeypatch, KeyboardInterrupt())
    assert _run(["segment", scene, "-o", out, *SEGMENT], capsys)[0] == 130
    # written inside the folder given (its file system, were it a mount point), not beside it
    assert os.path.dirname(os.path.dirname(str(calls[0]))) == str(out)
    assert out.is_dir() and os.listdir(out) == []  # the folder that was there is kept, empty
    assert sorted(os.listdir(tmp_path)) == ["objects", "room.pcd"]
    monkeypatch.undo()
    assert _run(["segment", scene, "-o", out, *SEGMENT], capsys)[0] == 0
    assert len(_csv(out / "segments.csv")) == 3 and len(os.listdir(out)) == 4


def test_segment_into_a_folder_it_cannot_write_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    scene = _blobs_scene(tmp_path)
    read = []
    monkeypatch.setattr("eppf.io.read_point_fields", lambda *a, **k: read.append(a))
    monkeypatch.setattr(os, "access", lambda path, mode: False)  # (root may write anywhere: no chmod test)
    (tmp_path / "empty").mkdir()
    for out in (tmp_path / "new", tmp_path / "empty"):
        _refused(["segment", scene, "-o", out, *SEGMENT], capsys, f"--output {out}: the folder", "is not writable")
    assert read == []


# ---------------------------------------------------------------------------
# Options the chosen mode would ignore
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("classifier, option, value", [
    ("kl", "--max-epochs", "3"), ("kl", "--recipe", "paper"), ("kl", "--precision", "float32"),
    ("4d", "--n-neighbors", "3"), ("pointnet", "--recipe", "paper"), ("pointnet", "--precision", "bfloat16"),
    ("pointnet", "--n-neighbors", "3"),
])
def test_train_refuses_options_its_classifier_ignores(tmp_path, capsys, classifier, option, value):
    argv = ["train", "--built-in", "-o", tmp_path / "m.eppf", "--classifier", classifier, option, value]
    err = _refused(argv, capsys, f"{option}: the {classifier} classifier does not use it")
    assert "leave it out" in err
    assert not (tmp_path / "m.eppf").exists()


def test_train_options_keep_their_defaults_where_they_apply():
    def clf(*extra):
        args = build_parser().parse_args(["train", "--built-in", "-o", "m.eppf", *extra])
        return make_pipeline_from_args(args)[-1]

    assert clf().n_neighbors == 1 and clf("--n-neighbors", "3").n_neighbors == 3
    assert clf("--classifier", "4d").max_epochs == 100
    assert clf("--classifier", "4d", "--max-epochs", "7").max_epochs == 7
    assert clf("--classifier", "pointnet", "--max-epochs", "7").max_epochs == 7
    assert clf("--classifier", "4d", "--recipe", "paper").precision == "float32"


def test_other_ignored_options_are_refused(tmp_path, capsys):
    data = tmp_path / "set.npz"
    rng = np.random.default_rng(0)
    np.savez(data, points=rng.normal(size=(40, 3)), offsets=np.array([0, 10, 20, 30, 40]),
             labels=np.array([0, 0, 1, 1]), class_names=np.array(["a", "b"]))
    _refused(["train", "--built-in", "-o", tmp_path / "m.eppf", "--all", "--test-size", "0.5"], capsys,
             "--test-size: --all trains on every object")
    _refused(["evaluate", "--built-in", "--model", tmp_path / "m.eppf", "--no-retrieval", "--descriptor", "esf"],
             capsys, "--descriptor: it sets the descriptor of the retrieval, which --no-retrieval skips")
    _refused(["evaluate", "--built-in", "--model", tmp_path / "m.eppf", "--no-retrieval", "--random-state", "3"],
             capsys, "--random-state: it seeds the retrieval's descriptors, which --no-retrieval skips")
    for command in (["describe", data, "-o", tmp_path / "d.npy"], ["train", "--data", data, "-o", tmp_path / "m"]):
        _refused([*command, "--n-points", "8"], capsys, f"--n-points: {data} is a .npz data set")
    assert not (tmp_path / "d.npy").exists() and not (tmp_path / "m").exists()


# ---------------------------------------------------------------------------
# eppf experiment --on-error
# ---------------------------------------------------------------------------


def _class_folder_with_a_bad_file(tmp_path):
    rng = np.random.default_rng(0)
    root = tmp_path / "objects"
    for name in ("box", "ball"):
        (root / name).mkdir(parents=True)
        for k in range(3):
            write_point_cloud(root / name / f"{k}.xyz", rng.normal(size=(40, 3)))
    (root / "box" / "broken.xyz").write_text("1 2\nnot numbers\n")
    return root


def test_experiment_on_error_skips_or_stops(tmp_path, capsys, monkeypatch):
    from eppf.experiments._common import load_or_pass

    seen = []

    def retrieval(data, quick, random_state, **kw):  # the experiment's loading, without its computing
        seen.append(load_or_pass(data, quick=quick, random_state=random_state))

    monkeypatch.setattr("eppf.experiments.run_retrieval", retrieval)
    root = _class_folder_with_a_bad_file(tmp_path)
    base = ["experiment", "retrieval", "--data", root, "--out", tmp_path / "r"]
    err = _refused(base, capsys, "broken.xyz")  # the default: an experiment's figures are the whole data set's
    assert seen == []
    status, _, err = _run([*base, "--on-error", "skip"], capsys)
    assert status == 0, err
    assert err.startswith("eppf experiment: warning: ") and "broken.xyz" in err and len(err.splitlines()) == 1
    (data,) = seen
    assert len(data.clouds) == 6 and "1 of 7 files could not be read" in data.source  # in the report's data line
    _refused([*base, "--on-error", "raise"], capsys, "broken.xyz")
    with pytest.raises(SystemExit) as exc:  # a bad choice: argparse's one line
        main([str(a) for a in base] + ["--on-error", "ignore"])
    assert exc.value.code == 2 and "--on-error: invalid choice: 'ignore'" in capsys.readouterr().err


def test_experiment_help_lists_on_error(capsys):
    for name in ("retrieval", "ablation", "classification", "noise", "runtime"):
        with pytest.raises(SystemExit):
            main(["experiment", name, "--help"])
        assert "--on-error {skip,raise}" in capsys.readouterr().out, name
