"""Point-cloud saliency and multi-scale saliency features (Section 6.2.3, Eq. 6.30-6.36).

* :func:`pointcloud_saliency`: PCA normals of every point (Eq. 6.31), the normals of the point and
  its ``k`` nearest neighbours stacked into ``N_i`` (Eq. 6.30), ``C_i = N_i^T N_i`` (Eq. 6.32) and
  ``s_i = 1 / ||lambda(C_i)||_2`` (Eq. 6.33). ``C_i`` does not depend on the sign of the normals, so
  no orientation step is needed.
* :func:`normalize_saliency_pair`: the exponential normalisation of two maps (Eq. 6.34).
* :func:`multiscale_features`: mean saliency over the ``K, 2K, ..., 5K`` nearest neighbours
  (Eq. 6.35) concatenated with the coordinates (Eq. 6.36).
"""

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
    """Spectral saliency of a point cloud (Eq. 6.30-6.33).

    Parameters
    ----------
    P : (n, 3) float
    k : int
        Neighbours in the normal patch ``N_i`` besides the point (thesis: 20).
    normal_k : int
        Neighbours of the PCA normal estimate (Eq. 6.31).
    normals : (n, 3) float, optional
        Given normals (skip Eq. 6.31).
    normalize : bool
        Min-max normalise to [0, 1] (Eq. 6.4); ``False`` returns the raw ``1 / ||lambda||`` values,
        which lie in ``[1 / (k + 1), sqrt(3) / (k + 1)]`` (as Eq. 6.34 expects).

    Returns
    -------
    (n,) float64; high on edges and corners, low on flat areas.
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
    """Joint exponential normalisation of a target and a query map (Eq. 6.34).

    ``s' = 1 - exp(-K_s s) / s_max``. The printed ``s_max = max(max(s_t), max(s_q))`` of the
    saliency does not map into [0, 1]; it is read here as the largest of the exponentials
    (reached at the smallest saliency), so that ``s' = 1 - exp(-K_s (s - s_min))`` with the joint
    minimum: 0 on the flattest point of both clouds, growing quickly to 1 (``K_s = 1000`` suits raw
    values of :func:`pointcloud_saliency` with ``normalize=False``).
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
    """Augmented feature vectors ``f = [v, a]`` (Eq. 6.35-6.36).

    ``a_i[j] = mean of s over the (j + 1) K nearest neighbours of v_i`` (the point included),
    ``j = 0..n_scales - 1``.

    Returns
    -------
    (n, 3 + n_scales) float64
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
