"""Speed and leave-one-out retrieval of EPPF and the paper's baseline descriptors.

Prints one table in the layout of the paper's Table II: one column per
descriptor (and matching metric), rows for the number of bins, the
milliseconds of CPU time per object on one thread (best of ``--repeats``
passes) at 1,024 points
(ModelNet10) and 10,000 points (the largest DALES objects), then per data
set the total accuracy, mean class accuracy, macro precision, recall and F1
of leave-one-out 1-NN retrieval, as mean ± std over ``--draws`` descriptor
draws where the descriptor is random.
PCL 1.13's own ESF and OUR-CVFH outputs (``pcl_<data set>.npz`` files with
arrays ``esf`` and ``ourcvfh``, one row per object, in ``--reference-dir``)
are scored the same way as a yardstick when given.

Every object is centered on its mean and scaled so its largest bounding-box
side is 1 (as the PCL reference runs), and gets PCA normals over 10
neighbors pointing away from its centroid, computed once and given to every
descriptor (normal estimation is timed separately).

Before the table, the EPPF kernel is timed at every level the CPU has
(in one process, passes alternating; ``--eppf-kernel`` does only this, on
ModelNet10, every level's output checked equal to the scalar kernel's)
beside our GASD and VFH, and PCL 1.13's ESF, GASD, VFH, CVFH and GRSD are
timed on the same objects in the same run by the harness in
``benchmarks/pcl_harness`` (built on demand where PCL, pkg-config and a C++
compiler are installed; left out with one line otherwise). No figure is
quoted from another run or machine: the CPU model and the SIMD level each
kernel ran at are printed with the figures.

``--targets`` prints every ratio of the speed targets (issue 29) side by
side in one run, one thread, 1,024 points, normals given: eppf at each
``--levels`` level in a process of its own (``EPPF_SIMD``; e.g.
``--levels native,avx2,scalar`` runs an AVX2-only and a portable machine's
code on an AVX-512 one), PCL and Open3D natively, each ratio with PASS/FAIL;
``--compare-build PATH`` adds the EPPF kernel of another checkout (with
built extensions) at each level; ``--rst`` also prints the table for
``docs/performance.rst``. Without ``--data-dir`` it runs on the built-in
synthetic shapes.

``--callgrind`` counts instead the instructions per object that eppf's
compiled code executes for each task (``valgrind --tool=callgrind``; counts do
not depend on the machine's load), at each ``--levels`` level, and with
``--compare-build PATH`` beside the other build's, with their ratio. valgrind
models a CPU without AVX-512: there the kernels run at most their AVX2 code.

Usage::

    python benchmarks/bench_baselines.py --targets --levels native,avx2,scalar [--data-dir DIR] [--rst]
    python benchmarks/bench_baselines.py --callgrind --levels scalar,avx2 --compare-build OTHER_CHECKOUT
    python benchmarks/bench_baselines.py --data-dir DIR       # everything
    python benchmarks/bench_baselines.py --data-dir DIR --eppf-kernel   # EPPF kernel levels, GASD, VFH
    python benchmarks/bench_baselines.py --data-dir DIR --draws 3 --descriptors esf wahl
    python benchmarks/bench_baselines.py --data-dir DIR --no-retrieval   # timings only

Apart from ``--targets`` and ``--callgrind`` (which fall back to the
synthetic shapes), needs ``modelnet10_1024.npz`` and ``dales_objects.npz`` in
``--data-dir`` (default: ``$EPPF_BENCH_DATA``, no other default); exits with status 2 and
how to make them when they are absent (``scripts/make_modelnet_npz.py``).
"""

import argparse
import os
import sys
import time

import numpy as np
from sklearn.metrics import pairwise_distances_chunked

import eppf
from eppf.preprocessing._normals import estimate_normals_batch
from eppf.utils._validation import pack_point_clouds
from eppf.metrics import leave_one_out_retrieval, retrieval_scores

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import _pcl  # noqa: E402
from _data import default_dir, in_dir, write_objects  # noqa: E402
from _sidebyside import cpu_model, describe_levels, load_average, parse_levels  # noqa: E402

DATASETS = {"modelnet10": "modelnet10_1024", "dales": "dales_objects"}
METRICS = ("total_accuracy", "mean_class_accuracy", "macro_precision", "macro_recall", "macro_f1")
SHORT = ("acc", "mAcc", "P", "R", "F1")


def descriptors():
    """name -> (factory(random_state), random?, matching metrics), for every registered descriptor.

    Built from ``eppf.registry.DESCRIPTORS`` (one thread, the paper's sample
    counts, per-object scaling for those that take a scaling), each scored by
    its natural metric and, where the paper's tables use it, the other one.
    """
    from eppf.registry import DESCRIPTORS

    out = {}
    for name, spec in DESCRIPTORS.items():
        metrics = (spec.metric,) + tuple(m for m in ("kl", "l1") if m != spec.metric and name in ("esf", "ourcvfh"))
        out[name] = (lambda rs, spec=spec: spec.make(scaling="object", random_state=rs, n_jobs=1),
                     not spec.deterministic, metrics)
    return out


DATA_DIR = None  # set by main()


def load(name):
    path = in_dir("bench_baselines", DATA_DIR, DATASETS[name])
    d = np.load(path)
    pts, off = d["points"].astype(np.float64), d["offsets"]
    clouds = []
    for k in range(len(off) - 1):
        p = pts[off[k] : off[k + 1]]
        p = p - p.mean(axis=0)
        clouds.append(p / np.ptp(p, axis=0).max())
    return clouds, d["labels"]


def with_normals(clouds):
    points, _, offsets = pack_point_clouds(clouds)
    t = time.process_time()
    normals = estimate_normals_batch(points, offsets, 10, "centroid", n_jobs=1)
    dt = time.process_time() - t
    out = [np.hstack([points[a:b], normals[a:b]]) for a, b in zip(offsets[:-1], offsets[1:])]
    return out, dt


def loo_l1(X, y):
    """Leave-one-out 1-NN with the L1 distance (ties to the lowest index)."""
    y = np.asarray(y)
    pred = np.empty(len(X), dtype=y.dtype)
    start = 0
    for block in pairwise_distances_chunked(X, metric="manhattan", working_memory=256):
        rows = np.arange(start, start + len(block))
        block[np.arange(len(block)), rows] = np.inf
        pred[rows] = y[np.argmin(block, axis=1)]
        start += len(block)
    return pred


def score(X, y, metric):
    pred = leave_one_out_retrieval(X, y) if metric == "kl" else loo_l1(X, y)
    return retrieval_scores(y, pred)


def time_descriptor(factory, clouds, repeats=1):
    """Milliseconds per object, best of ``repeats`` passes: CPU time of this
    process (robust on a shared machine, one thread) and wall-clock time.
    The best pass is the one least disturbed by other work on the machine."""
    est = factory(0).fit(clouds)
    est.transform(clouds[:2])  # warm up
    cpu, wall = [], []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        est.transform(clouds)
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - t)
    return 1e3 * min(cpu) / len(clouds), 1e3 * min(wall) / len(clouds)


def pcl_times(clouds, tasks, repeats=3):
    """PCL 1.13's CPU ms per object for each task on these clouds (the harness, one thread), in this run.

    {task: ms}; empty (with one printed line) where the harness cannot be built.
    """
    import tempfile

    exe = _pcl.harness()
    if exe is None:
        return {}
    out = {}
    with tempfile.TemporaryDirectory(prefix="eppf-bench-") as tmp:
        path = os.path.join(tmp, "objects.bin")
        write_objects(path, clouds)
        for task in tasks:
            print(f"PCL {task} ...", flush=True)
            try:
                out[task] = _pcl.time_pcl(exe, path, task, repeats=repeats)
            except (RuntimeError, ValueError, OSError) as exc:
                print(f"PCL {task}: not measured ({exc})", flush=True)
    return out


def _vs_pcl(ms, pcl, name):
    return f"; PCL 1.13 in this run: {pcl[name]:.3f} ({ms / pcl[name]:.0%} of PCL's)" if name in pcl else ""


def bench_vfh_gasd(clouds, repeats=3, pcl=None):
    """VFH and GASD (PCL 1.13's global descriptors): ms per object, 1 thread, normals given,
    beside PCL's own time on the same objects in the same run (``pcl``: {task: ms} of :func:`pcl_times`)."""
    from eppf.descriptors._gasd import GASDTransformer
    from eppf.descriptors._vfh import VFHTransformer

    pcl = pcl or {}
    for name, factory in (("vfh", lambda rs: VFHTransformer(n_jobs=1)), ("gasd", lambda rs: GASDTransformer(n_jobs=1))):
        ms, wall = time_descriptor(factory, clouds, repeats)
        print(f"{name}: {ms:.3f} ms/object at 1,024 points (CPU time; wall clock {wall:.3f}){_vs_pcl(ms, pcl, name)}",
              flush=True)


# (name, kernel level, what it is) for the EPPF kernel comparison; levels the CPU lacks are left out.
EPPF_LEVELS = (
    ("EPPF, scalar kernel", 0, "portable C, one pair at a time"),
    ("EPPF, AVX2 kernel", 1, "the default until the AVX-512 kernel: f1-f3 and walks 4 pairs at a time"),
    ("EPPF, AVX-512, grouped walk", 2, "draws, f1-f3 and walks 8 pairs at a time, lines grouped by length"),
    ("EPPF, AVX-512, skipping walk", 3, "as level 2, lanes refilled from a queue, lines walked along their dominant "
     "axis past voxels of an empty cone ahead"),
)


def _pack(clouds):
    """The (N, 3) points, (N, 3) normals and offsets of clouds with normals, as the kernel reads them."""
    stacked = np.ascontiguousarray(np.vstack(clouds))
    offsets = np.cumsum([0] + [len(c) for c in clouds]).astype(np.int64)
    return stacked[:, :3], stacked[:, 3:6], offsets


def bench_eppf_kernel(clouds, repeats=5, pcl=None):
    """The EPPF kernel at every level the CPU has, beside our GASD and VFH, in one run.

    The paper's settings (EPPFTransformer's defaults: 20,000 pairs, 64^3
    grid, n_bins (20, 4, 5, 3)), normals given, one thread. Two figures per
    row, CPU ms per object (best of ``repeats`` passes; the levels' passes
    alternate so that a busy spell of a shared machine hits all of them):
    the compiled kernel alone (``eppf_counts`` on the packed clouds) and the
    whole ``transform`` (validation, kernel, weighting). Every level must
    give the same counts, bit for bit (checked here). Returns the rows
    (name, kernel ms, transform ms) and prints them as a table with the
    ratios to our GASD and VFH and, where ``pcl`` ({task: ms} of
    :func:`pcl_times`, measured in this run on these objects) has them, to
    PCL 1.13's ESF and GASD.
    """
    from eppf import EPPFTransformer, GASDTransformer, VFHTransformer
    from eppf.descriptors import _eppf_fast as core
    from eppf.utils._validation import object_seeds

    levels = [row for row in EPPF_LEVELS if row[1] in core._simd_levels()]
    points, normals, offsets = _pack(clouds)
    n = len(clouds)
    scales = np.array([1.0 / np.ptp(c[:, :3], axis=0).max() for c in clouds])  # scaling="object"
    seeds = object_seeds(0, n)
    est = EPPFTransformer(scaling="object", random_state=0, n_jobs=1).fit(clouds)
    args = (points, normals, offsets, scales, seeds, est.n_pairs, tuple(est.n_bins), est.grid_size,
            float(np.sqrt(3.0)), 1)
    kern = {lv: np.inf for _, lv, _ in levels}
    full = {lv: np.inf for _, lv, _ in levels}
    outs, descs = {}, {}
    old = core._set_simd_level(levels[-1][1])
    try:
        est.transform(clouds[:2])  # warm up
        for _ in range(repeats):
            for _, lv, _ in levels:
                core._set_simd_level(lv)
                c = time.process_time()
                outs[lv], _ = core.eppf_counts(*args)
                kern[lv] = min(kern[lv], time.process_time() - c)
                c = time.process_time()
                descs[lv] = est.transform(clouds)
                full[lv] = min(full[lv], time.process_time() - c)
    finally:
        core._set_simd_level(old)
    for _, lv, _ in levels[1:]:
        if not (np.array_equal(outs[lv], outs[0]) and np.array_equal(descs[lv], descs[0])):
            raise AssertionError(f"EPPF kernel level {lv} does not give the scalar kernel's output")
    default = core._default_simd_level()
    rows = [(name + (" (default)" if lv == default else ""), 1e3 * kern[lv] / n, 1e3 * full[lv] / n)
            for name, lv, _ in levels]
    others = {}
    for name, factory in (("GASD (ours)", lambda rs: GASDTransformer(n_jobs=1)),
                          ("VFH (ours)", lambda rs: VFHTransformer(n_jobs=1))):
        others[name], _ = time_descriptor(factory, clouds, repeats)
    gasd, vfh = others["GASD (ours)"], others["VFH (ours)"]
    pcl = pcl or {}
    esf, pgasd = pcl.get("esf"), pcl.get("gasd")
    print(f"\nEPPF kernel at the paper's settings vs our GASD and VFH: {n} ModelNet10 objects of 1,024 points, "
          f"normals given, one thread, CPU ms per object, best of {repeats} (1-minute load average "
          f"{load_average():.1f}; every EPPF level bit-identical); CPU: {cpu_model()}; "
          f"kernels by default: {describe_levels(eppf.simd_levels())}")
    print("| descriptor | kernel ms/object | transform ms/object | transform / our GASD | transform / our VFH "
          "| transform / PCL GASD | PCL ESF / kernel |")
    print("|---|---|---|---|---|---|---|")
    for name, k_ms, t_ms in rows:
        print(f"| {name} | {k_ms:.3f} | {t_ms:.3f} | {t_ms / gasd:.2f} | {t_ms / vfh:.2f} "
              f"| {f'{t_ms / pgasd:.2f}' if pgasd else '-'} | {f'{esf / k_ms:.0f}x' if esf else '-'} |")
    for name, ms in others.items():
        print(f"| {name} | - | {ms:.3f} | {ms / gasd:.2f} | {ms / vfh:.2f} | "
              f"{f'{ms / pgasd:.2f}' if pgasd else '-'} | |")
    for task in ("esf", "gasd", "vfh"):
        if task in pcl:
            print(f"| PCL 1.13 {task.upper()} (this run, same objects) | - | {pcl[task]:.3f} | | | | |")
    if len(rows) > 1:
        best = rows[[lv for _, lv, _ in levels].index(default)]
        print(f"speed-up of the default kernel over the AVX2 one: {rows[1][1] / best[1]:.2f}x (kernel), "
              f"{rows[1][2] / best[2]:.2f}x (transform)")
    return rows, others


def time_grsd_cvfh(clouds, repeats=1, pcl=None):
    """GRSD and CVFH beside PCL 1.13's time per object on the same objects in the same run
    (``pcl``: {task: ms} of :func:`pcl_times`; 1 thread, 1,024 points, normals given), with the
    PCL reference runs' settings, and CVFH also with PCL's defaults."""
    from eppf.descriptors._cvfh import CVFHTransformer
    from eppf.descriptors._grsd import GRSDTransformer

    pcl = pcl or {}
    specs = (
        ("GRSD", "grsd", lambda rs: GRSDTransformer(normalize=False, n_jobs=1)),
        ("CVFH", "cvfh", lambda rs: CVFHTransformer(
            aggregate="first", eps_angle=float(np.deg2rad(5.0)), curvature_threshold=1.0, normalize=False, n_jobs=1)),
        ("CVFH, PCL's defaults", None, lambda rs: CVFHTransformer(aggregate="first", normalize=False, n_jobs=1)),
    )
    for name, task, factory in specs:
        cpu, wall = time_descriptor(factory, clouds, repeats)
        print(f"{name}: {cpu:.2f} ms/object at 1,024 points (CPU time, 1 thread; wall clock {wall:.2f})"
              f"{_vs_pcl(cpu, pcl, task) if task else ''}", flush=True)


def fmt(values):
    v = 100 * np.asarray(values)
    if len(v) == 1:
        return f"{v[0]:6.2f}"
    return f"{v.mean():6.2f}±{v.std():4.2f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=10, help="descriptor draws for random descriptors (default 10)")
    ap.add_argument("--descriptors", nargs="+", default=list(descriptors()), choices=list(descriptors()))
    ap.add_argument("--datasets", nargs="+", default=list(DATASETS), choices=list(DATASETS))
    ap.add_argument("--n-time", type=int, default=None,
                    help="objects timed at 1,024 points (default 100; 20 with --callgrind)")
    ap.add_argument("--repeats", type=int, default=3, help="timing passes, the best one reported (default 3)")
    ap.add_argument("--no-retrieval", action="store_true")
    ap.add_argument("--eppf-kernel", action="store_true",
                    help="only the EPPF kernel levels beside our GASD and VFH (ModelNet10 only, under a minute)")
    ap.add_argument("--no-reference", action="store_true", help="skip PCL's reference rows")
    ap.add_argument("--data-dir", default=default_dir(),
                    help="folder with modelnet10_1024.npz and dales_objects.npz (default: $EPPF_BENCH_DATA)")
    ap.add_argument("--reference-dir", default=None, help="folder with PCL's pcl_<data set>.npz outputs (optional)")
    ap.add_argument("--no-pcl", action="store_true", help="leave PCL out (otherwise timed where its harness builds)")
    ap.add_argument("--targets", action="store_true",
                    help="every ratio of the speed targets side by side in one run, PASS/FAIL (see --levels)")
    ap.add_argument("--callgrind", action="store_true",
                    help="instructions per object of eppf's compiled code under valgrind (see --compare-build)")
    ap.add_argument("--levels", default=None,
                    help="with --targets or --callgrind: comma-separated EPPF_SIMD levels, each in a process of its "
                         "own: native, avx512, avx2, scalar or all (default: native for --targets, "
                         "scalar,avx2 for --callgrind)")
    ap.add_argument("--compare-build", default=None, metavar="PATH",
                    help="with --targets or --callgrind: another checkout with built extensions, timed beside this one")
    ap.add_argument("--n-large", type=int, default=10, help="with --targets: objects grown to 10,000 points (default 10)")
    ap.add_argument("--no-open3d", action="store_true", help="with --targets: leave Open3D out")
    ap.add_argument("--tasks", default="eppf,eppf_kernel,normals,esf,gasd,cvfh,grsd",
                    help="with --callgrind: the tasks counted (default: %(default)s)")
    ap.add_argument("--rst", action="store_true", help="with --targets: also print the table as reStructuredText")
    args = ap.parse_args(argv)
    global DATA_DIR
    DATA_DIR = args.data_dir
    if args.n_time is None:
        args.n_time = 20 if args.callgrind else 100
    try:
        levels = parse_levels(args.levels or ("scalar,avx2" if args.callgrind else "native"))
    except ValueError as exc:
        ap.error(str(exc))
    if args.targets:
        import _targets

        _targets.run(DATA_DIR, args.n_time, args.n_large, levels, args.repeats, compare_build=args.compare_build,
                     pcl=not args.no_pcl, open3d=not args.no_open3d, rst=args.rst,
                     command="python benchmarks/bench_baselines.py " + " ".join(
                         "PATH" if os.path.isabs(a) else a for a in (argv if argv is not None else sys.argv[1:])))
        return
    if args.callgrind:
        import _callgrind

        _callgrind.run(DATA_DIR, args.n_time, levels, args.tasks.split(","), args.compare_build)
        return
    if args.eppf_kernel:
        mn, _ = load("modelnet10")
        stride = max(1, len(mn) // args.n_time)
        c1k, _ = with_normals(mn[::stride][: args.n_time])
        bench_eppf_kernel(c1k, args.repeats, {} if args.no_pcl else pcl_times(c1k, ("esf", "gasd", "vfh")))
        return
    for name in {"modelnet10", "dales"} | set(args.datasets):  # both are timed; check before any work
        in_dir("bench_baselines", DATA_DIR, DATASETS[name])
    table = {}  # (descriptor, metric) -> {"ms1k", "ms10k", dataset: {metric: values}}
    specs = descriptors()

    # Speed: the same clouds for every descriptor, normals given.
    mn, _ = load("modelnet10")
    stride = max(1, len(mn) // args.n_time)
    c1k, t_n1k = with_normals(mn[::stride][: args.n_time])
    dales, _ = load("dales")
    big = [c for c in dales if len(c) >= 10000][:10]
    c10k, t_n10k = with_normals([c[:10000] for c in big])
    print(f"normals (PCA, k=10): {1e3 * t_n1k / len(c1k):.2f} ms/object at 1,024 points, "
          f"{1e3 * t_n10k / len(c10k):.2f} at 10,000", flush=True)
    pcl = {} if args.no_pcl else pcl_times(c1k, ("esf", "gasd", "vfh", "cvfh", "grsd"), args.repeats)
    bench_vfh_gasd(c1k, args.repeats, pcl)
    bench_eppf_kernel(c1k, args.repeats, pcl)
    time_grsd_cvfh(c1k, args.repeats, pcl)
    for name in list(args.descriptors):
        factory, _, metrics = specs[name]
        try:
            (ms1k, wall1k) = time_descriptor(factory, c1k, args.repeats)
        except Exception as exc:  # a descriptor still being written elsewhere
            print(f"{name}: skipped ({type(exc).__name__}: {exc})", flush=True)
            args.descriptors = [d for d in args.descriptors if d != name]
            continue
        ms10k, wall10k = time_descriptor(factory, c10k, args.repeats)
        print(f"{name}: {ms1k:.2f} ms/object at 1,024 points, {ms10k:.2f} at 10,000 (CPU time; "
              f"wall clock {wall1k:.2f} and {wall10k:.2f})", flush=True)
        for m in metrics:
            table[(name, m)] = {"ms1k": ms1k, "ms10k": ms10k}

    if not args.no_retrieval:
        for ds in args.datasets:
            clouds, y = load(ds)
            clouds, _ = with_normals(clouds)
            for name in args.descriptors:
                factory, random, metrics = specs[name]
                draws = args.draws if random else 1
                res = {m: {k: [] for k in METRICS} for m in metrics}
                t = time.perf_counter()
                for r in range(draws):
                    X = factory(1000 + r).fit_transform(clouds)
                    for m in metrics:
                        s = score(X, y, m)
                        for k in METRICS:
                            res[m][k].append(s[k])
                for m in metrics:
                    table[(name, m)][ds] = res[m]
                    table[(name, m)]["n_bins"] = X.shape[1]
                print(f"{ds} {name}: {draws} draw(s) in {time.perf_counter() - t:.0f} s, "
                      + ", ".join(f"{m} acc {fmt(res[m]['total_accuracy'])}" for m in metrics), flush=True)
            ref = os.path.join(args.reference_dir or "", f"pcl_{DATASETS[ds]}.npz")
            if not args.no_reference and args.reference_dir and os.path.exists(ref):
                r = np.load(ref)
                for key in ("esf", "ourcvfh"):
                    X = r[key].astype(np.float64)
                    for m in ("kl", "l1"):
                        Xm = X / X.sum(axis=1, keepdims=True) if m == "kl" else X
                        s = score(Xm, y, m)
                        table.setdefault((f"PCL {key}", m), {})[ds] = {k: [s[k]] for k in METRICS}
                        table[(f"PCL {key}", m)]["n_bins"] = X.shape[1]

    print()
    print(format_table(table, args.datasets, args.draws))


# The paper's column order (Table II), then PCL's own outputs as a yardstick.
ORDER = ("ourcvfh", "esf", "wahl", "eppf_short", "eppf", "PCL ourcvfh", "PCL esf")
TITLES = {
    "ourcvfh": "OUR-CVFH", "esf": "ESF", "wahl": "Wahl", "eppf_short": "EPPF short", "eppf": "EPPF",
    "PCL ourcvfh": "PCL OUR-CVFH", "PCL esf": "PCL ESF",
}
ROWS = (
    ("total_accuracy", "Total accuracy (%)"),
    ("mean_class_accuracy", "Mean accuracy (%)"),
    ("macro_precision", "Mean precision (%)"),
    ("macro_recall", "Mean recall (%)"),
    ("macro_f1", "F1-score (%)"),
)


def format_table(table, datasets, draws):
    """Markdown table in the layout of the paper's Table II: one column per
    descriptor (and matching metric), rows N_bins, ms per object, then the
    retrieval metrics per data set (mean ± std over the draws)."""
    keys = sorted(table, key=lambda k: (ORDER.index(k[0]) if k[0] in ORDER else len(ORDER), k[1]))
    head = ["Dataset", "Metric"] + [f"{TITLES.get(n, n)} ({'sym. KL' if m == 'kl' else 'L1'})" for n, m in keys]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def row(label, metric, cells):
        lines.append("| " + " | ".join([label, metric] + cells) + " |")

    row("", "N_bins", [str(table[k].get("n_bins", "-")) for k in keys])
    row("", "ms/object, 1,024 pts (CPU, 1 thread)", [f"{table[k]['ms1k']:.2f}" if "ms1k" in table[k] else "-" for k in keys])
    row("", "ms/object, 10,000 pts (CPU, 1 thread)", [f"{table[k]['ms10k']:.2f}" if "ms10k" in table[k] else "-" for k in keys])
    for ds in datasets:
        for i, (metric, label) in enumerate(ROWS):
            row(ds if i == 0 else "", label, [fmt(table[k][ds][metric]) if ds in table[k] else "-" for k in keys])
    lines.append("")
    lines.append(f"mean ± std over {draws} draws for the random descriptors (ESF, Wahl, EPPF); one run otherwise")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
