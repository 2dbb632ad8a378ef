"""Model files that loading cannot turn into running code.

A model file is a zip container with two members:

``manifest.json``
    The format name and version, the eppf version that wrote the file and
    the saved object as a tree: estimators by class name (from a fixed
    allow-list) with their ``get_params()`` values and fitted attributes,
    numbers, strings, lists, tuples and string-keyed dicts as JSON, and
    arrays by reference.
``arrays.npz``
    The arrays, written and read by NumPy with ``allow_pickle=False``.

Loading builds estimators only from the allow-list, by calling the class
with the recorded parameters and setting the recorded attributes; nothing in
the file names a function or module to import. The torch networks of
:class:`~eppf.EPPF4DClassifier` and :class:`~eppf.PointNetClassifier` are
stored as their ``state_dict`` tensors and rebuilt for prediction.

Models written by eppf 0.1 are pickles (joblib files); :func:`load_model`
opens them only with ``trust=True``.
"""

import errno
import json
import math
import numbers
import os
import shutil
import tempfile
import warnings
import zipfile
import zlib

import numpy as np

from ._version import __version__
from .utils._atomic import atomic_write

__all__ = ["load_model", "save_model"]

FORMAT = "eppf-model"
FORMAT_VERSION = 1

_MANIFEST = "manifest.json"
_ARRAYS = "arrays.npz"
_MAX_MANIFEST_BYTES = 64 << 20

#: Classes a model file may hold: the name written to the file -> (module, attribute).
ALLOWED = {
    "eppf.EPPFTransformer": ("eppf.descriptors", "EPPFTransformer"),
    "eppf.ESFTransformer": ("eppf.descriptors", "ESFTransformer"),
    "eppf.WahlTransformer": ("eppf.descriptors", "WahlTransformer"),
    "eppf.OURCVFHTransformer": ("eppf.descriptors", "OURCVFHTransformer"),
    "eppf.VFHTransformer": ("eppf.descriptors", "VFHTransformer"),
    "eppf.CVFHTransformer": ("eppf.descriptors", "CVFHTransformer"),
    "eppf.GASDTransformer": ("eppf.descriptors", "GASDTransformer"),
    "eppf.GASDColorTransformer": ("eppf.descriptors", "GASDColorTransformer"),
    "eppf.GRSDTransformer": ("eppf.descriptors", "GRSDTransformer"),
    "eppf.DescriptorUnion": ("eppf.descriptors", "DescriptorUnion"),
    "eppf.DescriptorPool": ("eppf.descriptors", "DescriptorPool"),
    "eppf.ProportionTransformer": ("eppf.descriptors", "ProportionTransformer"),
    "eppf.EPPFGASDTransformer": ("eppf.descriptors", "EPPFGASDTransformer"),
    "eppf.KLNearestNeighbors": ("eppf.neighbors", "KLNearestNeighbors"),
    "eppf.EPPF4DClassifier": ("eppf.classifiers", "EPPF4DClassifier"),
    "eppf.PointNetClassifier": ("eppf.classifiers", "PointNetClassifier"),
    "eppf.preprocessing.GaussianNoise": ("eppf.preprocessing", "GaussianNoise"),
    "eppf.preprocessing.RandomDropout": ("eppf.preprocessing", "RandomDropout"),
    "eppf.preprocessing.Occlusion": ("eppf.preprocessing", "Occlusion"),
    "eppf.preprocessing.RandomRotation": ("eppf.preprocessing", "RandomRotation"),
    "eppf.preprocessing.RandomScaling": ("eppf.preprocessing", "RandomScaling"),
    "eppf.preprocessing.Resampler": ("eppf.preprocessing", "Resampler"),
    "sklearn.pipeline.Pipeline": ("sklearn.pipeline", "Pipeline"),
    "sklearn.preprocessing.Normalizer": ("sklearn.preprocessing", "Normalizer"),
    "sklearn.preprocessing.StandardScaler": ("sklearn.preprocessing", "StandardScaler"),
    "sklearn.preprocessing.MinMaxScaler": ("sklearn.preprocessing", "MinMaxScaler"),
    "sklearn.preprocessing.MaxAbsScaler": ("sklearn.preprocessing", "MaxAbsScaler"),
    "sklearn.decomposition.PCA": ("sklearn.decomposition", "PCA"),
    "sklearn.linear_model.LogisticRegression": ("sklearn.linear_model", "LogisticRegression"),
}

# Estimators whose ``net_`` is a skorch network, rebuilt from its state_dict.
_NET_OWNERS = ("eppf.EPPF4DClassifier", "eppf.PointNetClassifier")

_TORCH_DTYPES = ("float32", "float64", "float16", "bfloat16", "int64", "int32", "int16", "int8", "uint8", "bool")


def _import_class(name):
    import importlib

    module, attr = ALLOWED[name]
    return getattr(importlib.import_module(module), attr)


def _class_name(obj):
    """The allow-list name of ``obj``'s exact class, or None."""
    cls = type(obj)
    for name, (module, attr) in ALLOWED.items():
        if cls.__name__ == attr and (cls.__module__ == module or cls.__module__.startswith(module + ".")):
            if _import_class(name) is cls:
                return name
    return None


# ------------------------------------------------------------------- encoding
class _Encoder:
    def __init__(self):
        self.arrays = {}

    def array(self, arr):
        key = f"a{len(self.arrays)}"
        self.arrays[key] = arr
        return key

    def encode(self, value, where):
        if value is None or isinstance(value, (bool, str)):
            return value
        if isinstance(value, numbers.Integral) and type(value) is int:
            return value
        if type(value) is float:
            return value if math.isfinite(value) else {"__type__": "float", "value": repr(value)}
        if isinstance(value, np.ndarray):
            return self._ndarray(value, where)
        if isinstance(value, np.generic):
            if value.dtype.hasobject:
                raise TypeError(f"save_model: cannot save {where}: numpy object scalars are not supported")
            return {"__type__": "npscalar", "ref": self.array(np.asarray(value))}
        if isinstance(value, list):
            return [self.encode(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if isinstance(value, tuple) and type(value) is tuple:
            return {"__type__": "tuple", "items": [self.encode(v, f"{where}[{i}]") for i, v in enumerate(value)]}
        if type(value) is slice:
            parts = (value.start, value.stop, value.step)
            if not all(v is None or (isinstance(v, int) and not isinstance(v, bool)) for v in parts):
                raise TypeError(f"save_model: cannot save {where}: a slice of non-integers")
            return {"__type__": "slice", "items": list(parts)}
        if type(value) is dict:
            for k in value:
                if not isinstance(k, str):
                    raise TypeError(f"save_model: cannot save {where}: dict keys must be str, got {type(k).__name__}")
            return {"__type__": "dict", "items": {k: self.encode(v, f"{where}[{k!r}]") for k, v in value.items()}}
        if isinstance(value, np.random.RandomState):
            kind, keys, pos, has_gauss, cached = value.get_state()
            return {"__type__": "random_state", "keys": self.array(np.asarray(keys)), "pos": int(pos),
                    "has_gauss": int(has_gauss), "cached_gaussian": self.encode(float(cached), where)}
        prepared = _prepared_type()
        if isinstance(value, prepared):
            return {"__type__": "kl_prepared", "H": self.array(np.asarray(value.H))}
        name = _class_name(value)
        if name is not None:
            return self._estimator(value, name, where)
        raise TypeError(
            f"save_model: cannot save {where}: objects of type {type(value).__module__}.{type(value).__qualname__} "
            f"are not supported by the safe model format (allowed: numbers, strings, lists, tuples, dicts, "
            f"arrays and the estimators {', '.join(sorted(ALLOWED))})"
        )

    def _ndarray(self, arr, where):
        if arr.dtype.hasobject:
            items = arr.ravel().tolist()
            if not all(isinstance(v, str) for v in items):
                raise TypeError(f"save_model: cannot save {where}: object arrays must hold only strings")
            return {"__type__": "objarray", "shape": list(arr.shape), "items": items}
        return {"__type__": "ndarray", "ref": self.array(arr)}

    def _estimator(self, est, name, where):
        params = est.get_params(deep=False)
        attrs = {}
        for key, value in vars(est).items():
            if key in params:
                continue
            if key == "net_" and name in _NET_OWNERS:
                attrs[key] = self._net(value, f"{where}.{key}")
            elif key == "ensemble_nets_" and name in _NET_OWNERS and isinstance(value, list):
                attrs[key] = [self._net(net, f"{where}.{key}[{i}]") for i, net in enumerate(value)]
            else:
                attrs[key] = self.encode(value, f"{where}.{key}")
        return {"__type__": "estimator", "class": name,
                "params": {k: self.encode(v, f"{where}.{k}") for k, v in params.items()},
                "attributes": attrs}

    def _net(self, net, where):
        tensors = []
        for key, tensor in net.module_.state_dict().items():
            t = tensor.detach().cpu()
            dtype = str(t.dtype).replace("torch.", "")
            if dtype not in _TORCH_DTYPES:
                raise TypeError(f"save_model: cannot save {where}: tensor {key} has dtype {dtype}")
            values = t.float().numpy() if dtype == "bfloat16" else t.numpy()
            tensors.append({"name": key, "dtype": dtype, "ref": self.array(np.array(values))})
        history = [dict(epoch) for epoch in net.history]
        try:
            history = self.encode(history, f"{where}.history")
        except TypeError:  # a callback logged something that is not plain data
            history = None
        return {"__type__": "skorch_net", "state_dict": tensors, "history": history}


def _prepared_type():
    from .neighbors._base import Prepared

    return Prepared


def save_model(model, path):
    """Save a model in eppf's safe model-file format.

    Parameters
    ----------
    model : estimator, or dict / list / tuple of estimators and plain values
        A fitted (or unfitted) estimator of eppf or one of the scikit-learn
        classes on the allow-list (``Pipeline``, ``Normalizer``,
        ``StandardScaler``, ``MinMaxScaler``, ``MaxAbsScaler``, ``PCA``,
        ``LogisticRegression``), or a string-keyed dict holding such
        estimators next to numbers, strings, lists and arrays (``eppf train``
        saves a dict with the pipeline, its class names and settings).
    path : str or path-like
        The file to write; the name is used as given (``eppf train`` uses
        ``.joblib`` or whatever ``-o`` says).

    Raises
    ------
    TypeError
        If ``model`` holds an object the format cannot represent (a function,
        an estimator not on the allow-list...); nothing is written then.

    See Also
    --------
    load_model : Read the file back.

    Notes
    -----
    The file is a zip container holding ``manifest.json`` (the format
    version, the eppf version, class names, parameters and fitted attributes)
    and ``arrays.npz`` (every array, stored without pickle). It is written
    to a temporary file that replaces ``path`` only when complete, so a full
    disk or an interrupt never leaves a truncated model behind.

    The torch networks of :class:`~eppf.EPPF4DClassifier` and
    :class:`~eppf.PointNetClassifier` are saved as their weights (the
    module's ``state_dict``) and training history; the optimizer state and
    the training callbacks are not, which prediction does not need
    (``fit`` builds a new network anyway).

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from eppf import KLNearestNeighbors, load_model, save_model
    >>> clf = KLNearestNeighbors().fit([[0.9, 0.1], [0.2, 0.8]], ["a", "b"])
    >>> path = os.path.join(tempfile.mkdtemp(), "model.eppf")
    >>> save_model(clf, path)
    >>> load_model(path).predict([[0.8, 0.2]])
    array(['a'], dtype='<U1')
    """
    encoder = _Encoder()
    root = encoder.encode(model, "model")
    manifest = {"format": FORMAT, "format_version": FORMAT_VERSION, "eppf_version": __version__,
                "numpy_version": np.__version__, "root": root}
    text = json.dumps(manifest, allow_nan=False, indent=1)
    with atomic_write(path, "wb") as fh:
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
            zf.writestr(_MANIFEST, text)
            with zf.open(_ARRAYS, "w", force_zip64=True) as member:
                np.savez(member, **encoder.arrays)


# ------------------------------------------------------------------- decoding
class _Decoder:
    def __init__(self, arrays, path):
        self.arrays, self.path = arrays, path

    def fail(self, where, problem):
        return ValueError(f"{self.path}: {where}: {problem}")

    def array(self, ref, where):
        if not isinstance(ref, str) or ref not in self.arrays:
            raise self.fail(where, f"refers to an array {ref!r} that is not in {_ARRAYS}")
        return self.arrays[ref]

    def decode(self, node, where):
        if node is None or isinstance(node, (bool, str, int, float)):
            return node
        if isinstance(node, list):
            return [self.decode(v, f"{where}[{i}]") for i, v in enumerate(node)]
        if not isinstance(node, dict):
            raise self.fail(where, f"unexpected JSON value of type {type(node).__name__}")
        kind = node.get("__type__")
        if kind == "float":
            text = node.get("value")
            if text not in ("nan", "inf", "-inf"):
                raise self.fail(where, f"bad float {text!r}")
            return float(text)
        if kind == "tuple":
            return tuple(self.decode(v, f"{where}[{i}]") for i, v in enumerate(self._list(node, "items", where)))
        if kind == "slice":
            parts = self._list(node, "items", where)
            if len(parts) != 3 or not all(v is None or (type(v) is int) for v in parts):
                raise self.fail(where, "a slice must hold three ints or nulls")
            return slice(*parts)
        if kind == "dict":
            items = node.get("items")
            if not isinstance(items, dict):
                raise self.fail(where, "a dict without items")
            return {k: self.decode(v, f"{where}[{k!r}]") for k, v in items.items()}
        if kind == "ndarray":
            return self.array(node.get("ref"), where)
        if kind == "npscalar":
            arr = self.array(node.get("ref"), where)
            if arr.ndim != 0:
                raise self.fail(where, f"a numpy scalar stored with shape {arr.shape}")
            return arr[()]
        if kind == "objarray":
            shape = self._list(node, "shape", where)
            items = self._list(node, "items", where)
            if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape) \
                    or math.prod(shape) != len(items) or not all(isinstance(v, str) for v in items):
                raise self.fail(where, "an object array whose shape and strings disagree")
            out = np.empty(len(items), dtype=object)
            out[:] = items
            return out.reshape(shape)
        if kind == "random_state":
            keys = self.array(node.get("keys"), where)
            pos, has_gauss = node.get("pos"), node.get("has_gauss")
            cached = self.decode(node.get("cached_gaussian"), where)
            if keys.shape != (624,) or keys.dtype != np.uint32 or not isinstance(pos, int) \
                    or not isinstance(has_gauss, int) or not isinstance(cached, float):
                raise self.fail(where, "a malformed random state")
            rs = np.random.RandomState()
            rs.set_state(("MT19937", keys, pos, has_gauss, cached))
            return rs
        if kind == "kl_prepared":
            return self._prepared(self.array(node.get("H"), where), where)
        if kind == "estimator":
            return self._estimator(node, where)
        raise self.fail(where, f"unknown node type {kind!r}")

    def _list(self, node, key, where):
        value = node.get(key)
        if not isinstance(value, list):
            raise self.fail(where, f"missing list {key!r}")
        return value

    def _prepared(self, H, where):
        from .neighbors._base import prepare_histograms

        if H.ndim != 2 or H.dtype != np.float64 or not np.all(np.isfinite(H)) or (H.size and H.min() <= 0):
            raise self.fail(where, "the stored training histograms must be a 2D array of positive finite float64")
        # H is already floored (and renormalised): a floor of 0 keeps it as it is
        # and recomputes the logarithms and row terms exactly as fit did.
        return prepare_histograms(H, 0.0, False, "load_model")

    def _estimator(self, node, where):
        name = node.get("class")
        if not isinstance(name, str) or name not in ALLOWED:
            raise ValueError(
                f"{self.path}: {where}: class {name!r} is not on the allow-list of classes a model file may "
                f"hold ({', '.join(sorted(ALLOWED))}); refusing to load it"
            )
        cls = _import_class(name)
        params = node.get("params")
        attrs = node.get("attributes")
        if not isinstance(params, dict) or not isinstance(attrs, dict):
            raise self.fail(where, f"{name} without params or attributes")
        params = {k: self.decode(v, f"{where}.{k}") for k, v in params.items()}
        try:
            est = cls(**params)
        except TypeError as exc:
            raise self.fail(where, f"{name} does not accept the stored parameters ({exc})") from None
        net = None
        members = None
        state = {}
        for key, value in attrs.items():
            if not isinstance(key, str) or not key.isidentifier() or key.startswith("__") or key in params:
                raise self.fail(where, f"{name} has a bad attribute name {key!r}")
            if key == "net_" and name in _NET_OWNERS:
                net = value
            elif key == "ensemble_nets_" and name in _NET_OWNERS:
                if not isinstance(value, list):
                    raise self.fail(where, f"{name}.ensemble_nets_ must be a list of networks")
                members = value
            else:
                state[key] = self.decode(value, f"{where}.{key}")
        vars(est).update(state)
        _check_params(est, name, self.fail, where)
        if state or net is not None or members is not None:  # saved fitted: its fitted state must be whole
            problem = _fitted_problem(est, name)
            if problem:
                raise self.fail(where, f"{name} has a broken fitted state: {problem}")
        if net is not None:
            est.net_ = self._net(est, name, net, f"{where}.net_")
        if members is not None:
            est.ensemble_nets_ = [self._net(est, name, node, f"{where}.ensemble_nets_[{i}]")
                                  for i, node in enumerate(members)]
        return est

    def _net(self, est, name, node, where):
        import torch

        if not isinstance(node, dict) or node.get("__type__") != "skorch_net":
            raise self.fail(where, "a network without its weights")
        tensors = {}
        for i, entry in enumerate(self._list(node, "state_dict", where)):
            if not isinstance(entry, dict) or not isinstance(entry.get("name"), str) \
                    or entry.get("dtype") not in _TORCH_DTYPES:
                raise self.fail(where, f"malformed tensor entry {i}")
            arr = np.ascontiguousarray(self.array(entry.get("ref"), where))
            tensors[entry["name"]] = torch.from_numpy(arr).to(getattr(torch, entry["dtype"]))
        history = self.decode(node.get("history"), f"{where}.history")
        try:
            with torch.random.fork_rng(devices=[]):  # initializing draws random weights
                net = est._untrained_net(len(est.classes_))
                net.module_.load_state_dict(tensors, strict=True)
        except (RuntimeError, ValueError, TypeError, AttributeError, KeyError) as exc:
            raise self.fail(where, f"cannot rebuild the network of {name}: {str(exc).splitlines()[0]}") from None
        if isinstance(history, list):
            from skorch.history import History

            net.history_ = History(history)
        return net


# ------------------------------------------------------ rebuilt estimators
# A hand-edited file can hold an estimator whose parameters its own code would refuse, or whose
# fitted attributes are missing or of another kind than fit sets: it would load and then fail in
# predict or transform with an error that names neither the file nor the problem. Loading checks
# the parameters with the estimator's own validation and the fitted attributes against what fit
# sets, as written below from each class's fit (attributes are read, never called).


def _check_params(est, name, fail, where):
    """Refuse parameters the estimator's own validation refuses (as fit and predict would)."""
    from .utils._param_validation import validate_params

    try:
        if getattr(type(est), "_parameter_constraints", None) is not None and name.startswith("eppf."):
            validate_params(est)
        elif hasattr(est, "_validate_params"):  # scikit-learn's own
            est._validate_params()
    except (ValueError, TypeError) as exc:
        raise fail(where, f"{name} has parameters it does not accept: {exc}") from None


def _int(value, low=0):
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)) and value >= low


def _positive_real(value):
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)) \
        and math.isfinite(value) and value > 0


#: dtype kinds of class labels a classifier's fit accepts (scikit-learn's checks): ints, unsigned ints,
#: bools, floats, strings, objects (strings of a mixed length), datetimes and time spans.
_LABEL_KINDS = "iubfUOMm"


def _array(value, ndim, kinds, length=None):
    """Whether ``value`` is an ndarray of ``ndim`` dimensions and a dtype kind in ``kinds``
    (finite when floating), with ``length`` rows when given."""
    return isinstance(value, np.ndarray) and value.ndim == ndim and value.dtype.kind in kinds \
        and (length is None or value.shape[0] == length) \
        and (value.dtype.kind != "f" or bool(np.all(np.isfinite(value))))


def _int_tuple(value):
    return type(value) is tuple and all(_int(v, 1) for v in value)


def _attrs_problem(est, checks):
    """The first of ``checks`` (attribute, test, what it must be) that ``est`` fails, described."""
    for attr, test, what in checks:
        if attr not in vars(est):
            return f"its fitted attribute {attr} is missing"
        value = vars(est)[attr]
        if not test(value):
            shown = f"an array of shape {value.shape} and dtype {value.dtype}" if isinstance(value, np.ndarray) \
                else repr(value)[:80]
            return f"{attr} must be {what}, got {shown}"
    return None


def _descriptor_problem(est, name):
    from .descriptors import DescriptorPool, DescriptorUnion
    from .descriptors._base import PointCloudDescriptor

    if isinstance(est, PointCloudDescriptor):
        checks = [("n_features_out_", lambda v: _int(v, 1), "a positive int")]
        if "scale_" in vars(est) or name in ("eppf.EPPFTransformer", "eppf.CVFHTransformer",
                                               "eppf.OURCVFHTransformer", "eppf.GRSDTransformer"):
            checks.append(("scale_", lambda v: v is None or _positive_real(v), "None or a positive finite float"))
        if name == "eppf.EPPFTransformer":  # fit learns a scale only with scaling="fit"
            fit_scale = est.scaling == "fit"
            checks[-1] = ("scale_", lambda v: _positive_real(v) if fit_scale else v is None,
                          "a positive finite float (scaling='fit')" if fit_scale else "None (scaling is not 'fit')")
            n_bins, functions, _ = est._resolve_params()
            shape = tuple(b for b, f in zip(n_bins, _eppf_functions()) if f in functions)
            checks += [("n_bins_", lambda v: v == n_bins, f"{n_bins} (from n_bins)"),
                       ("functions_", lambda v: v == functions, f"{functions} (from functions)"),
                       ("histogram_shape_", lambda v: v == shape, f"{shape} (from n_bins and functions)")]
        if name == "eppf.WahlTransformer":
            n_bins = est._check_params()[0]
            checks.append(("n_bins_", lambda v: v == n_bins, f"{n_bins} (from n_bins)"))
        problem = _attrs_problem(est, checks)
        if problem is None:
            width = int(est._n_features(est._check_params()))
            if est.n_features_out_ != width:
                problem = f"n_features_out_ is {est.n_features_out_} but its parameters give {width} features"
        return problem
    if isinstance(est, DescriptorUnion):
        problem = _attrs_problem(est, [
            ("transformers_", lambda v: type(v) is list and len(v) > 0 and all(
                type(t) is tuple and len(t) == 2 and isinstance(t[0], str) and _is_descriptor(t[1]) for t in v),
             "a non-empty list of (name, fitted descriptor) pairs"),
            ("weights_", lambda v: _array(v, 1, "f", len(est.transformers_)), "a float array of one weight per block"),
            ("feature_slices_", lambda v: type(v) is dict, "a dict of slices"),
            ("n_features_out_", lambda v: _int(v, 1), "a positive int")])
        if problem is None:
            col = 0
            for block, t in est.transformers_:
                width = getattr(t, "n_features_out_", None)
                if est.feature_slices_.get(block) != slice(col, col + width):
                    return f"feature_slices_[{block!r}] must be slice({col}, {col + width}) (block widths in order)"
                col += width
            if len(est.feature_slices_) != len(est.transformers_) or est.n_features_out_ != col:
                return f"feature_slices_ and n_features_out_ must cover the blocks' {col} features"
        return problem
    if isinstance(est, DescriptorPool):
        # (n_features_out_ comes with the first pool a fitted pool computes: fit alone leaves it unset)
        problem = _attrs_problem(est, [
            ("transformers_", lambda v: type(v) is list and len(v) > 0 and all(_is_descriptor(t) for t in v),
             "a non-empty list of fitted descriptors")])
        widths = {getattr(t, "n_features_out_", None) for t in est.transformers_} if problem is None else set()
        if problem is None and "n_features_out_" in vars(est):
            widths.add(est.n_features_out_)
        if len(widths) > 1:
            return f"its fitted descriptors and n_features_out_ must all give one number of features, got {widths}"
        return problem
    return None


def _eppf_functions():
    from .descriptors._eppf import FUNCTIONS

    return FUNCTIONS


def _is_descriptor(est):
    """A fitted eppf descriptor (what a union or a pool computes with)."""
    from .descriptors import DescriptorPool, DescriptorUnion
    from .descriptors._base import PointCloudDescriptor

    return isinstance(est, (PointCloudDescriptor, DescriptorUnion, DescriptorPool)) and "n_features_out_" in vars(est)


def _classifier_problem(est, name):
    classes = ("classes_", lambda v: _array(v, 1, _LABEL_KINDS) and len(v) > 0, "a non-empty 1D array")
    if name == "eppf.KLNearestNeighbors":
        from .neighbors._base import Prepared

        problem = _attrs_problem(est, [
            ("n_features_in_", lambda v: _int(v, 1), "a positive int"),
            ("floor_", _positive_real, "a positive finite float"), classes,
            ("_renormalize", lambda v: isinstance(v, (bool, np.bool_)), "a bool"),
            ("_fit_data", lambda v: isinstance(v, Prepared), "the training histograms"),
            ("n_samples_fit_", lambda v: v == est._fit_data.H.shape[0], "the number of training histograms"),
            ("_y", lambda v: _array(v, 1, "iu", est.n_samples_fit_) and (not v.size or (
                v.min() >= 0 and v.max() < len(est.classes_))),
             "an int array of one index into classes_ per training histogram")])
        if problem is None and est._fit_data.H.shape[1] != est.n_features_in_:
            return f"n_features_in_ is {est.n_features_in_} but the training histograms have " \
                   f"{est._fit_data.H.shape[1]} bins"
        return problem
    if name == "eppf.EPPF4DClassifier":
        n_bins = est._n_bins if _int_tuple(vars(est).get("_n_bins")) else None
        n_side = vars(est).get("n_side_features_")
        n_flat = math.prod(n_bins) if n_bins else None
        # (in order: each test reads only what the ones before it checked)
        side = lambda v: _array(v, 1, "f", n_side)  # noqa: E731
        flat = lambda v: _array(v, 1, "f") and len(v) in (1, n_flat)  # noqa: E731
        return _attrs_problem(est, [
            ("_n_bins", lambda v: v == tuple(int(b) for b in est.n_bins), "the n_bins parameter as a tuple"),
            ("n_side_features_", lambda v: _int(v, 0), "an int >= 0"),
            ("n_features_in_", lambda v: v == n_flat + n_side, "prod(n_bins) + n_side_features_"),
            ("n_draws_fit_", lambda v: _int(v, 1), "a positive int"), classes,
            ("side_mean_", side, "a float array of n_side_features_ values"),
            ("side_scale_", side, "a float array of n_side_features_ values"),
            ("input_mean_", flat, "a float array of 1 or prod(n_bins) values"),
            ("input_scale_", flat, "a float array of 1 or prod(n_bins) values")])
    if name == "eppf.PointNetClassifier":
        return _attrs_problem(est, [classes, ("_predict_seed", lambda v: _int(v, 0) and v < 2**32, "an int seed")])
    return None


def _sklearn_problem(est, name):
    n_in = vars(est).get("n_features_in_")
    checks = [("n_features_in_", lambda v: _int(v, 1), "a positive int")]
    feature = lambda v: v is None or _array(v, 1, "f", n_in)  # noqa: E731
    if name == "sklearn.preprocessing.StandardScaler":
        checks += [(a, feature, "None or a float array of n_features_in_ values") for a in ("mean_", "var_", "scale_")]
        # an array where transform uses it (fit also keeps the mean without centering, unless with_std=False too)
        checks += [(a, lambda v: v is not None, f"a float array ({kind}=True)")
                   for a, kind in (("mean_", "with_mean"), ("scale_", "with_std")) if getattr(est, kind)]
    elif name in ("sklearn.preprocessing.MinMaxScaler", "sklearn.preprocessing.MaxAbsScaler"):
        attrs = ("min_", "scale_") if name.endswith("MinMaxScaler") else ("scale_",)
        checks += [(a, lambda v: _array(v, 1, "f", n_in), "a float array of n_features_in_ values") for a in attrs]
    elif name == "sklearn.decomposition.PCA":
        checks += [("mean_", lambda v: _array(v, 1, "f", n_in), "a float array of n_features_in_ values"),
                   ("components_", lambda v: _array(v, 2, "f") and v.shape[1] == n_in and len(v) > 0,
                    "a float array of shape (n_components, n_features_in_)"),
                   ("explained_variance_", lambda v: _array(v, 1, "f", len(est.components_)),
                    "a float array of one value per component")]
    elif name == "sklearn.linear_model.LogisticRegression":
        checks += [("classes_", lambda v: _array(v, 1, _LABEL_KINDS) and len(v) >= 2,
                    "a 1D array of two or more classes"),
                   ("coef_", lambda v: _array(v, 2, "f") and v.shape[1] == n_in
                    and len(v) == (1 if len(est.classes_) == 2 else len(est.classes_)),
                    "a float array of shape (1 or n_classes, n_features_in_)"),
                   ("intercept_", lambda v: _array(v, 1, "f", len(est.coef_)),
                    "a float array of one value per row of coef_")]
    return _attrs_problem(est, checks)


def _fitted_problem(est, name):
    """What is wrong with the fitted state of a rebuilt ``est`` (allow-list ``name``), or None.

    Written from each class's ``fit``: the attributes it sets, their kind and how they agree with
    each other and with the parameters. Classes without fitted state worth checking (the
    perturbations, Pipeline and Normalizer beyond ``n_features_in_``) pass.
    """
    if name.startswith("eppf.") and not name.startswith("eppf.preprocessing."):
        return _descriptor_problem(est, name) or _classifier_problem(est, name)
    if name.startswith("sklearn.") and name != "sklearn.pipeline.Pipeline":
        return _sklearn_problem(est, name)
    return None


def _version_tuple(text):
    try:
        from packaging.version import Version

        return Version(text)
    except Exception:  # packaging missing or an odd version string
        parts = []
        for piece in str(text).split("."):
            digits = "".join(c for c in piece if c.isdigit())
            parts.append(int(digits) if digits else 0)
        return tuple(parts)


def _read_arrays(zf, path):
    """The arrays of ``arrays.npz`` in an open model container, read without pickle."""
    if _ARRAYS not in zf.namelist():
        raise ValueError(f"{path}: the model file has no {_ARRAYS}")
    spool = tempfile.SpooledTemporaryFile(max_size=64 << 20)
    with spool:
        with zf.open(_ARRAYS) as member:
            shutil.copyfileobj(member, spool, 1 << 20)
        spool.seek(0)
        try:
            inner = zipfile.ZipFile(spool)
        except zipfile.BadZipFile:
            raise ValueError(f"{path}: {_ARRAYS} inside the model file is not a readable .npz") from None
        arrays = {}
        with inner:
            for info in inner.infolist():
                if not info.filename.endswith(".npy"):
                    raise ValueError(f"{path}: unexpected member {info.filename!r} in {_ARRAYS}")
                key = info.filename[:-4]
                with inner.open(info) as fp:
                    _check_npy_header(fp, info, path)
                with inner.open(info) as fp:
                    arrays[key] = np.lib.format.read_array(fp, allow_pickle=False)
    return arrays


def _check_npy_header(fp, info, path):
    """Refuse an array whose header promises other data than the member holds."""
    fmt = np.lib.format
    version = fmt.read_magic(fp)
    if version == (1, 0):
        shape, _, dtype = fmt.read_array_header_1_0(fp)
    elif version in ((2, 0), (3, 0)):
        shape, _, dtype = fmt.read_array_header_2_0(fp)
    else:
        raise ValueError(f"{path}: array {info.filename} has an unknown .npy version {version}")
    if dtype.hasobject:
        raise ValueError(f"{path}: array {info.filename} holds Python objects (pickle), which model files may not")
    need = math.prod(int(s) for s in shape) * dtype.itemsize
    if fp.tell() + need != info.file_size:
        raise ValueError(f"{path}: array {info.filename} declares shape {shape} of {dtype} "
                         f"({need} bytes) but holds {info.file_size - fp.tell()} bytes")


def _looks_like_pickle(path):
    with open(path, "rb") as fh:
        head = fh.read(4)
    # pickle protocol 2+ opens with 0x80; joblib's compressed files with zlib/gzip/xz/lz4 magics.
    return head[:1] == b"\x80" or head[:2] in (b"\x78\x01", b"\x78\x9c", b"\x78\xda", b"\x1f\x8b") \
        or head[:4] in (b"\xfd7zX", b"\x04\x22\x4d\x18")


def load_model(path, *, trust=False):
    """Load a model written by :func:`save_model` or ``eppf train``.

    Parameters
    ----------
    path : str or path-like
        The model file.
    trust : bool, default=False
        Also accept a pickled model (a joblib file written by eppf 0.1).
        Unpickling can run any code the file contains, and a file made to
        do so still yields a working model, so the harm would go unnoticed:
        pass ``True`` only for files you made yourself. Files in the safe
        format load the same way either way.

    Returns
    -------
    model : object
        What was saved: an estimator, or the dict ``eppf train`` saves
        (``"model"``, ``"classes"``, ``"params"``, ``"eppf_version"``...).

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ValueError
        If the file is not a model file in the safe format (and ``trust`` is
        False), is truncated or corrupt, was written in a newer format
        version, names a class that is not on the allow-list, holds arrays
        of Python objects, or holds an estimator whose parameters it does
        not accept or whose fitted attributes are missing, of another kind
        than ``fit`` sets or disagree with each other or with the
        parameters. The message names the file.
    OSError
        If reading the file fails (the message names it).

    Warns
    -----
    UserWarning
        If the file was written by a newer eppf than the one running.

    See Also
    --------
    save_model : Write a model file.

    Notes
    -----
    Loading reads ``manifest.json`` as JSON and ``arrays.npz`` with
    ``allow_pickle=False``, checks every array's header against its stored
    size, and creates only estimators of the allow-listed eppf and
    scikit-learn classes, from their recorded parameters and fitted
    attributes. No name in the file is imported or called, so a model file
    from anyone can be opened; it can at worst predict badly.

    Examples
    --------
    >>> import os, tempfile
    >>> from eppf import KLNearestNeighbors, load_model, save_model
    >>> path = os.path.join(tempfile.mkdtemp(), "model.eppf")
    >>> save_model(KLNearestNeighbors(n_neighbors=3), path)
    >>> load_model(path)
    KLNearestNeighbors(n_neighbors=3)
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such model file: {path}")
    # the safe format is a zip archive from its first byte; zipfile.is_zipfile alone also
    # says yes to a pickle whose last bytes hold a zip archive (a pickled torch module's)
    with open(path, "rb") as fh:
        zip_head = fh.read(4) == b"PK\x03\x04"
    if not (zip_head and zipfile.is_zipfile(path)):
        return _load_untrusted_or_refuse(path, trust)
    try:
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            if _MANIFEST not in names:
                raise ValueError(f"{path} is a zip file but not an eppf model file (it has no {_MANIFEST})")
            if zf.getinfo(_MANIFEST).file_size > _MAX_MANIFEST_BYTES:
                raise ValueError(f"{path}: {_MANIFEST} is larger than {_MAX_MANIFEST_BYTES >> 20} MiB")
            try:
                manifest = json.loads(zf.read(_MANIFEST).decode("utf-8"))
            except (ValueError, RecursionError) as exc:  # bad UTF-8 or JSON, absurd nesting or numbers
                raise ValueError(f"{path}: {_MANIFEST} is not valid JSON ({type(exc).__name__}: {exc})") from None
            _check_manifest(manifest, path)
            arrays = _read_arrays(zf, path)
    except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, KeyError) as exc:
        raise ValueError(f"cannot load model {path}: corrupt or truncated model file ({type(exc).__name__}: {exc})") from None
    except OSError as exc:
        if exc.errno == errno.EINVAL:  # a seek to an offset the archive's directory gives, outside any file
            raise ValueError(f"cannot load model {path}: corrupt model file (an entry's offset is invalid)") from None
        raise OSError(exc.errno, f"cannot read model file {path} ({exc.strerror or exc})", path) from None
    try:
        return _Decoder(arrays, path).decode(manifest["root"], "model")
    except RecursionError:
        raise ValueError(f"{path}: the model tree in {_MANIFEST} is nested too deeply") from None
    except (ValueError, TypeError) as exc:  # raised while rebuilding, e.g. by an estimator's own checks
        if path in str(exc):
            raise
        raise ValueError(f"{path}: cannot rebuild the model: {exc}") from None


def _check_manifest(manifest, path):
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise ValueError(f"{path}: {_MANIFEST} does not describe an eppf model (format {FORMAT!r} expected)")
    version = manifest.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise ValueError(f"{path}: bad format version {version!r}")
    if version > FORMAT_VERSION:
        raise ValueError(f"{path} was written in model format version {version} by eppf "
                         f"{manifest.get('eppf_version')}; this eppf {__version__} reads up to version "
                         f"{FORMAT_VERSION}: upgrade eppf to load it")
    written_by = manifest.get("eppf_version")
    if not isinstance(written_by, str):
        raise ValueError(f"{path}: {_MANIFEST} does not record the eppf version that wrote it")
    if _newer(written_by, __version__):
        warnings.warn(f"{path} was saved by eppf {written_by}, which is newer than this eppf {__version__}; "
                      "it may not load or predict as it did there", UserWarning, stacklevel=3)
    if "root" not in manifest:
        raise ValueError(f"{path}: {_MANIFEST} holds no model")


def _newer(a, b):
    try:
        return _version_tuple(a) > _version_tuple(b)
    except TypeError:
        return False


#: Where the classes of an eppf 0.1 pickle live now (the flat modules became subpackages).
_MODULES_0_1 = {
    "eppf._descriptor": "eppf.descriptors._eppf",
    "eppf._esf": "eppf.descriptors._esf",
    "eppf._wahl": "eppf.descriptors._wahl",
    "eppf._ourcvfh": "eppf.descriptors._ourcvfh",
    "eppf._pool": "eppf.descriptors._pool",
    "eppf._neighbors": "eppf.neighbors._kl",
    "eppf._cnn": "eppf.classifiers._eppf_cnn",
    "eppf._pointnet": "eppf.classifiers._pointnet",
    "eppf._normals": "eppf.preprocessing._normals",
    "eppf._perturb": "eppf.preprocessing._perturb",
    "eppf._sampling": "eppf.utils._sampling",
    "eppf._validation": "eppf.utils._validation",
    "eppf._chunks": "eppf.utils._chunks",
}


class _modules_of_0_1:
    """While a trusted 0.1 pickle loads, its module names resolve to today's modules."""

    def __enter__(self):
        import importlib
        import sys

        self.added = []
        for old, new in _MODULES_0_1.items():
            if old not in sys.modules:
                sys.modules[old] = importlib.import_module(new)
                self.added.append(old)
        return self

    def __exit__(self, *exc):
        import sys

        for old in self.added:
            sys.modules.pop(old, None)
        return False


def _load_untrusted_or_refuse(path, trust):
    with open(path, "rb") as fh:
        head = fh.read(4)
    if head[:4] == b"PK\x03\x04":
        raise ValueError(f"cannot load model {path}: corrupt or truncated model file (its zip container is incomplete)")
    if not trust:
        if not _looks_like_pickle(path):
            raise ValueError(f"cannot load model {path}: not an eppf model file (neither the safe zip format "
                             "nor a pickle)")
        raise ValueError(
            f"{path} is not an eppf model in the safe format but a pickle (an eppf 0.1 joblib model?). "
            "Loading a pickle can run any code it contains, so it is refused by default; if you made this "
            "file yourself, load it with load_model(path, trust=True) or '--trust' on the command line, "
            "then save it again with save_model to get a safe file"
        )
    import joblib

    try:
        with _modules_of_0_1():
            return joblib.load(path)
    except Exception as exc:  # a corrupt or foreign file raises all sorts of errors
        first = str(exc).splitlines()[0] if str(exc) else "no details"
        raise ValueError(f"cannot load model {path}: not a readable joblib file ({type(exc).__name__}: {first})") from None

