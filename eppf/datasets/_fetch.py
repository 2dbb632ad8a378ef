"""Download helpers in the style of scikit-learn's ``fetch_*`` functions.

Files go to a data home folder (``$EPPF_DATA`` or ``~/eppf_data``). A download
is written to ``<name>.part`` and only moved to its final name, with an atomic
rename, once it is complete and its SHA-256 checked, so a file under its
final name is always whole.

An interrupted download is resumed only when that cannot mix two files: the
server's validator of the first response (a strong ``ETag``, else
``Last-Modified``) is kept beside the part in ``<name>.part.json`` and sent as
``If-Range``, and the rest is appended only if the server answers ``206`` with
a ``Content-Range`` starting at the part's size and the same validator. Any
other answer, or a part without a matching record, starts again from zero.

Only ``http``, ``https`` and ``file`` URLs are fetched (redirects too).
Archives are extracted into a temporary folder that is renamed when
extraction has finished; members that would land outside it (absolute paths,
``..``, links pointing out) and device files are refused.
"""

import hashlib
import http.client
import json
import os
import shutil
import socket
import tarfile
import tempfile
import urllib.error
import urllib.parse
import urllib.request
import warnings
import zipfile

from ..utils._param_validation import validate_parameter
from ..io._api import check_flag
from ._loaders import MODELNET_VERSION, check_path, load_modelnet

__all__ = ["clear_data_home", "fetch_file", "fetch_modelnet", "get_data_home"]

MODELNET_URLS = {
    10: "http://3dvision.princeton.edu/projects/2014/3DShapeNets/ModelNet10.zip",
    40: "http://modelnet.cs.princeton.edu/ModelNet40.zip",
}

#: SHA-256 digests of files eppf knows, by URL: :func:`fetch_file` checks a
#: download against them when no ``sha256`` is given. Princeton publishes none
#: for the ModelNet archives, so they are not listed; such downloads warn (see
#: :func:`fetch_file`). Add an entry only from a digest published by the
#: data's authors or computed from a copy known to be good.
KNOWN_SHA256 = {}

_SCHEMES = ("http", "https", "file")
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
    return _data_home(data_home, "get_data_home")


def _data_home(data_home, owner):
    """:func:`get_data_home` for ``owner``, whose name a bad ``data_home``'s error carries."""
    if data_home is None:
        data_home = os.environ.get("EPPF_DATA", os.path.join("~", "eppf_data"))
    data_home = os.path.expanduser(check_path(data_home, "data_home", owner))
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
    shutil.rmtree(_data_home(data_home, "clear_data_home"))


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


def _check_url(url, owner):
    if not isinstance(url, str):
        raise TypeError(f"{owner}: url must be a str, got {type(url).__name__}")
    scheme = urllib.parse.urlsplit(url).scheme.lower()
    if scheme not in _SCHEMES:
        raise ValueError(f"{owner}: only http, https and file URLs can be fetched, got {scheme or 'no'} scheme "
                         f"in {url!r}")
    return scheme


class _RedirectHandler(urllib.request.HTTPRedirectHandler):
    """Follow redirects to http and https only (urllib would also follow ftp)."""

    def redirect_request(self, req, fp, code, msg, headers, newurl):
        scheme = urllib.parse.urlsplit(newurl).scheme.lower()
        if scheme not in ("http", "https"):
            raise urllib.error.HTTPError(req.full_url, code, f"redirect to a {scheme or 'relative'} URL "
                                         f"refused: {newurl}", headers, fp)
        return super().redirect_request(req, fp, code, msg, headers, newurl)


_OPENER = urllib.request.build_opener(_RedirectHandler)


def _validator(headers):
    """The response's validator usable in ``If-Range``: a strong ETag, else Last-Modified."""
    etag = headers.get("ETag")
    if etag and not etag.startswith("W/"):
        return etag
    return headers.get("Last-Modified") or None


def _content_range(value):
    """``(start, total or None)`` of a ``Content-Range: bytes start-end/total`` header, or None."""
    if not value or not value.startswith("bytes "):
        return None
    span, _, total = value[6:].partition("/")
    first, _, last = span.partition("-")
    if not (first.strip().isdigit() and last.strip().isdigit()):
        return None
    return int(first), (int(total) if total.strip().isdigit() else None)


def _read_record(record, url):
    """The validator stored for ``url`` beside a partial download, or None."""
    try:
        with open(record) as fh:
            data = json.load(fh)
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("url") != url or not isinstance(data.get("validator"), str):
        return None
    return data["validator"]


def _write_record(record, url, validator):
    tmp = record + ".tmp"
    with open(tmp, "w") as fh:
        json.dump({"url": url, "validator": validator}, fh)
    os.replace(tmp, record)


def _discard(*paths):
    for path in paths:
        try:
            os.remove(path)
        except FileNotFoundError:
            pass


def _open(url, headers, owner, part, timeout):
    """The response for ``url``, or None for ``416 Range Not Satisfiable``."""
    request = urllib.request.Request(url, headers={"User-Agent": "eppf", **headers})
    try:
        return _OPENER.open(request, timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and "Range" in headers:
            exc.close()
            return None
        raise OSError(f"{owner}: could not download {url}: HTTP {exc.code} {exc.reason}") from None
    except (urllib.error.URLError, socket.timeout, ConnectionError, http.client.HTTPException) as exc:
        reason = getattr(exc, "reason", exc)
        raise OSError(
            f"{owner}: could not download {url} ({reason}). Check the network connection (are you offline?), "
            f"or download the file by hand and place it at {part[:-5]!r}"
        ) from None


def _download(url, part, owner, timeout):
    """Fetch ``url`` into ``part``, resuming it only when the server proves it is the same file."""
    record = part + ".json"
    scheme = urllib.parse.urlsplit(url).scheme.lower()
    have = os.path.getsize(part) if os.path.exists(part) else 0
    validator = _read_record(record, url) if have and scheme != "file" else None
    if have and validator is None:  # no proof of what the part holds: start again
        _discard(part, record)
        have = 0
    for _ in range(2):
        headers = {"Range": f"bytes={have}-", "If-Range": validator} if have else {}
        response = _open(url, headers, owner, part, timeout)
        if response is None:  # the server cannot serve the rest of this part
            _discard(part, record)
            have = 0
            continue
        status = getattr(response, "status", None) or 200
        span = _content_range(response.headers.get("Content-Range")) if status == 206 else None
        if status == 206 and (span is None or span[0] != have
                              or (have and _validator(response.headers) != validator)):
            # a range that does not continue this part (or a 206 nobody asked for): ask for the whole file
            response.close()
            _discard(part, record)
            if not have:
                raise OSError(f"{owner}: could not download {url}: the server sent a partial answer "
                              f"(Content-Range {response.headers.get('Content-Range')!r}) to a full request")
            have = 0
            continue
        if status not in (200, 206):
            response.close()
            raise OSError(f"{owner}: could not download {url}: unexpected HTTP status {status}")
        break
    else:
        raise OSError(f"{owner}: could not download {url}: the server's answers to a restarted download "
                      "were not usable")
    with response:
        resume = status == 206 and have > 0
        if not resume:
            have = 0
            _discard(record)
            new_validator = _validator(response.headers) if scheme != "file" else None
            if new_validator is not None:
                _write_record(record, url, new_validator)
        if status == 206 and span[1] is not None:
            expected = span[1]
        else:
            length = response.headers.get("Content-Length")
            expected = have + int(length) if length is not None and length.isdigit() else None
        got = have
        try:
            with open(part, "ab" if resume else "wb") as fh:
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
        digest listed for ``url`` in ``KNOWN_SHA256`` is used; for a URL
        without one, the first download cannot be verified: it is accepted
        with a ``UserWarning``, its digest is recorded beside the file in
        ``<filename>.sha256`` and later calls check the file against it.
    data_home : str or path-like, default=None
        Folder to download into; see :func:`get_data_home`.
    filename : str or path-like, default=None
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
        transfer); a truncated transfer is kept and resumed by the next call
        when the server supports it (see Notes).
    ValueError
        If the URL's scheme is not ``http``, ``https`` or ``file``, or the
        downloaded file does not match ``sha256`` (it is deleted).

    Warns
    -----
    UserWarning
        When a file is downloaded without a known digest (trust on first
        use), and when a cached file no longer matches its digest.

    Notes
    -----
    A partial download resumes only if the server identified the file with
    a strong ``ETag`` or a ``Last-Modified`` date (kept in
    ``<filename>.part.json``) and answers the ``Range`` + ``If-Range``
    request with ``206 Partial Content`` whose ``Content-Range`` starts at
    the part's size and whose validator is unchanged. Otherwise the download
    starts again from the first byte, so a stale part can never be joined
    to a different file.

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
    _check_url(url, owner)
    download_if_missing = check_flag(download_if_missing, "download_if_missing", owner)
    sha256 = _check_sha256(sha256, owner)
    if sha256 is None and url in KNOWN_SHA256:
        sha256 = _check_sha256(KNOWN_SHA256[url], owner)
    if filename is None:
        filename = os.path.basename(url.split("?", 1)[0].rstrip("/")) or "download"
    filename = check_path(filename, "filename", owner)
    if os.sep in filename or (os.altsep and os.altsep in filename) or filename in (".", ".."):
        raise ValueError(f"{owner}: filename must be a plain file name, got {filename!r}")
    home = _data_home(data_home, owner)
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
        _discard(part, part + ".json")
        raise ValueError(
            f"{owner}: checksum mismatch for {url}: expected sha256 {sha256}, got {digest}; "
            "the corrupted download was deleted"
        )
    os.replace(part, target)
    _discard(part + ".json")
    if sha256 is None:
        warnings.warn(
            f"{owner}: no SHA-256 is known for {url}; the download could not be verified, so its digest is "
            f"recorded in {record!r} and only later copies are checked against it. Pass sha256= to verify it",
            UserWarning, stacklevel=2)
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
                _extract_tar(tf, tmp, archive, owner)
        else:
            raise ValueError(f"{owner}: {archive!r} is neither a zip nor a tar archive")
        os.replace(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


#: Whether this Python's tarfile has extraction filters (3.10.12+, 3.11.4+, 3.12+).
_HAS_TAR_FILTER = hasattr(tarfile, "data_filter")


def _extract_tar(tf, folder, archive, owner):
    """Extract a tar archive with the "data" filter, or equivalent checks on older Pythons."""
    if _HAS_TAR_FILTER:
        try:
            tf.extractall(folder, filter="data")
        except tarfile.FilterError as exc:
            raise ValueError(f"{owner}: {archive!r} holds an unsafe member: {exc}") from None
        return
    root = os.path.realpath(folder)

    def inside(path):
        path = os.path.realpath(path)
        return path == root or path.startswith(root + os.sep)

    members = []
    for member in tf.getmembers():
        name = member.name
        if os.path.isabs(name) or name.startswith(("/", "\\")) or ".." in name.replace("\\", "/").split("/"):
            raise ValueError(f"{owner}: {archive!r} holds a path outside the archive: {name!r}")
        if not inside(os.path.join(folder, name)):
            raise ValueError(f"{owner}: {archive!r} holds a path outside the archive: {name!r}")
        if member.isdev() or not (member.isfile() or member.isdir() or member.issym() or member.islnk()):
            raise ValueError(f"{owner}: {archive!r} holds a device or special file: {name!r}")
        if member.issym() or member.islnk():
            target = member.linkname
            base = os.path.dirname(os.path.join(folder, name)) if member.issym() else folder
            # no ".." in targets: with it, a link through another link can climb out
            if os.path.isabs(target) or ".." in target.replace("\\", "/").split("/") \
                    or not inside(os.path.join(base, target)):
                raise ValueError(f"{owner}: {archive!r} holds a link pointing outside the archive: "
                                 f"{name!r} -> {target!r}")
        member.mode = (member.mode & 0o755) | (0o600 if member.isfile() else 0o700)  # no setuid, owner rw
        member.uid = member.gid = 0
        member.uname = member.gname = ""
        members.append(member)
    # the checks above replace the filter; on a Python that has filters (only
    # in tests) say so, which also keeps 3.12+ from warning about the default
    trusted = {"filter": "fully_trusted"} if hasattr(tarfile, "fully_trusted_filter") else {}
    tf.extractall(folder, members=members, numeric_owner=True, **trusted)


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
        default the first download is accepted with a ``UserWarning`` and its
        digest recorded and checked on later calls (see :func:`fetch_file`).
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
    validate_parameter(version, MODELNET_VERSION, name="version", owner=owner)
    download_if_missing = check_flag(download_if_missing, "download_if_missing", owner)
    home = _data_home(data_home, owner)
    folder = os.path.join(home, f"ModelNet{version}")
    if not os.path.isdir(folder):
        archive = fetch_file(url or MODELNET_URLS[version], sha256=sha256, data_home=home,
                             filename=f"ModelNet{version}.zip", download_if_missing=download_if_missing)
        extracted = _extract(archive, os.path.join(home, f".ModelNet{version}-extracted"), owner)
        inner = os.path.join(extracted, f"ModelNet{version}")
        os.replace(inner if os.path.isdir(inner) else extracted, folder)
        shutil.rmtree(extracted, ignore_errors=True)
    return load_modelnet(folder, version=version, **load_kwargs)
