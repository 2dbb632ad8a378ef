"""Wavefront OBJ meshes: ``v`` and ``f`` lines (``f 1/2/3``, ``f 1//3`` and
negative, relative indices); texture coordinates, normals, groups and
materials are skipped. Polygons are split by fans from their first vertex."""

import itertools
from array import array

import numpy as np

from ._common import Mesh, text_lines
from ._errors import FileFormatError


def read_obj(path, data, owner):
    text = text_lines(data, path, owner, split=False)
    if "\n" not in text and "\r" in text:  # classic Mac line ends
        text = text.replace("\r", "\n")
    # flat arrays, not lists of tuples: a few times the output in memory
    coords, tris, tri_lines = array("d"), array("q"), array("q")
    n_v, pos, n = 0, 0, len(text)
    for i in itertools.count():  # line by line, without a list of all lines
        if pos >= n:
            break
        end = text.find("\n", pos)
        end = n if end < 0 else end
        line, pos = text[pos:end], end + 1
        if "#" in line:
            line = line.split("#", 1)[0]
        parts = line.split()
        if not parts:
            continue
        tag = parts[0]
        if tag == "v":
            try:
                if len(parts) < 4:
                    raise ValueError
                coords.extend((float(parts[1]), float(parts[2]), float(parts[3])))
            except ValueError:
                raise FileFormatError(f"{owner}: {path!r} line {i + 1}: malformed vertex: {line.strip()[:80]!r}") from None
            n_v += 1
        elif tag == "f":
            if len(parts) < 4:
                raise FileFormatError(
                    f"{owner}: {path!r} line {i + 1}: a face needs at least 3 vertices: {line.strip()[:80]!r}"
                )
            ids = []
            for tok in parts[1:]:
                try:
                    j = int(tok.split("/", 1)[0])
                except ValueError:
                    raise FileFormatError(f"{owner}: {path!r} line {i + 1}: malformed face index {tok!r}") from None
                if j == 0:
                    raise FileFormatError(f"{owner}: {path!r} line {i + 1}: OBJ indices start at 1, got 0")
                # negative indices count back from the latest vertex
                ids.append(j - 1 if j > 0 else n_v + j)
            if min(ids) < 0 or max(ids) >= 2 ** 62:  # checked against the final count below
                raise FileFormatError(f"{owner}: {path!r} line {i + 1}: face index out of range 1..{max(n_v, 1)}")
            for k in range(1, len(ids) - 1):  # a fan from the first vertex
                tris.extend((ids[0], ids[k], ids[k + 1]))
                tri_lines.append(i)
    if not n_v and tris:  # (a file of no vertices and no faces is a mesh of nothing, as a PLY file may be)
        raise FileFormatError(f"{owner}: {path!r} holds no vertices ('v' lines)")
    faces = np.frombuffer(tris, dtype=np.int64).reshape(-1, 3).copy()
    bad = np.flatnonzero((faces >= n_v).any(axis=1))
    if bad.size:
        raise FileFormatError(f"{owner}: {path!r} line {tri_lines[int(bad[0])] + 1}: face index out of range 1..{n_v}")
    return Mesh(np.frombuffer(coords, dtype=np.float64).reshape(-1, 3).copy(), faces)


def write_obj(path, vertices, faces, binary=True):
    with open(path, "w") as fh:
        np.savetxt(fh, vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(fh, faces + 1, fmt="f" + " %d" * faces.shape[1])
