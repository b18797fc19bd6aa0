"""Scene segmentation: adaptive-epsilon DBSCAN (Section 6.2.3, Eq. 6.28-6.29) and plane removal.

Connection rule: docs/decisions.md#register-segment-reading.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_points


def _check_int(v, name: str, minimum: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int | np.integer) or int(v) < minimum:
        raise InvalidInputError(f"`{name}` must be an integer >= {minimum}; got {v!r}.")
    return int(v)


def _check_float(v, name: str, *, lo: float = 0.0, hi: float = np.inf) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InvalidInputError(f"`{name}` must be a number; got {v!r}.") from None
    if not np.isfinite(f) or not lo < f <= hi:
        raise InvalidInputError(f"`{name}` must be in ({lo:g}, {hi:g}]; got {v!r}.")
    return f


def adaptive_eps(points, *, k_a: int = 5, eps_scale: float = 2.0, workers: int = -1) -> np.ndarray:
    """Per-point radius ``eps_i = eps_scale * mean of the K_a nearest distances`` (Eq. 6.29)."""
    P = as_points(points, "points")
    k_a = _check_int(k_a, "k_a", 1)
    eps_scale = _check_float(eps_scale, "eps_scale")
    if P.shape[0] <= k_a:
        raise InvalidInputError(f"`points` needs more than `k_a` = {k_a} points; got {P.shape[0]}.")
    d, _ = cKDTree(P).query(P, k=k_a + 1, workers=workers)
    return eps_scale * d[:, 1:].mean(axis=1)


def adaptive_dbscan(
    points,
    *,
    k_a: int = 5,
    eps_scale: float = 2.0,
    n_neighbors: int = 10,
    min_samples: int = 4,
    min_cluster_size: int = 1,
    workers: int = -1,
) -> np.ndarray:
    """DBSCAN with the radius of Eq. 6.29 (thesis ``K_a = 5``, ``eps_scale = 2``).

    Candidates are the ``n_neighbors`` nearest points; a point with ``min_samples`` connected
    neighbours is a core point; clusters smaller than ``min_cluster_size`` become noise. Returns
    (n,) int64 labels ``0 .. n_c - 1`` by decreasing size, ``-1`` for noise (Eq. 6.28).
    """
    P = as_points(points, "points")
    k_a = _check_int(k_a, "k_a", 1)
    n_neighbors = _check_int(n_neighbors, "n_neighbors", 1)
    min_samples = _check_int(min_samples, "min_samples", 0)
    min_cluster_size = _check_int(min_cluster_size, "min_cluster_size", 1)
    eps_scale = _check_float(eps_scale, "eps_scale")
    if n_neighbors < k_a:
        raise InvalidInputError(f"`n_neighbors` must be >= `k_a` = {k_a}; got {n_neighbors}.")
    n = P.shape[0]
    if n <= k_a:
        raise InvalidInputError(f"`points` needs more than `k_a` = {k_a} points; got {n}.")
    kk = min(n_neighbors, n - 1)
    d, idx = cKDTree(P).query(P, k=kk + 1, workers=workers)
    d, idx = d[:, 1:], idx[:, 1:]
    eps = eps_scale * d[:, :k_a].mean(axis=1)  # Eq. 6.29
    # mutual reachability inside the candidate neighbourhood: D_ij <= min(eps_i, eps_j)
    conn = d <= np.minimum(eps[:, None], eps[idx])
    core = conn.sum(axis=1) >= min_samples
    rows = np.repeat(np.arange(n), kk).reshape(n, kk)
    cc = conn & core[:, None] & core[idx]
    G = sp.coo_matrix((np.ones(int(cc.sum())), (rows[cc], idx[cc])), shape=(n, n)).tocsr()
    _, comp = connected_components(G, directed=True, connection="weak")
    labels = np.full(n, -1, dtype=np.int64)
    labels[core] = comp[core]
    # border points: the nearest connected core neighbour (columns are sorted by distance)
    border = ~core
    bc = conn[border] & core[idx[border]]
    has = bc.any(axis=1)
    first = np.argmax(bc, axis=1)
    bi = np.flatnonzero(border)[has]
    labels[bi] = labels[idx[bi, first[has]]]
    return _relabel(labels, min_cluster_size)


def split_creases(
    points, normals, viewpoint, *, crease: float = 0.2, k: int = 10, min_size: int = 30
) -> np.ndarray:
    """Pieces of a segment cut along its concave creases, as seen from ``viewpoint``.

    With normals ``n`` turned towards the viewpoint, a neighbour pair ``(i, j)`` among the ``k``
    nearest is concave when ``(n_j - n_i) . (p_j - p_i) / |p_j - p_i| < -crease`` (about the
    angle between the normals, in radians). Points with a concave pair are crease points; the
    other points are linked to their neighbours closer than 3 median spacings and the connected
    parts are the pieces; a crease point joins the piece of its nearest non-crease point.

    Parameters
    ----------
    points, normals : (n, 3) arrays
        Segment points and (unoriented) unit normals.
    viewpoint : (3,) array
        Sensor position.
    crease, k, min_size
        Concavity threshold, neighbours, smallest piece kept.

    Returns
    -------
    (n,) int64 labels ``0 .. n_p - 1`` by decreasing size, ``-1`` for points of small pieces.
    """
    P = as_points(points, "points")
    N = np.asarray(normals, dtype=np.float64)
    e = np.asarray(viewpoint, dtype=np.float64)
    n = P.shape[0]
    if n <= k:
        return _relabel(np.zeros(n, dtype=np.int64), min_size)
    N = N * np.where(np.einsum("ij,ij->i", N, e - P) < 0, -1.0, 1.0)[:, None]
    tree = cKDTree(P)
    d, idx = tree.query(P, k=k + 1)
    d, idx = d[:, 1:], idx[:, 1:]
    D = P[idx] - P[:, None, :]
    conc = np.einsum("ikc,ikc->ik", N[idx] - N[:, None, :], D) / np.maximum(d, 1e-300)
    cr = (conc < -crease).any(axis=1)
    if not cr.any() or cr.all():
        return _relabel(np.zeros(n, dtype=np.int64), min_size)
    ok = ~cr[:, None] & ~cr[idx] & (d < 3.0 * np.median(d[:, 0]))
    rows = np.repeat(np.arange(n), k).reshape(n, k)
    G = sp.coo_matrix((np.ones(int(ok.sum())), (rows[ok], idx[ok])), shape=(n, n)).tocsr()
    _, comp = connected_components(G, directed=False)
    inner = np.flatnonzero(~cr)
    _, j = cKDTree(P[inner]).query(P[cr], k=1)
    comp[cr] = comp[inner[j]]
    return _relabel(comp.astype(np.int64), min_size)


def _relabel(labels: np.ndarray, min_size: int) -> np.ndarray:
    """Renumber clusters by decreasing size; small ones become -1."""
    out = np.full(labels.shape, -1, dtype=np.int64)
    ok = labels >= 0
    if not ok.any():
        return out
    uniq, first, inv, cnt = np.unique(
        labels[ok], return_index=True, return_inverse=True, return_counts=True
    )
    first_global = np.flatnonzero(ok)[first]
    order = np.lexsort((first_global, -cnt))
    rank = np.empty(uniq.size, dtype=np.int64)
    rank[order] = np.arange(uniq.size)
    new = rank[inv]
    new[cnt[inv] < min_size] = -1
    out[ok] = new
    return out


def fit_plane_ransac(
    points, *, threshold: float, n_hypotheses: int = 500, sample: int = 20_000, rng=0
) -> tuple[np.ndarray, np.ndarray]:
    """``([n, c], inliers)`` of the plane with most points within ``threshold`` (RANSAC, refit)."""
    P = as_points(points, "points")
    threshold = _check_float(threshold, "threshold")
    g = np.random.default_rng(rng)
    n = P.shape[0]
    if n < 3:
        return np.array([0.0, 0.0, 1.0, 0.0]), np.zeros(n, dtype=bool)
    S = P[g.choice(n, min(n, sample), replace=False)] if n > sample else P
    tri = S[g.integers(0, S.shape[0], size=(n_hypotheses, 3))]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(nrm, axis=1)
    ok = ln > 1e-12
    if not ok.any():
        return np.array([0.0, 0.0, 1.0, 0.0]), np.zeros(n, dtype=bool)
    nrm = nrm[ok] / ln[ok, None]
    c = np.einsum("ij,ij->i", nrm, tri[ok, 0])
    best, best_cnt = 0, -1
    for s in range(0, nrm.shape[0], 64):
        cnt = (np.abs(S @ nrm[s : s + 64].T - c[s : s + 64]) <= threshold).sum(axis=0)
        j = int(np.argmax(cnt))
        if cnt[j] > best_cnt:
            best, best_cnt = s + j, int(cnt[j])
    nv, cv = nrm[best], c[best]
    for _ in range(2):  # least-squares refits on the inliers
        inl = np.abs(P @ nv - cv) <= threshold
        if inl.sum() < 3:
            break
        Q = P[inl]
        mu = Q.mean(axis=0)
        _, _, Vt = np.linalg.svd(Q - mu, full_matrices=False)
        nv = Vt[-1]
        cv = float(nv @ mu)
    inl = np.abs(P @ nv - cv) <= threshold
    return np.r_[nv, cv], inl


def remove_planes(
    points,
    *,
    threshold: float,
    min_fraction: float = 0.15,
    max_planes: int = 3,
    rng=0,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """``(keep, planes)`` after removing up to ``max_planes`` planes of ``min_fraction`` points."""
    P = as_points(points, "points")
    min_fraction = _check_float(min_fraction, "min_fraction", hi=1.0)
    max_planes = _check_int(max_planes, "max_planes", 0)
    g = np.random.default_rng(rng)
    keep = np.ones(P.shape[0], dtype=bool)
    planes: list[np.ndarray] = []
    for _ in range(max_planes):
        idx = np.flatnonzero(keep)
        if idx.size < 3:
            break
        plane, inl = fit_plane_ransac(P[idx], threshold=threshold, rng=g)
        if inl.sum() < min_fraction * P.shape[0]:
            break
        keep[idx[inl]] = False
        planes.append(plane)
    return keep, planes


__all__ = ["adaptive_dbscan", "adaptive_eps", "fit_plane_ransac", "remove_planes", "split_creases"]
