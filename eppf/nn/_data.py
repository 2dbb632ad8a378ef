"""Torch datasets: a pool of descriptor draws per object, augmented point clouds."""

import numpy as np
import torch
from torch.utils.data import Dataset

__all__ = ["AugmentedPointClouds", "DescriptorPoolDataset"]


class DescriptorPoolDataset(Dataset):
    """Dataset whose every access picks one of an object's descriptor draws.

    Parameters
    ----------
    X : ndarray of shape (n_objects, n_draws, n_features), float32
        ``n_draws`` descriptors per object (random pairs drawn afresh for
        each). With one draw this is a plain dataset.
    y : ndarray of shape (n_objects,), int64
        Encoded labels.
    random_state : int
        Seed of the generator that picks the draw on every access; as the
        data loader asks for items in a seeded order, a training run stays
        reproducible, and every epoch sees fresh draws.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.nn import DescriptorPoolDataset
    >>> X = np.zeros((3, 2, 4), dtype=np.float32)
    >>> X[:, 1] = 1
    >>> ds = DescriptorPoolDataset(X, np.arange(3), random_state=0)
    >>> len(ds), ds[0][0].shape
    (3, (4,))
    """

    def __init__(self, X, y, random_state=0):
        X = np.asarray(X)
        if X.ndim != 3:
            raise ValueError(f"DescriptorPoolDataset: X must have shape (n_objects, n_draws, n_features), got {X.shape}")
        y = np.asarray(y)
        if y.shape != (X.shape[0],):
            raise ValueError(f"DescriptorPoolDataset: y must have shape ({X.shape[0]},), got {y.shape}")
        self.X = X
        self.y = y
        self.rng = np.random.default_rng(random_state)

    def __len__(self):
        return self.X.shape[0]

    def __getitem__(self, i):
        n_draws = self.X.shape[1]
        k = int(self.rng.integers(n_draws)) if n_draws > 1 else 0
        return self.X[i, k], self.y[i]


class AugmentedPointClouds(Dataset):
    """Point clouds augmented afresh on every access (seeded).

    Every access to an object applies, in this order and each when enabled,
    a random rotation about the z axis, a random uniform scaling in
    [0.8, 1.25] and Gaussian jitter (sigma 0.01, clipped to +-0.05) to its
    points, drawing from one generator seeded by ``random_state``; as the
    data loader asks for items in a seeded order, a training run stays
    reproducible.

    Parameters
    ----------
    X : ndarray of shape (n_objects, n_points, 3)
        Point clouds (converted to float64 for the augmentation, returned as
        float32).
    y : ndarray of shape (n_objects,)
        Encoded labels.
    random_state : int
        Seed of the augmentation generator.
    rotation : {"z", None}, default="z"
        Rotate about z by an angle uniform in [0, 2 pi), or not at all.
    jitter : bool, default=True
        Add clipped Gaussian noise to every coordinate.
    scale : bool, default=True
        Scale every object by a factor uniform in [0.8, 1.25].

    See Also
    --------
    eppf.classifiers.PointNetClassifier : Trains on these augmented clouds.
    DescriptorPoolDataset : The descriptor counterpart (several draws per object).

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.nn import AugmentedPointClouds
    >>> ds = AugmentedPointClouds(np.zeros((2, 5, 3)), np.array([0, 1]), random_state=0)
    >>> len(ds), tuple(ds[1][0].shape), ds[1][1]
    (2, (5, 3), 1)
    """

    def __init__(self, X, y, random_state=0, *, rotation="z", jitter=True, scale=True):
        X = np.asarray(X)
        if X.ndim != 3 or X.shape[2] != 3:
            raise ValueError(f"AugmentedPointClouds: X must have shape (n_objects, n_points, 3), got {X.shape}")
        y = np.asarray(y)
        if y.shape != (X.shape[0],):
            raise ValueError(f"AugmentedPointClouds: y must have shape ({X.shape[0]},), got {y.shape}")
        if rotation not in ("z", None):
            raise ValueError(f"AugmentedPointClouds: rotation must be 'z' or None, got {rotation!r}")
        self.X = X
        self.y = y
        self.rotation = rotation
        self.jitter = bool(jitter)
        self.scale = bool(scale)
        self.rng = np.random.default_rng(random_state)

    def __len__(self):
        return self.X.shape[0]

    def __getitem__(self, i):
        pts = self.X[i].astype(np.float64)
        rng = self.rng
        if self.rotation == "z":
            a = rng.uniform(0.0, 2 * np.pi)
            c, s = np.cos(a), np.sin(a)
            rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            pts = pts @ rot.T
        if self.scale:
            pts = pts * rng.uniform(0.8, 1.25)
        if self.jitter:
            pts = pts + np.clip(0.01 * rng.standard_normal(pts.shape), -0.05, 0.05)
        return torch.from_numpy(pts.astype(np.float32)), int(self.y[i])
