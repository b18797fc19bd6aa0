"""Orthogonal iterations (OI) for the low-frequency Laplacian eigenspaces of submeshes
(Section 4.1.4, Eq. 4.7; Section 5.2.1, Algorithms 6-7, Eq. 5.42-5.44; Appendix A, Eq. A.1-A.4).

The ``n_l`` eigenvectors of a submesh Laplacian ``L[i]`` with the smallest eigenvalues are the
dominant eigenvectors of ``T[i] = (L[i] + delta I)^-1``. Orthogonal iteration refines a starting
subspace by ``U <- Onorm(T^zeta U)``; because consecutive submeshes of the same mesh have similar
Laplacians (Fig. 5.53, Table 5.7), the subspace of the previous submesh is a good start for the next
one (subspace tracking, Eq. 4.7), and a single iteration is often enough (Fig. 5.55). ``T^zeta U`` is
never formed: ``(L + delta I)`` is factorised once per submesh with a sparse LU and ``zeta`` solves are
applied (Eq. 5.42). The orthonormalisation is a Householder QR (Eq. A.3-A.4), followed by a
Rayleigh-Ritz step (the eigen-decomposition of the small matrix ``Q^T L Q``) that orders the basis by
increasing Ritz value, so that ``U[:, :m]`` is the best ``m``-dimensional low-pass basis in the span.

The dynamic variant (DOI, Algorithm 7) also adapts the subspace size ``n_l`` of every submesh so that
the low-pass residual of a given signal stays between two thresholds.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit
from scipy.sparse.csgraph import reverse_cuthill_mckee

from .._errors import ConvergenceWarning, InvalidInputError
from .._progress import progress
from .._validation import as_rng, check_choice, check_positive
from ..linalg._common import check_on_nonconvergence, report_nonconvergence, single_thread_blas
from .gft import fix_signs
from .partition import Submeshes, as_adjacency

__all__ = [
    "DOIResult",
    "OIResult",
    "ShiftedFactor",
    "dynamic_orthogonal_iteration",
    "orthogonal_iteration",
    "shifted_factor",
    "submesh_eigenbases",
]

#: default relative shift: ``delta = DELTA_REL * mean(diag(L))`` (about 0.06 for a binary mesh Laplacian)
DELTA_REL = 1e-2
#: default thresholds of DOI on the relative low-pass residual ``||V - U U^T V||_F / ||V - mean(V)||_F``
DOI_EPS_LOW = 0.02
DOI_EPS_HIGH = 0.03


# ---------------------------------------------------------------- compiled kernels
@njit(cache=True)
def _nb_induced(indptr, indices, data, part, gmap):
    """CSR ``(ptr, ind, val)`` of the subgraph of a global CSR induced by ``part`` (local numbering).

    ``gmap`` is a global scratch array filled with -1; it is restored before returning.
    """
    m = part.size
    for a in range(m):
        gmap[part[a]] = a
    cnt = 0
    for a in range(m):
        g = part[a]
        for p in range(indptr[g], indptr[g + 1]):
            if gmap[indices[p]] >= 0:
                cnt += 1
    ptr = np.empty(m + 1, np.int64)
    ind = np.empty(cnt, np.int64)
    val = np.empty(cnt, np.float64)
    ptr[0] = 0
    q = 0
    for a in range(m):
        g = part[a]
        for p in range(indptr[g], indptr[g + 1]):
            b = gmap[indices[p]]
            if b >= 0:
                ind[q] = b
                val[q] = data[p]
                q += 1
        ptr[a + 1] = q
    for a in range(m):
        gmap[part[a]] = -1
    return ptr, ind, val


@njit(cache=True)
def _nb_permuted_laplacian(ptr, ind, val, perm, shift):
    """CSR of ``P (D - C + shift I) P^T`` (row ``r`` is old row ``perm[r]``, diagonal first).

    The matrix is symmetric, so the same arrays are also its CSC.
    """
    m = ptr.size - 1
    inv = np.empty(m, np.int64)
    for r in range(m):
        inv[perm[r]] = r
    Pp = np.empty(m + 1, np.int64)
    Pi = np.empty(ind.size + m, np.int64)
    Px = np.empty(ind.size + m, np.float64)
    q = 0
    for r in range(m):
        o = perm[r]
        Pp[r] = q
        dpos = q
        q += 1
        deg = 0.0
        for p in range(ptr[o], ptr[o + 1]):
            Pi[q] = inv[ind[p]]
            Px[q] = -val[p]
            deg += val[p]
            q += 1
        Pi[dpos] = r
        Px[dpos] = deg + shift
    Pp[m] = q
    return Pp, Pi, Px


@njit(cache=True, fastmath=True)
def _nb_envelope_cholesky(Ap, Ai, Ax):
    """Cholesky ``A = R R^T`` of a symmetric positive definite matrix in envelope (skyline) form.

    ``(Ap, Ai, Ax)``: CSR of the full symmetric ``A`` (rows in any index order), after a bandwidth
    reducing ordering (reverse Cuthill-McKee) so that the envelope -- columns ``first[i]..i`` of every
    row ``i`` -- is small; Cholesky fill stays inside the envelope, and the rows of ``R`` are dense
    there, so every entry is a contiguous dot product. Returns the CSR of ``R`` (row ``i``: columns
    ``first[i]..i``, the diagonal last) and a success flag (False if ``A`` is not positive definite).
    """
    n = Ap.size - 1
    first = np.empty(n, np.int64)
    for i in range(n):
        f = i
        for p in range(Ap[i], Ap[i + 1]):
            if Ai[p] < f:
                f = Ai[p]
        first[i] = f
    Rp = np.empty(n + 1, np.int64)
    Rp[0] = 0
    for i in range(n):
        Rp[i + 1] = Rp[i] + i - first[i] + 1
    Rx = np.zeros(Rp[n], np.float64)
    Ri = np.empty(Rp[n], np.int64)
    for i in range(n):
        base = Rp[i] - first[i]
        for j in range(first[i], i + 1):
            Ri[base + j] = j
        for p in range(Ap[i], Ap[i + 1]):
            j = Ai[p]
            if j <= i:
                Rx[base + j] += Ax[p]
    for i in range(n):
        fi = first[i]
        bi = Rp[i] - fi
        for j in range(fi, i):
            fj = first[j]
            bj = Rp[j] - fj
            lo = fi if fi > fj else fj
            acc = Rx[bi + j]
            for t in range(lo, j):
                acc -= Rx[bi + t] * Rx[bj + t]
            Rx[bi + j] = acc / Rx[bj + j]
        acc = Rx[bi + i]
        for t in range(fi, i):
            acc -= Rx[bi + t] * Rx[bi + t]
        if not acc > 0.0:
            return Rp, Ri, Rx, False
        Rx[bi + i] = np.sqrt(acc)
    return Rp, Ri, Rx, True


@njit(cache=True)
def _nb_transpose_rows(Rp, Ri, Rx):
    """CSC of a lower factor given as CSR with the diagonal last in each row (diagonal first per column)."""
    n = Rp.size - 1
    cnt = np.zeros(n + 1, np.int64)
    for p in range(Rp[n]):
        cnt[Ri[p] + 1] += 1
    for j in range(n):
        cnt[j + 1] += cnt[j]
    Lp = cnt.copy()
    Li = np.empty(Rp[n], np.int64)
    Lx = np.empty(Rp[n], np.float64)
    nxt = cnt[:-1].copy()
    # rows in descending order would put the diagonal last; ascending puts it first (row j = col j)
    for i in range(n):
        for p in range(Rp[i], Rp[i + 1]):
            j = Ri[p]
            q = nxt[j]
            nxt[j] += 1
            Li[q] = i
            Lx[q] = Rx[p]
    return Lp, Li, Lx


@njit(cache=True, fastmath=True, inline="always")
def _subtract_rows(acc, Y, idx, val, p, end):  # pragma: no cover - jitted
    """``acc -= sum_{q in [p, end)} val[q] * Y[idx[q]]``, four entries per pass (a quarter of the
    traffic on ``acc``)."""
    k = acc.shape[0]
    while p + 3 < end:
        i0, i1, i2, i3 = idx[p], idx[p + 1], idx[p + 2], idx[p + 3]
        v0, v1, v2, v3 = val[p], val[p + 1], val[p + 2], val[p + 3]
        for c in range(k):
            acc[c] -= (v0 * Y[i0, c] + v1 * Y[i1, c]) + (v2 * Y[i2, c] + v3 * Y[i3, c])
        p += 4
    while p < end:
        i0 = idx[p]
        v0 = val[p]
        for c in range(k):
            acc[c] -= v0 * Y[i0, c]
        p += 1


@njit(cache=True, fastmath=True)
def _nb_solve_power(Lp, Li, Lx, Rp, Ri, Rx, Y, zeta, normalize):
    """``Y <- (R R^T)^-zeta Y`` in place, all columns at once (row-major ``Y``).

    ``(Lp, Li, Lx)``: CSC of the Cholesky factor ``R`` (diagonal first in every column);
    ``(Rp, Ri, Rx)``: its CSR (diagonal last in every row). Each solve is a forward sweep over the rows
    of ``R`` and a backward sweep over its columns, accumulating one row of the result at a time. With
    ``normalize`` every column is rescaled to unit norm after each solve.
    """
    n, k = Y.shape
    acc = np.empty(k)
    nrm = np.empty(k)
    for _ in range(zeta):
        for j in range(n):
            for c in range(k):
                acc[c] = Y[j, c]
            last = Rp[j + 1] - 1
            _subtract_rows(acc, Y, Ri, Rx, Rp[j], last)
            d = 1.0 / Rx[last]
            for c in range(k):
                Y[j, c] = acc[c] * d
        for j in range(n - 1, -1, -1):
            for c in range(k):
                acc[c] = Y[j, c]
            _subtract_rows(acc, Y, Li, Lx, Lp[j] + 1, Lp[j + 1])
            d = 1.0 / Lx[Lp[j]]
            for c in range(k):
                Y[j, c] = acc[c] * d
        if not normalize:
            continue
        for c in range(k):
            nrm[c] = 0.0
        for i in range(n):
            for c in range(k):
                nrm[c] += Y[i, c] * Y[i, c]
        for c in range(k):
            nrm[c] = 1.0 / np.sqrt(nrm[c]) if nrm[c] > 0 else 1.0
        for i in range(n):
            for c in range(k):
                Y[i, c] *= nrm[c]
    return Y


@dataclass(frozen=True, eq=False)
class OIResult:
    """Result of :func:`orthogonal_iteration` with ``full_output=True``.

    Attributes
    ----------
    eigenvalues : (k,) Ritz values, ascending (approximate eigenvalues of ``L``)
    eigenvectors : (n, k) orthonormal Ritz vectors, signs fixed by :func:`fix_signs`
    n_iter : int, iterations performed
    converged : bool, ``residual <= tol`` (False when no ``tol`` was given)
    residual : float, ``max_j ||L u_j - theta_j u_j|| / ||L||_inf``
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    n_iter: int
    converged: bool
    residual: float


@dataclass(frozen=True, eq=False)
class DOIResult:
    """Result of :func:`dynamic_orthogonal_iteration` (Algorithm 7).

    Attributes
    ----------
    eigenvalues : (n_l,) Ritz values, ascending
    eigenvectors : (n, n_l) orthonormal basis, signs fixed
    n_iter : int, OI steps performed
    converged : bool, the final residual lies in the accepted band (see the function)
    residual : float, relative low-pass residual ``||X - U U^T X||_F / ||X - mean(X)||_F`` of the result
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


def _as_laplacian(L) -> sp.csc_matrix:
    if not sp.issparse(L):
        arr = np.asarray(L, dtype=np.float64)
        if arr.ndim != 2:
            raise InvalidInputError(f"`L` must be a square matrix; got shape {arr.shape}.")
        L = sp.csc_matrix(arr)
    if L.ndim != 2 or L.shape[0] != L.shape[1] or L.shape[0] == 0:
        raise InvalidInputError(f"`L` must be a non-empty square matrix; got shape {L.shape}.")
    L = sp.csc_matrix(L, dtype=np.float64)
    if L.nnz and not np.isfinite(L.data).all():
        raise InvalidInputError("`L` contains NaN or inf entries.")
    return L


def _delta(L: sp.spmatrix, delta) -> float:
    if delta is None:
        d = float(np.abs(L.diagonal()).mean())
        return DELTA_REL * d if d > 0 else DELTA_REL
    check_positive(delta, "delta")
    return float(delta)


def _check_zeta(zeta) -> int:
    check_positive(zeta, "zeta", integer=True)
    return int(zeta)


class ShiftedFactor:
    """Factorisation of ``L + delta I`` applying ``T = (L + delta I)^-1`` (Eq. 4.7, 5.42).

    For a positive definite ``L + delta I`` (any Laplacian with non-negative weights) this is a sparse
    Cholesky factorisation ``P (L + delta I) P^T = R R^T`` with a reverse Cuthill-McKee ordering ``P``,
    computed and applied by compiled (numba) up-looking and triangular-solve kernels that work on all
    the right-hand sides at once; otherwise (e.g. cotangent weights with negative entries) a SuperLU
    factorisation is used.

    Attributes
    ----------
    n : int
    delta : float
    method : {"cholesky", "superlu"}
    """

    def __init__(self, L, *, delta: float | None = None) -> None:
        L = _as_laplacian(L)
        self.n = L.shape[0]
        self.delta = _delta(L, delta)
        M = (L + self.delta * sp.identity(self.n, format="csc")).tocsr()
        perm = reverse_cuthill_mckee(M, symmetric_mode=True).astype(np.int64)
        Mp = M[perm][:, perm].tocsc()
        self._init(perm, Mp.indptr.astype(np.int64), Mp.indices.astype(np.int64), Mp.data, M)

    @classmethod
    def _from_permuted(cls, perm, Ap, Ai, Ax, delta: float) -> ShiftedFactor:
        """From the CSC arrays of ``P (L + delta I) P^T`` (internal fast path)."""
        self = cls.__new__(cls)
        self.n = perm.size
        self.delta = float(delta)
        self._init(perm, Ap, Ai, Ax, None)
        return self

    def _init(self, perm, Ap, Ai, Ax, M) -> None:
        self.perm = perm
        Rp, Ri, Rx, ok = _nb_envelope_cholesky(Ap, Ai, Ax)
        if ok:
            self.method = "cholesky"
            self._chol = (*_nb_transpose_rows(Rp, Ri, Rx), Rp, Ri, Rx)
            self._lu = None
        else:
            self.method = "superlu"
            self._chol = None
            if M is None:
                inv = np.empty_like(perm)
                inv[perm] = np.arange(perm.size)
                Mp = sp.csc_matrix((Ax, Ai, Ap), shape=(self.n, self.n))
                M = Mp[inv][:, inv]
            self._lu = spla.splu(
                sp.csc_matrix(M), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True}
            )

    def solve(self, B) -> np.ndarray:
        """``(L + delta I)^-1 B`` for ``B`` of shape (n,) or (n, k)."""
        B = np.asarray(B, dtype=np.float64)
        if B.shape[0] != self.n or B.ndim not in (1, 2):
            raise InvalidInputError(f"`B` must have {self.n} rows; got shape {B.shape}.")
        if self._lu is not None:
            return self._lu.solve(B)
        Y = np.ascontiguousarray(B.reshape(self.n, -1)[self.perm])
        _nb_solve_power(*self._chol, Y, 1, False)
        out = np.empty_like(Y)
        out[self.perm] = Y
        return out.reshape(B.shape)

    def power(self, Y: np.ndarray, zeta: int) -> np.ndarray:
        """``T^zeta Y`` with every column rescaled to unit norm after each solve (span unchanged)."""
        if self._lu is not None:
            for _ in range(zeta):
                Y = self._lu.solve(Y)
                nrm = np.sqrt(np.einsum("ij,ij->j", Y, Y))
                nrm[nrm == 0] = 1.0
                Y = Y / nrm
            return Y
        Z = np.ascontiguousarray(Y[self.perm])
        _nb_solve_power(*self._chol, Z, int(zeta), True)
        out = np.empty_like(Z)
        out[self.perm] = Z
        return out


def shifted_factor(L, *, delta: float | None = None) -> ShiftedFactor:
    """Factorise ``L + delta I`` once so that ``T = (L + delta I)^-1`` can be applied many times.

    ``delta`` defaults to ``1e-2 * mean(diag(L))``: small compared with the part of the spectrum that a
    low-pass keeps, yet large enough that ``T^zeta`` does not drown the low non-constant eigenvectors
    under the (near-)null space of ``L`` in floating point. Pass the result as ``factor=`` to
    :func:`orthogonal_iteration` to reuse it. See :class:`ShiftedFactor`.
    """
    return ShiftedFactor(L, delta=delta)


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
    """Orthonormal basis of the columns of ``Y`` (the ``Q`` of a QR factorisation, Eq. A.3-A.4).

    Tall-skinny ``Y`` (the OI case, e.g. 700 x 70) goes through Cholesky QR applied twice
    (``G = Y^T Y = R^T R``, ``Q = Y R^-1``, repeated on ``Q``): two matrix products and two
    triangular solves (BLAS 3) instead of the Householder sweeps, with the same span and an
    orthogonality at rounding level as long as ``cond(Y)`` is below about ``1e7`` (after the
    warm-started ``T^zeta``, about ``1e6``). When the first Cholesky fails or the second factor is
    not close to the identity (``Y`` too ill-conditioned), the Householder QR is used.
    """
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
    full_output: bool = False,
    on_nonconvergence: str = "warn",
):
    """Orthogonal iteration ``U <- Onorm(T^zeta U)``, ``T = (L + delta I)^-1`` (Eq. 4.7, Algorithm 6).

    Each of the ``n_iter`` iterations applies ``T^zeta`` with ``zeta`` sparse triangular solves
    (Eq. 5.42), orthonormalises with a Householder QR (Eq. A.3) and ends with a Rayleigh-Ritz step, so
    the columns of the result are ordered by increasing Ritz value (approximate eigenvalue of ``L``)
    and ``U[:, :m]`` is the best ``m``-dimensional low-pass basis in the subspace. The convergence
    factor per iteration is ``((lambda_k + delta) / (lambda_{k+1} + delta))^zeta`` (Section 4.1.4).

    Parameters
    ----------
    L : sparse or dense (n, n)
        Symmetric positive semi-definite Laplacian ``L = D - C`` (any weights, or normalized).
    U0 : (n, k)
        Starting subspace (e.g. the subspace of the previous submesh); need not be orthonormal but must
        have full column rank.
    delta : float, optional
        Positive shift of ``T``; default ``1e-2 * mean(diag(L))`` (see :func:`shifted_factor`).
    zeta : int
        Power of ``T`` per iteration (the thesis uses 1-4 for compression, 3-10 for denoising).
    n_iter : int
        Number of iterations (the maximum when ``tol`` is given).
    factor : SuperLU or callable, optional
        Factorisation of ``L + delta I`` from :func:`shifted_factor` (or any ``solve(B)`` callable),
        reused instead of factorising again; ``delta`` is then ignored.
    tol : float, optional
        Stop as soon as the relative Ritz residual ``max_j ||L u_j - theta_j u_j|| / ||L||_inf`` is
        at most ``tol``.
    full_output : bool
        Return an :class:`OIResult` (eigenvalues, eigenvectors, n_iter, converged, residual) instead
        of the basis alone.
    on_nonconvergence : {"warn", "raise", "ignore"}
        With ``tol``, when ``n_iter`` iterations do not reach it: ``"warn"`` emits a
        :class:`~spectrageo.ConvergenceWarning`, ``"raise"`` raises
        :class:`~spectrageo.ConvergenceError` (``partial`` is the :class:`OIResult`), ``"ignore"``
        returns silently (``converged`` is still False).

    Returns
    -------
    (n, k) ndarray or OIResult
        Orthonormal Ritz vectors, ascending, signs fixed by :func:`fix_signs` (an
        :class:`OIResult` when ``full_output``).
    """
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
    return result if full_output else U


def _oi(L, U, factor, zeta: int, n_iter: int, tol, want_residual: bool, ritz: bool = True):
    """Core of :func:`orthogonal_iteration` (no validation); returns (theta, U, n_iter, residual).

    ``ritz=False`` (only with ``tol=None``): Algorithm 6 as written, ``U <- Onorm(T^zeta U)`` without
    the Rayleigh-Ritz step; ``theta`` is then all NaN and the basis is not ordered.
    """
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
    """Dynamic orthogonal iteration (Algorithm 7, Eq. 5.43-5.44): OI whose subspace size adapts to a
    signal ``X`` so that its low-pass residual lies between ``eps_low`` and ``eps_high``.

    Each step ``t`` performs one OI step ``U <- Onorm(T^zeta U)`` (with Rayleigh-Ritz ordering) and
    measures the residual ``R = X - U U^T X`` (Eq. 5.43) by the relative norm
    ``rho = ||R||_F / ||X - mean(X)||_F``. Then, following the text of Section 5.2.1:

    * ``rho > eps_high`` (too much information lost): one column is appended, the normalised residual
      direction, and the next step orthonormalises ``T^zeta [U r/||r||]`` (Eq. 5.44), ``n_l += 1``;
    * ``rho < eps_low`` (more components than needed): the last column (largest Ritz value) is
      dropped, ``n_l -= 1``;
    * otherwise stop.

    Readings and safeguards (the thesis leaves these open):

    * The listing of Algorithm 7 swaps the two tests (it grows the subspace when the residual is
      *below* ``eps_l``); the text, which grows it when the residual is too large, is implemented.
    * Eq. (5.43) sums the residual vectors of the x, y and z coordinates, which can cancel; the
      Frobenius norm of the whole residual ``R`` (n, d) is used instead, and the appended direction is
      the leading left singular vector of ``R`` (the single direction that removes most of it).
    * The thresholds are relative (scale and translation invariant): the thesis gives no values; the
      defaults ``(0.02, 0.03)`` bracket the residual of a 10 % low-pass of the coordinates on
      700-vertex submeshes of the Stanford bunny (median 0.026; 0.036 on fandisk, 0.040 on armadillo).
    * If one column more or less jumps across the whole band (the band is too narrow for this
      submesh), the iteration stops at the larger subspace, which satisfies ``rho <= eps_high``.

    Parameters
    ----------
    L : sparse (n, n) Laplacian of the submesh
    U0 : (n, m0) starting subspace (e.g. the result of the previous submesh)
    X : (n,) or (n, d) signal (e.g. the vertex coordinates of the submesh)
    eps_low, eps_high : float, 0 <= eps_low < eps_high
    delta, zeta : see :func:`orthogonal_iteration`
    t_max : int, maximum number of OI steps
    min_size, max_size : bounds of ``n_l`` (``max_size`` defaults to ``n - 1``)
    factor : see :func:`orthogonal_iteration`
    on_nonconvergence : {"warn", "raise", "ignore"}
        Policy when ``converged`` is False (see :func:`orthogonal_iteration`).

    Returns
    -------
    DOIResult
        ``converged`` is True when ``eps_low <= rho <= eps_high``, or when ``rho`` is below the band at
        ``min_size`` or after the band-jump safeguard (then ``rho < eps_high`` too); False when
        ``t_max`` steps were not enough or ``max_size`` was reached above the band. ``residual`` is
        ``rho`` of the returned basis.
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
    for name, v in (("eps_low", eps_low), ("eps_high", eps_high)):
        check_positive(v, name, allow_zero=True)
    if not eps_low < eps_high:
        raise InvalidInputError(
            f"`eps_low` must be smaller than `eps_high`; got {eps_low!r} >= {eps_high!r}."
        )
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
    """The ``k`` lowest eigenpairs of a small Laplacian with LAPACK (MRRR on a subset when k << n).

    Divide and conquer on all pairs is faster than MRRR on a subset from ``k`` of about a quarter
    of ``n`` on (e.g. 32 vs 41 ms for 172 of 575 pairs, one thread; 51 vs 33 ms for 70 of 700).
    """
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


def submesh_eigenbases(
    C,
    subs: Submeshes,
    n_keep: int | float,
    *,
    method: str = "oi",
    delta: float | None = None,
    zeta: int = 4,
    n_iter: int = 1,
    tol: float | None = None,
    signal=None,
    eps_low: float = DOI_EPS_LOW,
    eps_high: float = DOI_EPS_HIGH,
    t_max: int = 100,
    laplacian: str = "binary",
    normalized: bool = False,
    warm_start: bool = True,
    ritz: bool = True,
    rng=None,
    info: list | None = None,
) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Low-frequency eigenbases of every submesh Laplacian, in submesh order (Algorithms 6-7).

    Yields ``(i, eigenvalues (k_i,), eigenvectors (n_i, k_i))`` for ``i = 0, 1, ...``; the rows of the
    eigenvectors follow ``subs.parts[i]``, the columns are ascending with signs fixed. The
    ``method`` argument:

    ``"exact"``
        Dense LAPACK eigendecomposition of each submesh Laplacian (``O(n_i^3)``, the "SVD" reference
        of Fig. 5.55); only the ``k`` lowest pairs are computed.
    ``"oi"``
        Subspace tracking (Eq. 4.7, Algorithm 6): the first submesh is decomposed exactly (as in the
        thesis), every following one runs ``n_iter`` orthogonal iterations ``Onorm(T^zeta U)`` started
        from the previous submesh's subspace (rows in the order of the sorted global indices; the
        equal submesh sizes make the shapes agree). With ``tol`` the iterations continue (up to
        ``n_iter``) until the relative Ritz residual is at most ``tol``.
    ``"doi"``
        Dynamic OI (Algorithm 7) on ``signal`` (required): the subspace size of every submesh is
        adapted so that the relative low-pass residual of the signal lies in ``[eps_low, eps_high]``
        (see :func:`dynamic_orthogonal_iteration`). The first submesh starts from its ``n_keep``
        exact lowest eigenvectors and may take up to ``max(t_max, n_i)`` steps (one column is
        added per step, so a tight band can need hundreds); the others start from their
        predecessor's subspace and take at most ``t_max`` steps.

    Parameters
    ----------
    C : sparse (n, n) symmetric adjacency of the whole graph
    subs : Submeshes (from :func:`~spectrageo.spectral.partition.overlapped_submeshes`)
    n_keep : int (count) or float in (0, 1] (fraction of each submesh's size)
    laplacian : {"binary", "weighted"}
        Binary ``L = D - C`` on the sparsity pattern (Eq. 4.1) or weighted with the values of ``C``.
        Negative weights (cotangent weights of obtuse triangles) are accepted; ``L + delta I`` is
        then factorised by SuperLU when it is not positive definite, and OI converges to the
        eigenvalues of smallest ``|lambda + delta|``.
    normalized : bool, use ``D^-1/2 L D^-1/2``
    warm_start : bool
        ``False`` starts every OI from a random orthonormal basis instead (an ablation of Eq. 4.7).
    ritz : bool
        ``"oi"`` only: ``False`` skips the Rayleigh-Ritz step and runs Algorithm 6 exactly as written
        (``U <- Onorm(T^zeta U)``): the yielded basis spans the same subspace and gives the same
        low-pass ``U U^T x``, but its columns are not ordered and the eigenvalues are NaN. Faster when
        only the projection is needed (used by :func:`~spectrageo.spectral.lowpass`).
    rng : seed for the random starts (when ``warm_start=False`` or sizes differ)
    info : list, optional
        If given, one :class:`OIResult` / :class:`DOIResult` per submesh is appended (``"exact"``:
        an :class:`OIResult` with ``n_iter=0``).
    """
    check_choice(method, "method", ("oi", "doi", "exact"))
    check_choice(laplacian, "laplacian", ("binary", "weighted"))
    if not isinstance(subs, Submeshes):
        raise InvalidInputError(f"`subs` must be a Submeshes; got {type(subs).__name__}.")
    # negative weights (cotangent) only matter with laplacian="weighted", where an indefinite
    # L + delta I is factorised by SuperLU instead of Cholesky
    C = as_adjacency(C, allow_negative=True)
    if C.shape[0] != subs.n_vertices:
        raise InvalidInputError(
            f"`C` has {C.shape[0]} vertices but `subs` was built for {subs.n_vertices}."
        )
    _n_keep(n_keep, max(int(subs.sizes.max()), 1))  # validate early
    zeta = _check_zeta(zeta)
    check_positive(n_iter, "n_iter", integer=True)
    if delta is not None:
        check_positive(delta, "delta")
    if tol is not None:
        check_positive(tol, "tol", allow_zero=True)
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
        delta,
        zeta,
        int(n_iter),
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
        ritz,
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
        """``(L, local)``: the submesh Laplacian and the CSR arrays of its adjacency.

        With ``matrix=False`` (and not normalized) ``L`` is not built and is None: the shifted
        factorisation only needs ``local``.
        """
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
