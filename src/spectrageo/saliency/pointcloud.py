"""Point-cloud saliency and multi-scale features (Section 6.2.3, Eq. 6.30-6.36)."""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_points, check_positive
from ..geometry.features import patch_eigenvalues
from ..geometry.pointcloud import pca_normals
from ..graph.adjacency import knn
from ._common import check_int, minmax


def pointcloud_saliency(
    P, *, k: int = 20, normal_k: int = 10, normals=None, normalize: bool = True
) -> np.ndarray:
    """Spectral saliency ``1 / ||lambda(N_i^T N_i)||_2`` over ``k`` neighbours (Eq. 6.30-6.33); PCA
    normals of ``normal_k`` neighbours (Eq. 6.31) unless given; raw values if not ``normalize``.
    """
    P = as_points(P, "P")
    n = P.shape[0]
    k = check_int(k, "k", minimum=2, maximum=n - 1 if n > 1 else 2)
    if normals is None:
        N = pca_normals(P, k=check_int(normal_k, "normal_k", minimum=2), orient="none")
    else:
        N = np.asarray(normals, dtype=np.float64)
        if N.shape != (n, 3):
            raise InvalidInputError(f"`normals` must have shape ({n}, 3); got {N.shape}.")
        if not np.isfinite(N).all():
            raise InvalidInputError("`normals` contains NaN or inf values.")
        nrm = np.linalg.norm(N, axis=1, keepdims=True)
        N = np.divide(N, nrm, out=np.zeros_like(N), where=nrm > 0)
    nb, _ = knn(P, k + 1, include_self=True)
    ev = patch_eigenvalues(N, nb) * (k + 1)  # eigenvalues of C_i = N_i^T N_i
    nr = np.linalg.norm(ev, axis=1)
    s = np.divide(1.0, nr, out=np.zeros_like(nr), where=nr > 0)
    if (nr <= 0).any():
        s[nr <= 0] = s[nr > 0].max() if (nr > 0).any() else 0.0
    return minmax(s) if normalize else s


def normalize_saliency_pair(s_t, s_q, *, K_s: float = 1000.0) -> tuple[np.ndarray, np.ndarray]:
    """Joint normalisation ``1 - exp(-K_s (s - s_min))`` of two maps (Eq. 6.34, read as in
    docs/decisions.md#saliency-readings).
    """
    a = np.asarray(s_t, dtype=np.float64)
    b = np.asarray(s_q, dtype=np.float64)
    check_positive(K_s, "K_s")
    if a.ndim != 1 or b.ndim != 1 or a.size == 0 or b.size == 0:
        raise InvalidInputError("`s_t` and `s_q` must be non-empty 1-D arrays.")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise InvalidInputError("saliency maps contain NaN or inf values.")
    lo = min(a.min(), b.min())
    return 1.0 - np.exp(-K_s * (a - lo)), 1.0 - np.exp(-K_s * (b - lo))


def multiscale_features(P, saliency, *, K: int = 5, n_scales: int = 5) -> np.ndarray:
    """``[v, a]`` (n, 3 + n_scales) with ``a_j`` the mean saliency of the ``(j + 1) K`` nearest
    points (Eq. 6.35-6.36).
    """
    P = as_points(P, "P")
    n = P.shape[0]
    s = np.asarray(saliency, dtype=np.float64)
    if s.shape != (n,):
        raise InvalidInputError(f"`saliency` must have shape ({n},); got {s.shape}.")
    if not np.isfinite(s).all():
        raise InvalidInputError("`saliency` contains NaN or inf values.")
    K = check_int(K, "K")
    n_scales = check_int(n_scales, "n_scales")
    kmax = min(K * n_scales, n)
    nb, _ = knn(P, kmax, include_self=True)
    cs = np.cumsum(s[nb], axis=1)
    sizes = np.minimum(K * np.arange(1, n_scales + 1), kmax)
    a = cs[:, sizes - 1] / sizes
    return np.c_[P, a]


__all__ = ["multiscale_features", "normalize_saliency_pair", "pointcloud_saliency"]
