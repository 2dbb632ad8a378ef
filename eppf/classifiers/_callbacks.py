"""skorch callbacks of the eppf classifiers: a wall-clock budget and a one-line epoch log.

Imported when a fit starts (not by ``import eppf``, which stays free of
torch and skorch).
"""

import time

from skorch.callbacks import Callback

__all__ = ["EpochLog", "TimeBudget"]


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
        return self

    def on_train_begin(self, net, X=None, y=None, **kwargs):
        self.start_ = time.monotonic()

    def on_epoch_end(self, net, dataset_train=None, dataset_valid=None, **kwargs):
        if time.monotonic() - self.start_ > self.seconds:
            self.sink(f"Stopping: time budget of {self.seconds:g} s used after {len(net.history)} epochs.")
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
