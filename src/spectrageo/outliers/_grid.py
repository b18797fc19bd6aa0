"""Exact k-nearest-neighbour queries on a Morton-sorted cloud: a uniform grid, then an octree.

On the Z-order of the 21-bit quantised coordinates the points of every cell of side ``2^L`` quanta
are one contiguous run, for every level ``L``, so the levels nest into an implicit octree built in
O(n). *Grid pass*: at the level ``L0`` of about :data:`TARGET_PER_CELL` points per cell, a query
scans the ``3 x 3 x 3`` cells around its own and is certified exact when its ``k``-th distance is
below the distance to the block's faces. *Octree pass* for the other queries (isolated points,
borders): a nearest-first branch-and-bound over the levels above ``L0``. Both are exact: the
lists equal a kd-tree's up to the order of equidistant points.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._threads import numba_threads

#: Points per cell, averaged over points, of the first grid level.
TARGET_PER_CELL = 8.0
#: The octree search scans a cell's points directly once it holds at most this many.
SCAN_RUN = 24
#: Largest candidate count of a grid cell's block copied to a contiguous buffer (larger blocks
#: are scanned cell by cell, skipping cells farther than the current k-th distance).
BUFMAX = 1024
#: Coarsest octree level: the first with at most this many occupied cells.
TOP_CELLS = 64
#: Bits per axis of the Morton codes.
BITS = 21
#: Cost of an octree-pass query in grid-pass queries (the ``serial_below`` rule of
#: :func:`knn_sorted`): they are far from the data, or on its borders.
TREE_QUERY_COST = 8


@njit(cache=True, inline="always")
def _spread3(x):  # pragma: no cover - compiled
    """Insert two zero bits between the 21 low bits of ``x`` (uint64)."""
    x = x & np.uint64(0x1FFFFF)
    x = (x | (x << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x1249249249249249)
    return x


@njit(cache=True, inline="always")
def _compact3(x):  # pragma: no cover - compiled
    """Inverse of :func:`_spread3`: every third bit of ``x`` into the 21 low bits."""
    x = x & np.uint64(0x1249249249249249)
    x = (x | (x >> np.uint64(2))) & np.uint64(0x10C30C30C30C30C3)
    x = (x | (x >> np.uint64(4))) & np.uint64(0x100F00F00F00F00F)
    x = (x | (x >> np.uint64(8))) & np.uint64(0x1F0000FF0000FF)
    x = (x | (x >> np.uint64(16))) & np.uint64(0x1F00000000FFFF)
    x = (x | (x >> np.uint64(32))) & np.uint64(0x1FFFFF)
    return x


@njit(cache=True)
def morton_encode(q):  # pragma: no cover - compiled
    """Morton codes of the (n, 3) uint64 quantised coordinates ``q``."""
    n = q.shape[0]
    out = np.empty(n, dtype=np.uint64)
    for i in range(n):
        out[i] = (
            _spread3(q[i, 0])
            | (_spread3(q[i, 1]) << np.uint64(1))
            | (_spread3(q[i, 2]) << np.uint64(2))
        )
    return out


#: Multiplier of the hash of cell keys (Fibonacci hashing: ``2^64`` over the golden ratio).
_HASH_MUL = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True)
def _cell_table(keys):  # pragma: no cover - compiled
    """Open-addressing hash table of the occupied cells ``keys`` (distinct): slots hold the
    position of a key in ``keys`` (-1: empty); at most half of the ``2^b`` slots are used.
    Returns the table and ``64 - b`` (the shift of :func:`_find_cell`)."""
    b = 1
    while (1 << b) < 2 * keys.shape[0]:
        b += 1
    table = np.full(1 << b, -1, dtype=np.int64)
    mask = (1 << b) - 1
    shift = np.uint64(64 - b)
    for p in range(keys.shape[0]):
        h = np.int64((keys[p] * _HASH_MUL) >> shift)
        while table[h] >= 0:
            h = (h + 1) & mask
        table[h] = p
    return table, shift


@njit(cache=True, inline="always")
def _find_cell(table, shift, keys, key):  # pragma: no cover - compiled
    """Position of ``key`` in ``keys`` (the cells of :func:`_cell_table`), or -1."""
    mask = table.shape[0] - 1
    h = np.int64((key * _HASH_MUL) >> shift)
    while True:
        p = table[h]
        if p < 0 or keys[p] == key:
            return p
        h = (h + 1) & mask


def _offsets() -> np.ndarray:
    o = [(dx, dy, dz) for dz in (-1, 0, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    o.sort(key=lambda t: abs(t[0]) + abs(t[1]) + abs(t[2]))
    return np.array(o, dtype=np.int64)


#: The 27 cell offsets of a block, the centre first, then faces, edges and corners.
_OFFSETS = _offsets()


@njit(cache=True, inline="always")
def _insert(bd, bi, cnt, k, d, j):  # pragma: no cover - compiled
    """Insert ``(d, j)`` into the ascending top-``k`` list of ``cnt`` entries; new count."""
    if cnt < k:
        pos = cnt
        cnt += 1
    else:
        pos = k - 1
    while pos > 0 and bd[pos - 1] > d:
        bd[pos] = bd[pos - 1]
        bi[pos] = bi[pos - 1]
        pos -= 1
    bd[pos] = d
    bi[pos] = j
    return cnt


@njit(cache=True, inline="always")
def _write(qi, bd, bi, k, out_idx, dmean, dlast, dzero):  # pragma: no cover - compiled
    """Neighbours of query ``qi``, their mean and ``k``-th distance, and whether the nearest is
    at distance 0."""
    acc = 0.0
    for c in range(k):
        out_idx[qi, c] = bi[c]
        acc += np.sqrt(bd[c])
    dmean[qi] = acc / k
    dlast[qi] = np.sqrt(bd[k - 1])
    dzero[qi] = bd[0] == 0.0


@njit(cache=True, parallel=True)
def _grid_pass(
    X, ukeys, ustarts, table, shift, Q, gstart, gkeys, self_idx, k, L, lo, w, out_idx, dmean,
    dlast, dzero, bound,
):  # pragma: no cover - compiled  # fmt: skip
    """Grid pass at level ``L``: the ``k`` nearest data points ``X`` of every query ``Q``.

    Queries are grouped by cell (``gstart``, ``gkeys``); ``ukeys`` / ``ustarts`` are the occupied
    data cells and their runs, found through the hash table ``table`` (:func:`_cell_table`).
    Certified queries get their neighbours and ``bound[q] = -1``; the others keep in
    ``bound[q]`` the squared ``k``-th distance found, for the octree pass.
    """
    ng = gkeys.shape[0]
    maxc = (1 << (BITS - L)) - 1
    n_chunks = min(ng, 1024)
    self_query = self_idx.shape[0] == 0
    for ch in prange(n_chunks):
        g0 = ch * ng // n_chunks
        g1 = (ch + 1) * ng // n_chunks
        bd = np.empty(k)
        bi = np.empty(k, dtype=np.int64)
        rs = np.empty(27, dtype=np.int64)
        re = np.empty(27, dtype=np.int64)
        ro = np.empty((27, 3), dtype=np.int64)
        bxs = np.empty(BUFMAX)
        bys = np.empty(BUFMAX)
        bzs = np.empty(BUFMAX)
        dd = np.empty(BUFMAX)
        bjs = np.empty(BUFMAX, dtype=np.int64)
        for g in range(g0, g1):
            key = gkeys[g]
            cx = np.int64(_compact3(key))
            cy = np.int64(_compact3(key >> np.uint64(1)))
            cz = np.int64(_compact3(key >> np.uint64(2)))
            nr = 0
            for o in range(27):  # the cell itself, then faces, edges, corners
                x = cx + _OFFSETS[o, 0]
                y = cy + _OFFSETS[o, 1]
                z = cz + _OFFSETS[o, 2]
                if x < 0 or x > maxc or y < 0 or y > maxc or z < 0 or z > maxc:
                    continue
                nk = (
                    _spread3(np.uint64(x))
                    | (_spread3(np.uint64(y)) << np.uint64(1))
                    | (_spread3(np.uint64(z)) << np.uint64(2))
                )
                p = _find_cell(table, shift, ukeys, nk)
                if p >= 0:
                    rs[nr] = ustarts[p]
                    re[nr] = ustarts[p + 1]
                    ro[nr, 0] = _OFFSETS[o, 0]
                    ro[nr, 1] = _OFFSETS[o, 1]
                    ro[nr, 2] = _OFFSETS[o, 2]
                    nr += 1
            nb = 0
            for r in range(nr):
                nb += re[r] - rs[r]
            if nb <= BUFMAX:
                c = 0
                for r in range(nr):
                    for j in range(rs[r], re[r]):
                        bxs[c] = X[j, 0]
                        bys[c] = X[j, 1]
                        bzs[c] = X[j, 2]
                        bjs[c] = j
                        c += 1
            # faces of the query's cell, and of the block (inf where no cell lies beyond)
            x0 = lo[0] + cx * w
            y0 = lo[1] + cy * w
            z0 = lo[2] + cz * w
            bx0 = x0 - w if cx >= 1 else -np.inf
            by0 = y0 - w if cy >= 1 else -np.inf
            bz0 = z0 - w if cz >= 1 else -np.inf
            bx1 = x0 + 2 * w if cx + 2 <= maxc else np.inf
            by1 = y0 + 2 * w if cy + 2 <= maxc else np.inf
            bz1 = z0 + 2 * w if cz + 2 <= maxc else np.inf
            for qi in range(gstart[g], gstart[g + 1]):
                qx = Q[qi, 0]
                qy = Q[qi, 1]
                qz = Q[qi, 2]
                gx0 = (qx - x0) ** 2  # squared gaps to the faces of the query's own cell
                gx1 = (x0 + w - qx) ** 2
                gy0 = (qy - y0) ** 2
                gy1 = (y0 + w - qy) ** 2
                gz0 = (qz - z0) ** 2
                gz1 = (z0 + w - qz) ** 2
                me = qi if self_query else self_idx[qi]
                cnt = 0
                worst = np.inf
                if nb <= BUFMAX:
                    for c in range(nb):
                        ddx = bxs[c] - qx
                        ddy = bys[c] - qy
                        ddz = bzs[c] - qz
                        dd[c] = ddx * ddx + ddy * ddy + ddz * ddz
                    c = 0
                    while c < nb and cnt < k:  # the first k candidates
                        j = bjs[c]
                        if j != me:
                            cnt = _insert(bd, bi, cnt, k, dd[c], j)
                        c += 1
                    if cnt == k:
                        worst = bd[k - 1]
                    while c < nb:  # then only those nearer than the k-th
                        d = dd[c]
                        if d < worst:
                            j = bjs[c]
                            if j != me:
                                _insert(bd, bi, k, k, d, j)
                                worst = bd[k - 1]
                        c += 1
                else:
                    for r in range(nr):
                        if cnt == k:  # skip a cell that cannot hold a nearer point
                            bx = gx0 if ro[r, 0] < 0 else (gx1 if ro[r, 0] > 0 else 0.0)
                            by = gy0 if ro[r, 1] < 0 else (gy1 if ro[r, 1] > 0 else 0.0)
                            bz = gz0 if ro[r, 2] < 0 else (gz1 if ro[r, 2] > 0 else 0.0)
                            if bx + by + bz > worst:
                                continue
                        for j in range(rs[r], re[r]):
                            ddx = X[j, 0] - qx
                            ddy = X[j, 1] - qy
                            ddz = X[j, 2] - qz
                            d = ddx * ddx + ddy * ddy + ddz * ddz
                            if (cnt == k and d >= worst) or j == me:
                                continue
                            cnt = _insert(bd, bi, cnt, k, d, j)
                            if cnt == k:
                                worst = bd[k - 1]

                if cnt < k:
                    bound[qi] = np.inf
                    continue
                m = min(qx - bx0, bx1 - qx, qy - by0, by1 - qy, qz - bz0, bz1 - qz) - 1e-9 * w
                if m <= 0.0 or worst >= m * m:
                    bound[qi] = worst
                    continue
                _write(qi, bd, bi, k, out_idx, dmean, dlast, dzero)
                bound[qi] = -1.0


@njit(cache=True)
def _cell_boxes(ckey, clev, wl, lo):  # pragma: no cover - compiled
    """The (slightly enlarged) box of every octree cell: ``(x0, y0, z0, x1, y1, z1)`` rows, the
    cell of key ``ckey[f]`` and side ``wl[clev[f]]`` grown by ``1e-9`` of its side."""
    out = np.empty((ckey.shape[0], 6))
    for f in range(ckey.shape[0]):
        key = ckey[f]
        w = wl[clev[f]]
        e = 1e-9 * w
        w2 = w + 2 * e
        for a in range(3):
            x0 = lo[a] + np.float64(_compact3(key >> np.uint64(a))) * w - e
            out[f, a] = x0
            out[f, 3 + a] = x0 + w2
    return out


@njit(cache=True, inline="always")
def _box_dist2(box, f, qx, qy, qz):  # pragma: no cover - compiled
    """Squared distance from a point to the box ``f`` of :func:`_cell_boxes`."""
    gx = max(box[f, 0] - qx, 0.0, qx - box[f, 3])
    gy = max(box[f, 1] - qy, 0.0, qy - box[f, 4])
    gz = max(box[f, 2] - qz, 0.0, qz - box[f, 5])
    return gx * gx + gy * gy + gz * gz


@njit(cache=True, parallel=True)
def _tree_pass(
    X,
    box,
    cbeg,
    cend,
    clev,
    chlo,
    chhi,
    top_lo,
    top_hi,
    Q,
    sel,
    self_idx,
    bound,
    k,
    out_idx,
    dmean,
    dlast,
    dzero,
):  # pragma: no cover - compiled
    """Octree pass: exact ``k`` nearest data points of the queries ``Q[sel]``.

    Cells of all levels are flat arrays: box ``box`` (:func:`_cell_boxes`), data run
    ``cbeg:cend``, level ``clev`` (0 = the grid level), children ``chlo:chhi`` (flat indices; none
    for level 0); the coarsest level is ``top_lo:top_hi``. ``bound[q]`` (squared distance)
    prunes before ``k`` points are found. ``self_idx`` as in :func:`_grid_pass`.
    """
    m = sel.shape[0]
    nlev = clev[top_lo] + 1
    self_query = self_idx.shape[0] == 0
    n_chunks = min(m, 1024)
    for ch in prange(n_chunks):
        t0 = ch * m // n_chunks
        t1 = (ch + 1) * m // n_chunks
        bd = np.empty(k)
        bi = np.empty(k, dtype=np.int64)
        ntop = top_hi - top_lo
        cap = ntop + 8 * nlev + 8
        stk = np.empty(cap, dtype=np.int64)
        sd = np.empty(max(ntop, 8))
        si = np.empty(max(ntop, 8), dtype=np.int64)
        for t in range(t0, t1):
            qi = sel[t]
            qx = Q[qi, 0]
            qy = Q[qi, 1]
            qz = Q[qi, 2]
            me = qi if self_query else self_idx[qi]
            b0 = bound[qi]
            cnt = 0
            worst = np.inf
            # the top cells, pushed farthest first
            nc = 0
            for f in range(top_lo, top_hi):
                d = _box_dist2(box, f, qx, qy, qz)
                pos = nc
                nc += 1
                while pos > 0 and sd[pos - 1] < d:
                    sd[pos] = sd[pos - 1]
                    si[pos] = si[pos - 1]
                    pos -= 1
                sd[pos] = d
                si[pos] = f
            sp = 0
            for c in range(nc):
                if sd[c] <= b0:
                    stk[sp] = si[c]
                    sp += 1
            while sp > 0:
                sp -= 1
                f = stk[sp]
                lim = worst if cnt == k else b0
                if _box_dist2(box, f, qx, qy, qz) > lim:
                    continue
                if clev[f] == 0 or cend[f] - cbeg[f] <= SCAN_RUN:
                    for j in range(cbeg[f], cend[f]):
                        ddx = X[j, 0] - qx
                        ddy = X[j, 1] - qy
                        ddz = X[j, 2] - qz
                        d = ddx * ddx + ddy * ddy + ddz * ddz
                        if j == me or (cnt == k and d >= worst) or (cnt < k and d > b0):
                            continue
                        cnt = _insert(bd, bi, cnt, k, d, j)
                        if cnt == k:
                            worst = bd[k - 1]
                    continue
                nc = 0
                for c in range(chlo[f], chhi[f]):
                    d = _box_dist2(box, c, qx, qy, qz)
                    if d > lim:
                        continue
                    pos = nc
                    nc += 1
                    while pos > 0 and sd[pos - 1] < d:
                        sd[pos] = sd[pos - 1]
                        si[pos] = si[pos - 1]
                        pos -= 1
                    sd[pos] = d
                    si[pos] = c
                for c in range(nc):
                    stk[sp] = si[c]
                    sp += 1
            _write(qi, bd, bi, k, out_idx, dmean, dlast, dzero)


@njit(cache=True, nogil=True)
def radix_argsort(keys):  # pragma: no cover - compiled
    """``np.argsort(keys, kind="stable")`` of unsigned 64-bit ``keys``: a least-significant-digit
    radix sort of 11-bit digits, skipping the digits every key shares."""
    n = keys.shape[0]
    order = np.arange(n)
    if n < 2:
        return order
    count = np.zeros((6, 2049), dtype=np.int64)  # one histogram per digit, in one sweep
    mask = np.uint64(2047)
    for i in range(n):
        v = keys[i]
        for p in range(6):
            count[p, ((v >> np.uint64(11 * p)) & mask) + 1] += 1
    src = keys.copy()
    dst = np.empty(n, dtype=keys.dtype)
    dst_o = np.empty(n, dtype=np.int64)
    for p in range(6):
        c = count[p]
        if c.max() == n:  # one digit for all: the order stands
            continue
        for d in range(2048):
            c[d + 1] += c[d]
        shift = np.uint64(11 * p)
        for i in range(n):
            d = (src[i] >> shift) & mask
            q = c[d]
            c[d] = q + 1
            dst[q] = src[i]
            dst_o[q] = order[i]
        order, dst_o = dst_o, order
        src, dst = dst, src
    return order


def _coarsen(keys: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One level up (keys ``>> 3``): new keys, run starts (last = n) and first-child positions
    (into ``keys``; last = ``keys.size``)."""
    ck = keys >> np.uint64(3)
    brk = np.flatnonzero(ck[1:] != ck[:-1]) + 1
    first = np.concatenate([[0], brk, [keys.size]])
    return ck[first[:-1]], starts[first], first


@njit(cache=True)
def _occupancy_at(codes, shift):  # pragma: no cover - compiled
    """Mean over points of the number of points in their cell at ``codes >> shift``
    (``sum count^2 / n``), in one pass without allocating."""
    n = codes.shape[0]
    acc = 0.0
    run = 1
    for i in range(1, n):
        if (codes[i] >> shift) == (codes[i - 1] >> shift):
            run += 1
        else:
            acc += run * run
            run = 1
    acc += run * run
    return acc / n


@njit(cache=True)
def _cells_at(codes, shift):  # pragma: no cover - compiled
    """Occupied cells of the sorted ``codes`` at ``codes >> shift``: keys and run starts (last
    = n), in two passes without temporaries."""
    n = codes.shape[0]
    nc = 1
    for i in range(1, n):
        if (codes[i] >> shift) != (codes[i - 1] >> shift):
            nc += 1
    keys = np.empty(nc, dtype=np.uint64)
    starts = np.empty(nc + 1, dtype=np.int64)
    keys[0] = codes[0] >> shift
    starts[0] = 0
    c = 1
    for i in range(1, n):
        key = codes[i] >> shift
        if key != keys[c - 1]:
            keys[c] = key
            starts[c] = i
            c += 1
    starts[nc] = n
    return keys, starts


def _first_level(codes: np.ndarray) -> int:
    """The finest level whose cells hold :data:`TARGET_PER_CELL` points per point (bisection:
    the occupancy grows with the level)."""
    lo_l, hi_l = 0, BITS
    while lo_l < hi_l:
        mid = (lo_l + hi_l) // 2
        if _occupancy_at(codes, np.uint64(3 * mid)) >= TARGET_PER_CELL:
            hi_l = mid
        else:
            lo_l = mid + 1
    return lo_l


def knn_sorted(
    X: np.ndarray,
    codes: np.ndarray,
    k: int,
    lo: np.ndarray,
    scale: float,
    *,
    query: np.ndarray | None = None,
    qcodes: np.ndarray | None = None,
    self_index: np.ndarray | None = None,
    serial_below: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact kNN of Morton-sorted points by the grid and octree passes of this module.

    ``X`` (n, 3) sorted by ``codes`` (quantised with ``lo`` and ``scale``); ``query`` (m, 3) sorted
    by ``qcodes`` (default ``X``); ``self_index[i]`` the row excluded for query ``i`` (or -1).
    A pass of fewer than ``serial_below`` queries (octree: :data:`TREE_QUERY_COST` each) runs
    on the calling thread. Returns ``(idx, dmean, dlast, dzero)``: (m, k) neighbour rows nearest
    first (int32 when ``n < 2^31``), mean and ``k``-th distances and whether the nearest is at
    distance 0.
    """
    n = X.shape[0]
    if query is None:
        query, qcodes = X, codes
        if self_index is None:
            self_index = np.empty(0, dtype=np.int64)  # the kernels' flag for "q itself"
    m = query.shape[0]
    if self_index is None:
        self_index = np.full(m, -1, dtype=np.int64)
    self_index = np.ascontiguousarray(self_index, dtype=np.int64)
    itype = np.int32 if n < 2**31 - 1 else np.int64
    out_idx = np.empty((m, k), dtype=itype)
    dmean, dlast = np.empty(m), np.empty(m)
    dzero = np.zeros(m, dtype=np.bool_)
    if m == 0:
        return out_idx, dmean, dlast, dzero
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    if scale <= 0:  # every point coincides: any k other points are nearest
        scale = 1.0
    L0 = _first_level(codes)
    keys, starts = _cells_at(codes, np.uint64(3 * L0))
    gkeys, gstart = _cells_at(qcodes, np.uint64(3 * L0))
    bound = np.empty(m)
    w0 = float(2**L0) / scale
    table, shift = _cell_table(keys)
    with numba_threads(1 if m < serial_below else -1):
        _grid_pass(
            X,
            keys,
            starts,
            table,
            shift,
            query,
            gstart,
            gkeys,
            self_index,
            k,
            L0,
            lo,
            w0,
            out_idx,
            dmean,
            dlast,
            dzero,
            bound,
        )
    sel = np.flatnonzero(bound >= 0)
    if sel.size == 0:
        return out_idx, dmean, dlast, dzero
    # the octree above L0, as flat arrays over its levels
    lev_keys, lev_starts, lev_first = [keys], [starts], [None]
    L = L0
    while L < BITS and lev_keys[-1].size > TOP_CELLS:
        kk, ss, ff = _coarsen(lev_keys[-1], lev_starts[-1])
        lev_keys.append(kk)
        lev_starts.append(ss)
        lev_first.append(ff)
        L += 1
    off = np.cumsum([0] + [a.size for a in lev_keys])
    ckey = np.concatenate(lev_keys)
    cbeg = np.concatenate([s[:-1] for s in lev_starts]).astype(np.int64)
    cend = np.concatenate([s[1:] for s in lev_starts]).astype(np.int64)
    clev = np.concatenate([np.full(a.size, i, dtype=np.int64) for i, a in enumerate(lev_keys)])
    chlo = np.zeros(ckey.size, dtype=np.int64)
    chhi = np.zeros(ckey.size, dtype=np.int64)
    for i in range(1, len(lev_keys)):
        f = lev_first[i].astype(np.int64) + off[i - 1]
        chlo[off[i] : off[i + 1]] = f[:-1]
        chhi[off[i] : off[i + 1]] = f[1:]
    wl = np.array([float(2 ** (L0 + i)) / scale for i in range(len(lev_keys))])
    with numba_threads(1 if sel.size * TREE_QUERY_COST < serial_below else -1):
        _tree_pass(
            X,
            _cell_boxes(ckey, clev, wl, lo),
            cbeg,
            cend,
            clev,
            chlo,
            chhi,
            int(off[-2]),
            int(off[-1]),
            query,
            sel,
            self_index,
            bound,
            k,
            out_idx,
            dmean,
            dlast,
            dzero,
        )
    return out_idx, dmean, dlast, dzero
