"""The packaging metadata: one version string, and minimum pins that match the declared bounds."""

import re
from pathlib import Path

import pytest

import eppf

tomllib = pytest.importorskip("tomllib")  # Python 3.11+
Version = pytest.importorskip("packaging.version").Version

ROOT = Path(__file__).resolve().parents[1]


def _project():
    with open(ROOT / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)


def _name(requirement):
    """(normalised name, lower bound) of a ``name[extras]>=x`` requirement."""
    m = re.fullmatch(r"([A-Za-z0-9_.-]+)(?:\[[^\]]*\])?>=([0-9][^,;\s]*)", requirement)
    assert m, f"{requirement!r} is not of the form name>=version"
    return re.sub(r"[-_.]+", "-", m[1]).lower(), Version(m[2])


def test_version_is_read_from_one_place():
    pyproject = _project()
    assert "version" not in pyproject["project"]
    assert "version" in pyproject["project"]["dynamic"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "eppf._version.__version__"}
    from eppf._version import __version__

    assert eppf.__version__ == __version__
    Version(__version__)  # a valid PEP 440 version


def test_changelog_has_a_section_for_this_version():
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert re.search(rf"^## \[{re.escape(eppf.__version__)}\]", text, re.M), \
        f"CHANGELOG.md has no '## [{eppf.__version__}]' section"


def test_minimum_constraints_are_the_declared_bounds():
    project = _project()["project"]
    extras = project["optional-dependencies"]
    declared = {}
    for requirement in project["dependencies"] + [r for group in extras.values() for r in group]:
        name, bound = _name(requirement)
        assert declared.setdefault(name, bound) == bound, f"{name} has two lower bounds"
    pins = {}
    for line in (ROOT / "constraints-min.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            m = re.fullmatch(r"([A-Za-z0-9_.-]+)==(\S+)", line)
            assert m, f"constraints-min.txt: {line!r} is not of the form name==version"
            pins[re.sub(r"[-_.]+", "-", m[1]).lower()] = Version(m[2])
    needed = {_name(r)[0] for r in project["dependencies"] + extras["test"]}
    assert needed <= set(pins), f"constraints-min.txt pins none of {sorted(needed - set(pins))}"
    for name, pin in pins.items():
        if name in declared:
            assert pin == declared[name], f"constraints-min.txt pins {name}=={pin}, pyproject.toml declares >={declared[name]}"
