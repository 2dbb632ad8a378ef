"""Tests of the download helpers against a local HTTP server on 127.0.0.1."""

import hashlib
import http.server
import io
import os
import re
import socket
import threading
import zipfile

import pytest

from eppf.datasets import clear_data_home, fetch_file, fetch_modelnet, get_data_home

PAYLOAD = bytes(range(256)) * 64  # 16 KiB
SHA = hashlib.sha256(PAYLOAD).hexdigest()


class _Handler(http.server.BaseHTTPRequestHandler):
    """Serves ``server.files``; ``server.mode`` may truncate or corrupt."""

    def log_message(self, *args):  # keep the test output quiet
        pass

    def do_GET(self):
        srv = self.server
        srv.requests.append((self.path, self.headers.get("Range")))
        data = srv.files.get(self.path)
        if data is None:
            self.send_error(404)
            return
        if srv.mode == "corrupt":
            data = data[:100] + b"X" + data[101:]
        start = 0
        rng = self.headers.get("Range")
        if rng and srv.ranges:
            start = int(re.match(r"bytes=(\d+)-", rng).group(1))
            if start >= len(data):
                self.send_response(416)
                self.end_headers()
                return
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        else:
            self.send_response(200)
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


def test_fetch_file_truncated_then_resumed(server, tmp_path):
    server.mode = "truncate"
    with pytest.raises(OSError, match=r"fetch_file: download of .*/data\.bin stopped after \d+ of 16384 bytes"):
        fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path)
    part = tmp_path / "data.bin.part"
    have = part.stat().st_size
    assert 0 < have < len(PAYLOAD)
    assert not (tmp_path / "data.bin").exists()  # never a partial file under the final name
    server.mode = "ok"
    path = fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path)
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD
    assert server.requests[-1][1] == f"bytes={have}-"


def test_fetch_file_resume_without_range_support(server, tmp_path):
    server.mode = "truncate"
    with pytest.raises(OSError, match="stopped after"):
        fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path)
    server.mode, server.ranges = "ok", False  # the server answers 200 with the whole file
    path = fetch_file(server.url + "/data.bin", sha256=SHA, data_home=tmp_path)
    with open(path, "rb") as fh:
        assert fh.read() == PAYLOAD


def test_fetch_file_records_digest_without_sha(server, tmp_path):
    path = fetch_file(server.url + "/data.bin", data_home=tmp_path)
    with open(path + ".sha256") as fh:
        assert fh.read().strip() == SHA
    with open(path, "r+b") as fh:  # local corruption is detected and repaired
        fh.write(b"garbage")
    with pytest.warns(UserWarning, match="does not match its checksum; downloading it again"):
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
    with pytest.raises(ValueError, match="holds a path outside the archive"):
        fetch_modelnet(40, data_home=tmp_path / "home", url=server.url + "/ModelNet40.zip")
    assert not (tmp_path / "escape.txt").exists()


def test_data_home(tmp_path, monkeypatch):
    monkeypatch.setenv("EPPF_DATA", str(tmp_path / "env_home"))
    assert get_data_home() == str(tmp_path / "env_home") and os.path.isdir(tmp_path / "env_home")
    (tmp_path / "env_home" / "f").write_text("x")
    clear_data_home()
    assert not (tmp_path / "env_home").exists()
