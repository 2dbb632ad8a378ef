"""``eppf describe --descriptor NAME`` for every registered descriptor, on the built-in shapes."""

import numpy as np
import pytest

from eppf.cli import main
from eppf.datasets import make_shapes
from eppf.registry import DESCRIPTORS


@pytest.fixture(scope="module")
def shapes_npz(tmp_path_factory):
    bunch = make_shapes(2, n_points=300, classes=["box", "sphere", "cylinder"], random_state=0)
    offsets = np.cumsum([0] + [len(c) for c in bunch.data])
    path = tmp_path_factory.mktemp("shapes") / "shapes.npz"
    np.savez(path, points=np.vstack(bunch.data), offsets=offsets, labels=bunch.target,
             class_names=bunch.target_names)
    return path, bunch


@pytest.mark.parametrize("name", list(DESCRIPTORS))
def test_every_registered_descriptor_runs_through_describe(tmp_path, capsys, shapes_npz, name):
    path, bunch = shapes_npz
    out = tmp_path / "d.npz"
    status = main(["describe", str(path), "-o", str(out), "--descriptor", name, "--n-pairs", "500",
                   "--n-jobs", "1", "--no-progress"])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert "Traceback" not in captured.err
    with np.load(out) as f:
        X, labels, names, descriptor = f["descriptors"], f["labels"], list(f["class_names"]), str(f["descriptor"])
    spec = DESCRIPTORS[name]
    expected = spec.make(n_samples=500, random_state=0, n_jobs=1).fit_transform(bunch.data)
    np.testing.assert_allclose(X, expected, rtol=1e-12, atol=1e-12)
    assert descriptor == name and np.isfinite(X).all() and len(X) == len(bunch.data)
    np.testing.assert_array_equal(labels, bunch.target)
    assert names == list(bunch.target_names)
    # retrieve on this database, by the descriptor's own metric, shows the class names
    status = main(["retrieve", "--database", str(out), "--query-descriptors", str(out), "-k", "1",
                   "--no-progress"])
    table = capsys.readouterr().out.splitlines()[2:]
    assert status == 0 and len(table) == len(X)
    for line, truth in zip(table, bunch.target_names[bunch.target]):
        cells = [c.strip() for c in line.split("|")]
        assert cells[1] == truth and cells[4] == truth and float(cells[5]) == pytest.approx(0, abs=1e-9)
