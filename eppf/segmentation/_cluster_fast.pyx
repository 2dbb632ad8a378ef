# cython: language_level=3
"""Compiled kernels of the segmentation: Euclidean clustering on a grid, the
slope-limited lowest surface of the grid ground model.

Clustering (``connect``)
------------------------
The points are binned in cubic cells of side ``s`` a little under
``tolerance / sqrt(3)``, so that any two points of one cell are closer than the
tolerance: a cell is connected as a whole. Two points closer than the
tolerance then lie in cells at most two apart along each axis. The cells,
sorted lexicographically by their integer coordinates, are visited in order;
for each, the 62 cells after it in that order within two cells along every axis
lie in 13 runs of consecutive sorted cells (one per (dx, dy) column), whose
starts only move forward from one cell to the next, so each run is found by
advancing a pointer: linear time after the sort. A pair of cells not yet in
one component is joined (union-find) when some pair of their points is closer
than the tolerance (the points of the first cell at least the tolerance away from
the second's bounding box are skipped). One thread, one fixed order: the
components do not depend on the number of threads.

Cell coordinates come from :func:`cells`, through ``clamp_floor64``: bounded
for every double; the caller checks that the scene spans at most ``2**30``
cells along each axis (where the floor's rounding stays below the margin
of ``s``).
"""
from libc.math cimport sqrt
from libc.stdint cimport int64_t

from eppf.utils._common cimport clamp_floor64

import numpy as np


def cells(const double[:, ::1] pts, double x0, double y0, double z0, double inv_side, int64_t limit):
    """Integer cell coordinates ``floor((p - origin) * inv_side)`` of each point, clamped to ``[0, limit - 1]``."""
    cdef Py_ssize_t n = pts.shape[0], i
    out = np.empty((n, 3), dtype=np.int64)
    cdef int64_t[:, ::1] c = out
    with nogil:
        for i in range(n):
            c[i, 0] = clamp_floor64((pts[i, 0] - x0) * inv_side, limit)
            c[i, 1] = clamp_floor64((pts[i, 1] - y0) * inv_side, limit)
            c[i, 2] = clamp_floor64((pts[i, 2] - z0) * inv_side, limit)
    return out


cdef inline int64_t _find(int64_t* parent, int64_t a) noexcept nogil:
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


cdef inline int _before(const int64_t* c, int64_t x, int64_t y, int64_t z) noexcept nogil:
    """Whether cell coordinates ``c`` come before (x, y, z) lexicographically."""
    if c[0] != x:
        return c[0] < x
    if c[1] != y:
        return c[1] < y
    return c[2] < z


cdef inline double _box_gap2(const double* p, const double* box) noexcept nogil:
    """Squared distance from point ``p`` to the box ``box`` (lower x, y, z, then upper x, y, z)."""
    cdef double g = 0.0, d
    cdef int k
    for k in range(3):
        d = box[k] - p[k]
        if d > 0.0:
            g += d * d
        else:
            d = p[k] - box[k + 3]
            if d > 0.0:
                g += d * d
    return g


cdef int _touch(const double[:, ::1] pts, const int64_t[::1] order, int64_t a0, int64_t a1, int64_t b0, int64_t b1,
                const double* box_b, double tol2) noexcept nogil:
    """Whether some point of sorted range [a0, a1) is closer than the tolerance to one of [b0, b1), whose
    points lie in ``box_b``: points of the first range at least the tolerance from that box are skipped,
    so that two dense cells facing each other across a gap cost little more than their sizes."""
    cdef int64_t i, j, p, q
    cdef double dx, dy, dz
    for i in range(a0, a1):
        p = order[i]
        if _box_gap2(&pts[p, 0], box_b) >= tol2:
            continue
        for j in range(b0, b1):
            q = order[j]
            dx = pts[p, 0] - pts[q, 0]
            dy = pts[p, 1] - pts[q, 1]
            dz = pts[p, 2] - pts[q, 2]
            if dx * dx + dy * dy + dz * dz < tol2:
                return 1
    return 0


def runs(const int64_t[:, ::1] cells, const int64_t[::1] order):
    """(start, cell) of the occupied cells: the points of cell ``a`` are ``order[start[a]:start[a + 1]]``
    and its coordinates ``cell[a]``, given ``order`` sorting the points' ``cells`` lexicographically."""
    cdef Py_ssize_t n = order.shape[0], i
    cdef int64_t m = 0, p, prev = -1
    start_arr = np.empty(n + 1, dtype=np.int64)
    cdef int64_t[::1] start = start_arr
    with nogil:
        for i in range(n):
            p = order[i]
            if prev < 0 or cells[p, 0] != cells[prev, 0] or cells[p, 1] != cells[prev, 1] or cells[p, 2] != cells[prev, 2]:
                start[m] = i
                m += 1
            prev = p
        start[m] = n
    start_arr = start_arr[:m + 1].copy()
    return start_arr, np.ascontiguousarray(np.asarray(cells)[np.asarray(order)[start_arr[:m]]])


def connect(const double[:, ::1] pts, const int64_t[::1] order, const int64_t[::1] start, const int64_t[:, ::1] cell,
            double tolerance):
    """The component of each point: a representative point index per component (int64, shape (n,)).

    ``order``, ``start`` and ``cell`` describe the occupied cells in lexicographic order (see :func:`runs`).
    """
    cdef Py_ssize_t n = pts.shape[0]
    cdef int64_t m = cell.shape[0]
    cdef int64_t i, a, b, k, ra, rb, x, y, z, p
    cdef double tol2 = tolerance * tolerance
    # the 13 forward columns (dx, dy) and the lowest dz of each
    cdef int64_t col_dx[13]
    cdef int64_t col_dy[13]
    cdef int64_t col_lo[13]
    cdef int64_t ptr[13]
    cdef int ncol = 0, dx, dy
    col_dx[0] = 0; col_dy[0] = 0; col_lo[0] = 1
    ncol = 1
    for dy in range(1, 3):
        col_dx[ncol] = 0; col_dy[ncol] = dy; col_lo[ncol] = -2
        ncol += 1
    for dx in range(1, 3):
        for dy in range(-2, 3):
            col_dx[ncol] = dx; col_dy[ncol] = dy; col_lo[ncol] = -2
            ncol += 1
    roots = np.empty(n, dtype=np.int64)
    parent_arr = np.empty(max(m, 1), dtype=np.int64)
    box_arr = np.empty((max(m, 1), 6))
    cdef int64_t[::1] parent = parent_arr
    cdef double[:, ::1] box = box_arr
    cdef int64_t[::1] out = roots
    cdef int d
    with nogil:
        for a in range(m):
            parent[a] = a
            for d in range(3):
                box[a, d] = pts[order[start[a]], d]
                box[a, d + 3] = pts[order[start[a]], d]
            for i in range(start[a] + 1, start[a + 1]):
                p = order[i]
                for d in range(3):
                    if pts[p, d] < box[a, d]:
                        box[a, d] = pts[p, d]
                    if pts[p, d] > box[a, d + 3]:
                        box[a, d + 3] = pts[p, d]
        for k in range(ncol):
            ptr[k] = 0
        for a in range(m):
            x = cell[a, 0]
            y = cell[a, 1]
            z = cell[a, 2]
            for k in range(ncol):
                # first cell at or after (x + dx, y + dy, z + lo): only moves forward
                while ptr[k] < m and _before(&cell[ptr[k], 0], x + col_dx[k], y + col_dy[k], z + col_lo[k]):
                    ptr[k] += 1
                b = ptr[k]
                while b < m and cell[b, 0] == x + col_dx[k] and cell[b, 1] == y + col_dy[k] and cell[b, 2] <= z + 2:
                    ra = _find(&parent[0], a)
                    rb = _find(&parent[0], b)
                    if ra != rb and _touch(pts, order, start[a], start[a + 1], start[b], start[b + 1], &box[b, 0], tol2):
                        if ra < rb:
                            parent[rb] = ra
                        else:
                            parent[ra] = rb
                    b += 1
        for a in range(m):
            ra = _find(&parent[0], a)
            p = order[start[ra]]
            for i in range(start[a], start[a + 1]):
                out[order[i]] = p
    return roots


def slope_envelope(double[:, ::1] surface, double step, double diagonal):
    """``surface = min over cells c' of (surface[c'] + chamfer distance)``, in place, 8-neighbor chamfer
    weights ``step`` (along an axis) and ``diagonal``: one raster pass forward, one backward (exact for a
    3x3 chamfer mask). Empty cells hold +inf."""
    cdef Py_ssize_t h = surface.shape[0], w = surface.shape[1], i, j
    cdef double v
    with nogil:
        for i in range(h):
            for j in range(w):
                v = surface[i, j]
                if j > 0 and surface[i, j - 1] + step < v:
                    v = surface[i, j - 1] + step
                if i > 0:
                    if surface[i - 1, j] + step < v:
                        v = surface[i - 1, j] + step
                    if j > 0 and surface[i - 1, j - 1] + diagonal < v:
                        v = surface[i - 1, j - 1] + diagonal
                    if j + 1 < w and surface[i - 1, j + 1] + diagonal < v:
                        v = surface[i - 1, j + 1] + diagonal
                surface[i, j] = v
        for i in range(h - 1, -1, -1):
            for j in range(w - 1, -1, -1):
                v = surface[i, j]
                if j + 1 < w and surface[i, j + 1] + step < v:
                    v = surface[i, j + 1] + step
                if i + 1 < h:
                    if surface[i + 1, j] + step < v:
                        v = surface[i + 1, j] + step
                    if j + 1 < w and surface[i + 1, j + 1] + diagonal < v:
                        v = surface[i + 1, j + 1] + diagonal
                    if j > 0 and surface[i + 1, j - 1] + diagonal < v:
                        v = surface[i + 1, j - 1] + diagonal
                surface[i, j] = v


cdef int64_t _first_at_or_after(const int64_t[:, ::1] cell, int64_t m, int64_t x, int64_t y, int64_t z) noexcept nogil:
    """Index of the first of the ``m`` sorted cells not before (x, y, z): binary search."""
    cdef int64_t lo = 0, hi = m, mid
    while lo < hi:
        mid = lo + (hi - lo) // 2
        if _before(&cell[mid, 0], x, y, z):
            lo = mid + 1
        else:
            hi = mid
    return lo


def nearest_distances(const double[:, ::1] pts, const int64_t[:, ::1] cells, const int64_t[::1] order,
                      const int64_t[::1] start, const int64_t[:, ::1] cell, const int64_t[::1] sample):
    """For each point of ``sample``, the distance to its nearest point at a positive distance among those of
    its own and the 26 adjacent cells (+inf when there is none). Exact for distances up to the cells' side
    (0 where the squared distance underflows).

    ``cells`` holds each point's cell; ``order``, ``start`` and ``cell`` the occupied cells (see :func:`runs`).
    """
    cdef Py_ssize_t ns = sample.shape[0]
    cdef int64_t m = cell.shape[0]
    cdef int64_t s, p, q, b, j, x, y, z
    cdef int dx, dy
    cdef double best, d, ex, ey, ez
    out_arr = np.full(ns, np.inf)
    cdef double[::1] out = out_arr
    with nogil:
        for s in range(ns):
            p = sample[s]
            x = cells[p, 0]
            y = cells[p, 1]
            z = cells[p, 2]
            best = out[s]
            for dx in range(-1, 2):
                for dy in range(-1, 2):
                    b = _first_at_or_after(cell, m, x + dx, y + dy, z - 1)
                    while b < m and cell[b, 0] == x + dx and cell[b, 1] == y + dy and cell[b, 2] <= z + 1:
                        for j in range(start[b], start[b + 1]):
                            q = order[j]
                            ex = pts[p, 0] - pts[q, 0]
                            ey = pts[p, 1] - pts[q, 1]
                            ez = pts[p, 2] - pts[q, 2]
                            d = ex * ex + ey * ey + ez * ez
                            # coincident points are left out; a point apart whose square underflows to 0 is not
                            if d < best and (ex != 0.0 or ey != 0.0 or ez != 0.0):
                                best = d
                        b += 1
            out[s] = sqrt(best)
    return out_arr


def crowding(const double[:, ::1] pts, const int64_t[:, ::1] cells, const int64_t[::1] order,
             const int64_t[::1] start, const int64_t[:, ::1] cell, const int64_t[::1] sample):
    """For each point of ``sample``: (the number of points in its cell, the longest side of their bounding box).

    Each cell's box is measured once, however many sample points it holds: linear time in the points.
    ``cells``, ``order``, ``start`` and ``cell`` as for :func:`nearest_distances`.
    """
    cdef Py_ssize_t ns = sample.shape[0]
    cdef int64_t m = cell.shape[0]
    cdef int64_t s, p, q, b, j
    cdef int d
    cdef double lo, hi, w
    count_arr = np.empty(ns, dtype=np.int64)
    width_arr = np.empty(ns)
    known_arr = np.full(max(m, 1), -1.0)
    cdef int64_t[::1] count = count_arr
    cdef double[::1] width = width_arr
    cdef double[::1] known = known_arr
    with nogil:
        for s in range(ns):
            p = sample[s]
            b = _first_at_or_after(cell, m, cells[p, 0], cells[p, 1], cells[p, 2])  # p's own cell
            count[s] = start[b + 1] - start[b]
            if known[b] < 0.0:
                known[b] = 0.0
                for d in range(3):
                    lo = pts[p, d]
                    hi = lo
                    for j in range(start[b], start[b + 1]):
                        q = order[j]
                        if pts[q, d] < lo:
                            lo = pts[q, d]
                        if pts[q, d] > hi:
                            hi = pts[q, d]
                    w = hi - lo
                    if w > known[b]:
                        known[b] = w
            width[s] = known[b]
    return count_arr, width_arr
