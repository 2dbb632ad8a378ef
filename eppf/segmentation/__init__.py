"""Scenes into objects: ground removal, Euclidean clustering, segments from a field.

The layer between files (:mod:`eppf.io`) and descriptors: a scan of a scene is
split into the point clouds of its objects, which the descriptors then
describe one by one (PCL's cluster-recognition recipe).

- :func:`remove_ground` finds the ground: a RANSAC plane, or for terrain that
  is not one plane, a slope-limited lowest surface on a grid;
- :func:`euclidean_clusters` connects points closer than a tolerance, with the
  semantics of PCL's ``EuclideanClusterExtraction`` (minimum and maximum
  cluster sizes);
- :func:`split_by_field` takes segments from an integer field (``instance``,
  ``label``, ``classification``);
- :func:`segment_scene` and :class:`SceneSegmenter` do the whole: ground, then
  clusters or a field's segments.

Labels are int64, one per point, -1 for ground and points in no segment;
segments are numbered 0, 1, ... the same way on every run. The tolerance,
unless given, is derived from the point spacing, so the defaults work on
LiDAR in meters and on CAD-scale scenes alike.
"""

from ._cluster import euclidean_clusters, split_by_field
from ._ground import remove_ground
from ._scene import SceneSegmenter, segment_scene

__all__ = ["SceneSegmenter", "euclidean_clusters", "remove_ground", "segment_scene", "split_by_field"]
