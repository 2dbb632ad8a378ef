"""``eppf segment``: split a scan of a scene into its objects, one file per object and an index CSV.

The scene is read with every per-point field (:func:`eppf.io.read_point_fields`) and split by
:func:`eppf.segmentation.segment_scene`: the ground removed, the other points clustered (or split by an
integer field with ``--by``). What this module shares with ``eppf predict --segment``: the segmentation
options (:func:`add_segmentation`), reading and splitting a scene the one way (:func:`segment_file`), and
the segments' point clouds (:class:`Scene`).
"""

import hashlib
import os
import re
import secrets
import shutil
import socket
import stat
import sys
import time
from dataclasses import dataclass

import numpy as np

from ..io._common import NORMAL_NAME_SETS
from ..utils._atomic import atomic_write
from ._common import (SEGMENT_INDEX, SEGMENT_INDEX_HEADER, Command, add_runtime, count, positive_float,
                      positive_int, progress_of, register)

__all__ = ["run_segment"]

#: Formats that keep every field of a segment (:func:`eppf.io.write_point_fields`).
FIELD_FORMATS = ("las", "laz", "pcd", "ply")
#: Format of the segment files of a scene in another format (text, E57, NumPy): it keeps every field.
FALLBACK_FORMAT = "ply"


def add_segmentation(parser, prefix=""):
    """``--by``, ``--ground``, ``--tolerance``, ``--min-points`` and ``--max-points``: the same in ``eppf
    segment`` and ``eppf predict --segment`` (defaults None, resolved by :func:`segmentation_settings`, so
    that ``predict`` can tell whether one was given)."""
    from ..segmentation._scene import DEFAULT_MIN_POINTS, GROUND

    parser.add_argument("--by", metavar="FIELD", default=None,
                        help=f"{prefix}take the segments from an integer field of the file (instance, label, "
                             "classification, ...): one per value, no ground removed unless --ground says so")
    parser.add_argument("--ground", choices=GROUND, default=None,
                        help=f"{prefix}the ground removed before clustering: 'auto' (the default: a plane when one "
                             "fits, else a slope-limited lowest surface for terrain), 'plane' (a robust plane "
                             "fit), 'grid' (the lowest surface) or 'none'")
    parser.add_argument("--tolerance", type=positive_float, default=None, metavar="DISTANCE",
                        help=f"{prefix}clustering distance, in the file's units (meters for LiDAR): points closer "
                             "are one object; also the height above the ground under which points are ground "
                             "(default: five times the median distance between neighboring points)")
    parser.add_argument("--min-points", type=positive_int, default=None, metavar="N",
                        help=f"{prefix}smallest object kept; smaller clusters are left out as noise "
                             f"(default: {DEFAULT_MIN_POINTS})")
    parser.add_argument("--max-points", type=positive_int, default=None, metavar="N",
                        help=f"{prefix}largest object kept (default: no limit)")


def add_arguments(p):
    p.add_argument("scene", metavar="SCENE", help="a point cloud file of a scene (LAS, LAZ, E57, PCD, PLY, text "
                                                  "or NumPy; every extension of eppf.io.supported_extensions() "
                                                  "but meshes)")
    p.add_argument("-o", "--output", required=True, metavar="FOLDER",
                   help=f"a new or empty folder for one file per object and the index {SEGMENT_INDEX}; they "
                        "appear in it only when all are written (a run stopped midway leaves none)")
    add_segmentation(p)
    p.add_argument("--format", choices=FIELD_FORMATS, default=None,
                   help="format of the object files (default: the scene's when it is LAS, LAZ, PCD or PLY, "
                        f"else {FALLBACK_FORMAT.upper()}); every field of the scene is kept")
    add_runtime(p, n_jobs=False, random_state="seed of the RANSAC ground plane, the only thing it draws at "
                                               "random (default: 0)")


def segmentation_settings(args):
    """Keyword arguments of :func:`eppf.segmentation.segment_scene` from the options."""
    given = dict(by=args.by, ground=args.ground, tolerance=args.tolerance, min_points=args.min_points,
                 max_points=args.max_points, random_state=getattr(args, "random_state", None))
    return {name: value for name, value in given.items() if value is not None}  # segment_scene's defaults


def given_segmentation_options(args):
    """The segmentation options given on the command line (their names as typed)."""
    return [f"--{name.replace('_', '-')}" for name in ("by", "ground", "tolerance", "min_points", "max_points")
            if getattr(args, name, None) is not None]


def stage(cmd, text, progress):
    """A line on standard error about long work, unless ``--no-progress``."""
    if progress:
        print(f"{cmd}: {text}", file=sys.stderr, flush=True)


@dataclass
class Scene:
    """A scene read and split: its points, fields, labels, and its segments' points grouped."""

    path: str
    points: np.ndarray   # (n, 3) float64, the file's coordinates
    fields: dict         # name -> per-point array, as read_point_fields gives them
    labels: np.ndarray   # (n,) int64 segment of each point, -1 for ground and unassigned
    ground: np.ndarray   # (n,) bool
    tolerance: float     # the clustering distance used (None when none was needed)
    order: np.ndarray    # point indices sorted by segment (ground and unassigned left out)
    starts: np.ndarray   # (n_segments + 1,) boundaries of each segment in ``order``

    @property
    def n_segments(self):
        return len(self.starts) - 1

    def indices(self, k):
        """Indices of the points of segment ``k``, in the file's order."""
        return self.order[self.starts[k]:self.starts[k + 1]]

    def cloud(self, k):
        """The points of segment ``k``, with the scene's normals when it has them (as
        :func:`eppf.io.read_point_cloud` reads a file's normals)."""
        idx = self.indices(k)
        for names in NORMAL_NAME_SETS:  # (the readers' names: PCD/NumPy/LAS, PLY, E57)
            if all(n in self.fields and self.fields[n].ndim == 1 for n in names):
                normals = np.column_stack([self.fields[n][idx] for n in names]).astype(np.float64)
                return np.hstack([self.points[idx], normals])
        return self.points[idx]

    def centroid(self, k):
        return self.points[self.indices(k)].mean(axis=0)


def segment_file(path, settings, cmd, progress):
    """Read a scene with every field and split it: a :class:`Scene`.

    Errors of the segmentation (a field that does not exist, a scene too small) name the file.
    """
    from ..io import read_point_fields
    from ..segmentation import SceneSegmenter

    path = str(path)
    if os.path.isdir(path):
        raise ValueError(f"{path} is a folder; give the file of one scene")
    if not os.path.exists(path):
        raise FileNotFoundError(f"no such file: {path}")
    t0 = time.perf_counter()
    points, fields = read_point_fields(path)
    stage(cmd, f"read {count(len(points), 'point')} of {path} in {time.perf_counter() - t0:.1f} s; segmenting",
          progress)
    by = settings.get("by")
    if by is not None and by not in fields:
        have = ", ".join(fields) or "none"
        raise ValueError(f"--by {by}: {path} has no field {by!r} (its fields: {have})")
    keep = np.isfinite(points).all(axis=1)  # PCL's NaN points: no segment, no ground; kept in a labeled output
    if not keep.any():
        raise ValueError(f"{path}: no point has finite coordinates")
    t0 = time.perf_counter()
    seg = SceneSegmenter(**settings)
    sub_fields = fields if keep.all() else {k: v[keep] for k, v in fields.items()}
    try:
        seg.fit(points[keep], fields=sub_fields)
    except (ValueError, TypeError) as exc:
        raise type(exc)(f"{path}: {exc}") from None
    labels = np.full(len(points), -1, dtype=np.int64)
    ground = np.zeros(len(points), dtype=bool)
    labels[keep], ground[keep] = seg.labels_, seg.ground_mask_
    in_segment = np.flatnonzero(labels >= 0)
    order = in_segment[np.argsort(labels[in_segment], kind="stable")]
    sizes = np.bincount(labels[in_segment], minlength=seg.n_segments_)
    starts = np.concatenate([[0], np.cumsum(sizes)])
    scene = Scene(path, points, fields, labels, ground, seg.tolerance_, order, starts)
    stage(cmd, f"{count(scene.n_segments, 'segment')} in {time.perf_counter() - t0:.1f} s", progress)
    return scene


def summary(scene):
    """``"8 segments of 9,000 points (1,000 ground, 12 in no segment), tolerance 0.15"``."""
    n = len(scene.points)
    n_ground = int(scene.ground.sum())
    loose = n - n_ground - len(scene.order)
    tol = "" if scene.tolerance is None else f", tolerance {scene.tolerance:.4g}"
    return (f"{count(scene.n_segments, 'segment')} of {count(n, 'point')} ({n_ground} ground, {loose} in no "
            f"segment{tol})")


def coordinate(value):
    """A coordinate for a CSV: enough digits for millimeters at 1e7 (projected LiDAR coordinates)."""
    return format(float(value), ".12g")


#: What names a partial folder of ``eppf segment`` (:func:`_partial_folder`), inside an existing output folder or
#: after ``.<name of a new one>`` beside it.
PARTIAL_MARK = ".eppf-partial-"
#: The rest of its name: this machine (a hash of its host name), the process that writes it, a random part.
_PARTIAL_TAIL = re.compile(r"([0-9a-f]{8})-([0-9]+)-[0-9a-f]{8}")
#: Seconds without a change after which the partial folder of a process that is gone is removed.
STALE_AFTER = 120


def _host():
    return hashlib.blake2b(socket.gethostname().encode("utf-8", "surrogateescape"), digest_size=4).hexdigest()


def _is_stale_partial(path, tail):
    """True for a partial folder that no eppf process can be writing: named by :func:`_partial_folder` on this
    machine (``tail``, the name after :data:`PARTIAL_MARK`), by a process that no longer runs, a real folder of
    this user unchanged for :data:`STALE_AFTER` seconds. Anything else (another machine on a shared disk, a
    running or reused process id, a folder of an earlier eppf without the process id) is not, and is left
    alone."""
    match = _PARTIAL_TAIL.fullmatch(tail)
    if match is None or match.group(1) != _host() or os.name != "posix":
        return False  # (elsewhere, a signal 0 is not a harmless probe)
    pid = int(match.group(2))
    try:
        info = os.lstat(path)
    except OSError:
        return False
    if (pid == os.getpid() or not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid()
            or time.time() - info.st_mtime < STALE_AFTER):
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except (OSError, OverflowError):
        return False
    return False


def _remove_stale_partials(parent, prefix):
    """Remove the stale partial folders (:func:`_is_stale_partial`) named ``prefix`` + tail in ``parent``, left by
    a run that was killed outright (SIGKILL, a power cut: its own cleanup never ran); the names of the others
    with that prefix."""
    try:
        names = [n for n in os.listdir(parent) if n.startswith(prefix)]
    except OSError:
        return []
    left = []
    for name in names:
        path = os.path.join(parent, name)
        if not _is_stale_partial(path, name[len(prefix):]):
            left.append(name)
            continue
        try:
            shutil.rmtree(path)
        except OSError as exc:
            raise OSError(f"cannot remove {path}, the partial folder of an eppf segment run that was killed "
                          f"({exc.strerror or exc}); delete it") from None
    return left


def check_output_folder(folder):
    """A new or empty folder for the segment files (refused before any work).

    The partial folders that a killed run left (in the folder, or beside it for a new one) are removed when no
    eppf process can be writing them (:func:`_is_stale_partial`); a folder that holds only other partial
    folders is refused with their names, to delete when no ``eppf segment`` is writing into it.
    """
    folder = str(folder)
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise ValueError(f"--output {folder} is a file; give a new or empty folder")
    names = os.listdir(folder) if os.path.isdir(folder) else None
    if names:
        if any(not n.startswith(PARTIAL_MARK) for n in names):
            raise ValueError(f"--output {folder} is not empty; give a new or empty folder (the segment files of "
                             "another run would mix with these)")
        left = _remove_stale_partials(folder, PARTIAL_MARK)
        if left:
            raise ValueError(f"--output {folder} is not empty: it holds {', '.join(sorted(left))}, the partial "
                             f"folder{'s' if len(left) > 1 else ''} of an eppf segment run that was stopped or is "
                             "still running; if no eppf segment is writing into the folder, delete "
                             f"{'them' if len(left) > 1 else 'it'} and run again")
    elif names is None:
        # (beside a new folder they block nothing, but would stay there, hidden, for good)
        _remove_stale_partials(os.path.dirname(os.path.abspath(folder)), _beside_prefix(folder))
    parent = os.path.dirname(os.path.abspath(folder))
    if not os.path.isdir(parent):
        raise ValueError(f"--output {folder}: the folder {os.path.dirname(folder) or '.'} does not exist")
    where = folder if os.path.isdir(folder) else (os.path.dirname(folder) or ".")
    if not os.access(where, os.W_OK):  # (found now, not after the segmentation)
        raise ValueError(f"--output {folder}: the folder {where} is not writable")
    return folder


def output_format(scene_path, chosen):
    from ..io import format_of

    if chosen is not None:
        return chosen
    try:
        name = format_of(scene_path)
    except ValueError:
        name = None
    return name if name in FIELD_FORMATS else FALLBACK_FORMAT


def _beside_prefix(folder):
    """The start of the name of a partial folder beside the new ``folder``."""
    return f".{os.path.basename(os.path.normpath(os.path.abspath(folder)))}{PARTIAL_MARK}"


def _partial_folder(folder):
    """A new, empty, hidden folder on the file system of ``folder`` (its files are renamed into place at the
    end), made with the permissions a new folder gets: beside a new ``folder``, inside an existing one (which
    may be a mount point or a link to another file system). Its name says which machine and process write it,
    so that a later run can tell when it is stale (:func:`_is_stale_partial`)."""
    if os.path.isdir(folder):
        parent, prefix = folder, PARTIAL_MARK
    else:
        parent = os.path.dirname(os.path.abspath(folder))
        prefix = _beside_prefix(folder)
    while True:
        path = os.path.join(parent, f"{prefix}{_host()}-{os.getpid()}-{secrets.token_hex(4)}")
        try:
            os.mkdir(path)
        except FileExistsError:
            continue
        return path


def _write_segments(scene, folder, fmt, by, progress):
    """One file per segment and the index into ``folder``."""
    import csv

    from ..io import write_point_fields
    from ..utils import progress_bar

    width = max(3, len(str(max(scene.n_segments - 1, 0))))
    header = SEGMENT_INDEX_HEADER.split(",") + ([by] if by else [])
    rows = []
    for k in progress_bar(range(scene.n_segments), desc="writing", unit="obj", enabled=progress):
        idx = scene.indices(k)
        name = f"segment_{k:0{width}d}.{fmt}"
        write_point_fields(os.path.join(folder, name), scene.points[idx], {f: v[idx] for f, v in scene.fields.items()},
                           format=fmt)
        row = [k, name, len(idx), *map(coordinate, scene.centroid(k))]
        if by:
            row.append(scene.fields[by][idx[0]].item())
        rows.append(row)
    index = os.path.join(folder, SEGMENT_INDEX)
    with atomic_write(index, "w", newline="", encoding="utf-8", errors="surrogateescape") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        writer.writerows(rows)


def _publish(partial, folder):
    """The complete ``partial`` folder becomes ``folder``: renamed when ``folder`` does not exist; its files
    moved into ``folder`` (the index last) when that is an empty folder that was there before, which is kept."""
    if os.path.dirname(os.path.abspath(partial)) != os.path.abspath(folder):
        os.rename(partial, folder)
        return
    names = sorted(os.listdir(partial), key=lambda n: n == SEGMENT_INDEX)
    moved = []
    try:
        for name in names:
            os.replace(os.path.join(partial, name), os.path.join(folder, name))
            moved.append(name)
    except BaseException:
        for name in moved:  # this run's files only: the folder was empty
            try:
                os.remove(os.path.join(folder, name))
            except OSError:
                pass
        raise
    os.rmdir(partial)


def run_segment(args, out=None):
    """Run ``eppf segment``: split a scene into objects, one file each, with an index CSV.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf segment`` arguments.
    out : file-like, default=None
        Where the summary goes (standard output by default).

    Returns
    -------
    scene : Scene
        The scene, its labels and segments.
    """
    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf segment")
    progress = progress_of(args)
    folder = check_output_folder(args.output)
    fmt = output_format(args.scene, args.format)
    scene = segment_file(args.scene, segmentation_settings(args), cmd, progress)
    # The files go into a new hidden folder and reach the output only when complete: an error or a Ctrl-C
    # midway leaves no partial output (which would make the rerun refuse a folder that is not empty).
    partial = _partial_folder(folder)
    try:
        _write_segments(scene, partial, fmt, args.by, progress)
        _publish(partial, folder)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)  # this run's own folder: nothing that was there before
        raise
    index = os.path.join(folder, SEGMENT_INDEX)
    print(f"eppf: {summary(scene)} -> {count(scene.n_segments, fmt.upper() + ' file')} in {folder}, index "
          f"{index}", file=out)
    return scene


register(Command(
    "segment", "split a scan of a scene into objects: one file per object and an index CSV",
    "Split a scene (a LiDAR tile, a room scan) into objects the way PCL's cluster-recognition recipe does: remove "
    "the ground, then connect points closer than --tolerance (Euclidean clustering; clusters of --min-points to "
    "--max-points points are kept). With --by FIELD the segments come from an integer field of the file instead. "
    f"Each object is written with every field of the scene, in the file's coordinates, and {SEGMENT_INDEX} lists "
    "them: segment, file, n_points and the centroid x, y, z.",
    add_arguments, run_segment,
))
