# cython: language_level=3
"""Compiled kernel of the GASD shape descriptor (Lima & Teichrieb 2016, PCL 1.13).

Python allocates every array; the kernel fills one descriptor row and one
4x4 alignment transform per object, in parallel over objects (``prange``).
Every object is computed by one thread in a fixed order, so the output does
not depend on the number of threads. See ``eppf/descriptors/_gasd.py`` for the
description of every step.
"""
from cython.parallel cimport prange
from libc.math cimport sqrt, floor, fabs, cos, sin, atan2, frexp, ldexp
from libc.stdint cimport int8_t, int64_t
from libc.string cimport memset

from ..utils._common cimport pow2_scale

# PCL runs its eigen solver in single precision: its branch thresholds are
# float's (Eigen::NumTraits<float>::epsilon() and dummy_precision()).
cdef double _F_EPS = 1.1920928955078125e-07
cdef double _F_PREC = 1e-05
cdef double _F_MIN = 1.1754943508222875e-38

# interpolation modes
cdef enum:
    INTERP_NONE = 0
    INTERP_TRILINEAR = 1
    INTERP_QUADRILINEAR = 2

# sign conventions
cdef enum:
    SIGN_PCL = 0
    SIGN_MAJORITY = 1


cdef inline void _roots2(double b, double c, double* r) noexcept nogil:
    cdef double d = b * b - 4.0 * c
    if d < 0.0:
        d = 0.0
    d = sqrt(d)
    r[0] = 0.0
    r[2] = 0.5 * (b + d)
    r[1] = 0.5 * (b - d)


cdef void _roots(const double* m, double* r) noexcept nogil:
    """Eigenvalues of the symmetric 3x3 ``m`` (row-major), increasing: PCL's closed form."""
    cdef double m00 = m[0], m01 = m[1], m02 = m[2], m11 = m[4], m12 = m[5], m22 = m[8]
    cdef double c0 = (m00 * m11 * m22 + 2.0 * m01 * m02 * m12 - m00 * m12 * m12
                      - m11 * m02 * m02 - m22 * m01 * m01)
    cdef double c1 = m00 * m11 - m01 * m01 + m00 * m22 - m02 * m02 + m11 * m22 - m12 * m12
    cdef double c2 = m00 + m11 + m22
    cdef double c2_3, a_3, half_b, q, rho, theta, ct, st, t
    if fabs(c0) < _F_EPS:
        _roots2(c2, c1, r)
        return
    c2_3 = c2 / 3.0
    a_3 = (c1 - c2 * c2_3) / 3.0
    if a_3 > 0.0:
        a_3 = 0.0
    half_b = 0.5 * (c0 + c2_3 * (2.0 * c2_3 * c2_3 - c1))
    q = half_b * half_b + a_3 * a_3 * a_3
    if q > 0.0:
        q = 0.0
    rho = sqrt(-a_3)
    theta = atan2(sqrt(-q), half_b) / 3.0
    ct = cos(theta)
    st = sin(theta)
    r[0] = c2_3 + 2.0 * rho * ct
    r[1] = c2_3 - rho * (ct + sqrt(3.0) * st)
    r[2] = c2_3 - rho * (ct - sqrt(3.0) * st)
    if r[0] >= r[1]:
        t = r[0]; r[0] = r[1]; r[1] = t
    if r[1] >= r[2]:
        t = r[1]; r[1] = r[2]; r[2] = t
        if r[0] >= r[1]:
            t = r[0]; r[0] = r[1]; r[1] = t
    if r[0] <= 0.0:
        _roots2(c2, c1, r)


cdef inline void _cross(const double* a, const double* b, double* out) noexcept nogil:
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


cdef inline double _sq(const double* a) noexcept nogil:
    return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]


cdef double _null_vector(const double* m, double lam, double* out) noexcept nogil:
    """Largest cross product of two rows of ``m - lam I``, normalized; returns its squared length.

    PCL's rule: rows (0, 1), then (0, 2), then (1, 2), the first one that is
    at least as long as the others.
    """
    cdef double a[9]
    cdef double v1[3]
    cdef double v2[3]
    cdef double v3[3]
    cdef double l1, l2, l3, s
    cdef int i
    for i in range(9):
        a[i] = m[i]
    a[0] -= lam
    a[4] -= lam
    a[8] -= lam
    _cross(&a[0], &a[3], v1)
    _cross(&a[0], &a[6], v2)
    _cross(&a[3], &a[6], v3)
    l1 = _sq(v1)
    l2 = _sq(v2)
    l3 = _sq(v3)
    if l1 >= l2 and l1 >= l3:
        s = sqrt(l1)
        for i in range(3):
            out[i] = v1[i] / s
        return l1
    if l2 >= l1 and l2 >= l3:
        s = sqrt(l2)
        for i in range(3):
            out[i] = v2[i] / s
        return l2
    s = sqrt(l3)
    for i in range(3):
        out[i] = v3[i] / s
    return l3


cdef void _unit_orthogonal(const double* v, double* out) noexcept nogil:
    """Eigen's ``unitOrthogonal`` of a 3-vector."""
    cdef double inv
    if not (fabs(v[0]) <= fabs(v[2]) * _F_PREC) or not (fabs(v[1]) <= fabs(v[2]) * _F_PREC):
        inv = 1.0 / sqrt(v[0] * v[0] + v[1] * v[1])
        out[0] = -v[1] * inv
        out[1] = v[0] * inv
        out[2] = 0.0
    else:
        inv = 1.0 / sqrt(v[2] * v[2] + v[1] * v[1])
        out[0] = 0.0
        out[1] = -v[2] * inv
        out[2] = v[1] * inv


cdef inline void _cross_unit(const double* a, const double* b, double* out) noexcept nogil:
    cdef double s
    _cross(a, b, out)
    s = sqrt(_sq(out))
    if s > 0.0:
        out[0] /= s
        out[1] /= s
        out[2] /= s


cdef void eigen33(const double* mat, double* evecs, double* evals) noexcept nogil:
    """PCL's ``eigen33``: eigenvalues increasing, eigenvectors in ``evecs[3 * j : 3 * j + 3]``.

    The signs of the eigenvectors are those PCL's solver produces (they come
    from which rows' cross product is longest), which GASD's frame inherits.
    """
    cdef double sm[9]
    cdef double scale = 0.0, mm0, mm1, mm2
    cdef double mmax[3]
    cdef int i, min_el, max_el, mid_el
    for i in range(9):
        if fabs(mat[i]) > scale:
            scale = fabs(mat[i])
    if scale <= _F_MIN:
        scale = 1.0
    for i in range(9):
        sm[i] = mat[i] / scale
    _roots(sm, evals)
    if evals[2] - evals[0] <= _F_EPS:
        memset(evecs, 0, 9 * sizeof(double))
        evecs[0] = 1.0
        evecs[4] = 1.0
        evecs[8] = 1.0
    elif evals[1] - evals[0] <= _F_EPS:
        _null_vector(sm, evals[2], &evecs[6])
        _unit_orthogonal(&evecs[6], &evecs[3])
        _cross(&evecs[3], &evecs[6], &evecs[0])
    elif evals[2] - evals[1] <= _F_EPS:
        _null_vector(sm, evals[0], &evecs[0])
        _unit_orthogonal(&evecs[0], &evecs[3])
        _cross(&evecs[0], &evecs[3], &evecs[6])
    else:
        mmax[2] = _null_vector(sm, evals[2], &evecs[6])
        min_el = 2
        max_el = 2
        mm1 = _null_vector(sm, evals[1], &evecs[3])
        mmax[1] = mm1
        if mm1 <= mmax[min_el]:
            min_el = 1
        if mm1 > mmax[max_el]:
            max_el = 1
        # the longest cross product of each eigenvalue decides which columns
        # are recomputed as cross products of the other two (the column with
        # the longest stays as solved); this reproduces PCL 1.13's signs
        mm0 = _null_vector(sm, evals[0], &evecs[0])
        mmax[0] = mm0
        if mm0 <= mmax[min_el]:
            min_el = 0
        if mm0 > mmax[max_el]:
            max_el = 0
        mid_el = 3 - min_el - max_el
        _cross_unit(&evecs[3 * ((min_el + 1) % 3)], &evecs[3 * ((min_el + 2) % 3)], &evecs[3 * min_el])
        _cross_unit(&evecs[3 * ((mid_el + 1) % 3)], &evecs[3 * ((mid_el + 2) % 3)], &evecs[3 * mid_el])
    for i in range(3):
        evals[i] *= scale


cdef inline int64_t _clamp_index(double t, int64_t lo, int64_t hi) noexcept nogil:
    """``floor(t)`` clamped to ``[lo, hi]`` in floating point first (NaN -> lo)."""
    if not (t > <double>lo):
        return lo
    if t >= <double>hi:
        return hi
    return <int64_t>floor(t)


cdef inline void _flip_majority(const double* pts, Py_ssize_t n, double sc, const double* c, double* axis) noexcept nogil:
    """Point ``axis`` to the side of the centroid that holds more points (ties: positive third moment)."""
    cdef Py_ssize_t i
    cdef int64_t pos = 0, neg = 0
    cdef double t, m3 = 0.0
    for i in range(n):
        t = (((pts[3 * i] * sc - c[0]) * axis[0] + (pts[3 * i + 1] * sc - c[1]) * axis[1])
             + (pts[3 * i + 2] * sc - c[2]) * axis[2])
        if t > 0.0:
            pos += 1
        elif t < 0.0:
            neg += 1
        m3 += t * t * t
    if neg > pos or (neg == pos and m3 < 0.0):
        axis[0] = -axis[0]
        axis[1] = -axis[1]
        axis[2] = -axis[2]


cdef int _gasd_frame(const double* pts, Py_ssize_t n, double sc, const double* view, int sign_mode,
                     double* rot, double* c) noexcept nogil:
    """Centroid ``c`` and rotation ``rot`` (rows x, y, z) of GASD's reference frame."""
    cdef Py_ssize_t i
    cdef double cov[9]
    cdef double evecs[9]
    cdef double evals[3]
    cdef double dx, dy, dz
    cdef int j
    c[0] = 0.0
    c[1] = 0.0
    c[2] = 0.0
    for i in range(n):
        c[0] += pts[3 * i] * sc
        c[1] += pts[3 * i + 1] * sc
        c[2] += pts[3 * i + 2] * sc
    c[0] /= n
    c[1] /= n
    c[2] /= n
    memset(cov, 0, 9 * sizeof(double))
    for i in range(n):
        dx = pts[3 * i] * sc - c[0]
        dy = pts[3 * i + 1] * sc - c[1]
        dz = pts[3 * i + 2] * sc - c[2]
        cov[0] += dx * dx
        cov[1] += dx * dy
        cov[2] += dx * dz
        cov[4] += dy * dy
        cov[5] += dy * dz
        cov[8] += dz * dz
    cov[3] = cov[1]
    cov[6] = cov[2]
    cov[7] = cov[5]
    eigen33(cov, evecs, evals)
    # x: largest eigenvalue's vector, z: smallest's, y = z cross x
    for j in range(3):
        rot[j] = evecs[6 + j]
        rot[6 + j] = evecs[j]
    if sign_mode == SIGN_PCL:
        if rot[6] * view[0] + rot[7] * view[1] + rot[8] * view[2] > 0.0:
            rot[6] = -rot[6]
            rot[7] = -rot[7]
            rot[8] = -rot[8]
    else:
        _flip_majority(pts, n, sc, c, &rot[0])
        _flip_majority(pts, n, sc, c, &rot[6])
    _cross(&rot[6], &rot[0], &rot[3])
    if not (evals[2] > 0.0):
        return 1
    for j in range(9):
        if not (fabs(rot[j]) <= 1.0 + 1e-6):  # NaN from a degenerate solve
            return 1
    return 0


cdef inline void _local(const double* rot, const double* c, const double* p, double sc, double* q) noexcept nogil:
    cdef double dx = p[0] * sc - c[0], dy = p[1] * sc - c[1], dz = p[2] * sc - c[2]
    q[0] = (rot[0] * dx + rot[1] * dy) + rot[2] * dz
    q[1] = (rot[3] * dx + rot[4] * dy) + rot[5] * dz
    q[2] = (rot[6] * dx + rot[7] * dy) + rot[8] * dz


cdef inline void _add(double* out, int64_t g, int64_t hs, int64_t ix, int64_t iy, int64_t iz,
                      int64_t h, double w) noexcept nogil:
    """Add ``w`` to cell (ix, iy, iz), slot h, if they lie inside the grid (PCL's padding is dropped)."""
    if ix < 0 or ix >= g or iy < 0 or iy >= g or iz < 0 or iz >= g or h < 0 or h >= hs:
        return
    out[((ix * g + iy) * g + iz) * hs + h] += w


cdef inline void _add_sample(double* out, const double* q, double max_coord, int64_t half, int64_t hs, int interp,
                             double hbin, double incr, bint wrap) noexcept nogil:
    """PCL's addSampleToHistograms for one aligned point ``q`` with histogram coordinate ``hbin``.

    ``wrap``: the histogram is circular (hue), so PCL's padding bins fold
    onto the opposite ends instead of being dropped. Otherwise (the shape
    grid) trilinear weights whose 8 cells all lie inside the grid take a
    direct path: the same weights, added without bounds checks.
    """
    cdef double s[3]
    cdef double f[3]
    cdef int64_t b[3]
    cdef int64_t g = 2 * half, hb, h, ax, ay, az, e
    cdef int64_t sx = hs, sy = g * hs, sxx = g * g * hs
    cdef double ft, wx, wxy, w, w0, ww
    cdef double* o
    cdef int j
    for j in range(3):
        s[j] = (q[j] / max_coord) * <double>half + <double>half
    if interp == INTERP_NONE:
        for j in range(3):
            b[j] = _clamp_index(s[j], -1, g + 1)
        hb = _clamp_index(hbin, -1, hs)
        if wrap:
            hb = (hb + hs) % hs
        _add(out, g, hs, b[0], b[1], b[2], hb, incr)
        return
    # interpolation: bin centers carry full weight
    for j in range(3):
        s[j] -= 0.5
        b[j] = _clamp_index(s[j], -2, g + 1)
        f[j] = s[j] - <double>b[j]
        if not (f[j] >= 0.0):
            f[j] = 0.0
        elif f[j] > 1.0:
            f[j] = 1.0
    hbin -= 0.5
    hb = _clamp_index(hbin, -2, hs + 1)
    ft = hbin - <double>hb
    if not (ft >= 0.0):
        ft = 0.0
    elif ft > 1.0:
        ft = 1.0
    if interp == INTERP_TRILINEAR and not wrap:
        if hb < 0 or hb >= hs:
            return  # PCL's bin below the histogram, dropped from the output
        if b[0] >= 0 and b[0] < g - 1 and b[1] >= 0 and b[1] < g - 1 and b[2] >= 0 and b[2] < g - 1:
            o = out + ((b[0] * g + b[1]) * g + b[2]) * hs + hb
            wx = incr * f[0]
            w0 = incr - wx
            w = w0 * f[1]
            ww = w * f[2]
            o[sy + sx] += ww
            o[sy] += w - ww
            w = w0 - w
            ww = w * f[2]
            o[sx] += ww
            o[0] += w - ww
            w = wx * f[1]
            ww = w * f[2]
            o[sxx + sy + sx] += ww
            o[sxx + sy] += w - ww
            w = wx - w
            ww = w * f[2]
            o[sxx + sx] += ww
            o[sxx] += w - ww
            return
    for ax in range(2):
        wx = incr * f[0] if ax else incr - incr * f[0]
        for ay in range(2):
            wxy = wx * f[1] if ay else wx - wx * f[1]
            for az in range(2):
                w = wxy * f[2] if az else wxy - wxy * f[2]
                if interp == INTERP_TRILINEAR:
                    h = (hb + hs) % hs if wrap else hb
                    _add(out, g, hs, b[0] + ax, b[1] + ay, b[2] + az, h, w)
                else:
                    for e in range(2):
                        h = hb + e
                        if wrap:
                            h = (h + hs) % hs
                        _add(out, g, hs, b[0] + ax, b[1] + ay, b[2] + az, h, w * ft if e else w - w * ft)


cdef int _gasd_object(const double* pts, Py_ssize_t n, const double* view, int sign_mode,
                      int64_t half, int64_t hs, int interp, double* out, double* transform,
                      const double* hue, int64_t chalf, int64_t chs, int cinterp, double* cout) noexcept nogil:
    cdef double rot[9]
    cdef double c[3]
    cdef double q[3]
    cdef double max_coord = 0.0, dmax = 0.0, d, t, frac, hbin, step, incr
    cdef Py_ssize_t i
    cdef int j
    cdef double sc = pow2_scale(pts, n)
    if _gasd_frame(pts, n, sc, view, sign_mode, rot, c):
        return 1
    for j in range(3):
        transform[4 * j] = rot[3 * j]
        transform[4 * j + 1] = rot[3 * j + 1]
        transform[4 * j + 2] = rot[3 * j + 2]
        transform[4 * j + 3] = -((rot[3 * j] * c[0] + rot[3 * j + 1] * c[1]) + rot[3 * j + 2] * c[2]) / sc
    transform[12] = 0.0
    transform[13] = 0.0
    transform[14] = 0.0
    transform[15] = 1.0
    for i in range(n):
        _local(rot, c, &pts[3 * i], sc, q)
        for j in range(3):
            if fabs(q[j]) > max_coord:
                max_coord = fabs(q[j])
        d = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
        if d > dmax:
            dmax = d
    if not (max_coord > 0.0) or not (dmax > 0.0):
        return 1
    incr = 100.0 / <double>(n - 1)
    # PCL's expressions (a division each, not a multiplication by the
    # inverse), so that the farthest point lands where PCL puts it
    step = dmax / <double>half
    for i in range(n):
        _local(rot, c, &pts[3 * i], sc, q)
        d = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
        t = d / step
        frac = t - floor(t)
        if not (frac >= 0.0):
            frac = 0.0
        hbin = frac * <double>hs
        _add_sample(out, q, max_coord, half, hs, interp, hbin, incr, False)
    if hue != NULL:
        # GASDColorEstimation: the same aligned points, cube and weights, a
        # circular histogram of hue bins in each cell of the color grid
        for i in range(n):
            _local(rot, c, &pts[3 * i], sc, q)
            _add_sample(cout, q, max_coord, chalf, chs, cinterp, hue[i] * <double>chs, incr, True)
    return 0


def gasd_batch(const double[:, ::1] points, const int64_t[::1] offsets, const double[::1] view,
               int sign_mode, int64_t half, int64_t hs, int interp,
               double[:, ::1] out, double[:, :, ::1] transforms, int8_t[::1] status, int num_threads,
               const double[::1] hue=None, int64_t chalf=1, int64_t chs=1, int cinterp=0):
    """GASD rows of packed objects: object k is ``points[offsets[k]:offsets[k + 1]]``.

    ``out`` (n_objects, (2 half)^3 hs [+ (2 chalf)^3 chs]) must be zeroed;
    ``transforms`` receives each object's 4x4 alignment; ``status[k] = 1``
    marks an object whose frame is undefined (no spread). With ``hue``
    (one value in [0, 1) per point: hue / 360) the color grid follows the
    shape grid in each row.
    """
    cdef Py_ssize_t n_objects = offsets.shape[0] - 1
    cdef Py_ssize_t k
    cdef int64_t width = (2 * half) ** 3 * hs
    cdef const double* hp = NULL
    cdef Py_ssize_t cpos = 0
    if hue is not None:
        if hue.shape[0] != points.shape[0] or chalf < 1 or chs < 1:
            raise ValueError("gasd_batch: hue needs one value per point and a colour grid")
        hp = &hue[0]
        cpos = width
        width += (2 * chalf) ** 3 * chs
    if out.shape[0] != n_objects or transforms.shape[0] != n_objects or status.shape[0] != n_objects:
        raise ValueError("gasd_batch: output arrays do not match the number of objects")
    if out.shape[1] != width or transforms.shape[1] != 4 or transforms.shape[2] != 4:
        raise ValueError("gasd_batch: output arrays have the wrong width")
    if view.shape[0] != 3 or points.shape[1] != 3:
        raise ValueError("gasd_batch: points and view need 3 columns")
    for k in range(n_objects):
        if offsets[k + 1] - offsets[k] < 2 or offsets[k] < 0 or offsets[k + 1] > points.shape[0]:
            raise ValueError("gasd_batch: every object needs at least 2 points inside points")
    if n_objects == 0:
        return
    for k in prange(n_objects, nogil=True, schedule="dynamic", num_threads=num_threads):
        status[k] = <int8_t>_gasd_object(
            &points[offsets[k], 0], offsets[k + 1] - offsets[k], &view[0], sign_mode, half, hs, interp,
            &out[k, 0], &transforms[k, 0, 0],
            (hp + offsets[k]) if hp != NULL else NULL, chalf, chs, cinterp, &out[k, cpos],
        )


def eigen33_pcl(const double[:, ::1] mat):
    """PCL's eigen33 of one symmetric 3x3 matrix (test hook): (eigenvalues, eigenvectors as columns)."""
    import numpy as np

    cdef double m[9]
    cdef double ev[9]
    cdef double lam[3]
    cdef int i
    if mat.shape[0] != 3 or mat.shape[1] != 3:
        raise ValueError("eigen33_pcl: a 3x3 matrix is needed")
    for i in range(9):
        m[i] = mat[i // 3, i % 3]
    eigen33(m, ev, lam)
    vals = np.array([lam[0], lam[1], lam[2]])
    vecs = np.array([[ev[3 * j + i] for j in range(3)] for i in range(3)])
    return vals, vecs
