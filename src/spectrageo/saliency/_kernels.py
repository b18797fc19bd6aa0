"""Fused element-wise kernels of the patch RPCA (one pass over the matrix per iteration)."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, parallel=True)
def ialm_sparse_step(
    M: np.ndarray,
    L: np.ndarray,
    Y: np.ndarray,
    S: np.ndarray,
    A_next: np.ndarray,
    mu: float,
    mu_next: float,
    thr: float,
    group: bool,
) -> float:  # pragma: no cover - jitted
    """One sparse/multiplier update of the inexact ALM, in place; returns ``||M - L - S||_F^2``.

    ``S = shrink(M - L + Y / mu, thr)`` (group shrinkage of consecutive 3-vectors when ``group``,
    element-wise soft thresholding otherwise), ``Y += mu (M - L - S)`` and the next SVT input
    ``A_next = M - S + Y / mu_next``.
    """
    m, p = M.shape
    inv = 1.0 / mu
    inv_next = 1.0 / mu_next
    acc = np.zeros(m)
    for i in numba.prange(m):
        zz = 0.0
        if group:
            for j in range(0, p, 3):
                t0 = M[i, j] - L[i, j] + Y[i, j] * inv
                t1 = M[i, j + 1] - L[i, j + 1] + Y[i, j + 1] * inv
                t2 = M[i, j + 2] - L[i, j + 2] + Y[i, j + 2] * inv
                nrm = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                sc = 0.0
                if nrm > thr:
                    sc = 1.0 - thr / nrm
                for q in range(3):
                    if q == 0:
                        t = t0
                    elif q == 1:
                        t = t1
                    else:
                        t = t2
                    s = t * sc
                    S[i, j + q] = s
                    z = M[i, j + q] - L[i, j + q] - s
                    zz += z * z
                    y = Y[i, j + q] + mu * z
                    Y[i, j + q] = y
                    A_next[i, j + q] = M[i, j + q] - s + y * inv_next
        else:
            for j in range(p):
                t = M[i, j] - L[i, j] + Y[i, j] * inv
                if t > thr:
                    s = t - thr
                elif t < -thr:
                    s = t + thr
                else:
                    s = 0.0
                S[i, j] = s
                z = M[i, j] - L[i, j] - s
                zz += z * z
                y = Y[i, j] + mu * z
                Y[i, j] = y
                A_next[i, j] = M[i, j] - s + y * inv_next
        acc[i] = zz
    return acc.sum()
