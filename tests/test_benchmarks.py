"""The benchmarks' helper logic (benchmarks/_*.py): no PCL, Open3D, valgrind or real data needed."""

import os
import sys

import numpy as np
import pytest

BENCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks")
sys.path.insert(0, BENCH)

import _callgrind  # noqa: E402,F401  (imports cleanly)
import _pcl  # noqa: E402
import _sidebyside as sbs  # noqa: E402
import _targets  # noqa: E402
from _data import read_objects, write_objects  # noqa: E402

X86 = """processor\t: 0
vendor_id\t: AuthenticAMD
cpu family\t: 25
model\t\t: 17
model name\t: AMD EPYC 9454 48-Core Processor
flags\t\t: fpu sse2 avx avx2 avx512f avx512bw
processor\t: 1
model name\t: ignored second copy
"""
ARM = """processor\t: 0
BogoMIPS\t: 243.75
Features\t: fp asimd evtstrm aes crc32
CPU implementer\t: 0x41
CPU part\t: 0xd0c
"""


def test_cpu_model_reads_cpuinfo():
    assert sbs.cpu_model(X86, "Linux") == "AMD EPYC 9454 48-Core Processor (family 25, model 17; AVX-512)"
    assert "AVX2)" in sbs.cpu_model(X86.replace(" avx512f avx512bw", ""), "Linux")
    arm = sbs.cpu_model(ARM, "Linux")
    assert "part 0xd0c" in arm and arm.endswith("(NEON/ASIMD)")


def test_parse_levels():
    assert sbs.parse_levels(None) == ("native",)
    assert sbs.parse_levels("scalar, AVX2,avx-512,avx2") == ("scalar", "avx2", "avx512")
    assert sbs.parse_levels("all") == ("native", "avx2", "scalar")
    with pytest.raises(ValueError, match="unknown SIMD level 'sse4'"):
        sbs.parse_levels("avx2,sse4")


def test_level_env():
    assert sbs.level_env("native") == {}
    assert sbs.level_env("avx512") == {"EPPF_SIMD": "avx512"}
    env = sbs.level_env("avx2")
    assert env["EPPF_SIMD"] == "avx2"
    assert sbs.level_env("scalar", older_cpu=False) == {"EPPF_SIMD": "scalar"}


def test_objects_file_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    clouds = [rng.normal(size=(n, 6)) for n in (5, 1, 17)]
    path = str(tmp_path / "o.bin")
    write_objects(path, clouds)
    back = read_objects(path)
    assert len(back) == 3 and all(np.array_equal(a, b) for a, b in zip(clouds, back))
    with open(path, "rb") as f:
        assert f.read(8) == b"EPPFOBJ1"
    with pytest.raises(ValueError, match="all alike"):
        write_objects(path, [np.zeros((3, 3)), np.zeros((3, 6))])
    (tmp_path / "bad.bin").write_bytes(b"NOTOBJ00" + bytes(16))
    with pytest.raises(ValueError, match="not an objects file"):
        read_objects(str(tmp_path / "bad.bin"))
    with open(path, "r+b") as f:  # truncated values
        f.truncate(os.path.getsize(path) - 8)
    with pytest.raises(ValueError, match="does not match"):
        read_objects(path)


def test_verdicts():
    assert _targets.verdict("esf", 0.19, "avx2") == "PASS"
    assert _targets.verdict("esf", 0.21, "avx512") == "FAIL"
    assert _targets.verdict("esf", 0.5, "scalar") == "info"
    assert _targets.verdict("normals", 3.1, "avx2") == "PASS"
    assert _targets.verdict("normals", 2.9, "avx2") == "FAIL"
    assert _targets.verdict("portable_avx2", 1.4, "scalar") == "PASS"
    assert _targets.verdict("cvfh", None, "avx2") == "n/a"
    assert _targets.tier({"eppf": "avx512-skipping"}) == "avx512"
    assert _targets.tier({"eppf": "scalar"}) == "scalar"


def test_targets_table_from_timings():
    t = sbs.Timings()
    for key, ms in {("native", "eppf", "1k"): 0.3, ("native", "eppf_kernel", "1k"): 0.25,
                    ("avx2", "eppf", "1k"): 0.9, ("avx2", "eppf_kernel", "1k"): 0.8,
                    ("scalar", "eppf_kernel", "1k"): 1.6, ("pcl", "gasd", "1k"): 0.4,
                    ("pcl", "esf", "1k"): 10.0, ("native", "esf", "1k"): 1.5, ("avx2", "esf", "1k"): 2.5}.items():
        t.add(key, ms / 1e3)
    rows = _targets.build_rows([("native", "avx512"), ("avx2", "avx2"), ("scalar", "scalar")], t)
    table = {label: cells for label, _, cells in rows}
    assert table["EPPF transform / PCL GASD"][:2] == ["0.750 PASS", "2.25 PASS"]
    assert table["EPPF kernel, portable / AVX2"] == ["-", "-", "2.00 FAIL"]
    assert table["ESF, eppf / PCL"][:2] == ["0.150 PASS", "0.250 FAIL"]
    assert table["CVFH, eppf / PCL"] == ["-", "-", "-"]
    text = _targets.format_text(["figure", "target", "a", "b", "c"], rows)
    assert "0.750 PASS" in text
    docutils = pytest.importorskip("docutils.core")
    rst = _targets.format_rst("title", ["figure", "target", "a", "b", "c"], rows)
    tree = docutils.publish_doctree(rst, settings_overrides={"report_level": 2, "halt_level": 2})
    assert "0.750 PASS" in tree.astext()


def test_callgrind_parts(tmp_path):
    out = str(tmp_path / "cg.out")
    for i, total in enumerate([100, 0, 250, 0], start=1):
        with open(f"{out}.{i}", "w") as f:
            f.write(f"desc: Trigger: --dump-before=marker\nsummary: {total}\ntotals: {total}\n")
    with open(out, "w") as f:
        f.write("desc: Trigger: Program termination\nsummary: 7\n")
    parts = sbs.callgrind_parts(out)
    assert parts == [100, 0, 250, 0]
    assert sbs.split_parts(parts, 2) == [100, 250]
    assert sbs.split_parts([5, 6], 2) == [5, 6]
    with pytest.raises(ValueError, match="3 marked parts for 2 tasks"):
        sbs.split_parts([1, 2, 3], 2)
    cmd = sbs.callgrind_command("x.out", ["python", "w.py"])
    assert cmd[:2] == ["valgrind", "--tool=callgrind"] and cmd[-2:] == ["python", "w.py"]


def test_pcl_output_and_missing_tools(capsys, monkeypatch, tmp_path):
    assert _pcl.parse_line("noise\npcl_bench esf objects 3 ms_per_object 12.5 passes 1\n", "esf") == 12.5
    with pytest.raises(ValueError, match="no result line for 'gasd'"):
        _pcl.parse_line("pcl_bench esf objects 3 ms_per_object 12.5 passes 1", "gasd")
    tools, missing = _pcl.find_tools(which=lambda name: None)
    assert tools is None and "compiler" in missing
    monkeypatch.setenv("EPPF_BENCH_CACHE", str(tmp_path))
    monkeypatch.setattr(_pcl, "find_tools", lambda: (None, "pkg-config is not on PATH"))
    assert _pcl.harness() is None
    assert capsys.readouterr().out == "PCL: skipped (pkg-config is not on PATH)\n"
    assert _pcl.compile_command("c++", ["-lpcl_common"], "out")[-3:] == ["-o", "out", "-lpcl_common"]
    rows = tmp_path / "r.bin"
    np.arange(2 * 21, dtype=np.float32).tofile(rows)
    assert _pcl.read_rows(str(rows), "grsd", [5, 5]).shape == (2, 21)
    normals = _pcl.read_rows(str(rows), "normals", [4, 10])
    assert [n.shape for n in normals] == [(4, 3), (10, 3)]
    with pytest.raises(ValueError, match="unknown PCL task"):
        _pcl.time_pcl("exe", "file", "fpfh")


def test_worker_times_a_task_at_a_level(tmp_path):
    rng = np.random.default_rng(1)
    clouds = []
    for _ in range(2):
        p = rng.normal(size=(200, 3))
        clouds.append(np.hstack([p, p / np.linalg.norm(p, axis=1, keepdims=True)]))
    path = str(tmp_path / "o.bin")
    write_objects(path, clouds)
    w = sbs.Worker("scalar", timeout=300)
    try:
        info = w.ask(op="info")
        assert info["levels"]["EPPF_SIMD"] == "scalar" and info["levels"]["eppf"] == "scalar"
        r = w.ask(op="time", task="gasd", file=path)
        assert r["n"] == 2 and r["cpu_s"] >= 0
        with pytest.raises(sbs.WorkerError, match="unknown task 'nope'"):
            w.ask(op="time", task="nope", file=path)
        out = str(tmp_path / "rows.npy")
        w.ask(op="rows", task="gasd", file=path, out=out)  # the worker carried on after the error
        from eppf import GASDTransformer

        assert np.array_equal(np.load(out), GASDTransformer(n_jobs=1).fit_transform([c[:, :3] for c in clouds]))
    finally:
        w.close()
    assert w.proc.poll() is not None


def test_check_build(tmp_path):
    with pytest.raises(ValueError, match="no eppf package"):
        sbs.check_build(str(tmp_path))
    (tmp_path / "eppf").mkdir()
    (tmp_path / "eppf" / "__init__.py").write_text("")
    with pytest.raises(ValueError, match="no built extensions"):
        sbs.check_build(str(tmp_path))


def test_walk_model_codes_and_lookups():
    # The model's "cone, cap 3" grid is the portable kernel's code grid; its quadrant grids follow their
    # definition (brute force over the voxels a run of steps can reach); a hand-walked line's look-ups.
    import itertools

    import bench_walk_model as wm

    from eppf.descriptors._eppf_fast import _cone_codes

    rng = np.random.default_rng(3)
    for g, density in ((7, 0.05), (9, 0.02), (5, 0.3)):
        occ = rng.random((g, g, g)) < density
        cone = wm.code_grids(occ, "cone")
        assert np.array_equal(np.stack([np.minimum(cone[(a, 0, 0)], 3) for a in range(3)]),
                              _cone_codes(occ, portable=True))
        grids = wm.code_grids(occ, "quadrant")
        for (a, sy, sz), e in grids.items():
            for x, y, z in itertools.product(range(g), repeat=3):
                v = np.array([x, y, z])
                others = [m for m in range(3) if m != a]
                run = 0  # voxels from v on, along +a, every path of steps by (0 or sy, 0 or sz) empty
                while True:
                    free = True
                    for j in range(run + 1):  # the voxels run steps ahead: offsets 0..run times the signs
                        for k in range(run + 1):
                            w = v.copy()
                            w[a] += run
                            w[others[0]] += sy * j
                            w[others[1]] += sz * k
                            if w[a] >= g:
                                free = free and True
                            elif 0 <= w[others[0]] < g and 0 <= w[others[1]] < g and occ[tuple(w)]:
                                free = False
                    if not free or v[a] + run >= g:
                        break
                    run += 1
                expected = run if v[a] + run < g else wm.ANY
                assert e[x, y, z] == expected, (a, sy, sz, x, y, z)
    # hand-walked lines: 8 inner voxels, lo = 4, hi = 7 (T = 10), empty but the last
    inner_occ = np.array([0, 0, 0, 0, 0, 0, 0, 1], dtype=bool)
    inner_e = np.array([5, 4, 3, 3, 2, 1, 1, 0])
    assert wm.lookups(inner_occ, inner_e, 4, 7, 3) == 3  # skips 3, 3, 1: occ 2 + 1 left < 4, bottom bin
    assert wm.lookups(inner_occ, inner_e, 4, 7, 1) == 7  # one voxel a look-up until occ + rem < lo
    assert wm.lookups(inner_occ, inner_e, 4, 7, wm.ANY) == 3  # skips 5, 1, 1 (the codes of voxels 5 and 6)
    assert wm.lookups(np.array([True]), np.array([0]), 1, 3, 3) == 1  # T = 3: one look-up, occupied: top
    assert wm.lookups(np.array([False]), np.array([1]), 1, 2, 3) == 0  # both ends reach hi = 2 at once
    # from inner voxel 4: skips 2 and 1, the occupied last voxel, then voxels 0-3: a skip of 3 and one of 1
    # (its code 3 cut at the start voxel): occ + rem stays at lo until the last voxel is seen
    assert wm.lookups(inner_occ, inner_e, 4, 7, 3, start=4) == 5
    assert wm.lookups(inner_occ, inner_e, 4, 7, 3, start=0) == 3
    full = np.array([1, 1, 1, 1, 1, 1, 1, 1], dtype=bool)  # every voxel occupied: hi reached, from any start
    for start in range(8):
        assert wm.lookups(full, np.zeros(8, dtype=int), 4, 7, 3, start=start) == 5
