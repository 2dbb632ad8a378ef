# cython: language_level=3
"""Compiled parser for tables of numbers in text files (XYZ, CSV, PTS, ASCII PCD bodies).

Only plain tables are handled here: every non-blank row holds the same number
of numbers. Anything else makes the parser return None and the caller's
line-by-line reader reads the file or names the line at fault.
"""

import numpy as np

from ._text_scan cimport end_of_line, number_start, skip_blank
from libc.stdlib cimport strtod


# Exact powers of ten: 10**k is a float64 without rounding up to k = 22.
cdef double[23] _POW10 = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                          1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22]


cdef inline bint _ends_token(const char* p, const char* lim) noexcept nogil:
    # the end of the buffer, white space or a table separator
    return p == lim or p[0] == b' ' or p[0] == b'\t' or p[0] == b'\r' or p[0] == b'\n' or p[0] == b',' \
        or p[0] == b';' or p[0] == b'\v' or p[0] == b'\f'


cdef inline double _strtod(const char* p, const char* lim, char** endp) noexcept nogil:
    """``strtod(p, endp)``, with a shortcut that gives the same double for short plain decimals.

    A token ``[sign]digits[.digits][(e|E)[sign]digits]`` followed by white
    space, a separator or the end, with at most 19 digits whose integer M is
    at most 2**53 and a decimal exponent E with |E| <= 22, is M * 10**E (or
    M / 10**-E): both operands are float64 without rounding, so the one
    IEEE operation rounds the exact value once, to the nearest double, as a
    correctly rounding strtod does (Clinger's fast path). Anything else
    (more digits, larger exponents, inf, nan, hexadecimal, a token that goes
    on) is handed to strtod itself, so the result and the end pointer are
    always strtod's.
    """
    cdef const char* q = p
    cdef bint neg = False, eneg = False
    cdef unsigned long long m = 0
    cdef int digits = 0, frac = 0, ex = 0, expdigits = 0
    cdef double v
    if q < lim and (q[0] == b'-' or q[0] == b'+'):
        neg = q[0] == b'-'
        q += 1
    while q < lim and q[0] >= b'0' and q[0] <= b'9':
        if digits < 19:
            m = m * 10 + <unsigned long long>(q[0] - 48)
        digits += 1
        q += 1
    if q < lim and q[0] == b'.':
        q += 1
        while q < lim and q[0] >= b'0' and q[0] <= b'9':
            if digits < 19:
                m = m * 10 + <unsigned long long>(q[0] - 48)
            digits += 1
            frac += 1
            q += 1
    if digits == 0 or digits > 19:
        return strtod(p, endp)
    if q < lim and (q[0] == b'e' or q[0] == b'E'):
        q += 1
        if q < lim and (q[0] == b'-' or q[0] == b'+'):
            eneg = q[0] == b'-'
            q += 1
        while q < lim and q[0] >= b'0' and q[0] <= b'9':
            if ex < 10000:
                ex = ex * 10 + (q[0] - 48)
            expdigits += 1
            q += 1
        if expdigits == 0:
            return strtod(p, endp)  # "1e" or "1e+": strtod stops before the e
    if not _ends_token(q, lim) or m > (1ULL << 53):
        return strtod(p, endp)
    ex = (-ex if eneg else ex) - frac
    if ex < -22 or ex > 22:
        return strtod(p, endp)
    v = <double>m
    if ex >= 0:
        v = v * _POW10[ex]
    else:
        v = v / _POW10[-ex]
    endp[0] = <char*>q
    return -v if neg else v


cdef inline bint _is_sep(char c) noexcept nogil:
    return c == b' ' or c == b'\t' or c == b',' or c == b';'


cdef inline bint _not_python_float(const char* p, const char* end) noexcept nogil:
    """Whether strtod's token ``[p, end)`` is one Python's ``float`` refuses (hexadecimal, ``nan(...)``)."""
    while p < end:
        if p[0] == b'x' or p[0] == b'X' or p[0] == b'(':
            return True
        p += 1
    return False


def parse_float_table(bytes data, Py_ssize_t start):
    """Parse rows of numbers (separated by spaces, tabs, commas or semicolons) from ``data[start:]``.

    Every non-blank row must hold as many numbers as the first. Returns a
    float64 array of shape (n_rows, n_columns), or None when a row differs
    or holds anything but numbers (the caller then reports the line).
    """
    cdef const char* s = data
    cdef Py_ssize_t n = len(data)
    cdef Py_ssize_t i = start, k = 0, n_cols = -1, row_count = 0, cols, cap
    cdef char* end
    cdef bint ok = True
    cap = data.count(b"\n", start) + 1
    # the first row fixes the column count
    i = skip_blank(s, i, n)
    if i >= n:
        return None
    cols = 0
    cdef Py_ssize_t j = i
    while j < n and s[j] != b'\n':
        while j < n and (_is_sep(s[j]) or s[j] == b'\r'):
            j += 1
        if j >= n or s[j] == b'\n':
            break
        _strtod(s + j, s + n, &end)
        if end == s + j or _not_python_float(s + j, end):
            return None
        j = end - s
        cols += 1
    if cols == 0:
        return None
    n_cols = cols
    out = np.empty(cap * n_cols, dtype=np.float64)
    cdef double[::1] o = out
    with nogil:
        while True:
            i = skip_blank(s, i, n)
            if i >= n:
                break
            cols = 0
            while True:
                while i < n and _is_sep(s[i]):
                    i += 1
                if i >= n or s[i] == b'\n' or s[i] == b'\r':
                    break
                if cols == n_cols or not number_start(s[i]):
                    ok = False
                    break
                o[k] = _strtod(s + i, s + n, &end)
                if end == s + i or _not_python_float(s + i, end):
                    ok = False
                    break
                i = end - s
                k += 1
                cols += 1
                if i < n and not (_is_sep(s[i]) or s[i] == b'\n' or s[i] == b'\r'):
                    ok = False
                    break
            if not ok or cols != n_cols:
                ok = False
                break
            row_count += 1
            i = end_of_line(s, i, n)
            if i < 0:
                ok = False
                break
    if not ok:
        return None
    return out[:row_count * n_cols].reshape(row_count, n_cols)


cdef inline bint _is_space(char c) noexcept nogil:
    return c == b' ' or c == b'\t' or c == b'\r' or c == b'\n' or c == b'\v' or c == b'\f'


def parse_tokens(bytes data, Py_ssize_t start):
    """Parse every whitespace-separated number of ``data[start:]`` (ASCII PLY bodies).

    Returns ``(values, -1)`` with a float64 array of all the numbers, or
    ``(None, offset)`` with the offset of the first token that is not a
    decimal number (hexadecimal ones are refused, as Python's ``float``
    refuses them). Allocates one float64 per token, counted first.
    """
    cdef const char* s = data
    cdef Py_ssize_t n = len(data)
    cdef Py_ssize_t i = start, count = 0, k = 0, tok, bad = -1
    cdef char* end
    with nogil:
        while i < n:
            while i < n and _is_space(s[i]):
                i += 1
            if i < n:
                count += 1
                while i < n and not _is_space(s[i]):
                    i += 1
    out = np.empty(count, dtype=np.float64)
    cdef double[::1] o = out
    i = start
    with nogil:
        while i < n and k < count:
            while i < n and _is_space(s[i]):
                i += 1
            if i >= n:
                break
            tok = i
            while i < n and not _is_space(s[i]):
                if s[i] == b'x' or s[i] == b'X' or s[i] == 0:
                    bad = tok
                i += 1
            if bad >= 0:
                break
            o[k] = _strtod(s + tok, s + n, &end)
            if end != s + i:  # strtod stopped inside the token
                bad = tok
                break
            k += 1
    if bad >= 0:
        return None, bad
    return out, -1
