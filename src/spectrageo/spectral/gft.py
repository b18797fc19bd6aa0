"""Graph Fourier transform (Section 4.1.2, Eq. 4.3-4.5) and whole-graph low-pass (Eq. 4.6)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .._errors import InvalidInputError
from .._validation import as_points

DENSE_LIMIT = 4000


def fix_signs(U: np.ndarray) -> np.ndarray:
    """Make each column's largest-magnitude entry positive (deterministic eigenvector signs)."""
    if U.size == 0:
        return U
    idx = np.argmax(np.abs(U), axis=0)
    s = np.sign(U[idx, np.arange(U.shape[1])])
    s[s == 0] = 1.0
    return U * s


@dataclass(frozen=True, eq=False)
class Eigenbasis:
    """The ``k`` lowest eigenpairs of a Laplacian: ascending ``eigenvalues`` (k,) and orthonormal
    ``eigenvectors`` (n, k) with signs fixed by :func:`fix_signs`.
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray

    @property
    def n(self) -> int:
        return int(self.eigenvectors.shape[0])

    @property
    def k(self) -> int:
        return int(self.eigenvectors.shape[1])

    @classmethod
    def from_laplacian(
        cls, L, k: int | None = None, *, method: str = "auto", tol: float = 0.0
    ) -> Eigenbasis:
        """The ``k`` lowest eigenpairs of ``L`` (all when None) by ``numpy.linalg.eigh``
        (``"dense"``), shift-invert ``eigsh`` (``"sparse"``) or dense when ``n <= 4000`` (``"auto"``).
        """
        n = L.shape[0]
        if L.shape != (n, n):
            raise InvalidInputError(f"`L` must be square; got {L.shape}.")
        if n == 0:
            raise InvalidInputError("`L` is empty.")
        k = n if k is None else int(k)
        if not 1 <= k <= n:
            raise InvalidInputError(f"`k` must be in 1..{n}; got {k}.")
        if method == "auto":
            method = "dense" if (n <= DENSE_LIMIT or k >= n // 2) else "sparse"
        if method == "dense":
            A = L.toarray() if sp.issparse(L) else np.asarray(L, dtype=np.float64)
            w, U = np.linalg.eigh(A)
            w, U = w[:k], U[:, :k]
        elif method == "sparse":
            if k >= n - 1:
                raise InvalidInputError(
                    f"`k` = {k} too large for the sparse solver on n = {n}; use method='dense'."
                )
            Ls = sp.csc_matrix(L, dtype=np.float64)
            scale = max(float(abs(Ls).max()), 1e-12)
            w, U = spla.eigsh(Ls, k=k, sigma=-1e-6 * scale, which="LM", tol=tol)
            order = np.argsort(w)
            w, U = w[order], U[:, order]
        else:
            raise InvalidInputError(
                f"`method` must be 'auto', 'dense' or 'sparse'; got {method!r}."
            )
        return cls(np.asarray(w), fix_signs(np.asarray(U)))

    def gft(self, X) -> np.ndarray:
        """``X_hat = U^T X`` (Eq. 4.4) for a signal (n,) or (n, d)."""
        X = np.asarray(X, dtype=np.float64)
        if X.shape[0] != self.n:
            raise InvalidInputError(f"signal must have {self.n} rows; got shape {X.shape}.")
        return self.eigenvectors.T @ X

    def igft(self, X_hat) -> np.ndarray:
        """``X = U X_hat`` (Eq. 4.5); ``X_hat`` may have fewer than ``k`` rows (low-pass)."""
        X_hat = np.asarray(X_hat, dtype=np.float64)
        r = X_hat.shape[0]
        if r > self.k:
            raise InvalidInputError(
                f"`X_hat` has {r} rows; the basis has only {self.k} components."
            )
        return self.eigenvectors[:, :r] @ X_hat

    def lowpass(self, X, n_keep: int) -> np.ndarray:
        """Keep the ``n_keep`` lowest-frequency components: ``U_nl U_nl^T X`` (Eq. 4.6)."""
        if not 1 <= n_keep <= self.k:
            raise InvalidInputError(f"`n_keep` must be in 1..{self.k}; got {n_keep}.")
        Uk = self.eigenvectors[:, :n_keep]
        return Uk @ (Uk.T @ np.asarray(X, dtype=np.float64))


def gft(V, basis: Eigenbasis) -> np.ndarray:
    """Graph Fourier transform ``U^T V`` (Eq. 4.4)."""
    return basis.gft(V)


def igft(V_hat, basis: Eigenbasis) -> np.ndarray:
    """Inverse graph Fourier transform ``U V_hat`` (Eq. 4.5)."""
    return basis.igft(V_hat)


def lowpass_whole(V, L, *, keep: float | int) -> np.ndarray:
    """Whole-graph low-pass of ``V`` (n, d) on ``L`` (Section 4.1.3), keeping a fraction or a
    count ``keep`` of the components.
    """
    V = np.asarray(V, dtype=np.float64)
    if V.ndim == 2 and V.shape[1] == 3:
        V = as_points(V, "V")
    n = L.shape[0]
    n_keep = _n_keep(keep, n)
    basis = Eigenbasis.from_laplacian(L, n_keep)
    return basis.lowpass(V, n_keep)


def _n_keep(keep: float | int, n: int) -> int:
    if isinstance(keep, bool):
        raise InvalidInputError(
            f"`keep` must be a fraction in (0, 1] or a count >= 1; got {keep!r}."
        )
    if isinstance(keep, (int, np.integer)):
        if not 1 <= keep <= n:
            raise InvalidInputError(f"`keep` must be in 1..{n} as a count; got {keep}.")
        return int(keep)
    keep = float(keep)
    if not 0.0 < keep <= 1.0:
        raise InvalidInputError(
            f"`keep` must be a fraction in (0, 1] or a count >= 1; got {keep!r}."
        )
    return max(1, int(round(keep * n)))
