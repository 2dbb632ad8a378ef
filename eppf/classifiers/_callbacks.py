"""skorch callbacks of the eppf classifiers: a wall-clock budget, a one-line epoch log, weight averaging.

Imported when a fit starts (not by ``import eppf``, which stays free of
torch and skorch).
"""

import collections
import time

from skorch.callbacks import Callback

__all__ = ["EpochLog", "TimeBudget", "WeightAveraging"]


class TimeBudget(Callback):
    """Ends training after the first epoch that finishes past a deadline.

    Stops the way skorch's own ``EarlyStopping`` does: ``on_epoch_end``
    raises ``KeyboardInterrupt``, which ``NeuralNet.partial_fit`` catches
    before it runs every callback's ``on_train_end`` (so ``EarlyStopping``
    still loads the best epoch's weights). Callbacks after this one do not
    see the last epoch's ``on_epoch_end``.

    Parameters
    ----------
    seconds : float
        Budget in seconds, counted from ``on_train_begin``.
    sink : callable
        Receives the stopping message (a no-op when quiet).
    """

    def __init__(self, seconds, sink):
        self.seconds = seconds
        self.sink = sink

    def initialize(self):
        self.start_ = None
        self.stopped_ = False
        return self

    def on_train_begin(self, net, X=None, y=None, **kwargs):
        self.start_ = time.monotonic()

    def on_epoch_end(self, net, dataset_train=None, dataset_valid=None, **kwargs):
        if time.monotonic() - self.start_ > self.seconds:
            self.sink(f"Stopping: time budget of {self.seconds:g} s used after {len(net.history)} epochs.")
            self.stopped_ = True  # (a Ctrl-C the net swallows is told apart by this)
            raise KeyboardInterrupt


class EpochLog(Callback):
    """Writes one line per epoch: epoch, training loss, validation loss and accuracy, seconds.

    Reads the row skorch's default callbacks have just written to
    ``net.history``, so it must come before any callback that may stop
    training in ``on_epoch_end`` (then the last epoch is logged too).

    Parameters
    ----------
    sink : callable
        Receives each line.
    max_epochs : int
        Printed after the epoch number.
    """

    def __init__(self, sink, max_epochs):
        self.sink = sink
        self.max_epochs = max_epochs

    def on_epoch_end(self, net, dataset_train=None, dataset_valid=None, **kwargs):
        row = net.history[-1]
        width = len(str(self.max_epochs))
        parts = [f"epoch {row['epoch']:>{width}}/{self.max_epochs}", f"train_loss {row['train_loss']:.4f}"]
        if "valid_loss" in row:
            parts.append(f"valid_loss {row['valid_loss']:.4f}")
        if "valid_acc" in row:
            parts.append(f"valid_acc {row['valid_acc']:.4f}")
        parts.append(f"{row['dur']:.2f} s")
        self.sink("  ".join(parts))


class WeightAveraging(Callback):
    """Keeps the weights of the last ``n_epochs`` epochs; :meth:`apply` loads their average.

    Stochastic weight averaging (Izmailov et al., 2018) of the epochs that
    end training: one network whose weights are the mean of several
    snapshots along the trajectory, which generalizes about as well as an
    ensemble of those snapshots at the cost of one network. The snapshots
    are taken in ``on_epoch_end``, so the callback must come before any
    callback that may stop training there (early stopping, the time
    budget), or it would miss the last epoch. The average replaces the
    weights only when the classifier calls :meth:`apply` after ``fit``
    (after early stopping has loaded the best epoch's, which it overrides).

    The sum runs over the snapshots in epoch order on the weights' own
    device and dtype, so the result is reproducible. Buffers that are not
    floating point (counters) are taken from the last snapshot.

    Parameters
    ----------
    n_epochs : int
        Snapshots kept (the last ones).
    sink : callable
        Receives a line saying which epochs were averaged.
    """

    def __init__(self, n_epochs, sink):
        self.n_epochs = n_epochs
        self.sink = sink

    def initialize(self):
        self.snapshots_ = collections.deque(maxlen=int(self.n_epochs))
        self.epochs_ = collections.deque(maxlen=int(self.n_epochs))
        return self

    def on_epoch_end(self, net, dataset_train=None, dataset_valid=None, **kwargs):
        self.snapshots_.append({k: v.detach().clone() for k, v in net.module_.state_dict().items()})
        self.epochs_.append(len(net.history))

    def apply(self, net):
        """Load the average of the kept snapshots into ``net.module_``; returns the epochs averaged."""
        if not self.snapshots_:
            return []
        snaps = list(self.snapshots_)
        average = {}
        for key, last in snaps[-1].items():
            if not last.is_floating_point():
                average[key] = last
                continue
            total = snaps[0][key].clone()
            for snap in snaps[1:]:
                total += snap[key]
            average[key] = total / len(snaps)
        net.module_.load_state_dict(average)
        epochs = list(self.epochs_)
        self.sink(f"weights averaged over epochs {epochs[0]} to {epochs[-1]}")
        self.snapshots_.clear()  # not pickled with the model
        return epochs
