# cython: language_level=3
"""FLANN's single k-d tree and its exact radius search, in single precision.

PCL's ``KdTree`` wraps FLANN's ``KDTreeSingleIndex`` (middle split, leaf size
15); an unsorted radius search returns neighbors in that tree's depth-first
order, best child first, and PCL's GRSD (the normal of the first neighbor)
and CVFH (the order of its region growing) depend on that order. Shared by
GRSD's kernel (radius search around voxel centroids) and CVFH's (every
point's neighbors). For ``n`` points the caller provides:

- ``vind``: ``n`` int32 (the tree's point order);
- ``ni``, ``nf``: ``5 * 2n`` int32 and ``2 * 2n`` float (node arrays);
- ``stk``, ``sbox``: ``3 * 2n`` int32 and ``6 * 2n`` float (the build's
  stack), reused by the search as ``2n`` int32 and ``4 * 2n`` float;
- ``hits``, ``hd2``: ``n`` int32 and ``n`` float (one search's neighbors
  and their squared distances);
- ``root_box``: the exact bounds of the points (lows, then highs).
"""

from libc.stdint cimport int32_t

cdef enum:
    LEAF_MAX = 15       # FLANN leaf size PCL's KdTreeFLANN asks for


# ---------------------------------------------------------------- k-d tree
# Node arrays (n_nodes <= 2 n - 1):
#   ni[5 * id + 0..4] = left, right (leaf point range), divfeat (-1 for a leaf),
#                       child1, child2
#   nf[2 * id + 0..1] = divlow, divhigh

cdef inline int build_tree(const float* p, int n, int32_t* vind, int32_t* ni, float* nf,
                           int32_t* stk, float* sbox) noexcept nogil:
    """FLANN 1.9 KDTreeSingleIndex::buildIndex (middleSplit, leaf size 15),
    iteratively. Returns the number of nodes (the root is node 0)."""
    cdef int i, d, n_nodes = 1, top = 0, node, left, right, count
    cdef int cutfeat, k, lo_i, hi_i, lim1, lim2, idx, c1, c2, t
    cdef float mn, mx, span, max_span, cutval, v
    cdef float* box
    for i in range(n):
        vind[i] = i
    # root box: exact bounds
    box = sbox
    for d in range(3):
        box[d] = p[d]
        box[3 + d] = p[d]
    for i in range(1, n):
        for d in range(3):
            v = p[3 * i + d]
            if v < box[d]:
                box[d] = v
            if v > box[3 + d]:
                box[3 + d] = v
    stk[0] = 0
    stk[1] = 0
    stk[2] = n
    top = 1
    while top > 0:
        top -= 1
        node = stk[3 * top]
        left = stk[3 * top + 1]
        right = stk[3 * top + 2]
        box = sbox + 6 * top
        count = right - left
        if count <= LEAF_MAX:
            ni[5 * node] = left
            ni[5 * node + 1] = right
            ni[5 * node + 2] = -1
            ni[5 * node + 3] = -1
            ni[5 * node + 4] = -1
            continue
        # middleSplit: largest side of the approximate box, refined by exact spreads
        max_span = box[3] - box[0]
        cutfeat = 0
        for d in range(1, 3):
            span = box[3 + d] - box[d]
            if span > max_span:
                max_span = span
                cutfeat = d
        mn = p[3 * vind[left] + cutfeat]
        mx = mn
        for i in range(left + 1, right):
            v = p[3 * vind[i] + cutfeat]
            if v < mn:
                mn = v
            if v > mx:
                mx = v
        cutval = (mn + mx) / <float>2.0
        max_span = mx - mn
        k = cutfeat
        for d in range(3):
            if d == k:
                continue
            span = box[3 + d] - box[d]
            if span > max_span:
                mn = p[3 * vind[left] + d]
                mx = mn
                for i in range(left + 1, right):
                    v = p[3 * vind[i] + d]
                    if v < mn:
                        mn = v
                    if v > mx:
                        mx = v
                span = mx - mn
                if span > max_span:
                    max_span = span
                    cutfeat = d
                    cutval = (mn + mx) / <float>2.0
        # planeSplit: < cutval | == cutval | > cutval
        lo_i = 0
        hi_i = count - 1
        while True:
            while lo_i <= hi_i and p[3 * vind[left + lo_i] + cutfeat] < cutval:
                lo_i += 1
            while lo_i <= hi_i and p[3 * vind[left + hi_i] + cutfeat] >= cutval:
                hi_i -= 1
            if lo_i > hi_i:
                break
            t = vind[left + lo_i]
            vind[left + lo_i] = vind[left + hi_i]
            vind[left + hi_i] = t
            lo_i += 1
            hi_i -= 1
        lim1 = lo_i
        hi_i = count - 1
        while True:
            while lo_i <= hi_i and p[3 * vind[left + lo_i] + cutfeat] <= cutval:
                lo_i += 1
            while lo_i <= hi_i and p[3 * vind[left + hi_i] + cutfeat] > cutval:
                hi_i -= 1
            if lo_i > hi_i:
                break
            t = vind[left + lo_i]
            vind[left + lo_i] = vind[left + hi_i]
            vind[left + hi_i] = t
            lo_i += 1
            hi_i -= 1
        lim2 = lo_i
        if lim1 > count // 2:
            idx = lim1
        elif lim2 < count // 2:
            idx = lim2
        else:
            idx = count // 2
        c1 = n_nodes
        c2 = n_nodes + 1
        n_nodes += 2
        ni[5 * node] = left
        ni[5 * node + 1] = right
        ni[5 * node + 2] = cutfeat
        ni[5 * node + 3] = c1
        ni[5 * node + 4] = c2
        # divlow / divhigh: the children's exact bounds along cutfeat
        mx = p[3 * vind[left] + cutfeat]
        for i in range(left + 1, left + idx):
            v = p[3 * vind[i] + cutfeat]
            if v > mx:
                mx = v
        mn = p[3 * vind[left + idx] + cutfeat]
        for i in range(left + idx + 1, right):
            v = p[3 * vind[i] + cutfeat]
            if v < mn:
                mn = v
        nf[2 * node] = mx
        nf[2 * node + 1] = mn
        # children's approximate boxes: the parent's with the cut applied;
        # child2 pushed first (it reuses this slot), child1 on top
        for d in range(6):
            sbox[6 * (top + 1) + d] = box[d]
        box[cutfeat] = cutval                       # slot top, child2: low = cutval
        sbox[6 * (top + 1) + 3 + cutfeat] = cutval  # slot top + 1, child1: high = cutval
        stk[3 * top] = c2
        stk[3 * top + 1] = left + idx
        stk[3 * top + 2] = right
        stk[3 * (top + 1)] = c1
        stk[3 * (top + 1) + 1] = left
        stk[3 * (top + 1) + 2] = left + idx
        top += 2
    return n_nodes


cdef inline int radius_search(const float* p, const float* q, float r2, const int32_t* vind,
                              const int32_t* ni, const float* nf, const float* root_box,
                              int32_t* sn, float* sf, int32_t* hits, float* hd2) noexcept nogil:
    """FLANN's exact radius search (squared distance < r2, single precision),
    hits in the tree's depth-first order, best child first. Returns the count."""
    cdef int top = 0, node, i, j, feat, n_hits = 0, best, other
    cdef float mind, d0, d1, d2, dist, diff, val, diff1, diff2, cut, dst, nm
    cdef float* ent
    # initial distances to the root box
    sf[0] = 0.0
    for j in range(3):
        sf[1 + j] = 0.0
        if q[j] < root_box[j]:
            diff = q[j] - root_box[j]
            sf[1 + j] = diff * diff
            sf[0] = sf[0] + sf[1 + j]
        if q[j] > root_box[3 + j]:
            diff = q[j] - root_box[3 + j]
            sf[1 + j] = diff * diff
            sf[0] = sf[0] + sf[1 + j]
    sn[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = sn[top]
        ent = sf + 4 * top
        feat = ni[5 * node + 2]
        if feat < 0:
            for i in range(ni[5 * node], ni[5 * node + 1]):
                j = vind[i]
                diff = q[0] - p[3 * j]
                dist = diff * diff
                diff = q[1] - p[3 * j + 1]
                dist = dist + diff * diff
                diff = q[2] - p[3 * j + 2]
                dist = dist + diff * diff
                if dist < r2:
                    hits[n_hits] = j
                    hd2[n_hits] = dist
                    n_hits += 1
            continue
        val = q[feat]
        diff1 = val - nf[2 * node]
        diff2 = val - nf[2 * node + 1]
        if diff1 + diff2 < 0:
            best = ni[5 * node + 3]
            other = ni[5 * node + 4]
            diff = val - nf[2 * node + 1]
        else:
            best = ni[5 * node + 4]
            other = ni[5 * node + 3]
            diff = val - nf[2 * node]
        cut = diff * diff
        mind = ent[0]
        d0 = ent[1]
        d1 = ent[2]
        d2 = ent[3]
        dst = ent[1 + feat]
        nm = mind + cut - dst
        # the other child goes below the best one (visited after its subtree)
        if nm <= r2:
            sn[top] = other
            sf[4 * top] = nm
            sf[4 * top + 1] = d0
            sf[4 * top + 2] = d1
            sf[4 * top + 3] = d2
            sf[4 * top + 1 + feat] = cut
            top += 1
        sn[top] = best
        sf[4 * top] = mind
        sf[4 * top + 1] = d0
        sf[4 * top + 2] = d1
        sf[4 * top + 3] = d2
        top += 1
    return n_hits
