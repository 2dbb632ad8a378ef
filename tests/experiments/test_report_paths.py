"""Experiment reports record data files by base name, never by a machine's absolute path."""

import numpy as np

from eppf.datasets import save_npz
from eppf.experiments import load_data
from eppf.experiments._common import portable_command, write_report


def _small_npz(folder):
    rng = np.random.default_rng(0)
    clouds = [rng.normal(size=(30, 3)) for _ in range(8)]
    path = folder / "deep" / "inside" / "my_set.npz"
    path.parent.mkdir(parents=True)
    save_npz(path, clouds, [0, 1] * 4, ["a", "b"], split=["train"] * 6 + ["test"] * 2)
    return path


def test_report_names_the_file_not_its_folder(tmp_path):
    path = _small_npz(tmp_path)
    data = load_data(str(path))
    assert data.source == "`my_set.npz`"
    command = f"python -m eppf.experiments retrieval --data {path} --out {tmp_path / 'out'} --cache-dir /tmp/x/cache --quiet"
    paths = write_report(str(tmp_path / "out"), "retrieval", title="t", command=command, data=data,
                         protocol={"draws": 1}, table="| a |\n| --- |\n| 1 |", csv_rows=[{"a": 1}], log=lambda m: None)
    md = open(paths["md"]).read()
    assert str(tmp_path) not in md
    assert "deep/inside" not in md
    assert "- data: `my_set.npz`" in md
    assert "python -m eppf.experiments retrieval --data my_set.npz --out out --quiet" in md
    assert "/tmp/x" not in md


def test_portable_command_cases():
    # relative --out is kept; = forms are rewritten; builtin stays; folders keep a slash only when they exist
    assert portable_command("p x --data=/a/b/c.npz --out=docs/results/c") == "p x --data c.npz --out docs/results/c"
    assert portable_command("p x --data builtin --cache-dir=/tmp/c --n-jobs 2") == "p x --data builtin --n-jobs 2"
    assert portable_command("p x --data ../elsewhere/data/m.npz") == "p x --data m.npz"
    assert portable_command("p x --data") == "p x --data"
    # a recorded function call and an unparsable string are left alone
    call = "eppf.experiments.run_noise(...)  # function call; see the protocol"
    assert portable_command(call) == call
    assert portable_command('p "unclosed') == 'p "unclosed'
