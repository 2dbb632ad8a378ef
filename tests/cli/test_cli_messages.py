"""What a new user meets first: a file too small to describe is skipped by name like an unreadable one,
messages count in English, --no-progress silences every model, and predict's CSV marks unreliable rows."""

import csv

import numpy as np
import pytest

from eppf.cli import main
from eppf.io import write_point_cloud

from tests.cli._helpers import run as _run

FAST = ["--n-pairs", "600", "--n-jobs", "1"]


def _folder(root, n_per_class=3, n_points=120):
    """Two classes (blobs, sticks) of ``n_per_class`` XYZ files each."""
    rng = np.random.default_rng(3)
    for name, stretch in (("blob", [1.0, 1.0, 1.0]), ("stick", [3.0, 0.3, 0.3])):
        (root / name).mkdir(parents=True)
        for i in range(n_per_class):
            write_point_cloud(root / name / f"{i}.xyz", rng.normal(size=(n_points, 3)) * stretch)
    return root


@pytest.fixture(scope="module")
def kl_model(tmp_path_factory):
    root = tmp_path_factory.mktemp("kl")
    data = _folder(root / "data")
    assert main(["train", "--data", str(data), "-o", str(root / "m.eppf"), "--test-size", "0", "--no-progress",
                 *FAST]) == 0
    return root / "m.eppf"


def test_a_one_point_file_is_skipped_by_name_not_fatal(tmp_path, kl_model, capsys):
    scans = tmp_path / "scans"
    scans.mkdir()
    rng = np.random.default_rng(0)
    write_point_cloud(scans / "good.xyz", rng.normal(size=(100, 3)))
    write_point_cloud(scans / "single.xyz", rng.normal(size=(1, 3)))
    status, out, err = _run(["predict", scans, "--model", kl_model, "--no-progress", *FAST[2:]], capsys)
    assert status == 0, err
    assert "good.xyz" in out and "single.xyz" not in out
    assert "skipped 1 of 2 files" in err and "single.xyz: 1 point," in err and "point cloud 1" not in err
    status, out, err = _run(["describe", scans, "-o", tmp_path / "d.npz", "--no-progress", *FAST], capsys)
    assert status == 0, err
    with np.load(tmp_path / "d.npz") as saved:
        assert saved["descriptors"].shape[0] == 1 and saved["ids"].tolist() == [str(scans / "good.xyz")]
    assert "single.xyz: 1 point," in err
    # --on-error raise stops at it, naming the file
    for argv in (["predict", scans, "--model", kl_model], ["describe", scans, "-o", tmp_path / "e.npz"]):
        status, _, err = _run([*argv, "--on-error", "raise", "--no-progress"], capsys)
        assert status == 2 and err.startswith(f"eppf {argv[0]}: error: {scans / 'single.xyz'}: 1 point,"), err
    assert not (tmp_path / "e.npz").exists()


def test_a_one_point_file_in_training_data_is_skipped(tmp_path, capsys):
    data = _folder(tmp_path / "data")
    write_point_cloud(data / "blob" / "single.xyz", np.zeros((1, 3)))
    status, out, err = _run(["train", "--data", data, "-o", tmp_path / "m.eppf", "--test-size", "0",
                             "--no-progress", *FAST], capsys)
    assert status == 0, err
    assert "single.xyz: 1 point," in err and "training on all 6 objects" in out


def test_messages_count_in_english(tmp_path, kl_model, capsys):
    one_class = tmp_path / "one"
    (one_class / "a").mkdir(parents=True)
    for i in range(2):
        write_point_cloud(one_class / "a" / f"{i}.xyz", np.random.default_rng(i).normal(size=(50, 3)))
    status, _, err = _run(["train", "--data", one_class, "-o", tmp_path / "m.eppf", "--no-progress"], capsys)
    assert status == 2 and "has one class ('a');" in err and "np.str_" not in err
    small = tmp_path / "small.xyz"
    write_point_cloud(small, np.random.default_rng(0).normal(size=(5, 3)))
    status, out, err = _run(["predict", small, "--model", kl_model, "--no-progress", "-o", tmp_path / "p.csv"],
                            capsys)
    assert status == 0
    assert "1 object has too few points" in err and "its result is unreliable" in err and "(5 points)" in err
    assert "1 objects" not in err and "eppf: 1 row ->" in out


def test_predict_csv_marks_the_rows_warned_as_unreliable(tmp_path, kl_model, capsys):
    scans = tmp_path / "scans"
    scans.mkdir()
    rng = np.random.default_rng(1)
    write_point_cloud(scans / "a_good.xyz", rng.normal(size=(100, 3)))
    write_point_cloud(scans / "b_small.xyz", rng.normal(size=(7, 3)))
    assert _run(["predict", scans, "--model", kl_model, "-o", tmp_path / "p.csv", "--no-progress"], capsys)[0] == 0
    with open(tmp_path / "p.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["unreliable"] for r in rows][0] == ""
    assert rows[1]["unreliable"].startswith("7 points;") and "--normal-neighbors" in rows[1]["unreliable"]
    # a printed table has the column only when a row is marked
    _, out, _ = _run(["predict", scans / "a_good.xyz", "--model", kl_model, "--no-progress"], capsys)
    assert "unreliable" not in out.splitlines()[0]


def test_a_commands_own_output_in_its_input_folder_is_not_read_back(tmp_path, kl_model, capsys):
    # predict -o scans/labels.csv, run twice: the second run read its own CSV as a point file (a CSV is one)
    # and skipped it with a warning; retrieve's CSV and describe's .npy likewise
    scans = tmp_path / "scans"
    scans.mkdir()
    rng = np.random.default_rng(2)
    for name in ("a.xyz", "b.xyz"):
        write_point_cloud(scans / name, rng.normal(size=(100, 3)))
    for _ in range(2):
        status, out, err = _run(["predict", scans, "--model", kl_model, "-o", scans / "labels.csv", "--no-progress"],
                                capsys)
        assert status == 0 and err == "", err
        assert "eppf: 2 rows ->" in out
    (scans / "labels.csv").unlink()  # (another command's CSV is read as what it is: a point file)
    status, out, err = _run(["describe", scans, "-o", scans / "d.npy", "--n-pairs", "500", "--no-progress"], capsys)
    assert status == 0 and err == "", err
    status, out, err = _run(["describe", scans, "-o", scans / "d.npy", "--n-pairs", "500", "--no-progress"], capsys)
    assert status == 0 and err == "" and "2 eppf descriptors" in out, (out, err)


def test_no_progress_silences_a_cnn_model_trained_with_progress(tmp_path, capsys):
    pytest.importorskip("torch")
    data = _folder(tmp_path / "data", n_per_class=4, n_points=80)
    # trained with progress: the descriptor pool's fitted copies are made verbose
    status, _, err = _run(["train", "--data", data, "-o", tmp_path / "cnn.eppf", "--classifier", "4d",
                           "--n-bins", "4", "2", "2", "2", "--max-epochs", "1", "--test-size", "0", *FAST], capsys)
    assert status == 0, err
    status, out, err = _run(["predict", data / "blob", "--model", tmp_path / "cnn.eppf", "--no-progress",
                             *FAST[2:]], capsys)
    assert status == 0 and "probability" in out
    assert err == "", err
    # and with progress, the bars are back
    status, _, err = _run(["predict", data / "blob", "--model", tmp_path / "cnn.eppf", *FAST[2:]], capsys)
    assert status == 0 and "EPPF" in err
