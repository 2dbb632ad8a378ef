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


def test_main_bad_input_gives_one_line_error_and_status_1(tmp_path, capsys):
    assert main(["--data", str(tmp_path / "missing.npz"), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("eppf: error:") and "missing.npz" in err[0]


def test_readme_main_command_runs_on_built_in_data():
    # The README's first command ends in `eppf`; run it the same way, as a process.
    env = dict(os.environ, OMP_NUM_THREADS="2")
    proc = subprocess.run([sys.executable, "-m", "eppf", "--no-progress", "--n-pairs", "5000"],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "built-in synthetic shapes" in proc.stdout
    assert "Total accuracy (%)" in proc.stdout
