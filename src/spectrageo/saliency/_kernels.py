"""Fused kernel of the patch RPCA (one pass over the matrix per iteration)."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(nogil=True, cache=True)
def ialm_fused_step(
    M: np.ndarray,
    A: np.ndarray,
    Y: np.ndarray,
    Qk: np.ndarray,
    W: np.ndarray,
    mu: float,
    mu_next: float,
    thr: float,
    group: bool,
    lo: int,
    hi: int,
) -> float:  # pragma: no cover - jitted
    """One inexact-ALM pass over the rows ``lo..hi-1`` (SVT rebuild, shrinkage, multiplier, next
    SVT input), in place; returns their share of ``||M - L - S||_F^2``."""
    p = M.shape[1]
    r = Qk.shape[1]
    inv = 1.0 / mu
    inv_next = 1.0 / mu_next
    t = np.empty(r)
    L = np.empty(p)
    acc = 0.0
    for i in range(lo, hi):
        t[:] = 0.0
        for j in range(p):
            a = A[i, j]
            for c in range(r):
                t[c] += a * Qk[j, c]
        L[:] = 0.0
        for c in range(r):
            tc = t[c]
            for j in range(p):
                L[j] += tc * W[c, j]
        if group:
            for j in range(0, p, 3):
                t0 = M[i, j] - L[j] + Y[i, j] * inv
                t1 = M[i, j + 1] - L[j + 1] + Y[i, j + 1] * inv
                t2 = M[i, j + 2] - L[j + 2] + Y[i, j + 2] * inv
                nrm = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                sc = 0.0
                if nrm > thr:
                    sc = 1.0 - thr / nrm
                for q in range(3):
                    if q == 0:
                        u = t0
                    elif q == 1:
                        u = t1
                    else:
                        u = t2
                    s = u * sc
                    z = M[i, j + q] - L[j + q] - s
                    acc += z * z
                    y = Y[i, j + q] + mu * z
                    Y[i, j + q] = y
                    A[i, j + q] = M[i, j + q] - s + y * inv_next
        else:
            for j in range(p):
                u = M[i, j] - L[j] + Y[i, j] * inv
                if u > thr:
                    s = u - thr
                elif u < -thr:
                    s = u + thr
                else:
                    s = 0.0
                z = M[i, j] - L[j] - s
                acc += z * z
                y = Y[i, j] + mu * z
                Y[i, j] = y
                A[i, j] = M[i, j] - s + y * inv_next
    return acc
