"""``pca-pred``: trajectory PCA with the coefficients predicted along the mesh.

Not a method of the thesis (Coddyac-like, after Vasa and Skala): the normalised trajectories of
a block of ``T`` frames, one row ``y_v`` (3T,) per vertex (x, then y, then z over time), are

    y_v ~ m~ + sum_j c~_vj b~_j,    c~_vj = s q_vj,

``m~`` the quantised mean trajectory, ``b~_j`` the quantised eigen-trajectories of the vertex
covariance (principal components, by decreasing variance), ``q_vj`` integers. The coefficients
are least-squares projections on the dequantised basis, rounded on one grid of step ``s``; a
component is kept while its error removed pays for its bits (``lambda = ln2/6 s^2``, as in
``pca-q``). The integers are coded losslessly vertex by vertex in the static predictive
coder's order (most decoded faces first, :func:`._predictive_kernel.traversal_order`):

1. base prediction ``p_vj`` (a rational): the mean of the parallelograms ``q_a + q_b - q_c``
   of the vertex's decoded faces, or of its decoded 1-ring (one flag per component, the
   encoder's choice), else 0;
2. the base residual ``r_vj = q_vj - p_vj`` is predicted (``x_vj``) from the vertex's own
   decoded ``r_v0 .. r_v(j-1)`` (the first :data:`PREG`) by a ridge regression fitted on the
   decoded two rings (locally the residual trajectories of a rigidly moving patch span three
   dimensions, so few components predict the rest), used for a component while its running
   cost is the lower one (both ends keep it);
3. ``q_vj - round(p_vj + x_vj)`` goes through the binary range coder of :mod:`._rangecoder`,
   each binary decision under the mean of three adaptive models (:func:`_contexts`: the
   component with the decoded 1-ring's residual bit lengths and the vertex's two previous
   ones; with the vertex's bit lengths so far against the decoded vertices' and the two
   rings'; with the spread of the values the base prediction averages); its sign in contexts
   of the component and the rounding remainder (the side the real prediction leans to).

The mean and basis trajectories are integers on per-column steps, each row predicted from
its own previous values (order 0, 1 or 2, two bits per row) and range coded under two adaptive
models (:func:`_code_basis`).

The encoder may round a coefficient to its other nearest integer when that saves more than
:data:`RDO_LAMBDA` squared steps per bit. The decoder's floating-point steps (the regression,
one product :func:`._dense_fixed.matmul`) are numba loops in a written order without BLAS or
``fastmath``: the same bits on every machine. See docs/decisions.md#anim-pca-pred,
docs/decisions.md#anim-pred2-traversal, docs/decisions.md#anim-pred2-rational,
docs/decisions.md#anim-speed-coder and docs/decisions.md#anim-pred3-contexts.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._errors import InvalidInputError
from ._container import Reader, varint
from ._predictive_kernel import (
    KMAX,
    PB3,
    _code_signed,
    _order,
    _parallelogram_corners,
    _vertex_faces,
)
from ._rangecoder import RATE0, RATE_MAX, _bit_at, finish, start
from ._rangecoder import bitlen as _bitlen
from ._rangecoder import direct as _direct

TAG_BASIS = 3
TAG_COEFF = 4
#: step of the mean trajectory relative to the coefficient step
MEAN_RATIO = 0.25
#: step of basis column ``j``: ``BASIS_RATIO * s sqrt(n / 3T) / ||c_j||``
BASIS_RATIO = 0.5
#: most parallelograms averaged per vertex
MAXP = 4
#: most decoded neighbours averaged per vertex
MAXN = 8
#: most decoded vertices of the two rings in a vertex's local regression
MAXR = 24
#: previous components regressed on (their base residuals) in the local regression
#: (docs/decisions.md#anim-pred3-contexts)
PREG = 32
#: ridge of the local regression (squared integer residuals)
RIDGE = 20.0
#: fewest ring vertices for a local regression
MINR = 8
#: rate-distortion weight of the encoder's choice between the two nearest integers
#: (squared steps per estimated bit)
RDO_LAMBDA = 0.15
#: component contexts: one each below ``_JDIRECT``, then by bit length
_JDIRECT = 24
_JB = _JDIRECT + 8
#: neighbour-magnitude buckets
_NB = 6
#: buckets of the bit lengths of the vertex's two previous components
_NP = 5
_NCTX = _JB * _NB * _NP
#: models per magnitude context: zero flag, unary bit lengths, top mantissa bits
_STRIDE = 1 + KMAX + KMAX
#: buckets a bit of the vertex's mean residual bit length above the decoded vertices' (the
#: second context's activity classes)
_ASCALE = 2.0
_NCTX2 = _NCTX + _JB * _NB * _NB
#: classes of the spread of the base prediction's values (the third context)
_NS = 8
_NCTX3 = _NCTX2 + _JB * _NS * _NB
#: probability bits of the residual models
PBM = 16
#: weight of the second model (the vertex's activity) in the mean of the three
_W2 = 2
#: sign contexts per component: classes of the prediction's rounding remainder in [-1/2, 1/2)
_NF = 5


# ----------------------------------------------------------------------------- traversal
def make_plan(F: np.ndarray, n: int) -> tuple:
    """``(F, order, ptr, vf, rings, n1)``: the vertex order of the static predictive coder
    (:func:`._predictive_kernel.traversal_order`: most decoded faces first), the vertex-face
    incidence, up to ``MAXR`` vertices of the two rings decoded before each vertex (n, MAXR;
    -1 where there are fewer), the decoded 1-ring first, and the 1-ring's count (n,)."""
    F = np.ascontiguousarray(F, dtype=np.int64)
    ptr, vf = _vertex_faces(F, n)
    order = _order(F, n, ptr, vf)
    rings, n1 = _rings(ptr, vf, F, order)
    return F, order, ptr, vf, rings, n1


@numba.njit(cache=True)
def _rings(ptr, vf, F, order):
    """Up to ``MAXR`` vertices of the two rings of every vertex decoded before it, the 1-ring
    first (n, MAXR), and how many of them are in the 1-ring (n,)."""
    n = order.size
    pos = np.empty(n, np.int64)
    for i in range(n):
        pos[order[i]] = i
    Rg = np.full((n, MAXR), -1, np.int64)
    n1 = np.zeros(n, np.int64)
    stamp = np.full(n, -1, np.int64)
    for v in range(n):
        m = 0
        stamp[v] = v
        for ring in range(
            2
        ):  # the decoded 1-ring first, then the 2-ring through every 1-ring vertex
            for t in range(ptr[v], ptr[v + 1]):
                for j in range(3):
                    u = F[vf[t], j]
                    if ring == 0:
                        if stamp[u] != v and pos[u] < pos[v] and m < MAXR:
                            stamp[u] = v
                            Rg[v, m] = u
                            m += 1
                        continue
                    for t2 in range(ptr[u], ptr[u + 1]):
                        for j2 in range(3):
                            w = F[vf[t2], j2]
                            if stamp[w] != v and pos[w] < pos[v] and m < MAXR:
                                stamp[w] = v
                                Rg[v, m] = w
                                m += 1
            if ring == 0:
                n1[v] = m
    return Rg, n1


@numba.njit(cache=True)
def _jctx(j):
    return j if j < _JDIRECT else _JDIRECT + min(_bitlen(j - _JDIRECT), _JB - _JDIRECT - 1)


@numba.njit(cache=True)
def _base(F, ptr, vf, vis, Rg, nn, v, Q, flags, abc, out, fr):
    """Predictions ``out + fr`` (k,) of the vertex ``v`` from the decoded ``Q`` (n, >= k): the
    mean of the parallelograms ``a + b - c`` (:func:`._predictive_kernel._parallelogram_corners`,
    found once per vertex) where its flag is 0, else (or without one) the mean of the decoded
    1-ring's ``nn`` vertices, else 0; ``out`` the floor (int64), ``fr`` the remainder over the
    count, in [0, 1); returns the parallelogram count."""
    k = out.size
    cnt = _parallelogram_corners(F, ptr, vf, vis, v, abc, abc[0, :0])
    sp = np.zeros(k, np.int64)
    sr = np.zeros(k, np.int64)
    for i in range(cnt):
        a, b, c = abc[i, 0], abc[i, 1], abc[i, 2]
        for j in range(k):
            sp[j] += Q[a, j] + Q[b, j] - Q[c, j]
    for i in range(nn):
        u = Rg[v, i]
        for j in range(k):
            sr[j] += Q[u, j]
    for j in range(k):
        if cnt > 0 and flags[j] == 0:
            out[j] = sp[j] // cnt
            fr[j] = (sp[j] - cnt * out[j]) / cnt
        elif nn > 0:
            out[j] = sr[j] // nn
            fr[j] = (sr[j] - nn * out[j]) / nn
        else:
            out[j] = 0
            fr[j] = 0.0
    return cnt


def _padded(Q: np.ndarray) -> np.ndarray:
    """``Q`` (n, k) in an (n, 3 ceil(k / 3)) int64 array, zero columns after."""
    n, k = Q.shape
    out = np.zeros((n, 3 * (-(-k // 3))), np.int64)
    out[:, :k] = Q
    return out


@numba.njit(cache=True)
def choose_flags(order, ptr, vf, F, Rg, n1, Q, k):
    """Per component, 1 where the decoded 1-ring's mean predicts ``Q`` (n, 3 ceil(k / 3)) with
    fewer residual bits (``2 bitlen + 1``) than the parallelograms."""
    n = Q.shape[0]
    cost = np.zeros((2, k), np.int64)
    vis = np.zeros(n, np.bool_)
    abc = np.zeros((MAXP, 3), np.int64)
    out = np.zeros(k, np.int64)
    par = np.zeros(k, np.int64)
    fr = np.zeros(k)
    s = np.zeros(k, np.int64)
    for v in order:
        nn = min(n1[v], MAXN)
        if _base(F, ptr, vf, vis, Rg, nn, v, Q, par, abc, out, fr) > 0:
            s[:] = 0
            for i in range(nn):
                u = Rg[v, i]
                for j in range(k):
                    s[j] += Q[u, j]
            for j in range(k):
                e = Q[v, j] - out[j]
                cost[0, j] += 2 * _bitlen(-e if e < 0 else e) + 1
                e = Q[v, j] - s[j] // nn
                cost[1, j] += 2 * _bitlen(-e if e < 0 else e) + 1
        vis[v] = True
    return (cost[1] < cost[0]).astype(np.int64)


@numba.njit(cache=True, inline="always")
def _mbit(enc, st, buf, probs, cnts, i, j, l, b):
    """Bit ``b`` under the mean of the adaptive probabilities ``probs[i]``, ``probs[j]`` and
    ``probs[l]`` (those >= 0), each updated ``1 / min(n + RATE0, RATE_MAX)`` of the way to the
    bit at its ``n``-th use (``cnts``)."""
    p = probs[i]
    c = 1
    if j >= 0:
        p += _W2 * probs[j]
        c += _W2
    if l >= 0:
        p += probs[l]
        c += 1
    b = _bit_at(enc, st, buf, p // c, b, PBM)
    for x in (i, j, l):
        if x >= 0:
            d = min(cnts[x] + RATE0, RATE_MAX)
            cnts[x] = min(cnts[x] + 1, RATE_MAX)
            q = probs[x]
            probs[x] = q + ((1 << PBM) - q) // d if b == 0 else q - q // d
    return b


@numba.njit(cache=True)
def _code_res(enc, st, buf, probs, cnts, bases, value, sign):
    """Residual ``value`` (encoder) or the decoded one: a zero flag, the sign (model ``sign``),
    the bit length in unary and the top mantissa bit under the mean of the models at the three
    ``bases`` (:func:`_mbit`), the other bits direct."""
    b0, b1, b2 = bases[0], bases[1], bases[2]
    if _mbit(enc, st, buf, probs, cnts, b0, b1, b2, 1 if value == 0 else 0):
        return np.int64(0)
    neg = _mbit(enc, st, buf, probs, cnts, sign, -1, -1, 1 if value < 0 else 0)
    a = -value if value < 0 else value
    n_bits = _bitlen(a) if enc else 0
    k = 1
    while k < KMAX:
        if _mbit(enc, st, buf, probs, cnts, b0 + k, b1 + k, b2 + k, 1 if k < n_bits else 0) == 0:
            break
        k += 1
    m = np.int64(1)
    for j in range(k - 2, -1, -1):
        b = (a >> j) & 1 if enc else 0
        if j == k - 2:
            o = KMAX + k
            b = _mbit(enc, st, buf, probs, cnts, b0 + o, b1 + o, b2 + o, b)
        else:
            b = _direct(enc, st, buf, b)
        m = (m << 1) | b
    return -m if neg else m


@numba.njit(cache=True)
def _contexts(j, nn, mr, m1, m2, pz, ab, spr, bases):
    """Model offsets ``bases`` (3,) of component ``j``'s residual at a vertex, each with the
    component's class (:func:`_jctx`): (1) the decoded 1-ring's (``nn`` vertices, bit lengths
    summing to ``m1``) mean residual bit length and the vertex's two previous ones (``pz``);
    (2) the class ``ab`` of the vertex's bit lengths so far above the decoded vertices' mean
    (0: none yet) and the decoded two rings' (``mr``, sum ``m2``) mean; (3) the spread ``spr``
    of the values the base prediction averages and the 1-ring's mean."""
    jc = _jctx(j)
    b1 = 0 if nn == 0 else min(1 + (m1 + nn // 2) // nn, _NB - 1)
    b2 = 0 if mr == 0 else min(1 + (m2 + mr // 2) // mr, _NB - 1)
    bases[0] = ((jc * _NB + b1) * _NP + pz) * _STRIDE
    bases[1] = (_NCTX + (jc * _NB + ab) * _NB + b2) * _STRIDE
    bases[2] = (_NCTX2 + (jc * _NS + min(spr, _NS - 1)) * _NB + b1) * _STRIDE


@numba.njit(cache=True)
def _spread(Q, abc, cnt, Rg, v, nn, flag, j):
    """Bit length of the range of the values :func:`_base` averages for component ``j`` (0
    with fewer than two)."""
    lo = np.int64(0)
    hi = np.int64(0)
    if cnt > 1 and flag == 0:
        for i in range(cnt):
            x = Q[abc[i, 0], j] + Q[abc[i, 1], j] - Q[abc[i, 2], j]
            lo = x if i == 0 or x < lo else lo
            hi = x if i == 0 or x > hi else hi
    elif nn > 1 and (cnt == 0 or flag != 0):
        for i in range(nn):
            x = Q[Rg[v, i], j]
            lo = x if i == 0 or x < lo else lo
            hi = x if i == 0 or x > hi else hi
    else:
        return 0
    return 1 + _bitlen(hi - lo)


@numba.njit(cache=True)
def _local_factor(Rg, Rb, v, qm, X, L):
    """Rows ``X`` (m, qm) of the ring's base residuals in the first ``qm`` components and the
    Cholesky factor ``L`` of ``X^T X + RIDGE I`` (sums in index order); returns ``m``."""
    m = 0
    while m < MAXR and Rg[v, m] >= 0:
        u = Rg[v, m]
        for i in range(qm):
            X[m, i] = float(Rb[u, i])
        m += 1
    if m < MINR:
        return m
    for i in range(qm):
        for j in range(i + 1):
            a = RIDGE if i == j else 0.0
            for r in range(m):
                a += X[r, i] * X[r, j]
            for t in range(j):
                a -= L[i, t] * L[j, t]
            L[i, j] = math.sqrt(a) if i == j else a / L[j, j]
    return m


@numba.njit(cache=True)
def _ring_weights(Rb, v, q, m, X, L, w, u):
    """Weights ``u`` (m,) of the ring's rows with ``u . y`` the ridge regression's prediction of
    any ring column ``y`` from the vertex's own first ``q`` base residuals:
    ``u = X_q (L_q L_q^T)^{-1} r_v`` (two triangular solves, ``w`` (q,) scratch)."""
    for i in range(q):
        a = float(Rb[v, i])
        for t in range(i):
            a -= L[i, t] * w[t]
        w[i] = a / L[i, i]
    for i in range(q - 1, -1, -1):
        a = w[i]
        for t in range(i + 1, q):
            a -= L[t, i] * w[t]
        w[i] = a / L[i, i]
    for r in range(m):
        a = 0.0
        for i in range(q):
            a += X[r, i] * w[i]
        u[r] = a


@numba.njit(cache=True)
def _local_predict(Rg, Rb, v, j, q, m, X, L, w, y):
    """Ridge regression of the ring's base residual of component ``j`` on its first ``q``
    components, applied to the vertex's own (decoded) first ``q`` (a float)."""
    _ring_weights(Rb, v, q, m, X, L, w, y)
    x = 0.0
    for r in range(m):
        x += y[r] * float(Rb[Rg[v, r], j])
    return x


@numba.njit(cache=True)
def _local_predict_rest(Rg, Rb, v, j0, q, m, X, L, Y, W, xs):
    """:func:`_local_predict` of every component ``j >= j0`` on the first ``q`` into ``xs``
    (``xs[j - j0]``), the same operations in the same order per component, the ring weights
    computed once (``Y`` (MAXR, >= 1), ``W`` (q, >= 1) scratch: their first columns)."""
    nj = Rb.shape[1] - j0
    u = Y[:, 0]
    _ring_weights(Rb, v, q, m, X, L, W[:, 0], u)
    for jj in range(nj):
        xs[jj] = 0.0
    for r in range(m):
        c = u[r]
        g = Rg[v, r]
        for jj in range(nj):
            xs[jj] += c * float(Rb[g, j0 + jj])


@numba.njit(cache=True)
def code(enc, F, order, ptr, vf, Rg, n1, flags, Q, X, lam, buf):
    """Encode ``Q`` (n, k) int64 (in an (n, 3 ceil(k / 3)) array) into ``buf`` (returns the
    byte count, which may exceed the buffer) or decode ``buf`` into ``Q`` (returns the bytes
    read, -1 when the data ran out).

    The real base residual ``r = Q - p`` (``p``: :func:`_base`, with its remainder) of a
    component is further predicted by :func:`_local_predict` (``x``) where that has been
    cheaper so far for that component (a running cost both ends keep); the coded residual is
    ``e = Q - round(p + x)``, its sign in the context of the component and of the rounding
    remainder ``p + x - round(p + x)`` (:data:`_NF` classes). With ``lam > 0`` the encoder
    first re-quantises every ``X`` (n, k, in steps) to the one of its two nearest integers
    minimising ``(X - q)^2 + lam (2 bitlen|e| + 1)`` and writes it to ``Q``."""
    n = Q.shape[0]
    k = flags.size
    probs = np.full(_NCTX3 * _STRIDE + _JB * _NF, 1 << (PBM - 1), np.int64)
    bases = np.zeros(3, np.int64)
    cnts = np.zeros(probs.size, np.int64)
    colsum = np.zeros(k, np.int64)
    m1 = np.zeros(k, np.int64)
    m2 = np.zeros(k, np.int64)
    nvis = 0
    fr = np.zeros(k)
    st = np.zeros(6, np.int64)
    start(enc, st, buf)
    ek = np.zeros((n, k), np.int64)
    Rb = np.zeros((n, k))
    acc = np.zeros((2, k), np.int64)
    rdo = enc and lam > 0
    qm = min(PREG, k)
    Xr = np.zeros((MAXR, max(qm, 1)))
    L = np.zeros((max(qm, 1), max(qm, 1)))
    w = np.zeros(max(qm, 1))
    yr = np.zeros(MAXR)
    Yr = np.zeros((MAXR, 1))
    Wr = np.zeros((max(qm, 1), 1))
    xs = np.zeros(k)
    vis = np.zeros(n, np.bool_)
    abc = np.zeros((MAXP, 3), np.int64)
    base = np.zeros(k, np.int64)
    for v in order:
        nn = min(n1[v], MAXN)
        cnt = _base(F, ptr, vf, vis, Rg, nn, v, Q, flags, abc, base, fr)
        m = _local_factor(Rg, Rb, v, qm, Xr, L)
        ws = 0
        cs = 0
        mr = 0
        while mr < MAXR and Rg[v, mr] >= 0:
            mr += 1
        m1[:] = 0
        for i in range(mr):  # the decoded rings' residual bit lengths, the 1-ring's first
            if i == nn:
                m2[:] = m1
            u = Rg[v, i]
            for j in range(k):
                m1[j] += ek[u, j]
        if mr == nn:
            m2[:] = m1
        else:
            m1, m2 = m2, m1
        pz = 0
        for j in range(k):
            p = base[j]
            xr = 0.0
            reg = j > 0 and m >= MINR
            if reg and j < qm:
                xr = _local_predict(Rg, Rb, v, j, j, m, Xr, L, w, yr)
            elif reg:  # the same regression on the first qm for every later component
                if j == qm:
                    _local_predict_rest(Rg, Rb, v, qm, qm, m, Xr, L, Yr, Wr, xs)
                xr = xs[j - qm]
            use = reg and acc[1, j] < acc[0, j]
            r0 = fr[j]
            p0 = p + np.int64(math.floor(r0 + 0.5))
            r1 = fr[j] + xr
            p1 = p + np.int64(math.floor(r1 + 0.5))
            pt = p1 if use else p0
            f = (r1 if use else r0) - (pt - p)
            fc = min(max(np.int64(math.floor((f + 0.5) * _NF)), 0), _NF - 1)
            sgn = _NCTX3 * _STRIDE + _jctx(j) * _NF + fc
            spr = _spread(Q, abc, cnt, Rg, v, nn, flags[j], j)
            ab = 0
            if j > 0 and nvis > 0:
                act = np.int64(math.floor(_ASCALE * (ws - cs / nvis) / j + 0.5))
                ab = min(max(act + 3, 1), _NB - 1)
            _contexts(j, nn, mr, m1[j], m2[j], pz, ab, spr, bases)
            if rdo:
                x = X[v, j]
                q0 = np.int64(np.floor(x))
                e0 = q0 - pt
                e1 = e0 + 1
                c0 = (x - q0) ** 2 + lam * (2 * _bitlen(-e0 if e0 < 0 else e0) + 1)
                c1 = (q0 + 1 - x) ** 2 + lam * (2 * _bitlen(-e1 if e1 < 0 else e1) + 1)
                Q[v, j] = q0 if c0 <= c1 else q0 + 1
            e = Q[v, j] - pt if enc else np.int64(0)
            e = _code_res(enc, st, buf, probs, cnts, bases, e, sgn)
            Q[v, j] = pt + e
            Rb[v, j] = (Q[v, j] - p) - fr[j]
            if reg:
                e2 = Q[v, j] - p1
                eb = Q[v, j] - p0
                acc[0, j] += 2 * _bitlen(-eb if eb < 0 else eb) + 1 - (acc[0, j] >> 6)
                acc[1, j] += 2 * _bitlen(-e2 if e2 < 0 else e2) + 1 - (acc[1, j] >> 6)
            b = _bitlen(-e if e < 0 else e)
            ek[v, j] = b
            ws += b
            cs += colsum[j]
            b2 = b + (ek[v, j - 1] if j > 0 else b)
            pz = min((b2 + 1) // 2, _NP - 1)
        vis[v] = True
        nvis += 1
        for j in range(k):
            colsum[j] += ek[v, j]
        if not enc and st[5] > buf.size + 8:
            return -1
    if enc:
        return finish(st, buf)
    return st[5] if st[5] <= buf.size + 4 else -1


def encode_coefficients(X: np.ndarray, pl, lam: float) -> tuple[bytes, np.ndarray]:
    """``(chunk, Q)``: the coefficients ``X`` (n, k, in steps) quantised to integers ``Q`` (the
    nearest, or the cheaper neighbour with ``lam > 0``: :func:`code`) and range coded in the
    order of ``pl`` (:func:`make_plan`), after one predictor flag per component (packed bits)."""
    F, order, ptr, vf, Rg, n1 = pl
    k = X.shape[1]
    Xp = _padded(np.zeros(X.shape, np.int64)).astype(np.float64)
    Xp[:, :k] = X
    Q0 = np.rint(Xp).astype(np.int64)
    flags = choose_flags(order, ptr, vf, F, Rg, n1, Q0, k)
    head = np.packbits(flags.astype(np.uint8)).tobytes()
    size = 64 + Q0.size // 2
    while True:
        buf = np.zeros(size, np.uint8)
        Q = Q0.copy()
        used = code(True, F, order, ptr, vf, Rg, n1, flags, Q, Xp, float(lam), buf)
        if used <= size:
            return head + buf[:used].tobytes(), Q[:, :k]
        size = int(used) + 16


def decode_coefficients(data: bytes, pl, n: int, k: int) -> np.ndarray:
    """Inverse of :func:`encode_coefficients`: ``Q`` (n, k) int64."""
    F, order, ptr, vf, Rg, n1 = pl
    Q = _padded(np.zeros((n, k), np.int64))
    if k == 0:
        return Q[:, :0]
    nb = (k + 7) // 8
    if len(data) < nb:
        raise InvalidInputError(".sga coefficients are malformed (truncated).")
    flags = np.unpackbits(np.frombuffer(data[:nb], np.uint8))[:k].astype(np.int64)
    buf = np.frombuffer(data[nb:], np.uint8).copy()
    if code(False, F, order, ptr, vf, Rg, n1, flags, Q, np.zeros((1, 1)), 0.0, buf) < 0:
        raise InvalidInputError(".sga coefficients are malformed (truncated).")
    return np.ascontiguousarray(Q[:, :k])


# ----------------------------------------------------------------------------- basis
#: bit-length buckets of the basis coder's two contexts
_BNA = 12
_BSTRIDE = 2 * KMAX + 2
#: largest |integer| a decoded basis value may have (a damaged stream is refused beyond it)
_BMAX = 1 << 40


@numba.njit(cache=True, inline="always")
def _bpred(Z, r, c, t, o):
    """Prediction of ``Z[r, c, t]`` of order ``o`` (0: none, 1: the previous value, 2: linear
    from the two previous), lower orders at the start of a coordinate."""
    if o == 0 or t == 0:
        return np.int64(0)
    if o == 1 or t == 1:
        return Z[r, c, t - 1]
    return 2 * Z[r, c, t - 1] - Z[r, c, t - 2]


@numba.njit(cache=True)
def _code_basis(enc, Z, orders, buf):
    """Encode the integer trajectories ``Z`` (R, 3, T) (row 0 the mean, then the basis columns)
    into ``buf`` (returns the byte count) or decode ``buf`` into ``Z`` (returns the bytes read,
    -1 when the data ran out or a value left ``[-_BMAX, _BMAX]``). Row ``r`` is predicted with
    order ``orders[r]`` (:func:`_bpred`); the residual goes through
    :func:`._predictive_kernel._code_signed` under the mean of two adaptive models: the start
    class of ``t`` with the mean bit length of the row's two previous residuals, and with the
    bit lengths of the previous row's residual at the same ``(c, t)`` and of the previous
    coordinate's at the same ``t``."""
    R, _c, T = Z.shape
    probs = np.full(6 * _BNA * _BSTRIDE, 1 << (PB3 - 1), np.int64)
    cnts = np.zeros(probs.size, np.int64)
    st = np.zeros(6, np.int64)
    start(enc, st, buf)
    E = np.zeros((R, 3, T), np.int64)
    for r in range(R):
        o = orders[r]
        for c in range(3):
            for t in range(T):
                p = _bpred(Z, r, c, t, o)
                tc = 2 if o == 0 or t >= o else t
                a = E[r, c, t - 1] if t >= 1 else 0
                a += E[r, c, t - 2] if t >= 2 else a
                b = (E[r - 1, c, t] if r > 1 else 0) + (E[r, c - 1, t] if c > 0 else 0)
                base = (tc * _BNA + min((a + 1) // 2, _BNA - 1)) * _BSTRIDE
                base2 = ((3 + tc) * _BNA + min(b, _BNA - 1)) * _BSTRIDE
                v = Z[r, c, t] - p if enc else np.int64(0)
                v = _code_signed(enc, st, buf, probs, cnts, base, v, -1, base2)
                if not enc:
                    z = v + p
                    if z > _BMAX or z < -_BMAX or st[5] > buf.size + 8:
                        return -1
                    Z[r, c, t] = z
                E[r, c, t] = _bitlen(-v if v < 0 else v)
    if enc:
        return finish(st, buf)
    return st[5] if st[5] <= buf.size + 4 else -1


def _orders(Z: np.ndarray) -> np.ndarray:
    """Per row, the prediction order (0, 1 or 2) of the smallest ``sum 2 bitlen|residual| + 1``."""
    cost = np.stack(
        [
            np.sum(2 * np.ceil(np.log2(np.abs(np.diff(Z, n=o, axis=2)) + 1)) + 1, axis=(1, 2))
            for o in (0, 1, 2)
        ]
    )
    return np.argmin(cost, axis=0).astype(np.int64)


def basis_chunk(qm, sm, qB, sb, T: int) -> bytes:
    """Mean trajectory (step ``sm``) and basis columns (``qB`` (3T, k), steps ``sb``): the
    steps, two bits per row (its prediction order), then :func:`_code_basis`'s stream."""
    k = qB.shape[1]
    Z = np.concatenate([np.asarray(qm).reshape(1, 3, T), qB.T.reshape(k, 3, T)]).astype(np.int64)
    if np.abs(Z).max() > _BMAX:
        raise InvalidInputError("quantised basis values are too large to code; use a coarser step.")
    orders = _orders(Z)
    bits = np.stack([orders >> 1, orders & 1], axis=1).astype(np.uint8)
    head = varint(k) + np.float32(sm).tobytes() + sb.astype("<f4").tobytes()
    size = 64 + 2 * Z.size
    while True:
        buf = np.zeros(size, np.uint8)
        used = _code_basis(True, Z, orders, buf)
        if used <= size:
            return head + np.packbits(bits.ravel()).tobytes() + buf[:used].tobytes()
        size = int(used) + 16


def read_basis(buf: bytes, T: int) -> tuple[np.ndarray, np.ndarray]:
    """``(mean (3T,), basis (3T, k))`` dequantised from a basis chunk."""
    r = Reader(buf, "trajectory basis")
    k = r.varint()
    if k > 3 * T:
        raise InvalidInputError(".sga trajectory basis is malformed (too many components).")
    sm = float(np.frombuffer(r.take(4), "<f4")[0])
    sb = np.frombuffer(r.take(4 * k), "<f4").astype(np.float64)
    if not (math.isfinite(sm) and sm > 0 and np.isfinite(sb).all() and (sb > 0).all()):
        raise InvalidInputError(".sga trajectory basis is malformed (bad steps).")
    nb = (2 * (k + 1) + 7) // 8
    bits = np.unpackbits(np.frombuffer(r.take(nb), np.uint8))[: 2 * (k + 1)].reshape(k + 1, 2)
    orders = (2 * bits[:, 0] + bits[:, 1]).astype(np.int64)
    if (orders > 2).any():
        raise InvalidInputError(".sga trajectory basis is malformed (bad prediction order).")
    Z = np.zeros((k + 1, 3, T), np.int64)
    if _code_basis(False, Z, orders, np.frombuffer(r.rest(), np.uint8).copy()) < 0:
        raise InvalidInputError(".sga trajectory basis is malformed (truncated or damaged).")
    Z = Z.reshape(k + 1, 3 * T)
    return Z[0] * sm, (Z[1:] * sb[:, None]).T


# ----------------------------------------------------------------------------- encoder
def _counts(q: np.ndarray) -> np.ndarray:
    """Occurrences of the distinct values of the integer-valued ``q``, by increasing value (those
    of ``np.unique``; by ``np.bincount`` where the range is small)."""
    lo, hi = float(q.min()), float(q.max())
    if hi - lo > 4 * q.size + 1024:
        return np.unique(q, return_counts=True)[1]
    cnt = np.bincount((q - lo).astype(np.int64))
    return cnt[cnt > 0]


class PcaPredEncoder:
    """Analysis of one block ``X`` (T, n, 3) (normalised frames) shared by every step."""

    def __init__(self, X: np.ndarray, F: np.ndarray, plan: tuple | None = None) -> None:
        T, n = X.shape[:2]
        self.T, self.n = T, n
        Y = np.ascontiguousarray(X.transpose(1, 2, 0).reshape(n, 3 * T))
        self.mu = Y.mean(axis=0)
        self.Yc = Y - self.mu
        if 3 * T <= n:
            w, V = np.linalg.eigh(self.Yc.T @ self.Yc)
            V = V[:, ::-1]
        else:  # the vertex Gram matrix is the smaller one
            w, U = np.linalg.eigh(self.Yc @ self.Yc.T)
            U = U[:, ::-1][:, : 3 * T]
            V = self.Yc.T @ U
            V /= np.maximum(np.linalg.norm(V, axis=0), 1e-300)
        idx = np.argmax(np.abs(V), axis=0)
        sg = np.sign(V[idx, np.arange(V.shape[1])])
        sg[sg == 0] = 1.0
        self.V = V * sg
        self.energy = np.maximum(w[::-1][: V.shape[1]], 0.0)  # ||Yc v_j||^2
        self._C = np.zeros((n, 0))
        self.plan = make_plan(F, n) if plan is None else plan
        self._q: dict = {}
        self._p: dict = {}

    def cols(self, k: int) -> np.ndarray:
        """Coefficients (n, k) of the first ``k`` components on the exact basis (computed as
        far as asked)."""
        if self._C.shape[1] < k:
            self._C = np.hstack([self._C, self.Yc @ self.V[:, self._C.shape[1] : k]])
        return self._C[:, :k]

    def significant(self) -> int:
        """Components holding more than 1e-9 of the energy each."""
        return int(np.count_nonzero(self.energy > 1e-9 * max(float(self.energy.sum()), 1e-300)))

    def keep(self, s: float) -> int:
        """Components kept at step ``s``: the last one whose removed error beats ``lambda`` times
        its bits (zero-order entropy of its rounded coefficients plus its basis column)."""
        lam = math.log(2) / 6.0 * s * s
        col = 8.0 * self.T  # about 8 bits per basis entry
        k = 0
        C = self.cols(int(np.count_nonzero(self.energy >= lam * col)))
        for j in range(C.shape[1]):
            c = C[:, j]
            q = np.rint(c / s)
            gain = self.energy[j] - float(np.sum((c - s * q) ** 2))
            cnt = _counts(q)
            bits = -float(np.sum(cnt * np.log2(cnt / q.size)))
            if gain > lam * (bits + col):
                k = j + 1
        return k

    def project(self, s: float) -> tuple:
        """``(qm, sm, qB, sb, C)`` at step ``s``: the quantised mean (step ``sm``) and basis
        (steps ``sb``) and the coefficients ``C`` (n, k) on the dequantised basis, in steps
        (cached for the last step)."""
        if s not in self._p:
            self._p = {s: self._project(s)}
        return self._p[s]

    def _project(self, s: float) -> tuple:
        T, n = self.T, self.n
        k = self.keep(s)
        sm = float(np.float32(MEAN_RATIO * s))
        qm = np.rint(self.mu / sm).astype(np.int64)
        norms = np.sqrt(self.energy[:k])
        sb = BASIS_RATIO * s * math.sqrt(n / (3.0 * T)) / np.maximum(norms, 1e-30)
        sb = np.clip(sb, 2.0**-24, 0.25).astype(np.float32).astype(np.float64)
        qB = np.rint(self.V[:, :k] / sb).astype(np.int64)
        Bq = qB * sb
        Yr = self.Yc + (self.mu - qm * sm)
        if k:
            C = np.linalg.solve(Bq.T @ Bq, Bq.T @ Yr.T).T
        else:
            C = np.zeros((n, 0))
        return qm, sm, qB, sb, C / s

    def quantise(self, s: float):
        """``(qm, sm, qB, sb, Q, mean~, basis~, coefficient chunk)`` at step ``s`` (cached for
        the last step)."""
        if s in self._q:
            return self._q[s]
        qm, sm, qB, sb, C = self.project(s)
        coef, Q = encode_coefficients(C, self.plan, RDO_LAMBDA)
        self._q = {s: (qm, sm, qB, sb, Q, qm * sm, qB * sb, coef)}
        return self._q[s]

    def chunks(self, s: float) -> list:
        qm, sm, qB, sb, _Q, _m, _B, coef = self.quantise(s)
        return [(TAG_BASIS, basis_chunk(qm, sm, qB, sb, self.T)), (TAG_COEFF, coef)]


def synthesise(mean: np.ndarray, B: np.ndarray, Q: np.ndarray, s: float, T: int) -> np.ndarray:
    """Normalised frames (T, n, 3) of ``m~ + (s Q) B~^T``, the product in a fixed order."""
    from ._dense_fixed import matmul

    n, k = Q.shape
    Y = np.broadcast_to(mean, (n, 3 * T)).copy()
    if k:
        Y += matmul(np.ascontiguousarray(Q * s, dtype=np.float64), np.ascontiguousarray(B.T))
    return Y.reshape(n, 3, T).transpose(2, 0, 1)


def reconstruct(pl, n: int, chunks, nf: int, step: float) -> np.ndarray:
    """Normalised frames (nf, n, 3) of a ``pca-pred`` block segment; ``pl``: :func:`make_plan`."""
    tags = [t for t, _ in chunks]
    if tags != [TAG_BASIS, TAG_COEFF]:
        raise InvalidInputError(f".sga block has chunks {tags}; expected [3, 4].")
    mean, B = read_basis(chunks[0][1], nf)
    Q = decode_coefficients(chunks[1][1], pl, n, B.shape[1])
    return synthesise(mean, B, Q, step, nf)


# ----------------------------------------------------------------------------- file
#: coder version, in the stream header's ``n_iter`` field (1: the breadth-first order and floor
#: predictions of the first development code; 2: one magnitude context per residual bit, the
#: regression on the first 12 components; 3: the basis in Laplace groups of first differences;
#: none read any more)
CODER = 4
#: default frames per block (one trajectory PCA each; its covariance is (3 block)^2)
PRED_BLOCK = 512
#: default coefficient step (fraction of the frames' bounding-box diagonal)
PRED_STEP = 2.5e-4


class PcaPredFileEncoder:
    """A whole ``pca-pred`` file: blocks of ``block`` frames of ``frames`` (T, n, 3) normalised
    by ``(origin, scale)``, each analysed once and coded at any step."""

    def __init__(self, frames, F, block: int, origin, scale: float) -> None:
        self.method = "pca-pred"
        self.T, self.n = frames.shape[:2]
        self.F = F
        self.origin, self.scale = origin, scale
        self.blk = min(block, self.T)
        self.anchors = np.zeros(0, np.int64)
        self.reordered = False
        X = (frames - origin) / scale
        self.parts = [
            (t0, PcaPredEncoder(X[t0 : t0 + self.blk], F)) for t0 in range(0, self.T, self.blk)
        ]

    def params(self, step: float):
        from ._sga_format import Params

        return Params(self.method, self.T, self.blk, 0, float(step), 1.0, 1.0, 0, CODER)

    def build(self, step: float) -> bytes:
        from ._sga_format import block_segment, header_segment, index_segment

        m = self.F.shape[0]
        o = tuple(self.origin)
        p = self.params(step)
        head = header_segment(
            self.method, self.n, m, o, self.scale, p, self.F, self.anchors, self.reordered
        )
        out = [head]
        off = len(out[0])
        entries = []
        for b, (t0, enc) in enumerate(self.parts):
            seg = block_segment(
                self.method, self.n, m, o, self.scale, b, t0, enc.T, step, enc.chunks(step)
            )
            entries.append((t0, enc.T, off, len(seg)))
            off += len(seg)
            out.append(seg)
        out.append(index_segment(self.method, self.n, m, o, self.scale, entries))
        return b"".join(out)

    def frames(self, step: float) -> np.ndarray:
        """The decoded frames (T, n, 3) of the file at ``step`` (products by BLAS: within
        rounding of the decoder's fixed-order ones)."""
        out = []
        for _t0, enc in self.parts:
            Q, mean, B = enc.quantise(step)[4:7]
            Y = mean + (Q * step) @ B.T
            out.append(Y.reshape(enc.n, 3, enc.T).transpose(2, 0, 1))
        return np.concatenate(out) * self.scale + self.origin

    def sq_error(self, step: float, rounded: bool = False) -> float:
        """Squared Frobenius error of :meth:`frames` against the coded frames; ``rounded``: of
        the coefficients rounded to the nearest step instead of the coder's choices (no coding)."""
        e2 = 0.0
        for _t0, enc in self.parts:
            if rounded:
                qm, sm, qB, sb, C = enc.project(step)
                Q, mean, B = np.rint(C), qm * sm, qB * sb
            else:
                Q, mean, B = enc.quantise(step)[4:7]
            D = (Q * step) @ B.T
            D -= enc.Yc
            D += mean - enc.mu
            e2 += float(np.einsum("ij,ij->", D, D))
        return e2 * self.scale * self.scale
