"""
=================================================
Tuning the descriptor with GridSearchCV
=================================================

:class:`eppf.descriptors.EPPFTransformer` is an ordinary scikit-learn transformer, so its
parameters, including the readings of the paper such as the bin counts
``n_bins`` and the distance-weighting constant ``c``, can be searched with
``GridSearchCV`` like any other hyper-parameter.
"""

import matplotlib.pyplot as plt
import numpy as np
from sklearn.model_selection import GridSearchCV, StratifiedKFold
from sklearn.pipeline import Pipeline

from eppf import EPPFTransformer, KLNearestNeighbors
from eppf.datasets import make_shapes

shapes = make_shapes(n_samples_per_class=6, n_points=512, random_state=0)
pipe = Pipeline([
    ("eppf", EPPFTransformer(n_pairs=3000, random_state=0)),
    ("knn", KLNearestNeighbors()),
])
param_grid = {
    "eppf__n_bins": [(20, 4, 5, 3), (15, 3, 4, 3)],  # full and "EPPF short"
    "eppf__c": [1.05, 1.2, 2.0],
}
cv = StratifiedKFold(n_splits=3, shuffle=True, random_state=0)
grid = GridSearchCV(pipe, param_grid, cv=cv).fit(shapes.data, shapes.target)
print("best parameters:", grid.best_params_)
print(f"best cross-validated accuracy: {grid.best_score_:.3f}")

# %%
# Mean cross-validated accuracy for every combination.

n_bins_values, c_values = param_grid["eppf__n_bins"], param_grid["eppf__c"]
scores = np.empty((len(n_bins_values), len(c_values)))
for params, score in zip(grid.cv_results_["params"], grid.cv_results_["mean_test_score"]):
    scores[n_bins_values.index(params["eppf__n_bins"]), c_values.index(params["eppf__c"])] = score

fig, ax = plt.subplots(figsize=(5, 2.5))
image = ax.imshow(scores, cmap="viridis")
ax.set_xticks(np.arange(len(c_values)), labels=c_values)
ax.set_yticks(np.arange(len(n_bins_values)), labels=[str(b) for b in n_bins_values])
ax.set_xlabel("c")
ax.set_ylabel("n_bins")
for (i, j), value in np.ndenumerate(scores):
    ax.text(j, i, f"{value:.2f}", ha="center", va="center", color="w")
fig.colorbar(image, ax=ax, label="accuracy")
fig.tight_layout()
plt.show()
