"""Descriptor computation in chunks through joblib: locally and on a dask cluster."""

import numpy as np
import pytest
from joblib import parallel_config
from numpy.testing import assert_array_equal

import eppf._descriptor as descriptor_module
from eppf import EPPFTransformer


def _clouds(n=12):
    rng = np.random.default_rng(0)
    return [rng.normal(size=(rng.integers(30, 120), 3)) * rng.uniform(0.5, 2.0) for _ in range(n)]


@pytest.mark.parametrize("backend", ["threading", "loky"])
def test_chunked_joblib_run_is_bit_identical(monkeypatch, backend):
    clouds = _clouds()
    est = EPPFTransformer(n_pairs=2000, random_state=7, n_jobs=1).fit(clouds)
    whole = est.transform(clouds)
    monkeypatch.setattr(descriptor_module, "_CHUNK", 5)  # several chunks of uneven length
    with parallel_config(backend=backend, n_jobs=2):
        chunked = est.transform(clouds)
    assert_array_equal(whole, chunked)


def test_progress_bar_does_not_change_output(monkeypatch):
    clouds = _clouds(6)
    monkeypatch.setattr(descriptor_module, "_CHUNK", 4)
    quiet = EPPFTransformer(n_pairs=500, random_state=1).fit_transform(clouds)
    loud = EPPFTransformer(n_pairs=500, random_state=1, verbose=1).fit_transform(clouds)
    assert_array_equal(quiet, loud)


def test_dask_local_cluster_matches_local_run(monkeypatch):
    distributed = pytest.importorskip("dask.distributed")
    clouds = _clouds()
    est = EPPFTransformer(n_pairs=2000, random_state=3, n_jobs=1).fit(clouds)
    local = est.transform(clouds)
    monkeypatch.setattr(descriptor_module, "_CHUNK", 4)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster):
        with parallel_config(backend="dask"):
            remote = est.transform(clouds)
    assert_array_equal(local, remote)
