"""Geometric saliency by RPCA of patch normals (Eq. 6.8-6.9); decisions: saliency-rpca-choices."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_choice, check_positive
from ..linalg._common import single_thread_blas
from ._common import PER, check_int, check_k, check_mesh, face_patches, face_to_vertex, minmax
from ._common import mesh_normals as _mesh_normals

SPARSE_NORMS = ("patch", "center")
SHRINKAGES = ("group", "elementwise")
SOLVERS = ("internal", "ialm", "godec")
#: rows of the patch matrix per block of the internal solver's passes (one thread each); the Gram
#: matrix and the residual are summed per block, so they depend on this, not on the threads
ROWS = 32768


@dataclass(frozen=True)
class PatchRPCA:
    """Result of :func:`geometric_face_values`: raw ``values`` (q,) and the solver's ``n_iter``,
    ``converged``, ``residual`` and ``rank``.
    """

    values: np.ndarray
    n_iter: int
    converged: bool
    residual: float
    rank: int


def coherence_matrix(normals: np.ndarray, patches: np.ndarray) -> np.ndarray:
    """Rows ``[g_i, g_i1, ..., g_ik]`` of Eq. (6.8), (q, 3 (k + 1)) C-contiguous float64."""
    patches = np.asarray(patches, dtype=np.int64)
    return np.ascontiguousarray(normals[patches].reshape(patches.shape[0], -1), dtype=np.float64)


def _gram(A: np.ndarray) -> np.ndarray:
    """``A^T A``: blocks of :data:`ROWS` rows on threads, added in block order."""
    from .._threads import thread_map

    parts = thread_map(lambda a: A[a : a + ROWS].T @ A[a : a + ROWS], range(0, A.shape[0], ROWS))
    G = parts[0]
    for P in parts[1:]:
        G += P
    return G


def _svt_basis(A: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Qk, W)`` with ``D_tau(A) = (A Qk) W`` for a tall ``A``, from its Gram matrix."""
    w, Q = np.linalg.eigh(_gram(A))
    sv = np.sqrt(np.maximum(w, 0.0))
    keep = sv > tau
    Qk = np.ascontiguousarray(Q[:, keep])
    W = np.ascontiguousarray(((1.0 - tau / sv[keep])[:, None]) * Qk.T)
    return Qk, W


def _ialm_tall(
    M: np.ndarray, *, lam: float, tol: float, max_iter: int, group: bool
) -> tuple[np.ndarray, int, bool, float, int]:
    """Inexact ALM for ``min ||E||_* + lam ||S||`` s.t. ``M = E + S``, O(q p^2) per iteration."""
    from .._threads import thread_map
    from ._kernels import ialm_fused_step

    m, p = M.shape
    norm_fro = float(np.linalg.norm(M))
    if norm_fro == 0.0:
        return np.zeros_like(M), 0, True, 0.0, 0
    two = float(np.sqrt(max(np.linalg.eigvalsh(_gram(M))[-1], 0.0)))
    # row blocks throughout: whole-matrix temporaries cost more in fresh pages than in arithmetic
    blocks = range(0, m, ROWS)
    if group:
        dual = max(
            float(np.sqrt((M[a : a + ROWS].reshape(-1, 3) ** 2).sum(axis=1)).max()) for a in blocks
        )
    else:
        dual = max(float(np.abs(M[a : a + ROWS]).max()) for a in blocks)
    dual /= lam
    Y = M / max(two, dual)
    mu = 1.25 / two
    mu_bar = mu * 1e7
    rho = 1.5
    A = Y / mu
    A += M  # M - S + Y / mu with S = 0
    converged, resid, rank, it = False, np.inf, 0, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - returned below
        Qk, W = _svt_basis(A, 1.0 / mu)
        rank = Qk.shape[1]
        mu_next = min(mu * rho, mu_bar)
        args = (M, A, Y, Qk, W, mu, mu_next, lam / mu, group)
        # row blocks on threads; the partial sums added in block order (the same on any count)
        zz = sum(thread_map(lambda a, x=args: ialm_fused_step(*x, a, min(a + ROWS, m)), blocks))
        mu = mu_next
        resid = float(np.sqrt(zz)) / norm_fro
        if resid <= tol:
            converged = True
            break
    # S = M - A + Y / mu (A = M - S + Y / mu after the last step), in A's and Y's memory
    S = np.subtract(M, A, out=A)
    S += np.divide(Y, mu, out=Y)
    return S, it, converged, resid, rank


def geometric_face_values(
    normals: np.ndarray,
    patches: np.ndarray,
    *,
    sparse_norm: str = "patch",
    shrinkage: str = "group",
    solver: str = "internal",
    lam: float | None = None,
    tol: float = 1e-4,
    max_iter: int = 300,
    rng=None,
) -> PatchRPCA:
    """Raw geometric saliency (Eq. 6.8-6.9) of the faces whose ``patches`` (q, k + 1) are given.

    ``normals`` (m, 3) unit; ``sparse_norm`` "patch" (row of ``S``,
    docs/decisions.md#saliency-sparse-norm) or "center" (Eq. 6.9); ``shrinkage`` "group" or
    "elementwise" (Eq. 4.18); ``solver`` "internal", "ialm" or "godec" (elementwise only); ``lam``
    default ``1 / sqrt(max(q, 3 (k + 1)))``; stop at ``||M - E - S||_F <= tol ||M||_F`` or
    ``max_iter``. Returns :class:`PatchRPCA`.
    """
    check_choice(sparse_norm, "sparse_norm", SPARSE_NORMS)
    check_choice(shrinkage, "shrinkage", SHRINKAGES)
    check_choice(solver, "solver", SOLVERS)
    check_positive(tol, "tol")
    max_iter = check_int(max_iter, "max_iter")
    if solver != "internal" and shrinkage == "group":
        raise InvalidInputError(
            f'`solver` = {solver!r} supports only shrinkage="elementwise"; got shrinkage="group".'
        )
    M = coherence_matrix(np.asarray(normals, dtype=np.float64), patches)
    q, p = M.shape
    if q == 0:
        return PatchRPCA(np.zeros(0), 0, True, 0.0, 0)
    lam = 1.0 / np.sqrt(max(q, p)) if lam is None else float(check_positive(lam, "lam"))
    if solver == "internal":
        # one BLAS thread for the thin products: see docs/decisions.md#saliency-rpca-choices
        with single_thread_blas():
            S, n_iter, conv, resid, rank = _ialm_tall(
                M, lam=lam, tol=float(tol), max_iter=max_iter, group=shrinkage == "group"
            )
    else:
        from ..linalg import rpca

        res = rpca(
            M,
            method=solver,
            lam=lam if solver == "ialm" else None,
            tol=float(tol),
            max_iter=max_iter,
            on_nonconvergence="ignore",
            rng=rng,
        )
        S, n_iter, conv, resid, rank = res.sparse, res.n_iter, res.converged, res.residual, res.rank
    if sparse_norm == "patch":
        vals = np.linalg.norm(S, axis=1)
    else:
        vals = np.linalg.norm(S[:, :3], axis=1)
    return PatchRPCA(vals, int(n_iter), bool(conv), float(resid), int(rank))


def geometric_saliency(
    V,
    F,
    *,
    k: int = 25,
    per: str = "vertex",
    normals="guided",
    sparse_norm: str = "patch",
    shrinkage: str = "group",
    solver: str = "internal",
    tol: float = 1e-4,
    max_iter: int = 300,
    rng=None,
) -> np.ndarray:
    """Normalised geometric saliency (Eq. 6.8-6.9, 6.12) per vertex or face; options as in
    :func:`geometric_face_values` and :func:`saliency`.
    """
    check_choice(per, "per", PER)
    V, F = check_mesh(V, F)
    k = check_k(k, F.shape[0])
    N = _mesh_normals(V, F, normals)
    patches = face_patches(V[F].mean(axis=1), k)
    res = geometric_face_values(
        N,
        patches,
        sparse_norm=sparse_norm,
        shrinkage=shrinkage,
        solver=solver,
        tol=tol,
        max_iter=max_iter,
        rng=rng,
    )
    s = minmax(res.values)
    return s if per == "face" else face_to_vertex(s, F, V.shape[0])


__all__ = [
    "PatchRPCA",
    "coherence_matrix",
    "geometric_face_values",
    "geometric_saliency",
]
