"""The outlier test of the robustification (Eq. 6.42 against a threshold) without unneeded work.

:func:`outlier_keep` answers ``rpca_scores(P, k, opts).scores <= threshold`` for the NumPy patch
RPCA (:mod:`spectrageo.outliers._rpca_numpy`, the options of :func:`._robust.outlier_result`)
with the same decision for every point, computing less:

* step 1, the exact kNN: when every point is its own nearest neighbour (no exact copies), the
  k-d tree's answer without its first column, the neighbour lists and distances of
  :func:`spectrageo.outliers._common.knn_chunked` without its per-row search for the point
  itself;
* step 5, the rebuilt patches: their ``k`` nearest unflagged points are searched in the whole
  cloud's k-d tree (more neighbours asked, the flagged ones left out) instead of a new tree of
  the unflagged points (see :func:`_rebuild`);
* step 7, the tangent weighting ``sqrt(<s, n>^2 + w^2 |s - <s, n> n|^2)`` with ``w <= 1``, is at
  most the residual norm ``|s|``, and step 6 only subtracts a non-negative baseline; so a point
  whose final residual vector has ``|s| <= threshold`` passes whatever its normal, and the
  normals, weighted scores and baselines are computed only for the other points (their rows and
  their neighbours' rows, per row as in the full computation).

Steps 2-5 (centring, the inexact ALM of Eq. 4.22 on the patch matrix of Eq. 5.98 with its
stopping rules, the choice of the patches to rebuild and their replayed pass) are those of the
NumPy backend, called as they are. Exact copies, a cloud above one block or options the shortcut does not
cover go through :func:`._robust.outlier_result` unchanged.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: The screen keeps a point without its normal when ``|s| <= threshold * (1 - SCREEN_MARGIN)``:
#: a relative margin far above the rounding of ``|s|`` and of the weighted norm, so that the
#: screen never keeps a point that the full computation removes.
SCREEN_MARGIN = 1e-9


def _knn(X: np.ndarray, k: int):
    """:func:`spectrageo.outliers._common.knn_chunked` of ``X`` on itself, the k-d tree of ``X``
    and the tree's answer: ``(neighbours, tree, d, i)`` with the distances ``d`` and rows ``i``
    (n, k + 1) of ``tree.query(X, k + 1)``, the point itself first; None when a point is not
    the first answer of its own query (exact copies: the caller takes the general path)."""
    from ..outliers._common import KNN_CHUNK, KNN_SERIAL_BELOW, Neighbours

    n = X.shape[0]
    if n > KNN_CHUNK or n < k + 2:
        return None
    tree = cKDTree(X)
    d, i = tree.query(X, k=k + 1, workers=1 if n < KNN_SERIAL_BELOW else -1)
    d, i = d.reshape(n, k + 1), i.reshape(n, k + 1)
    if not np.array_equal(i[:, 0], np.arange(n)) or np.any(d[:, 1] == 0.0):
        return None
    itype = np.int32 if n < 2**31 - 1 else np.int64
    idx = np.ascontiguousarray(i[:, 1:], dtype=itype)
    dd = np.ascontiguousarray(d[:, 1:])
    return Neighbours(idx, dd.mean(axis=1), dd[:, -1].copy(), 0), tree, d, i


def _rebuild(X: np.ndarray, tree: cKDTree, idx: np.ndarray, s1: np.ndarray, k: int):
    """Step 5 (:func:`spectrageo.outliers._rpca_numpy._rebuild`): the patches with more than
    ``k / 2`` flagged points get the ``k`` nearest unflagged points of their centre (the centre
    excluded), in place in ``idx``; returns the rebuilt rows and their former neighbour lists.

    The neighbours are found in ``tree`` (the whole cloud's) by asking for more of them and
    leaving out the flagged points, instead of a k-d tree of the unflagged points; where a row
    has two equally distant candidates among its first ``k + 1`` (whose order two trees may
    give differently) or too few unflagged ones, the search falls back to a k-d tree of the
    unflagged points (:func:`spectrageo.outliers._rpca_numpy._rebuild`).
    """
    from ..outliers import _rpca_numpy as rn

    flagged, rebuild = rn.rebuild_rows(idx, s1, k)
    if rebuild.size == 0:
        return rebuild, idx[:0].copy()
    kq = min(s1.size, 2 * (k + 1))
    while True:
        d, i = tree.query(X[rebuild], k=kq)
        d, i = d.reshape(rebuild.size, kq), i.reshape(rebuild.size, kq)
        ok = ~flagged[i] & (i != rebuild[:, None])
        enough = np.count_nonzero(ok, axis=1) >= k + 1
        if enough.all() or kq == s1.size:
            break
        kq = min(s1.size, 2 * kq)
    if not enough.all():
        return rn._rebuild(X, idx, s1, k)
    # the first k + 1 unflagged candidates of every row, in distance order
    order = np.argsort(~ok, axis=1, kind="stable")[:, : k + 1]
    rows = np.arange(rebuild.size)[:, None]
    dk, ik = d[rows, order], i[rows, order]
    if np.any(dk[:, 1:] == dk[:, :-1]):
        return rn._rebuild(X, idx, s1, k)
    old = idx[rebuild]
    idx[rebuild] = ik[:, :k]
    return rebuild, old


def outlier_keep(P: np.ndarray, k: int, threshold: float) -> tuple:
    """Points whose RPCA outlier score ``m_i`` (Eq. 6.42, in point spacings) is at most
    ``threshold``, the exact kNN that the scoring searched, and its k-d tree search.

    The same decision as ``outlier_result(P, k).scores <= threshold``
    (:func:`._robust.outlier_result`) for every point; see the module docstring for what is
    left out.

    Parameters
    ----------
    P : (n, 3) float64
        The points, ``n > k + 1``.
    k : int
        Patch size (neighbours per point).
    threshold : float
        Largest score kept (thesis: 0.6).

    Returns
    -------
    keep : (n,) bool
        True where ``m_i <= threshold``.
    neighbors : (n, k) int or None
        The exact ``k`` nearest neighbours of every point in input order (self excluded), or
        None when they were not searched on the whole cloud (exact copies).
    search : tuple or None
        ``(tree, d, i)``: the ``cKDTree`` of ``P`` and its answer to ``tree.query(P, k + 1)``,
        distances ``d`` (n, k + 1) float64 and rows ``i`` (n, k + 1) int, every point first in its
        own row and no two points equal; None when the general path was taken.
    """
    from ..outliers import RPCAOptions
    from ..outliers import _rpca_numpy as rn
    from ..outliers.rpca import BLOCK_SIZE
    from ._robust import exact_neighbors, outlier_result

    opts = RPCAOptions(on_nonconvergence="ignore", clusters=False, backend="numpy")
    X = np.ascontiguousarray(P, dtype=np.float64)
    n = X.shape[0]
    covered = opts.refine and opts.second_pass == "replay" and opts.tangent_weight <= 1
    if covered and k + 1 < n <= BLOCK_SIZE and np.isfinite(threshold) and threshold >= 0:
        with rn._blas_controller().limit(limits=1, user_api="blas"):
            found = _knn(X, k)
            if found is not None:
                nb, tree, d, i = found
                return (*_keep(X, k, float(threshold), opts, nb, tree), (tree, d, i))
    res = outlier_result(X, k)
    return np.asarray(res.scores) <= threshold, exact_neighbors(res), None


def _keep(
    X: np.ndarray, k: int, thr: float, opts, nb, tree: cKDTree
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 2-7 of :func:`spectrageo.outliers._rpca_numpy._score` for the decision only."""
    from ..outliers import _rpca_numpy as rn

    n = X.shape[0]
    idx = nb.idx
    weighted = opts.tangent_weight < 1
    record: list = []
    first = rn.first_pass(X, nb, opts, record)
    Pn, S1, s1 = first.Pn, first.S1, first.out[0]
    rebuilt, old_idx = _rebuild(X, tree, idx, s1, k)
    scores, S2 = s1, S1
    if rebuilt.size:
        scores, S2 = s1.copy(), S1.copy()
        vec = np.empty((rebuilt.size, 3) if weighted else (0, 3), dtype=np.float32)
        sc, _ = rn._replay(rn._patches(Pn, old_idx, rebuilt),
                           rn._patches(Pn, idx[rebuilt], rebuilt), record, vec)  # fmt: skip
        scores[rebuilt] = sc
        if weighted:
            S2[rebuilt] = vec
    # the unweighted norm bounds the weighted one and the baseline is non-negative: the points
    # at most thr (with a margin for rounding) pass as they are
    keep = np.ones(n, dtype=bool)
    cand = np.flatnonzero(scores > thr * (1.0 - SCREEN_MARGIN))
    if cand.size:
        fin = scores[cand]
        if weighted:
            w2 = float(opts.tangent_weight) ** 2
            rows = np.unique(np.concatenate([cand, idx[cand].ravel()]))
            N = rn._normals(X, idx[rows])
            pos = np.searchsorted(rows, cand)
            fin = rn._tangent_weighted(S2[cand], N[pos], w2)
            s1w = np.zeros(n)
            s1w[rows] = rn._tangent_weighted(S1[rows], N, w2)
        else:
            s1w = s1
        rn._subtract_baseline(fin, s1w, idx[cand])
        keep[cand] = fin <= thr
    if rebuilt.size:
        idx[rebuilt] = old_idx
    return keep, idx
