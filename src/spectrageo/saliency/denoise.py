"""Saliency-aware guided denoising (Section 6.1.3, Eq. 6.20-6.23).

Guided normal filtering needs, for every face, an "ideal" patch whose normals agree. Here the ideal
patch is chosen by the saliency map: among the candidate patches of face ``f_i`` (the first-ring
face patches that contain it) the one with the smallest mean face saliency ``Xi`` is taken
(Eq. 6.20-6.21), since low saliency marks flat, consistent areas. The guided normal of the face is
the area-weighted mean normal of that patch, and a joint bilateral filter (Eq. 6.22-6.23) smooths
the face normals, followed by the vertex update of Section 4.7.

Building blocks for other denoisers:

* :func:`select_patches_by_saliency` (Eq. 6.20-6.21) takes any binary patch matrix ``P``
  (``P[j, l] = 1`` when face ``l`` is in the patch centred at ``j``, the convention of
  ``spectrageo.denoise``) and returns the centre of the chosen patch of every face;
* :func:`saliency_patch_weights` gives the same choice as a sparse row-stochastic (m, m) matrix of
  area weights: ``W @ N`` (then row-normalised) is the saliency-guided normal field;
* :func:`saliency_guided_normals` and :func:`saliency_denoise` are the whole method.
"""

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
    """Binary (m, m) CSR patch matrix of the first-ring face patches (faces sharing a vertex)."""
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
    """Ideal patch of every face: the candidate with the lowest mean saliency (Eq. 6.20-6.21).

    Parameters
    ----------
    face_saliency : (m,) float
        Per-face saliency ``s_g``.
    P : (m, m) sparse binary
        Patch matrix (row ``j`` = members of the patch centred at face ``j``). The candidate
        patches of face ``i`` are those containing it (column ``i``).

    Returns
    -------
    (m,) int64: centre of the chosen patch of every face (ties: lowest centre index; a face in no
    patch keeps itself).
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
    """Sparse (m, m) weights of the saliency-guided normals (Eq. 6.20-6.21 then area mean).

    Row ``i`` holds the face areas of the members of face ``i``'s chosen patch, divided by their sum;
    ``normalize(W @ N)`` is the guided normal field for any current normals ``N``.
    ``P`` defaults to :func:`first_ring_patches`.
    """
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
    """Guided normals from the least salient candidate patch (Eq. 6.20-6.21), shape (m, 3).

    ``face_saliency`` defaults to :func:`spectrageo.saliency.saliency` (``per="face"``, with
    ``saliency_options``); ``normals`` to the face normals of ``(V, F)``.
    """
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
    """Saliency-aware guided denoising (Eq. 6.20-6.23 and the vertex update of Section 4.7).

    Each of the ``n_iter`` iterations recomputes the guided normals ``g`` of the current face
    normals on the saliency-chosen patches and applies the joint bilateral filter over the
    first-ring faces ``Psi_1i``::

        n_i <- normalize( sum_j A_j W1_ij W2_ij n_j ),
        W1_ij = exp(-||c_i - c_j||^2 / (2 sigma_1i^2)),  W2_ij = exp(-||g_i - g_j||^2 / (2 sigma_r^2))

    then ``vertex_iter`` vertex updates (Eq. 4.28-4.29) fit the vertices to the normals. The thesis
    sets ``sigma_1i`` to the mean *squared* centroid distance over ``Psi_1i``, which has units of
    length squared; the mean distance is used instead (same role, consistent units).

    Parameters
    ----------
    V, F : noisy mesh
    face_saliency : (m,) float, optional
        Per-face saliency of the noisy mesh (default: :func:`spectrageo.saliency.saliency` with
        ``saliency_options``, computed once).
    sigma_r : float
        Range width ``sigma_2`` (thesis: 0.25).
    n_iter, vertex_iter : int
        Normal-filtering and vertex-update iterations (thesis: 15 and 20).

    Returns
    -------
    (n, 3) float64 denoised vertices.
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
