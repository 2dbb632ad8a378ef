"""DescriptorUnion and the EPPF + GASD preset: the KL decomposition, parameters, errors, pipelines."""

import pickle
import re

import numpy as np
import pytest
from sklearn.base import BaseEstimator, TransformerMixin, clone
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline

from eppf.descriptors import (DescriptorUnion, EPPFGASDTransformer, EPPFTransformer, ESFTransformer,
                              GASDTransformer)
from eppf.metrics import leave_one_out_retrieval
from eppf.neighbors import KLNearestNeighbors, symmetric_kl_distances
from eppf.registry import DESCRIPTORS, make_descriptor


class HeightHistogram(TransformerMixin, BaseEstimator):
    """A tiny, independent descriptor: histogram of z (``sign`` and ``zero_row`` make it misbehave)."""

    def __init__(self, n_bins=6, sign=1.0, zero_row=None):
        self.n_bins = n_bins
        self.sign = sign
        self.zero_row = zero_row

    def fit(self, X, y=None):
        self.n_features_out_ = self.n_bins
        return self

    def transform(self, X):
        rows = []
        for k, c in enumerate(X):
            z = np.asarray(c)[:, 2]
            h, _ = np.histogram(z, bins=self.n_bins, range=(-3.0, 3.0))
            rows.append(np.zeros(self.n_bins) if k == self.zero_row else self.sign * h.astype(float))
        return np.array(rows)


def _clouds(n=8, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        scale = [3.0, 2.0, 1.0] if k % 2 else [1.0, 1.0, 2.5]
        out.append(rng.normal(size=(150 + 10 * k, 3)) * scale)
    return out


def _union(**kw):
    return DescriptorUnion([("eppf", EPPFTransformer(n_pairs=1500, random_state=0)),
                            ("gasd", GASDTransformer())], **kw)


CLOUDS = _clouds()


# ------------------------------------------------------------ the identity
def test_rows_are_weighted_block_distributions():
    union = _union(weights={"eppf": 3, "gasd": 1})
    U = union.fit_transform(CLOUDS)
    np.testing.assert_allclose(union.weights_, [0.75, 0.25])
    assert U.shape == (len(CLOUDS), 1200 + 512) == (len(CLOUDS), union.n_features_out_)
    E = EPPFTransformer(n_pairs=1500, random_state=0).fit_transform(CLOUDS)
    G = GASDTransformer().fit_transform(CLOUDS)
    np.testing.assert_allclose(U[:, :1200], 0.75 * E / E.sum(1, keepdims=True), rtol=1e-13)
    np.testing.assert_allclose(U[:, 1200:], 0.25 * G / G.sum(1, keepdims=True), rtol=1e-13)
    np.testing.assert_allclose(U.sum(axis=1), 1.0, rtol=1e-13)


@pytest.mark.parametrize("weights", [{"eppf": 0.5, "gasd": 0.5}, {"eppf": 0.9, "gasd": 0.1}, {"eppf": 0.2}])
def test_kl_of_union_is_weighted_sum_of_block_kl(weights):
    union = _union(weights=weights)
    U = union.fit_transform(CLOUDS)
    f = 0.5 * U[U > 0].min()  # the "auto" floor of the union, as KLNearestNeighbors learns it
    total = np.zeros((len(CLOUDS), len(CLOUDS)))
    for (name, _), w in zip(union.transformers_, union.weights_):
        P = U[:, union.feature_slices_[name]] / w  # the block's own distribution
        np.testing.assert_allclose(P.sum(axis=1), 1.0, rtol=1e-13)
        # floor interaction: block b is floored at f / w_b on its own scale
        total += w * symmetric_kl_distances(P, floor=f / w)
    D = symmetric_kl_distances(U)
    np.testing.assert_allclose(D, total, rtol=1e-10, atol=1e-12)
    # and a direct NumPy reference for one pair
    a, b = np.maximum(U[0], f), np.maximum(U[3], f)
    assert np.isclose(D[0, 3], np.sum((a - b) * np.log(a / b)), rtol=1e-10)
    # KLNearestNeighbors on the union ranks by exactly that weighted sum
    knn = KLNearestNeighbors(n_neighbors=len(CLOUDS) - 1).fit(U, np.arange(len(CLOUDS)))
    assert knn.floor_ == f
    order = np.argsort(np.where(np.eye(len(CLOUDS), dtype=bool), np.inf, total), axis=1, kind="stable")
    np.testing.assert_array_equal(knn.kneighbors(return_distance=False)[:, 0], order[:, 0])


def test_weight_zero_block_adds_nothing_but_keeps_width():
    union = _union(weights={"eppf": 1.0, "gasd": 0.0})
    U = union.fit_transform(CLOUDS)
    assert U.shape[1] == 1712 and not U[:, 1200:].any()
    E = U[:, :1200]
    f = 0.5 * E[E > 0].min()
    np.testing.assert_allclose(symmetric_kl_distances(U), symmetric_kl_distances(E, floor=f), rtol=1e-12, atol=1e-13)


def test_normalize_none_only_weights():
    union = DescriptorUnion([("a", HeightHistogram()), ("b", HeightHistogram(n_bins=3))], normalize="none",
                            weights={"a": 1, "b": 3})
    U = union.fit_transform(CLOUDS)
    np.testing.assert_allclose(U[:, :6], 0.25 * HeightHistogram().fit_transform(CLOUDS))
    np.testing.assert_allclose(U[:, 6:], 0.75 * HeightHistogram(n_bins=3).fit_transform(CLOUDS))
    # "none" lets negative blocks through; "block" refuses them (below)
    neg = DescriptorUnion([("a", HeightHistogram(sign=-1.0))], normalize="none").fit_transform(CLOUDS)
    assert neg.min() < 0


# -------------------------------------------------------------- validation
@pytest.mark.parametrize("weights, exc, match", [
    ({"eppf": -0.1, "gasd": 1.0}, ValueError, "weight of block 'eppf' must be a finite float >= 0, got -0.1"),
    ({"eppf": 0.0, "gasd": 0.0}, ValueError, "positive finite sum"),
    ({"eppf": float("nan")}, ValueError, "must be a finite float >= 0, got nan"),
    ({"eppf": float("inf")}, ValueError, "must be a finite float >= 0, got inf"),
    ({"esf": 1.0}, ValueError, r"unknown blocks \['esf'\]"),
    ({"eppf": "1"}, TypeError, "must be a finite float >= 0, got '1'"),
    ({"eppf": True}, TypeError, "must be a finite float >= 0, got True"),
    ([0.5, 0.5], TypeError, "weights must be None or a dict"),
])
def test_bad_weights(weights, exc, match):
    with pytest.raises(exc, match="DescriptorUnion: .*" + match):
        _union(weights=weights).fit(CLOUDS)


@pytest.mark.parametrize("blocks, exc, match", [
    ([], ValueError, "transformer_list is empty"),
    ("eppf", TypeError, "transformer_list must be a list"),
    ([("a", HeightHistogram()), ("a", HeightHistogram())], ValueError, "unique, 'a' appears twice"),
    ([("a__b", HeightHistogram())], ValueError, "must not contain '__'"),
    ([("weights", HeightHistogram())], ValueError, "conflicts with a parameter"),
    ([("a", np.ones(3))], TypeError, "block 'a' must be a transformer"),
    ([(3, HeightHistogram())], TypeError, "names must be non-empty str"),
    ([HeightHistogram()], TypeError, r"transformer_list\[0\] must be a \(name, transformer\) tuple"),
])
def test_bad_blocks(blocks, exc, match):
    with pytest.raises(exc, match="DescriptorUnion: .*" + match):
        DescriptorUnion(blocks).fit(CLOUDS)


def test_bad_normalize_and_n_jobs():
    with pytest.raises(ValueError, match="DescriptorUnion: normalize must be 'block' or 'none'"):
        _union(normalize="l2").fit(CLOUDS)
    with pytest.raises((ValueError, TypeError), match="DescriptorUnion"):
        _union(n_jobs=0).fit(CLOUDS)


def test_bad_clouds_are_reported_once_by_the_union():
    bad = list(CLOUDS)
    bad[2] = bad[2].copy()
    bad[2][5, 1] = np.nan
    with pytest.raises(ValueError, match="DescriptorUnion.*2"):
        _union().fit(bad)
    fitted = _union().fit(CLOUDS)
    with pytest.raises(ValueError, match="DescriptorUnion.*2"):
        fitted.transform(bad)
    with pytest.raises(ValueError, match="DescriptorUnion"):
        fitted.transform([np.zeros((1, 3))])
    with pytest.raises(ValueError, match="DescriptorUnion"):
        fitted.transform([])
    with pytest.raises(TypeError, match="DescriptorUnion"):
        fitted.transform("clouds")
    # ESF needs 3 points: the union asks for the most any block needs, and says so itself
    esf = DescriptorUnion([("esf", ESFTransformer(n_triplets=200, random_state=0)), ("h", HeightHistogram())])
    with pytest.raises(ValueError, match="DescriptorUnion"):
        esf.fit_transform([np.random.default_rng(0).normal(size=(2, 3))] + CLOUDS[:2])


def test_blocks_that_cannot_be_distributions_are_refused():
    with pytest.raises(ValueError, match="DescriptorUnion: block 'h' gave negative values for point cloud 0"):
        DescriptorUnion([("h", HeightHistogram(sign=-1.0))]).fit_transform(CLOUDS)
    with pytest.raises(ValueError, match="DescriptorUnion: block 'h' gave a row summing to 0.0 for point cloud 3"):
        DescriptorUnion([("h", HeightHistogram(zero_row=3))]).fit_transform(CLOUDS)
    with pytest.raises(ValueError, match="DescriptorUnion: block 'h' gave non-finite values for point cloud 0"):
        DescriptorUnion([("h", HeightHistogram(sign=np.inf))]).fit_transform(CLOUDS)


def test_block_errors_are_prefixed_with_the_union_and_block():
    union = DescriptorUnion([("eppf", EPPFTransformer(n_pairs=-5))])
    with pytest.raises(ValueError, match="DescriptorUnion: block 'eppf': EPPFTransformer"):
        union.fit(CLOUDS)


def test_transform_before_fit():
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        _union().transform(CLOUDS)


# ------------------------------------------------------ sklearn behaviour
def test_nested_params_clone_and_pickle():
    union = _union(weights={"eppf": 0.6, "gasd": 0.4})
    params = union.get_params()
    assert params["eppf__n_pairs"] == 1500 and params["gasd__half_grid_size"] == 4
    assert params["eppf"] is union.transformer_list[0][1]
    union.set_params(eppf__n_pairs=700, gasd__half_grid_size=2)
    assert union.transformer_list[0][1].n_pairs == 700 and union.named_transformers.gasd.half_grid_size == 2
    replacement = HeightHistogram(n_bins=4)
    union.set_params(gasd=replacement, weights={"eppf": 1.0})
    assert union.transformer_list[1] == ("gasd", replacement) and union.weights == {"eppf": 1.0}
    assert set(union.get_params(deep=False)) == {"transformer_list", "weights", "normalize", "n_jobs"}
    twin = clone(union)
    assert twin.transformer_list[0][1] is not union.transformer_list[0][1]
    assert twin.get_params()["eppf__n_pairs"] == 700
    U = union.fit_transform(CLOUDS)
    assert U.shape == (len(CLOUDS), 1204)
    # the transformers given stay unfitted; the fitted clones are in transformers_
    assert not hasattr(union.transformer_list[0][1], "n_bins_")
    again = pickle.loads(pickle.dumps(union))
    np.testing.assert_array_equal(again.transform(CLOUDS), U)
    np.testing.assert_array_equal(twin.fit_transform(CLOUDS), U)


def test_feature_names_are_prefixed():
    union = _union().fit(CLOUDS)
    names = union.get_feature_names_out()
    assert len(names) == union.n_features_out_ == 1712
    eppf_names = union.transformers_[0][1].get_feature_names_out()
    assert list(names[:1200]) == ["eppf__" + n for n in eppf_names]
    assert all(n.startswith("gasd__") for n in names[1200:])
    other = DescriptorUnion([("h", HeightHistogram(n_bins=3))]).fit(CLOUDS)
    assert list(other.get_feature_names_out()) == ["h__0", "h__1", "h__2"]


def test_fit_transform_equals_fit_then_transform_and_seeds_stay_per_block():
    union = _union()
    np.testing.assert_array_equal(union.fit_transform(CLOUDS), union.fit(CLOUDS).transform(CLOUDS))
    other_seed = _union().set_params(eppf__random_state=1).fit_transform(CLOUDS)
    U = union.transform(CLOUDS)
    assert not np.array_equal(other_seed[:, :1200], U[:, :1200])
    np.testing.assert_array_equal(other_seed[:, 1200:], U[:, 1200:])


def test_bit_identical_for_any_n_jobs():
    ref = _union(n_jobs=1).fit_transform(CLOUDS)
    union = _union(n_jobs=2).fit(CLOUDS)
    assert all(est.n_jobs == 2 for _, est in union.transformers_)  # passed down to the clones
    assert union.transformer_list[0][1].n_jobs is None  # not to the blocks given
    np.testing.assert_array_equal(union.transform(CLOUDS), ref)
    np.testing.assert_array_equal(_union().fit_transform(CLOUDS), ref)


def test_pipeline_with_kl_nearest_neighbors_and_an_sklearn_classifier():
    clouds = _clouds(12, seed=3)
    y = np.array([k % 2 for k in range(12)])
    pipe = make_pipeline(_union(), KLNearestNeighbors()).fit(clouds[:8], y[:8])
    U = _union().fit_transform(clouds)
    direct = KLNearestNeighbors().fit(U[:8], y[:8]).predict(U[8:])
    np.testing.assert_array_equal(pipe.predict(clouds[8:]), direct)
    assert pipe.score(clouds[8:], y[8:]) == np.mean(direct == y[8:])
    # leave-one-out retrieval on the union rows works like on any descriptor
    assert leave_one_out_retrieval(U, y).shape == (12,)
    # EPPF4DClassifier reshapes its input to the EPPF grid (width prod(n_bins)), so it cannot
    # take a union; any scikit-learn classifier can
    logreg = make_pipeline(_union(), LogisticRegression(max_iter=200)).fit(clouds, y)
    assert logreg.predict(clouds).shape == (12,)


# ----------------------------------------------------------------- preset
def test_preset_is_the_union_it_says():
    preset = EPPFGASDTransformer(eppf_weight=0.8, n_pairs=1500, scaling="object", random_state=0)
    union = DescriptorUnion([("eppf", EPPFTransformer(n_pairs=1500, scaling="object", random_state=0)),
                             ("gasd", GASDTransformer())], weights={"eppf": 0.8, "gasd": 1 - 0.8})
    np.testing.assert_array_equal(preset.fit_transform(CLOUDS), union.fit_transform(CLOUDS))
    np.testing.assert_allclose(preset.weights_, [0.8, 0.2])
    assert set(preset.get_params()) == {"eppf_weight", "n_pairs", "scaling", "n_neighbors", "random_state", "n_jobs"}
    assert clone(preset).get_params() == preset.get_params()
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(preset)).transform(CLOUDS), preset.transform(CLOUDS))
    with pytest.raises(ValueError, match=re.escape("EPPFGASDTransformer: eppf_weight must be a float in [0.0, 1.0], got 1.5")):
        EPPFGASDTransformer(eppf_weight=1.5).fit(CLOUDS)
    with pytest.raises(TypeError, match="EPPFGASDTransformer: eppf_weight"):
        EPPFGASDTransformer(eppf_weight="half").fit(CLOUDS)


def test_preset_is_registered():
    spec = DESCRIPTORS["eppf+gasd"]
    assert spec.metric == "kl" and spec.sampling == "n_pairs" and spec.data_scaling
    est = make_descriptor("eppf+gasd", n_samples=900, scaling="object", random_state=4, n_jobs=1)
    assert isinstance(est, EPPFGASDTransformer)
    assert (est.n_pairs, est.scaling, est.random_state, est.n_jobs) == (900, "object", 4, 1)
    assert est.eppf_weight == EPPFGASDTransformer().eppf_weight


# ----------------------------------------------------------------- script
def _script():
    import importlib.util
    import os

    path = os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "combine_descriptors.py")
    spec = importlib.util.spec_from_file_location("combine_descriptors", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_script_table_and_missing_file(tmp_path, capsys):
    script = _script()
    assert script.main(["--data", str(tmp_path / "absent.npz")]) == 2
    assert "not found" in capsys.readouterr().err
    clouds = _clouds(24, seed=5)
    labels = np.array([k % 2 for k in range(24)])
    path = tmp_path / "tiny.npz"
    np.savez(path, points=np.concatenate(clouds), offsets=np.cumsum([0] + [len(c) for c in clouds]),
             labels=labels, class_names=np.array(["flat", "tall"]),
             split=np.array(["train"] * 16 + ["test"] * 8))
    assert script.main(["--data", str(path), "--others", "gasd", "--cache", str(tmp_path / "cache")]) == 0
    out = capsys.readouterr().out
    assert "| EPPF+GASD w=0.5 |" in out and "| GASD |" in out and "w chosen on train" in out
    assert len(list((tmp_path / "cache").glob("*.npy"))) == 2  # EPPF draw 0 and GASD, each computed once
    np.savez(tmp_path / "nosplit.npz", points=np.concatenate(clouds), offsets=np.cumsum([0] + [len(c) for c in clouds]),
             labels=labels, class_names=np.array(["flat", "tall"]))
    assert script.main(["--data", str(tmp_path / "nosplit.npz")]) == 2
    assert "no train/test split" in capsys.readouterr().err


class _ListOnly(HeightHistogram):
    """A third-party block that insists on the list of (n_i, 3|6) arrays the union hands such blocks."""

    def transform(self, X):
        assert isinstance(X, list) and all(isinstance(c, np.ndarray) and c.shape[1] in (3, 6) for c in X)
        return super().transform(X)


def test_blocks_get_the_bits_they_give_alone_validated_once():
    # the union validates the clouds once: eppf's descriptors then copy clouds without normals instead of
    # validating them again, other blocks get the list of arrays; every block's rows must be its own bits,
    # for clouds without normals, with normals (validated again by each block) and mixed, and odd dtypes
    rng = np.random.default_rng(4)
    plain = [c.astype(np.float32) if k == 2 else c for k, c in enumerate(_clouds(6, seed=4))]
    with_normals = [np.hstack([c, rng.normal(size=c.shape) * 3.0]) for c in _clouds(6, seed=5)]
    mixed = [with_normals[0], plain[1], with_normals[2]]
    blocks = [("eppf", EPPFTransformer(n_pairs=800, random_state=3)), ("gasd", GASDTransformer()),
              ("height", _ListOnly())]
    for X in (plain, with_normals, mixed):
        union = DescriptorUnion(blocks, normalize="none", weights={"eppf": 1, "gasd": 1, "height": 1})
        U = union.fit_transform(X)
        np.testing.assert_array_equal(union.transform(X), U)
        for (name, est), w in zip(blocks, union.weights_):
            alone = np.asarray(clone(est).fit(X).transform(X), dtype=np.float64)
            # (normalize="none": the block's rows times its weight, 1/3)
            np.testing.assert_array_equal(U[:, union.feature_slices_[name]], alone * w)


def test_checked_clouds_are_copied_as_validation_would_give_them():
    from eppf.utils import check_packed_clouds
    from eppf.utils._validation import CheckedClouds

    packed = check_packed_clouds(_clouds(4))
    checked = CheckedClouds.of(packed)
    fast, full = check_packed_clouds(checked, min_points=3), check_packed_clouds(list(packed), min_points=3)
    assert type(fast) is not CheckedClouds
    for field in ("points", "offsets", "lower", "upper", "has_normals"):
        np.testing.assert_array_equal(getattr(fast, field), getattr(full, field))
        assert not np.shares_memory(getattr(fast, field), getattr(packed, field))  # the caller's own arrays
    assert fast.normals is None
    # a block needing more points than some cloud has is still told so by the full validation
    with pytest.raises(ValueError, match="point cloud 0 has 150 points; at least 151"):
        check_packed_clouds(checked, owner="Needy", min_points=151)
    with pytest.raises(ValueError, match="only clouds without normals"):
        CheckedClouds.of(check_packed_clouds([np.hstack([c, c]) for c in _clouds(2)]))
