"""Stages 2-3 of the traversal connectivity code (vertex labels, face order) and the bit
buffers, Fenwick ranks and Elias steps the stages share (:mod:`._conn_traverse`)."""

from __future__ import annotations

import numba
import numpy as np

from ._rangecoder import bitlen as _bitlen

#: adjacency entries walked per end point when building a candidate list
CAP = 32
C_SEQ = 3
C_EXPLICIT = 4
C_VERTEX = 5
#: faces around the previous face's corners offered as candidates for the next one
VMAX = 24


# ----------------------------------------------------------------------------- bit buffers
@numba.njit(cache=True, inline="always")
def _put(buf, pos, value, width):
    for k in range(width - 1, -1, -1):
        if (value >> k) & 1:
            buf[pos >> 3] |= np.uint8(1 << (7 - (pos & 7)))
        pos += 1
    return pos


@numba.njit(cache=True, inline="always")
def _get(buf, pos, width, nbits):
    if pos + width > nbits:
        return -1, pos
    value = 0
    for _ in range(width):
        value = (value << 1) | ((buf[pos >> 3] >> (7 - (pos & 7))) & 1)
        pos += 1
    return value, pos


@numba.njit(cache=True, inline="always")
def _contains(cand, nc, y):
    for i in range(nc):
        if cand[i] == y:
            return True
    return False


@numba.njit(cache=True, inline="always")
def _push_unique(cand, nc, y):
    """Append ``y`` to ``cand[:nc]`` unless it is there; returns the new length."""
    if _contains(cand, nc, y):
        return nc
    cand[nc] = y
    return nc + 1


# ----------------------------------------------------------------------------- Fenwick ranks
@numba.njit(cache=True)
def _fen_init(n):
    tree = np.zeros(n + 1, dtype=np.int64)
    for i in range(1, n + 1):
        tree[i] += 1
        j = i + (i & -i)
        if j <= n:
            tree[j] += tree[i]
    return tree


@numba.njit(cache=True, inline="always")
def _fen_add(tree, i, delta):
    i += 1
    n = tree.size - 1
    while i <= n:
        tree[i] += delta
        i += i & -i


@numba.njit(cache=True, inline="always")
def _fen_prefix(tree, i):
    """Number of unused items with index < i."""
    s = 0
    while i > 0:
        s += tree[i]
        i -= i & -i
    return s


@numba.njit(cache=True)
def _fen_select(tree, r):
    """Index of the unused item of rank r (0-based)."""
    n = tree.size - 1
    step = 1
    while step * 2 <= n:
        step *= 2
    pos = 0
    while step > 0:
        if pos + step <= n and tree[pos + step] <= r:
            pos += step
            r -= tree[pos]
        step //= 2
    return pos


@numba.njit(cache=True, inline="always")
def _zig(d):
    return 2 * d if d >= 0 else -2 * d - 1


@numba.njit(cache=True, inline="always")
def _unzig(z):
    return z >> 1 if z % 2 == 0 else -((z + 1) >> 1)


@numba.njit(cache=True, inline="always")
def _elias_put(bits, pos, d):
    """Signed step ``d`` as (length symbol, raw bits below the leading one); returns both."""
    z = _zig(d)
    k = _bitlen(z)
    if k > 1:
        pos = _put(bits, pos, z, k - 1)
    return k, pos


@numba.njit(cache=True, inline="always")
def _elias_get(bits, pos, k, nbits):
    """Inverse of :func:`_elias_put`; ``ok`` is False when the raw bits run out."""
    if k <= 1:
        return _unzig(k), pos, True
    lo, pos = _get(bits, pos, k - 1, nbits)
    if lo < 0:
        return 0, pos, False
    return _unzig((1 << (k - 1)) | lo), pos, True


@numba.njit(cache=True)
def _ranks(encode, n_items, seq, n_univ, sym, bits, pos, nbits):
    """Stage 2: a sequence of distinct items of ``range(n_univ)`` as Elias-coded rank steps."""
    tree = _fen_init(n_univ)
    prev = -1
    remaining = n_univ
    for c in range(n_items):
        p = _fen_prefix(tree, prev + 1)
        if encode:
            sym[c], pos = _elias_put(bits, pos, _fen_prefix(tree, seq[c]) - p)
            x = seq[c]
        else:
            d, pos, ok = _elias_get(bits, pos, sym[c], nbits)
            if not ok:
                return 1, pos
            r = p + d
            if r < 0 or r >= remaining:
                return 1, pos
            x = _fen_select(tree, r)
            seq[c] = x
        _fen_add(tree, x, -1)
        remaining -= 1
        prev = x
    return 0, pos


@numba.njit(cache=True)
def _face_order(encode, m, Fc, nptr, nbrs, vptr, vf, inv, cls, sym, bits, pos, nbits):
    """Stage 3: the file's face order over the canonical faces (``inv[t]`` = canonical index).

    Candidates for the next face: the next canonical face (:data:`C_SEQ`), up to three unplaced
    edge neighbours of the previous face (symbols 0-2), then up to :data:`VMAX` unplaced faces
    around its corners (symbols ``C_VERTEX + i``); otherwise its rank step (:data:`C_EXPLICIT`).
    """
    tree = _fen_init(m)
    placed = np.zeros(m, dtype=np.bool_)
    cand = np.zeros(3, dtype=np.int64)
    vc = np.zeros(VMAX, dtype=np.int64)
    prev = -1
    n_sym = 0
    for t in range(m):
        nc = 0
        if prev >= 0:
            for q in range(nptr[prev], nptr[prev + 1]):
                if not placed[nbrs[q]]:
                    nc = _push_unique(cand, nc, nbrs[q])
                    if nc == 3:
                        break
        seq = prev + 1
        if seq >= m or placed[seq]:
            seq = -1
        k = 0
        for i in range(nc):  # the next canonical face has its own symbol
            if cand[i] != seq:
                cand[k] = cand[i]
                k += 1
        nc = k
        nvc = 0
        if prev >= 0:
            for corner in range(3):
                x = Fc[prev, corner]
                lim = min(vptr[x + 1], vptr[x] + CAP)
                for q in range(vptr[x], lim):
                    g = vf[q]
                    if placed[g] or g == seq or nvc == VMAX:
                        continue
                    if not _contains(cand, nc, g):  # not already an edge candidate
                        nvc = _push_unique(vc, nvc, g)
        if encode:
            j = inv[t]
            s = C_EXPLICIT
            if j == seq:
                s = C_SEQ
            else:
                for i in range(nc):
                    if cand[i] == j:
                        s = i
                if s == C_EXPLICIT:
                    for i in range(nvc):
                        if vc[i] == j:
                            s = C_VERTEX + i
                            break
            cls[t] = s
            if s == C_EXPLICIT:
                d = _fen_prefix(tree, j) - _fen_prefix(tree, prev + 1)
                sym[n_sym], pos = _elias_put(bits, pos, d)
                n_sym += 1
        else:
            s = cls[t]
            if s < nc:
                j = cand[s]
            elif s == C_SEQ and seq >= 0:
                j = seq
            elif C_VERTEX <= s < C_VERTEX + nvc:
                j = vc[s - C_VERTEX]
            elif s == C_EXPLICIT:
                if n_sym >= sym.size:
                    return 1, n_sym, pos
                d, pos, ok = _elias_get(bits, pos, sym[n_sym], nbits)
                n_sym += 1
                if not ok:
                    return 1, n_sym, pos
                r = _fen_prefix(tree, prev + 1) + d
                if r < 0 or r >= m - t:
                    return 1, n_sym, pos
                j = _fen_select(tree, r)
            else:
                return 1, n_sym, pos
            inv[t] = j
        placed[j] = True
        _fen_add(tree, j, -1)
        prev = j
    return 0, n_sym, pos


@numba.njit(cache=True)
def _face_neighbours_kernel(Fc, nd, n_vert):
    m = Fc.shape[0]
    # faces of every vertex, ascending (counting sort over the non-degenerate faces)
    deg = np.zeros(n_vert + 1, dtype=np.int64)
    for f in range(m):
        if nd[f]:
            for k in range(3):
                deg[Fc[f, k] + 1] += 1
    for v in range(n_vert):
        deg[v + 1] += deg[v]
    vf = np.empty(deg[n_vert], dtype=np.int64)
    fill = deg[:n_vert].copy()
    for f in range(m):
        if nd[f]:
            for k in range(3):
                v = Fc[f, k]
                vf[fill[v]] = f
                fill[v] += 1
    cnt = np.zeros(m + 1, dtype=np.int64)
    out = np.empty(max(1, 3 * deg[n_vert]), dtype=np.int64)
    n_out = 0
    for f in range(m):
        if nd[f]:
            for k in range(3):
                a = Fc[f, k]
                b = Fc[f, (k + 1) % 3]
                x, y = (a, b) if deg[a + 1] - deg[a] <= deg[b + 1] - deg[b] else (b, a)
                for q in range(deg[x], deg[x + 1]):
                    g = vf[q]
                    if g != f and (Fc[g, 0] == y or Fc[g, 1] == y or Fc[g, 2] == y):
                        if n_out == out.size:
                            grown = np.empty(2 * out.size, dtype=np.int64)
                            grown[:n_out] = out[:n_out]
                            out = grown
                        out[n_out] = g
                        n_out += 1
        cnt[f + 1] = n_out
    return cnt, out[:n_out], deg, vf


def _face_neighbours(Fc: np.ndarray):
    """Faces sharing an edge with each face (CSR: by edge of the face, then face index), and the
    non-degenerate faces around every vertex (CSR, ascending)."""
    nd = (Fc[:, 0] != Fc[:, 1]) & (Fc[:, 1] != Fc[:, 2]) & (Fc[:, 0] != Fc[:, 2])
    n_vert = int(Fc.max()) + 1 if Fc.shape[0] else 1
    return _face_neighbours_kernel(np.ascontiguousarray(Fc, dtype=np.int64), nd, n_vert)
