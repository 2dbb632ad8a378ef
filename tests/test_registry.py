"""Tests of eppf/registry.py: building registered descriptors by name."""

import re

import pytest

from eppf.registry import DESCRIPTORS, make_descriptor


def test_make_passes_shared_settings_only_where_they_apply():
    esf = DESCRIPTORS["esf"].make(n_samples=300, scaling="object", random_state=1, n_jobs=1, verbose=1)
    assert esf.get_params()["n_triplets"] == 300 and esf.get_params()["random_state"] == 1
    assert "verbose" not in esf.get_params() and "scaling" not in esf.get_params()
    eppf = DESCRIPTORS["eppf"].make(n_samples=300, scaling="object", verbose=1, functions=("distance",))
    assert (eppf.n_pairs, eppf.scaling, eppf.verbose, eppf.functions) == (300, "object", 1, ("distance",))


def test_make_refuses_unknown_and_fixed_settings():
    with pytest.raises(ValueError, match=re.escape("descriptor 'esf': ESFTransformer has no parameter(s) "
                                                   "n_neighbors, n_pairs; its parameters are")):
        DESCRIPTORS["esf"].make(n_pairs=10, n_neighbors=5)
    with pytest.raises(ValueError, match=re.escape("descriptor 'eppf_short': n_bins is fixed by the entry "
                                                   "(n_bins=(15, 3, 4, 3))")):
        make_descriptor("eppf_short", n_bins=(20, 4, 5, 3))
