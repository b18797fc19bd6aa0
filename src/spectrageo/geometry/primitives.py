"""Per-face and per-vertex quantities of triangle meshes (thesis Chapter 3). Zero-area faces and
isolated vertices get zero normals, never NaN.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._validation import as_faces, as_points, check_choice


def _VF(V, F):  # noqa: N802
    V = as_points(V, "V")
    return V, as_faces(F, V.shape[0], "F")


def _normalize_rows(X: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(X, axis=1, keepdims=True)
    out = np.zeros_like(X)
    np.divide(X, norm, out=out, where=norm > 0)
    return out


def face_centroids(V, F) -> np.ndarray:
    """Face centroids ``c = (v1 + v2 + v3) / 3`` (Eq. 3.1), shape (m, 3)."""
    V, F = _VF(V, F)
    return V[F].mean(axis=1)


def _face_cross(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    v0, v1, v2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return np.cross(v1 - v0, v2 - v0)


def face_normals(V, F, *, unit: bool = True) -> np.ndarray:
    """Face normals ``(v2 - v1) x (v3 - v1)`` (Eq. 3.2), (m, 3): unit (zero for degenerate faces)
    or, with ``unit=False``, of length twice the face area.
    """
    V, F = _VF(V, F)
    cr = _face_cross(V, F)
    return _normalize_rows(cr) if unit else cr


def face_areas(V, F) -> np.ndarray:
    """Triangle areas, shape (m,)."""
    V, F = _VF(V, F)
    return 0.5 * np.linalg.norm(_face_cross(V, F), axis=1)


def vertex_face_matrix(F, n_vertices: int) -> sp.csr_matrix:
    """Sparse (n, m) incidence matrix: entry (i, j) = 1 if vertex i belongs to face j."""
    F = as_faces(F, n_vertices, "F")
    m = F.shape[0]
    rows = F.ravel()
    cols = np.repeat(np.arange(m), 3)
    A = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n_vertices, m))
    A.sum_duplicates()
    A.data[:] = 1.0
    return A


def vertex_normals(V, F, *, weighting: str = "mean") -> np.ndarray:
    """Unit vertex normals (n, 3): mean of the incident unit face normals (Eq. 3.3) or
    area-weighted (``weighting="area"``); zero for isolated vertices.
    """
    check_choice(weighting, "weighting", ("mean", "area"))
    V, F = _VF(V, F)
    fn = face_normals(V, F, unit=(weighting == "mean"))
    A = vertex_face_matrix(F, V.shape[0])
    return _normalize_rows(np.asarray(A @ fn))


def edges(F, n_vertices: int | None = None) -> np.ndarray:
    """Unique undirected edges ``(i, j)`` with ``i < j``, shape (e, 2), sorted lexicographically."""
    F = np.asarray(F)
    if n_vertices is not None:
        F = as_faces(F, n_vertices, "F")
    F = np.asarray(F, dtype=np.int64)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E.sort(axis=1)
    E = E[E[:, 0] != E[:, 1]]
    if E.size == 0:
        return E.reshape(0, 2)
    # sorted 1-D keys are much faster than np.unique(axis=0); i * n + j orders like (i, j)
    n = np.int64(E.max()) + 1
    key = np.sort(E[:, 0] * n + E[:, 1])
    key = key[np.r_[True, key[1:] != key[:-1]]]
    return np.stack([key // n, key % n], axis=1)


def edge_lengths(V, F) -> np.ndarray:
    """Lengths of the unique edges returned by :func:`edges`, shape (e,)."""
    V, F = _VF(V, F)
    E = edges(F)
    return np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)


def mean_edge_length(V, F) -> float:
    """Mean length of the unique edges (the ``l`` of Eq. 4.36)."""
    el = edge_lengths(V, F)
    return float(el.mean()) if el.size else 0.0


def boundary_edges(F, n_vertices: int | None = None) -> np.ndarray:
    """Edges used by exactly one face, shape (b, 2), oriented as in their face."""
    F = np.asarray(F, dtype=np.int64)
    if n_vertices is not None:
        F = as_faces(F, n_vertices, "F")
    H = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(H, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return H[counts[inv.ravel()] == 1]


def boundary_loops(F, n_vertices: int | None = None) -> list[np.ndarray]:
    """Closed boundary loops as vertex index arrays; non-manifold boundaries are split at the
    pinch vertex deterministically.
    """
    B = boundary_edges(F, n_vertices)
    if B.size == 0:
        return []
    order = np.argsort(B[:, 0], kind="stable")
    B = B[order]
    used = np.zeros(len(B), dtype=bool)
    starts = np.searchsorted(B[:, 0], B[:, 0], side="left")
    first = {int(v): int(s) for v, s in zip(B[:, 0], starts)}
    loops = []
    for e0 in range(len(B)):
        if used[e0]:
            continue
        loop = [int(B[e0, 0])]
        used[e0] = True
        cur = int(B[e0, 1])
        while cur != loop[0]:
            loop.append(cur)
            s = first.get(cur)
            if s is None:
                break
            k = s
            while k < len(B) and B[k, 0] == cur and used[k]:
                k += 1
            if k >= len(B) or B[k, 0] != cur:
                break
            used[k] = True
            cur = int(B[k, 1])
        loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def cotangent_weights(V, F) -> sp.csr_matrix:
    """Symmetric sparse (n, n) cotangent weights ``(cot a + cot b) / 2`` (zero for degenerate
    triangles).
    """
    V, F = _VF(V, F)
    n = V.shape[0]
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, o = F[:, (k + 1) % 3], F[:, (k + 2) % 3], F[:, k]
        a = V[i] - V[o]
        b = V[j] - V[o]
        cross = np.linalg.norm(np.cross(a, b), axis=1)
        dot = np.einsum("ij,ij->i", a, b)
        cot = np.zeros_like(dot)
        np.divide(dot, cross, out=cot, where=cross > 1e-300)
        rows += [i, j]
        cols += [j, i]
        vals += [0.5 * cot, 0.5 * cot]
    W = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )
    W.sum_duplicates()
    return W


def vertex_areas(V, F) -> np.ndarray:
    """Barycentric vertex areas (one third of the incident face areas), shape (n,)."""
    V, F = _VF(V, F)
    A = face_areas(V, F)
    return np.bincount(F.ravel(), weights=np.repeat(A / 3.0, 3), minlength=V.shape[0])


def mean_curvature(V, F) -> np.ndarray:
    """Signed mean curvature (n,) from ``H n = (L_cot V) / (2 A)`` with barycentric areas,
    positive on convex parts of an outward-oriented surface; 0 where the area is zero.
    """
    V, F = _VF(V, F)
    W = cotangent_weights(V, F)
    d = np.asarray(W.sum(axis=1)).ravel()
    LV = d[:, None] * V - W @ V  # cotangent Laplacian applied to V (positive semi-definite form)
    A = vertex_areas(V, F)
    Hn = np.zeros_like(V)
    np.divide(LV, (2.0 * A)[:, None], out=Hn, where=A[:, None] > 0)
    H = np.linalg.norm(Hn, axis=1)
    sign = np.sign(np.einsum("ij,ij->i", Hn, vertex_normals(V, F, weighting="area")))
    sign[sign == 0] = 1.0
    return H * sign
