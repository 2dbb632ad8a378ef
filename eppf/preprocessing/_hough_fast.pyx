# cython: language_level=3
"""Compiled kernel for randomized-Hough surface normals (Boulch and Marlet,
SGP 2012), parallel over points with OpenMP.

For each point, with its neighborhood given (global indices into the packed
coordinates):

- random triplets of distinct neighbors are drawn from the point's private
  generator; each non-degenerate triplet's plane normal votes into an
  accumulator over the directions of the half sphere (antipodal directions
  identified), made of rings of constant polar angle cut into bins of about
  equal area;
- voting stops early when the leading bin's share is ahead of the second's by
  more than ``2 / sqrt(t)`` after ``t`` votes, or after ``n_triplets`` votes;
- the accumulator is repeated under ``n_rotations`` random rotations (one
  unrotated pass when 0); each pass gives the mean of the votes of its winning
  bin and a confidence (that bin's share of the votes);
- the passes' normals are grouped greedily (the most confident first, with
  those within ``cluster_angle`` of it) and the group with the largest summed
  confidence gives the normal, its confidence-weighted mean.

A point's generator is seeded from its object's seed and its index in the
object only, and no state is shared between points, so the output is
bit-identical for any thread count or chunking.
"""
from cython.parallel cimport prange, threadid
from libc.math cimport sqrt, fabs, floor, sin, cos, M_PI
from libc.stdint cimport int64_t, int32_t, uint64_t, uint32_t

from eppf.utils._common cimport splitmix64, rand_below

import numpy as np

cdef double _PI = M_PI
# Triplets whose cross product is below this fraction of the product of its
# two edge lengths are treated as collinear and do not vote.
cdef double _COLLINEAR = 1e-10
# At most this many draws are spent looking for three distinct neighbors.
cdef int _MAX_DRAW = 64


cdef inline void _random_rotation(uint64_t* state, double* r) noexcept nogil:
    """A uniformly random rotation matrix (row-major ``r``) from a uniform unit
    quaternion (Shoemake's construction)."""
    cdef double u1, u2, u3, a, b, w, x, y, z
    u1 = (splitmix64(state) >> 11) * (1.0 / 9007199254740992.0)
    u2 = (splitmix64(state) >> 11) * (2.0 * _PI / 9007199254740992.0)
    u3 = (splitmix64(state) >> 11) * (2.0 * _PI / 9007199254740992.0)
    a = sqrt(1.0 - u1)
    b = sqrt(u1)
    w = a * sin(u2)
    x = a * cos(u2)
    y = b * sin(u3)
    z = b * cos(u3)
    r[0] = 1.0 - 2.0 * (y * y + z * z)
    r[1] = 2.0 * (x * y - w * z)
    r[2] = 2.0 * (x * z + w * y)
    r[3] = 2.0 * (x * y + w * z)
    r[4] = 1.0 - 2.0 * (x * x + z * z)
    r[5] = 2.0 * (y * z - w * x)
    r[6] = 2.0 * (x * z - w * y)
    r[7] = 2.0 * (y * z + w * x)
    r[8] = 1.0 - 2.0 * (x * x + y * y)


cdef inline double _pseudo_angle(double x, double y) noexcept nogil:
    """A cheap increasing function of the azimuth atan2(y, x) on [0, 2 pi),
    with values in [0, 4) (the "diamond angle"); 0 for x = y = 0. The
    direction (-x, -y) gets the value plus 2, modulo 4."""
    cdef double d = fabs(x) + fabs(y)
    if not (d > 0.0):
        return 0.0
    if y >= 0.0:
        return y / d if x >= 0.0 else 1.0 - x / d
    return 2.0 - y / d if x < 0.0 else 3.0 + x / d


cdef inline int64_t _bin_of(double ux, double uy, double uz, int64_t n_rings,
                            const double* ring_z, const int64_t* ring_start,
                            const int64_t* ring_bins, const double* edges) noexcept nogil:
    """Bin of the unit direction ``u`` (taken with ``u_z >= 0``: the caller
    flips it). ``ring_z[j]`` is the cosine of ring ``j``'s lower polar bound;
    ``edges[ring_start[j]:ring_start[j] + ring_bins[j] - 1]`` are the pseudo
    angles of its bins' azimuth boundaries. Only comparisons pick the ring
    and the bin, so any float (NaN included) gives a valid bin."""
    cdef double p
    cdef int64_t j = 0, lo, hi, mid
    cdef const double* e
    while j < n_rings - 1 and uz <= ring_z[j]:
        j += 1
    p = _pseudo_angle(ux, uy)
    # The last ring touches the equator: there theta and theta + pi are the
    # same projective direction, so its bins span half the azimuths.
    if j == n_rings - 1 and p >= 2.0:
        p -= 2.0
    e = edges + ring_start[j]
    lo = 0
    hi = ring_bins[j] - 1
    while lo < hi:
        mid = (lo + hi) >> 1
        if p >= e[mid]:
            lo = mid + 1
        else:
            hi = mid
    return ring_start[j] + lo


cdef double _one_pass(const double* pts, const int64_t* nb, int64_t k, uint64_t* state,
                      const double* rot, int64_t n_triplets, int64_t n_rings, const double* ring_z,
                      const int64_t* ring_start, const int64_t* ring_bins, const double* edges,
                      const double* centre, int64_t n_bins,
                      int64_t* count, double* acc, double* normal) noexcept nogil:
    """One accumulator pass; writes the winning bin's mean vote to ``normal``
    and returns its share of the votes (0 when no triplet voted)."""
    cdef int64_t t, b, i1 = -1, i2 = -1, votes = 0, lead
    cdef int64_t a0, a1, a2
    cdef int draws
    cdef double e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, nrm, l1, l2
    cdef double ux, uy, uz, sgn
    cdef const double* p0
    cdef const double* p1
    cdef const double* p2
    for b in range(n_bins):
        count[b] = 0
        acc[3 * b] = 0.0
        acc[3 * b + 1] = 0.0
        acc[3 * b + 2] = 0.0
    for t in range(n_triplets):
        a0 = rand_below(state, <uint32_t>k)
        a1 = rand_below(state, <uint32_t>k)
        draws = 0
        while a1 == a0 and draws < _MAX_DRAW:
            a1 = rand_below(state, <uint32_t>k)
            draws += 1
        a2 = rand_below(state, <uint32_t>k)
        draws = 0
        while (a2 == a0 or a2 == a1) and draws < _MAX_DRAW:
            a2 = rand_below(state, <uint32_t>k)
            draws += 1
        p0 = pts + 3 * nb[a0]
        p1 = pts + 3 * nb[a1]
        p2 = pts + 3 * nb[a2]
        e1x = p1[0] - p0[0]
        e1y = p1[1] - p0[1]
        e1z = p1[2] - p0[2]
        e2x = p2[0] - p0[0]
        e2y = p2[1] - p0[1]
        e2z = p2[2] - p0[2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        nrm = nx * nx + ny * ny + nz * nz
        l1 = e1x * e1x + e1y * e1y + e1z * e1z
        l2 = e2x * e2x + e2y * e2y + e2z * e2z
        # |e1 x e2| = |e1| |e2| sin(angle): compared squared, no sqrt spent on
        # triplets that do not vote.
        if not (nrm > (_COLLINEAR * _COLLINEAR) * l1 * l2) or not (nrm > 0.0):
            continue
        nrm = sqrt(nrm)
        nx /= nrm
        ny /= nrm
        nz /= nrm
        ux = rot[0] * nx + rot[1] * ny + rot[2] * nz
        uy = rot[3] * nx + rot[4] * ny + rot[5] * nz
        uz = rot[6] * nx + rot[7] * ny + rot[8] * nz
        if uz < 0.0:
            ux = -ux
            uy = -uy
            uz = -uz
        b = _bin_of(ux, uy, uz, n_rings, ring_z, ring_start, ring_bins, edges)
        # Votes of one bin are summed with one sign (that of the bin's center).
        # u is the rotated vote after the flip into u_z >= 0; n, unrotated,
        # takes the same flips.
        sgn = 1.0 if ux * centre[3 * b] + uy * centre[3 * b + 1] + uz * centre[3 * b + 2] >= 0.0 else -1.0
        if (rot[6] * nx + rot[7] * ny + rot[8] * nz) < 0.0:
            sgn = -sgn
        acc[3 * b] += sgn * nx
        acc[3 * b + 1] += sgn * ny
        acc[3 * b + 2] += sgn * nz
        count[b] += 1
        votes += 1
        # Leading and second bins (distinct), ties to the earlier leader.
        if b == i1:
            pass
        elif i1 < 0 or count[b] > count[i1]:
            i2 = i1
            i1 = b
        elif i2 < 0 or (b != i2 and count[b] > count[i2]):
            i2 = b
        lead = count[i1] - (count[i2] if i2 >= 0 else 0)
        # Stop once share(i1) - share(i2) > 2 / sqrt(votes).
        if lead * lead > 4 * votes:
            break
    if votes == 0:
        return 0.0
    nx = acc[3 * i1]
    ny = acc[3 * i1 + 1]
    nz = acc[3 * i1 + 2]
    nrm = sqrt(nx * nx + ny * ny + nz * nz)
    if not (nrm > 0.0):
        return 0.0
    normal[0] = nx / nrm
    normal[1] = ny / nrm
    normal[2] = nz / nrm
    return <double>count[i1] / <double>votes


cdef void _fallback(const double* pts, const int64_t* nb, int64_t k, double* out) noexcept nogil:
    """Normal of a neighborhood where no triplet voted (coincident or
    collinear points): a unit vector orthogonal to the direction to the
    farthest neighbor, or (1, 0, 0) when all points coincide."""
    cdef int64_t i
    cdef double dx, dy, dz, d2, best = 0.0, lx = 0.0, ly = 0.0, lz = 0.0, ax, ay, az, nx, ny, nz, nrm
    cdef const double* q = pts + 3 * nb[0]
    for i in range(1, k):
        dx = pts[3 * nb[i]] - q[0]
        dy = pts[3 * nb[i] + 1] - q[1]
        dz = pts[3 * nb[i] + 2] - q[2]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 > best:
            best = d2
            lx = dx
            ly = dy
            lz = dz
    out[0] = 1.0
    out[1] = 0.0
    out[2] = 0.0
    if not (best > 0.0):
        return
    # Cross with the axis least aligned with the line.
    ax = 0.0
    ay = 0.0
    az = 0.0
    if fabs(lx) <= fabs(ly) and fabs(lx) <= fabs(lz):
        ax = 1.0
    elif fabs(ly) <= fabs(lz):
        ay = 1.0
    else:
        az = 1.0
    nx = ly * az - lz * ay
    ny = lz * ax - lx * az
    nz = lx * ay - ly * ax
    nrm = sqrt(nx * nx + ny * ny + nz * nz)
    if nrm > 0.0:
        out[0] = nx / nrm
        out[1] = ny / nrm
        out[2] = nz / nrm


cdef void _point_normal(const double* pts, const int64_t* nb, int64_t k, uint64_t seed,
                        int64_t local, int64_t n_triplets, int64_t n_rot, double cos_tol,
                        int64_t n_rings, const double* ring_z, const int64_t* ring_start,
                        const int64_t* ring_bins, const double* edges, const double* centre,
                        int64_t n_bins, int64_t* count, double* acc,
                        double* nrms, double* conf, int32_t* used, double* out) noexcept nogil:
    cdef uint64_t state
    cdef double rot[9]
    cdef int64_t r, passes, i, j, best_i
    cdef double sx, sy, sz, sc, best_c, d, nrm
    cdef bint any_vote = False
    # The point's private stream: its object's seed and its index in the object.
    state = seed ^ (<uint64_t>local * <uint64_t>0xD1B54A32D192ED03)
    state = splitmix64(&state)
    passes = n_rot if n_rot > 0 else 1
    for r in range(passes):
        if n_rot > 0:
            _random_rotation(&state, rot)
        else:
            for i in range(9):
                rot[i] = 1.0 if i % 4 == 0 else 0.0
        conf[r] = _one_pass(pts, nb, k, &state, rot, n_triplets, n_rings, ring_z, ring_start,
                            ring_bins, edges, centre, n_bins, count, acc, nrms + 3 * r)
        used[r] = 0
        if conf[r] > 0.0:
            any_vote = True
        else:
            used[r] = 1
    if not any_vote:
        _fallback(pts, nb, k, out)
        return
    # Greedy grouping of the passes' normals (unoriented axes).
    best_c = -1.0
    out[0] = 1.0
    out[1] = 0.0
    out[2] = 0.0
    while True:
        i = -1
        for j in range(passes):
            if not used[j] and (i < 0 or conf[j] > conf[i]):
                i = j
        if i < 0:
            break
        used[i] = 1
        sx = conf[i] * nrms[3 * i]
        sy = conf[i] * nrms[3 * i + 1]
        sz = conf[i] * nrms[3 * i + 2]
        sc = conf[i]
        for j in range(passes):
            if used[j]:
                continue
            d = nrms[3 * i] * nrms[3 * j] + nrms[3 * i + 1] * nrms[3 * j + 1] + nrms[3 * i + 2] * nrms[3 * j + 2]
            if fabs(d) > cos_tol:
                used[j] = 1
                if d < 0.0:
                    sx -= conf[j] * nrms[3 * j]
                    sy -= conf[j] * nrms[3 * j + 1]
                    sz -= conf[j] * nrms[3 * j + 2]
                else:
                    sx += conf[j] * nrms[3 * j]
                    sy += conf[j] * nrms[3 * j + 1]
                    sz += conf[j] * nrms[3 * j + 2]
                sc += conf[j]
        if sc > best_c:
            nrm = sqrt(sx * sx + sy * sy + sz * sz)
            if nrm > 0.0:
                best_c = sc
                out[0] = sx / nrm
                out[1] = sy / nrm
                out[2] = sz / nrm


def ring_layout(int64_t n_phi):
    """Rings of the half-sphere accumulator for ``n_phi`` slices of the whole
    sphere (polar step ``pi / n_phi``): ``(ring_start, ring_bins, ring_z,
    edges, centers)``, the first bin of each ring, its number of bins (about
    its area over ``(pi / n_phi)^2``), the cosine of its lower polar bound,
    the pseudo angles (see ``_pseudo_angle``) of the azimuth boundaries
    between its bins (equal steps of azimuth, from ``ring_start``, one unused
    slot per ring), and the unit center direction of every bin (on the
    equator for the last ring, whose bins identify azimuths ``theta`` and
    ``theta + pi``)."""
    cdef double dphi = _PI / n_phi
    cdef double ref = dphi * dphi
    cdef double lo, hi, area
    starts = []
    bins = []
    zs = []
    phis = []
    cdef int64_t j = 0, total = 0, m
    while True:
        lo = 0.0 if j == 0 else (j - 0.5) * dphi
        if lo >= 0.5 * _PI - 1e-12:
            break
        hi = 0.5 * dphi if j == 0 else (j + 0.5) * dphi
        if hi > 0.5 * _PI:
            hi = 0.5 * _PI
        area = 2.0 * _PI * (cos(lo) - cos(hi))
        m = <int64_t>floor(area / ref + 0.5)
        if m < 1:
            m = 1
        starts.append(total)
        bins.append(m)
        zs.append(cos(hi))
        phis.append(j * dphi)
        total += m
        j += 1
    phis[len(phis) - 1] = 0.5 * _PI
    centres = []
    edges = np.full(total, 4.0)
    for j in range(len(bins)):
        span = _PI if j == len(bins) - 1 else 2.0 * _PI
        for b in range(bins[j]):
            th = (b + 0.5) * span / bins[j]
            centres.append((np.sin(phis[j]) * np.cos(th), np.sin(phis[j]) * np.sin(th), np.cos(phis[j])))
            if b > 0:
                th = b * span / bins[j]
                edges[starts[j] + b - 1] = _pseudo_angle(cos(th), sin(th))
    return (np.array(starts, dtype=np.int64), np.array(bins, dtype=np.int64),
            np.array(zs, dtype=np.float64), edges, np.ascontiguousarray(centres, dtype=np.float64))


def hough_normals(const double[:, ::1] points, const int64_t[:, ::1] neighbors,
                  const int64_t[::1] n_valid, const uint64_t[::1] seeds, const int64_t[::1] local,
                  int64_t n_triplets, int64_t n_phi, int64_t n_rotations, double cluster_angle,
                  double[:, ::1] out, int num_threads):
    """Fill ``out[i]`` with the unoriented Hough normal of point ``i``.

    ``neighbors[i, :n_valid[i]]`` are global row indices into ``points`` of
    point ``i``'s neighborhood; ``seeds[i]`` is its object's seed and
    ``local[i]`` its index in the object. The kernel checks every index
    against ``points`` and raises ValueError on any out of range.
    """
    cdef Py_ssize_t n = out.shape[0], n_pts = points.shape[0]
    cdef Py_ssize_t kmax = neighbors.shape[1]
    cdef Py_ssize_t i, j, tid
    cdef int64_t n_rings, n_bins, passes
    if n == 0:
        return
    if neighbors.shape[0] != n or n_valid.shape[0] != n or seeds.shape[0] != n or local.shape[0] != n:
        raise ValueError("hough_normals: per-point arrays differ in length")
    if n_phi < 2 or n_triplets < 1 or n_rotations < 0 or num_threads < 1:
        raise ValueError("hough_normals: invalid parameters")
    nv = np.asarray(n_valid)
    if nv.min() < 3 or nv.max() > kmax or nv.max() >= 2 ** 31:
        raise ValueError("hough_normals: neighbourhoods must hold 3 to neighbors.shape[1] points")
    nbs = np.asarray(neighbors)
    mask = np.arange(kmax)[None, :] < nv[:, None]
    if (nbs[mask] < 0).any() or (nbs[mask] >= n_pts).any():
        raise ValueError("hough_normals: neighbour index out of range")
    rs, rb, rz, re, rc = ring_layout(n_phi)
    cdef const int64_t[::1] ring_start = rs
    cdef const int64_t[::1] ring_bins = rb
    cdef const double[::1] ring_z = rz
    cdef const double[::1] edges = re
    cdef const double[:, ::1] centre = rc
    n_rings = rs.shape[0]
    n_bins = int(rb.sum())
    passes = n_rotations if n_rotations > 0 else 1
    count_arr = np.zeros((num_threads, n_bins), dtype=np.int64)
    acc_arr = np.zeros((num_threads, 3 * n_bins), dtype=np.float64)
    nrm_arr = np.zeros((num_threads, 3 * passes), dtype=np.float64)
    conf_arr = np.zeros((num_threads, passes), dtype=np.float64)
    used_arr = np.zeros((num_threads, passes), dtype=np.int32)
    cdef int64_t[:, ::1] count = count_arr
    cdef double[:, ::1] acc = acc_arr
    cdef double[:, ::1] nrms = nrm_arr
    cdef double[:, ::1] conf = conf_arr
    cdef int32_t[:, ::1] used = used_arr
    cdef double cos_tol = cos(cluster_angle)
    with nogil:
        for i in prange(n, num_threads=num_threads, schedule="dynamic", chunksize=16):
            tid = threadid()
            _point_normal(&points[0, 0], &neighbors[i, 0], n_valid[i], seeds[i], local[i],
                          n_triplets, n_rotations, cos_tol, n_rings, &ring_z[0], &ring_start[0],
                          &ring_bins[0], &edges[0], &centre[0, 0], n_bins, &count[tid, 0], &acc[tid, 0], &nrms[tid, 0],
                          &conf[tid, 0], &used[tid, 0], &out[i, 0])
