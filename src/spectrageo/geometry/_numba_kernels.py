"""Sequential kernels that cannot be vectorised with numpy."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def propagate_signs(
    N: np.ndarray, child: np.ndarray, par: np.ndarray
) -> None:  # pragma: no cover - jitted
    """Flip ``N[child[t]]`` to agree with ``N[par[t]]``, in order (BFS order of a spanning tree)."""
    for t in range(child.shape[0]):
        c = child[t]
        p = par[t]
        d = N[c, 0] * N[p, 0] + N[c, 1] * N[p, 1] + N[c, 2] * N[p, 2]
        if d < 0:
            N[c, 0] = -N[c, 0]
            N[c, 1] = -N[c, 1]
            N[c, 2] = -N[c, 2]


@numba.njit(cache=True)
def vertex_update_kernel(V, F, N, inv_deg, n_iter):  # pragma: no cover - jitted
    """``n_iter`` in-place steps of Eq. (4.28) (one pass over the faces each); ``inv_deg`` 0 = fixed."""
    n = V.shape[0]
    m = F.shape[0]
    delta = np.empty((n, 3))
    for _ in range(n_iter):
        delta[:, :] = 0.0
        for j in range(m):
            a = F[j, 0]
            b = F[j, 1]
            c = F[j, 2]
            c0 = (V[a, 0] + V[b, 0] + V[c, 0]) / 3.0
            c1 = (V[a, 1] + V[b, 1] + V[c, 1]) / 3.0
            c2 = (V[a, 2] + V[b, 2] + V[c, 2]) / 3.0
            n0 = N[j, 0]
            n1 = N[j, 1]
            n2 = N[j, 2]
            for t in range(3):
                v = F[j, t]
                p = n0 * (c0 - V[v, 0]) + n1 * (c1 - V[v, 1]) + n2 * (c2 - V[v, 2])
                delta[v, 0] += p * n0
                delta[v, 1] += p * n1
                delta[v, 2] += p * n2
        for i in range(n):
            s = inv_deg[i]
            V[i, 0] += delta[i, 0] * s
            V[i, 1] += delta[i, 1] * s
            V[i, 2] += delta[i, 2] * s
    return V


@numba.njit(cache=True, nogil=True)
def min_eigvec3(a00, a11, a22, a01, a02, a12):  # pragma: no cover - compiled
    """``(lambda_min, x, y, z)``: smallest eigenvalue of a symmetric 3x3 matrix and its unit
    eigenvector (cyclic Jacobi rotations, backward stable also for repeated eigenvalues)."""
    A = np.empty((3, 3))
    A[0, 0], A[1, 1], A[2, 2] = a00, a11, a22
    A[0, 1] = A[1, 0] = a01
    A[0, 2] = A[2, 0] = a02
    A[1, 2] = A[2, 1] = a12
    V = np.eye(3)
    for _ in range(30):
        off = A[0, 1] ** 2 + A[0, 2] ** 2 + A[1, 2] ** 2
        diag = A[0, 0] ** 2 + A[1, 1] ** 2 + A[2, 2] ** 2
        if off == 0.0 or off <= 1e-30 * diag:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = A[p, q]
            if apq == 0.0:
                continue
            theta = (A[q, q] - A[p, p]) / (2.0 * apq)
            t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            A[p, p] -= t * apq
            A[q, q] += t * apq
            A[p, q] = A[q, p] = 0.0
            r = 3 - p - q
            arp, arq = A[r, p], A[r, q]
            A[r, p] = A[p, r] = c * arp - s * arq
            A[r, q] = A[q, r] = s * arp + c * arq
            for i in range(3):
                vip, viq = V[i, p], V[i, q]
                V[i, p] = c * vip - s * viq
                V[i, q] = s * vip + c * viq
    j = 0
    if A[1, 1] < A[j, j]:
        j = 1
    if A[2, 2] < A[j, j]:
        j = 2
    return A[j, j], V[0, j], V[1, j], V[2, j]


@numba.njit(cache=True, nogil=True)
def patch_covariance(P, row):  # pragma: no cover - jitted
    """``(cxx, cyy, czz, cxy, cxz, cyz)`` of ``(1/k) sum (p - mean)(p - mean)^T`` over the points
    ``P[row]`` (``k = row.size``)."""
    k = row.shape[0]
    mx = 0.0
    my = 0.0
    mz = 0.0
    for q in range(k):
        j = row[q]
        mx += P[j, 0]
        my += P[j, 1]
        mz += P[j, 2]
    mx /= k
    my /= k
    mz /= k
    cxx = 0.0
    cyy = 0.0
    czz = 0.0
    cxy = 0.0
    cxz = 0.0
    cyz = 0.0
    for q in range(k):
        j = row[q]
        dx = P[j, 0] - mx
        dy = P[j, 1] - my
        dz = P[j, 2] - mz
        cxx += dx * dx
        cyy += dy * dy
        czz += dz * dz
        cxy += dx * dy
        cxz += dx * dz
        cyz += dy * dz
    return cxx / k, cyy / k, czz / k, cxy / k, cxz / k, cyz / k


@numba.njit(cache=True, parallel=True)
def patch_min_variance(P, idx, lam, dirs):  # pragma: no cover - jitted
    """Smallest eigenvalue ``lam[i]`` and its unit eigenvector ``dirs[i]`` of the covariance
    ``(1/k) sum (p - mean)(p - mean)^T`` of the points ``P[idx[i]]`` (``k`` = row length)."""
    for i in numba.prange(idx.shape[0]):
        cxx, cyy, czz, cxy, cxz, cyz = patch_covariance(P, idx[i])
        w, x, y, z = min_eigvec3(cxx, cyy, czz, cxy, cxz, cyz)
        lam[i] = w
        dirs[i, 0] = x
        dirs[i, 1] = y
        dirs[i, 2] = z
