"""Fixtures of the io tests: a random cloud and a file written from text or bytes."""

import numpy as np
import pytest


def _cloud(n=40, normals=True, seed=0):
    rng = np.random.RandomState(seed)
    xyz = rng.uniform(-2, 3, size=(n, 3))
    if not normals:
        return xyz
    nrm = rng.normal(size=(n, 3))
    return np.hstack([xyz, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)])


def _write(path, text, mode="w"):
    with open(path, mode) as fh:
        fh.write(text)
    return str(path)


@pytest.fixture
def make_cloud():
    """``make_cloud(n=40, normals=True, seed=0)``: ``n`` points in [-2, 3)^3, with unit normals unless ``normals=False``."""
    return _cloud


@pytest.fixture
def write_file():
    """``write_file(path, text, mode="w")``: write ``text`` (bytes with ``mode="wb"``) to ``path``; return it as a str."""
    return _write
