"""Thin SVD ``(s, V)`` of tall-skinny matrices accumulated over row chunks, never a full SVD.

Products ``W f(s) V^T`` with ``X = W diag(s) V^T`` are applied per chunk as
``X_c @ (V diag(f(s)/s) V^T)``. ``(s, V)`` comes from a Gram matrix preconditioned by the previous
iterate's ``V' diag(1/s')`` (accurate when ``X`` is close to it), or from TSQR when the Gram
matrix has fewer than 8 reliable digits.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

#: Smallest eigenvalue ratio of the (preconditioned) Gram matrix that is accepted.
GRAM_MIN_RATIO = 1e-8


class CoreAccumulator:
    """Accumulate ``(s, V)`` of a tall matrix with ``n`` columns from its row chunks, in
    ``"gram"`` (optionally preconditioned by ``precond = (s, V)``) or ``"qr"`` mode.
    """

    def __init__(self, n: int, mode: str = "gram", precond=None) -> None:
        self.n = n
        self.mode = mode
        self._G = np.zeros((n, n))
        self._Rs: list[np.ndarray] = []
        self._stack_rows = 0
        self._B = None  # X = Y B with Y = X P, B = P^{-1}
        self._P = None
        if mode == "gram" and precond is not None:
            s, V = precond
            if s.size and s[0] > 0:
                floor = s[0] * 1e-8
                ss = np.maximum(s, floor)
                self._P = V / ss
                self._B = ss[:, None] * V.T

    def add(self, X: np.ndarray) -> None:
        X = np.asarray(X, dtype=np.float64)
        if self.mode == "gram":
            Y = X if self._P is None else X @ self._P
            self._G += Y.T @ Y
            return
        R = sla.qr(X, mode="r", check_finite=False)[0]
        self._Rs.append(R[: min(X.shape[0], self.n)])
        self._stack_rows += self._Rs[-1].shape[0]
        if self._stack_rows > 64 * self.n:  # keep the stack of R factors small
            self._Rs = [self._reduce()]
            self._stack_rows = self._Rs[0].shape[0]

    def _reduce(self) -> np.ndarray:
        if not self._Rs:
            return np.zeros((0, self.n))
        R = sla.qr(np.vstack(self._Rs), mode="r", check_finite=False)[0]
        return R[: min(R.shape[0], self.n)]

    def finish(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Return ``(s, V)`` (descending), or ``None`` when the Gram matrix is too ill-conditioned."""
        if self.mode == "gram":
            w, Q = np.linalg.eigh(self._G)
            if w[-1] <= 0:
                return np.zeros(self.n), np.eye(self.n)
            if w[0] < GRAM_MIN_RATIO * w[-1]:
                return None
            F = np.sqrt(w)[:, None] * Q.T  # G = F^T F
            if self._B is not None:
                F = F @ self._B
            s, Vt = _svd(F)
            return s, Vt.T
        R = self._reduce()
        if R.shape[0] < self.n:
            R = np.vstack([R, np.zeros((self.n - R.shape[0], self.n))])
        s, Vt = _svd(R)
        return s, Vt.T


def _svd(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(s, Vt)`` of a small square matrix by ``gesdd``, or ``gesvd`` where ``gesdd`` fails."""
    try:
        _, s, Vt = np.linalg.svd(X)
    except np.linalg.LinAlgError:
        _, s, Vt = sla.svd(X, lapack_driver="gesvd", check_finite=False)
    return s, Vt


def positive_part(s: np.ndarray, m: int) -> int:
    """Number of numerically non-zero singular values of an ``m``-row matrix."""
    if s.size == 0 or s[0] == 0:
        return 0
    tol = s[0] * max(m, s.size) * np.finfo(np.float64).eps
    return int(np.count_nonzero(s > tol))
