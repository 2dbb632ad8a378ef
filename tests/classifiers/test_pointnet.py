import pickle
import re

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("skorch")

from sklearn.base import clone  # noqa: E402

from eppf.classifiers._pointnet import PointNetClassifier, _normalise_and_sample  # noqa: E402
from eppf.nn import PointNet, PointNetLoss, TNet  # noqa: E402
from eppf.nn import orthogonality_penalty as penalty  # noqa: E402

FAST = dict(n_points=32, max_epochs=2, batch_size=8, early_stopping=False, n_jobs=1)


def _sphere(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _box(rng, n):
    return rng.uniform(-1, 1, size=(n, 3)) * [0.1, 0.1, 1.0]


def _toy(n_per_class=12, seed=0, labels=("ball", "stick")):
    rng = np.random.default_rng(seed)
    X, y = [], []
    for i in range(n_per_class):
        X.append(_sphere(rng, 40 + i) * rng.uniform(0.5, 2) + rng.normal(size=3))
        y.append(labels[0])
        X.append(_box(rng, 50 + i) * rng.uniform(0.5, 2) + rng.normal(size=3))
        y.append(labels[1])
    return X, np.array(y)


def test_module_output_shapes():
    torch.manual_seed(0)
    net = PointNet(n_classes=5).eval()
    logits, feat = net(torch.randn(4, 20, 3))
    assert logits.shape == (4, 5)
    assert feat.shape == (4, 64, 64)
    assert TNet(3).eval()(torch.randn(2, 3, 10)).shape == (2, 3, 3)


@pytest.mark.parametrize("k", [3, 64])
def test_tnet_identity_at_init(k):
    torch.manual_seed(0)
    out = TNet(k).train()(torch.randn(3, k, 16))
    expected = torch.eye(k).expand(3, k, k)
    assert torch.allclose(out, expected)


def test_orthogonality_penalty():
    q, _ = torch.linalg.qr(torch.randn(2, 64, 64, dtype=torch.float64))
    assert penalty(q).item() == pytest.approx(0.0, abs=1e-20 + 1e-10)
    a = 2 * torch.eye(4, dtype=torch.float64).unsqueeze(0)
    # I - 4 I = -3 I, squared Frobenius norm 4 * 9.
    assert penalty(a).item() == pytest.approx(36.0)
    b = torch.randn(3, 5, 5, dtype=torch.float64)
    ref = np.mean([np.sum((np.eye(5) - m @ m.T) ** 2) for m in b.numpy()])
    assert penalty(b).item() == pytest.approx(ref)


def test_loss_adds_regulariser():
    logits = torch.randn(4, 3)
    y = torch.tensor([0, 1, 2, 0])
    feat = torch.randn(4, 6, 6)
    ce = torch.nn.functional.cross_entropy(logits, y)
    loss = PointNetLoss(reg_weight=0.5)((logits, feat), y)
    assert loss.item() == pytest.approx((ce + 0.5 * penalty(feat)).item(), rel=1e-6)


def test_module_permutation_invariance():
    torch.manual_seed(0)
    net = PointNet(n_classes=3).eval()
    x = torch.randn(2, 30, 3)
    perm = torch.randperm(30)
    with torch.no_grad():
        a, _ = net(x)
        b, _ = net(x[:, perm])
    assert torch.allclose(a, b, atol=1e-5)


def test_normalise_and_sample():
    rng = np.random.default_rng(0)
    big = rng.normal(size=(100, 3)) * [1, 2, 3] + 5
    small = rng.normal(size=(10, 3))
    out = _normalise_and_sample([big, small], 50, np.array([1, 2], dtype=np.uint64), "t")
    assert out.shape == (2, 50, 3)
    for pts in out:
        side = pts.max(axis=0) - pts.min(axis=0)
        assert np.all(np.abs(pts) <= 0.5 + 1e-6)
    # without replacement for the larger cloud: 50 distinct points
    assert np.unique(out[0], axis=0).shape[0] == 50
    # the small cloud keeps all its points (bbox intact)
    side = out[1].max(axis=0) - out[1].min(axis=0)
    assert side.max() == pytest.approx(1.0, rel=1e-6)
    assert np.unique(out[1], axis=0).shape[0] == 10


def test_learns_separable_set():
    X, y = _toy(12, seed=0)
    clf = PointNetClassifier(
        n_points=48, max_epochs=15, batch_size=8, early_stopping=False, random_state=0, n_jobs=1,
        augment_rotation=None,
    ).fit(X, y)
    Xt, yt = _toy(6, seed=1)
    assert clf.score(Xt, yt) >= 0.9
    proba = clf.predict_proba(Xt)
    assert proba.shape == (12, 2)
    assert np.allclose(proba.sum(axis=1), 1.0, atol=1e-5)
    assert clf.n_epochs_ == 15


def test_prediction_invariant_to_point_order():
    X, y = _toy(4)
    clf = PointNetClassifier(**FAST, random_state=0).fit(X, y)
    rng = np.random.default_rng(5)
    clouds = [rng.normal(size=(32, 3)) for _ in range(3)]
    shuffled = [c[rng.permutation(32)] for c in clouds]
    assert np.allclose(clf.predict_proba(clouds), clf.predict_proba(shuffled), atol=1e-5)


def test_determinism_and_string_labels():
    X, y = _toy(5, labels=("zeta", "alpha"))
    a = PointNetClassifier(**FAST, random_state=3).fit(X, y)
    b = PointNetClassifier(**FAST, random_state=3).fit(X, y)
    np.testing.assert_array_equal(a.predict_proba(X), b.predict_proba(X))
    np.testing.assert_array_equal(a.classes_, ["alpha", "zeta"])
    assert set(a.predict(X)) <= {"alpha", "zeta"}
    c = PointNetClassifier(**FAST, random_state=4).fit(X, y)
    assert not np.array_equal(a.predict_proba(X), c.predict_proba(X))


def test_global_torch_rng_untouched():
    X, y = _toy(3)
    torch.manual_seed(123)
    expected = torch.rand(1)
    torch.manual_seed(123)
    PointNetClassifier(**FAST, random_state=0).fit(X, y).predict(X)
    assert torch.rand(1).item() == expected.item()


def test_early_stopping_and_six_columns():
    X, y = _toy(5)
    X6 = [np.hstack([c, np.ones_like(c)]) for c in X]
    clf = PointNetClassifier(
        n_points=32, max_epochs=3, batch_size=8, early_stopping=True, validation_fraction=0.2,
        n_iter_no_change=1, random_state=0, n_jobs=1,
    ).fit(X6, y)
    assert 1 <= clf.best_epoch_ <= clf.n_epochs_ <= 3
    assert "valid_loss" in clf.net_.history[-1]
    np.testing.assert_allclose(clf.predict_proba(X6), clf.predict_proba(X), atol=1e-6)


def test_pickle_and_clone():
    X, y = _toy(3)
    clf = PointNetClassifier(**FAST, random_state=0).fit(X, y)
    restored = pickle.loads(pickle.dumps(clf))
    np.testing.assert_array_equal(restored.predict_proba(X), clf.predict_proba(X))
    cl = clone(clf)
    assert cl.get_params() == clf.get_params()
    assert not hasattr(cl, "net_")


def test_drop_last_single_object_batch():
    # 9 training objects with batch_size 8 leave a batch of one: must not crash.
    X, y = _toy(5)
    PointNetClassifier(**FAST, random_state=0).fit(X[:9], y[:9])


@pytest.mark.parametrize(
    "params, msg",
    [
        ({"n_points": 0}, "PointNetClassifier: n_points must be an int >= 1, got 0"),
        ({"max_epochs": 1.5}, "PointNetClassifier: max_epochs must be an int >= 1, got 1.5"),
        ({"lr": 0.0}, "PointNetClassifier: lr must be a float in (0.0, inf), got 0.0"),
        ({"batch_size": 1}, "PointNetClassifier: batch_size must be an int >= 2, got 1"),
        ({"dropout": 1.0}, "PointNetClassifier: dropout must be a float in [0.0, 1.0), got 1.0"),
        ({"reg_weight": -1.0}, "PointNetClassifier: reg_weight must be a float in [0.0, inf), got -1.0"),
        ({"augment_rotation": "y"}, "PointNetClassifier: augment_rotation must be 'z' or None, got 'y'"),
        ({"jitter": "yes"}, "PointNetClassifier: jitter must be True or False, got 'yes'"),
        ({"early_stopping": 1}, "PointNetClassifier: early_stopping must be True or False, got 1"),
        ({"validation_fraction": 1.0}, "PointNetClassifier: validation_fraction must be a float in (0.0, 1.0), got 1.0"),
        ({"device": 0}, "PointNetClassifier: device must be a str such as 'cpu' or 'cuda', got 0"),
        ({"n_jobs": 0}, "PointNetClassifier: n_jobs must be None or a non-zero int (-1: all cores), got 0"),
        ({"verbose": -1}, "PointNetClassifier: verbose must be an int >= 0, got -1"),
    ],
)
def test_bad_params(params, msg):
    X, y = _toy(2)
    with pytest.raises(ValueError, match=re.escape(msg)):
        PointNetClassifier(**{**FAST, **params}).fit(X, y)


def test_bad_input():
    X, y = _toy(2)
    clf = PointNetClassifier(**FAST)
    with pytest.raises(ValueError, match=re.escape("PointNetClassifier: point cloud 1 contains NaN")):
        clf.fit([X[0], np.full((5, 3), np.nan), X[2], X[3]], y)
    with pytest.raises(ValueError, match=re.escape("PointNetClassifier: point cloud 0 has 1 point")):
        clf.fit([np.zeros((1, 3))] + X[1:], y)
    with pytest.raises(ValueError, match=re.escape("PointNetClassifier: X has 4 objects but y has 3 labels")):
        clf.fit(X, y[:3])
    with pytest.raises(ValueError, match=re.escape("PointNetClassifier: y has a single class 'ball'")):
        clf.fit(X, np.array(["ball"] * 4))
    with pytest.raises(ValueError, match=re.escape("PointNetClassifier: y must be 1D")):
        clf.fit(X, y[:, None])
    with pytest.raises(TypeError, match=re.escape("PointNetClassifier: X must be a list of point clouds")):
        clf.fit(None, y)
    with pytest.raises(ValueError, match=re.escape("PointNetClassifier: at least 2 training objects")):
        PointNetClassifier(**{**FAST, "early_stopping": True, "validation_fraction": 0.5}).fit(X[:3], y[:3])


def test_labels_of_mixed_kinds_or_nan_are_named():
    X, _ = _toy(2)
    clf = PointNetClassifier(**FAST)
    with pytest.raises(TypeError, match=r"^PointNetClassifier: y must hold class labels of one kind .* float, int, str"):
        clf.fit(X, np.array(["ball", 1, 2.5, "stick"], dtype=object))
    with pytest.raises(ValueError, match=r"^PointNetClassifier: y must hold class labels of one kind .*NaN"):
        clf.fit(X, np.array([0.0, 1.0, np.nan, 1.0]))


def test_clouds_near_the_float64_limits():
    import warnings

    X, y = _toy(2)
    clf = PointNetClassifier(**FAST)
    overflowing = [np.vstack([c, [[1e308, 0, 0], [-1e308, 0, 0]]]) for c in X]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused before the overflow (it trained on NaN and zeros)
        with pytest.raises(ValueError, match=r"^PointNetClassifier: object 0's bounding box overflows float64"):
            clf.fit(overflowing, y)
        # far from the origin but with a finite box: its center (lo + hi) / 2 overflowed to inf
        far = [c * 1e306 + 1.5e308 for c in X]
        got = _normalise_and_sample(far, 32, np.arange(4), "t")
        near = _normalise_and_sample([c * 1e306 for c in X], 32, np.arange(4), "t")
    assert np.isfinite(got).all() and np.abs(got).max() <= 0.5 + 1e-6
    np.testing.assert_allclose(got, near, atol=1e-2)  # the same shapes, up to the rounding of 1.5e308 + x


def test_not_fitted():
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        PointNetClassifier().predict([np.eye(3)])


def test_augmentation():
    from eppf.classifiers._pointnet import _make_dataset

    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.5, 0.5, size=(2, 20, 3)).astype(np.float32)
    y = np.array([0, 1])
    rot = _make_dataset(pts, y, seed=0, rotation="z", jitter=False, scale=False)
    a, label = rot[1]
    a = a.numpy()
    assert label == 1
    # rotation about z: z kept, xy radii kept, xy changed
    np.testing.assert_allclose(a[:, 2], pts[1, :, 2], atol=1e-6)
    np.testing.assert_allclose(np.hypot(a[:, 0], a[:, 1]), np.hypot(pts[1, :, 0], pts[1, :, 1]), atol=1e-6)
    assert not np.allclose(a, pts[1])
    jit = _make_dataset(pts, y, seed=0, rotation=None, jitter=True, scale=False)
    d = jit[0][0].numpy() - pts[0]
    assert 0 < np.abs(d).max() <= 0.05 + 1e-6
    sc = _make_dataset(pts, y, seed=0, rotation=None, jitter=False, scale=True)
    ratio = sc[0][0].numpy() / pts[0]
    assert np.allclose(ratio, ratio[0, 0], rtol=1e-5) and 0.8 <= ratio[0, 0] <= 1.25
    # seeded: same seed, same stream
    again = _make_dataset(pts, y, seed=0, rotation="z", jitter=True, scale=True)
    same = _make_dataset(pts, y, seed=0, rotation="z", jitter=True, scale=True)
    np.testing.assert_array_equal(again[0][0].numpy(), same[0][0].numpy())


def test_a_huge_n_points_is_refused_in_parameter_validation():
    # NumPy's "Unable to allocate" came out of the resampling (or torch's allocator out of the first batch)
    rng = np.random.default_rng(0)
    X, y = [rng.normal(size=(20, 3)) for _ in range(4)], [0, 1, 0, 1]
    with pytest.raises(ValueError, match=re.escape("PointNetClassifier: n_points must be at most 2**24 = 16,777,216, "
                                                   "got 1,000,000,000,000")):
        PointNetClassifier(n_points=10**12, verbose=0).fit(X, y)


def test_too_many_classes_for_the_network_are_refused_before_it_is_built(monkeypatch):
    # a network of 10**7 classes has 2.6 billion weights in its last layer alone
    from eppf.classifiers import _base

    monkeypatch.setattr(_base, "MAX_PARAMETERS", 3_000_000)  # (the default network has 3.5 million)
    rng = np.random.default_rng(0)
    X, y = [rng.normal(size=(20, 3)) for _ in range(4)], [0, 1, 0, 1]
    with pytest.raises(ValueError, match=r"PointNetClassifier: the network would have 3,[\d,]+ parameters \(2 classes\), "
                                         r"more than the 3,000,000 it may have"):
        PointNetClassifier(n_points=8, max_epochs=1, early_stopping=False, verbose=0).fit(X, y)


@pytest.mark.parametrize("kwargs, exc, msg", [
    ({"n_classes": 10**12}, ValueError, "PointNet: n_classes=1,000,000,000,000 gives the last layer 257,000,000,000,000 "
                                        "parameters, more than the 1,000,000,000 a network may have"),
    ({"n_classes": 10**30}, ValueError, "PointNet: n_classes=1,000,000,000,000,000,000,000,000,000,000 gives the last layer"),
    ({"n_classes": 2.5}, TypeError, "PointNet: n_classes must be an int >= 2, got 2.5"),
    ({"n_classes": 0}, ValueError, "PointNet: n_classes must be an int >= 2, got 0"),
    ({"n_classes": 3, "dropout": 2}, ValueError, "PointNet: dropout must be a float in [0, 1), got 2"),
])
def test_pointnet_module_checks_its_arguments_before_building(kwargs, exc, msg):
    # torch's allocator raised RuntimeError for a huge n_classes, torch.empty an overflow or type
    # TypeError, and 0 classes or dropout=2 built a network that could not train
    with pytest.raises(exc, match=re.escape(msg)):
        PointNet(**kwargs)
