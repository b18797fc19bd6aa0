"""Shifted factorisation ``T = (L + delta I)^-1`` of orthogonal iterations (Eq. 4.7, 5.42)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit
from scipy.sparse.csgraph import reverse_cuthill_mckee

from .._errors import InvalidInputError
from .._validation import check_positive

#: default relative shift: ``delta = DELTA_REL * mean(diag(L))`` (about 0.06 for a binary mesh Laplacian)
DELTA_REL = 1e-2


# ---------------------------------------------------------------- compiled kernels
@njit(cache=True)
def _nb_induced(indptr, indices, data, part, gmap):
    """CSR of the subgraph induced by ``part``, locally numbered (``gmap``: scratch of -1)."""
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
    """CSR (= CSC) of ``P (D - C + shift I) P^T``, diagonal first."""
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
    """Envelope Cholesky ``A = R R^T`` of a symmetric CSR after a bandwidth-reducing order;
    returns the CSR of ``R`` (diagonal last) and False when ``A`` is not positive definite.
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
    """``acc -= sum_{q in [p, end)} val[q] * Y[idx[q]]``, four entries per pass."""
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
    """``Y <- (R R^T)^-zeta Y`` in place from the CSC and CSR of ``R`` (optionally normalized)."""
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
    """``T = (L + delta I)^-1`` (Eq. 4.7, 5.42) by a compiled envelope Cholesky in reverse
    Cuthill-McKee order, or SuperLU when not positive definite (``method``).
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
    """Factorise ``L + delta I`` once, for ``factor=`` of :func:`orthogonal_iteration`; ``delta``
    defaults to ``1e-2 * mean(diag(L))``, small next to the kept spectrum.
    """
    return ShiftedFactor(L, delta=delta)
