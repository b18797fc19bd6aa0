"""Incremental SVD: update a thin SVD when columns are appended (Section 5.2.4, Eq. 5.69-5.71)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_positive

__all__ = ["IncrementalSVD", "isvd_update"]


def _as_float_2d(x: Any, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise InvalidInputError(f"`{name}` must be a 2-D array; got shape {arr.shape}.")
    if not np.isfinite(arr).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    return arr


def isvd_update(
    U: Any,
    s: Any,
    Vt: Any,
    C: Any,
    *,
    rank: int | None = None,
    tol: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Thin SVD of ``[A, C]`` from a thin SVD ``A = U diag(s) Vt`` (Brand's method, Eq. 5.69-5.71).

    With ``P = U^T C`` and ``QR = qr((I - U U^T) C)`` (Eq. 5.69), the SVD of the small
    ``K = [[diag(s), P], [0, R]]`` (Eq. 5.70) updates both factors (Eq. 5.71) in
    ``O(m (r + c)^2 + (r + c)^3)``.

    Parameters
    ----------
    U, s, Vt : (m, r), (r,), (r, N) or None
        The factorisation (``r`` may be 0; ``Vt=None`` tracks only ``U`` and ``s``).
    C : (m, c) or (m,) array_like
        Columns to append.
    rank, tol : int, float, optional
        Keep at most ``rank`` triplets; drop values ``<= tol * s_max``.

    Returns
    -------
    U_new : (m, r') ndarray
    s_new : (r',) ndarray, descending
    Vt_new : (r', N + c) ndarray or None
    """
    U = _as_float_2d(U, "U")
    s = np.asarray(s, dtype=np.float64).ravel()
    C = _as_float_2d(C, "C")
    m, r = U.shape
    if s.shape != (r,):
        raise InvalidInputError(
            f"`s` must have shape ({r},) to match `U` {U.shape}; got {s.shape}."
        )
    if C.shape[0] != m:
        raise InvalidInputError(f"`C` must have {m} rows like `U`; got shape {C.shape}.")
    if Vt is not None:
        Vt = _as_float_2d(Vt, "Vt")
        if Vt.shape[0] != r:
            raise InvalidInputError(f"`Vt` must have {r} rows to match `s`; got shape {Vt.shape}.")
    if rank is not None:
        check_positive(rank, "rank", integer=True)
    if tol is not None:
        check_positive(tol, "tol", allow_zero=True)
    c = C.shape[1]
    # Eq. 5.69 with re-orthogonalisation
    P = U.T @ C
    Rres = C - U @ P
    P2 = U.T @ Rres
    Rres -= U @ P2
    P += P2
    Q, Rq = np.linalg.qr(Rres)
    # Eq. 5.70
    K = np.zeros((r + c, r + c))
    K[:r, :r] = np.diag(s)
    K[:r, r:] = P
    K[r:, r:] = Rq
    Uk, sk, Vkt = np.linalg.svd(K)
    if tol is None:
        tol = max(m, r + c) * np.finfo(np.float64).eps
    keep = int(np.count_nonzero(sk > tol * (sk[0] if sk.size else 0.0))) if sk.size else 0
    if rank is not None:
        keep = min(keep, int(rank))
    # Eq. 5.71
    U_new = np.hstack([U, Q]) @ Uk[:, :keep]
    s_new = sk[:keep]
    Vt_new = None
    if Vt is not None:
        W = Vkt[:keep]
        Vt_new = np.hstack([W[:, :r] @ Vt, W[:, r:]])
    return U_new, s_new, Vt_new


class IncrementalSVD:
    """Running thin SVD of a matrix that grows by blocks of columns (Section 5.2.4), truncated
    to ``rank`` after each update; ``compute_v`` also tracks ``Vt``; ``tol`` as in :func:`isvd_update`.

    Examples
    --------
    >>> import numpy as np
    >>> A = np.random.default_rng(0).normal(size=(50, 12))
    >>> inc = IncrementalSVD()
    >>> for j in range(0, 12, 4):
    ...     _ = inc.update(A[:, j : j + 4])
    >>> bool(np.allclose(inc.s, np.linalg.svd(A, compute_uv=False)))
    True
    """

    def __init__(
        self, rank: int | None = None, *, compute_v: bool = True, tol: float | None = None
    ):
        if rank is not None:
            check_positive(rank, "rank", integer=True)
        self.rank = rank
        self.compute_v = compute_v
        self.tol = tol
        self.U: np.ndarray | None = None
        self.s: np.ndarray | None = None
        self.Vt: np.ndarray | None = None
        self.n_columns = 0

    def update(self, C: Any) -> IncrementalSVD:
        """Append the columns ``C`` ((m, c) or (m,)) and update the factorisation; returns self."""
        C = _as_float_2d(C, "C")
        if self.U is None:
            m = C.shape[0]
            U, s = np.zeros((m, 0)), np.zeros(0)
            Vt = np.zeros((0, 0)) if self.compute_v else None
        else:
            U, s, Vt = self.U, self.s, self.Vt
            if C.shape[0] != U.shape[0]:
                raise InvalidInputError(
                    f"`C` must have {U.shape[0]} rows like the previous columns; got shape {C.shape}."
                )
        self.U, self.s, self.Vt = isvd_update(U, s, Vt, C, rank=self.rank, tol=self.tol)
        self.n_columns += C.shape[1]
        return self

    def reconstruct(self) -> np.ndarray:
        """``U diag(s) Vt`` (needs ``compute_v=True``)."""
        if self.U is None:
            raise InvalidInputError("no column has been added yet.")
        if self.Vt is None:
            raise InvalidInputError(
                "`compute_v=False`: the right singular vectors are not tracked."
            )
        return (self.U * self.s) @ self.Vt
