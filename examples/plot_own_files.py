"""
=====================================================
Classifying your own point cloud files
=====================================================

How to use eppf on clouds stored in files: train a classifier on the
built-in shapes, then read PLY and PCD files with
:func:`eppf.io.read_point_cloud` and classify them; then a labeled folder
with :func:`eppf.datasets.load_folder`, and the same from the command
line. To keep the example self-contained we first write some new built-in
objects to a temporary folder with :func:`eppf.io.write_point_cloud`;
replace that folder with yours. Every format of
:func:`eppf.io.supported_extensions` is read the same way: point files
(PCD, PLY, LAS and LAZ with the ``las`` extra, E57 with the ``e57`` extra,
XYZ/TXT/CSV/PTS text tables, NPY, NPZ) and meshes (OFF, OBJ, STL, PLY with
faces), which are sampled. For a scan of a whole scene rather than one
object per file, see :ref:`sphx_glr_auto_examples_plot_classify_scan.py`.
"""

import shutil
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from sklearn.pipeline import Pipeline

from eppf import EPPFTransformer, KLNearestNeighbors
from eppf.datasets import load_folder, make_shapes
from eppf.io import read_point_cloud, write_point_cloud

# %%
# A model trained on the built-in shapes: EPPF descriptors matched by
# symmetric KL divergence to the closest training object.

train = make_shapes(n_samples_per_class=20, n_points=1024, random_state=0)
model = Pipeline(
    [
        ("eppf", EPPFTransformer(n_pairs=10000, random_state=0)),
        ("match", KLNearestNeighbors()),
    ]
)
model.fit(train.data, train.target_names[train.target])

# %%
# Write files
# -----------
# New objects (another random seed, so none of them was seen in training),
# alternately as binary PLY and binary PCD. Both store float32 coordinates.

folder = Path(tempfile.mkdtemp(prefix="eppf_example_"))
new = make_shapes(n_samples_per_class=1, n_points=1024, random_state=1)
for k, (cloud, label) in enumerate(zip(new.data, new.target)):
    suffix = ".ply" if k % 2 == 0 else ".pcd"
    write_point_cloud(folder / f"object_{k:02d}{suffix}", cloud)
truth = {f"object_{k:02d}": new.target_names[label] for k, label in enumerate(new.target)}

# %%
# Read and classify
# -----------------
# Every file in the folder becomes an (n_points, 3) array (or (n_points, 6)
# when the file holds normals); the pipeline takes the list of them.

paths = sorted(p for p in folder.iterdir() if p.suffix in (".ply", ".pcd"))
clouds = [read_point_cloud(p) for p in paths]
predicted = model.predict(clouds)

print(f"{'file':<16} {'points':>6}  {'true':<9} predicted")
for path, cloud, label in zip(paths, clouds, predicted):
    print(f"{path.name:<16} {len(cloud):>6}  {truth[path.stem]:<9} {label}")
print(f"correct: {np.mean([truth[p.stem] == y for p, y in zip(paths, predicted)]):.0%}")

# %%
# One of the clouds as read back from its file.

cloud, name, label = clouds[-1], paths[-1].name, predicted[-1]
fig = plt.figure(figsize=(5, 5))
ax = fig.add_subplot(projection="3d")
ax.scatter(cloud[:, 0], cloud[:, 1], cloud[:, 2], s=2, c=cloud[:, 2], cmap="viridis")
ax.set_title(f"{name}: predicted {label}")
ax.set_xlabel("x")
ax.set_ylabel("y")
ax.set_zlabel("z")
ax.set_box_aspect(np.ptp(cloud[:, :3], axis=0))
plt.show()

# %%
# A labeled folder
# ----------------
# Training data from files: one subfolder per class (optionally inside
# ``train/`` and ``test/``). :func:`eppf.datasets.load_folder` reads it with
# labels, sampling meshes with one seed per file, as the command line does.

labelled = folder / "labelled"
for k, (cloud, label) in enumerate(zip(new.data, new.target)):
    (labelled / new.target_names[label]).mkdir(parents=True, exist_ok=True)
    write_point_cloud(labelled / new.target_names[label] / f"{k:02d}.ply", cloud)
data = load_folder(labelled)
print(f"{len(data.data)} objects of {len(data.target_names)} classes: {', '.join(data.target_names)}")
print(f"the model on them: {np.mean(model.predict(data.data) == data.target_names[data.target]):.0%} right")

# %%
# The command line
# ----------------
# The same without Python: ``eppf train`` fits and saves a model (from a
# labeled folder with ``--data``; here from the built-in shapes), ``eppf
# predict`` classifies files and folders with it, ``eppf evaluate`` scores
# it on a labeled folder. Here they run through :func:`eppf.cli.main`,
# which is what the ``eppf`` command runs.
#
# .. code-block:: bash
#
#    eppf train --data my_objects/ -o model.eppf     # or --built-in
#    eppf predict --model model.eppf new_files/ -o labels.csv
#    eppf evaluate --data labelled/ --model model.eppf --no-retrieval

from eppf.cli import main  # noqa: E402

model_file = str(folder / "model.eppf")
main(["train", "--built-in", "-o", model_file, "--test-size", "0", "--n-pairs", "10000", "--no-progress"])
main(["predict", "--model", model_file, *map(str, paths[:4]), "--no-progress"])
main(["evaluate", "--data", str(labelled), "--model", model_file, "--no-retrieval", "--no-progress"])

# %%
# Remove the temporary folder.

shutil.rmtree(folder)
