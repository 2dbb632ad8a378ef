"""The layout's rules, checked on the source: data flows one way, modules form no cycle, and none takes another's private names.

- the subpackages are layered (``utils`` at the bottom, then ``io`` and
  ``preprocessing``, ``segmentation``, ``descriptors`` and ``nn``, ...,
  ``cli`` at the top):
  the contract is declared in ``pyproject.toml`` (``[tool.importlinter]``)
  and checked by import-linter on grimp's import graph;
- no two eppf modules import each other, directly or through others, at
  module level or inside functions (grimp's graph has both);
- across subpackages a module imports public names only: never a name
  ``_x``, a private module as a name, or a compiled kernel ``_x_fast``
  (a kernel belongs to the package beside it);
- within a package, a module never imports a private name (``_x``) of a
  sibling module: what two modules share is public in the one that defines
  it, or lives a layer below.
"""

import ast
import contextlib
import io
import re
from pathlib import Path

import pytest

importlinter_cli = pytest.importorskip("importlinter.cli", reason="import-linter comes with the test extra")
grimp = pytest.importorskip("grimp", reason="grimp comes with import-linter (the test extra)")

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "eppf"

#: Crossings that changes under way remove. Each must still be there: when it
#: goes, its entry goes too, so the list only shrinks.
PENDING_CROSSINGS = set()
#: Cycles (sorted members) that changes under way remove, with the same rule.
PENDING_CYCLES = set()


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _name(path):
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path):
    """(absolute module, imported names, relative level, line) of every import in ``path``, functions included."""
    return _imports_of(path.read_text(), _name(path), path.name == "__init__.py")


def _imports_of(source, name, is_package):
    """The imports of the source of module ``name`` (a package's ``__init__`` when ``is_package``)."""
    tree = ast.parse(source)
    parts = name.split(".")
    package = parts if is_package else parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            yield module, [a.name for a in node.names], node.level, node.lineno
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, [], 0, node.lineno


def _subpackage(module):
    """The first component under eppf (``descriptors`` for ``eppf.descriptors._esf``, ``metrics`` for ``eppf.metrics``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "eppf" else ("eppf" if module == "eppf" else None)


def test_layers_follow_the_contract():
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = importlinter_cli.lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True,
                                               no_logo=True)
    assert status == 0, out.getvalue()


def _contract_layers():
    """The subpackages and top-level modules named in pyproject.toml's layers contract."""
    text = (ROOT / "pyproject.toml").read_text()
    block = text[text.index("[tool.importlinter]"):]
    block = block[block.index("layers = [") + len("layers = ["):]
    block = block[: block.index("]")]
    return {name.strip() for line in re.findall(r'"([^"]*)"', block) for name in re.split(r"[|:]", line)}


def test_every_subpackage_and_module_has_a_layer():
    children = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    children |= {p.stem for p in PACKAGE.glob("*.py") if p.name != "__init__.py"}
    assert children == _contract_layers()


def _kernel_only_package_imports():
    """``(module, package)`` where ``module`` imports its package only as ``from . import _x_fast``.

    grimp sees Python files only, so it reads ``from . import _eppf_fast``
    (a compiled kernel beside the module) as an import of the package's
    ``__init__``; such an edge is not one.
    """
    spurious = set()
    for path in _modules():
        name = _name(path)
        own = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        kernel_only, other = set(), set()
        for module, names, level, _ in _imports(path):
            if not level or module == name:
                continue
            folder = PACKAGE.parent.joinpath(*module.split("."))
            if names and all((folder / f"{n}.pyx").is_file() for n in names):
                kernel_only.add(module)
            else:
                other.add(module)
        spurious |= {(name, pkg) for pkg in kernel_only - other if pkg == own}
    return spurious


def _cycles(graph, ignore=frozenset()):
    """Strongly connected components of more than one module (Tarjan, iterative), edges in ``ignore`` left out."""
    adjacency = {
        m: sorted(t for t in graph.find_modules_directly_imported_by(m) if (m, t) not in ignore) for m in graph.modules
    }
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    counter = 0
    for root in sorted(adjacency):
        if root in index:
            continue
        work = [(root, iter(adjacency[root]))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(adjacency[child])))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def _chain(graph, members):
    """One cycle through ``members``, for the message: a -> b -> ... -> a."""
    first = members[0]
    for nxt in sorted(graph.find_modules_directly_imported_by(first)):
        if nxt in members:
            back = graph.find_shortest_chain(importer=nxt, imported=first)
            if back:
                return " -> ".join((first,) + tuple(back))
    return ", ".join(members)


def test_no_import_cycles():
    graph = grimp.build_graph("eppf", cache_dir=None)
    assert graph.modules, "grimp found no eppf module"
    cycles = {tuple(c): _chain(graph, c) for c in _cycles(graph, _kernel_only_package_imports())}
    new = [chain for members, chain in cycles.items() if members not in PENDING_CYCLES]
    assert not new, "import cycles (function-level imports count):\n" + "\n".join(new)
    gone = sorted(PENDING_CYCLES - set(cycles))
    assert not gone, f"the cycles {gone} are gone: remove them from PENDING_CYCLES"


def test_the_cycle_finder_sees_imports_inside_functions(tmp_path, monkeypatch):
    pkg = tmp_path / "cyclepkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("def f():\n    from .c import g\n    return g\n")
    (pkg / "c.py").write_text("from .a import b\n\ndef g():\n    return b\n")
    (pkg / "d.py").write_text("from . import a\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    graph = grimp.build_graph("cyclepkg", cache_dir=None)
    assert _cycles(graph) == [["cyclepkg.a", "cyclepkg.b", "cyclepkg.c"]]


def _private_crossings(name, imports):
    """``(line, what)`` for each import of module ``name`` from another subpackage that is not that subpackage's to give."""
    own = _subpackage(name)
    for module, names, _, line in imports:
        target = _subpackage(module)
        if target is None or target == own:
            continue
        kernels = [p for p in module.split(".") if p.startswith("_") and p.endswith("_fast")]
        if kernels:
            yield line, f"the kernel {module} of another package"
        private = [n for n in names if n.startswith("_") and not n.startswith("__")]
        if private:
            yield line, f"private {private} from {module}"


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_private_names_across_subpackages(path):
    where = str(path.relative_to(PACKAGE))
    found = {what: line for line, what in _private_crossings(_name(path), _imports(path))}
    pending = {what for file, what in PENDING_CROSSINGS if file == where}
    new = [f"line {line}: {what}" for what, line in found.items() if what not in pending]
    assert not new, f"{where} imports\n" + "\n".join(new)
    gone = sorted(pending - set(found))
    assert not gone, f"{where} no longer imports {gone}: remove them from PENDING_CROSSINGS"


def test_the_private_name_check_sees_crossings():
    source = (
        "from ..descriptors._esf_fast import esf_batch\n"
        "from ..utils._validation import check_n_jobs\n"
        "def f():\n    from ..neighbors._kl import _named\n"
        "from ._common import _own\n"
    )
    found = list(_private_crossings("eppf.cli._probe", _imports_of(source, "eppf.cli._probe", False)))
    assert found == [
        (1, "the kernel eppf.descriptors._esf_fast of another package"),
        (4, "private ['_named'] from eppf.neighbors._kl"),
    ]


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_private_names_of_a_sibling(path):
    here = _name(path)
    package = here if path.name == "__init__.py" else here.rsplit(".", 1)[0]
    for module, names, level, _ in _imports(path):
        if level != 1 or module.rsplit(".", 1)[0] != package or module == package:
            continue  # not a sibling module of the same package
        private = [n for n in names if n.startswith("_") and not n.startswith("__")]
        assert not private, f"{path.relative_to(PACKAGE)} imports private {private} from its sibling {module}"
