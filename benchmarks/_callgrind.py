"""Instructions per object of eppf's compiled code, two builds side by side (``bench_baselines.py --callgrind``).

Wall and CPU times move with other work on a shared machine; the number of
instructions a kernel executes does not. Each (build, level) runs once under
``valgrind --tool=callgrind`` (``_sidebyside.run_callgrind``): every task on
the same 1,024-point objects with normals given, counted only inside eppf's
compiled entry points and only for the timed pass. The table gives
instructions per object for this checkout and, with ``--compare-build``, the
other one and the ratio (this / other). valgrind models a CPU without
AVX-512, so the kernels run at most their AVX2 code there; the level each
ran at is printed. One run costs a minute or two (the interpreter and
NumPy start under valgrind).
"""

import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _data import benchmark_objects, write_objects  # noqa: E402
from _sidebyside import REPO, check_build, cpu_model, describe_levels, run_callgrind  # noqa: E402


def run(data_dir, n_objects, levels, tasks, compare_build=None):
    """Count, print and return {(build, level): ({task: instructions per object}, levels)}."""
    builds = [("this", REPO)]
    if compare_build is not None:
        builds.append(("other", check_build(compare_build)))
    small, _, source = benchmark_objects(data_dir, n_objects, 0, prog="bench_baselines")
    from eppf.preprocessing._normals import estimate_normals_batch
    from eppf.utils._validation import pack_point_clouds

    points, _, offsets = pack_point_clouds(small)
    nrm = estimate_normals_batch(points, offsets, 10, "centroid", n_jobs=1)
    clouds = [np.hstack([points[a:b], nrm[a:b]]) for a, b in zip(offsets[:-1], offsets[1:])]
    print(f"CPU: {cpu_model()} (valgrind's model of it has no AVX-512); objects: {source}", flush=True)
    results = {}
    with tempfile.TemporaryDirectory(prefix="eppf-callgrind-") as tmp:
        path = os.path.join(tmp, "objects.bin")
        write_objects(path, clouds)
        for lv in levels:
            for name, build in builds:
                print(f"callgrind: {name} build at {lv} ({', '.join(tasks)}) ...", flush=True)
                try:
                    results[(name, lv)] = run_callgrind(tasks, path, lv, build)
                except (RuntimeError, ValueError, OSError) as exc:
                    print(f"  failed: {exc}", flush=True)
                    continue
                print(f"  kernels: {describe_levels(results[(name, lv)][1])}", flush=True)
    print(f"\ninstructions per object in eppf's compiled code (callgrind), {len(clouds)} objects, one thread")
    head = f"{'level':<8} {'task':<12} {'this build':>14}"
    if compare_build is not None:
        head += f" {'other build':>14} {'this/other':>10}"
    print(head)
    print("-" * len(head))
    for lv in levels:
        mine = results.get(("this", lv), ({}, {}))[0]
        theirs = results.get(("other", lv), ({}, {}))[0]
        for task in tasks:
            line = f"{lv:<8} {task:<12} {mine.get(task, float('nan')):>14,.0f}"
            if compare_build is not None:
                a, b = mine.get(task), theirs.get(task)
                line += f" {b if b is not None else float('nan'):>14,.0f} {a / b if a and b else float('nan'):>10.3f}"
            print(line, flush=True)
    return results
