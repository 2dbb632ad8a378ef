"""The EPPF_SIMD switch: each value caps every kernel's SIMD level; anything else is an error."""

import json
import os
import subprocess
import sys

import pytest

import eppf
from eppf.utils._simd import SIMD_CAPS, simd_cap

_ORDER = {"eppf": ("scalar", "avx2", "avx512-grouped", "avx512-skipping"),
          "normals": ("scalar", "avx2", "avx512"), "esf": ("scalar", "avx2")}


def _levels_with(value):
    env = dict(os.environ)
    env.pop("EPPF_SIMD", None)
    if value is not None:
        env["EPPF_SIMD"] = value
    code = "import json, eppf; print(json.dumps(eppf.simd_levels()))"
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)


def test_simd_levels_names_every_kernel():
    levels = eppf.simd_levels()
    assert set(levels) == {"machine", "EPPF_SIMD", "eppf", "normals", "esf"}
    for kernel, names in _ORDER.items():
        assert levels[kernel] in names


@pytest.mark.parametrize("cap", SIMD_CAPS)
def test_each_cap_limits_every_kernel(cap):
    full = json.loads(_levels_with(None).stdout)
    run = _levels_with(cap)
    assert run.returncode == 0, run.stderr
    capped = json.loads(run.stdout)
    assert capped["EPPF_SIMD"] == cap
    for kernel, names in _ORDER.items():
        rank = names.index(capped[kernel])
        assert rank <= names.index(full[kernel])  # never more than the CPU runs
        if cap == "scalar":
            assert capped[kernel] == "scalar"
        elif cap == "avx2":
            assert not capped[kernel].startswith("avx512")
        else:
            assert capped[kernel] == full[kernel]  # avx512 caps nothing


@pytest.mark.parametrize("value", ["sse", "AVX2", "none", " scalar"])
def test_an_unknown_cap_is_an_error_at_import(value):
    run = _levels_with(value)
    assert run.returncode != 0
    assert "EPPF_SIMD must be one of 'scalar', 'avx2', 'avx512' or unset" in run.stderr
    assert repr(value) in run.stderr


def test_simd_cap_reads_the_environment(monkeypatch):
    monkeypatch.delenv("EPPF_SIMD", raising=False)
    assert simd_cap() is None
    monkeypatch.setenv("EPPF_SIMD", "")
    assert simd_cap() is None
    monkeypatch.setenv("EPPF_SIMD", "avx2")
    assert simd_cap() == "avx2"
    monkeypatch.setenv("EPPF_SIMD", "avx-512")
    with pytest.raises(ValueError, match="EPPF_SIMD must be one of"):
        simd_cap()
