"""Outputs unchanged by refactoring, on every CPU: fingerprints against recorded ones.

``tests/data/fingerprints.json`` was written by ``tests/fingerprints.py``; every
public computation must still give what it records, compared as its
reproducibility class promises (the documentation's reproducibility page):
eppf's compiled kernels bit for bit, NumPy/BLAS/LAPACK/torch results within
their tolerance, labels exactly. The references hold on every CPU, so CI also
runs this file with the portable kernels forced and NumPy, OpenBLAS and torch
held to AVX2 (``scripts/older_cpu_env.py``). A deliberate change of an output is
recorded by re-running ``python tests/fingerprints.py --write
tests/data/fingerprints.json`` in the commit that makes it, with the reason in
its message.
"""

import json
import os
import platform

import pytest

from tests import fingerprints

_REF = os.path.join(os.path.dirname(__file__), "data", "fingerprints.json")

with open(_REF) as fh:
    REFERENCE = json.load(fh)


@pytest.mark.parametrize("group", sorted(fingerprints.GROUPS))
def test_outputs_bit_identical_to_recorded(group):
    if group == "networks":
        if not fingerprints.networks_compared():
            pytest.skip(f"network probabilities are compared on x86-64 only, not on {platform.machine()}")
        recorded, running = REFERENCE["networks.torch"], fingerprints.torch_release()
        if running != recorded:
            pytest.skip(f"network probabilities were recorded with torch {recorded}, not {running}")
    now = fingerprints.compute([group])
    ref = {k: v for k, v in REFERENCE.items() if k.startswith(group + ".")}
    assert ref, f"no recorded fingerprints for {group}"
    differing = sorted(k for k in ref if not fingerprints.matches(now.get(k), ref[k]))
    assert not differing, f"outputs changed: {differing}"
    assert sorted(now) == sorted(ref)


def test_fingerprint_detects_a_changed_bit():
    import numpy as np

    a = np.arange(5, dtype=float)
    b = a.copy()
    b[2] = np.nextafter(b[2], 10)
    assert fingerprints._digest(a) != fingerprints._digest(b)


def _shapes_descriptors():
    import eppf

    clouds, y, _ = fingerprints._shapes(20)
    return eppf.EPPFTransformer(n_pairs=3000, random_state=0).fit_transform(clouds), clouds


def test_class_b_tolerance_passes_rounding_and_catches_a_real_change():
    import numpy as np

    import eppf

    X, _ = _shapes_descriptors()
    ref = fingerprints._close(eppf.symmetric_kl_distances(X[:8], X[8:]))
    # rounding: the same distances summed in another order (float64 sums of the
    # terms of d(a, b) = sum((a - b)(ln a - ln b)), as another BLAS would)
    floor = 0.5 * X[X > 0].min()
    A, B = np.maximum(X[:8], floor), np.maximum(X[8:], floor)
    other = np.array([[np.sum(((a - b) * (np.log(a) - np.log(b)))[::-1]) for b in B] for a in A])
    assert not np.array_equal(other, eppf.symmetric_kl_distances(X[:8], X[8:]))
    assert fingerprints.matches(fingerprints._close(other), ref)
    # a real change: one pair of one object moved to a neighbouring bin
    moved = X.copy()
    k = np.flatnonzero(moved[0])[0]
    moved[0, k] -= 1.0 / 3000
    moved[0, k + 1] += 1.0 / 3000
    assert not fingerprints.matches(fingerprints._close(eppf.symmetric_kl_distances(moved[:8], moved[8:])), ref)


def test_class_b_fingerprint_of_a_large_output_catches_a_change_anywhere():
    import numpy as np

    from eppf import preprocessing

    _, clouds = _shapes_descriptors()
    out = np.vstack(preprocessing.RandomRotation(random_state=0).fit_transform(clouds[:4]))
    ref = fingerprints._close(out)
    assert "sums" in ref  # large: probes and weighted sums, not every value
    jitter = out * (1 + 1e-15 * np.sign(np.sin(np.arange(out.size))).reshape(out.shape))
    assert fingerprints.matches(fingerprints._close(jitter), ref)
    # one coordinate of one point, not one of the probed places, moved by 1e-6
    probed = set(np.linspace(0, out.size - 1, fingerprints.N_PROBES).astype(int).tolist())
    i = next(i for i in range(1, out.size) if i not in probed)
    changed = out.copy().ravel()
    changed[i] += 1e-6
    assert not fingerprints.matches(fingerprints._close(changed.reshape(out.shape)), ref)
    # another rotation of the same clouds
    other = np.vstack(preprocessing.RandomRotation(random_state=1).fit_transform(clouds[:4]))
    assert not fingerprints.matches(fingerprints._close(other), ref)
    assert not fingerprints.matches(fingerprints._close(out[:-1]), ref)


def test_regions_fingerprint_catches_another_descriptor():
    import numpy as np

    import eppf

    _, clouds = _shapes_descriptors()
    X = eppf.OURCVFHTransformer().fit_transform(clouds[:6])
    ref = fingerprints._regions(X)
    assert fingerprints.matches(fingerprints._regions(X + 1e-4 * (np.arange(X.shape[1]) % 2)), ref)
    assert not fingerprints.matches(fingerprints._regions(X[::-1]), ref)  # each object given another's
    assert not fingerprints.matches(fingerprints._regions(eppf.VFHTransformer().fit_transform(
        [np.hstack([c, eppf.estimate_normals(c)]) for c in clouds[:6]])), ref)


def test_approximate_fingerprint_tolerates_kernel_noise_only():
    ref = fingerprints._approx([[0.2, 0.8]])
    assert fingerprints.matches(fingerprints._approx([[0.2 + 3e-5, 0.8 - 3e-5]]), ref)
    assert not fingerprints.matches(fingerprints._approx([[0.2 + 8e-4, 0.8 - 8e-4]]), ref)
    assert not fingerprints.matches(fingerprints._approx([[0.2, 0.8, 0.0]]), ref)
    assert not fingerprints.matches("a digest", ref)


@pytest.mark.parametrize("machine", ["x86_64", "aarch64"])
def test_check_compares_the_networks_where_they_are_promised(monkeypatch, capsys, tmp_path, machine):
    # `fingerprints.py --check` (scripts/check_arm64.sh runs it) follows the same promise as the test above:
    # a network fingerprint that differs fails the check on x86-64 and is listed as not compared elsewhere;
    # any other output that differs fails it everywhere.
    ref = {"descriptors.a": "d1", "networks.p": {"values": [0.5], "atol": 1e-4}}
    path = tmp_path / "ref.json"
    path.write_text(json.dumps(ref))
    monkeypatch.setattr(fingerprints.platform, "machine", lambda: machine)
    monkeypatch.setattr(fingerprints, "compute", lambda: {"descriptors.a": "d1", "networks.p": {"values": [0.9]}})
    status = fingerprints.main(["--check", str(path)])
    out = capsys.readouterr().out
    if machine == "x86_64":
        assert status == 1 and "differs: networks.p" in out and "1 of 2 fingerprints equal" in out
    else:
        assert status == 0 and "differs" not in out and "1 of 1 fingerprints equal" in out
        assert "not compared on aarch64: networks.p" in out
    monkeypatch.setattr(fingerprints, "compute", lambda: {"descriptors.a": "d2", "networks.p": {"values": [0.5]}})
    assert fingerprints.main(["--check", str(path)]) == 1
    assert "differs: descriptors.a" in capsys.readouterr().out
