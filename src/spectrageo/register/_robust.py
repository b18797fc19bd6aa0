"""Robustification: small-scale outlier and boundary removal (Section 6.2.5, Eq. 6.42-6.44)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ._common import WORKERS


def boundary_mask(P: np.ndarray, k: int, neighbors: np.ndarray | None = None) -> np.ndarray:
    """Boundary points: mean kNN distance at least twice the cloud mean (Eq. 6.43-6.44).

    ``neighbors`` (n, k): the exact ``k`` nearest neighbours of every point (self excluded), when
    already known; otherwise they are searched.
    """
    n = P.shape[0]
    if neighbors is not None and neighbors.shape == (n, k):
        d = _neighbor_distances(P, neighbors)
    else:
        kk = int(min(k + 1, n))
        d, _ = cKDTree(P).query(P, k=kk, workers=WORKERS)
        d = np.asarray(d).reshape(n, kk)[:, 1:]
    d_psi = d.mean(axis=1) if d.shape[1] else np.zeros(n)
    d_bar = float(d_psi.mean())
    return d_psi >= 2.0 * d_bar


def _neighbor_distances(P: np.ndarray, neighbors: np.ndarray) -> np.ndarray:
    """``|P[neighbors[i, j]] - P[i]|`` (n, k), one coordinate at a time (gathers of contiguous
    columns, no (n, k, 3) temporary); the squares are summed in the order x, y, z, as
    ``np.square(P[neighbors] - P[:, None]).sum(axis=2)`` sums them, so the values are the same."""
    s = None
    for j in range(3):
        c = np.ascontiguousarray(P[:, j])
        dc = c[neighbors]
        dc -= c[:, None]
        dc *= dc
        if s is None:
            s = dc
        else:
            s += dc
    return np.sqrt(s, out=s)


def outlier_result(P: np.ndarray, k: int) -> Any:
    """The RPCA scores of Eq. 6.42 (a :class:`~spectrageo.outliers.PatchRPCAResult`)."""
    from ..outliers import RPCAOptions, rpca_scores

    # the cluster flags (step 8 of rpca_scores) leave the scores unchanged and are not used here
    # (docs/decisions.md#register-cli-startup); the NumPy backend computes the same scores
    # without loading numba (docs/decisions.md#register-numpy-rpca)
    opts = RPCAOptions(on_nonconvergence="ignore", clusters=False, backend="numpy")
    return rpca_scores(P, k, opts)


def outlier_scores(P: np.ndarray, k: int) -> np.ndarray:
    """``m_i`` of Eq. 6.42: RPCA sparse-row norm in point spacings."""
    return np.asarray(outlier_result(P, k).scores)


def exact_neighbors(res: Any) -> np.ndarray | None:
    """The exact kNN (n, k) in input order that :func:`outlier_result` searched, or None."""
    if res.knn is None:
        return None
    order, idx = res.knn
    out = np.empty_like(idx)
    out[order] = order[idx]
    return out
