"""Feature vertices, feature curves and model similarity (Section 6.1.1, Eq. 6.1-6.7)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._errors import InvalidInputError
from .._validation import as_faces, as_points
from ..geometry.features import patch_eigenvalues
from ..geometry.primitives import edges as mesh_edges
from ..geometry.primitives import mean_curvature, vertex_normals
from ..graph.adjacency import knn
from ._common import check_int, minmax

#: Number of saliency classes of the feature-vertex step and how many of the highest are features.
N_SALIENCY_CLASSES = 5
N_FEATURE_CLASSES = 3


def _check_values(values, n: int | None, name: str) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 1 or (n is not None and v.shape[0] != n):
        want = f"({n},)" if n is not None else "(n,)"
        raise InvalidInputError(f"`{name}` must have shape {want}; got {v.shape}.")
    if not np.isfinite(v).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    return v


def kmeans_1d(values, n_clusters: int, *, max_iter: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic 1-D k-means from quantiles: ``(labels, centers)`` by ascending centre."""
    x = _check_values(values, None, "values")
    n_clusters = check_int(n_clusters, "n_clusters")
    if x.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    order = np.argsort(x, kind="stable")
    xs = x[order]
    csum = np.r_[0.0, np.cumsum(xs)]
    centers = np.unique(np.quantile(xs, (np.arange(n_clusters) + 0.5) / n_clusters))
    for _ in range(max_iter):
        # boundaries between consecutive centres split the sorted data into contiguous runs
        mids = 0.5 * (centers[1:] + centers[:-1])
        cuts = np.r_[0, np.searchsorted(xs, mids, side="right"), xs.size]
        cnt = np.diff(cuts)
        keep = cnt > 0
        new = (csum[cuts[1:]] - csum[cuts[:-1]])[keep] / cnt[keep]
        if new.shape == centers.shape and np.allclose(new, centers, rtol=0, atol=1e-14):
            centers = new
            break
        centers = new
    mids = 0.5 * (centers[1:] + centers[:-1])
    labels = np.searchsorted(mids, x, side="right").astype(np.int64)
    return labels, centers


def calinski_harabasz_1d(values, labels) -> float:
    """``CH = [B / (c - 1)] / [W / (n - c)]``; nan for ``c < 2`` or ``c >= n``, inf if ``W = 0``."""
    x = np.asarray(values, dtype=np.float64)
    lab = np.asarray(labels)
    ids, inv = np.unique(lab, return_inverse=True)
    c, n = ids.size, x.size
    if c < 2 or c >= n:
        return float("nan")
    cnt = np.bincount(inv)
    mean_c = np.bincount(inv, weights=x) / cnt
    B = float((cnt * (mean_c - x.mean()) ** 2).sum())
    W = float(((x - mean_c[inv]) ** 2).sum())
    if W <= 0:
        return float("inf")
    return (B / (c - 1)) / (W / (n - c))


def vertex_spectral_saliency(V, F=None, *, patch: int = 15, normals=None) -> np.ndarray:
    """Per-vertex ``1 / ||lambda(N_i^T N_i)||_2`` over ``patch`` nearest vertices, min-max
    normalised (Eq. 6.1-6.4); ``normals`` are required when ``F`` is None.
    """
    V = as_points(V, "V")
    n = V.shape[0]
    patch = check_int(patch, "patch", minimum=2, maximum=n)
    if normals is not None:
        N = np.asarray(normals, dtype=np.float64)
        if N.shape != (n, 3):
            raise InvalidInputError(f"`normals` must have shape ({n}, 3); got {N.shape}.")
        if not np.isfinite(N).all():
            raise InvalidInputError("`normals` contains NaN or inf values.")
        nrm = np.linalg.norm(N, axis=1, keepdims=True)
        N = np.divide(N, nrm, out=np.zeros_like(N), where=nrm > 0)
    elif F is not None:
        N = vertex_normals(V, as_faces(F, n, "F"), weighting="area")
    else:
        raise InvalidInputError("`normals` is required when `F` is None (a point cloud).")
    nb, _ = knn(V, patch, include_self=True)
    ev = patch_eigenvalues(N, nb) * patch
    nrm = np.linalg.norm(ev, axis=1)
    s = np.divide(1.0, nrm, out=np.zeros_like(nrm), where=nrm > 0)
    if (nrm <= 0).any():  # patches of zero normals: as salient as the most salient valid one
        s[nrm <= 0] = s[nrm > 0].max() if (nrm > 0).any() else 0.0
    return minmax(s)


@dataclass(frozen=True)
class FeatureVertices:
    """Result of :func:`feature_vertices`: ``mask``, ``classes`` (0 least salient), ``centers``."""

    mask: np.ndarray
    classes: np.ndarray
    centers: np.ndarray
    saliency: np.ndarray

    @property
    def indices(self) -> np.ndarray:
        """Indices of the feature vertices."""
        return np.flatnonzero(self.mask)


def feature_vertices(
    V, F=None, *, saliency=None, patch: int = 15, n_classes: int = 5, n_feature_classes: int = 3
) -> FeatureVertices:
    """Feature vertices: the top ``n_feature_classes`` of ``n_classes`` k-means classes of
    the normalised saliency (default :func:`vertex_spectral_saliency`; thesis: 3 of 5).
    """
    V = as_points(V, "V")
    n = V.shape[0]
    n_classes = check_int(n_classes, "n_classes", minimum=2)
    n_feature_classes = check_int(
        n_feature_classes, "n_feature_classes", minimum=1, maximum=n_classes - 1
    )
    if saliency is None:
        if F is None:
            raise InvalidInputError("`F` is required when `saliency` is not given.")
        s = vertex_spectral_saliency(V, F, patch=patch)
    else:
        s = minmax(_check_values(saliency, n, "saliency"))
    labels, centers = kmeans_1d(s, n_classes)
    n_found = centers.size
    # classes keep their rank from the top: the most salient found class is class n_classes - 1
    classes = labels + (n_classes - n_found)
    if np.ptp(s) == 0:
        mask = np.zeros(n, dtype=bool)
        classes = np.zeros(n, dtype=np.int64)
    else:
        mask = classes >= n_classes - n_feature_classes
    return FeatureVertices(mask, classes.astype(np.int64), centers, s)


@dataclass(frozen=True)
class FeatureCurves:
    """Result of :func:`feature_curves`: ``labels`` (-1 off features), ``n_curves``, ``scores``."""

    labels: np.ndarray
    n_curves: int
    curvature: np.ndarray
    saliency: np.ndarray
    features: FeatureVertices
    scores: dict


def feature_curves(
    V,
    F,
    *,
    saliency=None,
    patch: int = 15,
    max_curves: int = 5,
    connected: bool = False,
) -> FeatureCurves:
    """Feature curves: k-means clusters of the feature vertices' mean curvature, their number in
    ``2..max_curves`` by the Calinski-Harabasz index (Section 6.1.1); optionally split by edges.
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    max_curves = check_int(max_curves, "max_curves")
    fv = feature_vertices(V, F, saliency=saliency, patch=patch)
    H = mean_curvature(V, F)
    n = V.shape[0]
    labels = np.full(n, -1, dtype=np.int64)
    idx = fv.indices
    scores: dict[int, float] = {}
    if idx.size == 0:
        return FeatureCurves(labels, 0, H, fv.saliency, fv, scores)
    h = H[idx]
    best_lab = np.zeros(idx.size, dtype=np.int64)
    best_score = -np.inf
    for c in range(2, max_curves + 1):
        if c >= idx.size:
            break
        lab, cen = kmeans_1d(h, c)
        if cen.size < c:
            continue
        sc = calinski_harabasz_1d(h, lab)
        scores[c] = sc
        if sc > best_score:
            best_score, best_lab = sc, lab
    labels[idx] = best_lab
    if connected:
        E = mesh_edges(F)
        same = (labels[E[:, 0]] == labels[E[:, 1]]) & (labels[E[:, 0]] >= 0)
        E = E[same]
        A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
        _, comp = connected_components(A, directed=False)
        _, new = np.unique(comp[idx], return_inverse=True)
        labels[idx] = new
    n_curves = int(labels.max()) + 1
    return FeatureCurves(labels, n_curves, H, fv.saliency, fv, scores)


def curve_descriptor(saliency, curvature, *, bins: int = 10) -> np.ndarray:
    """Descriptor ``q = [hist(s), hist(m_c)]`` of normalised inputs per value (Eq. 6.5-6.6)."""
    s = _check_values(saliency, None, "saliency")
    m = _check_values(curvature, s.size, "curvature")
    bins = check_int(bins, "bins", minimum=2)
    if s.size == 0:
        raise InvalidInputError("`saliency` is empty.")
    hs, _ = np.histogram(minmax(s), bins=bins, range=(0.0, 1.0))
    hm, _ = np.histogram(minmax(m), bins=bins, range=(0.0, 1.0))
    return np.r_[hs, hm].astype(np.float64) / s.size


def curve_similarity(q_a, q_b) -> float:
    """Pearson correlation of two descriptors (Eq. 6.7); 0 when one is constant."""
    a = np.asarray(q_a, dtype=np.float64).ravel()
    b = np.asarray(q_b, dtype=np.float64).ravel()
    if a.shape != b.shape:
        raise InvalidInputError(
            f"`q_a` and `q_b` must have the same length; got {a.size}, {b.size}."
        )
    da, db = a - a.mean(), b - b.mean()
    den = np.sqrt((da * da).sum() * (db * db).sum())
    return float((da * db).sum() / den) if den > 0 else 0.0


def model_descriptor(V, F, *, patch: int = 15, bins: int = 10) -> np.ndarray:
    """Descriptor (Eq. 6.5-6.6) of the feature vertices of a mesh."""
    fc = feature_curves(V, F, patch=patch)
    sel = fc.labels >= 0
    if not sel.any():  # no features: describe the whole surface
        sel = np.ones_like(sel)
    return curve_descriptor(fc.saliency[sel], fc.curvature[sel], bins=bins)


def similarity_matrix(meshes, *, patch: int = 15, bins: int = 10) -> np.ndarray:
    """(p, p) correlation of the descriptors of ``meshes``; ``1 - r`` is Fig. 6.5's distance."""
    descs = []
    for i, m in enumerate(meshes):
        if hasattr(m, "vertices") and hasattr(m, "faces"):
            V, F = m.vertices, m.faces
        else:
            try:
                V, F = m
            except (TypeError, ValueError) as exc:
                raise InvalidInputError(
                    f"`meshes[{i}]` must be a (V, F) pair or a Mesh; got {type(m).__name__}."
                ) from exc
        descs.append(model_descriptor(V, F, patch=patch, bins=bins))
    p = len(descs)
    S = np.eye(p)
    for i in range(p):
        for j in range(i + 1, p):
            S[i, j] = S[j, i] = curve_similarity(descs[i], descs[j])
    return S


__all__ = [
    "FeatureCurves",
    "FeatureVertices",
    "calinski_harabasz_1d",
    "curve_descriptor",
    "curve_similarity",
    "feature_curves",
    "feature_vertices",
    "kmeans_1d",
    "model_descriptor",
    "similarity_matrix",
    "vertex_spectral_saliency",
]
