#!/usr/bin/env bash
# The test suite against the oldest release of every dependency eppf declares.
#
#   scripts/check_min_versions.sh [pytest arguments]
#
# Makes a virtual environment (build/venv-min, or $EPPF_MIN_VENV) that sees no other
# site-packages, installs the pins of constraints-min.txt there (wheels only), then eppf
# itself with its test extra, checks that the pinned versions are what is imported, and
# runs the tests. A second run reuses the environment (delete the folder for a new one).
#
# torch comes from PyTorch's CPU wheel index ($EPPF_TORCH_INDEX, by default
# https://download.pytorch.org/whl/cpu), about 200 MB; set EPPF_TORCH_INDEX= (empty)
# where that index cannot be reached, and pip takes torch from PyPI, whose Linux x86-64
# build is the CUDA one (about 2.5 GB with its nvidia-* packages).
# PYTHON picks the interpreter that makes the environment (default: python3).
set -euo pipefail
cd "$(dirname "$0")/.."

venv=${EPPF_MIN_VENV:-build/venv-min}
torch_index=${EPPF_TORCH_INDEX-https://download.pytorch.org/whl/cpu}

[ -x "$venv/bin/python" ] || "${PYTHON:-python3}" -m venv "$venv"
py="$venv/bin/python"

# torch alone first: only it may come from the extra index
torch_pin=$(grep -E '^torch==' constraints-min.txt)
if [ -n "$torch_index" ]; then
    "$py" -m pip install --only-binary=:all: --extra-index-url "$torch_index" "$torch_pin"
else
    "$py" -m pip install --only-binary=:all: "$torch_pin"
fi
# every pin, as a requirement, from wheels only (an old release without a wheel for this
# Python fails here instead of compiling for minutes)
"$py" -m pip install --only-binary=:all: -r constraints-min.txt
"$py" -m pip install -c constraints-min.txt -e ".[test]"

"$py" - <<'PY'
import importlib.metadata as md
import os
import re

from packaging.version import Version

import eppf

root = os.getcwd()
assert os.path.dirname(os.path.dirname(os.path.abspath(eppf.__file__))) == root, (
    f"eppf is imported from {eppf.__file__}, not from this checkout")
wrong = []
with open("constraints-min.txt") as fh:
    for line in fh:
        m = re.match(r"([A-Za-z0-9_.-]+)==(\S+)", line)
        if m:
            have = md.version(m[1])
            print(f"{m[1]:>16} {have}")
            if Version(Version(have).public) != Version(m[2]):
                wrong.append(f"{m[1]} {have} (pinned {m[2]})")
if wrong:
    raise SystemExit("not the minimum versions: " + ", ".join(wrong))
print(f"eppf {eppf.__version__} from {os.path.dirname(eppf.__file__)}")
PY

exec "$py" -m pytest -p no:cacheprovider "$@"
