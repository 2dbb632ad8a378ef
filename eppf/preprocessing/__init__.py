"""Preprocessing of point clouds: normals, sampling, perturbations.

Each transformer maps a list of point clouds (arrays of shape (n_i, 3) or
(n_i, 6), normals last) to a new list, so it can stand in a
:class:`~sklearn.pipeline.Pipeline` before a descriptor transformer, or be
applied once to a data set (``GaussianNoise(0.02).fit_transform(data.data)``).
``fit`` learns nothing; the transformers work unfitted too.

Randomness: one seed per object is drawn from ``random_state``
(:func:`eppf.utils.object_seeds`), and object ``k`` is perturbed with its
own generator. A fixed integer ``random_state`` therefore gives the same
output on every call and for any split of the data into chunks; a
``RandomState`` instance gives fresh draws on each call (augmentation).

The work on one cloud is done by private functions beside the transformers;
:func:`sample_mesh` turns meshes (see :func:`eppf.io.read_mesh`) into clouds, and
:func:`estimate_normals` gives clouds PCA normals (the descriptors call it
themselves when a cloud has none).
"""

from ._normals import estimate_normals
from ..utils._sampling import sample_mesh
from ._transformers import GaussianNoise, Occlusion, RandomDropout, RandomRotation, RandomScaling, Resampler

__all__ = [
    "GaussianNoise",
    "Occlusion",
    "RandomDropout",
    "RandomRotation",
    "RandomScaling",
    "Resampler",
    "estimate_normals",
    "sample_mesh",
]
