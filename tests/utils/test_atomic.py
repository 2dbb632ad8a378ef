"""atomic_write: a file is replaced only by a complete new one."""

import errno
import os
import stat

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import eppf.utils._atomic as atomic_module
from eppf import KLNearestNeighbors, load_model, save_model
from eppf.utils._atomic import atomic_write
from eppf.cli import main


class _FailingFile:
    """A file whose writes fail once ``limit`` bytes have gone through."""

    def __init__(self, real, limit, exc):
        self._real, self._limit, self._exc, self.written = real, limit, exc, 0

    def write(self, data):
        room = self._limit - self.written
        if len(data) > room:
            self._real.write(data[:max(room, 0)])
            self.written = self._limit
            raise self._exc
        self.written += len(data)
        return self._real.write(data)

    def __getattr__(self, name):
        return getattr(self._real, name)


def _fail_after(monkeypatch, limit, exc):
    real_fdopen = os.fdopen
    opened = []

    def fdopen(fd, mode, **kwargs):
        opened.append(_FailingFile(real_fdopen(fd, mode, **kwargs), limit, exc))
        return opened[-1]

    monkeypatch.setattr(atomic_module, "_fdopen", fdopen)
    return opened


def _enospc():
    return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_successful_write_replaces_and_keeps_permissions(tmp_path):
    path = tmp_path / "out.bin"
    path.write_bytes(b"old")
    os.chmod(path, 0o640)
    with atomic_write(path) as fh:
        fh.write(b"new contents")
    assert path.read_bytes() == b"new contents"
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o640
    assert os.listdir(tmp_path) == ["out.bin"]
    fresh = tmp_path / "fresh.txt"
    with atomic_write(fresh, "w", newline="") as fh:
        fh.write("a\r\nb")
    assert fresh.read_bytes() == b"a\r\nb"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(os.stat(fresh).st_mode) == 0o666 & ~mask


@pytest.mark.parametrize("exc", [RuntimeError("writer bug"), KeyboardInterrupt(), _enospc()],
                         ids=["error", "ctrl-c", "enospc"])
def test_failure_mid_write_leaves_old_file_and_no_temp(tmp_path, exc):
    path = tmp_path / "out.bin"
    path.write_bytes(b"old contents")
    with pytest.raises(type(exc)):
        with atomic_write(path) as fh:
            fh.write(b"x" * 5000)
            raise exc
    assert path.read_bytes() == b"old contents"
    assert os.listdir(tmp_path) == ["out.bin"]


def test_full_disk_while_saving_a_model_keeps_the_old_model(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    X = rng.random((30, 40))
    path = tmp_path / "m.eppf"
    good = KLNearestNeighbors().fit(X, np.arange(30) % 2)
    save_model(good, path)
    before = path.read_bytes()
    opened = _fail_after(monkeypatch, 3000, _enospc())
    with pytest.raises(OSError) as info:
        save_model(KLNearestNeighbors().fit(X[::-1], np.arange(30) % 3), path)
    assert info.value.errno == errno.ENOSPC
    assert opened and opened[0].written == 3000  # it did fail part way through the file
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["m.eppf"]
    monkeypatch.undo()
    assert_array_equal(load_model(path).predict(X), good.predict(X))


@pytest.mark.parametrize("output", ["out.npz", "out.npy"])
def test_full_disk_in_cli_describe_keeps_old_output(tmp_path, monkeypatch, capsys, output):
    cloud = tmp_path / "c.xyz"
    np.savetxt(cloud, np.random.default_rng(1).normal(size=(60, 3)))
    out = tmp_path / output
    argv = ["describe", str(cloud), "-o", str(out), "--n-pairs", "500", "--n-jobs", "1", "--no-progress"]
    assert main(argv) == 0
    before = out.read_bytes()
    _fail_after(monkeypatch, 300, _enospc())
    capsys.readouterr()
    assert main(argv + ["--random-state", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left" in err[0]
    assert out.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == sorted(["c.xyz", output])


def test_csv_output_is_atomic(tmp_path, monkeypatch, capsys):
    from eppf.cli._common import emit as _emit

    path = tmp_path / "rows.csv"
    path.write_text("old\n")
    _fail_after(monkeypatch, 10, _enospc())
    with pytest.raises(OSError):
        _emit([("a", 1, 0.5)] * 100, ["x", "y", "z"], str(path), None)
    assert path.read_text() == "old\n" and os.listdir(tmp_path) == ["rows.csv"]
    monkeypatch.undo()
    import io

    _emit([("a", 1, 0.5)], ["x", "y", "z"], str(path), io.StringIO())
    assert path.read_text().splitlines() == ["x,y,z", "a,1,0.5"]


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="mode must be"):
        with atomic_write(tmp_path / "x", "a"):
            pass
    with pytest.raises(FileNotFoundError, match="no such folder"):
        with atomic_write(tmp_path / "missing" / "x"):
            pass
