"""Adjacency of mesh vertices and point clouds (Eq. 3.6, 3.7, 4.2): connectivity, k-rings, kNN
and radius graphs; :func:`knn` is re-exported from :mod:`spectrageo.geometry.neighbors`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from ..geometry.neighbors import knn
from ..geometry.primitives import edges

__all__ = ["adjacency_matrix", "face_adjacency", "k_ring", "knn", "knn_graph", "radius_graph"]


def adjacency_matrix(F, n_vertices: int) -> sp.csr_matrix:
    """Binary, symmetric vertex adjacency ``C`` of a triangle mesh (Eq. 3.6), CSR (n, n) float64."""
    F = as_faces(F, n_vertices, "F")
    E = edges(F)
    data = np.ones(2 * len(E))
    C = sp.csr_matrix(
        (data, (np.concatenate([E[:, 0], E[:, 1]]), np.concatenate([E[:, 1], E[:, 0]]))),
        shape=(n_vertices, n_vertices),
    )
    return C


def face_adjacency(F, *, shared: str = "edge") -> sp.csr_matrix:
    """Binary (m, m) adjacency of faces sharing an edge (``shared="edge"``) or a vertex (``"vertex"``)."""
    F = np.asarray(F, dtype=np.int64)
    if F.ndim != 2 or F.shape[1] != 3:
        raise InvalidInputError(f"`F` must have shape (m, 3); got {F.shape}.")
    m = F.shape[0]
    n = int(F.max()) + 1 if m else 0
    if shared == "vertex":
        VF = sp.csr_matrix((np.ones(3 * m), (F.ravel(), np.repeat(np.arange(m), 3))), shape=(n, m))
        A = (VF.T @ VF).tocsr()
        A.setdiag(0)
        A.eliminate_zeros()
        A.data[:] = 1.0
        return A
    if shared != "edge":
        raise InvalidInputError(f"`shared` must be 'edge' or 'vertex'; got {shared!r}.")
    H = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    H.sort(axis=1)
    fid = np.tile(np.arange(m), 3)
    key = H[:, 0] * max(n, 1) + H[:, 1]
    order = np.argsort(key, kind="stable")
    key, fid = key[order], fid[order]
    # pair all faces that share the same edge key (handles non-manifold edges too)
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    counts = np.diff(np.r_[starts, key.size])
    rows, cols = [], []
    for c in np.unique(counts[counts > 1]):
        grp = starts[counts == c][:, None] + np.arange(c)[None, :]
        f = fid[grp]
        a, b = np.triu_indices(c, 1)
        rows.append(f[:, a].ravel())
        cols.append(f[:, b].ravel())
    if rows:
        r, c_ = np.concatenate(rows), np.concatenate(cols)
    else:
        r = c_ = np.zeros(0, dtype=np.int64)
    A = sp.csr_matrix((np.ones(2 * r.size), (np.r_[r, c_], np.r_[c_, r])), shape=(m, m))
    A.sum_duplicates()
    A.data[:] = 1.0
    return A


def k_ring(C: sp.spmatrix, seeds, k: int = 1, *, include_seeds: bool = True) -> np.ndarray:
    """Sorted vertices within ``k`` edges of ``seeds`` on ``C`` (Eq. 3.7)."""
    check_positive(k, "k", integer=True, allow_zero=True)
    C = sp.csr_matrix(C)
    n = C.shape[0]
    seeds = np.atleast_1d(np.asarray(seeds, dtype=np.int64))
    if seeds.size and (seeds.min() < 0 or seeds.max() >= n):
        raise InvalidInputError(
            f"`seeds` must be vertex indices in 0..{n - 1}; got {seeds.min()}..{seeds.max()}."
        )
    mask = np.zeros(n, dtype=bool)
    mask[seeds] = True
    frontier = mask.copy()
    for _ in range(k):
        nb = (C @ frontier.astype(np.float64)) > 0
        frontier = nb & ~mask
        mask |= nb
        if not frontier.any():
            break
    if not include_seeds:
        mask[seeds] = False
    return np.flatnonzero(mask)


def _symmetrize(W: sp.csr_matrix, mode: str) -> sp.csr_matrix:
    if mode == "union":
        return W.maximum(W.T).tocsr()
    if mode == "mutual":
        return W.minimum(W.T).tocsr()
    if mode == "none":
        return W.tocsr()
    raise InvalidInputError(f"`symmetric` must be 'union', 'mutual' or 'none'; got {mode!r}.")


def knn_graph(
    P, k: int = 10, *, weights: str = "binary", sigma: float | None = None, symmetric: str = "union"
) -> sp.csr_matrix:
    """Sparse (n, n) kNN graph with ``"binary"``, ``"gaussian"`` (Eq. 4.2, ``sigma``: mean kNN
    distance) or ``"distance"`` weights, symmetrised by ``"union"``, ``"mutual"`` or ``"none"``.
    """
    P = as_points(P, "P")
    idx, dist = knn(P, k)
    n = P.shape[0]
    if weights == "binary":
        w = np.ones_like(dist)
    elif weights == "gaussian":
        s = float(sigma) if sigma is not None else float(dist.mean())
        s = s if s > 0 else 1.0
        w = np.exp(-(dist**2) / (2 * s * s))
    elif weights == "distance":
        w = dist
    else:
        raise InvalidInputError(
            f"`weights` must be 'binary', 'gaussian' or 'distance'; got {weights!r}."
        )
    rows = np.repeat(np.arange(n), k)
    W = sp.csr_matrix((w.ravel(), (rows, idx.ravel())), shape=(n, n))
    W.sum_duplicates()
    return _symmetrize(W, symmetric)


def radius_graph(P, radius: float, *, max_pairs: int = 50_000_000) -> sp.csr_matrix:
    """Binary symmetric (n, n) graph of points closer than ``radius``; refuses more than
    ``max_pairs`` edges.
    """
    P = as_points(P, "P")
    check_positive(radius, "radius")
    tree = cKDTree(P)
    counts = tree.query_ball_point(P, r=radius, return_length=True, workers=-1)
    total = int(np.sum(counts)) - P.shape[0]
    if total > max_pairs:
        raise InvalidInputError(
            f"`radius` = {radius} joins {total} ordered pairs (> max_pairs = {max_pairs}); use a smaller radius."
        )
    pairs = tree.query_pairs(r=radius, output_type="ndarray")
    n = P.shape[0]
    W = sp.csr_matrix(
        (
            np.ones(2 * len(pairs)),
            (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]]),
        ),
        shape=(n, n),
    )
    return W
