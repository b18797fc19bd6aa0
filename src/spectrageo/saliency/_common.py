"""Helpers shared by the saliency modules."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice
from ..geometry.primitives import face_areas, face_centroids, face_normals, vertex_face_matrix
from ..graph.adjacency import knn

#: Normals a saliency map can be computed from.
NORMALS = ("guided", "face")
#: Element a map is reported on.
PER = ("vertex", "face")


def check_mesh(V, F, names=("V", "F")) -> tuple[np.ndarray, np.ndarray]:
    """``(V, F)`` validated; a mesh without a face of positive area is refused."""
    V = as_points(V, names[0])
    F = as_faces(F, V.shape[0], names[1])
    if F.shape[0] and not (face_areas(V, F) > 0).any():
        what = "the mesh" if names[0] == "V" else f"the mesh `{names[0]}`"
        raise InvalidInputError(
            f"every face of {what} is degenerate (zero area: its vertices coincide or are "
            "collinear); saliency is undefined there."
        )
    return V, F


def check_int(value, name: str, *, minimum: int = 1, maximum: int | None = None) -> int:
    """An integer ``minimum <= value <= maximum`` (bools rejected)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise InvalidInputError(f"`{name}` must be an integer; got {value!r}.")
    if value < minimum:
        raise InvalidInputError(f"`{name}` must be >= {minimum}; got {value}.")
    if maximum is not None and value > maximum:
        raise InvalidInputError(f"`{name}` must be <= {maximum}; got {value}.")
    return int(value)


def check_k(k, n_faces: int, name: str = "k") -> int:
    """Patch size ``k``, needing ``k + 1 <= n_faces``."""
    k = check_int(k, name, minimum=2)
    if k + 1 > n_faces:
        raise InvalidInputError(
            f"`{name}` = {k} needs at least {k + 1} faces (the face and its {k} neighbours); "
            f"the mesh has {n_faces}."
        )
    return k


def minmax(x: np.ndarray, *, rtol: float = 1e-9) -> np.ndarray:
    """Min-max normalisation to [0, 1] (Eq. 6.4, 6.12); zeros for a spread below ``rtol``."""
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return x.copy()
    lo, hi = float(x.min()), float(x.max())
    scale = max(abs(lo), abs(hi), np.finfo(float).tiny)
    if hi - lo <= rtol * scale:
        return np.zeros_like(x)
    return (x - lo) / (hi - lo)


def face_patches(centroids: np.ndarray, k: int) -> np.ndarray:
    """(m, k + 1) int64 patches: each face, then its ``k`` nearest faces by centroid."""
    nb, _ = knn(centroids, k, include_self=False)
    return np.concatenate([np.arange(centroids.shape[0])[:, None], nb], axis=1)


def mesh_normals(V: np.ndarray, F: np.ndarray, normals) -> np.ndarray:
    """Face normals: "face" (Eq. 3.2), "guided" (Eq. 4.8-4.11) or a given (m, 3) array."""
    if isinstance(normals, str):
        check_choice(normals, "normals", NORMALS)
        N = face_normals(V, F)
        if normals == "face":
            return N
        from ..denoise._normals import guided_normals, patch_matrix

        return guided_normals(N, face_areas(V, F), patch_matrix(F))
    N = np.asarray(normals, dtype=np.float64)
    if N.shape != F.shape:
        raise InvalidInputError(f"`normals` must have shape {F.shape}; got {N.shape}.")
    if not np.isfinite(N).all():
        raise InvalidInputError("`normals` contains NaN or inf values.")
    nrm = np.linalg.norm(N, axis=1, keepdims=True)
    return np.divide(N, nrm, out=np.zeros_like(N), where=nrm > 0)


def face_to_vertex(values: np.ndarray, F: np.ndarray, n_vertices: int) -> np.ndarray:
    """First-ring mean of face values at every vertex (Eq. 6.14); isolated vertices 0."""
    A = vertex_face_matrix(F, n_vertices)
    deg = np.asarray(A.sum(axis=1)).ravel()
    out = np.asarray(A @ np.asarray(values, dtype=np.float64)).ravel()
    return np.divide(out, deg, out=np.zeros_like(out), where=deg > 0)


def vertex_ring_matrix(F: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """Row-normalised (n, m) vertex-face incidence: ``A @ s_face`` is Eq. 6.14."""
    A = vertex_face_matrix(F, n_vertices).astype(np.float64)
    deg = np.asarray(A.sum(axis=1)).ravel()
    inv = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    return sp.diags(inv) @ A


def centroids_of(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    return face_centroids(V, F)
