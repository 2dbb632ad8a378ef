"""Error paths of the ``eppf`` command: one line naming the right thing, exit status 2, no traceback."""

import dataclasses
import time

import numpy as np
import pytest

import eppf
from eppf.cli import main
from eppf.cli._common import SUBCOMMANDS
from eppf.io import write_point_cloud


def _run(argv, capsys):
    status = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def _one_line_error(status, err, command):
    lines = err.strip().splitlines()
    assert status == 2, err
    assert "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith(f"eppf {command}: error:"), err
    return lines[0]


def _class_folder(root, counts):
    rng = np.random.default_rng(0)
    for name, n in counts.items():
        (root / name).mkdir(parents=True)
        for i in range(n):
            write_point_cloud(root / name / f"{i}.xyz", rng.normal(size=(60, 3)) * (1 + len(name)))
    return root


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"eppf {eppf.__version__}"


def test_subcommand_table_and_registry_choices():
    from eppf.cli import build_parser
    from eppf.registry import CLASSIFIERS, DESCRIPTORS

    assert list(SUBCOMMANDS) and set(SUBCOMMANDS) == {"run", "describe", "retrieve", "train", "predict", "segment",
                                                      "evaluate", "bench", "experiment"}
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert list(sub.choices) == ["run", "describe", "retrieve", "train", "predict", "segment", "evaluate", "bench",
                                 "experiment"]
    for name in ("describe", "train", "evaluate", "bench"):
        action = next(a for a in sub.choices[name]._actions if a.dest == "descriptor")
        assert list(action.choices) == list(DESCRIPTORS)
    action = next(a for a in sub.choices["train"]._actions if a.dest == "classifier")
    assert set(CLASSIFIERS) <= set(action.choices)
    # one vocabulary: the PCA neighbourhood is --normal-neighbors wherever descriptors are computed
    for name in ("run", "describe", "train", "evaluate"):
        flags = {s for a in sub.choices[name]._actions for s in a.option_strings}
        assert "--normal-neighbors" in flags and "--no-progress" in flags and "--random-state" in flags


@pytest.mark.parametrize("command", ["train", "evaluate", "run"])
def test_missing_data_folder_says_it_does_not_exist(tmp_path, capsys, command):
    argv = {"train": ["train", "-o", tmp_path / "m.model"], "evaluate": ["evaluate"], "run": []}[command]
    status, _, err = _run(argv + ["--data", f"{tmp_path}/nope/", "--no-progress"], capsys)
    if command == "run":  # no subcommand: plain "eppf: error:"
        assert err.startswith("eppf: error:") and len(err.strip().splitlines()) == 1
        line = err.strip()
    else:
        line = _one_line_error(status, err, command)
    assert status == 2 and "nope" in line and "folder" in line and "does not exist" in line
    assert "load_npz" not in line and "Traceback" not in err


def test_one_object_class_is_named(tmp_path, capsys):
    data = _class_folder(tmp_path / "objects", {"chair": 3, "lamp": 1})
    status, _, err = _run(["train", "--data", data, "-o", tmp_path / "m.model", "--no-progress"], capsys)
    line = _one_line_error(status, err, "train")
    assert "'lamp'" in line and "only one object" in line and "--test-size 0" in line
    # with nothing held out it trains
    assert _run(["train", "--data", data, "-o", tmp_path / "m.model", "--test-size", "0", "--n-pairs", "500",
                 "--no-progress"], capsys)[0] == 0


def test_one_class_folder_is_refused(tmp_path, capsys):
    data = _class_folder(tmp_path / "objects", {"chair": 4})
    status, _, err = _run(["train", "--data", data, "-o", tmp_path / "m.model", "--no-progress"], capsys)
    line = _one_line_error(status, err, "train")
    assert "one class" in line and "'chair'" in line


def test_output_path_is_checked_before_the_work(tmp_path, capsys, monkeypatch):
    data = _class_folder(tmp_path / "objects", {"chair": 3, "lamp": 3})
    calls = []
    for module in ("_common", "_describe"):  # load_labelled (train, evaluate) and describe read through these
        monkeypatch.setattr(f"eppf.cli.{module}.read_inputs", lambda *a, **k: calls.append(1))
    for argv in (["train", "--data", data, "-o", tmp_path / "missing_dir" / "x.model"],
                 ["describe", data, "-o", tmp_path / "missing_dir" / "d.npz"],
                 ["describe", data, "-o", tmp_path / "d.csv"],
                 ["evaluate", "--data", data, "-o", tmp_path / "missing_dir" / "e.csv"]):
        t0 = time.perf_counter()
        status, out, err = _run(argv + ["--no-progress"], capsys)
        line = _one_line_error(status, err, argv[0])
        assert ("missing_dir" in line and "does not exist" in line) or ".npy or .npz" in line
        assert out == "" and time.perf_counter() - t0 < 2
    assert calls == []  # nothing was read


def test_tiny_cloud_gets_a_warning_naming_the_file(tmp_path, capsys):
    rng = np.random.default_rng(1)
    folder = tmp_path / "clouds"
    folder.mkdir()
    write_point_cloud(folder / "big.xyz", rng.normal(size=(200, 3)))
    write_point_cloud(folder / "tiny.xyz", rng.normal(size=(8, 3)))
    status, _, err = _run(["describe", folder, "-o", tmp_path / "d.npy", "--n-pairs", "500", "--no-progress"],
                          capsys)
    assert status == 0
    lines = [line for line in err.splitlines() if "warning" in line]
    assert len(lines) == 1 and "tiny.xyz (8 points)" in lines[0] and "big.xyz" not in lines[0]
    assert "21" in lines[0] and "--normal-neighbors" in lines[0]
    # with fewer normal neighbours the same cloud is fine
    status, _, err = _run(["describe", folder, "-o", tmp_path / "d.npy", "--n-pairs", "500", "--normal-neighbors",
                           "5", "--no-progress"], capsys)
    assert status == 0 and "warning" not in err


def test_normal_neighbors_reach_the_descriptor_and_are_refused_where_meaningless(tmp_path, capsys):
    rng = np.random.default_rng(1)
    cloud = tmp_path / "c.xyz"
    write_point_cloud(cloud, rng.normal(size=(120, 3)))
    assert _run(["describe", cloud, "-o", tmp_path / "a.npy", "--n-pairs", "500", "--normal-neighbors", "7",
                 "--no-progress"], capsys)[0] == 0
    expected = eppf.EPPFTransformer(n_pairs=500, n_neighbors=7, random_state=0).fit_transform(
        [np.loadtxt(cloud)])
    np.testing.assert_allclose(np.load(tmp_path / "a.npy"), expected, rtol=1e-12, atol=1e-15)
    status, _, err = _run(["describe", cloud, "-o", tmp_path / "b.npy", "--descriptor", "esf",
                           "--normal-neighbors", "7", "--no-progress"], capsys)
    assert "estimates no normals" in _one_line_error(status, err, "describe")


def test_missing_optional_dependency_gives_install_advice(capsys, monkeypatch):
    def needs_matplotlib(args):
        raise ModuleNotFoundError("No module named 'matplotlib'", name="matplotlib")

    monkeypatch.setitem(SUBCOMMANDS, "bench", dataclasses.replace(SUBCOMMANDS["bench"], run=needs_matplotlib))
    status, _, err = _run(["bench", "--no-progress"], capsys)
    line = _one_line_error(status, err, "bench")
    assert 'pip install -c constraints.txt -e ".[plot]"' in line and "matplotlib" in line


def test_experiment_takes_no_progress_and_keeps_quiet_as_deprecated(monkeypatch, capsys):
    seen = []
    monkeypatch.setattr("eppf.experiments.run_retrieval", lambda **kw: seen.append((kw["verbose"], kw["command"])))
    assert main(["experiment", "retrieval", "--quick", "--no-progress"]) == 0
    assert "deprecated" not in capsys.readouterr().err
    assert main(["experiment", "retrieval", "--quiet"]) == 0
    assert main(["experiment", "retrieval"]) == 0
    assert seen == [(False, "eppf experiment retrieval --quick --no-progress"),
                    (False, "eppf experiment retrieval --quiet"), (True, "eppf experiment retrieval")]
    assert "--quiet is deprecated" in capsys.readouterr().err


@pytest.mark.parametrize("which", ["database", "queries"])
def test_retrieve_refuses_a_descriptor_file_whose_header_declares_more_than_it_holds(tmp_path, capsys, which):
    # np.load allocated what the header declared before reading; eppf.io's reader checks it first
    import io

    head = io.BytesIO()
    np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False, "shape": (10**11, 128)})
    bad = tmp_path / "bad.npy"
    bad.write_bytes(head.getvalue() + bytes(800))
    good = tmp_path / "db.npz"
    np.savez(good, descriptors=np.full((3, 4), 0.25))
    argv = ["retrieve", "--database", bad if which == "database" else good, "--query-descriptors",
            good if which == "database" else bad]
    line = _one_line_error(*_run(argv, capsys)[::2], "retrieve")
    assert str(bad) in line and "the header declares an array of shape (100000000000, 128)" in line


@pytest.mark.parametrize("argv, option", [(["--resolution", "nan"], "--resolution"),
                                          (["--resolution", "-1"], "--resolution"),
                                          (["--n-points", "100", "--resolution", "0.5"], "--resolution")])
def test_bare_eppf_checks_the_sampling_options_as_eppf_run_does(tmp_path, capsys, argv, option):
    # `eppf --data x` (the README's spelling) took --resolution as any float and both options together, and
    # failed later on every file ("no file could be read") instead of naming the option
    data = _class_folder(tmp_path / "objects", {"chair": 2, "lamp": 2})
    with pytest.raises(SystemExit) as exc:
        main(["--data", str(data), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err
    line = err.strip().splitlines()[-1]
    assert line.startswith("eppf: error: argument") and option in line and "no file could be read" not in err


@pytest.mark.parametrize("option", [["--n-points", "64"], ["--resolution", "0.5"]])
def test_evaluate_with_a_model_refuses_the_sampling_options_it_would_ignore(tmp_path, capsys, option):
    # with --model, files are read with the model's saved sampling settings: --n-points/--resolution were
    # accepted and silently ignored (retrieval included), so the table looked like that of the asked sampling
    data = _class_folder(tmp_path / "objects", {"chair": 3, "lamp": 3})
    model = tmp_path / "m.model"
    assert _run(["train", "--data", data, "-o", model, "--test-size", "0", "--n-pairs", "500", "--no-progress"],
                capsys)[0] == 0
    status, out, err = _run(["evaluate", "--data", data, "--model", model, "--n-pairs", "500", "--no-progress",
                             *option], capsys)
    line = _one_line_error(status, err, "evaluate")
    assert option[0] in line and "--model" in line and out == ""
    # without --model they apply, as before
    assert _run(["evaluate", "--data", data, "--n-pairs", "500", "--no-progress", *option], capsys)[0] == 0


@pytest.mark.parametrize("option", [["--descriptor", "esf"], ["--n-pairs", "500"], ["--n-bins", "4", "2", "2", "2"],
                                    ["--scaling", "object"], ["--normal-neighbors", "5"]])
def test_pointnet_training_refuses_the_descriptor_options_it_would_ignore(tmp_path, capsys, option):
    # PointNet reads the points: a descriptor option was accepted, ignored and recorded in the model's params
    data = _class_folder(tmp_path / "objects", {"chair": 3, "lamp": 3})
    model = tmp_path / "m.model"
    status, out, err = _run(["train", "--data", data, "-o", model, "--classifier", "pointnet", "--max-epochs", "1",
                             "--no-progress", *option], capsys)
    line = _one_line_error(status, err, "train")
    assert line.startswith(f"eppf train: error: {option[0]}:") and "pointnet" in line
    assert out == "" and not model.exists()


def test_experiment_data_help_names_the_folders_it_reads():
    # eppf experiment --data reads a folder of class subfolders (load_data: load_folder), as the README says;
    # its help named only 'builtin' and .npz files
    from eppf.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["experiment"]
    for name, parser in next(a for a in sub._actions if a.dest == "experiment").choices.items():
        text = next(a for a in parser._actions if a.dest == "data").help
        assert "folder" in text and ".npz" in text, name
