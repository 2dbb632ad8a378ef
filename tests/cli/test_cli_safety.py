"""What the commands leave behind when they stop midway: no partial ``eppf segment`` folder."""

import os

import numpy as np
import pytest

from eppf.io import write_point_fields

from tests.cli._helpers import read_csv as _csv
from tests.cli._helpers import run as _run


def _refused(argv, capsys, *texts):
    status, _, err = _run([*argv, "--no-progress"], capsys)
    assert status == 2, (argv, err)
    assert len(err.strip().splitlines()) == 1, err
    for text in texts:
        assert text in err, (argv, err)
    return err


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
    _fail_on_second_file(monkeypatch, KeyboardInterrupt())
    assert _run(["segment", scene, "-o", out, *SEGMENT], capsys)[0] == 130
    assert out.is_dir() and os.listdir(out) == []  # the folder that was there is kept, empty
    assert sorted(os.listdir(tmp_path)) == ["objects", "room.pcd"]
    monkeypatch.undo()
    assert _run(["segment", scene, "-o", out, *SEGMENT], capsys)[0] == 0
    assert len(_csv(out / "segments.csv")) == 3 and len(os.listdir(out)) == 4
