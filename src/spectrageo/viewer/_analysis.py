"""The computations the viewer shows: feature vertices, feature curves and scalar fields.

Every call into the feature/saliency packages goes through this module. Feature vertices
(Appendix C) of a mesh come from :func:`spectrageo.saliency.feature_vertices` (Section 6.1.1,
Eq. 6.1-6.4); without it, and for point clouds, from the patch classification of Section 4.4
(Eq. 4.14-4.15: edges and corners). Feature curves (Section 6.1.1) come from
:func:`spectrageo.saliency.feature_curves`, else from k-means on the curvature of the feature
vertices, 2-5 clusters by the Calinski-Harabasz score (for point clouds the surface variation
``l1 / (l1 + l2 + l3)`` of the kNN covariance stands in for the curvature).
"""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError

#: Names of the detectors (reported in the UI and the JSON API).
SALIENCY_SOURCE = (
    "spectrageo.saliency.feature_vertices (Section 6.1.1, Eq. 6.1-6.4, 5-class k-means)"
)
FEATURE_SOURCE = "spectrageo.geometry.features.classify_vertices (Section 4.4, Eq. 4.14-4.15)"


def _saliency_fn(name: str):
    try:
        from .. import saliency as _sal
    except ImportError:  # pragma: no cover - the package is part of spectrageo
        return None
    return getattr(_sal, name, None)


def point_normals(P: np.ndarray, normals=None) -> np.ndarray:
    """Normals of a point cloud: the stored ones when present, else PCA normals (Eq. 6.31)."""
    if normals is not None and np.shape(normals) == np.shape(P):
        return np.asarray(normals, dtype=np.float64)
    from ..geometry import pca_normals

    return pca_normals(P, k=min(10, max(3, len(P) - 1)))


def feature_vertices(V, F=None, *, patch: int = 15, normals=None) -> tuple[np.ndarray, str]:
    """Boolean (n,) mask of the feature vertices and the name of the method used.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int or None (point cloud)
    patch : int
        Patch size (Appendix C default 15).
    normals : (n, 3) float, optional
        Point-cloud normals; PCA normals when absent.
    """
    custom = _saliency_fn("feature_vertices")
    if custom is not None and F is not None:
        res = custom(V, F, patch=patch)
        return np.asarray(getattr(res, "mask", res), dtype=bool), SALIENCY_SOURCE
    from ..geometry.features import classify_vertices

    if F is None:
        normals = point_normals(V, normals)
        fc = classify_vertices(V, None, patch=patch, normals=normals)
    else:
        fc = classify_vertices(V, F, patch=patch)
    return np.asarray(fc.is_feature, dtype=bool), FEATURE_SOURCE


def curvature(V, F=None) -> np.ndarray:
    """Per-vertex curvature used for the feature curves: mean curvature (mesh) or surface variation."""
    if F is not None:
        from ..geometry import mean_curvature

        return np.asarray(mean_curvature(V, F), dtype=np.float64)
    from ..graph import knn

    P = np.asarray(V, dtype=np.float64)
    k = min(10, max(2, len(P) - 1))
    idx, _ = knn(P, k, include_self=True)
    Q = P[idx] - P[idx].mean(axis=1, keepdims=True)
    C = np.einsum("nki,nkj->nij", Q, Q) / k
    ev = np.linalg.eigvalsh(C)
    tot = ev.sum(axis=1)
    return np.divide(ev[:, 0], tot, out=np.zeros_like(tot), where=tot > 0)


def feature_curves(
    V, F, mask: np.ndarray, *, patch: int = 15, max_curves: int = 5, rng=0
) -> np.ndarray:
    """Curve label per vertex (-1 off the features), Section 6.1.1; ``mask`` comes from
    :func:`feature_vertices` with the same ``patch``. The fallback (module docstring) numbers the
    clusters by increasing curvature of their centres (deterministic for a fixed ``rng``)."""
    lib = _saliency_fn("feature_curves")
    if lib is not None and F is not None and _saliency_fn("feature_vertices") is not None:
        return np.asarray(lib(V, F, patch=patch, max_curves=max_curves).labels, dtype=np.int32)
    return _curves_fallback(V, F, mask, max_curves=max_curves, rng=rng)


def _curves_fallback(V, F, mask, *, max_curves: int = 5, rng=0) -> np.ndarray:
    from sklearn.cluster import KMeans
    from sklearn.metrics import calinski_harabasz_score

    mask = np.asarray(mask, dtype=bool)
    labels = np.full(mask.shape[0], -1, dtype=np.int32)
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return labels
    mc = curvature(V, F)[idx]
    lo, hi = float(mc.min()), float(mc.max())
    x = ((mc - lo) / (hi - lo) if hi > lo else np.zeros_like(mc))[:, None]
    n_distinct = len(np.unique(np.round(x[:, 0], 12)))
    best, best_score = np.zeros(idx.size, dtype=np.int32), -np.inf
    for c in range(2, min(max_curves, n_distinct) + 1):
        km = KMeans(n_clusters=c, n_init=4, random_state=rng).fit(x)
        score = calinski_harabasz_score(x, km.labels_)
        if score > best_score:
            order = np.argsort(np.argsort(km.cluster_centers_[:, 0]))
            best, best_score = order[km.labels_].astype(np.int32), score
    labels[idx] = best
    return labels


def vertex_field(values, n_vertices: int, F=None) -> np.ndarray:
    """A per-vertex (n,) or per-face (m,) scalar field as per-vertex float64: face values averaged
    over each vertex's incident faces (first-ring mean, Eq. 6.14); NaN (grey) without faces."""
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == n_vertices:
        return v
    if F is not None and v.size == len(F):
        F = np.asarray(F, dtype=np.int64)
        s = np.bincount(F.ravel(), weights=np.repeat(v, 3), minlength=n_vertices)
        c = np.bincount(F.ravel(), minlength=n_vertices).astype(np.float64)
        return np.divide(s, c, out=np.full(n_vertices, np.nan), where=c > 0)
    nf = "" if F is None else f" or faces ({len(F)})"
    raise InvalidInputError(
        f"scalar field has {v.size} values; expected one per vertex ({n_vertices}){nf}."
    )


def saliency_field(V, F, *, method: str = "spectral") -> np.ndarray:
    """Per-vertex saliency of a mesh (Section 6.1.2), via :func:`spectrageo.saliency.saliency`."""
    from .. import saliency as _sal

    return np.asarray(_sal.saliency(V, F, method=method, per="vertex"), dtype=np.float64)
