"""Outlier scores by RPCA of the kNN patch matrix (thesis Section 5.4.1, Eq. 5.98-5.99,
Algorithm 14): the public entry point; the pipeline of one region is :mod:`._rpca_core`, its
ALM :mod:`._rpca_solver` and the k-d tiles of large clouds :mod:`._rpca_tiled`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from .._device import resolve_backend
from .._errors import InvalidInputError
from .._validation import options_with_legacy
from ._common import as_cloud, check_k, knn_chunked
from ._range import range_ratio
from ._rpca_types import (  # noqa: F401 - RANK_TOL and REFINE_MIN_TAU are re-exported
    RANK_TOL,
    REFINE_MIN_TAU,
    PatchRPCAResult,
    RPCAOptions,
    report,
    scores_deduplicated,
)
from ._svt import RANK_BIN, RANK_FLOOR  # noqa: F401 - re-exported

__all__ = ["PatchRPCAResult", "RPCAOptions", "knn_patch_matrix", "rpca_scores"]

#: Default number of points per independent RPCA block and largest tile of
#: ``partition="tiles"`` (``RPCAOptions(block_size=None)``): 2^22, chosen for time and memory on
#: the 10^7-point benchmark clouds; see docs/decisions.md#outliers-block-size.
BLOCK_SIZE = 2**22


def knn_patch_matrix(P: Any, k: int = 10, *, neighbors: Any = None) -> np.ndarray:
    """The spatial coherence matrix ``M`` of Eq. (5.98), shape ``(3n, k + 1)``.

    Rows ``3i .. 3i+2`` hold the coordinates of ``v_i`` (column 0) and of its ``k`` nearest
    neighbours (columns 1..k, nearest first). :func:`rpca_scores` never forms it.

    Parameters
    ----------
    P : (n, 3) array_like or PointCloud
    k : int
        Number of neighbours (``n >= k + 1``).
    neighbors : (n, k) array_like of int, optional
        Precomputed neighbour indices (e.g. from :func:`spectrageo.graph.knn`).

    Returns
    -------
    (3n, k + 1) ndarray of float64
    """
    X, _ = as_cloud(P)
    n = X.shape[0]
    if neighbors is None:
        k = check_k(k, n)
        idx = knn_chunked(X, k).idx
    else:
        idx = np.asarray(neighbors)
        if idx.ndim != 2 or idx.shape[0] != n:
            raise InvalidInputError(
                f"`neighbors` must have shape ({n}, k); got {tuple(idx.shape)}."
            )
        if idx.dtype.kind not in "iu":
            raise InvalidInputError(f"`neighbors` must hold integer indices; got {idx.dtype}.")
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise InvalidInputError(f"`neighbors` has indices outside 0..{n - 1}.")
    cols = np.concatenate([np.arange(n)[:, None], idx], axis=1)
    return np.ascontiguousarray(np.transpose(X[cols], (0, 2, 1)).reshape(3 * n, cols.shape[1]))


def rpca_scores(
    P: Any,
    k: int = 10,
    options: RPCAOptions | None = None,
    *,
    smoothed: bool = False,
    workers: int = -1,
    device: Any = "cpu",
    **legacy: Any,
) -> PatchRPCAResult:
    """Per-point outlier scores ``||s_i||_2`` of Eq. (5.99) from RPCA of the patch matrix.

    For every point the patch ``[v_i, v_i1, ..., v_ik]`` fills three rows of ``M`` (Eq. 5.98); a
    point off the surface sampled by its neighbours shows in the first column of the sparse part
    ``S`` of ``M = E + S``. Steps (1-4: Algorithm 14; 5-8: documented additions):

    1. Exact kNN on the Morton-sorted cloud; spacing ``h`` = median of the mean kNN distances.
    2. Coordinates centred per block and divided by ``h`` (scores are in spacings).
    3. Principal component pursuit (Eq. 4.18) of each block's ``3m x (k+1)`` patch matrix by the
       inexact ALM of Eq. 4.22 (``mu_0 = 1.25 / ||M||_2``, ``mu <- rho mu``, SVT through the
       ``(k+1) x (k+1)`` Gram matrix), stopped by ``tol`` or the ranking rule (``rank_tol``;
       docs/decisions.md#outliers-rank-tol).
    4. ``score_i`` = the norm of ``S[3i:3i+3, 0]``.
    5. ``refine``: patches with more than ``k / 2`` points scoring at least ``max(tau_1, 1)``
       spacings are rebuilt from the nearest unflagged points and rescored
       (docs/decisions.md#outliers-second-pass).
    6. ``refine``: ``score_i = max(||s_i|| - Q_q(||s_j^{(1)}||), 0)`` over the patch of ``v_i``,
       ``Q_q`` the ``q = 0.3`` quantile (docs/decisions.md#outliers-baseline-quantile).
    7. ``tangent_weight = w < 1``: the tangential part of ``s_i`` (against the PCA normal of the
       neighbours) is weighted by ``w``.
    8. ``clusters``: small volumetric clusters of the kNN graph are flagged (scores unchanged).
    9. ``viewpoint`` (or ``grid``: the origin) given: ``score_i / max(rho_i, 1)^p``, ``rho_i``
       the spacing predicted at the point's range over ``h`` (:func:`._range.range_ratio`),
       ``p`` = ``range_power`` (docs/decisions.md#outliers-range-model).

    ``RPCAOptions(refine=False, tangent_weight=1, clusters=False)`` gives the thesis' score; the
    defaults were chosen on the tuning split (docs/decisions.md#outlier-rpca-constants). Clouds of
    more than ``block_size`` points are scored on k-d tiles with halos (``partition="tiles"``;
    docs/decisions.md#outliers-tiles).

    Parameters
    ----------
    P : (n, 3) array_like or PointCloud
        Finite coordinates, ``n >= k + 1``; exact duplicates are scored once per position.
    k : int
        Neighbours per patch.
    options : RPCAOptions, optional
        Solver and refinement options (default ``RPCAOptions()``).
    smoothed : bool
        Also return the first column of ``E`` (a smoothed position of every point).
    workers : int
        Threads (-1: all cores); the scores do not depend on it
        (docs/decisions.md#outliers-deterministic).
    device : {"cpu", "cuda", "auto"} or torch.device
        Where step 3 runs: numba kernels (or NumPy, ``options.backend``), or the PyTorch path
        (within ``1e-3`` spacings; docs/decisions.md#outliers-gpu-tolerance).
    **legacy
        Deprecated: the fields of :class:`RPCAOptions` as keyword arguments.

    Returns
    -------
    PatchRPCAResult

    Raises
    ------
    InvalidInputError
        Bad shapes or ``block_size < k + 1``.
    ConvergenceError
        ``on_nonconvergence="raise"`` and a block reached ``max_iter``.
    """
    opts = options_with_legacy(options, legacy, RPCAOptions, "rpca_scores")
    X, _ = as_cloud(P)
    k = check_k(k, X.shape[0])
    block_size = BLOCK_SIZE if opts.block_size is None else int(opts.block_size)
    if block_size < k + 1:
        raise InvalidInputError(f"`block_size` must be >= k + 1 = {k + 1}; got {block_size}.")
    if opts.backend == "numpy":
        if not (isinstance(device, str) and device in ("cpu", "auto")):
            raise InvalidInputError(f"backend='numpy' runs on the CPU; got device={device!r}.")
        from ._rpca_numpy import score_numpy

        return score_numpy(X, k, opts, block_size=block_size, smoothed=smoothed)
    kw = opts.solver_kwargs(
        block_size=block_size, smoothed=smoothed, workers=workers, device=device
    )
    kw["device"] = resolve_backend(device)  # "cpu" (numba) or a torch.device
    res = _dispatch(X, k, **kw)
    if opts.sensor_origin is None:
        return res
    rho = np.maximum(range_ratio(X, k, opts.sensor_origin), 1.0)
    kth = None if res.kth_distance is None else res.kth_distance / rho
    return replace(res, scores=res.scores / rho**opts.range_power, kth_distance=kth)


def _dispatch(X: np.ndarray, k: int, **kw: Any) -> PatchRPCAResult:
    """One region, or the k-d tiles of a cloud above ``block_size`` points (numba kernels,
    imported here: ``backend="numpy"`` never loads numba)."""
    from ._rpca_core import has_duplicates, score_in_threads
    from ._rpca_tiled import rpca_tiles_in_memory

    if kw["partition"] == "tiles" and X.shape[0] > kw["block_size"]:
        if has_duplicates(X):  # score the distinct positions (a tile of copies has no patch)
            return scores_deduplicated(X, k, _dispatch, kw)
        res = rpca_tiles_in_memory(X, k, kw)
        report(res, kw["on_nonconvergence"], kw["max_iter"])
        return res
    return score_in_threads(X, k, **kw)
