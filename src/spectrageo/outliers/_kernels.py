"""Fused numba kernels of the kNN-patch RPCA (Eq. 5.98-5.99) and of the point filters.

``M`` (``3n x (k+1)``) is never stored: row ``3r + c`` is gathered from the points. The solver
state is ``R = M - E + Y / mu`` (``S = R - clip(R, lam/mu)``, ``Y / mu = clip(R, lam/mu)``). One
call of :func:`patch_ialm_pass` is one IALM iteration (Eq. 4.22) over a range of points: it forms
the SVT argument, applies ``E = X W``, updates ``R`` and returns ``||M - E - S||_F^2`` and the
next Gram matrix. Rows are processed in tiles of ``TILE`` points stored column by column, so
``X W`` and ``X^T X`` are vectorised loops over contiguous columns. The kernels are serial and
release the GIL; the caller runs disjoint ranges on threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..geometry._numba_kernels import min_eigvec3, patch_covariance
from ._grid import _spread3

#: Points per tile of the patch kernels (``3 * TILE`` rows of ``M`` in the tile buffers).
TILE = 128


@njit(cache=True, nogil=True)
def morton_quantised(P, lo, scale, out):  # pragma: no cover - compiled
    """``out[i]``: the Morton code of ``min(floor((P[i] - lo) * scale), 2^21 - 1)`` (x in bit 0),
    :func:`._grid.morton_encode` of the quantised coordinates without their (n, 3) temporary."""
    top = np.uint64(2**21 - 1)
    for i in range(P.shape[0]):
        code = np.uint64(0)
        for j in range(3):
            q = np.uint64((P[i, j] - lo[j]) * scale)
            code |= _spread3(min(q, top)) << np.uint64(j)
        out[i] = code


@njit(cache=True, nogil=True)
def gather_rows(P, order, out):  # pragma: no cover - compiled
    """``out[i] = P[order[i]]`` for an (n, 3) ``P`` (``P[order]`` is a slow fancy index there)."""
    for i in range(order.shape[0]):
        o = order[i]
        for c in range(3):
            out[i, c] = P[o, c]


@njit(cache=True, nogil=True)
def centre_and_scale(X, lo, hi, inv_h, centre, out):  # pragma: no cover - compiled
    """``centre = X[lo:hi].mean(axis=0)`` (rows added in order to 0, as numpy sums over axis 0
    of an (m, 3) array) and ``out = (X - centre) * inv_h`` rounded to ``out``'s dtype."""
    for c in range(3):
        centre[c] = 0.0  # numpy's sum starts from its identity (-0.0 sums give +0.0)
    for i in range(lo, hi):
        for c in range(3):
            centre[c] += X[i, c]
    for c in range(3):
        centre[c] /= hi - lo
    for i in range(X.shape[0]):
        for c in range(3):
            out[i, c] = (X[i, c] - centre[c]) * inv_h


@njit(cache=True, nogil=True)
def _gather_tile(Pn, centers, nbrs, s, nt, Mt):  # pragma: no cover - compiled
    """Rows ``3s .. 3(s + nt)`` of ``M`` into the column-major tile buffer ``Mt`` (K, >= 3 nt)."""
    K = nbrs.shape[1] + 1
    for p in range(nt):
        r = s + p
        ci = centers[r]
        for c in range(3):
            Mt[0, 3 * p + c] = Pn[ci, c]
        for j in range(1, K):
            q = nbrs[r, j - 1]
            for c in range(3):
                Mt[j, 3 * p + c] = Pn[q, c]


@njit(cache=True, nogil=True, fastmath=True)
def _gram_add(Xt, nr, G):  # pragma: no cover - compiled
    """``G += X^T X`` for the column-major tile ``Xt`` (K, >= nr), in float64."""
    K = Xt.shape[0]
    for a in range(K):
        for b in range(a, K):
            acc = 0.0
            for i in range(nr):
                acc += np.float64(Xt[a, i]) * np.float64(Xt[b, i])
            G[a, b] += acc
            if b != a:
                G[b, a] += acc


@njit(cache=True, nogil=True)
def patch_gram(Pn, centers, nbrs, G, lo, hi):  # pragma: no cover - compiled
    """``G = M^T M`` over the patch rows of the points ``lo .. hi`` (``G`` (K, K) float64,
    overwritten; accumulated in float64 whatever the dtype of ``Pn``)."""
    K = nbrs.shape[1] + 1
    Mt = np.empty((K, 3 * TILE))
    G[:, :] = 0.0
    for s in range(lo, hi, TILE):
        nt = min(hi, s + TILE) - s
        _gather_tile(Pn, centers, nbrs, s, nt, Mt)
        _gram_add(Mt, 3 * nt, G)


@njit(cache=True, nogil=True, fastmath=True)
def patch_ialm_pass(
    Pn, centers, nbrs, R, W, A, B, tp, fp, t, f1, E0, S0, V0, G, lo, hi
):  # pragma: no cover - compiled
    """One IALM iteration (Eq. 4.22) over the patch rows of the points ``lo .. hi``.

    Forms the SVT argument, applies ``E = X W`` (factored ``X A B`` while ``W`` has low rank),
    updates ``R`` with the scalars of the step and writes the next Gram matrix to ``G`` (float64).
    ``E0`` (m, 3), ``S0`` (m,) and ``V0`` (m, 3, or no rows) receive the first column of ``E``, the
    first-column score and residual vector of every point. Returns the partial ``||M - E - S||_F^2``.
    """
    K = nbrs.shape[1] + 1
    r = A.shape[1]
    low = 2 * r < K
    dt = R.dtype
    Mt = np.empty((K, 3 * TILE), dt)
    Xt = np.empty((K, 3 * TILE), dt)
    Yt = np.empty((K, 3 * TILE), dt)
    Et = np.empty((K, 3 * TILE), dt)
    Tt = np.empty((max(r, 1), 3 * TILE), dt)
    want_v = V0.shape[0] > 0
    G[:, :] = 0.0
    res = 0.0
    for s in range(lo, hi, TILE):
        nt = min(hi, s + TILE) - s
        nr = 3 * nt
        _gather_tile(Pn, centers, nbrs, s, nt, Mt)
        base = 3 * s * K
        for j in range(K):
            o = base + j * nr
            for i in range(nr):
                rv = R[o + i]
                cl = min(max(rv, -tp), tp)
                y = cl * fp
                Yt[j, i] = y
                Xt[j, i] = Mt[j, i] - rv + cl + y
        # E = X W, column by column
        if low:
            for q in range(r):
                for i in range(nr):
                    Tt[q, i] = 0.0
                for a in range(K):
                    w = A[a, q]
                    for i in range(nr):
                        Tt[q, i] += Xt[a, i] * w
            for j in range(K):
                for i in range(nr):
                    Et[j, i] = 0.0
                for q in range(r):
                    w = B[q, j]
                    for i in range(nr):
                        Et[j, i] += Tt[q, i] * w
        else:
            for j in range(K):
                for i in range(nr):
                    Et[j, i] = 0.0
                for a in range(K):
                    w = W[a, j]
                    for i in range(nr):
                        Et[j, i] += Xt[a, i] * w
        for j in range(K):
            o = base + j * nr
            for i in range(nr):
                rn = Mt[j, i] - Et[j, i] + Yt[j, i]
                R[o + i] = rn
                cl = min(max(rn, -t), t)
                z = cl - Yt[j, i]  # M - E - S = R - Y/mu - S = clip(R) - Y/mu
                res += np.float64(z) * np.float64(z)
                Xt[j, i] = Mt[j, i] - rn + f1 * cl  # the next SVT argument
        _gram_add(Xt, nr, G)
        for p in range(nt):
            acc = 0.0
            for c in range(3):
                E0[s + p, c] = Et[0, 3 * p + c]
                v = R[base + 3 * p + c]
                sv = v - min(max(v, -t), t)
                if want_v:
                    V0[s + p, c] = sv
                acc += np.float64(sv) * np.float64(sv)
            S0[s + p] = np.sqrt(acc)
    return res


@njit(cache=True)
def rank_bins(s, floor, inv_width, bins):  # pragma: no cover - compiled
    """Quantise scores to the bins of the ranking stop rule; return how many bins changed.

    ``bin = floor(log10(s / floor) * inv_width)`` for ``s >= floor``, ``-1`` below (all scores
    below the floor tie). ``bins`` holds the previous bins and is updated in place.
    """
    changed = 0
    for i in range(s.shape[0]):
        v = s[i]
        b = np.int32(-1)
        if v >= floor:
            b = np.int32(np.floor(np.log10(v / floor) * inv_width))
        if b != bins[i]:
            changed += 1
            bins[i] = b
    return changed


@njit(cache=True, nogil=True)
def normal_of(cxx, cyy, czz, cxy, cxz, cyz):  # pragma: no cover - compiled
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (a covariance).

    Closed form: the eigenvalues by the trigonometric solution of the characteristic cubic, the
    eigenvector as the largest cross product of two rows of ``C - lambda_min I``. When the two
    smallest eigenvalues are within ``1e-4`` of the largest (the vector is then ill-determined
    and the cross products lose their digits) it falls back to the Jacobi iteration of
    :func:`spectrageo.geometry._numba_kernels.min_eigvec3`.
    """
    q = (cxx + cyy + czz) / 3.0
    bxx = cxx - q
    byy = cyy - q
    bzz = czz - q
    p2 = (bxx * bxx + byy * byy + bzz * bzz + 2.0 * (cxy * cxy + cxz * cxz + cyz * cyz)) / 6.0
    if p2 > 0.0:
        p = np.sqrt(p2)
        det = (
            bxx * (byy * bzz - cyz * cyz)
            - cxy * (cxy * bzz - cyz * cxz)
            + cxz * (cxy * cyz - byy * cxz)
        )
        r = det / (2.0 * p2 * p)
        r = min(max(r, -1.0), 1.0)
        phi = np.arccos(r) / 3.0
        l_max = q + 2.0 * p * np.cos(phi)
        l_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
        l_mid = 3.0 * q - l_max - l_min
        if l_mid - l_min > 1e-4 * max(abs(l_max), 1e-300):
            ax, ay, az = cxx - l_min, cxy, cxz
            bx, by, bz = cxy, cyy - l_min, cyz
            ex, ey, ez = cxz, cyz, czz - l_min
            v1x, v1y, v1z = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
            v2x, v2y, v2z = ay * ez - az * ey, az * ex - ax * ez, ax * ey - ay * ex
            v3x, v3y, v3z = by * ez - bz * ey, bz * ex - bx * ez, bx * ey - by * ex
            n1 = v1x * v1x + v1y * v1y + v1z * v1z
            n2 = v2x * v2x + v2y * v2y + v2z * v2z
            n3 = v3x * v3x + v3y * v3y + v3z * v3z
            if n2 > n1 and n2 >= n3:
                v1x, v1y, v1z, n1 = v2x, v2y, v2z, n2
            elif n3 > n1:
                v1x, v1y, v1z, n1 = v3x, v3y, v3z, n3
            if n1 > 0.0:
                inv = 1.0 / np.sqrt(n1)
                return v1x * inv, v1y * inv, v1z * inv
    _, nx, ny, nz = min_eigvec3(cxx, cyy, czz, cxy, cxz, cyz)
    return nx, ny, nz


@njit(cache=True, parallel=True)
def tangent_weighted_norms(P, nbrs, S1, S2, w2, out1, out2):  # pragma: no cover - compiled
    """``out = sqrt(|<s, n>|^2 + w2 |s - <s, n> n|^2)`` for the residuals ``S1`` and ``S2``.

    ``n_i`` is the normal of the neighbours ``P[nbrs[i]]`` of point ``i`` (the eigenvector of the
    smallest eigenvalue of their covariance about their mean, :func:`normal_of`; the point
    itself is left out, so an outlying point does not tilt its own normal).
    """
    for i in prange(nbrs.shape[0]):
        cxx, cyy, czz, cxy, cxz, cyz = patch_covariance(P, nbrs[i])
        nx, ny, nz = normal_of(cxx, cyy, czz, cxy, cxz, cyz)
        out1[i] = _weighted_norm(S1[i, 0], S1[i, 1], S1[i, 2], nx, ny, nz, w2)
        out2[i] = _weighted_norm(S2[i, 0], S2[i, 1], S2[i, 2], nx, ny, nz, w2)


@njit(cache=True, nogil=True)
def _weighted_norm(sx, sy, sz, nx, ny, nz, w2):  # pragma: no cover - compiled
    """``sqrt(<s, n>^2 + w2 |s - <s, n> n|^2)`` for a unit ``n``."""
    pn = sx * nx + sy * ny + sz * nz
    ss = sx * sx + sy * sy + sz * sz
    return np.sqrt(max(w2 * ss + (1.0 - w2) * pn * pn, 0.0))


@njit(cache=True, parallel=True)
def bilateral_offsets(P, N, nbrs, sigma1, sigma2, out):  # pragma: no cover - compiled
    """Bilateral displacement ``d_i`` along ``n_i`` over the kNN cell (Eq. 5.100).

    ``d_i = sum_j W1 W2 <n_i, v_j - v_i> / sum_j W1 W2`` with ``W1 = exp(-|v_i - v_j|^2 /
    (2 sigma1^2))`` and ``W2 = exp(-<n_i, v_i - v_j>^2 / (2 sigma2_i^2))``.
    """
    n, k = nbrs.shape
    for i in prange(n):
        num = 0.0
        den = 0.0
        s1 = 2.0 * sigma1 * sigma1
        s2 = 2.0 * sigma2[i] * sigma2[i]
        for q in range(k):
            j = nbrs[i, q]
            dx = P[j, 0] - P[i, 0]
            dy = P[j, 1] - P[i, 1]
            dz = P[j, 2] - P[i, 2]
            h = N[i, 0] * dx + N[i, 1] * dy + N[i, 2] * dz
            w = np.exp(-(dx * dx + dy * dy + dz * dz) / s1)
            if s2 > 0:
                w *= np.exp(-(h * h) / s2)
            num += w * h
            den += w
        out[i] = num / den if den > 0 else 0.0


@njit(cache=True, nogil=True)
def count_flagged(idx, flagged):  # pragma: no cover - compiled
    """Number of flagged neighbours ``sum_j flagged[idx[i, j]]`` of every point (int64), on the
    calling thread (docs/decisions.md#outliers-speed-serial-regions)."""
    n, k = idx.shape
    out = np.zeros(n, dtype=np.int64)
    for i in range(n):
        c = 0
        for j in range(k):
            if flagged[idx[i, j]]:
                c += 1
        out[i] = c
    return out


@njit(cache=True, parallel=True)
def subtract_patch_quantile(scores, s1, idx, q):  # pragma: no cover - compiled
    """``scores[i] = max(scores[i] - Q_q(s1[idx[i, :]]), 0)`` in place, ``Q_q`` the ``q``-quantile
    with linear interpolation between order statistics (:func:`numpy.quantile`'s default).

    The two order statistics are found by rank counting (``rank_j`` = the values below ``v_j``,
    ties by position), without the branches of a sort."""
    n, k = idx.shape
    n_chunks = min(n, 256)
    pos = q * (k - 1)
    lo = min(int(np.floor(pos)), k - 1)
    hi = min(lo + 1, k - 1)
    g = pos - lo
    for ch in prange(n_chunks):
        v = np.empty(k)
        for i in range(ch * n // n_chunks, (ch + 1) * n // n_chunks):
            for j in range(k):
                v[j] = s1[idx[i, j]]
            a = 0.0
            b = 0.0
            for j in range(k):
                x = v[j]
                r = 0
                for m in range(j):
                    r += v[m] <= x
                for m in range(j + 1, k):
                    r += v[m] < x
                if r == lo:
                    a = x
                if r == hi:
                    b = x
            base = a + g * (b - a)
            d = scores[i] - base
            scores[i] = d if d > 0.0 else 0.0


@njit(cache=True, nogil=True)
def surely_not_surface(X, rows, nb, beta, flat, out):  # pragma: no cover - compiled
    """``out[t]``: the point ``X[rows[t]]`` with neighbours ``X[nb[t]]`` is certainly no surface
    candidate of :func:`._support.sparse_surface` (``off > beta d`` or ``l_1 > flat * trace``),
    whatever the rounding of that function's arithmetic; False when unsure.

    With ``C`` the neighbours' covariance (``s = tr C``, ``m_2`` the sum of its principal 2x2
    minors): ``l_1 >= 4 det C / s^2``, ``l_2 >= (m_2 - 3 s det C / m_2) / s`` and, for the
    smallest eigenvector ``n`` and ``u = v - mean``, ``(n^T u)^2 >= |u|^2 - u^T C u / l_2``. Each
    test keeps a margin of many times the rounding error of ``C`` (cancellation against the
    coordinates' magnitude included); rows where that error is not small are left unsure.
    """
    eps = 2.220446049250313e-16
    k = nb.shape[1]
    for t in range(rows.shape[0]):
        out[t] = False
        i = rows[t]
        mx = 0.0
        my = 0.0
        mz = 0.0
        big = max(abs(X[i, 0]), abs(X[i, 1]), abs(X[i, 2]))
        for j in range(k):
            q = nb[t, j]
            mx += X[q, 0]
            my += X[q, 1]
            mz += X[q, 2]
            big = max(big, abs(X[q, 0]), abs(X[q, 1]), abs(X[q, 2]))
        mx /= k
        my /= k
        mz /= k
        cxx = cyy = czz = cxy = cxz = cyz = d = 0.0
        for j in range(k):
            q = nb[t, j]
            ax = X[q, 0] - mx
            ay = X[q, 1] - my
            az = X[q, 2] - mz
            cxx += ax * ax
            cyy += ay * ay
            czz += az * az
            cxy += ax * ay
            cxz += ax * az
            cyz += ay * az
            ex = X[q, 0] - X[i, 0]
            ey = X[q, 1] - X[i, 1]
            ez = X[q, 2] - X[i, 2]
            d += np.sqrt(ex * ex + ey * ey + ez * ez)
        d /= k
        cxx /= k
        cyy /= k
        czz /= k
        cxy /= k
        cxz /= k
        cyz /= k
        s = cxx + cyy + czz
        if not s > 0.0:
            continue
        r = eps * big / np.sqrt(s)  # relative rounding of the centred coordinates
        rel = 16.0 * (k + 2) * (r + (k + 2) * r * r) + 1e-12
        if rel > 1e-4:
            continue
        dc = 32.0 * rel * s  # bound on the error of C (entries and spectral norm)
        det = (
            cxx * (cyy * czz - cyz * cyz)
            - cxy * (cxy * czz - cyz * cxz)
            + cxz * (cxy * cyz - cyy * cxz)
        )
        if 4.0 * det / (s * s) > flat * s + 64.0 * dc:  # l_1 > flat * trace
            out[t] = True
            continue
        m2 = cxx * cyy - cxy * cxy + cxx * czz - cxz * cxz + cyy * czz - cyz * cyz
        if not m2 > 16.0 * dc * s:
            continue
        l2 = (m2 - 3.0 * (abs(det) + 8.0 * dc * s * s) * s / m2) / s - 16.0 * dc
        if not l2 > 0.0:
            continue
        ux = X[i, 0] - mx
        uy = X[i, 1] - my
        uz = X[i, 2] - mz
        uu = ux * ux + uy * uy + uz * uz
        ucu = (
            cxx * ux * ux
            + cyy * uy * uy
            + czz * uz * uz
            + 2.0 * (cxy * ux * uy + cxz * ux * uz + cyz * uy * uz)
        )
        lb = uu * (1.0 - 8.0 * eps) - (ucu + dc * uu) / l2 * (1.0 + 8.0 * eps)
        if lb > 0.0 and np.sqrt(lb) - (2 * k + 8) * eps * big > beta * d * (1.0 + 1e-9):
            out[t] = True  # off > beta * d
