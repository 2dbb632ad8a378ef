"""Reading and sampling ModelNet-style OFF meshes versus computing their EPPF descriptors.

Usage::

    nice -n 10 python benchmarks/bench_io.py                 # 200 meshes of ~400 faces, 20 of ~4,000
    python benchmarks/bench_io.py --n-meshes 500 --n-jobs 2

Meshes are random convex hulls written in ModelNet's official layout
(``<class>/train/<class>_<k>.off``) with ModelNet's glued first line
(``OFF<n_v> <n_f> 0``) and six significant digits per coordinate, as in the
published files. Per object the table reports, in milliseconds:

- ``read``: :func:`eppf.io.read_mesh` alone;
- ``read+sample``: :func:`eppf.datasets.load_modelnet` with ``n_points=2048``
  (reading, area-weighted sampling with face normals, bookkeeping);
- ``EPPF``: :class:`eppf.EPPFTransformer` ``fit_transform`` on those clouds
  (normals given, so no normal estimation), with the same ``n_jobs``.

The target: ``read+sample`` below ``EPPF``.
"""

import argparse
import os
import tempfile
import time

import numpy as np
from scipy.spatial import ConvexHull

from eppf import EPPFTransformer
from eppf.datasets import load_modelnet
from eppf.io import read_mesh


def write_meshes(root, n_meshes, n_vertices, seed=0):
    rng = np.random.RandomState(seed)
    files = []
    for k in range(n_meshes):
        cls = ("chair", "table", "lamp", "sofa")[k % 4]
        folder = os.path.join(root, cls, "train")
        os.makedirs(folder, exist_ok=True)
        # points on an ellipsoid all lie on the hull: about 2 * n_vertices faces
        pts = rng.normal(size=(n_vertices, 3))
        pts /= np.linalg.norm(pts, axis=1, keepdims=True)
        pts *= rng.uniform(5, 50, size=3)
        hull = ConvexHull(pts)
        used = np.unique(hull.simplices)
        remap = np.full(n_vertices, -1)
        remap[used] = np.arange(used.size)
        v, f = pts[used], remap[hull.simplices]
        path = os.path.join(folder, f"{cls}_{k:04d}.off")
        with open(path, "w") as fh:
            fh.write(f"OFF{len(v)} {len(f)} 0\n")
            fh.write("".join(f"{a:.6g} {b:.6g} {c:.6g}\n" for a, b, c in v))
            fh.write("".join(f"3 {a} {b} {c}\n" for a, b, c in f))
        files.append(path)
    return files


def run(n_meshes, n_vertices, n_jobs):
    with tempfile.TemporaryDirectory() as root:
        files = write_meshes(root, n_meshes, n_vertices)
        n_faces = np.mean([read_mesh(f).faces.shape[0] for f in files])
        t0 = time.perf_counter()
        for f in files:
            read_mesh(f)
        t_read = time.perf_counter() - t0
        t0 = time.perf_counter()
        data = load_modelnet(root, n_points=2048, n_jobs=n_jobs)
        t_load = time.perf_counter() - t0
        est = EPPFTransformer(random_state=0, n_jobs=n_jobs)
        est.fit_transform(data.data[:4])  # warm-up
        t0 = time.perf_counter()
        est.fit_transform(data.data)
        t_eppf = time.perf_counter() - t0
    per = 1e3 / n_meshes
    return n_faces, t_read * per, t_load * per, t_eppf * per


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-meshes", type=int, default=200)
    parser.add_argument("--n-jobs", type=int, default=1)
    args = parser.parse_args()
    cases = [(args.n_meshes, 220), (max(2, args.n_meshes // 10), 2100)]
    print(f"n_jobs={args.n_jobs}; milliseconds per object")
    print(f"{'meshes':>7} {'faces':>7} {'read':>8} {'read+sample':>12} {'EPPF':>8}")
    for n_meshes, n_vertices in cases:
        n_faces, t_read, t_load, t_eppf = run(n_meshes, n_vertices, args.n_jobs)
        print(f"{n_meshes:>7} {n_faces:>7.0f} {t_read:>8.2f} {t_load:>12.2f} {t_eppf:>8.2f}")


if __name__ == "__main__":
    main()
