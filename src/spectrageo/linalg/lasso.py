"""LASSO by the alternating direction method of multipliers (Eq. 5.96)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import check_positive
from ._common import check_on_nonconvergence, check_tol_iter, report_nonconvergence

__all__ = ["LassoResult", "lasso"]


@dataclass(frozen=True)
class LassoResult:
    """Result of :func:`lasso`: ``coef`` (the sparse ADMM iterate ``z``), ``n_iter``, ``converged``,
    primal ``residual`` ``||x - z||_F``, ``dual_residual`` ``rho ||z - z_prev||_F`` and the
    ``objective``.
    """

    coef: np.ndarray = field(repr=False)
    n_iter: int
    converged: bool
    residual: float
    dual_residual: float = 0.0
    objective: float = 0.0


def lasso(
    A: Any,
    b: Any,
    *,
    alpha: float,
    rho: float = 1.0,
    tol: float = 1e-6,
    max_iter: int = 5000,
    x0: Any = None,
    on_nonconvergence: str = "warn",
) -> LassoResult:
    """Solve ``min_x (1 / (2 n_samples)) ||b - A x||_2^2 + alpha ||x||_1`` by ADMM (Eq. 5.96).

    Eq. 5.96 in scikit-learn's scaling (``gamma = alpha * n_samples``, no intercept). ADMM (Boyd et
    al., 2011, Section 6.4) iterates ``x = (A^T A / N + rho I)^{-1} (A^T b / N + rho (z - u))``,
    ``z = S_{alpha / rho}(x + u)``, ``u = u + x - z`` with one factorisation (Cholesky, the inversion
    lemma when wide, or sparse LU) for all iterations and targets, until Boyd's primal and dual
    rules with absolute and relative tolerance ``tol`` hold.

    Parameters
    ----------
    A, b : (n_samples, n_features) array or sparse, (n_samples,) or (n_samples, n_targets)
    alpha, rho : float
        ``l1`` weight (``>= 0``) and ADMM penalty (``> 0``).
    tol, max_iter, x0, on_nonconvergence
        Stopping rule, warm start ``z`` and the policy of :func:`rpca`.

    Returns
    -------
    LassoResult
    """
    check_on_nonconvergence(on_nonconvergence)
    check_tol_iter(tol, max_iter)
    check_positive(alpha, "alpha", allow_zero=True)
    check_positive(rho, "rho")
    is_sparse = sp.issparse(A)
    if is_sparse:
        A = sp.csr_matrix(A, dtype=np.float64)
        if not np.isfinite(A.data).all():
            raise InvalidInputError("`A` contains NaN or inf values.")
    else:
        A = np.asarray(A, dtype=np.float64)
        if not np.isfinite(A).all():
            raise InvalidInputError("`A` contains NaN or inf values.")
    if A.ndim != 2 or A.shape[0] == 0 or A.shape[1] == 0:
        raise InvalidInputError(f"`A` must be a non-empty 2-D array; got shape {A.shape}.")
    N, p = A.shape
    b = np.asarray(b, dtype=np.float64)
    vector = b.ndim == 1
    B = b[:, None] if vector else b
    if B.ndim != 2 or B.shape[0] != N:
        raise InvalidInputError(
            f"`b` must have shape ({N},) or ({N}, n_targets) to match `A` {A.shape}; got {b.shape}."
        )
    if not np.isfinite(B).all():
        raise InvalidInputError("`b` contains NaN or inf values.")
    k = B.shape[1]
    Z = np.zeros((p, k))
    if x0 is not None:
        x0 = np.asarray(x0, dtype=np.float64)
        if x0.reshape(-1).shape != (p * k,):
            raise InvalidInputError(f"`x0` must have {p * k} entries; got shape {x0.shape}.")
        Z = x0.reshape(p, k).copy()

    solve = _factorised_solver(A, N, rho, is_sparse)
    Atb = (A.T @ B) / N
    U = np.zeros_like(Z)
    thr = alpha / rho
    sq = np.sqrt(p * k)
    converged, r_norm, s_norm = False, np.inf, np.inf
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
        X = solve(Atb + rho * (Z - U))
        Z_old = Z
        V = X + U
        Z = V - np.clip(V, -thr, thr)
        U = V - Z  # = U + X - Z
        r_norm = float(np.linalg.norm(X - Z))
        s_norm = rho * float(np.linalg.norm(Z - Z_old))
        eps_pri = tol * (sq + max(np.linalg.norm(X), np.linalg.norm(Z)))
        eps_dual = tol * (sq + rho * np.linalg.norm(U))
        if r_norm <= eps_pri and s_norm <= eps_dual:
            converged = True
            break
    resid = B - A @ Z
    obj = float(0.5 / N * np.sum(resid**2) + alpha * np.abs(Z).sum())
    coef = Z[:, 0] if vector else Z
    result = LassoResult(coef, it, converged, r_norm, s_norm, obj)
    return report_nonconvergence(result, on_nonconvergence, "LASSO (ADMM)")


def _factorised_solver(
    A, N: int, rho: float, is_sparse: bool
) -> Callable[[np.ndarray], np.ndarray]:
    """Return ``q -> (A^T A / N + rho I)^{-1} q`` with the factorisation computed once."""
    n_samples, p = A.shape
    if is_sparse:
        from ._common import spd_factor

        K = (A.T @ A) / N + rho * sp.identity(p, format="csr")
        lu = spd_factor(K)
        return lu.solve
    if p <= n_samples:
        K = (A.T @ A) / N
        K[np.diag_indices(p)] += rho
        cf = sla.cho_factor(K, lower=True, check_finite=False)
        return lambda q: sla.cho_solve(cf, q, check_finite=False)
    # Woodbury: (rho I + A^T A / N)^{-1} q = q / rho - A^T (I + A A^T / (N rho))^{-1} A q / (N rho^2)
    K = (A @ A.T) / (N * rho)
    K[np.diag_indices(n_samples)] += 1.0
    cf = sla.cho_factor(K, lower=True, check_finite=False)

    def solve(q: np.ndarray) -> np.ndarray:
        return q / rho - A.T @ sla.cho_solve(cf, A @ q, check_finite=False) / (N * rho**2)

    return solve
