"""Shared set-up of the test suite.

The tests mirror the package (``tests/descriptors/test_esf.py`` tests
``eppf/descriptors/_esf.py``). ``tests`` and its folders are packages, so the
helpers several of them import are imported by name: ``tests.eppf_reference``
(a NumPy reference of EPPF), ``tests.fingerprints`` (digests of every output)
and ``tests._public_api`` (the public modules). Fixtures shared by the tests
of one folder live in that folder's ``conftest.py``.
"""
