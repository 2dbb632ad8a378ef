"""``eppf describe``: descriptors of files, folders or a ``.npz`` data set.

Files and folders are streamed: chunks of files are read on reader threads
(:func:`eppf.utils._stream.ordered_map`) while the descriptor, whose compiled
kernels release the GIL, describes the chunk before; rows go to the output
file as they come (:class:`eppf.utils._stream.RowWriter`), so memory holds a
few chunks whatever the number of files. The rows are bit for bit those of
``fit_transform`` on all the clouds read the one way (:func:`read_inputs`):

- per-object seeds are consecutive draws of one ``RandomState(random_state)``
  (:func:`eppf.utils.object_seeds`), so the descriptor is given such a
  generator before it is fitted, and each chunk's ``transform`` draws the
  seeds of its rows, those that follow the previous chunk's;
- a descriptor whose scale is learnt from the data set (``scaling="fit"``,
  EPPF's default: one over the largest bounding-box side of any object)
  needs every object before the first row: a first pass reads every file
  and keeps the largest object; the descriptor is fitted on it (the same
  scale as fitting on all of them) and the second pass describes the
  clouds. A cloud that took longer to read than to write (a sampled mesh, a
  text file) is spilled, as read, to an unnamed temporary file in the first
  pass and taken from there; the others (binary point files) are read again,
  on the reader thread, and must come back with the same shape;
- other descriptors are fitted on the first cloud (they learn nothing from
  the data) and describe while the files are read;
- with ``--n-jobs`` above 1, chunks are described side by side
  (:class:`_ParallelRows`), each by a single-threaded copy of the fitted
  descriptor on its own thread (the compiled kernels release the GIL),
  rather than one chunk at a time on OpenMP threads: no OpenMP team waits
  at a barrier or spins between a chunk's kernels while the other core has
  work. A copy gets the generator in the state the chunk's first row would
  find it in (the chunk's seeds are drawn ahead on a copy of it), so its
  rows are those of the one generator, bit for bit; a descriptor whose
  draws that does not predict (checked on the first chunk) is described
  one chunk at a time as before.

A ``.npz`` data set is read whole and described in one ``fit_transform``.
"""

import collections
import copy
import json
import os
import re
import shutil
import sys
import tempfile
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..utils import check_n_jobs, object_seeds
from ..utils._atomic import atomic_write
from ..utils._bounds import largest_sides
from ..utils._stream import RowWriter, ordered_map
from ._common import (Command, add_descriptor, add_runtime, add_sampling, check_output, descriptor_settings,
                      is_data_set_input, make_descriptor, min_points_needed, plan_inputs, progress_of, read_inputs,
                      register, sampling_from_args, warn_tiny)

__all__ = ["run_describe"]

#: Files per chunk of the stream (reading, describing and writing go chunk by chunk).
CHUNK_FILES = 128
#: Bytes of files per chunk (file sizes on disk): bounds a chunk's memory for large files.
CHUNK_BYTES = 32 << 20
#: Files of the first chunk described (at most CHUNK_FILES): with ``--n-jobs`` above 1 it is described alone,
#: on the calling thread (:class:`_ParallelRows`), before chunks go side by side, so it is kept short.
FIRST_CHUNK_FILES = 16


def add_arguments(p):
    p.add_argument("inputs", nargs="+", help="point cloud or mesh files (every extension of "
                                             "eppf.io.supported_extensions(), any case), folders (searched "
                                             "recursively; a folder of class subfolders keeps its labels) or "
                                             "one .npz data set")
    p.add_argument("-o", "--output", required=True, help="output file, .npy (the matrix) or .npz (with ids, "
                                                         "labels and class names when known, and how the "
                                                         "descriptors were made)")
    add_descriptor(p)
    add_sampling(p)
    add_runtime(p)


def _write_stream(fh, run, plan, state):
    """Run the stream into a ``.npy`` row writer on ``fh``; the number of columns written."""
    writer = []

    def sink(rows):
        if not writer:
            writer.append(RowWriter(fh, rows.shape[1]))
        writer[0].write(rows)

    run(sink)
    plan.report_skipped(state["skipped"], len(state["kept"]))
    writer[0].close()
    return writer[0].n_cols


def run_describe(args, out=None):
    """Run ``eppf describe``: compute descriptors of files and save them.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf describe`` arguments.
    out : file-like, default=None
        Where the summary line goes (standard output by default).

    Returns
    -------
    shape : tuple of int
        ``(n_objects, n_features)`` of the descriptors that were saved.
    """
    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf describe")
    output = check_output(args.output, (".npy", ".npz"))
    progress = progress_of(args)
    t0 = time.perf_counter()
    sampling = sampling_from_args(args)
    if is_data_set_input(args.inputs):
        est = make_descriptor(args.descriptor, descriptor_settings(args, progress))
        params = _saved_params(est)
        objects = read_inputs(args.inputs, sampling, on_error=args.on_error, progress=progress, cmd=cmd)
        warn_tiny(objects.clouds, objects.ids, est, cmd, args.descriptor)
        X = est.fit_transform(objects.clouds)
        meta = _Meta(objects.ids, objects.labels, objects.class_names, objects.split,
                     getattr(est, "scale_", None), params)
        _save(output, X, meta, args, sampling)
        n, n_features = X.shape
    else:
        est = make_descriptor(args.descriptor, descriptor_settings(args, False))
        n, n_features, meta = _stream(args, est, sampling, output, progress, cmd)
    seconds = time.perf_counter() - t0
    labelled = "" if meta.labels is None else f", {len(meta.class_names)} classes"
    print(f"eppf: {n} {args.descriptor} descriptors of {n_features} bins{labelled} -> {output} "
          f"({1e3 * seconds / n:.2f} ms per object, {n / seconds:.0f} files per second, {seconds:.1f} s)", file=out)
    return n, n_features


class _Meta:
    """What the .npz output keeps beside the descriptors."""

    def __init__(self, ids, labels, class_names, split, scale, params):
        self.ids, self.labels, self.class_names, self.split = ids, labels, class_names, split
        self.scale, self.params = scale, params


def _saved_params(est):
    return {k: v for k, v in est.get_params().items() if k not in ("verbose", "n_jobs")}


def _npz_extras(meta, args, sampling):
    arrays = dict(ids=meta.ids, descriptor=np.array(args.descriptor),
                  params=np.array(json.dumps(meta.params, default=list)),
                  sampling=np.array(json.dumps(sampling)),
                  scale=np.array(np.nan if meta.scale is None else meta.scale))
    if meta.labels is not None:
        arrays.update(labels=meta.labels, class_names=meta.class_names)
    if meta.split is not None:
        arrays.update(split=meta.split)
    return arrays


def _save(output, X, meta, args, sampling):
    """The in-memory path: save ``X`` (and, for .npz, ``meta``) atomically."""
    if output.lower().endswith(".npy"):
        with atomic_write(output) as fh:
            np.save(fh, X)
        return
    with atomic_write(output) as fh:
        np.savez(fh, descriptors=X, **_npz_extras(meta, args, sampling))


# ---------------------------------------------------------------------------
# The stream
# ---------------------------------------------------------------------------


def _learns_scale(est):
    """True when the descriptor (or a block of it) learns its scale from the data set."""
    return any(v == "fit" for k, v in est.get_params().items() if k == "scaling" or k.endswith("__scaling"))


def _chunks(plan):
    """Entry indices in chunks of at most CHUNK_FILES files (FIRST_CHUNK_FILES for the first) and (but for one
    large file) CHUNK_BYTES bytes."""
    chunks, current, size = [], [], 0
    for k, (f, _, _) in enumerate(plan.entries):
        try:
            n_bytes = os.stat(f).st_size
        except OSError:
            n_bytes = 0  # (the reader names the problem)
        most = CHUNK_FILES if chunks else min(FIRST_CHUNK_FILES, CHUNK_FILES)
        if current and (len(current) >= most or size + n_bytes > CHUNK_BYTES):
            chunks.append(current)
            current, size = [], 0
        current.append(k)
        size += n_bytes
    if current:
        chunks.append(current)
    return chunks


def _read_chunk(plan, chunk):
    """``[(k, cloud, None, seconds) or (k, None, exception, seconds)]`` of one chunk of entries (on a reader
    thread); ``seconds`` is the thread's CPU time spent reading the file (waiting for a busy core not counted)."""
    out = []
    for k in chunk:
        t0 = time.thread_time()
        try:
            out.append((k, plan.read(k), None, time.thread_time() - t0))
        except (ValueError, OSError, KeyError) as exc:
            out.append((k, None, exc, time.thread_time() - t0))
    return out


#: Bytes per second at which the first pass is taken to write clouds to its temporary file: a cloud that
#: was read faster than it could be written (a binary point file) is read again in the second pass instead.
SPILL_BYTES_PER_SECOND = 250e6


def _name_files(exc, files):
    """The descriptor's message with "point cloud <i>" (its index in the chunk) replaced by the file's name."""
    def repl(m):
        i = int(m.group(1))
        return f"point cloud {files[i]}" if 0 <= i < len(files) else m.group(0)

    return ValueError(re.sub(r"point cloud (\d+)", repl, str(exc), count=1))


class _Bar:
    """A tqdm bar over files, or nothing."""

    def __init__(self, total, enabled, desc):
        self.bar = None
        if enabled:
            try:
                from tqdm.auto import tqdm
            except ImportError:  # pragma: no cover
                return
            self.bar = tqdm(total=total, desc=desc, unit="file", file=sys.stderr, leave=False)

    def update(self, n):
        if self.bar is not None:
            self.bar.update(n)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _stream(args, est, sampling, output, progress, cmd):
    plan = plan_inputs(args.inputs, sampling, cmd=cmd)
    params = _saved_params(est)
    if "random_state" in est.get_params(deep=False) and 0 <= args.random_state < 2 ** 32:
        # consecutive draws of one generator: chunk after chunk, the seeds of one fit_transform
        # (a seed out of range stays as it is, for the descriptor's own message)
        est.set_params(random_state=np.random.RandomState(args.random_state))
    n_threads = check_n_jobs(args.n_jobs)
    workers = max(1, min(2, n_threads))
    chunks = _chunks(plan)
    state = dict(kept=[], skipped=[], tiny_clouds=[], tiny_ids=[], fitted=False)
    need, _ = min_points_needed(est)

    def accept(results):
        """Clouds and file names of one chunk's results; skipped or raised files handled in order."""
        clouds, files, kept, seconds = [], [], [], []
        for k, cloud, exc, secs in results:
            if exc is not None:
                state["skipped"].append((plan.entries[k][0], plan.error(k, exc, args.on_error)))
                continue
            state["kept"].append(k)
            clouds.append(cloud)
            files.append(plan.entries[k][0])
            kept.append(k)
            seconds.append(secs)
            if len(cloud) < need:
                state["tiny_clouds"].append(cloud)
                state["tiny_ids"].append(plan.entries[k][0])
        return clouds, files, kept, seconds

    def fit(cloud, file):
        try:
            est.fit([cloud])
        except ValueError as exc:
            raise _name_files(exc, [file]) from None
        state["fitted"] = True

    rows = _ParallelRows(est, n_threads)

    def describe(clouds, files, sink):
        if not clouds:
            return
        if not state["fitted"]:
            fit(clouds[0], files[0])
        rows.submit(clouds, files, sink)

    def run(sink):
        try:
            _run(sink)
            rows.finish(sink)
        finally:
            rows.close()

    def _run(sink):
        bar = _Bar(len(plan.entries), progress, "reading" if _learns_scale(est) else "describing")
        try:
            if not _learns_scale(est):
                for results in ordered_map(lambda c: _read_chunk(plan, c), chunks, workers=workers,
                                           depth=workers + 1):
                    clouds, files, _, _ = accept(results)
                    describe(clouds, files, sink)
                    bar.update(len(results))
                return
            with tempfile.TemporaryFile(prefix="eppf-describe-") as spill:
                # records: (file, entry, offset in the spill or -1 to read the file again, shape) per kept cloud
                records, best = [], (-np.inf, None, None)
                offset = 0
                for results in ordered_map(lambda c: _read_chunk(plan, c), chunks, workers=workers,
                                           depth=workers + 1):
                    clouds, files, kept, seconds = accept(results)
                    bar.update(len(results))
                    if not clouds:
                        continue
                    clouds = [np.ascontiguousarray(c, dtype=np.float64) for c in clouds]
                    sides = largest_sides(clouds)
                    j = int(np.argmax(sides))
                    if sides[j] > best[0] or best[1] is None:
                        best = (sides[j], clouds[j], files[j])
                    spilled = []
                    for cloud, file, k, secs in zip(clouds, files, kept, seconds):
                        # which clouds are spilled changes the time only: a file read again gives the same cloud
                        if secs * SPILL_BYTES_PER_SECOND > cloud.nbytes:
                            records.append((file, k, offset, cloud.shape))
                            offset += cloud.nbytes
                            spilled.append(cloud)
                        else:
                            records.append((file, k, -1, cloud.shape))
                    if spilled:  # one write per chunk; clouds of different widths are laid end to end
                        spill.write(b"".join(c.data for c in spilled))
                bar.close()
                if not records:
                    return
                # the data set's scale: fitting on the largest object gives the scale of fitting on all of them
                fit(best[1], best[2])
                best = None
                spill.flush()
                fd = spill.fileno()
                first = min(FIRST_CHUNK_FILES, CHUNK_FILES)
                groups = [records[:first]] + [records[i:i + CHUNK_FILES] for i in range(first, len(records),
                                                                                         CHUNK_FILES)]
                bar = _Bar(len(records), progress, "describing")
                for clouds, files in ordered_map(lambda g: _read_back(plan, fd, g), groups, workers=1, depth=2):
                    describe(clouds, files, sink)
                    bar.update(len(clouds))
        finally:
            bar.close()

    if output.lower().endswith(".npy"):
        with atomic_write(output) as fh:
            n_features = _write_stream(fh, run, plan, state)
        meta = _kept_meta(plan, state["kept"], None, params)
    else:
        with tempfile.TemporaryFile(prefix="eppf-describe-rows-") as rows_file:
            n_features = _write_stream(rows_file, run, plan, state)
            meta = _kept_meta(plan, state["kept"], getattr(est, "scale_", None), params)
            rows_file.seek(0)
            with atomic_write(output) as fh:
                # np.savez's layout (stored, one .npy per array); the descriptors are copied from the rows file
                with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
                    with zf.open("descriptors.npy", "w", force_zip64=True) as entry:
                        shutil.copyfileobj(rows_file, entry, 1 << 20)
                    for name, value in _npz_extras(meta, args, sampling).items():
                        with zf.open(name + ".npy", "w", force_zip64=True) as entry:
                            np.lib.format.write_array(entry, np.asanyarray(value), allow_pickle=False)
    warn_tiny(state["tiny_clouds"], state["tiny_ids"], est, cmd, args.descriptor)
    return len(state["kept"]), n_features, meta


def _kept_meta(plan, kept, scale, params):
    """The :class:`_Meta` of the entries ``kept`` (indices, in order): the ids, labels, class names and split
    that ``plan.objects`` gives them (the same arrays), without the resolved paths it also makes (a
    ``realpath`` per file, which describe does not save)."""
    entries = plan.entries
    ids = np.asarray([entries[k][0] for k in kept], dtype=str)
    labels = split = None
    if plan.class_names is not None:
        index = {c: j for j, c in enumerate(plan.class_names)}
        labels = np.asarray([index[entries[k][2][0]] for k in kept], dtype=np.int64)
        split = np.asarray([entries[k][2][1] for k in kept], dtype=str)
        split = split if (split != "").all() else None
    return _Meta(ids, labels, plan.class_names, split, scale, params)


class _ParallelRows:
    """Descriptor rows of chunks, in order: one chunk at a time, or side by side on threads.

    With ``n_threads`` above 1, a descriptor that describes each cloud on its
    own (its rows depend on the cloud, the fitted state and, with a
    ``random_state``, consecutive seeds of one generator) runs a chunk's
    ``transform`` on one of ``n_threads`` threads, with a shallow copy of the
    fitted descriptor set to one thread (``n_jobs=1``) and to a copy of the
    generator in the state that chunk's first row finds it in: the chunk's
    seeds are drawn ahead from the one generator, the way ``transform``
    draws them (:func:`eppf.utils.object_seeds`, one per cloud). The
    first chunk is described on the calling thread, with the descriptor's
    own ``n_jobs``, and checks that prediction: when its generator ends
    elsewhere (a descriptor that draws otherwise), every chunk is described
    one at a time as before. Each later chunk checks it again and stops the
    command if it fails.

    Rows reach ``sink`` in chunk order; at most ``n_threads + 1`` chunks
    wait or run at a time, so memory does not grow with the number of files.
    """

    def __init__(self, est, n_threads):
        self.est, self.workers = est, int(n_threads)
        self.pool, self.pending, self.base, self.generator = None, collections.deque(), None, None
        self.first = True
        params = est.get_params(deep=True)
        # only a top-level generator (one stream of seeds) and a top-level thread count can be set per copy
        nested = [k for k in params if k.endswith("__random_state") or k.endswith("__n_jobs")]
        rs = params.get("random_state")
        self.parallel = (self.workers > 1 and "n_jobs" in params and not nested
                         and (rs is None or isinstance(rs, np.random.RandomState)) and "random_state" in params)

    def _copy(self, generator):
        """A shallow copy of the fitted descriptor drawing from ``generator``."""
        e = copy.copy(self.base)
        if generator is not None:
            e.set_params(random_state=generator)
        return e

    def _ahead(self, n):
        """A copy of the generator for a chunk of ``n`` clouds, and its state after them (the one generator
        moves on by the chunk's seeds)."""
        if self.generator is None:
            return None, None
        ahead = copy.deepcopy(self.generator)
        object_seeds(self.generator, n)
        return ahead, self.generator.get_state()

    @staticmethod
    def _transform(e, clouds, files, expected):
        try:
            rows = e.transform(clouds)
        except ValueError as exc:
            raise _name_files(exc, files) from None
        if expected is not None and not _same_state(e.random_state.get_state(), expected):
            raise RuntimeError(f"eppf describe: {type(e).__name__} drew seeds other than one per cloud; "
                               "run it with --n-jobs 1")
        return rows

    def submit(self, clouds, files, sink):
        """Describe one chunk (rows to ``sink`` now or with a later call, in order)."""
        if self.first:
            self.first = False
            if self.parallel:
                self.base = copy.copy(self.est)
                rs = self.est.get_params()["random_state"]
                self.generator = None if rs is None else copy.deepcopy(rs)
                ahead, expected = self._ahead(len(clouds))
                probe = self._copy(ahead)  # the descriptor's own n_jobs on this thread
                rows = self._transform(probe, clouds, files, None)
                if expected is None or _same_state(probe.random_state.get_state(), expected):
                    self.base.set_params(n_jobs=1)
                    self.pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="eppf-describe")
                else:  # not predicted: one chunk at a time, from where the probe's generator is
                    self.est.set_params(random_state=probe.random_state)
                    self.parallel = False
                sink(rows)
                return
        if not self.parallel:
            sink(self._transform(self.est, clouds, files, None))
            return
        ahead, expected = self._ahead(len(clouds))
        self.pending.append(self.pool.submit(self._transform, self._copy(ahead), clouds, files, expected))
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


def _same_state(a, b):
    """Whether two ``RandomState.get_state()`` tuples are the same state."""
    return a[0] == b[0] and np.array_equal(a[1], b[1]) and a[2:] == b[2:]


def _read_back(plan, fd, group):
    """Clouds and file names of the first pass's records ``(file, entry, offset, shape)``.

    Spilled clouds come from the temporary file (one read for the group's
    span); the others are read from their files again, as in the first pass,
    and a file that cannot be read again or gives another shape stops the
    command, naming it.
    """
    spilled = [r for r in group if r[2] >= 0]
    buf, start = None, 0
    if spilled:
        start = spilled[0][2]
        end = spilled[-1][2] + 8 * int(np.prod(spilled[-1][3]))
        buf = bytearray(end - start)
        view, got = memoryview(buf), 0
        while got < len(buf):  # pread may return fewer bytes than asked
            n = os.preadv(fd, [view[got:]], start + got)
            if n <= 0:
                raise OSError(f"eppf describe: the temporary file of the read clouds ended early "
                              f"({got} of {len(buf)} bytes)")
            got += n
    clouds = []
    for file, k, off, shape in group:
        if off >= 0:
            cloud = np.frombuffer(buf, dtype=np.float64, count=int(np.prod(shape)), offset=off - start).reshape(shape)
        else:
            try:
                cloud = plan.read(k)
            except (ValueError, OSError, KeyError) as exc:
                raise ValueError(f"{file} could not be read again for its descriptor (it changed while eppf "
                                 f"describe ran?): {exc}") from None
            if cloud.shape != shape:
                raise ValueError(f"{file} changed while eppf describe ran: {shape[0]} points in the first pass, "
                                 f"{cloud.shape[0]} now")
        clouds.append(cloud)
    return clouds, [r[0] for r in group]


register(Command(
    "describe", "compute descriptors of point cloud or mesh files, a folder or a .npz data set",
    "Compute descriptors of point clouds and save them to .npy (the matrix) or .npz (with object ids, labels and "
    "class names when the input has them, and the descriptor's parameters). Files and folders are streamed: "
    "read, described and written chunk by chunk, in memory that does not grow with the number of files.",
    add_arguments, run_describe,
))
