"""The one progress bar of eppf: a tqdm bar on standard error, or nothing.

Every command and estimator that shows progress (a descriptor's ``verbose``,
the command line's reading and describing bars) goes through
:func:`progress_bar`, so bars look alike everywhere and disappear when done.
"""

import sys

__all__ = ["progress_bar"]


class _Silent:
    """What :func:`progress_bar` gives when progress is off: the same calls, doing nothing."""

    def __init__(self, iterable):
        self.iterable = iterable

    def __iter__(self):
        return iter(self.iterable)

    def update(self, n=1):
        pass

    def close(self):
        pass


def progress_bar(iterable=None, *, total=None, desc="", unit="it", enabled=True):
    """A progress bar over ``iterable`` (or ``total`` steps), or a silent stand-in.

    Parameters
    ----------
    iterable : iterable, default=None
        Items to iterate over while the bar advances; None for a bar advanced
        by :meth:`update`.
    total : int, default=None
        Steps of a bar without ``iterable`` (or when ``len(iterable)`` is not
        known).
    desc : str, default=""
        The bar's label.
    unit : str, default="it"
        What one step is (``"file"``, ``"obj"``).
    enabled : bool, default=True
        False (or tqdm not installed) gives an object with the same
        ``__iter__``, ``update`` and ``close`` that shows nothing.

    Returns
    -------
    bar : tqdm bar or stand-in
        Iterate over it, or call ``update(n)`` and ``close()``. The bar is
        written to standard error and erased when closed.

    See Also
    --------
    transform_in_chunks : Shows this bar over objects with ``verbose``.

    Examples
    --------
    >>> from eppf.utils import progress_bar
    >>> bar = progress_bar(total=3, desc="files", enabled=False)
    >>> bar.update(3); bar.close()
    >>> list(progress_bar(range(3), enabled=False))
    [0, 1, 2]
    """
    if enabled:
        try:
            from tqdm.auto import tqdm
        except ImportError:  # pragma: no cover - tqdm is a dependency
            pass
        else:
            return tqdm(iterable, total=total, desc=desc, unit=unit, file=sys.stderr, leave=False)
    return _Silent(() if iterable is None else iterable)
