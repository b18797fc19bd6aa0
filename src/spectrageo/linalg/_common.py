"""Helpers of the low-rank / sparse solvers: checks, thresholding, non-convergence, row chunks,
noise and rank estimators.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np

from .._errors import ConvergenceError, ConvergenceWarning, InvalidInputError
from .._validation import check_choice, check_positive

_ON_NONCONVERGENCE = ("warn", "raise", "ignore")

#: Target size in bytes of one row chunk of a working array (bounded temporaries).
CHUNK_BYTES = 8 << 20


def as_matrix(
    M: Any, name: str = "M", *, allow_nan: bool = False, check: bool = True
) -> np.ndarray:
    """``M`` as a 2-D float array (float32 kept, ints to float64), checked finite in row chunks."""
    if hasattr(M, "toarray") and not isinstance(M, np.ndarray):
        raise InvalidInputError(f"`{name}` must be a dense array; got a sparse {type(M).__name__}.")
    try:
        arr = np.asarray(M)
    except (TypeError, ValueError) as exc:  # pragma: no cover - exotic inputs
        raise InvalidInputError(
            f"`{name}` must be a numeric 2-D array; got {type(M).__name__}."
        ) from exc
    if arr.dtype.kind not in "biuf":
        raise InvalidInputError(f"`{name}` must be a numeric 2-D array; got dtype {arr.dtype}.")
    if arr.dtype.kind != "f" or arr.dtype.itemsize < 4:
        arr = arr.astype(np.float64)
    elif arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    if arr.ndim != 2:
        raise InvalidInputError(
            f"`{name}` must be a 2-D array (m, n); got shape {tuple(arr.shape)}."
        )
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InvalidInputError(f"`{name}` is empty; got shape {tuple(arr.shape)}.")
    if check and not allow_nan:
        for sl in row_chunks(arr.shape[0], arr.shape[1], arr.itemsize):
            if not np.isfinite(arr[sl]).all():
                raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    return arr


def check_on_nonconvergence(value: str) -> str:
    return check_choice(value, "on_nonconvergence", _ON_NONCONVERGENCE)


def check_tol_iter(tol: Any, max_iter: Any) -> None:
    check_positive(tol, "tol")
    check_positive(max_iter, "max_iter", integer=True)


def report_nonconvergence(result: Any, policy: str, what: str) -> Any:
    """Apply the ``on_nonconvergence`` policy to a finished ``result``: warn with
    :class:`ConvergenceWarning`, raise :class:`ConvergenceError` (``partial``) or return it.
    """
    if result.converged or policy == "ignore":
        return result
    msg = (
        f"{what} did not converge in {result.n_iter} iterations "
        f"(residual {result.residual:.3g}); increase `max_iter` or relax `tol`."
    )
    if policy == "raise":
        raise ConvergenceError(msg, partial=result)
    warnings.warn(msg, ConvergenceWarning, stacklevel=3)
    return result


def soft_threshold(x: np.ndarray, tau: float, out: np.ndarray | None = None) -> np.ndarray:
    """Element-wise shrinkage ``sign(x) max(|x| - tau, 0)`` (the operator Q_tau of Eq. 4.20)."""
    # x - clip(x, -tau, tau) equals the shrinkage and needs a single temporary.
    c = np.clip(x, -tau, tau)
    return np.subtract(x, c, out=out)


def hard_threshold(x: np.ndarray, tau: float, out: np.ndarray | None = None) -> np.ndarray:
    """Element-wise ``x * (|x| > tau)``."""
    return np.multiply(x, np.abs(x) > tau, out=out)


def row_chunks(m: int, n: int, itemsize: int, chunk_rows: int | None = None) -> Iterator[slice]:
    """Slices covering ``range(m)`` in blocks of about :data:`CHUNK_BYTES` per (rows, n) block."""
    if chunk_rows is None:
        chunk_rows = max(256, CHUNK_BYTES // max(1, n * itemsize))
    for start in range(0, m, chunk_rows):
        yield slice(start, min(m, start + chunk_rows))


def marchenko_pastur_median(beta: float) -> float:
    """Median of the Marchenko-Pastur law with aspect ratio ``beta`` in (0, 1]."""
    from scipy import integrate, optimize

    if beta < 1e-6:
        return 1.0
    a, b = (1 - np.sqrt(beta)) ** 2, (1 + np.sqrt(beta)) ** 2

    def density(x: float) -> float:
        return np.sqrt(max((b - x) * (x - a), 0.0)) / (2 * np.pi * beta * x)

    def cdf(x: float) -> float:
        return integrate.quad(density, a, x, limit=200)[0]

    return float(optimize.brentq(lambda x: cdf(x) - 0.5, a, b, xtol=1e-12))


def noise_sigma_from_singular_values(s: np.ndarray, m: int, n: int) -> float:
    """Noise deviation from the median singular value and the median of the
    Marchenko-Pastur law of aspect ratio ``min/max`` (Gavish & Donoho, 2014).
    """
    big, small = max(m, n), min(m, n)
    beta = small / big
    return float(np.median(s) / np.sqrt(big * marchenko_pastur_median(beta)))


def estimate_rank(s: np.ndarray, m: int, n: int) -> int:
    """Rank by the optimal hard threshold ``omega(beta) * median(s)`` for unknown noise (Gavish &
    Donoho, 2014), at least 1.
    """
    beta = min(m, n) / max(m, n)
    omega = 0.56 * beta**3 - 0.95 * beta**2 + 1.82 * beta + 1.43
    r = int(np.count_nonzero(s > omega * np.median(s)))
    return max(1, min(r, len(s)))


#: Matrices whose short side is at most this always get a full SVD.
FULL_SVD_MAX = 500


def top_svd(X: np.ndarray, k: int, rng: np.random.Generator):
    """Leading ``k`` singular triplets ``(U, s, Vt)``, ``s`` descending (LAPACK or ARPACK)."""
    p = min(X.shape)
    k = max(1, min(k, p))
    if p <= FULL_SVD_MAX or k > p // 5:
        U, s, Vt = np.linalg.svd(X, full_matrices=False)
        return U[:, :k], s[:k], Vt[:k]
    from scipy.sparse.linalg import svds

    U, s, Vt = svds(X, k=k, rng=rng)
    order = np.argsort(s)[::-1]
    return U[:, order], s[order], Vt[order]


def blas_threads(short_side: int, *, chunked: bool = False):
    """One BLAS thread for small problems and the chunked engine
    (docs/decisions.md#linalg-blas-threads).
    """
    if chunked or short_side <= FULL_SVD_MAX:
        return single_thread_blas()
    return contextlib.nullcontext()


_CONTROLLER = None


def single_thread_blas():
    """BLAS on one thread through a cached ``threadpoolctl`` controller."""
    global _CONTROLLER
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=1, user_api="blas")


def spd_factor(K):
    """SuperLU of a sparse SPD ``K``, minimum-degree order of ``K + K^T`` without pivoting
    (docs/decisions.md#linalg-spd-factor); ``RuntimeError`` when ``K`` is singular.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    return splu(
        sp.csc_matrix(K),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
