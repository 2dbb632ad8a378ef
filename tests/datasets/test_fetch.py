"""Tests of the download helpers against a local HTTP server on 127.0.0.1."""

import hashlib
import http.server
import io
import json
import os
import re
import socket
import tarfile
import threading
import warnings
import zipfile

import pytest

from eppf.datasets import clear_data_home, fetch_file, fetch_modelnet, get_data_home

PAYLOAD = bytes(range(256)) * 64  # 16 KiB
SHA = hashlib.sha256(PAYLOAD).hexdigest()


class _Handler(http.server.BaseHTTPRequestHandler):
    """Serves ``server.files``.

    ``server.mode`` may truncate or corrupt; ``server.ranges`` says whether
    Range is honoured, ``server.if_range`` whether If-Range is checked,
    ``server.etag`` / ``server.last_modified`` give each file a validator
    ("strong", "weak" or None; True or None), ``server.range_offset`` makes
    a buggy server start its 206 answer elsewhere.
    """

    def log_message(self, *args):  # keep the test output quiet
        pass

    def _validators(self, data):
        srv, out = self.server, {}
        tag = hashlib.md5(data).hexdigest()
        if srv.etag == "strong":
            out["ETag"] = f'"{tag}"'
        elif srv.etag == "weak":
            out["ETag"] = f'W/"{tag}"'
        if srv.last_modified:
            out["Last-Modified"] = srv.last_modified_for.get(self.path, "Mon, 01 Jun 2026 10:00:00 GMT")
        return out

    def do_GET(self):
        srv = self.server
        srv.requests.append((self.path, self.headers.get("Range"), self.headers.get("If-Range")))
        if self.path in srv.redirects:
            self.send_response(302)
            self.send_header("Location", srv.redirects[self.path])
            self.end_headers()
            return
        data = srv.files.get(self.path)
        if data is None:
            self.send_error(404)
            return
        if srv.mode == "corrupt":
            data = data[:100] + b"X" + data[101:]
        validators = self._validators(data)
        start = 0
        rng = self.headers.get("Range")
        if_range = self.headers.get("If-Range")
        use_range = rng and srv.ranges and not (srv.if_range and if_range and if_range not in validators.values())
        if use_range:
            start = int(re.match(r"bytes=(\d+)-", rng).group(1))
            if start >= len(data):
                self.send_response(416)
                self.send_header("Content-Range", f"bytes */{len(data)}")
                self.end_headers()
                return
            start = max(0, start + srv.range_offset)
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        else:
            self.send_response(200)
        for key, value in validators.items():
            self.send_header(key, value)
        body = data[start:]
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        if srv.mode == "truncate":
            self.wfile.write(body[: len(body) // 3])
            self.wfile.flush()
            self.close_connection = True
            self.connection.shutdown(socket.SHUT_RDWR)
            return
        self.wfile.write(body)


@pytest.fixture
def server():
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    srv.files = {"/data.bin": PAYLOAD}
    srv.mode = "ok"
    srv.ranges = True
    srv.if_range = True
    srv.etag = "strong"
    srv.last_modified = False
    srv.last_modified_for = {}
    srv.range_offset = 0
    srv.redirects = {}
    srv.requests = []
    thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    srv.url = f"http://127.0.0.1:{srv.server_address[1]}"
    yield srv
    srv.shutdown()
    srv.server_close()


def test_fetch_file_downloads_verifies_and_caches(server, tmp_path):
    path = fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path)
    assert path == os.path.join(str(tmp_path), "data.bin")
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD
    assert not os.path.exists(path + ".part")
    n = len(server.requests)
    assert fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path) == path
    assert len(server.requests) == n  # served from the data home, no request


def test_fetch_file_checksum_mismatch_deletes(server, tmp_path):
    server.mode = "corrupt"
    with pytest.raises(ValueError, match=re.escape(f"fetch_file: checksum mismatch for {server.url}/data.bin: expected sha256 {SHA}")):
        fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path)
    assert os.listdir(tmp_path) == []


def _truncated_part(server, tmp_path):
    server.mode = "truncate"
    with pytest.raises(OSError, match=r"fetch_file: download of .*/data\.bin stopped after \d+ of 16384 bytes"):
        fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path)
    part = tmp_path / "data.bin.part"
    have = part.stat().st_size
    assert 0 < have < len(PAYLOAD)
    assert not (tmp_path / "data.bin").exists()  # never a partial file under the final name
    server.mode = "ok"
    return have


def _fetched(server, tmp_path, **kwargs):
    path = fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path, **kwargs)
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD
    assert sorted(os.listdir(tmp_path)) == ["data.bin"]  # no part, no record left behind
    return path


@pytest.mark.parametrize("etag, last_modified", [("strong", False), (None, True), ("weak", True)],
                         ids=["etag", "last-modified", "weak-etag-falls-back"])
def test_fetch_file_truncated_then_resumed_with_validator(server, tmp_path, etag, last_modified):
    server.etag, server.last_modified = etag, last_modified
    have = _truncated_part(server, tmp_path)
    record = json.loads((tmp_path / "data.bin.part.json").read_text())
    expected = f'"{hashlib.md5(PAYLOAD).hexdigest()}"' if etag == "strong" else "Mon, 01 Jun 2026 10:00:00 GMT"
    assert record["validator"] == expected
    _fetched(server, tmp_path)
    assert server.requests[-1][1:] == (f"bytes={have}-", expected)
    assert len(server.requests) == 2  # resumed, not restarted


@pytest.mark.parametrize("etag", [None, "weak"])
def test_fetch_file_without_usable_validator_restarts(server, tmp_path, etag):
    server.etag = etag
    _truncated_part(server, tmp_path)
    assert not (tmp_path / "data.bin.part.json").exists()
    _fetched(server, tmp_path)
    assert server.requests[-1][1] is None  # asked for the whole file again


def test_fetch_file_resume_without_range_support(server, tmp_path):
    _truncated_part(server, tmp_path)
    server.ranges = False  # the server answers 200 with the whole file
    _fetched(server, tmp_path)
    assert server.requests[-1][1] is not None and len(server.requests) == 2


OTHER = bytes(reversed(range(256))) * 400  # 100 KB of other content


@pytest.mark.parametrize("record", [False, True], ids=["no-record", "record-of-other-file"])
def test_stale_part_of_other_content_is_never_spliced(server, tmp_path, record):
    """A .part left by another file (40,000 bytes) and a server that honours Range."""
    server.files["/data.bin"] = PAYLOAD * 6  # 98,304 bytes now
    sha = hashlib.sha256(PAYLOAD * 6).hexdigest()
    (tmp_path / "data.bin.part").write_bytes(OTHER[:40_000])
    if record:  # a record from when the URL served OTHER; this server ignores If-Range
        (tmp_path / "data.bin.part.json").write_text(json.dumps(
            {"url": server.url + "/data.bin", "validator": f'"{hashlib.md5(OTHER).hexdigest()}"'}))
        server.if_range = False
    path = fetch_file(server.url + "/data.bin", sha256=sha, data_home=tmp_path)
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD * 6
    if record:  # it asked, saw another ETag on the 206, and started again
        assert [r[1] for r in server.requests] == ["bytes=40000-", None]
    else:
        assert [r[1] for r in server.requests] == [None]


def test_stale_part_with_unknown_digest_records_the_right_file(server, tmp_path):
    (tmp_path / "data.bin.part").write_bytes(OTHER[:4_000])
    with pytest.warns(UserWarning, match="no SHA-256 is known"):
        path = fetch_file(server.url + "/data.bin", data_home=tmp_path)
    assert (tmp_path / "data.bin.sha256").read_text().strip() == SHA
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD


def test_changed_file_with_if_range_server_restarts(server, tmp_path):
    have = _truncated_part(server, tmp_path)
    server.files["/data.bin"] = OTHER  # new content, new ETag: the server answers 200
    sha = hashlib.sha256(OTHER).hexdigest()
    path = fetch_file(server.url + "/data.bin", sha256=sha, data_home=tmp_path)
    with open(path, "rb") as fh:
        assert fh.read() == OTHER
    assert server.requests[-1][1] == f"bytes={have}-" and len(server.requests) == 2


def test_content_range_not_starting_at_the_part_restarts(server, tmp_path):
    _truncated_part(server, tmp_path)
    server.range_offset = -100  # a buggy server: overlapping bytes
    _fetched(server, tmp_path)
    assert server.requests[-1][1] is None and len(server.requests) == 3


def test_part_longer_than_the_file_restarts(server, tmp_path):
    (tmp_path / "data.bin.part").write_bytes(PAYLOAD + b"extra")
    (tmp_path / "data.bin.part.json").write_text(json.dumps(
        {"url": server.url + "/data.bin", "validator": f'"{hashlib.md5(PAYLOAD).hexdigest()}"'}))
    _fetched(server, tmp_path)  # 416, then the whole file
    assert [r[1] for r in server.requests] == [f"bytes={len(PAYLOAD) + 5}-", None]


def test_file_urls_never_resume(tmp_path):
    src = tmp_path / "src.bin"
    src.write_bytes(PAYLOAD)
    home = tmp_path / "home"
    home.mkdir()
    (home / "src.bin.part").write_bytes(OTHER[:1000])
    path = fetch_file(src.as_uri(), sha256=SHA, data_home=home)
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD


@pytest.mark.parametrize("url", ["data:text/plain;base64,aGVsbG8=", "ftp://127.0.0.1/x.zip", "x.zip",
                                 "javascript:alert(1)", "gopher://h/x"])
def test_only_http_https_and_file_urls(tmp_path, url):
    with pytest.raises(ValueError, match="only http, https and file URLs can be fetched"):
        fetch_file(url, data_home=tmp_path, filename="x")
    assert os.listdir(tmp_path) == []


def test_redirect_to_another_scheme_is_refused(server, tmp_path):
    server.redirects["/go"] = "ftp://127.0.0.1:9/data.bin"
    with pytest.raises(OSError, match="redirect to a ftp URL refused"):
        fetch_file(server.url + "/go", data_home=tmp_path, filename="data.bin")
    server.redirects["/go2"] = "/data.bin"  # a redirect within http is followed
    path = fetch_file(server.url + "/go2", sha256=SHA, data_home=tmp_path, filename="data.bin")
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD


def test_missing_digest_is_a_warning_known_digest_is_used(server, tmp_path, monkeypatch):
    import eppf.datasets._fetch as fetch_module

    with pytest.warns(UserWarning, match="no SHA-256 is known for .*data.bin"):
        fetch_file(server.url + "/data.bin", data_home=tmp_path / "a")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fetch_file(server.url + "/data.bin", data_home=tmp_path / "b", sha256=SHA)
    bad = "0" * 64
    monkeypatch.setitem(fetch_module.KNOWN_SHA256, server.url + "/data.bin", bad)
    with pytest.raises(ValueError, match=f"expected sha256 {bad}"):
        fetch_file(server.url + "/data.bin", data_home=tmp_path / "c")


def test_fetch_file_records_digest_without_sha(server, tmp_path):
    with pytest.warns(UserWarning, match="no SHA-256 is known"):
        path = fetch_file(server.url + "/data.bin", data_home=tmp_path)
    with open(path + ".sha256") as fh:
        assert fh.read().strip() == SHA
    with open(path, "r+b") as fh:  # local corruption is detected and repaired
        fh.write(b"garbage")
    with pytest.warns(UserWarning, match="does not match its checksum; downloading it again"):
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*no SHA-256 is known")
            fetch_file(server.url + "/data.bin", data_home=tmp_path)
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD


def test_fetch_file_offline_and_http_errors(server, tmp_path):
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()  # nothing listens on this port now
    with pytest.raises(OSError, match=re.escape(f"fetch_file: could not download http://127.0.0.1:{port}/x.zip")) as info:
        fetch_file(f"http://127.0.0.1:{port}/x.zip", data_home=tmp_path, timeout=5)
    assert "are you offline?" in str(info.value)
    with pytest.raises(OSError, match="HTTP 404"):
        fetch_file(server.url + "/missing.bin", data_home=tmp_path)
    with pytest.raises(OSError, match="is missing and download_if_missing=False"):
        fetch_file(server.url + "/data.bin", data_home=tmp_path, download_if_missing=False)


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        ({"sha256": "abc"}, "fetch_file: sha256 must be 64 hexadecimal digits, got 'abc'"),
        ({"filename": "../evil"}, "fetch_file: filename must be a plain file name, got '../evil'"),
    ],
)
def test_fetch_file_parameter_errors(tmp_path, kwargs, msg):
    with pytest.raises(ValueError, match=re.escape(msg)):
        fetch_file("http://127.0.0.1:9/x", data_home=tmp_path, **kwargs)


def _modelnet_zip():
    off = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for cls in ("chair", "bed"):
            for split in ("train", "test"):
                zf.writestr(f"ModelNet10/{cls}/{split}/{cls}_0001.off", off)
        zf.writestr("__MACOSX/ModelNet10/._chair", "")
    return buf.getvalue()


def test_fetch_modelnet_from_local_server(server, tmp_path):
    archive = _modelnet_zip()
    server.files["/ModelNet10.zip"] = archive
    sha = hashlib.sha256(archive).hexdigest()
    data = fetch_modelnet(10, data_home=tmp_path, url=server.url + "/ModelNet10.zip", sha256=sha, n_points=32)
    assert data.target_names.tolist() == ["bed", "chair"] and len(data.data) == 4
    assert os.path.isdir(tmp_path / "ModelNet10" / "chair" / "train")
    n = len(server.requests)
    again = fetch_modelnet(10, data_home=tmp_path, url=server.url + "/ModelNet10.zip", sha256=sha, n_points=32)
    assert len(server.requests) == n and len(again.data) == 4
    with pytest.raises(ValueError, match="fetch_modelnet: version must be 40 or 10"):
        fetch_modelnet(20, data_home=tmp_path)


def test_fetch_modelnet_rejects_path_traversal(server, tmp_path):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("../escape.txt", "x")
    server.files["/ModelNet40.zip"] = buf.getvalue()
    with pytest.raises(ValueError, match="holds a path outside the archive"), \
            pytest.warns(UserWarning, match="no SHA-256 is known"):
        fetch_modelnet(40, data_home=tmp_path / "home", url=server.url + "/ModelNet40.zip")
    assert not (tmp_path / "escape.txt").exists()


def test_data_home(tmp_path, monkeypatch):
    monkeypatch.setenv("EPPF_DATA", str(tmp_path / "env_home"))
    assert get_data_home() == str(tmp_path / "env_home") and os.path.isdir(tmp_path / "env_home")
    (tmp_path / "env_home" / "f").write_text("x")
    clear_data_home()
    assert not (tmp_path / "env_home").exists()


# ---------------------------------------------------------------- tar archives
def _tar(tmp_path, add):
    path = tmp_path / "a.tar"
    with tarfile.open(path, "w") as tf:
        add(tf)
    return str(path)


def _member(tf, name, data=b"x", **attrs):
    info = tarfile.TarInfo(name)
    for key, value in attrs.items():
        setattr(info, key, value)
    if info.isfile():
        info.size = len(data)
        tf.addfile(info, io.BytesIO(data))
    else:
        tf.addfile(info)


UNSAFE_TARS = {
    "dotdot": lambda tf: _member(tf, "ok/../../escape.txt"),
    "symlink-out": lambda tf: _member(tf, "link", type=tarfile.SYMTYPE, linkname="/etc"),
    "symlink-up": lambda tf: _member(tf, "link", type=tarfile.SYMTYPE, linkname="../.."),
    "hardlink-out": lambda tf: _member(tf, "hard", type=tarfile.LNKTYPE, linkname="/etc/passwd"),
    "device": lambda tf: _member(tf, "dev", type=tarfile.CHRTYPE, devmajor=1, devminor=3),
    "fifo": lambda tf: _member(tf, "fifo", type=tarfile.FIFOTYPE),
}


@pytest.mark.parametrize("has_filter", [True, False], ids=["data-filter", "own-checks"])
@pytest.mark.parametrize("kind", sorted(UNSAFE_TARS))
def test_unsafe_tar_members_are_refused(tmp_path, monkeypatch, has_filter, kind):
    import eppf.datasets._fetch as fetch_module

    if has_filter and not fetch_module._HAS_TAR_FILTER:
        pytest.skip("this Python's tarfile has no extraction filters")
    monkeypatch.setattr(fetch_module, "_HAS_TAR_FILTER", has_filter)
    archive = _tar(tmp_path, UNSAFE_TARS[kind])
    home = tmp_path / "home"
    home.mkdir()
    with pytest.raises(ValueError, match=re.escape(archive)):
        fetch_module._extract(archive, str(home / "out"), "fetch_test")
    assert os.listdir(home) == []  # the temporary folder is gone too
    assert not (tmp_path / "escape.txt").exists()


@pytest.mark.parametrize("has_filter", [True, False], ids=["data-filter", "own-checks"])
def test_safe_tar_extracts_with_inner_links(tmp_path, monkeypatch, has_filter):
    import eppf.datasets._fetch as fetch_module

    if has_filter and not fetch_module._HAS_TAR_FILTER:
        pytest.skip("this Python's tarfile has no extraction filters")
    monkeypatch.setattr(fetch_module, "_HAS_TAR_FILTER", has_filter)

    def add(tf):
        _member(tf, "d", type=tarfile.DIRTYPE, mode=0o755)
        _member(tf, "d/a.off", b"OFF\n", mode=0o4755)  # setuid bit: dropped
        _member(tf, "d/b.off", type=tarfile.SYMTYPE, linkname="a.off")

    out = fetch_module._extract(_tar(tmp_path, add), str(tmp_path / "out"), "fetch_test")
    assert open(os.path.join(out, "d", "b.off")).read() == "OFF\n"
    assert not os.stat(os.path.join(out, "d", "a.off")).st_mode & 0o4000
