"""numpydoc validation of every public docstring.

In the spirit of scikit-learn's ``sklearn/tests/test_docstrings.py``: every
public class, its public methods and properties, and every public function of
the modules in ``tests/_public_api.py`` go through numpydoc's validator, and
every error is a failure except the few codes listed in ``IGNORED`` (with
their reasons) and the names in ``SKIP`` (docstrings in files other engineers
are editing now, fixed by their owners after the merge).
"""

import importlib
import inspect
import re
from pathlib import Path

import pytest

from tests._public_api import public_modules

numpydoc_validate = pytest.importorskip("numpydoc.validate")

ROOT = Path(__file__).resolve().parents[1]

# numpydoc error codes not enforced, and why.
IGNORED = {
    # The Returns section names what is returned (``self : object``,
    # ``X_new : ndarray``) as scikit-learn's docstrings do; numpydoc wants the
    # type alone on that line.
    "RT02": "everywhere",
    # An extended summary is not required: a one-line summary and the
    # Parameters/Returns sections describe a small function completely, and
    # the classes that need more have it.
    "ES01": "everywhere",
    # Methods and properties are documented within their class, whose
    # docstring carries the See Also and Examples sections (scikit-learn's
    # rule too); top-level classes and functions must have both.
    "SA01": "members",
    "EX01": "members",
}

# Failures in files that other engineers are editing in parallel: listed by
# name so that their merges stay clean (each fixed by its owner after the merge).
SKIP = {
    "eppf.datasets.clear_data_home": ("SA01",),
    "eppf.datasets.fetch_file": ("SA01",),
    "eppf.datasets.fetch_modelnet": ("SA01",),
    "eppf.datasets.get_data_home": ("SA01",),
    "eppf.datasets.load_folder": ("SA01",),
    "eppf.datasets.load_s3dis_objects": ("SA01",),
    "eppf.datasets.load_scannet_objects": ("SA01",),
    "eppf.nn.Conv4d.extra_repr": ("GL08",),
    "eppf.nn.Conv4d.forward": ("PR01", "RT01"),
    "eppf.nn.Conv4d.forward_folded": ("PR07", "RT03"),
    "eppf.nn.DescriptorPoolDataset": ("SA01",),
    "eppf.nn.EPPFNet2D.forward": ("PR01", "RT01"),
    "eppf.nn.EPPFNet3D.forward": ("PR01", "RT01"),
    "eppf.nn.EPPFNet4D.forward": ("PR01", "RT01"),
    "eppf.nn.check_n_bins": ("RT03", "SA01"),
    "eppf.nn.conv4d": ("SA01",),
    "eppf.nn.count_parameters": ("PR07", "RT03", "SA01"),
    "eppf.nn.plane_shape": ("RT03", "SA01"),
    "eppf.nn.same_padding": ("SA01",),
    "eppf.utils.check_n_jobs": ("EX01", "PR01", "RT01", "SA01"),
    "eppf.utils.check_point_cloud": ("EX01", "SA01"),
    "eppf.utils.check_point_clouds": ("EX01", "SA01"),
    "eppf.utils.object_seeds": ("EX01", "PR01", "RT01", "SA01"),
    "eppf.utils.pack_point_clouds": ("EX01", "RT03", "SA01"),
}


def _defining_module(obj):
    return getattr(obj, "__module__", "") or ""


def _members(cls):
    """Public methods and properties of ``cls`` defined by eppf (not inherited from scikit-learn or torch)."""
    out = []
    for name in sorted(dir(cls)):
        if name.startswith("_"):
            continue
        for klass in cls.__mro__:
            if name in vars(klass):
                attr = vars(klass)[name]
                break
        else:  # pragma: no cover - dir() lists only what the MRO has
            continue
        if not klass.__module__.startswith("eppf"):
            continue
        if isinstance(attr, (staticmethod, classmethod)):
            attr = attr.__func__
        if inspect.isfunction(attr) or isinstance(attr, property):
            out.append(name)
    return out


def public_objects():
    """Import paths of every public class, member and function, each object once.

    An object exported by several modules (``eppf.EPPFTransformer`` and
    ``eppf.descriptors.EPPFTransformer``) is named after the deepest one.
    """
    by_id = {}
    for modname, module in public_modules():
        for name in module.__all__:
            obj = getattr(module, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue  # constants (FUNCTIONS, DESCRIPTORS) have no docstring of their own
            if not _defining_module(obj).startswith("eppf"):
                continue
            path = f"{modname}.{name}"
            old = by_id.get(id(obj))
            if old is None or old[0].count(".") < path.count("."):
                by_id[id(obj)] = (path, obj)
    paths = []
    for path, obj in by_id.values():
        paths.append(path)
        if inspect.isclass(obj):
            paths.extend(f"{path}.{m}" for m in _members(obj))
    return sorted(paths)


def _is_member(path):
    """True for a method or property (the parent of its last component is a class)."""
    parent, _, _ = path.rpartition(".")
    try:
        importlib.import_module(parent)
        return False
    except ImportError:
        return True


def _errors(path):
    result = numpydoc_validate.validate(path)
    member = _is_member(path)
    errors = []
    for code, message in result["errors"]:
        scope = IGNORED.get(code)
        if scope == "everywhere" or (scope == "members" and member):
            continue
        if code in SKIP.get(path, ()):
            continue
        errors.append(f"{code}: {message}")
    return errors, result


PUBLIC = public_objects()


def test_public_objects_found():
    # the walk must see the estimators, their methods and plain functions
    for path in ("eppf.descriptors.EPPFTransformer", "eppf.descriptors.EPPFTransformer.transform",
                 "eppf.neighbors.symmetric_kl_distances", "eppf.preprocessing.GaussianNoise.fit"):
        assert path in PUBLIC
    assert "eppf.EPPFTransformer" not in PUBLIC  # re-exports are checked where they are most specific
    # members inherited from scikit-learn or torch are theirs to document
    for path in ("eppf.descriptors.EPPFTransformer.get_params", "eppf.descriptors.EPPFTransformer.set_output",
                 "eppf.nn.Conv4d.train", "eppf.neighbors.KLNearestNeighbors.score"):
        assert path not in PUBLIC


@pytest.mark.parametrize("path", PUBLIC)
def test_docstring(path):
    errors, result = _errors(path)
    where = f"{result.get('file')}:{result.get('file_line')}"
    assert not errors, f"{path} ({where}):\n" + "\n".join(errors)


def test_skip_list_names_public_objects():
    assert set(SKIP) <= set(PUBLIC), sorted(set(SKIP) - set(PUBLIC))
    assert all(set(codes) <= set(numpydoc_validate.ERROR_MSGS) for codes in SKIP.values())


# ------------------------------------------------------------- the registry


def _api_reference():
    """Module -> names listed under its ``currentmodule`` in docs/api.rst."""
    api = ROOT / "docs" / "api.rst"
    if not api.exists():
        pytest.skip("docs/api.rst not present")
    sections = re.split(r"^\.\. currentmodule:: (\S+)$", api.read_text(), flags=re.M)
    listed = {}
    for module, body in zip(sections[1::2], sections[2::2]):
        listed.setdefault(module, set()).update(re.findall(r"^   (\w+)$", body, flags=re.M))
    return listed


def test_every_registered_estimator_is_public_and_documented():
    from eppf.registry import CLASSIFIERS, DESCRIPTORS

    listed = _api_reference()
    modules = dict(public_modules())
    for spec in list(DESCRIPTORS.values()) + list(CLASSIFIERS.values()):
        cls = spec.estimator_class()
        exported = [m for m, mod in modules.items() if getattr(mod, cls.__name__, None) is cls
                    and cls.__name__ in mod.__all__]
        assert exported, f"registry entry {spec.name!r}: {cls.__name__} is not exported by a public module"
        assert any(cls.__name__ in listed.get(m, ()) for m in exported), \
            f"registry entry {spec.name!r}: {cls.__name__} is not in docs/api.rst"
        path = max((f"{m}.{cls.__name__}" for m in exported), key=lambda p: p.count("."))
        assert path in PUBLIC
        errors, _ = _errors(path)
        assert not errors, f"{path}: " + "; ".join(errors)
