r"""Small volumetric clusters: outliers that gather into blobs away from the surface.

Why. The RPCA score of Eq. (5.99) measures how far a point lies from the low-rank consensus of
its own ``k``-nearest-neighbour patch, and the local baseline of
:func:`spectrageo.outliers.rpca_scores` (step 6) subtracts the level of the patch around it.
Both assume that a point's neighbours are mostly inliers. Outliers that come in clusters
(spray, dust, reflections, a second return hitting a small object, the ``"blobs"`` pattern of
:func:`spectrageo.noise.corrupt_outliers`) have only other outliers as neighbours: their patch is
a small cloud of its own, its consensus is the cluster, and the score stays low (median 0.3-1.9
spacings on the tuning scans with 10-30 % of blob points, against thresholds of 0.4-0.7).

Rule. With ``h`` the point spacing of the RPCA (median over points of the mean distance to the
``k`` nearest neighbours), link ``i`` and ``j`` when ``j`` is among the ``k`` nearest neighbours of
``i`` and ``|v_i - v_j| <= a h`` (``a = radius``), and take the connected components of that graph
(union-find over the ``n k`` kNN edges: ``O(n k)`` time, ``O(n)`` extra memory, no radius search).
A component ``C`` is a cluster of outliers when

.. math::

    4 \le |C| \le \min(N_{max}, \lfloor n / 10 \rfloor) \quad\text{and}\quad
    \lambda_3(\Sigma_C) / \operatorname{tr}\Sigma_C > f,

with ``Sigma_C`` the covariance of its points, ``lambda_3`` its smallest eigenvalue,
``N_max = max_size`` and ``f = min_thickness``; the largest component is never flagged. The
thickness test keeps small pieces of *surface* that the scan holds apart from the rest (a
separate small object, a fragment beyond a gap: flat, ``lambda_3 / tr`` near 0) and flags
volumetric blobs (an isotropic cluster has ``lambda_3 / tr`` near 1/3). Components of fewer than
four points (isolated points and pairs farther than ``a h`` from everything) have no defined
thickness; they are left to the RPCA score, which finds isolated far points on its own.
Lower bound :data:`CLUSTER_MIN` = 4: chosen on the tuning split; see
docs/decisions.md#outlier-rpca-constants.

Constants: :data:`CLUSTER_RADIUS` = 3 and :data:`CLUSTER_MAX` = 150 were chosen on the tuning
split of :mod:`spectrageo.evaluate.outliers` (``uniform``, ``halo`` and ``blobs`` on its four
scans, 5/10/30 %; ``a`` in {2, 3, 4}, ``N_max`` in {60, 150, 400}); :data:`CLUSTER_THICKNESS` =
0.05 was set once (a flat piece has a ratio near 0, an isotropic blob near 1/3) and not swept.
With ``a = 3`` and ``N_max = 150`` the F1
of ``rpca`` on blobs rose from 0.60-0.78 to 0.72-0.98, uniform and halo moved by -0.01 to
+0.03, and 0.00-0.21 % of the points of the unmodified tuning scans fall in flagged components
(``a = 2`` split the stereo scan's surface into pieces, 4 % flagged without the thickness test;
``a = 4`` merged more blobs with the surface at 30 %).
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
def _components(X, idx, r2):  # pragma: no cover - compiled
    """Component label (a root index) of every point of the graph of kNN edges ``<= sqrt(r2)``."""
    n, k = idx.shape
    parent = np.arange(n)
    for i in range(n):
        for j in range(k):
            q = idx[i, j]
            if q < 0 or q == i:
                continue
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
) -> np.ndarray:
    """Boolean mask of the points in small volumetric clusters (module notes).

    ``X`` (n, 3) float64 points, ``idx`` (n, k) their nearest neighbours (self excluded, any
    order, ``-1`` for none), ``h`` the point spacing (same units as ``X``).
    """
    n = X.shape[0]
    flag = np.zeros(n, dtype=bool)
    limit = min(int(max_size), n // 10)
    if n == 0 or limit < 1 or not np.isfinite(h) or h <= 0:
        return flag
    lab = _components(np.ascontiguousarray(X, dtype=np.float64), idx, float(radius * h) ** 2)
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
