"""Linear algebra with a fixed order of floating-point operations, for bit-identical decoders.

Numba loops without BLAS, LAPACK or ``fastmath``, every sum in one written order and vectorised
only across independent outputs (docs/decisions.md#deterministic-decoders): :class:`SparseCholesky`
(:mod:`._cholesky`, ordered by :mod:`._amd`), :func:`matmul` and :func:`orthonormal_columns`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._errors import InvalidInputError
from ._amd import _min_degree, fill_reducing_order
from ._cholesky import SparseCholesky, _gemm_nt_sub

__all__ = [
    "SparseCholesky",
    "_gemm_nt_sub",
    "_min_degree",
    "fill_reducing_order",
    "matmul",
    "orthonormal_columns",
]


# ----------------------------------------------------------------------------- dense helpers
@njit(cache=True)
def _matmul_kernel(A, B, C):  # pragma: no cover - jitted
    """``C = A @ B`` summed with ``k`` ascending, four ``k`` per pass, innermost loop over ``j``."""
    m, kk = A.shape
    n = B.shape[1]
    for i in range(m):
        ci = C[i]
        for j in range(n):
            ci[j] = 0.0
        k = 0
        while k + 4 <= kk:
            a0 = A[i, k]
            a1 = A[i, k + 1]
            a2 = A[i, k + 2]
            a3 = A[i, k + 3]
            b0 = B[k]
            b1 = B[k + 1]
            b2 = B[k + 2]
            b3 = B[k + 3]
            for j in range(n):
                ci[j] = ci[j] + a0 * b0[j] + a1 * b1[j] + a2 * b2[j] + a3 * b3[j]
            k += 4
        while k < kk:
            a0 = A[i, k]
            b0 = B[k]
            for j in range(n):
                ci[j] += a0 * b0[j]
            k += 1


def matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Dense ``A @ B`` (m, k) x (k, n), every entry summed in index order without BLAS."""
    A = np.ascontiguousarray(A, dtype=np.float64)
    B = np.ascontiguousarray(B, dtype=np.float64)
    if A.ndim != 2 or B.ndim != 2 or A.shape[1] != B.shape[0]:
        raise InvalidInputError(f"`A` and `B` do not chain: shapes {A.shape} and {B.shape}.")
    C = np.empty((A.shape[0], B.shape[1]))
    _matmul_kernel(A, B, C)
    return C


@njit(cache=True)
def _householder_q(A):  # pragma: no cover - jitted
    """Householder ``Q`` (m, k) of ``A`` with a non-negative ``R`` diagonal, sums in index order."""
    m, k = A.shape
    V = np.zeros((m, k))
    tau = np.zeros(k)
    sgn = np.ones(k)
    for j in range(k):
        s = 0.0
        for i in range(j, m):
            s += A[i, j] * A[i, j]
        nrm = math.sqrt(s)
        alpha = A[j, j]
        if nrm == 0.0:
            V[j, j] = 1.0
            continue
        beta = -math.copysign(nrm, alpha)
        den = alpha - beta
        V[j, j] = 1.0
        for i in range(j + 1, m):
            V[i, j] = A[i, j] / den
        tau[j] = (beta - alpha) / beta
        if beta < 0.0:
            sgn[j] = -1.0
        for c in range(j + 1, k):
            w = 0.0
            for i in range(j, m):
                w += V[i, j] * A[i, c]
            w = tau[j] * w
            for i in range(j, m):
                A[i, c] -= w * V[i, j]
    Q = np.zeros((m, k))
    for j in range(k):
        Q[j, j] = 1.0
    for j in range(k - 1, -1, -1):
        for c in range(j, k):
            w = 0.0
            for i in range(j, m):
                w += V[i, j] * Q[i, c]
            w = tau[j] * w
            for i in range(j, m):
                Q[i, c] -= w * V[i, j]
    for i in range(m):
        for j in range(k):
            Q[i, j] = Q[i, j] * sgn[j]
    return Q


def orthonormal_columns(A: np.ndarray) -> np.ndarray:
    """``Q`` (m, k) of the Householder QR of ``A`` (``k <= m``) with ``R``'s diagonal
    non-negative, without LAPACK; a zero column keeps a unit vector.
    """
    A = np.array(A, dtype=np.float64, order="C", copy=True)
    if A.ndim != 2 or A.shape[1] > A.shape[0]:
        raise InvalidInputError(f"`A` must have shape (m, k) with k <= m; got {A.shape}.")
    if A.shape[1] == 0:
        return A
    return _householder_q(A)
