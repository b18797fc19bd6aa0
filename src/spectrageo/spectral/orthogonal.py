"""Orthogonal iterations ``U <- Onorm(T^zeta U)`` for the low-frequency eigenspaces of submesh
Laplacians, tracked from submesh to submesh (Eq. 4.7, Algorithms 6-7, Appendix A).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from .._errors import ConvergenceWarning, InvalidInputError
from .._progress import progress
from .._validation import (
    as_rng,
    check_choice,
    check_positive,
    deprecated_flag,
    options_with_legacy,
)
from ..linalg._common import check_on_nonconvergence, report_nonconvergence, single_thread_blas
from ._shifted import (
    DELTA_REL,
    ShiftedFactor,
    _as_laplacian,
    _check_zeta,
    _delta,
    _nb_induced,
    _nb_permuted_laplacian,
    shifted_factor,
)
from .gft import fix_signs
from .partition import Submeshes, as_adjacency

__all__ = [
    "DOIResult",
    "OIResult",
    "ShiftedFactor",
    "SubmeshBases",
    "SubmeshOptions",
    "dynamic_orthogonal_iteration",
    "orthogonal_iteration",
    "orthogonal_iteration_result",
    "shifted_factor",
    "submesh_eigenbases",
    "submesh_eigenbases_result",
]

#: default thresholds of DOI on the relative low-pass residual ``||V - U U^T V||_F / ||V - mean(V)||_F``
DOI_EPS_LOW = 0.02
DOI_EPS_HIGH = 0.03


@dataclass(frozen=True, eq=False)
class OIResult:
    """Result of :func:`orthogonal_iteration`: ascending Ritz ``eigenvalues`` (k,), ``eigenvectors``
    (n, k), ``n_iter``, ``converged`` and ``residual`` ``max_j ||L u_j - theta_j u_j|| / ||L||_inf``.
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    n_iter: int
    converged: bool
    residual: float


@dataclass(frozen=True, eq=False)
class DOIResult:
    """Result of :func:`dynamic_orthogonal_iteration`, as :class:`OIResult`; ``residual`` is
    ``||X - U U^T X||_F / ||X - mean(X)||_F``.
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    n_iter: int
    converged: bool
    residual: float

    @property
    def size(self) -> int:
        """Subspace size ``n_l`` found."""
        return int(self.eigenvectors.shape[1])


def _apply_T(factor, Y: np.ndarray, zeta: int) -> np.ndarray:
    """``T^zeta Y`` by ``zeta`` solves, columns rescaled between solves (span unchanged)."""
    if isinstance(factor, ShiftedFactor):
        return factor.power(Y, zeta)
    solve = factor.solve if hasattr(factor, "solve") else factor
    for _ in range(zeta):
        Y = np.asarray(solve(Y), dtype=np.float64)
        nrm = np.sqrt(np.einsum("ij,ij->j", Y, Y))
        nrm[nrm == 0] = 1.0
        Y = Y / nrm
    return Y


def _onorm(Y: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the columns of ``Y`` (Eq. A.3-A.4; docs/decisions.md#spectral-onorm)."""
    n, k = Y.shape
    if 4 * k <= n:
        Q = _cholesky_qr(Y)
        if Q is not None:
            R2, Q2 = _cholesky_qr(Q, with_r=True)
            if R2 is not None and np.abs(R2 - np.eye(k)).max() < 1e-4:
                return Q2
    Q, _ = sla.qr(Y, mode="economic", overwrite_a=True, check_finite=False)
    return Q


def _cholesky_qr(Y: np.ndarray, *, with_r: bool = False):
    """``Y R^-1`` with ``Y^T Y = R^T R`` (None when the Gram matrix is not numerically positive definite)."""
    G = Y.T @ Y
    try:
        R = sla.cholesky(G, lower=False, check_finite=False)
    except np.linalg.LinAlgError:
        return (None, None) if with_r else None
    if not np.isfinite(R).all() or np.diag(R).min() <= 0:
        return (None, None) if with_r else None
    # Q = Y R^-1, i.e. R^T Q^T = Y^T
    Q = sla.solve_triangular(R, Y.T, trans="T", lower=False, check_finite=False).T
    return (R, Q) if with_r else Q


def _rayleigh_ritz(L: sp.spmatrix, Q: np.ndarray):
    """Ritz pairs of ``L`` on span(Q): ascending values ``theta``, vectors ``Q W``; also ``(L Q, W)``."""
    LQ = L @ Q
    H = Q.T @ LQ
    H = 0.5 * (H + H.T)
    theta, W = sla.eigh(H, driver="evd", check_finite=False)  # all pairs: divide and conquer
    return theta, Q @ W, (LQ, W)


def _ritz_residual(LQW, U: np.ndarray, theta: np.ndarray, norm_L: float) -> float:
    LQ, W = LQW
    R = LQ @ W - U * theta
    return float(np.sqrt(np.einsum("ij,ij->j", R, R)).max() / norm_L) if U.size else 0.0


def _norm_inf(L: sp.spmatrix) -> float:
    v = float(np.abs(L).sum(axis=1).max()) if L.nnz else 0.0
    return v if v > 0 else 1.0


def _check_basis(U0, n: int, name: str = "U0") -> np.ndarray:
    U0 = np.asarray(U0, dtype=np.float64)
    if U0.ndim != 2 or U0.shape[0] != n:
        raise InvalidInputError(f"`{name}` must have shape ({n}, k); got {U0.shape}.")
    if not 1 <= U0.shape[1] <= n:
        raise InvalidInputError(f"`{name}` must have between 1 and {n} columns; got {U0.shape[1]}.")
    if not np.isfinite(U0).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf.")
    return U0


def orthogonal_iteration(
    L,
    U0,
    *,
    delta: float | None = None,
    zeta: int = 4,
    n_iter: int = 1,
    factor=None,
    tol: float | None = None,
    full_output: bool | None = None,
    on_nonconvergence: str = "warn",
):
    """Orthogonal iteration ``U <- Onorm(T^zeta U)``, ``T = (L + delta I)^-1`` (Eq. 4.7, Algorithm 6).

    ``zeta`` sparse solves per iteration (Eq. 5.42), QR (Eq. A.3) and a Rayleigh-Ritz step that
    orders the columns; convergence factor ``((lambda_k + delta) / (lambda_{k+1} + delta))^zeta``.

    Parameters
    ----------
    L, U0 : sparse (n, n), (n, k)
        Laplacian ``L = D - C`` and a starting subspace of full column rank.
    delta, zeta, n_iter, factor
        Shift (default ``1e-2 mean(diag(L))``), power, iterations, reused :class:`ShiftedFactor`.
    tol, full_output, on_nonconvergence
        Ritz-residual tolerance; deprecated (:func:`orthogonal_iteration_result` returns the
        :class:`OIResult`); the policy when ``tol`` is not reached.
    """
    if full_output is not None:
        deprecated_flag(
            "orthogonal_iteration", "full_output", "orthogonal_iteration_result() (the OIResult)"
        )
    args = (L, U0, delta, zeta, n_iter, factor, tol, on_nonconvergence)
    result = _orthogonal_iteration(*args, bool(full_output))
    return result if full_output else result.eigenvectors


def orthogonal_iteration_result(
    L,
    U0,
    *,
    delta: float | None = None,
    zeta: int = 4,
    n_iter: int = 1,
    factor=None,
    tol: float | None = None,
    on_nonconvergence: str = "warn",
) -> OIResult:
    """:func:`orthogonal_iteration` returning the :class:`OIResult` (with the final residual)."""
    return _orthogonal_iteration(L, U0, delta, zeta, n_iter, factor, tol, on_nonconvergence, True)


def _orthogonal_iteration(
    L, U0, delta, zeta, n_iter, factor, tol, on_nonconvergence, full_output: bool
) -> OIResult:
    L = _as_laplacian(L)
    n = L.shape[0]
    U = _check_basis(U0, n)
    zeta = _check_zeta(zeta)
    check_positive(n_iter, "n_iter", integer=True)
    if tol is not None:
        check_positive(tol, "tol", allow_zero=True)
    if factor is None:
        factor = shifted_factor(L, delta=delta)
    elif not (hasattr(factor, "solve") or callable(factor)):
        raise InvalidInputError("`factor` must be a SuperLU object or a callable solve(B).")
    check_on_nonconvergence(on_nonconvergence)
    with single_thread_blas():
        theta, U, it, res = _oi(L, U, factor, zeta, int(n_iter), tol, full_output)
    result = OIResult(theta, U, it, bool(tol is not None and res <= tol), float(res))
    if tol is not None:
        report_nonconvergence(result, on_nonconvergence, f"Orthogonal iteration (tol={tol:g})")
    return result


def _oi(L, U, factor, zeta: int, n_iter: int, tol, want_residual: bool, ritz: bool = True):
    """Core of :func:`orthogonal_iteration`: ``(theta, U, n_iter, residual)``."""
    if not ritz and tol is None and not want_residual:
        for _ in range(n_iter):
            U = _onorm(_apply_T(factor, U, zeta))
        return np.full(U.shape[1], np.nan), U, n_iter, np.nan
    norm_L = _norm_inf(L)
    theta = np.zeros(U.shape[1])
    res = np.nan
    it = 0
    for it in range(1, n_iter + 1):  # noqa: B007
        Q = _onorm(_apply_T(factor, U, zeta))
        theta, U, LQW = _rayleigh_ritz(L, Q)
        if tol is not None or (want_residual and it == n_iter):
            res = _ritz_residual(LQW, U, theta, norm_L)
            if tol is not None and res <= tol:
                break
    return theta, fix_signs(U), it, res


def _relative_residual(X: np.ndarray, U: np.ndarray, scale: float):
    R = X - U @ (U.T @ X)
    return R, float(np.linalg.norm(R) / scale)


def dynamic_orthogonal_iteration(
    L,
    U0,
    X,
    *,
    eps_low: float = DOI_EPS_LOW,
    eps_high: float = DOI_EPS_HIGH,
    delta: float | None = None,
    zeta: int = 4,
    t_max: int = 100,
    min_size: int = 1,
    max_size: int | None = None,
    factor=None,
    on_nonconvergence: str = "warn",
) -> DOIResult:
    """Dynamic orthogonal iteration (Algorithm 7, Eq. 5.43-5.44): the subspace grows or shrinks
    until the relative low-pass residual of ``X`` lies in ``[eps_low, eps_high]``.

    Above the band the leading left singular vector of the residual is appended (Eq. 5.44), below
    it the last Ritz column is dropped (the text of Section 5.2.1 is followed where the listing swaps
    the tests); a column that jumps the band keeps the larger subspace.
    See docs/decisions.md#spectral-doi-band.

    Parameters
    ----------
    L, U0, X : sparse (n, n), (n, m0), (n,) or (n, d)
        Submesh Laplacian, starting subspace and signal.
    eps_low, eps_high
        The band of the relative residual.
    delta, zeta
        As in :func:`orthogonal_iteration`.
    t_max, min_size, max_size
        The step limit and the bounds of ``n_l`` (``max_size`` defaults to ``n - 1``).
    factor, on_nonconvergence
        As in :func:`orthogonal_iteration`.

    Returns
    -------
    DOIResult
    """
    L = _as_laplacian(L)
    n = L.shape[0]
    U = _check_basis(U0, n)
    X = np.asarray(X, dtype=np.float64)
    if X.ndim == 1:
        X = X[:, None]
    if X.ndim != 2 or X.shape[0] != n:
        raise InvalidInputError(f"`X` must have shape ({n},) or ({n}, d); got {X.shape}.")
    if not np.isfinite(X).all():
        raise InvalidInputError("`X` contains NaN or inf.")
    _check_band(eps_low, eps_high)
    zeta = _check_zeta(zeta)
    check_positive(t_max, "t_max", integer=True)
    max_size = n - 1 if max_size is None else int(max_size)
    check_positive(min_size, "min_size", integer=True)
    if not 1 <= min_size <= max_size <= n:
        raise InvalidInputError(
            f"need 1 <= `min_size` <= `max_size` <= {n}; got {min_size} and {max_size}."
        )
    if factor is None:
        factor = shifted_factor(L, delta=delta)
    check_on_nonconvergence(on_nonconvergence)
    with single_thread_blas():
        res = _doi(L, U, X, eps_low, eps_high, zeta, int(t_max), int(min_size), max_size, factor)
    return report_nonconvergence(res, on_nonconvergence, "Dynamic orthogonal iteration")


def _doi(L, U, X, eps_low, eps_high, zeta, t_max, min_size, max_size, factor) -> DOIResult:
    """Core of :func:`dynamic_orthogonal_iteration` (no validation)."""
    if X.ndim == 1:
        X = X[:, None]
    n = U.shape[0]
    if U.shape[1] > max_size:
        U = U[:, :max_size]
    Xc = X - X.mean(axis=0)
    scale = float(np.linalg.norm(Xc))
    if scale == 0.0:
        scale = max(float(np.linalg.norm(X)), 1.0)

    last = 0  # +1 after a column was added, -1 after one was dropped
    prev = None  # evaluated state before the last drop
    state = None
    converged = False
    t = 0
    for t in range(1, t_max + 1):  # noqa: B007
        Q = _onorm(_apply_T(factor, U, zeta))
        theta, U, _ = _rayleigh_ritz(L, Q)
        R, rho = _relative_residual(X, U, scale)
        state = (theta, U, rho)
        k = U.shape[1]
        if rho > eps_high:
            if last == -1:
                state = prev  # dropping a column overshot the band: keep the larger subspace
                converged = True
                break
            if k >= max_size:
                break  # cannot grow any more: not converged
            u, sv, _ = np.linalg.svd(R, full_matrices=False)
            r = u[:, 0] if sv[0] > 0 else np.eye(n)[:, k % n]
            U = np.column_stack([U, r])
            last = 1
        elif rho < eps_low:
            if last == 1 or k <= min_size:
                converged = True  # one more column jumped over the band, or at the minimum size
                break
            prev = state
            U = U[:, : k - 1]
            last = -1
        else:
            converged = True
            break
    theta, U, rho = state
    return DOIResult(theta, fix_signs(U), t, converged, float(rho))


def _n_keep(n_keep, size: int) -> int:
    if isinstance(n_keep, bool):
        raise InvalidInputError(
            f"`n_keep` must be a count >= 1 or a fraction in (0, 1]; got {n_keep!r}."
        )
    if isinstance(n_keep, (int, np.integer)):
        if n_keep < 1:
            raise InvalidInputError(f"`n_keep` must be >= 1 as a count; got {n_keep}.")
        return int(min(n_keep, size))
    if isinstance(n_keep, (float, np.floating)):
        if not 0.0 < n_keep <= 1.0:
            raise InvalidInputError(
                f"`n_keep` must be a fraction in (0, 1] or a count >= 1; got {n_keep!r}."
            )
        return max(1, int(round(float(n_keep) * size)))
    raise InvalidInputError(f"`n_keep` must be an int or a float; got {type(n_keep).__name__}.")


def _dense_lowest(L: sp.spmatrix, k: int):
    """The ``k`` lowest eigenpairs by LAPACK (docs/decisions.md#spectral-dense-lowest)."""
    A = L.toarray()
    n = A.shape[0]
    if 4 * k < n:
        w, U = sla.eigh(A, subset_by_index=[0, k - 1], driver="evr", check_finite=False)
    else:
        w, U = sla.eigh(A, driver="evd", check_finite=False)
        w, U = w[:k], U[:, :k]
    return w, U


def _random_basis(gen: np.random.Generator, n: int, k: int) -> np.ndarray:
    return _onorm(gen.standard_normal((n, k)))


def _carry_over(U: np.ndarray, n: int, gen: np.random.Generator) -> np.ndarray:
    """Previous submesh's subspace as a start for a submesh with ``n`` vertices (rows cut or padded)."""
    if U.shape[0] == n:
        return U
    if U.shape[0] > n:
        return _onorm(U[:n].copy())
    pad = gen.standard_normal((n - U.shape[0], U.shape[1])) / np.sqrt(n)
    return _onorm(np.vstack([U, pad]))


def _check_band(eps_low, eps_high) -> None:
    for name, v in (("eps_low", eps_low), ("eps_high", eps_high)):
        check_positive(v, name, allow_zero=True)
    if not eps_low < eps_high:
        raise InvalidInputError(
            f"`eps_low` must be smaller than `eps_high`; got {eps_low!r} >= {eps_high!r}."
        )


def _check_iteration(opts) -> None:
    """Validate the OI / DOI fields shared by :class:`SubmeshOptions` and ``LowpassOptions``."""
    if opts.delta is not None:
        check_positive(opts.delta, "delta")
    object.__setattr__(opts, "zeta", _check_zeta(opts.zeta))
    check_positive(opts.n_iter, "n_iter", integer=True)
    object.__setattr__(opts, "n_iter", int(opts.n_iter))
    if opts.tol is not None:
        check_positive(opts.tol, "tol", allow_zero=True)
    _check_band(opts.eps_low, opts.eps_high)
    check_positive(opts.t_max, "t_max", integer=True)


@dataclass(frozen=True)
class SubmeshOptions:
    """Options of :func:`submesh_eigenbases`: ``delta``, ``zeta``, ``n_iter``, ``tol`` of
    :func:`orthogonal_iteration`; ``eps_low``, ``eps_high``, ``t_max`` of DOI; ``normalized``;
    ``warm_start=False`` (random starts); ``ritz=False`` (Algorithm 6 without Rayleigh-Ritz: the same
    low-pass, unordered columns, NaN eigenvalues, faster).
    """

    delta: float | None = None
    zeta: int = 4
    n_iter: int = 1
    tol: float | None = None
    eps_low: float = DOI_EPS_LOW
    eps_high: float = DOI_EPS_HIGH
    t_max: int = 100
    normalized: bool = False
    warm_start: bool = True
    ritz: bool = True

    def __post_init__(self) -> None:
        _check_iteration(self)


def submesh_eigenbases(
    C,
    subs: Submeshes,
    n_keep: int | float,
    *,
    method: str = "oi",
    laplacian: str = "binary",
    signal=None,
    options: SubmeshOptions | None = None,
    rng=None,
    info: list | None = None,
    **legacy,
) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Low-frequency eigenbases of every submesh Laplacian, in submesh order (Algorithms 6-7).

    Yields ``(i, eigenvalues (k_i,), eigenvectors (n_i, k_i))``, rows following ``subs.parts[i]``:
    dense LAPACK per submesh (``"exact"``), OI from the previous subspace after an exact first
    submesh (``"oi"``, Eq. 4.7), or Algorithm 7 on ``signal`` (``"doi"``).

    Parameters
    ----------
    C, subs : sparse (n, n), Submeshes
        Adjacency of the whole graph and its :func:`overlapped_submeshes`.
    n_keep : int or float
        A count, or a fraction in (0, 1] of each submesh's size.
    method, laplacian, signal
        Solver; ``L = D - C`` on the pattern (``"binary"``) or the values of ``C``; the DOI signal.
    options, rng, info
        :class:`SubmeshOptions` (old keywords warn), random starts; ``info`` is deprecated
        (:func:`submesh_eigenbases_result` returns the per-submesh results).
    """
    if info is not None:
        deprecated_flag("submesh_eigenbases", "info", "submesh_eigenbases_result() (its `info`)")
    return _submesh_stream(C, subs, n_keep, method, laplacian, signal, options, rng, info, legacy)


@dataclass(frozen=True, eq=False)
class SubmeshBases:
    """Result of :func:`submesh_eigenbases_result`, per submesh in order: ``eigenvalues``
    (k_i,), ``eigenvectors`` (n_i, k_i) and ``info`` (:class:`OIResult` / :class:`DOIResult`).
    """

    eigenvalues: tuple
    eigenvectors: tuple
    info: tuple


def submesh_eigenbases_result(
    C,
    subs: Submeshes,
    n_keep: int | float,
    *,
    method: str = "oi",
    laplacian: str = "binary",
    signal=None,
    options: SubmeshOptions | None = None,
    rng=None,
    **legacy,
) -> SubmeshBases:
    """All bases of :func:`submesh_eigenbases` at once, with one result per submesh."""
    info: list = []
    args = (C, subs, n_keep, method, laplacian, signal, options, rng)
    out = list(_submesh_stream(*args, info, legacy))
    return SubmeshBases(tuple(w for _, w, _ in out), tuple(U for *_, U in out), tuple(info))


def _submesh_stream(C, subs, n_keep, method, laplacian, signal, options, rng, info, legacy):
    o = options_with_legacy(options, legacy, SubmeshOptions, "submesh_eigenbases")
    check_choice(method, "method", ("oi", "doi", "exact"))
    check_choice(laplacian, "laplacian", ("binary", "weighted"))
    if not isinstance(subs, Submeshes):
        raise InvalidInputError(f"`subs` must be a Submeshes; got {type(subs).__name__}.")
    C = as_adjacency(C, allow_negative=True)
    if C.shape[0] != subs.n_vertices:
        raise InvalidInputError(
            f"`C` has {C.shape[0]} vertices but `subs` was built for {subs.n_vertices}."
        )
    _n_keep(n_keep, max(int(subs.sizes.max()), 1))  # validate early
    if info is not None and not isinstance(info, list):
        raise InvalidInputError(f"`info` must be a list or None; got {type(info).__name__}.")
    X = None
    if method == "doi":
        if signal is None:
            raise InvalidInputError("`signal` is required for method='doi' (Algorithm 7).")
        X = np.asarray(signal, dtype=np.float64)
        if X.ndim not in (1, 2) or X.shape[0] != subs.n_vertices:
            raise InvalidInputError(
                f"`signal` must have {subs.n_vertices} rows; got shape {X.shape}."
            )
        if not np.isfinite(X).all():
            raise InvalidInputError("`signal` contains NaN or inf.")
    gen = as_rng(rng)
    return _eigenbases(
        C,
        subs,
        n_keep,
        method,
        o.delta,
        o.zeta,
        o.n_iter,
        o.tol,
        X,
        o.eps_low,
        o.eps_high,
        o.t_max,
        laplacian,
        o.normalized,
        o.warm_start,
        gen,
        info,
        o.ritz,
    )


class _SubmeshSystems:
    """Builds submesh Laplacians (and their shifted factorisations) from a global adjacency quickly."""

    def __init__(self, C: sp.csr_matrix, binary: bool, normalized: bool, delta) -> None:
        self.indptr = C.indptr.astype(np.int64)
        self.indices = C.indices.astype(np.int64)
        self.data = np.ones(C.nnz) if binary else C.data.astype(np.float64)
        self.gmap = np.full(C.shape[0], -1, dtype=np.int64)
        self.normalized = normalized
        self.delta = delta

    def laplacian(self, part: np.ndarray, *, matrix: bool = True):
        """``(L, local)``: submesh Laplacian (None if not ``matrix``) and CSR of its adjacency."""
        ptr, ind, val = _nb_induced(self.indptr, self.indices, self.data, part, self.gmap)
        m = part.size
        if not matrix and not self.normalized and not (val.size and val.min() < 0):
            return None, (ptr, ind, val)
        if self.normalized:
            from ..graph import laplacian_from_adjacency

            A = sp.csr_matrix((val, ind, ptr), shape=(m, m))
            return laplacian_from_adjacency(A, normalized=True).tocsr(), None
        Lp, Li, Lx = _nb_permuted_laplacian(ptr, ind, val, np.arange(m, dtype=np.int64), 0.0)
        return sp.csr_matrix((Lx, Li, Lp), shape=(m, m)), (ptr, ind, val)

    def factor(self, L, local) -> ShiftedFactor:
        if local is None or (local[2].size and local[2].min() < 0):
            return ShiftedFactor(L, delta=self.delta)
        ptr, ind, val = local
        m = ptr.size - 1
        if L is not None:
            delta = _delta(L, self.delta)
        elif self.delta is None:  # mean diagonal of D - C = mean weighted degree
            d = float(val.sum()) / m if m else 0.0
            delta = DELTA_REL * d if d > 0 else DELTA_REL
        else:
            delta = float(self.delta)
        A = sp.csr_matrix((val, ind, ptr), shape=(m, m))
        perm = reverse_cuthill_mckee(A, symmetric_mode=True).astype(np.int64)
        Ap, Ai, Ax = _nb_permuted_laplacian(ptr, ind, val, perm, delta)
        return ShiftedFactor._from_permuted(perm, Ap, Ai, Ax, delta)


def _eigenbases(
    C,
    subs,
    n_keep,
    method,
    delta,
    zeta,
    n_iter,
    tol,
    X,
    eps_low,
    eps_high,
    t_max,
    laplacian,
    normalized,
    warm_start,
    gen,
    info,
    ritz=True,
):
    systems = _SubmeshSystems(C, laplacian == "binary", normalized, delta)
    U_prev = None

    # results are collected when the caller asks for them or convergence must be checked
    track = info if info is not None else ([] if (method == "doi" or tol is not None) else None)

    def step(i, U_prev):
        part = subs.parts[i]
        ni = part.size
        k = _n_keep(n_keep, ni)
        direct = method == "exact" or (U_prev is None and warm_start) or ni <= 2
        # plain Algorithm 6 (no Ritz step, no residual): the Laplacian matrix itself is not needed
        bare = method == "oi" and not direct and not ritz and tol is None and info is None
        L, local = systems.laplacian(part, matrix=not bare)
        if direct:
            if method == "doi":
                w, U = _dense_lowest(L, k)
                # one column per step from n_keep: allow enough steps to reach any band
                res = _doi(
                    L,
                    fix_signs(U),
                    X[part],
                    eps_low,
                    eps_high,
                    zeta,
                    max(t_max, ni),
                    1,
                    ni - 1,
                    systems.factor(L, local),
                )
                w, U = res.eigenvalues, res.eigenvectors
                if track is not None:
                    track.append(res)
                return w, U
            w, U = _dense_lowest(L, k)
            U = fix_signs(U)
            if track is not None:
                track.append(OIResult(w, U, 0, True, 0.0))
            return w, U
        else:
            if warm_start:
                U0 = _carry_over(U_prev, ni, gen)
                if method == "oi" and U0.shape[1] != k:
                    U0 = (
                        U0[:, :k]
                        if U0.shape[1] > k
                        else np.column_stack([U0, gen.standard_normal((ni, k - U0.shape[1]))])
                    )
            else:
                U0 = _random_basis(gen, ni, k)
            factor = systems.factor(L, local)
            if method == "oi":
                w, U, it, r = _oi(L, U0, factor, zeta, n_iter, tol, info is not None, ritz)
                res = OIResult(w, U, it, bool(tol is not None and r <= tol), float(r))
            else:
                res = _doi(L, U0, X[part], eps_low, eps_high, zeta, t_max, 1, ni - 1, factor)
            w, U = res.eigenvalues, res.eigenvectors
            if track is not None:
                track.append(res)
        return w, U

    failed = []
    n_info = len(track) if track is not None else 0
    for i in progress(range(len(subs.parts)), desc=f"submeshes ({method})", total=len(subs.parts)):
        # many small dense products: multithreaded BLAS only adds synchronisation cost
        with single_thread_blas():
            w, U = step(i, U_prev)
        if track is not None and len(track) > n_info:
            r = track[-1]
            n_info = len(track)
            if (method == "doi" or tol is not None) and not r.converged:
                failed.append(i)
            if info is None:  # only the last result was needed
                track.clear()
                n_info = 0
        U_prev = U
        yield i, w, U
    if failed:
        warnings.warn(
            f"{len(failed)} of {len(subs.parts)} submeshes did not converge ({method}; first: "
            f"{failed[0]}); increase `t_max`/`n_iter` or widen the band.",
            ConvergenceWarning,
            stacklevel=2,
        )
