"""precision="auto": which CPUs compute bfloat16 natively, and the warning where one emulates it."""

import re
import warnings

import pytest
import torch

from eppf.nn import BFloat16EmulationWarning, check_precision, native_bfloat16, resolve_precision
from eppf.nn import _precision

# /proc/cpuinfo excerpts (one processor each, the lines that matter) of the CPU kinds users have.
AVX2_EPYC = """processor\t: 0
vendor_id\t: AuthenticAMD
model name\t: AMD EPYC 7B12
flags\t\t: fpu vme de pse tsc msr pae mce cx8 apic sep mtrr pge mca cmov pat pse36 clflush mmx fxsr sse sse2 ht \
syscall nx mmxext fxsr_opt pdpe1gb rdtscp lm constant_tsc rep_good nopl pni pclmulqdq ssse3 fma cx16 sse4_1 sse4_2 \
movbe popcnt aes xsave avx f16c rdrand hypervisor lahf_lm cmp_legacy abm sse4a misalignsse 3dnowprefetch topoext \
ssbd ibrs ibpb stibp vmmcall fsgsbase bmi1 avx2 smep bmi2 rdseed adx smap clflushopt clwb sha_ni xsaveopt xsavec \
xgetbv1 clzero xsaveerptr arat npt nrip_save umip rdpid
bugs\t\t: sysret_ss_attrs spectre_v1 spectre_v2 spec_store_bypass
"""
ZEN4_EPYC = """processor\t: 0
vendor_id\t: AuthenticAMD
model name\t: AMD EPYC 9B14
flags\t\t: fpu vme de pse tsc msr pae mce cx8 apic sep mtrr pge mca cmov pat pse36 clflush mmx fxsr sse sse2 ht \
syscall nx mmxext fxsr_opt pdpe1gb rdtscp lm constant_tsc rep_good nopl pni pclmulqdq ssse3 fma cx16 sse4_1 sse4_2 \
movbe popcnt aes xsave avx f16c rdrand hypervisor lahf_lm cmp_legacy abm sse4a misalignsse 3dnowprefetch topoext \
fsgsbase bmi1 avx2 smep bmi2 erms invpcid avx512f avx512dq rdseed adx smap avx512ifma clflushopt clwb avx512cd \
sha_ni avx512bw avx512vl xsaveopt xsavec xgetbv1 xsaves avx512_bf16 clzero xsaveerptr wbnoinvd arat avx512vbmi \
umip pku ospke avx512_vbmi2 gfni vaes vpclmulqdq avx512_vnni avx512_bitalg avx512_vpopcntdq rdpid fsrm
"""
SAPPHIRE_RAPIDS = """processor\t: 0
vendor_id\t: GenuineIntel
model name\t: Intel(R) Xeon(R) Platinum 8481C CPU @ 2.70GHz
flags\t\t: fpu vme de pse tsc msr pae mce cx8 apic sep mtrr pge mca cmov pat pse36 clflush mmx fxsr sse sse2 ss ht \
syscall nx pdpe1gb rdtscp lm constant_tsc rep_good nopl xtopology nonstop_tsc cpuid tsc_known_freq pni pclmulqdq \
ssse3 fma cx16 pcid sse4_1 sse4_2 x2apic movbe popcnt aes xsave avx f16c rdrand hypervisor lahf_lm abm \
3dnowprefetch fsgsbase tsc_adjust bmi1 hle avx2 smep bmi2 erms invpcid rtm avx512f avx512dq rdseed adx smap \
avx512ifma clflushopt clwb avx512cd sha_ni avx512bw avx512vl xsaveopt xsavec xgetbv1 xsaves avx_vnni avx512_bf16 \
arat avx512vbmi umip pku ospke waitpkg avx512_vbmi2 gfni vaes vpclmulqdq avx512_vnni avx512_bitalg avx512_vpopcntdq \
rdpid cldemote movdiri movdir64b fsrm md_clear serialize tsxldtrk amx_bf16 avx512_fp16 amx_tile amx_int8 arch_capabilities
"""
SKYLAKE_AVX512 = """processor\t: 0
vendor_id\t: GenuineIntel
model name\t: Intel(R) Xeon(R) CPU @ 2.00GHz
flags\t\t: fpu sse sse2 ssse3 fma sse4_1 sse4_2 avx f16c bmi1 avx2 bmi2 avx512f avx512dq avx512cd avx512bw avx512vl
"""
GRAVITON3 = """processor\t: 0
BogoMIPS\t: 2100.00
Features\t: fp asimd evtstrm aes pmull sha1 sha2 crc32 atomics fphp asimdhp cpuid asimdrdm jscvt fcma lrcpc dcpop \
sha3 sm3 sm4 asimddp sha512 sve asimdfhm dit uscat ilrcpc flagm ssbs paca pacg dcpodp svei8mm svebf16 i8mm bf16 dgh rng
CPU implementer\t: 0x41
CPU part\t: 0xd40
"""
GRAVITON2 = """processor\t: 0
BogoMIPS\t: 243.75
Features\t: fp asimd evtstrm aes pmull sha1 sha2 crc32 atomics fphp asimdhp cpuid asimdrdm lrcpc dcpop asimddp ssbs
CPU implementer\t: 0x41
CPU part\t: 0xd0c
"""


@pytest.fixture(autouse=True)
def _onednn_uncapped(monkeypatch, request):
    # The tests read the CPU's features; a oneDNN cap in the environment (an older-CPU run)
    # is tested on its own below.
    if "onednn" not in request.node.name:
        monkeypatch.delenv("ONEDNN_MAX_CPU_ISA", raising=False)
        monkeypatch.delenv("DNNL_MAX_CPU_ISA", raising=False)


@pytest.fixture
def fresh_warning(monkeypatch):
    """The once-per-process emulation warning not yet given."""
    monkeypatch.setattr(_precision, "_warned_emulation", False)


def _emulating(monkeypatch, native):
    monkeypatch.setattr(_precision, "native_bfloat16", lambda device="cpu", **kw: native)


# ------------------------------------------------------------------ detection
@pytest.mark.parametrize(
    "text, native",
    [
        (AVX2_EPYC, False),  # AVX2 only: bfloat16 is emulated
        (SKYLAKE_AVX512, False),  # AVX-512 without its BF16 extension is not enough
        (ZEN4_EPYC, True),  # avx512_bf16
        (SAPPHIRE_RAPIDS, True),  # avx512_bf16 and amx_bf16
        (SAPPHIRE_RAPIDS.replace(" avx512_bf16", ""), True),  # amx_bf16 alone suffices
        (GRAVITON3, True),  # ARM with bf16
        (GRAVITON2, False),  # ARM without it
        ("", False),  # nothing known: float32
        ("model name\t: mystery\n", False),
    ],
)
def test_native_bfloat16_from_cpuinfo_text(text, native):
    assert native_bfloat16(cpuinfo=text) is native


def test_svebf16_alone_is_not_read_as_bf16():
    # words are matched whole: 'svebf16' or 'avx512_bf16x' are not 'bf16'
    assert _precision._cpuinfo_features("Features\t: fp asimd svebf16\n") == {"fp", "asimd", "svebf16"}
    assert native_bfloat16(cpuinfo="flags\t: avx2 avx512_bf16x\n") is False


def test_proc_cpuinfo_is_read_when_torch_cannot_tell(monkeypatch, tmp_path):
    # torch before 2.13 has no torch.cpu.get_capabilities: the kernel's list decides
    monkeypatch.delattr(torch.cpu, "get_capabilities", raising=False)
    for text, native in ((AVX2_EPYC, False), (ZEN4_EPYC, True), (GRAVITON3, True)):
        path = tmp_path / "cpuinfo"
        path.write_text(text)
        monkeypatch.setattr(_precision, "_CPUINFO", str(path))
        assert native_bfloat16() is native
    monkeypatch.setattr(_precision, "_CPUINFO", str(tmp_path / "absent"))  # e.g. macOS or Windows
    assert native_bfloat16() is False
    assert resolve_precision("auto") == "float32"


@pytest.mark.parametrize(
    "caps, native",
    [
        ({"architecture": "x86_64", "avx2": True, "avx512_bf16": False, "amx_bf16": False}, False),
        ({"architecture": "x86_64", "avx2": True, "avx512_bf16": True, "amx_bf16": False}, True),
        ({"architecture": "x86_64", "avx512_bf16": False, "amx_bf16": True}, True),
        ({"architecture": "aarch64", "neon": True, "bf16": True, "sve_max_length": 256}, True),
        ({"architecture": "aarch64", "neon": True, "bf16": False}, False),
    ],
)
def test_torch_capabilities_decide_where_torch_has_them(monkeypatch, tmp_path, caps, native):
    monkeypatch.setattr(torch.cpu, "get_capabilities", lambda: caps, raising=False)
    monkeypatch.setattr(_precision, "_CPUINFO", str(tmp_path / "absent"))
    assert native_bfloat16() is native


def test_auto_on_this_machine_agrees_with_the_kernels_flags():
    # Two independent sources: torch's CPUID reading and the Linux kernel's feature list.
    try:
        with open("/proc/cpuinfo") as fh:
            words = _precision._cpuinfo_features(fh.read())
    except OSError:
        pytest.skip("no /proc/cpuinfo on this system")
    expected = bool(words & {"avx512_bf16", "amx_bf16", "bf16"})
    assert native_bfloat16() is expected  # (the fixture lifts any oneDNN cap)
    assert resolve_precision("auto") == ("bfloat16" if expected else "float32")


def test_devices_other_than_the_cpu():
    if not torch.cuda.is_available():
        assert native_bfloat16("cuda") is False
        assert native_bfloat16("cuda:1") is False
    else:
        major, _ = torch.cuda.get_device_capability()
        assert native_bfloat16("cuda") is (major >= 8)
    assert native_bfloat16("meta") is False  # unknown kinds of device: float32
    assert resolve_precision("auto", "meta") == "float32"


# ----------------------------------------------------------------- resolution
@pytest.mark.parametrize("native", [False, True])
def test_resolve_auto_follows_the_hardware_and_keeps_explicit_choices(monkeypatch, fresh_warning, native):
    _emulating(monkeypatch, native)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "auto" and "float32" never warn
        assert resolve_precision("auto") == ("bfloat16" if native else "float32")
        assert resolve_precision("float32") == "float32"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert resolve_precision("bfloat16") == "bfloat16"
    assert len(caught) == (0 if native else 1)


def test_explicit_bfloat16_on_an_emulating_cpu_warns_once(monkeypatch, fresh_warning):
    _emulating(monkeypatch, False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            assert resolve_precision("bfloat16", owner="EPPF4DClassifier") == "bfloat16"
    assert len(caught) == 1
    w = caught[0]
    assert issubclass(w.category, BFloat16EmulationWarning) and issubclass(w.category, UserWarning)
    text = str(w.message)
    assert text.startswith("EPPF4DClassifier: precision='bfloat16' on a CPU without native bfloat16")
    assert "an epoch of the 4D network took 3.6 times as long as in float32" in text
    assert "precision='auto'" in text


def test_bfloat16_on_a_gpu_does_not_warn_about_the_cpu(monkeypatch, fresh_warning):
    _emulating(monkeypatch, False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert resolve_precision("bfloat16", "meta") == "bfloat16"


@pytest.mark.parametrize("value", ["fp16", "Auto", None, 16])
def test_check_precision_refuses_other_values(value):
    with pytest.raises(ValueError, match=re.escape("Net: precision must be 'float32' or 'bfloat16', got")):
        check_precision(value, owner="Net")
    msg = f"Est: precision must be 'auto', 'float32' or 'bfloat16', got {value!r}"
    with pytest.raises(ValueError, match=re.escape(msg)):
        check_precision(value, owner="Est", allow_auto=True)
    with pytest.raises(ValueError, match=re.escape(msg)):
        resolve_precision(value, owner="Est")


def test_check_precision_takes_auto_only_where_allowed():
    assert check_precision("auto", allow_auto=True) == "auto"
    with pytest.raises(ValueError, match="precision must be 'float32' or 'bfloat16', got 'auto'"):
        check_precision("auto")


@pytest.mark.parametrize("env, below", [
    ({}, False),
    ({"ONEDNN_MAX_CPU_ISA": "AVX2"}, True),
    ({"ONEDNN_MAX_CPU_ISA": "avx512_core"}, True),  # AVX-512 without BF16 dot products
    ({"DNNL_MAX_CPU_ISA": "AVX2"}, True),  # the older name
    ({"ONEDNN_MAX_CPU_ISA": "AVX512_CORE_BF16"}, False),
    ({"ONEDNN_MAX_CPU_ISA": "ALL"}, False),
])
def test_onednn_cap_below_bf16(env, below):
    assert _precision.onednn_isa_below_bf16(env) is below


def test_onednn_cap_makes_auto_float32(monkeypatch):
    # a CPU with AVX512_BF16 whose oneDNN is held to AVX2 emulates bfloat16: "auto" is float32 there
    monkeypatch.setattr(_precision, "_cpu_features", lambda: {"avx2", "avx512f", "avx512_bf16"})
    monkeypatch.delenv("DNNL_MAX_CPU_ISA", raising=False)
    monkeypatch.delenv("ONEDNN_MAX_CPU_ISA", raising=False)
    assert native_bfloat16() is True
    assert resolve_precision("auto") == "bfloat16"
    monkeypatch.setenv("ONEDNN_MAX_CPU_ISA", "AVX2")
    assert native_bfloat16() is False
    assert resolve_precision("auto") == "float32"
    # a description of another machine is not this process's oneDNN
    assert native_bfloat16(cpuinfo="flags\t: avx2 avx512_bf16\n") is True
