r"""Locally sparse points: a kept point far sparser than the kept points around it (a stage of
:func:`spectrageo.outliers.remove_outliers`, ``method="rpca"``).

With ``d_i`` the distance from ``v_i`` to its ``k``-th nearest neighbour (range-normalised with a
viewpoint: ``PatchRPCAResult.kth_distance``), ``K`` the points the other stages keep and ``N_i``
the ``m k`` nearest kept points of ``v_i``, the point is *locally sparse* when

.. math::

    d_i > \gamma \, \max\bigl(\operatorname{median}_{j \in N_i} d_j,\; Q_q(d_K)\bigr) :

radius removal's test against the kept points around the point instead of the whole cloud. A
region sampled uniformly more sparsely (grazing angles, far ranges) is compared with itself and
kept; a point above a surface is compared with the surface. Flagged points on their neighbours'
plane are kept (:func:`on_surface`). See docs/decisions.md#outliers5-local-density.
"""

from __future__ import annotations

import numpy as np

from ._common import SortedCloud, knn_grid

__all__ = ["LOCAL_FACTOR", "LOCAL_FLOOR", "LOCAL_REFERENCE", "locally_sparse_kept", "on_surface"]

#: ``gamma``: the largest ratio of a kept point's ``k``-th neighbour distance to the median of
#: its kept neighbours'.
LOCAL_FACTOR = 2.25
#: ``m``: the reference neighbourhood holds ``m k`` kept points.
LOCAL_REFERENCE = 3
#: ``q``: the reference is at least this quantile of the kept points' spacings.
LOCAL_FLOOR = 0.05


def locally_sparse_kept(
    X: np.ndarray,
    keep: np.ndarray,
    spacing: np.ndarray,
    k: int,
    *,
    factor: float | None = LOCAL_FACTOR,
    reference: int = LOCAL_REFERENCE,
    floor: float = LOCAL_FLOOR,
    order: np.ndarray | None = None,
) -> np.ndarray:
    """Boolean mask (n,) of the kept points of ``X`` that are locally sparse (module notes).

    Parameters
    ----------
    X : (n, 3) ndarray
        Finite points.
    keep : (n,) bool ndarray
        The points kept by the other stages (``K``); only they are tested.
    spacing : (n,) ndarray
        ``d``: each point's ``k``-th neighbour distance in ``X``.
    k : int
        Neighbours per point; the reference holds ``reference * k`` kept points.
    factor : float or None
        ``gamma``; None turns the stage off (no point flagged).
    reference : int
        ``m``.
    floor : float
        ``q``, in [0, 1].
    order : (n,) ndarray, optional
        The Morton order of ``X`` (``PatchRPCAResult.knn[0]``): saves its sort.

    Returns
    -------
    (n,) bool ndarray
        The flagged points, a subset of ``keep``: none when ``K`` holds at most ``m k`` points,
        none whose reference spacing is 0.
    """
    out = np.zeros(keep.size, dtype=bool)
    K = np.flatnonzero(keep)
    m = int(reference) * int(k)
    if factor is None or K.size <= m:
        return out
    d = np.asarray(spacing, dtype=np.float64)[K]
    low = float(np.quantile(d, floor))
    if not np.any(d > factor * low):  # only these can pass
        return out
    # the kept points as a subset of the sorted cloud of X (lists: rows of that cloud)
    sc = SortedCloud.of(X, order)
    rows = np.flatnonzero(keep[sc.order])
    ds = np.asarray(spacing, dtype=np.float64)[sc.order]  # sorted positions, as the lists
    cand = np.flatnonzero(ds[rows] > factor * low)
    q = rows[cand]
    nb = knn_grid(sc, m, subset=rows, query=q, self_index=cand)
    ref = np.maximum(np.median(ds[nb.idx], axis=1), low)
    flag = (ds[q] > factor * ref) & (ref > 0)
    out[sc.order[q[flag]]] = True
    return out


def on_surface(X: np.ndarray, flagged: np.ndarray, knn: tuple | None) -> np.ndarray:
    """The points of ``flagged`` (n,) bool that lie on their ``k`` neighbours' plane: the
    surface candidates of :mod:`._support` (plane residual at most ``SUPPORT_BETA`` times their
    mean neighbour distance, ``l_1 / trace`` at most ``SUPPORT_FLAT``), e.g. the first row of a
    region sampled more sparsely than the one next to it. ``knn``: ``(order, idx)`` of
    :class:`~._rpca_types.PatchRPCAResult` (None: none)."""
    from ._support import SUPPORT_BETA, SUPPORT_FLAT, _candidates

    out = np.zeros(flagged.size, dtype=bool)
    rows = np.flatnonzero(flagged)
    if rows.size == 0 or knn is None:
        return out
    order, idx = knn
    inv = np.empty(X.shape[0], dtype=np.int64)
    inv[order] = np.arange(X.shape[0])
    out[rows] = _candidates(X, rows, order[idx[inv[rows]]], SUPPORT_BETA, SUPPORT_FLAT)
    return out
