"""The file fuzz harness (scripts/fuzz_files.py --short): about 200 mutated files of every
format, each read in a forked child under a 4 GiB address-space limit; every outcome must be
a successful read or a FileFormatError/OSError naming the file, with bounded memory and time."""

import os
import subprocess
import sys

import pytest

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scripts", "fuzz_files.py")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the harness forks a child per file")
def test_fuzz_files_short():
    root = os.path.dirname(os.path.dirname(SCRIPT))
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    result = subprocess.run([sys.executable, "-W", "error::RuntimeWarning", SCRIPT, "--short"], cwd=root, env=env,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-4000:]
    lines = result.stdout.splitlines()
    total = next(line for line in lines if line.startswith("all "))
    ok, documented, failed = map(int, total.split()[1:])
    assert failed == 0 and ok + documented == 200
    # the mutations reach both outcomes: some files still read, most are refused
    assert ok > 10 and documented > 100
    # every seed format took part
    for name in ("ascii.pcd", "binary.pcd", "compressed.pcd", "cloud_binary.ply", "mesh_ascii.ply", "mesh.off",
                 "mesh.obj", "ascii.stl", "binary.stl", "cloud.xyz", "count.pts", "cloud.npy", "cloud.npz"):
        assert any(line.startswith(name + " ") for line in lines), name
    # and the optional formats, whose hostile headers (counts, offsets, extra-bytes descriptors) are refused
    import importlib.util

    optional = {"extra.las": "laspy", "tile.laz": "laspy", "pointwise.laz": "laspy", "scans.e57": "pye57"}
    for name, module in optional.items():
        if importlib.util.find_spec(module) is not None:
            row = next(line for line in lines if line.startswith(name + " "))
            assert int(row.split()[2]) > 0 and int(row.split()[3]) == 0, row


def _harness():
    import importlib.util

    spec = importlib.util.spec_from_file_location("fuzz_files", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the harness forks a child per file")
def test_fuzz_harness_classifies_failures(tmp_path, monkeypatch):
    """The child's outcome classes, with stand-in readers (the fork inherits the monkeypatch)."""
    import resource
    import signal
    import time

    import numpy as np

    import eppf.io
    from eppf.io import FileFormatError

    fuzz = _harness()
    monkeypatch.setattr(fuzz, "ADDRESS_SPACE", resource.RLIM_INFINITY)  # pytest's own process may be large
    path = str(tmp_path / "f.xyz")
    with open(path, "w") as fh:
        fh.write("1 2 3\n")

    def reader(behaviour):
        def read(p, **kwargs):
            if behaviour == "documented":
                raise FileFormatError(f"read_point_cloud: {p!r}: bad")
            if behaviour == "anonymous":
                raise FileFormatError("bad content")
            if behaviour == "foreign":
                raise KeyError("x")
            if behaviour == "hang":
                time.sleep(30)
            if behaviour == "signal":
                os.kill(os.getpid(), signal.SIGSEGV)
            if behaviour == "memory":
                np.ones(330 * 2 ** 20 // 8)  # 330 MB touched
            return np.zeros((1, 3))
        return read

    expected = {"ok": ("ok", ""), "documented": ("documented", "FileFormatError"),
                "anonymous": ("FAIL", "does not name the file"), "foreign": ("FAIL", "KeyError"),
                "hang": ("FAIL", "hang"), "signal": ("FAIL", "SIGSEGV"), "memory": ("FAIL", "peak RSS grew")}
    for behaviour, (cls, why) in expected.items():
        monkeypatch.setattr(eppf.io, "read_point_cloud", reader(behaviour))
        result = fuzz.read_in_child(path, timeout=0.5 if behaviour == "hang" else 30.0)
        assert result["cls"] == cls and why in result["why"], (behaviour, result)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the harness forks a child per file")
def test_a_child_crashed_on_purpose_prints_no_fault_handler_banner(tmp_path):
    """A crash is an outcome the parent reports: no "Fatal Python error" on stderr, fault handler on or not."""
    path = tmp_path / "f.xyz"
    path.write_text("1 2 3\n")
    code = (
        "import faulthandler, os, signal, sys\n"
        "faulthandler.enable()\n"
        f"sys.path.insert(0, {os.path.dirname(SCRIPT)!r})\n"
        "import fuzz_files, eppf.io\n"
        "eppf.io.read_point_cloud = lambda p, **k: os.kill(os.getpid(), signal.SIGSEGV)\n"
        f"print(fuzz_files.read_in_child({str(path)!r}, timeout=30.0)['why'])\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "SIGSEGV" in run.stdout
    assert "Fatal Python error" not in run.stderr and "Segmentation fault" not in run.stderr
