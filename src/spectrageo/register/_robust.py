"""Robustification by small-scale outlier and boundary removal (thesis Section 6.2.5,
Eq. 6.42-6.44)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._common import WORKERS


def boundary_mask(P: np.ndarray, k: int) -> np.ndarray:
    """True for boundary points by Eq. 6.43-6.44: the mean distance ``d_Psi_i`` to the ``k``
    nearest neighbours is at least twice the mean ``d_bar`` of those means over the cloud."""
    n = P.shape[0]
    kk = int(min(k + 1, n))
    d, _ = cKDTree(P).query(P, k=kk, workers=WORKERS)
    d = np.asarray(d).reshape(n, kk)[:, 1:]
    d_psi = d.mean(axis=1) if d.shape[1] else np.zeros(n)
    d_bar = float(d_psi.mean())
    return d_psi >= 2.0 * d_bar


def outlier_scores(P: np.ndarray, k: int) -> np.ndarray:
    """``m_i = ||(x~_i, y~_i, z~_i)||`` of Eq. 6.42: the norm of the point's row of the sparse
    part of the RPCA of its kNN patch matrix (Section 4.5 / 5.4.1,
    :func:`spectrageo.outliers.rpca_scores`), in units of the point spacing."""
    from ..outliers import rpca_scores

    return np.asarray(rpca_scores(P, k=k, on_nonconvergence="ignore").scores)
