"""Low-rank matrix completion by the augmented Lagrange multiplier method (Section 5.3.1)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_rng, check_positive
from ._common import (
    FULL_SVD_MAX,
    blas_threads,
    check_on_nonconvergence,
    check_tol_iter,
    report_nonconvergence,
    top_svd,
)
from ._kernels import completion_update

__all__ = ["CompletionResult", "complete_matrix"]

#: From this many entries on, the Gram products of :func:`_svt_gram` are long enough to gain from
#: a multithreaded BLAS (26002 x 96, two cores: 3.8 -> 3.0 s for the whole completion); below, BLAS
#: runs on one thread (see :func:`._common.blas_threads`).
GRAM_THREADED_SIZE = 1_000_000


@dataclass(frozen=True)
class CompletionResult:
    """Result of :func:`complete_matrix`: the ``completed`` (m, n) matrix, ``n_iter``, ``converged``,
    ``residual`` ``||P_omega(M - E)||_F / ||P_omega(M)||_F``, the ``rank`` of the last ``E`` and
    ``n_singular``, the count ``n_lambda`` of Eq. 5.89.
    """

    completed: np.ndarray = field(repr=False)
    n_iter: int
    converged: bool
    residual: float
    rank: int = 0
    n_singular: int = 0


def complete_matrix(
    M: Any,
    observed: Any,
    *,
    tol: float = 1e-7,
    max_iter: int = 500,
    mu: float | None = None,
    rho: float = 1.05,
    sv_start: int | None = None,
    sv_max: int | None = None,
    keep_observed: bool = True,
    on_nonconvergence: str = "warn",
    rng: Any = None,
) -> CompletionResult:
    """Fill the unobserved entries of a low-rank matrix (Eq. 5.80-5.89).

    Solves ``min ||E||_*  s.t.  E + S = D, P_omega(S) = 0`` (Eq. 5.80) by ALM: ``E`` thresholds the
    ``n_lambda`` leading singular values of ``D - S + Y / mu`` (Eq. 5.85-5.86),
    ``S = -P_{omega-bar}(E)`` (Eq. 5.87; Eq. 5.88 prints a complement typo), ``Y <- Y + mu (D - E - S)``,
    ``mu <- rho mu`` (Eq. 5.84). ``n_lambda`` grows from ``floor(k/2)`` to ``floor(3k/4)`` unless the
    trailing values flatten (Eq. 5.89). Defaults: docs/decisions.md#linalg-completion-rho.

    Parameters
    ----------
    M, observed : (m, n) array_like, (m, n) bool
        Data (entries outside ``observed`` are ignored, may be NaN) and the mask ``omega``.
    tol, max_iter, mu, rho
        Stopping rule; initial penalty (default ``1 / ||D||_2``) and its growth (``>= 1``).
    sv_start, sv_max, keep_observed
        Bounds of ``n_lambda``; put the data back on the observed entries (Section 5.3.1).
    on_nonconvergence, rng
        See :func:`rpca`; start vectors of the partial SVD. Returns a :class:`CompletionResult`.
    """
    check_on_nonconvergence(on_nonconvergence)
    check_tol_iter(tol, max_iter)
    try:
        D = np.array(M, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(
            f"`M` must be a numeric 2-D array; got {type(M).__name__}."
        ) from exc
    if D.ndim != 2 or D.size == 0:
        raise InvalidInputError(f"`M` must be a non-empty 2-D array (m, n); got shape {D.shape}.")
    mask = np.asarray(observed)
    if mask.shape != D.shape:
        raise InvalidInputError(
            f"`observed` must have the shape of `M` {D.shape}; got {tuple(mask.shape)}."
        )
    if mask.dtype != bool:
        if mask.dtype.kind not in "iu" or not np.isin(mask, (0, 1)).all():
            raise InvalidInputError("`observed` must be a boolean mask (or 0/1 integers).")
        mask = mask.astype(bool)
    n_obs = int(mask.sum())
    if n_obs == 0:
        raise InvalidInputError("`observed` selects no entry; at least one must be known.")
    if not np.isfinite(D[mask]).all():
        raise InvalidInputError("`M` contains NaN or inf values at observed entries.")
    D[~mask] = 0.0
    m, n = D.shape
    k_all = min(m, n)
    sv_lo = max(1, k_all // 2) if sv_start is None else sv_start
    sv_hi = max(1, (3 * k_all) // 4) if sv_max is None else sv_max
    check_positive(sv_lo, "sv_start", integer=True)
    check_positive(sv_hi, "sv_max", integer=True)
    if sv_lo > k_all or sv_hi > k_all:
        raise InvalidInputError(
            f"`sv_start` and `sv_max` must be <= min(m, n) = {k_all}; got {sv_lo} and {sv_hi}."
        )
    sv_hi = max(sv_hi, sv_lo)
    gen = as_rng(rng)
    normD = float(np.linalg.norm(D))
    if normD == 0:
        result = CompletionResult(np.zeros_like(D), 0, True, 0.0, 0, sv_lo)
        return result
    if mu is None:
        mu = 1.0 / float(top_svd(D, 1, gen)[1][0])
    else:
        check_positive(mu, "mu")
    check_positive(rho, "rho")
    if rho < 1:
        raise InvalidInputError(f"`rho` must be >= 1; got {rho!r}.")

    with blas_threads(k_all if D.size < GRAM_THREADED_SIZE else FULL_SVD_MAX + 1):
        E, it, converged, residual, rank, n_lam = _alm(
            D, mask, mu, rho, sv_lo, sv_hi, tol, max_iter, normD, gen
        )
    completed = np.where(mask, D, E) if keep_observed else E
    result = CompletionResult(completed, it, converged, residual, rank, n_lam)
    return report_nonconvergence(result, on_nonconvergence, "Matrix completion (ALM)")


def _svt_gram(X: np.ndarray, k: int, tau: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Eq. 5.85-5.86 from the Gram matrix of the tall orientation, for a short side of at
    most :data:`FULL_SVD_MAX`; returns ``(E, lambda (k,), r)``.
    """
    tall = X.shape[0] >= X.shape[1]
    A = X if tall else X.T
    w, V = np.linalg.eigh(A.T @ A)
    w, V = w[::-1][:k], V[:, ::-1][:, :k]
    lam = np.sqrt(np.maximum(w, 0.0))
    shr = np.maximum(lam - tau, 0.0)
    r = int(np.count_nonzero(shr))
    if r == 0:
        return np.zeros_like(X), lam, 0
    W = (V[:, :r] * (shr[:r] / lam[:r])) @ V[:, :r].T
    E = A @ W
    return (E if tall else E.T), lam, r


def _alm(D, mask, mu, rho, sv_lo, sv_hi, tol, max_iter, normD, gen):
    """ALM iterations of :func:`complete_matrix`; ``S`` is never stored (``-E`` off ``omega``)."""
    Y = np.zeros_like(D)
    X = D.copy()  # S = 0, Y = 0
    E = np.zeros_like(D)
    n_lam = sv_lo
    converged, residual, rank = False, np.inf, 0
    it = 0
    gram = min(D.shape) <= FULL_SVD_MAX
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
        if gram:  # Eq. 5.85-5.86 from the small Gram matrix
            E, lam, rank = _svt_gram(X, n_lam, 1.0 / mu)
        else:
            U, lam, Vt = top_svd(X, n_lam, gen)  # Eq. 5.85, n_lambda leading triplets
            shr = np.maximum(lam - 1.0 / mu, 0.0)  # Eq. 5.86
            rank = int(np.count_nonzero(shr))
            E = (U[:, :rank] * shr[:rank]) @ Vt[:rank]
        E = np.ascontiguousarray(E)
        # Eq. 5.87 and 5.84: S = -P_omega-bar(E), Y += mu (D - E - S), next argument
        res2 = completion_update(D, mask, E, Y, mu, mu * rho, X)
        residual = float(np.sqrt(res2)) / normD
        mu *= rho
        if residual < tol:
            converged = True
            break
        # Eq. 5.89: grow n_lambda unless the last two computed singular values are equal
        if n_lam < 2 or lam.size < n_lam or lam[n_lam - 1] <= 0.995 * lam[n_lam - 2]:
            n_lam = min(n_lam + 1, sv_hi)
    return E, it, converged, residual, rank, n_lam
