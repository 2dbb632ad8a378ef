"""Write a file so that it is either complete or not changed at all.

:func:`atomic_write` writes to a temporary file in the target's folder,
flushes it to disk and only then renames it over the target. A failure part
way (a full disk, an exception in the writer, Ctrl-C) removes the temporary
file and leaves any existing file under the target name as it was.
"""

import contextlib
import os
import tempfile

__all__ = ["atomic_write"]

# The opener of the temporary file; a module attribute so that tests can
# put a failing writer in its place.
_fdopen = os.fdopen


def _default_mode():
    """Permission bits a newly created file gets under the current umask."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_write(path, mode="wb", **open_kwargs):
    """Open a temporary file that replaces ``path`` when the block ends.

    Parameters
    ----------
    path : str or path-like
        The file to write. Its folder must exist.
    mode : {"wb", "w"}, default="wb"
        Binary or text mode.
    **open_kwargs
        Passed to :func:`open` for the temporary file (``newline``,
        ``encoding``...).

    Yields
    ------
    fh : file object
        The temporary file, opened in ``mode``.

    Notes
    -----
    On success the data are flushed and ``fsync``-ed, the file gets the
    permissions of the file it replaces (or the umask's default for a new
    file) and :func:`os.replace` moves it into place, which is atomic on
    POSIX and Windows when both names are on the same file system. On any
    exception, ``KeyboardInterrupt`` included, the temporary file is removed
    and the exception propagates; the old file is untouched.

    Examples
    --------
    >>> import os, tempfile
    >>> from eppf.utils._atomic import atomic_write
    >>> path = os.path.join(tempfile.mkdtemp(), "out.txt")
    >>> with atomic_write(path, "w") as fh:
    ...     _ = fh.write("complete")
    >>> open(path).read()
    'complete'
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write: mode must be 'wb' or 'w', got {mode!r}")
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"cannot write {path}: no such folder {folder}")
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp", dir=folder)
    fh = None
    try:
        fh = _fdopen(fd, mode, **open_kwargs)
        yield fh
        fh.flush()
        os.fsync(fh.fileno())
        fh.close()
        try:
            perms = os.stat(path).st_mode & 0o7777
        except FileNotFoundError:
            perms = _default_mode()
        os.chmod(tmp, perms)
        os.replace(tmp, path)
    except BaseException:
        if fh is not None:
            with contextlib.suppress(Exception):
                fh.close()
        else:
            with contextlib.suppress(OSError):
                os.close(fd)
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_folder(folder)


def _fsync_folder(folder):
    """Make the rename durable where the platform allows it (best effort)."""
    try:
        dir_fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dir_fd)
    except OSError:
        pass
    finally:
        os.close(dir_fd)
