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
already in canonical order are written as :data:`MARKER_INLINE2`: stages 2-3 implied, every
stage-1 symbol range coded in traversal order under contexts of the decoded neighbourhood
(docs/decisions.md#codec-conn-inline), the coder's first byte (always zero) left out
(docs/decisions.md#codec-rc-flush); :data:`MARKER_INLINE` (with that byte) and
:data:`MARKER_CANONICAL` files (the same with stage-1
streams, docs/decisions.md#codec-conn-canonical) still decode. Both sides
run one compiled state machine (:func:`_topology`). See docs/decisions.md#compress-connectivity,
docs/decisions.md#compress-conn-contexts and docs/decisions.md#codec-conn-adaptive.
"""

from __future__ import annotations

import numba
import numpy as np

from .._errors import InvalidInputError
from . import _rangecoder as rc
from ._conn_orders import (
    C_VERTEX,
    CAP,
    VMAX,
    _elias_get,
    _elias_put,
    _face_neighbours,
    _face_order,
    _fen_add,
    _fen_prefix,
    _fen_select,
    _get,
    _push_unique,
    _put,
    _ranks,
    _zig,
)
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
#: border steps walked from each end point of the gate for further candidates (4-6 best on the
#: tuning meshes of ``benchmarks/connectivity.py``; 12 and 24 cost a little more, 2 clearly more)
WALK = 6
W_FAR = 1  # an old vertex on the decoded region's border, by its rank there
W_ANY = KMAX + 2  # any old vertex, by its id; candidates are symbols 2 .. KMAX + 1
W_ALPHA = KMAX + 3
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
#: buckets ``(lo, hi)`` of the inline format's contexts: the third vertex's three mixed models
#: take the faces decoded around the gate's end ``v``, times those around ``u``, times those
#: around the first candidate; the gate the border gates found at ``u`` and at ``v`` (0-2
#: each) times the faces around ``v`` (docs/decisions.md#codec-conn-inline)
THIRD_BUCKETS = ((2, 7), (2, 5), (3, 6))
GATE_BUCKETS = ((0, 2), (1, 4))
_NA = THIRD_BUCKETS[0][1] - THIRD_BUCKETS[0][0] + 1
_NB = _NA * (THIRD_BUCKETS[1][1] - THIRD_BUCKETS[1][0] + 1)
_NC = _NB * (THIRD_BUCKETS[2][1] - THIRD_BUCKETS[2][0] + 1)
_NG = (GATE_BUCKETS[0][1] + 1) ** 2 * (GATE_BUCKETS[1][1] - GATE_BUCKETS[1][0] + 1)
#: models of the inline format: gate contexts, orientation, seed corner, then symbol models of
#: :data:`._rangecoder.SYM_STRIDE` probabilities (the far step's length, the third vertex's)
M_ORIENT = _NG
M_SEED = _NG + 1
M_FAR = _NG + 2
M_THIRD = M_FAR + rc.SYM_STRIDE
N_MODELS = M_THIRD + (_NA + _NB + _NC) * rc.SYM_STRIDE


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
def _neighbours(x0, excl, border, cand, nc, ecnt, head, nxt, to):
    """Append the decoded neighbours of ``x0`` but ``excl`` across border edges (one face) or,
    with ``border`` False, across the others."""
    ent = head[x0]
    steps = 0
    while ent != -1 and steps < CAP and nc < KMAX:
        y = to[ent]
        steps += 1
        if y != excl and (ecnt[ent >> 1] == 1) == border:
            nc = _push_unique(cand, nc, y)
        ent = nxt[ent]
    return nc


@numba.njit(cache=True)
def _candidates(u, v, cand, hkeys, hval, ecnt, head, nxt, to, interior_last):
    """Decoded neighbours of v, then u: border edges first (one face), then the others; then
    :data:`WALK` border steps from v and from u (Edgebreaker's S vertices are on the border,
    often a few edges away). ``interior_last``: the walks before the neighbours across
    interior edges, which a manifold face cannot use."""
    nc = _neighbours(v, u, True, cand, 0, ecnt, head, nxt, to)
    nc = _neighbours(u, v, True, cand, nc, ecnt, head, nxt, to)
    if not interior_last:
        nc = _neighbours(v, u, False, cand, nc, ecnt, head, nxt, to)
        nc = _neighbours(u, v, False, cand, nc, ecnt, head, nxt, to)
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
    if interior_last:
        nc = _neighbours(v, u, False, cand, nc, ecnt, head, nxt, to)
        nc = _neighbours(u, v, False, cand, nc, ecnt, head, nxt, to)
    return nc


@numba.njit(cache=True, inline="always")
def _context(hist, fv, n_ctx):
    """Context of the third-vertex symbol: in the static format the classes of the two symbols
    before it (``hist``); in the adaptive one the faces already decoded around the gate's end
    ``v``, whose decoded neighbours are the first candidates."""
    if n_ctx == N_CTX:
        return hist
    return min(fv, n_ctx - 1)


@numba.njit(cache=True, inline="always")
def _bucket(x, lo_hi):
    """``min(max(x, lo), hi) - lo``."""
    return min(max(x, lo_hi[0]), lo_hi[1]) - lo_hi[0]


@numba.njit(cache=True, inline="always")
def _io_bit(encode, st, rbuf, probs, cnts, model, syms, k, cur, lens, b):
    """Binary symbol of stream ``k``: range coded under counted model ``model`` when ``rbuf``
    is given (the inline format), else written to or read from ``syms``; -1 when the
    decoder's stream is exhausted."""
    if rbuf.size:
        return rc.bit_counted(encode, st, rbuf, probs, cnts, model, b, rc.PB_SYM)
    if encode:
        syms[k, cur[k]] = b
    elif cur[k] >= lens[k]:
        return -1
    else:
        b = syms[k, cur[k]]
    cur[k] += 1
    return b


@numba.njit(cache=True, inline="always")
def _io_raw(encode, st, rbuf, bits, pos, nbits, value, width):
    """``width`` raw bits of ``value``: equiprobable range-coder bits (inline) or the bit
    buffer. Returns ``(value, pos)``; the value is -1 when the buffer runs out."""
    if not rbuf.size:
        if encode:
            return value, _put(bits, pos, value, width)
        return _get(bits, pos, width, nbits)
    out = 0
    for j in range(width - 1, -1, -1):
        out = (out << 1) | rc.direct(encode, st, rbuf, (value >> j) & 1 if encode else 0)
    return out, pos


@numba.njit(cache=True)
def _io_far(encode, st, rbuf, probs, cnts, syms, cur, lens, bits, pos, nbits, d):
    """Signed rank step ``d`` of a far border vertex (Elias length and raw bits); returns
    ``(d, pos, ok)``."""
    if not rbuf.size:
        if encode:
            syms[3, cur[3]], pos = _elias_put(bits, pos, d)
            cur[3] += 1
            return d, pos, True
        if cur[3] >= lens[3]:
            return 0, pos, False
        cur[3] += 1
        return _elias_get(bits, pos, syms[3, cur[3] - 1], nbits)
    z = _zig(d) if encode else 0
    k = rc.code_symbol(encode, st, rbuf, probs, cnts, M_FAR, _bitlen(z), 65)
    if k > 63:
        return 0, pos, False
    if k > 1:
        lo, pos = _io_raw(encode, st, rbuf, bits, pos, nbits, z, k - 1)
        z = (1 << (k - 1)) | lo
    else:
        z = k
    return (z >> 1 if z % 2 == 0 else -((z + 1) >> 1)), pos, True


@numba.njit(cache=True, inline="always")
def _seed_start(F, f, cid):
    """Corner of seed face ``f`` coded first: its numbered vertex of smallest id, else corner 0.

    The canonical face then starts at its smallest index, so :func:`canonical`'s faces
    re-traverse to themselves (docs/decisions.md#codec-conn-fixed-point).
    """
    r0 = 0
    best = -1
    for k in range(3):
        y = cid[F[f, k]]
        if y != -1 and (best == -1 or y < best):
            best = y
            r0 = k
    return r0


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
    rbuf,
):
    """Stage 1, run identically by encoder (``encode``) and decoder.

    Encoder inputs: ``F`` (file faces), ``ekeys/eptr/efaces`` (undirected file edges of the
    non-degenerate faces, sorted, with their faces). It fills ``syms`` (streams 0-3, lengths in
    ``lens``), the raw bits, ``Fc`` (canonical faces), ``order`` (file index of each canonical
    face) and ``L`` (file label of each canonical vertex). The decoder reads the same streams and
    fills ``Fc``. With a non-empty ``rbuf`` every symbol and raw bit is range coded there in
    traversal order instead (:data:`MARKER_INLINE`; the returned position is then the byte
    count). Returns ``(status, n_canonical_vertices, bit_position)``; status 0 is success.
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
    gdone = np.zeros(N, dtype=np.int64)  # gates found closed (mesh border) at each vertex
    inline = rbuf.size > 0
    st = np.zeros(6, np.int64)
    probs = np.full(N_MODELS if inline else 0, 1 << (rc.PB_SYM - 1), np.int64)
    cnts = np.zeros(probs.size, np.int64)
    if inline:
        rc.start(encode, st, rbuf)
    ctx = 0
    while t < m:
        if inline and st[5] > rbuf.size + 8:
            return 1, nv, pos
        if sp == 0:  # seed face, corner by corner
            if encode:
                while done[fpos]:
                    fpos += 1
                f = fpos
                r0 = _seed_start(F, f, cid)
                for j in range(3):
                    k = (r0 + j) % 3
                    x = F[f, k]
                    old = cid[x] != -1
                    _io_bit(
                        True, st, rbuf, probs, cnts, M_SEED, syms, 2, cur, lens, 1 if old else 0
                    )
                    if old:
                        _, pos = _io_raw(True, st, rbuf, bits, pos, 0, cid[x], _bitlen(nv - 1))
                    else:
                        cid[x] = nv
                        L[nv] = x
                        nv += 1
                    c[j] = cid[x]
                done[f] = True
                order[t] = f
            else:
                for k in range(3):
                    s = _io_bit(False, st, rbuf, probs, cnts, M_SEED, syms, 2, cur, lens, 0)
                    if s < 0:
                        return 1, nv, pos
                    if s == 0:
                        if nv >= N:
                            return 1, nv, pos
                        c[k] = nv
                        nv += 1
                    else:
                        val, pos = _io_raw(False, st, rbuf, bits, pos, nbits, 0, _bitlen(nv - 1))
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
        gm = _bucket(gdone[u], GATE_BUCKETS[0]) * (GATE_BUCKETS[0][1] + 1)
        gm = (gm + _bucket(gdone[v], GATE_BUCKETS[0])) * (
            GATE_BUCKETS[1][1] - GATE_BUCKETS[1][0] + 1
        )
        gm += _bucket(fcnt[v], GATE_BUCKETS[1])
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
        g = _io_bit(encode, st, rbuf, probs, cnts, gm, syms, 0, cur, lens, 1 if f >= 0 else 0)
        if g < 0:
            return 1, nv, pos
        if g == 0:
            gdone[u] += 1
            gdone[v] += 1
            continue
        orient = 1
        if encode:
            for k in range(3):
                if F[f, k] == b and F[f, (k + 1) % 3] == a:
                    orient = 0
                if F[f, k] != a and F[f, k] != b:
                    w = F[f, k]
        orient = _io_bit(encode, st, rbuf, probs, cnts, M_ORIENT, syms, 1, cur, lens, orient)
        if orient < 0:
            return 1, nv, pos
        p, q2 = (v, u) if orient == 0 else (u, v)
        nc = _candidates(u, v, cand, hkeys, hval, ecnt, head, nxt, to, inline)
        cx = _context(ctx, fcnt[v], n_ctx)
        d = 0
        cw = -1
        s = 0
        if encode:
            cw = cid[w]
            if cw == -1:
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
                elif s == W_FAR:
                    s = W_ANY
            done[f] = True
            order[t] = f
        if inline:
            ma = _bucket(fcnt[v], THIRD_BUCKETS[0])
            mb = ma * (THIRD_BUCKETS[1][1] - THIRD_BUCKETS[1][0] + 1)
            mb += _bucket(fcnt[u], THIRD_BUCKETS[1])
            mc = mb * (THIRD_BUCKETS[2][1] - THIRD_BUCKETS[2][0] + 1)
            mc += _bucket(fcnt[cand[0]] if nc > 0 else 0, THIRD_BUCKETS[2])
            s = rc.code_symbol(
                encode, st, rbuf, probs, cnts, M_THIRD + ma * rc.SYM_STRIDE, s, W_ALPHA,
                M_THIRD + (_NA + mb) * rc.SYM_STRIDE, M_THIRD + (_NA + _NB + mc) * rc.SYM_STRIDE,
            )  # fmt: skip
        elif encode:
            wsym[cur[4]] = s  # all contexts in one array, split by ``wctx`` afterwards
            wctx[cur[4]] = ctx * 64 + min(fcnt[v], 63)  # both formats' contexts
            cur[4] += 1
        else:
            if cur[4 + cx] >= lens[4 + cx]:
                return 1, nv, pos
            s = wsym[woff[cx] + cur[4 + cx]]
            cur[4 + cx] += 1
        if s == W_FAR:
            d, pos, ok = _io_far(
                encode, st, rbuf, probs, cnts, syms, cur, lens, bits, pos, nbits, d
            )
            if not ok:
                return 1, nv, pos
            if not encode:
                r = _fen_prefix(btree, u) + d
                if r < 0 or r >= _fen_prefix(btree, N):
                    return 1, nv, pos
                cw = _fen_select(btree, r)
                if cw >= nv or cw == u or cw == v:
                    return 1, nv, pos
        elif s == W_ANY:
            cw, pos = _io_raw(encode, st, rbuf, bits, pos, nbits, cw, _bitlen(nv - 1))
            if not encode and (cw < 0 or cw >= nv or cw == u or cw == v):
                return 1, nv, pos
        elif not encode:
            if s == 0:
                if nv >= N:
                    return 1, nv, pos
                cw = nv
                nv += 1
            elif 2 <= s <= nc + 1:
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
    if inline:
        if encode:
            return 0, nv, rc.finish(st, rbuf)
        if st[5] > rbuf.size + 4:
            return 1, nv, pos
    for k in range(lens.size):
        if not encode and cur[k] != lens[k]:
            return 1, nv, pos
        lens[k] = cur[k]
    return 0, nv, pos


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
#: first byte of the code of faces in :func:`canonical` order whose stage-1 symbols are range
#: coded in traversal order under contexts of the decoded neighbourhood, the walks before the
#: interior neighbours among the candidates (docs/decisions.md#codec-conn-inline)
MARKER_INLINE = 0x43
#: :data:`MARKER_INLINE` without the range coder's first byte, which is always zero (the coded
#: interval starts inside ``[0, 1)``); written (docs/decisions.md#codec-rc-flush)
MARKER_INLINE2 = 0x44
MARKERS = (MARKER, MARKER_ADAPTIVE, MARKER_CANONICAL, MARKER_INLINE, MARKER_INLINE2)
_NO_RC = np.zeros(0, dtype=np.uint8)


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
    syms, wsym, wctx, lens, Fc, order, L, z = _stage1_arrays(m, NV_CTX)
    bits = _bitbuf(64 * (3 * m + 3))
    st, nv, pos = _topology(
        True, m, F, ekeys, eptr, efaces, n_univ, syms, wsym, wctx, z, lens, bits, 0, Fc, order, L,
        _NO_RC,
    )  # fmt: skip
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


def canonical(F: np.ndarray, n_vertices: int, traversed=None) -> tuple[np.ndarray, np.ndarray]:
    """``(perm, G)``: the traversal's vertex order (unused vertices last) and faces ``G`` in it.

    ``G`` lists the faces in traversal order, each rotated to start at its smallest index
    (orientation kept), so that :func:`encode` spends almost nothing on the two orders. ``G``
    is a fixed point: ``canonical(G, n)`` is ``(arange(n), G)``, so ``G`` codes inline.
    ``traversed``: :func:`traverse` of ``F``, when the caller has it.
    """
    F = np.ascontiguousarray(F, dtype=np.int64)
    _, _, _, _, Fc, _, L = _traverse(F) if traversed is None else traversed
    unused = np.ones(n_vertices, dtype=bool)
    unused[L] = False
    perm = np.r_[L, np.flatnonzero(unused)].astype(np.int64)
    rot = np.argmin(Fc, axis=1)
    idx = (rot[:, None] + np.arange(3)[None, :]) % 3
    return perm, np.take_along_axis(Fc, idx, axis=1)


def traverse(F: np.ndarray):
    """The traversal of ``F`` (int64, (m, 3), m >= 1) that :func:`encode` and :func:`canonical`
    start from; pass it to both to traverse once."""
    return _traverse(np.ascontiguousarray(F, dtype=np.int64))


def encode(F: np.ndarray, traversed=None) -> bytes:
    """Traversal code of ``F`` (int64, (m, 3), m >= 1); see the module docstring. Faces in
    :func:`canonical` order: :data:`MARKER_INLINE2`; others: the smaller of the adaptive and the
    static format. ``traversed``: :func:`traverse` of ``F``, when the caller has it."""
    F = np.ascontiguousarray(F, dtype=np.int64)
    m = F.shape[0]
    if _maybe_canonical(F):
        code = _encode_inline(F)
        if code is not None:
            return code
    n_univ, topo, bitsA, posA, Fc, order, L = _traverse(F) if traversed is None else traversed
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


def _stage1_arrays(m: int, n_ctx: int):
    """Stage-1 work arrays of :func:`_topology`: syms, wsym, wctx, lens, canonical faces,
    order, labels and a placeholder."""
    return (
        np.zeros((4, 3 * m + 3), dtype=np.int32),  # gate, orient, seed, far border
        np.zeros(m + 1, dtype=np.int32),  # third vertices of all contexts, in order
        np.zeros(m + 1, dtype=np.int16),
        np.zeros(4 + n_ctx, dtype=np.int64),
        np.zeros((m, 3), dtype=np.int64),
        np.zeros(m, dtype=np.int64),
        np.zeros(3 * m + 3, dtype=np.int64),
        np.zeros(1, dtype=np.int64),
    )


def _maybe_canonical(F: np.ndarray) -> bool:
    """Necessary conditions of :func:`canonical` order: every face starts at its smallest index
    and the vertices appear in order."""
    if not ((F[:, 0] <= F[:, 1]) & (F[:, 0] <= F[:, 2])).all():
        return False
    first = np.maximum.accumulate(F.max(axis=1))
    return bool(F.min() == 0 and (np.diff(first) <= 3).all() and first[0] <= 2)


def _encode_inline(F: np.ndarray) -> bytes | None:
    """:data:`MARKER_INLINE2` code of ``F``, or None when its faces are not in canonical order."""
    m = F.shape[0]
    n_univ = int(F.max()) + 1
    ekeys, eptr, efaces = _edge_table(F, n_univ)
    syms, wsym, wctx, lens, Fc, order, L, z = _stage1_arrays(m, NV_CTX)
    rbuf = np.zeros(24 * m + 1024, dtype=np.uint8)
    st, nv, nb = _topology(
        True, m, F, ekeys, eptr, efaces, n_univ, syms, wsym, wctx, z, lens, _NO_RC, 0, Fc, order, L,
        rbuf,
    )  # fmt: skip
    if st != 0 or nb > rbuf.size:  # pragma: no cover - at most 24 bytes per face are written
        raise RuntimeError("connectivity range coder overflow")
    if nv != n_univ or (L[:nv] != np.arange(nv)).any() or (order != np.arange(m)).any():
        return None
    if (F != Fc[np.arange(m)[:, None], (np.argmin(Fc, axis=1)[:, None] + np.arange(3)) % 3]).any():
        return None
    if rbuf[0] != 0:  # pragma: no cover - LZMA's coder never carries into its first byte
        raise RuntimeError("connectivity range coder wrote a nonzero first byte")
    return bytes([MARKER_INLINE2]) + rbuf[1:nb].tobytes()


def _decode_inline(blob: bytes, n_vertices: int, m: int) -> np.ndarray:
    """Faces of a :data:`MARKER_INLINE` code (after its first byte)."""
    rbuf = np.frombuffer(blob, dtype=np.uint8).copy()
    syms, wsym, wctx, lens, Fc, _, _, z = _stage1_arrays(1, NV_CTX)
    Fc = np.zeros((m, 3), dtype=np.int64)
    woff = np.zeros(NV_CTX + 1, dtype=np.int64)
    dummyF = np.zeros((1, 3), dtype=np.int64)
    st, nv, _ = _topology(
        False, m, dummyF, z, z, z, 1, syms, wsym, wctx, woff, lens, _NO_RC, 0, Fc, z, z, rbuf
    )
    if st != 0 or rbuf.size == 0 or not 1 <= nv <= n_vertices:
        raise InvalidInputError(".sgc connectivity is malformed (topology stream).")
    return Fc


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
    if marker in (MARKER_INLINE, MARKER_INLINE2):
        blob = r.rest()
        Fc = _decode_inline(b"\0" + blob if marker == MARKER_INLINE2 else blob, n_vertices, m)
    else:
        Fc = _decode_streams(r, marker, n_vertices, m)
        if marker != MARKER_CANONICAL:
            return Fc
    idx = (np.argmin(Fc, axis=1)[:, None] + np.arange(3)[None, :]) % 3
    return np.take_along_axis(Fc, idx, axis=1)


def _decode_streams(r: Reader, marker: int, n_vertices: int, m: int) -> np.ndarray:
    """Faces of a code with streams (:data:`MARKER`, :data:`MARKER_ADAPTIVE`: the file's
    faces; :data:`MARKER_CANONICAL`: the canonical faces before their rotation)."""
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
        False, m, dummyF, z, z, z, n_univ, syms, wsym, w16, woff, lens, bA, nA, Fc, z, z, _NO_RC
    )
    if st != 0 or nv2 != nv:
        raise InvalidInputError(".sgc connectivity is malformed (topology stream).")
    if marker == MARKER_CANONICAL:
        return Fc
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
