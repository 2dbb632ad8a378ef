"""The ``eppf`` command's glibc heap settings (eppf.utils._malloc)."""

import ctypes
import platform
import sys

import pytest

from eppf.cli import _main
from eppf.utils import _malloc

GLIBC = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"


@pytest.mark.parametrize("environ", [
    {"MALLOC_MMAP_THRESHOLD_": "1000000"},
    {"MALLOC_TRIM_THRESHOLD_": "0"},
    {"MALLOC_TOP_PAD_": "0"},
    {"GLIBC_TUNABLES": "glibc.malloc.mmap_threshold=65536"},
])
def test_user_choice_stands(environ, monkeypatch):
    calls = []
    monkeypatch.setattr(_malloc.ctypes, "CDLL", lambda *a: calls.append(a))
    assert _malloc.keep_freed_memory(environ) is False
    assert calls == []  # the C library is not even opened


def _fake_libc(monkeypatch, mallopt, version="2.36"):
    class Libc:
        pass

    Libc.mallopt = staticmethod(mallopt)  # a plain function stands in for the foreign one
    monkeypatch.setattr(_malloc.ctypes, "CDLL", lambda *a: Libc())
    monkeypatch.setattr(_malloc.sys, "platform", "linux")
    monkeypatch.setattr(_malloc.platform, "libc_ver", lambda: ("glibc", version))


def test_unrelated_tunables_do_not_stop_it(monkeypatch):
    calls = []
    _fake_libc(monkeypatch, lambda param, value: calls.append((param, value)) or 1)
    assert _malloc.keep_freed_memory({"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX512F"}) is True
    assert calls == [(-3, _malloc.MMAP_THRESHOLD), (-1, _malloc.TRIM_THRESHOLD)]


def test_older_glibc_cap_falls_back_to_32_mib(monkeypatch):
    calls = []

    def mallopt(param, value):
        calls.append((param, value))
        return 0 if (param == -3 and value > 32 << 20) else 1

    _fake_libc(monkeypatch, mallopt, "2.31")
    assert _malloc.keep_freed_memory({}) is True
    assert calls == [(-3, _malloc.MMAP_THRESHOLD), (-3, 32 << 20), (-1, _malloc.TRIM_THRESHOLD)]


def test_refused_settings_report_false(monkeypatch):
    _fake_libc(monkeypatch, lambda param, value: 0)
    assert _malloc.keep_freed_memory({}) is False


def test_other_platforms_untouched(monkeypatch):
    monkeypatch.setattr(_malloc.ctypes, "CDLL", lambda *a: pytest.fail("opened a C library"))
    monkeypatch.setattr(_malloc.sys, "platform", "darwin")
    assert _malloc.keep_freed_memory({}) is False
    monkeypatch.setattr(_malloc.sys, "platform", "linux")
    monkeypatch.setattr(_malloc.platform, "libc_ver", lambda: ("", ""))  # musl
    assert _malloc.keep_freed_memory({}) is False


@pytest.mark.skipif(not GLIBC, reason="glibc only")
def test_real_glibc_accepts_the_settings():
    # mallopt returns 1 on success; the settings only move where memory comes from
    assert _malloc.keep_freed_memory({}) is True
    buf = ctypes.create_string_buffer(64 << 20)  # served from the heap now, still usable
    buf[len(buf) - 1] = b"x"
    assert buf.raw[-1:] == b"x"


def test_command_applies_it_only_as_the_process_command(monkeypatch):
    calls = []
    monkeypatch.setattr(_main, "keep_freed_memory", lambda: calls.append(1) or True)
    with pytest.raises(SystemExit):
        _main.main(["--version"])  # a Python caller's argv: its allocator is left alone
    assert calls == []
    monkeypatch.setattr(sys, "argv", ["eppf", "--version"])
    with pytest.raises(SystemExit):
        _main.main()
    assert calls == [1]
