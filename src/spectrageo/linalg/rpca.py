"""Robust PCA ``M = E + S (+ G)``: inexact ALM for principal component pursuit (Eq. 4.18-4.23)
and GoDec's bilateral factorisation (Eq. 5.29-5.35), row-chunked for tall matrices.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_rng, check_choice, check_positive, options_with_legacy
from . import _kernels as _k
from ._chunked import CoreAccumulator, positive_part
from ._common import (
    CHUNK_BYTES,
    FULL_SVD_MAX,
    as_matrix,
    blas_threads,
    check_on_nonconvergence,
    check_tol_iter,
    estimate_rank,
    hard_threshold,
    report_nonconvergence,
    row_chunks,
    soft_threshold,
    top_svd,
)

__all__ = ["RPCASolverOptions", "RPCAResult", "rpca"]

_METHODS = ("ialm", "godec")
_BACKENDS = ("auto", "chunked", "dense")
#: ``backend="auto"`` uses the chunked engine when the short side of ``M`` is at most this.
CHUNKED_MAX_COLS = 256


@dataclass(frozen=True)
class RPCAResult:
    """Result of :func:`rpca`: ``low_rank`` ``E`` and ``sparse`` ``S`` (shaped like ``M``), ``noise``
    ``G = M - E - S`` (Eq. 4.23, with ``noise_aware``), ``n_iter``, ``converged``, ``rank``, ``method``
    and ``residual``, the stopping quantity: ``||M - E - S||_F / ||M||_F`` for PCP, the relative
    change of ``(E, S)`` for GoDec and the noise-aware model.
    """

    low_rank: np.ndarray = field(repr=False)
    sparse: np.ndarray = field(repr=False)
    n_iter: int
    converged: bool
    residual: float
    noise: np.ndarray | None = field(default=None, repr=False)
    rank: int = 0
    method: str = "ialm"


@dataclass(frozen=True)
class RPCASolverOptions:
    """Engine options of :func:`rpca`, validated on construction.

    ``noise_level``: deviation of ``G`` (estimated when None). ``mu``: the IALM penalty schedule
    (``"continuation"``, Lin, Chen & Ma 2010; ``"thesis"``, the fixed ``m n / (4 ||M||_1)`` of
    Eq. 4.22; or ``mu_0``), grown by ``rho >= 1`` (default 1.5, 1 with ``"thesis"``); see
    docs/decisions.md#linalg-rpca-mu. ``threshold``: GoDec's ``"soft"`` (Eq. 5.32) or ``"hard"``
    operator. ``backend``: ``"chunked"`` (rows streamed, SVDs from the Gram matrix or a TSQR),
    ``"dense"`` or ``"auto"`` (chunked up to :data:`CHUNKED_MAX_COLS` columns). ``dtype``: working
    precision of the chunked engine (float32 needs ``tol >= 1e-6``).
    """

    noise_level: float | None = None
    mu: float | str = "continuation"
    rho: float | None = None
    threshold: str = "soft"
    backend: str = "auto"
    dtype: Any = None

    def __post_init__(self) -> None:
        check_choice(self.backend, "backend", _BACKENDS)
        check_choice(self.threshold, "threshold", ("soft", "hard"))
        if self.noise_level is not None:
            check_positive(self.noise_level, "noise_level")
        if isinstance(self.mu, str):
            check_choice(self.mu, "mu", ("continuation", "thesis"))
        else:
            check_positive(self.mu, "mu")
        if self.rho is not None:
            check_positive(self.rho, "rho")
            if self.rho < 1:
                raise InvalidInputError(f"`rho` must be >= 1; got {self.rho!r}.")
        if self.dtype is not None:
            try:
                dt = np.dtype(self.dtype)
            except TypeError as exc:
                raise InvalidInputError(
                    f"`dtype` must be 'float32' or 'float64'; got {self.dtype!r}."
                ) from exc
            if dt not in (np.float32, np.float64):
                raise InvalidInputError(
                    f"`dtype` must be 'float32' or 'float64'; got {self.dtype!r}."
                )


def rpca(
    M: Any,
    *,
    method: str = "ialm",
    rank: int | None = None,
    lam: float | None = None,
    tol: float = 1e-7,
    max_iter: int | None = None,
    noise_aware: bool = False,
    on_nonconvergence: str = "warn",
    options: RPCASolverOptions | None = None,
    rng: Any = None,
    **legacy: Any,
) -> RPCAResult:
    """Decompose ``M`` into a low-rank ``E`` and a sparse ``S`` (Eq. 4.16), optionally plus noise.

    ``"ialm"`` solves ``min ||E||_* + lam ||S||_1  s.t.  E + S = M`` (Eq. 4.18) with the augmented
    Lagrangian updates of Eq. 4.19-4.22 (``Y <- Y + mu (M - E - S)``; Eq. 4.22 prints ``M - E + S``)
    until ``||M - E - S||_F <= tol ||M||_F``; ``lam`` defaults to ``1 / sqrt(max(m, n))``.
    ``noise_aware`` fits ``M = E + S + G`` (Eq. 4.23) as stable PCP. ``"godec"`` iterates the QR
    updates of Eq. 5.33-5.35 with ``lam`` defaulting to ``3 * 1.4826 * median|M - M_r|`` and ``rank``
    to the Gavish-Donoho estimate.

    Parameters
    ----------
    M : (m, n) array_like
        Finite data; float32 stays float32 unless ``options.dtype`` says otherwise.
    method, rank, lam : {"ialm", "godec"}, int, float
        Solver; target rank (GoDec) or rank cap (IALM); ``||S||_1`` weight or GoDec threshold.
    tol, max_iter, noise_aware
        Stopping tolerance; default 1000 iterations for PCP, 500 otherwise; fit ``G`` too.
    on_nonconvergence : {"warn", "raise", "ignore"}
        Policy when ``max_iter`` comes first (:class:`ConvergenceError` carries ``partial``).
    options, rng : RPCASolverOptions, seed or Generator
        Engine options (old keywords warn); GoDec's random start and row sampling.

    Returns
    -------
    RPCAResult

    Raises
    ------
    InvalidInputError
        Bad shape or values, unknown choices, ``rank`` out of range.
    """
    o = options_with_legacy(options, legacy, RPCASolverOptions, "rpca")
    mu, backend, dtype = o.mu, o.backend, o.dtype
    check_choice(method, "method", _METHODS)
    check_on_nonconvergence(on_nonconvergence)
    A0 = as_matrix(M, "M")
    m0, n0 = A0.shape
    if max_iter is None:
        max_iter = 1000 if (method == "ialm" and not noise_aware) else 500
    check_tol_iter(tol, max_iter)
    if rank is not None:
        if isinstance(rank, bool) or not isinstance(rank, (int, np.integer)):
            raise InvalidInputError(f"`rank` must be an integer; got {rank!r}.")
        if not 1 <= rank <= min(m0, n0):
            raise InvalidInputError(
                f"`rank` must be between 1 and min(m, n) = {min(m0, n0)}; got {rank}."
            )
        rank = int(rank)
    if lam is not None:
        check_positive(lam, "lam")
    rho = o.rho if o.rho is not None else (1.0 if mu == "thesis" else 1.5)
    if dtype is None:
        dt = np.dtype(np.float32) if A0.dtype == np.float32 else np.dtype(np.float64)
    else:
        dt = np.dtype(dtype)
    gen = as_rng(rng)

    # Work on the tall orientation (rows >= columns); PCP and GoDec are transpose-symmetric.
    transposed = m0 < n0
    A = A0.T if transposed else A0
    if backend == "auto":
        backend = "chunked" if A.shape[1] <= CHUNKED_MAX_COLS else "dense"
    ctx = _Context(A, dt, backend)

    with blas_threads(A.shape[1], chunked=backend == "chunked"):
        if method == "ialm" and not noise_aware:
            res = _ialm(ctx, lam=lam, mu=mu, rho=rho, rank=rank, tol=tol, max_iter=max_iter)
            what = "RPCA (inexact ALM)"
        elif method == "ialm":
            res = _stable_pcp(
                ctx, lam=lam, sigma=o.noise_level, rank=rank, tol=tol, max_iter=max_iter
            )
            what = "RPCA (noise-aware, stable PCP)"
        else:
            res = _godec(
                ctx,
                rank=rank,
                lam=lam,
                threshold=o.threshold,
                tol=tol,
                max_iter=max_iter,
                rng=gen,
                want_noise=noise_aware,
            )
            what = "RPCA (GoDec bilateral factorisation)"
    E, S, G, n_iter, converged, residual, r_out = res
    if transposed:
        E, S = E.T, S.T
        G = None if G is None else G.T
    result = RPCAResult(
        low_rank=E,
        sparse=S,
        n_iter=n_iter,
        converged=converged,
        residual=float(residual),
        noise=G,
        rank=int(r_out),
        method=method,
    )
    return report_nonconvergence(result, on_nonconvergence, what)


# --------------------------------------------------------------------------------------------
# shared machinery


class _Context:
    """The tall input ``A`` (m >= n), working dtype, backend and lazily computed norms."""

    def __init__(self, A: np.ndarray, dt: np.dtype, backend: str) -> None:
        self.A = A
        self.m, self.n = A.shape
        self.dt = dt
        self.backend = backend
        self.core_mode = "gram"
        self.chunk_rows = max(256, CHUNK_BYTES // (self.n * 8))
        self._fro: float | None = None
        self._l1: float | None = None
        self._core0: tuple[np.ndarray, np.ndarray] | None = None

    def slices(self):
        return row_chunks(self.m, self.n, 8, self.chunk_rows)

    def buffer(self, dtype=None) -> np.ndarray:
        """A flat scratch buffer for one chunk (use :func:`_view`)."""
        return np.empty(self.chunk_rows * self.n, dtype=self.dt if dtype is None else dtype)

    def norms(self) -> tuple[float, float]:
        if self._fro is None:
            fro2 = l1 = 0.0
            for sl in self.slices():
                c = np.asarray(self.A[sl], dtype=np.float64)
                fro2 += float(np.einsum("ij,ij->", c, c))
                l1 += float(np.abs(c).sum())
            self._fro, self._l1 = float(np.sqrt(fro2)), l1
        return self._fro, self._l1

    def core_of_input(self) -> tuple[np.ndarray, np.ndarray]:
        """``(s, V)`` of ``A`` itself (Gram matrix, or TSQR when that is too ill-conditioned)."""
        if self._core0 is None:
            acc = CoreAccumulator(self.n, "gram")
            for sl in self.slices():
                acc.add(self.A[sl])
            core = acc.finish()
            if core is None:
                core = self.tsqr(lambda sl, out: out.__setitem__(slice(None), self.A[sl]))
            self._core0 = core
        return self._core0

    def tsqr(self, fill: Callable) -> tuple[np.ndarray, np.ndarray]:
        """TSQR core of the rows that ``fill(sl, out)`` writes (switches the solve to TSQR)."""
        self.core_mode = "qr"
        acc = CoreAccumulator(self.n, "qr")
        buf = self.buffer(np.float64)
        for sl in self.slices():
            X = _view(buf, sl.stop - sl.start, self.n)
            fill(sl, X)
            acc.add(X)
        return acc.finish()

    def accumulator(self, s: np.ndarray, V: np.ndarray) -> CoreAccumulator:
        if self.core_mode == "qr":
            return CoreAccumulator(self.n, "qr")
        return CoreAccumulator(self.n, "gram", precond=(s, V))

    def singular_values(self) -> np.ndarray:
        if self.backend == "chunked":
            return self.core_of_input()[0]
        return np.linalg.svd(self.A, compute_uv=False)


def _view(buf: np.ndarray, rows: int, cols: int) -> np.ndarray:
    return buf[: rows * cols].reshape(rows, cols)


def _svt_factors(s: np.ndarray, V: np.ndarray, tau: float, m: int, rank: int | None):
    """Factors ``(Pa, Pb)`` with ``X @ Pa @ Pb = D_tau(X)`` given the core ``(s, V)`` of ``X``."""
    p = positive_part(s, m)
    shr = np.maximum(s[:p] - tau, 0.0)
    k = int(np.count_nonzero(shr > 0))
    if rank is not None:
        k = min(k, rank)
    Vk = V[:, :k]
    return Vk * (shr[:k] / s[:k]), Vk.T.copy(), k


def _dense_svt(X: np.ndarray, tau: float, sv: int, rank: int | None, rng: np.random.Generator):
    """Exact singular value thresholding ``D_tau(X)`` from a predicted count ``sv`` (enlarged
    while every computed value exceeds ``tau``); returns ``(E, svp, k)``.
    """
    p = min(X.shape)
    if p <= FULL_SVD_MAX:
        sv = p
    while True:
        U, s, Vt = top_svd(X, sv, rng)
        svp = int(np.count_nonzero(s > tau))
        if svp < s.size or sv >= p or (rank is not None and svp >= rank):
            break
        sv = min(p, sv + max(1, round(0.05 * p)))
    k = svp if rank is None else min(svp, rank)
    E = (U[:, :k] * (s[:k] - tau)) @ Vt[:k]
    return E, svp, k


def _next_sv(svp: int, sv: int, n: int) -> int:
    """Predicted number of singular values for the next iteration (Lin, Chen & Ma, 2010)."""
    if svp < sv:
        return min(svp + 1, n)
    return min(svp + max(1, round(0.05 * n)), n)


# --------------------------------------------------------------------------------------------
# PCP by (inexact) ALM, Eq. 4.19-4.22


def _ialm(ctx: _Context, *, lam, mu, rho, rank, tol, max_iter):
    m, n = ctx.m, ctx.n
    lam = 1.0 / np.sqrt(m) if lam is None else float(lam)
    fro, l1 = ctx.norms()
    if fro == 0:
        Z = np.zeros((m, n), ctx.dt)
        return Z, Z.copy(), None, 0, True, 0.0, 0
    if mu == "thesis":
        mu0 = m * n / (4.0 * l1)
    elif mu == "continuation":
        s_max = ctx.core_of_input()[0][0] if ctx.backend == "chunked" else _spectral_norm(ctx.A)
        mu0 = 1.25 / s_max
    else:
        mu0 = float(mu)
    mu_max = mu0 * 1e7
    if ctx.backend == "chunked":
        return _ialm_chunked(ctx, lam, mu0, rho, mu_max, rank, tol, max_iter, fro)
    return _ialm_dense(ctx, lam, mu0, rho, mu_max, rank, tol, max_iter, fro)


def _spectral_norm(A: np.ndarray) -> float:
    if min(A.shape) <= FULL_SVD_MAX:
        return float(np.linalg.norm(A, 2))
    from scipy.sparse.linalg import svds

    return float(svds(A, k=1, return_singular_vectors=False, rng=0)[0])


def _ialm_dense(ctx, lam, mu, rho, mu_max, rank, tol, max_iter, fro):
    A = np.asarray(ctx.A, dtype=np.float64)
    S = np.zeros_like(A)
    Y = np.zeros_like(A)
    rng = np.random.default_rng(0)
    sv = min(10, min(A.shape))
    n_short = min(A.shape)
    converged, residual, k = False, np.inf, 0
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (it is the iteration count returned)
        E, svp, k = _dense_svt(A - S + Y / mu, 1.0 / mu, sv, rank, rng)
        sv = _next_sv(svp, sv, n_short)
        S = soft_threshold(A - E + Y / mu, lam / mu)
        Z = A - E - S
        residual = float(np.linalg.norm(Z)) / fro
        Y += mu * Z
        mu = min(mu * rho, mu_max)
        if residual <= tol:
            converged = True
            break
    return E, S, None, it, converged, residual, k


def _ialm_chunked(ctx, lam, mu, rho, mu_max, rank, tol, max_iter, fro):
    """Chunked IALM storing ``R = M - E + Y/mu``: ``S = Q_{lam/mu}(R)`` and
    ``Y = mu clip(R, +-lam/mu)`` share one array (Eq. 4.22); one pass per iteration.
    """
    m, n, dt = ctx.m, ctx.n, ctx.dt
    R = np.zeros((m, n), dt)  # becomes S at the end
    E = np.zeros((m, n), dt)
    X, Ymu, T1, T2 = (ctx.buffer() for _ in range(4))
    Xn = ctx.buffer(np.float64)  # the core is accumulated in float64
    s, V = ctx.core_of_input()
    mu_prev = mu  # R = 0 encodes S = Y = 0 whatever mu_prev is
    converged, residual, k = False, np.inf, 0
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (it is the iteration count returned)
        Pa, Pb, k = _svt_factors(s, V, 1.0 / mu, m, rank)
        Pa, Pb = Pa.astype(dt), Pb.astype(dt)
        mu_next = min(mu * rho, mu_max)
        acc = ctx.accumulator(s, V)
        res2 = 0.0
        for sl in ctx.slices():
            rows = sl.stop - sl.start
            Mc, Rc = ctx.A[sl], R[sl]
            Xc, Yc, Xnc = _view(X, rows, n), _view(Ymu, rows, n), _view(Xn, rows, n)
            _k.ialm_prepare(Mc, Rc, lam / mu_prev, mu_prev / mu, Xc, Yc)
            Ec = _lowrank_apply(Xc, Pa, Pb, T1, T2, rows)
            res2 += _k.ialm_update(Mc, Ec, Yc, lam / mu, mu / mu_next, Rc, E[sl], Xnc)
            acc.add(Xnc)
        residual = np.sqrt(res2) / fro
        mu_prev, mu = mu, mu_next
        if residual <= tol:
            converged = True
            break
        core = acc.finish()
        if core is None:
            t, f = lam / mu_prev, mu_prev / mu
            core = ctx.tsqr(lambda sl, out, t=t, f=f: _k.ialm_next_x(ctx.A[sl], R[sl], t, f, out))
        s, V = core
    t = lam / mu_prev
    for sl in ctx.slices():
        _k.soft_inplace(R[sl], t)
    return E, R, None, it, converged, residual, k


def _lowrank_apply(Xc, Pa, Pb, T1, T2, rows):
    """``(Xc @ Pa) @ Pb`` into scratch buffers."""
    k = Pa.shape[1]
    if k == 0:
        out = _view(T2, rows, Pb.shape[1])
        out[...] = 0
        return out
    a = np.matmul(Xc, Pa, out=_view(T1, rows, k))
    return np.matmul(a, Pb, out=_view(T2, rows, Pb.shape[1]))


# --------------------------------------------------------------------------------------------
# alternating block minimisation: GoDec (Eq. 5.35) and stable PCP (Eq. 4.23)


def _alternating_chunked(
    ctx,
    e_step: Callable,
    get_tau: Callable,
    hard: bool,
    tol,
    max_iter,
    want_noise,
    before_pass: Callable | None = None,
):
    """Chunked ``E = X Pa Pb`` / ``S = threshold(M - E, tau)`` iterations with ``X = M - S``,
    ``e_step(s, V) -> (Pa, Pb, rank)``; stops at ``||(dE, dS)|| <= tol ||M||_F``.
    """
    m, n, dt = ctx.m, ctx.n, ctx.dt
    fro, _ = ctx.norms()
    S = np.zeros((m, n), dt)
    E = np.zeros((m, n), dt)
    X, T1, T2 = (ctx.buffer() for _ in range(3))
    Xn = ctx.buffer(np.float64)  # the core is accumulated in float64
    s, V = ctx.core_of_input()
    converged, change, k = False, np.inf, 0
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (it is the iteration count returned)
        Pa, Pb, k = e_step(s, V)
        if before_pass is not None:
            before_pass(it, Pa, Pb)
        tau = float(get_tau())
        Pa, Pb = Pa.astype(dt), Pb.astype(dt)
        acc = ctx.accumulator(s, V)
        d2 = 0.0
        for sl in ctx.slices():
            rows = sl.stop - sl.start
            Mc = ctx.A[sl]
            Xc, Xnc = _view(X, rows, n), _view(Xn, rows, n)
            _k.subtract_into(Mc, S[sl], Xc)
            Ec = _lowrank_apply(Xc, Pa, Pb, T1, T2, rows)
            d2 += _k.alt_update(Mc, Ec, E[sl], S[sl], Xnc, tau, hard)
            acc.add(Xnc)
        change = np.sqrt(d2) / fro if fro > 0 else 0.0
        if change <= tol:
            converged = True
            break
        core = acc.finish()
        if core is None:
            core = ctx.tsqr(lambda sl, out: _k.subtract_into(ctx.A[sl], S[sl], out))
        s, V = core
    G = None
    if want_noise:
        G = np.empty((m, n), dt)
        for sl in ctx.slices():
            Gc = np.asarray(ctx.A[sl], dtype=dt) - E[sl]
            Gc -= S[sl]
            G[sl] = Gc
    return E, S, G, it, converged, change, k


def _stable_pcp(ctx, *, lam, sigma, rank, tol, max_iter):
    m, n = ctx.m, ctx.n
    lam = 1.0 / np.sqrt(m) if lam is None else float(lam)
    if sigma is None:
        sigma = _robust_noise_sigma(ctx)
    nu = (np.sqrt(m) + np.sqrt(n)) * float(sigma)
    if nu <= 0:
        raise InvalidInputError("the estimated noise level is 0; pass `noise_level` > 0.")
    tau_s = lam * nu
    if ctx.backend == "chunked":
        return _alternating_chunked(
            ctx,
            lambda s, V: _svt_factors(s, V, nu, m, rank),
            lambda: tau_s,
            False,
            tol,
            max_iter,
            True,
        )
    A = np.asarray(ctx.A, dtype=np.float64)
    fro = float(np.linalg.norm(A))
    rng = np.random.default_rng(0)
    S = np.zeros_like(A)
    E = np.zeros_like(A)
    sv = min(10, n)
    converged, change, k, it = False, np.inf, 0, 0
    for it in range(1, max_iter + 1):  # noqa: B007 (it is the iteration count returned)
        E_new, svp, k = _dense_svt(A - S, nu, sv, rank, rng)
        sv = _next_sv(svp, sv, n)
        S_new = soft_threshold(A - E_new, tau_s)
        change = np.sqrt(np.linalg.norm(E_new - E) ** 2 + np.linalg.norm(S_new - S) ** 2) / fro
        E, S = E_new, S_new
        if change <= tol:
            converged = True
            break
    return E, S, A - E - S, it, converged, change, k


def _robust_noise_sigma(ctx: _Context, max_rows: int = 200_000) -> float:
    """Entry deviation of ``G``: MAD of ``M - E_0,r`` after a loose PCP
    (docs/decisions.md#linalg-rpca-mu).
    """
    m, n = ctx.m, ctx.n
    fro, _ = ctx.norms()
    if fro == 0:
        return 0.0
    s_max = ctx.core_of_input()[0][0] if ctx.backend == "chunked" else _spectral_norm(ctx.A)
    mu0 = 1.25 / s_max
    args = (ctx, 1.0 / np.sqrt(m), mu0, 1.5, mu0 * 1e7, None, 1e-4, 200, fro)
    if ctx.backend == "chunked":
        E0 = _ialm_chunked(*args)[0]
        acc = CoreAccumulator(n, "qr")
        for sl in ctx.slices():
            acc.add(E0[sl])
        s, V = acc.finish()
    else:
        E0 = _ialm_dense(*args)[0]
        _, s, Vt = np.linalg.svd(E0, full_matrices=False)
        V = Vt.T
    p = positive_part(s, m)
    if p <= 1:
        r = p
    else:
        h = max(1, p // 2)
        r = int(np.argmax(s[:h] / s[1 : h + 1])) + 1
    rows = np.arange(m) if m <= max_rows else np.linspace(0, m - 1, max_rows).astype(np.int64)
    Es = np.asarray(E0[rows], dtype=np.float64)
    Vr = V[:, :r]
    R = np.asarray(ctx.A[rows], dtype=np.float64) - (Es @ Vr) @ Vr.T
    return 1.4826 * float(np.median(np.abs(R - np.median(R))))


def _godec(ctx, *, rank, lam, threshold, tol, max_iter, rng, want_noise):
    m, n = ctx.m, ctx.n
    if rank is None:
        rank = estimate_rank(ctx.singular_values(), m, n)
    r = rank
    thresh = soft_threshold if threshold == "soft" else hard_threshold
    T0 = rng.standard_normal((r, n))  # bilateral random projection start
    state = {"T": T0, "lam": None if lam is None else float(lam)}

    if ctx.backend == "chunked":
        s0, V0 = ctx.core_of_input()

        def e_step(s, V):
            # Eq. 5.33-5.35 in the coordinates of X = W C, C = diag(s) V^T, W orthonormal:
            # qr(X T^T) = W qr(C T^T);  Q = W Qs;  T <- Qs^T C;  W T = X V diag(1/s) Qs T.
            p = positive_part(s, m)
            C = s[:p, None] * V[:, :p].T
            Qs, _ = np.linalg.qr(C @ state["T"].T)
            T = Qs.T @ C
            state["T"] = T
            Pa = V[:, :p] @ (Qs / s[:p, None])
            return Pa, T, Qs.shape[1]

        def before_pass(it, Pa, Pb):
            if it == 1 and state["lam"] is None:
                # residual of the best rank-r approximation of M on a sample of rows
                idx = np.sort(rng.choice(m, size=min(m, 200_000), replace=False))
                Ms = np.asarray(ctx.A[idx], dtype=np.float64)
                Vr = V0[:, :r]
                state["lam"] = _default_godec_lam(Ms - (Ms @ Vr) @ Vr.T)

        return _alternating_chunked(
            ctx,
            e_step,
            lambda: state["lam"],
            threshold == "hard",
            tol,
            max_iter,
            want_noise,
            before_pass=before_pass,
        )

    # dense: the literal updates of Eq. 5.35
    A = np.asarray(ctx.A, dtype=np.float64)
    fro = float(np.linalg.norm(A))
    if state["lam"] is None:
        U, s, Vt = np.linalg.svd(A, full_matrices=False)
        state["lam"] = _default_godec_lam(A - (U[:, :r] * s[:r]) @ Vt[:r])
    lam_v = state["lam"]
    T = T0
    S = np.zeros_like(A)
    E = np.zeros_like(A)
    converged, change, it = False, np.inf, 0
    for it in range(1, max_iter + 1):  # noqa: B007 (it is the iteration count returned)
        X = A - S
        Q, _ = np.linalg.qr(X @ T.T)  # Eq. 5.33
        T = Q.T @ X  # Eq. 5.35, T update
        E_new = Q @ T  # W T = Q Q^T (M - S), Eq. 5.34
        S_new = thresh(A - E_new, lam_v)
        change = np.sqrt(np.linalg.norm(E_new - E) ** 2 + np.linalg.norm(S_new - S) ** 2) / fro
        E, S = E_new, S_new
        if change <= tol:
            converged = True
            break
    G = A - E - S if want_noise else None
    return E, S, G, it, converged, change, r


def _default_godec_lam(residual: np.ndarray) -> float:
    sigma = 1.4826 * float(np.median(np.abs(residual)))
    if sigma == 0:
        sigma = float(np.abs(residual).max()) * 1e-3 or 1e-12
    return 3.0 * sigma
