"""Retrieval and 1-NN classification of descriptors by symmetric Kullback-Leibler divergence."""

from ._kl import KLNearestNeighbors, symmetric_kl_distances

__all__ = ["KLNearestNeighbors", "symmetric_kl_distances"]
