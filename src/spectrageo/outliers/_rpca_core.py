"""The patch RPCA pipeline of one region (steps 1-8 of :func:`spectrageo.outliers.rpca_scores`).

Validated keyword arguments come from :meth:`RPCAOptions.solver_kwargs`; numba (and torch)
threads are already limited by the caller.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._threads import numba_threads
from . import _kernels as _k
from . import _thresholds
from ._clusters import cluster_outliers
from ._common import (
    Neighbours,
    SortedCloud,
    check_span,
    knn_grid,
    morton_codes,
    spacing_from,
)
from ._rpca_solver import replay_blocks, solve_blocks
from ._rpca_types import (  # noqa: F401 - the constants and scores_deduplicated are re-exported
    BASELINE_QUANTILE,
    REFINE_MIN_TAU,
    PatchRPCAResult,
    report,
    scores_deduplicated,
)


def score_in_threads(X: np.ndarray, k: int, **opts: Any) -> PatchRPCAResult:
    """:func:`score_cloud` with numba (and torch) threads limited to ``opts["workers"]``."""
    backend, workers = opts["device"], opts["workers"]
    if isinstance(backend, str):
        with numba_threads(workers):
            return score_cloud(X, k, **opts)
    from ._torch import torch_threads

    with numba_threads(workers), torch_threads(backend, workers):
        return score_cloud(X, k, **opts)


def score_cloud(X: np.ndarray, k: int, **opts: Any) -> PatchRPCAResult:
    """Steps 1-8 on the cloud ``X`` (one region: no tiles), with the options ``opts``."""
    n = X.shape[0]
    smoothed, refine = opts["smoothed"], opts["refine"]
    tangent_weight = opts["tangent_weight"]
    weighted = tangent_weight < 1
    if opts.get("knn") is None:
        sc = SortedCloud.of(X)
        nb = knn_grid(sc, k)
    else:  # a tile region: the halo search's sorted cloud and own points' neighbours
        sc, nb = _complete_knn(opts["knn"], k)
    order, Xs = sc.order, sc.points
    if nb.n_zero:
        return scores_deduplicated(X, k, score_cloud, dict(opts, knn=None))
    h = spacing_from(nb.dmean)
    check_span(Xs, h, opts["dtype"])
    idx, dlast_s = nb.idx, nb.dlast
    del nb
    clusters_s = cluster_outliers(Xs, idx, h, kth=dlast_s) if opts["clusters"] else None  # step 8
    solve_kw = {
        key: opts[key]
        for key in ("lam", "rho", "tol", "rank_tol", "max_iter", "block_size", "workers", "dtype")
    }
    solve_kw["device"] = opts.get("device", "cpu")
    record: list | None = [] if refine and opts["second_pass"] == "replay" else None
    scores_s, E0_s, S1, n_iter, converged, residual, n_blocks = solve_blocks(
        Xs, h, idx, smoothed=smoothed, vectors=weighted, record=record, **solve_kw
    )
    n_refined = 0
    S2 = S1
    if refine:
        s1 = scores_s
        rebuilt, old_idx = _rebuild_outlier_patches(sc, idx, s1, k)
        n_refined = int(rebuilt.size)
        if n_refined and record is not None:
            scores_s = s1.copy()
            S2 = None if S1 is None else S1.copy()
            replay_blocks(
                Xs,
                h,
                idx,
                rebuilt,
                old_idx,
                record,
                dtype=solve_kw["dtype"],
                scores_s=scores_s,
                E0_s=E0_s,
                S_s=S2,
                workers=solve_kw["workers"],
            )
        elif n_refined:  # otherwise the second pass would repeat the first
            scores_s, E0_s, S2, it2, conv2, res2, _ = solve_blocks(
                Xs, h, idx, smoothed=smoothed, vectors=weighted, **solve_kw
            )
            n_iter, converged = max(n_iter, it2), converged and conv2
            residual = max(residual, res2)
        else:
            scores_s = s1.copy()
    if weighted:  # step 7: the residuals measured along the local normal (patches final)
        s1 = np.empty(n)
        _k.tangent_weighted_norms(Xs, idx, S1, S2, float(tangent_weight) ** 2, s1, scores_s)
        del S1, S2
    if refine:
        _subtract_local_baseline(scores_s, s1, idx)
        if n_refined:
            idx[rebuilt] = old_idx  # the exact kNN again (PatchRPCAResult.knn)

    scores = np.empty(n)
    scores[order] = scores_s
    clusters = None
    if clusters_s is not None:
        clusters = np.empty(n, dtype=bool)
        clusters[order] = clusters_s
    sm = None
    if smoothed:
        sm = np.empty((n, 3))
        sm[order] = E0_s
    kth = np.empty(n)
    kth[order] = dlast_s
    res = PatchRPCAResult(
        scores=scores,
        spacing=h,
        smoothed=sm,
        n_iter=n_iter,
        converged=converged,
        residual=residual,
        n_blocks=n_blocks,
        n_refined=n_refined,
        clusters=clusters,
        kth_distance=kth,
        knn=(order, idx),
    )
    report(res, opts["on_nonconvergence"], opts["max_iter"])
    return res


def _complete_knn(knn: Any, k: int) -> tuple[SortedCloud, Neighbours]:
    """Step 1 on a tile region whose first ``m`` rows (the tile's own points) already have their
    exact ``k`` nearest neighbours from the halo search (:mod:`._halo`): ``knn`` is
    ``(sc, nbr, n_zero, dmean)`` with ``sc`` the region's sorted cloud, ``nbr`` (m, k) region
    rows, ``n_zero`` the own points with a duplicate, ``dmean`` (m,). The other rows are searched
    here; the result is what :func:`knn_grid` gives for every row, up to the order of exactly
    equidistant neighbours."""
    sc, nbr, n_zero, dmean = knn
    n, m = sc.points.shape[0], nbr.shape[0]
    if nbr.shape[1] != k:  # pragma: no cover - internal: the halo searched with another k
        raise ValueError("neighbour lists of another k")
    pos = np.empty(n, dtype=np.int64)
    pos[sc.order] = np.arange(n)
    idt = np.int32 if n < 2**31 else np.int64
    idx = np.empty((n, k), dtype=idt)
    dm = np.empty(n)
    own = pos[:m]
    idx[own] = pos[nbr]
    dm[own] = dmean
    dlast = np.full(n, np.nan)  # not used by the scores
    if n > m:
        q = np.sort(pos[m:])
        rest = knn_grid(sc, k, query=q, self_index=q)
        idx[q] = rest.idx
        dm[q] = rest.dmean
        n_zero += rest.n_zero
    return sc, Neighbours(idx, dm, dlast, int(n_zero))


def _rebuild_outlier_patches(
    sc: SortedCloud, idx: np.ndarray, s1: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """Step 5 of :func:`spectrageo.outliers.rpca_scores`: rebuild, in place, the patches made
    mostly of flagged points.

    The ``k`` nearest unflagged points of each rebuilt patch's centre are found on the unflagged
    points of the same sorted cloud (:func:`._common.knn_grid` with a subset: far outliers then
    see empty space around them, which the octree search prunes). Returns the (sorted) rows
    whose patches were rebuilt and their former neighbour lists.
    """
    tau = max(_thresholds.auto_threshold(s1, minimum=_thresholds.RPCA_MIN_TAU), REFINE_MIN_TAU)
    flagged = s1 >= tau
    n_kept = s1.size - int(np.count_nonzero(flagged))
    none = np.empty(0, dtype=np.int64), idx[:0].copy()
    if n_kept < k + 1 or n_kept == s1.size:
        return none
    rebuild = np.flatnonzero(_k.count_flagged(idx, flagged) * 2 > k)
    if rebuild.size == 0:
        return none
    kept = np.flatnonzero(~flagged)
    pos = np.minimum(np.searchsorted(kept, rebuild), kept.size - 1)
    own = np.where(kept[pos] == rebuild, pos, -1)  # an unflagged centre excludes itself
    nb = knn_grid(sc, k, subset=kept, query=rebuild, self_index=own)
    old = idx[rebuild]
    idx[rebuild] = nb.idx
    return rebuild, old


def _subtract_local_baseline(scores: np.ndarray, s1: np.ndarray, idx: np.ndarray) -> None:
    """Step 6: ``scores -= the BASELINE_QUANTILE of s1 over each patch``, floored at 0, in place."""
    _k.subtract_patch_quantile(scores, s1, idx, BASELINE_QUANTILE)


def has_duplicates(X: np.ndarray) -> bool:
    """Whether two rows of ``X`` are equal (exact check only where Morton codes collide)."""
    sc = morton_codes(X)[0]
    sc.sort()  # in place: the values only
    if not np.any(sc[1:] == sc[:-1]):
        return False
    return int(np.unique(X, axis=0).shape[0]) < X.shape[0]
