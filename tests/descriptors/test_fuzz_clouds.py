"""The short run of ``scripts/fuzz_clouds.py``: no crash, hang or silent NaN on adversarial clouds."""

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCRIPT = os.path.join(ROOT, "scripts", "fuzz_clouds.py")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the fuzz harness forks a child per case")
def test_short_fuzz_run_has_no_failure():
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    res = subprocess.run([sys.executable, SCRIPT, "--short"], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-4000:]
    lines = res.stdout.splitlines()
    n_cases = int(lines[0].split()[0])
    assert n_cases >= 200
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    try:
        import fuzz_clouds
    finally:
        sys.path.pop(0)
    names = fuzz_clouds.ESTIMATORS  # every registered descriptor and estimate_normals
    assert len(names) >= 10 and names[-1] == "estimate_normals"
    table = {ln.split()[0]: [int(v) for v in ln.split()[1:]] for ln in lines[2:2 + len(names)]}
    for name in names:
        ok, clean, fail = table[name]
        assert fail == 0 and ok + clean == n_cases
        assert ok >= 50 and clean >= 25  # both outcomes are exercised: the cases are neither all easy nor all invalid


def test_fuzz_harness_reports_a_crash_as_a_failure(monkeypatch):
    # the harness itself must turn a signal in the child into FAIL, not pass over it
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    try:
        import fuzz_clouds
    finally:
        sys.path.pop(0)

    def crash(name, clouds, rng):
        if name == "ESFTransformer":
            import faulthandler

            faulthandler.disable()  # (no traceback on the test's output)
            os.kill(os.getpid(), 11)
        if name == "WahlTransformer":
            return "FAIL", "non-finite output"
        return "ok", ""

    monkeypatch.setattr(fuzz_clouds, "run_one", crash)
    results = fuzz_clouds.run_case(0, 3, timeout=30)
    status = [r[0] for r in results]
    assert status == ["ok", "FAIL", "FAIL"] + ["ok"] * (len(fuzz_clouds.ESTIMATORS) - 3)
    assert "signal 11" in results[1][1]
