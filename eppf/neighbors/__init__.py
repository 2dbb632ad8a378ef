"""Retrieval and 1-NN classification of descriptors by symmetric Kullback-Leibler divergence."""

from ._ann import ApproximateKLNearestNeighbors
from ._kl import KLNearestNeighbors, symmetric_kl_distances

__all__ = ["ApproximateKLNearestNeighbors", "KLNearestNeighbors", "symmetric_kl_distances"]
