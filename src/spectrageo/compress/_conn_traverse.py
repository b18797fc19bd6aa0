"""Order-preserving connectivity coding by traversal: topology first, then the two orders.

Label triples cost about ``3 log2(n)`` bits per face when a file's orders are incoherent; an
order-preserving code needs about ``log2(m!) + log2(n!)`` bits plus a few bits per face:

1. **Topology** by a depth-first traversal over shared edges, vertices numbered as met
   (canonical ids). Across an open edge the encoder codes whether a face lies there, its
   orientation and its third vertex: *new*, a candidate both sides list from the decoded
   neighbourhood (Edgebreaker's L/R and most S cases, up to :data:`WALK` border edges away),
   another border vertex by rank step (Elias-gamma), or an explicit id. Unreachable faces are
   sent as *seeds*.
2. **Vertex labels**: each file label as its rank step among the unused labels.
3. **Face order**: each file face as the canonical successor, an unplaced edge neighbour of
   the previous face, or its rank; then its rotation.

:func:`canonical` is the order in which all three are nearly free (``--reorder``). Stage 1's
symbols use adaptive models (:mod:`._rangecoder`, first byte :data:`MARKER_ADAPTIVE`), the
third vertex in :data:`NV_CTX` contexts (faces already decoded around the gate's end); the other
stages static categorical models with ``constriction``'s ANS coder. Files of the static format
(:data:`MARKER`: every stream static, the third vertex in 16 contexts) still decode. Faces
already in canonical order are written as :data:`MARKER_CANONICAL`: stages 2-3 implied, stage 1
with counted adaptive models (docs/decisions.md#codec-conn-canonical). Both sides
run one compiled state machine (:func:`_topology`). See docs/decisions.md#compress-connectivity,
docs/decisions.md#compress-conn-contexts and docs/decisions.md#codec-conn-adaptive.
"""

from __future__ import annotations

import numba
import numpy as np

from .._errors import InvalidInputError
from ._conn_streams import (
    adaptive_blob,
    canonical_sizes,
    read_canonical,
    read_streams,
    static_tables,
    static_words,
)
from ._container import Reader, varint
from ._rangecoder import bitlen as _bitlen

#: length of the candidate list for the third vertex of a traversed face
KMAX = 30
#: adjacency entries walked per end point when building the candidate list
CAP = 32
#: border steps walked from each end point of the gate for further candidates (4-6 best on the
#: tuning meshes of ``benchmarks/connectivity.py``; 12 and 24 cost a little more, 2 clearly more)
WALK = 6
W_FAR = 1  # an old vertex on the decoded region's border, by its rank there
W_ANY = KMAX + 2  # any old vertex, by its id; candidates are symbols 2 .. KMAX + 1
W_ALPHA = KMAX + 3
C_SEQ = 3
C_EXPLICIT = 4
C_VERTEX = 5
#: faces around the previous face's corners offered as candidates for the next one
VMAX = 24
#: contexts of the third-vertex symbol: the classes of the two previous ones
N_CTX = 16
#: alphabets of the categorical streams, in stream order
ALPHABETS = (
    2,  # gate: a face lies across the open edge
    2,  # orient: 0 consistent with its neighbour, 1 flipped
    2,  # seed corner: new or old
    65,  # far border vertex: Elias length of its rank step
    *([W_ALPHA] * N_CTX),  # third vertex: new, far, candidate 1..KMAX, any; one per context
    65,  # vertex label: Elias length
    C_VERTEX + VMAX,  # face order: edge neighbour 0-2, next, explicit, around a corner
    65,  # face order: Elias length
    3,  # rotation relative to smallest label first
)
N_STREAMS = len(ALPHABETS)
N_TOPO = 4 + N_CTX  # streams of stage 1 (static format)
#: contexts of the third-vertex symbol in the adaptive format: 0-5 faces already decoded around
#: the gate's end ``v`` (docs/decisions.md#codec-conn-adaptive)
NV_CTX = 6


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


# ----------------------------------------------------------------------------- edge table
@numba.njit(cache=True, inline="always")
def _slot(hkeys, key):
    mask = hkeys.size - 1
    h = (np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(20)
    i = np.int64(h & np.uint64(mask))
    while hkeys[i] != -1 and hkeys[i] != key:
        i = (i + 1) & mask
    return i


@numba.njit(cache=True)
def _add_edge(a, b, N, hkeys, hval, ecnt, head, nxt, to, ne, bcnt, btree):
    """Count one more face on edge {a, b}; returns the new number of edges. ``bcnt`` counts
    the border edges (one face) of every vertex, ``btree`` flags vertices with one (Fenwick)."""
    lo, hi = (a, b) if a < b else (b, a)
    key = lo * N + hi
    i = _slot(hkeys, key)
    if hkeys[i] == -1:
        hkeys[i] = key
        hval[i] = ne
        e = ne
        ne += 1
        ecnt[e] = 0
        to[2 * e] = hi
        nxt[2 * e] = head[lo]
        head[lo] = 2 * e
        to[2 * e + 1] = lo
        nxt[2 * e + 1] = head[hi]
        head[hi] = 2 * e + 1
    else:
        e = hval[i]
    ecnt[e] += 1
    if ecnt[e] <= 2:
        step = 1 if ecnt[e] == 1 else -1
        for x in (lo, hi):
            bcnt[x] += step
            if bcnt[x] == (1 if step == 1 else 0):
                _fen_add(btree, x, step)
    return ne


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


@numba.njit(cache=True)
def _candidates(u, v, cand, hkeys, hval, ecnt, head, nxt, to):
    """Decoded neighbours of v, then u: border edges first (one face), then the others."""
    nc = 0
    for p in range(4):
        x0 = v if p % 2 == 0 else u
        excl = u if p % 2 == 0 else v
        want_border = p < 2
        ent = head[x0]
        steps = 0
        while ent != -1 and steps < CAP and nc < KMAX:
            y = to[ent]
            steps += 1
            if y != excl and (ecnt[ent >> 1] == 1) == want_border:
                nc = _push_unique(cand, nc, y)
            ent = nxt[ent]
    # then further along the border, WALK steps from v and from u (Edgebreaker's S vertices
    # are on the border, often a few edges away)
    for p in range(2):
        prev = u if p == 0 else v
        cur = v if p == 0 else u
        for _ in range(WALK):
            if nc >= KMAX:
                return nc
            ent = head[cur]
            steps = 0
            y = -1
            while ent != -1 and steps < CAP:
                steps += 1
                if ecnt[ent >> 1] == 1 and to[ent] != prev:
                    y = to[ent]
                    break
                ent = nxt[ent]
            if y == -1 or y == u or y == v:
                break
            nc = _push_unique(cand, nc, y)
            prev, cur = cur, y
    return nc


@numba.njit(cache=True, inline="always")
def _context(hist, fv, n_ctx):
    """Context of the third-vertex symbol: in the static format the classes of the two symbols
    before it (``hist``); in the adaptive one the faces already decoded around the gate's end
    ``v``, whose decoded neighbours are the first candidates."""
    if n_ctx == N_CTX:
        return hist
    return min(fv, n_ctx - 1)


@numba.njit(cache=True)
def _topology(
    encode,
    m,
    F,
    ekeys,
    eptr,
    efaces,
    n_univ,
    syms,
    wsym,
    wctx,
    woff,
    lens,
    bits,
    nbits,
    Fc,
    order,
    L,
):
    """Stage 1, run identically by encoder (``encode``) and decoder.

    Encoder inputs: ``F`` (file faces), ``ekeys/eptr/efaces`` (undirected file edges of the
    non-degenerate faces, sorted, with their faces). It fills ``syms`` (streams 0-3, lengths in
    ``lens``), the raw bits, ``Fc`` (canonical faces), ``order`` (file index of each canonical
    face) and ``L`` (file label of each canonical vertex). The decoder reads the same streams and
    fills ``Fc``. Returns ``(status, n_canonical_vertices, bit_position)``; status 0 is success.
    """
    N = np.int64(3 * m + 3)
    cap = 1
    while cap < 4 * m + 8:  # edges <= 3m: load <= 3/4, about 3/8 on closed meshes
        cap *= 2
    hkeys = np.full(cap, -1, dtype=np.int64)
    hval = np.zeros(cap, dtype=np.int64)
    ecnt = np.zeros(N, dtype=np.int64)
    head = np.full(N, -1, dtype=np.int64)
    nxt = np.full(2 * N, -1, dtype=np.int64)
    to = np.zeros(2 * N, dtype=np.int64)
    su = np.zeros(N, dtype=np.int64)
    sv = np.zeros(N, dtype=np.int64)
    cand = np.zeros(KMAX, dtype=np.int64)
    bcnt = np.zeros(N, dtype=np.int64)
    btree = np.zeros(N + 1, dtype=np.int64)
    cid = np.full(n_univ if encode else 1, -1, dtype=np.int64)
    done = np.zeros(m if encode else 1, dtype=np.bool_)
    c = np.zeros(3, dtype=np.int64)
    ne = 0
    nv = 0
    sp = 0
    t = 0
    fpos = 0
    pos = 0
    n_ctx = lens.size - 4
    cur = np.zeros(lens.size, dtype=np.int64)  # read/write cursor per stream
    fcnt = np.zeros(N, dtype=np.int64)  # faces decoded around each vertex
    ctx = 0
    while t < m:
        if sp == 0:  # seed face, corner by corner
            if encode:
                while done[fpos]:
                    fpos += 1
                f = fpos
                for k in range(3):
                    x = F[f, k]
                    if cid[x] == -1:
                        syms[2, cur[2]] = 0
                        cid[x] = nv
                        L[nv] = x
                        nv += 1
                    else:
                        syms[2, cur[2]] = 1
                        pos = _put(bits, pos, cid[x], _bitlen(nv - 1))
                    cur[2] += 1
                    c[k] = cid[x]
                done[f] = True
                order[t] = f
            else:
                for k in range(3):
                    if cur[2] >= lens[2]:
                        return 1, nv, pos
                    s = syms[2, cur[2]]
                    cur[2] += 1
                    if s == 0:
                        if nv >= N:
                            return 1, nv, pos
                        c[k] = nv
                        nv += 1
                    else:
                        val, pos = _get(bits, pos, _bitlen(nv - 1), nbits)
                        if val < 0 or val >= nv:
                            return 1, nv, pos
                        c[k] = val
            Fc[t, 0] = c[0]
            Fc[t, 1] = c[1]
            Fc[t, 2] = c[2]
            t += 1
            for k in range(3):
                fcnt[c[k]] += 1
            if c[0] != c[1] and c[1] != c[2] and c[0] != c[2]:
                for k in range(3):
                    ne = _add_edge(
                        c[k], c[(k + 1) % 3], N, hkeys, hval, ecnt, head, nxt, to, ne, bcnt, btree
                    )
                for k in range(2, -1, -1):
                    su[sp] = c[k]
                    sv[sp] = c[(k + 1) % 3]
                    sp += 1
            continue
        sp -= 1
        u = su[sp]
        v = sv[sp]
        lo, hi = (u, v) if u < v else (v, u)
        e = hval[_slot(hkeys, lo * N + hi)]
        if ecnt[e] >= 2:
            continue
        f = -1
        w = -1
        if encode:
            a = L[u]
            b = L[v]
            la, lb = (a, b) if a < b else (b, a)
            key = la * n_univ + lb
            i = np.searchsorted(ekeys, key)
            if i < ekeys.size and ekeys[i] == key:
                for q in range(eptr[i], eptr[i + 1]):
                    if not done[efaces[q]]:
                        f = efaces[q]
                        break
            syms[0, cur[0]] = 1 if f >= 0 else 0
            cur[0] += 1
            if f < 0:
                continue
            orient = 1
            for k in range(3):
                if F[f, k] == b and F[f, (k + 1) % 3] == a:
                    orient = 0
                if F[f, k] != a and F[f, k] != b:
                    w = F[f, k]
            syms[1, cur[1]] = orient
            cur[1] += 1
        else:
            if cur[0] >= lens[0]:
                return 1, nv, pos
            g = syms[0, cur[0]]
            cur[0] += 1
            if g == 0:
                continue
            if cur[1] >= lens[1]:
                return 1, nv, pos
            orient = syms[1, cur[1]]
            cur[1] += 1
        p, q2 = (v, u) if orient == 0 else (u, v)
        nc = _candidates(u, v, cand, hkeys, hval, ecnt, head, nxt, to)
        cx = _context(ctx, fcnt[v], n_ctx)
        if encode:
            cw = cid[w]
            if cw == -1:
                s = 0
                cid[w] = nv
                L[nv] = w
                cw = nv
                nv += 1
            else:
                s = W_FAR
                for i in range(nc):
                    if cand[i] == cw:
                        s = 2 + i
                        break
                if s == W_FAR and bcnt[cw] > 0:
                    d = _fen_prefix(btree, cw) - _fen_prefix(btree, u)
                    syms[3, cur[3]], pos = _elias_put(bits, pos, d)
                    cur[3] += 1
                elif s == W_FAR:
                    s = W_ANY
                    pos = _put(bits, pos, cw, _bitlen(nv - 1))
            wsym[cur[4]] = s  # all contexts in one array, split by ``wctx`` afterwards
            wctx[cur[4]] = ctx * 64 + min(fcnt[v], 63)  # both formats' contexts
            cur[4] += 1
            done[f] = True
            order[t] = f
        else:
            if cur[4 + cx] >= lens[4 + cx]:
                return 1, nv, pos
            s = wsym[woff[cx] + cur[4 + cx]]
            cur[4 + cx] += 1
            if s == 0:
                if nv >= N:
                    return 1, nv, pos
                cw = nv
                nv += 1
            elif s == W_FAR:
                if cur[3] >= lens[3]:
                    return 1, nv, pos
                d, pos, ok = _elias_get(bits, pos, syms[3, cur[3]], nbits)
                cur[3] += 1
                if not ok:
                    return 1, nv, pos
                r = _fen_prefix(btree, u) + d
                if r < 0 or r >= _fen_prefix(btree, N):
                    return 1, nv, pos
                cw = _fen_select(btree, r)
                if cw >= nv or cw == u or cw == v:
                    return 1, nv, pos
            elif s == W_ANY:
                cw, pos = _get(bits, pos, _bitlen(nv - 1), nbits)
                if cw < 0 or cw >= nv or cw == u or cw == v:
                    return 1, nv, pos
            elif s <= nc + 1:
                cw = cand[s - 2]
            else:
                return 1, nv, pos
        ctx = 4 * (ctx % 4) + (0 if s == 0 else (s - 1 if 2 <= s <= 3 else 3))
        Fc[t, 0] = p
        Fc[t, 1] = q2
        Fc[t, 2] = cw
        t += 1
        fcnt[p] += 1
        fcnt[q2] += 1
        fcnt[cw] += 1
        ne = _add_edge(p, q2, N, hkeys, hval, ecnt, head, nxt, to, ne, bcnt, btree)
        ne = _add_edge(q2, cw, N, hkeys, hval, ecnt, head, nxt, to, ne, bcnt, btree)
        ne = _add_edge(cw, p, N, hkeys, hval, ecnt, head, nxt, to, ne, bcnt, btree)
        su[sp] = q2
        sv[sp] = cw
        sp += 1
        su[sp] = cw
        sv[sp] = p
        sp += 1
    for k in range(lens.size):
        if not encode and cur[k] != lens[k]:
            return 1, nv, pos
        lens[k] = cur[k]
    return 0, nv, pos


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


# ----------------------------------------------------------------------------- helpers
def _edge_table(F: np.ndarray, n_univ: int):
    """Sorted undirected edge keys of the non-degenerate faces, with their faces (CSR)."""
    nd = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    fi = np.flatnonzero(nd)
    G = F[fi]
    a = np.concatenate([G[:, 0], G[:, 1], G[:, 2]])
    b = np.concatenate([G[:, 1], G[:, 2], G[:, 0]])
    face = np.tile(fi, 3)
    key = np.minimum(a, b) * n_univ + np.maximum(a, b)
    o = np.lexsort((face, key))
    key = key[o]
    face = face[o]
    ukeys, starts = np.unique(key, return_index=True)
    eptr = np.r_[starts, key.size].astype(np.int64)
    return ukeys.astype(np.int64), eptr, face.astype(np.int64)


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


def _bitbuf(nbits_max: int) -> np.ndarray:
    return np.zeros(nbits_max // 8 + 8, dtype=np.uint8)


# ----------------------------------------------------------------------------- public
#: first byte of the traversal code with static models (read only)
MARKER = 0x40
#: first byte of the traversal code whose stage-1 streams use adaptive models (written)
MARKER_ADAPTIVE = 0x41
#: first byte of the adaptive code of faces already in :func:`canonical` order: stages 2-3 are
#: implied (docs/decisions.md#codec-conn-canonical)
MARKER_CANONICAL = 0x42
MARKERS = (MARKER, MARKER_ADAPTIVE, MARKER_CANONICAL)


def _layout(marker: int) -> tuple[int, tuple[int, ...]]:
    """Number of third-vertex contexts and the alphabets of all streams of a format."""
    n_ctx = N_CTX if marker == MARKER else NV_CTX  # the canonical format is adaptive's
    alphas = ALPHABETS[:4] + (W_ALPHA,) * n_ctx + ALPHABETS[N_TOPO:]
    return n_ctx, alphas


def _traverse(F: np.ndarray):
    """Stage 1 of the encoder: the stage-1 streams of both formats (by first byte), the raw
    bits, canonical faces, file index of each canonical face and file label of each vertex."""
    m = F.shape[0]
    n_univ = int(F.max()) + 1
    ekeys, eptr, efaces = _edge_table(F, n_univ)
    syms = np.zeros((4, 3 * m + 3), dtype=np.int32)  # gate, orient, seed, far border
    wsym = np.zeros(m + 1, dtype=np.int32)  # third vertices of all contexts, in order
    wctx = np.zeros(m + 1, dtype=np.int16)
    lens = np.zeros(4 + NV_CTX, dtype=np.int64)
    bits = _bitbuf(64 * (3 * m + 3))
    Fc = np.zeros((m, 3), dtype=np.int64)
    order = np.zeros(m, dtype=np.int64)
    L = np.zeros(3 * m + 3, dtype=np.int64)
    z = np.zeros(1, dtype=np.int64)
    st, nv, pos = _topology(
        True, m, F, ekeys, eptr, efaces, n_univ, syms, wsym, wctx, z, lens, bits, 0, Fc, order, L
    )
    if st != 0:  # pragma: no cover - the encoder's own state machine cannot fail
        raise RuntimeError("connectivity traversal failed")
    nw = int(lens[4])
    head = [syms[k, : lens[k]] for k in range(4)]
    topo = {}
    for marker in MARKERS[:2]:
        n_ctx = _layout(marker)[0]
        c = wctx[:nw] >> 6 if marker == MARKER else np.minimum(wctx[:nw] & 63, n_ctx - 1)
        by_ctx = np.argsort(c, kind="stable")
        splits = np.cumsum(np.bincount(c, minlength=n_ctx))[:-1]
        topo[marker] = head + np.split(wsym[:nw][by_ctx], splits)
    return n_univ, topo, bits, pos, Fc, order, L[:nv]


def canonical(F: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """``(perm, G)``: the traversal's vertex order (unused vertices last) and faces ``G`` in it.

    ``G`` lists the faces in traversal order, each rotated to start at its smallest index
    (orientation kept), so that :func:`encode` spends almost nothing on the two orders.
    """
    F = np.ascontiguousarray(F, dtype=np.int64)
    _, _, _, _, Fc, _, L = _traverse(F)
    unused = np.ones(n_vertices, dtype=bool)
    unused[L] = False
    perm = np.r_[L, np.flatnonzero(unused)].astype(np.int64)
    rot = np.argmin(Fc, axis=1)
    idx = (rot[:, None] + np.arange(3)[None, :]) % 3
    return perm, np.take_along_axis(Fc, idx, axis=1)


def encode(F: np.ndarray) -> bytes:
    """Traversal code of ``F`` (int64, (m, 3), m >= 1); see the module docstring. The smaller of
    the adaptive and the static format."""
    F = np.ascontiguousarray(F, dtype=np.int64)
    m = F.shape[0]
    n_univ, topo, bitsA, posA, Fc, order, L = _traverse(F)
    nv = L.size
    vb = np.zeros(nv, dtype=np.int64)
    bitsB = _bitbuf(64 * nv + 64)
    st, posB = _ranks(True, nv, L, n_univ, vb, bitsB, 0, 0)
    nptr, nbrs, vptr, vf = _face_neighbours(Fc)
    inv = np.empty(m, dtype=np.int64)
    inv[order] = np.arange(m)
    fc = np.zeros(m, dtype=np.int64)
    fb = np.zeros(m, dtype=np.int64)
    bitsC = _bitbuf(64 * m + 64)
    st, n_fb, posC = _face_order(True, m, Fc, nptr, nbrs, vptr, vf, inv, fc, fb, bitsC, 0, 0)
    rest = [vb, fc, fb[:n_fb], _rotation_symbols(F[order], L[Fc])]
    n_topo = 4 + NV_CTX
    out = []
    if nv == n_univ and (L == np.arange(nv)).all() and (order == np.arange(m)).all():
        if not rest[3].any():  # every face starts at its smallest index
            head = bytes([MARKER_CANONICAL]) + varint(nv) + canonical_sizes(topo[MARKER_ADAPTIVE])
            head += varint(posA) + bitsA[: (posA + 7) // 8].tobytes()
            alphas = _layout(MARKER_ADAPTIVE)[1][:n_topo]
            out.append(bytes(head) + adaptive_blob(topo[MARKER_ADAPTIVE], alphas, True))
    raw = b"".join(
        varint(pos) + bb[: (pos + 7) // 8].tobytes()
        for bb, pos in ((bitsA, posA), (bitsB, posB), (bitsC, posC))
    )
    for marker in MARKERS[:2]:
        n_ctx, alphas = _layout(marker)
        streams = topo[marker] + rest
        head = bytearray([marker]) + varint(n_univ) + varint(nv)
        if marker == MARKER:
            for s, alpha in zip(streams, alphas, strict=True):
                head += varint(s.size) + static_tables([s], [alpha])
            out.append(bytes(head) + raw + static_words(streams, alphas))
            continue
        for s in streams:
            head += varint(s.size)
        head += static_tables(rest, alphas[n_topo:])
        blob = adaptive_blob(topo[marker], alphas[:n_topo])
        head += varint(len(blob)) + blob
        out.append(bytes(head) + raw + static_words(rest, alphas[n_topo:]))
    return min(out, key=len)


def _rotation_symbols(Ff: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Rotation r with ``Ff == roll(G, -r)``, coded relative to the smallest label first."""
    r = np.full(Ff.shape[0], -1, dtype=np.int64)
    for k in (2, 1, 0):
        ok = (Ff == np.roll(G, -k, axis=1)).all(axis=1)
        r[ok] = k
    if (r < 0).any():  # pragma: no cover - traversal keeps every face a rotation of the file's
        raise RuntimeError("connectivity traversal lost a face's orientation")
    return (r - np.argmin(G, axis=1)) % 3


def decode(buf: bytes, n_vertices: int, n_faces: int) -> np.ndarray:
    """Inverse of :func:`encode`; ``buf`` starts with one of :data:`MARKERS`."""
    r = Reader(buf, "connectivity")
    marker = r.take(1)[0]
    if marker not in MARKERS:
        raise InvalidInputError(".sgc connectivity is malformed (unknown scheme).")
    m = int(n_faces)
    n_univ = r.varint()
    nv = n_univ if marker == MARKER_CANONICAL else r.varint()
    if not (1 <= n_univ <= n_vertices and 1 <= nv <= n_univ and nv <= 3 * m):
        raise InvalidInputError(".sgc connectivity is malformed (bad vertex counts).")
    n_ctx, alphas = _layout(marker)
    n_topo = 4 + n_ctx
    if marker == MARKER_CANONICAL:
        sizes, streams, bits = read_canonical(r, alphas[:n_topo], m)
    else:
        sizes, streams, bits = read_streams(r, marker == MARKER_ADAPTIVE, n_topo, alphas, m, nv)
    syms = np.zeros((4, max(1, max(sizes[:4]))), dtype=np.int32)
    for k in range(4):
        syms[k, : sizes[k]] = streams[k]
    wsym = np.concatenate([np.zeros(0, dtype=np.int32), *streams[4:n_topo]]).astype(np.int32)
    woff = np.r_[0, np.cumsum(sizes[4:n_topo])].astype(np.int64)
    lens = np.array(sizes[:n_topo], dtype=np.int64)
    Fc = np.zeros((m, 3), dtype=np.int64)
    dummyF = np.zeros((1, 3), dtype=np.int64)
    z = np.zeros(1, dtype=np.int64)
    (bA, nA), (bB, nB), (bC, nC) = bits
    w16 = np.zeros(1, dtype=np.int16)
    st, nv2, _ = _topology(
        False, m, dummyF, z, z, z, n_univ, syms, wsym, w16, woff, lens, bA, nA, Fc, z, z
    )
    if st != 0 or nv2 != nv:
        raise InvalidInputError(".sgc connectivity is malformed (topology stream).")
    if marker == MARKER_CANONICAL:
        idx = (np.argmin(Fc, axis=1)[:, None] + np.arange(3)[None, :]) % 3
        return np.take_along_axis(Fc, idx, axis=1)
    L = np.zeros(nv, dtype=np.int64)
    st, _ = _ranks(False, nv, L, n_univ, streams[n_topo], bB, 0, nB)
    if st != 0:
        raise InvalidInputError(".sgc connectivity is malformed (vertex labels).")
    nptr, nbrs, vptr, vf = _face_neighbours(Fc)
    inv = np.zeros(m, dtype=np.int64)
    cls, fb = streams[n_topo + 1], streams[n_topo + 2]
    st, used, _ = _face_order(False, m, Fc, nptr, nbrs, vptr, vf, inv, cls, fb, bC, 0, nC)
    if st != 0 or used != sizes[n_topo + 2]:
        raise InvalidInputError(".sgc connectivity is malformed (face order).")
    G = L[Fc]
    rot = (streams[n_topo + 3] + np.argmin(G, axis=1)) % 3
    idx = (rot[:, None] + np.arange(3)[None, :]) % 3
    return np.take_along_axis(G, idx, axis=1)[inv]
