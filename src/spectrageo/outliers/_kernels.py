"""Fused numba kernels of the kNN-patch RPCA (Eq. 5.98-5.99) and of the point filters.

The patch matrix ``M`` (``3n x (k+1)``) is never stored: its row ``3r + c`` is gathered from the
points as ``[P[centers[r], c], P[nbrs[r, 0], c], ..., P[nbrs[r, k-1], c]]``. The solver state is a
single array ``R = M - E + Y / mu`` of the shape of ``M``; the sparse part and the Lagrange
multiplier follow from it (``S = R - clip(R, lam/mu)``, ``Y / mu = clip(R, lam/mu)``), as in the
row-chunked engine of :func:`spectrageo.linalg.rpca`. One call of :func:`patch_ialm_pass` is one
IALM iteration (Eq. 4.22) over all rows: it forms the SVT argument, applies the low-rank operator
``W`` (``E = X W``), updates ``R``, accumulates ``||M - E - S||_F^2`` and the Gram matrix of the
next SVT argument, block by block (one partial sum per block, reduced afterwards).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def patch_gram(Pn, centers, nbrs, gram_parts, l1_parts):  # pragma: no cover - compiled
    """Gram matrix ``M^T M`` (partial per block) and ``||M||_1`` of the patch matrix."""
    m = centers.shape[0]
    K = nbrs.shape[1] + 1
    nb = gram_parts.shape[0]
    for b in prange(nb):
        lo = b * m // nb
        hi = (b + 1) * m // nb
        G = gram_parts[b]
        G[:, :] = 0.0
        row = np.empty(K)
        l1 = 0.0
        for r in range(lo, hi):
            for c in range(3):
                row[0] = Pn[centers[r], c]
                for j in range(1, K):
                    row[j] = Pn[nbrs[r, j - 1], c]
                for j in range(K):
                    l1 += abs(row[j])
                    rj = row[j]
                    for q in range(j, K):
                        G[j, q] += rj * row[q]
        l1_parts[b] = l1


@njit(cache=True, parallel=True, fastmath=True)
def patch_ialm_pass(
    Pn, centers, nbrs, R, A, B, tp, fp, t, f, E0, gram_parts, res_parts
):  # pragma: no cover - compiled
    """One IALM iteration over all rows of the implicit patch matrix.

    The low-rank step is ``E = (X A) B`` with ``A`` (K, r) and ``B`` (r, K) the factors of the
    singular value thresholding operator (``r`` = singular values above the threshold).
    ``tp = lam / mu_prev`` and ``fp = mu_prev / mu`` decode the stored ``R`` into the current
    ``S`` and ``Y / mu``; ``t = lam / mu`` and ``f = mu / mu_next`` encode the next SVT argument
    ``M - S + Y_new / mu_next`` whose Gram matrix is accumulated (upper triangle) in
    ``gram_parts``. ``E0`` receives the first column of ``E`` (the smoothed point, Eq. 5.99).
    """
    m = centers.shape[0]
    K = nbrs.shape[1] + 1
    rk = A.shape[1]
    nb = gram_parts.shape[0]
    for b in prange(nb):
        lo = b * m // nb
        hi = (b + 1) * m // nb
        G = gram_parts[b]
        G[:, :] = 0.0
        mrow = np.empty(K)
        x = np.empty(K)
        ymu = np.empty(K)
        xn = np.empty(K)
        e = np.empty(K)
        a = np.empty(rk)
        res = 0.0
        for r in range(lo, hi):
            for c in range(3):
                i = 3 * r + c
                mrow[0] = Pn[centers[r], c]
                for j in range(1, K):
                    mrow[j] = Pn[nbrs[r, j - 1], c]
                for j in range(K):
                    rv = R[i, j]
                    cl = min(max(rv, -tp), tp)
                    y = cl * fp
                    ymu[j] = y
                    x[j] = mrow[j] - rv + cl + y
                for q in range(rk):
                    a[q] = 0.0
                for j in range(K):
                    xj = x[j]
                    for q in range(rk):
                        a[q] += xj * A[j, q]
                for j in range(K):
                    e[j] = 0.0
                for q in range(rk):
                    aq = a[q]
                    for j in range(K):
                        e[j] += aq * B[q, j]
                E0[r, c] = e[0]
                for j in range(K):
                    rn = mrow[j] - e[j] + ymu[j]
                    R[i, j] = rn
                    cl = min(max(rn, -t), t)
                    z = cl - ymu[j]  # M - E - S = R - Y/mu - S = clip(R) - Y/mu
                    res += z * z
                    xn[j] = mrow[j] - rn + cl + f * cl
                for j in range(K):
                    xj = xn[j]
                    for q in range(j, K):
                        G[j, q] += xj * xn[q]
        res_parts[b] = res


@njit(cache=True, parallel=True)
def first_column_scores(R, t, out):  # pragma: no cover - compiled
    """``out[r] = || S[3r:3r+3, 0] ||_2`` with ``S = R - clip(R, t)`` (Eq. 5.99)."""
    m = out.shape[0]
    for r in prange(m):
        acc = 0.0
        for c in range(3):
            v = R[3 * r + c, 0]
            s = v - min(max(v, -t), t)
            acc += s * s
        out[r] = np.sqrt(acc)


@njit(cache=True, parallel=True)
def sparse_part(R, t, out):  # pragma: no cover - compiled
    """``out = R - clip(R, -t, t)`` (the shrinkage of Eq. 4.20)."""
    m, n = R.shape
    for i in prange(m):
        for j in range(n):
            v = R[i, j]
            out[i, j] = v - min(max(v, -t), t)


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
