"""Outputs unchanged by refactoring: fingerprints against those recorded before the package split.

``tests/data/fingerprints.json`` was written by ``tests/fingerprints.py`` on the
flat layout of eppf 0.1.0 (commit 27d57c8); every public computation there must
still give the same bits. A deliberate change of an output is recorded by
re-running ``python tests/fingerprints.py --write tests/data/fingerprints.json``
in the commit that makes it, with the reason in its message.
"""

import json
import os

import pytest

import fingerprints

_REF = os.path.join(os.path.dirname(__file__), "data", "fingerprints.json")

with open(_REF) as fh:
    REFERENCE = json.load(fh)


@pytest.mark.parametrize("group", sorted(fingerprints.GROUPS))
def test_outputs_bit_identical_to_recorded(group):
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


def test_approximate_fingerprint_tolerates_kernel_noise_only():
    ref = fingerprints._approx([[0.2, 0.8]])
    assert fingerprints.matches(fingerprints._approx([[0.2 + 3e-5, 0.8 - 3e-5]]), ref)
    assert not fingerprints.matches(fingerprints._approx([[0.2 + 8e-4, 0.8 - 8e-4]]), ref)
    assert not fingerprints.matches(fingerprints._approx([[0.2, 0.8, 0.0]]), ref)
    assert not fingerprints.matches("a digest", ref)
