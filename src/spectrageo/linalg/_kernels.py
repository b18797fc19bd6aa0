"""Fused element-wise kernels of the row-chunked RPCA engines (numba).

Each kernel makes one pass over a chunk and writes several outputs, so that a solver iteration
reads the input and its state once instead of through a chain of numpy temporaries. The loops
are serial on purpose: they are memory-bound, the matrix products between them already use the
BLAS threads, and numba parallel regions cost milliseconds per call on a loaded machine.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def ialm_prepare(Mc, Rc, t, ratio, X, Ymu):  # pragma: no cover - compiled
    """``Ymu = ratio * clip(R, -t, t)``, ``X = M - (R - clip(R)) + Ymu``.

    With ``t = lam / mu_prev`` and ``ratio = mu_prev / mu``: ``S = R - clip(R)`` and
    ``Y / mu = ratio * clip(R)``, so ``X = M - S + Y / mu`` (the argument of the SVT, Eq. 4.21).
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
    """Write ``E``, ``R = M - E + Y/mu``, the next SVT argument; return ``||M - E - S||^2``.

    ``S = R - clip(R, t)`` and ``Y_new / mu = clip(R, t)`` with ``t = lam / mu``; the next SVT
    argument is ``M - S + Y_new / mu_next = E + (1 + f) clip(R) - Y/mu`` with ``f = mu / mu_next``.
    """
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
    """One pass of the completion ALM after ``E`` (Eq. 5.84 and 5.87), in place.

    On observed entries: ``Z = D - E``, ``Y += mu Z``, next SVT argument ``X = D + Y / mu_next``;
    elsewhere ``S = -E`` so ``X = D - S + Y / mu_next = E`` (``D`` and ``Y`` vanish there).
    Returns ``||Z||_F^2``.
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
