"""The Sphinx documentation builds without a single warning."""

import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.mark.skipif(not (DOCS / "conf.py").exists(), reason="docs/ not present")
def test_docs_build_without_warnings(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("numpydoc")
    pytest.importorskip("sphinx_gallery")
    pytest.importorskip("matplotlib")
    # -E: read every source afresh; -W: warnings are errors. The dummy builder
    # reads and resolves everything (autosummary, numpydoc, cross-references)
    # but writes no HTML, which keeps the test fast; the gallery examples run.
    cmd = [
        sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q",
        "-b", "dummy", "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "out"),
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "WARNING" not in result.stderr, result.stderr
