"""Dense linear algebra in a fixed order of operations, for the codec decoders (numba, no BLAS).

Plain loops compiled without ``fastmath`` (no reassociation, no FMA, vectorised only across
independent outputs), so a decoder turns the same bytes into the same numbers on every machine
(docs/decisions.md#deterministic-decoders). Matrices are C-ordered float64; accumulations run
over the summation index in ascending order (column indices cast to ``uint64`` so LLVM
vectorises them). Kernels: :func:`tridiagonalise` (``dsytd2``) with :func:`apply_q` /
:func:`apply_qt`; :func:`ql_rotations` (implicit QL, rotations recorded; :func:`rotate`,
:func:`rotate_t`); :func:`eigh`, :func:`eigh_lowest` (Jacobi fallback :func:`eigh_jacobi`;
ascending, largest entry positive); :func:`qr`, :func:`svd`; :func:`matmul`, :func:`matmul_tn`;
:func:`reverse_cuthill_mckee`, :func:`envelope_cholesky`, :func:`solve_power` (Eq. 5.42).
numba caches by source file: after editing this module, clear its callers' caches.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

#: sweeps of the one-sided Jacobi SVD and of the Jacobi eigensolver before giving up
JACOBI_SWEEPS = 60
#: QL iterations allowed per eigenvalue
QL_ITERS = 60


@njit(nogil=True, cache=True)
def hypot(a, b):
    """``sqrt(a^2 + b^2)`` without overflow, from one square root: ``|a| sqrt(1 + (b/a)^2)``
    with ``|a| >= |b|`` (within 2 ulp; the same on every machine, unlike the C library's)."""
    a = abs(a)
    b = abs(b)
    if a < b:
        a, b = b, a
    if a == 0.0:
        return 0.0
    r = b / a
    return a * math.sqrt(1.0 + r * r)


@njit(nogil=True, cache=True)
def _reflector(x, lo, hi):
    """Householder reflector ``H = I - tau v v^T`` with ``H x[lo:hi] = (beta, 0, ..., 0)`` (LAPACK
    ``dlarfg``): ``x[lo+1:hi]`` is overwritten with ``v[1:]`` (``v[0] = 1``); returns
    ``(beta, tau)``, ``tau = 0`` when ``x[lo+1:hi]`` is zero."""
    alpha = x[lo]
    s = 0.0
    for r in range(lo + 1, hi):
        s += x[r] * x[r]
    if s == 0.0:
        return alpha, 0.0
    beta = hypot(alpha, math.sqrt(s))
    if alpha >= 0.0:
        beta = -beta
    tau = (beta - alpha) / beta
    scal = 1.0 / (alpha - beta)
    for r in range(lo + 1, hi):
        x[r] *= scal
    return beta, tau


# ----------------------------------------------------------------------------- tridiagonal
@njit(nogil=True, cache=True)
def _next_reflector(A, i, v, w, d, e, tau):
    """Reflector of step ``i`` of :func:`tridiagonalise` from row ``i`` of ``A`` (already
    updated by the previous steps): sets ``d[i]``, ``e[i]``, ``tau[i]``, ``v[i+1:]`` (with
    ``v[i+1] = 1``) and zeroes ``w[i+1:]`` for the product ``A22 v``; returns ``tau[i]``."""
    n = A.shape[0]
    row = A[i]
    d[i] = row[i]
    beta, t = _reflector(row, i + 1, n)
    e[i] = beta
    tau[i] = t
    if t != 0.0:
        row[i + 1] = beta
        v[i + 1] = 1.0
        for r in range(i + 2, n):
            v[r] = row[r]
        for c in range(i + 1, n):
            w[c] = 0.0
    return t


@njit(nogil=True, cache=True)
def tridiagonalise(A):
    """``A = Q T Q^T`` in place for a symmetric ``A`` (n, n): returns ``(tau, d, e)``.

    Unblocked Householder tridiagonalisation (LAPACK's ``dsytd2``): step ``i`` reflects
    ``A[i, i+1:]`` onto its first entry with ``H_i = I - tau_i v v^T`` and updates the trailing block
    by ``A <- A - v w^T - w v^T``, ``w = tau (A v) - tau^2 (v^T A v) v / 2``, both triangles alike.
    ``Q = H_0 ... H_{n-2}``; row ``i`` of ``A`` then holds ``v[1:]`` in columns ``i+2..n-1``; ``d`` and
    ``e`` are the diagonal and off-diagonal of ``T`` (``e[n-1] = 0``).
    """
    n = A.shape[0]
    d = np.empty(max(n, 1))
    e = np.zeros(max(n, 1))
    tau = np.zeros(max(n - 1, 1))
    if n <= 1:
        if n == 1:
            d[0] = A[0, 0]
        return tau, d[:n], e[:n]
    bufs = np.empty((4, n))
    va, wa, vb, wb = bufs[0], bufs[1], bufs[2], bufs[3]
    # column indices are converted to unsigned so that numba leaves out its negative-index
    # handling and LLVM vectorises the loops across columns
    if _next_reflector(A, 0, va, wa, d, e, tau) != 0.0:
        for r in range(1, n):
            vr = va[r]
            for c in range(1, n):
                cu = uint64(c)
                wa[cu] += vr * A[r, cu]
    for i in range(n - 1):
        v, w = (va, wa) if i % 2 == 0 else (vb, wb)
        v2, w2 = (vb, wb) if i % 2 == 0 else (va, wa)
        t = tau[i]
        if t != 0.0:
            dot = 0.0
            for c in range(i + 1, n):
                w[c] *= t
                dot += w[c] * v[c]
            a2 = -0.5 * t * dot
            for c in range(i + 1, n):
                w[c] += a2 * v[c]
            r = i + 1
            vr = v[r]
            wr = w[r]
            for c in range(i + 1, n):
                cu = uint64(c)
                A[r, cu] -= vr * w[cu] + wr * v[cu]
        if i + 1 < n - 1:
            t2 = _next_reflector(A, i + 1, v2, w2, d, e, tau)
        else:
            t2 = 0.0
            d[n - 1] = A[n - 1, n - 1]
        for r in range(i + 2, n):
            if t != 0.0 and t2 != 0.0:
                vr = v[r]
                wr = w[r]
                v2r = v2[r]
                A[r, i + 1] -= vr * w[i + 1] + wr * v[i + 1]
                for c in range(i + 2, n):
                    cu = uint64(c)
                    a = A[r, cu] - (vr * w[cu] + wr * v[cu])
                    A[r, cu] = a
                    w2[cu] += v2r * a
            elif t != 0.0:
                vr = v[r]
                wr = w[r]
                for c in range(i + 1, n):
                    cu = uint64(c)
                    A[r, cu] -= vr * w[cu] + wr * v[cu]
            elif t2 != 0.0:
                v2r = v2[r]
                for c in range(i + 2, n):
                    cu = uint64(c)
                    w2[cu] += v2r * A[r, cu]
    return tau, d, e


@njit(nogil=True, cache=True)
def _apply_reflectors(A, tau, Y, transpose):
    """``Y <- Q^T Y`` (``transpose``) or ``Y <- Q Y`` with the reflectors of
    :func:`tridiagonalise` (each ``H_i`` is symmetric: ``Q^T`` applies ``H_0`` first)."""
    n, k = Y.shape
    s = np.empty(k)
    for j in range(n - 1):
        i = j if transpose else n - 2 - j
        t = tau[i]
        if t == 0.0:
            continue
        v = A[i]
        y0 = Y[i + 1]
        for c in range(k):
            s[c] = y0[c]
        for r in range(i + 2, n):
            vr = v[r]
            yr = Y[r]
            for c in range(k):
                s[c] += vr * yr[c]
        for c in range(k):
            s[c] *= t
            y0[c] -= s[c]
        for r in range(i + 2, n):
            vr = v[r]
            yr = Y[r]
            for c in range(k):
                yr[c] -= s[c] * vr


@njit(nogil=True, cache=True)
def apply_q(A, tau, Y):
    """``Y <- Q Y`` in place, ``Q`` from :func:`tridiagonalise` (``Y`` (n, k))."""
    _apply_reflectors(A, tau, Y, False)


@njit(nogil=True, cache=True)
def apply_qt(A, tau, Y):
    """``Y <- Q^T Y`` in place, ``Q`` from :func:`tridiagonalise` (``Y`` (n, k))."""
    _apply_reflectors(A, tau, Y, True)


@njit(nogil=True, cache=True)
def ql_rotations(d, e, idx, cs, sn, z):
    """Eigenvalues of the symmetric tridiagonal ``(d, e)`` by implicit QL with Wilkinson shifts
    (in place into ``d``, unsorted; ``e`` destroyed), recording the plane rotations.

    ``Z = G_1 ... G_M``, ``G_t`` rotating coordinates ``(i_t, i_t + 1)`` by ``(c_t, s_t)``. Returns
    ``(idx, cs, sn, M, info)``: the rotation arrays (grown when too short), their count and
    ``info = 1`` if an eigenvalue needed more than :data:`QL_ITERS` iterations. A non-empty row
    vector ``z`` is multiplied by every rotation as it is made (``z <- z Z``).
    """
    n = d.size
    track = z.size == n and n > 0
    cap = idx.size
    M = 0
    if n > 0:
        e[n - 1] = 0.0
    for l in range(n):  # noqa: E741 (the index of the text books)
        it = 0
        while True:
            m = l
            while m < n - 1:
                dd = abs(d[m]) + abs(d[m + 1])
                if abs(e[m]) + dd == dd:
                    break
                m += 1
            if m == l:
                break
            it += 1
            if it > QL_ITERS:
                return idx, cs, sn, M, 1
            if M + (m - l) > cap:
                cap = 2 * cap + (m - l)
                idx2 = np.empty(cap, np.int32)
                cs2 = np.empty(cap)
                sn2 = np.empty(cap)
                idx2[:M] = idx[:M]
                cs2[:M] = cs[:M]
                sn2[:M] = sn[:M]
                idx, cs, sn = idx2, cs2, sn2
            g = (d[l + 1] - d[l]) / (2.0 * e[l])
            r = hypot(g, 1.0)
            g = d[m] - d[l] + e[l] / (g + (r if g >= 0.0 else -r))
            s = 1.0
            c = 1.0
            p = 0.0
            i = m - 1
            early = False
            while i >= l:
                f = s * e[i]
                b = c * e[i]
                r = math.sqrt(f * f + g * g)
                e[i + 1] = r
                if r == 0.0:
                    d[i + 1] -= p
                    e[m] = 0.0
                    early = True
                    break
                ri = 1.0 / r
                s = f * ri
                c = g * ri
                g = d[i + 1] - p
                r = (d[i] - g) * s + 2.0 * c * b
                p = s * r
                d[i + 1] = g + p
                g = c * r - b
                idx[M] = i
                cs[M] = c
                sn[M] = s
                M += 1
                if track:
                    zf = z[i + 1]
                    zy = z[i]
                    z[i + 1] = s * zy + c * zf
                    z[i] = c * zy - s * zf
                i -= 1
            if early:
                continue
            d[l] -= p
            e[l] = g
            e[m] = 0.0
    return idx, cs, sn, M, 0


@njit(nogil=True, cache=True)
def rotate_t(idx, cs, sn, M, Y):
    """``Y <- Z^T Y = G_M^T ... G_1^T Y`` (rows of ``Y`` are the coordinates)."""
    k = Y.shape[1]
    for t in range(M):
        i = idx[t]
        c = cs[t]
        s = sn[t]
        y0 = Y[i]
        y1 = Y[i + 1]
        for col in range(k):
            f = y1[col]
            y = y0[col]
            y1[col] = s * y + c * f
            y0[col] = c * y - s * f


@njit(nogil=True, cache=True)
def rotate(idx, cs, sn, M, Y):
    """``Y <- Z Y = G_1 ... G_M Y``."""
    k = Y.shape[1]
    for t in range(M - 1, -1, -1):
        i = idx[t]
        c = cs[t]
        s = sn[t]
        y0 = Y[i]
        y1 = Y[i + 1]
        for col in range(k):
            f = y1[col]
            y = y0[col]
            y0[col] = c * y + s * f
            y1[col] = c * f - s * y


# ----------------------------------------------------------------------------- eigenvalues
@njit(nogil=True, cache=True)
def fix_signs(U):
    """In place: every column's largest-magnitude entry (the first of equal ones) made positive
    (the convention of :func:`spectrageo.spectral.gft.fix_signs`)."""
    n, k = U.shape
    best = np.zeros(k)
    at = np.zeros(k, np.int64)
    for r in range(n):
        for c in range(k):
            a = abs(U[r, c])
            if a > best[c]:
                best[c] = a
                at[c] = r
    for c in range(k):
        if U[at[c], c] < 0.0:
            for r in range(n):
                U[r, c] = -U[r, c]


@njit(nogil=True, cache=True)
def eigh_jacobi(A):
    """Eigenpairs of a symmetric ``A`` (n, n) by the cyclic Jacobi method (row-by-row sweeps,
    rotation angles of Rutishauser): ``(w, U, info)``, unsorted, ``A U = U diag(w)``;
    ``info = 1`` if :data:`JACOBI_SWEEPS` sweeps did not bring the off-diagonal part to rounding
    level. Slow (``O(n^3)`` per sweep) but converges on any symmetric matrix; the fallback of
    :func:`eigh`."""
    n = A.shape[0]
    B = A.copy()
    U = np.zeros((n, n))
    for i in range(n):
        U[i, i] = 1.0
    for _sweep in range(JACOBI_SWEEPS):
        off = 0.0
        diag = 0.0
        for p in range(n):
            diag += B[p, p] * B[p, p]
            for q in range(p + 1, n):
                off += B[p, q] * B[p, q]
        if off <= 1e-32 * diag or off == 0.0:
            return np.diag(B).copy(), U, 0
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = B[p, q]
                if apq == 0.0:
                    continue
                theta = (B[q, q] - B[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + hypot(theta, 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = t * c
                for r in range(n):  # columns p, q
                    bp = B[r, p]
                    bq = B[r, q]
                    B[r, p] = c * bp - s * bq
                    B[r, q] = s * bp + c * bq
                for r in range(n):  # rows p, q
                    bp = B[p, r]
                    bq = B[q, r]
                    B[p, r] = c * bp - s * bq
                    B[q, r] = s * bp + c * bq
                B[p, q] = 0.0
                B[q, p] = 0.0
                for r in range(n):
                    up = U[r, p]
                    uq = U[r, q]
                    U[r, p] = c * up - s * uq
                    U[r, q] = s * up + c * uq
    return np.diag(B).copy(), U, 1


@njit(nogil=True, cache=True)
def eigh_lowest(A, k):
    """The ``k`` lowest eigenpairs of a symmetric ``A`` (n, n): ``(w (k,), U (n, k), info)``.

    :func:`tridiagonalise`, :func:`ql_rotations`, eigenvalues in ascending order (stable sort),
    the eigenvectors ``Q Z e_j`` of the first ``k`` formed by applying the rotations and the
    reflectors to unit vectors, signs by :func:`fix_signs`. Where the QL iteration does not
    converge, cyclic Jacobi (:func:`eigh_jacobi`) on ``A``. ``info != 0`` only when both fail.
    ``A`` is not modified.
    """
    n = A.shape[0]
    B = A.copy()
    tau, d, e = tridiagonalise(B)
    cap = n * n + 16
    idx, cs, sn, M, info = ql_rotations(
        d, e, np.empty(cap, np.int32), np.empty(cap), np.empty(cap), np.empty(0)
    )
    if info != 0:
        w, U, info = eigh_jacobi(A)
        order = np.argsort(w, kind="mergesort")[:k]
        Uk = np.empty((n, k))
        for j in range(k):
            for r in range(n):
                Uk[r, j] = U[r, order[j]]
        fix_signs(Uk)
        return w[order].copy(), Uk, info
    order = np.argsort(d, kind="mergesort")[:k]
    W = np.zeros((n, k))
    for j in range(k):
        W[order[j], j] = 1.0
    rotate(idx, cs, sn, M, W)
    apply_q(B, tau, W)
    fix_signs(W)
    return d[order].copy(), W, 0


@njit(nogil=True, cache=True)
def eigh(A):
    """All eigenpairs of a symmetric ``A``: :func:`eigh_lowest` with ``k = n``."""
    return eigh_lowest(A, A.shape[0])


# ----------------------------------------------------------------------------- QR and SVD
@njit(nogil=True, cache=True)
def _householder_qr(R):
    """Householder QR of ``R`` (m, n), m >= n, in place: returns ``tau`` (n,); the upper
    triangle holds ``R``, column ``j`` below the diagonal ``v_j[1:]`` (LAPACK ``dgeqr2``)."""
    m, n = R.shape
    tau = np.zeros(n)
    s = np.empty(n)
    col = np.empty(m)
    for j in range(n):
        for r in range(j, m):
            col[r] = R[r, j]
        beta, t = _reflector(col, j, m)
        tau[j] = t
        if t == 0.0:
            continue
        R[j, j] = beta
        for r in range(j + 1, m):
            R[r, j] = col[r]
        # columns c > j: s = v^T R[j:, c] (rows ascending), R[j:, c] -= t s v
        for c in range(j + 1, n):
            s[c] = R[j, c]
        for r in range(j + 1, m):
            vr = col[r]
            for c in range(j + 1, n):
                cu = uint64(c)
                s[cu] += vr * R[r, cu]
        for c in range(j + 1, n):
            s[c] *= t
            R[j, c] -= s[c]
        for r in range(j + 1, m):
            vr = col[r]
            for c in range(j + 1, n):
                cu = uint64(c)
                R[r, cu] -= s[cu] * vr
    return tau


@njit(nogil=True, cache=True)
def _form_q(H, tau):
    """The thin ``Q`` (m, n) of :func:`_householder_qr`: ``H_0 ... H_{n-1}`` applied to the first
    ``n`` columns of the identity (LAPACK ``dorg2r``)."""
    m, n = H.shape
    Q = np.zeros((m, n))
    for j in range(n):
        Q[j, j] = 1.0
    s = np.empty(n)
    for j in range(n - 1, -1, -1):
        t = tau[j]
        if t == 0.0:
            continue
        for c in range(j, n):
            s[c] = Q[j, c]
        for r in range(j + 1, m):
            vr = H[r, j]
            for c in range(j, n):
                cu = uint64(c)
                s[cu] += vr * Q[r, cu]
        for c in range(j, n):
            s[c] *= t
            Q[j, c] -= s[c]
        for r in range(j + 1, m):
            vr = H[r, j]
            for c in range(j, n):
                cu = uint64(c)
                Q[r, cu] -= s[cu] * vr
    return Q


@njit(nogil=True, cache=True)
def qr(Y):
    """Thin QR ``Y = Q R`` of ``Y`` (m, n), m >= n, by Householder reflections: ``(Q (m, n),
    R (n, n))`` (``R`` upper triangular, diagonal of either sign). ``Y`` is not modified."""
    m, n = Y.shape
    H = Y.copy()
    tau = _householder_qr(H)
    R = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            R[i, j] = H[i, j]
    return _form_q(H, tau), R


@njit(nogil=True, cache=True)
def r_factor(Y):
    """The ``R`` (n, n) of the thin QR of ``Y`` (m, n), m >= n (:func:`qr` without ``Q``)."""
    m, n = Y.shape
    H = Y.copy()
    _householder_qr(H)
    R = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            R[i, j] = H[i, j]
    return R


@njit(nogil=True, cache=True)
def _jacobi_columns(G, V):
    """One-sided Jacobi (Hestenes) on the rows of ``G`` (n, m) -- the columns of ``G^T`` --
    rotated pairwise until mutually orthogonal to rounding, the rotations accumulated into the
    rows of ``V`` (n, n). Returns the number of sweeps (``JACOBI_SWEEPS + 1`` if not converged)."""
    n, m = G.shape
    tol = 1e-15
    for sweep in range(JACOBI_SWEEPS):
        rotated = False
        for p in range(n - 1):
            gp = G[p]
            for q in range(p + 1, n):
                gq = G[q]
                a = 0.0
                b = 0.0
                g = 0.0
                for r in range(m):
                    a += gp[r] * gp[r]
                    b += gq[r] * gq[r]
                    g += gp[r] * gq[r]
                if g == 0.0 or abs(g) <= tol * math.sqrt(a) * math.sqrt(b):
                    continue
                rotated = True
                zeta = (b - a) / (2.0 * g)
                t = 1.0 / (abs(zeta) + hypot(zeta, 1.0))
                if zeta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = c * t
                for r in range(m):
                    x = gp[r]
                    y = gq[r]
                    gp[r] = c * x - s * y
                    gq[r] = s * x + c * y
                vp = V[p]
                vq = V[q]
                for r in range(n):
                    x = vp[r]
                    y = vq[r]
                    vp[r] = c * x - s * y
                    vq[r] = s * x + c * y
        if not rotated:
            return sweep + 1
    return JACOBI_SWEEPS + 1


@njit(nogil=True, cache=True)
def _svd_square(R):
    """``R = U diag(s) V^T`` for a square ``R`` (n, n) by one-sided Jacobi: ``(U, s, V, info)``,
    ``s`` descending (stable order), columns of ``U`` for zero singular values are zero."""
    n = R.shape[0]
    G = np.ascontiguousarray(R.T)  # rows of G = columns of R
    Vt = np.zeros((n, n))  # rows = columns of V
    for i in range(n):
        Vt[i, i] = 1.0
    sweeps = _jacobi_columns(G, Vt)
    info = 1 if sweeps > JACOBI_SWEEPS else 0
    s = np.empty(n)
    for j in range(n):
        a = 0.0
        for r in range(n):
            a += G[j, r] * G[j, r]
        s[j] = math.sqrt(a)
    neg = np.empty(n)
    for j in range(n):
        neg[j] = -s[j]
    order = np.argsort(neg, kind="mergesort")
    U = np.zeros((n, n))
    V = np.empty((n, n))
    so = np.empty(n)
    for jj in range(n):
        j = order[jj]
        so[jj] = s[j]
        inv = 1.0 / s[j] if s[j] > 0.0 else 0.0
        for r in range(n):
            U[r, jj] = G[j, r] * inv
            V[r, jj] = Vt[j, r]
    return U, so, V, info


@njit(nogil=True, cache=True)
def svd(Y):
    """Thin SVD ``Y = U diag(s) V^T`` of ``Y`` (m, n), m >= n: ``(U (m, n), s (n,), V (n, n),
    info)``, ``s`` descending.

    Householder QR ``Y = Q R`` (:func:`qr`), then one-sided Jacobi on ``R`` (high relative
    accuracy, whatever the conditioning); ``U = Q U_R``. Columns of ``U`` for zero singular
    values are zero. ``info = 1`` if the Jacobi sweeps did not converge.
    """
    Q, R = qr(Y)
    Ur, s, V, info = _svd_square(R)
    return matmul(Q, Ur), s, V, info


@njit(nogil=True, cache=True)
def svd_values(Y):
    """``(s, V, info)`` of the thin SVD of ``Y`` (m, n), m >= n, without ``U``."""
    _Ur, s, V, info = _svd_square(r_factor(Y))
    return s, V, info


# ----------------------------------------------------------------------------- products
@njit(nogil=True, cache=True)
def matmul(A, B):
    """``A B`` for ``A`` (p, q), ``B`` (q, r): every entry summed over ``q`` in ascending order."""
    p, q = A.shape
    r = B.shape[1]
    C = np.zeros((p, r))
    for i in range(p):
        Ci = C[i]
        Ai = A[i]
        for t in range(q):
            a = Ai[t]
            Bt = B[t]
            for j in range(r):
                Ci[j] += a * Bt[j]
    return C


@njit(nogil=True, cache=True)
def matmul_tn(A, B):
    """``A^T B`` for ``A`` (q, p), ``B`` (q, r): every entry summed over ``q`` in ascending order."""
    q, p = A.shape
    r = B.shape[1]
    C = np.zeros((p, r))
    for t in range(q):
        At = A[t]
        Bt = B[t]
        for i in range(p):
            a = At[i]
            Ci = C[i]
            for j in range(r):
                Ci[j] += a * Bt[j]
    return C


# ----------------------------------------------------------------------------- shifted solves
@njit(nogil=True, cache=True)
def reverse_cuthill_mckee(ptr, ind):
    """Reverse Cuthill-McKee ordering of a symmetric pattern (CSR ``ptr``, ``ind``): ``perm`` (n,).

    The algorithm of :func:`scipy.sparse.csgraph.reverse_cuthill_mckee` with stable sorts, every tie
    broken by the vertex index (SciPy's unstable argsort depends on the CPU features).
    """
    n = ptr.size - 1
    deg = np.empty(n, np.int64)
    for i in range(n):
        deg[i] = ptr[i + 1] - ptr[i]
    by_degree = np.argsort(deg, kind="mergesort")
    seen = np.zeros(n, np.bool_)
    order = np.empty(n, np.int64)
    nb = np.empty(n, np.int64)
    head = 0
    tail = 0
    for z in range(n):
        seed = by_degree[z]
        if seen[seed]:
            continue
        seen[seed] = True
        order[tail] = seed
        tail += 1
        while head < tail:
            u = order[head]
            head += 1
            cnt = 0
            for p in range(ptr[u], ptr[u + 1]):
                v = ind[p]
                if v != u and not seen[v]:
                    seen[v] = True
                    nb[cnt] = v
                    cnt += 1
            if cnt == 0:
                continue
            kids = np.sort(nb[:cnt])  # by index, then stably by degree
            kd = np.empty(cnt, np.int64)
            for a in range(cnt):
                kd[a] = deg[kids[a]]
            rank = np.argsort(kd, kind="mergesort")
            for a in range(cnt):
                order[tail] = kids[rank[a]]
                tail += 1
    return order[::-1].copy()


@njit(nogil=True, cache=True)
def envelope_cholesky(Ap, Ai, Ax):
    """Cholesky ``A = R R^T`` of a symmetric positive definite matrix in envelope form, as
    :func:`spectrageo.spectral.orthogonal._nb_envelope_cholesky` (same loops, compiled without
    ``fastmath``): returns the CSR ``(Rp, Ri, Rx)`` of ``R`` (diagonal last in each row) and a
    success flag."""
    n = Ap.size - 1
    first = np.empty(n, np.int64)
    for i in range(n):
        f = i
        for p in range(Ap[i], Ap[i + 1]):
            if Ai[p] < f:
                f = Ai[p]
        first[i] = f
    Rp = np.empty(n + 1, np.int64)
    Rp[0] = 0
    for i in range(n):
        Rp[i + 1] = Rp[i] + i - first[i] + 1
    Rx = np.zeros(Rp[n], np.float64)
    Ri = np.empty(Rp[n], np.int64)
    for i in range(n):
        base = Rp[i] - first[i]
        for j in range(first[i], i + 1):
            Ri[base + j] = j
        for p in range(Ap[i], Ap[i + 1]):
            j = Ai[p]
            if j <= i:
                Rx[base + j] += Ax[p]
    for i in range(n):
        fi = first[i]
        bi = Rp[i] - fi
        for j in range(fi, i):
            fj = first[j]
            bj = Rp[j] - fj
            lo = fi if fi > fj else fj
            acc = Rx[bi + j]
            for t in range(lo, j):
                acc -= Rx[bi + t] * Rx[bj + t]
            Rx[bi + j] = acc / Rx[bj + j]
        acc = Rx[bi + i]
        for t in range(fi, i):
            acc -= Rx[bi + t] * Rx[bi + t]
        if not acc > 0.0:
            return Rp, Ri, Rx, False
        Rx[bi + i] = math.sqrt(acc)
    return Rp, Ri, Rx, True


@njit(nogil=True, cache=True)
def transpose_rows(Rp, Ri, Rx):
    """CSC of the lower factor of :func:`envelope_cholesky` (diagonal first in every column)."""
    n = Rp.size - 1
    cnt = np.zeros(n + 1, np.int64)
    for p in range(Rp[n]):
        cnt[Ri[p] + 1] += 1
    for j in range(n):
        cnt[j + 1] += cnt[j]
    Lp = cnt.copy()
    Li = np.empty(Rp[n], np.int64)
    Lx = np.empty(Rp[n], np.float64)
    nxt = cnt[:-1].copy()
    for i in range(n):
        for p in range(Rp[i], Rp[i + 1]):
            j = Ri[p]
            q = nxt[j]
            nxt[j] += 1
            Li[q] = i
            Lx[q] = Rx[p]
    return Lp, Li, Lx


@njit(nogil=True, cache=True)
def _subtract_rows(acc, Y, idx, val, p, end):
    """``acc -= val[q] Y[idx[q]]`` for ``q = p .. end-1`` in that order."""
    k = acc.shape[0]
    for q in range(p, end):
        v = val[q]
        y = Y[idx[q]]
        for c in range(k):
            acc[c] -= v * y[c]


@njit(nogil=True, cache=True)
def solve_power(Lp, Li, Lx, Rp, Ri, Rx, Y, zeta):
    """``Y <- (R R^T)^-zeta Y`` in place (row-major ``Y`` (n, k)), every column rescaled to unit
    norm after each solve: ``zeta`` forward sweeps over the rows of ``R`` (CSR ``Rp, Ri, Rx``)
    and backward sweeps over its columns (CSC ``Lp, Li, Lx``), Eq. (5.42)."""
    n, k = Y.shape
    acc = np.empty(k)
    nrm = np.empty(k)
    for _ in range(zeta):
        for j in range(n):
            for c in range(k):
                acc[c] = Y[j, c]
            last = Rp[j + 1] - 1
            _subtract_rows(acc, Y, Ri, Rx, Rp[j], last)
            d = 1.0 / Rx[last]
            for c in range(k):
                Y[j, c] = acc[c] * d
        for j in range(n - 1, -1, -1):
            for c in range(k):
                acc[c] = Y[j, c]
            _subtract_rows(acc, Y, Li, Lx, Lp[j] + 1, Lp[j + 1])
            d = 1.0 / Lx[Lp[j]]
            for c in range(k):
                Y[j, c] = acc[c] * d
        for c in range(k):
            nrm[c] = 0.0
        for i in range(n):
            for c in range(k):
                nrm[c] += Y[i, c] * Y[i, c]
        for c in range(k):
            nrm[c] = 1.0 / math.sqrt(nrm[c]) if nrm[c] > 0 else 1.0
        for i in range(n):
            for c in range(k):
                Y[i, c] *= nrm[c]
    return Y
