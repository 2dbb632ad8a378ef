"""Every ratio issue 29 targets, side by side in one run (``bench_baselines.py --targets``).

One thread, 1,024-point objects with normals given (PCA, 10 neighbors,
pointing away from the centroid, as the PCL reference runs), CPU ms per
object, best of the rounds. Columns: eppf at each requested SIMD level (a
worker process each, ``EPPF_SIMD`` set; below AVX-512 NumPy and OpenBLAS are
held to AVX2 too); PCL 1.13 (the harness of ``pcl_harness/``) and Open3D run
natively once a round. Rows: the EPPF kernel and transform, PCL's GASD,
normals against Open3D at 1,024 and 10,000 points, CVFH, GRSD and ESF against
PCL's, and with ``--compare-build`` the EPPF kernel against another build,
each ratio with PASS/FAIL against the issue's target at the levels the issue
sets it for ("info" elsewhere).
"""

import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import _pcl  # noqa: E402
from _data import benchmark_objects, write_objects  # noqa: E402
from _sidebyside import (Worker, WorkerError, check_build, cpu_model, describe_levels, load_average,  # noqa: E402
                         run_rounds)

#: eppf tasks timed at each level; (task, objects): "1k" the 1,024-point objects with normals, "10k" the large ones.
EPPF_JOBS = (("eppf_kernel", "1k"), ("eppf", "1k"), ("gasd", "1k"), ("esf", "1k"), ("cvfh", "1k"),
             ("cvfh_default", "1k"), ("grsd", "1k"), ("normals", "1k"), ("normals", "10k"))
PCL_JOBS = (("gasd", "1k"), ("esf", "1k"), ("cvfh", "1k"), ("cvfh_default", "1k"), ("grsd", "1k"), ("normals", "1k"),
            ("normals", "10k"))
COMPARE_JOBS = (("eppf_kernel", "1k"), ("eppf", "1k"))


def tier(levels):
    """The CPU kind a worker's kernels stand for: "avx512", "avx2" or "scalar" (from its EPPF kernel's level)."""
    name = str(levels.get("eppf", "scalar"))
    return "avx512" if name.startswith("avx512") else "avx2" if name.startswith("avx2") else "scalar"


#: (figure, comparison, threshold, tiers the issue sets it for). Ratios are "ours / theirs" unless said.
TARGETS = {
    "eppf_gasd": ("<=", 2.3, ("avx2", "avx512")),
    "portable_avx2": ("<=", 1.5, ("scalar",)),
    "build_avx2": ("<=", 0.5, ("avx2",)),
    "build_avx512": ("<=", 1.0, ("avx512",)),
    "normals": (">=", 3.0, ("avx2", "avx512")),
    "cvfh": ("<=", 0.5, ("avx2", "avx512")),
    "grsd": ("<=", 0.5, ("avx2", "avx512")),
    "esf": ("<=", 0.2, ("avx2", "avx512")),
}


def verdict(name, ratio, tier_name):
    """``"PASS"``/``"FAIL"`` against target ``name`` where the issue sets it for ``tier_name``; ``"info"`` elsewhere."""
    op, threshold, tiers = TARGETS[name]
    if ratio is None or not np.isfinite(ratio):
        return "n/a"
    if tier_name not in tiers:
        return "info"
    ok = ratio <= threshold if op == "<=" else ratio >= threshold
    return "PASS" if ok else "FAIL"


def target_text(name):
    op, threshold, tiers = TARGETS[name]
    return f"{'≤' if op == '<=' else '≥'} {threshold:g} ({', '.join(tiers)})"


def _ratio(a, b):
    return None if a is None or b is None or b == 0 else a / b


def _ms(v):
    return "-" if v is None else f"{v:.3f}" if v < 10 else f"{v:.2f}"


def _cell(ratio, name, tier_name):
    if ratio is None:
        return "-"
    return f"{ratio:#.3g} {verdict(name, ratio, tier_name)}"


def _plain(ratio):
    return "-" if ratio is None else f"{ratio:#.3g}"


def build_rows(columns, t, compare=None):
    """The table: a list of (figure, target, [cell per column]).

    ``columns``: (key, tier) per eppf column; ``t``: the run's Timings with keys
    (who, task, objects), who a column key, "pcl", "open3d" or ("build", key).
    """
    def ours(col, task, objs="1k"):
        return t.ms((col, task, objs))

    pcl = {job: t.ms(("pcl",) + job) for job in PCL_JOBS}
    o3d = {objs: t.ms(("open3d", "open3d_normals", objs)) for objs in ("1k", "10k")}
    rows = []

    def add(label, target, cells):
        rows.append((label, target, cells))

    add("EPPF kernel, ms", "", [_ms(ours(c, "eppf_kernel")) for c, _ in columns])
    add("EPPF transform, ms", "", [_ms(ours(c, "eppf")) for c, _ in columns])
    add("PCL GASD, ms", "", [_ms(pcl[("gasd", "1k")])] * len(columns))
    add("EPPF transform / PCL GASD", target_text("eppf_gasd"),
        [_cell(_ratio(ours(c, "eppf"), pcl[("gasd", "1k")]), "eppf_gasd", tr) for c, tr in columns])
    add("our GASD / PCL GASD", "", [_plain(_ratio(ours(c, "gasd"), pcl[("gasd", "1k")])) for c, _ in columns])
    avx2 = next((c for c, tr in columns if tr == "avx2"), None)
    cells = []
    for c, tr in columns:
        kern = lambda col: ours(col, "eppf_kernel") or ours(col, "eppf")  # noqa: E731
        cells.append(_cell(_ratio(kern(c), kern(avx2)), "portable_avx2", tr) if tr == "scalar" and avx2 else "-")
    add("EPPF kernel, portable / AVX2", target_text("portable_avx2"), cells)
    if compare is not None:
        for task, label in (("eppf_kernel", "EPPF kernel"), ("eppf", "EPPF transform")):
            cells = []
            for c, tr in columns:
                r = _ratio(ours(c, task), t.ms((("build", c), task, "1k")))
                name = "build_avx512" if tr == "avx512" else "build_avx2"
                cells.append(_cell(r, name, tr if tr in ("avx2", "avx512") else "-"))
            add(f"{label}, this build / --compare-build", "≤ 0.5 (avx2), ≤ 1 (avx512)", cells)
    for objs, n in (("1k", "1,024"), ("10k", "10,000")):
        add(f"normals {n} pts, eppf ms", "", [_ms(ours(c, "normals", objs)) for c, _ in columns])
        add(f"normals {n} pts, Open3D ms", "", [_ms(o3d[objs])] * len(columns))
        add(f"normals {n} pts, Open3D / eppf", target_text("normals"),
            [_cell(_ratio(o3d[objs], ours(c, "normals", objs)), "normals", tr) for c, tr in columns])
        add(f"normals {n} pts, PCL / eppf", "",
            [_plain(_ratio(pcl[("normals", objs)], ours(c, "normals", objs))) for c, _ in columns])
    for task, label in (("cvfh", "CVFH"), ("cvfh_default", "CVFH, PCL's defaults"), ("grsd", "GRSD"),
                        ("esf", "ESF")):
        target = task.split("_")[0]
        add(f"{label}, eppf ms", "", [_ms(ours(c, task)) for c, _ in columns])
        add(f"{label}, PCL ms", "", [_ms(pcl[(task, "1k")])] * len(columns))
        add(f"{label}, eppf / PCL", target_text(target),
            [_cell(_ratio(ours(c, task), pcl[(task, "1k")]), target, tr) for c, tr in columns])
    return rows


def format_text(headers, rows):
    """A plain-text table: figure, target, one column per eppf level."""
    widths = [max(len(h), *(len(r[i] if i < 2 else r[2][i - 2]) for r in rows)) for i, h in enumerate(headers)]
    def line(cells):
        return "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))
    out = [line(headers), "  ".join("-" * w for w in widths)]
    out += [line([label, target] + cells) for label, target, cells in rows]
    return "\n".join(out)


def format_rst(title, headers, rows):
    """The same table as an rST ``list-table`` (for docs/performance.rst)."""
    out = [f".. list-table:: {title}", "   :header-rows: 1", ""]
    for cells in [headers] + [[label, target] + cells for label, target, cells in rows]:
        out.append(f"   * - {cells[0]}")
        out += [f"     - {c}" if c else "     -" for c in cells[1:]]
    return "\n".join(out)


def run(data_dir, n_objects, n_large, levels, rounds, compare_build=None, pcl=True, open3d=True, rst=False,
        command=""):
    """Measure and print the targets table; returns (headers, rows)."""
    if compare_build is not None:
        compare_build = check_build(compare_build)
    print(f"CPU: {cpu_model()}; {os.cpu_count()} logical CPUs; load average {load_average():.1f}", flush=True)
    small, big, source = benchmark_objects(data_dir, n_objects, n_large, prog="bench_baselines")
    from eppf.preprocessing._normals import estimate_normals_batch
    from eppf.utils._validation import pack_point_clouds

    points, _, offsets = pack_point_clouds(small)
    nrm = estimate_normals_batch(points, offsets, 10, "centroid", n_jobs=1)
    c1k = [np.hstack([points[a:b], nrm[a:b]]) for a, b in zip(offsets[:-1], offsets[1:])]
    print(f"objects: {source}; {len(big)} of them grown to 10,000 points for the normals", flush=True)
    with tempfile.TemporaryDirectory(prefix="eppf-bench-") as tmp:
        files = {"1k": os.path.join(tmp, "objects_1k.bin"), "10k": os.path.join(tmp, "objects_10k.bin")}
        write_objects(files["1k"], c1k)
        write_objects(files["10k"], big)
        workers, jobs, columns, headers = [], [], [], ["figure", "target"]
        legend = []
        try:
            seen = {}
            probe = Worker("native")
            native = probe.ask(op="info")["levels"]
            probe.close()
            for lv in levels:
                print(f"starting eppf at {lv} ...", flush=True)
                w = Worker(lv)
                workers.append(w)
                info = w.ask(op="info")
                got = describe_levels(info["levels"])
                if got in seen:
                    print(f"  {lv}: the kernels run as at {seen[got]} ({got}): left out", flush=True)
                    continue
                seen[got] = lv
                tr = tier(info["levels"])
                emulated = got != describe_levels(native)
                head = f"{'native (' + tr + ')' if lv == 'native' else lv}{', emulated' if emulated else ''}"
                legend.append(f"{head}: {'EPPF_SIMD unset' if lv == 'native' else 'EPPF_SIMD=' + lv}, {got}")
                print(f"  {legend[-1]} (eppf {info['version']})", flush=True)
                columns.append((lv, tr))
                headers.append(head)
                jobs += [((lv, task, objs), f"{lv}:{task}@{objs}",
                          w.timer(task, files[objs])) for task, objs in EPPF_JOBS]
                if compare_build is not None:
                    cw = Worker(lv, build=compare_build)
                    workers.append(cw)
                    cinfo = cw.ask(op="info")
                    if not os.path.abspath(cinfo["eppf"]).startswith(compare_build + os.sep):
                        raise ValueError(f"--compare-build: the worker imported eppf from {cinfo['eppf']}, "
                                         f"not from {compare_build}")
                    print(f"  compare build at {lv}: {describe_levels(cinfo['levels'])} (eppf {cinfo['version']})",
                          flush=True)
                    jobs += [((("build", lv), task, objs), f"build:{lv}:{task}",
                              cw.timer(task, files[objs])) for task, objs in COMPARE_JOBS]
            exe = _pcl.harness() if pcl else None
            if exe is not None:
                jobs += [(("pcl", task, objs), f"pcl:{task}@{objs}", _pcl_call(exe, task, files[objs]))
                         for task, objs in PCL_JOBS]
            if open3d:
                ow = Worker("native", pin=True)
                workers.append(ow)
                try:
                    ow.ask(op="time", task="open3d_normals", file=files["1k"])
                    jobs += [(("open3d", "open3d_normals", objs), f"open3d@{objs}",
                              ow.timer("open3d_normals", files[objs])) for objs in ("1k", "10k")]
                except WorkerError as exc:
                    print(f"Open3D: skipped ({exc})", flush=True)
            t = run_rounds(jobs, rounds)
            if exe is not None and workers:
                _agreement(workers[0], exe, files["1k"], tmp)
        finally:
            for w in workers:
                w.close()
    rows = build_rows(columns, t, compare_build)
    print(f"\nCPU ms per object, one thread, best of {rounds} rounds; {source}; normals given; "
          f"load average {load_average():.1f} at the end. PCL and Open3D run natively (the same figure in every "
          "column); 'emulated': eppf held to a lower level on this CPU.", flush=True)
    for key, msg in t.errors.items():
        print(f"  not measured: {key}: {msg}")
    print("columns: " + "; ".join(legend))
    print(format_text(headers, rows), flush=True)
    if rst:
        print()
        print("Columns: " + "; ".join(legend) + ".\n")
        print(format_rst(f"{cpu_model()}: ``{command}``", headers, rows))
    return headers, rows


def _pcl_call(exe, task, path):
    return lambda: _pcl.time_pcl(exe, path, task) / 1e3


def _agreement(worker, exe, path, tmp):
    """PCL's GASD rows beside eppf's on the timed objects: the same objects and settings, so (nearly) the same rows."""
    try:
        ours = os.path.join(tmp, "gasd.npy")
        worker.ask(op="rows", task="gasd", file=path, out=ours)
        X = np.load(ours)
        theirs = os.path.join(tmp, "gasd_pcl.bin")
        _pcl.time_pcl(exe, path, "gasd", rows=theirs)
        R = _pcl.read_rows(theirs, "gasd", [0] * len(X))
        l1 = np.abs(X - R).sum(axis=1)
        print(f"check: eppf's and PCL's GASD rows on these objects, per-row L1 distance: median {np.median(l1):.1e}, "
              f"max {l1.max():.1e} (row sums {X.sum(axis=1).mean():.3f} / {R.sum(axis=1).mean():.3f})", flush=True)
    except (WorkerError, RuntimeError, ValueError, OSError) as exc:
        print(f"check of PCL's GASD rows not made ({exc})", flush=True)
