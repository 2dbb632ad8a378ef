"""Look-ups per f4 line under other skip codes: a model of the EPPF walk, not a timing.

The f4 walk (``eppf/descriptors/_eppf_walk_port.h``) steps along each line's
dominant axis, in the direction in which that coordinate grows, and at every
step looks up a 2-bit code of the voxel it stands on: 0 where the voxel is
occupied, else how many voxels from it on (at most 3) are proved empty by the
cone ahead of it (every voxel a line of slope at most 1 in both other axes
can reach), and it moves that far. A line stops once its f4 bin is certain.
The time of the walk follows its look-ups, and the look-ups follow the codes:
this script counts them for other codes, to tell which would pay for their
extra grids before any kernel is written.

Each scheme gives a voxel the number ``E`` of voxels from it on proved empty
(0 where occupied), computed by dynamic programming over the grid's slices
along the axis (``E = 1 + min E`` of the voxels a step can reach), capped at
``cap``:

- ``cone``: today's cone (a step moves by -1, 0 or +1 in both other axes);
  cap 3 is today's codes, cap 1 a walk without skips;
- ``cone@s``: today's cone, the walk beginning a share ``s`` of the way into
  the line and taking the voxels before that point last (the surface the line
  leaves is walked only if the bin is still uncertain);
- ``quadrant``: four cones a step direction, one per sign of the two other
  axes' slopes (a step moves by 0 or +1 times that sign in each), chosen by
  the line: narrower, so longer skips near the surface, but four grids an
  axis instead of one, and caps above 3 need a third bit plane.

A line is the one ``_line_bin`` walks: voxel ``v1 + floor(k delta / L + 1/2)``
at step k = 0..L, both ends occupied, bins at ``ceil(b T / n4)`` occupied
voxels of T = L + 1; the model applies the stopping rule after every look-up
(the kernels test every few steps, so they look up a little more). Objects:
ModelNet10, 1,024 points each, on the default 64^3 grid over the bounding
cube, random pairs (numpy's generator, not the kernel's draws: the same
statistics). Lines without inner voxels (L <= 1) are not walked and not
counted. The counts depend on the data only, not on the CPU.

Measured with ``python benchmarks/bench_walk_model.py --data-dir DIR``
(100 objects, 4,000 pairs each)::

    scheme     cap  look-ups per walked line  vs today's codes
    cone         1                     20.30              2.20
    cone         3                      9.24              1.00
    cone         7                      7.88              0.85
    cone       any                      7.74              0.84
    quadrant     3                      8.27              0.89
    quadrant     7                      5.91              0.64
    quadrant   any                      5.39              0.58
    cone@0.25    3                      9.32              1.01
    cone@0.25  any                      7.79              0.84
    cone@0.5     3                      9.69              1.05
    cone@0.5   any                      8.34              0.90

(95.8% of the walked lines end in the bottom f4 bin; 76 s with the last rows.) Longer skips of
today's cone save 15% of the look-ups at cap 7 (a third bit plane and three
times the cone steps to build it) and 16% without a cap: a line spends its
look-ups near its two ends, on the surface, where the wide cone meets other
surface voxels at once. Quadrant cones with skips up to 7 save 36%, but
need 12 grids of 3 bit planes (1.2 MB at 64^3, beyond a Zen 2 core's 512 KB
L2 cache) instead of 3 grids of 2 (192 KB), built per object with 12 times
the cone steps: building today's grids takes about 3% of the AVX2 kernel's
time (perf), so about 36% for these, against about 20% saved in the walk
(36% of its 55%). Beginning the walks inside the line saves nothing (1.01 and
1.05 at cap 3): lines meet occupied voxels along their length too, not only
at the surface they leave. None halves the kernel.
"""

import argparse
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from _data import default_dir, in_dir  # noqa: E402

#: The default EPPF grid and f4 bins (EPPFTransformer's grid_size and n_bins[3]).
GRID, N4 = 64, 3
#: No cap: larger than any line.
ANY = 1 << 20
SCHEMES = (("cone", (1, 3, 7, ANY)), ("quadrant", (3, 7, ANY)))
#: Walks of today's cone that begin this share of the way into the line (the surface the line leaves is
#: left for last), at these caps.
STARTS, START_CAPS = (0.25, 0.5), (3, ANY)


def voxels(points, grid=GRID):
    """The voxel of every point on a ``grid``^3 grid over the points' bounding cube (as the kernels place them)."""
    low = points.min(axis=0)
    side = (points.max(axis=0) - low).max()
    return np.clip(np.floor((points - low) * (grid / side)).astype(np.int64), 0, grid - 1)


def empty_run(occupied, axis, moves):
    """``E`` of every voxel for steps along +``axis``: 0 where occupied, else 1 + the least ``E`` of the
    voxels one step on, offset by each (dy, dz) of ``moves`` in the other two axes (outside the grid: ANY)."""
    occ = np.moveaxis(occupied, axis, 0)
    g = occ.shape[1]
    out = np.empty(occ.shape, dtype=np.int64)
    ahead = np.full(occ.shape[1:], ANY, dtype=np.int64)
    for x in range(occ.shape[0] - 1, -1, -1):
        padded = np.pad(ahead, 1, constant_values=ANY)
        least = np.full(occ.shape[1:], ANY, dtype=np.int64)
        for dy, dz in moves:
            least = np.minimum(least, padded[1 + dy:1 + dy + g, 1 + dz:1 + dz + g])
        ahead = np.where(occ[x], 0, np.minimum(least + 1, ANY))
        out[x] = ahead
    return np.moveaxis(out, 0, axis)


def code_grids(occupied, scheme):
    """{(axis, sign_y, sign_z): E grid}; the cone's grid serves every sign pair (key signs 0)."""
    if scheme == "cone":
        box = [(dy, dz) for dy in (-1, 0, 1) for dz in (-1, 0, 1)]
        return {(a, 0, 0): empty_run(occupied, a, box) for a in range(3)}
    return {(a, sy, sz): empty_run(occupied, a, [(0, 0), (sy, 0), (0, sz), (sy, sz)])
            for a in range(3) for sy in (-1, 1) for sz in (-1, 1)}


def lookups(inner_occupied, inner_e, lo, hi, cap, start=0):
    """Look-ups of one line's walk: (occupied flags, E) of its inner voxels in walk order, bin thresholds.

    The walk begins at inner voxel ``start`` (0: the first, as the kernels walk) and goes to the line's
    end, then walks the voxels before ``start`` (its skips there stop at ``start``): the voxels counted,
    and so the bin, are the same from any start.
    """
    occ, count, rem = 2, 0, len(inner_occupied)
    for k, stop in ((start, len(inner_occupied)), (0, start)):
        while k < stop and rem and occ < hi and occ + rem >= lo:
            count += 1
            if inner_occupied[k]:
                occ, k, rem = occ + 1, k + 1, rem - 1
            else:
                step = min(int(inner_e[k]), cap, stop - k)
                k, rem = k + step, rem - step
    return count


def model_object(points, rng, n_pairs, schemes=SCHEMES):
    """{(scheme, cap): (look-ups, walked lines)} and the f4 bin counts of one object's random pairs."""
    vox = voxels(points)
    occupied = np.zeros((GRID,) * 3, dtype=bool)
    occupied[vox[:, 0], vox[:, 1], vox[:, 2]] = True
    grids = {name: code_grids(occupied, name) for name, _ in schemes}
    n = len(points)
    first = rng.integers(0, n, n_pairs)
    second = rng.integers(0, n - 1, n_pairs)
    second += second >= first
    totals = {(name, cap): [0, 0] for name, caps in schemes for cap in caps}
    totals.update({(share, cap): [0, 0] for share in STARTS for cap in START_CAPS})
    bins = np.zeros(N4, dtype=np.int64)
    for a, b in zip(first, second):
        delta = vox[b] - vox[a]
        length = int(np.abs(delta).max())
        if length <= 1:
            continue
        thresholds = [math.ceil(k * (length + 1) / N4) for k in range(1, N4)]
        steps = np.arange(length + 1)[:, None]
        line = vox[a] + np.floor(steps * delta / length + 0.5).astype(np.int64)
        axis = int(np.argmax(np.abs(delta)))
        if delta[axis] < 0:  # walked from the other end, so that the dominant coordinate grows
            line, delta = line[::-1], -delta
        inner = line[1:-1]
        inner_occupied = occupied[inner[:, 0], inner[:, 1], inner[:, 2]]
        bins[sum(2 + int(inner_occupied.sum()) >= t for t in thresholds)] += 1
        others = [m for m in range(3) if m != axis]
        signs = tuple(1 if delta[m] >= 0 else -1 for m in others)
        for name, caps in schemes:
            e = grids[name][(axis, 0, 0) if name == "cone" else (axis, *signs)]
            inner_e = e[inner[:, 0], inner[:, 1], inner[:, 2]]
            for cap in caps:
                counted = totals[(name, cap)]
                counted[0] += lookups(inner_occupied, inner_e, thresholds[0], thresholds[-1], cap)
                counted[1] += 1
            if name == "cone":
                for share in STARTS:
                    for cap in START_CAPS:
                        counted = totals[(share, cap)]
                        counted[0] += lookups(inner_occupied, inner_e, thresholds[0], thresholds[-1], cap,
                                              start=int(share * len(inner)))
                        counted[1] += 1
    return totals, bins


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data-dir", default=default_dir(), help="folder of modelnet10_1024.npz "
                                                                   "(default $EPPF_BENCH_DATA)")
    parser.add_argument("--objects", type=int, default=100, help="objects, spread over the file (default 100)")
    parser.add_argument("--pairs", type=int, default=4000, help="random pairs per object (default 4,000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.objects < 1 or args.pairs < 1:
        parser.error("--objects and --pairs must be at least 1")
    path = in_dir("bench_walk_model", args.data_dir, "modelnet10_1024")
    with np.load(path, allow_pickle=False) as data:
        points, offsets = data["points"], data["offsets"]
    pick = np.linspace(0, len(offsets) - 2, args.objects).astype(int)
    rng = np.random.default_rng(args.seed)
    totals = {}
    bins = np.zeros(N4, dtype=np.int64)
    start = time.perf_counter()
    for done, k in enumerate(pick, 1):
        got, got_bins = model_object(points[offsets[k]:offsets[k + 1]], rng, args.pairs)
        for key, (n_lookups, n_lines) in got.items():
            counted = totals.setdefault(key, [0, 0])
            counted[0] += n_lookups
            counted[1] += n_lines
        bins += got_bins
        print(f"object {done}/{len(pick)} ({time.perf_counter() - start:.0f} s)", flush=True)
    print(f"\n{len(pick)} ModelNet10 objects, {args.pairs:,} random pairs each, {GRID}^3 grid; walked lines' f4 bins: "
          + ", ".join(f"{share:.1%}" for share in bins / bins.sum()))
    today = totals[("cone", 3)][0] / totals[("cone", 3)][1]
    print(f"\n{'scheme':<9}{'cap':>5}  look-ups per walked line  vs today's codes")
    for name, caps in SCHEMES:
        for cap in caps:
            per_line = totals[(name, cap)][0] / totals[(name, cap)][1]
            label = "any" if cap == ANY else str(cap)
            print(f"{name:<9}{label:>5}  {per_line:>24.2f}  {per_line / today:>16.2f}")
    for share in STARTS:
        for cap in START_CAPS:
            per_line = totals[(share, cap)][0] / totals[(share, cap)][1]
            label = "any" if cap == ANY else str(cap)
            print(f"{'cone@' + format(share, 'g'):<9}{label:>5}  {per_line:>24.2f}  {per_line / today:>16.2f}")


if __name__ == "__main__":
    main()
