"""Descriptor computation in chunks through joblib: locally and on a dask cluster."""

import numpy as np
import pytest
from joblib import parallel_config
from numpy.testing import assert_array_equal

import eppf.utils._chunks as chunks_module
from eppf import EPPFTransformer, ESFTransformer
from eppf.descriptors import GASDColorTransformer
from eppf.registry import DESCRIPTORS, make_descriptor


def _clouds(n=12):
    rng = np.random.default_rng(0)
    return [rng.normal(size=(rng.integers(30, 120), 3)) * rng.uniform(0.5, 2.0) for _ in range(n)]


def _make(name):
    """Every registered descriptor, with few samples per object (2,000 pairs or triplets)."""
    return make_descriptor(name, n_samples=2000, random_state=7, n_jobs=1)


@pytest.mark.parametrize("name", list(DESCRIPTORS))
@pytest.mark.parametrize("backend", ["threading", "loky"])
def test_chunked_joblib_run_is_bit_identical(monkeypatch, backend, name):
    clouds = _clouds()
    est = _make(name).fit(clouds)
    whole = est.transform(clouds)
    monkeypatch.setattr(chunks_module, "CHUNK", 5)  # several chunks of uneven length
    with parallel_config(backend=backend, n_jobs=2):
        chunked = est.transform(clouds)
    assert_array_equal(whole, chunked)


def test_chunked_colour_gasd_is_bit_identical(monkeypatch):
    # The one descriptor with extra per-point columns (RGB): they are sliced with their clouds.
    rng = np.random.default_rng(3)
    clouds = [np.hstack([c, rng.integers(0, 256, size=(len(c), 3))]) for c in _clouds()]
    est = GASDColorTransformer(n_jobs=1).fit(clouds)
    whole = est.transform(clouds)
    # Each row depends on its own cloud's colours only.
    assert_array_equal(est.transform(clouds[3:5]), whole[3:5])
    monkeypatch.setattr(chunks_module, "CHUNK", 5)
    with parallel_config(backend="loky", n_jobs=2):
        chunked = est.transform(clouds)
    assert_array_equal(whole, chunked)


def test_progress_bar_does_not_change_output(monkeypatch):
    clouds = _clouds(6)
    monkeypatch.setattr(chunks_module, "CHUNK", 4)
    quiet = EPPFTransformer(n_pairs=500, random_state=1).fit_transform(clouds)
    loud = EPPFTransformer(n_pairs=500, random_state=1, verbose=1).fit_transform(clouds)
    assert_array_equal(quiet, loud)


@pytest.mark.parametrize("name", ["eppf", "esf"])
def test_dask_local_cluster_matches_local_run(monkeypatch, name):
    distributed = pytest.importorskip("dask.distributed")
    clouds = _clouds()
    est = _make(name).fit(clouds)
    local = est.transform(clouds)
    monkeypatch.setattr(chunks_module, "CHUNK", 4)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster):
        with parallel_config(backend="dask"):
            remote = est.transform(clouds)
    assert_array_equal(local, remote)


def test_error_in_a_later_chunk_names_the_global_index(monkeypatch):
    import re

    clouds = _clouds(7)
    clouds[6] = np.vstack([np.zeros((3, 3)), [[1.0, 1.0, 1.0]] * 2])
    clouds[6][:, :] = np.linspace(0, 1, 5)[:, None]  # five collinear points: no ESF triangle
    monkeypatch.setattr(chunks_module, "CHUNK", 3)
    with pytest.raises(ValueError, match=re.escape("ESFTransformer: point cloud 6 has no triangles")):
        ESFTransformer(n_triplets=100, random_state=0).fit_transform(clouds)


@pytest.mark.parametrize("name", list(DESCRIPTORS))
def test_point_bounded_chunks_give_the_same_descriptors(monkeypatch, name):
    clouds = _clouds()
    est = _make(name).fit(clouds)
    whole = est.transform(clouds)
    monkeypatch.setattr(chunks_module, "CHUNK_POINTS", 150)  # one to three clouds per chunk
    assert len(chunks_module._chunk_bounds(clouds, chunks_module.CHUNK, 150)) > len(clouds) // 3
    assert_array_equal(est.transform(clouds), whole)
