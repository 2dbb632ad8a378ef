"""Where the benchmarks find the real data sets, and what to say when they are absent.

The data are not part of the repository. A benchmark takes a file with
``--data FILE.npz`` or a folder of them with ``--data-dir DIR`` (default: the
environment variable ``EPPF_BENCH_DATA``; there is no other default), and
stops with exit status 2 and :data:`HOW_TO_GET` when a file it needs is
missing.
"""

import os
import sys

ENV = "EPPF_BENCH_DATA"
HOW_TO_GET = (
    "The data are not part of the repository. Make modelnet10_1024.npz (ModelNet10, 1,024 points per object) with\n"
    "  python scripts/make_modelnet_npz.py --root PATH/TO/ModelNet10 -o modelnet10_1024.npz\n"
    "or with --download instead of --root to fetch Princeton's archive (about 450 MB) into the data home.\n"
    "Other sets (dales_objects.npz, ...) go in the same flat layout through eppf.datasets.save_npz."
)


def default_dir():
    """The data folder named by ``$EPPF_BENCH_DATA``, or None."""
    return os.environ.get(ENV) or None


def _stop(message):
    print(message, file=sys.stderr)
    sys.exit(2)


def require(prog, path, what="data file"):
    """Return ``path`` if it is a file; otherwise exit 2 saying how to get it."""
    if path is None:
        _stop(f"{prog}: no {what} given; pass --data FILE.npz (or set ${ENV} to the folder holding it).\n{HOW_TO_GET}")
    if not os.path.isfile(path):
        _stop(f"{prog}: {what} {path!r} not found.\n{HOW_TO_GET}")
    return path


def in_dir(prog, folder, name):
    """``folder/name.npz``, required to exist (exit 2 with the recipe otherwise)."""
    if not folder:
        _stop(f"{prog}: no data folder; give --data-dir DIR or set ${ENV}.\n{HOW_TO_GET}")
    return require(prog, os.path.join(folder, name + ".npz"))


# ------------------------------------------------------------ objects shared between processes

#: The first bytes of an objects file (see :func:`write_objects`).
MAGIC = b"EPPFOBJ1"


def write_objects(path, clouds):
    """Write clouds ((n_i, 3) points or (n_i, 6) points and normals) to one binary file.

    The layout, read by :func:`read_objects` and by the PCL harness
    (``benchmarks/pcl_harness/pcl_bench.cpp``), little-endian: the 8 bytes
    ``EPPFOBJ1``, int64 number of objects, int64 number of columns (3 or 6),
    int64 offsets (number of objects + 1), then the float64 values row by row.
    Every process of a side-by-side run times the same objects this way.
    """
    import numpy as np

    clouds = [np.asarray(c, dtype=np.float64) for c in clouds]
    cols = {c.shape[1] if c.ndim == 2 else -1 for c in clouds} or {3}
    if len(cols) != 1 or cols.pop() not in (3, 6):
        raise ValueError(f"write_objects: every cloud must be (n, 3) or (n, 6), all alike, for {path!r}")
    width = clouds[0].shape[1] if clouds else 3
    offsets = np.cumsum([0] + [len(c) for c in clouds]).astype("<i8")
    with open(path, "wb") as f:
        f.write(MAGIC)
        np.array([len(clouds), width], dtype="<i8").tofile(f)
        offsets.tofile(f)
        for c in clouds:
            np.ascontiguousarray(c, dtype="<f8").tofile(f)


def read_objects(path):
    """The clouds of a file written by :func:`write_objects`, as a list of float64 arrays."""
    import numpy as np

    with open(path, "rb") as f:
        if f.read(8) != MAGIC:
            raise ValueError(f"{path!r} is not an objects file (no {MAGIC.decode()} header)")
        n, width = (int(v) for v in np.fromfile(f, dtype="<i8", count=2))
        offsets = np.fromfile(f, dtype="<i8", count=n + 1)
        values = np.fromfile(f, dtype="<f8")
    if width not in (3, 6) or len(offsets) != n + 1 or values.size != offsets[-1] * width:
        raise ValueError(f"{path!r}: the header does not match the file's size")
    values = values.reshape(-1, width)
    return [values[a:b] for a, b in zip(offsets[:-1], offsets[1:])]


def scaled(cloud):
    """The cloud centered on its mean and scaled so its largest bounding-box side is 1 (the PCL reference runs)."""
    import numpy as np

    p = np.asarray(cloud, dtype=np.float64)
    p = p - p.mean(axis=0)
    return p / np.ptp(p, axis=0).max()


def densify(cloud, n_points, rng):
    """``cloud`` grown to ``n_points``: its points plus points drawn uniformly on segments
    from a random point to one of its 6 nearest neighbors, so the new points lie on the
    sampled surface at a higher density (seeded by ``rng``)."""
    import numpy as np
    from scipy.spatial import cKDTree

    c = np.asarray(cloud, dtype=np.float64)
    if n_points <= len(c):
        return np.ascontiguousarray(c[:n_points])
    _, nb = cKDTree(c).query(c, 7)
    a = rng.integers(0, len(c), size=n_points - len(c))
    b = nb[a, rng.integers(1, 7, size=len(a))]
    t = rng.random((len(a), 1))
    return np.ascontiguousarray(np.vstack([c, c[a] + t * (c[b] - c[a])]))


def benchmark_objects(folder, n_objects, n_large, large=10_000, prog="benchmark"):
    """The objects of a side-by-side run: (small, large, source).

    ``small``: ``n_objects`` ModelNet10 objects of 1,024 points (every k-th
    object of ``folder/modelnet10_1024.npz``), or the built-in synthetic
    shapes when ``folder`` is None; ``large``: the first ``n_large`` of them
    grown to ``large`` points by :func:`densify`. All centered and scaled by
    :func:`scaled`; points only (normals are added by the caller).
    """
    import numpy as np

    rng = np.random.default_rng(0)
    if folder:
        path = in_dir(prog, folder, "modelnet10_1024")
        with np.load(path, allow_pickle=False) as d:
            pts, off = d["points"], d["offsets"]
        pick = np.linspace(0, len(off) - 2, n_objects).astype(int)
        small = [scaled(pts[off[k]:off[k + 1]]) for k in pick]
        source = f"ModelNet10 ({os.path.basename(path)}), {n_objects} objects spread over the file"
    else:
        from eppf.datasets import make_shapes

        shapes = make_shapes(max(1, -(-n_objects // 10)), n_points=1024, random_state=0)
        small = [scaled(c) for c in shapes.data[:n_objects]]
        source = f"built-in synthetic shapes (eppf.datasets.make_shapes), {len(small)} objects"
    big = [scaled(densify(c, large, rng)) for c in small[:n_large]]
    return small, big, source
