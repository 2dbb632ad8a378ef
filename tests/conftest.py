"""Shared set-up of the test suite.

The tests mirror the package (``tests/descriptors/test_esf.py`` tests
``eppf/descriptors/_esf.py``); the helpers that several of them import
(``eppf_reference``, ``fingerprints``, ``_public_api``) live here in ``tests/``,
which is put on ``sys.path`` for test modules in the subfolders.
"""

import os
import sys

TESTS = os.path.dirname(os.path.abspath(__file__))
if TESTS not in sys.path:
    sys.path.insert(0, TESTS)
