"""Turn ModelNet10 or ModelNet40 into one flat ``.npz`` file for the experiments.

The experiments, ``eppf --data`` and the scripts in this folder read data sets
in the flat ``.npz`` layout (see :func:`eppf.datasets.load_npz`). This script
makes ``modelnet10_1024.npz`` (or any other size) from

- a local ModelNet folder in any layout :func:`eppf.datasets.load_modelnet`
  recognises (``--root``: Princeton's ``<class>/<train|test>/*.off`` meshes,
  ``modelnet40_normal_resampled`` or ``modelnet40_ply_hdf5_2048``), or
- Princeton's archive, downloaded once into the data home (``--download``,
  through :func:`eppf.datasets.fetch_modelnet`; ModelNet10 is about 450 MB).

Meshes are sampled by area with ``--n-points`` points each (seeded per file,
so the file is the same on every run); the official train/test split and the
file names (as ``ids``) are kept. Only coordinates are stored unless
``--normals`` is given.

Usage::

    python scripts/make_modelnet_npz.py --root ~/data/ModelNet10 -o modelnet10_1024.npz
    python scripts/make_modelnet_npz.py --download --version 10 -o modelnet10_1024.npz
    eppf experiment retrieval --data modelnet10_1024.npz

Exit status: 0 when the file was written, 2 on a usage error or a missing or
unreadable folder (with a message saying what to do), 130 on Ctrl-C (the
output file is then not written at all).
"""

import argparse
import os
import sys


def build_parser():
    p = argparse.ArgumentParser(
        prog="make_modelnet_npz.py",
        description="Write ModelNet10/40 as a flat .npz file (points, offsets, labels, class_names, split, ids).",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--root", help="a local ModelNet folder (official OFF meshes, resampled or HDF5 layout)")
    src.add_argument("--download", action="store_true",
                     help="download Princeton's archive once into the data home ($EPPF_DATA or ~/eppf_data)")
    p.add_argument("-o", "--output", required=True, help="the .npz file to write (its folder must exist)")
    p.add_argument("--version", type=int, choices=(10, 40), default=10, help="ModelNet10 or ModelNet40 (default 10)")
    p.add_argument("--n-points", type=int, default=1024, help="points per object (default 1024)")
    p.add_argument("--normals", action="store_true", help="also store normals (six columns)")
    p.add_argument("--subset", choices=("all", "train", "test"), default="all", help="which split part (default all)")
    p.add_argument("--on-error", choices=("raise", "skip"), default="raise",
                   help="stop at an unreadable file (default) or skip it with a warning")
    p.add_argument("--n-jobs", type=int, default=None, help="files read in parallel (default one)")
    p.add_argument("--random-state", type=int, default=0, help="seed of mesh sampling (default 0)")
    p.add_argument("--data-home", default=None, help="with --download: where the archive goes")
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    if args.n_points < 1:
        print(f"make_modelnet_npz: --n-points must be at least 1, got {args.n_points}", file=sys.stderr)
        return 2
    out_dir = os.path.dirname(os.path.abspath(args.output))
    if not os.path.isdir(out_dir):
        print(f"make_modelnet_npz: cannot write {args.output!r}: no such folder {out_dir!r}", file=sys.stderr)
        return 2
    if args.root is not None and not os.path.isdir(args.root):
        print(f"make_modelnet_npz: no such folder: {args.root!r}\n"
              f"  Give the folder that holds ModelNet{args.version}'s class folders (e.g. the unpacked\n"
              f"  ModelNet{args.version}.zip from https://modelnet.cs.princeton.edu/), or use --download.",
              file=sys.stderr)
        return 2
    from eppf.datasets import fetch_modelnet, load_modelnet, save_npz

    load_kwargs = dict(version=args.version, subset=args.subset, n_points=args.n_points,
                       normals=bool(args.normals), on_error=args.on_error, n_jobs=args.n_jobs,
                       random_state=args.random_state)
    try:
        if args.root is not None:
            data = load_modelnet(args.root, **load_kwargs)
        else:
            data = fetch_modelnet(data_home=args.data_home, **load_kwargs)
        save_npz(args.output, data.data, data.target, data.target_names, split=data.split, ids=data.ids)
    except KeyboardInterrupt:
        print("make_modelnet_npz: interrupted; nothing written", file=sys.stderr)
        return 130
    except (OSError, ValueError) as exc:
        print(f"make_modelnet_npz: {exc}", file=sys.stderr)
        return 2
    n_train = int((data.split == "train").sum())
    print(f"wrote {args.output}: {len(data.data)} objects ({n_train} train / {len(data.data) - n_train} test), "
          f"{len(data.target_names)} classes, {args.n_points} points each"
          + (f"; {len(data.skipped)} files skipped" if data.skipped else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
