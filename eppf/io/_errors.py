"""The exception every reader of :mod:`eppf.io` raises for bad file content."""

__all__ = ["FileFormatError"]


class FileFormatError(ValueError):
    """A file's content is not a valid file of its format.

    Raised by :func:`~eppf.io.read_point_cloud` and :func:`~eppf.io.read_mesh`
    for empty, truncated or malformed files and for headers whose counts do
    not fit the file (checked before anything is allocated). The message
    names the file and, where known, the line (text formats) or the byte
    offset (binary formats). It subclasses :class:`ValueError`, so code that
    catches ``ValueError`` keeps working; a file that cannot be opened raises
    :class:`OSError` (``FileNotFoundError``, ``IsADirectoryError``,
    ``PermissionError``) instead.

    See Also
    --------
    read_point_cloud : Read a point cloud.
    read_mesh : Read a triangle mesh.

    Examples
    --------
    >>> import os, tempfile
    >>> from eppf.io import FileFormatError, read_mesh
    >>> path = os.path.join(tempfile.mkdtemp(), "bad.off")
    >>> with open(path, "w") as fh:
    ...     _ = fh.write("OFF\\n3 1 0\\n0 0 0\\n")
    >>> try:
    ...     read_mesh(path)
    ... except FileFormatError as exc:
    ...     print(str(exc).split(": ", 1)[1].split("' ", 1)[1])
    line 3: file ends after 1 of 3 vertices (truncated)
    """
