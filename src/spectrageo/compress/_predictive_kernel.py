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
input (:func:`_choose`). Format 2 (:func:`_visit2`) codes the signs with adaptive models in
the context of the gate face's integer normal and of the decoded neighbours' residual signs
along theirs, mixes the parallelograms' spread into the magnitude context, and has the encoder
compare subsets and grid points by their cost under the current models. Format 3 is format 2
with counted models (16-bit probabilities whose n-th update moves them ``1 / min(n +
RES_RATE0, RES_RATE_MAX)`` of the way, so that they learn from few vertices), every magnitude
bit under the mean of its model and a coarse one (the neighbour bucket and the prediction class:
at most one, two, or more parallelograms), the subset flags in the context of the
parallelograms' spread, with one parallelogram its triangle's height in the magnitude context,
and a stream without its always-zero first byte and with its trailing
zero bytes implied. Decoding is integer arithmetic: bit-identical on every machine
(docs/decisions.md#codec-model-cost, docs/decisions.md#codec-counted-residuals).
"""

from __future__ import annotations

import heapq

import numba
import numpy as np

from ._rangecoder import _bit_at, finish, start
from ._rangecoder import bit as _rbit
from ._rangecoder import bitlen as _bitlen
from ._rangecoder import direct as _direct

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
#: classes of a coordinate axis against the gate face's normal (signs of format 2)
NAX = 3
#: weight of the parallelograms' spread against the neighbours' residual lengths in the
#: magnitude context of format 2 (docs/decisions.md#codec-model-cost)
SPREAD_WEIGHT = 1
_SIGNS = _NPROB
_NPROB2 = _SIGNS + 3 * NAX * 3 * 2
#: spread classes of the subset flags of format 3: the bit length of the parallelograms'
#: largest coordinate spread, ``0, 1, .., FLAG_SPREAD - 1`` or more
FLAG_SPREAD = 4
_FLAGS3 = _NPROB2
_MAG3 = _FLAGS3 + FLAG_SPREAD * (MAXP + 1) * MAXP * 2
#: coarse magnitude contexts of format 3, mixed with the fine ones: the neighbour bucket times
#: the prediction class (at most one, two, or more parallelograms)
_NPROB3 = _MAG3 + 3 * NB * _STRIDE
#: format 3, one parallelogram ``a + b - c``: the magnitude context mixes the bit length of
#: ``|2 (a + b - 2 c)| >> HEIGHT_SHIFT`` along the coordinate (twice the gate triangle's height
#: vector) into the neighbour bucket, as the spread does with two or more parallelograms
#: (docs/decisions.md#codec-counted-residuals)
HEIGHT_SHIFT = 2
#: probability bits of the residual models
PB = 11
_ONE = 1 << PB
#: probability bits of the counted models of format 3
PB3 = 16
#: counted models of format 3: the n-th update of a model moves its probability
#: ``1 / min(n + RES_RATE0, RES_RATE_MAX)`` of the way to the bit seen
#: (docs/decisions.md#codec-counted-residuals)
RES_RATE0 = 4
RES_RATE_MAX = 32
#: encoder's cost, in 1/16 bit, of a bit of probability ``i / 2**PB``
_COST = np.array([round(-16 * np.log2(max(i, 0.5) / _ONE)) for i in range(_ONE + 1)], np.int64)


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
def _mbit(enc, st, buf, probs, cnts, i, b, j=-1):
    """Code bit ``b`` (encoder) or return the decoded bit with the model ``probs[i]``: shift-5
    updates of ``PB`` bits (formats 1-2, ``cnts`` empty), or counted updates of ``PB3`` bits,
    the n-th (``cnts[i]``) moving it ``1 / min(n + RES_RATE0, RES_RATE_MAX)`` of the way;
    ``j >= 0`` (counted only): under the mean of ``probs[i]`` and ``probs[j]``, both updated."""
    if cnts.size == 0:
        return _rbit(enc, st, buf, probs, i, b, PB)
    p = probs[i] if j < 0 else (probs[i] + probs[j]) >> 1
    b = _bit_at(enc, st, buf, p, b, PB3)
    _count(probs, cnts, i, b)
    if j >= 0:
        _count(probs, cnts, j, b)
    return b


@numba.njit(cache=True, inline="always")
def _count(probs, cnts, i, b):
    d = min(cnts[i] + RES_RATE0, RES_RATE_MAX)
    cnts[i] = min(cnts[i] + 1, RES_RATE_MAX)
    p = probs[i]
    probs[i] = p + ((1 << PB3) - p) // d if b == 0 else p - p // d


@numba.njit(cache=True, inline="always")
def _p11(probs, cnts, i, j=-1):
    """Probability of :func:`_mbit` on ``PB`` bits (the encoder's cost table)."""
    if cnts.size == 0:
        return probs[i]
    return (probs[i] if j < 0 else (probs[i] + probs[j]) >> 1) >> (PB3 - PB)


@numba.njit(cache=True)
def _code_int(enc, st, buf, probs, base, value):
    """Code one residual (encoder: ``value``; decoder: returns it)."""
    return _code_signed(enc, st, buf, probs, np.zeros(0, np.int64), base, value, -1)


@numba.njit(cache=True, inline="always")
def _o(i, j):
    """Index ``i + j`` of the second model, or -1 when ``j`` is -1 (none)."""
    return -1 if j == -1 else i + j


@numba.njit(cache=True)
def _code_signed(enc, st, buf, probs, cnts, base, value, sign, base2=-1):
    """:func:`_code_int` with the sign coded by the adaptive model ``probs[sign]`` (``sign``
    < 0: a direct bit); ``cnts``: see :func:`_mbit`; ``base2 >= 0``: every magnitude bit
    under the mean of the models at ``base + i`` and ``base2 + i``."""
    j = -1 if base2 < 0 else base2 - base
    if _mbit(enc, st, buf, probs, cnts, base, 1 if value == 0 else 0, _o(base, j)) == 1:
        return np.int64(0)
    if sign < 0:
        neg = _direct(enc, st, buf, 1 if value < 0 else 0)
    else:
        neg = _mbit(enc, st, buf, probs, cnts, sign, 1 if value < 0 else 0)
    a = -value if value < 0 else value
    n_bits = _bitlen(a) if enc else 0
    k = 1
    while (
        k < KMAX
        and _mbit(enc, st, buf, probs, cnts, base + k, 1 if k < n_bits else 0, _o(base + k, j)) == 1
    ):
        k += 1
    m = np.int64(1)
    for j in range(k - 2, -1, -1):
        b = (a >> j) & 1 if enc else 0
        if j == k - 2:
            b = _mbit(enc, st, buf, probs, cnts, base + KMAX + k, b, _o(base + KMAX + k, j))
        else:
            b = _direct(enc, st, buf, b)
        m = (m << 1) | b
    return -m if neg else m


@numba.njit(cache=True)
def _parallelograms(F, ptr, vf, G, vis, v, P):
    """Parallelogram predictions ``a + b - c`` of ``v`` into the rows of ``P``; returns their
    count (at most ``P.shape[0]``)."""
    return _parallelograms_at(F, ptr, vf, G, vis, v, P, np.zeros(0, np.int64))


@numba.njit(cache=True)
def _parallelograms_at(F, ptr, vf, G, vis, v, P, gate):
    """:func:`_parallelograms`; ``gate[0]`` (when ``gate`` is not empty) gets the face of the
    first parallelogram's opposite corner."""
    k = _parallelogram_corners(F, ptr, vf, vis, v, P, gate)
    for i in range(k):  # row i holds its corners until it is replaced by their parallelogram
        a, b, c = P[i, 0], P[i, 1], P[i, 2]
        for d in range(3):
            P[i, d] = G[a, d] + G[b, d] - G[c, d]
    return k


@numba.njit(cache=True)
def _parallelogram_corners(F, ptr, vf, vis, v, abc, gate):
    """Corners ``(a, b, c)`` of the parallelograms ``a + b - c`` of ``v`` (decoded edge
    ``(a, b)``, decoded opposite ``c``) into the rows of ``abc``; returns their count (at most
    ``abc.shape[0]``); ``gate[0]`` (when ``gate`` is not empty) gets the first one's opposite
    face."""
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
                if k == 0 and gate.size:
                    gate[0] = h
                abc[k, 0] = a
                abc[k, 1] = b
                abc[k, 2] = c
                k += 1
                break
        if k == abc.shape[0]:
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
def _predict(enc, st, buf, probs, cnts, F, ptr, vf, G, T, vis, v, f, prev, p, P, e, W):
    """Prediction of vertex ``v`` (met in face ``f``) into ``p``; returns its class 0-2. With
    parallelograms, the subset averaged is chosen by the encoder and sent as one flag each."""
    gate = W[0]
    gate[0] = -1
    k = _parallelograms_at(F, ptr, vf, G, vis, v, P, gate)
    if k > 0:
        best = (1 << k) - 1
        if enc and k > 1:
            _mean_of(P, best, k, p)
            bc = _choose(T, v, p, e, probs, cnts, W[6], W[3], W[4])
            for mask in range(1, (1 << k) - 1):
                _mean_of(P, mask, k, p)
                c = _choose(T, v, p, e, probs, cnts, W[6], W[3], W[4]) + 1
                if c < bc:
                    bc = c
                    best = mask
        if k > 1:
            best = _code_flags(enc, st, buf, probs, cnts, k, best, _FLAGS)
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
def _normal(F, G, h, nv):
    """Integer normal of face ``h`` into ``nv`` (3,), scaled down below ``2**15``; zero when
    ``h < 0``."""
    nv[:] = 0
    if h < 0:
        return
    a = F[h, 0]
    b = F[h, 1]
    c = F[h, 2]
    u0 = G[b, 0] - G[a, 0]
    u1 = G[b, 1] - G[a, 1]
    u2 = G[b, 2] - G[a, 2]
    w0 = G[c, 0] - G[a, 0]
    w1 = G[c, 1] - G[a, 1]
    w2 = G[c, 2] - G[a, 2]
    m = max(max(abs(u0), abs(u1)), max(abs(u2), max(abs(w0), max(abs(w1), abs(w2)))))
    s = max(_bitlen(m) - 24, 0)
    u0 >>= s
    u1 >>= s
    u2 >>= s
    w0 >>= s
    w1 >>= s
    w2 >>= s
    nv[0] = u1 * w2 - u2 * w1
    nv[1] = u2 * w0 - u0 * w2
    nv[2] = u0 * w1 - u1 * w0
    m = max(max(abs(nv[0]), abs(nv[1])), abs(nv[2]))
    s = max(_bitlen(m) - 15, 0)
    for d in range(3):
        nv[d] >>= s


@numba.njit(cache=True)
def _visit(enc, st, buf, probs, F, ptr, vf, G, T, vis, ek, v, f, prev, p, P, e3, W):
    none = np.zeros(0, np.int64)
    cls = _predict(enc, st, buf, probs, none, F, ptr, vf, G, T, vis, v, f, prev, p, P, e3, W)
    if enc:
        _choose(T, v, p, e3, probs, none, W[6], W[3], W[4])
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
def _bit_cost(p, b):
    return _COST[p] if b == 0 else _COST[_ONE - p]


@numba.njit(cache=True)
def _cost_int(probs, cnts, base, value, sign, base2=-1):
    """Encoder: cost (1/16 bit) of :func:`_code_signed` under the current models."""
    j = -1 if base2 < 0 else base2 - base
    if value == 0:
        return _COST[_ONE - _p11(probs, cnts, base, _o(base, j))]
    c = _COST[_p11(probs, cnts, base, _o(base, j))]
    c += 16 if sign < 0 else _bit_cost(_p11(probs, cnts, sign), 1 if value < 0 else 0)
    nb = _bitlen(-value if value < 0 else value)
    k = 1
    while k < KMAX:
        if k < nb:
            c += _COST[_ONE - _p11(probs, cnts, base + k, _o(base + k, j))]
            k += 1
        else:
            c += _COST[_p11(probs, cnts, base + k, _o(base + k, j))]
            break
    if k >= 2:
        a = -value if value < 0 else value
        i = base + KMAX + k
        c += _bit_cost(_p11(probs, cnts, i, _o(i, j)), (a >> (k - 2)) & 1) + 16 * (k - 2)
    return c


@numba.njit(cache=True, inline="always")
def _coarse(cnts, bk, d):
    """Format 3: base of the coarse magnitude model of coordinate ``d``: its bucket
    ``bk[d]`` and the prediction class ``bk[3]`` (else -1: none)."""
    return _MAG3 + (bk[3] * NB + bk[d]) * _STRIDE if cnts.size else -1


@numba.njit(cache=True)
def _cost3(probs, cnts, bk, e, sg):
    c = 0
    prev_zero = 1
    for d in range(3):
        ctx = (d * NB + bk[d]) * 3 + (0 if d == 0 else 1 + prev_zero)
        c += _cost_int(probs, cnts, ctx * _STRIDE, e[d], sg[d], _coarse(cnts, bk, d))
        prev_zero = 1 if e[d] == 0 else 0
    return c


@numba.njit(cache=True)
def _cost(probs, cnts, bk, e, sg):
    """Encoder: cost of the residuals ``e`` (3,): under the current models (1/16 bit), or the
    estimate ``2 bitlen + (e != 0)`` each when ``bk[0] < 0`` (format 1)."""
    if bk[0] >= 0:
        return _cost3(probs, cnts, bk, e, sg)
    c = 0
    for d in range(3):
        c += _bitlen(-e[d] if e[d] < 0 else e[d]) * 2 + (1 if e[d] != 0 else 0)
    return c


@numba.njit(cache=True)
def _choose(T, v, p, e, probs, cnts, bk, sg, tmp):
    """Encoder: residuals ``e`` (3,) of vertex ``v`` from prediction ``p``; returns their cost
    (:func:`_cost`). ``rho > 0``: of the grid points within distance ``rho`` of ``X[v]`` (grid
    units) around the sphere's point toward the prediction, the cheapest; else each coordinate
    the integer of ``[L, H]`` nearest the prediction."""
    L, H, X, rho = T
    if rho <= 0:
        for d in range(3):
            e[d] = _clamp(p[d], L[v, d], H[v, d]) - p[d]
        return _cost(probs, cnts, bk, e, sg)
    n2 = 0.0
    for d in range(3):
        n2 += (p[d] - X[v, d]) ** 2
    if n2 <= rho * rho:
        e[:] = 0
        return _cost(probs, cnts, bk, e, sg)
    t = rho / np.sqrt(n2)
    best = -1
    for mask in range(8):
        r2 = 0.0
        for d in range(3):
            y = X[v, d] + (p[d] - X[v, d]) * t
            g = np.int64(np.floor(y)) + ((mask >> d) & 1)
            r2 += (g - X[v, d]) ** 2
            tmp[d] = g - p[d]
        if r2 <= rho * rho:
            c = _cost(probs, cnts, bk, tmp, sg)
            if best < 0 or c < best:
                best = c
                e[:] = tmp
    if best >= 0:
        return best
    for d in range(3):
        e[d] = np.int64(np.floor(X[v, d] + 0.5)) - p[d]
    return _cost(probs, cnts, bk, e, sg)


@numba.njit(cache=True)
def _code_flags(enc, st, buf, probs, cnts, k, best, fb):
    """The subset ``best`` of ``k > 1`` parallelograms as one adaptive flag each (the last
    implied when no other is set), the models from ``probs[fb + 2 k MAXP:]``; returns it
    (decoder: the decoded subset)."""
    base = fb + (k * MAXP) * 2
    mask = 0
    used = 0
    for j in range(k):
        if j == k - 1 and used == 0:
            mask |= 1 << j
            break
        b = _mbit(enc, st, buf, probs, cnts, base + j * 2 + min(used, 1), (best >> j) & 1)
        mask |= b << j
        used += b
    return mask


@numba.njit(cache=True)
def _flag_cost(probs, cnts, k, mask, fb):
    base = fb + (k * MAXP) * 2
    used = 0
    c = 0
    for j in range(k):
        if j == k - 1 and used == 0:
            break
        b = (mask >> j) & 1
        c += _bit_cost(_p11(probs, cnts, base + j * 2 + min(used, 1)), b)
        used += b
    return c


@numba.njit(cache=True)
def _visit2(enc, st, buf, probs, cnts, F, ptr, vf, G, T, vis, ek, v, prev, p, P, e3, W):
    """Format 2: :func:`_visit` with adaptive signs in the context of the gate face's normal
    and the decoded neighbours' residuals along theirs, and the encoder's choices (subset,
    grid point) by their cost under the current models. Format 3 (``cnts`` not empty):
    counted models, each magnitude bit also under the coarse model of its bucket and
    prediction class (:func:`_coarse`), the subset flags under the bit length of the
    parallelograms' largest coordinate spread (:data:`FLAG_SPREAD` classes), and with one
    parallelogram the gate triangle's height in the magnitude bucket (:data:`HEIGHT_SHIFT`)."""
    gate, nv, conv, sg, tmp, bk, _ = W
    gate[0] = -1
    k = _parallelograms_at(F, ptr, vf, G, vis, v, P, gate)
    cls = 2
    if k == 0:
        cls = _predict(enc, st, buf, probs, cnts, F, ptr, vf, G, T, vis, v, -1, prev, p, P, e3, W)
    t = 0
    cnt = 0
    sc = 0
    for u in range(ptr[v], ptr[v + 1]):
        g = vf[u]
        for j in range(3):
            w = F[g, j]
            if w != v and vis[w]:
                t += ek[w]
                cnt += 1
                sc += conv[w]
    bucket = 0 if cls == 0 else min(1 + (t + cnt // 2) // max(cnt, 1), NB - 1)
    for d in range(3):
        bk[d] = bucket
    bk[3] = 0 if k <= 1 else (1 if k == 2 else 2)
    for d in range(3):
        if k >= 2:
            lo = P[0, d]
            hi = P[0, d]
            for j in range(1, k):
                lo = min(lo, P[j, d])
                hi = max(hi, P[j, d])
            sp = _bitlen((hi - lo) >> 1)
            c = max(cnt, 1) * (SPREAD_WEIGHT + 1)
            bk[d] = min(1 + (t + SPREAD_WEIGHT * sp * cnt + c // 2) // c, NB - 1)
        elif k == 1 and cnts.size:
            h = gate[0]
            hv = 3 * P[0, d] - G[F[h, 0], d] - G[F[h, 1], d] - G[F[h, 2], d]  # 2 (P - c)
            sp = _bitlen(abs(hv) >> HEIGHT_SHIFT)
            c = max(cnt, 1) * 2
            bk[d] = min(1 + (t + sp * cnt + c // 2) // c, NB - 1)
    s3 = 0 if sc < 0 else (1 if sc == 0 else 2)
    fb = _FLAGS
    if cnts.size and k >= 2:  # format 3: flags in the context of the spread
        w = 0
        for d in range(3):
            lo = P[0, d]
            hi = P[0, d]
            for j in range(1, k):
                lo = min(lo, P[j, d])
                hi = max(hi, P[j, d])
            w = max(w, hi - lo)
        fb = _FLAGS3 + min(_bitlen(w), FLAG_SPREAD - 1) * (MAXP + 1) * MAXP * 2
    _normal(F, G, gate[0], nv)
    mn = max(max(abs(nv[0]), abs(nv[1])), abs(nv[2]))
    for d in range(3):
        an = abs(nv[d])
        ax = 2 if 4 * an >= 3 * mn else (1 if 20 * an >= 7 * mn else 0)
        sg[d] = _SIGNS + ((d * NAX + ax) * 3 + s3) * 2 + (1 if nv[d] < 0 else 0)
        if mn == 0:
            sg[d] = -1
    if k > 0:
        best = (1 << k) - 1
        if enc and k > 1:
            bc = -1
            for mask in range(1, 1 << k):
                _mean_of(P, mask, k, p)
                c = _choose(T, v, p, e3, probs, cnts, bk, sg, tmp)
                c += _flag_cost(probs, cnts, k, mask, fb)
                if bc < 0 or c < bc:
                    bc = c
                    best = mask
        if k > 1:
            best = _code_flags(enc, st, buf, probs, cnts, k, best, fb)
        _mean_of(P, best, k, p)
    if enc:
        _choose(T, v, p, e3, probs, cnts, bk, sg, tmp)
    mx = 0
    prev_zero = 1
    dot = 0
    for d in range(3):
        ctx = (d * NB + bk[d]) * 3 + (0 if d == 0 else 1 + prev_zero)
        e = e3[d] if enc else np.int64(0)
        e = _code_signed(enc, st, buf, probs, cnts, ctx * _STRIDE, e, sg[d], _coarse(cnts, bk, d))
        G[v, d] = p[d] + e
        dot += e * nv[d]
        a = _bitlen(-e if e < 0 else e)
        prev_zero = 1 if a == 0 else 0
        mx = max(mx, a)
    conv[v] = 0 if dot == 0 else (1 if dot > 0 else -1)
    ek[v] = mx
    vis[v] = True


@numba.njit(cache=True)
def traversal_order(F, n):
    """The vertex order (n,) both ends derive from the connectivity ``F`` (m, 3): the next vertex
    is the one with the most faces whose two other corners come before it (a heap; ties first
    come first served); a new component starts at the first face with an unvisited corner, then
    the isolated vertices in index order."""
    ptr, vf = _vertex_faces(F, n)
    return _order(F, n, ptr, vf)


@numba.njit(cache=True)
def _order(F, n, ptr, vf):
    """:func:`traversal_order` with the vertex-face incidence ``ptr``, ``vf`` given."""
    m = F.shape[0]
    vis = np.zeros(n, np.bool_)
    gates = np.zeros(n, np.int64)
    seen = np.zeros(n, np.bool_)
    order = np.empty(n, np.int64)
    i = 0
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
            vis[v] = True
            order[i] = v
            i += 1
            # a vertex gains a gate with each face whose two other corners are visited
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
    return order


@numba.njit(nogil=True, cache=True)
def run(enc, F, n, G, buf, L, H, X, rho, ver=1):
    """Encode into ``buf`` (returns the byte count) or decode ``buf`` into ``G`` (n, 3) int64
    (returns the bytes read, or -1 when the data ran out), the vertices in
    :func:`traversal_order`. The encoder sends for each coordinate the integer in ``[L, H]``
    closest to its prediction (``rho > 0``: the grid point within ``rho`` of ``X``, grid units,
    near it) and writes it to ``G``. ``ver``: the residual format (1: tag 6, :func:`_visit`;
    2: tag 7, :func:`_visit2`; 3: tag 8, :func:`_visit2` with counted and mixed models, the
    stream taken as followed by zero bytes: the encoder ends it on the value of its final
    interval with the most trailing zero bits, so that they need not be stored, and the
    decoder never runs out)."""
    T = (L, H, X, rho)
    e3 = np.zeros(3, np.int64)
    ptr, vf = _vertex_faces(F, n)
    probs = np.full(_NPROB3, (1 << PB3 if ver >= 3 else _ONE) >> 1, np.int64)
    cnts = np.zeros(_NPROB3 if ver >= 3 else 0, np.int64)
    # work arrays: gate face, normal, convexity signs, sign models, candidate residuals,
    # magnitude buckets, and buckets of -1 (format 1's cost estimate)
    z = np.zeros(3, np.int64)
    bk = np.zeros(4, np.int64)
    W = (np.zeros(1, np.int64), z, np.zeros(n, np.int64), z.copy(), z.copy(), bk, z - 1)
    st = np.zeros(6, np.int64)
    start(enc, st, buf)
    vis = np.zeros(n, np.bool_)
    ek = np.zeros(n, np.int64)
    p = np.zeros(3, np.int64)
    P = np.zeros((MAXP, 3), np.int64)
    prev = -1
    for v in _order(F, n, ptr, vf):
        if ver == 1:
            _visit(enc, st, buf, probs, F, ptr, vf, G, T, vis, ek, v, -1, prev, p, P, e3, W)
        else:
            _visit2(enc, st, buf, probs, cnts, F, ptr, vf, G, T, vis, ek, v, prev, p, P, e3, W)
        prev = v
        if not enc and ver < 3 and st[5] > buf.size + 8:
            return -1
    if enc:
        return finish(st, buf)
    return st[5] if st[5] <= buf.size + 4 or ver >= 3 else -1
