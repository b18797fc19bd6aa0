"""Singular value thresholding through the Gram matrix, and the ranking stop rule's levels.

Shared by the numba solver (:mod:`._rpca_solver`) and the PyTorch path (:mod:`._torch`) of the
patch RPCA, so that both threshold with identical operators when their Gram matrices agree.
"""

from __future__ import annotations

import numpy as np

__all__ = ["RANK_BIN", "RANK_FLOOR", "svt_operator"]

#: Ranking stop rule of the ALM (see :func:`spectrageo.outliers.rpca_scores`): the scores are
#: ranked by the levels ``RANK_FLOOR * 2^j`` spacings (the smallest automatic threshold of
#: ``remove_outliers`` and its doublings; scores below the floor tie), and the ALM stops once the
#: shrinkage level ``lam / mu`` is below the floor and at most ``rank_tol`` of the points changed
#: level in one iteration.
RANK_FLOOR = 0.4
RANK_BIN = float(np.log10(2.0))  # decades per level


def svt_operator(G: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``W`` (K, K) with ``X W = D_tau(X)`` (Eq. 4.21) from the Gram matrix ``G = X^T X``, and its
    factors ``W = A B`` (``A`` (K, r), ``B`` (r, K)).

    ``X = U diag(s) V^T`` gives ``D_tau(X) = X V_r diag(1 - tau / s_r) V_r^T`` over the ``r``
    singular values above ``tau`` (the eigenpairs of ``G``); never an SVD of the tall ``X``.
    """
    w, V = np.linalg.eigh(G)
    s = np.sqrt(np.maximum(w, 0.0))
    pos = s > tau
    K = G.shape[0]
    if not pos.any():  # everything thresholded away: E = 0
        return np.zeros_like(G), np.zeros((K, 1)), np.zeros((1, K))
    Vr = V[:, pos]
    A = np.ascontiguousarray(Vr * (1.0 - tau / s[pos]))
    return np.ascontiguousarray(A @ Vr.T), A, np.ascontiguousarray(Vr.T)
