"""Integer kernels of the ``predictive`` codec: traversal, parallelogram prediction, range coder.

Both ends derive the vertex order from the connectivity: the next vertex is the one with the
most faces whose two other corners are decoded (a heap; ties first come first served; a new
component starts at the first face with an unvisited corner). A vertex is predicted by the mean
(floor) of a subset of its parallelograms ``a + b - c`` (edge ``(a, b)`` decoded with a decoded
opposite ``c``; the encoder picks the subset, one adaptive flag each); else the midpoint of two
decoded neighbours, one neighbour, or the previous vertex. Residuals go through an adaptive
binary range coder (LZMA's: 11-bit probabilities, shift-5 update): a zero flag, a direct sign,
the bit length in unary and the top mantissa bit adaptive, the other bits direct. Contexts: the
coordinate, the decoded neighbours' residual bit lengths and whether the previous coordinate's
residual was zero. The encoder may choose each vertex's grid point within a sphere around the
input (:func:`_choose`). Decoding is integer arithmetic: bit-identical on every machine.
"""

from __future__ import annotations

import heapq

import numba
import numpy as np

from ._rangecoder import bit as _rbit
from ._rangecoder import bitlen as _bitlen
from ._rangecoder import direct as _direct
from ._rangecoder import finish, start

#: bit lengths of residuals (|e| < 2**KMAX)
KMAX = 42
#: neighbour-magnitude buckets of the contexts
NB = 6
_STRIDE = 1 + KMAX + KMAX
_NCTX = 3 * NB * 3
#: most parallelograms averaged per vertex
MAXP = 4
_FLAGS = _NCTX * _STRIDE
_NPROB = _FLAGS + (MAXP + 1) * MAXP * 2
#: probability bits of the residual models
PB = 11
_ONE = 1 << PB


@numba.njit(cache=True)
def _vertex_faces(F, n):
    m = F.shape[0]
    ptr = np.zeros(n + 1, np.int64)
    for f in range(m):
        for k in range(3):
            ptr[F[f, k] + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    vf = np.empty(ptr[n], np.int64)
    fill = ptr[:n].copy()
    for f in range(m):
        for k in range(3):
            v = F[f, k]
            vf[fill[v]] = f
            fill[v] += 1
    return ptr, vf


@numba.njit(cache=True)
def _code_int(enc, st, buf, probs, base, value):
    """Code one residual (encoder: ``value``; decoder: returns it)."""
    if _rbit(enc, st, buf, probs, base, 1 if value == 0 else 0, PB) == 1:
        return np.int64(0)
    neg = _direct(enc, st, buf, 1 if value < 0 else 0)
    a = -value if value < 0 else value
    n_bits = _bitlen(a) if enc else 0
    k = 1
    while k < KMAX and _rbit(enc, st, buf, probs, base + k, 1 if k < n_bits else 0, PB) == 1:
        k += 1
    m = np.int64(1)
    for j in range(k - 2, -1, -1):
        b = (a >> j) & 1 if enc else 0
        if j == k - 2:
            b = _rbit(enc, st, buf, probs, base + KMAX + k, b, PB)
        else:
            b = _direct(enc, st, buf, b)
        m = (m << 1) | b
    return -m if neg else m


@numba.njit(cache=True)
def _parallelograms(F, ptr, vf, G, vis, v, P):
    """Parallelogram predictions ``a + b - c`` of ``v`` into the rows of ``P``; returns their
    count (at most ``P.shape[0]``)."""
    k = 0
    for t in range(ptr[v], ptr[v + 1]):
        g = vf[t]
        a = -1
        b = -1
        for j in range(3):
            w = F[g, j]
            if w != v:
                if a < 0:
                    a = w
                else:
                    b = w
        if a < 0 or b < 0 or not vis[a] or not vis[b]:
            continue
        for u in range(ptr[a], ptr[a + 1]):
            h = vf[u]
            if h == g:
                continue
            c = -1
            hasb = False
            for j in range(3):
                w = F[h, j]
                if w == b:
                    hasb = True
                elif w != a:
                    c = w
            if hasb and c >= 0 and c != v and vis[c]:
                for d in range(3):
                    P[k, d] = G[a, d] + G[b, d] - G[c, d]
                k += 1
                break
        if k == P.shape[0]:
            break
    return k


@numba.njit(cache=True)
def _mean_of(P, mask, k, p):
    s0 = np.int64(0)
    s1 = np.int64(0)
    s2 = np.int64(0)
    c = 0
    for j in range(k):
        if (mask >> j) & 1:
            s0 += P[j, 0]
            s1 += P[j, 1]
            s2 += P[j, 2]
            c += 1
    p[0] = s0 // c
    p[1] = s1 // c
    p[2] = s2 // c


@numba.njit(cache=True)
def _clamp(x, lo, hi):
    return lo if x < lo else (hi if x > hi else x)


@numba.njit(cache=True)
def _choose(L, H, X, rho, v, p, e):
    """Encoder: residuals ``e`` (3,) of vertex ``v`` from prediction ``p``; returns their cost
    estimate. ``rho > 0``: the grid point within distance ``rho`` of ``X[v]`` (grid units) near
    the prediction; else each coordinate the integer of ``[L, H]`` nearest it."""
    if rho > 0:
        n2 = 0.0
        for d in range(3):
            n2 += (p[d] - X[v, d]) ** 2
        if n2 <= rho * rho:
            e[:] = 0
            return 0
        t = rho / np.sqrt(n2)
        best = -1
        for mask in range(8):
            r2 = 0.0
            c = 0
            for d in range(3):
                y = X[v, d] + (p[d] - X[v, d]) * t
                g = np.int64(np.floor(y)) + ((mask >> d) & 1)
                r2 += (g - X[v, d]) ** 2
                a = g - p[d]
                c += _bitlen(-a if a < 0 else a) * 2 + (1 if a != 0 else 0)
            if r2 <= rho * rho and (best < 0 or c < best):
                best = c
                for d in range(3):
                    y = X[v, d] + (p[d] - X[v, d]) * t
                    e[d] = np.int64(np.floor(y)) + ((mask >> d) & 1) - p[d]
        if best >= 0:
            return best
        c = 0
        for d in range(3):
            e[d] = np.int64(np.floor(X[v, d] + 0.5)) - p[d]
            c += _bitlen(-e[d] if e[d] < 0 else e[d]) * 2 + (1 if e[d] != 0 else 0)
        return c
    c = 0
    for d in range(3):
        e[d] = _clamp(p[d], L[v, d], H[v, d]) - p[d]
        c += _bitlen(-e[d] if e[d] < 0 else e[d]) * 2 + (1 if e[d] != 0 else 0)
    return c


@numba.njit(cache=True)
def _predict(enc, st, buf, probs, F, ptr, vf, G, T, vis, v, f, prev, p, P, e):
    """Prediction of vertex ``v`` (met in face ``f``) into ``p``; returns its class 0-2. With
    parallelograms, the subset averaged is chosen by the encoder and sent as one flag each."""
    k = _parallelograms(F, ptr, vf, G, vis, v, P)
    if k > 0:
        best = (1 << k) - 1
        if enc and k > 1:
            _mean_of(P, best, k, p)
            bc = _choose(T[0], T[1], T[2], T[3], v, p, e)
            for mask in range(1, (1 << k) - 1):
                _mean_of(P, mask, k, p)
                c = _choose(T[0], T[1], T[2], T[3], v, p, e) + 1
                if c < bc:
                    bc = c
                    best = mask
        if k > 1:
            base = _FLAGS + (k * MAXP) * 2
            mask = 0
            used = 0
            for j in range(k):
                if j == k - 1 and used == 0:
                    mask |= 1 << j
                    break
                b = _rbit(enc, st, buf, probs, base + j * 2 + min(used, 1), (best >> j) & 1, PB)
                mask |= b << j
                used += b
            best = mask
        _mean_of(P, best, k, p)
        return 2
    a = -1
    b = -1
    for t in range(ptr[v], ptr[v + 1]):
        g = vf[t]
        x = -1
        y = -1
        for j in range(3):
            w = F[g, j]
            if w != v and vis[w]:
                if x < 0:
                    x = w
                else:
                    y = w
        if x >= 0 and a < 0:
            a = x
        if y >= 0:
            a = x
            b = y
            break
    if a >= 0 and b >= 0:
        for d in range(3):
            p[d] = (G[a, d] + G[b, d]) >> 1
        return 1
    if a >= 0:
        for d in range(3):
            p[d] = G[a, d]
        return 1
    for d in range(3):
        p[d] = G[prev, d] if prev >= 0 else 0
    return 0


@numba.njit(cache=True)
def _visit(enc, st, buf, probs, F, ptr, vf, G, T, vis, ek, v, f, prev, p, P, e3):
    cls = _predict(enc, st, buf, probs, F, ptr, vf, G, T, vis, v, f, prev, p, P, e3)
    if enc:
        _choose(T[0], T[1], T[2], T[3], v, p, e3)
    t = 0
    cnt = 0
    for u in range(ptr[v], ptr[v + 1]):
        g = vf[u]
        for j in range(3):
            w = F[g, j]
            if w != v and vis[w]:
                t += ek[w]
                cnt += 1
    bucket = 0 if cls == 0 else min(1 + (t + cnt // 2) // max(cnt, 1), NB - 1)
    mx = 0
    prev_zero = 1
    for d in range(3):
        ctx = (d * NB + bucket) * 3 + (0 if d == 0 else 1 + prev_zero)
        e = e3[d] if enc else np.int64(0)
        e = _code_int(enc, st, buf, probs, ctx * _STRIDE, e)
        G[v, d] = p[d] + e
        a = _bitlen(-e if e < 0 else e)
        prev_zero = 1 if a == 0 else 0
        mx = max(mx, a)
    ek[v] = mx
    vis[v] = True


@numba.njit(cache=True)
def run(enc, F, n, G, buf, L, H, X, rho):
    """Encode into ``buf`` (returns the byte count) or decode ``buf`` into ``G`` (n, 3) int64
    (returns the bytes read, or -1 when the data ran out). The encoder sends for each coordinate
    the integer in ``[L, H]`` closest to its prediction (``rho > 0``: the grid point within ``rho``
    of ``X``, grid units, near it) and writes it to ``G``."""
    T = (L, H, X, rho)
    e3 = np.zeros(3, np.int64)
    m = F.shape[0]
    ptr, vf = _vertex_faces(F, n)
    probs = np.full(_NPROB, _ONE >> 1, np.int64)
    st = np.zeros(6, np.int64)
    start(enc, st, buf)
    vis = np.zeros(n, np.bool_)
    gates = np.zeros(n, np.int64)
    seen = np.zeros(n, np.bool_)
    ek = np.zeros(n, np.int64)
    p = np.zeros(3, np.int64)
    P = np.zeros((MAXP, 3), np.int64)
    prev = -1
    seq = 0
    heap = [(np.int64(0), np.int64(0), np.int64(0))]
    heap.pop()
    for s in range(n + m):
        seed = F[s, 0] if s < m else s - m
        if vis[seed]:
            continue
        heapq.heappush(heap, (np.int64(0), np.int64(seq), np.int64(seed)))
        seq += 1
        while len(heap) > 0:
            neg, _sq, v = heapq.heappop(heap)
            if vis[v] or -neg != gates[v]:
                continue
            _visit(enc, st, buf, probs, F, ptr, vf, G, T, vis, ek, v, -1, prev, p, P, e3)
            prev = v
            # most decoded neighbourhood first: a vertex gains a gate with each face whose two
            # other corners are decoded
            for t in range(ptr[v], ptr[v + 1]):
                g = vf[t]
                for j in range(3):
                    w = F[g, j]
                    if w == v or vis[w]:
                        continue
                    third = F[g, 0] + F[g, 1] + F[g, 2] - v - w
                    if vis[third]:
                        gates[w] += 1
                    elif seen[w]:
                        continue
                    seen[w] = True
                    heapq.heappush(heap, (-gates[w], np.int64(seq), np.int64(w)))
                    seq += 1
            if not enc and st[5] > buf.size + 8:
                return -1
    if enc:
        return finish(st, buf)
    return st[5] if st[5] <= buf.size + 4 else -1
