"""A slow, literal NumPy reading of the EPPF functions, for testing the kernel.

Written straight from the paper's formulas (arccos, max of the two beta
angles, an explicit voxel walk with exact integer rounding) rather than from
the kernel's shortcuts, so that agreement means something.
"""

import numpy as np

F1_MAX = np.sqrt(3.0)


def bin_index(v, lo, hi, n):
    """clip(floor(n (v - lo) / (hi - lo)), 0, n - 1)."""
    return np.clip(np.floor(n * (v - lo) / (hi - lo)).astype(np.int64), 0, n - 1)


def voxelise(points, grid):
    """Voxel coordinates of each point on a grid over the bounding cube."""
    lo = points.min(axis=0)
    side = np.ptp(points, axis=0).max()
    inv = grid / side
    return np.clip(np.floor((points - lo) * inv).astype(np.int64), 0, grid - 1)


def line_voxels(a, b):
    """Voxels of the integer line a -> b: step k visits a + floor(k * delta / L + 1/2)."""
    a = np.asarray(a, dtype=np.int64)
    delta = np.asarray(b, dtype=np.int64) - a
    L = int(np.abs(delta).max())
    if L == 0:
        return a[None, :]
    k = np.arange(L + 1)[:, None]
    # floor(k * delta / L + 1/2) == floor((2 k delta + L) / (2 L)), in exact integers
    return a[None, :] + (2 * k * delta[None, :] + L) // (2 * L)


def pair_functions(points, normals, i, j, scale, grid=64):
    """The four function values (f1..f4) and f4's (occupied, total) for pairs (i, j)."""
    vox = voxelise(points, grid)
    occupied = {tuple(v) for v in vox}
    d = points[j] - points[i]
    dist = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    f1 = dist * scale
    inv = 1.0 / dist
    c1 = np.clip((normals[i] * d).sum(axis=1) * inv, -1, 1)
    c2 = np.clip((normals[j] * d).sum(axis=1) * inv, -1, 1)
    beta1 = np.arccos(c1) - np.pi / 2
    beta2 = np.arccos(c2) - np.pi / 2
    f2 = np.maximum(beta1, beta2)
    f3 = np.arccos(np.clip(np.abs((normals[i] * normals[j]).sum(axis=1)), 0, 1))
    occ = np.empty(len(i), dtype=np.int64)
    tot = np.empty(len(i), dtype=np.int64)
    for t, (a, b) in enumerate(zip(i, j)):
        line = line_voxels(vox[a], vox[b])
        tot[t] = len(line)
        occ[t] = sum(tuple(v) in occupied for v in line)
    return f1, f2, f3, occ, tot


def pair_bins(points, normals, i, j, scale, n_bins=(20, 4, 5, 3), grid=64):
    """Bin indices (n_pairs, 4) of the pairs, as the paper's histogram defines them."""
    f1, f2, f3, occ, tot = pair_functions(points, normals, i, j, scale, grid)
    n1, n2, n3, n4 = n_bins
    b4 = np.minimum((n4 * occ) // tot, n4 - 1)  # floor(n4 * f4) on [0, 1], exactly
    # f1 bins by the bin density n1 / F1_MAX (the same real number as n1 (v - 0) / (F1_MAX - 0))
    b1 = np.minimum(np.floor(f1 * (n1 / F1_MAX)).astype(np.int64), n1 - 1)
    return np.stack(
        [b1, bin_index(f2, -np.pi / 2, np.pi / 2, n2),
         bin_index(f3, 0.0, np.pi / 2, n3), b4], axis=1,
    ), occ, tot


def descriptor(points, normals, pairs, scale, n_bins=(20, 4, 5, 3), c=1.2, grid=64):
    """Weighted, normalised EPPF histogram from given pairs."""
    bins, _, _ = pair_bins(points, normals, pairs[:, 0], pairs[:, 1], scale, n_bins, grid)
    hist = np.zeros(n_bins)
    np.add.at(hist, tuple(bins.T), 1.0)
    alpha = np.log(np.arange(n_bins[0]) / n_bins[0] + c)
    hist *= alpha[:, None, None, None]
    return (hist / hist.sum()).ravel()
