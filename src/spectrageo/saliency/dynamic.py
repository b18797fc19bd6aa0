"""Saliency of mesh animations with per-frame reuse (Section 6.1.2, Eq. 6.16)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, check_positive, options_with_legacy
from ..geometry.primitives import face_areas, vertex_face_matrix
from ..graph.adjacency import knn
from ._common import check_k, mesh_normals
from ._options import SaliencyOptions
from .combined import saliency_components
from .geometric import geometric_face_values
from .spectral import spectral_face_values


@dataclass(frozen=True)
class AnimationSaliency:
    """Result of :func:`animation_saliency`: ``values`` (T, n) and ``recomputed`` (T, n) bool."""

    values: np.ndarray
    recomputed: np.ndarray

    @property
    def recomputed_fraction(self) -> np.ndarray:
        """(T,) fraction of the vertices recomputed per frame."""
        return self.recomputed.mean(axis=1)


def first_ring_areas(V, F) -> np.ndarray:
    """Area of the faces around every vertex, ``A(i, l)`` of Eq. (6.16)."""
    V = np.asarray(V, dtype=np.float64)
    return np.asarray(vertex_face_matrix(F, V.shape[0]) @ face_areas(V, F)).ravel()


def area_change(A_prev, A_cur) -> np.ndarray:
    """``d = |A_cur - A_prev| / max(A_prev, A_cur)`` of Eq. (6.16); 0 where both vanish."""
    den = np.maximum(A_prev, A_cur)
    return np.divide(np.abs(A_cur - A_prev), den, out=np.zeros_like(den), where=den > 0)


def _norm(raw, lo, hi):
    span = hi - lo
    if span <= 0:
        return np.zeros_like(raw)
    return np.clip((raw - lo) / span, 0.0, 1.0)


def animation_saliency(
    frames,
    F,
    options: SaliencyOptions | None = None,
    *,
    threshold: float = 0.1,
    method: str = "combined",
    **legacy,
) -> AnimationSaliency:
    """Per-vertex saliency (T, n) of every frame, recomputing only where ``d >= threshold``
    (Eq. 6.16, thesis 0.1) with frame 0's bounds; ``options``, ``method`` as in :func:`saliency`.
    """
    X = np.asarray(frames, dtype=np.float64)
    if X.ndim != 3 or X.shape[2] != 3 or X.shape[0] < 1:
        raise InvalidInputError(f"`frames` must have shape (T, n, 3) with T >= 1; got {X.shape}.")
    if not np.isfinite(X).all():
        raise InvalidInputError("`frames` contains NaN or inf values.")
    T, n, _ = X.shape
    F = as_faces(F, n, "F")
    check_positive(threshold, "threshold", allow_zero=True)
    opts = options_with_legacy(options, legacy, SaliencyOptions, "animation_saliency")
    k = check_k(opts.k, F.shape[0])
    w1, w2 = opts.weights
    normals = opts.normals
    comp = saliency_components(X[0], F, opts, method=method)
    geo_opts = opts.geometric()
    b2 = (comp.spectral_raw.min(), comp.spectral_raw.max())
    b1 = None
    if comp.geometric_raw is not None:
        b1 = (comp.geometric_raw.min(), comp.geometric_raw.max())
    face_vals = comp.combined.copy()
    A = vertex_face_matrix(F, n).tocsr().astype(np.float64)
    deg = np.asarray(A.sum(axis=1)).ravel()
    AT = A.T.tocsr()
    values = np.empty((T, n))
    recomputed = np.zeros((T, n), dtype=bool)
    values[0] = np.divide(A @ face_vals, deg, out=np.zeros(n), where=deg > 0)
    recomputed[0] = True
    areas_prev = first_ring_areas(X[0], F)
    m = F.shape[0]
    for t in range(1, T):
        areas = first_ring_areas(X[t], F)
        changed = area_change(areas_prev, areas) >= threshold
        areas_prev = areas
        values[t] = values[t - 1]
        if not changed.any():
            continue
        recomputed[t] = changed
        faces = np.flatnonzero(np.asarray(AT @ changed.astype(np.float64)).ravel() > 0)
        V = X[t]
        N = mesh_normals(V, F, normals)
        C = V[F].mean(axis=1)
        # the face is its own nearest centroid: query k + 1 and move it out (stable sort)
        nb, _ = knn(C, k + 1, query=C[faces])
        order = np.argsort(nb == faces[:, None], axis=1, kind="stable")
        patches = np.c_[faces, np.take_along_axis(nb, order, axis=1)[:, :k]]
        s2 = _norm(spectral_face_values(N, patches), *b2)
        if method == "spectral":
            new = s2
        else:
            lam = 1.0 / np.sqrt(max(m, 3 * (k + 1)))
            g = geometric_face_values(N, patches, lam=lam, **geo_opts)
            s1 = _norm(g.values, *b1)
            new = s1 if method == "geometric" else (w1 * s1 + w2 * s2) / (w1 + w2)
        face_vals[faces] = new
        ring = np.asarray(A[changed] @ face_vals).ravel()
        values[t, changed] = ring / np.maximum(deg[changed], 1)
    return AnimationSaliency(values, recomputed)


__all__ = ["AnimationSaliency", "animation_saliency", "area_change", "first_ring_areas"]
