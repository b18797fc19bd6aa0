r"""Small volumetric clusters: outliers that gather into blobs away from the surface (step 8 of
:func:`spectrageo.outliers.rpca_scores`).

Link ``i`` and ``j`` when ``j`` is among the ``k`` nearest neighbours of ``i`` and ``|v_i - v_j|
<= a h`` (``h`` the point spacing), take the connected components (union-find over the kNN
edges) and flag a component ``C`` when

.. math::

    4 \le |C| \le \min(N_{max}, \lfloor n / 10 \rfloor) \quad\text{and}\quad
    \lambda_3(\Sigma_C) / \operatorname{tr}\Sigma_C > f,

``Sigma_C`` the covariance of its points; the largest component is never flagged. Constants
chosen on the tuning split; see docs/decisions.md#outliers-cluster-rule.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Link length in point spacings.
CLUSTER_RADIUS = 3.0
#: Largest component that may be flagged (points).
CLUSTER_MAX = 150
#: Smallest ``lambda_3 / trace`` of a flagged component.
CLUSTER_THICKNESS = 0.05
#: Smallest flagged component (points): isolated points and pairs are left to the score.
CLUSTER_MIN = 4


@njit(cache=True, nogil=True)
def _find(parent, i):  # pragma: no cover - compiled
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True, nogil=True)
def _components(X, idx, r2, near):  # pragma: no cover - compiled
    """Component label (a root index) of every point of the graph of kNN edges ``<= sqrt(r2)``;
    ``near[i]``: every edge of ``i`` is that short (not measured)."""
    n, k = idx.shape
    parent = np.arange(n)
    for i in range(n):
        for j in range(k):
            q = idx[i, j]
            if q < 0 or q == i:
                continue
            if not near[i]:
                d2 = 0.0
                for c in range(3):
                    t = X[i, c] - X[q, c]
                    d2 += t * t
                if d2 > r2:
                    continue
            a = _find(parent, i)
            b = _find(parent, q)
            if a != b:
                if a < b:
                    parent[b] = a
                else:
                    parent[a] = b
    for i in range(n):
        parent[i] = _find(parent, i)
    return parent


def cluster_outliers(
    X: np.ndarray,
    idx: np.ndarray,
    h: float,
    *,
    radius: float = CLUSTER_RADIUS,
    max_size: int = CLUSTER_MAX,
    min_thickness: float = CLUSTER_THICKNESS,
    kth: np.ndarray | None = None,
) -> np.ndarray:
    """Boolean mask of the points in small volumetric clusters (module notes).

    ``X`` (n, 3) float64 points, ``idx`` (n, k) their nearest neighbours (self excluded, any
    order, ``-1`` for none), ``h`` the point spacing (same units as ``X``); ``kth`` (n,), when
    known, the distance to the farthest listed neighbour (NaN: unknown).
    """
    n = X.shape[0]
    flag = np.zeros(n, dtype=bool)
    limit = min(int(max_size), n // 10)
    if n == 0 or limit < 1 or not np.isfinite(h) or h <= 0:
        return flag
    r = float(radius * h)
    near = np.zeros(n, dtype=bool) if kth is None else kth <= r * (1.0 - 1e-9)
    lab = _components(np.ascontiguousarray(X, dtype=np.float64), idx, r**2, near)
    size = np.bincount(lab, minlength=n)
    small = (size > 0) & (size <= limit)
    small[int(np.argmax(size))] = False
    if not small.any():
        return flag
    cand = small[lab]
    pts, lab_c = X[cand], lab[cand]
    cnt = size[lab_c]
    # per-component covariance of the candidate points (bincount over the component labels)
    _, comp = np.unique(lab_c, return_inverse=True)
    csize = np.bincount(comp).astype(np.float64)
    mu = np.stack([np.bincount(comp, pts[:, c]) / csize for c in range(3)], axis=1)
    Y = pts - mu[comp]
    cov = np.empty((csize.size, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = cov[:, b, a] = np.bincount(comp, Y[:, a] * Y[:, b]) / csize
    ev = np.linalg.eigvalsh(cov)
    tr = ev.sum(axis=1)
    thick = np.where(tr > 0, ev[:, 0] / np.where(tr > 0, tr, 1.0), 0.0)
    bad = (thick[comp] > min_thickness) & (cnt >= CLUSTER_MIN)
    flag[np.flatnonzero(cand)[bad]] = True
    return flag
