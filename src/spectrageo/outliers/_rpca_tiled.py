"""The patch RPCA of a cloud above ``block_size`` points: k-d tiles with halos of reach ``(k, k)``.

The score depends on the whole region's patch matrix, so a large cloud is defined as the tiles of
``spectrageo outliers --tile`` (:mod:`._tiles`, :mod:`._halo`): steps 1-8 on each region, the own
points' scores kept and rescaled to the global spacing; see docs/decisions.md#outliers-tiles.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._device import resolve_backend
from .._errors import InvalidInputError
from .._progress import progress
from ._halo import tile_job
from ._rpca_core import score_in_threads
from ._rpca_types import PatchRPCAResult
from ._tiles import memory_tiles

__all__ = ["rpca_tile_scores", "rpca_tiles_in_memory", "to_global_spacing"]


def rpca_tile_scores(R, m, dmean, *, workers, k, kw, knn=None) -> dict:
    """Steps 1-8 on the region ``R`` (own points first, ``m`` of them); per-own-point values.

    ``dmean``: the own points' mean ``k``-NN distance; ``kw``: the pipeline's keyword arguments
    (:meth:`RPCAOptions.solver_kwargs`); ``knn``: the region's sorted cloud and the own points'
    neighbours from the halo search, reused by step 1. Returns ``scores``, ``dmean``,
    ``spacing``, the convergence figures and ``clusters`` / ``smoothed`` when computed.
    """
    opts = dict(
        kw,
        device=resolve_backend(kw["device"]),
        workers=workers,
        on_nonconvergence="ignore",
        partition="blocks",  # no further tiling: the region is the untiled method's tile
        knn=knn,
    )
    r = score_in_threads(R, k, **opts)
    out: dict[str, Any] = {
        "dmean": np.asarray(dmean, dtype=np.float64),
        "spacing": float(r.spacing),
        "n_iter": r.n_iter,
        "converged": r.converged,
        "residual": r.residual,
        "n_blocks": r.n_blocks,
        "n_refined": r.n_refined,
    }
    if r.clusters is not None:
        out["clusters"] = np.asarray(r.clusters[:m], dtype=bool)
    if r.smoothed is not None:
        out["smoothed"] = r.smoothed[:m]
    out["scores"] = np.asarray(r.scores[:m], dtype=np.float64)
    return out


rpca_tile_scores.takes_knn = True  # type: ignore[attr-defined]


def to_global_spacing(scores, dmean, tile_of, spacing) -> float:
    """Scores of the tiles (each in units of its own spacing) to units of the global spacing
    ``h`` (median over all points of the mean kNN distance), in place; returns ``h``."""
    h = float(np.median(dmean))
    if not h > 0:  # the untiled run scores distinct positions; tiles cannot (copies span tiles)
        raise InvalidInputError(
            "more than half of the points are exact copies of others (median kNN distance 0); "
            "tiled RPCA needs distinct points: remove the copies or run without --tile."
        )
    scores *= (spacing / h)[tile_of]
    return h


def rpca_tiles_in_memory(X: np.ndarray, k: int, kw: dict) -> PatchRPCAResult:
    """``rpca_scores(X, k, partition="tiles")`` for a cloud above ``kw["block_size"]`` points:
    the tiles run one after the other in this process (``n_blocks`` = the tiles)."""
    n = X.shape[0]
    tiles = memory_tiles(X, kw["block_size"])
    T = tiles.n_tiles
    scores, dmean = np.empty(n), np.empty(n)
    tile_of = np.empty(n, dtype=np.int32)
    spacing = np.full(T, np.nan)
    clusters = np.zeros(n, dtype=bool) if kw["clusters"] else None
    smoothed = np.empty((n, 3)) if kw["smoothed"] else None
    params = {"k": k, "kw": kw}
    n_iter, converged, residual, n_refined = 0, True, 0.0, 0
    for t in progress(range(T), desc=f"RPCA outlier scores, {T} tiles", total=T):
        r = tile_job(
            tiles.spill, t, tiles.boxes, tiles.gbox, (k, k), rpca_tile_scores, params, kw["workers"]
        )
        rows = r["idx"]
        if rows.size == 0:
            continue
        scores[rows], dmean[rows], tile_of[rows] = r["scores"], r["dmean"], t
        spacing[t] = r["spacing"]
        if clusters is not None and "clusters" in r:
            clusters[rows] = r["clusters"]
        if smoothed is not None:
            smoothed[rows] = r["smoothed"]
        n_iter, converged = max(n_iter, r["n_iter"]), converged and r["converged"]
        residual, n_refined = max(residual, r["residual"]), n_refined + r["n_refined"]
    h = to_global_spacing(scores, dmean, tile_of, spacing)
    return PatchRPCAResult(
        scores=scores,
        spacing=h,
        smoothed=smoothed,
        n_iter=n_iter,
        converged=converged,
        residual=residual,
        n_blocks=T,
        n_refined=n_refined,
        clusters=clusters,
    )
