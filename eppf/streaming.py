"""Descriptors of many files in bounded memory: :func:`describe_files`.

Files are read in chunks on reader threads (:func:`eppf.utils.ordered_map`)
while the descriptor, whose compiled kernels release the GIL, describes the
chunk before; rows go to the output as they come
(:class:`eppf.utils._stream.RowWriter`), so memory holds a few chunks whatever the
number of files. The rows are bit for bit those of ``fit_transform`` on all
the clouds, through hooks the descriptors expose:

- a descriptor that learns from the data set (``scaling="fit"``, EPPF's
  default: one over the largest bounding-box side of any object) says so
  (``_learns_from_data``) and is fitted chunk by chunk with ``partial_fit``
  in a first pass that reads every file; the second pass describes them. A
  cloud that took longer to read than to write (a sampled mesh, a text file)
  is spilled, as read, to an unnamed temporary file in the first pass and
  taken from there; the others (binary point files) are read again, on the
  reader thread, and must come back with the same shape;
- other descriptors are fitted on the first cloud (they learn nothing from
  the data) and describe while the files are read;
- each chunk is described by the copy of the fitted descriptor that the
  descriptor makes for it (``_stream_part``): it draws the chunk's seeds,
  those that follow the previous chunk's in one generator, as one
  ``transform`` over all the clouds would. With ``n_jobs`` above 1 the
  copies are single-threaded and chunks are described side by side, one
  per thread (no OpenMP team waits at a barrier between a chunk's kernels
  while another core has work).
"""

import collections
import io
import numbers
import os
import re
import tempfile
import time
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from sklearn.base import clone
from sklearn.utils import Bunch

from .utils import check_n_jobs, ordered_map, progress_bar
from .utils._atomic import atomic_write
from .utils._param_validation import RANDOM_STATE, Interval, validate_parameter
from .utils._stream import RowWriter

__all__ = ["describe_files"]

#: Files per chunk of the stream (reading, describing and writing go chunk by chunk).
CHUNK_FILES = 128
#: Bytes of files per chunk (file sizes on disk): bounds a chunk's memory for large files.
CHUNK_BYTES = 32 << 20
#: Files of the first chunk (at most the chunk size): describing starts as soon as they are read.
FIRST_CHUNK_FILES = 16
#: Bytes per second at which the first pass is taken to write clouds to its temporary file: a cloud that
#: was read faster than it could be written (a binary point file) is read again in the second pass instead.
SPILL_BYTES_PER_SECOND = 250e6
#: What a reader raises for a file that cannot be read (readers: ValueError; OS and h5py: OSError, KeyError).
READ_ERRORS = (ValueError, OSError, KeyError)


#: ``chunk_size`` of the streaming functions (:mod:`eppf.utils._param_validation`); None means CHUNK_FILES.
_CHUNK_SIZE = [Interval(numbers.Integral, 1, None, closed="left", description="a positive int")]

def describe_files(files, descriptor, *, output=None, n_points=None, resolution=None, normals="auto",
                   random_state=0, n_jobs=None, on_error="raise", chunk_size=None, progress=False):
    """Describe point cloud or mesh files, streamed in memory that does not grow with their number.

    Every file is read with :func:`eppf.io.read_point_cloud` and described by
    a clone of ``descriptor``; the rows are bit for bit those of
    ``clone(descriptor).fit_transform(clouds)`` on all the clouds read the
    same way, whatever ``n_jobs`` and ``chunk_size``.

    Parameters
    ----------
    files : sequence of str or path-like
        Point cloud or mesh files (every extension of
        :func:`eppf.io.supported_extensions`, any case) and folders, searched
        recursively for such files (hidden files and folders skipped, sorted
        by path).
    descriptor : descriptor transformer
        An eppf descriptor (a class of :mod:`eppf.descriptors`, a
        :class:`~eppf.descriptors.DescriptorUnion`); it is cloned, not
        changed.
    output : str, path-like or binary file, default=None
        Where the rows go as they are made: a ``.npy`` path (written
        atomically) or a seekable binary file open for writing (a ``.npy``
        array is written from its current position). None keeps the rows
        in memory and returns them.
    n_points : int, default=None
        Points per object: meshes are sampled with this many (2,048 when
        None), point files resampled to it (kept as they are when None).
    resolution : float, default=None
        Instead of ``n_points``, sample meshes on a voxel grid of this cell
        size.
    normals : {"auto", True, False}, default="auto"
        Normals read from the files (face normals for meshes): when present,
        always, or never.
    random_state : int, RandomState instance or None, default=0
        Seed of mesh sampling and resampling: each file gets its own seed
        from this one and its path relative to the folder it was found in
        (its own folder for a file named directly), the seeds of
        :func:`eppf.datasets.load_folder`, which takes the same values: an
        int in 0..2**32-1, a RandomState or None (a fresh seed), from which
        every folder or file of ``files`` draws its base seed in turn, as
        ``load_folder`` does for its folder. The descriptor's draws follow
        the descriptor's own ``random_state``.
    n_jobs : int, default=None
        Threads (joblib's meaning); None takes the descriptor's ``n_jobs``.
        With more than one, files are read on up to two threads while chunks
        are described side by side by single-threaded copies of the fitted
        descriptor.
    on_error : {"raise", "skip"}, default="raise"
        A file that cannot be read stops the call (a ValueError naming it),
        or is skipped with a warning and listed in ``skipped``.
    chunk_size : int, default=None
        Files per chunk (:data:`CHUNK_FILES`, 128, when None), and at most
        32 MiB of files; memory holds a few chunks of clouds.
    progress : bool, default=False
        Show progress bars over the files on standard error.

    Returns
    -------
    result : :class:`~sklearn.utils.Bunch`
        ``descriptors`` (ndarray of shape (n_files_read, n_features), or None
        when written to ``output``), ``n_features``, ``files`` (the files
        described, in row order), ``skipped`` (``(file, message)`` pairs),
        ``n_points`` (points per cloud read) and ``descriptor`` (the fitted
        clone).

    Raises
    ------
    ValueError
        If a file cannot be read and ``on_error="raise"``, if no file could
        be read, if a cloud cannot be described (the message names the
        file), or if ``n_points`` is above a billion.
    TypeError
        If ``descriptor`` is not an eppf descriptor, or ``files``,
        ``output`` or ``random_state`` is of a type they do not take.
    FileNotFoundError
        If a file or folder of ``files`` does not exist.

    See Also
    --------
    eppf.io.read_point_cloud : How each file is read.
    eppf.datasets.load_folder : Load a labeled folder into memory.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from eppf import EPPFTransformer, describe_files
    >>> from eppf.datasets import make_shapes
    >>> from eppf.io import read_point_cloud, write_point_cloud
    >>> folder = tempfile.mkdtemp()
    >>> clouds, _ = make_shapes(2, n_points=256, classes=["box", "sphere"], return_X_y=True)
    >>> for k, cloud in enumerate(clouds):
    ...     write_point_cloud(os.path.join(folder, f"scan{k}.ply"), cloud)
    >>> est = EPPFTransformer(n_pairs=500, random_state=0)
    >>> result = describe_files([folder], est)
    >>> result.descriptors.shape, [os.path.basename(f) for f in result.files]
    ((4, 1200), ['scan0.ply', 'scan1.ply', 'scan2.ply', 'scan3.ply'])
    >>> same = est.fit_transform([read_point_cloud(f) for f in result.files])
    >>> bool((result.descriptors == same).all())
    True
    """
    from .datasets._folder import object_files
    from .datasets._loaders import check_path, file_seeds
    from .io._api import check_sampling_args

    owner = "describe_files"
    if on_error not in ("raise", "skip"):
        raise ValueError(f"{owner}: on_error must be 'raise' or 'skip', got {on_error!r}")
    # once, not per file (where "skip" hid them); n_points within the readers' bound before any file is read
    check_sampling_args(owner, normals, n_points, resolution)
    validate_parameter(random_state, RANDOM_STATE, name="random_state", owner=owner)
    if output is not None and not (hasattr(output, "write") or isinstance(output, (str, bytes, os.PathLike))):
        raise TypeError(f"{owner}: output must be a .npy path or a binary file open for writing, "
                        f"got {type(output).__name__}")
    if isinstance(files, (str, bytes, os.PathLike)):
        files = [files]
    elif not hasattr(files, "__iter__"):
        raise TypeError(f"{owner}: files must be a path or a sequence of paths, got {type(files).__name__}")
    files = list(files)
    names, seeds = [], []
    for k, item in enumerate(files):
        path = check_path(item, f"files[{k}]", owner)
        if os.path.isdir(path):
            found = object_files(path)
            root = path
        elif os.path.isfile(path):
            found, root = [path], os.path.dirname(path) or "."
        else:
            raise FileNotFoundError(f"{owner}: no such file or folder: {path}")
        names += found
        seeds += file_seeds(random_state, root, found)
    if not names:
        raise ValueError(f"{owner}: no point cloud or mesh files in {[os.fsdecode(f) for f in files]}")

    def read(k):
        from .io import read_point_cloud

        cloud = read_point_cloud(names[k], normals=normals, n_points=n_points, resolution=resolution,
                                 random_state=seeds[k])
        return np.asarray(cloud, dtype=np.float64)

    def unreadable(k, exc):
        msg = str(exc)
        msg = msg if names[k] in msg else f"{names[k]}: {msg}"
        if on_error == "raise":
            raise ValueError(f"{owner}: {msg}") from None
        return msg

    if output is None:
        rows = []
        result = stream_descriptors(names, read, descriptor, rows.append, n_jobs=n_jobs, unreadable=unreadable,
                                    chunk_size=chunk_size, progress=progress)
        X = np.concatenate(rows) if rows else None
    elif hasattr(output, "write"):
        _check_binary_seekable(output, owner)  # (before the work: the .npy header is written last, in bytes)
        X, result = None, write_descriptors(output, names, read, descriptor, n_jobs=n_jobs, unreadable=unreadable,
                                            chunk_size=chunk_size, progress=progress)
    else:
        output = check_path(output, "output", owner)
        if not output.lower().endswith(".npy"):
            raise ValueError(f"{owner}: output must be a .npy path or a binary file, got {output}")
        with atomic_write(output) as fh:
            result = write_descriptors(fh, names, read, descriptor, n_jobs=n_jobs, unreadable=unreadable,
                                       chunk_size=chunk_size, progress=progress)
        X = None
    if result.skipped:
        warnings.warn(f"{owner}: {skipped_summary(result.skipped, len(names))}; the list is in 'skipped'",
                      UserWarning, stacklevel=2)
    return Bunch(descriptors=X, n_features=result.n_features, files=[names[k] for k in result.kept],
                 skipped=result.skipped, n_points=result.shapes[:, 0].copy(), descriptor=result.descriptor)


def _check_binary_seekable(fh, owner):
    """A file object ``describe_files`` can write a ``.npy`` array to: binary and seekable."""
    if isinstance(fh, io.TextIOBase):
        raise TypeError(f"{owner}: output must be a file opened in binary mode ('wb'), got {fh!r}")
    try:
        seekable = fh.seekable() if hasattr(fh, "seekable") else False
    except (OSError, ValueError):  # (a closed file)
        seekable = False
    if not seekable:
        raise ValueError(f"{owner}: output must be seekable (the .npy header is completed after the rows), got "
                         f"{fh!r}; write to a .npy path or a regular file")


def _first_messages(skipped):
    """The messages of the first three ``(file, message)`` pairs, and how many more there are."""
    more = f"; and {len(skipped) - 3} more" if len(skipped) > 3 else ""
    return "; ".join(f"{m}" for _, m in skipped[:3]) + more


def skipped_summary(skipped, n_files):
    """``"skipped 2 of 9 files that could not be read: <first messages>"`` for ``(file, message)`` pairs."""
    return f"skipped {len(skipped)} of {n_files} files that could not be read: {_first_messages(skipped)}"


def nothing_read(skipped, n_files):
    """The ValueError of a stream in which no file could be read."""
    return ValueError(f"no file could be read ({len(skipped)} of {n_files}): {_first_messages(skipped)}")


def write_descriptors(fh, names, read, descriptor, **kwargs):
    """:func:`stream_descriptors` into a ``.npy`` array written to ``fh`` as the rows come (RowWriter)."""
    writer = []

    def sink(rows):
        if not writer:
            writer.append(RowWriter(fh, rows.shape[1]))
        writer[0].write(rows)

    result = stream_descriptors(names, read, descriptor, sink, **kwargs)
    writer[0].close()
    return result


def stream_descriptors(names, read, descriptor, sink, *, n_jobs=None, unreadable=None, chunk_size=None,
                       progress=False, owner="describe_files"):
    """The engine of :func:`describe_files` (and of ``eppf describe``): rows of ``read(k)`` for every file, in order.

    Parameters
    ----------
    names : list of str
        The files (their sizes bound the chunks; messages name them).
    read : callable
        ``read(k)`` -> the float64 cloud of file ``k``, or a ValueError,
        OSError or KeyError when it cannot be read (called on reader threads).
    descriptor : descriptor transformer
        Cloned and fitted on the clouds (see the module docstring).
    sink : callable
        Called with each chunk's rows (float64, 2-D), in file order.
    n_jobs : int, default=None
        Threads; None takes the descriptor's ``n_jobs``.
    unreadable : callable, default=None
        ``unreadable(k, exc)`` for a file that cannot be read: returns the
        message to list it under, or raises. None raises ``exc``.
    chunk_size : int, default=None
        Files per chunk (:data:`CHUNK_FILES` when None).
    progress : bool, default=False
        Progress bars over the files.
    owner : str, default="describe_files"
        The caller's name in messages.

    Returns
    -------
    result : :class:`~sklearn.utils.Bunch`
        ``kept`` (indices of the files described, in order), ``skipped``
        (``(name, message)`` pairs), ``shapes`` (int array (n_kept, 2) of the
        clouds' shapes), ``n_features`` and ``descriptor`` (the fitted clone).
    """
    if not (hasattr(descriptor, "partial_fit") and hasattr(descriptor, "_stream_part")):
        pool = hasattr(descriptor, "n_draws") and hasattr(descriptor, "transformer")
        hint = (" (a pool gives several draws a cloud, which are not one row a file: stream its transformer)"
                if pool else "")
        raise TypeError(f"{owner}: descriptor must be an eppf descriptor transformer (with partial_fit), "
                        f"got {type(descriptor).__name__}{hint}")
    chunk_size = CHUNK_FILES if chunk_size is None else chunk_size
    validate_parameter(chunk_size, _CHUNK_SIZE, name="chunk_size", owner=owner)
    est = clone(descriptor)
    if n_jobs is None:
        n_jobs = est.get_params(deep=False).get("n_jobs")
    stream = _Stream(names, read, est, check_n_jobs(n_jobs), unreadable, chunk_size, progress, owner)
    n_features = stream.run(sink)
    shapes = np.asarray(stream.shapes, dtype=np.int64).reshape(-1, 2)
    return Bunch(kept=stream.kept, skipped=stream.skipped, shapes=shapes, n_features=n_features, descriptor=est)


def _name_files(exc, files):
    """The descriptor's message with "point cloud <i>" (its index in the chunk) replaced by the file's name."""
    def repl(m):
        i = int(m.group(1))
        return f"point cloud {files[i]}" if 0 <= i < len(files) else m.group(0)

    return ValueError(re.sub(r"point cloud (\d+)", repl, str(exc), count=1))


class _Stream:
    """One run of :func:`stream_descriptors`: the chunks, the readers, the passes and what was read."""

    def __init__(self, names, read, est, n_threads, unreadable, chunk_size, progress, owner):
        self.names, self.read, self.est, self.n_threads, self.owner = names, read, est, n_threads, owner
        self.unreadable, self.chunk_size, self.progress = unreadable, chunk_size, progress
        self.readers = max(1, min(2, n_threads))
        self.kept, self.skipped, self.shapes = [], [], []

    def _chunks(self):
        """File indices in chunks of at most ``chunk_size`` files (FIRST_CHUNK_FILES for the first) and (but
        for one large file) CHUNK_BYTES bytes."""
        chunks, current, size = [], [], 0
        for k, f in enumerate(self.names):
            try:
                n_bytes = os.stat(f).st_size
            except OSError:
                n_bytes = 0  # (the reader names the problem)
            most = self.chunk_size if chunks else min(FIRST_CHUNK_FILES, self.chunk_size)
            if current and (len(current) >= most or size + n_bytes > CHUNK_BYTES):
                chunks.append(current)
                current, size = [], 0
            current.append(k)
            size += n_bytes
        if current:
            chunks.append(current)
        return chunks

    def _read_chunk(self, chunk):
        """``[(k, cloud, None, seconds) or (k, None, exception, seconds)]`` of one chunk (on a reader thread);
        ``seconds`` is the thread's CPU time spent reading the file (waiting for a busy core not counted)."""
        out = []
        for k in chunk:
            t0 = time.thread_time()
            try:
                out.append((k, self.read(k), None, time.thread_time() - t0))
            except READ_ERRORS as exc:
                out.append((k, None, exc, time.thread_time() - t0))
        return out

    def _read_chunks(self):
        return ordered_map(self._read_chunk, self._chunks(), workers=self.readers, depth=self.readers + 1)

    def _accept(self, results):
        """Clouds, indices and read seconds of one chunk's results; unreadable files handled in order."""
        clouds, kept, seconds = [], [], []
        for k, cloud, exc, secs in results:
            if exc is not None:
                if self.unreadable is None:
                    raise exc
                self.skipped.append((self.names[k], self.unreadable(k, exc)))
                continue
            clouds.append(cloud)
            kept.append(k)
            seconds.append(secs)
            self.kept.append(k)
            self.shapes.append((cloud.shape[0], cloud.shape[1] if cloud.ndim > 1 else 1))
        return clouds, kept, seconds

    def _fit(self, clouds, kept):
        try:
            self.est.partial_fit(clouds)
        except ValueError as exc:
            raise _name_files(exc, [self.names[k] for k in kept]) from None

    def run(self, sink):
        """Read, fit and describe; rows to ``sink``; the number of columns."""
        rows = _Rows(self.est, self.n_threads)
        try:
            if self.est._learns_from_data():
                self._two_passes(rows, sink)
            else:
                self._one_pass(rows, sink)
            rows.finish(sink)
        finally:
            rows.close()
        if not self.kept:
            raise nothing_read(self.skipped, len(self.names))
        return int(self.est.n_features_out_)

    def _one_pass(self, rows, sink):
        bar = progress_bar(total=len(self.names), desc="describing", unit="file", enabled=self.progress)
        try:
            for results in self._read_chunks():
                clouds, kept, _ = self._accept(results)
                if clouds:
                    if not rows.started:
                        self._fit(clouds[:1], kept[:1])  # it learns nothing from the clouds
                    rows.submit(clouds, [self.names[k] for k in kept], sink)
                bar.update(len(results))
        finally:
            bar.close()

    def _two_passes(self, rows, sink):
        with tempfile.TemporaryFile(prefix="eppf-describe-") as spill:
            # records: (entry, offset in the spill or -1 to read the file again, shape) per kept cloud
            records, offset = [], 0
            bar = progress_bar(total=len(self.names), desc="reading", unit="file", enabled=self.progress)
            try:
                for results in self._read_chunks():
                    clouds, kept, seconds = self._accept(results)
                    bar.update(len(results))
                    if not clouds:
                        continue
                    clouds = [np.ascontiguousarray(c, dtype=np.float64) for c in clouds]
                    self._fit(clouds, kept)
                    spilled = []
                    for cloud, k, secs in zip(clouds, kept, seconds):
                        # which clouds are spilled changes the time only: a file read again gives the same cloud
                        if secs * SPILL_BYTES_PER_SECOND > cloud.nbytes:
                            records.append((k, offset, cloud.shape))
                            offset += cloud.nbytes
                            spilled.append(cloud)
                        else:
                            records.append((k, -1, cloud.shape))
                    if spilled:  # one write per chunk; clouds of different widths are laid end to end
                        spill.write(b"".join(c.data for c in spilled))
            finally:
                bar.close()
            if not records:
                return
            spill.flush()
            fd = spill.fileno()
            first, size = min(FIRST_CHUNK_FILES, self.chunk_size), self.chunk_size
            groups = [records[:first]] + [records[i:i + size] for i in range(first, len(records), size)]
            bar = progress_bar(total=len(records), desc="describing", unit="file", enabled=self.progress)
            try:
                for clouds, files in ordered_map(lambda g: self._read_back(fd, g), groups, workers=1, depth=2):
                    rows.submit(clouds, files, sink)
                    bar.update(len(clouds))
            finally:
                bar.close()

    def _read_back(self, fd, group):
        """Clouds and file names of the first pass's records ``(entry, offset, shape)``.

        Spilled clouds come from the temporary file (one read for the group's
        span); the others are read from their files again, as in the first
        pass, and a file that cannot be read again or gives another shape
        stops the stream, naming it.
        """
        spilled = [r for r in group if r[1] >= 0]
        buf, start = None, 0
        if spilled:
            start = spilled[0][1]
            end = spilled[-1][1] + 8 * int(np.prod(spilled[-1][2]))
            buf = bytearray(end - start)
            view, got = memoryview(buf), 0
            while got < len(buf):  # pread may return fewer bytes than asked
                n = os.preadv(fd, [view[got:]], start + got)
                if n <= 0:
                    raise OSError(f"{self.owner}: the temporary file of the read clouds ended early "
                                  f"({got} of {len(buf)} bytes)")
                got += n
        clouds = []
        for k, off, shape in group:
            file = self.names[k]
            if off >= 0:
                cloud = np.frombuffer(buf, dtype=np.float64, count=int(np.prod(shape)),
                                      offset=off - start).reshape(shape)
            else:
                try:
                    cloud = self.read(k)
                except READ_ERRORS as exc:
                    raise ValueError(f"{file} could not be read again for its descriptor (it changed while "
                                     f"{self.owner} ran?): {exc}") from None
                if cloud.shape != shape:
                    raise ValueError(f"{file} changed while {self.owner} ran: {shape[0]} points in the first "
                                     f"pass, {cloud.shape[0]} now")
            clouds.append(cloud)
        return clouds, [self.names[r[0]] for r in group]


class _Rows:
    """Descriptor rows of chunks, in order: one chunk at a time, or side by side on threads.

    Each chunk is described by the copy of the fitted descriptor that the
    descriptor makes for it (``_stream_part``, in chunk order on the calling
    thread): the copy draws the chunk's seeds. With ``n_threads`` above 1 the
    copies are single-threaded (``n_jobs=1``) and run on ``n_threads``
    threads; otherwise each chunk is described on the calling thread with
    the descriptor's own ``n_jobs``. Rows reach ``sink`` in chunk order; at
    most ``n_threads + 1`` chunks wait or run at a time, so memory does not
    grow with the number of files.
    """

    def __init__(self, est, n_threads):
        self.est, self.workers = est, int(n_threads)
        self.parallel = self.workers > 1 and "n_jobs" in est.get_params(deep=False)
        self.pool, self.pending, self.generator, self.started = None, collections.deque(), None, False

    @staticmethod
    def _transform(part, clouds, files):
        try:
            return part.transform(clouds)
        except ValueError as exc:
            raise _name_files(exc, files) from None

    def submit(self, clouds, files, sink):
        """Describe one chunk (rows to ``sink`` now or with a later call, in order)."""
        if not self.started:
            self.started = True
            self.generator = self.est._stream_generator()
            if self.parallel:
                self.pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="eppf-describe")
        if not self.parallel:
            sink(self._transform(self.est._stream_part(len(clouds), self.generator), clouds, files))
            return
        part = self.est._stream_part(len(clouds), self.generator, n_jobs=1)
        self.pending.append(self.pool.submit(self._transform, part, clouds, files))
        while len(self.pending) > self.workers:
            sink(self.pending.popleft().result())

    def finish(self, sink):
        """Send the rows of the chunks still running."""
        while self.pending:
            sink(self.pending.popleft().result())

    def close(self):
        """Cancel what has not started and wait for the rest (after an error, Ctrl-C or :meth:`finish`)."""
        for future in self.pending:
            future.cancel()
        self.pending.clear()
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None
