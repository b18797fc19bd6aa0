r"""Sparse surface regions: removed points that sample a surface at their own spacing (the
do-no-harm stage of :func:`spectrageo.outliers.remove_outliers`).

For a removed point ``v_i`` with ``k`` nearest neighbours ``N_i`` (the whole cloud), let
``n_i`` be the normal of their PCA plane (covariance ``Sigma_i``, eigenvalues
``l_1 <= l_2 <= l_3``) and ``d_i`` their mean distance to ``v_i``. ``v_i`` is a *surface
candidate* when

.. math::

    |n_i^T (v_i - \bar v_{N_i})| \le \beta\, d_i
    \quad\text{and}\quad l_1 / (l_1 + l_2 + l_3) \le f,

i.e. it lies on the plane of its neighbours within a small fraction of its *own* spacing (an
outlier a few spacings off the surface lies about one own spacing off it). Candidates linked by
kNN edges form groups; the points of groups of at least ``G`` candidates are kept: a large
connected region sampled more sparsely than the rest of the cloud is not removed. Constants
chosen on the tuning split; see docs/decisions.md#outliers-sparse-regions.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SUPPORT_BETA", "SUPPORT_FLAT", "SUPPORT_GROUP", "sparse_surface", "within_spread"]

#: Largest plane residual of a candidate, in its own mean kNN distances (``beta``).
SUPPORT_BETA = 0.2
#: Largest ``l_1 / trace`` of its neighbours' covariance (``f``).
SUPPORT_FLAT = 0.05
#: Fewest candidates of a kept group (``G``).
SUPPORT_GROUP = 20


def sparse_surface(
    X: np.ndarray,
    removed: np.ndarray,
    k: int,
    knn: tuple | None = None,
    *,
    beta: float = SUPPORT_BETA,
    flat: float = SUPPORT_FLAT,
    group: int = SUPPORT_GROUP,
) -> np.ndarray:
    """Boolean mask of the removed points of ``X`` (n, 3) in large sparse surface regions.

    ``removed`` (n,) bool: the points the other stages remove; ``k``: neighbours per point;
    ``knn``: ``(order, idx)`` of :class:`~._rpca_types.PatchRPCAResult` (else a k-d tree search).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from ._kernels import surely_not_surface

    n = X.shape[0]
    keep = np.zeros(n, dtype=bool)
    rows = np.flatnonzero(removed)
    if rows.size < group or n <= k + 1:
        return keep
    if knn is not None:
        order, idx = knn
        inv = np.empty(n, dtype=np.int64)
        inv[order] = np.arange(n)
        nb = order[idx[inv[rows]]]
        k = nb.shape[1]
    else:
        _, nb = cKDTree(X).query(X[rows], k + 1)
        nb = np.where(nb[:, :1] == rows[:, None], nb[:, 1:], nb[:, :-1])  # drop the point itself
    cand = np.zeros(rows.size, dtype=bool)
    # the rows certainly failing a test are left out of the exact tests below, which give the
    # same bits row by row (docs/decisions.md#outliers-speed-support-bounds)
    out = np.empty(rows.size, dtype=bool)
    surely_not_surface(X, rows, nb, float(beta), float(flat), out)
    unsure = np.flatnonzero(~out)
    if unsure.size:
        cand[unsure] = _candidates(X, rows[unsure], nb[unsure], beta, flat)
    if np.count_nonzero(cand) < group:
        return keep
    pos = np.full(n, -1, dtype=np.int64)
    pos[rows[cand]] = np.arange(np.count_nonzero(cand))
    src = np.repeat(np.flatnonzero(cand), k)
    dst = pos[nb[cand].reshape(-1)]
    a, b = pos[rows[src]], dst
    ok = b >= 0
    m = int(np.count_nonzero(cand))
    g = coo_matrix((np.ones(int(ok.sum())), (a[ok], b[ok])), shape=(m, m))
    _, lab = connected_components(g, directed=False)
    big = np.bincount(lab)[lab] >= group
    keep[rows[cand][big]] = True
    return keep


def _plane_stats(X: np.ndarray, rows: np.ndarray, nb: np.ndarray):
    """``(off, w, d)`` of the points ``X[rows]`` with neighbours ``X[nb]`` ((m, k) indices): the
    offset from the neighbours' PCA plane, the covariance eigenvalues (m, 3), ascending, and
    the mean distance to the neighbours."""
    Y = X[nb]  # (m, k, 3)
    mu = Y.mean(axis=1)
    C = np.einsum("mka,mkb->mab", Y - mu[:, None], Y - mu[:, None]) / nb.shape[1]
    w, V = np.linalg.eigh(C)
    off = np.abs(np.einsum("ma,ma->m", X[rows] - mu, V[:, :, 0]))
    d = np.linalg.norm(Y - X[rows][:, None], axis=2).mean(axis=1)
    return off, w, d


def _candidates(X: np.ndarray, rows: np.ndarray, nb: np.ndarray, beta: float, flat: float):
    """The surface candidates (module notes) among the points ``X[rows]`` with neighbours
    ``X[nb]`` ((m, k) indices)."""
    off, w, d = _plane_stats(X, rows, nb)
    tr = w.sum(axis=1)
    return (off <= beta * d) & (w[:, 0] <= flat * np.where(tr > 0, tr, 1.0)) & (tr > 0)


def within_spread(X: np.ndarray, rows: np.ndarray, knn: tuple, factor: float) -> np.ndarray:
    """Boolean mask over ``rows``: the point lies within ``factor`` standard deviations of its
    ``k`` neighbours' PCA plane, ``|n_i^T (v_i - mean(N_i))| <= factor sqrt(l_1)``.

    ``X`` (n, 3) points, ``rows`` (m,) indices, ``knn``: ``(order, idx)`` of
    :class:`~._rpca_types.PatchRPCAResult`.
    """
    if rows.size == 0:
        return np.zeros(0, dtype=bool)
    order, idx = knn
    inv = np.empty(X.shape[0], dtype=np.int64)
    inv[order] = np.arange(X.shape[0])
    off, w, _ = _plane_stats(X, rows, order[idx[inv[rows]]])
    return off <= factor * np.sqrt(np.maximum(w[:, 0], 0.0))
