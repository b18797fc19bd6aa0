"""Classification of faces and vertices into corners, edges and flat areas (Section 4.4, Eq. 4.14-4.15):
a deterministic 3-means of the eigenvalues of ``R_i = N_i^T N_i / k`` of each patch of normals
(docs/decisions.md#geometry-feature-floor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, as_rng, check_positive
from .neighbors import knn
from .primitives import face_centroids, face_normals, vertex_normals

FLAT = 0
EDGE = 1
CORNER = 2
LABEL_NAMES = ("flat", "edge", "corner")

_EIG_CHUNK = 500_000
_KMEANS_FIT_MAX = 200_000


@dataclass(frozen=True)
class FeatureClasses:
    """Result of :func:`classify_faces` / :func:`classify_vertices`: ``labels`` (m,) int8 (0 flat,
    1 edge, 2 corner), ascending ``eigenvalues`` (m, 3) of ``R_i / k``, patch ``neighbors`` (m, k),
    class ``centers`` (3, 3), and the 3-means ``n_iter``, ``converged`` and ``residual`` (inertia).
    """

    labels: np.ndarray
    eigenvalues: np.ndarray
    neighbors: np.ndarray
    centers: np.ndarray
    n_iter: int
    converged: bool
    residual: float

    @property
    def is_feature(self) -> np.ndarray:
        """(m,) bool: corner or edge (the "feature" class of Section 5.1.1)."""
        return self.labels != FLAT

    @property
    def counts(self) -> dict[str, int]:
        """Number of elements per class name."""
        c = np.bincount(self.labels, minlength=3)
        return {name: int(c[i]) for i, name in enumerate(LABEL_NAMES)}


def patch_matrix(neighbors: np.ndarray, n_elements: int | None = None) -> sp.csr_matrix:
    """Sparse binary (m, m) matrix ``M`` with ``M[i, j] = 1`` when ``j`` is in the patch of ``i``."""
    nb = np.asarray(neighbors, dtype=np.int64)
    m, k = nb.shape
    n = m if n_elements is None else int(n_elements)
    M = sp.csr_matrix(
        (np.ones(m * k), nb.ravel(), np.arange(0, m * k + 1, k, dtype=np.int64)), shape=(m, n)
    )
    M.sum_duplicates()
    M.data[:] = 1.0
    return M


def patch_eigenvalues(normals: np.ndarray, neighbors: np.ndarray) -> np.ndarray:
    """Ascending eigenvalues (m, 3) of ``R_i = N_i^T N_i / k`` for unit ``normals`` (m, 3) and
    patch ``neighbors`` (m, k) (Eq. 4.14-4.15).
    """
    N = np.asarray(normals, dtype=np.float64)
    nb = np.asarray(neighbors, dtype=np.int64)
    k = nb.shape[1]
    prods = np.stack(
        [
            N[:, 0] * N[:, 0],
            N[:, 1] * N[:, 1],
            N[:, 2] * N[:, 2],
            N[:, 0] * N[:, 1],
            N[:, 0] * N[:, 2],
            N[:, 1] * N[:, 2],
        ],
        axis=1,
    )
    S = (patch_matrix(nb, N.shape[0]) @ prods) / k
    return _sym3_eigvalsh(S)


def _sym3_eigvalsh(S: np.ndarray) -> np.ndarray:
    """Eigenvalues (ascending) of symmetric 3x3 matrices given as (m, 6) [xx, yy, zz, xy, xz, yz]."""
    m = S.shape[0]
    out = np.empty((m, 3))
    for s in range(0, m, _EIG_CHUNK):
        c = S[s : s + _EIG_CHUNK]
        R = np.empty((len(c), 3, 3))
        R[:, 0, 0], R[:, 1, 1], R[:, 2, 2] = c[:, 0], c[:, 1], c[:, 2]
        R[:, 0, 1] = R[:, 1, 0] = c[:, 3]
        R[:, 0, 2] = R[:, 2, 0] = c[:, 4]
        R[:, 1, 2] = R[:, 2, 1] = c[:, 5]
        out[s : s + len(c)] = np.linalg.eigvalsh(R)
    return out


@numba.njit(cache=True)
def _assign(X, centers, labels, sums, counts):  # pragma: no cover - jitted
    """One Lloyd pass: nearest centre per row, cluster sums and counts; whether a label changed."""
    m, d = X.shape
    kc = centers.shape[0]
    sums[:] = 0.0
    counts[:] = 0
    changed = False
    for i in range(m):
        best = 0
        bd = np.inf
        for c in range(kc):
            dist = 0.0
            for a in range(d):
                t = X[i, a] - centers[c, a]
                dist += t * t
            if dist < bd:
                bd = dist
                best = c
        if labels[i] != best:
            changed = True
            labels[i] = best
        counts[best] += 1
        for a in range(d):
            sums[best, a] += X[i, a]
    return changed


def _lloyd(X: np.ndarray, centers: np.ndarray, max_iter: int):
    """Lloyd iterations (compiled assignment + centre update in one pass over the rows)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    labels = np.full(X.shape[0], -1, dtype=np.int64)
    sums = np.empty_like(centers)
    counts = np.empty(centers.shape[0], dtype=np.int64)
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - returned after the loop
        if not _assign(X, centers, labels, sums, counts):
            converged = True
            break
        nz = counts > 0
        centers[nz] = sums[nz] / counts[nz, None]
    return labels, centers, it, converged


def cluster_eigenvalues(
    eigenvalues: np.ndarray, *, min_feature: float = 0.02, max_iter: int = 100, rng=None
):
    """3-means of normalised patch eigenvalues (m, 3) into flat / edge / corner (Section 4.4).

    ``min_feature`` is the floor on a feature cluster's mean ``l2`` (0: plain 3-means),
    ``max_iter`` bounds the Lloyd iterations, ``rng`` subsamples the fit above 200,000 points.
    Returns ``(labels (m,) int8, centers (3, 3), n_iter, converged, residual)``.
    """
    X = np.asarray(eigenvalues, dtype=np.float64)
    m = X.shape[0]
    fit = X
    if m > _KMEANS_FIT_MAX:
        sel = as_rng(rng).choice(m, _KMEANS_FIT_MAX, replace=False)
        fit = X[np.sort(sel)]
    init = np.array([[1 / 3, 1 / 3, 1 / 3], [0.0, 0.5, 0.5], [0.0, 0.0, 1.0]])
    lab, centers, n_iter, converged = _lloyd(fit, init.copy(), max_iter)
    if fit is not X:
        d = ((X[:, None, :] - centers[None, :, :]) ** 2).sum(axis=2)
        lab = np.argmin(d, axis=1)
    # name the clusters by their centres (deterministic)
    present = [c for c in range(3) if np.any(lab == c)]
    corner = max(present, key=lambda c: (centers[c, 0], centers[c, 1]))
    rest = [c for c in present if c != corner]
    edge = max(rest, key=lambda c: centers[c, 1]) if rest else None
    mapping = np.full(3, FLAT, dtype=np.int8)
    mapping[corner] = CORNER
    if edge is not None:
        mapping[edge] = EDGE
    if len(present) < 3 or len(rest) < 2:
        # fewer than three non-empty clusters: the lowest-l2 one is flat
        if len(present) == 1:
            mapping[corner] = FLAT
        elif len(present) == 2:
            lo = min(present, key=lambda c: centers[c, 1])
            hi = max(present, key=lambda c: centers[c, 1])
            mapping[lo], mapping[hi] = FLAT, EDGE
    for c in present:
        if mapping[c] != FLAT and centers[c, 1] < min_feature:
            mapping[c] = FLAT
    labels = mapping[lab].astype(np.int8)
    ordered = np.zeros((3, 3))
    for c in range(3):
        sel = labels == c
        if sel.any():
            ordered[c] = X[sel].mean(axis=0)
    resid = float(((X - centers[lab]) ** 2).sum(axis=1).mean()) if m else 0.0
    return labels, ordered, int(n_iter), bool(converged), resid


def _check_common(patch, min_feature, n_elem, what):
    if isinstance(patch, bool) or not isinstance(patch, (int, np.integer)):
        raise InvalidInputError(f"`patch` must be an integer; got {patch!r}.")
    if patch < 3:
        raise InvalidInputError(f"`patch` must be >= 3; got {patch}.")
    if patch > n_elem:
        raise InvalidInputError(f"`patch` = {patch} exceeds the number of {what} ({n_elem}).")
    check_positive(min_feature, "min_feature", allow_zero=True)


def _as_normals(normals, m: int, name: str = "normals") -> np.ndarray:
    N = np.asarray(normals, dtype=np.float64)
    if N.shape != (m, 3):
        raise InvalidInputError(f"`{name}` must have shape ({m}, 3); got {N.shape}.")
    if not np.isfinite(N).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    norm = np.linalg.norm(N, axis=1, keepdims=True)
    return np.divide(N, norm, out=np.zeros_like(N), where=norm > 0)


def _check_some_area(N: np.ndarray) -> None:
    """Refuse a mesh without any face of positive area (all patches would be flat)."""
    if not np.any(np.einsum("ij,ij->i", N, N) > 0):
        raise InvalidInputError(
            "every face of the mesh is degenerate (zero area): there are no normals to classify."
        )


def classify_faces(
    V, F, *, patch: int = 15, normals=None, min_feature: float = 0.02, rng=None
) -> FeatureClasses:
    """Label every face as corner, edge or flat (Section 4.4, Eq. 4.14-4.15).

    Parameters
    ----------
    V, F : (n, 3) float, (m, 3) int
    patch : int
        Nearest faces by centroid (itself included) forming ``N_i``; larger finds larger features.
    normals, min_feature, rng
        Face normals to analyse (default those of ``(V, F)``); see :func:`cluster_eigenvalues`.

    Examples
    --------
    >>> fc = classify_faces(V, F, patch=15)          # doctest: +SKIP
    >>> fc.counts                                    # doctest: +SKIP
    {'flat': 11000, 'edge': 1800, 'corner': 146}
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    m = F.shape[0]
    _check_common(patch, min_feature, m, "faces")
    if normals is None:
        N = face_normals(V, F)
        _check_some_area(N)
    else:
        N = _as_normals(normals, m)
    nb, _ = knn(face_centroids(V, F), int(patch), include_self=True)
    ev = patch_eigenvalues(N, nb)
    labels, centers, n_iter, conv, res = cluster_eigenvalues(ev, min_feature=min_feature, rng=rng)
    return FeatureClasses(labels, ev, nb, centers, n_iter, conv, res)


def classify_vertices(
    V, F=None, *, patch: int = 15, normals=None, min_feature: float = 0.02, rng=None
) -> FeatureClasses:
    """Label every vertex or point as corner, edge or flat (Section 4.4): patches of the
    ``patch`` nearest vertices, with ``normals`` or the area-weighted vertex normals of ``(V, F)``
    (a point cloud, ``F=None``, needs ``normals``). Returns a :class:`FeatureClasses`.
    """
    V = as_points(V, "V")
    n = V.shape[0]
    if F is not None:
        F = as_faces(F, n, "F")
    _check_common(patch, min_feature, n, "vertices")
    if normals is not None:
        N = _as_normals(normals, n)
    elif F is not None:
        _check_some_area(face_normals(V, F))
        N = vertex_normals(V, F, weighting="area")
    else:
        raise InvalidInputError("`normals` is required when `F` is None (a point cloud).")
    nb, _ = knn(V, int(patch), include_self=True)
    ev = patch_eigenvalues(N, nb)
    labels, centers, n_iter, conv, res = cluster_eigenvalues(ev, min_feature=min_feature, rng=rng)
    return FeatureClasses(labels, ev, nb, centers, n_iter, conv, res)


__all__ = [
    "CORNER",
    "EDGE",
    "FLAT",
    "LABEL_NAMES",
    "FeatureClasses",
    "classify_faces",
    "classify_vertices",
    "cluster_eigenvalues",
    "patch_eigenvalues",
    "patch_matrix",
]
