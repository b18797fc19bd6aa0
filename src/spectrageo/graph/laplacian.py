"""Graph Laplacians of meshes and point clouds (Section 4.1.1) and delta coordinates (Section 4.3).

All Laplacians are returned as CSR float64 in the positive semi-definite form ``L = D - C``, with
``D = diag(C 1)``; the normalized form is ``D^-1/2 L D^-1/2``. Every row of ``D - C`` sums to zero,
so ``L 1 = 0``.
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
    """``L = D - C`` (Eq. 4.1) or, with ``normalized=True``, ``D^-1/2 L D^-1/2`` from a symmetric ``C``.

    Isolated nodes (degree 0) get a zero row in the normalized form.
    """
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
    """Weighted vertex adjacency ``C`` of Eq. (4.2).

    ``kind="binary"``: ``w = 1``; ``"gaussian"``: ``w = exp(-|vi - vj|^2 / (2 sigma^2))`` with ``sigma``
    defaulting to the mean edge length; ``"cotangent"``: ``w = (cot a + cot b) / 2``.
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
    """Laplacian ``L = D - C`` of a triangle mesh (binary Eq. 4.1, Gaussian or cotangent Eq. 4.2).

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    kind : {"binary", "gaussian", "cotangent"}
    normalized : bool
        Return ``D^-1/2 L D^-1/2`` instead.
    sigma : float, optional
        Gaussian width (``alpha`` in the thesis); defaults to the mean edge length.
    """
    return laplacian_from_adjacency(
        weighted_adjacency(V, F, kind=kind, sigma=sigma), normalized=normalized
    )


def point_cloud_laplacian(
    P, k: int = 10, *, kind: str = "binary", normalized: bool = False, sigma: float | None = None
) -> sp.csr_matrix:
    """Laplacian ``L = D - C`` of the symmetrised kNN graph of a point cloud.

    ``kind``: ``"binary"`` or ``"gaussian"`` (cotangent weights need faces).
    """
    check_choice(kind, "kind", ("binary", "gaussian"))
    C = knn_graph(P, k, weights=kind, sigma=sigma)
    return laplacian_from_adjacency(C, normalized=normalized)


def delta_coordinates(V, F=None, *, L: sp.spmatrix | None = None) -> np.ndarray:
    """Differential coordinates ``delta_i = v_i - (1/d_i) sum_{j in N(i)} v_j`` (Eq. 4.12), (n, 3).

    Computed as ``D^-1 L V`` with the binary Laplacian of ``F`` (or with a given Laplacian ``L``);
    Eq. (4.13) writes the unnormalised ``L V``. Isolated vertices get zero.
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
