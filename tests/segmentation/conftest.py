"""Analytic scenes for the segmentation tests: spheres and boxes on planes and slopes."""

import numpy as np
import pytest


def sphere(center, radius, n, rng):
    """``n`` points on a sphere's surface."""
    d = rng.normal(size=(n, 3))
    return np.asarray(center) + radius * d / np.linalg.norm(d, axis=1)[:, None]


def floor(extent, n, rng, noise=0.0, height=None):
    """``n`` points on the square [0, extent]^2 at z = height(x, y) (0 when None), plus normal noise in z."""
    xy = rng.uniform(0, extent, size=(n, 2))
    z = np.zeros(n) if height is None else height(xy[:, 0], xy[:, 1])
    return np.column_stack([xy, z + rng.normal(0, noise, n) if noise else z])


@pytest.fixture
def spheres_on_plane():
    """(points, truth): 5 spheres of 600 points, radius 0.5, 3 m apart, resting 0.1 m above a noisy floor
    of 20,000 points (truth -1), in projected coordinates (offset 5e5, 4.5e6, 100)."""
    rng = np.random.default_rng(0)
    ground = floor(14.0, 20000, rng, noise=0.005)
    balls = [sphere((1.5 + 3 * k, 7.0, 0.6), 0.5, 600, rng) for k in range(5)]
    points = np.vstack([ground] + balls) + np.array([5e5, 4.5e6, 100.0])
    truth = np.repeat(np.arange(-1, 5), [len(ground)] + [600] * 5)
    return points, truth
