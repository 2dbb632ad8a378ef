# cython: language_level=3
"""Compiled parser for the body of plain OFF files (vertex lines, then triangle lines).

Only the common form is handled here: each vertex line holds exactly three
numbers and each face line is ``3 i j k``; blank lines are skipped. Anything
else (comments, colors, polygons, bad numbers, a short file) makes the
parser return None, and :mod:`eppf.io._off` falls back to its line-by-line
reader, which reads the file or names the line at fault.
"""

import numpy as np

from ._text_scan cimport end_of_line, number_start, skip_blank
from libc.stdlib cimport strtod, strtol


def parse_off_body(bytes data, Py_ssize_t start, Py_ssize_t n_vertices, Py_ssize_t n_faces):
    """Parse ``n_vertices`` vertex lines and ``n_faces`` triangle lines from ``data[start:]``.

    Returns ``(vertices, faces, end)`` with float64 (n_vertices, 3) and int64
    (n_faces, 3) arrays and the offset after the last face line, or None when
    the body is not in the plain form.
    """
    cdef const char* s = data
    cdef Py_ssize_t n = len(data)
    cdef Py_ssize_t i = start, k, j
    cdef char* end
    cdef long count
    cdef bint ok = True
    vertices = np.empty((n_vertices, 3), dtype=np.float64)
    faces = np.empty((n_faces, 3), dtype=np.int64)
    cdef double[:, ::1] v = vertices
    cdef long long[:, ::1] f = faces
    with nogil:
        for k in range(n_vertices):
            i = skip_blank(s, i, n)
            for j in range(3):
                while i < n and (s[i] == b' ' or s[i] == b'\t'):
                    i += 1
                if i >= n or not number_start(s[i]):
                    ok = False
                    break
                v[k, j] = strtod(s + i, &end)
                if end == s + i:
                    ok = False
                    break
                i = end - s
            if not ok:
                break
            i = end_of_line(s, i, n)
            if i < 0:
                ok = False
                break
        if ok:
            for k in range(n_faces):
                i = skip_blank(s, i, n)
                if i >= n or s[i] < b'0' or s[i] > b'9':
                    ok = False
                    break
                count = strtol(s + i, &end, 10)
                if count != 3 or end == s + i:
                    ok = False
                    break
                i = end - s
                for j in range(3):
                    while i < n and (s[i] == b' ' or s[i] == b'\t'):
                        i += 1
                    if i >= n or s[i] < b'0' or s[i] > b'9':
                        ok = False
                        break
                    f[k, j] = strtol(s + i, &end, 10)
                    i = end - s
                if not ok:
                    break
                i = end_of_line(s, i, n)
                if i < 0:
                    ok = False
                    break
    if not ok:
        return None
    return vertices, faces, i
