"""The paper's experiments as reproducible commands.

Each experiment takes a data set (the built-in synthetic shapes or a ``.npz``
file in the layout of :func:`eppf.datasets.load_npz`) and writes a Markdown
report (table, exact command, protocol, machine), a CSV table and a PNG plot
into an output folder. Run them as ``eppf experiment NAME [options]``
or call the functions:

- :func:`run_retrieval`: Table II, leave-one-out KL 1-NN retrieval of
  OUR-CVFH, ESF, Wahl, EPPF short and EPPF;
- :func:`run_classification`: Table III, PointNet and the EPPF 2D, 3D and 4D
  networks trained on the training split, scored on the test split;
- :func:`run_ablation`: EPPF retrieval with each point-pair function removed;
- :func:`run_noise`: accuracy against Gaussian noise, retraining per level;
- :func:`run_runtime`: milliseconds per object of every descriptor and of
  normal estimation.

:data:`PRESETS` names the paper's ModelNet40 protocol (clean, Gaussian noise
of σ 0.07, 0.10 and 0.15, occluded): :func:`apply_preset` applies one to a
data set, and ``--preset`` of the classification and noise commands does the
same.

Descriptors are cached on disk (``--cache-dir``), so a rerun skips them.
"""

from ._ablation import run_ablation
from ._classification import TrainingOptions, run_classification
from ._common import Dataset, ExperimentError, ExperimentSettings, load_data
from ._noise import run_noise
from ._presets import PRESETS, Preset, apply_preset, get_preset
from ._retrieval import run_retrieval
from ._runtime import run_runtime

__all__ = [
    "Dataset",
    "ExperimentError",
    "ExperimentSettings",
    "PRESETS",
    "Preset",
    "TrainingOptions",
    "apply_preset",
    "get_preset",
    "load_data",
    "run_ablation",
    "run_classification",
    "run_noise",
    "run_retrieval",
    "run_runtime",
]
