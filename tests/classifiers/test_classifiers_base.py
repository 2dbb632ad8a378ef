"""The shared skorch scaffolding (eppf/classifiers/_base.py), through both classifiers."""

import math
import pickle
import re

import numpy as np
import pytest
import torch
from sklearn.exceptions import NotFittedError
from skorch import NeuralNetClassifier
from skorch.callbacks import Callback

from eppf import EPPF4DClassifier, PointNetClassifier
from eppf.classifiers._base import SkorchClassifierBase, _torch_threads, _validation_split
from eppf.classifiers._callbacks import EpochLog, TimeBudget

N_BINS = (4, 2, 3, 2)
EPPF_FAST = dict(n_bins=N_BINS, filters=(4, 8, 4), n_hidden=16, batch_size=16, n_jobs=1)
PN_FAST = dict(n_points=24, batch_size=8, n_jobs=1)


def _descriptors(n, labels, seed=0):
    """Rows whose mass sits in a class-specific block (easily separable)."""
    rng = np.random.default_rng(seed)
    n_features = math.prod(N_BINS)
    codes = rng.integers(0, len(labels), n)
    X = rng.random((n, n_features)) * 0.3
    block = n_features // len(labels)
    for c in range(len(labels)):
        X[codes == c, c * block : (c + 1) * block] += 1.0
    X /= X.sum(axis=1, keepdims=True)
    return X, np.asarray(labels, dtype=object)[codes].astype(type(labels[0]))


def _clouds(n, labels, seed=0):
    rng = np.random.default_rng(seed)
    X, y = [], []
    for i in range(n):
        c = i % len(labels)
        X.append(rng.normal(size=(30, 3)) * [1.0, 1.0, 1.0 + 4.0 * c])
        y.append(labels[c])
    return X, np.asarray(y)


def _make(kind, **params):
    if kind == "eppf":
        X, y = _descriptors(30, ["cat", "dog"])
        return EPPF4DClassifier(**{**EPPF_FAST, **params}), X, y
    X, y = _clouds(12, ["ball", "stick"])
    return PointNetClassifier(**{**PN_FAST, **params}), X, y


KINDS = ["eppf", "pointnet"]


def test_both_classifiers_share_the_base():
    for cls in (EPPF4DClassifier, PointNetClassifier):
        assert issubclass(cls, SkorchClassifierBase)
        assert not issubclass(cls, NeuralNetClassifier)  # wrapped, not subclassed


# ---------------------------------------------------------------- time budget
def test_time_budget_is_a_skorch_callback_that_stops_after_the_deadline(monkeypatch):
    import eppf.classifiers._callbacks as cb

    clock = [100.0]
    monkeypatch.setattr(cb.time, "monotonic", lambda: clock[0])
    said = []
    budget = TimeBudget(5.0, said.append).initialize()
    assert isinstance(budget, Callback)
    assert budget.get_params() == {"seconds": 5.0, "sink": said.append}

    class Net:
        history = [{}, {}, {}]

    budget.on_train_begin(Net())
    clock[0] = 105.0  # exactly at the budget: keep going
    budget.on_epoch_end(Net())
    assert said == []
    clock[0] = 105.5
    with pytest.raises(KeyboardInterrupt):
        budget.on_epoch_end(Net())
    assert said == ["Stopping: time budget of 5 s used after 3 epochs."]


@pytest.mark.parametrize("kind, early_stopping", [("eppf", False), ("eppf", True), ("pointnet", True)])
def test_time_budget_ends_fit_after_first_epoch(kind, early_stopping, capsys):
    clf, X, y = _make(kind, max_epochs=6, max_time=1e-9, early_stopping=early_stopping, random_state=0, verbose=0)
    clf.fit(X, y)
    assert clf.n_epochs_ == 1 and clf.best_epoch_ == 1
    assert capsys.readouterr().out == ""  # verbose=0: not even the budget's message
    names = [name for name, _ in clf.net_.callbacks]
    assert "time_budget" in names and ("early_stopping" in names) == early_stopping
    if kind == "eppf":
        # Without a budget, the same fit runs every epoch.
        clf.set_params(max_time=None, early_stopping=False, max_epochs=3).fit(X, y)
        assert clf.n_epochs_ == 3


@pytest.mark.parametrize("kind", KINDS)
def test_time_budget_message_when_verbose(kind, capsys):
    clf, X, y = _make(kind, max_epochs=4, max_time=1e-9, early_stopping=False, random_state=0, verbose=1)
    clf.fit(X, y)
    out = capsys.readouterr().out
    assert "Stopping: time budget of 1e-09 s used after 1 epochs." in out


# -------------------------------------------------------------- epoch logging
@pytest.mark.parametrize("kind", KINDS)
def test_verbose_prints_one_line_per_epoch(kind, capsys):
    clf, X, y = _make(kind, max_epochs=2, early_stopping=True, validation_fraction=0.3, n_iter_no_change=5,
                      random_state=0, verbose=1)
    clf.fit(X, y)
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("epoch ")]
    assert len(lines) == clf.n_epochs_ == 2
    pattern = re.compile(r"^epoch ([12])/2  train_loss \d+\.\d{4}  valid_loss \d+\.\d{4}  valid_acc \d\.\d{4}  "
                         r"\d+\.\d\d s$")
    for k, line in enumerate(lines, start=1):
        m = pattern.match(line)
        assert m and int(m.group(1)) == k, line
        row = clf.net_.history[k - 1]
        assert f"train_loss {row['train_loss']:.4f}" in line and f"valid_acc {row['valid_acc']:.4f}" in line
    if kind == "eppf":
        clf.set_params(verbose=0).fit(X, y)
        assert capsys.readouterr().out == ""


@pytest.mark.parametrize("kind", KINDS)
def test_default_verbosity_prints_each_epoch_and_verbose_0_nothing(kind, capsys):
    # As skorch: a fit that runs for minutes says how it goes unless asked not to.
    clf, X, y = _make(kind, max_epochs=3, early_stopping=False, random_state=0)
    assert clf.get_params()["verbose"] == 1
    clf.fit(X, y)
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == clf.n_epochs_ == 3
    assert [ln.split("  ")[0] for ln in lines] == ["epoch 1/3", "epoch 2/3", "epoch 3/3"]
    assert all(re.search(r"  train_loss \d+\.\d{4}  \d+\.\d\d s$", ln) for ln in lines), lines
    clf.set_params(verbose=0).fit(X, y)
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize("verbose", [0, 1])
def test_ensemble_numbers_its_networks_from_one(verbose, capsys):
    clf, X, y = _make("eppf", max_epochs=2, early_stopping=False, n_estimators=3, random_state=0, verbose=verbose)
    clf.fit(X, y)
    out = capsys.readouterr().out
    if not verbose:
        assert out == ""
        return
    lines = out.splitlines()
    # each network announced before its own epochs
    assert lines == [
        "network 1 of 3 of the ensemble", lines[1], lines[2],
        "network 2 of 3 of the ensemble", lines[4], lines[5],
        "network 3 of 3 of the ensemble", lines[7], lines[8],
    ]
    assert [ln.split("  ")[0] for k, ln in enumerate(lines) if k % 3] == ["epoch 1/2", "epoch 2/2"] * 3
    clf.set_params(n_estimators=1).fit(X, y)  # a single network is not called an ensemble
    assert "network" not in capsys.readouterr().out


def test_epoch_log_without_validation():
    said = []

    class Net:
        history = [{"epoch": 7, "train_loss": 0.25, "dur": 1.5}]

    EpochLog(said.append, 100).on_epoch_end(Net())
    assert said == ["epoch   7/100  train_loss 0.2500  1.50 s"]


def test_early_stopping_message_when_verbose(capsys):
    # lr=0 cannot improve the validation loss: patience 1 stops after epoch 2.
    clf, X, y = _make("eppf", max_epochs=10, lr=1e-12, n_iter_no_change=1, random_state=0, verbose=1)
    clf.fit(X, y)
    out = capsys.readouterr().out
    assert clf.n_epochs_ < 10
    assert "Stopping since valid_loss has not improved" in out
    assert len([ln for ln in out.splitlines() if ln.startswith("epoch ")]) == clf.n_epochs_


# ------------------------------------------------------------ torch threads
@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


@pytest.mark.parametrize("kind", KINDS)
def test_threads_set_during_fit_and_predict_and_restored(kind, two_threads, monkeypatch):
    seen = {}
    fit, predict_proba = NeuralNetClassifier.fit, NeuralNetClassifier.predict_proba

    def spy_fit(net, *args, **kwargs):
        seen["fit"] = torch.get_num_threads()
        return fit(net, *args, **kwargs)

    def spy_predict(net, *args, **kwargs):
        seen["predict"] = torch.get_num_threads()
        return predict_proba(net, *args, **kwargs)

    monkeypatch.setattr(NeuralNetClassifier, "fit", spy_fit)
    monkeypatch.setattr(NeuralNetClassifier, "predict_proba", spy_predict)
    clf, X, y = _make(kind, max_epochs=1, early_stopping=False, random_state=0, n_jobs=1)
    clf.fit(X, y)
    assert seen["fit"] == 1 and torch.get_num_threads() == 2
    clf.predict(X)
    assert seen["predict"] == 1 and torch.get_num_threads() == 2
    if kind == "eppf":
        # n_jobs=None leaves torch's setting alone
        clf.set_params(n_jobs=None).predict(X)
        assert seen["predict"] == 2


def test_threads_restored_when_fit_raises(two_threads, monkeypatch):
    def boom(net, *args, **kwargs):
        assert torch.get_num_threads() == 1
        raise RuntimeError("boom")

    monkeypatch.setattr(NeuralNetClassifier, "fit", boom)
    clf, X, y = _make("pointnet", max_epochs=1, early_stopping=False, n_jobs=1)
    with pytest.raises(RuntimeError, match="boom"):
        clf.fit(X, y)
    assert torch.get_num_threads() == 2
    with _torch_threads(None):
        assert torch.get_num_threads() == 2


@pytest.mark.parametrize(
    "kind, at, extra",
    [(kind, at, extra) for kind in KINDS for at, extra in [(1, {}), (3, {}), (3, {"early_stopping": False}), (8, {})]]
    + [("eppf", 5, {"n_estimators": 2})],
)
def test_ctrl_c_during_training_ends_fit(kind, at, extra, monkeypatch):
    # skorch's partial_fit swallows every KeyboardInterrupt (its early stopping's and the
    # time budget's too); a user's Ctrl-C must still end fit, not return a half-trained
    # network (nor crash on a history without valid_loss, nor go on with the next member).
    from eppf.nn import EPPFNet4D, PointNet

    module = EPPFNet4D if kind == "eppf" else PointNet
    forward, calls = module.forward, []

    def interrupted_forward(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == at:
            raise KeyboardInterrupt
        return forward(self, *args, **kwargs)

    monkeypatch.setattr(module, "forward", interrupted_forward)
    clf, X, y = _make(kind, **{"max_epochs": 3, "random_state": 0, "verbose": 0, **extra})
    with pytest.raises(KeyboardInterrupt):
        clf.fit(X, y)
    assert len(calls) == at  # nothing trained after the interrupt
    assert not hasattr(clf, "net_")


# ---------------------------------------------------------------- labels
@pytest.mark.parametrize("labels", [["zebra", "ant", "mole"], [30, -7, 4]])
def test_labels_map_back(labels):
    X, y = _descriptors(60, labels, seed=3)
    clf = EPPF4DClassifier(**{**EPPF_FAST, "lr": 1e-2}, max_epochs=12, early_stopping=False, random_state=0).fit(X, y)
    assert list(clf.classes_) == sorted(labels)
    pred = clf.predict(X)
    assert pred.dtype == y.dtype and set(pred) <= set(labels)
    # columns of predict_proba follow classes_: a permuted mapping would score near 1/3
    assert np.mean(pred == y) >= 0.9
    np.testing.assert_array_equal(pred, clf.classes_[np.argmax(clf.predict_proba(X), axis=1)])


@pytest.mark.parametrize("kind", KINDS)
def test_missing_labels_are_named(kind):
    clf, X, _ = _make(kind, max_epochs=1, verbose=0)
    with pytest.raises(ValueError, match=re.escape(f"{type(clf).__name__}: y is None; class labels are needed")):
        clf.fit(X, None)
    # NaT is no class either (np.unique kept it as one, where a NaN label is refused)
    y = np.array(["2020-01-01", "2020-01-02"] * (len(X) // 2) + ["2020-01-01"] * (len(X) % 2), dtype="datetime64[D]")
    y[0] = np.datetime64("NaT")
    with pytest.raises(ValueError, match=re.escape(f"{type(clf).__name__}: y contains NaT (not-a-time) labels")):
        clf.fit(X, y)


def test_pointnet_order_preserving_relabelling_changes_nothing_but_the_names():
    X, y = _clouds(12, ["b", "a"])
    kw = dict(PN_FAST, max_epochs=1, early_stopping=False, random_state=0)
    a = PointNetClassifier(**kw).fit(X, y)
    b = PointNetClassifier(**kw).fit(X, np.where(y == "a", "alpha", "beta"))
    assert list(a.classes_) == ["a", "b"] and list(b.classes_) == ["alpha", "beta"]
    np.testing.assert_array_equal(a.predict_proba(X), b.predict_proba(X))
    np.testing.assert_array_equal(np.where(a.predict(X) == "a", "alpha", "beta"), b.predict(X))


@pytest.mark.parametrize("kind", KINDS)
def test_ragged_labels_are_named(kind):
    # NumPy's bare "setting an array element with a sequence" named neither the estimator nor y
    clf, X, y = _make(kind, max_epochs=1, verbose=0)
    ragged = [[0], [1, 2]] * (len(X) // 2)
    with pytest.raises(ValueError, match=f"{type(clf).__name__}: y must be a 1D sequence of class labels"):
        clf.fit(X, ragged)


# ---------------------------------------------------------------- not fitted
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("method", ["predict", "predict_proba"])
def test_not_fitted(kind, method):
    clf, X, _ = _make(kind)
    with pytest.raises(NotFittedError, match=type(clf).__name__):
        getattr(clf, method)(X)


# ---------------------------------------------------------------- failed refit
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("error", [RuntimeError("boom"), KeyboardInterrupt()])
def test_a_failed_refit_leaves_the_previous_fit(kind, error, monkeypatch):
    # a refit that raised midway (after the labels were encoded) left the new classes_ beside the old
    # net_: predict then named the old network's classes with the new labels
    from eppf.nn import EPPFNet4D, PointNet

    clf, X, y = _make(kind, max_epochs=1, early_stopping=False, random_state=0, verbose=0)
    clf.fit(X, y)
    before = dict(clf.__dict__)
    proba = clf.predict_proba(X)
    module = EPPFNet4D if kind == "eppf" else PointNet
    forward, calls = module.forward, []

    def failing_forward(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:  # midway through the first epoch
            raise error
        return forward(self, *args, **kwargs)

    monkeypatch.setattr(module, "forward", failing_forward)
    new_y = np.where(y == y[0], "first", "second")
    new_y[-1] = "third"
    with pytest.raises(type(error)):
        clf.fit(X, new_y)
    assert len(calls) == 2
    monkeypatch.setattr(module, "forward", forward)
    assert clf.__dict__.keys() == before.keys()
    assert all(clf.__dict__[k] is v for k, v in before.items())  # the very objects of the first fit
    assert list(clf.classes_) == sorted(set(y))
    np.testing.assert_array_equal(clf.predict_proba(X), proba)


def test_an_ensemble_whose_last_network_fails_keeps_the_previous_fit(monkeypatch):
    # the ensemble trains its networks one after another: a failure in the last one must not leave the
    # networks trained before it beside the previous fit's
    from eppf.nn import EPPFNet4D

    clf, X, y = _make("eppf", max_epochs=1, early_stopping=False, n_estimators=2, random_state=0, verbose=0)
    forward, calls = EPPFNet4D.forward, []

    def counting_forward(self, *args, **kwargs):
        calls.append(1)
        return forward(self, *args, **kwargs)

    monkeypatch.setattr(EPPFNet4D, "forward", counting_forward)
    clf.fit(X, y)
    total = len(calls)  # forward calls of a whole fit of both networks
    before = dict(clf.__dict__)
    proba = clf.predict_proba(X)
    calls.clear()

    def failing_forward(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == total - 1:  # within the second network's training
            raise RuntimeError("boom")
        return forward(self, *args, **kwargs)

    monkeypatch.setattr(EPPFNet4D, "forward", failing_forward)
    with pytest.raises(RuntimeError, match="boom"):
        clf.fit(X, np.where(y == y[0], "first", "second"))
    monkeypatch.setattr(EPPFNet4D, "forward", forward)
    assert clf.__dict__.keys() == before.keys() and all(clf.__dict__[k] is v for k, v in before.items())
    np.testing.assert_array_equal(clf.predict_proba(X), proba)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("error", [ValueError("late"), KeyboardInterrupt()])
def test_a_failed_first_fit_leaves_the_estimator_unfitted(kind, error, monkeypatch):
    clf, X, y = _make(kind, max_epochs=1, early_stopping=False, random_state=0, verbose=0)
    params = clf.get_params()

    def failing_datasets(*args, **kwargs):  # after the inputs and labels were taken in
        raise error

    monkeypatch.setattr(type(clf), "_make_datasets", failing_datasets)
    with pytest.raises(type(error)):
        clf.fit(X, y)
    assert not hasattr(clf, "classes_") and not hasattr(clf, "n_features_in_")
    assert not [k for k in vars(clf) if k.endswith("_") or k.startswith("_")]
    assert clf.get_params() == params
    with pytest.raises(NotFittedError):
        clf.predict(X)


# -------------------------------------------------------- validation split
def test_validation_split_is_stratified_seeded_and_disjoint():
    y = np.repeat([0, 1, 2], [20, 10, 30])
    tr, va = _validation_split(y, 3, 0.2, seed=5, owner="X")
    assert len(va) == 12 and len(tr) == 48
    assert np.intersect1d(tr, va).size == 0 and np.union1d(tr, va).size == 60
    np.testing.assert_array_equal(np.bincount(y[va], minlength=3), [4, 2, 6])  # class shares kept
    tr2, va2 = _validation_split(y, 3, 0.2, seed=5, owner="X")
    np.testing.assert_array_equal(va, va2)
    assert not np.array_equal(np.sort(va), np.sort(_validation_split(y, 3, 0.2, seed=6, owner="X")[1]))


def test_validation_split_falls_back_to_unstratified_for_singleton_classes():
    y = np.array([0, 0, 0, 0, 0, 1])
    tr, va = _validation_split(y, 2, 0.34, seed=0, owner="X")
    assert len(va) == 3 and len(tr) == 3


# ---------------------------------------------------------------- parameters
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize(
    "params, err, msg",
    [
        ({"random_state": -1}, ValueError,
         "random_state must be None or an int in [0, 4294967295] or a numpy RandomState, got -1"),
        ({"random_state": "0"}, TypeError,
         "random_state must be None or an int in [0, 4294967295] or a numpy RandomState, got '0'"),
        ({"lr_schedule": "step"}, ValueError, "lr_schedule must be 'constant' or 'plateau', got 'step'"),
        ({"max_time": float("inf")}, ValueError, "max_time must be None or a float in (0.0, inf), got inf"),
        ({"n_jobs": 1.0}, TypeError, "n_jobs must be None or a non-zero int (-1: all cores), got 1.0"),
        ({"verbose": True}, ValueError, "verbose must be an int >= 0, got True"),
    ],
)
def test_common_parameters_are_checked_in_fit(kind, params, err, msg):
    clf, X, y = _make(kind, **params)
    with pytest.raises(err, match=re.escape(f"{type(clf).__name__}: {msg}")):
        clf.fit(X, y)


def test_accepts_a_randomstate_and_pickles():
    clf, X, y = _make("eppf", max_epochs=1, early_stopping=False, random_state=np.random.RandomState(0))
    clf.fit(X, y)
    again = pickle.loads(pickle.dumps(clf))
    np.testing.assert_array_equal(again.predict_proba(X), clf.predict_proba(X))


def test_names_of_models_pickled_before_the_move_still_resolve():
    import io

    import eppf.nn

    find = pickle.Unpickler(io.BytesIO(b"")).find_class
    for name in ("TNet", "PointNet", "PointNetLoss", "orthogonality_penalty"):
        assert find("eppf.classifiers._pointnet", name) is getattr(eppf.nn, name)
    assert find("eppf.classifiers._eppf_cnn", "_TimeBudget") is TimeBudget
    assert callable(find("eppf.classifiers._eppf_cnn", "_silent"))
    with pytest.raises(AttributeError):
        find("eppf.classifiers._pointnet", "NoSuchThing")


@pytest.mark.parametrize("kind", KINDS)
def test_tags(kind):
    clf, _, _ = _make(kind)
    assert clf.__sklearn_tags__().estimator_type == "classifier"
    assert not clf.__sklearn_tags__().non_deterministic
    assert clf.set_params(device="cuda").__sklearn_tags__().non_deterministic


@pytest.mark.parametrize("cls", [EPPF4DClassifier, PointNetClassifier])
def test_unusable_device_is_a_clear_error(cls):
    import torch

    X = np.random.default_rng(0).dirichlet(np.ones(1200), size=8) if cls is EPPF4DClassifier else \
        [np.random.default_rng(k).normal(size=(64, 3)) for k in range(8)]
    y = np.arange(8) % 2
    with pytest.raises(ValueError, match=re.escape(f"{cls.__name__}: device='tpu9' is not a torch device")):
        cls(device="tpu9", max_epochs=1).fit(X, y)
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match=re.escape(f"{cls.__name__}: device='cuda' but torch sees no CUDA GPU")):
            cls(device="cuda", max_epochs=1).fit(X, y)
