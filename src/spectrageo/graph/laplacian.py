"""Graph Laplacians ``L = D - C`` (CSR float64, positive semi-definite, ``L 1 = 0``; normalized
``D^-1/2 L D^-1/2``) of meshes and point clouds (Section 4.1.1) and delta coordinates (Section 4.3).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice
from ..geometry.primitives import cotangent_weights, edges
from .adjacency import adjacency_matrix, knn_graph

KINDS = ("binary", "gaussian", "cotangent")


def laplacian_from_adjacency(C: sp.spmatrix, *, normalized: bool = False) -> sp.csr_matrix:
    """``L = D - C`` (Eq. 4.1), or ``D^-1/2 L D^-1/2`` (zero rows for isolated nodes)."""
    C = sp.csr_matrix(C, dtype=np.float64)
    if C.shape[0] != C.shape[1]:
        raise InvalidInputError(f"`C` must be square; got {C.shape}.")
    d = np.asarray(C.sum(axis=1)).ravel()
    L = (sp.diags(d) - C).tocsr()
    if not normalized:
        return L
    inv = np.zeros_like(d)
    np.divide(1.0, np.sqrt(np.abs(d)), out=inv, where=d > 0)
    Dm = sp.diags(inv)
    return (Dm @ L @ Dm).tocsr()


def weighted_adjacency(V, F, *, kind: str = "binary", sigma: float | None = None) -> sp.csr_matrix:
    """Vertex adjacency ``C`` of Eq. (4.2): ``"binary"`` 1, ``"gaussian"``
    ``exp(-|vi - vj|^2 / (2 sigma^2))`` (``sigma``: mean edge length) or ``"cotangent"``.
    """
    check_choice(kind, "kind", KINDS)
    V = as_points(V, "V")
    n = V.shape[0]
    F = as_faces(F, n, "F")
    if kind == "binary":
        return adjacency_matrix(F, n)
    if kind == "cotangent":
        return cotangent_weights(V, F)
    E = edges(F)
    d2 = np.sum((V[E[:, 0]] - V[E[:, 1]]) ** 2, axis=1)
    s = float(sigma) if sigma is not None else float(np.sqrt(d2).mean())
    if not s > 0:
        s = 1.0
    w = np.exp(-d2 / (2.0 * s * s))
    return sp.csr_matrix(
        (np.r_[w, w], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)
    )


def mesh_laplacian(
    V, F, *, kind: str = "binary", normalized: bool = False, sigma: float | None = None
) -> sp.csr_matrix:
    """Laplacian ``L = D - C`` (n, n) of a mesh ``V`` (n, 3), ``F`` (m, 3) with the weights
    of :func:`weighted_adjacency` (``sigma`` is the thesis's ``alpha``), optionally ``normalized``.
    """
    return laplacian_from_adjacency(
        weighted_adjacency(V, F, kind=kind, sigma=sigma), normalized=normalized
    )


def point_cloud_laplacian(
    P, k: int = 10, *, kind: str = "binary", normalized: bool = False, sigma: float | None = None
) -> sp.csr_matrix:
    """Laplacian ``L = D - C`` of the symmetrised binary or Gaussian kNN graph of a cloud."""
    check_choice(kind, "kind", ("binary", "gaussian"))
    C = knn_graph(P, k, weights=kind, sigma=sigma)
    return laplacian_from_adjacency(C, normalized=normalized)


def delta_coordinates(V, F=None, *, L: sp.spmatrix | None = None) -> np.ndarray:
    """Differential coordinates ``v_i - (1/d_i) sum_{j in N(i)} v_j`` (Eq. 4.12), (n, 3), as
    ``D^-1 L V`` with the binary Laplacian of ``F`` or a given ``L`` (zero where isolated).
    """
    V = as_points(V, "V")
    if L is None:
        if F is None:
            raise InvalidInputError("`delta_coordinates` needs `F` or `L`.")
        L = mesh_laplacian(V, F, kind="binary")
    L = sp.csr_matrix(L)
    if L.shape != (V.shape[0], V.shape[0]):
        raise InvalidInputError(f"`L` must have shape ({V.shape[0]}, {V.shape[0]}); got {L.shape}.")
    d = L.diagonal()
    LV = L @ V
    out = np.zeros_like(LV)
    np.divide(LV, d[:, None], out=out, where=d[:, None] > 0)
    return out
