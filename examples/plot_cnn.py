"""
=====================================================
Classifying with the 4D convolutional network
=====================================================

Train the paper's network (:class:`eppf.classifiers.EPPF4DClassifier`, two 4D
convolutions, a 2D convolution and dense layers) on "EPPF short"
descriptors (15 x 3 x 4 x 3 bins) of the built-in shapes, then look at its
learning curve, its confusion matrix on the held-out split and how its
first filters respond to one object, as in the paper's network-response
figure.

The network here is much smaller than the paper's (fewer filters, 256
hidden units, 20 epochs) so that the example runs in seconds on a CPU; the
defaults of :class:`eppf.classifiers.EPPF4DClassifier` are the paper's.
"""

import matplotlib.pyplot as plt

from eppf import EPPF4DClassifier, EPPFTransformer
from eppf.datasets import make_shapes
from eppf.plotting import (
    plot_confusion_matrix,
    plot_descriptor,
    plot_filter_responses,
    plot_learning_curve,
)

N_BINS = (15, 3, 4, 3)  # "EPPF short"

shapes = make_shapes(n_samples_per_class=30, n_points=512, random_state=0)
train = shapes.split == "train"
eppf = EPPFTransformer(n_bins=N_BINS, n_pairs=5000, random_state=0)
X = eppf.fit_transform(shapes.data)
X_train, y_train = X[train], shapes.target[train]
X_test, y_test = X[~train], shapes.target[~train]
print(f"{len(X_train)} training and {len(X_test)} test objects, {X.shape[1]} bins each")

# %%
# Training
# --------
# Early stopping holds out 10% of the training objects (never the test
# split) and keeps the weights of the epoch with the lowest validation loss.
# ``n_jobs=1`` keeps torch to one thread, the fastest setting for a network
# this small.

clf = EPPF4DClassifier(
    n_bins=N_BINS,
    filters=(8, 16, 16),
    n_hidden=256,
    lr=2e-3,
    max_epochs=20,
    n_iter_no_change=5,
    n_jobs=1,
    random_state=0,
)
clf.fit(X_train, y_train)
print(f"trained {clf.n_epochs_} epochs, kept epoch {clf.best_epoch_}")
print(f"test accuracy: {clf.score(X_test, y_test):.3f}")

ax = plot_learning_curve(clf)
ax.set_title("EPPF4DClassifier on the built-in shapes")
plt.show()

# %%
# Confusion matrix on the test split
# ----------------------------------
# Rows are the true classes, normalised so that the diagonal is each class's
# recall.

ax = plot_confusion_matrix(y_test, clf.predict(X_test), display_labels=shapes.target_names)
ax.figure.set_size_inches(7, 6)
plt.show()

# %%
# Descriptor and filter responses
# -------------------------------
# The descriptor of one test chair as slices of its 4D histogram (rows: f4
# bins, columns: f3 bins, each panel f1 x f2) ...

chair = int(list(shapes.target_names).index("chair"))
index = int(((y_test == chair)).nonzero()[0][0])
plot_descriptor(X_test[index], N_BINS, title="EPPF descriptor of a chair")
plt.show()

# %%
# ... and the responses of the first filters of both 4D convolutions to it,
# each 4D response shown by its maximum over the f3 and f4 bins. The first
# layer spreads the sparse histogram over neighbouring distance bins; the
# second mixes the first layer's channels.

plot_filter_responses(clf, X_test[index], n_filters=6)
plt.show()
