"""Ctrl-C: ``eppf`` stops promptly with one line and exit status 130."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eppf.utils._chunks import CHUNK, CHUNK_POINTS, _chunk_bounds

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a child process is POSIX")
def test_sigint_exits_130_with_one_line():
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    # many descriptor draws: the job is still computing when the signal comes
    # A suite started in the background by a non-interactive shell inherits SIGINT ignored, and so would the child
    # (Python then installs no KeyboardInterrupt handler): give the child the default disposition, as a terminal would.
    proc = subprocess.Popen([sys.executable, "-m", "eppf", "--no-progress", "--repeats", "500", "--n-jobs", "1"],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        first = proc.stdout.readline()  # printed once the data are loaded, before any descriptor
        assert "built-in synthetic shapes" in first
        time.sleep(0.5)
        assert proc.poll() is None
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        latency = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130
    assert err.strip().splitlines() == ["eppf: interrupted"]
    assert "Traceback" not in out
    assert latency < 5.0  # the kernels hand control back between chunks


#: A ``sitecustomize`` that makes one import raise KeyboardInterrupt, as a Ctrl-C during it would.
_INTERRUPT_AT_IMPORT = """
import sys

class _CtrlC:
    def find_spec(self, name, path=None, target=None):
        if name == {name!r}:
            raise KeyboardInterrupt
        return None

sys.meta_path.insert(0, _CtrlC())
"""

#: What pip's console script of ``eppf = "eppf.cli:main"`` runs.
_CONSOLE_SCRIPT = """import re
import sys
from eppf.cli import main
if __name__ == "__main__":
    sys.argv[0] = re.sub(r"(-script\\.pyw|\\.exe)?$", "", sys.argv[0])
    sys.exit(main())
"""


def _interrupted_at_import(tmp_path, module, argv):
    (tmp_path / "sitecustomize.py").write_text(_INTERRUPT_AT_IMPORT.format(name=module))
    script = tmp_path / "eppf"
    script.write_text(_CONSOLE_SCRIPT)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), str(ROOT)]))
    argv = [str(script) if a == "SCRIPT" else a for a in argv]
    return subprocess.run([sys.executable, *argv], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=60)


@pytest.mark.parametrize("module, argv", [
    ("sklearn", ["-m", "eppf", "--version"]),   # while eppf itself imports (most of the first second)
    ("sklearn", ["SCRIPT", "--version"]),       # the same, from the installed eppf script
    ("eppf.registry", ["SCRIPT", "--version"]),  # while eppf.cli imports, before main() runs
])
def test_ctrl_c_while_the_command_imports_is_one_line_and_130(tmp_path, module, argv):
    proc = _interrupted_at_import(tmp_path, module, argv)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.splitlines() == ["eppf: interrupted"]
    assert proc.stdout == ""


def test_ctrl_c_while_a_program_imports_eppf_is_its_keyboard_interrupt(tmp_path):
    proc = _interrupted_at_import(tmp_path, "sklearn", ["-c", "import eppf"])
    assert "KeyboardInterrupt" in proc.stderr and "eppf: interrupted" not in proc.stderr


@pytest.mark.parametrize("spec, argv, orig_argv, expected", [
    (None, ["/usr/bin/eppf", "--version"], None, True),                  # pip's console script
    ("__main__", ["/venv/Scripts/eppf.exe"], None, True),                # Windows: the .exe zip's __main__
    (None, ["/venv/Scripts/eppf-script.py"], None, True),
    ("eppf.__main__", ["/src/eppf/__main__.py"], None, True),            # python -m eppf, running
    (None, ["-m"], ["python", "-X", "dev", "-m", "eppf", "run"], True),  # python -m eppf, importing eppf
    (None, ["-m"], ["python", "-m", "pytest"], False),
    ("pytest.__main__", ["/venv/bin/eppf"], None, False),
    (None, ["/home/me/analysis.py"], None, False),
    (None, ["-c"], None, False),
    (None, [""], None, False),                                           # the interactive interpreter
])
def test_is_eppf_command(monkeypatch, spec, argv, orig_argv, expected):
    import types
    from importlib.machinery import ModuleSpec

    from eppf._command import is_eppf_command

    main = types.ModuleType("__main__")
    main.__spec__ = None if spec is None else ModuleSpec(spec, None)
    monkeypatch.setitem(sys.modules, "__main__", main)
    monkeypatch.setattr(sys, "argv", argv)
    monkeypatch.setattr(sys, "orig_argv", orig_argv or ["python", *argv], raising=False)
    assert is_eppf_command() is expected


def test_command_interrupt_guard(monkeypatch, capsys):
    import eppf._command as command

    monkeypatch.setattr(command, "is_eppf_command", lambda: True)
    with pytest.raises(SystemExit) as exc:
        with command.command_interrupt_guard():
            raise KeyboardInterrupt
    assert exc.value.code == 130 and capsys.readouterr().err == "eppf: interrupted\n"
    monkeypatch.setattr(command, "is_eppf_command", lambda: False)
    with pytest.raises(KeyboardInterrupt):
        with command.command_interrupt_guard():
            raise KeyboardInterrupt
    assert capsys.readouterr().err == ""


def test_chunks_are_bounded_in_objects_and_points():
    sizes = [10, 70_000, 5, 5, 30_000, 30_000, 10_000] + [3] * 600
    clouds = [range(s) for s in sizes]
    chunks = _chunk_bounds(clouds, CHUNK, CHUNK_POINTS)
    assert chunks[0][0] == 0 and chunks[-1][1] == len(clouds)
    assert all(a[1] == b[0] for a, b in zip(chunks[:-1], chunks[1:]))  # contiguous, in order
    for lo, hi in chunks:
        assert 1 <= hi - lo <= CHUNK
        assert hi - lo == 1 or sum(sizes[lo:hi]) <= CHUNK_POINTS
    assert (1, 2) in chunks  # a cloud above the bound is a chunk of its own
    # greedy: no chunk could take the next cloud without breaking a bound
    for (lo, hi), _ in zip(chunks[:-1], chunks[1:]):
        assert hi - lo == CHUNK or sum(sizes[lo:hi + 1]) > CHUNK_POINTS
    assert _chunk_bounds([], CHUNK, CHUNK_POINTS) == []


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_point_bound_grows_with_the_threads(monkeypatch, n_jobs):
    import numpy as np

    import eppf.utils._chunks as chunks_module
    from eppf import EPPFTransformer

    seen = []
    real = chunks_module._chunk_bounds

    def spy(clouds, chunk, chunk_points):
        seen.append(chunk_points)
        return real(clouds, chunk, chunk_points)

    monkeypatch.setattr(chunks_module, "_chunk_bounds", spy)
    clouds = [np.random.default_rng(k).normal(size=(50, 3)) for k in range(3)]
    EPPFTransformer(n_pairs=100, random_state=0, n_jobs=n_jobs).fit_transform(clouds)
    assert seen == [CHUNK_POINTS * n_jobs]
