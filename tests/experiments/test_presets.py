"""Tests of the ModelNet40 presets: what they do to the clouds, their errors, and both commands end to end."""

import csv
import os
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.optimize import linprog

from eppf import EPPFTransformer, KLNearestNeighbors
from eppf.cli._experiment import run_experiment
from eppf.datasets import save_npz
from eppf.experiments import (
    PRESETS,
    ExperimentError,
    Preset,
    apply_preset,
    get_preset,
    load_data,
    run_classification,
    run_noise,
)
from eppf.experiments._common import draw_seeds
from eppf.metrics import retrieval_scores

from . import experiment_main as main

N = 1024


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """A small synthetic set (10 classes, 3 objects each, 20 train / 10 test) with more points than the presets keep."""
    data = load_data("builtin", n_per_class=3, n_points=1100, random_state=0)
    path = tmp_path_factory.mktemp("presets") / "syn.npz"
    save_npz(path, data.clouds, data.y, data.target_names, split=data.split)
    return str(path)


@pytest.fixture(scope="module")
def raw(synthetic):
    return load_data(synthetic)


@pytest.fixture
def no_plots(monkeypatch):
    """The reports without their PNG (the plots are tested elsewhere and cost seconds here)."""
    monkeypatch.setitem(sys.modules, "matplotlib", None)


def rows_of(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def row_set(cloud):
    return {tuple(r) for r in np.asarray(cloud).tolist()}


def test_the_presets():
    assert list(PRESETS) == ["modelnet40-clean", "modelnet40-noise-0.07", "modelnet40-noise-0.10",
                             "modelnet40-noise-0.15", "modelnet40-occluded"]
    assert all(p.n_points == N for p in PRESETS.values())
    assert [p.noise for p in PRESETS.values()] == [0.0, 0.07, 0.1, 0.15, 0.0]
    assert [p.occlusion for p in PRESETS.values()] == [0.0, 0.0, 0.0, 0.0, 0.5]
    assert PRESETS["modelnet40-noise-0.07"].noise_levels == (0.0, 0.07)
    assert PRESETS["modelnet40-clean"].noise_levels == PRESETS["modelnet40-occluded"].noise_levels == (0, 0.07, 0.1, 0.15)
    assert get_preset("modelnet40-clean") is PRESETS["modelnet40-clean"]
    custom = Preset("mine", "one line", n_points=100, noise=0.2)
    assert get_preset(custom) is custom


@pytest.mark.parametrize("name", ["nope", "modelnet40-noise-0.1", None, 3])
def test_unknown_preset(name, raw):
    with pytest.raises(ExperimentError, match="unknown preset .*; choose from modelnet40-clean, modelnet40-noise-0.07"):
        apply_preset(raw, name)


def test_clean_draws_distinct_points_of_every_object(raw):
    out = apply_preset(raw, "modelnet40-clean", random_state=0)
    assert len(out.clouds) == len(raw.clouds)
    for before, after in zip(raw.clouds, out.clouds):
        assert after.shape == (N, 3) and after.dtype == np.float64
        kept = row_set(after)
        assert len(kept) == N and kept <= row_set(before)  # a subset without repeats
    assert_array_equal(out.split, raw.split)
    assert_array_equal(out.y, raw.y)
    assert raw.clouds[0].shape == (1100, 3)  # the input is not modified
    assert "preset `modelnet40-clean`" in out.source and "no perturbation" in out.source
    # the comparison with the paper's ModelNet40 is written down
    assert "40 classes, 9,843 training / 2,468 test" in out.source and "this data set 10, 20 / 10" in out.source


def test_deterministic_under_random_state(raw):
    for name in PRESETS:
        a = apply_preset(raw, name, random_state=5)
        b = apply_preset(raw, name, random_state=5)
        c = apply_preset(raw, name, random_state=6)
        assert all(np.array_equal(x, y) for x, y in zip(a.clouds, b.clouds))
        assert not any(np.array_equal(x, y) for x, y in zip(a.clouds, c.clouds))


@pytest.mark.parametrize("sigma", [0.07, 0.10, 0.15])
def test_noise_is_sigma_times_the_largest_side_on_train_and_test(raw, sigma):
    clean = apply_preset(raw, "modelnet40-clean", random_state=1)
    noisy = apply_preset(raw, f"modelnet40-noise-{sigma:.2f}", random_state=1)
    # the same points are drawn, then moved: the residual is the noise, in units of each object's largest side
    z = {part: [] for part in ("train", "test")}
    for k, (c, n) in enumerate(zip(clean.clouds, noisy.clouds)):
        side = np.ptp(c, axis=0).max()
        z[raw.split[k]].append(((n - c) / side).ravel())
    for part, values in z.items():
        values = np.concatenate(values)  # 3 * 1024 draws per object
        assert abs(values.mean()) < 4 * sigma / np.sqrt(values.size)
        assert_allclose(values.std(), sigma, rtol=0.03), part
    # without the noise (what the noise experiment starts from) the clouds are the clean ones
    base = apply_preset(raw, f"modelnet40-noise-{sigma:.2f}", random_state=1, noise=False)
    assert all(np.array_equal(x, y) for x, y in zip(base.clouds, clean.clouds))
    assert "left to the noise experiment" in base.source


def _separable(kept, removed):
    """Whether a plane has all kept points on one side and all removed ones on the other (an LP feasibility)."""
    # find w, b with w.k - b >= 1 and w.r - b <= -1
    a = np.vstack([np.hstack([-kept, np.ones((len(kept), 1))]), np.hstack([removed, -np.ones((len(removed), 1))])])
    res = linprog(np.zeros(4), A_ub=a, b_ub=-np.ones(len(a)), bounds=[(None, None)] * 4, method="highs")
    return res.status == 0


def test_occluded_removes_one_side_of_a_plane_on_train_and_test(raw):
    clean = apply_preset(raw, "modelnet40-clean", random_state=2)
    occluded = apply_preset(raw, "modelnet40-occluded", random_state=2)
    parts = set()
    for k, (c, o) in enumerate(zip(clean.clouds, occluded.clouds)):
        assert o.shape == (N // 2, 3)
        kept = row_set(o)
        assert kept <= row_set(c)
        mask = np.array([tuple(r) in kept for r in c.tolist()])
        assert _separable(c[mask], c[~mask])
        parts.add(raw.split[k])
    assert parts == {"train", "test"}
    # the check can fail: a random half of the points is not cut off by a plane
    c = clean.clouds[0]
    rand = np.random.default_rng(0).permutation(N) < N // 2
    assert not _separable(c[rand], c[~rand])


def test_data_the_presets_cannot_apply_to(raw, tmp_path):
    # no split of its own: the made-up 70/30 split is not the paper's
    path = tmp_path / "nosplit.npz"
    save_npz(path, raw.clouds, raw.y, raw.target_names)
    with pytest.raises(ExperimentError, match="has no train/test split of its own"):
        apply_preset(load_data(path), "modelnet40-clean")
    # too few points: named object, count and class
    clouds = list(raw.clouds)
    clouds[4] = clouds[4][:700]
    path = tmp_path / "short.npz"
    save_npz(path, clouds, raw.y, raw.target_names, split=raw.split)
    with pytest.raises(ExperimentError, match=r"at least 1024 points per object, but 1 of the 30 objects of 'short' "
                                              r"have fewer \(object 4, class '.+', has 700\)"):
        apply_preset(load_data(path), "modelnet40-noise-0.10")
    # only training objects
    only_train = load_data(path)
    only_train.split[:] = "train"
    with pytest.raises(ExperimentError, match="needs training and test objects, got 30 and 0"):
        apply_preset(only_train, "modelnet40-clean")
    with pytest.raises(ExperimentError, match="data must be a Dataset"):
        apply_preset(raw.clouds, "modelnet40-clean")
    with pytest.raises(ExperimentError, match="--random-state must be an int, got 0.5"):
        apply_preset(raw, "modelnet40-clean", random_state=0.5)


def test_a_folder_of_objects_takes_a_preset(raw, tmp_path):
    for k, cloud in enumerate(raw.clouds[:12]):
        folder = tmp_path / "objs" / raw.split[k] / str(raw.target_names[raw.y[k]])
        folder.mkdir(parents=True, exist_ok=True)
        np.savetxt(folder / f"{k}.xyz", cloud)
    data = load_data(tmp_path / "objs")
    out = apply_preset(data, "modelnet40-occluded", random_state=0)
    assert "the folder's split" in out.split_source and "preset `modelnet40-occluded`" in out.source
    assert all(c.shape == (N // 2, 3) for c in out.clouds)
    assert_array_equal(out.split, data.split)


def test_classification_command_with_a_noise_preset(synthetic, raw, tmp_path, no_plots):
    out = tmp_path / "out"
    argv = ["classification", "--data", synthetic, "--preset", "modelnet40-noise-0.10", "--models", "kl", "--quick",
            "--n-jobs", "1", "--random-state", "3", "--out", str(out)]
    assert run_experiment(argv + ["--no-progress"]) == 0
    with open(out / "classification.md") as f:
        md = f.read()
    assert "--preset modelnet40-noise-0.10" in md and "preset `modelnet40-noise-0.10`" in md and "σ = 0.1" in md
    row = rows_of(out / "classification.csv")[0]
    # by hand: the preset's clouds, EPPF fitted on the training split, KL 1-NN
    data = apply_preset(raw, "modelnet40-noise-0.10", random_state=3)
    est = EPPFTransformer(n_pairs=5000, scaling="object", random_state=draw_seeds(3, 1)[0], n_jobs=1)
    Xtr = est.fit_transform([data.clouds[i] for i in data.train])
    Xte = est.transform([data.clouds[i] for i in data.test])
    pred = KLNearestNeighbors(n_neighbors=1).fit(Xtr, data.y[data.train]).predict(Xte)
    expected = retrieval_scores(data.y[data.test], pred)
    assert_allclose(float(row["total_accuracy"]), expected["total_accuracy"], atol=1e-6)
    assert_allclose(float(row["macro_f1"]), expected["macro_f1"], atol=1e-6)
    # and the function route gives the same row
    res = run_classification(data, models=["kl"], quick=True, n_jobs=1, random_state=3, verbose=False)
    assert_allclose(res["rows"][0]["total_accuracy"], float(row["total_accuracy"]), atol=1e-6)


def test_noise_command_sweeps_the_preset_levels(synthetic, raw, tmp_path, no_plots):
    out = tmp_path / "noise"
    argv = ["noise", "--data", synthetic, "--preset", "modelnet40-noise-0.15", "--models", "kl", "--quick",
            "--n-jobs", "1", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    rows = rows_of(out / "noise.csv")
    assert [float(r["sigma"]) for r in rows] == [0.0, 0.15]
    with open(out / "noise.md") as f:
        md = f.read()
    assert "preset modelnet40-noise-0.15" in md and "its σ is swept from 0" in md
    assert "drop from σ=0 to σ=0.15" in md
    # level 0 is the classification of the clean preset (the same points, no noise)
    clean = run_classification(apply_preset(raw, "modelnet40-clean", random_state=0), models=["kl"], quick=True,
                               n_jobs=1, verbose=False)
    assert_allclose(float(rows[0]["total_accuracy"]), clean["rows"][0]["total_accuracy"], atol=1e-6)
    # the same command again: the same figures
    assert main(argv[:-1] + [str(tmp_path / "again")]) == 0
    again = rows_of(tmp_path / "again" / "noise.csv")
    assert [(r["sigma"], r["total_accuracy"], r["macro_f1"]) for r in again] == \
        [(r["sigma"], r["total_accuracy"], r["macro_f1"]) for r in rows]


def test_noise_with_the_occluded_preset_and_given_levels(raw):
    res = run_noise(raw, preset="modelnet40-occluded", models=["kl"], quick=True, n_jobs=1, verbose=False)
    assert res["levels"] == [0.0, 0.07, 0.1, 0.15]
    assert res["preset"] == "modelnet40-occluded"
    res = run_noise(raw, preset="modelnet40-occluded", levels=[0.0], models=["kl"], quick=True, n_jobs=1,
                    verbose=False)
    occluded = run_classification(apply_preset(raw, "modelnet40-occluded", random_state=0), models=["kl"],
                                  quick=True, n_jobs=1, verbose=False)
    assert_allclose(res["rows"][0]["total_accuracy"], occluded["rows"][0]["total_accuracy"], atol=1e-6)


@pytest.mark.parametrize(
    "extra, msg",
    [
        (["--preset", "nope"], "argument --preset: invalid choice: 'nope'"),
        (["--preset", "modelnet40-clean", "--quick"], "needs at least 1024 points per object"),
    ],
)
@pytest.mark.parametrize("experiment", ["classification", "noise"])
def test_cli_errors_are_one_line(experiment, extra, msg, tmp_path, capsys):
    # the quick built-in set has 256 points per object
    assert main([experiment, "--models", "kl", "--out", str(tmp_path)] + extra) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and len(err.splitlines()) == 1
    assert not os.listdir(tmp_path)


def test_help_lists_the_presets(capsys):
    for experiment in ("classification", "noise"):
        assert main([experiment, "--help"]) == 0
        text = capsys.readouterr().out
        for p in PRESETS.values():
            assert f"  {p.name} " in text
    assert "--levels replaces the preset's levels" in " ".join(text.split())
