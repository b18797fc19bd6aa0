"""Robust principal component analysis: ``M = E + S`` (low-rank + sparse), optionally ``+ G`` (noise).

Two solvers, both exposed through :func:`rpca`:

- ``method="ialm"``: principal component pursuit (PCP, Eq. 4.18) by the augmented Lagrange
  multiplier method of Eq. 4.19-4.22; with ``noise_aware=True`` the stable-PCP model of Eq. 4.23.
- ``method="godec"``: the SVD-free bilateral factorisation ``E = W T`` with QR updates
  (Eq. 5.29-5.35, Section 5.1.2), the low-rank + sparse + noise model of GoDec.

Large tall-skinny matrices (e.g. the ``3n x (k+1)`` kNN patch matrix of Eq. 5.98 with ``n`` in the
tens of millions) go through a row-chunked engine that never forms a full SVD and never holds more
than the input plus two working arrays of its size (see :mod:`spectrageo.linalg._chunked`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_rng, check_choice, check_positive
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

__all__ = ["RPCAResult", "rpca"]

_METHODS = ("ialm", "godec")
_BACKENDS = ("auto", "chunked", "dense")
#: ``backend="auto"`` uses the chunked engine when the short side of ``M`` is at most this.
CHUNKED_MAX_COLS = 256


@dataclass(frozen=True)
class RPCAResult:
    """Result of :func:`rpca`.

    Attributes
    ----------
    low_rank : (m, n) ndarray
        The low-rank part ``E``.
    sparse : (m, n) ndarray
        The sparse part ``S``.
    n_iter : int
        Iterations performed.
    converged : bool
        Whether the stopping rule was met before ``max_iter``.
    residual : float
        The quantity the stopping rule compares with ``tol``: ``||M - E - S||_F / ||M||_F`` for
        PCP (``method="ialm"``), the relative change ``||(E, S)_t - (E, S)_{t-1}||_F / ||M||_F``
        between the last two iterates for GoDec and for the noise-aware model.
    noise : (m, n) ndarray or None
        The dense noise part ``G = M - E - S`` of Eq. 4.23 (only with ``noise_aware=True``).
    rank : int
        Rank of ``low_rank`` (singular values kept at the last iteration).
    method : str
        The solver used.
    """

    low_rank: np.ndarray = field(repr=False)
    sparse: np.ndarray = field(repr=False)
    n_iter: int
    converged: bool
    residual: float
    noise: np.ndarray | None = field(default=None, repr=False)
    rank: int = 0
    method: str = "ialm"


def rpca(
    M: Any,
    *,
    method: str = "ialm",
    rank: int | None = None,
    lam: float | None = None,
    tol: float = 1e-7,
    max_iter: int | None = None,
    noise_aware: bool = False,
    noise_level: float | None = None,
    mu: float | str = "continuation",
    rho: float | None = None,
    threshold: str = "soft",
    backend: str = "auto",
    dtype: Any = None,
    on_nonconvergence: str = "warn",
    rng: Any = None,
) -> RPCAResult:
    r"""Decompose ``M`` into a low-rank ``E`` and a sparse ``S`` (Eq. 4.16), optionally plus noise.

    **method="ialm"** solves principal component pursuit (Eq. 4.18)
    ``min ||E||_* + lam ||S||_1  s.t.  E + S = M`` with the augmented Lagrangian of Eq. 4.19 and the
    alternating updates of Eq. 4.22 (singular value thresholding ``D_{1/mu}`` for ``E``, Eq. 4.21;
    shrinkage ``Q_{lam/mu}`` for ``S``, Eq. 4.20; ``Y <- Y + mu (M - E - S)``: Eq. 4.22 prints
    ``M - E + S``, a sign typo). It stops when ``||M - E - S||_F <= tol ||M||_F`` (thesis:
    ``beta = 1e-7``). ``lam`` defaults to ``1 / sqrt(max(m, n))``.

    The penalty ``mu``: the thesis sets ``mu = n^2 / (4 ||M||_1)``, which is the choice
    ``m n / (4 ||M||_1)`` of Candes et al. (2011) for a square ``n x n`` matrix, kept fixed as in
    Eq. 4.22 (``mu="thesis"``; ``m n`` is used for rectangular ``M``). With a fixed ``mu`` the
    iteration recovers planted problems but about twice as slowly (30-36 iterations instead of
    15-17 on 100 x 80 to 300 x 300 matrices of rank 3-10 with 5-10 % gross errors) and does not
    reach ``tol = 1e-7`` within 3000 iterations on a ``6000 x 11`` kNN patch matrix; growing ``mu``
    from that large start breaks recovery (relative error 2.5 on the 200 x 200 case). The default
    ``mu="continuation"`` is the inexact ALM schedule of Lin, Chen & Ma (2010):
    ``mu_0 = 1.25 / ||M||_2``, ``mu <- min(rho mu, 1e7 mu_0)`` with ``rho = 1.5`` (20-40
    iterations, same solution). A number sets ``mu_0`` directly (with ``rho`` default 1.5).
    ``rank``, if given, additionally caps the number of singular values kept by ``D_{1/mu}``.

    **noise_aware=True** with ``"ialm"`` fits ``M = E + S + G`` (Eq. 4.23) as stable PCP in its
    Lagrangian form ``min ||E||_* + lam ||S||_1 + ||M - E - S||_F^2 / (2 nu)`` by exact block
    minimisation (``E = D_nu(M - S)``, ``S = Q_{lam nu}(M - E)``), with
    ``nu = (sqrt(m) + sqrt(n)) sigma`` -- the spectral norm of an ``m x n`` Gaussian noise
    matrix of entry deviation ``sigma`` -- so that pure-noise singular values are removed.
    ``sigma = noise_level``, or, if ``None``, a robust estimate: a loose PCP solve (``tol=1e-4``)
    gives a low-rank ``E_0``, which is truncated at the largest ratio of consecutive singular
    values (in the leading half of its spectrum), and ``sigma = 1.4826 * MAD(M - E_0,r)`` (on at
    most 200000 sampled rows). The median absolute deviation ignores the sparse gross errors,
    which dominate the singular values of ``M`` itself (a median-singular-value estimate is off by
    two orders of magnitude with 5 % of outliers). Pass ``noise_level`` when it is known (it also
    saves the extra solve). ``G = M - E - S`` is returned as ``noise``.

    **method="godec"** is the bilateral factorisation of Eq. 5.29-5.35: ``E = W T`` with
    ``rank(W) = rank(T) <= rank`` and an ``l1``-regularised ``S`` (Eq. 5.30), updated SVD-free by
    ``QR = qr((M - S) T^T)``, ``W = Q``, ``T = Q^T (M - S)``, ``S = D_lam(M - W T)`` (Eq. 5.33-5.35),
    starting from a Gaussian random ``T`` (bilateral random projection). ``lam`` is the element
    threshold of Eq. 5.32 (default ``3 * 1.4826 * median|M - M_r|`` with ``M_r`` the best rank-``r``
    approximation of ``M``: a robust three-sigma level of the residual). ``threshold="soft"`` is
    Eq. 5.32; ``"hard"`` keeps entries above ``lam`` unshrunk (exact recovery when there is no
    noise). ``rank`` defaults to the Gavish-Donoho hard-threshold estimate from the singular
    values of ``M``. The model has a noise term by construction; ``noise_aware=True`` returns it.
    Stops when the relative change of ``(E, S)`` falls below ``tol``.

    Parameters
    ----------
    M : (m, n) array_like
        Data matrix (finite). float32 input is processed in float32 unless ``dtype`` says otherwise.
    method : {"ialm", "godec"}
    rank : int, optional
        Target rank (GoDec) or cap on the rank (IALM). ``1 <= rank <= min(m, n)``.
    lam : float, optional
        IALM: weight of ``||S||_1``. GoDec: threshold of Eq. 5.32.
    tol : float
        Stopping tolerance (see ``RPCAResult.residual``).
    max_iter : int, optional
        Default 1000 for PCP, 500 for GoDec and the noise-aware model.
    noise_aware : bool
        Fit ``M = E + S + G`` and return ``G`` (Eq. 4.23).
    noise_level : float, optional
        Standard deviation of the entries of ``G`` (noise-aware IALM only).
    mu : {"continuation", "thesis"} or float
        Penalty schedule of the IALM (see above).
    rho : float, optional
        Growth factor of ``mu`` (``>= 1``).
    threshold : {"soft", "hard"}
        Sparse-part operator of GoDec.
    backend : {"auto", "chunked", "dense"}
        ``"chunked"``: row-chunked engine on the tall orientation of ``M``; every SVD is computed
        from the ``n x n`` Gram matrix or a TSQR reduction of ``M - S`` (``n = min(m, n)``), memory
        is the input plus two arrays of its size (three with ``noise_aware``) plus a few 8 MB
        chunks. ``"dense"``: whole-matrix updates with full or partial (ARPACK, predicted rank)
        SVDs for IALM and the literal QR updates of Eq. 5.35 for GoDec. ``"auto"``: chunked when
        ``min(m, n) <= 256``.
    dtype : {None, "float32", "float64"}
        Working precision of the chunked engine (``None``: float32 for float32 input, else
        float64). float32 halves memory; its rounding floor is a relative residual of ~1e-6, so
        use ``tol >= 1e-6`` with it.
    on_nonconvergence : {"warn", "raise", "ignore"}
        ``"warn"``: return with ``converged=False`` and a :class:`ConvergenceWarning`; ``"raise"``:
        raise :class:`ConvergenceError` whose ``partial`` is the result; ``"ignore"``: return it.
    rng : int, Generator or None
        Random initial ``T`` of GoDec and row sampling for its default threshold.

    Returns
    -------
    RPCAResult
        ``low_rank`` and ``sparse`` have the shape of ``M`` (float64, or float32 in float32 mode).

    Raises
    ------
    InvalidInputError
        Bad shape, NaN/inf, unknown ``method``/``backend``/``threshold``, ``rank`` out of range...
    ConvergenceError
        With ``on_nonconvergence="raise"`` when ``max_iter`` is reached first.
    """
    check_choice(method, "method", _METHODS)
    check_choice(backend, "backend", _BACKENDS)
    check_choice(threshold, "threshold", ("soft", "hard"))
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
    if noise_level is not None:
        check_positive(noise_level, "noise_level")
    if isinstance(mu, str):
        check_choice(mu, "mu", ("continuation", "thesis"))
    else:
        check_positive(mu, "mu")
    if rho is None:
        rho = 1.0 if mu == "thesis" else 1.5
    check_positive(rho, "rho")
    if rho < 1:
        raise InvalidInputError(f"`rho` must be >= 1; got {rho!r}.")
    if dtype is None:
        dt = np.dtype(np.float32) if A0.dtype == np.float32 else np.dtype(np.float64)
    else:
        try:
            dt = np.dtype(dtype)
        except TypeError as exc:
            raise InvalidInputError(
                f"`dtype` must be 'float32' or 'float64'; got {dtype!r}."
            ) from exc
        if dt not in (np.float32, np.float64):
            raise InvalidInputError(f"`dtype` must be 'float32' or 'float64'; got {dtype!r}.")
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
                ctx, lam=lam, sigma=noise_level, rank=rank, tol=tol, max_iter=max_iter
            )
            what = "RPCA (noise-aware, stable PCP)"
        else:
            res = _godec(
                ctx,
                rank=rank,
                lam=lam,
                threshold=threshold,
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
        """TSQR core of the matrix whose rows ``sl`` ``fill(sl, out)`` writes; switches to TSQR
        for the rest of the solve."""
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
    """Singular value thresholding ``D_tau(X)`` with a predicted number ``sv`` of triplets.

    Returns ``(E, svp, k)``: ``svp`` singular values exceed ``tau``, ``k`` are kept (``svp`` capped
    by ``rank``). The thresholding is exact: when all ``sv`` computed values exceed ``tau`` (so
    more might), ``sv`` is enlarged and the partial SVD repeated (the prediction of Lin, Chen & Ma
    only saves work, it never truncates); a short side of at most ``FULL_SVD_MAX`` always gets a
    full SVD.
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
    """Chunked IALM storing only ``R = M - E + Y/mu`` between iterations.

    With ``R^{t+1} = M - E^{t+1} + Y^t / mu_t`` the updates of Eq. 4.22 give
    ``S^{t+1} = Q_{lam/mu_t}(R^{t+1})`` and ``Y^{t+1} = mu_t clip(R^{t+1}, +-lam/mu_t)``, so one
    array holds both ``S`` and ``Y``; a second one receives ``E``. Each iteration is one pass over
    the rows that also accumulates the core of the next SVT argument ``M - S + Y/mu``.
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
    """Chunked ``E = X Pa Pb`` / ``S = threshold(M - E, tau)`` iterations with ``X = M - S``.

    ``e_step(s, V)`` maps the core of ``X`` to ``(Pa, Pb, rank)``. Stops when
    ``sqrt(||dE||^2 + ||dS||^2) <= tol ||M||_F``.
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
    """Entry deviation of the dense noise of ``M = E + S + G`` (see :func:`rpca`, noise_aware).

    Loose PCP ``M = E_0 + S_0``; ``E_0`` truncated at its largest singular-value ratio; robust
    (MAD) deviation of ``M - E_0,r`` on a deterministic sample of rows.
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
