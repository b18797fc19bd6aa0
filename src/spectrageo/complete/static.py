"""Inpainting of static meshes with known connectivity (thesis Section 5.3.1)."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, check_choice, check_positive
from ..graph import adjacency_matrix, laplacian_from_adjacency
from ..linalg import complete_matrix, laplacian_interpolation
from ..linalg._common import spd_factor
from ._common import as_known, as_partial_points, check_components

__all__ = ["INPAINT_METHODS", "inpaint", "patch_indices"]

INPAINT_METHODS = ("mc", "li", "lsm")


def patch_indices(C: sp.spmatrix, k: int, *, max_ring: int = 64) -> np.ndarray:
    """Index matrix ``A`` (n, k) of Eq. (5.77): each vertex, then ``k - 1`` neighbours gathered
    ring by ring in increasing index order (repeating itself in a small component).
    """
    check_positive(k, "k", integer=True)
    C = sp.csr_matrix(C, dtype=np.float64)
    C.data[:] = 1.0
    C.setdiag(0)
    C.eliminate_zeros()
    n = C.shape[0]
    need = k - 1
    A = np.repeat(np.arange(n, dtype=np.int64)[:, None], k, axis=1)
    if need == 0:
        return A
    filled = np.zeros(n, dtype=np.int64)
    reached = sp.identity(n, format="csr")
    frontier = sp.identity(n, format="csr")
    for _ in range(max_ring):
        active = filled < need
        if not active.any():
            break
        frontier = sp.diags(active.astype(np.float64)) @ frontier
        nxt = (frontier @ C).tocsr()
        nxt.data[:] = 1.0
        nxt = (nxt - nxt.multiply(reached)).tocsr()
        nxt.eliminate_zeros()
        if nxt.nnz == 0:
            break
        nxt.sort_indices()
        rows = np.repeat(np.arange(n), np.diff(nxt.indptr))
        rank = np.arange(nxt.nnz) - nxt.indptr[rows] + filled[rows]
        take = rank < need
        A[rows[take], 1 + rank[take]] = nxt.indices[take]
        filled = np.minimum(filled + np.diff(nxt.indptr), need)
        reached = (reached + nxt).tocsr()
        reached.data[:] = 1.0
        frontier = nxt
    return A


def _auto_k(C: sp.csr_matrix, known: np.ndarray, k_min: int = 8, k_max: int = 64) -> int:
    """Smallest ``k`` of ``k_min, 2 k_min, ... <= k_max`` whose patches all hold a known vertex."""
    k = k_min
    while True:
        A = patch_indices(C, k)
        if known[A].any(axis=1).all() or k >= k_max:
            return k
        k = min(2 * k, k_max)


def _mc(
    V: np.ndarray,
    known: np.ndarray,
    C: sp.csr_matrix,
    *,
    k: int | None,
    tol: float,
    max_iter: int,
    rho: float,
    max_passes: int,
    rng: Any,
) -> np.ndarray:
    """Eq. 5.77-5.89 on centred, scaled coordinates, repeated inwards, LI for the rest."""
    out = V.copy()
    cur = known.copy()
    k_used = _auto_k(C, cur) if k is None else k
    A = patch_indices(C, k_used)
    for _ in range(max_passes):
        if cur.all():
            break
        c = out[cur].mean(axis=0)
        scale = float(np.linalg.norm(out[cur].max(axis=0) - out[cur].min(axis=0))) or 1.0
        X = np.where(cur[:, None], (out - c) / scale, 0.0)
        obs = cur[A]
        M = np.concatenate([X[A, d] for d in range(3)], axis=1)  # (n, 3k): [x | y | z] patches
        mask = np.tile(obs, (1, 3))
        res = complete_matrix(
            M, mask, tol=tol, max_iter=max_iter, rho=rho, on_nonconvergence="ignore", rng=rng
        )
        E = res.completed
        # rows holding at least one known entry give an estimate of their own vertex (column 0)
        rows = ~cur & obs.any(axis=1)
        if not rows.any():
            break
        est = np.stack([E[:, d * k_used] for d in range(3)], axis=1)
        out[rows] = est[rows] * scale + c
        cur = cur | rows
    if not cur.all():  # unreachable by the patches (k capped): Laplacian interpolation fallback
        L = laplacian_from_adjacency(C)
        idx = np.flatnonzero(cur)
        out = laplacian_interpolation(L, idx, out[idx])
    return out


def _lsm(V: np.ndarray, known: np.ndarray, C: sp.csr_matrix, weight: float) -> np.ndarray:
    """Least-squares meshes ``min ||(I - D^-1 C) V||^2 + w^2 ||V_k - V~_k||^2``."""
    n = V.shape[0]
    d = np.asarray(C.sum(axis=1)).ravel()
    inv = np.zeros(n)
    np.divide(1.0, d, out=inv, where=d > 0)
    L = (sp.identity(n) - sp.diags(inv) @ C).tocsc()
    S = sp.diags(known.astype(np.float64) * weight**2)
    K = (L.T @ L + S).tocsc()
    rhs = np.where(known[:, None], V, 0.0) * weight**2
    try:
        X = spd_factor(K).solve(rhs)
    except RuntimeError as exc:  # pragma: no cover - components are checked beforehand
        raise InvalidInputError("the least-squares-meshes system is singular.") from exc
    return X


def inpaint(
    V: Any,
    F: Any,
    known: Any,
    *,
    method: str = "li",
    k: int | None = None,
    tol: float = 1e-3,
    max_iter: int = 100,
    rho: float = 1.2,
    max_passes: int = 8,
    lsm_weight: float = 1.0,
    rng: Any = None,
) -> np.ndarray:
    """Recover the unknown vertices of a mesh with known connectivity (Section 5.3.1).

    ``"li"`` (default, docs/decisions.md#complete-inpaint-li) minimises ``||L V||_F`` over the
    unknown rows with ``L = D - C`` (Eq. 4.24-4.27); ``"mc"`` completes the k-ring patch matrix
    ``[X_A | Y_A | Z_A]`` (Eq. 5.77-5.78) by ALM (Eq. 5.80-5.89) and reads vertex ``i`` from column
    0 of each block (readings: docs/decisions.md#complete-mc-readings); ``"lsm"`` is least-squares
    meshes (Sorkine & Cohen-Or 2004) with soft constraints of weight ``lsm_weight``.

    Parameters
    ----------
    V : (n, 3) array_like
        Positions; unknown rows may hold anything, NaN included.
    F : (m, 3) array_like of int
    known : (n,) bool or (n_k,) int
    method : {"li", "mc", "lsm"}
    k, tol, max_iter, rho, max_passes, rng
        Patch size (default automatic) and ALM settings of ``"mc"``.

    Returns
    -------
    (n, 3) float64 ndarray, known rows exactly the input rows.

    Raises
    ------
    InvalidInputError
        Bad shapes or ``known``, NaN at known rows, a component without known vertex.
    """
    check_choice(method, "method", INPAINT_METHODS)
    try:
        n = int(np.asarray(V).shape[0]) if np.ndim(V) == 2 else -1
    except (TypeError, ValueError):
        n = -1
    if n < 0:
        as_partial_points(V)  # raises the shape error
    mask = as_known(known, n)
    X = as_partial_points(V, mask)
    F = as_faces(F, n, "F")
    if k is not None:
        check_positive(k, "k", integer=True)
        if k < 2:
            raise InvalidInputError(f"`k` must be >= 2; got {k}.")
    check_positive(max_passes, "max_passes", integer=True)
    check_positive(lsm_weight, "lsm_weight")
    if mask.all():
        return X
    C = adjacency_matrix(F, n)
    check_components(C, mask)
    if method == "mc":
        out = _mc(
            X, mask, C, k=k, tol=tol, max_iter=max_iter, rho=rho, max_passes=max_passes, rng=rng
        )
    elif method == "li":
        idx = np.flatnonzero(mask)
        out = laplacian_interpolation(laplacian_from_adjacency(C), idx, X[idx])
    else:
        out = _lsm(X, mask, C, lsm_weight)
    out[mask] = X[mask]
    if not np.isfinite(out).all():  # pragma: no cover - guarded by the component check
        raise InvalidInputError("completion produced non-finite positions.")
    return out
