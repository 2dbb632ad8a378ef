"""The recommended recipe ("EPPF 4D+") of the classification experiment and of ``eppf train``."""

import numpy as np

from eppf import EPPF4DClassifier, EPPFTransformer
from eppf.descriptors import DescriptorPool, DescriptorUnion, GASDTransformer, ProportionTransformer
from eppf.experiments import run_classification
from eppf.registry import RECIPE, recommended_pipeline_parts


def test_recommended_parts_are_the_documented_recipe():
    pool, clf = recommended_pipeline_parts(EPPFTransformer(n_bins=(15, 3, 4, 3)), n_jobs=1, random_state=3,
                                           max_epochs=7, n_iter_no_change=2)
    assert isinstance(pool, DescriptorPool) and pool.n_draws == RECIPE["n_draws"] and pool.random_state == 3
    assert (pool.augment.low, pool.augment.high) == RECIPE["stretch"]
    # per-draw normals and 8 test draws: the cheaper settings missed the test check (the registry's docstring)
    assert pool.share_normals is RECIPE["share_normals"] is False
    assert pool.test_draws is RECIPE["test_draws"] is None
    union = pool.transformer
    assert isinstance(union, DescriptorUnion) and union.normalize == "none"
    assert [type(t) for _, t in union.transformer_list] == [EPPFTransformer, GASDTransformer, ProportionTransformer]
    assert isinstance(clf, EPPF4DClassifier) and clf.conv == "4d" and clf.n_bins == (15, 3, 4, 3)
    assert clf.n_side_features == "auto" and clf.filters == RECIPE["filters"] and clf.n_hidden == RECIPE["n_hidden"]
    assert clf.lr_schedule == "plateau" and clf.precision == "auto" and clf.max_epochs == 7
    assert clf.n_iter_no_change == RECIPE["min_patience"]  # at least 8 epochs of patience
    assert clf.n_estimators == RECIPE["n_estimators"] == 1  # one network: on validation data an ensemble gained nothing
    assert clf.label_smoothing == RECIPE["label_smoothing"] == 0.1
    quick_pool, quick_clf = recommended_pipeline_parts(EPPFTransformer(), quick=True, n_iter_no_change=2)
    assert quick_pool.n_draws == 2 and quick_clf.n_iter_no_change == 2 and quick_clf.n_estimators == 1
    assert quick_pool.test_draws is None


def test_classification_experiment_trains_4d_plus_on_pools(tmp_path, capsys):
    result = run_classification("builtin", quick=True, models=["4d+"], n_jobs=1, out=str(tmp_path), verbose=False)
    assert capsys.readouterr().out == ""  # verbose=False: the networks' epochs are not printed either
    (row,) = result["rows"]
    assert row["model"] == "EPPF 4D+" and row["n_test"] == 20 and 0 <= row["total_accuracy"] <= 1
    report = (tmp_path / "classification.md").read_text()
    assert "EPPF 4D+: the recommended recipe" in report and "n_side_features='auto'" in report
    assert "label_smoothing=0.1" in report and "n_estimators=1" in report  # quick: one network
    # the pools are cached: a second run reads them
    again = run_classification("builtin", quick=True, models=["4d+"], n_jobs=1, out=str(tmp_path), verbose=False)
    assert again["cache"].n_loaded == 1 and again["cache"].n_computed == 0
    np.testing.assert_array_equal(again["predictions"]["4d+"], result["predictions"]["4d+"])
