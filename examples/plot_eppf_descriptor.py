"""
=======================================
The EPPF descriptor as a 4D histogram
=======================================

Compute EPPF descriptors of two built-in shapes and look at them as 4D
histograms: for each object, the f1 (distance) x f2 (angle) plane of the
histogram, summed over f3 (normal angle) and f4 (occupancy). Different shapes
fill different regions of the plane, which is what the matching and the CNN
use.
"""

import matplotlib.pyplot as plt
import numpy as np

from eppf import EPPFTransformer
from eppf.datasets import make_shapes

shapes = make_shapes(n_samples_per_class=1, classes=["sphere", "chair"], random_state=0)
eppf = EPPFTransformer(n_pairs=5000, random_state=0)
X = eppf.fit_transform(shapes.data)
print("descriptor length:", X.shape[1], "- sums:", np.round(X.sum(axis=1), 6))

# %%
# ``to_histogram`` reshapes flat descriptors to ``histogram_shape_``, here
# (20, 4, 5, 3) over (f1, f2, f3, f4). Sum out f3 and f4 to get a 2D picture.

H = eppf.to_histogram(X)
fig, axes = plt.subplots(1, len(H), figsize=(8, 3), sharey=True)
for ax, h, label in zip(axes, H, shapes.target):
    ax.imshow(h.sum(axis=(2, 3)).T, origin="lower", aspect="auto", cmap="viridis")
    ax.set_title(shapes.target_names[label])
    ax.set_xlabel("f1 bin (distance)")
axes[0].set_ylabel("f2 bin (angle)")
fig.tight_layout()
plt.show()
