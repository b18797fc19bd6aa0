"""Geometric saliency by RPCA of the normals of overlapping face patches (Eq. 6.8-6.9, Appendix E).

The patch normals of every face are the rows of a coherence matrix ``M``: row ``i`` holds
``[g_i, g_i1, ..., g_ik]`` (the guided normals of the face and of its ``k`` nearest faces, Eq. 6.8),
i.e. the ``(n_f, 3 (k + 1))`` arrangement used for Table E.1 (Eq. 6.8 prints the transposed
``3 n_f x (k + 1)`` block layout; both hold the same numbers and the low-rank/sparse split behaves the
same). Neighbouring normals of flat regions agree, so those rows are explained by a low-rank ``E``;
rows crossing creases, corners or defects leave a sparse residual ``S`` (``M = E + S``, Eq. 4.16).
The geometric saliency of face ``i`` is the magnitude of its part of ``S`` (Eq. 6.9).

Choices (each selectable):

* ``sparse_norm="patch"`` (default): ``s_1i = ||S_i||_2`` over the whole row ``i`` (the sparse
  energy of the patch). Eq. (6.9) reads only the first column (``sparse_norm="center"``:
  ``||S_i1||_2``, the face's own normal). Default chosen on the tuning split; see
  docs/decisions.md#saliency-sparse-norm.
* ``shrinkage="group"`` (default): the sparse penalty is the sum of the Euclidean norms of the
  normals in ``S`` (the l2,1 model of Tang & Nehorai, Appendix E) instead of the element-wise l1 norm
  of Eq. (4.18). The l1 norm depends on the coordinate axes, so a rotated copy of a mesh gets a
  slightly different map (Pearson about 0.995); the group norm makes the map exactly invariant to
  rotations, uniform scaling and translations. ``shrinkage="elementwise"`` is Eq. (4.18).
* ``solver="internal"`` (default): an inexact ALM (Lin, Chen & Ma 2010, the solver of Eq. 4.19-4.22)
  specialised to this tall, 3(k + 1)-column matrix: singular value thresholding from the
  (3(k + 1))^2 Gram matrix and one fused pass per iteration for shrinkage, multiplier and residual.
  ``solver="ialm"`` / ``"godec"`` hand the matrix to :func:`spectrageo.linalg.rpca` (element-wise
  shrinkage only).
"""

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


@dataclass(frozen=True)
class PatchRPCA:
    """Result of :func:`geometric_face_values`.

    Attributes
    ----------
    values : (q,) float64
        Raw geometric saliency of the analysed faces (not normalised).
    n_iter, converged, residual
        Solver iterations, whether ``||M - E - S||_F <= tol ||M||_F`` was reached, final ratio.
    rank : int
        Rank of the low-rank part at the last iteration.
    """

    values: np.ndarray
    n_iter: int
    converged: bool
    residual: float
    rank: int


def coherence_matrix(normals: np.ndarray, patches: np.ndarray) -> np.ndarray:
    """Rows ``[g_i, g_i1, ..., g_ik]`` of Eq. (6.8), shape (q, 3 (k + 1)), C-contiguous float64."""
    patches = np.asarray(patches, dtype=np.int64)
    return np.ascontiguousarray(normals[patches].reshape(patches.shape[0], -1), dtype=np.float64)


def _svt_basis(A: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """Right singular basis of ``D_tau(A)`` for a tall ``A``, from its (p, p) Gram matrix.

    Returns ``(Qk, W)``, (p, r) and (r, p), with ``D_tau(A) = (A Qk) W`` (singular value
    thresholding, ``W = diag(1 - tau / sigma) Qk^T`` over the singular values above ``tau``).
    """
    w, Q = np.linalg.eigh(A.T @ A)
    sv = np.sqrt(np.maximum(w, 0.0))
    keep = sv > tau
    Qk = np.ascontiguousarray(Q[:, keep])
    W = np.ascontiguousarray(((1.0 - tau / sv[keep])[:, None]) * Qk.T)
    return Qk, W


def _ialm_tall(
    M: np.ndarray, *, lam: float, tol: float, max_iter: int, group: bool
) -> tuple[np.ndarray, int, bool, float, int]:
    """Inexact ALM for ``min ||E||_* + lam ||S||_(1 | 2,1)  s.t.  M = E + S`` with ``M`` tall.

    Per iteration: one (p, p) Gram matrix and its eigendecomposition (the SVT basis,
    :func:`_svt_basis`), then one fused pass over the rows (:func:`._kernels.ialm_fused_step`)
    that rebuilds the low-rank row, shrinks, updates the multiplier and forms the next SVT input;
    neither the low-rank nor the sparse matrix is stored during the iterations. Cost O(q p^2) per iteration, linear in the rows.
    """
    from ._kernels import ialm_fused_step

    m, p = M.shape
    norm_fro = float(np.linalg.norm(M))
    if norm_fro == 0.0:
        return np.zeros_like(M), 0, True, 0.0, 0
    two = float(np.sqrt(max(np.linalg.eigvalsh(M.T @ M)[-1], 0.0)))
    if group:
        dual = float(np.sqrt((M.reshape(m, -1, 3) ** 2).sum(axis=2)).max()) / lam
    else:
        dual = float(np.abs(M).max()) / lam
    Y = M / max(two, dual)
    mu = 1.25 / two
    mu_bar = mu * 1e7
    rho = 1.5
    A = M + Y / mu  # M - S + Y / mu with S = 0
    converged, resid, rank, it = False, np.inf, 0, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - returned below
        Qk, W = _svt_basis(A, 1.0 / mu)
        rank = Qk.shape[1]
        mu_next = min(mu * rho, mu_bar)
        zz = ialm_fused_step(M, A, Y, Qk, W, mu, mu_next, lam / mu, group)
        mu = mu_next
        resid = float(np.sqrt(zz)) / norm_fro
        if resid <= tol:
            converged = True
            break
    S = M - A + Y / mu  # A = M - S + Y / mu after the last step
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
    """Raw geometric saliency of the faces whose patches are given (Eq. 6.8-6.9).

    Parameters
    ----------
    normals : (m, 3) float
        Unit (guided) face normals.
    patches : (q, k + 1) int
        Patch of each analysed face, the face itself first (:func:`face_patches`). Passing the rows
        of a subset of faces builds the reduced matrix ``M'`` of the fast variant (Table 6.1).
    sparse_norm : {"patch", "center"}
        Norm of the whole row of ``S`` (default) or of its first 3-vector (Eq. 6.9); see the module
        docstring.
    shrinkage : {"group", "elementwise"}
        Sparse penalty: sum of normal-vector norms (rotation invariant, default) or l1 (Eq. 4.18).
    solver : {"internal", "ialm", "godec"}
        See the module docstring. The library solvers need ``shrinkage="elementwise"``.
    lam : float, optional
        Sparse weight; default ``1 / sqrt(max(q, 3 (k + 1)))`` (Candes et al.).
    tol : float
        Stop when ``||M - E - S||_F <= tol ||M||_F``. The map is stable from about 1e-4 on (the
        thesis' 1e-7 changes it by less than 1e-3 in Pearson terms at several times the cost).
    max_iter : int
        Iteration cap (a non-converged run still returns its last ``S``; see ``converged``).
    rng : seed or Generator
        Only used by ``solver="godec"``.

    Returns
    -------
    :class:`PatchRPCA`
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
        # The products of the tall (q, 3(k+1)) matrix are too thin to gain from BLAS threads, and
        # OpenBLAS threads spinning on a loaded machine made them up to 10x slower; one thread.
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
    """Normalised geometric saliency of a mesh (Eq. 6.8-6.9, 6.12), per vertex or per face.

    Parameters are those of :func:`geometric_face_values` plus ``k`` (neighbours per patch), ``per``
    (``"face"`` or ``"vertex"``: first-ring mean, Eq. 6.14) and ``normals`` (``"guided"``,
    ``"face"`` or an (m, 3) array).

    Returns
    -------
    (n,) or (m,) float64 in [0, 1].
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
