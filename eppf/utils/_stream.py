"""Bounded, ordered work ahead of a consumer: the pipeline under :func:`eppf.describe_files`.

:func:`ordered_map` runs a function over a sequence of items on a few threads
and yields the results in the items' order, with at most ``depth`` results
computed ahead of the consumer. The consumer (say, a descriptor kernel that
releases the GIL) works on result ``k`` while the threads produce ``k + 1``,
``k + 2``...; memory holds at most ``depth + 1`` results whatever the number
of items. When the consumer stops early (an exception, Ctrl-C, ``close()``)
the items not started are canceled and the running ones are waited for, so
no thread outlives the call.

:class:`RowWriter` appends float64 rows to an open binary file as a ``.npy``
array whose row count is known only at the end: a header of fixed length is
written first and rewritten with the final shape when the rows are done, so
the rows go to disk as they come and never sit in memory together.
"""

import collections
import struct
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["RowWriter", "ordered_map"]


def ordered_map(func, items, *, workers=1, depth=2):
    """Yield ``func(item)`` for every item, in order, computing ahead on threads.

    The one ordered thread map of eppf: the readers and describers of
    :func:`eppf.describe_files`, and the blocks of distances of the
    neighbor searches (:func:`eppf.utils._blas.map_blocks`).

    Parameters
    ----------
    func : callable
        Called once per item, on a worker thread.
    items : iterable
        The inputs, consumed lazily.
    workers : int, default=1
        Threads running ``func``.
    depth : int, default=2
        Results computed (or being computed) ahead of the consumer; at least
        ``workers``.

    Yields
    ------
    result : object
        ``func(item)``, in the order of ``items``. An exception raised by
        ``func`` is raised here, at that item's turn.

    See Also
    --------
    transform_in_chunks : Descriptor rows chunk by chunk through joblib.

    Examples
    --------
    >>> from eppf.utils import ordered_map
    >>> list(ordered_map(lambda x: x * x, range(5), workers=2, depth=3))
    [0, 1, 4, 9, 16]
    """
    workers = max(1, int(workers))
    depth = max(workers, int(depth))
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="eppf-stream")
    pending = collections.deque()
    try:
        for item in items:
            pending.append(pool.submit(func, item))
            if len(pending) >= depth:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
    finally:
        for future in pending:
            future.cancel()
        pool.shutdown(wait=True, cancel_futures=True)


#: Bytes of the ``.npy`` header :class:`RowWriter` writes (magic, version, length, dict, padding).
HEADER_BYTES = 128


def _npy_header(n_rows, n_cols):
    text = "{'descr': '<f8', 'fortran_order': False, 'shape': (%d, %d), }" % (n_rows, n_cols)
    pad = HEADER_BYTES - 10 - len(text) - 1
    if pad < 0:  # pragma: no cover - shapes beyond 10**40 rows
        raise ValueError(f"a shape of ({n_rows}, {n_cols}) does not fit a {HEADER_BYTES}-byte .npy header")
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", HEADER_BYTES - 10) + (text + " " * pad + "\n").encode("latin1")


class RowWriter:
    """Append float64 rows to a binary file as one ``.npy`` array.

    Parameters
    ----------
    fh : binary file object
        Open for writing at offset 0 (for instance the temporary file of
        :func:`eppf.utils._atomic.atomic_write`), seekable.
    n_cols : int
        Columns of every row.

    Notes
    -----
    The header has a fixed length (:data:`HEADER_BYTES`, a multiple of 64 as
    the format asks), so that :meth:`close` can rewrite it in place with the
    final row count; the rows are written little-endian in C order, as
    :func:`numpy.save` writes them.

    Examples
    --------
    >>> import io, numpy as np
    >>> from eppf.utils._stream import RowWriter
    >>> buf = io.BytesIO()
    >>> w = RowWriter(buf, 2)
    >>> w.write(np.ones((3, 2)))
    >>> w.write(np.zeros((1, 2)))
    >>> w.close()
    >>> _ = buf.seek(0)
    >>> np.load(buf).tolist()
    [[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [0.0, 0.0]]
    """

    def __init__(self, fh, n_cols):
        self.fh, self.n_cols, self.n_rows = fh, int(n_cols), 0
        self.fh.write(_npy_header(0, self.n_cols))

    def write(self, rows):
        """Append ``rows`` of shape (k, n_cols)."""
        rows = np.ascontiguousarray(rows, dtype="<f8")
        if rows.ndim != 2 or rows.shape[1] != self.n_cols:
            raise ValueError(f"RowWriter: rows must have shape (k, {self.n_cols}), got {rows.shape}")
        self.fh.write(rows.tobytes())
        self.n_rows += rows.shape[0]

    def close(self):
        """Rewrite the header with the final row count and leave the file at its end."""
        end = self.fh.tell()
        self.fh.seek(0)
        self.fh.write(_npy_header(self.n_rows, self.n_cols))
        self.fh.seek(end)

