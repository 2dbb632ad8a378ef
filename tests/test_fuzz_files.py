"""The file fuzz harness (scripts/fuzz_files.py --short): about 200 mutated files of every
format, each read in a forked child under a 4 GiB address-space limit; every outcome must be
a successful read or a FileFormatError/OSError naming the file, with bounded memory and time."""

import os
import subprocess
import sys

import pytest

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "fuzz_files.py")


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
