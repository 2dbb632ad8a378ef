"""Read and write point clouds and meshes.

One table (:mod:`eppf.io._formats`) maps every extension to its format, so
every reader, the folder loaders and the command line accept the same files:

======================  ======  =============================================
extensions              kind    notes
======================  ======  =============================================
``.pcd``                cloud   PCL; ``ascii``, ``binary``, ``binary_compressed``
``.ply``                both    ASCII and both binary byte orders; a mesh when it has faces
``.xyz .txt .csv``      cloud   rows ``x y z [nx ny nz | more]``, one header line allowed
``.pts``                cloud   Open3D; the same rows, after an optional count line
``.xyzn``               cloud   Open3D; ``x y z nx ny nz``
``.xyzrgb``             cloud   Open3D; ``x y z r g b`` (color ignored)
``.npy .npz``           cloud   NumPy arrays of shape (n, 3) or (n, 6) (wider: normals when columns 4-6 have
                                unit length); an ``.npz`` with several holds
                                ``points`` (Open3D: ``positions``) and optionally ``normals``
``.off``                mesh    including ModelNet's ``OFF490 518 0`` first line
``.obj``                mesh    Wavefront; polygons split into triangles
``.stl``                mesh    binary and ASCII
======================  ======  =============================================

Extensions match in any case (``scan.PLY``). :func:`read_point_cloud` reads
every one of them: mesh files are sampled uniformly over their surface
(area-weighted), with the settings (``n_points``, ``resolution``,
``random_state``) as keyword parameters, exactly as the folder loaders of
:mod:`eppf.datasets` sample them. :func:`read_mesh` reads the mesh formats.

A cloud is returned as a float64 array of shape (n_points, 3), or
(n_points, 6) with the normals in columns 3 to 5 when the file has them, the
layout every eppf estimator accepts. A mesh is returned as a :class:`Mesh`
``(vertices, faces)`` with polygons split into triangles (a fan from each
polygon's first vertex).

Every reader is bounded by its file: each count in a header (PCD ``POINTS``,
PLY element counts, OFF counts, the STL triangle count, a ``.pts`` count
line, an NPY shape) is checked against the bytes the file holds before
anything is allocated. Bad content raises :class:`FileFormatError` (a
:class:`ValueError`), a file that cannot be opened an :class:`OSError`; both
name the file, and the line or byte where known.

All readers are written here, with no optional dependency: the formats are
simple enough that a careful reader is shorter than the glue to a library,
every error can name the file and the line or byte, and the hot paths (plain
OFF bodies, numeric tables, LZF) are compiled.
"""

from ._api import read_mesh, read_point_cloud, write_mesh, write_point_cloud
from ._common import Mesh
from ._errors import FileFormatError
from ._fields import read_point_fields, write_point_fields
from ._formats import format_of, supported_extensions

__all__ = ["FileFormatError", "Mesh", "format_of", "read_mesh", "read_point_cloud", "read_point_fields",
           "supported_extensions", "write_mesh", "write_point_cloud", "write_point_fields"]
