"""Fuzz the file readers of eppf.io with mutated files.

Usage::

    python scripts/fuzz_files.py                 # about 3,000 files
    python scripts/fuzz_files.py --short         # about 200 files, a few seconds (run by the test suite)
    python scripts/fuzz_files.py --n-files 10000 --seed 3 --keep failures/

Valid files of every format are written first (PCD ``ascii``, ``binary`` and
``binary_compressed``; PLY ASCII and binary, cloud and mesh; OFF; OBJ; STL
ASCII and binary; XYZ, PTS; NPY; NPZ; and, when laspy and pye57 are
installed, LAS with extra bytes, LAZ 1.2 (point-wise chunks) and 1.4 (layered
chunks), and E57 with two scans), then mutated
with a fixed seed: bit flips, truncations, a number of the header set to 0,
-1, a huge value, 1e308 or NaN, a duplicated or removed line, runs of random
bytes (overwritten or inserted), and a binary header field (1, 2, 4 or 8
bytes in the first 400, where LAS, LAZ and E57 keep their counts, offsets,
VLR lengths and extra-bytes descriptors) set to 0, all ones, a power of two or
random bytes. An E57 mutant gets its pages' CRC-32C checksums recomputed half
of the time, so that libE57Format parses the hostile content instead of
refusing a bad checksum. Each mutant is read with
:func:`eppf.io.read_point_cloud` and :func:`eppf.io.read_point_fields` (and
:func:`eppf.io.read_mesh` for mesh formats) in a forked child limited to 4 GiB of address space
(``RLIMIT_AS``) and a per-file timeout. Outcomes:

- ``ok``: the file was read;
- ``documented``: a ``FileFormatError`` or an ``OSError`` whose message names
  the file (or, for an optional package that is missing, an ``ImportError``
  naming it);
- ``FAIL``: the child died of a signal, hung past the timeout, raised another
  exception type, raised an error that does not name the file, or its peak
  resident memory (``getrusage``) grew by more than 300 MB.

A table per format is printed; the exit status is 1 if anything failed.
"""

import argparse
import faulthandler
import io
import json
import os
import re
import resource
import select
import signal
import struct
import sys
import tempfile
import time
import zipfile

import numpy as np

ADDRESS_SPACE = 4 << 30
RSS_LIMIT_MB = 300
NUMBERS = [b"0", b"-1", b"999999999999", b"18446744073709551616", b"1e308", b"nan", b"-inf", b"2147483648", b"1"]


# --------------------------------------------------------------------------- valid seed files


def _lzf_compress(data):
    """A greedy LZF encoder (literal runs and back references), enough to write valid PCD blocks."""
    out, lit, table, i, n = bytearray(), bytearray(), {}, 0, len(data)

    def flush():
        for k in range(0, len(lit), 32):
            chunk = lit[k:k + 32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
        lit.clear()

    while i < n:
        key = bytes(data[i:i + 3])
        ref = table.get(key)
        table[key] = i
        if ref is not None and len(key) == 3 and i - ref - 1 < 8192:
            length = 3
            while i + length < n and length < 264 and data[ref + length] == data[i + length]:
                length += 1
            flush()
            off = i - ref - 1
            if length - 2 < 7:
                out.append(((length - 2) << 5) | (off >> 8))
            else:
                out += bytes([(7 << 5) | (off >> 8), length - 2 - 7])
            out.append(off & 0xFF)
            i += length
        else:
            lit.append(data[i])
            i += 1
    flush()
    return bytes(out)


def seed_files(folder, rng):
    """Write one valid file per format variant; returns {variant: path}."""
    from eppf.io import write_mesh, write_point_cloud

    n = 24
    xyz = np.round(rng.normal(size=(n, 3)), 2)
    nrm = rng.normal(size=(n, 3))
    cloud = np.hstack([xyz, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)])
    v = rng.normal(size=(10, 3))
    f = np.array([[0, 1, 2], [1, 2, 3], [3, 4, 5], [5, 6, 7], [7, 8, 9], [9, 0, 4]])
    quads = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    paths = {}

    def put(name, writer, *args, **kwargs):
        path = os.path.join(folder, name)
        writer(path, *args, **kwargs)
        paths[name] = path

    put("ascii.pcd", write_point_cloud, cloud, binary=False)
    put("binary.pcd", write_point_cloud, cloud, binary=True)
    raw = b"".join(np.ascontiguousarray(cloud[:, k], dtype="<f4").tobytes() for k in range(6))
    comp = _lzf_compress(raw)
    head = (f"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z normal_x normal_y normal_z\nSIZE 4 4 4 4 4 4\n"
            f"TYPE F F F F F F\nCOUNT 1 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
            "DATA binary_compressed\n")
    path = os.path.join(folder, "compressed.pcd")
    with open(path, "wb") as fh:
        fh.write(head.encode() + struct.pack("<II", len(comp), len(raw)) + comp)
    paths["compressed.pcd"] = path
    put("cloud_ascii.ply", write_point_cloud, cloud, binary=False)
    put("cloud_binary.ply", write_point_cloud, cloud, binary=True)
    put("mesh_ascii.ply", write_mesh, v, quads, binary=False)
    put("mesh_binary.ply", write_mesh, v, f, binary=True)
    put("mesh.off", write_mesh, v, f)
    path = os.path.join(folder, "modelnet.off")
    with open(path, "w") as fh:
        fh.write(f"OFF{len(v)} {len(quads)} 0\n" + "".join(f"{a:.6g} {b:.6g} {c:.6g}\n" for a, b, c in v)
                 + "".join("4 " + " ".join(map(str, q)) + "\n" for q in quads))
    paths["modelnet.off"] = path
    put("mesh.obj", write_mesh, v, quads)
    put("ascii.stl", write_mesh, v, f, binary=False)
    put("binary.stl", write_mesh, v, f, binary=True)
    put("cloud.xyz", write_point_cloud, cloud)
    path = os.path.join(folder, "count.pts")
    with open(path, "w") as fh:
        fh.write(f"{n}\n" + "".join(f"{a} {b} {c} 0.5 10 20 30\n" for a, b, c in xyz))
    paths["count.pts"] = path
    put("cloud.npy", write_point_cloud, cloud)
    put("cloud.npz", write_point_cloud, cloud)
    path = os.path.join(folder, "deflated.npz")
    buf = io.BytesIO()
    np.save(buf, cloud)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("points.npy", buf.getvalue())
    paths["deflated.npz"] = path
    paths.update(_optional_seeds(folder, xyz, rng))
    return paths


def _optional_seeds(folder, xyz, rng):
    """LAS, LAZ and E57 seed files, when laspy and pye57 are installed."""
    paths = {}
    try:
        import laspy
    except ImportError:
        laspy = None
    if laspy is not None:
        n = xyz.shape[0]
        for name, fmt, version in (("extra.las", 3, "1.2"), ("tile.laz", 6, "1.4"), ("pointwise.laz", 1, "1.2")):
            header = laspy.LasHeader(point_format=fmt, version=version)
            header.offsets, header.scales = np.array([5e5, 4e6, 0.0]), np.array([0.01, 0.01, 0.01])
            if name.endswith(".las"):
                header.add_extra_dims([laspy.ExtraBytesParams("reflectance", "f4"),
                                       laspy.ExtraBytesParams("normal", "3f8")])
            las = laspy.LasData(header)
            las.x, las.y, las.z = xyz[:, 0] + 5e5, xyz[:, 1] + 4e6, xyz[:, 2]
            las.classification = rng.randint(0, 20, size=n)
            las.intensity = rng.randint(0, 1000, size=n)
            if name.endswith(".las"):
                las.reflectance = rng.normal(size=n).astype("f4")
                las.normal = rng.normal(size=(n, 3))
            path = os.path.join(folder, name)
            # the single-threaded backend: lazrs's parallel one would start a thread pool that the forks lack
            las.write(path, laz_backend=laspy.LazBackend.Lazrs if name.endswith(".laz") else None)
            paths[name] = path
    try:
        import pye57
    except ImportError:
        return paths
    path = os.path.join(folder, "scans.e57")
    with pye57.E57(path, mode="w") as e57:
        for k in range(2):
            e57.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1], "cartesianZ": xyz[:, 2] + k,
                                "intensity": np.linspace(0, 1, len(xyz))}, translation=np.array([k, 0.0, 0.0]))
    paths["scans.e57"] = path
    return paths


def _crc32c_table():
    table = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
        table.append(c)
    return table


_CRC32C = _crc32c_table()


def e57_fix_checksums(data):
    """Recompute the big-endian CRC-32C at the end of every 1,024-byte E57 page."""
    b = bytearray(data)
    for start in range(0, len(b) - 1023, 1024):
        c = 0xFFFFFFFF
        for x in b[start:start + 1020]:
            c = _CRC32C[(c ^ x) & 0xFF] ^ (c >> 8)
        b[start + 1020:start + 1024] = struct.pack(">I", c ^ 0xFFFFFFFF)
    return bytes(b)


# --------------------------------------------------------------------------- mutations


def _header_end(data):
    for marker in (b"end_header\n", b"\nDATA ", b"}\n"):
        k = data.find(marker)
        if k >= 0:
            return min(len(data), k + len(marker) + 40)
    return min(len(data), 200)


def mutate(data, rng):
    """One random mutation of ``data``: (kind, mutated bytes)."""
    kind = ["flip", "truncate", "number", "number", "dup_line", "drop_line", "random_run", "insert", "flip_many",
            "binary_field"][rng.randint(10)]
    b = bytearray(data)
    if kind == "binary_field":
        width = [1, 2, 4, 8][rng.randint(4)]
        k = rng.randint(max(1, min(len(b), 400) - width + 1))
        value = [b"\0" * width, b"\xff" * width, (1 << (8 * width - 1)).to_bytes(width, "little"),
                 rng.randint(0, 256, size=width, dtype=np.uint8).tobytes()][rng.randint(4)]
        b[k:k + width] = value[:max(0, len(b) - k)]
    elif kind in ("flip", "flip_many"):
        for _ in range(1 if kind == "flip" else rng.randint(2, 30)):
            k = rng.randint(len(b))
            b[k] ^= 1 << rng.randint(8)
    elif kind == "truncate":
        b = b[:rng.randint(len(b))]
    elif kind == "number":
        head = bytes(b[:_header_end(data)])
        spans = [m.span() for m in re.finditer(rb"-?\d+(\.\d+)?(e[-+]?\d+)?", head)]
        if not spans:
            return mutate(data, rng)
        s, e = spans[rng.randint(len(spans))]
        b[s:e] = NUMBERS[rng.randint(len(NUMBERS))]
    elif kind in ("dup_line", "drop_line"):
        lines = bytes(b).split(b"\n")
        k = rng.randint(len(lines))
        if kind == "dup_line":
            lines.insert(k, lines[k])
        else:
            del lines[k]
        b = bytearray(b"\n".join(lines))
    elif kind == "random_run":
        k = rng.randint(len(b))
        run = rng.randint(0, 256, size=rng.randint(1, 64), dtype=np.uint8).tobytes()
        b[k:k + len(run)] = run
    else:
        k = rng.randint(len(b) + 1)
        b[k:k] = rng.randint(0, 256, size=rng.randint(1, 64), dtype=np.uint8).tobytes()
    return kind, bytes(b)


# --------------------------------------------------------------------------- reading in a child


def _child(path, write_fd):
    """Read ``path`` under the limits; report the outcome on ``write_fd`` and exit."""
    outcome = {"cls": "ok", "why": ""}
    try:
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))
        import eppf.io
        from eppf.io import FileFormatError, read_mesh, read_point_fields, supported_extensions

        base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        ext = os.path.splitext(path)[1].lower()
        readers = [eppf.io.read_point_cloud] + ([read_mesh] if ext in supported_extensions("mesh") else []) + \
            ([read_point_fields] if ext in supported_extensions("cloud") else [])
        for reader in readers:
            try:
                reader(path)
            except (FileFormatError, OSError, ImportError) as exc:
                if os.path.basename(path) not in str(exc):
                    outcome = {"cls": "FAIL", "why": f"{reader.__name__}: error does not name the file: {exc}"}
                    break
                outcome = {"cls": "documented", "why": f"{type(exc).__name__}: {str(exc)[:200]}"}
            except BaseException as exc:  # noqa: BLE001 - anything else is a failure
                outcome = {"cls": "FAIL", "why": f"{reader.__name__}: {type(exc).__name__}: {str(exc)[:300]}"}
                break
        grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024
        if grown > RSS_LIMIT_MB and outcome["cls"] != "FAIL":
            outcome = {"cls": "FAIL", "why": f"peak RSS grew by {grown:.0f} MB"}
    except BaseException as exc:  # noqa: BLE001
        outcome = {"cls": "FAIL", "why": f"harness: {type(exc).__name__}: {exc}"}
    os.write(write_fd, json.dumps(outcome).encode())
    os.close(write_fd)
    os._exit(0)


def read_in_child(path, timeout):
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        os.close(r)
        # a crash is an outcome the parent reports ("killed by signal ..."): no
        # fault handler's traceback (pytest's, inherited by the fork) on stderr
        faulthandler.disable()
        _child(path, w)
    os.close(w)
    chunks, deadline = [], time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        ready, _, _ = select.select([r], [], [], max(left, 0))
        if not ready:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(r)
            return {"cls": "FAIL", "why": f"hang: no result after {timeout:.0f} s"}
        chunk = os.read(r, 65536)
        if not chunk:
            break
        chunks.append(chunk)
    os.close(r)
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        return {"cls": "FAIL", "why": f"killed by signal {signal.Signals(os.WTERMSIG(status)).name}"}
    try:
        return json.loads(b"".join(chunks))
    except ValueError:
        return {"cls": "FAIL", "why": f"child exited with status {os.WEXITSTATUS(status)} and no result"}


# --------------------------------------------------------------------------- main


def _read(path):
    with open(path, "rb") as fh:  # (closed here: an open file left to the collector warns under -W error)
        return fh.read()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n-files", type=int, default=3000, help="mutated files in all (default 3000)")
    parser.add_argument("--short", action="store_true", help="about 200 files (the test suite's run)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds per file")
    parser.add_argument("--keep", default=None, help="folder to copy failing files into")
    args = parser.parse_args(argv)
    n_files = 200 if args.short else args.n_files
    rng = np.random.RandomState(args.seed)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import eppf.io  # noqa: F401 - imported once here, shared by the forked children

    started = time.monotonic()
    table, failures = {}, []
    with tempfile.TemporaryDirectory() as tmp:
        seeds = seed_files(tmp, rng)
        names = sorted(seeds)
        originals = {name: _read(path) for name, path in seeds.items()}
        # the valid files themselves must read
        for name in names:
            result = read_in_child(seeds[name], args.timeout)
            if result["cls"] != "ok":
                failures.append((name, "valid file", result["why"]))
        for k in range(n_files):
            name = names[k % len(names)]
            kind, data = mutate(originals[name], rng)
            if name.endswith(".e57") and rng.randint(2):
                kind, data = kind + "+crc", e57_fix_checksums(data)
            stem, ext = os.path.splitext(name)
            path = os.path.join(tmp, f"fuzz{k:05d}_{stem}{ext}")
            with open(path, "wb") as fh:
                fh.write(data)
            result = read_in_child(path, args.timeout)
            row = table.setdefault(name, {"ok": 0, "documented": 0, "FAIL": 0})
            row[result["cls"]] += 1
            if result["cls"] == "FAIL":
                failures.append((os.path.basename(path), kind, result["why"]))
                if args.keep:
                    os.makedirs(args.keep, exist_ok=True)
                    with open(os.path.join(args.keep, os.path.basename(path)), "wb") as fh:
                        fh.write(data)
            else:
                os.remove(path)
    width = max(len(n) for n in table)
    print(f"{'seed file':<{width}}  {'ok':>6}  {'documented':>10}  {'FAIL':>5}")
    for name in names:
        row = table.get(name, {"ok": 0, "documented": 0, "FAIL": 0})
        print(f"{name:<{width}}  {row['ok']:>6}  {row['documented']:>10}  {row['FAIL']:>5}")
    total = {c: sum(r[c] for r in table.values()) for c in ("ok", "documented", "FAIL")}
    print(f"{'all':<{width}}  {total['ok']:>6}  {total['documented']:>10}  {total['FAIL']:>5}")
    print(f"{n_files} mutated files (seed {args.seed}) in {time.monotonic() - started:.1f} s")
    for name, kind, why in failures[:30]:
        print(f"FAIL {name} ({kind}): {why}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
