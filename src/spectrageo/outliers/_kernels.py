"""Fused numba kernels of the kNN-patch RPCA (Eq. 5.98-5.99) and of the point filters.

The patch matrix ``M`` (``3n x (k+1)``) is never stored: its row ``3r + c`` is gathered from the
points as ``[P[centers[r], c], P[nbrs[r, 0], c], ..., P[nbrs[r, k-1], c]]``. The solver state is a
single array ``R = M - E + Y / mu`` of the shape of ``M``; the sparse part and the Lagrange
multiplier follow from it (``S = R - clip(R, lam/mu)``, ``Y / mu = clip(R, lam/mu)``), as in the
row-chunked engine of :func:`spectrageo.linalg.rpca`. One call of :func:`patch_ialm_pass` is one
IALM iteration (Eq. 4.22) over the rows of a range of points: it forms the SVT argument, applies
the low-rank operator ``W`` (``E = X W``), updates ``R``, and returns ``||M - E - S||_F^2`` and the
Gram matrix of the next SVT argument over that range. The kernels are serial and release the GIL;
the caller runs disjoint point ranges on threads and sums the partial results.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..geometry._numba_kernels import min_eigvec3, patch_covariance

#: Points per tile of the patch kernels (``3 * TILE`` rows of ``M`` in the tile buffers).
TILE = 128


@njit(cache=True, nogil=True)
def _gather_tile(Pn, centers, nbrs, s, nt, Mt):  # pragma: no cover - compiled
    """Rows ``3s .. 3(s + nt)`` of the patch matrix ``M`` into the tile buffer ``Mt``."""
    K = nbrs.shape[1] + 1
    for p in range(nt):
        r = s + p
        ci = centers[r]
        for c in range(3):
            Mt[3 * p + c, 0] = Pn[ci, c]
        for j in range(1, K):
            q = nbrs[r, j - 1]
            for c in range(3):
                Mt[3 * p + c, j] = Pn[q, c]


@njit(cache=True, nogil=True)
def patch_gram(Pn, centers, nbrs, G, lo, hi):  # pragma: no cover - compiled
    """``G = M^T M`` over the patch rows of the points ``lo .. hi`` (``G`` (K, K) overwritten)."""
    K = nbrs.shape[1] + 1
    Mt = np.empty((3 * TILE, K))
    Gt = np.empty((K, K))
    G[:, :] = 0.0
    for s in range(lo, hi, TILE):
        nt = min(hi, s + TILE) - s
        _gather_tile(Pn, centers, nbrs, s, nt, Mt)
        if nt == TILE:
            np.dot(Mt.T, Mt, Gt)
        else:
            Gt[:, :] = np.dot(Mt[: 3 * nt].T, Mt[: 3 * nt])
        G += Gt


@njit(cache=True, nogil=True, fastmath=True)
def patch_ialm_pass(
    Pn, centers, nbrs, R, W, tp, fp, t, f, E0, G, lo, hi
):  # pragma: no cover - compiled
    """One IALM iteration (Eq. 4.22) over the patch rows of the points ``lo .. hi``.

    ``W`` (K, K) is the singular value thresholding operator of the current SVT argument ``X``
    (``D_{1/mu}(X) = X W``). ``tp = lam / mu_prev`` and ``fp = mu_prev / mu`` decode the stored
    ``R`` into the current ``S`` and ``Y / mu``; ``t = lam / mu`` and ``f = mu / mu_next`` encode
    the next SVT argument ``M - S + Y_new / mu_next``, whose Gram matrix is written to ``G``.
    ``E0`` receives the first column of ``E`` (the smoothed point, Eq. 5.99). Returns the partial
    ``||M - E - S||_F^2``. Rows are processed in tiles of ``TILE`` points: the elementwise steps
    run over contiguous tile buffers and the two small products (``X W`` and ``X^T X``) go to BLAS.
    """
    K = nbrs.shape[1] + 1
    Mt = np.empty((3 * TILE, K))
    Xt = np.empty((3 * TILE, K))
    Yt = np.empty((3 * TILE, K))
    Et = np.empty((3 * TILE, K))
    Gt = np.empty((K, K))
    Mf = Mt.ravel()
    Xf = Xt.ravel()
    Yf = Yt.ravel()
    Ef = Et.ravel()
    Rf = R.ravel()
    G[:, :] = 0.0
    res = 0.0
    f1 = 1.0 + f
    for s in range(lo, hi, TILE):
        nt = min(hi, s + TILE) - s
        nr = 3 * nt
        ne = nr * K
        _gather_tile(Pn, centers, nbrs, s, nt, Mt)
        base = 3 * s * K
        for i in range(ne):
            rv = Rf[base + i]
            cl = min(max(rv, -tp), tp)
            y = cl * fp
            Yf[i] = y
            Xf[i] = Mf[i] - rv + cl + y
        if nt == TILE:
            np.dot(Xt, W, Et)
        else:
            Et[:nr] = np.dot(Xt[:nr], W)
        for i in range(ne):
            rn = Mf[i] - Ef[i] + Yf[i]
            Rf[base + i] = rn
            cl = min(max(rn, -t), t)
            z = cl - Yf[i]  # M - E - S = R - Y/mu - S = clip(R) - Y/mu
            res += z * z
            Xf[i] = Mf[i] - rn + f1 * cl
        for p in range(nt):
            for c in range(3):
                E0[s + p, c] = Et[3 * p + c, 0]
        if nt == TILE:
            np.dot(Xt.T, Xt, Gt)
        else:
            Gt[:, :] = np.dot(Xt[:nr].T, Xt[:nr])
        G += Gt
    return res


@njit(cache=True, nogil=True)
def first_column_scores(R, t, out, vec):  # pragma: no cover - compiled
    """``out[r] = || S[3r:3r+3, 0] ||_2`` with ``S = R - clip(R, t)`` (Eq. 5.99).

    ``vec`` (m, 3) receives the residual vectors ``S[3r:3r+3, 0]`` unless it has no rows.
    """
    m = out.shape[0]
    keep = vec.shape[0] == m
    for r in range(m):
        acc = 0.0
        for c in range(3):
            v = R[3 * r + c, 0]
            s = v - min(max(v, -t), t)
            if keep:
                vec[r, c] = s
            acc += s * s
        out[r] = np.sqrt(acc)


@njit(cache=True, parallel=True)
def tangent_weighted_norms(P, nbrs, S1, S2, w2, out1, out2):  # pragma: no cover - compiled
    """``out = sqrt(|<s, n>|^2 + w2 |s - <s, n> n|^2)`` for the residuals ``S1`` and ``S2``.

    ``n_i`` is the normal of the neighbours ``P[nbrs[i]]`` of point ``i`` (the eigenvector of the
    smallest eigenvalue of their covariance about their mean; the point itself is left out, so an
    outlying point does not tilt its own normal).
    """
    for i in prange(nbrs.shape[0]):
        cxx, cyy, czz, cxy, cxz, cyz = patch_covariance(P, nbrs[i])
        _, nx, ny, nz = min_eigvec3(cxx, cyy, czz, cxy, cxz, cyz)
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
