"""Fused serial element-wise kernels of the row-chunked RPCA engines (numba): one memory-bound
pass per chunk writes several outputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def ialm_prepare(Mc, Rc, t, ratio, X, Ymu):  # pragma: no cover - compiled
    """``Ymu = ratio * clip(R, -t, t)`` and the SVT argument ``X = M - S + Y / mu`` (Eq. 4.21)
    with ``S = R - clip(R)``.
    """
    m, n = Mc.shape
    for i in range(m):
        for j in range(n):
            r = Rc[i, j]
            c = min(max(r, -t), t)
            y = ratio * c
            Ymu[i, j] = y
            X[i, j] = Mc[i, j] - r + c + y


@njit(cache=True)
def ialm_update(Mc, Ec, Ymu, t, f, R_out, E_out, Xn):  # pragma: no cover - compiled
    """Write ``E``, ``R = M - E + Y/mu`` and the next SVT argument; return ``||M - E - S||^2``."""
    m, n = Mc.shape
    acc = 0.0
    for i in range(m):
        for j in range(n):
            e = Ec[i, j]
            y = Ymu[i, j]
            r = Mc[i, j] - e + y
            c = min(max(r, -t), t)
            g = float(c) - float(y)
            acc += g * g
            R_out[i, j] = r
            E_out[i, j] = e
            Xn[i, j] = e + (1.0 + f) * c - y
    return acc


@njit(cache=True)
def ialm_next_x(Mc, Rc, t, f, X):  # pragma: no cover - compiled
    """``X = M - (R - clip(R, t)) + f clip(R, t)`` (the next SVT argument from ``M`` and ``R``)."""
    m, n = Mc.shape
    for i in range(m):
        for j in range(n):
            r = Rc[i, j]
            c = min(max(r, -t), t)
            X[i, j] = Mc[i, j] - r + c + f * c


@njit(cache=True)
def alt_update(Mc, Ec, E_io, S_io, Xn, tau, hard):  # pragma: no cover - compiled
    """``S = threshold(M - E)``; write ``E``, ``S`` and ``Xn = M - S``; return the squared change."""
    m, n = Mc.shape
    acc = 0.0
    for i in range(m):
        for j in range(n):
            e = Ec[i, j]
            de = float(e) - float(E_io[i, j])
            E_io[i, j] = e
            z = Mc[i, j] - e
            if hard:
                s = z if abs(z) > tau else 0.0 * z
            else:
                s = z - min(max(z, -tau), tau)
            ds = float(s) - float(S_io[i, j])
            S_io[i, j] = s
            acc += de * de + ds * ds
            Xn[i, j] = Mc[i, j] - s
    return acc


@njit(cache=True)
def subtract_into(A, B, out):  # pragma: no cover - compiled
    """``out = A - B``."""
    m, n = A.shape
    for i in range(m):
        for j in range(n):
            out[i, j] = A[i, j] - B[i, j]


def soft_inplace(R: np.ndarray, t: float) -> None:
    """``R <- sign(R) max(|R| - t, 0)`` chunk-friendly (numpy; called once per solve)."""
    c = np.clip(R, -t, t)
    R -= c


@njit(cache=True)
def completion_update(D, mask, E, Y, mu, mu_next, X):  # pragma: no cover - compiled
    """One in-place pass of the completion ALM after ``E`` (Eq. 5.84, 5.87); returns
    ``||D - E||_F^2`` on the observed entries.
    """
    m, n = D.shape
    res = 0.0
    inv = 1.0 / mu_next
    for i in range(m):
        for j in range(n):
            if mask[i, j]:
                z = D[i, j] - E[i, j]
                y = Y[i, j] + mu * z
                Y[i, j] = y
                res += z * z
                X[i, j] = D[i, j] + y * inv
            else:
                X[i, j] = E[i, j]
    return res
