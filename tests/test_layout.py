"""The layout's rules, checked on the source: data flows one way, and no module takes a sibling's private names.

- ``eppf.utils`` imports no other part of eppf, and ``eppf.io`` nothing but
  ``eppf.utils`` (the foundation imports nothing above it);
- ``preprocessing`` imports only the foundation, ``descriptors`` nothing above
  ``preprocessing``;
- a module never imports a private name (``_x``) of a sibling module in its own
  package: what two modules share is public in the one that defines it, or
  lives a layer below.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "eppf"

#: subpackage -> the eppf subpackages it may import
ALLOWED = {
    "utils": {"utils"},
    "io": {"utils", "io"},
    "preprocessing": {"utils", "io", "preprocessing"},
    "descriptors": {"utils", "io", "preprocessing", "descriptors"},
}


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _imports(path):
    """(absolute module, imported names, relative level) of every ``from ... import`` in ``path``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
        package = parts
    else:
        package = parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            yield module, [a.name for a in node.names], node.level
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, [], 0


def _subpackage(module):
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "eppf" else None


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_follow_the_layers(path):
    own = _subpackage(".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts))
    if own not in ALLOWED:
        return
    for module, names, _ in _imports(path):
        target = _subpackage(module)
        if module.startswith("eppf") and module != "eppf":
            assert target in ALLOWED[own], f"{path.relative_to(PACKAGE)} imports {module} (above {own})"
        assert module != "eppf", f"{path.relative_to(PACKAGE)} imports the top-level eppf package"


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_private_names_of_a_sibling(path):
    here = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    package = here.rsplit(".", 1)[0] if not here.endswith("__init__") else here.rsplit(".", 1)[0]
    for module, names, level in _imports(path):
        if level != 1 or module.rsplit(".", 1)[0] != package or module == package:
            continue  # not a sibling module of the same package
        private = [n for n in names if n.startswith("_") and not n.startswith("__")]
        assert not private, f"{path.relative_to(PACKAGE)} imports private {private} from its sibling {module}"
