"""Download helpers in the style of scikit-learn's ``fetch_*`` functions.

Files go to a data home folder (``$EPPF_DATA`` or ``~/eppf_data``). A download
is written to ``<name>.part``, resumed from where it stopped with an HTTP
``Range`` request, checked against its SHA-256, and only then moved to its
final name with an atomic rename, so a file under its final name is always
complete. Archives are extracted into a temporary folder that is renamed when
extraction has finished.
"""

import hashlib
import http.client
import os
import shutil
import socket
import tarfile
import tempfile
import urllib.error
import urllib.request
import warnings
import zipfile

__all__ = ["clear_data_home", "fetch_file", "fetch_modelnet", "get_data_home"]

MODELNET_URLS = {
    10: "http://3dvision.princeton.edu/projects/2014/3DShapeNets/ModelNet10.zip",
    40: "http://modelnet.cs.princeton.edu/ModelNet40.zip",
}

_CHUNK = 1 << 16


def get_data_home(data_home=None):
    """Return the folder where eppf keeps downloaded data, creating it.

    Parameters
    ----------
    data_home : str or path-like, default=None
        The folder. None means ``$EPPF_DATA`` if set, else ``~/eppf_data``.

    Returns
    -------
    data_home : str
        The folder's path, with ``~`` expanded.

    Examples
    --------
    >>> import tempfile
    >>> from eppf.datasets import get_data_home
    >>> home = get_data_home(tempfile.mkdtemp())
    """
    if data_home is None:
        data_home = os.environ.get("EPPF_DATA", os.path.join("~", "eppf_data"))
    data_home = os.path.expanduser(os.fspath(data_home))
    os.makedirs(data_home, exist_ok=True)
    return data_home


def clear_data_home(data_home=None):
    """Delete the data home folder and everything in it.

    Parameters
    ----------
    data_home : str or path-like, default=None
        The folder; see :func:`get_data_home`.

    Examples
    --------
    >>> import os
    >>> from eppf.datasets import clear_data_home, get_data_home
    >>> home = get_data_home("my_eppf_data")
    >>> os.path.isdir(home)
    True
    >>> clear_data_home(home)
    >>> os.path.isdir(home)
    False
    """
    shutil.rmtree(get_data_home(data_home))


def _sha256(path):
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _check_sha256(sha256, owner):
    if sha256 is None:
        return None
    text = str(sha256).lower()
    if len(text) != 64 or any(c not in "0123456789abcdef" for c in text):
        raise ValueError(f"{owner}: sha256 must be 64 hexadecimal digits, got {sha256!r}")
    return text


def _download(url, part, owner, timeout):
    """Fetch ``url`` into ``part``, resuming an existing partial file."""
    have = os.path.getsize(part) if os.path.exists(part) else 0
    request = urllib.request.Request(url, headers={"User-Agent": "eppf"})
    if have:
        request.add_header("Range", f"bytes={have}-")
    try:
        response = urllib.request.urlopen(request, timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and have:  # nothing left to fetch: the partial file is whole
            return
        raise OSError(f"{owner}: could not download {url}: HTTP {exc.code} {exc.reason}") from None
    except (urllib.error.URLError, socket.timeout, ConnectionError, http.client.HTTPException) as exc:
        reason = getattr(exc, "reason", exc)
        raise OSError(
            f"{owner}: could not download {url} ({reason}). Check the network connection (are you offline?), "
            f"or download the file by hand and place it at {part[:-5]!r}"
        ) from None
    with response:
        status = getattr(response, "status", 200)
        mode = "ab" if (have and status == 206) else "wb"
        start = have if mode == "ab" else 0
        length = response.headers.get("Content-Length")
        expected = start + int(length) if length is not None and length.isdigit() else None
        got = start
        try:
            with open(part, mode) as fh:
                while True:
                    block = response.read(_CHUNK)
                    if not block:
                        break
                    fh.write(block)
                    got += len(block)
        except (http.client.IncompleteRead, ConnectionError, socket.timeout, OSError) as exc:
            got = os.path.getsize(part)
            raise OSError(
                f"{owner}: download of {url} stopped after {got} of {expected if expected else '?'} bytes "
                f"({type(exc).__name__}); call again to resume from {part!r}"
            ) from None
    if expected is not None and got < expected:
        raise OSError(
            f"{owner}: download of {url} stopped after {got} of {expected} bytes (truncated); "
            f"call again to resume from {part!r}"
        )


def fetch_file(url, *, sha256=None, data_home=None, filename=None, download_if_missing=True, timeout=60):
    """Download a file once into the data home and return its path.

    Parameters
    ----------
    url : str
        Where to download from (``http``, ``https`` or ``file``).
    sha256 : str, default=None
        Expected SHA-256 of the file, 64 hexadecimal digits. When given, a
        file whose digest differs is deleted and reported. When None, the
        digest of the first download is recorded beside the file in
        ``<filename>.sha256`` and later calls check the file against it.
    data_home : str or path-like, default=None
        Folder to download into; see :func:`get_data_home`.
    filename : str, default=None
        Name of the file in ``data_home``; default: the last part of the URL.
    download_if_missing : bool, default=True
        If False and the file is absent, raise instead of downloading.
    timeout : float, default=60
        Seconds to wait for the server.

    Returns
    -------
    path : str
        The complete, verified file.

    Raises
    ------
    OSError
        If the download fails or stops early (offline, HTTP error, truncated
        transfer); a truncated transfer is kept and resumed by the next call.
    ValueError
        If the downloaded file does not match ``sha256`` (it is deleted).

    Examples
    --------
    >>> import os, pathlib, tempfile
    >>> from eppf.datasets import fetch_file
    >>> src = os.path.join(tempfile.mkdtemp(), "hello.txt")
    >>> _ = open(src, "w").write("hello")
    >>> path = fetch_file(pathlib.Path(src).as_uri(), data_home=tempfile.mkdtemp(),
    ...                   sha256="2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824")
    >>> open(path).read()
    'hello'
    """
    owner = "fetch_file"
    sha256 = _check_sha256(sha256, owner)
    if filename is None:
        filename = os.path.basename(url.split("?", 1)[0].rstrip("/")) or "download"
    if os.sep in filename or (os.altsep and os.altsep in filename) or filename in (".", ".."):
        raise ValueError(f"{owner}: filename must be a plain file name, got {filename!r}")
    home = get_data_home(data_home)
    target = os.path.join(home, filename)
    record = target + ".sha256"
    if os.path.exists(target):
        want = sha256
        if want is None and os.path.exists(record):
            with open(record) as fh:
                want = fh.read().strip()
        if want is None or _sha256(target) == want:
            return target
        warnings.warn(f"{owner}: {target!r} does not match its checksum; downloading it again", UserWarning, stacklevel=2)
        os.remove(target)
    if not download_if_missing:
        raise OSError(f"{owner}: {target!r} is missing and download_if_missing=False")
    part = target + ".part"
    _download(url, part, owner, timeout)
    digest = _sha256(part)
    if sha256 is not None and digest != sha256:
        os.remove(part)
        raise ValueError(
            f"{owner}: checksum mismatch for {url}: expected sha256 {sha256}, got {digest}; "
            "the corrupted download was deleted"
        )
    os.replace(part, target)
    if sha256 is None:
        tmp = record + ".tmp"
        with open(tmp, "w") as fh:
            fh.write(digest + "\n")
        os.replace(tmp, record)
    return target


def _extract(archive, folder, owner):
    """Extract a zip or tar archive into ``folder`` atomically and safely."""
    if os.path.isdir(folder):
        return folder
    parent = os.path.dirname(folder)
    tmp = tempfile.mkdtemp(prefix=".extract-", dir=parent)
    try:
        if zipfile.is_zipfile(archive):
            with zipfile.ZipFile(archive) as zf:
                root = os.path.realpath(tmp)
                for name in zf.namelist():
                    dest = os.path.realpath(os.path.join(tmp, name))
                    if dest != root and not dest.startswith(root + os.sep):
                        raise ValueError(f"{owner}: {archive!r} holds a path outside the archive: {name!r}")
                zf.extractall(tmp)
        elif tarfile.is_tarfile(archive):
            with tarfile.open(archive) as tf:
                tf.extractall(tmp, filter="data")
        else:
            raise ValueError(f"{owner}: {archive!r} is neither a zip nor a tar archive")
        os.replace(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def fetch_modelnet(version=40, *, data_home=None, url=None, sha256=None, download_if_missing=True, **load_kwargs):
    """Download Princeton's ModelNet archive once, then load it.

    Parameters
    ----------
    version : {40, 10}, default=40
        ModelNet40 (about 2 GB) or ModelNet10 (about 450 MB).
    data_home : str or path-like, default=None
        Folder to download into; see :func:`get_data_home`.
    url : str, default=None
        Mirror to download from; default: the official archive.
    sha256 : str, default=None
        Expected SHA-256 of the archive. Princeton publishes none, so by
        default the digest of the first download is recorded and checked on
        later calls (see :func:`fetch_file`).
    download_if_missing : bool, default=True
        If False and the data is absent, raise instead of downloading.
    **load_kwargs
        Passed to :func:`load_modelnet` (``subset``, ``n_points``, ...).

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch` or tuple
        What :func:`load_modelnet` returns.

    Examples
    --------
    The first call downloads the archive (ModelNet10: about 450 MB); later
    calls load the extracted folder:

    >>> from eppf.datasets import fetch_modelnet
    >>> train = fetch_modelnet(10, subset="train", n_points=1024)  # doctest: +SKIP

    Offline, ``download_if_missing=False`` fails with a clear error instead:

    >>> fetch_modelnet(10, data_home="empty_home", download_if_missing=False)
    Traceback (most recent call last):
    ...
    OSError: fetch_file: '...ModelNet10.zip' is missing and download_if_missing=False
    """
    owner = "fetch_modelnet"
    if version not in (10, 40) or isinstance(version, bool):
        raise ValueError(f"{owner}: version must be 40 or 10, got {version!r}")
    from ._loaders import load_modelnet

    home = get_data_home(data_home)
    folder = os.path.join(home, f"ModelNet{version}")
    if not os.path.isdir(folder):
        archive = fetch_file(url or MODELNET_URLS[version], sha256=sha256, data_home=home,
                             filename=f"ModelNet{version}.zip", download_if_missing=download_if_missing)
        extracted = _extract(archive, os.path.join(home, f".ModelNet{version}-extracted"), owner)
        inner = os.path.join(extracted, f"ModelNet{version}")
        os.replace(inner if os.path.isdir(inner) else extracted, folder)
        shutil.rmtree(extracted, ignore_errors=True)
    return load_modelnet(folder, version=version, **load_kwargs)
