"""Saliency-aware guided denoising (Section 6.1.3, Eq. 6.20-6.23)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from ..geometry.primitives import face_areas, face_centroids, face_normals
from ..geometry.update import update_vertices
from ..graph.adjacency import face_adjacency
from ._common import check_int


def first_ring_patches(F) -> sp.csr_matrix:
    """Binary (m, m) CSR matrix of the first-ring face patches (faces sharing a vertex)."""
    F = np.asarray(F, dtype=np.int64)
    P = (face_adjacency(F, shared="vertex") + sp.identity(F.shape[0], format="csr")).tocsr()
    P.data[:] = 1.0
    P.sort_indices()
    return P


def _check_face_values(values, m: int, name: str) -> np.ndarray:
    s = np.asarray(values, dtype=np.float64)
    if s.shape != (m,):
        raise InvalidInputError(f"`{name}` must have shape ({m},); got {s.shape}.")
    if not np.isfinite(s).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    return s


def select_patches_by_saliency(face_saliency, P) -> np.ndarray:
    """Centre of the least salient patch containing each face (Eq. 6.20-6.21), (m,) int64;
    ``P[j, l] = 1`` when face ``l`` is in the patch centred at ``j``.
    """
    P = sp.csr_matrix(P, dtype=np.float64)
    m = P.shape[0]
    if P.shape != (m, m):
        raise InvalidInputError(f"`P` must be square (m, m); got {P.shape}.")
    s = _check_face_values(face_saliency, m, "face_saliency")
    P.data[:] = 1.0
    size = np.asarray(P.sum(axis=1)).ravel()
    xi = np.divide(P @ s, size, out=np.full(m, np.inf), where=size > 0)  # Eq. 6.21
    PT = P.T.tocsr()  # row i: centres of the patches containing face i
    PT.sort_indices()
    best = np.arange(m, dtype=np.int64)
    counts = np.diff(PT.indptr)
    has = counts > 0
    if PT.nnz:
        cand = xi[PT.indices]
        lo = np.full(m, np.inf)
        lo[has] = np.minimum.reduceat(cand, PT.indptr[:-1][has])
        rows = np.repeat(np.arange(m), counts)
        hit = np.flatnonzero(cand == lo[rows])
        first = np.r_[True, rows[hit][1:] != rows[hit][:-1]]
        best[rows[hit[first]]] = PT.indices[hit[first]]
    return best


def saliency_patch_weights(V, F, face_saliency, *, P=None) -> sp.csr_matrix:
    """Row-stochastic (m, m) area weights of the chosen patches: ``normalize(W @ N)``."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    P = first_ring_patches(F) if P is None else sp.csr_matrix(P, dtype=np.float64)
    best = select_patches_by_saliency(face_saliency, P)
    A = face_areas(V, F)
    W = (P[best] @ sp.diags(A)).tocsr()
    tot = np.asarray(W.sum(axis=1)).ravel()
    inv = np.divide(1.0, tot, out=np.zeros_like(tot), where=tot > 0)
    return (sp.diags(inv) @ W).tocsr()


def _unit(X: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(X, axis=1, keepdims=True)
    return np.divide(X, n, out=np.zeros_like(X), where=n > 0)


def saliency_guided_normals(V, F, *, face_saliency=None, normals=None, **saliency_options):
    """Guided normals (m, 3) from the least salient candidate patch (Eq. 6.20-6.21)."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    if face_saliency is None:
        from .combined import saliency as _saliency

        face_saliency = _saliency(V, F, per="face", **saliency_options)
    N = face_normals(V, F) if normals is None else np.asarray(normals, dtype=np.float64)
    if N.shape != F.shape:
        raise InvalidInputError(f"`normals` must have shape {F.shape}; got {N.shape}.")
    return _unit(np.asarray(saliency_patch_weights(V, F, face_saliency) @ N))


def saliency_denoise(
    V,
    F,
    *,
    face_saliency=None,
    sigma_r: float = 0.25,
    n_iter: int = 15,
    vertex_iter: int = 20,
    **saliency_options,
) -> np.ndarray:
    """Saliency-aware guided denoising (Eq. 6.20-6.23, Section 4.7), (n, 3) float64.

    ``n_iter`` joint bilateral passes (range width ``sigma_r``, thesis 0.25; spatial width as in
    docs/decisions.md#saliency-readings) and ``vertex_iter`` vertex updates; ``face_saliency``
    defaults to :func:`saliency` with ``saliency_options`` (``method``, ``options``).
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    check_positive(sigma_r, "sigma_r")
    n_iter = check_int(n_iter, "n_iter", minimum=0)
    vertex_iter = check_int(vertex_iter, "vertex_iter", minimum=0)
    m = F.shape[0]
    if face_saliency is None:
        from .combined import saliency as _saliency

        face_saliency = _saliency(V, F, per="face", **saliency_options)
    s = _check_face_values(face_saliency, m, "face_saliency")
    Wg = saliency_patch_weights(V, F, s)
    A = face_areas(V, F)
    C = face_centroids(V, F)
    ring = face_adjacency(F, shared="vertex").tocsr()
    rows = np.repeat(np.arange(m), np.diff(ring.indptr))
    cols = ring.indices
    d = np.linalg.norm(C[rows] - C[cols], axis=1)
    cnt = np.maximum(np.diff(ring.indptr), 1)
    sigma1 = np.bincount(rows, weights=d, minlength=m) / cnt
    sigma1[sigma1 <= 0] = d.mean() if d.size else 1.0
    # spatial part with the face itself included (W1_ii = 1)
    rows_all = np.r_[rows, np.arange(m)]
    cols_all = np.r_[cols, np.arange(m)]
    d_all = np.r_[d, np.zeros(m)]
    w_sp = A[cols_all] * np.exp(-(d_all**2) / (2.0 * sigma1[rows_all] ** 2))
    N = face_normals(V, F)
    for _ in range(n_iter):
        g = _unit(np.asarray(Wg @ N))
        w = w_sp * np.exp(-np.sum((g[rows_all] - g[cols_all]) ** 2, axis=1) / (2.0 * sigma_r**2))
        Wt = sp.csr_matrix((w, (rows_all, cols_all)), shape=(m, m))
        Nn = _unit(np.asarray(Wt @ N))
        empty = ~Nn.any(axis=1)
        Nn[empty] = N[empty]
        N = Nn
    return update_vertices(V, F, N, n_iter=vertex_iter) if vertex_iter else V.copy()


__all__ = [
    "first_ring_patches",
    "saliency_denoise",
    "saliency_guided_normals",
    "saliency_patch_weights",
    "select_patches_by_saliency",
]
