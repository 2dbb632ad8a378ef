"""
=====================================================
Classify the objects in a scan
=====================================================

A scan holds a scene, not one object per file: a LiDAR tile, a room. This
example goes from such a scan to classified objects, PCL's
cluster-recognition recipe: remove the ground, cluster the rest into
objects (:mod:`eppf.segmentation`), describe each object and classify it.

To stay self-contained it first makes a scan: eight built-in shapes of
classes the model was trained on, but new objects, standing upright 3 m
apart on a noisy ground plane, in projected (UTM-like) coordinates, written
as a LAS file with :func:`eppf.io.write_point_fields` (LAS needs the ``las``
extra: ``pip install "eppf[las]"``). With a scan of your own, start at
"Read and segment".
"""

import os
import tempfile

import matplotlib.pyplot as plt
import numpy as np
from sklearn.pipeline import Pipeline

from eppf import EPPFTransformer, KLNearestNeighbors
from eppf.datasets import make_shapes
from eppf.io import read_point_fields, write_point_fields
from eppf.segmentation import SceneSegmenter

# %%
# A model
# -------
# EPPF descriptors matched by symmetric KL divergence to the closest of the
# training objects: the built-in shapes, in their own units (meters here).

train = make_shapes(n_samples_per_class=8, n_points=1024, random_state=0)
model = Pipeline([("eppf", EPPFTransformer(n_pairs=5000, random_state=0)), ("match", KLNearestNeighbors())])
model.fit(train.data, train.target_names[train.target])

# %%
# A scan to classify
# ------------------
# One new object of each of eight classes (another seed: none was seen in
# training), turned about the vertical only, as objects stand in a scan.

rng = np.random.default_rng(1)
origin = np.array([512000.0, 5403000.0, 250.0])  # easting, northing, height in meters
new = make_shapes(n_samples_per_class=1, n_points=1000, rotate="z", random_state=1)
parts, truth = [], []
for k in range(8):
    cloud = new.data[k].copy()
    x, y = (k % 4) * 3.0, (k // 4) * 3.0
    cloud[:, :2] += [x, y] - cloud[:, :2].mean(axis=0)
    cloud[:, 2] -= cloud[:, 2].min()  # on the ground
    parts.append(cloud)
    truth.append((x, y, new.target_names[new.target[k]]))
ground = np.column_stack([rng.uniform([-1.5, -1.5], [10.5, 4.5], size=(7200, 2)), rng.normal(0, 0.01, 7200)])
scan = np.vstack(parts + [ground]) + origin
folder = tempfile.mkdtemp(prefix="eppf_scan_")
path = os.path.join(folder, "tile.las")
write_point_fields(path, scan, {"intensity": rng.integers(0, 4000, len(scan)).astype(np.uint16)})

# %%
# Read and segment
# ----------------
# :func:`eppf.io.read_point_fields` gives the coordinates as float64 in the
# file's own units and offsets, and every other per-point field (here
# LAS's ``intensity``, ``classification``, ...) as named arrays.
# :class:`~eppf.segmentation.SceneSegmenter` removes the ground and clusters
# the other points; the clustering distance, unless given, comes from the
# point spacing, so the defaults suit LiDAR in meters and CAD-scale scenes.

points, fields = read_point_fields(path)
print(f"{len(points)} points, fields: {', '.join(fields)}")
segmenter = SceneSegmenter().fit(points)
labels = segmenter.labels_
print(f"{segmenter.n_segments_} segments, {segmenter.ground_mask_.sum()} ground points, "
      f"tolerance {segmenter.tolerance_:.3f} m")

# %%
# Classify every segment
# ----------------------
# Each segment is one point cloud, in the file's coordinates (the EPPF
# descriptor does not depend on where an object stands).

segments = [points[labels == k] for k in range(segmenter.n_segments_)]
predicted = model.predict(segments)
print(f"{'segment':>7} {'points':>6} {'easting':>12} {'northing':>12}  {'true':<9} predicted")
n_right = 0
for k, (cloud, label) in enumerate(zip(segments, predicted)):
    cx, cy, _ = cloud.mean(axis=0)
    nearest = min(truth, key=lambda t: np.hypot(t[0] + origin[0] - cx, t[1] + origin[1] - cy))
    n_right += nearest[2] == label
    print(f"{k:>7} {len(cloud):>6} {cx:>12.2f} {cy:>12.2f}  {nearest[2]:<9} {label}")
print(f"{n_right} of {len(truth)} objects classified right")

# %%
# The labeled scan
# ----------------
# Every point keeps its fields and gets two more, its ``segment`` (-1:
# ground) and its class, which any LAS viewer can color by.

class_names = list(model.classes_)
point_class = np.full(len(points), -1, dtype=np.int32)
for k, label in enumerate(predicted):
    point_class[labels == k] = class_names.index(label)
write_point_fields(os.path.join(folder, "labelled.las"), points,
                   dict(fields, segment=labels.astype(np.int32), **{"class": point_class}))

fig, ax = plt.subplots(figsize=(8, 4.2))
local = points - origin
ax.scatter(*local[labels < 0, :2].T, s=0.5, c="0.8")
colors = [c for i, c in enumerate(plt.get_cmap("tab10").colors) if i != 7] + ["black"]  # no gray: ground's
for k, label in enumerate(predicted):
    mine = local[labels == k]
    ax.scatter(*mine[:, :2].T, s=2, color=colors[class_names.index(label)])
    ax.annotate(label, mine[:, :2].mean(axis=0) + [0, 0.9], ha="center", fontsize=9)
ax.set_aspect("equal")
ax.set_xlabel(f"easting - {origin[0]:.0f} (m)")
ax.set_ylabel(f"northing - {origin[1]:.0f} (m)")
ax.set_title("the scan from above: ground in gray, objects by predicted class")
plt.show()

# %%
# The same from the command line
# ------------------------------
# ``eppf segment`` writes one file per object (every field kept, the scan's
# format) and an index of them; ``eppf predict --segment`` classifies every
# object of a scan with a model trained by ``eppf train`` (here on a folder
# with one subfolder of LAS or other files per class):
#
# .. code-block:: bash
#
#    eppf segment tile.las -o objects/              # objects/segment_000.las ... and objects/segments.csv
#    eppf train --data my_objects/ -o model.eppf
#    eppf predict --model model.eppf tile.las --segment -o labels.csv --labelled-output labelled.las
#
# ``labels.csv`` has one row per object: ``segment``, ``n_points``, the
# centroid ``x``, ``y``, ``z`` in the scan's coordinates, ``class`` and the
# model's evidence; ``--tolerance``, ``--ground``, ``--min-points`` and
# ``--by FIELD`` (segments from a field such as ``instance``) set the
# segmentation (see :doc:`/cli`).

for name in os.listdir(folder):
    os.remove(os.path.join(folder, name))
os.rmdir(folder)
