# cython: language_level=3
"""Compiled LZF decompressor for ``DATA binary_compressed`` PCD files.

LZF (the format of liblzf, which PCL uses) is a stream of control bytes:
``c < 32`` starts a literal run of ``c + 1`` bytes; otherwise the top three
bits give a back-reference length (7 means "add the next byte"), the low five
bits and the following byte give the distance back into the output. Every
read is checked against the end of the input and every write against the
declared output size, so no input can make this read or write out of bounds.
"""

from libc.string cimport memcpy

# the most output one input byte can give: a long back reference takes 3
# input bytes and writes at most 7 + 255 + 2 = 264 bytes
LZF_MAX_RATIO = 88

cdef enum:
    OK = 0
    LITERAL_OVERFLOW = 1
    TRUNCATED_REFERENCE = 2
    BAD_REFERENCE = 3
    SHORT_OUTPUT = 4


def lzf_decompress(const unsigned char[::1] src, Py_ssize_t expected):
    """Decompress ``src`` into ``expected`` bytes.

    Returns ``(out, status, position, written)``: the output (a bytearray of
    ``expected`` bytes), a status code (0: success, 1: a literal run
    overflows, 2: a truncated back reference, 3: a reference before the start
    or past the end of the output, 4: the output is shorter than expected) and
    the input offset where decoding stopped and the bytes written so far.
    """
    if expected < 0:
        raise ValueError("expected must be >= 0")
    out = bytearray(expected)
    cdef unsigned char[::1] dst = out
    cdef Py_ssize_t n = src.shape[0]
    cdef Py_ssize_t ip = 0, op = 0, length, ref, k
    cdef unsigned int ctrl
    cdef int status = OK
    with nogil:
        while ip < n:
            ctrl = src[ip]
            ip += 1
            if ctrl < 32:
                length = ctrl + 1
                if length > n - ip or length > expected - op:
                    status = LITERAL_OVERFLOW
                    break
                memcpy(&dst[op], &src[ip], length)
                ip += length
                op += length
            else:
                length = ctrl >> 5
                if length == 7:
                    if ip >= n:
                        status = TRUNCATED_REFERENCE
                        break
                    length += src[ip]
                    ip += 1
                if ip >= n:
                    status = TRUNCATED_REFERENCE
                    break
                ref = op - <Py_ssize_t>((ctrl & 0x1F) << 8) - src[ip] - 1
                ip += 1
                length += 2
                if ref < 0 or length > expected - op:
                    status = BAD_REFERENCE
                    break
                if ref + length <= op:
                    memcpy(&dst[op], &dst[ref], length)
                    op += length
                else:  # overlapping: byte by byte, repeating the pattern
                    for k in range(length):
                        dst[op] = dst[ref + k]
                        op += 1
        if status == OK and op != expected:
            status = SHORT_OUTPUT
    return out, status, ip, op
