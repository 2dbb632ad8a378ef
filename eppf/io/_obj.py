"""Wavefront OBJ meshes: ``v`` and ``f`` lines (``f 1/2/3``, ``f 1//3`` and
negative, relative indices); texture coordinates, normals, groups and
materials are skipped. Polygons are split by fans from their first vertex."""

import numpy as np

from ._common import Mesh, fan, text_lines
from ._errors import FileFormatError


def read_obj(path, data, owner):
    lines = text_lines(data, path, owner)
    verts, polys, poly_lines = [], [], []
    for i, line in enumerate(lines):
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
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except ValueError:
                raise FileFormatError(f"{owner}: {path!r} line {i + 1}: malformed vertex: {line.strip()[:80]!r}") from None
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
                ids.append(j - 1 if j > 0 else len(verts) + j)
            polys.append(ids)
            poly_lines.append(i)
    if not verts:
        raise FileFormatError(f"{owner}: {path!r} holds no vertices ('v' lines)")
    n_v = len(verts)
    for ids, i in zip(polys, poly_lines):
        if min(ids) < 0 or max(ids) >= n_v:
            raise FileFormatError(f"{owner}: {path!r} line {i + 1}: face index out of range 1..{n_v}")
    return Mesh(np.array(verts, dtype=np.float64), fan(polys))


def write_obj(path, vertices, faces, binary=True):
    with open(path, "w") as fh:
        np.savetxt(fh, vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(fh, faces + 1, fmt="f" + " %d" * faces.shape[1])
