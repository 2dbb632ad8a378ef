# cython: language_level=3
"""Inline scanning helpers shared by the compiled text parsers (OFF and XYZ).

Each takes the buffer ``s`` of length ``n`` and a position ``i``:

- ``skip_blank``: past spaces, tabs, carriage returns and whole blank lines;
- ``end_of_line``: after a line's last value, past spaces, tabs and ``\\r`` to
  just after the ``\\n`` (or to the end); -1 when anything else follows;
- ``number_start``: whether a character can begin a number.
"""


cdef inline Py_ssize_t skip_blank(const char* s, Py_ssize_t i, Py_ssize_t n) noexcept nogil:
    while i < n and (s[i] == b' ' or s[i] == b'\t' or s[i] == b'\r' or s[i] == b'\n'):
        i += 1
    return i


cdef inline Py_ssize_t end_of_line(const char* s, Py_ssize_t i, Py_ssize_t n) noexcept nogil:
    while i < n and (s[i] == b' ' or s[i] == b'\t' or s[i] == b'\r'):
        i += 1
    if i == n:
        return i
    if s[i] == b'\n':
        return i + 1
    return -1


cdef inline bint number_start(char c) noexcept nogil:
    return (c >= b'0' and c <= b'9') or c == b'-' or c == b'+' or c == b'.'
