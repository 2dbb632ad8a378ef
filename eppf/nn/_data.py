"""Torch dataset over a pool of descriptor draws per object."""

import numpy as np
from torch.utils.data import Dataset

__all__ = ["DescriptorPoolDataset"]


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
