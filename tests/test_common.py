"""scikit-learn's estimator checks, run once for every public estimator of eppf.

As in scikit-learn's own ``sklearn/tests/test_common.py``, the estimators are
collected rather than listed: every :class:`~sklearn.base.BaseEstimator`
exported by a public module (``tests/_public_api.py``) and every class in
:data:`eppf.registry.DESCRIPTORS` and :data:`eppf.registry.CLASSIFIERS`, so a
new descriptor is checked as soon as it is registered. They fall in two
families:

- estimators on descriptor matrices that take any number of columns
  (``FULL_CHECKS``) pass scikit-learn's ``parametrize_with_checks`` in full;
- every other estimator gets scikit-learn's checks that need no data, then
  the same API contract checked here on small inputs of the kind it takes:
  lists of point clouds of different sizes, or (EPPF4DClassifier) descriptor
  matrices whose width is fixed by ``n_bins``, which scikit-learn's generated
  data cannot have.

Every check takes an unfitted estimator and fits its own clones, so the checks
are independent of each other and of their order.
"""

import copy
import inspect
import pickle
import re
import warnings

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.base import BaseEstimator, clone, is_classifier
from sklearn.exceptions import NotFittedError
from sklearn.utils import get_tags
from sklearn.utils import estimator_checks as skchecks
from sklearn.utils.estimator_checks import parametrize_with_checks

from tests._public_api import public_modules
from eppf.datasets import make_shapes
from eppf.registry import CLASSIFIERS, DESCRIPTORS

# ------------------------------------------------------------------ estimators

# Estimators on descriptor matrices that pass every scikit-learn check.
FULL_CHECKS = {"KLNearestNeighbors", "ApproximateKLNearestNeighbors"}

# Small settings, so that the whole file runs in seconds on one core. Classes
# not listed are built with their defaults (and random_state=0 when they have
# one): give a new estimator an entry here if its defaults are slow.
TINY = {
    "EPPFTransformer": dict(n_pairs=300),
    "ESFTransformer": dict(n_triplets=300),
    "WahlTransformer": dict(n_pairs=300),
    "EPPFGASDTransformer": dict(n_pairs=300),
    "Resampler": dict(n_points=32),
    "DescriptorPool": dict(n_draws=2),
    "PointNetClassifier": dict(n_points=16, max_epochs=1, batch_size=4, early_stopping=False, n_jobs=1),
    "EPPF4DClassifier": dict(n_bins=(2, 2, 3, 1), max_epochs=1, n_hidden=4, filters=(2, 2, 2), batch_size=4,
                             early_stopping=False, n_jobs=1),
}


def _tiny(cls, **fixed):
    """An instance of ``cls`` with the small settings and a fixed seed."""
    accepted = inspect.signature(cls).parameters
    params = dict(TINY.get(cls.__name__, {}))
    if "random_state" in accepted:
        params["random_state"] = 0
    if cls.__name__ in ("CachedTransformer", "DescriptorPool"):  # a wrapper: give it a small seeded descriptor
        from eppf.descriptors import ESFTransformer

        params["transformer"] = _tiny(ESFTransformer)
    if cls.__name__ == "DescriptorUnion":  # a composite: give it two small blocks
        from eppf.descriptors import ESFTransformer, GASDTransformer

        params["transformer_list"] = [("esf", _tiny(ESFTransformer)), ("gasd", GASDTransformer())]
    params.update(fixed)
    return cls(**params)


def public_estimator_classes():
    """Every BaseEstimator subclass exported by a public module, by name."""
    out = {}
    for _, module in public_modules():
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name)
            if isinstance(obj, type) and issubclass(obj, BaseEstimator):
                out[obj.__name__] = obj
    return out


def registered_estimators():
    """One small instance per registry entry (with the entry's fixed parameters)."""
    out = []
    for spec in DESCRIPTORS.values():
        cls = spec.estimator_class()
        fixed = dict(spec.fixed)
        if spec.sampling is not None:
            fixed[spec.sampling] = TINY.get(cls.__name__, {}).get(spec.sampling, 300)
        out.append(_tiny(cls, **fixed))
    for spec in CLASSIFIERS.values():
        out.append(_tiny(spec.estimator_class(), **spec.fixed))
    return out


def _all_estimators():
    """Small instances of every public and every registered estimator, no duplicates."""
    seen, out = set(), []
    for est in [_tiny(cls) for cls in public_estimator_classes().values()] + registered_estimators():
        key = repr(est)
        if key not in seen:
            seen.add(key)
            out.append(est)
    return out


ALL = _all_estimators()
FULL = [est for est in ALL if type(est).__name__ in FULL_CHECKS]
API = [est for est in ALL if type(est).__name__ not in FULL_CHECKS]
# Clusterers (eppf.segmentation.SceneSegmenter) take one scene, not a list of clouds or
# a descriptor matrix: they get scikit-learn's data-free checks here, and their API
# contract (fit/fit_predict, fitted attributes, clone, pickle, bad input) on scenes
# in tests/segmentation/test_segmenter.py.
SCENE = [est for est in API if get_tags(est).estimator_type == "clusterer"]


def _input_kind(est):
    """``"points"`` (a list of clouds) or ``"descriptors"`` (a matrix of fixed width)."""
    for spec in CLASSIFIERS.values():
        if spec.estimator_class() is type(est):
            return spec.input
    return "descriptors" if get_tags(est).input_tags.two_d_array else "points"


def _est_id(est):
    return re.sub(r"\s+", "", repr(est))


# ------------------------------------------------------------------------ data

_CLASSES = np.array(["box", "sphere"])


def _shapes(n_per_class=3, n_points=64, seed=0):
    X, y = make_shapes(n_per_class, n_points=n_points, classes=list(_CLASSES), return_X_y=True, random_state=seed)
    return X, _CLASSES[y]


def _data(est, ragged=True):
    """Small training data of the kind ``est`` takes, with string labels.

    Point clouds have 64 points, less 4 per position in the list when
    ``ragged``, so no two have the same size.
    """
    if _input_kind(est) == "points":
        X, y = _shapes()
        if ragged:
            X = [c[: 64 - 4 * k] for k, c in enumerate(X)]
        if type(est).__name__ == "GASDColorTransformer":  # points followed by RGB colours in [0, 255]
            rng = np.random.default_rng(1)
            X = [np.hstack([c, rng.uniform(0, 255, size=(len(c), 3))]) for c in X]
        return X, y
    width = int(np.prod(est.get_params()["n_bins"]))
    X = np.random.default_rng(0).dirichlet(np.ones(width), size=8)
    return X, np.tile(_CLASSES, 4)


def _fit(est, X, y):
    return est.fit(X, y) if is_classifier(est) else est.fit(X)


def _output(est, X):
    """What the fitted ``est`` makes of ``X``: its transform, or its class probabilities."""
    return est.transform(X) if hasattr(est, "transform") else est.predict_proba(X)


def _assert_same(a, b):
    """Bit-identical outputs (arrays, or lists of clouds)."""
    if isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b)
        for u, v in zip(a, b):
            assert u.dtype == v.dtype
            assert_array_equal(u, v)
    else:
        assert a.dtype == b.dtype
        assert_array_equal(a, b)


def _differs(a, b):
    if isinstance(a, list):
        return any(u.shape != v.shape or not np.array_equal(u, v) for u, v in zip(a, b))
    return not np.array_equal(a, b)


def _seed_params(est):
    """Names of the (possibly nested) random_state parameters of ``est``."""
    return [k for k in est.get_params(deep=True) if k == "random_state" or k.endswith("__random_state")]


def _owner_names(est):
    """Names an error message may use for ``est``: its own, or a wrapped estimator's."""
    names = {type(est).__name__}
    names |= {type(v).__name__ for v in est.get_params(deep=True).values() if isinstance(v, BaseEstimator)}
    return names


# ------------------------------------------------- scikit-learn's full checks


@parametrize_with_checks(
    FULL
    + [
        # the non-default branches: distance weights, several neighbours and
        # chunks smaller than the data; a fixed floor with renormalisation
        _tiny(public_estimator_classes()["KLNearestNeighbors"], n_neighbors=3, weights="distance", chunk_size=7),
        _tiny(public_estimator_classes()["KLNearestNeighbors"], floor=1e-3, renormalize=True),
    ]
)
def test_sklearn_compatible_estimator(estimator, check):
    check(estimator)


# ------------------------------------- scikit-learn's checks that need no data

SKLEARN_DATA_FREE_CHECKS = [
    skchecks.check_estimator_cloneable,
    skchecks.check_estimator_tags_renamed,
    skchecks.check_valid_tag_types,
    skchecks.check_estimator_repr,
    skchecks.check_no_attributes_set_in_init,
    skchecks.check_mixin_order,
    skchecks.check_do_not_raise_errors_in_init_or_set_params,
    skchecks.check_parameters_default_constructible,
    skchecks.check_get_params_invariance,
    skchecks.check_set_params,
]


@pytest.mark.parametrize(
    "estimator, check",
    [(est, chk) for est in API for chk in SKLEARN_DATA_FREE_CHECKS],
    ids=[f"{_est_id(est)}-{chk.__name__}" for est in API for chk in SKLEARN_DATA_FREE_CHECKS],
)
def test_sklearn_data_free_checks(estimator, check):
    with warnings.catch_warnings():
        # check_set_params only warns when set_params validates: here that fails
        warnings.filterwarnings("error", message=".*parameter validation until fit.*")
        warnings.filterwarnings("error", message=".*parameters changed after set_params.*")
        check(type(estimator).__name__, estimator)


# ----------------------------------------- the API contract on suitable input


def check_init_stores_params_unchanged(est):
    # __init__ stores every argument as it is given: no copy, no conversion, no validation
    cls = type(est)
    names = [p for p in inspect.signature(cls).parameters if p not in ("self",)]
    sentinels = {name: object() for name in names}
    new = cls(**sentinels)
    for name, value in sentinels.items():
        assert getattr(new, name) is value, name
        assert new.get_params(deep=False)[name] is value, name
    assert set(vars(new)) == set(names)


def check_get_set_params_round_trip(est):
    params = est.get_params(deep=False)
    required = {k: params[k] for k, p in inspect.signature(type(est)).parameters.items() if p.default is p.empty}
    fresh = type(est)(**required)
    assert fresh.set_params(**params) is fresh
    assert fresh.get_params(deep=False).keys() == params.keys()
    assert all(fresh.get_params(deep=False)[k] is v for k, v in params.items())
    assert repr(fresh) == repr(est)
    cloned = clone(est)
    assert cloned is not est
    assert repr(cloned) == repr(est)
    # cloning a fitted estimator keeps the parameters and drops what fit learned
    X, y = _data(est)
    fitted = _fit(clone(est), X, y)
    learned = {k for k in vars(fitted) if k.endswith("_") and not k.startswith("_")}
    assert learned or not get_tags(est).requires_fit, "fit sets no attribute ending in '_'"
    again = clone(fitted)
    assert repr(again) == repr(est)
    assert not learned & set(vars(again))


def check_repr(est):
    text = repr(est)
    assert text.startswith(type(est).__name__ + "(")
    defaults = {k: p.default for k, p in inspect.signature(type(est)).parameters.items()}
    for name, value in est.get_params(deep=False).items():
        shown = value is not defaults.get(name) and repr(value) != repr(defaults.get(name))
        if shown and not isinstance(value, BaseEstimator):
            assert f"{name}=" in text, (name, text)


def check_fit_returns_self(est):
    X, y = _data(est)
    est = clone(est)
    assert _fit(est, X, y) is est


def check_not_fitted(est):
    X, y = _data(est)
    methods = [m for m in ("transform", "predict", "predict_proba", "decision_function") if hasattr(est, m)]
    assert methods
    if get_tags(est).requires_fit:
        for method in methods:
            with pytest.raises(NotFittedError, match=f"{type(est).__name__} instance is not fitted yet"):
                getattr(clone(est), method)(X)
        if hasattr(est, "get_feature_names_out"):
            with pytest.raises(NotFittedError):
                clone(est).get_feature_names_out()
    else:
        # stateless: works unfitted, and gives what a fitted one gives
        _assert_same(_output(clone(est), X), _output(_fit(clone(est), X, y), X))


def check_pickle_round_trip(est):
    X, y = _data(est)
    restored = pickle.loads(pickle.dumps(est))
    assert repr(restored) == repr(est)
    fitted = _fit(clone(est), X, y)
    expected = _output(fitted, X)
    # unpickled fitted estimator: same output; unpickled unfitted one, fitted: same output
    _assert_same(_output(pickle.loads(pickle.dumps(fitted)), X), expected)
    _assert_same(_output(_fit(restored, X, y), X), expected)
    if is_classifier(est):
        assert_array_equal(pickle.loads(pickle.dumps(fitted)).predict(X), fitted.predict(X))


def check_no_n_features_in_for_point_clouds(est):
    X, y = _data(est)
    fitted = _fit(clone(est), X, y)
    # feature_names_in_ only comes from data frames, which these estimators never see
    assert not hasattr(fitted, "feature_names_in_")
    if _input_kind(est) == "points":
        # scikit-learn's rule for non-tabular input (as CountVectorizer): no n_features_in_
        assert not hasattr(fitted, "n_features_in_")
    else:
        assert fitted.n_features_in_ == np.asarray(X).shape[-1]


def check_get_feature_names_out(est):
    X, y = _data(est)
    fitted = _fit(clone(est), X, y)
    out = fitted.transform(X)
    if isinstance(out, list):
        # a list of clouds has no features to name
        assert not hasattr(fitted, "get_feature_names_out")
        return
    names = fitted.get_feature_names_out()
    assert len(names) == out.shape[-1]  # the last axis (a descriptor pool's is (objects, draws, features))
    assert all(isinstance(n, str) for n in names)
    assert len(set(names)) == len(names)
    assert_array_equal(fitted.get_feature_names_out(None), names)


def check_input_tags(est):
    tags = get_tags(est)
    if _input_kind(est) == "points":
        # a list of clouds is not a feature matrix; an (n_objects, n_points, 3) array is read as one
        assert tags.input_tags.two_d_array is False
        assert tags.input_tags.three_d_array is True
    else:
        assert tags.input_tags.two_d_array is True
    assert tags.input_tags.sparse is False and tags.input_tags.allow_nan is False


def check_tags(est):
    tags = get_tags(est)
    if is_classifier(est):
        assert tags.estimator_type == "classifier"
        assert tags.target_tags.required
    else:
        assert tags.transformer_tags is not None
    # every instance here is seeded (or draws nothing): deterministic on the CPU
    assert tags.non_deterministic is False


def check_three_d_array_as_declared(est):
    # a 3D array is read as its slices along the first axis
    X, y = _data(est, ragged=False)
    if _input_kind(est) == "points":
        cube = np.stack(X)
        fitted = _fit(clone(est), cube, y)
        _assert_same(_output(fitted, cube), _output(_fit(clone(est), list(X), y), list(X)))
    else:
        fitted = _fit(clone(est), X, y)
        _assert_same(_output(fitted, X[:, None, :]), _output(fitted, X))


def check_fit_transform_equals_fit_then_transform(est):
    X, _ = _data(est)
    _assert_same(clone(est).fit_transform(X), clone(est).fit(X).transform(X))


def check_fit_transform_reads_an_iterator_once(est):
    # fit and transform take an iterator of clouds, so fit_transform does too (the descriptors' and
    # CachedTransformer's fit used it up: "X is empty", or a TypeError, from the transform after it)
    X, _ = _data(est)
    _assert_same(clone(est).fit_transform(c for c in X), clone(est).fit_transform(X))


def check_deterministic_under_int_random_state(est):
    X, y = _data(est)
    fitted = _fit(clone(est), X, y)
    first = _output(fitted, X)
    _assert_same(_output(fitted, X), first)  # a second call draws the same
    _assert_same(_output(_fit(clone(est), X, y), X), first)  # so does a second fit
    seeds = _seed_params(est)
    if seeds:
        # and the seed is used: another one changes the draw
        other = clone(est).set_params(**{k: 1 for k in seeds})
        assert _differs(_output(_fit(other, X, y), X), first)


def check_random_state_none_draws_afresh(est):
    # random_state=None: every fit (and, for stateless transformers, every call) draws anew
    X, y = _data(est)
    unseeded = clone(est).set_params(**{k: None for k in _seed_params(est)})
    assert _differs(_output(_fit(clone(unseeded), X, y), X), _output(_fit(clone(unseeded), X, y), X))


def check_output_dtype_and_shape(est):
    X, y = _data(est)
    copies = [np.array(c, copy=True) for c in X]
    fitted = _fit(clone(est), X, y)
    out = _output(fitted, X)
    for a, b in zip(X, copies):
        assert_array_equal(a, b)  # neither fit nor transform/predict modifies the input
    if is_classifier(est):
        assert_array_equal(fitted.classes_, np.unique(y))
        assert isinstance(out, np.ndarray) and out.shape == (len(X), len(fitted.classes_))
        assert out.dtype.kind == "f" and np.all(out >= 0)
        np.testing.assert_allclose(out.sum(axis=1), 1.0, rtol=1e-5)
        pred = fitted.predict(X)
        assert pred.shape == (len(X),) and pred.dtype == fitted.classes_.dtype
        assert_array_equal(pred, fitted.classes_[np.argmax(out, axis=1)])
        return
    preserves = get_tags(est).transformer_tags.preserves_dtype
    if isinstance(out, list):
        assert len(out) == len(X)
        for cloud, new in zip(X, out):
            assert isinstance(new, np.ndarray) and new.ndim == 2 and new.shape[1] == np.shape(cloud)[1]
            assert new.dtype == np.float64 and np.isfinite(new).all()
    else:
        # a descriptor pool is (objects, draws, features), every other transformer (objects, features)
        ndim = 3 if type(est).__name__ == "DescriptorPool" else 2
        assert isinstance(out, np.ndarray) and out.shape[0] == len(X) and out.ndim == ndim
        assert out.dtype == np.float64 and np.isfinite(out).all()
        if hasattr(fitted, "n_features_out_"):
            assert out.shape[-1] == fitted.n_features_out_
    # float32 input: float32 out only if the tags say the dtype is preserved
    out32 = _output(_fit(clone(est), [np.asarray(c, dtype=np.float32) for c in X], y),
                    [np.asarray(c, dtype=np.float32) for c in X])
    dtypes = {a.dtype for a in out32} if isinstance(out32, list) else {out32.dtype}
    assert dtypes == ({np.dtype(np.float32)} if "float32" in preserves else {np.dtype(np.float64)})


def _bad_inputs(est):
    """(description, X, y, message pattern): inputs that must raise a ValueError."""
    X, y = _data(est)
    if _input_kind(est) == "points":
        good, two = X[0], _CLASSES  # labels of two classes, so y is never the problem
        nan = np.array(X[1], dtype=float)
        nan[5, 1] = np.nan
        inf = np.array(X[1], dtype=float)
        inf[2, 0] = np.inf
        return [
            ("one_point", [good, good[:1]], two, r"point cloud 1 has 1 point"),
            ("nan", [good, nan], two, r"point cloud 1 contains NaN"),
            ("inf", [good, inf], two, r"point cloud 1 contains NaN or infinite"),
            ("two_columns", [good, X[1][:, :2]], two, r"point cloud 1 must have shape"),
            ("flat", [good, X[1][:, 0]], two, r"point cloud 1 must have shape"),
            ("empty", [], two[:0], r"empty"),
        ]
    nan = X.copy()
    nan[1, 2] = np.nan
    return [
        ("nan", nan, y, r"NaN"),
        ("width", X[:, :-1], y, r"values"),
        ("flat", X[0], y, r"shape"),
    ]


def check_rejects_bad_input(est):
    X, y = _data(est)
    fitted = _fit(clone(est), X, y)
    owner = rf"^({'|'.join(map(re.escape, _owner_names(est)))}): "
    method = "transform" if hasattr(est, "transform") else "predict"
    for what, bad, y_bad, pattern in _bad_inputs(est):
        for stage, call in ((method, lambda: getattr(fitted, method)(bad)),
                            ("fit", lambda: _fit(clone(est), bad, y_bad))):
            try:
                call()
            except ValueError as exc:  # any other exception fails the test as it is
                assert re.search(owner + ".*" + pattern, str(exc)), f"{what} in {stage}: {exc}"
            else:
                raise AssertionError(f"{what} in {stage}: no ValueError")


API_CHECKS = [
    check_init_stores_params_unchanged,
    check_get_set_params_round_trip,
    check_repr,
    check_fit_returns_self,
    check_not_fitted,
    check_pickle_round_trip,
    check_no_n_features_in_for_point_clouds,
    check_get_feature_names_out,
    check_input_tags,
    check_tags,
    check_three_d_array_as_declared,
    check_fit_transform_equals_fit_then_transform,
    check_fit_transform_reads_an_iterator_once,
    check_deterministic_under_int_random_state,
    check_random_state_none_draws_afresh,
    check_output_dtype_and_shape,
    check_rejects_bad_input,
]

# Known departures from the contract, each with its reason. ``strict``: the
# test fails once the estimator is fixed, so the entry cannot outlive the bug.
KNOWN_FAILURES = {}


# Checks that only apply to some estimators (the others are not generated, rather than skipped).
_APPLIES = {
    check_get_feature_names_out: lambda est: not is_classifier(est),
    # point-cloud estimators should all take 3D arrays (check_input_tags), so all are tried
    check_three_d_array_as_declared: lambda est: get_tags(est).input_tags.three_d_array or _input_kind(est) == "points",
    check_fit_transform_equals_fit_then_transform: lambda est: hasattr(est, "transform"),
    check_fit_transform_reads_an_iterator_once: lambda est: hasattr(est, "transform") and _input_kind(est) == "points",
    check_random_state_none_draws_afresh: lambda est: bool(_seed_params(est)),
}


def _api_params():
    out = []
    for est in API:
        if est in SCENE:
            continue
        for chk in API_CHECKS:
            if not _APPLIES.get(chk, lambda est: True)(est):
                continue
            reason = KNOWN_FAILURES.get((type(est).__name__, chk.__name__))
            marks = [pytest.mark.xfail(reason=reason, strict=True)] if reason else []
            out.append(pytest.param(est, chk, marks=marks, id=f"{_est_id(est)}-{chk.__name__}"))
    return out


@pytest.mark.parametrize("estimator, check", _api_params())
def test_api_contract(estimator, check):
    check(estimator)


# ------------------------------------------------------------------ coverage


def test_every_public_estimator_is_checked():
    checked = {type(est).__name__ for est in ALL}
    assert set(public_estimator_classes()) <= checked
    # the ones the task names explicitly, in case an export goes missing
    assert {"EPPFTransformer", "ESFTransformer", "WahlTransformer", "OURCVFHTransformer", "PointNetClassifier",
            "EPPF4DClassifier", "KLNearestNeighbors", "GaussianNoise", "RandomDropout", "Occlusion",
            "RandomRotation", "RandomScaling", "Resampler"} <= checked
    # every registry entry, with its fixed parameters (EPPF short's bins, each network variant)
    for spec in list(DESCRIPTORS.values()) + list(CLASSIFIERS.values()):
        cls = spec.estimator_class()
        assert any(type(e) is cls and all(e.get_params()[k] == v for k, v in spec.fixed.items()) for e in ALL), \
            spec.name
    assert FULL and all(type(e).__name__ in FULL_CHECKS for e in FULL)


def test_sklearn_checks_cover_descriptor_matrix_classifiers():
    # the registry's classifiers on descriptors that take any width are in FULL_CHECKS; the others
    # (EPPF4DClassifier: width = prod(n_bins), so scikit-learn's generated matrices do not fit) are API-checked
    for spec in CLASSIFIERS.values():
        est = _tiny(spec.estimator_class(), **spec.fixed)
        if spec.input == "descriptors" and "n_bins" not in est.get_params():
            assert type(est).__name__ in FULL_CHECKS, spec.name


# ------------------------------------------------- the checks catch mistakes
# Broken variants of one transformer: each check that guards the rule broken must fail.

from eppf.descriptors import ESFTransformer  # noqa: E402


class _ConvertsInInit(ESFTransformer):
    def __init__(self, n_triplets=300, grid_size=64, n_bins=64, random_state=0, n_jobs=None):
        super().__init__(copy.copy(n_triplets), grid_size, n_bins, random_state, n_jobs)


class _IgnoresSeed(ESFTransformer):
    def transform(self, X):
        return super().transform(X) + np.random.uniform(0, 1e-12)


class _NoFitCheck(ESFTransformer):
    def transform(self, X):
        if not hasattr(self, "n_features_out_"):
            self.fit(X)
        return super().transform(X)


class _SetsNFeaturesIn(ESFTransformer):
    def fit(self, X, y=None):
        self.n_features_in_ = 3
        return super().fit(X, y)


class _ShortNames(ESFTransformer):
    def get_feature_names_out(self, input_features=None):
        return super().get_feature_names_out()[:-1]


class _AnonymousErrors(ESFTransformer):
    def transform(self, X):
        try:
            return super().transform(X)
        except ValueError as exc:
            raise ValueError(str(exc).split(": ", 1)[1]) from None


class _ModifiesInput(ESFTransformer):
    def fit(self, X, y=None):
        super().fit(X, y)
        X[0][0, 0] += 1.0
        return self


@pytest.mark.parametrize(
    "broken, check",
    [
        (_ConvertsInInit(), check_init_stores_params_unchanged),
        (_IgnoresSeed(n_triplets=300, random_state=0), check_deterministic_under_int_random_state),
        (_IgnoresSeed(n_triplets=300, random_state=0), check_pickle_round_trip),
        (_NoFitCheck(n_triplets=300, random_state=0), check_not_fitted),
        (_SetsNFeaturesIn(n_triplets=300, random_state=0), check_no_n_features_in_for_point_clouds),
        (_ShortNames(n_triplets=300, random_state=0), check_get_feature_names_out),
        (_AnonymousErrors(n_triplets=300, random_state=0), check_rejects_bad_input),
        (_ModifiesInput(n_triplets=300, random_state=0), check_output_dtype_and_shape),
    ],
    ids=lambda v: type(v).__name__.strip("_") if isinstance(v, BaseEstimator) else v.__name__,
)
def test_checks_fail_on_broken_estimators(broken, check):
    with pytest.raises((AssertionError, pytest.fail.Exception)):
        check(broken)
    check(ESFTransformer(n_triplets=300, random_state=0))  # the unbroken one passes
