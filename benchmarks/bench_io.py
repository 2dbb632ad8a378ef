"""Files to descriptors: reading, reading with normals, and ``eppf describe`` end to end.

Usage::

    nice -n 10 python benchmarks/bench_io.py                      # 10,000 files of each kind (minutes)
    python benchmarks/bench_io.py --las-only                      # LAS/LAZ reading speed only (seconds)
    nice -n 10 python benchmarks/bench_io.py --n-files 2000 --sizes 1000,2000 --kinds ply,ply_normals
    python benchmarks/bench_io.py --cache-dir /tmp/eppf-io        # keep the folders for the next run

Folders of ``--n-files`` files of 1,024 points are written once per kind.
The clouds are anisotropic Gaussian blobs (``normal(size=(1024, 3))`` times
a per-file stretch in [0.5, 2] per axis): volumes whose density falls off
from the centre, not the surfaces that scanners and mesh samplers give.
They time reading and the pipeline, but they are the slow case of the
normals' neighbour search (a 3D neighbourhood puts about three times as
many points in the searched 3x3x3 block of cells as a surface does, and in
the sparse tails a quarter of the queries need a second try), so
``+normals`` is about 1.4x what ModelNet10 surfaces of the same size take
(``benchmarks/bench_normals.py``), and their PCA normals mean nothing
geometrically. The kinds: ``ply`` (binary, xyz), ``ply_normals`` (binary,
xyz and normals), ``ply_ascii``, ``pcd`` (binary), ``xyz`` (text) and ``off``
(a 512-face closed mesh per file, sampled to 1,024 points with face normals).
The report, per kind:

- ``read ms/file``: :func:`eppf.io.read_point_cloud` on ``--read-files``
  files of the folder (the way ``eppf describe`` reads them: the file's own
  seed, meshes sampled with ``n_points=1024``), one thread;
- ``+normals ms/file``: the same files, then PCA normals
  (:func:`eppf.preprocessing.estimate_normals`, 20 neighbours) where the file
  has none, one thread (``--normals-files`` files);

and for ``--describe-kinds``, ``python -m eppf describe FOLDER -o out.npy
--n-jobs N`` in a fresh process on the first 1k/5k/10k files (``--sizes``):
the files per second of its summary line (planning, reading, normals, EPPF,
writing; the interpreter's start and imports excluded), the wall time of the
whole process, its CPU seconds per file and its peak RSS (``ru_maxrss``).
Flat RSS across the sizes is the check that memory does not grow with the
number of files (the output rows go to disk as they come).

LAS/LAZ reading speed (``--las-points``, 2,000,000 by default; 0 skips it;
``--las-only`` runs only this): one point-format-3 tile in projected
coordinates (millimeter grid, random intensity, returns, classification,
GPS time, color) plus two extra-bytes dimensions, written by laspy as
``.las`` and ``.laz``, then read five times each (the best time counts) by
:func:`eppf.io.read_point_fields` (coordinates and every field),
:func:`eppf.io.read_point_cloud` (coordinates) and laspy itself
(``laspy.read`` and every dimension as an array, plus ``x y z``: laspy's
own speed, fields included), in millions of points per second. The
``.las`` tile is read in this process. The ``.laz`` tile is read in a fresh
process per thread count, once with ``RAYON_NUM_THREADS=1`` and once with
every core (``os.cpu_count()``): laspy decodes LAZ with lazrs's parallel
backend (``LazBackend.LazrsParallel``, its default when lazrs is installed,
which eppf's readers keep), whose chunks (50,000 points each here) are
decoded in parallel on rayon's global thread pool, whose size ``RAYON_NUM_THREADS`` sets for the whole
process. On the 2-vCPU AMD EPYC (Zen 4) KVM guest, shared with other jobs
(load average 3.9 to 4.6), laspy 2.7.0 and lazrs 0.8.2, ``--las-only``::

    file  threads  reader                Mpoints/s
    .las        -  read_point_fields          36.6
    .las        -  read_point_cloud           52.0
    .las        -  laspy, every field         16.9
    .laz        1  read_point_fields           1.4
    .laz        1  read_point_cloud            1.5
    .laz        1  laspy, every field          1.5
    .laz        2  read_point_fields           1.4
    .laz        2  read_point_cloud            1.5
    .laz        2  laspy, every field          1.4

An uncompressed tile is read in one call into fresh memory, every
whole-byte dimension is a view of the records and only the bit fields
(return number, classification, flags) and the scaled coordinates are
computed, so eppf reads it faster than laspy's own ``read`` does. LAZ is
bound by lazrs's arithmetic decoding, the same in eppf and in laspy: about
1.5 million points per second per core for this format-3 tile with GPS
time, color and extra bytes, so 20 million per second would take some 14
free cores. Here the second thread gains nothing: two threads used 1.05
CPU seconds per wall second against 0.95 for one (``getrusage``), because
the other jobs leave this process about one core's worth of time (a quiet
machine with more cores was not measured).

EPPF's default ``scaling="fit"`` needs the data set's scale before the first
row, so ``describe`` reads every file in a first pass and describes in a
second (sampled meshes and text files are kept in a temporary file, binary
point files read again beside the descriptor): the first pass is not hidden
behind the descriptor, as reading is with ``--scaling object`` (``--extra
"--scaling object"`` to measure that).

One run (2-vCPU Intel Xeon KVM guest, shared with other jobs, load
average 6 to 8; ``--n-jobs 2``)::

    kind          read ms/file  +normals ms/file
    ply                  0.209             4.281
    ply_normals          0.259             0.240
    ply_ascii            0.646             4.610
    pcd                  0.282             4.151
    xyz                  1.202             5.182
    off                  1.465             1.473

    kind          files  files/s  wall s  CPU ms/file  peak RSS MiB
    ply_normals    1000      251     8.3         3.17           150
    ply_normals    5000      366    18.0         1.66           156
    ply_normals   10000      365    31.1         1.49           159
    ply            1000      146    10.6         5.08           148
    ply           10000      128    82.1         3.36           155

The process got about 40% of the machine. A quiet run (load average 1.4 to
1.7) after the faster normals and EPPF kernels, ``--kinds ply,ply_normals
--sizes 10000``::

    kind          read ms/file  +normals ms/file
    ply                  0.133             1.430
    ply_normals          0.186             0.156

    kind          files  files/s  wall s  CPU ms/file  peak RSS MiB
    ply_normals   10000      821    14.4         1.43           158
    ply           10000      515    21.3         2.70           157

On the 2-vCPU AMD EPYC (Zen 4) KVM guest, ``--kinds ply,ply_normals --sizes
10000``, after the normals' search went to AVX-512 and ``describe --n-jobs
2`` started describing two chunks side by side on single-threaded copies of
the descriptor (same rows, bit for bit), beside the previous code (the main
branch) run right after; the machine was shared with niced jobs of others
(load average 11.6 to 12.9), so files per second are those of a process
that got part of the machine, and CPU per file is the figure to compare::

    kind          files  files/s  wall s  CPU ms/file  peak RSS MiB
    ply_normals   10000      519    22.3         1.47           186   now
    ply           10000      318    34.5         2.26           182   now
    ply_normals   10000      486    23.3         1.53           162   before
    ply           10000      211    50.4         3.40           155   before

At a load average of 6.6 to 7.1 the new code gave 1,001 files/s with
normals in the files (1.15 ms CPU per file) and 552 without (1.93 ms);
before these changes a quiet run (load about 1) gave 1,587 and 692 (1.25
and 2.84 ms). Without normals in the files, 2 ms of CPU per file would
make 1,000 files/s on two free cores; a quiet run to show it is still to
be done. Peak memory stays flat in the number of files (167 MiB at 1,000
files, 176 at 10,000); two chunks in flight instead of one cost about 20
MiB.

Later, on the same AMD guest at load averages of 1.2 to 1.9, after the
binary PLY reader's one-call path for plain ``x y z [normals]`` files (0.053
-> 0.026 ms per file here) and the EPPF wrapper passing the estimated
normals to the kernel without copies, three runs of this command each beside
the previous code (the main branch), one right after the other::

    kind          files  files/s  wall s  CPU ms/file  peak RSS MiB
    ply_normals   10000     2374     5.5         0.78           184   now
    ply           10000     1265     9.1         1.52           162   now
    ply_normals   10000     2125     5.9         0.88           188   before
    ply           10000     1205     9.5         1.53           163   before

(the other two pairs: ``ply`` 1,381 and 1,330 files/s now against 1,338
and 1,254 before). So without normals in the files ``describe`` makes
1,265 to 1,381 files per second on two cores; the CPU per file depends on
the machine's other load (the main branch took 2.16 ms per file beside
other jobs' compilers, 1.53 in a quieter moment), so compare runs made side
by side.
"""

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from eppf.io import read_point_cloud, write_mesh, write_point_cloud  # noqa: E402

KINDS = ("ply", "ply_normals", "ply_ascii", "pcd", "xyz", "off")
EXT = {"ply": "ply", "ply_normals": "ply", "ply_ascii": "ply", "pcd": "pcd", "xyz": "xyz", "off": "off"}
N_POINTS = 1024


def _sphere_mesh():
    """A closed 512-face mesh of the unit sphere (a convex hull of 258 points)."""
    from scipy.spatial import ConvexHull

    rng = np.random.RandomState(0)
    v = rng.normal(size=(258, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v, ConvexHull(v).simplices


def write_folder(folder, kind, n_files, seed=0):
    """``n_files`` files of one kind in ``folder`` (kept when it already holds them)."""
    done = os.path.join(folder, ".complete")
    if os.path.exists(done) and int(open(done).read()) >= n_files:
        return
    os.makedirs(folder, exist_ok=True)
    rng = np.random.RandomState(seed)
    mesh = _sphere_mesh() if kind == "off" else None
    for k in range(n_files):
        path = os.path.join(folder, f"obj_{k:05d}.{EXT[kind]}")
        stretch = rng.uniform(0.5, 2.0, size=3)
        if kind == "off":
            write_mesh(path, mesh[0] * stretch * rng.uniform(0.9, 1.1, size=(len(mesh[0]), 1)), mesh[1])
            continue
        p = rng.normal(size=(N_POINTS, 3)) * stretch
        if kind == "ply_normals":
            p = np.hstack([p, p / np.linalg.norm(p, axis=1, keepdims=True)])
        write_point_cloud(path, p, binary=kind != "ply_ascii")
    with open(done, "w") as fh:
        fh.write(str(n_files))


def _files(folder):
    return sorted(os.path.join(folder, f) for f in os.listdir(folder) if not f.startswith("."))


def time_reading(files, kind, with_normals):
    """Milliseconds per file of reading (and normals where the file has none), one thread."""
    from eppf.datasets._loaders import file_seeds
    from eppf.preprocessing import estimate_normals

    seeds = file_seeds(0, os.path.dirname(files[0]), files)
    n_points = N_POINTS if kind == "off" else None
    read_point_cloud(files[0], n_points=n_points, random_state=seeds[0])  # warm caches and imports
    t0 = time.perf_counter()
    for f, s in zip(files, seeds):
        c = read_point_cloud(f, n_points=n_points, random_state=s)
        if with_normals and c.shape[1] == 3:
            estimate_normals(c, n_neighbors=20, n_jobs=1)
    return 1e3 * (time.perf_counter() - t0) / len(files)


def run_describe(folder, n_files, n_jobs, extra, work):
    """(files/s of the summary line, wall s, CPU s per file, peak RSS MiB) of one describe process."""
    sub = os.path.join(work, f"describe_{os.path.basename(folder)}_{n_files}")
    if not os.path.isdir(sub):  # the first n files, as links
        os.makedirs(sub)
        for f in _files(folder)[:n_files]:
            os.symlink(f, os.path.join(sub, os.path.basename(f)))
    out = os.path.join(work, "out.npy")
    cmd = [sys.executable, "-m", "eppf", "describe", sub, "-o", out, "--n-jobs", str(n_jobs), "--no-progress"]
    cmd += shlex.split(extra)
    if os.path.basename(folder) == "off":
        cmd += ["--n-points", str(N_POINTS)]
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with tempfile.TemporaryFile("w+") as so, tempfile.TemporaryFile("w+") as se:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=so, stderr=se, env=env)
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own CPU time and peak RSS
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        so.seek(0)
        se.seek(0)
        stdout, stderr = so.read(), se.read()
    if proc.returncode:
        raise RuntimeError(f"describe failed: {stderr.strip()}")
    m = re.search(r"([\d.]+) files per second", stdout)
    rate = float(m.group(1)) if m else float("nan")
    return rate, wall, usage, stdout.strip()


def write_las_tile(folder, n_points, seed=0):
    """A point-format-3 LAS and LAZ tile of ``n_points`` in projected coordinates, every dimension filled."""
    import laspy

    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=3)
    header.scales, header.offsets = np.array([0.001, 0.001, 0.001]), np.array([512000.0, 5403000.0, 0.0])
    header.add_extra_dims([laspy.ExtraBytesParams("reflectance", "f4"), laspy.ExtraBytesParams("deviation", "u2")])
    las = laspy.LasData(header)
    las.points = laspy.ScaleAwarePointRecord.zeros(n_points, header=header)
    las.x = 512000.0 + rng.uniform(0, 1000, n_points)
    las.y = 5403000.0 + rng.uniform(0, 1000, n_points)
    las.z = rng.uniform(200, 260, n_points)
    las.intensity = rng.integers(0, 4096, n_points)
    las.return_number = rng.integers(1, 4, n_points)
    las.number_of_returns = np.full(n_points, 3)
    las.classification = rng.choice([1, 2, 5, 6], n_points)
    las.gps_time = np.sort(rng.uniform(0, 3600, n_points))
    for c in ("red", "green", "blue"):
        las[c] = rng.integers(0, 65536, n_points)
    las.reflectance = rng.normal(size=n_points).astype("f4")
    las.deviation = rng.integers(0, 100, n_points)
    paths = []
    for ext in ("las", "laz"):
        path = os.path.join(folder, f"tile.{ext}")
        las.write(path)
        paths.append(path)
    return paths


def _las_readers():
    """(name, function of a path) of eppf's two readers and laspy's own reading of every field."""
    import laspy

    from eppf.io import read_point_fields

    def laspy_every_field(path):
        las = laspy.read(path)
        return [np.asarray(las[name]) for name in list(las.point_format.dimension_names) + ["x", "y", "z"]]

    return (("read_point_fields", read_point_fields), ("read_point_cloud", read_point_cloud),
            ("laspy, every field", laspy_every_field))


def _best_rates(path, n_points, repeats):
    """[(reader, million points per second)], the best of ``repeats`` reads of ``path`` by each reader."""
    rows = []
    for name, func in _las_readers():
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            func(path)
            best = min(best, time.perf_counter() - t0)
        rows.append((name, n_points / best / 1e6))
    return rows


def _laz_rates(path, n_points, repeats, threads):
    """``_best_rates`` of a LAZ file in a fresh process whose lazrs decodes on ``threads`` threads.

    laspy decodes LAZ with lazrs's parallel backend when it is installed (eppf's readers use laspy's
    default), on rayon's global thread pool, whose size is fixed by ``RAYON_NUM_THREADS`` when the
    process first uses it: hence one process per thread count.
    """
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--time-file", path, "--las-points",
                          str(n_points), "--repeats", str(repeats)], env=env, check=True, capture_output=True,
                         text=True).stdout
    return [(name, float(rate)) for name, rate in (line.rsplit("\t", 1) for line in out.splitlines() if line)]


def time_las(paths, n_points, repeats=5):
    """Rows (file, threads, reader, million points per second): .las in this process, .laz decoded on one
    thread and on every core (``os.cpu_count()``), best of ``repeats``."""
    rows = []
    for path in paths:
        ext = os.path.splitext(path)[1]
        if ext == ".laz":
            for threads in dict.fromkeys((1, os.cpu_count() or 1)):
                rows += [(ext, threads, name, rate) for name, rate in _laz_rates(path, n_points, repeats, threads)]
        else:
            rows += [(ext, "-", name, rate) for name, rate in _best_rates(path, n_points, repeats)]
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--las-points", type=int, default=2000000, help="points of the LAS/LAZ tile (0: skip)")
    p.add_argument("--las-only", action="store_true", help="only the LAS/LAZ reading speed")
    p.add_argument("--n-files", type=int, default=10000, help="files per kind's folder (default 10,000)")
    p.add_argument("--kinds", default=",".join(KINDS), help="kinds to read (default: all)")
    p.add_argument("--read-files", type=int, default=2000, help="files timed for reading per kind")
    p.add_argument("--normals-files", type=int, default=300, help="files timed for reading + normals per kind")
    p.add_argument("--describe-kinds", default="ply_normals,ply", help="kinds run through eppf describe")
    p.add_argument("--sizes", default="1000,5000,10000", help="numbers of files given to eppf describe")
    p.add_argument("--n-jobs", type=int, default=2, help="--n-jobs of eppf describe (default 2)")
    p.add_argument("--extra", default="", help="more eppf describe options, e.g. \"--scaling object\"")
    p.add_argument("--cache-dir", default=None, help="keep the folders here (default: a temporary folder)")
    p.add_argument("--time-file", default=None, help=argparse.SUPPRESS)  # a child of time_las: one LAS/LAZ file
    p.add_argument("--repeats", type=int, default=5, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.time_file:
        for name, rate in _best_rates(args.time_file, args.las_points, args.repeats):
            print(f"{name}\t{rate!r}")
        return
    if args.las_points:
        with tempfile.TemporaryDirectory(prefix="eppf-bench-las-") as folder:
            rows = time_las(write_las_tile(folder, args.las_points), args.las_points)
        print(f"{'file':5s} {'threads':>7s}  {'reader':20s} {'Mpoints/s':>10s}")
        for ext, threads, name, rate in rows:
            print(f"{ext:5s} {threads!s:>7s}  {name:20s} {rate:10.1f}", flush=True)
        if args.las_only:
            return
        print()
    os.environ.setdefault("OMP_NUM_THREADS", str(args.n_jobs))
    base = args.cache_dir or tempfile.mkdtemp(prefix="eppf-bench-io-")
    kinds = [k for k in args.kinds.split(",") if k]
    describe_kinds = [k for k in args.describe_kinds.split(",") if k]
    sizes = [int(s) for s in args.sizes.split(",") if s]
    n_files = max([args.n_files] + sizes)
    for kind in dict.fromkeys(kinds + describe_kinds):
        t0 = time.perf_counter()
        write_folder(os.path.join(base, kind), kind, n_files)
        print(f"# {kind}: {n_files} files ready in {time.perf_counter() - t0:.1f} s", file=sys.stderr)

    print(f"{'kind':12s} {'read ms/file':>13s} {'+normals ms/file':>17s}")
    for kind in kinds:
        files = _files(os.path.join(base, kind))
        read = time_reading(files[:args.read_files], kind, False)
        normals = time_reading(files[:args.normals_files], kind, True)
        print(f"{kind:12s} {read:13.3f} {normals:17.3f}", flush=True)

    if not describe_kinds:
        return
    with tempfile.TemporaryDirectory(prefix="eppf-bench-describe-") as work:
        print(f"\neppf describe --n-jobs {args.n_jobs} {args.extra}".rstrip())
        print(f"{'kind':12s} {'files':>6s} {'files/s':>8s} {'wall s':>7s} {'CPU ms/file':>12s} {'peak RSS MiB':>13s}")
        for kind in describe_kinds:
            for n in sizes:
                rate, wall, usage, line = run_describe(os.path.join(base, kind), n, args.n_jobs, args.extra, work)
                cpu = 1e3 * (usage.ru_utime + usage.ru_stime) / n
                print(f"{kind:12s} {n:6d} {rate:8.0f} {wall:7.1f} {cpu:12.2f} {usage.ru_maxrss / 1024:13.0f}",
                      flush=True)


if __name__ == "__main__":
    main()
