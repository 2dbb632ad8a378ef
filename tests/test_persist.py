"""Safe model files: round trips, refusal of pickles and foreign classes, corrupt files."""

import io
import json
import os
import pickle
import re
import struct
import warnings
import zipfile

import joblib
import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.decomposition import PCA
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import FunctionTransformer, Normalizer, StandardScaler

import eppf
from eppf import (
    EPPF4DClassifier,
    EPPFTransformer,
    ESFTransformer,
    KLNearestNeighbors,
    OURCVFHTransformer,
    PointNetClassifier,
    WahlTransformer,
    load_model,
    save_model,
)
from eppf.datasets import make_shapes


@pytest.fixture(scope="module")
def shapes():
    X, y = make_shapes(2, n_points=160, random_state=0, return_X_y=True)
    return X, y


def _round_trip(obj, tmp_path, name="model.joblib"):
    path = tmp_path / name
    save_model(obj, path)
    assert zipfile.is_zipfile(path)
    return load_model(path)


def _descriptors(n=12, bins=24, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.random((n, bins)) * (rng.random((n, bins)) > 0.4)
    X[:, 0] += 1e-3
    return X / X.sum(axis=1, keepdims=True), np.array(["chair", "table", "lamp"])[np.arange(n) % 3]


# ---------------------------------------------------------------- round trips
@pytest.mark.parametrize("params", [{}, {"n_neighbors": 3, "weights": "distance", "renormalize": True},
                                    {"floor": 1e-4, "chunk_size": 2}])
def test_kl_nearest_neighbors_round_trip_is_exact(tmp_path, params):
    X, y = _descriptors()
    Q, _ = _descriptors(seed=1)
    clf = KLNearestNeighbors(**params).fit(X, y)
    back = _round_trip(clf, tmp_path)
    assert type(back) is KLNearestNeighbors and back.get_params() == clf.get_params()
    assert back.floor_ == clf.floor_ and back.n_samples_fit_ == clf.n_samples_fit_
    assert_array_equal(back.classes_, clf.classes_)
    for a, b in zip(back._fit_data, clf._fit_data):  # the rebuilt private state, bit for bit
        assert_array_equal(a, b)
    assert_array_equal(back.predict(Q), clf.predict(Q))
    assert_array_equal(back.predict_proba(Q), clf.predict_proba(Q))
    for a, b in zip(back.kneighbors(Q), clf.kneighbors(Q)):
        assert_array_equal(a, b)
    assert_array_equal(back.kneighbors(return_distance=False), clf.kneighbors(return_distance=False))


@pytest.mark.parametrize("labels", [np.array(["2020-01-01", "2021-06-30", "2022-12-31"], dtype="datetime64[D]"),
                                    np.array([1, 5, 60], dtype="timedelta64[s]")])
@pytest.mark.parametrize("kind", ["kl", "eppf"])
def test_time_labels_round_trip(tmp_path, labels, kind):
    # fit accepts dates and time spans as labels (scikit-learn's check does); load_model
    # refused the classes_ of the very file save_model wrote from them
    X, names = _descriptors()
    y = labels[np.searchsorted(np.unique(names), names)]
    if kind == "kl":
        clf = KLNearestNeighbors().fit(X, y)
    else:
        clf = EPPF4DClassifier(n_bins=(2, 2, 3, 2), filters=(2, 2, 2), n_hidden=4, max_epochs=1,
                               early_stopping=False, precision="float32", random_state=0, verbose=0).fit(X, y)
    back = _round_trip(clf, tmp_path)
    assert back.classes_.dtype == labels.dtype
    assert_array_equal(back.classes_, labels)
    assert_array_equal(back.predict(X), clf.predict(X))


@pytest.mark.parametrize("make", [
    lambda: EPPFTransformer(n_bins=(6, 2, 3, 2), n_pairs=400, random_state=3),
    lambda: ESFTransformer(n_triplets=400, n_bins=8, random_state=3),
    lambda: WahlTransformer(n_bins=3, n_pairs=400, random_state=3),
    lambda: OURCVFHTransformer(),
], ids=["eppf", "esf", "wahl", "ourcvfh"])
def test_descriptor_pipelines_round_trip(tmp_path, shapes, make):
    X, y = shapes
    steps = [("descriptor", make())]
    if isinstance(steps[0][1], OURCVFHTransformer):
        steps.append(("l1", Normalizer(norm="l1")))
    model = Pipeline(steps + [("classifier", KLNearestNeighbors())]).fit(X[::2], y[::2])
    back = _round_trip(model, tmp_path)
    assert [n for n, _ in back.steps] == [n for n, _ in model.steps]
    assert back.get_params(deep=True).keys() == model.get_params(deep=True).keys()
    assert_array_equal(back[:-1].transform(X[1::2]), model[:-1].transform(X[1::2]))
    assert_array_equal(back.predict(X[1::2]), model.predict(X[1::2]))


def test_unfitted_estimator_and_random_state_instance_round_trip(tmp_path, shapes):
    est = EPPFTransformer(n_pairs=300, random_state=np.random.RandomState(5))
    back = _round_trip(est, tmp_path)
    assert isinstance(back.random_state, np.random.RandomState)
    # same generator state: both draw the same descriptors
    X, _ = shapes
    assert_array_equal(back.fit_transform(X[:3]), est.fit_transform(X[:3]))


def test_allow_listed_sklearn_estimators_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 6))
    y = (X[:, 0] + X[:, 1] > 0).astype(int)
    model = Pipeline([("scale", StandardScaler()), ("pca", PCA(3, random_state=0)),
                      ("lr", LogisticRegression())]).fit(X, y)
    back = _round_trip(model, tmp_path)
    assert_array_equal(back.predict_proba(X), model.predict_proba(X))


def test_cli_style_dict_round_trips_with_plain_values(tmp_path):
    X, y = _descriptors()
    saved = {"format": "eppf-model", "model": KLNearestNeighbors().fit(X, y), "eppf_version": eppf.__version__,
             "params": {"n_bins": [20, 4, 5, 3], "scaling": None, "test_size": 0.25, "all": False,
                        "nested": {"t": (1, 2.5), "nan": float("nan"), "i64": np.int64(7)}},
             "classes": ["chair", "lamp", "table"], "data": "x.npz", "names": np.array(["a", "b"], dtype=object)}
    back = _round_trip(saved, tmp_path)
    assert list(back) == list(saved)
    assert back["params"]["nested"]["t"] == (1, 2.5) and np.isnan(back["params"]["nested"]["nan"])
    assert back["params"]["nested"]["i64"] == 7 and back["params"]["nested"]["i64"].dtype == np.int64
    assert {k: v for k, v in back["params"].items() if k != "nested"} == \
        {k: v for k, v in saved["params"].items() if k != "nested"}
    assert back["names"].dtype == object and back["names"].tolist() == ["a", "b"]
    assert_array_equal(back["model"].predict(X), saved["model"].predict(X))


def test_eppf4d_classifier_round_trip_predicts_identically(tmp_path):
    import torch

    X, y = _descriptors(n=12, bins=6 * 2 * 2 * 2)
    clf = EPPF4DClassifier(n_bins=(6, 2, 2, 2), max_epochs=2, n_hidden=8, filters=(2, 2, 2), batch_size=4,
                           early_stopping=False, random_state=0).fit(X, y)
    before = torch.random.get_rng_state()
    back = _round_trip(clf, tmp_path)
    assert torch.equal(torch.random.get_rng_state(), before)  # rebuilding does not touch the caller's stream
    assert_array_equal(back.predict_proba(X), clf.predict_proba(X))
    assert_array_equal(back.predict(X), clf.predict(X))
    assert back.n_epochs_ == clf.n_epochs_ == len(back.net_.history)
    assert_array_equal(back.input_mean_, clf.input_mean_)


def _cpu_with_native_bfloat16(monkeypatch, native):
    from eppf.nn import _precision

    monkeypatch.setattr(_precision, "native_bfloat16", lambda device="cpu", **kw: native)


@pytest.mark.parametrize("native", [False, True])
def test_eppf4d_classifier_keeps_its_precision_across_save_and_load(tmp_path, monkeypatch, native):
    # "auto" is resolved once, in fit; the model loads in that precision on any machine.
    X, y = _descriptors(n=12, bins=6 * 2 * 2 * 2)
    _cpu_with_native_bfloat16(monkeypatch, native)
    clf = EPPF4DClassifier(n_bins=(6, 2, 2, 2), max_epochs=2, n_hidden=8, filters=(2, 2, 2), batch_size=4,
                           early_stopping=False, random_state=0).fit(X, y)
    assert clf.precision_ == ("bfloat16" if native else "float32")
    _cpu_with_native_bfloat16(monkeypatch, not native)  # loaded where "auto" would choose the other
    back = _round_trip(clf, tmp_path)
    assert back.precision == "auto" and back.precision_ == clf.precision_
    assert back.net_.module_.precision == clf.precision_
    assert_array_equal(back.predict_proba(X), clf.predict_proba(X))


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_eppf4d_classifier_saved_before_precision_existed_still_loads(tmp_path, precision):
    # Files written before precision_ existed hold an explicit precision ("auto" did not exist either).
    X, y = _descriptors(n=12, bins=6 * 2 * 2 * 2)
    clf = EPPF4DClassifier(n_bins=(6, 2, 2, 2), max_epochs=2, n_hidden=8, filters=(2, 2, 2), batch_size=4,
                           early_stopping=False, precision=precision, random_state=0).fit(X, y)
    path = tmp_path / "old.eppf"
    save_model(clf, path)

    def drop(m):
        del m["root"]["attributes"]["precision_"]
        return m

    _rewrite(path, manifest=drop)
    from eppf.nn import BFloat16EmulationWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BFloat16EmulationWarning)  # should this CPU emulate it
        back = load_model(path)
    assert not hasattr(back, "precision_")
    assert back.net_.module_.precision == precision
    assert_array_equal(back.predict_proba(X), clf.predict_proba(X))
    # a trusted pickle of such a model too
    del clf.precision_
    joblib.dump(clf, tmp_path / "old.joblib")
    assert_array_equal(load_model(tmp_path / "old.joblib", trust=True).predict_proba(X), back.predict_proba(X))


def test_pointnet_classifier_round_trip_predicts_identically(tmp_path, shapes):
    X, y = shapes
    clf = PointNetClassifier(n_points=32, max_epochs=1, batch_size=8, early_stopping=False, random_state=0)
    clf.fit(X[:8], y[:8])
    back = _round_trip(clf, tmp_path)
    assert_array_equal(back.predict_proba(X[8:]), clf.predict_proba(X[8:]))


def test_objects_outside_the_format_are_refused_and_nothing_is_written(tmp_path):
    model = Pipeline([("f", FunctionTransformer(np.sqrt)), ("knn", KLNearestNeighbors())])
    with pytest.raises(TypeError, match="FunctionTransformer"):
        save_model(model, tmp_path / "m.eppf")
    with pytest.raises(TypeError, match=r"model\['x'\]: objects of type builtins.function"):
        save_model({"x": lambda v: v}, tmp_path / "m.eppf")
    assert os.listdir(tmp_path) == []


# ----------------------------------------------------------------- pickles
class _WritesMarker:
    """Unpickling this calls ``open(marker, "w")``: code run by loading."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_pickle_with_code_payload_is_refused_without_trust(tmp_path):
    marker = tmp_path / "payload-ran"
    X, y = _descriptors()
    path = tmp_path / "evil.joblib"
    # a real model plus the payload: it would load and predict normally
    joblib.dump({"format": "eppf-model", "model": KLNearestNeighbors().fit(X, y), "x": _WritesMarker(str(marker))},
                path)
    with pytest.raises(ValueError, match=re.escape(str(path))) as info:
        load_model(path)
    assert "trust=True" in str(info.value) and "--trust" in str(info.value)
    assert "run any code" in str(info.value)
    assert not marker.exists()
    # the same through the command line: one-line error, status 1, payload not run
    from eppf.cli import main

    cloud = tmp_path / "c.xyz"
    np.savetxt(cloud, np.random.default_rng(0).normal(size=(40, 3)))
    assert main(["predict", str(cloud), "--model", str(path), "--no-progress"]) == 2
    assert not marker.exists()
    # plain pickle.dump files are refused the same way
    with open(tmp_path / "evil.pkl", "wb") as fh:
        pickle.dump(_WritesMarker(str(marker)), fh)
    with pytest.raises(ValueError, match="trust=True"):
        load_model(tmp_path / "evil.pkl")
    assert not marker.exists()


def test_trust_loads_an_old_pickled_model(tmp_path):
    X, y = _descriptors()
    clf = KLNearestNeighbors().fit(X, y)
    marker = tmp_path / "harmless"
    path = tmp_path / "old.joblib"
    joblib.dump({"format": "eppf-model", "model": clf, "touch": _WritesMarker(str(marker))}, path)
    old = load_model(path, trust=True)
    assert marker.exists()  # trust=True does run what the pickle holds: why it is not the default
    assert_array_equal(old["model"].predict(X), clf.predict(X))
    # converting it: save again, and the new file loads without trust
    del old["touch"]
    back = _round_trip(old, tmp_path, "new.eppf")
    assert_array_equal(back["model"].predict(X), clf.predict(X))


# ---------------------------------------------------------- hostile files
def _rewrite(path, manifest=None, arrays=None):
    """Rewrite a model file with a changed manifest and/or arrays."""
    with zipfile.ZipFile(path) as zf:
        text = zf.read("manifest.json")
        blob = zf.read("arrays.npz")
    if manifest is not None:
        text = json.dumps(manifest(json.loads(text)))
    if arrays is not None:
        blob = arrays(blob)
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("manifest.json", text)
        zf.writestr("arrays.npz", blob)


@pytest.fixture
def model_file(tmp_path):
    X, y = _descriptors()
    path = tmp_path / "m.eppf"
    save_model(Pipeline([("l1", Normalizer(norm="l1")), ("knn", KLNearestNeighbors().fit(X, y))]), path)
    return path


def test_class_not_on_the_allow_list_is_refused(model_file):
    def swap(m):
        m["root"]["params"]["steps"][0]["items"][1]["class"] = "os.system"
        return m

    _rewrite(model_file, manifest=swap)
    with pytest.raises(ValueError, match=re.escape(str(model_file)) + ".*'os.system' is not on the allow-list"):
        load_model(model_file)


@pytest.mark.parametrize("change, message", [
    (lambda m: dict(m, format_version=99), "format version 99"),
    (lambda m: dict(m, format="other"), "does not describe an eppf model"),
    (lambda m: {k: v for k, v in m.items() if k != "eppf_version"}, "does not record the eppf version"),
    (lambda m: dict(m, root={"__type__": "function", "name": "os.system"}), "unknown node type 'function'"),
    (lambda m: dict(m, root={"__type__": "ndarray", "ref": "a999"}), "not in arrays.npz"),
])
def test_bad_manifest_gives_value_error_naming_the_file(model_file, change, message):
    _rewrite(model_file, manifest=change)
    with pytest.raises(ValueError, match=re.escape(str(model_file))) as info:
        load_model(model_file)
    assert message in str(info.value)


def test_newer_eppf_version_warns(model_file):
    _rewrite(model_file, manifest=lambda m: dict(m, eppf_version="99.0"))
    with pytest.warns(UserWarning, match="saved by eppf 99.0, which is newer"):
        load_model(model_file)
    _rewrite(model_file, manifest=lambda m: dict(m, eppf_version="0.0.1"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_model(model_file)  # older: no warning


def _npz(**arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def test_arrays_of_python_objects_are_refused(model_file, tmp_path):
    marker = tmp_path / "payload-ran"
    evil = np.empty(1, dtype=object)
    evil[0] = _WritesMarker(str(marker))
    _rewrite(model_file, manifest=lambda m: dict(m, root={"__type__": "ndarray", "ref": "a0"}),
             arrays=lambda blob: _npz(a0=evil))
    with pytest.raises(ValueError, match="holds Python objects"):
        load_model(model_file)
    assert not marker.exists()


def test_array_header_promising_more_data_than_stored_is_refused(model_file):
    def lie(blob):
        good = _npz(a0=np.zeros(4))
        with zipfile.ZipFile(io.BytesIO(good)) as zf:
            data = zf.read("a0.npy")
        data = data.replace(b"(4,)", b"(9,)")
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w") as zf:
            zf.writestr("a0.npy", data)
        return out.getvalue()

    _rewrite(model_file, manifest=lambda m: dict(m, root={"__type__": "ndarray", "ref": "a0"}), arrays=lie)
    with pytest.raises(ValueError, match=r"declares shape \(9,\)"):
        load_model(model_file)


@pytest.mark.parametrize("cut", [30, 200, -100, -10])
def test_truncated_model_file_gives_value_error_naming_it(model_file, cut):
    data = model_file.read_bytes()
    model_file.write_bytes(data[:cut])
    with pytest.raises(ValueError, match=re.escape(f"cannot load model {model_file}")):
        load_model(model_file)


def test_corrupted_bytes_inside_the_container_are_detected(model_file):
    data = bytearray(model_file.read_bytes())
    with zipfile.ZipFile(model_file) as zf:
        info = zf.getinfo("arrays.npz")
    mid = info.header_offset + 30 + len(info.filename) + info.compress_size // 2
    data[mid] ^= 0xFF
    model_file.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=re.escape(str(model_file))):
        load_model(model_file)


def test_central_directory_offset_past_the_entries_gives_value_error_naming_the_file(model_file):
    # the end record's central-directory offset moved on: zipfile places every entry before byte 0 and its
    # seek fails with EINVAL (an OSError that named nothing)
    data = bytearray(model_file.read_bytes())
    end = data.rindex(b"PK\x05\x06")
    offset = struct.unpack_from("<I", data, end + 16)[0]
    struct.pack_into("<I", data, end + 16, offset + 2**24)
    model_file.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=re.escape(f"cannot load model {model_file}: corrupt model file")):
        load_model(model_file)


def test_other_files_give_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such model file"):
        load_model(tmp_path / "missing.eppf")
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01garbage" * 10)
    with pytest.raises(ValueError, match="not an eppf model file"):
        load_model(junk)
    with pytest.raises(ValueError, match="cannot load model"):
        load_model(junk, trust=True)
    other_zip = tmp_path / "other.zip"
    with zipfile.ZipFile(other_zip, "w") as zf:
        zf.writestr("readme.txt", "hi")
    with pytest.raises(ValueError, match="no manifest.json"):
        load_model(other_zip)


# ------------------------------------------------------------- command line
def test_cli_train_writes_a_safe_file_that_predict_and_evaluate_read(tmp_path, capsys):
    from eppf.cli import main

    model = tmp_path / "m.joblib"
    assert main(["train", "--built-in", "-o", str(model), "--n-pairs", "300", "--n-jobs", "1", "--no-progress"]) == 0
    assert zipfile.is_zipfile(model)
    saved = load_model(model)
    assert saved["format"] == "eppf-model" and len(saved["classes"]) == 10
    assert saved["params"]["n_pairs"] == 300 and saved["params"]["classifier"] == "kl"
    X, _ = make_shapes(1, random_state=9, return_X_y=True)
    folder = tmp_path / "clouds"
    folder.mkdir()
    for i, cloud in enumerate(X[:2]):
        np.savetxt(folder / f"{i}.xyz", cloud)
    capsys.readouterr()
    assert main(["predict", str(folder), "--model", str(model), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert err == "" and out.count(str(folder)) == 2
    # an old pickled model: refused with a hint, accepted with --trust
    old = tmp_path / "old.joblib"
    joblib.dump(saved, old)
    assert main(["predict", str(folder), "--model", str(old), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--trust" in err and len(err.strip().splitlines()) == 1
    assert main(["predict", str(folder), "--model", str(old), "--trust", "--no-progress"]) == 0
    assert capsys.readouterr().out == out


def test_every_model_option_documents_safety_and_trust():
    from eppf.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    with_model = 0
    for name, p in sub.choices.items():
        actions = {a.dest: a for a in p._actions}
        if "model" in actions:
            with_model += 1
            assert "safe" in actions["model"].help and "--trust" in actions["model"].help
            assert "trust" in actions and "run any code" in actions["trust"].help
    assert with_model == 2


def test_hostile_values_in_the_tree_give_value_errors_naming_the_file(model_file):
    with zipfile.ZipFile(model_file) as zf:
        manifest = json.loads(zf.read("manifest.json"))
    ref = manifest["root"]["params"]["steps"][1]["items"][1]["attributes"]["_fit_data"]["H"]
    # training histograms that are not positive
    _rewrite(model_file, manifest=lambda m: dict(m, root={"__type__": "kl_prepared", "H": ref}),
             arrays=lambda blob: _npz(**{ref: -np.ones((2, 3))}))
    with pytest.raises(ValueError, match=re.escape(str(model_file)) + ".*positive finite"):
        load_model(model_file)
    # values an estimator's own code rejects while rebuilding
    _rewrite(model_file, manifest=lambda m: dict(m, root={"__type__": "kl_prepared", "H": ref}),
             arrays=lambda blob: _npz(**{ref: np.full((2, 3), 1e308)}))
    with pytest.raises(ValueError, match=re.escape(str(model_file)) + ".*too large"):
        load_model(model_file)
    deep = "[" * 100_000 + "]" * 100_000
    with zipfile.ZipFile(model_file, "w") as zf:
        zf.writestr("manifest.json", '{"format": "eppf-model", "format_version": 1, "eppf_version": "0.1.0", '
                    f'"root": {deep}}}')
        zf.writestr("arrays.npz", _npz())
    with pytest.raises(ValueError, match=re.escape(str(model_file))):
        load_model(model_file)


def test_every_registered_descriptor_round_trips(tmp_path):
    # the allow-list covers every descriptor the registry offers, so 'eppf train --descriptor X' can save
    from eppf.datasets import make_shapes
    from eppf.registry import DESCRIPTORS

    X, y = make_shapes(2, n_points=96, classes=["box", "sphere"], return_X_y=True, random_state=0)
    for name, spec in DESCRIPTORS.items():
        est = spec.make(n_samples=300, random_state=0, n_jobs=1).fit(X)
        path = tmp_path / f"{name}.eppf"
        save_model(est, path)
        back = load_model(path)
        assert type(back) is type(est), name
        np.testing.assert_array_equal(back.transform(X), est.transform(X), err_msg=name)


def test_trusted_eppf_0_1_pickle_still_loads_and_predicts():
    # tests/data/model_0_1.joblib: a Pipeline(EPPFTransformer, KLNearestNeighbors) pickled by eppf 0.1.0,
    # whose classes lived in the flat modules (eppf._descriptor, eppf._neighbors) of that layout
    from eppf.datasets import make_shapes

    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "model_0_1.joblib")
    with pytest.raises(ValueError, match="trust=True"):
        load_model(path)
    model = load_model(path, trust=True)
    Q, _ = make_shapes(1, n_points=96, classes=["box", "sphere"], return_X_y=True, random_state=1)
    np.testing.assert_array_equal(model.predict(Q), [0, 1])
    import sys

    assert "eppf._descriptor" not in sys.modules  # the old names were only aliases while loading


def test_a_pickle_that_ends_in_a_zip_archive_is_a_pickle(tmp_path):
    # zipfile.is_zipfile finds an archive's end record in a file's last bytes (as a pickled
    # torch module's state can leave there); such a file is still a pickle: refused unless trusted
    import io
    import pickle
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("data.pkl", b"x")
    path = tmp_path / "old.joblib"
    path.write_bytes(pickle.dumps(["model"], protocol=4) + buf.getvalue())
    assert zipfile.is_zipfile(path)
    with pytest.raises(ValueError, match="is not an eppf model in the safe format but a pickle"):
        load_model(path)


# ------------------------------------------- hand-edited fitted state and parameters
# A hand-edited file whose estimator has parameters its code refuses, or fitted attributes missing or of
# another kind than fit sets, loaded and then failed in predict or transform with an AttributeError,
# IndexError or TypeError naming neither the file nor the problem; it is refused at load.
@pytest.fixture(scope="module")
def fitted_models(tmp_path_factory):
    from eppf.descriptors import DescriptorUnion

    X, y = make_shapes(2, n_points=96, classes=["box", "sphere"], return_X_y=True, random_state=0)
    H, yh = _descriptors(n=12, bins=4 * 2 * 2 * 2)
    eppf_t = EPPFTransformer(n_bins=(4, 2, 2, 2), n_pairs=300, random_state=0)
    models = {
        "kl": Pipeline([("l1", Normalizer(norm="l1")), ("knn", KLNearestNeighbors(n_neighbors=2))]).fit(H, yh),
        "eppf": eppf_t.fit(X),
        "union": DescriptorUnion([("e", EPPFTransformer(n_bins=(4, 2, 2, 2), n_pairs=300, random_state=0)),
                                  ("s", ESFTransformer(n_triplets=300, n_bins=4, random_state=0))]).fit(X),
        "cnn": EPPF4DClassifier(n_bins=(4, 2, 2, 2), max_epochs=1, n_hidden=4, filters=(2, 2, 2), batch_size=4,
                                early_stopping=False, random_state=0).fit(H, yh),
        "sklearn": Pipeline([("scale", StandardScaler()), ("pca", PCA(2, random_state=0)),
                             ("lr", LogisticRegression())]).fit(H, yh),
    }
    folder = tmp_path_factory.mktemp("fitted")
    for name, model in models.items():
        save_model(model, folder / f"{name}.eppf")
    return folder


def _estimator_node(manifest, cls):
    """The first estimator node of class ``cls`` in a manifest's tree."""
    def walk(node):
        if isinstance(node, dict):
            if node.get("__type__") == "estimator" and node["class"] == cls:
                return node
            node = list(node.values())
        if isinstance(node, list):
            for v in node:
                found = walk(v)
                if found is not None:
                    return found
        return None

    return walk(manifest["root"])


def _array_of(value):
    return lambda blob: _npz(**dict(np.load(io.BytesIO(blob))), edited=value)


_EDITED = {"__type__": "ndarray", "ref": "edited"}


@pytest.mark.parametrize("model, cls, change, arrays, message", [
    # parameters the estimator's own validation refuses
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["params"].update(n_neighbors=-1), None, "n_neighbors must be"),
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["params"].update(weights=None), None, "weights must be"),
    ("sklearn", "sklearn.decomposition.PCA", lambda n: n["params"].update(n_components="x"), None, "n_components"),
    # KLNearestNeighbors: attributes missing, of another kind, disagreeing with each other
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["attributes"].pop("classes_"), None, "classes_ is missing"),
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["attributes"].pop("_fit_data"), None, "_fit_data is missing"),
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["attributes"].update(classes_=["chair", "lamp", "table"]), None,
     "classes_ must be a non-empty 1D array"),
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["attributes"].update(floor_=None), None,
     "floor_ must be a positive finite float"),
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["attributes"].update(n_samples_fit_=3), None,
     "n_samples_fit_ must be the number of training histograms"),
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["attributes"].update(n_features_in_=5), None,
     "n_features_in_ is 5 but the training histograms have 32 bins"),
    ("kl", "eppf.KLNearestNeighbors", lambda n: n["attributes"].update(_y=_EDITED), _array_of(np.arange(12) % 4),
     "_y must be an int array of one index into classes_"),
    ("kl", "sklearn.preprocessing.Normalizer", lambda n: n["attributes"].update(n_features_in_="x"), None,
     "n_features_in_ must be a positive int"),
    # descriptors
    ("eppf", "eppf.EPPFTransformer", lambda n: n["attributes"].pop("n_bins_"), None, "n_bins_ is missing"),
    ("eppf", "eppf.EPPFTransformer", lambda n: n["attributes"].update(n_features_out_=7), None,
     "n_features_out_ is 7 but its parameters give 32"),
    ("eppf", "eppf.EPPFTransformer", lambda n: n["attributes"].update(scale_="x"), None, "scale_ must be a positive"),
    ("eppf", "eppf.EPPFTransformer", lambda n: n["attributes"].update(scale_=None), None,
     "scale_ must be a positive finite float (scaling='fit')"),
    ("eppf", "eppf.EPPFTransformer",  # an EPPF node relabelled as another descriptor of the allow-list
     lambda n: n.update({"class": "eppf.GASDTransformer", "params": {}}), None, "n_features_out_ is 32 but"),
    ("union", "eppf.DescriptorUnion", lambda n: n["attributes"].update(weights_=_EDITED), _array_of(np.array([1.0, np.nan])),
     "weights_ must be a float array of one weight per block"),
    ("union", "eppf.DescriptorUnion", lambda n: n["attributes"]["feature_slices_"]["items"].pop("s"), None,
     "feature_slices_['s'] must be slice(32, "),
    ("union", "eppf.DescriptorUnion",  # a classifier where a fitted block was
     lambda n: n["attributes"]["transformers_"][0]["items"].__setitem__(1, {
         "__type__": "estimator", "class": "eppf.KLNearestNeighbors", "params": {}, "attributes": {}}), None,
     "transformers_ must be a non-empty list of (name, fitted descriptor) pairs"),
    # the 4D network's classifier and the scikit-learn classes
    ("cnn", "eppf.EPPF4DClassifier", lambda n: n["attributes"].update(input_mean_=[0.0]), None,
     "input_mean_ must be a float array"),
    ("cnn", "eppf.EPPF4DClassifier", lambda n: n["attributes"].update(n_features_in_=31), None,
     "n_features_in_ must be prod(n_bins) + n_side_features_"),
    ("cnn", "eppf.EPPF4DClassifier", lambda n: n["attributes"].pop("side_mean_"), None, "side_mean_ is missing"),
    ("sklearn", "sklearn.linear_model.LogisticRegression", lambda n: n["attributes"].pop("coef_"), None,
     "coef_ is missing"),
    ("sklearn", "sklearn.preprocessing.StandardScaler", lambda n: n["attributes"].update(scale_=_EDITED),
     _array_of(np.ones(5)), "scale_ must be None or a float array of n_features_in_ values"),
    ("sklearn", "sklearn.preprocessing.StandardScaler", lambda n: n["attributes"].update(mean_=None), None,
     "mean_ must be a float array (with_mean=True)"),
])
def test_broken_parameters_or_fitted_state_are_refused_at_load(fitted_models, tmp_path, model, cls, change, arrays,
                                                               message):
    path = tmp_path / "edited.eppf"
    path.write_bytes((fitted_models / f"{model}.eppf").read_bytes())

    def edit(m):
        change(_estimator_node(m, cls))
        return m

    _rewrite(path, manifest=edit, arrays=arrays)
    with pytest.raises(ValueError, match=re.escape(str(path))) as info:
        load_model(path)
    assert message in str(info.value)


def test_unedited_fitted_models_pass_the_load_checks(fitted_models):
    for name in ("kl", "eppf", "union", "cnn", "sklearn"):
        assert load_model(fitted_models / f"{name}.eppf") is not None


def test_every_allow_listed_estimator_fitted_the_usual_ways_loads(tmp_path):
    # The load checks must not refuse what eppf itself saves: every registered descriptor fitted by fit or
    # partial_fit, a pool fitted only (no pool computed yet: no n_features_out_) or by fit_transform, the
    # perturbations, and the scikit-learn steps in their variants (no centering, binary and multiclass).
    from sklearn.base import clone
    from sklearn.preprocessing import MaxAbsScaler, MinMaxScaler

    from eppf.descriptors import DescriptorPool, GASDColorTransformer, ProportionTransformer
    from eppf.preprocessing import GaussianNoise, Occlusion, RandomDropout, RandomRotation, RandomScaling, Resampler
    from eppf.registry import make_descriptor

    X, y = make_shapes(2, n_points=96, classes=["box", "sphere", "cylinder"], return_X_y=True, random_state=0)
    colored = [np.hstack([c, np.full((len(c), 3), 0.5)]) for c in X]
    H, yh = _descriptors(n=12, bins=4 * 2 * 2 * 2)
    small = dict(eppf=dict(n_pairs=300), eppf_short=dict(n_pairs=300), esf=dict(n_triplets=300),
                 wahl=dict(n_pairs=300))
    models = []
    for name in ("ourcvfh", "esf", "wahl", "eppf_short", "eppf", "vfh", "gasd", "cvfh", "grsd", "eppf+gasd"):
        est = make_descriptor(name, **small.get(name, {}))
        models += [clone(est).fit(X), clone(est).partial_fit(X[:3]).partial_fit(X[3:])]
    models += [GASDColorTransformer().fit(colored), ProportionTransformer().fit(X)]
    pool = DescriptorPool(make_descriptor("gasd"), 2, augment=RandomScaling(), random_state=0)
    computed = clone(pool)
    computed.fit_transform(X)
    models += [clone(pool).fit(X), computed]
    models += [t.fit(X) for t in (GaussianNoise(), Occlusion(), RandomDropout(), RandomRotation(), RandomScaling(),
                                  Resampler(64))]
    models += [StandardScaler(with_mean=False).fit(H), StandardScaler(with_std=False).fit(H), MinMaxScaler().fit(H),
               MaxAbsScaler().fit(H), PCA(3).fit(H), LogisticRegression().fit(H, yh),
               LogisticRegression().fit(H, yh == "chair"), KLNearestNeighbors(n_neighbors=3).fit(H, yh)]
    for k, model in enumerate(models):
        save_model(model, tmp_path / f"m{k}.eppf")
        back = load_model(tmp_path / f"m{k}.eppf")
        assert type(back) is type(model), model
