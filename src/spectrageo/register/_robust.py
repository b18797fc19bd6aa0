"""Robustification: small-scale outlier and boundary removal (Section 6.2.5, Eq. 6.42-6.44)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._common import WORKERS


def boundary_mask(P: np.ndarray, k: int) -> np.ndarray:
    """Boundary points: mean kNN distance at least twice the cloud mean (Eq. 6.43-6.44)."""
    n = P.shape[0]
    kk = int(min(k + 1, n))
    d, _ = cKDTree(P).query(P, k=kk, workers=WORKERS)
    d = np.asarray(d).reshape(n, kk)[:, 1:]
    d_psi = d.mean(axis=1) if d.shape[1] else np.zeros(n)
    d_bar = float(d_psi.mean())
    return d_psi >= 2.0 * d_bar


def outlier_scores(P: np.ndarray, k: int) -> np.ndarray:
    """``m_i`` of Eq. 6.42: RPCA sparse-row norm in point spacings."""
    from ..outliers import RPCAOptions, rpca_scores

    # the cluster flags (step 8 of rpca_scores) leave the scores unchanged and are not used here
    # (docs/decisions.md#register-cli-startup)
    opts = RPCAOptions(on_nonconvergence="ignore", clusters=False)
    return np.asarray(rpca_scores(P, k, opts).scores)
