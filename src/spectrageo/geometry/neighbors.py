"""k nearest neighbours of points (Section 3.1.10), below :mod:`spectrageo.geometry` and
:mod:`spectrageo.graph`.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_points, check_positive

_CHUNK = 262_144


def knn(
    P,
    k: int,
    *,
    query=None,
    include_self: bool = False,
    workers: int = -1,
    tree: cKDTree | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """k nearest neighbours (Section 3.1.10): ``(indices, distances)`` (q, k), nearest first.

    Without ``query`` the points query themselves, excluding themselves unless ``include_self``.
    Chunked :class:`scipy.spatial.cKDTree` queries keep memory O(q k).
    """
    P = as_points(P, "P")
    check_positive(k, "k", integer=True)
    self_query = query is None
    Q = P if self_query else as_points(query, "query")
    extra = 1 if (self_query and not include_self) else 0
    if k + extra > P.shape[0]:
        raise InvalidInputError(
            f"`k` = {k} needs at least {k + extra} points; the cloud has {P.shape[0]}."
        )
    tree = tree if tree is not None else cKDTree(P)
    kk = k + extra
    idx = np.empty((Q.shape[0], k), dtype=np.int64)
    dist = np.empty((Q.shape[0], k), dtype=np.float64)
    # Self-queries run in the tree's leaf order: neighbouring queries then walk the same nodes,
    # which is about 3x faster on unordered clouds than the input order (results are scattered back).
    order = tree.indices if (self_query and tree.n == P.shape[0]) else None
    for s in range(0, Q.shape[0], _CHUNK):
        rows = (
            order[s : s + _CHUNK]
            if order is not None
            else np.arange(s, min(s + _CHUNK, Q.shape[0]))
        )
        d, i = tree.query(Q[rows], k=kk, workers=workers)
        d = d.reshape(len(d), kk)
        i = i.reshape(len(i), kk)
        if extra:
            # drop the query point itself (it may not be first when duplicates exist)
            is_self = i == rows[:, None]
            has_self = is_self.any(axis=1)
            drop = np.where(has_self, np.argmax(is_self, axis=1), kk - 1)
            keep = np.ones_like(i, dtype=bool)
            keep[np.arange(len(i)), drop] = False
            i = i[keep].reshape(len(i), k)
            d = d[keep].reshape(len(d), k)
        idx[rows] = i
        dist[rows] = d
    return idx, dist
